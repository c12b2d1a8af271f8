"""Heading autopilot and engine order, vectorised over ships.

Heading: PID on the heading error with yaw-rate damping, rudder command clipped to the rudder
limit (the steering gear adds its own rate limit and lag, see :mod:`trafficsim.ships.base`):
delta_c = kp e + ki int(e) dt - kd r, e = wrap(psi_d - psi). The integral only accumulates while
|e| < 10 deg (anti wind-up). Speed: the engine order is the steady calm-water rps for the ordered
speed, as on a ship's telegraph; the speed then follows from the dynamics.
"""

from __future__ import annotations

import numpy as np

INTEGRAL_BAND_RAD = np.radians(10.0)


def rudder_command(psi_d: np.ndarray, psi: np.ndarray, r: np.ndarray, integral: np.ndarray,
                   kp: np.ndarray, kd_s: np.ndarray, ki_per_s: np.ndarray,
                   rudder_max_rad: np.ndarray, dt: float) -> np.ndarray:
    """Rudder command (rad, + = starboard) for all ships; updates ``integral`` (rad s) in place.

    Args:
        psi_d, psi: desired and actual (estimated) heading, rad, ``(n,)``.
        r: yaw rate, rad/s, ``(n,)``.
        kp (-), kd_s (s), ki_per_s (1/s): controller gains, ``(n,)``.
    """
    err = (psi_d - psi + np.pi) % (2.0 * np.pi) - np.pi
    integral += np.where(np.abs(err) < INTEGRAL_BAND_RAD, err * dt, 0.0)
    cmd = kp * err + ki_per_s * integral - kd_s * r
    return np.clip(cmd, -rudder_max_rad, rudder_max_rad)
