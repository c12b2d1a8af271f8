"""A chunk of a campaign as one batch: an encounter whose state stops being finite is flagged
and frozen while the others run on, whatever the chunking; the summary, the figures, the
report and the command line leave it out of the outcomes and name it."""

import json
from pathlib import Path

import numpy as np

from trafficsim.campaign.runner import run_chunk
from trafficsim.campaign.spec import load_spec
from trafficsim.cli import main
from trafficsim.render.report import write_report

SPEC = """schema_version: 1
name: runaway
n_encounters: 8
seed: 5
duration_s: 300
chunk_encounters: 4
encounter_types: {head_on: 1, crossing_give_way: 1}
ship_types: {cargo: 1, runaway.yaml: 1}
"""


def _spec(runaway_ship: Path) -> Path:
    path = runaway_ship.parent / "spec.yaml"
    path.write_text(SPEC)
    return path


def test_a_diverging_encounter_is_flagged_and_the_others_run_on(runaway_ship):
    spec = load_spec(_spec(runaway_ship))
    whole = run_chunk(spec, 0, 8)
    diverged = np.asarray(whole["diverged"])
    runaway = (np.asarray(whole["type_i"]) == "runaway") | (np.asarray(whole["type_j"])
                                                               == "runaway")
    assert diverged.any() and not diverged.all()
    assert not (diverged & ~runaway).any()  # only encounters with the runaway ship
    at = np.asarray(whole["diverged_at_s"])
    assert (np.isfinite(at) == diverged).all() and (at[diverged] < 120.0).all()
    assert np.isfinite(np.asarray(whole["min_range_m"])).all()
    # the same rows whatever chunk ran them: a frozen encounter touches no other
    parts = [run_chunk(spec, a, b) for a, b in ((0, 3), (3, 8))]
    for key, value in whole.items():
        if not key.startswith("_"):
            joined = [v for p in parts for v in np.asarray(p[key]).tolist()]
            np.testing.assert_array_equal(np.asarray(value).tolist(), joined, err_msg=key)


def test_diverged_encounters_are_named_and_left_out_of_the_outcomes(runaway_ship, tmp_path,
                                                                    capsys):
    out = tmp_path / "out"
    assert main(["campaign", str(_spec(runaway_ship)), "--out", str(out), "--workers", "1",
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out
    rows = run_chunk(load_spec(_spec(runaway_ship)), 0, 8)
    enc = np.asarray(rows["encounter"])
    gone = sorted(set(enc[np.asarray(rows["diverged"])].tolist()))
    s = json.loads((out / "summary.json").read_text())
    assert s["n_encounters"] == 8 and s["diverged"] == len(gone) > 0
    assert s["diverged_encounters"] == gone and s["n_completed"] == 8 - len(gone)
    assert s["encounters_all_compliant"] == 8 - len(gone)  # no rogues in this spec
    kept = ~np.isin(enc, gone)
    cpa_nm = [np.min(np.asarray(rows["min_range_m"])[enc == e]) / 1852.0
              for e in sorted(set(enc[kept].tolist()))]
    assert s["cpa_nm"]["p50"] == np.percentile(cpa_nm, 50)
    assert f"DIVERGED: {len(gone)} encounters" in printed
    assert ", ".join(map(str, gone)) in printed

    report = write_report(out, worst=0, progress=False)
    page = report.path.read_text()
    assert f"{len(gone)} encounters diverged" in page
    # its replay is written up to the divergence, then ends as a diverged run does
    replay = tmp_path / "replay"
    assert main(["replay", str(out), "--encounter", str(gone[0]), "--out", str(replay)]) == 1
    assert "state became non-finite" in capsys.readouterr().err
    at = np.asarray(rows["diverged_at_s"])[enc == gone[0]][0]
    assert json.loads((replay / "summary.json").read_text())["diverged_at_s"] == at
