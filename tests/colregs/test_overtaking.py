"""Rule 13(d), end to end: an overtaking ship stays the give-way ship until finally past and clear.

COLREG Rule 13(d): "Any subsequent alteration of the bearing between the two vessels shall not
make the overtaking vessel a crossing vessel ... or relieve her of the duty of keeping clear of
the overtaken vessel until she is finally past and clear" (shared/reference/colregs.md, section
2.1; section 2.2: keep the label until past and clear).

Ship A (cargo, 16 kn, north) comes up with ship B (cargo, 10 kn, course 015) from 37 deg abaft
her port beam, on a collision course; both run ``rules/colregs.yaml``. A gives way by 30 deg to
starboard and, slower across B's track than B along it, opens beyond ``far_clear_nm`` (2 NM)
while still abaft B's beam: she is not past, so both ships keep their roles while A goes back
towards her route, and the pair is released only once A is finally past and clear (B more than
22.5 deg abaft A's beam, A more than 22.5 deg forward of B's beam, range opening beyond
``clear_nm``). In the second scenario B's route turns 30 deg to starboard, towards A, just after
A opened beyond 2 NM: a fresh look would make the pair a crossing with A on B's starboard side
(B give-way, A stand-on), but A stays the overtaking give-way ship and gives way again.
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
ABAFT_BEAM_DEG, AHEAD_OF_BEAM_DEG = 112.5, 67.5  # rules/colregs.yaml
B_START = (-7453.73, -1997.22)  # B's start: both would meet at the origin after 25 min
B_SPEED_MPS = 10.0 * NM / 3600.0
TURN_S = 1200.0  # when B's route turns in the second scenario

SCENARIO = """\
schema_version: 1
name: {name}
description: Rule 13(d) - ship A overtakes ship B, sheers off beyond 2 NM abeam
duration_s: 3600
seed: 1
record_every_s: 10.0
ships:
  - name: A
    type: cargo
    north_m: -12346.67
    east_m: 0
    heading_deg: 0
    speed_kn: 16
    route: [[27653.3, 0]]
    behaviour: colregs
  - name: B
    type: cargo
    north_m: {b_north}
    east_m: {b_east}
    heading_deg: 15
    speed_kn: 10
    route: {b_route}
    behaviour: colregs
"""


def _b_route(turn_deg: float) -> str:
    """B's route: on along 015, turning ``turn_deg`` to starboard where she is at
    :data:`TURN_S` (none for 0)."""
    n0, e0 = B_START
    c = math.radians(15.0)
    if turn_deg == 0.0:
        return f"[[{n0 + 40000.0 * math.cos(c):.1f}, {e0 + 40000.0 * math.sin(c):.1f}]]"
    d = B_SPEED_MPS * TURN_S
    wn, we = n0 + d * math.cos(c), e0 + d * math.sin(c)
    c2 = math.radians(15.0 + turn_deg)
    return (f"[[{wn:.1f}, {we:.1f}], "
            f"[{wn + 40000.0 * math.cos(c2):.1f}, {we + 40000.0 * math.sin(c2):.1f}]]")


@functools.cache
def _run(turn_deg: float, out_root: str) -> tuple[dict, dict[str, np.ndarray]]:
    name = f"overtaking_turn{turn_deg:.0f}"
    scenario = Path(out_root) / f"{name}.yaml"
    scenario.write_text(SCENARIO.format(name=name, b_north=B_START[0], b_east=B_START[1],
                                        b_route=_b_route(turn_deg)))
    summary = run_scenario(scenario, Path(out_root) / name)
    table = pq.read_table(Path(out_root) / name / "decisions.parquet")
    return summary, {c: np.asarray(table.column(c).to_pylist()) for c in table.column_names}


@pytest.fixture(scope="module")
def out_root(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("overtaking"))


def _rows(dec: dict[str, np.ndarray], ship: str) -> np.ndarray:
    """The decision rows of ``ship`` about the other ship, in time order."""
    return np.flatnonzero(dec["ship"] == ship)


def _released(dec: dict[str, np.ndarray], rows: np.ndarray) -> int:
    """Index (into ``rows``) of the first step without a role after the first with one."""
    role = dec["decided_own_role"][rows]
    first = int(np.flatnonzero(role != "no_role")[0])
    return first + int(np.flatnonzero(role[first:] == "no_role")[0])


@pytest.mark.parametrize("turn_deg", [0.0, 30.0])
def test_overtaking_pair_keeps_its_roles_until_finally_past_and_clear(turn_deg: float,
                                                                      out_root: str) -> None:
    """Both ships hold give_way / overtaking and stand_on / overtaken from the first step until
    they are released together, and only at a step where the overtaking ship is finally past
    and clear, seen from either ship; the range had opened beyond 2 NM with A still abaft B's
    beam (where the pair was released before), and A meanwhile went back towards her route.
    Never a crossing, no blind spot, and the ships pass beyond 1 NM."""
    summary, dec = _run(turn_deg, out_root)
    a, b = _rows(dec, "A"), _rows(dec, "B")
    ra, rb = _released(dec, a), _released(dec, b)
    held_a, held_b = a[:ra], b[:rb]
    assert set(dec["decided_own_role"][held_a]) == {"give_way"}
    assert set(dec["decided_encounter"][held_a]) == {"overtaking"}
    assert set(dec["decided_own_role"][held_b]) == {"stand_on"}
    assert set(dec["decided_encounter"][held_b]) == {"overtaken"}
    assert dec["t_s"][a[ra]] == dec["t_s"][b[rb]]
    # (a) released only once finally past and clear (A's view; B's view mirrored)
    at, bt = a[ra], b[rb]
    assert dec["tcpa_min"][at] < 0.0 and dec["range_nm"][at] > 1.0
    assert dec["bearing_abs_deg"][at] > ABAFT_BEAM_DEG
    assert dec["aspect_abs_deg"][at] < AHEAD_OF_BEAM_DEG
    assert dec["aspect_abs_deg"][bt] > ABAFT_BEAM_DEG
    assert dec["bearing_abs_deg"][bt] < AHEAD_OF_BEAM_DEG
    # ... not at the earlier steps where the range had opened beyond 2 NM with A abeam of B
    abeam = held_a[(dec["tcpa_min"][held_a] < 0.0) & (dec["range_nm"][held_a] > 2.0)
                   & (dec["aspect_abs_deg"][held_a] <= ABAFT_BEAM_DEG)]
    assert abeam.size > 0
    assert "overtaking_resume" in dec["path"][abeam[0]]
    assert dec["decided_own_manoeuvre"][abeam[0]] == "resume_route"
    # (b) never re-classified as a crossing: released once, never engaged again
    pair = np.concatenate([a, b])
    assert not np.isin(dec["decided_encounter"][pair], ["crossing", "head_on"]).any()
    for rows, r in ((a, ra), (b, rb)):
        assert set(dec["decided_own_role"][rows[r:]]) == {"no_role"}
    assert summary["blind_spots"] == []
    assert summary["pairs"][0]["min_range_m"] > NM


def test_overtaking_ship_gives_way_again_as_overtaking_ship_when_the_bearing_changes(
        out_root: str) -> None:
    """B's route turns 30 deg towards A after A opened beyond 2 NM abeam: a new risk of
    collision with A forward of B's beam (aspect below 112.5 deg, which a fresh look would call
    a crossing with B the give-way ship). A acts again as the overtaking give-way ship (Rule
    13(d)); B stands on."""
    _, dec = _run(30.0, out_root)
    a = _rows(dec, "A")
    acts = a[dec["decided_own_manoeuvre"][a] == "alter_course"]
    gap = np.flatnonzero(np.diff(dec["t_s"][acts]) > 10.0 + 1e-6)
    again = acts[gap[0] + 1]  # the first step of the second alteration
    assert dec["t_s"][again] > TURN_S
    assert "overtaking_risk>give_way_overtaking" in dec["path"][again]
    assert dec["decided_own_role"][again] == "give_way"
    assert dec["decided_encounter"][again] == "overtaking"
    assert dec["aspect_abs_deg"][again] < ABAFT_BEAM_DEG
    assert dec["dcpa_nm"][again] < 1.0
    b = _rows(dec, "B")
    same = b[dec["t_s"][b] == dec["t_s"][again]]
    assert dec["decided_own_role"][same].tolist() == ["stand_on"]
