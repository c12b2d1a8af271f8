"""Fitting and ranking effects (trafficsim.diagnose.fit) on small exact data: runs replayed
from the KVLCC2 and measured through an effect's measurement model without noise, so the cost
of the right effect is zero and the cost of a known error is known in closed form."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from trafficsim import effects
from trafficsim.diagnose import fit, selftest
from trafficsim.diagnose.data import CHANNELS, PHASES, Dataset, dataset
from trafficsim.identify import replay
from trafficsim.identify.preprocess import Kinematics
from trafficsim.io.trialdata import TrialData
from trafficsim.ships import base
from trafficsim.ships.library import load_ship

DT = 2.0
N = 61  # 120 s; windows of 30 s: 16 samples from 0, 30, 60, 90 s
HORIZON = 30.0
SPEC = load_ship("kvlcc2")
LENGTH = float(SPEC["particulars"]["length_m"])
SPEED = float(SPEC["service_speed_kn"]) * 1852.0 / 3600.0
_T = np.arange(N) * DT
ZIGZAG = np.where(_T < 20, 0.0, np.where(_T < 80, 20.0, -20.0))
TURN = np.where(_T < 20, 0.0, -30.0)


def _rps() -> float:
    family = base.families()[SPEC["model"]]
    return float(base.steady_rps_for_speed(family, family.build([SPEC]),
                                           base.Actuators.from_specs([SPEC]),
                                           np.array([SPEED]))[0])


def run(name: str, rudder_deg: np.ndarray, psi0: float = 0.0,
        hidden: Mapping[str, Mapping[str, float]] | None = None) -> Kinematics:
    """The KVLCC2 replayed through ``rudder_deg`` (in the ``hidden`` current), measured through
    the ``hidden`` effects without noise; the "smoothed" state is the measured one."""
    return sailed(name, rudder_deg, psi0, hidden)


def bias(deg: float) -> dict[str, dict[str, float]]:
    return {"compass_bias": {"bias_deg": deg, "deviation_b_deg": 0.0, "deviation_c_deg": 0.0}}


def current(north: float, east: float) -> dict[str, dict[str, float]]:
    return {"current": {"north_mps": north, "east_mps": east}}


def exact(hidden: Mapping[str, Any] | None = None, rudder: np.ndarray = ZIGZAG,
          name: str = "a", psi0: float = 6.0) -> Dataset:
    """One run cut into 4 windows (the heading passes 2 pi on the way)."""
    return dataset([run(name, rudder, psi0, hidden)], HORIZON)


def _shifted(data: Dataset, channel: str, offset: float) -> Dataset:
    target = data.target.copy()
    target[..., CHANNELS.index(channel)] += offset
    return Dataset(data.runs, data.windows, target, data.phase, data.sigma, data.channels)


def _scored(data: Dataset) -> np.ndarray:
    """Samples an EffectResiduals scores: in the window, after its first sample."""
    valid = data.windows.valid().copy()
    valid[:, 0] = False
    return valid


# --- EffectSet --------------------------------------------------------------------------------


def test_effect_set_lays_out_base_global_then_per_run_by_effect_key_run() -> None:
    param = fit.EffectSet.of(SPEC, ("current", "lever_arm", "wind"), refit=("R0",),
                             runs=("r1", "r2"))
    assert param.names == ("base.R0", "lever_arm.x_m", "lever_arm.y_m",
                           "current.north_mps@r1", "current.north_mps@r2",
                           "current.east_mps@r1", "current.east_mps@r2",
                           "wind.north_mps@r1", "wind.north_mps@r2",
                           "wind.east_mps@r1", "wind.east_mps@r2")
    assert param.p == 11 and param.n_global == 3 and param.per_run == ("current", "wind")
    # lever arm bounds are fractions of the length (0.5 L ahead, 0.25 L abeam)
    assert param.lower[1:3].tolist() == [-0.5 * LENGTH, -0.25 * LENGTH]
    assert param.upper[1:3].tolist() == [0.5 * LENGTH, 0.25 * LENGTH]
    assert param.start[0] == SPEC["coefficients"]["R0"]
    assert param.start[7:].tolist() == [0.5] * 4  # the wind's start value
    groups = param.columns()
    assert [g.tolist() for g, _ in groups] == [[0], [1], [2], [3, 4], [5, 6], [7, 8], [9, 10]]
    assert [per for _, per in groups] == [False] * 3 + [True] * 4


def test_effect_set_without_environment_has_no_free_runs() -> None:
    param = fit.EffectSet.of(SPEC, ("resistance",), runs=("r1", "r2"))
    assert param.free_runs == () and param.names == ("resistance.scale",)
    assert param.n_global == 1 and [g.tolist() for g, _ in param.columns()] == [[0]]


def test_effect_set_starts_are_given_per_run_and_clipped_into_bounds() -> None:
    param = fit.EffectSet.of(SPEC, ("compass_bias", "current"), {**bias(50.0), **current(1, 2)},
                             runs=("r1", "r2"), run_start={"r2": current(-9.0, 0.25)})
    assert param.start.tolist() == [20.0, 0.0, 0.0, 1.0, -3.0, 2.0, 0.25]


def test_effect_set_values_map_theta_with_fixed_and_run_fixed() -> None:
    param = fit.EffectSet.of(SPEC, ("current", "compass_bias", "resistance"),
                             runs=("r1", "r2"), fixed={"resistance": {"scale": 1.4}},
                             run_fixed={"r0": current(0.1, 0.2)})
    assert "resistance.scale" not in param.names
    theta = np.arange(1.0, param.p + 1.0)
    assert param.values(theta) == {
        "resistance": {"scale": 1.4},
        "compass_bias": {"bias_deg": 1.0, "deviation_b_deg": 2.0, "deviation_c_deg": 3.0}}
    assert param.run_values(theta) == {"r0": current(0.1, 0.2), "r1": current(4.0, 6.0),
                                       "r2": current(5.0, 7.0)}


def test_effect_set_ship_takes_refitted_coefficients_on_a_copy() -> None:
    param = fit.EffectSet.of(SPEC, ("resistance",), refit=("R0", "N_r"))
    ship = param.ship(np.array([0.03, -0.06, 1.2]))
    assert ship["coefficients"]["R0"] == 0.03 and ship["coefficients"]["N_r"] == -0.06
    assert SPEC["coefficients"]["R0"] == 0.022  # the base spec is untouched
    plain = fit.EffectSet.of(SPEC, ("resistance",)).ship(np.array([1.2]))
    assert plain["coefficients"] == SPEC["coefficients"]


# --- small pure helpers -----------------------------------------------------------------------


def test_alternate_takes_even_windows_of_each_run_in_time_order() -> None:
    windows = SimpleNamespace(run=np.array([1, 0, 1, 0, 1, 0, 0]),
                              t0_s=np.array([20.0, 30.0, 0.0, 0.0, 10.0, 10.0, 20.0]))
    first = fit.alternate(SimpleNamespace(windows=windows))
    # run 0 in time order: windows 3, 5, 6, 1; run 1: windows 2, 4, 0
    assert first.tolist() == [True, False, True, True, False, False, True]


def test_penalised_cost() -> None:
    assert fit.penalised(10.0, 3, 60) == pytest.approx(11.0)
    assert fit.penalised(10.0, 0, 60) == 10.0
    assert fit.penalised(2.0, 1, 0) == pytest.approx(6.0)  # n_eff counted at least once


def test_candidate_shrinkage_train_holdout_and_in_sample() -> None:
    base_c = fit.Candidate((), {}, {}, 8.0, 10.0, 0)
    c = fit.Candidate(("wind",), {}, {}, 2.0, 4.0, 4, cost_hold_insample=3.0)
    assert c.shrinkage(base_c) == pytest.approx((0.75, 0.6))
    assert c.shrinkage_insample(base_c) == pytest.approx(0.7)
    c.cost_hold_insample = None
    assert c.shrinkage_insample(base_c) == pytest.approx(0.6)


def test_candidate_mean_value_global_or_mean_over_runs() -> None:
    c = fit.Candidate(("current", "resistance"), {"resistance": {"scale": 1.3}}, {}, 0.0, 0.0,
                      0, run_values={"a": current(1.0, 2.0), "b": current(3.0, -2.0),
                                     "c": current(100.0, 100.0)})
    assert c.mean_value("resistance", ["a"]) == {"scale": 1.3}
    assert c.mean_value("current", ["a", "b", "missing"]) == {"north_mps": 2.0,
                                                              "east_mps": 0.0}


def test_mean_start_averages_the_folds_that_have_the_run() -> None:
    folds = ({"a": current(1.0, 2.0), "b": current(5.0, 5.0)}, {"a": current(3.0, 4.0)})
    assert fit._mean_start(folds, ["a", "b", "c"]) == {"a": current(2.0, 3.0),
                                                       "b": current(5.0, 5.0)}


def test_scales_from_the_data_speed_and_ship_length() -> None:
    data = exact()
    valid = data.windows.valid()
    u, v = data.windows.target[..., 3][valid], data.windows.target[..., 4][valid]
    speed = np.sqrt(np.mean(u * u + v * v))
    sc = fit.scales(data, LENGTH)
    assert sc["north"] == sc["east"] == pytest.approx(32.0)
    assert sc["psi"] == sc["cog_psi"] == 0.05
    assert sc["u"] == sc["v"] == sc["sog"] == pytest.approx(0.05 * speed)
    assert sc["r"] == pytest.approx(0.05 * speed / LENGTH)


# --- EffectResiduals on exact data ------------------------------------------------------------


def test_exact_data_has_zero_cost_and_every_scored_sample_counted() -> None:
    data = exact()
    assert data.channels == CHANNELS and data.windows.w == 4
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    assert res.m == 4 * 15 * 8  # the first sample of each window is the start state
    assert res.cost(np.zeros(0)) < 1e-20


def test_position_offset_costs_its_closed_form() -> None:
    data = exact()
    sc = fit.scales(data, LENGTH)
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), _shifted(data, "north", 5.0), sc)
    n_north = int(_scored(data).sum())
    assert res.cost(np.zeros(0)) == pytest.approx(0.5 * n_north * (5.0 / sc["north"]) ** 2)
    by_channel = res.by_channel(np.zeros(0))
    assert by_channel["north"] == pytest.approx(5.0)
    assert by_channel["east"] < 1e-9
    # the error is uniform, so each phase's share of the cost is its share of the samples
    by_phase = res.by_phase(np.zeros(0))
    scored = _scored(data)
    for k, name in enumerate(PHASES):
        count = int(np.sum((data.phase == k) & scored))
        if count == 0:
            assert name not in by_phase
            continue
        assert by_phase[name]["samples"] == count
        assert by_phase[name]["cost_share"] == pytest.approx(count / n_north)
        assert by_phase[name]["north"] == pytest.approx(5.0)
    assert sum(p["cost_share"] for p in by_phase.values()) == pytest.approx(1.0)


def test_heading_residual_wraps_and_reads_in_degrees() -> None:
    data = exact()
    sc = fit.scales(data, LENGTH)
    delta = np.radians(0.5)
    # a measured heading one turn (plus half a degree) off differs by half a degree
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()),
                              _shifted(data, "psi", 2 * np.pi + delta), sc)
    n = int(_scored(data).sum())
    assert res.cost(np.zeros(0)) == pytest.approx(0.5 * n * (delta / 0.05) ** 2, rel=1e-6)
    assert res.by_channel(np.zeros(0))["psi"] == pytest.approx(0.5, rel=1e-6)


def test_floor_is_half_the_weighted_noise_per_scored_sample() -> None:
    data = exact()
    sigma = np.array([1.0, 2.0, 0.001, 0.01, 0.02, 1e-4, 0.03, np.nan])
    data = Dataset(data.runs, data.windows, data.target, data.phase, sigma, data.channels)
    sc = fit.scales(data, LENGTH)
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, sc)
    n = int(_scored(data).sum())
    expected = 0.5 * n * sum((s / sc[c]) ** 2 for s, c in zip(sigma[:7], CHANNELS, strict=False))
    assert res.floor() == pytest.approx(expected)


def test_costs_and_floors_by_window_add_up_to_the_whole() -> None:
    """The per-window parts that the selection check scores on: the total is the cost itself
    (to the bit) and the parts add up to it; the windows' floors add up to the floor."""
    train, hold = trio({"compass_bias": {"bias_deg": 2.0}})
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ("compass_bias",)), hold,
                              fit.scales(train, LENGTH))
    theta = np.array([1.0] + [0.0] * (res.param.p - 1))
    total, parts = res.cost_by_window(theta)
    assert total == res.cost(theta) and parts.shape == (hold.windows.w,)
    assert parts.sum() == pytest.approx(total, rel=1e-12) and (parts > 0).all()
    assert res.window_floors().sum() == pytest.approx(res.floor(), rel=1e-12)


def test_parameter_count_is_the_candidates_penalty_p() -> None:
    train = exact(current(0.1, 0.25), ZIGZAG, "a", 0.0)
    hold = exact(current(0.15, -0.05), TURN, "b", 1.0)
    cand = fit.fit_set(SPEC, ("current", "compass_bias"), train, hold,
                       fit.scales(train, LENGTH), max_nfev=2)
    n_bias = len(effects.REGISTRY["compass_bias"].keys)
    assert cand.p == fit.parameter_count(cand.effects, 1) == 2 + n_bias
    assert fit.parameter_count(("current", "compass_bias"), 3) == 6 + n_bias
    assert fit.parameter_count((), 5) == 0
    assert cand.hold_windows.sum() == pytest.approx(cand.cost_hold, rel=1e-12)


def test_check_groups_are_the_held_out_runs_or_a_single_runs_halves_in_time() -> None:
    win = SimpleNamespace(run=np.array([1, 0, 1, 0, 1]), run_names=("x", "y"), w=5,
                          t0_s=np.array([0.0, 0.0, 30.0, 30.0, 60.0]))
    groups = fit.check_groups(SimpleNamespace(windows=win))
    assert [g[0] for g in groups] == ["x", "y"]
    assert groups[0][1].tolist() == [False, True, False, True, False]
    one = SimpleNamespace(run=np.zeros(5, dtype=int), run_names=("x",), w=5,
                          t0_s=np.array([90.0, 0.0, 60.0, 120.0, 30.0]))
    halves = fit.check_groups(SimpleNamespace(windows=one))
    assert [g[0] for g in halves] == ["x, first half", "x, second half"]
    assert halves[0][1].tolist() == [False, True, False, False, True]  # t0 0 and 30 s
    assert (halves[0][1] ^ halves[1][1]).all()
    lone = SimpleNamespace(run=np.zeros(1, dtype=int), run_names=("x",), w=1,
                           t0_s=np.zeros(1))
    assert fit.check_groups(SimpleNamespace(windows=lone)) == []


def test_selection_check_scores_each_choice_on_the_run_it_did_not_see() -> None:
    """Two held-out runs of two windows. Effect A removes 90 % of run x's gap and nothing of
    run y's, B half of run y's and nothing of x's: on both runs A wins (45 % against 25 %),
    but chosen on y alone B wins and does nothing on x, and chosen on x alone A does nothing
    on y, so a choice made without the run it is scored on shrinks the gap by nothing."""
    win = SimpleNamespace(run=np.array([0, 0, 1, 1]), run_names=("x", "y"), w=4,
                          t0_s=np.array([0.0, 30.0, 0.0, 30.0]))
    hold = SimpleNamespace(windows=win)

    def cand(names: tuple[str, ...], parts: list[float]) -> fit.Candidate:
        return fit.Candidate(names, {}, {}, 0.0, float(sum(parts)), 0,
                             hold_windows=np.array(parts))

    base = cand((), [10.0, 10.0, 10.0, 10.0])
    a = cand(("compass_bias",), [1.0, 1.0, 10.0, 10.0])
    b = cand(("resistance",), [10.0, 10.0, 5.0, 5.0])
    scoring = fit.Scoring(None, 4000, 2, 1.0)
    sel = fit.select(base, [b, a], scoring, None, forward_steps=1)
    assert sel.chosen is a and sel.attributable and [c.effects for c in sel.ranked] == [
        a.effects, b.effects]
    assert 1.0 - a.cost_hold / base.cost_hold == pytest.approx(0.45)
    check = fit.selection_check(base, [a, b], a, hold, 1000, np.ones(4), None, 1)
    assert [(p["left_out"], p["chosen"]) for p in check["parts"]] == [
        ("x", ["resistance"]), ("y", ["compass_bias"])]
    assert [p["shrinkage"] for p in check["parts"]] == [0.0, 0.0]
    assert check["same_choice"] == 1 and check["shrinkage_holdout"] == 0.0
    # the parts' choices are not held to the noise floor (a part alone may be too short)
    assert fit.select(base, [a, b], fit.Scoring(None, 4000, 2, 1e9), None, 1).chosen is base
    assert fit.selection_check(base, [a, b], a, hold, 1000, np.full(4, 1e9), None,
                               1)["same_choice"] == 1


def test_delayed_replays_on_the_inputs_logged_the_latency_earlier() -> None:
    """Report latency: a window's measured start is the truth ``latency`` earlier, so the
    replay keeps that start and runs on the inputs logged ``latency`` before each sample (the
    run's first sample before the run); starts and targets stay as they are."""
    data = exact()
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    win = data.windows
    assert np.array_equal(res.delayed(0.0).inputs, win.inputs)
    later = res.delayed(3.0)  # 1.5 samples before each sample
    assert later.x0 is win.x0 and later.target is win.target
    trial = data.runs[0].trial
    logged = np.stack([trial.rudder_rad, trial.rps], axis=1)
    for i, start in enumerate((0, 15, 30, 45)):
        for k in range(int(win.n_samples[i])):
            at = start + k - 1.5
            expected = (logged[0] if at <= 0.0
                        else 0.5 * (logged[int(at - 0.5)] + logged[int(at + 0.5)]))
            np.testing.assert_allclose(later.inputs[i, k], expected, rtol=1e-12, atol=1e-12)


def test_gear_start_follows_the_logged_rudder_at_the_rate_limit() -> None:
    data = exact()
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    logged = data.windows.inputs[:, 0, 0]
    # tau 0.2 s, rate 0.5 deg/s. The log (2 s samples) reads as a ramp from 0 at 18 s to
    # 20 deg at 20 s (10 deg/s), as the replay reads it. The lag y' = (u - y) / tau follows
    # y = 10 s - 2 (1 - exp(-s / tau)) until its rate reaches 0.5 deg/s, at s0 = -tau
    # ln(0.95), then ramps at the limit: 12 s after 18 s (window at 30 s) it is at
    # y(s0) + 0.5 (12 - s0). It is 0.1 deg (tau x rate) short of 20 deg at about 57.8 s and
    # closes the rest as exp(-t / tau) by 60 s. From 78 s the order ramps to -20 deg at
    # 20 deg/s: the gear comes back at the limit from s1 = -tau ln(0.975) on
    steer = np.array([[0.0, 0.0], [0.2, np.radians(0.5)]])
    start = res.gear_start(steer)
    assert np.degrees(logged).tolist() == pytest.approx([0.0, 20.0, 20.0, -20.0])
    assert np.array_equal(start[0], logged)  # no gear: the logged angle
    tau = 0.2
    s0, s1 = -tau * np.log(0.95), -tau * np.log(0.975)
    up = 10.0 * s0 - 2.0 * (1.0 - 0.95) + 0.5 * (12.0 - s0)
    down = 20.0 - (20.0 * s1 - 4.0 * (1.0 - 0.975)) - 0.5 * (12.0 - s1)
    # (each 0.2 s step clipped whole: within half a step's rate of the continuous gear)
    assert np.degrees(start[1]).tolist() == pytest.approx([0.0, up, 20.0, down], abs=0.005)


def test_env_offsets_give_every_window_its_run_current() -> None:
    a, b = run("a", ZIGZAG, 0.0), run("b", TURN, 0.0)
    data = dataset([a, b], HORIZON)
    param = fit.EffectSet.of(SPEC, ("current",), runs=("a", "b"))
    res = fit.EffectResiduals(param, data, fit.scales(data, LENGTH))
    theta = np.array([0.1, 0.2, 0.3, 0.4])  # north a, north b, east a, east b
    off = res.env_offsets(theta[None])[0]
    assert off.shape == (8, 4)
    assert np.allclose(off[:4], [0.1, 0.3, 0.0, 0.0]) and np.allclose(off[4:], [0.2, 0.4, 0, 0])
    no_env = fit.EffectResiduals(fit.EffectSet.of(SPEC, ("compass_bias",)), data,
                                 fit.scales(data, LENGTH))
    assert not no_env.env_offsets(np.zeros((2, 3))).any()


def test_per_run_jacobian_equals_one_column_at_a_time_differences() -> None:
    data = dataset([run("a", ZIGZAG, 0.0, current(0.1, 0.2)),
                    run("b", TURN, 1.0, current(-0.2, 0.1))], HORIZON)
    param = fit.EffectSet.of(SPEC, ("current", "compass_bias"), runs=("a", "b"))
    res = fit.EffectResiduals(param, data, fit.scales(data, LENGTH))
    x = np.array([0.5, 0.0, 0.0, 0.05, 0.05, 0.05, 0.05])
    h = np.array([1e-3, 2e-3, 3e-3, 1e-3, 2e-3, 1e-3, 1e-3])
    r0 = res(x[None])[0]
    jac = res.jacobian(x, r0, h)
    for j in range(x.size):
        xp = x.copy()
        xp[j] += h[j]
        assert np.allclose(jac[:, j], (res(xp[None])[0] - r0) / h[j], rtol=1e-9, atol=1e-9), j
    assert jac[res._row_run == "b", 3:5].any() and not jac[res._row_run == "a", 4].any()


def test_cross_fitted_scores_each_fold_with_the_other_folds_values() -> None:
    data = exact()
    sc = fit.scales(data, LENGTH)
    params = (fit.EffectSet.of(SPEC, ("compass_bias",), fixed=bias(1.0)),
              fit.EffectSet.of(SPEC, ("compass_bias",), fixed=bias(-2.0)))
    first = fit.alternate(data)
    assert first.tolist() == [True, False, True, False]
    errs = fit.CrossFitted(params, data, sc, first).errors(np.zeros(0))[0]
    e_a = fit.EffectResiduals(params[0], data, sc).errors(np.zeros(0))[0]
    e_b = fit.EffectResiduals(params[1], data, sc).errors(np.zeros(0))[0]
    assert np.array_equal(errs[[0, 2]], e_b[[0, 2]]) and np.array_equal(errs[[1, 3]], e_a[[1, 3]])
    assert not np.allclose(e_a, e_b)


# --- fits -------------------------------------------------------------------------------------


def test_coherent_compass_bias_removes_the_whole_gap() -> None:
    data = exact(bias(3.0))
    sc = fit.scales(data, LENGTH)
    right = fit.EffectResiduals(fit.EffectSet.of(SPEC, ("compass_bias",), fixed=bias(3.0)),
                                data, sc)
    wrong = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, sc)
    assert right.cost(np.zeros(0)) < 1e-20 < 1.0 < wrong.cost(np.zeros(0))


def test_grid_start_picks_the_grid_point_of_a_global_effect() -> None:
    data = exact(bias(-2.5))
    param = fit.EffectSet.of(SPEC, ("compass_bias",))
    res = fit.EffectResiduals(param, data, fit.scales(data, LENGTH))
    assert fit._grid_start(param, res, "compass_bias", param.initial()).tolist() == [-2.5, 0, 0]


def test_grid_start_picks_each_runs_own_grid_point() -> None:
    r1, r2 = 0.03 * SPEED, 0.075 * SPEED  # the grid's radii
    c45 = np.sqrt(0.5)
    data = dataset([run("a", ZIGZAG, 0.0, current(0.0, r1)),
                    run("b", TURN, 2.0, current(-r2 * c45, -r2 * c45))], HORIZON)
    param = fit.EffectSet.of(SPEC, ("current",), runs=("a", "b"))
    res = fit.EffectResiduals(param, data, fit.scales(data, LENGTH))
    x = fit._grid_start(param, res, "current", param.initial())
    assert x == pytest.approx([0.0, -r2 * c45, r1, -r2 * c45], abs=1e-9)


def test_fit_set_recovers_a_compass_bias_off_the_grid() -> None:
    train, hold = exact(bias(3.2)), exact(bias(3.2), TURN, "b", 1.0)
    sc = fit.scales(train, LENGTH)
    cand = fit.fit_set(SPEC, ("compass_bias",), train, hold, sc)
    base_c = fit.fit_set(SPEC, (), train, hold, sc)
    # the run sails headings within 20 deg of north, so bias and deviation trade off: what is
    # determined is the compass error over those headings
    psi = train.runs[0].smooth["psi_rad"]
    error = effects.compass_error(psi, cand.values["compass_bias"])
    assert np.degrees(error) == pytest.approx(np.full(N, 3.2), abs=2e-3)
    assert cand.p == 3 and cand.run_values == {} and cand.fold_run_values == ()
    assert base_c.effects == () and base_c.p == 0 and base_c.cost_hold > 1.0
    assert cand.shrinkage(base_c) == pytest.approx((1.0, 1.0), abs=1e-3)
    assert cand.table["compass_bias.bias_deg"]["value"] == cand.values["compass_bias"]["bias_deg"]


def test_fit_set_cross_fits_the_current_of_a_held_out_run() -> None:
    train = exact(current(0.1, 0.25), ZIGZAG, "a", 0.0)
    hold = exact(current(0.15, -0.05), TURN, "b", 1.0)
    cand = fit.fit_set(SPEC, ("current",), train, hold, fit.scales(train, LENGTH))
    for name, (north, east) in (("a", (0.1, 0.25)), ("b", (0.15, -0.05))):
        got = cand.run_values[name]["current"]
        assert got["north_mps"] == pytest.approx(north, abs=1e-3), name
        assert got["east_mps"] == pytest.approx(east, abs=1e-3), name
    assert len(cand.fold_run_values) == 2
    for fold in cand.fold_run_values:  # each half of run b alone finds its current too
        assert fold["b"]["current"]["east_mps"] == pytest.approx(-0.05, abs=1e-3)
    assert cand.p == 2  # two parameters per held-out run
    assert cand.cost_hold < 1e-8 and cand.cost_hold_insample is not None
    assert "current.north_mps@b" in cand.table and "current.north_mps@a" in cand.table


def test_phase_shrinkage_of_the_right_effect_is_complete_in_every_phase() -> None:
    train, hold = exact(bias(2.0)), exact(bias(2.0), TURN, "b", 1.0)
    sc = fit.scales(train, LENGTH)
    cand = fit.Candidate(("compass_bias",), bias(2.0), {}, 0.0, 0.0, 3)
    half = fit.Candidate(("compass_bias",), bias(1.0), {}, 0.0, 0.0, 3)
    full = fit.phase_shrinkage(SPEC, cand, hold, sc)
    present = {PHASES[k] for k in np.unique(hold.phase[_scored(hold)])}
    assert set(full) == present and len(present) >= 2
    assert all(v == pytest.approx(1.0, abs=1e-9) for v in full.values())
    # against a candidate as its own base nothing shrinks
    assert all(v == pytest.approx(0.0, abs=1e-12)
               for v in fit.phase_shrinkage(SPEC, half, hold, sc, half).values())


# --- injection and recovery on small noisy runs -------------------------------------------------

TURN_B = np.where(_T < 20, 0.0, 25.0)
NOISE = (1.0, 0.2, 0.05)  # position m, heading deg, velocities m/s (the self-test's levels)
CANDIDATES = ("current", "lever_arm", "resistance", "propeller_asymmetry")


def sailed(name: str, rudder_deg: np.ndarray, psi0: float = 0.0,
           hidden: Mapping[str, Mapping[str, float]] | None = None,
           rng: np.random.Generator | None = None, noise: float = 1.0) -> Kinematics:
    """The KVLCC2 with the ``hidden`` effects (hull effects on its spec, current in the
    replay, instruments through :func:`effects.measure`) replayed through ``rudder_deg`` at
    2 s; with ``rng``, white noise of ``noise`` times :data:`NOISE` on the measured channels,
    while the "smoothed" state stays the noise-free measurement (a perfect smoother)."""
    hidden = effects.check(hidden or {})
    n = len(rudder_deg)
    t = np.arange(n) * DT
    rud = np.radians(np.asarray(rudder_deg, float))
    rps = np.full(n, _rps())
    off = effects.environment_offset(hidden)
    x0 = np.zeros((base.N_STATE, 1))
    x0[2, 0], x0[3, 0] = psi0, SPEED
    env = np.zeros((1, n, 4))
    env[..., 0], env[..., 1] = off[0], off[1]
    win = replay.Windows(x0, np.stack([rud, rps], -1)[None], env, np.array([DT]),
                         np.array([n]), np.full((1, n, 6), np.nan), np.array([0]),
                         np.array([0.0]), (name,))
    truth, _ = replay.simulate(replay.model_rows([effects.apply_spec(SPEC, hidden)]), win)
    m = {k: v[0, 0] for k, v in effects.measure(truth, np.array([DT]), [hidden]).items()}
    smooth = {"north_m": m["north"].copy(), "east_m": m["east"].copy(),
              "psi_rad": m["psi"].copy(), "u_mps": m["u"].copy(), "v_mps": m["v"].copy(),
              "r_radps": m["r"].copy()}
    if rng is not None:
        pos, head, vel = (noise * s for s in NOISE)
        for k in ("north", "east"):
            m[k] = m[k] + rng.normal(0.0, pos, n)
        m["psi"] = m["psi"] + np.radians(rng.normal(0.0, head, n))
        for k in ("u", "v", "sog"):
            m[k] = m[k] + rng.normal(0.0, vel, n)
        m["r"] = m["r"] + rng.normal(0.0, vel / LENGTH, n)
        m["cog"] = m["cog"] + rng.normal(0.0, vel / SPEED, n)
    trial = TrialData(name, "", t, m["north"], m["east"], np.mod(m["psi"], 2 * np.pi), rud, rps,
                      u_mps=m["u"], v_mps=m["v"], r_radps=m["r"], sog_mps=m["sog"],
                      cog_rad=np.mod(m["cog"], 2 * np.pi))
    return Kinematics(trial, smooth, {}, {})


def trio(hidden: Mapping[str, Any] | None, seed: int | None = 1, noise: float = 1.0
         ) -> tuple[Dataset, Dataset]:
    """Training runs ``a`` (zig-zag) and ``c`` (port turn), held-out run ``b`` (starboard
    turn), 4 windows of 30 s each; noise-free with ``seed=None``."""
    rng = None if seed is None else np.random.default_rng(seed)
    train = dataset([sailed("a", ZIGZAG, 0.0, hidden, rng, noise),
                     sailed("c", TURN, 3.0, hidden, rng, noise)], HORIZON)
    hold = dataset([sailed("b", TURN_B, 1.0, hidden, rng, noise)], HORIZON)
    return train, hold


def test_a_near_tie_is_named_in_the_verdict() -> None:
    """A hidden steering lag: a report latency explains the late response nearly as well, and
    the verdict says so; an effect far behind (resistance) is not named."""
    hidden = {"steering_lag": {"tau_s": 8.0, "rate_degps": 1.5}}
    runs = selftest.simulate_trial(SPEC, effects.check(hidden), np.random.default_rng(0))
    train, hold = selftest.prepare(SPEC, *runs)
    diag = fit.diagnose(SPEC, train, hold, ("steering_lag", "ais_latency", "resistance"),
                        forward_steps=1)
    first, second = diag.singles[0].effects[0], diag.singles[1].effects[0]
    assert {first, second} == {"steering_lag", "ais_latency"} and diag.attributable
    assert f"; nearly as good alone: {second} (" in diag.verdict
    assert "(the data hardly tell them apart); chosen without each held-out run" in diag.verdict
    assert "resistance" not in diag.verdict
    # each held-out run alone prefers the other rival: the check sees the tie too
    check = diag.check
    assert {tuple(part["chosen"]) for part in check["parts"]} == {(first,), (second,)}
    assert check["same_choice"] == 1
    assert diag.verdict.endswith(f"the same 1 of 2 times, and the gap "
                                 f"{fit.gap_change(check['shrinkage_holdout'])} on the runs "
                                 "left out")
    assert fit.gap_change(0.77) == "77 % smaller" and fit.gap_change(-0.104) == "10 % larger"
    assert fit.gap_change(-0.004) == "0 % smaller"


@pytest.mark.parametrize(("hidden", "noise", "tol"), [
    ({"lever_arm": {"x_m": -80.0, "y_m": 5.0}}, 1.0, 0.05),
    (current(0.3, -0.2), 1.0, 0.1),
    ({"resistance": {"scale": 1.6}}, 0.3, 0.05),
    ({"propeller_asymmetry": {"rudder_offset_deg": 3.0}}, 0.3, 0.05),
], ids=["lever_arm", "current", "resistance", "propeller_asymmetry"])
def test_injected_effect_is_ranked_first_chosen_and_its_size_recovered(hidden, noise,
                                                                       tol) -> None:
    """An effect hidden in noisy runs: it is ranked first and chosen alone, the verdict names
    it with the held-out shrinkage it reports, its magnitude (training runs' mean for the
    current, as the self-test measures it) is within ``tol``, and what is left of the held-out
    gap is the noise: the cost with the effect is within 1.5 times the noise floor."""
    name = next(iter(hidden))
    train, hold = trio(hidden, noise=noise)
    diag = fit.diagnose(SPEC, train, hold, CANDIDATES, forward_steps=1)
    best = diag.singles[0]
    assert diag.attributable and best.effects == (name,) and diag.chosen.effects == (name,)
    shrink = best.shrinkage(diag.base)[1]
    assert diag.verdict.startswith(f"{name}: held-out gap {100 * shrink:.0f} % smaller")
    eff = effects.REGISTRY[name]
    truth = eff.magnitude(effects.check(hidden)[name])
    got = eff.magnitude(best.mean_value(name, train.windows.run_names))
    assert got == pytest.approx(truth, rel=tol)
    assert diag.base.cost_hold > 3.0 * diag.floor_hold
    assert best.cost_hold < 1.5 * diag.floor_hold
    if name == "current":  # every run's own vector, held-out run b included, within a
        # quarter of the current's speed
        for run_name in ("a", "b", "c"):
            v = best.run_values[run_name]["current"]
            err = np.hypot(v["north_mps"] - 0.3, v["east_mps"] + 0.2)
            assert err < 0.25 * np.hypot(0.3, 0.2), run_name


def test_no_effect_attributes_nothing() -> None:
    """Noisy runs of the base ship itself: the held-out gap is the noise (its ratio to the
    floor is what the verdict prints), no candidate's penalised score reaches MIN_GAIN, so
    nothing is added, the base is kept, and the residuals after are those before."""
    train, hold = trio(None)
    diag = fit.diagnose(SPEC, train, hold, CANDIDATES, forward_steps=2)
    ratio = diag.base.cost_hold / diag.floor_hold
    assert ratio < fit.FLOOR_FACTOR
    assert diag.verdict == (f"not attributable: the held-out gap is {ratio:.1f} times the "
                            f"data's noise floor (below 3)")
    assert not diag.attributable and diag.chosen is diag.base and diag.steps == []
    for c in diag.singles:
        score = 1.0 - fit.penalised(c.cost_hold, c.p, diag.n_eff) / diag.base.cost_hold
        assert score <= fit.MIN_GAIN, c.effects
    for label in ("train", "holdout"):
        assert diag.residuals[label]["after"] == diag.residuals[label]["before"]


def test_noise_free_base_runs_are_not_attributable() -> None:
    """Exact data of the base ship: no gap at all (a zero ratio), whatever the candidates."""
    train, hold = trio(None, seed=None)
    diag = fit.diagnose(SPEC, train, hold, ("resistance", "compass_bias"), forward_steps=1)
    assert not diag.attributable and diag.chosen.effects == ()
    assert "held-out gap is 0.0 times" in diag.verdict


def test_progress_names_each_fit_as_it_ends() -> None:
    train, hold = trio(None, seed=None)
    lines: list[str] = []
    fit.diagnose(SPEC, train, hold, ("resistance", "compass_bias"), forward_steps=1,
                 progress=lines.append)
    assert len(lines) == 3 and lines[0].startswith("base: held-out cost ")
    assert lines[1].startswith("resistance (1/2): held-out gap ") and lines[1].endswith(" s)")
    assert lines[2].startswith("compass_bias (2/2): held-out gap ")


def test_below_the_floor_the_base_is_chosen_and_the_trace_kept() -> None:
    """A rudder offset of 3 deg under full noise: the effect shrinks the held-out cost by
    more than 5 % and the selection adds it, but the gap is below 3 times the floor, so the
    verdict keeps the base; ``steps`` still shows what the selection found."""
    train, hold = trio({"propeller_asymmetry": {"rudder_offset_deg": 3.0}})
    diag = fit.diagnose(SPEC, train, hold, ("current", "propeller_asymmetry"), forward_steps=1)
    assert not diag.attributable and diag.chosen.effects == ()
    assert "not attributable: the held-out gap is" in diag.verdict
    assert [s["effects"] for s in diag.steps] == [["propeller_asymmetry"]]
    # the check's parts choose without the gate, and are compared with what the selection
    # found before it (each half of held-out run b alone finds the offset too)
    assert [p["chosen"] for p in diag.check["parts"]] == [["propeller_asymmetry"]] * 2
    assert diag.check["same_choice"] == 2


def test_refitted_base_absorbs_a_resistance_change() -> None:
    """With ``refit=("R0",)`` the base is the hull refitted on the training runs: a 60 %
    higher resistance goes into R0 (0.022 x 1.6) and the resistance effect, which only scales
    R0 again, has nothing left to explain on the held-out run."""
    train, hold = trio({"resistance": {"scale": 1.6}}, noise=0.3)
    diag = fit.diagnose(SPEC, train, hold, ("resistance",), forward_steps=1, refit=("R0",))
    assert diag.base.coefficients["R0"] == pytest.approx(0.022 * 1.6, rel=0.02)
    res = diag.singles[0]
    assert res.shrinkage(diag.base)[1] < fit.MIN_GAIN
    assert diag.chosen.effects == () and not diag.attributable
    assert diag.base.cost_hold < 1.5 * diag.floor_hold


# --- the held-out check sees only data the fit did not -----------------------------------------


def _with_target(data: Dataset, target: np.ndarray) -> Dataset:
    return Dataset(data.runs, data.windows, target, data.phase, data.sigma, data.channels)


def test_training_fit_never_reads_the_held_out_targets() -> None:
    """A global effect is fitted on the training runs only: spoiling every held-out target
    leaves its values, table and training cost bit for bit unchanged and only raises the
    held-out cost."""
    lever = {"lever_arm": {"x_m": 60.0, "y_m": -4.0}}
    train, hold = exact(lever), exact(lever, TURN, "b", 1.0)
    sc = fit.scales(train, LENGTH)
    clean = fit.fit_set(SPEC, ("lever_arm",), train, hold, sc)
    target = hold.target.copy()
    target[..., CHANNELS.index("north")] += 40.0
    target[..., CHANNELS.index("psi")] += 0.3
    spoiled = fit.fit_set(SPEC, ("lever_arm",), train, _with_target(hold, target), sc)
    assert spoiled.values == clean.values and spoiled.table == clean.table
    assert spoiled.cost_train == clean.cost_train
    assert clean.values["lever_arm"]["x_m"] == pytest.approx(60.0, abs=0.05)
    assert spoiled.cost_hold > 1e3 * max(clean.cost_hold, 1e-9)


def test_cross_fitting_scores_each_window_with_a_vector_fitted_without_it() -> None:
    """Held-out run b (4 windows, folds {0, 2} and {1, 3}): spoiling window 1 leaves the
    current fitted on the first fold bit for bit unchanged and moves the other; spoiling
    window 0 does the opposite; and the held-out cost is the sum over windows, each window
    replayed alone (a one-window subset) with the current of the fold it is not in."""
    train = exact(current(0.1, 0.25), ZIGZAG, "a", 0.0)
    hold = exact(current(0.15, -0.05), TURN, "b", 1.0)
    sc = fit.scales(train, LENGTH)
    noise = np.random.default_rng(4).normal(0.0, 1.0, hold.target.shape)
    noisy = _with_target(hold, hold.target + noise * np.array([2, 2, 0.003, 0.02, 0.02, 1e-4,
                                                               0.02, 0.003]))
    clean = fit.fit_set(SPEC, ("current",), train, noisy, sc)
    assert fit.alternate(noisy).tolist() == [True, False, True, False]
    folds = clean.fold_run_values
    for k, window in ((0, 1), (1, 0)):
        target = noisy.target.copy()
        target[window, :, CHANNELS.index("north")] += 30.0
        spoiled = fit.fit_set(SPEC, ("current",), train, _with_target(noisy, target), sc)
        assert spoiled.fold_run_values[k] == folds[k], window
        assert spoiled.fold_run_values[1 - k]["b"] != folds[1 - k]["b"], window
        assert spoiled.run_values["a"] == clean.run_values["a"]  # training run untouched
    total = 0.0
    for i in range(noisy.windows.w):
        other = folds[0] if i % 2 else folds[1]
        one = noisy.subset(np.arange(noisy.windows.w) == i)
        total += fit.EffectResiduals(fit.EffectSet.of(SPEC, ("current",), run_fixed=other),
                                     one, sc).cost(np.zeros(0))
    assert clean.cost_hold == pytest.approx(total, rel=1e-10)
    assert clean.cost_hold_insample < clean.cost_hold  # in sample is the optimistic one


def test_held_out_run_of_one_window_is_scored_with_the_environment_off() -> None:
    """A held-out run of a single window has no second fold: it is scored with the current
    off (module doc), i.e. exactly like the base ship, while its full-run fit finds the
    current."""
    train = exact(current(0.2, 0.1), ZIGZAG, "a", 0.0)
    hold = dataset([sailed("b", TURN[:16], 1.0, current(0.2, 0.1))], HORIZON)
    assert hold.windows.w == 1
    sc = fit.scales(train, LENGTH)
    cand = fit.fit_set(SPEC, ("current",), train, hold, sc)
    assert "b" in cand.fold_run_values[0] and "b" not in cand.fold_run_values[1]
    off = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), hold, sc).cost(np.zeros(0))
    assert off > 0.1 and cand.cost_hold == pytest.approx(off, rel=1e-12)
    assert cand.cost_hold_insample < 1e-6 * off
    got = cand.run_values["b"]["current"]
    assert (got["north_mps"], got["east_mps"]) == pytest.approx((0.2, 0.1), abs=1e-3)


# --- edge cases ---------------------------------------------------------------------------------


def test_nan_gaps_in_measured_channels_are_left_out() -> None:
    """Samples 20-24 of the north position and SOG from sample 45 on missing in the trial:
    with a uniform 5 m north offset the cost is that of the remaining north samples, the RMS
    stays 5 m, and the missing samples leave the count ``m`` and the floor's counts."""
    k = run("a", ZIGZAG, 6.0)
    north, sog = k.trial.north_m.copy(), k.trial.sog_mps.copy()
    north[20:25] = np.nan
    sog[45:] = np.nan
    trial = replace(k.trial, north_m=north, sog_mps=sog)
    data = dataset([Kinematics(trial, k.smooth, {}, {})], HORIZON)
    sc = fit.scales(data, LENGTH)
    full = exact()
    # windows 0-15, 15-30, 30-45, 45-60 (shared boundaries), each scored after its first
    # sample: north loses 20-24 (window 1), SOG loses 45 (end of window 2) and 46-60
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), _shifted(data, "north", 5.0), sc)
    assert res.m == full.windows.w * 15 * 8 - 5 - 16
    assert res.cost(np.zeros(0)) == pytest.approx(0.5 * (60 - 5) * (5.0 / sc["north"]) ** 2)
    assert res.by_channel(np.zeros(0))["north"] == pytest.approx(5.0)
    sigma = np.full(8, 0.01)
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), Dataset(
        data.runs, data.windows, data.target, data.phase, sigma, data.channels), sc)
    counts = np.full(8, 60)
    counts[0], counts[6] = 55, 44
    assert res.floor() == pytest.approx(0.5 * sum(
        n * (0.01 / sc[c]) ** 2 for n, c in zip(counts, CHANNELS, strict=True)))


def test_a_dataset_without_windows_costs_nothing() -> None:
    """No window (an empty subset): nothing is scored, the cost and floor are zero, no phase is
    reported and every channel's RMS is NaN; a fit with such held-out data still fits the
    training runs as usual."""
    data = exact(bias(2.0))
    empty = data.subset(np.zeros(data.windows.w, dtype=bool))
    sc = fit.scales(data, LENGTH)
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), empty, sc)
    assert res.m == 0 and res.cost(np.zeros(0)) == 0.0 and res.floor() == 0.0
    assert res.by_phase(np.zeros(0)) == {}
    assert all(np.isnan(v) for v in res.by_channel(np.zeros(0)).values())
    cand = fit.fit_set(SPEC, ("compass_bias",), data, empty, sc)
    with_hold = fit.fit_set(SPEC, ("compass_bias",), data, exact(bias(2.0), TURN, "b"), sc)
    assert cand.values == with_hold.values and cand.cost_hold == 0.0


def test_straight_steady_runs_attribute_nothing() -> None:
    """Runs with the rudder amidships throughout (constant heading and speed): every sample
    is in the approach phase, and with noise the diagnosis attributes nothing."""
    rng = np.random.default_rng(2)
    zero = np.zeros(46)
    train = dataset([sailed("a", zero, 0.5, None, rng), sailed("c", zero, 2.0, None, rng)],
                    HORIZON)
    hold = dataset([sailed("b", zero, 4.0, None, rng)], HORIZON)
    assert set(np.unique(train.phase[train.windows.valid()])) == {0}
    diag = fit.diagnose(SPEC, train, hold, ("current", "resistance"), forward_steps=1)
    assert not diag.attributable and diag.chosen.effects == ()
    assert set(diag.residuals["holdout"]["before"]["by_phase"]) == {"approach"}


def test_gear_start_of_a_stable_lag_settles_on_the_logged_rudder() -> None:
    """A 1 s lag without rate limiting (the log's ramps, 10 and 20 deg/s over 2 s, make it
    turn at 20 deg/s at most, under 90 deg/s): a ramp of slope a leaves the lag tau a (1 -
    exp(-2 / tau)) behind at its end, which decays as exp(-t / tau) over the 10 s to the next
    window start (windows at 30 and 90 s; the one at 60 s, 40 s on, has settled): the exact
    lag of the linear input, however the steps are cut."""
    data = exact()
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    start = res.gear_start(np.array([[1.0, np.radians(90.0)]]))[0]
    behind = (1.0 - np.exp(-2.0)) * np.exp(-10.0)  # per deg/s of ramp, tau = 1 s
    assert np.degrees(start) == pytest.approx([0.0, 20.0 - 10.0 * behind, 20.0,
                                               -20.0 + 20.0 * behind], abs=1e-9)


def test_gear_start_of_a_fast_lag_is_the_logged_rudder() -> None:
    """A gear at the fit's lower bound (0.05 s lag, 90 deg/s) reaches a 20 deg step in about
    0.25 s and then stays there: 10 s after each step it is at the logged angle. A first-order
    lag with a rate limit never overshoots its target."""
    data = exact()
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    lower = effects.bounds("steering_lag", LENGTH)[0][0]
    start = res.gear_start(np.array([[lower, np.radians(90.0)]]))[0]
    assert np.degrees(start) == pytest.approx([0.0, 20.0, 20.0, -20.0], abs=0.01)


def test_gear_start_bridges_a_gap_in_the_logged_rudder() -> None:
    """The logged rudder missing at 26 and 28 s while it stays at 20 deg (20-78 s): the replay
    interpolates the gap (window inputs at 20 deg), and a 1 s, 5 deg/s gear that has been at
    20 deg since about 25 s is still there at the 30 s window start."""
    k = run("a", ZIGZAG, 6.0)
    rud = k.trial.rudder_rad.copy()
    rud[13:15] = np.nan
    data = dataset([Kinematics(replace(k.trial, rudder_rad=rud), k.smooth, {}, {})], HORIZON)
    assert np.degrees(data.windows.inputs[1, 0, 0]) == pytest.approx(20.0)
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    start = res.gear_start(np.array([[1.0, np.radians(5.0)]]))[0]
    assert np.degrees(start[1]) == pytest.approx(20.0, abs=0.05)


def test_gear_start_is_the_gear_on_the_log_read_linearly_between_samples() -> None:
    """On an irregular log, the gear at every window start equals a fine independent
    integration (1 ms Euler) of the lag with its rate limit driven by the log interpolated
    linearly between samples, as the replay drives its windows (a log held for each sample
    would leave the gear about half a sample behind)."""
    rng = np.random.default_rng(7)
    log = np.clip(np.cumsum(rng.normal(0.0, 6.0, N)), -35.0, 35.0)
    data = exact(rudder=log)
    res = fit.EffectResiduals(fit.EffectSet.of(SPEC, ()), data, fit.scales(data, LENGTH))
    gears = [(4.0, 2.5), (8.0, 1.0), (1.0, 90.0)]  # lag s, rate deg/s
    start = np.degrees(res.gear_start(np.array([[tau, np.radians(rate)] for tau, rate in gears])))
    h = 0.001
    for g, (tau, rate) in enumerate(gears):
        y, t, expected = log[0], 0.0, []
        for t0 in (0.0, 30.0, 60.0, 90.0):
            while t < t0 - 1e-9:
                y += h * min(max((np.interp(t, _T, log) - y) / tau, -rate), rate)
                t += h
            expected.append(y)
        assert start[g] == pytest.approx(expected, abs=0.02), (tau, rate)
