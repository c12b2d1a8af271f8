"""The map projection: north up, one scale, every point of a fitted view inside its area."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trafficsim.render.view import CLIP_PX, View, fit, follow, nice_length_m
from trafficsim.units import NM

coords = st.floats(-1e5, 1e5, allow_nan=False)


def test_north_is_up_and_east_is_right():
    view = View(200, 100, 1000.0, -500.0, 10.0, 100.0, 50.0)
    x, y = view.to_px(np.array([1000.0, 1100.0, 1000.0]), np.array([-500.0, -500.0, -400.0]))
    np.testing.assert_allclose(x, [100.0, 100.0, 110.0])
    np.testing.assert_allclose(y, [50.0, 40.0, 50.0])
    assert view.points(np.array([1000.0]), np.array([-500.0])).tolist() == [[100, 50]]


@given(coords, coords)
def test_pixels_map_back_to_metres(north, east):
    view = View(640, 480, 123.0, -456.0, 7.5, 300.0, 250.0)
    x, y = view.to_px(north, east)
    n, e = view.to_m(x, y)
    assert abs(n - north) < 1e-6 and abs(e - east) < 1e-6


@given(st.lists(st.tuples(coords, coords), min_size=1, max_size=30))
def test_fit_keeps_every_point_inside_its_area(points):
    north, east = np.array(points).T
    area = (10, 40, 500, 300)
    view = fit(north, east, 640, 480, margin=0.05, area=area)
    x, y = view.to_px(north, east)
    assert np.all(x >= area[0]) and np.all(x <= area[0] + area[2])
    assert np.all(y >= area[1]) and np.all(y <= area[1] + area[3])
    assert view.m_per_px >= NM / 500  # never closer than the smallest extent


def test_fit_ignores_nan_and_follow_scale():
    view = fit(np.array([0.0, np.nan, 5000.0]), np.array([0.0, 7.0, 0.0]), 100, 100,
               margin=0.0)
    assert view.m_per_px == 50.0 and view.centre_north_m == 2500.0
    assert follow(3 * NM, 800, 600).m_per_px == 3 * NM / 300


def test_scale_bar_lengths_are_round():
    assert nice_length_m(10.0, 200.0) == (NM, "1 NM")
    assert nice_length_m(1.0, 120.0) == (100.0, "100 m")
    assert nice_length_m(100.0, 200.0) == (10 * NM, "10 NM")


def test_fit_by_hand_whole_frame():
    """Points (0, 0) and (1000 N, 4000 E) in 500 x 300 px, 10 % margins: the east span
    4000 m fills 0.8 * 500 = 400 px, so 10 m/px (the north span 1852 m -- the smallest extent --
    would need only 7.7 m/px); centre (500 N, 2000 E) at pixel (250, 150)."""
    view = fit(np.array([0.0, 1000.0]), np.array([0.0, 4000.0]), 500, 300, margin=0.1)
    assert view.m_per_px == 10.0
    assert (view.centre_north_m, view.centre_east_m) == (500.0, 2000.0)
    assert (view.origin_x_px, view.origin_y_px) == (250.0, 150.0)
    x, y = view.to_px(np.array([0.0, 1000.0]), np.array([0.0, 4000.0]))
    np.testing.assert_allclose(x, [50.0, 450.0])  # 250 -/+ 2000 m / 10 m/px: 10 % of 500 free
    np.testing.assert_allclose(y, [200.0, 100.0])  # south point lower on the screen


def test_fit_by_hand_inside_an_area():
    """Area left 100, top 50, 400 x 200 px, no margin: the north span 2000 m over 200 px gives
    10 m/px (east needs 1852 / 400 = 4.6); the extreme points land on the area's top and
    bottom edges, the centre on the area's middle (300, 150)."""
    view = fit(np.array([0.0, 2000.0]), np.array([0.0, 1000.0]), 600, 300, margin=0.0,
               area=(100, 50, 400, 200))
    assert view.m_per_px == 10.0 and (view.origin_x_px, view.origin_y_px) == (300.0, 150.0)
    x, y = view.to_px(np.array([0.0, 2000.0]), np.array([0.0, 1000.0]))
    np.testing.assert_allclose(x, [250.0, 350.0])
    np.testing.assert_allclose(y, [250.0, 50.0])
    assert (view.width_px, view.height_px) == (600, 300)


def test_fit_of_no_finite_point_shows_the_smallest_extent_round_the_origin():
    view = fit(np.array([np.nan, np.inf]), np.array([1.0, np.nan]), 200, 100)
    assert (view.centre_north_m, view.centre_east_m) == (0.0, 0.0)
    assert view.m_per_px == pytest.approx(NM / (0.88 * 100))  # height is the tighter side


def test_follow_by_hand_inside_an_area():
    """Range 1000 m to the nearer edge of a 300 x 200 px area at (0, 40): 1000 m over 100 px
    is 10 m/px; centred on a ship at (5000 N, -300 E), a point 500 m north of it is 50 px
    above the area's middle (150, 140)."""
    view = follow(1000.0, 640, 480, area=(0, 40, 300, 200)).centred_on(5000.0, -300.0)
    assert view.m_per_px == 10.0 and (view.origin_x_px, view.origin_y_px) == (150.0, 140.0)
    x, y = view.to_px(np.array([5000.0, 5500.0, 5000.0]), np.array([-300.0, -300.0, -1300.0]))
    np.testing.assert_allclose(x, [150.0, 150.0, 50.0])
    np.testing.assert_allclose(y, [140.0, 90.0, 140.0])


def test_points_floor_towards_minus_infinity_and_far_points_clip():
    """A point maps to the pixel floor(x), floor(y): -0.5 px is pixel -1, not 0 (truncation
    would put two columns of points on pixel 0); far points are clipped, NaN stays NaN."""
    view = View(10, 10, 0.0, 0.0, 1.0, 0.0, 0.0)
    pts = view.points(np.array([0.5, -0.25, 0.0]), np.array([-0.5, 0.999, 2.0]))
    assert pts.tolist() == [[-1, -1], [0, 0], [2, 0]]
    x, y = view.to_px(np.array([1e12, -1e12, np.nan]), np.array([-1e12, 1e12, 0.0]))
    assert x[:2].tolist() == [-CLIP_PX, CLIP_PX] and y[:2].tolist() == [-CLIP_PX, CLIP_PX]
    assert np.isnan(y[2]) and x[2] == 0.0


@given(coords, coords, st.floats(1.0, 100.0))
def test_moving_north_goes_up_and_east_goes_right(north, east, scale):
    """One step north is ``1 / m_per_px`` px up, one step east the same to the right (one
    scale for both axes keeps shapes; scales from 1 m/px keep these points inside the clip)."""
    view = View(640, 480, 10.0, 20.0, scale, 300.0, 200.0)
    x0, y0 = view.to_px(north, east)
    x1, y1 = view.to_px(north + 50.0, east)
    x2, y2 = view.to_px(north, east + 50.0)
    assert x1 == pytest.approx(x0) and y0 - y1 == pytest.approx(50.0 / scale, rel=1e-9)
    assert y2 == pytest.approx(y0) and x2 - x0 == pytest.approx(50.0 / scale, rel=1e-9)


def test_centred_on_keeps_scale_size_and_origin():
    view = View(640, 480, 0.0, 0.0, 7.0, 300.0, 250.0)
    moved = view.centred_on(123.0, -45.0)
    assert (moved.m_per_px, moved.origin_x_px, moved.origin_y_px, moved.width_px) == (
        7.0, 300.0, 250.0, 640)
    x, y = moved.to_px(np.array(123.0), np.array(-45.0))
    assert (float(x), float(y)) == (300.0, 250.0)
    assert view.centre_north_m == 0.0  # frozen: a new view, the old one unchanged


@pytest.mark.parametrize(("m_per_px", "target", "expected"), [
    (NM / 100.0, 100.0, (NM, "1 NM")),               # exactly 1 NM wanted
    (0.1 * NM / 100.0, 100.0, (0.1 * NM, "0.1 NM")),  # exactly 0.1 NM
    (0.0999 * NM / 100.0, 100.0, (100.0, "100 m")),  # just under 0.1 NM: metres
    (0.3, 10.0, (2.0, "2 m")),                       # 3 m wanted
    (0.001, 100.0, (1.0, "1 m")),                    # under 1 m: the smallest bar
    (1e4, 1e4, (50.0 * NM, "50 NM")),                # far beyond: the largest bar
])
def test_scale_bar_boundaries(m_per_px, target, expected):
    length, label = nice_length_m(m_per_px, target)
    assert (length, label) == (pytest.approx(expected[0]), expected[1])
    assert length <= max(m_per_px * target, 1.0)  # never longer than asked (bar fits)


@given(st.floats(-5000.0, 5000.0), st.floats(-5000.0, 5000.0))
def test_metres_of_a_pixel_map_back_to_that_pixel(x_px, y_px):
    """``to_m`` then ``to_px`` returns the pixel coordinates (the two are inverses both ways)."""
    view = View(640, 480, -321.0, 987.0, 3.25, 310.5, 201.0)
    n, e = view.to_m(x_px, y_px)
    x, y = view.to_px(n, e)
    assert x == pytest.approx(x_px, abs=1e-9) and y == pytest.approx(y_px, abs=1e-9)


def test_follow_range_reaches_the_nearer_edge_only():
    """Range 1000 m in a 300 x 200 px frame: the nearer edges are top and bottom, 100 px from
    the centre (150, 100), so 10 m/px; 1000 m north is row 0, 1000 m south row 200, while
    1000 m east is only column 250 (the wider side shows more)."""
    view = follow(1000.0, 300, 200).centred_on(-40.0, 70.0)
    assert view.m_per_px == 10.0
    x, y = view.to_px(np.array([960.0, -1040.0, -40.0]), np.array([70.0, 70.0, 1070.0]))
    np.testing.assert_allclose(x, [150.0, 150.0, 250.0])
    np.testing.assert_allclose(y, [0.0, 200.0, 100.0])


def test_points_of_any_shape_are_the_floors_of_to_px():
    """``points`` of ``(n, 6)`` arrays (hull outlines) is ``(n, 6, 2)``, each entry the floor of
    the float pixel, checked point by point."""
    view = View(100, 100, 3.0, -7.0, 2.5, 50.0, 50.0)
    rng = np.random.default_rng(4)
    north, east = rng.uniform(-200, 200, (3, 6)), rng.uniform(-200, 200, (3, 6))
    pts = view.points(north, east)
    assert pts.shape == (3, 6, 2) and pts.dtype == np.int64
    for i in range(3):
        for j in range(6):
            x = 50.0 + (east[i, j] + 7.0) / 2.5
            y = 50.0 - (north[i, j] - 3.0) / 2.5
            assert pts[i, j].tolist() == [int(np.floor(x)), int(np.floor(y))]


def test_fit_of_one_point_centres_it_at_the_smallest_extent():
    """A lone ship at (1234 N, -567 E) in 400 x 200 px: the 1 NM extent over 0.88 * 200 px
    (the tighter side), the ship on the frame's middle pixel corner (200, 100)."""
    view = fit(np.array([1234.0]), np.array([-567.0]), 400, 200)
    assert view.m_per_px == pytest.approx(NM / 176.0)
    x, y = view.to_px(np.array([1234.0]), np.array([-567.0]))
    assert (float(x[0]), float(y[0])) == (200.0, 100.0)


@given(st.lists(st.tuples(coords, coords), min_size=1, max_size=20), coords, coords)
def test_fit_moves_with_the_points_and_keeps_its_scale(points, dn, de):
    """Shifting every point by (dn, de) shifts the view's centre by the same and leaves the
    scale, so every point keeps its pixel."""
    north, east = np.array(points).T
    a = fit(north, east, 300, 200)
    b = fit(north + dn, east + de, 300, 200)
    assert b.m_per_px == pytest.approx(a.m_per_px, rel=1e-9)
    assert b.centre_north_m == pytest.approx(a.centre_north_m + dn, abs=1e-6)
    assert b.centre_east_m == pytest.approx(a.centre_east_m + de, abs=1e-6)
    xa, ya = a.to_px(north, east)
    xb, yb = b.to_px(north + dn, east + de)
    np.testing.assert_allclose(xb, xa, atol=1e-6)
    np.testing.assert_allclose(yb, ya, atol=1e-6)


def test_fit_swapping_the_axes_swaps_the_frame():
    """North/east points in a w x h frame and the same points with north and east swapped in
    an h x w frame need the same scale (one scale for both axes)."""
    north, east = np.array([0.0, 3000.0, 500.0]), np.array([-800.0, 4000.0, 100.0])
    assert fit(north, east, 500, 300).m_per_px == pytest.approx(
        fit(east, north, 300, 500).m_per_px)
