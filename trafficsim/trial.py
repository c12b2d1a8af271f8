"""``trafficsim trial``: one standard manoeuvre of one ship, written as trial data and indices."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trafficsim.io.results import write_csv, write_json
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import load_ship


def run_trial(ship: str, manoeuvre: str, rudder_deg: float | None, heading_deg: float | None,
              port: bool, speed_kn: float | None, dt_s: float | None, out_dir: Path
              ) -> tuple[dict[str, float], dict[str, dict[str, Any]]]:
    """Run the manoeuvre; write ``trial.csv`` (trial-data format) and ``indices.json``."""
    spec = load_ship(ship)
    if manoeuvre == "turning":
        rudder = rudder_deg if rudder_deg is not None else 35.0
        track, indices = manoeuvres.turning_circle(spec, -rudder if port else rudder,
                                                   speed_kn, dt_s)
    elif manoeuvre == "zigzag":
        rudder = rudder_deg if rudder_deg is not None else 10.0
        track, indices = manoeuvres.zigzag(spec, rudder, heading_deg, speed_kn, dt_s)
    else:
        track, indices = manoeuvres.crash_stop(spec, speed_kn, dt_s)
    criteria = manoeuvres.imo_criteria(manoeuvre, indices)
    write_csv(out_dir / "trial.csv", track)
    write_json(out_dir / "indices.json", {"ship": spec["name"], "manoeuvre": manoeuvre,
                                          "indices": indices, "imo_msc137": criteria})
    return indices, criteria
