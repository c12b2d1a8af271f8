import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from trafficsim.campaign.generator import _weighted, classify, draw
from trafficsim.campaign.spec import load_spec
from trafficsim.errors import InputError
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
                            other.east_m, own.speed_mps, other.speed_mps) == kind
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
    assert classify(north, math.pi, 5000.0, 100.0, 6.0, 6.0) == "head_on"
    assert classify(north, math.radians(260), 4000.0, 4000.0, 6.0, 6.0) == "crossing_give_way"
    assert classify(north, math.radians(100), 4000.0, -4000.0, 6.0, 6.0) == "crossing_stand_on"
    # a slower ship ahead on the same course: we overtake; a faster one astern overtakes us
    assert classify(north, 0.0, 3000.0, 0.0, 8.0, 5.0) == "overtaking"
    assert classify(north, 0.0, -3000.0, 0.0, 5.0, 8.0) == "overtaken"
    # coming up from abaft her beam but slower, a ship overtakes no one (rules/colregs.yaml's
    # speed_ratio tests): the sectors of a crossing decide
    assert classify(north, 0.0, 3000.0, 0.0, 5.0, 8.0) != "overtaking"
    assert classify(north, 0.0, -3000.0, 0.0, 8.0, 5.0) != "overtaken"


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


# --------------------------------------------------------------------------------------------
# start geometry, worked out independently of trafficsim.geometry
# --------------------------------------------------------------------------------------------

SPEC = """schema_version: 1
name: gen
n_encounters: {n}
seed: {seed}
duration_s: 2400
chunk_encounters: {chunk}
ship_types: {{cargo: 1, container: 1, fishing: 1}}
{extra}
"""


def _spec(tmp_path, extra="", n=50, seed=7, chunk=10, name="g.yaml"):
    path = tmp_path / name
    path.write_text(SPEC.format(extra=extra, n=n, seed=seed, chunk=chunk))
    return load_spec(path)


def _deg(angle):
    return math.degrees(angle) % 360.0


def _relative(own, other):
    """Bearing of ``other`` from the own bow, of the own ship from the other's bow, and the
    other's course minus the own course, all in degrees [0, 360)."""
    bearing = _deg(math.atan2(other.east_m - own.east_m, other.north_m - own.north_m)
                   - own.heading_rad)
    aspect = _deg(math.atan2(own.east_m - other.east_m, own.north_m - other.north_m)
                  - other.heading_rad)
    return bearing, aspect, _deg(other.heading_rad - own.heading_rad)


def _dcpa_tcpa(own, other):
    """Closed form: t = -(p . w) / |w|^2 and d = |p x w| / |w| (colregs.md section 4)."""
    pn, pe = other.north_m - own.north_m, other.east_m - own.east_m
    wn = other.speed_mps * math.cos(other.heading_rad) - own.speed_mps * math.cos(
        own.heading_rad)
    we = other.speed_mps * math.sin(other.heading_rad) - own.speed_mps * math.sin(
        own.heading_rad)
    w2 = wn * wn + we * we
    return abs(pn * we - pe * wn) / math.sqrt(w2), -(pn * wn + pe * we) / w2, (pn, pe, wn, we)


@pytest.mark.parametrize("dcpa, tcpa", [((0.0, 0.0), (15.0, 15.0)), ((0.5, 2.0), (5.0, 8.0)),
                                        ((3.0, 3.0), (20.0, 40.0))])
def test_start_dcpa_tcpa_fall_in_the_spec_ranges(tmp_path, dcpa, tcpa):
    """DCPA and TCPA computed from the drawn positions and velocities by the closed form lie in
    the spec's ranges and equal the recorded ones; a single-valued range gives that value
    exactly (DCPA 0: a collision course)."""
    spec = _spec(tmp_path, extra=f"dcpa_nm: [{dcpa[0]}, {dcpa[1]}]\n"
                                 f"tcpa_min: [{tcpa[0]}, {tcpa[1]}]")
    for index in range(60):
        enc = draw(spec, index)
        own = enc.ships[0]
        for k, other in enumerate(enc.ships[1:]):
            d, t, _ = _dcpa_tcpa(own, other)
            assert dcpa[0] * NM - 1e-6 <= d <= dcpa[1] * NM + 1e-6
            assert tcpa[0] * 60 * (1 - 1e-12) <= t <= tcpa[1] * 60 * (1 + 1e-12)
            assert d == pytest.approx(enc.dcpa_m[k], abs=1e-6)
            assert t == pytest.approx(enc.tcpa_s[k], rel=1e-12)
            if dcpa[0] == dcpa[1]:
                assert d == pytest.approx(dcpa[0] * NM, abs=1e-6)


def test_the_dcpa_side_is_drawn_on_both_sides(tmp_path):
    """``n`` is a unit vector across ``w`` "either side": the sign of p x w (which side of the
    relative track the own ship passes) takes both values about equally."""
    spec = _spec(tmp_path, extra="dcpa_nm: [0.5, 0.5]")
    signs = []
    for index in range(200):
        enc = draw(spec, index)
        for other in enc.ships[1:]:
            _, _, (pn, pe, wn, we) = _dcpa_tcpa(enc.ships[0], other)
            signs.append(np.sign(pn * we - pe * wn))
    share = np.mean(np.array(signs) > 0)
    assert 0.35 < share < 0.65


SECTORS = {
    # bearing of the other ship from the own bow, aspect (own ship from the other's bow) and
    # the other's course relative to the own, by the generator's sectors (Rules 13-15)
    "head_on": lambda b, a, c: 174.0 <= c <= 186.0 and min(b, 360.0 - b) <= 10.0
    and min(a, 360.0 - a) <= 10.0,
    "crossing_give_way": lambda b, a, c: 0.0 <= b <= 112.5 and not 112.5 < a < 247.5
    and 190.0 <= c <= 345.0,
    "crossing_stand_on": lambda b, a, c: 247.5 <= b < 360.0 and not 112.5 < a < 247.5
    and 15.0 <= c <= 170.0,
    "overtaking": lambda b, a, c: 112.5 < a < 247.5 and (c <= 30.0 or c >= 330.0),
    "overtaken": lambda b, a, c: 112.5 < b < 247.5 and not 112.5 < a < 247.5
    and (c <= 30.0 or c >= 330.0),
}


@pytest.mark.parametrize("kind", list(SECTORS))
def test_each_type_has_its_rule_sectors_and_relative_course(tmp_path, kind):
    """A spec with one encounter type draws only that type, and every drawn pair has the
    relative bearing, aspect and course of the type, computed from the positions directly:
    give-way has the other on the own starboard side (bearing 0-112.5 deg) heading across to
    port, stand-on the mirror image, overtaking the own ship more than 22.5 deg abaft the
    other's beam, overtaken the other ship abaft the own beam, head-on nearly reciprocal."""
    spec = _spec(tmp_path, extra=f"encounter_types: {{{kind}: 1}}")
    for index in range(40):
        enc = draw(spec, index)
        assert enc.kind == kind and enc.pair_kinds == [kind] and len(enc.ships) == 2
        b, a, c = _relative(enc.ships[0], enc.ships[1])
        assert SECTORS[kind](b, a, c), (index, b, a, c)


def test_overtaking_means_coming_up_from_astern(tmp_path):
    """Overtaking: the other ship is ahead of the own ship (bearing within 90 deg of the bow),
    the own ship sails towards her (v_own . p > 0) and the range closes (TCPA > 0)."""
    spec = _spec(tmp_path, extra="encounter_types: {overtaking: 1}")
    for index in range(40):
        own, other = draw(spec, index).ships
        b, _, _ = _relative(own, other)
        assert b < 90.0 or b > 270.0
        _, tcpa, (pn, pe, _, _) = _dcpa_tcpa(own, other)
        assert pn * math.cos(own.heading_rad) + pe * math.sin(own.heading_rad) > 0.0
        assert tcpa > 0.0


def test_head_on_needs_the_other_ship_ahead(tmp_path):
    """Rule 14(b): head-on when nearly reciprocal and each ship sees the other ahead or nearly
    ahead (within 10 deg). On reciprocal courses 10 km apart, 1 km to the side is 5.7 deg off
    the bow (head-on), 2 km is 11.3 deg (a crossing, the other on the own starboard bow), and a
    ship on the beam is no head-on situation. With DCPA 3 NM and TCPA 1 min the other ship
    would start nearly abeam (atan(3 NM / (closing speed x 1 min)) ~ 80 deg): no head-on
    geometry exists, and the draw says so."""
    assert classify(0.0, math.pi, 10000.0, 1000.0, 6.0, 6.0) == "head_on"
    assert classify(0.0, math.pi, 10000.0, 2000.0, 6.0, 6.0) == "crossing_give_way"
    assert classify(0.0, math.pi, 10000.0, -2000.0, 6.0, 6.0) == "crossing_stand_on"
    assert classify(0.0, math.pi, 500.0, 2836.0, 6.0, 6.0) != "head_on"  # bearing 80 deg
    spec = _spec(tmp_path, extra="encounter_types: {head_on: 1}\ndcpa_nm: [3, 3]\n"
                                 "tcpa_min: [1, 1]")
    with pytest.raises(InputError, match="no geometry for head_on"):
        draw(spec, 0)


@pytest.mark.parametrize("own_psi", [0.0, 1.0, math.pi, 5.5, 2 * math.pi - 1e-9])
def test_classify_is_invariant_under_rotating_the_whole_picture(own_psi):
    """Rotating both headings and the relative position by the same angle changes no type
    (the sectors are relative bearings; no wrap problem at 0 / 2 pi)."""
    cases = [(math.pi, 5000.0, 100.0, 6.0, 6.0), (math.radians(260), 4000.0, 4000.0, 6.0, 6.0),
             (math.radians(100), 4000.0, -4000.0, 6.0, 6.0), (0.0, 3000.0, 0.0, 8.0, 5.0),
             (0.0, -3000.0, 0.0, 5.0, 8.0)]
    for other_rel, n, e, *speeds in cases:
        ref = classify(0.0, other_rel, n, e, *speeds)
        c, s = math.cos(own_psi), math.sin(own_psi)
        rot = classify(own_psi, own_psi + other_rel, n * c - e * s, n * s + e * c, *speeds)
        assert rot == ref
        assert classify(own_psi - 2 * math.pi, own_psi + other_rel + 4 * math.pi,
                        n * c - e * s, n * s + e * c, *speeds) == ref


def test_classify_mirrors_between_two_closing_ships():
    """Seen from the other ship of a closing pair, overtaking and overtaken swap (two closing
    ships can never both be abaft each other's beam, nor neither when one is), and a meeting
    (head-on or crossing) stays a meeting."""
    mirror = {"overtaking": "overtaken", "overtaken": "overtaking"}
    meeting = {"head_on", "crossing_give_way", "crossing_stand_on"}
    rng = np.random.default_rng(1)
    seen = set()
    for _ in range(4000):
        psi_a, psi_b = rng.uniform(0, 2 * math.pi, 2)
        n, e = rng.uniform(-5000, 5000, 2)
        ua, ub = rng.uniform(2, 10, 2)
        wn = ub * math.cos(psi_b) - ua * math.cos(psi_a)
        we = ub * math.sin(psi_b) - ua * math.sin(psi_a)
        if n * wn + e * we >= 0.0:  # opening: no encounter
            continue
        ab = classify(psi_a, psi_b, n, e, ua, ub)
        ba = classify(psi_b, psi_a, -n, -e, ub, ua)
        if ab in mirror:
            assert ba == mirror[ab], (psi_a, psi_b, n, e)
        else:
            assert ab in meeting and ba in meeting, (psi_a, psi_b, n, e)
        seen.add(ab)
    assert seen == meeting | set(mirror)


def test_classify_sector_boundaries():
    """Own ship north-bound. 112.5 deg is the limit of the overtaking sector (Rule 13: *more*
    than 22.5 deg abaft the beam): just inside it is overtaken, just outside crossing."""
    r = 3000.0

    def at(bearing_deg, other_deg):  # (the other ship faster: she may overtake)
        b = math.radians(bearing_deg)
        return classify(0.0, math.radians(other_deg), r * math.cos(b), r * math.sin(b), 5.0,
                        8.0)

    assert at(112.6, 300.0) == "overtaken" and at(247.4, 60.0) == "overtaken"
    assert at(112.4, 300.0) == "crossing_give_way"
    assert at(247.6, 60.0) == "crossing_stand_on"
    # courses reciprocal within 15 deg (rules/colregs.yaml's reciprocal_deg 165) with each
    # ship within 10 deg of the other's bow: head-on; 16 deg off reciprocal: crossing. Bearing
    # 8 deg and the other 14 deg past reciprocal put the own ship 8 - 14 = -6 deg off her bow
    assert at(2.0, 185.9) == "head_on" and at(2.0, 174.1) == "head_on"
    assert at(8.0, 194.0) == "head_on" and at(-8.0, 166.0) == "head_on"
    assert at(8.0, 196.0) == "crossing_give_way" and at(-8.0, 164.0) == "crossing_stand_on"


# --------------------------------------------------------------------------------------------
# reproducibility, weights, rogues, environment
# --------------------------------------------------------------------------------------------

def _same(a, b):
    assert (a.index, a.kind, a.pair_kinds, a.dcpa_m, a.tcpa_s, a.env) == (
        b.index, b.kind, b.pair_kinds, b.dcpa_m, b.tcpa_s, b.env)
    for s, t in zip(a.ships, b.ships, strict=True):
        assert (s.name, s.spec["name"], s.north_m, s.east_m, s.heading_rad, s.speed_mps,
                s.behaviour, s.ship_in_encounter, s.filter) == (
            t.name, t.spec["name"], t.north_m, t.east_m, t.heading_rad, t.speed_mps,
            t.behaviour, t.ship_in_encounter, t.filter)
        np.testing.assert_array_equal(s.route_m, t.route_m)
        assert dict(s.sensors) == dict(t.sensors)


def test_an_encounter_is_fixed_by_seed_and_index_only(tmp_path):
    """Campaign size, chunking, the order of drawing and a shared ship cache change nothing;
    another seed changes the encounter."""
    sensors = "sensors: {gnss_sigma_m: [1, 5]}\nrogue_fraction: 0.3\ncurrent_kn: [0, 2]"
    a = _spec(tmp_path, extra=sensors, n=50, chunk=10, name="a.yaml")
    b = _spec(tmp_path, extra=sensors, n=5000, chunk=999, name="b.yaml")
    cache: dict = {}
    forward = [draw(a, i) for i in range(12)]
    backward = [draw(b, i, cache) for i in reversed(range(12))][::-1]
    for x, y in zip(forward, backward, strict=True):
        _same(x, y)
    other_seed = _spec(tmp_path, extra=sensors, seed=8, name="c.yaml")
    assert [draw(other_seed, i).ships[0].heading_rad for i in range(12)] != [
        e.ships[0].heading_rad for e in forward]


def test_the_own_ship_is_never_a_rogue(tmp_path):
    """rogue_fraction 1: every other ship breaks the rules (turn_port or late_action, both
    used), the own ship always runs the policy."""
    spec = _spec(tmp_path, extra="rogue_fraction: 1.0")
    behaviours = set()
    for index in range(60):
        enc = draw(spec, index)
        assert enc.ships[0].behaviour == "colregs" and enc.ships[0].name == "own"
        behaviours |= {s.behaviour for s in enc.ships[1:]}
    assert behaviours == {"turn_port", "late_action"}


def test_multi_ship_counts_and_fallback_pair_types(tmp_path):
    """multi_ships [4, 4]: always 4 ships. With multi the only type, the other ships take
    every pair type (equal weights); with multi and head-on only, every pair is head-on."""
    spec = _spec(tmp_path, extra="encounter_types: {multi: 1}\nmulti_ships: [4, 4]")
    kinds = Counter()
    for index in range(40):
        enc = draw(spec, index)
        assert enc.kind == "multi" and len(enc.ships) == 4 and len(enc.pair_kinds) == 3
        assert [s.ship_in_encounter for s in enc.ships] == [0, 1, 2, 3]
        kinds.update(enc.pair_kinds)
    assert set(kinds) == set(SECTORS)
    only = _spec(tmp_path, extra="encounter_types: {multi: 1, head_on: 1}\n"
                                 "multi_ships: [3, 5]", name="o.yaml")
    sizes = set()
    for index in range(60):
        enc = draw(only, index)
        assert set(enc.pair_kinds) == {"head_on"}
        sizes.add(len(enc.ships))
    assert sizes == {2, 3, 4, 5}


def test_encounter_type_weights_set_the_frequencies(tmp_path):
    """Weights 3 : 1 : 0 give about 75 % / 25 % / none over 400 encounters."""
    spec = _spec(tmp_path, extra="encounter_types: {head_on: 3, overtaken: 1, multi: 0}",
                 n=400)
    kinds = Counter(draw(spec, i).kind for i in range(400))
    assert set(kinds) == {"head_on", "overtaken"}
    assert 0.68 < kinds["head_on"] / 400 < 0.82


def test_speeds_routes_environment_and_sensors_within_the_spec(tmp_path):
    """Speed = service speed x a fraction in speed_fraction; a straight route along the
    initial course, longer than the run; current and wind speeds in their ranges; sensor
    sigmas in their ranges and the filter of the spec."""
    from trafficsim.units import from_kn

    spec = _spec(tmp_path, extra="speed_fraction: [0.5, 0.7]\ncurrent_kn: [1, 2]\n"
                                 "wind_mps: [5, 6]\nsensors: {gnss_sigma_m: [2, 3], "
                                 "compass_sigma_deg: [0.2, 0.3], filter: ekf}")
    for index in range(40):
        enc = draw(spec, index)
        assert from_kn(1.0) - 1e-12 <= enc.env.current_speed_mps <= from_kn(2.0) + 1e-12
        assert 5.0 <= enc.env.wind_speed_mps <= 6.0
        assert 0.0 <= enc.env.current_towards_rad < 2 * math.pi
        for s in enc.ships:
            frac = s.speed_mps / from_kn(s.spec["service_speed_kn"])
            assert 0.5 - 1e-12 <= frac <= 0.7 + 1e-12
            assert s.route_m.shape == (1, 2)
            dn, de = s.route_m[0, 0] - s.north_m, s.route_m[0, 1] - s.east_m
            assert math.atan2(de, dn) == pytest.approx(
                math.remainder(s.heading_rad, 2 * math.pi), abs=1e-9)
            assert math.hypot(dn, de) > s.speed_mps * spec.duration_s
            assert 2.0 <= s.sensors["gnss"]["sigma_m"] <= 3.0
            assert 0.2 <= s.sensors["compass"]["sigma_deg"] <= 0.3
            assert "radar" in s.sensors and "ais" in s.sensors and s.filter == "ekf"


def test_radars_and_transponders_start_unsynchronised(tmp_path, monkeypatch):
    """Each ship's first radar scan falls within one scan period and its first AIS report
    within one reporting interval at its start speed, drawn from a stream of their own: the
    times differ from ship to ship and spread over the whole period, they are the same at
    every draw of the encounter, and the encounter's geometry is the one drawn without them."""
    from trafficsim.campaign import generator
    from trafficsim.sensors import ais

    spec = _spec(tmp_path, extra="sensors: {gnss_sigma_m: [2, 3]}")
    timed = [draw(spec, index) for index in range(60)]
    scans, reports = [], []
    for index, enc in enumerate(timed):
        for s, t in zip(enc.ships, draw(spec, index).ships, strict=True):
            interval = float(ais.reporting_interval_s(np.array([s.speed_mps]),
                                                      np.array([False]))[0])
            scan, report = s.sensors["radar"]["scan_phase_s"], s.sensors["ais"]["first_report_s"]
            assert 0.0 <= scan < 2.5 and 0.0 <= report < interval
            assert (scan, report) == (t.sensors["radar"]["scan_phase_s"],
                                      t.sensors["ais"]["first_report_s"])
            scans.append(scan / 2.5)
            reports.append(report / interval)
    for u in (scans, reports):
        assert len(set(u)) == len(u)
        assert np.histogram(u, bins=5, range=(0.0, 1.0))[0].min() > len(u) / 10
    monkeypatch.setattr(generator, "_phase", lambda setups, rng: None)
    for index, enc in enumerate(timed):
        plain = draw(spec, index)
        assert plain.env == enc.env
        for a, b in zip(plain.ships, enc.ships, strict=True):
            assert (a.north_m, a.east_m, a.heading_rad, a.speed_mps, a.behaviour) == (
                b.north_m, b.east_m, b.heading_rad, b.speed_mps, b.behaviour)
            assert a.sensors["gnss"] == b.sensors["gnss"]
            assert "scan_phase_s" not in a.sensors["radar"]


def test_a_scan_phase_or_first_report_in_a_ship_file_is_kept(tmp_path, monkeypatch):
    """Times a ship file sets are not replaced by drawn ones."""
    from trafficsim.campaign import generator

    spec = _spec(tmp_path, extra="sensors: {gnss_sigma_m: [2, 3]}")
    enc = draw(spec, 0)
    for s in enc.ships:
        s.sensors["radar"]["scan_phase_s"] = 1.25
        s.sensors["ais"]["first_report_s"] = 7.0
    generator._phase(enc.ships, np.random.default_rng(0))
    for s in enc.ships:
        assert s.sensors["radar"]["scan_phase_s"] == 1.25
        assert s.sensors["ais"]["first_report_s"] == 7.0


def test_without_sensors_ships_have_perfect_knowledge(tmp_path):
    spec = _spec(tmp_path)
    for s in draw(spec, 0).ships:
        assert s.filter == "none"


def _same_speed_overtaking(tmp_path, weights="{overtaking: 1}"):
    path = tmp_path / "x.yaml"
    path.write_text(SPEC.format(n=5, seed=1, chunk=5, extra="").replace(
        "{cargo: 1, container: 1, fishing: 1}", "{cargo: 1}")
        + f"encounter_types: {weights}\nspeed_fraction: [1, 1]\ndcpa_nm: [0, 0]\n")
    line = path.read_text().splitlines().index(f"encounter_types: {weights}") + 1
    return path, line


def test_an_impossible_geometry_is_an_input_error_naming_the_key(tmp_path, monkeypatch):
    """Overtaking between ships of the same speed on a collision course cannot be drawn: with
    equal speeds w is square to the mean course, so each ship sees the other within 15 deg of
    the beam, never abaft it. The draw gives up with an InputError at the spec's line of
    encounter_types.overtaking, located where it is raised (a worker process), and so it
    stays when pickled back to the campaign."""
    import pickle

    from trafficsim.campaign import generator as gen
    from trafficsim.errors import InputError

    monkeypatch.setattr(gen, "MAX_TRIES", 3)
    monkeypatch.setattr(gen, "TRIES_PER_SHIP", 20)
    path, line = _same_speed_overtaking(tmp_path)
    with pytest.raises(InputError) as info:
        gen.draw(load_spec(path), 3)
    back = pickle.loads(pickle.dumps(info.value))
    for err in (info.value, back):
        assert (err.path, err.line, err.key) == (str(path), line, "encounter_types.overtaking")
        assert str(err).startswith(f"{path}:{line}: encounter_types.overtaking: encounter 3: "
                                   "no geometry for overtaking in 3 draws")
    assert "the overtaking ship must be the faster" in str(info.value)


def test_drawing_errors_name_each_type_no_draw_can_place(tmp_path, monkeypatch):
    """One draw of every weighted type: overtaking fails (same speeds), head-on does not; the
    error names the type's key, not an encounter index. A spec whose types all draw has none."""
    from trafficsim.campaign import generator as gen

    monkeypatch.setattr(gen, "MAX_TRIES", 3)
    monkeypatch.setattr(gen, "TRIES_PER_SHIP", 20)
    path, line = _same_speed_overtaking(tmp_path, "{head_on: 1, overtaking: 1, overtaken: 0}")
    errors = gen.drawing_errors(load_spec(path))
    assert [(e.line, e.key) for e in errors] == [(line, "encounter_types.overtaking")]
    assert "encounter 0" not in errors[0].message
    assert gen.drawing_errors(_spec(tmp_path, "encounter_types: {overtaking: 1, multi: 1}")) == []


def test_ship_errors_load_and_build_every_ship_type(tmp_path):
    """A ship file with a misspelt coefficient, or a scenario file named as a ship, is an
    error located in that file, as the campaign meets it when it builds the ships."""
    from trafficsim.campaign.generator import ship_errors
    from trafficsim.ships.library import LIBRARY_DIR

    text = (LIBRARY_DIR / "cargo.yaml").read_text()
    assert "  K_prime:" in text
    (tmp_path / "typo.yaml").write_text(text.replace("  K_prime:", "  K_prim:"))
    (tmp_path / "scenario.yaml").write_text("schema_version: 1\nname: s\nduration_s: 60\n"
                                            "ships: []\n")
    spec = _spec(tmp_path).model_copy(
        update={"ship_types": {"cargo": 1.0, "typo.yaml": 1.0, "scenario.yaml": 1.0}})
    spec._path = tmp_path / "g.yaml"
    errors = ship_errors(spec)
    assert [Path(e.path).name for e in errors] == ["typo.yaml", "scenario.yaml"]
    assert errors[0].key == "coefficients.K_prim" and "did you mean 'K_prime'" in str(errors[0])
    assert "missing required key 'model'" in str(errors[1])
    assert ship_errors(_spec(tmp_path)) == []


# --------------------------------------------------------------------------------------------
# start CPA by brute-force propagation, per encounter type
# --------------------------------------------------------------------------------------------

def _closest_by_search(own, other, t_max):
    """Time and distance of the closest approach of the two straight tracks, found by ternary
    search on the convex range |p0 + w t| over [0, t_max] (no closed form used)."""
    def gap(t):
        on = own.north_m + own.speed_mps * math.cos(own.heading_rad) * t
        oe = own.east_m + own.speed_mps * math.sin(own.heading_rad) * t
        tn = other.north_m + other.speed_mps * math.cos(other.heading_rad) * t
        te = other.east_m + other.speed_mps * math.sin(other.heading_rad) * t
        return math.hypot(tn - on, te - oe)

    lo, hi = 0.0, t_max
    for _ in range(200):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        if gap(a) < gap(b):
            hi = b
        else:
            lo = a
    t = 0.5 * (lo + hi)
    return t, gap(t)


@pytest.mark.parametrize("kind", ["head_on", "crossing_give_way", "crossing_stand_on",
                                  "overtaking", "overtaken", "multi"])
def test_start_cpa_found_by_propagating_the_tracks_is_in_the_spec_ranges(tmp_path, kind):
    """Propagating both ships along their initial courses and searching for the smallest
    range gives a DCPA in dcpa_nm and a TCPA in tcpa_min for every drawn ship, equal to the
    recorded ones (the search runs to three times the largest TCPA, so a CPA outside the range
    would be found, not cut off)."""
    spec = _spec(tmp_path, extra=f"encounter_types: {{{kind}: 1}}\ndcpa_nm: [0.1, 0.9]\n"
                                 "tcpa_min: [8, 20]")
    for index in range(80):
        enc = draw(spec, index)
        own = enc.ships[0]
        assert len(enc.ships) - 1 == len(enc.dcpa_m) == len(enc.tcpa_s)
        for k, other in enumerate(enc.ships[1:]):
            t, d = _closest_by_search(own, other, 3 * 20 * 60)
            assert 0.1 * NM - 1e-3 <= d <= 0.9 * NM + 1e-3, (index, k, d)
            assert 8 * 60 - 1e-3 <= t <= 20 * 60 + 1e-3, (index, k, t)
            assert d == pytest.approx(enc.dcpa_m[k], abs=1e-3)
            assert t == pytest.approx(enc.tcpa_s[k], abs=1e-3)


def test_a_zero_dcpa_means_both_ships_reach_one_point_at_the_tcpa(tmp_path):
    """dcpa_nm [0, 0]: each ship, run along its course for TCPA seconds, ends where the own
    ship ends (a collision course), for every type."""
    spec = _spec(tmp_path, extra="dcpa_nm: [0, 0]")
    for index in range(60):
        enc = draw(spec, index)
        own = enc.ships[0]
        for k, other in enumerate(enc.ships[1:]):
            t = enc.tcpa_s[k]
            own_at = (own.speed_mps * math.cos(own.heading_rad) * t,
                      own.speed_mps * math.sin(own.heading_rad) * t)
            other_at = (other.north_m + other.speed_mps * math.cos(other.heading_rad) * t,
                        other.east_m + other.speed_mps * math.sin(other.heading_rad) * t)
            assert math.dist(own_at, other_at) < 1e-6


# --------------------------------------------------------------------------------------------
# classification at the sector edges
# --------------------------------------------------------------------------------------------

def _at(bearing_deg, other_deg, own_deg=0.0, r=4000.0, own_speed=6.0, other_speed=6.0):
    b = math.radians(own_deg + bearing_deg)
    return classify(math.radians(own_deg), math.radians(other_deg), r * math.cos(b),
                    r * math.sin(b), own_speed, other_speed)


def test_head_on_needs_the_own_ship_nearly_ahead_of_the_other_too():
    """Bearing 8 deg and courses 5.9 deg off reciprocal: the own ship lies at 180 + 8 = 188
    deg from the other, so her aspect is 188 - 174.1 = 13.9 deg with the other on 174.1 deg
    (over 10: a crossing from starboard) but 188 - 185.9 = 2.1 deg with the other on 185.9 deg
    (head-on); mirrored, -8 deg gives -13.9 and -2.1."""
    assert _at(8.0, 174.1) == "crossing_give_way"
    assert _at(8.0, 185.9) == "head_on"
    assert _at(-8.0, 185.9) == "crossing_stand_on"
    assert _at(-8.0, 174.1) == "head_on"


def test_head_on_bearing_limit_is_ten_degrees_inclusive_of_nearly_ahead():
    """Reciprocal courses: bearing 9.9 deg (aspect 9.9) is head-on, 10.1 deg a crossing."""
    assert _at(9.9, 180.0) == "head_on" and _at(-9.9, 180.0) == "head_on"
    assert _at(10.1, 180.0) == "crossing_give_way"
    assert _at(-10.1, 180.0) == "crossing_stand_on"


@pytest.mark.parametrize("own_deg", [0.0, 90.0, 359.9, -720.0])
def test_sides_across_the_bow_and_the_north_wrap(own_deg):
    """A crossing ship 0.5 deg either side of the own bow is on that side, whatever the own
    course (including courses that put the bow line on the 0 / 360 deg wrap)."""
    assert _at(0.5, own_deg + 250.0, own_deg) == "crossing_give_way"
    assert _at(-0.5, own_deg + 110.0, own_deg) == "crossing_stand_on"
    assert _at(359.5, own_deg + 110.0, own_deg) == "crossing_stand_on"


def test_overtaking_sector_edges_seen_from_the_other_ship():
    """The own ship at 180 deg +- 67.4 from the other's bow (inside the stern sector) is
    overtaking; at +- 67.6 (outside) it is not. Other ship north-bound at the origin's north:
    the own ship's bearing from her is 180 + a, so the other's bearing from the own ship is a."""
    for a, inside in ((67.4, True), (-67.4, True), (67.6, False), (-67.6, False)):
        got = _at(a, 0.0, own_speed=8.0, other_speed=5.0)  # own north-bound: aspect 180 + a
        assert (got == "overtaking") is inside, (a, got)


# --------------------------------------------------------------------------------------------
# the reference's overtaking criterion, and what the drawn encounters depend on
# --------------------------------------------------------------------------------------------

def test_the_overtaking_ship_is_the_faster_one(tmp_path):
    """Rule 13 "coming up with" her: every implementation in colregs.md 2.2 (DNV speed ratio,
    commonocean "OS faster", NTNU speed difference) and the project's own rules/colregs.yaml
    (overtaking: aspect > 112.5 and speed_ratio < 1; overtaken: bearing > 112.5 and
    speed_ratio > 1) call a ship overtaking only when she is the faster. A drawn overtaking
    encounter must have the own ship faster, an overtaken one the other ship faster;
    otherwise the rule network run on the very start state calls it a crossing and the grade
    (Rule 13 / 17) judges the ships for roles they do not hold."""
    spec = _spec(tmp_path, extra="encounter_types: {overtaking: 1, overtaken: 1}")
    slower = []
    for index in range(300):
        enc = draw(spec, index)
        own, other = enc.ships
        if (enc.kind == "overtaking") != (own.speed_mps > other.speed_mps):
            slower.append(index)
    assert slower == []


def test_the_policy_does_not_change_the_drawn_encounter(tmp_path):
    """README: "Encounter k depends only on (seed, k)"; the no_avoidance policy is the
    do-nothing baseline, to be run on the same draws (colregs.md section 5). The ships'
    positions, courses, speeds and the current of encounter k must not depend on the policy."""
    extra = "current_kn: [0, 2]\nwind_mps: [0, 10]\nrogue_fraction: 0.0"
    rules = _spec(tmp_path, extra=extra, name="r.yaml")
    baseline = _spec(tmp_path, extra=extra + "\npolicy: no_avoidance", name="n.yaml")
    for index in range(20):
        a, b = draw(rules, index), draw(baseline, index)
        assert a.env == b.env, index
        assert [(s.north_m, s.east_m, s.heading_rad, s.speed_mps) for s in a.ships] == [
            (s.north_m, s.east_m, s.heading_rad, s.speed_mps) for s in b.ships], index


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_huge_weights_are_refused_or_drawn_by_their_share(tmp_path):
    """Two weights of 1e308 (finite, >= 0, so valid by the schema) sum to inf: the spec
    must either be refused with a located error or draw both types half the time each."""
    from trafficsim.errors import ScenarioError

    path = tmp_path / "huge.yaml"
    path.write_text(SPEC.format(n=5, seed=1, chunk=5, extra="encounter_types: "
                                "{head_on: 1.0e+308, overtaken: 1.0e+308}"))
    try:
        spec = load_spec(path)
    except ScenarioError as err:
        assert "encounter_types" in str(err)
        return
    kinds = Counter(draw(spec, i).kind for i in range(40))
    assert set(kinds) == {"head_on", "overtaken"}


# --------------------------------------------------------------------------------------------
# ship types, speeds and rogues against their stated distributions
# --------------------------------------------------------------------------------------------

def _within(count, n, p, sigmas=4.5):
    """Binomial count within ``sigmas`` standard deviations of n p."""
    return abs(count - n * p) <= sigmas * math.sqrt(n * p * (1 - p))


def test_ship_types_follow_their_weights(tmp_path):
    """ship_types {cargo: 3, container: 1, fishing: 0}: over 1,200 crossing encounters the own
    ship is cargo with share 3/4 (binomial, 4.5 sigma), never fishing."""
    path = tmp_path / "t.yaml"
    path.write_text(SPEC.format(n=5, seed=2, chunk=5, extra="encounter_types: "
                                "{crossing_give_way: 1, crossing_stand_on: 1}").replace(
        "{cargo: 1, container: 1, fishing: 1}", "{cargo: 3, container: 1, fishing: 0}"))
    spec = load_spec(path)
    own = Counter(draw(spec, i).ships[0].spec["name"] for i in range(1200))
    assert set(own) == {"cargo", "container"}
    assert _within(own["cargo"], 1200, 0.75)


def test_speed_fractions_are_uniform_in_the_range(tmp_path):
    """Own speed / service speed over 800 encounters: a Kolmogorov-Smirnov test against the
    uniform law on speed_fraction [0.5, 0.9] does not reject it (the own ship is drawn
    before any geometry is tried)."""
    from scipy import stats

    from trafficsim.units import from_kn

    spec = _spec(tmp_path, extra="speed_fraction: [0.5, 0.9]\n"
                                 "encounter_types: {head_on: 1, crossing_give_way: 1}")
    frac = [s.speed_mps / from_kn(s.spec["service_speed_kn"])
            for s in (draw(spec, i).ships[0] for i in range(800))]
    assert min(frac) >= 0.5 - 1e-12 and max(frac) <= 0.9 + 1e-12
    assert stats.kstest(frac, stats.uniform(0.5, 0.4).cdf).pvalue > 1e-3


@pytest.mark.parametrize("fraction", [0.0, 0.2])
def test_rogue_share_of_the_other_ships(tmp_path, fraction):
    """rogue_fraction f: each other ship is a rogue with probability f (binomial, 4.5 sigma
    over all other ships of 400 encounters), the two rogue behaviours about equally often."""
    spec = _spec(tmp_path, extra=f"rogue_fraction: {fraction}")
    others = [s.behaviour for i in range(400) for s in draw(spec, i).ships[1:]]
    rogues = [b for b in others if b != "colregs"]
    assert set(rogues) <= {"turn_port", "late_action"}
    if fraction == 0.0:
        assert rogues == []
    else:
        assert _within(len(rogues), len(others), fraction)
        assert _within(rogues.count("turn_port"), len(rogues), 0.5)


def test_encounters_do_not_depend_on_the_spec_keys_that_are_not_draws(tmp_path):
    """Name, campaign size, chunking and decision period are not draws: changing them leaves
    every ship of the first encounters where it was; the duration only lengthens the route."""
    a = _spec(tmp_path, n=20, chunk=3, name="a.yaml")
    b_path = tmp_path / "b.yaml"
    b_path.write_text(SPEC.format(n=7000, seed=7, chunk=1000, extra="decision_period_s: 30")
                      .replace("name: gen", "name: other").replace("duration_s: 2400",
                                                                   "duration_s: 7200"))
    b = load_spec(b_path)
    for index in (0, 5, 19):
        x, y = draw(a, index), draw(b, index)
        assert (x.kind, x.pair_kinds, x.dcpa_m, x.tcpa_s, x.env) == (
            y.kind, y.pair_kinds, y.dcpa_m, y.tcpa_s, y.env)
        for s, t in zip(x.ships, y.ships, strict=True):
            assert (s.north_m, s.east_m, s.heading_rad, s.speed_mps, s.behaviour) == (
                t.north_m, t.east_m, t.heading_rad, t.speed_mps, t.behaviour)
            # same direction, a route three times as long (1.5 x duration x speed + 1 NM)
            for u in (s, t):
                leg = math.hypot(u.route_m[0, 0] - u.north_m, u.route_m[0, 1] - u.east_m)
                duration = 2400.0 if u is s else 7200.0
                assert leg == pytest.approx(1.5 * duration * u.speed_mps + NM)


def test_no_two_ships_of_a_multi_ship_encounter_start_in_an_unavoidable_collision(tmp_path):
    """Every pair of other ships starts at least the spec's largest DCPA (1 NM) apart, and a
    pair closing to less than that does so no sooner than the spec's least TCPA (10 min):
    checked by stepping the straight tracks (0.5 s) over the first 10 min, not by the closed
    form the generator uses."""
    spec = _spec(tmp_path, extra="encounter_types: {multi: 1}\nmulti_ships: [5, 5]\n"
                                 "dcpa_nm: [0, 1]\ntcpa_min: [10, 30]", n=60)
    t = np.arange(0.0, 600.0, 0.5)
    for index in range(60):
        others = draw(spec, index).ships[1:]
        for k, a in enumerate(others):
            for b in others[k + 1:]:
                (an, ae), (bn, be) = _velocity(a), _velocity(b)
                rng = np.hypot(b.north_m - a.north_m + (bn - an) * t,
                               b.east_m - a.east_m + (be - ae) * t)
                assert rng[0] >= NM, (index, a.name, b.name)
                assert rng.min() >= NM * (1 - 1e-9) or rng.argmin() == t.size - 1, (
                    index, a.name, b.name, rng.min())


def test_classify_names_the_mutual_crossing_only_when_asked():
    """Each ship seeing the other on the same side (both to starboard, or both to port; the
    network's mutual_crossing, Rule 14(c)) is ``crossing_mutual`` with ``mutual``; without it,
    as the draws classify, the own ship's side alone decides, so the draws are unchanged."""
    north = 0.0
    both_stbd = (north, math.pi, 4000.0, 4000.0, 6.0, 6.0)  # reciprocal, 45 deg to starboard
    both_port = (north, math.radians(200.0), 7397.8, -387.7, 6.0, 6.0)
    assert classify(*both_stbd, mutual=True) == "crossing_mutual"
    assert classify(*both_port, mutual=True) == "crossing_mutual"
    assert classify(*both_stbd) == "crossing_give_way"
    assert classify(*both_port) == "crossing_stand_on"
    crossing = (north, math.radians(270.0), 4000.0, 4000.0, 6.0, 6.0)  # she sees us to port
    assert classify(*crossing, mutual=True) == classify(*crossing) == "crossing_give_way"
    assert classify(north, math.pi, 5000.0, 100.0, 6.0, 6.0, mutual=True) == "head_on"


def test_classify_takes_the_reciprocal_test_on_the_own_course():
    """Headings 172 deg apart, each ship within 6 deg of the other's bow: head-on; with the own
    course over ground 4.8 deg to starboard of her heading and the other's course at 167.3 deg
    (a current setting east) the courses are 162.5 deg apart: a crossing, as the network sees
    it (bearings from the own bow, the reciprocal test on the courses)."""
    geometry = (15000.0, -560.0, 6.17, 6.17)
    assert classify(0.0, math.radians(172.0), *geometry) == "head_on"
    assert classify(0.0, math.radians(167.3), *geometry,
                    own_course=math.radians(4.8)) == "crossing_stand_on"


def test_no_other_ship_starts_nearer_than_min_start_range_nm(tmp_path):
    """With ``min_start_range_nm: 1.5`` every other ship starts at least 1.5 NM from the own
    ship and from every other ship; without it, slow overtakings start nearer, and the
    encounters are those of a spec that gives 0 (the key only rejects draws)."""
    kinds = "encounter_types: {overtaking: 1, overtaken: 1, multi: 1}\n"

    def starts(spec):
        ranges, own = [], []
        for index in range(40):
            ships = draw(spec, index).ships
            for k, a in enumerate(ships):
                for b in ships[k + 1:]:
                    ranges.append(math.hypot(b.north_m - a.north_m, b.east_m - a.east_m))
                    own.append(k == 0)
        return np.array(ranges), np.array(own)

    far, _ = starts(_spec(tmp_path, kinds + "min_start_range_nm: 1.5", name="far.yaml"))
    assert far.min() >= 1.5 * NM
    near, own = starts(_spec(tmp_path, kinds, name="near.yaml"))
    assert (near[own] < 1.5 * NM).sum() >= 5 and near[own].min() < 0.6 * NM
    zero, _ = starts(_spec(tmp_path, kinds + "min_start_range_nm: 0", name="zero.yaml"))
    np.testing.assert_array_equal(near, zero)


def test_a_start_range_no_draw_reaches_names_the_key(tmp_path, monkeypatch):
    """Overtaking at 10-12 min TCPA cannot start 10 NM away with these speeds: the error
    names ``min_start_range_nm`` beside the other limits."""
    from trafficsim.campaign import generator as gen

    monkeypatch.setattr(gen, "MAX_TRIES", 3)
    monkeypatch.setattr(gen, "TRIES_PER_SHIP", 20)
    spec = _spec(tmp_path, "encounter_types: {overtaking: 1}\ntcpa_min: [10, 12]\n"
                 "min_start_range_nm: 10")
    errors = gen.drawing_errors(spec)
    assert [e.key for e in errors] == ["encounter_types.overtaking"]
    assert "DCPA and TCPA ranges and min_start_range_nm 10" in errors[0].message
