"""``trafficsim diagnose``: where the sim-to-real gap lies, which effect causes it, how far it
shrinks; and ``--self-test N``.

Choices when not given (documented in the README): working sampling interval as in
``trafficsim identify`` (the data's, thinned to at most ``L / (20 U)``); replay windows of
``3 L / U``; without ``--holdout`` the windows alternate between training and held-out;
candidates: every effect of the library that acts on the ship's model (no hull effects for
``nomoto`` and ``response`` ships). The runs and the flags are checked as in ``identify``. The
measured wind of the runs is never used by the diagnosis (a wind model is a candidate effect);
when the runs carry it and ``wind`` is chosen, the fitted wind is compared with the logged one
afterwards (``confirmation``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim import effects
from trafficsim.diagnose import data as ddata
from trafficsim.diagnose import fit, report
from trafficsim.errors import InputError
from trafficsim.folders import refuse_other_results
from trafficsim.identify import datacheck, preprocess
from trafficsim.identify.command import horizon_of, read_runs, working_interval_s
from trafficsim.ships.library import load_ship
from trafficsim.units import compass_deg

KNOT = 1852.0 / 3600.0


def load_base(ship: str) -> dict[str, Any]:
    """A library name, a ship file, or an MMG parameter folder
    (:mod:`trafficsim.diagnose.mmgfolder`)."""
    path = Path(ship)
    if path.is_dir():
        from trafficsim.diagnose.mmgfolder import read_folder

        return read_folder(path)
    return dict(load_ship(ship, flag="--ship"))


def _candidates(names: Sequence[str] | None, spec: Mapping[str, Any]) -> tuple[str, ...]:
    """The candidate effects: those given (each once, each acting on ``spec``'s family), or
    every effect of the library that acts on it."""
    if not names:
        return tuple(n for n in effects.NAMES if _inapplicable(n, spec) is None)
    for name in names:
        try:
            effects.check({name: {}}, where="--effects")
        except InputError as exc:
            raise InputError(exc.message, key="--effects") from None
        if names.count(name) > 1:
            raise InputError(f"effect '{name}' listed twice in {' '.join(names)}",
                             key="--effects")
        why = _inapplicable(name, spec)
        if why is not None:
            raise InputError(why, key="--effects")
    return tuple(names)


def _inapplicable(name: str, spec: Mapping[str, Any]) -> str | None:
    """Why effect ``name`` cannot act on the ship ``spec`` (None: it can)."""
    try:
        effects.apply_spec(spec, effects.check({name: {}}))
    except InputError as exc:
        return exc.message
    return None


def _refit(spec: dict[str, Any], refit: str | Sequence[str] | None) -> tuple[str, ...]:
    """Names of the base coefficients refitted with every candidate (checked)."""
    from trafficsim.identify.parameters import DEFAULT_FIT, Parametrisation

    if not refit or (isinstance(refit, str) and not refit.strip()):
        return ()
    if isinstance(refit, str):
        names = DEFAULT_FIT.get(spec["model"], ()) if refit == "default" else tuple(
            n.strip() for n in refit.split(",") if n.strip())
        if not names and refit != "default":
            raise InputError(f"expected coefficient names separated by commas, got {refit!r}",
                             key="--refit")
    else:
        names = tuple(refit)
    try:
        return Parametrisation.of(spec, names).names
    except InputError as exc:
        raise InputError(exc.message, key="--refit") from None


def diagnose(ship: str, data: Sequence[Path], out: Path, holdout: Sequence[Path] = (),
             horizon_s: float | None = None, dt_s: float | None = None,
             candidates: Sequence[str] | None = None,
             refit: str | Sequence[str] | None = None, progress: bool = False
             ) -> dict[str, Any]:
    """Diagnose the runs ``data`` (held-out ``holdout``) against ``ship``; write the reports.

    ``refit``: base coefficients fitted jointly with every candidate (``"default"``: the
    family's subset of ``trafficsim identify``, :data:`trafficsim.identify.parameters.
    DEFAULT_FIT`; a comma-separated string or a sequence of names). ``progress``: a line on
    stderr as each fit ends."""
    start = time.perf_counter()
    refuse_other_results(out, "diagnose", "a diagnosis")
    spec = load_base(ship)
    names = _candidates(candidates, spec)
    refit_names = _refit(spec, refit)
    length = float(spec["particulars"]["length_m"])
    u_service = float(spec["service_speed_kn"]) * KNOT
    train_files, hold_files, trials = read_runs(data, holdout)
    datacheck.check_propeller(trials, spec)
    datacheck.check_motion(trials[: len(train_files)], length)
    work_dt = working_interval_s(trials, length, u_service, dt_s)
    horizon = horizon_of(trials, length, u_service, horizon_s, work_dt)
    kin = preprocess.smooth_runs(trials, length, u_service, dt_s=work_dt)
    datacheck.check_units(trials, kin, spec)
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
    diag = fit.diagnose(spec, train, hold, names, refit=refit_names,
                        progress=_stderr_line if progress else None)
    if not hold_files and diag.attributable:
        diag.verdict += (" (held out: alternate windows of the same runs, not runs the fit has "
                         "not seen)")
    extra: dict[str, Any] = {
        "data": {"ship": ship, "train": [str(p) for p in train_files],
                 "holdout": [str(p) for p in hold_files],
                 "holdout_split": split, "working_dt_s": work_dt, "horizon_s": horizon,
                 "wind_columns": "withheld (not used by the diagnosis)"},
        "refit": list(refit_names),
        "candidates": list(names)}
    conf = confirmation(diag, kin, ["training"] * len(train_files) + ["holdout"] * len(
        hold_files) if hold_files else ["training and holdout"] * len(kin))
    if conf:
        extra["confirmation"] = conf
    if "mmg_folder" in spec:
        extra["notes"] = spec["mmg_folder"]
    rep = report.summary(spec, diag, train, hold, extra)
    rep["elapsed_s"] = time.perf_counter() - start
    report.write(out, rep)
    return rep


def logged_wind(trial: Any) -> tuple[float, float, float, float] | None:
    """A run's logged true wind: mean air velocity over ground (towards) north and east,
    mean speed and RMS speed (m/s); None when no sample has both speed and direction."""
    sp = np.asarray(trial.wind_speed_mps, float)
    fr = np.asarray(trial.wind_from_rad, float)
    ok = np.isfinite(sp) & np.isfinite(fr)
    if not ok.any():
        return None
    sp, fr = sp[ok], fr[ok]
    return (float(np.mean(-sp * np.cos(fr))), float(np.mean(-sp * np.sin(fr))),
            float(np.mean(sp)), float(np.sqrt(np.mean(sp * sp))))


def confirmation(diag: fit.Diagnosis, runs: Sequence[preprocess.Kinematics],
                 roles: Sequence[str]) -> dict[str, Any] | None:
    """With the logged wind (never used by the fit, read only here): per run, the fitted
    environmental effect (wind, and current) against the run's mean logged true wind as an
    air velocity over ground: direction error, speed ratio, and over all runs the
    correlation of the fitted and logged north and east components."""
    logged = {}
    for run, role in zip(runs, roles, strict=True):
        wind = logged_wind(run.trial) if run.trial.has_wind else None
        if wind is not None:  # (wind columns left blank throughout say nothing)
            logged[run.name] = (role, wind)
    if not logged:
        return None
    out: dict[str, Any] = {}
    for cand in diag.singles:
        name = cand.effects[0]
        if name not in effects.PER_RUN:
            continue
        rows = []
        for run, (role, (ln, le, mean_sp, rms_sp)) in logged.items():
            v = cand.run_values.get(run, {}).get(name)
            if v is None:
                continue
            fn, fe = v["north_mps"], v["east_mps"]
            diff = (np.degrees(np.arctan2(fe, fn) - np.arctan2(le, ln)) + 180.0) % 360.0 - 180.0
            rows.append({"run": run, "role": role, "fitted_north_mps": fn, "fitted_east_mps": fe,
                         "fitted_speed_mps": float(np.hypot(fn, fe)),
                         "fitted_towards_deg": float(compass_deg(np.arctan2(fe, fn))),
                         "logged_north_mps": ln, "logged_east_mps": le,
                         "logged_vector_speed_mps": float(np.hypot(ln, le)),
                         "logged_mean_speed_mps": mean_sp, "logged_rms_speed_mps": rms_sp,
                         "logged_towards_deg": float(compass_deg(np.arctan2(le, ln))),
                         "direction_error_deg": float(diff),
                         "speed_ratio": float(np.hypot(fn, fe) / max(np.hypot(ln, le), 1e-9))})
        if not rows:
            continue
        err = np.abs([r["direction_error_deg"] for r in rows])
        f = np.array([[r["fitted_north_mps"], r["fitted_east_mps"]] for r in rows])
        lg = np.array([[r["logged_north_mps"], r["logged_east_mps"]] for r in rows])
        out[name] = {
            "runs": rows,
            "median_abs_direction_error_deg": float(np.median(err)),
            "runs_within_30_deg": int(np.sum(err <= 30.0)),
            "runs_within_45_deg": int(np.sum(err <= 45.0)), "n_runs": len(rows),
            "median_speed_ratio": float(np.median([r["speed_ratio"] for r in rows])),
            "component_correlation": float(np.corrcoef(f.ravel(), lg.ravel())[0, 1])
            if len(rows) > 1 else float("nan")}
    if not out:
        return None
    text = []
    for name, c in out.items():
        text.append(f"Fitted {name} per run against the logged true wind (air velocity "
                    f"towards; used only here): direction within 30 deg on "
                    f"{c['runs_within_30_deg']} of {c['n_runs']} runs (45 deg: "
                    f"{c['runs_within_45_deg']}), median |error| "
                    f"{c['median_abs_direction_error_deg']:.0f} deg, median speed ratio "
                    f"{c['median_speed_ratio']:.2g}, correlation of the north and east "
                    f"components {c['component_correlation']:.2f}.")
    return {"text": " ".join(text), **out}


def _stderr_line(text: str) -> None:
    print(f"  {text}", file=sys.stderr, flush=True)


def self_test(n: int, out: Path | None, seed: int = 0, progress: bool = True
              ) -> dict[str, Any]:
    """``--self-test N``: injection and recovery; writes ``selftest.json`` if ``out``;
    ``progress``: a line per trial on stderr."""
    from trafficsim.diagnose import selftest

    if out is not None:
        refuse_other_results(out, "diagnose", "a self-test")
    def trial_line(i: int, t: dict[str, Any]) -> None:
        size = (f"magnitude {t['magnitude_fitted']:.3g} (true {t['magnitude_true']:.3g}), "
                if "magnitude_true" in t else "")
        _stderr_line(f"trial {i + 1}/{n}: hidden {t['hidden']}, first-ranked "
                     f"{t['first_ranked']}, {size}{t['seconds']:.1f} s")

    res = selftest.run(n, seed, progress=trial_line if progress else None)
    if out is not None:
        from trafficsim.io.results import write_json

        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "selftest.json", res)
    return res
