"""Tests of the decision-network compiler, the compiled evaluator and its explanations.

The differential test runs random networks (written as rule files) through the compiled kernel
and through a plain-Python reference evaluator that reads the same data as written, sharing no
code with the engine.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trafficsim.colregs.network import (
    OP_ALL,
    OP_ANY,
    OP_BETWEEN,
    OP_EQ,
    OP_FALSE,
    OP_GT,
    OP_LE,
    OP_NOT,
    OP_TRUE,
    ActionField,
    Vocabulary,
    compile_rules,
    evaluate,
    explain,
    load,
    loads,
)
from trafficsim.colregs.rulefile import parse
from trafficsim.errors import ScenarioError

from .test_rulefile import VOCAB, written_test, written_value

HERE = Path(__file__).parent
EXAMPLE = HERE / "rules" / "valid" / "example.yaml"
NAN = math.nan


def _features(**columns: list[float]) -> np.ndarray:
    """``(n_features, m)`` array of VOCAB features; unnamed features are NaN."""
    m = len(next(iter(columns.values())))
    out = np.full((len(VOCAB.features), m), NAN)
    for name, values in columns.items():
        out[VOCAB.features.index(name)] = values
    return out


def _one_node(test: str) -> str:
    return ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            f"  a: {{test: {test}, yes: {{to: y, next: true}}, no: {{to: n, next: true}}}}\n"
            "  y: {test: true, yes: {to: a, next: true}}\n"
            "  n: {test: true, yes: {to: a, next: true}}\n")


def _holds(test: str, values: list[float], feature: str = "range_nm") -> list[bool]:
    net = loads(_one_node(test), VOCAB)
    decision = evaluate(net, _features(**{feature: values}), net.initial_cursor(len(values)))
    return [bool(c == net.node_index("y")) for c in decision.cursor]


# ------------------------------------------------------------------------------------------
# Compiler
# ------------------------------------------------------------------------------------------

def test_example_compiles_to_the_hand_written_arrays() -> None:
    net = load(EXAMPLE, VOCAB)
    assert net.node_names == ("assess", "classify", "give_way", "monitor")
    assert net.start == 0
    f = VOCAB.features.index
    # assess: [tcpa_min, between, [0, 20]]
    # classify: {all: [[bearing <= 6], {any: [[speed_ratio > 1], {not: [own_role == 1]}]}]}
    # give_way: true; monitor: [tcpa_min > 0]
    expected = [(OP_BETWEEN, f("tcpa_min"), 0.0, 20.0),
                (1, f("bearing_deg"), 6.0, 6.0),        # OP_LE
                (OP_GT, f("speed_ratio"), 1.0, 1.0),
                (4, f("own_role"), 1.0, 1.0),           # OP_EQ
                (OP_NOT, 1, 0.0, 0.0),
                (OP_ANY, 2, 0.0, 0.0),
                (OP_ALL, 2, 0.0, 0.0),
                (OP_TRUE, 0, 0.0, 0.0),
                (OP_GT, f("tcpa_min"), 0.0, 0.0)]
    got = list(zip(net.code.tolist(), net.arg.tolist(), net.lo.tolist(), net.hi.tolist(),
                   strict=True))
    assert got == expected
    assert OP_LE == 1
    assert net.prog_start.tolist() == [0, 1, 7, 8, 9]
    # rows: no, yes; -1 = omitted dead branch of the literal test of give_way
    assert net.child.tolist() == [[0, 0, -1, 0], [1, 2, 3, 3]]
    assert net.child_next.tolist() == [[True, True, False, True], [False, False, True, True]]
    assert net.action_fields == ("role", "manoeuvre", "direction", "course_change_deg",
                                 "speed_factor")
    table = np.full((4, 5), NAN)
    table[2, :4] = [1.0, 1.0, 1.0, 30.0]  # give_way, alter_course, starboard, turn_deg
    np.testing.assert_array_equal(net.actions, table)
    # classify evaluates speed_ratio while bearing's result waits, then own_role under not
    # while two wait: 3 deep; longest immediate chain assess -> classify -> give_way
    assert (net.max_stack, net.max_depth) == (3, 3)


def test_max_depth_is_the_longest_immediate_chain() -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            "  a: {test: [range_nm, '<', 1], yes: b, no: d}\n"
            "  b: {test: [range_nm, '<', 0.25], yes: c, no: d}\n"
            "  c: {test: true, yes: d}\n"
            "  d: {test: true, yes: {to: a, next: true}}\n")
    net = loads(text, VOCAB)
    assert net.max_depth == 4
    d = evaluate(net, _features(range_nm=[0.1, 0.5, 5.0]), net.initial_cursor(3))
    assert d.path.tolist() == [[0, 1, 2, 3], [0, 1, 3, -1], [0, 3, -1, -1]]
    assert d.path_len.tolist() == [4, 3, 2]
    assert d.cursor.tolist() == [0, 0, 0]


def test_deeply_nested_tests_need_a_deep_stack() -> None:
    test = "[range_nm, '<', 1]"
    for _ in range(6):
        test = f"{{all: [true, {{any: [false, {test}]}}]}}"
    net = loads(_one_node(test), VOCAB)
    assert net.max_stack == 13
    assert _holds(test, [0.0, 2.0, NAN]) == [True, False, False]


# ------------------------------------------------------------------------------------------
# Evaluation semantics
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("op, value, expected", [
    ("'<'", 1, [True, False, False, False]),
    ("'<='", 1, [True, True, False, False]),
    ("'>'", 1, [False, False, True, False]),
    ("'>='", 1, [False, True, True, False]),
    ("'=='", 1, [False, True, False, False]),
    ("'!='", 1, [True, False, True, False]),
    ("between", "[1, 2]", [False, True, True, False]),
    ("between", "[1, 1]", [False, True, False, False]),
])
def test_operators_at_their_boundaries_and_nan(op: str, value: Any, expected: list[bool]
                                               ) -> None:
    values = [0.5, 1.0, 2.0, NAN]
    assert _holds(f"[range_nm, {op}, {value}]", values) == expected


def test_nan_makes_every_comparison_false_but_not_inverts_it() -> None:
    values = [NAN]
    assert _holds("[range_nm, '!=', 3]", values) == [False]
    assert _holds("{not: [range_nm, '==', 3]}", values) == [True]
    assert _holds("{any: [[range_nm, '<', 1], [range_nm, '>=', 1]]}", values) == [False]


def test_literals_and_combinators() -> None:
    values = [0.0, 1.5, 3.0]
    assert _holds("true", values) == [True] * 3
    assert _holds("false", values) == [False] * 3
    assert _holds("{all: [[range_nm, '>', 1], [range_nm, '<', 2]]}", values) == [
        False, True, False]
    assert _holds("{any: [[range_nm, '<', 1], [range_nm, '>', 2]]}", values) == [
        True, False, True]
    assert _holds("{not: {any: [[range_nm, '<', 1], [range_nm, '>', 2]]}}", values) == [
        False, True, False]
    assert _holds("{all: [true]}", values) == [True] * 3
    assert _holds("{any: [false]}", values) == [False] * 3


def test_enum_constants_compare_as_floats() -> None:
    values = [0.0, 1.0, 2.0]  # undecided, give_way, stand_on
    assert _holds("[own_role, '==', give_way]", values, "own_role") == [False, True, False]
    assert _holds("[own_role, '>=', give_way]", values, "own_role") == [False, True, True]


def test_example_decisions_by_hand() -> None:
    net = load(EXAMPLE, VOCAB)
    # pair 0: tcpa 10 in [0, 20], bearing 3 <= 6, speed ratio 0.5, own_role undecided
    #         -> not(give_way) holds -> give_way node (action) -> next: monitor
    # pair 1: tcpa 30 outside the look-ahead -> next: assess
    # pair 2: bearing 10 > 6 -> classify says no -> next: assess
    # pair 3: tcpa NaN -> between is false -> next: assess
    # pair 4: starts at monitor, tcpa -1 -> next: assess (no action)
    # pair 5: starts at monitor, tcpa 4 -> stays at monitor
    feats = _features(tcpa_min=[10, 30, 10, NAN, -1, 4], bearing_deg=[3, 3, 10, 3, 3, 3],
                      speed_ratio=[0.5, 0.5, 0.5, 0.5, 0.5, 0.5],
                      own_role=[0, 0, 0, 0, 0, 0])
    cursor = np.array([0, 0, 0, 0, 3, 3])
    d = evaluate(net, feats, cursor)
    assert d.cursor.tolist() == [3, 0, 0, 0, 0, 3]
    assert d.path.tolist() == [[0, 1, 2], [0, -1, -1], [0, 1, -1], [0, -1, -1], [3, -1, -1],
                               [3, -1, -1]]
    assert d.path_len.tolist() == [3, 1, 2, 1, 1, 1]
    assert d.path.dtype == np.int32 and d.cursor.dtype == np.int64
    np.testing.assert_array_equal(d.action("course_change_deg"), [30, NAN, NAN, NAN, NAN, NAN])
    np.testing.assert_array_equal(d.action("direction"), [1, NAN, NAN, NAN, NAN, NAN])
    assert np.isnan(d.action("speed_factor")).all()
    assert d.actions.shape == (5, 6)
    cursor_before = cursor.copy()
    evaluate(net, feats, cursor)
    np.testing.assert_array_equal(cursor, cursor_before)  # inputs are not modified


def test_later_nodes_overwrite_earlier_action_fields_within_a_call() -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            "  a: {test: true, action: {course_change_deg: 10, role: give_way}, yes: b}\n"
            "  b: {test: [range_nm, '<', 1], action: {course_change_deg: 20}, yes: c, "
            "no: {to: a, next: true}}\n"
            "  c: {test: true, action: {speed_factor: 0.5, role: stand_on}, "
            "yes: {to: a, next: true}}\n")
    net = loads(text, VOCAB)
    d = evaluate(net, _features(range_nm=[0.0, 2.0]), net.initial_cursor(2))
    assert d.action("course_change_deg").tolist() == [20.0, 20.0]
    assert d.action("role").tolist() == [2.0, 1.0]
    np.testing.assert_array_equal(d.action("speed_factor"), [0.5, NAN])
    # a next step starts afresh: no action carries over from the previous call
    d2 = evaluate(net, _features(range_nm=[0.0, 2.0]), d.cursor)
    np.testing.assert_array_equal(d2.actions, d.actions)


def test_literal_false_with_only_a_no_child() -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            "  a: {test: false, no: b}\n"
            "  b: {test: true, yes: {to: a, next: true}}\n")
    net = loads(text, VOCAB)
    assert net.child[:, 0].tolist() == [1, -1]
    d = evaluate(net, _features(range_nm=[0.0]), net.initial_cursor(1))
    assert d.path[0].tolist() == [0, 1] and d.cursor.tolist() == [0]


def test_empty_batch_and_input_checks() -> None:
    net = load(EXAMPLE, VOCAB)
    d = evaluate(net, np.zeros((len(VOCAB.features), 0)), np.zeros(0, dtype=int))
    assert d.cursor.shape == (0,) and d.actions.shape == (5, 0) and d.path.shape == (0, 3)
    with pytest.raises(ValueError, match="features must have shape"):
        evaluate(net, np.zeros((3, 2)), np.zeros(2, dtype=int))
    with pytest.raises(ValueError, match="cursor must have shape"):
        evaluate(net, np.zeros((len(VOCAB.features), 2)), np.zeros(3, dtype=int))
    with pytest.raises(ValueError, match=r"outside 0\.\.3"):
        evaluate(net, np.zeros((len(VOCAB.features), 2)), np.array([0, 4]))
    with pytest.raises(ValueError, match="outside"):
        evaluate(net, np.zeros((len(VOCAB.features), 1)), np.array([-1]))
    assert net.node_index("monitor") == 3
    with pytest.raises(KeyError):
        net.node_index("nope")


def test_load_reports_errors_located() -> None:
    with pytest.raises(ScenarioError) as info:
        loads("schema_version: 1\nname: t\nstart: a\nnodes:\n  a: {test: [x, '<', 1]}\n",
              VOCAB, "mine.yaml")
    assert str(info.value).startswith("mine.yaml:5: nodes.a")


# ------------------------------------------------------------------------------------------
# Explanation
# ------------------------------------------------------------------------------------------

def test_explain_tells_the_path_with_values() -> None:
    net = load(EXAMPLE, VOCAB)
    feats = _features(tcpa_min=[10.0], bearing_deg=[3.0], speed_ratio=[0.5], own_role=[1.0])
    feats[VOCAB.features.index("own_role")] = 0.0
    d = evaluate(net, feats, net.initial_cursor(1))
    text = explain(net, d.path[0], feats[:, 0])
    lines = text.splitlines()
    assert lines[0] == (f"1. assess ({EXAMPLE}:11): Is the other ship a hazard within the "
                        "look-ahead time?")
    assert lines[1] == ("   test [tcpa_min, between, [0, look_ahead_min]]: tcpa_min = 10, "
                        "look_ahead_min = 20 -> yes")
    assert lines[2] == "   yes -> classify (now)"
    assert "   test {all: [[bearing_deg, <=, head_on_deg], {any: [[speed_ratio, >, 1], " \
           "{not: [own_role, ==, give_way]}]}]} -> yes" in lines
    assert "       [bearing_deg, <=, head_on_deg]: bearing_deg = 3, head_on_deg = 6 -> true" \
        in lines
    assert "         [speed_ratio, >, 1]: speed_ratio = 0.5 -> false" in lines
    assert "           [own_role, ==, give_way]: own_role = 0, give_way = 1 -> false" in lines
    assert ("   action: role = give_way, manoeuvre = alter_course, direction = starboard, "
            "course_change_deg = turn_deg (30)") in lines
    assert lines[-1] == "   yes -> monitor (next step)"


def test_explain_marks_missing_values_and_named_constants() -> None:
    net = loads(_one_node("{any: [[range_nm, '<', 1], [own_role, '==', give_way]]}"), VOCAB)
    feats = _features(range_nm=[NAN], own_role=[1.0])
    d = evaluate(net, feats, net.initial_cursor(1))
    text = explain(net, d.path[0], feats[:, 0])
    assert "range_nm = NaN (missing value: comparison is false) -> false" in text
    assert "[own_role, ==, give_way]: own_role = 1 (give_way), give_way = 1 -> true" in text


EXTENDS = HERE / "rules" / "extends"


def test_explain_names_the_file_of_each_node_of_an_extended_rule_set() -> None:
    net = load(EXTENDS / "grandchild.yaml", VOCAB)
    feats = _features(tcpa_min=[10.0], range_nm=[0.5])
    d = evaluate(net, feats, net.initial_cursor(1))
    assert [net.node_names[k] for k in d.path[0, :d.path_len[0]]] == ["watch", "decide", "slow"]
    assert d.action("speed_factor").tolist() == [0.5]
    lines = explain(net, d.path[0], feats[:, 0]).splitlines()
    base, me = EXTENDS / "base.yaml", EXTENDS / "grandchild.yaml"
    assert lines[0] == (f"1. watch ({base}:12): Is the other ship a hazard within the "
                        "look-ahead time?")
    assert lines[3] == (f"2. decide ({me}:10): Close in? Then slow down (base.yaml's turn is no "
                        "longer reached).")
    assert lines[6] == f"3. slow ({me}:15)"
    assert "   action: manoeuvre = reduce_speed, speed_factor = slow_factor (0.5)" in lines


def test_enum_parameter_override_changes_the_action_and_its_explanation() -> None:
    feats = _features(tcpa_min=[10.0, 10.0], own_role=[1.0, 0.0])
    sides = {}
    for name in ("base", "turn_port"):
        net = load(EXTENDS / f"{name}.yaml", VOCAB)
        d = evaluate(net, feats, net.initial_cursor(2))
        # pair 0 gives way (own_role == ahead_role == give_way) and turns; pair 1 does not
        assert d.path[0].tolist() == [0, 1, 2] and d.path_len.tolist() == [3, 2]
        sides[name] = d.action("direction").tolist()
        text = explain(net, d.path[0], feats[:, 0])
        assert ("   test [own_role, ==, ahead_role]: own_role = 1 (give_way), ahead_role = "
                "give_way (1) -> yes") in text
        side = "starboard" if name == "base" else "port"
        assert (f"   action: manoeuvre = alter_course, direction = side ({side}), "
                "course_change_deg = turn_deg (30)") in text
        assert f"3. turn ({EXTENDS / 'base.yaml'}:21)" in text
    assert sides["base"][0] == VOCAB.enums["starboard"] == 1.0
    assert sides["turn_port"][0] == VOCAB.enums["port"] == -1.0
    assert math.isnan(sides["base"][1]) and math.isnan(sides["turn_port"][1])


def test_late_action_override_moves_the_threshold() -> None:
    feats = _features(tcpa_min=[4.0, 10.0], own_role=[0.0, 0.0])
    for name, expected in (("base", [2, 2]), ("late", [2, 1])):
        net = load(EXTENDS / f"{name}.yaml", VOCAB)
        d = evaluate(net, feats, net.initial_cursor(2))
        assert d.path_len.tolist() == expected, name


def test_explain_refuses_features_that_do_not_match_the_path() -> None:
    net = load(EXAMPLE, VOCAB)
    feats = _features(tcpa_min=[10.0], bearing_deg=[3.0], speed_ratio=[0.5], own_role=[0.0])
    d = evaluate(net, feats, net.initial_cursor(1))
    feats[VOCAB.features.index("tcpa_min")] = 50.0
    with pytest.raises(ValueError, match="do not lead along this path"):
        explain(net, d.path[0], feats[:, 0])


# ------------------------------------------------------------------------------------------
# Differential test against a plain-Python reference
# ------------------------------------------------------------------------------------------

DIFF_VOCAB = Vocabulary(
    features=("a", "b", "c"),
    enums={"red": 1.0, "blue": 2.0},
    actions={"colour": ActionField(("red", "blue")), "x": ActionField(), "y": ActionField()})
PARAMS = {"p": 1.5, "q": -1.0}
VALUES = [-2.0, -1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0, NAN]
OPS = ["<", "<=", ">", ">=", "==", "!=", "between"]


def _resolve(value: Any) -> float:
    return written_value(value, PARAMS, DIFF_VOCAB)


def _ref_test(test: Any, feats: dict[str, float]) -> bool:
    """Reference semantics, straight from the language description."""
    return written_test(test, feats, PARAMS, DIFF_VOCAB)


def _ref_run(net: dict[str, Any], feats: dict[str, float], node: str
             ) -> tuple[str, dict[str, float], list[str]]:
    actions: dict[str, float] = {}
    path = []
    while True:
        path.append(node)
        spec = net["nodes"][node]
        for key, value in spec.get("action", {}).items():
            actions[key] = _resolve(value)
        edge = spec["yes"] if _ref_test(spec["test"], feats) else spec["no"]
        if isinstance(edge, str):
            edge = {"to": edge}
        if edge.get("next", False):
            return edge["to"], actions, path
        node = edge["to"]


@st.composite
def _comparison(draw: st.DrawFn) -> list[Any]:
    feature = draw(st.sampled_from(DIFF_VOCAB.features))
    op = draw(st.sampled_from(OPS))
    number = st.sampled_from([-2, -1, 0, 0.5, 1, 1.5, 2, 3])
    if op == "between":
        lo = draw(st.one_of(number, st.sampled_from(list(PARAMS))))
        hi = draw(st.one_of(number, st.sampled_from(list(PARAMS))))
        if _resolve(lo) > _resolve(hi):
            lo, hi = hi, lo
        return [feature, op, [lo, hi]]
    return [feature, op, draw(st.one_of(number, st.sampled_from([*PARAMS, "red", "blue"])))]


_TESTS = st.recursive(
    st.one_of(_comparison(), st.booleans()),
    lambda inner: st.one_of(
        st.lists(inner, min_size=1, max_size=3).map(lambda items: {"all": items}),
        st.lists(inner, min_size=1, max_size=3).map(lambda items: {"any": items}),
        inner.map(lambda item: {"not": item})),
    max_leaves=6)


@st.composite
def _network(draw: st.DrawFn) -> dict[str, Any]:
    """A random valid network: immediate edges only point to later nodes (no loops)."""
    n = draw(st.integers(1, 8))
    names = [f"n{k}" for k in range(n)]
    nodes: dict[str, Any] = {}
    for k, name in enumerate(names):
        spec: dict[str, Any] = {"test": draw(_TESTS)}
        for branch in ("yes", "no"):
            later = names[k + 1:]
            if later and draw(st.booleans()):
                target = draw(st.sampled_from(later))
                spec[branch] = target if draw(st.booleans()) else {"to": target, "next": False}
            else:
                spec[branch] = {"to": draw(st.sampled_from(names)), "next": True}
        if isinstance(spec["test"], bool) and draw(st.booleans()):
            del spec["no" if spec["test"] else "yes"]  # the dead branch may be omitted
        fields = draw(st.lists(st.sampled_from(["colour", "x", "y"]), unique=True, max_size=3))
        if fields:
            spec["action"] = {f: draw(st.sampled_from(["red", "blue"])) if f == "colour"
                              else draw(st.one_of(st.sampled_from([-30, 0, 12.5]),
                                                  st.sampled_from(list(PARAMS))))
                              for f in fields}
        nodes[name] = spec
    reached, frontier = {"n0"}, ["n0"]
    while frontier:
        spec = nodes[frontier.pop()]
        for branch in ("yes", "no"):
            if branch in spec:
                edge = spec[branch]
                target = edge if isinstance(edge, str) else edge["to"]
                if target not in reached:
                    reached.add(target)
                    frontier.append(target)
    kept = {name: spec for name, spec in nodes.items() if name in reached}
    text = repr(kept)  # a file may declare no parameter that nothing uses
    return {"schema_version": 1, "name": "random", "start": "n0",
            "parameters": {k: v for k, v in PARAMS.items() if f"'{k}'" in text}, "nodes": kept}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(net_data=_network(), data=st.data())
def test_kernel_matches_the_reference_evaluator(net_data: dict[str, Any],
                                                data: st.DataObject) -> None:
    text = yaml.safe_dump(net_data, sort_keys=False)
    net = compile_rules(parse(text, DIFF_VOCAB, "random.yaml"), DIFF_VOCAB)
    m = data.draw(st.integers(1, 12))
    feats = np.array(data.draw(st.lists(st.lists(st.sampled_from(VALUES), min_size=m,
                                                 max_size=m), min_size=3, max_size=3)))
    cursor = np.array(data.draw(st.lists(st.integers(0, net.n_nodes - 1), min_size=m,
                                         max_size=m)))
    d = evaluate(net, feats, cursor)
    for i in range(m):
        values = dict(zip(DIFF_VOCAB.features, feats[:, i], strict=True))
        to, actions, path = _ref_run(net_data, values, net.node_names[cursor[i]])
        assert net.node_names[d.cursor[i]] == to
        assert [net.node_names[k] for k in d.path[i, :d.path_len[i]]] == path
        assert (d.path[i, d.path_len[i]:] == -1).all()
        for row, name in enumerate(DIFF_VOCAB.actions):
            if name in actions:
                assert d.actions[row, i] == actions[name]
            else:
                assert math.isnan(d.actions[row, i])
        explain(net, d.path[i], feats[:, i])  # consistent with the kernel: does not raise


def test_load_reuses_a_compiled_file_until_it_or_a_file_it_extends_changes(tmp_path) -> None:
    for name in ("base.yaml", "turn_port.yaml"):
        (tmp_path / name).write_bytes((EXTENDS / name).read_bytes())
    child = tmp_path / "turn_port.yaml"
    first = load(child, VOCAB)
    assert load(child, VOCAB) is first
    base = tmp_path / "base.yaml"
    text = base.read_text()
    assert "turn_deg: 30" in text
    base.write_text(text.replace("turn_deg: 30", "turn_deg: 40"))  # same size, same second
    again = load(child, VOCAB)
    assert again is not first
    assert again.rules.parameters["turn_deg"] == 40.0 and first.rules.parameters["turn_deg"] == 30.0
    base.unlink()
    with pytest.raises(ScenarioError):
        load(child, VOCAB)


# ------------------------------------------------------------------------------------------
# A tiny rule file written to disk, run exactly as written
# ------------------------------------------------------------------------------------------

TINY_VOCAB = Vocabulary(
    features=("a", "b"),
    enums={"low": -2.0, "high": 4.0},
    actions={"level": ActionField(("low", "high")), "n": ActionField()})

_PY_OPS = {"<": lambda x, c: x < c, "<=": lambda x, c: x <= c, ">": lambda x, c: x > c,
           ">=": lambda x, c: x >= c, "==": lambda x, c: x == c, "!=": lambda x, c: x != c}
_SAMPLES = [-math.inf, -3.0, -2.0, -0.0, 0.0, 1.0, 2.5, 4.0, 7.0, math.inf, NAN]


_TINY_PARAMS = {"lim": "2.5", "lo_p": "-2", "hi_p": "4", "lvl": "high"}


def _tiny_file(tmp_path: Path, test: str) -> Path:
    """A three-node file testing ``test``; it declares the parameters ``test`` uses (a file
    may declare no parameter that nothing uses)."""
    path = tmp_path / "tiny.yaml"
    used = ", ".join(f"{k}: {v}" for k, v in _TINY_PARAMS.items()
                     if re.search(rf"\b{k}\b", test))
    path.write_text("schema_version: 1\nname: tiny\nstart: t\n"
                    f"parameters: {{{used}}}\nnodes:\n"
                    f"  t: {{test: {test}, yes: {{to: y, next: true}}, "
                    "no: {to: n, next: true}}\n"
                    "  y: {test: true, yes: {to: t, next: true}}\n"
                    "  n: {test: true, yes: {to: t, next: true}}\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("op", list(_PY_OPS))
@pytest.mark.parametrize(("operand", "value"), [("2.5", 2.5), ("lim", 2.5), ("low", -2.0),
                                                ("lvl", 4.0), ("0", 0.0), ("-0.0", 0.0)])
def test_every_operator_on_every_operand_kind(tmp_path: Path, op: str, operand: str,
                                              value: float) -> None:
    """``[a, op, v]`` with v a number, a parameter, an enum constant or an enum-valued
    parameter holds exactly where Python's operator does on the resolved float, infinities
    included; NaN is false for every operator."""
    net = load(_tiny_file(tmp_path, f"[a, '{op}', {operand}]"), TINY_VOCAB)
    feats = np.array([_SAMPLES, np.zeros(len(_SAMPLES))])
    d = evaluate(net, feats, net.initial_cursor(len(_SAMPLES)))
    held = [bool(c == net.node_index("y")) for c in d.cursor]
    want = [False if math.isnan(x) else _PY_OPS[op](x, value) for x in _SAMPLES]
    assert held == want


@pytest.mark.parametrize(("bounds", "lo", "hi"), [("[lo_p, hi_p]", -2.0, 4.0),
                                                  ("[-2, lim]", -2.0, 2.5),
                                                  ("[lim, lim]", 2.5, 2.5),
                                                  ("[-.inf, 0]", None, None)])
def test_between_is_inclusive_on_both_ends(tmp_path: Path, bounds: str, lo: float | None,
                                           hi: float | None) -> None:
    if lo is None:  # an infinite bound is refused at load, located
        with pytest.raises(ScenarioError) as info:
            load(_tiny_file(tmp_path, f"[a, between, {bounds}]"), TINY_VOCAB)
        assert info.value.key == "nodes.t.test[2][0]" and info.value.line == 6
        return
    net = load(_tiny_file(tmp_path, f"[b, between, {bounds}]"), TINY_VOCAB)
    feats = np.array([np.zeros(len(_SAMPLES)), _SAMPLES])
    d = evaluate(net, feats, net.initial_cursor(len(_SAMPLES)))
    held = [bool(c == net.node_index("y")) for c in d.cursor]
    assert held == [(not math.isnan(x)) and lo <= x <= hi for x in _SAMPLES]


def test_a_tiny_network_over_several_steps(tmp_path: Path) -> None:
    """Hand trace of a watch / act / monitor network over three decision steps for three
    pairs, with the cursors, paths and merged actions each step."""
    path = tmp_path / "watch.yaml"
    path.write_text(
        "schema_version: 1\n"              # 1
        "name: watch\n"                     # 2
        "start: watch\n"                    # 3
        "parameters: {near: 2, lvl: low}\n"  # 4
        "nodes:\n"                          # 5
        "  watch:\n"                        # 6
        "    test: [a, '<', near]\n"        # 7
        "    action: {level: high}\n"       # 8
        "    yes: act\n"                    # 9
        "    no: {to: watch, next: true}\n"  # 10
        "  act:\n"                          # 11
        "    test: {not: [b, '>', 0]}\n"    # 12
        "    action: {level: lvl, n: 1}\n"  # 13
        "    yes: {to: monitor, next: true}\n"  # 14
        "    no: monitor\n"                 # 15
        "  monitor:\n"                      # 16
        "    test: {any: [[a, '>=', 5], [b, '==', high]]}\n"  # 17
        "    action: {n: 2}\n"              # 18
        "    yes: {to: watch, next: true}\n"  # 19
        "    no: {to: monitor, next: true}\n",  # 20
        encoding="utf-8")
    net = load(path, TINY_VOCAB)
    assert net.node_names == ("watch", "act", "monitor") and net.max_depth == 3
    W, A, M = 0, 1, 2
    cursor = net.initial_cursor(3)
    # step 1: a = 1, 3, 1; b = 0, 0, 1
    d = evaluate(net, np.array([[1.0, 3.0, 1.0], [0.0, 0.0, 1.0]]), cursor)
    # pair 0: watch (a < 2) -> act: not(b > 0) holds -> next monitor; level: high then low
    # pair 1: watch: a = 3 -> next watch; level high
    # pair 2: watch -> act: b > 0, so not fails -> monitor now (n = 2, later wins) -> any:
    #         a >= 5 no, b == 4 no -> next monitor
    assert d.path.tolist() == [[W, A, -1], [W, -1, -1], [W, A, M]]
    assert d.cursor.tolist() == [M, W, M]
    assert d.action("level").tolist() == [-2.0, 4.0, -2.0]
    np.testing.assert_array_equal(d.action("n"), [1.0, NAN, 2.0])
    # step 2: the monitors see a = 6 (pair 0) and b = high (pair 2); pair 1 closes in
    d = evaluate(net, np.array([[6.0, 1.5, 0.0], [0.0, 7.0, 4.0]]), d.cursor)
    assert d.path.tolist() == [[M, -1, -1], [W, A, M], [M, -1, -1]]
    assert d.cursor.tolist() == [W, M, W]
    np.testing.assert_array_equal(d.action("level"), [NAN, -2.0, NAN])
    assert d.action("n").tolist() == [2.0, 2.0, 2.0]
    # explanation of pair 1 names the file and the lines written above
    lines = explain(net, d.path[1], np.array([1.5, 7.0])).splitlines()
    assert lines[0] == f"1. watch ({path}:6)"
    assert lines[1] == "   test [a, <, near]: a = 1.5, near = 2 -> yes"
    assert lines[2] == "   action: level = high"
    assert lines[3] == "   yes -> act (now)"
    assert lines[4] == f"2. act ({path}:11)"
    assert "   action: level = lvl (low), n = 1" in lines
    assert lines[-1] == "   no -> monitor (next step)"
    # step 3, same features, from an int32 cursor and a Fortran-ordered array:
    # pair 0 watch: a = 6 -> next watch; pair 1 monitor: neither holds -> next monitor;
    # pair 2 watch -> act (b = 4 > 0: not fails) -> monitor now: b == high -> next watch
    feats = np.asfortranarray(np.array([[6.0, 1.5, 0.0], [0.0, 7.0, 4.0]]))
    before = feats.copy()
    d3 = evaluate(net, feats, d.cursor.astype(np.int32))
    np.testing.assert_array_equal(feats, before)
    assert d3.cursor.tolist() == [W, M, W]
    assert d3.path.tolist() == [[W, -1, -1], [M, -1, -1], [W, A, M]]


def test_compiled_tables_of_a_tiny_file(tmp_path: Path) -> None:
    """The postfix program of ``{all: [[a, >, 1], {not: [b, ==, high]}, {any: [false, true]}]}``
    written out by hand, and the stack it needs: 4 (the all's first two results wait while the
    any's two items are on the stack)."""
    net = load(_tiny_file(tmp_path, "{all: [[a, '>', 1], {not: [b, '==', high]}, "
                                    "{any: [false, true]}]}"), TINY_VOCAB)
    got = list(zip(net.code.tolist(), net.arg.tolist(), net.lo.tolist(), net.hi.tolist(),
                   strict=True))
    assert got[:7] == [(OP_GT, 0, 1.0, 1.0), (OP_EQ, 1, 4.0, 4.0), (OP_NOT, 1, 0.0, 0.0),
                       (OP_FALSE, 0, 0.0, 0.0), (OP_TRUE, 0, 0.0, 0.0), (OP_ANY, 2, 0.0, 0.0),
                       (OP_ALL, 3, 0.0, 0.0)]
    assert net.max_stack == 4
    feats = np.array([[2.0, 2.0, 0.0, NAN], [0.0, 4.0, 0.0, 0.0]])
    d = evaluate(net, feats, net.initial_cursor(4))
    assert [net.node_names[c] for c in d.cursor] == ["y", "n", "n", "n"]


# ------------------------------------------------------------------------------------------
# The documented example, verbatim
# ------------------------------------------------------------------------------------------

DOCS = HERE.parents[1] / "docs" / "rules.md"


def _docs_block(after: str) -> str:
    """The first fenced block of docs/rules.md after the line containing ``after``."""
    lines = DOCS.read_text(encoding="utf-8").splitlines()
    k = next(i for i, line in enumerate(lines) if after in line)
    start = next(i for i in range(k, len(lines)) if lines[i].startswith("```")) + 1
    end = next(i for i in range(start, len(lines)) if lines[i].startswith("```"))
    return "\n".join(lines[start:end])


def test_explanation_of_the_docs_example_is_the_documented_text() -> None:
    """docs/rules.md prints the explanation of pair 0 of its worked example; ``explain`` gives
    that text, with the file named as it was loaded."""
    net = load(EXAMPLE, VOCAB)
    feats = _features(tcpa_min=[10.0, 30.0, 10.0], bearing_deg=[3.0, 3.0, 12.0],
                      speed_ratio=[0.5, 0.5, 0.5], own_role=[0.0, 0.0, 0.0])
    d = evaluate(net, feats, net.initial_cursor(3))
    expected = _docs_block("The explanation of pair 0").replace("(example.yaml:",
                                                                 f"({EXAMPLE}:")
    assert explain(net, d.path[0], feats[:, 0]) == expected
    assert d.cursor.tolist() == [3, 0, 0]
    assert [d.path[i, :d.path_len[i]].tolist() for i in range(3)] == [[0, 1, 2], [0], [0, 1]]


def test_example_network_on_a_grid_against_a_hand_evaluation() -> None:
    """example.yaml from ``assess``, every combination of boundary values: ``assess`` holds on
    0 <= tcpa <= 20 (inclusive), ``classify`` on bearing <= 6 (6 included) and (speed_ratio
    > 1 or own_role != give_way (1)), NaN making each comparison false (so NaN own_role makes
    the ``not`` hold)."""
    import itertools

    tcpa = [-1e-9, 0.0, 20.0, 20.000001, NAN]
    bearing = [-180.0, 5.999999, 6.0, 6.000001, NAN]
    ratio = [0.5, 1.0, 1.000001, math.inf, NAN]
    role = [0.0, 1.0, 2.0, NAN]
    combos = list(itertools.product(tcpa, bearing, ratio, role))
    cols = list(zip(*combos, strict=True))
    feats = _features(tcpa_min=list(cols[0]), bearing_deg=list(cols[1]),
                      speed_ratio=list(cols[2]), own_role=list(cols[3]))
    net = load(EXAMPLE, VOCAB)
    d = evaluate(net, feats, net.initial_cursor(len(combos)))
    for i, (t, b, r, o) in enumerate(combos):
        hazard = 0.0 <= t <= 20.0
        classify = hazard and b <= 6.0 and (r > 1.0 or o != 1.0)
        path = [0] + ([1] if hazard else []) + ([2] if classify else [])
        assert d.path[i, :d.path_len[i]].tolist() == path, combos[i]
        assert d.cursor[i] == (3 if classify else 0)
        turn = d.action("course_change_deg")[i]
        assert turn == 30.0 if classify else math.isnan(turn)


# ------------------------------------------------------------------------------------------
# Content-free: the engine attaches no meaning to any name
# ------------------------------------------------------------------------------------------

_RENAME = {
    # features
    "tcpa_min": "zorp", "dcpa_nm": "quux_q", "range_nm": "blit", "bearing_deg": "wimble",
    "aspect_deg": "frob", "speed_ratio": "gnarl", "own_role": "mood",
    # enum constants and action fields
    "undecided": "meh", "give_way": "blorp", "stand_on": "snark", "port": "lefty",
    "starboard": "righty", "keep_course": "plain", "alter_course": "twist",
    "reduce_speed": "creep", "role": "stance", "manoeuvre": "move", "direction": "side_x",
    "course_change_deg": "amount", "speed_factor": "slowness",
    # nodes and parameters of example.yaml
    "assess": "n_one", "classify": "n_two", "monitor": "n_four", "look_ahead_min": "p_far",
    "turn_deg": "p_turn", "head_on_deg": "p_cone", "example": "toy",
}
#: the features in another order than VOCAB's
_TOY_FEATURES = ("mood", "gnarl", "frob", "wimble", "blit", "quux_q", "zorp")


def _toy_vocab() -> Vocabulary:
    return Vocabulary(
        features=_TOY_FEATURES,
        enums={_RENAME[k]: v + 0.0 for k, v in VOCAB.enums.items()},
        actions={_RENAME[k]: ActionField(tuple(_RENAME[c] for c in f.constants))
                 for k, f in VOCAB.actions.items()})


def _renamed(text: str) -> str:
    # the node give_way shares its name with the enum constant; rename the node separately
    text = re.sub(r"^  give_way:", "  n_three:", text, flags=re.MULTILINE)
    text = text.replace("yes: give_way\n", "yes: n_three\n")
    return re.sub(r"\b(" + "|".join(sorted(_RENAME, key=len, reverse=True)) + r")\b",
                  lambda m: _RENAME[m.group(1)], text)


def test_engine_is_content_free_under_a_renaming_of_every_name(tmp_path: Path) -> None:
    """example.yaml with every node, parameter, feature, constant and field renamed to
    invented words, run with a vocabulary of those words (features in another order): the same
    node indices, paths, cursors and actions as the original on random features, and the
    explanation differs only by the renaming."""
    toy_path = tmp_path / "toy.yaml"
    toy_path.write_text(_renamed(EXAMPLE.read_text(encoding="utf-8")), encoding="utf-8")
    for word in ("tcpa_min", "assess", "give_way", "starboard", "course_change_deg"):
        assert word not in toy_path.read_text()
    toy = load(toy_path, _toy_vocab())
    net = load(EXAMPLE, VOCAB)
    assert toy.node_names == ("n_one", "n_two", "n_three", "n_four")
    rng = np.random.default_rng(7)
    m = 400
    feats = _features(tcpa_min=list(rng.choice([-1.0, 0.0, 10.0, 20.0, 25.0, NAN], m)),
                      bearing_deg=list(rng.choice([0.0, 6.0, 7.0, NAN], m)),
                      speed_ratio=list(rng.choice([0.5, 1.0, 2.0], m)),
                      own_role=list(rng.choice([0.0, 1.0, 2.0], m)),
                      dcpa_nm=list(rng.random(m)), range_nm=list(rng.random(m)),
                      aspect_deg=list(rng.random(m)))
    toy_feats = np.array([feats[VOCAB.features.index(next(k for k, v in _RENAME.items()
                                                          if v == name))]
                          for name in _TOY_FEATURES])
    cursor = rng.integers(0, 4, m)
    a, b = evaluate(net, feats, cursor), evaluate(toy, toy_feats, cursor)
    np.testing.assert_array_equal(a.cursor, b.cursor)
    np.testing.assert_array_equal(a.path, b.path)
    for field, value in zip(VOCAB.actions, a.actions, strict=True):
        np.testing.assert_array_equal(b.action(_RENAME[field]), value)
    for i in range(12):
        text = explain(net, a.path[i], feats[:, i]).replace(str(EXAMPLE), "@PATH@")
        text = re.sub(r"(\d\. |-> )give_way \(", r"\1n_three (", text)
        assert explain(toy, b.path[i], toy_feats[:, i]) == _renamed(text).replace(
            "@PATH@", str(toy_path))
    assert (a.path_len == 3).any() and (a.path_len == 1).any()


def test_a_toy_network_of_invented_words_by_hand(tmp_path: Path) -> None:
    """A three-node file about nothing in particular, traced by hand."""
    vocab = Vocabulary(features=("hunger", "ripeness"), enums={"apple": 7.0, "pear": 9.0},
                       actions={"pick": ActionField(("apple", "pear")), "bites": ActionField()})
    path = tmp_path / "orchard.yaml"
    path.write_text(
        "schema_version: 1\nname: orchard\nstart: hungry\nparameters: {fav: pear}\nnodes:\n"
        "  hungry: {test: [hunger, '>=', 3], yes: ripe, no: {to: hungry, next: true}}\n"
        "  ripe:\n    test: {any: [[ripeness, '==', apple], [ripeness, '==', fav]]}\n"
        "    action: {pick: fav, bites: 2}\n    yes: eat\n    no: {to: hungry, next: true}\n"
        "  eat: {test: true, action: {bites: 5}, yes: {to: hungry, next: true}}\n",
        encoding="utf-8")
    net = load(path, vocab)
    # pair 0: hunger 3 >= 3, ripeness 9 == pear: ripe sets pick pear, bites 2; eat bites 5
    # pair 1: hunger 3, ripeness 8 matches neither: pick pear, bites 2, back to hungry
    # pair 2: hunger 2.9 < 3: nothing
    d = evaluate(net, np.array([[3.0, 3.0, 2.9], [9.0, 8.0, 9.0]]), net.initial_cursor(3))
    assert [d.path[i, :d.path_len[i]].tolist() for i in range(3)] == [[0, 1, 2], [0, 1], [0]]
    np.testing.assert_array_equal(d.action("pick"), [9.0, 9.0, NAN])
    np.testing.assert_array_equal(d.action("bites"), [5.0, 2.0, NAN])
    assert d.cursor.tolist() == [0, 0, 0]
    assert "pick = fav (pear)" in explain(net, d.path[0], [3.0, 9.0])


# ------------------------------------------------------------------------------------------
# Input checks of evaluate
# ------------------------------------------------------------------------------------------

def test_a_cursor_that_is_not_a_node_index_is_refused() -> None:
    """``evaluate``'s docstring: ValueError for "a cursor that is not a node index"; 2.7 is
    none, and silently running from node 2 hides a caller's mistake."""
    net = load(EXAMPLE, VOCAB)
    feats = _features(tcpa_min=[10.0], bearing_deg=[3.0], speed_ratio=[0.5], own_role=[0.0])
    with pytest.raises(ValueError):
        evaluate(net, feats, np.array([2.7]))


def test_integer_cursors_of_any_integer_dtype_are_the_same() -> None:
    """int8 / int32 / uint16 / int64 cursors give one decision."""
    net = load(EXAMPLE, VOCAB)
    feats = _features(tcpa_min=[10.0, 1.0, -1.0, 10.0], bearing_deg=[3.0] * 4,
                      speed_ratio=[0.5] * 4, own_role=[0.0] * 4)
    base = evaluate(net, feats, np.array([0, 3, 3, 1]))
    for dtype in (np.int8, np.int32, np.uint16):
        d = evaluate(net, feats, np.array([0, 3, 3, 1], dtype=dtype))
        np.testing.assert_array_equal(d.cursor, base.cursor)
        np.testing.assert_array_equal(d.path, base.path)


# ------------------------------------------------------------------------------------------
# The bundled COLREGS network (rules/colregs.yaml) with the COLREGS vocabulary
# ------------------------------------------------------------------------------------------

RULES = HERE.parents[1] / "rules"
REFERENCE = HERE.parents[2] / "shared" / "reference" / "imazu.yaml"

#: feature values of a pair at its first step (memory at its start values, docs/rules.md)
_START = {"range_nm": 5.0, "bearing_deg": 0.0, "aspect_deg": 0.0, "course_diff_deg": 0.0,
          "dcpa_nm": 0.0, "tcpa_min": 20.0, "bcr_nm": math.inf, "bct_min": math.inf,
          "speed_ratio": 1.0, "own_speed_kn": 12.0, "other_speed_kn": 12.0, "domain_nm": 0.5,
          "time_to_domain_min": math.inf, "predicted_domain_entry": 0.0,
          "visibility_nm": 10.0, "own_role": 0.0, "encounter": 10.0, "other_role": 0.0,
          "own_manoeuvre": 20.0, "time_in_role_min": 0.0, "other_course_change_deg": 0.0,
          "other_speed_change_ratio": 1.0, "own_course_change_deg": 0.0}


def _colregs_feats(rows: list[dict[str, float]]) -> np.ndarray:
    """``(n_features, m)`` in VOCABULARY order; the *_abs_deg and range_to_domain_nm features
    follow from the signed ones as the vocabulary defines them."""
    from trafficsim.colregs.vocabulary import VOCABULARY

    out = np.empty((len(VOCABULARY.features), len(rows)))
    for i, row in enumerate(rows):
        f = {**_START, **row}
        f["bearing_abs_deg"] = abs(f["bearing_deg"])
        f["aspect_abs_deg"] = abs(f["aspect_deg"])
        f["course_diff_abs_deg"] = abs(f["course_diff_deg"])
        f["range_to_domain_nm"] = f["range_nm"] - f["domain_nm"]
        out[:, i] = [f[name] for name in VOCABULARY.features]
    return out


def _colregs_net():
    from trafficsim.colregs.vocabulary import VOCABULARY

    return load(RULES / "colregs.yaml", VOCABULARY)


def _step(net, rows: list[dict[str, float]], start: str | list[str] = "assess"):
    """(path names, {field: value or enum name}, cursor name) of each pair after one step."""
    from trafficsim.colregs.vocabulary import VOCABULARY

    starts = [start] * len(rows) if isinstance(start, str) else start
    d = evaluate(net, _colregs_feats(rows), np.array([net.node_index(s) for s in starts]))
    numeric = {k for k, f in VOCABULARY.actions.items() if f.numeric}
    out = []
    for i in range(len(rows)):
        acts = {}
        for field in VOCABULARY.actions:
            v = d.action(field)[i]
            if not math.isnan(v):
                acts[field] = float(v) if field in numeric else next(
                    c for c in VOCABULARY.actions[field].constants if VOCABULARY.enums[c] == v)
        out.append(([net.node_names[k] for k in d.path[i, :d.path_len[i]]], acts,
                    net.node_names[d.cursor[i]]))
    return out


# documented defaults (docs/rules.md, table of rules/colregs.yaml parameters)
_LOOK, _CPA, _ACT, _TURN, _HEAD, _RECIP, _ABAFT, _RV, _SLOW = (
    30.0, 1.0, 15.0, 30.0, 10.0, 165.0, 112.5, 2.0, 0.5)
_ACT_NM = 2.7  # give_way_act_nm


def _hand_first_step(f: dict[str, float]) -> tuple[list[str], dict, str]:
    """One decision step from ``assess`` with the memory at its start values, written from the
    diagram and parameter table of docs/rules.md (Rules 7, 13, 14, 15, 16, 19)."""
    path, act = ["assess"], {}
    b, a, cd, sr = f["bearing_deg"], f["aspect_deg"], abs(f["course_diff_deg"]), f["speed_ratio"]

    def risk() -> bool:
        return f["dcpa_nm"] < _CPA and 0.0 <= f["tcpa_min"] <= _LOOK

    def give_way_wait(node: str = "give_way_wait") -> str:
        path.append(node)
        # the range test is not the overtaking ship's (overtaking_wait)
        close = node == "give_way_wait" and f["range_nm"] <= _ACT_NM and f["tcpa_min"] <= _LOOK
        if f["tcpa_min"] <= _ACT or f["time_to_domain_min"] <= _ACT or close:
            path.append("give_way_act")
            act.update(manoeuvre="alter_course", course_change_deg=_TURN, pass_distance_nm=1.0)
            return "keep_clear"
        return "give_way_still"

    def role(node: str, own: str, encounter: str, other: str, side: str) -> None:
        path.append(node)
        act.update(role=own, encounter=encounter, other_role=other, direction=side)

    if f["visibility_nm"] < _RV:
        path.append("rv_risk")
        if not risk():
            return path, act, "assess"
        path.append("rv_side")
        if abs(b) < 90.0:
            role("rv_forward", "no_role", "restricted_visibility", "no_role", "starboard")
            act["speed_factor"] = _SLOW
        else:
            path.append("rv_abaft")
            if b > 0.0:
                role("rv_abaft_starboard", "no_role", "restricted_visibility", "no_role", "port")
            else:
                role("rv_abaft_port", "no_role", "restricted_visibility", "no_role",
                     "starboard")
        return path, act, give_way_wait()
    path.append("risk")
    if not risk():
        return path, act, "assess"
    path.append("overtaking")
    if abs(a) > _ABAFT and sr < 1.0:
        role("give_way_overtaking", "give_way", "overtaking", "stand_on", "either")
        return path, act, give_way_wait("overtaking_wait")
    path.append("overtaken")
    if abs(b) > _ABAFT and sr > 1.0:
        role("stand_on_overtaken", "stand_on", "overtaken", "give_way", "either")
        act["manoeuvre"] = "keep"
        return path, act, "overtaken_watch"
    path.append("head_on")
    if abs(b) <= _HEAD and abs(a) <= _HEAD and cd >= _RECIP:
        role("head_on_role", "mutual_give_way", "head_on", "mutual_give_way", "starboard")
        return path, act, give_way_wait()
    path.append("crossing_side")
    if b > 0.0:
        path.append("crossing_starboard")
        if a > 0.0:
            role("mutual_crossing", "mutual_give_way", "crossing", "mutual_give_way",
                 "starboard")
        else:
            role("give_way_crossing", "give_way", "crossing", "stand_on", "starboard")
        return path, act, give_way_wait()
    path.append("crossing_port")
    if a > 0.0:
        role("stand_on_crossing", "stand_on", "crossing", "give_way", "starboard")
        act["manoeuvre"] = "keep"
        return path, act, "stand_on_watch"
    role("mutual_crossing", "mutual_give_way", "crossing", "mutual_give_way", "starboard")
    return path, act, give_way_wait()


_EPS = 1e-9
_ANGLES = [-180.0, -112.5 - _EPS, -112.5, -90.0, -10.0 - _EPS, -10.0, -0.0, 0.0, 10.0,
           10.0 + _EPS, 45.0, 112.5, 112.5 + _EPS, 180.0, NAN]


def test_bundled_classification_on_a_boundary_grid() -> None:
    """Every combination of bearing and aspect at and beside the documented sector limits
    (10 deg, 112.5 deg, 0, 180), course differences at 165 deg, speed ratios at 1: the first
    step of rules/colregs.yaml matches the hand-written classification node for node, with
    the same actions and cursor. Exactly 112.5 deg is not "more than 22.5 deg abaft the beam";
    exactly 10 deg and exactly 165 deg are head-on."""
    import itertools

    rows = [{"bearing_deg": b, "aspect_deg": a, "course_diff_deg": c, "speed_ratio": r}
            for b, a, c, r in itertools.product(_ANGLES, _ANGLES,
                                                [0.0, 165.0 - _EPS, 165.0, -180.0],
                                                [0.5, 1.0, 1.0 + _EPS])]
    got = _step(_colregs_net(), rows)
    for row, result in zip(rows, got, strict=True):
        assert result == _hand_first_step({**_START, **row}), row
    # the grid reaches every classification node
    reached = {name for path, _, _ in got for name in path}
    assert {"give_way_overtaking", "stand_on_overtaken", "head_on_role", "mutual_crossing",
            "give_way_crossing", "stand_on_crossing"} <= reached


def test_bundled_risk_window_timing_and_restricted_visibility_grid() -> None:
    """Rule 7 window (dcpa < 1 NM, 0 <= tcpa <= 30 min, both ends included), the early-action
    threshold (tcpa or time to domain <= 15 min) and the Rule 19 branch (visibility < 2 NM;
    forward of the beam below 90 deg, abeam counts as abaft), against the hand classification."""
    import itertools

    rows = [{"visibility_nm": v, "dcpa_nm": dc, "tcpa_min": t, "time_to_domain_min": ttd,
             "bearing_deg": b, "aspect_deg": -b if not math.isnan(b) else NAN,
             "course_diff_deg": 90.0}
            for v, dc, t, ttd, b in itertools.product(
                [10.0, _RV, _RV - _EPS], [0.0, 1.0 - _EPS, 1.0, NAN],
                [-_EPS, 0.0, 15.0, 15.0 + _EPS, 30.0, 30.0 + _EPS, math.inf, NAN],
                [math.inf, 15.0, 15.0 + _EPS], [-90.0, 90.0, 90.0 - _EPS, -45.0, 180.0])]
    got = _step(_colregs_net(), rows)
    for row, result in zip(rows, got, strict=True):
        assert result == _hand_first_step({**_START, **row}), row
    asked = [r for r, (_, act, _) in zip(rows, got, strict=True)
             if act.get("manoeuvre") == "alter_course"]
    assert asked and all(r["tcpa_min"] <= 15.0 or r["time_to_domain_min"] <= 15.0
                         for r in asked)


_ROLE_OF = {  # reference expected_os_role (prefix) -> role, encounter, other role, side
    "head-on": ("mutual_give_way", "head_on", "mutual_give_way", "starboard"),
    "OS give-way": ("give_way", "crossing", "stand_on", "starboard"),
    "OS overtaking": ("give_way", "overtaking", "stand_on", "either"),
    "OS stand-on": ("stand_on", "crossing", "give_way", "starboard"),
}
_DNV_CLASS = {"head_on": "head-on", "crossing_give_way": "OS give-way",
              "overtaking_give_way": "OS overtaking", "crossing_stand_on": "OS stand-on"}


def _fold(deg: float) -> float:
    """Degrees to (-180, 180]."""
    out = math.fmod(deg, 360.0)
    if out > 180.0:
        out -= 360.0
    elif out <= -180.0:
        out += 360.0
    return out


def _imazu_targets() -> list[tuple[int, dict]]:
    import yaml

    data = yaml.safe_load(REFERENCE.read_text(encoding="utf-8"))
    return [(case["id"], t) for case in data["cases"] for t in case["targets"]]


def _imazu_rows(own_view: bool) -> list[dict[str, float]]:
    """Features of each Imazu target from the reference's derived values (own ship north at
    12 kn; every ship reaches the origin at 30 min: DCPA 0, TCPA 30 min), seen by the own
    ship, or by the target (bearing and aspect swap, the course difference and speed ratio
    invert)."""
    rows = []
    for _, t in _imazu_targets():
        d = t["derived"]
        beta, alpha = _fold(d["rel_bearing_from_os_deg"]), _fold(d["aspect_os_seen_from_ts_deg"])
        course, ratio = _fold(t["course_deg"]), t["speed_kn"] / 12.0
        if not own_view:
            beta, alpha, course, ratio = alpha, beta, _fold(-course), 1.0 / ratio
        rows.append({"range_nm": d["range_nm"], "bearing_deg": beta, "aspect_deg": alpha,
                     "course_diff_deg": course, "speed_ratio": ratio,
                     "dcpa_nm": d["dcpa_nm"], "tcpa_min": d["tcpa_min"]})
    return rows


def test_bundled_rules_give_the_reference_roles_of_the_imazu_cases() -> None:
    """Every target of the 22 Imazu cases at t = 0 (TCPA exactly 30 min, the inclusive end of
    the look-ahead): the own ship's role, encounter, expected role of the other and side are
    those of the reference's ``expected_os_role`` (and its DNV class agrees); give-way ships
    wait for the action time (those starting within give_way_act_nm act at once, but for an
    overtaking ship), the stand-on ship keeps course and watches."""
    targets = _imazu_targets()
    assert len(targets) == 50
    got = _step(_colregs_net(), _imazu_rows(own_view=True))
    for (case, t), (path, act, cursor) in zip(targets, got, strict=True):
        key = next(k for k in _ROLE_OF if t["expected_os_role"].startswith(k))
        assert _DNV_CLASS[t["derived"]["class_dnv_trafficgen"]] == key
        role, encounter, other, side = _ROLE_OF[key]
        assert (act.get("role"), act.get("encounter"), act.get("other_role"),
                act.get("direction")) == (role, encounter, other, side), (case, t["name"], path)
        if role == "stand_on":
            assert act["manoeuvre"] == "keep" and cursor == "stand_on_watch"
        elif t["derived"]["range_nm"] <= 2.7 and encounter != "overtaking":
            # a target starting at close quarters (give_way_act_nm): act at once
            assert act["manoeuvre"] == "alter_course" and cursor == "keep_clear"
        else:
            assert "manoeuvre" not in act and cursor == "give_way_still"


def test_imazu_roles_seen_from_the_targets_are_the_complement() -> None:
    """The same encounters seen by each target: every pair has one give-way and one stand-on
    ship (or both mutual_give_way in a head-on), the overtaken target stands on, and each
    ship's expected role of the other is the role the other takes: no blind spot."""
    net = _colregs_net()
    own = _step(net, _imazu_rows(own_view=True))
    other = _step(net, _imazu_rows(own_view=False))
    partner = {"give_way": "stand_on", "stand_on": "give_way",
               "mutual_give_way": "mutual_give_way"}
    for (_, a, _), (path, b, cursor) in zip(own, other, strict=True):
        assert b["role"] == partner[a["role"]], path
        assert a["other_role"] == b["role"] and b["other_role"] == a["role"]
        if a["encounter"] == "overtaking":
            assert b["encounter"] == "overtaken" and cursor == "overtaken_watch"
            assert b["direction"] == "either" and b["manoeuvre"] == "keep"
        else:
            assert b["encounter"] == a["encounter"]


def test_around_the_clock_encounters_by_the_rules_sectors() -> None:
    """The reference's "Around the Clock" set: own ship north, a target of equal speed on
    course k x 15 deg (k = 1..23), both reaching a common point at 25 min. Bearing and aspect
    computed here from the positions. With equal speeds nobody overtakes; courses within 15 deg
    of reciprocal (165, 180, 195: each ship 7.5 deg or less off the other's bow) are head-on;
    a target coming from port (course 15..150) is crossed as stand-on, from starboard
    (210..345) as give-way."""
    speed_nm_min = 12.0 / 60.0
    dist = 25.0 * speed_nm_min
    rows, expected = [], []
    for k in range(1, 24):
        c = 15.0 * k
        tx, ty = -dist * math.sin(math.radians(c)), -dist * math.cos(math.radians(c))
        ox, oy = 0.0, -dist
        beta = _fold(math.degrees(math.atan2(tx - ox, ty - oy)))
        alpha = _fold(math.degrees(math.atan2(ox - tx, oy - ty)) - c)
        rows.append({"range_nm": math.hypot(tx - ox, ty - oy), "bearing_deg": beta,
                     "aspect_deg": alpha, "course_diff_deg": _fold(c), "speed_ratio": 1.0,
                     "tcpa_min": 25.0, "dcpa_nm": 0.0})
        expected.append("stand_on" if c < 165.0 else "give_way" if c > 195.0
                        else "mutual_give_way")
    got = _step(_colregs_net(), rows)
    assert [act["role"] for _, act, _ in got] == expected
    assert [act["encounter"] for _, act, _ in got] == [
        "head_on" if r == "mutual_give_way" else "crossing" for r in expected]
    assert abs(rows[10]["bearing_deg"] + 7.5) < 1e-9 and rows[10]["course_diff_deg"] == 165.0


_GW = {"bearing_deg": 45.0, "aspect_deg": -45.0, "course_diff_deg": 90.0, "tcpa_min": 20.0,
       "dcpa_nm": 0.0}
_HEAD_ON, _OVERTAKING, _OVERTAKEN = 11.0, 13.0, 14.0  # the encounter constants (docs/rules.md)
_MUTUAL = 3.0  # the mutual_give_way role
#: an overtaking ship after her alteration: range opening at 1.5 NM
_OT = {"encounter": _OVERTAKING, "tcpa_min": -0.5, "range_nm": 1.5, "bearing_deg": -150.0,
       "aspect_deg": 30.0, "dcpa_nm": 1.2}
_CLEAR = {"role": "no_role", "encounter": "no_encounter", "other_role": "no_role",
          "manoeuvre": "resume_route"}
#: a stand-on ship closing slowly with a give-way ship that has not acted (Rule 17(a)(ii))
_SLOW_CLOSE = {"tcpa_min": 25.0, "range_nm": 1.62, "dcpa_nm": 1.0 - _EPS,
               "time_to_domain_min": 20.0, "time_in_role_min": 3.0, "bearing_deg": -85.0,
               "aspect_deg": 75.0, "other_course_change_deg": 10.0 - _EPS,
               "other_speed_change_ratio": 0.8 + _EPS}


@pytest.mark.parametrize(("start", "row", "path", "actions", "cursor"), [
    # give_way_still: risk remains; tcpa just above 15 and domain entry after 15: wait
    ("give_way_still", {**_GW, "tcpa_min": 15.0 + _EPS, "time_to_domain_min": 15.5},
     ["give_way_still", "give_way_wait"], {}, "give_way_still"),
    # tcpa exactly 15 = action_time_min: act, turn_deg 30, pass_distance_nm 1
    ("give_way_still", {**_GW, "tcpa_min": 15.0},
     ["give_way_still", "give_way_wait", "give_way_act"],
     {"manoeuvre": "alter_course", "course_change_deg": 30.0, "pass_distance_nm": 1.0},
     "keep_clear"),
    # the risk is gone (dcpa exactly 1 is not < 1): clear, forget the encounter
    ("give_way_still", {**_GW, "dcpa_nm": 1.0},
     ["give_way_still", "risk_gone", "mutual_still", "clear"], _CLEAR, "assess"),
    # ... but in a head-on or mutual crossing (Rule 14) the own ship still alters in her turn
    # while the CPA is ahead and under far_clear_nm (2), whatever the other ship did
    ("give_way_still", {**_GW, "dcpa_nm": 2.0 - _EPS, "own_role": _MUTUAL,
                        "encounter": _HEAD_ON},
     ["give_way_still", "risk_gone", "mutual_still"], {}, "give_way_wait"),
    *[("give_way_still", {**_GW, "dcpa_nm": 1.5, "own_role": _MUTUAL, "encounter": _HEAD_ON,
                          **row},
       ["give_way_still", "risk_gone", "mutual_still", "clear"], _CLEAR, "assess")
      for row in ({"dcpa_nm": 2.0}, {"tcpa_min": -_EPS})],
    # ... but an overtaking ship stays the give-way ship until past and clear (Rule 13(d))
    ("give_way_still", {**_GW, "dcpa_nm": 1.0, "encounter": _OVERTAKING},
     ["give_way_still", "risk_gone", "overtaking_watch", "overtaking_risk"], {},
     "overtaking_watch"),
    # keep_clear: past CPA but range exactly clear_nm: not yet clear; no emergency
    ("keep_clear", {"tcpa_min": -0.5, "range_nm": 1.0, "bearing_deg": 150.0},
     ["keep_clear", "past_and_clear", "emergency_check"], {}, "keep_clear"),
    # range 1.5 > 1 but the other exactly 112.5 deg off the bow and within 2 NM: not clear
    ("keep_clear", {"tcpa_min": -0.5, "range_nm": 1.5, "bearing_deg": -112.5},
     ["keep_clear", "past_and_clear", "emergency_check"], {}, "keep_clear"),
    # ... more than 22.5 deg abaft the beam: past and clear
    ("keep_clear", {"tcpa_min": -0.5, "range_nm": 1.5, "bearing_deg": -112.5 - _EPS},
     ["keep_clear", "past_and_clear", "clear"], _CLEAR, "assess"),
    # ... or beyond far_clear_nm (2 NM) whatever the bearing; exactly 2 is not beyond
    ("keep_clear", {"tcpa_min": -0.5, "range_nm": 2.0, "bearing_deg": 10.0},
     ["keep_clear", "past_and_clear", "emergency_check"], {}, "keep_clear"),
    ("keep_clear", {"tcpa_min": -0.5, "range_nm": 2.0 + _EPS, "bearing_deg": 10.0},
     ["keep_clear", "past_and_clear", "clear"], _CLEAR, "assess"),
    # Rule 17(b): domain entry exactly emergency_min (2) ahead, CPA not past: emergency
    ("keep_clear", {"tcpa_min": 0.0, "range_nm": 0.4, "time_to_domain_min": 2.0},
     ["keep_clear", "past_and_clear", "emergency_check", "emergency"],
     {"manoeuvre": "emergency", "course_change_deg": 60.0, "speed_factor": 0.5,
      "pass_distance_nm": 1.0}, "keep_clear"),
    ("keep_clear", {"tcpa_min": -_EPS, "range_nm": 0.4, "time_to_domain_min": 2.0},
     ["keep_clear", "past_and_clear", "emergency_check"], {}, "keep_clear"),
    # Rule 13(d), the overtaking ship: finally past and clear once the range opens beyond
    # clear_nm with the overtaken ship more than 22.5 deg abaft her beam and herself more than
    # 22.5 deg forward of the overtaken ship's beam; each limit itself is not beyond it
    ("keep_clear", {**_OT, "bearing_deg": -112.5 - _EPS, "aspect_deg": 67.5 - _EPS},
     ["keep_clear", "overtaking_keep_clear", "clear"], _CLEAR, "assess"),
    *[("keep_clear", {**_OT, **row}, ["keep_clear", "overtaking_keep_clear",
                                      "overtaking_apart", "emergency_check"], {}, "keep_clear")
      for row in ({"bearing_deg": -112.5}, {"aspect_deg": 67.5}, {"range_nm": 1.0},
                  {"tcpa_min": 0.0})],
    # ... abeam at 1.9 NM, the overtaken ship abaft her beam only because she altered course
    # (30 deg off the overtaken ship's course): not past
    ("keep_clear", {**_OT, "range_nm": 1.9, "bearing_deg": -120.0, "aspect_deg": 97.5},
     ["keep_clear", "overtaking_keep_clear", "overtaking_apart", "emergency_check"], {},
     "keep_clear"),
    # ... beyond far_clear_nm abeam (the old release): back to the route, still give-way
    ("keep_clear", {**_OT, "range_nm": 2.0 + _EPS, "bearing_deg": -90.0, "aspect_deg": 105.0},
     ["keep_clear", "overtaking_keep_clear", "overtaking_apart", "overtaking_resume"],
     {"manoeuvre": "resume_route"}, "overtaking_watch"),
    ("keep_clear", {**_OT, "range_nm": 2.0, "bearing_deg": -90.0, "aspect_deg": 105.0},
     ["keep_clear", "overtaking_keep_clear", "overtaking_apart", "emergency_check"], {},
     "keep_clear"),
    # the overtaken ship after acting (Rule 17): the same geometry seen from her
    ("keep_clear", {**_OT, "encounter": _OVERTAKEN, "bearing_deg": 67.5 - _EPS,
                    "aspect_deg": -112.5 - _EPS},
     ["keep_clear", "overtaking_keep_clear", "clear"], _CLEAR, "assess"),
    ("keep_clear", {**_OT, "encounter": _OVERTAKEN, "range_nm": 2.0 + _EPS,
                    "bearing_deg": 75.0, "aspect_deg": -105.0},
     ["keep_clear", "overtaking_keep_clear", "overtaking_apart", "overtaking_resume"],
     {"manoeuvre": "resume_route"}, "overtaken_watch"),
    # overtaking_watch (resuming, still give-way): a new risk of collision with the pair
    # abeam, which a fresh look would call a crossing (aspect 100 < 112.5): overtaking again
    ("overtaking_watch", {"encounter": _OVERTAKING, "tcpa_min": 3.0, "range_nm": 0.5,
                          "dcpa_nm": 0.3, "bearing_deg": -60.0, "aspect_deg": 100.0,
                          "speed_ratio": 0.6},
     ["overtaking_watch", "overtaking_risk", "give_way_overtaking", "overtaking_wait",
      "give_way_act"],
     {"role": "give_way", "encounter": "overtaking", "other_role": "stand_on",
      "direction": "either", "manoeuvre": "alter_course", "course_change_deg": 30.0,
      "pass_distance_nm": 1.0}, "keep_clear"),
    ("overtaking_watch", {"encounter": _OVERTAKING, "tcpa_min": -1.0, "range_nm": 3.0,
                          "dcpa_nm": 1.5, "bearing_deg": -80.0, "aspect_deg": 100.0},
     ["overtaking_watch", "overtaking_risk"], {}, "overtaking_watch"),
    ("overtaking_watch", {"encounter": _OVERTAKING, "tcpa_min": -1.0, "range_nm": 1.0 + _EPS,
                          "dcpa_nm": 1.5, "bearing_deg": 112.5 + _EPS,
                          "aspect_deg": -67.5 + _EPS},
     ["overtaking_watch", "clear"], _CLEAR, "assess"),
    # Rule 17(a)(ii): domain entry within 10 min, other turned < 10 deg, kept > 0.8 speed
    ("stand_on_watch", {"tcpa_min": 5.0, "time_to_domain_min": 10.0,
                        "other_course_change_deg": 10.0 - _EPS,
                        "other_speed_change_ratio": 0.8 + _EPS},
     ["stand_on_watch", "stand_on_check", "stand_on_act"],
     {"manoeuvre": "reduce_speed", "speed_factor": 0.5, "pass_distance_nm": 1.0},
     "keep_clear"),
    ("stand_on_watch", {"tcpa_min": 5.0, "time_to_domain_min": 10.0,
                        "other_course_change_deg": 10.0},
     ["stand_on_watch", "stand_on_check", "stand_on_close"], {}, "stand_on_watch"),
    ("stand_on_watch", {"tcpa_min": 5.0, "time_to_domain_min": 10.0,
                        "other_speed_change_ratio": 0.8},
     ["stand_on_watch", "stand_on_check", "stand_on_close"], {}, "stand_on_watch"),
    ("stand_on_watch", {"tcpa_min": 5.0, "time_to_domain_min": 10.0 + _EPS},
     ["stand_on_watch", "stand_on_check", "stand_on_close"], {}, "stand_on_watch"),
    # ... a slow closing: domain entry far off, but within stand_on_act_nm (1.62) with the CPA
    # closer than cpa_limit_nm, within the look-ahead and the role held not_acting_min (3):
    # a substantial alteration, keeping the speed, whatever the other ship did (Rule 17(b):
    # it has not opened the CPA); each limit beside it not
    *[("stand_on_watch", {**_SLOW_CLOSE, **row},
       ["stand_on_watch", "stand_on_check", "stand_on_close", "stand_on_turn"],
       {"manoeuvre": "alter_course", "course_change_deg": 30.0, "pass_distance_nm": 1.0},
       "keep_clear")
      for row in ({}, {"other_course_change_deg": 40.0}, {"other_speed_change_ratio": 0.5})],
    *[("stand_on_watch", {**_SLOW_CLOSE, **row},
       ["stand_on_watch", "stand_on_check", "stand_on_close"], {}, "stand_on_watch")
      for row in ({"range_nm": 1.62 + _EPS}, {"dcpa_nm": 1.0}, {"tcpa_min": 30.0 + _EPS},
                  {"tcpa_min": -_EPS}, {"time_in_role_min": 3.0 - _EPS})],
    *[("overtaken_watch", {**_SLOW_CLOSE, "bearing_deg": -150.0, "aspect_deg": 20.0, **row},
       ["overtaken_watch", "overtaken_check", "overtaken_close", "stand_on_turn"],
       {"manoeuvre": "alter_course", "course_change_deg": 30.0, "pass_distance_nm": 1.0},
       "keep_clear")
      for row in ({}, {"other_course_change_deg": 40.0})],
    # give_way_wait: the other ship within give_way_act_nm (2.7), the CPA within the
    # look-ahead: act whatever the time to CPA; not beyond either, nor when overtaking
    ("give_way_still", {**_GW, "tcpa_min": 25.0, "range_nm": 2.7},
     ["give_way_still", "give_way_wait", "give_way_act"],
     {"manoeuvre": "alter_course", "course_change_deg": 30.0, "pass_distance_nm": 1.0},
     "keep_clear"),
    *[("give_way_still", {**_GW, "tcpa_min": 25.0, "range_nm": 2.7, **row},
       ["give_way_still", "give_way_wait"], {}, "give_way_still")
      for row in ({"range_nm": 2.7 + _EPS}, {"tcpa_min": 30.0 + _EPS},
                  {"encounter": _OVERTAKING})],
    # overtaken: released once the overtaking ship is finally past and clear (Rule 13(d)):
    # the overtaken ship more than 22.5 deg abaft her beam, she more than 22.5 deg forward of
    # the overtaken ship's beam, range opening beyond clear_nm; not far off while abeam or astern
    ("overtaken_watch", {"tcpa_min": -1.0, "range_nm": 1.0 + _EPS, "bearing_deg": -67.5 + _EPS,
                         "aspect_deg": 112.5 + _EPS},
     ["overtaken_watch", "clear"], _CLEAR, "assess"),
    *[("overtaken_watch", {"tcpa_min": -1.0, "range_nm": 1.5, "bearing_deg": -45.0,
                           "aspect_deg": 135.0, **row},
       ["overtaken_watch", "overtaken_check", "overtaken_close"], {}, "overtaken_watch")
      for row in ({"bearing_deg": -67.5}, {"aspect_deg": 112.5}, {"range_nm": 1.0},
                  {"tcpa_min": 0.0}, {"range_nm": 5.0, "bearing_deg": 80.0, "aspect_deg": -100.0},
                  {"range_nm": 5.0, "bearing_deg": 120.0, "aspect_deg": -60.0})],
    # no track (NaN geometry): every comparison false; the keep_clear ship keeps clear
    ("keep_clear", {k: NAN for k in ("tcpa_min", "range_nm", "bearing_deg",
                                     "time_to_domain_min")},
     ["keep_clear", "past_and_clear", "emergency_check"], {}, "keep_clear"),
    ("keep_clear", {**{k: NAN for k in ("tcpa_min", "range_nm", "bearing_deg", "aspect_deg",
                                        "time_to_domain_min")}, "encounter": _OVERTAKING},
     ["keep_clear", "overtaking_keep_clear", "overtaking_apart", "emergency_check"], {},
     "keep_clear"),
])
def test_bundled_later_steps_at_their_thresholds(start: str, row: dict, path: list[str],
                                                 actions: dict, cursor: str) -> None:
    """Steps after the role is set, from the node the previous step left the pair at, at
    and beside each documented threshold (action_time_min 15, cpa_limit_nm 1, clear_nm 1,
    far_clear_nm 2, abaft_beam_deg 112.5, ahead_of_beam_deg 67.5, emergency_min 2,
    stand_on_act_min 10, not_acting_deg 10, not_slowing_ratio 0.8, give_way_act_nm 2.7,
    stand_on_act_nm 1.62, not_acting_min 3): path, merged actions (only
    those set in this step) and the next cursor, worked out from docs/rules.md."""
    ((got_path, got_actions, got_cursor),) = _step(_colregs_net(), [row], start)
    assert (got_path, got_actions, got_cursor) == (path, actions, cursor)


def test_bundled_give_way_encounter_over_successive_steps() -> None:
    """Imazu case 2 seen step by step, each step from the previous cursor: role at the first
    step, no new action while waiting, the alteration once TCPA reaches 15 min, then clear
    once past and more than 22.5 deg abaft the beam; the role is set once (the memory keeps
    it), so later steps leave it unset."""
    net = _colregs_net()
    steps = [{**_GW, "tcpa_min": 30.0},
             {**_GW, "tcpa_min": 20.0},
             {**_GW, "tcpa_min": 15.0},
             {"tcpa_min": 0.2, "range_nm": 0.9, "bearing_deg": 95.0},
             {"tcpa_min": -3.0, "range_nm": 1.2, "bearing_deg": 120.0}]
    cursor = "assess"
    trace = []
    for row in steps:
        ((path, act, cursor),) = _step(net, [row], cursor)
        trace.append((path[-1], sorted(act), cursor))
    assert trace == [
        ("give_way_wait", ["direction", "encounter", "other_role", "role"], "give_way_still"),
        ("give_way_wait", [], "give_way_still"),
        ("give_way_act", ["course_change_deg", "manoeuvre", "pass_distance_nm"], "keep_clear"),
        ("emergency_check", [], "keep_clear"),
        ("clear", ["encounter", "manoeuvre", "other_role", "role"], "assess")]


def test_bundled_variants_turn_to_port_and_act_later() -> None:
    """turn_port.yaml: the give-way crossing alters to port, the overtaking side stays
    'either'; late_action.yaml: at TCPA 10 min the bundled file acts, the late one waits
    until 3 min."""
    from trafficsim.colregs.vocabulary import VOCABULARY

    port = load(RULES / "turn_port.yaml", VOCABULARY)
    late = load(RULES / "late_action.yaml", VOCABULARY)
    rows = [{**_GW, "tcpa_min": 30.0},
            {"bearing_deg": 0.0, "aspect_deg": 180.0, "speed_ratio": 0.7, "tcpa_min": 30.0}]
    assert [a["direction"] for _, a, _ in _step(port, rows)] == ["port", "either"]
    assert [a["direction"] for _, a, _ in _step(_colregs_net(), rows)] == ["starboard", "either"]
    wait = [{**_GW, "tcpa_min": t} for t in (10.0, 3.0 + _EPS, 3.0)]
    starts = ["give_way_still"] * 3
    assert [c for _, _, c in _step(_colregs_net(), wait, starts)] == ["keep_clear"] * 3
    assert [c for _, _, c in _step(late, wait, starts)] == [
        "give_way_still", "give_way_still", "keep_clear"]


def test_bundled_kernel_matches_a_plain_reading_of_the_yaml_from_every_node() -> None:
    """rules/colregs.yaml read with plain PyYAML and run by a small interpreter here, from
    every node as the cursor, on random features drawn from each threshold of the file and
    its neighbours (and NaN, +-inf): same path, actions and cursor as the compiled kernel."""
    import yaml

    from trafficsim.colregs.vocabulary import VOCABULARY

    raw = yaml.safe_load((RULES / "colregs.yaml").read_text(encoding="utf-8"))
    params = raw["parameters"]
    enums = VOCABULARY.enums

    def num(w):
        w = params.get(w, w) if isinstance(w, str) else w
        return float(enums[w]) if isinstance(w, str) else float(w)

    def holds(test, x):
        if isinstance(test, bool):
            return test
        if isinstance(test, list):
            v = x[test[0]]
            if v != v:
                return False
            if test[1] == "between":
                return num(test[2][0]) <= v <= num(test[2][1])
            c = num(test[2])
            return {"<": v < c, "<=": v <= c, ">": v > c, ">=": v >= c, "==": v == c,
                    "!=": v != c}[test[1]]
        (word, inner), = test.items()
        if word == "not":
            return not holds(inner, x)
        return (all if word == "all" else any)(holds(t, x) for t in inner)

    def run(node, x):
        path, acts = [], {}
        while True:
            path.append(node)
            spec = raw["nodes"][node]
            for field, w in (spec.get("action") or {}).items():
                acts[field] = num(w)
            # PyYAML reads the plain keys yes / no as booleans
            edge = spec.get(True) if holds(spec["test"], x) else spec.get(False)
            edge = {"to": edge} if isinstance(edge, str) else edge
            if edge.get("next", False):
                return path, acts, edge["to"]
            node = edge["to"]

    values = sorted({float(v) for v in params.values() if not isinstance(v, str)})
    pool = [NAN, math.inf, -math.inf, 0.0, -1.0, 90.0, 180.0, -180.0,
            *values, *(v + 1e-9 for v in values), *(v - 1e-9 for v in values)]
    rng = np.random.default_rng(2024)
    names = list(raw["nodes"])
    m = 40 * len(names)
    x_all = rng.choice(pool, size=(len(VOCABULARY.features), m))
    x_all[VOCABULARY.features.index("own_role")] = rng.choice([0.0, 1.0, 2.0, 3.0], m)
    x_all[VOCABULARY.features.index("encounter")] = rng.choice(np.arange(10.0, 16.0), m)
    cursor = np.repeat(np.arange(len(names)), 40)
    net = _colregs_net()
    assert list(net.node_names) == names
    d = evaluate(net, x_all, cursor)
    for i in range(m):
        x = dict(zip(VOCABULARY.features, x_all[:, i], strict=True))
        path, acts, to = run(names[cursor[i]], x)
        assert [names[k] for k in d.path[i, :d.path_len[i]]] == path
        assert names[d.cursor[i]] == to
        for row, field in enumerate(VOCABULARY.actions):
            want = acts.get(field, NAN)
            assert d.actions[row, i] == want or (math.isnan(want)
                                                 and math.isnan(d.actions[row, i]))
