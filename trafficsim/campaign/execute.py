"""Run a whole campaign: chunks on an executor, each written atomically; resumable.

The encounters are cut into chunks of ``chunk_encounters``. Every finished chunk is written to
``OUT/chunks/NNNNNNNN-MMMMMMMM.parquet`` (temp file, fsync, rename), so a campaign killed at any
point and started again with the same command runs only the missing chunks (and any chunk
damaged from outside, which no longer reads). ``OUT/campaign.json`` and every chunk record the
hash of the campaign's inputs (:func:`inputs_digest`: the spec and the ship and rules files it
names), so a folder or a chunk holding results of other inputs is refused: an edited ship file
cannot mix its results with the old ones (and so is a run's folder,
:mod:`trafficsim.folders`). The ship files are built and one encounter of every type is drawn
before anything is made. When every chunk
is there the rows are gathered in encounter order into ``encounters.parquet`` with
``summary.json`` and the figures. A chunk's rows do not depend on which executor, worker or
chunk neighbours computed it (:mod:`trafficsim.campaign.runner`), so the results are the same on
one worker, many, or a Dask cluster.

Executors: ``local`` runs chunks in ``workers`` processes (``spawn``ed, one thread of BLAS each;
``workers = 1`` runs in this process); ``dask`` submits them through
``distributed.Client(address).get_executor()``, the same ``concurrent.futures`` interface.
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import multiprocessing
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim import __version__
from trafficsim.campaign.spec import CampaignSpec, load_spec
from trafficsim.errors import InputError
from trafficsim.io.results import atomic_write, write_json, write_parquet


def chunks(spec: CampaignSpec) -> list[tuple[int, int]]:
    """``(start, stop)`` encounter ranges of the campaign's chunks."""
    c, n = spec.chunk_encounters, spec.n_encounters
    return [(s, min(s + c, n)) for s in range(0, n, c)]


def _chunk_path(out: Path, start: int, stop: int) -> Path:
    return out / "chunks" / f"{start:08d}-{stop:08d}.parquet"


def _chunk_schema() -> Any:
    """The ``pyarrow.Schema`` of a chunk's rows (:data:`~.runner.COLUMNS`), without metadata."""
    import pyarrow as pa

    from trafficsim.campaign.runner import COLUMNS

    return pa.schema([(name, pa.type_for_alias(kind)) for name, kind in COLUMNS.items()])


def _chunk_done(path: Path, digest: str) -> bool:
    """Whether ``path`` holds a finished chunk of the inputs of ``digest``. Chunks are written
    atomically, so only damage from outside (a disk fault, an edit) makes one unreadable or
    changes its columns (one dropped, added or of another type, or empty values) or timings;
    such a chunk is run again, as its rows are fixed by the inputs.

    Raises:
        InputError: the chunk holds results of other inputs, or is no file.
    """
    import pyarrow.parquet as pq

    if not path.exists():
        return False
    _expect_file(path, "a chunk file of the campaign's results")
    try:  # the whole table: damage inside the data leaves the footer readable
        table = pq.read_table(path)
    except (OSError, ValueError):  # (pyarrow's ArrowInvalid is a ValueError)
        return False
    meta = table.schema.metadata or {}
    written = meta.get(b"inputs_sha256")  # (absent in chunks of older versions)
    if written is not None and written.decode(errors="replace") != digest:
        raise InputError(f"{path} holds results of other inputs (another spec, or ship or "
                         "rules files changed since); use another --out folder or delete it")
    if (not table.schema.remove_metadata().equals(_chunk_schema())
            or any(column.null_count for column in table.columns)):
        return False
    try:
        int(meta[b"ship_steps"]), float(meta[b"seconds"])
    except (KeyError, ValueError):
        return False
    return True


def _spec_hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def inputs_digest(spec: CampaignSpec) -> str:
    """SHA-256 of everything a campaign reads from files: the spec, the ship files (or MMG
    parameter folders) its ``ship_types`` name and its ``rules`` file with the files that one
    extends. Contents only, so a copy of the lot elsewhere has the same digest."""
    from trafficsim.campaign.runner import rules_path
    from trafficsim.colregs.network import rules_digest
    from trafficsim.colregs.rulefile import parse_file
    from trafficsim.colregs.vocabulary import VOCABULARY
    from trafficsim.ships.library import find_ship

    assert spec.path is not None
    digest = hashlib.sha256()

    def add(role: str, path: Path) -> None:
        digest.update(f"{role}\0".encode())
        digest.update(hashlib.sha256(path.read_bytes()).digest())

    add("spec", spec.path)
    for kind in sorted(spec.ship_types):
        found = find_ship(kind, spec.path.parent)
        for f in sorted(found.iterdir()) if found.is_dir() else [found]:
            if f.is_file():
                add(f"ship {kind} {f.name if found.is_dir() else ''}", f)
    rules = rules_path(spec)
    if rules is not None:  # (the digest the decision records carry, of the file and its chain)
        digest.update(f"rules\0{rules_digest(parse_file(rules, VOCABULARY).files)}".encode())
    return digest.hexdigest()


def _job(spec_path: str, start: int, stop: int) -> dict[str, Any]:
    """One chunk, in a worker: load the spec, run, return the rows."""
    from trafficsim.campaign.runner import run_chunk

    return run_chunk(load_spec(spec_path), start, stop)


def _write_chunk(path: Path, rows: dict[str, Any], digest: str) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = {"ship_steps": str(rows["_ship_steps"]), "seconds": repr(rows["_seconds"]),
            "inputs_sha256": digest}
    table = pa.table({k: v for k, v in rows.items() if not k.startswith("_")})
    table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                           **{k.encode(): v.encode() for k, v in meta.items()}})
    atomic_write(path, lambda fh: pq.write_table(table, fh))


#: what the campaign writes into its folder beside ``chunks/``
OUTPUTS = ("campaign.json", "encounters.parquet", "summary.json", "cpa_histogram.png",
           "rates_by_type.png")


def _expect_file(path: Path, what: str) -> None:
    """Refuse a folder (or other non-file) where the campaign reads or writes a file."""
    if path.exists() and not path.is_file():
        found = "a folder" if path.is_dir() else "something other than a file"
        raise InputError(f"expected {what} (or nothing), found {found}; remove it",
                         path=str(path))


def _check_folder(out: Path, spec: CampaignSpec, digest: str) -> None:
    """Refuse a folder of another campaign's results or of a run's, or one with a folder where
    the campaign writes a file; record this one's (the spec's path is updated when the same
    inputs come from another place, for ``replay``)."""
    from trafficsim.folders import refuse_other_results

    assert spec.path is not None
    refuse_other_results(out, "campaign", "a campaign")
    for name in OUTPUTS:
        _expect_file(out / name, f"the campaign's {name}")
    if (out / "chunks").exists() and not (out / "chunks").is_dir():
        raise InputError("expected the folder of the campaign's chunks (or nothing), found a "
                         "file; remove it", path=str(out / "chunks"))
    manifest = out / "campaign.json"
    record = {"spec": str(spec.path), "spec_sha256": _spec_hash(spec.path),
              "inputs_sha256": digest, "name": spec.name, "n_encounters": spec.n_encounters,
              "chunk_encounters": spec.chunk_encounters, "trafficsim_version": __version__}
    if manifest.exists():
        try:
            old = json.loads(manifest.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot read {manifest}: {exc}") from None
        if not isinstance(old, dict):
            raise InputError(f"cannot read {manifest}: expected a JSON object, got "
                             f"{type(old).__name__}")
        # (a manifest of an older version holds the spec's hash only)
        same = (old.get("inputs_sha256") == digest if "inputs_sha256" in old
                else old.get("spec_sha256") == record["spec_sha256"])
        if not same:
            raise InputError(f"{out} holds results of another campaign (spec "
                             f"{old.get('spec', '?')}, or ship or rules files changed since); "
                             "use another --out folder or delete it")
        if old.get("spec") == record["spec"] and "inputs_sha256" in old:
            return
    write_json(manifest, record)


#: what ``--address`` takes, for its messages
DASK_ADDRESS = "a Dask scheduler address tcp://HOST:PORT (e.g. tcp://127.0.0.1:8786)"


def _dask_address(address: str) -> str:
    """``address`` if it reads as a scheduler address (``[tcp|tls|ws|wss|ucx]://HOST:PORT``,
    ``HOST:PORT``, or a ``LocalCluster``'s ``inproc://`` one).

    Raises:
        InputError: at ``--address``, anything else.
    """
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme == "inproc" and location:
            return address
        host, port = parse_host_port(location)
        if scheme not in ("tcp", "tls", "ws", "wss", "ucx") or not host or not 0 < port < 65536:
            raise ValueError(address)
    except (ValueError, TypeError):
        raise InputError(f"expected {DASK_ADDRESS}, got '{address}'", key="--address") from None
    return address


@contextmanager
def _executor(kind: str, workers: int, address: str | None) -> Iterator[cf.Executor | None]:
    if kind == "dask":
        from distributed import Client

        if address is None:
            raise InputError("--executor dask needs --address (a scheduler address, or a "
                             "distributed.LocalCluster's)")
        address = _dask_address(address)
        try:
            client = Client(address)
        except (OSError, ValueError, TypeError) as exc:  # (a timeout is an OSError)
            raise InputError(f"no Dask scheduler reached at '{address}' ({exc}); expected "
                             "the address of a running scheduler, tcp://HOST:PORT",
                             key="--address") from None
        with client:
            yield client.get_executor(pure=False)
        return
    if workers <= 1:
        yield None
        return
    # spawned workers inherit the environment and import numpy after it: one BLAS thread each
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    context = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        yield pool


def run_campaign(spec_path: str | os.PathLike[str], out_dir: str | os.PathLike[str],
                 workers: int | None = None, executor: str = "local",
                 address: str | None = None, progress: bool = True) -> dict[str, Any]:
    """Run (or finish) the campaign of ``spec_path`` into ``out_dir``; return the summary.

    Raises:
        InputError: a faulty spec (located), a bad ``address``, or ``out_dir`` holding
            another spec's results or a run's.
    """
    from tqdm import tqdm

    from trafficsim.campaign.generator import spec_errors

    spec = load_spec(spec_path)
    assert spec.path is not None
    errors = spec_errors(spec)  # before anything is made: a folder records its inputs
    if errors:
        raise errors[0]
    out = Path(out_dir)
    workers = (os.cpu_count() or 1) if workers is None else workers
    with _executor(executor, workers, address) as pool:  # (a bad executor flag: nothing made)
        out.mkdir(parents=True, exist_ok=True)
        digest = inputs_digest(spec)
        new = not (out / "campaign.json").exists()
        _check_folder(out, spec, digest)
        every = chunks(spec)
        todo = [c for c in every if not _chunk_done(_chunk_path(out, *c), digest)]
        t0 = time.perf_counter()
        ship_steps_now = 0
        bar = tqdm(total=len(every), initial=len(every) - len(todo), unit="chunk",
                   disable=not progress, desc=spec.name)
        try:
            if pool is None:
                results = ((c, _job(str(spec.path), *c)) for c in todo)
            else:
                futures = {pool.submit(_job, str(spec.path), *c): c for c in todo}
                results = ((futures[f], f.result()) for f in cf.as_completed(futures))
            for (start, stop), rows in results:
                _write_chunk(_chunk_path(out, start, stop), rows, digest)
                ship_steps_now += int(rows["_ship_steps"])
                bar.update(1)
        except BaseException:
            # nothing to resume: a corrected spec may start afresh in this folder
            if new and not any((out / "chunks").glob("*.parquet")):
                (out / "campaign.json").unlink(missing_ok=True)
            raise
    bar.close()
    wall = time.perf_counter() - t0
    return finish(spec, out, ship_steps_now / wall if ship_steps_now else None)


def read_rows(out: Path, spec: CampaignSpec) -> tuple[dict[str, np.ndarray], int, float]:
    """Every chunk's rows in encounter order, the ship-steps simulated and the seconds the
    chunks took (summed over workers)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    tables, steps, seconds = [], 0, 0.0
    for start, stop in chunks(spec):
        table = pq.read_table(_chunk_path(out, start, stop))
        steps += int(table.schema.metadata[b"ship_steps"])
        seconds += float(table.schema.metadata[b"seconds"])
        tables.append(table.replace_schema_metadata(None))
    table = pa.concat_tables(tables)
    return {name: table.column(name).to_numpy(zero_copy_only=False)
            for name in table.column_names}, steps, seconds


def finish(spec: CampaignSpec, out: Path, ship_steps_per_s: float | None) -> dict[str, Any]:
    """Gather the chunks into ``encounters.parquet``, ``summary.json`` and the figures.

    ``ship_steps_per_s``: the rate of this invocation (wall clock, all workers); None when it
    ran no chunk, and the rate of one worker from the chunks' own timings is reported instead.
    """
    from trafficsim.campaign.figures import write_figures
    from trafficsim.campaign.summary import summarise

    rows, ship_steps, seconds = read_rows(out, spec)
    if ship_steps_per_s is None:
        ship_steps_per_s = ship_steps / seconds if seconds > 0 else None
    write_parquet(out / "encounters.parquet", {k: v.tolist() if v.dtype == object else v
                                               for k, v in rows.items()})
    summary = {"campaign": spec.name, "seed": spec.seed, "policy": spec.policy,
               **summarise(rows), "ship_steps": ship_steps,
               "ship_steps_per_s": ship_steps_per_s}
    write_json(out / "summary.json", summary)
    write_figures(rows, out)
    return summary
