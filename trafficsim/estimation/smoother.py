"""Fixed-interval Rauch-Tung-Striebel smoother and the trial-data preprocessing of seed 001.

Smoother [seed 001, eq 8], backwards from ``X(N|N) = X(N)``::

    A_s(k)   = P(k) Phi^T P(k+1|k)^-1
    X(k|N)   = X(k) + A_s(k) [X(k+1|N) - Phi X(k)]
    P(k|N)   = P(k) + A_s(k) [P(k+1|N) - P(k+1|k)] A_s(k)^T

The covariance recursion (third line) is not printed in the paper; it is the standard RTS
result (Rauch, Tung & Striebel 1965): the smoothed error is the filtered error corrected by the
gain-weighted error of the later smoothed estimate. ``A_s`` is computed as
``solve(P(k+1|k), Phi P(k))^T`` (a batched LAPACK solve over series, no explicit inverse,
no Python loop over series).

The CA filter has no estimate at the first sample (it initialises from two samples); the smoothed
estimate there is the backward model prediction ``Phi^-1 X(1|N)`` with covariance
``Phi^-1 (P(1|N) + Q) Phi^-T``, which is the limit of the RTS step for a filtered covariance
growing without bound (no information at sample 0). Our addition, so that smoothed records
cover every sample.

:func:`body_velocities` turns a recorded track (position, heading) into surge, sway and yaw rate
the way seed 001 section 4.1 does for identification data.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from trafficsim.estimation import ca
from trafficsim.sensors import wrap_2pi


class Smoothed(NamedTuple):
    """Smoothed record."""

    x: np.ndarray  # (m, N, k) X(k|N)
    p: np.ndarray  # (m, N, k, k) P(k|N)


def rts(x: np.ndarray, p: np.ndarray, x_pred: np.ndarray, p_pred: np.ndarray,
        phi: np.ndarray, first: int = 0) -> Smoothed:
    """Fixed-interval RTS smoother [seed 001, eq 8] for any linear filter's record.

    Args:
        x: ``(m, N, k)`` filtered estimates X(j).
        p: ``(m, N, k, k)`` filtered covariances P(j).
        x_pred: ``(m, N, k)`` predictions X(j|j-1) (used for j > first).
        p_pred: ``(m, N, k, k)`` prediction covariances P(j|j-1) (used for j > first).
        phi: ``(m, k, k)`` transition, constant over the record.
        first: first sample with a filtered estimate; earlier samples are left NaN.

    Returns:
        :class:`Smoothed` with NaN before ``first``.
    """
    n = x.shape[1]
    xs = np.full_like(x, np.nan)
    ps = np.full_like(p, np.nan)
    xs[:, -1], ps[:, -1] = x[:, -1], p[:, -1]
    for j in range(n - 2, first - 1, -1):
        # A^T = P(j+1|j)^-1 Phi P(j)  (both covariances symmetric); a singular P(j+1|j) (no
        # process noise on a state the start left exact) takes the pseudo-inverse
        rhs = phi @ p[:, j]
        try:
            a = np.swapaxes(np.linalg.solve(p_pred[:, j + 1], rhs), -1, -2)
        except np.linalg.LinAlgError:
            a = np.swapaxes(np.linalg.pinv(p_pred[:, j + 1], hermitian=True) @ rhs, -1, -2)
        dx = xs[:, j + 1] - x_pred[:, j + 1]
        xs[:, j] = x[:, j] + np.einsum("mij,mj->mi", a, dx)
        pj = p[:, j] + a @ (ps[:, j + 1] - p_pred[:, j + 1]) @ np.swapaxes(a, -1, -2)
        ps[:, j] = 0.5 * (pj + np.swapaxes(pj, -1, -2))
    return Smoothed(xs, ps)


def smooth_ca(params: ca.CAParams, z: np.ndarray) -> Smoothed:
    """CA filter [seed 001, eqs 6-7] then RTS smoother [eq 8] over whole records.

    Args:
        params: :class:`~trafficsim.estimation.ca.CAParams` of ``m`` series.
        z: ``(m, N)`` measurements (NaN = missing; the first two must be present).

    Returns:
        :class:`Smoothed`, states ``(m, N, 3)`` = position, velocity, acceleration and
        covariances ``(m, N, 3, 3)``; sample 0 by the backward model prediction (module doc).
    """
    f = ca.run(params, z)
    phi = ca.transition(params.dt_s)
    out = rts(f.x, f.p, f.x_pred, f.p_pred, phi, first=1)
    phi_inv = ca.transition(-params.dt_s)  # the CA transition inverts by reversing time
    x0 = np.einsum("mij,mj->mi", phi_inv, out.x[:, 1])
    p0 = phi_inv @ (out.p[:, 1] + ca.process_noise(params)) @ np.swapaxes(phi_inv, -1, -2)
    out.x[:, 0], out.p[:, 0] = x0, p0
    return out


#: defaults of :func:`body_velocities` (our choices; seed 001 gives none)
BODY_DEFAULTS = {
    "sigma_pos_m": 1.0,          # position fix noise per axis
    "sigma_heading_rad": np.radians(0.2),  # compass noise
    "sigma_acc_mps2": 0.05,      # CA manoeuvre acceleration of a position axis
    "sigma_yaw_acc_radps2": 1e-3,  # CA manoeuvre "acceleration" of the heading (yaw accel.)
    "alpha_per_s": 1.0 / 30.0,
}


def body_velocities(north: np.ndarray, east: np.ndarray, heading: np.ndarray, dt: float,
                    *, sigma_pos_m: float = BODY_DEFAULTS["sigma_pos_m"],
                    sigma_heading_rad: float = BODY_DEFAULTS["sigma_heading_rad"],
                    sigma_acc_mps2: float = BODY_DEFAULTS["sigma_acc_mps2"],
                    sigma_yaw_acc_radps2: float = BODY_DEFAULTS["sigma_yaw_acc_radps2"],
                    alpha_per_s: float = BODY_DEFAULTS["alpha_per_s"],
                    current_north_mps: float | np.ndarray = 0.0,
                    current_east_mps: float | np.ndarray = 0.0) -> dict[str, np.ndarray]:
    """Surge, sway and yaw rate from a recorded track [seed 001, section 4.1, eq 9].

    North and east positions and the (unwrapped) heading are each smoothed by the CA filter and
    RTS smoother; then, with ``u_N, u_E`` the smoothed velocities::

        U    = sqrt(u_N^2 + u_E^2)
        chi  = atan2(u_E, u_N)            course over ground, 0 = north, clockwise
        beta = chi - psi                  drift angle [seed 001, after eq 9]
        u    = U cos beta,  v = U sin beta   [seed 001, eq 9, corrected]
        r    = d psi / dt                 smoothed heading rate

    Eq 9 as extracted reads ``u = cos beta, v = sin beta``, which has lost the factor ``U``; we
    use ``u = U cos beta, v = U sin beta``. The paper writes the course as
    ``arctan(u_xi / u_eta)`` in its own space axes; in our north-east frame with the heading
    clockwise from north the course is ``atan2(u_E, u_N)``, so that ``beta > 0`` means the ship
    moves to starboard of its heading and ``v > 0`` (starboard), matching the state convention.
    ``u, v`` are computed as the rotation of the ground velocity into the body frame, which
    equals the formulas above and stays defined at ``U = 0``.

    The smoothed velocities are over ground; ``u, v`` relative to the water (the simulator's
    state) subtract a known uniform current first (``current_*_mps``; seed 001's simulator data
    had none).

    Args:
        north, east: ``(N,)`` or ``(n, N)`` positions, m, sampled every ``dt`` s.
        heading: same shape, rad (any wrapping; unwrapped along time here).
        dt: sampling period, s.
        sigma_pos_m, sigma_heading_rad: measurement noise of position (per axis) and heading.
        sigma_acc_mps2, sigma_yaw_acc_radps2, alpha_per_s: CA process noise (see
            :mod:`trafficsim.estimation.ca`), position axes and heading respectively.
        current_north_mps, current_east_mps: scalar or ``(n,)`` current, m/s.

    Uncertainty: the smoothed covariances ``P(k|N)`` of the three independent series give the
    standard deviations of ``u, v, r`` to first order (the rotation's Jacobian):
    ``var u = cos^2 psi var u_N + sin^2 psi var u_E + v^2 var psi`` and
    ``var v = sin^2 psi var u_N + cos^2 psi var u_E + u^2 var psi``; ``var r`` is the heading
    series' own velocity variance.

    Missing samples (NaN) are skipped by the filter (prediction only); the heading is unwrapped
    over its finite samples, so a gap does not spoil the rest of the record. The first two samples
    of every series must be finite (they start the filter).

    Returns:
        dict of arrays with the input's shape: ``north_m, east_m, psi_rad`` (smoothed),
        ``u_mps, v_mps, r_radps, speed_mps`` (U), ``course_rad``, ``drift_rad`` (beta),
        ``vn_mps, ve_mps`` (smoothed ground velocity), and the standard deviations
        ``sigma_u_mps, sigma_v_mps, sigma_r_radps, sigma_psi_rad, sigma_north_m, sigma_east_m``.
    """
    north = np.asarray(north, dtype=float)
    shape = north.shape
    n_rows = 1 if north.ndim == 1 else shape[0]
    pos = np.stack([north.reshape(n_rows, -1), np.asarray(east, float).reshape(n_rows, -1)],
                   axis=1).reshape(2 * n_rows, -1)
    psi = unwrap_finite(np.asarray(heading, float).reshape(n_rows, -1))

    pos_sm = smooth_ca(ca.CAParams.of(2 * n_rows, dt, sigma_pos_m, sigma_acc_mps2, alpha_per_s),
                       pos)
    psi_sm = smooth_ca(ca.CAParams.of(n_rows, dt, sigma_heading_rad, sigma_yaw_acc_radps2,
                                      alpha_per_s), psi)
    pos_s = pos_sm.x.reshape(n_rows, 2, -1, 3)
    pos_p = pos_sm.p.reshape(n_rows, 2, -1, 3, 3)
    psi_s = psi_sm.x

    vn, ve = pos_s[:, 0, :, 1], pos_s[:, 1, :, 1]
    heading_s, r = psi_s[..., 0], psi_s[..., 1]
    cn = np.reshape(np.asarray(current_north_mps, float), (-1, 1))
    ce = np.reshape(np.asarray(current_east_mps, float), (-1, 1))
    wn, we = vn - cn, ve - ce  # velocity through the water, earth frame
    c, s = np.cos(heading_s), np.sin(heading_s)
    course = np.arctan2(ve, vn)
    out = {
        "north_m": pos_s[:, 0, :, 0], "east_m": pos_s[:, 1, :, 0],
        "psi_rad": heading_s, "r_radps": r,
        "u_mps": wn * c + we * s, "v_mps": -wn * s + we * c,
        "speed_mps": np.hypot(vn, ve), "course_rad": wrap_2pi(course),
        "drift_rad": np.angle(np.exp(1j * (course - heading_s))),
        "vn_mps": vn, "ve_mps": ve,
    }
    var_vn, var_ve = pos_p[:, 0, :, 1, 1], pos_p[:, 1, :, 1, 1]
    var_psi = psi_sm.p[..., 0, 0]
    u, v = out["u_mps"], out["v_mps"]
    out["sigma_u_mps"] = np.sqrt(c * c * var_vn + s * s * var_ve + v * v * var_psi)
    out["sigma_v_mps"] = np.sqrt(s * s * var_vn + c * c * var_ve + u * u * var_psi)
    out["sigma_r_radps"] = np.sqrt(psi_sm.p[..., 1, 1])
    out["sigma_psi_rad"] = np.sqrt(var_psi)
    out["sigma_north_m"] = np.sqrt(pos_p[:, 0, :, 0, 0])
    out["sigma_east_m"] = np.sqrt(pos_p[:, 1, :, 0, 0])
    return {k: v.reshape(shape) for k, v in out.items()}


def unwrap_finite(angle: np.ndarray) -> np.ndarray:
    """``np.unwrap`` along the last axis over the finite samples only (NaN stay NaN).

    ``np.unwrap`` would turn every sample after a NaN into NaN; here a gap is bridged by the
    shortest turn between the samples either side of it.
    """
    a = np.array(angle, dtype=float, copy=True)
    rows = a.reshape(int(np.prod(a.shape[:-1])), a.shape[-1])  # (-1 fails on no samples)
    for row in rows:  # one pass per series (records, not ships on a step path)
        ok = np.isfinite(row)
        row[ok] = np.unwrap(row[ok])
    return rows.reshape(a.shape)
