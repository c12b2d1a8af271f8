"""The floor under the sensor layer's cost: standard normals drawn for every ship from its own
keyed stream (:class:`trafficsim.noise.NoiseBank`), ten per ship and step, about what the
instruments of one ship draw in a step (GNSS two, compass one, sea state four, radar and AIS
reports the rest). Run with ``make bench``; the figure goes in the README."""

import numpy as np

from trafficsim.noise import BLOCK_STEPS, NoiseBank

N_SHIPS = 10000
STEPS = 4 * BLOCK_STEPS  # whole blocks: every refill is counted


def test_ten_normals_per_ship_10000_ships(benchmark):
    ships = np.arange(N_SHIPS)
    bank = NoiseBank(1, ships // 2, ships % 2, "gnss", dims=10)

    def run() -> None:
        for _ in range(STEPS):
            bank.next()

    benchmark.pedantic(run, rounds=3, warmup_rounds=1)
    draws = bank.next()
    assert draws.shape == (N_SHIPS, 10)
    assert abs(draws.mean()) < 0.05 and abs(draws.std() - 1.0) < 0.05
    if benchmark.stats is not None:
        rate = N_SHIPS * STEPS / benchmark.stats.stats.mean
        benchmark.extra_info["ship_steps_per_s"] = rate
        print(f"\nten normals per ship: {rate:,.0f} ship-steps/s, "
              f"{1e9 / rate:.1f} ns per ship-step")
