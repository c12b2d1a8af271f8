"""Tests of the decision step: roles per pair, pair memory (Rule 13(d)), orders, blind spots,
the decision records, and two rogue-ship scenarios run through the engine.

Ship states are passed as the engine passes them: ``own_state`` (3, n) north, east, heading;
``own_vel`` (2, n); ``other`` (4, m) per directed pair in the order of
:func:`trafficsim.sensors.radar.directed_pairs` (first every ``i -> j``, then every ``j -> i``).
Expected orders are hand computed from the closed-form DCPA of straight tracks
(shared/reference/colregs.md section 4).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from trafficsim.colregs.decider import (
    BEHAVIOURS,
    DRAW_AHEAD_MPS,
    PASSED_FLOOR_FACTOR,
    RESUME_MARGIN,
    RULES_DIR,
    BlindSpot,
    Decider,
    rules_file,
)
from trafficsim.colregs.vocabulary import (
    ALTER_COURSE,
    FEATURES,
    GIVE_WAY,
    KEEP,
    MEMORY,
    MUTUAL_GIVE_WAY,
    NO_ACTION,
    NO_ROLE,
    RESUME_ROUTE,
    STAND_ON,
    STARBOARD,
    VOCABULARY,
)
from trafficsim.errors import InputError
from trafficsim.run import run_scenario
from trafficsim.sensors.radar import directed_pairs

HERE = Path(__file__).parent
BOTH_STAND_ON = HERE / "rules" / "decider" / "both_stand_on.yaml"
STAND_ON_NEAR = HERE / "rules" / "decider" / "stand_on_near.yaml"
SLOW_IN_FOG = HERE / "rules" / "decider" / "slow_in_fog.yaml"
NM = 1852.0
V = 12.0 * NM / 3600.0  # 12 kn, m/s
LENGTH = np.array([150.0, 150.0])
ENC = VOCABULARY.enums

Ship = tuple[float, float, float, float]  # north m, east m, course = heading deg, speed m/s


def mem(dec: Decider, name: str) -> np.ndarray:
    return dec.memory[MEMORY.index(name)]


def feature(dec: Decider, name: str) -> np.ndarray:
    assert dec.last_features is not None
    return dec.last_features[FEATURES.index(name)]


def snapshot(dec: Decider, ships: list[Ship], nan_pairs: tuple[int, ...] = (),
             route_deg: list[float] | None = None, route_mps: list[float] | None = None
             ) -> tuple:
    """``decide`` arguments (after ``t_s``) for ships on straight courses; ``nan_pairs``:
    directed pairs whose observer has no track of the target; ``route_deg``, ``route_mps``: the
    route courses and speeds (default: the present ones)."""
    a = np.array(ships, dtype=float)
    north, east, course_deg, speed = a.T
    hdg = np.radians(course_deg)
    own_state = np.stack([north, east, hdg])
    own_vel = np.stack([speed * np.cos(hdg), speed * np.sin(hdg)])
    other = np.concatenate([own_state[:2, dec.tgt], own_vel[:, dec.tgt]])
    other[:, list(nan_pairs)] = np.nan
    route = hdg if route_deg is None else np.radians(np.asarray(route_deg, dtype=float))
    route_speed = speed if route_mps is None else np.asarray(route_mps, dtype=float)
    return own_state, own_vel, np.full(len(ships), 150.0), other, route, route_speed


def decide(dec: Decider, t_s: float, ships: list[Ship], nan_pairs: tuple[int, ...] = (),
           route_deg: list[float] | None = None, route_mps: list[float] | None = None) -> None:
    dec.decide(t_s, *snapshot(dec, ships, nan_pairs, route_deg, route_mps))


def build(behaviours: list[str], rules: Path | None = None) -> Decider:
    return Decider.build(behaviours, np.array([0]), np.array([1]), rules)


def head_on(tcpa_min: float) -> list[Ship]:
    """Ship 0 heading north, ship 1 dead ahead heading south, both 12 kn: range 2 V TCPA."""
    return [(0.0, 0.0, 0.0, V), (2.0 * V * 60.0 * tcpa_min, 0.0, 180.0, V)]


def crossing(tcpa_min: float) -> list[Ship]:
    """Imazu case 2: ship 0 heading north, ship 1 heading west from its starboard bow, both
    12 kn and meeting at the origin after ``tcpa_min``."""
    d = V * 60.0 * tcpa_min
    return [(-d, 0.0, 0.0, V), (0.0, d, 270.0, V)]


def wrap_deg(x: np.ndarray) -> np.ndarray:
    return np.mod(np.degrees(x), 360.0)


# --------------------------------------------------------------------------------------------
# Building
# --------------------------------------------------------------------------------------------

def test_build_pairs_networks_and_memory():
    pi, pj = np.array([0, 0, 1]), np.array([1, 2, 2])
    dec = Decider.build(["colregs", "keep_course", "turn_port", "colregs"], pi, pj)
    obs, tgt = directed_pairs(pi, pj)
    np.testing.assert_array_equal(dec.obs, obs)
    np.testing.assert_array_equal(dec.tgt, tgt)
    np.testing.assert_array_equal(dec.obs[dec.reverse], dec.tgt)
    np.testing.assert_array_equal(dec.tgt[dec.reverse], dec.obs)
    assert dec.ship_net.tolist() == [0, -1, 1, 0]
    assert [n.rules.name for n in dec.networks] == ["colregs", "turn_port"]
    assert dec.horizon_s == 1800.0  # look_ahead_min 30 of rules/colregs.yaml
    assert (mem(dec, "own_role") == NO_ROLE).all()
    assert (mem(dec, "own_manoeuvre") == NO_ACTION).all()
    assert (mem(dec, "encounter") == ENC["no_encounter"]).all()
    assert np.isnan(dec.course_order_rad).all()
    assert (dec.speed_factor == 1.0).all()
    assert (dec.candidate == -1).all()


def test_rules_files_and_unknown_behaviour():
    assert set(BEHAVIOURS) == {"colregs", "keep_course", "turn_port", "late_action"}
    assert rules_file("keep_course") is None
    assert rules_file("colregs") == RULES_DIR / "colregs.yaml"
    assert rules_file("colregs", BOTH_STAND_ON) == BOTH_STAND_ON
    assert rules_file("turn_port", BOTH_STAND_ON) == RULES_DIR / "turn_port.yaml"
    with pytest.raises(InputError, match="unknown behaviour 'zigzag'"):
        build(["colregs", "zigzag"])


# --------------------------------------------------------------------------------------------
# Roles and orders
# --------------------------------------------------------------------------------------------

def test_head_on_mutual_give_way_then_both_turn_to_starboard():
    """Rule 14: both ships mutual_give_way. At TCPA 20 min no action yet; at 14 min each turns
    30 deg to starboard: on reciprocal courses at equal speed a turn theta of one ship passes
    at range sin(theta / 2) (the other held), 10371 sin 15 = 2684 m >= 1 NM, and 30 deg is the
    least alteration the rules ask."""
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, head_on(20.0))
    assert mem(dec, "own_role").tolist() == [MUTUAL_GIVE_WAY, MUTUAL_GIVE_WAY]
    assert mem(dec, "other_role").tolist() == [MUTUAL_GIVE_WAY, MUTUAL_GIVE_WAY]
    assert mem(dec, "encounter").tolist() == [ENC["head_on"]] * 2
    assert np.isnan(dec.course_order_rad).all()

    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, head_on(14.0))
    assert mem(dec, "own_role").tolist() == [MUTUAL_GIVE_WAY, MUTUAL_GIVE_WAY]
    assert mem(dec, "own_manoeuvre").tolist() == [ALTER_COURSE, ALTER_COURSE]
    assert 2.0 * V * 840.0 * math.sin(math.radians(15.0)) == pytest.approx(2684.0, abs=1.0)
    np.testing.assert_allclose(wrap_deg(dec.course_order_rad), [30.0, 210.0], atol=1e-9)
    np.testing.assert_array_equal(dec.speed_factor, [1.0, 1.0])
    assert dec.blind_spots == []


def test_crossing_roles_and_give_way_acts_at_action_time():
    """Rule 15: the ship with the other on her starboard side gives way; Rule 16 with the 15 min
    action time of rules/colregs.yaml: no action while TCPA and time to domain entry exceed it,
    then a course order to starboard. At TCPA 14 min (6 NM x 14/30 = 5186 m each way) a 30 deg
    turn passes at 5186 (1 + sin 30 - cos 30) / sqrt(2 + 2 sin 30) = 1898 m >= 1 NM."""
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, crossing(16.5))
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
    assert mem(dec, "other_role").tolist() == [STAND_ON, GIVE_WAY]
    assert mem(dec, "encounter").tolist() == [ENC["crossing"]] * 2
    assert mem(dec, "own_manoeuvre").tolist() == [NO_ACTION, KEEP]
    assert feature(dec, "tcpa_min")[0] == pytest.approx(16.5)
    assert feature(dec, "time_to_domain_min")[0] > 15.0
    assert np.isnan(dec.course_order_rad).all()

    # 2.5 min later on the same tracks: TCPA 14 min
    decide(dec, 150.0, crossing(14.0))
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
    assert mem(dec, "own_manoeuvre").tolist() == [ALTER_COURSE, KEEP]
    direction, change, factor, distance = dec.request[:, 0]
    assert (direction, change, distance) == (STARBOARD, 30.0, 1.0)
    assert np.isnan(factor)  # no speed reduction asked
    d = 14.0 * 60.0 * V
    th = math.radians(30.0)
    assert d * (1 + math.sin(th) - math.cos(th)) / math.sqrt(2 + 2 * math.sin(th)) == \
        pytest.approx(1898.0, abs=1.0)
    assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(30.0, abs=1e-9)
    assert np.isnan(dec.course_order_rad[1])  # the stand-on ship keeps her course and speed
    np.testing.assert_array_equal(dec.speed_factor, [1.0, 1.0])
    assert dec.kept_distance_m[0] == pytest.approx(NM)


def test_give_way_waits_until_action_time_in_small_steps():
    """One decision every 10 s along the tracks (TCPA 20 -> 14.7 min): the first course order
    comes once TCPA or the time to domain entry falls to 15 min, not before, and is kept."""
    dec = build(["colregs", "colregs"])
    first = None
    for k in range(0, 33):
        t = 10.0 * k
        tcpa = 20.0 - t / 60.0
        decide(dec, t, crossing(tcpa))
        due = min(feature(dec, "tcpa_min")[0], feature(dec, "time_to_domain_min")[0]) <= 15.0
        if first is None:
            assert np.isnan(dec.course_order_rad[0]) != due
            if due:
                first = tcpa
        else:
            assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(30.0)
    assert first is not None and 15.0 <= first <= 17.0


def test_one_manoeuvre_keeps_clear_of_a_ship_that_asked_nothing_rule_8d():
    """Three ships: the crossing of test_crossing_roles_and_give_way_acts_at_action_time and a
    stopped ship 10000 m from ship 0 on bearing 030 (5000 m off her track, 3474 m off ship 1's:
    no risk, no role). The 30 deg turn would run at it (30, 35, 40 deg pass it at
    10000 sin 0, 5, 10 deg = 0, 872, 1736 m); 45 deg passes it at 2588 m and ship 1 at
    5186 x 0.5412 = 2806 m."""
    pi, pj = np.array([0, 0, 1]), np.array([1, 2, 2])
    dec = Decider.build(["colregs", "colregs", "keep_course"], pi, pj)
    ships = crossing(14.0)
    b = math.radians(30.0)
    ships.append((ships[0][0] + 10000.0 * math.cos(b), 10000.0 * math.sin(b), 0.0, 0.0))
    decide(dec, 0.0, ships)
    # directed pairs: 0->1, 0->2, 1->2, 1->0, 2->0, 2->1
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, NO_ROLE, NO_ROLE, STAND_ON, NO_ROLE,
                                             NO_ROLE]
    assert feature(dec, "dcpa_nm")[1] == pytest.approx(5000.0 / NM)
    assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(45.0)
    assert np.isnan(dec.course_order_rad[1:]).all()

    two = build(["colregs", "colregs"])
    decide(two, 0.0, ships[:2])
    assert wrap_deg(two.course_order_rad[0]) == pytest.approx(30.0)


def test_keep_course_ship_takes_no_decisions():
    dec = build(["colregs", "keep_course"])
    cursor = dec.cursor.copy()
    for k, tcpa in enumerate((20.0, 14.0, 13.0)):
        decide(dec, 10.0 * k, crossing(tcpa))
        assert mem(dec, "own_role")[1] == NO_ROLE
        assert mem(dec, "own_manoeuvre")[1] == NO_ACTION
        assert dec.cursor[1] == cursor[1]
        assert np.isnan(dec.course_order_rad[1]) and dec.speed_factor[1] == 1.0
    assert mem(dec, "own_role")[0] == GIVE_WAY
    # the snapshots hold ship 0 on her old course: at TCPA 13 min (4815 m each way) the 30 deg
    # turn would pass at 0.366 x 4815 = 1763 m < 1 NM; 35 deg would do (4815 (1 + sin 35 -
    # cos 35) / sqrt(2 + 2 sin 35) = 2047 m), but a replacement is substantial (Rule 8(b), at
    # least 15 deg more): 45 deg
    assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(45.0)
    assert dec.blind_spots == []

    # the rogue on the give-way side: the colregs ship still stands on
    dec = build(["keep_course", "colregs"])
    decide(dec, 0.0, crossing(14.0))
    assert mem(dec, "own_role").tolist() == [NO_ROLE, STAND_ON]
    assert np.isnan(dec.course_order_rad).all()


def test_role_memory_holds_until_past_and_clear():
    """Rule 13(d): once past the CPA but not yet clear the give-way ship keeps her role and her
    manoeuvre (a fresh look would find no risk of collision); when past and clear, no role and
    back to the route."""
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, crossing(14.0))
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
    order = dec.course_order_rad[0]

    # ship 0 on her new course 030; ship 1 1.57 NM away bearing 329 (61 deg on the port bow),
    # opening: TCPA < 0 but within 2 NM and forward of the beam
    past = [(0.0, 0.0, 30.0, V), (2500.0, -1500.0, 270.0, V)]
    decide(dec, 60.0, past, route_deg=[0.0, 270.0])
    assert feature(dec, "tcpa_min")[0] < 0.0
    assert feature(dec, "range_nm")[0] == pytest.approx(math.hypot(2500, 1500) / NM)
    assert feature(dec, "bearing_deg")[0] == pytest.approx(
        math.degrees(math.atan2(-1500.0, 2500.0)) - 30.0)
    assert mem(dec, "own_role")[0] == GIVE_WAY
    assert mem(dec, "own_manoeuvre")[0] == ALTER_COURSE
    assert dec.course_order_rad[0] == order
    # the memory features seen at this step: 1 min in role, the other unchanged, 30 deg turned
    assert feature(dec, "time_in_role_min")[0] == pytest.approx(1.0)
    assert feature(dec, "other_course_change_deg")[0] == pytest.approx(0.0, abs=1e-9)
    assert feature(dec, "other_speed_change_ratio")[0] == pytest.approx(1.0)
    assert feature(dec, "own_course_change_deg")[0] == pytest.approx(30.0)
    # the stand-on ship sees ship 0 121 deg on her port side (abaft the beam): clear
    assert mem(dec, "own_role")[1] == NO_ROLE

    # 2.5 NM apart, opening: past and clear; the route course (000) passes at
    # |3500 (-V) - (-3000)(-V)| / (V sqrt 2) = 4596 m >= 1 NM, so the route is resumed
    clear = [(0.0, 0.0, 30.0, V), (3500.0, -3000.0, 270.0, V)]
    decide(dec, 70.0, clear, route_deg=[0.0, 270.0])
    assert mem(dec, "own_role").tolist() == [NO_ROLE, NO_ROLE]
    assert mem(dec, "encounter").tolist() == [ENC["no_encounter"]] * 2
    assert mem(dec, "own_manoeuvre")[0] == RESUME_ROUTE
    assert np.isnan(dec.course_order_rad).all()
    assert dec.candidate.tolist() == [-1, -1]


def test_role_memory_survives_other_ship_manoeuvre():
    """The stand-on ship keeps her role when the give-way ship's course change would, on a
    fresh look, make her the give-way ship; the memory reports the change in the other's
    course and speed since the role was set."""
    dec = build(["colregs", "colregs"])
    decide(dec, 120.0, crossing(14.0))
    ships = crossing(13.0)
    ships[0] = (ships[0][0], ships[0][1], 60.0, 0.7 * V)  # ship 0 turned 60 deg and slowed
    decide(dec, 180.0, ships)
    assert mem(dec, "own_role")[1] == STAND_ON
    assert feature(dec, "other_course_change_deg")[1] == pytest.approx(60.0)
    assert feature(dec, "other_speed_change_ratio")[1] == pytest.approx(0.7)
    assert feature(dec, "time_in_role_min")[1] == pytest.approx(1.0)


def test_role_memory_holds_through_a_track_dropout():
    """The give-way ship loses her track of the stand-on ship for two periods: her role and
    her manoeuvre are kept (every test on the unknown features is false) and come back with
    the track."""
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, crossing(14.0))
    order = dec.course_order_rad[0]
    for k in (1, 2):
        decide(dec, 10.0 * k, crossing(14.0 - k / 6.0), nan_pairs=(0,))
        assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
        assert mem(dec, "own_manoeuvre")[0] == ALTER_COURSE
        assert dec.course_order_rad[0] == order
    decide(dec, 30.0, crossing(13.5))
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
    assert np.isfinite(dec.course_order_rad[0])


def test_no_track_no_role():
    """NaN for what ship 0 knows of ship 1 (no track): every test is false, no role, no order;
    ship 1 still sees ship 0 (truth) and stands on. Once a track exists ship 0 gives way."""
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, crossing(14.0), nan_pairs=(0,))
    assert np.isnan(feature(dec, "range_nm")[0])
    assert mem(dec, "own_role").tolist() == [NO_ROLE, STAND_ON]
    assert mem(dec, "own_manoeuvre")[0] == NO_ACTION
    assert np.isnan(dec.course_order_rad).all()
    assert dec.blind_spots == []
    decide(dec, 10.0, crossing(14.0 - 1.0 / 6.0))
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
    assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(30.0)


def _fog_then_clear(ahead_mps: float) -> Decider:
    """slow_in_fog.yaml on ship 0 heading north at 12 kn; ship 1 (keeping course) 1200 m dead
    ahead on the same course at ``ahead_mps``. Fog: ship 0 slows to half speed (3.09 m/s);
    then the visibility clears and she asks to resume her route."""
    dec = build(["colregs", "keep_course"], rules=SLOW_IN_FOG)
    dec.visibility_nm = 1.0
    ships = [(0.0, 0.0, 0.0, V), (1200.0, 0.0, 0.0, ahead_mps)]
    decide(dec, 0.0, ships)
    assert mem(dec, "own_manoeuvre")[0] == ENC["reduce_speed"]
    assert dec.speed_factor[0] == 0.5
    assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(0.0)
    dec.visibility_nm = 10.0
    ships[0] = (0.0, 0.0, 0.0, 0.5 * V)
    decide(dec, 10.0, ships, route_deg=[0.0, 0.0], route_mps=[V, ahead_mps])
    assert mem(dec, "own_manoeuvre")[0] == RESUME_ROUTE
    return dec


def test_resume_route_when_full_speed_is_safe():
    """Ship 1 ahead at 8 m/s, faster than ship 0 at full speed: resuming opens the range,
    so the ship is released to her route at full speed."""
    dec = _fog_then_clear(8.0)
    assert np.isnan(dec.course_order_rad[0])
    assert dec.speed_factor[0] == 1.0
    assert dec.candidate[0] == -1


def test_resume_route_not_into_a_slower_ship_ahead():
    """Ship 1 ahead at 4.5 m/s: at half speed (3.09 m/s) the range opens, at full speed
    (6.17 m/s) ship 0 closes on her at 1.67 m/s on the same track (CPA 0 m after 718 s, within
    the look-ahead). Resuming must not create this close-quarters situation (Rule 8(d)): she
    follows her route at the reduced speed until full speed keeps the 0.5 NM asked plus the
    resume margin (926 x 1.1 = 1019 m) over the 30 min look-ahead, i.e. until ship 1 is
    1019 + 1.67 x 1800 = 4031 m ahead."""
    dec = _fog_then_clear(4.5)
    assert dec.speed_factor[0] == 0.5
    assert np.isnan(dec.course_order_rad[0])  # on her route, at the reduced speed
    assert dec.candidate[0] >= 0  # not yet released
    closing = V - 4.5
    assert 0.5 * NM * (1.0 + RESUME_MARGIN) + closing * 1800.0 == pytest.approx(4031.0, abs=1.0)
    for ahead_m, factor in ((3900.0, 0.5), (4100.0, 1.0)):
        decide(dec, 20.0, [(0.0, 0.0, 0.0, 0.5 * V), (ahead_m, 0.0, 0.0, 4.5)],
               route_deg=[0.0, 0.0], route_mps=[V, 4.5])
        assert dec.speed_factor[0] == factor, ahead_m
    assert dec.candidate[0] == -1 and np.isnan(dec.course_order_rad[0])  # released


def test_a_manoeuvre_asked_while_resuming_on_a_new_leg_starts_from_the_present_course():
    """Ship 0 slows on her course 000 in fog, resumes her route at half speed behind the slower
    ship 1 when it clears (not yet released), and follows it round onto a leg 090. Fog again:
    she slows on her present course, 090, not on the 000 the first manoeuvre was taken from
    (which would turn her 90 deg to port). On the same leg, the manoeuvre she ran is taken up
    from its own base course."""
    for leg_deg, heading_deg, expected_deg in ((90.0, 90.0, 90.0), (0.0, 10.0, 0.0)):
        dec = _fog_then_clear(4.5)
        assert dec.candidate[0] >= 0 and dec.resuming[0]
        dec.visibility_nm = 1.0
        decide(dec, 300.0, [(2000.0, 0.0, heading_deg, 0.5 * V), (3000.0, 0.0, 0.0, 4.5)],
               route_deg=[leg_deg, 0.0], route_mps=[V, 4.5])
        assert mem(dec, "own_manoeuvre")[0] == ENC["reduce_speed"]
        assert dec.speed_factor[0] == 0.5
        assert not dec.resuming[0]
        assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(expected_deg), leg_deg


def test_route_line_model_follows_the_route_guidance():
    """Route guidance steers leg course - atan(e / 600 m) for a 150 m ship (look-ahead 4
    lengths): the decision step recovers the cross-track error e from the route course it is
    given, and starts a new model where the route course is not the one predicted (a new
    leg)."""
    dec = build(["colregs", "keep_course"])
    far = (30000.0, 30000.0, 180.0, V)  # no encounter
    decide(dec, 0.0, [(0.0, 0.0, 0.0, V), far])
    assert dec.line_course_rad[0] == 0.0
    for east in (300.0, -1200.0):
        ships = [(500.0, east, 0.0, V), far]
        route = math.degrees(-math.atan(east / 600.0))
        decide(dec, 10.0, ships, route_deg=[route, 180.0])
        assert dec.line_course_rad[0] == 0.0
        assert dec.cross_track_m[0] == pytest.approx(east)
    decide(dec, 20.0, [(500.0, -1200.0, 0.0, V), far], route_deg=[90.0, 180.0])
    assert dec.line_course_rad[0] == pytest.approx(math.radians(90.0))
    assert dec.cross_track_m[0] == 0.0


def _overtaken_ship_ahead() -> tuple[Decider, float]:
    """Ship 0 (colregs, 150 m: route look-ahead 600 m) overtakes ship 1 (keep_course, 8.4 kn)
    on her route line, the line north through the origin: 1500 m astern (TCPA 13.5 min) she
    gives way (Rule 13). Returns the decider and ship 1's speed."""
    v1 = 8.4 * NM / 3600.0
    dec = build(["colregs", "keep_course"])
    decide(dec, 0.0, [(0.0, 0.0, 0.0, V), (1500.0, 0.0, 0.0, v1)])
    assert mem(dec, "own_role")[0] == GIVE_WAY
    assert mem(dec, "encounter")[0] == ENC["overtaking"]
    assert mem(dec, "own_manoeuvre")[0] == ALTER_COURSE
    assert dec.kept_distance_m[0] == pytest.approx(NM)
    return dec, v1


def _path_ranges_m(own: Ship, other: Ship, course_deg: float, horizon_s: float = 1800.0,
                   n: int = 18_001) -> np.ndarray:
    """Range to ``other`` (straight on) of ship 0 steering ``course_deg`` until she meets her
    route line (north through the origin), then north along it, densely sampled over
    ``horizon_s``; no code shared with the decider."""
    t = np.linspace(0.0, horizon_s, n)
    c = math.radians(course_deg)
    v = own[3]
    across = v * math.sin(c)
    meet = -own[1] / across if own[1] * across < 0.0 else math.inf
    t1 = np.minimum(t, meet)
    north = own[0] + v * math.cos(c) * t1 + v * (t - t1)
    east = own[1] + across * t1
    oc = math.radians(other[2])
    return np.hypot(other[0] + other[3] * math.cos(oc) * t - north,
                    other[1] + other[3] * math.sin(oc) * t - east)


def _path_closest_m(own: Ship, other: Ship, course_deg: float) -> float:
    """The least of :func:`_path_ranges_m`; +inf when the range opens from the start."""
    rng = _path_ranges_m(own, other, course_deg)
    return math.inf if rng[1] > rng[0] else float(rng.min())


def _path_least_m(own: Ship, other: Ship, course_deg: float) -> float:
    """The least of :func:`_path_ranges_m`, even where the range opens at first (it may close
    again along the route line)."""
    return float(_path_ranges_m(own, other, course_deg).min())


def test_overtaking_ship_holds_off_the_line_then_crosses_ahead_rule_13d():
    """The overtaking ship has sheered off to 3600 m starboard of her line and is still
    1000 m astern of ship 1, heading 030: 2.02 NM off, range opening, 15.5 deg abaft ship 1's
    beam: not past, so she resumes her route but stays the give-way overtaking ship (Rule
    13(d)). Her route course steers straight back onto the line (000 - atan(3600 / 600) =
    279.5 deg) and would meet it 2550 m astern of ship 1, then close on her along it: she is
    not released, but turns back towards it only as far as her path keeps ship 1 at 1 NM x 1.1
    (a course 5 deg further does not).

    4500 m ahead of ship 1 she is finally past and clear (ship 1 abaft her beam, she 38.7 deg
    off ship 1's bow) and, ahead of ship 1's beam with the range opening and drawing ahead of
    her, has passed her at 5763 m; the range kept from here on is that, at most 1.5 x the
    1 NM her manoeuvre kept: 2778 m. Her route would meet the line (in 3600 / (V sin 80.54) =
    591 s, 600 m further north) 4500 + 600 - 4.32 x 591 = 2545 m ahead of ship 1, cutting back
    across her bow nearer than that: she is not released, and turns back only as far as her
    path keeps ship 1 at 2778 m (Rules 13(d), 8(d)). 4800 m ahead of ship 1 her route meets
    the line 2845 m ahead of her: released. The next step, on her route course, the risk test
    does not take her back (no hunting)."""
    dec, v1 = _overtaken_ship_ahead()
    los = math.degrees(-math.atan(3600.0 / 600.0))
    assert los == pytest.approx(-80.54, abs=0.01)
    need = NM * (1.0 + RESUME_MARGIN)
    n1 = 6000.0
    one = (n1, 0.0, 0.0, v1)
    own: Ship = (n1 - 1000.0, 3600.0, 30.0, V)
    assert _path_closest_m(own, one, los) < need  # the route: astern of her, then onto her
    decide(dec, 600.0, [own, one], route_deg=[los, 0.0])
    assert feature(dec, "range_nm")[0] == pytest.approx(math.hypot(1000.0, 3600.0) / NM)
    assert feature(dec, "aspect_abs_deg")[0] == pytest.approx(
        math.degrees(math.atan2(3600.0, -1000.0)))
    assert mem(dec, "own_role")[0] == GIVE_WAY
    assert mem(dec, "encounter")[0] == ENC["overtaking"]
    assert mem(dec, "own_manoeuvre")[0] == RESUME_ROUTE
    assert dec.candidate[0] >= 0  # resuming, not released
    assert np.isnan(dec.passed_range_m[0])  # astern of her beam: not passed
    course = float(wrap_deg(dec.course_order_rad[0]))
    assert 0.0 < (course - los) % 360.0 < 30.0 - los  # between her route course and 030
    assert _path_closest_m(own, one, course) >= need
    assert _path_closest_m(own, one, course - 5.0) < need
    assert dec.speed_factor[0] == 1.0

    own = (n1 + 4500.0, 3600.0, course, V)
    passed = math.hypot(4500.0, 3600.0)
    assert passed == pytest.approx(5763.0, abs=1.0)
    floor = PASSED_FLOOR_FACTOR * NM
    assert floor == pytest.approx(2778.0)
    t1 = 3600.0 / (V * math.sin(math.radians(-los)))  # 591 s to the line, 600 m north
    assert 4500.0 + 600.0 - v1 * t1 == pytest.approx(2545.0, abs=1.0)
    assert _path_least_m(own, one, los) == pytest.approx(2545.0, abs=1.0)
    decide(dec, 610.0, [own, one], route_deg=[los, 0.0])
    assert feature(dec, "bearing_abs_deg")[0] > 112.5
    assert feature(dec, "aspect_abs_deg")[0] == pytest.approx(
        math.degrees(math.atan2(3600.0, 4500.0)))
    assert mem(dec, "own_role")[0] == NO_ROLE  # past and clear
    assert dec.passed_range_m[0] == pytest.approx(floor)
    assert dec.candidate[0] >= 0  # resuming, not released
    turned = float(wrap_deg(dec.course_order_rad[0]))
    assert 0.0 < (turned - los) % 360.0 <= (course - los) % 360.0  # not away from the route
    assert _path_least_m(own, one, turned) >= floor - 1.0
    assert _path_least_m(own, one, turned - 5.0) < floor

    for ahead_m, released in ((4700.0, False), (4800.0, True)):
        own = (n1 + ahead_m, 3600.0, turned, V)
        assert (_path_least_m(own, one, los) >= floor) == released, ahead_m
        decide(dec, 620.0, [own, one], route_deg=[los, 0.0])
        assert (dec.candidate[0] == -1) == released, ahead_m
    assert np.isnan(dec.course_order_rad[0]) and dec.speed_factor[0] == 1.0
    assert np.isnan(dec.passed_range_m[0])  # forgotten with the return
    c = math.radians(los)
    ahead = [(own[0] + 10.0 * V * math.cos(c), own[1] + 10.0 * V * math.sin(c), los, V),
             (n1 + 10.0 * v1, 0.0, 0.0, v1)]
    los_next = math.degrees(-math.atan(ahead[0][1] / 600.0))
    decide(dec, 630.0, ahead, route_deg=[los_next, 0.0])
    assert feature(dec, "dcpa_nm")[0] > 1.0  # no risk of collision on her route course
    assert mem(dec, "own_role")[0] == NO_ROLE
    assert np.isnan(dec.course_order_rad[0])


def test_ship_keeping_pace_sets_no_passed_floor():
    """Ahead of ship 1's beam (4500 m ahead, 3600 m to starboard) with the range opening, but
    on a course 10 deg off hers at her speed: drawing ahead of her along her own course by
    4.32 (1 - cos 10 deg) = 0.07 m/s, below ``DRAW_AHEAD_MPS``, she has not passed ship 1
    and keeps no floor; drawing ahead at 12 kn she has."""
    dec, v1 = _overtaken_ship_ahead()
    los = math.degrees(-math.atan(3600.0 / 600.0))
    one = (6000.0, 0.0, 0.0, v1)
    decide(dec, 600.0, [(5000.0, 3600.0, 30.0, V), one], route_deg=[los, 0.0])
    assert dec.candidate[0] >= 0  # resuming
    assert v1 * (1.0 - math.cos(math.radians(10.0))) < DRAW_AHEAD_MPS
    one = (10_500.0, 0.0, 0.0, v1)
    decide(dec, 610.0, [(15_000.0, 3600.0, 10.0, v1), one], route_deg=[los, 0.0])
    assert dec.candidate[0] >= 0
    assert np.isnan(dec.passed_range_m[0])
    decide(dec, 620.0, [(15_000.0, 3600.0, 10.0, V), one], route_deg=[los, 0.0])
    assert dec.passed_range_m[0] == pytest.approx(PASSED_FLOOR_FACTOR * NM)


def test_lost_track_resumes_after_the_timeout():
    """Ship 0 gives way to ship 1 (crossing, 30 deg to starboard), then loses her track. The
    pair keeps its encounter for lost_track_min (3 min in rules/colregs.yaml): the order is
    held at 170 s; at 190 s the pair forgets it (as past and clear) and, with no other ship
    known, ship 0 is back on her route. When the track comes back the encounter starts
    afresh from the first node."""
    dec = build(["colregs", "colregs"])
    assert dec.lost_track_s.tolist() == [180.0, 180.0]
    decide(dec, 0.0, crossing(14.0))
    order = dec.course_order_rad[0]
    assert wrap_deg(order) == pytest.approx(30.0)
    for t in (10.0, 170.0):
        decide(dec, t, crossing(14.0 - t / 60.0), nan_pairs=(0,))
        assert mem(dec, "own_role")[0] == GIVE_WAY
        assert dec.course_order_rad[0] == order
    decide(dec, 190.0, crossing(14.0 - 190.0 / 60.0), nan_pairs=(0,))
    assert mem(dec, "own_role")[0] == NO_ROLE
    assert mem(dec, "encounter")[0] == ENC["no_encounter"]
    assert mem(dec, "own_manoeuvre")[0] == RESUME_ROUTE
    assert np.isnan(dec.request[:, 0]).all()
    assert np.isnan(dec.course_order_rad[0]) and dec.candidate[0] == -1
    assert mem(dec, "own_role")[1] == STAND_ON  # ship 1 still sees ship 0
    decide(dec, 200.0, crossing(14.0 - 200.0 / 60.0))
    assert mem(dec, "own_role")[0] == GIVE_WAY  # a new encounter
    assert feature(dec, "time_in_role_min")[0] == 0.0


def test_lost_track_resume_keeps_clear_of_the_ships_it_knows():
    """As above, with a stopped ship 2 known to ship 0, 3000 m ahead and 1950 m to port of her
    route line: her route passes it at 1950 m, no risk of collision (> 1 NM) but short of the
    resume distance (1 NM x 1.1 = 2037 m); her 030 course at 3000 sin 30 + 1950 cos 30 =
    3189 m. After the timeout she resumes, but is not released to the route: she keeps a
    course that passes ship 2 at the resume distance."""
    pi, pj = np.array([0, 0, 1]), np.array([1, 2, 2])
    dec = Decider.build(["colregs", "colregs", "keep_course"], pi, pj)
    ships = crossing(14.0)
    stopped = (ships[0][0] + 3000.0, -1950.0, 0.0, 0.0)
    # directed pairs: 0->1, 0->2, 1->2, 1->0, 2->0, 2->1
    decide(dec, 0.0, [*ships, stopped], route_deg=[0.0, 270.0, 0.0])
    assert mem(dec, "own_role")[:2].tolist() == [GIVE_WAY, NO_ROLE]
    assert wrap_deg(dec.course_order_rad[0]) == pytest.approx(30.0)
    decide(dec, 190.0, [*ships, stopped], nan_pairs=(0,), route_deg=[0.0, 270.0, 0.0])
    assert mem(dec, "own_role")[0] == NO_ROLE
    assert dec.candidate[0] >= 0  # resuming, not released
    course = wrap_deg(dec.course_order_rad[0])
    assert 0.0 < course <= 30.0
    c = math.radians(course)
    assert 3000.0 * math.sin(c) + 1950.0 * math.cos(c) >= NM * (1.0 + RESUME_MARGIN)


# --------------------------------------------------------------------------------------------
# Blind spots
# --------------------------------------------------------------------------------------------

def test_blind_spot_after_more_than_one_period():
    dec = build(["colregs", "colregs"], rules=BOTH_STAND_ON)
    assert [n.rules.name for n in dec.networks] == ["both_stand_on"]
    decide(dec, 0.0, crossing(14.0))
    assert mem(dec, "own_role").tolist() == [STAND_ON, STAND_ON]
    assert dec.blind_spots == []
    decide(dec, 10.0, crossing(14.0 - 1.0 / 6.0))
    assert dec.blind_spots == [BlindSpot(ship=0, other=1, role="stand_on", from_s=10.0,
                                         periods=2)]
    decide(dec, 20.0, crossing(14.0 - 2.0 / 6.0))
    assert len(dec.blind_spots) == 1  # one report per blind spot, not one per period
    assert dec.blind_spot_report(["own", "TS1"]) == [
        {"ship": "own", "other": "TS1", "role": "stand_on", "from_s": 10.0}]
    # standing on changes no order
    assert np.isnan(dec.course_order_rad).all()


def test_blind_spot_between_different_networks():
    """Ship 0 on the faulty network stands on; ship 1 on turn_port (the COLREGS classification)
    stands on by Rule 15: a blind spot. With ship 1 keeping course (no role) there is none."""
    dec = Decider.build(["colregs", "turn_port"], np.array([0]), np.array([1]), BOTH_STAND_ON)
    for k in range(3):
        decide(dec, 10.0 * k, crossing(14.0 - k / 6.0))
    assert [(b.ship, b.other, b.role) for b in dec.blind_spots] == [(0, 1, "stand_on")]
    dec = build(["colregs", "keep_course"], rules=BOTH_STAND_ON)
    for k in range(3):
        decide(dec, 10.0 * k, crossing(14.0 - k / 6.0))
    assert dec.blind_spots == []


def test_blind_spot_reported_each_time_it_sets_in():
    """stand_on_near.yaml: both ships stand on within 5 NM. Ranges (NM) per period 4, 4, 4
    (one report, at the second period), 6 (condition broken), 4, 4 (a second report)."""
    dec = build(["colregs", "colregs"], rules=STAND_ON_NEAR)
    reports = []
    for k, range_nm in enumerate((4.0, 4.0, 4.0, 6.0, 4.0, 4.0)):
        decide(dec, 10.0 * k, [(0.0, 0.0, 0.0, V), (range_nm * NM, 0.0, 90.0, V)])
        reports.append(len(dec.blind_spots))
    assert reports == [0, 1, 1, 1, 1, 2]
    assert [b.from_s for b in dec.blind_spots] == [10.0, 50.0]


@pytest.mark.parametrize("ships", [head_on(14.0), crossing(14.0)], ids=["head_on", "crossing"])
def test_colregs_network_has_no_blind_spot(ships):
    dec = build(["colregs", "colregs"])
    for k in range(4):
        decide(dec, 10.0 * k, ships)
    assert dec.blind_spots == []


# --------------------------------------------------------------------------------------------
# Records and determinism
# --------------------------------------------------------------------------------------------

RECORD_COLUMNS = ["t_s", "ship", "other", "rules", "rules_sha1", "path", "decided_own_role",
                  "decided_encounter", "decided_other_role", "decided_own_manoeuvre",
                  "course_order_deg", *FEATURES]


def test_records_one_row_per_step_and_deciding_pair():
    dec = build(["colregs", "keep_course"])
    dec.record = True
    times = (0.0, 150.0, 160.0)
    for t, tcpa in zip(times, (16.5, 14.0, 14.0 - 1.0 / 6.0), strict=True):
        decide(dec, t, crossing(tcpa))
    cols = dec.records(["own", "TS1"])
    assert list(cols) == RECORD_COLUMNS
    assert all(len(v) == 3 for v in cols.values())
    assert list(cols["t_s"]) == list(times)
    assert cols["ship"] == ["own"] * 3 and cols["other"] == ["TS1"] * 3
    assert all(r == str(RULES_DIR / "colregs.yaml") for r in cols["rules"])
    assert cols["path"][0] == ("assess>risk>overtaking>overtaken>head_on>crossing_side>"
                               "crossing_starboard>give_way_crossing>give_way_wait")
    assert cols["path"][1] == "give_way_still>give_way_wait>give_way_act"
    assert cols["path"][2].startswith("keep_clear")
    assert cols["decided_own_role"] == ["give_way"] * 3
    assert cols["decided_encounter"] == ["crossing"] * 3
    assert cols["decided_other_role"] == ["stand_on"] * 3
    assert cols["decided_own_manoeuvre"] == ["no_action", "alter_course", "alter_course"]
    np.testing.assert_allclose(cols["course_order_deg"][1:], [30.0, 30.0])
    assert np.isnan(cols["course_order_deg"][0])
    assert cols["tcpa_min"][0] == pytest.approx(16.5)
    assert cols["tcpa_min"][1] == pytest.approx(14.0)
    assert cols["own_role"][0] == NO_ROLE  # memory as the network saw it, before the step
    assert cols["own_role"][1] == GIVE_WAY
    assert feature(dec, "range_nm")[0] == cols["range_nm"][2]


def test_records_two_deciding_ships_and_empty_history():
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, crossing(14.0))
    empty = dec.records(["a", "b"])  # record is off: no rows
    assert list(empty) == RECORD_COLUMNS
    assert all(len(v) == 0 for v in empty.values())

    dec = build(["colregs", "turn_port"])
    dec.record = True
    for k in range(2):
        decide(dec, 10.0 * k, crossing(14.0 - k / 6.0))
    cols = dec.records(["a", "b"])
    assert all(len(v) == 4 for v in cols.values())
    assert cols["ship"] == ["a", "b", "a", "b"]
    assert cols["other"] == ["b", "a", "b", "a"]
    assert list(cols["t_s"]) == [0.0, 0.0, 10.0, 10.0]
    assert Path(cols["rules"][1]).name == "turn_port.yaml"
    assert cols["decided_own_role"][:2] == ["give_way", "stand_on"]


def _run(behaviours: list[str]) -> tuple[Decider, list[np.ndarray]]:
    dec = build(behaviours)
    dec.record = True
    orders = []
    for k in range(12):
        ships = crossing(15.5 - k / 3.0)
        ships[1] = (ships[1][0] + 37.0 * k, ships[1][1], 270.0 + 2.0 * k, V * (1 - 0.01 * k))
        decide(dec, 20.0 * k, ships)
        orders.append(np.concatenate([dec.course_order_rad, dec.speed_factor]))
    return dec, orders


def test_deterministic():
    a, orders_a = _run(["colregs", "colregs"])
    b, orders_b = _run(["colregs", "colregs"])
    for x, y in zip(orders_a, orders_b, strict=True):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.memory, b.memory)
    np.testing.assert_array_equal(a.cursor, b.cursor)
    ra, rb = a.records(["a", "b"]), b.records(["a", "b"])
    for name in ra:
        if isinstance(ra[name], np.ndarray):
            np.testing.assert_array_equal(ra[name], rb[name])
        else:
            assert ra[name] == rb[name]


# --------------------------------------------------------------------------------------------
# Engine level: rogue ships (scenario files written to tmp_path, as scenarios/imazu/imazu02)
# --------------------------------------------------------------------------------------------

SCENARIO = """schema_version: 1
name: {name}
description: Imazu case 2 with a rogue give-way ship.
duration_s: 2700
seed: 1
record_every_s: 10.0
ships:
  - name: own
    type: cargo
    north_m: -11112
    east_m: 0
    heading_deg: 0
    speed_kn: 12
    route: [[11112, 0]]
    behaviour: {own}
  - name: TS1
    type: cargo
    north_m: 0
    east_m: 11112
    heading_deg: 270
    speed_kn: 12
    behaviour: colregs
"""


def read_parquet(path: Path) -> dict[str, list]:
    import pyarrow.parquet as pq  # only the engine-level tests need it

    return pq.read_table(path).to_pydict()


def _scenario(tmp_path: Path, own: str) -> tuple[dict, dict, dict]:
    path = tmp_path / f"rogue_{own}.yaml"
    path.write_text(SCENARIO.format(name=f"rogue_{own}", own=own))
    run_scenario(path, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    return summary, read_parquet(tmp_path / "out" / "trajectories.parquet"), \
        read_parquet(tmp_path / "out" / "decisions.parquet")


def _ship(table: dict, name: str, column: str) -> np.ndarray:
    return np.asarray(table[column])[np.asarray(table["ship"]) == name]


def test_rogue_turn_port_alters_to_port(tmp_path):
    summary, traj, decisions = _scenario(tmp_path, "turn_port")
    course = _ship(traj, "own", "course_order_deg")
    t = _ship(traj, "own", "t_s")
    # it gives way as COLREGS classify the encounter, but to port: a 30 deg turn, 000 -> 330
    assert np.any(np.abs(course - 330.0) < 0.5)
    first = t[np.argmax(np.abs((course + 180.0) % 360.0 - 180.0) > 1.0)]
    assert 800.0 <= first <= 1000.0  # about 15 min before the unaltered CPA at 1800 s
    before_cpa = t <= 1800.0
    assert (((course[before_cpa] + 180.0) % 360.0 - 180.0) <= 1e-6).all()  # never to starboard
    assert _ship(traj, "own", "east_m").min() < -2000.0
    roles = _ship(decisions, "own", "decided_own_role")
    assert "give_way" in roles
    assert all(Path(r).name == "turn_port.yaml" for r in _ship(decisions, "own", "rules"))
    assert summary["collisions"] == 0


def test_rogue_keep_course_stand_on_ship_acts(tmp_path):
    """Rule 17(a)(ii): the give-way ship keeps her course and speed; the stand-on ship acts
    once domain entry is 10 min away, and the two pass clear."""
    summary, traj, decisions = _scenario(tmp_path, "keep_course")
    np.testing.assert_allclose(_ship(traj, "own", "east_m"), 0.0, atol=1.0)  # the rogue
    assert "own" not in decisions["ship"]  # keep_course: no decisions
    manoeuvre = _ship(decisions, "TS1", "decided_own_manoeuvre")
    acting = np.flatnonzero(np.isin(manoeuvre, ["reduce_speed", "alter_course", "emergency"]))
    assert acting.size
    k = acting[0]
    assert _ship(decisions, "TS1", "decided_own_role")[k] == "stand_on"
    assert _ship(decisions, "TS1", "time_to_domain_min")[k] <= 10.0
    assert (_ship(decisions, "TS1", "time_to_domain_min")[:k] > 10.0).all()
    assert set(manoeuvre[:k]) <= {"no_action", "keep"}
    course = _ship(traj, "TS1", "course_order_deg")
    sog = _ship(traj, "TS1", "sog_kn")
    assert np.any(np.abs(course - 270.0) > 5.0) or sog.min() < 10.0  # she did act
    (pair,) = summary["pairs"]
    assert pair["collision"] is False
    assert summary["collisions"] == 0
    assert pair["min_range_m"] >= 0.5 * NM


# --------------------------------------------------------------------------------------------
# The classification of rules/colregs.yaml, seen from both ships of a pair
# --------------------------------------------------------------------------------------------

NAME = {v: k for k, v in ENC.items()}


def roles(ships: list[Ship], visibility_nm: float = 10.0) -> list[tuple[str, str, str]]:
    """(own_role, encounter, other_role) of ship 0 about ship 1 and of ship 1 about ship 0
    after one decision of two ships running rules/colregs.yaml."""
    dec = Decider.build(["colregs", "colregs"], np.array([0]), np.array([1]),
                        visibility_nm=visibility_nm)
    decide(dec, 0.0, ships)
    return [tuple(NAME[float(mem(dec, k)[p])] for k in ("own_role", "encounter", "other_role"))
            for p in (0, 1)]


def at_bearing(range_nm: float, bearing_deg: float, course_deg: float,
               speed: float = V) -> Ship:
    """A ship ``range_nm`` from the origin on true bearing ``bearing_deg``."""
    b = math.radians(bearing_deg)
    return (range_nm * NM * math.cos(b), range_nm * NM * math.sin(b), course_deg, speed)


OWN: Ship = (0.0, 0.0, 0.0, V)  # at the origin, north at 12 kn
GW_CROSS = ("give_way", "crossing", "stand_on")
SO_CROSS = ("stand_on", "crossing", "give_way")
MUTUAL_HO = ("mutual_give_way", "head_on", "mutual_give_way")
MUTUAL_CROSS = ("mutual_give_way", "crossing", "mutual_give_way")
NONE = ("no_role", "no_encounter", "no_role")


@pytest.mark.parametrize(("ships", "expected"), [
    # Rule 14: reciprocal courses, dead ahead; and 5 deg on either bow (each sees the other
    # 5 deg off: 3 sin 5 = 0.26 NM DCPA)
    ([OWN, at_bearing(6.0, 0.0, 180.0)], [MUTUAL_HO, MUTUAL_HO]),
    ([OWN, at_bearing(3.0, 5.0, 180.0)], [MUTUAL_HO, MUTUAL_HO]),
    ([OWN, at_bearing(3.0, -5.0, 180.0)], [MUTUAL_HO, MUTUAL_HO]),
    # Rule 15 (Imazu case 2 at TCPA 20 min): the other on the starboard bow steering west,
    # both reaching (4 NM, 0) together; the mirror from port
    ([OWN, at_bearing(4.0 * math.sqrt(2.0), 45.0, 270.0)], [GW_CROSS, SO_CROSS]),
    ([OWN, at_bearing(4.0 * math.sqrt(2.0), -45.0, 90.0)], [SO_CROSS, GW_CROSS]),
    # Rule 13: 12 kn coming up on a 6 kn ship 1 NM ahead, 0.2 NM to starboard (TCPA 10 min)
    ([OWN, (NM, 0.2 * NM, 0.0, V / 2)], [("give_way", "overtaking", "stand_on"),
                                         ("stand_on", "overtaken", "give_way")]),
    ([(NM, 0.2 * NM, 0.0, V / 2), OWN], [("stand_on", "overtaken", "give_way"),
                                         ("give_way", "overtaking", "stand_on")]),
    # Rule 14(c) doubt: reciprocal courses, each 14 deg on the other's port bow
    ([OWN, at_bearing(3.0, -14.0, 180.0)], [MUTUAL_CROSS, MUTUAL_CROSS]),
    # no risk of collision (Rule 7): DCPA 3 sin 30 = 1.5 NM; TCPA 31 min; opening
    ([OWN, at_bearing(3.0, 30.0, 180.0)], [NONE, NONE]),
    ([OWN, at_bearing(2.0 * V * 60.0 * 31.0 / NM, 0.0, 180.0)], [NONE, NONE]),
    ([OWN, at_bearing(3.0, 180.0, 180.0)], [NONE, NONE]),
], ids=["head_on", "head_on_5_stbd", "head_on_5_port", "crossing_stbd", "crossing_port",
        "overtaking", "overtaken", "port_port_doubt", "dcpa_1_5", "tcpa_31", "opening"])
def test_textbook_encounters(ships, expected):
    assert roles(ships) == expected


def _overtaking_geometry(theta_deg: float) -> list[Ship]:
    """Ship 1 at the origin steering north at 6 kn; ship 0 (12 kn) 1 NM from her on relative
    bearing ``theta_deg`` from her bow, steering so that the relative motion points straight
    at her (DCPA 0): own velocity = v1 + k u, u the unit vector from ship 0 to ship 1, with
    |v1 + k u| = 12 kn, i.e. k = 6 cos(theta) + sqrt(36 cos^2(theta) + 108) kn."""
    th = math.radians(theta_deg)
    k = (6.0 * math.cos(th) + math.sqrt(36.0 * math.cos(th) ** 2 + 108.0)) * V / 12.0
    ux, uy = -math.cos(th), -math.sin(th)
    vn, ve = V / 2.0 + k * ux, k * uy
    assert math.hypot(vn, ve) == pytest.approx(V)
    return [(NM * math.cos(th), NM * math.sin(th), math.degrees(math.atan2(ve, vn)), V),
            (0.0, 0.0, 0.0, V / 2.0)]


@pytest.mark.parametrize(("theta", "expected"), [
    # more than 22.5 deg abaft her beam: Rule 13, whatever the side
    (112.6, [("give_way", "overtaking", "stand_on"), ("stand_on", "overtaken", "give_way")]),
    (-112.6, [("give_way", "overtaking", "stand_on"), ("stand_on", "overtaken", "give_way")]),
    (150.0, [("give_way", "overtaking", "stand_on"), ("stand_on", "overtaken", "give_way")]),
    # just forward of that line: a crossing. At +112.4 ship 0 sees ship 1 27.5 deg on her port
    # bow (ship 1 then has ship 0 on her starboard side and gives way); at -112.4 the mirror
    (112.4, [SO_CROSS, GW_CROSS]),
    (-112.4, [GW_CROSS, SO_CROSS]),
])
def test_overtaking_sector_boundary_at_112_5_degrees(theta, expected):
    assert roles(_overtaking_geometry(theta)) == expected


@pytest.mark.parametrize(("deviation", "expected"), [
    (14.9, [MUTUAL_CROSS, MUTUAL_CROSS]), (-14.9, [SO_CROSS, GW_CROSS]),
    (15.1, [MUTUAL_CROSS, MUTUAL_CROSS]), (-15.1, [SO_CROSS, GW_CROSS]),
    (9.9, [MUTUAL_HO, MUTUAL_HO]), (-9.9, [MUTUAL_HO, MUTUAL_HO])])
def test_head_on_needs_each_ship_ahead_of_the_other(deviation, expected):
    """Ship 1 dead ahead of ship 0 at 3 NM on course 180 + deviation; ship 0 lies on her bow at
    -deviation. Within 10 deg both see head-on. Beyond, ship 1 sees ship 0 off her bow, so
    neither calls it head-on (both ships see the same situation): ship 0 has her at bearing 0
    (not to starboard) and goes by how ship 1 sees her: on ship 1's port bow (+) both are in
    doubt (mutual), on her starboard bow (-) ship 1 gives way and ship 0 stands on."""
    assert roles([OWN, at_bearing(3.0, 0.0, 180.0 + deviation)]) == expected


@pytest.mark.parametrize(("course", "expected"), [
    (194.9, [MUTUAL_HO, MUTUAL_HO]), (195.1, [GW_CROSS, SO_CROSS])])
def test_head_on_reciprocal_course_boundary_at_165_degrees(course, expected):
    """Ship 1 8 deg on ship 0's starboard bow at 3 NM; ship 0 about 7 deg on her port bow (both
    within the 10 deg of head-on). Course difference 165.1 deg: head-on for both; 164.9 deg:
    a crossing, ship 0 (the other to starboard) gives way and ship 1 stands on."""
    assert roles([OWN, at_bearing(3.0, 8.0, course)]) == expected


def test_each_on_the_others_starboard_bow_is_not_a_blind_spot():
    """Reciprocal courses, each ship 14 deg on the other's starboard bow, 3 NM apart (DCPA
    3 sin 14 = 0.73 NM, TCPA 7.5 min): Rule 14(c) doubt, the mirror of the port-to-port case
    that crossing_port resolves as mutual_give_way. Rule 15 cannot make both ships the give-way
    ship with the other standing on: the decision step reports it as a blind spot."""
    ships = [OWN, at_bearing(3.0, 14.0, 180.0)]
    got = roles(ships)
    assert not (got[0][0] == got[1][0] == "give_way"), got
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, ships)
    decide(dec, 10.0, ships)
    assert dec.blind_spots == []


def test_restricted_visibility_has_no_roles_and_turns_away():
    """Rule 19 (visibility 1 NM < 2 NM): no stand-on ship. A ship forward of the beam asks for
    a starboard alteration and reduced speed; one abaft the beam to starboard asks to turn to
    port (away from her), one abaft to port to starboard."""
    def request(ships):
        dec = Decider.build(["colregs", "colregs"], np.array([0]), np.array([1]),
                            visibility_nm=1.0)
        decide(dec, 0.0, ships)
        return (NAME[float(mem(dec, "own_role")[0])], NAME[float(mem(dec, "encounter")[0])],
                NAME[float(dec.request[0, 0])], float(dec.request[2, 0]))
    rv = "restricted_visibility"
    assert request([OWN, at_bearing(6.0, 0.0, 180.0)]) == ("no_role", rv, "starboard", 0.5)
    # a 14 kn ship coming up from 1 NM on the starboard quarter (bearing 135) on course 340
    astern_stbd = at_bearing(1.0, 135.0, 340.0, 14.0 * NM / 3600.0)
    got = request([OWN, astern_stbd])
    assert got[:3] == ("no_role", rv, "port")
    astern_port = at_bearing(1.0, -135.0, 20.0, 14.0 * NM / 3600.0)
    assert request([OWN, astern_port])[:3] == ("no_role", rv, "starboard")

def _pairs_decided(ships: list[tuple[float, float, float, float]]) -> Decider:
    """One decision at t = 0 of colregs ships paired (0, 1), (2, 3), ... from rows of (north m,
    east m, course deg, speed m/s), each ship knowing the others' true motion."""
    n = len(ships)
    dec = Decider.build(["colregs"] * n, np.arange(0, n, 2), np.arange(1, n, 2))
    a = np.array(ships)
    hdg = np.radians(a[:, 2])
    own_state = np.stack([a[:, 0], a[:, 1], hdg])
    own_vel = np.stack([a[:, 3] * np.cos(hdg), a[:, 3] * np.sin(hdg)])
    other = np.concatenate([own_state[:2, dec.tgt], own_vel[:, dec.tgt]])
    dec.decide(0.0, own_state, own_vel, np.full(n, 150.0), other, hdg, a[:, 3])
    return dec



def test_both_views_agree_over_many_random_pairs():
    """500 disjoint pairs of ships steering where they head, both running the rules: a risk
    of collision is seen by both or neither; Rule 13 labels come in overtaking / overtaken
    pairs; never both stand-on; a stand-on ship's other ship is give-way or mutual give-way."""
    rng = np.random.default_rng(21)
    k = 600
    ships = []
    for _ in range(k):
        course = rng.uniform(0.0, 360.0, 2)
        speed = rng.uniform(3.0, 20.0, 2) * NM / 3600.0
        rel = rng.uniform(-3.0, 3.0, 2) * NM
        ships += [(0.0, 0.0, course[0], speed[0]), (rel[0], rel[1], course[1], speed[1])]
    dec = _pairs_decided(ships)
    role, enc = mem(dec, "own_role"), mem(dec, "encounter")
    r_role, r_enc = role[dec.reverse], enc[dec.reverse]
    assert ((role == NO_ROLE) == (r_role == NO_ROLE)).all()
    engaged = int((role != NO_ROLE).sum())
    assert engaged > 100  # the sample holds many encounters
    assert ((enc == ENC["overtaking"]) == (r_enc == ENC["overtaken"])).all()
    assert not ((role == STAND_ON) & (r_role == STAND_ON)).any()
    so = role == STAND_ON
    assert np.isin(r_role[so], [GIVE_WAY, MUTUAL_GIVE_WAY]).all()
    assert ((enc == ENC["head_on"]) <= np.isin(r_enc, [ENC["head_on"], ENC["crossing"]])).all()


def test_other_course_change_is_measured_the_short_way_across_north():
    """Ship 0 east at 12 kn gives way to ship 1 on her starboard bow steering 350. When ship 1
    then steers 010, she has changed course by 20 deg (not 340): the Rule 17(a)(ii) test
    "course changed less than not_acting_deg" must see 20."""
    d = 4.0 * NM
    ships = [(0.0, 0.0, 90.0, V), (-d, d, 350.0, V)]
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, ships)
    assert NAME[float(mem(dec, "own_role")[0])] == "give_way"
    ships[1] = (-d + 10.0 * V, d, 10.0, V)
    decide(dec, 10.0, ships)
    assert feature(dec, "other_course_change_deg")[0] == pytest.approx(20.0)
    assert feature(dec, "other_speed_change_ratio")[0] == pytest.approx(1.0)
    assert feature(dec, "time_in_role_min")[0] == pytest.approx(10.0 / 60.0)


# --------------------------------------------------------------------------------------------
# Speed orders
# --------------------------------------------------------------------------------------------

def _dcpa_m(pn: float, pe: float, wn: float, we: float) -> float:
    """Closed-form DCPA of straight tracks, |p x w| / |w| (colregs.md section 4)."""
    return abs(pn * we - pe * wn) / math.hypot(wn, we)


def test_stand_on_ship_acts_by_slowing_on_her_course_rule_17a_ii():
    """Ship 0 (keep_course) steers north from 2600 m south of the origin, ship 1 (colregs)
    west from 3600 m east of it, both 12 kn: ship 1 has ship 0 on her port side and stands on
    (Rule 15). At the next step the give-way ship has not acted and domain entry is < 10 min
    away: Rule 17(a)(ii), slow to half speed. Relative to ship 1, ship 0 is at
    p = (-2538, -3538) m; at full speed on 270 the relative velocity (V, V) passes at
    0.38 NM, at half speed (V, V/2) at |p x w| / |w| = 2029 m >= 1 NM: the speed reduction
    alone suffices, so her course order is her own course 270 at half speed."""
    dec = build(["keep_course", "colregs"])
    ships = [(-2600.0, 0.0, 0.0, V), (0.0, 3600.0, 270.0, V)]
    decide(dec, 0.0, ships)
    assert mem(dec, "own_role")[1] == STAND_ON
    assert mem(dec, "own_manoeuvre")[1] == KEEP
    assert np.isnan(dec.course_order_rad[1]) and dec.speed_factor[1] == 1.0
    moved = [(-2600.0 + 10.0 * V, 0.0, 0.0, V), (0.0, 3600.0 - 10.0 * V, 270.0, V)]
    decide(dec, 10.0, moved)
    assert feature(dec, "time_to_domain_min")[1] <= 10.0
    assert mem(dec, "own_manoeuvre")[1] == ENC["reduce_speed"]
    p = (moved[0][0] - moved[1][0], moved[0][1] - moved[1][1])
    assert _dcpa_m(*p, V, V) < NM
    assert _dcpa_m(*p, V, V / 2.0) == pytest.approx(2029.0, abs=1.0)
    assert dec.speed_factor[1] == 0.5
    assert wrap_deg(dec.course_order_rad[1]) == pytest.approx(270.0, abs=1e-9)
    assert dec.kept_distance_m[1] == pytest.approx(NM)


def test_restricted_visibility_alters_and_slows_where_both_are_safe():
    """Rule 19 head-on at TCPA 14.9 min (range R = 2 V 894 s = 11038 m), visibility 1 NM:
    each ship asks for 30 deg to starboard and half speed. At half speed on 030 the relative
    velocity is (-V - V/2 cos 30, -V/2 sin 30): DCPA = R (V/4) / |w| = 0.17186 R = 1897 m
    >= 1 NM, so 030 at half speed (and 210 for the other ship). In clear weather the same
    encounter asks for no speed reduction: 030 at full speed."""
    ships = head_on(14.9)
    R = ships[1][0]
    th = math.radians(30.0)
    assert _dcpa_m(R, 0.0, -V - 0.5 * V * math.cos(th), -0.5 * V * math.sin(th)) == \
        pytest.approx(1897.0, abs=1.0)
    fog = Decider.build(["colregs", "colregs"], np.array([0]), np.array([1]), visibility_nm=1.0)
    decide(fog, 0.0, ships)
    assert mem(fog, "encounter").tolist() == [ENC["restricted_visibility"]] * 2
    assert mem(fog, "own_manoeuvre").tolist() == [ALTER_COURSE, ALTER_COURSE]
    np.testing.assert_allclose(wrap_deg(fog.course_order_rad), [30.0, 210.0], atol=1e-9)
    np.testing.assert_array_equal(fog.speed_factor, [0.5, 0.5])
    clear = build(["colregs", "colregs"])
    decide(clear, 0.0, ships)
    np.testing.assert_allclose(wrap_deg(clear.course_order_rad), [30.0, 210.0], atol=1e-9)
    np.testing.assert_array_equal(clear.speed_factor, [1.0, 1.0])


def test_a_stopped_give_way_ship_alters_to_starboard_of_her_heading():
    """Ship 0 heads 090 (route speed 6 m/s); ship 1 comes up from 2.5 NM due south (on ship
    0's starboard beam) steering north at 12 kn, TCPA 12.5 min: Rule 15, ship 0 gives way to
    starboard. Below 0.1 m/s own course is the heading (features module), so a ship lying
    stopped and one creeping ahead at 0.2 m/s see the same encounter and must get the same
    order: 120, the least alteration asked (30 deg), which at 6 m/s passes ship 1 at
    |p x w| / |w| = 4630 x 5.196 / 10.542 = 2282 m >= 1 NM (p = (-4630, 0) m,
    w = (6.173 + 3, -5.196) m/s)."""
    w = (V + 3.0, -6.0 * math.sin(math.radians(120.0)))
    assert _dcpa_m(-2.5 * NM, 0.0, *w) == pytest.approx(2282.0, abs=1.0)
    orders = []
    for own_speed in (0.2, 0.0):
        dec = build(["colregs", "keep_course"])
        ships = [(0.0, 0.0, 90.0, own_speed), (-2.5 * NM, 0.0, 0.0, V)]
        decide(dec, 0.0, ships, route_mps=[6.0, V])
        assert feature(dec, "bearing_deg")[0] == pytest.approx(90.0)
        assert feature(dec, "course_diff_deg")[0] == pytest.approx(-90.0)
        assert mem(dec, "own_role")[0] == GIVE_WAY
        assert dec.request[0, 0] == STARBOARD
        orders.append(float(wrap_deg(dec.course_order_rad[0])))
    assert orders[0] == pytest.approx(120.0)
    assert orders[1] == pytest.approx(orders[0])


# --------------------------------------------------------------------------------------------
# Lost tracks: the limit and the observer's own rules file
# --------------------------------------------------------------------------------------------

def test_lost_track_is_kept_for_exactly_lost_track_min():
    """The encounter is forgotten when the track has been lost for LONGER than
    lost_track_min (3 min): last known at 0 s, still held at 180 s, forgotten at 180.5 s."""
    dec = build(["colregs", "colregs"])
    decide(dec, 0.0, crossing(14.0))
    assert mem(dec, "own_role")[0] == GIVE_WAY
    decide(dec, 180.0, crossing(11.0), nan_pairs=(0,))
    assert mem(dec, "own_role")[0] == GIVE_WAY
    assert mem(dec, "own_manoeuvre")[0] == ALTER_COURSE
    decide(dec, 180.5, crossing(11.0), nan_pairs=(0,))
    assert mem(dec, "own_role")[0] == NO_ROLE
    assert mem(dec, "other_role")[0] == NO_ROLE
    assert mem(dec, "own_manoeuvre")[0] == RESUME_ROUTE
    assert dec.cursor[0] == dec.start_cursor[0]


def test_each_observer_forgets_after_its_own_rules_files_limit(tmp_path):
    """Ship 0 runs a rules file that extends colregs.yaml with lost_track_min 1 and
    look_ahead_min 40; ship 1 runs turn_port.yaml (3 min, 30 min). Both lose their tracks
    after t = 0: at 70 s ship 0 has forgotten (> 60 s), ship 1 still stands on; at 190 s she
    has forgotten too. The feature look-ahead is the longest of the files (40 min)."""
    rules = tmp_path / "quick_forget.yaml"
    rules.write_text("schema_version: 1\nname: quick_forget\n"
                     f"extends: {RULES_DIR / 'colregs.yaml'}\n"
                     "parameters:\n  lost_track_min: 1.0\n  look_ahead_min: 40.0\n")
    dec = Decider.build(["colregs", "turn_port"], np.array([0]), np.array([1]), rules)
    assert dec.lost_track_s.tolist() == [60.0, 180.0]
    assert dec.horizon_s == 2400.0
    decide(dec, 0.0, crossing(14.0))
    assert mem(dec, "own_role").tolist() == [GIVE_WAY, STAND_ON]
    decide(dec, 70.0, crossing(14.0 - 70.0 / 60.0), nan_pairs=(0, 1))
    assert mem(dec, "own_role").tolist() == [NO_ROLE, STAND_ON]
    decide(dec, 190.0, crossing(14.0 - 190.0 / 60.0), nan_pairs=(0, 1))
    assert mem(dec, "own_role").tolist() == [NO_ROLE, NO_ROLE]


def test_lost_track_limit_of_a_keep_course_ship_and_a_pair_never_known():
    """A keep_course ship takes no decisions: her pairs have an infinite lost-track limit. A
    pair whose target has never been known is not 'lost': it has no last-known time, and
    gets no role."""
    dec = build(["colregs", "keep_course"])
    assert dec.lost_track_s.tolist() == [180.0, math.inf]
    decide(dec, 0.0, crossing(14.0), nan_pairs=(0,))
    decide(dec, 1000.0, crossing(14.0), nan_pairs=(0,))
    assert np.isnan(dec.last_known_s[0]) and dec.last_known_s[1] == 1000.0
    assert mem(dec, "own_role")[0] == NO_ROLE
    assert mem(dec, "own_manoeuvre")[0] == NO_ACTION


# --------------------------------------------------------------------------------------------
# Port / starboard mirror of the classification
# --------------------------------------------------------------------------------------------

def test_mirror_image_encounters_swap_only_the_crossing_roles():
    """600 random two-ship encounters and their mirror images (east and courses negated). The
    Rule 7 and 13/14 tests read distances, times and |angles|, which the mirror keeps, so the
    encounter kind is the same; Rule 15 reads the side: a give-way crossing becomes a stand-on
    crossing and back, mutual give-way stays (both ships see each other on the same side),
    and head-on / overtaking roles are kept."""
    rng = np.random.default_rng(41)
    k = 600
    course = rng.uniform(0.0, 360.0, (k, 2))
    speed = rng.uniform(3.0, 20.0, (k, 2)) * NM / 3600.0
    rel = rng.uniform(-3.0, 3.0, (k, 2)) * NM

    def run(sign: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        ships = []
        for i in range(k):
            ships += [(0.0, 0.0, sign * course[i, 0], speed[i, 0]),
                      (rel[i, 0], sign * rel[i, 1], sign * course[i, 1], speed[i, 1])]
        dec = _pairs_decided(ships)
        return (mem(dec, "own_role").copy(), mem(dec, "encounter").copy(),
                mem(dec, "other_role").copy(), feature(dec, "bearing_deg").copy())

    role, enc, other_role, bearing = run(1.0)
    m_role, m_enc, m_other_role, m_bearing = run(-1.0)
    np.testing.assert_allclose(((bearing + m_bearing + 180.0) % 360.0) - 180.0, 0.0, atol=1e-9)
    np.testing.assert_array_equal(m_enc, enc)
    swap = {GIVE_WAY: STAND_ON, STAND_ON: GIVE_WAY}
    crossing_ = enc == ENC["crossing"]
    assert ((role == GIVE_WAY) & crossing_).sum() > 20
    for mine, mirrored in ((role, m_role), (other_role, m_other_role)):
        want = np.where(crossing_, [swap.get(float(r), float(r)) for r in mine], mine)
        np.testing.assert_array_equal(mirrored, want)


# --------------------------------------------------------------------------------------------
# Resuming the route: never away from it, and only as far as it is safe (brute force)
# --------------------------------------------------------------------------------------------

SWERVE = """schema_version: 1
name: swerve
description: Alter course to starboard below 2 NM visibility; resume the route otherwise.
start: fog
nodes:
  fog:
    test: [visibility_nm, "<", 2.0]
    yes: act
    no: resume
  act:
    test: true
    action: {manoeuvre: alter_course, direction: starboard, course_change_deg: 30.0,
             pass_distance_nm: 0.5}
    yes: {to: fog, next: true}
  resume:
    test: true
    action: {manoeuvre: resume_route}
    yes: {to: fog, next: true}
"""


def test_resuming_turns_only_towards_the_route_and_keeps_the_distance(tmp_path):
    """200 disjoint groups: a 150 m ship on a route line north through the origin at 12 kn
    and three keep_course ships at random around her. In fog she alters course (30 deg or
    more to starboard, 0.5 NM kept); 60 s later, in clear weather, she resumes. Her new order
    (or, when put back on her route, the route course 000 - atan(e / 600 m)) lies between
    her order and the line's course or the route course: she never turns away from her
    route. Where she steers, the course at the speed ordered passes every ship that is
    closing at least the kept distance straight on, and at least 1.1 x that along the path
    (straight to the line, then north along it), by sampling every 0.1 s over the 30 min
    look-ahead (no code shared with the decider)."""
    rules = tmp_path / "swerve.yaml"
    rules.write_text(SWERVE)
    rng = np.random.default_rng(43)
    g, k = 200, 3
    n = g * (k + 1)
    own = np.arange(g) * (k + 1)
    others = np.setdiff1d(np.arange(n), own)
    behaviours = ["keep_course"] * n
    for o in own:
        behaviours[o] = "colregs"
    pi = np.repeat(own, k)
    pj = (own[:, None] + 1 + np.arange(k)[None, :]).ravel()
    dec = Decider.build(behaviours, pi, pj, rules)
    north, east = np.zeros(n), np.zeros(n)
    course, speed = np.zeros(n), np.full(n, V)
    r, b = rng.uniform(0.6, 3.0, others.size) * NM, rng.uniform(0, 2 * np.pi, others.size)
    north[others], east[others] = r * np.cos(b), r * np.sin(b)
    course[others] = rng.uniform(0, 2 * np.pi, others.size)
    speed[others] = rng.uniform(0.0, 9.0, others.size)

    def step(t, north, east, course, route):
        own_state = np.stack([north, east, course])
        own_vel = np.stack([speed * np.cos(course), speed * np.sin(course)])
        other = np.concatenate([own_state[:2, dec.tgt], own_vel[:, dec.tgt]])
        dec.decide(t, own_state, own_vel, np.full(n, 150.0), other, route, np.full(n, V))

    dec.visibility_nm = 1.0
    step(0.0, north, east, course, course.copy())
    first = dec.course_order_rad[own].copy()
    assert np.isfinite(first).all()
    kept = dec.kept_distance_m[own].copy()
    np.testing.assert_allclose(kept, 0.5 * NM)
    course2 = course.copy()
    course2[own] = first
    north2, east2 = north + speed * np.cos(course2) * 60.0, east + speed * np.sin(course2) * 60.0
    route = course2.copy()
    route[own] = -np.arctan(east2[own] / 600.0)
    dec.visibility_nm = 10.0
    step(60.0, north2, east2, course2, route)
    new, factor, cand = (dec.course_order_rad[own], dec.speed_factor[own], dec.candidate[own])
    assert (mem(dec, "own_manoeuvre")[: g * k] == RESUME_ROUTE).all()  # the own ships' pairs
    released = np.isnan(new) & (cand < 0)
    assert (factor[released] == 1.0).all()
    assert 20 < released.sum() < g - 20  # both outcomes occur

    def wrap(a):
        return (a + math.pi) % (2 * math.pi) - math.pi

    t = np.arange(0.0, dec.horizon_s + 0.05, 0.1)
    steered = 0
    for i in range(g):
        o = own[i]
        c = route[o] if np.isnan(new[i]) else new[i]
        d = wrap(c - first[i])
        towards = [wrap(target - first[i]) for target in (0.0, route[o])]
        assert abs(d) < 1e-12 or any(np.sign(d) == np.sign(w) and abs(d) <= abs(w) + 1e-9
                                     for w in towards), (i, np.degrees([first[i], c]))
        if not np.isnan(new[i]) and new[i] == first[i]:
            continue  # no safe candidate: she keeps her order (nothing more to check)
        steered += 1
        v = V * factor[i]
        across = v * math.sin(c)
        meet = -east2[o] / across if east2[o] * across < 0.0 else math.inf
        t1 = np.minimum(t, meet)
        path_n = north2[o] + v * math.cos(c) * t1 + v * (t - t1)
        path_e = east2[o] + across * t1
        line_n, line_e = north2[o] + v * math.cos(c) * t, east2[o] + v * math.sin(c) * t
        j1 = int(np.searchsorted(t, meet))
        for j in o + 1 + np.arange(k):
            qn = north2[j] + speed[j] * math.cos(course2[j]) * t
            qe = east2[j] + speed[j] * math.sin(course2[j]) * t
            straight = np.hypot(qn - line_n, qe - line_e)
            if straight[1] < straight[0]:
                assert straight.min() >= kept[i] - 1e-6, (i, j)
            path = np.hypot(qn - path_n, qe - path_e)
            if path[1] < path[0]:
                assert path[: max(j1, 2)].min() >= kept[i] * (1 + RESUME_MARGIN) - 1e-6, (i, j)
            if j1 < t.size - 2 and path[j1 + 1] < path[j1]:
                assert path[j1:].min() >= kept[i] * (1 + RESUME_MARGIN) - 1e-6, (i, j)
    assert steered > 50
