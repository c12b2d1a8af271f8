"""Output folders: a command refuses to write its results among results of another kind (a
run's or a replay's summary.json replaced a campaign's, a campaign's replaced a run's, a
diagnosis's report replaced an identification's)."""

import json
import shutil
from pathlib import Path

import pytest

from tests.conftest import SCENARIOS, error_line
from trafficsim import cli
from trafficsim.folders import refuse_other_results, results_kind

CAMPAIGN_HOLDS = "holds a campaign's results (campaign.json, encounters.parquet, summary.json)"
RUN_HOLDS = "holds a run's results (trajectories.parquet, summary.json)"


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> tuple[Path, Path, Path]:
    """A finished two-encounter campaign's folder, a run's folder, and the campaign spec."""
    root = tmp_path_factory.mktemp("folders")
    spec = root / "spec.yaml"
    spec.write_text("schema_version: 1\nname: small\nn_encounters: 2\nseed: 3\n"
                    "duration_s: 60\nencounter_types: {head_on: 1}\ntcpa_min: [1, 1]\n")
    assert cli.main(["campaign", str(spec), "--out", str(root / "campaign"), "--workers", "1",
                     "--no-progress"]) == 0
    assert cli.main(["run", str(SCENARIOS / "head_on.yaml"), "--out", str(root / "run")]) == 0
    return root / "campaign", root / "run", spec


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_results_kind_tells_a_campaign_from_a_run(folders, tmp_path):
    campaign, run, _ = folders
    assert results_kind(campaign) == "campaign" and results_kind(run) == "run"
    assert results_kind(tmp_path) is None and results_kind(tmp_path / "missing") is None
    (tmp_path / "summary.json").write_text("{not json")
    assert results_kind(tmp_path) is None
    (tmp_path / "summary.json").write_text(json.dumps({"scenario": "s"}))
    assert results_kind(tmp_path) == "run"
    (tmp_path / "summary.json").write_text(json.dumps({"campaign": "c"}))
    assert results_kind(tmp_path) == "campaign"
    refuse_other_results(tmp_path, "campaign", "a campaign")


@pytest.mark.parametrize("argv, into, holds, writes", [
    (["replay", "{campaign}", "--encounter", "0", "--out", "{campaign}"], "campaign",
     CAMPAIGN_HOLDS, "a replay (a run folder)"),
    (["run", str(SCENARIOS / "head_on.yaml"), "--out", "{campaign}"], "campaign",
     CAMPAIGN_HOLDS, "a run"),
    (["campaign", "{spec}", "--out", "{run}", "--workers", "1", "--no-progress"], "run",
     RUN_HOLDS, "a campaign"),
    (["report", "{campaign}", "--worst", "0", "--out", "{campaign}", "--no-progress"],
     "campaign", CAMPAIGN_HOLDS, "a report"),
    (["report", "{campaign}", "--worst", "0", "--out", "{run}", "--no-progress"], "run",
     RUN_HOLDS, "a report"),
])
def test_results_are_not_written_among_results_of_another_kind(capsys, folders, argv, into,
                                                                holds, writes):
    campaign, run, spec = folders
    names = {"campaign": campaign, "run": run, "spec": spec}
    folder = names[into]
    before = _snapshot(folder)
    line = error_line(capsys, [a.format(**names) for a in argv])
    assert line == (f"trafficsim: error: --out: {folder} {holds}; {writes} must not be written "
                    "among them: use another --out folder")
    assert _snapshot(folder) == before


def test_results_of_the_same_kind_are_written_over_as_before(capsys, folders, tmp_path):
    """A run into a run's folder, a replay into a replay's, a campaign resumed in its own
    folder, and the report into its default folder (replays in it) go on as before."""
    campaign, run, spec = folders
    out = tmp_path / "run"
    shutil.copytree(run, out)
    assert cli.main(["run", str(SCENARIOS / "head_on.yaml"), "--out", str(out)]) == 0
    for _ in range(2):
        assert cli.main(["replay", str(campaign), "--encounter", "1", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["encounter"] == 1
    assert cli.main(["campaign", str(spec), "--out", str(campaign), "--no-progress"]) == 0
    for _ in range(2):
        assert cli.main(["report", str(campaign), "--worst", "1", "--no-progress"]) == 0
    assert (campaign / "report" / "index.html").is_file()
    capsys.readouterr()


def test_results_kind_tells_trials_identifications_diagnoses_and_reports(tmp_path):
    kinds = {"trial": {"indices.json": "{}"},
             "identify": {"report.json": json.dumps({"coefficients": {}})},
             "diagnose": {"report.json": json.dumps({"verdict": "v"})},
             "report": {"index.html": "<html></html>"}}
    for kind, files in kinds.items():
        folder = tmp_path / kind
        folder.mkdir()
        for name, text in files.items():
            (folder / name).write_text(text)
        assert results_kind(folder) == kind
    only_ship = tmp_path / "ship_only"  # an identification that stopped before its report
    only_ship.mkdir()
    (only_ship / "ship.yaml").write_text("name: x\n")
    assert results_kind(only_ship) == "identify"
    self_test = tmp_path / "self_test"
    self_test.mkdir()
    (self_test / "selftest.json").write_text("{}")
    assert results_kind(self_test) == "diagnose"
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "report.json").write_text(json.dumps({"something": 1}))
    assert results_kind(tmp_path / "other") is None


@pytest.fixture(scope="module")
def trial_folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("trial")
    assert cli.main(["trial", "container", "--manoeuvre", "turning", "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("into, files, holds, argv, writes", [
    ("trial", None, "a trial's results (trial.csv, indices.json)",
     ["identify", "--model", "nomoto", "--base", "container", "--data", "{trial}/trial.csv",
      "--out", "{folder}"], "an identification"),
    ("identify", {"ship.yaml": "name: x\n", "report.json": '{"coefficients": {}}'},
     "an identification's results (ship.yaml, report.json, report.md)",
     ["diagnose", "--ship", "container", "--data", "{trial}/trial.csv", "--out", "{folder}"],
     "a diagnosis"),
    ("diagnose", {"report.json": '{"verdict": "v"}'},
     "a diagnosis's results (report.json, report.md, residuals_by_phase.png or selftest.json)",
     ["identify", "--model", "nomoto", "--base", "container", "--data", "{trial}/trial.csv",
      "--out", "{folder}"], "an identification"),
    ("run", {"summary.json": '{"scenario": "s"}'}, RUN_HOLDS[len("holds "):],
     ["trial", "container", "--manoeuvre", "turning", "--out", "{folder}"], "a trial"),
    ("run", {"summary.json": '{"scenario": "s"}'}, RUN_HOLDS[len("holds "):],
     ["diagnose", "--self-test", "1", "--out", "{folder}"], "a self-test"),
])
def test_trials_fits_and_diagnoses_are_not_written_among_results_of_another_kind(
        capsys, tmp_path, trial_folder, into, files, holds, argv, writes):
    """identify and diagnose both write report.json and report.md: one replaced the other's."""
    folder = trial_folder if files is None else tmp_path / into
    folder.mkdir(exist_ok=True)
    for name, text in (files or {}).items():
        (folder / name).write_text(text)
    before = _snapshot(folder)
    line = error_line(capsys, [a.format(trial=trial_folder, folder=folder) for a in argv])
    assert line == (f"trafficsim: error: --out: {folder} holds {holds}; {writes} must not be "
                    "written among them: use another --out folder")
    assert _snapshot(folder) == before
