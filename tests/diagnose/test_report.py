"""Reports of a diagnosis (trafficsim.diagnose.report): the JSON summary of a hand-made
diagnosis on small exact data, the one-page markdown and parameter text of a hand-made report,
the files written, and the numbers of a real small diagnosis recomputed from its fits."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.diagnose.test_fit import LENGTH, SPEC, TURN, bias, current, exact, trio
from trafficsim.diagnose import fit, report
from trafficsim.diagnose.data import ANGLES, CHANNELS, PHASES


def _table(**values: tuple[float, float]) -> dict[str, dict[str, float]]:
    """Fit table rows ``name=(value, half width)`` (``__`` for ``.``, ``_at_`` for ``@``)."""
    return {k.replace("__", ".").replace("_at_", "@"):
            {"value": v, "ci95_low": v - h, "ci95_high": v + h} for k, (v, h) in values.items()}


def _diagnosis(chosen_effect: bool = True) -> tuple[fit.Diagnosis, Any, Any]:
    train, hold = exact(bias(2.0)), exact(bias(2.0), TURN, "b", 1.0)
    base_c = fit.Candidate((), {}, {}, 8.0, 10.0, 0)
    right = fit.Candidate(("compass_bias",), bias(2.0), _table(compass_bias__bias_deg=(2.0, 0.1)),
                          2.0, 1.0, 3)
    # resistance at its off value: the base ship itself, nothing shrinks in any phase
    idle = fit.Candidate(("resistance",), {"resistance": {"scale": 1.0}},
                         _table(resistance__scale=(1.0, 0.02)), 6.0, 9.0, 1,
                         cost_hold_insample=7.0)
    residuals = {"holdout": {"before": {"by_phase": {
        "approach": {"samples": 3, "cost_share": 0.2}, "execute": {"samples": 4, "cost_share": 0.7},
        "steady": {"samples": 5, "cost_share": 0.1}}}}}
    chosen = right if chosen_effect else base_c
    diag = fit.Diagnosis(base_c, [right, idle], chosen, [{"added": "compass_bias"}], 0.5, 2.0,
                         30, chosen_effect, "verdict text", 1.5, residuals)
    return diag, train, hold


def test_summary_scores_and_gap_of_a_hand_made_diagnosis() -> None:
    diag, train, hold = _diagnosis()
    rep = report.summary(SPEC, diag, train, hold, {"refit": ["R0"]})
    first, second = rep["ranking"]
    assert first["effect"] == "compass_bias" and second["effect"] == "resistance"
    assert first["shrinkage_train"] == pytest.approx(0.75)
    assert first["shrinkage_holdout"] == pytest.approx(0.9)
    assert first["shrinkage_holdout_insample"] == pytest.approx(0.9)
    assert second["shrinkage_holdout_insample"] == pytest.approx(0.3)
    # 1 - J (1 + 2 p / n_eff) / J_base
    assert first["penalised_score"] == pytest.approx(1 - 1.0 * (1 + 6 / 30) / 10.0)
    assert second["penalised_score"] == pytest.approx(1 - 9.0 * (1 + 2 / 30) / 10.0)
    # per phase on the held-out data: the right bias removes everything, the idle effect nothing
    assert len(first["per_phase"]) >= 2 and set(first["per_phase"]) == set(second["per_phase"])
    assert all(v == pytest.approx(1.0, abs=1e-9) for v in first["per_phase"].values())
    assert all(v == pytest.approx(0.0, abs=1e-9) for v in second["per_phase"].values())
    ch = rep["chosen"]
    assert ch["effects"] == ["compass_bias"] and ch["per_phase"] == first["per_phase"]
    assert (ch["shrinkage_train"], ch["shrinkage_holdout"]) == pytest.approx((0.75, 0.9))
    g = rep["gap"]
    assert g["holdout_gap_over_floor"] == pytest.approx(5.0)
    assert g["phases_by_share"] == ["execute", "approach", "steady"]
    assert (g["cost_holdout_before"], g["cost_holdout_after"]) == (10.0, 1.0)
    assert rep["windows"] == {"train": 4, "holdout": 4, "samples_per_window": 16}
    assert rep["channel_scales"]["north"] == pytest.approx(0.1 * LENGTH)
    assert rep["refit"] == ["R0"] and rep["verdict"] == "verdict text"


def test_summary_with_nothing_chosen() -> None:
    diag, train, hold = _diagnosis(chosen_effect=False)
    ch = report.summary(SPEC, diag, train, hold)["chosen"]
    assert ch["effects"] == [] and ch["per_phase"] == {}
    assert ch["shrinkage_train"] == ch["shrinkage_holdout"] == 0.0
    assert ch["shrinkage_holdout_insample"] == 0.0


def test_parameter_text_global_with_half_width_and_runs_counted() -> None:
    table = _table(compass_bias__bias_deg=(2.0, 0.1), base__R0=(0.03, 0.001),
                   current__north_mps_at_a=(0.1, 0.01), current__east_mps_at_a=(0.2, 0.01),
                   current__north_mps_at_b=(0.3, 0.01))
    assert report.parameter_text(table) == ("bias_deg 2 +- 0.1; "
                                            "one value per run (2 runs, report.json)")
    assert report.parameter_text(_table(resistance__scale=(1.23456, 0.0456))) == \
        "scale 1.235 +- 0.046"
    assert report.parameter_text({}) == ""
    # an interval the data do not bound (JSON null or inf), a value on its bound
    loose = {"steering_lag.tau_s": {"value": 1.15, "ci95_low": 1.0, "ci95_high": 1.3},
             "steering_lag.rate_degps": {"value": 49.97, "ci95_low": -np.inf,
                                         "ci95_high": np.inf},
             "compass_bias.deviation_c_deg": {"value": 20.0, "ci95_low": 19.0,
                                              "ci95_high": None, "at_bound": True}}
    assert report.parameter_text(loose) == (
        "tau_s 1.15 +- 0.15; rate_degps 49.97 (not determined by the data); "
        "deviation_c_deg 20 (not determined by the data) (on its bound)")
    assert report.parameter_text({"a.b": {"value": 20.0, "ci95_high": 21.0,
                                          "at_bound": True}}) == "b 20 +- 1 (on its bound)"
    assert report.parameter_text({"a.b": {"value": 2.0, "ci95_high": 2.1,
                                          "ci95_clustered_high": 2.5}}) == (
        "b 2 +- 0.1 (0.5 windows clustered)")


def test_confirmation_lines() -> None:
    row = {"run": "a", "role": "training", "fitted_speed_mps": 12.345, "fitted_towards_deg": 90.4,
           "logged_vector_speed_mps": 11.111, "logged_mean_speed_mps": 12.0,
           "logged_towards_deg": 100.6, "direction_error_deg": -10.2}
    conf = {"text": "Winds agree.", "wind": {"runs": [row, {**row, "run": "b",
                                                             "direction_error_deg": 4.6}],
                                             "n_runs": 2}}
    lines = report.confirmation_lines(conf)
    assert lines[0] == "## Confirmation (logged wind, not used by the diagnosis)"
    assert lines[2] == "Winds agree."
    assert "Fitted `wind` per run (air or water velocity towards):" in lines
    assert "| a | training | 12.3 | 90 | 11.11 / 12.00 | 101 | -10 |" in lines
    assert "| b | training | 12.3 | 90 | 11.11 / 12.00 | 101 | +5 |" in lines


def _rep(chosen: tuple[str, ...] = ("compass_bias",)) -> dict[str, Any]:
    nan = float("nan")
    before = {"approach": {"samples": 3, "cost_share": 0.25, "north": 12.345, "psi": 2.0},
              "steady": {"samples": 7, "cost_share": 0.75, "north": 0.5, "psi": 1.0}}
    after = {"approach": {"samples": 3, "cost_share": 0.5, "north": 0.01234, "psi": nan},
             "steady": {"samples": 7, "cost_share": 0.5, "north": 0.02, "psi": 0.1}}
    return {
        "ship": "kvlcc2", "verdict": "compass_bias: held-out gap 90 % smaller",
        "ranking": [{"effect": "compass_bias", "parameters": _table(
            compass_bias__bias_deg=(2.0, 0.1)), "shrinkage_train": 0.754,
            "shrinkage_holdout": 0.9, "shrinkage_holdout_insample": 0.926,
            "penalised_score": 0.88}],
        "chosen": {"effects": list(chosen), "shrinkage_holdout": 0.9 if chosen else 0.0,
                   "per_phase": {"approach": 0.999, "steady": 0.5} if chosen else {}},
        "gap": {"cost_train_before": 8.0, "cost_holdout_before": 10.0, "cost_train_after": 2.0,
                "cost_holdout_after": 1.0, "noise_floor_train": 0.5, "noise_floor_holdout": 2.0,
                "holdout_gap_over_floor": 5.0, "phases_by_share": ["steady", "approach"]},
        "residuals": {"holdout": {"before": {"by_phase": before},
                                  "after": {"by_phase": after}}},
        "channels": ["north", "psi"],
    }


def test_markdown_where_which_and_how_far() -> None:
    lines = report.markdown(_rep()).splitlines()
    assert lines[0] == "# Sim-to-real gap diagnosis: kvlcc2"
    assert "**Verdict:** compass_bias: held-out gap 90 % smaller" in lines
    assert ("Held-out gap 5.0 times the data's noise floor. Phases by share of the held-out "
            "gap: steady 75 %, approach 25 %.") in lines
    assert "| phase | samples | north (m) before / after | psi (deg) before / after |" in lines
    # phases in their manoeuvre order, absent ones left out
    rows = [ln for ln in lines if ln.startswith(("| approach", "| execute", "| steady"))]
    assert rows == ["| approach | 3 | 12.3 / 0.0123 | 2 / nan |",
                    "| steady | 7 | 0.5 / 0.02 | 1 / 0.1 |"]
    assert "| 1 | compass_bias | bias_deg 2 +- 0.1 | 75 % | 90 % | 93 % | 88 % |" in lines
    assert ("Chosen (forward selection): compass_bias. Held-out cost 10 -> 1 (90 % smaller; "
            "noise floor 2); training 8 -> 2.") in lines
    assert "Held-out shrinkage per phase: approach 100 %, steady 50 %." in lines
    assert "![residuals by phase](residuals_by_phase.png)" in lines
    assert not any(ln.startswith(("## Confirmation", "## Notes")) for ln in lines)


def test_markdown_states_the_selection_check() -> None:
    rep = _rep()
    rep["selection_check"] = {
        "parts": [{"left_out": "x", "windows": 3, "chosen": ["compass_bias"],
                   "shrinkage": 0.804},
                  {"left_out": "y", "windows": 2, "chosen": [], "shrinkage": 0.0}],
        "same_choice": 1, "shrinkage_holdout": 0.5}
    lines = report.markdown(rep).splitlines()
    assert ("Selection check (the choice made on the other held-out data, scored on the part "
            "left out): the same choice 1 of 2 times; gap 50 % smaller on the parts left out: "
            "what a choice does on held-out data it has not seen.") in lines
    assert "| x | 3 | compass_bias | 80 % |" in lines and "| y | 2 | nothing | 0 % |" in lines
    rep["selection_check"]["shrinkage_holdout"] = -0.104
    assert "; gap 10 % larger on the parts left out" in report.markdown(rep)
    rep["selection_check"] = {}
    assert "Selection check: needs two or more held-out windows." in report.markdown(rep)


def test_markdown_setup_names_ship_runs_split_windows_and_candidates() -> None:
    rep = _rep()
    assert "## Setup" not in report.markdown(rep)  # (no data: a report of the Python API)
    rep.update(data={"ship": "ships/x.yaml", "train": ["/d/a.csv", "/d/b.csv"],
                     "holdout": ["/d/c.csv"], "holdout_split": "held-out runs",
                     "working_dt_s": 0.5, "horizon_s": 22.5,
                     "wind_columns": "withheld (not used by the diagnosis)"},
               windows={"train": 40, "holdout": 12}, candidates=["wind", "current"],
               refit=["R0"])
    lines = report.markdown(rep).splitlines()
    at = lines.index("## Setup")
    assert lines[at + 2: at + 8] == [
        "- Ship: ships/x.yaml; base coefficients refitted with every candidate: R0",
        "- Training runs: a.csv, b.csv", "- Held out: c.csv",
        "- Windows: 40 training, 12 held out, 22.5 s each, replayed at 0.5 s; wind columns "
        "withheld (not used by the diagnosis)", "- Candidates: wind, current", ""]
    assert at < lines.index("## Where")
    rep["data"].update(holdout=[], holdout_split="alternate windows of the same runs")
    text = report.markdown(rep)
    assert "- Held out: alternate windows of the same runs\n" in text
    assert "not on runs it has not seen. Give `--holdout` runs for that." in text


def test_markdown_with_nothing_chosen_confirmation_and_notes() -> None:
    rep = _rep(chosen=())
    rep["notes"] = "ignored entries: x"
    rep["confirmation"] = {"text": "conf text", "wind": {"runs": []}}
    text = report.markdown(rep)
    assert "Chosen (forward selection): nothing." in text
    assert "Held-out shrinkage per phase" not in text
    assert text.index("## Confirmation") < text.index("## Notes\n\nignored entries: x")


def test_write_puts_json_markdown_and_plot_in_a_new_folder(tmp_path: Path) -> None:
    rep = _rep()
    out = tmp_path / "deep" / "out"
    report.write(out, rep)
    saved = json.loads((out / "report.json").read_text())
    assert saved["residuals"]["holdout"]["after"]["by_phase"]["approach"]["psi"] is None  # NaN
    assert saved["ranking"][0]["parameters"]["compass_bias.bias_deg"]["value"] == 2.0
    assert (out / "report.md").read_text() == report.markdown(rep)
    png = (out / "residuals_by_phase.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 1000
    assert sorted(p.name for p in out.iterdir()) == ["report.json", "report.md",
                                                     "residuals_by_phase.png"]
    assert np.isnan(rep["residuals"]["holdout"]["after"]["by_phase"]["approach"]["psi"])


# --- a real small diagnosis, its numbers recomputed ----------------------------------------------

Z = np.zeros(0)


@pytest.fixture(scope="module")
def real() -> tuple[dict[str, Any], fit.Diagnosis, Any, Any, dict[str, float]]:
    """Noisy runs with a current and a GNSS antenna 80 m aft: both are chosen."""
    hidden = {**current(0.3, -0.2), "lever_arm": {"x_m": -80.0, "y_m": 5.0}}
    train, hold = trio(hidden)
    diag = fit.diagnose(SPEC, train, hold, ("current", "lever_arm", "resistance"),
                        forward_steps=2)
    return report.summary(SPEC, diag, train, hold), diag, train, hold, fit.scales(train, LENGTH)


def _windows_cost(cand: fit.Candidate, hold: Any, sc: dict[str, float]) -> np.ndarray:
    """``(W, N, c)`` weighted squared errors of a candidate on the held-out windows, each
    window replayed alone with the environment of the fold it is not in (``alternate``: the
    even windows of run b are the first fold)."""
    out = []
    for i in range(hold.windows.w):
        env = cand.run_values
        if cand.fold_run_values:
            env = cand.fold_run_values[1 if i % 2 == 0 else 0]
        one = hold.subset(np.arange(hold.windows.w) == i)
        res = fit.EffectResiduals(fit.EffectSet.of(SPEC, cand.effects, fixed=cand.values,
                                                   run_fixed=env), one, sc)
        out.append(res.errors(Z)[0, 0] * res._weights)
    return np.array(out) ** 2


def test_real_summary_scores_agree_with_recomputed_costs(real) -> None:
    """Each ranking row's shrinkages are ``1 - J_with / J_base`` of the candidate replayed
    again (training, cross-fitted held-out, held-out with full-run environments), its
    penalised score uses ``p`` = 2 per held-out run for the current, the effect's own
    parameters otherwise, and ``n_eff`` = held-out windows x 8 channels; rows are best first."""
    rep, diag, train, hold, sc = real
    assert diag.chosen.effects == ("current", "lever_arm")
    base_t = fit.evaluation(SPEC, diag.base, train, sc).cost(Z)
    base_h = float(np.sum(_windows_cost(diag.base, hold, sc))) / 2
    assert diag.base.cost_hold == pytest.approx(base_h, rel=1e-10)
    n_eff = hold.windows.w * len(CHANNELS)
    p = {"current": 2 * 1, "lever_arm": 2, "resistance": 1}
    assert [r["effect"] for r in rep["ranking"]] == [c.effects[0] for c in diag.singles]
    for row, cand in zip(rep["ranking"], diag.singles, strict=True):
        j_t = fit.evaluation(SPEC, cand, train, sc).cost(Z)
        j_h = float(np.sum(_windows_cost(cand, hold, sc))) / 2
        j_in = fit.evaluation(SPEC, cand, hold, sc).cost(Z)
        assert row["shrinkage_train"] == pytest.approx(1 - j_t / base_t, rel=1e-9, abs=1e-12)
        assert row["shrinkage_holdout"] == pytest.approx(1 - j_h / base_h, rel=1e-9, abs=1e-12)
        assert row["shrinkage_holdout_insample"] == pytest.approx(1 - j_in / base_h, rel=1e-9,
                                                                  abs=1e-12)
        assert row["penalised_score"] == pytest.approx(
            1 - j_h * (1 + 2 * p[row["effect"]] / n_eff) / base_h, rel=1e-9, abs=1e-12)
    scores = [r["penalised_score"] for r in rep["ranking"]]
    assert scores == sorted(scores, reverse=True)


def test_real_summary_gap_and_floor_recomputed(real) -> None:
    """Costs before and after the chosen set replayed again; the floor by hand, ``1/2 sum_c
    m_c (sigma_c / s_c)^2`` over the scored finite samples of each channel."""
    rep, diag, train, hold, sc = real
    g = rep["gap"]
    after = float(np.sum(_windows_cost(diag.chosen, hold, sc))) / 2
    assert g["cost_holdout_after"] == pytest.approx(after, rel=1e-10)
    assert g["cost_train_after"] == pytest.approx(
        fit.evaluation(SPEC, diag.chosen, train, sc).cost(Z), rel=1e-10)
    assert g["cost_train_before"] == pytest.approx(
        fit.evaluation(SPEC, diag.base, train, sc).cost(Z), rel=1e-10)
    for data, key in ((train, "noise_floor_train"), (hold, "noise_floor_holdout")):
        scored = data.windows.valid().copy()
        scored[:, 0] = False
        floor = 0.0
        for j, c in enumerate(CHANNELS):
            m = int(np.sum(scored & np.isfinite(data.target[..., j])))
            floor += 0.5 * m * (data.sigma[j] / sc[c]) ** 2
        assert g[key] == pytest.approx(floor, rel=1e-12)
    assert g["holdout_gap_over_floor"] == pytest.approx(
        g["cost_holdout_before"] / g["noise_floor_holdout"])
    ch = rep["chosen"]
    assert ch["effects"] == list(diag.steps[-1]["effects"])
    assert ch["shrinkage_holdout"] == pytest.approx(1 - after / g["cost_holdout_before"])
    shares = rep["residuals"]["holdout"]["before"]["by_phase"]
    assert g["phases_by_share"] == sorted(shares, key=lambda k: -shares[k]["cost_share"])


def test_real_per_phase_shrinkage_averages_to_the_held_out_shrinkage(real) -> None:
    """Per phase ``1 - J_k,with / J_k,base``; weighted by each phase's share of the base cost
    (the residuals before) they add up to the whole held-out shrinkage, for every row and the
    chosen set (every scored sample belongs to one phase)."""
    rep, *_ = real
    shares = rep["residuals"]["holdout"]["before"]["by_phase"]
    assert sum(v["cost_share"] for v in shares.values()) == pytest.approx(1.0)
    for row in (*rep["ranking"], rep["chosen"]):
        assert set(row["per_phase"]) == set(shares)
        total = sum(shares[k]["cost_share"] * v for k, v in row["per_phase"].items())
        assert total == pytest.approx(row["shrinkage_holdout"], rel=1e-9, abs=1e-12)


def test_real_residuals_after_recomputed_per_channel_and_phase(real) -> None:
    """The held-out RMS after the chosen set (angles and yaw rate in degrees), per channel and
    per phase, from the windows replayed one by one; the phase sample counts add up to the
    scored samples of a channel."""
    rep, diag, _, hold, sc = real
    w2 = _windows_cost(diag.chosen, hold, sc)
    weights = np.array([sc[c] for c in CHANNELS])
    err2 = w2 * weights**2
    scored = hold.windows.valid().copy()
    scored[:, 0] = False
    after = rep["residuals"]["holdout"]["after"]
    for j, c in enumerate(CHANNELS):
        sel = scored & np.isfinite(hold.target[..., j])
        rms = np.sqrt(np.mean(err2[..., j][sel]))
        if c in ANGLES or c == "r":
            rms = np.degrees(rms)
        assert after["by_channel"][c] == pytest.approx(rms, rel=1e-9)
        for k, name in enumerate(PHASES):
            s = sel & (hold.phase == k)
            if s.any():
                v = np.sqrt(np.mean(err2[..., j][s]))
                v = np.degrees(v) if c in ANGLES or c == "r" else v
                assert after["by_phase"][name][c] == pytest.approx(v, rel=1e-9)
    assert sum(p["samples"] for p in after["by_phase"].values()) == int(scored.sum())


def test_real_markdown_states_the_report_numbers(real) -> None:
    """The page's verdict, ranking order and 'how far' line carry the report's numbers."""
    rep, diag, *_ = real
    text = report.markdown(rep)
    g = rep["gap"]
    pct = 100 * (1 - g["cost_holdout_after"] / g["cost_holdout_before"])
    assert (f"Chosen (forward selection): current + lever_arm. Held-out cost "
            f"{g['cost_holdout_before']:.4g} -> {g['cost_holdout_after']:.4g} ({pct:.0f} % "
            f"smaller;") in text
    assert f"**Verdict:** current + lever_arm: held-out gap {pct:.0f} % smaller" in text
    rows = [ln.split(" | ")[1] for ln in text.splitlines() if ln.startswith("| ")
            and ln.split(" | ")[0][2:].isdigit()]
    assert rows == [c.effects[0] for c in diag.singles]
    assert "one value per run (3 runs, report.json)" in text  # a, c fitted, b cross-fitted


def test_real_selection_check_scores_the_halves_of_the_held_out_run(real) -> None:
    """One held-out run of four windows: the check leaves out its first and second half in
    turn; each half's cost before is the base's on those windows replayed one at a time."""
    rep, diag, _, hold, sc = real
    check = rep["selection_check"]
    assert check == diag.check and [p["left_out"] for p in check["parts"]] == [
        "b, first half", "b, second half"]
    per_window = _windows_cost(diag.base, hold, sc).sum(axis=(1, 2)) / 2.0
    order = np.argsort(hold.windows.t0_s)
    for part, idx in zip(check["parts"], (order[:2], order[2:]), strict=True):
        assert part["windows"] == 2
        assert part["cost_before"] == pytest.approx(per_window[idx].sum(), rel=1e-9)
        assert part["shrinkage"] == pytest.approx(1 - part["cost_after"] / part["cost_before"])
    after = sum(p["cost_after"] for p in check["parts"])
    assert check["shrinkage_holdout"] == pytest.approx(1 - after / diag.base.cost_hold)


def test_real_summary_without_an_effect_keeps_the_gap() -> None:
    """Noisy runs of the base ship: nothing chosen, the cost after is the cost before."""
    train, hold = trio(None)
    diag = fit.diagnose(SPEC, train, hold, ("resistance",), forward_steps=1)
    rep = report.summary(SPEC, diag, train, hold)
    g = rep["gap"]
    assert rep["chosen"]["effects"] == [] and not rep["attributable"]
    assert (g["cost_holdout_after"], g["cost_train_after"]) == (g["cost_holdout_before"],
                                                               g["cost_train_before"])
    assert "Chosen (forward selection): nothing." in report.markdown(rep)
