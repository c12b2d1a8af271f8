"""Heading autopilot and engine order.

Heading: PID on the heading error with yaw-rate damping, rudder command clipped to the rudder
limit (the steering gear adds its own rate limit and lag, see :mod:`trafficsim.ships.kernels`):
delta_c = kp e + ki int(e) dt - kd r, e = wrap(psi_d - psi). The integral only accumulates while
|e| < 10 deg (anti wind-up). Speed: the engine order is the steady calm-water rps for the ordered
speed, as on a ship's telegraph; the speed then follows from the dynamics.

One compiled loop over ships; no Python loop per ship.
"""

from __future__ import annotations

import math

import numpy as np

from trafficsim.jit import kernel
from trafficsim.sensors import mod_2pi_scalar

INTEGRAL_BAND_RAD = math.radians(10.0)


def rudder_command(psi_d: np.ndarray, psi: np.ndarray, r: np.ndarray, integral: np.ndarray,
                   kp: np.ndarray, kd_s: np.ndarray, ki_per_s: np.ndarray,
                   rudder_max_rad: np.ndarray, dt: float) -> np.ndarray:
    """Rudder command (rad, + = starboard) for all ships; updates ``integral`` (rad s) in place.

    Args:
        psi_d, psi: desired and actual (estimated) heading, rad, ``(n,)``.
        r: yaw rate, rad/s, ``(n,)``.
        kp (-), kd_s (s), ki_per_s (1/s): controller gains, ``(n,)`` or scalars.
        integral: ``(n,)`` float array, the controller's memory.
    """
    n = np.shape(psi)[0]

    def arr(v: np.ndarray | float) -> np.ndarray:
        if isinstance(v, np.ndarray) and v.shape == (n,) and v.dtype == float:
            return np.ascontiguousarray(v)  # (the common case: per-ship columns every step)
        return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), (n,)))

    out = np.empty(n)
    _rudder_command(arr(psi_d), arr(psi), arr(r), integral, arr(kp), arr(kd_s), arr(ki_per_s),
                    arr(rudder_max_rad), float(dt), out)
    return out


@kernel
def _rudder_command(psi_d: np.ndarray, psi: np.ndarray, r: np.ndarray, integral: np.ndarray,
                    kp: np.ndarray, kd_s: np.ndarray, ki_per_s: np.ndarray,
                    rudder_max: np.ndarray, dt: float, out: np.ndarray) -> None:
    for i in range(psi.shape[0]):
        err = mod_2pi_scalar(psi_d[i] - psi[i] + math.pi) - math.pi
        if abs(err) < INTEGRAL_BAND_RAD:
            integral[i] += err * dt
        cmd = kp[i] * err + ki_per_s[i] * integral[i] - kd_s[i] * r[i]
        out[i] = min(max(cmd, -rudder_max[i]), rudder_max[i])
