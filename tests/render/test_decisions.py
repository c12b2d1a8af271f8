"""The decision a frame shows for each ship at a time: which pair is chosen, the line of text
(role, encounter, manoeuvre, course order, rule node), from a finished run's table or a running
decider's latest step."""

import math

import numpy as np
import pytest

from tests.render.conftest import Ship
from trafficsim.io.results import write_parquet
from trafficsim.render.data import load_run
from trafficsim.render.decisions import (
    COLUMNS,
    DecisionTable,
    LiveDecisions,
    ShipDecision,
    choose,
    words,
)


def _rows(*rows: dict) -> dict[str, list]:
    """Columns of decision rows; each row gives what it needs, the rest is a quiet default."""
    default = {"t_s": 0.0, "ship": "own", "other": "ts", "rules": "/rules/colregs.yaml",
               "path": "assess", "decided_own_role": "no_role",
               "decided_encounter": "no_encounter", "decided_own_manoeuvre": "no_action",
               "course_order_deg": math.nan, "range_nm": 1.0}
    return {c: [{**default, **r}[c] for r in rows] for c in COLUMNS}


def _decision(**kw) -> ShipDecision:
    base = dict(t_s=0.0, other="ts", role="give_way", encounter="crossing",
                manoeuvre="alter_course", course_order_deg=30.0, node="keep_clear",
                rules="colregs.yaml")
    return ShipDecision(**{**base, **kw})


def test_words_turns_underscores_into_spaces():
    assert words("give_way") == "give way"
    assert words("alter_course") == "alter course"
    assert words("emergency") == "emergency"


def test_a_line_gives_role_encounter_manoeuvre_course_order_and_rule_node():
    assert _decision().line("own") == (
        "own -> ts: give way, crossing; alter course to 030 deg  [colregs.yaml: keep_clear]")


def test_a_line_without_a_course_order_names_only_the_manoeuvre():
    line = _decision(manoeuvre="reduce_speed", course_order_deg=math.nan).line("own")
    assert line == "own -> ts: give way, crossing; reduce speed  [colregs.yaml: keep_clear]"


@pytest.mark.parametrize("order, shown", [(-10.0, "350"), (365.0, "005"), (7.4, "007"),
                                          (0.0, "000"), (359.4, "359")])
def test_course_orders_are_shown_in_three_digits_within_0_to_359(order, shown):
    assert f"alter course to {shown} deg " in _decision(course_order_deg=order).line("own")


@pytest.mark.parametrize("order", [359.6, 359.99])
def test_a_course_order_just_under_north_is_shown_as_000(order):
    # the % 360 shows the intent to keep orders within 000 .. 359; 0.2 deg shows as 000
    assert " to 000 deg " in _decision(course_order_deg=order).line("own")


@pytest.mark.parametrize("role, has_role", [("give_way", True), ("stand_on", True),
                                            ("no_role", False), ("", False)])
def test_has_role_is_false_only_for_no_role_or_empty(role, has_role):
    assert _decision(role=role).has_role is has_role


def test_a_ship_without_a_role_shows_no_role_instead_of_the_encounter():
    line = _decision(role="no_role", encounter="overtaking", manoeuvre="no_action",
                     course_order_deg=math.nan, node="assess").line("own")
    assert line == "own -> ts: no role; no action  [colregs.yaml: assess]"


def test_the_rule_node_is_the_last_node_of_the_path_and_rules_the_file_name():
    cols = _rows({"ship": "a", "path": "assess>risk>crossing>keep_clear",
                  "rules": "/deep/folder/my_rules.yaml"},
                 {"ship": "b", "path": "single_node", "rules": "colregs.yaml"},
                 {"ship": "c", "path": ""})
    shown = choose(cols, range(3))
    assert (shown["a"].node, shown["a"].rules) == ("keep_clear", "my_rules.yaml")
    assert (shown["b"].node, shown["b"].rules) == ("single_node", "colregs.yaml")
    assert shown["c"].node == ""


@pytest.mark.parametrize("asking", ["alter_course", "reduce_speed", "emergency"])
def test_a_manoeuvre_that_asks_something_wins_over_a_closer_role(asking):
    cols = _rows({"other": "near", "decided_own_role": "stand_on", "range_nm": 0.1,
                  "decided_own_manoeuvre": "keep"},
                 {"other": "far", "decided_own_role": "give_way", "range_nm": 5.0,
                  "decided_own_manoeuvre": asking})
    assert choose(cols, range(2))["own"].other == "far"


def test_a_role_wins_over_a_closer_pair_without_one():
    cols = _rows({"other": "near", "range_nm": 0.1},
                 {"other": "far", "decided_own_role": "stand_on", "range_nm": 5.0,
                  "decided_own_manoeuvre": "keep"})
    assert choose(cols, range(2))["own"].other == "far"


def test_without_roles_the_closest_pair_is_shown():
    cols = _rows({"other": "b", "range_nm": 2.0}, {"other": "c", "range_nm": 0.3},
                 {"other": "d", "range_nm": 1.0})
    assert choose(cols, range(3))["own"].other == "c"


def test_an_unknown_range_counts_as_farthest():
    cols = _rows({"other": "unknown", "range_nm": math.nan},
                 {"other": "known", "range_nm": 9.0},
                 {"other": "also_unknown", "range_nm": math.nan})
    assert choose(cols, range(3))["own"].other == "known"


def test_of_equal_pairs_the_first_row_is_kept():
    cols = _rows({"other": "first", "range_nm": 1.0}, {"other": "second", "range_nm": 1.0})
    assert choose(cols, range(2))["own"].other == "first"


def test_choose_looks_only_at_the_rows_given_and_keeps_each_ship_apart():
    cols = _rows({"ship": "a", "other": "x", "range_nm": 0.1},
                 {"ship": "a", "other": "y", "range_nm": 3.0},
                 {"ship": "b", "other": "a", "range_nm": 0.2, "decided_own_role": "give_way"},
                 {"ship": "c", "other": "a"})
    shown = choose(cols, np.array([1, 2]))
    assert set(shown) == {"a", "b"}
    assert shown["a"].other == "y" and shown["b"].other == "a" and shown["b"].has_role


def test_choose_copies_every_field_of_the_row_shown():
    cols = _rows({"t_s": 42.0, "ship": "a", "other": "b", "decided_own_role": "give_way",
                  "decided_encounter": "head_on", "decided_own_manoeuvre": "alter_course",
                  "course_order_deg": 123.0, "path": "x>y", "rules": "/r/c.yaml"})
    assert choose(cols, [0])["a"] == ShipDecision(
        t_s=42.0, other="b", role="give_way", encounter="head_on", manoeuvre="alter_course",
        course_order_deg=123.0, node="y", rules="c.yaml")


def _steps() -> DecisionTable:
    """Three decision steps (t = 10, 20, 30 s) of ship a towards b and c, ship b towards a."""
    rows = []
    for t, closer in ((10.0, "b"), (20.0, "c"), (30.0, "b")):
        for ship, other in (("a", "b"), ("a", "c"), ("b", "a")):
            rows.append({"t_s": t, "ship": ship, "other": other,
                         "range_nm": 0.5 if other == closer or ship == "b" else 2.0})
    return DecisionTable(_rows(*rows))


@pytest.mark.parametrize("t, step, other", [
    (10.0, 10.0, "b"), (15.0, 10.0, "b"), (19.999, 10.0, "b"), (20.0, 20.0, "c"),
    (29.0, 20.0, "c"), (30.0, 30.0, "b"), (1e6, 30.0, "b")])
def test_a_table_gives_the_last_step_at_or_before_the_time(t, step, other):
    shown = _steps().at(t)
    assert set(shown) == {"a", "b"}
    assert shown["a"].t_s == shown["b"].t_s == step and shown["a"].other == other


def test_a_table_shows_nothing_before_its_first_step():
    assert _steps().at(9.99) == {}
    assert _steps().at(-1.0) == {}


def test_a_time_a_rounding_error_short_of_a_step_shows_that_step():
    assert _steps().at(20.0 - 1e-11)["a"].t_s == 20.0
    assert _steps().at(float(np.nextafter(20.0, 0.0)))["a"].t_s == 20.0


def test_an_empty_table_shows_nothing():
    assert DecisionTable({c: [] for c in COLUMNS}).at(100.0) == {}


def test_rows_out_of_time_order_are_refused():
    with pytest.raises(ValueError, match="not in time order"):
        DecisionTable(_rows({"t_s": 20.0}, {"t_s": 10.0}))


def test_a_table_answers_the_same_after_many_steps_were_asked():
    table = DecisionTable(_rows(*({"t_s": float(t), "other": f"s{t}"} for t in range(200))))
    first = {t: table.at(float(t))["own"].other for t in range(200)}  # past any cache size
    assert first == {t: f"s{t}" for t in range(200)}
    assert table.at(3.5)["own"].other == "s3" and table.at(150.0)["own"].other == "s150"


def test_a_decisions_parquet_in_a_run_folder_is_read_and_shown(synthetic_run):
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 1000.0, 0.0, 180.0)], 5)
    cols = _rows({"t_s": 5.0, "ship": "a", "other": "b", "decided_own_role": "give_way",
                  "decided_encounter": "head_on", "decided_own_manoeuvre": "alter_course",
                  "course_order_deg": 35.0, "path": "assess>head_on>turn_starboard",
                  "rules": "/somewhere/colregs.yaml"},
                 {"t_s": 5.0, "ship": "b", "other": "a"})
    extra = {"decided_other_role": ["give_way", "give_way"], "f_range_nm": [0.5, 0.5]}
    write_parquet(run / "decisions.parquet",
                  {k: (v if isinstance(v[0], str) else np.asarray(v))
                   for k, v in {**cols, **extra}.items()})
    data = load_run(run)
    assert data.decisions is not None
    assert data.decisions.at(0.0) == {}
    shown = data.decisions.at(float(data.t_s[3]))
    assert shown["a"].line("a") == ("a -> b: give way, head on; alter course to 035 deg  "
                                    "[colregs.yaml: turn_starboard]")
    assert shown["b"].line("b") == "b -> a: no role; no action  [colregs.yaml: assess]"


class FakeDecider:
    """A decider's recording side: ``history`` holds steps ``(t_s, rows)``; ``records`` turns
    the steps held into columns (as :meth:`Decider.records`)."""

    def __init__(self) -> None:
        self.history: list[tuple[float, list[dict]]] = []
        self.calls: list[int] = []  # shared with copies (LiveDecisions reads a copy)

    def records(self, names):
        self.calls.append(len(self.history))
        return _rows(*({"t_s": t, **r} for t, rows in self.history for r in rows))


def test_live_decisions_show_nothing_before_the_first_step():
    assert LiveDecisions(FakeDecider(), ["own", "ts"]).at(100.0) == {}


def test_live_decisions_show_the_latest_step_only():
    decider = FakeDecider()
    live = LiveDecisions(decider, ["own", "a", "b"])
    decider.history.append((10.0, [{"other": "a", "decided_own_role": "give_way"}]))
    assert live.at(10.0)["own"].other == "a"
    decider.history.append((20.0, [{"other": "b", "range_nm": 3.0}]))
    shown = live.at(20.0)
    # a role at step 10 would win over step 20's pair if older steps were still looked at
    assert shown["own"].other == "b" and shown["own"].t_s == 20.0
    assert len(decider.history) == 2  # the decider keeps its history


def test_live_decisions_show_nothing_for_a_time_before_the_latest_step():
    decider = FakeDecider()
    live = LiveDecisions(decider, ["own", "ts"])
    decider.history.append((20.0, [{}]))
    assert live.at(19.0) == {}
    assert live.at(20.0 - 1e-11)["own"].t_s == 20.0
    assert live.at(25.0)["own"].t_s == 20.0


def test_live_decisions_read_the_decider_again_only_after_a_new_step():
    decider = FakeDecider()
    live = LiveDecisions(decider, ["own", "ts"])
    decider.history.append((5.0, [{}]))
    for t in (5.0, 6.0, 7.0):
        live.at(t)
    assert decider.calls == [1]  # once, and with the latest step only
    decider.history.append((10.0, [{}]))
    assert live.at(10.0)["own"].t_s == 10.0 and decider.calls == [1, 1]
