"""Per-pair outcome metrics measured on true states: minimum range, CPA at start, collision,
ship-domain violation.

A collision is an overlap of the two hull outlines (:func:`trafficsim.geometry.hull_outlines`);
the exact polygon test runs only for pairs whose centres are closer than ``0.5 (L + B)`` of the
one plus that of the other (a bound on the hull radius ``0.5 hypot(L, B)``, the distance of the
outline's stern corners from its centre), so the per-step cost is one range computation per
pair. A domain violation is either
ship's reference point inside the other's domain (:mod:`trafficsim.colregs.domains`, the
scenario's domain model, sized by the ship's length and speed through the water; Coldwell's
head-on and crossing shape).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trafficsim.colregs import domains
from trafficsim.geometry import cos_sin, cpa, hull_outlines, hulls_overlap
from trafficsim.jit import kernel
from trafficsim.ships.base import EAST, NORTH, PSI, U


@dataclass
class PairMetrics:
    """Accumulated metrics, ``(P,)`` arrays aligned with the batch's ``pair_i``/``pair_j``."""

    dcpa0_m: np.ndarray
    tcpa0_s: np.ndarray
    min_range_m: np.ndarray
    t_min_range_s: np.ndarray
    collision: np.ndarray
    t_collision_s: np.ndarray
    domain: str = "coldwell"
    domain_violation: np.ndarray | None = None  # (P,) bool, either ship inside the other's
    t_domain_violation_s: np.ndarray | None = None  # (P,) first time, NaN if never
    #: (P,) bool: the pairs still measured; a pair whose run has ended keeps its figures
    active: np.ndarray | None = None

    @classmethod
    def start(cls, pos: np.ndarray, vel: np.ndarray, pi: np.ndarray, pj: np.ndarray,
              domain: str = "coldwell") -> PairMetrics:
        """Initial metrics from positions and ground velocities ``(2, n)`` north/east;
        ``domain`` names the ship-domain model of the violation metric."""
        d = pos[:, pj] - pos[:, pi]
        dv = vel[:, pj] - vel[:, pi]
        dcpa, tcpa = cpa(d[0], d[1], dv[0], dv[1])
        rng = np.sqrt(d[0] * d[0] + d[1] * d[1])  # (as the compiled step: no libm hypot)
        p = pi.shape[0]
        return cls(dcpa, tcpa, rng, np.zeros(p), np.zeros(p, bool), np.full(p, np.nan),
                   domain, np.zeros(p, bool), np.full(p, np.nan), np.ones(p, bool))

    def accumulate(self, x: np.ndarray, length_m: np.ndarray, beam_m: np.ndarray,
                   pi: np.ndarray, pj: np.ndarray, t_s: float) -> None:
        """Update with the true state ``x`` ``(N_STATE, n)`` at time ``t_s``: ranges and
        domains in one compiled loop over pairs, hull outlines only for pairs close enough to
        touch."""
        near = np.empty(pi.shape[0], dtype=np.int64)
        count = _accumulate(x, length_m, beam_m, pi, pj, float(t_s),
                            domains.domain_code(self.domain),
                            self.min_range_m, self.t_min_range_s, self.domain_violation,
                            self.t_domain_violation_s, self.collision, self.active, near)
        if count:
            near = near[:count]
            a, b = pi[near], pj[near]
            hit = hulls_overlap(
                hull_outlines(x[NORTH, a], x[EAST, a], x[PSI, a], length_m[a], beam_m[a]),
                hull_outlines(x[NORTH, b], x[EAST, b], x[PSI, b], length_m[b], beam_m[b]))
            self.collision[near[hit]] = True
            self.t_collision_s[near[hit]] = t_s


@kernel
def _inside_domain(kind: int, x: np.ndarray, own: int, sign: float, dn: float, de: float,
                   rng: float, length_m: np.ndarray) -> bool:
    """Whether the other ship of a pair (``sign`` x (dn, de) from ship ``own``, at range
    ``rng``) is inside the domain of ``own``, sized by its length and speed through the water;
    beyond the domain's reach (with a margin far above rounding) without turning to the body
    frame."""
    prm = domains.ship_params(kind, length_m[own], x[U, own], False)
    if rng > domains.reach_m(kind, prm) * (1.0 + 1e-9):
        return False
    c, s = cos_sin(x[PSI, own])
    fwd, stbd = sign * (dn * c + de * s), sign * (-dn * s + de * c)
    return domains.inside(kind, prm, fwd, stbd)


@kernel
def _accumulate(x: np.ndarray, length_m: np.ndarray, beam_m: np.ndarray, pi: np.ndarray,
                pj: np.ndarray, t_s: float, kind: int, min_range: np.ndarray, t_min: np.ndarray,
                violation: np.ndarray, t_violation: np.ndarray, collision: np.ndarray,
                active: np.ndarray, near: np.ndarray) -> int:
    """Minimum range and first domain violation of every active pair, in place; the pairs
    not yet collided whose centres are close enough for their outlines to touch go to ``near``
    (their count is returned)."""
    count = 0
    for p in range(pi.shape[0]):
        if not active[p]:
            continue
        a, b = pi[p], pj[p]
        dn, de = x[NORTH, b] - x[NORTH, a], x[EAST, b] - x[EAST, a]
        rng = math.sqrt(dn * dn + de * de)
        if rng < min_range[p]:
            min_range[p], t_min[p] = rng, t_s
        # (a pair beyond both ships' largest possible domain skips sizing them)
        outside = rng > max(domains.reach_bound_m(kind, length_m[a]),
                            domains.reach_bound_m(kind, length_m[b]))
        if not violation[p] and not outside and (
                _inside_domain(kind, x, a, 1.0, dn, de, rng, length_m)
                or _inside_domain(kind, x, b, -1.0, dn, de, rng, length_m)):
            violation[p], t_violation[p] = True, t_s
        reach = 0.5 * (length_m[a] + beam_m[a] + length_m[b] + beam_m[b])
        if rng < reach and not collision[p]:
            near[count] = p
            count += 1
    return count
