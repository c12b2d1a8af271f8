import math

import numpy as np
import pytest

from tests.sensors import Z, assert_bound, assert_mean, assert_std, random_headings
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank
from trafficsim.sensors import compass, wrap_2pi, wrap_pi
from trafficsim.sensors.compass import COMPASS_NORMAL_DIMS

N = 20_000
DEG = math.radians(1.0)


def run(configs, psi, steps, dt=1.0, seed=2, wave=None):
    """Readings ``(steps, n)`` and errors wrapped to [-pi, pi)."""
    rng = np.random.default_rng(seed)
    n = len(configs)
    params = compass.build(configs, dt)
    state = compass.init(params, rng.standard_normal((n, COMPASS_NORMAL_DIMS)))
    out = []
    for _ in range(steps):
        state, reading = compass.step(params, state, psi,
                                      rng.standard_normal((n, COMPASS_NORMAL_DIMS)), wave)
        out.append(reading)
    readings = np.stack(out)
    return params, readings, wrap_pi(readings - psi)


def test_gyro_default_is_one_degree_white_noise():
    # random heading error of a gyro about 1 deg [seed 002, sec 2.9]
    psi = random_headings(N)
    _, _, err = run([{}] * N, psi, steps=3)
    assert_mean(err, 0.0, DEG)
    assert_std(err, DEG)
    assert abs(np.corrcoef(err[0], err[1])[0, 1]) < Z / math.sqrt(N)


def test_magnetic_default_variance_is_the_catfish_fluxgate_value():
    # variance of psi 0.0054 rad^2, random error < 4 deg after correction [seed 002, sec 3.4]
    psi = random_headings(N, seed=3)
    params, _, err = run([{"kind": "magnetic"}] * N, psi, steps=3)
    assert params.sigma_rad[0] ** 2 == pytest.approx(0.0054)
    var = err.var()
    assert abs(var - 0.0054) < Z * 0.0054 * math.sqrt(2.0 / err.size), var
    assert math.degrees(math.sqrt(var)) == pytest.approx(4.2, abs=0.1)


def test_bias_and_gauss_markov_drift_statistics():
    cfg = {"sigma_deg": 0.3, "bias_deg": 2.0, "drift_sigma_deg": 0.5, "drift_tau_s": 120.0}
    dt = 2.0
    psi = random_headings(N, seed=4)
    _, _, err = run([cfg] * N, psi, steps=6, dt=dt)
    total = math.hypot(0.3, 0.5) * DEG
    assert_mean(err, 2.0 * DEG, total)
    for k in (0, 5):
        assert_std(err[k], total)
    # lag covariance comes from the drift only: a^lag sigma_d^2
    for lag in (1, 5):
        cov = np.mean((err[0] - err[0].mean()) * (err[lag] - err[lag].mean()))
        expected = math.exp(-lag * dt / 120.0) * (0.5 * DEG) ** 2
        assert abs(cov - expected) < Z * total ** 2 / math.sqrt(N), (cov, expected)


def test_deviation_curve_is_exact():
    coef = [1.0, 2.0, -3.0, 0.5, -0.25]  # A, B, C, D, E in degrees
    cfg = {"kind": "magnetic", "sigma_deg": 0.0, "deviation_deg": coef}
    psi = np.radians(np.arange(0.0, 360.0, 1.0))
    _, _, err = run([cfg] * psi.size, psi, steps=1)
    a, b, c, d, e = np.radians(coef)
    expected = a + b * np.sin(psi) + c * np.cos(psi) + d * np.sin(2 * psi) + e * np.cos(2 * psi)
    np.testing.assert_allclose(err[0], expected, atol=1e-13)
    # by hand: psi 0 -> A + C + E = -2.25 deg; 90 -> A + B - E = 3.25; 45 -> A + (B + C)/sqrt2 + D
    np.testing.assert_allclose(np.degrees(err[0, [0, 90, 45]]),
                               [-2.25, 3.25, 1.0 - 1.0 / math.sqrt(2.0) + 0.5], atol=1e-11)


def test_readings_are_wrapped_to_zero_two_pi():
    cfg = {"sigma_deg": 0.0, "bias_deg": 1.0}
    psi = np.array([2 * math.pi - 0.5 * DEG, -0.1, 7.0, 0.0, -4 * math.pi])
    _, readings, _ = run([cfg] * psi.size, psi, steps=1)
    np.testing.assert_allclose(readings[0], [0.5 * DEG, 2 * math.pi - 0.1 + DEG,
                                             7.0 - 2 * math.pi + DEG, DEG, DEG], atol=1e-12)
    _, readings, _ = run([{"sigma_deg": 30.0}] * N, random_headings(N, 5), steps=2)
    assert np.all((readings >= 0.0) & (readings < 2 * math.pi))
    # np.mod alone returns 2 pi for a tiny negative angle
    assert wrap_2pi(np.array([-1e-17]))[0] == 0.0
    assert wrap_pi(np.array([math.pi]))[0] == -math.pi


def test_wave_yaw_is_added_to_the_reading():
    cfg = {"sigma_deg": 0.0}
    psi = np.array([0.0, 1.0])
    _, readings, _ = run([cfg] * 2, psi, steps=1, wave=np.array([-0.01, 0.02]))
    np.testing.assert_allclose(readings[0], [2 * math.pi - 0.01, 1.02], atol=1e-12)


def test_config_errors_are_reported():
    with pytest.raises(InputError, match="no deviation"):
        compass.build([{"deviation_deg": [0, 0, 0, 0, 1]}], 1.0)
    with pytest.raises(InputError, match="5 finite"):
        compass.build([{"kind": "magnetic", "deviation_deg": [1, 2]}], 1.0)
    with pytest.raises(InputError, match="expected one of"):
        compass.build([{"kind": "fluxgate"}], 1.0)
    with pytest.raises(InputError, match="unknown"):
        compass.build([{"sigma_rad": 0.1}], 1.0)


def test_same_draws_give_same_readings_and_ships_are_independent():
    configs = [{"kind": "magnetic", "deviation_deg": [1, 2, 3, 4, 5]},
               {"drift_sigma_deg": 2.0, "drift_tau_s": 30.0}, {}]
    psi = np.array([0.3, 3.0, 6.0])

    def go(order):
        bank = NoiseBank(3, [5] * 3, list(order), "compass", COMPASS_NORMAL_DIMS)
        params = compass.build([configs[i] for i in order], 0.5)
        state = compass.init(params, bank.next())
        out = []
        for _ in range(30):
            state, reading = compass.step(params, state, psi[list(order)], bank.next())
            out.append(reading)
        return np.stack(out)

    a = go([0, 1, 2])
    np.testing.assert_array_equal(a, go([0, 1, 2]))
    np.testing.assert_array_equal(go([1, 2, 0]), a[:, [1, 2, 0]])


def test_vectorised_step_matches_a_scalar_compass_loop():
    """Mixed gyros and magnetic compasses with bias, drift, deviation and wave yaw, 40 steps:
    the array code equals a per-ship loop of the docstring's formula."""
    rng = np.random.default_rng(11)
    n, dt = 10, 0.7
    configs = []
    for i in range(n):
        cfg = {"kind": "magnetic" if i % 2 else "gyro", "bias_deg": float(rng.normal(0, 2)),
               "drift_sigma_deg": float(rng.choice([0.0, 1.5])), "drift_tau_s": 90.0}
        if i % 3:
            cfg["sigma_deg"] = float(rng.uniform(0.0, 3.0))
        if i % 2 and i % 5:
            cfg["deviation_deg"] = [float(v) for v in rng.normal(0, 3, 5)]
        configs.append(cfg)
    params = compass.build(configs, dt)
    z0 = rng.standard_normal((n, COMPASS_NORMAL_DIMS))
    state = compass.init(params, z0)
    drift = [configs[i]["drift_sigma_deg"] * DEG * z0[i, 1] for i in range(n)]
    psi = rng.uniform(-7.0, 7.0, n)
    a = math.exp(-dt / 90.0)
    for _ in range(40):
        psi = psi + rng.normal(0.0, 0.2, n)
        z = rng.standard_normal((n, COMPASS_NORMAL_DIMS))
        wave = rng.normal(0.0, 0.01, n)
        state, reading = compass.step(params, state, psi, z, wave)
        for i, cfg in enumerate(configs):
            sd = cfg.get("sigma_deg", 1.0 if cfg["kind"] == "gyro"
                         else math.degrees(math.sqrt(0.0054)))
            drift[i] = a * drift[i] + cfg["drift_sigma_deg"] * DEG * math.sqrt(1 - a * a) * z[i, 1]
            h = psi[i] + wave[i]
            A, B, C, D, E = np.radians(cfg.get("deviation_deg", [0.0] * 5))
            dev = (A + B * math.sin(h) + C * math.cos(h) + D * math.sin(2 * h)
                   + E * math.cos(2 * h))
            want = (h + cfg["bias_deg"] * DEG + drift[i] + sd * DEG * z[i, 0] + dev) % (2 * math.pi)
            diff = (reading[i] - want + math.pi) % (2 * math.pi) - math.pi
            assert abs(diff) < 1e-12, (i, reading[i], want)
        assert np.all((reading >= 0.0) & (reading < 2 * math.pi))


def test_deviation_coefficients_recovered_by_least_squares():
    """Swinging the compass through all headings and fitting A + B sin + C cos + D sin 2 +
    E cos 2 to its errors returns the configured coefficients (seed 002 fits its fluxgate
    compass the same way, sec 3.4)."""
    coef = np.array([0.8, -4.0, 2.5, 1.2, -0.6])
    params = compass.build([{"kind": "magnetic", "sigma_deg": 0.0, "deviation_deg":
                             coef.tolist()}], 1.0)
    psi = np.radians(np.arange(0.0, 360.0, 7.5))
    errors = []
    for p in psi:
        state = compass.init(params, np.zeros((1, 2)))
        _, r = compass.step(params, state, np.array([p]), np.zeros((1, 2)))
        errors.append(wrap_pi(r - p)[0])
    basis = np.stack([np.ones_like(psi), np.sin(psi), np.cos(psi), np.sin(2 * psi),
                      np.cos(2 * psi)], axis=1)
    fit, *_ = np.linalg.lstsq(basis, np.degrees(errors), rcond=None)
    np.testing.assert_allclose(fit, coef, atol=1e-9)
    # the deviation function itself is periodic in heading
    one = compass.deviation(params, np.array([0.4]))
    np.testing.assert_allclose(compass.deviation(params, np.array([0.4 + 2 * math.pi])), one,
                               atol=1e-14)
    np.testing.assert_allclose(compass.deviation(params, np.array([0.4 - 6 * math.pi])), one,
                               atol=1e-13)


def test_reading_near_north_wraps_both_ways():
    """True heading just west of north with a positive error reads just east of north, and a
    heading just east of north with a negative error reads just below 2 pi."""
    cfg = [{"sigma_deg": 0.0, "bias_deg": 0.5}, {"sigma_deg": 0.0, "bias_deg": -0.5}]
    params = compass.build(cfg, 1.0)
    state = compass.init(params, np.zeros((2, 2)))
    psi = np.array([2 * math.pi - 0.2 * DEG, 0.2 * DEG])
    _, r = compass.step(params, state, psi, np.zeros((2, 2)))
    np.testing.assert_allclose(r, [0.3 * DEG, 2 * math.pi - 0.3 * DEG], atol=1e-13)


def test_drift_is_white_when_the_step_is_long():
    """dt >> tau: the drift loses its memory (a = exp(-dt/tau) -> 0) and keeps its sd."""
    cfg = {"sigma_deg": 0.0, "drift_sigma_deg": 2.0, "drift_tau_s": 1.0}
    _, _, err = run([cfg] * N, random_headings(N, 7), steps=2, dt=200.0, seed=12)
    assert_std(err[1], 2.0 * DEG)
    assert abs(np.corrcoef(err[0], err[1])[0, 1]) < Z / math.sqrt(N)


def test_defaults_by_kind_per_ship():
    params = compass.build([{}, {"kind": "magnetic"}, {"kind": "magnetic", "sigma_deg": 0.5}],
                           1.0)
    np.testing.assert_allclose(np.degrees(params.sigma_rad),
                               [1.0, math.degrees(math.sqrt(0.0054)), 0.5])
    assert params.magnetic.tolist() == [False, True, True]
    assert not params.has_deviation


@pytest.mark.parametrize(("cfg", "key"), [
    ({"sigma_deg": -0.1}, "compass[1].sigma_deg"),
    ({"drift_tau_s": 0.0}, "compass[1].drift_tau_s"),
    ({"drift_sigma_deg": math.inf}, "compass[1].drift_sigma_deg"),
    ({"bias_deg": "east"}, "compass[1].bias_deg"),
    ({"kind": "magnetic", "deviation_deg": [1, 2, 3, 4, 5, 6]}, "compass[1].deviation_deg"),
    ({"kind": "magnetic", "deviation_deg": [1, 2, "x", 4, 5]}, "compass[1].deviation_deg"),
    ({"kind": "magnetic", "deviation_deg": [0, 0, math.nan, 0, 0]}, "compass[1].deviation_deg"),
    ({"kind": "gyro", "deviation_deg": [0, 0, 0, 0, 0]}, "compass[1].deviation_deg"),
    ({"kind": "Gyro"}, "compass[1].kind"),
])
def test_config_errors_name_the_ship_and_key(cfg, key):
    with pytest.raises(InputError) as err:
        compass.build([{}, cfg], 1.0)
    assert err.value.key == key


@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("sigma_deg", 30.0, 1000.0, "must be <= 30, got 1000.0"),
    ("drift_sigma_deg", 30.0, 30.5, "must be <= 30, got 30.5"),
    ("drift_tau_s", 86_400.0, 86_401.0, "must be <= 86400, got 86401.0"),
    ("bias_deg", 180.0, 180.5, "must be <= 180, got 180.5"),
    ("bias_deg", -180.0, -181.0, "must be >= -180, got -181.0"),
])
@pytest.mark.parametrize("kind", ["gyro", "magnetic"])
def test_physical_upper_bounds(key, inside, beyond, message, kind):
    """Generous bounds no real compass exceeds (module docstring): just inside is accepted,
    beyond is refused naming the ship and key."""
    assert_bound(lambda c: compass.build(c, 1.0), "compass", key, inside, beyond, message,
                 kind=kind)


def test_deviation_coefficients_are_bounded():
    """Each of A..E within +-30 deg: the curve at the bounds is accepted, one coefficient
    beyond is refused naming the ship's ``deviation_deg``."""
    edge = [30.0, -30.0, 30.0, -30.0, 30.0]
    p = compass.build([{}, {"kind": "magnetic", "deviation_deg": edge}], 1.0)
    np.testing.assert_allclose(p.dev_c, [0.0, math.radians(30.0)])
    for j in range(5):
        coef = [0.0] * 5
        coef[j] = 30.5 if j % 2 else -30.5
        with pytest.raises(InputError) as err:
            compass.build([{}, {"kind": "magnetic", "deviation_deg": coef}], 1.0)
        assert err.value.key == "compass[1].deviation_deg"
        assert err.value.message == ("each coefficient must be within +-30 deg, got "
                                     f"{[float(c) for c in coef]}")
