"""Campaign runs: the same rows whatever the chunking, worker count or executor; a killed run
resumes to the same result; a folder of another spec is refused."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from trafficsim.campaign import execute
from trafficsim.campaign.execute import chunks, read_rows, run_campaign
from trafficsim.campaign.generator import draw
from trafficsim.campaign.runner import run_chunk
from trafficsim.campaign.spec import load_spec
from trafficsim.cli import main
from trafficsim.errors import InputError

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
    assert "another campaign" in err and "Traceback" not in err
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


@pytest.mark.parametrize("address", ["garbage", "tcp://", "tcp://host:notaport",
                                     "http://127.0.0.1:8786", "tcp://[::1", "tcp://:8786",
                                     "tcp://host:0", "inproc://"])
def test_a_bad_dask_address_exits_2_naming_the_flag_before_anything_is_made(
        write_spec, tmp_path, capsys, address):
    from tests.conftest import error_line

    out = tmp_path / "o"
    line = error_line(capsys, ["campaign", write_spec(), "--out", out, "--executor", "dask",
                               "--address", address])
    assert line == ("trafficsim: error: --address: expected a Dask scheduler address "
                    f"tcp://HOST:PORT (e.g. tcp://127.0.0.1:8786), got '{address}'")
    assert not out.exists()


def test_no_dask_scheduler_at_the_address_exits_2_naming_the_flag(write_spec, tmp_path,
                                                                    capsys):
    import dask

    from tests.conftest import error_line

    out = tmp_path / "o"
    with dask.config.set({"distributed.comm.timeouts.connect": "0.2s"}):
        line = error_line(capsys, ["campaign", write_spec(), "--out", out, "--executor",
                                   "dask", "--address", "tcp://127.0.0.1:1"])
    assert line.startswith("trafficsim: error: --address: no Dask scheduler reached at "
                           "'tcp://127.0.0.1:1' (Timed out trying to connect")
    assert line.endswith("expected the address of a running scheduler, tcp://HOST:PORT")
    assert not out.exists()


def test_a_spec_no_encounter_can_be_drawn_from_is_refused_before_anything_is_made(
        write_spec, tmp_path, capsys):
    """Same-speed ships cannot overtake: the campaign says so at the spec's line of
    encounter_types.overtaking and makes no folder, so that the corrected spec runs in the
    same --out (a folder would record the faulty spec's inputs and refuse the corrected one)."""
    from tests.conftest import error_line

    spec = write_spec(n=2, duration=120,
                      extra="encounter_types: {overtaking: 1}\nspeed_fraction: [1.0, 1.0]")
    spec.write_text(spec.read_text().replace("{cargo: 2, container: 1, fishing: 1}",
                                             "{cargo: 1}"))
    out = tmp_path / "o"
    line = error_line(capsys, ["campaign", spec, "--out", out, "--workers", "1",
                               "--no-progress"])
    assert line.startswith(f"trafficsim: error: {spec}:9: encounter_types.overtaking: no "
                           "geometry for overtaking in 1000 draws")
    assert not out.exists()
    spec.write_text(spec.read_text().replace("[1.0, 1.0]", "[0.6, 1.0]"))
    assert main(["campaign", str(spec), "--out", str(out), "--workers", "1",
                 "--no-progress"]) == 0


def test_a_bad_ship_file_is_refused_before_anything_is_made(write_spec, tmp_path, capsys):
    """A ship file with a misspelt coefficient is located in that file before a folder is
    made (before, the campaign recorded it in campaign.json and then failed in a chunk)."""
    from tests.conftest import error_line
    from trafficsim.ships.library import LIBRARY_DIR

    text = (LIBRARY_DIR / "cargo.yaml").read_text()
    (tmp_path / "typo.yaml").write_text(text.replace("  K_prime:", "  K_prim:"))
    spec = write_spec(n=2, duration=120)
    spec.write_text(spec.read_text().replace("{cargo: 2,", "{typo.yaml: 2,"))
    out = tmp_path / "o"
    line = error_line(capsys, ["campaign", spec, "--out", out, "--workers", "1",
                               "--no-progress"])
    assert line.startswith(f"trafficsim: error: {tmp_path / 'typo.yaml'}:")
    assert "coefficients.K_prim: unknown coefficient" in line
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


@pytest.mark.parametrize("name", ["chunks/00000000-00000002.parquet", "chunks",
                                  "summary.json", "encounters.parquet", "campaign.json"])
def test_a_folder_or_file_where_the_campaign_expects_the_other_is_named(base, tmp_path, capsys,
                                                                        name):
    """Resuming with a folder in place of a chunk file (or of a file the campaign writes, or
    a file in place of chunks/) names that path and what was expected, not a temp file."""
    from tests.conftest import error_line

    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    path = out / name
    shutil.rmtree(path) if path.is_dir() else path.unlink()
    path.write_text("") if name == "chunks" else path.mkdir()
    line = error_line(capsys, ["campaign", spec, "--out", out, "--workers", "1",
                               "--no-progress"])
    what = ("the folder of the campaign's chunks (or nothing), found a file" if name == "chunks"
            else "a chunk file of the campaign's results (or nothing), found a folder"
            if name.startswith("chunks/") else
            f"the campaign's {name} (or nothing), found a folder")
    assert line == f"trafficsim: error: {path}: expected {what}; remove it"


# --------------------------------------------------------------------------------------------
# resuming after an interruption at any point, and the chunking, workers and executors
# --------------------------------------------------------------------------------------------

WEATHER = (SENSORS + "\ncurrent_kn: [0, 1]\nwind_mps: [0, 10]\ntcpa_min: [2, 5]")
# encounters 0..4 in chunks of two: (0, 2), (2, 4) and the short last chunk (4, 5)
N, CHUNK, DURATION = 5, 2, 300
CHUNK_NAMES = ["00000000-00000002.parquet", "00000002-00000004.parquet",
               "00000004-00000005.parquet"]


def _spec_text(chunk: int = CHUNK) -> str:
    from tests.campaign.conftest import SMALL

    return SMALL.format(n=N, chunk=chunk, duration=DURATION, extra=WEATHER, rogue=0.3)


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """One uninterrupted run of a small campaign (rules, rogues, instruments, current, wind):
    the reference every interrupted run must end up identical to."""
    folder = tmp_path_factory.mktemp("base")
    spec = folder / "spec.yaml"
    spec.write_text(_spec_text())
    summary = run_campaign(spec, folder / "out", workers=1, progress=False)
    return spec, folder / "out", summary


def _copy(base_out: Path, tmp_path: Path) -> Path:
    out = tmp_path / "copy"
    shutil.copytree(base_out, out)
    return out


@pytest.fixture
def jobs(monkeypatch):
    """The chunks a run computes (in-process runs look ``_job`` up at each call)."""
    ran: list[tuple[int, int]] = []
    real = execute._job

    def job(spec_path, start, stop):
        ran.append((start, stop))
        return real(spec_path, start, stop)

    monkeypatch.setattr(execute, "_job", job)
    return ran


def _without_rate(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k != "ship_steps_per_s"}


def _stamps(out: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in (out / "chunks").glob("*.parquet")}


@pytest.mark.parametrize(("n", "chunk", "expected"), [
    (1, 1, [(0, 1)]),
    (5, 2, [(0, 2), (2, 4), (4, 5)]),
    (6, 3, [(0, 3), (3, 6)]),
    (3, 500, [(0, 3)]),
    (4, 1, [(0, 1), (1, 2), (2, 3), (3, 4)]),
])
def test_chunks_cut_the_encounters_into_consecutive_ranges(write_spec, n, chunk, expected):
    """Chunks are ``[start, stop)`` ranges of ``chunk_encounters`` that tile ``0 .. n - 1``
    without gap or overlap, the last one short when ``chunk`` does not divide ``n``."""
    got = chunks(load_spec(write_spec(n=n, chunk=chunk)))
    assert got == expected
    covered = [i for a, b in got for i in range(a, b)]
    assert covered == list(range(n))


def test_the_base_run_writes_every_chunk_and_no_temp_file(base):
    """Every chunk is a file named by its range; every write was renamed into place (no
    ``.NAME.*.tmp`` left); the ship-steps are the ships of every drawn encounter times the
    steps (300 s of 1 s steps), worked out from the generator alone."""
    spec_path, out, summary = base
    assert sorted(p.name for p in (out / "chunks").iterdir()) == CHUNK_NAMES
    assert not list(out.rglob("*.tmp"))
    spec = load_spec(spec_path)
    assert summary["ship_steps"] == sum(len(draw(spec, i).ships) for i in range(N)) * DURATION
    steps = sum(int(pq.read_schema(out / "chunks" / n).metadata[b"ship_steps"])
                for n in CHUNK_NAMES)
    assert steps == summary["ship_steps"]
    assert json.loads((out / "summary.json").read_text())["ship_steps"] == summary["ship_steps"]


def test_the_gathered_rows_are_one_batch_of_every_encounter(base):
    """``encounters.parquet`` (three chunks gathered in encounter order) holds exactly the rows
    of all five encounters simulated as one batch: chunk boundaries leave no trace."""
    spec_path, out, _ = base
    whole = run_chunk(load_spec(spec_path), 0, N)
    table = _table(out)
    assert table.keys() == {k for k in whole if not k.startswith("_")}
    for key in table:
        _equal(np.asarray(whole[key]).tolist(), table[key], key)
    assert table["encounter"] == sorted(table["encounter"])
    assert set(table["encounter"]) == set(range(N))


def test_a_chunk_missing_in_the_middle_is_the_only_one_run_again(base, tmp_path, jobs):
    """Deleting the middle chunk and the gathered results (a run killed after chunks 1 and 3
    were written, as ``as_completed`` may order them): the rerun computes that chunk alone,
    leaves the others untouched and ends identical to the uninterrupted run."""
    _, base_out, summary = base
    spec = base[0]
    out = _copy(base_out, tmp_path)
    for name in ("encounters.parquet", "summary.json", "cpa_histogram.png",
                 "rates_by_type.png", "chunks/" + CHUNK_NAMES[1]):
        (out / name).unlink()
    before = _stamps(out)
    again = run_campaign(spec, out, workers=1, progress=False)
    assert jobs == [(2, 4)]
    after = _stamps(out)
    assert {k: after[k] for k in before} == before
    _same(_table(base_out), _table(out))
    assert _without_rate(again) == _without_rate(summary)


def test_stale_temp_files_of_an_interrupted_write_change_nothing(base, tmp_path, jobs):
    """A run killed inside ``atomic_write`` leaves ``.NAME.XXXX.tmp`` beside the missing file:
    the rerun neither mistakes it for a chunk nor is disturbed by it."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    (out / "chunks" / CHUNK_NAMES[2]).unlink()
    (out / "encounters.parquet").unlink()
    half = (base_out / "chunks" / CHUNK_NAMES[2]).read_bytes()
    (out / "chunks" / f".{CHUNK_NAMES[2]}.k3j9x_.tmp").write_bytes(half[: len(half) // 2])
    (out / ".encounters.parquet.a1b2c3.tmp").write_bytes(b"PAR1 half")
    run_campaign(spec, out, workers=1, progress=False)
    assert jobs == [(4, 5)]
    _same(_table(base_out), _table(out))
    assert sorted(p.name for p in (out / "chunks").glob("*.parquet")) == CHUNK_NAMES


@pytest.mark.parametrize("cut", ["half", "header", "footer_gone"])
def test_a_partially_written_chunk_is_run_again(base, tmp_path, jobs, cut):
    """A chunk file cut short (as a non-atomic copy or a full disk leaves it: half the bytes,
    only the ``PAR1`` magic, or all but the last 8 footer bytes) does not read, so it is
    computed again and the result is identical."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    path = out / "chunks" / CHUNK_NAMES[1]
    data = path.read_bytes()
    path.write_bytes({"half": data[: len(data) // 2], "header": data[:4],
                      "footer_gone": data[:-8]}[cut])
    (out / "encounters.parquet").unlink()
    run_campaign(spec, out, workers=1, progress=False)
    assert jobs == [(2, 4)]
    _same(_table(base_out), _table(out))


def test_a_chunk_damaged_inside_is_run_again(base, tmp_path, jobs):
    """The docstring: a chunk "damaged from outside, which no longer reads" is run again.
    Bytes overwritten in the data pages, footer intact: ``pq.read_table`` fails on it (checked
    here), so it no longer reads and must be recomputed, not end the resume in a traceback."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    path = out / "chunks" / CHUNK_NAMES[0]
    data = bytearray(path.read_bytes())
    data[100:600] = b"\xab" * 500
    path.write_bytes(bytes(data))
    with pytest.raises(Exception):  # noqa: B017 - any pyarrow failure: it does not read
        pq.read_table(path)
    (out / "encounters.parquet").unlink()
    run_campaign(spec, out, workers=1, progress=False)
    assert jobs == [(0, 2)]
    _same(_table(base_out), _table(out))


def test_a_parquet_file_without_the_chunk_metadata_is_not_a_finished_chunk(base, tmp_path,
                                                                           jobs):
    """A readable Parquet file at a chunk's name but without the ``ship_steps`` metadata every
    finished chunk carries (a file put there by something else) is computed again."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    path = out / "chunks" / CHUNK_NAMES[2]
    pq.write_table(pq.read_table(path).replace_schema_metadata(None), path)
    run_campaign(spec, out, workers=1, progress=False)
    assert jobs == [(4, 5)]
    assert b"ship_steps" in pq.read_schema(path).metadata
    _same(_table(base_out), _table(out))


def test_every_chunk_has_the_schema_a_resume_expects(base):
    """The schema a resumed campaign holds a chunk to (:data:`trafficsim.campaign.runner.
    COLUMNS`) is the one the runner writes, column for column: otherwise every chunk would run
    again."""
    _, out, _ = base
    for name in CHUNK_NAMES:
        schema = pq.read_schema(out / "chunks" / name).remove_metadata()
        assert schema.equals(execute._chunk_schema()), (name, schema)


@pytest.mark.parametrize("damage", ["dropped", "strings", "renamed", "empty values"])
def test_a_chunk_resaved_with_another_schema_is_run_again(base, tmp_path, jobs, damage):
    """A chunk re-saved with its metadata but a column dropped, of another type, renamed or
    with empty values reads, yet cannot be gathered with the others: it counts as damaged and
    runs again (before, the resume ended in pyarrow's "Schema ... was different" dump)."""
    import pyarrow as pa

    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    path = out / "chunks" / CHUNK_NAMES[1]
    table = pq.read_table(path)
    k = table.column_names.index("collision")
    table = {"dropped": lambda t: t.remove_column(k),
             "strings": lambda t: t.set_column(k, "collision", pa.array(
                 [str(v) for v in t.column(k).to_pylist()])),
             "renamed": lambda t: t.rename_columns(
                 [c if c != "collision" else "collided" for c in t.column_names]),
             "empty values": lambda t: t.set_column(k, "collision", pa.array(
                 [None] * t.num_rows, pa.bool_())),
             }[damage](table).replace_schema_metadata(table.schema.metadata)
    pq.write_table(table, path)
    assert b"ship_steps" in pq.read_schema(path).metadata
    for name in ("encounters.parquet", "summary.json"):
        (out / name).unlink()
    run_campaign(spec, out, workers=1, progress=False)
    assert jobs == [(2, 4)]
    _same(_table(base_out), _table(out))


def test_a_campaign_failing_before_its_first_chunk_leaves_no_manifest(write_spec, tmp_path):
    """Two-minute encounters with TCPA 1-2 min pass ``validate`` (one encounter of each type
    draws), but no multi-ship geometry is found for encounter 3. A campaign that fails so
    before any chunk is written leaves no ``campaign.json``, so the corrected spec runs in the
    same folder instead of being refused as "another campaign"; once a chunk is written the
    manifest stays, to guard it."""
    from trafficsim.campaign.generator import NoGeometryError, spec_errors

    spec = write_spec(n=4, chunk=4, duration=120)
    assert spec_errors(load_spec(spec)) == []
    out = tmp_path / "o"
    with pytest.raises(NoGeometryError, match="encounter 3: no geometry"):
        run_campaign(spec, out, workers=1, progress=False)
    assert not (out / "campaign.json").exists() and not list(out.rglob("*.parquet"))
    spec.write_text(spec.read_text().replace("duration_s: 120", "duration_s: 600").replace(
        "tcpa_min: [1, 2]", "tcpa_min: [3, 10]"))
    assert run_campaign(spec, out, workers=1, progress=False)["n_encounters"] == 4
    halves = write_spec(n=4, chunk=2, duration=120, name="halves.yaml")
    with pytest.raises(NoGeometryError, match="encounter 3: no geometry"):
        run_campaign(halves, tmp_path / "p", workers=1, progress=False)
    assert (tmp_path / "p" / "campaign.json").is_file()  # beside chunk 0-2
    assert [f.name for f in (tmp_path / "p" / "chunks").iterdir()] == [
        "00000000-00000002.parquet"]


def test_interrupted_between_chunks_resumes_with_the_rest(base, tmp_path, monkeypatch):
    """A Ctrl-C right after the first chunk is written: one chunk on disk, nothing gathered, no
    temp file; the rerun computes only the other two and ends identical."""
    spec, base_out, summary = base
    out = tmp_path / "out"
    real = execute._write_chunk
    written: list[str] = []

    def write_then_stop(path, rows, digest):
        if written:
            raise KeyboardInterrupt
        real(path, rows, digest)
        written.append(path.name)

    monkeypatch.setattr(execute, "_write_chunk", write_then_stop)
    with pytest.raises(KeyboardInterrupt):
        run_campaign(spec, out, workers=1, progress=False)
    assert [p.name for p in (out / "chunks").iterdir()] == written == [CHUNK_NAMES[0]]
    assert not (out / "encounters.parquet").exists() and not list(out.rglob("*.tmp"))
    monkeypatch.setattr(execute, "_write_chunk", real)
    ran: list[tuple[int, int]] = []
    job = execute._job
    monkeypatch.setattr(execute, "_job", lambda p, a, b: ran.append((a, b)) or job(p, a, b))
    again = run_campaign(spec, out, workers=1, progress=False)
    assert ran == [(2, 4), (4, 5)]
    _same(_table(base_out), _table(out))
    assert _without_rate(again) == _without_rate(summary)


def test_a_write_failing_halfway_leaves_no_chunk_and_no_temp_file(base, tmp_path, monkeypatch):
    """A chunk write that dies after some bytes (a full disk) leaves neither a chunk file nor
    its temp file, so the next run cannot take half a chunk for a whole one."""
    spec, base_out, _ = base
    out = tmp_path / "out"
    real = execute.atomic_write
    calls = {"n": 0}

    def dying(path, write):
        calls["n"] += 1
        if calls["n"] < 2:
            return real(path, write)

        def half(fh):
            fh.write(b"PAR1" + b"\0" * 100)
            raise OSError(28, "No space left on device")

        return real(path, half)

    monkeypatch.setattr(execute, "atomic_write", dying)
    with pytest.raises(OSError, match="No space"):
        run_campaign(spec, out, workers=1, progress=False)
    assert sorted(p.name for p in (out / "chunks").iterdir()) == [CHUNK_NAMES[0]]
    monkeypatch.setattr(execute, "atomic_write", real)
    run_campaign(spec, out, workers=1, progress=False)
    _same(_table(base_out), _table(out))


def test_interrupted_while_gathering_finishes_without_running_a_chunk(base, tmp_path, jobs,
                                                                      monkeypatch):
    """Killed while drawing the figures (every chunk written, ``encounters.parquet`` perhaps
    too): the rerun runs no chunk and reports the rate of one worker from the chunks' own
    timings, ship-steps over seconds summed from their metadata."""
    import trafficsim.campaign.figures as figures

    spec, base_out, summary = base
    out = _copy(base_out, tmp_path)
    (out / "summary.json").unlink()
    (out / "rates_by_type.png").unlink()
    real = figures.write_figures

    def killed(rows, where):
        raise KeyboardInterrupt

    monkeypatch.setattr(figures, "write_figures", killed)
    with pytest.raises(KeyboardInterrupt):
        run_campaign(spec, out, workers=1, progress=False)
    monkeypatch.setattr(figures, "write_figures", real)
    again = run_campaign(spec, out, workers=1, progress=False)
    assert jobs == []
    metas = [pq.read_schema(out / "chunks" / n).metadata for n in CHUNK_NAMES]
    steps = sum(int(m[b"ship_steps"]) for m in metas)
    seconds = sum(float(m[b"seconds"]) for m in metas)
    assert again["ship_steps_per_s"] == pytest.approx(steps / seconds, rel=1e-12)
    assert _without_rate(again) == _without_rate(summary)
    _same(_table(base_out), _table(out))
    for name in ("summary.json", "rates_by_type.png", "cpa_histogram.png"):
        assert (out / name).stat().st_size > 0


def test_read_rows_gathers_in_encounter_order_whatever_the_write_order(base, tmp_path):
    """Chunks completed out of order (their files' times reversed) are read back by range:
    the rows come in encounter order, with the steps and seconds summed over the chunks."""
    spec_path, base_out, summary = base
    out = _copy(base_out, tmp_path)
    for k, name in enumerate(CHUNK_NAMES):
        os.utime(out / "chunks" / name, ns=(10**18 - k, 10**18 - k))
    rows, steps, seconds = read_rows(out, load_spec(spec_path))
    assert rows["encounter"].tolist() == _table(base_out)["encounter"]
    assert steps == summary["ship_steps"] and seconds > 0


def test_chunk_size_does_not_change_the_results(base, tmp_path):
    """The same campaign in chunks of 1 and of 5 (one batch) as of 2: identical rows and
    summaries (the rate aside)."""
    _, base_out, summary = base
    for chunk in (1, 5):
        spec = tmp_path / f"c{chunk}.yaml"
        spec.write_text(_spec_text(chunk))
        out = tmp_path / f"out{chunk}"
        other = run_campaign(spec, out, workers=1, progress=False)
        assert len(list((out / "chunks").glob("*.parquet"))) == len(range(0, N, chunk))
        _same(_table(base_out), _table(out))
        assert _without_rate(other) == _without_rate(summary)


def test_a_changed_spec_is_refused_and_the_folder_left_alone(base, tmp_path):
    """The folder's spec edited between runs (here only its chunk size, which would cut the
    encounters differently) is refused with an InputError: no chunk is added, removed or
    rewritten, and ``campaign.json`` still names the first spec."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    (out / "chunks" / CHUNK_NAMES[1]).unlink()
    manifest = (out / "campaign.json").read_text()
    before = _stamps(out)
    changed = tmp_path / "spec.yaml"
    changed.write_text(_spec_text(chunk=3))
    with pytest.raises(InputError, match="another campaign"):
        run_campaign(changed, out, workers=1, progress=False)
    assert _stamps(out) == before
    assert (out / "campaign.json").read_text() == manifest
    assert json.loads(manifest)["spec"] == str(spec)


def test_the_same_spec_bytes_elsewhere_resume_the_folder(base, tmp_path, jobs):
    """The folder is tied to the spec's content (its SHA-256), not its path: an identical copy
    of the spec finishes the campaign, computing only the missing chunk."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    (out / "chunks" / CHUNK_NAMES[0]).unlink()
    copy = tmp_path / "elsewhere" / "same.yaml"
    copy.parent.mkdir()
    copy.write_bytes(spec.read_bytes())
    run_campaign(copy, out, workers=1, progress=False)
    assert jobs == [(0, 2)]
    _same(_table(base_out), _table(out))


def test_an_unreadable_manifest_is_an_input_error(base, tmp_path):
    """``campaign.json`` that is not JSON is named in an InputError, not a traceback."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    (out / "campaign.json").write_text("{half a manifest")
    with pytest.raises(InputError, match=r"cannot read .*campaign\.json"):
        run_campaign(spec, out, workers=1, progress=False)


@pytest.mark.parametrize("text", ["[]", "null"])
def test_a_manifest_that_is_not_an_object_is_an_input_error(base, tmp_path, text):
    """Valid JSON that is not an object is no more a manifest than broken JSON: the
    documented InputError (as :func:`replay.campaign_spec` gives for the same file)."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    (out / "campaign.json").write_text(text)
    with pytest.raises(InputError):
        run_campaign(spec, out, workers=1, progress=False)


def test_resuming_on_a_threaded_dask_worker_gives_the_same_results(base, tmp_path):
    """Chunks deleted from a finished run and recomputed on a tiny in-process LocalCluster
    whose one worker runs two chunks at once in threads: identical results, so chunks share
    no state inside a process."""
    from distributed import LocalCluster

    spec, base_out, summary = base
    out = _copy(base_out, tmp_path)
    for name in (CHUNK_NAMES[0], CHUNK_NAMES[2], "../encounters.parquet"):
        (out / "chunks" / name).unlink()
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                      dashboard_address=None) as cluster:
        again = run_campaign(spec, out, executor="dask", address=cluster.scheduler_address,
                             progress=False)
    _same(_table(base_out), _table(out))
    assert _without_rate(again) == _without_rate(summary)



def _spec_with_files(folder: Path) -> Path:
    """A one-chunk-per-encounter spec whose ship type and rules are files beside it."""
    from trafficsim.colregs.decider import RULES_DIR
    from trafficsim.ships.library import find_ship

    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(find_ship("container"), folder / "mine.yaml")
    (folder / "rules.yaml").write_text("schema_version: 1\nname: mine\nextends: base.yaml\n"
                                       "parameters: {turn_deg: 40}\n")
    shutil.copy(RULES_DIR / "colregs.yaml", folder / "base.yaml")
    spec = folder / "spec.yaml"
    spec.write_text("schema_version: 1\nname: files\nn_encounters: 2\nseed: 3\n"
                    "duration_s: 300\ntcpa_min: [2, 5]\nchunk_encounters: 1\n"
                    "ship_types: {mine.yaml: 1}\n"
                    "rules: rules.yaml\n")
    return spec


@pytest.mark.parametrize("edit", ["mine.yaml", "rules.yaml", "base.yaml"])
def test_an_input_file_edited_between_runs_is_refused(tmp_path, edit):
    """The folder is tied to every file the spec reads, not the spec alone: a ship file, the
    rules file or the file it extends edited after a kill would mix old and new results, so
    the rerun is refused and nothing is written."""
    spec = _spec_with_files(tmp_path / "in")
    out = tmp_path / "out"
    run_campaign(spec, out, workers=1, progress=False)
    (out / "chunks" / "00000001-00000002.parquet").unlink()
    before = _stamps(out)
    path = tmp_path / "in" / edit
    path.write_text(path.read_text() + "\n# edited\n")
    with pytest.raises(InputError, match=r"another campaign .*ship or rules files changed"):
        run_campaign(spec, out, workers=1, progress=False)
    assert _stamps(out) == before


def test_the_inputs_digest_is_of_contents_not_places(tmp_path):
    """The whole input folder copied elsewhere has the same digest; one byte more in any of
    its files, another."""
    a = _spec_with_files(tmp_path / "a")
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    digest = execute.inputs_digest(load_spec(a))
    assert execute.inputs_digest(load_spec(tmp_path / "b" / "spec.yaml")) == digest
    for name in ("spec.yaml", "mine.yaml", "rules.yaml", "base.yaml"):
        f = tmp_path / "b" / name
        text = f.read_text()
        f.write_text(text + "\n")
        assert execute.inputs_digest(load_spec(tmp_path / "b" / "spec.yaml")) != digest, name
        f.write_text(text)


def test_a_chunk_of_other_inputs_is_refused_without_the_manifest(base, tmp_path):
    """With ``campaign.json`` deleted the chunks still name their inputs: another spec's run
    into the folder is refused instead of reusing them."""
    _, base_out, _ = base
    out = _copy(base_out, tmp_path)
    (out / "campaign.json").unlink()
    other = tmp_path / "other.yaml"
    other.write_text(_spec_text().replace("seed: 11", "seed: 12"))
    with pytest.raises(InputError, match="holds results of other inputs"):
        run_campaign(other, out, workers=1, progress=False)


def test_resuming_from_a_copy_of_the_spec_records_its_place(base, tmp_path):
    """The same inputs from another place finish the folder, and ``campaign.json`` then names
    that spec, which ``replay`` reads (the first may be gone)."""
    spec, base_out, _ = base
    out = _copy(base_out, tmp_path)
    copy = tmp_path / "moved" / "spec.yaml"
    copy.parent.mkdir()
    copy.write_bytes(spec.read_bytes())
    run_campaign(copy, out, workers=1, progress=False)
    assert json.loads((out / "campaign.json").read_text())["spec"] == str(copy)
