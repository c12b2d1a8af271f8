"""``trafficsim diagnose``'s command layer: base ship, candidate and refit lists, the logged-wind
confirmation, the self-test's files, argument errors (one line, exit code 2), and one small
run end to end on runs sailed in a known wind."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tests.conftest import error_line
from trafficsim import cli, effects
from trafficsim.diagnose import command, selftest
from trafficsim.errors import InputError, ShipLibraryError
from trafficsim.identify.parameters import DEFAULT_FIT
from trafficsim.io.results import write_csv
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships.library import load_ship


def _write_csv(path: Path, columns: dict) -> Path:
    write_csv(path, columns, fmt="%.17g")  # (every digit: the file reads back exactly)
    return path


def test_load_base() -> None:
    """A library name gives the ship; an unknown one names the flag with a suggestion; a
    folder is read as an MMG parameter folder (whose errors name the missing file)."""
    spec = command.load_base("kvlcc2")
    assert spec["model"] == "mmg" and spec["name"] == "kvlcc2"
    spec["coefficients"]["R0"] = 1.0
    assert command.load_base("kvlcc2")["coefficients"]["R0"] != 1.0
    with pytest.raises(ShipLibraryError, match=r"^--ship: unknown ship 'kvlc2' \(did you "
                                               r"mean 'kvlcc2'\?\)"):
        command.load_base("kvlc2")


def test_load_base_folder_without_mmg_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"principal_particulars\.csv|MMG_params\.csv"):
        command.load_base(str(tmp_path))


def test_candidates() -> None:
    """The library's effects that act on the ship by default (no hull effects for a nomoto
    ship); given ones each once and acting on it, else an error under --effects."""
    kv, cargo = load_ship("kvlcc2"), load_ship("cargo")
    assert command._candidates(None, kv) == effects.NAMES
    assert command._candidates([], kv) == effects.NAMES
    hull = ("resistance", "propeller_asymmetry", "shallow_water")
    assert command._candidates(None, cargo) == tuple(n for n in effects.NAMES if n not in hull)
    assert command._candidates(["wind", "current"], kv) == ("wind", "current")
    with pytest.raises(InputError, match=r"^--effects: unknown effect 'curent' \(did "
                                         r"you mean 'current'\?\)"):
        command._candidates(["current", "curent"], kv)
    with pytest.raises(InputError, match=r"^--effects: effect 'current' listed twice in "
                                         r"current wind current$"):
        command._candidates(["current", "wind", "current"], kv)
    with pytest.raises(InputError, match=r"^--effects: effect 'resistance' acts on the hull "
                                         r"model of the mmg and mmg_berthing families; ship "
                                         r"'cargo' is a 'nomoto' model"):
        command._candidates(["wind", "resistance"], cargo)


def test_refit_names() -> None:
    """``default``: identify's subset of the family; a comma list (spaces ignored) or a
    sequence as given; an unknown name is reported under --refit."""
    kv = load_ship("kvlcc2")
    assert command._refit(kv, None) == () and command._refit(kv, "") == ()
    assert command._refit(kv, "default") == DEFAULT_FIT["mmg"]
    assert command._refit(kv, " N_r, Y_v ,") == ("N_r", "Y_v")
    assert command._refit(kv, ["R0"]) == ("R0",)
    with pytest.raises(InputError, match="expected coefficient names separated by commas"):
        command._refit(kv, " , ")  # commas but no name: a slip, not 'refit nothing'
    with pytest.raises(InputError) as err:
        command._refit(kv, "N_rr")
    assert err.value.key == "--refit" and "unknown coefficient 'N_rr'" in str(err.value)
    assert str(err.value).startswith("--refit: ")


def _wind_trial(speed, from_deg, name="w"):
    t = np.arange(len(speed), dtype=float)
    return from_arrays(name, {"t_s": t, "north_m": t, "east_m": t, "heading_deg": t,
                              "rudder_deg": t, "rpm": t, "wind_speed_mps": speed,
                              "wind_from_deg": from_deg})


def test_logged_wind_by_hand() -> None:
    """Wind from east (90 deg) at 10 and 20 m/s: the air moves towards west, mean velocity
    (0, -15); mean speed 15, RMS sqrt((100 + 400) / 2); NaN samples ignored."""
    trial = _wind_trial([10.0, 20.0, np.nan, 5.0], [90.0, 90.0, 90.0, np.nan])
    n, e, mean, rms = command.logged_wind(trial)
    assert n == pytest.approx(0.0, abs=1e-12) and e == pytest.approx(-15.0)
    assert mean == pytest.approx(15.0) and rms == pytest.approx(np.sqrt(250.0))
    n, e, _, _ = command.logged_wind(_wind_trial([8.0, 8.0], [0.0, 0.0]))
    assert (n, e) == pytest.approx((-8.0, 0.0))  # from north: towards south


def _diag(run_values: dict, effect: str = "wind"):
    return SimpleNamespace(singles=[SimpleNamespace(effects=(effect,), run_values=run_values),
                                    SimpleNamespace(effects=("resistance",), run_values={})])


def _runs(*trials):
    return [SimpleNamespace(name=t.name, trial=t) for t in trials]


def test_confirmation_by_hand() -> None:
    """Logged wind from 350 deg (air towards 170 deg) and from 10 deg (towards 190 deg);
    fitted air velocities towards 190 deg and 170 deg at 2 and 1/2 the speed: direction errors
    +20 and -20 deg (wrapped across 180, not 340), speed ratios 2 and 0.5."""
    a = _wind_trial([10.0, 10.0], [350.0, 350.0], "a")
    b = _wind_trial([10.0, 10.0], [10.0, 10.0], "b")
    calm = from_arrays("c", {"t_s": [0.0, 1.0], "north_m": [0, 1], "east_m": [0, 0],
                             "heading_deg": [0, 0], "rudder_deg": [0, 0], "rpm": [0, 0]})

    def towards(deg, speed):
        r = np.radians(deg)
        return {"wind": {"north_mps": speed * np.cos(r), "east_mps": speed * np.sin(r)}}

    diag = _diag({"a": towards(190.0, 20.0), "b": towards(170.0, 5.0)})
    conf = command.confirmation(diag, _runs(a, b, calm), ["training", "holdout", "training"])
    rows = {r["run"]: r for r in conf["wind"]["runs"]}
    assert set(rows) == {"a", "b"}  # the calm run has no logged wind
    assert rows["a"]["direction_error_deg"] == pytest.approx(20.0)
    assert rows["b"]["direction_error_deg"] == pytest.approx(-20.0)
    assert rows["a"]["speed_ratio"] == pytest.approx(2.0)
    assert rows["b"]["speed_ratio"] == pytest.approx(0.5)
    assert rows["a"]["logged_towards_deg"] == pytest.approx(170.0)
    assert rows["a"]["fitted_towards_deg"] == pytest.approx(190.0)
    assert rows["b"]["role"] == "holdout"
    assert conf["wind"]["median_abs_direction_error_deg"] == pytest.approx(20.0)
    assert conf["wind"]["runs_within_30_deg"] == 2 and conf["wind"]["n_runs"] == 2
    assert conf["wind"]["median_speed_ratio"] == pytest.approx(1.25)
    assert "resistance" not in conf  # not a per-run environment
    assert "direction within 30 deg on 2 of 2 runs" in conf["text"]


def test_confirmation_absent_without_logged_wind_or_environment_effect() -> None:
    calm = from_arrays("c", {"t_s": [0.0, 1.0], "north_m": [0, 1], "east_m": [0, 0],
                             "heading_deg": [0, 0], "rudder_deg": [0, 0], "rpm": [0, 0]})
    assert command.confirmation(_diag({}), _runs(calm), ["training"]) is None
    a = _wind_trial([10.0, 10.0], [0.0, 0.0], "a")
    only_hull = SimpleNamespace(singles=[SimpleNamespace(effects=("resistance",),
                                                         run_values={})])
    assert command.confirmation(only_hull, _runs(a), ["training"]) is None
    one = command.confirmation(_diag({"a": {"wind": {"north_mps": -9.0, "east_mps": 0.0}}}),
                               _runs(a), ["training"])
    assert np.isnan(one["wind"]["component_correlation"])  # one run: no correlation


def test_confirmation_skips_a_run_without_any_wind_reading() -> None:
    """A run whose wind columns hold no value (a failed anemometer) has no logged wind: it is
    left out like a run without the columns, and the other run's comparison stands."""
    empty = _wind_trial([np.nan, np.nan], [np.nan, np.nan], "empty")
    good = _wind_trial([10.0, 10.0], [0.0, 0.0], "good")
    diag = _diag({"empty": {"wind": {"north_mps": 3.0, "east_mps": 0.0}},
                  "good": {"wind": {"north_mps": -10.0, "east_mps": 0.0}}})
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        conf = command.confirmation(diag, _runs(empty, good), ["training", "training"])
    assert conf["wind"]["n_runs"] == 1
    assert conf["wind"]["median_abs_direction_error_deg"] == pytest.approx(0.0, abs=1e-9)
    assert conf["wind"]["median_speed_ratio"] == pytest.approx(1.0)


def test_self_test_writes_its_result_and_reports_progress(tmp_path, monkeypatch, capsys) -> None:
    """``self_test`` passes N and the seed through, prints one progress line per trial and
    writes ``selftest.json`` (NaN as null) into a folder it creates."""
    seen = {}
    trial = {"hidden": "wind", "first_ranked": "current", "magnitude_fitted": 0.5,
             "magnitude_true": 0.4, "seconds": 1.25}

    def fake_run(n, seed, progress=None):
        seen.update(n=n, seed=seed, progress=progress)
        for i in range(n):
            progress(i, trial)
        return {"n": n, "accuracy": float("nan"), "trials": [trial] * n}

    monkeypatch.setattr(selftest, "run", fake_run)
    res = command.self_test(2, tmp_path / "a" / "b", seed=7)
    assert seen["n"] == 2 and seen["seed"] == 7 and res["n"] == 2
    err = capsys.readouterr().err.splitlines()
    assert err == ["  trial 1/2: hidden wind, first-ranked current, magnitude 0.5 (true 0.4), "
                   "1.2 s", "  trial 2/2: hidden wind, first-ranked current, magnitude 0.5 "
                   "(true 0.4), 1.2 s"]
    saved = json.loads((tmp_path / "a" / "b" / "selftest.json").read_text())
    assert saved["n"] == 2 and saved["accuracy"] is None
    trial.clear()  # a trial that hides nothing has no magnitude
    trial.update(hidden="none", first_ranked="not attributable", seconds=3.0)
    assert command.self_test(1, None)["n"] == 1
    assert capsys.readouterr().err == ("  trial 1/1: hidden none, first-ranked not attributable, "
                                       "3.0 s\n")
    seen.clear()
    command.self_test(0, None, progress=False)
    assert seen["progress"] is None and capsys.readouterr().err == ""
    assert not (tmp_path / "selftest.json").exists()


@pytest.mark.parametrize("argv, expect", [
    (["diagnose", "--data", "x.csv", "--out", "o"], "--ship: diagnose needs --ship, --data "
                                                    "and --out (or --self-test N)"),
    (["diagnose", "--ship", "kvlcc2", "--out", "o"], "diagnose needs --ship, --data and --out"),
    (["diagnose", "--ship", "kvlcc2", "--data", "x.csv"], "diagnose needs --ship"),
    (["diagnose", "--ship", "kvlcc2", "--data", "x.csv", "--out", "o", "--seed", "3"],
     "--seed: applies only with --self-test"),
    (["diagnose", "--self-test", "2", "--ship", "kvlcc2"],
     "--ship: applies only without --self-test"),
    (["diagnose", "--self-test", "2", "--refit"], "--refit: applies only without --self-test"),
    (["diagnose", "--ship", "kvlcc2", "--data", "x.csv", "--out", "o", "--refit", "N_rr"],
     "--refit: unknown coefficient 'N_rr'"),
    (["diagnose", "--ship", "kvlcc2", "--data", "x.csv", "--out", "o", "--effects", "wnd"],
     "--effects: unknown effect 'wnd' (did you mean 'wind'?)"),
    (["diagnose", "--ship", "kvlcc2", "--data", "x.csv", "--out", "o", "--effects", "wind",
      "wind"], "--effects: effect 'wind' listed twice in wind wind"),
    (["diagnose", "--ship", "cargo", "--data", "x.csv", "--out", "o", "--effects",
      "shallow_water"], "--effects: effect 'shallow_water' acts on the hull model"),
    (["diagnose", "--ship", "kvlc2", "--data", "x.csv", "--out", "o"],
     "--ship: unknown ship 'kvlc2'"),
])
def test_cli_argument_errors(capsys, argv, expect) -> None:
    assert expect in error_line(capsys, argv)


def test_cli_missing_data_file(tmp_path, capsys) -> None:
    line = error_line(capsys, ["diagnose", "--ship", "kvlcc2", "--data", tmp_path / "none.csv",
                                "--out", tmp_path / "o"])
    assert "none.csv: trial data file not found (given with --data)" in line
    assert not (tmp_path / "o").exists()


def test_cli_blank_or_coarse_data_names_the_file(tmp_path, capsys) -> None:
    """A file of blank lines is an empty file; a run sampled every 50 s is coarser than the
    KVLCC2's L/U (40.13 s) and cannot be replayed: both one line naming the file, exit 2."""
    blank = tmp_path / "blank.csv"
    blank.write_text("\n")
    line = error_line(capsys, ["diagnose", "--ship", "kvlcc2", "--data", blank, "--out",
                                tmp_path / "o"])
    assert line.endswith(f"{blank}:1: empty file (blank lines only); expected a header row")
    t = np.arange(40.0) * 50.0
    coarse = _write_csv(tmp_path / "coarse.csv", {
        "t_s": t, "north_m": 7 * t, "east_m": 0.01 * t * t, "heading_deg": 0.1 * t,
        "rudder_deg": 10.0 * (t > 100), "rpm": t * 0 + 60})
    line = error_line(capsys, ["diagnose", "--ship", "kvlcc2", "--data", coarse, "--out",
                                tmp_path / "o", "--effects", "current"])
    assert (f"{coarse}: t_s: sampling interval 50 s (median time step) exceeds L/U = 40.13 s "
            "of the ship (320 m at 15.5 kn)") in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value", ["0", "-1", "two"])
def test_cli_bad_self_test_count(capsys, value) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["diagnose", "--self-test", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--self-test" in err[0]


def test_too_little_data_to_hold_out(tmp_path, capsys) -> None:
    """One short run and a horizon as long as it: one window, nothing to hold out."""
    t = np.arange(60.0)
    path = _write_csv(tmp_path / "short.csv", {
        "t_s": t, "north_m": 7 * t, "east_m": 0.01 * t * t, "heading_deg": 0.1 * t,
        "rudder_deg": t * 0 + 10, "rpm": t * 0 + 60})
    line = error_line(capsys, ["diagnose", "--ship", "kvlcc2", "--data", path, "--out",
                                tmp_path / "o", "--horizon-s", "59", "--effects", "current"])
    assert "--data: too little data to hold any window out" in line


@pytest.mark.parametrize("gap, extra, expect", [
    (True, [], "run.csv:33: t_s: time jumps from 30 s to 1000000031 s"),
    (False, ["--dt-s", "1e9"], "--dt-s: expected at most L/U = 40.13 s"),
    (False, ["--dt-s", "1e-9"], "--dt-s: expected at least the data's sampling interval (1 s)"),
    (False, ["--horizon-s", "1e9"], "--horizon-s: expected at most the longest run's duration "
                                    "(59 s"),
    (False, ["--horizon-s", "1e-9"], "--horizon-s: expected at least two working sampling "
                                     "intervals"),
])
def test_cli_bad_data_or_interval_names_the_file_or_flag(tmp_path, capsys, gap, extra,
                                                         expect) -> None:
    """A time gap the smoother cannot bridge is located in the file (it once took the
    machine's memory); a working interval or horizon out of range names its flag, not the
    data."""
    t = np.arange(60.0)
    path = _write_csv(tmp_path / "run.csv", {
        "t_s": t + 1e9 * (t > 30) * gap, "north_m": 7 * t, "east_m": 0.01 * t * t,
        "heading_deg": 0.1 * t, "rudder_deg": 10.0 * (t > 5), "rpm": t * 0 + 60})
    line = error_line(capsys, ["diagnose", "--ship", "kvlcc2", "--data", path, "--out",
                                tmp_path / "o", "--effects", "current", *extra])
    assert expect in line
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def windy_runs(tmp_path_factory) -> tuple[Path, list[Path], float]:
    """Two KVLCC2 runs (zig-zag 10/10 and a 35 deg turn) sailed in a 30 m/s wind from 20 deg,
    measured with the self-test's noise, the wind logged in the CSV files."""
    root = tmp_path_factory.mktemp("diagcmd")
    spec = load_ship("kvlcc2")
    from_deg = 20.0
    towards = np.radians(from_deg + 180.0)
    hidden = {"wind": {"north_mps": 30.0 * np.cos(towards), "east_mps": 30.0 * np.sin(towards)}}
    train, _ = selftest.simulate_runs(spec, [hidden] * 3, [hidden] * 2,
                                      np.random.default_rng(1))
    paths = []
    for trial in (train[0], train[2]):
        cols = trial.to_csv_columns()
        cols["wind_speed_mps"] = np.full(trial.n, 30.0)
        cols["wind_from_deg"] = np.full(trial.n, from_deg)
        paths.append(_write_csv(root / f"{trial.name}.csv", cols))
    return root, paths, from_deg


def test_end_to_end_finds_the_wind_and_confirms_it(windy_runs, tmp_path, capsys) -> None:
    """Wind ranked first; the fitted per-run wind points within 15 deg of the logged one
    (the confirmation, which reads the logged wind only after the fit); reports written."""
    _, paths, _ = windy_runs
    out = tmp_path / "out"
    rc = cli.main(["diagnose", "--ship", "kvlcc2", "--data", *map(str, paths), "--out",
                   str(out), "--effects", "wind", "current"])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    assert "1. wind" in printed.out and f"results: {out / 'report.md'}" in printed.out
    assert "  wind (1/2): held-out gap " in printed.err  # progress as each fit ends
    rep = json.loads((out / "report.json").read_text())
    assert rep["ranking"][0]["effect"] == "wind"
    assert rep["candidates"] == ["wind", "current"] and rep["refit"] == []
    assert rep["data"]["holdout"] == [] and rep["data"]["holdout_split"].startswith("alternate")
    conf = rep["confirmation"]["wind"]
    assert conf["n_runs"] == 2
    for row in conf["runs"]:
        assert abs(row["direction_error_deg"]) < 15.0
        assert row["logged_towards_deg"] == pytest.approx(200.0)
        assert row["role"] == "training and holdout"
    md = (out / "report.md").read_text()
    assert rep["data"]["ship"] == "kvlcc2" and "- Ship: kvlcc2" in md
    assert f"- Training runs: {paths[0].name}, {paths[1].name}" in md
    assert "- Held out: alternate windows of the same runs (no --holdout given)" in md
    assert (f"- Windows: {rep['windows']['train']} training, {rep['windows']['holdout']} held "
            "out,") in md
    assert "- Candidates: wind, current" in md and "Give `--holdout` runs for that." in md
    assert rep["attributable"] and rep["verdict"].endswith(  # says what was held out
        "(held out: alternate windows of the same runs, not runs the fit has not seen)")
    assert (out / "residuals_by_phase.png").read_bytes()[:4] == b"\x89PNG"
