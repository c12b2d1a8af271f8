"""One manoeuvre per ship that satisfies every encounter at once (Rule 8(d)).

Each pair's decision asks something of the own ship (alter course to a side by at least some
angle, reduce speed, pass at some distance). A ship with several threats gets ONE manoeuvre: the
mildest candidate (course offset from the ship's base course, speed factor) on the requested
side whose predicted distance at the closest point of approach is at least the required one for
EVERY other ship around it - those that asked for the manoeuvre and those that did not, so that
avoiding one ship creates no new close-quarters situation with another (Rule 8(d)).

The requested side is a rule, not a preference: a turn to starboard asked by Rules 14(a), 15,
17(c) or 19(d) is never replaced by a turn to port because only the port turn passes far
enough. Where no candidate on the requested side satisfies every pair, the one on that side
with the largest worst-case margin is taken (a speed reduction on the base course belongs to
both sides, Rule 8(e)).

Candidates: course offsets -90..+90 degrees in 5 degree steps, each at full speed and at the
requested reduced speed. Preference: starboard first where either side is allowed, the
smallest alteration at or above the requested least one (a large, readily apparent alteration
rather than a succession of small ones, Rule 8(b)), full speed before reduced speed (a speed
reduction only where it is asked for or the alteration alone does not suffice, Rule 8(e)), and
a reduced speed before running alongside a near ship at little relative speed (which leaves the
encounter unresolved). Where no alteration as large as asked is safe, a speed reduction on the
base course comes before a smaller alteration (Rule 8(e) has a ship slacken her speed where
necessary; Rule 8(b) advises against small alterations).

A ship already manoeuvring keeps its manoeuvre while it still satisfies every pair and does not
run alongside a ship. The turn and the change of speed take time that the straight-line
prediction does not see, so a manoeuvre chosen on the limit may soon fall short; replaced by the
next that just suffices, it would be followed by another, a little larger, and so on (the
succession of small alterations Rule 8(b) advises against). A manoeuvre that does fall short is
replaced by one that differs from it substantially: by at least ``APPARENT_CHANGE_DEG`` in
course (half Woerner/Minne's readily apparent course change of 30 deg, colregs.md section 2.3,
added to an alteration that was already that large; or all the way to the largest offset), or
by its speed alone (their readily apparent speed reduction is to 50 %); and by a larger
alteration before a smaller one, which would undo part of the manoeuvre (towards the ship it
avoids, as a rule).

Prediction: straight lines, own velocity = factor x route speed along the candidate course, the
other ship's estimated velocity held (the DCPA of [colregs.md section 4]), closest approach
counted within the look-ahead. Pairs already past their CPA (TCPA <= 0) constrain nothing.
"""

from __future__ import annotations

import math

import numpy as np

from trafficsim.colregs.vocabulary import PORT, STARBOARD
from trafficsim.geometry import cos_sin, hypot_below
from trafficsim.jit import kernel

#: candidate course offsets, rad (+ = starboard), and whether a candidate runs at reduced speed
LARGEST_OFFSET_DEG = 90.0
OFFSETS_RAD = np.radians(np.arange(-LARGEST_OFFSET_DEG, LARGEST_OFFSET_DEG + 1e-9, 5.0))
_OFF = np.concatenate([OFFSETS_RAD, OFFSETS_RAD])
_REDUCED = np.concatenate([np.zeros(OFFSETS_RAD.size, bool), np.ones(OFFSETS_RAD.size, bool)])
N_CANDIDATES = _OFF.size
#: a candidate that leaves a ship within this many required distances at a relative speed below
#: ALONGSIDE_SPEED_MPS runs alongside it: allowed, but only when nothing else is safe
ALONGSIDE_RANGE_FACTOR = 2.0
ALONGSIDE_SPEED_MPS = 1.0
#: a replaced manoeuvre's course changes by at least this much, or only its speed changes:
#: half the readily apparent course change of colregs.md section 2.3 (30 deg), on top of an
#: alteration that was already at least that (the rules' turn_deg)
APPARENT_CHANGE_DEG = 15.0


def candidate_offset_rad(k: np.ndarray) -> np.ndarray:
    """Course offset of candidate ``k``, rad."""
    return _OFF[k]


def candidate_reduced(k: np.ndarray) -> np.ndarray:
    """Whether candidate ``k`` runs at the reduced speed."""
    return _REDUCED[k]


def choose(base_course_rad: np.ndarray, route_speed_mps: np.ndarray, speed_factor: np.ndarray,
           side: np.ndarray, least_change_rad: np.ndarray, reduce_asked: np.ndarray,
           current: np.ndarray, pair_ship: np.ndarray, rel_north_m: np.ndarray,
           rel_east_m: np.ndarray, oth_vn_mps: np.ndarray, oth_ve_mps: np.ndarray,
           required_m: np.ndarray, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Choose a candidate for each of ``s`` manoeuvring ships (one compiled loop over the ships
    and their pairs).

    Args:
        base_course_rad: ``(s,)`` course the offsets are taken from (the course over ground
            when the manoeuvre began), rad.
        route_speed_mps: ``(s,)`` speed over ground at full speed, m/s.
        speed_factor: ``(s,)`` fraction of the route speed of the reduced-speed candidates.
        side: ``(s,)`` ``STARBOARD``, ``PORT`` or ``EITHER`` (vocabulary constants; any value
            but the first two allows both sides).
        least_change_rad: ``(s,)`` smallest course alteration asked for, rad (0: none asked).
        reduce_asked: ``(s,)`` bool, a speed reduction was asked for.
        current: ``(s,)`` int candidate the ship is running, -1 for none.
        pair_ship: ``(q,)`` int, which of the ``s`` ships each pair belongs to.
        rel_north_m, rel_east_m: ``(q,)`` other ship minus own ship position, m.
        oth_vn_mps, oth_ve_mps: ``(q,)`` other ship's velocity over ground, m/s.
        required_m: ``(q,)`` distance at CPA the pair needs, m (0: no constraint).
        horizon_s: look-ahead: a later CPA counts by the range at its end, s.

    Returns:
        ``(s,)`` int chosen candidate and ``(s,)`` bool whether it satisfies every pair.
    """
    s = np.shape(base_course_rad)[0]
    chosen, ok = np.empty(s, dtype=np.int64), np.empty(s, dtype=bool)
    f = np.ascontiguousarray
    _choose(f(base_course_rad, float), f(route_speed_mps, float), f(speed_factor, float),
            f(side, float), f(np.degrees(least_change_rad), float), f(reduce_asked, bool),
            f(current, np.int64), f(pair_ship, np.int64), f(rel_north_m, float),
            f(rel_east_m, float), f(oth_vn_mps, float), f(oth_ve_mps, float),
            f(required_m, float), float(horizon_s), _COS_OFF, _SIN_OFF, _OFF_DEG, _REDUCED,
            chosen, ok)
    return chosen, ok


_OFF_DEG, _COS_OFF, _SIN_OFF = np.degrees(_OFF), np.cos(_OFF), np.sin(_OFF)


@kernel
def closest_offset(pn: float, pe: float, dvn: float, dve: float, span_s: float
                   ) -> tuple[float, float]:
    """The other ship's position relative to the own ship at the closest approach over the next
    ``span_s`` on straight lines, where the range closes now; ``(inf, inf)`` where it opens.

    ``pn, pe``, ``dvn, dve``: the other ship's position and velocity relative to the own ship.
    A later CPA counts by the position at the end of the span (a slowly closing ship on a nearly
    parallel course counts by where it will be then, not at its late CPA); no relative motion
    keeps the present position (it counts: it is not past the CPA); a pair already past its CPA
    (range opening) constrains nothing. The closed-form DCPA/TCPA of straight tracks
    [colregs.md section 4]; closing is told by the sign of the product itself (``-dot / v2``
    can underflow to 0 at a tiny range).
    """
    v2 = dvn * dvn + dve * dve
    dot = pn * dvn + pe * dve
    if not (dot < 0.0 or v2 <= 1e-12):
        return math.inf, math.inf
    t = -dot / max(v2, 1e-12) if v2 > 1e-12 else 0.0
    t = min(max(t, 0.0), span_s)
    return pn + dvn * t, pe + dve * t


@kernel
def closest_m(pn: float, pe: float, dvn: float, dve: float, span_s: float) -> float:
    """Closest range over the next ``span_s`` (:func:`closest_offset`; +inf where the range
    opens)."""
    a, b = closest_offset(pn, pe, dvn, dve, span_s)
    return math.hypot(a, b)


@kernel
def _choose(base: np.ndarray, speed: np.ndarray, factor: np.ndarray, side: np.ndarray,
            least_deg: np.ndarray, reduce_asked: np.ndarray, current: np.ndarray,
            pair_ship: np.ndarray, pn: np.ndarray, pe: np.ndarray, ovn: np.ndarray,
            ove: np.ndarray, required: np.ndarray, horizon_s: float, cos_off: np.ndarray,
            sin_off: np.ndarray, off_deg: np.ndarray, reduced: np.ndarray, chosen: np.ndarray,
            ok_out: np.ndarray) -> None:
    """:func:`choose`, ship by ship over the ship's pairs: a running manoeuvre on the requested
    side that still keeps every pair's distance without running alongside a ship is kept, the
    only candidate looked at (most ships at most decision steps); otherwise, per candidate,
    whether it keeps every pair's distance and whether it runs alongside a ship; then, on the
    requested side, the cheapest candidate keeping every distance by the preference cost of
    the module docstring. Safety needs only the sign of each margin, told by the squares
    (:func:`~trafficsim.geometry.hypot_below`); the worst margins themselves are worked out
    only for a ship with no safe candidate on the requested side, which takes the largest."""
    s, n_cand, q = base.shape[0], off_deg.shape[0], pair_ship.shape[0]
    first = np.zeros(s + 1, dtype=np.int64)  # the pairs of ship i: mine[first[i]:first[i + 1]]
    for p in range(q):
        first[pair_ship[p] + 1] += 1
    for i in range(s):
        first[i + 1] += first[i]
    mine, fill = np.empty(q, dtype=np.int64), first[:s].copy()
    for p in range(q):
        mine[fill[pair_ship[p]]] = p
        fill[pair_ship[p]] += 1
    safe = np.empty(n_cand, dtype=np.bool_)
    alongside = np.empty(n_cand, dtype=np.bool_)
    worst = np.empty(n_cand)
    for i in range(s):
        cb, sb = cos_sin(base[i])
        pairs = mine[first[i]:first[i + 1]]
        run = current[i]
        run_deg = math.nan
        if run >= 0:
            run_deg = off_deg[run]
            if not _wrong_side(side[i], run_deg):
                keeps, beside = _verdict(cb, sb, speed[i], factor[i], reduced[run],
                                         cos_off[run], sin_off[run], pairs, pn, pe, ovn, ove,
                                         required, horizon_s)
                if keeps and not beside:  # a running manoeuvre still satisfying every pair
                    chosen[i], ok_out[i] = run, True
                    continue
        stuck = True  # nothing safe on the requested side
        for k in range(n_cand):
            if _wrong_side(side[i], off_deg[k]):  # never eligible: no verdict needed
                safe[k], alongside[k] = False, False
                continue
            safe[k], alongside[k] = _verdict(cb, sb, speed[i], factor[i], reduced[k],
                                             cos_off[k], sin_off[k], pairs, pn, pe, ovn, ove,
                                             required, horizon_s)
            stuck = stuck and not safe[k]
        top = -math.inf
        if stuck:  # nothing safe on the requested side: its largest worst-case margin
            for k in range(n_cand):
                if _wrong_side(side[i], off_deg[k]):  # never eligible: no margin needed
                    continue
                worst[k] = math.inf
                vn, ve = _own_velocity(cb, sb, speed[i], factor[i], reduced[k], cos_off[k],
                                       sin_off[k])
                for p in pairs:
                    margin = closest_m(pn[p], pe[p], ovn[p] - vn, ove[p] - ve,
                                       horizon_s) - required[p]
                    if margin < worst[k]:
                        worst[k] = margin
                top = max(top, worst[k])
        best_k, best_c = 0, math.inf  # the cheapest eligible candidate
        for k in range(n_cand):
            if _wrong_side(side[i], off_deg[k]):
                continue
            eligible = worst[k] >= top - 1e-6 if stuck else safe[k]
            if eligible:
                c = _cost(off_deg[k], reduced[k], least_deg[i], reduce_asked[i], alongside[k],
                          run_deg)
                if c < best_c:
                    best_k, best_c = k, c
        chosen[i] = best_k
        ok_out[i] = safe[best_k]


@kernel
def _verdict(cb: float, sb: float, speed: float, factor: float, reduced: bool, cos_off: float,
             sin_off: float, pairs: np.ndarray, pn: np.ndarray, pe: np.ndarray,
             ovn: np.ndarray, ove: np.ndarray, required: np.ndarray, horizon_s: float
             ) -> tuple[bool, bool]:
    """Whether one candidate of a ship keeps every one of its ``pairs``' distances, and whether
    it runs alongside one of their ships (within ``ALONGSIDE_RANGE_FACTOR`` asked distances at
    less than ``ALONGSIDE_SPEED_MPS`` relative speed)."""
    vn, ve = _own_velocity(cb, sb, speed, factor, reduced, cos_off, sin_off)
    keeps, beside = True, False
    for p in pairs:
        req = required[p]
        dvn, dve = ovn[p] - vn, ove[p] - ve
        a, b = closest_offset(pn[p], pe[p], dvn, dve, horizon_s)
        if hypot_below(a, b, req):  # closest_m - req < 0
            keeps = False
        if (req > 0.0 and dvn * dvn + dve * dve < ALONGSIDE_SPEED_MPS * ALONGSIDE_SPEED_MPS
                and hypot_below(pn[p], pe[p], ALONGSIDE_RANGE_FACTOR * max(req, 1.0))):
            beside = True
    return keeps, beside


@kernel
def _own_velocity(cb: float, sb: float, speed: float, factor: float, reduced: bool,
                  cos_off: float, sin_off: float) -> tuple[float, float]:
    """Own velocity north and east of a candidate: the course base + offset by the angle-sum
    formulas (``cb, sb``: cos and sin of the base course), at the reduced speed or not."""
    sp = speed * (factor if reduced else 1.0)
    return sp * (cb * cos_off - sb * sin_off), sp * (sb * cos_off + cb * sin_off)


@kernel
def _wrong_side(side: float, offset_deg: float) -> bool:
    """Whether a course offset turns to the side not allowed."""
    return (side == STARBOARD and offset_deg < 0.0) or (side == PORT and offset_deg > 0.0)


@kernel
def _cost(offset_deg: float, reduced: bool, least_deg: float, reduce_asked: bool,
          alongside: bool, run_deg: float) -> float:
    """Preference cost of a candidate on the requested side (module docstring): lower is
    preferred. ``run_deg``: course offset of the running manoeuvre it would replace (NaN for
    none); a replacement changes it by at least ``APPARENT_CHANGE_DEG``, or to the largest
    offset, or not at all, and goes back towards the base course only where nothing further
    out will do."""
    d = offset_deg
    too_small = abs(d) < least_deg - 1e-9 and d != 0.0
    step = abs(d - run_deg)  # NaN (no running manoeuvre) compares false
    small_step = (step > 0.0 and step < APPARENT_CHANGE_DEG - 1e-9
                  and abs(d) < LARGEST_OFFSET_DEG - 1e-9)
    back = abs(d) < abs(run_deg) - 1e-9
    c = abs(d) + (0.5 if d < 0.0 else 0.0)  # starboard first among equals (EITHER)
    c += 500.0 * too_small + 500.0 * small_step + 600.0 * back + 400.0 * alongside
    if reduced:
        c += -0.25 if reduce_asked else 200.0
    if d == 0.0 and least_deg > 0.0:
        c += 300.0  # a bare speed reduction only where no alteration is asked
    return c
