"""Campaign runs: the same rows whatever the chunking, worker count or executor; a killed run
resumes to the same result; a folder of another spec is refused."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from trafficsim.campaign.execute import run_campaign
from trafficsim.campaign.runner import run_chunk
from trafficsim.campaign.spec import load_spec
from trafficsim.cli import main

SENSORS = "sensors: {gnss_sigma_m: [1, 5], compass_sigma_deg: [0.1, 0.5]}"


def _table(out: Path) -> dict:
    return pq.read_table(out / "encounters.parquet").to_pydict()


def _equal(a, b, key: str) -> None:
    """Columns equal element by element (NaN equal to NaN)."""
    x, y = np.asarray(a), np.asarray(b)
    if x.dtype.kind in "fiub" and y.dtype.kind in "fiub":
        np.testing.assert_array_equal(x, y, err_msg=key)
    else:
        assert list(a) == list(b), key


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        _equal(a[key], b[key], key)


def test_rows_do_not_depend_on_the_chunking(write_spec):
    spec = load_spec(write_spec(n=4, extra=SENSORS, duration=600))
    whole = run_chunk(spec, 0, 4)
    parts = [run_chunk(spec, a, b) for a, b in ((0, 1), (1, 3), (3, 4))]
    for key, value in whole.items():
        if key.startswith("_"):
            continue
        joined = [v for p in parts for v in np.asarray(p[key]).tolist()]
        _equal(np.asarray(value).tolist(), joined, key)


def test_one_or_two_workers_and_dask_give_the_same_results(write_spec, tmp_path):
    from distributed import LocalCluster

    spec = write_spec(n=6, chunk=2, duration=600)
    one = run_campaign(spec, tmp_path / "one", workers=1, progress=False)
    two = run_campaign(spec, tmp_path / "two", workers=2, progress=False)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        dask = run_campaign(spec, tmp_path / "dask", executor="dask",
                            address=cluster.scheduler_address, progress=False)
    _same(_table(tmp_path / "one"), _table(tmp_path / "two"))
    _same(_table(tmp_path / "one"), _table(tmp_path / "dask"))
    for s in (two, dask):
        assert {k: v for k, v in s.items() if k != "ship_steps_per_s"} == {
            k: v for k, v in one.items() if k != "ship_steps_per_s"}
    assert one["n_encounters"] == 6 and one["ship_steps"] > 6 * 2 * 600
    for name in ("summary.json", "cpa_histogram.png", "rates_by_type.png"):
        assert (tmp_path / "one" / name).stat().st_size > 0


def test_a_killed_campaign_resumes_to_the_same_result(write_spec, tmp_path):
    spec = write_spec(n=8, chunk=1, duration=900)
    run_campaign(spec, tmp_path / "whole", workers=1, progress=False)
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "trafficsim", "campaign", str(spec), "--out", str(out),
           "--workers", "1", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    chunks = out / "chunks"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and len(list(chunks.glob("*.parquet"))) < 2:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list(chunks.glob("*.parquet")))
    assert 2 <= done < 8, "the kill came too late to test resuming"
    assert not (out / "encounters.parquet").exists()
    assert subprocess.run(cmd, capture_output=True).returncode == 0
    _same(_table(tmp_path / "whole"), _table(out))
    assert not list(chunks.glob(".*.tmp"))


def test_a_folder_of_another_spec_is_refused(write_spec, tmp_path, capsys):
    out = tmp_path / "out"
    run_campaign(write_spec(n=1, chunk=1, duration=300), out, workers=1, progress=False)
    other = write_spec(n=2, chunk=1, duration=300, name="other.yaml")
    assert main(["campaign", str(other), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "another campaign spec" in err and "Traceback" not in err
    assert json.loads((out / "campaign.json").read_text())["n_encounters"] == 1


def test_bad_flags_and_specs_exit_2(write_spec, tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        main(["campaign", str(write_spec()), "--out", str(tmp_path), "--workers", "0"])
    assert info.value.code == 2
    bad = write_spec(extra="n_encounters_typo: 3", name="bad.yaml")
    assert main(["campaign", str(bad), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:9:" in err and "n_encounters_typo" in err


def test_dask_without_an_address_exits_2_before_anything_is_made(write_spec, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["campaign", str(write_spec()), "--out", str(out), "--executor", "dask"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trafficsim: error: --executor dask needs --address")
    assert "chunk" not in err  # no progress bar began
    assert not out.exists()


def test_a_damaged_chunk_is_run_again(write_spec, tmp_path):
    """A chunk file that no longer reads (garbage, emptied) is redone, not a traceback."""
    spec = write_spec(n=3, chunk=1, duration=300)
    out = tmp_path / "o"
    run_campaign(spec, out, workers=1, progress=False)
    before = _table(out)
    paths = sorted((out / "chunks").glob("*.parquet"))
    paths[0].write_bytes(b"garbage")
    paths[2].write_bytes(b"")
    untouched = paths[1].stat().st_mtime_ns
    run_campaign(spec, out, workers=1, progress=False)
    _same(before, _table(out))
    assert paths[1].stat().st_mtime_ns == untouched  # only the damaged ones ran again
