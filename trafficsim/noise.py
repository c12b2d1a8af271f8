"""Random streams for a batch: one keyed numpy ``SFC64`` stream per (encounter, ship, purpose).

Every stream is ``Generator(SFC64(SeedSequence(seed, spawn_key=(encounter, ship, purpose))))``:
keyed explicitly, never by order of creation, so adding a ship, changing the batch size or the
number of workers leaves every other stream bit-identical (``SeedSequence.spawn`` is stateful
and would not). ``ship`` is the ship's index within its encounter; ``purpose`` the index of a
named purpose in :data:`PURPOSES`.

Drawing from thousands of generators one call at a time would put a Python loop over ships on
the step path. Instead a :class:`NoiseBank` holds the 256-bit state of each of its streams in
one array, and one compiled loop advances every stream as numpy's ``SFC64`` does (the raw
64-bit words are bit-identical to ``bit_generator.random_raw``) while it fills a block of
``block_steps`` steps; the step path reads a row of the block. Uniforms are numpy's 53-bit
doubles of those words (bit-identical to ``Generator.random``); normals come from the 256-layer
ziggurat of Marsaglia & Tsang (J. Stat. Softw. 5(8), 2000) on the same words. The values a
ship sees depend only on its own stream, never on the batch or the block size.

Instruments that measure only now and then (a radar scan, an AIS report) draw instead at need:
their compiled loops call :func:`normal_from` on the streams' states (:attr:`NoiseBank.state`)
when an event happens, so the numbers drawn per event are fixed and nothing is drawn between
events. :func:`peek_normals` shows, without drawing them, the numbers the next event will use.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from trafficsim.jit import inline_kernel, kernel

#: every purpose that draws random numbers; append only (the index is part of the stream key)
PURPOSES = ("gnss", "gnss_gross", "compass", "log", "actuators", "waves", "radar", "ais",
            "initial", "ais_rx", "gnss2", "gnss2_gross", "gnss3", "gnss3_gross", "encounter",
            "phase")
#: steps per block: small, since a refill is one compiled call whatever its size
BLOCK_STEPS = 16


def generator(seed: int, encounter: int, ship: int, purpose: str,
              other: int | None = None) -> np.random.Generator:
    """The stream of one ship of one encounter for one purpose (and, for observations of
    another ship, that ship's index ``other`` within the encounter)."""
    key: tuple[int, ...] = (int(encounter), int(ship), PURPOSES.index(purpose))
    if other is not None:
        key = (*key, int(other))
    return np.random.Generator(np.random.SFC64(np.random.SeedSequence(seed, spawn_key=key)))


# numpy's SeedSequence (hash constants of its ``bit_generator`` module, after M. O'Neill's
# seed_seq_fe) and SFC64 seeding, so that a bank seeds all its streams in one compiled loop
_POOL_WORDS = 4
_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R, _M32 = 0xCA01F9DD, 0x4973F715, 0xFFFFFFFF


def _words(value: int) -> list[int]:
    """``value`` >= 0 as little-endian 32-bit words (0 is one word), as SeedSequence reads it."""
    if value < 0:
        raise ValueError(f"seeds and stream keys must be >= 0, got {value}")
    out = [value & _M32]
    value >>= 32
    while value:
        out.append(value & _M32)
        value >>= 32
    return out


def seeded_states(seed: int, keys: Sequence[Sequence[int]]) -> np.ndarray:
    """``(len(keys), 4)`` uint64 states of ``SFC64(SeedSequence(seed, spawn_key=key))`` for
    every key: bit-identical to numpy's, in one compiled loop (numpy takes about 40 us a
    stream, most of a campaign's start-up)."""
    run = _words(int(seed))
    prefix = run + [0] * (_POOL_WORDS - len(run))
    try:
        table = np.asarray(keys) if len(keys) else None
    except ValueError:  # keys of different lengths
        table = None
    if (table is not None and table.ndim == 2 and table.shape[1] > 0
            and table.dtype.kind in "iu" and table.min() >= 0 and table.max() <= _M32):
        # every key one word per element: the rows at once
        entropy = np.empty((table.shape[0], len(prefix) + table.shape[1]), dtype=np.uint64)
        entropy[:, : len(prefix)] = prefix
        entropy[:, len(prefix):] = table
        out = np.empty((table.shape[0], 4), dtype=np.uint64)
        _seed_sfc64(entropy, np.full(table.shape[0], entropy.shape[1], dtype=np.int64), out)
        return out
    rows = [prefix + [w for k in key for w in _words(int(k))] if len(key) else run
            for key in keys]
    width = max((len(r) for r in rows), default=0)
    entropy = np.zeros((len(rows), width), dtype=np.uint64)
    lengths = np.array([len(r) for r in rows], dtype=np.int64)
    for i, r in enumerate(rows):  # start-up only: one short list per stream
        entropy[i, : len(r)] = r
    out = np.empty((len(rows), 4), dtype=np.uint64)
    _seed_sfc64(entropy, lengths, out)
    return out


@inline_kernel
def _hashmix(value: int, const: np.ndarray) -> int:
    value = (value ^ const[0]) & _M32
    const[0] = (const[0] * _MULT_A) & _M32
    value = (value * const[0]) & _M32
    return value ^ (value >> 16)


@inline_kernel
def _mix(x: int, y: int) -> int:
    result = (_MIX_L * x - _MIX_R * y) & _M32
    return result ^ (result >> 16)


@kernel
def _seed_sfc64(entropy: np.ndarray, lengths: np.ndarray, out: np.ndarray) -> None:
    """SeedSequence pool of each row's entropy words, its first 3 uint64 words, and SFC64's
    seeding from them (counter 1, then 12 outputs discarded)."""
    pool = np.empty(_POOL_WORDS, dtype=np.uint64)
    const = np.empty(1, dtype=np.uint64)
    words = np.empty(6, dtype=np.uint64)
    mask = np.uint64(_M32)
    for row in range(entropy.shape[0]):
        n = lengths[row]
        const[0] = np.uint64(_INIT_A)
        for i in range(_POOL_WORDS):
            pool[i] = _hashmix(entropy[row, i] if i < n else np.uint64(0), const)
        for src in range(_POOL_WORDS):
            for dst in range(_POOL_WORDS):
                if src != dst:
                    pool[dst] = _mix(pool[dst], _hashmix(pool[src], const))
        for src in range(_POOL_WORDS, n):
            for dst in range(_POOL_WORDS):
                pool[dst] = _mix(pool[dst], _hashmix(entropy[row, src], const))
        h = np.uint64(_INIT_B)
        for i in range(6):
            v = pool[i % _POOL_WORDS] ^ h
            h = (h * np.uint64(_MULT_B)) & mask
            v = (v * h) & mask
            words[i] = v ^ (v >> np.uint64(16))
        s = out[row]
        for i in range(3):
            s[i] = words[2 * i] | (words[2 * i + 1] << np.uint64(32))
        s[3] = np.uint64(1)
        for _ in range(12):
            _raw(s)


def _ziggurat_tables(layers: int = 256, r: float = 3.6541528853610088,
                     area: float = 4.92867323399e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ziggurat of ``exp(-x^2/2)`` in ``layers`` strips of equal ``area`` (Marsaglia & Tsang
    2000, table 1: r and the strip area for 256 strips); 52-bit random integers.

    Strip 0 is the base (the rectangle of width r plus the tail, as a rectangle of the same
    area and width ``area / f(r)``), strip ``layers - 1`` the one resting on it, strip 1 the
    top. Returns ``(k, w, f)``: a 52-bit integer below ``k[i]`` falls under the curve in strip
    i for sure; ``w[i]`` maps it to x; ``f[i]`` is the density at the strip's right edge
    (``f[0] = 1``, the top of strip 1).
    """
    scale = 2.0**52
    edge = np.empty(layers)  # right edge x of every strip
    edge[0], edge[layers - 1] = area / math.exp(-0.5 * r * r), r
    for i in range(layers - 2, 0, -1):
        edge[i] = math.sqrt(-2.0 * math.log(area / edge[i + 1]
                                            + math.exp(-0.5 * edge[i + 1] ** 2)))
    f = np.exp(-0.5 * edge * edge)
    f[0] = 1.0  # the top of strip 1
    k = np.empty(layers, dtype=np.int64)
    k[0] = int(r / edge[0] * scale)
    k[1] = 0  # the top strip is never wholly under the curve
    k[2:] = (edge[1:-1] / edge[2:] * scale).astype(np.int64)
    return k, edge / scale, f


_K, _W, _F = _ziggurat_tables()
_R = 3.6541528853610088
_U53 = 1.0 / 9007199254740992.0  # 2^-53


@inline_kernel
def _raw(s: np.ndarray) -> np.uint64:
    """Next 64-bit word of an ``SFC64`` state ``s = [a, b, c, counter]`` (advanced in place)."""
    a, b, c, w = s[0], s[1], s[2], s[3]
    out = a + b + w
    s[3] = w + np.uint64(1)
    s[0] = b ^ (b >> np.uint64(11))
    s[1] = c + (c << np.uint64(3))
    s[2] = ((c << np.uint64(24)) | (c >> np.uint64(40))) + out
    return out


@inline_kernel
def _uniform(s: np.ndarray) -> float:
    """Uniform on [0, 1) from the top 53 bits of the next word."""
    return float(_raw(s) >> np.uint64(11)) * _U53


@inline_kernel
def _normal(s: np.ndarray, k: np.ndarray, w: np.ndarray, f: np.ndarray) -> float:
    """Standard normal by the ziggurat (see :func:`_ziggurat_tables`).

    A try is accepted with probability 0.985, so 64 tries never all fail (1e-100); the loops
    are bounded because unbounded ones keep the compiler from optimising the common case.
    """
    for _ in range(64):
        u = _raw(s)
        i = np.int64(u & np.uint64(0xFF))
        u >>= np.uint64(8)
        sign = 1.0 - 2.0 * float(u & np.uint64(1))
        bits = np.int64((u >> np.uint64(1)) & np.uint64(0xFFFFFFFFFFFFF))
        x = float(bits) * w[i]
        if bits < k[i]:
            return sign * x
        if i == 0:  # the tail beyond r
            for _ in range(64):
                xt = -math.log1p(-_uniform(s)) / _R
                yt = -math.log1p(-_uniform(s))
                if yt + yt > xt * xt:
                    return sign * (_R + xt)
        elif f[i] + _uniform(s) * (f[i - 1] - f[i]) < math.exp(-0.5 * x * x):
            return sign * x
    return 0.0


@kernel
def _fill(state: np.ndarray, out: np.ndarray, normal: bool, k: np.ndarray, w: np.ndarray,
          f: np.ndarray) -> None:
    """Fill ``out (steps, n, dims)`` from the ``n`` streams ``state (n, 4)``, each stream in
    step-major order (so the sequence does not depend on the block size)."""
    steps, n, dims = out.shape
    for j in range(n):
        s = state[j]
        for t in range(steps):
            for d in range(dims):
                out[t, j, d] = _normal(s, k, w, f) if normal else _uniform(s)


@inline_kernel
def normal_from(streams: np.ndarray, row: int) -> float:
    """Next standard normal of stream ``row`` of ``streams (n, 4)`` (advanced in place): for
    compiled loops that draw at need."""
    return _normal(streams[row], _K, _W, _F)


@inline_kernel
def uniform_from(streams: np.ndarray, row: int) -> float:
    """Next uniform on [0, 1) of stream ``row`` of ``streams (n, 4)`` (advanced in place)."""
    return _uniform(streams[row])


@kernel
def _normals(state: np.ndarray, out: np.ndarray) -> None:
    for j in range(out.shape[0]):
        for d in range(out.shape[1]):
            out[j, d] = normal_from(state, j)


def peek_normals(streams: np.ndarray, count: int) -> np.ndarray:
    """The next ``count`` standard normals of every stream of ``streams (n, 4)``, ``(n,
    count)``, without advancing them: what an event drawing ``count`` numbers by
    :func:`normal_from` will see."""
    out = np.empty((streams.shape[0], int(count)))
    _normals(np.array(streams, dtype=np.uint64), out)
    return out


def check_streams(streams: np.ndarray, rows: int) -> None:
    """Raise ``ValueError`` unless ``streams`` is a C-contiguous ``(rows, 4)`` uint64 array
    (drawn from in place, so never a converted copy)."""
    if (not isinstance(streams, np.ndarray) or streams.shape != (rows, 4)
            or streams.dtype != np.uint64 or not streams.flags.c_contiguous):
        got = (f"{streams.dtype} {streams.shape}" if isinstance(streams, np.ndarray)
               else type(streams).__name__)
        raise ValueError(f"streams must be a C-contiguous ({rows}, 4) uint64 array, got {got}")


def independent_streams(n: int, seed: int = 0, purpose: str = "radar") -> np.ndarray:
    """``(n, 4)`` states of ``n`` independent streams (keyed ``(seed, 0, row, purpose)``): for
    calling the at-need instruments outside the engine."""
    return NoiseBank(seed, [0] * n, range(n), purpose, 1).state


class NoiseBank:
    """Standard-normal and uniform draws for every ship, step by step, from keyed streams.

    Args:
        seed: the run's (or campaign's) seed.
        encounter: ``(n,)`` encounter index of every ship (campaign-wide index, not batch row).
        ship_in_encounter: ``(n,)`` index of every ship within its encounter.
        purpose: a name from :data:`PURPOSES`.
        dims: numbers drawn per ship per step.
        kind: ``"normal"`` (standard normal) or ``"uniform"`` ([0, 1)).
        other: optional ``(n,)`` index within the encounter of the other ship of each row
            (rows are then directed pairs: observer ``ship_in_encounter``, target ``other``).
    """

    def __init__(self, seed: int, encounter: Sequence[int] | np.ndarray,
                 ship_in_encounter: Sequence[int] | np.ndarray, purpose: str, dims: int,
                 kind: str = "normal", block_steps: int = BLOCK_STEPS,
                 other: Sequence[int] | np.ndarray | None = None) -> None:
        if kind not in ("normal", "uniform"):
            raise ValueError(f"kind must be 'normal' or 'uniform', got {kind!r}")
        self.kind, self.dims, self.block_steps = kind, int(dims), int(block_steps)
        columns = [encounter, ship_in_encounter] + ([] if other is None else [other])
        rows = {len(c) for c in columns}
        if len(rows) > 1:
            raise ValueError(f"encounter, ship_in_encounter and other differ in length: {rows}")
        self._keys = (seed, [np.array(c) for c in columns], purpose)  # (copies)
        self._state: np.ndarray | None = None  # seeded at the first draw: unread banks cost 0
        self._block: np.ndarray | None = None  # allocated at the first block: none at need
        self._row = self.block_steps

    @property
    def state(self) -> np.ndarray:
        """``(n, 4)`` uint64 ``SFC64`` state of every stream, advanced by every refill (or, for
        instruments that draw at need, by :func:`normal_from`)."""
        if self._state is None:
            seed, columns, purpose = self._keys
            p = np.full(len(columns[0]), PURPOSES.index(purpose))
            keys = [*columns[:2], p, *columns[2:]]  # (encounter, ship, purpose[, other])
            self._state = seeded_states(seed, np.stack(keys, axis=1) if len(p) else [])
        return self._state

    def _refill(self) -> None:
        if self._block is None:
            self._block = np.empty((self.block_steps, len(self._keys[1][0]), self.dims))
        _fill(self.state, self._block, self.kind == "normal", _K, _W, _F)
        self._row = 0

    def next(self) -> np.ndarray:
        """This step's draws, ``(n, dims)`` (a view, valid until the next call)."""
        if self._row == self.block_steps:
            self._refill()
        row = self._block[self._row]
        self._row += 1
        return row
