"""trial.py: a standard manoeuvre written as trial data and indices, its checks reported under
the command-line flags, and the instrument columns of ``--sensors``."""

import json
import math
import re

import numpy as np
import pytest

from trafficsim.errors import InputError
from trafficsim.ships import base, manoeuvres
from trafficsim.ships.library import LIBRARY_DIR, load_ship
from trafficsim.trial import SP_RANGE_M2PS3, run_trial, sensor_columns
from trafficsim.units import KN

TRACK_COLUMNS = ["t_s", "north_m", "east_m", "heading_deg", "rudder_deg", "rpm", "u_mps",
                 "v_mps", "r_degps", "sog_kn", "cog_deg"]
SENSOR_COLUMNS = ["gnss_fix_north_m", "gnss_fix_east_m", "gnss_north_m", "gnss_east_m",
                  "gnss_sog_kn", "gnss_cog_deg", "compass_heading_deg", "est_north_m",
                  "est_east_m", "est_heading_deg", "est_sog_kn", "est_cog_deg", "est_r_degps"]


def _read_csv(path):
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    data = np.array([[float(c) for c in row.split(",")] for row in lines[1:]])
    return header, {h: data[:, i] for i, h in enumerate(header)}


def _trial(tmp_path, ship, manoeuvre, rudder=None, heading=None, port=False, speed=None,
           dt=None, **kw):
    return run_trial(ship, manoeuvre, rudder, heading, port, speed, dt, tmp_path, **kw)


def _assert_csv_holds(col, track):
    for key in TRACK_COLUMNS:  # written to 6 significant digits
        np.testing.assert_allclose(col[key], track[key], rtol=1e-5, atol=1e-9, err_msg=key)


# --- manoeuvres and files --------------------------------------------------------------------


def test_turning_trial_writes_the_manoeuvres_track_and_indices(tmp_path):
    indices, criteria = _trial(tmp_path, "container", "turning", rudder=20.0)
    track, expected = manoeuvres.turning_circle(load_ship("container"), 20.0)
    header, col = _read_csv(tmp_path / "trial.csv")
    assert header == TRACK_COLUMNS
    _assert_csv_holds(col, track)
    assert indices == expected
    stored = json.loads((tmp_path / "indices.json").read_text())
    assert (stored["ship"], stored["manoeuvre"]) == ("container", "turning")
    assert stored["indices"] == pytest.approx(expected)
    assert stored["imo_msc137"] == criteria
    advance = criteria["advance_L"]
    assert advance["value"] == pytest.approx(expected["advance_m"] / 175.0)
    assert advance["limit"] == 4.5 and advance["pass"] == (advance["value"] <= 4.5)
    assert criteria["tactical_diameter_L"]["value"] == pytest.approx(
        expected["tactical_diameter_m"] / 175.0)


def test_port_turn_puts_the_rudder_to_port(tmp_path):
    indices, _ = _trial(tmp_path, "container", "turning", rudder=20.0, port=True)
    track, expected = manoeuvres.turning_circle(load_ship("container"), -20.0)
    assert indices == expected and indices["rudder_deg"] == -20.0
    _, col = _read_csv(tmp_path / "trial.csv")
    _assert_csv_holds(col, track)
    assert col["rudder_deg"].min() == pytest.approx(-20.0, abs=1e-3)
    assert col["rudder_deg"].max() <= 1e-9
    assert col["east_m"][len(col["east_m"]) // 8] < 0.0  # from north a port turn goes west


def test_turning_rudder_defaults_to_35_deg(tmp_path):
    indices, _ = _trial(tmp_path, "container", "turning")
    assert indices["rudder_deg"] == 35.0
    _, col = _read_csv(tmp_path / "trial.csv")
    assert col["rudder_deg"].max() == pytest.approx(35.0, abs=1e-3)


@pytest.mark.parametrize("rudder, heading, expect_rudder, expect_heading, criteria", [
    (None, None, 10.0, 10.0, ["initial_turning_distance_L", "first_overshoot_deg",
                              "second_overshoot_deg"]),
    (20.0, None, 20.0, 20.0, ["first_overshoot_deg"]),
    (20.0, 5.0, 20.0, 5.0, []),  # IMO sets limits for 10/10 and 20/20 only
])
def test_zigzag_defaults_to_10_10_and_the_heading_to_the_rudder_angle(
        tmp_path, rudder, heading, expect_rudder, expect_heading, criteria):
    indices, crit = _trial(tmp_path, "container", "zigzag", rudder=rudder, heading=heading)
    assert (indices["rudder_deg"], indices["heading_deg"]) == (expect_rudder, expect_heading)
    assert list(crit) == criteria
    _, col = _read_csv(tmp_path / "trial.csv")
    assert col["rudder_deg"].max() == pytest.approx(expect_rudder, abs=1e-3)
    assert col["rudder_deg"].min() == pytest.approx(-expect_rudder, abs=1e-3)
    if "first_overshoot_deg" in crit:
        limit = 25.0 if expect_rudder == 20.0 else float(np.clip(
            5.0 + 0.5 * 175.0 / (indices["approach_speed_kn"] * KN), 10.0, 20.0))
        assert crit["first_overshoot_deg"]["limit"] == pytest.approx(limit)
        assert crit["first_overshoot_deg"]["value"] == indices["first_overshoot_deg"]


def test_crash_stop_trial_ends_dead_in_the_water(tmp_path):
    indices, criteria = _trial(tmp_path, "cargo", "crash-stop")
    _, col = _read_csv(tmp_path / "trial.csv")
    assert col["t_s"][-1] == pytest.approx(indices["time_to_stop_s"], rel=1e-5)
    assert col["u_mps"][-1] <= 1e-5 < col["u_mps"][-2]
    assert np.all(col["rudder_deg"] == 0.0)
    spec = load_ship("cargo")
    astern = base.Actuators.from_specs([spec]).rps_min[0]
    assert col["rpm"][-1] == pytest.approx(60.0 * astern, rel=0.05)  # engine gone full astern
    path = np.sum(np.hypot(np.diff(col["north_m"]), np.diff(col["east_m"])))
    assert indices["track_reach_m"] == pytest.approx(path, rel=1e-4)
    reach = criteria["track_reach_L"]
    assert reach["value"] == pytest.approx(path / 160.93, rel=1e-4) and reach["limit"] == 15.0
    stored = json.loads((tmp_path / "indices.json").read_text())
    assert (stored["ship"], stored["manoeuvre"]) == ("cargo", "crash-stop")


def test_port_zigzag_trial_puts_the_first_rudder_to_port(tmp_path):
    """``--port`` on a zig-zag: the first rudder order is to port (negative), the log mirrors
    the starboard-first trial, and the indices and IMO verdicts are those of that trial."""
    stbd, crit_s = _trial(tmp_path / "s", "container", "zigzag")
    port, crit_p = _trial(tmp_path / "p", "container", "zigzag", port=True)
    _, col_s = _read_csv(tmp_path / "s" / "trial.csv")
    _, col_p = _read_csv(tmp_path / "p" / "trial.csv")
    first = np.flatnonzero(col_p["rudder_deg"] != 0.0)[0]
    assert col_p["rudder_deg"][first] < 0.0
    np.testing.assert_allclose(col_p["rudder_deg"], -col_s["rudder_deg"], atol=1e-9)
    assert port["rudder_deg"] == -10.0
    for key in ("initial_turning_time_s", "first_overshoot_deg", "second_overshoot_deg"):
        assert port[key] == pytest.approx(stbd[key], rel=1e-6)
    assert {k: v["pass"] for k, v in crit_p.items()} == {k: v["pass"] for k, v in crit_s.items()}


# --- checks under their flags ----------------------------------------------------------------


@pytest.mark.parametrize("manoeuvre, kw, flag, message", [
    ("turning", {"speed": 100.0}, "--speed-kn",
     "expected at most 2 times the service speed of 'container' (22 kn), got 100 kn"),
    ("crash-stop", {"speed": 44.5}, "--speed-kn",
     "expected at most 2 times the service speed of 'container' (22 kn), got 44.5 kn"),
    ("turning", {"rudder": 40.0}, "--rudder-deg",
     "expected at most the ship's rudder limit, 35 deg; got 40"),
    ("turning", {"rudder": 35.5, "port": True}, "--rudder-deg",
     "expected at most the ship's rudder limit, 35 deg; got 35.5"),
    ("zigzag", {"rudder": 36.0}, "--rudder-deg",
     "expected at most the ship's rudder limit, 35 deg; got 36"),
    ("crash-stop", {"dt": 0.0005}, "--dt-s", "expected a time step from 0.001 to 60 s, got 0.0005"),
    ("zigzag", {"dt": 61.0}, "--dt-s", "expected a time step from 0.001 to 60 s, got 61"),
    ("turning", {"dt": 0.0}, "--dt-s", "expected a time step from 0.001 to 60 s, got 0"),
    ("zigzag", {"dt": 20.0}, "--dt-s",
     "expected at most L/U = 15.5 s for this ship (a longer step skips its manoeuvring motion), "
     "got 20"),
])
def test_values_a_manoeuvre_rejects_are_reported_under_their_flag(tmp_path, manoeuvre, kw, flag,
                                                                  message):
    out = tmp_path / "out"
    with pytest.raises(InputError) as err:
        _trial(out, "container", manoeuvre, **kw)
    assert err.value.key == flag and err.value.message == message
    assert str(err.value) == f"{flag}: {message}"
    assert not out.exists()  # nothing written


def test_a_ship_model_that_runs_away_is_one_line_naming_the_file_and_time(tmp_path):
    """A sign error in a ship file (a destabilising sway derivative) makes the state NaN
    within seconds: one SimulationError naming the file and the time, nothing written."""
    from trafficsim.errors import SimulationError
    from trafficsim.ships.library import LIBRARY_DIR

    text = (LIBRARY_DIR / "kvlcc2.yaml").read_text()
    assert "  Y_v: -0.315\n" in text
    ship = tmp_path / "runaway.yaml"
    ship.write_text(text.replace("  Y_v: -0.315\n", "  Y_v: 31.5\n"))
    for manoeuvre in ("turning", "zigzag"):
        with pytest.raises(SimulationError) as err:
            _trial(tmp_path / "out", str(ship), manoeuvre)
        assert str(err.value).startswith(f"{ship}: the ship's state became non-finite at t = ")
        assert not (tmp_path / "out").exists()


def test_an_error_without_a_flag_keeps_its_message(tmp_path):
    with pytest.raises(InputError, match="cannot go astern") as err:
        _trial(tmp_path / "out", "catfish", "crash-stop")
    assert err.value.key is None
    assert not (tmp_path / "out").exists()


def test_values_at_the_limits_are_accepted(tmp_path):
    """The fastest speed the engine holds, the largest time step, the full rudder to port."""
    indices, _ = _trial(tmp_path / "a", "cargo", "crash-stop", speed=20.0, dt=60.0)
    assert indices["time_to_stop_s"] % 60.0 == 0.0  # whole 60 s steps
    _, col = _read_csv(tmp_path / "a" / "trial.csv")
    assert np.all(np.diff(col["t_s"]) == 60.0)
    indices, _ = _trial(tmp_path / "b", "cargo", "turning", rudder=35.0, port=True, dt=5.0)
    assert indices["rudder_deg"] == -35.0


def test_a_speed_the_engine_cannot_hold_is_refused_under_its_flag(tmp_path):
    """Beyond the speed the engine holds at full power the approach would be a ship slowing
    down: refused, naming that speed, under ``--speed-kn``; nothing is written."""
    with pytest.raises(InputError) as err:
        _trial(tmp_path / "a", "cargo", "turning", speed=20.1)
    assert err.value.key == "--speed-kn"
    assert "at its largest propeller speed (1.7778 rev/s) it makes 20.00 kn, got 20.1 kn" in (
        err.value.message)
    assert not (tmp_path / "a" / "trial.csv").exists()


# --- instruments -----------------------------------------------------------------------------


def _straight(spec, speed_mps=6.0, heading_deg=30.0, n=301, dt=1.0):
    """A straight run at steady speed with the propeller speed that holds it."""
    family = base.families()[spec["model"]]
    rps = base.steady_rps_for_speed(family, family.build([spec]),
                                    base.Actuators.from_specs([spec]), np.array([speed_mps]))[0]
    t = dt * np.arange(n)
    psi = math.radians(heading_deg)
    return {"t_s": t, "north_m": speed_mps * t * math.cos(psi),
            "east_m": speed_mps * t * math.sin(psi), "heading_deg": np.full(n, heading_deg),
            "u_mps": np.full(n, speed_mps), "v_mps": np.zeros(n), "r_degps": np.zeros(n),
            "rudder_deg": np.zeros(n), "rpm": np.full(n, 60.0 * rps)}


def _rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


def test_sensor_columns_scatter_about_a_straight_run_and_the_filters_smooth_them():
    """Defaults: DGPS sigma 2 m per axis, gyro sigma 1 deg; receiver filter and EKF estimate
    closer to the truth than the raw fixes; speed and course over ground those of the run."""
    track = _straight(load_ship("cargo"))
    col = sensor_columns(track, load_ship("cargo"))
    assert list(col) == SENSOR_COLUMNS
    fix_n = col["gnss_fix_north_m"] - track["north_m"]
    fix_e = col["gnss_fix_east_m"] - track["east_m"]
    assert 1.7 < fix_n.std() < 2.3 and 1.7 < fix_e.std() < 2.3
    compass = (col["compass_heading_deg"] - 30.0 + 180.0) % 360.0 - 180.0
    assert 0.85 < compass.std() < 1.15
    fix_rms = _rms(np.hypot(fix_n, fix_e))
    receiver = np.hypot(col["gnss_north_m"] - track["north_m"],
                        col["gnss_east_m"] - track["east_m"])
    est = np.hypot(col["est_north_m"] - track["north_m"], col["est_east_m"] - track["east_m"])
    assert _rms(receiver) < 0.6 * fix_rms and _rms(est) < 0.6 * fix_rms
    settled = slice(50, None)
    sog_kn = 6.0 / KN
    for key in ("gnss_sog_kn", "est_sog_kn"):
        assert np.mean(col[key][settled]) == pytest.approx(sog_kn, abs=0.15), key
    for key in ("gnss_cog_deg", "est_cog_deg", "est_heading_deg"):
        assert np.mean(col[key][settled]) == pytest.approx(30.0, abs=1.0), key
    assert np.abs(col["est_r_degps"]).max() < 1.0


def test_a_lower_sp_smooths_the_receivers_speed_but_not_the_raw_fixes():
    spec = load_ship("cargo")
    track = _straight(spec)
    cols = {sp: sensor_columns(track, spec, sp_m2ps3=sp) for sp in (0.001, 0.01, 0.1)}
    spread = [np.std(cols[sp]["gnss_sog_kn"][50:] - 6.0 / KN) for sp in (0.001, 0.01, 0.1)]
    assert spread[0] < spread[1] < spread[2]
    np.testing.assert_array_equal(cols[0.001]["gnss_fix_north_m"], cols[0.1]["gnss_fix_north_m"])


def test_the_seed_keys_the_instrument_noise():
    spec = load_ship("cargo")
    track = _straight(spec, n=60)
    a, again, other = (sensor_columns(track, spec, seed=s) for s in (3, 3, 4))
    for key in SENSOR_COLUMNS:
        np.testing.assert_array_equal(a[key], again[key], err_msg=key)
    assert np.abs(a["gnss_fix_north_m"] - other["gnss_fix_north_m"]).max() > 0.5


def test_sensor_columns_take_the_ship_files_receiver():
    spec = {**load_ship("cargo"), "sensors": {"gnss": {"sigma_m": 6.0}}}
    track = _straight(spec)
    col = sensor_columns(track, spec)
    assert 5.0 < (col["gnss_fix_north_m"] - track["north_m"]).std() < 7.0


def test_trial_with_sensors_appends_the_instrument_columns(tmp_path):
    indices, _ = _trial(tmp_path, "container", "zigzag", rudder=10.0, sensors=True,
                        sp_m2ps3=0.05, seed=7)
    spec = load_ship("container")
    track, expected = manoeuvres.zigzag(spec, 10.0)
    assert indices == expected  # the manoeuvre is the same with or without instruments
    header, col = _read_csv(tmp_path / "trial.csv")
    assert header == TRACK_COLUMNS + SENSOR_COLUMNS
    _assert_csv_holds(col, track)
    want = sensor_columns(track, spec, 0.05, 7)
    for key in SENSOR_COLUMNS:
        np.testing.assert_allclose(col[key], want[key], rtol=1e-5, atol=1e-6, err_msg=key)
    # the sp and seed given are the ones used
    assert np.abs(col["gnss_north_m"] - sensor_columns(track, spec, 0.01, 7)["gnss_north_m"]
                  ).max() > 0.01
    assert np.abs(col["gnss_fix_north_m"] - sensor_columns(track, spec, 0.05, 0)
                  ["gnss_fix_north_m"]).max() > 0.5


def test_trial_with_sensors_takes_a_receiver_given_by_drms(tmp_path):
    ship = tmp_path / "boxer.yaml"
    ship.write_text((LIBRARY_DIR / "container.yaml").read_text()
                    + "sensors:\n  gnss: {drms_m: 10.0}\n")
    load_ship(str(ship))  # a valid ship file
    _trial(tmp_path / "out", str(ship), "zigzag", rudder=10.0, sensors=True)
    _, col = _read_csv(tmp_path / "out" / "trial.csv")
    sigma = 10.0 / math.sqrt(2.0)  # per axis
    assert 0.75 * sigma < np.std(col["gnss_fix_north_m"] - col["north_m"]) < 1.25 * sigma


# --- flags out of range and manoeuvres that never complete -------------------------------------


@pytest.mark.parametrize("manoeuvre, kw, flag, message", [
    ("turning", {"speed": 1e-6}, "--speed-kn",
     "expected at least 0.1 times the service speed of 'container' (22 kn), got 1e-06 kn"),
    ("zigzag", {"heading": 400.0}, "--heading-deg",
     "expected a heading change from 1 to 90 deg, got 400"),
    ("zigzag", {"heading": 1e-9}, "--heading-deg",
     "expected a heading change from 1 to 90 deg, got 1e-09"),
    ("zigzag", {"heading": 170.0, "rudder": 5.0}, "--heading-deg",
     "expected a heading change from 1 to 90 deg, got 170"),
    ("turning", {"sensors": True, "sp_m2ps3": 1e300}, "--sp",
     "expected a receiver filter S_p from 1e-06 to 10000 m^2/s^3, got 1e+300"),
    ("turning", {"sensors": True, "sp_m2ps3": 1e-7}, "--sp",
     "expected a receiver filter S_p from 1e-06 to 10000 m^2/s^3, got 1e-07"),
])
def test_flags_out_of_range_are_refused_under_their_flag(tmp_path, manoeuvre, kw, flag, message):
    """The audit's values: 1e-6 kn gave NaN advance and tactical diameter, a 400 or 1e-9 deg
    zig-zag meaningless indices, S_p 1e300 406 NaN cells in trial.csv."""
    out = tmp_path / "out"
    with pytest.raises(InputError) as err:
        _trial(out, "container", manoeuvre, **kw)
    assert err.value.key == flag and err.value.message == message
    assert not out.exists()


def test_sp_at_its_limits_gives_finite_receiver_columns(tmp_path):
    """Both ends of the range are accepted and the receiver's columns stay finite."""
    for sp in SP_RANGE_M2PS3:
        _trial(tmp_path / str(sp), "fishing", "turning", sensors=True, sp_m2ps3=sp)
        _, col = _read_csv(tmp_path / str(sp) / "trial.csv")
        for key in SENSOR_COLUMNS[2:6]:
            assert np.isfinite(col[key]).all(), (sp, key)


@pytest.mark.parametrize("manoeuvre, kw, flag, message", [
    ("zigzag", {"rudder": 0.1, "heading": 90.0}, "--heading-deg",
     r"^the zig-zag did not complete: with 0\.1 deg rudder the heading changed by at most "
     r"[0-9.]+ deg in 3 h; give a smaller --heading-deg than 90 or a larger --rudder-deg$"),
    ("turning", {"rudder": 0.01}, "--rudder-deg",
     r"^the turn did not complete: the heading changed by [0-9.]+ deg in 6 h, not the 540 deg "
     r"the indices need; give a larger rudder angle$"),
])
def test_a_manoeuvre_that_never_completes_is_an_error_naming_the_flag(tmp_path, manoeuvre, kw,
                                                                      flag, message):
    """A rudder too small for the heading change: the zig-zag never reversed (its overshoots
    were NaN with exit code 0), the turn never came round; nothing is written."""
    out = tmp_path / "out"
    with pytest.raises(InputError) as err:
        _trial(out, "tanker", manoeuvre, **kw)
    assert err.value.key == flag and re.match(message, err.value.message), err.value.message
    assert not out.exists()


def test_a_crash_stop_that_never_stops_is_an_error_naming_the_ship_file(tmp_path):
    """Astern power too weak to stop the ship in the 2 h the manoeuvre runs."""
    text = (LIBRARY_DIR / "container.yaml").read_text()
    ship = tmp_path / "weak.yaml"
    ship.write_text(text.replace("  rps_min: -0.90", "  rps_min: -0.0001"))
    with pytest.raises(InputError, match=r"^.*weak\.yaml: the crash stop did not complete: "
                                         r"'container' was still making [0-9.e-]+ m/s after "
                                         r"2 h of full astern \(its ship file's rps_min\)$"):
        _trial(tmp_path / "out", str(ship), "crash-stop")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args, expect", [
    (["container", "--manoeuvre", "turning", "--sensors", "--sp", "1e300"], "--sp: expected"),
    (["container", "--manoeuvre", "turning", "--speed-kn", "1e-6"], "--speed-kn: expected"),
    (["container", "--manoeuvre", "zigzag", "--heading-deg", "400"], "--heading-deg: expected"),
    (["container", "--manoeuvre", "zigzag", "--heading-deg", "170", "--rudder-deg", "5"],
     "--heading-deg: expected"),
], ids=lambda a: "_".join(a[2:]) if isinstance(a, list) else None)
def test_the_audits_commands_exit_2_with_one_line(tmp_path, capsys, args, expect):
    from trafficsim import cli

    assert cli.main(["trial", *args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"trafficsim: error: {expect}")
