"""Encounter-feature throughput (geometry, CPA, bow crossing, domain look-ahead), pairs per second.

Run with ``make bench``; the figure printed in ``extra_info`` goes in the README.
"""

import numpy as np
import pytest

from trafficsim.colregs.domains import DOMAINS
from trafficsim.colregs.features import NAMES, pair_features

N_PAIRS = 100_000


def _pairs(m: int) -> tuple[np.ndarray, ...]:
    """Random directed pairs within 10 NM of each other, 0-15 kn, 50-350 m."""
    rng = np.random.default_rng(0)
    pos = lambda: rng.uniform(-10_000.0, 10_000.0, m)  # noqa: E731
    vel = lambda: rng.uniform(-6.0, 6.0, m)  # noqa: E731
    return (pos(), pos(), vel(), vel(), rng.uniform(0.0, 2 * np.pi, m),
            rng.uniform(50.0, 350.0, m), pos(), pos(), vel(), vel(), rng.uniform(50.0, 350.0, m))


@pytest.mark.parametrize("domain", DOMAINS)
def test_pair_features_100000_pairs(benchmark, domain):
    args = _pairs(N_PAIRS)
    f = benchmark.pedantic(pair_features, args=(*args, domain, 5.0, 1800.0), rounds=20,
                           warmup_rounds=2)
    assert f.values.shape == (len(NAMES), N_PAIRS)
    assert not np.isnan(f.values).any()
    if benchmark.stats is not None:  # None under --benchmark-disable
        rate = N_PAIRS / benchmark.stats.stats.min
        benchmark.extra_info["pairs_per_s"] = rate
        print(f"\n{domain}: {rate:,.0f} pairs/s ({benchmark.stats.stats.min * 1e3:.1f} ms "
              f"per {N_PAIRS:,} pairs)")
