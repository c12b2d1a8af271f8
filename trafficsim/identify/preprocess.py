"""Pre-processing of trial runs: u, v, r and their uncertainty from position and heading.

Seed 001 derives the identification data from recorded positions and heading by a per-axis
constant-acceleration Kalman filter and the fixed-interval RTS smoother [seed 001, section 4.1,
eqs 6-9]; :func:`trafficsim.estimation.smoother.body_velocities` implements it. This module
prepares runs for it and keeps the result with the measured inputs:

* a sampling that is not uniform is resampled onto a uniform grid (linear interpolation, angles
  unwrapped first; samples farther than one interval from any measurement become NaN); a time
  step longer than :data:`~trafficsim.identify.datacheck.MAX_GAP_INTERVALS` median intervals is
  refused (:func:`~trafficsim.identify.datacheck.check_gaps`), shorter gaps are bridged;
* repeated values (a receiver that did not update repeats its last output: the FRT-DS-ESSO
  files hold runs of identical positions and headings up to 2.5 s long) are treated as missing,
  so the smoother bridges them instead of reading a stop-and-go motion; counted in the report.
  Only runs of repeats up to 5 s long count: a value held longer is a constant signal (a
  ship on a steady heading recorded without noise);
* leading samples are dropped until position and heading are finite twice in a row (the filter
  starts from two samples [seed 001, after eq 8]);
* all runs with the same sampling interval are smoothed in one vectorised call (padded with
  missing samples).

Noise settings, when not given (documented choices, not from seed 001, which gives none):

* measurement noise of each series from the data: the robust (MAD) standard deviation of its
  third differences divided by sqrt(20) (white noise of variance s^2 has third differences of
  variance 20 s^2, while a smooth track's third difference is negligible at trial sampling
  rates), with floors of 1 mm and 0.01 deg;
* process noise of the CA model from the ship's length ``L`` and speed ``U`` (the scales of a
  turning ship: accelerations of order ``U^2 / L``, yaw accelerations ``U^2 / L^2``, time
  ``L / U``): manoeuvre acceleration ``sigma_a = U^2 / (4 L)``, yaw acceleration
  ``sigma_r' = U^2 / (4 L^2)``, correlation rate ``alpha = U / L``. A 225 m ship at 13 kn gets
  the smoother's default ``sigma_a`` (0.05 m/s2) and ``alpha`` (1/30 s) and a fifth of its
  generous default yaw acceleration; the 3 m FRT-DS-ESSO model at 0.4 m/s gets 0.013 m/s2,
  0.0044 rad/s2 and 1/7.5 s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from trafficsim.errors import DataError
from trafficsim.estimation.smoother import body_velocities, unwrap_finite
from trafficsim.identify.datacheck import check_gaps
from trafficsim.io.trialdata import TrialData

_SQRT20 = np.sqrt(20.0)
#: floors of the noise estimates (m, rad)
MIN_SIGMA_POS_M = 1e-3
MIN_SIGMA_HEADING_RAD = np.radians(0.01)
#: longest run of repeated values read as a receiver that did not update, s
MAX_STALE_S = 5.0


@dataclass(frozen=True)
class SmootherSettings:
    """Noise settings of the CA filter / RTS smoother; None = automatic (module doc)."""

    sigma_pos_m: float | None = None
    sigma_heading_rad: float | None = None
    sigma_acc_mps2: float | None = None
    sigma_yaw_acc_radps2: float | None = None
    alpha_per_s: float | None = None
    mask_repeats: bool = True


@dataclass(frozen=True)
class Kinematics:
    """One run ready for identification: the measured run and its smoothed motion.

    Attributes:
        trial: the measured run after resampling, repeat masking and trimming (``(N,)``).
        smooth: smoothed series, ``(N,)`` each: ``north_m, east_m, psi_rad`` (unwrapped),
            ``u_mps, v_mps, r_radps`` and ``sigma_*`` (see ``body_velocities``).
        settings: the noise settings used (automatic ones filled in).
        repeats_masked: samples of position / heading treated as missing because repeated.
    """

    trial: TrialData
    smooth: dict[str, np.ndarray]
    settings: dict[str, Any]
    repeats_masked: dict[str, int]

    @property
    def name(self) -> str:
        return self.trial.name

    @property
    def t_s(self) -> np.ndarray:
        return self.trial.t_s

    @property
    def dt_s(self) -> float:
        return self.trial.dt_s

    def decimate(self, step: int) -> Kinematics:
        """Every ``step``-th sample (smoothed series are already low-pass)."""
        if step <= 1:
            return self
        idx = slice(0, None, step)
        return replace(self, trial=self.trial.take(idx),
                       smooth={k: v[idx] for k, v in self.smooth.items()})

    def report(self) -> dict[str, Any]:
        """Samples, NaN counts, masked repeats and the smoother's settings."""
        return {"name": self.name, "path": self.trial.path, **self.trial.nan_report(),
                "repeats_masked": self.repeats_masked, "smoother": self.settings,
                "median_sigma": {k: float(np.nanmedian(self.smooth[k])) for k in
                                 ("sigma_u_mps", "sigma_v_mps", "sigma_r_radps")}}


def resample_uniform(trial: TrialData, dt_s: float | None = None) -> TrialData:
    """The run on a uniform time grid (no-op if it already is one to 1 %).

    Series, and the extra columns kept under their own names, are interpolated linearly over
    their finite samples (angles unwrapped first: the heading, course and wind direction, and
    extra columns in ``_rad``); grid points farther than ``dt_s`` from every finite sample of
    a series are NaN. A time step longer than ``MAX_GAP_INTERVALS`` median intervals is a
    DataError (:func:`~trafficsim.identify.datacheck.check_gaps`).
    """
    check_gaps(trial)
    steps = np.diff(trial.t_s)
    dt = float(np.median(steps)) if dt_s is None else float(dt_s)
    if dt_s is None and np.all(np.abs(steps - dt) <= 0.01 * dt):
        return trial
    grid = trial.t_s[0] + dt * np.arange(int(np.floor(trial.duration_s / dt + 1e-9)) + 1)
    angles = {"psi_rad", "cog_rad", "wind_from_rad"}

    def on_grid(values: np.ndarray, angle: bool) -> np.ndarray:
        ok = np.isfinite(values)
        if ok.sum() < 2:
            return np.full(grid.shape, np.nan)
        t_ok = trial.t_s[ok]
        out = np.interp(grid, t_ok, np.unwrap(values[ok]) if angle else values[ok])
        pos = np.clip(np.searchsorted(t_ok, grid), 1, t_ok.size - 1)
        gap = np.minimum(np.abs(grid - t_ok[pos - 1]), np.abs(t_ok[pos] - grid))
        out[gap > dt * (1.0 + 1e-9)] = np.nan
        return out

    series: dict[str, np.ndarray | None] = {key: on_grid(values, key in angles)
                                            for key, values in trial.arrays().items()
                                            if key != "t_s"}
    extra = {key: on_grid(values, key.endswith("_rad")) for key, values in trial.extra.items()}
    return replace(trial, t_s=grid, extra=extra).with_series(**series)


def _stale(same: np.ndarray, dt: float, max_stale_s: float) -> np.ndarray:
    """Samples equal to the previous one within runs of repeats lasting at most
    ``max_stale_s`` (a longer run of one value is a genuinely constant signal)."""
    out = np.zeros_like(same)
    i, n = 0, same.size
    while i < n:
        if not same[i]:
            i += 1
            continue
        j = i
        while j < n and same[j]:
            j += 1
        if (j - i) * dt <= max_stale_s:
            out[i:j] = True
        i = j
    return out


def mask_repeats(trial: TrialData, max_stale_s: float = MAX_STALE_S
                 ) -> tuple[TrialData, dict[str, int]]:
    """Positions (north and east both) and headings equal to the previous sample -> NaN, in
    runs of repeats up to ``max_stale_s`` long (module doc)."""
    n, e, psi = trial.north_m.copy(), trial.east_m.copy(), trial.psi_rad.copy()
    dt = trial.dt_s
    same_pos = _stale(np.r_[False, (np.diff(n) == 0.0) & (np.diff(e) == 0.0)], dt, max_stale_s)
    same_psi = _stale(np.r_[False, np.diff(psi) == 0.0], dt, max_stale_s)
    n[same_pos] = np.nan
    e[same_pos] = np.nan
    psi[same_psi] = np.nan
    return (trial.with_series(north_m=n, east_m=e, psi_rad=psi),
            {"position": int(same_pos.sum()), "heading": int(same_psi.sum())})


def first_usable(trial: TrialData) -> int:
    """Index of the first sample at which position and heading are finite twice in a row."""
    ok = np.isfinite(trial.north_m) & np.isfinite(trial.east_m) & np.isfinite(trial.psi_rad)
    both = ok[:-1] & ok[1:]
    if not both.any():
        raise DataError("no two consecutive samples with position and heading; cannot smooth",
                        path=trial.path or None)
    return int(np.argmax(both))


def noise_from_data(values: np.ndarray, floor: float) -> float:
    """Measurement noise sigma of a series from its third differences (module doc)."""
    d3 = np.diff(values, 3)
    d3 = d3[np.isfinite(d3)]
    if d3.size < 10:
        return floor
    mad = np.median(np.abs(d3 - np.median(d3)))
    return max(1.4826 * mad / _SQRT20, floor)


def resolve_settings(trials: Sequence[TrialData], length_m: float, speed_mps: float,
                     settings: SmootherSettings) -> dict[str, Any]:
    """Fill the automatic settings (module doc) from the runs and the ship."""
    s = asdict(settings)
    if s["sigma_pos_m"] is None:  # median over runs and axes
        s["sigma_pos_m"] = float(np.median([
            noise_from_data(v, MIN_SIGMA_POS_M) for t in trials for v in (t.north_m, t.east_m)]))
    if s["sigma_heading_rad"] is None:
        s["sigma_heading_rad"] = float(np.median([
            noise_from_data(unwrap_finite(t.psi_rad), MIN_SIGMA_HEADING_RAD) for t in trials]))
    u, length = max(float(speed_mps), 1e-3), float(length_m)
    if s["sigma_acc_mps2"] is None:
        s["sigma_acc_mps2"] = u * u / (4.0 * length)
    if s["sigma_yaw_acc_radps2"] is None:
        s["sigma_yaw_acc_radps2"] = u * u / (4.0 * length * length)
    if s["alpha_per_s"] is None:
        s["alpha_per_s"] = u / length
    return {k: v if isinstance(v, bool) else float(v) for k, v in s.items()}


def smooth_runs(trials: Sequence[TrialData], length_m: float, speed_mps: float,
                settings: SmootherSettings = SmootherSettings(),
                dt_s: float | None = None) -> list[Kinematics]:
    """Resample, mask repeats, decimate, trim and smooth runs [seed 001, section 4.1].

    Args:
        trials: measured runs.
        length_m, speed_mps: ship length and a typical speed (automatic process noise).
        settings: noise settings (None entries automatic).
        dt_s: sampling interval to work at: runs sampled faster keep every k-th sample
            (``k = round(dt_s / dt)``, after repeats are masked); None keeps the data's rate.

    Returns:
        one :class:`Kinematics` per run, in order.
    """
    prepared: list[TrialData] = []
    masked: list[dict[str, int]] = []
    for trial in trials:
        t = resample_uniform(trial)
        counts = {"position": 0, "heading": 0}
        if settings.mask_repeats:
            t, counts = mask_repeats(t)
        if dt_s is not None and dt_s > t.dt_s:
            t = t.take(slice(0, None, max(1, round(dt_s / t.dt_s))))
        t = t.take(slice(first_usable(t), None))
        if t.n < 4:
            raise DataError("fewer than 4 usable samples", path=trial.path or None)
        prepared.append(t)
        masked.append(counts)
    resolved = resolve_settings(prepared, length_m, speed_mps, settings)
    out: list[Kinematics | None] = [None] * len(prepared)
    # one vectorised smoother call per sampling interval (runs padded with missing samples)
    groups: dict[float, list[int]] = {}
    for i, t in enumerate(prepared):
        groups.setdefault(round(t.dt_s, 9), []).append(i)
    for dt, members in groups.items():
        length = max(prepared[i].n for i in members)
        pad = np.full((3, len(members), length), np.nan)
        for row, i in enumerate(members):
            t = prepared[i]
            pad[0, row, : t.n] = t.north_m
            pad[1, row, : t.n] = t.east_m
            pad[2, row, : t.n] = unwrap_finite(t.psi_rad)
        sm = body_velocities(
            pad[0], pad[1], pad[2], dt,
            sigma_pos_m=resolved["sigma_pos_m"], sigma_heading_rad=resolved["sigma_heading_rad"],
            sigma_acc_mps2=resolved["sigma_acc_mps2"],
            sigma_yaw_acc_radps2=resolved["sigma_yaw_acc_radps2"],
            alpha_per_s=resolved["alpha_per_s"])
        for row, i in enumerate(members):
            n = prepared[i].n
            out[i] = Kinematics(prepared[i], {k: v[row, :n] for k, v in sm.items()},
                                resolved, masked[i])
    return [k for k in out if k is not None]
