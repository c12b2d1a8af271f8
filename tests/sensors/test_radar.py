"""Radar / ARPA plots: noise statistics, range limits, detection probability, scan schedule,
propagation of own navigation errors, converted-measurement covariance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.sensors import assert_bound
from trafficsim.errors import InputError
from trafficsim.noise import NoiseBank, independent_streams, peek_normals
from trafficsim.sensors import radar
from trafficsim.ships.base import EAST, N_STATE, NORTH, PSI

NM = 1852.0


def _scene(n_pairs: int, seed: int, r_min: float = 1.0 * NM, r_max: float = 11.0 * NM):
    """Observers 0..N-1 and their targets N..2N-1 at random range, bearing and headings."""
    rng = np.random.default_rng(seed)
    x = np.zeros((N_STATE, 2 * n_pairs))
    x[NORTH, :n_pairs] = rng.uniform(-5e4, 5e4, n_pairs)
    x[EAST, :n_pairs] = rng.uniform(-5e4, 5e4, n_pairs)
    x[PSI] = rng.uniform(0.0, 2 * math.pi, 2 * n_pairs)
    r = rng.uniform(r_min, r_max, n_pairs)
    b = rng.uniform(0.0, 2 * math.pi, n_pairs)
    x[NORTH, n_pairs:] = x[NORTH, :n_pairs] + r * np.cos(b)
    x[EAST, n_pairs:] = x[EAST, :n_pairs] + r * np.sin(b)
    obs = np.arange(n_pairs)
    return x, obs, obs + n_pairs


def _measure(params, x, obs, tgt, seed=0, est=None, **kw):
    n = x.shape[1]
    due = np.ones(n, dtype=bool)
    est_n, est_e, est_psi = (x[NORTH], x[EAST], x[PSI]) if est is None else est
    streams = independent_streams(obs.shape[0], seed)
    return radar.measure(params, due, obs, tgt, x, est_n, est_e, est_psi, streams, 0.0, **kw)


def test_directed_pairs_both_directions() -> None:
    obs, tgt = radar.directed_pairs(np.array([0, 0, 1]), np.array([1, 2, 2]))
    assert obs.tolist() == [0, 0, 1, 1, 2, 2]
    assert tgt.tolist() == [1, 2, 2, 0, 0, 1]


def test_default_sigmas_are_the_a823_budget() -> None:
    """A.823(19) annex: 20 m pulse + 0.01 NM rectangular quantisation; 0.05 beam, +-0.05
    backlash, +-0.1 quantisation, 0.03 encoder (deg)."""
    p = radar.build([{}])
    assert p.sigma_range_m[0] == pytest.approx(22.67, abs=0.01)
    assert math.degrees(p.sigma_bearing_rad[0]) == pytest.approx(0.0870, abs=1e-4)
    assert p.max_range_m[0] == pytest.approx(12 * NM)
    assert p.p_detect[0] == 0.8


@pytest.mark.parametrize("sigma_b_deg", [radar.DEFAULT_SIGMA_BEARING_DEG, 1.0],
                         ids=["a823", "1deg"])
def test_error_statistics_match_configured_sigmas(sigma_b_deg: float) -> None:
    n_pairs = 20000
    x, obs, tgt = _scene(n_pairs, seed=1)
    params = radar.build([{"sigma_range_m": 25.0, "sigma_bearing_deg": sigma_b_deg,
                           "p_detect": 1.0}] * (2 * n_pairs))
    plots = _measure(params, x, obs, tgt, seed=2)
    assert plots.valid.all()
    rel_n = x[NORTH, tgt] - x[NORTH, obs]
    rel_e = x[EAST, tgt] - x[EAST, obs]
    e_r = plots.range_m - np.hypot(rel_n, rel_e)
    true_b = np.arctan2(rel_e, rel_n) - x[PSI, obs]
    e_b = (plots.bearing_rad - true_b + math.pi) % (2 * math.pi) - math.pi
    # sample sigma of N normals has relative standard error 1/sqrt(2N) = 0.5 %
    assert np.std(e_r) == pytest.approx(25.0, rel=0.02)
    assert np.std(e_b) == pytest.approx(math.radians(sigma_b_deg), rel=0.02)
    assert abs(np.mean(e_r)) < 4 * 25.0 / math.sqrt(n_pairs)
    assert abs(np.mean(e_b)) < 4 * math.radians(sigma_b_deg) / math.sqrt(n_pairs)
    # earth-frame errors are consistent with the converted-measurement covariance:
    # e^T R^-1 e is chi-square(2), mean 2 with standard error 2/sqrt(N) = 0.014
    e = np.stack([plots.north_m - x[NORTH, tgt], plots.east_m - x[EAST, tgt]], axis=1)
    nees = np.einsum("ki,kij,kj->k", e, np.linalg.inv(plots.cov), e)
    assert np.mean(nees) == pytest.approx(2.0, abs=0.06)


def test_draws_at_need_only_at_scans() -> None:
    """Draws as the engine makes them, one ``radar`` stream per directed pair: three numbers
    per pair at each scan of its observer, none between scans; the plots of one scan use the
    numbers the streams held, and successive scans are independent."""
    n_pairs = 5000
    x, obs, tgt = _scene(n_pairs, seed=3)
    params = radar.build([{"p_detect": 1.0, "scan_period_s": 2.0}] * (2 * n_pairs))
    bank = NoiseBank(7, np.zeros(n_pairs, int), obs, radar.RADAR_PURPOSE,
                     radar.RADAR_NORMAL_DIMS, other=tgt)
    state, errors = radar.init(params), []
    true_range = np.hypot(x[NORTH, tgt] - x[NORTH, obs], x[EAST, tgt] - x[EAST, obs])
    for t in range(4):
        before = bank.state.copy()
        z = peek_normals(before, radar.RADAR_NORMAL_DIMS)
        state, plots = radar.step(params, state, float(t), obs, tgt, x, x[NORTH], x[EAST],
                                  x[PSI], bank.state)
        if t % 2:  # between scans: nothing drawn, no plot
            np.testing.assert_array_equal(bank.state, before)
            assert not plots.valid.any()
            continue
        assert plots.valid.all()
        np.testing.assert_allclose(plots.range_m, true_range + params.sigma_range_m[obs] * z[:, 0],
                                   rtol=1e-13)
        errors.append(plots.range_m - true_range)
    assert np.std(errors[0]) == pytest.approx(radar.DEFAULT_SIGMA_RANGE_M, rel=0.04)
    assert abs(np.corrcoef(errors[0], errors[1])[0, 1]) < 4 / math.sqrt(n_pairs)


def test_max_and_min_range() -> None:
    n_pairs = 4
    x = np.zeros((N_STATE, 2 * n_pairs))
    x[NORTH, n_pairs:] = [11.99 * NM, 12.01 * NM, 30.0, 50.0]
    obs, tgt = np.arange(n_pairs), np.arange(n_pairs) + n_pairs
    params = radar.build([{"p_detect": 1.0, "sigma_range_m": 0.0}] * (2 * n_pairs))
    plots = _measure(params, x, obs, tgt)
    assert plots.valid.tolist() == [True, False, False, True]
    assert np.isnan(plots.north_m[1]) and np.isnan(plots.cov[2]).all()


def test_detection_probability_per_scan() -> None:
    """MSC.192(79) 5.3.1.1: an indication in 8 of 10 scans, p_detect = 0.8."""
    n_pairs = 40000
    x, obs, tgt = _scene(n_pairs, seed=4)
    params = radar.build([{}] * (2 * n_pairs))
    frac = _measure(params, x, obs, tgt, seed=5).valid.mean()
    assert frac == pytest.approx(0.8, abs=4 * math.sqrt(0.16 / n_pairs))


@pytest.mark.parametrize(("period", "dt", "expected"), [(2.5, 1.0, 40), (2.5, 0.1, 40),
                                                        (3.0, 1.0, 34), (2.5, 5.0, 20)])
def test_scan_schedule(period: float, dt: float, expected: int) -> None:
    """Scans at t = 0, T, 2T ... (first step at or after each), one per step at most."""
    params = radar.build([{"scan_period_s": period}])
    state = radar.init(params)
    n_scans = 0
    for k in range(round(100.0 / dt)):
        state, due = radar.scan_due(params, state, k * dt)
        n_scans += int(due[0])
    assert n_scans == expected


def test_no_plot_between_scans_or_when_disabled() -> None:
    x, obs, tgt = _scene(3, seed=6)
    params = radar.build([{"p_detect": 1.0}] * 3 + [{"p_detect": 1.0, "enabled": False}] * 3)
    state = radar.init(params)
    streams = independent_streams(3)
    state, plots = radar.step(params, state, 0.0, obs, tgt, x, x[NORTH], x[EAST], x[PSI],
                              streams)
    assert plots.valid.all()
    state, plots = radar.step(params, state, 1.0, obs, tgt, x, x[NORTH], x[EAST], x[PSI],
                              streams)
    assert not plots.valid.any()
    _, plots = radar.step(params, state, 0.0, tgt, obs, x, x[NORTH], x[EAST], x[PSI],
                          streams)
    assert not plots.valid.any()  # the observers 3..5 have their radar off


def test_own_navigation_errors_propagate() -> None:
    """A heading error rotates the plot about own antenna; a position error shifts it."""
    x = np.zeros((N_STATE, 2))
    x[NORTH, 1], x[EAST, 1] = 6000.0, 2000.0
    x[PSI] = [0.3, 1.0]
    params = radar.build([{"sigma_range_m": 0.0, "sigma_bearing_deg": 0.0, "p_detect": 1.0,
                           "antenna_x_m": 50.0, "antenna_y_m": 5.0}] * 2)
    obs, tgt = np.array([0]), np.array([1])
    exact = _measure(params, x, obs, tgt)
    assert exact.north_m[0] == pytest.approx(6000.0, abs=1e-6)
    assert exact.east_m[0] == pytest.approx(2000.0, abs=1e-6)

    dpsi, dn, de = math.radians(1.0), 30.0, -20.0
    est = (x[NORTH] + dn, x[EAST] + de, x[PSI] + dpsi)
    plot = _measure(params, x, obs, tgt, est=est)
    # expected: the antenna estimate plus the true antenna-to-target vector rotated by dpsi
    c0, s0 = math.cos(0.3), math.sin(0.3)
    ant_true = np.array([50.0 * c0 - 5.0 * s0, 50.0 * s0 + 5.0 * c0])
    c1, s1 = math.cos(0.3 + dpsi), math.sin(0.3 + dpsi)
    ant_est = np.array([dn + 50.0 * c1 - 5.0 * s1, de + 50.0 * s1 + 5.0 * c1])
    rel = np.array([6000.0, 2000.0]) - ant_true
    rot = np.array([[math.cos(dpsi), -math.sin(dpsi)], [math.sin(dpsi), math.cos(dpsi)]])
    expect = ant_est + rot @ rel
    assert plot.north_m[0] == pytest.approx(expect[0], abs=1e-6)
    assert plot.east_m[0] == pytest.approx(expect[1], abs=1e-6)
    # the cross-range error is range * heading error: 6.3 km * 1 deg = 110 m
    assert np.hypot(plot.north_m[0] - 6000.0 - dn, plot.east_m[0] - 2000.0 - de) == \
        pytest.approx(np.hypot(*rel) * 2 * math.sin(dpsi / 2), abs=2.0)


def test_converted_covariance_includes_own_navigation_uncertainty() -> None:
    x = np.zeros((N_STATE, 2))
    x[EAST, 1] = 5000.0  # target due east: range along east, cross-range along north
    params = radar.build([{"sigma_range_m": 20.0, "sigma_bearing_deg": 0.5, "p_detect": 1.0}] * 2)
    obs, tgt = np.array([0]), np.array([1])
    var_psi = math.radians(0.3) ** 2
    pos_cov = np.array([[[4.0, 1.0], [1.0, 9.0]]] * 2)
    plot = _measure(params, x, obs, tgt, own_heading_var_rad2=np.full(2, var_psi),
                    own_pos_cov_m2=pos_cov)
    # about the measured line of sight (near east): range variance along it, cross-range
    # (bearing and own heading) across it, own position covariance added
    cross = plot.range_m[0] ** 2 * (math.radians(0.5) ** 2 + var_psi)
    c, s = math.cos(plot.bearing_rad[0]), math.sin(plot.bearing_rad[0])
    assert plot.cov[0, 0, 0] == pytest.approx(c * c * 400.0 + s * s * cross + 4.0)
    assert plot.cov[0, 1, 1] == pytest.approx(s * s * 400.0 + c * c * cross + 9.0)
    assert plot.cov[0, 0, 1] == pytest.approx(c * s * (400.0 - cross) + 1.0)
    assert plot.cov[0, 0, 0] == pytest.approx(5000.0**2 * (math.radians(0.5) ** 2 + var_psi)
                                              + 4.0, rel=0.02)


def test_bad_config_and_draws_rejected() -> None:
    with pytest.raises(InputError):
        radar.build([{"sigma_range": 3.0}])
    with pytest.raises(InputError):
        radar.build([{"p_detect": 1.2}])
    with pytest.raises(InputError):
        radar.build([{"scan_period_s": 0.0}])
    params = radar.build([{}] * 2)
    x = np.zeros((N_STATE, 2))
    due = np.ones(2, dtype=bool)
    for bad in (np.zeros((1, 3)), independent_streams(2), independent_streams(1).astype(float)):
        with pytest.raises(ValueError, match="streams"):
            radar.measure(params, due, np.array([0]), np.array([1]), x, x[NORTH], x[EAST],
                          x[PSI], bad, 0.0)


def _reference_plots(params, due, obs, tgt, x, est_n, est_e, est_psi, draws, var_psi=None,
                     pos_cov=None):
    """The measurement model of the module docstring written with whole-array numpy
    operations, one formula per line (the compiled loop must give the same numbers)."""
    def rotate(psi, bx, by):
        return bx * np.cos(psi) - by * np.sin(psi), bx * np.sin(psi) + by * np.cos(psi)

    ax, ay = params.antenna_x_m[obs], params.antenna_y_m[obs]
    psi = x[PSI, obs]
    dn_a, de_a = rotate(psi, ax, ay)
    rel_n = x[NORTH, tgt] - (x[NORTH, obs] + dn_a)
    rel_e = x[EAST, tgt] - (x[EAST, obs] + de_a)
    true_range = np.hypot(rel_n, rel_e)
    rng = true_range + params.sigma_range_m[obs] * draws[:, 0]
    brg = np.mod(np.arctan2(rel_e, rel_n) - psi + params.sigma_bearing_rad[obs] * draws[:, 1]
                 + math.pi, 2 * math.pi) - math.pi
    valid = (due[obs] & (true_range <= params.max_range_m[obs])
             & (true_range >= params.min_range_m[obs]) & (draws[:, 2] < params.z_detect[obs])
             & (rng > 0.0))
    en_a, ee_a = rotate(est_psi[obs], ax, ay)
    theta = est_psi[obs] + brg
    c, s = np.cos(theta), np.sin(theta)
    north = est_n[obs] + en_a + rng * c
    east = est_e[obs] + ee_a + rng * s
    var_r = params.sigma_range_m[obs] ** 2
    var_b = params.sigma_bearing_rad[obs] ** 2 + (0.0 if var_psi is None else var_psi[obs])
    cross = rng * rng * var_b
    cov = np.empty((obs.shape[0], 2, 2))
    cov[:, 0, 0] = c * c * var_r + s * s * cross
    cov[:, 1, 1] = s * s * var_r + c * c * cross
    cov[:, 0, 1] = cov[:, 1, 0] = c * s * (var_r - cross)
    if pos_cov is not None:
        cov = cov + pos_cov[obs]
    return valid, north, east, cov, rng, brg


@pytest.mark.parametrize("own_uncertainty", [False, True])
def test_compiled_plots_match_array_formulas(own_uncertainty: bool) -> None:
    """Every observer sees every other ship of a 12-ship group: random antennas (half at the
    reference point), detection, scan phases, own estimates; NaN exactly where no plot."""
    rng = np.random.default_rng(21)
    n = 12
    i, j = np.triu_indices(n, 1)
    obs, tgt = radar.directed_pairs(i, j)
    x = np.zeros((N_STATE, n))
    x[NORTH], x[EAST] = rng.uniform(-2e4, 2e4, (2, n))
    x[PSI] = rng.uniform(-4.0, 10.0, n)
    cfg = [{"antenna_x_m": float(rng.uniform(-60, 60)) if k % 2 else 0.0,
            "antenna_y_m": float(rng.uniform(-8, 8)) if k % 2 else 0.0,
            "sigma_bearing_deg": float(rng.choice([0.087, 1.0])),
            "max_range_nm": float(rng.choice([6.0, 12.0])), "min_range_m": 40.0,
            "p_detect": float(rng.choice([0.0, 0.8, 1.0]))} for k in range(n)]
    params = radar.build(cfg)
    due = rng.random(n) < 0.8
    est = (x[NORTH] + rng.normal(0, 5, n), x[EAST] + rng.normal(0, 5, n),
           x[PSI] + rng.normal(0, 0.01, n))
    streams = independent_streams(obs.shape[0], 21)
    draws = peek_normals(streams, radar.RADAR_NORMAL_DIMS)
    extra = {}
    if own_uncertainty:
        a = rng.normal(0, 3, (n, 2, 2))
        extra = {"var_psi": rng.uniform(0, 1e-4, n), "pos_cov": a @ a.transpose(0, 2, 1)}
    plots = radar.measure(params, due, obs, tgt, x, *est, streams, 5.0,
                          own_heading_var_rad2=extra.get("var_psi"),
                          own_pos_cov_m2=extra.get("pos_cov"))
    valid, *values = _reference_plots(params, due, obs, tgt, x, *est, draws, **extra)
    assert 0 < valid.sum() < valid.size
    np.testing.assert_array_equal(plots.valid, valid)
    for got, want in zip((plots.north_m, plots.east_m, plots.cov, plots.range_m,
                          plots.bearing_rad), values, strict=True):
        want = np.where(valid.reshape((-1,) + (1,) * (want.ndim - 1)), want, np.nan)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-9)
    assert plots.t_s == 5.0


@pytest.mark.parametrize("seed", range(6))
def test_scan_steps_are_the_first_steps_at_or_after_each_scheduled_scan(seed: int) -> None:
    """Steps no longer than the period: scans happen exactly on the first step at or after
    ``scan_phase_s + k scan_period_s`` (k = 0, 1, ...), one per revolution; a disabled radar
    never scans and keeps its schedule."""
    rng = np.random.default_rng(seed)
    period = float(rng.uniform(1.0, 4.0))
    dt = float(rng.uniform(0.05, 1.0)) * period
    phase = float(rng.uniform(-0.5, 3.0)) * period
    params = radar.build([{"scan_period_s": period, "scan_phase_s": phase},
                          {"scan_period_s": period, "scan_phase_s": phase, "enabled": False}])
    state = radar.init(params)
    steps = 400
    got = []
    for k in range(steps):
        state, due = radar.scan_due(params, state, k * dt)
        assert not due[1]
        if due[0]:
            got.append(k)
    assert state.next_scan_s[1] == phase
    want = sorted({max(0, math.ceil((phase + j * period - 1e-9) / dt)) for j in range(10_000)
                   if phase + j * period <= (steps - 1) * dt + 1e-9})
    assert got == want


def test_steps_longer_than_the_period_scan_every_step() -> None:
    params = radar.build([{"scan_period_s": 2.0}])
    state = radar.init(params)
    for k in range(30):
        state, due = radar.scan_due(params, state, 5.0 * k)
        assert due[0]
        assert state.next_scan_s[0] == pytest.approx(5.0 * k + 2.0)


def test_range_limits_are_inclusive_and_negative_ranges_are_dropped() -> None:
    """A target exactly at ``min_range_m`` or ``max_range_nm`` is plotted; a plot whose noisy
    range is not positive is not (target 50 m away, range sd 60 m: P(50 + 60 z > 0) =
    Phi(5/6) = 0.798)."""
    x = np.zeros((N_STATE, 4))
    x[NORTH, 2], x[EAST, 3] = 40.0, 12.0 * NM
    params = radar.build([{"p_detect": 1.0, "sigma_range_m": 0.0, "sigma_bearing_deg": 0.0}] * 4)
    obs, tgt = np.array([0, 1]), np.array([2, 3])
    plots = _measure(params, x, obs, tgt)
    assert plots.valid.tolist() == [True, True]
    np.testing.assert_allclose(plots.range_m, [40.0, 12.0 * NM])
    np.testing.assert_allclose(plots.bearing_rad, [0.0, math.pi / 2], atol=1e-15)

    n_pairs = 20000
    x = np.zeros((N_STATE, 2 * n_pairs))
    x[NORTH, n_pairs:] = 50.0
    params = radar.build([{"p_detect": 1.0, "sigma_range_m": 60.0}] * (2 * n_pairs))
    obs = np.arange(n_pairs)
    plots = _measure(params, x, obs, obs + n_pairs, seed=9)
    assert np.all(plots.range_m[plots.valid] > 0.0)
    p = 0.5 * (1.0 + math.erf(50.0 / 60.0 / math.sqrt(2.0)))
    assert plots.valid.mean() == pytest.approx(p, abs=5 * math.sqrt(p * (1 - p) / n_pairs))


@pytest.mark.parametrize("p_detect", [0.0, 1.0])
def test_detection_probability_zero_and_one(p_detect: float) -> None:
    n_pairs = 2000
    x, obs, tgt = _scene(n_pairs, seed=10)
    params = radar.build([{"p_detect": p_detect}] * (2 * n_pairs))
    valid = _measure(params, x, obs, tgt, seed=11).valid
    assert valid.all() == valid.any() == bool(p_detect)


def test_polar_noise_pulls_the_mean_plot_in_by_the_conversion_bias() -> None:
    """Bearing noise sd s: ``E[cos(b + s z)] = cos(b) exp(-s^2/2)``, so the mean plot lies at
    ``r exp(-s^2/2)`` along the line of sight (the bias the module docstring works out;
    r = 5 km, s = 10 deg: 75.6 m short) with no mean cross-range error."""
    n_pairs = 20000
    r, s = 5000.0, math.radians(10.0)
    rng = np.random.default_rng(12)
    b = rng.uniform(0.0, 2 * math.pi, n_pairs)
    x = np.zeros((N_STATE, 2 * n_pairs))
    x[PSI, :n_pairs] = rng.uniform(0.0, 2 * math.pi, n_pairs)
    x[NORTH, n_pairs:], x[EAST, n_pairs:] = r * np.cos(b), r * np.sin(b)
    params = radar.build([{"p_detect": 1.0, "sigma_range_m": 0.0,
                           "sigma_bearing_deg": 10.0}] * (2 * n_pairs))
    obs = np.arange(n_pairs)
    plots = _measure(params, x, obs, obs + n_pairs, seed=13)
    along = plots.north_m * np.cos(b) + plots.east_m * np.sin(b)
    cross = -plots.north_m * np.sin(b) + plots.east_m * np.cos(b)
    sd_along = r * math.sqrt((1 + math.exp(-2 * s * s)) / 2 - math.exp(-s * s))
    assert abs(along.mean() - r * math.exp(-s * s / 2)) < 5 * sd_along / math.sqrt(n_pairs)
    assert abs(cross.mean()) < 5 * r * s / math.sqrt(n_pairs)
    assert r - along.mean() == pytest.approx(75.6, abs=3.0)


def test_bearing_dead_astern_wraps_into_minus_pi_pi() -> None:
    """Targets right astern (true relative bearing +-pi): every bearing is in [-pi, pi) and
    its error, taken the short way round, has the configured sd."""
    n_pairs = 20000
    rng = np.random.default_rng(14)
    psi = rng.uniform(0.0, 2 * math.pi, n_pairs)
    x = np.zeros((N_STATE, 2 * n_pairs))
    x[PSI, :n_pairs] = psi
    x[NORTH, n_pairs:], x[EAST, n_pairs:] = -3000.0 * np.cos(psi), -3000.0 * np.sin(psi)
    params = radar.build([{"p_detect": 1.0, "sigma_bearing_deg": 1.0}] * (2 * n_pairs))
    obs = np.arange(n_pairs)
    plots = _measure(params, x, obs, obs + n_pairs, seed=15)
    assert np.all((plots.bearing_rad >= -math.pi) & (plots.bearing_rad < math.pi))
    assert (plots.bearing_rad > 0).any() and (plots.bearing_rad < 0).any()
    err = np.mod(plots.bearing_rad, 2 * math.pi) - math.pi  # bearing - pi, the short way
    assert np.std(err) == pytest.approx(math.radians(1.0), rel=0.03)
    assert abs(np.mean(err)) < 5 * math.radians(1.0) / math.sqrt(n_pairs)


def test_plot_is_the_same_for_own_heading_estimate_plus_a_turn() -> None:
    """The own heading estimate enters through cos and sin only: psi_est and psi_est + 2 pi
    put the plot (and its antenna offset) in the same place."""
    x, obs, tgt = _scene(50, seed=16)
    params = radar.build([{"antenna_x_m": 30.0, "antenna_y_m": -4.0}] * 100)
    a = _measure(params, x, obs, tgt, seed=17)
    b = _measure(params, x, obs, tgt, seed=17,
                 est=(x[NORTH], x[EAST], x[PSI] + 2 * math.pi))
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(b.north_m, a.north_m, atol=1e-8)
    np.testing.assert_allclose(b.east_m, a.east_m, atol=1e-8)


@pytest.mark.parametrize(("cfg", "key"), [
    ({"sigma_range_m": -1.0}, "radar[1].sigma_range_m"),
    ({"sigma_bearing_deg": math.nan}, "radar[1].sigma_bearing_deg"),
    ({"max_range_nm": -12.0}, "radar[1].max_range_nm"),
    ({"min_range_m": "near"}, "radar[1].min_range_m"),
    ({"scan_period_s": 0.0}, "radar[1].scan_period_s"),
    ({"scan_phase_s": math.inf}, "radar[1].scan_phase_s"),
    ({"p_detect": -0.1}, "radar[1].p_detect"),
    ({"enabled": "on"}, "radar[1].enabled"),
    ({"range_nm": 6.0}, "radar[1]"),
])
def test_config_errors_name_the_ship_and_key(cfg, key) -> None:
    with pytest.raises(InputError) as err:
        radar.build([{}, cfg])
    assert err.value.key == key


@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("sigma_range_m", 1000.0, 1000.5, "must be <= 1000, got 1000.5"),
    ("sigma_bearing_deg", 30.0, 31.0, "must be <= 30, got 31.0"),
    ("max_range_nm", 96.0, 10_000.0, "must be <= 96, got 10000.0"),
    ("scan_period_s", 60.0, 60.5, "must be <= 60, got 60.5"),
    ("antenna_x_m", -250.0, -250.5, "must be >= -250, got -250.5"),
    ("antenna_y_m", 250.0, 251.0, "must be <= 250, got 251.0"),
])
def test_physical_upper_bounds(key, inside, beyond, message) -> None:
    """Generous bounds no ship's radar exceeds (module docstring): just inside is accepted,
    beyond is refused naming the ship and key."""
    assert_bound(radar.build, "radar", key, inside, beyond, message)


def test_a_minimum_range_beyond_the_maximum_is_refused():
    """``min_range_m`` 30,000 m with ``max_range_nm`` 12 (22,224 m) would detect nothing ever:
    refused under the ship's key; equal limits are allowed (one range detects)."""
    with pytest.raises(InputError, match="must not exceed max_range_nm") as err:
        radar.build([{}, {"min_range_m": 30000.0}])
    assert err.value.key == "radar[1].min_range_m"
    p = radar.build([{"min_range_m": 1852.0, "max_range_nm": 1.0}])
    assert p.min_range_m[0] == p.max_range_m[0] == 1852.0


# ---------------------------------------------------------------- converted covariance, limits


def test_converted_covariance_matches_a_monte_carlo_of_the_polar_noise() -> None:
    """20000 observers at one geometry (target 8 km at true bearing 030, own heading 070,
    antenna 40 m forward and 3 m to starboard), range sd 25 m, bearing sd 0.5 deg, each with
    its own navigation error drawn from the heading variance (0.3 deg)^2 and position
    covariance [[16, 6], [6, 9]] m^2 passed to ``measure``: the sample covariance of the plot
    errors equals the converted-measurement covariance within sampling error (standard error
    of a sample covariance: sqrt((S_ii S_jj + S_ij^2) / N)); the mean error is the conversion
    bias r (1 - exp(-s^2/2)) = 0.3 m, below the sampling noise."""
    n = 20000
    r, b, psi = 8000.0, math.radians(30.0), math.radians(70.0)
    x = np.zeros((N_STATE, 2 * n))
    x[PSI, :n] = psi
    x[NORTH, n:], x[EAST, n:] = r * math.cos(b), r * math.sin(b)
    params = radar.build([{"sigma_range_m": 25.0, "sigma_bearing_deg": 0.5, "p_detect": 1.0,
                           "antenna_x_m": 40.0, "antenna_y_m": 3.0}] * (2 * n))
    rng = np.random.default_rng(40)
    var_psi = math.radians(0.3) ** 2
    p_own = np.array([[16.0, 6.0], [6.0, 9.0]])
    d_pos = rng.standard_normal((2 * n, 2)) @ np.linalg.cholesky(p_own).T
    est = (x[NORTH] + d_pos[:, 0], x[EAST] + d_pos[:, 1],
           x[PSI] + math.sqrt(var_psi) * rng.standard_normal(2 * n))
    obs = np.arange(n)
    plots = _measure(params, x, obs, obs + n, seed=41, est=est,
                     own_heading_var_rad2=np.full(2 * n, var_psi),
                     own_pos_cov_m2=np.broadcast_to(p_own, (2 * n, 2, 2)))
    assert plots.valid.all()
    e = np.stack([plots.north_m - x[NORTH, n:], plots.east_m - x[EAST, n:]], axis=1)
    want = plots.cov.mean(axis=0)
    got = np.cov(e.T)
    se = np.sqrt((np.outer(np.diag(want), np.diag(want)) + want**2) / n)
    assert np.all(np.abs(got - want) < 4 * se), (got, want)
    assert np.all(np.abs(e.mean(axis=0)) < 4 * np.sqrt(np.diag(want) / n))
    # the geometry makes the ellipse strongly tilted: the test sees the off-diagonal term
    assert abs(want[0, 1]) > 0.5 * math.sqrt(want[0, 0] * want[1, 1])


def test_converted_covariance_is_the_finite_difference_jacobian() -> None:
    """``J`` of the docstring is the derivative of (r, b) -> p_a + r (cos(psi + b),
    sin(psi + b)): a central difference of that map at the measured range and bearing, put
    through diag(sigma_r^2, sigma_b^2 + var_psi), gives the reported covariance."""
    x, obs, tgt = _scene(30, seed=42)
    params = radar.build([{"sigma_range_m": 30.0, "sigma_bearing_deg": 0.7,
                           "p_detect": 1.0}] * 60)
    var_psi = np.linspace(0.0, 1e-4, 60)
    plots = _measure(params, x, obs, tgt, seed=43, own_heading_var_rad2=var_psi)
    assert plots.valid.all()

    def to_chart(k, rng_m, brg):
        t = x[PSI, obs[k]] + brg
        return np.array([x[NORTH, obs[k]] + rng_m * math.cos(t),
                         x[EAST, obs[k]] + rng_m * math.sin(t)])

    for k in range(30):
        rr, bb = plots.range_m[k], plots.bearing_rad[k]
        hr, hb = 1e-3, 1e-7
        J = np.stack([(to_chart(k, rr + hr, bb) - to_chart(k, rr - hr, bb)) / (2 * hr),
                      (to_chart(k, rr, bb + hb) - to_chart(k, rr, bb - hb)) / (2 * hb)], axis=1)
        D = np.diag([30.0**2, math.radians(0.7) ** 2 + var_psi[obs[k]]])
        np.testing.assert_allclose(plots.cov[k], J @ D @ J.T, rtol=1e-5,
                                   atol=1e-6 * plots.cov[k].max())
        # the plot itself is that map at the measured range and bearing
        np.testing.assert_allclose([plots.north_m[k], plots.east_m[k]], to_chart(k, rr, bb),
                                   atol=1e-6)


def test_range_limits_are_measured_from_the_antenna() -> None:
    """Antenna 50 m forward of the reference point, heading 000, min 40 m: a target 60 m ahead
    of the reference point is 10 m from the antenna (not plotted), one 30 m astern is 80 m
    from it (plotted). Max 1 NM: a target 1 NM + 30 m ahead is 1 NM - 20 m from the antenna
    (plotted), one 1 NM - 30 m astern is 1 NM + 20 m from it (not plotted)."""
    ahead = [60.0, -30.0, NM + 30.0, -(NM - 30.0)]
    n_pairs = len(ahead)
    x = np.zeros((N_STATE, 2 * n_pairs))
    x[NORTH, n_pairs:] = ahead
    params = radar.build([{"p_detect": 1.0, "sigma_range_m": 0.0, "sigma_bearing_deg": 0.0,
                           "antenna_x_m": 50.0, "min_range_m": 40.0,
                           "max_range_nm": 1.0}] * (2 * n_pairs))
    obs = np.arange(n_pairs)
    plots = _measure(params, x, obs, obs + n_pairs)
    assert plots.valid.tolist() == [False, True, True, False]
    np.testing.assert_allclose(plots.range_m[1:3], [80.0, NM - 20.0])
    # the plot lands on the target: antenna position plus the measured polar vector
    np.testing.assert_allclose(plots.north_m[1:3], [-30.0, NM + 30.0], atol=1e-9)


def test_detections_over_scans_are_independent_bernoulli_draws() -> None:
    """One pair scanned 4000 times (p_detect 0.5, one scan per 2.5 s step) through its single
    stream: the detection rate is 0.5 within 4 standard errors and detection at one scan does
    not predict the next (P(d_k and d_k+1) = 0.25; overlapping pairs share a draw, so the
    variance of their mean is (3/16 + 2 (1/8 - 1/16)) / N = (5/16) / N)."""
    params = radar.build([{"p_detect": 0.5}] * 2)
    x = np.zeros((N_STATE, 2))
    x[EAST, 1] = 3000.0
    obs, tgt = np.array([0]), np.array([1])
    state, streams = radar.init(params), independent_streams(1, 44)
    hits = []
    for k in range(4000):
        state, plots = radar.step(params, state, 2.5 * k, obs, tgt, x, x[NORTH], x[EAST], x[PSI],
                                  streams)
        hits.append(bool(plots.valid[0]))
    h = np.array(hits)
    assert abs(h.mean() - 0.5) < 4 * math.sqrt(0.25 / h.size)
    both = (h[1:] & h[:-1]).mean()
    assert abs(both - 0.25) < 4 * math.sqrt(5.0 / 16.0 / h.size)


def test_scan_due_is_pure_and_counts_one_period_per_revolution() -> None:
    """``scan_due`` returns a new state and leaves the old one as it was; with steps of 0.7 s
    and a 2.5 s period the scans over 700 s number 700 / 2.5 = 280 (+1 for t = 0), each the
    first step at or after its scheduled time k * 2.5."""
    params = radar.build([{"scan_period_s": 2.5}])
    state = radar.init(params)
    before = state.next_scan_s.copy()
    new, due = radar.scan_due(params, state, 0.0)
    np.testing.assert_array_equal(state.next_scan_s, before)
    assert due[0] and new.next_scan_s[0] == 2.5
    state, times = radar.init(params), []
    for k in range(1001):
        state, due = radar.scan_due(params, state, 0.7 * k)
        if due[0]:
            times.append(k)
    assert len(times) == 281
    assert times == [math.ceil(2.5 * j / 0.7 - 1e-9) for j in range(281)]
