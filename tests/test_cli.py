"""The command line as a user meets it: exit codes, one-line errors, files on disk."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.conftest import SCENARIOS
from trafficsim.ships.library import LIBRARY_DIR


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "trafficsim", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


def one_line_error(res):
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr
    return lines[0]


def test_run_writes_trajectories_and_summary(tmp_path):
    res = cli("run", SCENARIOS / "head_on.yaml", "--out", tmp_path)
    assert res.returncode == 0, res.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["n_ships"] == 2 and summary["seed"] == 1
    assert summary["ship_steps_per_s"] > 0 and "numpy" in summary["versions"]
    pair = summary["pairs"][0]
    for key in ("min_range_m", "t_min_range_s", "dcpa_m", "tcpa_s", "collision"):
        assert key in pair
    assert pair["dcpa_m"] < 1.0  # the ships start on reciprocal courses on the same line
    assert not pair["collision"] and pair["min_range_m"] > 500.0  # the routes keep them apart
    table = pq.read_table(tmp_path / "trajectories.parquet")
    assert table.num_rows == 2 * (2400 // 5 + 1)
    assert {"t_s", "ship", "north_m", "east_m", "heading_deg", "sog_kn"} <= set(table.column_names)


@pytest.mark.parametrize("args, expect", [
    (["run"], "required"),
    (["run", "x.yaml"], "--out"),
    (["frobnicate"], "invalid choice"),
    (["trial", "kvlcc2", "--manoeuvre", "spin", "--out", "o"], "invalid choice"),
    (["trial", "kvlcc2", "--manoeuvre", "turning", "--rudder-deg", "-5", "--out", "o"],
     "positive"),
    (["trial", "kvlcc2", "--manoeuvre", "turning", "--speed-kn", "fast", "--out", "o"],
     "expected a number, got 'fast'"),
    (["campaign", "x.yaml", "--out", "o", "--workers", "two"], "expected a whole number"),
    # values a ship cannot carry out (an absurd approach speed would make the automatic time
    # step vanishingly small and the manoeuvre endless)
    (["trial", "kvlcc2", "--manoeuvre", "turning", "--speed-kn", "1e9", "--out", "o"],
     "--speed-kn: expected at most 2 times the service speed of 'kvlcc2' (15.5 kn), got 1e+09"),
    (["trial", "kvlcc2", "--manoeuvre", "turning", "--rudder-deg", "90", "--out", "o"],
     "--rudder-deg: expected at most the ship's rudder limit, 35 deg; got 90"),
    (["trial", "cargo", "--manoeuvre", "zigzag", "--rudder-deg", "40", "--out", "o"],
     "--rudder-deg: expected at most"),
    (["trial", "kvlcc2", "--manoeuvre", "crash-stop", "--dt-s", "1e-9", "--out", "o"],
     "--dt-s: expected a time step from 0.001 to 60 s"),
    # flags that would do nothing where they are given
    (["trial", "cargo", "--manoeuvre", "turning", "--sp", "0.1", "--out", "o"],
     "--sp: applies only with --sensors"),
    (["trial", "cargo", "--manoeuvre", "turning", "--seed", "3", "--out", "o"],
     "--seed: applies only with --sensors"),
    (["trial", "cargo", "--manoeuvre", "turning", "--heading-deg", "20", "--out", "o"],
     "--heading-deg: applies only to --manoeuvre zigzag"),
    (["trial", "cargo", "--manoeuvre", "crash-stop", "--port", "--out", "o"],
     "--port: applies only to --manoeuvre turning or zigzag"),
    (["trial", "cargo", "--manoeuvre", "crash-stop", "--rudder-deg", "20", "--out", "o"],
     "--rudder-deg: applies only to --manoeuvre turning or zigzag"),
    (["campaign", "x.yaml", "--out", "o", "--address", "tcp://127.0.0.1:1"],
     "--address: applies only with --executor dask"),
    (["campaign", "x.yaml", "--out", "o", "--executor", "dask", "--address",
      "tcp://127.0.0.1:1", "--workers", "7"],
     "--workers: applies only to local processes (a Dask cluster has its own workers)"),
    (["identify", "--model", "response", "--base", "cargo", "--data", "x.csv", "--out", "o",
      "--method", "ekf", "--max-nfev", "3"],
     "--max-nfev: applies only to the output-error fit (--method oe or ekf+oe)"),
    (["identify", "--model", "response", "--base", "cargo", "--data", "x.csv", "--out", "o",
      "--method", "ekf", "--bounds", "a1=-1:0"],
     "--bounds: applies only to the output-error fit (--method oe or ekf+oe)"),
    (["render", "nodir", "--out", "o", "--range-nm", "2"],
     "--range-nm: applies only with --follow"),
    (["render", "nodir", "--out", "o", "--fps", "5"], "--fps: applies only to GIF and MP4 frames"),
    # non-finite and out-of-range numbers (they crashed the frame drawing)
    (["render", "nodir", "--out", "o", "--every-s", "nan"],
     "expected a positive number, got 'nan'"),
    (["render", "nodir", "--out", "o", "--dpi", "inf"], "expected a positive number, got 'inf'"),
    (["render", "nodir", "--out", "o", "--dpi", "20000"],
     "expected 10 to 1200 dots per inch, got '20000'"),
    (["explain", "nodir", "--ship", "a", "--at-s", "nan"], "expected a finite number, got 'nan'"),
    (["identify", "--model", "response", "--base", "cargo", "--data", "x.csv", "--out", "o",
      "--bounds", "a1=nan:1"], "expected NAME=LOW:HIGH (numbers; -inf and inf for no bound)"),
    (["diagnose", "--self-test", "2", "--ship", "cargo"],
     "--ship: applies only without --self-test"),
    (["diagnose", "--ship", "cargo", "--data", "x.csv", "--out", "o", "--seed", "3"],
     "--seed: applies only with --self-test"),
    (["diagnose", "--ship", "nosuch", "--data", "x.csv", "--out", "o"],
     "--ship: unknown ship 'nosuch'"),
    (["identify", "--model", "response", "--base", "bulkcarrier", "--data", "x.csv", "--out",
      "o"], "--base: unknown ship 'bulkcarrier' (did you mean 'bulk_carrier'?)"),
])
def test_bad_flags_give_one_line_and_exit_2(args, expect):
    assert expect in one_line_error(cli(*args))


def test_missing_scenario_file_is_named(tmp_path):
    line = one_line_error(cli("run", tmp_path / "nope.yaml", "--out", tmp_path / "o"))
    assert "nope.yaml" in line and "not found" in line


def test_bad_scenario_names_file_line_and_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    text = (SCENARIOS / "head_on.yaml").read_text().replace("speed_kn: 12\n", "speed_kn: fast\n", 1)
    bad.write_text(text)
    line = one_line_error(cli("run", bad, "--out", tmp_path / "o"))
    expected_line = text.splitlines().index("    speed_kn: fast") + 1
    assert f"bad.yaml:{expected_line}:" in line and "speed_kn" in line


def test_a_run_that_diverges_is_one_line_naming_ship_and_time_with_exit_1(tmp_path):
    ship = (LIBRARY_DIR / "bulk_carrier.yaml").read_text()
    (tmp_path / "runaway.yaml").write_text(ship.replace("  a1: -1.4347e-4\n", "  a1: 1.0e-2\n"))
    scenario = (SCENARIOS / "head_on.yaml").read_text().replace("type: container",
                                                                 "type: runaway.yaml")
    (tmp_path / "s.yaml").write_text(scenario)
    res = cli("run", tmp_path / "s.yaml", "--out", tmp_path / "o")
    assert res.returncode == 1 and "Traceback" not in res.stderr
    found = re.fullmatch(r"trafficsim: error: state became non-finite at t = (\d+) s for ships "
                         r"boxer; reduce dt_s or check the ship files \(the run up to then is "
                         r"in (.+)\)", res.stderr.strip())
    assert found and Path(found[2]) == tmp_path / "o"
    # the run up to then is written, to render and look at: it ends at the step that diverged,
    # the ships standing frozen at their last finite state (one step before)
    t = pq.read_table(tmp_path / "o" / "trajectories.parquet").column("t_s").to_numpy()
    assert t.max() == int(found[1])
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["diverged_at_s"] == t.max() - 1.0


def test_unknown_ship_type_suggests_the_right_one():
    line = one_line_error(cli("trial", "kvlc2", "--manoeuvre", "turning", "--out", "o"))
    assert "did you mean 'kvlcc2'" in line


def test_validate_accepts_bundled_files_and_rejects_bad_ones(tmp_path):
    files = sorted(SCENARIOS.glob("*.yaml"))
    res = cli("validate", *files)
    assert res.returncode == 0, res.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema_version: 1\nname: x\nduration_s: -5\nships: []\n")
    res = cli("validate", bad)
    assert res.returncode == 2 and "bad.yaml:3:" in res.stderr


def test_trial_turning_writes_trial_csv_and_indices(tmp_path):
    res = cli("trial", "kvlcc2", "--manoeuvre", "turning", "--out", tmp_path)
    assert res.returncode == 0, res.stderr
    header = (tmp_path / "trial.csv").read_text().splitlines()[0].split(",")
    assert header[:6] == ["t_s", "north_m", "east_m", "heading_deg", "rudder_deg", "rpm"]
    data = json.loads((tmp_path / "indices.json").read_text())
    assert data["indices"]["tactical_diameter_m"] > 0
    assert data["imo_msc137"]["advance_L"]["pass"]


def test_help_is_fast_and_lists_the_commands():
    res = cli("--help")
    assert res.returncode == 0
    for command in ("run", "trial", "validate"):
        assert command in res.stdout


def test_make_run_campaign_is_valid():
    makefile = (Path(__file__).resolve().parents[1] / "Makefile").read_text()
    spec = makefile.split("CAMPAIGN ?= ")[1].split()[0]
    res = cli("validate", Path(__file__).resolve().parents[1] / spec)
    assert res.returncode == 0 and res.stdout.strip().endswith(": ok"), res.stderr


def test_validate_checks_the_ship_files_a_scenario_uses(tmp_path):
    ship = tmp_path / "boat.yaml"
    text = (Path(__file__).resolve().parents[1] / "trafficsim/ships/library/catfish.yaml"
            ).read_text().replace("  beam_m:", "  beam_m: wide\n  beam_typo:", 1)
    ship.write_text(text)
    scenario = tmp_path / "s.yaml"
    scenario.write_text("schema_version: 1\nname: s\nduration_s: 10\nships:\n  - name: a\n"
                        "    type: boat.yaml\n    north_m: 0\n    east_m: 0\n    heading_deg: 0\n")
    res = cli("validate", scenario)
    assert res.returncode == 2 and "boat.yaml:" in res.stderr and "Traceback" not in res.stderr


def test_unwritable_output_folder_is_one_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    line = one_line_error(cli("run", SCENARIOS / "head_on.yaml", "--out", blocker / "out"))
    assert str(blocker) in line


def test_trajectories_keep_truth_measurements_and_estimates_side_by_side(tmp_path):
    res = cli("run", SCENARIOS / "crossing_sensors.yaml", "--out", tmp_path)
    assert res.returncode == 0, res.stderr
    table = pq.read_table(tmp_path / "trajectories.parquet").to_pydict()
    for key in ("gnss_north_m", "gnss_east_m", "gnss_valid", "compass_heading_deg",
                "est_north_m", "est_east_m", "est_heading_deg", "est_sog_kn", "est_cog_deg"):
        assert key in table
    import numpy as np

    err = np.hypot(np.array(table["est_north_m"]) - np.array(table["north_m"]),
                   np.array(table["est_east_m"]) - np.array(table["east_m"]))
    assert 0.0 < np.sqrt(np.mean(err**2)) < 8.0


def test_trial_with_sensors_records_the_receiver_lag_of_seed_000(tmp_path):
    """Turning at 35 deg: the receiver's filtered speed over ground lags the truth in the turn
    (seed 000: a bias of order 0.5 m/s at S_p = 0.01), larger at a lower S_p."""
    import numpy as np

    def speed_bias(sp):
        out = tmp_path / f"sp{sp}"
        res = cli("trial", "kvlcc2", "--manoeuvre", "turning", "--sensors", "--sp", sp,
                  "--out", out)
        assert res.returncode == 0, res.stderr
        data = np.genfromtxt(out / "trial.csv", delimiter=",", names=True)
        for key in ("gnss_north_m", "gnss_sog_kn", "est_north_m", "est_heading_deg"):
            assert np.isfinite(data[key]).all()
        # while the ship slows in the turn the lagging filter overstates the speed
        lag = (data["gnss_sog_kn"] - data["sog_kn"]) * 1852 / 3600
        slowing = data["t_s"] < data["t_s"][np.argmax(data["heading_deg"] > 90.0)]
        return float(np.max(np.convolve(lag[slowing], np.ones(15) / 15, mode="valid")))

    low, mid = speed_bias(0.001), speed_bias(0.01)
    assert 0.1 < mid < 1.0 and low > mid


@pytest.mark.parametrize("flag", [["--frames-every-s", "10"], ["--follow", "tanker"],
                                  ["--measurements"], ["--size", "640x480"], ["--fps", "5"],
                                  ["--size", "960x720"], ["--dpi", "96"]])
def test_frame_flags_without_frames_are_refused_not_ignored(tmp_path, flag):
    scenario = Path(__file__).parent.parent / "scenarios" / "head_on.yaml"
    line = one_line_error(cli("run", scenario, "--out", tmp_path / "o", *flag))
    assert line == (f"trafficsim: error: {flag[0]}: applies only with --frames (png, gif or "
                    "mp4)")
    assert not (tmp_path / "o").exists()


# --- in-process: every subcommand and flag ---------------------------------------------------

KN = 1852.0 / 3600.0


def usage_error(capsys, argv):
    """A flag argparse refuses: exit 2 and one line naming the command, no traceback."""
    from trafficsim import cli as cli_module

    with pytest.raises(SystemExit) as stop:
        cli_module.main([str(a) for a in argv])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _ident(*more):
    return ["identify", "--model", "response", "--base", "cargo", "--data", "x.csv",
            "--out", "o", *more]


def _render(*more):
    return ["render", "nodir", "--out", "o", *more]


@pytest.mark.parametrize("args, expect", [
    (["run", "s.yaml", "--out"], "argument --out: expected one argument"),
    (["run", "s.yaml", "--out", "o", "--frames", "jpg"], "argument --frames: invalid choice"),
    (["run", "s.yaml", "--out", "o", "--frames", "--fps", "0"],
     "argument --fps: expected a positive number, got '0'"),
    (["run", "s.yaml", "--out", "o", "--frames", "--frames-every-s", "-1"],
     "argument --frames-every-s: expected a positive number, got '-1'"),
    (["campaign", "s.yaml"], "required: --out"),
    (["campaign", "s.yaml", "--out", "o", "--executor", "ray"],
     "argument --executor: invalid choice: 'ray'"),
    (["campaign", "s.yaml", "--out", "o", "--workers", "0"],
     "argument --workers: expected a positive number, got '0'"),
    (["explain", "d"], "required: --ship"),
    (["explain", "d", "--ship", "a", "--at-s", "soon"],
     "argument --at-s: expected a number, got 'soon'"),
    (["explain", "d", "--ship", "a", "--at-s", "inf"],
     "argument --at-s: expected a finite number, got 'inf'"),
    (["trial", "cargo", "--out", "o"], "required: --manoeuvre"),
    (["trial", "cargo", "--manoeuvre", "turning"], "required: --out"),
    (["trial", "cargo", "--manoeuvre", "turning", "--out", "o", "--seed", "x"],
     "argument --seed: expected an integer, got 'x'"),
    (["trial", "cargo", "--manoeuvre", "turning", "--out", "o", "--dt-s", "0"],
     "argument --dt-s: expected a positive number, got '0'"),
    (["trial", "cargo", "--manoeuvre", "zigzag", "--out", "o", "--heading-deg", "nan"],
     "argument --heading-deg: expected a positive number, got 'nan'"),
    (["trial", "cargo", "--manoeuvre", "turning", "--out", "o", "--sp", "-0.01"],
     "argument --sp: expected a positive number, got '-0.01'"),
    (["identify", "--model", "arima", "--base", "cargo", "--data", "x.csv", "--out", "o"],
     "argument --model: invalid choice: 'arima'"),
    (["identify", "--model", "response", "--data", "x.csv", "--out", "o"], "required: --base"),
    (_ident("--max-nfev", "0"), "argument --max-nfev: expected a positive number, got '0'"),
    (_ident("--max-nfev", "2.5"), "argument --max-nfev: expected a whole number, got '2.5'"),
    (_ident("--wind", "maybe"), "argument --wind: invalid choice: 'maybe'"),
    (_ident("--method", "ls"), "argument --method: invalid choice: 'ls'"),
    (_ident("--columns", "north_m"), "argument --columns: expected NAME=COLUMN,... got 'north_m'"),
    (_ident("--columns", "north_m=a,east_m="), "argument --columns: expected NAME=COLUMN"),
    (_ident("--bounds", "a1=1:"), "argument --bounds: expected NAME=LOW:HIGH"),
    (_ident("--bounds", "=1:2"), "argument --bounds: expected NAME=LOW:HIGH"),
    (_ident("--bounds", "a1=1"), "argument --bounds: expected NAME=LOW:HIGH"),
    (_ident("--fit", " , "), "argument --fit: expected coefficient names separated by commas"),
    (_ident("--horizon-s", "0"), "argument --horizon-s: expected a positive number, got '0'"),
    (_ident("--sigma-pos-m", "inf"),
     "argument --sigma-pos-m: expected a positive number, got 'inf'"),
    (_ident("--sigma-heading-deg", "0"),
     "argument --sigma-heading-deg: expected a positive number, got '0'"),
    (["diagnose", "--self-test", "0"],
     "argument --self-test: expected a positive number, got '0'"),
    (["diagnose", "--self-test", "2", "--seed", "1.5"],
     "argument --seed: expected an integer, got '1.5'"),
    (["diagnose", "--dt-s", "inf"], "argument --dt-s: expected a positive number, got 'inf'"),
    (["validate"], "required: files"),
    (_render("--format", "webm"), "argument --format: invalid choice: 'webm'"),
    (_render("--size", "100"), "argument --size: expected WIDTHxHEIGHT in pixels"),
    (_render("--size", "64x8193"), "argument --size: expected 64 to 8192 pixels each way"),
    (_render("--size", "63x64"), "argument --size: expected 64 to 8192 pixels each way"),
    (_render("--dpi", "9.99"), "argument --dpi: expected 10 to 1200 dots per inch"),
    (_render("--dpi", "1200.5"), "argument --dpi: expected 10 to 1200 dots per inch"),
    (_render("--range-nm", "0"), "argument --range-nm: expected a positive number, got '0'"),
    (_render("--every-s", "-inf"), "argument --every-s: expected one argument"),
    (["report", "d", "--worst", "-1"], "argument --worst: expected a number >= 0, got '-1'"),
    (["report", "d", "--worst", "2.0"], "argument --worst: expected an integer, got '2.0'"),
    (["replay", "d", "--out", "o"], "required: --encounter"),
    (["replay", "d", "--out", "o", "--encounter", "1.5"],
     "argument --encounter: expected an integer, got '1.5'"),
    (["replay", "d", "--out", "o", "--encounter", "1", "--record-every-s", "nan"],
     "argument --record-every-s: expected a positive number, got 'nan'"),
])
def test_every_subcommand_refuses_a_bad_flag_in_one_line(capsys, args, expect):
    line = usage_error(capsys, args)
    assert line.startswith(f"trafficsim {args[0]}: error: ")
    assert expect in line
    assert line.endswith(f"(see 'trafficsim {args[0]} --help')")


def test_no_subcommand_is_a_usage_error(capsys):
    line = usage_error(capsys, [])
    assert line.startswith("trafficsim: error: the following arguments are required: command")


def test_version_prints_the_package_version(capsys):
    from trafficsim import __version__
    from trafficsim import cli as cli_module

    with pytest.raises(SystemExit) as stop:
        cli_module.main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"trafficsim {__version__}"


def test_each_subcommands_help_documents_every_one_of_its_flags():
    """The help text a user reads lists each option the parser takes (none undocumented)."""
    import argparse

    from trafficsim import cli as cli_module

    parser = cli_module.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == {"run", "campaign", "explain", "trial", "identify", "diagnose",
                                "validate", "render", "report", "replay"}
    for name, command in sub.choices.items():
        text = command.format_help()
        for action in command._actions:
            for flag in action.option_strings:
                assert flag in text, (name, flag)
            if action.option_strings and not isinstance(action, argparse._HelpAction):
                assert action.help or action.choices, (name, action.option_strings)


# --- unreadable inputs -----------------------------------------------------------------------

BAD_FILES = {
    "missing": (None, "file not found"),
    "folder": ("folder", "is a directory, expected a YAML file"),
    "not utf-8": (b"name: \xff\xfe\n", "file is not UTF-8 text (byte 0xFF)"),
    "empty": (b"", "file is empty"),
    "a list": (b"- a\n- b\n", "the top level must be a mapping"),
    "bad yaml": (b"name: [1,\n", "invalid YAML"),
}


def _bad_file(tmp_path, kind):
    content, expect = BAD_FILES[kind]
    path = tmp_path / "in.yaml"
    if content == "folder":
        path.mkdir()
    elif content is not None:
        path.write_bytes(content)
    return path, expect


@pytest.mark.parametrize("kind", list(BAD_FILES))
@pytest.mark.parametrize("command", ["run", "validate", "campaign"])
def test_an_unreadable_input_file_is_one_located_line_and_nothing_is_written(
        capsys, tmp_path, command, kind):
    from tests.conftest import error_line

    path, expect = _bad_file(tmp_path, kind)
    argv = [command, path] if command == "validate" else [command, path, "--out", tmp_path / "o"]
    line = error_line(capsys, argv)
    assert line.startswith(f"trafficsim: error: {path}") and expect in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("kind", ["missing", "not utf-8", "empty", "a list"])
def test_an_unreadable_ship_file_for_trial_is_one_line(capsys, tmp_path, kind):
    from tests.conftest import error_line

    path, expect = _bad_file(tmp_path, kind)
    if kind == "missing":
        expect = "not found"
    line = error_line(capsys, ["trial", path, "--manoeuvre", "turning", "--out", tmp_path / "o"])
    assert str(path) in line and expect in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["identify", "diagnose"])
@pytest.mark.parametrize("kind, expect", [
    ("missing", "trial data file not found (given with --data)"),
    ("folder", "folder has no .csv trial files (given with --data)"),
    ("binary", "not a text file"),
])
def test_unreadable_trial_data_is_one_line_naming_the_file(capsys, tmp_path, command, kind,
                                                           expect):
    from tests.conftest import error_line

    data = tmp_path / "run.csv"
    if kind == "folder":
        data = tmp_path / "runs"
        data.mkdir()
    elif kind == "binary":
        data.write_bytes(b"\xff\xfe\x00\x01")
    base = ["--base", "cargo", "--model", "response"] if command == "identify" else [
        "--ship", "cargo"]
    line = error_line(capsys, [command, *base, "--data", data, "--out", tmp_path / "o"])
    assert line.startswith(f"trafficsim: error: {data}: ") and expect in line


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    """A 60 s head-on run of two colregs ships (decisions every 10 s), recorded every 10 s."""
    from trafficsim.run import run_scenario

    folder = tmp_path_factory.mktemp("run")
    scenario = folder / "s.yaml"
    scenario.write_text(
        "schema_version: 1\nname: meet\nduration_s: 60\nrecord_every_s: 10\nships:\n"
        "  - {name: a, type: cargo, north_m: 0, east_m: 0, heading_deg: 0, speed_kn: 12}\n"
        "  - {name: b, type: container, north_m: 5000, east_m: 200, heading_deg: 180,"
        " speed_kn: 12}\n")
    run_scenario(scenario, folder / "out")
    return folder / "out"


def _spoilt(run_folder, tmp_path, name, content):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(run_folder, copy)
    if content is None:
        (copy / name).unlink()
    else:
        (copy / name).write_text(content)
    return copy


@pytest.mark.parametrize("command", ["render", "explain"])
@pytest.mark.parametrize("name, content, expect", [
    ("trajectories.parquet", "garbage", "trajectories.parquet: unreadable"),
    ("summary.json", "garbage", "summary.json: unreadable"),
    ("summary.json", None, "summary.json: missing"),
    ("decisions.parquet", "garbage", "decisions.parquet: unreadable"),
])
def test_a_spoilt_run_folder_is_one_line_naming_the_file(capsys, tmp_path, run_folder, command,
                                                         name, content, expect):
    """render reads every file of the run folder, explain only the decisions."""
    from tests.conftest import error_line

    if command == "explain" and name != "decisions.parquet":
        return
    spoilt = _spoilt(run_folder, tmp_path, name, content)
    argv = (["render", spoilt, "--out", tmp_path / "f", "--no-progress"] if command == "render"
            else ["explain", spoilt, "--ship", "a"])
    line = error_line(capsys, argv)
    assert f"{spoilt}/{expect}" in line


@pytest.mark.parametrize("argv, expect", [
    (["render", "{missing}", "--out", "{tmp}/f", "--no-progress"], "{missing}: no such folder"),
    (["render", "{empty}", "--out", "{tmp}/f", "--no-progress"],
     "{empty}: no trajectories.parquet here"),
    (["explain", "{empty}", "--ship", "a"], "{empty}/decisions.parquet: no decisions recorded"),
    (["explain", "{missing}", "--ship", "a"], "{missing}: no such folder"),
    (["report", "{missing}", "--no-progress"], "{missing}: no such folder"),
    (["report", "{empty}", "--no-progress"], "{empty}: no encounters.parquet here"),
    (["replay", "{missing}", "--encounter", "0", "--out", "{tmp}/r"],
     "{missing}: no such folder"),
    (["replay", "{empty}", "--encounter", "0", "--out", "{tmp}/r"],
     "{empty}: no campaign.json here"),
    (["replay", "{garbage}", "--encounter", "0", "--out", "{tmp}/r"],
     "{garbage}/campaign.json: unreadable"),
    (["report", "{garbage}", "--no-progress"], "{garbage}/encounters.parquet: unreadable"),
])
def test_missing_or_empty_result_folders_are_one_line(capsys, tmp_path, argv, expect):
    from tests.conftest import error_line

    (tmp_path / "empty").mkdir()
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "campaign.json").write_text("{not json")
    (tmp_path / "garbage" / "encounters.parquet").write_text("x")
    names = {"missing": tmp_path / "missing", "empty": tmp_path / "empty",
             "garbage": tmp_path / "garbage", "tmp": tmp_path}
    line = error_line(capsys, [a.format(**names) for a in argv])
    assert expect.format(**names) in line


@pytest.mark.parametrize("command", ["run", "trial", "render", "campaign"])
def test_an_output_folder_below_a_file_is_one_line_naming_it(capsys, tmp_path, run_folder,
                                                             command):
    from tests.conftest import error_line

    blocker = tmp_path / "file"
    blocker.write_text("")
    out = blocker / "out"
    spec = tmp_path / "spec.yaml"
    spec.write_text("schema_version: 1\nname: c\nn_encounters: 1\nseed: 1\nduration_s: 1800\n"
                    "ship_types: {cargo: 1}\n")
    argv = {"run": ["run", SCENARIOS / "head_on.yaml", "--out", out],
            "trial": ["trial", "cargo", "--manoeuvre", "turning", "--out", out],
            "render": ["render", run_folder, "--out", out, "--no-progress"],
            "campaign": ["campaign", spec, "--out", out, "--workers", "1", "--no-progress"]
            }[command]
    line = error_line(capsys, argv)
    assert line == f"trafficsim: error: {out}: Not a directory"


# --- scenario values: located at their line --------------------------------------------------

GOOD = ("schema_version: 1\nname: t\nduration_s: 20\nships:\n  - name: a\n    type: cargo\n"
        "    north_m: 0\n    east_m: 0\n    heading_deg: 0\n")


@pytest.mark.parametrize("old, new, key, expect", [
    ("duration_s: 20\n", "duration_s: 20\ndt_s: 0\n", "dt_s", "must be > 0, got 0"),
    ("duration_s: 20\n", "duration_s: 20\ndt_s: .nan\n", "dt_s", "expected a finite number"),
    ("duration_s: 20\n", "duration_s: 20\ndt_s: 30\n", "dt_s", "must not exceed duration_s"),
    ("duration_s: 20\n", "duration_s: 20\nseed: -1\n", "seed", "must be >= 0, got -1"),
    ("duration_s: 20\n", "duration_s: 20\nseed: 1.5\n", "seed", "expected a whole number"),
    ("duration_s: 20\n", "duration_s: 20\nrecord_every_s: 0.3\n", "record_every_s",
     "must be a whole multiple of dt_s"),
    ("duration_s: 20\n", "duration_s: 20\ndecision_period_s: 0.5\n", "decision_period_s",
     "must be a whole multiple of dt_s"),
    ("duration_s: 20\n", "duration_s: 20\ndomain: circle\n", "domain", "expected 'coldwell'"),
    ("duration_s: 20\n", "duration_s: 20\nrules: nope.yaml\n", "rules", "rules file not found"),
    ("duration_s: 20\n", "duration_s: 20\nenvironment:\n  current: {speed_kn: 11, "
     "towards_deg: 0}\n", "environment.current.speed_kn", "must be <= 10, got 11"),
    ("heading_deg: 0\n", "heading_deg: 360\n", "ships[0].heading_deg", "must be < 360"),
    ("heading_deg: 0\n", "heading_deg: 0\n    speed_kn: .inf\n", "ships[0].speed_kn",
     "expected a finite number"),
    ("heading_deg: 0\n", "heading_deg: 0\n    route: [[1, 2, 3]]\n", "ships[0].route[0]",
     "expected exactly 2 numbers, got 3"),
    ("heading_deg: 0\n", "heading_deg: 0\n    behaviour: crazy\n", "ships[0].behaviour",
     "expected 'colregs'"),
    ("heading_deg: 0\n", "heading_deg: 0\n    typo: 1\n", "ships[0].typo", "unknown key"),
    ("type: cargo\n", "type: cargoo\n", "ships[0].type", "did you mean 'cargo'"),
    ("north_m: 0\n", "north_m: 2.0e+6\n", "ships[0].north_m", "must be <= 1000000"),
])
def test_a_bad_scenario_value_is_one_line_at_its_line_and_key(capsys, tmp_path, old, new, key,
                                                              expect):
    from tests.conftest import error_line

    text = GOOD.replace(old, new, 1)
    assert text != GOOD
    path = tmp_path / "s.yaml"
    path.write_text(text)
    top = key.split(".")[0].split("[")[0]
    leaf = key.rsplit(".", 1)[-1].split("[")[0]
    # the line of the faulty key: the last line naming it (below its parent for nested keys)
    line_no = max(k for k, ln in enumerate(text.splitlines(), 1)
                  if ln.strip().startswith(f"{leaf}:") or f"{{{leaf}:" in ln
                  or f" {leaf}:" in ln or (leaf == top and ln.startswith(f"{top}:")))
    line = error_line(capsys, ["run", path, "--out", tmp_path / "o"])
    assert line.startswith(f"trafficsim: error: {path}:{line_no}: {key}: "), line
    assert expect in line
    assert not (tmp_path / "o").exists()


def test_duplicate_ship_names_point_at_the_second_name(capsys, tmp_path):
    from tests.conftest import error_line

    path = tmp_path / "s.yaml"
    path.write_text(GOOD + GOOD.split("ships:\n")[1])
    line = error_line(capsys, ["run", path, "--out", tmp_path / "o"])
    assert line.startswith(f"trafficsim: error: {path}:10: ships[1].name: duplicate ship name "
                           "'a' (already used by ships[0])")


def test_a_bad_ship_file_a_scenario_uses_is_located_in_the_ship_file(capsys, tmp_path):
    from tests.conftest import error_line

    ship = (LIBRARY_DIR / "cargo.yaml").read_text()
    assert "  length_m: 160.93\n" in ship
    (tmp_path / "boat.yaml").write_text(ship.replace("  length_m: 160.93\n", "  length_m: -5\n"))
    line_no = ship.splitlines().index("  length_m: 160.93") + 1
    path = tmp_path / "s.yaml"
    path.write_text(GOOD.replace("type: cargo", "type: boat.yaml"))
    line = error_line(capsys, ["run", path, "--out", tmp_path / "o"])
    assert line.startswith(f"trafficsim: error: {tmp_path / 'boat.yaml'}:{line_no}: "
                           "particulars.length_m: must be >= ")


def _two_ship_rules_scenario(tmp_path):
    (tmp_path / "rules.yaml").write_text("schema_version: 1\n")  # lacks name, nodes and start
    path = tmp_path / "s.yaml"
    path.write_text(GOOD.replace("duration_s: 20\n", "duration_s: 20\nrules: rules.yaml\n")
                    + "  - {name: b, type: cargo, north_m: 3000, east_m: 0, heading_deg: 180}\n")
    return path


@pytest.mark.parametrize("command", ["run", "campaign"])
def test_a_rules_file_with_several_problems_is_still_one_line(capsys, tmp_path, command):
    from tests.conftest import error_line

    if command == "run":
        path = _two_ship_rules_scenario(tmp_path)
    else:
        (tmp_path / "rules.yaml").write_text("schema_version: 1\n")
        path = tmp_path / "spec.yaml"
        path.write_text("schema_version: 1\nname: c\nn_encounters: 1\nseed: 1\n"
                        "duration_s: 1800\nrules: rules.yaml\nship_types: {cargo: 1}\n")
    argv = [command, path, "--out", tmp_path / "o"] + (
        ["--workers", "1", "--no-progress"] if command == "campaign" else [])
    line = error_line(capsys, argv)
    assert line.startswith(f"trafficsim: error: {tmp_path / 'rules.yaml'}:1: ")


def test_validate_prints_every_problem_of_a_rules_file_one_per_line(capsys, tmp_path):
    """validate (unlike run) lists all: the three missing keys, each at line 1."""
    from trafficsim import cli as cli_module

    rules = tmp_path / "rules.yaml"
    rules.write_text("schema_version: 1\nnodes: {}\n")
    assert cli_module.main(["validate", str(rules)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) >= 2
    assert all(ln.startswith(f"trafficsim: error: {rules}:") for ln in lines)


def test_validate_reports_good_files_as_ok_and_bad_ones_by_line(capsys, tmp_path):
    from trafficsim import cli as cli_module

    good = tmp_path / "good.yaml"
    good.write_text(GOOD)
    bad = tmp_path / "bad.yaml"
    bad.write_text(GOOD.replace("duration_s: 20", "duration_s: -5"))
    ship = LIBRARY_DIR / "cargo.yaml"
    assert cli_module.main(["validate", str(good), str(bad), str(ship)]) == 2
    out, err = capsys.readouterr()
    assert out.splitlines() == [f"{good}: ok", f"{ship}: ok"]
    assert err.splitlines() == [f"trafficsim: error: {bad}:3: duration_s: must be > 0, got -5"]
    assert cli_module.main(["validate", str(good), str(ship)]) == 0


# --- values refused instead of a traceback or a crash ----------------------------------------


@pytest.mark.parametrize("argv", [
    ["trial", "cargo", "--manoeuvre", "turning", "--sensors", "--seed", "-1", "--out", "{o}"],
    ["diagnose", "--self-test", "1", "--seed", "-1", "--out", "{o}"],
])
def test_a_negative_seed_is_refused_in_one_line(capsys, tmp_path, argv):
    from trafficsim import cli as cli_module

    argv = [a.format(o=tmp_path / "o") for a in argv]
    try:
        code = cli_module.main(argv)
    except SystemExit as stop:  # refused by argparse
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--seed" in err, err


def _tiny_scenario(tmp_path, seconds=4):
    path = tmp_path / "tiny.yaml"
    path.write_text(GOOD.replace("duration_s: 20", f"duration_s: {seconds}"))
    return path


def test_a_gif_frame_rate_too_low_to_encode_is_refused_in_one_line(capsys, tmp_path):
    from trafficsim import cli as cli_module

    code = cli_module.main(["run", str(_tiny_scenario(tmp_path)), "--out", str(tmp_path / "o"),
                            "--frames", "gif", "--size", "64x64", "--fps", "0.001"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--fps" in err, err


def test_a_follow_range_too_small_to_draw_is_refused_in_one_line(capsys, tmp_path):
    from trafficsim import cli as cli_module

    code = cli_module.main(["run", str(_tiny_scenario(tmp_path, 2)), "--out",
                            str(tmp_path / "o"), "--frames", "--follow", "a", "--range-nm",
                            "1e-12"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--range-nm" in err, err


@pytest.mark.parametrize("flag", ["--sigma-pos-m", "--sigma-heading-deg"])
def test_an_absurd_smoother_noise_is_refused_in_one_line(capsys, tmp_path, flag):
    from trafficsim import cli as cli_module

    assert cli_module.main(["trial", "cargo", "--manoeuvre", "zigzag", "--out",
                            str(tmp_path / "t")]) == 0
    capsys.readouterr()
    code = cli_module.main(["identify", "--model", "response", "--base", "cargo", "--data",
                            str(tmp_path / "t" / "trial.csv"), "--out", str(tmp_path / "o"),
                            flag, "1e200"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and flag in err, err


def test_an_interrupted_command_says_so_and_exits_130(capsys, tmp_path, monkeypatch):
    import trafficsim.run
    from trafficsim import cli as cli_module

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(trafficsim.run, "run_scenario", interrupted)
    assert cli_module.main(["run", str(_tiny_scenario(tmp_path)), "--out",
                            str(tmp_path / "o")]) == 130
    assert capsys.readouterr().err == "trafficsim: interrupted\n"


def test_output_into_a_closed_pipe_ends_quietly_with_exit_0(tmp_path):
    """validate of many files into a reader that has gone: no traceback, exit 0."""
    good = tmp_path / "good.yaml"
    good.write_text(GOOD)
    proc = subprocess.Popen([sys.executable, "-m", "trafficsim", "validate", *[str(good)] * 300],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0 and err == b""


# --- good runs: the documented outputs -------------------------------------------------------


def test_run_of_a_straight_instrumented_ship_keeps_truth_measurement_and_estimate(capsys,
                                                                               tmp_path):
    """cargo due north at 12 kn for 120 s with DGPS (sigma 2 m), a gyro (0.3 deg) and a pv
    filter: the truth keeps close to the straight line north = 12 kn x t (the autopilot
    steers on the noisy heading estimate: a few metres off it, not exactly on it); the fixes
    scatter about the truth with about 2 m per axis, the compass about 0.3 deg; the estimate
    lies nearer than the fixes and its speed is about 12 kn."""
    from trafficsim import cli as cli_module

    path = tmp_path / "s.yaml"
    path.write_text(GOOD.replace("duration_s: 20", "duration_s: 120\nseed: 9") + (
        "    speed_kn: 12\n    behaviour: keep_course\n    filter: pv\n"
        "    sensors:\n      gnss: {sigma_m: 2.0}\n      compass: {kind: gyro, sigma_deg: 0.3}\n"))
    assert cli_module.main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("t: 1 ships, 120 s simulated in ")
    assert out[-1] == (f"results: {tmp_path / 'o' / 'trajectories.parquet'}, "
                       f"{tmp_path / 'o' / 'summary.json'}")
    import numpy as np

    c = {k: np.asarray(v) for k, v in
         pq.read_table(tmp_path / "o" / "trajectories.parquet").to_pydict().items()}
    t = c["t_s"]
    np.testing.assert_array_equal(t, np.arange(121.0))
    np.testing.assert_allclose(c["north_m"], 12 * KN * t, atol=0.3)
    np.testing.assert_allclose(c["east_m"], 0.0, atol=3.0)
    np.testing.assert_allclose(c["sog_kn"], 12.0, atol=0.01)
    assert np.abs((c["heading_deg"] + 180.0) % 360.0 - 180.0).max() < 0.5
    assert c["gnss_valid"].all()
    dn, de = c["gnss_north_m"] - c["north_m"], c["gnss_east_m"] - c["east_m"]
    assert 1.5 < dn.std() < 2.6 and 1.5 < de.std() < 2.6
    assert abs(dn.mean()) < 0.6 and abs(de.mean()) < 0.6
    dh = (c["compass_heading_deg"] - c["heading_deg"] + 180.0) % 360.0 - 180.0
    assert 0.2 < dh.std() < 0.42
    est = np.hypot(c["est_north_m"] - c["north_m"], c["est_east_m"] - c["east_m"])
    assert np.sqrt(np.mean(est[10:] ** 2)) < 0.75 * np.sqrt(np.mean(dn**2 + de**2))
    assert abs(np.median(c["est_sog_kn"][10:]) - 12.0) < 0.3
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    (ship,) = summary["ships"]
    assert ship["north_m"] == c["north_m"][-1] == pytest.approx(12 * KN * 120, abs=0.3)
    assert (summary["seed"], summary["n_steps"], summary["pairs"]) == (9, 120, [])


def test_run_prints_each_pairs_closed_form_closest_approach(capsys, tmp_path):
    """a north at 10 kn from the origin, b west at 10 kn from (2000, 3000): relative position
    d = (2000, 3000), velocity w = (-v, -v); tcpa = -d.w / |w|^2 = 2500 / v = 486.0 s,
    dcpa = |d + w tcpa| = |(-500, 500)| = 707.1 m; 1 s steps meet it within 0.01 m."""
    from trafficsim import cli as cli_module

    v = 10 * KN
    tcpa, dcpa = 2500.0 / v, 500.0 * 2**0.5
    path = tmp_path / "s.yaml"
    path.write_text(GOOD.replace("duration_s: 20", "duration_s: 600\nrecord_every_s: 60")
                    + "    speed_kn: 10\n    behaviour: keep_course\n"
                    "  - {name: b, type: cargo, north_m: 2000, east_m: 3000, heading_deg: 270,"
                    " speed_kn: 10, behaviour: keep_course}\n")
    assert cli_module.main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.splitlines()
    (pair,) = json.loads((tmp_path / "o" / "summary.json").read_text())["pairs"]
    flag = "  domain entered" if pair["domain_violation"] else ""
    assert out[1] == f"  a - b: min range {dcpa:.0f} m at t = {round(tcpa)} s{flag}"
    assert pair["dcpa_m"] == pytest.approx(dcpa, rel=1e-9)
    assert pair["tcpa_s"] == pytest.approx(tcpa, rel=1e-9)
    assert dcpa <= pair["min_range_m"] < dcpa + 0.01
    assert pair["t_min_range_s"] == round(tcpa)
    assert pair["collision"] is False
    rows = pq.read_table(tmp_path / "o" / "trajectories.parquet").num_rows
    assert rows == 2 * (600 // 60 + 1)


@pytest.mark.parametrize("fmt, every, fps, frames", [
    ("png", "2", None, 6), ("png", None, None, 11), ("gif", None, "4", 11), ("gif", "5", None, 3)])
def test_run_draws_a_frame_every_frames_every_s(capsys, tmp_path, fmt, every, fps, frames):
    """10 s recorded every second: 11 records; every 2 s: records 0, 2, ..., 10 (6 frames);
    every 5 s: 3. A GIF holds them at 1000 / fps ms each (default fps 10: 100 ms)."""
    from PIL import Image

    from trafficsim import cli as cli_module

    argv = ["run", str(_tiny_scenario(tmp_path, 10)), "--out", str(tmp_path / "o"), "--frames",
            fmt, "--size", "64x64"]
    argv += [] if every is None else ["--frames-every-s", every]
    argv += [] if fps is None else ["--fps", fps]
    assert cli_module.main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    folder = tmp_path / "o" / "frames"
    if fmt == "png":
        assert sorted(p.name for p in folder.iterdir()) == [
            f"frame_{k:05d}.png" for k in range(frames)]
        assert out[-1] == f"frames: {frames} (png) in {folder}"
    else:
        gif = folder / "t.gif"
        assert out[-1] == f"frames: {frames} (gif) in {gif}"
        with Image.open(gif) as im:
            assert im.n_frames == frames and im.size == (64, 64)
            assert im.info["duration"] == 1000 / (10.0 if fps is None else float(fps))


def test_trial_to_port_mirrors_the_starboard_turn(capsys, tmp_path):
    """cargo (a Nomoto model, symmetric): the port turn's track is the starboard turn's
    mirrored about the approach line, east negated and heading 360 - heading."""
    import numpy as np

    from trafficsim import cli as cli_module

    for side, more in (("stbd", []), ("port", ["--port"])):
        assert cli_module.main(["trial", "cargo", "--manoeuvre", "turning", "--rudder-deg",
                                "20", "--speed-kn", "12", "--out", str(tmp_path / side),
                                *more]) == 0
    out = capsys.readouterr().out
    assert out.count("approach_speed_kn: 12") == 2
    s = np.genfromtxt(tmp_path / "stbd" / "trial.csv", delimiter=",", names=True)
    p = np.genfromtxt(tmp_path / "port" / "trial.csv", delimiter=",", names=True)
    np.testing.assert_array_equal(s["t_s"], p["t_s"])
    np.testing.assert_allclose(p["north_m"], s["north_m"], atol=1e-3)
    np.testing.assert_allclose(p["east_m"], -s["east_m"], atol=1e-3)
    np.testing.assert_allclose(p["rudder_deg"], -s["rudder_deg"], atol=1e-6)
    # (the CSV keeps 6 significant digits: 0.001 deg near 360)
    np.testing.assert_allclose(np.sin(np.radians(p["heading_deg"])),
                               -np.sin(np.radians(s["heading_deg"])), atol=3e-5)
    assert s["rudder_deg"].max() == pytest.approx(20.0, abs=1e-6)
    assert s["sog_kn"][0] == pytest.approx(12.0, abs=1e-3)
    a, b = (json.loads((tmp_path / k / "indices.json").read_text())["indices"]
            for k in ("stbd", "port"))
    assert a["tactical_diameter_m"] == pytest.approx(b["tactical_diameter_m"], rel=1e-6)


def test_trial_sensor_noise_is_keyed_by_the_seed_and_leaves_the_truth_alone(capsys, tmp_path):
    import numpy as np

    from trafficsim import cli as cli_module

    def once(seed, name):
        assert cli_module.main(["trial", "cargo", "--manoeuvre", "crash-stop", "--sensors",
                                "--seed", seed, "--out", str(tmp_path / name)]) == 0
        return np.genfromtxt(tmp_path / name / "trial.csv", delimiter=",", names=True)

    a, again, other = once("4", "a"), once("4", "b"), once("5", "c")
    assert a.dtype.names == again.dtype.names
    for key in a.dtype.names:
        np.testing.assert_array_equal(a[key], again[key])
    for key in ("t_s", "north_m", "east_m", "heading_deg", "sog_kn"):
        np.testing.assert_array_equal(a[key], other[key])
    assert not np.array_equal(a["gnss_fix_north_m"], other["gnss_fix_north_m"])
    err = a["gnss_fix_north_m"] - a["north_m"]
    assert 0.5 < np.nanstd(err) < 5.0  # a few metres: a receiver's fix, not the truth


def test_explain_names_the_ship_time_and_refuses_unknown_ships_and_early_times(
        capsys, run_folder):
    from tests.conftest import error_line
    from trafficsim import cli as cli_module

    assert cli_module.main(["explain", str(run_folder), "--ship", "a", "--at-s", "25"]) == 0
    out = capsys.readouterr().out
    assert "t = 20 s, a about b" in out  # the last decision step at or before 25 s
    line = error_line(capsys, ["explain", run_folder, "--ship", "zed"])
    assert "--ship: ship 'zed' took no decisions" in line and "a, b" in line
    line = error_line(capsys, ["explain", run_folder, "--ship", "a", "--at-s", "-5"])
    assert "--at-s: the first decision is at t = 0 s, after --at-s -5" in line


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory):
    """Three 2-minute encounters of a small campaign, run through the command line."""
    from trafficsim import cli as cli_module

    folder = tmp_path_factory.mktemp("campaign")
    spec = folder / "spec.yaml"
    spec.write_text("schema_version: 1\nname: small\nn_encounters: 3\nseed: 11\n"
                    "duration_s: 120\nchunk_encounters: 2\nship_types: {cargo: 2, container: 1}\n"
                    "encounter_types: {head_on: 1, multi: 1}\nmulti_ships: [3, 3]\n"
                    "tcpa_min: [1, 2]\ndcpa_nm: [0, 0.2]\n")
    assert cli_module.main(["campaign", str(spec), "--out", str(folder / "out"), "--workers",
                            "1", "--no-progress"]) == 0
    return folder / "out"


def test_campaign_prints_counts_that_match_its_table(capsys, campaign_folder):
    """Run again on its own folder (every chunk done): the first line's counts are those of
    encounters.parquet (encounters; encounters with a collision in some pair)."""
    import numpy as np

    from trafficsim import cli as cli_module

    spec = campaign_folder.parent / "spec.yaml"
    assert cli_module.main(["campaign", str(spec), "--out", str(campaign_folder),
                            "--no-progress"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = pq.read_table(campaign_folder / "encounters.parquet").to_pydict()
    enc = np.array(rows["encounter"])
    hit = {e for e, c in zip(enc, rows["collision"], strict=True) if c}
    assert sorted(set(enc.tolist())) == [0, 1, 2]
    assert out[0].startswith(f"small: 3 encounters, {len(hit)} with a collision ")
    assert out[-1].startswith(f"results: {campaign_folder / 'encounters.parquet'}, ")


def test_replay_prints_each_pair_as_the_campaign_recorded_it(capsys, tmp_path, campaign_folder):
    from trafficsim import cli as cli_module

    rows = pq.read_table(campaign_folder / "encounters.parquet").to_pydict()
    for k in (0, 2):
        out = tmp_path / f"r{k}"
        assert cli_module.main(["replay", str(campaign_folder), "--encounter", str(k), "--out",
                                str(out), "--record-every-s", "20"]) == 0
        lines = capsys.readouterr().out.splitlines()
        mine = [i for i, e in enumerate(rows["encounter"]) if e == k]
        expected = [f"  {rows['ship_i'][i]} - {rows['ship_j'][i]}: min range "
                    f"{rows['min_range_m'][i]:.0f} m at t = {rows['t_cpa_s'][i]:.0f} s"
                    + ("  COLLISION" if rows["collision"][i] else "") for i in mine]
        assert lines[1:-1] == expected
        ships = {rows["ship_i"][i] for i in mine} | {rows["ship_j"][i] for i in mine}
        assert lines[0].endswith(f": {len(ships)} ships, 120 s")
        t = pq.read_table(out / "trajectories.parquet").column("t_s").to_pylist()
        assert sorted(set(t)) == [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0]


def test_replay_refuses_an_encounter_the_campaign_does_not_have(capsys, campaign_folder,
                                                                  tmp_path):
    from tests.conftest import error_line

    line = error_line(capsys, ["replay", campaign_folder, "--encounter", "3", "--out",
                               tmp_path / "r"])
    assert line == "trafficsim: error: --encounter: expected an encounter index 0 .. 2, got 3"
    line = error_line(capsys, ["replay", campaign_folder, "--encounter", "0", "--out",
                               tmp_path / "r", "--record-every-s", "1.5"])
    assert "--record-every-s: expected a whole multiple of the campaign's step (1 s)" in line
    assert not (tmp_path / "r").exists()


# --- bad input of run, render, explain and validate ------------------------------------------


@pytest.mark.parametrize("change, expect", [
    (lambda s: [], "summary.json: expected a JSON object"),
    (lambda s: {**s, "record_every_s": "x"}, "summary.json:1: record_every_s: expected a "
     "positive number, got 'x'"),
    (lambda s: {**s, "ships": [{**s["ships"][0], "length_m": "big"}, *s["ships"][1:]]},
     "summary.json:1: ships[0].length_m: expected a positive number"),
    (lambda s: {**s, "ships": [{**s["ships"][0], "route_m": [[1, "a"]]}, *s["ships"][1:]]},
     "summary.json:1: ships[0].route_m[0][1]: expected a finite number"),
    (lambda s: {**s, "duration_s": [1]}, "summary.json:1: duration_s: expected a finite number"),
])
def test_a_damaged_summary_is_one_line_naming_the_file_and_key(capsys, tmp_path, run_folder,
                                                              change, expect):
    from tests.conftest import error_line

    summary = json.loads((run_folder / "summary.json").read_text())
    spoilt = _spoilt(run_folder, tmp_path, "summary.json", json.dumps(change(summary)))
    line = error_line(capsys, ["render", spoilt, "--out", tmp_path / "f", "--no-progress"])
    assert f"{spoilt}/{expect}" in line, line


@pytest.mark.parametrize("command, name, column", [
    ("render", "trajectories.parquet", "north_m"), ("render", "decisions.parquet", "t_s"),
    ("explain", "decisions.parquet", "t_s")])
def test_a_column_of_the_wrong_type_is_one_line_naming_file_and_column(
        capsys, tmp_path, run_folder, command, name, column):
    import pyarrow as pa

    from tests.conftest import error_line

    spoilt = _spoilt(run_folder, tmp_path, "summary.json",
                     (run_folder / "summary.json").read_text())
    table = pq.read_table(spoilt / name)
    text = pa.array([str(v) for v in table.column(column).to_pylist()])
    pq.write_table(table.set_column(table.column_names.index(column), column, text),
                   spoilt / name)
    argv = (["render", spoilt, "--out", tmp_path / "f", "--no-progress"] if command == "render"
            else ["explain", spoilt, "--ship", "a"])
    line = error_line(capsys, argv)
    assert f"{spoilt}/{name}: {column}: expected numbers, got string values" in line, line


@pytest.mark.parametrize("argv, flag", [
    (["explain", "{run}", "--ship", "a", "--at-s", "1e9"], "--at-s"),
    (["render", "{run}", "--out", "{tmp}/f", "--every-s", "1e9"], "--every-s"),
    (["render", "{run}", "--out", "{tmp}/f", "--follow", "a", "--range-nm", "1e9"],
     "--range-nm"),
    (["render", "{run}", "--out", "{tmp}/f", "--measurements"], "--measurements"),
    (["run", "{scenario}", "--out", "{tmp}/o", "--frames", "--frames-every-s", "1e9"],
     "--frames-every-s"),
    (["run", "{scenario}", "--out", "{tmp}/o", "--frames", "--measurements"], "--measurements"),
])
def test_flags_beyond_the_run_or_doing_nothing_are_refused(capsys, tmp_path, run_folder, argv,
                                                          flag):
    from tests.conftest import error_line

    names = {"run": run_folder, "tmp": tmp_path, "scenario": _tiny_scenario(tmp_path)}
    line = error_line(capsys, [a.format(**names) for a in argv])
    assert line.startswith(f"trafficsim: error: {flag}: "), line
    assert not (tmp_path / "o").exists() and not (tmp_path / "f").exists()


@pytest.mark.parametrize("command", ["run", "render"])
def test_an_empty_output_folder_is_refused(capsys, tmp_path, run_folder, command):
    source = _tiny_scenario(tmp_path) if command == "run" else run_folder
    line = usage_error(capsys, [command, source, "--out", ""])
    assert "--out: expected a folder name, got an empty one" in line


@pytest.mark.parametrize("argv", [
    ["campaign", "--out", " ", "c.yaml"], ["trial", "--out", "", "cargo"],
    ["identify", "--out", "", "--model", "nomoto", "--base", "cargo", "--data", "d.csv"],
    ["diagnose", "--out", "", "--self-test", "1"], ["report", "--out", "", "c"],
    ["replay", "--out", "", "c", "--encounter", "0"]])
def test_every_command_refuses_an_empty_output_folder(capsys, argv):
    line = usage_error(capsys, argv)
    assert "--out: expected a folder name, got an empty one" in line


def test_a_scenario_too_big_for_memory_names_the_ships_key(capsys, tmp_path, monkeypatch):
    from tests.conftest import error_line
    from trafficsim import run

    monkeypatch.setattr(run, "available_memory_bytes", lambda: 1000)
    path = tmp_path / "s.yaml"
    path.write_text(GOOD + "  - {name: b, type: cargo, north_m: 5000, east_m: 0, "
                    "heading_deg: 180}\n")
    line = error_line(capsys, ["run", path, "--out", tmp_path / "o"])
    assert line.startswith(f"trafficsim: error: {path}:4: ships: 2 ships in one encounter "
                           "make 1 ship pair(s)"), line
    assert "0.0 GB free: at most about 1 ships fit" in line and not (tmp_path / "o").exists()


def test_running_out_of_memory_is_one_line(capsys, tmp_path, monkeypatch):
    import trafficsim.run

    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(trafficsim.run, "run_scenario", exhausted)
    from trafficsim import cli as cli_module

    assert cli_module.main(["run", str(_tiny_scenario(tmp_path)), "--out",
                            str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trafficsim: error: out of memory in 'run'") and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


SHIP_B = ("  - name: b\n    type: {type}\n    north_m: 5000\n    east_m: 0\n"
          "    heading_deg: 180\n")


@pytest.mark.parametrize("extra, key, expect", [
    ("    effects: {resistance: {scale: 2}}\n", "ships[1].effects.resistance",
     "acts on the hull model of the mmg and mmg_berthing families"),
    ("    sensors: {ais: {}}\n    effects: {ais_latency: {latency_s: 100000}}\n",
     "ships[1].effects.ais_latency.latency_s",
     "expected 0 to 12 s (the ship's AIS latency 2 s plus this must be <= 14 s), got 100000"),
    ("    sensors: {actuators: {rudder_sigma_deg: -3}}\n",
     "ships[1].sensors.actuators.rudder_sigma_deg", "must be >= 0.0, got -3.0"),
    ("    filter: pv\n    sensors: {navigation: {pv_sp_m2ps3: 0}}\n",
     "ships[1].sensors.navigation.pv_sp_m2ps3", "must be > 0.0, got 0.0"),
    ("    sensors: {gnss: {gross_prob: 2}}\n", "ships[1].sensors.gnss.gross_prob",
     "must be <= 1, got 2"),
    ("    speed_kn: 60\n", "ships[1].speed_kn", "expected at most 2 times the service speed"),
    ("    effects: {current: {north_mps: 1000}}\n", "ships[1].effects.current.north_mps",
     "expected a current of at most 5.144 m/s = 10 kn"),
    ("    effects: {wind: {east_mps: -1000}}\n", "ships[1].effects.wind.east_mps",
     "expected a wind of at most 60 m/s"),
    ("    effects: {compass_bias: {bias_deg: 720}}\n", "ships[1].effects.compass_bias.bias_deg",
     "expected -180 to 180 deg, got 720"),
    ("    effects: {propeller_asymmetry: {rudder_offset_deg: 1000}}\n",
     "ships[1].effects.propeller_asymmetry.rudder_offset_deg", "within +-90 deg"),
    ("    route: [[6000, 0], [6000, 0]]\n", "ships[1].route[1]", "a leg of no length"),
    ("    route: [[5000, 0]]\n", "ships[1].route[0]", "is the ship's start position"),
    ("    filter: pv\n    sensors: {navigation: {adaptive_window_steps: 10}}\n",
     "ships[1].sensors.navigation.adaptive_window_steps", "needs filter: ekf, got filter: pv"),
])
@pytest.mark.parametrize("command", ["run", "validate"])
def test_what_run_refuses_validate_refuses_at_the_line_and_key(capsys, tmp_path, extra, key,
                                                               expect, command):
    from tests.conftest import error_line

    path = tmp_path / "s.yaml"
    path.write_text(GOOD + SHIP_B.format(type="cargo") + extra)
    argv = ["run", path, "--out", tmp_path / "o"] if command == "run" else ["validate", path]
    line = error_line(capsys, argv)
    assert re.match(rf"trafficsim: error: {re.escape(str(path))}:\d+: {re.escape(key)}: ", line)
    assert expect in line, line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("old, new, key, expect", [
    ("north_m: 5000", "north_m: 50", "ships[1].north_m", "starts where its hull overlaps"),
    ("duration_s: 20\n", "duration_s: 20\nrecord_every_s: 1000\n", "record_every_s",
     "must not exceed duration_s (20 s), got 1000"),
    ("duration_s: 20\n", "duration_s: 20\ndecision_period_s: 500\n", "decision_period_s",
     "must not exceed duration_s (20 s), got 500"),
])
def test_doubtful_scenario_values_are_refused_at_their_key(capsys, tmp_path, old, new, key,
                                                           expect):
    from tests.conftest import error_line

    path = tmp_path / "s.yaml"
    text = (GOOD + SHIP_B.format(type="cargo")).replace(old, new, 1)
    path.write_text(text)
    for argv in (["run", path, "--out", tmp_path / "o"], ["validate", path]):
        line = error_line(capsys, argv)
        assert f": {key}: " in line and expect in line, line


def test_a_lone_route_point_ahead_and_a_fast_but_possible_ship_still_run(capsys, tmp_path):
    from trafficsim import cli as cli_module

    path = tmp_path / "s.yaml"
    path.write_text(GOOD + "    route: [[3000, 500]]\n" + SHIP_B.format(type="cargo")
                    + "    speed_kn: 30\n")
    assert cli_module.main(["run", str(path), "--out", str(tmp_path / "o")]) == 0


def test_a_single_colregs_ship_with_a_broken_rules_file_is_refused(capsys, tmp_path):
    from tests.conftest import error_line

    (tmp_path / "rules.yaml").write_text("schema_version: 1\nname: x\nstart: a\nnodes:\n"
                                         "  a: {test: [bogus, '>', 1]}\n")
    path = tmp_path / "s.yaml"
    path.write_text(GOOD.replace("ships:", "rules: rules.yaml\nships:"))
    line = error_line(capsys, ["run", path, "--out", tmp_path / "o"])
    assert f"{tmp_path / 'rules.yaml'}:5: nodes.a.test[0]: unknown feature 'bogus'" in line
