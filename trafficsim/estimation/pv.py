"""The GNSS receiver's position-velocity (PV) Kalman filter, 4 states per ship [seed 000, eqs 1-5].

A stand-alone (D)GPS receiver measures position only; the velocity it outputs (speed and course
over ground) is the velocity state of this filter [seed 000, sect. 2]. The model is the constant
velocity ("PV random walk") model of Brown & Hwang (1997), the seed's reference [2]: per axis the
velocity is driven by white acceleration noise of power spectral density ``S_p``::

    state     [v, p] per axis, z = p + noise, sigma = 2 m (DGPS)          [seed 000, eqs 1-2]
    Phi     = [[1, 0], [dt, 1]]                                           [seed 000, eq 3]
    Q       = S_p [[dt, dt^2/2], [dt^2/2, dt^3/3]]    R = sigma^2 (4 m^2) [seed 000, eq 4]

The seed orders the state ``[v_NS, v_EW, x, y]`` (velocities first, x north, y east); here it is
``[N, E, vN, vE]`` (positions first), the same filter permuted. Units of ``S_p``: ``Q_vv = S_p dt``
is a velocity variance (m^2/s^2), so ``S_p`` is in m^2/s^3, the two-sided spectral density of
the white-noise acceleration; the seed's values are 0.001, 0.01 (its optimum for a 100 m tanker)
and 0.1 [seed 000, sect. 2]. The seed steps the filter at 1 s with sigma = 2 m.

North and east decouple (Phi, Q, H, R are block diagonal with equal blocks), so every matrix
operation is closed-form on one 2x2 block per axis: no matrix inversion, no per-ship loop.
Covariances are stored as those blocks, ``P`` of shape ``(n, 2, 2, 2)`` indexed
``[ship, axis (0 north, 1 east), i, j]`` with ``i, j`` in (position, velocity);
:func:`full_covariance` assembles the equivalent ``(n, 4, 4)`` matrix in the ``x`` order.

The recursion is the seed's (predict ``P = Phi P Phi^T + Q``; gain
``K = P H^T (H P H^T + R)^-1``; ``P = (I - K H) P``) [seed 000, sect. 2, steps 1-3]. It converges
to the steady-state gain of :func:`steady_state_gain` in well under 30 cycles from any large
initial ``P`` [seed 000, sect. 2], after which the filter is the seed's eq 5
``x_k+1 = Phi x_k + K_inf (z_k+1 - H Phi x_k)``. The recursion is kept (not only eq 5) because a
receiver that loses its fix (``valid = False``) predicts only and its covariance grows; the gain
then re-converges.

Known property the seed is about: under manoeuvres the constant-velocity model lags, so the
velocity output is biased (order 0.5 m/s in speed and 10 deg in course at ``S_p = 0.01`` for a
100 m ship turning from 7 m/s; larger at lower ``S_p``) [seed 000, sect. 2-3, figs 2-4].
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.io.yamlio import finite_number, shown
from trafficsim.jit import inline_kernel, kernel
from trafficsim.sensors import wrap_2pi

#: state layout of ``PVState.x``: north, east position (m), north, east velocity (m/s)
N_STATE = 4
POS_N, POS_E, VEL_N, VEL_E = range(N_STATE)
#: indices of the per-axis covariance blocks and of the entries in a block
AXIS_NORTH, AXIS_EAST = 0, 1
POS, VEL = 0, 1

#: config defaults: DGPS position noise, the seed's optimal S_p, 1 s updates [seed 000, sect. 2]
DEFAULT_SIGMA_M = 2.0
DEFAULT_SP_M2PS3 = 0.01
DEFAULT_DT_S = 1.0
#: default initial velocity uncertainty when the filter starts without a velocity, m/s
DEFAULT_SIGMA_VEL0_MPS = 10.0


@dataclass(frozen=True)
class PVParams:
    """Per-ship filter constants, each ``(n,)``.

    Attributes:
        sigma_m: standard deviation of the position fix per axis (north and east), m.
        sp: spectral density ``S_p`` of the white-noise acceleration, m^2/s^3 [seed 000, eq 4].
        dt_s: filter cycle (time between fixes), s.
    """

    sigma_m: np.ndarray
    sp: np.ndarray
    dt_s: np.ndarray

    @property
    def n(self) -> int:
        return int(self.sigma_m.shape[0])


@dataclass(frozen=True)
class PVState:
    """Filter state of ``n`` ships.

    Attributes:
        x: ``(n, 4)`` estimate ``[north_m, east_m, v_north_mps, v_east_mps]`` (earth frame, NED).
        P: ``(n, 2, 2, 2)`` error covariance as per-axis blocks ``[ship, axis, i, j]``, axis 0
            north, 1 east, ``i, j`` 0 position (m), 1 velocity (m/s); units m^2, m^2/s, m^2/s^2.
    """

    x: np.ndarray
    P: np.ndarray


def build(configs: Sequence[Mapping[str, Any]]) -> PVParams:
    """Parameters from one config dict per ship.

    Keys (all optional; other keys are ignored so a GNSS sensor config can be shared):
    ``sigma_m`` position noise per axis, m (default 2.0 [seed 000, eq 4: R = 4 m^2]);
    ``sp_m2ps3`` acceleration noise spectral density S_p, m^2/s^3 (default 0.01, the seed's
    optimum); ``dt_s`` filter cycle, s (default 1.0).

    Raises:
        InputError: a value is not a finite positive number.
    """
    def column(key: str, default: float) -> np.ndarray:
        values = np.empty(len(configs))
        for i, c in enumerate(configs):
            value = finite_number(c.get(key, default))
            if value is None or not value > 0.0:
                raise InputError(f"ship {i}: expected a finite positive number, got "
                                 f"{shown(c.get(key, default))}", key=key)
            values[i] = value
        return values

    return PVParams(sigma_m=column("sigma_m", DEFAULT_SIGMA_M),
                    sp=column("sp_m2ps3", DEFAULT_SP_M2PS3),
                    dt_s=column("dt_s", DEFAULT_DT_S))


def _tracking_index(sigma_m: Any, sp: Any, dt: Any) -> np.ndarray:
    """``lambda = sqrt(S_p dt^3) / sigma``: process over measurement noise per cycle."""
    return np.sqrt(np.asarray(sp, float) * np.asarray(dt, float) ** 3) / np.asarray(sigma_m, float)


def _steady_alpha_beta(sigma_m: Any, sp: Any, dt: Any) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state ``alpha`` (position gain) and ``beta`` (velocity gain x dt), dimensionless.

    Solves the discrete algebraic Riccati equation of this model per axis in closed form, the
    alpha-beta filter of Kalata's tracking index (Kalata P.R. 1984, "The tracking index: a
    generalized parameter for alpha-beta and alpha-beta-gamma target trackers", IEEE Trans. AES
    20(2)) worked for the seed's continuous white-noise Q (eq 4) instead of Kalata's
    piecewise-constant one. With ``alpha = M_pp / (M_pp + R)``, ``beta = dt M_pv / (M_pp + R)``
    (``M`` the predicted covariance) the fixed point of the recursion gives::

        beta^2 = lambda^2 (1 - alpha),     alpha^2 = (2 - alpha) beta - beta^2 / 6

    Writing ``s = sqrt(1 - alpha)`` makes the quartic in ``s`` palindromic,
    ``(s + 1/s)^2 - lambda (s + 1/s) + lambda^2 / 6 - 4 = 0``, hence::

        w = (lambda + sqrt(16 + lambda^2 / 3)) / 2,   s = (w - sqrt(w^2 - 4)) / 2,
        alpha = 1 - s^2,   beta = lambda s,

    with ``s`` computed as ``2 / (w + sqrt(w^2 - 4))`` (the same root, the other being
    ``1/s``), which does not cancel at a large tracking index.
    """
    lam = _tracking_index(sigma_m, sp, dt)
    w = 0.5 * (lam + np.sqrt(16.0 + lam * lam / 3.0))
    s = 2.0 / (w + np.sqrt(np.maximum(w * w - 4.0, 0.0)))
    return 1.0 - s * s, lam * s


def steady_state_gain(sigma_m: Any, sp: Any, dt: Any) -> np.ndarray:
    """Steady-state Kalman gain ``K_inf`` per axis [seed 000, eq 5].

    Args:
        sigma_m: position noise, m; ``sp``: S_p, m^2/s^3; ``dt``: cycle, s. Scalars or arrays of
            one broadcast shape ``S``.

    Returns:
        ``S + (2,)``: ``[K_position (dimensionless), K_velocity (1/s)]``, the same for north and
        east (the 4x4 ``K_inf`` of the seed is this block on each axis).
    """
    alpha, beta = _steady_alpha_beta(sigma_m, sp, dt)
    return np.stack([alpha, beta / np.asarray(dt, float)], axis=-1)


def steady_state_covariance(sigma_m: Any, sp: Any, dt: Any) -> np.ndarray:
    """Steady-state a-posteriori covariance block of one axis.

    From the same fixed point as :func:`steady_state_gain` (``r = sigma^2``, ``q = S_p``)::

        P_pp = alpha r,   P_pv = beta r / dt,   P_vv = q dt / beta - beta r / dt^2 - q dt / 2

    Args:
        sigma_m, sp, dt: as :func:`steady_state_gain`.

    Returns:
        ``S + (2, 2)`` covariance of (position m, velocity m/s).
    """
    alpha, beta = _steady_alpha_beta(sigma_m, sp, dt)
    r = np.asarray(sigma_m, float) ** 2
    q, dt = np.asarray(sp, float), np.asarray(dt, float)
    ppv = beta * r / dt
    out = np.empty((*np.shape(alpha), 2, 2))
    out[..., POS, POS] = alpha * r
    out[..., POS, VEL] = out[..., VEL, POS] = ppv
    out[..., VEL, VEL] = q * dt / beta - beta * r / dt**2 - 0.5 * q * dt
    return out


def init(params: PVParams, north_m: Any, east_m: Any, v_north_mps: Any = 0.0,
         v_east_mps: Any = 0.0, sigma_pos_m: Any = None,
         sigma_vel_mps: Any = DEFAULT_SIGMA_VEL0_MPS, converged: bool = False) -> PVState:
    """Initial filter state, typically at the first fix.

    Args:
        params: filter parameters of ``n`` ships.
        north_m, east_m: ``(n,)`` (or scalar) initial position, m.
        v_north_mps, v_east_mps: ``(n,)`` (or scalar) initial velocity, m/s (default at rest).
        sigma_pos_m: ``(n,)`` initial position standard deviation, m (default ``params.sigma_m``).
        sigma_vel_mps: ``(n,)`` initial velocity standard deviation, m/s (default 10).
        converged: start from the steady-state covariance (:func:`steady_state_covariance`)
            instead of the diagonal one given by the two sigmas, e.g. for a receiver that has been
            running long before the simulation starts.

    Returns:
        The state; ``P`` is the same on both axes.
    """
    n = params.n
    x = np.empty((n, N_STATE))
    x[:, POS_N] = north_m
    x[:, POS_E] = east_m
    x[:, VEL_N] = v_north_mps
    x[:, VEL_E] = v_east_mps
    if converged:
        block = steady_state_covariance(params.sigma_m, params.sp, params.dt_s)
    else:
        sp0 = params.sigma_m if sigma_pos_m is None else np.broadcast_to(sigma_pos_m, (n,))
        sv0 = np.broadcast_to(np.asarray(sigma_vel_mps, float), (n,))
        block = np.zeros((n, 2, 2))
        block[:, POS, POS] = np.square(sp0)
        block[:, VEL, VEL] = np.square(sv0)
    P = np.repeat(block[:, None, :, :], 2, axis=1)
    return PVState(x=x, P=P)


def predict(params: PVParams, state: PVState) -> PVState:
    """Time update over one cycle ``params.dt_s``: ``x = Phi x``, ``P = Phi P Phi^T + Q``.

    [seed 000, eqs 3-4 and recursion step 1], per axis in closed form (one compiled loop).
    """
    x, P = np.empty_like(state.x), np.empty_like(state.P)
    _predict(state.x, state.P, params.dt_s, params.sp, x, P)
    return PVState(x=x, P=P)


@kernel
def _predict(x0: np.ndarray, P0: np.ndarray, dt_s: np.ndarray, sp: np.ndarray, x: np.ndarray,
             P: np.ndarray) -> None:
    for i in range(x0.shape[0]):
        dt, q = dt_s[i], sp[i]
        x[i, POS_N] = x0[i, POS_N] + dt * x0[i, VEL_N]
        x[i, POS_E] = x0[i, POS_E] + dt * x0[i, VEL_E]
        x[i, VEL_N] = x0[i, VEL_N]
        x[i, VEL_E] = x0[i, VEL_E]
        for a in range(2):
            pp, pv, vv = P0[i, a, POS, POS], P0[i, a, POS, VEL], P0[i, a, VEL, VEL]
            P[i, a, POS, POS] = pp + 2.0 * dt * pv + dt * dt * vv + q * dt**3 / 3.0
            P[i, a, POS, VEL] = pv + dt * vv + 0.5 * q * dt * dt
            P[i, a, VEL, POS] = P[i, a, POS, VEL]
            P[i, a, VEL, VEL] = vv + q * dt


def gain(params: PVParams, predicted: PVState) -> np.ndarray:
    """Kalman gain ``K = P H^T (H P H^T + R)^-1`` per axis [seed 000, recursion step 2].

    Args:
        params: filter parameters.
        predicted: state after :func:`predict`.

    Returns:
        ``(n, 2, 2)`` gain ``[ship, axis, (position -, velocity 1/s)]``.
    """
    P = predicted.P
    s = P[:, :, POS, POS] + np.square(params.sigma_m)[:, None]  # innovation variance, m^2
    return P[:, :, :, POS] / s[:, :, None]


def update(params: PVParams, predicted: PVState, z_north: Any, z_east: Any,
           valid: Any = True) -> PVState:
    """Measurement update with a position fix [seed 000, recursion steps 2-3 and state step 2].

    Args:
        params: filter parameters.
        predicted: state after :func:`predict`.
        z_north, z_east: ``(n,)`` measured position, m (ignored, may be NaN, where not valid).
        valid: ``(n,)`` bool, False where the receiver has no fix (the prediction is kept); a
            NaN fix counts as none too, as in :func:`trafficsim.estimation.ca.update`.

    Returns:
        The updated state.
    """
    n = params.n
    zn = np.ascontiguousarray(np.broadcast_to(np.asarray(z_north, float), (n,)))
    ze = np.ascontiguousarray(np.broadcast_to(np.asarray(z_east, float), (n,)))
    ok = np.ascontiguousarray(np.broadcast_to(np.asarray(valid, bool), (n,))
                              & ~np.isnan(zn) & ~np.isnan(ze))
    x, P = predicted.x.copy(), predicted.P.copy()
    _update(x, P, params.sigma_m, zn, ze, ok)
    return PVState(x=x, P=P)


@inline_kernel
def update_axis(x: np.ndarray, P: np.ndarray, i: int, a: int, r: float, z: float) -> None:
    """Update axis ``a`` of filter ``i`` (``x (n, 4)``, ``P (n, 2, 2, 2)``, in place) with
    the position ``z`` of variance ``r``: gain ``K = (pp, pv) / s``, ``s = pp + r``, and
    ``P = (I - K H) P`` in closed form, symmetric by construction and positive definite
    (``vv - pv^2 / s > 0`` since ``pv^2 <= pp vv < s vv``). One division, the rest products
    with ``1 / s``."""
    pos, vel = (POS_N, VEL_N) if a == 0 else (POS_E, VEL_E)
    pp, pv, vv = P[i, a, POS, POS], P[i, a, POS, VEL], P[i, a, VEL, VEL]
    inv = 1.0 / (pp + r)
    nu = z - x[i, pos]
    x[i, pos] += pp * inv * nu
    x[i, vel] += pv * inv * nu
    P[i, a, POS, POS] = pp * r * inv
    P[i, a, POS, VEL] = P[i, a, VEL, POS] = pv * r * inv
    P[i, a, VEL, VEL] = vv - pv * pv * inv


@kernel
def _update(x: np.ndarray, P: np.ndarray, sigma_m: np.ndarray, zn: np.ndarray, ze: np.ndarray,
            ok: np.ndarray) -> None:
    for i in range(x.shape[0]):
        if ok[i]:  # no fix: keep the prediction (a NaN fix cannot leak)
            r = sigma_m[i] * sigma_m[i]
            update_axis(x, P, i, 0, r, zn[i])
            update_axis(x, P, i, 1, r, ze[i])


def step(params: PVParams, state: PVState, z_north: Any, z_east: Any,
         valid: Any = True) -> PVState:
    """One filter cycle: :func:`predict` then :func:`update` (predict only where not ``valid``).

    Args:
        params: filter parameters of ``n`` ships.
        state: state at the previous fix.
        z_north, z_east: ``(n,)`` position fix at the end of the cycle, m.
        valid: ``(n,)`` bool, False = no fix this cycle.

    Returns:
        The state at the new fix.
    """
    return update(params, predict(params, state), z_north, z_east, valid)


def velocity_over_ground(state: PVState) -> tuple[np.ndarray, np.ndarray]:
    """The receiver's speed and course over ground from the velocity states [seed 000, eq 6].

    Returns:
        ``(sog_mps, cog_rad)``, each ``(n,)``; course in [0, 2 pi), 0 = north, clockwise.
    """
    vn, ve = state.x[:, VEL_N], state.x[:, VEL_E]
    return np.hypot(vn, ve), wrap_2pi(np.arctan2(ve, vn))


def full_covariance(state: PVState) -> np.ndarray:
    """The ``(n, 4, 4)`` covariance in the order of ``x`` ([N, E, vN, vE]); off-axis blocks 0."""
    n = state.P.shape[0]
    out = np.zeros((n, N_STATE, N_STATE))
    for axis, (ip, iv) in enumerate(((POS_N, VEL_N), (POS_E, VEL_E))):
        out[:, ip, ip] = state.P[:, axis, POS, POS]
        out[:, ip, iv] = out[:, iv, ip] = state.P[:, axis, POS, VEL]
        out[:, iv, iv] = state.P[:, axis, VEL, VEL]
    return out


def nees(state: PVState, truth: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``e^T P^-1 e`` (4 degrees of freedom when consistent).

    Args:
        state: filter state.
        truth: ``(n, 4)`` true ``[north_m, east_m, v_north_mps, v_east_mps]``.

    Returns:
        ``(n,)`` NEES, the sum of the two axes' 2x2 quadratic forms (closed-form inverses).
    """
    e = state.x - truth
    ep = e[:, [POS_N, POS_E]]
    ev = e[:, [VEL_N, VEL_E]]
    P = state.P
    pp, pv, vv = P[:, :, POS, POS], P[:, :, POS, VEL], P[:, :, VEL, VEL]
    det = pp * vv - pv * pv
    return np.sum((vv * ep * ep - 2.0 * pv * ep * ev + pp * ev * ev) / det, axis=1)
