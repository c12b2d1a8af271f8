"""Compiled step kernels: one fused loop over all ships of a batch, whatever their model family.

Each family module supplies a scalar ``accel(p, x, env) -> (du, dv, dr)`` compiled with numba
(``p``: the ship's packed parameter row, ``x``: its 8-state in the layout of
:mod:`trafficsim.ships.base`, ``env``: ``(current_north_mps, current_east_mps, wind_speed_mps,
wind_from_rad)``). This module dispatches on an integer family code and integrates with classic
RK4: per ship, kinematics, steering gear (first-order lag with rate limit, [seed 002, eq 4.7])
and engine (first-order lag, [seed 002, eq 4.8]) are added to the family's accelerations.

The loop runs over ships inside compiled code, so the cost per ship-step is a few hundred
floating-point operations with no interpreter overhead, from one ship to a million.
Kernels are cached on disk (``cache=True``); the first run after installation compiles them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from trafficsim.jit import inline_kernel, kernel
from trafficsim.ships import mmg, mmg_berthing, modular, nomoto, response
from trafficsim.ships.base import gather_ship

#: integer codes of the model families in the compiled dispatch
FAMILY_CODE = {"nomoto": 0, "response": 1, "mmg": 2, "modular": 3, "mmg_berthing": 4}
#: columns of the actuator table
RUDDER_MAX, RUDDER_RATE, RUDDER_TAU, RPS_MAX, RPS_MIN, ENGINE_TAU = range(6)
TWO_PI = 2.0 * math.pi


@kernel
def accel(code: int, p: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Body-frame accelerations of one ship of family ``code``."""
    if code == 0:
        return nomoto.accel(p, x, env)
    if code == 1:
        return response.accel(p, x, env)
    if code == 2:
        return mmg.accel(p, x, env)
    if code == 4:
        return mmg_berthing.accel(p, x, env)
    return modular.accel(p, x, env)


@inline_kernel
def motion_rates(du: float, dv: float, dr: float, x: np.ndarray, env: np.ndarray,
                 out: np.ndarray) -> None:
    """Rates of the six motion states: position and heading from the velocities through the
    water turned to the earth frame plus the current, and the family's accelerations."""
    c, s = math.cos(x[2]), math.sin(x[2])
    out[0] = x[3] * c - x[4] * s + env[0]
    out[1] = x[3] * s + x[4] * c + env[1]
    out[2] = x[5]
    out[3] = du
    out[4] = dv
    out[5] = dr


@inline_kernel
def _derivative(accel_fn: Callable, p: np.ndarray, a: np.ndarray, x: np.ndarray,
                rudder_cmd: float, rps_cmd: float, env: np.ndarray, out: np.ndarray) -> None:
    du, dv, dr = accel_fn(p, x, env)
    motion_rates(du, dv, dr, x, env, out)
    target = min(max(rudder_cmd, -a[RUDDER_MAX]), a[RUDDER_MAX])
    rate = (target - x[6]) / a[RUDDER_TAU]
    out[6] = min(max(rate, -a[RUDDER_RATE]), a[RUDDER_RATE])
    out[7] = (min(max(rps_cmd, a[RPS_MIN]), a[RPS_MAX]) - x[7]) / a[ENGINE_TAU]


@inline_kernel
def _rk4(accel_fn: Callable, p: np.ndarray, a: np.ndarray, x: np.ndarray, rc: float, nc: float,
         env: np.ndarray, h: float, substeps: int, w: np.ndarray) -> None:
    """``substeps`` classic RK4 steps of ``h`` of one ship in place; ``w`` ``(5, 8)`` scratch.
    Written once and compiled once per family (``accel_fn``), so a ship's four derivative
    evaluations carry no family dispatch."""
    xt, k1, k2, k3, k4 = w[0], w[1], w[2], w[3], w[4]
    for _ in range(substeps):
        _derivative(accel_fn, p, a, x, rc, nc, env, k1)
        for j in range(8):
            xt[j] = x[j] + 0.5 * h * k1[j]
        _derivative(accel_fn, p, a, xt, rc, nc, env, k2)
        for j in range(8):
            xt[j] = x[j] + 0.5 * h * k2[j]
        _derivative(accel_fn, p, a, xt, rc, nc, env, k3)
        for j in range(8):
            xt[j] = x[j] + h * k3[j]
        _derivative(accel_fn, p, a, xt, rc, nc, env, k4)
        for j in range(8):
            x[j] += (h / 6.0) * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@kernel
def step_ships(codes: np.ndarray, P: np.ndarray, A: np.ndarray, X: np.ndarray,
               rudder_cmd: np.ndarray, rps_cmd: np.ndarray, E: np.ndarray, dt: float,
               substeps: np.ndarray) -> None:
    """Advance every ship by ``dt`` in place (RK4, ``substeps[i]`` equal steps for ship i).

    Args:
        codes: ``(n,)`` family codes; P: ``(n, k)`` packed parameters; A: ``(n, 6)`` actuators.
        X: ``(8, n)`` state, updated in place; rudder_cmd (rad), rps_cmd (rev/s): ``(n,)``.
        E: ``(4, n)`` environment rows (current north, current east, wind speed, wind from).
    """
    n = X.shape[1]
    x = np.empty(8)
    w = np.empty((5, 8))
    env = np.empty(4)
    for i in range(n):
        gather_ship(X, E, i, x, env)
        code, p, a = codes[i], P[i], A[i]
        rc, nc = rudder_cmd[i], rps_cmd[i]
        m = substeps[i]
        h = dt / m
        if code == 0:
            _rk4(nomoto.accel, p, a, x, rc, nc, env, h, m, w)
        elif code == 1:
            _rk4(response.accel, p, a, x, rc, nc, env, h, m, w)
        elif code == 2:
            _rk4(mmg.accel, p, a, x, rc, nc, env, h, m, w)
        elif code == 4:
            _rk4(mmg_berthing.accel, p, a, x, rc, nc, env, h, m, w)
        else:
            _rk4(modular.accel, p, a, x, rc, nc, env, h, m, w)
        x[2] = x[2] % TWO_PI
        for j in range(8):
            X[j, i] = x[j]


@kernel
def accelerations(codes: np.ndarray, P: np.ndarray, X: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Body-frame accelerations ``(3, n)`` (du, dv, dr) of every ship at state ``X`` ``(8, n)``."""
    n = X.shape[1]
    out = np.empty((3, n))
    x = np.empty(8)
    env = np.empty(4)
    for i in range(n):
        gather_ship(X, E, i, x, env)
        du, dv, dr = accel(codes[i], P[i], x, env)
        out[0, i] = du
        out[1, i] = dv
        out[2, i] = dr
    return out
