"""Pair metrics on true states: minimum range, collision and ship-domain violation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from trafficsim.colregs import domains
from trafficsim.errors import InputError
from trafficsim.geometry import hull_outlines
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
    d0 = x[[NORTH, EAST]][:, pj] - x[[NORTH, EAST]][:, pi]
    min_range = np.sqrt(d0[0] * d0[0] + d0[1] * d0[1])
    t_min, first = np.zeros(n // 2), np.full(n // 2, np.nan)
    for t in range(1, 26):
        x[NORTH] += rng.normal(0, 150, n)
        x[EAST] += rng.normal(0, 150, n)
        x[PSI] += 0.05
        m.accumulate(x, length, length / 6, pi, pj, float(t))
        dn, de = x[NORTH, pj] - x[NORTH, pi], x[EAST, pj] - x[EAST, pi]
        rng_now = np.sqrt(dn * dn + de * de)
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



def _pentagon(north: float, east: float, psi: float, length: float, beam: float):
    """Hull outline written out: stern corners, shoulders at 0.3 L, bow point at 0.5 L."""
    body = [(-0.5, -0.5), (0.3, -0.5), (0.5, 0.0), (0.3, 0.5), (-0.5, 0.5)]
    c, s = math.cos(psi), math.sin(psi)
    return shapely.Polygon([(north + x * length * c - y * beam * s,
                             east + x * length * s + y * beam * c) for x, y in body])


def _one_pair(north, east, heading_deg, length, beam, t_s=1.0):
    """Metrics of ships 0 and 1 after one accumulate at ``t_s`` (zero speed)."""
    x = np.zeros((8, 2))
    x[NORTH], x[EAST], x[PSI] = north, east, np.radians(heading_deg)
    pi, pj = np.array([0]), np.array([1])
    m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, 2)), pi, pj)
    m.accumulate(x, np.asarray(length, float), np.asarray(beam, float), pi, pj, t_s)
    return m


def test_start_gives_closed_form_cpa_and_range() -> None:
    """Head-on with a 300 m offset: relative position (1000, 300), relative velocity (-10, 0):
    tcpa 100 s, dcpa 300 m; equal velocities: tcpa 0, dcpa the range; opening straight away
    at 4 m/s from 400 m: the closest point was 100 s ago, through the same spot (dcpa 0)."""
    pos = np.array([[0.0, 1000.0, 0.0, 500.0, 0.0, 0.0],
                    [0.0, 300.0, 0.0, 0.0, 0.0, 400.0]])
    vel = np.array([[5.0, -5.0, 3.0, 3.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 1.0, 0.0, 4.0]])
    pi, pj = np.array([0, 2, 4]), np.array([1, 3, 5])
    m = PairMetrics.start(pos, vel, pi, pj)
    np.testing.assert_allclose(m.tcpa0_s[:2], [100.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(m.dcpa0_m, [300.0, 500.0, 0.0], rtol=1e-14, atol=1e-12)
    assert m.tcpa0_s[2] == pytest.approx(-400.0 * 4.0 / 16.0, rel=1e-14)
    np.testing.assert_allclose(m.min_range_m, [math.hypot(1000, 300), 500.0, 400.0],
                               rtol=1e-15)
    np.testing.assert_array_equal(m.t_min_range_s, 0.0)
    assert not m.collision.any() and np.isnan(m.t_collision_s).all()
    assert not m.domain_violation.any() and np.isnan(m.t_domain_violation_s).all()


@pytest.mark.parametrize("factor, hit", [(0.999, True), (1.001, False)])
def test_bow_to_bow_and_side_by_side_contact(factor: float, hit: bool) -> None:
    """Reciprocal headings on one line touch when the centres are (L_a + L_b) / 2 apart (the
    bow points); parallel ships abeam touch at (B_a + B_b) / 2."""
    La, Lb, Ba, Bb = 120.0, 200.0, 20.0, 32.0
    m = _one_pair([0.0, factor * (La + Lb) / 2], [0.0, 0.0], [0.0, 180.0], [La, Lb], [Ba, Bb])
    assert bool(m.collision[0]) == hit
    assert (m.t_collision_s[0] == 1.0) if hit else np.isnan(m.t_collision_s[0])
    m = _one_pair([0.0, 10.0], [0.0, factor * (Ba + Bb) / 2], [0.0, 0.0], [La, Lb], [Ba, Bb])
    assert bool(m.collision[0]) == hit


def test_bow_into_the_stern_quarter_is_a_collision() -> None:
    """Ship B's bow half a metre into ship A's stern corner along A's diagonal: the outlines
    overlap (shapely says so) while the centres are 100.5 m apart, more than (100 + 100) / 2."""
    L, B = 100.0, 20.0
    corner = np.array([-0.5 * L, 0.5 * B])
    u = corner / np.hypot(*corner)
    centre = corner + (0.5 * L - 0.5) * u
    heading = math.degrees(math.atan2(-u[1], -u[0]))  # B's bow towards A's centre
    pa = _pentagon(0.0, 0.0, 0.0, L, B)
    pb = _pentagon(centre[0], centre[1], math.radians(heading), L, B)
    assert pa.intersects(pb) and np.hypot(*centre) > L
    m = _one_pair([0.0, centre[0]], [0.0, centre[1]], [0.0, heading], [L, L], [B, B])
    assert m.collision[0]


def test_hull_outlines_are_the_documented_pentagons() -> None:
    """The metric's outlines (geometry.hull_outlines) are the pentagons written out above, so
    the brute-force reference below tests the metric, not a different shape."""
    rng = np.random.default_rng(60)
    for _ in range(20):
        n, e, psi = rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3), rng.uniform(0, 7)
        out = hull_outlines(np.array([n]), np.array([e]), np.array([psi]), np.array([150.0]),
                            np.array([25.0]))[0]
        ref = np.array(_pentagon(n, e, psi, 150.0, 25.0).exterior.coords)
        np.testing.assert_allclose(out[:-1], ref[:-1], rtol=0, atol=1e-9)


def test_metrics_match_a_brute_force_loop_over_steps() -> None:
    """Slender ships (beam L / 40: corners within 0.03 % of L / 2) milling about each other for
    40 steps: minimum range and its first time, collision and its first time per pair equal
    a loop over steps and pairs with shapely on every pair (no prefilter)."""
    rng = np.random.default_rng(61)
    n = 60
    pi, pj = np.triu_indices(6)
    keep = pi != pj
    base_i, base_j = pi[keep], pj[keep]
    groups = np.arange(0, n, 6)
    pi = np.concatenate([g + base_i for g in groups])
    pj = np.concatenate([g + base_j for g in groups])
    length = rng.uniform(60, 200, n)
    beam = length / 40
    x = np.zeros((8, n))
    x[NORTH] = rng.uniform(-250, 250, n) + np.repeat(groups * 10_000.0, 6)
    x[EAST] = rng.uniform(-250, 250, n)
    x[PSI] = rng.uniform(0, 2 * np.pi, n)
    m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, n)), pi, pj)
    p = pi.size
    d0 = x[[NORTH, EAST]][:, pj] - x[[NORTH, EAST]][:, pi]
    ref_min = np.sqrt(d0[0] * d0[0] + d0[1] * d0[1])  # (the metric's range: root of squares)
    ref_tmin, ref_col, ref_tcol = np.zeros(p), np.zeros(p, bool), np.full(p, np.nan)
    for t in range(1, 41):
        x[NORTH] += rng.normal(0, 20, n)
        x[EAST] += rng.normal(0, 20, n)
        x[PSI] += rng.normal(0, 0.2, n)
        m.accumulate(x, length, beam, pi, pj, float(t))
        for k in range(p):
            a, b = pi[k], pj[k]
            dn, de = x[NORTH, b] - x[NORTH, a], x[EAST, b] - x[EAST, a]
            rng_k = math.sqrt(dn * dn + de * de)
            if rng_k < ref_min[k]:
                ref_min[k], ref_tmin[k] = rng_k, t
            if not ref_col[k] and _pentagon(x[NORTH, a], x[EAST, a], x[PSI, a], length[a],
                                            beam[a]).intersects(
                    _pentagon(x[NORTH, b], x[EAST, b], x[PSI, b], length[b], beam[b])):
                ref_col[k], ref_tcol[k] = True, t
    np.testing.assert_array_equal(m.min_range_m, ref_min)
    np.testing.assert_array_equal(m.t_min_range_s, ref_tmin)
    np.testing.assert_array_equal(m.collision, ref_col)
    np.testing.assert_array_equal(m.t_collision_s, ref_tcol)
    assert 0 < ref_col.sum() < p


@pytest.mark.parametrize("domain", domains.DOMAINS)
def test_pair_order_does_not_matter(domain: str) -> None:
    """Every metric is of the unordered pair: listing each pair as (j, i) gives the same
    ranges, collisions and domain violations (either ship inside the other's domain)."""
    rng = np.random.default_rng(62)
    n = 200
    pi, pj = np.arange(0, n, 2), np.arange(1, n, 2)
    x = np.zeros((8, n))
    x[NORTH], x[EAST] = rng.uniform(-1500, 1500, (2, n))
    x[PSI], x[U] = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 9, n)
    length = rng.uniform(60, 300, n)
    vel = rng.normal(0, 4, (2, n))
    ms = [PairMetrics.start(x[[NORTH, EAST]], vel, a, b, domain) for a, b in ((pi, pj), (pj, pi))]
    for t in range(1, 8):
        x[NORTH] += rng.normal(0, 300, n)
        x[EAST] += rng.normal(0, 300, n)
        for m, (a, b) in zip(ms, ((pi, pj), (pj, pi)), strict=True):
            m.accumulate(x, length, length / 6, a, b, float(t))
    one, two = ms
    np.testing.assert_allclose(one.dcpa0_m, two.dcpa0_m, rtol=1e-12)
    np.testing.assert_allclose(one.tcpa0_s, two.tcpa0_s, rtol=1e-12)
    np.testing.assert_array_equal(one.min_range_m, two.min_range_m)
    np.testing.assert_array_equal(one.collision, two.collision)
    np.testing.assert_array_equal(one.domain_violation, two.domain_violation)
    np.testing.assert_array_equal(one.t_domain_violation_s, two.t_domain_violation_s)
    assert 0 < one.domain_violation.sum() < n // 2


def test_first_times_stick_and_ties_keep_the_earliest() -> None:
    """A collision and a domain violation keep their first time while they go on; the
    minimum range keeps the first time it was reached when a later step only equals it."""
    pi, pj = np.array([0]), np.array([1])
    length, beam = np.full(2, 100.0), np.full(2, 20.0)
    x = np.zeros((8, 2))
    x[NORTH, 1] = 1000.0
    m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, 2)), pi, pj)
    for t, d in ((1.0, 50.0), (2.0, 30.0), (3.0, 30.0), (4.0, 60.0)):
        x[NORTH, 1] = d
        m.accumulate(x, length, beam, pi, pj, t)
    assert m.collision[0] and m.t_collision_s[0] == 1.0
    assert m.domain_violation[0] and m.t_domain_violation_s[0] == 1.0
    assert m.min_range_m[0] == 30.0 and m.t_min_range_s[0] == 2.0


def test_a_pair_no_longer_active_keeps_its_figures() -> None:
    """Two pairs close to collision; the second stops being measured first (its encounter
    ended): it keeps its range, and no later collision or domain entry counts for it."""
    pi, pj = np.array([0, 2]), np.array([1, 3])
    length, beam = np.full(4, 100.0), np.full(4, 20.0)
    x = np.zeros((8, 4))
    x[NORTH, [1, 3]] = 3000.0
    m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, 4)), pi, pj)
    m.active[1] = False
    x[NORTH, [1, 3]] = 30.0
    m.accumulate(x, length, beam, pi, pj, 1.0)
    assert m.collision.tolist() == [True, False]
    assert m.domain_violation.tolist() == [True, False]
    assert m.min_range_m.tolist() == [30.0, 3000.0] and m.t_min_range_s.tolist() == [1.0, 0.0]


def test_no_pairs_and_unknown_domain() -> None:
    """A batch without pairs accumulates nothing; an unknown domain name is an InputError
    that suggests the near name."""
    x = np.zeros((8, 1))
    empty = np.zeros(0, dtype=np.int64)
    m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, 1)), empty, empty)
    m.accumulate(x, np.full(1, 100.0), np.full(1, 20.0), empty, empty, 1.0)
    assert m.min_range_m.shape == (0,) and m.collision.shape == (0,)
    x = np.zeros((8, 2))
    x[NORTH, 1] = 5000.0
    pi, pj = np.array([0]), np.array([1])
    with pytest.raises(InputError, match="coldwell"):
        m = PairMetrics.start(x[[NORTH, EAST]], np.zeros((2, 2)), pi, pj, "coldwel")
        m.accumulate(x, np.full(2, 100.0), np.full(2, 20.0), pi, pj, 1.0)
