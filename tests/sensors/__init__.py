"""Tests of the own-ship sensor models; small shared helpers."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from trafficsim.errors import InputError
from trafficsim.ships import base

#: tolerance multiplier for statistical checks (fixed seeds; about 1 in 1.7 million to fail by
#: chance if the seed were redrawn)
Z = 5.0


def truth(n: int, **rows: float | np.ndarray) -> np.ndarray:
    """``(8, n)`` truth state: zeros except the named rows (``psi=``, ``u=`` ... by row name)."""
    x = np.zeros((base.N_STATE, n))
    for name, value in rows.items():
        x[getattr(base, name.upper())] = value
    return x


def random_headings(n: int, seed: int = 0) -> np.ndarray:
    """``(n,)`` headings uniform on [0, 2 pi)."""
    return np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, n)


def assert_mean(sample: np.ndarray, mean: float, sigma: float) -> None:
    """Sample mean within Z standard errors of ``mean`` (population sd ``sigma``)."""
    tol = Z * sigma / math.sqrt(sample.size)
    assert abs(sample.mean() - mean) < tol, (sample.mean(), mean, tol)


def assert_std(sample: np.ndarray, sigma: float) -> None:
    """Sample standard deviation within Z standard errors (normal data) of ``sigma``."""
    tol = Z * sigma / math.sqrt(2.0 * sample.size)
    assert abs(sample.std() - sigma) < tol, (sample.std(), sigma, tol)


def assert_rate(hits: int, trials: int, p: float) -> None:
    """Binomial count within Z standard deviations of ``p * trials``."""
    tol = Z * math.sqrt(trials * p * (1.0 - p)) + 1.0
    assert abs(hits - p * trials) < tol, (hits, p * trials, tol)


def assert_bound(build: Callable[[list[dict]], object], what: str, key: str, inside: float,
                 beyond: float, message: str, **same: object) -> None:
    """A physical bound of a config key: ``inside`` (just within it) builds; ``beyond`` is
    refused for the second ship, naming ``<what>[1].<key>`` and saying ``message``. ``same``:
    further keys both configs carry (e.g. ``kind``)."""
    build([{**same}, {**same, key: inside}])
    with pytest.raises(InputError) as err:
        build([{**same}, {**same, key: beyond}])
    assert (err.value.key, err.value.message) == (f"{what}[1].{key}", message)

