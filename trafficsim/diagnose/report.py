"""Reports of a diagnosis: ``report.json``, a one-page ``report.md`` and the residual plots.

``report.json``: ``ranking`` (best first: ``effect``, fitted ``parameters`` with nominal 95 %
intervals, ``shrinkage_train``, ``shrinkage_holdout`` (cross-fitted for per-run environments,
:mod:`trafficsim.diagnose.fit`), ``shrinkage_holdout_insample`` (the held-out runs'
environments fitted on all their windows), ``per_phase`` held-out shrinkage (cross-fitted),
``penalised_score``), ``chosen`` (forward selection), ``verdict``, ``gap`` (costs before and
after, noise floors), ``selection_check`` (:func:`trafficsim.diagnose.fit.selection_check`)
and ``residuals`` (RMS per phase and channel, before and after, on training
and held-out data). ``residuals_by_phase.png``: held-out RMS per phase and channel before and
after the chosen effects.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.diagnose.data import PHASES, Dataset
from trafficsim.diagnose.fit import Diagnosis, gap_change, penalised, phase_shrinkage, scales
from trafficsim.io.results import atomic_write, write_json

_UNITS = {"north": "m", "east": "m", "psi": "deg", "u": "m/s", "v": "m/s", "r": "deg/s",
          "sog": "m/s", "cog_psi": "deg"}


def summary(spec: Mapping[str, Any], diag: Diagnosis, train: Dataset, hold: Dataset,
            extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """JSON-ready report of a diagnosis."""
    sc = scales(train, float(spec["particulars"]["length_m"]))
    ranking = []
    for c in diag.singles:
        sh_t, sh_h = c.shrinkage(diag.base)
        ranking.append({
            "effect": c.effects[0], "parameters": c.table,
            "shrinkage_train": sh_t, "shrinkage_holdout": sh_h,
            "shrinkage_holdout_insample": c.shrinkage_insample(diag.base),
            "penalised_score": 1.0 - penalised(c.cost_hold, c.p, diag.n_eff)
            / diag.base.cost_hold,
            "per_phase": phase_shrinkage(spec, c, hold, sc, diag.base)})
    chosen = diag.chosen
    sh = chosen.shrinkage(diag.base) if chosen.effects else (0.0, 0.0)
    before = diag.residuals["holdout"]["before"]["by_phase"]
    carriers = sorted(before, key=lambda k: -before[k]["cost_share"])
    out = {
        "ship": spec.get("name"),
        "verdict": diag.verdict,
        "attributable": diag.attributable,
        "ranking": ranking,
        "chosen": {"effects": list(chosen.effects), "parameters": chosen.table,
                   "shrinkage_train": sh[0], "shrinkage_holdout": sh[1],
                   "shrinkage_holdout_insample": chosen.shrinkage_insample(diag.base)
                   if chosen.effects else 0.0,
                   "per_phase": phase_shrinkage(spec, chosen, hold, sc, diag.base) if chosen.effects
                   else {}, "steps": diag.steps},
        "gap": {"cost_train_before": diag.base.cost_train, "cost_holdout_before":
                diag.base.cost_hold, "cost_train_after": chosen.cost_train,
                "cost_holdout_after": chosen.cost_hold, "noise_floor_train": diag.floor_train,
                "noise_floor_holdout": diag.floor_hold,
                "holdout_gap_over_floor": diag.base.cost_hold / max(diag.floor_hold, 1e-300),
                "phases_by_share": carriers},
        "selection_check": diag.check,
        "residuals": diag.residuals,
        "channels": list(train.channels), "channel_scales": sc,
        "windows": {"train": train.windows.w, "holdout": hold.windows.w,
                    "samples_per_window": int(train.windows.n)},
        "elapsed_s": diag.elapsed_s,
    }
    if extra:
        out.update(extra)
    return out


def _plot(rep: Mapping[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = rep["residuals"]["holdout"]
    chans = rep["channels"]
    fig, axes = plt.subplots(1, len(chans), figsize=(3.0 * len(chans), 3.2), squeeze=False)
    x = np.arange(len(PHASES))
    for ax, ch in zip(axes[0], chans, strict=True):
        for k, (label, off) in enumerate((("before", -0.2), ("after", 0.2))):
            vals = [res[label]["by_phase"].get(p, {}).get(ch, np.nan) for p in PHASES]
            ax.bar(x + off, vals, width=0.4, label=label, color=("#c44", "#48c")[k])
        ax.set_xticks(x, [p[:5] for p in PHASES], rotation=45, fontsize=7)
        ax.set_title(f"{ch} RMS ({_UNITS.get(ch, '')})", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("held-out residuals by manoeuvre phase, before and after "
                 + (" + ".join(rep["chosen"]["effects"]) or "(nothing chosen)"), fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    atomic_write(path, lambda fh: fh.write(buf.getvalue()))


def markdown(rep: Mapping[str, Any]) -> str:
    """One page: where the gap is, why, how much is left."""
    g = rep["gap"]
    hold = rep["residuals"]["holdout"]
    lines = [f"# Sim-to-real gap diagnosis: {rep.get('ship')}", "",
             f"**Verdict:** {rep['verdict']}", "", *setup_lines(rep),
             "## Where", "",
             f"Held-out gap {g['holdout_gap_over_floor']:.1f} times the data's noise floor. "
             f"Phases by share of the held-out gap: "
             + ", ".join(f"{p} {100 * hold['before']['by_phase'][p]['cost_share']:.0f} %"
                         for p in g["phases_by_share"]) + ".", "",
             "| phase | samples | " + " | ".join(f"{c} ({_UNITS.get(c, '')}) before / after"
                                               for c in rep["channels"]) + " |",
             "|---|---|" + "---|" * len(rep["channels"])]
    for p in PHASES:
        b = hold["before"]["by_phase"].get(p)
        a = hold["after"]["by_phase"].get(p)
        if b is None:
            continue
        cells = [f"{b.get(c, float('nan')):.3g} / {a.get(c, float('nan')):.3g}"
                 for c in rep["channels"]]
        lines.append(f"| {p} | {b['samples']} | " + " | ".join(cells) + " |")
    lines += ["", "## Which", "",
              "| rank | effect | parameters (95 % nominal) | shrinkage train | shrinkage held-out "
              "(cross-fitted) | held-out, run environments in sample | penalised score |",
              "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rep["ranking"], 1):
        par = parameter_text(r["parameters"])
        lines.append(f"| {i} | {r['effect']} | {par} | {100 * r['shrinkage_train']:.0f} % | "
                     f"{100 * r['shrinkage_holdout']:.0f} % | "
                     f"{100 * r['shrinkage_holdout_insample']:.0f} % | "
                     f"{100 * r['penalised_score']:.0f} % |")
    ch = rep["chosen"]
    lines += ["", "## How far", "",
              f"Chosen (forward selection): {' + '.join(ch['effects']) or 'nothing'}. "
              f"Held-out cost {g['cost_holdout_before']:.4g} -> {g['cost_holdout_after']:.4g} "
              f"({100 * ch['shrinkage_holdout']:.0f} % smaller; noise floor "
              f"{g['noise_floor_holdout']:.4g}); training {g['cost_train_before']:.4g} -> "
              f"{g['cost_train_after']:.4g}.", ""]
    if ch["per_phase"]:
        lines.append("Held-out shrinkage per phase: " + ", ".join(
            f"{p} {100 * v:.0f} %" for p, v in ch["per_phase"].items()) + ".")
    lines += check_lines(rep.get("selection_check") or {})
    lines += ["", "![residuals by phase](residuals_by_phase.png)", ""]
    if "confirmation" in rep:
        lines += confirmation_lines(rep["confirmation"])
    if "notes" in rep:
        lines += ["## Notes", "", str(rep["notes"]), ""]
    return "\n".join(lines)


def setup_lines(rep: Mapping[str, Any]) -> list[str]:
    """What was diagnosed and how: ship, runs, split, windows, candidates (nothing without
    ``data``, e.g. a report made by the Python API alone)."""
    data = rep.get("data")
    if not data:
        return []
    win = rep.get("windows", {})
    hold = ", ".join(Path(f).name for f in data["holdout"]) or data["holdout_split"]
    lines = ["## Setup", "",
             f"- Ship: {data.get('ship', rep.get('ship'))}"
             + (f"; base coefficients refitted with every candidate: {', '.join(rep['refit'])}"
                if rep.get("refit") else ""),
             f"- Training runs: {', '.join(Path(f).name for f in data['train'])}",
             f"- Held out: {hold}",
             f"- Windows: {win.get('train', '?')} training, {win.get('holdout', '?')} held out, "
             f"{data['horizon_s']:.3g} s each, replayed at {data['working_dt_s']:.3g} s; wind "
             f"columns {data['wind_columns']}",
             f"- Candidates: {', '.join(rep.get('candidates', []))}"]
    if not data["holdout"]:
        lines.append("- The held-out windows come from the training runs themselves, in the "
                     "same conditions: they test the fit on data it has not seen, not on runs "
                     "it has not seen. Give `--holdout` runs for that.")
    return [*lines, ""]


def check_lines(check: Mapping[str, Any]) -> list[str]:
    """The selection check: the choice made without each part of the held-out data and its
    shrinkage on that part."""
    if not check:
        return ["", "Selection check: needs two or more held-out windows."]
    lines = ["", "Selection check (the choice made on the other held-out data, scored on the "
             f"part left out): the same choice {check['same_choice']} of "
             f"{len(check['parts'])} times; gap {gap_change(check['shrinkage_holdout'])} on "
             "the parts left out: what a choice does on held-out data it has not seen.", "",
             "| left out | windows | chosen without it | shrinkage there |", "|---|---|---|---|"]
    for part in check["parts"]:
        lines.append(f"| {part['left_out']} | {part['windows']} | "
                     f"{' + '.join(part['chosen']) or 'nothing'} | "
                     f"{100 * part['shrinkage']:.0f} % |")
    return lines


def parameter_text(table: Mapping[str, Mapping[str, float]]) -> str:
    """Fitted parameters in one line: global ones with their 95 % half-width; per-run ones
    (``effect.key@run``) and refitted base coefficients (``base.*``) counted only."""
    glob = [f"{k.split('.', 1)[1]} {v['value']:.4g} {_half_width(v)}"
            for k, v in table.items() if "@" not in k and not k.startswith("base.")]
    runs = {k.split("@", 1)[1] for k in table if "@" in k}
    if runs:
        glob.append(f"one value per run ({len(runs)} runs, report.json)")
    return "; ".join(glob)


def _half_width(v: Mapping[str, Any]) -> str:
    """``'+- 0.1'`` (nominal) with ``' (0.4 windows clustered)'`` where known, or
    ``'(not determined by the data)'``; ``' (on its bound)'`` added."""
    def half(key: str) -> float:
        high = v.get(key)
        return high - v["value"] if high is not None else math.inf

    text = f"+- {half('ci95_high'):.2g}"
    if not math.isfinite(half("ci95_high")):
        text = "(not determined by the data)"
    elif math.isfinite(half("ci95_clustered_high")):
        text += f" ({half('ci95_clustered_high'):.2g} windows clustered)"
    return text + (" (on its bound)" if v.get("at_bound") else "")


def confirmation_lines(conf: Mapping[str, Any]) -> list[str]:
    """The confirmation with the logged wind: summary and a table per run."""
    lines = ["## Confirmation (logged wind, not used by the diagnosis)", "", str(conf["text"]),
             ""]
    for name, c in conf.items():
        if name == "text":
            continue
        lines += [f"Fitted `{name}` per run (air or water velocity towards):", "",
                  "| run | role | fitted m/s | fitted towards deg | logged m/s (vector mean / "
                  "mean speed) | logged towards deg | direction error deg |",
                  "|---|---|---|---|---|---|---|"]
        for r in c["runs"]:
            lines.append(f"| {r['run']} | {r['role']} | {r['fitted_speed_mps']:.3g} | "
                         f"{r['fitted_towards_deg']:.0f} | {r['logged_vector_speed_mps']:.2f} / "
                         f"{r['logged_mean_speed_mps']:.2f} | {r['logged_towards_deg']:.0f} | "
                         f"{r['direction_error_deg']:+.0f} |")
        lines.append("")
    return lines


def write(out_dir: Path, rep: Mapping[str, Any]) -> None:
    """``report.json``, ``report.md`` and ``residuals_by_phase.png`` (atomic writes)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "report.json", rep)
    _plot(rep, out_dir / "residuals_by_phase.png")
    body = markdown(rep)
    atomic_write(out_dir / "report.md", lambda fh: fh.write(body.encode()))
