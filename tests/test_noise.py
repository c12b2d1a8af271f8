import math

import numpy as np
import pytest

from trafficsim.noise import NoiseBank, generator


def _draws(bank: NoiseBank, steps: int) -> np.ndarray:
    return np.stack([bank.next().copy() for _ in range(steps)])


def _column(bank: NoiseBank) -> np.ndarray:
    """A whole block of the bank's first stream and first dimension, in step order."""
    bank.next()
    return bank._block[:, 0, 0].copy()


def _normal_cdf(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.vectorize(math.erf)(x / math.sqrt(2.0)))


def test_a_ship_sees_the_same_numbers_whatever_the_batch():
    alone = _draws(NoiseBank(7, [3], [1], "gnss", 2, block_steps=16), 40)
    big = _draws(NoiseBank(7, [0, 3, 3, 9], [0, 0, 1, 1], "gnss", 2, block_steps=16), 40)
    np.testing.assert_array_equal(alone[:, 0], big[:, 2])


def test_streams_differ_by_seed_ship_and_purpose_and_are_standard_normal():
    a = _draws(NoiseBank(1, [0, 0], [0, 1], "gnss", 1), 4000)
    b = _draws(NoiseBank(1, [0], [0], "compass", 1), 4000)
    c = _draws(NoiseBank(2, [0], [0], "gnss", 1), 4000)
    assert not np.array_equal(a[:, 0], a[:, 1])
    assert not np.array_equal(a[:, 0], b[:, 0]) and not np.array_equal(a[:, 0], c[:, 0])
    assert abs(a.mean()) < 0.05 and a.std() == pytest.approx(1.0, abs=0.05)


def test_block_boundaries_do_not_change_the_sequence_and_uniforms_are_numpys():
    small = _draws(NoiseBank(5, [2], [0], "ais", 3, kind="uniform", block_steps=7), 30)
    ref = generator(5, 2, 0, "ais").random((30, 3))
    np.testing.assert_array_equal(small[:, 0], ref)
    assert ((small >= 0) & (small < 1)).all()
    normals = [_draws(NoiseBank(5, [2], [0], "ais", 3, block_steps=b), 30) for b in (1, 7, 64)]
    np.testing.assert_array_equal(normals[0], normals[1])
    np.testing.assert_array_equal(normals[0], normals[2])


def test_the_compiled_stream_advances_as_numpys_sfc64():
    bank = NoiseBank(3, [1], [0], "radar", 1, kind="uniform", block_steps=1000)
    bank.next()
    g = generator(3, 1, 0, "radar")
    g.bit_generator.random_raw(1000)
    np.testing.assert_array_equal(bank.state[0], g.bit_generator.state["state"]["state"])


def test_normals_are_numpys_ziggurat_on_the_same_stream():
    """Same words, same 256-strip ziggurat: the values agree to the rounding of the strip
    tables (about 1e-11 relative) as long as no accept/reject decision falls between them."""
    bank = NoiseBank(0, [2], [0], "ais", 1, block_steps=5000)
    np.testing.assert_allclose(_column(bank), generator(0, 2, 0, "ais").standard_normal(5000),
                               rtol=1e-9)


def test_normals_follow_the_normal_distribution_into_the_tail():
    """Kolmogorov-Smirnov distance of 400,000 draws (99.9 % critical value 1.95 / sqrt(n)),
    and the count beyond the ziggurat's base strip (|x| > 3.6542, drawn by the tail method)
    within four standard deviations of its expectation."""
    n = 400_000
    bank = NoiseBank(11, [0], [0], "waves", 1, block_steps=n)
    x = np.sort(_column(bank))
    ks = np.max(np.abs(_normal_cdf(x) - (np.arange(n) + 0.5) / n))
    assert ks < 1.95 / math.sqrt(n)
    p_tail = 2.0 * (1.0 - _normal_cdf(np.array([3.6541528853610088]))[0])
    expected = n * p_tail
    assert abs(np.sum(np.abs(x) > 3.6541528853610088) - expected) < 4.0 * math.sqrt(expected)
    assert x.min() < -4.0 and x.max() > 4.0


def test_draws_at_need_follow_the_stream_and_peek_does_not_draw():
    """``normal_from`` continues the stream the bank's blocks would give; ``peek_normals``
    shows the next numbers without advancing; ``independent_streams`` is keyed, not ordered."""
    from trafficsim.noise import check_streams, independent_streams, peek_normals

    states = NoiseBank(4, [0, 1], [2, 0], "radar", 3).state
    before = states.copy()
    seen = peek_normals(states, 6)
    np.testing.assert_array_equal(states, before)
    block = _draws(NoiseBank(4, [0, 1], [2, 0], "radar", 3, block_steps=2), 2)  # (2, 2, 3)
    np.testing.assert_array_equal(seen, block.transpose(1, 0, 2).reshape(2, 6))
    np.testing.assert_array_equal(independent_streams(3, 9)[1:], independent_streams(5, 9)[1:3])
    check_streams(states, 2)
    for bad, rows in ((states, 3), (states.astype(np.int64), 2), (states[:, :3], 2),
                      (np.asfortranarray(np.tile(states, (1, 2)))[:, ::2], 2)):
        with pytest.raises(ValueError, match="streams"):
            check_streams(bad, rows)


def test_streams_seeded_in_one_loop_are_numpys():
    """``seeded_states`` is ``SFC64(SeedSequence(seed, spawn_key=key))`` bit for bit: seeds and
    key entries above 32 bits (several entropy words), keys of any length, the empty key."""
    from trafficsim.noise import seeded_states

    rng = np.random.default_rng(0)
    keys = [tuple(int(v) for v in rng.integers(0, 2**40 if k % 5 == 0 else 60, k % 6))
            for k in range(300)]
    for seed in (0, 7, 2026, 2**32 + 5, 2**70 + 3):
        want = [np.random.SFC64(np.random.SeedSequence(seed, spawn_key=key)).state["state"]
                ["state"] for key in keys]
        np.testing.assert_array_equal(seeded_states(seed, keys), np.array(want, np.uint64))
    # a table of equal keys of one word each (the engine's banks) is seeded at once
    table = rng.integers(0, 60, (200, 4))
    table[0] = [2**32 - 1, 0, 2**32 - 1, 1]
    for seed in (0, 2**70 + 3):
        want = [np.random.SFC64(np.random.SeedSequence(seed, spawn_key=tuple(map(int, key))))
                .state["state"]["state"] for key in table]
        np.testing.assert_array_equal(seeded_states(seed, table), np.array(want, np.uint64))
    with pytest.raises(ValueError, match=">= 0"):
        seeded_states(-1, [(0,)])
    with pytest.raises(ValueError, match=">= 0"):
        seeded_states(0, np.array([[1, -2, 3]]))
