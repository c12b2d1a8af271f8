"""Gross-error gate with a window that reopens after a rejection and a restart rule [seed 002, 6.6].

The thesis removes gross errors "by placing a window about the prediction and testing whether the
measurement falls within the window. If it does then both estimates can be filtered, if not then
the prediction must be accepted and the measurement ignored". Because a sharp turn coinciding with
a gross error would otherwise lock the filter onto its prediction, the window is opened "on an
update which follows a failure", and "the system should also test for several consecutive
failures and [be] restarted if this event occurs" [seed 002, 6.6]. The thesis' windows are 50 m
and 100 m in diameter around a Decca prediction (100 m recommended: "the window can be made very
much larger than the DRMS value", DRMS 10 m). It gives no factor for the reopening and no count
for the restart; our choices are below.

Rule, per ship, with ``c`` the number of consecutive rejections so far::

    window = threshold * reopen_factor ** c
    d <= window          -> accept, c = 0
    d >  window          -> reject, c = c + 1
        and if c >= max_rejections -> restart (the filter re-initialises from this
                                      measurement), c = 0
    d is NaN (no fix)    -> neither; c unchanged

Defaults (our choice): ``reopen_factor = 2`` (the window doubles after each failure, so a
genuine re-fix up to ``threshold * 2 ** (max_rejections - 1)`` away is taken without a restart),
``max_rejections = 3`` ("several" consecutive failures). Any genuine jump is therefore followed
within ``max_rejections`` fixes, while an isolated gross error costs one fix. The literal reading
"open the window" = accept the next fix unconditionally is ``reopen_factor = inf``.

The gate is generic: ``d`` is any non-negative distance-like statistic with ``threshold`` in the
same unit, e.g. the distance in metres between fix and prediction (the thesis' window, threshold
= window radius = diameter / 2) or the normalised innovation ``sqrt(nu^T S^-1 nu)`` of a Kalman
filter (PV, CA, EKF; threshold ``sqrt(chi2_quantile(p, dof))``). The factor scales the window
linearly in ``d``: for a squared statistic such as the NIS pass its square root.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

DEFAULT_WINDOW_DIAMETER_M = 100.0  # [seed 002, 6.6, figure 6.5b and 6.6]
DEFAULT_REOPEN_FACTOR = 2.0        # our choice (the thesis gives none)
DEFAULT_MAX_REJECTIONS = 3         # our choice ("several consecutive failures")
#: widest position window, m: ten times the coarsest fix a receiver may have (1000 m,
#: :data:`trafficsim.sensors.gnss.MAX_SIGMA_M`); the thesis' windows are 50-100 m [seed 002, 6.6].
#: (``gate_sigma`` has no upper bound: a very wide gate is how to gate nothing.)
MAX_WINDOW_DIAMETER_M = 10_000
#: the keys of a gate's settings (``build``)
KEYS = ("window_diameter_m", "gate_sigma", "reopen_factor", "max_rejections")


@dataclass(frozen=True)
class GateParams:
    """Gate parameters, ``(n,)`` arrays.

    Attributes:
        threshold: window half-size in the statistic's unit (m for a position window).
        reopen_factor: window growth per consecutive rejection, >= 1 (inf = fully open).
        max_rejections: consecutive rejections that restart the filter, >= 1.
        metres: True where the threshold is a position window in metres (the filter then
            gates the fix's distance from the prediction), False where it is in standard
            deviations (the normalised innovation).
    """

    threshold: np.ndarray
    reopen_factor: np.ndarray
    max_rejections: np.ndarray
    metres: np.ndarray


def build(configs: Sequence[Mapping[str, Any]]) -> GateParams:
    """Gate parameters from per-ship config dicts.

    Keys (optional): ``window_diameter_m`` (position window, default 100 m [seed 002, 6.6];
    threshold = diameter / 2; at most :data:`MAX_WINDOW_DIAMETER_M`) or ``gate_sigma``
    (threshold on a normalised innovation, takes precedence when given), ``reopen_factor``
    (default 2), ``max_rejections`` (default 3).
    """
    thr = np.array([float(c["gate_sigma"]) if "gate_sigma" in c
                    else 0.5 * float(c.get("window_diameter_m", DEFAULT_WINDOW_DIAMETER_M))
                    for c in configs])
    fac = np.array([float(c.get("reopen_factor", DEFAULT_REOPEN_FACTOR)) for c in configs])
    cnt = np.array([int(c.get("max_rejections", DEFAULT_MAX_REJECTIONS)) for c in configs],
                   dtype=np.int64)
    if not (np.all(thr > 0) and np.all(fac >= 1) and np.all(cnt >= 1)):  # (NaN fails too)
        raise ValueError("gate needs a positive window, reopen_factor >= 1, max_rejections >= 1")
    metres = np.array(["gate_sigma" not in c for c in configs], dtype=bool)
    wide = np.flatnonzero(metres & (thr > 0.5 * MAX_WINDOW_DIAMETER_M))
    if wide.size:
        raise ValueError(f"window_diameter_m must be <= {MAX_WINDOW_DIAMETER_M}, got "
                         f"{2.0 * thr[wide[0]]:g}")
    return GateParams(thr, fac, cnt, metres)


def init_state(n: int) -> np.ndarray:
    """Gate state: consecutive rejections per ship, ``(n,)`` int64 zeros."""
    return np.zeros(n, dtype=np.int64)


class GateResult(NamedTuple):
    """Outcome of one gate test."""

    accept: np.ndarray      # (n,) bool: filter this measurement
    restart: np.ndarray     # (n,) bool: re-initialise the filter from this measurement
    rejections: np.ndarray  # (n,) int64: new gate state (consecutive rejections)
    window: np.ndarray      # (n,) the window this measurement was tested against


def gate(params: GateParams, d: np.ndarray, rejections: np.ndarray) -> GateResult:
    """Test ``d`` against the window [seed 002, 6.6] (rule in the module docstring).

    Args:
        params: :class:`GateParams` of ``n`` ships.
        d: ``(n,)`` distance-like statistic (NaN = no measurement this step).
        rejections: ``(n,)`` gate state from the previous call (or :func:`init_state`).
    """
    d = np.asarray(d, dtype=float)
    with np.errstate(over="ignore"):  # reopen_factor = inf opens the window fully (inf ** 0 = 1)
        window = params.threshold * params.reopen_factor ** rejections
    have = ~np.isnan(d)  # (an infinite distance is a measurement, and rejected)
    accept = have & (d <= window)
    reject = have & ~accept
    count = np.where(accept, 0, rejections + reject)
    restart = reject & (count >= params.max_rejections)
    count = np.where(restart, 0, count).astype(np.int64)
    return GateResult(accept, restart, count, window)


def distance(innovation: np.ndarray) -> np.ndarray:
    """Euclidean length of ``(n, k)`` innovations (e.g. a position fix minus prediction, m)."""
    return np.sqrt(np.sum(np.square(innovation), axis=-1))


def normalised_distance(innovation: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Mahalanobis length ``sqrt(nu^T S^-1 nu)`` of innovations, closed form (no inversion).

    Args:
        innovation: ``(n,)`` scalar or ``(n, k)`` vector innovations, k = 1 or 2.
        s: innovation covariance, ``(n,)`` for scalars, ``(n, k)`` for independent components
            (diagonal S), or ``(n, 2, 2)`` full.
    """
    nu = np.asarray(innovation, dtype=float)
    s = np.asarray(s, dtype=float)
    if nu.ndim == 1:
        return np.abs(nu) / np.sqrt(s)
    if s.ndim == nu.ndim:  # diagonal
        return np.sqrt(np.sum(nu * nu / s, axis=-1))
    if nu.shape[-1] != 2:
        raise ValueError("full innovation covariance supported for k = 2 only")
    a, b, c = s[:, 0, 0], s[:, 0, 1], s[:, 1, 1]
    det = a * c - b * b
    q = (c * nu[:, 0] ** 2 - 2.0 * b * nu[:, 0] * nu[:, 1] + a * nu[:, 1] ** 2) / det
    return np.sqrt(q)


def chi2_sf(x: float, dof: int) -> float:
    """Survival function ``P(X > x)`` of the chi-square distribution with integer ``dof``.

    Closed form for integer degrees of freedom (no scipy): with ``h = x / 2``,
    even ``dof = 2k``: ``exp(-h) sum_{i<k} h^i / i!``; odd ``dof = 2k + 1``:
    ``erfc(sqrt(h)) + exp(-h) sum_{i<k} h^(i+1/2) / Gamma(i + 3/2)``. Terms are summed in
    logarithms so large ``x`` and ``dof`` do not overflow.
    """
    if x <= 0.0:
        return 1.0
    h = 0.5 * x
    k, odd = divmod(int(dof), 2)
    i = np.arange(k, dtype=float) + (0.5 if odd else 0.0)
    # log Gamma(i + 1) by the recurrence Gamma(j + 1) = j Gamma(j), one lgamma call
    lgam = math.lgamma(i[0] + 1.0) + np.concatenate(([0.0], np.cumsum(np.log(i[1:])))) \
        if k else i
    logs = i * math.log(h) - h - lgam
    top = float(logs.max()) if k else 0.0
    total = math.exp(top) * float(np.exp(logs - top).sum()) if k else 0.0
    if odd:
        total += math.erfc(math.sqrt(h))
    return min(1.0, total)


def chi2_quantile(p: float, dof: int) -> float:
    """Quantile ``x`` with ``P(X <= x) = p`` of the chi-square distribution (bisection on
    :func:`chi2_sf`); e.g. a gate threshold on the NIS. Relative accuracy against scipy: better
    than 5e-8 for ``p >= 1e-3`` and ``dof`` up to 2e5 (worse far in the lower tail, where
    ``1 - sf`` cancels)."""
    if not 0.0 < p < 1.0 or dof < 1:
        raise ValueError("need 0 < p < 1 and dof >= 1")
    lo, hi = 0.0, float(dof) + 10.0 * math.sqrt(2.0 * dof) + 50.0
    while chi2_sf(hi, dof) > 1.0 - p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 1.0 - chi2_sf(mid, dof) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * hi:
            break
    return 0.5 * (lo + hi)
