"""``trafficsim diagnose``: where the sim-to-real gap lies, which effect causes it, how far it
shrinks; and ``--self-test N``.

Choices when not given (documented in the README): working sampling interval as in
``trafficsim identify`` (the data's, thinned to at most ``L / (20 U)``); replay windows of
``3 L / U``; without ``--holdout`` the windows alternate between training and held-out. The
measured wind of the runs is never used by the diagnosis (a wind model is a candidate effect);
when the runs carry it and ``wind`` is chosen, the fitted wind is compared with the logged one
afterwards (``confirmation``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim import effects
from trafficsim.diagnose import data as ddata
from trafficsim.diagnose import fit, report
from trafficsim.errors import InputError
from trafficsim.identify import preprocess
from trafficsim.identify.command import expand_paths
from trafficsim.io.trialdata import read_trial
from trafficsim.ships.library import load_ship

KNOT = 1852.0 / 3600.0


def load_base(ship: str) -> dict[str, Any]:
    """A library name, a ship file, or an MMG parameter folder
    (:mod:`trafficsim.diagnose.mmgfolder`)."""
    path = Path(ship)
    if path.is_dir():
        from trafficsim.diagnose.mmgfolder import read_folder

        return read_folder(path)
    return dict(load_ship(ship))


def _candidates(names: Sequence[str] | None) -> tuple[str, ...]:
    if not names:
        return effects.NAMES
    for name in names:
        effects.check({name: {}}, where="--effects")
    return tuple(names)


def diagnose(ship: str, data: Sequence[Path], out: Path, holdout: Sequence[Path] = (),
             horizon_s: float | None = None, dt_s: float | None = None,
             candidates: Sequence[str] | None = None) -> dict[str, Any]:
    """Diagnose the runs ``data`` (held-out ``holdout``) against ``ship``; write the reports."""
    start = time.perf_counter()
    spec = load_base(ship)
    names = _candidates(candidates)
    length = float(spec["particulars"]["length_m"])
    u_service = float(spec["service_speed_kn"]) * KNOT
    train_files = expand_paths(data, "--data")
    hold_files = expand_paths(holdout, "--holdout")
    files = [*train_files, *hold_files]
    stems = [p.stem for p in files]
    trials = [read_trial(p, p.stem if stems.count(p.stem) == 1 else f"{p.parent.name}/{p.stem}")
              for p in files]
    native = min(t.dt_s for t in trials)
    work_dt = dt_s if dt_s is not None else native * max(
        1, int(np.floor(length / (20.0 * u_service) / native + 1e-9)))
    kin = preprocess.smooth_runs(trials, length, u_service, dt_s=work_dt)
    horizon = horizon_s if horizon_s is not None else 3.0 * length / u_service
    if hold_files:
        train = ddata.dataset(kin[: len(train_files)], horizon)
        hold = ddata.dataset(kin[len(train_files):], horizon)
        split = "held-out runs"
    else:
        every = ddata.dataset(kin, horizon)
        odd = np.arange(every.windows.w) % 2 == 1
        if odd.sum() == 0:
            raise InputError("too little data to hold any window out; give --holdout runs or "
                             "longer runs", key="--data")
        train, hold = every.subset(~odd), every.subset(odd)
        split = "alternate windows of the same runs (no --holdout given)"
    diag = fit.diagnose(spec, train, hold, names)
    extra: dict[str, Any] = {
        "data": {"train": [str(p) for p in train_files], "holdout": [str(p) for p in hold_files],
                 "holdout_split": split, "working_dt_s": work_dt, "horizon_s": horizon,
                 "wind_columns": "withheld (not used by the diagnosis)"},
        "candidates": list(names)}
    conf = confirmation(diag, kin[: len(train_files)])
    if conf:
        extra["confirmation"] = conf
    if "mmg_folder" in spec:
        extra["notes"] = spec["mmg_folder"]
    rep = report.summary(spec, diag, train, hold, extra)
    rep["elapsed_s"] = time.perf_counter() - start
    report.write(out, rep)
    return rep


def confirmation(diag: fit.Diagnosis, runs: Sequence[preprocess.Kinematics]) -> str | None:
    """With the logged wind (never used by the fit): compare the fitted wind or current with
    the mean logged true wind of the training runs (direction it blows towards)."""
    logged = [r.trial for r in runs if r.trial.has_wind]
    if not logged:
        return None
    sp = np.concatenate([np.nan_to_num(t.wind_speed_mps) for t in logged])
    fr = np.concatenate([np.nan_to_num(t.wind_from_rad) for t in logged])
    vn, ve = float(np.mean(-sp * np.cos(fr))), float(np.mean(-sp * np.sin(fr)))
    text = (f"Logged true wind on the training runs (used only here): mean speed "
            f"{np.mean(sp):.2f} m/s, mean air velocity {np.hypot(vn, ve):.2f} m/s towards "
            f"{np.degrees(np.arctan2(ve, vn)) % 360:.0f} deg.")
    for c in diag.singles:
        name = c.effects[0]
        if name in ("wind", "current"):
            v = c.values[name]
            fn, fe = v["north_mps"], v["east_mps"]
            diff = (np.degrees(np.arctan2(fe, fn) - np.arctan2(ve, vn)) + 180) % 360 - 180
            text += (f" Fitted {name}: {np.hypot(fn, fe):.3g} m/s towards "
                     f"{np.degrees(np.arctan2(fe, fn)) % 360:.0f} deg ({diff:+.0f} deg from the "
                     f"logged wind's direction).")
    return text


def self_test(n: int, out: Path | None, seed: int = 0) -> dict[str, Any]:
    """``--self-test N``: injection and recovery; writes ``selftest.json`` if ``out``."""
    import sys

    from trafficsim.diagnose import selftest

    def progress(i: int, t: dict[str, Any]) -> None:
        print(f"  trial {i + 1}/{n}: hidden {t['hidden']}, first-ranked {t['first_ranked']}, "
              f"magnitude {t['magnitude_fitted']:.3g} (true {t['magnitude_true']:.3g}), "
              f"{t['seconds']:.1f} s", file=sys.stderr, flush=True)

    res = selftest.run(n, seed, progress=progress)
    if out is not None:
        from trafficsim.io.results import write_json

        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "selftest.json", res)
    return res
