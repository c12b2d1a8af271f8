"""The thesis' filter for position fixing: straight-line prediction, fixed gain [seed 002, ch 6].

Prediction [seed 002, 6.2]: a regression line ``y = a x + b`` (eqs 6.1-6.3) is fitted through
the last ``n`` *filtered* positions (so the filter is recursive, 6.4); the start and finish points
on the line corresponding to the first and last of the ``n`` points are located, the distance
along ``x`` between them is multiplied by the growth factor ``A`` and laid off from the start
point, and eq 6.1 gives ``y`` there. Of Eastings and Northings, the one with the smaller variance
(denominator of eq 6.2) is the one "on which to perform the regression": we read this as the
dependent variable ``y``, the other (larger spread) being the abscissa ``x`` - the only reading
that keeps eq 6.2 well conditioned on a track running north or east.

Update [seed 002, eq 6.4]: ``x_hat = x + K (z - x)`` with a fixed scalar gain ``K`` for both
coordinates (the gain matrix is diagonal with equal elements, 6.4). The first ``n`` fixes
(after a start or restart) are passed through unfiltered: they are needed for the first
prediction (6.3). Without an accepted fix the prediction is the estimate (6.6).

Optimal gain [seed 002, eqs 6.5-6.8]: the prediction is modelled as ``x(k+1) = A x_hat(k)``, so
the scalar Riccati iteration ``P = A^2 P; K = P / (P + M); P = (1 - K) P`` converges to::

    K = 1 - 1 / A^2,     P = K M

(the fixed point of 6.6-6.8: from ``P = K M`` and ``K = A^2 K M / (A^2 K M + M)``), so the
gain does not depend on the measurement variance ``M`` (6.5) and ``P`` is proportional to it.

The growth factor: section 6.2 says ``1 + 1/n``, section 6.4 says ``1 + 1/(n - 1)`` and quotes
``A = 1.111`` for ``n = 10``, but every number printed in the chapter follows ``A = 1 + 1/n``:
``K = 1 - (n / (n + 1))^2 = (2n + 1) / (n + 1)^2`` gives table 6.1 (0.5556 for n = 2 ...
0.1736 for n = 10) to all printed digits, and the quoted ``K = 0.1736``, ``P = 17.36 m^2`` for
``M = 100`` and table 6.2 follow from ``A = 1.1``; ``A = 1.111`` would give ``K = 0.19``.
``extrapolation = "thesis"`` (default) uses ``A = 1 + 1/n`` for both prediction and gain.

That factor lays the prediction ``(n - 1)(n + 1)/n = n - 1/n`` fix intervals beyond the first
point instead of ``n``: on a straight track at constant speed the prediction lags by ``1/n``
interval and the filtered track settles ``n / (2n + 1)`` of an interval behind the truth (from
``e = (1 - K)(e - d/n)``, ``d`` the distance run per fix). ``extrapolation = "unbiased"`` uses
``A = n / (n - 1)`` (exactly one interval ahead, as 6.4's wording) with its own gain
``1 - 1/A^2 = (2n - 1) / n^2`` and has no lag.

The thesis' gross-error window (6.6) is :mod:`trafficsim.estimation.gating`; :func:`run` ties
both together.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from trafficsim.estimation import gating

EXTRAPOLATION_RULES = ("thesis", "unbiased")
DEFAULT_N_POINTS = 4  # "an optimal value for n can be estimated as 4" [seed 002, 6.4]


def growth_factor(n_points: np.ndarray | int, rule: str = "thesis") -> np.ndarray:
    """Prediction growth ``A`` for ``n`` regression points: ``1 + 1/n`` [seed 002, 6.2 and the
    numbers of tables 6.1, 6.2] or, ``rule="unbiased"``, ``1 + 1/(n - 1)`` [6.4's wording]."""
    n = np.asarray(n_points, dtype=float)
    if rule == "thesis":
        return 1.0 + 1.0 / n
    if rule == "unbiased":
        return 1.0 + 1.0 / (n - 1.0)
    raise ValueError(f"extrapolation must be one of {EXTRAPOLATION_RULES}, got {rule!r}")


def steady_gain(growth: np.ndarray | float) -> np.ndarray:
    """Fixed point ``K = 1 - 1/A^2`` of the gain iteration [seed 002, eqs 6.6-6.8]."""
    a = np.asarray(growth, dtype=float)
    return 1.0 - 1.0 / (a * a)


def iterate_gain(growth: np.ndarray | float, meas_var: np.ndarray | float, cycles: int = 200,
                 p0: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Iterate eqs 6.6-6.8 [seed 002] ``cycles`` times, broadcast over arrays.

    The thesis iterates "until a constant value for K is obtained to the desired accuracy" and
    quotes 70 cycles for A = 1.1, M = 100; it does not give the starting variance. From
    ``p0 = 1`` (the identity start of its chapter 7 filter) K settles at 0.1736 (4 decimals)
    after 72 cycles.

    Args:
        growth: transition ``A`` of eq 6.5.
        meas_var: measurement variance ``M``, m^2 (Decca in Plymouth Sound: 100).
        p0: starting variance of the estimate, m^2.

    Returns:
        gain ``K`` and estimate variance ``P`` (after eq 6.8, the thesis' "P" of table 6.2).
    """
    a2 = np.square(np.asarray(growth, dtype=float))
    m = np.asarray(meas_var, dtype=float)
    p = np.broadcast_to(np.asarray(p0, dtype=float), np.broadcast(a2, m).shape).copy()
    k = np.zeros_like(p)
    for _ in range(cycles):
        p = a2 * p          # eq 6.6
        k = p / (p + m)     # eq 6.7
        p = (1.0 - k) * p   # eq 6.8
    return k, p


@dataclass(frozen=True)
class LineFitParams:
    """Filter parameters, ``(n,)`` arrays.

    Attributes:
        n_points: regression points per ship (int64, >= 2).
        growth: prediction growth factor ``A``.
        gain: fixed filter gain ``K`` in [0, 1].
    """

    n_points: np.ndarray
    growth: np.ndarray
    gain: np.ndarray

    @property
    def n_max(self) -> int:
        """Length of the history buffer (largest ``n_points``)."""
        return int(self.n_points.max(initial=0))


def build(configs: Sequence[Mapping[str, Any]]) -> LineFitParams:
    """Parameters from per-ship config dicts.

    Keys (optional): ``n_points`` (default 4 [seed 002, 6.4]), ``extrapolation``
    (``"thesis"`` = ``1 + 1/n`` (default) or ``"unbiased"``), ``gain`` (fixed gain override,
    default the optimal :func:`steady_gain` of the growth factor).
    """
    n = np.array([int(c.get("n_points", DEFAULT_N_POINTS)) for c in configs], dtype=np.int64)
    if np.any(n < 2):
        raise ValueError("n_points must be >= 2")
    growth = np.array([float(growth_factor(ni, c.get("extrapolation", "thesis")))
                       for ni, c in zip(n, configs, strict=True)])
    gain = np.array([float(c["gain"]) if "gain" in c else float(steady_gain(g))
                     for g, c in zip(growth, configs, strict=True)])
    if not np.all((gain >= 0) & (gain <= 1)):  # (NaN fails too)
        raise ValueError("gain must be within [0, 1]")
    return LineFitParams(n, growth, gain)


class LineFitState(NamedTuple):
    """Filter memory.

    ``history`` ``(n, n_max, 2)``: last filtered positions (north, east), m, oldest first,
    newest at ``[:, -1]``; ``count`` ``(n,)`` int64: valid entries (saturates at ``n_max``).
    """

    history: np.ndarray
    count: np.ndarray


def init_state(params: LineFitParams) -> LineFitState:
    """Empty memory: the next ``n_points`` fixes pass unfiltered."""
    n = params.n_points.shape[0]
    return LineFitState(np.full((n, params.n_max, 2), np.nan), np.zeros(n, dtype=np.int64))


def restart(state: LineFitState, mask: np.ndarray) -> LineFitState:
    """Forget the history of masked ships (after a gate restart) [seed 002, 6.6]."""
    return LineFitState(state.history, np.where(np.asarray(mask, bool), 0, state.count))


def predict(params: LineFitParams, state: LineFitState) -> np.ndarray:
    """Straight-line prediction [seed 002, 6.2, eqs 6.1-6.3], ``(n, 2)`` north/east m.

    NaN for ships with fewer than ``n_points`` filtered positions.
    """
    h = state.history
    if h.shape[0] == 0:  # no ships
        return np.empty((0, 2))
    n_max = h.shape[1]
    npts = params.n_points
    w = (np.arange(n_max)[None, :] >= (n_max - npts)[:, None]).astype(float)  # last n valid
    hz = np.where(w[:, :, None] > 0, h, 0.0)
    mean = hz.sum(axis=1) / npts[:, None]
    dev = np.where(w[:, :, None] > 0, h - mean[:, None, :], 0.0)
    var = np.sum(dev * dev, axis=1)  # n * variance, the denominator of eq 6.2 / n, (n, 2)
    ix = np.argmax(var, axis=1)      # abscissa: larger spread; ordinate: minimum variance
    iy = 1 - ix
    rows = np.arange(h.shape[0])
    sxx = var[rows, ix]
    sxy = np.sum(dev[rows, :, ix] * dev[rows, :, iy], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(sxx > 0.0, sxy / sxx, 0.0)                # eq 6.2 (centred form)
    b = mean[rows, iy] - a * mean[rows, ix]                     # eq 6.3
    first = h[rows, n_max - npts, ix]
    last = h[rows, -1, ix]
    x_pred = first + params.growth * (last - first)
    y_pred = a * x_pred + b                                     # eq 6.1
    out = np.empty((h.shape[0], 2))
    out[rows, ix] = x_pred
    out[rows, iy] = y_pred
    ready = state.count >= npts
    return np.where(ready[:, None], out, np.nan)


class LineFitStep(NamedTuple):
    """One filter step."""

    estimate: np.ndarray    # (n, 2) filtered position, m (NaN before the first fix)
    prediction: np.ndarray  # (n, 2) prediction used, m (NaN during the unfiltered start)
    state: LineFitState


def step(params: LineFitParams, state: LineFitState, z: np.ndarray,
         accept: np.ndarray | None = None) -> LineFitStep:
    """One fix [seed 002, eq 6.4]: filter ``z`` against the straight-line prediction.

    Args:
        z: ``(n, 2)`` position fix north/east, m; NaN rows = no fix.
        accept: optional ``(n,)`` bool from a gate; False = fix ignored, prediction kept.
            During the unfiltered start (no prediction yet) every fix is taken.
    """
    z = np.asarray(z, dtype=float)
    pred = predict(params, state)
    ready = state.count >= params.n_points
    have = np.all(np.isfinite(z), axis=1)
    use = have if accept is None else have & np.asarray(accept, bool)
    filtered = pred + params.gain[:, None] * (z - pred)
    est = np.where(ready[:, None], np.where(use[:, None], filtered, pred),
                   np.where(have[:, None], z, np.nan))
    push = ready | have
    shifted = np.concatenate([state.history[:, 1:], est[:, None, :]], axis=1)
    hist = np.where(push[:, None, None], shifted, state.history)
    count = np.where(push, np.minimum(state.count + 1, hist.shape[1]), state.count)
    return LineFitStep(est, pred, LineFitState(hist, count))


class LineFitRun(NamedTuple):
    """A filtered record."""

    estimate: np.ndarray    # (n, N, 2)
    prediction: np.ndarray  # (n, N, 2)
    accepted: np.ndarray    # (n, N) bool, fix used by the filter (or the unfiltered start)
    rejected: np.ndarray    # (n, N) bool, fix refused by the window
    restarted: np.ndarray   # (n, N) bool, filter restarted from this fix


def run(params: LineFitParams, z: np.ndarray,
        gate_params: gating.GateParams | None = None) -> LineFitRun:
    """Filter whole records, optionally with the gross-error window [seed 002, 6.6].

    The window is tested on the distance (m) between fix and prediction, against
    ``gate_params.threshold`` (the window radius, half the thesis' diameter).

    Args:
        z: ``(n, N, 2)`` fixes north/east, m (NaN = no fix).
    """
    z = np.asarray(z, dtype=float)
    n, steps, _ = z.shape
    state = init_state(params)
    rej = gating.init_state(n)
    est = np.full((n, steps, 2), np.nan)
    pred = np.full((n, steps, 2), np.nan)
    acc = np.zeros((n, steps), bool)
    bad = np.zeros((n, steps), bool)
    rst = np.zeros((n, steps), bool)
    for k in range(steps):
        accept = None
        if gate_params is not None:
            d = gating.distance(z[:, k] - predict(params, state))  # NaN during the start
            g = gating.gate(gate_params, d, rej)
            rej = g.rejections
            state = restart(state, g.restart)
            accept = g.accept | np.isnan(d)  # no prediction yet: take the fix
            bad[:, k], rst[:, k] = ~g.accept & ~np.isnan(d) & ~g.restart, g.restart
        out = step(params, state, z[:, k], accept)
        state = out.state
        est[:, k], pred[:, k] = out.estimate, out.prediction
        have = np.all(np.isfinite(z[:, k]), axis=1)
        acc[:, k] = have & ~bad[:, k]
    return LineFitRun(est, pred, acc, bad, rst)
