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
effect's parameters the held-out prediction uses and ``n_eff`` the held-out windows times
channels (an AIC-like penalty that counts one independent error per window and channel, since
successive samples of a trajectory are strongly correlated). With ``refit``, base coefficients
are fitted on the training runs jointly with every candidate set, the base included.
Combinations: forward selection adds, to the best set so far, the candidate that lowers the
penalised held-out cost most, fitting the whole set jointly, while it lowers it by at least
``MIN_GAIN`` (5 %).

Environmental effects (``current``, ``wind``) are conditions of each run: one vector per run,
fitted on the training runs with the rest, and on each held-out run alone (the other
parameters fixed as trained) by two-fold cross-fitting (:func:`alternate`): the run's vector
is fitted on its even windows and scores its odd ones, and vice versa, so every held-out window
is scored with a vector fitted without it (a run with windows in one fold only is scored there
with the environment off). The held-out cost ``cost_hold`` is this cross-fitted one; the cost
with the vector fitted on all of a run's windows (``cost_hold_insample``) is kept for
comparison, and that full-run fit gives the reported per-run values. ``p`` still counts two
parameters per held-out run and environmental effect (documented choice): the global
parameters are scored out of sample too and counted, so the penalty is one parsimony rule for
every parameter the held-out prediction uses; and adjacent windows of a run share slowly
varying conditions (gusts, the smoothed start states), so the alternating folds are not fully
independent and part of the fit's optimism remains.

Selection check (:func:`selection_check`): the held-out shrinkage of the chosen set is
measured on the windows it was chosen on, and choosing the best of several noisy scores favours
the winner. So the choice is made again without each held-out run in turn (without each half of
a single held-out run), on the other held-out windows alone, and scored on the part left out:
``1 - sum(J_after) / sum(J_before)`` over the parts is the shrinkage the procedure achieves on
data its choice has not seen, and how often the parts' choices agree with the verdict's tells
how firm it is. Joint fits are fitted once per set of effects and shared with the check.

Noise floor: ``J_floor = 1/2 sum_channels m_c (sigma_c / s_c)^2`` with ``sigma_c`` each measured
channel's white noise; a gap below ``FLOOR_FACTOR`` (3) times its floor is "not attributable"
(a perfect model also carries the smoothed start state's error through each window, which is why
the factor is above 1).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trafficsim import effects
from trafficsim.diagnose.data import ANGLES, CHANNELS, PHASES, Dataset
from trafficsim.identify import output_error
from trafficsim.identify.parameters import Parametrisation
from trafficsim.identify.replay import Windows, model_rows, simulate, windows_from_runs

MIN_GAIN = 0.05
FLOOR_FACTOR = 3.0
#: penalised score within which another effect, alone, is named beside the chosen first one:
#: the data hardly tell them apart (a steering lag and a report latency both make the
#: response look late to the rudder)
NEAR_TIE = 0.02


@dataclass
class EffectSet:
    """Parameters of a set of effects on a base ship (the ``param`` of an output-error fit).

    The parameter vector is, in order: the base ship's coefficients ``refit`` fitted jointly
    with the effects (ship-file names); the parameters of the effects that are properties of
    the ship or its instruments (one value for all runs; absent when ``fixed`` gives them);
    and, for the environmental effects (:data:`trafficsim.effects.PER_RUN`), one value of each
    parameter per run of ``free_runs`` (laid out effect, key, run). ``run_fixed`` gives the
    environmental values of other runs (run name -> effect -> values).
    """

    spec: dict[str, Any]
    effects: tuple[str, ...]
    names: tuple[str, ...] = ()
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    start: np.ndarray = field(default_factory=lambda: np.zeros(0))
    refit: tuple[str, ...] = ()
    global_effects: tuple[str, ...] = ()
    fixed: dict[str, dict[str, float]] = field(default_factory=dict)
    free_runs: tuple[str, ...] = ()
    run_fixed: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)

    @classmethod
    def of(cls, spec: Mapping[str, Any], names: Sequence[str],
           start: Mapping[str, Mapping[str, float]] | None = None, *,
           refit: Sequence[str] = (), runs: Sequence[str] = (),
           run_start: Mapping[str, Mapping[str, Mapping[str, float]]] | None = None,
           fixed: Mapping[str, Mapping[str, float]] | None = None,
           run_fixed: Mapping[str, Mapping[str, Mapping[str, float]]] | None = None
           ) -> EffectSet:
        """Effects ``names`` on ``spec``; ``start``: values of the global effects (and a
        common start of the per-run ones); ``runs``: runs whose environment is fitted,
        ``run_start`` their starts; ``fixed``/``run_fixed``: values held fixed."""
        length = float(spec["particulars"]["length_m"])
        fixed = {k: dict(v) for k, v in (fixed or {}).items()}
        keys, lo, hi, x0 = [], [], [], []
        if refit:
            param = Parametrisation.of(spec, refit)
            keys += [f"base.{n}" for n in param.names]
            lo.append(param.lower)
            hi.append(param.upper)
            x0.append(param.initial())
        glob = tuple(n for n in names if n not in effects.PER_RUN and n not in fixed)
        for name in glob:
            a, b, s = effects.bounds(name, length)
            given = (start or {}).get(name)
            if given is not None:
                s = np.array([given[k] for k in effects.REGISTRY[name].keys])
            keys += [f"{name}.{k}" for k in effects.REGISTRY[name].keys]
            lo.append(a)
            hi.append(b)
            x0.append(np.clip(s, a, b))
        free_runs = tuple(runs) if any(n in effects.PER_RUN for n in names) else ()
        for name in (n for n in names if n in effects.PER_RUN):
            a, b, s = effects.bounds(name, length)
            for j, key in enumerate(effects.REGISTRY[name].keys):
                for run in free_runs:
                    given = ((run_start or {}).get(run, {}).get(name)
                             or (start or {}).get(name))
                    keys.append(f"{name}.{key}@{run}")
                    lo.append(a[j:j + 1])
                    hi.append(b[j:j + 1])
                    x0.append(np.clip([given[key] if given else s[j]], a[j], b[j]))
        return cls(dict(spec), tuple(names), tuple(keys), _cat(lo), _cat(hi), _cat(x0),
                   tuple(refit), glob, fixed, free_runs,
                   {r: {k: dict(v) for k, v in e.items()} for r, e in (run_fixed or {}).items()})

    @property
    def p(self) -> int:
        return len(self.names)

    @property
    def per_run(self) -> tuple[str, ...]:
        return tuple(n for n in self.effects if n in effects.PER_RUN)

    def initial(self) -> np.ndarray:
        return self.start.copy()

    @property
    def n_global(self) -> int:
        """Parameters that are not per run (base coefficients and global effects)."""
        return self.p - len(self.free_runs) * sum(len(effects.REGISTRY[n].keys)
                                                  for n in self.per_run)

    def columns(self) -> list[tuple[np.ndarray, bool]]:
        """Groups of parameter indices whose forward differences one perturbed model gives,
        with whether the group is per run: each base coefficient and global parameter alone,
        and each environmental parameter of all free runs together (a run's environment
        moves only that run's windows)."""
        groups = [(np.array([i]), False) for i in range(self.n_global)]
        nr = len(self.free_runs)
        for i in range(self.n_global, self.p, max(nr, 1)):
            groups.append((np.arange(i, i + nr), True))
        return groups

    def coefficients(self, theta: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.refit, theta[: len(self.refit)], strict=True)}

    def ship(self, theta: np.ndarray) -> dict[str, Any]:
        """The base ship with the refitted coefficients of ``theta`` (a copy if any)."""
        if not self.refit:
            return self.spec
        spec = dict(self.spec)
        spec["coefficients"] = {**spec["coefficients"], **self.coefficients(theta)}
        return spec

    def values(self, theta: np.ndarray) -> dict[str, dict[str, float]]:
        """Global effect values (:func:`trafficsim.effects.check` form) of one vector."""
        out: dict[str, dict[str, float]] = {k: dict(v) for k, v in self.fixed.items()}
        i = len(self.refit)
        for name in self.global_effects:
            eff = effects.REGISTRY[name]
            vals = eff.off()
            for key in eff.keys:
                vals[key] = float(theta[i])
                i += 1
            out[name] = vals
        return out

    def run_values(self, theta: np.ndarray) -> dict[str, dict[str, dict[str, float]]]:
        """Environmental effect values per run (run name -> effect -> values)."""
        out = {r: {k: dict(v) for k, v in e.items()} for r, e in self.run_fixed.items()}
        i = self.n_global
        for name in self.per_run:
            for key in effects.REGISTRY[name].keys:
                for run in self.free_runs:
                    out.setdefault(run, {}).setdefault(name, effects.REGISTRY[name].off())
                    out[run][name][key] = float(theta[i])
                    i += 1
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
        names = np.array(data.windows.run_names, dtype=object)
        self._row_run = names[data.windows.run[self.row_window]]

    @property
    def row_window(self) -> np.ndarray:
        """``(m,)`` the window of each residual (the clusters of
        :func:`trafficsim.identify.output_error.clustered_std`)."""
        return np.nonzero(self._mask)[0]

    def gear_start(self, steer: np.ndarray) -> np.ndarray:
        """``(k, W)`` rudder angle of each model's steering gear at each window's start: the
        gear (lag and rate limit, :func:`trafficsim.effects.steering`) run over the logged
        rudder from the start of the run, read as the replay reads it: linear between samples
        (first-order hold), gaps interpolated. 10 steps per sample, each the exact response of
        the lag to the linear input over the step, clipped to the rate limit: stable, never
        overshooting however short the lag, and exact where the limit is not reached."""
        win = self.data.windows
        k = steer.shape[0]
        out = np.repeat(win.inputs[None, :, 0, 0], k, axis=0)
        on = steer[:, 0] > 0.0
        if not on.any():
            return out
        tau, rate = steer[on, 0], steer[on, 1]
        for r, run in enumerate(self.data.runs):
            rud = run.trial.rudder_rad
            ok = np.isfinite(rud)
            rud = np.interp(run.t_s, run.t_s[ok], rud[ok]) if ok.any() else np.zeros(rud.size)
            dt = run.dt_s / 10.0
            approach, limit = -np.expm1(-dt / tau), rate * dt  # lag and rate limit per step
            state = np.full(tau.size, rud[0])
            at = np.empty((tau.size, rud.size))
            for j in range(rud.size):
                at[:, j] = state
                if j + 1 == rud.size:
                    break
                step = (rud[j + 1] - rud[j]) / 10.0  # input change per step
                for s in range(10):
                    # y' = (u - y) / tau, u = u0 + a t over the step: the change of y is
                    # du + (u0 - tau a - y)(1 - exp(-dt / tau)), du = a dt
                    start = rud[j] + step * s
                    change = step + (start - tau / dt * step - state) * approach
                    state = state + np.clip(change, -limit, limit)
            for i in np.flatnonzero(win.run == r):
                j0 = round(float(win.t0_s[i] - run.t_s[0]) / run.dt_s)
                out[on, i] = at[:, j0]
        return out

    def delayed(self, latency_s: float) -> Windows:
        """The windows with the inputs logged ``latency_s`` before each sample (before a run's
        first sample: its first).

        With report latency every measured state is the truth ``latency_s`` earlier, so a
        window's measured start is the truth at ``t0 - latency_s``: the replay starts there,
        on the inputs logged from then on, and its output, the truth ``latency_s`` before each
        sample, is compared with the data as it is. The replay thus runs the whole window on
        the model, as for every other candidate, and sees nothing of the data after the
        window's start. (A steering gear's angle at the start is still read at ``t0``.)
        """
        win = self.data.windows
        inputs = np.empty_like(win.inputs)
        # each window's samples, the padding repeating its last
        k = np.minimum(np.arange(win.n)[None, :], win.n_samples[:, None] - 1)
        for r, whole in enumerate(self._logged):
            on = win.run == r
            if not on.any():
                continue
            logged = whole.inputs[0, : int(whole.n_samples[0])]
            at = ((win.t0_s[on, None] - whole.t0_s[0] - latency_s + k[on] * win.dt_s[on, None])
                  / whole.dt_s[0])
            grid = np.arange(logged.shape[0])
            for j in range(2):
                inputs[on, :, j] = np.interp(at, grid, logged[:, j])
        return Windows(win.x0, inputs, win.env, win.dt_s, win.n_samples, win.target, win.run,
                       win.t0_s, win.run_names)

    @functools.cached_property
    def _logged(self) -> list[Windows]:
        """Every run as one window: its logged rudder and propeller speed, gaps bridged as
        the windows bridge them (built at the first :meth:`delayed`)."""
        return [windows_from_runs([run]) for run in self.data.runs]

    @property
    def m(self) -> int:
        return int(self._mask.sum())

    def env_offsets(self, thetas: np.ndarray) -> np.ndarray:
        """``(k, W, 4)`` current and air velocity of each window from each run's values."""
        win = self.data.windows
        out = np.zeros((thetas.shape[0], win.w, 4))
        if not self.param.per_run:
            return out
        names = win.run_names
        for i, th in enumerate(thetas):
            per = self.param.run_values(th)
            table = np.array([effects.environment_offset(per.get(n, {})) for n in names])
            out[i] = table[win.run]
        return out

    def errors(self, thetas: np.ndarray) -> np.ndarray:
        """``(k, W, N, c)`` unweighted errors (simulated minus measured, 0 where masked)."""
        thetas = np.atleast_2d(thetas)
        vals = [self.param.values(th) for th in thetas]
        specs = [effects.apply_spec(self.param.ship(th), v)
                 for th, v in zip(thetas, vals, strict=True)]
        win = self.data.windows
        run_env = self.env_offsets(thetas)
        x0 = np.stack([effects.true_start(win.x0, v, (run_env[i, :, 0], run_env[i, :, 1]))
                       for i, v in enumerate(vals)])
        env_off = run_env + np.stack([effects.environment_offset(v) for v in vals])[:, None]
        steer = np.array([effects.steering(v) for v in vals], dtype=float).reshape(-1, 2)
        x0[:, 6, :] = self.gear_start(steer)
        # report latency: the replay of :meth:`delayed`, one per latency among the models
        latency = np.array([v.get("ais_latency", {}).get("latency_s", 0.0) for v in vals])
        out = np.empty((len(vals), win.w, win.n, 6))
        diverged = np.zeros((len(vals), win.w), dtype=bool)
        for lat in np.unique(latency):
            on = np.flatnonzero(latency == lat)
            out[on], diverged[on] = simulate(
                model_rows([specs[i] for i in on]), self.delayed(lat) if lat > 0.0 else win,
                x0[on], env_off[on], steer[on])
        self.last_diverged = diverged
        undelayed = [{k: e for k, e in v.items() if k != "ais_latency"} for v in vals]
        meas = effects.measure(np.nan_to_num(out), win.dt_s, undelayed,
                               current_ne=run_env[..., :2])
        meas["cog_psi"] = meas["cog"] - meas["psi"]
        sim = np.stack([meas[c] for c in self.channels], axis=-1)
        err = sim - self._target[None]
        err = np.where(self._angle, np.mod(err + np.pi, 2 * np.pi) - np.pi, err)
        return np.where(self._mask[None], err, 0.0)

    def jacobian(self, x: np.ndarray, r0: np.ndarray, h: np.ndarray) -> np.ndarray:
        """``(m, p)`` forward differences, one perturbed model per group of
        :meth:`EffectSet.columns` (all in one replay)."""
        groups = self.param.columns()
        thetas = np.repeat(x[None, :], len(groups), axis=0)
        for g, (idx, _) in enumerate(groups):
            thetas[g, idx] += h[idx]
        diff = self(thetas) - r0[None, :]
        jac = np.zeros((r0.size, x.size))
        for g, (idx, per_run) in enumerate(groups):
            if not per_run:
                jac[:, idx[0]] = diff[g] / h[idx[0]]
                continue
            for j, run in zip(idx, self.param.free_runs, strict=True):
                rows = self._row_run == run
                jac[rows, j] = diff[g, rows] / h[j]
        return jac

    def run_costs(self, thetas: np.ndarray) -> dict[str, np.ndarray]:
        """Per run name, ``(k,)`` cost of each candidate on that run's windows."""
        r = self(np.atleast_2d(thetas))
        return {run: 0.5 * np.sum(r[:, self._row_run == run] ** 2, axis=1)
                for run in np.unique(self._row_run)}

    def __call__(self, thetas: np.ndarray) -> np.ndarray:
        err = self.errors(thetas) * self._weights
        return err[:, self._mask]

    def cost(self, theta: np.ndarray) -> float:
        r = self(np.atleast_2d(theta))[0]
        return 0.5 * float(r @ r)

    def cost_by_window(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """The cost of one vector (as :meth:`cost`, to the bit) and ``(W,)`` its part on
        each window, from one replay."""
        err = self.errors(np.atleast_2d(theta))[0] * self._weights
        r = err[self._mask]
        return 0.5 * float(r @ r), 0.5 * np.sum(err * err, axis=(1, 2))

    def floor(self) -> float:
        """Noise-floor cost of this dataset (module doc)."""
        sig = self.data.sigma[self._cols]
        counts = self._mask.sum(axis=(0, 1))
        return 0.5 * float(np.nansum(counts * (sig * self._weights) ** 2))

    def window_floors(self) -> np.ndarray:
        """``(W,)`` the noise-floor cost of each window (their sum is :meth:`floor`)."""
        sig = self.data.sigma[self._cols]
        counts = self._mask.sum(axis=1)
        return 0.5 * np.nansum(counts * (sig * self._weights) ** 2, axis=1)

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
    """A fitted set of effects and its costs.

    ``values``: the global effect values; ``run_values``: the environmental ones per run
    (training and held-out runs); ``coefficients``: the base coefficients refitted with the
    effects; ``p``: the effect parameters the held-out prediction uses (global ones plus the
    per-run ones of every held-out run), the ``p`` of the penalty. ``cost_hold``: held-out cost,
    cross-fitted for the environments of held-out runs (module doc); ``cost_hold_insample``:
    with each held-out run's environment fitted on all its windows (``None``: no such fit, the
    same as ``cost_hold``); ``fold_run_values``: the environments fitted on the first and on
    the second fold of :func:`alternate` (empty without such a fit); ``hold_windows``: ``(W,)``
    the part of ``cost_hold`` on each held-out window (for :func:`selection_check`).
    """

    effects: tuple[str, ...]
    values: dict[str, dict[str, float]]
    table: dict[str, dict[str, float]]
    cost_train: float
    cost_hold: float
    p: int
    fit: Any = None
    coefficients: dict[str, float] = field(default_factory=dict)
    run_values: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    cost_hold_insample: float | None = None
    fold_run_values: tuple[dict[str, dict[str, dict[str, float]]], ...] = ()
    hold_windows: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def shrinkage(self, base: Candidate) -> tuple[float, float]:
        return (1.0 - self.cost_train / max(base.cost_train, 1e-300),
                1.0 - self.cost_hold / max(base.cost_hold, 1e-300))

    def shrinkage_insample(self, base: Candidate) -> float:
        """Held-out shrinkage with each held-out run's environment fitted on all its windows
        (partly in sample; the same as the held-out one without per-run environments)."""
        cost = self.cost_hold if self.cost_hold_insample is None else self.cost_hold_insample
        return 1.0 - cost / max(base.cost_hold, 1e-300)

    def mean_value(self, name: str, runs: Sequence[str]) -> dict[str, float]:
        """An effect's value: the global one, or the mean over ``runs`` of a per-run one."""
        if name in self.values:
            return self.values[name]
        rows = [self.run_values[r][name] for r in runs if name in self.run_values.get(r, {})]
        return {k: float(np.mean([row[k] for row in rows]))
                for k in effects.REGISTRY[name].keys}


def _speed(spec: Mapping[str, Any]) -> float:
    return float(spec["service_speed_kn"]) * 1852.0 / 3600.0


def _grid_start(param: EffectSet, res: EffectResiduals, name: str, x: np.ndarray
                ) -> np.ndarray:
    """``x`` with effect ``name``'s parameters at the best point of its coarse grid; per run
    for an environmental effect (every grid point replayed on all runs in one call)."""
    spec = param.spec
    grid = effects.start_grid(name, float(spec["particulars"]["length_m"]), _speed(spec))
    thetas = np.repeat(x[None, :], grid.shape[0], axis=0)
    if name in effects.PER_RUN:
        nr = len(param.free_runs)
        first = param.n_global + nr * sum(len(effects.REGISTRY[n].keys)
                                          for n in param.per_run[: param.per_run.index(name)])
        for j in range(grid.shape[1]):
            thetas[:, first + j * nr: first + (j + 1) * nr] = grid[:, j:j + 1]
        thetas = np.clip(thetas, param.lower, param.upper)
        costs = res.run_costs(thetas)
        out = x.copy()
        for i, run in enumerate(param.free_runs):
            if run in costs:
                best = int(np.argmin(costs[run]))
                cols = first + np.arange(grid.shape[1]) * nr + i
                out[cols] = thetas[best, cols]
        return out
    first = len(param.refit) + sum(len(effects.REGISTRY[n].keys) for n in
                                   param.global_effects[: param.global_effects.index(name)])
    thetas[:, first:first + grid.shape[1]] = grid
    thetas = np.clip(thetas, param.lower, param.upper)
    return thetas[int(np.argmin(np.sum(res(thetas) ** 2, axis=1)))]


def _runs(data: Dataset) -> tuple[str, ...]:
    """Names of the runs that have windows in ``data``."""
    win = data.windows
    return tuple(win.run_names[i] for i in np.unique(win.run))


def alternate(data: Dataset) -> np.ndarray:
    """``(W,)`` first fold of the held-out cross-fitting: the even windows of each run (the
    windows of a run follow each other in time, so both folds cover the whole run)."""
    run = data.windows.run
    index = np.zeros(run.size, dtype=np.int64)
    for r in np.unique(run):
        at = np.flatnonzero(run == r)
        index[at[np.argsort(data.windows.t0_s[at], kind="stable")]] = np.arange(at.size)
    return index % 2 == 0


class CrossFitted(EffectResiduals):
    """Residuals on held-out data where each window's environment is the one fitted on the
    other fold: ``params[0]`` (fitted on the windows ``first``) scores the other windows,
    ``params[1]`` (fitted on the others) scores ``first``."""

    def __init__(self, params: tuple[EffectSet, EffectSet], data: Dataset,
                 scales: Mapping[str, float], first: np.ndarray) -> None:
        super().__init__(params[0], data, scales)
        self._other = EffectResiduals(params[1], data, scales)
        self._first = np.asarray(first, dtype=bool)

    def errors(self, thetas: np.ndarray) -> np.ndarray:
        a = super().errors(thetas)
        b = self._other.errors(thetas)
        return np.where(self._first[None, :, None, None], b, a)


def _fit_environments(ship: Mapping[str, Any], names: Sequence[str],
                      glob: Mapping[str, Mapping[str, float]],
                      known: Mapping[str, Mapping[str, Mapping[str, float]]], data: Dataset,
                      sc: Mapping[str, float], max_nfev: int,
                      start: Mapping[str, Mapping[str, Mapping[str, float]]] | None = None
                      ) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, Any], float]:
    """Fit the environment of every run of ``data`` not in ``known``, the rest fixed (global
    values ``glob``, ``known`` runs' environments); ``start``: starting values per run (a
    coarse grid for an effect without). Returns the environments of all runs, the fit's table
    and its cost on ``data``."""
    if data.windows.w == 0:
        return {r: {k: dict(v) for k, v in e.items()} for r, e in known.items()}, {}, 0.0
    runs = tuple(r for r in _runs(data) if r not in known)
    param = EffectSet.of(ship, names, fixed=glob, runs=runs, run_start=start, run_fixed=known)
    res = EffectResiduals(param, data, sc)
    if not param.p:
        return param.run_values(np.zeros(0)), {}, res.cost(np.zeros(0))
    x = param.initial()
    for name in param.per_run:
        if not all(name in (start or {}).get(r, {}) for r in runs):
            x = _grid_start(param, res, name, x)
    fitted = output_error.fit(param, data.windows, x0=x, max_nfev=max_nfev, rel_step=1e-4,
                              tol=1e-6, residuals=res)
    return param.run_values(fitted.x), fitted.table(), float(fitted.cost)


def _mean_start(folds: Sequence[Mapping[str, Mapping[str, Mapping[str, float]]]],
                runs: Sequence[str]) -> dict[str, dict[str, dict[str, float]]]:
    """Per run and effect, the mean of the folds' fitted values (where a fold has the run)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for run in runs:
        have = [f[run] for f in folds if run in f]
        for name in {n for h in have for n in h}:
            rows = [h[name] for h in have if name in h]
            out.setdefault(run, {})[name] = {k: float(np.mean([row[k] for row in rows]))
                                             for k in rows[0]}
    return out


def fit_set(spec: Mapping[str, Any], names: Sequence[str], train: Dataset, hold: Dataset,
            sc: Mapping[str, float], start: Mapping[str, Mapping[str, float]] | None = None,
            max_nfev: int = 30, refit: Sequence[str] = (),
            run_start: Mapping[str, Mapping[str, Mapping[str, float]]] | None = None,
            coefficients: Mapping[str, float] | None = None,
            fold_start: Sequence[Mapping[str, Mapping[str, Mapping[str, float]]]] = ()
            ) -> Candidate:
    """Fit the effects ``names`` (with the base coefficients ``refit``) jointly on ``train``;
    evaluate on ``hold`` (the ship's and instruments' parameters as fitted on ``train``),
    cross-fitting there the environment of each held-out run that is not a training run
    (module doc). ``coefficients``: starting values of the refitted coefficients;
    ``fold_start``: starting environments of the two folds' fits (fitted on the same folds)."""
    base_spec = dict(spec)
    if coefficients:
        base_spec["coefficients"] = {**spec["coefficients"], **coefficients}
    param = EffectSet.of(base_spec, names, start, refit=refit, runs=_runs(train),
                         run_start=run_start)
    res_t = EffectResiduals(param, train, sc)
    if param.p == 0:
        cost_hold, hold_windows = EffectResiduals(param, hold, sc).cost_by_window(np.zeros(0))
        return Candidate((), {}, {}, res_t.cost(np.zeros(0)), cost_hold, 0,
                         hold_windows=hold_windows)
    x_start = param.initial()
    if len(names) == 1 and start is None and run_start is None:
        x_start = _grid_start(param, res_t, names[0], x_start)
    result = output_error.fit(param, train.windows, x0=x_start, max_nfev=max_nfev,
                              rel_step=1e-4, tol=1e-6, residuals=res_t)
    x = result.x
    glob, runs_fit = param.values(x), param.run_values(x)
    coeffs = param.coefficients(x)
    table = result.table()
    ship = param.ship(x)
    hold_runs = _runs(hold)
    new_runs = tuple(r for r in hold_runs if r not in runs_fit) if param.per_run else ()
    cost_in, folds = None, ()
    if new_runs:
        first = alternate(hold)
        folds = tuple(_fit_environments(ship, names, glob, runs_fit, hold.subset(sel), sc,
                                        max_nfev, fold_start[k] if fold_start else None)[0]
                      for k, sel in enumerate((first, ~first)))
        cross = CrossFitted(tuple(EffectSet.of(ship, names, fixed=glob, run_fixed=f)
                                  for f in folds), hold, sc, first)
        cost_hold, hold_windows = cross.cost_by_window(np.zeros(0))
        runs_fit, table_h, cost_in = _fit_environments(ship, names, glob, runs_fit, hold, sc,
                                                       max_nfev, _mean_start(folds, new_runs))
        table.update(table_h)
    else:
        cost_hold, hold_windows = EffectResiduals(
            EffectSet.of(ship, names, fixed=glob, run_fixed=runs_fit), hold, sc
        ).cost_by_window(np.zeros(0))
    return Candidate(tuple(names), glob, table, result.cost, cost_hold,
                     parameter_count(names, len(hold_runs)), result, coeffs, runs_fit, cost_in,
                     folds, hold_windows)


def parameter_count(names: Sequence[str], n_runs: int) -> int:
    """The ``p`` of the penalty: the effects' global parameters plus their per-run ones on
    ``n_runs`` held-out runs (refitted base coefficients are not counted: the base has them
    too)."""
    keys = [len(effects.REGISTRY[n].keys) for n in names]
    per_run = sum(k for n, k in zip(names, keys, strict=True) if n in effects.PER_RUN)
    return int(sum(keys) - per_run + n_runs * per_run)


def penalised(cost: float, p: int, n_eff: int) -> float:
    return cost * (1.0 + 2.0 * p / max(n_eff, 1))


@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`.

    ``steps`` is the forward selection's trace (each effect added while it shrank the
    penalised held-out cost enough); ``chosen`` is the verdict's model, the base where the gap
    is below the noise floor whatever the trace added. ``check``: the
    :func:`selection_check` (empty with a single held-out window).
    """

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
    refit: tuple[str, ...] = ()
    check: dict[str, Any] = field(default_factory=dict)


@dataclass
class Scoring:
    """Held-out scores on a set of held-out windows: ``windows`` a ``(W,)`` mask, or None
    for all of them (then each candidate's ``cost_hold`` itself); ``n_eff`` the windows times
    channels, ``n_runs`` the held-out runs they belong to, ``floor`` their noise floor."""

    windows: np.ndarray | None
    n_eff: int
    n_runs: int
    floor: float

    def cost(self, c: Candidate) -> float:
        if self.windows is None:
            return c.cost_hold
        return float(np.sum(c.hold_windows[self.windows]))

    def penalised(self, c: Candidate) -> float:
        return penalised(self.cost(c), parameter_count(c.effects, self.n_runs), self.n_eff)


@dataclass
class Selection:
    """What the ranking, forward selection and noise-floor gate choose on one
    :class:`Scoring`: ``ranked`` singles best first with their penalised ``score``s; ``found``
    the forward selection's set, ``chosen`` the same or the base below the noise floor."""

    ranked: list[Candidate]
    score: dict[str, float]
    chosen: Candidate
    steps: list[dict[str, Any]]
    gap_ratio: float
    attributable: bool
    found: Candidate


def select(base: Candidate, singles: Sequence[Candidate], scoring: Scoring,
           joint: Any, forward_steps: int, gate: bool = True) -> Selection:
    """Rank the singles by penalised held-out shrinkage, add effects by forward selection
    while the penalised held-out cost drops by ``MIN_GAIN`` or more, then (``gate``) the
    noise-floor gate (module doc). ``joint(chosen, single)``: the set ``chosen`` plus the
    effect of ``single`` fitted jointly on the training runs."""
    before = scoring.cost(base)
    score = {c.effects[0]: 1.0 - scoring.penalised(c) / before for c in singles}
    ranked = sorted(singles, key=lambda c: -score[c.effects[0]])
    chosen, steps = base, []
    pool = [c for c in ranked if score[c.effects[0]] > MIN_GAIN][:4]
    current_pen = before
    for _ in range(forward_steps):
        best, best_pen = None, current_pen
        for single in pool:
            if single.effects[0] in chosen.effects:
                continue
            cand = single if not chosen.effects else joint(chosen, single)
            pen = scoring.penalised(cand)
            if pen < best_pen:
                best, best_pen = cand, pen
        if best is None or best_pen > (1.0 - MIN_GAIN) * current_pen:
            break
        steps.append({"added": best.effects[-1], "effects": list(best.effects),
                      "cost_holdout": scoring.cost(best), "penalised_cost_holdout": best_pen})
        chosen, current_pen = best, best_pen
    gap_ratio = before / max(scoring.floor, 1e-300)
    above = gap_ratio >= FLOOR_FACTOR or not gate
    return Selection(ranked, score, chosen if above else base, steps, gap_ratio,
                     above and bool(chosen.effects), chosen)


def check_groups(hold: Dataset) -> list[tuple[str, np.ndarray]]:
    """The parts of the held-out data that :func:`selection_check` leaves out in turn: each
    held-out run; a single held-out run's first and second half of its windows in time (none
    with fewer than two windows)."""
    win = hold.windows
    runs = np.unique(win.run)
    if runs.size > 1:
        return [(str(win.run_names[r]), win.run == r) for r in runs]
    if win.w < 2:
        return []
    order = np.argsort(win.t0_s, kind="stable")
    first = np.zeros(win.w, dtype=bool)
    first[order[: win.w // 2]] = True
    name = str(win.run_names[runs[0]])
    return [(f"{name}, first half", first), (f"{name}, second half", ~first)]


def selection_check(base: Candidate, singles: Sequence[Candidate], chosen: Candidate,
                    hold: Dataset, n_channels: int, floors: np.ndarray, joint: Any,
                    forward_steps: int) -> dict[str, Any]:
    """Selection left out of its own score: for each part of :func:`check_groups`, choose
    (:func:`select`) on the other held-out windows only and score that choice on the part
    left out. ``shrinkage_holdout`` is ``1 - sum(after) / sum(before)`` over the parts: the
    gap shrinkage of choosing by this procedure on data the choice has not seen (the held-out
    shrinkage of the verdict is measured on the windows it was chosen on, which favours it:
    the best of several noisy scores). The noise-floor gate is not applied to the parts'
    choices: whether the gap stands above the noise is asked of all the held-out data, once,
    by the verdict (a part alone may be too short to pass it). ``same_choice`` counts the
    parts whose choice is ``chosen``, the one forward selection makes on all the held-out
    data before that gate (the same set of effects, or nothing for both)."""
    groups = check_groups(hold)
    parts, before, after, same = [], 0.0, 0.0, 0
    for label, part in groups:
        rest = ~part
        scoring = Scoring(rest, int(rest.sum()) * n_channels,
                          int(np.unique(hold.windows.run[rest]).size), float(floors[rest].sum()))
        pick = select(base, singles, scoring, joint, forward_steps, gate=False)
        b = float(np.sum(base.hold_windows[part]))
        a = float(np.sum(pick.chosen.hold_windows[part]))
        before, after = before + b, after + a
        same += int(set(pick.chosen.effects) == set(chosen.effects))
        parts.append({"left_out": label, "windows": int(part.sum()),
                      "chosen": list(pick.chosen.effects),
                      "cost_before": b, "cost_after": a,
                      "shrinkage": 1.0 - a / max(b, 1e-300)})
    if not parts:
        return {}
    return {"parts": parts, "same_choice": same,
            "shrinkage_holdout": 1.0 - after / max(before, 1e-300)}


def gap_change(shrinkage: float) -> str:
    """``'25 % smaller'`` for a shrinkage of 0.25, ``'10 % larger'`` for -0.1."""
    pct = round(100 * shrinkage)
    return f"{pct} % smaller" if pct >= 0 else f"{-pct} % larger"


def diagnose(spec: Mapping[str, Any], train: Dataset, hold: Dataset,
             candidates: Sequence[str] = effects.NAMES, forward_steps: int = 3,
             max_nfev: int = 30, refit: Sequence[str] = (),
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Single-effect fits, ranking, forward selection, the noise-floor verdict and its
    :func:`selection_check`.

    ``refit``: base coefficients fitted jointly with every candidate set, the base included
    (the base without effects is then the base refitted on the training runs).
    ``progress``: called with a line of text as each fit ends."""
    t0 = time.perf_counter()
    say = progress or (lambda text: None)
    length = float(spec["particulars"]["length_m"])
    sc = scales(train, length)
    refit = tuple(refit)
    base = fit_set(spec, (), train, hold, sc, refit=refit, max_nfev=max_nfev)
    say(f"base{' refitted' if refit else ''}: held-out cost {base.cost_hold:.4g} "
        f"({time.perf_counter() - t0:.1f} s)")
    start_coeffs = base.coefficients or None
    res_h = EffectResiduals(EffectSet.of(spec, ()), hold, sc)
    n_eff = hold.windows.w * len(res_h.channels)
    floor_t = EffectResiduals(EffectSet.of(spec, ()), train, sc).floor()
    floor_h = res_h.floor()
    singles = []
    for k, name in enumerate(candidates, 1):
        t1 = time.perf_counter()
        singles.append(fit_set(spec, (name,), train, hold, sc, max_nfev=max_nfev, refit=refit,
                               coefficients=start_coeffs))
        say(f"{name} ({k}/{len(candidates)}): held-out gap "
            f"{gap_change(singles[-1].shrinkage(base)[1])} ({time.perf_counter() - t1:.1f} s)")
    fitted: dict[frozenset[str], Candidate] = {}

    def joint(chosen: Candidate, single: Candidate) -> Candidate:
        """The two fitted jointly, once per set of effects (the checks reuse the fits)."""
        names = (*chosen.effects, single.effects[0])
        if frozenset(names) in fitted:
            return fitted[frozenset(names)]
        start = {**chosen.values, **single.values}
        run_start = {r: {**chosen.run_values.get(r, {}), **single.run_values.get(r, {})}
                     for r in {*chosen.run_values, *single.run_values}}
        folds = tuple({r: {**a.get(r, {}), **b.get(r, {})} for r in {*a, *b}}
                      for a, b in zip(chosen.fold_run_values or ({}, {}),
                                      single.fold_run_values or ({}, {}), strict=True)
                      ) if chosen.fold_run_values or single.fold_run_values else ()
        t1 = time.perf_counter()
        got = fitted[frozenset(names)] = fit_set(
            spec, names, train, hold, sc, start, max_nfev, refit, run_start or None,
            chosen.coefficients or start_coeffs, folds)
        say(f"{' + '.join(names)} jointly: held-out gap {gap_change(got.shrinkage(base)[1])} "
            f"({time.perf_counter() - t1:.1f} s)")
        return got

    sel = select(base, singles, Scoring(None, n_eff, len(_runs(hold)), floor_h), joint,
                 forward_steps)
    chosen, score, gap_ratio = sel.chosen, sel.score, sel.gap_ratio
    if gap_ratio < FLOOR_FACTOR:
        verdict = (f"not attributable: the held-out gap is {gap_ratio:.1f} times the data's "
                   f"noise floor (below {FLOOR_FACTOR:g})")
    elif not chosen.effects:
        verdict = ("not attributable: no effect in the library shrinks the held-out gap by "
                   f"{100 * MIN_GAIN:.0f} % or more after the parameter penalty")
    else:
        sh = chosen.shrinkage(base)[1]
        verdict = (f"{' + '.join(chosen.effects)}: held-out gap {100 * sh:.0f} % smaller "
                   f"({gap_ratio:.1f} times the noise floor before)")
        rivals = [c for c in sel.ranked if c.effects[0] not in chosen.effects
                  and score[chosen.effects[0]] - score[c.effects[0]] <= NEAR_TIE]
        if rivals:
            verdict += ("; nearly as good alone: " + ", ".join(
                f"{c.effects[0]} ({100 * c.shrinkage(base)[1]:.0f} %)" for c in rivals)
                + " (the data hardly tell them apart)")
    check = selection_check(base, sel.ranked, sel.found, hold, len(res_h.channels),
                            res_h.window_floors(), joint, forward_steps)
    if check and sel.attributable:
        n, same = len(check["parts"]), check["same_choice"]
        word = "half" if check["parts"][0]["left_out"].endswith("half") else "run"
        verdict += (f"; chosen without each held-out {word} in turn: the same {same} of {n} "
                    f"times, and the gap {gap_change(check['shrinkage_holdout'])} on the "
                    f"{word}s left out")
    diag = Diagnosis(base, sel.ranked, chosen, sel.steps, floor_t, floor_h, n_eff,
                     sel.attributable, verdict, 0.0, {}, refit, check)
    diag.residuals = residual_summary(spec, diag, train, hold, sc)
    diag.elapsed_s = time.perf_counter() - t0
    return diag


def evaluation(spec: Mapping[str, Any], cand: Candidate, data: Dataset,
               sc: Mapping[str, float], held_out: bool = False) -> EffectResiduals:
    """Residuals of a fitted candidate on ``data`` (no free parameter: evaluate at
    ``np.zeros(0)``); ``held_out``: ``data`` are the held-out windows, scored cross-fitted
    when the candidate has fold environments (module doc)."""
    ship = dict(spec)
    if cand.coefficients:
        ship["coefficients"] = {**spec["coefficients"], **cand.coefficients}
    if held_out and cand.fold_run_values:
        return CrossFitted(tuple(EffectSet.of(ship, cand.effects, fixed=cand.values,
                                              run_fixed=f) for f in cand.fold_run_values),
                           data, sc, alternate(data))
    return EffectResiduals(EffectSet.of(ship, cand.effects, fixed=cand.values,
                                        run_fixed=cand.run_values), data, sc)


def residual_summary(spec: Mapping[str, Any], diag: Diagnosis, train: Dataset, hold: Dataset,
                     sc: Mapping[str, float]) -> dict[str, Any]:
    """Per phase and channel, before and after the chosen effects, on both datasets."""
    out: dict[str, Any] = {}
    x = np.zeros(0)
    for label, data in (("train", train), ("holdout", hold)):
        base = evaluation(spec, diag.base, data, sc)
        after = evaluation(spec, diag.chosen, data, sc, held_out=label == "holdout")
        out[label] = {
            "before": {"by_phase": base.by_phase(x), "by_channel": base.by_channel(x)},
            "after": {"by_phase": after.by_phase(x), "by_channel": after.by_channel(x)},
        }
    return out


def phase_shrinkage(spec: Mapping[str, Any], cand: Candidate, data: Dataset,
                    sc: Mapping[str, float], base_cand: Candidate | None = None
                    ) -> dict[str, float]:
    """Held-out cost shrinkage per phase of one candidate (against ``base_cand``, default
    the unchanged base ship), cross-fitted like the held-out cost."""
    base = evaluation(spec, base_cand, data, sc, held_out=True) if base_cand is not None \
        else EffectResiduals(EffectSet.of(spec, ()), data, sc)
    withe = evaluation(spec, cand, data, sc, held_out=True)
    eb = base.errors(np.zeros(0))[0] * base._weights
    ew = withe.errors(np.zeros(0))[0] * withe._weights
    out = {}
    for k, name in enumerate(PHASES):
        sel = (data.phase == k)[..., None] & base._mask
        jb = float(np.sum((eb * eb)[sel]))
        if jb > 0.0:
            out[name] = 1.0 - float(np.sum((ew * ew)[sel])) / jb
    return out
