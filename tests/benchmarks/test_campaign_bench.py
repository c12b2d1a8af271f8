"""Full campaign pipeline throughput in ship-steps per second: dynamics, GNSS and gyro on every
ship, the pv filter, radar, AIS and a tracker per observed ship, the decision network every
10 s, autopilot and pair metrics.

Steady-state rate over 100 steps (ten decision periods) of a batch already built; run with
``make bench``. The figures go in the README.
"""

import itertools
import multiprocessing
import os
import time
from pathlib import Path

import numpy as np
import pytest

from trafficsim.campaign.runner import prepare
from trafficsim.campaign.spec import load_spec

STEPS = 100
SPEC = """schema_version: 1
name: bench
n_encounters: {n}
seed: 1
duration_s: 1800
chunk_encounters: {n}
encounter_types: {types}
multi_ships: [{ships}, {ships}]
ship_types: {{cargo: 1, container: 1, bulk_carrier: 1}}
sensors: {{gnss_sigma_m: [1, 5], compass_sigma_deg: [0.1, 0.5]}}
"""
PAIRWISE = "{head_on: 1, crossing_give_way: 1, crossing_stand_on: 1, overtaking: 1, overtaken: 1}"


def _sim(tmp_path: Path, n: int, ships: int):
    types = PAIRWISE if ships == 2 else "{multi: 1}"
    path = tmp_path / "bench.yaml"
    path.write_text(SPEC.format(n=n, types=types, ships=max(ships, 3)))
    return prepare(load_spec(path), 0, n)[1]


@pytest.mark.parametrize("n, ships", [(10000, 2), (1000, 2), (100, 2), (2000, 3), (1000, 5)])
def test_full_pipeline(benchmark, tmp_path, n, ships):
    sim = _sim(tmp_path, n, ships)
    benchmark.pedantic(sim.run, args=(STEPS,), rounds=3, warmup_rounds=1)
    assert np.isfinite(sim.batch.x).all()
    if benchmark.stats is not None:
        rate = sim.batch.n_ships * STEPS / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\n{n} encounters of {ships} ships: {rate:,.0f} ship-steps/s")


ROUNDS = 3


def _half(path: str, start: int, stop: int, steps: int, barrier, results) -> None:
    """One worker of :func:`test_full_pipeline_on_every_core`: build its encounters, warm up,
    wait for the others, then step ``ROUNDS`` times; reports (ship-steps of a round, wall
    seconds of each round)."""
    sim = prepare(load_spec(Path(path)), start, stop)[1]
    sim.run(steps)
    seconds = []
    for _ in range(ROUNDS):
        barrier.wait()
        t0 = time.perf_counter()
        sim.run(steps)
        seconds.append(time.perf_counter() - t0)
    results.put((sim.batch.n_ships * steps, seconds))


def test_full_pipeline_on_every_core(benchmark, tmp_path):
    """The 10,000 two-ship encounters split over one process per core, stepping at the same
    time (as campaign chunks do): per round the ship-steps of all of them over the wall time of
    the slowest, averaged over the rounds. The rate is ``extra_info["ship_steps_per_s"]``; the
    timer's figure is the parent's CPU time, which waits. Untimed (``make test``), 200
    encounters check that it runs."""
    n = 200 if benchmark.disabled else 10000
    workers = min(os.cpu_count() or 1, 2) if benchmark.disabled else (os.cpu_count() or 1)
    path = tmp_path / "bench.yaml"
    path.write_text(SPEC.format(n=n, types=PAIRWISE, ships=3))
    bounds = np.linspace(0, n, workers + 1).round().astype(int)
    context = multiprocessing.get_context("spawn")

    def run() -> tuple[int, float]:
        barrier, results = context.Barrier(workers), context.Queue()
        procs = [context.Process(target=_half, args=(str(path), int(a), int(b), STEPS,
                                                     barrier, results))
                 for a, b in itertools.pairwise(bounds)]
        for proc in procs:
            proc.start()
        got = [results.get(timeout=600) for _ in procs]
        for proc in procs:
            proc.join()
            assert proc.exitcode == 0
        return sum(g[0] for g in got), np.max([g[1] for g in got], axis=0)

    ship_steps, seconds = benchmark.pedantic(run, rounds=1, iterations=1)
    assert ship_steps == 2 * n * STEPS and seconds.shape == (ROUNDS,) and (seconds > 0).all()
    if benchmark.stats is not None:
        rate = float(np.mean(ship_steps / seconds))
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\n{n} encounters on {workers} processes: {rate:,.0f} ship-steps/s")
