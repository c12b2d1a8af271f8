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
from dataclasses import fields

import numpy as np

from trafficsim.geometry import COS_SIN_MAX_RAD, SERIES_TURN_RAD, cos_sin, turned, turned_by_series
from trafficsim.jit import inline_kernel, kernel
from trafficsim.sensors import wrap_2pi_scalar
from trafficsim.ships import mmg, mmg_berthing, modular, nomoto, response
from trafficsim.ships.base import RPS, U, gather_ship

#: integer codes of the model families in the compiled dispatch
FAMILY_CODE = {"nomoto": 0, "response": 1, "mmg": 2, "modular": 3, "mmg_berthing": 4}
NOMOTO_CODE, RESPONSE_CODE = FAMILY_CODE["nomoto"], FAMILY_CODE["response"]
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
def _turned_kinematics(x: tuple | np.ndarray, env: tuple | np.ndarray, c: float, s: float
                       ) -> tuple[float, float, float]:
    """Rates of north, east and heading: the velocities through the water turned to the earth
    frame (``c``, ``s``: cosine and sine of the heading) plus the current, and the yaw rate."""
    return x[3] * c - x[4] * s + env[0], x[3] * s + x[4] * c + env[1], x[5]


@inline_kernel
def _kinematics(x: tuple | np.ndarray, env: tuple | np.ndarray) -> tuple[float, float, float]:
    """:func:`_turned_kinematics` at the heading ``x[2]``."""
    return _turned_kinematics(x, env, math.cos(x[2]), math.sin(x[2]))


@inline_kernel
def motion_rates(du: float, dv: float, dr: float, x: np.ndarray, env: np.ndarray,
                 out: np.ndarray) -> None:
    """Rates of the six motion states into ``out``: :func:`_kinematics` and the family's
    accelerations."""
    out[0], out[1], out[2] = _kinematics(x, env)
    out[3] = du
    out[4] = dv
    out[5] = dr


@inline_kernel
def _derivative(accel_fn: Callable, p: np.ndarray, a: np.ndarray, x: tuple, c: float, s: float,
                rudder_cmd: float, rps_cmd: float, env: tuple) -> tuple:
    """The eight state rates of one ship (``c``, ``s``: cosine and sine of its heading):
    kinematics, the family's accelerations, steering gear and engine."""
    du, dv, dr = accel_fn(p, x, env)
    dn, de, dpsi = _turned_kinematics(x, env, c, s)
    target = min(max(rudder_cmd, -a[RUDDER_MAX]), a[RUDDER_MAX])
    rate = (target - x[6]) / a[RUDDER_TAU]
    return (dn, de, dpsi, du, dv, dr, min(max(rate, -a[RUDDER_RATE]), a[RUDDER_RATE]),
            (min(max(rps_cmd, a[RPS_MIN]), a[RPS_MAX]) - x[7]) / a[ENGINE_TAU])


@inline_kernel
def _stage(x: tuple, f: float, k: tuple) -> tuple:
    """``x + f k`` of two 8-states."""
    return (x[0] + f * k[0], x[1] + f * k[1], x[2] + f * k[2], x[3] + f * k[3],
            x[4] + f * k[4], x[5] + f * k[5], x[6] + f * k[6], x[7] + f * k[7])


@inline_kernel
def _heading_cos_sin(psi: float) -> tuple[float, float]:
    """Cosine and sine of a heading: :func:`cos_sin` (libm beyond its reach), so that the
    scalar and the vectorised step agree to the bit."""
    if abs(psi) <= COS_SIN_MAX_RAD:
        return cos_sin(psi)
    return math.cos(psi), math.sin(psi)


@inline_kernel
def _rk4_step(accel_fn: Callable, turn_fn: Callable, p: np.ndarray, a: np.ndarray, x: tuple,
              c: float, s: float, rc: float, nc: float, env: tuple, h: float) -> tuple:
    """One classic RK4 step of ``h`` of one ship's 8-state ``x`` whose heading has cosine and
    sine ``c, s``: the stages turn them by their change of heading (``turn_fn``:
    :func:`turned`, or :func:`turned_by_series` where the caller checks the turn). Returns the
    new state (heading not wrapped) and the largest turn of a stage."""
    half, sixth = 0.5 * h, h / 6.0
    k1 = _derivative(accel_fn, p, a, x, c, s, rc, nc, env)
    c2, s2 = turn_fn(c, s, half * k1[2])
    k2 = _derivative(accel_fn, p, a, _stage(x, half, k1), c2, s2, rc, nc, env)
    c3, s3 = turn_fn(c, s, half * k2[2])
    k3 = _derivative(accel_fn, p, a, _stage(x, half, k2), c3, s3, rc, nc, env)
    c4, s4 = turn_fn(c, s, h * k3[2])
    k4 = _derivative(accel_fn, p, a, _stage(x, h, k3), c4, s4, rc, nc, env)
    new = (x[0] + sixth * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
           x[1] + sixth * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
           x[2] + sixth * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
           x[3] + sixth * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3]),
           x[4] + sixth * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4]),
           x[5] + sixth * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5]),
           x[6] + sixth * (k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6]),
           x[7] + sixth * (k1[7] + 2.0 * k2[7] + 2.0 * k3[7] + k4[7]))
    return new, max(abs(half * k1[2]), max(abs(half * k2[2]), abs(h * k3[2])))


@inline_kernel
def _rk4(accel_fn: Callable, p: np.ndarray, a: np.ndarray, x: tuple, rc: float, nc: float,
         env: tuple, h: float, substeps: int) -> tuple:
    """``substeps`` classic RK4 steps of ``h`` of one ship's 8-state ``x`` (a tuple, so that it
    stays in registers); returns the new state. Written once and compiled once per family
    (``accel_fn``), so a ship's four derivative evaluations carry no family dispatch."""
    for _ in range(substeps):
        # one cosine and sine of the heading per step; the stages turn them (turned)
        c, s = _heading_cos_sin(x[2])
        x, _ = _rk4_step(accel_fn, turned, p, a, x, c, s, rc, nc, env, h)
    return x


@inline_kernel
def _step_ship(i: int, codes: np.ndarray, P: np.ndarray, A: np.ndarray, X: np.ndarray,
               rudder_cmd: np.ndarray, rps_cmd: np.ndarray, E: np.ndarray, dt: float,
               substeps: np.ndarray) -> None:
    """Advance ship ``i`` of :func:`step_ships` in place."""
    x = (X[0, i], X[1, i], X[2, i], X[3, i], X[4, i], X[5, i], X[6, i], X[7, i])
    env = (E[0, i], E[1, i], E[2, i], E[3, i])
    code, p, a = codes[i], P[i], A[i]
    rc, nc = rudder_cmd[i], rps_cmd[i]
    m = substeps[i]
    h = dt / m
    if code == 0:
        x = _rk4(nomoto.accel, p, a, x, rc, nc, env, h, m)
    elif code == 1:
        x = _rk4(response.accel, p, a, x, rc, nc, env, h, m)
    elif code == 2:
        x = _rk4(mmg.accel, p, a, x, rc, nc, env, h, m)
    elif code == 4:
        x = _rk4(mmg_berthing.accel, p, a, x, rc, nc, env, h, m)
    else:
        x = _rk4(modular.accel, p, a, x, rc, nc, env, h, m)
    X[0, i], X[1, i], X[2, i], X[3, i] = x[0], x[1], wrap_2pi_scalar(x[2]), x[3]
    X[4, i], X[5, i], X[6, i], X[7, i] = x[4], x[5], x[6], x[7]


#: the families whose step is vectorised (codes 0 and 1), and their numbers of parameters
VECTORISED = {"nomoto": len(fields(nomoto.NomotoParams)),
              "response": len(fields(response.ResponseParams))}
N_NOMOTO_PARAMS = VECTORISED["nomoto"]


def vector_tables(codes: np.ndarray, P: np.ndarray, A: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """The tables of :func:`step_ships` column by column for its vectorised step: actuators
    ``(6, n)`` and the leading parameter columns ``(k, n)``, as many as the widest vectorised
    family present has (7 Nomoto, 17 response model); None when no ship belongs to a
    vectorised family. Make them once per batch: the parameters do not change while it
    runs."""
    codes, P = np.asarray(codes), np.asarray(P, dtype=float)
    present = [k for name, k in VECTORISED.items() if np.any(codes == FAMILY_CODE[name])]
    if not present:
        return None
    return (np.ascontiguousarray(np.asarray(A, dtype=float).T),
            np.ascontiguousarray(P[:, :max(present)].T))


@kernel
def step_ships(codes: np.ndarray, P: np.ndarray, A: np.ndarray, X: np.ndarray,
               rudder_cmd: np.ndarray, rps_cmd: np.ndarray, E: np.ndarray, dt: float,
               substeps: np.ndarray, tables: tuple[np.ndarray, np.ndarray] | None = None
               ) -> None:
    """Advance every ship by ``dt`` in place (RK4, ``substeps[i]`` equal steps for ship i).

    Args:
        codes: ``(n,)`` family codes; P: ``(n, k)`` packed parameters; A: ``(n, 6)`` actuators.
        X: ``(8, n)`` state, updated in place; rudder_cmd (rad), rps_cmd (rev/s): ``(n,)``.
        E: ``(4, n)`` environment rows (current north, current east, wind speed, wind from).
        tables: :func:`vector_tables` of ``codes, P, A``: the ships of the Nomoto and
            response families with one RK4 step then go through a vectorised loop
            (:func:`_vectorised`: the same numbers to the bit, several times faster), the
            others through the scalar one.
    """
    n = X.shape[1]
    if tables is None:
        for i in range(n):
            _step_ship(i, codes, P, A, X, rudder_cmd, rps_cmd, E, dt, substeps)
    else:
        scalar = np.ones(n, dtype=np.bool_)
        AT, PT = tables
        if PT.shape[0] == N_NOMOTO_PARAMS:
            _vectorised_nomoto(codes, PT, AT, X, rudder_cmd, rps_cmd, E, dt, substeps, scalar)
        else:
            _vectorised_mixed(codes, PT, AT, X, rudder_cmd, rps_cmd, E, dt, substeps, scalar)
        for i in range(n):
            if scalar[i]:
                _step_ship(i, codes, P, A, X, rudder_cmd, rps_cmd, E, dt, substeps)


@inline_kernel
def _vectorised(accel_fn: Callable, row_fn: Callable, max_code: int, codes: np.ndarray,
                PT: np.ndarray, AT: np.ndarray, X: np.ndarray, rudder_cmd: np.ndarray,
                rps_cmd: np.ndarray, E: np.ndarray, dt: float, substeps: np.ndarray,
                scalar: np.ndarray) -> None:
    """One RK4 step of ``dt`` of every ship of a family code up to ``max_code`` with one
    sub-step, as :func:`_step_ship` takes it, in a loop the compiler vectorises: parameters
    read column by column (``PT``, ``AT``; ``row_fn`` gives them as one tuple, ``accel_fn``
    takes it), the heading's cosine and sine from :func:`cos_sin`, the
    stages' turns by series alone, selects instead of branches. Every ship is computed; only
    those the loop takes exactly are stored and cleared in ``scalar`` (not: another family,
    several sub-steps, a stage turning more than ``SERIES_TURN_RAD``, a heading far outside
    ``[0, 2 pi)``)."""
    for i in range(X.shape[1]):
        x = (X[0, i], X[1, i], X[2, i], X[3, i], X[4, i], X[5, i], X[6, i], X[7, i])
        env = (E[0, i], E[1, i], E[2, i], E[3, i])
        a = (AT[0, i], AT[1, i], AT[2, i], AT[3, i], AT[4, i], AT[5, i])
        c, s = cos_sin(x[2])
        new, turn = _rk4_step(accel_fn, turned_by_series, row_fn(codes, PT, i), a, x, c, s,
                              rudder_cmd[i], rps_cmd[i], env, dt)
        psi = new[2]
        ok = ((codes[i] >= 0) & (codes[i] <= max_code) & (substeps[i] == 1)
              & (turn <= SERIES_TURN_RAD) & (psi > -TWO_PI) & (psi < 2.0 * TWO_PI)
              & (abs(x[2]) <= COS_SIN_MAX_RAD))
        if ok:
            scalar[i] = False
            # wrap_2pi_scalar of an angle in (-2 pi, 4 pi): the same bits (x - 2 pi is exact)
            w = psi + TWO_PI if psi < 0.0 else (psi - TWO_PI if psi >= TWO_PI else psi + 0.0)
            X[0, i], X[1, i], X[2, i], X[3, i] = new[0], new[1], 0.0 if w >= TWO_PI else w, new[3]
            X[4, i], X[5, i], X[6, i], X[7, i] = new[4], new[5], new[6], new[7]


@inline_kernel
def _nomoto_row(codes: np.ndarray, PT: np.ndarray, i: int) -> tuple:
    """Ship ``i``'s Nomoto parameters from their columns."""
    return (PT[0, i], PT[1, i], PT[2, i], PT[3, i], PT[4, i], PT[5, i], PT[6, i])


@inline_kernel
def _mixed_row(codes: np.ndarray, PT: np.ndarray, i: int) -> tuple:
    """Ship ``i``'s family code and the 17 leading columns of its parameters."""
    return (float(codes[i]), PT[0, i], PT[1, i], PT[2, i], PT[3, i], PT[4, i], PT[5, i],
            PT[6, i], PT[7, i], PT[8, i], PT[9, i], PT[10, i], PT[11, i], PT[12, i], PT[13, i],
            PT[14, i], PT[15, i], PT[16, i])


@inline_kernel
def _mixed_accel(row: tuple, x: tuple, env: tuple) -> tuple[float, float, float]:
    """The accelerations of a :func:`_mixed_row`'s family: both are worked out (a select is
    cheaper than a branch in a vectorised loop; the other's numbers are discarded)."""
    by_nomoto = nomoto.accel(row[1:], x, env)
    by_response = response.accel(row[1:], x, env)
    return by_nomoto if row[0] == NOMOTO_CODE else by_response


@kernel
def _vectorised_nomoto(codes: np.ndarray, PT: np.ndarray, AT: np.ndarray, X: np.ndarray,
                       rudder_cmd: np.ndarray, rps_cmd: np.ndarray, E: np.ndarray, dt: float,
                       substeps: np.ndarray, scalar: np.ndarray) -> None:
    """:func:`_vectorised` for a batch whose vectorised ships are all Nomoto ships."""
    _vectorised(nomoto.accel, _nomoto_row, NOMOTO_CODE, codes, PT, AT, X, rudder_cmd,
                rps_cmd, E, dt, substeps, scalar)


@kernel
def _vectorised_mixed(codes: np.ndarray, PT: np.ndarray, AT: np.ndarray, X: np.ndarray,
                      rudder_cmd: np.ndarray, rps_cmd: np.ndarray, E: np.ndarray, dt: float,
                      substeps: np.ndarray, scalar: np.ndarray) -> None:
    """:func:`_vectorised` for Nomoto and response-model ships together."""
    _vectorised(_mixed_accel, _mixed_row, max(NOMOTO_CODE, RESPONSE_CODE), codes, PT, AT, X,
                rudder_cmd, rps_cmd, E, dt, substeps, scalar)


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


@kernel
def steady_rps(codes: np.ndarray, P: np.ndarray, speed: np.ndarray, rps_max: np.ndarray,
               E: np.ndarray, iters: int, out: np.ndarray) -> None:
    """Propeller speed of steady straight-ahead ``speed`` per ship, into ``out`` ``(n,)``:
    ``iters`` bisections of ``[0, rps_max]`` on the sign of the surge acceleration with
    v = r = rudder = 0 (:func:`trafficsim.ships.base.steady_rps_for_speed`)."""
    x, env = np.zeros(8), np.empty(4)
    for i in range(speed.shape[0]):
        for j in range(4):
            env[j] = E[j, i]
        x[U] = speed[i]
        lo, hi = 0.0, rps_max[i]
        for _ in range(iters):
            mid = 0.5 * (lo + hi)
            x[RPS] = mid
            du, _, _ = accel(codes[i], P[i], x, env)
            if du > 0.0:
                hi = mid
            else:
                lo = mid
        out[i] = 0.5 * (lo + hi)
