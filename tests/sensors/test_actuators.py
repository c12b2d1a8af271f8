import math

import numpy as np
import pytest

from tests.sensors import assert_bound, assert_mean, assert_std, truth
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank
from trafficsim.sensors import actuators
from trafficsim.sensors.actuators import ACTUATOR_NORMAL_DIMS

N = 20_000
DEG = math.radians(1.0)


def read(configs, x, seed=4, steps=1):
    rng = np.random.default_rng(seed)
    params = actuators.build(configs)
    out = [actuators.measure(params, x, rng.standard_normal((len(configs), 2)))
           for _ in range(steps)]
    return np.stack([r.rudder_rad for r in out]), np.stack([r.rps for r in out])


def test_defaults_are_perfect_sensors():
    # seed 002 ignores the variances of rudder angle and engine revolutions (sec 3.4)
    rng = np.random.default_rng(0)
    x = truth(100, rudder=rng.uniform(-0.6, 0.6, 100), rps=rng.uniform(-2.0, 2.0, 100))
    rudder, rps = read([{}] * 100, x)
    np.testing.assert_array_equal(rudder[0], x[6])
    np.testing.assert_array_equal(rps[0], x[7])


def test_noise_and_bias_in_si_units():
    cfg = {"rudder_sigma_deg": 0.5, "rudder_bias_deg": 1.0, "shaft_sigma_rpm": 1.5,
           "shaft_bias_rpm": -2.0}
    x = truth(N, rudder=10.0 * DEG, rps=1.2)
    rudder, rps = read([cfg] * N, x, steps=2)
    assert_mean(rudder, 11.0 * DEG, 0.5 * DEG)
    assert_std(rudder, 0.5 * DEG)
    assert_mean(rps, 1.2 - 2.0 / 60.0, 1.5 / 60.0)
    assert_std(rps, 1.5 / 60.0)
    assert abs(np.corrcoef(rudder.ravel(), rps.ravel())[0, 1]) < 5.0 / math.sqrt(rudder.size)


def test_quantisation_grid_and_uniform_error():
    q_deg, q_rpm = 0.5, 2.0
    cfg = {"rudder_resolution_deg": q_deg, "shaft_resolution_rpm": q_rpm}
    rng = np.random.default_rng(1)
    x = truth(N, rudder=rng.uniform(-35.0, 35.0, N) * DEG, rps=rng.uniform(-2.0, 2.0, N))
    rudder, rps = read([cfg] * N, x)
    for reading, truth_row, q in ((rudder[0], x[6], q_deg * DEG), (rps[0], x[7], q_rpm / 60)):
        steps = reading / q
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)  # on the grid
        err = reading - truth_row
        assert np.abs(err).max() <= q / 2.0 + 1e-15
        # uniform on [-q/2, q/2]: mean 0, sd q / sqrt(12)
        assert_mean(err, 0.0, q / math.sqrt(12.0))
        # sd of the sample sd: sqrt((mu4 - sigma^4) / (4 sigma^2 N)) = q / sqrt(60 N)
        assert abs(err.std() - q / math.sqrt(12.0)) < 5.0 * q / math.sqrt(60.0 * N)


def test_noise_is_quantised_too():
    cfg = {"rudder_sigma_deg": 2.0, "rudder_resolution_deg": 1.0}
    rudder, _ = read([cfg] * 1000, truth(1000, rudder=0.3))
    steps = rudder[0] / DEG
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    assert np.unique(np.round(steps)).size > 5


def test_config_errors_are_reported():
    with pytest.raises(InputError, match="unknown"):
        actuators.build([{"rudder_sigma_rad": 0.1}])
    with pytest.raises(InputError, match=">= 0"):
        actuators.build([{"shaft_resolution_rpm": -1.0}])


def test_same_draws_give_same_readings_and_ships_are_independent():
    configs = [{"rudder_sigma_deg": 1.0}, {"shaft_sigma_rpm": 3.0, "shaft_resolution_rpm": 1.0},
               {"rudder_bias_deg": -1.0, "rudder_resolution_deg": 0.1}]
    x = truth(3, rudder=[0.1, -0.2, 0.3], rps=[1.0, 2.0, -1.0])

    def go(order):
        o = list(order)
        bank = NoiseBank(5, [2] * 3, o, "actuators", ACTUATOR_NORMAL_DIMS)
        params = actuators.build([configs[i] for i in o])
        out = []
        for _ in range(10):
            r = actuators.measure(params, x[:, o], bank.next())
            out.append(np.stack([r.rudder_rad, r.rps]))
        return np.stack(out)

    a = go([0, 1, 2])
    np.testing.assert_array_equal(a, go([0, 1, 2]))
    np.testing.assert_array_equal(go([1, 0, 2]), a[:, :, [1, 0, 2]])


def test_quantise_is_nearest_multiple_idempotent_and_odd():
    """Nearest multiple of q (error at most q/2), a fixed point of itself, the same for -x as
    for x, and untouched where the resolution is 0."""
    rng = np.random.default_rng(7)
    v = rng.uniform(-40.0, 40.0, 5000)
    q = rng.choice([0.0, 0.1, 0.5, 2.0], 5000)
    out = actuators.quantise(v, q)
    on = q > 0.0
    np.testing.assert_array_equal(out[~on], v[~on])
    assert np.all(np.abs(out[on] - v[on]) <= q[on] / 2.0 + 1e-12)
    k = out[on] / q[on]
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)
    np.testing.assert_array_equal(actuators.quantise(out, q), out)
    np.testing.assert_array_equal(actuators.quantise(-v, q), -out)
    # by hand: 0.74 -> 0.5 and 0.76 -> 1.0 at q = 0.5; -1.26 -> -1.5
    np.testing.assert_allclose(actuators.quantise(np.array([0.74, 0.76, -1.26]),
                                                  np.full(3, 0.5)), [0.5, 1.0, -1.5])


def test_vectorised_measure_matches_a_scalar_loop():
    """Readings in SI: degrees and rpm converted (1 rpm = 1/60 rev/s), noise and bias added,
    then rounded to the resolution; compared with a per-ship loop."""
    rng = np.random.default_rng(8)
    n = 40
    configs = [{"rudder_sigma_deg": float(rng.uniform(0, 2)),
                "rudder_bias_deg": float(rng.normal(0, 1)),
                "rudder_resolution_deg": float(rng.choice([0.0, 0.1, 1.0])),
                "shaft_sigma_rpm": float(rng.uniform(0, 5)),
                "shaft_bias_rpm": float(rng.normal(0, 2)),
                "shaft_resolution_rpm": float(rng.choice([0.0, 1.0, 5.0]))} for _ in range(n)]
    params = actuators.build(configs)
    x = truth(n, rudder=rng.uniform(-0.6, 0.6, n), rps=rng.uniform(-3, 3, n))
    z = rng.standard_normal((n, ACTUATOR_NORMAL_DIMS))
    got = actuators.measure(params, x, z)
    for i, c in enumerate(configs):
        rudder = x[6, i] + math.radians(c["rudder_bias_deg"] + c["rudder_sigma_deg"] * z[i, 0])
        rps = x[7, i] + (c["shaft_bias_rpm"] + c["shaft_sigma_rpm"] * z[i, 1]) / 60.0
        qr, qs = math.radians(c["rudder_resolution_deg"]), c["shaft_resolution_rpm"] / 60.0
        if qr:
            rudder = round(rudder / qr) * qr
        if qs:
            rps = round(rps / qs) * qs
        assert got.rudder_rad[i] == pytest.approx(rudder, rel=1e-12, abs=1e-14)
        assert got.rps[i] == pytest.approx(rps, rel=1e-12, abs=1e-14)


@pytest.mark.parametrize(("cfg", "key"), [
    ({"rudder_sigma_deg": -1.0}, "actuators[1].rudder_sigma_deg"),
    ({"rudder_resolution_deg": math.inf}, "actuators[1].rudder_resolution_deg"),
    ({"shaft_bias_rpm": "fast"}, "actuators[1].shaft_bias_rpm"),
    ({"shaft_sigma_rpm": math.nan}, "actuators[1].shaft_sigma_rpm"),
    ({"shaft_resolution_rps": 1.0}, "actuators[1]"),
])
def test_config_errors_name_the_ship_and_key(cfg, key):
    with pytest.raises(InputError) as err:
        actuators.build([{}, cfg])
    assert err.value.key == key


@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("rudder_sigma_deg", 10.0, 10.5, "must be <= 10, got 10.5"),
    ("rudder_bias_deg", 10.0, 11.0, "must be <= 10, got 11.0"),
    ("rudder_bias_deg", -10.0, -10.5, "must be >= -10, got -10.5"),
    ("rudder_resolution_deg", 10.0, 35.0, "must be <= 10, got 35.0"),
    ("shaft_sigma_rpm", 120.0, 121.0, "must be <= 120, got 121.0"),
    ("shaft_bias_rpm", -120.0, -121.0, "must be >= -120, got -121.0"),
    ("shaft_bias_rpm", 120.0, 120.5, "must be <= 120, got 120.5"),
    ("shaft_resolution_rpm", 120.0, 1000.0, "must be <= 120, got 1000.0"),
])
def test_physical_upper_bounds(key, inside, beyond, message):
    """Generous bounds no real indicator exceeds (module docstring): just inside is accepted,
    beyond is refused naming the ship and key."""
    assert_bound(actuators.build, "actuators", key, inside, beyond, message)
