"""The map projection: north up, one scale, every point of a fitted view inside its area."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from trafficsim.render.view import View, fit, follow, nice_length_m
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
