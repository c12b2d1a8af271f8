"""Injection and recovery: the hidden effects' sizes, the manoeuvres sailed, the measurement of
their tracks, and the bookkeeping of a small self-test."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from trafficsim import effects
from trafficsim.diagnose import fit, selftest
from trafficsim.errors import DataError
from trafficsim.sensors import ais
from trafficsim.ships.base import PSI, RPS, RUDDER, Env, U, V
from trafficsim.ships.library import load_ship

#: the documented ranges (module code) of each hidden effect's parameters
RANGES = {
    "gnss_lag": {"tau_s": (10.0, 30.0)},
    "steering_lag": {"tau_s": (4.0, 12.0), "rate_degps": (1.0, 2.5)},
    "shallow_water": {"draught_to_depth": (0.5, 0.8)},
    "ais_latency": {"latency_s": (4.0, 15.0)},
}
MAGNITUDE = {"current": (0.2, 0.6), "wind": (25.0, 40.0), "compass_bias": (1.5, 5.0),
             "propeller_asymmetry": (1.5, 3.5), "resistance": (0.25, 0.8)}


@pytest.mark.parametrize("name", effects.NAMES)
def test_hidden_effects_are_valid_and_in_range(name: str) -> None:
    """Every draw is a valid ``effects:`` entry (off values filling the rest), within its
    range, with both signs where a sign is drawn."""
    rng = np.random.default_rng(0)
    draws = [selftest.hidden_effect(name, rng) for _ in range(200)]
    eff = effects.REGISTRY[name]
    signs = set()
    for d in draws:
        assert set(d) <= set(eff.keys)
        full = effects.check({name: d})[name]
        for key, (lo, hi) in RANGES.get(name, {}).items():
            assert lo <= full[key] <= hi, (key, full[key])
        if name in MAGNITUDE:
            lo, hi = MAGNITUDE[name]
            assert lo <= eff.magnitude(full) <= hi + 1e-12
        if name == "lever_arm":
            assert 40.0 <= abs(full["x_m"]) <= 120.0 and abs(full["y_m"]) <= 15.0
        assert eff.magnitude(full) > 0.0  # the self-test divides by it
        signs.add(np.sign(next(iter(full.values()))))
    if name in ("lever_arm", "compass_bias", "propeller_asymmetry", "current", "wind"):
        assert signs == {-1.0, 1.0}


def test_resistance_is_raised_or_lowered() -> None:
    rng = np.random.default_rng(1)
    scales = np.array([selftest.hidden_effect("resistance", rng)["scale"] for _ in range(200)])
    up, down = scales[scales > 1], scales[scales < 1]
    assert up.size > 50 and down.size > 50
    assert up.min() >= 1.3 and up.max() <= 1.8 and down.min() >= 0.55 and down.max() <= 0.75


@pytest.fixture(scope="module")
def kvlcc2() -> dict:
    return load_ship("kvlcc2")


def test_turning_manoeuvre(kvlcc2) -> None:
    """Approach 60 s with the rudder amidships, then the rudder hard over to port until the
    heading has changed by 360 deg (the last row just short of it); samples every 2 s."""
    tr = selftest._manoeuvre(kvlcc2, Env(), "turning", 25.0, 360.0, -1.0)
    t, x, order = tr["t"], tr["x"], tr["order"]
    np.testing.assert_allclose(np.diff(t), selftest.STEP_S * selftest.SAMPLE_EVERY)
    assert np.all(order[t < selftest.APPROACH_S] == 0.0)
    assert np.all(order[t > selftest.APPROACH_S] == -np.radians(25.0))
    psi0 = x[PSI][np.searchsorted(t, selftest.APPROACH_S)]
    change = x[PSI] - psi0
    assert np.all(np.diff(x[PSI][t > selftest.APPROACH_S]) < 0)   # turning to port
    assert -2 * np.pi < change.min() < -2 * np.pi + np.radians(5.0)
    speed = kvlcc2["service_speed_kn"] * 1852 / 3600
    assert x[U][0] == pytest.approx(speed, rel=1e-6) and x[V][0] == 0.0
    assert np.ptp(x[RPS]) < 1e-9  # constant engine order


def test_zigzag_manoeuvre(kvlcc2) -> None:
    """20/20 starboard first: order +20 deg, reversed each time the heading change passes
    20 deg on the order's side; the run stops at the fifth reversal, so four are recorded."""
    tr = selftest._manoeuvre(kvlcc2, Env(), "zigzag", 20.0, 20.0, 1.0)
    t, x, order = tr["t"], tr["x"], tr["order"]
    after = order[t >= selftest.APPROACH_S]
    assert after[0] == np.radians(20.0)
    assert set(np.round(np.degrees(after), 9)) == {20.0, -20.0}
    reversals = np.flatnonzero(np.diff(np.sign(after)) != 0)
    assert reversals.size == 4
    psi0 = x[PSI][np.searchsorted(t, selftest.APPROACH_S)]
    change = np.degrees(x[PSI][t >= selftest.APPROACH_S] - psi0)
    for i in reversals:  # just before each reversal the heading is near the 20 deg limit
        side = np.sign(after[i])
        assert side * change[i + 1] > 15.0 and side * change[i] < 20.0 + 1e-9
    assert t[-1] <= selftest.MAX_RUN_S


def _track(n: int = 50, psi0: float = 3.0) -> dict[str, np.ndarray]:
    """A straight track at 6 m/s forward, 0.5 m/s to starboard, heading psi0 + 0.01 t."""
    t = 2.0 * np.arange(n)
    x = np.zeros((8, n))
    x[PSI] = psi0 + 0.01 * t
    x[U], x[V], x[5] = 6.0, 0.5, 0.01
    x[0], x[1] = 10.0 * t, -5.0 * t
    x[RUDDER] = np.radians(7.0)
    x[RPS] = 1.25
    return {"t": t, "x": x, "order": np.full(n, np.radians(-3.0))}


class _NoNoise:
    def normal(self, loc, scale, size):
        return np.zeros(size)


def test_measured_run_without_noise_is_the_truth() -> None:
    """Zero noise and no effect: positions and heading (written in [0, 360)) as sailed, SOG
    the speed through the water (no current), COG the heading plus the drift angle, rudder the
    actual angle, rpm = 60 rps."""
    tr = _track()
    run = selftest.measured_run("r", tr, {}, _NoNoise())
    x = tr["x"]
    np.testing.assert_allclose(run.north_m, x[0])
    np.testing.assert_allclose(run.east_m, x[1])
    deg = np.degrees(run.psi_rad)
    assert deg.min() >= 0.0 and deg.max() < 360.0
    np.testing.assert_allclose(np.unwrap(run.psi_rad), x[PSI], atol=1e-12)
    np.testing.assert_allclose(run.sog_mps, np.hypot(6.0, 0.5), rtol=1e-12)
    cog = np.unwrap(run.cog_rad)
    expect = x[PSI] + np.arctan2(0.5, 6.0)
    np.testing.assert_allclose(cog - 2 * np.pi * np.round((cog - expect) / (2 * np.pi)),
                               expect, atol=1e-12)
    np.testing.assert_allclose(run.rudder_rad, np.radians(7.0))
    np.testing.assert_allclose(run.rps, 1.25)
    np.testing.assert_array_equal(run.t_s, tr["t"])
    lagged = selftest.measured_run("r", tr, {"steering_lag": {"tau_s": 5.0, "rate_degps": 2.0}},
                                   _NoNoise())
    np.testing.assert_allclose(lagged.rudder_rad, np.radians(-3.0))  # the order is logged


def test_measured_run_noise_levels() -> None:
    """Position noise 1 m per axis and heading 0.2 deg (sample std within 20 %)."""
    tr = _track(n=2000, psi0=1.0)
    run = selftest.measured_run("r", tr, {}, np.random.default_rng(3))
    assert np.std(run.north_m - tr["x"][0]) == pytest.approx(1.0, rel=0.2)
    assert np.std(run.east_m - tr["x"][1]) == pytest.approx(1.0, rel=0.2)
    dpsi = np.angle(np.exp(1j * (run.psi_rad - tr["x"][PSI])))
    assert np.degrees(np.std(dpsi)) == pytest.approx(0.2, rel=0.2)
    # velocity noise 0.05 m/s per axis: SOG scatter about that
    assert np.std(run.sog_mps - np.hypot(6.0, 0.5)) == pytest.approx(0.05, rel=0.2)


def test_ais_latency_adds_ais_quantisation() -> None:
    tr = _track()
    run = selftest.measured_run("r", tr, {"ais_latency": {"latency_s": 4.0}}, _NoNoise())
    step = ais.POSITION_STEP_M
    np.testing.assert_allclose(run.north_m / step, np.round(run.north_m / step), atol=1e-6)
    heading_deg = np.degrees(run.psi_rad)
    np.testing.assert_allclose(heading_deg, np.round(heading_deg), atol=1e-6)
    sog_steps = run.sog_mps / ais.SOG_STEP_MPS
    np.testing.assert_allclose(sog_steps, np.round(sog_steps), atol=1e-6)
    # reported late: 4 s = 2 samples behind the truth (which moves 10 m/s north)
    np.testing.assert_allclose(run.north_m[5:], tr["x"][0][5:] - 40.0, atol=step)


def test_simulated_trial_runs_and_windows(kvlcc2) -> None:
    """Three training runs and two held-out ones, named by kind, rudder and side, cut into
    windows of 3 L / U."""
    train, hold = selftest.simulate_trial(kvlcc2, {}, np.random.default_rng(0))
    assert [t.name for t in train] == ["zigzag_10_s", "zigzag_20_p", "turning_35_s"]
    assert [t.name for t in hold] == ["zigzag_15_s", "turning_25_p"]
    assert all(t.dt_s == selftest.STEP_S * selftest.SAMPLE_EVERY for t in (*train, *hold))
    dtrain, dhold = selftest.prepare(kvlcc2, train, hold)
    assert dtrain.windows.run_names == ("zigzag_10_s", "zigzag_20_p", "turning_35_s")
    assert dhold.windows.run_names == ("zigzag_15_s", "turning_25_p")
    horizon = 3 * 320.0 / (15.5 * 1852 / 3600)
    per = round(horizon / 2.0) + 1
    assert dtrain.windows.n_samples.max() == per


def test_small_run_bookkeeping() -> None:
    """Three trials over two candidates: each hidden once and one with nothing hidden
    (balanced order); the confusion matrix, accuracy, false attributions and the magnitude
    counts agree with the trials; progress per trial."""
    calls = []
    res = selftest.run(3, seed=4, candidates=("current", "resistance"),
                       progress=lambda i, t: calls.append((i, t["hidden"])))
    assert res["labels"] == ["current", "resistance", "not attributable"]
    assert res["hidden_labels"] == ["current", "resistance", "none"]
    assert sorted(t["hidden"] for t in res["trials"]) == ["current", "none", "resistance"]
    assert [c[0] for c in calls] == [0, 1, 2]
    conf = np.array(res["confusion"])
    assert conf.shape == (3, 3) and conf.sum() == 3
    for t in res["trials"]:
        i = res["hidden_labels"].index(t["hidden"])
        assert conf[i, res["labels"].index(t["first_ranked"])] == 1
        if t["hidden"] == "none":
            assert "magnitude_true" not in t and t["hidden_values"] is None
            continue
        assert t["magnitude_rel_error"] == pytest.approx(
            (t["magnitude_fitted"] - t["magnitude_true"]) / t["magnitude_true"])
    correct = sum(t["correct"] for t in res["trials"])
    assert res["correct"] == correct == int(np.trace(conf))
    assert res["accuracy"] == correct / 3
    null = next(t for t in res["trials"] if t["hidden"] == "none")
    assert res["n_none"] == 1 and res["false_attributions"] == int(not null["correct"])
    sized = [t for t in res["trials"] if t["hidden"] != "none"]
    assert res["n_hidden"] == 2 and res["magnitude_within_20pct"] == sum(
        abs(t["magnitude_rel_error"]) <= 0.2 for t in sized)
    assert res["n_ranked"] == sum(t["correct"] for t in sized)
    assert res["ship"] == "kvlcc2" and res["seed"] == 4 and res["n"] == 3


def test_confusion_text() -> None:
    res = {"labels": ["current", "propeller_asymmetry", "not attributable"],
           "hidden_labels": ["current", "propeller_asymmetry", "none"],
           "confusion": [[3, 0, 1], [1, 2, 0], [1, 0, 1]], "correct": 6, "n": 9,
           "accuracy": 6 / 9, "magnitude_within_20pct": 4, "n_hidden": 7,
           "magnitude_within_20pct_ranked": 3, "n_ranked": 5, "n_none": 2,
           "false_attributions": 1}
    lines = selftest.confusion_text(res).splitlines()
    assert lines[0] == f"{'hidden / ranked':<20}{'current':>9}{'propelle':>9}{'not attr':>9}"
    assert lines[1] == f"{'current':<20}{3:>9d}{0:>9d}{1:>9d}"
    assert lines[2] == f"{'propeller_asymmetry':<20}{1:>9d}{2:>9d}{0:>9d}"
    assert lines[3] == f"{'none':<20}{1:>9d}{0:>9d}{1:>9d}"
    assert lines[4] == ("correct: 6/9 (67 %; with nothing hidden, 'not attributable' is "
                        "correct); attributed with nothing hidden: 1/2")
    assert lines[5] == ("magnitude within 20 %: 3/5 of the hidden effects found, 4/7 of all "
                        "hidden effects fitted alone")


# --- the hidden conditions reach the track and the instruments --------------------------------


def test_uniform_current_only_carries_the_track(kvlcc2) -> None:
    """A uniform current changes nothing of the motion through the water (heading, u, v, r,
    rudder, the reversals): the track over ground is the still-water one plus current x time."""
    still = selftest._manoeuvre(kvlcc2, Env(), "zigzag", 10.0, 10.0, 1.0)
    moved = selftest._manoeuvre(kvlcc2, Env(current_north_mps=0.3, current_east_mps=-0.2),
                                "zigzag", 10.0, 10.0, 1.0)
    t = still["t"]
    np.testing.assert_array_equal(moved["t"], t)
    np.testing.assert_array_equal(moved["order"], still["order"])
    for row in (PSI, U, V, 5, RUDDER, RPS):
        np.testing.assert_allclose(moved["x"][row], still["x"][row], rtol=0, atol=1e-9)
    np.testing.assert_allclose(moved["x"][0] - still["x"][0], 0.3 * t, atol=1e-6)
    np.testing.assert_allclose(moved["x"][1] - still["x"][1], -0.2 * t, atol=1e-6)


def test_simulate_runs_sails_each_run_in_its_own_hidden_conditions(kvlcc2, monkeypatch
                                                                   ) -> None:
    """Each run is sailed with its own hidden effects: its current in the environment, its
    air velocity (towards) as a true wind from the opposite direction, its hull and steering
    gear on a copy of the spec (the base spec unchanged), the manoeuvre of its row of
    TRAIN_RUNS / HOLD_RUNS, and the logged rudder the order behind a lagging gear."""
    calls = []

    def fake(spec, env, kind, rudder_deg, heading_deg, side):
        calls.append((spec, env, (kind, rudder_deg, heading_deg, side)))
        return _track(n=12)

    monkeypatch.setattr(selftest, "_manoeuvre", fake)
    hidden = [effects.check(h) for h in (
        {"current": {"north_mps": 0.3, "east_mps": -0.2}},
        {"wind": {"north_mps": 0.0, "east_mps": -30.0}},
        {"resistance": {"scale": 1.5}},
        {"steering_lag": {"tau_s": 6.0, "rate_degps": 2.0}},
        {})]
    r0 = kvlcc2["coefficients"]["R0"]
    train, hold = selftest.simulate_runs(kvlcc2, hidden[:3], hidden[3:], _NoNoise())
    assert [c[2] for c in calls] == [*selftest.TRAIN_RUNS, *selftest.HOLD_RUNS]
    envs = [c[1] for c in calls]
    assert (envs[0].current_north_mps, envs[0].current_east_mps) == (0.3, -0.2)
    assert envs[0].wind_speed_mps == 0.0
    assert envs[1].wind_speed_mps == pytest.approx(30.0)
    assert envs[1].wind_from_rad == pytest.approx(np.pi / 2)  # air moving west: from east
    assert (envs[1].current_north_mps, envs[1].current_east_mps) == (0.0, 0.0)
    specs = [c[0] for c in calls]
    assert specs[2]["coefficients"]["R0"] == pytest.approx(1.5 * r0)
    assert specs[3]["actuators"]["rudder_tau_s"] == 6.0
    assert specs[3]["actuators"]["rudder_rate_degps"] == 2.0
    assert specs[4]["coefficients"] == kvlcc2["coefficients"]
    assert kvlcc2["coefficients"]["R0"] == r0
    np.testing.assert_allclose(hold[0].rudder_rad, np.radians(-3.0))  # the order
    np.testing.assert_allclose(hold[1].rudder_rad, np.radians(7.0))  # the gear's angle
    assert [t.name for t in (*train, *hold)] == ["zigzag_10_s", "zigzag_20_p", "turning_35_s",
                                                 "zigzag_15_s", "turning_25_p"]


def test_measured_run_through_an_antenna_and_a_compass_error() -> None:
    """Antenna 50 m forward, 5 m to port, compass 3 deg high, no noise: position is the
    reference point plus R(psi) (50, -5); heading psi + 3 deg; the antenna moves at
    (u - r y, v + r x) = (6.05, 1.0) m/s in the body frame, so SOG is hypot(6.05, 1) and COG
    psi + atan2(1, 6.05)."""
    tr = _track()
    x = tr["x"]
    psi = x[PSI]
    hidden = effects.check({"lever_arm": {"x_m": 50.0, "y_m": -5.0},
                            "compass_bias": {"bias_deg": 3.0}})
    run = selftest.measured_run("r", tr, hidden, _NoNoise())
    c, s = np.cos(psi), np.sin(psi)
    np.testing.assert_allclose(run.north_m, x[0] + 50.0 * c + 5.0 * s, atol=1e-9)
    np.testing.assert_allclose(run.east_m, x[1] + 50.0 * s - 5.0 * c, atol=1e-9)
    dpsi = np.angle(np.exp(1j * (run.psi_rad - psi)))
    np.testing.assert_allclose(np.degrees(dpsi), 3.0, atol=1e-9)
    np.testing.assert_allclose(run.sog_mps, np.hypot(6.05, 1.0), rtol=1e-12)
    dcog = np.angle(np.exp(1j * (run.cog_rad - psi)))
    np.testing.assert_allclose(dcog, np.arctan2(1.0, 6.05), atol=1e-12)


def test_measured_run_in_a_current_reports_speed_over_ground() -> None:
    """Current (0.3, -0.2) m/s, no noise: positions as sailed (the track carries the drift),
    SOG and COG of the water velocity R(psi) (6, 0.5) plus the current."""
    tr = _track()
    psi = tr["x"][PSI]
    run = selftest.measured_run("r", tr, effects.check(
        {"current": {"north_mps": 0.3, "east_mps": -0.2}}), _NoNoise())
    vn = 6.0 * np.cos(psi) - 0.5 * np.sin(psi) + 0.3
    ve = 6.0 * np.sin(psi) + 0.5 * np.cos(psi) - 0.2
    np.testing.assert_allclose(run.north_m, tr["x"][0])
    np.testing.assert_allclose(run.sog_mps, np.hypot(vn, ve), rtol=1e-12)
    dcog = np.angle(np.exp(1j * (run.cog_rad - np.arctan2(ve, vn))))
    np.testing.assert_allclose(dcog, 0.0, atol=1e-12)


def test_run_bookkeeping_on_a_stand_in_diagnosis(monkeypatch) -> None:
    """With the diagnosis replaced by a stand-in: a current's fitted magnitude is that of the
    mean vector of the TRAINING runs only (held-out run b's wild value left out), a trial whose
    diagnosis is not attributable counts as 'not attributable' whatever is ranked first, and
    the held-out shrinkage and gap ratio are the stand-in's."""
    base_c = fit.Candidate((), {}, {}, 20.0, 10.0, 0)
    cur = fit.Candidate(("current",), {}, {}, 1.0, 2.5, 2, run_values={
        "a": {"current": {"north_mps": 0.3, "east_mps": 0.0}},
        "c": {"current": {"north_mps": 0.5, "east_mps": 0.0}},
        "b": {"current": {"north_mps": 9.0, "east_mps": 9.0}}})
    res = fit.Candidate(("resistance",), {"resistance": {"scale": 1.2}}, {}, 1.0, 5.0, 1)
    verdicts = iter([True, False, True])
    seen = []

    def diagnose(spec, dtrain, dhold, candidates, forward_steps):
        seen.append((candidates, forward_steps, dhold))
        return SimpleNamespace(singles=[cur, res], attributable=next(verdicts), base=base_c,
                               floor_hold=4.0)

    monkeypatch.setattr(selftest, "simulate_trial", lambda spec, hidden, rng: ([], []))
    monkeypatch.setattr(selftest, "prepare", lambda spec, train, hold: (
        SimpleNamespace(windows=SimpleNamespace(run_names=("a", "c"))), "hold"))
    monkeypatch.setattr(selftest.fit, "diagnose", diagnose)
    out = selftest.run(3, seed=3, candidates=("current", "resistance"))
    assert [s[:2] for s in seen] == [(("current", "resistance"), 1)] * 3
    by_name = {t["hidden"]: t for t in out["trials"]}
    assert set(by_name) == {"current", "resistance", "none"}
    first = out["trials"][0]
    assert first["first_ranked"] == "current"
    assert out["trials"][1]["first_ranked"] == "not attributable"
    # nothing hidden but an effect attributed: a false attribution, with what it claims
    null = by_name["none"]
    assert null["first_ranked"] == "current" and not null["correct"]
    assert null["shrinkage_holdout"] == pytest.approx(0.75)
    assert out["n_none"] == 1 and out["false_attributions"] == 1
    t = by_name["current"]
    assert t["magnitude_fitted"] == pytest.approx(0.4)
    assert t["fitted_values"] == {"north_mps": pytest.approx(0.4), "east_mps": 0.0}
    true = np.hypot(t["hidden_values"]["north_mps"], t["hidden_values"]["east_mps"])
    assert t["magnitude_true"] == pytest.approx(true)
    assert t["shrinkage_holdout"] == pytest.approx(0.75)
    r = by_name["resistance"]
    assert r["magnitude_fitted"] == pytest.approx(0.2)
    assert r["shrinkage_holdout"] == pytest.approx(0.5)
    assert all(x["gap_over_floor"] == pytest.approx(2.5) for x in out["trials"])
    conf = np.array(out["confusion"])
    row = out["hidden_labels"].index(out["trials"][1]["hidden"])
    assert conf[row, 2] == 1 and conf[2, 0] == 1 and conf.sum() == 3


def test_self_test_pipeline_recovers_a_hidden_compass_bias(kvlcc2) -> None:
    """A 3 deg compass bias hidden in the self-test's own runs (noise as documented): the
    compass error fitted on the training runs (which turn through every heading) is 3 deg
    within 0.15 deg at all headings, and scoring it on the held-out runs removes most of the
    held-out gap."""
    hidden = effects.check({"compass_bias": {"bias_deg": 3.0}})
    train, hold = selftest.simulate_trial(kvlcc2, hidden, np.random.default_rng(7))
    dtrain, dhold = selftest.prepare(kvlcc2, train, hold)
    sc = fit.scales(dtrain, kvlcc2["particulars"]["length_m"])
    cand = fit.fit_set(kvlcc2, ("compass_bias",), dtrain, dhold, sc)
    base_c = fit.fit_set(kvlcc2, (), dtrain, dhold, sc)
    psi = np.linspace(0.0, 2 * np.pi, 73)
    err = np.degrees(effects.compass_error(psi, cand.values["compass_bias"]))
    np.testing.assert_allclose(err, 3.0, atol=0.15)
    assert cand.shrinkage(base_c)[1] > 0.8


@pytest.mark.filterwarnings("ignore:Mean of empty slice", "ignore:invalid value encountered")
def test_prepare_refuses_runs_it_cannot_replay(kvlcc2) -> None:
    """A held-out run of one sample cannot be smoothed, and a run without any rudder
    reading cannot be replayed: both are a DataError (a user-data InputError) saying why."""
    tr = _track(n=60, psi0=0.5)
    good = selftest.measured_run("good", tr, {}, _NoNoise())
    one = selftest.measured_run("one", {k: v[..., :2] for k, v in tr.items()}, {}, _NoNoise())
    short = replace(one, t_s=one.t_s[:1], north_m=one.north_m[:1], east_m=one.east_m[:1],
                    psi_rad=one.psi_rad[:1], rudder_rad=one.rudder_rad[:1], rps=one.rps[:1],
                    sog_mps=one.sog_mps[:1], cog_rad=one.cog_rad[:1])
    with pytest.raises(DataError, match="cannot smooth"):
        selftest.prepare(kvlcc2, [good], [short])
    blind = replace(good, name="blind", rudder_rad=np.full(good.n, np.nan))
    with pytest.raises(DataError, match="no finite rudder angle sample"):
        selftest.prepare(kvlcc2, [good], [blind])
