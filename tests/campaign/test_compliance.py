"""Woerner-style grades on constructed encounters, through the engine."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from trafficsim.batch import EncounterEnv, ShipSetup, build_batch
from trafficsim.campaign.compliance import MIRROR, RULE_OF_KIND, PairObserver, grade
from trafficsim.campaign.compliance import _observe as _observe_kernel
from trafficsim.campaign.generator import classify
from trafficsim.colregs.decider import Decider
from trafficsim.colregs.vocabulary import (
    ENUMS,
    GIVE_WAY,
    MANOEUVRES,
    MEMORY,
    MUTUAL_GIVE_WAY,
    NO_ROLE,
    STAND_ON,
)
from trafficsim.engine import Simulation
from trafficsim.ships.base import EAST, N_STATE, NORTH, PSI, Env, U
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn


def _observe(ships, steps=1500):
    spec = load_ship("cargo")
    setups = [ShipSetup(f"s{k}", spec, 0, n, e, math.radians(h), from_kn(12.0),
                        np.array([route]) if route else np.zeros((0, 2)), k)
              for k, (n, e, h, route) in enumerate(ships)]
    sim = Simulation.start(build_batch(setups, [EncounterEnv()]), 1.0)
    obs = PairObserver.start(sim)
    for _ in range(steps // 10):
        sim.run(10)
        obs.observe(sim)
    return obs


def test_a_safe_starboard_turn_grades_high_and_standing_on_into_a_collision_zero():
    # ship 0 north-bound; ship 1 crossing from starboard, meeting at (6000, 0) after ~970 s
    crossing = (6000.0, 6000.0, 270.0, None)
    late = _observe([(0.0, 0.0, 0.0, None), crossing])
    g = grade(late)
    assert late.closest_m[0] < 200.0
    assert g[16][0] == 0.0 and g[15][0] == 0.0  # no manoeuvre and a collision range
    turned = _observe([(0.0, 0.0, 0.0, (3000.0, 4000.0)), crossing])
    g = grade(turned)
    assert math.degrees(turned.stbd_cpa[0]) > 30.0
    assert turned.range_at_manoeuvre_m[0] > 0.5 * turned.range0_m[0]
    assert not turned.crossed_ahead[0]
    assert g[16][0] > 0.5
    assert g[16][0] > grade(late)[16][0]


def test_crossing_ahead_is_detected_and_penalised():
    # ship 0 passes 1 km ahead of ship 1 (she crosses ahead of ship 1's bow)
    obs = _observe([(0.0, 0.0, 0.0, None), (4000.0, 4500.0, 270.0, None)])
    assert obs.crossed_ahead[0] and not obs.crossed_ahead[1]
    g = grade(obs)
    assert g[15][0] == pytest.approx(max(0.0, g[16][0] - 0.5))


def test_head_on_port_to_port_beats_starboard_to_starboard():
    """Reciprocal courses 800 m apart, neither turning: P_nsb = 1 and P_delay = 1; port to port
    P_sts = 0, so (1 - 0.6 - 0.2) (1 - 0.5) = 0.1; starboard to starboard P_sts = 1: 0."""
    ptp = grade(_observe([(0.0, 0.0, 0.0, None), (8000.0, -800.0, 180.0, None)]))
    sts = grade(_observe([(0.0, 0.0, 0.0, None), (8000.0, 800.0, 180.0, None)]))
    assert ptp[14][0] == pytest.approx(0.1, abs=0.01)
    assert sts[14][0] == 0.0


# --------------------------------------------------------------------------------------------
# grade() on observers built field by field: every term of colregs.md section 2.4 by hand
# --------------------------------------------------------------------------------------------

U0 = 6.0


def _fields(m=1, **over):
    """A PairObserver of ``m`` directed pairs whose own ship sails at ``U0`` and which, unless
    overridden, saw: start range 8000 m, closest 1500 m, both ships abeam of each other at the
    closest point (alpha = beta = 90 deg), a first manoeuvre at the start range, and a 40 deg
    starboard turn (so P_delay = 0 and P_na = 0); all ships at the origin, at rest over ground,
    running no rules."""
    x0 = np.zeros((N_STATE, 2 * m))
    x0[U] = U0
    own, tgt = np.arange(m), np.arange(m, 2 * m)

    def full(v):
        return np.full(m, float(v))

    values = dict(range0_m=full(8000.0), closest_m=full(1500.0),
                  alpha_cpa=full(math.pi / 2), beta_cpa=full(math.pi / 2),
                  stbd_rad=full(math.radians(40)), port_rad=full(0.0), faster_mps=full(0.0),
                  slower_mps=full(0.0), stbd_cpa=full(math.radians(40)), port_cpa=full(0.0),
                  faster_cpa=full(0.0), slower_cpa=full(0.0),
                  range_at_manoeuvre_m=full(8000.0), manoeuvre_cpa_m=full(8000.0),
                  side=full(1.0), ahead=full(0.0),
                  crossed_ahead=np.zeros(m, dtype=bool), runs_rules=np.zeros(m, dtype=bool),
                  first_role=full(math.nan), first_encounter=full(math.nan))
    for k, v in over.items():
        values[k] = np.broadcast_to(np.asarray(v, dtype=values[k].dtype), (m,)).copy()
    return PairObserver(own, tgt, x0, **values, asked=np.zeros((m, len(MANOEUVRES)), bool),
                        fired=np.zeros((m, 0), bool), node_names=[],
                        net_of_pair=np.full(m, -1), v0=np.zeros((2, 2 * m)))


@pytest.mark.parametrize("r_cpa, s_r", [
    (5000.0, 1.0), (1000.0, 1.0),
    (900.0, 0.8),  # 1 - 0.4 (1000 - 900) / (1000 - 800)
    (800.0, 0.6),  # 1 - 0.4, both branches agree at R_nm
    (500.0, 0.3),  # 1 - 0.4 - 0.6 (800 - 500) / (800 - 200)
    (200.0, 0.0), (199.0, 0.0), (0.0, 0.0),
])
def test_range_term_is_the_piecewise_linear_woerner_ramp(r_cpa, s_r):
    """With P_delay = P_na = 0, S16 is the safety score 0.5 s_r + 0.5 s_theta; abeam of each
    other (alpha = beta = 90 deg) s_theta = (1 - cos 90)(1 - cos 90) / 2 = 0.5."""
    g = grade(_fields(closest_m=r_cpa))
    assert g[16][0] == pytest.approx(0.5 * s_r + 0.25, abs=1e-12)


def test_range_term_is_continuous_at_its_breakpoints():
    """Just above and below R_min, R_nm and R_col the score differs by O(eps) only."""
    eps = 1e-6
    r = np.array([b + d for b in (1000.0, 800.0, 200.0) for d in (-eps, eps)])
    g = grade(_fields(m=r.size, closest_m=r))[16]
    assert np.all(np.abs(g[0::2] - g[1::2]) < 1e-5)


def test_pose_term_extremes():
    """Each ship astern of the other's beam at the closest point: (1 - cos 90)(1 - cos 180)
    / 2 = 1, so safety 1; each ship dead ahead of the other (bows pointing at each other):
    1 - cos 0 = 0, so safety = 0.5 s_r = 0.5."""
    g = grade(_fields(m=2, alpha_cpa=[math.pi, 0.0], beta_cpa=[math.pi, 0.0]))[16]
    assert g == pytest.approx([1.0, 0.5], abs=1e-12)


def test_own_ship_dead_ahead_of_the_other_at_cpa_has_no_pose_credit():
    """colregs.md 2.4: s_theta = (1 - cos alpha)(1 - cos beta) with alpha = bearing of the own
    ship from the other's bow, clipped at 90 deg. Own ship dead ahead of the other's bow at the
    closest point (``alpha_cpa`` = 0, the other on the own starboard beam) gives
    1 - cos 0 = 0, so S16 = 0.5 s_r + 0 = 0.5 (NTNU's AutoVerification also gives 0); the
    mirror case, the other ship dead ahead of the own bow and the own ship on her starboard
    beam, has beta clipped up to 90 deg: (1 - cos 90)(1 - cos 90) / 2 = 0.5, S16 = 0.75."""
    g = grade(_fields(m=2, alpha_cpa=[0.0, math.pi / 2], beta_cpa=[math.pi / 2, 0.0]))
    assert g[16] == pytest.approx([0.5, 0.75], abs=1e-12)


def test_pose_angles_are_taken_modulo_a_turn():
    """alpha and beta are stored unwrapped (atan2 minus heading): adding whole turns must not
    change any score."""
    a = _fields(m=3, alpha_cpa=[0.3, 2.0, -2.5], beta_cpa=[4.0, -1.0, 2.8],
                closest_m=[900.0, 1200.0, 300.0])
    b = _fields(m=3, alpha_cpa=[0.3 + 2 * np.pi, 2.0 - 4 * np.pi, -2.5 + 2 * np.pi],
                beta_cpa=[4.0 - 2 * np.pi, -1.0 + 2 * np.pi, 2.8 + 6 * np.pi],
                closest_m=[900.0, 1200.0, 300.0])
    ga, gb = grade(a), grade(b)
    for r in (13, 14, 15, 16, 17):
        np.testing.assert_allclose(ga[r], gb[r], atol=1e-12)


def test_give_way_early_and_substantial_beats_late_and_small():
    """Start 8000 m, closest 1500 m (s_r = 1), abeam (s_theta = 0.5): safety 0.75. The delay
    runs from detection at 5000 m (colregs.md's stage-2 range).
    Early, 35 deg at 7600 m, before detection: P_delay = 0, P_na = 0 -> 0.75.
    Late, 10 deg at 2000 m, speed kept: P_delay = 3000 / 3500; P_na_course =
    0.5 (1 - 100/900) = 4/9 and P_na_speed = 0.5, both >= 0.3, P_na = 2/9
    -> 0.75 (500/3500)(7/9)."""
    obs = _fields(m=2, stbd_cpa=np.radians([35.0, 10.0]), manoeuvre_cpa_m=[7600.0, 2000.0])
    g = grade(obs)
    early = 0.75
    late = 0.75 * (500 / 3500) * (7 / 9)
    assert g[16] == pytest.approx([early, late], abs=1e-12)
    assert g[15] == pytest.approx([early, late], abs=1e-12)  # neither crossed ahead
    assert g[13] == pytest.approx([early, late], abs=1e-12)


def test_the_delay_runs_from_detection_not_from_the_start():
    """The same 35 deg turn at 4000 m towards a ship passing at 1500 m scores alike whether the
    run starts 6, 8 or 12 km apart (before, the longer run scored better): the delay runs from
    the 5000 m detection range, P_delay = 1000 / 3500; a run starting at 4500 m counts from
    there, P_delay = 500 / 3000."""
    obs = _fields(m=4, range0_m=[6000.0, 8000.0, 12000.0, 4500.0],
                  stbd_cpa=np.radians([35.0] * 4), manoeuvre_cpa_m=[4000.0] * 4)
    g = grade(obs)[16]
    assert g == pytest.approx([0.75 * (1 - 1000 / 3500)] * 3 + [0.75 * (1 - 500 / 3000)],
                              abs=1e-12)


def test_no_manoeuvre_gives_full_delay_penalty():
    """No manoeuvre at all: r_man is taken as r_cpa, P_delay = 1 and S16 = 0 whatever the
    range."""
    g = grade(_fields(manoeuvre_cpa_m=np.nan, stbd_cpa=0.0, stbd_rad=0.0))
    assert g[16][0] == 0.0 and g[15][0] == 0.0 and g[13][0] == 0.0


@pytest.mark.parametrize("course_deg, kept, p_na", [
    (10.0, 1.0, (4 / 9) * 0.5),  # both terms >= 0.3
    (19.0, 1.0, 0.0),  # P_na_course = 0.5 (1 - 361/900) = 0.2994 < 0.3 -> 0
    (10.0, 0.79, 0.0),  # P_na_speed = 0.29 < 0.3 -> 0
    (10.0, 0.9, (4 / 9) * 0.4),
    (30.0, 1.0, 0.0),  # a 30 deg turn is readily apparent
])
def test_non_apparent_manoeuvre_penalty(course_deg, kept, p_na):
    """P_na = P_na_course P_na_speed unless either is below 0.3 (Minne's variant);
    P_na_course = 0.5 max(0, 1 - dchi^2 / 30^2), P_na_speed = kept - 0.5 for the share of the
    start speed kept above a half."""
    obs = _fields(stbd_cpa=math.radians(course_deg), slower_cpa=U0 * (1 - kept))
    assert grade(obs)[16][0] == pytest.approx(0.75 * (1 - p_na), abs=1e-12)


def test_a_port_turn_counts_as_a_course_change_for_the_apparent_test():
    """Rule 16 asks for a substantial change, not a side: Delta chi_max is the larger of the
    starboard and port changes."""
    a = grade(_fields(stbd_cpa=0.0, port_cpa=math.radians(40)))
    assert a[16][0] == pytest.approx(0.75, abs=1e-12)


def test_crossing_ahead_penalties_and_clipping():
    """S15 = S16 - 0.5 when the own ship crossed the other's bow line ahead of her; clipped
    at 0. Rule 13 does not look at the bow line: a crossing ahead away from the CPA costs
    nothing there."""
    g = grade(_fields(m=2, crossed_ahead=[True, True], closest_m=[1500.0, 200.0]))
    # safety 0.75 for the first; 0.5 * 0 + 0.25 = 0.25 for the second
    assert g[16] == pytest.approx([0.75, 0.25], abs=1e-12)
    assert g[15] == pytest.approx([0.25, 0.0], abs=1e-12)
    assert g[13] == pytest.approx(g[16], abs=1e-12)


@pytest.mark.parametrize("alpha_deg, penalised", [
    (0.0, True), (44.9, True), (-44.9, True), (45.0, False), (-45.0, False), (90.0, False),
    (315.1, True), (180.0, False)])
def test_rule_13_penalises_a_closest_point_ahead_of_the_overtaken_ship(alpha_deg, penalised):
    """S13 = S16 - 0.3 when the own ship is within 45 deg of the other's bow at the CPA
    (colregs.md section 2.4), whether or not it crossed her bow line; clipped at 0."""
    g = grade(_fields(m=2, alpha_cpa=math.radians(alpha_deg), closest_m=[1500.0, 200.0],
                      crossed_ahead=[False, True]))
    assert g[13] == pytest.approx(np.clip(g[16] - 0.3 * penalised, 0.0, 1.0), abs=1e-12)
    assert g[13][1] == pytest.approx(0.0 if penalised else g[16][1], abs=1e-12)


def test_head_on_grades_by_hand():
    """S14 = (1 - 0.6 P_nsb - 0.2 P_delay - P_sts)(1 - P_na_course), port to port at the
    closest point (alpha = beta = 270 deg clockwise: sin of the ccw angle 90 deg is 1, so
    P_sts = 0):
    * 25 deg to starboard at the start: P_nsb = 0, P_delay = 0,
      P_na_course = 0.5 (1 - 625/900) -> 1 - 0.5 * 275/900;
    * 10 deg to starboard: P_nsb = (1 - 10/20)^4 = 1/16, P_na_course = 4/9
      -> (1 - 0.6/16)(5/9);
    * 25 deg to port: no starboard change, P_nsb = 1 -> 0.4 (1 - 0.5 * 275/900);
    * 20 deg to starboard exactly: P_nsb = 0 -> 1 - 0.5 (1 - 400/900)."""
    stbd = np.radians([25.0, 10.0, 0.0, 20.0])
    port = np.radians([0.0, 0.0, 25.0, 0.0])
    obs = _fields(m=4, alpha_cpa=1.5 * math.pi, beta_cpa=1.5 * math.pi, stbd_cpa=stbd,
                  port_cpa=port)
    pna25 = 0.5 * 275 / 900
    expected = [1 - pna25, (1 - 0.6 / 16) * (5 / 9), 0.4 * (1 - pna25), 1 - 0.5 * 500 / 900]
    assert grade(obs)[14] == pytest.approx(expected, abs=1e-12)


def test_head_on_starboard_to_starboard_and_delay():
    """Starboard to starboard (alpha = beta = 90 deg clockwise, ccw -90: sin = -1): P_sts = 1,
    the score is 0 even after a good turn; port to port with no manoeuvre at all:
    (1 - 0.6 - 0.2)(1 - 0.5) = 0.1 (the value the engine test reaches)."""
    sts = _fields(alpha_cpa=math.pi / 2, beta_cpa=math.pi / 2, stbd_cpa=math.radians(40))
    assert grade(sts)[14][0] == 0.0
    idle = _fields(alpha_cpa=-math.pi / 2, beta_cpa=-math.pi / 2, stbd_cpa=0.0,
                   manoeuvre_cpa_m=np.nan)
    assert grade(idle)[14][0] == pytest.approx(0.1, abs=1e-12)


@pytest.mark.parametrize("over, expected", [
    ({}, 0.75),  # keeps course and speed: S17 = safety
    ({"stbd_cpa": math.radians(1.9)}, 0.75),  # under the 2 deg detectable change
    ({"stbd_cpa": math.radians(16.0)}, 0.75 - 0.25),  # 0.5 (16 - 2) / 28
    ({"port_cpa": math.radians(30.0)}, 0.75 - 0.5),
    ({"stbd_cpa": math.radians(60.0)}, 0.25),  # capped at 0.5
    ({"faster_cpa": 2.0}, 0.75 * (6 / 8) ** 2),  # P_up = (v0 / v_max)^2, v_max = 8
    ({"faster_cpa": 0.2}, 0.75),  # 0.2 m/s is not over the threshold
    ({"slower_cpa": 3.0}, 0.75 - 0.5 * 3 / 6),  # P_down = 0.5 dv / v0
    ({"slower_cpa": 0.19}, 0.75),
    ({"stbd_cpa": math.radians(16.0), "faster_cpa": 2.0, "slower_cpa": 1.0},
     (0.75 - 0.25) * (6 / 8) ** 2 - 0.5 / 6),
])
def test_stand_on_grades_by_hand(over, expected):
    """S17 = (S - P_course) P_up - P_down (Woerner), own speed 6 m/s, safety 0.75."""
    obs = _fields(**{"stbd_cpa": 0.0, **over})
    assert grade(obs)[17][0] == pytest.approx(expected, abs=1e-12)


def test_stand_on_keeping_course_is_graded_on_safety_alone_and_give_way_not():
    """A ship that never manoeuvres keeps the Rule 17 score of its safety while its Rule 16
    score is 0 (full delay): the same track, judged for the two roles."""
    obs = _fields(m=2, stbd_cpa=0.0, manoeuvre_cpa_m=np.nan, closest_m=[1500.0, 900.0])
    g = grade(obs)
    assert g[17] == pytest.approx([0.75, 0.5 * 0.8 + 0.25], abs=1e-12)
    assert np.all(g[16] == 0.0)


def test_every_score_lies_in_the_unit_interval():
    """Random observations, including collisions, big speed changes and NaN manoeuvre ranges:
    every rule's score stays in [0, 1]."""
    rng = np.random.default_rng(3)
    m = 2000
    obs = _fields(m=m, closest_m=rng.uniform(0, 3000, m),
                  range0_m=rng.uniform(500, 12000, m),
                  alpha_cpa=rng.uniform(-10, 10, m), beta_cpa=rng.uniform(-10, 10, m),
                  stbd_cpa=rng.uniform(0, 3, m), port_cpa=rng.uniform(0, 3, m),
                  faster_cpa=rng.uniform(0, 5, m), slower_cpa=rng.uniform(0, 8, m),
                  manoeuvre_cpa_m=np.where(rng.random(m) < 0.3, np.nan,
                                                rng.uniform(0, 12000, m)),
                  crossed_ahead=rng.random(m) < 0.5)
    for r, s in grade(obs).items():
        assert s.shape == (m,) and np.all((s >= 0.0) & (s <= 1.0)), r


# --------------------------------------------------------------------------------------------
# scores(): which directed pair's grade each column holds
# --------------------------------------------------------------------------------------------

def _pair(**over):
    """One undirected pair as two directed pairs (i -> j, j -> i) with different grades."""
    base = dict(closest_m=[1500.0, 1500.0], stbd_cpa=np.radians([40.0, 12.0]),
                manoeuvre_cpa_m=[8000.0, 5000.0], faster_cpa=[0.0, 1.0])
    base.update(over)
    return _fields(m=2, **base)


@pytest.mark.parametrize("kind", ["crossing_give_way", "crossing_stand_on", "overtaking",
                                  "overtaken", "head_on", "crossing_mutual"])
def test_scores_take_each_ship_by_the_rule_of_its_part(kind):
    """Ship i is graded by the rule of ``kind``, ship j by the rule of the mirrored kind
    (give-way <-> stand-on, overtaking <-> overtaken, head-on and the mutual give-way crossing
    both Rule 14); each ``score_ruleN`` column holds the ship the rule binds, where it binds
    both the lower of the two."""
    obs = _pair()
    g = grade(obs)
    out = obs.scores([kind, MIRROR[kind]])
    ri, rj = RULE_OF_KIND[kind], RULE_OF_KIND[MIRROR[kind]]
    assert out["compliance_i"][0] == pytest.approx(g[ri][0])
    assert out["compliance_j"][0] == pytest.approx(g[rj][1])
    for r in (13, 15, 17):
        bound = [s for s, rule in ((0, ri), (1, rj)) if rule == r]
        if bound:
            assert out[f"score_rule{r}"][0] == pytest.approx(g[r][bound[0]])
        else:
            assert np.isnan(out[f"score_rule{r}"][0])
    if ri == 14:
        assert out["score_rule14"][0] == pytest.approx(min(g[14]))
    else:
        assert np.isnan(out["score_rule14"][0])


def test_head_on_rule16_column_is_the_lower_of_the_two_ships():
    """Head-on, Rule 16 binds both ships (both give way): its column is the lower score,
    whichever ship of the pair has it, as for Rule 14."""
    for stbd in ([40.0, 12.0], [12.0, 40.0]):
        obs = _pair(stbd_cpa=np.radians(stbd))
        g = grade(obs)
        assert g[16][0] != g[16][1]
        assert obs.scores(["head_on"] * 2)["score_rule16"][0] == pytest.approx(min(g[16]))


def test_scores_of_an_unknown_kind_are_nan():
    out = _pair().scores(["no_such_kind"] * 2)
    assert np.isnan(out["compliance_i"][0]) and np.isnan(out["compliance_j"][0])
    assert all(np.isnan(out[f"score_rule{r}"][0]) for r in (13, 14, 15, 16, 17))


# --------------------------------------------------------------------------------------------
# PairObserver.observe on hand-made kinematic tracks (no engine)
# --------------------------------------------------------------------------------------------

def _track(n0, e0, legs, t):
    """North, east, heading (rad) and speed at time ``t`` of a ship starting at (n0, e0) and
    sailing ``legs`` = [(from_s, heading_deg, speed_mps), ...] (the first from 0)."""
    n, e = n0, e0
    ends = [leg[0] for leg in legs[1:]] + [math.inf]
    psi, speed = math.radians(legs[0][1]), legs[0][2]
    for (start, heading, u), end in zip(legs, ends, strict=True):
        if t < start or (t == start and start > 0):
            break
        psi, speed = math.radians(heading), u
        run = min(t, end) - start
        n += u * run * math.cos(psi)
        e += u * run * math.sin(psi)
    return n, e, psi, speed


def _state(ships, t):
    x = np.zeros((N_STATE, len(ships)))
    for k, (n0, e0, legs) in enumerate(ships):
        x[NORTH, k], x[EAST, k], x[PSI, k], x[U, k] = _track(n0, e0, legs, t)
    return x


def _sim(x):
    return SimpleNamespace(batch=SimpleNamespace(x=x, pair_i=np.array([0]),
                                                 pair_j=np.array([1]), env=Env(),
                                                 behaviours=["keep_course"] * 2),
                           decider=None)


def _run(ships, end_s=2000, every_s=10):
    obs = PairObserver.start(_sim(_state(ships, 0.0)))
    times = np.arange(every_s, end_s + every_s / 2, every_s, dtype=float)
    states = [_state(ships, t) for t in times]
    for x in states:
        obs.observe(_sim(x))
    return obs, times, states


# own ship north-bound from the origin at 6 m/s; a ship crossing from starboard, west-bound
# at 6 m/s from (6000, 6000): both reach (6000, 0) at t = 1000 s if nobody manoeuvres
OWN_STRAIGHT = (0.0, 0.0, [(0.0, 0.0, 6.0)])
CROSSER = (6000.0, 6000.0, [(0.0, 270.0, 6.0)])


def _bearings(x, o, t):
    dn, de = x[NORTH, t] - x[NORTH, o], x[EAST, t] - x[EAST, o]
    return math.atan2(de, dn) - x[PSI, o], math.atan2(-de, -dn) - x[PSI, t], math.hypot(dn, de)


def test_observer_records_the_closest_sample_and_the_first_manoeuvre():
    """Own ship turns 40 deg to starboard at t = 95 s and slows from 6 to 4 m/s at 300 s:
    every recorded quantity is checked against the sampled tracks directly."""
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 40.0, 6.0), (300.0, 40.0, 4.0)])
    obs, times, states = _run([own, CROSSER])
    ranges = [_bearings(x, 0, 1)[2] for x in states]
    k = int(np.argmin(ranges))
    assert obs.closest_m[0] == pytest.approx(ranges[k]) == obs.closest_m[1]
    assert obs.range0_m[0] == pytest.approx(math.hypot(6000.0, 6000.0))
    a, b, _ = _bearings(states[k], 0, 1)
    # alpha: the own ship seen from the other's bow; beta: the other seen from the own bow
    assert math.remainder(obs.alpha_cpa[0] - b, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    assert math.remainder(obs.beta_cpa[0] - a, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    # the turn is first seen at the sample t = 100 s
    assert obs.range_at_manoeuvre_m[0] == pytest.approx(ranges[list(times).index(100.0)])
    assert obs.manoeuvre_cpa_m[0] == obs.range_at_manoeuvre_m[0]  # made before the CPA
    assert math.degrees(obs.stbd_cpa[0]) == pytest.approx(40.0)
    assert obs.port_cpa[0] == 0.0 and obs.faster_cpa[0] == 0.0
    assert obs.slower_cpa[0] == pytest.approx(2.0 if times[k] >= 300 else 0.0)
    # the crossing ship held course and speed
    assert math.isnan(obs.range_at_manoeuvre_m[1])
    assert obs.stbd_cpa[1] == obs.port_cpa[1] == obs.slower_cpa[1] == 0.0


def test_give_way_turning_early_grades_higher_than_turning_late():
    """The same 40 deg starboard turn at 100 s and at 700 s: later means a larger P_delay and a
    closer CPA, never a better Rule 16/15 score; standing on into the collision scores 0."""
    early = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 40.0, 6.0)])
    late = (0.0, 0.0, [(0.0, 0.0, 6.0), (695.0, 40.0, 6.0)])
    g_early = grade(_run([early, CROSSER])[0])
    g_late = grade(_run([late, CROSSER])[0])
    g_none = grade(_run([OWN_STRAIGHT, CROSSER])[0])
    assert g_early[16][0] > g_late[16][0] > g_none[16][0] == 0.0
    assert g_early[15][0] > g_late[15][0]


def test_crossing_ahead_is_seen_for_the_ship_that_crossed_only():
    """Crosser west-bound at 6 m/s from (4000, 4500): the own ship reaches the crosser's bow
    line (north 4000) at 667 s with the crosser 500 m east of her, heading west: the own ship
    crossed ahead. From (6000, 3000) the crosser reaches the own track (east 0) at 500 s with
    the own ship at north 3000, 3 km astern of her: the crosser crossed ahead; the own ship
    later passes 3 km behind the crosser's stern."""
    own_ahead, _, _ = _run([OWN_STRAIGHT, (4000.0, 4500.0, [(0.0, 270.0, 6.0)])], end_s=1500)
    assert own_ahead.crossed_ahead.tolist() == [True, False]
    other_ahead, _, _ = _run([OWN_STRAIGHT, (6000.0, 3000.0, [(0.0, 270.0, 6.0)])],
                             end_s=1500)
    assert other_ahead.crossed_ahead.tolist() == [False, True]


def test_observer_is_symmetric_in_the_pair_order():
    """Swapping which ship is ``pair_i`` swaps the halves of every per-directed-pair array."""
    obs, _, _ = _run([OWN_STRAIGHT, CROSSER], end_s=1200)
    swapped, _, _ = _run([CROSSER, OWN_STRAIGHT], end_s=1200)
    for name in ("closest_m", "alpha_cpa", "beta_cpa", "stbd_cpa", "range_at_manoeuvre_m",
                 "crossed_ahead"):
        a, b = getattr(obs, name), getattr(swapped, name)
        np.testing.assert_array_equal(a, b[::-1], err_msg=name)


def test_observe_kernel_is_the_method():
    """The compiled loop called directly on the same samples gives the same fields."""
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 30.0, 6.0)])
    obs, _, states = _run([own, CROSSER], end_s=800)
    ref = PairObserver.start(_sim(_state([own, CROSSER], 0.0)))
    for x in states:
        _observe_kernel(x, ref.x0, ref.own, ref.tgt, ref.active, ref.closest_m, ref.alpha_cpa,
                        ref.beta_cpa, ref.stbd_rad, ref.port_rad, ref.faster_mps,
                        ref.slower_mps, ref.stbd_cpa, ref.port_cpa, ref.faster_cpa,
                        ref.slower_cpa, ref.range_at_manoeuvre_m, ref.manoeuvre_cpa_m,
                        ref.side, ref.ahead, ref.crossed_ahead)
    for name in ("closest_m", "alpha_cpa", "stbd_cpa", "range_at_manoeuvre_m", "manoeuvre_cpa_m",
                 "side", "ahead", "crossed_ahead"):
        np.testing.assert_array_equal(getattr(obs, name), getattr(ref, name))


def test_a_manoeuvre_after_the_cpa_does_not_lessen_the_delay_penalty():
    """The own ship stands on through the CPA (range ~1 km at t = 1000 s with a slower
    crosser) and turns only afterwards: the whole range from the start to the CPA was run
    before its first manoeuvre, so P_delay = 1 and S16 = S15 = 0, as for no manoeuvre."""
    crosser = (5000.0, 6000.0, [(0.0, 270.0, 6.0)])
    idle = grade(_run([OWN_STRAIGHT, crosser])[0])
    after = (0.0, 0.0, [(0.0, 0.0, 6.0), (1495.0, 40.0, 6.0)])
    obs = _run([after, crosser])[0]
    assert obs.range_at_manoeuvre_m[0] > obs.closest_m[0]  # turned after the closest sample
    assert idle[16][0] == 0.0
    assert grade(obs)[16][0] == 0.0


def test_head_on_starboard_turn_beats_port_turn():
    """Reciprocal courses, the other ship 300 m on the own port bow at 8 km: a 30 deg turn to
    starboard at 95 s passes port to port (alpha and beta near 270 deg, P_sts ~ 0, P_nsb = 0),
    a 30 deg turn to port crosses the other's bow (P_nsb = 1 and a starboard-to-starboard or
    close passing)."""
    other = (8000.0, -300.0, [(0.0, 180.0, 6.0)])
    stbd = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 30.0, 6.0)])
    port = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 330.0, 6.0)])
    obs_s, _, _ = _run([stbd, other], end_s=1200)
    obs_p, _, _ = _run([port, other], end_s=1200)
    assert math.degrees(obs_s.stbd_cpa[0]) == pytest.approx(30.0)
    assert obs_p.stbd_cpa[0] == 0.0 and math.degrees(obs_p.port_cpa[0]) == pytest.approx(30.0)
    b = math.degrees(obs_s.beta_cpa[0]) % 360.0
    assert 200.0 < b < 340.0  # the other ship passes on the own port side
    g_s, g_p = grade(obs_s)[14][0], grade(obs_p)[14][0]
    # 30 deg is apparent (P_na_course = 0) and made at the start (P_delay ~ 0)
    p_sts = 1 - ((np.sin(-obs_s.alpha_cpa[0]) + 1) / 2) ** 2 * (
        (np.sin(-obs_s.beta_cpa[0]) + 1) / 2) ** 2
    detect = min(obs_s.range0_m[0], 5000.0)
    p_delay = max(0.0, (detect - obs_s.range_at_manoeuvre_m[0]) / (detect - obs_s.closest_m[0]))
    assert g_s == pytest.approx(1.0 - 0.2 * p_delay - p_sts, abs=1e-9)
    assert g_s > 0.8 and g_p <= 0.4 + 1e-12  # 1 - 0.6 P_nsb at best


def test_crossing_ahead_between_two_samples_is_still_seen():
    """Both ships at 10 m/s, samples every 60 s (a decision period a spec may set). The own
    ship reaches the crosser's bow line (north 3000) at t = 305 s with the crosser 250 m east
    of her, heading west: she crosses 250 m ahead of the crosser. Sampled at 300 s (own short
    of the line) and 360 s (own past it, the crosser 300 m beyond the own track): the sign of
    the side changes between the two, and the crossing point was ahead of the crosser."""
    own = (-50.0, 0.0, [(0.0, 0.0, 10.0)])
    crosser = (3000.0, 3300.0, [(0.0, 270.0, 10.0)])
    dense, _, _ = _run([own, crosser], end_s=720, every_s=1)
    assert dense.crossed_ahead[0]
    coarse, _, _ = _run([own, crosser], end_s=720, every_s=60)
    assert coarse.crossed_ahead[0]


# --------------------------------------------------------------------------------------------
# hand-worked tracks: every term of the grade, from the sampled positions directly
# --------------------------------------------------------------------------------------------

def _by_hand(ships, end_s=2000, every_s=10):
    """What the observer should have seen of ship 0 towards ship 1, worked out here in plain
    Python from the track function (first smallest sampled range; course and speed changes
    from the start; first sample with a turn over 5 deg or a speed change over 0.2 m/s)."""
    n0, e0, psi0, u0 = _track(*ships[0], 0.0)
    n1, e1, _, _ = _track(*ships[1], 0.0)
    seen = dict(r0=math.hypot(n1 - n0, e1 - e0), r_cpa=math.inf, stbd=0.0, port=0.0,
                faster=0.0, slower=0.0, u0=u0, r_man=None)
    stbd = port = faster = slower = 0.0
    r_man = None
    for t in np.arange(every_s, end_s + every_s / 2, every_s):
        on, oe, opsi, ou = _track(*ships[0], float(t))
        tn, te, tpsi, _ = _track(*ships[1], float(t))
        change = math.degrees(math.remainder(opsi - psi0, 2 * math.pi))
        stbd, port = max(stbd, change), max(port, -change)
        faster, slower = max(faster, ou - u0), max(slower, u0 - ou)
        rng = math.hypot(tn - on, te - oe)
        if r_man is None and (abs(change) > 5.0 or abs(ou - u0) > 0.2):
            r_man = rng
        if rng < seen["r_cpa"]:
            seen.update(r_cpa=rng, stbd=stbd, port=port, faster=faster, slower=slower,
                        r_man=r_man, t_cpa=float(t),
                        beta=math.degrees(math.atan2(te - oe, tn - on) - opsi) % 360.0,
                        alpha=math.degrees(math.atan2(oe - te, on - tn) - tpsi) % 360.0)
    return seen


def _off_bow_deg(seen) -> float:
    """The own ship's angle off the other's bow at the CPA, 0-180 deg."""
    return abs((seen["alpha"] + 180) % 360 - 180)


def _woerner(seen, crossed=False):
    """colregs.md section 2.4 / the module docstring, term by term, angles in degrees."""
    r = seen["r_cpa"]
    if r >= 1000:
        s_r = 1.0
    elif r >= 800:
        s_r = 1 - 0.4 * (1000 - r) / 200
    elif r >= 200:
        s_r = 0.6 - 0.6 * (800 - r) / 600
    else:
        s_r = 0.0
    a = min(_off_bow_deg(seen), 90.0)
    b = min(max(seen["beta"], 90.0), 270.0)
    cos = lambda d: math.cos(math.radians(d))  # noqa: E731
    safety = 0.5 * s_r + 0.5 * (1 - cos(a)) * (1 - cos(b)) / 2
    r_man = r if seen["r_man"] is None else seen["r_man"]
    detect = min(seen["r0"], 5000.0)  # the stage-2 range of colregs.md (AIS version)
    p_delay = min(max((detect - r_man) / (detect - r), 0.0), 1.0)
    course = max(seen["stbd"], seen["port"])
    p_na_course = 0.5 * max(0.0, 1 - course**2 / 900)
    kept = (seen["u0"] - seen["slower"]) / seen["u0"]
    p_na_speed = kept - 0.5 if kept > 0.5 else 0.0
    p_na = 0.0 if min(p_na_course, p_na_speed) < 0.3 else p_na_course * p_na_speed
    s16 = safety * (1 - p_delay) * (1 - p_na)
    p_nsb = min(max(1 - seen["stbd"] / 20, 0.0), 1.0) ** 4
    sin = lambda d: math.sin(math.radians(-d))  # noqa: E731  (counter-clockwise)
    p_sts = 1 - ((sin(seen["alpha"]) + 1) / 2) ** 2 * ((sin(seen["beta"]) + 1) / 2) ** 2
    s14 = (1 - 0.6 * p_nsb - 0.2 * p_delay - p_sts) * (1 - p_na_course)
    p_course = 0.0 if course < 2 else 0.5 if course > 30 else 0.5 * (course - 2) / 28
    u0 = seen["u0"]
    p_up = (u0 / (u0 + seen["faster"])) ** 2 if seen["faster"] > 0.2 else 1.0
    p_down = 0.5 * seen["slower"] / u0 if seen["slower"] > 0.2 else 0.0
    s17 = (safety - p_course) * p_up - p_down
    clip = lambda v: min(max(v, 0.0), 1.0)  # noqa: E731
    ahead_at_cpa = _off_bow_deg(seen) < 45.0
    return {13: clip(s16 - 0.3 * ahead_at_cpa), 14: clip(s14),
            15: clip(s16 - 0.5 * crossed),
            16: clip(s16), 17: clip(s17), "safety": safety, "p_delay": p_delay}


def _check(ships, crossed=False, end_s=2000):
    obs, _, _ = _run(ships, end_s=end_s)
    seen = _by_hand(ships, end_s=end_s)
    assert bool(obs.crossed_ahead[0]) is crossed
    assert obs.closest_m[0] == pytest.approx(seen["r_cpa"], abs=1e-6)
    expected = _woerner(seen, crossed)
    g = grade(obs)
    for r in RULES_GRADED:
        assert g[r][0] == pytest.approx(expected[r], abs=1e-9), r
    return g, expected, seen


RULES_GRADED = (13, 14, 15, 16, 17)

# a ship passing on the reciprocal course 2 km to the east: both abeam at the CPA (safety
# 0.5 * 1 + 0.5 * (1 - cos 90)(1 - cos 90) / 2 = 0.75) when the CPA falls on a sample


def _passer(north):
    return (north, 2000.0, [(0.0, 180.0, 6.0)])


def test_stand_on_keeping_course_and_speed_is_graded_on_safety():
    """Own 6 m/s north, passer from 12 km north: abeam at 1000 s, 2 km apart: S17 = 0.75; no
    manoeuvre, so S16 = 0; starboard to starboard (each on the other's starboard beam),
    so P_sts = 1 and S14 = 0."""
    g, _, seen = _check([OWN_STRAIGHT, _passer(12000.0)])
    assert seen["t_cpa"] == 1000.0
    assert g[17][0] == pytest.approx(0.75, abs=1e-12)
    assert g[16][0] == 0.0 and g[14][0] == 0.0


def test_stand_on_slowing_down_is_penalised_by_half_the_share_of_speed_lost():
    """Own slows 6 -> 4 m/s at 300 s: at 1000 s it is at 1800 + 4 * 700 = 4600 m, the passer
    (from 10600 m) at 10600 - 6000 = 4600 m: abeam, safety 0.75. P_down = 0.5 * 2 / 6, so
    S17 = 0.75 - 1/6 = 7/12. As a give-way manoeuvre the slow-down is apparent (4/6 of the
    speed kept: P_na_speed = 1/6 < 0.3, so P_na = 0), first seen at 310 s (own 1840 m, passer
    8740 m: 7184 m apart, before the passer comes within the 5000 m detection range):
    P_delay = 0 and S16 = 0.75."""
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (300.0, 0.0, 4.0)])
    g, _, seen = _check([own, _passer(10600.0)])
    assert seen["t_cpa"] == 1000.0
    assert g[17][0] == pytest.approx(7 / 12, abs=1e-9)
    assert math.hypot(8740 - 1840, 2000) > 5000.0
    assert g[16][0] == pytest.approx(0.75, abs=1e-9)


def test_stand_on_speeding_up_is_penalised_by_the_speed_ratio_squared():
    """Own 6 -> 8 m/s at 300 s, passer from 13400 m: abeam at 1000 s (1800 + 5600 = 7400 m =
    13400 - 6000), safety 0.75; P_up = (6/8)^2, S17 = 0.75 * 0.5625 = 0.421875. Speeding up
    keeps the whole speed, so as a give-way manoeuvre it is not apparent: P_na = 0.5 * 0.5."""
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (300.0, 0.0, 8.0)])
    g, exp, _ = _check([own, _passer(13400.0)])
    assert g[17][0] == pytest.approx(0.421875, abs=1e-9)
    assert g[16][0] == pytest.approx(0.75 * (1 - exp["p_delay"]) * 0.75, abs=1e-9)


def test_speed_changes_up_to_0_2_mps_are_no_manoeuvre():
    """6 -> 5.85 m/s (0.15 m/s less) is below the detectable change: no first manoeuvre,
    no P_down, S17 = 0.75 (abeam at 1000 s: 1800 + 5.85 * 700 = 5895 = 11895 - 6000)."""
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (300.0, 0.0, 5.85)])
    obs, _, _ = _run([own, _passer(11895.0)])
    assert math.isnan(obs.range_at_manoeuvre_m[0])
    assert obs.slower_cpa[0] == pytest.approx(0.15)
    assert grade(obs)[17][0] == pytest.approx(0.75, abs=1e-9)


@pytest.mark.parametrize("turn_deg, detected", [(4.9, False), (5.1, True), (-5.1, True)])
def test_a_course_change_is_a_manoeuvre_only_over_5_degrees(turn_deg, detected):
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, turn_deg % 360.0, 6.0)])
    obs, _, _ = _run([own, _passer(12000.0)], end_s=400)
    assert (not math.isnan(obs.range_at_manoeuvre_m[0])) is detected
    side = obs.stbd_rad[0] if turn_deg > 0 else obs.port_rad[0]
    assert math.degrees(side) == pytest.approx(abs(turn_deg))


def test_stand_on_small_course_change_is_penalised_linearly():
    """Own turns 16 deg to port (away from the passer) at 95 s: P_course = 0.5 (16 - 2) / 28
    = 0.25 off the safety seen at the (now later, wider) CPA."""
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 344.0, 6.0)])
    g, exp, seen = _check([own, _passer(12000.0)])
    assert seen["port"] == pytest.approx(16.0)
    assert g[17][0] == pytest.approx(exp["safety"] - 0.25, abs=1e-9)


@pytest.mark.parametrize("legs", [
    [(0.0, 0.0, 6.0), (95.0, 40.0, 6.0)],  # early and substantial
    [(0.0, 0.0, 6.0), (95.0, 10.0, 6.0)],  # early but small: not readily apparent
    [(0.0, 0.0, 6.0), (695.0, 40.0, 6.0)],  # late
    [(0.0, 0.0, 6.0), (95.0, 0.0, 2.5)],  # slows to 2.5 / 6 of its speed: apparent
])
def test_give_way_tracks_graded_term_by_term(legs):
    """The crossing ship from starboard (meeting point 6 km north at 1000 s): each give-way
    track's Rule 13-17 scores equal the section 2.4 formulas evaluated on the positions,
    course and speed changes read off the sampled tracks here."""
    _check([(0.0, 0.0, legs), CROSSER])


def test_small_alteration_keeps_two_ninths_of_the_non_apparent_penalty():
    """A 10 deg turn with the speed kept: P_na_course = 0.5 (1 - 100/900) = 4/9 and
    P_na_speed = 1 - 0.5 = 0.5, both >= 0.3: S16 = S (1 - P_delay)(1 - 2/9); the same turn
    at 40 deg is apparent: S (1 - P_delay)."""
    small = [(0.0, 0.0, 6.0), (95.0, 10.0, 6.0)]
    g, exp, _ = _check([(0.0, 0.0, small), CROSSER])
    assert g[16][0] == pytest.approx(exp["safety"] * (1 - exp["p_delay"]) * 7 / 9, abs=1e-9)


def test_give_way_port_turn_crosses_ahead_and_loses_half_for_rule_15():
    """40 deg to port at 95 s: the own ship runs north-west and reaches the crosser's track
    (north 6000 m) at about 1276 s, 4.6 km west of the start, while the crosser (west-bound
    from east 6000 m) is only at east -1.7 km: the own ship crosses ahead of her. Rule 16
    grades the manoeuvre alone; Rule 15 takes 0.5 off it, Rule 13 0.3."""
    port = [(0.0, 0.0, 6.0), (95.0, 320.0, 6.0)]
    g, _, _ = _check([(0.0, 0.0, port), CROSSER], crossed=True)
    assert g[16][0] > 0.3
    assert g[15][0] == pytest.approx(max(0.0, g[16][0] - 0.5), abs=1e-9)
    assert g[13][0] == pytest.approx(g[16][0] - 0.3, abs=1e-9)
    stbd = grade(_run([(0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 40.0, 6.0)]), CROSSER])[0])
    assert stbd[15][0] > g[15][0]


def test_head_on_small_starboard_turn_pays_the_non_starboard_and_apparent_terms():
    """Reciprocal courses, the other 300 m on the own port bow at 8 km; a 10 deg starboard turn
    at 95 s: P_nsb = (1 - 10/20)^4 = 1/16, (1 - P_na_course) = 5/9, so S14 = (1 - 0.6/16 -
    0.2 P_delay - P_sts) 5/9, with P_sts from the passing geometry."""
    other = (8000.0, -300.0, [(0.0, 180.0, 6.0)])
    own = (0.0, 0.0, [(0.0, 0.0, 6.0), (95.0, 10.0, 6.0)])
    g, exp, seen = _check([own, other], end_s=1200)
    assert 180.0 < seen["beta"] < 360.0  # passes on the own port side
    sin = math.sin
    p_sts = 1 - ((sin(math.radians(-seen["alpha"])) + 1) / 2) ** 2 * (
        (sin(math.radians(-seen["beta"])) + 1) / 2) ** 2
    assert g[14][0] == pytest.approx(
        max(0.0, (1 - 0.6 / 16 - 0.2 * exp["p_delay"] - p_sts) * 5 / 9), abs=1e-9)


def test_overtaking_then_crossing_the_bow_far_ahead_keeps_rule_13():
    """Own ship (8 m/s) comes up 300 m to port of a 4 m/s ship on the same course, sheers 35
    deg to port from 95 s to 300 s (a readily apparent early manoeuvre, 205 * 8 * sin 35 =
    940 m more to port), passes her about 1.24 km off at some 574 s, then at 1300 s, 2.9 km
    ahead, turns to 60 deg: relative to her it runs due east and crosses her bow line 2.9 km
    ahead of her, the range opening all the while. The closest point is the passage abeam:
    crossed ahead, yet S13 = S16 (Rule 13 asks her to keep clear until past and clear)."""
    own = (0.0, 0.0, [(0.0, 0.0, 8.0), (95.0, 325.0, 8.0), (300.0, 0.0, 8.0),
                      (1300.0, 60.0, 8.0)])
    slow = (2000.0, 300.0, [(0.0, 0.0, 4.0)])
    g, _, seen = _check([own, slow], crossed=True, end_s=2400)
    assert seen["t_cpa"] < 1300.0
    assert _off_bow_deg(seen) > 45.0
    assert g[16][0] > 0.3
    assert g[13][0] == pytest.approx(g[16][0], abs=1e-9)


def test_overtaking_then_cutting_across_the_bow_close_ahead_loses_0_3_for_rule_13():
    """As above, sheering at 10 s, but at 1050 s, some 1.9 km ahead, she turns 90 deg to
    starboard straight across the other's bow: she passes 1.15 km ahead of her, nearer than
    abeam (1.24 km), so the closest point is made ahead of the other ship, 27 deg off her bow.
    S13 = S16 - 0.3."""
    own = (0.0, 0.0, [(0.0, 0.0, 8.0), (10.0, 325.0, 8.0), (215.0, 0.0, 8.0),
                      (1050.0, 90.0, 8.0)])
    slow = (2000.0, 300.0, [(0.0, 0.0, 4.0)])
    g, _, seen = _check([own, slow], crossed=True, end_s=1550)
    assert seen["t_cpa"] > 1050.0
    assert _off_bow_deg(seen) < 45.0
    assert g[16][0] > 0.4
    assert g[13][0] == pytest.approx(g[16][0] - 0.3, abs=1e-9)


# --------------------------------------------------------------------------------------------
# graded_kinds(): each ship graded for the part the rules gave it
# --------------------------------------------------------------------------------------------

def _encounter(ships, behaviour, env=None, steps=2400):
    """Cargo ships at 12 kn on routes along their courses ``ships`` = [(north, east,
    heading_deg), ...], all of one ``behaviour`` (``colregs``: each runs the bundled rules),
    observed once per 10 s decision period as a campaign observes them."""
    spec = load_ship("cargo")
    setups = []
    for k, (n, e, h) in enumerate(ships):
        psi = math.radians(h)
        route = np.array([[n + 40000.0 * math.cos(psi), e + 40000.0 * math.sin(psi)]])
        setups.append(ShipSetup(f"s{k}", spec, 0, n, e, psi, from_kn(12.0), route, k,
                                behaviour=behaviour))
    batch = build_batch(setups, [env or EncounterEnv()])
    decider = (None if behaviour == "keep_course"
               else Decider.build(batch.behaviours, batch.pair_i, batch.pair_j))
    sim = Simulation.start(batch, 1.0, decider=decider)
    obs = PairObserver.start(sim)
    for _ in range(steps // 10):
        sim.run(10)
        obs.observe(sim)
    return obs


def _by_headings(obs):
    """The start kind of every directed pair by t = 0 headings and water speeds, without the
    mutual class (how a pair used to be graded)."""
    x = obs.x0
    return [classify(x[PSI, o], x[PSI, t], x[NORTH, t] - x[NORTH, o], x[EAST, t] - x[EAST, o],
                     x[U, o], x[U, t]) for o, t in zip(obs.own, obs.tgt, strict=True)]


# the audit's mutual port-to-port crossing: courses 160 deg apart, each ship sees the other
# about 3 deg (A) and 17 deg (B) on her port bow, outside the 10 deg head-on sector
MUTUAL_PORT = [(0.0, 0.0, 0.0), (7397.8, -387.7, 200.0)]
# nearly reciprocal headings (172 deg apart, each ship within 6 deg of the other's bow: head-on
# by the headings) in a 1 kn current setting east: over ground the courses are 162.5 deg apart,
# so the network sees a crossing, ship 0 stand-on (ship 1 on her port bow), ship 1 give-way
DRIFTED = [(0.0, 0.0, 0.0), (15000.0, -560.0, 172.0)]


def _current():
    return EncounterEnv(from_kn(1.0), math.pi / 2)


def test_a_mutual_port_to_port_crossing_grades_both_ships_as_giving_way():
    """Rule 14(c): the network makes both ships mutual give-way (its mutual_crossing) and
    both turn some 30 deg to starboard; each is graded as head-on, S14 (starboard turn,
    port-to-port passing: about 0.97), not as a stand-on ship that altered course (S17 = 0.25,
    which the headings' crossing_stand_on class gave)."""
    obs = _encounter(MUTUAL_PORT, "colregs", steps=1200)
    assert _by_headings(obs) == ["crossing_stand_on"] * 2
    assert obs.first_role.tolist() == [MUTUAL_GIVE_WAY] * 2
    assert obs.first_encounter.tolist() == [ENUMS["crossing"]] * 2
    assert obs.graded_kinds() == (["crossing_mutual"] * 2, ["network"] * 2)
    assert np.all(np.degrees(obs.stbd_cpa) > 25.0)
    g = grade(obs)
    out = obs.scores(obs.graded_kinds()[0])
    for side, k in (("_i", 0), ("_j", 1)):
        assert out["compliance" + side][0] == pytest.approx(g[14][k])
        assert out["compliance" + side][0] > 0.9
        assert g[17][k] < 0.3  # the old grade
    assert out["score_rule14"][0] == pytest.approx(min(g[14]))
    assert out["score_rule16"][0] == pytest.approx(min(g[16]))
    assert np.isnan(out["score_rule15"][0]) and np.isnan(out["score_rule17"][0])


def test_a_pair_the_network_reads_otherwise_than_the_start_headings_takes_the_network_role():
    """By the t = 0 headings the drifted pair is head-on (both graded by Rule 14); the network,
    on courses over ground, makes ship 0 stand-on and ship 1 give-way in a crossing. Ship 0
    stands on and is graded by Rule 17 (not marked down by Rule 14 for not turning); ship 1
    gives way to starboard and is graded by Rule 15."""
    obs = _encounter(DRIFTED, "colregs", env=_current())
    assert _by_headings(obs) == ["head_on"] * 2
    assert obs.first_role.tolist() == [STAND_ON, GIVE_WAY]
    kinds, by = obs.graded_kinds()
    assert (kinds, by) == (["crossing_stand_on", "crossing_give_way"], ["network"] * 2)
    # ship 0 stood on: her heading moved less than a manoeuvre's 5 deg (the crab angle with
    # which her route guidance holds her track against the current)
    assert math.degrees(max(obs.stbd_cpa[0], obs.port_cpa[0])) < 5.0
    assert math.degrees(obs.stbd_cpa[1]) > 25.0
    g = grade(obs)
    out = obs.scores(kinds)
    assert out["compliance_i"][0] == pytest.approx(g[17][0])
    assert out["compliance_j"][0] == pytest.approx(g[15][1])
    assert g[17][0] > 0.6 > 0.1 > g[14][0]


@pytest.mark.parametrize("ships, env", [(MUTUAL_PORT, None), (DRIFTED, _current())],
                         ids=["mutual", "drifted"])
def test_a_baseline_is_graded_under_the_kind_of_the_rules_following_run(ships, env):
    """The same encounter with keep-course ships (the no_avoidance baseline) is graded by its
    start geometry, which reads the t = 0 state as the network does (its sectors, courses and
    speeds over ground, the mutual crossing): the same kinds as the rules-following run."""
    rules = _encounter(ships, "colregs", env=env, steps=1200)
    baseline = _encounter(ships, "keep_course", env=env, steps=1200)
    kinds, by = baseline.graded_kinds()
    assert by == ["geometry"] * 2
    assert kinds == rules.graded_kinds()[0] == rules.start_kinds()


def test_the_first_role_is_kept():
    """The observer keeps the role and encounter the network first gave each pair: a later
    role (the network's memory after each decision) does not replace it; a pair without a
    role yet takes its first."""
    obs = _fields(m=2)
    memory = np.zeros((len(MEMORY), 2))
    row_role, row_enc = MEMORY.index("own_role"), MEMORY.index("encounter")
    for role, enc in (((GIVE_WAY, NO_ROLE), (ENUMS["crossing"], ENUMS["no_encounter"])),
                      ((STAND_ON, STAND_ON), (ENUMS["overtaken"], ENUMS["crossing"]))):
        memory[row_role], memory[row_enc] = role, enc
        obs._decisions(SimpleNamespace(decider=SimpleNamespace(memory=memory.copy(),
                                                               last_decision=[None])))
    assert obs.first_role.tolist() == [GIVE_WAY, STAND_ON]
    assert obs.first_encounter.tolist() == [ENUMS["crossing"], ENUMS["crossing"]]


@pytest.mark.parametrize("runs_rules, role, encounter, kind, by", [
    (True, STAND_ON, "crossing", "crossing_stand_on", "network"),
    (True, MUTUAL_GIVE_WAY, "crossing", "crossing_mutual", "network"),
    (True, MUTUAL_GIVE_WAY, "head_on", "head_on", "network"),
    (True, GIVE_WAY, "overtaking", "overtaking", "network"),
    (True, STAND_ON, "overtaken", "overtaken", "network"),
    (True, math.nan, "no_encounter", "crossing_give_way", "geometry"),  # never engaged
    (True, GIVE_WAY, "head_on", "crossing_give_way", "geometry"),  # no such role in the table
    (False, STAND_ON, "crossing", "crossing_give_way", "geometry"),  # a rogue's own roles
])
def test_graded_kind_is_the_network_role_of_a_ship_that_runs_the_rules(runs_rules, role,
                                                                       encounter, kind, by):
    """Own ship north-bound at 6 m/s; the other west-bound at 6 m/s from (4000, 4000), 45 deg
    on the own starboard bow and seeing the own ship 45 deg on her port bow: crossing give-way
    by the start geometry. The first network role wins for a ship that runs the rules."""
    obs = _fields(m=1, runs_rules=runs_rules, first_role=role,
                  first_encounter=ENUMS[encounter] if role == role else math.nan)
    obs.x0[[NORTH, EAST, PSI], 1] = 4000.0, 4000.0, 1.5 * math.pi
    obs.v0[:] = [[U0, 0.0], [0.0, -U0]]
    assert obs.start_kinds() == ["crossing_give_way"]
    assert obs.graded_kinds() == ([kind], [by])


@pytest.mark.parametrize("other, kinds", [
    ((4000.0, 4000.0, 180.0), ["crossing_mutual", "crossing_mutual"]),  # both to starboard
    ((4000.0, -500.0, 200.0), ["crossing_mutual", "crossing_mutual"]),  # both to port
    ((4000.0, 200.0, 180.0), ["head_on", "head_on"]),
    ((4000.0, 4000.0, 270.0), ["crossing_give_way", "crossing_stand_on"]),
])
def test_start_kinds_name_the_mutual_crossing(other, kinds):
    """Calm water: the start geometry of both directed pairs, with the network's mutual
    crossing (each ship sees the other on the same side)."""
    obs = _fields(m=1)
    n, e, h = other
    obs.x0[[NORTH, EAST, PSI], 1] = n, e, math.radians(h)
    obs.v0[:, 0] = U0, 0.0
    obs.v0[:, 1] = U0 * math.cos(math.radians(h)), U0 * math.sin(math.radians(h))
    back = _fields(m=1)  # the same pair seen from the other ship
    back.x0[[NORTH, EAST, PSI], 0] = n, e, math.radians(h)
    back.v0[:, 0], back.v0[:, 1] = obs.v0[:, 1], obs.v0[:, 0]
    assert obs.start_kinds() + back.start_kinds() == kinds
