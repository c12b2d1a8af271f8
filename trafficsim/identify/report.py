"""Identification report: convergence plot (PNG), validation report (JSON and markdown)."""

from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.identify.augmented_ekf import EKFResult
from trafficsim.identify.output_error import FitResult
from trafficsim.io.results import atomic_write, write_json


def convergence_plot(path: Path, fit: FitResult | None, ekf: EKFResult | None) -> None:
    """PNG of the output-error cost and parameters per evaluation, and the EKF coefficient
    estimates per recursion (each normalised by its final value) [seed 001, figs 4-6]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (2 if fit is not None else 0) + (1 if ekf is not None else 0)
    fig, axes = plt.subplots(panels, 1, figsize=(8.0, 3.0 * panels), squeeze=False)
    ax_list = list(axes[:, 0])
    if ekf is not None:
        ax = ax_list.pop(0)
        final = np.where(np.abs(ekf.x) > 0, ekf.x, 1.0)
        every = max(1, ekf.trace.shape[0] // 1500)  # enough points for the eye
        steps = np.arange(1, ekf.trace.shape[0] + 1)[::every]
        for j, name in enumerate(ekf.names):
            ax.plot(steps, ekf.trace[::every, j] / final[j], lw=0.8, label=name)
        for s in ekf.run_starts[1:]:
            ax.axvline(s, color="0.6", lw=0.6, ls=":")
        ax.set_ylim(-1.0, 3.0)
        ax.set_xlabel("EKF recursion")
        ax.set_ylabel("estimate / final")
        ax.set_title("augmented-state EKF [seed 001, eq 5]")
        ax.legend(ncol=8, fontsize=6, loc="upper right")
    if fit is not None:
        ax_cost, ax_par = ax_list
        costs = np.array(fit.history_cost)
        ax_cost.semilogy(np.arange(1, costs.size + 1), costs, "o-", ms=3, lw=0.8,
                         label="evaluation")
        ax_cost.semilogy(np.arange(1, costs.size + 1), np.minimum.accumulate(costs), "k-",
                         lw=1.2, label="best so far")
        ax_cost.set_xlabel("model evaluation")
        ax_cost.set_ylabel("output-error cost")
        ax_cost.set_title("output-error fit (least squares)")
        ax_cost.legend(fontsize=7)
        xs = np.array(fit.history_x)
        ref = np.where(np.abs(fit.x) > 0, np.abs(fit.x), 1.0)
        for j, name in enumerate(fit.names):
            ax_par.plot(np.arange(1, xs.shape[0] + 1), xs[:, j] / ref[j], lw=0.8, label=name)
        ax_par.set_xlabel("model evaluation")
        ax_par.set_ylabel("value / |final|")
        ax_par.legend(ncol=6, fontsize=6, loc="best")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write(path, lambda fh: fh.write(buf.getvalue()))


def interval_text(c: Mapping[str, Any], key: str = "ci95") -> str:
    """A coefficient's 95 % interval ``'low .. high'`` (``key``: ``ci95`` the nominal one,
    ``ci95_clustered`` the windows-clustered one, ``'-'`` where there are too few windows for
    it); ``'not determined by the data'`` where the nominal one is unbounded (written as null
    in JSON); ``', on its bound'`` added where the value sits on one."""
    def finite(k: str) -> bool:
        low, high = c.get(f"{k}_low"), c.get(f"{k}_high")
        return low is not None and high is not None and bool(
            np.isfinite(low) and np.isfinite(high))

    if not finite("ci95"):
        text = "not determined by the data"
    elif not finite(key):
        text = "-"
    else:
        text = f"{_fmt(c[f'{key}_low'])} .. {_fmt(c[f'{key}_high'])}"
    return text + (", on its bound" if c.get("at_bound") else "")


def _fmt(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, (int, np.integer)):
        return str(value)
    v = float(value)
    return "-" if not np.isfinite(v) else f"{v:.{digits}g}"


def markdown(report: Mapping[str, Any]) -> str:
    """The validation report as markdown tables."""
    lines = [f"# Identification of `{report['ship']['name']}` ({report['model']} model)", "",
             f"Method: {report['method']}. Base ship: `{report['base_ship']}`. "
             f"Ship file: `{report['ship']['file']}`.", ""]
    lines += ["## Data", "", "| run | role | samples | duration s | NaN cells | repeats masked |",
              "|---|---|---|---|---|---|"]
    for run in report["data"]:
        nan = sum(run["nan_counts"].values())
        rep = run["repeats_masked"]
        lines.append(f"| {run['name']} | {run['role']} | {run['samples']} | "
                     f"{run['duration_s']:.1f} | {nan} | {rep['position']} / {rep['heading']} |")
    pre = report["preprocessing"]
    lines += ["", f"Smoother [seed 001, eqs 6-8]: sampling {_fmt(pre['dt_s'])} s, "
              f"position noise {_fmt(pre['smoother']['sigma_pos_m'])} m, heading noise "
              f"{_fmt(np.degrees(pre['smoother']['sigma_heading_rad']))} deg. "
              f"Wind: {pre['wind']}.", ""]
    if report.get("ekf"):
        ekf = report["ekf"]
        lines += ["## Augmented-state EKF", "", f"{ekf['recursions']} recursions in "
                  f"{ekf['elapsed_s']:.2f} s. The std is the filter's own (the root of its "
                  "covariance): it leaves out how the gain depends on the coefficients "
                  "(Ljung 1979) and is too narrow where the measured states are noisy; the "
                  "output-error fit's intervals are the ones to quote.", "",
                  "| coefficient | estimate | filter std |",
                  "|---|---|---|"]
        for name, c in ekf["coefficients"].items():
            lines.append(f"| {name} | {_fmt(c['value'])} | {_fmt(c['std'], 2)} |")
        lines.append("")
    fit = report.get("fit")
    if fit:
        lines += ["## Output-error fit", "",
                  f"{fit['evaluations']} evaluations, {fit['jacobians']} Jacobians, "
                  f"{fit['elapsed_s']:.1f} s; cost {_fmt(fit['cost_initial'])} -> "
                  f"{_fmt(fit['cost_final'])}; {fit['message']}", "",
                  "| coefficient | start | identified | 95 % interval (nominal) | 95 % interval "
                  "(windows clustered) | bounds |",
                  "|---|---|---|---|---|---|"]
        for name, c in fit["coefficients"].items():
            lines.append(f"| {name} | {_fmt(c['initial'])} | {_fmt(c['value'])} | "
                         f"{interval_text(c)} | {interval_text(c, 'ci95_clustered')} | "
                         f"{_fmt(c['lower'])} .. {_fmt(c['upper'])} |")
        lines.append("")
    val = report["validation"]
    lines += ["## Prediction error", "",
              f"Windows of {_fmt(val['horizon_s'])} s, each replayed from its measured start "
              "with the measured rudder and propeller speed.", "",
              "| data | run | model | u RMS m/s | v RMS m/s | r RMS deg/s | heading RMS deg "
              "| end position RMS m |", "|---|---|---|---|---|---|---|---|"]
    for role in ("training", "holdout"):
        for model, runs in val["prediction"].get(role, {}).items():
            for run, e in runs.items():
                lines.append(f"| {role} | {run} | {model} | {_fmt(e['u_rms_mps'], 3)} | "
                             f"{_fmt(e['v_rms_mps'], 3)} | {_fmt(e['r_rms_degps'], 3)} | "
                             f"{_fmt(e['heading_rms_deg'], 3)} | "
                             f"{_fmt(e['end_position_rms_m'], 3)} |")
    if val.get("measured_turns"):
        lines += ["", "## Measured turning tests", "",
                  "| run | rudder deg | index | measured | identified (error %) "
                  "| start (error %) |",
                  "|---|---|---|---|---|---|"]
        for turn in val["measured_turns"]:
            for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
                fit_e, start_e = turn["identified"][key], turn["start"][key]
                lines.append(f"| {turn['run']} | {turn['rudder_deg']:.0f} | {key} | "
                             f"{_fmt(turn['measured'][key])} | {_fmt(fit_e['value'])} "
                             f"({_fmt(fit_e['error_pct'], 3)}) | {_fmt(start_e['value'])} "
                             f"({_fmt(start_e['error_pct'], 3)}) |")
    if val.get("reference_comparison"):
        lines += ["", f"## Standard manoeuvres against the reference `{val['reference']}`", "",
                  "| manoeuvre | index | reference | identified | error % |",
                  "|---|---|---|---|---|"]
        for man, rows in val["reference_comparison"].items():
            for key, r in rows.items():
                lines.append(f"| {man} | {key} | {_fmt(r['reference'])} | "
                             f"{_fmt(r['identified'])} | {_fmt(r['error_pct'], 3)} |")
    lines += ["", "## Standard manoeuvres of the identified ship", "",
              "| manoeuvre | index | value | IMO limit | pass |", "|---|---|---|---|---|"]
    for man, m in val["standard_manoeuvres"].items():
        keys = ("advance_m", "transfer_m", "tactical_diameter_m") if man.startswith(
            "turning") else ("first_overshoot_deg", "second_overshoot_deg")
        for key in keys:
            lines.append(f"| {man} | {key} | {_fmt(m['indices'][key])} | | |")
        for key, c in m["imo"].items():
            lines.append(f"| {man} | {key} | {_fmt(c['value'])} | {_fmt(c['limit'])} | "
                         f"{'yes' if c['pass'] else 'NO'} |")
    return "\n".join(lines) + "\n"


def write_reports(out_dir: Path, report: Mapping[str, Any]) -> None:
    """``report.json`` and ``report.md`` in ``out_dir`` (atomic writes)."""
    write_json(out_dir / "report.json", report)
    body = markdown(report)
    atomic_write(out_dir / "report.md", lambda fh: fh.write(body.encode()))
