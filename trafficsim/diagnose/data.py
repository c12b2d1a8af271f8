"""Measured runs as replay windows with their measured channels, manoeuvre phases and noise.

The replay (:mod:`trafficsim.identify.replay`) starts each window from the state smoothed from
the measured position and heading; what the model's answer is compared with are the MEASURED
channels themselves (not the smoothed ones), so that sensor effects can be modelled on the
simulated side (:func:`trafficsim.effects.measure`):

* ``north, east`` position, ``psi`` heading (always);
* ``u, v, r`` when the data carry them as columns (e.g. FRT-DS-ESSO);
* ``sog`` and ``cog_psi`` (course over ground minus heading, the drift angle over ground) when
  the data carry SOG and COG.

Manoeuvre phases of every sample (:func:`phases`), from the measured rudder angle and the
smoothed yaw rate, thresholds relative to the run (our choice):

* ``approach``: rudder within 2 deg of zero and little yaw rate (below 10 % of the run's peak),
  also everything before the first rudder command;
* ``execute``: rudder out, yaw rate growing towards the rudder's side faster than 10 % of the
  run's peak yaw acceleration (rudder moving until the yaw rate peaks);
* ``steady``: rudder out, yaw rate on the rudder's side and no longer growing;
* ``checks``: rudder against the yaw rate (counter rudder, zig-zag checks and reversals);
* ``pullout``: rudder within 2 deg of zero while the ship still turns.

Noise floor (:func:`noise_sigma`): each measured channel's white-noise level from its third
differences (:func:`trafficsim.identify.preprocess.noise_from_data`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trafficsim.estimation.smoother import unwrap_finite
from trafficsim.identify import preprocess, replay
from trafficsim.identify.preprocess import Kinematics

PHASES = ("approach", "execute", "steady", "checks", "pullout")
#: measured channels in the order of the target arrays
CHANNELS = ("north", "east", "psi", "u", "v", "r", "sog", "cog_psi")
#: channels that are angles (residuals wrapped to [-pi, pi))
ANGLES = ("psi", "cog_psi")
_RUDDER_ZERO_RAD = np.radians(2.0)


def phases(rudder_rad: np.ndarray, r_radps: np.ndarray, dt_s: float) -> np.ndarray:
    """Phase index (:data:`PHASES`) of every sample of one run (module doc)."""
    rud = np.nan_to_num(rudder_rad)
    r = np.nan_to_num(r_radps)
    rdot = np.gradient(r, dt_s) if r.size > 1 else np.zeros_like(r)
    r_thr = 0.1 * max(float(np.max(np.abs(r))), 1e-9)
    a_thr = 0.1 * max(float(np.max(np.abs(rdot))), 1e-12)
    out = np.zeros(r.size, dtype=np.int64)
    out_rudder = np.abs(rud) >= _RUDDER_ZERO_RAD
    started = np.cumsum(out_rudder) > 0
    side = np.sign(rud)
    against = out_rudder & (side * r < -r_thr)
    growing = out_rudder & (side * rdot > a_thr) & ~against
    steady = out_rudder & ~against & ~growing
    out[growing] = 1
    out[steady] = 2
    out[against] = 3
    out[~out_rudder & (np.abs(r) > r_thr) & started] = 4
    out[~started] = 0
    return out


def noise_sigma(values: np.ndarray, angle: bool = False) -> float:
    """White-noise standard deviation of one measured series (third differences); NaN where
    fewer than ten third differences are known (too little to tell noise from motion)."""
    v = unwrap_finite(values) if angle else np.asarray(values, float)
    if np.sum(np.isfinite(np.diff(v, 3))) < 10:
        return float("nan")
    return preprocess.noise_from_data(v, 1e-9)


@dataclass
class Dataset:
    """Replay windows of a set of runs with measured channels, phases and noise levels.

    Attributes:
        runs: the smoothed runs.
        windows: replay windows (:class:`trafficsim.identify.replay.Windows`).
        target: ``(W, N, 8)`` measured :data:`CHANNELS` (NaN where absent or padded).
        phase: ``(W, N)`` phase index per sample (-1 on padding).
        sigma: ``(8,)`` noise standard deviation of each channel (NaN if absent).
        channels: the channels the data carry.
    """

    runs: list[Kinematics]
    windows: replay.Windows
    target: np.ndarray
    phase: np.ndarray
    sigma: np.ndarray
    channels: tuple[str, ...]

    def subset(self, mask: np.ndarray) -> Dataset:
        m = np.asarray(mask, dtype=bool)
        return Dataset(self.runs, self.windows.subset(m), self.target[m], self.phase[m],
                       self.sigma, self.channels)


def _measured(run: Kinematics) -> np.ndarray:
    """``(n, 8)`` measured channels of one run."""
    t = run.trial
    out = np.full((t.n, len(CHANNELS)), np.nan)
    out[:, 0], out[:, 1] = t.north_m, t.east_m
    out[:, 2] = unwrap_finite(t.psi_rad)
    for j, series in ((3, t.u_mps), (4, t.v_mps), (5, t.r_radps), (6, t.sog_mps)):
        if series is not None:
            out[:, j] = series
    if t.cog_rad is not None:
        out[:, 7] = np.mod(t.cog_rad - t.psi_rad + np.pi, 2 * np.pi) - np.pi
    return out


def dataset(runs: Sequence[Kinematics], horizon_s: float, use_wind: bool = False) -> Dataset:
    """Windows of ``horizon_s`` seconds over ``runs`` with measured channels and phases."""
    runs = list(runs)
    win = replay.windows_from_runs(runs, horizon_s, use_wind)
    measured = [_measured(r) for r in runs]
    run_phase = [phases(r.trial.rudder_rad, r.smooth["r_radps"], r.dt_s) for r in runs]
    target = np.full((win.w, win.n, len(CHANNELS)), np.nan)
    phase = np.full((win.w, win.n), -1, dtype=np.int64)
    for i in range(win.w):
        r = int(win.run[i])
        start = round(float(win.t0_s[i] - runs[r].t_s[0]) / runs[r].dt_s)
        c = int(win.n_samples[i])
        target[i, :c] = measured[r][start:start + c]
        phase[i, :c] = run_phase[r][start:start + c]
    sig = np.full(len(CHANNELS), np.nan)
    for j, name in enumerate(CHANNELS):
        vals = [noise_sigma(m[:, j], name in ANGLES) for m in measured]
        vals = [v for v in vals if np.isfinite(v)]
        if vals:
            sig[j] = float(np.median(vals))
    present = tuple(c for j, c in enumerate(CHANNELS) if np.isfinite(target[..., j]).any())
    return Dataset(runs, win, target, phase, sig, present)
