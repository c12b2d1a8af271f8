"""Fusion of several GNSS receivers by weight matrices with cross-covariances [seed 003].

Seed 003 (Borkowski et al., Transport Problems, 2008; after Sun & Deng 2004) fuses the estimates
``x_i`` of ``l`` sensors by the weighted mean [seed 003, eq 2]::

    x_f = A_1 x_1 + ... + A_l x_l,      A_1 + ... + A_l = I

Its weight formula [eq 3], ``A_i = (sum_j P_jj^-1)^-1 P_ii^-1``, uses the sensors' own
covariances only; it is the optimum when the sensors' errors are uncorrelated. With the joint
covariance ``Sigma`` (blocks ``P_ij``, the cross-covariances of eq 4 off the diagonal) the
minimum-variance unbiased (BLUE) weights are those of Sun & Deng (2004, Automatica 40:1017-1023,
the paper's refs [7, 8]), implemented by :func:`fuse`::

    P_f = (e^T Sigma^-1 e)^-1,    [A_1 ... A_l] = P_f e^T Sigma^-1,    e = [I; ...; I]

which minimises the trace of the fused error covariance ("optimal as it minimizes the trace of
fusion estimate error variance matrix" [seed 003, ch 2]) and reduces to eq 3 when every
``P_ij = 0`` (i != j) (:func:`fuse_uncorrelated`, tested equal). Positive cross-covariance (common
atmospheric or multipath error of receivers on one ship) reduces the gain from fusion: for two
receivers with standard deviations ``s1``, ``s2`` and correlation ``rho`` the fused variance is
``s1^2 s2^2 (1 - rho^2) / (s1^2 + s2^2 - 2 rho s1 s2)`` (tested).

For local Kalman filters, one per receiver, the cross-covariance of their estimation errors
follows [seed 003, eq 4] (:func:`cross_covariance_step`); :func:`joint_covariance` assembles
``Sigma`` for raw fixes from per-receiver covariances and correlation coefficients.

Receivers sit at different places on board: a fix is moved to the common reference point with the
heading [seed 003, eq 5] (:func:`to_reference_point`), and a heading error ``e`` adds up to
``2 |w| sin(e / 2)`` to the moved fix [eq 6] (:func:`lever_arm_error_m`). Per the paper, a
receiver's standard deviation is half its 95 % error [seed 003, ch 2] (``error95_m`` key).

Shapes: ``n`` ships, ``k`` receivers (slots; a ship with fewer receivers or a receiver without a
fix this step has ``valid`` False there), ``d = 2`` (north, east, m). All functions are vectorised
over ships (numpy, batched ``numpy.linalg`` on ``(n, 2k, 2k)`` stacks); no randomness.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

#: dimension of a position fix (north, east)
D = 2


@dataclass(frozen=True)
class FusionParams:
    """Receivers of every ship, ``(n, k)`` arrays (k = most receivers on any ship).

    Attributes:
        sigma_m: standard deviation of each position component of each receiver, m.
        offset_x_m, offset_y_m: body-frame vector from the receiver's antenna to the ship's
            reference point (x forward, y starboard), m: the ``w`` of [seed 003, eq 5].
        present: bool, the receiver slot exists on that ship.
        correlation: ``(n,)`` correlation coefficient of the errors of any two receivers of the
            ship (common-mode error), in [0, 1).
    """

    sigma_m: np.ndarray
    offset_x_m: np.ndarray
    offset_y_m: np.ndarray
    present: np.ndarray
    correlation: np.ndarray


#: keys of one receiver's config dict and their defaults; ``error95_m`` (the manufacturer's 95 %
#: horizontal figure) gives sigma = error95_m / 2 [seed 003, ch 2] when ``sigma_m`` is absent
RECEIVER_DEFAULTS: Mapping[str, float] = {"sigma_m": 5.0, "offset_x_m": 0.0, "offset_y_m": 0.0}


def build(configs: Sequence[Mapping[str, Any]]) -> FusionParams:
    """Receiver tables from per-ship configs.

    Each config: ``{"receivers": [{"sigma_m" or "error95_m", "offset_x_m", "offset_y_m"}, ...],
    "correlation": 0.0}`` (receiver keys default to :data:`RECEIVER_DEFAULTS`; a ship without
    ``receivers`` has one receiver at the reference point).
    """
    recs = [list(c.get("receivers", [{}])) for c in configs]
    n, k = len(configs), max(1, max((len(r) for r in recs), default=1))
    sigma = np.full((n, k), np.nan)
    ox = np.zeros((n, k))
    oy = np.zeros((n, k))
    present = np.zeros((n, k), dtype=bool)
    for i, ship in enumerate(recs):  # build time only
        for j, rc in enumerate(ship):
            unknown = set(rc) - {*RECEIVER_DEFAULTS, "error95_m"}
            if unknown:
                raise ValueError(f"unknown receiver keys {sorted(unknown)}")
            if "sigma_m" in rc:
                sigma[i, j] = float(rc["sigma_m"])
            elif "error95_m" in rc:
                sigma[i, j] = sigma_from_error95(float(rc["error95_m"]))
            else:
                sigma[i, j] = RECEIVER_DEFAULTS["sigma_m"]
            ox[i, j] = float(rc.get("offset_x_m", 0.0))
            oy[i, j] = float(rc.get("offset_y_m", 0.0))
            present[i, j] = True
    if not np.all(sigma[present] > 0.0):  # (NaN fails too)
        raise ValueError("receiver sigma_m must be > 0")
    sigma[~present] = 1.0  # unused slots: any positive number keeps the algebra finite
    rho = np.array([float(c.get("correlation", 0.0)) for c in configs])
    if not np.all((rho >= 0.0) & (rho < 1.0)):
        raise ValueError("correlation must be in [0, 1)")
    return FusionParams(sigma, ox, oy, present, rho)


def sigma_from_error95(error95_m: float | np.ndarray) -> float | np.ndarray:
    """Standard deviation from a 95 % error figure: half of it, as [seed 003, ch 2] defines
    ("a half of the error at 95% confidence level"). That is the rule for one axis; a
    manufacturer's horizontal 95 % radius of a circular error is 2.448 sigma per axis, so
    this sigma is then 22 % too large (give ``sigma_m`` instead)."""
    return 0.5 * error95_m


def to_reference_point(north_m: np.ndarray, east_m: np.ndarray, heading_rad: np.ndarray,
                       offset_x_m: np.ndarray, offset_y_m: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Move antenna fixes to the reference point [seed 003, eq 5].

    ``north + w_x cos(psi) - w_y sin(psi)``, ``east + w_y cos(psi) + w_x sin(psi)`` with ``w`` the
    body-frame vector from the antenna to the reference point. Arrays broadcast (e.g. ``(n, k)``
    fixes with ``(n, 1)`` heading).
    """
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    return north_m + offset_x_m * c - offset_y_m * s, east_m + offset_y_m * c + offset_x_m * s


def lever_arm_error_m(offset_x_m: np.ndarray, offset_y_m: np.ndarray,
                      heading_error_rad: np.ndarray) -> np.ndarray:
    """Position error added by moving a fix with a wrong heading [seed 003, eq 6]:
    ``2 |w| sin(e / 2)`` (the chord of the lever arm turned by the heading error)."""
    return 2.0 * np.hypot(offset_x_m, offset_y_m) * np.abs(np.sin(0.5 * heading_error_rad))


def _chol2(cov: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a stack of 2x2 covariances ``(..., 2, 2)`` in closed form."""
    L = np.zeros_like(cov)
    a = np.sqrt(cov[..., 0, 0])
    L[..., 0, 0] = a
    L[..., 1, 0] = cov[..., 1, 0] / a
    L[..., 1, 1] = np.sqrt(np.maximum(cov[..., 1, 1] - L[..., 1, 0] ** 2, 0.0))
    return L


def joint_covariance(cov: np.ndarray, correlation: np.ndarray | float) -> np.ndarray:
    """Joint covariance ``Sigma (n, 2k, 2k)`` of ``k`` receivers' fixes.

    Receiver ``i`` has error ``L_i w_i`` with ``L_i`` the Cholesky factor of its covariance; the
    errors of receivers ``i`` and ``j`` have correlation ``rho_ij`` per component, so the
    cross-covariance block is ``P_ij = rho_ij L_i L_j^T`` (``P_ij = rho_ij s_i s_j I`` for
    isotropic receivers).

    Args:
        cov: ``(n, k, 2, 2)`` each receiver's covariance, m2.
        correlation: ``(n,)`` or scalar common correlation of every pair, or ``(n, k, k)``
            correlation matrices (must be positive semi-definite for Sigma to be).
    """
    n, k = cov.shape[:2]
    rho = np.asarray(correlation, dtype=float)
    if rho.ndim <= 1:
        r = np.broadcast_to(rho, (n,))[:, None, None]
        rho = np.where(np.eye(k, dtype=bool)[None], 1.0, r)
    L = _chol2(cov)  # (n, k, 2, 2)
    blocks = rho[:, :, :, None, None] * np.einsum("niab,njcb->nijac", L, L)
    return blocks.transpose(0, 1, 3, 2, 4).reshape(n, D * k, D * k)


def receiver_covariance(params: FusionParams) -> np.ndarray:
    """Isotropic per-receiver covariances ``(n, k, 2, 2)`` from ``params.sigma_m``."""
    cov = np.zeros((*params.sigma_m.shape, D, D))
    cov[..., 0, 0] = cov[..., 1, 1] = params.sigma_m**2
    return cov


class Fused(NamedTuple):
    """Result of a fusion, per ship.

    Attributes:
        position: ``(n, 2)`` fused north, east (m); NaN where no receiver was valid.
        cov: ``(n, 2, 2)`` its error covariance P_f (m2); NaN where not valid.
        weights: ``(n, k, 2, 2)`` the weight matrices A_i [seed 003, eq 2-3] (0 for invalid
            receivers); they sum to the identity.
        valid: ``(n,)`` bool, at least one receiver contributed.
    """

    position: np.ndarray
    cov: np.ndarray
    weights: np.ndarray
    valid: np.ndarray


def fuse(fixes: np.ndarray, sigma: np.ndarray, valid: np.ndarray | None = None) -> Fused:
    """Minimum-variance (BLUE) fusion of ``k`` fixes with a joint covariance (Sun & Deng 2004).

    ``P_f = (e^T Sigma^-1 e)^-1``, ``A = P_f e^T Sigma^-1``, ``x_f = sum_i A_i x_i``
    [seed 003, eqs 2-3 generalised to cross-covariances]. Receivers marked invalid are removed
    exactly: their rows and columns of Sigma are replaced by identity blocks decoupled from the
    rest and their blocks of ``e`` zeroed, so the result is the BLUE of the valid ones.

    Args:
        fixes: ``(n, k, 2)`` north/east fixes (already at the common reference point), m.
        sigma: ``(n, 2k, 2k)`` joint covariance (receiver-major: rows ``2i, 2i+1`` are receiver
            i), m2.
        valid: ``(n, k)`` bool, default all.
    """
    n, k = fixes.shape[:2]
    valid = np.ones((n, k), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    v2 = np.repeat(valid, D, axis=1)  # (n, 2k)
    keep = v2[:, :, None] & v2[:, None, :]
    S = np.where(keep, sigma, 0.0)
    S = S + np.where(~v2, 1.0, 0.0)[:, :, None] * np.eye(D * k)[None]
    E = np.where(v2[:, :, None], np.tile(np.eye(D), (k, 1))[None], 0.0)  # (n, 2k, 2)
    SiE = np.linalg.solve(S, E)  # Sigma^-1 e, batched
    info = np.einsum("nai,naj->nij", E, SiE)  # e^T Sigma^-1 e
    ok = valid.any(axis=1)
    info[~ok] = np.eye(D)  # keep the algebra finite; flagged invalid below
    Pf = np.linalg.inv(info)
    Pf = 0.5 * (Pf + Pf.transpose(0, 2, 1))
    A = np.einsum("nij,naj->nia", Pf, SiE)  # (n, 2, 2k) = P_f e^T Sigma^-1
    W = A.reshape(n, D, k, D).transpose(0, 2, 1, 3)  # (n, k, 2, 2): A_i
    W = np.where(valid[:, :, None, None], W, 0.0)
    x = np.einsum("nkij,nkj->ni", W, np.where(valid[:, :, None], fixes, 0.0))
    x[~ok] = np.nan
    Pf[~ok] = np.nan
    return Fused(x, Pf, W, ok)


def fuse_uncorrelated(fixes: np.ndarray, cov: np.ndarray, valid: np.ndarray | None = None
                      ) -> Fused:
    """Fusion by the weight matrices of [seed 003, eq 3]: ``A_i = (sum_j P_jj^-1)^-1 P_ii^-1``.

    Optimal when the receivers' errors are uncorrelated; with correlated errors its covariance
    ``(sum_j P_jj^-1)^-1`` is too optimistic (tested). Closed-form 2x2 inverses, no solve.

    Args:
        fixes: ``(n, k, 2)`` fixes, m; cov: ``(n, k, 2, 2)`` each receiver's covariance, m2;
        valid: ``(n, k)`` bool, default all.
    """
    n, k = fixes.shape[:2]
    valid = np.ones((n, k), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    inv = _inv2(cov)
    inv = np.where(valid[:, :, None, None], inv, 0.0)
    info = inv.sum(axis=1)
    ok = valid.any(axis=1)
    info[~ok] = np.eye(D)
    Pf = _inv2(info)
    W = np.einsum("nij,nkjl->nkil", Pf, inv)
    x = np.einsum("nkij,nkj->ni", W, np.where(valid[:, :, None], fixes, 0.0))
    x[~ok] = np.nan
    Pf[~ok] = np.nan
    return Fused(x, Pf, W, ok)


def _inv2(m: np.ndarray) -> np.ndarray:
    """Inverse of a stack of 2x2 matrices ``(..., 2, 2)`` in closed form."""
    det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    out = np.empty_like(m)
    out[..., 0, 0] = m[..., 1, 1] / det
    out[..., 1, 1] = m[..., 0, 0] / det
    out[..., 0, 1] = -m[..., 0, 1] / det
    out[..., 1, 0] = -m[..., 1, 0] / det
    return out


def cross_covariance_step(P_ij: np.ndarray, Phi: np.ndarray, Q: np.ndarray, K_i: np.ndarray,
                          H_i: np.ndarray, K_j: np.ndarray, H_j: np.ndarray) -> np.ndarray:
    """Cross-covariance of the errors of two local Kalman filters after one step [seed 003, eq 4].

    ``P_ij(t) = (I - K_i H_i) (Phi P_ij(t-1) Phi^T + Q) (I - K_j H_j)^T`` for two filters on the
    same state model (``Phi``, ``Q``) with different sensors; ``i = j`` gives each filter's own
    covariance (with the Joseph term ``K R K^T`` added, see the tests). All arguments are stacks
    over ships (or broadcastable): ``P_ij, Phi, Q (n, s, s)``, ``K (n, s, m)``, ``H (n, m, s)``.
    """
    s = Phi.shape[-1]
    eye = np.eye(s)
    Ii = eye - K_i @ H_i
    Ij = eye - K_j @ H_j
    return Ii @ (Phi @ P_ij @ np.swapaxes(Phi, -1, -2) + Q) @ np.swapaxes(Ij, -1, -2)


def fuse_receivers(params: FusionParams, north_m: np.ndarray, east_m: np.ndarray,
                   heading_rad: np.ndarray, valid: np.ndarray) -> Fused:
    """The ship's position from its receivers' raw fixes: eq 5 then BLUE fusion.

    Args:
        params: receiver tables; north_m, east_m: ``(n, k)`` antenna fixes, m.
        heading_rad: ``(n,)`` heading used to move the fixes (compass or estimate), rad.
        valid: ``(n, k)`` bool, a fix this step (combined with ``params.present``).
    """
    n_ref, e_ref = to_reference_point(north_m, east_m, heading_rad[:, None], params.offset_x_m,
                                      params.offset_y_m)
    sigma = joint_covariance(receiver_covariance(params), params.correlation)
    return fuse(np.stack([n_ref, e_ref], axis=-1), sigma, valid & params.present)


def two_receiver_variance(s1: float, s2: float, rho: float) -> float:
    """Fused variance of two scalar measurements with standard deviations ``s1``, ``s2`` and
    correlation ``rho``: ``s1^2 s2^2 (1 - rho^2) / (s1^2 + s2^2 - 2 rho s1 s2)`` (BLUE)."""
    return s1 * s1 * s2 * s2 * (1.0 - rho * rho) / (s1 * s1 + s2 * s2 - 2.0 * rho * s1 * s2)
