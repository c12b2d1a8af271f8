"""The COLREGS vocabulary (trafficsim.colregs.vocabulary): its enum constants, the round trip
between their names and values, the feature order and the action fields a rules file may set."""

from __future__ import annotations

import math
import re

import pytest

from trafficsim.colregs import features, vocabulary
from trafficsim.colregs.rulefile import parse
from trafficsim.colregs.vocabulary import (
    ACTIONS,
    ALTER_COURSE,
    DIRECTIONS,
    EITHER,
    EMERGENCY,
    ENCOUNTERS,
    ENUMS,
    FEATURES,
    GIVE_WAY,
    KEEP,
    MANOEUVRES,
    MEMORY,
    MUTUAL_GIVE_WAY,
    NO_ACTION,
    NO_ROLE,
    PORT,
    REDUCE_SPEED,
    RESUME_ROUTE,
    ROLES,
    STAND_ON,
    STARBOARD,
    VOCABULARY,
)
from trafficsim.errors import InputError

GROUPS = (ROLES, ENCOUNTERS, MANOEUVRES, DIRECTIONS)
DOC = vocabulary.__doc__ or ""


def _one_action_rules(field: str, value: str) -> str:
    return ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
            f"  a: {{test: true, action: {{{field}: {value}}}, yes: {{to: a, next: true}}}}\n")


def test_enums_hold_every_constant_of_every_group_once() -> None:
    names = [n for group in GROUPS for n in group]
    assert len(set(names)) == len(names)
    assert list(ENUMS) == names


@pytest.mark.parametrize(("decade", "group"), list(enumerate(GROUPS)))
def test_each_group_of_constants_lives_in_its_own_decade_in_written_order(
        decade: int, group: tuple[str, ...]) -> None:
    assert len(group) <= 10
    assert [ENUMS[name] for name in group] == [10.0 * decade + k for k in range(len(group))]


@pytest.mark.parametrize("name", list(ENUMS))
def test_every_value_names_exactly_its_constant(name: str) -> None:
    assert VOCABULARY.enum_names(ENUMS[name]) == (name,)


@pytest.mark.parametrize("value", [-1.0, 0.5, 4.0, 9.0, 16.0, 26.0, 33.0, math.nan])
def test_a_value_that_is_no_constant_names_nothing(value: float) -> None:
    assert VOCABULARY.enum_names(value) == ()


@pytest.mark.parametrize(("constant", "name"), [
    (NO_ROLE, "no_role"), (GIVE_WAY, "give_way"), (STAND_ON, "stand_on"),
    (MUTUAL_GIVE_WAY, "mutual_give_way"), (NO_ACTION, "no_action"), (KEEP, "keep"),
    (ALTER_COURSE, "alter_course"), (REDUCE_SPEED, "reduce_speed"),
    (RESUME_ROUTE, "resume_route"), (EMERGENCY, "emergency"), (STARBOARD, "starboard"),
    (PORT, "port"), (EITHER, "either")])
def test_module_constants_carry_the_value_of_their_name(constant: float, name: str) -> None:
    assert constant == ENUMS[name]
    assert VOCABULARY.enum_names(constant) == (name,)


def test_the_vocabulary_is_built_from_the_module_tables() -> None:
    assert VOCABULARY.features == FEATURES
    assert dict(VOCABULARY.enums) == ENUMS
    assert dict(VOCABULARY.actions) == ACTIONS


def test_memory_features_follow_the_geometry_features() -> None:
    assert (*features.NAMES, *MEMORY) == FEATURES
    assert len(set(FEATURES)) == len(FEATURES)
    # the geometry features' own module documents them under these names
    assert all(f"``{name}``" in (features.__doc__ or "") for name in features.NAMES)


def test_memory_features_are_in_the_order_of_the_documented_table() -> None:
    rows = re.findall(r"^  ``(\w+)``", DOC, flags=re.MULTILINE)  # first column of the table
    assert tuple(rows) == MEMORY


def test_every_constant_and_action_field_is_documented() -> None:
    documented = set(re.findall(r"``(\w+)``", DOC))
    assert set(ENUMS) <= documented
    assert set(ACTIONS) <= documented


@pytest.mark.parametrize(("field", "group"), [
    ("role", ROLES), ("other_role", ROLES), ("encounter", ENCOUNTERS),
    ("manoeuvre", MANOEUVRES), ("direction", DIRECTIONS)])
def test_enum_action_fields_accept_exactly_their_group(field: str, group: tuple) -> None:
    assert ACTIONS[field].constants == group
    assert not ACTIONS[field].numeric


@pytest.mark.parametrize("field", ["course_change_deg", "speed_factor", "pass_distance_nm"])
def test_numeric_action_fields_take_numbers(field: str) -> None:
    assert ACTIONS[field].numeric and ACTIONS[field].constants == ()


def test_action_fields_are_the_documented_eight() -> None:
    assert set(ACTIONS) == {"role", "encounter", "other_role", "manoeuvre", "direction",
                            "course_change_deg", "speed_factor", "pass_distance_nm"}


@pytest.mark.parametrize(("field", "constant"), [
    (field, name) for field, spec in ACTIONS.items() for name in spec.constants])
def test_a_constant_set_in_a_rules_file_reads_back_as_its_name(field: str, constant: str
                                                              ) -> None:
    rules = parse(_one_action_rules(field, constant), VOCABULARY)
    value = rules.node("a").action[field].value
    assert value == ENUMS[constant]
    assert VOCABULARY.enum_names(value) == (constant,)


@pytest.mark.parametrize("constant", ROLES)
def test_a_role_tested_in_a_rules_file_compares_with_its_value(constant: str) -> None:
    source = ("schema_version: 1\nname: t\nstart: a\nnodes:\n"
              f"  a: {{test: [own_role, '==', {constant}], yes: {{to: a, next: true}}, "
              "no: {to: a, next: true}}\n")
    test = parse(source, VOCABULARY).node("a").test
    assert test.feature == "own_role"
    assert test.value.written == constant and test.value.value == ENUMS[constant]


@pytest.mark.parametrize(("field", "wrong"), [
    ("role", "alter_course"), ("direction", "give_way"), ("manoeuvre", "port"),
    ("encounter", "stand_on")])
def test_a_constant_of_another_group_is_refused_for_an_action_field(field: str, wrong: str
                                                                   ) -> None:
    with pytest.raises(InputError, match=f"unknown value '{wrong}' for action field '{field}'"):
        parse(_one_action_rules(field, wrong), VOCABULARY)
