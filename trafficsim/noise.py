"""Random streams for a batch: one ``numpy.random.Generator`` per (encounter, ship, purpose).

Every stream is ``Generator(PCG64(SeedSequence(seed, spawn_key=(encounter, ship, purpose))))``:
keyed explicitly, never by order of creation, so adding a ship, changing the batch size or the
number of workers leaves every other stream bit-identical (``SeedSequence.spawn`` is stateful
and would not). ``ship`` is the ship's index within its encounter; ``purpose`` the index of a
named purpose in :data:`PURPOSES`.

Drawing one number per ship per step from thousands of generators would be a Python loop over
ships on the step path. Instead each stream fills a block of ``block_steps`` steps at once, and
the step path reads a row of the block: the loop over streams runs once per block (about one
generator call per ship and purpose every 512 steps), and the values a ship sees depend only on
its own stream, never on the batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: every purpose that draws random numbers; append only (the index is part of the stream key)
PURPOSES = ("gnss", "gnss_gross", "compass", "log", "actuators", "waves", "radar", "ais",
            "initial", "ais_rx", "gnss2", "gnss2_gross", "gnss3", "gnss3_gross")
BLOCK_STEPS = 512


def generator(seed: int, encounter: int, ship: int, purpose: str,
              other: int | None = None) -> np.random.Generator:
    """The stream of one ship of one encounter for one purpose (and, for observations of
    another ship, that ship's index ``other`` within the encounter)."""
    key: tuple[int, ...] = (int(encounter), int(ship), PURPOSES.index(purpose))
    if other is not None:
        key = (*key, int(other))
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=key)))


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
        others = [None] * len(encounter) if other is None else list(other)
        self._gens = [generator(seed, e, s, purpose, o)
                      for e, s, o in zip(encounter, ship_in_encounter, others, strict=True)]
        self._block = np.empty((self.block_steps, len(self._gens), self.dims))
        self._row = self.block_steps

    def _refill(self) -> None:
        for k, g in enumerate(self._gens):  # once per block, not per step
            if self.kind == "normal":
                self._block[:, k, :] = g.standard_normal((self.block_steps, self.dims))
            else:
                self._block[:, k, :] = g.random((self.block_steps, self.dims))
        self._row = 0

    def next(self) -> np.ndarray:
        """This step's draws, ``(n, dims)`` (a view, valid until the next call)."""
        if self._row == self.block_steps:
            self._refill()
        row = self._block[self._row]
        self._row += 1
        return row
