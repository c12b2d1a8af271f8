"""``trafficsim identify`` end to end: a simulated ship identified from its noisy zig-zags, the
ship file used by ``trafficsim trial`` and ``trafficsim run``, and the command's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.test_cli import cli, one_line_error
from trafficsim.identify.command import identify
from trafficsim.run import run_scenario
from trafficsim.ships.library import load_ship
from trafficsim.trial import run_trial

#: the raw receiver fixes (DGPS, sigma 2 m) and compass the trial records beside the truth
MEASURED = {"north_m": "gnss_fix_north_m", "east_m": "gnss_fix_east_m",
            "heading_deg": "compass_heading_deg"}


@pytest.fixture(scope="module")
def identified(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """The bulk carrier of [seed 001] (response model) on zig-zags 10/10, 20/20 and 30/30,
    measured by the ship's own instruments (DGPS fixes sigma 2 m, gyro compass), a 15/15
    zig-zag held out; identified by the seeds' chain: RTS smoothing, augmented EKF from zero,
    output-error refinement."""
    root = tmp_path_factory.mktemp("identify")
    for rudder in (10, 20, 30, 15):
        run_trial("bulk_carrier", "zigzag", float(rudder), None, False, None, None,
                  root / f"zz{rudder}", sensors=True, seed=100 + rudder)
    out = root / "out"
    report = identify("response", [root / f"zz{r}" / "trial.csv" for r in (10, 20, 30)], out,
                      "bulk_carrier", holdout=[root / "zz15" / "trial.csv"],
                      reference="bulk_carrier", columns=MEASURED)
    return out, report


def test_turning_indices_recovered_within_5_percent(identified) -> None:
    """Advance, transfer and tactical diameter of the 35 deg turns of the identified model
    within 5 % of the true ship's (cf. [seed 001, table 2]: 1.9, 5.0 and -0.2 %)."""
    _, report = identified
    comparison = report["validation"]["reference_comparison"]
    for side in ("turning_35_starboard", "turning_35_port"):
        for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
            assert abs(comparison[side][key]["error_pct"]) < 5.0, (side, key)
    # the smoother saw the instruments' noise, not the truth
    assert report["preprocessing"]["smoother"]["sigma_pos_m"] == pytest.approx(2.0, rel=0.15)


def test_held_out_run_is_predicted_and_the_fit_helped(identified) -> None:
    """On the held-out zig-zag the identified model's end-of-window position error is a few
    metres over 100 s windows, far below the EKF estimate it started from."""
    _, report = identified
    hold = report["validation"]["prediction"]["holdout"]
    e, e0 = hold["identified"]["all"], hold["start"]["all"]
    assert e["end_position_rms_m"] < 15.0 and e["end_position_rms_m"] < 0.2 * e0[
        "end_position_rms_m"]
    assert e["heading_rms_deg"] < 1.0 and e["diverged_windows"] == 0
    assert report["ekf"]["recursions"] > 3000 and report["fit"]["converged"]


def test_outputs_on_disk_and_the_ship_file_works(identified, tmp_path: Path) -> None:
    out, report = identified
    assert (out / "convergence.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    on_disk = json.loads((out / "report.json").read_text())
    assert on_disk["ship"]["name"] == "bulk_carrier_identified"
    assert "## Prediction error" in (out / "report.md").read_text()
    spec = load_ship(str(out / "ship.yaml"))
    assert spec["model"] == "response"
    for name, value in report["coefficients"].items():
        assert spec["coefficients"][name] == pytest.approx(value, rel=1e-9)
    # usable by path in trafficsim trial ...
    res = cli("trial", out / "ship.yaml", "--manoeuvre", "turning", "--out", tmp_path / "t")
    assert res.returncode == 0, res.stderr
    # ... and in a scenario
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"""schema_version: 1
name: identified_ship
duration_s: 300
dt_s: 1.0
seed: 1
ships:
  - name: own
    type: {out / 'ship.yaml'}
    north_m: 0
    east_m: 0
    heading_deg: 0
    speed_kn: 12
    route: [[3000, 0]]
    behaviour: keep_course
""")
    summary = run_scenario(scenario, tmp_path / "run")
    assert summary["n_ships"] == 1


def test_cli_identify_runs_and_prints(tmp_path: Path) -> None:
    """The command line on a noise-free nomoto trial (quick): files written, summary printed."""
    run_trial("container", "zigzag", 20.0, None, False, None, None, tmp_path / "zz")
    res = cli("identify", "--model", "nomoto", "--base", "container", "--data",
              tmp_path / "zz", "--out", tmp_path / "o", "--fit", "K_prime,T_prime",
              "--bounds", "K_prime=0.5:10", "--max-nfev", "20")
    assert res.returncode == 0, res.stderr
    assert "results:" in res.stdout and "K_prime" in res.stdout
    assert (tmp_path / "o" / "ship.yaml").is_file()


@pytest.mark.parametrize("args, expect", [
    (["--model", "mmg", "--base", "bulk_carrier"], "needs an mmg base ship"),
    (["--model", "nomoto", "--base", "container", "--method", "ekf"], "response model only"),
    (["--model", "nomoto", "--base", "container", "--fit", "K_prim"], "did you mean 'K_prime'"),
    (["--model", "nomoto", "--base", "container", "--bounds", "K_prime=1"], "NAME=LOW:HIGH"),
    (["--model", "nomoto", "--base", "container", "--bounds", "T_prime=1:2", "--fit",
      "K_prime"], "not fitted"),
    (["--model", "nomoto", "--base", "kvlc2"], "did you mean 'kvlcc2'"),
])
def test_identify_errors_are_one_line(tmp_path: Path, args: list[str], expect: str) -> None:
    data = tmp_path / "run.csv"
    t = np.arange(0.0, 60.0)
    rows = ["t_s,north_m,east_m,heading_deg,rudder_deg,rpm"] + [
        f"{x},{7 * x},0,{0.1 * x},10,80" for x in t]
    data.write_text("\n".join(rows) + "\n")
    line = one_line_error(cli("identify", "--data", data, "--out", tmp_path / "o", *args))
    assert expect in line


def test_missing_data_file_is_named(tmp_path: Path) -> None:
    line = one_line_error(cli("identify", "--model", "nomoto", "--base", "container", "--data",
                              tmp_path / "none.csv", "--out", tmp_path / "o"))
    assert "none.csv" in line and "not found" in line
