"""Trial data: measured (or simulated) manoeuvres as one struct-of-arrays record, SI and radians.

Two file formats are read into the same :class:`TrialData`:

* the **trial-data CSV** of this project (what ``trafficsim trial`` writes): columns
  ``t_s, north_m, east_m, heading_deg, rudder_deg, rpm`` required; ``u_mps, v_mps, r_degps,
  sog_kn, cog_deg, wind_speed_mps, wind_from_deg`` optional; any other numeric column (e.g. the
  ``gnss_*`` and ``est_*`` columns of ``trafficsim trial --sensors``) is kept in
  :attr:`TrialData.extra` under its own name. Conventions: NED earth frame, heading 0 = north
  clockwise, positive rudder turns to starboard, ``rpm`` signed (negative = astern), wind
  direction = where the true wind blows FROM (0 = from north).
* the **FRT-DS-ESSO** free-running model tests of the Esso Osaka model (Osaka University; files
  ``data/{turning,zigzag,random,berthing}/*.csv``, 10 Hz), mapped as

  ================================  ================  ==========================================
  FRT-DS-ESSO column                 field             note
  ================================  ================  ==========================================
  ``t [s]``                          ``t_s``
  ``x_position_mid [m]``             ``north_m``       x0 axis taken as north
  ``y_position_mid [m]``             ``east_m``        y0 axis taken as east
  ``psi_hat [rad]``                  ``psi_rad``       from x0 towards y0
  ``u_velo [m/s]``                   ``u_mps``         midship, body x forward
  ``vm_velo [m/s]``                  ``v_mps``         midship, body y starboard
  ``r_angvelo [rad/s]``              ``r_radps``
  ``n_prop [rps]``                   ``rps``
  ``delta_rudder [rad]``             ``rudder_rad``    positive turns to starboard
  ``wind_velo_true [m/s]``           ``wind_speed_mps``
  ``wind_dir_true [rad]``            ``wind_from_rad`` direction the wind blows from, from x0
  ``wind_velo_relative_mid [m/s]``   ``extra``         ``apparent_wind_speed_mps``
  ``wind_dir_relative_mid [rad]``    ``extra``         ``apparent_wind_from_rad`` (from the bow,
                                                       positive from starboard)
  ================================  ================  ==========================================

  The frames were checked on the data (every file): rotating the position derivative by
  ``psi`` as a clockwise-from-x0 heading reproduces ``(u_velo, vm_velo)`` (2-s central
  differences agree to 0.005-0.01 m/s RMS; with the opposite handedness the error is 3-5 times
  larger), ``d psi/dt`` equals ``+r_angvelo``, a positive rudder gives a positive yaw rate, and
  the relative wind columns follow from the true wind (read as blowing FROM ``wind_dir_true``)
  and the ship's velocity to rounding. So ``O0-x0y0`` with ``psi`` from x0 to y0 is a
  right-handed frame with z down: x0 -> north, y0 -> east is exact, and every quantity keeps its
  sign. Rows that are entirely empty (some files end with them) are dropped and counted.

Missing values (empty cells, ``nan``) are kept as NaN and counted per column in
:attr:`TrialData.missing`; nothing is interpolated here (pre-processing treats NaN as a missing
measurement). Malformed files raise :class:`~trafficsim.errors.DataError` naming the file, the
line and the column; so do a file without a header row (empty, or blank lines only) and a true
wind speed column without its direction column or the other way round.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.errors import DataError

#: largest trial file read (bytes); real trials at 10 Hz for an hour are ~20 MB
MAX_BYTES = 200_000_000

REQUIRED_CSV = ("t_s", "north_m", "east_m", "heading_deg", "rudder_deg", "rpm")
OPTIONAL_CSV = ("u_mps", "v_mps", "r_degps", "sog_kn", "cog_deg", "wind_speed_mps",
                "wind_from_deg")
_KNOT = 1852.0 / 3600.0

#: FRT-DS-ESSO header -> TrialData field (``None``: kept in ``extra`` under the given name)
FRT_COLUMNS: dict[str, tuple[str, str | None]] = {
    "t [s]": ("t_s", None),
    "x_position_mid [m]": ("north_m", None),
    "y_position_mid [m]": ("east_m", None),
    "psi_hat [rad]": ("psi_rad", None),
    "u_velo [m/s]": ("u_mps", None),
    "vm_velo [m/s]": ("v_mps", None),
    "r_angvelo [rad/s]": ("r_radps", None),
    "n_prop [rps]": ("rps", None),
    "delta_rudder [rad]": ("rudder_rad", None),
    "wind_velo_true [m/s]": ("wind_speed_mps", None),
    "wind_dir_true [rad]": ("wind_from_rad", None),
    "wind_velo_relative_mid [m/s]": ("extra", "apparent_wind_speed_mps"),
    "wind_dir_relative_mid [rad]": ("extra", "apparent_wind_from_rad"),
}
FRT_REQUIRED = ("t [s]", "x_position_mid [m]", "y_position_mid [m]", "psi_hat [rad]",
                "n_prop [rps]", "delta_rudder [rad]")


@dataclass(frozen=True)
class TrialData:
    """One run of trial data, ``(N,)`` float arrays in time order, SI and radians.

    Attributes:
        name: run name (file stem unless given).
        path: file it was read from ("" if built in memory).
        t_s: time, s, strictly increasing.
        north_m, east_m: reference-point (midship) position, m, NED.
        psi_rad: heading, rad, 0 = north, clockwise (as recorded; not unwrapped).
        rudder_rad: measured rudder angle, rad, positive turns to starboard.
        rps: measured propeller speed, rev/s, negative astern.
        u_mps, v_mps, r_radps: body velocities if recorded (else None): surge, sway (starboard),
            yaw rate (starboard), relative to the water as far as the source knows.
        sog_mps, cog_rad: speed and course over ground if recorded.
        wind_speed_mps, wind_from_rad: true wind speed and the direction it blows from.
        extra: other numeric columns by name, ``(N,)`` each, unconverted.
        missing: NaN count per column present (field names), for the report.
        dropped_rows: entirely empty rows dropped while reading.
    """

    name: str
    path: str
    t_s: np.ndarray
    north_m: np.ndarray
    east_m: np.ndarray
    psi_rad: np.ndarray
    rudder_rad: np.ndarray
    rps: np.ndarray
    u_mps: np.ndarray | None = None
    v_mps: np.ndarray | None = None
    r_radps: np.ndarray | None = None
    sog_mps: np.ndarray | None = None
    cog_rad: np.ndarray | None = None
    wind_speed_mps: np.ndarray | None = None
    wind_from_rad: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    missing: dict[str, int] = field(default_factory=dict)
    dropped_rows: int = 0

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t_s.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) if self.n > 1 else 0.0

    @property
    def dt_s(self) -> float:
        """Median sampling interval, s."""
        return float(np.median(np.diff(self.t_s))) if self.n > 1 else float("nan")

    @property
    def has_wind(self) -> bool:
        return self.wind_speed_mps is not None and self.wind_from_rad is not None

    def arrays(self) -> dict[str, np.ndarray]:
        """The time-series fields present (not None), by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name in SERIES and getattr(self, f.name) is not None}

    def take(self, index: np.ndarray | slice) -> TrialData:
        """The same run restricted to ``index`` (a slice or an index/boolean array)."""
        changes: dict[str, Any] = {k: v[index] for k, v in self.arrays().items()}
        changes["extra"] = {k: v[index] for k, v in self.extra.items()}
        return _with_missing(replace(self, **changes))

    def with_series(self, **series: np.ndarray | None) -> TrialData:
        """A copy with some series replaced (same length)."""
        for key, value in series.items():
            if key not in SERIES:
                raise KeyError(key)
            if value is not None and np.shape(value) != (self.n,):
                raise ValueError(f"{key}: expected shape ({self.n},), got {np.shape(value)}")
        return _with_missing(replace(self, **series))

    def nan_report(self) -> dict[str, Any]:
        """Samples, duration, and the NaN count of each column that has any."""
        return {"samples": self.n, "duration_s": self.duration_s, "dt_s": self.dt_s,
                "dropped_empty_rows": self.dropped_rows,
                "nan_counts": {k: v for k, v in self.missing.items() if v}}

    def to_csv_columns(self) -> dict[str, np.ndarray]:
        """Columns of the trial-data CSV format (degrees, rpm, knots at the edge)."""
        cols = {"t_s": self.t_s, "north_m": self.north_m, "east_m": self.east_m,
                "heading_deg": np.degrees(self.psi_rad), "rudder_deg": np.degrees(self.rudder_rad),
                "rpm": self.rps * 60.0}
        optional = {"u_mps": self.u_mps, "v_mps": self.v_mps,
                    "r_degps": None if self.r_radps is None else np.degrees(self.r_radps),
                    "sog_kn": None if self.sog_mps is None else self.sog_mps / _KNOT,
                    "cog_deg": None if self.cog_rad is None else np.degrees(self.cog_rad),
                    "wind_speed_mps": self.wind_speed_mps,
                    "wind_from_deg": (None if self.wind_from_rad is None
                                      else np.degrees(self.wind_from_rad))}
        cols.update({k: v for k, v in optional.items() if v is not None})
        return cols


#: field names of the time series (``(N,)`` arrays) of :class:`TrialData`
SERIES = ("t_s", "north_m", "east_m", "psi_rad", "rudder_rad", "rps", "u_mps", "v_mps",
          "r_radps", "sog_mps", "cog_rad", "wind_speed_mps", "wind_from_rad")


def read_trial(path: str | Path, name: str | None = None,
               columns: Mapping[str, str] | None = None) -> TrialData:
    """Read a trial-data CSV or an FRT-DS-ESSO file (told apart by the header row).

    ``columns`` (trial-data CSV only) maps trial-data column names to other columns of the
    file to read them from, e.g. ``{"north_m": "gnss_fix_north_m"}`` to identify from the raw
    receiver fixes that ``trafficsim trial --sensors`` records beside the truth (the column it
    replaces is kept in ``extra`` as ``<name>_replaced``).
    """
    header, rows, lines = _read_table(Path(path))
    if "x_position_mid [m]" in header:
        if columns:
            raise DataError("column mapping applies to trial-data CSV files, not FRT-DS-ESSO "
                            "files", path=str(path))
        return _frt(Path(path), header, rows, lines, name)
    return _trial_csv(Path(path), _renamed(str(path), header, columns), rows, lines, name)


def read_trial_csv(path: str | Path, name: str | None = None,
                   columns: Mapping[str, str] | None = None) -> TrialData:
    """Read a file in the trial-data CSV format (module docstring; ``columns`` as in
    :func:`read_trial`)."""
    header, rows, lines = _read_table(Path(path))
    return _trial_csv(Path(path), _renamed(str(path), header, columns), rows, lines, name)


def _renamed(path: str, header: list[str], columns: Mapping[str, str] | None) -> list[str]:
    """Header with ``columns`` (trial-data name -> file column) applied."""
    if not columns:
        return header
    known = set(REQUIRED_CSV) | set(OPTIONAL_CSV)
    out = list(header)
    for target, source in columns.items():
        if target not in known:
            raise DataError(f"cannot map '{target}': expected one of the trial-data columns "
                            f"{', '.join((*REQUIRED_CSV, *OPTIONAL_CSV))}", path=path)
        if source not in header:
            raise DataError(f"column '{source}' (to read as {target}) not in the file; its "
                            f"columns: {', '.join(header)}", path=path, line=1)
    for target, source in columns.items():
        if target in out:
            out[out.index(target)] = f"{target}_replaced"
        out[header.index(source)] = target
    return out


def read_frt_ds_esso(path: str | Path, name: str | None = None) -> TrialData:
    """Read one FRT-DS-ESSO run (module docstring for the column mapping and frames)."""
    header, rows, lines = _read_table(Path(path))
    return _frt(Path(path), header, rows, lines, name)


def from_arrays(name: str, columns: Mapping[str, Any]) -> TrialData:
    """A run from in-memory trial-data CSV columns (the format of ``trafficsim trial``)."""
    header = list(columns)
    data = np.column_stack([np.asarray(columns[k], dtype=float) for k in header])
    return _trial_csv(Path(name), header, data, np.arange(2, data.shape[0] + 2), name,
                      path_text="")


def _rows(reader: Any, path: Path) -> Any:
    """The rows of ``reader``; a malformed one (a stray quote) is a located data error."""
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as err:
            raise DataError(f"not a CSV row ({err})", path=str(path),
                            line=reader.line_num) from None
        yield row


def _read_table(path: Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Header, ``(N, k)`` float table (empty cell or 'nan' -> NaN) and each row's file line."""
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise DataError(f"file is {size} bytes, larger than the {MAX_BYTES} allowed",
                            path=str(path))
        text = path.read_bytes().decode("utf-8-sig")
    except FileNotFoundError:
        raise DataError("trial data file not found", path=str(path)) from None
    except IsADirectoryError:
        raise DataError("expected a trial data file, got a folder", path=str(path)) from None
    except UnicodeDecodeError as err:
        raise DataError(f"not a text file ({err.reason})", path=str(path)) from None
    except OSError as err:
        raise DataError(f"cannot read ({err.strerror})", path=str(path)) from None
    # universal newlines: CR LF, LF and old Mac CR line ends alike
    reader = csv.reader(io.StringIO(text, newline=None))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise DataError("empty file; expected a header row", path=str(path), line=1) from None
    except csv.Error as err:
        raise DataError(f"not a CSV table ({err})", path=str(path), line=1) from None
    if not any(header):  # a blank first line (or only commas): no column names
        if all(not any(cell.strip() for cell in row) for row in _rows(reader, path)):
            raise DataError("empty file (blank lines only); expected a header row",
                            path=str(path), line=1)
        raise DataError("expected a header row of column names, got a blank line",
                        path=str(path), line=1)
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DataError(f"duplicate column(s) {', '.join(dup)}", path=str(path), line=1)
    values: list[list[float]] = []
    lines: list[int] = []
    for row in _rows(reader, path):
        line = reader.line_num
        if not row or all(not cell.strip() for cell in row):
            values.append([np.nan] * len(header))
            lines.append(line)
            continue
        if len(row) != len(header):
            raise DataError(f"expected {len(header)} values as in the header, got {len(row)}",
                            path=str(path), line=line)
        out = []
        for name, cell in zip(header, row, strict=True):
            cell = cell.strip()
            if not cell or cell.lower() == "nan":
                out.append(np.nan)
                continue
            try:
                out.append(float(cell))
            except ValueError:
                raise DataError(f"expected a number, got {cell[:40]!r}", path=str(path),
                                line=line, key=name) from None
        values.append(out)
        lines.append(line)
    table = np.array(values, dtype=float).reshape(-1, len(header))
    return header, table, np.array(lines, dtype=int)


def _clean_rows(path: str | None, table: np.ndarray, lines: np.ndarray, time_col: int
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """Drop entirely empty rows; check time is finite and strictly increasing."""
    empty = np.all(np.isnan(table), axis=1)
    table, lines = table[~empty], lines[~empty]
    if table.shape[0] < 2:
        raise DataError("fewer than two data rows", path=path)
    t = table[:, time_col]
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        got = "an infinite value" if np.isinf(t[i]) else "an empty cell or nan"
        raise DataError(f"expected a finite time in every row, got {got}", path=path,
                        line=int(lines[i]), key="time")
    back = np.diff(t) <= 0.0
    if back.any():
        i = int(np.argmax(back)) + 1
        raise DataError(f"time must increase from row to row, got {t[i]:g} after {t[i - 1]:g}",
                        path=path, line=int(lines[i]), key="time")
    return table, lines, int(empty.sum())


def _check_paired(path: str | None, header: Sequence[str], speed: str, direction: str
                  ) -> None:
    """Refuse a true wind speed column without its direction column or the other way round
    (alone, either would be read as no wind at all)."""
    for have, lack in ((speed, direction), (direction, speed)):
        if have in header and lack not in header:
            raise DataError(f"missing column, needed with {have}: the true wind is its speed "
                            "and the direction it blows from together (give both columns or "
                            "neither)", path=path, line=1, key=lack)


def _trial_csv(path: Path, header: Sequence[str], table: np.ndarray, lines: np.ndarray,
               name: str | None, path_text: str | None = None) -> TrialData:
    where = str(path) if path_text is None else path_text
    missing = [c for c in REQUIRED_CSV if c not in header]
    if missing:
        raise DataError(f"missing column(s) {', '.join(missing)}; a trial-data CSV needs "
                        f"{', '.join(REQUIRED_CSV)} (optional: {', '.join(OPTIONAL_CSV)}) or "
                        "the FRT-DS-ESSO columns", path=where or None, line=1)
    _check_paired(where or None, header, "wind_speed_mps", "wind_from_deg")
    table, lines, dropped = _clean_rows(where or None, table, lines, header.index("t_s"))
    col = {h: table[:, i] for i, h in enumerate(header)}

    def opt(key: str, scale: float = 1.0) -> np.ndarray | None:
        return col[key] * scale if key in col else None

    rad = np.pi / 180.0
    known = set(REQUIRED_CSV) | set(OPTIONAL_CSV)
    trial = TrialData(
        name=name or path.stem, path=where,
        t_s=col["t_s"], north_m=col["north_m"], east_m=col["east_m"],
        psi_rad=col["heading_deg"] * rad, rudder_rad=col["rudder_deg"] * rad,
        rps=col["rpm"] / 60.0,
        u_mps=opt("u_mps"), v_mps=opt("v_mps"), r_radps=opt("r_degps", rad),
        sog_mps=opt("sog_kn", _KNOT), cog_rad=opt("cog_deg", rad),
        wind_speed_mps=opt("wind_speed_mps"), wind_from_rad=opt("wind_from_deg", rad),
        extra={h: col[h] for h in header if h not in known}, dropped_rows=dropped)
    return _with_missing(trial)


def _frt(path: Path, header: Sequence[str], table: np.ndarray, lines: np.ndarray,
         name: str | None) -> TrialData:
    missing = [c for c in FRT_REQUIRED if c not in header]
    if missing:
        raise DataError(f"missing FRT-DS-ESSO column(s) {', '.join(repr(m) for m in missing)}",
                        path=str(path), line=1)
    _check_paired(str(path), header, "wind_velo_true [m/s]", "wind_dir_true [rad]")
    table, lines, dropped = _clean_rows(str(path), table, lines, header.index("t [s]"))
    series: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for i, h in enumerate(header):
        target, extra_name = FRT_COLUMNS.get(h, ("extra", h))
        if target == "extra":
            extra[extra_name or h] = table[:, i]
        else:
            series[target] = table[:, i]
    trial = TrialData(name=name or path.stem, path=str(path), extra=extra,
                      dropped_rows=dropped, **series)
    return _with_missing(trial)


def _with_missing(trial: TrialData) -> TrialData:
    counts = {k: int(np.count_nonzero(np.isnan(v))) for k, v in trial.arrays().items()}
    counts.update({k: int(np.count_nonzero(np.isnan(v))) for k, v in trial.extra.items()})
    return replace(trial, missing=counts)
