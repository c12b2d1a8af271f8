"""``trafficsim report``: the page, its figures, and the worst encounters replayed and drawn."""

import re

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from trafficsim.campaign.execute import run_campaign
from trafficsim.cli import main
from trafficsim.errors import InputError
from trafficsim.render.report import worst_encounters, write_report


def _rows(**columns):
    n = len(columns["encounter"])
    base = {"encounter_type": ["head_on"] * n, "t_cpa_s": [100.0] * n, "collision": [False] * n,
            "blind_spot": [False] * n, "blind_spot_role": [""] * n,
            "compliance_i": [0.9] * n, "compliance_j": [0.9] * n}
    base.update(columns)
    return {k: np.asarray(v) for k, v in base.items()}


def test_worst_encounters_take_turns_between_the_criteria():
    rows = _rows(encounter=[0, 1, 1, 2, 3, 4, 5],
                 min_range_m=[900.0, 300.0, 5000.0, 700.0, 400.0, 100.0, 800.0],
                 collision=[False, False, False, False, False, True, False],
                 blind_spot=[False, False, False, True, False, False, False],
                 blind_spot_role=["", "", "", "stand_on", "", "", ""],
                 compliance_i=[0.9, 0.9, 0.9, 0.9, 0.9, 0.9, 0.1],
                 compliance_j=[0.9, 0.9, np.nan, 0.5, 0.9, 0.9, np.nan])
    picks = worst_encounters(rows, 6)
    # collision 4; smallest CPA then 1 (4 taken); blind spot 2; lowest compliance 5;
    # then smallest CPA: 3, then 5 and 2 are taken, 0
    assert [p.encounter for p in picks] == [4, 1, 2, 5, 3, 0]
    assert picks[0].reasons == ["collision"] and picks[0].collision
    assert picks[2].reasons == ["blind spot"] and picks[2].blind_spot == "stand_on"
    assert picks[3].compliance == pytest.approx(0.1) and picks[1].min_range_m == 300.0
    assert [p.encounter for p in worst_encounters(rows, 2)] == [4, 1]
    assert worst_encounters(rows, 0) == []


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from tests.campaign.conftest import SMALL

    folder = tmp_path_factory.mktemp("campaign")
    spec = folder / "spec.yaml"
    spec.write_text(SMALL.format(n=3, chunk=3, duration=300, rogue=0.3,
                                 extra="dcpa_nm: [0.0, 0.3]\ntcpa_min: [3, 5]"))
    run_campaign(spec, folder / "out", workers=1, progress=False)
    return spec, folder / "out"


def test_the_report_page_shows_the_summary_figures_and_worst_encounters(campaign, tmp_path):
    _, out = campaign
    report = write_report(out, tmp_path / "report", worst=2)
    page = report.path.read_text()
    assert report.path == tmp_path / "report" / "index.html" and len(report.worst) == 2
    for heading in ("Summary", "By encounter type", "Figures", "Worst encounters (2)"):
        assert f"<h2>{heading}</h2>" in page
    for figure in ("cpa_histogram.png", "rates_by_type.png"):
        assert f"src='{figure}'" in page and (tmp_path / "report" / figure).stat().st_size > 0
    for pick in report.worst:
        k = pick.encounter
        assert f"trafficsim replay {out} --encounter {k} --out out/encounter_{k}" in page
        gif = tmp_path / "report" / "encounters" / f"encounter_{k}.gif"
        frames = iio.imread(gif, index=None)
        assert frames.shape[1:] == (480, 640, 3) and 20 <= len(frames) <= 100
        with Image.open(gif.with_suffix(".png")) as thumb:
            assert thumb.size == (320, 240)
        assert (gif.parent / f"encounter_{k}" / "trajectories.parquet").is_file()
    shown = [int(k) for k in re.findall(r"--encounter (\d+)", page)]
    assert shown == [p.encounter for p in report.worst]
    # a second report with fewer worst encounters drops the files of the others
    again = write_report(out, tmp_path / "report", worst=1)
    names = sorted(p.name for p in (tmp_path / "report" / "encounters").iterdir())
    k = again.worst[0].encounter
    assert names == [f"encounter_{k}", f"encounter_{k}.gif", f"encounter_{k}.png"]


def test_report_errors_and_the_command(campaign, tmp_path, capsys):
    _, out = campaign
    with pytest.raises(InputError, match=r"no encounters\.parquet here"):
        write_report(tmp_path)
    assert main(["report", str(out), "--worst", "0", "--out", str(tmp_path / "r"),
                 "--no-progress"]) == 0
    assert capsys.readouterr().out.startswith("report with 0 worst encounters in ")
    assert "Worst encounters (0)" in (tmp_path / "r" / "index.html").read_text()
    with pytest.raises(SystemExit):
        main(["report", str(out), "--worst", "-1"])
    assert "expected a number >= 0" in capsys.readouterr().err


def test_a_damaged_encounters_table_is_named_not_a_traceback(tmp_path, capsys):
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "encounters.parquet").write_bytes(b"junk")
    assert main(["report", str(broken), "--out", str(tmp_path / "r"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"trafficsim: error: {broken / 'encounters.parquet'}: unreadable "
                          "encounters table (") and "Traceback" not in err
