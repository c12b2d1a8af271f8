"""A chunk of a campaign as one batch: an encounter whose state stops being finite is flagged
and frozen while the others run on, whatever the chunking; the summary, the figures, the
report and the command line leave it out of the outcomes and name it."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from trafficsim.campaign.compliance import RULE_OF_KIND
from trafficsim.campaign.generator import classify, draw
from trafficsim.campaign.runner import COLUMNS, compliant, rules_path, run_chunk
from trafficsim.campaign.spec import load_spec
from trafficsim.cli import main
from trafficsim.render.report import write_report
from trafficsim.units import NM

SPEC = """schema_version: 1
name: runaway
n_encounters: 8
seed: 5
duration_s: 300
tcpa_min: [2, 5]
chunk_encounters: 4
encounter_types: {head_on: 1, crossing_give_way: 1}
ship_types: {cargo: 1, runaway.yaml: 1}
"""


def _spec(runaway_ship: Path) -> Path:
    path = runaway_ship.parent / "spec.yaml"
    path.write_text(SPEC)
    return path


def test_a_diverging_encounter_is_flagged_and_the_others_run_on(runaway_ship):
    spec = load_spec(_spec(runaway_ship))
    whole = run_chunk(spec, 0, 8)
    diverged = np.asarray(whole["diverged"])
    runaway = (np.asarray(whole["type_i"]) == "runaway") | (np.asarray(whole["type_j"])
                                                               == "runaway")
    assert diverged.any() and not diverged.all()
    assert not (diverged & ~runaway).any()  # only encounters with the runaway ship
    at = np.asarray(whole["diverged_at_s"])
    assert (np.isfinite(at) == diverged).all() and (at[diverged] < 120.0).all()
    assert np.isfinite(np.asarray(whole["min_range_m"])).all()
    # the same rows whatever chunk ran them: a frozen encounter touches no other
    parts = [run_chunk(spec, a, b) for a, b in ((0, 3), (3, 8))]
    for key, value in whole.items():
        if not key.startswith("_"):
            joined = [v for p in parts for v in np.asarray(p[key]).tolist()]
            np.testing.assert_array_equal(np.asarray(value).tolist(), joined, err_msg=key)


def test_diverged_encounters_are_named_and_left_out_of_the_outcomes(runaway_ship, tmp_path,
                                                                    capsys):
    out = tmp_path / "out"
    assert main(["campaign", str(_spec(runaway_ship)), "--out", str(out), "--workers", "1",
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out
    rows = run_chunk(load_spec(_spec(runaway_ship)), 0, 8)
    enc = np.asarray(rows["encounter"])
    gone = sorted(set(enc[np.asarray(rows["diverged"])].tolist()))
    s = json.loads((out / "summary.json").read_text())
    assert s["n_encounters"] == 8 and s["diverged"] == len(gone) > 0
    assert s["diverged_encounters"] == gone and s["n_completed"] == 8 - len(gone)
    assert s["encounters_all_compliant"] == 8 - len(gone)  # no rogues in this spec
    kept = ~np.isin(enc, gone)
    cpa_nm = [np.min(np.asarray(rows["min_range_m"])[enc == e]) / 1852.0
              for e in sorted(set(enc[kept].tolist()))]
    assert s["cpa_nm"]["p50"] == np.percentile(cpa_nm, 50)
    assert f"DIVERGED: {len(gone)} encounters" in printed
    assert ", ".join(map(str, gone)) in printed

    report = write_report(out, worst=0, progress=False)
    page = report.path.read_text()
    assert f"{len(gone)} encounters diverged" in page
    # its replay is written up to the divergence, then ends as a diverged run does
    replay = tmp_path / "replay"
    assert main(["replay", str(out), "--encounter", str(gone[0]), "--out", str(replay)]) == 1
    assert "state became non-finite" in capsys.readouterr().err
    at = np.asarray(rows["diverged_at_s"])[enc == gone[0]][0]
    assert json.loads((replay / "summary.json").read_text())["diverged_at_s"] == at


# --------------------------------------------------------------------------------------------
# rows checked against the generator and straight-line kinematics
# --------------------------------------------------------------------------------------------

ROWS_SPEC = """schema_version: 1
name: rows
n_encounters: 8
seed: 3
duration_s: {duration}
ship_types: {{cargo: 1, container: 1}}
dcpa_nm: [0.2, 0.6]
{extra}
"""


def _rows_spec(tmp_path, extra="", duration=400, name="r.yaml"):
    if "tcpa_min" not in extra:  # (a spec's TCPA must end within its duration)
        extra += f"\ntcpa_min: [{min(2, duration / 60):g}, {min(4, duration / 60):g}]"
    path = tmp_path / name
    path.write_text(ROWS_SPEC.format(extra=extra, duration=duration))
    return load_spec(path)


@pytest.fixture
def straight(tmp_path):
    """A no-avoidance chunk: every ship holds course and speed in calm water."""
    spec = _rows_spec(tmp_path, extra="policy: no_avoidance")
    return spec, run_chunk(spec, 0, 8)


def test_rows_are_the_pairs_of_each_encounter(straight):
    """n ships give n (n - 1) / 2 rows, in encounter order, with the campaign index and seed,
    and the pair type of the generator for the own ship's pairs (the sector rule from the
    start state for the others)."""
    spec, rows = straight
    encs = [draw(spec, i) for i in range(8)]
    expected_enc, expected_kind = [], []
    for enc in encs:
        n = len(enc.ships)
        for i in range(n):
            for j in range(i + 1, n):
                expected_enc.append(enc.index)
                if i == 0:
                    expected_kind.append(enc.pair_kinds[j - 1])
                else:
                    a, b = enc.ships[i], enc.ships[j]
                    expected_kind.append(classify(a.heading_rad, b.heading_rad,
                                                  b.north_m - a.north_m, b.east_m - a.east_m,
                                                  a.speed_mps, b.speed_mps))
    assert np.asarray(rows["encounter"]).tolist() == expected_enc
    assert list(rows["pair_type"]) == expected_kind
    assert np.all(np.asarray(rows["seed"]) == 3)
    assert list(rows["encounter_type"]) == [encs[e].kind for e in expected_enc]
    assert rows["_ship_steps"] == sum(len(e.ships) for e in encs) * 400


def test_straight_runs_meet_at_the_drawn_dcpa_and_tcpa(straight):
    """Nobody manoeuvres, no current or wind: the smallest range of an own-ship pair is the
    drawn DCPA (to a metre: the closest sample is within half a step of the CPA) at the drawn
    TCPA (to a step), and the start columns repeat the draw."""
    spec, rows = straight
    own_rows = [k for k, s in enumerate(rows["ship_i"]) if s == "own"]
    encs = {i: draw(spec, i) for i in range(8)}
    enc_col = np.asarray(rows["encounter"])
    for k in own_rows:
        enc = encs[int(enc_col[k])]
        j = int(rows["ship_j"][k].removeprefix("ship"))
        dcpa, tcpa = enc.dcpa_m[j - 1], enc.tcpa_s[j - 1]
        other = enc.ships[j]
        assert rows["dcpa0_nm"][k] * NM == pytest.approx(dcpa, abs=1e-6)
        assert rows["tcpa0_min"][k] * 60 == pytest.approx(tcpa, abs=1e-6)
        assert rows["range0_nm"][k] * NM == pytest.approx(math.hypot(other.north_m,
                                                                     other.east_m))
        assert rows["min_range_m"][k] == pytest.approx(dcpa, abs=1.0)
        assert abs(rows["t_cpa_s"][k] - tcpa) <= 1.0
        assert not rows["collision"][k] or dcpa < 100.0


def test_no_avoidance_ships_do_nothing_and_are_not_compliant(straight):
    """Keep-course ships ask for no manoeuvre, fire no rule and change course by nothing; as
    they do not run the rules, no pair counts as compliant."""
    _, rows = straight
    for side in ("_i", "_j"):
        assert set(rows["manoeuvres" + side]) == {""}
        assert set(rows["rules_fired" + side]) == {""}
        assert np.all(np.abs(rows["course_change_stbd_deg" + side]) < 1e-9)
        assert np.all(np.abs(rows["course_change_port_deg" + side]) < 1e-9)
    assert set(rows["behaviour_i"]) | set(rows["behaviour_j"]) == {"keep_course"}
    assert not compliant(rows).any()
    assert not np.asarray(rows["diverged"]).any()
    assert np.all(np.isnan(np.asarray(rows["diverged_at_s"])))


def test_the_decision_at_the_start_is_in_the_rules_fired(tmp_path):
    """Most encounters are first classified by the decision at t = 0, taken when the
    simulation starts: the rules fired and manoeuvres asked then are in the rows. A 5 s run
    (that decision only) fires rules that a 15 s run (decisions at 0 and 10 s) must list too."""
    spec = _rows_spec(tmp_path, extra="policy: colregs")
    short, longer = (run_chunk(spec.model_copy(update={"duration_s": d}), 0, 6)
                     for d in (5.0, 15.0))
    fired = 0
    for side in ("_i", "_j"):
        for key in ("rules_fired", "manoeuvres"):
            for a, b in zip(short[key + side], longer[key + side], strict=True):
                assert set(filter(None, a.split(","))) <= set(b.split(","))
                fired += key == "rules_fired" and a != ""
    assert fired > 0


def test_rows_name_the_part_each_ship_was_graded_for(tmp_path):
    """A ship that runs the rules is graded under the role its network first gave the pair
    (``graded_by_* = network``, a role node among its rules fired), other pairs under the start
    geometry; the no_avoidance baseline of the same draws is graded by the start geometry
    alone, and under the same kinds for the own ship's pairs, which the network engages at
    t = 0 with perfect knowledge. Each ship's compliance is the score of its kind's rule, the
    rule column the lower where both ships are bound by that rule."""
    roles = {"give_way_crossing", "stand_on_crossing", "mutual_crossing", "head_on_role",
             "give_way_overtaking", "stand_on_overtaken"}
    rules = run_chunk(_rows_spec(tmp_path, extra="policy: colregs"), 0, 8)
    base = run_chunk(_rows_spec(tmp_path, extra="policy: no_avoidance", name="b.yaml"), 0, 8)
    own = [k for k, s in enumerate(rules["ship_i"]) if s == "own"]
    for side, other in (("_i", "_j"), ("_j", "_i")):
        kinds, by = rules["graded_kind" + side], rules["graded_by" + side]
        assert set(kinds) <= set(RULE_OF_KIND) and set(by) <= {"network", "geometry"}
        assert set(base["graded_by" + side]) == {"geometry"}
        assert all(by[k] == "network" for k in own)
        assert [kinds[k] for k in own] == [base["graded_kind" + side][k] for k in own]
        for k, (kind, source) in enumerate(zip(kinds, by, strict=True)):
            fired = set(rules["rules_fired" + side][k].split(","))
            assert (source == "network") == bool(fired & roles), k
            rule = RULE_OF_KIND[kind]
            score, column = rules["compliance" + side][k], rules[f"score_rule{rule}"][k]
            if RULE_OF_KIND[rules["graded_kind" + other][k]] == rule:
                assert column == min(score, rules["compliance" + other][k])
            else:
                assert column == score
    assert {"graded_kind_i", "graded_kind_j", "graded_by_i", "graded_by_j"} <= set(COLUMNS)


def test_rogue_ships_are_graded_by_the_start_geometry(tmp_path):
    """A rogue ship runs a rules file of its own (turn_port, late_action): its roles are not
    the part the rules gave it, so it is graded under the start geometry; the ships that run
    the rules, under their networks' roles."""
    rows = run_chunk(_rows_spec(tmp_path, extra="rogue_fraction: 0.5"), 0, 8)
    rogue = network = 0
    for side in ("_i", "_j"):
        for behaviour, by in zip(rows["behaviour" + side], rows["graded_by" + side],
                                 strict=True):
            if behaviour != "colregs":
                assert by == "geometry"
                rogue += 1
            network += by == "network"
    assert rogue > 0 and network > 0


def test_compliant_needs_both_ships_on_the_rules():
    rows = {"behaviour_i": ["colregs", "colregs", "turn_port", "keep_course"],
            "behaviour_j": ["colregs", "late_action", "colregs", "colregs"]}
    assert compliant(rows).tolist() == [True, False, False, False]


def test_a_run_that_ends_between_decisions_is_observed_to_its_end(tmp_path):
    """95 s with 10 s decisions: the chunk runs 95 steps, not a whole number of decision
    periods (90 or 100): with a TCPA of 10 min the range still falls at the end, so the
    closest point is the last step, 95 s; the ship-steps are 95 per ship. (A spec refuses a
    run that ends before its TCPA; the runner is given one here all the same.)"""
    spec = _rows_spec(tmp_path, extra="policy: no_avoidance\ntcpa_min: [10, 10]", duration=600,
                      name="short.yaml").model_copy(update={"duration_s": 95.0})
    rows = run_chunk(spec, 0, 2)
    own = [k for k, s in enumerate(rows["ship_i"]) if s == "own"]
    assert all(rows["t_cpa_s"][k] == pytest.approx(95.0) for k in own)
    n_ships = sum(len(draw(spec, i).ships) for i in range(2))
    assert rows["_ship_steps"] == n_ships * 95


def test_rows_do_not_depend_on_the_chunk_with_rules_rogues_sensors_and_weather(tmp_path):
    """Encounters 2..5 run as one chunk or as 2..3 and 4..5 give the same rows, with the
    rules, rogues, noisy instruments, current and wind all drawing random numbers."""
    spec = _rows_spec(tmp_path, duration=120, extra="rogue_fraction: 0.5\ncurrent_kn: [0, 1]\n"
                 "wind_mps: [0, 10]\nsensors: {gnss_sigma_m: [1, 3]}")
    whole = run_chunk(spec, 2, 6)
    parts = [run_chunk(spec, 2, 4), run_chunk(spec, 4, 6)]
    for key, value in whole.items():
        if key.startswith("_"):
            continue
        joined = [v for p in parts for v in np.asarray(p[key]).tolist()]
        np.testing.assert_array_equal(np.asarray(value).tolist(), joined, err_msg=key)


def test_rules_are_found_relative_to_the_spec(tmp_path):
    """``rules:`` is relative to the spec file's folder, not the working directory."""
    sub = tmp_path / "a" / "b"
    sub.mkdir(parents=True)
    (tmp_path / "a" / "rules.yaml").write_text("x: 1\n")  # (it must exist to load the spec)
    spec = _rows_spec(sub, extra="rules: ../rules.yaml")
    assert rules_path(spec) == sub / "../rules.yaml"
    assert rules_path(_rows_spec(sub, name="n.yaml")) is None


def test_columns_and_ship_steps_with_a_two_second_step(tmp_path):
    """With 2 s steps a 300 s run is 150 steps: ship-steps are the drawn ships times 150; every
    column has one entry per pair, n (n - 1) / 2 for n ships, and no time of closest approach
    lies outside 0 .. 300 s or off the 2 s grid."""
    spec = _rows_spec(tmp_path, duration=300, extra="dt_s: 2\nencounter_types: {multi: 1, "
                      "head_on: 1}\nmulti_ships: [3, 4]")
    rows = run_chunk(spec, 0, 4)
    sizes = [len(draw(spec, i).ships) for i in range(4)]
    assert rows["_ship_steps"] == sum(sizes) * 150
    n_pairs = sum(n * (n - 1) // 2 for n in sizes)
    for key, value in rows.items():
        if not key.startswith("_"):
            assert len(value) == n_pairs, key
    t = np.asarray(rows["t_cpa_s"])
    assert np.all((t >= 0) & (t <= 300)) and np.all(t % 2.0 == 0.0)


def test_blind_spot_flags_roles_and_pair_types_agree(tmp_path):
    """A blind spot is flagged exactly where a role is named; an encounter of one other ship
    has its type as the type of its one pair; a pair's start range is at least its start DCPA
    (the DCPA is the smallest range ahead)."""
    spec = _rows_spec(tmp_path, duration=200, extra="sensors: {gnss_sigma_m: [3, 5]}\n"
                      "rogue_fraction: 0.3\nencounter_types: {crossing_give_way: 1, "
                      "head_on: 1, overtaking: 1, multi: 1}")
    rows = run_chunk(spec, 0, 8)
    blind = np.asarray(rows["blind_spot"])
    role = np.asarray(rows["blind_spot_role"], dtype=object)
    np.testing.assert_array_equal(blind, role != "")
    assert set(role[blind]) <= {"give_way", "stand_on", "head_on", "overtaking", "overtaken"}
    enc = np.asarray(rows["encounter"])
    for e in np.unique(enc):
        mine = np.flatnonzero(enc == e)
        kind = rows["encounter_type"][mine[0]]
        assert {rows["encounter_type"][i] for i in mine} == {kind}
        if kind != "multi":
            assert mine.size == 1 and rows["pair_type"][mine[0]] == kind
    assert np.all(np.asarray(rows["range0_nm"]) >= np.asarray(rows["dcpa0_nm"]) - 1e-12)


# --------------------------------------------------------------------------------------------
# running on past duration_s until every pair has passed its closest point
# --------------------------------------------------------------------------------------------

RUN_ON = ("tcpa_min: [8, 12]\nencounter_types: {overtaking: 1, crossing_give_way: 1, "
          "head_on: 1, multi: 1}")


@pytest.fixture(scope="module")
def run_on(tmp_path_factory):
    """Encounters of 8-12 min TCPA run 12 min (``duration_s``), and the same run on up to
    30 min (``max_duration_s``)."""
    folder = tmp_path_factory.mktemp("run_on")
    specs = []
    for name, extra in (("plain", RUN_ON), ("longer", RUN_ON + "\nmax_duration_s: 1800")):
        path = folder / f"{name}.yaml"
        path.write_text(ROWS_SPEC.format(extra=extra, duration=720).replace("seed: 3", "seed: 7"))
        specs.append(load_spec(path))
    return specs[1], run_chunk(specs[0], 0, 8), run_chunk(specs[1], 0, 8)


def _per_encounter(rows, name):
    _, first = np.unique(np.asarray(rows["encounter"]), return_index=True)
    return np.asarray(rows[name])[first]


def test_encounters_still_closing_run_on_until_their_pairs_have_passed(run_on):
    """At 12 min avoidance has delayed some closest points: their pairs are not passed. Run
    on, each encounter ends at the first decision step from 12 min at which all its pairs have
    passed (a whole number of 10 s periods), or at 30 min with the pairs still closing flagged;
    an encounter that had passed at 12 min ends there with the rows it had."""
    spec, plain, longer = run_on
    assert not np.all(plain["cpa_passed"])
    assert np.all(np.asarray(plain["end_s"]) == 720.0)
    end = _per_encounter(longer, "end_s")
    assert np.all((end >= 720.0) & (end <= 1800.0)) and np.all(end % 10.0 == 0.0)
    assert (end > 720.0).sum() >= 2 and ((end > 720.0) & (end < 1800.0)).any()
    enc = np.asarray(longer["encounter"])
    passed = np.asarray(longer["cpa_passed"])
    for e, t in zip(np.unique(enc), end, strict=True):
        mine = enc == e
        assert passed[mine].all() == (t < 1800.0)
        if t == 720.0:  # passed at duration_s: the same rows as without running on
            for key, value in plain.items():
                if not key.startswith("_"):
                    np.testing.assert_array_equal(np.asarray(value)[mine],
                                                  np.asarray(longer[key])[mine], err_msg=key)
    ran_on = np.isin(enc, np.unique(enc)[end > 720.0])
    assert np.all(np.asarray(longer["min_range_m"])[ran_on]
                  <= np.asarray(plain["min_range_m"])[ran_on])
    assert (np.asarray(longer["t_cpa_s"])[ran_on] > 720.0).any()
    assert np.all(np.asarray(longer["t_cpa_s"]) <= np.asarray(longer["end_s"]))
    n_ships = [len(draw(spec, i).ships) for i in range(8)]
    assert longer["_ship_steps"] == sum(n_ships) * round(end.max())


def test_an_ended_encounter_keeps_its_rows_while_its_chunk_runs_on(run_on):
    """Whatever chunk it runs in, with encounters running longer or alone, an encounter's
    rows are the same: its figures stop at its own end."""
    spec, _, whole = run_on
    end = _per_encounter(whole, "end_s")
    parts = [run_chunk(spec, a, b) for a, b in ((0, 2), (2, 3), (3, 8))]
    assert len({float(_per_encounter(p, "end_s").max()) for p in parts}) > 1
    for key, value in whole.items():
        if not key.startswith("_"):
            joined = [v for p in parts for v in np.asarray(p[key]).tolist()]
            np.testing.assert_array_equal(np.asarray(value).tolist(), joined, err_msg=key)
    assert end.min() < end.max()


def test_cpa_passed_is_the_straight_line_test_on_the_true_state(tmp_path):
    """Without avoidance every pair holds its course: ended at its start TCPA's upper end it
    has passed its CPA; stopped half-way it has not (closing, bound to pass nearer)."""
    spec = _rows_spec(tmp_path, extra="policy: no_avoidance\ntcpa_min: [4, 6]", duration=600)
    assert np.all(run_chunk(spec, 0, 4)["cpa_passed"])
    early = run_chunk(spec.model_copy(update={"duration_s": 120.0}), 0, 4)
    own = np.asarray(early["ship_i"]) == "own"
    assert not np.any(np.asarray(early["cpa_passed"])[own])


def test_the_command_line_counts_the_encounters_still_closing(run_on, tmp_path, capsys):
    """``trafficsim campaign`` says how many encounters ended still closing, as
    ``summary.json`` counts them."""
    spec, _, rows = run_on
    out = tmp_path / "out"
    assert main(["campaign", str(spec.path), "--out", str(out), "--workers", "1",
                 "--no-progress"]) == 0
    closing = len(set(np.asarray(rows["encounter"])[~np.asarray(rows["cpa_passed"])]))
    assert closing > 0
    assert json.loads((out / "summary.json").read_text())["cpa_not_passed"] == closing
    assert (f"{closing} encounters still closing at their end (max_duration_s)"
            in capsys.readouterr().out)
