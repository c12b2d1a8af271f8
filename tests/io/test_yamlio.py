"""Tests of the safe YAML loader and the pydantic error mapping (trafficsim.io.yamlio)."""

from __future__ import annotations

import contextlib
import math
import time
from typing import Literal

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import Field, field_validator

from trafficsim.errors import InputError, ScenarioError
from trafficsim.io import yamlio
from trafficsim.io.yamlio import (
    Document,
    FieldError,
    Integer,
    Number,
    Strict,
    Text,
    format_loc,
    load_yaml,
    locate,
    parse_loc,
    parse_yaml,
    validate,
    validate_document,
)


def _error(source: str | bytes, **kwargs: object) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        parse_yaml(source, "f.yaml", **kwargs)  # type: ignore[arg-type]
    return info.value


# ------------------------------------------------------------------------------------------
# Loading: data and lines
# ------------------------------------------------------------------------------------------

DOC = """\
# comment
name: demo
ships:
  - name: a
    speed: 12
  - {name: b, speed: 3.5}
env:
  wind:
    speed: 4
empty:
"""


def test_plain_data() -> None:
    doc = parse_yaml(DOC, "d.yaml")
    assert isinstance(doc, Document)
    assert doc.path == "d.yaml"
    assert doc.data == {"name": "demo",
                        "ships": [{"name": "a", "speed": 12}, {"name": "b", "speed": 3.5}],
                        "env": {"wind": {"speed": 4}}, "empty": None}


@pytest.mark.parametrize(("loc", "line"), [
    ((), 2),                              # the top-level mapping starts at its first key
    (("name",), 2),
    (("ships",), 3),                      # an entry is located at its key
    (("ships", 0), 4),
    (("ships", 0, "speed"), 5),
    (("ships", 1), 6),
    (("ships", 1, "speed"), 6),
    (("ships", 1, "missing"), 6),         # missing key -> its parent
    (("ships", 7, "speed"), 3),           # index out of range -> the list's entry
    (("env", "wind", "speed"), 9),
    (("env", "wind", "gust"), 8),
    (("env", "current", "speed"), 7),
    (("empty",), 10),
    (("nope",), 2),
    (("name", 0), 2),                     # path through a scalar stops at it
])
def test_line_of(loc: tuple[str | int, ...], line: int) -> None:
    assert parse_yaml(DOC).line_of(loc) == line


def test_node_at() -> None:
    doc = parse_yaml(DOC)
    node = doc.node_at(("ships", 0, "speed"))
    assert isinstance(node, yaml.ScalarNode) and node.value == "12"
    assert doc.node_at(("ships", 0, "nope")) is None
    assert doc.node_at(()) is doc.root


def test_error_helper_locates() -> None:
    err = parse_yaml(DOC, "d.yaml").error("bad speed", ("ships", 1, "speed"))
    assert isinstance(err, ScenarioError)
    assert str(err) == "d.yaml:6: ships[1].speed: bad speed"


def test_format_loc() -> None:
    assert format_loc(("ships", 1, "route", 0, 1)) == "ships[1].route[0][1]"
    assert format_loc(("a", "b")) == "a.b"
    assert format_loc(()) == ""
    # parse_loc reads plain dotted keys back
    for loc in (("ships", 1, "route", 0, 1), ("a", "b"), ("coefficients", "a1")):
        assert parse_loc(format_loc(loc)) == loc
    # an empty key stays visible; the validator's key marker is kept
    assert format_loc(("encounter_types", "", "[key]")) == "encounter_types[''][key]"
    assert format_loc(("types", "cargo", "[key]")) == "types.cargo[key]"


def test_crlf_and_bom_keep_lines() -> None:
    doc = parse_yaml(b"\xef\xbb\xbfa: 1\r\nb:\r\n  c: 2\r\n")
    assert doc.data == {"a": 1, "b": {"c": 2}}
    assert doc.line_of(("b", "c")) == 3


def test_load_yaml_reads_file(tmp_path) -> None:
    path = tmp_path / "x.yaml"
    path.write_text("a: 1\n", encoding="utf-8")
    doc = load_yaml(path)
    assert doc.data == {"a": 1} and doc.path == str(path)


# ------------------------------------------------------------------------------------------
# Loading: refused input
# ------------------------------------------------------------------------------------------

def test_error_is_scenario_and_value_error() -> None:
    err = _error("a: [1, 2\n")
    assert isinstance(err, InputError) and isinstance(err, ValueError)
    assert err.path == "f.yaml"


def test_duplicate_key_names_both_lines() -> None:
    err = _error("a: 1\nb:\n  c: 1\n  d: 2\n  c: 3\n")
    assert err.line == 5
    assert err.key == "b.c"
    assert "duplicate key 'c' (first at line 3, again at line 5)" in err.message


def test_duplicate_key_in_flow_mapping() -> None:
    assert _error("a: {x: 1, x: 2}\n").line == 1


def test_anchor_refused() -> None:
    err = _error("a: &x 1\nb: 2\n")
    assert err.line == 1 and "anchors ('&x') are not allowed" in err.message


def test_billion_laughs_refused_fast() -> None:
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    start = time.perf_counter()
    err = _error("\n".join(lines) + "\n")
    assert time.perf_counter() - start < 1.0
    assert err.line == 1 and "anchors" in err.message


def test_alias_refused() -> None:
    err = _error("a: 1\nb: *x\n")  # an unknown alias is refused before PyYAML complains
    assert err.line == 2 and "aliases ('*x') are not allowed" in err.message


def test_size_cap() -> None:
    err = _error("a: " + "x" * 100 + "\n", max_bytes=50)
    assert "larger than the limit of 50 bytes" in err.message
    assert err.line is None
    assert str(err) == f"f.yaml: {err.message}"


def test_size_cap_default_is_one_megabyte(tmp_path) -> None:
    assert yamlio.MAX_BYTES == 1_000_000
    path = tmp_path / "big.yaml"
    path.write_bytes(b"a: '" + b"x" * 1_000_000 + b"'\n")
    with pytest.raises(ScenarioError, match="larger than the limit of 1000000 bytes"):
        load_yaml(path)
    assert load_yaml(path, max_bytes=2_000_000).data["a"] == "x" * 1_000_000


def test_not_utf8_located() -> None:
    err = _error(b"a: 1\nb: caf\xe9\n")
    assert err.line == 2 and "not UTF-8" in err.message and "0xE9" in err.message


def test_control_character_located() -> None:
    err = _error("a: 1\nb: x\x00y\n")
    assert err.line == 2 and "U+0000" in err.message


@pytest.mark.parametrize("source", ["", "   \n\n", "# only\n# comments\n", b""])
def test_empty(source: str | bytes) -> None:
    err = _error(source)
    assert err.line == 1 and "file is empty" in err.message


@pytest.mark.parametrize(("source", "got"), [
    ("- a\n- b\n", "a list"), ("just text\n", "'just text'"), ("42\n", "'42'")])
def test_top_level_must_be_mapping(source: str, got: str) -> None:
    err = _error(source)
    assert err.line == 1
    assert err.message == f"the top level must be a mapping of 'key: value' lines, got {got}"


@pytest.mark.parametrize(("source", "line"), [
    ("a: 1\n2: b\n", 2), ("a:\n  ? [x, y]\n  : 1\n", 2), ("a: 1\n? {k: v}\n: 2\n", 2),
    ("a: 1\n1.5: b\n", 2), ("!!bool yes: 1\n", 1), ("a:\n  !!null ~: 1\n", 2),
    ("? \n: 1\n", 1)])
def test_keys_must_be_text(source: str, line: int) -> None:
    err = _error(source)
    assert err.line == line and "keys must be text" in err.message


def test_empty_key_is_named_without_a_quote_hint() -> None:
    err = _error("a: 1\n? \n: 2\n")
    assert err.message == "keys must be text, got an empty key"


WORD_KEYS = ["yes", "Yes", "YES", "no", "No", "NO", "true", "True", "TRUE", "false", "False",
             "FALSE", "on", "On", "ON", "off", "Off", "OFF", "y", "Y", "n", "N", "null",
             "Null", "NULL", "~"]


@pytest.mark.parametrize("word", WORD_KEYS)
def test_plain_word_keys_are_text_and_values_keep_yaml_meaning(word: str) -> None:
    # As a value the word keeps its YAML 1.1 meaning (what yaml.safe_load gives).
    expected_value = yaml.safe_load(f"k: {word}\n")["k"]
    text = f"top:\n  other: 1\n  {word}: {word}\nflow: {{{word}: [{word}]}}\n"
    doc = parse_yaml(text, "w.yaml")
    assert doc.data == {"top": {"other": 1, word: expected_value},
                        "flow": {word: [expected_value]}}
    assert doc.line_of(("top", word)) == 3 and doc.line_of(("flow", word)) == 4
    err = doc.error("bad", ("top", word))
    assert str(err) == f"w.yaml:3: top.{word}: bad"


# value as written -> as loaded: words are booleans / null as values, text as nested keys
_WORD_VALUES = {"1": 1, "yes": True, "~": None, "x": "x", "[on, 2]": [True, 2],
                "{off: no}": {"off": False}, "{~: null, Y: n}": {"~": None, "Y": "n"}}


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([*WORD_KEYS, "a", "b_c", "speed_kn"]),
                          st.sampled_from(list(_WORD_VALUES))),
                min_size=1, max_size=8, unique_by=lambda kv: kv[0]))
def test_plain_word_keys_are_text_at_their_lines(items: list[tuple[str, str]]) -> None:
    text = "# header\n" + "".join(f"{k}: {v}\n" for k, v in items)
    doc = parse_yaml(text)
    assert doc.data == {k: _WORD_VALUES[v] for k, v in items}
    assert list(doc.data) == [k for k, _ in items]
    for line, (key, _) in enumerate(items, start=2):
        assert doc.line_of((key,)) == line


def test_word_keys_and_their_quoted_forms_are_the_same_key() -> None:
    assert parse_yaml("'yes': 1\n\"no\": 2\n? on\n: 3\n").data == {"yes": 1, "no": 2, "on": 3}
    err = _error("a:\n  'no': 1\n  no: 2\n")
    assert err.line == 3 and err.key == "a.no"
    assert "duplicate key 'no' (first at line 2, again at line 3)" in err.message


def test_word_keys_keep_the_lines_of_later_errors() -> None:
    err = _error("yes: 1\nno:\n  off: 2\n  ~: [1, 2\nz: 3\n")
    assert err.line == 5 and "expected ',' or ']'" in err.message


def test_word_keys_reach_pydantic_as_text() -> None:
    class Switches(Strict):
        on: Number
        off: Number = 0.0

    doc = parse_yaml("on: 1\nof: 2\n", "s.yaml")
    with pytest.raises(ScenarioError) as info:
        validate_document(doc, Switches)
    assert str(info.value) == "s.yaml:2: of: unknown key 'of' (did you mean 'off'?)"
    assert validate_document(parse_yaml("on: 1\noff: 2\n"), Switches).off == 2.0


def test_merge_key_refused() -> None:
    err = _error("a:\n  <<: {b: 1}\n")
    assert err.line == 2 and "merge keys" in err.message


@pytest.mark.parametrize(("source", "line", "text"), [
    ("a: [1, 2\nb: 3\n", 2, "expected ',' or ']'"),
    ("a: 1\nb:\n\tc: 2\n", 3, "tabs cannot indent YAML, use spaces"),
    ("a: 1\n  b: 2\n", 2, "mapping values are not allowed here"),
    ("a: 'open\n", 2, "invalid YAML"),
    ("a: 1\n---\nb: 2\n", 2, "a second YAML document starts here"),
    ("a: !!python/object/apply:os.system [ls]\n", 1, "unsupported tag"),
    ("a: !custom 1\n", 1, "unsupported tag '!custom'"),
    ("a: !!binary aGVsbG8=\n", 1, "unsupported tag"),
    ("a: !!set {x: null}\n", 1, "unsupported tag"),
    ("a: !!int abc\n", 1, "'abc' is not a whole number"),
    ("a: !!float abc\n", 1, "'abc' is not a number"),
    ("a: !!bool maybe\n", 1, "'maybe' is not a boolean"),
    ("a: !!null x\n", 1, "'x' is not a valid null"),
    ("a: \"\\ud800\"\n", 1, "surrogate"),
])
def test_yaml_errors_located(source: str, line: int, text: str) -> None:
    err = _error(source)
    assert err.line == line
    assert text in err.message


def test_unclosed_bracket_names_where_it_opened() -> None:
    err = _error("a: 1\nb: [1,\n   2\nc: 3\n")
    assert err.line == 4 and "started at line 2" in err.message


def test_deep_nesting_refused() -> None:
    depth = 5000
    err = _error("a: " + "[" * depth + "]" * depth + "\n")
    assert err.line == 1 and "nesting is deeper than" in err.message


@pytest.mark.parametrize("exc", [
    ValueError("bad"), AttributeError("x"), RecursionError("deep"), TypeError("t"),
    yaml.YAMLError("plain yaml error")])
def test_any_library_exception_becomes_scenario_error(monkeypatch, exc: Exception) -> None:
    def boom(*args: object, **kwargs: object) -> None:
        raise exc

    monkeypatch.setattr(yamlio.yaml, "compose", boom)
    err = _error("a: 1\n")
    assert err.path == "f.yaml"


def test_missing_file_and_directory(tmp_path) -> None:
    with pytest.raises(ScenarioError, match="file not found"):
        load_yaml(tmp_path / "nope.yaml")
    with pytest.raises(ScenarioError, match="directory"):
        load_yaml(tmp_path)


# ------------------------------------------------------------------------------------------
# YAML 1.1 surprises
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("text", "value"), [
    ("yes", True), ("No", False), ("on", True), ("OFF", False), ("true", True),
    ("~", None), ("", None), ("null", None),
    ("12", 12), ("-0x1f", -31), ("0b101", 5), ("1_000", 1000), ("0", 0), ("-3", -3),
    ("1.5", 1.5), ("1.0e+3", 1000.0), ("-.inf", -math.inf),
    ("1:30", "1:30"), ("1:30.5", "1:30.5"), ("010", "010"), ("-007", "-007"),
    ("1e5", "1e5"), ("2024-01-01", "2024-01-01"), ("=", "="),
    ("'no'", "no"), ('"1:30"', "1:30"), ("!!str 5", "5"), ("!!int '7'", 7),
    ("!!float 2", 2.0),
])
def test_scalars(text: str, value: object) -> None:
    assert parse_yaml(f"a: {text}\n").data["a"] == value


def test_nan_loads_as_float() -> None:
    assert math.isnan(parse_yaml("a: .NaN\n").data["a"])


# ------------------------------------------------------------------------------------------
# Validation: the pydantic error mapping
# ------------------------------------------------------------------------------------------

class Inner(Strict):
    speed_kn: Number
    count: Integer = 0


class Model(Strict):
    name: Text
    kind: Literal["a", "b"] = "a"
    value: Number = 0.0
    plain: float = 0.0
    optional: float | None = None
    table: dict[str, float] = Field(default_factory=dict)
    whole: list[int] = Field(default_factory=list)
    items: tuple[Inner, ...] = ()
    inner: Inner | None = None
    tags: list[str] = Field(default_factory=list, min_length=0, max_length=2)

    @field_validator("items")
    @classmethod
    def _distinct(cls, items: tuple[Inner, ...]) -> tuple[Inner, ...]:
        if len(items) > 1 and items[0].speed_kn == items[1].speed_kn:
            raise FieldError("same speed as items[0]", loc=(1, "speed_kn"))
        return items


def _validation_error(source: str) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        validate_document(parse_yaml(source, "m.yaml"), Model)
    return info.value


@pytest.mark.parametrize(("source", "line", "key", "message"), [
    ("value: 1\n", 1, "name", "missing required key 'name'"),
    ("name: x\nvalu: 1\n", 2, "valu", "unknown key 'valu' (did you mean 'value'?)"),
    ("name: x\nzzz: 1\n", 2, "zzz", "unknown key 'zzz'; allowed keys: name, kind, value"),
    ("name: x\ninner: {speed_kn: 1, cnt: 2}\n", 2, "inner.cnt",
     "unknown key 'cnt' (did you mean 'count'?)"),
    ("name: x\nitems:\n  - {speed_kn: 1}\n  - {speed_kn: 2, sped_kn: 1}\n", 4,
     "items[1].sped_kn",
     "unknown key 'sped_kn' (did you mean 'speed_kn'?)"),
    ("name: x\nvalue: fast\n", 2, "value", "expected a number, got 'fast'"),
    ("name: x\nvalue: '12'\n", 2, "value", "expected a number, got '12' (remove the quotes)"),
    ("name: x\nvalue: yes\n", 2, "value",
     "expected a number, got 'yes' (YAML reads this word as a boolean)"),
    ("name: x\nvalue: false\n", 2, "value", "expected a number, got false"),
    ("name: x\nvalue:\n", 2, "value", "expected a number, got nothing (an empty value)"),
    ("name: x\nvalue: [1]\n", 2, "value", "expected a number, got a list"),
    ("name: x\nvalue: 1:30\n", 2, "value", "base-60 number 90"),
    ("name: x\nvalue: 2:03:04.5\n", 2, "value", "base-60 number 7384.5"),
    ("name: x\nvalue: 09\n", 2, "value", "write it without the leading zero"),
    ("name: x\nvalue: 1.5e3\n", 2, "value", "write 1.5e+3"),
    ("name: x\nvalue: .nan\n", 2, "value", "expected a finite number, got .nan"),
    ("name: x\nvalue: -.inf\n", 2, "value", "expected a finite number, got -.inf"),
    ("name: x\nplain: true\n", 2, "plain", "expected a number, got true"),
    ("name: x\nplain: '3'\n", 2, "plain", "expected a number, got '3'"),
    ("name: x\noptional: on\n", 2, "optional", "expected a number, got 'on'"),
    ("name: x\ntable: {a: 1, b: yes}\n", 2, "table.b", "expected a number, got 'yes'"),
    ("name: x\nwhole: [1, true]\n", 2, "whole[1]", "expected a whole number, got true"),
    ("name: x\nwhole: [1.5]\n", 2, "whole[0]", "expected a whole number, got 1.5"),
    ("name: x\ninner: {speed_kn: 1, count: 2.5}\n", 2, "inner.count",
     "expected a whole number, got 2.5"),
    ("name: x\ninner: {speed_kn: 1, count: true}\n", 2, "inner.count",
     "expected a whole number, got true"),
    ("name: no\n", 1, "name",
     "expected text, got 'no' (YAML reads it as a boolean; put it in quotes if you mean "
     "text: \"no\")"),
    ("name: 12\n", 1, "name", "put it in quotes if you mean text: \"12\""),
    ("name: '  '\n", 1, "name", "must not be empty"),
    ("name: x\nkind: c\n", 2, "kind", "expected 'a' or 'b', got 'c'"),
    ("name: x\nwhole: 5\n", 2, "whole", "expected a list, got 5"),
    ("name: x\ninner: 5\n", 2, "inner", "expected a mapping of 'key: value' lines, got 5"),
    ("name: x\ninner: [1]\n", 2, "inner", "expected a mapping of 'key: value' lines, got a list"),
    ("name: x\ntags: [a, b, c]\n", 2, "tags", "expected at most 2 items, got 3"),
    ("name: x\nitems:\n  - {speed_kn: 1}\n  - {speed_kn: 1}\n", 4, "items[1].speed_kn",
     "same speed as items[0]"),
])
def test_error_messages(source: str, line: int, key: str, message: str) -> None:
    err = _validation_error(source)
    assert err.line == line
    assert err.key == key
    assert message in err.message
    assert str(err).startswith(f"m.yaml:{line}: {key}: ")


def test_all_errors_kept_sorted_by_line() -> None:
    err = _validation_error("value: x\nplain: y\nzzz: 1\n")  # name missing: located at line 1
    assert [e.line for e in err.errors] == [1, 1, 2, 3]
    assert all(isinstance(e, ScenarioError) for e in err.errors)
    assert err.message.endswith("(and 3 more errors)")
    assert str(err.errors[0]).startswith("m.yaml:1: ")


def test_typo_is_not_also_reported_missing() -> None:
    err = _validation_error("name: x\ninner: {sped_kn: 1}\n")
    assert len(err.errors) == 1
    assert err.message == "unknown key 'sped_kn' (did you mean 'speed_kn'?)"
    err = _validation_error("name: x\ninner: {zzz: 1}\n")   # not close: both reported
    assert [e.message.split(" (")[0] for e in err.errors] == [
        "missing required key 'speed_kn'", "unknown key 'zzz'; allowed keys: speed_kn, count"]


def test_one_error_has_no_suffix() -> None:
    err = _validation_error("value: 1\n")
    assert err.message == "missing required key 'name'" and len(err.errors) == 1


def test_validate_reads_file_and_passes_context(tmp_path) -> None:
    class WithContext(Strict):
        name: Text

        @field_validator("name")
        @classmethod
        def _known(cls, name: str, info) -> str:
            if name not in info.context["known"]:
                raise ValueError(f"unknown name '{name}'")
            return name

    path = tmp_path / "c.yaml"
    path.write_text("name: a\n", encoding="utf-8")
    assert validate(path, WithContext, context={"known": {"a"}}).name == "a"
    with pytest.raises(ScenarioError, match=r"c.yaml:1: name: unknown name 'a'"):
        validate(path, WithContext, context={"known": set()})


def test_strict_model_accepts_numbers_and_is_frozen() -> None:
    model = validate_document(parse_yaml(
        "name: x\nvalue: 3\nplain: 2\noptional: 1.5\ntable: {a: 1}\nwhole: [1, 2]\n"), Model)
    assert model.value == 3.0 and isinstance(model.value, float)
    assert model.plain == 2.0 and model.optional == 1.5
    assert model.table == {"a": 1.0} and model.whole == [1, 2]
    with pytest.raises(Exception, match="frozen"):
        model.value = 4.0  # type: ignore[misc]


def test_strict_model_from_python_rejects_bool() -> None:
    with pytest.raises(Exception, match="valid number"):
        Inner.model_validate({"speed_kn": True})
    with pytest.raises(Exception, match="valid number"):
        Model.model_validate({"name": "x", "plain": True})
    assert Model.model_validate({"name": "x", "plain": 1}).plain == 1.0


# ------------------------------------------------------------------------------------------
# Properties
# ------------------------------------------------------------------------------------------

YAML_ALPHABET = st.sampled_from([*"abc019 :-,[]{}#&*!|>'\"%@`?\n\t.~_+<=\\",
                                 "yes", "no", "1:30", ".nan", "!!", "---", "\n  ", "\n- "])


def _only_scenario_errors(source: str | bytes) -> None:
    try:
        doc = parse_yaml(source, "p.yaml")
    except ScenarioError as err:
        assert err.path == "p.yaml"
        return
    assert isinstance(doc.data, dict)
    with contextlib.suppress(ScenarioError):
        validate_document(doc, Model)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=300))
def test_random_bytes_raise_only_scenario_errors(data: bytes) -> None:
    _only_scenario_errors(data)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200))
def test_random_text_raises_only_scenario_errors(text: str) -> None:
    _only_scenario_errors(text)


@settings(max_examples=500, deadline=None)
@given(st.lists(YAML_ALPHABET, max_size=60).map("".join))
def test_yaml_like_text_raises_only_scenario_errors(text: str) -> None:
    _only_scenario_errors(text)
    _only_scenario_errors("name: x\nitems:\n  - " + text)


# PyYAML's emitter mangles the YAML 1.1 line breaks NEL, LS and PS (not a loader matter).
TEXT = st.text(st.characters(exclude_categories=("Cs",),
                             exclude_characters="\x85\u2028\u2029"), max_size=12)
JSON_SCALARS = (st.none() | st.booleans() | st.integers() | TEXT | st.floats(allow_nan=False))
JSON_DATA = st.recursive(
    JSON_SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(TEXT, inner, max_size=4),
    max_leaves=20)


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(TEXT, JSON_DATA, min_size=1, max_size=5))
def test_safe_dump_round_trips(data: dict) -> None:
    text = yaml.safe_dump(data, allow_unicode=True)
    try:
        doc = parse_yaml(text)
    except ScenarioError as err:
        # Only characters YAML cannot carry (e.g. lone surrogates) may be refused.
        assert "surrogate" in err.message or "invalid character" in err.message
        return
    assert doc.data == data
    for key in data:
        assert 1 <= doc.line_of((key,)) <= text.count("\n") + 1


# ------------------------------------------------------------------------------------------
# Nesting depth, anchors, tags, non-finite numbers, duplicate keys, size cap
# ------------------------------------------------------------------------------------------

def _nested(levels: int, inner: str) -> str:
    """A top-level mapping holding ``levels - 1`` nested lists: ``levels`` containers."""
    k = levels - 1
    return "a: " + "[" * k + inner + "]" * k + "\n"


@pytest.mark.parametrize("inner", ["", "1"])
def test_nesting_below_the_limit_loads_and_above_is_refused(inner: str) -> None:
    """63 mappings/lists deep load (with or without a value inside); 65 are refused at line 1
    with the documented message."""
    data = parse_yaml(_nested(yamlio.MAX_DEPTH - 1, inner)).data["a"]
    depth = 1
    while isinstance(data, list) and data and isinstance(data[0], list):
        data, depth = data[0], depth + 1
    assert depth == yamlio.MAX_DEPTH - 2  # the lists below the top-level mapping
    err = _error(_nested(yamlio.MAX_DEPTH + 1, inner))
    assert err.line == 1 and f"deeper than {yamlio.MAX_DEPTH} levels" in err.message


def test_nesting_exactly_at_the_limit_loads_when_empty() -> None:
    assert parse_yaml(_nested(yamlio.MAX_DEPTH, "")).data["a"] is not None


def test_nesting_exactly_at_the_limit_loads_with_a_value_inside() -> None:
    """MAX_DEPTH is 'the deepest nesting of mappings and lists accepted': 64 containers (the
    top-level mapping and 63 lists) holding the number 1 must load."""
    assert parse_yaml(_nested(yamlio.MAX_DEPTH, "1")).data["a"] is not None


@pytest.mark.parametrize(("source", "line", "anchor"), [
    ("&top\na: 1\n", 1, "&top"),                      # on the document's mapping
    ("a: 1\n&k b: 2\n", 2, "&k"),                     # on a key
    ("a:\n  - 1\n  - &i 2\n", 3, "&i"),               # on a list item
    ("a: 1\nb: &m\n  c: 1\n", 2, "&m"),               # on a block mapping value
    ("a: [1, {b: &f 2}]\n", 1, "&f"),                 # inside flow collections
])
def test_anchors_anywhere_are_refused_at_their_line(source: str, line: int, anchor: str) -> None:
    err = _error(source)
    assert err.line == line and f"anchors ('{anchor}') are not allowed" in err.message


def test_alias_inside_a_flow_list_is_refused_at_its_line() -> None:
    err = _error("a: 1\nb:\n  c: [1, *a]\n")
    assert err.line == 3 and "aliases ('*a')" in err.message


@pytest.mark.parametrize(("source", "value"), [
    ("a: !!map {b: 1}\n", {"b": 1}), ("a: !!seq [1, 2]\n", [1, 2]), ("a: !!str 1.5\n", "1.5"),
    ("a: !<tag:yaml.org,2002:str> 7\n", "7"), ("a: !!null ''\n", None),
    ("a: !!bool 'On'\n", True), ("a: !!int '-0b11'\n", -3),
])
def test_plain_json_like_tags_are_accepted(source: str, value: object) -> None:
    assert parse_yaml(source).data["a"] == value


@pytest.mark.parametrize(("source", "line", "key", "tag"), [
    ("a:\n  b: !!omap [{c: 1}]\n", 2, "a.b", "'!!omap'"),
    ("a:\n  - !!pairs [{c: 1}]\n", 2, "a[0]", "'!!pairs'"),
    ("a: !local {b: 1}\n", 1, "a", "'!local'"),
    ("a: !local [1]\n", 1, "a", "'!local'"),
    ("a:\n  b:\n    c: !!python/tuple [1, 2]\n", 3, "a.b.c", "'!!python/tuple'"),
])
def test_other_tags_are_refused_with_line_and_key(source: str, line: int, key: str,
                                                  tag: str) -> None:
    err = _error(source)
    assert (err.line, err.key) == (line, key)
    assert f"unsupported tag {tag}" in err.message


@pytest.mark.parametrize(("text", "expected"), [
    (".inf", math.inf), (".Inf", math.inf), (".INF", math.inf), ("+.inf", math.inf),
    ("-.Inf", -math.inf), ("-.INF", -math.inf), ("1.0e+400", math.inf),
    ("-1.0e+400", -math.inf),
])
def test_infinite_spellings_load_as_infinity_and_a_number_refuses_them(text: str,
                                                                       expected: float) -> None:
    """YAML 1.1 spells infinity several ways (and a literal too large for a double
    overflows to it): each loads as the Python infinity, and a Number field refuses it."""
    assert parse_yaml(f"a: {text}\n").data["a"] == expected
    err = _validation_error(f"name: x\nvalue: {text}\n")
    assert (err.line, err.key) == (2, "value")
    assert err.message == f"expected a finite number, got {text}"


@pytest.mark.parametrize("text", [".nan", ".NaN", ".NAN"])
def test_nan_spellings_are_refused_by_every_numeric_field(text: str) -> None:
    assert math.isnan(parse_yaml(f"a: {text}\n").data["a"])
    for source, key in ((f"value: {text}", "value"), (f"plain: {text}", "plain"),
                        (f"optional: {text}", "optional"), (f"table: {{q: {text}}}", "table.q"),
                        (f"inner: {{speed_kn: {text}}}", "inner.speed_kn")):
        err = _validation_error(f"name: x\n{source}\n")
        assert (err.line, err.key) == (2, key)
        assert err.message == f"expected a finite number, got {text}"


class Nested(Strict):
    pair: tuple[float, float] = (0.0, 0.0)
    series: dict[str, list[float]] = Field(default_factory=dict)
    bag: set[float] = Field(default_factory=set)


@pytest.mark.parametrize(("source", "key", "message"), [
    ("pair: [1, .inf]\n", "pair[1]", "expected a finite number, got .inf"),
    ("pair: [yes, 1]\n", "pair[0]", "expected a number, got 'yes'"),
    ("series: {a: [1, 2, -.inf]}\n", "series.a[2]", "expected a finite number, got -.inf"),
    ("series: {a: [1, false]}\n", "series.a[1]", "expected a number, got false"),
    ("series: {a: [1, '2']}\n", "series.a[1]", "expected a number, got '2'"),
    ("bag: [1, true]\n", "bag[1]", "expected a number, got true"),
])
def test_nested_numbers_refuse_non_finite_bool_and_text(source: str, key: str,
                                                        message: str) -> None:
    """Nested number containers are screened like plain fields: pydantic's lax mode would
    read ``true`` as 1 and ``'2'`` as 2, and inf/nan are not finite."""
    with pytest.raises(ScenarioError) as info:
        validate_document(parse_yaml("# n\n" + source, "n.yaml"), Nested)
    err = info.value
    assert (err.line, err.key) == (2, key)
    assert message in err.message


def test_literal_too_large_without_a_dot_stays_text_with_a_hint() -> None:
    """``1e400`` is text in YAML 1.1 (no dot): a Number refuses it with the spelling to use."""
    assert parse_yaml("a: 1e400\n").data["a"] == "1e400"
    err = _validation_error("name: x\nvalue: 1e400\n")
    assert "expected a number, got '1e400'" in err.message and "write 1.0e+400" in err.message


@pytest.mark.parametrize(("source", "line", "key", "first"), [
    ("a: 1\nb: 2\na: 3\n", 3, "a", 1),
    ("ships:\n  - name: x\n    speed: 1\n    name: y\n", 4, "ships[0].name", 2),
    ("a:\n  - {k: 1}\n  - {k: 2, j: 0, k: 3}\n", 3, "a[1].k", 3),
])
def test_duplicate_keys_name_both_lines_and_the_key_path(source: str, line: int, key: str,
                                                         first: int) -> None:
    err = _error(source)
    assert (err.line, err.key) == (line, key)
    name = key.rsplit(".", 1)[-1]
    assert f"duplicate key '{name}' (first at line {first}, again at line {line})" in err.message


def test_the_same_key_in_different_mappings_is_not_a_duplicate() -> None:
    doc = parse_yaml("a: {k: 1}\nb: {k: 2}\nc:\n  - k: 3\n  - k: 4\n")
    assert doc.data == {"a": {"k": 1}, "b": {"k": 2}, "c": [{"k": 3}, {"k": 4}]}
    assert [doc.line_of(("c", i, "k")) for i in range(2)] == [4, 5]


def test_size_cap_is_inclusive_in_text_bytes_and_files(tmp_path) -> None:
    """The cap counts UTF-8 bytes (an 'e' with acute accent is 2): a document of exactly
    ``max_bytes`` loads, one byte more is refused, from text and from a file alike."""
    text = "a: '\u00e9\u00e9'\n"  # 4 + 2 * 2 + 2 = 10 bytes
    assert len(text.encode()) == 10
    assert parse_yaml(text, max_bytes=10).data == {"a": "\u00e9\u00e9"}
    assert "limit of 9 bytes" in _error(text, max_bytes=9).message
    path = tmp_path / "s.yaml"
    path.write_text(text, encoding="utf-8")
    assert load_yaml(path, max_bytes=10).data == {"a": "\u00e9\u00e9"}
    with pytest.raises(ScenarioError, match="limit of 9 bytes") as info:
        load_yaml(path, max_bytes=9)
    assert info.value.path == str(path)


def test_validation_lines_survive_bom_and_crlf() -> None:
    """A validation error is located at the same line with or without a BOM and CRLF."""
    src = "name: x\r\ninner:\r\n  speed_kn: 1\r\n  count: 2.5\r\n"
    for data in (src.encode(), b"\xef\xbb\xbf" + src.encode(), src.replace("\r\n", "\n")):
        with pytest.raises(ScenarioError) as info:
            validate_document(parse_yaml(data, "m.yaml"), Model)
        assert (info.value.line, info.value.key) == (4, "inner.count")


def test_locate_fills_the_line_of_an_error_raised_after_the_file_was_read(tmp_path):
    """An error naming a file and a key but no line gets the line of that key (of its parent
    where the key is absent); one already located, or whose file is not YAML, is left as is."""
    path = tmp_path / "s.yaml"
    path.write_text("a: 1\nb:\n  c: 2\n  d: [1, 2]\n")
    err = locate(InputError("bad", path=str(path), key="b.c"))
    assert err.line == 3 and str(err) == f"{path}:3: b.c: bad"
    assert locate(InputError("x", path=str(path), key="b.e")).line == 2  # absent: its parent
    assert locate(InputError("x", path=str(path), line=9, key="b.c")).line == 9
    (tmp_path / "t.csv").write_text("not: [yaml")
    assert locate(InputError("x", path=str(tmp_path / "t.csv"), key="a")).line is None
