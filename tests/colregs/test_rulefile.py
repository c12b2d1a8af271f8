"""Tests of the rule-file language and its checking loader, with golden corpora.

Every ``rules/invalid/*.yaml`` starts with one or more ``# expect: <line>: <message part>``
lines, one per error the loader must report, in line order.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trafficsim.colregs.network import _holds
from trafficsim.colregs.rulefile import (
    SCHEMA_VERSION,
    ActionField,
    AllOf,
    AnyOf,
    Comparison,
    Edge,
    EngineParameter,
    Literal,
    Not,
    Operand,
    Vocabulary,
    parse,
    parse_file,
    read_rules,
    render_test,
)
from trafficsim.errors import InputError, ScenarioError

HERE = Path(__file__).parent
EXTENDS = HERE / "rules" / "extends"
VALID = sorted((HERE / "rules" / "valid").glob("*.yaml"))
INVALID = sorted((HERE / "rules" / "invalid").glob("*.yaml"))
EXPECT = re.compile(r"# expect: (\d+): (.*)")

#: a vocabulary in the shape a collision-avoidance caller would give (the engine attaches no
#: meaning to it)
VOCAB = Vocabulary(
    features=("tcpa_min", "dcpa_nm", "range_nm", "bearing_deg", "aspect_deg", "speed_ratio",
              "own_role"),
    enums={"undecided": 0.0, "give_way": 1.0, "stand_on": 2.0, "port": -1.0, "starboard": 1.0,
           "keep_course": 0.0, "alter_course": 1.0, "reduce_speed": 2.0},
    actions={"role": ActionField(("give_way", "stand_on")),
             "manoeuvre": ActionField(("keep_course", "alter_course", "reduce_speed")),
             "direction": ActionField(("port", "starboard")),
             "course_change_deg": ActionField(),
             "speed_factor": ActionField((), "fraction of the route speed", (0.0, 1.0))},
    engine_parameters={"horizon_min": EngineParameter("the look-ahead, minutes"),
                       "memory_min": EngineParameter("how long a lost track is kept, minutes",
                                                     at_least=True)})

ONE_NODE = """\
schema_version: 1
name: t
start: a
nodes:
  a:
{node}
"""


def _expectations(path: Path) -> list[tuple[int, str]]:
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        match = EXPECT.match(line)
        if not match:
            break
        out.append((int(match.group(1)), match.group(2).strip()))
    assert out, f"{path.name}: first line must be '# expect: <line>: <message part>'"
    return out


def _errors(text: str, path: str = "r.yaml") -> list[InputError]:
    with pytest.raises(ScenarioError) as info:
        parse(text, VOCAB, path)
    return info.value.errors


# ------------------------------------------------------------------------------------------
# Golden corpora
# ------------------------------------------------------------------------------------------

def test_corpora_are_broad() -> None:
    assert len(INVALID) >= 40
    assert len(VALID) >= 3


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.stem)
def test_valid_corpus(path: Path) -> None:
    rules = parse_file(path, VOCAB)
    assert rules.path == str(path) and rules.files == (str(path),)
    assert rules.start in [node.name for node in rules.nodes]
    assert all(node.line > 0 and node.path == str(path) for node in rules.nodes)


@pytest.mark.parametrize("path", INVALID, ids=lambda p: p.stem)
def test_invalid_corpus(path: Path) -> None:
    expected = _expectations(path)
    with pytest.raises(ScenarioError) as info:
        parse_file(path, VOCAB)
    err = info.value
    assert isinstance(err, InputError)
    found = [(e.line, str(e)) for e in err.errors]
    assert len(found) == len(expected), str(err)
    for (line, part), (got_line, got) in zip(expected, found, strict=True):
        assert got_line == line, got
        assert part in got, got
        assert got.startswith(f"{path}:{line}: "), got
    # the exception carries the first error's place and lists every error, one per line
    assert err.line == expected[0][0]
    assert err.path == str(path)
    assert str(err).splitlines() == [str(e) for e in err.errors]


def test_every_error_names_file_line_and_key() -> None:
    for path in INVALID:
        with pytest.raises(ScenarioError) as info:
            parse_file(path, VOCAB)
        for err in info.value.errors:
            assert err.path == str(path) and err.line is not None and err.line >= 1
            if "YAML" not in err.message and "tag" not in err.message:
                assert err.key, f"{path.name}: {err}"


# ------------------------------------------------------------------------------------------
# Language elements
# ------------------------------------------------------------------------------------------

def test_every_element_parses_to_the_expected_tree() -> None:
    rules = parse_file(HERE / "rules" / "valid" / "every_element.yaml", VOCAB)
    assert rules.name == "every_element"
    assert rules.description == "Exercises the whole rule-file language."
    assert rules.parameters == {"near_nm": 2.0, "far_nm": 6.5, "lo_deg": -10.0, "hi_deg": 10.0,
                                "factor": 0.5}
    root, compare, act, more = rules.nodes
    assert root.test == Literal(False) and root.yes is None and root.no == Edge("compare")
    assert root.description == "Literal false: only the no branch is needed."
    assert compare.yes == Edge("act", False) and compare.no == Edge("root", True)
    assert isinstance(compare.test, AllOf) and len(compare.test.items) == 6
    first = compare.test.items[0]
    assert isinstance(first, Comparison) and first.feature == "range_nm" and first.op == "<"
    assert first.value.written == "far_nm" and first.value.value == 6.5
    inner = compare.test.items[4]
    assert isinstance(inner, AnyOf)
    role = inner.items[0]
    assert isinstance(role, Comparison) and role.value.value == 1.0  # give_way
    assert isinstance(inner.items[2], Not)
    lo, hi = inner.items[2].item.value
    assert (lo.written, lo.value, hi.written, hi.value) == ("lo_deg", -10.0, "hi_deg", 10.0)
    assert compare.test.items[5] == Literal(True)
    assert act.yes == Edge("act_more", False)
    assert {k: (o.written, o.value) for k, o in act.action.items()} == {
        "role": ("stand_on", 2.0), "manoeuvre": ("reduce_speed", 2.0),
        "speed_factor": ("factor", 0.5)}
    assert {k: o.value for k, o in more.action.items()} == {"manoeuvre": 0.0,
                                                            "course_change_deg": -5.0}
    assert render_test(act.test) == (
        "{not: {all: [[aspect_deg, between, [-180, 180]], [range_nm, <, near_nm]]}}")
    assert rules.node("act") is act
    with pytest.raises(KeyError):
        rules.node("missing")


def test_plain_and_quoted_yes_no_keys_are_the_same() -> None:
    plain = ("schema_version: 1\nname: t\nstart: a\nnodes:\n  a:\n"
             "    test: [tcpa_min, '<', 1]\n    yes: {to: a, next: true}\n    no: b\n"
             "  b: {test: false, no: {to: a, next: true}}\n")
    quoted = plain.replace("yes:", '"yes":').replace("no:", "'no':")
    assert quoted.count("'no':") == 2
    assert parse(plain, VOCAB).nodes == parse(quoted, VOCAB).nodes
    a, b = parse(plain, VOCAB).nodes
    assert a.yes == Edge("a", True) and a.no == Edge("b", False)
    assert b.yes is None and b.no == Edge("a", True)


def test_word_keys_are_text_only_where_they_are_keys() -> None:
    text = ONE_NODE.format(node="    description: |\n      yes: this line is text\n"
                                "      no: so is this\n    test: yes\n    yes: {to: a, "
                                "next: true}")
    node = parse(text, VOCAB).nodes[0]
    assert node.description == "yes: this line is text\nno: so is this"
    assert node.test == Literal(True)  # a yes *value* is still YAML's boolean
    doc = read_rules("a: {on: 1, off: no, 'yes': [yes]}\n")
    assert doc.data == {"a": {"on": 1, "off": False, "yes": [True]}}


def test_word_keys_keep_error_lines() -> None:
    # yes / no keys are read by the YAML reader itself: nothing is rewritten, lines stay exact
    text = ONE_NODE.format(node="    test: [tcpa_min, '<', 1]\n    yes: {to: a, next: true}\n"
                                "    no: {to: b, next: true}\n    on: 1")
    errors = _errors(text)
    assert [(e.line, e.key) for e in errors] == [(8, "nodes.a.no.to"), (9, "nodes.a.on")]
    assert errors[1].message.startswith("unknown key 'on'")


@pytest.mark.parametrize(("text", "hint"), [
    ("a: [x, !=, 1]\n", '; write the operator in quotes: "!="'),
    ("a: [x, >=, 1]\n", '; write the operator in quotes: ">" or ">="'),
    ("a: [x, !custom, 1]\n", None),
    ("a: !!python/name:os.system x\n", None),
])
def test_operator_hint_only_for_operators(text: str, hint: str | None) -> None:
    with pytest.raises(ScenarioError) as info:
        read_rules(text, "h.yaml")
    assert info.value.line == 1
    if hint is None:
        assert "operator" not in info.value.message
    else:
        assert info.value.message.endswith(hint)


def test_bytes_and_bom_are_read() -> None:
    text = ONE_NODE.format(node="    test: true\n    yes: {to: a, next: true}")
    assert parse(("\ufeff" + text).encode("utf-8"), VOCAB).name == "t"
    with pytest.raises(ScenarioError, match="not UTF-8"):
        parse(b"schema_version: 1\nname: \xff\n", VOCAB, "r.yaml")


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="file not found"):
        parse_file(tmp_path / "none.yaml", VOCAB)
    with pytest.raises(ScenarioError, match="is a directory"):
        parse_file(tmp_path, VOCAB)


def test_unsupported_schema_stops_checking() -> None:
    errors = _errors("schema_version: 3\nnodes: 7\nwhatever: 1\n")
    assert len(errors) == 1 and errors[0].line == 1
    assert f"reads schema_version {SCHEMA_VERSION}" in errors[0].message


def test_missing_schema_version_does_not_hide_other_errors() -> None:
    errors = _errors("name: t\nstart: a\nnodes:\n  a: {test: [speed, '<', 1], "
                     "yes: {to: a, next: true}, no: {to: a, next: true}}\n")
    assert [e.line for e in errors] == [1, 4]
    assert "unknown feature 'speed'" in errors[1].message


def test_unknown_key_without_a_close_match_lists_the_allowed_keys() -> None:
    text = ONE_NODE.format(node="    test: true\n    yes: {to: a, next: true}\n    zzz: 1")
    (err,) = _errors(text)
    assert err.message == ("unknown key 'zzz'; allowed keys of a node: description, test, yes, "
                           "no, action")


def test_typo_of_a_required_key_is_reported_once() -> None:
    text = ONE_NODE.format(node="    test: [tcpa_min, '<', 1]\n    yes: {to: a, next: true}\n"
                                "    non: {to: a, next: true}")
    (err,) = _errors(text)
    assert err.message == "unknown key 'non' (did you mean 'no'?)" and err.line == 8


def test_bad_edges_skip_the_graph_checks() -> None:
    # 'b' is misspelt as 'bb': do not also call 'b' unreachable
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n  a: {test: true, yes: bb}\n"
            "  b: {test: true, yes: {to: a, next: true}}\n")
    (err,) = _errors(text)
    assert "unknown node 'bb' (did you mean 'b'?)" in err.message


def test_two_loops_are_both_named() -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            "  a: {test: [range_nm, '<', 1], yes: b, no: c}\n"
            "  b: {test: true, yes: a}\n"
            "  c: {test: true, yes: c}\n")
    errors = _errors(text)
    assert [e.message.split(";")[0] for e in errors] == [
        "loop of immediate edges: a (yes) -> b (yes) -> a",
        "loop of immediate edges: c (yes) -> c"]
    assert [e.line for e in errors] == [6, 7]


def test_next_edges_may_form_loops() -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            "  a: {test: [range_nm, '<', 1], yes: b, no: {to: a, next: true}}\n"
            "  b: {test: true, yes: {to: a, next: true}}\n")
    assert [n.name for n in parse(text, VOCAB).nodes] == ["a", "b"]


def test_enum_constants_and_parameters_resolve_to_floats() -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nparameters: {k: 3}\nnodes:\n"
            "  a: {test: [own_role, '==', stand_on], yes: {to: a, next: true}, no: b}\n"
            "  b: {test: [range_nm, between, [k, 4.5]], action: {direction: port, "
            "course_change_deg: k}, yes: {to: a, next: true}, no: {to: a, next: true}}\n")
    a, b = parse(text, VOCAB).nodes
    assert a.test.value.value == 2.0
    assert [o.value for o in b.test.value] == [3.0, 4.5]
    assert b.action["direction"].value == -1.0 and b.action["course_change_deg"].value == 3.0


def test_vocabulary_rejects_inconsistent_names() -> None:
    with pytest.raises(ValueError, match="unique"):
        Vocabulary(features=("a", "a"))
    with pytest.raises(ValueError, match="both as feature and enum"):
        Vocabulary(features=("a",), enums={"a": 1.0})
    with pytest.raises(ValueError, match="unknown enum"):
        Vocabulary(features=("a",), enums={"x": 1.0}, actions={"f": ActionField(("y",))})
    with pytest.raises(ValueError, match="finite"):
        Vocabulary(features=("a",), enums={"x": math.nan})
    vocab = Vocabulary(features=["a", "b"], enums={"x": 1.0, "y": 1.0})
    assert vocab.features == ("a", "b") and vocab.enum_names(1.0) == ("x", "y")
    assert ActionField().numeric and not ActionField(("x",)).numeric


# ------------------------------------------------------------------------------------------
# Enum-valued parameters
# ------------------------------------------------------------------------------------------

ENUM_PARAMS = """\
schema_version: 1
name: t
start: a
parameters: {side: port, role_k: stand_on, k: 3}
nodes:
  a:
    test: {any: [[own_role, '==', role_k], [range_nm, '<', k]]}
    action: {direction: side, role: role_k, course_change_deg: k}
    yes: {to: a, next: true}
    no: {to: a, next: true}
"""


def test_enum_parameters_stand_for_their_constant() -> None:
    rules = parse(ENUM_PARAMS, VOCAB)
    assert rules.parameters == {"side": -1.0, "role_k": 2.0, "k": 3.0}
    assert rules.parameter_constants == {"side": "port", "role_k": "stand_on"}
    (node,) = rules.nodes
    assert node.action == {"direction": Operand("side", -1.0), "role": Operand("role_k", 2.0),
                           "course_change_deg": Operand("k", 3.0)}
    assert node.test.items[0].value == Operand("role_k", 2.0)


@pytest.mark.parametrize(("change", "line", "key", "message"), [
    (("direction: side", "direction: k"), 8, "nodes.a.action.direction",
     "parameter 'k' holds a number, but action field 'direction' takes one of: port, starboard"),
    (("direction: side", "direction: role_k"), 8, "nodes.a.action.direction",
     "parameter 'role_k' holds 'stand_on', which action field 'direction' does not take; "
     "expected one of: port, starboard"),
    (("course_change_deg: k", "course_change_deg: side"), 8,
     "nodes.a.action.course_change_deg",
     "parameter 'side' holds the enum constant 'port', but action field 'course_change_deg' "
     "takes a number or a parameter holding a number"),
    (("[range_nm, '<', k]", "[range_nm, between, [side, 4]]"), 7, "nodes.a.test.any[1][2][0]",
     "parameter 'side' holds the enum constant 'port'; expected a number or a parameter name "
     "holding a number"),
    (("side: port", "side: prot"), 4, "parameters.side",
     "unknown enum constant 'prot' (did you mean 'port'?); a parameter holds a number or an "
     "enum constant of the vocabulary"),
    (("side: port", "side: range_nm"), 4, "parameters.side",
     "'range_nm' is a feature; a parameter holds a number or an enum constant of the "
     "vocabulary"),
    (("side: port", "side: k"), 4, "parameters.side",
     "'k' is a parameter; a parameter holds a number or an enum constant of the vocabulary "
     "(parameters cannot refer to each other)"),
    (("side: port", "side: [port]"), 4, "parameters.side",
     "expected a number or an enum constant, got a list"),
])
def test_enum_parameter_errors_are_located(change: tuple[str, str], line: int, key: str,
                                           message: str) -> None:
    assert change[0] in ENUM_PARAMS
    errors = _errors(ENUM_PARAMS.replace(*change), "e.yaml")
    assert [(e.line, e.key, e.message) for e in errors] == [(line, key, message)]


# ------------------------------------------------------------------------------------------
# extends
# ------------------------------------------------------------------------------------------

def _child(tmp_path: Path, text: str, name: str = "child.yaml") -> Path:
    """``text`` written beside a copy of rules/extends/base.yaml."""
    (tmp_path / "base.yaml").write_text((EXTENDS / "base.yaml").read_text(encoding="utf-8"),
                                        encoding="utf-8")
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _child_errors(tmp_path: Path, text: str) -> list[tuple[str, int | None, str]]:
    """(file name, line, key: message) of every error of a child of base.yaml."""
    with pytest.raises(ScenarioError) as info:
        parse_file(_child(tmp_path, text), VOCAB)
    assert str(info.value).splitlines() == [str(e) for e in info.value.errors]
    return [(Path(e.path).name, e.line, f"{e.key}: {e.message}") for e in info.value.errors]


HEAD = "schema_version: 1\nname: child\nextends: base.yaml\n"


def test_parent_alone_is_a_plain_rule_set() -> None:
    base = parse_file(EXTENDS / "base.yaml", VOCAB)
    assert base.files == (str(EXTENDS / "base.yaml"),)
    assert base.parameter_constants == {"side": "starboard", "ahead_role": "give_way"}
    assert [(n.name, n.line, n.path) for n in base.nodes] == [
        ("watch", 12, str(EXTENDS / "base.yaml")), ("decide", 17, str(EXTENDS / "base.yaml")),
        ("turn", 21, str(EXTENDS / "base.yaml"))]


def test_child_overrides_an_enum_parameter() -> None:
    base = parse_file(EXTENDS / "base.yaml", VOCAB)
    port = parse_file(EXTENDS / "turn_port.yaml", VOCAB)
    assert port.name == "turn_port" and port.start == "watch"
    assert port.description == "Parent rule set of the extends tests."  # inherited
    assert port.path == str(EXTENDS / "turn_port.yaml")
    assert port.files == (str(EXTENDS / "turn_port.yaml"), str(EXTENDS / "base.yaml"))
    assert port.parameters == {**base.parameters, "side": -1.0}
    assert port.parameter_constants == {"side": "port", "ahead_role": "give_way"}
    # every node is the parent's, written in the parent's file, with the override applied
    assert [(n.name, n.path, n.line) for n in port.nodes] == [
        (n.name, n.path, n.line) for n in base.nodes]
    assert port.node("turn").action["direction"] == Operand("side", -1.0)
    assert base.node("turn").action["direction"] == Operand("side", 1.0)
    assert port.node("watch") == base.node("watch")


def test_child_overrides_a_number_parameter() -> None:
    late = parse_file(EXTENDS / "late.yaml", VOCAB)
    lo, hi = late.node("watch").test.value
    assert (lo.value, hi.written, hi.value) == (0.0, "look_ahead_min", 5.0)
    assert late.parameters["look_ahead_min"] == 5.0 and late.parameters["turn_deg"] == 30.0


def test_grandchild_replaces_and_adds_nodes() -> None:
    rules = parse_file(EXTENDS / "grandchild.yaml", VOCAB)
    base, port, me = (str(EXTENDS / f) for f in ("base.yaml", "turn_port.yaml",
                                                  "grandchild.yaml"))
    assert rules.files == (me, port, base)
    assert rules.description == "Replaces one node, adds one node and one parameter."
    # a replaced node keeps its place; added nodes follow; 'turn' is no longer reached, which
    # is allowed for a parent's node
    assert [(n.name, n.path, n.line) for n in rules.nodes] == [
        ("watch", base, 12), ("decide", me, 10), ("turn", base, 21), ("slow", me, 15)]
    assert rules.node("decide").yes == Edge("slow")
    assert rules.parameters == {"look_ahead_min": 20.0, "turn_deg": 45.0, "side": -1.0,
                                "ahead_role": 1.0, "slow_factor": 0.5}
    assert rules.node("turn").action["course_change_deg"].value == 45.0
    assert rules.node("turn").action["direction"].value == -1.0  # from turn_port.yaml
    assert rules.node("slow").action["speed_factor"] == Operand("slow_factor", 0.5)


def test_child_may_replace_start_and_add_used_parameters(tmp_path: Path) -> None:
    rules = parse_file(_child(tmp_path, HEAD + (
        "start: first\nparameters: {near: 1.5}\nnodes:\n"
        "  first: {test: [range_nm, '<', near], yes: turn, no: watch}\n")), VOCAB)
    assert rules.start == "first" and rules.parameters["near"] == 1.5
    assert [n.name for n in rules.nodes] == ["watch", "decide", "turn", "first"]


def test_extends_from_text_is_relative_to_the_path_given(tmp_path: Path) -> None:
    _child(tmp_path, "")
    rules = parse(HEAD, VOCAB, str(tmp_path / "virtual.yaml"))
    assert rules.files == (str(tmp_path / "virtual.yaml"), str(tmp_path / "base.yaml"))


@pytest.mark.parametrize(("text", "expected"), [
    ("extends: bse.yaml\n", [("child.yaml", 3, "extends: the file to extend, '{d}/bse.yaml', "
                              "does not exist (did you mean 'base.yaml'?); 'extends' takes a "
                              "path relative to the folder of this file")]),
    ("extends: 3\n", [("child.yaml", 3, "extends: expected the path of the rules file this one "
                       "extends, got 3 (put it in quotes)")]),
    ("extends: child.yaml\n", [("child.yaml", 3, "extends: extends loop: {d}/child.yaml -> "
                                "{d}/child.yaml; a rules file cannot extend itself, directly "
                                "or through the files it extends")]),
    ("extends: .\n", [("child.yaml", 3, "extends: the file to extend, '{d}', is a directory; "
                       "'extends' takes the path of a rules file")]),
])
def test_extends_errors_name_file_and_line(tmp_path: Path, text: str,
                                           expected: list[tuple[str, int, str]]) -> None:
    got = _child_errors(tmp_path, "schema_version: 1\nname: child\n" + text)
    assert got == [(f, line, m.format(d=tmp_path)) for f, line, m in expected]


def test_extends_loop_through_two_files() -> None:
    with pytest.raises(ScenarioError) as info:
        parse_file(EXTENDS / "loop_a.yaml", VOCAB)
    (err,) = info.value.errors
    a, b = EXTENDS / "loop_a.yaml", EXTENDS / "loop_b.yaml"
    assert (err.path, err.line, err.key) == (str(b), 3, "extends")
    assert err.message.startswith(f"extends loop: {a} -> {b} -> {a};")


@pytest.mark.parametrize(("text", "expected"), [
    # overrides: kind, misspelt name
    ("parameters:\n  side: 30\n  turn_deg: port\n", [
        ("child.yaml", 5, "parameters.side: parameter 'side' holds the enum constant "
         "'starboard' in {d}/base.yaml:9; an override must hold an enum constant too, got a "
         "number"),
        ("child.yaml", 6, "parameters.turn_deg: parameter 'turn_deg' holds a number in "
         "{d}/base.yaml:8; an override must hold a number too, got the enum constant 'port'")]),
    ("parameters:\n  look_ahed_min: 5\n", [
        ("child.yaml", 5, "parameters.look_ahed_min: parameter 'look_ahed_min' is not a "
         "parameter of '{d}/base.yaml' (did you mean 'look_ahead_min'?) and no node of this "
         "file uses it; a file that extends another may override the parameters it inherits, "
         "or add parameters for its own nodes")]),
    # an override that breaks the parent's text is located at the override
    ("parameters:\n  look_ahead_min: -5\n", [
        ("child.yaml", 5, "parameters.look_ahead_min: between needs lo <= hi, got [0, "
         "look_ahead_min] = [0, -5]; the value of 'look_ahead_min' set here is used at "
         "{d}/base.yaml:14 (nodes.watch.test[2])")]),
    ("parameters:\n  side: give_way\n", [
        ("child.yaml", 5, "parameters.side: parameter 'side' holds 'give_way', which action "
         "field 'direction' does not take; expected one of: port, starboard; the value of "
         "'side' set here is used at {d}/base.yaml:23 (nodes.turn.action.direction)")]),
    # the child's own nodes, start and keys
    ("nodes:\n  turn:\n    test: [speeed, '<', 1]\n    yes: {to: watch, next: true}\n"
     "    no: {to: watch, next: true}\n", [
         ("child.yaml", 6, "nodes.turn.test[0]: unknown feature 'speeed'")]),
    ("nodes:\n  turn:\n    test: true\n    action: {course_change_deg: side}\n    yes: watch\n", [
        ("child.yaml", 7, "nodes.turn.action.course_change_deg: parameter 'side' holds the "
         "enum constant 'starboard', but action field 'course_change_deg' takes a number or a "
         "parameter holding a number"),
        ("child.yaml", 8, "nodes.turn.yes: loop of immediate edges: watch (yes) -> decide "
         "(yes) -> turn (yes) -> watch; a decision step would never end: make one of these "
         "edges {{to: NAME, next: true}}")]),
    ("nodes:\n  extra:\n    test: true\n    yes: {to: watch, next: true}\n", [
        ("child.yaml", 5, "nodes.extra: node 'extra' cannot be reached from start 'watch'; link "
         "it from another node or remove it")]),
    ("start: wach\nnodes: {}\nextend: x\n", [
        ("child.yaml", 4, "start: unknown node 'wach' (did you mean 'watch'?); start must name "
         "a node under 'nodes'"),
        ("child.yaml", 5, "nodes: expected a non-empty mapping of node name -> node, got no "
         "nodes"),
        ("child.yaml", 6, "extend: unknown key 'extend' (did you mean 'extends'?)")]),
])
def test_child_errors_are_located_in_the_child(tmp_path: Path, text: str,
                                               expected: list[tuple[str, int, str]]) -> None:
    got = _child_errors(tmp_path, HEAD + text)
    assert got == [(f, line, m.format(d=tmp_path)) for f, line, m in expected]


def test_every_file_needs_schema_version_and_name(tmp_path: Path) -> None:
    got = _child_errors(tmp_path, "extends: base.yaml\n")
    assert got == [
        ("child.yaml", 1, "schema_version: missing required key 'schema_version'; expected "
         "'schema_version: 1' at the top of the file"),
        ("child.yaml", 1, "name: missing required key 'name' (the rule set's name as text)")]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(overrides=st.dictionaries(st.sampled_from(["look_ahead_min", "turn_deg"]),
                                 st.integers(-50, 50), max_size=2),
       side=st.sampled_from([None, "port", "starboard"]))
def test_overrides_merge_over_the_parent(tmp_path: Path, overrides: dict[str, int],
                                         side: str | None) -> None:
    params = dict(overrides) | ({"side": side} if side else {})
    lines = "".join(f"  {k}: {v}\n" for k, v in params.items())
    child = _child(tmp_path, HEAD + ("parameters:\n" + lines if lines else ""))
    base = parse_file(tmp_path / "base.yaml", VOCAB)
    expected = {**base.parameters, **{k: float(VOCAB.enums[v]) if isinstance(v, str)
                                      else float(v) for k, v in params.items()}}
    if expected["look_ahead_min"] < 0:  # [0, look_ahead_min] reversed: the override is wrong
        with pytest.raises(ScenarioError) as info:
            parse_file(child, VOCAB)
        (err,) = info.value.errors
        line = 5 + list(params).index("look_ahead_min")
        assert (err.path, err.line, err.key) == (str(child), line, "parameters.look_ahead_min")
        return
    rules = parse_file(child, VOCAB)
    assert rules.parameters == expected
    assert rules.parameter_constants == {"side": side or "starboard", "ahead_role": "give_way"}
    hi = rules.node("watch").test.value[1]
    assert hi.value == expected["look_ahead_min"]
    turn = rules.node("turn").action
    assert turn["course_change_deg"].value == expected["turn_deg"]
    assert turn["direction"].value == expected["side"]


def test_parent_errors_are_located_in_the_parent_and_reported_once(tmp_path: Path) -> None:
    child = _child(tmp_path, HEAD + "nodes:\n  extra: {test: true, yes: watch}\n")
    base = tmp_path / "base.yaml"
    base.write_text(base.read_text().replace("[tcpa_min,", "[tcpa_mn,").replace(
        "turn_deg: 30", "turn_deg: '30'"))
    with pytest.raises(ScenarioError) as info:
        parse_file(child, VOCAB)
    got = [(Path(e.path).name, e.line, e.key) for e in info.value.errors]
    # the file read first, then its parent; each error once although the parent is checked
    # alone and as part of the child
    assert got == [("child.yaml", 5, "nodes.extra"), ("base.yaml", 8, "parameters.turn_deg"),
                   ("base.yaml", 14, "nodes.watch.test[0]")]
    assert info.value.path == str(child) and info.value.line == 5


def test_parent_yaml_error_is_located_in_the_parent(tmp_path: Path) -> None:
    (tmp_path / "broken.yaml").write_text("schema_version: 1\nname: [x,\n")
    with pytest.raises(ScenarioError) as info:
        parse_file(_child(tmp_path, "schema_version: 1\nname: c\nextends: broken.yaml\n"), VOCAB)
    assert info.value.path == str(tmp_path / "broken.yaml") and info.value.line == 3
    assert "invalid YAML" in info.value.message


def test_parent_must_be_valid_alone(tmp_path: Path) -> None:
    # base.yaml uses a parameter that only the child declares: an error of base.yaml
    child = _child(tmp_path, HEAD + "parameters: {hi: 9}\nnodes:\n"
                   "  extra: {test: [range_nm, '<', hi], yes: {to: watch, next: true}, "
                   "no: turn}\n  watch: {test: true, yes: extra}\n")
    base = tmp_path / "base.yaml"
    base.write_text(base.read_text().replace("[0, look_ahead_min]", "[0, hi]"))
    with pytest.raises(ScenarioError) as info:
        parse_file(child, VOCAB)
    (err,) = info.value.errors
    assert (Path(err.path).name, err.line) == ("base.yaml", 14)
    assert err.message.startswith("unknown parameter 'hi'")


# ------------------------------------------------------------------------------------------
# Robustness: any text ends in a rule set or a located error
# ------------------------------------------------------------------------------------------

_EXAMPLE = (HERE / "rules" / "valid" / "example.yaml").read_text(encoding="utf-8")


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_mutated_files_fail_only_with_located_errors(data: st.DataObject) -> None:
    lines = _EXAMPLE.splitlines(keepends=True)
    k = data.draw(st.integers(0, len(lines) - 1))
    action = data.draw(st.sampled_from(["drop", "duplicate", "edit"]))
    if action == "drop":
        del lines[k]
    elif action == "duplicate":
        lines.insert(k, lines[k])
    else:
        pos = data.draw(st.integers(0, max(len(lines[k]) - 1, 0)))
        junk = data.draw(st.text(alphabet="ab_ :[]{},-0189\"'", max_size=4))
        lines[k] = lines[k][:pos] + junk + lines[k][pos + 1:]
    text = "".join(lines)
    try:
        parse(text, VOCAB, "m.yaml")
    except ScenarioError as err:
        assert err.path == "m.yaml" and err.errors
        assert all(e.line is None or 1 <= e.line <= text.count("\n") + 1 for e in err.errors)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_arbitrary_text_fails_only_with_located_errors(text: str) -> None:
    try:
        parse(text, VOCAB, "x.yaml")
    except ScenarioError as err:
        assert err.path == "x.yaml"


# ------------------------------------------------------------------------------------------
# Bad values written in a file: located errors, never a crash
# ------------------------------------------------------------------------------------------

TINY = """\
schema_version: 1
name: tiny
start: a
parameters:
  p: 2.5
  side: port
nodes:
  a:
    test: {test}
    action: {action}
    yes: {{to: a, next: true}}
    no: {{to: a, next: true}}
"""


def _tiny_error(tmp_path: Path, test: str = "true", action: str = "{speed_factor: 1}"
                ) -> ScenarioError:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY.format(test=test, action=action), encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        parse_file(path, VOCAB)
    return info.value


@pytest.mark.parametrize(("test", "action", "line", "key", "message"), [
    ("[range_nm, '<', .inf]", "{speed_factor: 1}", 9, "nodes.a.test[2]",
     "expected a finite number, got inf"),
    ("[range_nm, '<', true]", "{speed_factor: 1}", 9, "nodes.a.test[2]",
     "expected a number, a parameter name or an enum constant, got true"),
    ("[[range_nm], '<', 1]", "{speed_factor: 1}", 9, "nodes.a.test[0]",
     "expected a feature name, got a list"),
    ("[range_nm, between, [port, 3]]", "{speed_factor: 1}", 9, "nodes.a.test[2][0]",
     "'port' is an enum constant; expected a number or a parameter name"),
    ("[range_nm, between, [3, p]]", "{speed_factor: 1}", 9, "nodes.a.test[2]",
     "between needs lo <= hi, got [3, p] = [3, 2.5]"),
    ("{not: null}", "{speed_factor: 1}", 9, "nodes.a.test.not",
     "expected a test: a comparison [feature, op, value], {all: [...]}, {any: [...]}, "
     "{not: test}, true or false; got nothing (an empty value)"),
    ("true", "{speed_factor: [1]}", 10, "nodes.a.action.speed_factor",
     "expected a number, got a list"),
    ("true", "{direction: starbord}", 10, "nodes.a.action.direction",
     "unknown value 'starbord' for action field 'direction' (did you mean 'starboard'?); "
     "expected one of: port, starboard"),
    ("true", "{speed_factor: side}", 10, "nodes.a.action.speed_factor",
     "parameter 'side' holds the enum constant 'port', but action field 'speed_factor' "
     "takes a number or a parameter holding a number"),
    ("true", "{speed_factor: stand_on}", 10, "nodes.a.action.speed_factor",
     "'stand_on' is an enum constant, but action field 'speed_factor' takes a number or a "
     "parameter name"),
    ("[range_nm, 'lt', 1]", "{speed_factor: 1}", 9, "nodes.a.test[1]",
     "unknown operator 'lt' (did you mean '<'?); expected one of <, <=, >, >=, ==, !=, "
     "between (quote '>', '>=' and '!=' in YAML)"),
])
def test_bad_values_in_a_file_are_located(tmp_path: Path, test: str, action: str, line: int,
                                          key: str, message: str) -> None:
    err = _tiny_error(tmp_path, test, action)
    path = tmp_path / "tiny.yaml"
    assert [str(e) for e in err.errors] == [f"{path}:{line}: {key}: {message}"]
    assert (err.path, err.line, err.key) == (str(path), line, key)


_BIG = "1" + "0" * 400  # a YAML integer beyond the float range


@pytest.mark.parametrize(("test", "action", "line", "key"), [
    (f"[range_nm, '<', {_BIG}]", "{speed_factor: 1}", 9, "nodes.a.test[2]"),
    (f"[range_nm, between, [0, {_BIG}]]", "{speed_factor: 1}", 9, "nodes.a.test[2][1]"),
    ("true", f"{{speed_factor: -{_BIG}}}", 10, "nodes.a.action.speed_factor"),
])
def test_integer_beyond_the_float_range_is_a_located_error(tmp_path: Path, test: str,
                                                            action: str, line: int,
                                                            key: str) -> None:
    err = _tiny_error(tmp_path, test, action)
    assert (err.line, err.key) == (line, key)
    assert "finite" in err.message or "too large" in err.message


@pytest.mark.parametrize("written", ["1e5", "010"])
def test_plain_numbers_read_as_text_get_no_quote_hint(tmp_path: Path, written: str) -> None:
    """``1e5`` and ``010`` are written without quotes; YAML 1.1 reads them as text. Telling the
    user to remove quotes that are not there is wrong (quoted text does get that hint)."""
    err = _tiny_error(tmp_path, f"[range_nm, '<', {written}]")
    assert err.key == "nodes.a.test[2]"
    assert "remove the quotes" not in err.message
    quoted = _tiny_error(tmp_path, "[range_nm, '<', '15']")
    assert quoted.message.endswith("(remove the quotes)")


def test_errors_of_one_file_come_in_line_order_with_one_line_each(tmp_path: Path) -> None:
    path = tmp_path / "many.yaml"
    path.write_text(
        "schema_version: 1\nname: many\nstart: a\nparameters:\n  p: 'x'\nnodes:\n"
        "  c: {test: [bearing_dg, '<', 1], yes: a, no: {to: a, next: true}}\n"
        "  a: {test: [range_nm, '=<', 1], yes: c, no: {to: a, next: true}}\n"
        "  b: {test: true, yes: {to: a, next: maybe}}\n", encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        parse_file(path, VOCAB)
    errs = info.value.errors
    assert [(e.line, e.key) for e in errs] == [
        (5, "parameters.p"), (7, "nodes.c.test[0]"), (8, "nodes.a.test[1]"),
        (9, "nodes.b.yes.next")]
    assert "did you mean 'bearing_deg'" in errs[1].message
    assert "did you mean '<='" in errs[2].message
    assert str(info.value).splitlines() == [str(e) for e in errs]
    assert all(str(e).startswith(f"{path}:{e.line}: {e.key}: ") for e in errs)


# ------------------------------------------------------------------------------------------
# The bundled rules files
# ------------------------------------------------------------------------------------------

RULES = HERE.parents[1] / "rules"


def _line_of(path: Path, text: str) -> list[int]:
    return [k + 1 for k, line in enumerate(path.read_text().splitlines()) if text in line]


def test_bundled_variants_change_only_what_they_say() -> None:
    from trafficsim.colregs.vocabulary import VOCABULARY

    base = parse_file(RULES / "colregs.yaml", VOCABULARY)
    port = parse_file(RULES / "turn_port.yaml", VOCABULARY)
    late = parse_file(RULES / "late_action.yaml", VOCABULARY)
    assert port.parameters == {**base.parameters,
                               "alteration_side": VOCABULARY.enums["port"]}
    assert late.parameters == {**base.parameters, "action_time_min": 3.0,
                               "stand_on_act_min": 3.0, "give_way_act_nm": 0.0,
                               "stand_on_act_nm": 0.0}
    for rules in (port, late):
        assert [(n.name, n.line, n.path) for n in rules.nodes] == [
            (n.name, n.line, n.path) for n in base.nodes]
        assert rules.start == base.start == "assess"
    # the port variant: every node that used alteration_side now turns to port
    turned = [n.name for n in port.nodes if "direction" in n.action
              and n.action["direction"].written == "alteration_side"]
    assert turned == ["give_way_crossing", "head_on_role", "mutual_crossing"]
    assert all(port.node(n).action["direction"].value == VOCABULARY.enums["port"]
               for n in turned)
    assert all(base.node(n).action["direction"].value == VOCABULARY.enums["starboard"]
               for n in turned)


def test_override_breaking_the_bundled_look_ahead_names_every_use(tmp_path: Path) -> None:
    """A child of rules/colregs.yaml with a negative look-ahead: one error per use of the
    parameter, each at the override and naming the line of the use in the parent, then the
    decision step's own bound on it."""
    from trafficsim.colregs.vocabulary import VOCABULARY

    parent = RULES / "colregs.yaml"
    child = tmp_path / "late.yaml"
    child.write_text(f"schema_version: 1\nname: late\nextends: {parent}\nparameters:\n"
                     "  look_ahead_min: -3\n", encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        parse_file(child, VOCABULARY)
    uses = _line_of(parent, "[tcpa_min, between, [0, look_ahead_min]]")
    assert len(uses) == 5
    keys = ["nodes.risk.test.all[1][2]", "nodes.overtaking_risk.test.all[1][2]",
            "nodes.overtaken_close.test.all[2][2]", "nodes.stand_on_close.test.all[2][2]",
            "nodes.rv_risk.test.all[1][2]"]
    assert [str(e) for e in info.value.errors] == [
        f"{child}:5: parameters.look_ahead_min: between needs lo <= hi, got "
        f"[0, look_ahead_min] = [0, -3]; the value of 'look_ahead_min' set here is used at "
        f"{parent}:{line} ({key})" for line, key in zip(uses, keys, strict=True)] + [
        f"{child}:5: parameters.look_ahead_min: parameter 'look_ahead_min' (the look-ahead of "
        "time to domain entry and of the arbitration, minutes) must be > 0, got -3"]


# ------------------------------------------------------------------------------------------
# Documented errors through `trafficsim validate`: file, line, key, exit code 2
# ------------------------------------------------------------------------------------------

_COLREGS_ONE = """\
schema_version: 1
name: t
start: a
nodes:
  a:
    test: {test}
    yes: {yes}
    no: {{to: a, next: true}}
  b:
    test: true
    yes: {b_yes}
"""


def _colregs_text(test: str = "[tcpa_min, '<', 5]", yes: str = "b",
                  b_yes: str = "{to: a, next: true}") -> str:
    return _COLREGS_ONE.format(test=test, yes=yes, b_yes=b_yes)


def _line_with(text: str, part: str, nth: int = 1) -> int:
    """1-based line of the ``nth`` line of ``text`` containing ``part``."""
    hits = [k + 1 for k, line in enumerate(text.splitlines()) if part in line]
    return hits[nth - 1]


_DUPLICATE = _colregs_text() + "  b:\n    test: false\n    no: {to: a, next: true}\n"
_NO_CHILD = _colregs_text().replace("    no: {to: a, next: true}\n", "", 1)
_NO_START = _colregs_text().replace("start: a\n", "")

_CLI_CASES = {
    "unknown feature": (
        _colregs_text(test="[tcpa_mn, '<', 5]"), ("[tcpa_mn",), "nodes.a.test[0]",
        "unknown feature 'tcpa_mn' (did you mean 'tcpa_min'?)"),
    "bad operator": (
        _colregs_text(test="[tcpa_min, '=<', 5]"), ("'=<'",), "nodes.a.test[1]",
        "unknown operator '=<' (did you mean '<='?); expected one of <, <=, >, >=, ==, !=, "
        "between"),
    "unquoted not-equal": (
        _colregs_text(test="[tcpa_min, !=, 5]"), ("!=",), "nodes.a.test[1]",
        'write the operator in quotes: "!="'),
    "wrong nesting: all of one comparison": (
        _colregs_text(test="{all: [tcpa_min, '<', 5]}"), ("all:",), "nodes.a.test.all",
        "all takes a list of tests, got a single comparison"),
    "wrong nesting: not of a list": (
        _colregs_text(test="{not: [[tcpa_min, '<', 5], [range_nm, '<', 1]]}"), ("not:",),
        "nodes.a.test.not", "not takes one test, got a list of tests"),
    "type mismatch: enum constant as a bound": (
        _colregs_text(test="[tcpa_min, between, [0, give_way]]"), ("between",),
        "nodes.a.test[2][1]", "'give_way' is an enum constant; expected a number or a "
        "parameter name"),
    "type mismatch: text for a number": (
        _colregs_text(test="[tcpa_min, '<', '5']"), ("'5'",), "nodes.a.test[2]",
        "(remove the quotes)"),
    "type mismatch: feature as a value": (
        _colregs_text(test="[tcpa_min, '<', dcpa_nm]"), ("dcpa_nm",), "nodes.a.test[2]",
        "'dcpa_nm' is a feature"),
    "cycle of now edges": (
        _colregs_text(b_yes="a"), ("    yes: a",), "nodes.b.yes",
        "loop of immediate edges: a (yes) -> b (yes) -> a"),
    "duplicate node": (
        _DUPLICATE, ("  b:", 2), "nodes.b",
        f"duplicate key 'b' (first at line {_line_with(_DUPLICATE, '  b:')}, again at line "
        f"{_line_with(_DUPLICATE, '  b:', 2)})"),
    "missing child": (
        _NO_CHILD, ("  a:",), "nodes.a", "missing required key 'no'"),
    "missing start": (
        _NO_START, ("schema_version",), "start", "missing required key 'start'"),
    "unknown child": (
        _colregs_text(yes="bb"), ("yes: bb",), "nodes.a.yes",
        "unknown node 'bb' (did you mean 'b'?)"),
}


@pytest.mark.parametrize("kind", list(_CLI_CASES))
def test_documented_errors_exit_2_naming_file_line_and_key(tmp_path: Path, capsys, kind: str
                                                           ) -> None:
    """Each documented error kind, in a file checked against the COLREGS vocabulary by
    ``trafficsim validate``: exit code 2 and one stderr line ``file:line: key: message``, the
    line being where the faulty text is written (found here by searching the text)."""
    from trafficsim.cli import main

    text, (part, *nth), key, message = _CLI_CASES[kind]
    path = tmp_path / "rules.yaml"
    path.write_text(text, encoding="utf-8")
    line = _line_with(text, part, *nth)
    assert main(["validate", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    errors = captured.err.strip().splitlines()
    assert len(errors) == 1, captured.err
    head = f"trafficsim: error: {path}:{line}: {key}: "
    assert errors[0].startswith(head), errors[0]
    assert message in errors[0]


def test_validate_lists_every_error_and_still_checks_the_other_files(tmp_path: Path,
                                                                    capsys) -> None:
    """Two faulty lines and one good file: two located error lines, the good file reported
    ``ok`` with its node count, exit code 2."""
    from trafficsim.cli import main

    bad = tmp_path / "bad.yaml"
    text = _colregs_text(test="[tcpa_mn, '<', 5]", yes="bb")
    bad.write_text(text, encoding="utf-8")
    good = tmp_path / "good.yaml"
    good.write_text(_colregs_text(), encoding="utf-8")
    assert main(["validate", str(bad), str(good)]) == 2
    captured = capsys.readouterr()
    assert captured.out.strip() == f"{good}: ok (2 nodes)"
    assert [e.split(": ")[2] for e in captured.err.strip().splitlines()] == [
        f"{bad}:{_line_with(text, 'tcpa_mn')}", f"{bad}:{_line_with(text, 'yes: bb')}"]


def test_validate_counts_the_nodes_of_the_bundled_files(capsys) -> None:
    """``FILE: ok (N nodes)``, N counted here with plain PyYAML: the node keys of colregs.yaml,
    which its two variants inherit unchanged."""
    import yaml

    from trafficsim.cli import main

    n = len(yaml.safe_load((RULES / "colregs.yaml").read_text(encoding="utf-8"))["nodes"])
    files = [RULES / f for f in ("colregs.yaml", "turn_port.yaml", "late_action.yaml")]
    assert main(["validate", *map(str, files)]) == 0
    assert capsys.readouterr().out.splitlines() == [f"{f}: ok ({n} nodes)" for f in files]


# ------------------------------------------------------------------------------------------
# "A misspelt key is reported once (not also as the key it was meant to be missing)"
# ------------------------------------------------------------------------------------------

_GOOD_ONE = ("schema_version: 1\nname: t\nstart: a\n"
             "nodes:\n  a: {test: true, yes: {to: a, next: true}}\n")


def test_misspelt_node_key_is_reported_once() -> None:
    """The node-level case: ``tset`` is reported, ``test`` is not also called missing."""
    (err,) = _errors(_GOOD_ONE.replace("{test:", "{tset:"))
    assert err.key == "nodes.a.tset" and "did you mean 'test'" in err.message


@pytest.mark.parametrize(("old", "new", "key"), [
    ("name: t", "nme: t", "nme"),
    ("start: a", "strat: a", "strat"),
    ("nodes:", "nodse:", "nodse"),
    ("schema_version: 1", "schema_versoin: 1", "schema_versoin"),
    ("{to: a, next: true}", "{too: a, next: true}", "nodes.a.yes.too"),
])
def test_misspelt_required_keys_are_reported_once(old: str, new: str, key: str) -> None:
    """docs/rules.md (Errors): a misspelt key is reported once, as the unknown key with its
    "did you mean", not also as the required key it was meant to be."""
    assert old in _GOOD_ONE
    errors = _errors(_GOOD_ONE.replace(old, new, 1))
    assert [e.key for e in errors] == [key]
    assert "did you mean" in errors[0].message


# ------------------------------------------------------------------------------------------
# extends: each file valid by itself, every error once, in the file that holds the text
# ------------------------------------------------------------------------------------------

def test_parent_error_is_reported_once_whatever_the_child_adds(tmp_path: Path) -> None:
    """base.yaml names a node 'slw' that does not exist; the child adds a node 'slow'. The
    parent is checked alone and as part of the child ("an error found both ways is reported
    once"): one error at the parent's line, not a second copy with another hint."""
    child = _child(tmp_path, HEAD + "nodes:\n  slow: {test: true, yes: {to: watch, "
                                    "next: true}}\n")
    base = tmp_path / "base.yaml"
    text = base.read_text().replace("yes: turn", "yes: slw")
    base.write_text(text)
    with pytest.raises(ScenarioError) as info:
        parse_file(child, VOCAB)
    got = [(Path(e.path).name, e.line, e.key) for e in info.value.errors]
    assert got == [("base.yaml", _line_with(text, "yes: slw"), "nodes.decide.yes")]


def test_parent_typo_without_a_new_close_name_is_reported_once(tmp_path: Path) -> None:
    """The same parent error with a child that adds nothing resembling it: one error."""
    child = _child(tmp_path, HEAD + "parameters: {turn_deg: 40}\n")
    base = tmp_path / "base.yaml"
    text = base.read_text().replace("yes: turn", "yes: trn")
    base.write_text(text)
    with pytest.raises(ScenarioError) as info:
        parse_file(child, VOCAB)
    (err,) = info.value.errors
    assert (Path(err.path).name, err.line, err.key) == (
        "base.yaml", _line_with(text, "yes: trn"), "nodes.decide.yes")
    assert "did you mean 'turn'" in err.message


_MID = """\
schema_version: 1
name: mid
extends: base.yaml
parameters:
  near: 1.5
nodes:
  decide:
    test: [range_nm, "<", near]
    yes: turn
    no: {to: watch, next: true}
"""

_TOP = """\
schema_version: 1
name: top
extends: mid.yaml
nodes:
  decide:
    test: [range_nm, "<", 3]
    yes: turn
    no: {to: watch, next: true}
"""


def test_middle_file_adding_a_used_parameter_is_valid(tmp_path: Path) -> None:
    """mid.yaml adds ``near`` and uses it in the node it writes: valid by itself."""
    _child(tmp_path, _MID, "mid.yaml")
    rules = parse_file(tmp_path / "mid.yaml", VOCAB)
    assert rules.parameters["near"] == 1.5
    assert rules.node("decide").test.value == Operand("near", 1.5)


def test_replacing_the_node_that_used_a_parents_added_parameter(tmp_path: Path) -> None:
    """top.yaml replaces mid.yaml's ``decide`` entirely (documented). mid.yaml is valid by
    itself and its ``near`` is used by a node written in mid.yaml, so the chain must load: the
    replaced node is simply not part of the result, and ``near`` stays a parameter."""
    _child(tmp_path, _MID, "mid.yaml")
    (tmp_path / "top.yaml").write_text(_TOP, encoding="utf-8")
    rules = parse_file(tmp_path / "top.yaml", VOCAB)
    assert rules.node("decide").path == str(tmp_path / "top.yaml")
    assert rules.parameters["near"] == 1.5


def test_three_file_chain_lists_errors_file_by_file(tmp_path: Path) -> None:
    """Errors of a chain top -> mid -> base come in the order of ``files`` (the file read,
    then the one it extends, ...), by line within each file."""
    _child(tmp_path, _MID.replace('"<", near]', '"<", near]\n    action: {role: giveway}'),
           "mid.yaml")
    base = tmp_path / "base.yaml"
    btext = base.read_text().replace("turn_deg: 30", "turn_deg: '30'")
    base.write_text(btext)
    top = tmp_path / "top.yaml"
    ttext = ("schema_version: 1\nname: top\nextends: mid.yaml\nnodes:\n"
             "  extra: {test: [rnge_nm, '<', 1], yes: {to: watch, next: true}, "
             "no: {to: watch, next: true}}\n  turn: {test: true, yes: extra}\n")
    top.write_text(ttext)
    with pytest.raises(ScenarioError) as info:
        parse_file(top, VOCAB)
    got = [(Path(e.path).name, e.line) for e in info.value.errors]
    mtext = (tmp_path / "mid.yaml").read_text()
    assert got == [("top.yaml", _line_with(ttext, "rnge_nm")),
                   ("mid.yaml", _line_with(mtext, "giveway")),
                   ("base.yaml", _line_with(btext, "turn_deg"))]
    assert str(info.value).splitlines() == [str(e) for e in info.value.errors]


def test_absolute_extends_path_and_relative_one_give_the_same_rules(tmp_path: Path) -> None:
    """``extends`` relative to the folder of the file, or absolute: the same rule set."""
    rel = _child(tmp_path, HEAD + "parameters: {turn_deg: 50}\n")
    sub = tmp_path / "sub"
    sub.mkdir()
    absolute = sub / "abs.yaml"
    absolute.write_text(rel.read_text().replace("base.yaml", str(tmp_path / "base.yaml")))
    up = sub / "up.yaml"
    up.write_text(rel.read_text().replace("base.yaml", "../base.yaml"))
    a, b, c = (parse_file(p, VOCAB) for p in (rel, absolute, up))
    assert a.nodes == b.nodes == c.nodes
    assert a.parameters == b.parameters == c.parameters
    assert a.parameters["turn_deg"] == 50.0


# ------------------------------------------------------------------------------------------
# Language constructs against a plain evaluation of the written test
# ------------------------------------------------------------------------------------------

def written_value(value, params: dict[str, float], vocab=VOCAB) -> float:
    """A written value's number: a parameter's, an enum constant's, or the number itself."""
    if isinstance(value, str):
        return params[value] if value in params else vocab.enums[value]
    return float(value)


def written_test(test, x: dict[str, float], params: dict[str, float], vocab=VOCAB) -> bool:
    """The documented meaning of a test as written (PyYAML data), NaN comparisons false."""
    if isinstance(test, bool):
        return test
    if isinstance(test, list):
        feature, op, value = test
        v = x[feature]
        if math.isnan(v):
            return False
        if op == "between":
            return (written_value(value[0], params, vocab) <= v
                    <= written_value(value[1], params, vocab))
        c = written_value(value, params, vocab)
        return {"<": v < c, "<=": v <= c, ">": v > c, ">=": v >= c, "==": v == c,
                "!=": v != c}[op]
    (word, inner), = test.items()
    if word == "not":
        return not written_test(inner, x, params, vocab)
    results = [written_test(t, x, params, vocab) for t in inner]
    return all(results) if word == "all" else any(results)


def test_every_element_file_means_what_it_says_on_a_grid() -> None:
    """Every test of every_element.yaml, parsed, holds exactly where the written YAML (read
    with plain PyYAML) holds by the documented semantics, over a grid of feature values with
    the file's boundaries (2, 6.5, +-10, 0, 0.5, 180), NaN and infinities."""
    import itertools

    import yaml

    path = HERE / "rules" / "valid" / "every_element.yaml"
    raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    rules = parse_file(path, VOCAB)
    grid = {"range_nm": [2.0, 6.5, 7.0, math.nan], "dcpa_nm": [-1.0, 0.0, -0.5],
            "own_role": [1.0, 2.0, 0.0], "bearing_deg": [-10.0, 10.0, 10.5],
            "speed_ratio": [0.0, 0.5, 0.6], "aspect_deg": [-180.0, math.inf],
            "tcpa_min": [0.0, -0.0, 1e-300]}
    names = list(grid)
    checked = 0
    for values in itertools.product(*grid.values()):
        x = dict(zip(names, values, strict=True))
        for node in rules.nodes:
            written = raw["nodes"][node.name]["test"]
            assert _holds(node.test, x) == written_test(written, x, rules.parameters), (node, x)
            checked += 1
    assert checked == 4 * 3 * 3 * 3 * 3 * 2 * 3 * 4


@pytest.mark.parametrize(("written", "rendered"), [
    ("[range_nm, '<', 1]", "[range_nm, <, 1]"),
    ("[range_nm, between, [-2, 2.5]]", "[range_nm, between, [-2, 2.5]]"),
    ("{all: [true, {not: false}]}", "{all: [true, {not: false}]}"),
    ("{any: [[own_role, '!=', stand_on], {all: [[dcpa_nm, '>=', 0]]}]}",
     "{any: [[own_role, !=, stand_on], {all: [[dcpa_nm, >=, 0]]}]}"),
])
def test_render_test_round_trips(written: str, rendered: str) -> None:
    """``render_test`` writes the flow syntax back; quoting its operators again parses to the
    same tree."""
    (node,) = parse(ONE_NODE.format(node=f"    test: {written}\n    yes: {{to: a, next: true}}"
                                          "\n    no: {to: a, next: true}"), VOCAB).nodes
    assert render_test(node.test) == rendered
    quoted = re.sub(r", (<=|<|>=|>|==|!=), ", lambda m: f", '{m.group(1)}', ", rendered)
    (again,) = parse(ONE_NODE.format(node=f"    test: {quoted}\n    yes: {{to: a, next: true}}"
                                            "\n    no: {to: a, next: true}"), VOCAB).nodes
    assert again.test == node.test


def test_block_and_flow_styles_give_the_same_tree() -> None:
    """The docs' block-style example and the same test in flow style: one tree."""
    block = ("    test:\n      all:\n        - [range_nm, \"<\", far_nm]\n        - any:\n"
             "            - [own_role, \"==\", give_way]\n"
             "            - not: [bearing_deg, between, [lo_deg, hi_deg]]\n"
             "    yes: {to: a, next: true}\n    no: {to: a, next: true}")
    flow = ("    test: {all: [[range_nm, '<', far_nm], {any: [[own_role, '==', give_way], "
            "{not: [bearing_deg, between, [lo_deg, hi_deg]]}]}]}\n"
            "    yes: {to: a, next: true}\n    no: {to: a, next: true}")
    head = ONE_NODE.replace("nodes:", "parameters: {far_nm: 5, lo_deg: -3, hi_deg: 3}\nnodes:")
    (a,) = parse(head.replace("{node}", block), VOCAB).nodes
    (b,) = parse(head.replace("{node}", flow), VOCAB).nodes
    assert a.test == b.test
    assert isinstance(a.test, AllOf) and isinstance(a.test.items[1], AnyOf)


BACK_TO_A = "  b: {test: true, yes: {to: a, next: true}, no: {to: a, next: true}}\n"
RANGED = Vocabulary(features=("dcpa_nm", "bearing_deg", "tcpa_min"),
                    feature_ranges={"dcpa_nm": (0.0, math.inf), "bearing_deg": (-180.0, 180.0)})


@pytest.mark.parametrize(("test", "never"), [
    ("[dcpa_nm, '<', 0]", "'dcpa_nm < 0'"), ("[dcpa_nm, '<=', -0.5]", "'dcpa_nm <= -0.5'"),
    ("[dcpa_nm, '==', -1]", "'dcpa_nm == -1'"), ("[bearing_deg, '>', 180]", "'bearing_deg > 180'"),
    ("[bearing_deg, '>=', 181]", "'bearing_deg >= 181'"),
    ("[bearing_deg, between, [190, 200]]", "'bearing_deg between [190, 200] = [190, 200]'"),
    ("[dcpa_nm, '<', limit]", "'dcpa_nm < limit = -1'"),
])
def test_a_comparison_no_value_of_the_feature_satisfies_is_refused(test: str, never: str) -> None:
    """A branch that can never be taken is an authoring error (a sign slip in a threshold),
    refused at the comparison's value with the feature's range."""
    text = ("schema_version: 1\nname: t\nstart: a\nparameters: {limit: -1}\nnodes:\n"
            f"  a: {{test: {test}, yes: b, no: b}}\n{BACK_TO_A}")
    with pytest.raises(ScenarioError) as info:
        parse(text, RANGED, "r.yaml")
    feature = test[1:].split(",")[0]
    lo, hi = {"dcpa_nm": ("0", "inf"), "bearing_deg": ("-180", "180")}[feature]
    assert [str(e) for e in info.value.errors] == [
        f"r.yaml:6: nodes.a.test[2]: can never hold: {feature} takes values from {lo} to {hi}, "
        f"so {never} is never true"]


@pytest.mark.parametrize("test", [
    "[dcpa_nm, '<', 0.001]", "[dcpa_nm, '<=', 0]", "[dcpa_nm, '!=', -1]", "[dcpa_nm, '>', 1000]",
    "[bearing_deg, between, [-200, -180]]", "[bearing_deg, '>=', 180]",
    "[tcpa_min, '<', -1.0e+9]",  # (an unbounded feature: anything goes)
])
def test_comparisons_some_value_satisfies_are_kept(test: str) -> None:
    text = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            f"  a: {{test: {test}, yes: b, no: b}}\n{BACK_TO_A}")
    assert parse(text, RANGED, "r.yaml").nodes[0].test.feature == test[1:].split(",")[0]


def test_feature_ranges_must_be_of_known_features_and_ordered() -> None:
    with pytest.raises(ValueError, match="feature range"):
        Vocabulary(features=("a",), feature_ranges={"b": (0.0, 1.0)})
    with pytest.raises(ValueError, match="feature range"):
        Vocabulary(features=("a",), feature_ranges={"a": (1.0, 0.0)})


def test_the_colregs_vocabulary_bounds_its_geometry_and_memory_features() -> None:
    from trafficsim.colregs.vocabulary import FEATURE_RANGES, VOCABULARY

    assert VOCABULARY.feature_ranges["dcpa_nm"] == (0.0, math.inf)
    assert VOCABULARY.feature_ranges["course_diff_abs_deg"] == (0.0, 180.0)
    assert "tcpa_min" not in FEATURE_RANGES and "own_role" not in FEATURE_RANGES
