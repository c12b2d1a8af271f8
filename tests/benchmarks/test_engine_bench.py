"""Engine throughput (dynamics + guidance + autopilot + metrics) in ship-steps per second.

Run with ``make bench``; the figure printed in ``extra_info`` goes in the README.
"""

import numpy as np
import pytest

from trafficsim.batch import EncounterEnv, ShipSetup, build_batch
from trafficsim.engine import Simulation
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn

STEPS = 20


def _batch(type_: str, n_encounters: int, ships_per_encounter: int = 2):
    spec = load_ship(type_)
    rng = np.random.default_rng(0)
    ships = []
    for e in range(n_encounters):
        for s in range(ships_per_encounter):
            ships.append(ShipSetup(f"e{e}s{s}", spec, e, 3000.0 * s, 1000.0 * s,
                                   rng.uniform(0, 2 * np.pi), from_kn(spec["service_speed_kn"]),
                                   np.array([[8000.0, 4000.0 * s]])))
    envs = [EncounterEnv(0.3, 1.0, 8.0, 2.0)] * n_encounters
    return build_batch(ships, envs)


@pytest.mark.parametrize("type_", ["kvlcc2", "catfish", "container"])
def test_engine_10000_ships(benchmark, type_):
    sim = Simulation.start(_batch(type_, 5000), 1.0)
    benchmark.pedantic(sim.run, args=(STEPS,), rounds=3, warmup_rounds=1)
    assert np.isfinite(sim.batch.x).all()
    if benchmark.stats is not None:  # None under --benchmark-disable
        rate = sim.batch.n_ships * STEPS / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\n{type_}: {rate:,.0f} ship-steps/s")


@pytest.mark.parametrize("n_encounters", [1, 50, 500])
def test_engine_scaling_with_batch_size(benchmark, n_encounters):
    """Nomoto traffic: cost per ship-step as the batch grows (per-step overhead amortised)."""
    sim = Simulation.start(_batch("container", n_encounters), 1.0)
    steps = max(STEPS, 20000 // (2 * n_encounters))
    benchmark.pedantic(sim.run, args=(steps,), rounds=3, warmup_rounds=1)
    if benchmark.stats is not None:
        rate = sim.batch.n_ships * steps / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\n{2 * n_encounters} ships: {rate:,.0f} ship-steps/s")


@pytest.mark.parametrize("type_, filter_name, tracking", [
    ("container", "pv", False), ("container", "ekf", False), ("container", "pv", True),
    ("kvlcc2", "pv", True), ("catfish", "pv", True)])
def test_engine_with_instruments_and_filter_10000_ships(benchmark, type_, filter_name, tracking):
    """Engine plus DGPS, gyro, wave motion and a gated own-ship filter on every ship (and with
    ``tracking``: radar, AIS and a tracker of the other ship), on the Nomoto container ship and
    on the two surge-sway-yaw models (``mmg`` KVLCC2, ``modular`` Catfish): the layer's cost
    per ship-step is the difference of the inverse rates of this test and
    :func:`test_engine_10000_ships` for the same ship."""
    batch = _batch(type_, 5000)
    sensors = {"gnss": {"sigma_m": 2.0, "gross_prob": 0.001},
               "compass": {"kind": "gyro", "sigma_deg": 0.3},
               "waves": {"heading_sigma_deg": 0.3, "sway_sigma_m": 0.5}}
    if tracking:
        sensors = {**sensors, "radar": {}, "ais": {}}
    batch.sensors = [sensors] * batch.n_ships
    batch.filters = [filter_name] * batch.n_ships
    sim = Simulation.start(batch, 1.0, seed=1)
    benchmark.pedantic(sim.run, args=(STEPS,), rounds=3, warmup_rounds=1)
    assert np.isfinite(sim.nav.est).all()
    if benchmark.stats is not None:
        rate = sim.batch.n_ships * STEPS / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        extra = " and tracking" if tracking else ""
        print(f"\n{type_} with instruments, {filter_name} filter{extra}: {rate:,.0f} ship-steps/s")


def test_engine_with_decisions_10000_ships(benchmark):
    """Engine plus the COLREGS decision network (rules/colregs.yaml) every 10 s for every pair of
    5,000 two-ship encounters; 100 steps so that the decision step is amortised as in a run."""
    from trafficsim.colregs.decider import Decider

    batch = _batch("container", 5000)
    decider = Decider.build(["colregs"] * batch.n_ships, batch.pair_i, batch.pair_j)
    sim = Simulation.start(batch, 1.0, decider=decider, decision_period_s=10.0)
    steps = 100
    benchmark.pedantic(sim.run, args=(steps,), rounds=3, warmup_rounds=1)
    assert np.isfinite(sim.batch.x).all()
    if benchmark.stats is not None:
        rate = sim.batch.n_ships * steps / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\nwith decisions every 10 s: {rate:,.0f} ship-steps/s")
