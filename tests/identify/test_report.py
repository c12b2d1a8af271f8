"""Identification report: number formatting, the markdown tables, the JSON / markdown files and
the convergence plot."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from trafficsim.identify import report
from trafficsim.identify.augmented_ekf import EKFResult
from trafficsim.identify.output_error import FitResult

NAN = float("nan")


def _report(ekf: bool = False, fit: bool = True, reference: bool = False) -> dict[str, Any]:
    """A small report in the layout :func:`trafficsim.identify.command.identify` writes."""
    def err(value: float, pct: float) -> dict[str, float]:
        return {"value": value, "error_pct": pct}

    pred = {"u_rms_mps": 0.0123456, "v_rms_mps": 0.5, "r_rms_degps": 0.01, "heading_rms_deg": 1.25,
            "end_position_rms_m": 7.3456, "end_position_max_m": 9.0, "windows": 4,
            "diverged_windows": 0}
    return {
        "model": "nomoto", "method": "oe", "base_ship": "lib/cargo.yaml",
        "ship": {"name": "cargo_identified", "file": "out/ship.yaml"},
        "data": [
            {"name": "zz10", "role": "training", "samples": 101, "duration_s": 100.04,
             "nan_counts": {"north_m": 2, "psi_rad": 1}, "repeats_masked": {"position": 5,
                                                                             "heading": 0}},
            {"name": "zz15", "role": "holdout", "samples": 51, "duration_s": 50.0,
             "nan_counts": {}, "repeats_masked": {"position": 0, "heading": 3}}],
        "preprocessing": {"dt_s": 1.0, "wind": "none in the data",
                          "smoother": {"sigma_pos_m": 2.0, "sigma_heading_rad": math.radians(0.5)}},
        "ekf": ({"recursions": 3000, "elapsed_s": 1.234,
                 "coefficients": {"a1": {"value": -0.00123, "std": 4.5678e-5}}} if ekf else None),
        "fit": ({"evaluations": 12, "jacobians": 5, "elapsed_s": 3.21, "cost_initial": 1234.5,
                 "cost_final": 0.5, "message": "`ftol` condition satisfied.",
                 "coefficients": {"K_prime": {"initial": 2.0, "value": 2.5, "ci95_low": 2.4,
                                              "ci95_high": 2.6, "ci95_clustered_low": 2.1,
                                              "ci95_clustered_high": 2.9, "lower": 0.01,
                                              "upper": 50.0},
                                  "T_prime": {"initial": 3.0, "value": 3.5, "ci95_low": NAN,
                                              "ci95_high": NAN, "lower": -math.inf,
                                              "upper": math.inf}}} if fit else None),
        "validation": {
            "horizon_s": 100.0,
            "prediction": {"training": {"identified": {"zz10": pred, "all": pred},
                                        "start": {"zz10": {**pred, "u_rms_mps": 0.2}}},
                           "holdout": {"identified": {"zz15": {**pred, "v_rms_mps": NAN}}}},
            "measured_turns": [{"run": "turn1", "rudder_deg": -19.6,
                                "measured": {"advance_m": 700.0, "transfer_m": 650.0,
                                             "tactical_diameter_m": 1300.0},
                                "identified": {"advance_m": err(707.0, 1.0),
                                               "transfer_m": err(650.0, 0.0),
                                               "tactical_diameter_m": err(NAN, NAN)},
                                "start": {"advance_m": err(800.0, 14.2857),
                                          "transfer_m": err(600.0, -7.6923),
                                          "tactical_diameter_m": err(1200.0, -7.6923)}}],
            "standard_manoeuvres": {
                "turning_35_starboard": {
                    "indices": {"advance_m": 648.63, "transfer_m": 530.31,
                                "tactical_diameter_m": 1057.35},
                    "imo": {"advance_L": {"value": 4.03, "limit": 4.5, "pass": True},
                            "tactical_diameter_L": {"value": 6.57, "limit": 5.0,
                                                    "pass": False}}},
                "zigzag_20_20": {
                    "indices": {"first_overshoot_deg": 11.2, "second_overshoot_deg": 11.0},
                    "imo": {"first_overshoot_deg": {"value": 11.2, "limit": 25.0,
                                                    "pass": True}}}},
            "reference": "bulk_carrier" if reference else None,
            "reference_comparison": ({"turning_35_port": {"advance_m": {
                "reference": 600.0, "identified": 606.0, "error_pct": 1.0}}}
                if reference else None)},
    }


# --- _fmt -----------------------------------------------------------------------------------

@pytest.mark.parametrize("value, digits, text", [
    (None, 4, "-"), (NAN, 4, "-"), (math.inf, 4, "-"), (-math.inf, 4, "-"),
    (7, 4, "7"), (np.int64(123456789), 4, "123456789"), (0.0, 4, "0"),
    (3.14159265, 4, "3.142"), (np.float32(0.5), 4, "0.5"), (1234567.0, 4, "1.235e+06"),
    (-0.000123456, 2, "-0.00012"), (4.5678e-5, 2, "4.6e-05"),
])
def test_fmt(value: Any, digits: int, text: str) -> None:
    assert report._fmt(value, digits) == text


# --- markdown -------------------------------------------------------------------------------

def test_markdown_header_data_and_preprocessing() -> None:
    lines = report.markdown(_report()).splitlines()
    assert lines[0] == "# Identification of `cargo_identified` (nomoto model)"
    assert lines[2] == ("Method: oe. Base ship: `lib/cargo.yaml`. "
                        "Ship file: `out/ship.yaml`.")
    # NaN cells summed over columns; repeats as position / heading
    assert "| zz10 | training | 101 | 100.0 | 3 | 5 / 0 |" in lines
    assert "| zz15 | holdout | 51 | 50.0 | 0 | 0 / 3 |" in lines
    smoother = next(x for x in lines if x.startswith("Smoother"))
    assert "sampling 1 s" in smoother and "position noise 2 m" in smoother
    assert "heading noise 0.5 deg" in smoother  # radians shown in degrees
    assert smoother.endswith("Wind: none in the data.")


def test_markdown_sections_follow_the_report_content() -> None:
    bare = report.markdown(_report(ekf=False, fit=False, reference=False))
    assert "## Augmented-state EKF" not in bare and "## Output-error fit" not in bare
    assert "against the reference" not in bare
    full = report.markdown(_report(ekf=True, fit=True, reference=True))
    heads = [x for x in full.splitlines() if x.startswith("## ")]
    assert heads == ["## Data", "## Augmented-state EKF", "## Output-error fit",
                     "## Prediction error", "## Measured turning tests",
                     "## Standard manoeuvres against the reference `bulk_carrier`",
                     "## Standard manoeuvres of the identified ship"]
    assert full.endswith("|\n") and not full.endswith("\n\n")


def test_markdown_ekf_and_fit_tables() -> None:
    lines = report.markdown(_report(ekf=True, fit=True)).splitlines()
    assert any(line.startswith("3000 recursions in 1.23 s. The std is the filter's own")
               and "too narrow" in line for line in lines)
    assert "| coefficient | estimate | filter std |" in lines
    assert "| a1 | -0.00123 | 4.6e-05 |" in lines
    assert ("12 evaluations, 5 Jacobians, 3.2 s; cost 1234 -> 0.5; "
            "`ftol` condition satisfied.") in lines
    assert "| K_prime | 2 | 2.5 | 2.4 .. 2.6 | 2.1 .. 2.9 | 0.01 .. 50 |" in lines
    # an interval the data do not bound (null in JSON), no bounds
    assert ("| T_prime | 3 | 3.5 | not determined by the data | not determined by the data "
            "| - .. - |") in lines


def test_markdown_prediction_rows_training_first_then_holdout() -> None:
    lines = report.markdown(_report()).splitlines()
    rows = [x for x in lines if x.startswith(("| training", "| holdout"))]
    assert rows == [
        "| training | zz10 | identified | 0.0123 | 0.5 | 0.01 | 1.25 | 7.35 |",
        "| training | all | identified | 0.0123 | 0.5 | 0.01 | 1.25 | 7.35 |",
        "| training | zz10 | start | 0.2 | 0.5 | 0.01 | 1.25 | 7.35 |",
        "| holdout | zz15 | identified | 0.0123 | - | 0.01 | 1.25 | 7.35 |"]
    assert "Windows of 100 s, each replayed" in "\n".join(lines)


def test_markdown_measured_turns_reference_and_imo() -> None:
    lines = report.markdown(_report(reference=True)).splitlines()
    turns = [x for x in lines if x.startswith("| turn1 ")]
    assert turns == ["| turn1 | -20 | advance_m | 700 | 707 (1) | 800 (14.3) |",
                     "| turn1 | -20 | transfer_m | 650 | 650 (0) | 600 (-7.69) |",
                     "| turn1 | -20 | tactical_diameter_m | 1300 | - (-) | 1200 (-7.69) |"]
    assert "| turning_35_port | advance_m | 600 | 606 | 1 |" in lines
    assert "| turning_35_starboard | advance_m | 648.6 | | |" in lines
    assert "| turning_35_starboard | advance_L | 4.03 | 4.5 | yes |" in lines
    assert "| turning_35_starboard | tactical_diameter_L | 6.57 | 5 | NO |" in lines
    # zig-zags list their overshoots, not turning indices
    assert "| zigzag_20_20 | first_overshoot_deg | 11.2 | | |" in lines
    assert "| zigzag_20_20 | second_overshoot_deg | 11 | | |" in lines
    assert "| zigzag_20_20 | first_overshoot_deg | 11.2 | 25 | yes |" in lines


# --- write_reports --------------------------------------------------------------------------

def test_write_reports_json_and_markdown(tmp_path: Path) -> None:
    rep = _report(ekf=True, reference=True)
    rep["elapsed_s"] = np.float64(2.5)
    out = tmp_path / "new" / "dir"
    report.write_reports(out, rep)
    assert sorted(p.name for p in out.iterdir()) == ["report.json", "report.md"]
    assert (out / "report.md").read_text() == report.markdown(rep)
    back = json.loads((out / "report.json").read_text())
    assert back["elapsed_s"] == 2.5
    assert back["fit"]["coefficients"]["T_prime"]["ci95_low"] is None  # NaN -> null
    assert back["fit"]["coefficients"]["T_prime"]["lower"] is None  # -inf -> null
    turn = back["validation"]["measured_turns"][0]
    assert turn["identified"]["advance_m"] == {"value": 707.0, "error_pct": 1.0}
    assert back["data"][0]["nan_counts"] == {"north_m": 2, "psi_rad": 1}


# --- convergence_plot -----------------------------------------------------------------------

def _ekf(steps: int = 200) -> EKFResult:
    rng = np.random.default_rng(0)
    final = np.array([-0.5, 2.0, 0.0])
    trace = final * (1 - np.exp(-np.arange(1, steps + 1) / 30.0))[:, None]
    trace = trace + 0.01 * rng.normal(size=trace.shape)
    trace[-1] = final  # the filter's last estimate is its result
    return EKFResult(names=("a1", "b1", "c2"), x=final, std=np.ones(3), trace=trace,
                     run_starts=[0, steps // 2], innovation_rms=np.ones(3), steps=steps,
                     elapsed_s=0.1)


def _fit() -> FitResult:
    xs = [np.array([1.0, -2.0]), np.array([1.5, -3.0]), np.array([2.0, -4.0]),
          np.array([1.9, -3.9])]
    costs = [10.0, 4.0, 6.0, 1.0]
    x = np.array([2.0, -4.0])
    return FitResult(names=("K_prime", "T_prime"), x0=xs[0], x=x, lower=np.array([0.0, -9.0]),
                     upper=np.array([9.0, 0.0]), std=np.ones(2), ci95=np.ones(2),
                     corr=np.eye(2), cost0=10.0, cost=1.0, rms0=1.0, rms=0.1, nfev=4, njev=2,
                     message="ok", success=True, elapsed_s=0.1, m=100,
                     channels=("u", "v", "r", "psi"), scales={}, history_cost=costs,
                     history_x=xs)


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.mark.parametrize("with_fit, with_ekf, panels", [
    (True, True, 3), (True, False, 2), (False, True, 1)])
def test_convergence_plot_has_one_panel_per_history(tmp_path: Path, with_fit: bool,
                                                    with_ekf: bool, panels: int) -> None:
    """8 in wide, 3 in per panel, at 110 dpi: 880 x 330 pixels per panel."""
    path = tmp_path / "convergence.png"
    report.convergence_plot(path, _fit() if with_fit else None, _ekf() if with_ekf else None)
    assert _png_size(path) == (880, 330 * panels)


def test_convergence_plot_normalises_by_the_final_values(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """EKF estimates / final value (a zero final value left as is), parameters / |final|,
    costs with the best-so-far envelope, run boundaries marked."""
    import matplotlib.pyplot as plt

    figures: list[Any] = []
    monkeypatch.setattr(plt, "close", figures.append)  # keep the figure to inspect it
    ekf, fit = _ekf(), _fit()
    report.convergence_plot(tmp_path / "c.png", fit, ekf)
    (fig,) = figures
    ax_ekf, ax_cost, ax_par = fig.axes
    curves = [line.get_ydata() for line in ax_ekf.get_lines() if len(line.get_xdata()) > 2]
    assert len(curves) == 3
    np.testing.assert_allclose(curves[0], ekf.trace[:, 0] / -0.5)
    np.testing.assert_allclose(curves[1], ekf.trace[:, 1] / 2.0)
    np.testing.assert_allclose(curves[2], ekf.trace[:, 2])
    assert [c[-1] for c in curves[:2]] == [1.0, 1.0]
    marks = [line.get_xdata()[0] for line in ax_ekf.get_lines() if len(line.get_xdata()) == 2]
    assert marks == [100]
    evaluation, best = (line.get_ydata() for line in ax_cost.get_lines())
    np.testing.assert_array_equal(evaluation, [10.0, 4.0, 6.0, 1.0])
    np.testing.assert_array_equal(best, [10.0, 4.0, 4.0, 1.0])
    k_line, t_line = (line.get_ydata() for line in ax_par.get_lines())
    np.testing.assert_allclose(k_line, [0.5, 0.75, 1.0, 0.95])
    np.testing.assert_allclose(t_line, [-0.5, -0.75, -1.0, -0.975])
    monkeypatch.undo()
    plt.close(fig)


def test_markdown_numbers_are_the_validation_results_recomputed() -> None:
    """The standard-manoeuvre table of a real ship (cargo at 12 kn, from
    ``validation.standard_manoeuvres``): each index cell reads back as the manoeuvre's own
    value to the 4 digits shown, each IMO row's pass column is value <= limit, and the
    advance in ship lengths is advance / L."""
    from trafficsim.identify import validation
    from trafficsim.ships import manoeuvres
    from trafficsim.ships.library import load_ship

    spec = load_ship("cargo")
    man = validation.standard_manoeuvres(spec, 12.0)
    rep = _report()
    rep["validation"]["standard_manoeuvres"] = man
    lines = report.markdown(rep).splitlines()
    start = lines.index("## Standard manoeuvres of the identified ship")
    rows = [ln.strip("|").split("|") for ln in lines[start + 4:] if ln.startswith("| ")]
    cells = {(r[0].strip(), r[1].strip()): [c.strip() for c in r[2:]] for r in rows}
    _, direct = manoeuvres.turning_circle(spec, 35.0, 12.0)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
        assert float(cells[("turning_35_starboard", key)][0]) == pytest.approx(
            direct[key], rel=5e-4)
    L = spec["particulars"]["length_m"]
    adv = cells[("turning_35_starboard", "advance_L")]
    assert float(adv[0]) == pytest.approx(direct["advance_m"] / L, rel=5e-4)
    for (name, key), (value, limit, passed) in cells.items():
        if limit:
            c = man[name]["imo"][key]
            assert float(value) == pytest.approx(c["value"], rel=5e-4)
            assert passed == ("yes" if float(c["value"]) <= float(c["limit"]) else "NO")
    zz = man["zigzag_10_10"]["indices"]
    assert float(cells[("zigzag_10_10", "first_overshoot_deg")][0]) == pytest.approx(
        zz["first_overshoot_deg"], rel=5e-4)


def test_interval_text() -> None:
    assert report.interval_text({"ci95_low": 1.0, "ci95_high": 2.5}) == "1 .. 2.5"
    assert report.interval_text({"ci95_low": -np.inf, "ci95_high": np.inf}) == (
        "not determined by the data")
    assert report.interval_text({"ci95_low": None, "ci95_high": None}) == (
        "not determined by the data")
    assert report.interval_text({"ci95_low": 1.0, "ci95_high": 2.0, "at_bound": True}) == (
        "1 .. 2, on its bound")
    both = {"ci95_low": 1.0, "ci95_high": 2.0, "ci95_clustered_low": 0.5,
            "ci95_clustered_high": 2.5}
    assert report.interval_text(both, "ci95_clustered") == "0.5 .. 2.5"
    assert report.interval_text({**both, "ci95_clustered_high": None}, "ci95_clustered") == "-"
    assert report.interval_text({**both, "ci95_high": np.inf}, "ci95_clustered") == (
        "not determined by the data")
