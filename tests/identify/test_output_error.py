"""Output-error fit: batched Jacobian, bounds, recovery of a simulated ship."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.errors import InputError
from trafficsim.identify import output_error, preprocess, replay
from trafficsim.identify.parameters import Parametrisation
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import load_ship


@pytest.fixture(scope="module")
def cargo_runs() -> tuple[dict, list[preprocess.Kinematics]]:
    """Two zig-zags (10/10, 20/20) of the Nomoto cargo ship, fixes sigma 1 m, compass 0.2 deg."""
    spec = load_ship("cargo")
    rng = np.random.default_rng(11)
    trials = []
    for rudder in (10.0, 20.0):
        track, _ = manoeuvres.zigzag(spec, rudder, dt=1.0)
        n = track["t_s"].size
        track = {**track, "north_m": track["north_m"] + rng.normal(0, 1.0, n),
                 "east_m": track["east_m"] + rng.normal(0, 1.0, n),
                 "heading_deg": track["heading_deg"] + rng.normal(0, 0.2, n)}
        trials.append(from_arrays(f"zz{rudder:.0f}", track))
    return spec, preprocess.smooth_runs(trials, 160.93, 7.7)


def test_batched_jacobian_equals_central_differences(cargo_runs) -> None:
    """All columns from one replay equal serial central differences (to FD accuracy)."""
    spec, runs = cargo_runs
    param = Parametrisation.of(spec)
    win = replay.windows_from_runs(runs, 100.0)
    res = output_error.Residuals(param, win)
    x = param.initial() * np.array([1.1, 0.9, 1.2, 1.05, 0.8])
    r0 = res(x[None])[0]
    h = output_error.fd_steps(x, x, param.lower, param.upper, 1e-6)
    jac = output_error.jacobian(res, x, r0, h)
    assert jac.shape == (res.m, 5)
    for j in range(5):
        step = 1e-4 * abs(x[j])
        xp, xm = x.copy(), x.copy()
        xp[j] += step
        xm[j] -= step
        central = (res(xp[None])[0] - res(xm[None])[0]) / (2 * step)
        scale = np.abs(central).max()
        assert np.abs(jac[:, j] - central).max() < 2e-3 * scale


def test_fit_recovers_the_turning_of_a_simulated_ship(cargo_runs) -> None:
    """From a start 20-50 % off, the five Nomoto coefficients fitted to two noisy zig-zags
    give the 35 deg turning circle within 3 %; the weighted residual falls to the noise level
    (RMS about 1) and the nominal intervals are finite."""
    spec, runs = cargo_runs
    param = Parametrisation.of(spec)
    win = replay.windows_from_runs(runs, 100.0)
    start = param.initial() * np.array([1.3, 0.7, 1.5, 1.2, 0.8])
    fit = output_error.fit(param, win, x0=start)
    assert fit.cost < 0.1 * fit.cost0 and fit.rms < 1.5
    assert np.all(np.isfinite(fit.ci95)) and np.all(fit.std > 0)
    np.testing.assert_allclose(np.diag(fit.corr), 1.0)
    _, true = manoeuvres.turning_circle(spec, 35.0)
    _, got = manoeuvres.turning_circle(param.specs(fit.x[None])[0], 35.0)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
        assert got[key] == pytest.approx(true[key], rel=0.03), key
    assert len(fit.history_cost) >= fit.nfev and fit.history_cost[0] == pytest.approx(fit.cost0)


def test_bounds_hold(cargo_runs) -> None:
    """With K' bounded below its true value the solution sits on the bound, not beyond."""
    spec, runs = cargo_runs
    param = Parametrisation.of(spec, ["K_prime", "T_prime"], {"K_prime": (1.0, 3.0)})
    win = replay.windows_from_runs(runs, 100.0)
    fit = output_error.fit(param, win, x0=np.array([2.0, 4.0]), max_nfev=30)
    assert fit.x[0] == pytest.approx(3.0) and param.lower[0] <= fit.x[0] <= param.upper[0]


def test_parametrisation_checks_names_and_bounds() -> None:
    spec = load_ship("kvlcc2")
    with pytest.raises(InputError, match=r"unknown coefficient 'Y_vv'.*did you mean"):
        Parametrisation.of(spec, ["Y_vv"])
    with pytest.raises(InputError, match="not fitted"):
        Parametrisation.of(spec, ["Y_v"], {"N_r": (-1.0, 0.0)})
    with pytest.raises(InputError, match="empty bounds"):
        Parametrisation.of(spec, ["Y_v"], {"Y_v": (0.0, -1.0)})
    p = Parametrisation.of(spec)
    assert p.names == ("R0", "X_vr", "Y_v", "Y_r", "N_v", "N_r", "f_alpha")
    specs = p.specs(np.stack([p.initial(), p.initial() * 2]))
    assert specs[1]["coefficients"]["Y_v"] == 2 * spec["coefficients"]["Y_v"]
    assert specs[1]["coefficients"]["k_0"] == spec["coefficients"]["k_0"]
    assert spec["coefficients"]["Y_v"] == -0.315  # the base ship is not touched


def _windows_from_model(spec: dict, w: int = 2, n: int = 61, dt: float = 2.0, seed: int = 0
                        ) -> replay.Windows:
    """Windows whose targets are the replay of ``spec`` itself (noise-free), with rudder steps."""
    rng = np.random.default_rng(seed)
    speed = spec["service_speed_kn"] * 1852 / 3600
    x0 = np.zeros((8, w))
    x0[2] = rng.uniform(0, 2 * np.pi, w)
    x0[3] = speed
    inputs = np.zeros((w, n, 2))
    inputs[..., 0] = np.radians(np.repeat(rng.uniform(-20, 20, (w, n // 15 + 1)), 15,
                                          axis=1)[:, :n])
    inputs[..., 1] = 0.8 * float(spec["actuators"]["rps_max"])
    win = replay.Windows(x0, inputs, np.zeros((w, n, 4)), np.full(w, dt), np.full(w, n),
                         np.full((w, n, 6), np.nan), np.arange(w), np.zeros(w),
                         tuple(f"w{i}" for i in range(w)))
    out, _ = replay.simulate(replay.model_rows([spec]), win)
    return replay.Windows(win.x0, win.inputs, win.env, win.dt_s, win.n_samples, out[0],
                          win.run, win.t0_s, win.run_names)


def test_noise_free_fit_recovers_the_true_coefficients() -> None:
    """Targets replayed from the cargo ship itself: from a start 30 % off, K' and T' (and the
    other three Nomoto coefficients) come back to 1e-4 and the cost to ~0."""
    spec = load_ship("cargo")
    param = Parametrisation.of(spec)
    win = _windows_from_model(spec)
    truth = param.initial()
    res = output_error.Residuals(param, win)
    assert np.abs(res(truth[None])).max() < 1e-9
    fit = output_error.fit(param, win, x0=truth * np.array([1.3, 0.7, 1.0, 1.0, 1.0]),
                           channels=("u", "v", "r", "psi", "north", "east"))
    np.testing.assert_allclose(fit.x[:2], truth[:2], rtol=1e-4)
    assert fit.cost < 1e-8 * fit.cost0 and fit.success


def test_channel_scales_by_hand() -> None:
    """Speed RMS over the valid samples only (padding ignored); the weights of the module doc."""
    x0 = np.zeros((8, 2))
    target = np.full((2, 3, 6), np.nan)
    target[0, :, 3] = [3.0, 4.0, 0.0]
    target[0, :, 4] = [4.0, 3.0, 5.0]   # |V|^2 = 25 at every sample
    target[1, :2, 3] = [0.0, 5.0]
    target[1, :2, 4] = [5.0, 0.0]
    target[1, 2, 3:5] = 100.0           # padding beyond n_samples: ignored
    win = replay.Windows(x0, np.zeros((2, 3, 2)), np.zeros((2, 3, 4)), np.ones(2),
                         np.array([3, 2]), target, np.arange(2), np.zeros(2), ("a", "b"))
    s = output_error.channel_scales(win, 100.0)
    assert s == pytest.approx({"u": 0.25, "v": 0.25, "psi": 0.05, "r": 0.0025,
                               "north": 10.0, "east": 10.0})
    still = replay.Windows(x0, win.inputs, win.env, win.dt_s, win.n_samples,
                           np.zeros((2, 3, 6)), win.run, win.t0_s, win.run_names)
    assert output_error.channel_scales(still, 10.0)["u"] == pytest.approx(0.05 * 1e-3)


def test_residual_count_weights_and_masking() -> None:
    """``m`` counts finite targets of the chosen channels after each window's first sample;
    each residual is (sim - target) / scale, so doubling a scale halves its residuals."""
    spec = load_ship("cargo")
    param = Parametrisation.of(spec)
    win = _windows_from_model(spec, w=2, n=11)
    target = win.target.copy()
    target[0, 4, 3] = np.nan          # one u sample missing
    target[1, 0, 5] = np.nan          # the first sample never counts anyway
    offset = target.copy()
    offset[..., 3] += 0.1            # u measured 0.1 m/s too high
    win_off = replay.Windows(win.x0, win.inputs, win.env, win.dt_s, win.n_samples, offset,
                             win.run, win.t0_s, win.run_names)
    scales = {"u": 0.5, "r": 1e-3}
    res = output_error.Residuals(param, win_off, channels=("u", "r"), scales=scales)
    assert res.m == 2 * 2 * 10 - 1
    r = res(param.initial()[None])[0]
    assert r.shape == (res.m,)
    # u residuals are -0.1 / 0.5 = -0.2, r residuals 0 (the model is the truth)
    assert np.sum(np.isclose(r, -0.2, atol=1e-9)) == 19
    assert np.sum(np.abs(r) < 1e-9) == 20
    # the window of each residual: 19 of window 0 (one u sample missing), then 20 of window 1
    assert res.row_window.tolist() == [0] * 19 + [1] * 20
    res2 = output_error.Residuals(param, win_off, channels=("u", "r"),
                                  scales={"u": 1.0, "r": 1e-3})
    np.testing.assert_allclose(res2(param.initial()[None])[0], r * np.where(np.abs(r) > 1e-9,
                                                                           0.5, 1.0),
                               atol=1e-12)
    with pytest.raises(ValueError, match="unknown channel"):
        output_error.Residuals(param, win, channels=("u", "yaw"))


@pytest.mark.parametrize("x, x0, lo, hi, expect", [
    (2.0, 1.0, -np.inf, np.inf, 2e-6),          # relative to |x|
    (1.0, -4.0, -np.inf, np.inf, 4e-6),         # or to the start, whichever is larger
    (0.0, 0.0, -np.inf, np.inf, 1e-9),          # exactly 0 without bounds: floor 1e-3
    (1e-12, 0.0, -np.inf, np.inf, 1e-16),       # a tiny value: floor 1e-10
    (0.0, 0.0, 0.0, 10.0, 1e-8),                # floor 1e-3 of the bounds' width
    (3.0, 3.0, 0.0, 3.0, -3e-6),                # at the upper bound: step downwards
    (-1.0, -1.0, -np.inf, 0.0, 1e-6),           # room above: upwards
])
def test_fd_steps(x, x0, lo, hi, expect) -> None:
    h = output_error.fd_steps(np.array([x]), np.array([x0]), np.array([lo]), np.array([hi]),
                              1e-6)
    assert h[0] == pytest.approx(expect, rel=1e-12)


class _Linear:
    """A linear residual ``A theta - b`` with the :class:`Residuals` interface."""

    def __init__(self, a: np.ndarray, b: np.ndarray, jac: bool = False) -> None:
        self.a, self.b = a, b
        self.channels = ("u",)
        self.scales = {"u": 1.0}
        self.last_diverged = np.zeros(0, dtype=bool)
        self.calls = 0
        if jac:
            self.jacobian = lambda x, r0, h: self.a.copy()

    def __call__(self, thetas: np.ndarray) -> np.ndarray:
        self.calls += 1
        self.last_diverged = np.array([False, True, True])
        return thetas @ self.a.T - self.b


def _linear_case(seed: int, m: int) -> tuple[np.ndarray, np.ndarray, Parametrisation]:
    """``A`` ``(m, 2)``, ``b = A [1.5, -0.5] + noise`` and two unbounded coefficients."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(m, 2))
    b = a @ [1.5, -0.5] + rng.normal(0.0, 0.1, m)
    param = Parametrisation.of(load_ship("cargo"), ["K_prime", "T_prime"],
                               {"K_prime": (-np.inf, np.inf), "T_prime": (-np.inf, np.inf)})
    return a, b, param


@pytest.mark.parametrize("analytic", [False, True])
def test_linear_problem_gives_least_squares_and_its_covariance(analytic: bool) -> None:
    """On ``r = A theta - b`` the fit is the least-squares solution and the reported std is the
    textbook ``s^2 (A^T A)^-1`` with ``s^2 = |r|^2 / (m - p)`` (module doc)."""
    a, b, param = _linear_case(3, 40)
    lin = _Linear(a, b, jac=analytic)
    fit = output_error.fit(param, None, x0=np.array([0.3, 0.2]), residuals=lin)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    np.testing.assert_allclose(fit.x, sol, rtol=1e-7)
    r = a @ sol - b
    s2 = r @ r / (40 - 2)
    cov = s2 * np.linalg.inv(a.T @ a)
    np.testing.assert_allclose(fit.std, np.sqrt(np.diag(cov)), rtol=1e-5)
    np.testing.assert_allclose(fit.ci95, 1.959964 * fit.std)
    assert fit.corr[0, 1] == pytest.approx(cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]), rel=1e-5)
    assert fit.cost == pytest.approx(0.5 * r @ r, rel=1e-9)
    r0 = a @ [0.3, 0.2] - b
    assert fit.cost0 == pytest.approx(0.5 * r0 @ r0) and fit.rms0 == pytest.approx(
        np.sqrt(np.mean(r0 ** 2)))
    assert fit.m == 40 and fit.diverged_windows == 2 and fit.channels == ("u",)
    table = fit.table()
    assert table["K_prime"]["ci95_low"] == pytest.approx(fit.x[0] - fit.ci95[0])
    assert table["T_prime"]["initial"] == 0.2


def test_a_zero_start_without_bounds_is_fitted() -> None:
    """A coefficient starting at exactly 0 without bounds has no scale for a relative step:
    it gets an absolute one large enough to see (a step at rounding size would give a
    Jacobian column of noise and leave it where it started)."""
    rng = np.random.default_rng(4)
    a = rng.normal(size=(30, 2))
    b = a @ [0.8, -0.02] + 100.0 + rng.normal(0.0, 0.01, 30)  # large residuals at the start
    a = np.hstack([a, np.ones((30, 1))])
    param = Parametrisation.of(load_ship("bulk_carrier"), ["a2", "a3", "a5"],
                               {"a2": (-np.inf, np.inf), "a3": (-np.inf, np.inf),
                                "a5": (-np.inf, np.inf)})
    fit = output_error.fit(param, None, x0=np.zeros(3), residuals=_Linear(a, b))
    np.testing.assert_allclose(fit.x, np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-6)


def test_bounded_linear_problem_matches_lsq_linear() -> None:
    """With bounds that cut off the unconstrained optimum the solution is the bounded
    least-squares one (scipy's ``lsq_linear``), and a start outside the bounds is clipped."""
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(9)
    a = rng.normal(size=(30, 2))
    b = a @ [2.0, 1.0] + rng.normal(0.0, 0.05, 30)
    param = Parametrisation.of(load_ship("cargo"), ["K_prime", "T_prime"],
                               {"K_prime": (0.0, 1.0), "T_prime": (-5.0, 5.0)})
    fit = output_error.fit(param, None, x0=np.array([7.0, 0.0]), residuals=_Linear(a, b))
    assert fit.x0[0] == 1.0
    ref = lsq_linear(a, b, bounds=([0.0, -5.0], [1.0, 5.0]))
    np.testing.assert_allclose(fit.x, ref.x, atol=1e-6)
    assert fit.x[0] == pytest.approx(1.0)


def test_history_records_every_new_evaluation() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(10, 2))
    b = rng.normal(size=10)
    param = Parametrisation.of(load_ship("cargo"), ["K_prime", "T_prime"],
                               {"K_prime": (-np.inf, np.inf), "T_prime": (-np.inf, np.inf)})
    fit = output_error.fit(param, None, x0=np.array([1.0, 1.0]), residuals=_Linear(a, b))
    assert len(fit.history_x) == len(fit.history_cost) >= 2
    for x, c in zip(fit.history_x, fit.history_cost, strict=True):
        r = a @ x - b
        assert c == pytest.approx(0.5 * r @ r)
    assert fit.history_cost[0] == pytest.approx(fit.cost0)
    s = fit.summary()
    assert s["cost_final"] == fit.cost and s["correlation"]["K_prime"]["T_prime"] == fit.corr[
        0, 1]


_MMG_NAMES = ["R0", "Y_v", "N_r", "f_alpha"]
_MMG_START = np.array([1.2, 0.8, 1.25, 0.85])


def test_mmg_coefficients_come_back_from_noise_free_replays() -> None:
    """KVLCC2 L7 (MMG standard method) replayed with rudder steps: the resistance, two hull
    derivatives and the rudder's lift slope fitted from 15-25 % off return to the generating
    values (to 1e-6) and the cost falls to rounding level."""
    spec = load_ship("kvlcc2_l7")
    param = Parametrisation.of(spec, _MMG_NAMES)
    win = _windows_from_model(spec, w=2, n=61, dt=1.0)
    truth = param.initial()
    fit = output_error.fit(param, win, x0=truth * _MMG_START)
    np.testing.assert_allclose(fit.x, truth, rtol=1e-6)
    assert fit.cost < 1e-12 * fit.cost0 and fit.success and fit.diverged_windows == 0


def test_noisy_fit_is_unbiased_and_its_intervals_are_calibrated() -> None:
    """White measurement noise of exactly the channel scales on u, v, r and psi (so each
    weighted residual is N(0, 1) at the truth): over 12 noise draws the weighted RMS at the
    solution is about 1, every estimate lies within 4 of its reported standard deviations, and
    the mean squared standardised error is about 1 (the nominal intervals of the module doc are
    right for independent residuals)."""
    spec = load_ship("kvlcc2_l7")
    param = Parametrisation.of(spec, _MMG_NAMES)
    win = _windows_from_model(spec, w=2, n=61, dt=1.0)
    truth = param.initial()
    scales = output_error.channel_scales(win, spec["particulars"]["length_m"])
    z = []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        target = win.target.copy()
        for channel in ("psi", "u", "v", "r"):
            col = output_error.CHANNELS[channel]
            target[..., col] += rng.normal(0.0, scales[channel], target[..., col].shape)
        noisy = replay.Windows(win.x0, win.inputs, win.env, win.dt_s, win.n_samples, target,
                               win.run, win.t0_s, win.run_names)
        fit = output_error.fit(param, noisy, x0=truth * _MMG_START, scales=scales)
        assert 0.85 < fit.rms < 1.15
        z.append((fit.x - truth) / fit.std)
    z = np.array(z)
    assert np.all(np.abs(z) < 4.0), z
    assert 0.5 < np.mean(z**2) < 1.6
    assert np.all(np.abs(z.mean(axis=0)) < 3.0 / np.sqrt(12))


def test_jacobian_is_a_forward_difference_in_the_step_direction() -> None:
    """On a linear residual the forward difference is exact whatever the step's sign (steps
    pointing down from an upper bound) and size, and all columns come from one call."""
    rng = np.random.default_rng(2)
    a = rng.normal(size=(12, 3))
    lin = _Linear(a, rng.normal(size=12))
    x = np.array([0.5, -2.0, 3.0])
    r0 = lin(x[None])[0]
    lin.calls = 0
    jac = output_error.jacobian(lin, x, r0, np.array([1e-3, -2e-4, -0.5]))
    np.testing.assert_allclose(jac, a, rtol=1e-8, atol=1e-9)
    assert lin.calls == 1


def test_position_channels_use_the_replayed_track() -> None:
    """Targets shifted 3 m north: with the position channels chosen the north residuals are
    -3 m / (0.1 L) at every sample after the first and the east ones zero; heading-only or
    velocity channels do not see the shift."""
    spec = load_ship("cargo")
    param = Parametrisation.of(spec)
    win = _windows_from_model(spec, w=2, n=11)
    target = win.target.copy()
    target[..., 0] += 3.0
    shifted = replay.Windows(win.x0, win.inputs, win.env, win.dt_s, win.n_samples, target,
                             win.run, win.t0_s, win.run_names)
    L = spec["particulars"]["length_m"]
    res = output_error.Residuals(param, shifted, channels=("north", "east"))
    r = res(param.initial()[None])[0].reshape(2, 10, 2)
    np.testing.assert_allclose(r[..., 0], -3.0 / (0.1 * L), rtol=1e-9)
    assert np.abs(r[..., 1]).max() < 1e-9
    velocity = output_error.Residuals(param, shifted)
    assert np.abs(velocity(param.initial()[None])).max() < 1e-9


def test_a_coefficient_the_data_do_not_move_has_no_interval() -> None:
    """A column of zeros (a rate limit never reached) or two columns that move the residuals
    alike: the data do not determine those coefficients, and their interval is infinite (the
    pseudo-inverse gave 0 for the column of zeros); the determined one keeps its textbook
    interval."""
    rng = np.random.default_rng(5)
    a = rng.normal(size=(40, 1))
    b = a[:, 0] * 1.5 + rng.normal(0.0, 0.1, 40)
    param = Parametrisation.of(load_ship("cargo"), ["K_prime", "T_prime"],
                               {"K_prime": (-np.inf, np.inf), "T_prime": (0.0, 10.0)})
    zero = np.hstack([a, np.zeros((40, 1))])
    fit = output_error.fit(param, None, x0=np.array([0.3, 2.0]), residuals=_Linear(zero, b, True))
    assert fit.std[1] == np.inf and fit.ci95[1] == np.inf and np.isfinite(fit.std[0])
    r = a[:, 0] * fit.x[0] - b
    assert fit.std[0] == pytest.approx(np.sqrt(r @ r / 38 / (a[:, 0] @ a[:, 0])), rel=1e-6)
    table = fit.table()
    assert table["T_prime"]["ci95_high"] == np.inf and not table["T_prime"]["at_bound"]
    twins = np.hstack([a, 2.0 * a])
    fit = output_error.fit(param, None, x0=np.array([0.3, 2.0]), residuals=_Linear(twins, b, True))
    assert np.isinf(fit.std).all()
    jac = np.hstack([a, rng.normal(size=(40, 1)), np.zeros((40, 1))])
    assert output_error.undetermined(jac).tolist() == [False, False, True]
    assert output_error.undetermined(jac[:1]).tolist() == [True, True, True]  # one residual


def test_a_value_on_its_bound_is_flagged() -> None:
    assert output_error.on_bound(10.0, 0.0, 10.0) and output_error.on_bound(0.0, 0.0, 10.0)
    assert not output_error.on_bound(9.99, 0.0, 10.0)
    assert output_error.on_bound(-1.0, -1.0, np.inf) and not output_error.on_bound(
        5.0, -1.0, np.inf)
    assert not output_error.on_bound(3.0, -np.inf, np.inf)


def test_clustered_std_follows_errors_that_persist_along_a_window() -> None:
    """Residuals sharing an offset within each of 40 windows (as a trajectory error persists
    along a window) and a regressor that varies mostly between windows: over 300 draws the
    clustered standard deviation is the estimate's actual spread (within 15 %), the nominal
    one a fraction of it; for independent residuals the two agree."""
    rng = np.random.default_rng(11)
    g, n = 40, 25
    cluster = np.repeat(np.arange(g), n)
    a = np.column_stack([np.ones(g * n), np.repeat(rng.normal(size=g), n)
                         + 0.2 * rng.normal(size=g * n)])
    for offset_sd, white_sd, far_below in ((1.0, 0.3, True), (0.0, 1.0, False)):
        est, nominal, clustered = [], [], []
        for _ in range(300):
            b = a @ [1.0, -0.5] + np.repeat(rng.normal(0.0, offset_sd, g), n) + rng.normal(
                0.0, white_sd, g * n)
            theta = np.linalg.lstsq(a, b, rcond=None)[0]
            r = a @ theta - b
            est.append(theta)
            nominal.append(np.sqrt(np.diag(r @ r / (g * n - 2) * np.linalg.inv(a.T @ a))))
            clustered.append(output_error.clustered_std(a, r, cluster))
        spread = np.std(est, axis=0)
        np.testing.assert_allclose(np.mean(clustered, axis=0), spread, rtol=0.15)
        assert (np.mean(nominal, axis=0) < 0.4 * spread).all() == far_below
    assert np.isnan(output_error.clustered_std(a[:90], np.ones(90), cluster[:90])).all()


def test_fit_reports_the_clustered_std_of_its_windows() -> None:
    a, b, param = _linear_case(12, 60)
    lin = _Linear(a, b, jac=True)
    plain = output_error.fit(param, None, residuals=lin)
    assert np.isnan(plain.std_clustered).all()
    assert "ci95_clustered_high" not in plain.table()["K_prime"]  # (no NaN in the table)
    lin.row_window = np.repeat(np.arange(12), 5)
    fit = output_error.fit(param, None, residuals=lin)
    r = a @ fit.x - b
    np.testing.assert_allclose(fit.std_clustered,
                               output_error.clustered_std(a, r, lin.row_window), rtol=1e-6)
    row = fit.table()["K_prime"]
    assert row["ci95_clustered_high"] == pytest.approx(fit.x[0] + 1.959964
                                                       * fit.std_clustered[0])
