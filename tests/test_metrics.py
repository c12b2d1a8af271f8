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


@pytest.mark.parametrize("domain", domains.DOMAINS)
def test_compiled_metrics_match_array_formulas(domain: str) -> None:
    """Random pairs over 25 steps: minimum range, its time and the first domain violation as
    whole-array numpy formulas with the domain model's own ``contains``."""
    rng = np.random.default_rng(8)
    n = 600
    pi, pj = np.arange(0, n, 2), np.arange(1, n, 2)
    x = np.zeros((8, n))
    x[NORTH], x[EAST] = rng.uniform(-2500, 2500, (2, n))
    x[PSI], x[U] = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 9, n)
    length = rng.uniform(60, 300, n)
    m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, n)), pi, pj, domain)
    min_range = np.hypot(x[NORTH, pj] - x[NORTH, pi], x[EAST, pj] - x[EAST, pi])
    t_min, first = np.zeros(n // 2), np.full(n // 2, np.nan)
    for t in range(1, 26):
        x[NORTH] += rng.normal(0, 150, n)
        x[EAST] += rng.normal(0, 150, n)
        x[PSI] += 0.05
        m.accumulate(x, length, length / 6, pi, pj, float(t))
        dn, de = x[NORTH, pj] - x[NORTH, pi], x[EAST, pj] - x[EAST, pi]
        rng_now = np.hypot(dn, de)
        t_min = np.where(rng_now < min_range, t, t_min)
        min_range = np.minimum(min_range, rng_now)
        inside = np.zeros(n // 2, dtype=bool)
        for own, sign in ((pi, 1.0), (pj, -1.0)):
            c, s = np.cos(x[PSI, own]), np.sin(x[PSI, own])
            inside |= domains.contains(domain, sign * (dn * c + de * s),
                                       sign * (-dn * s + de * c), length[own], x[U, own])
        first = np.where(inside & np.isnan(first), t, first)
    np.testing.assert_array_equal(m.min_range_m, min_range)
    np.testing.assert_array_equal(m.t_min_range_s, t_min)
    np.testing.assert_array_equal(m.t_domain_violation_s, first)
    np.testing.assert_array_equal(m.domain_violation, ~np.isnan(first))
    assert 0 < m.domain_violation.sum() < n // 2


@pytest.mark.parametrize("domain", domains.DOMAINS)
def test_a_ship_just_inside_the_domain_at_any_bearing_is_a_violation(domain: str) -> None:
    """Also where the domain reaches farthest: the compiled loop skips the body-frame test only
    beyond the domain's reach."""
    bearings = np.radians(np.arange(0.0, 360.0, 5.0))
    reach = domains.boundary_distance_m(domain, bearings, np.full(bearings.size, L),
                                        np.full(bearings.size, 6.0))
    for b, r in zip(bearings, reach, strict=True):
        d = 0.999 * r
        x = _state([0.0, d * np.cos(b)], [0.0, d * np.sin(b)], [0.0, 0.0])
        assert _metrics(x, domain).domain_violation[0], np.degrees(b)
