"""What a frame shows: ships, their true and estimated tracks, instrument fixes, tracks of
other ships, decisions and collisions, as ``(n_records, n_ships)`` arrays in SI units.

:func:`load_run` reads a run folder (``trajectories.parquet``, ``summary.json`` and, when
present, ``tracks.parquet`` and ``decisions.parquet``); :func:`live_data` wraps the arrays a
running simulation records into (views, no copies), so frames can be drawn while it runs.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.colregs import domains
from trafficsim.errors import DataError, InputError
from trafficsim.io.results import check_numeric, read_parquet
from trafficsim.render.decisions import COLUMNS as DECISION_COLUMNS
from trafficsim.render.decisions import DecisionSource, DecisionTable, LiveDecisions
from trafficsim.units import KN

TRAJECTORY_COLUMNS = ("t_s", "ship", "north_m", "east_m", "heading_deg", "u_mps", "sog_kn",
                      "cog_deg", "est_north_m", "est_east_m", "gnss_north_m", "gnss_east_m",
                      "gnss_valid")
TRACK_COLUMNS = ("t_s", "observer", "target", "tracked", "track_north_m", "track_east_m",
                 "track_sog_kn", "track_cog_deg")
SHIP_KEYS = ("name", "length_m", "beam_m", "behaviour", "route_m")
#: text columns of the tables (every other column read holds numbers)
TEXT_COLUMNS = frozenset({"ship", "observer", "target", "other", "rules", "path",
                          "decided_own_role", "decided_encounter", "decided_own_manoeuvre"})


@dataclass(frozen=True)
class Ships:
    """The ships of a run, in record order."""

    names: list[str]
    length_m: np.ndarray  # (n,)
    beam_m: np.ndarray  # (n,)
    behaviours: list[str]
    routes: list[np.ndarray]  # per ship (k, 2) waypoints north/east metres

    @property
    def n(self) -> int:
        return len(self.names)


@dataclass
class Tracks:
    """Tracks of other ships (radar and AIS) per directed pair ``(m,)``."""

    observer: np.ndarray  # (m,) int ship index
    target: np.ndarray  # (m,) int
    north_m: np.ndarray  # (R, m) track predicted to the record time
    east_m: np.ndarray
    vn_mps: np.ndarray
    ve_mps: np.ndarray
    tracked: np.ndarray  # (R, m) 1 where the observer holds a track


@dataclass
class Collisions:
    """Pairs and the time their hulls first overlapped (NaN: never; may fill while running)."""

    ship_a: np.ndarray  # (P,) int
    ship_b: np.ndarray  # (P,) int
    t_s: np.ndarray  # (P,)


@dataclass
class RunData:
    """Everything a frame may show; arrays ``(R, n)`` have one row per record."""

    name: str
    ships: Ships
    domain: str
    record_every_s: float
    t_s: np.ndarray  # (R,)
    north_m: np.ndarray  # (R, n) truth
    east_m: np.ndarray
    psi_rad: np.ndarray
    u_mps: np.ndarray  # speed through the water (sizes the speed-dependent domains)
    vn_mps: np.ndarray  # velocity over ground
    ve_mps: np.ndarray
    est_north_m: np.ndarray  # (R, n) the estimate each ship steers on
    est_east_m: np.ndarray
    gnss_north_m: np.ndarray  # (R, n) raw fix
    gnss_east_m: np.ndarray
    gnss_valid: np.ndarray  # (R, n) 1 where the fix is valid
    has_estimate: np.ndarray  # (n,) bool: the ship runs a filter (estimate is not the truth)
    collisions: Collisions
    tracks: Tracks | None = None
    decisions: DecisionSource | None = None
    duration_s: float = 0.0
    count: int = 0  # records available (grows while a run goes)


def _need_dir(run_dir: Path) -> None:
    if not run_dir.exists():
        raise InputError("no such folder (the output folder of 'trafficsim run' "
                         "or 'trafficsim replay' was expected)", path=str(run_dir))
    if not run_dir.is_dir():
        raise InputError("not a folder (the output folder of 'trafficsim run' "
                         "was expected)", path=str(run_dir))


def _table(path: Path, columns: tuple[str, ...]) -> dict[str, np.ndarray]:
    table = read_parquet(path, "table", columns, only=True)
    check_numeric(table, path, [c for c in columns if c not in TEXT_COLUMNS])
    return {c: table.column(c).to_numpy(zero_copy_only=False) for c in columns}


def _number(value: Any, path: Path, key: str, positive: bool = False) -> float:
    """A finite number of ``summary.json`` (``positive``: above 0), else a DataError."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (positive and not value > 0):
        what = "a positive number" if positive else "a finite number"
        raise DataError(f"expected {what}, got {value!r} (run it again)", path=str(path),
                        key=key)
    return float(value)


def _route(value: Any, path: Path, key: str) -> np.ndarray:
    if not isinstance(value, list) or any(
            not isinstance(p, list) or len(p) != 2 for p in value):
        raise DataError(f"expected a list of [north_m, east_m] points, got {value!r}",
                        path=str(path), key=key)
    for k, point in enumerate(value):
        for j, coordinate in enumerate(point):
            _number(coordinate, path, f"{key}[{k}][{j}]")
    return np.asarray(value, dtype=float).reshape(-1, 2)


def read_summary(run_dir: Path) -> dict[str, Any]:
    """``summary.json`` of a run folder, with every value drawing or explaining reads checked.

    Raises:
        InputError: the file is missing; DataError: it does not read as JSON, or a value is
            missing or of the wrong type (names the file and the key).
    """
    path = run_dir / "summary.json"
    if not path.is_file():
        raise InputError("missing (a complete run folder was expected)",
                         path=str(path))
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise DataError(f"unreadable ({err})", path=str(path)) from None
    if not isinstance(summary, dict):
        raise DataError(f"expected a JSON object of the run's results, got "
                        f"{type(summary).__name__} (run it again)", path=str(path))
    ships = summary.get("ships")
    if not isinstance(ships, list) or not ships or any(
            not isinstance(s, dict) or any(k not in s for k in SHIP_KEYS) for s in ships):
        raise DataError(f"ships: expected each ship's {', '.join(SHIP_KEYS)} "
                        "(written by an older trafficsim? run it again)", path=str(path))
    for k, ship in enumerate(ships):
        for key in ("name", "behaviour"):
            if not isinstance(ship[key], str) or not ship[key]:
                raise DataError(f"expected text, got {ship[key]!r}", path=str(path),
                                key=f"ships[{k}].{key}")
        for key in ("length_m", "beam_m"):
            _number(ship[key], path, f"ships[{k}].{key}", positive=True)
        _route(ship["route_m"], path, f"ships[{k}].route_m")
    for key in ("record_every_s", "duration_s"):
        if summary.get(key) is not None:
            _number(summary[key], path, key, positive=key == "record_every_s")
    for key in ("scenario", "domain"):
        if key in summary and not isinstance(summary[key], str):
            raise DataError(f"expected text, got {summary[key]!r}", path=str(path), key=key)
    if summary.get("domain", "coldwell") not in domains.DOMAINS:
        raise DataError(f"expected one of {', '.join(domains.DOMAINS)}, got "
                        f"{summary['domain']!r}", path=str(path), key="domain")
    pairs = summary.get("pairs", [])
    if not isinstance(pairs, list) or any(not isinstance(p, dict) for p in pairs):
        raise DataError("expected a list of pair objects", path=str(path), key="pairs")
    for k, pair in enumerate(pairs):
        if pair.get("collision") and pair.get("t_collision_s") is not None:
            _number(pair["t_collision_s"], path, f"pairs[{k}].t_collision_s")
    return summary


def load_run(run_dir: str | Path) -> RunData:
    """Read a run folder.

    Raises:
        InputError: no such folder, no ``trajectories.parquet``, or files that are damaged or
            lack what drawing needs (each names the file).
    """
    run_dir = Path(run_dir)
    _need_dir(run_dir)
    traj_path = run_dir / "trajectories.parquet"
    if not traj_path.is_file():
        raise InputError("no trajectories.parquet here (the output folder of "
                         "'trafficsim run' or 'trafficsim replay' was expected)",
                         path=str(run_dir))
    summary = read_summary(run_dir)
    summary_path = run_dir / "summary.json"
    info = summary["ships"]
    names = [str(s["name"]) for s in info]
    n = len(names)
    cols = _table(traj_path, TRAJECTORY_COLUMNS)
    rows = cols["t_s"].shape[0]
    ship_col = np.asarray(cols["ship"], dtype=object)
    if rows == 0 or rows % n or np.any(ship_col.reshape(-1, n) != np.array(names, dtype=object)):
        raise DataError(f"rows are not one per record and ship in the order of "
                        f"summary.json's ships ({', '.join(names)})", path=str(traj_path))

    def grid(name: str) -> np.ndarray:
        return np.asarray(cols[name], dtype=float).reshape(-1, n)

    t_s = grid("t_s")[:, 0]
    sog, cog = grid("sog_kn") * KN, np.radians(grid("cog_deg"))
    north, east = grid("north_m"), grid("east_m")
    est_n, est_e = grid("est_north_m"), grid("est_east_m")
    ships = Ships(names, np.array([float(s["length_m"]) for s in info]),
                  np.array([float(s["beam_m"]) for s in info]),
                  [str(s["behaviour"]) for s in info],
                  [np.asarray(s["route_m"], dtype=float).reshape(-1, 2) for s in info])
    every = summary.get("record_every_s")
    if every is None:
        every = float(t_s[1] - t_s[0]) if t_s.shape[0] > 1 else 1.0
    pairs = summary.get("pairs", [])
    index = {name: k for k, name in enumerate(names)}
    if len(index) < n:
        raise DataError("two ships of the same name", path=str(summary_path), key="ships")

    def ship_of(pair: object, key: str) -> int:
        name = pair.get(key) if isinstance(pair, dict) else None
        if name not in index:
            raise DataError(f"pairs: {key} {name!r} is not one of the ships "
                            f"({', '.join(names)})", path=str(run_dir / "summary.json"))
        return index[name]

    collisions = Collisions(
        np.array([ship_of(p, "ship_a") for p in pairs], dtype=np.int64),
        np.array([ship_of(p, "ship_b") for p in pairs], dtype=np.int64),
        np.array([p["t_collision_s"] if p.get("collision") and p.get("t_collision_s")
                  is not None else np.nan for p in pairs], dtype=float))
    data = RunData(
        name=str(summary.get("scenario", run_dir.name)), ships=ships,
        domain=str(summary.get("domain", "coldwell")), record_every_s=float(every), t_s=t_s,
        north_m=north, east_m=east, psi_rad=np.radians(grid("heading_deg")),
        u_mps=grid("u_mps"), vn_mps=sog * np.cos(cog), ve_mps=sog * np.sin(cog),
        est_north_m=est_n, est_east_m=est_e, gnss_north_m=grid("gnss_north_m"),
        gnss_east_m=grid("gnss_east_m"),
        gnss_valid=np.asarray(cols["gnss_valid"], dtype=bool).reshape(-1, n),
        has_estimate=np.any(np.hypot(est_n - north, est_e - east) > 1e-6, axis=0),
        collisions=collisions,
        duration_s=float(t_s[-1] if summary.get("duration_s") is None else summary["duration_s"]),
        count=t_s.shape[0])
    if (run_dir / "tracks.parquet").is_file():
        data.tracks = _tracks(run_dir / "tracks.parquet", index, t_s.shape[0])
    if (run_dir / "decisions.parquet").is_file():
        try:
            data.decisions = DecisionTable(_table(run_dir / "decisions.parquet",
                                                  DECISION_COLUMNS))
        except DataError:
            raise
        except ValueError as err:  # (rows out of time order)
            raise DataError(str(err), path=str(run_dir / "decisions.parquet"), key="t_s") from None
    return data


def _tracks(path: Path, index: dict[str, int], n_records: int) -> Tracks:
    cols = _table(path, TRACK_COLUMNS)
    rows = cols["t_s"].shape[0]
    if rows % n_records:
        raise DataError("expected one row per record and observer-target pair",
                        path=str(path))
    m = rows // n_records
    try:
        obs = np.array([index[str(s)] for s in cols["observer"][:m]], dtype=np.int64)
        tgt = np.array([index[str(s)] for s in cols["target"][:m]], dtype=np.int64)
    except KeyError as err:
        raise DataError(f"unknown ship {err}", path=str(path)) from None

    def grid(name: str) -> np.ndarray:
        return np.asarray(cols[name], dtype=float).reshape(n_records, m)

    sog, cog = grid("track_sog_kn") * KN, np.radians(grid("track_cog_deg"))
    return Tracks(obs, tgt, grid("track_north_m"), grid("track_east_m"), sog * np.cos(cog),
                  sog * np.sin(cog), np.asarray(cols["tracked"], dtype=bool).reshape(n_records, m))


def live_data(rec: Any, sim: Any, name: str, record_every_s: float, duration_s: float
              ) -> RunData:
    """Views of a running simulation's recorder (:class:`trafficsim.run.Recorder`) and state
    (:class:`trafficsim.engine.Simulation`); ``count`` is set by the caller per frame."""
    from trafficsim.ships.base import EAST, NORTH, PSI, U

    b = sim.batch
    ships = Ships(list(b.names), b.length_m.copy(), b.beam_m.copy(),
                  list(b.behaviours) or ["keep_course"] * b.n_ships,
                  [b.waypoints[k, : b.n_waypoints[k]].copy() for k in range(b.n_ships)])
    m = sim.metrics
    data = RunData(
        name=name, ships=ships, domain=m.domain, record_every_s=record_every_s, t_s=rec.t,
        north_m=rec.x[:, NORTH], east_m=rec.x[:, EAST], psi_rad=rec.x[:, PSI],
        u_mps=rec.x[:, U], vn_mps=rec.vel[:, 0], ve_mps=rec.vel[:, 1],
        est_north_m=rec.est[:, NORTH], est_east_m=rec.est[:, EAST],
        gnss_north_m=rec.meas[:, 0], gnss_east_m=rec.meas[:, 1], gnss_valid=rec.meas[:, 2],
        has_estimate=np.array([f != "none" for f in b.filters], dtype=bool),
        collisions=Collisions(b.pair_i, b.pair_j, m.t_collision_s), duration_s=duration_s,
        count=rec.count)
    if rec.tracks is not None and sim.obs is not None:
        tr = rec.tracks
        data.tracks = Tracks(sim.obs.obs, sim.obs.tgt, tr[:, 0], tr[:, 1], tr[:, 2], tr[:, 3],
                             tr[:, 4])
    if sim.decider is not None and sim.decider.record:
        data.decisions = LiveDecisions(sim.decider, b.names)
    return data
