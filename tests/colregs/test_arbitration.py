"""Tests of the one-manoeuvre-per-ship arbitration (Rule 8(d)).

Expectations are computed by hand (closed-form DCPA of straight tracks, shared/reference/colregs.md
section 4) and checked again with an independent closest-approach search: the range of the two
straight tracks sampled densely over the look-ahead, sharing no code with the module.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from trafficsim.colregs.arbitration import (
    APPARENT_CHANGE_DEG,
    N_CANDIDATES,
    OFFSETS_RAD,
    _cost,
    candidate_offset_rad,
    candidate_reduced,
    choose,
)
from trafficsim.colregs.vocabulary import EITHER, PORT, STARBOARD

NM = 1852.0
V = 12.0 * NM / 3600.0  # 12 kn, m/s
H = 1800.0  # the 30 min look-ahead of rules/colregs.yaml, s
N_OFF = OFFSETS_RAD.size  # 37 offsets -90..90 deg; candidate k + N_OFF is k at reduced speed


def cand(offset_deg: float, reduced: bool = False) -> int:
    """Index of the candidate with this course offset (deg, + = starboard)."""
    k = round((offset_deg + 90.0) / 5.0)
    return k + (N_OFF if reduced else 0)


def closest_sampled(rel_n: float, rel_e: float, dvn: float, dve: float, horizon_s: float,
                    n: int = 20_001) -> float:
    """Least range of straight tracks over ``[0, horizon_s]`` by dense sampling, m; +inf when
    the range opens from the start (CPA past: no constraint)."""
    if rel_n * dvn + rel_e * dve >= 0.0:
        return math.inf
    t = np.linspace(0.0, horizon_s, n)
    return float(np.hypot(rel_n + dvn * t, rel_e + dve * t).min())


def worst_margin(base_deg: float, speed: float, factor: float, k: int, threats: list[tuple],
                 horizon_s: float) -> float:
    """Smallest (closest approach - required) over the threats for candidate ``k``, m.

    ``threats``: (rel_north_m, rel_east_m, other_vn, other_ve, required_m) per other ship.
    """
    off = (k % N_OFF) * 5.0 - 90.0
    c = math.radians(base_deg + off)
    sp = speed * (factor if k >= N_OFF else 1.0)
    vn, ve = sp * math.cos(c), sp * math.sin(c)
    return min(closest_sampled(pn, pe, ovn - vn, ove - ve, horizon_s) - req
               for pn, pe, ovn, ove, req in threats)


def choose_one(threats: list[tuple], *, base_deg: float = 0.0, speed: float = V,
               factor: float = 0.5, side: float = STARBOARD, least_deg: float = 30.0,
               reduce: bool = False, current: int = -1, horizon_s: float = H) -> tuple[int, bool]:
    """``choose`` for one ship with the threats as in :func:`worst_margin`."""
    t = np.array(threats, dtype=float).reshape(-1, 5)
    chosen, ok = choose(
        np.array([math.radians(base_deg)]), np.array([speed]), np.array([factor]),
        np.array([side]), np.array([math.radians(least_deg)]), np.array([reduce]),
        np.array([current]), np.zeros(t.shape[0], dtype=np.int64), t[:, 0], t[:, 1], t[:, 2],
        t[:, 3], t[:, 4], horizon_s)
    assert chosen.shape == ok.shape == (1,)
    return int(chosen[0]), bool(ok[0])


# Imazu case 2 seen from the own ship at the origin heading north at 12 kn: a ship 6 NM north-east
# heading west at 12 kn, both reaching (6 NM, 0) after 30 min. For a course offset theta (own
# velocity v (cos theta, sin theta)) the closed-form DCPA is
#     6 NM (1 + sin theta - cos theta) / sqrt(2 + 2 sin theta)
# = 4067 m at 30 deg, 5375 m at 40 deg, 6014 m at 45 deg, 7857 m at 60 deg.
D = 6.0 * NM
CROSSING = (D, D, 0.0, -V)


def dcpa_crossing(theta_deg: float) -> float:
    th = math.radians(theta_deg)
    return D * (1.0 + math.sin(th) - math.cos(th)) / math.sqrt(2.0 + 2.0 * math.sin(th))


def test_candidate_table():
    assert N_CANDIDATES == 2 * N_OFF == 74
    k = np.arange(N_CANDIDATES)
    np.testing.assert_allclose(np.degrees(candidate_offset_rad(k)),
                               np.tile(np.arange(-90.0, 91.0, 5.0), 2), atol=1e-12)
    np.testing.assert_array_equal(candidate_reduced(k), k >= N_OFF)
    assert math.degrees(candidate_offset_rad(np.array([cand(35.0)]))[0]) == pytest.approx(35.0)


def test_hand_computed_crossing_dcpa():
    """The closed form above agrees with the sampled closest approach (the check of the check)."""
    for theta in (30.0, 40.0, 45.0, 60.0):
        c = math.radians(theta)
        sampled = closest_sampled(D, D, -V * math.cos(c), -V - V * math.sin(c), 3600.0)
        assert sampled == pytest.approx(dcpa_crossing(theta), abs=0.01)
    assert dcpa_crossing(30.0) == pytest.approx(4067.4, abs=0.5)
    assert dcpa_crossing(40.0) == pytest.approx(5375.0, abs=0.5)
    assert dcpa_crossing(45.0) == pytest.approx(6014.0, abs=0.5)


def test_crossing_from_starboard_least_sufficient_starboard_turn():
    """3 NM asked, at least 30 deg: 30 (4067 m) and 40 (5375 m) fall short, 45 (6014 m) is the
    smallest starboard offset that passes at 3 NM."""
    chosen, ok = choose_one([(*CROSSING, 3 * NM)])
    assert ok
    assert chosen == cand(45.0)
    assert worst_margin(0.0, V, 0.5, chosen, [(*CROSSING, 3 * NM)], H) >= 0.0
    assert worst_margin(0.0, V, 0.5, cand(40.0), [(*CROSSING, 3 * NM)], H) < 0.0


@pytest.mark.parametrize("required_nm", [0.5, 1.0, 2.0, 3.0, 3.5])
def test_crossing_smallest_offset_matches_independent_search(required_nm):
    threats = [(*CROSSING, required_nm * NM)]
    chosen, ok = choose_one(threats)
    expected = next(cand(a) for a in np.arange(30.0, 91.0, 5.0)
                    if worst_margin(0.0, V, 0.5, cand(a), threats, H) >= 0.0)
    assert ok
    assert chosen == expected
    assert not candidate_reduced(np.array([chosen]))[0]


def test_least_change_is_honoured_even_when_a_smaller_turn_would_do():
    """1 NM needs only 15 deg here (10 deg: 1369 m, 15 deg: 2051 m), but 30 deg is asked
    (Rule 8(b)): 30 deg; with no least alteration asked, 15 deg."""
    threats = [(*CROSSING, 1 * NM)]
    assert dcpa_crossing(10.0) == pytest.approx(1369.0, abs=1.0)
    assert dcpa_crossing(15.0) == pytest.approx(2051.0, abs=1.0)
    assert choose_one(threats, least_deg=30.0) == (cand(30.0), True)
    assert choose_one(threats, least_deg=0.0) == (cand(15.0), True)


def test_offsets_are_taken_from_the_base_course():
    """The whole picture rotated by 100 deg gives the same offset."""
    rot = math.radians(100.0)
    c, s = math.cos(rot), math.sin(rot)
    pn, pe, vn, ve = CROSSING
    threat = (c * pn - s * pe, s * pn + c * pe, c * vn - s * ve, s * vn + c * ve, 3 * NM)
    assert choose_one([threat], base_deg=100.0) == (cand(45.0), True)


def test_port_side_is_honoured():
    """Port asked: the mirror image, -45 deg (-30: 4067 m, -40: 5375 m; the look-ahead is long
    enough here for every CPA to fall inside it)."""
    chosen, ok = choose_one([(*CROSSING, 3 * NM)], side=PORT, horizon_s=3600.0)
    assert ok
    assert chosen == cand(-45.0)
    assert worst_margin(0.0, V, 0.5, cand(-40.0), [(*CROSSING, 3 * NM)], 3600.0) < 0.0
    # starboard asked in the same picture: +45
    assert choose_one([(*CROSSING, 3 * NM)], horizon_s=3600.0)[0] == cand(45.0)


def test_asked_side_is_kept_when_only_the_other_side_passes():
    """Rules 14, 15 and 19(d): a ship 1.13 NM on the starboard bow (045 deg) steering west at
    12 kn, both ships reaching the same point in 4 min. Turned 90 deg to port the own ship
    runs parallel to her and keeps the 1.13 NM (the only candidate that passes at 1 NM); every
    starboard turn falls short. Starboard asked: the starboard candidate with the largest
    margin (the hard turn that passes astern of her), never the port turn; either side
    allowed, the port turn is taken."""
    r = 1.13 * NM / math.sqrt(2.0)
    threats = [(r, r, 0.0, -V, NM)]
    assert worst_margin(0.0, V, 0.5, cand(-90.0), threats, H) >= 0.0
    assert all(worst_margin(0.0, V, 0.5, cand(a, red), threats, H) < 0.0
               for a in np.arange(0.0, 91.0, 5.0) for red in (False, True))
    chosen, ok = choose_one(threats)
    assert not ok and 5.0 * (chosen % N_OFF) - 90.0 >= 0.0
    best = max(worst_margin(0.0, V, 0.5, k, threats, H) for k in range(N_CANDIDATES)
               if k % N_OFF >= cand(0.0))
    assert worst_margin(0.0, V, 0.5, chosen, threats, H) == pytest.approx(best, abs=1e-3)
    # a running port turn is not kept when starboard is asked, even while it keeps the distance
    assert choose_one(threats, current=cand(-90.0)) == (chosen, False)
    assert choose_one(threats, side=EITHER) == (cand(-90.0), True)


def test_either_side_prefers_starboard_among_equals():
    chosen, ok = choose_one([(*CROSSING, 3 * NM)], side=EITHER, horizon_s=3600.0)
    assert (chosen, ok) == (cand(45.0), True)


def test_closest_approach_counts_within_the_look_ahead():
    """A 30 deg port turn gives a CPA of 4067 m after 41 min; within a 30 min look-ahead the
    closest range is the one at its end: (6 NM - 1800 V cos 30, 6 NM - 1800 V (1 - sin 30)) =
    (1489 m, 5556 m), 5752 m, more than 3 NM, so -30 already satisfies the pair."""
    threats = [(*CROSSING, 3 * NM)]
    assert math.hypot(D - H * V * math.cos(math.radians(30.0)), D - H * V * 0.5) == \
        pytest.approx(5752.0, abs=1.0)
    assert choose_one(threats, side=PORT, horizon_s=H) == (cand(-30.0), True)


def test_pair_past_cpa_constrains_nothing():
    """A ship astern and opening (TCPA < 0 for every candidate) asks nothing: with no
    alteration asked the ship keeps its course at full speed."""
    threats = [(-2000.0, 0.0, -2 * V, 0.0, 5 * NM)]
    assert choose_one(threats, least_deg=0.0, side=EITHER) == (cand(0.0), True)


def test_second_ship_forces_a_larger_turn_rule_8d():
    """A stationary ship 8000 m away on bearing 030 is no threat on the present course (it
    passes at 8000 sin 30 = 4000 m) but a 30 or 40 deg turn towards it would pass at
    8000 sin 0 = 0 m and 8000 sin 10 = 1389 m: the turn grows to 45 deg (8000 sin 15 = 2071 m),
    which also clears the crossing ship (6014 m)."""
    b = math.radians(30.0)
    anchored = (8000.0 * math.cos(b), 8000.0 * math.sin(b), 0.0, 0.0, 1 * NM)
    crossing = (*CROSSING, 1 * NM)
    assert choose_one([crossing]) == (cand(30.0), True)
    assert worst_margin(0.0, V, 0.5, cand(0.0), [anchored], H) > 0.0  # not a threat now
    assert worst_margin(0.0, V, 0.5, cand(40.0), [crossing, anchored], H) < 0.0
    chosen, ok = choose_one([crossing, anchored])
    assert ok
    assert chosen == cand(45.0)
    assert worst_margin(0.0, V, 0.5, chosen, [crossing, anchored], H) == \
        pytest.approx(8000.0 * math.sin(math.radians(15.0)) - NM, abs=0.5)


def test_running_manoeuvre_is_kept_while_valid_rule_8b():
    threats = [(*CROSSING, 1 * NM)]
    # a 60 deg turn under way still passes at 7857 m: kept, not replaced by a smaller one
    assert choose_one(threats, current=cand(60.0)) == (cand(60.0), True)
    # a reduced-speed candidate under way is kept too
    assert choose_one(threats, current=cand(50.0, True)) == (cand(50.0, True), True)
    # the route course (offset 0) no longer satisfies the pair: replaced by the least turn
    assert choose_one(threats, current=cand(0.0)) == (cand(30.0), True)
    # a turn that stopped satisfying the pair (2.5 NM asked now, 4630 m) is replaced by one
    # substantial change (Rule 8(b)): 45 deg, not 35 deg (4726 m), the least that passes anew;
    # a speed reduction on the same course would do too but is not asked
    wider = [(*CROSSING, 2.5 * NM)]
    assert dcpa_crossing(30.0) < 2.5 * NM < dcpa_crossing(35.0)
    assert choose_one(wider) == (cand(35.0), True)
    assert choose_one(wider, current=cand(30.0)) == (cand(45.0), True)
    assert choose_one(wider, current=cand(30.0), reduce=True) == (cand(30.0, True), True)


def test_running_alongside_is_not_kept():
    """The running 30 deg turn puts the own ship alongside a ship 2500 m on her starboard beam
    steering 030 at 12 kn: no relative motion keeps the 2500 m (>= 1 NM, so it satisfies the
    pair), but within 2 x 1 NM at less than 1 m/s relative speed the encounter is never
    resolved. The running candidate is given up for one that is not alongside her."""
    c = math.radians(30.0)
    beam = (2500.0 * math.cos(c + math.pi / 2), 2500.0 * math.sin(c + math.pi / 2))
    threats = [(*beam, V * math.cos(c), V * math.sin(c), NM)]
    assert worst_margin(0.0, V, 0.5, cand(30.0), threats, H) == math.inf  # never closes
    chosen, ok = choose_one(threats, current=cand(30.0))
    assert ok and chosen != cand(30.0)
    off = math.radians(5.0 * (chosen % N_OFF) - 90.0)
    sp = V * (0.5 if candidate_reduced(np.array([chosen]))[0] else 1.0)
    assert math.hypot(V * math.cos(c) - sp * math.cos(off),
                      V * math.sin(c) - sp * math.sin(off)) >= 1.0


def test_running_manoeuvre_kept_as_the_encounter_develops():
    """Both ships advance along straight lines with the chosen manoeuvre: one decision per
    minute keeps the same candidate (no succession of small changes)."""
    threats = [(*CROSSING, 1 * NM)]
    chosen, _ = choose_one(threats)
    c = math.radians(5.0 * (chosen % N_OFF) - 90.0)
    pn, pe, ovn, ove = CROSSING
    for minute in range(1, 20):
        t = 60.0 * minute
        rel = (pn + (ovn - V * math.cos(c)) * t, pe + (ove - V * math.sin(c)) * t)
        assert choose_one([(*rel, ovn, ove, NM)], current=chosen) == (chosen, True)


def test_speed_reduction_only_when_asked():
    """3 NM: at full speed 45 deg is needed, at half speed 30 deg already passes at
    6 NM |(-1.25 + 0.433)| / 1.323 = 6862 m (CPA after 1731 s, inside the look-ahead)."""
    threats = [(*CROSSING, 3 * NM)]
    assert worst_margin(0.0, V, 0.5, cand(30.0, True), threats, H) == \
        pytest.approx(6862.0 - 3 * NM, abs=2.0)
    assert choose_one(threats, reduce=False) == (cand(45.0), True)
    assert choose_one(threats, reduce=True) == (cand(30.0, True), True)
    # asked to slow down, no alteration asked: a bare speed reduction when it suffices; at half
    # speed on the route course the range at the end of the look-ahead is (6 NM - 5556 m, 0)
    # = 3 NM, so 2 NM is kept
    two = [(*CROSSING, 2 * NM)]
    assert choose_one(two, reduce=True, least_deg=0.0, side=EITHER) == (cand(0.0, True), True)
    assert choose_one(two, reduce=False, least_deg=0.0) == (cand(30.0), True)


def ring(radius_m: float, required_m: float) -> list[tuple]:
    """Stationary ships on a circle around the own ship, every 10 deg from 260 to 100."""
    return [(radius_m * math.cos(math.radians(b)), radius_m * math.sin(math.radians(b)), 0.0,
             0.0, required_m) for b in np.arange(-100.0, 101.0, 10.0)]


def test_speed_reduction_when_no_alteration_works():
    """Boxed in by a ring of ships 8000 m away: at full speed every course passes within
    8000 sin 5 = 697 m of one of them inside the look-ahead; at half speed the own ship
    covers only 5556 m in 30 min and stays 2444 m off the ring. Not asked to slow down, the
    ship still slows, with the least alteration asked (30 deg to starboard)."""
    threats = ring(8000.0, NM)
    assert all(worst_margin(0.0, V, 0.5, cand(a), threats, H) < 0.0
               for a in np.arange(-90.0, 91.0, 5.0))
    chosen, ok = choose_one(threats, reduce=False)
    assert ok
    assert chosen == cand(30.0, True)
    assert choose_one(threats, reduce=False, least_deg=0.0, side=EITHER) == \
        (cand(0.0, True), True)


def test_a_speed_reduction_comes_before_an_alteration_smaller_than_asked():
    """The docstring's order where the asked alteration is not safe: slacken speed on the base
    course (Rule 8(e)) before any too-small alteration at full or reduced speed (Rule 8(b))."""
    def cost(offset, reduced):
        return _cost(float(offset), reduced, 30.0, False, False, math.nan)

    bare = cost(0.0, True)
    assert all(bare < cost(d, r) for d in (5.0, 10.0, 25.0) for r in (False, True))
    assert cost(30.0, False) < bare  # the asked alteration first of all


def test_a_replacement_is_readily_apparent_and_goes_further_out():
    """Rule 8(b): a running 30 deg turn that falls short is replaced by at least 45 deg, or by
    a speed reduction on its course, never by 35 or 40 deg; a running 80 deg turn by 90 deg
    (the largest offset) before any smaller alteration, which would undo part of the
    manoeuvre."""
    def cost(offset, reduced=False, run=30.0, reduce=False):
        return _cost(float(offset), reduced, 30.0, reduce, False, run)

    assert cost(30.0 + APPARENT_CHANGE_DEG) < min(cost(35.0), cost(40.0))
    assert cost(30.0, True, reduce=True) < cost(45.0, reduce=True)
    assert all(cost(90.0, run=80.0) < cost(d, r, run=80.0) for d in (30.0, 40.0, 60.0, 85.0)
               for r in (False, True))


def test_no_solution_returns_best_margin_and_not_ok():
    """A ship 1000 m dead ahead on a reciprocal course, 1 NM asked: nothing passes at 1 NM.
    Full speed passes at 1000 sin(theta / 2), best at 90 deg (707 m); half speed only at
    500 sin theta / sqrt(1.25 + cos theta) (447 m at 90 deg)."""
    threats = [(1000.0, 0.0, -V, 0.0, NM)]
    chosen, ok = choose_one(threats)
    assert not ok
    assert chosen == cand(90.0)
    assert worst_margin(0.0, V, 0.5, chosen, threats, H) == pytest.approx(707.1 - NM, abs=0.5)
    margins = [worst_margin(0.0, V, 0.5, k, threats, H) for k in range(N_CANDIDATES)
               if (k % N_OFF) >= cand(0.0)]
    assert max(margins) == pytest.approx(worst_margin(0.0, V, 0.5, chosen, threats, H), abs=0.01)
    # port asked: the mirror image, still on the asked side
    assert choose_one(threats, side=PORT) == (cand(-90.0), False)


def test_no_solution_tie_prefers_starboard():
    """Either side allowed, the mirror-symmetric picture above: +90 and -90 have the same
    margin; the starboard preference (Rules 14, 17(c)) should break the tie."""
    threats = [(1000.0, 0.0, -V, 0.0, NM)]
    assert choose_one(threats, side=EITHER) == (cand(90.0), False)


def test_no_relative_motion_keeps_the_present_range():
    """A ship 300 m on the starboard beam steering 030 at 12 kn: the 30 deg turn at full speed
    puts the own ship alongside her at 300 m for the whole look-ahead, which does not keep the
    1 NM asked."""
    c = math.radians(30.0)
    threats = [(0.0, 300.0, V * math.cos(c), V * math.sin(c), NM)]
    assert choose_one(threats) != (cand(30.0), True)


# --------------------------------------------------------------------------------------------
# Vectorisation: many ships at once = one ship at a time
# --------------------------------------------------------------------------------------------

def _margins(base, speed, factor, pair_ship, pn, pe, ovn, ove, req, horizon_s):
    """``(q, K)`` margin per pair and candidate, closed form written for this test; NaN with
    no relative motion (see test_no_relative_motion_keeps_the_present_range)."""
    k = np.arange(N_CANDIDATES)
    off = np.radians((k % N_OFF) * 5.0 - 90.0)
    sp = speed[pair_ship, None] * np.where(k >= N_OFF, factor[pair_ship, None], 1.0)
    c = base[pair_ship, None] + off
    rvn, rve = ovn[:, None] - sp * np.cos(c), ove[:, None] - sp * np.sin(c)
    closing = pn[:, None] * rvn + pe[:, None] * rve < 0.0
    w = rvn**2 + rve**2
    t = np.clip(-(pn[:, None] * rvn + pe[:, None] * rve) / np.where(w > 0, w, 1.0), 0.0,
                horizon_s)
    rng = np.hypot(pn[:, None] + rvn * t, pe[:, None] + rve * t)
    return np.where(w <= 1e-12, np.nan, np.where(closing, rng - req[:, None], np.inf))


def _alongside(base, speed, factor, pair_ship, pn, pe, ovn, ove, req):
    """``(q, K)`` whether a candidate runs alongside the pair's ship: within 2 x the asked
    distance at less than 1 m/s relative speed."""
    k = np.arange(N_CANDIDATES)
    off = np.radians((k % N_OFF) * 5.0 - 90.0)
    sp = speed[pair_ship, None] * np.where(k >= N_OFF, factor[pair_ship, None], 1.0)
    c = base[pair_ship, None] + off
    rel = np.hypot(ovn[:, None] - sp * np.cos(c), ove[:, None] - sp * np.sin(c))
    near = np.hypot(pn, pe)[:, None] < 2.0 * np.maximum(req, 1.0)[:, None]
    return near & (rel < 1.0) & (req[:, None] > 0.0)


@st.composite
def fleets(draw):
    s = draw(st.integers(1, 5))
    q = draw(st.integers(0, 10))
    f = st.floats
    ships = dict(
        base=np.array(draw(st.lists(f(-math.pi, math.pi), min_size=s, max_size=s))),
        speed=np.array(draw(st.lists(f(0.5, 12.0), min_size=s, max_size=s))),
        factor=np.array(draw(st.lists(f(0.2, 0.9), min_size=s, max_size=s))),
        side=np.array(draw(st.lists(st.sampled_from([STARBOARD, PORT, EITHER]), min_size=s,
                                    max_size=s))),
        least=np.radians(draw(st.lists(st.sampled_from([0.0, 10.0, 30.0, 60.0]), min_size=s,
                                       max_size=s))),
        reduce=np.array(draw(st.lists(st.booleans(), min_size=s, max_size=s))),
        current=np.array(draw(st.lists(st.integers(-1, N_CANDIDATES - 1), min_size=s,
                                       max_size=s)), dtype=np.int64),
    )
    pairs = dict(
        pair_ship=np.array(draw(st.lists(st.integers(0, s - 1), min_size=q, max_size=q)),
                           dtype=np.int64),
        pn=np.array(draw(st.lists(f(-15000.0, 15000.0), min_size=q, max_size=q))),
        pe=np.array(draw(st.lists(f(-15000.0, 15000.0), min_size=q, max_size=q))),
        ovn=np.array(draw(st.lists(f(-10.0, 10.0), min_size=q, max_size=q))),
        ove=np.array(draw(st.lists(f(-10.0, 10.0), min_size=q, max_size=q))),
        req=np.array(draw(st.lists(st.sampled_from([0.0, 500.0, 1852.0, 3704.0]), min_size=q,
                                   max_size=q))),
    )
    return ships, pairs


def _call(sh, pr, horizon_s=H):
    return choose(sh["base"], sh["speed"], sh["factor"], sh["side"], sh["least"],
                  sh["reduce"], sh["current"], pr["pair_ship"], pr["pn"], pr["pe"], pr["ovn"],
                  pr["ove"], pr["req"], horizon_s)


# found by hypothesis: at a range of 5e-324 m the time to the CPA underflowed to 0 in the
# arbitration but not the sign of the closing product in the reference
_TINY_RANGE = ({"base": np.zeros(3), "speed": np.ones(3), "factor": np.full(3, 0.5),
                "side": np.full(3, 30.0), "least": np.zeros(3), "reduce": np.zeros(3, bool),
                "current": np.zeros(3, dtype=np.int64)},
               {"pair_ship": np.array([0, 0]), "pn": np.zeros(2), "pe": np.array([5e-324, 0.0]),
                "ovn": np.zeros(2), "ove": np.array([-1.0, 0.0]), "req": np.array([500.0, 0.0])})


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fleets())
@example(_TINY_RANGE)
def test_vectorised_equals_one_ship_at_a_time(fleet):
    sh, pr = fleet
    chosen, ok = _call(sh, pr)
    s = sh["base"].size
    assert chosen.shape == ok.shape == (s,)
    assert chosen.dtype.kind == "i"
    assert ((chosen >= 0) & (chosen < N_CANDIDATES)).all()
    for i in range(s):
        mine = pr["pair_ship"] == i
        one_sh = {k: v[i:i + 1] for k, v in sh.items()}
        one_pr = {k: v[mine] for k, v in pr.items()}
        one_pr["pair_ship"] = np.zeros(int(mine.sum()), dtype=np.int64)
        c1, ok1 = _call(one_sh, one_pr)
        assert (int(c1[0]), bool(ok1[0])) == (int(chosen[i]), bool(ok[i]))
    # ok agrees with an independent margin computation (to a rounding tolerance); a pair with
    # no relative motion counts as met (hi) or as failed (lo)
    hi = np.full((s, N_CANDIDATES), np.inf)
    lo = np.full((s, N_CANDIDATES), np.inf)
    along = np.zeros((s, N_CANDIDATES), dtype=bool)
    if pr["pn"].size:
        m = _margins(sh["base"], sh["speed"], sh["factor"], pr["pair_ship"], pr["pn"], pr["pe"],
                     pr["ovn"], pr["ove"], pr["req"], H)
        np.minimum.at(hi, pr["pair_ship"], np.nan_to_num(m, nan=np.inf))
        np.minimum.at(lo, pr["pair_ship"], np.nan_to_num(m, nan=-np.inf))
        np.logical_or.at(along, pr["pair_ship"], _alongside(
            sh["base"], sh["speed"], sh["factor"], pr["pair_ship"], pr["pn"], pr["pe"],
            pr["ovn"], pr["ove"], pr["req"]))
    off = (np.arange(N_CANDIDATES) % N_OFF) * 5.0 - 90.0
    for i in range(s):
        # every choice is on the asked side; not ok only where nothing there satisfies all
        side = sh["side"][i]
        allowed = ~(((side == STARBOARD) & (off < 0.0)) | ((side == PORT) & (off > 0.0)))
        assert allowed[chosen[i]]
        if ok[i]:
            assert hi[i, chosen[i]] >= -1e-6
        else:
            assert (lo[i, allowed] < 1e-6).all()
        # a still-valid running manoeuvre on the asked side, not alongside a ship, is kept
        cur = sh["current"][i]
        if cur >= 0 and lo[i, cur] > 1e-6 and not along[i, cur] and allowed[cur]:
            assert chosen[i] == sh["current"][i]


def test_vectorised_hand_cases_at_once():
    """The hand cases above in one call give the answers they give alone."""
    b = math.radians(30.0)
    cases = [
        dict(threats=[(*CROSSING, 3 * NM)], side=STARBOARD, reduce=False, expect=cand(45.0)),
        dict(threats=[(*CROSSING, 3 * NM)], side=PORT, reduce=False, expect=cand(-30.0)),
        dict(threats=[(*CROSSING, 3 * NM)], side=STARBOARD, reduce=True,
             expect=cand(30.0, True)),
        dict(threats=[(*CROSSING, NM), (8000.0 * math.cos(b), 8000.0 * math.sin(b), 0.0, 0.0,
                                        NM)], side=STARBOARD, reduce=False, expect=cand(45.0)),
        dict(threats=[(1000.0, 0.0, -V, 0.0, NM)], side=STARBOARD, reduce=False,
             expect=cand(90.0)),
    ]
    s = len(cases)
    rows = [(i, t) for i, c in enumerate(cases) for t in c["threats"]]
    t = np.array([r[1] for r in rows])
    chosen, ok = choose(
        np.zeros(s), np.full(s, V), np.full(s, 0.5), np.array([c["side"] for c in cases]),
        np.full(s, math.radians(30.0)), np.array([c["reduce"] for c in cases]),
        np.full(s, -1), np.array([r[0] for r in rows]), t[:, 0], t[:, 1], t[:, 2], t[:, 3],
        t[:, 4], H)
    assert chosen.tolist() == [c["expect"] for c in cases]
    assert ok.tolist() == [True, True, True, True, False]



# --------------------------------------------------------------------------------------------
# Against a brute-force search written from the module docstring
# --------------------------------------------------------------------------------------------

def _brute(base_deg, speed, factor, threats, horizon_s):
    """Per candidate: (offset deg, reduced, worst margin m, safe, alongside), from the closed
    form of straight tracks: the range at the CPA when it lies within the look-ahead, at the
    look-ahead's end when later; a pair whose range opens constrains nothing."""
    out = []
    for k in range(N_CANDIDATES):
        off = (k % N_OFF) * 5.0 - 90.0
        reduced = k >= N_OFF
        c = math.radians(base_deg + off)
        sp = speed * (factor if reduced else 1.0)
        vn, ve = sp * math.cos(c), sp * math.sin(c)
        worst, beside = math.inf, False
        for pn, pe, ovn, ove, req in threats:
            dvn, dve = ovn - vn, ove - ve
            w2 = dvn * dvn + dve * dve
            dot = pn * dvn + pe * dve
            if w2 <= 1e-12:
                closest = math.hypot(pn, pe)
            elif dot >= 0.0:
                closest = math.inf
            else:
                t = min(-dot / w2, horizon_s)
                closest = math.hypot(pn + dvn * t, pe + dve * t)
            worst = min(worst, closest - req)
            beside |= req > 0 and w2 < 1.0 and math.hypot(pn, pe) < 2.0 * max(req, 1.0)
        out.append((off, reduced, worst, worst >= 0.0, beside))
    return out


@st.composite
def pictures(draw):
    """One ship and up to four others, most of them on a collision course or near it (aimed at
    a point near where the own ship will be after 5 to 25 min on her base course), each
    starting outside the distance it must be kept at (inside it no candidate keeps it, and
    which is least bad is a separate preference)."""
    f = st.floats
    base_deg, speed = draw(f(0.0, 360.0)), draw(f(3.0, 10.0))
    c = math.radians(base_deg)
    threats = []
    for _ in range(draw(st.integers(1, 4))):
        limit = draw(st.sampled_from([0.0, 500.0, 1000.0, 1852.0]))
        b, r = math.radians(draw(f(0.0, 360.0))), draw(f(max(1500.0, limit + 200.0), 12000.0))
        pn, pe = r * math.cos(b), r * math.sin(b)
        if draw(st.booleans()) or draw(st.booleans()):
            t = draw(f(300.0, 1500.0))
            an = speed * t * math.cos(c) + draw(f(-1500.0, 1500.0))
            ae = speed * t * math.sin(c) + draw(f(-1500.0, 1500.0))
            ovn, ove = (an - pn) / t, (ae - pe) / t
        else:
            ovn, ove = draw(f(-8.0, 8.0)), draw(f(-8.0, 8.0))
        threats.append((pn, pe, ovn, ove, limit))
    return threats, base_deg, speed


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.filter_too_much])
@given(picture=pictures(), factor=st.floats(0.3, 0.8),
       side=st.sampled_from([STARBOARD, PORT, EITHER]),
       least_deg=st.sampled_from([0.0, 10.0, 30.0]), reduce=st.booleans(),
       current=st.one_of(st.just(-1), st.just(-1), st.integers(0, N_CANDIDATES - 1)))
def test_choice_agrees_with_brute_force_search(picture, factor, side, least_deg, reduce,
                                               current):
    """Every candidate judged by the closed form; then, from the docstring's preference order:
    a running manoeuvre on the asked side that still keeps every distance (and runs alongside
    nobody) is kept; else, on the asked side, among the safe candidates those with at least
    the asked alteration and, replacing a running manoeuvre, a course at least
    APPARENT_CHANGE_DEG from its own, the largest offset or the same course, none nearer the
    base course: full speed first unless a reduction is asked, then the smallest alteration,
    starboard first among equals (and a reduced speed first among equals when it is asked);
    with no safe candidate on the asked side, the largest worst-case margin there."""
    threats, base_deg, speed = picture
    table = _brute(base_deg, speed, factor, threats, H)
    # skip pictures where rounding decides (a margin within a millimetre of zero) and where
    # running alongside would rank candidates (a separate preference, tested above)
    assume(all(abs(m) > 1e-3 for _, _, m, _, _ in table if math.isfinite(m)))
    assume(not any(b for *_, b in table))
    chosen, ok = choose_one(threats, base_deg=base_deg, speed=speed, factor=factor, side=side,
                            least_deg=least_deg, reduce=reduce, current=current)
    off, _, worst, safe, _ = table[chosen]
    assert ok == safe

    def right_side(o):
        return not ((side == STARBOARD and o < 0.0) or (side == PORT and o > 0.0))

    assert right_side(off)
    if current >= 0 and table[current][3] and right_side(table[current][0]):
        assert chosen == current
        return
    pool = [k for k, row in enumerate(table) if row[3] and right_side(row[0])]

    def apparent(o):
        if current < 0:
            return True
        run, step = table[current][0], abs(o - table[current][0])
        return (step == 0.0 or step >= APPARENT_CHANGE_DEG or abs(o) == 90.0) and \
            abs(o) >= abs(run)

    adequate = [k for k in pool if (least_deg == 0.0 or abs(table[k][0]) >= least_deg)
                and apparent(table[k][0])]
    if adequate:
        def key(k):
            o, red = table[k][0], table[k][1]
            return (abs(o), o < 0.0, not red) if reduce else (red, abs(o), o < 0.0)
        assert chosen == min(adequate, key=key)
    elif pool:
        assert ok
    else:
        assert not ok
        best = max(row[2] for row in table if right_side(row[0]))
        assert worst >= best - 1e-6
