"""``trafficsim identify``'s pieces: data paths, working interval, starting ship, argument
checks (one located line, exit code 2), and a small run end to end that recovers a changed
ship's coefficients."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import error_line
from trafficsim import cli
from trafficsim.errors import DataError, InputError
from trafficsim.identify import command
from trafficsim.identify.preprocess import Kinematics
from trafficsim.io.results import write_csv
from trafficsim.io.trialdata import TrialData, from_arrays
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import LIBRARY_DIR, load_ship

KNOT = 1852.0 / 3600.0


def _write_csv(path: Path, columns: dict) -> Path:
    write_csv(path, columns, fmt="%.17g")  # (every digit: the file reads back exactly)
    return path


def _simple_run(path: Path, n: int = 60, east_m: float = 0.0) -> Path:
    t = np.arange(float(n))
    return _write_csv(path, {"t_s": t, "north_m": 7 * t, "east_m": east_m + 0.01 * t * t,
                             "heading_deg": 0.1 * t, "rudder_deg": t * 0 + 10,
                             "rpm": t * 0 + 80})


def test_expand_paths(tmp_path: Path) -> None:
    """Files as given, a folder as its .csv files sorted; a missing path or a folder without
    .csv files is a DataError naming the path and the flag."""
    runs = tmp_path / "runs"
    runs.mkdir()
    for name in ("b.csv", "a.csv", "notes.txt"):
        (runs / name).write_text("x")
    single = tmp_path / "z.csv"
    single.write_text("x")
    got = command.expand_paths([single, runs], "--data")
    assert got == [single, runs / "a.csv", runs / "b.csv"]
    (runs / "C.CSV").write_text("x")  # an upper-case suffix is a trial file too
    (runs / "d.csv").mkdir()  # a folder named like one is not
    assert command.expand_paths([runs], "--data") == [runs / "C.CSV", runs / "a.csv",
                                                      runs / "b.csv"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DataError, match=rf"^{empty}: folder has no .csv trial files \(given "
                                        r"with --holdout\)"):
        command.expand_paths([empty], "--holdout")
    with pytest.raises(DataError, match=r"none.csv: trial data file not found \(given with "
                                        r"--data\)"):
        command.expand_paths([tmp_path / "none.csv"], "--data")


def test_read_runs_names_and_order(tmp_path: Path) -> None:
    """Training runs first, then held-out; a run is named by its stem, with its folder where
    two files share a stem."""
    for east, folder in enumerate(("day1", "day2")):
        (tmp_path / folder).mkdir()
        _simple_run(tmp_path / folder / "zz.csv", east_m=100.0 * east)
    _simple_run(tmp_path / "turn.csv")
    train, hold, trials = command.read_runs([tmp_path / "day1", tmp_path / "turn.csv"],
                                            [tmp_path / "day2"])
    assert train == [tmp_path / "day1" / "zz.csv", tmp_path / "turn.csv"]
    assert hold == [tmp_path / "day2" / "zz.csv"]
    assert [t.name for t in trials] == ["day1/zz", "turn", "day2/zz"]


def test_a_held_out_run_the_fit_has_seen_is_refused(tmp_path: Path) -> None:
    """The same file on both sides, or one recording cut into two files, is refused naming the
    held-out file; runs that share only a few samples (the common straight approach of two
    noise-free simulated trials) are accepted."""
    t = np.arange(60.0)
    cols = {"t_s": t, "north_m": 7 * t, "east_m": 0.01 * t * t, "heading_deg": 0.1 * t,
            "rudder_deg": t * 0 + 10, "rpm": t * 0 + 80}
    whole = _write_csv(tmp_path / "whole.csv", cols)
    with pytest.raises(DataError, match=r"given as training data .* and held out") as err:
        command.read_runs([whole], [whole])
    assert err.value.path == str(whole)
    cut = _write_csv(tmp_path / "cut.csv", {k: v[:40] for k, v in cols.items()})
    with pytest.raises(DataError, match=r"shares 40 samples \(t = 0 to 39 s\) with the "
                                        r"training run .*whole.csv"):
        command.read_runs([whole], [cut])
    turned = {k: v.copy() for k, v in cols.items()}
    turned["heading_deg"][5:] += 20.0
    turned["north_m"][5:] -= 3.0
    command.read_runs([whole], [_write_csv(tmp_path / "turned.csv", turned)])


@pytest.mark.parametrize("native, given, expect", [
    # L / (20 U) = 225 / (20 * 13 kn) = 1.682 s: 0.5 s data thinned by 3 to 1.5 s
    (0.5, None, 1.5),
    (0.1, None, 1.6),   # 16 samples of 0.1 s
    (2.0, None, 2.0),   # already coarser: kept
    (0.5, 4.0, 4.0),    # given: used as it is
])
def test_working_interval(native, given, expect) -> None:
    t = np.arange(0.0, 40.0 * native, native)
    trial = from_arrays("a", {"t_s": t, "north_m": t, "east_m": t, "heading_deg": t,
                              "rudder_deg": t, "rpm": t})
    slow = from_arrays("b", {"t_s": 3 * t, "north_m": t, "east_m": t, "heading_deg": t,
                             "rudder_deg": t, "rpm": t})
    got = command.working_interval_s([slow, trial], 225.0, 13 * KNOT, given)
    assert got == pytest.approx(expect)


def test_runs_sampled_more_coarsely_than_l_over_u_are_refused() -> None:
    """L/U = 225 m / 13 kn = 33.6 s: a run sampled every 40 s is named (whether --dt-s is
    given or not), one sampled every 30 s passes."""
    def run(name: str, dt: float) -> TrialData:
        t = np.arange(0.0, 40.0 * dt, dt)
        return from_arrays(name, {"t_s": t, "north_m": t, "east_m": t, "heading_deg": t,
                                  "rudder_deg": t, "rpm": t})

    assert command.working_interval_s([run("a", 30.0)], 225.0, 13 * KNOT, None) == 30.0
    for given in (None, 35.0):
        with pytest.raises(DataError, match=r"^t_s: sampling interval 40 s \(median time "
                                            r"step\) exceeds L/U = 33.64 s of the ship"):
            command.working_interval_s([run("a", 1.0), run("b", 40.0)], 225.0, 13 * KNOT,
                                       given)


def _kin(u: list[float], rps: list[float]) -> Kinematics:
    t = np.arange(float(len(u)))
    trial = from_arrays("k", {"t_s": t, "north_m": t, "east_m": t, "heading_deg": t,
                              "rudder_deg": t, "rpm": np.array(rps) * 60.0})
    return Kinematics(trial, {"u_mps": np.array(u, float)}, {}, {})


def test_starting_spec_same_family_is_a_copy() -> None:
    base = load_ship("cargo")
    spec = command.starting_spec("nomoto", base, [])
    assert spec == base
    spec["coefficients"]["K_prime"] = 99.0
    assert base["coefficients"]["K_prime"] == 3.858


def test_starting_nomoto_from_another_family() -> None:
    """From the response bulk carrier (225 m, 13 kn = 6.688 m/s): K' = T' = 2, n3' = 0,
    rps_service = U / median(u / n) over samples ahead above 30 % of U (here u/n = 5 at
    (5, 1.0) and (6, 1.2); 1.0 m/s is too slow, rps 0 is not ahead), surge_tau = 5 L / U."""
    base = load_ship("bulk_carrier")
    runs = [_kin([1.0, 5.0, 6.0], [0.2, 1.0, 1.2]), _kin([7.0, np.nan], [0.0, 1.0])]
    spec = command.starting_spec("nomoto", base, runs)
    u = 13 * KNOT
    c = spec["coefficients"]
    assert spec["model"] == "nomoto" and spec["name"] == "bulk_carrier_nomoto"
    assert (c["K_prime"], c["T_prime"], c["n3_prime"]) == (2.0, 2.0, 0.0)
    assert c["rps_service"] == pytest.approx(u / 5.0)
    assert c["surge_tau_s"] == pytest.approx(5 * 225.0 / u)
    assert base["model"] == "response"  # the base is untouched
    with pytest.raises(DataError, match="above 30 % of the service speed"):
        command.starting_spec("nomoto", base, [_kin([1.0, 1.5], [1.0, 1.0])])


def test_starting_response_from_another_family() -> None:
    """Coefficients zero (the EKF starts there [seed 001, section 4.2]); the rudder fade speed
    is 15 % of the service speed, at most 1 m/s."""
    cargo = load_ship("cargo")  # 15 kn: 0.15 * 7.72 > 1
    spec = command.starting_spec("response", cargo, [])
    assert spec["coefficients"]["rudder_fade_speed_mps"] == 1.0
    assert all(spec["coefficients"][n] == 0.0 for n in ("a1", "b1", "c3"))
    slow = {**cargo, "service_speed_kn": 5.0}
    spec = command.starting_spec("response", slow, [])
    assert spec["coefficients"]["rudder_fade_speed_mps"] == pytest.approx(0.15 * 5 * KNOT)


@pytest.mark.parametrize("model", ["mmg", "mmg_berthing"])
def test_wind_families_need_their_own_base(model) -> None:
    with pytest.raises(InputError, match=rf"^--base: the {model} model needs an {model} base"):
        command.starting_spec(model, load_ship("cargo"), [])


def test_wind_loads() -> None:
    kv = load_ship("kvlcc2")
    assert command._has_wind_loads(kv)
    no_area = {**kv, "particulars": {**kv["particulars"], "windage_lateral_area_m2": 0.0}}
    assert not command._has_wind_loads(no_area)
    assert not command._has_wind_loads(load_ship("cargo"))


@pytest.mark.parametrize("kwargs, expect", [
    ({"model": "modular"}, "--model: unknown model 'modular'"),
    ({"model": "nomoto", "method": "gradient"}, "--method: unknown method 'gradient'"),
    ({"model": "nomoto", "method": "ekf+oe"}, "--method: the augmented EKF identifies the "
                                               "response model only"),
])
def test_identify_checks_model_and_method_first(tmp_path, kwargs, expect) -> None:
    """Checked before any file is read (the data path does not even exist)."""
    with pytest.raises(InputError) as err:
        command.identify(data=[tmp_path / "none.csv"], out=tmp_path / "o", base="cargo",
                         **kwargs)
    assert str(err.value).startswith(expect)
    assert not (tmp_path / "o").exists()


def test_identify_response_from_other_family_needs_the_ekf(tmp_path) -> None:
    run = _simple_run(tmp_path / "r.csv")
    with pytest.raises(InputError, match=r"^--method: the response model from a base ship"):
        command.identify("response", [run], tmp_path / "o", "cargo", method="oe")
    with pytest.raises(InputError, match=r"^--fit: the augmented EKF estimates all 16"):
        command.identify("response", [run], tmp_path / "o", "bulk_carrier", method="ekf",
                         fit_names=["a1", "b1"])
    assert not (tmp_path / "o").exists()


def _bad_time_csv(tmp_path: Path, t: list[float]) -> Path:
    lines = ["t_s,north_m,east_m,heading_deg,rudder_deg,rpm"]
    lines += [f"{x},{7 * i},0,{i},10,80" for i, x in enumerate(t)]
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    return tmp_path / "bad.csv"


@pytest.mark.parametrize("t, expect", [
    ([0, 1, 2, 2, 3, 4, 5], ":5: time: time must increase from row to row, got 2 after 2"),
    ([0, 1, 2, 1.5, 3, 4, 5], ":5: time: time must increase from row to row, got 1.5 after 2"),
])
def test_duplicate_or_unsorted_time_stamps(tmp_path, capsys, t, expect) -> None:
    """A repeated or backward time stamp: the file, its line (header = line 1) and the key."""
    path = _bad_time_csv(tmp_path, t)
    line = error_line(capsys, ["identify", "--model", "nomoto", "--base", "cargo", "--data",
                                path, "--out", tmp_path / "o"])
    assert line.endswith(f"{path}{expect}")


def _csv_text(tmp_path: Path, name: str, text: str) -> Path:
    (tmp_path / name).write_text(text)
    return tmp_path / name


@pytest.mark.parametrize("make, extra, expect", [
    (lambda p: _csv_text(p, "a.csv", "t_s,north_m,east_m,heading_deg,rudder_deg\n0,0,0,0,0\n"
                                     "1,1,0,0,0\n"), [],
     "a.csv:1: missing column(s) rpm"),
    (lambda p: _csv_text(p, "b.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                                     "0,0,0,0,0,80\n1,1,0,0,five,80\n"), [],
     "b.csv:3: rudder_deg: expected a number, got 'five'"),
    (lambda p: _csv_text(p, "c.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"), [],
     "c.csv: fewer than two data rows"),
    (lambda p: _csv_text(p, "d.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},0,{i},,80\n" for i in range(30))), [],
     "d.csv: no finite rudder angle sample; the replay needs the measured rudder angle"),
    (lambda p: _csv_text(p, "e.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},0,,5,80\n" for i in range(30))), [],
     "e.csv: no two consecutive samples with position and heading"),
    (lambda p: _simple_run(p / "f.csv"), ["--columns", "north_m=gps_north"],
     "f.csv:1: column 'gps_north' (to read as north_m) not in the file"),
    (lambda p: _simple_run(p / "g.csv"), ["--base", "no/such/ship.yaml"],
     "--base: ship file 'no/such/ship.yaml' not found"),
    (lambda p: _simple_run(p / "h.csv"), ["--reference", "kvlc2"],
     "--reference: unknown ship 'kvlc2' (did you mean 'kvlcc2'?)"),
    (lambda p: _simple_run(p / "i.csv"), ["--fit", "K_prime,K_prime"],
     "--fit: coefficient listed twice"),
    (lambda p: _simple_run(p / "j.csv"), ["--bounds", "K_prime=3:1"],
     "--bounds: empty bounds for K_prime"),
    (lambda p: _csv_text(p, "k.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i + 1e9 * (i > 20)},{7 * i},0,{i},5,80\n"
                                   for i in range(30))),
     [], "k.csv:23: t_s: time jumps from 20 s to 1000000021 s, a gap of 1e+09 s"),
    (lambda p: _csv_text(p, "l.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},{'inf' if i == 4 else 0},{i},5,80\n"
                                   for i in range(30))),
     [], "l.csv:6: east_m: expected a finite number (an empty cell for a missing value), "
         "got inf"),
    (lambda p: _csv_text(p, "m.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},0,{i},3000,80\n" for i in range(30))),
     [], "m.csv:2: rudder_deg: expected a rudder angle of at most 90 deg either way, got 3000"),
    (lambda p: _csv_text(p, "n.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},0,{i},5,-99999\n" for i in range(30))),
     [], "n.csv:2: rpm: expected a propeller speed of at most 2 times the engine range of the "
         "base ship 'cargo'"),
    (lambda p: _csv_text(p, "o.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},0,0,0,0,0\n" for i in range(30))),
     [], "o.csv: the ship does not move in the run: its track spans 0 m"),
    (lambda p: _csv_text(p, "q.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},0,45,5,80\n" for i in range(30))),
     [], "q.csv: K_prime, T_prime, n3_prime cannot be identified from this data"),
    (lambda p: _simple_run(p / "r.csv"), ["--dt-s", "1e-9"],
     "--dt-s: expected at least the data's sampling interval (1 s)"),
    (lambda p: _simple_run(p / "s.csv"), ["--dt-s", "1e9"],
     "--dt-s: expected at most L/U = 20.85 s"),
    (lambda p: _simple_run(p / "t.csv", n=25), ["--dt-s", "9"],
     "--dt-s: an interval of 9 s leaves 3 sample(s) of run 't' (24 s long)"),
    (lambda p: _simple_run(p / "u.csv"), ["--horizon-s", "1e9"],
     "--horizon-s: expected at most the longest run's duration (59 s"),
    (lambda p: _simple_run(p / "v.csv"), ["--horizon-s", "1e-9"],
     "--horizon-s: expected at least two working sampling intervals (2 s)"),
    (lambda p: _simple_run(p / "w.csv"), ["--wind", "ignore"],
     "--wind: applies only to models with wind loads (mmg, mmg_berthing); the nomoto model "
     "has none"),
    (lambda p: _simple_run(p / "x.csv"), ["--wind", "ignore", "--model", "mmg", "--base",
                                          "kvlcc2"],
     "--wind: applies only when the model has wind loads and the runs carry wind; the runs "
     "carry no wind"),
    (lambda p: _csv_text(p, "blank.csv", "\n\n"), [],
     "blank.csv:1: empty file (blank lines only); expected a header row"),
    # cargo: L/U = 160.93 m / 15 kn = 20.85 s; one sample every 25 s is coarser
    (lambda p: _csv_text(p, "y.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{25 * i},{175 * i},0,{i},{5 * (i > 3)},80\n"
                                   for i in range(30))), [],
     "y.csv: t_s: sampling interval 25 s (median time step) exceeds L/U = 20.85 s of the ship "
     "(160.93 m at 15 kn): more than a ship length per sample, so it cannot identify or "
     "replay the ship's motion"),
    (lambda p: _simple_run(p / "z.csv"), ["--bounds", "K_prime=-5:-1"],
     "--bounds: K_prime=-5:-1 reaches outside the physical range of K_prime, which must be "
     "> 0 (rudder gain; positive rudder turns to starboard), got -5"),
    (lambda p: _simple_run(p / "z2.csv"), ["--bounds", "K_prime=0:5"],
     "--bounds: K_prime=0:5 reaches outside the physical range of K_prime, which must be > 0"),
    # rpm negated: the ship makes 7 m/s ahead on an astern propeller throughout
    (lambda p: _csv_text(p, "neg.csv", "t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
                         + "".join(f"{i},{7 * i},0,{0.5 * i},{10 * (i > 3)},-80\n"
                                   for i in range(60))), [],
     ": rpm: rps_service cannot be identified from this data: the ship makes way ahead above "
     "30 % of its service speed (2.31 m/s) only with the propeller stopped or astern"),
])
def test_bad_input_is_one_located_line(tmp_path, capsys, make, extra, expect) -> None:
    path = make(tmp_path)
    argv = ["identify", "--model", "nomoto", "--base", "cargo", "--data", path, "--out",
            tmp_path / "o", *extra]
    if "--base" in extra:
        argv[3:5] = []
    if "--model" in extra:
        argv[1:3] = []
    line = error_line(capsys, argv)
    assert expect in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("extra, expect", [
    (["--max-nfev", "0"], "expected a positive number, got '0'"),
    (["--dt-s", "nan"], "expected a positive number, got 'nan'"),
    (["--horizon-s", "-5"], "expected a positive number, got '-5'"),
    (["--columns", "north_m"], "expected NAME=COLUMN,... got 'north_m'"),
    (["--fit", ","], "expected coefficient names separated by commas"),
    (["--bounds", "K_prime=1:nan"], "expected NAME=LOW:HIGH"),
    (["--wind", "always"], "invalid choice: 'always'"),
    (["--model", "mmgg"], "invalid choice: 'mmgg'"),
])
def test_bad_flags_exit_2_in_one_line(tmp_path, capsys, extra, expect) -> None:
    """argparse-level errors: SystemExit(2) with one line naming the problem."""
    argv = ["identify", "--model", "nomoto", "--base", "cargo", "--data", tmp_path / "x.csv",
            "--out", tmp_path / "o", *extra]
    with pytest.raises(SystemExit) as exc:
        cli.main([str(a) for a in argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0]


@pytest.fixture(scope="module")
def cargo_zigzag(tmp_path_factory) -> tuple[Path, Path]:
    """A noise-free 20/20 zig-zag of the cargo ship as a trial CSV, and a base ship file that
    is the cargo ship with K' and T' 20-25 % off."""
    root = tmp_path_factory.mktemp("idcmd")
    track, _ = manoeuvres.zigzag(load_ship("cargo"), 20.0, dt=1.0)
    cols = from_arrays("zz", track).to_csv_columns()
    data = _write_csv(root / "zz.csv", cols)
    text = (LIBRARY_DIR / "cargo.yaml").read_text()
    assert "  K_prime: 3.858\n" in text and "  T_prime: 5.141\n" in text
    base = root / "cargo_off.yaml"
    base.write_text(text.replace("  K_prime: 3.858\n", "  K_prime: 3.0\n").replace(
        "  T_prime: 5.141\n", "  T_prime: 6.4\n").replace("name: cargo\n", "name: cargo_off\n"))
    return data, base


def test_end_to_end_recovers_the_changed_coefficients(cargo_zigzag, tmp_path, capsys) -> None:
    """K' and T' fitted from the true ship's zig-zag come back to the cargo ship's values
    (within 1 %); the flags reach the report; ship file, plot and reports are written and
    agree with each other."""
    data, base = cargo_zigzag
    out = tmp_path / "o"
    rc = cli.main(["identify", "--model", "nomoto", "--base", str(base), "--data", str(data),
                   "--out", str(out), "--fit", "K_prime,T_prime", "--max-nfev", "30",
                   "--name", "cargo_found", "--horizon-s", "150", "--sigma-pos-m", "0.05",
                   "--sigma-heading-deg", "0.02"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "K_prime" in captured.out and f"results: {out / 'ship.yaml'}" in captured.out
    report = json.loads((out / "report.json").read_text())
    assert report["coefficients"]["K_prime"] == pytest.approx(3.858, rel=0.01)
    assert report["coefficients"]["T_prime"] == pytest.approx(5.141, rel=0.01)
    assert report["method"] == "oe" and report["ekf"] is None
    assert report["validation"]["horizon_s"] == 150.0
    # the smoother's noise as given on the command line (heading converted to radians)
    smoother = report["preprocessing"]["smoother"]
    assert smoother["sigma_pos_m"] == 0.05
    assert smoother["sigma_heading_rad"] == pytest.approx(np.radians(0.02))
    assert report["preprocessing"]["dt_s"] == 1.0  # L / (20 U) = 1.04 s: 1 s data kept
    ship = load_ship(str(out / "ship.yaml"))
    assert ship["name"] == "cargo_found"
    for name in ("K_prime", "T_prime"):
        assert ship["coefficients"][name] == pytest.approx(report["coefficients"][name],
                                                           rel=1e-9)
    assert ship["coefficients"]["n3_prime"] == 72.06  # not fitted: from the base
    assert (out / "convergence.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "report.md").stat().st_size > 0
    pred = report["validation"]["prediction"]["training"]
    assert pred["identified"]["all"]["end_position_rms_m"] < pred["start"]["all"][
        "end_position_rms_m"]


def test_a_fit_no_ship_file_holds_names_the_data_and_writes_nothing(cargo_zigzag, tmp_path,
                                                                    capsys) -> None:
    """The cargo ship's zig-zag logged with 1.5 times its propeller speed: the fitted
    propeller speed at the service speed (2 rev/s) is beyond the base ship's engine (rps_max
    1.78): the error names the data file and its rpm column, not the ship file, which is not
    written."""
    data, _ = cargo_zigzag
    text = data.read_text().splitlines()
    rpm = text[0].split(",").index("rpm")
    rows = [row.split(",") for row in text[1:]]
    for row in rows:
        row[rpm] = repr(1.5 * float(row[rpm]))
    fast = tmp_path / "fast.csv"
    fast.write_text("\n".join([text[0], *(",".join(r) for r in rows)]) + "\n")
    out = tmp_path / "o"
    line = error_line(capsys, ["identify", "--model", "nomoto", "--base", "cargo", "--data",
                                fast, "--out", out, "--fit", "rps_service", "--max-nfev", "10"])
    assert f"error: {fast}: rpm: the propeller speed at the service speed fitted from this " \
           "data (rps_service 2" in line
    assert "beyond the engine of the base ship 'cargo' (--base; rps_max 1.7778 rev/s)" in line
    assert "ship.yaml" not in line and not out.exists()


def test_check_fitted_names_the_data_not_the_ship_file(tmp_path) -> None:
    """A fitted coefficient outside the range a ship file takes: one run is named by its file,
    several by --data; a valid ship passes."""
    run = command.read_runs([_simple_run(tmp_path / "r.csv")], [])[2]
    spec = load_ship("cargo")
    command.check_fitted(spec, spec, run)
    bad = {**spec, "coefficients": {**spec["coefficients"], "T_prime": -2.0}}
    with pytest.raises(InputError) as err:
        command.check_fitted(bad, spec, run)
    assert str(err.value).startswith(
        f"{tmp_path / 'r.csv'}: the coefficients fitted from this data make no valid ship "
        "(coefficients.T_prime: must be > 0")
    with pytest.raises(InputError) as err:
        command.check_fitted(bad, spec, run * 2)
    assert err.value.key == "--data" and err.value.path is None
    assert "fitted from the 2 training runs" in str(err.value)


def test_an_output_path_that_is_a_file(cargo_zigzag, tmp_path, capsys) -> None:
    data, base = cargo_zigzag
    blocker = tmp_path / "o"
    blocker.write_text("not a folder")
    line = error_line(capsys, ["identify", "--model", "nomoto", "--base", base, "--data",
                                data, "--out", blocker, "--fit", "K_prime", "--max-nfev", "3"])
    assert str(blocker) in line and "File exists" in line
