"""Gross-error window [seed 002, 6.6]: rule, helpers, and use with the ch 6 and CA filters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from trafficsim.estimation import ca, gating, linefit, tracker

SIGMA_DECCA = 10.0 / np.sqrt(2.0)  # DRMS 10 m in Plymouth Sound [seed 002, 6.4], per axis


def run_gate(params: gating.GateParams, seq: list[float]) -> list[tuple[bool, bool, float]]:
    rej = gating.init_state(1)
    out = []
    for d in seq:
        g = gating.gate(params, np.array([d]), rej)
        rej = g.rejections
        out.append((bool(g.accept[0]), bool(g.restart[0]), float(g.window[0])))
    return out


def test_gate_rule() -> None:
    p = gating.build([{"window_diameter_m": 100.0}])
    assert p.threshold[0] == 50.0 and p.reopen_factor[0] == 2.0 and p.max_rejections[0] == 3
    # isolated failure, the window doubles once, then closes again
    assert run_gate(p, [10, 60, 60, 60, 10]) == [
        (True, False, 50), (False, False, 50), (True, False, 100), (False, False, 50),
        (True, False, 100)]
    # three consecutive failures restart; a missing fix (NaN) changes nothing
    assert run_gate(p, [60, np.nan, 150, 500, 60]) == [
        (False, False, 50), (False, False, 100), (False, False, 100), (False, True, 200),
        (False, False, 50)]


def test_gate_fully_open_after_failure() -> None:
    """reopen_factor = inf: the literal "open the window on an update which follows a failure"."""
    p = gating.build([{"window_diameter_m": 100.0, "reopen_factor": float("inf")}])
    assert [a for a, _, _ in run_gate(p, [60, 1e6, 60])] == [False, True, False]


def test_gate_vectorised_and_build() -> None:
    p = gating.build([{"gate_sigma": 3.0, "max_rejections": 1}, {}])
    g = gating.gate(p, np.array([4.0, 40.0]), gating.init_state(2))
    np.testing.assert_array_equal(g.accept, [False, True])
    np.testing.assert_array_equal(g.restart, [True, False])
    with pytest.raises(ValueError):
        gating.build([{"reopen_factor": 0.5}])


def test_normalised_distance_closed_form() -> None:
    rng = np.random.default_rng(0)
    nu = rng.normal(size=(50, 2))
    a = rng.normal(size=(50, 2, 2))
    s = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(2)
    ref = np.sqrt(np.einsum("ni,ni->n", nu, np.linalg.solve(s, nu[..., None])[..., 0]))
    np.testing.assert_allclose(gating.normalised_distance(nu, s), ref, rtol=1e-10)
    diag = np.abs(rng.normal(size=(50, 2))) + 0.1
    np.testing.assert_allclose(gating.normalised_distance(nu, diag),
                               np.sqrt(np.sum(nu**2 / diag, axis=1)))
    np.testing.assert_allclose(gating.normalised_distance(nu[:, 0], diag[:, 0]),
                               np.abs(nu[:, 0]) / np.sqrt(diag[:, 0]))


@pytest.mark.parametrize(("p", "dof", "value"), [
    (0.95, 1, 3.841458820694124), (0.99, 1, 6.6348966010212145), (0.95, 2, 5.991464547107979),
    (0.95, 3, 7.814727903251178), (0.025, 10, 3.246972780236841), (0.975, 10, 20.48317735080739),
    (0.995, 100, 140.16948848727), (0.005, 100, 67.32756330547)])
def test_chi2_quantile_table(p: float, dof: int, value: float) -> None:
    """Standard table values (e.g. Abramowitz & Stegun table 26.8)."""
    assert gating.chi2_quantile(p, dof) == pytest.approx(value, rel=1e-8)


def decca_run(seed: int, ns: int = 300, steps: int = 300, step_m: float = 8.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """Straight tracks in random directions and Decca-like fixes (DRMS 10 m)."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(0.0, 2 * np.pi, ns)
    t = np.arange(steps, dtype=float)
    truth = np.stack([step_m * t * np.cos(th)[:, None], step_m * t * np.sin(th)[:, None]], -1)
    return truth, truth + rng.normal(0.0, SIGMA_DECCA, truth.shape)


def rms(est: np.ndarray, truth: np.ndarray, start: int = 20) -> float:
    return float(np.sqrt(np.mean(np.sum((est[:, start:] - truth[:, start:]) ** 2, axis=-1))))


def test_linefit_window_removes_gross_errors() -> None:
    """Isolated 100 m gross errors at 5 % of the fixes (random direction) against the thesis'
    100 m window (n = 4): every one is rejected and no good fix is; the filtered RMS error
    stays within 10 % of the filter on clean fixes (7.0 vs 6.7 m), while without the window it
    doubles (14.7 m)."""
    rng = np.random.default_rng(5)
    truth, z0 = decca_run(5)
    ns, steps = truth.shape[:2]
    gross = rng.random((ns, steps)) < 0.05
    gross[:, 1:] &= ~gross[:, :-1]  # isolated
    gross[:, :10] = False           # not during the unfiltered start
    ang = rng.uniform(0.0, 2 * np.pi, (ns, steps))
    z = z0 + np.where(gross[..., None], 100.0 * np.stack([np.cos(ang), np.sin(ang)], -1), 0.0)
    p = linefit.build([{"n_points": 4}] * ns)
    gp = gating.build([{"window_diameter_m": 100.0}] * ns)
    clean = linefit.run(p, z0)
    gated = linefit.run(p, z, gp)
    plain = linefit.run(p, z)
    assert np.array_equal(gated.rejected, gross)
    assert not gated.restarted.any()
    assert rms(gated.estimate, truth) < 1.10 * rms(clean.estimate, truth)
    assert rms(plain.estimate, truth) > 1.8 * rms(clean.estimate, truth)
    assert not linefit.run(p, z0, gp).rejected.any()  # clean fixes never rejected


@pytest.mark.parametrize(("jump_m", "back_to_fix_noise", "settled"), [(70.0, 9, 11),
                                                                      (500.0, 2, 14)])
def test_linefit_follows_a_genuine_jump(jump_m: float, back_to_fix_noise: int,
                                        settled: int) -> None:
    """The fixes jump for good (a re-fix that is genuinely elsewhere) at step j; 300 ships.

    500 m: two rejections, restart on the third fix (max_rejections = 3); the estimate is the
    fix itself for the n = 4 unfiltered fixes, then filtered again. 70 m (between the window
    and the reopened window): rejected once (99 % of ships), then taken through the doubled
    window without any restart; the straight-line prediction overshoots for a few fixes.
    Recovery (RMS over ships at each step): from j + 2 (500 m) or j + 9 (70 m) no worse than
    the raw fixes (DRMS 10 m, +10 %), from j + 14 or j + 11 within 15 % of the pre-jump
    filtered RMS (6.8 m)."""
    truth, z = decca_run(9)
    j = 150
    truth[:, j:, 0] += jump_m
    z[:, j:, 0] += jump_m
    ns = truth.shape[0]
    p = linefit.build([{"n_points": 4}] * ns)
    r = linefit.run(p, z, gating.build([{"window_diameter_m": 100.0}] * ns))
    err2 = np.sum((r.estimate - truth) ** 2, axis=-1)
    rms_step = np.sqrt(err2.mean(axis=0))
    before = np.sqrt(err2[:, 20:j].mean())
    assert r.rejected[:, j].mean() >= 0.95
    if jump_m > 100.0:
        assert r.rejected[:, j + 1].all() and r.restarted[:, j + 2].all()
        assert r.restarted.sum() == ns
        np.testing.assert_array_equal(r.estimate[:, j + 2:j + 6], z[:, j + 2:j + 6])
    else:
        assert not r.restarted.any()
    assert rms_step[j + back_to_fix_noise - 1] > 1.1 * 10.0  # the stated step is the first
    assert np.all(rms_step[j + back_to_fix_noise:] < 1.1 * 10.0)
    assert np.all(rms_step[j + settled:] < 1.15 * before)


def ca_two_axes(z: np.ndarray, params: ca.CAParams, gp: gating.GateParams | None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CA filter on north and east of each ship with the gate on the 2-D normalised innovation
    (independent axes: diagonal S), restart = :func:`ca.restart` of both axes."""
    ns, steps, _ = z.shape
    zz = z.reshape(ns, steps, 2).transpose(0, 2, 1).reshape(2 * ns, steps)
    x, p = ca.initial_state(params, zz[:, 0], zz[:, 1])
    est = np.full((2 * ns, steps), np.nan)
    rejected = np.zeros((ns, steps), bool)
    restarted = np.zeros((ns, steps), bool)
    rej = gating.init_state(ns)
    for k in range(2, steps):
        xp, pp = ca.predict(params, x, p)
        accept = None
        if gp is not None:
            nu = (zz[:, k] - xp[:, 0]).reshape(ns, 2)
            s = (pp[:, 0, 0] + params.sigma_meas**2).reshape(ns, 2)
            g = gating.gate(gp, gating.normalised_distance(nu, s), rej)
            rej = g.rejections
            accept = np.repeat(g.accept, 2)
            rejected[:, k] = ~g.accept & ~g.restart
            restarted[:, k] = g.restart
        x, p = ca.update(params, xp, pp, zz[:, k], accept)[:2]
        if gp is not None:
            x, p = ca.restart(params, x, p, zz[:, k], np.repeat(restarted[:, k], 2))
        est[:, k] = x[:, 0]
    return est.reshape(ns, 2, steps).transpose(0, 2, 1), rejected, restarted


def test_ca_with_gate_on_normalised_innovation() -> None:
    """The same gate on a CA filter (sigma 3 m, 2 s fixes), threshold sqrt(chi2_2(1 - 1e-6)) =
    5.3 sigma: isolated 100 m gross errors (5 %) are all rejected, the RMS stays within 10 % of
    the clean run (2.5 times worse without the gate); a genuine 300 m jump restarts on the third
    fix and the error is back to the fix noise at once."""
    rng = np.random.default_rng(6)
    ns, steps = 200, 200
    truth, _ = decca_run(6, ns, steps, 10.0)
    z0 = truth + rng.normal(0.0, 3.0, truth.shape)
    gross = rng.random((ns, steps)) < 0.05
    gross[:, 1:] &= ~gross[:, :-1]
    gross[:, :3] = False
    ang = rng.uniform(0.0, 2 * np.pi, (ns, steps))
    z = z0 + np.where(gross[..., None], 100.0 * np.stack([np.cos(ang), np.sin(ang)], -1), 0.0)
    params = ca.build([{"sigma_m": 3.0}] * ns, axes=2)
    gp = gating.build([{"gate_sigma": np.sqrt(gating.chi2_quantile(1 - 1e-6, 2))}] * ns)
    clean, _, _ = ca_two_axes(z0, params, None)
    gated, rejected, restarted = ca_two_axes(z, params, gp)
    plain, _, _ = ca_two_axes(z, params, None)
    np.testing.assert_array_equal(rejected, gross)
    assert not restarted.any()
    assert rms(gated, truth) < 1.10 * rms(clean, truth)
    assert rms(plain, truth) > 2.0 * rms(clean, truth)

    j = 100
    z0[:, j:, 1] += 300.0
    truth[:, j:, 1] += 300.0
    est, rejected, restarted = ca_two_axes(z0, params, gp)
    assert rejected[:, j:j + 2].all() and restarted[:, j + 2].all() and restarted.sum() == ns
    np.testing.assert_allclose(est[:, j + 2], z0[:, j + 2])  # restart at the fix
    err = np.abs(est - truth)[:, j + 2:]
    assert np.all(err < 5 * 3.0)
    assert np.all(np.sqrt(np.mean(err**2, axis=(0, 2))) < 3.5)  # raw fix noise 3 m at most


# ---------------------------------------------------------------- rule against a loop, edges


def _gate_reference(threshold: float, factor: float, max_rej: int, seq: list[float]
                    ) -> list[tuple[bool, bool, int, float]]:
    """The rule of the module docstring, one ship, written as plain if/else."""
    c = 0
    out = []
    for d in seq:
        window = threshold * (factor**c if c else 1.0)
        if math.isnan(d):
            out.append((False, False, c, window))
            continue
        if d <= window:
            c = 0
            out.append((True, False, c, window))
        else:
            c += 1
            restart = c >= max_rej
            if restart:
                c = 0
            out.append((False, restart, c, window))
    return out


def test_gate_vectorised_equals_the_rule_written_as_a_loop() -> None:
    """200 ships with random thresholds, factors (1 to 3, and inf), counts (1 to 4) and random
    statistics with 15 % NaN, 60 steps: accept, restart, state and window match the loop."""
    rng = np.random.default_rng(91)
    n, steps = 200, 60
    thr = rng.uniform(1, 10, n)
    fac = rng.choice([1.0, 1.5, 2.0, 3.0, np.inf], n)
    cnt = rng.integers(1, 5, n)
    cfg = [{"gate_sigma": t, "reopen_factor": f, "max_rejections": int(c)}
           for t, f, c in zip(thr, fac, cnt, strict=True)]
    p = gating.build(cfg)
    d = rng.uniform(0, 4, (n, steps)) * thr[:, None]
    d[rng.random((n, steps)) < 0.15] = np.nan
    rej = gating.init_state(n)
    got = []
    for k in range(steps):
        g = gating.gate(p, d[:, k], rej)
        rej = g.rejections
        got.append(g)
    for i in range(n):
        ref = _gate_reference(thr[i], fac[i], int(cnt[i]), list(d[i]))
        for k, (acc, rst, c, win) in enumerate(ref):
            g = got[k]
            assert (bool(g.accept[i]), bool(g.restart[i]), int(g.rejections[i])) == \
                (acc, rst, c), (i, k)
            assert g.window[i] == pytest.approx(win, rel=1e-12)


def test_gate_boundary_is_inclusive() -> None:
    """d equal to the window is accepted, the next float above it rejected."""
    p = gating.build([{"window_diameter_m": 100.0}] * 2)
    g = gating.gate(p, np.array([50.0, np.nextafter(50.0, 100.0)]), gating.init_state(2))
    np.testing.assert_array_equal(g.accept, [True, False])
    np.testing.assert_array_equal(g.rejections, [0, 1])


def test_reopen_factor_one_never_opens_and_empty_batch() -> None:
    p = gating.build([{"window_diameter_m": 20.0, "reopen_factor": 1.0, "max_rejections": 5}])
    out = run_gate(p, [15.0, 15.0, 15.0, 9.0])
    assert [w for _, _, w in out] == [10.0, 10.0, 10.0, 10.0]
    assert [a for a, _, _ in out] == [False, False, False, True]
    empty = gating.gate(gating.build([]), np.zeros(0), gating.init_state(0))
    assert empty.accept.shape == (0,) and empty.rejections.dtype == np.int64


def test_infinite_distance_is_a_rejection() -> None:
    """E.g. the normalised distance of a non-zero innovation with zero innovation variance."""
    p = gating.build([{"window_diameter_m": 100.0, "max_rejections": 1}])
    with np.errstate(divide="ignore"):
        d = gating.normalised_distance(np.array([3.0]), np.array([0.0]))
    assert d[0] == np.inf
    g = gating.gate(p, d, gating.init_state(1))
    assert not g.accept[0] and g.restart[0]


@pytest.mark.parametrize("cfg", [{"window_diameter_m": float("nan")},
                                 {"gate_sigma": float("nan")}, {"reopen_factor": float("nan")}])
def test_build_rejects_nan(cfg) -> None:
    with pytest.raises(ValueError):
        gating.build([cfg])


def test_build_refuses_a_window_wider_than_ten_km() -> None:
    """A position window of at most 10 km, ten times the coarsest fix; a normalised gate
    (``gate_sigma``, which takes precedence) has no upper bound."""
    assert gating.build([{"window_diameter_m": 10_000.0}]).threshold[0] == 5000.0
    with pytest.raises(ValueError) as err:
        gating.build([{}, {"window_diameter_m": 10_001.0}])
    assert str(err.value) == "window_diameter_m must be <= 10000, got 10001"
    assert gating.build([{"gate_sigma": 1e6, "window_diameter_m": 1e6}]).threshold[0] == 1e6


def test_normalised_distance_full_equals_diagonal_for_a_diagonal_s() -> None:
    rng = np.random.default_rng(92)
    nu = rng.normal(size=(30, 2))
    diag = rng.uniform(0.1, 5, (30, 2))
    full = np.zeros((30, 2, 2))
    full[:, 0, 0], full[:, 1, 1] = diag[:, 0], diag[:, 1]
    np.testing.assert_allclose(gating.normalised_distance(nu, full),
                               gating.normalised_distance(nu, diag), rtol=1e-12)
    with pytest.raises(ValueError):
        gating.normalised_distance(rng.normal(size=(3, 3)), np.tile(np.eye(3), (3, 1, 1)))


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 5, 9, 10, 31, 100])
def test_chi2_sf_against_scipy(dof: int) -> None:
    """Closed form against scipy.stats over the bulk and the far upper tail (down to 1e-200)."""
    x = np.concatenate([np.linspace(0.01, 3 * dof + 30, 60), [dof + 800.0]])
    for xi in x:
        ref = float(stats.chi2.sf(xi, dof))
        assert gating.chi2_sf(float(xi), dof) == pytest.approx(ref, rel=1e-9, abs=1e-300)
    assert gating.chi2_sf(0.0, dof) == 1.0 and gating.chi2_sf(-1.0, dof) == 1.0


def test_chi2_quantile_agrees_with_scipy_and_the_trackers_even_quantile() -> None:
    for p in (0.5, 0.9, 0.99, 0.9999):
        for dof in (2, 4, 6):
            assert gating.chi2_quantile(p, dof) == pytest.approx(
                tracker.chi2_quantile_even(p, dof), rel=1e-9)
        for dof in (1, 3, 7, 50):
            assert gating.chi2_quantile(p, dof) == pytest.approx(stats.chi2.ppf(p, dof),
                                                                 rel=1e-8)
    for p, dof in ((0.0, 2), (1.0, 2), (0.5, 0)):
        with pytest.raises(ValueError):
            gating.chi2_quantile(p, dof)


def test_nis_gate_on_gaussian_innovations_rejects_its_nominal_fraction() -> None:
    """Innovations drawn with a correlated covariance S: the normalised distance equals the norm
    of the Cholesky-whitened innovation, and the fraction beyond sqrt(chi2_quantile(0.99, 2))
    is 1 % within binomial 4-sigma bounds."""
    rng = np.random.default_rng(47)
    n = 40_000
    S = np.array([[9.0, 4.0], [4.0, 3.0]])
    L = np.linalg.cholesky(S)
    nu = rng.standard_normal((n, 2)) @ L.T
    d = gating.normalised_distance(nu, np.broadcast_to(S, (n, 2, 2)))
    white = np.linalg.solve(L, nu.T).T
    np.testing.assert_allclose(d, np.linalg.norm(white, axis=1), rtol=1e-10)
    thr = math.sqrt(gating.chi2_quantile(0.99, 2))
    frac = np.mean(d > thr)
    assert abs(frac - 0.01) < 4 * math.sqrt(0.01 * 0.99 / n)


@pytest.mark.parametrize("factor,max_rej", [(2.0, 3), (3.0, 2), (1.5, 4)])
def test_a_jump_up_to_the_widest_window_is_taken_without_restart(factor: float,
                                                                max_rej: int) -> None:
    """A genuine jump of exactly threshold * factor^(max_rejections - 1) is accepted at the
    max_rejections-th fix with no restart; one a little farther restarts there instead."""
    thr = 50.0
    p = gating.build([{"window_diameter_m": 2 * thr, "reopen_factor": factor,
                       "max_rejections": max_rej}] * 2)
    widest = thr * factor ** (max_rej - 1)
    d = np.array([widest, widest * 1.001])
    rej = gating.init_state(2)
    for i in range(max_rej - 1):
        g = gating.gate(p, d, rej)
        assert not g.accept.any() and not g.restart.any()
        assert g.rejections.tolist() == [i + 1, i + 1]
        rej = g.rejections
    g = gating.gate(p, d, rej)
    assert g.accept.tolist() == [True, False]
    assert g.restart.tolist() == [False, True]
    assert g.rejections.tolist() == [0, 0]
    np.testing.assert_allclose(g.window, widest)


def test_missing_measurements_keep_the_rejection_count_and_window() -> None:
    """NaN distances neither accept nor reject: the consecutive count and thus the widened
    window survive a gap."""
    p = gating.build([{"window_diameter_m": 20.0}])
    g = gating.gate(p, np.array([50.0]), gating.init_state(1))
    for _ in range(3):
        g2 = gating.gate(p, np.array([np.nan]), g.rejections)
        assert not g2.accept[0] and not g2.restart[0]
        assert g2.rejections[0] == 1 and g2.window[0] == 20.0
    g3 = gating.gate(p, np.array([19.0]), g2.rejections)
    assert g3.accept[0] and g3.window[0] == 20.0  # 10 m radius doubled once


def test_build_gate_sigma_takes_precedence_and_marks_a_normalised_gate() -> None:
    """gate_sigma wins over window_diameter_m and marks the gate as not in metres; the window
    diameter gives a radius of half of it (default 100 m -> 50 m)."""
    p = gating.build([{"gate_sigma": 3.0, "window_diameter_m": 80.0}, {}, {"window_diameter_m":
                                                                          50.0}])
    np.testing.assert_array_equal(p.threshold, [3.0, 50.0, 25.0])
    assert p.metres.tolist() == [False, True, True]
    np.testing.assert_array_equal(p.reopen_factor, 2.0)
    np.testing.assert_array_equal(p.max_rejections, 3)
    for bad in ({"gate_sigma": 0.0}, {"reopen_factor": 0.5}, {"max_rejections": 0},
                {"window_diameter_m": -1.0}):
        with pytest.raises(ValueError, match="gate needs"):
            gating.build([bad])
