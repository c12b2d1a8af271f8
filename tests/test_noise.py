import math

import numba
import numpy as np
import pytest

from trafficsim.noise import NoiseBank, generator, normal_from, uniform_from


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


# ---------------------------------------------------------------------------------------------
# keyed streams: batch composition and order, independence, at-need draws


def test_permuted_and_duplicated_rows_draw_each_keys_own_numbers():
    """Rows of a bank in any order, with a key repeated, each draw their key's stream: the
    batch's composition changes nothing (normal and uniform banks, with an ``other``)."""
    keys = [(0, 0, 1), (0, 1, 0), (3, 2, 0), (5, 0, 4)]
    for kind in ("normal", "uniform"):
        def bank(rows, kind=kind):
            enc, ship, other = zip(*rows, strict=True)
            return _draws(NoiseBank(9, enc, ship, "ais_rx", 2, kind=kind, block_steps=5,
                                    other=other), 12)
        base = bank(keys)
        order = [2, 0, 3, 1, 2]
        mixed = bank([keys[i] for i in order])
        for j, i in enumerate(order):
            np.testing.assert_array_equal(mixed[:, j], base[:, i])


def test_rows_with_another_ship_are_numpys_keyed_generator():
    """A directed-pair row ``(encounter, observer, purpose, other)`` draws the uniforms of
    ``generator(seed, encounter, observer, purpose, other)``; the pair reversed is another
    stream."""
    bank = NoiseBank(21, [4, 4], [1, 2], "radar", 1, kind="uniform", other=[2, 1])
    got = _draws(bank, 20)
    np.testing.assert_array_equal(got[:, 0, 0], generator(21, 4, 1, "radar", 2).random(20))
    np.testing.assert_array_equal(got[:, 1, 0], generator(21, 4, 2, "radar", 1).random(20))
    assert not np.array_equal(got[:, 0, 0], got[:, 1, 0])


def test_empty_banks_and_bad_arguments():
    """A bank of no ships draws ``(0, dims)`` arrays; unequal key columns or an unknown kind
    are refused; seeds and keys must be >= 0; an unknown purpose is not a stream."""
    from trafficsim.noise import seeded_states

    bank = NoiseBank(1, [], [], "gnss", 3)
    assert bank.next().shape == (0, 3) and bank.state.shape == (0, 4)
    assert seeded_states(1, []).shape == (0, 4)
    with pytest.raises(ValueError, match="differ in length"):
        NoiseBank(1, [0, 1], [0], "gnss", 1)
    with pytest.raises(ValueError, match="differ in length"):
        NoiseBank(1, [0, 1], [0, 1], "gnss", 1, other=[0])
    with pytest.raises(ValueError, match="kind"):
        NoiseBank(1, [0], [0], "gnss", 1, kind="gauss")
    with pytest.raises(ValueError, match=">= 0"):
        NoiseBank(1, [0], [-1], "gnss", 1).next()
    with pytest.raises(ValueError):
        generator(1, 0, 0, "sonar")


def test_neighbouring_keys_give_uncorrelated_streams():
    """Streams whose keys differ in one entry by one (encounter, ship, purpose, seed): sample
    correlations below 5 / sqrt(n) (n = 20,000: 0.035; the standard error is 0.007), and no
    lag-1 autocorrelation within a stream."""
    n = 20_000
    ref = _column(NoiseBank(3, [7], [2], "gnss", 1, block_steps=n))
    others = [_column(NoiseBank(3, [8], [2], "gnss", 1, block_steps=n)),
              _column(NoiseBank(3, [7], [3], "gnss", 1, block_steps=n)),
              _column(NoiseBank(3, [7], [2], "gnss_gross", 1, block_steps=n)),
              _column(NoiseBank(4, [7], [2], "gnss", 1, block_steps=n)),
              _column(NoiseBank(3, [2], [7], "gnss", 1, block_steps=n))]
    bound = 5.0 / math.sqrt(n)
    for other in others:
        assert abs(np.corrcoef(ref, other)[0, 1]) < bound
    assert abs(np.corrcoef(ref[:-1], ref[1:])[0, 1]) < bound


@numba.njit
def _at_need(streams, rows, count, normal):
    """``count`` draws at need from each stream of ``rows`` in turn, ``(len(rows), count)``."""
    out = np.empty((rows.shape[0], count))
    for j in range(rows.shape[0]):
        for i in range(count):
            out[j, i] = (normal_from(streams, rows[j]) if normal
                         else uniform_from(streams, rows[j]))
    return out


def _moments(x: np.ndarray) -> tuple[float, float, float, float]:
    m, s = x.mean(), x.std()
    z = (x - m) / s
    return float(m), float(s * s), float(np.mean(z**3)), float(np.mean(z**4))


def test_at_need_draws_have_the_moments_of_their_distributions():
    """``normal_from``: mean 0, variance 1, skewness 0, kurtosis 3; ``uniform_from``: mean 1/2,
    variance 1/12, in [0, 1), kurtosis 9/5. 100,000 draws over 4 streams; bounds of about five
    standard errors (mean 0.016 and 0.0046, variance 0.022 and 0.0014, skewness 0.04 and
    0.04, kurtosis 0.08 and 0.04)."""
    from trafficsim.noise import independent_streams

    rows = np.arange(4)
    normals = _at_need(independent_streams(4, 17), rows, 25_000, True).ravel()
    uniforms = _at_need(independent_streams(4, 18), rows, 25_000, False).ravel()
    m, v, skew, kurt = _moments(normals)
    assert abs(m) < 0.016 and abs(v - 1.0) < 0.022
    assert abs(skew) < 0.04 and abs(kurt - 3.0) < 0.08
    m, v, skew, kurt = _moments(uniforms)
    assert abs(m - 0.5) < 0.0046 and abs(v - 1.0 / 12.0) < 0.0014
    assert abs(skew) < 0.04 and abs(kurt - 1.8) < 0.04
    assert uniforms.min() >= 0.0 and uniforms.max() < 1.0


def test_uniform_at_need_continues_numpys_stream_and_rows_advance_alone():
    """``uniform_from`` on row ``i`` gives numpy's ``Generator.random`` of that row's key and
    advances that row only; ``independent_streams`` row ``i`` is keyed ``(seed, 0, i,
    purpose)``."""
    from trafficsim.noise import independent_streams

    streams = independent_streams(3, 5, "ais")
    before = streams.copy()
    got = _at_need(streams, np.array([1]), 50, False)[0]
    np.testing.assert_array_equal(got, generator(5, 0, 1, "ais").random(50))
    np.testing.assert_array_equal(streams[[0, 2]], before[[0, 2]])
    assert not np.array_equal(streams[1], before[1])


def test_normal_at_need_continues_the_banks_normals():
    """``normal_from`` on a bank's state continues the very sequence the bank's blocks give:
    block draws then at-need draws are the first ``a + b`` normals of the stream."""
    whole = _draws(NoiseBank(6, [1, 2], [0, 0], "compass", 1, block_steps=40), 40)[:, :, 0].T
    bank = NoiseBank(6, [1, 2], [0, 0], "compass", 1, block_steps=25)
    first = _draws(bank, 25)[:, :, 0].T
    rest = _at_need(bank.state, np.arange(2), 15, True)
    np.testing.assert_array_equal(np.hstack([first, rest]), whole)


def test_peek_of_nothing_and_of_many():
    """Peeking zero numbers gives ``(n, 0)``; peeking is repeatable."""
    from trafficsim.noise import independent_streams, peek_normals

    streams = independent_streams(3, 2)
    assert peek_normals(streams, 0).shape == (3, 0)
    np.testing.assert_array_equal(peek_normals(streams, 10), peek_normals(streams, 10))


def _numpy_state(seed, key):
    return [int(v) for v in np.random.SFC64(
        np.random.SeedSequence(seed, spawn_key=key)).state["state"]["state"]]


@pytest.mark.parametrize("seed,keys", [
    (2**40 + 3, [(1, 2, 3)]),
    (2**130 + 7, [(1, 2, 3), (0, 0, 0)]),
    (5, [(2**33, 1, 2), (1, 2**32, 0)]),
    (5, [(), (1,), (1, 2, 3, 4)]),
    (2**64 - 1, [(2**32 - 1, 0, 14)]),
])
def test_seeding_of_multiword_seeds_keys_and_ragged_keys_is_numpys(seed, keys):
    """Seeds and key elements beyond 32 bits, empty and ragged keys take the general path; the
    states still equal numpy's SeedSequence + SFC64 seeding."""
    from trafficsim.noise import seeded_states

    out = seeded_states(seed, keys)
    assert out.shape == (len(keys), 4) and out.dtype == np.uint64
    for row, key in zip(out, keys, strict=True):
        assert [int(v) for v in row] == _numpy_state(seed, key)


def test_seeding_accepts_small_integer_key_arrays_and_refuses_negative_values():
    """Keys as int8/uint32 arrays give numpy's states; a negative seed or key is refused."""
    from trafficsim.noise import seeded_states

    for dtype in (np.int8, np.uint32, np.int64):
        out = seeded_states(9, np.array([[3, 1, 4]], dtype=dtype))
        assert [int(v) for v in out[0]] == _numpy_state(9, (3, 1, 4))
    with pytest.raises(ValueError, match=">= 0"):
        seeded_states(-1, [(0, 0, 0)])
    with pytest.raises(ValueError, match=">= 0"):
        seeded_states(1, [(0, -2, 0)])


def test_bank_uniforms_and_normals_pass_ks_against_scipy_with_the_right_moments():
    """20 000 draws per kind: Kolmogorov-Smirnov p > 0.001 against U(0, 1) and N(0, 1); mean,
    variance (1/12 and 1), skewness and excess kurtosis within 5 standard errors."""
    from scipy import stats

    n = 20_000
    ubank = NoiseBank(3, [0] * 10, range(10), "waves", 1, kind="uniform")
    zbank = NoiseBank(3, [0] * 10, range(10), "waves", 1)
    u = np.concatenate([ubank.next().copy() for _ in range(n // 10)]).ravel()
    z = np.concatenate([zbank.next().copy() for _ in range(n // 10)]).ravel()
    assert u.min() >= 0.0 and u.max() < 1.0
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert stats.kstest(z, "norm").pvalue > 1e-3
    assert abs(u.mean() - 0.5) < 5 * math.sqrt(1 / 12 / n)
    assert abs(u.var() - 1 / 12) < 5 * math.sqrt(1 / 180 / n)
    assert abs(z.mean()) < 5 / math.sqrt(n)
    assert abs(z.var() - 1.0) < 5 * math.sqrt(2 / n)
    assert abs(stats.skew(z)) < 5 * math.sqrt(6 / n)
    assert abs(stats.kurtosis(z)) < 5 * math.sqrt(24 / n)


def test_new_banks_reproduce_exactly_and_rows_do_not_depend_on_the_draw_order():
    """Two banks with the same keys draw identical numbers; numbers of one row do not depend on
    how many other rows exist or on the bank's block length (a row is its own stream)."""
    a = NoiseBank(12, [4, 4, 5], [0, 1, 0], "compass", 3, block_steps=5).next().copy()
    bank1 = NoiseBank(12, [4, 4, 5], [0, 1, 0], "compass", 3, block_steps=5)
    bank2 = NoiseBank(12, [5], [0], "compass", 3, block_steps=7)
    s1 = np.stack([bank1.next().copy() for _ in range(23)])
    s2 = np.stack([bank2.next().copy() for _ in range(23)])
    np.testing.assert_array_equal(a, s1[0])
    np.testing.assert_array_equal(s1[:, 2], s2[:, 0])
    bank3 = NoiseBank(12, [4, 4, 5], [0, 1, 0], "compass", 3, block_steps=5)
    np.testing.assert_array_equal(np.stack([bank3.next().copy() for _ in range(23)]), s1)


def test_streams_of_all_purposes_ships_and_encounters_are_mutually_uncorrelated():
    """Every purpose of two ships in two encounters (60 streams): off-diagonal sample
    correlations of 4 000 normals stay within 5 standard errors, and the lag-1
    autocorrelation of each stream within 5 standard errors of 0."""
    from trafficsim.noise import PURPOSES

    n = 4000
    cols = []
    for purpose in PURPOSES:
        bank = NoiseBank(1, [0, 0, 1, 1], [0, 1, 0, 1], purpose, 1)
        cols.append(np.concatenate([bank.next().copy() for _ in range(n)], axis=1))
    x = np.concatenate(cols, axis=0)  # (60, n)
    c = np.corrcoef(x)
    off = c[~np.eye(len(c), dtype=bool)]
    assert np.abs(off).max() < 5 / math.sqrt(n)
    lag = np.array([np.corrcoef(r[:-1], r[1:])[0, 1] for r in x])
    assert np.abs(lag).max() < 5 / math.sqrt(n)


def test_independent_streams_are_the_keyed_streams_and_check_streams_refuses_bad_arrays():
    """independent_streams(n, seed, purpose) are the states of keys (0, row, purpose): numpy's
    generator for that key draws the same first uniform; check_streams refuses wrong shape,
    dtype and non-contiguous arrays, naming the expected shape."""
    from trafficsim.noise import check_streams, independent_streams

    st = independent_streams(3, seed=8, purpose="ais")
    for row in range(3):
        assert [int(v) for v in st[row]] == [int(v) for v in generator(
            8, 0, row, "ais").bit_generator.state["state"]["state"]]
    first = uniform_from(st, 1)
    assert first == generator(8, 0, 1, "ais").random()
    check_streams(st, 3)
    for bad in (st[:2], st.astype(np.int64), np.asfortranarray(st), [[0] * 4] * 3):
        with pytest.raises(ValueError, match=r"\(3, 4\) uint64"):
            check_streams(bad, 3)
