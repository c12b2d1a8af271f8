"""Campaign statistics: rates with Wilson intervals and CPA quantiles, overall and per type.

Rates are per encounter: an encounter counts as a collision when any of its pairs collides, a
near miss when its smallest range is below ``R_NM_M`` (800 m, the near-miss range of
``../shared/reference/colregs.md`` section 2.4) without a collision, and a domain violation
when any ship entered another's domain. The 95 % interval of a rate ``k / n`` is Wilson's score
interval (Wilson 1927, J. Am. Stat. Assoc. 22:209-212). An encounter that diverged (its
state stopped being finite and it stood frozen from then on) has no outcome: it is counted
and listed apart, and every rate, quantile and score is over the encounters that ran to the
end. ``cpa_not_passed`` counts the encounters that reached ``max_duration_s`` with a pair
still closing to less than its smallest range so far: their smallest range (in the quantiles
and the near-miss rate) bounds their closest approach from above.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from trafficsim.campaign.compliance import R_NM_M, RULES
from trafficsim.campaign.spec import ENCOUNTER_TYPES
from trafficsim.units import NM

Z95 = 1.959963984540054


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of the proportion ``k / n`` (``(nan, nan)`` for ``n = 0``).

    The interval always holds ``k / n``; the clamp keeps rounding from moving its ends past it
    (``k = 0`` gives a lower end of exactly 0, ``k = n`` an upper end of exactly 1)."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half))


def completed(table: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The rows of the encounters that ran to the end: all but those that diverged (all of a
    table from before the ``diverged`` column)."""
    if "diverged" not in table:
        return {k: np.asarray(v) for k, v in table.items()}
    keep = ~np.asarray(table["diverged"], dtype=bool)
    return {k: np.asarray(v)[keep] for k, v in table.items()}


def diverged_encounters(table: Mapping[str, Any]) -> list[int]:
    """Indices of the encounters that diverged, ascending."""
    if "diverged" not in table:
        return []
    enc = np.asarray(table["encounter"], dtype=np.int64)
    return np.unique(enc[np.asarray(table["diverged"], dtype=bool)]).tolist()


def per_encounter(table: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Collapse pair rows to one row per encounter (rows sorted by encounter)."""
    enc = np.asarray(table["encounter"])
    ids, first = np.unique(enc, return_index=True)
    idx = np.searchsorted(ids, enc)

    def any_of(name: str) -> np.ndarray:
        out = np.zeros(ids.shape[0], dtype=bool)
        np.logical_or.at(out, idx, np.asarray(table[name], dtype=bool))
        return out

    min_range = np.full(ids.shape[0], np.inf)
    np.minimum.at(min_range, idx, np.asarray(table["min_range_m"], dtype=float))
    rogue = np.zeros(ids.shape[0], dtype=bool)
    for side in ("behaviour_i", "behaviour_j"):
        np.logical_or.at(rogue, idx, np.asarray(table[side], dtype=object) != "colregs")
    collision = any_of("collision")
    open_ended = np.zeros(ids.shape[0], dtype=bool)
    if "cpa_passed" in table:  # (a table from before the column: every pair taken as passed)
        np.logical_or.at(open_ended, idx, ~np.asarray(table["cpa_passed"], dtype=bool))
    return {"encounter": ids, "type": np.asarray(table["encounter_type"], dtype=object)[first],
            "collision": collision, "near_miss": (min_range < R_NM_M) & ~collision,
            "domain_violation": any_of("domain_violation"), "blind_spot": any_of("blind_spot"),
            "min_range_m": min_range, "all_compliant": ~rogue, "cpa_not_passed": open_ended}


def _stats(enc: dict[str, np.ndarray], rows: dict[str, np.ndarray]) -> dict[str, Any]:
    n = int(enc["encounter"].shape[0])
    out: dict[str, Any] = {"n_encounters": n}
    for name in ("collision", "near_miss", "domain_violation", "blind_spot"):
        k = int(np.sum(enc[name]))
        low, high = wilson(k, n)
        out[name] = {"count": k, "rate": k / n if n else math.nan, "ci95": [low, high]}
    out["cpa_not_passed"] = int(np.sum(enc["cpa_not_passed"]))
    cpa_nm = enc["min_range_m"] / NM
    out["cpa_nm"] = ({f"p{q}": float(np.percentile(cpa_nm, q)) for q in (1, 5, 50)} if n
                     else {f"p{q}": math.nan for q in (1, 5, 50)})
    out["compliance"] = {f"rule{r}": _mean(rows[f"score_rule{r}"]) for r in RULES}
    return out


def _mean(values: np.ndarray) -> float | None:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None


def summarise(table: dict[str, np.ndarray]) -> dict[str, Any]:
    """``summary.json`` content (without the timing keys the runner adds)."""
    diverged = diverged_encounters(table)
    n_all = int(np.unique(np.asarray(table["encounter"])).shape[0])
    table = completed(table)
    enc = per_encounter(table)
    types = np.asarray(table["encounter_type"], dtype=object)
    overall = _stats(enc, table)
    compliant = enc["all_compliant"]
    summary: dict[str, Any] = {
        "n_encounters": n_all,
        "n_completed": overall["n_encounters"],
        "diverged": len(diverged),
        "diverged_encounters": diverged,
        "collisions": overall["collision"]["count"],
        "collisions_all_compliant": int(np.sum(enc["collision"] & compliant)),
        "encounters_all_compliant": int(np.sum(compliant)),
        **{k: v for k, v in overall.items() if k != "n_encounters"},
        "by_type": {},
    }
    for kind in ENCOUNTER_TYPES:
        sel_enc = enc["type"] == kind
        if not sel_enc.any():
            continue
        sel_rows = types == kind
        summary["by_type"][kind] = _stats({k: v[sel_enc] for k, v in enc.items()},
                                          {k: np.asarray(v)[sel_rows] for k, v in table.items()
                                           if k.startswith("score_rule")})
    return summary
