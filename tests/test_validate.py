"""Tests of ``trafficsim validate`` (trafficsim.validate): scenario, ship and rules files."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from tests.conftest import SCENARIOS, SHARED
from trafficsim import cli
from trafficsim.colregs.rulefile import parse_file
from trafficsim.colregs.vocabulary import VOCABULARY
from trafficsim.validate import (
    EXIT_INVALID,
    check_file,
    is_rules_data,
    validate_file,
    validate_files,
)

RULES = Path(__file__).parent / "colregs" / "rules" / "colregs"
SMALL, PORT, INVALID = (RULES / f"{n}.yaml" for n in ("small", "small_port", "small_invalid"))


def _run(paths: list[Path]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = validate_files(paths, out, err)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize(("data", "expected"), [
    ({"nodes": {}}, True), ({"extends": "a.yaml"}, True), ({"ships": []}, False),
    ({"model": "x"}, False), ([1], False), (None, False)])
def test_rules_files_are_told_by_their_keys(data: object, expected: bool) -> None:
    assert is_rules_data(data) is expected


def test_small_rules_files_are_valid_against_the_colregs_vocabulary() -> None:
    small = parse_file(SMALL, VOCABULARY)
    port = parse_file(PORT, VOCABULARY)
    assert [n.name for n in small.nodes] == ["watch", "classify", "give_way", "monitor"]
    assert small.node("give_way").action["direction"].value == VOCABULARY.enums["starboard"]
    assert port.node("give_way").action["direction"].value == VOCABULARY.enums["port"]
    assert port.node("give_way").path == str(SMALL)


def test_valid_rules_files_print_their_node_count() -> None:
    assert check_file(SMALL) == ([], "ok (4 nodes)")
    code, out, err = _run([SMALL, PORT])
    assert code == 0 and err == ""
    # a file that extends another counts the nodes it inherits
    assert out.splitlines() == [f"{SMALL}: ok (4 nodes)", f"{PORT}: ok (4 nodes)"]


def test_one_node_is_singular(tmp_path: Path) -> None:
    path = tmp_path / "one.yaml"
    path.write_text("schema_version: 1\nname: one\nstart: a\nnodes:\n"
                    "  a: {test: true, yes: {to: a, next: true}}\n")
    assert check_file(path) == ([], "ok (1 node)")


def test_invalid_rules_file_lists_every_error_located() -> None:
    code, out, err = _run([INVALID])
    assert code == EXIT_INVALID and out == ""
    lines = err.splitlines()
    assert [line.split(": ", 4)[2:4] for line in lines] == [
        [f"{INVALID}:7", "parameters.alteration_side"],
        [f"{INVALID}:12", "nodes.watch.no.to"],
        [f"{INVALID}:16", "nodes.give_way.action.speed"]]
    assert all(line.startswith("trafficsim: error: ") for line in lines)
    assert "unknown enum constant 'starbord' (did you mean 'starboard'?)" in lines[0]
    assert "unknown node 'wach' (did you mean 'watch'?)" in lines[1]
    assert "unknown action field 'speed'" in lines[2]
    assert validate_file(INVALID)[0].line == 7


def test_errors_of_an_extended_file_are_located_in_it(tmp_path: Path) -> None:
    (tmp_path / "small.yaml").write_text(SMALL.read_text().replace("[dcpa_nm,", "[dcpa,"))
    child = tmp_path / "child.yaml"
    child.write_text(PORT.read_text().replace("alteration_side: port", "alteration_sid: port"))
    errors = validate_file(child)
    assert [(Path(e.path).name, e.line, e.key) for e in errors] == [
        ("child.yaml", 6, "parameters.alteration_sid"),
        ("small.yaml", 14, "nodes.watch.test.all[1][0]")]
    assert "(did you mean 'alteration_side'?)" in errors[0].message
    assert "unknown feature 'dcpa' (did you mean 'dcpa_nm'?)" in errors[1].message


def test_rules_file_with_invalid_yaml_gets_the_operator_hint(tmp_path: Path) -> None:
    path = tmp_path / "op.yaml"
    path.write_text(SMALL.read_text().replace('[tcpa_min, ">", 0]', "[tcpa_min, !=, 0]"))
    (error,) = validate_file(path)
    assert error.line == 29 and error.message.endswith('write the operator in quotes: "!="')


def test_rules_file_missing_its_parent(tmp_path: Path) -> None:
    path = tmp_path / "orphan.yaml"
    path.write_text("schema_version: 1\nname: orphan\nextends: nowhere.yaml\n")
    (error,) = validate_file(path)
    assert (error.path, error.line, error.key) == (str(path), 3, "extends")
    assert "does not exist" in error.message


def test_scenarios_and_ship_files_are_still_checked(tmp_path: Path) -> None:
    scenario = SCENARIOS / "head_on.yaml"
    assert check_file(scenario) == ([], "ok")
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema_version: 1\nname: x\nduration_s: -5\nships: []\n")
    code, out, err = _run([scenario, bad])
    assert code == EXIT_INVALID
    assert out == f"{scenario}: ok\n" and f"{bad}:3:" in err
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: [x,\n")
    (error,) = validate_file(broken)
    assert error.path == str(broken) and "invalid YAML" in error.message


def test_cli_validate_checks_rules_files(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["validate", str(SMALL), str(PORT)]) == 0
    out = capsys.readouterr().out
    assert str(SMALL) in out and str(PORT) in out and "ok" in out
    assert cli.main(["validate", str(SMALL), str(INVALID)]) == cli.EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 3 and f"{INVALID}:12: nodes.watch.no.to" in err


@pytest.mark.parametrize("kind", ["scenario", "campaign"])
def test_a_bad_rules_file_a_scenario_or_campaign_names_is_reported(tmp_path, capsys, kind):
    """The rules file is checked with the file that names it: ``validate`` saying "ok" and
    ``run`` then failing on the rules would make validate worthless."""
    (tmp_path / "rules.yaml").write_text("schema_version: 1\nname: r\nnodes:\n"
                                         "  a: {test: [rnge_nm, '<', 1], yes: a, no: a}\n"
                                         "start: a\n")
    path = tmp_path / "f.yaml"
    if kind == "scenario":
        path.write_text("schema_version: 1\nname: s\nduration_s: 60\nrules: rules.yaml\n"
                        "ships:\n  - {name: a, type: cargo, north_m: 0, east_m: 0, "
                        "heading_deg: 0}\n")
    else:
        path.write_text("schema_version: 1\nname: c\nn_encounters: 1\nseed: 1\n"
                        "duration_s: 1800\nrules: rules.yaml\n")
    assert validate_files([path]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'rules.yaml'}:4: nodes.a.test" in err and "rnge_nm" in err


def test_a_ship_files_model_checks_run_and_are_located(tmp_path, capsys):
    """A value only the model family checks (the response model's fade speed must be > 0) is
    found by validate, for the ship file and for a scenario naming it, at its line."""
    from trafficsim.ships.library import LIBRARY_DIR

    text = (LIBRARY_DIR / "bulk_carrier.yaml").read_text()
    assert "  c3: " in text
    lines = text.splitlines(keepends=True)
    at = next(k for k, t in enumerate(lines) if t.startswith("  c3: "))
    lines.insert(at + 1, "  rudder_fade_speed_mps: 0\n")
    ship = tmp_path / "bc.yaml"
    ship.write_text("".join(lines))
    scenario = tmp_path / "s.yaml"
    scenario.write_text("schema_version: 1\nname: s\nduration_s: 60\nships:\n"
                        "  - {name: a, type: bc.yaml, north_m: 0, east_m: 0, heading_deg: 0}\n")
    assert validate_files([ship, scenario]) == 2
    err = capsys.readouterr().err.splitlines()
    want = f"trafficsim: error: {ship}:{at + 2}: coefficients.rudder_fade_speed_mps: "
    assert len(err) == 2 and all(line.startswith(want) for line in err)


CAMPAIGN = ("schema_version: 1\nname: c\nn_encounters: 4\nseed: 1\nduration_s: 1800\n"
            "ship_types: {ships}\nencounter_types: {types}\nspeed_fraction: [1.0, 1.0]\n")


def test_a_campaigns_ship_files_are_loaded_and_built_as_the_campaign_does(tmp_path, capsys):
    """A misspelt coefficient in a ship file, or a scenario file named as a ship, is found by
    validate, located in that file, as ``campaign`` finds it."""
    from trafficsim.ships.library import LIBRARY_DIR

    text = (LIBRARY_DIR / "cargo.yaml").read_text()
    line = next(k for k, t in enumerate(text.splitlines(), 1) if t.startswith("  K_prime:"))
    (tmp_path / "typo.yaml").write_text(text.replace("  K_prime:", "  K_prim:"))
    typo = tmp_path / "c1.yaml"
    typo.write_text(CAMPAIGN.format(ships="{cargo: 1, typo.yaml: 1}", types="{head_on: 1}"))
    as_ship = tmp_path / "c2.yaml"
    as_ship.write_text(CAMPAIGN.format(ships=f"{{{SCENARIOS / 'head_on.yaml'}: 1}}",
                                       types="{head_on: 1}"))
    code, out, err = _run([typo, as_ship])
    assert code == EXIT_INVALID and out == ""
    lines = err.splitlines()
    assert lines[0] == (f"trafficsim: error: {tmp_path / 'typo.yaml'}:{line}: "
                        "coefficients.K_prim: unknown coefficient 'K_prim' for model 'nomoto' "
                        "(did you mean 'K_prime'?)")
    assert lines[1].startswith(f"trafficsim: error: {SCENARIOS / 'head_on.yaml'}:")
    assert "missing required key 'model'" in lines[1] and len(lines) > 2


def test_a_campaign_whose_encounters_cannot_be_drawn_is_invalid(tmp_path):
    """Same-speed ships cannot overtake: validate draws one encounter of each weighted type
    and reports the type at its line in the spec, as ``campaign`` would fail on it; the
    head-on type of the same spec draws."""
    path = tmp_path / "c.yaml"
    path.write_text(CAMPAIGN.format(ships="{cargo: 1}", types="{head_on: 1, overtaking: 1}"))
    (error,) = validate_file(path)
    assert (error.path, error.line, error.key) == (str(path), 7, "encounter_types.overtaking")
    assert error.message.startswith("no geometry for overtaking in 1000 draws")
    path.write_text(CAMPAIGN.format(ships="{cargo: 1}", types="{head_on: 1, overtaking: 0}"))
    assert check_file(path) == ([], "ok")


@pytest.mark.parametrize("drop, kind, key", [
    ("model", "ship", "model"), ("n_encounters", "campaign", "n_encounters")])
def test_a_file_without_its_deciding_key_is_told_by_its_other_keys(tmp_path, drop, kind, key):
    from trafficsim.ships.library import LIBRARY_DIR
    from trafficsim.validate import file_kind

    source = (LIBRARY_DIR / "container.yaml" if kind == "ship"
              else Path(__file__).parent.parent / "scenarios" / "campaign_default.yaml")
    text = "\n".join(line for line in source.read_text().splitlines()
                     if not line.startswith((f"{drop}:", "rules:")))
    path = tmp_path / "f.yaml"
    path.write_text(text + "\n")
    import yaml

    assert file_kind(yaml.safe_load(text)) == kind
    errors = validate_file(path)
    assert len(errors) == 1 and errors[0].key == key, [str(e) for e in errors]
    assert "missing" in errors[0].message


def test_an_mmg_parameter_folder_is_checked_as_a_ship(tmp_path):
    """Any ship path may be an MMG parameter folder: validate reads it as a ship; a folder
    without the folder's files is no ship."""
    folder = SHARED / "data" / "esso-osaka-mmg" / "python_module" / "input_csv"
    if not folder.is_dir():
        pytest.skip("the authors' MMG parameter folder is not beside the repository")
    assert check_file(folder) == ([], "ok")
    (error,) = check_file(tmp_path)[0]
    assert error.path == str(tmp_path) and "MMG parameter folder" in error.message


def test_a_pipe_is_refused_as_no_regular_file(tmp_path: Path) -> None:
    # validate reads a file more than once (is it a rules file? then its own loader), so a
    # pipe would be found empty the second time; the refusal opens nothing (no writer needed)
    import os

    pipe = tmp_path / "scenario.yaml"
    os.mkfifo(pipe)
    code, _, err = _run([pipe])
    assert code == 2
    assert err.strip().splitlines() == [
        f"trafficsim: error: {pipe}: is not a regular file (a pipe or a device): validate "
        "reads a file more than once and looks for the files it names beside it; save it to a "
        "file first"]


@pytest.mark.parametrize(("old", "new", "key", "message"), [
    ("      radar: {sigma_range_m: 25,", "      radar: {antenna_y_m: 12, sigma_range_m: 25,",
     "ships[0].sensors.radar.antenna_y_m",
     "must lie on board, within +-11.585 m of the reference point (half the beam B of the "
     "ship's hull, L = 160.93 m, B = 23.17 m), got 12"),
    ("{sigma_m: 3.0, antenna_x_m: 40,", "{sigma_m: 3.0, antenna_x_m: 81,",
     "ships[0].sensors.gnss2.antenna_x_m",
     "must lie on board, within +-80.465 m of the reference point (half the length L of the "
     "ship's hull, L = 160.93 m, B = 23.17 m), got 81"),
    ("      radar: {}\n", "      radar: {}\n      log: {kind: doppler, lever_x_m: -170}\n",
     "ships[1].sensors.log.lever_x_m",
     "must lie on board, within +-160 m of the reference point (half the length L of the "
     "ship's hull, L = 320 m, B = 58 m), got -170"),
    ("    filter: pv\n    sensors:\n      gnss: {sigma_m: 2.0,",
     "    filter: pv\n    effects: {lever_arm: {x_m: -50}}\n    sensors:\n"
     "      gnss: {sigma_m: 2.0,",
     "ships[0].effects.lever_arm.x_m",
     "must lie on board, within +-80.465 m of the reference point (half the length L of the "
     "ship's hull, L = 160.93 m, B = 23.17 m), got -90 (the ship's gnss.antenna_x_m with this "
     "effect of -50)"),
])
def test_an_antenna_or_lever_off_the_hull_is_one_located_error(tmp_path, capsys, old, new,
                                                               key, message):
    """``validate`` refuses a GNSS or radar antenna or a log transducer outside the box of the
    ship's hull outline (its ship file's L and B), in one line naming the file, the line and
    the key: the key's own line, or that of the effect that moved the antenna there."""
    from tests.conftest import error_line

    text = (SCENARIOS / "crossing_sensors.yaml").read_text()
    assert text.count(old) == 1
    text = text.replace(old, new)
    path = tmp_path / "s.yaml"
    path.write_text(text)
    added = next(t for t in new.splitlines() if t not in old.splitlines())
    line = text[:text.index(added)].count("\n") + 1
    assert error_line(capsys, ["validate", path]) == (
        f"trafficsim: error: {path}:{line}: {key}: {message}")
