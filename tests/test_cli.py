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
                                  ["--measurements"], ["--size", "640x480"], ["--fps", "5"]])
def test_frame_flags_without_frames_are_refused_not_ignored(tmp_path, flag):
    scenario = Path(__file__).parent.parent / "scenarios" / "head_on.yaml"
    line = one_line_error(cli("run", scenario, "--out", tmp_path / "o", *flag))
    assert line == (f"trafficsim: error: {flag[0]}: applies only with --frames (png, gif or "
                    "mp4)")
    assert not (tmp_path / "o").exists()
