import math

import numba
import numpy as np
import pytest

from tests.conftest import packed_divisions, requires_avx
from trafficsim.control import guidance
from trafficsim.control.guidance import LOOKAHEAD_L, TURN_RADIUS_L, RouteState, desired_course


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


def _wrapdiff(a, b):
    """a - b wrapped to [-pi, pi] (courses compare modulo a turn)."""
    return np.remainder(np.asarray(a) - np.asarray(b) + np.pi, 2 * np.pi) - np.pi


@pytest.mark.parametrize("bearing_deg", [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0,
                                         359.9, 0.1])
def test_leg_course_is_the_ned_bearing_clockwise_from_north(bearing_deg):
    """At the leg start the desired course is the bearing of the waypoint: north 0, east
    pi/2, south pi, west 3 pi/2 (modulo a turn)."""
    b = math.radians(bearing_deg)
    wp, n = _route([[3000.0 * math.cos(b), 3000.0 * math.sin(b)]])
    r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
    c = desired_course(r, wp, n, np.zeros(1), np.zeros(1), np.array([100.0]))
    assert abs(_wrapdiff(c[0], b)) < 1e-12


def test_line_of_sight_law_against_vector_geometry():
    """Many ships on legs of random direction, anywhere beside the first half of their leg:
    chi_d = chi_leg - atan(e / (4 L)), e the signed distance to the leg line (positive when
    the ship is on the starboard side, i.e. the leg direction turned clockwise by 90 deg)."""
    rng = np.random.default_rng(50)
    n = 200
    start = rng.uniform(-5000, 5000, (n, 2))
    chi = rng.uniform(-np.pi, np.pi, n)
    u = np.stack([np.cos(chi), np.sin(chi)], axis=1)  # along the leg (north, east)
    stbd = np.stack([-np.sin(chi), np.cos(chi)], axis=1)  # 90 deg clockwise of it
    wp = (start + 4000.0 * u)[:, None, :]
    along, e = rng.uniform(-500, 2000, n), rng.uniform(-3000, 3000, n)
    pos = start + along[:, None] * u + e[:, None] * stbd
    L = rng.uniform(50, 300, n)
    r = RouteState.start(start[:, 0], start[:, 1], np.zeros(n))
    c = desired_course(r, wp, np.ones(n, np.int64), pos[:, 0], pos[:, 1], L)
    expected = chi - np.arctan(e / (LOOKAHEAD_L * L))
    np.testing.assert_allclose(_wrapdiff(c, expected), 0.0, atol=1e-9)
    np.testing.assert_array_equal(r.wp_index, 0)


def test_mirror_positions_steer_mirror_courses():
    """Positions mirrored across the leg give courses mirrored about the leg course; on the
    line the leg course itself; far off it, nearly perpendicular towards the line."""
    chi = math.radians(30.0)
    u, s = np.array([math.cos(chi), math.sin(chi)]), np.array([-math.sin(chi), math.cos(chi)])
    wp = np.array([[10000.0 * u]])
    one = np.ones(1, np.int64)
    out = []
    for off in (400.0, -400.0, 0.0, 1e7, -1e7):
        p = 1000.0 * u + off * s
        r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
        out.append(desired_course(r, wp, one, p[:1], p[1:], np.array([100.0]))[0])
    assert out[0] - chi == pytest.approx(-(out[1] - chi), rel=1e-12)
    assert out[0] < chi < out[1]
    assert out[2] == pytest.approx(chi, abs=1e-12)
    assert out[3] == pytest.approx(chi - math.pi / 2, abs=1e-4)
    assert out[4] == pytest.approx(chi + math.pi / 2, abs=1e-4)


@pytest.mark.parametrize("turn_deg", [10.0, 60.0, 90.0, -90.0, 120.0, 150.0, 170.0, 180.0])
def test_wheel_over_distance_is_the_tangent_circle_geometry(turn_deg):
    """Wheel over when the distance to go is R tan(|dchi| / 2) (R = 3 L; course change capped
    at 150 deg; at least half a length), the same for port and starboard turns: a hair
    before that point the ship stays on its leg, a hair after it is on the next one."""
    L = 100.0
    d = math.radians(turn_deg)
    wp, n = _route([[2000.0, 0.0], [2000.0 + 1000.0 * math.cos(d), 1000.0 * math.sin(d)]])
    wo = max(TURN_RADIUS_L * L * math.tan(min(abs(d), math.radians(150.0)) / 2), 0.5 * L)
    for to_go, index in ((wo + 1e-6, 0), (wo - 1e-6, 1)):
        r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
        c = desired_course(r, wp, n, np.array([2000.0 - to_go]), np.zeros(1), np.array([L]))
        assert r.wp_index[0] == index, to_go
        if index == 1:  # on the next leg, from the waypoint: its course, LOS-corrected
            np.testing.assert_array_equal(r.leg_start[:, 0], wp[0, 0])
            leg = math.atan2(wp[0, 1, 1] - wp[0, 0, 1], wp[0, 1, 0] - wp[0, 0, 0])
            e = to_go * math.sin(d)  # signed offset of the ship from the new leg line
            assert abs(_wrapdiff(c[0], leg - math.atan(e / (LOOKAHEAD_L * L)))) < 1e-9


def test_last_waypoint_is_reached_within_half_a_length_and_its_course_held():
    """The last leg has no turn: the route ends half a length before its last waypoint; from
    then on the last leg's course is held wherever the ship goes."""
    wp, n = _route([[0.0, 1000.0]])
    L = np.array([120.0])
    r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
    desired_course(r, wp, n, np.array([30.0]), np.array([1000.0 - 60.0 - 1e-3]), L)
    assert r.wp_index[0] == 0
    desired_course(r, wp, n, np.array([30.0]), np.array([1000.0 - 60.0]), L)
    assert r.wp_index[0] == 1
    for north, east in ((500.0, 5000.0), (-3000.0, -10.0)):
        c = desired_course(r, wp, n, np.array([north]), np.array([east]), L)
        assert c[0] == pytest.approx(math.pi / 2, abs=1e-15)


def test_a_waypoint_on_the_start_position_is_skipped():
    """A first waypoint at the start position (a zero-length leg) is passed at once and the
    ship steers the leg from it to the second waypoint."""
    wp, n = _route([[0.0, 0.0], [-500.0, 0.0]])
    r = RouteState.start(np.zeros(1), np.zeros(1), np.array([1.0]))
    c = desired_course(r, wp, n, np.zeros(1), np.zeros(1), np.array([50.0]))
    assert r.wp_index[0] == 1
    assert abs(_wrapdiff(c[0], math.pi)) < 1e-12


def test_start_copies_the_heading():
    """The held course is the start heading as it was: later changes to the caller's array
    do not move it."""
    psi = np.array([0.7])
    r = RouteState.start(np.zeros(1), np.zeros(1), psi)
    psi[0] = 2.0
    c = desired_course(r, np.zeros((1, 1, 2)), np.zeros(1, np.int64), np.zeros(1), np.zeros(1),
                       np.array([100.0]))
    assert c[0] == 0.7


def _follow(wps, steps=2400, speed=5.0, dt=2.0, length=100.0):
    """A point ship steering the desired course with a turn rate limit of speed / (2 L)
    (tighter than the guidance's 3 L radius) along a route; returns its track and the
    waypoint index per step."""
    wp, n = _route(wps)
    r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
    pos, psi = np.zeros(2), 0.0
    track, idx = [], []
    for _ in range(steps):
        c = desired_course(r, wp, n, pos[:1], pos[1:], np.array([length]))[0]
        turn = float(np.clip(_wrapdiff(c, psi), -speed / (2 * length) * dt,
                             speed / (2 * length) * dt))
        psi += turn
        pos = pos + speed * dt * np.array([math.cos(psi), math.sin(psi)])
        track.append(pos.copy())
        idx.append(int(r.wp_index[0]))
    return np.array(track), np.array(idx)


def test_a_ship_follows_a_route_leg_by_leg_and_passes_near_each_waypoint():
    """Along a four-waypoint route with turns of 90, 135 and 90 deg the waypoint index only
    grows, one at a time; each waypoint is passed within the cut-corner distance of the
    tangent circle R (1 / cos(dchi / 2) - 1) plus slack for the turn-rate lag, and the
    ship ends on the last leg's line holding its course."""
    wps = [[3000.0, 0.0], [3000.0, 3000.0], [0.0, 0.0], [0.0, -3000.0]]
    track, idx = _follow(wps)
    assert np.all(np.diff(idx) >= 0) and np.all(np.diff(idx) <= 1)
    assert idx[-1] == 4
    R = TURN_RADIUS_L * 100.0
    for k, turn in zip(range(3), (90.0, 135.0, 90.0), strict=True):
        miss = np.hypot(*(track - np.array(wps[k])).T).min()
        assert miss < R * (1 / math.cos(math.radians(turn) / 2) - 1) + 150.0, k
    assert abs(track[-1, 0]) < 5.0 and track[-1, 1] < -3000.0


def test_ships_in_one_call_equal_ships_alone():
    """Several ships with routes of different lengths (padded with their last waypoint) in one
    call give the same courses and route progress, bit for bit, as each ship alone with its
    own unpadded route."""
    routes = [[[2000.0, 0.0], [2000.0, 2000.0], [0.0, 2500.0]], [[-1500.0, 300.0]], [],
              [[100.0, 100.0], [900.0, -400.0]]]
    n = len(routes)
    w = max(len(rt) for rt in routes)
    wp = np.zeros((n, w, 2))
    for i, rt in enumerate(routes):
        if rt:
            wp[i, : len(rt)] = rt
            wp[i, len(rt):] = rt[-1]
    nwp = np.array([len(rt) for rt in routes], dtype=np.int64)
    L = np.array([100.0, 60.0, 80.0, 150.0])
    rng = np.random.default_rng(51)
    path = np.cumsum(rng.normal(0.0, 1.0, (300, n, 2)) + np.array([6.0, 6.5]), axis=0)
    r_all = RouteState.start(np.zeros(n), np.zeros(n), np.array([0.1, 0.2, 0.3, 0.4]))
    alone = [RouteState.start(np.zeros(1), np.zeros(1), np.array([h]))
             for h in (0.1, 0.2, 0.3, 0.4)]
    for p in path:
        c_all = desired_course(r_all, wp, nwp, p[:, 0], p[:, 1], L)
        for i, rt in enumerate(routes):
            wpi = np.array([rt], dtype=float) if rt else np.zeros((1, 1, 2))
            c = desired_course(alone[i], wpi, nwp[i:i + 1], p[i:i + 1, 0], p[i:i + 1, 1],
                               L[i:i + 1])
            assert c[0] == c_all[i]
            assert alone[i].wp_index[0] == r_all.wp_index[i]
    assert list(r_all.wp_index) != [0, 0, 0, 0]


def test_a_repeated_waypoint_is_passed_over_and_the_route_course_held():
    """A route ending in the same point twice holds the course of the leg that reaches it
    (90 deg), as the route without the repeat does; atan2(0, 0) = 0 deg is no course."""
    L = np.array([100.0])
    courses = {}
    for name, wps in (("once", [[0.0, 5000.0]]), ("twice", [[0.0, 5000.0], [0.0, 5000.0]])):
        wp, n = _route(wps)
        r = RouteState.start(np.zeros(1), np.zeros(1), np.array([np.pi / 2]))
        courses[name] = [desired_course(r, wp, n, np.zeros(1), np.array([e]), L)[0]
                         for e in (4000.0, 4990.0, 5000.0, 5010.0, 6000.0)]
        assert r.wp_index[0] == n[0]
    np.testing.assert_allclose(courses["twice"], courses["once"])
    np.testing.assert_allclose(courses["once"], np.pi / 2)


def test_a_repeat_inside_a_route_does_not_change_the_wheel_over():
    """[a, b, b, c] steers like [a, b, c]: the turn at b is towards c (90 deg: wheel-over
    3 L tan 45 deg = 300 m before b), not towards the repeat of b."""
    L = np.array([100.0])
    track = [(650.0, 0.0), (710.0, 0.0), (1000.0, 400.0), (1000.0, 2000.0)]
    out = {}
    for name, wps in (("plain", [[1000.0, 0.0], [1000.0, 1000.0]]),
                      ("repeat", [[1000.0, 0.0], [1000.0, 0.0], [1000.0, 1000.0]])):
        wp, n = _route(wps)
        r = RouteState.start(np.zeros(1), np.zeros(1), np.zeros(1))
        out[name] = [(desired_course(r, wp, n, np.array([p]), np.array([q]), L)[0],
                      wps[min(r.wp_index[0], len(wps) - 1)]) for p, q in track]
    assert [c for c, _ in out["repeat"]] == pytest.approx([c for c, _ in out["plain"]])
    assert [w for _, w in out["repeat"]] == [w for _, w in out["plain"]]


def test_a_route_of_only_the_start_point_holds_the_start_heading():
    wp, n = _route([[100.0, 200.0], [100.0, 200.0]])
    r = RouteState.start(np.array([100.0]), np.array([200.0]), np.array([2.0]))
    c = desired_course(r, wp, n, np.array([100.0]), np.array([200.0]), np.array([100.0]))
    assert c[0] == 2.0 and r.wp_index[0] == 2


@requires_avx
def test_the_loop_over_ships_on_a_leg_is_vectorised() -> None:
    """The steering of ships on a leg compiles to packed divisions of four or eight ships per
    instruction (ymm or zmm registers: a branch in the loop leaves at most the two-wide
    pairing of scalar code). Compiled afresh, since cached code cannot be inspected."""
    n = 16
    rng = np.random.default_rng(2)
    north, east, psi = rng.uniform(-1e4, 1e4, (3, n))
    route = guidance.RouteState.start(north, east, psi)
    fresh = numba.njit(error_model="numpy")(guidance._desired_course.py_func)
    fresh(route.leg_start, route.wp_index, route.hold_course_rad, route.leg, route.leg_index,
          rng.uniform(-3e4, 3e4, (n, 2, 2)), np.full(n, 2), north, east, np.full(n, 100.0),
          np.empty(n))
    assert packed_divisions(fresh.inspect_asm(fresh.signatures[0]))
