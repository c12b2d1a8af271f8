"""The position-fixing filter of seed 002, chapter 6: tables 6.1, 6.2 and the filter itself."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.estimation import gating, linefit

# Table 6.1 "Variation in Gain with Number of Points" [seed 002, 6.4]
TABLE_6_1 = [(2, 0.5556), (3, 0.4375), (4, 0.3600), (5, 0.3056), (6, 0.2653), (7, 0.2344),
             (8, 0.2099), (10, 0.1736)]
# gains printed on figures 6.3a-h (three decimals)
FIGURE_6_3 = [(2, 0.556), (3, 0.437), (4, 0.360), (5, 0.306), (6, 0.265), (7, 0.234),
              (8, 0.210), (10, 0.174)]
# Table 6.2 "Variation in Predicted Error Variance with Measurement Variance": (M, P, digits).
# The extracted text prints P = 7.36 for M = 1; P is proportional to M (K does not depend on M,
# 6.5) and every other entry is K M with K = 0.1736, so the printed "7.36" is an extraction
# defect of 0.1736, tested as such.
TABLE_6_2 = [(1.0, 0.1736, 4), (10.0, 1.736, 3), (25.0, 4.338, 3), (50.0, 8.677, 3),
             (100.0, 17.36, 2), (200.0, 34.71, 2)]


@pytest.mark.parametrize(("n", "gain"), TABLE_6_1)
def test_table_6_1(n: int, gain: float) -> None:
    """K = 1 - 1/A^2 with A = 1 + 1/n, rounded to the printed 4 decimals; the iteration of
    eqs 6.6-6.8 (M = 100, the Decca variance) gives the same."""
    a = linefit.growth_factor(n)
    assert round(float(linefit.steady_gain(a)), 4) == gain
    k, p = linefit.iterate_gain(a, 100.0)
    assert round(float(k), 4) == gain
    assert float(p) == pytest.approx(100.0 * float(k))  # P = K M at the fixed point


@pytest.mark.parametrize(("n", "gain"), FIGURE_6_3)
def test_figure_6_3_gain_labels(n: int, gain: float) -> None:
    assert abs(float(linefit.steady_gain(linefit.growth_factor(n))) - gain) <= 0.0005 + 1e-12


@pytest.mark.parametrize(("m_var", "p_printed", "digits"), TABLE_6_2)
def test_table_6_2(m_var: float, p_printed: float, digits: int) -> None:
    """P after eq 6.8 for n = 10 (A = 1.1, K = 0.1736, the values quoted in 6.4), within one
    unit of the last printed digit: the printout rounds some entries (17.36 from 17.355) and
    truncates others (4.338 from 4.3388, 8.677 from 8.6776)."""
    _, p = linefit.iterate_gain(linefit.growth_factor(10), m_var)
    assert abs(float(p) - p_printed) <= 10.0**-digits + 1e-12


def test_section_6_4_numbers() -> None:
    """6.4: "K = 0.1736 after 70 cycles ... P is 17.36 metres^2" for M = 100. These follow from
    A = 1.1 (= 1 + 1/n, n = 10); the A = 1.111 printed beside them would give K = 0.19. From a
    unit starting variance the 4-decimal K settles at 0.1736 after 72 cycles (thesis: 70)."""
    k, p = linefit.iterate_gain(1.1, 100.0)
    assert round(float(k), 4) == 0.1736 and round(float(p), 2) == 17.36
    rounded = [round(float(linefit.iterate_gain(1.1, 100.0, cycles=c)[0]), 4)
               for c in range(1, 101)]
    settled = next(c for c in range(1, 101) if all(r == 0.1736 for r in rounded[c - 1:]))
    assert 65 <= settled <= 75
    assert round(float(linefit.steady_gain(1.111)), 2) == 0.19
    assert float(linefit.steady_gain(linefit.growth_factor(10, "unbiased"))) == pytest.approx(0.19)


def test_gain_independent_of_measurement_variance() -> None:
    """6.5: with n = 5 "the Kalman gain remains constant irrespective of the variance of the
    measurement process"."""
    k, _ = linefit.iterate_gain(linefit.growth_factor(5), np.array([1.0, 10, 25, 50, 100, 200]),
                                cycles=200)
    np.testing.assert_allclose(k, 11.0 / 36.0, rtol=1e-9)


def track(n_ships: int, steps: int, step_m: float, course_rad: np.ndarray) -> np.ndarray:
    t = np.arange(steps, dtype=float)
    c = np.asarray(course_rad, float)[:, None]
    return np.stack([step_m * t * np.cos(c) + 1000.0, step_m * t * np.sin(c) - 500.0], axis=-1) \
        * np.ones((n_ships, 1, 1))


def test_start_is_unfiltered_then_eq_6_4() -> None:
    p = linefit.build([{"n_points": 4}])
    rng = np.random.default_rng(1)
    z = track(1, 12, 8.0, np.array([0.3])) + rng.normal(0.0, 5.0, (1, 12, 2))
    r = linefit.run(p, z)
    np.testing.assert_array_equal(r.estimate[:, :4], z[:, :4])
    assert np.all(np.isnan(r.prediction[:, :4])) and np.all(np.isfinite(r.prediction[:, 4:]))
    np.testing.assert_allclose(r.estimate[:, 4:],
                               r.prediction[:, 4:] + 0.36 * (z[:, 4:] - r.prediction[:, 4:]))


@pytest.mark.parametrize("course_deg", [0.0, 90.0, 180.0, 270.0, 33.0, 123.0])
@pytest.mark.parametrize("rule", ["thesis", "unbiased"])
def test_prediction_lays_off_growth_times_span(course_deg: float, rule: str) -> None:
    """Points on a line (also due north / east, where one coordinate has zero variance):
    prediction = first + A (last - first), A = 1 + 1/n or n/(n - 1) [seed 002, 6.2, 6.4]."""
    n = 5
    p = linefit.build([{"n_points": n, "extrapolation": rule}])
    pts = track(1, n, 7.0, np.array([np.radians(course_deg)]))
    state = linefit.LineFitState(pts.copy(), np.array([n]))
    a = float(linefit.growth_factor(n, rule))
    expect = pts[:, 0] + a * (pts[:, -1] - pts[:, 0])
    np.testing.assert_allclose(linefit.predict(p, state), expect, atol=1e-9)


@pytest.mark.parametrize("n", [2, 4, 10])
def test_steady_lag_of_the_thesis_rule(n: int) -> None:
    """Noise-free straight track, d = 5 m per fix: the thesis' A = 1 + 1/n settles n/(2n + 1) d
    behind the truth (module docstring); the unbiased rule has no lag."""
    d, steps = 5.0, 300
    course = np.radians(30.0)
    truth = track(2, steps, d, np.array([course, course]))
    p = linefit.build([{"n_points": n}, {"n_points": n, "extrapolation": "unbiased"}])
    e = linefit.run(p, truth).estimate[:, -1] - truth[:, -1]
    along = e @ np.array([np.cos(course), np.sin(course)])
    assert along[0] == pytest.approx(-n / (2 * n + 1) * d, abs=1e-6)
    assert along[1] == pytest.approx(0.0, abs=1e-6)
    assert np.abs(e @ np.array([-np.sin(course), np.cos(course)])).max() < 1e-6


def test_noise_reduction_close_to_k_m() -> None:
    """Straight track, Decca-like fixes (sigma 7.07 m per axis, DRMS 10 m, M = 50 per axis):
    the filtered error variance per axis (lag removed) is at most K M (+10 %), K M being the
    thesis' "predicted error variance" (6.4); measured 0.46, 0.33, 0.17 M for n = 2, 4, 10."""
    rng = np.random.default_rng(7)
    ns, steps, m_var = 600, 200, 50.0
    ns_each = ns // 3
    p = linefit.build([{"n_points": n} for n in (2, 4, 10) for _ in range(ns_each)])
    truth = track(ns, steps, 6.0, rng.uniform(0, 2 * np.pi, ns))
    z = truth + rng.normal(0.0, np.sqrt(m_var), truth.shape)
    e = linefit.run(p, z).estimate[:, 50:] - truth[:, 50:]
    for j, _ in enumerate((2, 4, 10)):
        blk = e[j * ns_each:(j + 1) * ns_each]
        var = (blk - blk.mean(axis=1, keepdims=True)).var(axis=(0, 1)).mean()
        assert var < 1.10 * p.gain[j * ns_each] * m_var
        assert var < 0.5 * m_var


def test_vectorised_over_ships_with_different_n() -> None:
    rng = np.random.default_rng(2)
    cfgs = [{"n_points": 2}, {"n_points": 7}, {"n_points": 4, "extrapolation": "unbiased"},
            {"n_points": 3, "gain": 0.5}]
    z = track(4, 40, 6.0, rng.uniform(0, 6, 4)) + rng.normal(0.0, 5.0, (4, 40, 2))
    z[1, 20] = np.nan  # a missing fix: the prediction is the estimate
    together = linefit.run(linefit.build(cfgs), z).estimate
    for i, c in enumerate(cfgs):
        alone = linefit.run(linefit.build([c]), z[i:i + 1]).estimate
        np.testing.assert_allclose(together[i], alone[0], rtol=1e-12, atol=1e-9)
    r = linefit.run(linefit.build(cfgs), z)
    np.testing.assert_allclose(r.estimate[1, 20], r.prediction[1, 20])


def test_build_checks() -> None:
    with pytest.raises(ValueError):
        linefit.build([{"n_points": 1}])
    with pytest.raises(ValueError):
        linefit.build([{"gain": 1.5}])
    with pytest.raises(ValueError):
        linefit.build([{"extrapolation": "cubic"}])
    p = linefit.build([{}])
    assert p.n_points[0] == 4 and p.gain[0] == pytest.approx(0.36)


# ---------------------------------------------------------------- against a per-ship loop


def _regression_prediction(pts: np.ndarray, growth: float) -> np.ndarray:
    """[seed 002, 6.2]: abscissa = coordinate of larger spread, y on x by np.polyfit, the
    start point plus growth times the span along x, y from the line."""
    spread = ((pts - pts.mean(axis=0)) ** 2).sum(axis=0)
    ix = int(np.argmax(spread))
    iy = 1 - ix
    if spread[ix] > 0:
        a, b = np.polyfit(pts[:, ix], pts[:, iy], 1)
    else:
        a, b = 0.0, pts[:, iy].mean()
    out = np.empty(2)
    out[ix] = pts[0, ix] + growth * (pts[-1, ix] - pts[0, ix])
    out[iy] = a * out[ix] + b
    return out


def _reference_run(n_pts: int, growth: float, gain: float, z: np.ndarray,
                   gate: tuple[float, float, int] | None) -> dict[str, np.ndarray]:
    """The filter of the module docstring for one ship, as a plain loop with a list history."""
    steps = z.shape[0]
    out = {"estimate": np.full((steps, 2), np.nan), "prediction": np.full((steps, 2), np.nan),
           "rejected": np.zeros(steps, bool), "restarted": np.zeros(steps, bool)}
    hist: list[np.ndarray] = []
    fails = 0
    for k in range(steps):
        have = bool(np.all(np.isfinite(z[k])))
        pred = _regression_prediction(np.array(hist[-n_pts:]), growth) \
            if len(hist) >= n_pts else None
        use = have
        if gate is not None and pred is not None and have:
            thr, fac, max_rej = gate
            if np.hypot(*(z[k] - pred)) <= thr * fac**fails:
                fails = 0
            else:
                fails += 1
                use = False
                if fails >= max_rej:
                    fails = 0
                    hist, pred = [], None
                    out["restarted"][k] = True
                else:
                    out["rejected"][k] = True
        if pred is None:
            if have:
                out["estimate"][k] = z[k]
                hist.append(z[k].copy())
            continue
        out["prediction"][k] = pred
        est = pred + gain * (z[k] - pred) if use else pred
        out["estimate"][k] = est
        hist.append(est)
    return out


@pytest.mark.parametrize("gated", [False, True])
def test_run_equals_a_per_ship_loop_with_brute_force_regression(gated: bool) -> None:
    """Ships with n = 2..6, both growth rules, a gain override, noisy curving tracks with
    missing fixes, gross errors and a persistent jump (restart): estimates, predictions and
    the rejected / restarted flags equal a plain loop using np.polyfit."""
    rng = np.random.default_rng(101)
    cfgs = [{"n_points": 2}, {"n_points": 3, "extrapolation": "unbiased"}, {"n_points": 4},
            {"n_points": 5, "gain": 0.5}, {"n_points": 6}, {"n_points": 4, "gain": 0.0}]
    ns, steps = len(cfgs), 80
    t = np.arange(steps, dtype=float)
    head = rng.uniform(0, 2 * np.pi, ns)[:, None] + 0.01 * t
    z = np.stack([np.cumsum(6.0 * np.cos(head), axis=1), np.cumsum(6.0 * np.sin(head), axis=1)],
                 axis=-1) + rng.normal(0, 4.0, (ns, steps, 2))
    z[rng.random((ns, steps)) < 0.1] = np.nan
    gross = rng.random((ns, steps)) < 0.05
    z[gross] += 150.0
    z[:, 60:, 1] += 400.0
    p = linefit.build(cfgs)
    gp = gating.build([{"window_diameter_m": 80.0}] * ns) if gated else None
    r = linefit.run(p, z, gp)
    for i in range(ns):
        ref = _reference_run(int(p.n_points[i]), float(p.growth[i]), float(p.gain[i]), z[i],
                             (40.0, 2.0, 3) if gated else None)
        np.testing.assert_allclose(r.estimate[i], ref["estimate"], rtol=1e-9, atol=1e-7)
        np.testing.assert_allclose(r.prediction[i], ref["prediction"], rtol=1e-9, atol=1e-7)
        np.testing.assert_array_equal(r.rejected[i], ref["rejected"])
        np.testing.assert_array_equal(r.restarted[i], ref["restarted"])
    if gated:
        assert r.restarted.any() and r.rejected.any()
        assert not (r.rejected & r.accepted).any()


def test_stationary_ship_predicts_its_own_position() -> None:
    """All regression points equal (no spread on either axis): the prediction is that point,
    finite, and the filtered estimate stays on it."""
    p = linefit.build([{"n_points": 4}])
    z = np.tile([[[250.0, -40.0]]], (1, 10, 1))
    r = linefit.run(p, z)
    np.testing.assert_allclose(r.prediction[0, 4:], np.tile([250.0, -40.0], (6, 1)))
    np.testing.assert_allclose(r.estimate[0], z[0])


def test_start_takes_every_fix_and_waits_over_missing_ones() -> None:
    """During the unfiltered start a refusal from the gate is ignored and a missing fix gives
    no estimate and does not count towards the n points."""
    p = linefit.build([{"n_points": 3}])
    st = linefit.init_state(p)
    out = linefit.step(p, st, np.array([[1.0, 2.0]]), accept=np.array([False]))
    np.testing.assert_array_equal(out.estimate, [[1.0, 2.0]])
    assert out.state.count[0] == 1
    out = linefit.step(p, out.state, np.array([[np.nan, np.nan]]))
    assert np.all(np.isnan(out.estimate)) and out.state.count[0] == 1
    for z in ([2.0, 4.0], [3.0, 6.0]):
        out = linefit.step(p, out.state, np.array([z]))
    assert out.state.count[0] == 3
    nxt = linefit.step(p, out.state, np.array([[10.0, 10.0]]), accept=np.array([False]))
    a = float(linefit.growth_factor(3))
    np.testing.assert_allclose(nxt.estimate, [[1.0 + 2.0 * a, 2.0 + 4.0 * a]])


def test_restart_forgets_the_history() -> None:
    p = linefit.build([{"n_points": 2}, {"n_points": 2}])
    st = linefit.init_state(p)
    for z in ([0.0, 0.0], [1.0, 0.0], [2.0, 0.0]):
        st = linefit.step(p, st, np.array([z, z])).state
    st = linefit.restart(st, np.array([True, False]))
    out = linefit.step(p, st, np.array([[500.0, 500.0], [3.0, 0.0]]))
    np.testing.assert_array_equal(out.estimate[0], [500.0, 500.0])
    assert np.all(np.isnan(out.prediction[0])) and np.all(np.isfinite(out.prediction[1]))


def test_build_rejects_nan_gain() -> None:
    with pytest.raises(ValueError):
        linefit.build([{"gain": float("nan")}])


@pytest.mark.parametrize("course_deg", [0.0, 33.0, 90.0, 200.0, 315.0])
def test_unbiased_rule_tracks_a_straight_run_exactly_across_gaps(course_deg: float) -> None:
    """Noise-free fixes at constant velocity: with A = n/(n-1) the line prediction is exactly
    the next position, so every estimate is the truth, also through missing fixes (where the
    estimate is the prediction and is pushed into the history)."""
    n_pts, steps, d = 4, 30, 7.0
    c = np.radians(course_deg)
    k = np.arange(steps)
    truth = np.stack([100.0 + d * k * np.cos(c), -50.0 + d * k * np.sin(c)], axis=-1)[None]
    z = truth.copy()
    z[0, [6, 7, 8, 15]] = np.nan
    p = linefit.build([{"n_points": n_pts, "extrapolation": "unbiased"}])
    out = linefit.run(p, z)
    np.testing.assert_allclose(out.estimate, truth, atol=1e-8)
    assert np.all(np.isnan(out.prediction[0, :n_pts]))
    np.testing.assert_allclose(out.prediction[0, n_pts:], truth[0, n_pts:], atol=1e-8)


def test_prediction_is_translation_equivariant_and_swaps_with_the_axes() -> None:
    """Shifting every fix by a constant shifts the prediction by it; exchanging north and east
    exchanges the prediction's components (the abscissa choice follows the spread)."""
    rng = np.random.default_rng(41)
    p = linefit.build([{"n_points": 5}] * 6)
    hist = np.cumsum(rng.normal(0.0, 20.0, (6, 5, 2)), axis=1)
    st = linefit.LineFitState(hist, np.full(6, 5, dtype=np.int64))
    base = linefit.predict(p, st)
    shift = np.array([1234.5, -987.0])
    moved = linefit.predict(p, linefit.LineFitState(hist + shift, st.count))
    np.testing.assert_allclose(moved, base + shift, rtol=1e-12, atol=1e-8)
    swapped = linefit.predict(p, linefit.LineFitState(hist[..., ::-1].copy(), st.count))
    np.testing.assert_allclose(swapped, base[:, ::-1], rtol=1e-12, atol=1e-8)


def test_prediction_equals_numpy_polyfit_on_the_smaller_spread_axis() -> None:
    """The prediction is numpy's least-squares line through the last n points (ordinate the axis
    of smaller spread) evaluated at first + A (last - first) along the other axis."""
    rng = np.random.default_rng(43)
    n_pts = 6
    p = linefit.build([{"n_points": n_pts}])
    for _ in range(20):
        pts = np.column_stack([np.arange(n_pts) * rng.normal(0, 10), np.arange(n_pts)
                               * rng.normal(0, 10)]) + rng.normal(0.0, 2.0, (n_pts, 2))
        pred = linefit.predict(p, linefit.LineFitState(pts[None], np.array([n_pts])))[0]
        ix = int(np.argmax(pts.var(axis=0)))
        iy = 1 - ix
        slope, icept = np.polyfit(pts[:, ix], pts[:, iy], 1)
        x = pts[0, ix] + (1 + 1 / n_pts) * (pts[-1, ix] - pts[0, ix])
        assert pred[ix] == pytest.approx(x)
        assert pred[iy] == pytest.approx(slope * x + icept, abs=1e-8)


def test_iterate_gain_broadcasts_and_reaches_the_fixed_point() -> None:
    """Eqs 6.6-6.8 iterated over a grid of A and M converge to K = 1 - 1/A^2 and P = K M."""
    a = np.array([[1.1], [1.25], [1.5]])
    m = np.array([[1.0, 100.0, 2500.0]])
    k, pvar = linefit.iterate_gain(a, m, cycles=2000)
    assert k.shape == (3, 3)
    np.testing.assert_allclose(k, np.broadcast_to(linefit.steady_gain(a), (3, 3)), rtol=1e-9)
    np.testing.assert_allclose(pvar, k * m, rtol=1e-9)
    with pytest.raises(ValueError, match="extrapolation"):
        linefit.growth_factor(4, "linear")
    with pytest.raises(ValueError, match="n_points"):
        linefit.build([{"n_points": 1}])


def test_empty_batch_runs_to_empty_outputs() -> None:
    """No ships: build, init_state and run give empty arrays, as the other filters do."""
    p = linefit.build([])
    st = linefit.init_state(p)
    assert st.history.shape[0] == 0
    out = linefit.run(p, np.zeros((0, 5, 2)))
    assert out.estimate.shape == (0, 5, 2) and out.accepted.shape == (0, 5)
