"""Tests of the decision-network compiler, the compiled evaluator and its explanations.

The differential test runs random networks (written as rule files) through the compiled kernel
and through a plain-Python reference evaluator that reads the same data as written, sharing no
code with the engine.
"""

from __future__ import annotations

import math
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

from .test_rulefile import VOCAB

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
    if isinstance(value, str):
        return PARAMS[value] if value in PARAMS else DIFF_VOCAB.enums[value]
    return float(value)


def _ref_test(test: Any, feats: dict[str, float]) -> bool:
    """Reference semantics, straight from the language description."""
    if isinstance(test, bool):
        return test
    if isinstance(test, list):
        feature, op, value = test
        x = feats[feature]
        if math.isnan(x):
            return False
        if op == "between":
            return _resolve(value[0]) <= x <= _resolve(value[1])
        c = _resolve(value)
        return {"<": x < c, "<=": x <= c, ">": x > c, ">=": x >= c, "==": x == c,
                "!=": x != c}[op]
    if "all" in test:
        return all(_ref_test(t, feats) for t in test["all"])
    if "any" in test:
        return any(_ref_test(t, feats) for t in test["any"])
    return not _ref_test(test["not"], feats)


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
    return {"schema_version": 1, "name": "random", "start": "n0", "parameters": PARAMS,
            "nodes": {name: spec for name, spec in nodes.items() if name in reached}}


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


def _tiny_file(tmp_path: Path, test: str) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text("schema_version: 1\nname: tiny\nstart: t\n"
                    "parameters: {lim: 2.5, lo_p: -2, hi_p: 4, lvl: high}\nnodes:\n"
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
