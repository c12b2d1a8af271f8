"""Per-pair outcome metrics measured on true states: minimum range, CPA at start, collision,
ship-domain violation.

A collision is an overlap of the two hull outlines (:func:`trafficsim.geometry.hull_outlines`);
the exact polygon test runs only for pairs whose centres are closer than half the sum of their
lengths, so the per-step cost is one range computation per pair. A domain violation is either
ship's reference point inside the other's domain (:mod:`trafficsim.colregs.domains`, the
scenario's domain model, sized by the ship's length and speed through the water; Coldwell's
head-on and crossing shape).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trafficsim.colregs import domains
from trafficsim.geometry import cpa, hull_outlines, hulls_overlap
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

    @classmethod
    def start(cls, pos: np.ndarray, vel: np.ndarray, pi: np.ndarray, pj: np.ndarray,
              domain: str = "coldwell") -> PairMetrics:
        """Initial metrics from positions and ground velocities ``(2, n)`` north/east;
        ``domain`` names the ship-domain model of the violation metric."""
        d = pos[:, pj] - pos[:, pi]
        dv = vel[:, pj] - vel[:, pi]
        dcpa, tcpa = cpa(d[0], d[1], dv[0], dv[1])
        rng = np.hypot(d[0], d[1])
        p = pi.shape[0]
        return cls(dcpa, tcpa, rng, np.zeros(p), np.zeros(p, bool), np.full(p, np.nan),
                   domain, np.zeros(p, bool), np.full(p, np.nan))

    def accumulate(self, x: np.ndarray, length_m: np.ndarray, beam_m: np.ndarray,
                   pi: np.ndarray, pj: np.ndarray, t_s: float) -> None:
        """Update with the true state ``x`` ``(N_STATE, n)`` at time ``t_s``."""
        dn = x[NORTH, pj] - x[NORTH, pi]
        de = x[EAST, pj] - x[EAST, pi]
        rng = np.hypot(dn, de)
        closer = rng < self.min_range_m
        self.min_range_m = np.where(closer, rng, self.min_range_m)
        self.t_min_range_s = np.where(closer, t_s, self.t_min_range_s)
        self._domains(x, dn, de, length_m, pi, pj, t_s)
        near = np.flatnonzero((rng < 0.5 * (length_m[pi] + length_m[pj])) & ~self.collision)
        if near.size:
            a, b = pi[near], pj[near]
            hit = hulls_overlap(
                hull_outlines(x[NORTH, a], x[EAST, a], x[PSI, a], length_m[a], beam_m[a]),
                hull_outlines(x[NORTH, b], x[EAST, b], x[PSI, b], length_m[b], beam_m[b]))
            self.collision[near[hit]] = True
            self.t_collision_s[near[hit]] = t_s

    def _domains(self, x: np.ndarray, dn: np.ndarray, de: np.ndarray, length_m: np.ndarray,
                 pi: np.ndarray, pj: np.ndarray, t_s: float) -> None:
        """Mark pairs where either ship is inside the other's domain."""
        inside = np.zeros(pi.shape[0], dtype=bool)
        for own, sign in ((pi, 1.0), (pj, -1.0)):  # both directions of every pair at once
            c, s = np.cos(x[PSI, own]), np.sin(x[PSI, own])
            fwd, stbd = sign * (dn * c + de * s), sign * (-dn * s + de * c)
            inside |= domains.contains(self.domain, fwd, stbd, length_m[own], x[U, own])
        new = inside & ~self.domain_violation
        self.domain_violation |= inside
        self.t_domain_violation_s[new] = t_s
