from pathlib import Path

import pytest

from trafficsim.campaign.spec import load_spec
from trafficsim.errors import ScenarioError


def test_defaults_and_ranges(write_spec):
    spec = load_spec(write_spec())
    assert spec.n_encounters == 6 and spec.chunk_encounters == 2
    assert spec.dcpa_nm == (0.0, 1.0) and spec.tcpa_min == (10.0, 30.0)
    assert spec.policy == "colregs" and spec.sensors is None
    assert spec.path is not None and spec.path.is_absolute()


@pytest.mark.parametrize("extra, line, words", [
    ("dcpa_nm: [1.0, 0.5]", 9, ["dcpa_nm", "low <= high"]),
    ("encounter_types: {head_on: 1, crosing: 1}", 9, ["encounter_types", "crosing"]),
    ("policy: sometimes", 9, ["policy", "colregs"]),
    ("dt_s: 2\ndecision_period_s: 7", 10, ["decision_period_s", "whole multiple"]),
    ("dt_s: 7", 9, ["dt_s", "duration_s", "whole multiple"]),
    ("sensors: {gnss_sigma_m: [5, 1]}", 9, ["gnss_sigma_m", "low <= high"]),
    ("tcpa_min: [0, 30]", 9, ["tcpa_min"]),
])
def test_errors_name_the_line_and_key(write_spec, extra, line, words):
    path = write_spec(extra=extra)
    with pytest.raises(ScenarioError) as info:
        load_spec(path)
    text = str(info.value)
    assert str(path) in text
    assert f":{line}:" in text
    for w in words:
        assert w in text


def test_unknown_ship_type_is_located(tmp_path: Path, write_spec):
    path = write_spec()
    path.write_text(path.read_text().replace("fishing: 1", "fishin: 1"))
    with pytest.raises(ScenarioError) as info:
        load_spec(path)
    assert ":7:" in str(info.value) and "fishin" in str(info.value)


MINIMAL = """schema_version: 1
name: minimal
n_encounters: 3
duration_s: 1800
{extra}
"""


def _minimal(tmp_path: Path, extra: str = "", name: str = "min.yaml") -> Path:
    path = tmp_path / name
    path.write_text(MINIMAL.format(extra=extra))
    return path


def _error(path: Path) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        load_spec(path)
    return info.value


def test_documented_defaults_of_the_optional_keys(tmp_path):
    """dt_s 1.0, chunk_encounters 500 and decision_period_s 10 are the defaults the module
    docstring states; sensors absent means perfect knowledge (None), rules absent means None."""
    spec = load_spec(_minimal(tmp_path))
    assert spec.dt_s == 1.0 and spec.chunk_encounters == 500
    assert spec.decision_period_s == 10.0
    assert spec.sensors is None and spec.rules is None


def test_every_documented_key_of_the_bundled_default_campaign_is_read(root):
    """The bundled spec writes every key of the module docstring; each must come back as
    written in the file."""
    spec = load_spec(root / "scenarios" / "campaign_default.yaml")
    assert (spec.name, spec.n_encounters, spec.seed, spec.duration_s) == (
        "campaign_default", 1000, 2026, 1800.0)
    assert spec.chunk_encounters == 250 and spec.policy == "colregs"
    assert spec.rules == "../rules/colregs.yaml" and spec.domain == "coldwell"
    assert spec.encounter_types == {k: 1.0 for k in (
        "head_on", "crossing_give_way", "crossing_stand_on", "overtaking", "overtaken",
        "multi")}
    assert spec.multi_ships == (3, 5) and spec.dcpa_nm == (0.0, 1.0)
    assert spec.tcpa_min == (10.0, 30.0) and spec.speed_fraction == (0.6, 1.0)
    assert spec.ship_types == {"cargo": 3, "container": 2, "tanker": 1, "bulk_carrier": 2,
                               "ferry": 1, "fishing": 1}
    assert spec.current_kn == (0.0, 1.0) and spec.wind_mps == (0.0, 15.0)
    assert spec.rogue_fraction == 0.05
    s = spec.sensors
    assert s is not None and s.gnss_sigma_m == (1.0, 5.0) and s.compass_sigma_deg == (0.1, 0.5)
    assert s.radar and s.ais and s.filter == "pv"
    assert (root / "scenarios" / spec.rules).resolve() == (root / "rules" / "colregs.yaml")


@pytest.mark.parametrize("missing", ["schema_version", "name", "n_encounters", "duration_s"])
def test_a_missing_required_key_is_named(tmp_path, missing):
    """The four keys without a default: their absence is reported by name."""
    text = MINIMAL.format(extra="")
    lines = [ln for ln in text.splitlines() if not ln.startswith(missing + ":")]
    path = tmp_path / "m.yaml"
    path.write_text("\n".join(lines) + "\n")
    err = _error(path)
    assert f"missing required key '{missing}'" in str(err) and str(path) in str(err)


@pytest.mark.parametrize("extra", [
    "n_encounters: 1",
    "n_encounters: 10000000",
    "seed: 0",
    "duration_s: 1800\ndt_s: 60\ndecision_period_s: 60",
    "chunk_encounters: 1",
    "chunk_encounters: 1000000",
    "decision_period_s: 600",
    "multi_ships: [3, 3]",
    "multi_ships: [5, 5]",
    "dcpa_nm: [10, 10]",
    "duration_s: 7200\ntcpa_min: [1, 120]",
    "max_duration_s: 1800",
    "min_start_range_nm: 0",
    "min_start_range_nm: 20",
    "max_duration_s: 86400",
    "speed_fraction: [0.2, 1.2]",
    "current_kn: [5, 5]",
    "wind_mps: [0, 40]",
    "visibility_nm: 100",
    "rogue_fraction: 1",
    "rogue_fraction: 0",
    "encounter_types: {multi: 1, head_on: 0}",
    "sensors: {gnss_sigma_m: [0.1, 500], compass_sigma_deg: [0, 10], filter: ekf}",
    "sensors: {}",
])
def test_values_on_the_documented_bounds_are_accepted(tmp_path, extra):
    """Each bound is inclusive where the schema says ``ge``/``le`` (a range may be a single
    value, low == high)."""
    text = MINIMAL.format(extra=extra)
    for key in ("duration_s", "n_encounters"):
        if extra.startswith(key):
            text = "\n".join(ln for ln in text.splitlines()[:4] if not ln.startswith(key))
            text += "\n" + extra + "\n"
    path = tmp_path / "b.yaml"
    path.write_text(text)
    load_spec(path)


@pytest.mark.parametrize("extra, key, words", [
    ("n_encounters: 0", "n_encounters", ">= 1"),
    ("n_encounters: 10000001", "n_encounters", "<= 10000000"),
    ("n_encounters: 10.0", "n_encounters", "whole number"),
    ("n_encounters: true", "n_encounters", "whole number"),
    ("seed: -1", "seed", ">= 0"),
    ("seed: '3'", "seed", "whole number"),
    ("duration_s: 0", "duration_s", "> 0"),
    ("duration_s: fast", "duration_s", "expected a number"),
    ("duration_s: .nan", "duration_s", "finite"),
    ("max_duration_s: 1799", "max_duration_s", "at least duration_s (1800 s), got 1799"),
    ("max_duration_s: 3600.5", "max_duration_s", "whole multiple of dt_s (1 s"),
    ("max_duration_s: 0", "max_duration_s", "> 0"),
    ("min_start_range_nm: -1", "min_start_range_nm", ">= 0"),
    ("min_start_range_nm: 21", "min_start_range_nm", "<= 20"),
    ("dt_s: 61", "dt_s", "<= 60"),
    ("dt_s: 0", "dt_s", "> 0"),
    ("chunk_encounters: 0", "chunk_encounters", ">= 1"),
    ("decision_period_s: 601", "decision_period_s", "<= 600"),
    ("policy: avoid", "policy", "no_avoidance"),
    ("domain: circle", "domain", "goodwin"),
    ("visibility_nm: 0", "visibility_nm", "> 0"),
    ("rogue_fraction: 1.01", "rogue_fraction", "<= 1"),
    ("multi_ships: [2, 5]", "multi_ships[0]", ">= 3"),
    ("multi_ships: [3, 6]", "multi_ships[1]", "<= 5"),
    ("multi_ships: [5, 3]", "multi_ships", "low <= high"),
    ("dcpa_nm: [0, 10.5]", "dcpa_nm[1]", "<= 10"),
    ("dcpa_nm: [0, 1, 2]", "dcpa_nm", "at most 2"),
    ("tcpa_min: [10, 121]", "tcpa_min[1]", "<= 120"),
    ("speed_fraction: [0.1, 1.0]", "speed_fraction[0]", ">= 0.2"),
    ("speed_fraction: [1.0, 0.6]", "speed_fraction", "low <= high"),
    ("current_kn: [0, 6]", "current_kn[1]", "<= 5"),
    ("current_kn: [-1, 1]", "current_kn[0]", ">= 0"),
    ("wind_mps: [0, 41]", "wind_mps[1]", "<= 40"),
    ("wind_mps: [20, 10]", "wind_mps", "low <= high"),
    ("encounter_types: {head_on: 0, multi: 0}", "encounter_types", "at least one weight > 0"),
    ("encounter_types: {}", "encounter_types", "at least one weight > 0"),
    ("encounter_types: {head_on: -1, multi: 2}", "encounter_types.head_on", ">= 0"),
    ("encounter_types: {head_onn: 1}", "encounter_types.head_onn: unknown encounter type "
     "'head_onn' (did you mean 'head_on'?)", ""),
    ("encounter_types: {multi: 1, bogus: 1}", "encounter_types.bogus: unknown encounter type "
     "'bogus' (expected one of head_on, crossing_give_way, crossing_stand_on, overtaking, "
     "overtaken, multi)", ""),
    ("ship_types: {cargo: 0}", "ship_types", "at least one weight > 0"),
    ("ship_types: {cargo: fast}", "ship_types.cargo", "expected a number"),
    ("name: ''", "name", "must not be empty"),
    ("schema_version: 2\nname2: x", "schema_version", "unsupported schema_version 2"),
    ("sensors: {gnss_sigma_m: [0.05, 1]}", "sensors.gnss_sigma_m[0]", ">= 0.1"),
    ("sensors: {compass_sigma_deg: [0, 11]}", "sensors.compass_sigma_deg[1]", "<= 10"),
    ("sensors: {compass_sigma_deg: [1, 0.5]}", "sensors.compass_sigma_deg", "low <= high"),
    ("sensors: {filter: kalman}", "sensors.filter", "ekf"),
    ("sensors: {lidar: true}", "sensors.lidar", "unknown key"),
    ("n_encounter: 4", "n_encounter", "did you mean 'n_encounters'"),
])
def test_bad_values_name_the_file_line_and_key(tmp_path, extra, key, words):
    """Every bad value ends in a ScenarioError located at the line of its key (the extra
    lines start at line 5 of the file) that names the key and says what was expected."""
    text = MINIMAL.format(extra=extra)
    if extra.startswith(("n_encounters:", "schema_version:", "name:", "duration_s:")):
        first = extra.split(":")[0]
        text = "\n".join(ln for ln in text.splitlines()[:4] if not ln.startswith(first + ":"))
        text += "\n" + extra + "\n"
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    err = _error(path)
    line = next(i for i, ln in enumerate(text.splitlines(), 1)
                if ln.startswith(key.split(".")[0].split("[")[0] + ":"))
    assert err.path == str(path) and err.line == line, str(err)
    assert key in str(err) and words in str(err), str(err)


def test_all_errors_are_collected_in_line_order(tmp_path):
    """Three independent mistakes: the message is the first by line plus "(and 2 more
    errors)", and ``errors`` holds all three sorted by line."""
    path = _minimal(tmp_path, extra="rogue_fraction: 2\nvisibility_nm: -1\nseed: -4")
    err = _error(path)
    assert [e.line for e in err.errors] == [5, 6, 7]
    assert [e.key for e in err.errors] == ["rogue_fraction", "visibility_nm", "seed"]
    assert "(and 2 more errors)" in str(err) and err.line == 5


def test_ship_files_are_found_relative_to_the_spec(tmp_path):
    """A ship type that is a path is looked up next to the spec (not the working
    directory); a path that does not exist is located at its line under ship_types."""
    from trafficsim.ships.library import LIBRARY_DIR

    sub = tmp_path / "specs"
    sub.mkdir()
    (sub / "mine.yaml").write_text((LIBRARY_DIR / "cargo.yaml").read_text())
    spec = load_spec(_minimal(sub, extra="ship_types:\n  mine.yaml: 1\n  cargo: 1"))
    assert spec.ship_types == {"mine.yaml": 1.0, "cargo": 1.0}
    path = _minimal(sub, extra="ship_types:\n  cargo: 1\n  nothere.yaml: 1", name="n.yaml")
    err = _error(path)
    assert err.line == 7 and err.key == "ship_types.nothere.yaml" and "not found" in str(err)


def test_unknown_library_ship_suggests_the_close_name(tmp_path):
    err = _error(_minimal(tmp_path, extra="ship_types: {tankr: 1}"))
    assert err.line == 5 and "did you mean 'tanker'" in str(err)


def test_a_spec_is_frozen(tmp_path):
    """Strict models are frozen: a loaded spec cannot be changed by accident."""
    spec = load_spec(_minimal(tmp_path))
    with pytest.raises(ValueError):
        spec.n_encounters = 5


@pytest.mark.parametrize("extra", [
    "duration_s: 1800\ndt_s: 0.1",
    "dt_s: 0.5\ndecision_period_s: 2.5",
    "dt_s: 0.2\ndecision_period_s: 10",
    "dt_s: 60\ndecision_period_s: 600",
])
def test_whole_multiples_in_floating_point_are_accepted(tmp_path, extra):
    """600 / 0.1 and 10 / 0.2 are not exact in binary floating point, yet whole numbers of
    steps: the tolerance must accept them."""
    text = MINIMAL.format(extra=extra)
    if extra.startswith("duration_s"):
        text = text.replace("duration_s: 1800\n", "", 1)
    path = tmp_path / "w.yaml"
    path.write_text(text)
    load_spec(path)


@pytest.mark.parametrize("duration", ["900.5", "0.5"])
def test_duration_not_a_whole_number_of_default_steps_is_refused(tmp_path, duration):
    """``dt_s: 1`` written out makes 900.5 s an error ("whole multiple"); leaving dt_s at its
    documented default of 1 s must not change that (the runner would run round(900.5) = 900
    steps, and round(0.5) = 0 steps for 0.5 s)."""
    written = MINIMAL.replace("duration_s: 1800", f"duration_s: {duration}")
    explicit = tmp_path / "explicit.yaml"
    explicit.write_text(written.format(extra="dt_s: 1"))
    assert "whole multiple" in str(_error(explicit))
    implicit = tmp_path / "implicit.yaml"
    implicit.write_text(written.format(extra=""))
    assert "whole multiple" in str(_error(implicit))


def test_default_decision_period_is_ten_seconds_in_whole_steps(tmp_path):
    """``decision_period_s: 10`` written with ``dt_s: 3`` is refused (not whole steps); left
    out, the default 10 s is rounded to whole steps: 3 steps of 3 s = 9 s, said as such,
    rather than claimed as 10 s while the engine decides every round(10 / 3) = 3 steps."""
    explicit = _minimal(tmp_path, extra="dt_s: 3\ndecision_period_s: 10", name="e.yaml")
    assert "decision_period_s" in str(_error(explicit))
    implicit = load_spec(_minimal(tmp_path, extra="dt_s: 3", name="i.yaml"))
    assert implicit.decision_period_s == 9.0
    assert load_spec(_minimal(tmp_path, extra="dt_s: 0.3", name="d.yaml")).decision_period_s \
        == pytest.approx(33 * 0.3, rel=1e-15)
    assert load_spec(_minimal(tmp_path, extra="dt_s: 60", name="m.yaml")).decision_period_s \
        == 60.0  # at least one step


def test_a_one_item_range_is_reported_as_a_short_list(tmp_path):
    """``dcpa_nm: [0.5]`` lacks the high end of a range, a list item: calling list position 1
    a missing *key* points the user at a mapping that is not there."""
    err = _error(_minimal(tmp_path, extra="dcpa_nm: [0.5]"))
    assert err.line == 5 and "dcpa_nm" in str(err)
    assert "key" not in err.message and "2" in err.message


def test_a_rules_file_that_does_not_exist_is_reported_at_its_line(tmp_path):
    """A misspelt ``rules:`` file is found when the spec is loaded (and so by ``trafficsim
    validate``), at the key's line, not when the first chunk runs."""
    err = _error(_minimal(tmp_path, extra="rules: no_such_rules.yaml"))
    assert err.line == 5 and "rules file not found" in str(err)
    assert str(tmp_path / "no_such_rules.yaml") in str(err)
    rules = tmp_path / "mine.yaml"
    rules.write_text("x: 1\n")
    spec = load_spec(_minimal(tmp_path, extra="rules: mine.yaml", name="ok.yaml"))
    assert spec.rules == "mine.yaml"


def test_the_format_example_of_the_module_docstring_loads_as_written(tmp_path, root):
    """The YAML block of ``trafficsim.campaign.spec``'s docstring is the documented format:
    written to a file (with its ``../rules/colregs.yaml`` next door) it loads, and reads back
    the values it shows."""
    from trafficsim.campaign import spec as spec_module

    doc = spec_module.__doc__
    block = doc[doc.index("::\n") + 3: doc.index("Every range is")]
    text = "\n".join(ln[4:] for ln in block.splitlines()) + "\n"
    (tmp_path / "rules").mkdir()
    (tmp_path / "rules" / "colregs.yaml").write_text(
        (root / "rules" / "colregs.yaml").read_text())
    (tmp_path / "specs").mkdir()
    path = tmp_path / "specs" / "doc.yaml"
    path.write_text(text)
    spec = load_spec(path)
    assert (spec.name, spec.n_encounters, spec.seed, spec.duration_s) == (
        "default", 1000, 1, 1800.0)
    assert spec.multi_ships == (3, 5) and spec.tcpa_min == (10.0, 30.0)
    assert spec.ship_types["cargo"] == 2 and spec.rogue_fraction == 0.05
    assert spec.sensors is not None and spec.sensors.filter == "pv"


BLOCK = """schema_version: 1
name: block
n_encounters: 3
duration_s: 600
sensors:
  radar: true
  gnss_sigma_m: [5, 1]
ship_types:
  cargo: 2
  fishing: -1
encounter_types:
  head_on: 1
  crosing: 1
multi_ships:
  - 3
  - 6
"""


def test_errors_in_block_mappings_point_at_the_nested_line(tmp_path):
    """Written as block mappings and lists, every bad entry is located at its own line (not
    at the header line of its section), with its dotted key; all four are collected."""
    path = tmp_path / "block.yaml"
    path.write_text(BLOCK)
    err = _error(path)
    lines = BLOCK.splitlines()
    expected = [(lines.index("  gnss_sigma_m: [5, 1]") + 1, "sensors.gnss_sigma_m"),
                (lines.index("  fishing: -1") + 1, "ship_types.fishing"),
                (lines.index("  crosing: 1") + 1, "encounter_types.crosing"),
                (lines.index("  - 6") + 1, "multi_ships[1]")]
    got = [(e.line, e.key) for e in err.errors]
    assert [g[0] for g in got] == [e[0] for e in expected], got
    for (_, key), (_, want) in zip(got, expected, strict=True):
        assert key.startswith(want) and "[key]" not in key, got
    assert err.path == str(path) and str(path) in str(err)


def test_a_file_that_is_not_a_mapping_or_not_yaml_is_located(tmp_path):
    """A list at the top level, and a tab-broken line, are ScenarioErrors naming the file."""
    listed = tmp_path / "list.yaml"
    listed.write_text("- schema_version: 1\n")
    assert str(listed) in str(_error(listed))
    broken = tmp_path / "broken.yaml"
    broken.write_text("schema_version: 1\nname: [x\n")
    err = _error(broken)
    assert str(broken) in str(err) and err.line is not None


@pytest.mark.parametrize("extra, tcpa", [
    ("", "30 min = 1800 s"),  # the default tcpa_min [10, 30]
    ("tcpa_min: [1, 5.5]", "5.5 min = 330 s"),
])
def test_a_duration_shorter_than_the_largest_start_tcpa_is_refused_at_its_line(
        tmp_path, capsys, extra, tcpa):
    """An encounter drawn with a start TCPA beyond the run never reaches its CPA: its smallest
    range would be the last step's. ``duration_s`` below ``60 * tcpa_min[1]`` is refused at
    its line, by ``load_spec`` and by ``validate`` (exit 2, one line); equal is accepted."""
    from tests.conftest import error_line

    path = tmp_path / "short.yaml"
    path.write_text(MINIMAL.replace("duration_s: 1800", "duration_s: 300").format(extra=extra))
    err = _error(path)
    assert (err.path, err.line, err.key) == (str(path), 4, "duration_s")
    assert f"must be at least tcpa_min's upper end, {tcpa}, so that every encounter reaches " \
           "its CPA" in err.message and err.message.endswith("got 300")
    line = error_line(capsys, ["validate", path])
    assert line.startswith(f"trafficsim: error: {path}:4: duration_s: must be at least")
    path.write_text(MINIMAL.replace("duration_s: 1800", "duration_s: 330").format(
        extra="tcpa_min: [1, 5.5]"))
    assert load_spec(path).duration_s == 330.0


def test_a_decision_period_longer_than_the_duration_is_refused(tmp_path):
    """As in a scenario file: the ships would decide once, at the start."""
    path = _minimal(tmp_path, extra="decision_period_s: 600")
    path.write_text(path.read_text().replace("duration_s: 1800", "duration_s: 60\n"
                                             "tcpa_min: [1, 1]"))
    err = _error(path)
    assert (err.path, err.line, err.key) == (str(path), 6, "decision_period_s")
    assert err.message == ("must not exceed duration_s (60 s), got 600 (the ships would decide "
                           "once, at the start)")
    path.write_text(path.read_text().replace("decision_period_s: 600", "decision_period_s: 60"))
    assert load_spec(path).decision_period_s == 60.0


def test_an_encounter_runs_at_most_max_duration_s_and_at_least_duration_s(tmp_path):
    """Without ``max_duration_s`` an encounter runs ``duration_s``; with it, up to that."""
    assert load_spec(_minimal(tmp_path)).longest_s == 1800.0
    spec = load_spec(_minimal(tmp_path, extra="max_duration_s: 3600", name="m.yaml"))
    assert (spec.duration_s, spec.max_duration_s, spec.longest_s) == (1800.0, 3600.0, 3600.0)
