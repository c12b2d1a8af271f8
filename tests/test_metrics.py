"""Pair metrics on true states: minimum range, collision and ship-domain violation."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.colregs import domains
from trafficsim.metrics import PairMetrics
from trafficsim.ships.base import EAST, NORTH, PSI, U

L = 160.0


def _state(north: list[float], east: list[float], heading_deg: list[float],
           speed: float = 6.0) -> np.ndarray:
    x = np.zeros((8, len(north)))
    x[NORTH], x[EAST], x[PSI], x[U] = north, east, np.radians(heading_deg), speed
    return x


def _metrics(x: np.ndarray, domain: str = "coldwell") -> PairMetrics:
    pi, pj = np.array([0]), np.array([1])
    vel = np.stack([x[U] * np.cos(x[PSI]), x[U] * np.sin(x[PSI])])
    m = PairMetrics.start(x[[NORTH, EAST]], vel, pi, pj, domain)
    m.accumulate(x, np.full(2, L), np.full(2, 28.0), pi, pj, 5.0)
    return m


@pytest.mark.parametrize("domain", domains.DOMAINS)
def test_domain_violation_is_either_ship_inside_the_others_domain(domain: str) -> None:
    # the other ship dead ahead, just inside and just outside own domain's forward extent
    ahead = domains.boundary_distance_m(domain, np.array([0.0]), np.array([L]),
                                        np.array([6.0]))[0]
    for dist, inside in ((0.95 * ahead, True), (1.05 * ahead, False)):
        # the second ship points away: only the first ship's domain can hold it... unless its
        # own domain astern reaches back that far; checked with the domain model itself
        x = _state([0.0, dist], [0.0, 0.0], [0.0, 0.0])
        aft = domains.boundary_distance_m(domain, np.array([np.pi]), np.array([L]),
                                          np.array([6.0]))[0]
        m = _metrics(x, domain)
        assert bool(m.domain_violation[0]) == (inside or dist <= aft)
        assert (m.t_domain_violation_s[0] == 5.0) == bool(m.domain_violation[0])


def test_coldwell_domain_is_asymmetric_so_direction_matters() -> None:
    """Coldwell: about 3.2 L to starboard, 1.7 L to port on the beam. Two ships 2.5 L apart
    side by side: a violation when either has the other on her starboard beam, none when each
    has the other to port (passing port to port)."""
    x = _state([0.0, 0.0], [0.0, 2.5 * L], [0.0, 0.0])  # same heading: one sees it to starboard
    assert _metrics(x).domain_violation[0]
    x = _state([0.0, 0.0], [0.0, 2.5 * L], [180.0, 0.0])  # reciprocal, each to port of the other
    assert not _metrics(x).domain_violation[0]
    x = _state([0.0, 0.0], [0.0, 2.5 * L], [0.0, 180.0])  # reciprocal, starboard to starboard
    assert _metrics(x).domain_violation[0]
