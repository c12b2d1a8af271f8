"""Checks of trial runs that the reader accepts as files but a fit cannot use.

Each failure is one :class:`~trafficsim.errors.DataError` at the file, line and column (the
column as the file names it, the value as the file holds it), or an
:class:`~trafficsim.errors.InputError` naming ``--data`` when it concerns all training runs:

* a time step longer than :data:`MAX_GAP_INTERVALS` typical (median) sampling intervals: gaps
  up to that are bridged (resampled onto the uniform grid as missing samples, which the
  smoother bridges), a longer one is refused (split the run at it), so the resampled run holds
  at most ``MAX_GAP_INTERVALS`` times the samples of the file;
* a value that is not finite (``inf``; an empty cell or ``nan`` is a missing value and allowed);
* a value no instrument can read: a rudder angle beyond 90 deg either way, a position farther
  than half the Earth's circumference from the origin, a negative speed over ground or wind
  speed, a true wind speed above :data:`MAX_WIND_MPS`, a propeller speed beyond twice the base
  ship's engine range (``rps_min .. rps_max``, whichever is larger in size; an rpm column
  holding rev/s reads 60 times too fast);
* runs that do not excite what is fitted: a ship that does not move (its track spans less than
  its length in every training run), and coefficients of the sway and yaw motion from runs in
  none of which both the rudder and the heading move by :data:`MIN_EXCURSION_DEG` or more;
  and the propeller speed at the service speed (``rps_service`` of ``nomoto``) from runs in
  which the ship makes way ahead above :data:`AHEAD_FRACTION` of its service speed only with
  the propeller stopped or astern (an rpm column whose sign is reversed reads so);
* columns in other units than their names say, told by what the ship does while it makes way
  above :data:`AHEAD_FRACTION` of its service speed: a heading that turns through less than
  :data:`HEADING_TURN_FRACTION` of the track's own turn (of at least
  :data:`MIN_TRACK_TURN_DEG`; radians in a degrees column turn 57 times too little), and a
  propeller that turns below :data:`RPS_FLOOR_FRACTION` of the base ship's largest speed
  (rev/s in an rpm column read 60 times too slow; in the FRT-DS-ESSO runs the median at speed
  is 0.30-0.77 of it).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from trafficsim.errors import DataError, InputError
from trafficsim.estimation.smoother import unwrap_finite
from trafficsim.io import trialdata
from trafficsim.io.trialdata import TrialData
from trafficsim.units import KN

if TYPE_CHECKING:  # (preprocess imports this module)
    from trafficsim.identify.preprocess import Kinematics

#: longest time step bridged, in median sampling intervals
MAX_GAP_INTERVALS = 20
#: largest rudder angle either way, deg
MAX_RUDDER_DEG = 90.0
#: largest distance of a position from the origin of its local frame, m
MAX_POSITION_M = 2.0e7
#: largest true wind speed, m/s (the strongest sustained winds on record, in tropical
#: cyclones, stay below it: Hurricane Patricia 2015, about 96 m/s)
MAX_WIND_MPS = 100.0
#: speeds ahead above this fraction of the service speed tell the propeller speed giving it
AHEAD_FRACTION = 0.3
#: propeller speeds up to this multiple of the base ship's engine range
RPS_FACTOR = 2.0
#: smallest rudder and heading excursion (largest minus smallest) that excites the yaw, deg
MIN_EXCURSION_DEG = 1.0
#: the smallest turn of the track at speed (course over ground, deg) that tells a heading
#: column's unit, and the fraction of it the heading must turn through (in the FRT-DS-ESSO
#: runs the heading turns through 0.53-3.3 times the track's turn; the same runs' headings
#: written in radians 0.01-0.04 times)
MIN_TRACK_TURN_DEG = 20.0
HEADING_TURN_FRACTION = 0.1
#: the smallest median propeller speed at speed, as a fraction of the base ship's largest
RPS_FLOOR_FRACTION = 1.0 / 20.0
#: coefficients a run without turning determines (surge and propulsion only)
SURGE_ONLY = frozenset({"rps_service", "surge_tau_s", "R0", "X_0F", "X_0A", "a1", "a8", "a9"})

#: trial-data CSV column of each TrialData field
_CSV_COLUMN = {"t_s": "t_s", "north_m": "north_m", "east_m": "east_m", "psi_rad": "heading_deg",
               "rudder_rad": "rudder_deg", "rps": "rpm", "u_mps": "u_mps", "v_mps": "v_mps",
               "r_radps": "r_degps", "sog_mps": "sog_kn", "cog_rad": "cog_deg",
               "wind_speed_mps": "wind_speed_mps", "wind_from_rad": "wind_from_deg"}
#: FRT-DS-ESSO column of each TrialData field (and renamed extra column)
_FRT_COLUMN = {(extra or field): header for header, (field, extra) in
               trialdata.FRT_COLUMNS.items()}


def _located(trial: TrialData, field: str, index: int,
             columns: Mapping[str, str] | None) -> tuple[int | None, str, float | None]:
    """File line, file column name and file value of sample ``index`` of ``field`` (a series
    or an extra column); line and value None for a run not read from a file."""
    column = field
    line, value = None, None
    header: list[str] = []
    table, lines = np.empty((0, 0)), np.empty(0, dtype=int)
    if trial.path:
        try:
            header, table, lines = trialdata._read_table(Path(trial.path))
        except (DataError, OSError):
            header = []
    frt = "x_position_mid [m]" in header
    if frt:
        column = _FRT_COLUMN.get(field, field)
    elif field in _CSV_COLUMN:
        column = _CSV_COLUMN[field]
        column = (columns or {}).get(column, column)
    elif field.endswith("_replaced"):  # a column another one was read in place of
        column = field.removesuffix("_replaced")
    if column in header:
        keep = ~np.all(np.isnan(table), axis=1)
        rows = np.flatnonzero(keep)
        if index < rows.size:
            line = int(lines[rows[index]])
            value = float(table[rows[index], header.index(column)])
    return line, column, value


def column_of(trial: TrialData, field: str, columns: Mapping[str, str] | None = None) -> str:
    """The column of ``field`` as the run's file names it (``rpm``, ``n_prop [rps]``, ...)."""
    return _located(trial, field, 0, columns)[1]


def _error(trial: TrialData, field: str, index: int, columns: Mapping[str, str] | None,
           message: str) -> DataError:
    line, column, value = _located(trial, field, index, columns)
    if value is not None:
        message = message.replace("{value}", f"{value:.10g}")
    else:
        message = message.replace("{value}", "this value")
    return DataError(message, path=trial.path or None, line=line, key=column)


def check_gaps(trial: TrialData, columns: Mapping[str, str] | None = None) -> None:
    """Refuse a time step longer than :data:`MAX_GAP_INTERVALS` median intervals."""
    if trial.n < 3:
        return
    steps = np.diff(trial.t_s)
    dt = float(np.median(steps))
    longest = int(np.argmax(steps))
    gap = float(steps[longest])
    if gap <= MAX_GAP_INTERVALS * dt:
        return
    t0, t1 = float(trial.t_s[longest]), float(trial.t_s[longest + 1])
    raise _error(trial, "t_s", longest + 1, columns,
                 f"time jumps from {t0:.10g} s to {t1:.10g} s, a gap of {gap:.6g} s "
                 f"({gap / dt:.6g} sampling intervals of {dt:.6g} s); gaps of up to "
                 f"{MAX_GAP_INTERVALS} intervals ({MAX_GAP_INTERVALS * dt:.6g} s) are bridged, "
                 "a longer one is not: split the run into two files at this line")


def _series(trial: TrialData) -> Iterable[tuple[str, np.ndarray]]:
    yield from trial.arrays().items()
    yield from trial.extra.items()


def _first(trial: TrialData, bad: Mapping[str, np.ndarray]) -> tuple[str, int] | None:
    """The field and index of the earliest sample flagged in ``bad`` (per field)."""
    found = [(int(np.argmax(mask)), field) for field, mask in bad.items() if mask.any()]
    if not found:
        return None
    index, field = min(found)
    return field, index


def check_values(trial: TrialData, columns: Mapping[str, str] | None = None) -> None:
    """Refuse infinite values and readings no instrument gives (module doc)."""
    first = _first(trial, {k: np.isinf(v) for k, v in _series(trial)})
    if first is not None:
        raise _error(trial, *first, columns, "expected a finite number (an empty cell for a "
                     "missing value), got {value}")
    rad = np.radians(MAX_RUDDER_DEG)
    limits = [
        ({"rudder_rad": np.abs(trial.rudder_rad) > rad},
         f"expected a rudder angle of at most {MAX_RUDDER_DEG:g} deg either way, got {{value}}"),
        ({k: np.abs(getattr(trial, k)) > MAX_POSITION_M for k in ("north_m", "east_m")},
         f"expected a position within {MAX_POSITION_M:g} m of the origin (half the Earth's "
         "circumference), got {value}"),
        ({k: getattr(trial, k) < 0.0 for k in ("sog_mps", "wind_speed_mps")
          if getattr(trial, k) is not None},
         "expected a speed of at least 0, got {value}"),
        ({"wind_speed_mps": trial.wind_speed_mps > MAX_WIND_MPS}
         if trial.wind_speed_mps is not None else {},
         f"expected a true wind speed of at most {MAX_WIND_MPS:g} m/s (above the strongest "
         "sustained winds on record), got {value}"),
    ]
    for bad, message in limits:
        first = _first(trial, bad)
        if first is not None:
            raise _error(trial, *first, columns, message)


def check_run(trial: TrialData, columns: Mapping[str, str] | None = None) -> None:
    """Time gaps, non-finite values and impossible readings of one run."""
    check_gaps(trial, columns)
    check_values(trial, columns)


def check_propeller(trials: Sequence[TrialData], spec: Mapping[str, Any],
                    columns: Mapping[str, str] | None = None) -> None:
    """Refuse propeller speeds beyond :data:`RPS_FACTOR` times the base ship's engine range."""
    most = _engine_range(spec)
    if not most > 0.0:
        return
    limit = RPS_FACTOR * most
    for trial in trials:
        first = _first(trial, {"rps": np.abs(trial.rps) > limit})
        if first is not None:
            raise _error(trial, *first, columns,
                         f"expected a propeller speed of at most {RPS_FACTOR:g} times the "
                         f"engine range of the base ship '{spec.get('name')}' ({limit:.4g} "
                         f"rev/s = {60.0 * limit:.4g} rpm either way), got {{value}}")


def _engine_range(spec: Mapping[str, Any]) -> float:
    """The base ship's largest propeller speed either way, rev/s (0 without actuators)."""
    act = spec.get("actuators", {})
    return max(abs(float(act.get("rps_max", 0.0))), abs(float(act.get("rps_min", 0.0))))


def _index_at(trial: TrialData, t_s: float) -> int:
    """The sample of ``trial`` (as read) nearest the time ``t_s``."""
    return int(np.argmin(np.abs(trial.t_s - t_s)))


def _span(trial: TrialData) -> float | None:
    """Largest extent of the track, m (NaN-aware; None without two finite positions)."""
    ok = np.isfinite(trial.north_m) & np.isfinite(trial.east_m)
    if ok.sum() < 2:
        return None
    return float(np.hypot(np.ptp(trial.north_m[ok]), np.ptp(trial.east_m[ok])))


def _excursion_deg(values: np.ndarray, angle: bool = False) -> float:
    v = unwrap_finite(values) if angle else np.asarray(values, float)
    v = v[np.isfinite(v)]
    return float(np.degrees(np.ptp(v))) if v.size else 0.0


def _where(trials: Sequence[TrialData]) -> tuple[str | None, str, str]:
    """(path, key, wording) to name the training runs in an error."""
    if len(trials) == 1:
        return trials[0].path or None, "", "the run"
    names = ", ".join(t.name for t in trials)
    return None, "--data", f"any of the {len(trials)} training runs ({names})"


def check_motion(trials: Sequence[TrialData], length_m: float) -> None:
    """Refuse training runs in none of which the track spans the ship's length (runs without
    two positions are left to the smoother, which names them)."""
    spans = [s for s in map(_span, trials) if s is not None]
    if not spans or len(spans) < len(trials) or max(spans) >= length_m:
        return
    span = max(spans)
    path, key, runs = _where(trials)
    raise InputError(f"the ship does not move in {runs}: its track spans {span:.3g} m, less "
                     f"than its length ({length_m:g} m); there is nothing to fit or replay",
                     path=path, key=key or None)


def check_excitation(trials: Sequence[TrialData], names: Sequence[str]) -> None:
    """Refuse a fit of sway or yaw coefficients from runs in none of which both the rudder and
    the heading move by :data:`MIN_EXCURSION_DEG` or more."""
    turning = [n for n in names if n not in SURGE_ONLY]
    if not turning or any(not np.isfinite(t.rudder_rad).any() for t in trials):
        return  # (a run without any rudder reading is refused by the replay, named)
    rudder = [_excursion_deg(t.rudder_rad) for t in trials]
    heading = [_excursion_deg(t.psi_rad, angle=True) for t in trials]
    if any(a >= MIN_EXCURSION_DEG and b >= MIN_EXCURSION_DEG for a, b in
           zip(rudder, heading, strict=True)):
        return
    path, key, _ = _where(trials)
    surge = [n for n in names if n in SURGE_ONLY]
    instead = f" or fit only {', '.join(surge)} (--fit)" if surge else ""
    where = ("in this run the rudder and the heading do not" if len(trials) == 1 else
             f"in none of the {len(trials)} training runs ({', '.join(t.name for t in trials)})"
             " do the rudder and the heading")
    raise InputError(f"{', '.join(turning)} cannot be identified from this data: {where} both "
                     f"move by {MIN_EXCURSION_DEG:g} deg or more (largest excursions: rudder "
                     f"{max(rudder):.3g} deg, heading {max(heading):.3g} deg), so nothing "
                     f"excites the turning motion; give runs with rudder manoeuvres (turns, "
                     f"zig-zags){instead}", path=path, key=key or None)


def check_propulsion(trials: Sequence[TrialData], runs: Sequence[Kinematics],
                     u_service_mps: float, columns: Mapping[str, str] | None = None,
                     optional: bool = True) -> None:
    """Refuse training runs (``trials``, smoothed as ``runs``) in which the ship makes way ahead
    above :data:`AHEAD_FRACTION` of the service speed only with the propeller stopped or
    astern: the propeller speed giving the service speed (``rps_service``) is then not
    determined, and a fit drives it to its bound (``optional``: the base ship could give it
    instead, which the message suggests). Runs that never go that fast (with an rpm reading)
    are left alone."""
    fast = [np.isfinite(r.smooth["u_mps"]) & np.isfinite(r.trial.rps)
            & (r.smooth["u_mps"] > AHEAD_FRACTION * u_service_mps) for r in runs]
    if not any(f.any() for f in fast) or any(
            (f & (r.trial.rps > 0.0)).any() for f, r in zip(fast, runs, strict=True)):
        return
    i = next(k for k, f in enumerate(fast) if f.any())
    j = int(np.argmax(fast[i]))
    u, t = float(runs[i].smooth["u_mps"][j]), float(runs[i].t_s[j])
    why = (f"the ship makes way ahead above {100 * AHEAD_FRACTION:g} % of its service speed "
           f"({AHEAD_FRACTION * u_service_mps:.3g} m/s) only with the propeller stopped or "
           "astern")
    hint = ("the rpm is signed (negative astern): check the sign of the column"
            + (", or fit without rps_service (--fit)" if optional else ""))
    if len(trials) == 1:
        raise _error(trials[0], "rps", _index_at(trials[0], t), columns,
                     f"rps_service cannot be identified from this data: {why} (here "
                     f"{u:.3g} m/s ahead, the column reading {{value}}); {hint}")
    path, key, where = _where(trials)
    raise InputError(f"rps_service cannot be identified from {where}: {why} (run "
                     f"'{runs[i].name}' at t = {t:.6g} s: {u:.3g} m/s ahead at "
                     f"{60.0 * float(runs[i].trial.rps[j]):.4g} rpm); {hint}",
                     path=path, key=key or None)


def check_units(trials: Sequence[TrialData], runs: Sequence[Kinematics],
                spec: Mapping[str, Any], columns: Mapping[str, str] | None = None) -> None:
    """Refuse a heading or propeller-speed column whose values are in other units than its
    name says (module docstring). ``trials``: the runs as read; ``runs``: the same smoothed."""
    u_service = float(spec["service_speed_kn"]) * KN
    most = _engine_range(spec)
    for trial, run in zip(trials, runs, strict=True):
        north, east, t = run.smooth["north_m"], run.smooth["east_m"], run.t_s
        if t.size < 3:
            continue
        vn, ve = np.gradient(north, t), np.gradient(east, t)
        fast = np.isfinite(vn) & np.isfinite(ve) & (np.hypot(vn, ve) > AHEAD_FRACTION * u_service)
        if fast.sum() < 3:
            continue
        first_fast_s = float(t[int(np.argmax(fast))])  # (where a refusal points)
        track = float(np.degrees(np.ptp(np.unwrap(np.arctan2(ve[fast], vn[fast])))))
        heading = _excursion_deg(run.trial.psi_rad[fast], angle=True)
        if (track >= MIN_TRACK_TURN_DEG and np.isfinite(run.trial.psi_rad[fast]).any()
                and heading < HEADING_TURN_FRACTION * track):
            raise _error(trial, "psi_rad", _index_at(trial, first_fast_s), columns,
                         f"the heading turns through {heading:.3g} deg while the ship's track "
                         f"turns through {track:.3g} deg at speed (above "
                         f"{100 * AHEAD_FRACTION:g} % of the service speed): a heading in "
                         "radians, or a frozen compass, reads so; expected degrees clockwise "
                         "from north")
        rps = run.trial.rps[fast]
        ahead = rps[np.isfinite(rps) & (rps > 0.0)]
        median = float(np.median(ahead)) if ahead.size else np.inf
        if most > 0.0 and median < RPS_FLOOR_FRACTION * most:
            raise _error(trial, "rps", _index_at(trial, first_fast_s), columns,
                         f"the propeller turns at a median {60.0 * median:.4g} "
                         f"rpm (here {{value}} as read) while the ship makes way above "
                         f"{100 * AHEAD_FRACTION:g} % of its service speed: less than "
                         f"1/{1.0 / RPS_FLOOR_FRACTION:g} of the base ship "
                         f"'{spec.get('name')}''s largest ({60.0 * most:.4g} rpm); a column "
                         "holding rev/s where rpm is expected reads so")


#: share of the shorter run's samples two runs must have in common (same time stamp,
#: position and heading) to be one recording; noise-free simulated trials of one ship share a
#: few samples of their common approach, a recording cut into two files nearly all of one
SHARED_FRACTION = 0.5


def check_split(train: Sequence[TrialData], holdout: Sequence[TrialData]) -> None:
    """Refuse a held-out run that is (part of) a training run: the same file on both sides, or
    one recording in two files (:data:`SHARED_FRACTION` of the shorter one's samples with the
    same time stamp, position and heading), which would score the fit on data it was fitted
    to."""
    for h in holdout:
        for t in train:
            if h.path and t.path and Path(h.path).resolve() == Path(t.path).resolve():
                raise DataError("given as training data (--data) and held out (--holdout): a "
                                "held-out run must be one the fit has not seen", path=h.path)
            _, ih, it = np.intersect1d(h.t_s, t.t_s, assume_unique=True, return_indices=True)
            same = ((h.north_m[ih] == t.north_m[it]) & (h.east_m[ih] == t.east_m[it])
                    & (h.psi_rad[ih] == t.psi_rad[it]))
            if int(same.sum()) >= max(2, SHARED_FRACTION * min(h.t_s.size, t.t_s.size)):
                times = h.t_s[ih][same]
                raise DataError(
                    f"shares {int(same.sum())} samples (t = {times[0]:g} to {times[-1]:g} s) "
                    f"with the training run {t.path or t.name}: one recording cannot be both "
                    "fitted and held out", path=h.path or None)

