import math
from collections import Counter

import numpy as np
import pytest

from trafficsim.campaign.generator import _weighted, classify, draw
from trafficsim.campaign.spec import load_spec
from trafficsim.geometry import cpa
from trafficsim.units import NM


@pytest.mark.parametrize("n_names", [1, 2, 6, 9, 17])
def test_weighted_draw_is_numpys_choice(n_names):
    """The same draw as ``Generator.choice`` with probabilities, number for number (numpy sums
    eight or more weights pairwise)."""
    names = tuple(f"t{k}" for k in range(n_names))
    for trial in range(50):
        w = np.random.default_rng(trial).uniform(0.0, 3.0, n_names)
        w[trial % n_names] += 0.1
        weights = dict(zip(names, w.tolist(), strict=True))
        mine, theirs = np.random.default_rng(trial), np.random.default_rng(trial)
        for _ in range(20):
            assert _weighted(weights, names, mine) == names[theirs.choice(n_names, p=w / w.sum())]


def _velocity(setup):
    return setup.speed_mps * math.cos(setup.heading_rad), setup.speed_mps * math.sin(
        setup.heading_rad)


def test_an_encounter_depends_only_on_seed_and_index(write_spec):
    spec = load_spec(write_spec())
    a, b = draw(spec, 4), draw(spec, 4)
    draw(spec, 3)
    c = draw(spec, 4)
    for x in (b, c):
        assert x.kind == a.kind and x.pair_kinds == a.pair_kinds
        for s, t in zip(a.ships, x.ships, strict=True):
            assert (s.north_m, s.east_m, s.heading_rad, s.speed_mps, s.behaviour) == (
                t.north_m, t.east_m, t.heading_rad, t.speed_mps, t.behaviour)
    assert draw(spec, 5).ships[1].north_m != a.ships[1].north_m


def test_start_geometry_has_the_drawn_dcpa_tcpa_and_type(write_spec):
    spec = load_spec(write_spec(extra="dcpa_nm: [0.2, 0.8]\ntcpa_min: [12, 25]"))
    kinds = Counter()
    for index in range(300):
        enc = draw(spec, index)
        own = enc.ships[0]
        assert own.behaviour == "colregs" and (own.north_m, own.east_m) == (0.0, 0.0)
        on, oe = _velocity(own)
        for k, other in enumerate(enc.ships[1:]):
            vn, ve = _velocity(other)
            dcpa, tcpa = cpa(np.array(other.north_m), np.array(other.east_m),
                             np.array(vn - on), np.array(ve - oe))
            assert float(dcpa) == pytest.approx(enc.dcpa_m[k], abs=1e-6)
            assert float(tcpa) == pytest.approx(enc.tcpa_s[k], rel=1e-9)
            assert 0.2 * NM <= enc.dcpa_m[k] <= 0.8 * NM and 720 <= enc.tcpa_s[k] <= 1500
            kind = enc.pair_kinds[k]
            assert classify(own.heading_rad, other.heading_rad, other.north_m,
                            other.east_m) == kind
            kinds[kind] += 1
        if enc.kind == "multi":
            assert 3 <= len(enc.ships) <= 5
        else:
            assert len(enc.ships) == 2 and enc.pair_kinds == [enc.kind]
    # equal weights: every pair type is common (5 types + multi-ship mixtures)
    assert len(kinds) == 5 and min(kinds.values()) > 0.12 * sum(kinds.values())


def test_classify_by_the_rule_sectors():
    north = 0.0
    # ahead, reciprocal: head-on; ahead on the starboard bow crossing: give way
    assert classify(north, math.pi, 5000.0, 100.0) == "head_on"
    assert classify(north, math.radians(260), 4000.0, 4000.0) == "crossing_give_way"
    assert classify(north, math.radians(100), 4000.0, -4000.0) == "crossing_stand_on"
    # a slower ship ahead on the same course: we overtake; a ship astern: we are overtaken
    assert classify(north, 0.0, 3000.0, 0.0) == "overtaking"
    assert classify(north, 0.0, -3000.0, 0.0) == "overtaken"


def test_ship_types_rogues_and_policy(write_spec):
    spec = load_spec(write_spec(rogue=0.5))
    ships = [s for i in range(200) for s in draw(spec, i).ships[1:]]
    rogue = np.mean([s.behaviour in ("turn_port", "late_action") for s in ships])
    assert 0.4 < rogue < 0.6
    types = Counter(s.spec["name"] for s in ships)
    assert set(types) == {"cargo", "container", "fishing"}
    assert types["cargo"] > types["fishing"]  # weights 2 : 1
    baseline = load_spec(write_spec(extra="policy: no_avoidance", name="b.yaml", rogue=0.5))
    assert {s.behaviour for i in range(50) for s in draw(baseline, i).ships} == {"keep_course"}
