"""Result files: atomic writes (a reader sees the old file or the new one, never a part, and no
temp file is left behind), JSON without NaN, and table reads that name the file."""

import json
import math

import numpy as np
import pytest

from trafficsim.errors import DataError
from trafficsim.io.results import (
    atomic_write,
    read_parquet,
    write_csv,
    write_json,
    write_parquet,
)


def test_a_write_that_fails_keeps_the_old_file_and_leaves_no_temp_file(tmp_path):
    path = tmp_path / "summary.json"
    write_json(path, {"n": 1})

    def crash(fh):
        fh.write(b'{"n": 2, "half')
        raise RuntimeError("killed mid-write")

    with pytest.raises(RuntimeError, match="killed mid-write"):
        atomic_write(path, crash)
    assert json.loads(path.read_text()) == {"n": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]


def test_a_write_creates_its_folder_and_replaces_the_file_whole(tmp_path):
    path = tmp_path / "a" / "b" / "x.bin"
    atomic_write(path, lambda fh: fh.write(b"first, longer"))
    atomic_write(path, lambda fh: fh.write(b"second"))
    assert path.read_bytes() == b"second"
    assert [p.name for p in path.parent.iterdir()] == ["x.bin"]


def test_json_turns_nan_and_inf_into_null_and_numpy_into_plain_values(tmp_path):
    path = tmp_path / "s.json"
    write_json(path, {"nan": math.nan, "inf": np.float64(np.inf), "int": np.int64(3),
                      "flag": np.bool_(True), "arr": np.array([1.0, np.nan]),
                      "nested": [{"x": -math.inf}, (np.float32(0.5),)]})
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"nan": None, "inf": None, "int": 3, "flag": True,
                                "arr": [1.0, None], "nested": [{"x": None}, [0.5]]}


def test_parquet_round_trips_and_a_reader_asks_for_its_columns(tmp_path):
    path = tmp_path / "t.parquet"
    write_parquet(path, {"t_s": np.array([0.0, 1.0]), "ship": ["a", "b"]})
    table = read_parquet(path, "trajectories", ("t_s", "ship"))
    assert table.column("ship").to_pylist() == ["a", "b"]
    assert read_parquet(path, columns=("t_s",), only=True).column_names == ["t_s"]
    with pytest.raises(DataError, match=r"t\.parquet.*columns missing: speed_kn"):
        read_parquet(path, "trajectories", ("t_s", "speed_kn"))


@pytest.mark.parametrize("content", [b"", b"PAR1 not really", b"\x00" * 64])
def test_a_damaged_table_is_one_error_naming_the_file(tmp_path, content):
    path = tmp_path / "encounters.parquet"
    path.write_bytes(content)
    with pytest.raises(DataError, match=r"encounters\.parquet.*unreadable encounters table"):
        read_parquet(path, "encounters table")


def test_csv_has_a_header_and_the_numbers(tmp_path):
    path = tmp_path / "trial.csv"
    write_csv(path, {"t_s": np.array([0.0, 0.5]), "speed_kn": np.array([12.0, 11.75])})
    lines = path.read_text().splitlines()
    assert lines == ["t_s,speed_kn", "0,12", "0.5,11.75"]


def test_bearings_rounded_up_to_360_are_written_as_0(tmp_path):
    """359.9996 deg reads "360" at six significant digits, outside [0, 360): written as 0; a
    bearing that stays below, and any other column, is written as it is."""
    path = tmp_path / "t.csv"
    write_csv(path, {"heading_deg": np.array([359.9996, 359.999, 12.5]),
                     "gnss_cog_deg": np.array([359.99999, 0.0, 180.0]),
                     "rudder_deg": np.array([359.9996, 0.0, 1.0])})
    rows = [line.split(",") for line in path.read_text().splitlines()]
    assert rows[1] == ["0", "0", "360"] and rows[2] == ["359.999", "0", "0"]
    assert rows[3] == ["12.5", "180", "1"]
