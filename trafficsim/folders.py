"""What an output folder holds, so that a command does not write its results over results of
another kind (a run's ``summary.json`` over a campaign's, or a campaign's over a run's)."""

from __future__ import annotations

import json
from pathlib import Path

from trafficsim.errors import InputError

#: the kinds of results a folder can hold, as messages name them
HOLDS = {"campaign": "a campaign's results (campaign.json, encounters.parquet, summary.json)",
         "run": "a run's results (trajectories.parquet, summary.json)"}


def results_kind(folder: Path) -> str | None:
    """``"campaign"`` (``trafficsim campaign``'s ``campaign.json``, or a campaign's summary) or
    ``"run"`` (``trafficsim run`` or ``replay``: trajectories, or a scenario's summary) when
    ``folder`` holds such results, else None."""
    if (folder / "campaign.json").exists():
        return "campaign"
    if (folder / "trajectories.parquet").exists():
        return "run"
    try:
        summary = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    if isinstance(summary, dict):
        if "campaign" in summary:
            return "campaign"
        if "scenario" in summary:
            return "run"
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
