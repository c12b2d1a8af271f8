"""Route guidance: line-of-sight steering along waypoint legs with a wheel-over point.

Each ship follows the leg from its previous waypoint (initially its start position) to its
current waypoint. The desired course is the leg course corrected by the line-of-sight law
chi_d = chi_leg - atan(e / Delta), e the cross-track error (positive to starboard of the leg) and
Delta the look-ahead distance (Fossen 2011, eq. 10.73). The ship moves to the next leg at the
wheel-over point, when the distance to go along the leg falls below R tan(|dchi| / 2), R the
turning radius and dchi the course change at the waypoint (the geometry of a circular turn
tangent to both legs). After the last waypoint the ship holds the last leg's course. A
waypoint that repeats the point before it (or the start) has no leg and is passed over.

One compiled loop over ships (:func:`_desired_course`); no Python loop per ship. The constants of
a ship's current leg (course, direction, length, wheel-over distance) are worked out when it
starts the leg and kept, so a step costs one arctangent per ship.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trafficsim.jit import kernel

#: look-ahead distance and turning radius in ship lengths
LOOKAHEAD_L = 4.0
TURN_RADIUS_L = 3.0
_MAX_TURN = math.radians(150.0)


@dataclass
class RouteState:
    """Progress of every ship along its route, ``(n,)`` arrays.

    Attributes:
        leg_start: ``(n, 2)`` north/east of the current leg's start, m.
        wp_index: index of the waypoint being steered to (== n_waypoints when the route is done).
        hold_course_rad: course held when there is no (more) route.
        leg: ``(n, 5)`` constants of the current leg: course (rad), north and east extent (m),
            length (m), distance to go at which the ship wheels over (m).
        leg_index: waypoint index ``leg`` was worked out for (-1: not yet).
    """

    leg_start: np.ndarray
    wp_index: np.ndarray
    hold_course_rad: np.ndarray
    leg: np.ndarray
    leg_index: np.ndarray

    @classmethod
    def start(cls, north_m: np.ndarray, east_m: np.ndarray, heading_rad: np.ndarray) -> RouteState:
        n = np.shape(north_m)[0]
        return cls(np.stack([north_m, east_m], axis=1), np.zeros(n, np.int64),
                   np.asarray(heading_rad, dtype=float).copy(), np.zeros((n, 5)),
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
def _wrap(a: float) -> float:
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
    ln, le = tn - leg_start[i, 0], te - leg_start[i, 1]
    course = math.atan2(le, ln)
    turn = 0.0
    j = _next_distinct(i, k + 1, tn, te, waypoints, n_waypoints)
    if j < n_waypoints[i]:
        nn, ne = waypoints[i, j, 0] - tn, waypoints[i, j, 1] - te
        turn = abs(_wrap(math.atan2(ne, nn) - course))
    wheel_over = TURN_RADIUS_L * length[i] * math.tan(min(turn, _MAX_TURN) / 2.0)
    leg[i, 0], leg[i, 1], leg[i, 2] = course, ln, le
    leg[i, 3] = max(math.hypot(ln, le), 1e-9)
    leg[i, 4] = max(wheel_over, 0.5 * length[i])
    leg_index[i] = k


@kernel
def _enter(i: int, k: int, leg_start: np.ndarray, wp_index: np.ndarray,
           waypoints: np.ndarray, n_waypoints: np.ndarray, length: np.ndarray, leg: np.ndarray,
           leg_index: np.ndarray) -> int:
    """Start ship ``i``'s leg to waypoint ``k``, skipping waypoints that repeat the leg's start
    (a leg of no length has no course); returns the waypoint steered to."""
    k = _next_distinct(i, k, leg_start[i, 0], leg_start[i, 1], waypoints, n_waypoints)
    wp_index[i] = k
    if k < n_waypoints[i]:
        _leg(i, k, leg_start, waypoints, n_waypoints, length, leg, leg_index)
    return k


@kernel
def _desired_course(leg_start: np.ndarray, wp_index: np.ndarray, hold: np.ndarray,
                    leg: np.ndarray, leg_index: np.ndarray, waypoints: np.ndarray,
                    n_waypoints: np.ndarray, north: np.ndarray, east: np.ndarray,
                    length: np.ndarray, out: np.ndarray) -> None:
    for i in range(north.shape[0]):
        k = wp_index[i]
        if k < n_waypoints[i] and leg_index[i] != k:
            k = _enter(i, k, leg_start, wp_index, waypoints, n_waypoints, length, leg, leg_index)
        if k < n_waypoints[i]:
            rn, re = north[i] - leg_start[i, 0], east[i] - leg_start[i, 1]
            to_go = leg[i, 3] - (rn * leg[i, 1] + re * leg[i, 2]) / leg[i, 3]
            if to_go <= leg[i, 4]:  # wheel over: next leg (held as the course if the last)
                hold[i] = leg[i, 0]
                leg_start[i, 0], leg_start[i, 1] = waypoints[i, k, 0], waypoints[i, k, 1]
                k = _enter(i, k + 1, leg_start, wp_index, waypoints, n_waypoints, length, leg,
                           leg_index)
        if k < n_waypoints[i]:
            rn, re = north[i] - leg_start[i, 0], east[i] - leg_start[i, 1]
            cross = (-rn * leg[i, 2] + re * leg[i, 1]) / leg[i, 3]  # + = starboard of the leg
            out[i] = leg[i, 0] - math.atan(cross / (LOOKAHEAD_L * length[i]))
        else:
            out[i] = hold[i]
