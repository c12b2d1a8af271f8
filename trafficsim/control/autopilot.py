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

from trafficsim.jit import inline_kernel, kernel
from trafficsim.sensors import TWO_PI, mod_2pi_scalar

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


#: ships per block in which :func:`_rudder_command` looks for the ships outside the fast wrap
_BLOCK = 64


@kernel
def _rudder_command(psi_d: np.ndarray, psi: np.ndarray, r: np.ndarray, integral: np.ndarray,
                    kp: np.ndarray, kd_s: np.ndarray, ki_per_s: np.ndarray,
                    rudder_max: np.ndarray, dt: float, out: np.ndarray) -> None:
    """PID on the heading error wrapped to [-pi, pi), in place. The ships whose
    ``psi_d - psi + pi`` lies within (-2 pi, 2 pi) (all of them, as a rule) in a loop without
    branches, which the compiler vectorises (the wrap as :func:`mod_2pi_scalar` gives it
    there); the others after it, one by one, with the division. They are picked out block by
    block from the flags that loop leaves: a loop over all ships with the division inside would
    be vectorised too, the division then worked out for every ship."""
    n = psi.shape[0]
    outside = np.empty(n, dtype=np.bool_)
    wide = False
    for i in range(n):
        a = psi_d[i] - psi[i] + math.pi
        inside = -TWO_PI < a < TWO_PI
        outside[i] = not inside
        wide |= not inside
        err = (a + 0.0 if a >= 0.0 else a + TWO_PI) - math.pi
        integrate = inside and abs(err) < INTEGRAL_BAND_RAD
        integral[i] = integral[i] + err * dt if integrate else integral[i]
        out[i] = _pid(err, integral[i], r[i], kp[i], kd_s[i], ki_per_s[i], rudder_max[i])
    for start in range(0, n if wide else 0, _BLOCK):
        stop = min(start + _BLOCK, n)
        any_outside = False
        for i in range(start, stop):
            any_outside |= outside[i]
        for i in range(start, stop if any_outside else start):
            if outside[i]:
                err = mod_2pi_scalar(psi_d[i] - psi[i] + math.pi) - math.pi
                if abs(err) < INTEGRAL_BAND_RAD:
                    integral[i] += err * dt
                out[i] = _pid(err, integral[i], r[i], kp[i], kd_s[i], ki_per_s[i],
                              rudder_max[i])


@inline_kernel
def _pid(err: float, integral: float, r: float, kp: float, kd_s: float, ki_per_s: float,
         rudder_max: float) -> float:
    """The rudder command of one ship, limited to +/- ``rudder_max``."""
    cmd = kp * err + ki_per_s * integral - kd_s * r
    return min(max(cmd, -rudder_max), rudder_max)
