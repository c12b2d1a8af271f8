"""Rule 14(a), end to end: in a head-on encounter each ship alters her course to starboard.

Ship A (cargo, 12 kn, north) meets ship B (cargo, 12 kn) on a course 15 deg off the reciprocal
(195 deg, or 165 deg for the mirror image), both on a collision course meeting at the origin
after 20 min and both running ``rules/colregs.yaml``. Each sees the other 7.5 deg off her bow,
one to port and one to starboard, so the Coldwell domain's starboard offset makes one ship reach
her action time first. Her 30 deg alteration alone opens the CPA beyond ``cpa_limit_nm`` before
the other's action time; the other must still alter to starboard in her turn (``mutual_still``)
rather than be released and pass on her course (shared/reference/colregs.md, section 2.1).

On exactly reciprocal courses along one route line both ships alter 30 deg at 6.5 NM and are
released abeam of each other at 3 NM (``past_and_clear`` beyond ``far_clear_nm``). Both resume
at once, each back towards the one line: each must check her way back against the other doing
the same (``Decider._resume``'s mirror hypothesis) and come no nearer to her; steering back
with the other ship's velocity held, both turned in steeply, met again as a mutual crossing
(CPA 0.93 NM) and altered a second time (Rule 8(d): no new close-quarters situation).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from trafficsim.run import run_scenario

NM = 1852.0

SCENARIO = """\
schema_version: 1
name: head_on_{course}
description: Rule 14(a) - courses 15 deg off reciprocal, both ships run the rules
duration_s: 2400
seed: 1
record_every_s: 10.0
ships:
  - name: A
    type: cargo
    north_m: -7408.0
    east_m: 0
    heading_deg: 0
    speed_kn: 12
    route: [[32592.0, 0.0]]
    behaviour: colregs
  - name: B
    type: cargo
    north_m: {b_north:.2f}
    east_m: {b_east:.2f}
    heading_deg: {course}
    speed_kn: 12
    route: [[{end_north:.1f}, {end_east:.1f}]]
    behaviour: colregs
"""


@functools.cache
def _run(course: int, out_root: str) -> tuple[dict, dict[str, np.ndarray]]:
    c = math.radians(course)
    b_north, b_east = -7408.0 * math.cos(c), -7408.0 * math.sin(c)  # at the origin in 20 min
    scenario = Path(out_root) / f"head_on_{course}.yaml"
    scenario.write_text(SCENARIO.format(course=course, b_north=b_north, b_east=b_east,
                                        end_north=b_north + 40000.0 * math.cos(c),
                                        end_east=b_east + 40000.0 * math.sin(c)))
    summary = run_scenario(scenario, Path(out_root) / f"head_on_{course}")
    table = pq.read_table(Path(out_root) / f"head_on_{course}" / "decisions.parquet")
    return summary, {name: np.asarray(table.column(name).to_pylist())
                     for name in table.column_names}


@pytest.fixture(scope="module")
def out_root(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("head_on"))


@pytest.mark.parametrize("course", [195, 165])
def test_each_ship_alters_to_starboard(course: int, out_root: str) -> None:
    summary, dec = _run(course, out_root)
    heading = {"A": 0.0, "B": float(course)}
    first_turn = {}
    for ship in ("A", "B"):
        rows = np.flatnonzero(dec["ship"] == ship)
        assert dec["decided_own_role"][rows[0]] == "mutual_give_way"
        assert dec["decided_encounter"][rows[0]] == "head_on"
        turns = rows[dec["decided_own_manoeuvre"][rows] == "alter_course"]
        assert turns.size > 0, ship  # (before mutual_still, one ship never altered)
        k = turns[0]
        first_turn[ship] = dec["t_s"][k]
        change = (dec["course_order_deg"][k] - heading[ship]) % 360.0
        assert 30.0 - 1e-3 <= change < 90.0, (ship, change)  # to starboard, readily apparent
        assert dec["tcpa_min"][k] > 0.0
    # the ship acting second: the first one's alteration had opened the CPA beyond
    # cpa_limit_nm (1 NM), and mutual_still kept her engaged (before, she was released)
    second = max(first_turn, key=first_turn.get)
    rows = np.flatnonzero(dec["ship"] == second)
    k = rows[dec["t_s"][rows] == first_turn[second]][0]
    assert dec["dcpa_nm"][k] >= 1.0
    before = rows[dec["t_s"][rows] < first_turn[second]]
    assert any("mutual_still" in path for path in dec["path"][before])
    assert summary["blind_spots"] == []
    pair = summary["pairs"][0]
    assert not pair["collision"] and pair["min_range_m"] > 1.5 * NM


def test_ships_released_abeam_go_back_to_their_line_without_meeting_again(out_root: str
                                                                         ) -> None:
    summary, dec = _run(180, out_root)
    pair = summary["pairs"][0]
    for ship in ("A", "B"):
        rows = np.flatnonzero(dec["ship"] == ship)
        engaged = dec["decided_own_role"][rows] != "no_role"
        starts = np.flatnonzero(engaged[1:] & ~engaged[:-1]) + 1
        assert engaged[0] and starts.size == 0, ship  # one engagement, from the start
        released = dec["t_s"][rows][np.flatnonzero(~engaged)[0]]
        # released abeam beyond far_clear_nm, the range still that of the passage
        k = rows[np.flatnonzero(~engaged)[0]]
        assert 80.0 < dec["bearing_abs_deg"][k] < 112.5 and dec["range_nm"][k] > 2.0
        # the closest approach is the passage itself: the ways back close nothing
        assert pair["t_min_range_s"] <= released
        # ... and both ships are back on the route by the end (resuming, then released)
        assert dec["decided_own_manoeuvre"][rows][-1] in ("resume_route", "no_action")
        assert np.isnan(dec["course_order_deg"][rows[-1]])
    assert pair["min_range_m"] > 1.5 * NM
