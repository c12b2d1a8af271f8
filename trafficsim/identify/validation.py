"""Validation of an identified model: standard manoeuvres and prediction errors.

Three checks, as in [seed 001, section 4.3, table 2] and the usual practice of system
identification:

* **standard manoeuvres**: turning circles (35 deg both ways) and zig-zags (10/10, 20/20) of the
  identified ship (:mod:`trafficsim.ships.manoeuvres`), with the IMO MSC.137(76) criteria; when a
  reference ship is known (a simulated trial), the same manoeuvres of the reference and the
  errors of advance, transfer, tactical diameter and overshoots in % of the reference, as in
  [seed 001, table 2];
* **measured turns**: every run holding a rudder angle of 10 deg or more through 180 deg of
  heading change is a turning test; its advance, transfer and tactical diameter measured on the
  smoothed track are compared with the model replaying the same run from the execute point
  (measured inputs, :mod:`trafficsim.identify.replay`);
* **prediction error**: each run cut into windows of the fit's horizon, each replayed from its
  measured start; RMS errors of surge, sway, yaw rate and heading and the position error at the
  window's end, per run, for the identified model and the starting model, on the training runs
  and on held-out runs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from trafficsim.identify import replay
from trafficsim.identify.preprocess import Kinematics
from trafficsim.ships import manoeuvres

#: turning-circle indices compared, and zig-zag indices compared
TURN_KEYS = ("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m")
ZIGZAG_KEYS = ("first_overshoot_deg", "second_overshoot_deg", "initial_turning_time_s")
#: smallest held rudder angle (deg) and heading change (deg) of a measured turning test
MIN_TURN_RUDDER_DEG = 10.0
MIN_TURN_CHANGE_DEG = 180.0


def standard_manoeuvres(spec: Mapping[str, Any], speed_kn: float | None = None
                        ) -> dict[str, dict[str, Any]]:
    """Turning circles 35 deg starboard / port and zig-zags 10/10, 20/20 with IMO criteria."""
    out: dict[str, dict[str, Any]] = {}
    for key, rudder in (("turning_35_starboard", 35.0), ("turning_35_port", -35.0)):
        _, ind = manoeuvres.turning_circle(spec, rudder, speed_kn)
        out[key] = {"indices": ind, "imo": manoeuvres.imo_criteria("turning", ind)}
    for key, rudder in (("zigzag_10_10", 10.0), ("zigzag_20_20", 20.0)):
        _, ind = manoeuvres.zigzag(spec, rudder, rudder, speed_kn)
        out[key] = {"indices": ind, "imo": manoeuvres.imo_criteria("zigzag", ind)}
    return out


def compare_manoeuvres(fitted: Mapping[str, dict[str, Any]],
                       reference: Mapping[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per manoeuvre and index: reference, identified and error in % of the reference."""
    out: dict[str, dict[str, Any]] = {}
    for name, ref in reference.items():
        keys = TURN_KEYS if name.startswith("turning") else ZIGZAG_KEYS
        rows = {}
        for key in keys:
            a, b = float(ref["indices"][key]), float(fitted[name]["indices"][key])
            err = 100.0 * (b - a) / abs(a) if np.isfinite(a) and a != 0 else float("nan")
            rows[key] = {"reference": a, "identified": b, "error_pct": err}
        out[name] = rows
    return out


def turning_segment(run: Kinematics) -> tuple[int, int] | None:
    """``(execute, end)`` sample indices of a held-rudder turn of 180 deg or more, else None.

    The held rudder is the most common rudder angle (to 1 deg) among samples with at least
    ``MIN_TURN_RUDDER_DEG``; the segment is the longest stretch within 1 deg of it.
    """
    rud = np.degrees(run.trial.rudder_rad)
    big = np.isfinite(rud) & (np.abs(rud) >= MIN_TURN_RUDDER_DEG)
    if big.sum() < 3:
        return None
    values, counts = np.unique(np.round(rud[big]), return_counts=True)
    held = values[np.argmax(counts)]
    near = np.abs(rud - held) <= 1.0
    best, start, best_span = None, None, 0
    for i, flag in enumerate(np.r_[near, False]):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            if i - start > best_span:
                best, best_span = (start, i), i - start
            start = None
    if best is None:
        return None
    i0, i1 = best
    psi = run.smooth["psi_rad"]
    if abs(np.degrees(psi[i1 - 1] - psi[i0])) < MIN_TURN_CHANGE_DEG:
        return None
    return i0, i1


def turning_indices(t: np.ndarray, north: np.ndarray, east: np.ndarray, psi: np.ndarray
                    ) -> dict[str, float]:
    """Advance, transfer (at 90 deg) and tactical diameter (transfer at 180 deg) of a track
    that starts at the execute point (``psi`` unwrapped, rad), as in ``manoeuvres``."""
    psi0 = psi[0]
    dn, de = north - north[0], east - east[0]
    along = dn * np.cos(psi0) + de * np.sin(psi0)
    across = -dn * np.sin(psi0) + de * np.cos(psi0)
    change = np.degrees(np.abs(psi - psi0))

    def at(level: float, y: np.ndarray) -> float:
        idx = np.nonzero(change >= level)[0]
        if idx.size == 0 or idx[0] == 0:
            return float("nan")
        i = idx[0]
        return float(np.interp(level, [change[i - 1], change[i]], [y[i - 1], y[i]]))

    return {"advance_m": at(90.0, along), "transfer_m": abs(at(90.0, across)),
            "tactical_diameter_m": abs(at(180.0, across)),
            "time_to_90_s": at(90.0, t - t[0]), "time_to_180_s": at(180.0, t - t[0])}


def measured_turns(runs: Sequence[Kinematics], models: replay.ModelRows,
                   labels: Sequence[str], use_wind: bool) -> list[dict[str, Any]]:
    """Measured turning indices of each turning run against each model's replay of it."""
    out = []
    for run in runs:
        seg = turning_segment(run)
        if seg is None:
            continue
        i0, i1 = seg
        piece = Kinematics(run.trial.take(slice(i0, i1)),
                           {k: v[i0:i1] for k, v in run.smooth.items()},
                           run.settings, run.repeats_masked)
        win = replay.windows_from_runs([piece], None, use_wind=use_wind)
        sim, _ = replay.simulate(models, win)
        t = piece.t_s
        sm = piece.smooth
        measured = turning_indices(t, sm["north_m"], sm["east_m"], sm["psi_rad"])
        entry: dict[str, Any] = {
            "run": run.name, "execute_t_s": float(t[0]),
            "rudder_deg": float(np.degrees(np.nanmedian(piece.trial.rudder_rad))),
            "rps": float(np.nanmedian(piece.trial.rps)),
            "approach_speed_mps": float(np.hypot(sm["u_mps"][0], sm["v_mps"][0])),
            "measured": measured}
        for j, label in enumerate(labels):
            s = sim[j, 0]
            ind = turning_indices(t, s[:, 0], s[:, 1], s[:, 2])
            entry[label] = {k: {"value": v, "error_pct": 100.0 * (v - measured[k]) / measured[k]
                                if np.isfinite(measured[k]) and measured[k] else float("nan")}
                            for k, v in ind.items()}
        out.append(entry)
    return out


def prediction_errors(models: replay.ModelRows, labels: Sequence[str],
                      windows: replay.Windows) -> dict[str, dict[str, Any]]:
    """Per model and run: RMS output errors over the windows and the end-of-window position
    error (RMS and maximum), plus the same over all runs."""
    sim, diverged = replay.simulate(models, windows)
    tgt = windows.target
    valid = windows.valid()
    valid[:, 0] = False
    last = windows.n_samples - 1
    idx = np.arange(windows.w)
    out: dict[str, dict[str, Any]] = {}
    for j, label in enumerate(labels):
        err = sim[j] - tgt
        end = np.hypot(err[idx, last, 0], err[idx, last, 1])
        per_run: dict[str, Any] = {}
        groups = [(name, windows.run == r) for r, name in enumerate(windows.run_names)]
        for name, sel in [*groups, ("all", np.ones(windows.w, dtype=bool))]:
            if not sel.any():
                continue
            mask = valid[sel]

            def rms(col: int, sel: np.ndarray = sel, mask: np.ndarray = mask,
                    err: np.ndarray = err) -> float:
                e = err[sel][..., col][mask]
                e = e[np.isfinite(e)]
                return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")

            per_run[name] = {
                "windows": int(sel.sum()),
                "u_rms_mps": rms(3), "v_rms_mps": rms(4),
                "r_rms_degps": float(np.degrees(rms(5))), "heading_rms_deg":
                    float(np.degrees(rms(2))),
                "end_position_rms_m": float(np.sqrt(np.mean(end[sel] ** 2))),
                "end_position_max_m": float(np.max(end[sel])),
                "diverged_windows": int(diverged[j][sel].sum())}
        out[label] = per_run
    return out
