"""Replay of ship models with measured inputs: against a plain per-window reference, the
truth, and in batches."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.errors import DataError
from trafficsim.identify import preprocess, replay
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships import base, kernels, manoeuvres
from trafficsim.ships.library import load_ship


def _reference(spec: dict, x0: np.ndarray, inputs: np.ndarray, env: np.ndarray, dt: float,
               substeps: int) -> np.ndarray:
    """Textbook RK4 of one ship with first-order-hold inputs via ``base.accelerations``."""
    family = base.families()[spec["model"]]
    params = family.build([spec])

    def deriv(x: np.ndarray, k: int, f: float) -> np.ndarray:
        xs = np.zeros((8, 1))
        xs[:6, 0] = x
        xs[6, 0] = (1 - f) * inputs[k, 0] + f * inputs[k + 1, 0]
        xs[7, 0] = (1 - f) * inputs[k, 1] + f * inputs[k + 1, 1]
        e = base.Env(env[k, 0], env[k, 1], env[k, 2], env[k, 3])
        du, dv, dr = base.accelerations(family, params, xs, e)
        c, s = np.cos(x[2]), np.sin(x[2])
        return np.array([x[3] * c - x[4] * s + env[k, 0], x[3] * s + x[4] * c + env[k, 1],
                         x[5], du[0], dv[0], dr[0]])

    out = [x0[:6].copy()]
    x = x0[:6].copy()
    h = dt / substeps
    for k in range(inputs.shape[0] - 1):
        for s in range(substeps):
            f0, fm, f1 = s / substeps, (s + 0.5) / substeps, (s + 1) / substeps
            k1 = deriv(x, k, f0)
            k2 = deriv(x + 0.5 * h * k1, k, fm)
            k3 = deriv(x + 0.5 * h * k2, k, fm)
            k4 = deriv(x + h * k3, k, f1)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(x.copy())
    return np.array(out)


def _windows(rng: np.random.Generator, w: int, n: int, dt: float, speed: float, rps: float
             ) -> replay.Windows:
    x0 = np.zeros((8, w))
    x0[0] = rng.normal(0, 100, w)
    x0[2] = rng.uniform(0, 2 * np.pi, w)
    x0[3] = speed * rng.uniform(0.8, 1.1, w)
    x0[4] = rng.normal(0, 0.05 * speed, w)
    x0[5] = rng.normal(0, 0.002, w)
    inputs = np.zeros((w, n, 2))
    inputs[..., 0] = np.radians(np.cumsum(rng.normal(0, 3, (w, n)), axis=1)).clip(-0.6, 0.6)
    inputs[..., 1] = rps * rng.uniform(0.7, 1.1, (w, n))
    env = np.zeros((w, n, 4))
    env[..., 2] = rng.uniform(0, 15, (w, n))
    env[..., 3] = rng.uniform(0, 2 * np.pi, (w, n))
    return replay.Windows(x0, inputs, env, np.full(w, dt), np.array([n, n - 7][:w]),
                          np.full((w, n, 6), np.nan), np.arange(w), np.zeros(w),
                          tuple(f"w{i}" for i in range(w)))


@pytest.mark.parametrize("ship", ["kvlcc2", "cargo", "bulk_carrier", "catfish"])
def test_replay_equals_a_plain_rk4_reference(ship: str) -> None:
    """Every family, with wind and time-varying inputs, 2 windows of different lengths: the
    compiled replay equals a per-window RK4 written with numpy (to rounding)."""
    spec = load_ship(ship)
    rng = np.random.default_rng(7)
    speed = spec["service_speed_kn"] * 1852 / 3600
    rps = float(spec["actuators"]["rps_max"]) * 0.8
    win = _windows(rng, 2, 25, 2.0, speed, rps)
    models = replay.model_rows([spec])
    sub = int(replay.substeps(models, win)[0, 0])
    out, diverged = replay.simulate(models, win)
    assert not diverged.any()
    for w in range(2):
        n = win.n_samples[w]
        ref = _reference(spec, win.x0[:, w], win.inputs[w, :n], win.env[w, :n], 2.0, sub)
        np.testing.assert_allclose(out[0, w, :n], ref, rtol=1e-9, atol=1e-9)
        assert np.all(np.isnan(out[0, w, n:]))


def test_batches_are_independent() -> None:
    """k models x W windows in one call equal each model on each window alone."""
    specs = [load_ship("kvlcc2"), load_ship("container"), load_ship("bulk_carrier")]
    rng = np.random.default_rng(3)
    win = _windows(rng, 2, 30, 1.0, 7.0, 1.2)
    models = replay.model_rows(specs)
    out, _ = replay.simulate(models, win)
    for m, spec in enumerate(specs):
        for w in range(2):
            one, _ = replay.simulate(replay.model_rows([spec]), win.subset(np.arange(2) == w))
            np.testing.assert_array_equal(out[m, w], one[0, 0])


def test_replaying_the_measured_inputs_reproduces_the_trial() -> None:
    """A 20/20 zig-zag of the KVLCC2 (steering gear and engine lags in the truth) replayed from
    its first state with the recorded rudder and rpm: heading within 0.2 deg and position
    within 0.5 % of the distance run over 20 minutes."""
    spec = load_ship("kvlcc2")
    track, _ = manoeuvres.zigzag(spec, 20.0, dt=1.0)
    trial = from_arrays("zz", track)
    smooth = {"north_m": trial.north_m, "east_m": trial.east_m,
              "psi_rad": np.unwrap(trial.psi_rad),
              "u_mps": trial.u_mps, "v_mps": trial.v_mps, "r_radps": trial.r_radps}
    run = preprocess.Kinematics(trial, smooth, {}, {})
    win = replay.windows_from_runs([run], None)
    out, _ = replay.simulate(replay.model_rows([spec]), win)
    sim = out[0, 0]
    dist = np.sum(np.hypot(np.diff(trial.north_m), np.diff(trial.east_m)))
    assert np.degrees(np.abs(sim[:, 2] - np.unwrap(trial.psi_rad)).max()) < 0.2
    assert np.hypot(sim[:, 0] - trial.north_m, sim[:, 1] - trial.east_m).max() < 0.005 * dist
    # cut into 100 s windows, each from its own measured state: errors smaller still
    win = replay.windows_from_runs([run], 100.0)
    assert win.w >= (trial.n - 1) // 100 and np.all(win.n_samples <= 101)
    out, _ = replay.simulate(replay.model_rows([spec]), win)
    err = np.abs(out[0, :, :, 2] - win.target[:, :, 2])
    assert np.nanmax(np.degrees(err)) < 0.1


def test_a_diverging_candidate_is_frozen_and_flagged() -> None:
    spec = load_ship("bulk_carrier")
    bad = dict(spec, coefficients={**spec["coefficients"], "c2": 5.0, "b1": 3.0})
    rng = np.random.default_rng(1)
    win = _windows(rng, 2, 400, 2.0, 6.0, 1.4)
    out, diverged = replay.simulate(replay.model_rows([spec, bad]), win)
    assert not diverged[0].any() and diverged[1].all()
    valid = win.valid()
    assert np.all(np.isfinite(out[1][valid]))


def _with(win: replay.Windows, **changes) -> replay.Windows:
    fields = dict(x0=win.x0, inputs=win.inputs, env=win.env, dt_s=win.dt_s,
                  n_samples=win.n_samples, target=win.target, run=win.run, t0_s=win.t0_s,
                  run_names=win.run_names)
    fields.update(changes)
    return replay.Windows(**fields)


@pytest.mark.parametrize("ship", ["kvlcc2", "cargo", "bulk_carrier"])
def test_rotation_and_translation_invariance(ship: str) -> None:
    """The hull does not know where north is: turning the start (position about the origin,
    heading) and the wind direction by 70 deg and shifting the start by (300, -200) m turns
    and shifts the replayed track the same way; u, v, r are unchanged."""
    spec = load_ship(ship)
    rng = np.random.default_rng(5)
    speed = spec["service_speed_kn"] * 1852 / 3600
    win = _windows(rng, 2, 40, 2.0, speed, float(spec["actuators"]["rps_max"]) * 0.8)
    a = np.radians(70.0)
    c, s = np.cos(a), np.sin(a)
    x0 = win.x0.copy()
    x0[0], x0[1] = c * win.x0[0] - s * win.x0[1] + 300.0, s * win.x0[0] + c * win.x0[1] - 200.0
    x0[2] = win.x0[2] + a
    env = win.env.copy()
    env[..., 3] = win.env[..., 3] + a
    models = replay.model_rows([spec])
    out, _ = replay.simulate(models, win)
    rot, _ = replay.simulate(models, _with(win, x0=x0, env=env))
    for w in range(2):
        n = win.n_samples[w]
        o, q = out[0, w, :n], rot[0, w, :n]
        np.testing.assert_allclose(q[:, 0], c * o[:, 0] - s * o[:, 1] + 300.0, atol=1e-6)
        np.testing.assert_allclose(q[:, 1], s * o[:, 0] + c * o[:, 1] - 200.0, atol=1e-6)
        np.testing.assert_allclose(q[:, 2], o[:, 2] + a, atol=1e-9)
        np.testing.assert_allclose(q[:, 3:], o[:, 3:], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("ship", ["kvlcc2", "cargo"])
def test_uniform_current_only_drifts_the_track(ship: str) -> None:
    """Without wind, a uniform current (per model through ``env_offset``) leaves the motion
    through the water unchanged and moves the position by current x elapsed time; the
    ``(k, 4)`` and ``(k, W, 4)`` forms of the offset agree."""
    spec = load_ship(ship)
    rng = np.random.default_rng(9)
    win = _windows(rng, 2, 30, 2.0, 6.0, float(spec["actuators"]["rps_max"]) * 0.8)
    win = _with(win, env=np.zeros_like(win.env))
    models = replay.model_rows([spec, spec])
    off = np.array([[0.0, 0.0, 0.0, 0.0], [0.4, -0.7, 0.0, 0.0]])
    out, _ = replay.simulate(models, win, env_offset=off)
    t = 2.0 * np.arange(win.n)
    for w in range(2):
        n = win.n_samples[w]
        base_, cur = out[0, w, :n], out[1, w, :n]
        np.testing.assert_allclose(cur[:, 0], base_[:, 0] + 0.4 * t[:n], atol=1e-6)
        np.testing.assert_allclose(cur[:, 1], base_[:, 1] - 0.7 * t[:n], atol=1e-6)
        np.testing.assert_allclose(cur[:, 2:], base_[:, 2:], rtol=1e-9, atol=1e-12)
    per_window = np.repeat(off[:, None, :], 2, axis=1)
    again, _ = replay.simulate(models, win, env_offset=per_window)
    np.testing.assert_array_equal(again, out)


def test_air_velocity_offset_is_the_wind_it_describes() -> None:
    """An air-velocity offset of (-12, 0) m/s over ground ("towards" south) on a windless
    window is a true wind of 12 m/s from north; an offset that cancels the window's wind
    leaves a calm (KVLCC2, which has windage)."""
    spec = load_ship("kvlcc2")
    rng = np.random.default_rng(2)
    win = _windows(rng, 1, 30, 2.0, 7.0, 1.2)
    calm = _with(win, env=np.zeros_like(win.env))
    from_north = calm.env.copy()
    from_north[..., 2] = 12.0
    models = replay.model_rows([spec])
    windy, _ = replay.simulate(models, _with(calm, env=from_north))
    offset, _ = replay.simulate(models, calm, env_offset=np.array([[0.0, 0.0, -12.0, 0.0]]))
    np.testing.assert_allclose(offset, windy, rtol=1e-9, atol=1e-9)
    still, _ = replay.simulate(models, calm)
    cancelled, _ = replay.simulate(models, _with(calm, env=from_north),
                                   env_offset=np.array([[0.0, 0.0, 12.0, 0.0]]))
    np.testing.assert_allclose(cancelled, still, rtol=1e-9, atol=1e-9)
    assert np.abs(windy - still)[0, 0, -1, :2].max() > 0.1  # the wind does act


def _reference_lag(spec: dict, x0: np.ndarray, gear0: float, inputs: np.ndarray, dt: float,
                   tau: float, rate: float) -> np.ndarray:
    """Textbook RK4 of the seven states (motion + rudder of a first-order, rate-limited
    steering gear following the first-order-hold measured rudder), via base.accelerations."""
    family = base.families()[spec["model"]]
    params = family.build([spec])

    def foh(k: int, f: float, j: int) -> float:
        return (1 - f) * inputs[k, j] + f * inputs[k + 1, j]

    def deriv(x: np.ndarray, k: int, f: float) -> np.ndarray:
        xs = np.zeros((8, 1))
        xs[:7, 0] = x
        xs[7, 0] = foh(k, f, 1)
        du, dv, dr = base.accelerations(family, params, xs, base.Env())
        c, s = np.cos(x[2]), np.sin(x[2])
        gear = np.clip((foh(k, f, 0) - x[6]) / tau, -rate, rate)
        return np.array([x[3] * c - x[4] * s, x[3] * s + x[4] * c, x[5], du[0], dv[0], dr[0],
                         gear])

    x = np.r_[x0[:6], gear0]
    out = [x[:6].copy()]
    for k in range(inputs.shape[0] - 1):
        k1 = deriv(x, k, 0.0)
        k2 = deriv(x + 0.5 * dt * k1, k, 0.5)
        k3 = deriv(x + 0.5 * dt * k2, k, 0.5)
        k4 = deriv(x + dt * k3, k, 1.0)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(x[:6].copy())
    return np.array(out)


def test_steering_gear_equals_a_plain_rk4_of_seven_states() -> None:
    """With ``steering = (tau, rate)`` the hull feels a lagged, rate-limited rudder started
    at row 6 of ``x0``; one sub-step per sample (max_dt_s = dt) so the reference is plain."""
    spec = load_ship("kvlcc2")
    spec["integration"] = {"max_dt_s": 1.0}
    rng = np.random.default_rng(4)
    win = _windows(rng, 1, 40, 1.0, 7.0, 1.2)
    win = _with(win, env=np.zeros_like(win.env))
    models = replay.model_rows([spec])
    assert replay.substeps(models, win)[0, 0] == 1
    x0 = np.repeat(win.x0[None], 1, axis=0).copy()
    x0[0, 6, 0] = np.radians(-5.0)
    tau, rate = 3.0, np.radians(2.0)
    out, _ = replay.simulate(models, win, x0=x0, steering=np.array([[tau, rate]]))
    ref = _reference_lag(spec, win.x0[:, 0], np.radians(-5.0), win.inputs[0], 1.0, tau, rate)
    np.testing.assert_allclose(out[0, 0], ref, rtol=1e-9, atol=1e-9)
    plain, _ = replay.simulate(models, win)
    assert np.abs(out - plain)[0, 0, -1, 2] > 1e-4  # the lag does change the heading


def test_a_gear_already_at_a_constant_measured_rudder_changes_nothing() -> None:
    """Measured rudder constant and the gear starting there (the default start): the lagged
    replay is the un-lagged one."""
    spec = load_ship("cargo")
    rng = np.random.default_rng(6)
    win = _windows(rng, 2, 20, 2.0, 7.0, 1.5)
    inputs = win.inputs.copy()
    inputs[..., 0] = np.radians(15.0)
    win = _with(win, inputs=inputs)
    models = replay.model_rows([spec])
    lag, _ = replay.simulate(models, win, steering=np.array([[5.0, 0.05]]))
    plain, _ = replay.simulate(models, win)
    np.testing.assert_allclose(lag, plain, rtol=1e-12, atol=1e-12)


def test_a_frozen_replay_holds_its_last_finite_state() -> None:
    """A yaw-unstable candidate (c2 > 0) runs away part-way through the window: from then on
    its output is the last state before the runaway guard tripped."""
    spec = load_ship("bulk_carrier")
    bad = dict(spec, coefficients={**spec["coefficients"], "c2": 0.05})
    rng = np.random.default_rng(1)
    win = _windows(rng, 1, 400, 2.0, 6.0, 1.4)
    out, diverged = replay.simulate(replay.model_rows([bad]), win)
    assert diverged[0, 0]
    o = out[0, 0]
    change = np.any(np.diff(o, axis=0) != 0.0, axis=1)
    last_move = int(np.flatnonzero(change).max()) + 1
    assert last_move < win.n - 1                     # it froze before the end ...
    assert np.all(o[last_move:] == o[last_move])     # ... and stayed frozen
    assert np.all(np.abs(o[:, 3:]) <= 1e3)           # runaway guard (speed, yaw rate)


@pytest.mark.parametrize("dt, max_dt, expect", [(2.0, 0.5, 4), (1.0, 1.0, 1), (1.0, 5.0, 1),
                                                (2.5, 1.0, 3), (3.0, 1.0, 3)])
def test_substeps(dt, max_dt, expect) -> None:
    """ceil(dt / max_dt_s), at least one (exact multiples do not round up)."""
    spec = dict(load_ship("cargo"), integration={"max_dt_s": max_dt})
    win = replay.Windows(np.zeros((8, 1)), np.zeros((1, 2, 2)), np.zeros((1, 2, 4)),
                         np.array([dt]), np.array([2]), np.zeros((1, 2, 6)), np.zeros(1, int),
                         np.zeros(1), ("a",))
    assert replay.substeps(replay.model_rows([spec]), win)[0, 0] == expect


def test_model_rows_pads_mixed_families() -> None:
    specs = [load_ship("cargo"), load_ship("kvlcc2"), load_ship("bulk_carrier")]
    rows = replay.model_rows(specs)
    widths = [base.pack(base.families()[s["model"]].build([s]))[0].shape[0] for s in specs]
    assert rows.k == 3 and rows.params.shape == (3, max(widths))
    for i, w in enumerate(widths):
        np.testing.assert_array_equal(rows.params[i, w:], 0.0)
    assert list(rows.codes) == [kernels.FAMILY_CODE[s["model"]] for s in specs]
    np.testing.assert_array_equal(rows.max_dt_s, [float(s.get("integration", {}).get(
        "max_dt_s", 1.0)) for s in specs])
    no_integration = {k: v for k, v in specs[0].items() if k != "integration"}
    assert replay.model_rows([no_integration]).max_dt_s[0] == 1.0


def _run(name: str, n: int, dt: float = 1.0, **series) -> preprocess.Kinematics:
    """A run of ``n`` samples whose smoothed outputs are easy to recognise (north = 10 t, ...)."""
    t = np.arange(n) * dt
    cols = {"t_s": t, "north_m": 10 * t, "east_m": t * 0, "heading_deg": t * 0 + 5,
            "rudder_deg": t, "rpm": 60 + t}
    cols.update(series)
    trial = from_arrays(name, cols)
    smooth = {"north_m": 10.0 * t, "east_m": -t, "psi_rad": 0.01 * t, "u_mps": 5 + t,
              "v_mps": 0.1 * t, "r_radps": 0.001 * t}
    return preprocess.Kinematics(trial, smooth, {}, {})


def test_windows_cut_share_boundaries_and_start_from_their_state() -> None:
    """15 s horizon at 1 s: a 41-sample run gives windows starting at 0, 15, 30 (16, 16 and 11
    samples: 10 s is at least half a horizon); each starts from the smoothed state at its
    first sample; inputs are padded with their last value; t0 is the start time."""
    run = _run("a", 41)
    win = replay.windows_from_runs([run], 15.0)
    assert win.w == 3 and list(win.n_samples) == [16, 16, 11] and win.n == 16
    np.testing.assert_array_equal(win.t0_s, [0.0, 15.0, 30.0])
    for i, s in enumerate((0, 15, 30)):
        np.testing.assert_allclose(win.x0[:6, i], [10 * s, -s, 0.01 * s, 5 + s, 0.1 * s,
                                                   0.001 * s])
        assert win.target[i, 0, 0] == 10 * s
    # consecutive windows share their boundary sample
    assert win.target[0, 15, 0] == win.target[1, 0, 0]
    # rudder (rad) and rps of the measured run; the short window padded with its last value
    np.testing.assert_allclose(win.inputs[2, :11, 0], np.radians(np.arange(30, 41)))
    np.testing.assert_allclose(win.inputs[2, 11:, 0], np.radians(40.0))
    np.testing.assert_allclose(win.inputs[0, :, 1], (60 + np.arange(16)) / 60)
    assert np.all(np.isnan(win.target[2, 11:]))
    np.testing.assert_array_equal(win.valid()[2], np.arange(16) < 11)
    whole = replay.windows_from_runs([run], None)
    assert whole.w == 1 and whole.n_samples[0] == 41


def test_windows_of_several_runs_and_subset() -> None:
    a, b = _run("a", 21), _run("b", 11, dt=0.5)
    win = replay.windows_from_runs([a, b], 5.0)
    # a: per = 6 samples -> starts 0, 5, 10, 15 (6 each); b: per = 11 -> one window of 11
    assert list(win.run) == [0, 0, 0, 0, 1] and list(win.n_samples) == [6, 6, 6, 6, 11]
    np.testing.assert_array_equal(win.dt_s, [1, 1, 1, 1, 0.5])
    assert win.run_names == ("a", "b")
    sub = win.subset(win.run == 1)
    assert sub.w == 1 and sub.dt_s[0] == 0.5 and sub.run_names == ("a", "b")
    np.testing.assert_array_equal(sub.target[0], win.target[4])
    # a run shorter than the horizon still gives its one window
    short = replay.windows_from_runs([_run("s", 3)], 100.0)
    assert short.w == 1 and short.n_samples[0] == 3


def test_last_piece_of_half_a_horizon_is_kept() -> None:
    """10 s horizon at 1 s, 16 samples: the last piece (samples 10-15) spans 5 s, exactly half
    a horizon: not shorter, so kept."""
    win = replay.windows_from_runs([_run("a", 16)], 10.0)
    assert list(win.n_samples) == [11, 6]


def test_last_piece_shorter_than_half_a_horizon_is_dropped() -> None:
    """10 s horizon at 1 s, 15 samples: the last piece (samples 10-14) spans 4 s, shorter than
    half a horizon (5 s), so the module doc says it is dropped."""
    win = replay.windows_from_runs([_run("a", 15)], 10.0)
    assert list(win.n_samples) == [11]


def test_missing_inputs_interpolated_and_wind_only_when_asked() -> None:
    t = np.arange(11.0)
    rud = t.copy()
    rud[[0, 4, 5]] = np.nan
    run = _run("a", 11, rudder_deg=rud, wind_speed_mps=t * 0 + 8.0,
               wind_from_deg=np.where(t == 3, np.nan, 90.0))
    win = replay.windows_from_runs([run], None)
    # leading NaN held at the first known value, interior ones linear
    np.testing.assert_allclose(np.degrees(win.inputs[0, :, 0]), [1, 1, 2, 3, 4, 5, 6, 7, 8, 9,
                                                                10])
    assert np.all(win.env[0, :, 2:] == 0.0)  # wind withheld unless use_wind
    windy = replay.windows_from_runs([run], None, use_wind=True)
    np.testing.assert_allclose(windy.env[0, :, 2], 8.0)
    np.testing.assert_allclose(windy.env[0, :, 3], np.radians(90.0))
    np.testing.assert_array_equal(windy.env[0, :, :2], 0.0)


def test_a_run_without_any_rudder_reading_is_refused() -> None:
    from trafficsim.errors import DataError

    t = np.arange(10.0)
    run = _run("a", 10, rudder_deg=t * np.nan)
    trial = run.trial
    run = preprocess.Kinematics(trial.__class__(**{**trial.__dict__, "path": "runs/a.csv"}),
                                run.smooth, {}, {})
    with pytest.raises(DataError, match=r"runs/a.csv: no finite rudder angle sample"):
        replay.windows_from_runs([run], None)
    with pytest.raises(DataError, match="no replay window"):
        replay.windows_from_runs([], 10.0)


def test_missing_wind_direction_interpolated_across_north() -> None:
    """Wind from 350 deg, then a missing sample, then from 10 deg: the gap is from north
    (0 deg), the short way round as preprocess.resample_uniform does for angles."""
    t = np.arange(3.0)
    run = _run("a", 3, wind_speed_mps=t * 0 + 8.0, wind_from_deg=[350.0, np.nan, 10.0])
    win = replay.windows_from_runs([run], None, use_wind=True)
    middle = np.degrees(win.env[0, 1, 3]) % 360.0
    assert min(middle, 360.0 - middle) < 1e-6


@pytest.mark.parametrize("ship", ["cargo", "bulk_carrier", "kvlcc2"])
def test_replay_equals_the_engine_step_with_actuators_at_rest(ship: str) -> None:
    """Rudder and propeller held at constant values and the engine's steering gear and
    propeller states already there (their lags then have nothing to do): the replay equals
    ``base.step`` of the engine, step by step with the same sub-steps, for a steady turn;
    the engine wraps its heading, the replay does not."""
    spec = load_ship(ship)
    family = base.families()[spec["model"]]
    params = family.build([spec])
    act = base.Actuators.from_specs([spec])
    speed = spec["service_speed_kn"] * 1852 / 3600
    rudder, rps = np.radians(20.0), 0.8 * float(spec["actuators"]["rps_max"])
    n, dt = 60, 2.0
    x = np.zeros((8, 1))
    x[:, 0] = [50.0, -20.0, np.radians(350.0), speed, 0.0, 0.0, rudder, rps]
    win = replay.Windows(x.copy(), np.tile([rudder, rps], (1, n, 1)), np.zeros((1, n, 4)),
                         np.array([dt]), np.array([n]), np.full((1, n, 6), np.nan),
                         np.zeros(1, int), np.zeros(1), ("w",))
    models = replay.model_rows([spec])
    sub = int(replay.substeps(models, win)[0, 0])
    out, diverged = replay.simulate(models, win)
    assert not diverged.any()
    engine = [x[:6, 0].copy()]
    for _ in range(n - 1):
        x = base.step(family, params, act, x, np.array([rudder]), np.array([rps]), base.Env(),
                      dt, substeps=sub)
        engine.append(x[:6, 0].copy())
    engine = np.array(engine)
    engine[:, 2] = np.unwrap(engine[:, 2])
    np.testing.assert_allclose(out[0, 0], engine, rtol=1e-9, atol=1e-8)
    assert out[0, 0, -1, 2] - out[0, 0, 0, 2] > np.radians(20.0)  # it did turn (past north)


def test_windows_at_two_seconds_with_a_horizon_not_a_multiple_of_the_interval() -> None:
    """31 s horizon at 2 s sampling: round(31 / 2) = 16 intervals, 17 samples per window; a
    61-sample run gives windows at samples 0, 16, 32 (17, 17, 17) and a last piece of 13
    samples (12 intervals >= 8, half a horizon): kept; targets hold the smoothed outputs."""
    run = _run("r", 61, dt=2.0)
    win = replay.windows_from_runs([run], 31.0)
    np.testing.assert_array_equal(win.n_samples, [17, 17, 17, 13])
    np.testing.assert_array_equal(win.t0_s, [0.0, 32.0, 64.0, 96.0])
    np.testing.assert_array_equal(win.x0[0], 10 * win.t0_s)
    for i in range(win.w):
        s = round(win.t0_s[i] / 2.0)
        c = win.n_samples[i]
        np.testing.assert_array_equal(win.target[i, :c, 0], run.smooth["north_m"][s:s + c])
        assert np.all(np.isnan(win.target[i, c:]))
    np.testing.assert_array_equal(win.dt_s, 2.0)


def test_no_runs_give_no_window_and_a_short_run_is_one_window() -> None:
    """No runs: the documented DataError; two samples and a horizon longer than the run: the
    whole run is one window (the first piece is always kept)."""
    for horizon in (10.0, None):
        with pytest.raises(DataError, match="no replay window"):
            replay.windows_from_runs([], horizon)
    win = replay.windows_from_runs([_run("two", 2)], 100.0)
    assert win.w == 1 and win.n_samples[0] == 2


def test_replay_is_linear_interpolation_of_the_inputs_not_a_hold() -> None:
    """A rudder ramp sampled every 2 s equals the same ramp sampled every 1 s (first-order hold
    reproduces a linear input exactly); both use 0.5 s RK4 steps, so the 1 s replay's every
    other sample is the 2 s replay to rounding."""
    spec = dict(load_ship("cargo"), integration={"max_dt_s": 0.5})
    speed = spec["service_speed_kn"] * 1852 / 3600
    out = []
    for dt, n in ((2.0, 31), (1.0, 61)):
        t = dt * np.arange(n)
        inputs = np.stack([np.radians(0.5) * t, np.full(n, 1.5)], axis=-1)[None]
        x0 = np.zeros((8, 1))
        x0[3] = speed
        win = replay.Windows(x0, inputs, np.zeros((1, n, 4)), np.array([dt]), np.array([n]),
                             np.full((1, n, 6), np.nan), np.zeros(1, int), np.zeros(1), ("w",))
        out.append(replay.simulate(replay.model_rows([spec]), win)[0][0, 0])
    np.testing.assert_allclose(out[0], out[1][::2], rtol=1e-9, atol=1e-9)
