"""Campaign figures (PNG, drawn headless with matplotlib's Agg backend).

* ``cpa_histogram.png``: smallest range of every ship pair, pairs that entered a ship domain
  apart from those that did not, with the collision, near-miss and safe-passing ranges of the
  compliance grade (``../shared/reference/colregs.md`` section 2.4);
* ``rates_by_type.png``: collision, near-miss and domain-violation rates per encounter type,
  with their Wilson 95 % intervals.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trafficsim.campaign.compliance import R_COL_M, R_MIN_M, R_NM_M
from trafficsim.campaign.spec import ENCOUNTER_TYPES
from trafficsim.campaign.summary import completed, per_encounter, wilson
from trafficsim.units import NM


def write_figures(rows: dict[str, np.ndarray], out: Path) -> list[Path]:
    """Draw both figures into ``out`` from the encounters that ran to the end; return their
    paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = [out / "cpa_histogram.png", out / "rates_by_type.png"]
    rows = completed(rows)
    rng_nm = np.asarray(rows["min_range_m"], dtype=float) / NM
    inside = np.asarray(rows["domain_violation"], dtype=bool)
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    bins = np.linspace(0.0, max(2.0, float(np.percentile(rng_nm, 99)) if rng_nm.size else 2.0),
                       41)
    shown = np.minimum(rng_nm, bins[-1])  # the last bin holds every pair beyond it
    ax.hist([shown[~inside], shown[inside]], bins=bins, stacked=True,
            label=["domain kept", "domain entered"], color=["#4c72b0", "#dd8452"])
    for r, name in ((R_COL_M, "collision range"), (R_NM_M, "near miss"),
                    (R_MIN_M, "safe passing")):
        ax.axvline(r / NM, color="k", ls="--", lw=0.8)
        ax.text(r / NM, ax.get_ylim()[1] * 0.95, f" {name}", rotation=90, va="top", fontsize=8)
    ax.set_xlabel(f"smallest range of the pair (NM; the last bin: {bins[-1]:.1f} NM and more)")
    ax.set_ylabel("ship pairs")
    ax.legend()
    fig.tight_layout()
    fig.savefig(paths[0])
    plt.close(fig)

    enc = per_encounter(rows)
    kinds = [k for k in ENCOUNTER_TYPES if np.any(enc["type"] == k)]
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    width = 0.27
    for j, (name, colour) in enumerate((("collision", "#c44e52"), ("near_miss", "#dd8452"),
                                        ("domain_violation", "#4c72b0"))):
        rates, low, high = [], [], []
        for kind in kinds:
            sel = enc["type"] == kind
            k, n = int(np.sum(enc[name][sel])), int(np.sum(sel))
            lo, hi = wilson(k, n)
            rates.append(k / n)
            low.append(max(0.0, k / n - lo))
            high.append(max(0.0, hi - k / n))
        x = np.arange(len(kinds)) + (j - 1) * width
        ax.bar(x, rates, width, yerr=[low, high], capsize=3, label=name.replace("_", " "),
               color=colour)
    ax.set_xticks(np.arange(len(kinds)), [k.replace("_", " ") for k in kinds], fontsize=8)
    ax.set_ylabel("share of encounters (95 % interval)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(paths[1])
    plt.close(fig)
    return paths
