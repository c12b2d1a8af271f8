import math

import numpy as np
import pytest

from tests.sensors import assert_bound, assert_mean, assert_rate, assert_std, random_headings, truth
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank
from trafficsim.sensors import gnss
from trafficsim.sensors.gnss import GNSS_NORMAL_DIMS, GNSS_UNIFORM_DIMS
from trafficsim.ships.base import EAST, NORTH, PSI

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
    # the receiver starts in an outage that lasts the whole step: nothing to report yet (the
    # most frequent and longest outages: p_start = 1 - exp(-1) = 0.63 > the uniform 0.5)
    params = gnss.build([{"dropout_rate_per_h": 3600, "dropout_mean_s": 86400}], 1.0)
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


def _scalar_step(cfg, dt, k, up, gm, last, x_col, z, u, wave_ne=None, wave_psi=0.0):
    """One receiver, one step, from the module docstring with plain floats: returns the new
    (up, gm, last) and the fix (north, east, valid, gross)."""
    sigma = cfg.get("sigma_m", cfg.get("drms_m", 2.0 * math.sqrt(2.0)) / math.sqrt(2.0))
    every = max(1, round(1.0 / (cfg.get("rate_hz", 1.0) * dt)))
    p_start = 1.0 - math.exp(-cfg.get("dropout_rate_per_h", 0.0) / 3600.0 * dt)
    p_end = min(1.0, dt / cfg.get("dropout_mean_s", 30.0))
    a = math.exp(-dt / cfg.get("gm_tau_s", 300.0))
    q = cfg.get("gm_sigma_m", 0.0) * math.sqrt(1.0 - a * a)
    up = u[2] >= p_start if up else u[2] < p_end
    valid = k % every == 0 and up
    gm = [a * gm[0] + q * z[2], a * gm[1] + q * z[3]]
    gross = valid and u[0] < cfg.get("gross_prob", 0.0)
    jump = cfg.get("gross_size_m", 50.0) if gross else 0.0
    psi = x_col[2] + wave_psi
    ax, ay = cfg.get("antenna_x_m", 0.0), cfg.get("antenna_y_m", 0.0)
    north = x_col[0] + ax * math.cos(psi) - ay * math.sin(psi)
    east = x_col[1] + ax * math.sin(psi) + ay * math.cos(psi)
    if wave_ne is not None:
        north, east = north + wave_ne[0], east + wave_ne[1]
    north += sigma * z[0] + gm[0] + jump * math.cos(2 * math.pi * u[1])
    east += sigma * z[1] + gm[1] + jump * math.sin(2 * math.pi * u[1])
    if valid:
        last = [north, east]
    return up, gm, last, (last[0], last[1], valid, gross)


@pytest.mark.parametrize("dt", [0.2, 1.0, 3.0])
def test_vectorised_step_matches_a_scalar_receiver_loop(dt):
    """Twelve receivers with every feature switched on in different mixes, 60 steps with a
    moving truth and wave motion: the array code equals a per-ship loop of the docstring's
    model (lever arm turned by wave yaw, wave displacement, schedule, outages, gross errors,
    Gauss-Markov error)."""
    rng = np.random.default_rng(5)
    n = 12
    configs = []
    for i in range(n):
        cfg = {"rate_hz": float(rng.choice([0.25, 1.0, 5.0])),
               "gm_sigma_m": float(rng.choice([0.0, 4.0])), "gm_tau_s": 40.0,
               "gross_prob": float(rng.choice([0.0, 0.3])), "gross_size_m": 25.0,
               "dropout_rate_per_h": float(rng.choice([0.0, 400.0])), "dropout_mean_s": 5.0}
        cfg["drms_m" if i % 3 == 0 else "sigma_m"] = float(rng.uniform(0.5, 9.0))
        if i % 2:
            cfg["antenna_x_m"], cfg["antenna_y_m"] = (float(v) for v in rng.normal(0, 20, 2))
        configs.append(cfg)
    params = gnss.build(configs, dt)
    z0 = rng.standard_normal((n, GNSS_NORMAL_DIMS))
    state = gnss.init(params, z0)
    gm = [list(configs[i]["gm_sigma_m"] * z0[i, 2:4]) for i in range(n)]
    up, last = [True] * n, [[math.nan, math.nan] for _ in range(n)]
    x = truth(n, north=rng.uniform(-1e3, 1e3, n), east=rng.uniform(-1e3, 1e3, n),
              psi=rng.uniform(-1.0, 7.0, n))
    for k in range(60):
        x[PSI] += 0.05
        x[NORTH] += 3.0
        z = rng.standard_normal((n, GNSS_NORMAL_DIMS))
        u = rng.random((n, GNSS_UNIFORM_DIMS))
        wave_ne = rng.normal(0.0, 1.0, (2, n))
        wave_psi = rng.normal(0.0, 0.02, n)
        state, fix = gnss.step(params, state, x, z, u, wave_ne, wave_psi)
        for i in range(n):
            up[i], gm[i], last[i], want = _scalar_step(configs[i], dt, k, up[i], gm[i], last[i],
                                                       x[:, i], z[i], u[i], wave_ne[:, i],
                                                       wave_psi[i])
            got = (fix.north_m[i], fix.east_m[i], fix.valid[i], fix.gross[i])
            assert got[2:] == want[2:], (k, i)
            np.testing.assert_allclose(got[:2], want[:2], rtol=1e-12, atol=1e-9)


def test_gross_errors_are_per_fix_not_per_step():
    """With a fix every 4th step, gross errors occur on a fraction ``gross_prob`` of the fixes
    and never on a step without a fix."""
    cfg = {"sigma_m": 0.0, "gross_prob": 0.2, "rate_hz": 0.25}
    _, _, _, valid, gross = run([cfg] * 5000, truth(5000), steps=8)
    assert not gross[~valid].any()
    assert valid.sum() == 2 * 5000
    assert_rate(int(gross.sum()), int(valid.sum()), 0.2)


def test_outages_hide_scheduled_fixes_only_and_short_mean_lasts_one_step():
    """``dropout_mean_s`` below the step: ``p_end = 1``, every outage is one step long. With a
    fix every 2nd step, the scheduled fixes are missing at the stationary unavailable
    fraction ``p_start / (p_start + p_end)``."""
    dt, rate_h = 1.0, 720.0
    cfg = {"sigma_m": 0.0, "dropout_rate_per_h": rate_h, "dropout_mean_s": 0.5, "rate_hz": 0.5}
    params = gnss.build([cfg] * N, dt)
    assert params.p_end[0] == 1.0 and params.every[0] == 2
    rng = np.random.default_rng(8)
    state = gnss.init(params, rng.standard_normal((N, 4)))
    ups = []
    for _ in range(6):
        state, _ = gnss.step(params, state, truth(N), rng.standard_normal((N, 4)),
                             rng.random((N, 3)))
        ups.append(state.up.copy())
    ups = np.array(ups)
    assert not np.any(~ups[:-1] & ~ups[1:])  # never two steps down in a row
    p_start = 1.0 - math.exp(-rate_h / 3600.0)
    _, _, _, valid, _ = run([cfg] * N, truth(N), steps=6, dt=dt)
    assert not valid[1::2].any()
    missing = int((~valid[2::2]).sum())  # scheduled steps 2, 4
    assert_rate(missing, valid[2::2].size, p_start / (p_start + 1.0))


def test_gauss_markov_error_is_white_when_the_step_is_long():
    """dt >> tau: ``a = exp(-dt/tau)`` vanishes, the error is white with the stationary sd."""
    cfg = {"sigma_m": 0.0, "gm_sigma_m": 3.0, "gm_tau_s": 1.0}
    _, en, _, _, _ = run([cfg] * N, truth(N), steps=2, dt=100.0, seed=9)
    assert_std(en[1], 3.0)
    assert abs(np.corrcoef(en[0], en[1])[0, 1]) < 5.0 / math.sqrt(N)


@pytest.mark.parametrize(("cfg", "key", "match"), [
    ({"rate_hz": -1.0}, "gnss[1].rate_hz", "> 0"),
    ({"drms_m": -3.0}, "gnss[1].drms_m", ">= 0"),
    ({"gm_tau_s": 0.0}, "gnss[1].gm_tau_s", "> 0"),
    ({"dropout_mean_s": 0.0}, "gnss[1].dropout_mean_s", "> 0"),
    ({"dropout_rate_per_h": -1.0}, "gnss[1].dropout_rate_per_h", ">= 0"),
    ({"gross_size_m": math.nan}, "gnss[1].gross_size_m", "finite"),
    ({"antenna_x_m": "fore"}, "gnss[1].antenna_x_m", "number"),
    ({"sigma_m": 1.0, "drms_m": 1.0}, "gnss[1]", "not both"),
    ({"antenna_z_m": 1.0}, "gnss[1]", "unknown"),
])
def test_config_errors_name_the_ship_and_key(cfg, key, match):
    with pytest.raises(InputError, match=match) as err:
        gnss.build([{}, cfg], 1.0)
    assert err.value.key == key



@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("sigma_m", 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    ("sigma_m", 1000.0, 1e9, "must be <= 1000, got 1000000000.0"),
    ("drms_m", 1000.0, 1001.0, "must be <= 1000, got 1001.0"),
    ("gm_sigma_m", 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    ("gross_size_m", 10_000.0, 10_001.0, "must be <= 10000, got 10001.0"),
    ("rate_hz", 100.0, 101.0, "must be <= 100, got 101.0"),
    ("gm_tau_s", 86_400.0, 86_401.0, "must be <= 86400, got 86401.0"),
    ("dropout_mean_s", 86_400.0, 86_401.0, "must be <= 86400, got 86401.0"),
    ("dropout_rate_per_h", 3600.0, 3601.0, "must be <= 3600, got 3601.0"),
    ("antenna_x_m", 250.0, 250.5, "must be <= 250, got 250.5"),
    ("antenna_x_m", -250.0, -100_000.0, "must be >= -250, got -100000.0"),
    ("antenna_y_m", -250.0, -250.5, "must be >= -250, got -250.5"),
    ("antenna_y_m", 250.0, 251.0, "must be <= 250, got 251.0"),
])
def test_physical_upper_bounds(key, inside, beyond, message):
    """Generous bounds no real receiver exceeds (module docstring): just inside is accepted,
    beyond is refused naming the ship and key."""
    assert_bound(lambda c: gnss.build(c, 1.0), "gnss", key, inside, beyond, message)


@pytest.mark.parametrize("dt", [0.0, -1.0, math.nan])
def test_time_step_must_be_positive(dt):
    with pytest.raises(InputError, match="dt"):
        gnss.build([{}], dt)


def test_reference_point_round_trip_and_heading_wrap():
    """``to_reference_point`` undoes ``antenna_position`` at the true heading, and a heading
    of psi + 2 pi gives the same antenna position as psi."""
    rng = np.random.default_rng(3)
    n = 200
    cfgs = [{"antenna_x_m": float(a), "antenna_y_m": float(b)} for a, b in rng.normal(0, 40,
                                                                                       (n, 2))]
    params = gnss.build(cfgs, 1.0)
    psi = rng.uniform(0.0, 2 * math.pi, n)
    x = truth(n, north=rng.normal(0, 1e4, n), east=rng.normal(0, 1e4, n), psi=psi)
    north, east = gnss.antenna_position(params, x)
    np.testing.assert_allclose(np.hypot(north - x[NORTH], east - x[EAST]),
                               np.hypot(params.antenna_x_m, params.antenna_y_m), rtol=1e-9)
    pn, pe = gnss.to_reference_point(params, north, east, psi)
    np.testing.assert_allclose(pn, x[NORTH], atol=1e-9)
    np.testing.assert_allclose(pe, x[EAST], atol=1e-9)
    x2 = x.copy()
    x2[PSI] = psi - 2 * math.pi
    n2, e2 = gnss.antenna_position(params, x2)
    np.testing.assert_allclose(n2, north, atol=1e-9)
    np.testing.assert_allclose(e2, east, atol=1e-9)


def test_antenna_position_without_lever_arm_is_a_copy():
    """No lever arm: the reference point itself, as a new array (the caller may add to it)."""
    params = gnss.build([{}] * 3, 1.0)
    x = truth(3, north=[1.0, 2.0, 3.0], east=[4.0, 5.0, 6.0], psi=[0.0, 1.0, 2.0])
    north, east = gnss.antenna_position(params, x, np.array([0.3, 0.3, 0.3]))
    np.testing.assert_array_equal(north, x[NORTH])
    np.testing.assert_array_equal(east, x[EAST])
    north += 100.0
    east += 100.0
    np.testing.assert_array_equal(x[NORTH], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(x[EAST], [4.0, 5.0, 6.0])
