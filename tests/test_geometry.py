import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from trafficsim.geometry import NORM_MARGIN, cpa, hull_outlines, hulls_overlap, hypot_below

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
