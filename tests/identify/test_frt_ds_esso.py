"""Identification on real data: the FRT-DS-ESSO free-running model tests of the Esso Osaka
(3 m model), trained on the runs of the data set's ``Train-TZRB`` column and tested on its
``Test (TZRB)`` column (the split of Wakita et al. 2022, listed in the data set's README)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import SHARED
from trafficsim.identify.command import identify

ESSO = SHARED / "data" / "frt-ds-esso" / "data"
BASE = Path(__file__).parent / "data" / "esso_base.yaml"
TRAIN_TZRB = ["random/random_06-Aug-2020_16_24_25_4.csv",
              "random/random_06-Aug-2020_16_24_25_6.csv",
              "turning/turn_cut_14-Sep-2020_15_58_08.csv",
              "turning/turn_cut_14-Sep-2020_16_09_02.csv",
              "zigzag/zigzag_31-Jul-2020_13_22_52.csv", "zigzag/zigzag_31-Jul-2020_13_50_28.csv",
              "berthing/berthing_12-Nov-2020_11_14_47.csv",
              "berthing/berthing_12-Nov-2020_13_37_05.csv"]
TEST_TZRB = ["random/random_06-Aug-2020_16_24_25_3.csv", "turning/turn_14-Oct-2020_15_06_53.csv",
             "zigzag/zigzag_31-Jul-2020_13_42_53.csv", "berthing/berthing_12-Nov-2020_11_38_50.csv",
             "berthing/berthing_12-Nov-2020_11_49_21.csv",
             "berthing/berthing_12-Nov-2020_13_21_03.csv"]

pytestmark = pytest.mark.skipif(not ESSO.is_dir(), reason="FRT-DS-ESSO data set not present")


@pytest.fixture(scope="module")
def esso(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """mmg model, default subset (R0, X_vr, Y_v, Y_r, N_v, N_r, f_alpha) from the KVLCC2-based
    starting ship, measured wind used; all 8 training runs at the default working interval
    (0.3 s) and horizon (3 L/U = 22.5 s)."""
    out = tmp_path_factory.mktemp("esso")
    return identify("mmg", [ESSO / f for f in TRAIN_TZRB], out, str(BASE),
                    holdout=[ESSO / f for f in TEST_TZRB])


def test_split_and_data_report(esso: dict) -> None:
    roles = [d["role"] for d in esso["data"]]
    assert roles == ["training"] * 8 + ["holdout"] * 6
    zz = next(d for d in esso["data"] if d["name"] == "zigzag_31-Jul-2020_13_50_28")
    assert zz["dropped_empty_rows"] == 327  # reported, not crashed on
    assert all(d["repeats_masked"]["position"] > 0 for d in esso["data"])
    assert esso["preprocessing"]["wind"].startswith("used")
    assert esso["preprocessing"]["dt_s"] == pytest.approx(0.3)


def test_fit_improves_the_test_runs(esso: dict) -> None:
    """On the authors' test runs the identified model predicts better than the starting model
    (end-of-window position and heading errors over all test windows), no replay diverges, and
    the fitted coefficients stay inside their bounds."""
    hold = esso["validation"]["prediction"]["holdout"]
    fit, start = hold["identified"]["all"], hold["start"]["all"]
    assert fit["end_position_rms_m"] < 0.9 * start["end_position_rms_m"]
    assert fit["heading_rms_deg"] < start["heading_rms_deg"]
    assert fit["end_position_rms_m"] < 0.35  # metres after 22.5 s, ship length 3 m
    assert fit["diverged_windows"] == 0
    train = esso["validation"]["prediction"]["training"]
    assert train["identified"]["all"]["end_position_rms_m"] < train["start"]["all"][
        "end_position_rms_m"]
    for c in esso["fit"]["coefficients"].values():
        assert c["lower"] <= c["value"] <= c["upper"]
    assert esso["fit"]["cost_final"] < 0.9 * esso["fit"]["cost_initial"]


def test_measured_turning_tests_are_found(esso: dict) -> None:
    """The two training turns and the test turn (20 deg rudder) are recognised and their
    indices measured; the identified tactical diameter of the test turn is within 15 %."""
    turns = {t["run"]: t for t in esso["validation"]["measured_turns"]}
    assert set(turns) == {"turn_cut_14-Sep-2020_15_58_08", "turn_cut_14-Sep-2020_16_09_02",
                          "turn_14-Oct-2020_15_06_53"}
    test_turn = turns["turn_14-Oct-2020_15_06_53"]
    assert test_turn["rudder_deg"] == pytest.approx(-20.0, abs=1.0)
    assert abs(test_turn["identified"]["tactical_diameter_m"]["error_pct"]) < 15.0
