"""Rogue ships and restricted visibility, end to end (``trafficsim run`` on scenario files).

The stand-on ship of ``scenarios/rogue_give_way.yaml`` must avoid a give-way ship that keeps its
course, turns to port, or acts late (Rule 17(a)(ii), 17(b)); in restricted visibility (Rule 19)
no ship takes a role and the own ship alters to starboard for a ship forward of the beam.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.conftest import SCENARIOS
from trafficsim.run import run_scenario

NM = 1852.0


def _run(tmp_path: Path, source: Path, replace: dict[str, str]) -> tuple[dict, dict]:
    text = source.read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    scenario = tmp_path / source.name
    scenario.write_text(text)
    summary = run_scenario(scenario, tmp_path / "out")
    table = pq.read_table(tmp_path / "out" / "decisions.parquet")
    return summary, {c: np.asarray(table.column(c).to_pylist()) for c in table.column_names}


@pytest.mark.parametrize("rogue", ["keep_course", "turn_port", "late_action"])
def test_stand_on_ship_avoids_a_rogue_give_way_ship(tmp_path: Path, rogue: str) -> None:
    summary, dec = _run(tmp_path, SCENARIOS / "rogue_give_way.yaml",
                        {"behaviour: keep_course": f"behaviour: {rogue}"})
    pair = summary["pairs"][0]
    assert not pair["collision"]
    assert pair["min_range_m"] >= 0.5 * NM, pair
    cargo = dec["ship"] == "cargo"
    assert set(dec["decided_own_role"][cargo]) >= {"stand_on"}
    if rogue == "keep_course":  # the stand-on ship had to act by her own manoeuvre
        acted = cargo & np.isin(dec["decided_own_manoeuvre"], ["reduce_speed", "alter_course",
                                                               "emergency"])
        assert acted.any()
        first = np.flatnonzero(acted)[0]
        assert "stand_on_act" in dec["path"][first]
        # ... only after watching: the give-way ship's course unchanged, domain entry near
        assert dec["time_to_domain_min"][first] <= 10.0
        assert dec["other_course_change_deg"][first] < 10.0
    if rogue == "turn_port":  # the rogue (heading 090) gave way to port: by 30 deg or more
        tanker = (dec["ship"] == "tanker") & (dec["decided_own_manoeuvre"] == "alter_course")
        assert tanker.any()
        assert 0.0 <= dec["course_order_deg"][np.flatnonzero(tanker)[0]] <= 60.0 + 1e-6


def test_restricted_visibility_has_no_roles_and_turns_to_starboard(tmp_path: Path) -> None:
    """Imazu case 1 (head-on) in 1 NM visibility: Rule 19 mode, not Rule 14."""
    summary, dec = _run(tmp_path, SCENARIOS / "imazu" / "imazu01.yaml",
                        {"record_every_s: 10.0": "record_every_s: 10.0\nvisibility_nm: 1.0"})
    own = dec["ship"] == "own"
    assert set(dec["decided_own_role"][own]) == {"no_role"}
    assert "restricted_visibility" in set(dec["decided_encounter"][own])
    alter = own & (dec["decided_own_manoeuvre"] == "alter_course")
    assert alter.any()
    first = dec["course_order_deg"][np.flatnonzero(alter)[0]]
    assert 0.0 < first < 180.0  # Rule 19(d)(i): not to port for a ship forward of the beam
    assert summary["pairs"][0]["min_range_m"] >= 0.5 * NM


RV_CROSSING = """\
schema_version: 1
name: rv_crossing_both
description: Rule 19 - a 90 deg crossing in 1 NM visibility, both ships running the rules
duration_s: 3600
seed: 1
record_every_s: 10.0
visibility_nm: 1.0
ships:
  - {name: A, type: cargo, north_m: -7408.0, east_m: 0, heading_deg: 0, speed_kn: 12,
     route: [[32592.0, 0.0]], behaviour: colregs}
  - {name: B, type: cargo, north_m: 0, east_m: -7408.0, heading_deg: 90, speed_kn: 12,
     route: [[0.0, 32592.0]], behaviour: colregs}
"""


def test_restricted_visibility_ships_resume_without_meeting_again(tmp_path: Path) -> None:
    """Both ships alter to starboard and slow down (Rule 19(d)(i), (e)), pass, are released
    beyond 2 NM with the other abeam or abaft, and both resume at once: each checks her way
    back against the other turning back as she does, so neither is engaged again (each
    checking against the other holding her velocity, ship A was engaged three times and
    turned 95 deg to port towards B abaft her port beam, against Rule 19(d)(ii))."""
    scenario = tmp_path / "rv_crossing_both.yaml"
    scenario.write_text(RV_CROSSING)
    summary = run_scenario(scenario, tmp_path / "out")
    table = pq.read_table(tmp_path / "out" / "decisions.parquet")
    dec = {c: np.asarray(table.column(c).to_pylist()) for c in table.column_names}
    for ship in ("A", "B"):
        rows = np.flatnonzero(dec["ship"] == ship)
        engaged = dec["decided_encounter"][rows] == "restricted_visibility"
        assert engaged[0] and not (engaged[1:] & ~engaged[:-1]).any(), ship  # engaged once
        assert set(dec["decided_own_role"][rows]) == {"no_role"}
    assert summary["pairs"][0]["min_range_m"] > 1.5 * NM
