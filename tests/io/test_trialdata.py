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
from trafficsim.io.trialdata import REQUIRED_CSV, read_trial, read_trial_csv
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
     "expected a time in every row"),
    ("", 1, "empty file"),
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
