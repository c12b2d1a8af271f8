import math

import numpy as np
import pytest

from tests.sensors import Z, assert_bound
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank
from trafficsim.sensors import waves
from trafficsim.sensors.waves import WAVE_NORMAL_DIMS

SIGMAS = {"heading_sigma_deg": 2.0, "surge_sigma_m": 1.5, "sway_sigma_m": 0.8}
SIGMA_SI = np.array([math.radians(2.0), 1.5, 0.8])


def expm_series(a: np.ndarray) -> np.ndarray:
    """Reference matrix exponential: Taylor series with scaling and squaring."""
    squarings = max(0, math.ceil(math.log2(max(np.abs(a).sum(), 1e-300))) + 4)
    b = a / 2.0 ** squarings
    out, term = np.eye(2), np.eye(2)
    for k in range(1, 25):
        term = term @ b / k
        out = out + term
    for _ in range(squarings):
        out = out @ out
    return out


@pytest.mark.parametrize("zeta", [0.05, 0.1, 0.7, 1.0, 2.5])
@pytest.mark.parametrize("t", [0.01, 0.5, 3.0, 20.0])
def test_closed_form_transition_is_the_matrix_exponential(zeta, t):
    w0 = 0.9
    a = np.array([[0.0, 1.0], [-w0 * w0, -2.0 * zeta * w0]])
    phi = np.array(waves.transition(np.array([w0]), np.array([zeta]), t))[:, 0].reshape(2, 2)
    np.testing.assert_allclose(phi, expm_series(a * t), rtol=1e-10, atol=1e-13)


def test_transition_reproduces_the_seed_004_correlation_functions():
    # K(t)/D = exp(-mu t) (cos bt + mu/b sin bt) [seed 004, eq 15] and the derivative's
    # K'(t)/(D (mu^2 + b^2)) = exp(-mu t) (cos bt - mu/b sin bt) [seed 004, eq 24]
    w0, zeta = 0.6, 0.15
    mu = zeta * w0
    beta = math.sqrt(w0 * w0 - mu * mu)
    for t in np.linspace(0.0, 40.0, 81):
        f11, _, _, f22 = (v[0] for v in waves.transition(np.array([w0]), np.array([zeta]), t))
        e = math.exp(-mu * t)
        assert f11 == pytest.approx(e * (math.cos(beta * t) + mu / beta * math.sin(beta * t)),
                                    abs=1e-13)
        assert f22 == pytest.approx(e * (math.cos(beta * t) - mu / beta * math.sin(beta * t)),
                                    abs=1e-13)


@pytest.mark.parametrize("dt", [0.01, 0.5, 5.0])
def test_process_noise_is_the_integral_of_the_driven_response(dt):
    # Q = int_0^dt Phi(s) b b^T Phi(s)^T ds with b = (0, 1)
    params = waves.build([{"peak_period_s": 7.0, "damping_ratio": 0.12}], dt)
    s = np.linspace(0.0, dt, 4001)
    f12, f22 = [], []
    for si in s:
        _, a12, _, a22 = waves.transition(params.omega0, params.zeta, si)
        f12.append(a12[0])
        f22.append(a22[0])
    f12, f22 = np.array(f12), np.array(f22)

    def integral(f):  # trapezoidal rule (np.trapezoid needs numpy 2)
        return float(np.sum((f[1:] + f[:-1]) * np.diff(s)) / 2.0)

    q = np.array([[integral(f12 * f12), integral(f12 * f22)],
                  [integral(f12 * f22), integral(f22 * f22)]])
    lo = np.array([[params.l11[0, 0], 0.0], [params.l21[0, 0], params.l22[0, 0]]])
    np.testing.assert_allclose(lo @ lo.T, q, rtol=1e-5, atol=1e-12 * dt)


def _simulate(params, state, steps, rng, keep=False):
    n = params.omega0.shape[0]
    out = []
    for _ in range(steps):
        state = waves.step(params, state, rng.standard_normal((n, WAVE_NORMAL_DIMS)))
        if keep:
            out.append(waves.outputs(params, state))
    return state, (np.stack(out) if keep else None)


@pytest.mark.parametrize("form", ["bandpass", "lowpass"])
@pytest.mark.parametrize("dt", [0.05, 0.5, 2.0, 10.0])
def test_stationary_variance_is_right_at_any_dt(form, dt):
    n = 10_000
    cfg = {**SIGMAS, "peak_period_s": 8.0, "damping_ratio": 0.1, "form": form}
    params = waves.build([cfg] * n, dt)
    rng = np.random.default_rng(7)
    # from rest: after 6 decay times (e^-12 left) the variance must have grown to sigma^2 exactly
    state = waves.WaveState(z1=np.zeros((n, 3)), z2=np.zeros((n, 3)))
    decay = 1.0 / (0.1 * 2.0 * math.pi / 8.0)
    state, _ = _simulate(params, state, math.ceil(6.0 * decay / dt), rng)
    _, ys = _simulate(params, state, 2, rng, keep=True)
    for y in ys:
        tol = Z * SIGMA_SI ** 2 * math.sqrt(2.0 / n)
        assert np.all(np.abs(y.var(axis=0) - SIGMA_SI ** 2) < tol), (y.var(axis=0), SIGMA_SI ** 2)
        assert np.all(np.abs(y.mean(axis=0)) < Z * SIGMA_SI / math.sqrt(n))
    # the stationary start has the same variance
    start = waves.init(params, rng.standard_normal((n, WAVE_NORMAL_DIMS)))
    y0 = waves.outputs(params, start)
    assert np.all(np.abs(y0.var(axis=0) - SIGMA_SI ** 2) < Z * SIGMA_SI ** 2 * math.sqrt(2 / n))


def test_autocorrelation_follows_seed_004_eq_15_for_the_lowpass_form():
    n, dt = 20_000, 0.5
    params = waves.build([{**SIGMAS, "form": "lowpass", "peak_period_s": 6.0,
                           "damping_ratio": 0.2}] * n, dt)
    rng = np.random.default_rng(8)
    state = waves.init(params, rng.standard_normal((n, WAVE_NORMAL_DIMS)))
    y0 = waves.outputs(params, state)[:, 1]
    _, ys = _simulate(params, state, 12, rng, keep=True)
    mu = 0.2 * 2.0 * math.pi / 6.0
    beta = math.sqrt((2.0 * math.pi / 6.0) ** 2 - mu * mu)
    for k in (2, 4, 8, 12):
        t = k * dt
        expected = math.exp(-mu * t) * (math.cos(beta * t) + mu / beta * math.sin(beta * t))
        rho = np.corrcoef(y0, ys[k - 1][:, 1])[0, 1]
        assert abs(rho - expected) < Z / math.sqrt(n), (k, rho, expected)


def _averaged_spectrum(form, zeta, n_ships=512, steps=4096, dt=0.5, seed=9):
    params = waves.build([{**SIGMAS, "form": form, "peak_period_s": 8.0,
                           "damping_ratio": zeta}] * n_ships, dt)
    rng = np.random.default_rng(seed)
    state = waves.init(params, rng.standard_normal((n_ships, WAVE_NORMAL_DIMS)))
    _, ys = _simulate(params, state, steps, rng, keep=True)
    y = ys[:, :, 2]  # sway channel, (steps, ships)
    # two-sided periodogram, var = (1/2pi) int P domega
    p = dt / steps * np.abs(np.fft.rfft(y, axis=0)) ** 2
    p = p.mean(axis=1)
    width = 21
    smooth = np.convolve(p, np.ones(width) / width, mode="same")
    omega = 2.0 * np.pi * np.fft.rfftfreq(steps, dt)
    # analytic spectrum of the sampled process (aliases folded in)
    w0, c = params.omega0[0], params.gain[0, 2]
    num_pow = 2 if form == "bandpass" else 0

    def s_cont(w):
        return c * c * w ** num_pow / ((w0 * w0 - w * w) ** 2 + (2 * zeta * w0 * w) ** 2)

    s_alias = sum(s_cont(omega + 2.0 * np.pi * m / dt) for m in range(-200, 201))
    # the same moving average on both sides: compare like with like at the peak
    s_smooth = np.convolve(s_alias, np.ones(width) / width, mode="same")
    return params, omega, smooth, s_alias, s_smooth, width


def test_bandpass_spectrum_peaks_at_omega0_with_the_analytic_level():
    params, omega, smooth, s_alias, s_smooth, width = _averaged_spectrum("bandpass", 0.1)
    w0 = params.omega0[0]
    inner = slice(width, len(omega) - width)
    peak = omega[inner][np.argmax(smooth[inner])]
    assert waves.peak_frequency(params)[0] == w0
    assert abs(peak - w0) < 0.03 * w0, (peak, w0)
    # peak level c^2 / (4 lam^2 w0^2) and the shape around it
    c = params.gain[0, 2]
    assert s_alias[np.argmin(np.abs(omega - w0))] == pytest.approx(
        c * c / (4 * 0.01 * w0 * w0), rel=0.01)
    band = (omega > 0.4 * w0) & (omega < 2.5 * w0)
    np.testing.assert_allclose(smooth[band], s_smooth[band], rtol=0.08)


def test_lowpass_spectrum_matches_the_analytic_shape_and_peak():
    params, omega, smooth, _, s_smooth, _ = _averaged_spectrum("lowpass", 0.3)
    w0 = params.omega0[0]
    band = (omega > 0.05 * w0) & (omega < 2.5 * w0)
    np.testing.assert_allclose(smooth[band], s_smooth[band], rtol=0.08)
    # |h(jw)|^2 of the lowpass form peaks at w0 sqrt(1 - 2 lam^2), not at w0
    w = np.linspace(0.5 * w0, 1.5 * w0, 200_001)
    h2 = 1.0 / ((w0 * w0 - w * w) ** 2 + (0.6 * w0 * w) ** 2)
    assert waves.peak_frequency(params)[0] == pytest.approx(w[np.argmax(h2)], abs=1e-5)
    assert waves.peak_frequency(params)[0] == pytest.approx(w0 * math.sqrt(0.82))


def test_offsets_are_the_outputs_rotated_into_the_earth_frame():
    params = waves.build([SIGMAS] * 2, 1.0)
    state = waves.init(params, np.random.default_rng(1).standard_normal((2, WAVE_NORMAL_DIMS)))
    y = waves.outputs(params, state)
    np.testing.assert_array_equal(waves.heading_offset(params, state), y[:, 0])
    ne = waves.position_offset(params, state, np.array([0.0, math.pi / 2.0]))
    # heading north: surge -> north, sway -> east; heading east: surge -> east, sway -> south
    np.testing.assert_allclose(ne[:, 0], [y[0, 1], y[0, 2]], atol=1e-15)
    np.testing.assert_allclose(ne[:, 1], [-y[1, 2], y[1, 1]], atol=1e-15)


def test_calm_default_gives_no_motion():
    params = waves.build([{}] * 4, 0.5)
    rng = np.random.default_rng(2)
    state = waves.init(params, rng.standard_normal((4, WAVE_NORMAL_DIMS)))
    state, ys = _simulate(params, state, 5, rng, keep=True)
    assert np.all(ys == 0.0)


def test_config_errors_are_reported():
    with pytest.raises(InputError, match="> 0"):
        waves.build([{"damping_ratio": 0.0}], 1.0)
    with pytest.raises(InputError, match="expected one of"):
        waves.build([{"form": "jonswap"}], 1.0)
    with pytest.raises(InputError, match="dt"):
        waves.build([{}], 0.0)


def test_same_draws_give_same_motion_and_ships_are_independent():
    configs = [SIGMAS, {**SIGMAS, "form": "lowpass", "peak_period_s": 5.0},
               {"heading_sigma_deg": 1.0, "damping_ratio": 1.0}]

    def go(order):
        o = list(order)
        bank = NoiseBank(6, [4] * 3, o, "waves", WAVE_NORMAL_DIMS)
        params = waves.build([configs[i] for i in o], 0.25)
        state = waves.init(params, bank.next())
        out = []
        for _ in range(20):
            state = waves.step(params, state, bank.next())
            out.append(waves.outputs(params, state))
        return np.stack(out)

    a = go([0, 1, 2])
    np.testing.assert_array_equal(a, go([0, 1, 2]))
    np.testing.assert_array_equal(go([2, 0, 1]), a[:, [2, 0, 1]])


def _phi(w0, zeta, t):
    return np.array(waves.transition(np.array([w0]), np.array([zeta]), t))[:, 0].reshape(2, 2)


@pytest.mark.parametrize("zeta", [0.05, 0.5, 1.0, 1.0 + 1e-9, 3.0])
def test_transition_is_a_semigroup(zeta):
    """``expm(A (t1 + t2)) = expm(A t1) expm(A t2)`` and ``expm(0) = I`` in every damping
    regime (including the switch between the branches at critical damping)."""
    w0 = 1.3
    np.testing.assert_allclose(_phi(w0, zeta, 0.0), np.eye(2), atol=1e-15)
    for t1, t2 in ((0.3, 1.1), (2.0, 5.0), (0.01, 7.3)):
        np.testing.assert_allclose(_phi(w0, zeta, t1 + t2), _phi(w0, zeta, t1) @ _phi(w0, zeta, t2),
                                   rtol=1e-11, atol=1e-14)


def test_overdamped_transition_over_a_long_step_is_finite():
    """Over-damped, w0 = 2 pi / 8, lam = 10, t = 100 s: the slow root ``mu - sqrt(mu^2 - w0^2)``
    = 0.0394 1/s leaves ``phi11 = (e^-(mu-r)t (1 + mu/r) + e^-(mu+r)t (1 - mu/r)) / 2`` =
    0.0196, which the module's 'exact for any dt' discretisation must reproduce."""
    w0, zeta, t = 2 * math.pi / 8.0, 10.0, 100.0
    mu = zeta * w0
    r = math.sqrt(mu * mu - w0 * w0)
    slow, fast = math.exp(-(mu - r) * t), math.exp(-(mu + r) * t)
    want11 = 0.5 * (slow * (1 + mu / r) + fast * (1 - mu / r))
    want12 = 0.5 * (slow - fast) / r
    with np.errstate(all="ignore"):
        phi = _phi(w0, zeta, t)
    assert phi[0, 0] == pytest.approx(want11, rel=1e-9)
    assert phi[0, 1] == pytest.approx(want12, rel=1e-9)


@pytest.mark.parametrize("dt", [0.02, 1.0, 30.0])
@pytest.mark.parametrize("zeta", [0.1, 0.5, 1.0])
def test_discrete_lyapunov_identity(dt, zeta):
    """Stationary covariance is kept exactly: ``Phi P Phi^T + L L^T = P`` with ``P =
    diag(1/(4 lam w0^3), 1/(4 lam w0))``; ``L`` is lower triangular with a non-negative
    diagonal."""
    params = waves.build([{"peak_period_s": 9.0, "damping_ratio": zeta}], dt)
    w0 = 2 * math.pi / 9.0
    P = np.diag([1 / (4 * zeta * w0**3), 1 / (4 * zeta * w0)])
    np.testing.assert_allclose(np.diag(P), [params.p11[0, 0], params.p22[0, 0]], rtol=1e-14)
    phi = np.array([[params.phi11[0, 0], params.phi12[0, 0]],
                    [params.phi21[0, 0], params.phi22[0, 0]]])
    lo = np.array([[params.l11[0, 0], 0.0], [params.l21[0, 0], params.l22[0, 0]]])
    assert lo[0, 0] >= 0.0 and lo[1, 1] >= 0.0
    np.testing.assert_allclose(phi @ P @ phi.T + lo @ lo.T, P, rtol=1e-10, atol=1e-12 * P.max())


def test_gains_are_seed_004_eq_16_and_the_bandpass_counterpart():
    """Lowpass ``c = 2 b sqrt(D mu)`` [seed 004, eq 16] with ``b = w0``, ``mu = lam w0``,
    ``D = sigma^2``; bandpass ``c = sigma sqrt(4 lam w0)`` (module docstring)."""
    cfg = {**SIGMAS, "peak_period_s": 6.5, "damping_ratio": 0.17}
    low = waves.build([{**cfg, "form": "lowpass"}], 0.5)
    band = waves.build([cfg], 0.5)
    b = 2 * math.pi / 6.5
    mu = 0.17 * b
    np.testing.assert_allclose(low.gain[0], 2 * b * np.sqrt(SIGMA_SI**2 * mu), rtol=1e-13)
    np.testing.assert_allclose(band.gain[0], SIGMA_SI * math.sqrt(4 * 0.17 * b), rtol=1e-13)


def test_bandpass_autocorrelation_is_the_derivative_process():
    """Bandpass output ``z2``: correlation ``exp(-mu t) (cos bt - mu/b sin bt)`` (module
    docstring; derivative of the seed 004 eq 15 process, eq 24), negative at half a period."""
    n, dt = 20_000, 0.5
    params = waves.build([{**SIGMAS, "peak_period_s": 6.0, "damping_ratio": 0.2}] * n, dt)
    rng = np.random.default_rng(18)
    state = waves.init(params, rng.standard_normal((n, WAVE_NORMAL_DIMS)))
    y0 = waves.outputs(params, state)[:, 0]
    _, ys = _simulate(params, state, 8, rng, keep=True)
    w0 = 2 * math.pi / 6.0
    mu = 0.2 * w0
    beta = math.sqrt(w0 * w0 - mu * mu)
    for k in (1, 3, 6, 8):
        t = k * dt
        expected = math.exp(-mu * t) * (math.cos(beta * t) - mu / beta * math.sin(beta * t))
        rho = np.corrcoef(y0, ys[k - 1][:, 0])[0, 1]
        assert abs(rho - expected) < Z / math.sqrt(n), (k, rho, expected)


def test_vectorised_step_matches_a_per_ship_matrix_loop():
    """Ships with different periods, damping and forms: the array step equals, ship by ship
    and channel by channel, ``z <- Phi z + L e`` with ``Phi`` the series matrix exponential
    and ``L`` the Cholesky factor of ``P - Phi P Phi^T``."""
    rng = np.random.default_rng(19)
    configs = [{**SIGMAS, "peak_period_s": float(rng.uniform(3, 15)),
                "damping_ratio": float(rng.choice([0.05, 0.3, 0.8, 1.0])),
                "form": "lowpass" if i % 2 else "bandpass"} for i in range(8)]
    dt = 0.4
    params = waves.build(configs, dt)
    n = len(configs)
    state = waves.init(params, rng.standard_normal((n, WAVE_NORMAL_DIMS)))
    z = np.stack([state.z1, state.z2], axis=-1)  # (n, 3, 2)
    mats = []
    for cfg in configs:
        w0, lam = 2 * math.pi / cfg["peak_period_s"], cfg["damping_ratio"]
        phi = expm_series(np.array([[0.0, 1.0], [-w0 * w0, -2 * lam * w0]]) * dt)
        P = np.diag([1 / (4 * lam * w0**3), 1 / (4 * lam * w0)])
        mats.append((phi, np.linalg.cholesky(P - phi @ P @ phi.T), P))
    for _ in range(25):
        e = rng.standard_normal((n, WAVE_NORMAL_DIMS))
        state = waves.step(params, state, e)
        out = waves.outputs(params, state)
        for i, (cfg, (phi, lo, P)) in enumerate(zip(configs, mats, strict=True)):
            for ch in range(3):
                z[i, ch] = phi @ z[i, ch] + lo @ e[i, 2 * ch:2 * ch + 2]
                row = 1 if cfg["form"] == "bandpass" else 0
                want = SIGMA_SI[ch] * z[i, ch, row] / math.sqrt(P[row, row])
                assert out[i, ch] == pytest.approx(want, rel=1e-8, abs=1e-12)


def test_position_offset_keeps_length_and_is_periodic_in_heading():
    params = waves.build([SIGMAS] * 50, 1.0)
    rng = np.random.default_rng(4)
    state = waves.init(params, rng.standard_normal((50, WAVE_NORMAL_DIMS)))
    y = waves.outputs(params, state)
    psi = rng.uniform(0, 2 * math.pi, 50)
    ne = waves.position_offset(params, state, psi)
    np.testing.assert_allclose(np.hypot(*ne), np.hypot(y[:, 1], y[:, 2]), rtol=1e-12)
    np.testing.assert_allclose(waves.position_offset(params, state, psi + 2 * math.pi), ne,
                               atol=1e-12)


@pytest.mark.parametrize(("cfg", "key"), [
    ({"peak_period_s": 0.0}, "waves[1].peak_period_s"),
    ({"peak_period_s": -8.0}, "waves[1].peak_period_s"),
    ({"damping_ratio": -0.1}, "waves[1].damping_ratio"),
    ({"heading_sigma_deg": -1.0}, "waves[1].heading_sigma_deg"),
    ({"surge_sigma_m": math.inf}, "waves[1].surge_sigma_m"),
    ({"sway_sigma_m": "big"}, "waves[1].sway_sigma_m"),
    ({"form": "highpass"}, "waves[1].form"),
    ({"hs_m": 2.0}, "waves[1]"),
])
def test_config_errors_name_the_ship_and_key(cfg, key):
    with pytest.raises(InputError) as err:
        waves.build([{}, cfg], 1.0)
    assert err.value.key == key


@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("heading_sigma_deg", 30.0, 30.5, "must be <= 30, got 30.5"),
    ("surge_sigma_m", 50.0, 51.0, "must be <= 50, got 51.0"),
    ("sway_sigma_m", 50.0, 50.5, "must be <= 50, got 50.5"),
    ("peak_period_s", 0.5, 0.49, "must be >= 0.5, got 0.49"),
    ("peak_period_s", 60.0, 61.0, "must be <= 60, got 61.0"),
    ("damping_ratio", 1.0, 1.01, "must be <= 1, got 1.01"),
])
def test_physical_upper_bounds(key, inside, beyond, message):
    """Physical bounds (module docstring; the filter itself needs only positive period and
    damping): just inside is accepted, beyond is refused naming the ship and key."""
    assert_bound(lambda c: waves.build(c, 1.0), "waves", key, inside, beyond, message)


@pytest.mark.parametrize("zeta", [0.05, 0.3, 0.69, 0.72, 1.0])
def test_peak_frequency_is_the_argmax_of_the_transfer_function(zeta):
    """``|h(jw)|^2`` on a fine grid from 0: bandpass ``w^2 / D(w)`` peaks at w0 for any damping;
    lowpass ``1 / D(w)`` at ``w0 sqrt(1 - 2 lam^2)``, at 0 once ``lam >= 1/sqrt 2``
    (``D(w) = (w0^2 - w^2)^2 + 4 lam^2 w0^2 w^2``)."""
    params = waves.build([{"peak_period_s": 10.0, "damping_ratio": zeta},
                          {"peak_period_s": 10.0, "damping_ratio": zeta, "form": "lowpass"}], 1.0)
    w0 = 2 * math.pi / 10.0
    w = np.linspace(0.0, 3.0 * w0, 300_001)
    den = (w0 * w0 - w * w) ** 2 + 4 * zeta**2 * w0 * w0 * w * w
    peaks = waves.peak_frequency(params)
    assert peaks[0] == pytest.approx(w[np.argmax(w * w / den)], abs=2e-5)
    assert peaks[1] == pytest.approx(w[np.argmax(1.0 / den)], abs=2e-5)
