"""Run one scenario file: build the batch, simulate, write ``trajectories.parquet`` and
``summary.json`` to the output folder.

:func:`record_run` and :func:`write_run` are shared with the replay of a campaign encounter
(:mod:`trafficsim.campaign.replay`), so both write the same run folder."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim import __version__
from trafficsim.batch import Batch, EncounterEnv, ShipSetup, build_batch
from trafficsim.colregs.decider import Decider
from trafficsim.engine import Simulation, divergence_message, earth_velocity
from trafficsim.errors import ScenarioError, SimulationError
from trafficsim.io.results import write_json, write_parquet
from trafficsim.io.scenario import Scenario, load_scenario
from trafficsim.navigation import merge_sensors
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.units import compass_deg, from_kn, to_kn


def scenario_decider(scn: Scenario, batch: Batch, record: bool = True) -> Decider | None:
    """The collision-avoidance decisions of a scenario (None when no ship decides or there is
    no other ship; the rules file it names is read all the same, so a faulty one is refused
    as ``trafficsim validate`` refuses it); ``record`` keeps every decision step for
    ``decisions.parquet``."""
    rules = None if scn.rules is None else Path(scn.path).parent / scn.rules
    if batch.pair_i.size == 0 or all(b == "keep_course" for b in batch.behaviours):
        from trafficsim.colregs import network
        from trafficsim.colregs.decider import rules_file
        from trafficsim.colregs.vocabulary import VOCABULARY

        files = {rules_file(b, rules) for b in batch.behaviours} | {rules}
        for path in sorted(str(f) for f in files if f is not None):
            network.load(path, VOCABULARY)
        return None
    decider = Decider.build(batch.behaviours, batch.pair_i, batch.pair_j, rules, scn.domain,
                            scn.visibility_nm)
    decider.record = record
    return decider


def scenario_setups(scn: Scenario, encounter: int = 0) -> tuple[list[ShipSetup], EncounterEnv]:
    """Ships and environment of a scenario in SI units."""
    from trafficsim import effects

    base_dir = Path(scn.path).parent
    ships = []
    for k, s in enumerate(scn.ships):
        spec = load_ship(s.type, base_dir)
        found = s.effects or {}
        sensors = merge_sensors(spec.get("sensors"), s.sensors)
        if found:
            spec = effects.apply_spec(spec, found)
            sensors = effects.apply_sensors(sensors, found, scn.dt_s)
        speed_kn = s.speed_kn if s.speed_kn is not None else spec["service_speed_kn"]
        route = np.array(s.route, dtype=float).reshape(-1, 2) if s.route else np.zeros((0, 2))
        ships.append(ShipSetup(name=s.name, spec=spec, encounter=encounter, north_m=s.north_m,
                               east_m=s.east_m, heading_rad=float(np.radians(s.heading_deg)),
                               speed_mps=from_kn(speed_kn), route_m=route, ship_in_encounter=k,
                               sensors=sensors, filter=s.filter, behaviour=s.behaviour,
                               effects=found))
    env = scn.environment
    enc_env = EncounterEnv()
    if env is not None:
        cur, wind = env.current, env.wind
        enc_env = EncounterEnv(
            current_speed_mps=from_kn(cur.speed_kn) if cur else 0.0,
            current_towards_rad=float(np.radians(cur.towards_deg)) if cur else 0.0,
            wind_speed_mps=wind.speed_mps if wind else 0.0,
            wind_from_rad=float(np.radians(wind.from_deg)) if wind else 0.0,
        )
    return ships, enc_env


@dataclass
class Recorder:
    """Decimated snapshots of the true state and the orders, preallocated."""

    x: np.ndarray  # (n_records, N_STATE, n)
    course_order: np.ndarray  # (n_records, n)
    rudder_cmd: np.ndarray  # (n_records, n)
    vel: np.ndarray  # (n_records, 2, n) ground velocity north/east
    t: np.ndarray  # (n_records,)
    meas: np.ndarray  # (n_records, 4, n) GNSS fix north, east, fix valid, compass heading
    est: np.ndarray  # (n_records, 6, n) the estimate used by guidance and autopilot
    est_vel: np.ndarray  # (n_records, 2, n) estimated ground velocity north/east
    tracks: np.ndarray | None = None  # (n_records, 5, m) tracks of other ships and "tracked"
    count: int = 0

    @classmethod
    def allocate(cls, n_records: int, n_ships: int, n_state: int) -> Recorder:
        z = np.zeros
        return cls(z((n_records, n_state, n_ships)), z((n_records, n_ships)),
                   z((n_records, n_ships)), z((n_records, 2, n_ships)), z(n_records),
                   np.full((n_records, 4, n_ships), np.nan), z((n_records, 6, n_ships)),
                   z((n_records, 2, n_ships)))

    def __call__(self, sim: Simulation) -> None:
        k = self.count
        x = sim.batch.x
        self.x[k] = x
        self.course_order[k] = sim.course_order_rad
        self.rudder_cmd[k] = sim.rudder_cmd_rad
        self.vel[k] = earth_velocity(x, sim.batch.env)
        self.t[k] = sim.t_s
        nav = sim.nav
        self.est[k] = x[:6] if nav is None else nav.est
        self.est_vel[k] = self.vel[k] if nav is None else nav.ground_velocity(sim.batch.env)
        if nav is not None and nav.fix is not None:
            self.meas[k] = (nav.fix.north_m, nav.fix.east_m, nav.fix.valid, nav.heading_meas)
        if sim.obs is not None:
            if self.tracks is None:
                m = sim.obs.obs.shape[0]
                self.tracks = np.full((self.t.shape[0], 5, m), np.nan)
            xp, active = sim.obs.predicted_tracks(sim.t_s)
            self.tracks[k, :4] = np.where(active[None, :], xp.T, np.nan)
            self.tracks[k, 4] = active
        self.count += 1

    def track_columns(self, sim: Simulation) -> dict[str, Any] | None:
        """One row per recorded time and directed pair: the observer's track of the target
        (predicted to the time) beside the target's true position."""
        if self.tracks is None or sim.obs is None:
            return None
        k, b, o = self.count, sim.batch, sim.obs
        m = o.obs.shape[0]
        tr = self.tracks[:k]
        true_n, true_e = self.x[:k, NORTH][:, o.tgt], self.x[:k, EAST][:, o.tgt]
        names = np.array(b.names, dtype=object)
        return {
            "t_s": np.repeat(self.t[:k], m),
            "observer": np.tile(names[o.obs], k).tolist(),
            "target": np.tile(names[o.tgt], k).tolist(),
            "tracked": (tr[:, 4] == 1.0).ravel(),
            "track_north_m": tr[:, 0].ravel(),
            "track_east_m": tr[:, 1].ravel(),
            "track_sog_kn": to_kn(np.hypot(tr[:, 2], tr[:, 3])).ravel(),
            "track_cog_deg": compass_deg(np.arctan2(tr[:, 3], tr[:, 2])).ravel(),
            "north_m": true_n.ravel(),
            "east_m": true_e.ravel(),
            "error_m": np.hypot(tr[:, 0] - true_n, tr[:, 1] - true_e).ravel(),
        }

    def columns(self, batch: Batch) -> dict[str, Any]:
        """Long-format table: one row per record and ship."""
        k, n = self.count, batch.n_ships
        x = self.x[:k]
        sog = np.hypot(self.vel[:k, 0], self.vel[:k, 1])
        cog = np.arctan2(self.vel[:k, 1], self.vel[:k, 0])
        return {
            "t_s": np.repeat(self.t[:k], n),
            "encounter": np.tile(batch.encounter, k),
            "ship": np.tile(np.array(batch.names, dtype=object), k).tolist(),
            "north_m": x[:, NORTH].ravel(),
            "east_m": x[:, EAST].ravel(),
            "heading_deg": compass_deg(x[:, PSI]).ravel(),
            "u_mps": x[:, U].ravel(),
            "v_mps": x[:, V].ravel(),
            "r_degps": np.degrees(x[:, R]).ravel(),
            "sog_kn": to_kn(sog).ravel(),
            "cog_deg": compass_deg(cog).ravel(),
            "rudder_deg": np.degrees(x[:, RUDDER]).ravel(),
            "rpm": (60.0 * x[:, RPS]).ravel(),
            "course_order_deg": compass_deg(self.course_order[:k]).ravel(),
            "rudder_cmd_deg": np.degrees(self.rudder_cmd[:k]).ravel(),
            **self._navigation_columns(),
        }

    def _navigation_columns(self) -> dict[str, np.ndarray]:
        """Measurements and the estimate beside the truth (estimate = truth without a filter)."""
        k = self.count
        est, meas = self.est[:k], self.meas[:k]
        vn, ve = self.est_vel[:k, 0], self.est_vel[:k, 1]
        return {
            "gnss_north_m": meas[:, 0].ravel(),
            "gnss_east_m": meas[:, 1].ravel(),
            "gnss_valid": meas[:, 2].ravel() == 1.0,
            "compass_heading_deg": compass_deg(meas[:, 3]).ravel(),
            "est_north_m": est[:, NORTH].ravel(),
            "est_east_m": est[:, EAST].ravel(),
            "est_heading_deg": compass_deg(est[:, PSI]).ravel(),
            "est_r_degps": np.degrees(est[:, R]).ravel(),
            "est_sog_kn": to_kn(np.hypot(vn, ve)).ravel(),
            "est_cog_deg": compass_deg(np.arctan2(ve, vn)).ravel(),
        }


def package_versions() -> dict[str, str]:
    """Versions of the interpreter and the libraries that shape the results."""
    import numba
    import pyarrow
    import shapely

    return {"trafficsim": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "numba": numba.__version__,
            "shapely": shapely.__version__, "pyarrow": pyarrow.__version__}


def record_steps(scn: Scenario) -> int:
    """Steps between records of a scenario run (its ``record_every_s``, at least one step)."""
    return max(1, round(scn.record_every_s / scn.dt_s))


#: ``on_record(recorder, sim)``: called after each record (frames drawn while a run goes)
RecordHook = Callable[[Recorder, Simulation], None]


def record_run(sim: Simulation, n_steps: int, every: int, on_record: RecordHook | None = None
               ) -> tuple[Recorder, float]:
    """Step ``sim`` ``n_steps`` times, recording every ``every`` steps (and at the start).

    Returns the recorder and the wall time of steps 2 .. n (the first step compiles any kernel
    not yet in the cache; time spent in ``on_record`` is not counted)."""
    batch = sim.batch
    # (one record more than the period gives, for the state a diverged run ends on)
    rec = Recorder.allocate(n_steps // every + 2, batch.n_ships, batch.x.shape[0])
    hook_s = 0.0

    def record() -> None:
        nonlocal hook_s
        rec(sim)
        if on_record is not None:
            t0 = time.perf_counter()
            on_record(rec, sim)
            hook_s += time.perf_counter() - t0

    record()
    wall = None
    for k in range(1, n_steps + 1):
        sim.step()
        if sim.all_diverged:  # nothing moves any more: its last state ends the record
            record()
            break
        if k % every == 0:
            record()
        if k == 1:  # the clock starts after the first step
            hook_s = 0.0
            wall = time.perf_counter()
    return rec, 0.0 if wall is None else time.perf_counter() - wall - hook_s


def raise_if_diverged(sim: Simulation, out_dir: Path) -> None:
    """After a run is written: a run whose state stopped being finite is an error naming the
    ships and the time, and where the run up to then is."""
    since = sim.first_diverged_s
    if since is not None and sim.diverged_ships is not None:
        names = [sim.batch.names[k] for k in np.flatnonzero(sim.diverged_ships)]
        raise SimulationError(f"{divergence_message(since + sim.dt, names)} (the run up to "
                              f"then is in {out_dir})")


def write_run(out_dir: Path, rec: Recorder, sim: Simulation, summary: dict[str, Any]) -> None:
    """Write a run folder: trajectories, tracks and decisions (when there are any), summary."""
    batch = sim.batch
    out_dir.mkdir(parents=True, exist_ok=True)
    write_parquet(out_dir / "trajectories.parquet", rec.columns(batch))
    tracks = rec.track_columns(sim)
    if tracks is not None:
        write_parquet(out_dir / "tracks.parquet", tracks)
    if sim.decider is not None and sim.decider.record:
        write_parquet(out_dir / "decisions.parquet", sim.decider.records(batch.names))
    write_json(out_dir / "summary.json", summary)


#: memory a run takes per ship pair, bytes (measured: 600 cargo ships, 10-100 s): per pair
#: (results and summary), and per directed pair and recorded decision step (decisions.parquet)
PAIR_BYTES, DECISION_BYTES = 2600, 900


def available_memory_bytes() -> int | None:
    """Memory the machine can give a new process without swapping: Linux's ``MemAvailable``
    (free memory plus the caches it can drop), else the free pages (None where it cannot
    tell)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def check_pair_memory(scn: Scenario, available: int | None = None) -> None:
    """Refuse, naming the ``ships`` key, a scenario whose ship pairs would not fit in memory
    (pairs grow as the square of the ships of an encounter)."""
    available = available_memory_bytes() if available is None else available
    n = len(scn.ships)
    if available is None or n < 2:
        return
    deciding = any(s.behaviour != "keep_course" for s in scn.ships)
    steps = int(scn.duration_s // scn.decision_period_s) + 1 if deciding else 0

    def need(ships: int) -> float:
        pairs = ships * (ships - 1) / 2
        return pairs * PAIR_BYTES + 2 * pairs * steps * DECISION_BYTES

    if need(n) <= available:
        return
    most = n
    while most > 1 and need(most) > available:
        most = min(most - 1, int(most * 0.99))
    raise ScenarioError(
        f"{n} ships in one encounter make {n * (n - 1) // 2:,} ship pair(s), about "
        f"{need(n) / 1e9:.1f} GB for this run, and this machine has {available / 1e9:.1f} GB "
        f"free: at most about {most} ships fit (or a shorter duration_s, a longer "
        "decision_period_s, or keep_course ships)", path=str(scn.path), key="ships")


def run_scenario(path: Path, out_dir: Path, on_record: RecordHook | None = None
                 ) -> dict[str, Any]:
    """Simulate the scenario at ``path``; write results to ``out_dir``; return the summary."""
    from trafficsim.folders import refuse_other_results

    scn = load_scenario(path)
    refuse_other_results(Path(out_dir), "run", "a run")  # (not a campaign's folder)
    check_pair_memory(scn)
    ships, env = scenario_setups(scn)
    batch = build_batch(ships, [env])
    decider = scenario_decider(scn, batch)
    sim = Simulation.start(batch, scn.dt_s, scn.seed, decider, scn.decision_period_s,
                           scn.domain, isolate_divergence=True)
    n_steps = round(scn.duration_s / scn.dt_s)
    every = record_steps(scn)
    rec, wall = record_run(sim, n_steps, every, on_record)
    header = {"scenario": scn.name, "scenario_file": str(scn.path), "seed": scn.seed,
              "duration_s": scn.duration_s, "dt_s": scn.dt_s}
    summary = run_summary(header, sim, n_steps, wall, max(sim.step_index - 1, 1),
                          every * scn.dt_s, scn.domain)
    write_run(out_dir, rec, sim, summary)
    raise_if_diverged(sim, out_dir)
    return summary


def run_summary(header: dict[str, Any], sim: Simulation, n_steps: int, wall_s: float,
                timed_steps: int, record_every_s: float, domain: str) -> dict[str, Any]:
    """``summary.json`` of a run: ``header`` (scenario, scenario_file, seed, duration_s, dt_s)
    then the outcome per pair, the ships (with what drawing them needs: particulars,
    behaviour, route) and the run's metadata."""
    b, m = sim.batch, sim.metrics
    pairs = [
        {"ship_a": b.names[i], "ship_b": b.names[j],
         "min_range_m": float(m.min_range_m[k]), "t_min_range_s": float(m.t_min_range_s[k]),
         "dcpa_m": float(m.dcpa0_m[k]), "tcpa_s": float(m.tcpa0_s[k]),
         "collision": bool(m.collision[k]), "t_collision_s": float(m.t_collision_s[k]),
         "domain_violation": bool(m.domain_violation[k]),
         "t_domain_violation_s": float(m.t_domain_violation_s[k])}
        for k, (i, j) in enumerate(zip(b.pair_i, b.pair_j, strict=True))
    ]
    x = b.x
    ships = [
        {"name": b.names[k], "type": b.types[k], "north_m": float(x[NORTH, k]),
         "east_m": float(x[EAST, k]), "heading_deg": float(compass_deg(x[PSI, k])),
         "route_done": bool(sim.route.wp_index[k] >= b.n_waypoints[k]),
         "length_m": float(b.length_m[k]), "beam_m": float(b.beam_m[k]),
         "behaviour": b.behaviours[k] if b.behaviours else "keep_course",
         "route_m": b.waypoints[k, : b.n_waypoints[k]].tolist()}
        for k in range(b.n_ships)
    ]
    return {
        **header,
        "n_ships": b.n_ships,
        "n_steps": n_steps,
        "record_every_s": record_every_s,
        "collisions": int(m.collision.sum()),
        "domain": domain,
        "domain_violations": int(m.domain_violation.sum()),
        "blind_spots": [] if sim.decider is None else sim.decider.blind_spot_report(b.names),
        "diverged_at_s": sim.first_diverged_s,
        "pairs": pairs,
        "ships": ships,
        "wall_time_s": wall_s,
        "ship_steps_per_s": b.n_ships * timed_steps / max(wall_s, 1e-9),
        "versions": package_versions(),
    }
