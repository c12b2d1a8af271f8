"""Run folders built by hand, with exactly the files and columns ``trafficsim run`` writes, so a
test knows where every ship is."""

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from trafficsim.io.results import write_json, write_parquet
from trafficsim.units import KN


@dataclass
class Ship:
    name: str
    north_m: float
    east_m: float
    heading_deg: float
    speed_kn: float = 0.0
    length_m: float = 100.0
    beam_m: float = 20.0
    route_m: list = field(default_factory=list)


def write_run(folder: Path, ships: Sequence[Ship], n_records: int, every_s: float = 5.0,
              name: str = "synthetic", turn_degps: float = 0.0) -> Path:
    """Ships sailing straight (or turning at ``turn_degps``) at constant speed; estimates a
    few metres off the truth for the first ship, GNSS fixes scattered around it."""
    t = np.arange(n_records) * every_s
    n = len(ships)
    rng = np.random.default_rng(0)
    cols: dict[str, list] = {k: [] for k in (
        "t_s", "encounter", "ship", "north_m", "east_m", "heading_deg", "u_mps", "v_mps",
        "r_degps", "sog_kn", "cog_deg", "rudder_deg", "rpm", "course_order_deg",
        "rudder_cmd_deg", "gnss_north_m", "gnss_east_m", "gnss_valid", "compass_heading_deg",
        "est_north_m", "est_east_m", "est_heading_deg", "est_r_degps", "est_sog_kn",
        "est_cog_deg")}
    for k in range(n_records):
        for j, s in enumerate(ships):
            psi = np.radians(s.heading_deg + turn_degps * t[k])
            v = s.speed_kn * KN
            # straight: integrate; turning: the position of the exact circle
            if turn_degps == 0.0:
                north = s.north_m + v * t[k] * np.cos(psi)
                east = s.east_m + v * t[k] * np.sin(psi)
            else:
                w = np.radians(turn_degps)
                p0 = np.radians(s.heading_deg)
                north = s.north_m + v / w * (np.sin(psi) - np.sin(p0))
                east = s.east_m - v / w * (np.cos(psi) - np.cos(p0))
            off = 3.0 * rng.standard_normal(2) if j == 0 else np.zeros(2)
            gnss = 5.0 * rng.standard_normal(2)
            heading = np.degrees(psi) % 360.0
            for key, value in (
                    ("t_s", t[k]), ("encounter", 0), ("ship", s.name), ("north_m", north),
                    ("east_m", east), ("heading_deg", heading), ("u_mps", v), ("v_mps", 0.0),
                    ("r_degps", turn_degps), ("sog_kn", s.speed_kn), ("cog_deg", heading),
                    ("rudder_deg", 0.0), ("rpm", 60.0), ("course_order_deg", heading),
                    ("rudder_cmd_deg", 0.0), ("gnss_north_m", north + gnss[0]),
                    ("gnss_east_m", east + gnss[1]), ("gnss_valid", True),
                    ("compass_heading_deg", heading), ("est_north_m", north + off[0]),
                    ("est_east_m", east + off[1]), ("est_heading_deg", heading),
                    ("est_r_degps", turn_degps), ("est_sog_kn", s.speed_kn),
                    ("est_cog_deg", heading)):
                cols[key].append(value)
    folder.mkdir(parents=True, exist_ok=True)
    write_parquet(folder / "trajectories.parquet",
                  {k: (v if k == "ship" else np.asarray(v)) for k, v in cols.items()})
    pairs = [{"ship_a": a.name, "ship_b": b.name, "min_range_m": 1000.0, "t_min_range_s": 0.0,
              "dcpa_m": 1000.0, "tcpa_s": 0.0, "collision": False, "t_collision_s": None,
              "domain_violation": False, "t_domain_violation_s": None}
             for i, a in enumerate(ships) for b in ships[i + 1:]]
    write_json(folder / "summary.json", {
        "scenario": name, "scenario_file": "none", "seed": 0,
        "duration_s": float(t[-1]), "dt_s": 1.0, "n_ships": n, "n_steps": int(t[-1]),
        "record_every_s": every_s, "collisions": 0, "domain": "coldwell",
        "domain_violations": 0, "blind_spots": [], "pairs": pairs,
        "ships": [{"name": s.name, "type": "cargo", "north_m": s.north_m, "east_m": s.east_m,
                   "heading_deg": s.heading_deg, "route_done": False, "length_m": s.length_m,
                   "beam_m": s.beam_m, "behaviour": "keep_course", "route_m": s.route_m}
                  for s in ships]})
    return folder


@pytest.fixture
def synthetic_run(tmp_path: Path):
    """``synthetic_run(ships, n_records, ...)`` writes a run folder; returns its path."""
    count = 0

    def make(ships: Sequence[Ship], n_records: int = 10, **kw) -> Path:
        nonlocal count
        count += 1
        return write_run(tmp_path / f"run{count}", ships, n_records, **kw)

    return make


TINY_SCENARIO = """schema_version: 1
name: tiny
duration_s: {duration}
seed: 3
record_every_s: 5.0
ships:
  - name: own
    type: cargo
    north_m: -3000
    east_m: 0
    heading_deg: 0
    speed_kn: 12
    route: [[6000, 0]]
    filter: pv
    sensors:
      gnss: {{sigma_m: 3.0}}
      compass: {{kind: gyro, sigma_deg: 0.3}}
      radar: {{}}
      ais: {{}}
  - name: other
    type: cargo
    north_m: 0
    east_m: 3000
    heading_deg: 270
    speed_kn: 12
    behaviour: keep_course
    sensors:
      radar: {{}}
      ais: {{}}
"""


@pytest.fixture
def tiny_scenario(tmp_path: Path):
    """A short crossing with instruments, radar, AIS and decisions; returns its path."""

    def make(duration_s: float = 400.0) -> Path:
        path = tmp_path / "tiny.yaml"
        path.write_text(TINY_SCENARIO.format(duration=duration_s))
        return path

    return make
