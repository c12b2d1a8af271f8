"""trafficsim diagnose: phases, recovery of a changed hull from its trials, the noise-floor
verdict, a small injection-recovery self-test, and the command line's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from trafficsim import cli, effects
from trafficsim.diagnose import command, fit, selftest
from trafficsim.diagnose.data import PHASES, phases
from trafficsim.ships.library import LIBRARY_DIR, load_ship
from trafficsim.trial import run_trial


def test_phases_of_a_turn_and_a_zigzag() -> None:
    t = np.arange(0.0, 300.0, 1.0)
    rudder = np.radians(np.where(t < 50, 0.0, 35.0))
    r = np.where(t < 50, 0.0, 0.01 * (1 - np.exp(-(t - 50) / 20.0)))
    ph = phases(rudder, r, 1.0)
    names = [PHASES[k] for k in ph]
    assert names[0] == "approach" and names[55] == "execute" and names[-1] == "steady"
    # counter rudder against the yaw rate is a check; rudder amidships while turning, pull-out
    rudder2 = np.radians(np.where(t < 150, 20.0, np.where(t < 250, -20.0, 0.0)))
    r2 = np.full(t.size, 0.005)
    ph2 = [PHASES[k] for k in phases(rudder2, r2, 1.0)]
    assert ph2[200] == "checks" and ph2[280] == "pullout"


def test_fouled_hull_found_and_measured(tmp_path: Path) -> None:
    text = (LIBRARY_DIR / "kvlcc2.yaml").read_text()
    assert "  R0: 0.022\n" in text
    ship = tmp_path / "fouled.yaml"
    ship.write_text(text.replace("  R0: 0.022\n", "  R0: 0.0286\n").replace(
        "name: kvlcc2\n", "name: kvlcc2_fouled\n"))
    # at 14 kn: the fouled hull makes 15.27 kn at full power, short of the service 15.5 kn
    run_trial(str(ship), "zigzag", 10.0, None, False, 14.0, 2.0, tmp_path / "z10")
    run_trial(str(ship), "zigzag", 20.0, None, False, 14.0, 2.0, tmp_path / "z20")
    run_trial(str(ship), "turning", 35.0, None, True, 14.0, 2.0, tmp_path / "tc")
    rep = command.diagnose("kvlcc2", [tmp_path / "z10", tmp_path / "z20"], tmp_path / "out",
                           [tmp_path / "tc"], candidates=["current", "resistance",
                                                          "shallow_water"])
    best = rep["ranking"][0]
    assert best["effect"] == "resistance"
    assert best["parameters"]["resistance.scale"]["value"] == pytest.approx(1.3, rel=0.01)
    assert best["shrinkage_holdout"] > 0.95 and rep["chosen"]["effects"] == ["resistance"]
    saved = json.loads((tmp_path / "out" / "report.json").read_text())
    assert next(r["effect"] for r in saved["ranking"]) == "resistance"
    assert set(saved["ranking"][0]) >= {"effect", "parameters", "shrinkage_train",
                                        "shrinkage_holdout", "per_phase"}
    assert (tmp_path / "out" / "residuals_by_phase.png").stat().st_size > 1000
    assert "## Where" in (tmp_path / "out" / "report.md").read_text()


def test_no_effect_is_not_attributable() -> None:
    spec = load_ship("kvlcc2")
    rng = np.random.default_rng(3)
    train, hold = selftest.simulate_trial(spec, {}, rng)
    dt, dh = selftest.prepare(spec, train, hold)
    diag = fit.diagnose(spec, dt, dh, ("current", "resistance"), forward_steps=1)
    assert not diag.attributable and "not attributable" in diag.verdict


def test_self_test_small() -> None:
    res = selftest.run(3, seed=11)
    assert res["correct"] >= 2
    assert res["magnitude_within_20pct"] >= 2
    assert np.asarray(res["confusion"]).sum() == 3
    text = selftest.confusion_text(res)
    # header, a row per effect and one for 'none', the counts and the magnitudes
    assert text.splitlines()[-2].startswith("correct: ")
    assert len(text.splitlines()) == len(effects.NAMES) + 4


def test_cli_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["diagnose", "--ship", "kvlcc2", "--data", "x.csv", "--out", "o",
                     "--effects", "curent"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'current'" in err and len(err.strip().splitlines()) == 1
    assert cli.main(["diagnose", "--data", "x.csv"]) == 2


def test_wind_of_each_run_recovered() -> None:
    """Every run sails in its own wind (the weather of its day): the environment is fitted per
    run, on the training and the held-out runs alike, and each run's wind is recovered."""
    spec = load_ship("kvlcc2")
    rng = np.random.default_rng(5)
    winds = [(30.0, 20.0), (28.0, 140.0), (35.0, 250.0), (32.0, 310.0), (26.0, 75.0)]

    def hidden(speed: float, towards_deg: float) -> dict:
        a = np.radians(towards_deg)
        return {"wind": {"north_mps": speed * np.cos(a), "east_mps": speed * np.sin(a)}}

    train, hold = selftest.simulate_runs(spec, [hidden(*w) for w in winds[:3]],
                                         [hidden(*w) for w in winds[3:]], rng)
    dt, dh = selftest.prepare(spec, train, hold)
    diag = fit.diagnose(spec, dt, dh, ("wind", "current", "resistance", "compass_bias"),
                        forward_steps=1)
    assert diag.attributable and diag.singles[0].effects == ("wind",)
    best = diag.singles[0]
    # the gap is about 7 times the noise floor before; what is left is near the floor
    assert best.shrinkage(diag.base)[1] > 0.6
    assert best.p == 2 * len(hold)  # per-run parameters of the held-out runs are counted
    names = [*dt.windows.run_names, *dh.windows.run_names]
    for run, (speed, towards) in zip(names, winds, strict=True):
        v = best.run_values[run]["wind"]
        err = (np.degrees(np.arctan2(v["east_mps"], v["north_mps"])) - towards + 180) % 360 - 180
        assert abs(err) < 10.0, (run, err)
        assert np.hypot(v["north_mps"], v["east_mps"]) == pytest.approx(speed, rel=0.3)
