import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from trafficsim import geometry
from trafficsim.geometry import (
    NORM_MARGIN,
    atan2,
    cpa,
    hull_outlines,
    hulls_overlap,
    hypot_below,
    norm_side,
)
from trafficsim.jit import kernel

finite = st.floats(-1e5, 1e5, allow_nan=False)
speed = st.floats(-30, 30, allow_nan=False)


def test_cpa_head_on_and_parallel():
    dcpa, tcpa = cpa(np.array([1000.0]), np.array([0.0]), np.array([-10.0]), np.array([0.0]))
    assert dcpa[0] == 0.0 and tcpa[0] == 100.0
    dcpa, tcpa = cpa(np.array([1000.0]), np.array([50.0]), np.array([0.0]), np.array([0.0]))
    assert dcpa[0] == np.hypot(1000, 50) and tcpa[0] == 0.0


@given(finite, finite, speed, speed)
def test_cpa_is_symmetric_between_the_two_ships(n, e, vn, ve):
    d1, t1 = cpa(np.array([n]), np.array([e]), np.array([vn]), np.array([ve]))
    d2, t2 = cpa(np.array([-n]), np.array([-e]), np.array([-vn]), np.array([-ve]))
    assert np.allclose(d1, d2) and np.allclose(t1, t2)
    assert d1[0] <= np.hypot(n, e) + 1e-6


def test_hull_outline_points_the_bow_along_the_heading():
    hull = hull_outlines(np.array([0.0]), np.array([0.0]), np.array([np.pi / 2]),
                         np.array([100.0]), np.array([20.0]))
    bow = hull[0, 2]
    assert np.allclose(bow, [0.0, 50.0])  # heading east: bow 50 m east


def test_hulls_overlap_only_when_touching():
    z = np.zeros(2)
    a = hull_outlines(z, z, z, np.full(2, 100.0), np.full(2, 20.0))
    b = hull_outlines(np.array([90.0, 110.0]), z, z, np.full(2, 100.0), np.full(2, 20.0))
    assert hulls_overlap(a, b).tolist() == [True, False]


@settings(max_examples=500, deadline=None)  # (the first call compiles)
@given(st.floats(), st.floats(), st.floats())
def test_hypot_below_is_the_comparison_it_replaces(a, b, limit):
    assert hypot_below(a, b, limit) == (math.hypot(a, b) < limit)


def test_hypot_below_decides_within_the_margin_by_hypot_itself():
    """Points on, just inside and just outside a circle, at every bearing and at the edge of
    the band where the squares alone no longer decide."""
    for limit in (1e-3, 1.0, 926.0, 3.7e4):
        for bearing in np.radians(np.arange(0.0, 360.0, 7.5)):
            for f in (1.0, 1.0 - 1e-16, 1.0 + 1e-15, 1.0 - NORM_MARGIN, 1.0 + NORM_MARGIN,
                      1.0 - 2 * NORM_MARGIN, 1.0 + 2 * NORM_MARGIN):
                a, b = f * limit * math.cos(bearing), f * limit * math.sin(bearing)
                assert hypot_below(a, b, limit) == (math.hypot(a, b) < limit)


def _near_ties(rng, n):
    """Points at log-uniform sizes (1e-100 to 1e100) with limits a relative ``delta`` from
    their norm: well inside, at twice the margin, just inside the margin, on it."""
    a = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-100, 100, n)
    b = a * rng.uniform(-3.0, 3.0, n)
    scale = 10.0 ** rng.uniform(-3, 3, n)
    delta = rng.choice([-1e-3, -2 * NORM_MARGIN, -0.5 * NORM_MARGIN, 0.0, 0.5 * NORM_MARGIN,
                        2 * NORM_MARGIN, 1e-3], n)
    limit = np.hypot(a, b) / scale * (1.0 + delta)
    return a, b, limit, scale, delta


def test_norm_side_is_never_wrong_and_decides_outside_the_margin():
    """+1 only when ``hypot / scale > limit`` and -1 only when below (checked with hypot
    itself); with the limit at twice the margin or more from the norm the squares decide."""
    rng = np.random.default_rng(0)
    a, b, limit, scale, delta = _near_ties(rng, 20_000)
    for i in range(a.size):
        side = norm_side(a[i], b[i], limit[i], scale[i])
        value = math.hypot(a[i], b[i]) / scale[i]
        if side == 1:
            assert value > limit[i]
        elif side == -1:
            assert value < limit[i]
        if abs(delta[i]) >= 2 * NORM_MARGIN:
            assert side == (-1 if delta[i] > 0 else 1)


def test_norm_side_on_exact_ties_nan_infinity_and_zero():
    """Pythagorean triples on their circle (at several binary scales) are ties (0); NaN is
    undecided; an infinite offset is surely above a finite limit; the origin against a zero
    limit is a tie, any other point surely above it."""
    for p, q, r in ((3, 4, 5), (5, 12, 13), (8, 15, 17), (20, 21, 29)):
        for k in (-40, 0, 40):
            s = 2.0**k
            assert norm_side(p * s, q * s, r * s, 1.0) == 0
            assert norm_side(p * s, q * s, r, s) == 0
    assert norm_side(math.nan, 1.0, 1.0, 1.0) == 0 and norm_side(1.0, 1.0, math.nan, 1.0) == 0
    assert norm_side(math.inf, 0.0, 1e100, 1.0) == 1
    assert norm_side(0.0, 0.0, 0.0, 1.0) == 0 and norm_side(1e-3, 0.0, 0.0, 1.0) == 1
    assert not hypot_below(0.0, 0.0, 0.0) and not hypot_below(0.0, 0.0, -1.0)


def test_hypot_below_with_squares_in_the_subnormal_range():
    """hypot(1.6e-162, 1.6e-162) = 2.26e-162 < 2.4e-162, but each square (2.56e-324) rounds
    to the smallest subnormal 4.9e-324, so the sum of squares (9.9e-324) exceeds the
    limit's square (5.76e-324, also rounded to 4.9e-324): the squares do not decide here."""
    a = b = 1.6e-162
    assert math.hypot(a, b) < 2.4e-162
    assert norm_side(a, b, 2.4e-162, 1.0) != 1
    assert hypot_below(a, b, 2.4e-162)


def test_cpa_against_a_brute_force_search_over_time():
    """DCPA is the least distance over a fine time grid (the grid minimum can only be larger,
    by at most the distance run in half a grid step) and it is reached at TCPA."""
    rng = np.random.default_rng(1)
    n = 200
    rn, re = rng.uniform(-5000, 5000, n), rng.uniform(-5000, 5000, n)
    vn, ve = rng.uniform(-10, 10, n), rng.uniform(-10, 10, n)
    dcpa, tcpa = cpa(rn, re, vn, ve)
    t = np.linspace(-3000.0, 3000.0, 60001)  # 0.1 s
    for i in range(n):
        d = np.hypot(rn[i] + vn[i] * t, re[i] + ve[i] * t)
        speed = math.hypot(vn[i], ve[i])
        if -3000.0 < tcpa[i] < 3000.0:
            assert dcpa[i] <= d.min() + 1e-9
            assert d.min() - dcpa[i] <= 0.05 * speed + 1e-9
        assert math.hypot(rn[i] + vn[i] * tcpa[i], re[i] + ve[i] * tcpa[i]) == pytest.approx(
            dcpa[i], rel=1e-9, abs=1e-6)


def test_cpa_of_no_relative_motion_empty_and_past_encounters():
    """Relative speed at or below 1e-6 m/s: the range now, TCPA 0; no pairs: empty arrays;
    ships moving apart: TCPA < 0 and DCPA is less than the range now."""
    d, t = cpa(np.array([30.0, 30.0]), np.array([40.0, 40.0]), np.array([0.0, 1e-7]),
               np.array([0.0, 0.0]))
    np.testing.assert_array_equal(d, [50.0, 50.0])
    np.testing.assert_array_equal(t, [0.0, 0.0])
    d, t = cpa(*(np.zeros(0),) * 4)
    assert d.shape == (0,) and t.shape == (0,)
    d, t = cpa(np.array([100.0]), np.array([10.0]), np.array([5.0]), np.array([0.0]))
    assert t[0] == pytest.approx(-20.0) and d[0] == pytest.approx(10.0)


def test_hull_outline_area_and_shape_do_not_depend_on_heading():
    """Area of the pentagon: 0.8 L x B rectangle plus a 0.2 L x B triangle = 0.9 L B; the
    outline is closed, centred on the reference point along the ship, and the bow is at
    L / 2 along the heading, whatever the heading."""
    import shapely

    rng = np.random.default_rng(2)
    k = 50
    north, east = rng.uniform(-1e3, 1e3, k), rng.uniform(-1e3, 1e3, k)
    heading = rng.uniform(-10.0, 10.0, k)
    length, beam = rng.uniform(10.0, 400.0, k), rng.uniform(2.0, 60.0, k)
    hull = hull_outlines(north, east, heading, length, beam)
    assert hull.shape == (k, 6, 2)
    np.testing.assert_array_equal(hull[:, 0], hull[:, -1])
    np.testing.assert_allclose(shapely.area(shapely.polygons(hull)), 0.9 * length * beam,
                               rtol=1e-9)
    bow = hull[:, 2]
    np.testing.assert_allclose(bow[:, 0], north + 0.5 * length * np.cos(heading), atol=1e-9)
    np.testing.assert_allclose(bow[:, 1], east + 0.5 * length * np.sin(heading), atol=1e-9)


def test_hulls_touching_side_by_side_overlap_and_the_test_is_symmetric():
    """Two 100 x 20 m hulls heading north: centres 20 m apart abeam touch (overlap), 20.01 m
    apart do not; ``a`` against ``b`` equals ``b`` against ``a``; no pairs, no answers."""
    z = np.zeros(3)
    a = hull_outlines(z, z, z, np.full(3, 100.0), np.full(3, 20.0))
    b = hull_outlines(z, np.array([20.0, 20.01, -19.99]), z, np.full(3, 100.0),
                      np.full(3, 20.0))
    assert hulls_overlap(a, b).tolist() == [True, False, True]
    assert hulls_overlap(b, a).tolist() == [True, False, True]
    assert hulls_overlap(np.zeros((0, 6, 2)), np.zeros((0, 6, 2))).shape == (0,)


@pytest.mark.parametrize("d", [0.0, 1e-9, -0.003, 0.03, -0.0625, 0.0625, 0.0626, -0.7, 3.0])
@pytest.mark.parametrize("angle", [0.0, 1.1, -2.5, 6.2])
def test_turned_is_the_cosine_and_sine_of_the_sum(angle: float, d: float) -> None:
    """The RK4 stages turn the step's cosine and sine by the heading change: within a few
    rounding errors of libm's values of the summed angle (whose own sum rounds by up to half
    an ulp of ``angle + d``), on both sides of the series' reach."""
    c, s = geometry.turned(math.cos(angle), math.sin(angle), d)
    tol = 4e-16 + 0.5 * math.ulp(angle + d)
    assert c == pytest.approx(math.cos(angle + d), abs=tol)
    assert s == pytest.approx(math.sin(angle + d), abs=tol)


def test_the_series_is_exact_to_rounding_at_its_reach() -> None:
    """Truncation of the cos/sin series at the largest turn they serve is below rounding."""
    d = np.linspace(-geometry.SERIES_TURN_RAD, geometry.SERIES_TURN_RAD, 2001)
    got = np.array([geometry.turned(1.0, 0.0, v) for v in d])
    np.testing.assert_allclose(got[:, 0], np.cos(d), rtol=0, atol=2.3e-16)
    np.testing.assert_allclose(got[:, 1], np.sin(d), rtol=0, atol=2.3e-16)


@kernel
def _cos_sin_all(angle: np.ndarray, out: np.ndarray) -> None:
    for i in range(angle.shape[0]):
        out[0, i], out[1, i] = geometry.cos_sin(angle[i])


def test_cos_sin_is_within_one_ulp_of_libm() -> None:
    """The call-free cosine and sine agree with libm's to one unit in the last place, across
    headings, their stages, and angles up to the reach of the reduction (quadrant edges,
    multiples of pi/2 and the sign of the angle included)."""
    rng = np.random.default_rng(7)
    edges = np.arange(-40, 41) * (math.pi / 4.0)
    angle = np.concatenate([rng.uniform(-20.0, 20.0, 200_000), edges, np.nextafter(edges, 9.0),
                            rng.uniform(-geometry.COS_SIN_MAX_RAD, geometry.COS_SIN_MAX_RAD,
                                        20_000), [0.0, 1e-300, -1e-12, 2.0 * math.pi]])
    got = np.empty((2, angle.size))
    _cos_sin_all(angle, got)
    for value, ref in ((got[0], np.cos(angle)), (got[1], np.sin(angle))):
        assert np.all(np.abs(value - ref) <= np.spacing(np.abs(ref)))
    assert np.mean(got[0] == np.cos(angle)) > 0.7  # mostly the same bits


def test_cos_sin_of_nan_is_nan() -> None:
    got = np.empty((2, 1))
    _cos_sin_all(np.array([math.nan]), got)
    assert np.isnan(got).all()


@kernel
def _atan_all(x: np.ndarray, out: np.ndarray) -> None:
    for i in range(x.shape[0]):
        out[i] = geometry.atan(x[i])


def test_atan_is_within_two_ulp_of_libm() -> None:
    """The call-free arctangent agrees with libm's to two units in the last place over the
    whole line: the breakpoints and thresholds of its reduction, +-1, tiny, huge and infinite
    arguments; NaN stays NaN."""
    rng = np.random.default_rng(8)
    splits = np.tan(np.arange(-11, 12) * math.pi / 24.0)
    x = np.concatenate([rng.uniform(-2.0, 2.0, 200_000), rng.standard_cauchy(100_000),
                        10.0 ** rng.uniform(-300, 300, 50_000) * rng.choice([-1.0, 1.0], 50_000),
                        splits, np.nextafter(splits, 9.0), np.nextafter(splits, -9.0),
                        [0.0, 1.0, -1.0, np.inf, -np.inf, 5e-324, -1e-310]])
    got = np.empty_like(x)
    _atan_all(x, got)
    ref = np.arctan(x)
    assert np.all(np.abs(got - ref) <= 2.0 * np.spacing(np.abs(ref)))
    assert np.mean(got == ref) > 0.6
    nan = np.empty(1)
    _atan_all(np.array([math.nan]), nan)
    assert math.isnan(nan[0])


def test_atan2_matches_the_library_everywhere():
    rng = np.random.default_rng(7)
    n = 200_000
    y = rng.normal(size=n) * 10.0 ** rng.uniform(-9, 9, n)
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-9, 9, n)
    err = max(abs(atan2(a, b) - math.atan2(a, b)) for a, b in zip(y, x, strict=True))
    assert err < 2e-15
    # the axes, the diagonals and the octant edges
    for deg in np.arange(-180.0, 180.01, 22.5):
        a = math.radians(deg)
        s, c = math.sin(a), math.cos(a)
        assert atan2(s, c) == pytest.approx(math.atan2(s, c), abs=2e-15)
    assert atan2(0.0, -1.0) == math.pi and atan2(0.0, 0.0) == 0.0
    assert math.isnan(atan2(math.nan, 1.0)) and math.isnan(atan2(1.0, math.nan))


@settings(max_examples=500, deadline=None)
@given(st.floats(-1e12, 1e12, allow_nan=False), st.floats(-1e12, 1e12, allow_nan=False))
def test_atan2_property(y, x):
    assume(x != 0.0 or y != 0.0)
    assert atan2(y, x) == pytest.approx(math.atan2(y, x), abs=2e-15)
