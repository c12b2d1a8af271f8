"""Fitting and ranking candidate effects: single-effect fits, forward selection, noise floor.

A candidate set of effects (:class:`EffectSet`) is a parametrisation of the base ship: its
parameters go through :mod:`trafficsim.effects` (ship spec, environment, steering gear, true
start of each window, measurement model) into ONE compiled replay of all candidates and windows
(:func:`trafficsim.identify.replay.simulate`), and the output-error least-squares fit of
:func:`trafficsim.identify.output_error.fit` (bounded, batched finite-difference Jacobian,
nominal intervals) estimates them on the training runs.

Cost of a set of windows: ``J = 1/2 sum ((y_sim - y_meas) / s_channel)^2`` over the measured
channels (:mod:`trafficsim.diagnose.data`), with the weights of
:func:`trafficsim.identify.output_error.channel_scales` (``0.1 L`` in position, ``0.05 rad`` in
heading and drift angle, ``0.05 U`` in velocities and SOG, ``0.05 U / L`` in yaw rate).
Gap shrinkage: ``1 - J_with / J_base``.

Ranking (documented choice): every effect is fitted alone on the training runs and scored on the
held-out runs by the penalised shrinkage ``1 - (J_with / J_base) (1 + 2 p / n_eff)``, ``p`` the
effect's parameters and ``n_eff`` the held-out windows times channels (an AIC-like penalty that
counts one independent error per window and channel, since successive samples of a trajectory
are strongly correlated). Combinations: forward selection adds, to the best set so far, the
candidate that lowers the penalised held-out cost most, fitting the whole set jointly, while it
lowers it by at least ``MIN_GAIN`` (5 %).

Noise floor: ``J_floor = 1/2 sum_channels m_c (sigma_c / s_c)^2`` with ``sigma_c`` each measured
channel's white noise; a gap below ``FLOOR_FACTOR`` (3) times its floor is "not attributable"
(a perfect model also carries the smoothed start state's error through each window, which is why
the factor is above 1).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trafficsim import effects
from trafficsim.diagnose.data import ANGLES, CHANNELS, PHASES, Dataset
from trafficsim.identify import output_error
from trafficsim.identify.replay import model_rows, simulate

MIN_GAIN = 0.05
FLOOR_FACTOR = 3.0


@dataclass
class EffectSet:
    """Parameters of a set of effects on a base ship (the ``param`` of an output-error fit)."""

    spec: dict[str, Any]
    effects: tuple[str, ...]
    names: tuple[str, ...] = ()
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    start: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def of(cls, spec: Mapping[str, Any], names: Sequence[str],
           start: Mapping[str, Mapping[str, float]] | None = None) -> EffectSet:
        length = float(spec["particulars"]["length_m"])
        keys, lo, hi, x0 = [], [], [], []
        for name in names:
            a, b, s = effects.bounds(name, length)
            given = (start or {}).get(name)
            if given is not None:
                s = np.array([given[k] for k in effects.REGISTRY[name].keys])
            keys += [f"{name}.{k}" for k in effects.REGISTRY[name].keys]
            lo.append(a)
            hi.append(b)
            x0.append(np.clip(s, a, b))
        return cls(dict(spec), tuple(names), tuple(keys), _cat(lo), _cat(hi), _cat(x0))

    @property
    def p(self) -> int:
        return len(self.names)

    def initial(self) -> np.ndarray:
        return self.start.copy()

    def values(self, theta: np.ndarray) -> dict[str, dict[str, float]]:
        """Effect values (:func:`trafficsim.effects.check` form) of one parameter vector."""
        out: dict[str, dict[str, float]] = {}
        i = 0
        for name in self.effects:
            eff = effects.REGISTRY[name]
            vals = eff.off()
            for key in eff.keys:
                vals[key] = float(theta[i])
                i += 1
            out[name] = vals
        return out


def _cat(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0)


class EffectResiduals:
    """Weighted residuals of candidate effect parameters on a dataset (``(k, p) -> (k, m)``)."""

    def __init__(self, param: EffectSet, data: Dataset, scales: Mapping[str, float]) -> None:
        self.param = param
        self.data = data
        self.channels = tuple(c for c in CHANNELS if c in data.channels)
        self.scales = {c: float(scales[c]) for c in self.channels}
        self._cols = np.array([CHANNELS.index(c) for c in self.channels])
        target = data.target[..., self._cols]
        mask = data.windows.valid()[..., None] & np.isfinite(target)
        mask[:, 0, :] = False
        self._mask = mask
        self._target = np.where(mask, target, 0.0)
        self._angle = np.array([c in ANGLES for c in self.channels])
        self._weights = 1.0 / np.array([self.scales[c] for c in self.channels])
        self.last_diverged = np.zeros(0, dtype=bool)
        self._smooth = [(run.t_s, np.stack([run.smooth[k] for k in
                                            ("north_m", "east_m", "psi_rad", "u_mps", "v_mps",
                                             "r_radps")])) for run in data.runs]

    def gear_start(self, steer: np.ndarray) -> np.ndarray:
        """``(k, W)`` rudder angle of each model's steering gear at each window's start: the
        gear (lag and rate limit, :func:`trafficsim.effects.steering`) run over the logged
        rudder from the start of the run (Euler, 10 steps per sample)."""
        win = self.data.windows
        k = steer.shape[0]
        out = np.repeat(win.inputs[None, :, 0, 0], k, axis=0)
        on = steer[:, 0] > 0.0
        if not on.any():
            return out
        tau, rate = steer[on, 0], steer[on, 1]
        for r, run in enumerate(self.data.runs):
            rud = np.nan_to_num(run.trial.rudder_rad)
            dt = run.dt_s / 10.0
            state = np.full(tau.size, rud[0])
            at = np.empty((tau.size, rud.size))
            for j in range(rud.size):
                at[:, j] = state
                for _ in range(10):
                    state = state + dt * np.clip((rud[j] - state) / tau, -rate, rate)
            for i in np.flatnonzero(win.run == r):
                j0 = round(float(win.t0_s[i] - run.t_s[0]) / run.dt_s)
                out[on, i] = at[:, j0]
        return out

    def ahead(self, lag_s: float) -> np.ndarray:
        """``(8, W)`` smoothed measured state ``lag_s`` after each window's start."""
        win = self.data.windows
        x = np.array(win.x0, dtype=float, copy=True)
        for i in range(win.w):
            t, states = self._smooth[int(win.run[i])]
            x[:6, i] = [np.interp(win.t0_s[i] + lag_s, t, row) for row in states]
        return x

    @property
    def m(self) -> int:
        return int(self._mask.sum())

    def errors(self, thetas: np.ndarray) -> np.ndarray:
        """``(k, W, N, c)`` unweighted errors (simulated minus measured, 0 where masked)."""
        thetas = np.atleast_2d(thetas)
        vals = [self.param.values(th) for th in thetas]
        rows = model_rows([effects.apply_spec(self.param.spec, v) for v in vals])
        win = self.data.windows
        x0 = np.stack([effects.true_start(
            win.x0, v, ahead=self.ahead(v["ais_latency"]["latency_s"])
            if "ais_latency" in v else None) for v in vals])
        env_off = np.stack([effects.environment_offset(v) for v in vals])
        steer = np.array([effects.steering(v) for v in vals], dtype=float).reshape(-1, 2)
        x0[:, 6, :] = self.gear_start(steer)
        out, diverged = simulate(rows, win, x0, env_off, steer)
        self.last_diverged = diverged
        meas = effects.measure(np.nan_to_num(out), win.dt_s, vals)
        meas["cog_psi"] = meas["cog"] - meas["psi"]
        sim = np.stack([meas[c] for c in self.channels], axis=-1)
        err = sim - self._target[None]
        err = np.where(self._angle, np.mod(err + np.pi, 2 * np.pi) - np.pi, err)
        return np.where(self._mask[None], err, 0.0)

    def __call__(self, thetas: np.ndarray) -> np.ndarray:
        err = self.errors(thetas) * self._weights
        return err[:, self._mask]

    def cost(self, theta: np.ndarray) -> float:
        r = self(np.atleast_2d(theta))[0]
        return 0.5 * float(r @ r)

    def floor(self) -> float:
        """Noise-floor cost of this dataset (module doc)."""
        sig = self.data.sigma[self._cols]
        counts = self._mask.sum(axis=(0, 1))
        return 0.5 * float(np.nansum(counts * (sig * self._weights) ** 2))

    def by_phase(self, theta: np.ndarray) -> dict[str, dict[str, float]]:
        """RMS error per phase and channel (channel units; angles in degrees) and the share of
        the cost each phase carries."""
        err = self.errors(theta)[0]
        w = err * self._weights
        total = float(np.sum(w * w)) or 1.0
        out: dict[str, dict[str, float]] = {}
        for k, name in enumerate(PHASES):
            sel = (self.data.phase == k)[..., None] & self._mask
            if not sel.any():
                continue
            row: dict[str, float] = {"samples": int(sel[..., 0].sum() if sel.shape[-1] else 0),
                                     "cost_share": float(np.sum((w * w)[sel]) / total)}
            for j, c in enumerate(self.channels):
                s = sel[..., j]
                if s.any():
                    v = float(np.sqrt(np.mean(err[..., j][s] ** 2)))
                    row[c] = float(np.degrees(v)) if c in ANGLES or c == "r" else v
            out[name] = row
        return out

    def by_channel(self, theta: np.ndarray) -> dict[str, float]:
        """RMS error per channel over all samples (angles and yaw rate in degrees)."""
        err = self.errors(theta)[0]
        out = {}
        for j, c in enumerate(self.channels):
            s = self._mask[..., j]
            v = float(np.sqrt(np.mean(err[..., j][s] ** 2))) if s.any() else float("nan")
            out[c] = float(np.degrees(v)) if c in ANGLES or c == "r" else v
        return out


def scales(data: Dataset, length_m: float) -> dict[str, float]:
    """Channel weights (module doc) from the data's speed and the ship length."""
    s = output_error.channel_scales(data.windows, length_m)
    s["sog"] = s["u"]
    s["cog_psi"] = s["psi"]
    return s


@dataclass
class Candidate:
    """A fitted set of effects and its costs."""

    effects: tuple[str, ...]
    values: dict[str, dict[str, float]]
    table: dict[str, dict[str, float]]
    cost_train: float
    cost_hold: float
    p: int
    fit: Any = None

    def shrinkage(self, base: Candidate) -> tuple[float, float]:
        return (1.0 - self.cost_train / max(base.cost_train, 1e-300),
                1.0 - self.cost_hold / max(base.cost_hold, 1e-300))


def fit_set(spec: Mapping[str, Any], names: Sequence[str], train: Dataset, hold: Dataset,
            sc: Mapping[str, float], start: Mapping[str, Mapping[str, float]] | None = None,
            max_nfev: int = 30) -> Candidate:
    """Fit the effects ``names`` jointly on ``train``; evaluate on ``hold``."""
    param = EffectSet.of(spec, names, start)
    res_t = EffectResiduals(param, train, sc)
    res_h = EffectResiduals(param, hold, sc)
    if param.p == 0:
        return Candidate((), {}, {}, res_t.cost(np.zeros(0)), res_h.cost(np.zeros(0)), 0)
    x_start = param.initial()
    if len(names) == 1 and start is None:  # best point of a coarse grid, in one replay
        grid = np.clip(effects.start_grid(names[0], float(spec["particulars"]["length_m"])),
                       param.lower, param.upper)
        costs = np.sum(res_t(grid) ** 2, axis=1)
        x_start = grid[int(np.argmin(costs))]
    result = output_error.fit(param, train.windows, x0=x_start, max_nfev=max_nfev,
                              rel_step=1e-4, tol=1e-6, residuals=res_t)
    x = result.x
    return Candidate(tuple(names), param.values(x), result.table(), result.cost,
                     res_h.cost(x), param.p, result)


def penalised(cost: float, p: int, n_eff: int) -> float:
    return cost * (1.0 + 2.0 * p / max(n_eff, 1))


@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`."""

    base: Candidate
    singles: list[Candidate]
    chosen: Candidate
    steps: list[dict[str, Any]]
    floor_train: float
    floor_hold: float
    n_eff: int
    attributable: bool
    verdict: str
    elapsed_s: float
    residuals: dict[str, Any]


def diagnose(spec: Mapping[str, Any], train: Dataset, hold: Dataset,
             candidates: Sequence[str] = effects.NAMES, forward_steps: int = 3,
             max_nfev: int = 30) -> Diagnosis:
    """Single-effect fits, ranking, forward selection and the noise-floor verdict."""
    t0 = time.perf_counter()
    length = float(spec["particulars"]["length_m"])
    sc = scales(train, length)
    base = fit_set(spec, (), train, hold, sc)
    res_h = EffectResiduals(EffectSet.of(spec, ()), hold, sc)
    n_eff = hold.windows.w * len(res_h.channels)
    floor_t = EffectResiduals(EffectSet.of(spec, ()), train, sc).floor()
    floor_h = res_h.floor()
    singles = [fit_set(spec, (name,), train, hold, sc, max_nfev=max_nfev) for name in candidates]
    score = {c.effects[0]: 1.0 - penalised(c.cost_hold, c.p, n_eff) / base.cost_hold
             for c in singles}
    singles.sort(key=lambda c: -score[c.effects[0]])
    chosen, steps = base, []
    pool = [c for c in singles if score[c.effects[0]] > MIN_GAIN][:4]
    current_pen = base.cost_hold
    for _ in range(forward_steps):
        best, best_pen = None, current_pen
        for single in pool:
            name = single.effects[0]
            if name in chosen.effects:
                continue
            names = (*chosen.effects, name)
            start = {**chosen.values, name: single.values[name]}
            cand = single if not chosen.effects else fit_set(spec, names, train, hold, sc,
                                                             start, max_nfev)
            pen = penalised(cand.cost_hold, cand.p, n_eff)
            if pen < best_pen:
                best, best_pen = cand, pen
        if best is None or best_pen > (1.0 - MIN_GAIN) * current_pen:
            break
        steps.append({"added": best.effects[-1], "effects": list(best.effects),
                      "cost_holdout": best.cost_hold, "penalised_cost_holdout": best_pen})
        chosen, current_pen = best, best_pen
    gap_ratio = base.cost_hold / max(floor_h, 1e-300)
    if gap_ratio < FLOOR_FACTOR:
        attributable = False
        verdict = (f"not attributable: the held-out gap is {gap_ratio:.1f} times the data's "
                   f"noise floor (below {FLOOR_FACTOR:g})")
        chosen = base
    elif not chosen.effects:
        attributable = False
        verdict = ("not attributable: no effect in the library shrinks the held-out gap by "
                   f"{100 * MIN_GAIN:.0f} % or more after the parameter penalty")
    else:
        attributable = True
        sh = chosen.shrinkage(base)[1]
        verdict = (f"{' + '.join(chosen.effects)}: held-out gap {100 * sh:.0f} % smaller "
                   f"({gap_ratio:.1f} times the noise floor before)")
    diag = Diagnosis(base, singles, chosen, steps, floor_t, floor_h, n_eff, attributable,
                     verdict, 0.0, {})
    diag.residuals = residual_summary(spec, diag, train, hold, sc)
    diag.elapsed_s = time.perf_counter() - t0
    return diag


def residual_summary(spec: Mapping[str, Any], diag: Diagnosis, train: Dataset, hold: Dataset,
                     sc: Mapping[str, float]) -> dict[str, Any]:
    """Per phase and channel, before and after the chosen effects, on both datasets."""
    out: dict[str, Any] = {}
    for label, data in (("train", train), ("holdout", hold)):
        base = EffectResiduals(EffectSet.of(spec, ()), data, sc)
        after = EffectResiduals(EffectSet.of(spec, diag.chosen.effects, diag.chosen.values),
                                data, sc)
        x_after = after.param.initial()
        out[label] = {
            "before": {"by_phase": base.by_phase(np.zeros(0)),
                       "by_channel": base.by_channel(np.zeros(0))},
            "after": {"by_phase": after.by_phase(x_after),
                      "by_channel": after.by_channel(x_after)},
        }
    return out


def phase_shrinkage(spec: Mapping[str, Any], cand: Candidate, data: Dataset,
                    sc: Mapping[str, float]) -> dict[str, float]:
    """Held-out cost shrinkage per phase of one candidate."""
    base = EffectResiduals(EffectSet.of(spec, ()), data, sc)
    withe = EffectResiduals(EffectSet.of(spec, cand.effects, cand.values), data, sc)
    eb = base.errors(np.zeros(0))[0] * base._weights
    ew = withe.errors(withe.param.initial())[0] * withe._weights
    out = {}
    for k, name in enumerate(PHASES):
        sel = (data.phase == k)[..., None] & base._mask
        jb = float(np.sum((eb * eb)[sel]))
        if jb > 0.0:
            out[name] = 1.0 - float(np.sum((ew * ew)[sel])) / jb
    return out
