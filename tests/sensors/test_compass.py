import math

import numpy as np
import pytest

from tests.sensors import Z, assert_mean, assert_std, random_headings
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
