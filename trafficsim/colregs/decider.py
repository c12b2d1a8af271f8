"""The decision step: features, decision networks, pair memory, one manoeuvre per ship.

Every decision period (default 10 s) :meth:`Decider.decide`

1. forgets the encounter of a pair whose track has been lost for longer than the rules file's
   ``lost_track_min`` (as at "past and clear"), and updates each ship's model of its route leg
   (:meth:`Decider._route_line`);
2. computes the encounter features of every directed pair (own ship, other ship) of every
   encounter from what the own ship knows (its own estimate; the other ship's track, or its
   true state where the own ship carries no radar or AIS) [seed 002, appendix F: "certain
   minimal information ... speed, course, relative position"];
3. evaluates each ship's decision network for all its pairs at once
   (:func:`trafficsim.colregs.network.evaluate`), starting each pair where its previous
   decision left it;
4. merges the actions into the pair's memory (role, encounter, expected role of the other, the
   manoeuvre asked of the own ship and its parameters: kept until a node sets them again, so a
   role holds until "past and clear", Rule 13(d));
5. records blind spots: pairs where both ships hold the same role (both give-way or both
   stand-on) for more than one decision period, the first fault of the 500-encounter study of
   [seed 002, appendix F, "Analysis of simulation results"];
6. gives each ship one manoeuvre that satisfies all its pairs at once
   (:mod:`trafficsim.colregs.arbitration`, Rule 8(d)), or, when no pair asks for a manoeuvre
   any more, turns it back towards its route as far as is safe at the speed it will sail and
   releases it to route guidance once the route is safe at route speed
   (:meth:`Decider._resume`).

Behaviours (per ship): ``colregs`` runs the scenario's rules file (default
``rules/colregs.yaml``); ``keep_course`` takes no decisions; ``turn_port`` and ``late_action``
run ``rules/turn_port.yaml`` and ``rules/late_action.yaml``, the non-compliant ships of the
bundled rules (each extends ``colregs.yaml`` with other parameters). Other behaviour is a rules
file given as the scenario's ``rules:``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trafficsim.colregs import arbitration, features, network
from trafficsim.colregs.vocabulary import (
    ALTER_COURSE,
    EMERGENCY,
    FEATURES,
    GIVE_WAY,
    MEMORY,
    MUTUAL_GIVE_WAY,
    NO_ACTION,
    NO_ROLE,
    PORT,
    REDUCE_SPEED,
    RESUME_ROUTE,
    STAND_ON,
    STARBOARD,
    VOCABULARY,
)
from trafficsim.control.guidance import LOOKAHEAD_L, signed_angle
from trafficsim.errors import InputError
from trafficsim.geometry import atan, atan2, cos_sin, hypot_below
from trafficsim.jit import kernel
from trafficsim.sensors import mod_2pi_scalar
from trafficsim.sensors.radar import directed_pairs

#: the bundled rules files (``rules/`` at the top of the project)
RULES_DIR = Path(__file__).resolve().parents[2] / "rules"
BEHAVIOURS = ("colregs", "keep_course", "turn_port", "late_action")
DEFAULT_LOOK_AHEAD_MIN = 30.0  # used when the rules file has no ``look_ahead_min`` parameter
DEFAULT_SLOW_FACTOR = 0.5  # reduced speed of the arbitration's candidates when none is asked
DEFAULT_LOST_TRACK_MIN = 3.0  # used when the rules file has no ``lost_track_min`` parameter
#: resuming keeps every ship this fraction beyond the distance the manoeuvre kept, so that the
#: risk test (a CPA closer than that distance) does not take a released ship back at once
RESUME_MARGIN = 0.1
#: a resuming ship keeps a ship she has passed no nearer than at the passage, at most this
#: times the distance her manoeuvre kept, while she draws ahead of her by at least
#: ``DRAW_AHEAD_MPS`` along her course (a ship keeping pace constrains nothing)
PASSED_FLOOR_FACTOR = 1.5
DRAW_AHEAD_MPS = 0.5
#: for this long after a pair in which both ships keep out of the way (head-on and mutual
#: crossings, Rule 14; restricted visibility, Rule 19) is released, a ship resuming her route
#: checks her way back also against the other ship turning back as she does (by the same
#: course change): both resume at once, each towards her own route line
MIRROR_S = 600.0
_RESTRICTED_VISIBILITY = VOCABULARY.enums["restricted_visibility"]
_NO_ENCOUNTER = VOCABULARY.enums["no_encounter"]
_RESUME_STEPS_RAD = np.radians(np.arange(0.0, 180.0 + 1e-9, 5.0))  # turns back to the route
_AWAY = math.sin(math.radians(5.0))  # a course more than this off the line's leads away
_LINE_TOL_RAD = math.radians(1.0)  # a route course off the line model by more: a new leg
_MEM = {name: len(features.NAMES) + k for k, name in enumerate(MEMORY)}
_NM = 1852.0
_ASKING = (ALTER_COURSE, REDUCE_SPEED, EMERGENCY)


def rules_file(behaviour: str, colregs_rules: str | Path | None = None) -> Path | None:
    """The rules file a behaviour runs (None for ``keep_course``)."""
    if behaviour == "keep_course":
        return None
    if behaviour == "colregs":
        return Path(colregs_rules) if colregs_rules is not None else RULES_DIR / "colregs.yaml"
    return RULES_DIR / f"{behaviour}.yaml"


@dataclass
class BlindSpot:
    """Both ships of a pair held the same role for more than one decision period."""

    ship: int
    other: int
    role: str
    from_s: float
    periods: int = 2


@dataclass
class Decider:
    """Decision networks and memory of every directed pair ``(m,)`` of a batch.

    Attributes:
        networks: the compiled networks in use; ``ship_net`` ``(n,)`` indexes them per ship
            (-1: ``keep_course``).
        obs, tgt: ``(m,)`` observer and target ship of each directed pair (the order of
            :func:`trafficsim.sensors.radar.directed_pairs`, shared with the trackers).
        reverse: ``(m,)`` the index of the pair seen from the other ship.
        memory: ``(len(MEMORY), m)`` pair memory (rows: :data:`~.vocabulary.MEMORY`).
        request: ``(4, m)`` direction, course_change_deg, speed_factor, pass_distance_nm of the
            manoeuvre each pair asks for.
        cursor: ``(m,)`` node each pair resumes at.
        role_since_s, other_cog_at_role, other_sog_at_role: ``(m,)`` when the role was set and
            the other ship's course and speed then.
        base_course_rad: ``(n,)`` course the ship's manoeuvre is taken from: her course over
            ground when it began (NaN: on route).
        base_leg_rad: ``(n,)`` the course of her route leg (:attr:`line_course_rad`) then.
        candidate: ``(n,)`` int the arbitration candidate it runs, kept while it resumes its
            route (-1: none, back on route).
        resuming: ``(n,)`` bool, resuming her route after the last decision step. A manoeuvre
            asked while she resumes takes up the one she ran, from its base course, unless her
            route has turned onto another leg since it began: then it starts afresh from her
            present course.
        course_order_rad, speed_factor: ``(n,)`` the orders (NaN course: follow the route, at
            ``speed_factor`` x route speed).
        kept_distance_m: ``(n,)`` the CPA distance the running manoeuvre keeps; resuming keeps
            it too, plus :data:`RESUME_MARGIN`.
        line_north_m, line_east_m, line_course_rad: ``(n,)`` a point and the course of the
            route leg each ship follows, as inferred from its route course (:meth:`_route_line`).
        cross_track_m: ``(n,)`` each ship's distance from that line, m (+ = starboard of it).
        last_known_s: ``(m,)`` when each observer last knew its target (NaN: never).
        lost_track_s: ``(m,)`` how long a lost track keeps the pair's encounter (the observer's
            rules file's ``lost_track_min``).
        start_cursor: ``(m,)`` the start node of each pair's network.
        passed_range_m: ``(m,)`` while the observer resumes her route, the range at which she
            was first seen ahead of the target's beam with the range opening (she has passed
            her; NaN: not yet): resuming then comes no nearer to the target than that, so
            that the closest approach stays the passage and no cutting back across her bow
            replaces it (Rules 13(d), 8(d)).
    """

    networks: list[network.Network]
    ship_net: np.ndarray
    obs: np.ndarray
    tgt: np.ndarray
    reverse: np.ndarray
    domain: str
    visibility_nm: float
    horizon_s: float
    memory: np.ndarray
    request: np.ndarray
    cursor: np.ndarray
    role_since_s: np.ndarray
    other_cog_at_role: np.ndarray
    other_sog_at_role: np.ndarray
    same_role_periods: np.ndarray
    base_course_rad: np.ndarray
    base_leg_rad: np.ndarray
    candidate: np.ndarray
    resuming: np.ndarray
    course_order_rad: np.ndarray
    speed_factor: np.ndarray
    kept_distance_m: np.ndarray
    line_north_m: np.ndarray
    line_east_m: np.ndarray
    line_course_rad: np.ndarray
    cross_track_m: np.ndarray
    last_known_s: np.ndarray
    mutual_released_s: np.ndarray
    lost_track_s: np.ndarray
    start_cursor: np.ndarray
    passed_range_m: np.ndarray
    blind_spots: list[BlindSpot] = field(default_factory=list)
    last_features: np.ndarray | None = None
    last_decision: list[network.Decision | None] = field(default_factory=list)
    record: bool = False  # keep every decision step for :meth:`records` (scenario runs)
    history: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = field(
        default_factory=list)

    @classmethod
    def build(cls, behaviours: Sequence[str], pair_i: np.ndarray, pair_j: np.ndarray,
              rules: str | Path | None = None, domain: str = "coldwell",
              visibility_nm: float = 10.0) -> Decider:
        """Networks per behaviour and empty memory for the directed pairs of ``pair_i < pair_j``.

        Raises:
            InputError: an unknown behaviour or a faulty rules file (located).
        """
        files: list[Path] = []
        net_of: dict[str, int] = {}  # network index per behaviour (-1: none)
        for name in dict.fromkeys(behaviours):  # distinct, in order of appearance
            if name not in BEHAVIOURS:
                raise InputError(f"unknown behaviour {name!r}; known: {', '.join(BEHAVIOURS)}",
                                 key="behaviour")
            path = rules_file(name, rules)
            if path is not None and path not in files:
                files.append(path)
            net_of[name] = -1 if path is None else files.index(path)
        ship_net = np.array([net_of[name] for name in behaviours], dtype=np.int64)
        nets = [network.load(p, VOCABULARY) for p in files]
        look = [n.rules.parameters.get("look_ahead_min", DEFAULT_LOOK_AHEAD_MIN) for n in nets]
        lost = np.array([60.0 * n.rules.parameters.get("lost_track_min", DEFAULT_LOST_TRACK_MIN)
                         for n in nets] + [math.inf])  # the last: keep_course (no decisions)
        obs, tgt = directed_pairs(pair_i, pair_j)
        m, n = obs.shape[0], len(behaviours)
        half = m // 2
        memory = np.zeros((len(MEMORY), m))
        memory[_MEM["own_role"] - len(features.NAMES)] = NO_ROLE
        memory[_MEM["own_manoeuvre"] - len(features.NAMES)] = NO_ACTION
        memory[_MEM["other_speed_change_ratio"] - len(features.NAMES)] = 1.0
        memory[_MEM["encounter"] - len(features.NAMES)] = VOCABULARY.enums["no_encounter"]
        memory[_MEM["other_role"] - len(features.NAMES)] = NO_ROLE
        cursor = np.zeros(m, dtype=np.int64)
        for k, net in enumerate(nets):
            cursor[ship_net[obs] == k] = net.start
        return cls(
            networks=nets, ship_net=ship_net, obs=obs, tgt=tgt,
            reverse=np.concatenate([np.arange(half, m), np.arange(half)]),
            domain=domain, visibility_nm=float(visibility_nm),
            horizon_s=60.0 * float(max(look, default=DEFAULT_LOOK_AHEAD_MIN)),
            memory=memory, request=np.full((4, m), np.nan), cursor=cursor,
            role_since_s=np.full(m, np.nan), other_cog_at_role=np.full(m, np.nan),
            other_sog_at_role=np.full(m, np.nan), same_role_periods=np.zeros(m, dtype=np.int64),
            base_course_rad=np.full(n, np.nan), base_leg_rad=np.full(n, np.nan),
            candidate=np.full(n, -1, dtype=np.int64), resuming=np.zeros(n, dtype=bool),
            course_order_rad=np.full(n, np.nan), speed_factor=np.ones(n),
            kept_distance_m=np.zeros(n), line_north_m=np.full(n, np.nan),
            line_east_m=np.full(n, np.nan), line_course_rad=np.full(n, np.nan),
            cross_track_m=np.full(n, np.nan),
            last_known_s=np.full(m, np.nan), mutual_released_s=np.full(m, np.nan),
            lost_track_s=lost[ship_net[obs]], start_cursor=cursor.copy(),
            passed_range_m=np.full(m, np.nan))

    def decide(self, t_s: float, own_state: np.ndarray, own_vel: np.ndarray,
               length_m: np.ndarray, other: np.ndarray, route_course_rad: np.ndarray,
               route_speed_mps: np.ndarray) -> None:
        """One decision step at ``t_s``; sets :attr:`course_order_rad`, :attr:`speed_factor`.

        Args:
            own_state: ``(3, n)`` own estimated north, east (m) and heading (rad) per ship.
            own_vel: ``(2, n)`` own estimated velocity over ground north/east, m/s.
            length_m: ``(n,)`` ship lengths (size the own domain).
            other: ``(4, m)`` what each observer knows of its target: north, east (m), velocity
                north, east (m/s); NaN where it knows nothing (no track).
            route_course_rad: ``(n,)`` the course the route guidance asks for now.
            route_speed_mps: ``(n,)`` the route speed.
        """
        o = self.obs
        self._forget_lost(t_s, other)
        self._route_line(own_state, length_m, route_course_rad)
        feats = np.empty((len(FEATURES), o.shape[0]))
        features.pair_features(
            own_state[0, o], own_state[1, o], own_vel[0, o], own_vel[1, o], own_state[2, o],
            length_m[o], other[0], other[1], other[2], other[3], length_m[self.tgt],
            self.domain, self.visibility_nm, self.horizon_s, out=feats[: len(features.NAMES)])
        self._memory_features(t_s, other, route_course_rad)
        feats[len(features.NAMES):] = self.memory
        self.last_features = feats
        self.last_decision = []
        pair_net = self.ship_net[o]
        # pairs in which both ships keep out of the way: head-on and mutual crossings (Rule 14)
        # and restricted visibility (Rule 19: no stand-on ship)
        both_act = ((self._mem("own_role") == MUTUAL_GIVE_WAY)
                    | (self._mem("encounter") == _RESTRICTED_VISIBILITY))
        for k, net in enumerate(self.networks):
            idx = np.flatnonzero(pair_net == k)
            if idx.size == 0:
                self.last_decision.append(None)
                continue
            # (one network for every pair, the common case: no copy of the feature table)
            sub = feats if idx.size == o.shape[0] else feats[:, idx]
            dec = network.evaluate(net, sub, self.cursor[idx])
            self.cursor[idx] = dec.cursor
            self._merge(idx, dec, t_s, other)
            self.last_decision.append(dec)
        self.mutual_released_s[both_act & (self._mem("encounter") == _NO_ENCOUNTER)] = t_s
        self._blind_spots(t_s)
        self._orders(t_s, own_state, own_vel, other, route_course_rad, route_speed_mps)
        if self.record:
            depth = max((n.max_depth for n in self.networks), default=1)
            path = np.full((o.shape[0], depth), -1, dtype=np.int32)
            for k, dec in enumerate(self.last_decision):
                if dec is not None:
                    idx = np.flatnonzero(pair_net == k)
                    path[idx, : dec.path.shape[1]] = dec.path
            self.history.append((t_s, feats, path, self.memory.copy(),
                                 self.course_order_rad.copy()))

    # ------------------------------------------------------------------------------------
    def _mem(self, name: str) -> np.ndarray:
        return self.memory[_MEM[name] - len(features.NAMES)]

    def _memory_features(self, t_s: float, other: np.ndarray,
                         route_course_rad: np.ndarray) -> None:
        _memory_rows(float(t_s), self._mem("own_role"), self.role_since_s,
                     self.other_cog_at_role, self.other_sog_at_role, other,
                     self.course_order_rad, route_course_rad, self.obs,
                     self._mem("time_in_role_min"), self._mem("other_course_change_deg"),
                     self._mem("other_speed_change_ratio"), self._mem("own_course_change_deg"))

    def _merge(self, idx: np.ndarray, dec: network.Decision, t_s: float,
               other: np.ndarray) -> None:
        """Fold a decision's action fields into the memory of the pairs ``idx``
        (:func:`_merge_actions`)."""
        rows = np.array([dec.action_fields.index(f) for f in _MERGED_FIELDS], dtype=np.int64)
        _merge_actions(idx, dec.actions, rows, float(t_s), other, self._mem("own_role"),
                       self._mem("encounter"), self._mem("other_role"),
                       self._mem("own_manoeuvre"), self.role_since_s, self.other_cog_at_role,
                       self.other_sog_at_role, self.request)

    def _blind_spots(self, t_s: float) -> None:
        role = self._mem("own_role")
        same = (role == role[self.reverse]) & ((role == GIVE_WAY) | (role == STAND_ON))
        self.same_role_periods = np.where(same, self.same_role_periods + 1, 0)
        half = self.obs.shape[0] // 2
        new = np.flatnonzero(self.same_role_periods[:half] == 2)  # more than one period
        names = {GIVE_WAY: "give_way", STAND_ON: "stand_on"}
        for p in new:
            self.blind_spots.append(BlindSpot(int(self.obs[p]), int(self.tgt[p]),
                                              names[float(role[p])], float(t_s)))

    def _forget_lost(self, t_s: float, other: np.ndarray) -> None:
        """A pair whose track has been lost for longer than :attr:`lost_track_s` forgets its
        encounter (as at "past and clear": no role, ``resume_route``, back to the start node);
        a later track starts a new encounter."""
        known = np.isfinite(other).all(axis=0)
        self.last_known_s[known] = t_s
        engaged = ((self._mem("own_role") != NO_ROLE) | np.isin(self._mem("own_manoeuvre"), _ASKING)
                   | (self._mem("encounter") != VOCABULARY.enums["no_encounter"]))
        lost = np.flatnonzero(~known & engaged & (t_s - self.last_known_s > self.lost_track_s))
        if lost.size == 0:
            return
        for name in ("own_role", "other_role"):
            self._mem(name)[lost] = NO_ROLE
        self._mem("encounter")[lost] = VOCABULARY.enums["no_encounter"]
        self._mem("own_manoeuvre")[lost] = RESUME_ROUTE
        self.request[:, lost] = np.nan
        self.cursor[lost] = self.start_cursor[lost]
        self.role_since_s[lost] = np.nan

    def _route_line(self, own_state: np.ndarray, length_m: np.ndarray,
                    route_course_rad: np.ndarray) -> None:
        """Keep each ship's model of the route leg it follows (a point and the leg course).

        Route guidance steers ``chi = chi_leg - atan(e / Delta)`` (e the cross-track error,
        Delta = LOOKAHEAD_L ship lengths, [Fossen 2011, eq. 10.73]); where the route course
        differs from what the model predicts by more than 1 deg (the first step, a new leg, a
        course held after the route's end), the model restarts as the line through the present
        position along the route course. Ships start on their route, so the first model is the
        first leg.
        """
        _route_line_model(own_state[0], own_state[1], length_m, route_course_rad,
                          self.line_north_m, self.line_east_m, self.line_course_rad,
                          self.cross_track_m)

    def _resume(self, t_s: float, ships_mask: np.ndarray, own_state: np.ndarray,
                own_vel: np.ndarray, other: np.ndarray, route_course_rad: np.ndarray,
                route_speed_mps: np.ndarray) -> np.ndarray:
        """Turn the masked ships (no pair asks any more) back towards their route as far as is
        safe; return which are released to route guidance at route speed.

        Candidates, each at route speed and at reduced speed (the manoeuvre's, else
        :data:`DEFAULT_SLOW_FACTOR`): the courses in 5 deg steps from the present order towards
        the course of the route line (parallel to it, :meth:`_route_line`) and towards the
        route course (which steers back onto the line); the route course itself is the route.
        A candidate is predicted on straight lines (the other ship's velocity held) both as it
        is steered (what the risk test sees) and as the path it leads to (straight on until it
        meets the route line, then along the line); it is safe when every other ship whose
        state is known passes at least :attr:`kept_distance_m` x (1 + :data:`RESUME_MARGIN`)
        within the look-ahead on both (ships already past their CPA constrain nothing). It
        counts only when the ship reaches it by turning through courses that keep the distance
        itself (the risk test sees every heading on the way), and a turn is tested at the
        present speed too (the speed changes slowly). Preference: the course nearest the route
        course at route speed (the route itself: the ship is released), then the same at
        reduced speed; a course that takes the ship further off her line after those, and
        there reduced speed first where a safe course nearer the route lies beyond headings she
        cannot turn through at route speed (the ship in the way draws clear sooner); running
        alongside a near ship last. With none, the ship keeps her order.

        So a ship does not steer back onto its line behind a slower ship on it: it holds a
        course parallel to the line, passes her, and crosses ahead of her once the range is
        safe (Rule 13(d)). Two ships that both kept out of the way (head-on and mutual
        crossings, restricted visibility), released at the same step, both resume at once,
        each back towards her own line: for :data:`MIRROR_S` after the release a candidate
        must also keep the other ship no nearer than she is now with her velocity turned by
        the candidate's change of course over ground (her return as seen from her; Rule 8(d),
        no new close-quarters situation). It never turns away from its route while resuming,
        and the margin keeps a released ship out of the risk test of the same pair: it does
        not hunt between avoiding and resuming.
        """
        o = self.obs
        n = ships_mask.shape[0]
        r = np.flatnonzero(ships_mask)
        s = r.size
        slot = np.full(n, -1, dtype=np.int64)
        slot[r] = np.arange(s)
        pairs = np.flatnonzero((slot[o] >= 0) & np.isfinite(other).all(axis=0))
        ps = slot[o[pairs]]
        route = route_course_rad[r]
        chi = self.line_course_rad[r]
        e = self.cross_track_m[r]
        ordered = np.where(np.isnan(self.course_order_rad[r]), route, self.course_order_rad[r])
        slow = np.where(self.speed_factor[r] < 1.0, self.speed_factor[r], DEFAULT_SLOW_FACTOR)
        c = np.ascontiguousarray
        found, home, row, course = (np.zeros(s, dtype=bool), np.zeros(s, dtype=bool),
                                    np.zeros(s, dtype=np.int64), np.zeros(s))
        pn = other[0, pairs] - own_state[0, o[pairs]]
        pe = other[1, pairs] - own_state[1, o[pairs]]
        vn, ve = own_vel[0, o[pairs]], own_vel[1, o[pairs]]
        # the own ship ahead of the other's beam, the range opening and she drawing ahead:
        # passed; the range then (at most PASSED_FLOOR_FACTOR x the distance kept) is kept
        # for the rest of the return, while she draws ahead
        wn, we = other[2, pairs], other[3, pairs]
        v2 = vn * vn + ve * ve
        ahead = v2 - (wn * vn + we * ve) > DRAW_AHEAD_MPS * np.sqrt(v2)  # (v - w) . v / |v|
        passing = (np.isnan(self.passed_range_m[pairs]) & ahead & (pn * wn + pe * we < 0.0)
                   & (pn * (wn - vn) + pe * (we - ve) > 0.0))
        self.passed_range_m[pairs[passing]] = np.minimum(
            np.hypot(pn[passing], pe[passing]),
            PASSED_FLOOR_FACTOR * self.kept_distance_m[o[pairs[passing]]])
        passed = np.where(ahead, self.passed_range_m[pairs], np.nan)
        _resume_plan(c(ordered), c(route), c(chi), c(e), c(slow), c(route_speed_mps[r]),
                     c(np.hypot(own_vel[0, r], own_vel[1, r])), c(own_vel[0, r]),
                     c(own_vel[1, r]), c(ps), c(pn), c(pe), c(wn), c(we),
                     c(self.kept_distance_m[o[pairs]]),
                     c(t_s - self.mutual_released_s[pairs] <= MIRROR_S), c(passed),
                     float(self.horizon_s), found, home, row, course)
        on_route = found & home
        factor = np.where(row < 2, 1.0, slow)
        released = np.zeros(n, dtype=bool)
        released[r] = on_route & (row < 2)
        steer = found & ~on_route
        self.course_order_rad[r[steer]] = np.mod(course[steer], 2 * math.pi)
        self.course_order_rad[r[on_route]] = np.nan  # on the route (at reduced speed: resuming)
        self.speed_factor[r[found]] = factor[found]
        return released

    def _orders(self, t_s: float, own_state: np.ndarray, own_vel: np.ndarray,
                other: np.ndarray, route_course_rad: np.ndarray,
                route_speed_mps: np.ndarray) -> None:
        """One manoeuvre per asking ship (arbitration); back to the route when none asks."""
        o = self.obs
        n = self.ship_net.shape[0]
        manoeuvre = self._mem("own_manoeuvre")
        asking = np.isin(manoeuvre, _ASKING) & (self.ship_net[o] >= 0)
        idle = np.ones(n, dtype=bool)
        idle[o[asking]] = False
        ships = np.flatnonzero(~idle)  # the asking ships, ascending
        # asked again while resuming, on a route leg other than the one the manoeuvre began on:
        # its base course is stale, a new manoeuvre starts from the present course
        stale = ~idle & self.resuming & (self.line_course_rad != self.base_leg_rad)
        self.base_course_rad[stale] = np.nan
        self.candidate[stale] = -1
        # back to the route only where it passes every ship at the distance the last manoeuvre
        # kept (Rule 8(d): resuming must not make a new close-quarters situation)
        resuming = idle & (self.candidate >= 0)
        if resuming.any():
            idle &= ~resuming | self._resume(t_s, resuming, own_state, own_vel, other,
                                             route_course_rad, route_speed_mps)
        self.resuming = resuming & ~idle
        self.base_course_rad[idle] = np.nan
        self.candidate[idle] = -1
        self.course_order_rad[idle] = np.nan
        self.speed_factor[idle] = 1.0
        self.kept_distance_m[idle] = 0.0
        self.passed_range_m[idle[o]] = np.nan
        if ships.size == 0:
            return
        start = ships[np.isnan(self.base_course_rad[ships])]
        # the course over ground, the heading where the ship barely moves (features module)
        vn, ve = own_vel[0, start], own_vel[1, start]
        self.base_course_rad[start] = np.where(
            np.hypot(vn, ve) < features.COURSE_MIN_SPEED_MPS, own_state[2, start],
            np.arctan2(ve, vn))
        self.base_leg_rad[start] = self.line_course_rad[start]
        slot = np.full(n, -1, dtype=np.int64)
        slot[ships] = np.arange(ships.size)
        pairs = np.flatnonzero(slot[o] >= 0)
        ps = slot[o[pairs]]
        direction, change, factor, distance = (r[pairs] for r in self.request)
        ask = asking[pairs]
        s = ships.size
        starboard = np.zeros(s, dtype=bool)
        port = np.zeros(s, dtype=bool)
        np.logical_or.at(starboard, ps, ask & (direction == STARBOARD))
        np.logical_or.at(port, ps, ask & (direction == PORT))
        side = np.where(starboard, STARBOARD, np.where(port, PORT, VOCABULARY.enums["either"]))
        least = np.zeros(s)
        np.maximum.at(least, ps, np.where(ask & np.isin(manoeuvre[pairs], (ALTER_COURSE,
                                                                           EMERGENCY)),
                                          np.nan_to_num(change), 0.0))
        # a speed reduction is asked by reduce_speed, or by any asking pair with a factor < 1
        slow = np.ones(s)
        np.minimum.at(slow, ps, np.where(ask, np.nan_to_num(factor, nan=1.0), 1.0))
        reduce = slow < 1.0
        with_reduce = np.zeros(s, dtype=bool)
        np.logical_or.at(with_reduce, ps, ask & (manoeuvre[pairs] == REDUCE_SPEED))
        reduce |= with_reduce
        slow = np.where(slow < 1.0, slow, DEFAULT_SLOW_FACTOR)
        need = np.zeros(s)
        np.maximum.at(need, ps, np.where(ask, np.nan_to_num(distance), 0.0))
        # every pair of the ship keeps at least the ship's largest asked distance (Rule 8(d))
        required = np.maximum(np.where(ask, np.nan_to_num(distance), 0.0), need[ps]) * _NM
        known = np.isfinite(other[:, pairs]).all(axis=0)
        required = np.where(known, required, 0.0)
        rel_n = np.nan_to_num(other[0, pairs] - own_state[0, o[pairs]])
        rel_e = np.nan_to_num(other[1, pairs] - own_state[1, o[pairs]])
        chosen, _ = arbitration.choose(
            self.base_course_rad[ships], route_speed_mps[ships], slow, side,
            np.radians(least), reduce, self.candidate[ships], ps, rel_n, rel_e,
            np.nan_to_num(other[2, pairs]), np.nan_to_num(other[3, pairs]), required,
            self.horizon_s)
        self.candidate[ships] = chosen
        self.kept_distance_m[ships] = need * _NM
        self.course_order_rad[ships] = np.mod(
            self.base_course_rad[ships] + arbitration.candidate_offset_rad(chosen), 2 * math.pi)
        self.speed_factor[ships] = np.where(arbitration.candidate_reduced(chosen), slow, 1.0)

    def records(self, names: Sequence[str]) -> dict[str, list | np.ndarray]:
        """Every recorded decision step as columns, one row per step and directed pair of a
        deciding ship: time, ship, other ship, rules file and the digest of its files
        (:func:`~trafficsim.colregs.network.rules_digest`), the path of nodes (names joined by
        ``>``), the role, encounter, expected role and manoeuvre after the step
        (``decided_*``), the ship's course order, and every feature as the network saw it."""
        rows = np.flatnonzero(self.ship_net[self.obs] >= 0)
        k = len(self.history)
        digests = [network.rules_digest(net.rules.files) for net in self.networks]
        cols: dict[str, list | np.ndarray] = {
            "t_s": np.repeat([h[0] for h in self.history], rows.size),
            "ship": [names[i] for i in self.obs[rows]] * k,
            "other": [names[i] for i in self.tgt[rows]] * k,
            "rules": [str(self.networks[self.ship_net[i]].rules.path)
                      for i in self.obs[rows]] * k,
            "rules_sha1": [digests[self.ship_net[i]] for i in self.obs[rows]] * k,
        }
        paths: list[str] = []
        for _, _, path, _, _ in self.history:
            for p in rows:
                net = self.networks[self.ship_net[self.obs[p]]]
                paths.append(">".join(net.node_names[j] for j in path[p] if j >= 0))
        cols["path"] = paths
        for name in ("own_role", "encounter", "other_role", "own_manoeuvre"):
            row = MEMORY.index(name)
            values = np.concatenate([h[3][row, rows] for h in self.history]) if k else []
            cols[f"decided_{name}"] = [VOCABULARY.enum_names(float(v))[0] for v in values]
        cols["course_order_deg"] = (np.degrees(np.concatenate(
            [h[4][self.obs[rows]] for h in self.history])) % 360.0 if k else np.zeros(0))
        for f, name in enumerate(FEATURES):  # as the network saw them (enums as values)
            cols[name] = (np.concatenate([h[1][f, rows] for h in self.history]) if k
                          else np.zeros(0))
        return cols

    def blind_spot_report(self, names: Sequence[str]) -> list[dict[str, object]]:
        """Blind spots as records: ship, other ship, role, time first seen."""
        return [{"ship": names[b.ship], "other": names[b.other], "role": b.role,
                 "from_s": b.from_s} for b in self.blind_spots]


#: the action fields :meth:`Decider._merge` folds in: four into the pair memory, four requests
_MERGED_FIELDS = ("role", "encounter", "other_role", "manoeuvre", "direction",
                  "course_change_deg", "speed_factor", "pass_distance_nm")


@kernel
def _merge_actions(idx: np.ndarray, actions: np.ndarray, rows: np.ndarray, t_s: float,
                   other: np.ndarray, own_role: np.ndarray, encounter: np.ndarray,
                   other_role: np.ndarray, own_manoeuvre: np.ndarray, role_since_s: np.ndarray,
                   cog_at_role: np.ndarray, sog_at_role: np.ndarray, request: np.ndarray
                   ) -> None:
    """The action fields ``actions[rows]`` (:data:`_MERGED_FIELDS`) of the pairs ``idx``, in
    place: a field set (not NaN) replaces the memory's or the request's value. A new role
    stamps its time and the other ship's course and speed then; a pair that drops its role
    (``no_role``) forgets what it asked before its new requests count (a later encounter starts
    afresh)."""
    mem = (own_role, encounter, other_role, own_manoeuvre)
    for q in range(idx.shape[0]):
        k = idx[q]
        role = actions[rows[0], q]
        if not math.isnan(role) and role != own_role[k]:
            role_since_s[k] = t_s
            cog_at_role[k] = math.atan2(other[3, k], other[2, k])
            sog_at_role[k] = math.hypot(other[2, k], other[3, k])
        for f in range(4):
            value = actions[rows[f], q]
            if not math.isnan(value):
                mem[f][k] = value
        for r in range(4):
            if role == NO_ROLE:
                request[r, k] = math.nan
            value = actions[rows[4 + r], q]
            if not math.isnan(value):
                request[r, k] = value


_DEG_PER_RAD = 180.0 / math.pi  # (the factor of np.degrees)


@kernel
def _memory_rows(t_s: float, own_role: np.ndarray, role_since_s: np.ndarray,
                 cog_at_role: np.ndarray, sog_at_role: np.ndarray, other: np.ndarray,
                 course_order_rad: np.ndarray, route_course_rad: np.ndarray, obs: np.ndarray,
                 time_in_role_min: np.ndarray, other_course_change_deg: np.ndarray,
                 other_speed_change_ratio: np.ndarray, own_course_change_deg: np.ndarray) -> None:
    """The memory features of every directed pair, in place: minutes in the present role, the
    other ship's change of course (deg) and speed (ratio) since the role was taken (0 and 1
    without a role), and the observer's ordered course change from its route (deg, 0 on the
    route). ``other`` ``(4, m)``: what the observer knows of the other ship."""
    for k in range(obs.shape[0]):
        if own_role[k] != NO_ROLE:
            vn, ve = other[2, k], other[3, k]
            cog, sog = atan2(ve, vn), math.sqrt(vn * vn + ve * ve)
            time_in_role_min[k] = (t_s - role_since_s[k]) / 60.0
            other_course_change_deg[k] = abs(signed_angle(cog - cog_at_role[k])) * _DEG_PER_RAD
            floor = sog_at_role[k]
            if not (floor >= 1e-6 or math.isnan(floor)):
                floor = 1e-6
            other_speed_change_ratio[k] = sog / floor
        else:
            time_in_role_min[k], other_course_change_deg[k] = 0.0, 0.0
            other_speed_change_ratio[k] = 1.0
        i = obs[k]
        order = course_order_rad[i]
        own = 0.0 if math.isnan(order) else signed_angle(order - route_course_rad[i])
        own_course_change_deg[k] = own * _DEG_PER_RAD


@kernel
def _route_line_model(north: np.ndarray, east: np.ndarray, length_m: np.ndarray,
                      route_course_rad: np.ndarray, line_north_m: np.ndarray,
                      line_east_m: np.ndarray, line_course_rad: np.ndarray,
                      cross_track_m: np.ndarray) -> None:
    """:meth:`Decider._route_line` over ships, in place: the course guidance would steer on
    the line model, ``chi_leg - atan(e / Delta)``, against the route course asked now; off
    by more than :data:`_LINE_TOL_RAD` (or no model yet), the model restarts through the
    ship's position along the route course (``e = 0``)."""
    for i in range(north.shape[0]):
        c = line_course_rad[i]
        cc, sc = cos_sin(c)
        e = -(north[i] - line_north_m[i]) * sc + (east[i] - line_east_m[i]) * cc
        predicted = c - atan(e / (LOOKAHEAD_L * length_m[i]))  # (guidance's own arctangent)
        if not abs(signed_angle(predicted - route_course_rad[i])) <= _LINE_TOL_RAD:
            line_north_m[i], line_east_m[i] = north[i], east[i]
            line_course_rad[i] = route_course_rad[i]
            e = 0.0
        cross_track_m[i] = e


@kernel
def _resume_plan(ordered: np.ndarray, route: np.ndarray, chi: np.ndarray, e: np.ndarray,
                 slow: np.ndarray, route_speed: np.ndarray, present: np.ndarray,
                 own_vn: np.ndarray, own_ve: np.ndarray, pair_ship: np.ndarray,
                 pn: np.ndarray, pe: np.ndarray, wn: np.ndarray,
                 we: np.ndarray, kept: np.ndarray, mirror: np.ndarray, passed_m: np.ndarray,
                 horizon_s: float, found: np.ndarray, home: np.ndarray, chosen_row: np.ndarray,
                 chosen_course: np.ndarray) -> None:
    """The candidates of :meth:`Decider._resume` and the choice among them, per resuming ship.

    Per ship (``ordered`` present course order, ``route`` route course, ``chi`` the route
    line's course, ``e`` cross-track error, ``slow`` reduced-speed factor) and its pairs (as
    :func:`_resume_margins`; ``mirror``: also with the other ship turned by each candidate's
    course change): rows (route speed, reduced speed) x (towards the line's course,
    towards the route course), steps :data:`_RESUME_STEPS_RAD`; out per ship whether a
    candidate was ``found``, whether it is the route itself (``home``), its row and course.
    One ship at a time in scratch arrays of its candidates, which stay in the first-level
    cache (arrays over all ships' candidates cost more to allocate and fill than the test).
    """
    s, k = ordered.shape[0], _RESUME_STEPS_RAD.size
    c1, s1, meet = np.empty((4, k)), np.empty((4, k)), np.empty((4, k))
    course, across, speed = np.empty((4, k)), np.empty((4, k)), np.empty(4)
    turned_home = np.empty((4, k), dtype=np.bool_)
    keeps, clears = np.empty((4, k), dtype=np.bool_), np.empty((4, k), dtype=np.bool_)
    alongside = np.empty((4, k), dtype=np.bool_)
    present_short, present_close = np.empty((2, k), np.bool_), np.empty((2, k), np.bool_)
    # per row, the steps before the turns clipped at the target course (which repeat the last)
    end = np.empty(4, dtype=np.int64)
    # the pairs of each ship, in their order (a counting sort by ship)
    first = np.zeros(s + 1, dtype=np.int64)
    for p in range(pair_ship.shape[0]):
        first[pair_ship[p] + 1] += 1
    for i in range(s):
        first[i + 1] += first[i]
    fill, by_ship = first[:-1].copy(), np.empty(pair_ship.shape[0], dtype=np.int64)
    for p in range(pair_ship.shape[0]):
        by_ship[fill[pair_ship[p]]] = p
        fill[pair_ship[p]] += 1
    deg = 180.0 / math.pi
    for i in range(s):
        c2, s2 = cos_sin(chi[i])
        for row in range(4):
            speed[row] = route_speed[i] * (1.0 if row < 2 else slow[i])
            if row >= 2:  # the courses of rows 0 and 1 at the reduced speed
                end[row] = end[row - 2]
                for step in range(end[row]):
                    turned_home[row, step] = turned_home[row - 2, step]
                    course[row, step] = course[row - 2, step]
                    c1[row, step], s1[row, step] = c1[row - 2, step], s1[row - 2, step]
                    across[row, step] = across[row - 2, step]
                    meet[row, step] = meet[row - 2, step]
                continue
            target = chi[i] if row % 2 == 0 else route[i]
            back = mod_2pi_scalar(target - ordered[i] + math.pi) - math.pi
            sign = 1.0 if back > 0.0 else (-1.0 if back < 0.0 else (0.0 if back == 0.0 else back))
            end[row] = k
            for step in range(k):
                turn = sign * min(_RESUME_STEPS_RAD[step], abs(back))
                cs = ordered[i] + turn
                if step >= 2 and cs == course[row, step - 1]:  # clipped: so are those after
                    end[row] = step
                    break
                turned_home[row, step] = abs(turn) >= abs(back) - 1e-9 and row % 2 == 1
                course[row, step] = cs
                if step == 1 and cs == course[row, 0]:  # no turn: step 0's course again
                    c1[row, 1], s1[row, 1] = c1[row, 0], s1[row, 0]
                    across[row, 1], meet[row, 1] = across[row, 0], meet[row, 0]
                    continue
                c1[row, step], s1[row, step] = cos_sin(cs)
                a = cos_sin(cs - chi[i])[1]  # cross-track rate per unit speed
                across[row, step] = a
                meet[row, step] = -e[i] / a if e[i] * a < -1e-9 else math.inf
        keeps[:], clears[:], alongside[:] = True, True, False
        # the own ship's course over ground now: the other ship, resuming at the same time,
        # has turned as far as she has (mirror hypothesis)
        v = math.sqrt(own_vn[i] * own_vn[i] + own_ve[i] * own_ve[i])
        co, so = (own_vn[i] / v, own_ve[i] / v) if v > 1e-9 else cos_sin(ordered[i])
        for j in range(first[i], first[i + 1]):
            p = by_ship[j]
            _resume_margins(c1, s1, c2, s2, meet, speed, end, present[i], pn[p], pe[p],
                            wn[p], we[p], kept[p], horizon_s, keeps, clears, alongside,
                            present_short, present_close, math.nan, math.nan)
            if mirror[p]:  # ... and no nearer than she is now (no new close quarters)
                now = math.sqrt(pn[p] * pn[p] + pe[p] * pe[p]) / (1.0 + RESUME_MARGIN)
                _resume_margins(c1, s1, c2, s2, meet, speed, end, present[i], pn[p], pe[p],
                                wn[p], we[p], max(kept[p], now), horizon_s, keeps, clears,
                                alongside, present_short, present_close, co, so)
            if passed_m[p] > 0.0:  # no nearer to a ship passed than at the passage
                _resume_margins(c1, s1, c2, s2, meet, speed, end, present[i], pn[p], pe[p],
                                wn[p], we[p], max(kept[p], passed_m[p] / (1.0 + RESUME_MARGIN)),
                                horizon_s, keeps, clears, alongside, present_short,
                                present_close, math.nan, math.nan, True)
        # a course further off the line comes after a reduced speed; there, where a safe
        # course nearer the route lies beyond courses not to be turned through at route speed,
        # a reduced speed first (the ship in the way draws clear sooner)
        blocked = False
        for row in range(2):
            clear = True
            for step in range(end[row]):
                clear = clear and clears[row, step]
                if keeps[row, step] and not clear:
                    blocked = True
        best, best_row, best_step = math.inf, 0, 0
        for row in range(4):
            clear = True  # every course turned through on the way keeps the distance
            for step in range(end[row]):
                clear = clear and clears[row, step]
                cs = course[row, step]
                # (a candidate repeating the one before is no better and reached no sooner)
                if not (clear and keeps[row, step]) or (
                        step > 0 and cs == course[row, step - 1]):
                    continue
                off = abs(mod_2pi_scalar(cs - route[i] + math.pi) - math.pi)
                away = e[i] * across[row, step] > _AWAY * abs(e[i])
                cost = (off * deg - 1.0 * turned_home[row, step]
                        + 5000.0 * alongside[row, step] + 2000.0 * away
                        + 1000.0 * ((row >= 2) != blocked))
                if cost < best:
                    best, best_row, best_step = cost, row, step
        found[i] = math.isfinite(best)  # none: the ship keeps its order
        home[i] = found[i] and turned_home[best_row, best_step]
        chosen_row[i] = best_row
        chosen_course[i] = course[best_row, best_step]


@kernel
def _resume_margins(c1: np.ndarray, s1: np.ndarray, c2: float, s2: float, meet_m: np.ndarray,
                    speed: np.ndarray, end: np.ndarray, present: float, pn: float, pe: float,
                    wn: float, we: float, kept: float, horizon_s: float, keeps: np.ndarray,
                    clears: np.ndarray, alongside: np.ndarray, present_short: np.ndarray,
                    present_close: np.ndarray, co: float, so: float,
                    path_only: bool = False) -> None:
    """The safety of one ship's :meth:`Decider._resume` candidates against one pair, in place.

    The other ship is at ``pn, pe`` relative, velocity ``wn, we``; candidate ``(row, step)``
    of course ``(c1, s1)`` (cos, sin) at ``speed[row]``, and at the ``present`` speed for the
    turns (step > 0): the closest approach as steered (straight on) and along the path it
    leads to (straight on for ``meet_m`` until the route line of direction ``(c2, s2)``, then
    along it). ``keeps`` is cleared where either comes closer than the kept distance with
    :data:`RESUME_MARGIN`, ``clears`` where the steered one comes closer than the kept
    distance; ``alongside`` marks a near ship passed at little relative speed. Only the sides
    of the distances are needed, told by the squares
    (:func:`~trafficsim.geometry.hypot_below`); a closest approach that is not a number (a
    position that is not, at no relative speed) constrains nothing, and where the path's first
    leg gives one its second leg is not looked at. Rows 2 and 3 repeat the courses of rows 0
    and 1 at the reduced speed, so at the present speed they take the verdicts of those rows
    (``present_short``, ``present_close``: scratch). Row ``row`` is looked at up to step
    ``end[row]``: the turns beyond are clipped at the target course and repeat the last.
    With ``co, so`` (cos, sin of the own ship's course over ground; NaN: not) the other ship's
    velocity is turned by each candidate's course change from it (the mirror hypothesis of
    :meth:`Decider._resume`; no running alongside is marked then). With ``path_only`` only the
    path counts (``keeps``; nothing is marked in ``clears`` or ``alongside``).
    """
    n_rows = c1.shape[0]
    mirror = not math.isnan(co)
    keep = kept * (1.0 + RESUME_MARGIN)
    near = (not mirror and not path_only
            and hypot_below(pn, pe, arbitration.ALONGSIDE_RANGE_FACTOR * keep))
    vn, ve = wn, we
    for row in range(n_rows):
        for step in range(end[row]):
            if mirror:  # turned by the change from the own course over ground to this one
                cd = c1[row, step] * co + s1[row, step] * so
                sd = s1[row, step] * co - c1[row, step] * so
                vn, ve = wn * cd - we * sd, wn * sd + we * cd
            short = close = False
            for variant in range(2):
                if variant == 1 and step == 0:
                    continue
                if variant == 1 and row >= 2:  # rows 2, 3: the courses of rows 0, 1
                    too_short, too_close = present_short[row - 2, step], present_close[
                        row - 2, step]
                else:
                    too_short, too_close = _too_close(
                        pn, pe, vn, ve, speed[row] if variant == 0 else present,
                        c1[row, step], s1[row, step], meet_m[row, step], c2, s2, horizon_s,
                        kept, keep, path_only)
                    if variant == 1:
                        present_short[row, step], present_close[row, step] = (too_short,
                                                                              too_close)
                short, close = short or too_short, close or too_close
            keeps[row, step] &= not short
            clears[row, step] &= not close
            if near:
                sp = speed[row]
                dvn = wn - sp * c1[row, step]
                dve = we - sp * s1[row, step]
                if dvn * dvn + dve * dve < arbitration.ALONGSIDE_SPEED_MPS**2:
                    alongside[row, step] = True


@kernel
def _too_close(pn: float, pe: float, wn: float, we: float, v: float, c1: float, s1: float,
               meet_m: float, c2: float, s2: float, horizon_s: float, kept: float, keep: float,
               path_only: bool = False) -> tuple[bool, bool]:
    """Whether one candidate, course ``(c1, s1)`` (cos, sin) at speed ``v``, passes the other
    ship (at ``pn, pe``, velocity ``wn, we``) nearer than ``keep`` - straight on (unless
    ``path_only``), or along its path: straight on for ``meet_m``, then along the route line
    ``(c2, s2)`` - and whether straight on nearer than ``kept`` (:func:`_resume_margins`)."""
    dn1, de1 = wn - v * c1, we - v * s1
    close = short = False
    if not path_only:
        a, b = arbitration.closest_offset(pn, pe, dn1, de1, horizon_s)
        close, short = hypot_below(a, b, kept), hypot_below(a, b, keep)
    if not short:
        t1 = min(meet_m / max(v, 1e-9), horizon_s)
        a, b = arbitration.closest_offset(pn, pe, dn1, de1, t1)
        short = hypot_below(a, b, keep)
        if not short and t1 < horizon_s and not _nan_range(a, b):
            a, b = arbitration.closest_offset(pn + dn1 * t1, pe + de1 * t1, wn - v * c2,
                                              we - v * s2, horizon_s - t1)
            short = hypot_below(a, b, keep)
    return short, close


@kernel
def _nan_range(a: float, b: float) -> bool:
    """Whether ``math.hypot(a, b)`` is not a number (a NaN and no infinity)."""
    return (math.isnan(a) or math.isnan(b)) and not (math.isinf(a) or math.isinf(b))
