"""``trafficsim explain`` (trafficsim.colregs.explain): which decision step it explains, the
path of rule nodes it walks with their file and line, the roles it shows, and its errors.

Most tests read a decisions file written here by hand against the small rules files of
``tests/colregs/rules/colregs`` (so every expected line is known); the last ones read the run
folder of a short simulation of ``scenarios/rogue_give_way.yaml``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.conftest import ROOT, SCENARIOS
from trafficsim.colregs.explain import explain_run, timeline
from trafficsim.colregs.vocabulary import ENUMS, FEATURES
from trafficsim.errors import DataError, InputError
from trafficsim.io.results import write_parquet
from trafficsim.run import run_scenario

RULES = Path(__file__).resolve().parent / "rules" / "colregs"
SMALL, PORT = RULES / "small.yaml", RULES / "small_port.yaml"

# feature values that lead small.yaml along a known path
QUIET = {"tcpa_min": 30.0, "dcpa_nm": 2.0, "range_nm": 5.0}  # watch -> no
CLOSE = {"tcpa_min": 10.0, "dcpa_nm": 0.5, "bearing_deg": 30.0, "range_nm": 2.0}  # give way
HELD = {"tcpa_min": 9.0, "dcpa_nm": 0.4, "range_nm": 1.8, "own_role": ENUMS["give_way"]}
NONE = ("no_role", "no_encounter", "no_role", "no_action")
GIVE = ("give_way", "crossing", "no_role", "alter_course")
NAN = math.nan

# t_s, ship, other, rules, path, decided state, course order (deg), features
ROWS = [
    (100, "own", "a", SMALL, "watch", NONE, NAN, QUIET),
    (100, "own", "b", SMALL, "watch", NONE, NAN, QUIET),
    (100, "b", "own", PORT, "watch", NONE, NAN, QUIET),
    (110, "own", "a", SMALL, "watch>classify>give_way", GIVE, 30.0, CLOSE),
    (110, "own", "b", SMALL, "watch", NONE, 30.0, QUIET),
    (110, "b", "own", PORT, "watch>classify>give_way", GIVE, 330.0, CLOSE),
    # own ship: only the course order changes
    (120, "own", "a", SMALL, "monitor", GIVE, 35.0, HELD),
    (120, "own", "b", SMALL, "watch", NONE, 35.0, QUIET),
    (120, "b", "own", PORT, "monitor", GIVE, 330.0, HELD),
    # nothing changes
    (130, "own", "a", SMALL, "monitor", GIVE, 35.0, HELD),
    (130, "own", "b", SMALL, "watch", NONE, 35.0, QUIET),
    (130, "b", "own", PORT, "monitor", GIVE, 330.0, HELD),
]


def _columns(rows: list[tuple], drop: str = "") -> dict[str, list]:
    cols: dict[str, list] = {
        "t_s": [float(r[0]) for r in rows], "ship": [r[1] for r in rows],
        "other": [r[2] for r in rows], "rules": [str(r[3]) for r in rows],
        "path": [r[4] for r in rows]}
    for i, name in enumerate(("own_role", "encounter", "other_role", "own_manoeuvre")):
        cols[f"decided_{name}"] = [r[5][i] for r in rows]
    cols["course_order_deg"] = [float(r[6]) for r in rows]
    for name in FEATURES:
        cols[name] = [float(r[7].get(name, 0.0)) for r in rows]
    return {k: v for k, v in cols.items() if k != drop}


def _line_of(rules: Path, node: str) -> int:
    """1-based line of ``node``'s key in a rules file, found by reading the file."""
    lines = rules.read_text().splitlines()
    return next(k + 1 for k, line in enumerate(lines) if line.startswith(f"  {node}:"))


def _sections(text: str) -> list[list[str]]:
    """The explanation blocks (a header, then the node lines) of explain_run's text."""
    blocks = [block.strip("\n") for block in text.split("\n\n")]
    return [block.splitlines() for block in blocks if block.startswith("t = ")]


def _node_titles(block: list[str]) -> list[str]:
    return [line.split(":")[0] for line in block if line[:1].isdigit()]


@pytest.fixture(scope="module")
def hand_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("hand")
    write_parquet(run / "decisions.parquet", _columns(ROWS))
    return run


def test_without_a_time_every_pair_is_explained_at_the_last_change_of_state(hand_run):
    # the course order alone changes at 120 s, nothing at 130 s: the last change of role,
    # encounter or manoeuvre is at 110 s
    blocks = _sections(explain_run(hand_run, "own"))
    assert [b[0] for b in blocks] == ["t = 110 s, own about a (small.yaml):",
                                      "t = 110 s, own about b (small.yaml):"]


def test_the_account_starts_with_the_timeline_of_changes(hand_run):
    text = explain_run(hand_run, "own")
    head = text.split("\n\n")[0].splitlines()
    assert head[0] == "own: decisions that changed something"
    # first row per other ship, then each change of state or of the course order
    assert [(line.split()[2], line.split()[4]) for line in head[1:]] == [
        ("100", "a:"), ("100", "b:"), ("110", "a:"), ("110", "b:"), ("120", "a:"), ("120", "b:")]
    assert head[3] == ("  t =     110 s           a: role give_way, encounter crossing, manoeuvre "
                       "alter_course; course order 30 deg; range 2.00 NM, DCPA 0.50 NM, "
                       "TCPA 10.0 min")
    assert "course order route" in head[1]


def test_timeline_reads_only_the_ship_asked_for(hand_run):
    cols = {c: np.asarray(v) for c, v in _columns(ROWS).items()}
    lines = timeline(cols, "b")
    assert [line.split()[2] for line in lines] == ["100", "110"]
    assert all(line.split()[4] == "own:" for line in lines)


@pytest.mark.parametrize(("at_s", "step"), [
    (100.0, 100), (109.99, 100), (110.0, 110), (125.0, 120), (1e6, 130)])
def test_a_time_explains_the_last_step_at_or_before_it(hand_run, at_s, step):
    text = explain_run(hand_run, "own", at_s)
    assert text.startswith("\n")  # no timeline with a time
    assert [b[0] for b in _sections(text)] == [f"t = {step} s, own about a (small.yaml):",
                                              f"t = {step} s, own about b (small.yaml):"]


def test_the_explanation_walks_the_recorded_path_with_file_and_line(hand_run):
    block = _sections(explain_run(hand_run, "own", 110.0))[0]
    nodes = ["watch", "classify", "give_way"]
    assert _node_titles(block) == [f"{k + 1}. {n} ({SMALL}" for k, n in enumerate(nodes)]
    for k, node in enumerate(nodes):
        assert any(line.startswith(f"{k + 1}. {node} ({SMALL}:{_line_of(SMALL, node)})")
                   for line in block)
    assert "   test [bearing_deg, between, [5, 112.5]]: bearing_deg = 30 -> yes" in block
    assert block[-1] == "   yes -> monitor (next step)"


def test_a_pair_that_saw_nothing_shows_the_failed_test_and_stays(hand_run):
    block = _sections(explain_run(hand_run, "own", 110.0))[1]
    assert _node_titles(block) == [f"1. watch ({SMALL}"]
    assert "       [tcpa_min, between, [0, look_ahead_min]]: tcpa_min = 30, " \
           "look_ahead_min = 20 -> false" in block
    assert block[-1] == "   no -> watch (next step)"


def test_the_role_set_and_the_role_held_are_shown_by_name(hand_run):
    set_block = _sections(explain_run(hand_run, "own", 110.0))[0]
    assert any(line.startswith("   action: role = give_way, encounter = crossing, "
                               "manoeuvre = alter_course") for line in set_block)
    held_block = _sections(explain_run(hand_run, "own", 120.0))[0]
    assert _node_titles(held_block) == [f"1. monitor ({SMALL}"]
    # the role memory the network saw, as a value and by name
    assert "       [own_role, ==, give_way]: own_role = 1 (give_way), give_way = 1 -> true" \
        in held_block


def test_each_ship_is_explained_with_its_own_rules_file(hand_run):
    (block,) = _sections(explain_run(hand_run, "b", 115.0))
    assert block[0] == "t = 110 s, b about own (small_port.yaml):"
    # small_port.yaml inherits its nodes from small.yaml and turns the alteration to port
    assert _node_titles(block) == [f"{k}. {n} ({SMALL}"
                                   for k, n in ((1, "watch"), (2, "classify"), (3, "give_way"))]
    assert any("direction = alteration_side (port)" in line for line in block)
    own = _sections(explain_run(hand_run, "own", 115.0))[0]
    assert any("direction = alteration_side (starboard)" in line for line in own)


def test_an_unknown_ship_is_an_error_naming_the_run_and_the_ships_that_decided(hand_run):
    with pytest.raises(InputError) as err:
        explain_run(hand_run, "a")
    assert err.value.key == "--ship"
    assert err.value.message == (f"ship 'a' took no decisions in {hand_run}; ships that did: "
                                 "b, own")


@pytest.mark.parametrize("at_s", [99.5, -1.0])
def test_a_time_before_the_first_decision_is_an_error(hand_run, at_s):
    with pytest.raises(InputError) as err:
        explain_run(hand_run, "own", at_s)
    assert err.value.key == "--at-s"
    assert err.value.message == f"the first decision is at t = 100 s, after --at-s {at_s:g}"


def test_a_folder_without_decisions_is_an_error_naming_the_missing_file(tmp_path):
    with pytest.raises(InputError, match="no decisions recorded here") as err:
        explain_run(tmp_path, "own")
    assert err.value.path == str(tmp_path / "decisions.parquet")
    assert str(err.value).startswith(f"{tmp_path / 'decisions.parquet'}: ")


def test_a_damaged_decisions_file_is_an_error_naming_it(tmp_path):
    (tmp_path / "decisions.parquet").write_bytes(b"PAR1 not a parquet file")
    with pytest.raises(DataError, match="unreadable decisions file") as err:
        explain_run(tmp_path, "own")
    assert err.value.path == str(tmp_path / "decisions.parquet")


def test_a_decisions_file_lacking_a_feature_is_an_error_naming_it(tmp_path):
    write_parquet(tmp_path / "decisions.parquet", _columns(ROWS, drop="tcpa_min"))
    with pytest.raises(DataError, match="columns missing: tcpa_min") as err:
        explain_run(tmp_path, "own")
    assert err.value.path == str(tmp_path / "decisions.parquet")


def test_a_decisions_file_lacking_the_course_order_is_an_error_naming_it(tmp_path):
    write_parquet(tmp_path / "decisions.parquet", _columns(ROWS, drop="course_order_deg"))
    with pytest.raises(DataError, match="columns missing: course_order_deg"):
        explain_run(tmp_path, "own")


# --- a simulated run --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rogue_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list]]:
    """The rogue give-way scenario cut to 1300 s: the cargo ship stands on, then acts."""
    folder = tmp_path_factory.mktemp("rogue")
    text = (SCENARIOS / "rogue_give_way.yaml").read_text()
    assert "duration_s: 3600\n" in text
    scenario = folder / "rogue.yaml"
    scenario.write_text(text.replace("duration_s: 3600\n", "duration_s: 1300\n"))
    run_scenario(scenario, folder / "run")
    return folder / "run", pq.read_table(folder / "run" / "decisions.parquet").to_pydict()


def test_a_run_is_explained_along_the_path_it_recorded(rogue_run):
    run, rec = rogue_run
    rules = ROOT / "rules" / "colregs.yaml"
    k = rec["t_s"].index(10.0)
    (block,) = _sections(explain_run(run, "cargo", 15.0))
    assert block[0] == "t = 10 s, cargo about tanker (colregs.yaml):"
    nodes = rec["path"][k].split(">")
    assert _node_titles(block) == [f"{i + 1}. {n} ({rules}" for i, n in enumerate(nodes)]
    for i, node in enumerate(nodes):
        assert f"{i + 1}. {node} ({rules}:{_line_of(rules, node)})" in "\n".join(block)


def test_a_run_without_a_time_explains_its_last_change_of_state(rogue_run):
    run, rec = rogue_run
    state = list(zip(*(rec[f"decided_{n}"] for n in
                       ("own_role", "encounter", "other_role", "own_manoeuvre")), strict=True))
    last = max(k for k in range(1, len(state)) if state[k] != state[k - 1])
    assert last < len(state) - 1  # the run goes on after it
    blocks = _sections(explain_run(run, "cargo"))
    assert [b[0] for b in blocks] == [f"t = {rec['t_s'][last]:g} s, cargo about tanker "
                                      "(colregs.yaml):"]
    action = next(line for line in reversed(blocks[0]) if line.startswith("   action:"))
    assert f"manoeuvre = {rec['decided_own_manoeuvre'][last]}" in action
    assert rec["decided_own_manoeuvre"][last] != rec["decided_own_manoeuvre"][last - 1]


def test_a_run_shows_the_roles_the_first_decision_set(rogue_run):
    run, rec = rogue_run
    (block,) = _sections(explain_run(run, "cargo", 0.0))
    action = next(line for line in block if line.startswith("   action:"))
    # the roles the explanation sets are the roles the run recorded
    assert f"role = {rec['decided_own_role'][0]}," in action
    assert f"other_role = {rec['decided_other_role'][0]}," in action
    assert (rec["decided_own_role"][0], rec["decided_other_role"][0]) == ("stand_on", "give_way")


def test_a_ship_that_keeps_her_course_took_no_decisions(rogue_run):
    run, _ = rogue_run
    with pytest.raises(InputError, match=r"ship 'tanker' took no decisions in .*; ships that "
                                         r"did: cargo$"):
        explain_run(run, "tanker")


# --- decisions recorded by the decision step itself (no simulation) ----------------------------

V12 = 12.0 * 1852.0 / 3600.0


def _crossing(tcpa_min: float) -> list[tuple[float, float, float, float]]:
    """Imazu case 2: own ship north, TS1 west from her starboard bow, meeting after tcpa_min."""
    d = V12 * 60.0 * tcpa_min
    return [(-d, 0.0, 0.0, V12), (0.0, d, 270.0, V12)]


# t_s, ships (north, east, course deg, speed), route courses deg: a crossing, the give-way
# action, past the CPA but not clear, then past and clear
STEPS = [
    (0.0, _crossing(16.5), None),
    (150.0, _crossing(14.0), None),
    (160.0, _crossing(14.0 - 1.0 / 6.0), None),
    (210.0, [(0.0, 0.0, 30.0, V12), (2500.0, -1500.0, 270.0, V12)], [0.0, 270.0]),
    (220.0, [(0.0, 0.0, 30.0, V12), (3500.0, -3000.0, 270.0, V12)], [0.0, 270.0]),
]


@pytest.fixture(scope="module")
def decided_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list]]:
    """A decisions file written from Decider.records of two colregs ships over STEPS."""
    from trafficsim.colregs.decider import Decider

    dec = Decider.build(["colregs", "colregs"], np.array([0]), np.array([1]))
    dec.record = True
    for t, ships, route_deg in STEPS:
        a = np.array(ships, dtype=float)
        hdg = np.radians(a[:, 2])
        own_state = np.stack([a[:, 0], a[:, 1], hdg])
        own_vel = np.stack([a[:, 3] * np.cos(hdg), a[:, 3] * np.sin(hdg)])
        other = np.concatenate([own_state[:2, dec.tgt], own_vel[:, dec.tgt]])
        route = hdg if route_deg is None else np.radians(route_deg)
        dec.decide(t, own_state, own_vel, np.full(2, 150.0), other, route, a[:, 3])
    run = tmp_path_factory.mktemp("decided")
    cols = dec.records(["own", "TS1"])
    write_parquet(run / "decisions.parquet", cols)
    return run, pq.read_table(run / "decisions.parquet").to_pydict()


def _actions(block: list[str]) -> list[dict[str, str]]:
    """The action fields each node of an explanation block set, in order."""
    out = []
    for line in block:
        if line.startswith("   action: "):
            fields = line[len("   action: "):].split(", ")
            out.append(dict(f.split(" = ", 1) for f in fields))
    return out


@pytest.mark.parametrize("ship", ["own", "TS1"])
def test_every_recorded_step_replays_along_its_recorded_path(decided_run, ship):
    """At each recorded step the explanation walks exactly the recorded nodes (the features
    and memory the network saw lead along them: explain raises otherwise)."""
    run, rec = decided_run
    rows = [k for k, s in enumerate(rec["ship"]) if s == ship]
    assert len(rows) == len(STEPS)
    for k in rows:
        (block,) = _sections(explain_run(run, ship, rec["t_s"][k]))
        assert block[0].startswith(f"t = {rec['t_s'][k]:g} s, {ship} about ")
        names = rec["path"][k].split(">")
        assert [t.split(" (")[0] for t in _node_titles(block)] == [
            f"{i + 1}. {n}" for i, n in enumerate(names)]


@pytest.mark.parametrize("ship", ["own", "TS1"])
def test_the_explained_actions_give_the_recorded_state(decided_run, ship):
    """The state recorded after each step is the state before it (the memory columns the
    network saw), overwritten by the last value each action field was set to along the
    explained path: role, encounter, other_role and manoeuvre alike."""
    run, rec = decided_run
    fields = {"role": "own_role", "encounter": "encounter", "other_role": "other_role",
              "manoeuvre": "own_manoeuvre"}
    names = {v: k for k, v in ENUMS.items()}
    rows = [k for k, s in enumerate(rec["ship"]) if s == ship]
    changed = 0
    for k in rows:
        (block,) = _sections(explain_run(run, ship, rec["t_s"][k]))
        state = {f: names[rec[col][k]] for f, col in fields.items()}  # as the network saw it
        for action in _actions(block):
            state.update({f: v for f, v in action.items() if f in fields})
        for f, col in fields.items():
            assert state[f] == rec[f"decided_{col}"][k], (k, f)
        changed += names[rec["own_role"][k]] != rec["decided_own_role"][k]
    assert changed >= 2  # the role was set and dropped again


def test_the_timeline_lists_exactly_the_recorded_changes(decided_run):
    """One timeline line per step where the recorded state or the rounded course order of
    own ship changed (the first step included), and the account without a time explains the
    last step whose state changed (found here from the recorded columns)."""
    run, rec = decided_run
    rows = [k for k, s in enumerate(rec["ship"]) if s == "own"]
    state = [tuple(rec[f"decided_{c}"][k] for c in ("own_role", "encounter", "other_role",
                                                     "own_manoeuvre")) for k in rows]
    course = [f"{rec['course_order_deg'][k]:.0f}" for k in rows]
    want = [rec["t_s"][rows[i]] for i in range(len(rows))
            if i == 0 or (state[i], course[i]) != (state[i - 1], course[i - 1])]
    cols = {c: np.asarray(v) for c, v in rec.items()}
    lines = timeline(cols, "own")
    assert [float(line.split()[2]) for line in lines] == want
    last = max(i for i in range(1, len(rows)) if state[i] != state[i - 1])
    blocks = _sections(explain_run(run, "own"))
    assert [b[0] for b in blocks] == [f"t = {rec['t_s'][rows[last]]:g} s, own about TS1 "
                                      "(colregs.yaml):"]


def _copied_rules_run(folder: Path, with_digest: bool) -> tuple[Path, Path]:
    """The hand-written decisions of ROWS against a copy of small.yaml (b's rows dropped),
    with the digest column a run writes or, as an older version wrote them, without."""
    from trafficsim.colregs.network import rules_digest

    rules = folder / "small.yaml"
    rules.write_text(SMALL.read_text())
    rows = [(*r[:3], rules, *r[4:]) for r in ROWS if r[1] == "own"]
    cols = _columns(rows)
    if with_digest:
        cols["rules_sha1"] = [rules_digest([str(rules)])] * len(rows)
    write_parquet(folder / "decisions.parquet", cols)
    return folder, rules


def test_a_rules_file_edited_after_the_run_is_refused(tmp_path):
    """A parameter edit still leads along the recorded path but would show a look-ahead the
    ship never used: the digest recorded with the decisions tells, and the error names the
    file."""
    run, rules = _copied_rules_run(tmp_path, with_digest=True)
    assert "look_ahead_min" in explain_run(run, "own")
    rules.write_text(rules.read_text().replace("look_ahead_min: 20", "look_ahead_min: 25"))
    with pytest.raises(InputError, match="changed since the run") as err:
        explain_run(run, "own")
    assert err.value.path == str(rules)


def test_without_a_digest_a_path_the_rules_no_longer_hold_is_refused(tmp_path):
    """An older run folder (no digest): a renamed node, or a test that no longer leads along
    the recorded path, is the same InputError rather than a KeyError or ValueError."""
    run, rules = _copied_rules_run(tmp_path, with_digest=False)
    text = rules.read_text()
    rules.write_text(text.replace("classify", "sort_out"))
    with pytest.raises(InputError, match="changed since the run"):
        explain_run(run, "own")
    rules.write_text(text.replace("safe_nm: 1.0", "safe_nm: 0.1"))  # watch no longer holds
    with pytest.raises(InputError, match="changed since the run"):
        explain_run(run, "own")


def test_a_run_records_the_digest_of_its_rules(rogue_run):
    """Every decision row of a run carries the digest of the rules files it decided by."""
    from trafficsim.colregs.network import rules_digest
    from trafficsim.colregs.rulefile import parse_file
    from trafficsim.colregs.vocabulary import VOCABULARY

    _, rec = rogue_run
    by_file = {r: rules_digest(parse_file(r, VOCABULARY).files) for r in set(rec["rules"])}
    assert rec["rules_sha1"] == [by_file[r] for r in rec["rules"]]
