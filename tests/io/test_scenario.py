"""Tests of the scenario schema and loader, with golden corpora of valid and invalid files.

Every ``scenarios/invalid/*.yaml`` starts with ``# expect: <line>: <substring of the message>``.
"""

from __future__ import annotations

import itertools
import math
import re
import shutil
import string
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from trafficsim.errors import ScenarioError
from trafficsim.io.scenario import (
    MAX_DURATION_S,
    SCHEMA_VERSION,
    Current,
    Scenario,
    Wind,
    load_scenario,
)
from trafficsim.ships import library

HERE = Path(__file__).parent
VALID = sorted((HERE / "scenarios" / "valid").glob("*.yaml"))
INVALID = sorted((HERE / "scenarios" / "invalid").glob("*.yaml"))
EXPECT = re.compile(rb"# expect: (\d+): (.*)")

MINIMAL = """\
schema_version: 1
name: t
duration_s: 420
{extra}ships:
  - {{name: own, type: kvlcc2, north_m: 0, east_m: 0, heading_deg: 0}}
"""


def _write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _expectation(path: Path) -> tuple[int, str]:
    match = EXPECT.match(path.read_bytes().splitlines()[0])
    assert match, f"{path.name}: first line must be '# expect: <line>: <message part>'"
    return int(match.group(1)), match.group(2).decode("utf-8").strip()


# ------------------------------------------------------------------------------------------
# Golden corpora
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("path", VALID, ids=lambda p: p.stem)
def test_valid_corpus(path: Path) -> None:
    scenario = load_scenario(path)
    assert scenario.schema_version == SCHEMA_VERSION
    assert scenario.path == path.resolve() and scenario.path.is_absolute()
    assert scenario.ships
    for ship_file in scenario.ship_files:
        assert ship_file is not None and ship_file.is_absolute() and ship_file.is_file()


def test_invalid_corpus_is_broad() -> None:
    assert len(INVALID) >= 14
    assert len(VALID) >= 2


@pytest.mark.parametrize("path", INVALID, ids=lambda p: p.stem)
def test_invalid_corpus(path: Path) -> None:
    line, text = _expectation(path)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert type(err) is ScenarioError
    assert err.line == line, str(err)
    assert err.path == str(path)
    assert text in str(err), str(err)
    assert str(err).startswith(f"{path}:{line}: ")


# ------------------------------------------------------------------------------------------
# Values and defaults
# ------------------------------------------------------------------------------------------

def test_full_values_keep_file_units() -> None:
    scenario = load_scenario(HERE / "scenarios" / "valid" / "full.yaml")
    assert scenario.name == "head_on"
    assert scenario.description.startswith("Two tankers")
    assert (scenario.duration_s, scenario.dt_s, scenario.seed) == (1800.0, 0.5, 42)
    assert scenario.record_every_s == 5.0
    assert scenario.environment.current == Current(speed_kn=0.5, towards_deg=90)
    assert scenario.environment.wind == Wind(speed_mps=10, from_deg=45.5)
    own, target = scenario.ships
    assert (own.name, own.type, own.speed_kn, own.heading_deg) == ("own", "kvlcc2", 12.0, 0.0)
    assert own.route == ((5000.0, 0.0), (9000.0, 3000.0))
    assert target.route == ((4000.0, 0.0), (-1000.5, -2000.0))
    assert (target.north_m, target.east_m) == (9000.0, -50.0)
    assert all(isinstance(v, float) for v in (own.north_m, target.east_m, own.speed_kn))
    assert own.ship_file == library.find_ship("kvlcc2")


def test_minimal_defaults() -> None:
    scenario = load_scenario(HERE / "scenarios" / "valid" / "minimal.yaml")
    assert scenario.dt_s == 1.0 and scenario.seed == 0 and scenario.record_every_s == 1.0
    assert scenario.description == ""
    assert scenario.environment.current is None and scenario.environment.wind is None
    (ship,) = scenario.ships
    assert ship.speed_kn is None and ship.route == ()


def test_quirks_file_values() -> None:
    scenario = load_scenario(HERE / "scenarios" / "valid" / "yaml_quirks.yaml")
    assert scenario.name == "no" and scenario.description == "1:30"
    assert scenario.duration_s == 5400.0
    assert math.isclose(scenario.record_every_s, 0.3)
    ship = scenario.ships[0]
    assert ship.name == "on" and ship.north_m == -1000.0 and ship.east_m == 16.0


@pytest.mark.parametrize(("dt", "every"), [(1.0, 1.0), (0.5, 1.0), (0.1, 1.0), (0.3, 1.2),
                                           (2.0, 2.0), (60.0, 60.0), (0.7, 1.4)])
def test_record_default_is_one_second_rounded_up_to_whole_steps(tmp_path, dt, every) -> None:
    scenario = load_scenario(_write(tmp_path, MINIMAL.format(extra=f"dt_s: {dt!r}\n")))
    assert math.isclose(scenario.record_every_s, every)
    ratio = scenario.record_every_s / scenario.dt_s
    assert abs(ratio - round(ratio)) < 1e-9


@pytest.mark.parametrize(("dt", "every", "ok"), [
    (0.1, 0.3, True), (0.1, 0.7, True), (0.2, 1.0, True), (1.0, 1.0, True), (2.0, 10.0, True),
    (0.1, 0.35, False), (1.0, 0.5, False), (2.0, 3.0, False), (0.3, 1.0, False)])
def test_record_every_must_be_multiple(tmp_path, dt, every, ok) -> None:
    path = _write(tmp_path, MINIMAL.format(extra=f"dt_s: {dt!r}\nrecord_every_s: {every!r}\n"))
    if ok:
        assert load_scenario(path).record_every_s == every
    else:
        with pytest.raises(ScenarioError, match="whole multiple of dt_s") as info:
            load_scenario(path)
        assert info.value.line == 5 and info.value.key == "record_every_s"


def test_limits(tmp_path) -> None:
    ok = MINIMAL.replace("duration_s: 420", f"duration_s: {MAX_DURATION_S!r}").format(extra="")
    assert load_scenario(_write(tmp_path, ok)).duration_s == 30 * 86400
    too_long = ok.replace(repr(MAX_DURATION_S), "2592001")
    with pytest.raises(ScenarioError, match="must be <= 2592000, got 2592001"):
        load_scenario(_write(tmp_path, too_long))
    with pytest.raises(ScenarioError, match=r"dt_s: must be <= 60, got 61"):
        load_scenario(_write(tmp_path, MINIMAL.format(extra="dt_s: 61\n")))
    with pytest.raises(ScenarioError, match=r"dt_s: must be > 0, got 0"):
        load_scenario(_write(tmp_path, MINIMAL.format(extra="dt_s: 0\n")))
    with pytest.raises(ScenarioError, match=r"seed: must be >= 0, got -1"):
        load_scenario(_write(tmp_path, MINIMAL.format(extra="seed: -1\n")))
    with pytest.raises(ScenarioError, match=r"seed: expected a whole number, got 1.5"):
        load_scenario(_write(tmp_path, MINIMAL.format(extra="seed: 1.5\n")))
    # positions in the flat local frame: within 1,000 km of the origin, route points too
    far = MINIMAL.format(extra="").replace("north_m: 0,", "north_m: 1000001,")
    with pytest.raises(ScenarioError, match=r"ships\[0\].north_m: must be <= 1000000, got 1000001"):
        load_scenario(_write(tmp_path, far))
    route = MINIMAL.format(extra="").replace("heading_deg: 0}",
                                             "heading_deg: 0, route: [[0, -2000000]]}")
    with pytest.raises(ScenarioError, match=r"route\[0\]\[1\]: must be >= -1000000"):
        load_scenario(_write(tmp_path, route))


def test_empty_optional_values_take_defaults(tmp_path) -> None:
    scenario = load_scenario(_write(tmp_path, MINIMAL.format(
        extra="dt_s: 0.5\nrecord_every_s:\nenvironment:\n")))
    assert scenario.record_every_s == 1.0 and scenario.environment.current is None


def test_validated_without_a_file_has_no_paths() -> None:
    scenario = Scenario.model_validate({
        "schema_version": 1, "name": "x", "duration_s": 10,
        "ships": [{"name": "a", "type": "kvlcc2", "north_m": 0, "east_m": 0, "heading_deg": 0}]})
    assert scenario.path is None and scenario.ship_files == (None,)


def test_default_dt_longer_than_duration(tmp_path) -> None:
    text = MINIMAL.replace("duration_s: 420", "duration_s: 0.5").format(extra="")
    with pytest.raises(ScenarioError, match=r"dt_s: must not exceed duration_s \(0.5 s\)"):
        load_scenario(_write(tmp_path, text))


@pytest.mark.parametrize(("environment", "message"), [
    ("  wind: {speed_mps: 61, from_deg: 0}\n", "environment.wind.speed_mps: must be <= 60"),
    ("  wind: {speed_mps: 5, from_deg: 360}\n", "environment.wind.from_deg: must be < 360"),
    ("  wind: {speed_mps: 5}\n", "environment.wind.from_deg: missing required key 'from_deg'"),
    ("  current: {speed_kn: -1, towards_deg: 0}\n", "environment.current.speed_kn: must be >= 0"),
    ("  current: {speed_kn: 1, towards: 0}\n", "unknown key 'towards' (did you mean"),
    ("  waves: {height_m: 1}\n", "environment.waves: unknown key 'waves'; allowed keys: "
                                 "current, wind"),
])
def test_environment_errors(tmp_path, environment: str, message: str) -> None:
    text = MINIMAL.format(extra="environment:\n" + environment)
    with pytest.raises(ScenarioError, match=re.escape(message)) as info:
        load_scenario(_write(tmp_path, text))
    assert info.value.line == 5


def test_frozen(tmp_path) -> None:
    scenario = load_scenario(HERE / "scenarios" / "valid" / "minimal.yaml")
    with pytest.raises(Exception, match="frozen"):
        scenario.name = "x"  # type: ignore[misc]
    with pytest.raises(Exception, match="frozen"):
        scenario.ships[0].north_m = 1.0  # type: ignore[misc]


def test_oversize_file(tmp_path) -> None:
    padding = "# " + "x" * 99 + "\n"
    text = MINIMAL.format(extra="") + padding * 10_001   # a little over 1 MB
    path = _write(tmp_path, text)
    assert path.stat().st_size > 1_000_000
    with pytest.raises(ScenarioError, match="larger than the limit of 1000000 bytes") as info:
        load_scenario(path)
    assert info.value.line is None
    assert str(info.value).startswith(f"{path}: ")


def test_zero_byte_file(tmp_path) -> None:
    with pytest.raises(ScenarioError, match="file is empty") as info:
        load_scenario(_write(tmp_path, ""))
    assert info.value.line == 1


def test_missing_file(tmp_path) -> None:
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "nope.yaml")


# ------------------------------------------------------------------------------------------
# Ship lookup
# ------------------------------------------------------------------------------------------

def test_ship_type_as_relative_path(tmp_path) -> None:
    (tmp_path / "ships").mkdir()
    shutil.copy(library.find_ship("kvlcc2"), tmp_path / "ships" / "tanker.yaml")
    (tmp_path / "scen").mkdir()
    text = MINIMAL.replace("type: kvlcc2", "type: ../ships/tanker.yaml").format(extra="")
    scenario = load_scenario(_write(tmp_path / "scen", text))
    assert scenario.ships[0].ship_file == (tmp_path / "ships" / "tanker.yaml").resolve()
    assert scenario.ships[0].type == "../ships/tanker.yaml"   # the file's text is kept


def test_ship_type_missing_path_located(tmp_path) -> None:
    text = MINIMAL.replace("type: kvlcc2", "type: ships/none.yaml").format(extra="")
    with pytest.raises(ScenarioError, match=r"ship file 'ships/none\.yaml' not found") as info:
        load_scenario(_write(tmp_path, text))
    assert info.value.line == 5 and info.value.key == "ships[0].type"


def test_ship_lookup_gets_the_scenario_directory(tmp_path, monkeypatch) -> None:
    calls: list[tuple[str, Path]] = []

    def fake_find_ship(kind: str, base_dir: Path | None) -> Path:
        calls.append((kind, base_dir))
        return Path(kind) if base_dir is None else base_dir / f"{kind}.yaml"

    monkeypatch.setattr(library, "find_ship", fake_find_ship)
    shutil.copy(library.LIBRARY_DIR / "kvlcc2.yaml", tmp_path / "kvlcc2.yaml")
    path = _write(tmp_path, MINIMAL.format(extra=""))
    scenario = load_scenario(path)
    # (then the ship file is read from where the lookup found it, for the per-ship checks)
    assert calls[0] == ("kvlcc2", tmp_path.absolute())
    assert scenario.ship_files == (tmp_path.absolute() / "kvlcc2.yaml",)


def test_every_error_is_collected(tmp_path) -> None:
    text = """\
schema_version: 1
name: many
duration_s: -1
ships:
  - name: a
    type: kvlcc
    north_m: x
    east_m: 0
    heading_deg: 0
  - name: b
    type: nosuchship
    north_m: 0
    east_m: 0
    heading_deg: 400
"""
    with pytest.raises(ScenarioError) as info:
        load_scenario(_write(tmp_path, text))
    errors = info.value.errors
    assert [(e.line, e.key) for e in errors] == [
        (3, "duration_s"), (6, "ships[0].type"), (7, "ships[0].north_m"),
        (11, "ships[1].type"), (14, "ships[1].heading_deg")]
    assert "unknown ship 'kvlcc' (did you mean 'kvlcc2'?)" in errors[1].message
    assert info.value.line == 3
    assert info.value.message.endswith("(and 4 more errors)")


# ------------------------------------------------------------------------------------------
# Properties
# ------------------------------------------------------------------------------------------

NAMES = st.text(string.ascii_letters + string.digits + "_- .", min_size=1, max_size=12).filter(
    str.strip) | st.sampled_from(["no", "yes", "on", "off", "1:30", "010", "null", "~", "1e5",
                                  "2024-01-01", "true", "#x", "- a", "a: b"])
COORD = st.floats(-1e6, 1e6, allow_nan=False) | st.integers(-10**6, 10**6)
DIRECTION = st.floats(0.0, 360.0, exclude_max=True) | st.integers(0, 359)


@st.composite
def scenarios(draw: st.DrawFn) -> dict:
    names = draw(st.lists(NAMES, min_size=1, max_size=4, unique=True))
    ships = []
    for name in names:
        ship = {"name": name, "type": "kvlcc2", "north_m": draw(COORD), "east_m": draw(COORD),
                "heading_deg": draw(DIRECTION)}
        if draw(st.booleans()):  # (at most twice the kvlcc2's 15.5 kn)
            ship["speed_kn"] = draw(st.floats(0.0, 31.0) | st.integers(0, 31))
        if draw(st.booleans()):
            route = draw(st.lists(st.lists(COORD, min_size=2, max_size=2), max_size=4))
            # no point twice in a row, and a lone point away from the start
            assume(all(a != b for a, b in itertools.pairwise(route)))
            assume(route != [[ship["north_m"], ship["east_m"]]])
            ship["route"] = route
        ships.append(ship)
    # hulls apart at the start (the kvlcc2 is 320 m long)
    assume(all(math.hypot(a["north_m"] - b["north_m"], a["east_m"] - b["east_m"]) > 400.0
               for k, a in enumerate(ships) for b in ships[:k]))
    set_dt = draw(st.booleans())
    dt = draw(st.sampled_from([0.1, 0.25, 0.5, 1.0, 2.0, 10.0])) if set_dt else 1.0
    data: dict = {"schema_version": 1, "name": draw(NAMES),
                  "duration_s": dt * draw(st.integers(1, int(MAX_DURATION_S / dt))),
                  "ships": ships}
    if set_dt:
        data["dt_s"] = dt
        if draw(st.booleans()):
            data["record_every_s"] = dt * draw(st.integers(1, 100))
            assume(data["record_every_s"] <= data["duration_s"])
    if draw(st.booleans()):
        data["seed"] = draw(st.integers(0, 2**64))
    if draw(st.booleans()):
        data["description"] = draw(st.text(max_size=30))
    environment = {}
    if draw(st.booleans()):
        environment["current"] = {"speed_kn": draw(st.floats(0.0, 10.0)),
                                  "towards_deg": draw(DIRECTION)}
    if draw(st.booleans()):
        environment["wind"] = {"speed_mps": draw(st.floats(0.0, 60.0)),
                               "from_deg": draw(DIRECTION)}
    if environment:
        data["environment"] = environment
    return data


def _as_lists(value: object) -> object:
    if isinstance(value, dict):
        return {k: _as_lists(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_as_lists(v) for v in value]
    return value


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=scenarios())
def test_random_valid_scenarios_round_trip(tmp_path_factory, data: dict) -> None:
    assume("\x85" not in data.get("description", "")
           and "\u2028" not in data.get("description", "")
           and "\u2029" not in data.get("description", ""))   # PyYAML emitter quirk
    folder = tmp_path_factory.mktemp("round")
    first = load_scenario(_write(folder, yaml.safe_dump(data, allow_unicode=True)))
    assert _as_lists(first.model_dump(exclude_unset=True)) == data
    # Dumping the validated scenario (defaults included) and loading it again is the identity.
    dumped = yaml.safe_dump(first.model_dump(mode="json"), allow_unicode=True)
    second = load_scenario(_write(folder, dumped, "again.yaml"))
    assert second.model_dump() == first.model_dump()
    assert second.ship_files == first.ship_files


BASE = (HERE / "scenarios" / "valid" / "full.yaml").read_text(encoding="utf-8")
PIECES = st.sampled_from([*":-,[]{}#&*!|>'\"\n\t .0123456789",
                          "yes", "no", "1:30", ".nan", ".inf", "~", "\n  ", "\n- ", "name",
                          "ships", "type", "kvlcc", "!!python/tuple", "<<: ", "? ", "---"])


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(edits=st.lists(st.tuples(st.integers(0, len(BASE)), st.integers(0, 3), PIECES),
                      min_size=1, max_size=4))
def test_mutated_scenarios_raise_only_scenario_errors(tmp_path_factory, edits) -> None:
    text = BASE
    for position, cut, piece in edits:
        text = text[:position] + piece + text[position + cut:]
    path = _write(tmp_path_factory.mktemp("mut"), text)
    try:
        load_scenario(path)
    except ScenarioError as err:
        assert err.path == str(path)
        assert err.line is None or 1 <= err.line <= text.count("\n") + 2
        for each in getattr(err, "errors", [err]):
            assert isinstance(each, ScenarioError) and each.message


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=200) | st.text(max_size=200).map(str.encode))
def test_random_files_raise_only_scenario_errors(tmp_path_factory, data: bytes) -> None:
    path = tmp_path_factory.mktemp("rnd") / "r.yaml"
    path.write_bytes(data)
    try:
        load_scenario(path)
    except ScenarioError as err:
        assert err.path == str(path)


@pytest.mark.parametrize("dt, period", [(1.0, 10.0), (3.0, 9.0), (4.0, 8.0), (60.0, 60.0)])
def test_default_decision_period_is_ten_seconds_in_whole_steps(tmp_path, dt, period) -> None:
    """Left out, the decision period is 10 s rounded to the nearest whole number of steps (at
    least one; 2.5 steps round to 2, as Python rounds): what the engine runs, rather than a
    10 s it cannot keep."""
    scn = load_scenario(_write(tmp_path, MINIMAL.format(extra=f"dt_s: {dt}\n")))
    assert scn.decision_period_s == period


def test_a_missing_rules_file_is_reported_at_its_line(tmp_path) -> None:
    """A misspelt ``rules:`` file is an error of the scenario, at the key's line, before the
    run starts."""
    with pytest.raises(ScenarioError, match="rules file not found") as info:
        load_scenario(_write(tmp_path, MINIMAL.format(extra="rules: nope.yaml\n")))
    assert info.value.line == 4 and info.value.key == "rules"


@pytest.mark.parametrize(("duration", "dt"), [("10.6", ""), ("2.5", ""), ("100", "dt_s: 3\n")])
def test_duration_not_a_whole_number_of_steps_is_refused(tmp_path, duration, dt) -> None:
    """10.6 s at the default 1 s step would simulate 11 s (2.5 s: 2 s, 100 s at 3 s: 99 s) and
    report the duration written: refused, naming both settings."""
    text = MINIMAL.replace("duration_s: 420", f"duration_s: {duration}").format(extra=dt)
    with pytest.raises(ScenarioError, match=rf"duration_s \({duration} s\) must be a whole "
                                            "multiple of dt_s"):
        load_scenario(_write(tmp_path, text))
