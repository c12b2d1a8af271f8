"""Decision-network throughput: a 30-node network evaluated for 100,000 pairs at once.

Reports pairs per second and pair-nodes per second (visited nodes summed over pairs); the
target is above 5 million pair-nodes per second. Run with ``make bench``.
"""

import numpy as np
import pytest

from trafficsim.colregs.network import ActionField, Vocabulary, evaluate, loads

N_NODES = 30
N_PAIRS = 100_000
VOCAB = Vocabulary(
    features=tuple(f"f{k}" for k in range(8)),
    enums={"a": 1.0, "b": 2.0},
    actions={"kind": ActionField(("a", "b")), "amount": ActionField()})


def _rules() -> str:
    """Three layers of ten nodes: compound tests, immediate chains within a layer, and next
    edges from each layer's end to the following layer."""
    lines = ["schema_version: 1", "name: bench", "start: n0", "parameters: {t: 0.5}", "nodes:"]
    for k in range(N_NODES):
        layer, j = divmod(k, 10)
        after = f"{{to: n{10 * ((layer + 1) % 3)}, next: true}}"
        f, g = f"f{k % 8}", f"f{(3 * k + 1) % 8}"
        test = (f"{{all: [[{f}, '<', t], {{any: [[{g}, between, [0.2, 0.9]], "
                f"{{not: [{f}, '==', a]}}]}}]}}" if k % 3 else f"[{f}, '>=', 0.3]")
        yes = f"n{k + 1}" if j < 9 else after
        no = f"n{k + 2}" if j < 8 else after
        action = f", action: {{kind: b, amount: {k}}}" if k % 4 == 0 else ""
        lines.append(f"  n{k}: {{test: {test}, yes: {yes}, no: {no}{action}}}")
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def network():
    return loads(_rules(), VOCAB, "bench.yaml")


def test_network_100000_pairs(benchmark, network) -> None:
    rng = np.random.default_rng(0)
    feats = rng.uniform(0.0, 1.0, (len(VOCAB.features), N_PAIRS))
    feats[rng.uniform(size=feats.shape) < 0.01] = np.nan  # some missing features
    cursor = rng.integers(0, network.n_nodes, N_PAIRS)
    decision = benchmark.pedantic(evaluate, args=(network, feats, cursor), rounds=10,
                                  warmup_rounds=1)
    assert network.n_nodes == N_NODES
    visits = int(decision.path_len.sum())
    assert visits > 2 * N_PAIRS  # the network does walk immediate chains
    if benchmark.stats is not None:  # None under --benchmark-disable
        seconds = benchmark.stats.stats.mean
        benchmark.extra_info["pairs_per_s"] = N_PAIRS / seconds
        benchmark.extra_info["pair_nodes_per_s"] = visits / seconds
        print(f"\ndecision network: {N_PAIRS / seconds:,.0f} pairs/s, "
              f"{visits / seconds:,.0f} pair-nodes/s ({visits / N_PAIRS:.1f} nodes per pair)")
