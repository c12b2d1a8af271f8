"""Replay: simulate ship models driven by MEASURED rudder angle and propeller speed.

Identification and sim-to-real comparisons need the model's answer to exactly the inputs the
real ship saw, from the state it was really in. The steering gear and engine of the model are
therefore bypassed: between two samples ``k, k+1`` the rudder angle and propeller speed are the
linear interpolation of the measured values (first-order hold; at RK4's stage times this is the
measured value at ``k``, their mean at mid-step [seed 001, eq 4, ``s_m(k)``] and the value at
``k+1``), and the environment (wind, current) is held at sample ``k``. Each family's compiled
hydrodynamics (``kernels.accel``) is integrated by classic RK4 with the kinematics of
:mod:`trafficsim.ships.kernels`; the heading is not wrapped, so it compares directly with an
unwrapped measured heading.

Many replays are one compiled call: ``k`` parameter sets (e.g. a model and its copies with one
coefficient perturbed each, the columns of a finite-difference Jacobian) times ``W`` windows
(pieces of the measured runs, each started from its own measured state). A model whose state
stops being finite (a candidate far from the truth can diverge) is frozen at its last finite
state for the rest of the window and flagged, so the residuals stay finite and large.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.estimation.smoother import unwrap_finite
from trafficsim.jit import kernel
from trafficsim.ships import base, kernels

#: replayed output channels, in order: north_m, east_m, psi_rad (unwrapped), u_mps, v_mps, r_radps
OUTPUTS = ("north_m", "east_m", "psi_rad", "u_mps", "v_mps", "r_radps")
N_OUT = 6
#: speed (m/s) or yaw rate (rad/s) above which a replay counts as diverged
_RUNAWAY = 1e3


@dataclass(frozen=True)
class ModelRows:
    """``k`` ship models ready for the compiled replay.

    Attributes:
        codes: ``(k,)`` family codes (:data:`trafficsim.ships.kernels.FAMILY_CODE`).
        params: ``(k, c)`` packed parameter rows, zero-padded to the widest family.
        max_dt_s: ``(k,)`` longest RK4 step each model allows (ship file
            ``integration.max_dt_s``).
    """

    codes: np.ndarray
    params: np.ndarray
    max_dt_s: np.ndarray

    @property
    def k(self) -> int:
        return int(self.codes.shape[0])


def model_rows(specs: Sequence[Mapping[str, Any]]) -> ModelRows:
    """Pack ship specs (parsed ship files, any mix of families) into :class:`ModelRows`."""
    fams = base.families()
    tables: list[np.ndarray] = []
    for spec in specs:
        family = fams[spec["model"]]
        tables.append(base.pack(family.build([spec]))[0])
    width = max(t.shape[0] for t in tables)
    params = np.zeros((len(specs), width))
    for i, row in enumerate(tables):
        params[i, : row.shape[0]] = row
    codes = np.array([kernels.FAMILY_CODE[s["model"]] for s in specs], dtype=np.int64)
    max_dt = np.array([float(s.get("integration", {}).get("max_dt_s", 1.0)) for s in specs])
    return ModelRows(codes, params, max_dt)


@dataclass(frozen=True)
class Windows:
    """``W`` replay windows, struct-of-arrays padded to ``N`` samples.

    Attributes:
        x0: ``(8, W)`` initial state (rows of :mod:`trafficsim.ships.base`; rudder and rps
            rows are ignored, the measured inputs drive the model).
        inputs: ``(W, N, 2)`` measured rudder angle (rad) and propeller speed (rev/s).
        env: ``(W, N, 4)`` current north, current east (m/s), true wind speed (m/s), wind from
            (rad) per sample.
        dt_s: ``(W,)`` sampling interval of each window, s.
        n_samples: ``(W,)`` samples in each window (the rest is padding).
        target: ``(W, N, 6)`` measured outputs (:data:`OUTPUTS`), NaN where missing or padded.
        run: ``(W,)`` index of the run each window comes from; t0_s: ``(W,)`` its start time.
        run_names: names of the runs.
    """

    x0: np.ndarray
    inputs: np.ndarray
    env: np.ndarray
    dt_s: np.ndarray
    n_samples: np.ndarray
    target: np.ndarray
    run: np.ndarray
    t0_s: np.ndarray
    run_names: tuple[str, ...]

    @property
    def w(self) -> int:
        return int(self.dt_s.shape[0])

    @property
    def n(self) -> int:
        return int(self.inputs.shape[1])

    def valid(self) -> np.ndarray:
        """``(W, N)`` True on the samples that belong to each window."""
        return np.arange(self.n)[None, :] < self.n_samples[:, None]

    def subset(self, mask: np.ndarray) -> Windows:
        """The windows where ``mask`` (``(W,)`` bool) is True."""
        m = np.asarray(mask, dtype=bool)
        return Windows(self.x0[:, m], self.inputs[m], self.env[m], self.dt_s[m],
                       self.n_samples[m], self.target[m], self.run[m], self.t0_s[m],
                       self.run_names)


def substeps(models: ModelRows, windows: Windows) -> np.ndarray:
    """``(k, W)`` RK4 sub-steps per sample interval so that each is at most ``max_dt_s``."""
    return np.maximum(1, np.ceil(windows.dt_s[None, :] / models.max_dt_s[:, None] - 1e-9)
                      ).astype(np.int64)


def simulate(models: ModelRows, windows: Windows, x0: np.ndarray | None = None,
             env_offset: np.ndarray | None = None, steering: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
    """Replay every model on every window in one compiled call.

    Args:
        models, windows: the ``k`` models and ``W`` windows.
        x0: ``(k, 8, W)`` initial state per model (default: every model starts from
            ``windows.x0``); a measurement effect (antenna lever arm, compass bias, report
            latency) moves the true start away from the measured one.
        env_offset: ``(k, 4)`` per-model environment added to the windows' (current north,
            current east, air velocity north, air velocity east over ground, all m/s, the
            air velocity "towards"), or ``(k, W, 4)`` per model and window (e.g. a wind of each
            run); default none. A zero air velocity leaves the windows' wind as it is.
        steering: ``(k, 2)`` steering gear between the measured rudder angle and the hull:
            first-order lag ``tau_s`` (s) and rate limit (rad/s); ``tau_s <= 0`` (default)
            means the hull feels the measured angle. The gear's angle at each window's start is
            row 6 of ``x0`` (default: the measured angle).

    Returns:
        ``out`` ``(k, W, N, 6)`` simulated :data:`OUTPUTS` (NaN beyond each window's samples)
        and ``diverged`` ``(k, W)`` bool (state frozen at its last finite value, see module doc).
    """
    out = np.full((models.k, windows.w, windows.n, N_OUT), np.nan)
    diverged = np.zeros((models.k, windows.w), dtype=np.bool_)
    if x0 is None:
        x0 = np.repeat(windows.x0[None], models.k, axis=0)
        x0[:, 6, :] = windows.inputs[:, 0, 0]  # a steering gear starts at the measured angle
    if env_offset is None:
        env_offset = np.zeros((models.k, 4))
    env_offset = np.asarray(env_offset, dtype=float)
    if env_offset.ndim == 2:
        env_offset = np.repeat(env_offset[:, None, :], windows.w, axis=1)
    if steering is None:
        steering = np.zeros((models.k, 2))
    _replay(models.codes, np.ascontiguousarray(models.params),
            substeps(models, windows), np.ascontiguousarray(x0, dtype=float),
            np.ascontiguousarray(windows.inputs), np.ascontiguousarray(windows.env),
            windows.dt_s.astype(float), windows.n_samples.astype(np.int64),
            np.ascontiguousarray(env_offset, dtype=float),
            np.ascontiguousarray(steering, dtype=float), out, diverged)
    return out, diverged


@kernel
def _derivative(code: int, p: np.ndarray, x: np.ndarray, env: np.ndarray,
                out: np.ndarray) -> None:
    """Time derivative of the 6 motion states (rudder, rps rows of ``x`` are inputs)."""
    du, dv, dr = kernels.accel(code, p, x, env)
    kernels.motion_rates(du, dv, dr, x, env, out)


@kernel
def _set_inputs(x: np.ndarray, u_in: np.ndarray, k: int, f: float, lag: bool) -> float:
    """Rudder and rps rows of ``x`` at fraction ``f`` of the interval ``k -> k+1``; with a
    steering ``lag`` the rudder row is a state and the measured angle is returned instead."""
    rudder = (1.0 - f) * u_in[k, 0] + f * u_in[k + 1, 0]
    if not lag:
        x[6] = rudder
    x[7] = (1.0 - f) * u_in[k, 1] + f * u_in[k + 1, 1]
    return rudder


@kernel
def _window_env(env_k: np.ndarray, off: np.ndarray, env: np.ndarray) -> None:
    """Environment of one sample: the window's plus a model's offset (``simulate``)."""
    env[0] = env_k[0] + off[0]
    env[1] = env_k[1] + off[1]
    env[2] = env_k[2]
    env[3] = env_k[3]
    if off[2] != 0.0 or off[3] != 0.0:
        # air velocity over ground (towards) = the window's wind + the offset
        an = -env_k[2] * math.cos(env_k[3]) + off[2]
        ae = -env_k[2] * math.sin(env_k[3]) + off[3]
        env[2] = math.sqrt(an * an + ae * ae)
        env[3] = math.atan2(-ae, -an)


@kernel
def _rudder_rate(measured: float, x: np.ndarray, steer: np.ndarray) -> float:
    """Steering gear: first-order lag with a rate limit towards the measured angle."""
    rate = (measured - x[6]) / steer[0]
    return min(max(rate, -steer[1]), steer[1])


@kernel
def _replay(codes: np.ndarray, P: np.ndarray, sub: np.ndarray, X0: np.ndarray,
            U_in: np.ndarray, E: np.ndarray, dt: np.ndarray, n_samples: np.ndarray,
            E_off: np.ndarray, steer: np.ndarray, out: np.ndarray, diverged: np.ndarray) -> None:
    """RK4 replay of ``k`` models x ``W`` windows with first-order-hold measured inputs.

    Args:
        codes ``(k,)``, P ``(k, c)``, sub ``(k, W)`` sub-steps per interval; X0 ``(k, 8, W)``;
        U_in ``(W, N, 2)`` rudder rad, rps; E ``(W, N, 4)`` environment per sample;
        dt ``(W,)`` s; n_samples ``(W,)``; E_off ``(k, W, 4)`` environment offsets; steer
        ``(k, 2)`` steering lag (s) and rate (rad/s); out ``(k, W, N, 6)`` (written);
        diverged ``(k, W)``.
    """
    n_models = codes.shape[0]
    n_win = X0.shape[2]
    x = np.empty(8)
    xt = np.empty(8)
    last = np.empty(6)
    k1 = np.empty(7)
    k2 = np.empty(7)
    k3 = np.empty(7)
    k4 = np.empty(7)
    env = np.empty(4)
    for m in range(n_models):
        code, p, st = codes[m], P[m], steer[m]
        lag = st[0] > 0.0
        for w in range(n_win):
            u_in, env_w, off = U_in[w], E[w], E_off[m, w]
            for j in range(8):
                x[j] = X0[m, j, w]
            for j in range(6):
                out[m, w, 0, j] = x[j]
                last[j] = x[j]
            frozen = False
            ns = sub[m, w]
            h = dt[w] / ns
            nx = 7 if lag else 6
            for k in range(n_samples[w] - 1):
                _window_env(env_w[k], off, env)
                if not frozen:
                    for s in range(ns):
                        f0 = s / ns
                        fm = (s + 0.5) / ns
                        f1 = (s + 1.0) / ns
                        d = _set_inputs(x, u_in, k, f0, lag)
                        _derivative(code, p, x, env, k1)
                        if lag:
                            k1[6] = _rudder_rate(d, x, st)
                        for j in range(nx):
                            xt[j] = x[j] + 0.5 * h * k1[j]
                        d = _set_inputs(xt, u_in, k, fm, lag)
                        _derivative(code, p, xt, env, k2)
                        if lag:
                            k2[6] = _rudder_rate(d, xt, st)
                        for j in range(nx):
                            xt[j] = x[j] + 0.5 * h * k2[j]
                        _derivative(code, p, xt, env, k3)
                        if lag:
                            k3[6] = _rudder_rate(d, xt, st)
                        for j in range(nx):
                            xt[j] = x[j] + h * k3[j]
                        d = _set_inputs(xt, u_in, k, f1, lag)
                        _derivative(code, p, xt, env, k4)
                        if lag:
                            k4[6] = _rudder_rate(d, xt, st)
                        for j in range(nx):
                            x[j] += (h / 6.0) * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
                    ok = True
                    for j in range(6):
                        if not math.isfinite(x[j]):
                            ok = False
                    if ok and (abs(x[3]) > _RUNAWAY or abs(x[4]) > _RUNAWAY
                               or abs(x[5]) > _RUNAWAY):
                        ok = False
                    if ok:
                        for j in range(6):
                            last[j] = x[j]
                    else:
                        frozen = True
                        diverged[m, w] = True
                for j in range(6):
                    out[m, w, k + 1, j] = last[j]


def _filled(values: np.ndarray, t: np.ndarray, what: str, path: str) -> np.ndarray:
    """``values`` with NaN replaced by linear interpolation over the finite samples."""
    ok = np.isfinite(values)
    if ok.all():
        return values
    if not ok.any():
        from trafficsim.errors import DataError

        raise DataError(f"no finite {what} sample; the replay needs the measured {what}",
                        path=path or None)
    return np.interp(t, t[ok], values[ok])


def windows_from_runs(runs: Sequence[Any], horizon_s: float | None = None,
                      use_wind: bool = False) -> Windows:
    """Cut smoothed runs (:class:`trafficsim.identify.preprocess.Kinematics`) into windows.

    Each window starts from the smoothed state at its first sample and runs ``horizon_s``
    seconds (``None``: the whole run is one window); consecutive windows share their boundary
    sample; a last piece shorter than half a horizon is dropped. Targets are the smoothed
    position, heading (unwrapped) and body velocities. Missing measured inputs are interpolated;
    wind enters only with ``use_wind`` and a run that has it.
    """
    pieces: list[tuple[int, int, int]] = []  # (run, first sample, samples)
    for r, run in enumerate(runs):
        n = run.trial.n
        if horizon_s is None:
            pieces.append((r, 0, n))
            continue
        per = max(2, round(horizon_s / run.dt_s) + 1)
        start = 0
        while start < n - 1:
            count = min(per, n - start)
            # keep a last piece of at least half a horizon (in intervals, not samples)
            if (count >= 2 and 2 * (count - 1) >= per - 1) or start == 0:
                pieces.append((r, start, count))
            start += per - 1
    if not pieces:
        from trafficsim.errors import DataError

        raise DataError("no replay window: runs too short for the horizon")
    n_max = max(c for _, _, c in pieces)
    w = len(pieces)
    x0 = np.zeros((base.N_STATE, w))
    inputs = np.zeros((w, n_max, 2))
    env = np.zeros((w, n_max, 4))
    target = np.full((w, n_max, N_OUT), np.nan)
    dt = np.zeros(w)
    n_samples = np.zeros(w, dtype=np.int64)
    run_idx = np.zeros(w, dtype=np.int64)
    t0 = np.zeros(w)
    prepared = []
    for run in runs:
        tr, sm = run.trial, run.smooth
        rud = _filled(tr.rudder_rad, tr.t_s, "rudder angle", tr.path)
        rps = _filled(tr.rps, tr.t_s, "propeller speed", tr.path)
        wind = np.zeros((tr.n, 2))
        if use_wind and tr.has_wind:
            wind[:, 0] = np.nan_to_num(_filled(tr.wind_speed_mps, tr.t_s, "wind speed", tr.path))
            # a gap in the direction is bridged the short way round (350 deg ... 10 deg)
            wind[:, 1] = np.nan_to_num(np.mod(_filled(unwrap_finite(tr.wind_from_rad), tr.t_s,
                                                      "wind direction", tr.path), 2.0 * np.pi))
        outs = np.stack([sm[k] for k in OUTPUTS], axis=1)
        prepared.append((rud, rps, wind, outs))
    for i, (r, s, c) in enumerate(pieces):
        rud, rps, wind, outs = prepared[r]
        sl = slice(s, s + c)
        x0[: N_OUT, i] = outs[s]
        inputs[i, :c, 0], inputs[i, :c, 1] = rud[sl], rps[sl]
        inputs[i, c:] = inputs[i, c - 1]
        env[i, :c, 2:] = wind[sl]
        target[i, :c] = outs[sl]
        dt[i] = runs[r].dt_s
        n_samples[i] = c
        run_idx[i] = r
        t0[i] = runs[r].t_s[s]
    return Windows(x0, inputs, env, dt, n_samples, target, run_idx, t0,
                   tuple(run.name for run in runs))
