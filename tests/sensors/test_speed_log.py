import math

import numpy as np
import pytest

from tests.sensors import Z, assert_bound, assert_mean, assert_std, random_headings, truth
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


def test_vectorised_measure_matches_a_scalar_log_loop():
    """Every kind and reference, lever arms, scale and bias errors, relative noise, a
    per-ship current: the array code equals a per-ship loop in which the ground velocity is
    worked out in the earth frame (velocity through the water turned by psi, plus current)
    and turned back into the body frame."""
    rng = np.random.default_rng(21)
    n = 24
    kinds = ["em", "doppler", "pulse"]
    configs = []
    for i in range(n):
        kind = kinds[i % 3]
        cfg = {"kind": kind, "scale_error": float(rng.uniform(-0.05, 0.05)),
               "bias_mps": float(rng.normal(0, 0.1)), "lever_x_m": float(rng.normal(0, 40)),
               "lever_y_m": float(rng.normal(0, 5)), "sigma_rel": float(rng.choice([0.0, 0.01]))}
        if kind == "doppler":
            cfg["reference"] = "ground" if i % 2 else "water"
            cfg["transverse_bias_mps"] = float(rng.normal(0, 0.05))
        if kind == "em" and i % 2:
            cfg["transverse"] = True
        configs.append(cfg)
    params = speed_log.build(configs)
    x = truth(n, psi=rng.uniform(-7, 7, n), u=rng.uniform(-2, 12, n), v=rng.normal(0, 1, n),
              r=rng.normal(0, 0.02, n))
    cn, ce = rng.normal(0, 1, n), rng.normal(0, 1, n)
    z = rng.standard_normal((n, LOG_NORMAL_DIMS))
    reading = speed_log.measure(params, x, Env(current_north_mps=cn, current_east_mps=ce), z)
    for i, cfg in enumerate(configs):
        kind = cfg["kind"]
        psi, u, v, r = x[2, i], x[3, i], x[4, i], x[5, i]
        if cfg.get("reference", "ground" if kind == "doppler" else "water") == "ground":
            vn = u * math.cos(psi) - v * math.sin(psi) + cn[i]
            ve = u * math.sin(psi) + v * math.cos(psi) + ce[i]
            u, v = vn * math.cos(psi) + ve * math.sin(psi), -vn * math.sin(psi) + ve * math.cos(psi)
        u, v = u - r * cfg["lever_y_m"], v + r * cfg["lever_x_m"]
        floor = math.sqrt(0.5) if kind == "pulse" else 0.1 * KNOT_MPS
        gain = 1.0 + cfg["scale_error"]
        want_u = gain * u + cfg["bias_mps"] + max(floor, cfg["sigma_rel"] * abs(u)) * z[i, 0]
        assert reading.u_mps[i] == pytest.approx(want_u, rel=1e-12, abs=1e-12)
        has_v = kind == "doppler" or cfg.get("transverse", False)
        assert reading.v_valid[i] == has_v
        if has_v:
            want_v = (gain * v + cfg.get("transverse_bias_mps", 0.0)
                      + max(floor, cfg["sigma_rel"] * abs(v)) * z[i, 1])
            assert reading.v_mps[i] == pytest.approx(want_v, rel=1e-12, abs=1e-12)
        else:
            assert math.isnan(reading.v_mps[i])


def test_bottom_track_keeps_the_speed_over_ground_at_any_heading():
    """A Doppler log in bottom track measures the ground speed: its (u, v) has the length of
    the earth-frame ground velocity at every heading (also across north, psi near 0 / 2 pi),
    and psi and psi + 2 pi read the same."""
    n = 721
    psi = np.linspace(-2 * math.pi, 2 * math.pi, n)
    x = truth(n, psi=psi, u=6.0, v=-0.7)
    env = Env(current_north_mps=0.8, current_east_mps=-1.1)
    cfg = {"kind": "doppler", "sigma_mps": 0.0, "sigma_rel": 0.0}
    _, u, v, _ = read([cfg] * n, x, env)
    vn = 6.0 * np.cos(psi) + 0.7 * np.sin(psi) + 0.8
    ve = 6.0 * np.sin(psi) - 0.7 * np.cos(psi) - 1.1
    np.testing.assert_allclose(np.hypot(u[0], v[0]), np.hypot(vn, ve), rtol=1e-12)
    # psi = -2 pi, 0 and 2 pi are the first, middle and last samples
    np.testing.assert_allclose(u[0, [0, 360, 720]], u[0, 360], atol=1e-12)
    np.testing.assert_allclose(v[0, [0, 360, 720]], v[0, 360], atol=1e-12)


def test_relative_noise_on_the_transverse_channel():
    """The transverse channel's sd is max(floor, sigma_rel |v|): with |v| = 10 m/s and
    sigma_rel 0.02 that is 0.2 m/s, above the 0.05 m/s floor."""
    cfg = {"kind": "doppler", "reference": "water", "sigma_rel": 0.02,
           "transverse_sigma_mps": 0.05, "sigma_mps": 0.3}
    _, u, v, _ = read([cfg] * N, truth(N, u=1.0, v=-10.0), steps=2, seed=6)
    assert_std(v, 0.2)
    assert_mean(v, -10.0, 0.2)
    assert_std(u, 0.3)  # 0.02 * 1 < 0.3


@pytest.mark.parametrize(("cfg", "key"), [
    ({"scale_error": -1.0}, "log[1].scale_error"),
    ({"sigma_mps": -0.1}, "log[1].sigma_mps"),
    ({"sigma_rel": math.nan}, "log[1].sigma_rel"),
    ({"transverse_sigma_mps": -1.0}, "log[1].transverse_sigma_mps"),
    ({"lever_x_m": "bow"}, "log[1].lever_x_m"),
    ({"kind": "pulse", "reference": "ground"}, "log[1].reference"),
    ({"kind": "doppler", "reference": "bottom"}, "log[1].reference"),
    ({"kind": "pitot"}, "log[1].kind"),
    ({"transverse": 1}, "log[1].transverse"),
    ({"bias_kn": 0.1}, "log[1]"),
])
def test_config_errors_name_the_ship_and_key(cfg, key):
    with pytest.raises(InputError) as err:
        speed_log.build([{}, cfg])
    assert err.value.key == key


@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("sigma_mps", 5.0, 5.5, "must be <= 5, got 5.5"),
    ("transverse_sigma_mps", 5.0, 6.0, "must be <= 5, got 6.0"),
    ("sigma_rel", 0.999, 1.0, "must be < 1, got 1.0"),
    ("scale_error", 0.999, 1.0, "must be < 1, got 1.0"),
    ("bias_mps", 5.0, 5.01, "must be <= 5, got 5.01"),
    ("bias_mps", -5.0, -6.0, "must be >= -5, got -6.0"),
    ("transverse_bias_mps", -5.0, -5.5, "must be >= -5, got -5.5"),
    ("transverse_bias_mps", 5.0, 100.0, "must be <= 5, got 100.0"),
    ("lever_x_m", 250.0, 250.5, "must be <= 250, got 250.5"),
    ("lever_x_m", -250.0, -251.0, "must be >= -250, got -251.0"),
    ("lever_y_m", 250.0, 1e5, "must be <= 250, got 100000.0"),
    ("lever_y_m", -250.0, -250.5, "must be >= -250, got -250.5"),
])
def test_physical_upper_bounds(key, inside, beyond, message):
    """Generous bounds no real log exceeds (module docstring): just inside is accepted, beyond
    is refused naming the ship and key."""
    assert_bound(speed_log.build, "log", key, inside, beyond, message, kind="doppler")
