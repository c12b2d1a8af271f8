"""The decision step: features, decision networks, pair memory, one manoeuvre per ship.

Every decision period (default 10 s) :meth:`Decider.decide`

1. computes the encounter features of every directed pair (own ship, other ship) of every
   encounter from what the own ship knows (its own estimate; the other ship's track, or its
   true state where the own ship carries no radar or AIS) [seed 002, appendix F: "certain
   minimal information ... speed, course, relative position"];
2. evaluates each ship's decision network for all its pairs at once
   (:func:`trafficsim.colregs.network.evaluate`), starting each pair where its previous
   decision left it;
3. merges the actions into the pair's memory (role, encounter, expected role of the other, the
   manoeuvre asked of the own ship and its parameters: kept until a node sets them again, so a
   role holds until "past and clear", Rule 13(d));
4. gives each ship one manoeuvre that satisfies all its pairs at once
   (:mod:`trafficsim.colregs.arbitration`, Rule 8(d)), or returns it to its route when no pair
   asks for a manoeuvre;
5. records blind spots: pairs where both ships hold the same role (both give-way or both
   stand-on) for more than one decision period, the first fault of the 500-encounter study of
   [seed 002, appendix F, "Analysis of simulation results"].

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
    NO_ACTION,
    NO_ROLE,
    PORT,
    REDUCE_SPEED,
    STAND_ON,
    STARBOARD,
    VOCABULARY,
)
from trafficsim.errors import InputError
from trafficsim.sensors.radar import directed_pairs

#: the bundled rules files (``rules/`` at the top of the project)
RULES_DIR = Path(__file__).resolve().parents[2] / "rules"
BEHAVIOURS = ("colregs", "keep_course", "turn_port", "late_action")
DEFAULT_LOOK_AHEAD_MIN = 30.0  # used when the rules file has no ``look_ahead_min`` parameter
DEFAULT_SLOW_FACTOR = 0.5  # reduced speed of the arbitration's candidates when none is asked
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
        base_course_rad: ``(n,)`` course the ship's manoeuvre is taken from (NaN: on route).
        candidate: ``(n,)`` int the arbitration candidate it runs (-1: none).
        course_order_rad, speed_factor: ``(n,)`` the orders (NaN course: follow the route).
        kept_distance_m: ``(n,)`` the CPA distance the running manoeuvre keeps; the route is
            resumed only where its course keeps it too.
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
    candidate: np.ndarray
    course_order_rad: np.ndarray
    speed_factor: np.ndarray
    kept_distance_m: np.ndarray
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
        ship_net = np.full(len(behaviours), -1, dtype=np.int64)
        for k, name in enumerate(behaviours):
            if name not in BEHAVIOURS:
                raise InputError(f"unknown behaviour {name!r}; known: {', '.join(BEHAVIOURS)}",
                                 key="behaviour")
            path = rules_file(name, rules)
            if path is None:
                continue
            if path not in files:
                files.append(path)
            ship_net[k] = files.index(path)
        nets = [network.load(p, VOCABULARY) for p in files]
        look = [n.rules.parameters.get("look_ahead_min", DEFAULT_LOOK_AHEAD_MIN) for n in nets]
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
            base_course_rad=np.full(n, np.nan), candidate=np.full(n, -1, dtype=np.int64),
            course_order_rad=np.full(n, np.nan), speed_factor=np.ones(n),
            kept_distance_m=np.zeros(n))

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
        feats = np.empty((len(FEATURES), o.shape[0]))
        geo = features.pair_features(
            own_state[0, o], own_state[1, o], own_vel[0, o], own_vel[1, o], own_state[2, o],
            length_m[o], other[0], other[1], other[2], other[3], length_m[self.tgt],
            self.domain, self.visibility_nm, self.horizon_s)
        feats[: len(features.NAMES)] = geo.values
        self._memory_features(t_s, other, route_course_rad)
        feats[len(features.NAMES):] = self.memory
        self.last_features = feats
        self.last_decision = []
        pair_net = self.ship_net[o]
        for k, net in enumerate(self.networks):
            idx = np.flatnonzero(pair_net == k)
            if idx.size == 0:
                self.last_decision.append(None)
                continue
            dec = network.evaluate(net, feats[:, idx], self.cursor[idx])
            self.cursor[idx] = dec.cursor
            self._merge(idx, dec, t_s, other)
            self.last_decision.append(dec)
        self._blind_spots(t_s)
        self._orders(own_state, own_vel, other, route_course_rad, route_speed_mps)
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
        has_role = self._mem("own_role") != NO_ROLE
        cog = np.arctan2(other[3], other[2])
        sog = np.hypot(other[2], other[3])
        self._mem("time_in_role_min")[:] = np.where(has_role, (t_s - self.role_since_s) / 60.0,
                                                    0.0)
        change = np.abs((cog - self.other_cog_at_role + math.pi) % (2 * math.pi) - math.pi)
        self._mem("other_course_change_deg")[:] = np.where(has_role, np.degrees(change), 0.0)
        ratio = sog / np.maximum(self.other_sog_at_role, 1e-6)
        self._mem("other_speed_change_ratio")[:] = np.where(has_role, ratio, 1.0)
        own = np.where(np.isnan(self.course_order_rad), 0.0,
                       (self.course_order_rad - route_course_rad + math.pi) % (2 * math.pi)
                       - math.pi)
        self._mem("own_course_change_deg")[:] = np.degrees(own)[self.obs]

    def _merge(self, idx: np.ndarray, dec: network.Decision, t_s: float,
               other: np.ndarray) -> None:
        """Fold a decision's action fields into the memory of the pairs ``idx``."""
        role = dec.action("role")
        new_role = ~np.isnan(role) & (role != self._mem("own_role")[idx])
        changed = idx[new_role]
        self.role_since_s[changed] = t_s
        self.other_cog_at_role[changed] = np.arctan2(other[3, changed], other[2, changed])
        self.other_sog_at_role[changed] = np.hypot(other[2, changed], other[3, changed])
        for field_name, mem_name in (("role", "own_role"), ("encounter", "encounter"),
                                     ("other_role", "other_role"),
                                     ("manoeuvre", "own_manoeuvre")):
            value = dec.action(field_name)
            row = self._mem(mem_name)
            row[idx] = np.where(np.isnan(value), row[idx], value)
        # a pair that drops its role forgets what it asked (a later encounter starts afresh)
        dropped = idx[(role == NO_ROLE)]
        self.request[:, dropped] = np.nan
        for r, field_name in enumerate(("direction", "course_change_deg", "speed_factor",
                                        "pass_distance_nm")):
            value = dec.action(field_name)
            self.request[r, idx] = np.where(np.isnan(value), self.request[r, idx], value)

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

    def _return_towards_route(self, ships_mask: np.ndarray, own_state: np.ndarray,
                              other: np.ndarray, route_course_rad: np.ndarray,
                              route_speed_mps: np.ndarray) -> np.ndarray:
        """Turn the masked ships back towards their route as far as is safe.

        Courses from the present order to the route course in quarters are tried; a course is
        safe when every other ship passes at least :attr:`kept_distance_m` within the
        look-ahead (straight lines). A ship whose route course is safe is released (returned
        True); the others steer the safe course nearest to the route, or keep their order.
        """
        o = self.obs
        n = ships_mask.shape[0]
        pairs = np.flatnonzero(ships_mask[o] & np.isfinite(other).all(axis=0))
        ob = o[pairs]
        current = np.where(np.isnan(self.course_order_rad), route_course_rad,
                           self.course_order_rad)
        back = (route_course_rad - current + math.pi) % (2 * math.pi) - math.pi
        new_course = current.copy()
        released = np.zeros(n, dtype=bool)
        for fraction in (0.25, 0.5, 0.75, 1.0):  # four vectorised tries, not a loop over ships
            course = current + fraction * back
            vn = route_speed_mps * self.speed_factor * np.cos(course)
            ve = route_speed_mps * self.speed_factor * np.sin(course)
            pn, pe = other[0, pairs] - own_state[0, ob], other[1, pairs] - own_state[1, ob]
            dvn, dve = other[2, pairs] - vn[ob], other[3, pairs] - ve[ob]
            v2 = np.maximum(dvn * dvn + dve * dve, 1e-12)
            tcpa = -(pn * dvn + pe * dve) / v2
            t = np.clip(tcpa, 0.0, self.horizon_s)
            closest = np.hypot(pn + dvn * t, pe + dve * t)
            bad = (tcpa > 0) & (closest < self.kept_distance_m[ob])
            safe = ships_mask.copy()
            safe[ob[bad]] = False
            new_course = np.where(safe, course, new_course)
            released = safe if fraction == 1.0 else released
        turning = ships_mask & ~released
        self.course_order_rad[turning] = np.mod(new_course[turning], 2 * math.pi)
        return released

    def _orders(self, own_state: np.ndarray, own_vel: np.ndarray, other: np.ndarray,
                route_course_rad: np.ndarray, route_speed_mps: np.ndarray) -> None:
        """One manoeuvre per asking ship (arbitration); back to the route when none asks."""
        o = self.obs
        n = self.ship_net.shape[0]
        manoeuvre = self._mem("own_manoeuvre")
        asking = np.isin(manoeuvre, _ASKING) & (self.ship_net[o] >= 0)
        ships = np.unique(o[asking])
        idle = np.ones(n, dtype=bool)
        idle[ships] = False
        # back to the route only where its course passes every ship at the distance the last
        # manoeuvre kept (Rule 8(d): resuming must not make a new close-quarters situation)
        resuming = idle & (self.candidate >= 0)
        if resuming.any():
            idle &= ~resuming | self._return_towards_route(resuming, own_state, other,
                                                           route_course_rad, route_speed_mps)
        self.base_course_rad[idle] = np.nan
        self.candidate[idle] = -1
        self.course_order_rad[idle] = np.nan
        self.speed_factor[idle] = 1.0
        self.kept_distance_m[idle] = 0.0
        if ships.size == 0:
            return
        start = np.isnan(self.base_course_rad[ships])
        course_now = np.arctan2(own_vel[1], own_vel[0])
        self.base_course_rad[ships[start]] = course_now[ships[start]]
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
        deciding ship: time, ship, other ship, rules file, the path of nodes (names joined by
        ``>``), the role, encounter, expected role and manoeuvre after the step
        (``decided_*``), the ship's course order, and every feature as the network saw it."""
        rows = np.flatnonzero(self.ship_net[self.obs] >= 0)
        k = len(self.history)
        cols: dict[str, list | np.ndarray] = {
            "t_s": np.repeat([h[0] for h in self.history], rows.size),
            "ship": [names[i] for i in self.obs[rows]] * k,
            "other": [names[i] for i in self.tgt[rows]] * k,
            "rules": [str(self.networks[self.ship_net[i]].rules.path)
                      for i in self.obs[rows]] * k,
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
