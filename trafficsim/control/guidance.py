"""Route guidance: line-of-sight steering along waypoint legs with a wheel-over point.

Each ship follows the leg from its previous waypoint (initially its start position) to its
current waypoint. The desired course is the leg course corrected by the line-of-sight law
chi_d = chi_leg - atan(e / Delta), e the cross-track error (positive to starboard of the leg) and
Delta the look-ahead distance (Fossen 2011, eq. 10.73). The ship moves to the next leg at the
wheel-over point, when the distance to go along the leg falls below R tan(|dchi| / 2), R the
turning radius and dchi the course change at the waypoint (the geometry of a circular turn
tangent to both legs). After the last waypoint the ship holds the last leg's course. A
waypoint that repeats the point before it (or the start) has no leg and is passed over.

Compiled loops over ships (:func:`_desired_course`); no Python loop per ship. The constants of
a ship's current leg (course, direction, length, wheel-over distance) are worked out when it
starts the leg and kept, so a step costs one arctangent per ship, in a vectorised loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trafficsim.geometry import atan
from trafficsim.jit import kernel

#: look-ahead distance and turning radius in ship lengths
LOOKAHEAD_L = 4.0
TURN_RADIUS_L = 3.0
_MAX_TURN = math.radians(150.0)


@dataclass
class RouteState:
    """Progress of every ship along its route, ``(n,)`` arrays.

    Attributes:
        leg_start: ``(2, n)`` north/east of the current leg's start, m.
        wp_index: index of the waypoint being steered to (== n_waypoints when the route is done).
        hold_course_rad: course held when there is no (more) route.
        leg: ``(5, n)`` constants of the current leg: course (rad), north and east extent (m),
            length (m), distance to go at which the ship wheels over (m).
        leg_index: waypoint index ``leg`` was worked out for (-1: not yet).

    Stored one row per quantity, so that the loop over ships on a leg is vectorised.
    """

    leg_start: np.ndarray
    wp_index: np.ndarray
    hold_course_rad: np.ndarray
    leg: np.ndarray
    leg_index: np.ndarray

    @classmethod
    def start(cls, north_m: np.ndarray, east_m: np.ndarray, heading_rad: np.ndarray) -> RouteState:
        n = np.shape(north_m)[0]
        return cls(np.stack([north_m, east_m]).astype(float), np.zeros(n, np.int64),
                   np.asarray(heading_rad, dtype=float).copy(), np.zeros((5, n)),
                   np.full(n, -1, np.int64))


def desired_course(route: RouteState, waypoints: np.ndarray, n_waypoints: np.ndarray,
                   north_m: np.ndarray, east_m: np.ndarray, length_m: np.ndarray) -> np.ndarray:
    """Desired course (rad) for every ship; advances ``route`` past wheel-over points in place.

    Args:
        waypoints: ``(n, W, 2)`` north/east metres, padded with each ship's last waypoint.
        n_waypoints: ``(n,)`` number of real waypoints per ship.
        north_m, east_m, length_m: ``(n,)`` ship positions and lengths.
    """
    out = np.empty(north_m.shape[0])
    _desired_course(route.leg_start, route.wp_index, route.hold_course_rad, route.leg,
                    route.leg_index, waypoints, n_waypoints, north_m, east_m, length_m, out)
    return out


@kernel
def signed_angle(a: float) -> float:
    """``a`` wrapped to [-pi, pi) as numpy's floored remainder gives it, rad."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


#: a waypoint closer than this to the point before it (m) repeats it and has no leg of its own
SAME_POINT_M = 1e-6


@kernel
def _next_distinct(i: int, k: int, n_north: float, n_east: float, waypoints: np.ndarray,
                   n_waypoints: np.ndarray) -> int:
    """Index of ship ``i``'s first waypoint from ``k`` on that is not the point (``n_north``,
    ``n_east``) (``n_waypoints[i]`` if none is)."""
    while k < n_waypoints[i] and math.hypot(waypoints[i, k, 0] - n_north,
                                            waypoints[i, k, 1] - n_east) <= SAME_POINT_M:
        k += 1
    return k


@kernel
def _leg(i: int, k: int, leg_start: np.ndarray, waypoints: np.ndarray, n_waypoints: np.ndarray,
         length: np.ndarray, leg: np.ndarray, leg_index: np.ndarray) -> None:
    """Constants of ship ``i``'s leg to waypoint ``k`` (:class:`RouteState`), a waypoint apart
    from the leg's start; the turn at its end is towards the next waypoint apart from it."""
    tn, te = waypoints[i, k, 0], waypoints[i, k, 1]
    ln, le = tn - leg_start[0, i], te - leg_start[1, i]
    course = math.atan2(le, ln)
    turn = 0.0
    j = _next_distinct(i, k + 1, tn, te, waypoints, n_waypoints)
    if j < n_waypoints[i]:
        nn, ne = waypoints[i, j, 0] - tn, waypoints[i, j, 1] - te
        turn = abs(signed_angle(math.atan2(ne, nn) - course))
    wheel_over = TURN_RADIUS_L * length[i] * math.tan(min(turn, _MAX_TURN) / 2.0)
    leg[0, i], leg[1, i], leg[2, i] = course, ln, le
    leg[3, i] = max(math.hypot(ln, le), 1e-9)
    leg[4, i] = max(wheel_over, 0.5 * length[i])
    leg_index[i] = k


@kernel
def _enter(i: int, k: int, leg_start: np.ndarray, wp_index: np.ndarray,
           waypoints: np.ndarray, n_waypoints: np.ndarray, length: np.ndarray, leg: np.ndarray,
           leg_index: np.ndarray) -> int:
    """Start ship ``i``'s leg to waypoint ``k``, skipping waypoints that repeat the leg's start
    (a leg of no length has no course); returns the waypoint steered to."""
    k = _next_distinct(i, k, leg_start[0, i], leg_start[1, i], waypoints, n_waypoints)
    wp_index[i] = k
    if k < n_waypoints[i]:
        _leg(i, k, leg_start, waypoints, n_waypoints, length, leg, leg_index)
    return k


@kernel
def _desired_course(leg_start: np.ndarray, wp_index: np.ndarray, hold: np.ndarray,
                    leg: np.ndarray, leg_index: np.ndarray, waypoints: np.ndarray,
                    n_waypoints: np.ndarray, north: np.ndarray, east: np.ndarray,
                    length: np.ndarray, out: np.ndarray) -> None:
    """The ships steering along a leg they are on, or holding a course after their route, in
    a loop the compiler vectorises (:func:`trafficsim.geometry.atan`; no branch: every ship's
    line-of-sight course is worked out and kept or not by a select); then, one by one, those
    that start a leg or wheel over onto the next (a step or two per leg)."""
    n = north.shape[0]
    turning = np.empty(n, dtype=np.bool_)
    for i in range(n):
        k = wp_index[i]
        on_route = k < n_waypoints[i]
        rn, re = north[i] - leg_start[0, i], east[i] - leg_start[1, i]
        turning[i] = on_route & ((leg_index[i] != k) | (_to_go(leg, i, rn, re) <= leg[4, i]))
        los = _line_of_sight(leg[0, i], leg[1, i], leg[2, i], leg[3, i], rn, re, length[i])
        out[i] = los if on_route else hold[i]  # (a turning ship's is replaced below)
    for i in range(n):
        if turning[i]:
            _turning_ship(i, leg_start, wp_index, hold, leg, leg_index, waypoints, n_waypoints,
                          north, east, length, out)


@kernel
def _to_go(leg: np.ndarray, i: int, rn: float, re: float) -> float:
    """Distance along ship ``i``'s leg from ``rn, re`` (from the leg's start) to its end, m."""
    return leg[3, i] - (rn * leg[1, i] + re * leg[2, i]) / leg[3, i]


@kernel
def _line_of_sight(course: float, ln: float, le: float, leg_length: float, rn: float,
                   re: float, length: float) -> float:
    """Course on a leg (``course``, extent ``ln, le``) for a ship at ``rn, re`` from its start:
    the leg course less the arctangent of the cross-track error over the look-ahead."""
    cross = (-rn * le + re * ln) / leg_length  # + = starboard of the leg
    return course - atan(cross / (LOOKAHEAD_L * length))


@kernel
def _turning_ship(i: int, leg_start: np.ndarray, wp_index: np.ndarray, hold: np.ndarray,
                  leg: np.ndarray, leg_index: np.ndarray, waypoints: np.ndarray,
                  n_waypoints: np.ndarray, north: np.ndarray, east: np.ndarray,
                  length: np.ndarray, out: np.ndarray) -> None:
    """Ship ``i`` of :func:`_desired_course` starting a leg or at its wheel-over point."""
    k = wp_index[i]
    if k < n_waypoints[i] and leg_index[i] != k:
        k = _enter(i, k, leg_start, wp_index, waypoints, n_waypoints, length, leg, leg_index)
    if k < n_waypoints[i]:
        rn, re = north[i] - leg_start[0, i], east[i] - leg_start[1, i]
        if _to_go(leg, i, rn, re) <= leg[4, i]:  # wheel over: next leg (held if the last)
            hold[i] = leg[0, i]
            leg_start[0, i], leg_start[1, i] = waypoints[i, k, 0], waypoints[i, k, 1]
            k = _enter(i, k + 1, leg_start, wp_index, waypoints, n_waypoints, length, leg,
                       leg_index)
    if k < n_waypoints[i]:
        rn, re = north[i] - leg_start[0, i], east[i] - leg_start[1, i]
        out[i] = _line_of_sight(leg[0, i], leg[1, i], leg[2, i], leg[3, i], rn, re, length[i])
    else:
        out[i] = hold[i]
