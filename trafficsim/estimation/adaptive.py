"""Innovation-based adaptive estimation of the measurement-noise covariance R.

Seed 004 proposes a Kalman filter whose parameters "automatically adjust ... depending on the
current state of measurement conditions" [seed 004, abstract and ch 1]; it does not spell out an
adaptation law. This module uses the classic innovation-based one (Mehra 1970, "On the
identification of variances and adaptive Kalman filtering", IEEE Trans. Autom. Control 15(2):
175-184; Myers & Tapley 1976, "Adaptive sequential estimation with unknown noise statistics",
IEEE Trans. Autom. Control 21(4):520-523): for an optimal filter the innovations
``nu = z - H x-`` are white with covariance ``S = H P- H^T + R`` [seed 002, eq 5.12], so over a
sliding window of the last ``N`` valid innovations the unbiased estimate is (Myers-Tapley form,
innovation mean removed)::

    nu_bar = (1/N) sum nu_j
    R_hat  = 1/(N-1) sum (nu_j - nu_bar)(nu_j - nu_bar)^T  -  (1/N) sum H P-_j H^T

``R_hat`` is made symmetric positive definite by clamping its eigenvalues to a floor variance.
When the true noise changes, the window holds only new innovations after ``N`` valid steps, so
``R_hat`` has followed within the window length (tested with the EKF of
:mod:`trafficsim.estimation.ekf`: GNSS noise doubling mid-run).

One estimator handles one measurement group of dimension ``m`` (GNSS: ``m = 2``, compass or log:
``m = 1``). Window sums are kept as running sums over a ring buffer (add the new innovation,
subtract the one leaving), so a step costs ``O(n m^2)`` whatever the window. Each ship has its own
window length (its ring wraps at its own length inside a buffer as long as the longest window).
No randomness, no loop over ships: numpy over all ships.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

#: measurement groups, the SI unit of their floor key, and the factor from that unit to SI
GROUPS: Mapping[str, tuple[str, float]] = {
    "gnss": ("floor_sigma_m", 1.0),
    "compass": ("floor_sigma_deg", math.pi / 180.0),
    "log": ("floor_sigma_mps", 1.0),
}
DEFAULT_WINDOW_STEPS = 60
DEFAULT_FLOOR_SIGMA = {"gnss": 0.1, "compass": 0.05, "log": 0.01}
#: longest window: a day of 1 s steps (the ring buffers grow with it, and a longer window
#: adapts to nothing within a run)
MAX_WINDOW_STEPS = 86_400
#: largest floor, in the floor key's unit: the instruments' own noise bounds (GNSS 1000 m,
#: compass 30 deg, log 5 m/s; :mod:`trafficsim.sensors`)
MAX_FLOOR_SIGMA = {"gnss": 1000, "compass": 30, "log": 5}


@dataclass(frozen=True)
class AdaptiveParams:
    """Per-ship settings, ``(n,)`` arrays.

    Attributes:
        window_steps: int64, number of most recent update steps in the window.
        min_samples: int64, valid innovations needed before the estimate replaces the prior R.
        floor_var: smallest eigenvalue allowed in R_hat (SI unit of the measurement, squared).
    """

    window_steps: np.ndarray
    min_samples: np.ndarray
    floor_var: np.ndarray


def build(configs: Sequence[Mapping[str, Any]], group: str) -> AdaptiveParams:
    """Settings for one measurement group (``"gnss"``, ``"compass"`` or ``"log"``).

    Keys: ``window_steps`` (default 60, at most :data:`MAX_WINDOW_STEPS`), ``min_samples``
    (default half the window, at least 3), and the floor standard deviation ``floor_sigma_m``
    (gnss, default 0.1 m), ``floor_sigma_deg`` (compass, 0.05 deg) or ``floor_sigma_mps`` (log,
    0.01 m/s), at most :data:`MAX_FLOOR_SIGMA`.
    """
    if group not in GROUPS:
        raise ValueError(f"group must be one of {list(GROUPS)}, got {group!r}")
    floor_key, factor = GROUPS[group]
    known = {"window_steps", "min_samples", floor_key}
    for cfg in configs:
        unknown = set(cfg) - known
        if unknown:
            raise ValueError(f"unknown adaptive-R keys {sorted(unknown)} for {group!r}; "
                             f"known: {sorted(known)}")
    window = np.array([int(c.get("window_steps", DEFAULT_WINDOW_STEPS)) for c in configs],
                      dtype=np.int64)
    if np.any(window < 3):
        raise ValueError("window_steps must be >= 3")
    if np.any(window > MAX_WINDOW_STEPS):
        raise ValueError(f"window_steps must be <= {MAX_WINDOW_STEPS}, got {window.max()}")
    min_samples = np.array([int(c.get("min_samples", max(3, w // 2)))
                            for c, w in zip(configs, window, strict=True)], dtype=np.int64)
    if np.any((min_samples < 2) | (min_samples > window)):
        raise ValueError("min_samples must be in [2, window_steps]")
    floor = np.array([float(c.get(floor_key, DEFAULT_FLOOR_SIGMA[group])) for c in configs])
    if np.any(floor <= 0.0):
        raise ValueError(f"{floor_key} must be > 0")
    if np.any(floor > MAX_FLOOR_SIGMA[group]):
        raise ValueError(f"{floor_key} must be <= {MAX_FLOOR_SIGMA[group]}, got "
                         f"{floor.max():g}")
    return AdaptiveParams(window, min_samples, (floor * factor) ** 2)


class AdaptiveState(NamedTuple):
    """Window buffers, running sums and the current estimate.

    Attributes:
        nu: ``(n, W, m)`` innovations in the ring buffer (W = longest window).
        hph: ``(n, W, m, m)`` the H P- H^T that went with them.
        used: ``(n, W)`` bool, the slot holds a valid innovation.
        head: ``(n,)`` int64, next slot to write (per-ship ring of length window_steps).
        count: ``(n,)`` int64, valid innovations in the window.
        sum_nu: ``(n, m)``; sum_nunu, sum_hph: ``(n, m, m)`` running window sums.
        R: ``(n, m, m)`` current estimate (the prior until ``min_samples`` are in the window).
    """

    nu: np.ndarray
    hph: np.ndarray
    used: np.ndarray
    head: np.ndarray
    count: np.ndarray
    sum_nu: np.ndarray
    sum_nunu: np.ndarray
    sum_hph: np.ndarray
    R: np.ndarray


def start(params: AdaptiveParams, R0: np.ndarray) -> AdaptiveState:
    """Empty window with the prior ``R0 (n, m, m)`` as the estimate."""
    R0 = np.asarray(R0, dtype=float)
    n, m = R0.shape[0], R0.shape[1]
    w = int(params.window_steps.max(initial=0))
    return AdaptiveState(
        nu=np.zeros((n, w, m)), hph=np.zeros((n, w, m, m)), used=np.zeros((n, w), dtype=bool),
        head=np.zeros(n, dtype=np.int64), count=np.zeros(n, dtype=np.int64),
        sum_nu=np.zeros((n, m)), sum_nunu=np.zeros((n, m, m)), sum_hph=np.zeros((n, m, m)),
        R=R0.copy())


def step(params: AdaptiveParams, state: AdaptiveState, nu: np.ndarray, hph: np.ndarray,
         valid: np.ndarray) -> AdaptiveState:
    """Add this step's innovations to the window and re-estimate R.

    Args:
        params: window settings; state: from :func:`start` or the previous step.
        nu: ``(n, m)`` innovations of the group (``Innovation.nu`` columns).
        hph: ``(n, m, m)`` their H P- H^T (``Innovation.hph`` block).
        valid: ``(n,)`` bool, the group was measured (all its components) this step; an invalid
            step still advances the window (the window is ``window_steps`` update steps).

    Returns:
        The new state; ``state.R`` is the estimate to use in the next update.
    """
    n = nu.shape[0]
    rows = np.arange(n)
    head = state.head
    valid = np.asarray(valid, dtype=bool)
    nu_v = np.where(valid[:, None], nu, 0.0)
    hph_v = np.where(valid[:, None, None], hph, 0.0)

    # leaving slot (if it held a valid innovation), then the new one in its place
    old_nu = state.nu[rows, head]
    old_used = state.used[rows, head]
    old_nu = np.where(old_used[:, None], old_nu, 0.0)
    old_hph = np.where(old_used[:, None, None], state.hph[rows, head], 0.0)
    sum_nu = state.sum_nu - old_nu + nu_v
    sum_nunu = (state.sum_nunu - old_nu[:, :, None] * old_nu[:, None, :]
                + nu_v[:, :, None] * nu_v[:, None, :])
    sum_hph = state.sum_hph - old_hph + hph_v
    count = state.count - old_used + valid

    buf_nu, buf_hph, used = state.nu.copy(), state.hph.copy(), state.used.copy()
    buf_nu[rows, head] = nu_v
    buf_hph[rows, head] = hph_v
    used[rows, head] = valid
    head = (head + 1) % params.window_steps

    R = state.R.copy()
    ready = count >= params.min_samples
    if np.any(ready):
        N = count[ready].astype(float)[:, None, None]
        mean = sum_nu[ready] / N[:, :, 0]
        C = (sum_nunu[ready] - N * mean[:, :, None] * mean[:, None, :]) / (N - 1.0)
        R_hat = C - sum_hph[ready] / N
        R[ready] = clamp_spd(R_hat, params.floor_var[ready])
    return AdaptiveState(buf_nu, buf_hph, used, head, count, sum_nu, sum_nunu, sum_hph, R)


def clamp_spd(R: np.ndarray, floor_var: np.ndarray) -> np.ndarray:
    """Symmetric positive-definite version of ``R (n, m, m)``: eigenvalues clamped to
    ``floor_var (n,)`` (closed form for m = 1, batched ``numpy.linalg.eigh`` otherwise)."""
    R = 0.5 * (R + np.swapaxes(R, -1, -2))
    if R.shape[-1] == 1:
        return np.maximum(R, floor_var[:, None, None])
    w, V = np.linalg.eigh(R)
    w = np.maximum(w, floor_var[:, None])
    return np.einsum("nij,nj,nkj->nik", V, w, V)


def innovation_group(nu: np.ndarray, hph: np.ndarray, mask: np.ndarray,
                     components: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slice one measurement group out of an EKF update's innovation record.

    Args:
        nu: ``(n, N_Z)``; hph: ``(n, N_Z, N_Z)``; mask: ``(n, N_Z)`` bool (the update's mask).
        components: the group's measurement indices, e.g. ``(ZN, ZE)`` for GNSS.

    Returns:
        ``nu (n, m)``, ``hph (n, m, m)``, ``valid (n,)`` (all components of the group valid).
    """
    idx = np.asarray(components)
    return (nu[:, idx], hph[:, idx[:, None], idx[None, :]], np.all(mask[:, idx], axis=1))
