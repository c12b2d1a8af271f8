import numpy as np
import pytest

from trafficsim.noise import NoiseBank, generator


def _draws(bank: NoiseBank, steps: int) -> np.ndarray:
    return np.stack([bank.next().copy() for _ in range(steps)])


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


def test_block_boundaries_do_not_change_the_sequence_and_generator_matches():
    small = _draws(NoiseBank(5, [2], [0], "ais", 3, kind="uniform", block_steps=7), 30)
    g = generator(5, 2, 0, "ais")
    ref = np.concatenate([g.random((7, 3)) for _ in range(5)])[:30]
    np.testing.assert_array_equal(small[:, 0], ref)
    assert ((small >= 0) & (small < 1)).all()
