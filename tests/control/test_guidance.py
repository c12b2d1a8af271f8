import numpy as np

from trafficsim.control.guidance import RouteState, desired_course


def _route(wps):
    w = np.array([wps], dtype=float)
    return w, np.array([len(wps)])


def test_on_the_leg_steers_the_leg_course():
    wp, n = _route([[1000.0, 1000.0]])
    r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
    c = desired_course(r, wp, n, np.zeros(1), np.zeros(1), np.array([100.0]))
    assert np.isclose(c[0], np.pi / 4)


def test_cross_track_error_steers_back_towards_the_leg():
    wp, n = _route([[5000.0, 0.0]])
    r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
    c = desired_course(r, wp, n, np.array([100.0]), np.array([200.0]), np.array([100.0]))
    assert -np.pi / 2 < c[0] < 0.0  # 200 m to starboard: steer to port


def test_wheel_over_switches_before_the_waypoint_and_last_leg_course_is_held():
    wp, n = _route([[1000.0, 0.0], [1000.0, 1000.0]])
    r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
    L = np.array([100.0])
    # 90 deg turn, R = 3 L -> wheel-over 300 m before the waypoint
    desired_course(r, wp, n, np.array([650.0]), np.zeros(1), L)
    assert r.wp_index[0] == 0
    c = desired_course(r, wp, n, np.array([710.0]), np.zeros(1), L)
    assert r.wp_index[0] == 1 and 0.0 < c[0] <= np.pi / 2
    c = desired_course(r, wp, n, np.array([1000.0]), np.array([960.0]), L)
    assert r.wp_index[0] == 2 and np.isclose(c[0], np.pi / 2)
    c = desired_course(r, wp, n, np.array([1200.0]), np.array([2000.0]), L)
    assert np.isclose(c[0], np.pi / 2)  # route done: hold the last leg's course


def test_no_route_holds_the_initial_heading():
    wp = np.zeros((2, 1, 2))
    n = np.zeros(2, dtype=np.int64)
    r = RouteState.start(np.zeros(2), np.zeros(2), np.array([0.3, 4.0]))
    c = desired_course(r, wp, n, np.array([50.0, -30.0]), np.array([10.0, 5.0]), np.full(2, 80.0))
    assert np.allclose(c, [0.3, 4.0])
