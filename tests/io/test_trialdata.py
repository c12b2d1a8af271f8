"""Trial-data reader: the project's trial CSV, FRT-DS-ESSO files, located errors, NaN reports."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import SHARED
from trafficsim.errors import DataError
from trafficsim.io.results import write_csv
from trafficsim.io.trialdata import REQUIRED_CSV, from_arrays, read_trial, read_trial_csv
from trafficsim.trial import run_trial

ESSO = SHARED / "data" / "frt-ds-esso" / "data"
needs_esso = pytest.mark.skipif(not ESSO.is_dir(), reason="FRT-DS-ESSO data set not present")


def test_reads_what_trafficsim_trial_writes(tmp_path: Path) -> None:
    """The reader takes ``trafficsim trial``'s trial.csv as it is: units converted, the optional
    columns picked up, the instrument columns of --sensors kept as extras."""
    run_trial("container", "zigzag", 10.0, None, False, None, None, tmp_path, sensors=True,
              seed=3)
    text = (tmp_path / "trial.csv").read_text().splitlines()
    header = text[0].split(",")
    raw = np.array([[float(c) for c in row.split(",")] for row in text[1:]])
    col = {h: raw[:, i] for i, h in enumerate(header)}
    tr = read_trial(tmp_path / "trial.csv")
    assert tr.n == raw.shape[0] and tr.name == "trial"
    np.testing.assert_allclose(tr.psi_rad, np.radians(col["heading_deg"]))
    np.testing.assert_allclose(tr.rudder_rad, np.radians(col["rudder_deg"]))
    np.testing.assert_allclose(tr.rps, col["rpm"] / 60.0)
    np.testing.assert_allclose(tr.r_radps, np.radians(col["r_degps"]))
    np.testing.assert_allclose(tr.sog_mps, col["sog_kn"] * 1852.0 / 3600.0)
    assert tr.wind_speed_mps is None and not tr.has_wind
    assert {"gnss_fix_north_m", "compass_heading_deg", "est_r_degps"} <= set(tr.extra)
    # the columns of a trial with sensors can stand in for the truth
    meas = read_trial(tmp_path / "trial.csv", columns={
        "north_m": "gnss_fix_north_m", "heading_deg": "compass_heading_deg"})
    np.testing.assert_allclose(meas.north_m, col["gnss_fix_north_m"])
    np.testing.assert_allclose(meas.extra["north_m_replaced"], col["north_m"])
    assert np.abs(meas.north_m - tr.north_m).max() > 0.5  # noisy fixes, not the truth


def test_round_trip_through_the_csv_format(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    n = 50
    cols = {"t_s": np.arange(n) * 0.5, "north_m": rng.normal(size=n) * 100,
            "east_m": rng.normal(size=n) * 100, "heading_deg": rng.uniform(0, 360, n),
            "rudder_deg": rng.uniform(-35, 35, n), "rpm": rng.uniform(-60, 90, n),
            "wind_speed_mps": rng.uniform(0, 15, n), "wind_from_deg": rng.uniform(0, 360, n)}
    write_csv(tmp_path / "a.csv", cols, fmt="%.17g")
    tr = read_trial_csv(tmp_path / "a.csv")
    write_csv(tmp_path / "b.csv", tr.to_csv_columns(), fmt="%.17g")
    back = read_trial_csv(tmp_path / "b.csv")
    for key, value in tr.arrays().items():
        np.testing.assert_allclose(getattr(back, key), value, rtol=1e-12, atol=1e-12)
    assert back.has_wind and back.u_mps is None


def test_missing_cells_are_counted_not_fatal(tmp_path: Path) -> None:
    body = ("t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n"
            "0,0,0,10,0,60\n1,5,,10,0,60\n2,10,0,nan,1,60\n,,,,,\n")
    (tmp_path / "t.csv").write_text(body)
    tr = read_trial_csv(tmp_path / "t.csv")
    assert tr.n == 3 and tr.dropped_rows == 1
    assert tr.missing["east_m"] == 1 and tr.missing["psi_rad"] == 1
    assert tr.nan_report()["nan_counts"] == {"east_m": 1, "psi_rad": 1}


@pytest.mark.parametrize("body, line, expect", [
    ("t_s,north_m,east_m\n0,0,0\n1,1,1\n", 1, "missing column(s) heading_deg, rudder_deg, rpm"),
    ("t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n0,0,0,0,0,60\n1,1,one,0,0,60\n", 3,
     "east_m: expected a number, got 'one'"),
    ("t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n0,0,0,0,0,60\n0,1,1,0,0,60\n", 3,
     "time must increase"),
    ("t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n0,0,0,0,0,60\n1,1,1,0,0\n", 3,
     "expected 6 values"),
    ("t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n0,0,0,0,0,60\n,1,1,0,0,60\n", 3,
     "expected a finite time in every row, got an empty cell or nan"),
    ("", 1, "empty file"),
    ("\n", 1, "empty file (blank lines only); expected a header row"),
    ("\n\n,,\n \n", 1, "empty file (blank lines only); expected a header row"),
    ("\nt_s,north_m,east_m,heading_deg,rudder_deg,rpm\n0,0,0,0,0,60\n", 1,
     "expected a header row of column names, got a blank line"),
    ("t_s,t_s,north_m\n", 1, "duplicate column"),
])
def test_bad_files_give_located_errors(tmp_path: Path, body: str, line: int, expect: str
                                       ) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(DataError) as err:
        read_trial(path)
    assert err.value.path == str(path) and err.value.line == line
    assert expect in str(err.value) and str(err.value).startswith(f"{path}:{line}: ")


def test_missing_file_and_bad_mapping(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="not found"):
        read_trial(tmp_path / "nope.csv")
    (tmp_path / "t.csv").write_text("t_s,north_m,east_m,heading_deg,rudder_deg,rpm\n0,0,0,0,0,6\n"
                                    "1,0,0,0,0,6\n")
    with pytest.raises(DataError, match=r"'gps_n'.*not in the file"):
        read_trial(tmp_path / "t.csv", columns={"north_m": "gps_n"})
    with pytest.raises(DataError, match="cannot map 'x'"):
        read_trial(tmp_path / "t.csv", columns={"x": "north_m"})


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(*[st.floats(-1e6, 1e6, allow_nan=False) for _ in range(5)]),
                min_size=2, max_size=20))
def test_any_numeric_table_reads_back(tmp_path: Path, rows: list[tuple[float, ...]]) -> None:
    """Property: a table of finite numbers with increasing time reads back exactly."""
    data = np.array(rows)
    t = np.cumsum(np.abs(data[:, 0]) + 0.25)
    cols = dict(zip(REQUIRED_CSV, [t, *data.T], strict=True))
    write_csv(tmp_path / "p.csv", cols, fmt="%.17g")
    tr = read_trial_csv(tmp_path / "p.csv")
    np.testing.assert_array_equal(tr.t_s, t)
    np.testing.assert_array_equal(tr.north_m, data[:, 0])
    np.testing.assert_allclose(tr.rps, data[:, 4] / 60.0, rtol=1e-15)


@needs_esso
def test_frt_ds_esso_columns_and_empty_rows() -> None:
    """The mapping of the data set's columns; the file with 327 trailing empty rows reads with
    them dropped and reported."""
    tr = read_trial(ESSO / "zigzag" / "zigzag_31-Jul-2020_13_50_28.csv")
    assert tr.n == 1701 and tr.dropped_rows == 327
    assert not any(tr.nan_report()["nan_counts"].values())
    assert tr.dt_s == pytest.approx(0.1) and tr.has_wind
    assert tr.u_mps is not None and tr.v_mps is not None and tr.r_radps is not None
    assert set(tr.extra) == {"apparent_wind_speed_mps", "apparent_wind_from_rad"}
    assert np.nanmax(np.abs(np.degrees(tr.rudder_rad))) == pytest.approx(30.0, abs=1.0)


@needs_esso
@pytest.mark.parametrize("run", ["turning/turn_14-Sep-2020_13_39_32.csv",
                                 "zigzag/zigzag_31-Jul-2020_13_22_52.csv",
                                 "random/random_06-Aug-2020_16_24_25_4.csv"])
def test_frt_ds_esso_frames_are_ned(run: str) -> None:
    """x0 -> north, y0 -> east, psi clockwise from x0 is a right-handed (z down) frame: the
    position derivative rotated by the heading reproduces the recorded (u, v) (2-s central
    differences), much better than with the other handedness; d psi/dt = +r; positive rudder
    turns to starboard; the recorded apparent wind follows from the true wind blowing FROM
    wind_dir_true and the ship's velocity."""
    tr = read_trial(ESSO / run)
    k = 10
    t, n, e, psi = tr.t_s, tr.north_m, tr.east_m, tr.psi_rad
    vn = (n[2 * k:] - n[:-2 * k]) / (t[2 * k:] - t[:-2 * k])
    ve = (e[2 * k:] - e[:-2 * k]) / (t[2 * k:] - t[:-2 * k])
    c, s = np.cos(psi[k:-k]), np.sin(psi[k:-k])
    u, v = tr.u_mps[k:-k], tr.v_mps[k:-k]
    ned = np.sqrt(np.mean((vn * c + ve * s - u) ** 2 + (-vn * s + ve * c - v) ** 2))
    mirrored = np.sqrt(np.mean((vn * c - ve * s - u) ** 2 + (vn * s + ve * c - v) ** 2))
    assert ned < 0.015 and mirrored > 2.5 * ned
    dpsi = np.gradient(np.unwrap(psi), t)
    assert np.sqrt(np.mean((dpsi - tr.r_radps) ** 2)) < 0.5 * np.sqrt(
        np.mean((dpsi + tr.r_radps) ** 2))
    lag = 30  # the yaw rate follows the rudder with a lag of a few seconds
    assert np.corrcoef(tr.rudder_rad[:-lag], tr.r_radps[lag:])[0, 1] > 0.3
    # apparent wind: air velocity relative to the ship, body frame, "from" angle off the bow
    wn = -tr.wind_speed_mps * np.cos(tr.wind_from_rad)
    we = -tr.wind_speed_mps * np.sin(tr.wind_from_rad)
    sn = tr.u_mps * np.cos(psi) - tr.v_mps * np.sin(psi)
    se = tr.u_mps * np.sin(psi) + tr.v_mps * np.cos(psi)
    an, ae = wn - sn, we - se
    ub = an * np.cos(psi) + ae * np.sin(psi)
    vb = -an * np.sin(psi) + ae * np.cos(psi)
    np.testing.assert_allclose(np.hypot(ub, vb), tr.extra["apparent_wind_speed_mps"],
                               atol=5e-3)
    angle = np.angle(np.exp(1j * (np.arctan2(-vb, -ub) - tr.extra["apparent_wind_from_rad"])))
    assert np.abs(angle).max() < 0.01


# ------------------------------------------------------------------------------------------
# Text encodings, line endings and located errors
# ------------------------------------------------------------------------------------------

HEADER = "t_s,north_m,east_m,heading_deg,rudder_deg,rpm"


def _write(tmp_path: Path, text: str | bytes, name: str = "t.csv") -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_bytes(text.encode("utf-8"))
    return path


def _located(path: Path, **kwargs) -> DataError:
    with pytest.raises(DataError) as info:
        read_trial(path, **kwargs)
    return info.value


def test_bom_and_crlf_read_like_plain_text(tmp_path: Path) -> None:
    """A UTF-8 byte order mark and Windows line ends change nothing: the header's first name
    is still ``t_s`` (not ``\\ufefft_s``) and every value is the same."""
    body = f"{HEADER},gnss_n\n0,1.5,2,90,-5,120,7\n0.5,2.5,3,91,-4,121,8\n"
    plain = read_trial_csv(_write(tmp_path, body, "plain.csv"))
    odd = read_trial_csv(_write(tmp_path, b"\xef\xbb\xbf" + body.replace("\n", "\r\n")
                                .encode(), "odd.csv"))
    for key, value in plain.arrays().items():
        np.testing.assert_array_equal(getattr(odd, key), value)
    np.testing.assert_array_equal(odd.extra["gnss_n"], [7.0, 8.0])
    assert set(odd.extra) == {"gnss_n"}


def test_bom_and_crlf_keep_error_lines(tmp_path: Path) -> None:
    """Line numbers count the header as line 1 whatever the line ends: the bad cell sits on
    line 4 of the file."""
    body = f"{HEADER}\r\n0,0,0,0,0,60\r\n1,1,1,0,0,60\r\n2,2,x2,0,0,60\r\n"
    path = _write(tmp_path, b"\xef\xbb\xbf" + body.encode())
    err = _located(path)
    assert (err.path, err.line, err.key) == (str(path), 4, "east_m")
    assert str(err) == f"{path}:4: east_m: expected a number, got 'x2'"


def test_cr_only_line_ends_read_or_give_a_data_error(tmp_path: Path) -> None:
    """Old Mac / some loggers end lines with a bare CR: the file is either read (universal
    newlines) or refused with a located DataError, never a raw csv.Error."""
    path = _write(tmp_path, f"{HEADER}\r0,0,0,0,0,60\r1,1,1,0,0,60\r")
    try:
        tr = read_trial(path)
    except DataError as err:
        assert err.path == str(path)
        return
    np.testing.assert_array_equal(tr.t_s, [0.0, 1.0])


def test_not_text_folder_and_size_cap_name_the_file(tmp_path: Path, monkeypatch) -> None:
    path = _write(tmp_path, f"{HEADER}\n0,0,0,caf\xe9,0,60\n".encode("latin-1"))
    err = _located(path)
    assert err.path == str(path) and "not a text file" in err.message
    err = _located(tmp_path)
    assert err.path == str(tmp_path) and "folder" in err.message
    from trafficsim.io import trialdata

    good = _write(tmp_path, f"{HEADER}\n0,0,0,0,0,60\n1,0,0,0,0,60\n", "g.csv")
    size = good.stat().st_size
    monkeypatch.setattr(trialdata, "MAX_BYTES", size)
    assert read_trial(good).n == 2  # exactly at the cap: read
    monkeypatch.setattr(trialdata, "MAX_BYTES", size - 1)
    err = _located(good)
    assert err.path == str(good) and f"file is {size} bytes" in err.message


@pytest.mark.parametrize(("rows", "line", "expect"), [
    # equal time stamps: the second of the pair is named
    (["0,0,0,0,0,60", "1,0,0,0,0,60", "1,0,0,0,0,60"], 4, "got 1 after 1"),
    # going back in time
    (["0,0,0,0,0,60", "2,0,0,0,0,60", "1.5,0,0,0,0,60"], 4, "got 1.5 after 2"),
    # empty rows between do not shift the line of the offending row
    (["0,0,0,0,0,60", "", ",,,,,", "2,0,0,0,0,60", "", "1,0,0,0,0,60"], 7, "got 1 after 2"),
    # an infinite or 'NaN' time is not a time
    (["0,0,0,0,0,60", "inf,0,0,0,0,60"], 3, "got an infinite value"),
    (["0,0,0,0,0,60", "1,0,0,0,0,60", "NaN,0,0,0,0,60"], 4,
     "expected a finite time in every row, got an empty cell or nan"),
    # a trailing comma is a seventh value
    (["0,0,0,0,0,60", "1,0,0,0,0,60,"], 3, "expected 6 values as in the header, got 7"),
    # a bad cell after blank lines, in the last column
    (["0,0,0,0,0,60", "", "1,0,0,0,0,sixty"], 4, "rpm: expected a number, got 'sixty'"),
    # a control character is shown, not printed
    (["0,0,0,0,0,60", "1,0,0,0,2.5\x00,60"], 3, "rudder_deg: expected a number, got '2.5\\x00'"),
])
def test_errors_name_file_and_line_of_the_row(tmp_path: Path, rows, line, expect) -> None:
    path = _write(tmp_path, HEADER + "\n" + "\n".join(rows) + "\n")
    err = _located(path)
    assert err.path == str(path) and err.line == line, str(err)
    assert expect in str(err)
    assert str(err).startswith(f"{path}:{line}: ")


@pytest.mark.parametrize("rows", [[], ["0,0,0,0,0,60"], ["0,0,0,0,0,60", ",,,,,", ""]])
def test_fewer_than_two_data_rows(tmp_path: Path, rows) -> None:
    """A header alone, or one sample (empty rows do not count), has no time step."""
    path = _write(tmp_path, HEADER + "\n" + "\n".join(rows) + ("\n" if rows else ""))
    err = _located(path)
    assert err.path == str(path) and "fewer than two data rows" in err.message


def test_header_and_cells_are_trimmed_and_nan_spellings_are_missing(tmp_path: Path) -> None:
    """Spaces around names and values are ignored; empty, 'nan' and 'NaN' cells are missing
    values (counted), quoted numbers are numbers."""
    body = (" t_s , north_m,east_m ,heading_deg,rudder_deg,rpm\n"
            ' 0 ,"12.5",  ,NaN,0,60\n'
            "1,nan,3,90,0, 60 \n")
    tr = read_trial_csv(_write(tmp_path, body))
    np.testing.assert_array_equal(tr.north_m, [12.5, np.nan])
    np.testing.assert_array_equal(tr.east_m, [np.nan, 3.0])
    assert tr.missing["north_m"] == 1 and tr.missing["east_m"] == 1
    assert tr.missing["psi_rad"] == 1 and tr.missing["rps"] == 0
    assert tr.nan_report()["nan_counts"] == {"north_m": 1, "east_m": 1, "psi_rad": 1}


def test_units_are_converted_at_the_edge(tmp_path: Path) -> None:
    """Degrees -> radians, rpm -> rev/s, knots -> m/s (1 kn = 1852/3600 m/s), each value
    checked by hand; ``to_csv_columns`` gives the file's numbers back."""
    body = (HEADER + ",r_degps,sog_kn,cog_deg,wind_speed_mps,wind_from_deg,u_mps\n"
            "0,1,2,90,-10,120,1.5,10,180,7,270,5\n"
            "2,3,4,360,35,-60,0,0,0,0,0,4\n")
    tr = read_trial_csv(_write(tmp_path, body))
    np.testing.assert_allclose(tr.psi_rad, [np.pi / 2, 2 * np.pi])
    np.testing.assert_allclose(tr.rudder_rad, [-np.pi / 18, 35 * np.pi / 180])
    np.testing.assert_allclose(tr.rps, [2.0, -1.0])
    np.testing.assert_allclose(tr.r_radps, [1.5 * np.pi / 180, 0.0])
    np.testing.assert_allclose(tr.sog_mps, [5.144444444444445, 0.0])  # 10 * 1852 / 3600
    np.testing.assert_allclose(tr.cog_rad, [np.pi, 0.0])
    np.testing.assert_allclose(tr.wind_from_rad, [1.5 * np.pi, 0.0])
    assert tr.has_wind and tr.v_mps is None and tr.extra == {}
    assert tr.duration_s == 2.0 and tr.dt_s == 2.0 and tr.n == 2
    back = tr.to_csv_columns()
    np.testing.assert_allclose(back["rpm"], [120.0, -60.0])
    np.testing.assert_allclose(back["sog_kn"], [10.0, 0.0])
    np.testing.assert_allclose(back["heading_deg"], [90.0, 360.0])
    assert "v_mps" not in back


def test_column_mapping_keeps_the_replaced_column(tmp_path: Path) -> None:
    body = HEADER + ",fix_n,fix_e\n0,1,2,0,0,60,11,22\n1,3,4,0,0,60,33,44\n"
    path = _write(tmp_path, body)
    tr = read_trial(path, columns={"north_m": "fix_n", "east_m": "fix_e"})
    np.testing.assert_array_equal(tr.north_m, [11.0, 33.0])
    np.testing.assert_array_equal(tr.east_m, [22.0, 44.0])
    np.testing.assert_array_equal(tr.extra["north_m_replaced"], [1.0, 3.0])
    np.testing.assert_array_equal(tr.extra["east_m_replaced"], [2.0, 4.0])
    assert set(tr.extra) == {"north_m_replaced", "east_m_replaced"}
    # an optional column that the file lacks can be supplied from another column
    tr = read_trial(path, columns={"u_mps": "fix_n"})
    np.testing.assert_array_equal(tr.u_mps, [11.0, 33.0])
    err = _located(path, columns={"north_m": "nope"})
    assert err.path == str(path) and err.line == 1 and "'nope'" in err.message


def test_from_arrays_agrees_with_the_file_and_locates_rows(tmp_path: Path) -> None:
    """In-memory columns read like the same CSV file; its errors have no file and count rows
    as a file would (header = line 1)."""
    cols = {"t_s": [0.0, 1.0, 2.0], "north_m": [0.0, 5.0, np.nan], "east_m": [1.0, 2.0, 3.0],
            "heading_deg": [0.0, 45.0, 90.0], "rudder_deg": [0.0, 1.0, 2.0],
            "rpm": [60.0, 60.0, 66.0], "gnss_n": [1.0, np.nan, 3.0]}
    mem = from_arrays("mem", cols)
    write_csv(tmp_path / "mem.csv", cols, fmt="%.17g")
    disk = read_trial_csv(tmp_path / "mem.csv")
    for key, value in disk.arrays().items():
        np.testing.assert_array_equal(getattr(mem, key), value)
    np.testing.assert_array_equal(mem.extra["gnss_n"], disk.extra["gnss_n"])
    assert mem.missing == disk.missing and mem.name == "mem" and mem.path == ""
    bad = dict(cols, t_s=[0.0, 1.0, 1.0])
    with pytest.raises(DataError) as info:
        from_arrays("mem", bad)
    assert info.value.path is None and info.value.line == 4


def test_take_and_with_series_recount_the_missing_values(tmp_path: Path) -> None:
    body = HEADER + "\n0,,0,0,0,60\n1,1,,0,0,60\n2,,,0,0,60\n3,3,3,0,0,60\n"
    tr = read_trial_csv(_write(tmp_path, body))
    assert tr.missing["north_m"] == 2 and tr.missing["east_m"] == 2
    head = tr.take(slice(0, 2))  # rows 0, 1: one gap each
    assert head.n == 2 and head.missing["north_m"] == 1 and head.missing["east_m"] == 1
    tail = tr.take(np.array([False, False, False, True]))
    assert tail.missing["north_m"] == 0 and tail.duration_s == 0.0 and np.isnan(tail.dt_s)
    filled = tr.with_series(north_m=np.arange(4.0))
    assert filled.missing["north_m"] == 0 and filled.missing["east_m"] == 2
    with pytest.raises(KeyError):
        tr.with_series(speed=np.zeros(4))
    with pytest.raises(ValueError, match=r"expected shape \(4,\)"):
        tr.with_series(north_m=np.zeros(3))


def test_take_all_rows_keeps_the_missing_counts_of_extra_columns(tmp_path: Path) -> None:
    """Reading counts NaNs of the extra columns too; the same run restricted to all its rows
    (or with a series replaced by itself) must report the same counts."""
    body = HEADER + ",gnss_n\n0,0,0,0,0,60,\n1,1,1,0,0,60,5\n2,2,2,0,0,60,nan\n"
    tr = read_trial_csv(_write(tmp_path, body))
    assert tr.missing["gnss_n"] == 2
    assert tr.take(slice(None)).missing == tr.missing
    assert tr.with_series(north_m=tr.north_m).missing == tr.missing


# ------------------------------------------------------------------------------------------
# FRT-DS-ESSO format (units in the column names), synthetic files
# ------------------------------------------------------------------------------------------

FRT_HEADER = ("t [s],x_position_mid [m],y_position_mid [m],psi_hat [rad],u_velo [m/s],"
              "vm_velo [m/s],r_angvelo [rad/s],n_prop [rps],delta_rudder [rad],"
              "wind_velo_true [m/s],wind_dir_true [rad],wind_velo_relative_mid [m/s],"
              "wind_dir_relative_mid [rad],temperature [degC]")


def test_frt_columns_map_without_conversion_and_trailing_empty_rows_drop(tmp_path: Path
                                                                         ) -> None:
    """Every FRT column lands in its field unchanged (already SI and radians); the relative
    wind goes to extras under its documented names, an unknown column under its own name;
    trailing empty rows are dropped and counted; a BOM and CRLF change nothing."""
    rows = ["0,1,2,0.5,3,-0.1,0.01,10,0.2,4,3.1,5,-0.7,20",
            "0.1,1.3,2.1,0.51,3,-0.1,0.011,10,0.2,4,3.1,5,-0.7,",
            ",,,,,,,,,,,,,", ",,,,,,,,,,,,,"]
    text = FRT_HEADER + "\r\n" + "\r\n".join(rows) + "\r\n"
    path = _write(tmp_path, b"\xef\xbb\xbf" + text.encode(), "run_1.csv")
    tr = read_trial(path)
    assert tr.name == "run_1" and tr.n == 2 and tr.dropped_rows == 2
    np.testing.assert_array_equal(tr.t_s, [0.0, 0.1])
    np.testing.assert_array_equal(tr.north_m, [1.0, 1.3])
    np.testing.assert_array_equal(tr.east_m, [2.0, 2.1])
    np.testing.assert_array_equal(tr.psi_rad, [0.5, 0.51])
    np.testing.assert_array_equal(tr.v_mps, [-0.1, -0.1])
    np.testing.assert_array_equal(tr.r_radps, [0.01, 0.011])
    np.testing.assert_array_equal(tr.rps, [10.0, 10.0])
    np.testing.assert_array_equal(tr.rudder_rad, [0.2, 0.2])
    np.testing.assert_array_equal(tr.wind_from_rad, [3.1, 3.1])
    assert set(tr.extra) == {"apparent_wind_speed_mps", "apparent_wind_from_rad",
                             "temperature [degC]"}
    np.testing.assert_array_equal(tr.extra["apparent_wind_from_rad"], [-0.7, -0.7])
    assert tr.missing["temperature [degC]"] == 1
    assert tr.nan_report()["dropped_empty_rows"] == 2


def test_frt_errors_name_the_columns_with_units(tmp_path: Path) -> None:
    header = FRT_HEADER.replace("n_prop [rps],", "").replace(",temperature [degC]", "")
    path = _write(tmp_path, header + "\n" + ",".join(["0"] * 12) + "\n")
    err = _located(path)
    assert err.line == 1 and "'n_prop [rps]'" in err.message
    good = _write(tmp_path, FRT_HEADER + "\n" + ",".join(["0"] * 14) + "\n"
                  + "0.1," + ",".join(["bad"] + ["0"] * 12) + "\n", "g.csv")
    err = _located(good)
    assert (err.line, err.key) == (3, "x_position_mid [m]")
    fine = _write(tmp_path, FRT_HEADER + "\n" + ",".join(["0"] * 14) + "\n"
                  + "0.1," + ",".join(["0"] * 13) + "\n", "f.csv")
    assert read_trial(fine).n == 2
    with pytest.raises(DataError, match="not FRT-DS-ESSO"):
        read_trial(fine, columns={"north_m": "x_position_mid [m]"})
    # the trial-data reader does not take an FRT file for one
    with pytest.raises(DataError, match="missing column"):
        read_trial_csv(fine)


@pytest.mark.parametrize("header, lacking", [
    (",wind_speed_mps", "wind_from_deg"),
    (",wind_from_deg", "wind_speed_mps"),
])
def test_wind_speed_and_direction_come_together(tmp_path: Path, header: str, lacking: str
                                                ) -> None:
    """A true wind speed without the direction it blows from (or the reverse) would be read as
    no wind at all: refused at the header, naming the missing column."""
    path = _write(tmp_path, HEADER + header + "\n0,0,0,0,0,60,5\n1,1,1,0,0,60,5\n")
    err = _located(path)
    assert (err.line, err.key) == (1, lacking)
    assert str(err).startswith(f"{path}:1: {lacking}: missing column, needed with ")
    mapped = _write(tmp_path, HEADER + ",anemometer_mps\n0,0,0,0,0,60,5\n1,1,1,0,0,60,5\n",
                    "m.csv")
    with pytest.raises(DataError) as raised:
        read_trial(mapped, columns={"wind_speed_mps": "anemometer_mps"})
    assert (raised.value.path, raised.value.key) == (str(mapped), "wind_from_deg")


@pytest.mark.parametrize("drop, lacking", [
    ("wind_dir_true [rad],", "wind_dir_true [rad]"),
    ("wind_velo_true [m/s],", "wind_velo_true [m/s]"),
])
def test_frt_wind_speed_and_direction_come_together(tmp_path: Path, drop: str, lacking: str
                                                    ) -> None:
    header = FRT_HEADER.replace(drop, "")
    path = _write(tmp_path, header + "\n" + ",".join(["0"] * 13) + "\n"
                  + "0.1," + ",".join(["0"] * 12) + "\n")
    err = _located(path)
    assert (err.path, err.line, err.key) == (str(path), 1, lacking)
