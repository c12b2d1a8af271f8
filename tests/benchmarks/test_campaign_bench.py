"""Full campaign pipeline throughput in ship-steps per second: dynamics, GNSS and gyro on every
ship, the pv filter, radar, AIS and a tracker per observed ship, the decision network every
10 s, autopilot and pair metrics.

The rate over the encounters' whole 30 minutes (1,800 steps of 1 s, from the start: the
manoeuvres and the returns to the routes included) of a batch already built; run with
``make bench``. The figures go in the README. Untimed (``make test``), a few steps check that
it runs.
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

DURATION_S = 1800
ROUNDS = 2
WARM_UP = 20  # encounters run once before the timed rounds
SPEC = """schema_version: 1
name: bench
n_encounters: {n}
seed: 1
duration_s: {duration}
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
    path.write_text(SPEC.format(n=n, types=types, ships=max(ships, 3), duration=DURATION_S))
    return prepare(load_spec(path), 0, n)[1]


def _steps(benchmark) -> int:
    """The encounters' whole duration when timed, a few steps otherwise."""
    return 30 if benchmark.disabled else DURATION_S


@pytest.mark.parametrize("n, ships", [(10000, 2), (1000, 2), (100, 2), (2000, 3), (1000, 5)])
def test_full_pipeline(benchmark, tmp_path, n, ships):
    steps, sims = _steps(benchmark), []
    _sim(tmp_path, min(n, WARM_UP), ships).run(steps)  # compiles what the kernel cache lacks

    def fresh() -> tuple[tuple[int], dict]:
        sims.append(_sim(tmp_path, n, ships))
        return (steps,), {}

    benchmark.pedantic(lambda k: sims[-1].run(k), setup=fresh, rounds=ROUNDS)
    assert np.isfinite(sims[-1].batch.x).all()
    if benchmark.stats is not None:
        rate = sims[-1].batch.n_ships * steps / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\n{n} encounters of {ships} ships: {rate:,.0f} ship-steps/s")


def _half(path: str, start: int, stop: int, steps: int, barrier, results) -> None:
    """One worker of :func:`test_full_pipeline_on_every_core`: warm up on a few encounters,
    then ``ROUNDS`` times build its encounters, wait for the others and run them; reports
    (ship-steps of a round, wall seconds of each round)."""
    spec = load_spec(Path(path))
    prepare(spec, start, min(stop, start + WARM_UP))[1].run(steps)
    seconds = []
    for _ in range(ROUNDS):
        sim = prepare(spec, start, stop)[1]
        barrier.wait()
        t0 = time.perf_counter()
        sim.run(steps)
        seconds.append(time.perf_counter() - t0)
    results.put((sim.batch.n_ships * steps, seconds))


def test_full_pipeline_on_every_core(benchmark, tmp_path):
    """The 10,000 two-ship encounters split over one process per core, running their 30
    minutes at the same time (as campaign chunks do): per round the ship-steps of all of them
    over the wall time of the slowest, averaged over the rounds. The rate is
    ``extra_info["ship_steps_per_s"]``; the timer's figure is the parent's CPU time, which
    waits. Untimed (``make test``), 200 encounters check that it runs."""
    n, steps = (200 if benchmark.disabled else 10000), _steps(benchmark)
    workers = min(os.cpu_count() or 1, 2) if benchmark.disabled else (os.cpu_count() or 1)
    path = tmp_path / "bench.yaml"
    path.write_text(SPEC.format(n=n, types=PAIRWISE, ships=3, duration=DURATION_S))
    bounds = np.linspace(0, n, workers + 1).round().astype(int)
    context = multiprocessing.get_context("spawn")

    def run() -> tuple[int, float]:
        barrier, results = context.Barrier(workers), context.Queue()
        procs = [context.Process(target=_half, args=(str(path), int(a), int(b), steps,
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
    assert ship_steps == 2 * n * steps and seconds.shape == (ROUNDS,) and (seconds > 0).all()
    if benchmark.stats is not None:
        rate = float(np.mean(ship_steps / seconds))
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\n{n} encounters on {workers} processes: {rate:,.0f} ship-steps/s")
