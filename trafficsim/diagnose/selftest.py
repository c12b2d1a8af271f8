"""Injection and recovery: trial data with one hidden effect, diagnosed blind.

Each trial draws an effect of the library and its size at random (ranges below, chosen so the
effect is clearly above the instruments' noise), sails the KVLCC2 (``mmg``, full scale) through
five manoeuvres with the engine's own stepping (:func:`trafficsim.ships.base.step`) with the
effect switched on through :mod:`trafficsim.effects` (ship spec, environment, steering gear),
measures them through the effect's measurement model (:func:`trafficsim.effects.measure`) plus
white noise (position 1 m per axis, heading 0.2 deg, SOG 0.05 m/s, COG 0.05 m/s / U rad; with
``ais_latency`` also the AIS message quantisation of :mod:`trafficsim.sensors.ais`), and
diagnoses the runs without knowing the effect: training runs zig-zag 10/10 (starboard first),
zig-zag 20/20 (port first) and a 35 deg starboard turning circle; held-out runs zig-zag 15/15
and a 25 deg port turning circle. The logged rudder is the actual rudder angle, except with
``steering_lag``, where it is the order (the effect's definition). One class of trials in
every ``len(candidates) + 1`` hides no effect at all (:data:`NONE`): the runs of the base ship
itself, with the same noise. A trial is correct when the diagnosis attributes the gap to the
hidden effect (first-ranked and attributable), or calls it "not attributable" where nothing is
hidden; the magnitude (:meth:`trafficsim.effects.Effect.magnitude`) of the hidden effect is
compared with the hidden one, counted both over the trials that ranked it first and, fitted
alone, over all trials that hide one.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from trafficsim import effects
from trafficsim.diagnose import data as ddata
from trafficsim.diagnose import fit
from trafficsim.identify import preprocess
from trafficsim.io.trialdata import TrialData, from_arrays
from trafficsim.sensors import ais
from trafficsim.ships import base, kernels
from trafficsim.ships.base import PSI, RPS, RUDDER, Actuators, Env, U
from trafficsim.ships.library import load_ship

SHIP = "kvlcc2"
STEP_S = 1.0
SAMPLE_EVERY = 2
APPROACH_S = 60.0
MAX_RUN_S = 900.0
NOISE = {"pos_m": 1.0, "heading_deg": 0.2, "vel_mps": 0.05}
#: (kind, rudder deg, heading deg, first side) of training and held-out runs
TRAIN_RUNS = (("zigzag", 10.0, 10.0, 1.0), ("zigzag", 20.0, 20.0, -1.0),
              ("turning", 35.0, 360.0, 1.0))
HOLD_RUNS = (("zigzag", 15.0, 15.0, 1.0), ("turning", 25.0, 360.0, -1.0))
#: the trials' class that hides no effect (its right answer is "not attributable")
NONE = "none"
UNATTRIBUTED = "not attributable"


def hidden_effect(name: str, rng: np.random.Generator) -> dict[str, float]:
    """A random size of effect ``name`` (ranges: module doc of the README's self-test)."""
    sign = lambda: float(rng.choice([-1.0, 1.0]))  # noqa: E731
    u = rng.uniform
    if name in ("current", "wind"):
        speed = u(0.2, 0.6) if name == "current" else u(25.0, 40.0)
        ang = u(0.0, 2 * np.pi)
        return {"north_mps": speed * np.cos(ang), "east_mps": speed * np.sin(ang)}
    if name == "gnss_lag":
        return {"tau_s": u(10.0, 30.0)}
    if name == "lever_arm":
        return {"x_m": sign() * u(40.0, 120.0), "y_m": sign() * u(0.0, 15.0)}
    if name == "compass_bias":
        return {"bias_deg": sign() * u(1.5, 5.0), "deviation_b_deg": 0.0,
                "deviation_c_deg": 0.0}
    if name == "steering_lag":
        return {"tau_s": u(4.0, 12.0), "rate_degps": u(1.0, 2.5)}
    if name == "resistance":
        return {"scale": u(1.3, 1.8) if rng.random() < 0.5 else u(0.55, 0.75)}
    if name == "propeller_asymmetry":
        return {"rudder_offset_deg": sign() * u(1.5, 3.5)}
    if name == "shallow_water":
        return {"draught_to_depth": u(0.5, 0.8)}
    return {"latency_s": u(4.0, 15.0)}


def _manoeuvre(spec: Mapping[str, Any], env: Env, kind: str, rudder_deg: float,
               heading_deg: float, side: float) -> dict[str, np.ndarray]:
    """True track of one manoeuvre: rows t, state (8), rudder order."""
    family = base.families()[spec["model"]]
    params = family.build([spec])
    act = Actuators.from_specs([spec])
    speed = float(spec["service_speed_kn"]) * 1852.0 / 3600.0
    rps0 = float(base.steady_rps_for_speed(family, params, act, np.array([speed]))[0])
    # the engine's compiled step (kernels.step_ships, as base.step) with the tables packed once
    code = np.array([kernels.FAMILY_CODE[spec["model"]]], dtype=np.int64)
    table, act_table = base.pack(params), base.actuator_table(act)
    env_rows = base.env_table(env, 1)
    sub = np.ones(1, dtype=np.int64)
    cmd, rps_cmd = np.zeros(1), np.array([rps0])
    x = np.zeros((base.N_STATE, 1))
    x[U], x[RPS] = speed, rps0
    rud, lim = np.radians(rudder_deg), np.radians(heading_deg)
    order = 0.0
    sign = side
    t, psi0 = 0.0, 0.0
    rows, orders = [], []
    n_rev, change = 0, 0.0
    while t <= MAX_RUN_S:
        if t >= APPROACH_S:
            if t - STEP_S < APPROACH_S:
                psi0 = float(x[PSI, 0])
            change = float(x[PSI, 0]) - psi0
            if kind == "turning":
                order = side * rud
                if abs(change) >= lim:
                    break
            else:
                order = sign * rud
                if sign * change >= lim:
                    sign = -sign
                    n_rev += 1
                    order = sign * rud
                    if n_rev > 4:
                        break
        rows.append(np.concatenate(([t], x[:, 0])))
        orders.append(order)
        cmd[0] = order
        kernels.step_ships(code, table, act_table, x, cmd, rps_cmd, env_rows, STEP_S, sub)
        prev = rows[-1][1 + PSI]
        x[PSI, 0] = prev + (x[PSI, 0] - prev + np.pi) % (2 * np.pi) - np.pi
        t += STEP_S
    a = np.array(rows)[::SAMPLE_EVERY]
    return {"t": a[:, 0], "x": a[:, 1:].T, "order": np.array(orders)[::SAMPLE_EVERY]}


def measured_run(name: str, track: Mapping[str, np.ndarray], hidden: Mapping[str, Any],
                 rng: np.random.Generator) -> TrialData:
    """Trial data of a true track through the hidden effect's measurement model plus noise."""
    x = track["x"]
    t = track["t"]
    dt = float(t[1] - t[0])
    truth = x[:6].T[None, None]  # (1, 1, N, 6)
    # the hidden current is in ``hidden`` (the track's kinematics already carry it)
    meas = {k: v[0, 0] for k, v in effects.measure(truth, np.array([dt]), [hidden]).items()}
    n = t.size
    pn = meas["north"] + rng.normal(0.0, NOISE["pos_m"], n)
    pe = meas["east"] + rng.normal(0.0, NOISE["pos_m"], n)
    head = meas["psi"] + np.radians(rng.normal(0.0, NOISE["heading_deg"], n))
    vn = meas["sog"] * np.cos(meas["cog"]) + rng.normal(0.0, NOISE["vel_mps"], n)
    ve = meas["sog"] * np.sin(meas["cog"]) + rng.normal(0.0, NOISE["vel_mps"], n)
    sog, cog = np.hypot(vn, ve), np.mod(np.arctan2(ve, vn), 2 * np.pi)
    if "ais_latency" in hidden:
        pn, pe = ais.quantise_position(pn, pe)
        head = ais.quantise_angle(head, np.radians(1.0))
        sog = ais.quantise_sog(sog)
        cog = ais.quantise_angle(cog, np.radians(0.1))
    rudder = track["order"] if "steering_lag" in hidden else x[RUDDER]
    return from_arrays(name, {
        "t_s": t, "north_m": pn, "east_m": pe, "heading_deg": np.degrees(np.mod(head, 2 * np.pi)),
        "rudder_deg": np.degrees(rudder), "rpm": x[RPS] * 60.0,
        "sog_kn": sog / (1852.0 / 3600.0), "cog_deg": np.degrees(cog)})


def simulate_trial(spec: Mapping[str, Any], hidden: Mapping[str, Mapping[str, float]],
                   rng: np.random.Generator) -> tuple[list[TrialData], list[TrialData]]:
    """Measured training and held-out runs of ``spec`` with the ``hidden`` effects on."""
    return simulate_runs(spec, [hidden] * len(TRAIN_RUNS), [hidden] * len(HOLD_RUNS), rng)


def simulate_runs(spec: Mapping[str, Any],
                  hidden_train: Sequence[Mapping[str, Mapping[str, float]]],
                  hidden_hold: Sequence[Mapping[str, Mapping[str, float]]],
                  rng: np.random.Generator) -> tuple[list[TrialData], list[TrialData]]:
    """Measured :data:`TRAIN_RUNS` and :data:`HOLD_RUNS` with the hidden effects of each run
    (e.g. a different wind on every run)."""
    out = []
    for runs, hiddens in ((TRAIN_RUNS, hidden_train), (HOLD_RUNS, hidden_hold)):
        trials = []
        for (kind, rud, head, side), hidden in zip(runs, hiddens, strict=True):
            ship = effects.apply_spec(spec, hidden)
            off = effects.environment_offset(hidden)
            ws, wf = effects.add_wind(np.zeros(1), np.zeros(1), off[2:3], off[3:4])
            env = Env(current_north_mps=off[0], current_east_mps=off[1],
                      wind_speed_mps=float(ws[0]) if off[2] or off[3] else 0.0,
                      wind_from_rad=float(wf[0]))
            track = _manoeuvre(ship, env, kind, rud, head, side)
            trials.append(measured_run(f"{kind}_{rud:g}_{'s' if side > 0 else 'p'}", track,
                                       hidden, rng))
        out.append(trials)
    return out[0], out[1]


def prepare(spec: Mapping[str, Any], train: list[TrialData], hold: list[TrialData]
            ) -> tuple[ddata.Dataset, ddata.Dataset]:
    """Smooth and cut the runs into windows of ``3 L / U``."""
    length = float(spec["particulars"]["length_m"])
    speed = float(spec["service_speed_kn"]) * 1852.0 / 3600.0
    kin = preprocess.smooth_runs([*train, *hold], length, speed)
    horizon = 3.0 * length / speed
    return (ddata.dataset(kin[: len(train)], horizon),
            ddata.dataset(kin[len(train):], horizon))


def run(n_trials: int, seed: int = 0, candidates: tuple[str, ...] = effects.NAMES,
        progress: Any = None) -> dict[str, Any]:
    """``n_trials`` injection-recovery trials, the hidden effects (and :data:`NONE`) taken in
    turn in a random order; confusion matrix, false attributions and magnitude errors."""
    rng = np.random.default_rng(seed)
    spec = load_ship(SHIP)
    hidden_labels = [*candidates, NONE]
    labels = [*candidates, UNATTRIBUTED]
    confusion = np.zeros((len(hidden_labels), len(labels)), dtype=np.int64)
    trials = []
    start = time.perf_counter()
    order = rng.permutation(np.resize(np.arange(len(hidden_labels)), n_trials))
    for i in range(n_trials):
        t0 = time.perf_counter()
        name = hidden_labels[int(order[i])]
        hidden = {} if name == NONE else {
            name: {**effects.REGISTRY[name].off(), **hidden_effect(name, rng)}}
        train, hold = simulate_trial(spec, hidden, rng)
        dtrain, dhold = prepare(spec, train, hold)
        diag = fit.diagnose(spec, dtrain, dhold, candidates, forward_steps=1)
        first = diag.singles[0].effects[0] if diag.attributable else UNATTRIBUTED
        trial: dict[str, Any] = {
            "hidden": name, "hidden_values": hidden.get(name), "first_ranked": first,
            "correct": first == (UNATTRIBUTED if name == NONE else name),
            "gap_over_floor": diag.base.cost_hold / max(diag.floor_hold, 1e-300)}
        if name == NONE:  # what the first-ranked effect would claim
            trial["shrinkage_holdout"] = diag.singles[0].shrinkage(diag.base)[1]
        else:
            fitted = next(c for c in diag.singles if c.effects[0] == name)
            fitted_values = fitted.mean_value(name, dtrain.windows.run_names)
            true_mag = effects.REGISTRY[name].magnitude(hidden[name])
            fit_mag = effects.REGISTRY[name].magnitude(fitted_values)
            trial.update({"fitted_values": fitted_values, "magnitude_true": true_mag,
                          "magnitude_fitted": fit_mag,
                          "magnitude_rel_error": (fit_mag - true_mag) / true_mag,
                          "shrinkage_holdout": fitted.shrinkage(diag.base)[1]})
        trial["seconds"] = time.perf_counter() - t0
        confusion[hidden_labels.index(name), labels.index(first)] += 1
        trials.append(trial)
        if progress is not None:
            progress(i, trial)
    correct = sum(t["correct"] for t in trials)
    sized = [t for t in trials if t["hidden"] != NONE]
    ranked = [t for t in sized if t["correct"]]
    nulls = [t for t in trials if t["hidden"] == NONE]

    def within(rows: list[dict[str, Any]]) -> int:
        return sum(abs(t["magnitude_rel_error"]) <= 0.2 for t in rows)

    return {"trials": trials, "labels": labels, "hidden_labels": hidden_labels,
            "confusion": confusion.tolist(), "n": n_trials, "correct": correct,
            "accuracy": correct / max(n_trials, 1),
            "magnitude_within_20pct": within(sized), "n_hidden": len(sized),
            "magnitude_within_20pct_fraction": within(sized) / max(len(sized), 1),
            "magnitude_within_20pct_ranked": within(ranked), "n_ranked": len(ranked),
            "n_none": len(nulls),
            "false_attributions": sum(not t["correct"] for t in nulls),
            "elapsed_s": time.perf_counter() - start, "seed": seed, "ship": SHIP}


def confusion_text(result: Mapping[str, Any]) -> str:
    """The confusion matrix as a plain-text table (rows hidden, columns the verdict)."""
    labels = result["labels"]
    short = [lab[:8] for lab in labels]
    corner = "hidden / ranked"
    head = f"{corner:<20}" + "".join(f"{s:>9}" for s in short)
    lines = [head]
    for name, row in zip(result["hidden_labels"], result["confusion"], strict=True):
        lines.append(f"{name:<20}" + "".join(f"{v:>9d}" for v in row))
    lines.append(f"correct: {result['correct']}/{result['n']} "
                 f"({100 * result['accuracy']:.0f} %; with nothing hidden, 'not attributable' "
                 f"is correct); attributed with nothing hidden: "
                 f"{result['false_attributions']}/{result['n_none']}")
    lines.append(f"magnitude within 20 %: {result['magnitude_within_20pct_ranked']}/"
                 f"{result['n_ranked']} of the hidden effects found, "
                 f"{result['magnitude_within_20pct']}/{result['n_hidden']} of all hidden "
                 "effects fitted alone")
    return "\n".join(lines)
