"""What every ship did towards every other during a campaign run, and its COLREGS grade.

:class:`PairObserver` samples the true state once per decision period for every directed pair
(own ship ``o``, other ship ``t``; both directions of each pair): the range and, at the closest
sample, the relative bearings ``alpha`` (of the own ship from the other's bow) and ``beta`` (of
the other ship from the own bow), as colregs.md defines them; the own ship's largest course
changes to starboard and port and its speed change so far; the range at its first manoeuvre (a
course change over 5 degrees or a speed change over 0.2 m/s) if that came before the closest
sample; whether it crossed the other ship's bow line ahead of her; the manoeuvres and rule
nodes its decision network produced towards her; and the role and encounter that network first
gave her.

:func:`grade` turns these into the Woerner-style scores of ``../shared/reference/colregs.md``
section 2.4 (Woerner 2016; Woerner et al. 2019, Auton. Robots 43:967-991, as implemented in
NTNU's AutoVerification with Minne's 2017 variants), per directed pair and by the rule that
applies to the own ship's part in the encounter:

* safety ``S = 0.5 s_r + 0.5 s_theta``: the range term ``s_r`` (1 above R_min = 1000 m, falling
  by gamma_nm = 0.4 to R_nm = 800 m and by gamma_col = 0.6 more to R_col = 200 m, 0 below) and
  the pose term ``(1 - cos alpha)(1 - cos beta)`` with alpha (the own ship seen from the other)
  clipped at 90 deg and beta (the other seen from the own ship) to [90, 270] deg: no credit for
  passing ahead of the other's bow, full credit for passing abaft her beam; divided by its
  largest value 2 so that ``S`` lies in [0, 1] (our reading);
* give-way (Rule 16): ``S16 = S (1 - P_delay)(1 - P_na)``, ``P_delay`` the share of the range
  from detection to the CPA run before the first manoeuvre (detection: the other ship inside the
  evaluator's stage-2 range of 5000 m, or the start range if closer; a manoeuvre before it
  costs nothing), ``P_na`` the non-apparent-manoeuvre
  penalty (course change under 30 deg and speed kept above half);
* overtaking (Rule 13) ``S16 - 0.3`` when the own ship passed ahead of the overtaken ship,
  within 45 deg of her bow at the CPA (``|alpha| < 45 deg``, Woerner's test as colregs.md
  section 2.4 states it): unlike Rule 15, Rule 13 has no clause against crossing ahead, and a
  ship finally past and clear may cross the other's bow; the score marks a closest approach
  made ahead of her; crossing give-way (Rule 15) ``S16 - 0.5`` when
  the own ship crossed ahead of the other (Rule 15: "avoid crossing ahead of the other
  vessel", tested on the bow line itself, at any range, rather than on alpha at the CPA);
* head-on (Rule 14): ``(1 - 0.6 P_nsb - 0.2 P_delay - P_sts)(1 - P_na_course)`` with the
  non-starboard penalty ``clip(1 - stbd / 20 deg, 0, 1)^4`` (the form colregs.md suggests) and
  the starboard-to-starboard penalty ``1 - ((sin a + 1)/2)^2 ((sin b + 1)/2)^2`` (angles
  counter-clockwise);
* stand-on (Rule 17, Woerner): ``(S - P_course) P_up - P_down``, ``P_course`` 0 below 2 deg,
  0.5 above 30 deg, linear between; ``P_up = (v0 / v_max)^2`` after a speed increase and
  ``P_down = 0.5 dv / v0`` after a reduction, each over 0.2 m/s.

Scores are clipped to [0, 1].

The part each ship is graded for (:meth:`PairObserver.graded_kinds`): a ship that runs the rules
(behaviour ``colregs``) is graded towards another under the role and encounter its decision network
first gave that pair (:data:`KIND_OF_ROLE`): the duty that governed its manoeuvre, held until the
pair was past and clear (Rule 13(d)), even where the start geometry reads otherwise (the network
decides from courses and speeds over ground at its decision step, and may first engage a pair later
in the run); a role the pair takes after it was cleared is not graded. The start geometry
(:meth:`PairObserver.start_kinds`: the network's sectors, Rules 13-15, applied to the true headings,
courses and speeds over ground at t = 0, so the kind the network gives a pair it engages at its
first decision with perfect knowledge) grades the other directed pairs: those of ships that run no
rules or break them (the keep-course ships of the ``no_avoidance`` baseline, rogue ships; so a
baseline pair is graded under the kind the rules-following run's network first gives it whenever
that network engages it at t = 0 without instruments), pairs the network never gave a role (among
them every pair in restricted visibility, where Rule 19 gives none), and roles outside
:data:`KIND_OF_ROLE` (a rules file of other roles).

A mutual give-way crossing (``crossing_mutual``: each ship sees the other on the same bow, both
to port or both to starboard; the network's ``mutual_crossing`` makes both ships
``mutual_give_way`` and turns both to starboard) is graded as head-on, Rule 14, for both ships:
Rule 14(c) has a ship in doubt whether a head-on situation exists assume that it does and act
accordingly, and of the scores of colregs.md section 2.4 only S14 grades what that asks of each
ship, the starboard alteration (``P_nsb``) and the port-to-port passing (``P_sts``); S15 penalises
crossing ahead of a stand-on ship, which this encounter does not have, and S16 ignores the side.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.campaign.generator import classify
from trafficsim.colregs.features import COURSE_MIN_SPEED_MPS
from trafficsim.colregs.vocabulary import (
    ENUMS,
    GIVE_WAY,
    MANOEUVRES,
    MEMORY,
    MUTUAL_GIVE_WAY,
    NO_ROLE,
    STAND_ON,
)
from trafficsim.engine import Simulation, earth_velocity
from trafficsim.jit import kernel
from trafficsim.ships.base import EAST, NORTH, PSI, U

R_MIN_M, R_NM_M, R_COL_M = 1000.0, 800.0, 200.0
GAMMA_NM, GAMMA_COL = 0.4, 0.6
APPARENT_COURSE_RAD = math.radians(30.0)
MANOEUVRE_COURSE_RAD = math.radians(5.0)
MANOEUVRE_SPEED_MPS = 0.2
#: r_detect of the delay penalty: the stage-2 range of NTNU's AutoVerification (AIS version;
#: 7000 m in the other), colregs.md sections 1 and 2.4
DETECT_RANGE_M = 5000.0
#: Rule 13's penalty: the overtaking ship passed within this of the overtaken ship's bow at
#: the CPA (colregs.md section 2.4, S13)
AHEAD_AT_CPA_RAD = math.radians(45.0)
#: the rule graded for the own ship's part in each kind of pair (a mutual give-way crossing
#: as head-on, Rule 14(c): module docstring)
RULE_OF_KIND = {"head_on": 14, "crossing_mutual": 14, "crossing_give_way": 15,
                "crossing_stand_on": 17, "overtaking": 13, "overtaken": 17}
MIRROR = {"head_on": "head_on", "crossing_mutual": "crossing_mutual",
          "crossing_give_way": "crossing_stand_on", "crossing_stand_on": "crossing_give_way",
          "overtaking": "overtaken", "overtaken": "overtaking"}
#: the kind graded for the role and encounter a decision network gave a directed pair (the
#: role nodes of rules/colregs.yaml: give_way_crossing, stand_on_crossing, mutual_crossing,
#: head_on_role, give_way_overtaking, stand_on_overtaken)
KIND_OF_ROLE: dict[tuple[float, float], str] = {
    (GIVE_WAY, ENUMS["crossing"]): "crossing_give_way",
    (STAND_ON, ENUMS["crossing"]): "crossing_stand_on",
    (MUTUAL_GIVE_WAY, ENUMS["crossing"]): "crossing_mutual",
    (MUTUAL_GIVE_WAY, ENUMS["head_on"]): "head_on",
    (GIVE_WAY, ENUMS["overtaking"]): "overtaking",
    (STAND_ON, ENUMS["overtaken"]): "overtaken",
}
RULES_BEHAVIOUR = "colregs"  # the behaviour of a ship that runs the rules
RULES = (13, 14, 15, 16, 17)
_ROLE_ROW, _ENCOUNTER_ROW = MEMORY.index("own_role"), MEMORY.index("encounter")


def _wrap_pi(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@dataclass
class PairObserver:
    """Samples of every directed pair ``(2P,)``: first the pairs ``(pair_i, pair_j)``, then
    ``(pair_j, pair_i)``."""

    own: np.ndarray
    tgt: np.ndarray
    x0: np.ndarray  # (N_STATE, n) true state at the start
    range0_m: np.ndarray
    closest_m: np.ndarray  # smallest sampled range
    alpha_cpa: np.ndarray  # rad, clockwise, at the closest sample: own ship from the other's bow
    beta_cpa: np.ndarray  # the other ship from the own bow
    stbd_rad: np.ndarray  # own ship's largest course change to starboard so far
    port_rad: np.ndarray
    faster_mps: np.ndarray  # largest speed increase so far
    slower_mps: np.ndarray
    stbd_cpa: np.ndarray  # the same, at the closest sample
    port_cpa: np.ndarray
    faster_cpa: np.ndarray
    slower_cpa: np.ndarray
    range_at_manoeuvre_m: np.ndarray  # NaN until the own ship manoeuvres
    manoeuvre_cpa_m: np.ndarray  # the same, at the closest sample (NaN: none before the CPA)
    side: np.ndarray  # m, the own ship off the other's bow line (starboard +) at the last
    #                   sample off it
    ahead: np.ndarray  # m, the own ship ahead of the other along her heading at that sample
    crossed_ahead: np.ndarray
    asked: np.ndarray  # (2P, len(MANOEUVRES)) manoeuvres the network asked
    fired: np.ndarray  # (2P, max nodes) rule nodes visited
    node_names: list[list[str]]  # per network
    net_of_pair: np.ndarray  # (2P,) network of the own ship, -1 none
    v0: np.ndarray  # (2, n) true velocity over ground north, east at the start, m/s
    runs_rules: np.ndarray  # (2P,) bool: the own ship runs the rules (behaviour colregs)
    first_role: np.ndarray  # (2P,) the role the own ship's network first gave (NaN: none yet)
    first_encounter: np.ndarray  # the encounter it gave with it (vocabulary constants)
    active: np.ndarray | None = None  # (2P,) bool: the pairs still observed (all: None)

    def __post_init__(self) -> None:
        if self.active is None:
            self.active = np.ones(self.own.shape[0], dtype=bool)

    @classmethod
    def start(cls, sim: Simulation) -> PairObserver:
        b = sim.batch
        own = np.concatenate([b.pair_i, b.pair_j])
        tgt = np.concatenate([b.pair_j, b.pair_i])
        x = b.x
        m = own.shape[0]
        rng0 = np.hypot(x[NORTH, tgt] - x[NORTH, own], x[EAST, tgt] - x[EAST, own])
        z = np.zeros(m)
        d = sim.decider
        names = [] if d is None else [list(net.node_names) for net in d.networks]
        width = max((len(n) for n in names), default=0)
        net = np.full(m, -1, dtype=np.int64)
        if d is not None:
            assert np.array_equal(d.obs, own)  # the decider's directed pairs, in this order
            net = d.ship_net[own]
        behaviours = np.asarray(b.behaviours, dtype=object)
        obs = cls(own, tgt, x.copy(), rng0, np.full(m, np.inf), z.copy(), z.copy(), z.copy(),
                  z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy(),
                  np.full(m, np.nan), np.full(m, np.nan), np.zeros(m), np.zeros(m),
                  np.zeros(m, dtype=bool),
                  np.zeros((m, len(MANOEUVRES)), dtype=bool), np.zeros((m, width), dtype=bool),
                  names, net, earth_velocity(x, b.env), behaviours[own] == RULES_BEHAVIOUR,
                  np.full(m, np.nan), np.full(m, np.nan))
        dn = x[NORTH, own] - x[NORTH, tgt]
        de = x[EAST, own] - x[EAST, tgt]
        c, s = np.cos(x[PSI, tgt]), np.sin(x[PSI, tgt])
        obs.side, obs.ahead = -dn * s + de * c, dn * c + de * s
        obs._decisions(sim)  # the decision at t = 0, taken when the simulation started
        return obs

    def observe(self, sim: Simulation) -> None:
        """One sample of the true state (and of the decisions just taken): one compiled loop
        over the active directed pairs."""
        _observe(sim.batch.x, self.x0, self.own, self.tgt, self.active, self.closest_m,
                 self.alpha_cpa,
                 self.beta_cpa, self.stbd_rad, self.port_rad, self.faster_mps,
                 self.slower_mps, self.stbd_cpa, self.port_cpa, self.faster_cpa,
                 self.slower_cpa, self.range_at_manoeuvre_m, self.manoeuvre_cpa_m, self.side,
                 self.ahead, self.crossed_ahead)
        self._decisions(sim)

    def _decisions(self, sim: Simulation) -> None:
        d = sim.decider
        if d is None or not d.last_decision:
            return
        role = d.memory[_ROLE_ROW]  # (the pair memory after the decision just taken)
        new = np.isnan(self.first_role) & (role != NO_ROLE) & self.active
        self.first_role[new] = role[new]
        self.first_encounter[new] = d.memory[_ENCOUNTER_ROW, new]
        for k, dec in enumerate(d.last_decision):
            if dec is None:
                continue
            idx = np.flatnonzero(self.net_of_pair == k)
            asked = dec.action("manoeuvre")
            live = self.active[idx]
            for j, name in enumerate(MANOEUVRES):
                self.asked[idx, j] |= (asked == ENUMS[name]) & live
            rows = np.repeat(idx, dec.path.shape[1])
            nodes = dec.path.ravel()
            keep = (nodes >= 0) & np.repeat(live, dec.path.shape[1])
            self.fired[rows[keep], nodes[keep]] = True

    def columns(self) -> dict[str, Any]:
        """Per undirected pair: what each of its two ships did (``_i``, ``_j``)."""
        half = self.own.shape[0] // 2
        out: dict[str, Any] = {}
        for suffix, part in (("_i", slice(0, half)), ("_j", slice(half, None))):
            asked = self.asked[part]
            fired = self.fired[part]
            nets = self.net_of_pair[part]
            out["manoeuvres" + suffix] = [
                ",".join(n for j, n in enumerate(MANOEUVRES) if row[j] and n != "no_action")
                for row in asked]
            out["rules_fired" + suffix] = [
                "" if net < 0 else ",".join(self.node_names[net][j] for j in np.flatnonzero(
                    row[: len(self.node_names[net])]))
                for row, net in zip(fired, nets, strict=True)]
            out["course_change_stbd_deg" + suffix] = np.degrees(self.stbd_cpa[part])
            out["course_change_port_deg" + suffix] = np.degrees(self.port_cpa[part])
            out["crossed_ahead" + suffix] = self.crossed_ahead[part]
        return out

    def start_kinds(self) -> list[str]:
        """The kind of every directed pair by its start geometry: the sectors of Rules 13-15
        as ``rules/colregs.yaml`` reads them (:func:`~.generator.classify` with the mutual
        give-way crossing), on the true state at t = 0 as the network sees it without
        instruments: bearings from the own bow, courses and speeds over ground (a course of a
        ship slower than 0.1 m/s: the own heading, or the own course for the other ship, as
        :mod:`trafficsim.colregs.features` takes them)."""
        x, v = self.x0, self.v0
        sog = np.hypot(v[0], v[1])
        cog = np.where(sog < COURSE_MIN_SPEED_MPS, x[PSI], np.arctan2(v[1], v[0]))
        return [classify(x[PSI, o], cog[t] if sog[t] >= COURSE_MIN_SPEED_MPS else cog[o],
                         x[NORTH, t] - x[NORTH, o], x[EAST, t] - x[EAST, o], sog[o], sog[t],
                         own_course=cog[o], mutual=True)
                for o, t in zip(self.own.tolist(), self.tgt.tolist(), strict=True)]

    def graded_kinds(self) -> tuple[list[str], list[str]]:
        """The kind each directed pair is graded under and where it comes from: ``"network"``,
        the role and encounter the own ship's decision network first gave the pair
        (:data:`KIND_OF_ROLE`), where the own ship runs the rules and its network gave the
        pair such a role; ``"geometry"``, :meth:`start_kinds`, otherwise (module
        docstring)."""
        start = self.start_kinds()
        kinds, source = [], []
        for k, (role, enc) in enumerate(zip(self.first_role.tolist(),
                                            self.first_encounter.tolist(), strict=True)):
            kind = KIND_OF_ROLE.get((role, enc)) if self.runs_rules[k] else None
            kinds.append(start[k] if kind is None else kind)
            source.append("geometry" if kind is None else "network")
        return kinds, source

    def scores(self, kinds: Sequence[str]) -> dict[str, np.ndarray]:
        """Compliance per undirected pair from the kind of every directed pair (``kinds``,
        ``(2P,)``, e.g. :meth:`graded_kinds`): the score of each ship (``compliance_i``,
        ``_j``, by the rule of its part) and one column per rule (``score_rule13`` ... ``17``:
        the ship the rule binds; where it binds both, as Rules 14 and 16 head-on and in a mutual
        give-way crossing: the lower of the two)."""
        half = self.own.shape[0] // 2
        if len(kinds) != self.own.shape[0]:
            raise ValueError(f"{len(kinds)} kinds for {self.own.shape[0]} directed pairs")
        graded = grade(self)
        out: dict[str, np.ndarray] = {}
        rule = np.array([RULE_OF_KIND.get(k, 0) for k in kinds])
        own_score = np.full(rule.shape[0], np.nan)
        for r in RULES:
            own_score = np.where(rule == r, graded[r], own_score)
        out["compliance_i"], out["compliance_j"] = own_score[:half], own_score[half:]
        for r in RULES:
            mine = np.where((rule == r) | ((r == 16) & np.isin(rule, (13, 15, 14))),
                            graded[r], np.nan)
            # the ship the rule binds; where it binds both (head-on and mutual crossings:
            # Rules 14 and 16; both ships given the same role), the lower
            out[f"score_rule{r}"] = np.fmin(mine[:half], mine[half:])
        return out


@kernel
def _larger(a: float, b: float) -> float:
    """``np.maximum(a, b)`` of two numbers (NaN wins; of equal numbers the second)."""
    return a if a > b or math.isnan(a) else b


@kernel
def _observe(x: np.ndarray, x0: np.ndarray, own: np.ndarray, tgt: np.ndarray,
             active: np.ndarray, closest: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
             stbd: np.ndarray, port: np.ndarray, faster: np.ndarray, slower: np.ndarray,
             stbd_cpa: np.ndarray, port_cpa: np.ndarray, faster_cpa: np.ndarray,
             slower_cpa: np.ndarray, range_at_manoeuvre: np.ndarray, manoeuvre_cpa: np.ndarray,
             side: np.ndarray, ahead: np.ndarray, crossed_ahead: np.ndarray) -> None:
    """:meth:`PairObserver.observe` of every active directed pair, in place (attributes of
    :class:`PairObserver`; ``x`` the true state now, ``x0`` at the start).

    The own ship crossed the other's bow line ahead of her when its side of the line changed
    since the last sample and the point where it crossed, interpolated linearly between the two
    samples in the other ship's frame, lies ahead of her: a crossing made between two samples
    is seen even when the other ship has passed that point by the second."""
    for k in range(own.shape[0]):
        if not active[k]:
            continue
        o, t = own[k], tgt[k]
        dn, de = x[NORTH, t] - x[NORTH, o], x[EAST, t] - x[EAST, o]
        rng = math.hypot(dn, de)
        change = (x[PSI, o] - x0[PSI, o] + math.pi) % (2.0 * math.pi) - math.pi
        dv = x[U, o] - x0[U, o]
        stbd[k], port[k] = _larger(stbd[k], change), _larger(port[k], -change)
        faster[k], slower[k] = _larger(faster[k], dv), _larger(slower[k], -dv)
        moved = abs(change) > MANOEUVRE_COURSE_RAD or abs(dv) > MANOEUVRE_SPEED_MPS
        if moved and math.isnan(range_at_manoeuvre[k]):
            range_at_manoeuvre[k] = rng
        if rng < closest[k]:
            closest[k] = rng
            alpha[k] = math.atan2(-de, -dn) - x[PSI, t]
            beta[k] = math.atan2(de, dn) - x[PSI, o]
            stbd_cpa[k], port_cpa[k] = stbd[k], port[k]
            faster_cpa[k], slower_cpa[k] = faster[k], slower[k]
            manoeuvre_cpa[k] = range_at_manoeuvre[k]
        c, s = math.cos(x[PSI, t]), math.sin(x[PSI, t])
        off = dn * s - de * c  # (the own ship relative to the other: -dn, -de)
        along = -dn * c - de * s
        if off * side[k] < 0.0:
            w = side[k] / (side[k] - off)  # share of the interval before the crossing
            if ahead[k] + w * (along - ahead[k]) > 0.0:
                crossed_ahead[k] = True
        if off != 0.0:
            side[k], ahead[k] = off, along


def grade(obs: PairObserver) -> dict[int, np.ndarray]:
    """Woerner-style scores of every directed pair for every rule (module docstring)."""
    r_cpa = obs.closest_m
    s_r = np.where(r_cpa >= R_MIN_M, 1.0,
                   np.where(r_cpa >= R_NM_M,
                            1.0 - GAMMA_NM * (R_MIN_M - r_cpa) / (R_MIN_M - R_NM_M),
                            np.where(r_cpa >= R_COL_M,
                                     1.0 - GAMMA_NM - GAMMA_COL * (R_NM_M - r_cpa)
                                     / (R_NM_M - R_COL_M), 0.0)))
    alpha = np.abs(_wrap_pi(obs.alpha_cpa))
    beta = obs.beta_cpa % (2.0 * np.pi)
    s_theta = ((1.0 - np.cos(np.minimum(alpha, np.pi / 2)))
               * (1.0 - np.cos(np.clip(beta, np.pi / 2, 1.5 * np.pi))) / 2.0)
    safety = 0.5 * s_r + 0.5 * s_theta
    r_man = np.where(np.isnan(obs.manoeuvre_cpa_m), r_cpa, obs.manoeuvre_cpa_m)
    r_detect = np.minimum(obs.range0_m, DETECT_RANGE_M)
    span = np.maximum(r_detect - r_cpa, 1e-9)
    p_delay = np.clip((r_detect - r_man) / span, 0.0, 1.0)
    course = np.maximum(obs.stbd_cpa, obs.port_cpa)
    p_na_course = 0.5 * np.maximum(0.0, 1.0 - course**2 / APPARENT_COURSE_RAD**2)
    u0 = np.maximum(obs.x0[U, obs.own], 1e-9)
    kept = (u0 - obs.slower_cpa) / u0
    p_na_speed = np.where(kept > 0.5, kept - 0.5, 0.0)
    p_na = np.where((p_na_course < 0.3) | (p_na_speed < 0.3), 0.0, p_na_course * p_na_speed)
    s16 = safety * (1.0 - p_delay) * (1.0 - p_na)
    s13 = s16 - 0.3 * (alpha < AHEAD_AT_CPA_RAD)
    s15 = s16 - 0.5 * obs.crossed_ahead
    p_nsb = np.clip(1.0 - obs.stbd_cpa / math.radians(20.0), 0.0, 1.0) ** 4
    a_ccw, b_ccw = -obs.alpha_cpa, -obs.beta_cpa
    p_sts = 1.0 - ((np.sin(a_ccw) + 1.0) / 2.0) ** 2 * ((np.sin(b_ccw) + 1.0) / 2.0) ** 2
    s14 = (1.0 - 0.6 * p_nsb - 0.2 * p_delay - p_sts) * (1.0 - p_na_course)
    deg = np.degrees(course)
    p_course = np.where(deg < 2.0, 0.0, np.where(deg > 30.0, 0.5, 0.5 * (deg - 2.0) / 28.0))
    v_max = u0 + obs.faster_cpa
    p_up = np.where(obs.faster_cpa > MANOEUVRE_SPEED_MPS, (u0 / v_max) ** 2, 1.0)
    p_down = np.where(obs.slower_cpa > MANOEUVRE_SPEED_MPS, 0.5 * obs.slower_cpa / u0, 0.0)
    s17 = (safety - p_course) * p_up - p_down
    return {r: np.clip(s, 0.0, 1.0) for r, s in
            ((13, s13), (14, s14), (15, s15), (16, s16), (17, s17))}
