import math

import numpy as np
import pytest

from tests.sensors import assert_mean, assert_rate, assert_std, random_headings, truth
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank
from trafficsim.sensors import gnss
from trafficsim.sensors.gnss import GNSS_NORMAL_DIMS, GNSS_UNIFORM_DIMS

N = 20_000


def run(configs, x, steps, dt=1.0, seed=1, wave_ne_m=None, wave_psi_rad=None):
    """Step ``steps`` times on a fixed truth; returns params and stacked readings."""
    rng = np.random.default_rng(seed)
    n = len(configs)
    params = gnss.build(configs, dt)
    state = gnss.init(params, rng.standard_normal((n, GNSS_NORMAL_DIMS)))
    fixes = []
    for _ in range(steps):
        state, fix = gnss.step(params, state, x, rng.standard_normal((n, GNSS_NORMAL_DIMS)),
                               rng.random((n, GNSS_UNIFORM_DIMS)), wave_ne_m, wave_psi_rad)
        fixes.append(fix)
    north = np.stack([f.north_m for f in fixes])
    east = np.stack([f.east_m for f in fixes])
    valid = np.stack([f.valid for f in fixes])
    gross = np.stack([f.gross for f in fixes])
    return params, north - x[0], east - x[1], valid, gross


def test_default_is_dgps_two_metres_white_noise_per_axis():
    # DGPS: standard deviation 2 m per axis, R = diag(4, 4) m^2 [seed 000, eq 4]
    x = truth(N, north=1000.0, east=-500.0, psi=random_headings(N))
    params, en, ee, valid, _ = run([{}] * N, x, steps=3)
    assert np.all(params.sigma_m == 2.0) and valid.all()
    for e in (en, ee):
        assert_mean(e, 0.0, 2.0)
        assert_std(e, 2.0)
    assert abs(np.corrcoef(en.ravel(), ee.ravel())[0, 1]) < 5.0 / math.sqrt(en.size)
    # white: no correlation from one fix to the next
    assert abs(np.corrcoef(en[0], en[1])[0, 1]) < 5.0 / math.sqrt(N)


@pytest.mark.parametrize("drms", [10.0, 100.0])
def test_drms_is_converted_to_per_axis_sigma_decca_fixes(drms):
    # Decca in Plymouth Sound: DRMS 10 m (SW British chain) and 100 m (English chain)
    # [seed 002, sec 3.4]; DRMS = sqrt(a^2 + b^2) [seed 002, sec 2.8]
    x = truth(N)
    params, en, ee, _, _ = run([{"drms_m": drms}] * N, x, steps=2)
    assert params.sigma_m[0] == pytest.approx(drms / math.sqrt(2.0))
    r2 = en ** 2 + ee ** 2
    # radial rms = drms; E[r^2] = drms^2, sd of r^2 = drms^2 for a circular normal error
    assert_mean(r2, drms ** 2, drms ** 2)
    r = np.sqrt(r2)
    # circular normal: P(r < drms) = 1 - e^-1, P(r < 2 drms) = 1 - e^-4
    assert_rate(int((r < drms).sum()), r.size, 1.0 - math.exp(-1.0))
    assert_rate(int((r < 2.0 * drms).sum()), r.size, 1.0 - math.exp(-4.0))


def test_config_errors_are_reported():
    with pytest.raises(InputError, match="not both"):
        gnss.build([{"sigma_m": 2.0, "drms_m": 3.0}], 1.0)
    with pytest.raises(InputError, match="unknown"):
        gnss.build([{"sigma": 2.0}], 1.0)
    with pytest.raises(InputError, match=">= 0"):
        gnss.build([{}, {"sigma_m": -1.0}], 1.0)
    with pytest.raises(InputError, match="> 0"):
        gnss.build([{"rate_hz": 0.0}], 1.0)
    with pytest.raises(InputError, match="gross_prob"):
        gnss.build([{"gross_prob": 1.5}], 1.0)


@pytest.mark.parametrize("dt", [1.0, 10.0])
def test_gauss_markov_error_is_stationary_with_exponential_correlation(dt):
    cfg = {"sigma_m": 0.0, "gm_sigma_m": 5.0, "gm_tau_s": 60.0, "rate_hz": 1.0 / dt}
    _, en, ee, valid, _ = run([cfg] * N, truth(N), steps=11, dt=dt)
    assert valid.all()
    for k in (0, 5, 10):  # stationary from the first step on
        assert_std(en[k], 5.0)
        assert_std(ee[k], 5.0)
    for lag in (1, 5, 10):
        rho = np.corrcoef(en[0], en[lag])[0, 1]
        expected = math.exp(-lag * dt / 60.0)
        assert abs(rho - expected) < 5.0 * (1.0 - expected ** 2) / math.sqrt(N) + 1e-3


def test_gross_errors_rate_size_and_random_direction():
    cfg = {"sigma_m": 0.0, "gross_prob": 0.05, "gross_size_m": 30.0}
    _, en, ee, valid, gross = run([cfg] * N, truth(N, psi=1.0), steps=5)
    r = np.hypot(en, ee)
    assert valid.all()
    assert_rate(int(gross.sum()), gross.size, 0.05)
    np.testing.assert_allclose(r[gross], 30.0, rtol=1e-12)
    assert np.all(r[~gross] == 0.0)
    bearing = np.arctan2(ee[gross], en[gross])
    k = bearing.size
    for trig in (np.cos(bearing), np.sin(bearing)):
        assert abs(trig.mean()) < 5.0 / math.sqrt(2.0 * k)  # var(cos) = 1/2 for uniform angle
    for q in range(4):  # each quadrant a quarter
        lo = -math.pi + q * math.pi / 2.0
        assert_rate(int(((bearing >= lo) & (bearing < lo + math.pi / 2.0)).sum()), k, 0.25)


def test_dropouts_start_and_end_rates_mean_length_and_unavailable_fraction():
    rate_per_h, mean_s, dt = 60.0, 20.0, 1.0
    cfg = {"sigma_m": 0.0, "dropout_rate_per_h": rate_per_h, "dropout_mean_s": mean_s}
    params = gnss.build([cfg] * N, dt)
    p_start = 1.0 - math.exp(-rate_per_h / 3600.0 * dt)
    p_end = 1.0 / mean_s
    assert params.p_start[0] == pytest.approx(p_start) and params.p_end[0] == pytest.approx(p_end)
    _, _, _, valid, _ = run([cfg] * N, truth(N), steps=300, dt=dt)
    up = valid  # a fix every step, so valid = no outage
    before, after = up[:-1], up[1:]
    starts = int((before & ~after).sum())
    ends = int((~before & after).sum())
    assert_rate(starts, int(before.sum()), p_start)
    assert_rate(ends, int((~before).sum()), p_end)
    # geometric outage lengths: mean = 1 / p_end steps = dropout_mean_s
    assert dt * int((~before).sum()) / ends == pytest.approx(mean_s, rel=0.03)
    # long-run unavailable fraction, one independent sample per ship at a late step
    stationary = p_start / (p_start + p_end)
    assert_rate(int((~up[-1]).sum()), N, stationary)


def test_fix_every_k_steps_and_last_fix_held_between():
    n = 50
    # 0.25 Hz at dt 0.5 s: a fix every 8 steps; 5 Hz at 0.5 s: every step
    params, en, ee, valid, _ = run([{"rate_hz": 0.25}] * n, truth(n), steps=25, dt=0.5)
    assert params.every[0] == 8
    assert np.array_equal(np.flatnonzero(valid[:, 0]), [0, 8, 16, 24])
    assert valid.all(axis=1).sum() == 4 and not valid[1:8].any()
    for k in range(1, 8):  # held, not fresh noise
        np.testing.assert_array_equal(en[k], en[0])
        np.testing.assert_array_equal(ee[k], ee[0])
    assert not np.array_equal(en[8], en[0])
    fast, *_ = run([{"rate_hz": 5.0}], truth(1), steps=1, dt=0.5)
    assert fast.every[0] == 1


def test_held_reading_is_nan_until_the_first_fix():
    # the receiver starts in an outage that lasts the whole step: nothing to report yet
    params = gnss.build([{"dropout_rate_per_h": 1e9, "dropout_mean_s": 1e9}], 1.0)
    state = gnss.init(params, np.zeros((1, GNSS_NORMAL_DIMS)))
    state, fix = gnss.step(params, state, truth(1), np.zeros((1, GNSS_NORMAL_DIMS)),
                           np.full((1, GNSS_UNIFORM_DIMS), 0.5))
    assert not fix.valid[0] and np.isnan(fix.north_m[0]) and np.isnan(fix.east_m[0])


def test_lever_arm_is_a_body_fixed_offset_that_turns_with_heading():
    # antenna 10 m forward, 3 m to port of the reference point [seed 003, eq 5]
    cfg = {"sigma_m": 0.0, "antenna_x_m": 10.0, "antenna_y_m": -3.0}
    headings = np.radians([0.0, 90.0, 180.0, 270.0])
    x = truth(4, north=100.0, east=200.0, psi=headings)
    _, en, ee, _, _ = run([cfg] * 4, x, steps=1)
    # by hand: north = 10 cos psi + 3 sin psi, east = 10 sin psi - 3 cos psi
    np.testing.assert_allclose(en[0], [10.0, 3.0, -10.0, -3.0], atol=1e-12)
    np.testing.assert_allclose(ee[0], [-3.0, 10.0, 3.0, -10.0], atol=1e-12)

    # straight run at constant heading: the same earth-frame offset at every position
    params = gnss.build([cfg], 1.0)
    state = gnss.init(params, np.zeros((1, GNSS_NORMAL_DIMS)))
    offsets = []
    psi_turn = np.radians(np.arange(0.0, 360.0, 15.0))
    for k, psi in enumerate(np.concatenate([np.full(10, 0.7), psi_turn])):
        xk = truth(1, north=50.0 * k, east=20.0 * k, psi=psi)
        state, fix = gnss.step(params, state, xk, np.zeros((1, 4)), np.full((1, 3), 0.5))
        offsets.append([fix.north_m[0] - xk[0, 0], fix.east_m[0] - xk[1, 0]])
    offsets = np.array(offsets)
    np.testing.assert_allclose(offsets[:10], offsets[0][None, :].repeat(10, 0), atol=1e-9)
    # turning: constant length, direction = heading + atan2(y_a, x_a)
    turn = offsets[10:]
    np.testing.assert_allclose(np.hypot(*turn.T), math.hypot(10.0, 3.0), rtol=1e-12)
    direction = np.arctan2(turn[:, 1], turn[:, 0])
    expected = psi_turn + math.atan2(-3.0, 10.0)
    np.testing.assert_allclose(np.angle(np.exp(1j * (direction - expected))), 0.0, atol=1e-12)


def test_reduction_to_reference_point_and_heading_error_effect():
    # seed 003: receivers 1 m apart, w = [0, 1]; a heading error e leaves 2 |w| sin(e/2) [eq 6]
    cfg = {"sigma_m": 0.0, "antenna_x_m": 0.0, "antenna_y_m": 1.0}
    n = 360
    psi = np.radians(np.arange(n, dtype=float))
    x = truth(n, north=5.0, east=-7.0, psi=psi)
    params, *_ = run([cfg] * n, x, steps=1)
    north, east = gnss.antenna_position(params, x)
    pn, pe = gnss.to_reference_point(params, north, east, psi)
    np.testing.assert_allclose(pn, 5.0, atol=1e-12)
    np.testing.assert_allclose(pe, -7.0, atol=1e-12)
    for e_deg in (1.0, 5.0, -10.0):
        e = math.radians(e_deg)
        pn, pe = gnss.to_reference_point(params, north, east, psi + e)
        np.testing.assert_allclose(np.hypot(pn - 5.0, pe + 7.0), 2.0 * math.sin(abs(e) / 2.0),
                                   rtol=1e-9)
    # 1 deg gyro error on a 1 m baseline: 1.75 cm
    assert 2.0 * math.sin(math.radians(1.0) / 2.0) == pytest.approx(0.01745, abs=1e-5)


def test_wave_motion_is_added_to_the_fix_and_turns_the_lever_arm():
    cfg = {"sigma_m": 0.0, "antenna_x_m": 20.0}
    x = truth(2, psi=0.0)
    wave = np.array([[1.0, -2.0], [0.5, 0.0]])
    _, en, ee, _, _ = run([cfg] * 2, x, steps=1, wave_ne_m=wave,
                          wave_psi_rad=np.array([0.0, math.pi / 2.0]))
    np.testing.assert_allclose(en[0], [21.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(ee[0], [0.5, 20.0], atol=1e-12)


def test_same_draws_give_same_fixes_and_ships_are_independent():
    configs = [{"drms_m": 10.0, "gross_prob": 0.1, "dropout_rate_per_h": 500.0,
                "gm_sigma_m": 3.0}, {}, {"rate_hz": 0.5, "antenna_x_m": -30.0}]
    n, steps = len(configs), 40
    x = truth(n, north=[1.0, 2.0, 3.0], psi=[0.1, 2.0, 4.0])

    def go(order):
        bank_n = NoiseBank(11, [0] * n, list(order), "gnss", GNSS_NORMAL_DIMS)
        bank_u = NoiseBank(11, [0] * n, list(order), "gnss_gross", GNSS_UNIFORM_DIMS,
                           kind="uniform")
        params = gnss.build([configs[i] for i in order], 1.0)
        state = gnss.init(params, bank_n.next())
        out = []
        for _ in range(steps):
            state, fix = gnss.step(params, state, x[:, list(order)], bank_n.next(),
                                   bank_u.next())
            out.append(np.stack([fix.north_m, fix.east_m, fix.valid, fix.gross]))
        return np.stack(out)

    a, b = go([0, 1, 2]), go([0, 1, 2])
    np.testing.assert_array_equal(a, b)
    c = go([2, 0, 1])
    np.testing.assert_array_equal(c, a[:, :, [2, 0, 1]])
