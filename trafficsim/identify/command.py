"""``trafficsim identify``: from trial runs to a validated ship file.

The chain of [seed 001]: pre-processing by the RTS smoother (section 4.1), identification
(augmented-state EKF, section 3, and/or a batch output-error fit), validation by standard
manoeuvres (section 4.3, table 2) and by prediction error on held-out runs. Writes into the
output folder:

* ``ship.yaml``: the identified ship (same schema as the ship library, validated by its loader;
  usable by path in scenarios and ``trafficsim trial``);
* ``convergence.png``: EKF estimates per recursion and output-error cost per evaluation;
* ``report.json``, ``report.md``: data, settings, coefficients with nominal 95 % intervals,
  prediction errors, measured turning tests, standard manoeuvres.

Choices when not given (documented in the README):

* working sampling interval: the data's, thinned to at most ``L / (20 U)`` (about 20 samples
  per ship length travelled; 2 s for a 225 m ship at 13 kn, seed 001's T); a given one lies
  between the data's interval and ``L / U`` and leaves every run 4 samples;
* fit horizon: windows of ``3 L / U`` seconds, each replayed from its measured start; a given
  one spans two working intervals at least and the longest run at most;
* wind: used when the runs carry it and the model has wind loads (``mmg`` with windage
  particulars); the ``response`` and ``nomoto`` families have no wind model, so wind is then
  ignored and its effect goes into the identified coefficients (``--wind ignore`` is refused
  where there is no wind to ignore);
* starting values: the base ship's coefficients when it is of the identified family; for
  ``response`` the EKF starts from zero as in [seed 001, section 4.2]; for ``nomoto`` from
  another family: K' = T' = 2, n3' = 0, ``rps_service`` from the measured speed per rps at
  speeds above 30 % of the service speed, ``surge_tau_s = 5 L / U``. ``mmg`` needs an ``mmg``
  base ship (every coefficient not fitted comes from it), ``mmg_berthing`` an ``mmg_berthing``
  one (e.g. an MMG parameter folder, :mod:`trafficsim.diagnose.mmgfolder`).

The runs are checked first (:mod:`trafficsim.identify.datacheck`): time gaps, non-finite and
impossible values, propeller speeds against the base ship, and whether they excite what is
fitted.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.errors import DataError, InputError
from trafficsim.folders import refuse_other_results
from trafficsim.identify import (
    augmented_ekf,
    datacheck,
    output_error,
    preprocess,
    replay,
    validation,
)
from trafficsim.identify.parameters import DEFAULT_FIT, Parametrisation, check_physical
from trafficsim.identify.report import convergence_plot, write_reports
from trafficsim.identify.shipfile import write_ship_file
from trafficsim.io.trialdata import TrialData, read_trial
from trafficsim.ships.base import families, limit_problems
from trafficsim.ships.library import load_ship

MODELS = ("response", "nomoto", "mmg", "mmg_berthing")
METHODS = ("oe", "ekf", "ekf+oe")
#: families with wind loads (Isherwood); each needs a base ship of its own family
WIND_FAMILIES = ("mmg", "mmg_berthing")
KNOT = 1852.0 / 3600.0


def expand_paths(paths: Sequence[Path], flag: str) -> list[Path]:
    """Files as given; a folder stands for the ``.csv`` files in it (sorted; the suffix in any
    case, ``RUN1.CSV`` too)."""
    out: list[Path] = []
    for p in paths:
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() == ".csv" and q.is_file())
            if not found:
                raise DataError(f"folder has no .csv trial files (given with {flag})", path=str(p))
            out.extend(found)
        elif p.is_file():
            out.append(p)
        else:
            raise DataError(f"trial data file not found (given with {flag})", path=str(p))
    return out


def read_runs(data: Sequence[Path], holdout: Sequence[Path],
              columns: Mapping[str, str] | None = None
              ) -> tuple[list[Path], list[Path], list[TrialData]]:
    """Training and held-out files (folders expanded) and their runs, training first; a run is
    named by its file's stem, with its folder where stems repeat. Each run is checked
    (:func:`trafficsim.identify.datacheck.check_run`: time gaps, non-finite values, impossible
    readings)."""
    train_files = expand_paths(data, "--data")
    hold_files = expand_paths(holdout, "--holdout")
    files = [*train_files, *hold_files]
    stems = [p.stem for p in files]
    trials = [read_trial(p, p.stem if stems.count(p.stem) == 1 else f"{p.parent.name}/{p.stem}",
                         columns)
              for p in files]
    for trial in trials:
        datacheck.check_run(trial, columns)
    datacheck.check_split(trials[: len(train_files)], trials[len(train_files):])
    return train_files, hold_files, trials


def working_interval_s(trials: Sequence[TrialData], length_m: float, u_service_mps: float,
                       dt_s: float | None, columns: Mapping[str, str] | None = None) -> float:
    """``dt_s`` if given, else the data's sampling thinned to at most ``L / (20 U)``.

    A run sampled more coarsely than ``L / U`` (a ship length per sample) is a DataError
    naming its file and time column (``columns`` as in :func:`read_runs`). A given ``dt_s``
    must lie between the finest sampling interval of the runs (runs are thinned, never
    interpolated onto a finer grid) and ``L / U``, and leave every run at least 4 samples (the
    smoother's minimum); else an InputError names ``--dt-s``."""
    most = length_m / u_service_mps
    for t in trials:
        if t.dt_s > most:
            raise DataError(f"sampling interval {t.dt_s:.4g} s (median time step) exceeds L/U "
                            f"= {most:.4g} s of the ship ({length_m:g} m at "
                            f"{u_service_mps / KNOT:.4g} kn): more than a ship length per "
                            "sample, so it cannot identify or replay the ship's motion; give "
                            f"data sampled every {most / 20.0:.4g} s (L/(20 U)) or more often",
                            path=t.path or None, key=datacheck.column_of(t, "t_s", columns))
    native = min(t.dt_s for t in trials)
    if dt_s is None:
        return native * max(1, int(np.floor(length_m / (20.0 * u_service_mps) / native + 1e-9)))
    if dt_s < native * (1.0 - 1e-6):
        raise InputError(f"expected at least the data's sampling interval ({native:.6g} s): "
                         f"runs are thinned to the working interval, not interpolated; got "
                         f"{dt_s:g}", key="--dt-s")
    if dt_s > most:
        raise InputError(f"expected at most L/U = {most:.4g} s (a ship length per sample; the "
                         f"default thins to L/(20 U) = {most / 20.0:.4g} s), got {dt_s:g}",
                         key="--dt-s")
    for t in trials:
        kept = int(np.floor(t.duration_s / dt_s + 1e-9)) + 1
        if kept < 4:
            raise InputError(f"an interval of {dt_s:g} s leaves {kept} sample(s) of run "
                             f"'{t.name}' ({t.duration_s:.4g} s long); the smoother needs at "
                             f"least 4 (at most {t.duration_s / 3.0:.4g} s for this run)",
                             key="--dt-s")
    return dt_s


def horizon_of(trials: Sequence[TrialData], length_m: float, u_service_mps: float,
               horizon_s: float | None, work_dt_s: float) -> float:
    """``horizon_s`` if given, else ``3 L / U``. A given horizon must span at least two working
    intervals and at most the longest run (a longer window replays the same); else an
    InputError names ``--horizon-s``."""
    if horizon_s is None:
        return 3.0 * length_m / u_service_mps
    longest = max(t.duration_s for t in trials)
    if horizon_s < 2.0 * work_dt_s:
        raise InputError(f"expected at least two working sampling intervals "
                         f"({2.0 * work_dt_s:.6g} s), got {horizon_s:g}", key="--horizon-s")
    if horizon_s > longest * (1.0 + 1e-9):
        raise InputError(f"expected at most the longest run's duration ({longest:.6g} s; a "
                         f"window that long replays each run whole), got {horizon_s:g}",
                         key="--horizon-s")
    return horizon_s


def starting_spec(model: str, base: Mapping[str, Any], runs: Sequence[preprocess.Kinematics]
                  ) -> dict[str, Any]:
    """The base ship turned into a ship of family ``model`` with starting coefficients."""
    spec = copy.deepcopy(dict(base))
    if base["model"] == model:
        return spec
    if model in WIND_FAMILIES:
        raise InputError(f"the {model} model needs an {model} base ship (every coefficient not "
                         f"fitted comes from it); '{base['name']}' is a {base['model']} ship",
                         key="--base")
    declared = families()[model].coefficients
    length = float(base["particulars"]["length_m"])
    u_service = float(base["service_speed_kn"]) * KNOT
    coeffs = {k: (0.0 if v is None else float(v)) for k, v in declared.items()}
    if model == "response":
        coeffs["rudder_fade_speed_mps"] = min(1.0, 0.15 * u_service)
    else:  # nomoto
        u = np.concatenate([r.smooth["u_mps"] for r in runs])
        n = np.concatenate([r.trial.rps for r in runs])
        ok = np.isfinite(u) & np.isfinite(n) & (u > 0.3 * u_service) & (n > 0)
        speed_per_rps = float(np.median(u[ok] / n[ok])) if ok.any() else None
        if speed_per_rps is None:
            raise DataError("no samples ahead above 30 % of the service speed to start the "
                            "nomoto surge model from")
        coeffs.update({"K_prime": 2.0, "T_prime": 2.0, "n3_prime": 0.0,
                       "rps_service": u_service / speed_per_rps,
                       "surge_tau_s": 5.0 * length / u_service})
    spec["model"] = model
    spec["coefficients"] = coeffs
    spec["name"] = f"{base['name']}_{model}"
    return spec


def check_fitted(spec: Mapping[str, Any], base: Mapping[str, Any],
                 trials: Sequence[TrialData], columns: Mapping[str, str] | None = None) -> None:
    """Refuse a fitted ship that no ship file can hold (a coefficient outside its physical
    range, or the nomoto service propeller speed beyond the base ship's engine), before
    anything is written: an InputError naming the training data (its file, or ``--data``) and
    what to change, not the output file."""
    problems = limit_problems(families()[spec["model"]], spec)
    if not problems:
        return
    key, problem = problems[0]
    single = len(trials) == 1
    path = (trials[0].path or None) if single else None
    where = "this data" if single else f"the {len(trials)} training runs"
    if key == "actuators.rps_max":  # (nomoto: rps_service beyond the engine's reach)
        rps = float(spec["coefficients"]["rps_service"])
        column = datacheck.column_of(trials[0], "rps", columns)
        raise InputError(
            f"the propeller speed at the service speed fitted from {where} (rps_service "
            f"{rps:.6g} rev/s = {60.0 * rps:.6g} rpm) is beyond the engine of the base ship "
            f"'{base['name']}' (--base; rps_max {float(base['actuators']['rps_max']):g} rev/s): "
            f"check the {column} column (signed, negative astern) or give a base ship whose "
            "engine reaches it; no ship file was written",
            path=path, key=column if path else "--data")
    raise InputError(
        f"the coefficients fitted from {where} make no valid ship ({key}: {problem}): bound "
        f"the coefficient inside that range (--bounds) or fit fewer (--fit); no ship file was "
        "written", path=path, key=None if path else "--data")


def _has_wind_loads(spec: Mapping[str, Any]) -> bool:
    parts = spec["particulars"]
    return (spec["model"] in WIND_FAMILIES
            and float(parts.get("windage_lateral_area_m2", 0.0)) > 0
            and float(parts.get("windage_frontal_area_m2", 0.0)) > 0)


def identify(model: str, data: Sequence[Path], out: Path, base: str,
             holdout: Sequence[Path] = (), method: str | None = None,
             fit_names: Sequence[str] | None = None,
             bounds: Mapping[str, tuple[float, float]] | None = None,
             horizon_s: float | None = None, dt_s: float | None = None, wind: str = "auto",
             reference: str | None = None, name: str | None = None, max_nfev: int = 60,
             channels: Sequence[str] = output_error.DEFAULT_CHANNELS,
             smoother: preprocess.SmootherSettings | None = None,
             columns: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Identify ``model`` from the ``data`` runs; write ship file, plot and reports to ``out``.

    ``columns`` maps trial-data column names to other columns of the CSV files (e.g. the raw
    GNSS fixes and compass of ``trafficsim trial --sensors``), see
    :func:`trafficsim.io.trialdata.read_trial`. Returns the report (also written as
    ``report.json``).
    """
    start = time.perf_counter()
    refuse_other_results(out, "identify", "an identification")
    if model not in MODELS:
        raise InputError(f"unknown model '{model}'; expected one of {', '.join(MODELS)}",
                         key="--model")
    method = method or ("ekf+oe" if model == "response" else "oe")
    if method not in METHODS:
        raise InputError(f"unknown method '{method}'; expected one of {', '.join(METHODS)}",
                         key="--method")
    if "ekf" in method and model != "response":
        raise InputError(f"the augmented EKF identifies the response model only, not {model}; "
                         "use --method oe", key="--method")
    if wind not in ("auto", "ignore"):
        raise InputError(f"expected auto or ignore, got '{wind}'", key="--wind")
    if wind == "ignore" and model not in WIND_FAMILIES:
        raise InputError(f"applies only to models with wind loads ({', '.join(WIND_FAMILIES)}); "
                         f"the {model} model has none, so there is no wind to ignore",
                         key="--wind")
    base_spec = load_ship(base, flag="--base")
    ref_spec = None if reference is None else load_ship(reference, flag="--reference")
    length = float(base_spec["particulars"]["length_m"])
    u_service = float(base_spec["service_speed_kn"]) * KNOT
    train_files, hold_files, trials = read_runs(data, holdout, columns)
    datacheck.check_propeller(trials, base_spec, columns)
    datacheck.check_motion(trials[: len(train_files)], length)
    work_dt = working_interval_s(trials, length, u_service, dt_s, columns)
    horizon = horizon_of(trials, length, u_service, horizon_s, work_dt)
    kin = preprocess.smooth_runs(trials, length, u_service,
                                 smoother or preprocess.SmootherSettings(), dt_s=work_dt)
    datacheck.check_units(trials, kin, base_spec, columns)
    train, hold = kin[: len(train_files)], kin[len(train_files):]

    names = tuple(fit_names) if fit_names else DEFAULT_FIT[model]
    if model == "nomoto" and ("rps_service" in names or base_spec["model"] != "nomoto"):
        datacheck.check_propulsion(trials[: len(train_files)], train, u_service, columns,
                                   optional=base_spec["model"] == "nomoto")
    spec0 = starting_spec(model, base_spec, train)
    if model == "response" and base_spec["model"] != "response" and "ekf" not in method:
        raise InputError("the response model from a base ship of another family needs the "
                         "EKF's estimate to start from: use --method ekf+oe", key="--method")
    if wind == "ignore" and not (_has_wind_loads(spec0) and any(t.has_wind for t in trials)):
        lacking = ("the runs carry no wind" if _has_wind_loads(spec0) else
                   f"the base ship '{base_spec['name']}' has no windage areas")
        raise InputError(f"applies only when the model has wind loads and the runs carry "
                         f"wind; {lacking}, so there is no wind to ignore", key="--wind")
    use_wind = wind == "auto" and _has_wind_loads(spec0) and any(t.has_wind for t in trials)
    wind_note = ("used (measured true wind, Isherwood loads)" if use_wind else
                 "ignored (--wind ignore)" if wind == "ignore" else
                 "ignored (the model has no wind loads)" if not _has_wind_loads(spec0) else
                 "none in the data")

    param = Parametrisation.of(spec0, names, bounds)
    check_physical(param.model, bounds)
    if "ekf" in method and param.names != augmented_ekf.NAMES:
        raise InputError("the augmented EKF estimates all 16 response coefficients; "
                         "--fit applies to the output-error fit only (--method oe)", key="--fit")
    datacheck.check_excitation(trials[: len(train_files)], param.names)
    x_start = param.initial()
    ekf_result = None
    if "ekf" in method:
        ekf_result = augmented_ekf.identify_response(train)
        x_start = np.clip(ekf_result.x, param.lower, param.upper)
    windows_train = replay.windows_from_runs(train, horizon, use_wind)
    fit_result = None
    x_final = x_start
    if "oe" in method:
        fit_result = output_error.fit(param, windows_train, x0=x_start, channels=channels,
                                      max_nfev=max_nfev)
        x_final = fit_result.x
    if fit_result is not None:
        ci = fit_result.ci95
    else:  # EKF only: its own covariance
        ci = output_error.Z95 * ekf_result.std if ekf_result is not None else np.zeros(param.p)

    fitted_spec = param.specs(x_final[None, :])[0]
    check_fitted(fitted_spec, base_spec, trials[: len(train_files)], columns)
    out.mkdir(parents=True, exist_ok=True)
    ship_name = name or f"{base_spec['name']}_identified"
    source = (f"trafficsim identify --model {model} --method {method}; training runs: "
              f"{', '.join(str(p) for p in train_files)}"
              + (f"; held-out runs: {', '.join(str(p) for p in hold_files)}" if hold_files
                 else "")
              + f"; identified coefficients: {', '.join(param.names)}; everything else "
              f"(particulars, actuators, other coefficients) from the base ship "
              f"{base_spec['name']} ({base_spec.get('path', base)}).")
    description = (f"{model} model identified from {len(train_files)} trial run(s) "
                   f"({method}), base ship {base_spec['name']}")
    ship_path = out / "ship.yaml"
    fitted_spec = write_ship_file(
        ship_path, fitted_spec, ship_name, description, source,
        {n: (float(v), float(c)) for n, v, c in zip(param.names, x_final, ci, strict=True)})

    # validation
    labels = ("identified", "start")
    models = param.rows(np.stack([x_final, x_start]))
    prediction = {"training": validation.prediction_errors(models, labels, windows_train)}
    if hold:
        windows_hold = replay.windows_from_runs(hold, horizon, use_wind)
        prediction["holdout"] = validation.prediction_errors(models, labels, windows_hold)
    turns = validation.measured_turns([*train, *hold], models, labels, use_wind)
    ref_name = None
    speed_kn = None
    comparison = None
    if ref_spec is not None:
        ref_name = ref_spec["name"]
        speed_kn = float(ref_spec["service_speed_kn"])
        ref_man = validation.standard_manoeuvres(ref_spec, speed_kn)
    standard = validation.standard_manoeuvres(fitted_spec, speed_kn)
    if reference is not None:
        comparison = validation.compare_manoeuvres(standard, ref_man)

    if fit_result is not None or ekf_result is not None:
        convergence_plot(out / "convergence.png", fit_result, ekf_result)
    roles = ["training"] * len(train) + ["holdout"] * len(hold)
    report: dict[str, Any] = {
        "model": model, "method": method, "base_ship": str(base_spec.get("path", base)),
        "ship": {"name": ship_name, "file": str(ship_path)},
        "data": [{**k.report(), "role": role} for k, role in zip(kin, roles, strict=True)],
        "preprocessing": {"dt_s": float(work_dt), "smoother": kin[0].settings,
                          "wind": wind_note},
        "ekf": ekf_result.summary() if ekf_result is not None else None,
        "fit": fit_result.summary() if fit_result is not None else None,
        "coefficients": {n: float(v) for n, v in zip(param.names, x_final, strict=True)},
        "validation": {"horizon_s": float(horizon), "prediction": prediction,
                       "measured_turns": turns, "standard_manoeuvres": standard,
                       "reference": ref_name, "reference_comparison": comparison},
        "elapsed_s": time.perf_counter() - start,
    }
    write_reports(out, report)
    return report
