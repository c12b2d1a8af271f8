import math

import numpy as np
import pytest

from tests.sensors import Z, assert_mean, assert_std, random_headings, truth
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank
from trafficsim.sensors import KNOT_MPS, speed_log
from trafficsim.sensors.speed_log import LOG_NORMAL_DIMS
from trafficsim.ships.base import Env

N = 20_000


def read(configs, x, env=None, seed=3, steps=1):
    rng = np.random.default_rng(seed)
    params = speed_log.build(configs)
    env = Env() if env is None else env
    out = [speed_log.measure(params, x, env, rng.standard_normal((len(configs), 2)))
           for _ in range(steps)]
    u = np.stack([r.u_mps for r in out])
    v = np.stack([r.v_mps for r in out])
    return params, u, v, out[0].v_valid


def test_em_measures_through_water_doppler_over_ground():
    # 1 m/s current to the north; ship heading east (90 deg) at u = 5, v = 0.2 through water
    x = truth(2, psi=math.pi / 2.0, u=5.0, v=0.2)
    env = Env(current_north_mps=1.0)
    cfgs = [{"kind": "em", "transverse": True, "sigma_mps": 0.0},
            {"kind": "doppler", "sigma_mps": 0.0, "sigma_rel": 0.0}]
    params, u, v, _ = read(cfgs, x, env)
    assert list(params.ground) == [False, True]
    # EM: current invisible. Doppler bottom track: the northward current is on the port side
    # of an east-heading ship, so over ground u = 5, v = 0.2 - 1 [seed 002, sec 2.10]
    np.testing.assert_allclose(u[0], [5.0, 5.0], atol=1e-12)
    np.testing.assert_allclose(v[0], [0.2, -0.8], atol=1e-12)
    # heading north the same current adds to the Doppler's longitudinal speed only
    x = truth(2, psi=0.0, u=5.0, v=0.2)
    _, u, v, _ = read(cfgs, x, env)
    np.testing.assert_allclose(u[0], [5.0, 6.0], atol=1e-12)
    np.testing.assert_allclose(v[0], [0.2, 0.2], atol=1e-12)
    # Doppler water track (deep water) ignores the current too
    _, u, _, _ = read([{"kind": "doppler", "reference": "water", "sigma_mps": 0.0,
                        "sigma_rel": 0.0}], truth(1, u=5.0), env)
    assert u[0, 0] == pytest.approx(5.0)


def test_pulse_log_default_variance_is_the_catfish_value():
    # variance of u 0.5 (m/s)^2, standard deviation of the order of 1 knot [seed 002, sec 3.4]
    x = truth(N, psi=random_headings(N), u=4.0)
    params, u, v, valid = read([{"kind": "pulse"}] * N, x, steps=2)
    assert params.sigma_mps[0] ** 2 == pytest.approx(0.5)
    assert abs(u.var() - 0.5) < Z * 0.5 * math.sqrt(2.0 / u.size)
    assert_mean(u, 4.0, math.sqrt(0.5))
    assert math.sqrt(0.5) / KNOT_MPS == pytest.approx(1.37, abs=0.01)  # "about 1 kn"
    assert not valid.any() and np.isnan(v).all()


def test_scale_factor_bias_and_noise():
    cfg = {"kind": "em", "transverse": True, "scale_error": 0.02, "bias_mps": 0.1,
           "sigma_mps": 0.2, "transverse_sigma_mps": 0.05, "transverse_bias_mps": -0.03}
    x = truth(N, psi=random_headings(N, 1), u=8.0, v=-0.5)
    _, u, v, valid = read([cfg] * N, x, steps=2)
    assert valid.all()
    assert_mean(u, 1.02 * 8.0 + 0.1, 0.2)
    assert_std(u, 0.2)
    assert_mean(v, 1.02 * -0.5 - 0.03, 0.05)
    assert_std(v, 0.05)


def test_doppler_noise_is_the_larger_of_the_floor_and_the_relative_error():
    # 0.2 % of the value or 0.1 kn, whichever is greater [seed 002, sec 2.10]
    x = truth(N, u=40.0, v=0.5)
    params, u, v, _ = read([{"kind": "doppler"}] * N, x, steps=2)
    assert params.sigma_mps[0] == pytest.approx(0.1 * KNOT_MPS)
    assert params.sigma_rel[0] == pytest.approx(0.002)
    assert_std(u, 0.002 * 40.0)  # 0.08 m/s > 0.051
    assert_std(v, 0.1 * KNOT_MPS)  # 0.001 m/s < 0.051
    assert_mean(u, 40.0, 0.08)


def test_transducer_lever_arm_sees_the_yaw_rate():
    cfg = {"kind": "doppler", "sigma_mps": 0.0, "sigma_rel": 0.0, "lever_x_m": -50.0,
           "lever_y_m": 2.0}
    x = truth(1, u=6.0, v=0.1, r=0.05)
    _, u, v, _ = read([cfg], x)
    # velocity at the transducer: u - r y, v + r x (aft transducer slips to port in a
    # starboard turn)
    assert u[0, 0] == pytest.approx(6.0 - 0.05 * 2.0)
    assert v[0, 0] == pytest.approx(0.1 - 0.05 * 50.0)


def test_config_errors_are_reported():
    with pytest.raises(InputError, match="through"):
        speed_log.build([{"kind": "em", "reference": "ground"}])
    with pytest.raises(InputError, match="no transverse"):
        speed_log.build([{"kind": "pulse", "transverse": True}])
    with pytest.raises(InputError, match="true or false"):
        speed_log.build([{"transverse": "yes"}])
    with pytest.raises(InputError, match="unknown"):
        speed_log.build([{"sigma_kn": 0.1}])


def test_same_draws_give_same_readings_and_ships_are_independent():
    configs = [{"kind": "doppler"}, {"kind": "pulse"}, {"kind": "em", "transverse": True}]
    x = truth(3, psi=[0.0, 1.0, 2.0], u=[3.0, 4.0, 5.0], v=[0.1, 0.2, 0.3], r=[0.0, 0.01, 0.0])
    env = Env(current_north_mps=np.array([0.5, 0.0, -0.2]), current_east_mps=0.3)

    def go(order):
        o = list(order)
        bank = NoiseBank(4, [1] * 3, o, "log", LOG_NORMAL_DIMS)
        params = speed_log.build([configs[i] for i in o])
        env_o = Env(current_north_mps=env.current_north_mps[o],
                    current_east_mps=env.current_east_mps)
        out = []
        for _ in range(10):
            r = speed_log.measure(params, x[:, o], env_o, bank.next())
            out.append(np.stack([r.u_mps, r.v_mps]))
        return np.stack(out)

    a = go([0, 1, 2])
    np.testing.assert_array_equal(a, go([0, 1, 2]))
    np.testing.assert_array_equal(go([2, 1, 0]), a[:, :, [2, 1, 0]])
