"""Route guidance: line-of-sight steering along waypoint legs with a wheel-over point.

Vectorised over ships. Each ship follows the leg from its previous waypoint (initially its start
position) to its current waypoint. The desired course is the leg course corrected by the
line-of-sight law chi_d = chi_leg - atan(e / Delta), e the cross-track error (positive to
starboard of the leg) and Delta the look-ahead distance (Fossen 2011, eq. 10.73). The ship moves
to the next leg at the wheel-over point, when the distance to go along the leg falls below
R tan(|dchi| / 2), R the turning radius and dchi the course change at the waypoint (the geometry
of a circular turn tangent to both legs). After the last waypoint the ship holds the last leg's
course.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: look-ahead distance and turning radius in ship lengths
LOOKAHEAD_L = 4.0
TURN_RADIUS_L = 3.0


@dataclass
class RouteState:
    """Progress of every ship along its route, ``(n,)`` arrays.

    Attributes:
        leg_start: ``(n, 2)`` north/east of the current leg's start, m.
        wp_index: index of the waypoint being steered to (== n_waypoints when the route is done).
        hold_course_rad: course held when there is no (more) route.
    """

    leg_start: np.ndarray
    wp_index: np.ndarray
    hold_course_rad: np.ndarray

    @classmethod
    def start(cls, north_m: np.ndarray, east_m: np.ndarray, heading_rad: np.ndarray) -> RouteState:
        return cls(np.stack([north_m, east_m], axis=1), np.zeros(north_m.shape, np.int64),
                   heading_rad.copy())


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _leg(route: RouteState, waypoints: np.ndarray, north_m: np.ndarray, east_m: np.ndarray
         ) -> tuple[np.ndarray, ...]:
    """Current leg geometry: target, course, distance to go and cross-track error, ``(n,)``."""
    rows = np.arange(north_m.shape[0])
    idx = np.minimum(route.wp_index, waypoints.shape[1] - 1)
    target = waypoints[rows, idx]
    leg = target - route.leg_start
    leg_len = np.maximum(np.hypot(leg[:, 0], leg[:, 1]), 1e-9)
    rel_n, rel_e = north_m - route.leg_start[:, 0], east_m - route.leg_start[:, 1]
    along = (rel_n * leg[:, 0] + rel_e * leg[:, 1]) / leg_len
    cross = (-rel_n * leg[:, 1] + rel_e * leg[:, 0]) / leg_len  # + = starboard of the leg
    return idx, target, np.arctan2(leg[:, 1], leg[:, 0]), leg_len - along, cross


def desired_course(route: RouteState, waypoints: np.ndarray, n_waypoints: np.ndarray,
                   north_m: np.ndarray, east_m: np.ndarray, length_m: np.ndarray) -> np.ndarray:
    """Desired course (rad) for every ship; advances ``route`` past wheel-over points in place.

    Args:
        waypoints: ``(n, W, 2)`` north/east metres, padded with each ship's last waypoint.
        n_waypoints: ``(n,)`` number of real waypoints per ship.
        north_m, east_m, length_m: ``(n,)`` ship positions and lengths.
    """
    rows = np.arange(north_m.shape[0])
    active = route.wp_index < n_waypoints
    idx, target, course, to_go, _ = _leg(route, waypoints, north_m, east_m)
    has_next = (idx + 1) < n_waypoints
    nxt_leg = waypoints[rows, np.minimum(idx + 1, waypoints.shape[1] - 1)] - target
    turn = np.where(has_next, np.abs(_wrap(np.arctan2(nxt_leg[:, 1], nxt_leg[:, 0]) - course)),
                    0.0)
    wheel_over = TURN_RADIUS_L * length_m * np.tan(np.minimum(turn, np.radians(150.0)) / 2.0)
    switch = active & (to_go <= np.maximum(wheel_over, 0.5 * length_m))
    route.hold_course_rad = np.where(switch & ~has_next, course, route.hold_course_rad)
    route.leg_start = np.where(switch[:, None], target, route.leg_start)
    route.wp_index = route.wp_index + switch

    _, _, course, _, cross = _leg(route, waypoints, north_m, east_m)
    los = course - np.arctan(cross / (LOOKAHEAD_L * length_m))
    return np.where(route.wp_index < n_waypoints, los, route.hold_course_rad)
