"""Batch output-error fit of ship-model coefficients to measured runs.

The model is replayed with the measured rudder and propeller speed from the measured state at the
start of each window (:mod:`trafficsim.identify.replay`) and its outputs are compared with the
smoothed measurements; ``scipy.optimize.least_squares`` (trust-region reflective, parameter
bounds) minimises the weighted squared output errors

    J(theta) = 1/2 sum_windows sum_samples sum_channels ((y_sim - y_meas) / s_channel)^2.

The Jacobian is a forward difference whose ``p`` perturbed models are replayed in ONE compiled
call with the unperturbed one (the columns are a batch of ships), instead of ``p`` serial
simulations.

Channel weights ``s`` (our choice, dimensionally consistent): with ``U`` the RMS speed of the
data and ``L`` the ship length, an error of ``s_u = s_v = 0.05 U`` in a velocity, ``0.05 rad``
in heading (a ``0.05 U`` cross-track velocity), ``0.05 U / L`` in yaw rate (a heading error of
0.05 rad after the time ``L / U``) and ``0.1 L`` in position count the same.

Confidence intervals: from the Jacobian at the solution, ``cov = s^2 (J^T J)^-1`` with
``s^2 = 2 J(theta) / (m - p)`` and 95 % intervals ``+-1.96 sqrt(diag cov)``. They assume
independent residuals; successive samples of a trajectory are correlated, so the intervals are
nominal (too narrow by about the square root of the correlation length in samples) and serve to
compare coefficients and spot unidentifiable ones (large intervals, correlations near +-1).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trafficsim.identify.parameters import Parametrisation
from trafficsim.identify.replay import Windows, simulate

#: output channels by name -> column of :data:`trafficsim.identify.replay.OUTPUTS`
CHANNELS = {"north": 0, "east": 1, "psi": 2, "u": 3, "v": 4, "r": 5}
DEFAULT_CHANNELS = ("u", "v", "r", "psi")
Z95 = 1.959964


def channel_scales(windows: Windows, length_m: float) -> dict[str, float]:
    """Channel weights ``s`` (module doc) from the data's RMS speed and the ship length."""
    valid = windows.valid()
    u, v = windows.target[..., 3][valid], windows.target[..., 4][valid]
    speed = float(np.sqrt(np.nanmean(u * u + v * v)))
    speed = max(speed, 1e-3)
    sv = 0.05 * speed
    return {"u": sv, "v": sv, "psi": 0.05, "r": sv / float(length_m),
            "north": 0.1 * float(length_m), "east": 0.1 * float(length_m)}


class Residuals:
    """Weighted output errors of candidate parameter vectors on a set of windows.

    ``self(thetas)`` with ``thetas`` ``(k, p)`` replays all ``k`` candidates at once and returns
    ``(k, m)`` residuals; ``m`` counts the finite target samples of the chosen channels after
    each window's first sample (which equals the initial state).
    """

    def __init__(self, param: Parametrisation, windows: Windows,
                 channels: Sequence[str] = DEFAULT_CHANNELS,
                 scales: Mapping[str, float] | None = None) -> None:
        unknown = [c for c in channels if c not in CHANNELS]
        if unknown:
            raise ValueError(f"unknown channel(s) {unknown}; expected some of {list(CHANNELS)}")
        self.param = param
        self.windows = windows
        self.channels = tuple(channels)
        length = float(param.spec["particulars"]["length_m"])
        self.scales = dict(channel_scales(windows, length) if scales is None else scales)
        cols = [CHANNELS[c] for c in self.channels]
        self._cols = np.array(cols)
        target = windows.target[..., self._cols]  # (W, N, c)
        mask = windows.valid()[..., None] & np.isfinite(target)
        mask[:, 0, :] = False
        self._mask = mask
        self._weights = 1.0 / np.array([self.scales[c] for c in self.channels])
        self._target = np.where(mask, target, 0.0)
        self.last_diverged = np.zeros(0, dtype=bool)

    @property
    def m(self) -> int:
        return int(self._mask.sum())

    @property
    def row_window(self) -> np.ndarray:
        """``(m,)`` the window of each residual (the clusters of :func:`clustered_std`)."""
        return np.nonzero(self._mask)[0]

    def errors(self, out: np.ndarray) -> np.ndarray:
        """``(k, W, N, c)`` unweighted output errors of replay outputs ``out`` (0 where masked)."""
        sim = out[..., self._cols]
        return np.where(self._mask, np.nan_to_num(sim) - self._target, 0.0)

    def __call__(self, thetas: np.ndarray) -> np.ndarray:
        out, diverged = simulate(self.param.rows(thetas), self.windows)
        self.last_diverged = diverged
        err = self.errors(out) * self._weights
        return err[:, self._mask]


@dataclass
class FitResult:
    """Result of an output-error fit (ship-file units throughout).

    Attributes:
        names, x0, x, lower, upper: fitted coefficients, start, solution, bounds ``(p,)``.
        std, ci95: standard deviation and half-width of the nominal 95 % interval ``(p,)``.
        std_clustered: ``(p,)`` standard deviation with the residuals of each window taken
            as correlated (:func:`clustered_std`; NaN where not available).
        corr: ``(p, p)`` correlation matrix of the estimate.
        cost0, cost: objective at the start and at the solution.
        rms0, rms: RMS of the weighted residuals at the start and at the solution.
        nfev, njev: model evaluations (each replays the data once) and Jacobians.
        history_cost, history_x: objective and parameters of every evaluation, in order.
        message: the optimiser's message; success: whether it reported convergence.
        elapsed_s: wall time; m: residual count; diverged_windows: windows whose replay diverged
            at the solution.
    """

    names: tuple[str, ...]
    x0: np.ndarray
    x: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    std: np.ndarray
    ci95: np.ndarray
    corr: np.ndarray
    cost0: float
    cost: float
    rms0: float
    rms: float
    nfev: int
    njev: int
    message: str
    success: bool
    elapsed_s: float
    m: int
    channels: tuple[str, ...]
    scales: dict[str, float]
    diverged_windows: int = 0
    history_cost: list[float] = field(default_factory=list)
    history_x: list[np.ndarray] = field(default_factory=list)
    std_clustered: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def table(self) -> dict[str, dict[str, Any]]:
        """Per coefficient: initial, value, std and nominal 95 % interval (infinite where
        the data do not determine it, :func:`undetermined`), the windows-clustered std and
        interval where there are enough windows (:func:`clustered_std`), bounds and whether
        the value is on one."""
        cl = self.std_clustered if self.std_clustered.size else np.full(len(self.names), np.nan)
        out = {}
        for n, a, b, s, c, k, lo, hi in zip(self.names, self.x0, self.x, self.std, self.ci95,
                                            cl, self.lower, self.upper, strict=True):
            row = {"initial": float(a), "value": float(b), "std": float(s),
                   "ci95_low": float(b - c), "ci95_high": float(b + c)}
            if not np.isnan(k):
                row.update(std_clustered=float(k), ci95_clustered_low=float(b - Z95 * k),
                           ci95_clustered_high=float(b + Z95 * k))
            out[n] = {**row, "lower": float(lo), "upper": float(hi),
                      "at_bound": on_bound(b, lo, hi)}
        return out

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (no histories)."""
        return {"coefficients": self.table(), "cost_initial": self.cost0, "cost_final": self.cost,
                "rms_weighted_initial": self.rms0, "rms_weighted_final": self.rms,
                "evaluations": self.nfev, "jacobians": self.njev, "converged": self.success,
                "message": self.message, "elapsed_s": self.elapsed_s, "residuals": self.m,
                "channels": list(self.channels), "channel_scales": self.scales,
                "diverged_windows": self.diverged_windows,
                "correlation": {a: {b: float(self.corr[i, j]) for j, b in enumerate(self.names)}
                                for i, a in enumerate(self.names)}}


#: fewest windows for a clustered standard deviation (a sandwich on fewer clusters is
#: itself too uncertain to quote)
MIN_CLUSTERS = 10


def clustered_std(jmat: np.ndarray, r: np.ndarray, cluster: np.ndarray,
                  bread: np.ndarray | None = None) -> np.ndarray:
    """``(p,)`` standard deviations of a least-squares estimate whose residuals are correlated
    within clusters (here the windows: a trajectory's errors persist along a window) and
    independent between them: the cluster-robust sandwich ``B M B`` with ``B = (J^T J)^+``,
    ``M = sum_g (J_g^T r_g)(J_g^T r_g)^T`` and the small-sample factor
    ``G / (G - 1) (m - 1) / (m - p)`` (the CR1 estimator of Cameron & Miller, "A
    practitioner's guide to cluster-robust inference", J. Human Resources 50(2), 2015). NaN
    with fewer than :data:`MIN_CLUSTERS` clusters. ``bread``: ``B`` if already worked out."""
    m, p = jmat.shape
    ids, cluster = np.unique(cluster, return_inverse=True)
    g = ids.size
    if g < MIN_CLUSTERS or m <= p:
        return np.full(p, np.nan)
    scores = np.stack([np.bincount(cluster, weights=jmat[:, j] * r, minlength=g)
                       for j in range(p)], axis=1)
    if bread is None:
        bread = np.linalg.pinv(jmat.T @ jmat)
    cov = bread @ (scores.T @ scores) @ bread * (g / (g - 1) * (m - 1) / (m - p))
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def on_bound(value: float, lower: float, upper: float) -> bool:
    """Whether a fitted value sits on a finite bound (within 1e-6 of the bounds' width, or
    of the value's size where the other bound is infinite): its interval then means little."""
    width = upper - lower if np.isfinite(upper - lower) else max(abs(value), 1.0)
    return bool(value - lower <= 1e-6 * width or upper - value <= 1e-6 * width)


def undetermined(jmat: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """``(p,)`` the coefficients the data do not determine: those with a share in a direction
    of the column-scaled Jacobian whose singular value is below ``rcond`` times the largest (a
    column of zeros, or columns that move the residuals alike). Their variance is unbounded;
    the pseudo-inverse would report a finite one (zero for a column of zeros)."""
    norms = np.linalg.norm(jmat, axis=0)
    out = ~(norms > 0.0)
    live = np.flatnonzero(~out)
    if live.size:  # singular values of R (QR of the scaled columns) are those of the columns
        _, sv, vt = np.linalg.svd(np.linalg.qr(jmat[:, live] / norms[live], mode="r"))
        weak = np.ones(live.size, dtype=bool)
        weak[: sv.size] = sv <= rcond * sv[0]
        if weak.any():
            out[live[np.abs(vt[weak]).max(axis=0) > 1e-6]] = True
    return out


def fd_steps(x: np.ndarray, x0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             rel_step: float) -> np.ndarray:
    """Signed forward-difference steps: relative to the value (or the start, if larger),
    pointing away from a bound. The scale has a floor of 1e-3 of the bounds' width, or
    without finite bounds 1e-10; a coefficient without bounds that is and started at exactly 0
    has no scale at all and gets 1e-3 (a step at rounding size would make its Jacobian column
    noise)."""
    width = np.where(np.isfinite(upper - lower), upper - lower, np.inf)
    size = np.maximum(np.abs(x), np.abs(x0))
    floor = np.where(np.isfinite(width), 1e-3 * width, np.where(size == 0.0, 1e-3, 1e-10))
    h = rel_step * np.maximum(size, floor)
    return np.where(x + h > upper, -h, h)


def jacobian(residuals: Residuals, x: np.ndarray, r0: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``(m, p)`` forward-difference Jacobian: all ``p`` perturbed models in one replay."""
    thetas = x[None, :] + np.diag(h)
    rr = residuals(thetas)
    return ((rr - r0[None, :]) / h[:, None]).T


def fit(param: Parametrisation, windows: Windows, x0: np.ndarray | None = None,
        channels: Sequence[str] = DEFAULT_CHANNELS, scales: Mapping[str, float] | None = None,
        max_nfev: int = 60, rel_step: float = 1e-6, tol: float = 1e-8,
        residuals: Any = None) -> FitResult:
    """Output-error least-squares fit of ``param``'s coefficients on ``windows``.

    Args:
        param: base ship, fitted names and bounds.
        windows: measured windows (:func:`trafficsim.identify.replay.windows_from_runs`).
        x0: starting values ``(p,)`` (default: the base ship's, clipped into the bounds).
        channels, scales: output channels and their weights (module doc).
        max_nfev: most model evaluations of the optimiser (Jacobians not counted).
        rel_step: relative finite-difference step.
        tol: ``ftol = xtol = gtol`` of ``least_squares``.
        residuals: another residual function of the same interface as :class:`Residuals`
            (``(k, p)`` candidates -> ``(k, m)`` weighted residuals in one replay, with
            ``channels``, ``scales``, ``last_diverged``), e.g. the effect models of
            :mod:`trafficsim.diagnose`; ``param`` then only gives names, bounds and start. If
            it has a ``jacobian(x, r0, h)`` method, that computes the forward differences
            (e.g. several columns of a sparse Jacobian from one perturbed model).
    """
    from scipy.optimize import least_squares

    start = time.perf_counter()
    res = Residuals(param, windows, channels, scales) if residuals is None else residuals
    lo, hi = param.lower, param.upper
    x_start = np.clip(param.initial() if x0 is None else np.asarray(x0, float), lo, hi)
    cache: dict[bytes, np.ndarray] = {}
    hist_cost: list[float] = []
    hist_x: list[np.ndarray] = []
    njev = 0

    def fun(x: np.ndarray) -> np.ndarray:
        key = x.tobytes()
        if key not in cache:
            r = res(x[None, :])[0]
            cache.clear()
            cache[key] = r
            hist_cost.append(0.5 * float(r @ r))
            hist_x.append(x.copy())
        return cache[key]

    def jac(x: np.ndarray) -> np.ndarray:
        nonlocal njev
        njev += 1
        steps = fd_steps(x, x_start, lo, hi, rel_step)
        if hasattr(res, "jacobian"):
            return res.jacobian(x, fun(x), steps)
        return jacobian(res, x, fun(x), steps)

    r_start = fun(x_start)
    sol = least_squares(fun, x_start, jac=jac, bounds=(lo, hi), x_scale="jac", method="trf",
                        max_nfev=max_nfev, ftol=tol, xtol=tol, gtol=tol)
    x = sol.x
    r = res(x[None, :])[0]
    diverged = int(res.last_diverged.sum())
    jmat = jac(x)
    m, p = r.size, x.size
    dof = max(m - p, 1)
    s2 = float(r @ r) / dof
    bread = np.linalg.pinv(jmat.T @ jmat)
    cov = s2 * bread
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    loose = undetermined(jmat)
    std[loose] = np.inf
    rows = getattr(res, "row_window", None)
    std_cl = clustered_std(jmat, r, rows, bread) if rows is not None else np.full(p, np.nan)
    std_cl[loose] = np.inf
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr = np.nan_to_num(corr)
    return FitResult(
        names=param.names, x0=x_start, x=x, lower=lo, upper=hi, std=std, ci95=Z95 * std,
        std_clustered=std_cl,
        corr=corr, cost0=0.5 * float(r_start @ r_start), cost=0.5 * float(r @ r),
        rms0=float(np.sqrt(np.mean(r_start**2))), rms=float(np.sqrt(np.mean(r**2))),
        nfev=int(sol.nfev), njev=njev, message=str(sol.message), success=bool(sol.status > 0),
        elapsed_s=time.perf_counter() - start, m=m, channels=res.channels, scales=res.scales,
        diverged_windows=diverged, history_cost=hist_cost, history_x=hist_x)
