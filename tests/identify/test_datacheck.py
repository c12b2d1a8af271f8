"""Checks of trial runs before a fit: time gaps, non-finite and impossible values (located at
file, line and column), propeller speeds against the base ship, and runs that excite nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trafficsim.errors import DataError, InputError
from trafficsim.identify import datacheck, preprocess
from trafficsim.io.trialdata import from_arrays, read_trial
from trafficsim.ships.library import load_ship

HEADER = "t_s,north_m,east_m,heading_deg,rudder_deg,rpm"
KNOT = 1852.0 / 3600.0


def _rows(n: int = 30) -> list[list[float]]:
    """A turning run (rudder 0 then 10 deg, heading growing): every check passes."""
    return [[float(i), 7.0 * i, 0.01 * i * i, 0.5 * i, 0.0 if i < 5 else 10.0, 80.0]
            for i in range(n)]


def _csv(path: Path, rows: list[list[float]], header: str = HEADER, blank_at: int = -1) -> Path:
    lines = [header]
    for i, row in enumerate(rows):
        if i == blank_at:
            lines.append(",,,,,")  # an empty row: dropped by the reader, lines still count
        lines.append(",".join(str(v) for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_valid_run_passes(tmp_path: Path) -> None:
    trial = read_trial(_csv(tmp_path / "ok.csv", _rows()))
    datacheck.check_run(trial)
    datacheck.check_propeller([trial], load_ship("cargo"))
    datacheck.check_motion([trial], 160.93)
    datacheck.check_excitation([trial], ("K_prime", "T_prime"))


def test_a_long_time_gap_is_refused_at_its_line(tmp_path: Path) -> None:
    """1 s samples with a jump of 1e9 s after row 10 (line 12 with the header and an empty row
    before it): refused at the line after the gap; a gap of 20 intervals is still bridged."""
    rows = _rows()
    for row in rows[10:]:
        row[0] += 1e9
    path = _csv(tmp_path / "gap.csv", rows, blank_at=3)
    with pytest.raises(DataError) as err:
        datacheck.check_run(read_trial(path))
    assert str(err.value).startswith(
        f"{path}:13: t_s: time jumps from 9 s to 1000000010 s, a gap of 1e+09 s (1e+09 "
        "sampling intervals of 1 s); gaps of up to 20 intervals (20 s) are bridged, a longer "
        "one is not: split the run into two files at this line")
    rows = _rows()
    for row in rows[10:]:
        row[0] += 19.0
    datacheck.check_run(read_trial(_csv(tmp_path / "bridged.csv", rows)))


def test_resampling_refuses_a_gap_it_cannot_hold_in_memory() -> None:
    """The resampler checks first: a grid over a 1e9 s gap would be 1e9 samples."""
    t = np.r_[np.arange(10.0), 1e9 + np.arange(10.0)]
    trial = from_arrays("g", {"t_s": t, "north_m": t, "east_m": t, "heading_deg": t,
                              "rudder_deg": t * 0, "rpm": t * 0 + 60})
    with pytest.raises(DataError, match=r"^t_s: time jumps from 9 s to 1000000000 s"):
        preprocess.resample_uniform(trial)


@pytest.mark.parametrize("row, col, value, expect", [
    (4, 2, "inf", "east_m: expected a finite number (an empty cell for a missing value), got inf"),
    (6, 1, "-inf", "north_m: expected a finite number (an empty cell for a missing value), "
                   "got -inf"),
    (7, 4, "3000", "rudder_deg: expected a rudder angle of at most 90 deg either way, got 3000"),
    (7, 4, "-90.5", "rudder_deg: expected a rudder angle of at most 90 deg either way, got "
                    "-90.5"),
    (2, 1, "1e308", "north_m: expected a position within 2e+07 m of the origin (half the "
                    "Earth's circumference), got 1e+308"),
])
def test_impossible_values_are_located(tmp_path: Path, row, col, value, expect) -> None:
    """The file, the line of the row (header = line 1), the column and the value as written."""
    rows: list[list] = _rows()
    rows[row][col] = value
    path = _csv(tmp_path / "bad.csv", rows)
    with pytest.raises(DataError) as err:
        datacheck.check_run(read_trial(path))
    assert str(err.value) == f"{path}:{row + 2}: {expect}"


def test_empty_cells_and_nan_stay_missing_values(tmp_path: Path) -> None:
    rows: list[list] = _rows()
    rows[3][1], rows[4][4] = "", "nan"
    datacheck.check_run(read_trial(_csv(tmp_path / "gaps.csv", rows)))


def test_negative_speeds_and_optional_columns(tmp_path: Path) -> None:
    """A negative speed over ground or wind speed is no reading; an infinite extra column is
    refused under its own name."""
    rows = [[*r, 13.0, 5.0, 90.0] for r in _rows()]
    rows[5][7] = -2.0
    path = _csv(tmp_path / "w.csv", rows, HEADER + ",sog_kn,wind_speed_mps,wind_from_deg")
    with pytest.raises(DataError, match=r":7: wind_speed_mps: expected a speed of at least 0, "
                                        r"got -2$"):
        datacheck.check_run(read_trial(path))
    rows = [[*r, 1.0] for r in _rows()]
    rows[8][6] = "inf"
    path = _csv(tmp_path / "x.csv", rows, HEADER + ",gnss_fix_north_m")
    with pytest.raises(DataError, match=r":10: gnss_fix_north_m: expected a finite number"):
        datacheck.check_run(read_trial(path))


def test_a_true_wind_above_100_mps_is_located(tmp_path: Path) -> None:
    """A true wind speed above 100 m/s (no wind on record is that strong) is refused at its
    line and column, in either file format; 100 m/s itself is a reading."""
    rows = [[*r, 100.0, 90.0] for r in _rows()]
    path = _csv(tmp_path / "w.csv", rows, HEADER + ",wind_speed_mps,wind_from_deg")
    datacheck.check_run(read_trial(path))
    rows[6][6] = 150.0
    path = _csv(tmp_path / "w.csv", rows, HEADER + ",wind_speed_mps,wind_from_deg")
    with pytest.raises(DataError) as err:
        datacheck.check_run(read_trial(path))
    assert str(err.value) == (f"{path}:8: wind_speed_mps: expected a true wind speed of at most "
                              "100 m/s (above the strongest sustained winds on record), got 150")
    header = ("t [s],x_position_mid [m],y_position_mid [m],psi_hat [rad],n_prop [rps],"
              "delta_rudder [rad],wind_velo_true [m/s],wind_dir_true [rad]")
    rows = [[0.1 * i, 0.04 * i, 0.0, 0.01 * i, 10.0, 0.2, 3.0, 1.0] for i in range(30)]
    rows[3][6] = 1e4
    path = _csv(tmp_path / "frt.csv", rows, header)
    with pytest.raises(DataError, match=r"frt.csv:5: wind_velo_true \[m/s\]: expected a true "
                                        r"wind speed of at most 100 m/s"):
        datacheck.check_run(read_trial(path))


def test_a_mapped_column_is_named_as_in_the_file(tmp_path: Path) -> None:
    """With ``--columns north_m=gnss_north``, an infinite fix is reported under gnss_north."""
    rows = [[*r, 7.0 * r[0]] for r in _rows()]
    rows[9][6] = "inf"
    path = _csv(tmp_path / "m.csv", rows, HEADER + ",gnss_north")
    columns = {"north_m": "gnss_north"}
    with pytest.raises(DataError, match=r"m.csv:11: gnss_north: expected a finite number"):
        datacheck.check_run(read_trial(path, columns=columns), columns)


def test_frt_columns_are_named_as_in_the_file(tmp_path: Path) -> None:
    """FRT-DS-ESSO runs: the rudder in radians under its own header, limit 90 deg."""
    header = ("t [s],x_position_mid [m],y_position_mid [m],psi_hat [rad],n_prop [rps],"
              "delta_rudder [rad]")
    rows = [[0.1 * i, 0.04 * i, 0.0, 0.01 * i, 10.0, 0.2] for i in range(30)]
    rows[12][5] = 1.6
    path = _csv(tmp_path / "frt.csv", rows, header)
    with pytest.raises(DataError) as err:
        datacheck.check_run(read_trial(path))
    assert str(err.value) == (f"{path}:14: delta_rudder [rad]: expected a rudder angle of at "
                              "most 90 deg either way, got 1.6")


def test_propeller_speed_against_the_base_ship(tmp_path: Path) -> None:
    """Up to twice the engine range (cargo: 1.7778 rev/s ahead) either way."""
    rows = _rows()
    rows[11][5] = -213.0  # 3.55 rev/s astern: within 2 x 1.7778
    ok = read_trial(_csv(tmp_path / "ok.csv", rows))
    datacheck.check_propeller([ok], load_ship("cargo"))
    rows[12][5] = -99999.0
    path = _csv(tmp_path / "rpm.csv", rows)
    with pytest.raises(DataError) as err:
        datacheck.check_propeller([ok, read_trial(path)], load_ship("cargo"))
    assert str(err.value) == (f"{path}:14: rpm: expected a propeller speed of at most 2 times "
                              "the engine range of the base ship 'cargo' (3.556 rev/s = 213.3 "
                              "rpm either way), got -99999")


def test_a_ship_that_does_not_move(tmp_path: Path) -> None:
    rows = [[float(i), 5.0, 5.0, 0.5 * i, 10.0 * (i % 2), 0.0] for i in range(30)]
    still = read_trial(_csv(tmp_path / "still.csv", rows))
    with pytest.raises(InputError) as err:
        datacheck.check_motion([still], 160.93)
    assert str(err.value) == (f"{tmp_path / 'still.csv'}: the ship does not move in the run: "
                              "its track spans 0 m, less than its length (160.93 m); there "
                              "is nothing to fit or replay")
    two = [still, read_trial(_csv(tmp_path / "s2.csv", rows))]
    with pytest.raises(InputError, match=r"^--data: the ship does not move in any of the 2 "
                                         r"training runs \(still, s2\)"):
        datacheck.check_motion(two, 160.93)
    datacheck.check_motion([*two, read_trial(_csv(tmp_path / "ok.csv", _rows()))], 160.93)
    # no positions at all: left to the smoother's "no two consecutive samples"
    blank = [[float(i), "", "", 0.5 * i, 10.0, 0.0] for i in range(30)]
    datacheck.check_motion([read_trial(_csv(tmp_path / "blank.csv", blank))], 160.93)


def test_turning_coefficients_need_rudder_and_heading_to_move(tmp_path: Path) -> None:
    """A straight run at constant rudder: K', T', n3' are refused, the surge coefficients
    alone are not; one turning run among straight ones is enough."""
    straight = [[float(i), 7.0 * i, 0.0, 30.0, 0.5, 80.0] for i in range(30)]
    run = read_trial(_csv(tmp_path / "straight.csv", straight))
    names = ("K_prime", "T_prime", "n3_prime", "rps_service", "surge_tau_s")
    with pytest.raises(InputError) as err:
        datacheck.check_excitation([run], names)
    assert str(err.value) == (
        f"{tmp_path / 'straight.csv'}: K_prime, T_prime, n3_prime cannot be identified from "
        "this data: in this run the rudder and the heading do not both move by 1 deg or more "
        "(largest excursions: rudder 0 deg, heading 0 deg), so nothing excites the turning "
        "motion; give runs with rudder manoeuvres (turns, zig-zags) or fit only rps_service, "
        "surge_tau_s (--fit)")
    datacheck.check_excitation([run], ("rps_service", "surge_tau_s"))
    # the rudder moves but the heading does not (a frozen compass): still nothing to fit
    frozen = [[*r[:4], 10.0 * (r[0] > 5), r[5]] for r in straight]
    run2 = read_trial(_csv(tmp_path / "frozen.csv", frozen))
    with pytest.raises(InputError, match=r"^--data: b1, c1 cannot be identified from this "
                                         r"data: in none of the 2 training runs \(straight, "
                                         r"frozen\) do the rudder and the heading both move.*"
                                         r"heading 0 deg\).* or fit only a1 \(--fit\)$"):
        datacheck.check_excitation([run, run2], ("a1", "b1", "c1"))
    turning = read_trial(_csv(tmp_path / "turn.csv", _rows()))
    datacheck.check_excitation([run, run2, turning], names)


def _turning(path: Path, rpm: float, n: int = 60) -> tuple[list, list]:
    """A cargo-ship turn at 7 m/s with the given rpm, read and smoothed."""
    rows = [[float(i), 7.0 * i, 0.01 * i * i, 0.5 * i, 0.0 if i < 5 else 10.0, rpm]
            for i in range(n)]
    trial = read_trial(_csv(path, rows))
    return [trial], preprocess.smooth_runs([trial], 160.93, 15 * KNOT)


def test_service_propeller_speed_needs_the_propeller_ahead(tmp_path: Path) -> None:
    """rps_service from a ship that makes 7 m/s ahead on -80 rpm (a column whose sign is
    reversed): refused at the file's rpm column (one run) or naming --data (several); the
    same ahead (or a run that never goes faster than 30 % of the service speed) passes."""
    u = 15 * KNOT
    trials, runs = _turning(tmp_path / "ok.csv", 80.0)
    datacheck.check_propulsion(trials, runs, u)
    neg_trials, neg_runs = _turning(tmp_path / "neg.csv", -80.0)
    with pytest.raises(DataError) as err:
        datacheck.check_propulsion(neg_trials, neg_runs, u)
    text = str(err.value)
    assert text.startswith(f"{tmp_path / 'neg.csv'}:") and err.value.key == "rpm"
    assert ("rps_service cannot be identified from this data: the ship makes way ahead above "
            "30 % of its service speed (2.31 m/s) only with the propeller stopped or astern "
            "(here 7") in text
    assert text.endswith("the column reading -80); the rpm is signed (negative astern): check "
                         "the sign of the column, or fit without rps_service (--fit)")
    with pytest.raises(InputError) as err:
        datacheck.check_propulsion(neg_trials * 2, neg_runs * 2, u, optional=False)
    assert err.value.key == "--data" and err.value.path is None
    assert str(err.value).endswith("check the sign of the column")
    datacheck.check_propulsion(neg_trials, neg_runs, 100.0)  # never faster than 30 m/s
    datacheck.check_propulsion([*neg_trials, *trials], [*neg_runs, *runs], u)


def _circle(path: Path, heading_scale: float = 1.0, rpm: float = 80.0, turn_degps: float = 1.0,
            n: int = 90) -> tuple[list, list]:
    """A cargo ship turning at ``turn_degps`` at 7 m/s for ``n`` s (heading column times
    ``heading_scale``), read and smoothed."""
    radius = 7.0 / np.radians(turn_degps) if turn_degps else np.inf
    rows = []
    for i in range(n):
        psi = np.radians(turn_degps * i)
        north, east = ((radius * np.sin(psi), radius * (1.0 - np.cos(psi))) if turn_degps
                       else (7.0 * i, 0.0))
        rows.append([float(i), north, east, heading_scale * np.degrees(psi), 10.0, rpm])
    trial = read_trial(_csv(path, rows))
    return [trial], preprocess.smooth_runs([trial], 160.93, 15 * KNOT)


def test_heading_and_propeller_columns_in_other_units_are_refused(tmp_path: Path) -> None:
    """A heading written in radians turns 57 times too little for the track it steers; an rpm
    column holding rev/s turns 60 times too slow for the way the ship makes."""
    cargo = load_ship("cargo")
    datacheck.check_units(*_circle(tmp_path / "ok.csv"), cargo)
    with pytest.raises(DataError) as err:
        datacheck.check_units(*_circle(tmp_path / "rad.csv", heading_scale=np.pi / 180.0),
                              cargo)
    text = str(err.value)
    assert err.value.key == "heading_deg" and text.startswith(f"{tmp_path / 'rad.csv'}:2:")
    assert ("the heading turns through 1.55 deg while the ship's track turns through 87.9 deg"
            in text)
    assert text.endswith("a heading in radians, or a frozen compass, reads so; expected "
                         "degrees clockwise from north")
    with pytest.raises(DataError) as err:
        datacheck.check_units(*_circle(tmp_path / "rps.csv", rpm=80.0 / 60.0), cargo)
    text = str(err.value)
    assert err.value.key == "rpm" and text.startswith(f"{tmp_path / 'rps.csv'}:2:")
    assert ("the propeller turns at a median 1.333 rpm (here 1.333333333 as read) while the ship "
            "makes way above 30 % of its service speed: less than 1/20 of the base ship "
            "'cargo''s largest (106.7 rpm); a column holding rev/s where rpm is expected reads "
            "so") in text


def test_a_straight_run_cannot_tell_the_heading_unit(tmp_path: Path) -> None:
    """Without a turn of the track of 20 deg the heading's unit is not told (nor is it needed
    for a refusal: such a run excites no turning coefficient)."""
    datacheck.check_units(*_circle(tmp_path / "s.csv", heading_scale=np.pi / 180.0,
                                   turn_degps=0.0), load_ship("cargo"))
    datacheck.check_units(*_circle(tmp_path / "slow.csv", heading_scale=np.pi / 180.0,
                                   turn_degps=0.2), load_ship("cargo"))
