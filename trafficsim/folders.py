"""What an output folder holds, so that a command does not write its results over results of
another kind (a run's ``summary.json`` over a campaign's, an identification's ``report.json``
over a diagnosis's, or a trial among a run's)."""

from __future__ import annotations

import json
from pathlib import Path

from trafficsim.errors import InputError

#: the kinds of results a folder can hold, as messages name them
HOLDS = {"campaign": "a campaign's results (campaign.json, encounters.parquet, summary.json)",
         "run": "a run's results (trajectories.parquet, summary.json)",
         "report": "a campaign report (index.html)",
         "trial": "a trial's results (trial.csv, indices.json)",
         "identify": "an identification's results (ship.yaml, report.json, report.md)",
         "diagnose": "a diagnosis's results (report.json, report.md, residuals_by_phase.png "
                     "or selftest.json)"}


def _json_keys(path: Path) -> set[str]:
    """The top-level keys of a JSON object file; none when it is absent or not such a file."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return set()
    return set(data) if isinstance(data, dict) else set()


def results_kind(folder: Path) -> str | None:
    """What kind of results ``folder`` holds (a key of :data:`HOLDS`), None for none:
    ``"campaign"`` (``campaign.json``, or a campaign's summary), ``"run"`` (``trafficsim run``
    or ``replay``: trajectories, or a scenario's summary), ``"report"`` (``index.html``),
    ``"trial"`` (``indices.json``), ``"identify"`` (``ship.yaml``, or a report with
    coefficients), ``"diagnose"`` (a report with a verdict, or ``selftest.json``)."""
    if (folder / "campaign.json").exists():
        return "campaign"
    if (folder / "trajectories.parquet").exists():
        return "run"
    summary = _json_keys(folder / "summary.json")
    if "campaign" in summary:
        return "campaign"
    if "scenario" in summary:
        return "run"
    if (folder / "index.html").exists():
        return "report"
    if (folder / "indices.json").exists():
        return "trial"
    report = _json_keys(folder / "report.json")
    if "coefficients" in report or (folder / "ship.yaml").exists():
        return "identify"
    if "verdict" in report or (folder / "selftest.json").exists():
        return "diagnose"
    return None


def refuse_other_results(folder: Path, kind: str, writes: str, flag: str = "--out") -> None:
    """Refuse to write ``writes`` (the command's results, in words) into ``folder`` when it
    holds results of a kind other than ``kind``.

    Raises:
        InputError: at ``flag``, naming the folder and what it holds.
    """
    held = results_kind(Path(folder))
    if held is not None and held != kind:
        raise InputError(f"{folder} holds {HOLDS[held]}; {writes} must not be written among "
                         f"them: use another {flag} folder", key=flag)
