"""``trafficsim report``: the page, its figures, and the worst encounters replayed and drawn."""

import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from PIL import Image

from trafficsim.campaign.execute import run_campaign
from trafficsim.campaign.summary import completed
from trafficsim.cli import main
from trafficsim.errors import InputError
from trafficsim.io.results import write_parquet
from trafficsim.render.report import worst_encounters, write_report
from trafficsim.units import NM


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


@pytest.mark.parametrize("column", ["collision", "min_range_m", "encounter", "encounter_type",
                                    "compliance_i", "score_rule13"])
def test_an_encounters_table_missing_a_column_is_named(tmp_path, capsys, column):
    """A column the report reads dropped from ``encounters.parquet``: one line naming the file
    and the column and what it holds, exit 2 (before, a KeyError traceback)."""
    from tests.conftest import error_line

    cols = _synthetic_columns()
    del cols[column]
    folder = tmp_path / "camp"
    folder.mkdir()
    write_parquet(folder / "encounters.parquet", cols)
    line = error_line(capsys, ["report", folder, "--no-progress"])
    assert line.startswith(f"trafficsim: error: {folder / 'encounters.parquet'}: {column}: "
                           "missing column (expected "), line
    assert not (folder / "report").exists()


@pytest.mark.parametrize(("column", "value", "expected"), [
    ("collision", lambda v: str(v), "expected true or false, got string values"),
    ("collision", lambda v: int(v), "expected true or false, got int64 values"),
    ("min_range_m", lambda v: f"{v} m", "expected numbers, got string values"),
    ("encounter", lambda v: float(v), "expected whole numbers, got double values"),
    ("encounter_type", lambda v: 1, "expected text, got int64 values"),
    ("blind_spot", lambda v: None, "expected true or false in every row, got 10 empty values"),
    ("encounter", lambda v: -v - 1, "expected encounter indices >= 0, got -7"),
])
def test_an_encounters_table_column_of_another_type_is_named(tmp_path, capsys, column, value,
                                                            expected):
    """``collision`` stored as text (``"False"`` is truthy: every pair a collision), numbers as
    text, a fractional encounter index, empty values, a negative index: one line naming the
    file, the column and what was expected, exit 2, instead of a page of nonsense."""
    from tests.conftest import error_line

    cols = _synthetic_columns()
    folder = tmp_path / "camp"
    folder.mkdir()
    table = pa.table({k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in cols.items()})
    changed = [value(v) for v in table.column(column).to_pylist()]
    k = table.column_names.index(column)
    table = table.set_column(k, column, pa.array(changed, type=pa.bool_() if column ==
                                                 "blind_spot" else None))
    pq.write_table(table, folder / "encounters.parquet")
    line = error_line(capsys, ["report", folder, "--no-progress"])
    assert line.startswith(f"trafficsim: error: {folder / 'encounters.parquet'}: {column}: "
                           f"{expected}"), line


def test_report_on_a_run_folder_says_it_needs_a_campaign(synthetic_run, capsys):
    """A run's folder (``trafficsim run`` or ``replay``) is no unfinished campaign: the message
    says what the folder holds and what ``report`` needs, not "run the campaign again"."""
    from tests.conftest import error_line
    from tests.render.conftest import Ship

    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0, 5.0), Ship("b", 900.0, 0.0, 180.0, 5.0)])
    line = error_line(capsys, ["report", run, "--no-progress"])
    assert line == (f"trafficsim: error: {run}: holds a run's results (of 'trafficsim run' or "
                    "'replay'), not a campaign's: report needs the output folder of 'trafficsim "
                    "campaign' ('trafficsim render' draws a run)")
    assert not (run / "report").exists()


def test_an_encounter_beyond_the_campaign_is_blamed_on_the_table(campaign, tmp_path, capsys):
    """An ``encounters.parquet`` holding encounter 1002 of a 3-encounter campaign names the
    file and its ``encounter`` column, not ``--encounter`` (a flag not given)."""
    import shutil

    from tests.conftest import error_line

    spec, out = campaign
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    table = pq.read_table(copy / "encounters.parquet")
    enc = table.column("encounter").to_numpy().copy()
    enc[enc == enc.max()] = 1002
    table = table.set_column(table.column_names.index("encounter"), "encounter", pa.array(enc))
    pq.write_table(table, copy / "encounters.parquet")
    line = error_line(capsys, ["report", copy, "--no-progress"])
    assert line == (f"trafficsim: error: {copy / 'encounters.parquet'}: encounter: encounter "
                    f"1002 is not one of the campaign's 3 (0 .. 2, spec {spec}): the table is "
                    "not this campaign's (run 'trafficsim campaign' on this folder again to "
                    "write it anew from its chunks)")
    assert "--encounter" not in line and not (copy / "report").exists()


# --------------------------------------------------------------------------------------------
# the page's tables and figures against the rows they are drawn from
# --------------------------------------------------------------------------------------------

# (encounter, type, smallest range m, collision, domain entered, blind-spot role, rogue j,
#  compliance i, compliance j, {rule: score}, diverged)
SYNTHETIC = [
    (0, "head_on", 150.0, True, True, "", False, 0.2, 0.4, {14: 0.2}, False),
    (1, "head_on", 600.0, False, True, "", False, 0.9, 0.8, {14: 0.8}, False),
    (2, "head_on", 3000.0, False, False, "", True, np.nan, np.nan, {}, False),
    (3, "crossing_give_way", 700.0, False, True, "give_way", False, 0.5, 1.0,
     {15: 0.5, 17: 1.0}, False),
    (4, "crossing_give_way", 2000.0, False, False, "", False, 1.0, 1.0, {15: 1.0, 17: 1.0},
     False),
    (5, "multi", 900.0, False, True, "", False, np.nan, np.nan, {}, False),
    (5, "multi", 1200.0, False, False, "", False, np.nan, np.nan, {}, False),
    (5, "multi", 2500.0, False, False, "", False, np.nan, np.nan, {}, False),
    (6, "overtaking", 10.0, True, True, "stand_on", False, 0.0, 0.0, {13: 0.0}, True),
    (6, "overtaking", 20.0, True, True, "", False, 0.0, 0.0, {13: 0.0}, True),
]


def _synthetic_columns(pairs=SYNTHETIC) -> dict:
    n = len(pairs)
    cols = {"encounter": np.array([p[0] for p in pairs], dtype=np.int64),
            "encounter_type": [p[1] for p in pairs],
            "min_range_m": np.array([p[2] for p in pairs]),
            "t_cpa_s": 100.0 + 10.0 * np.arange(n),
            "collision": np.array([p[3] for p in pairs]),
            "domain_violation": np.array([p[4] for p in pairs]),
            "blind_spot": np.array([p[5] != "" for p in pairs]),
            "blind_spot_role": [p[5] for p in pairs],
            "behaviour_i": ["colregs"] * n,
            "behaviour_j": ["turn_port" if p[6] else "colregs" for p in pairs],
            "compliance_i": np.array([p[7] for p in pairs]),
            "compliance_j": np.array([p[8] for p in pairs]),
            "diverged": np.array([p[10] for p in pairs])}
    for rule in (13, 14, 15, 16, 17):
        cols[f"score_rule{rule}"] = np.array([p[9].get(rule, np.nan) for p in pairs])
    return cols


def _synthetic_campaign(folder: Path, pairs=SYNTHETIC) -> Path:
    folder.mkdir(parents=True)
    write_parquet(folder / "encounters.parquet", _synthetic_columns(pairs))
    return folder


class _Tables(HTMLParser):
    """Every ``<table>`` of a page as rows of cell texts."""

    def __init__(self):
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append("".join(self._cell).strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _tables(page: str) -> list[list[list[str]]]:
    parser = _Tables()
    parser.feed(page)
    return parser.tables


def _rate_text(k: int, n: int) -> str:
    """A rate as the page prints it, the interval from scipy's Wilson score interval."""
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    low, high = max(0.0, float(ci.low)), min(1.0, float(ci.high))
    return f"{100 * k / n:.2f} % ({100 * low:.2f} - {100 * high:.2f} %)"


def test_the_summary_tables_are_the_rows_counted_by_hand(tmp_path):
    """A hand-made table of 7 encounters, the last diverged: the outcome table, the CPA
    quantiles, the per-rule means and the per-type table are the counts worked out here over
    encounters 0-5, the rates printed with Wilson intervals from scipy."""
    folder = _synthetic_campaign(tmp_path / "camp")
    report = write_report(folder, worst=0)
    page = report.path.read_text()
    assert report.path == folder / "report" / "index.html"
    outcomes, rules, by_type = _tables(page)
    # per encounter 0-5: collision {0}; near miss (< 800 m, no collision) {1 (600), 3 (700)};
    # domain entered {0, 1, 3, 5}; blind spot {3}
    assert outcomes[1:] == [
        ["collision", "1", _rate_text(1, 6)],
        ["near miss (< 800 m)", "2", _rate_text(2, 6)],
        ["ship domain entered", "4", _rate_text(4, 6)],
        ["blind spot (both ships in one role)", "1", _rate_text(1, 6)]]
    # smallest range per encounter, sorted: 150 600 700 900 2000 3000 m; numpy's linear
    # quantile at q (n - 1) / 100: P1 = 150 + 0.05 * 450 = 172.5 m = 0.093 NM, P5 = 150 +
    # 0.25 * 450 = 262.5 m = 0.142 NM, P50 = (700 + 900) / 2 = 800 m = 0.432 NM
    assert "P1 / P5 / P50: 0.09 / 0.14 / 0.43 NM" in page
    # encounter 2 has a rogue: 5 all-compliant encounters, encounter 0 a collision among them
    assert "Collisions with every ship compliant: 1 of 5 such encounters." in page
    # Rule 13 graded only in the diverged encounter: none; Rule 14 (0.2 + 0.8) / 2; Rule 15
    # (0.5 + 1.0) / 2; Rule 16 none; Rule 17 1.0
    assert rules == [["rule", "Rule 13", "Rule 14", "Rule 15", "Rule 16", "Rule 17"],
                     ["mean compliance", "-", "0.50", "0.75", "-", "1.00"]]
    # head-on {0, 1, 2}: P50 600 m; crossing {3, 4}: (700 + 2000) / 2 = 1350 m; multi {5}: 900
    assert by_type[1:] == [
        ["head on", "3", _rate_text(1, 3), _rate_text(1, 3), _rate_text(2, 3),
         _rate_text(0, 3), f"{600 / NM:.2f}"],
        ["crossing give way", "2", _rate_text(0, 2), _rate_text(1, 2), _rate_text(1, 2),
         _rate_text(1, 2), f"{1350 / NM:.2f}"],
        ["multi", "1", _rate_text(0, 1), _rate_text(0, 1), _rate_text(1, 1),
         _rate_text(0, 1), f"{900 / NM:.2f}"]]
    assert "<p>7 encounters from" in page
    assert "1 encounters diverged" in page and "left out of everything below: 6.</p>" in page
    assert "Worst encounters (0)" in page and "--encounter" not in page


def test_the_figures_of_the_report_are_drawn_from_its_rows(tmp_path, monkeypatch):
    """The data handed to matplotlib: the histogram gets the pairs of encounters 0-5 (not the
    diverged 6), split by domain entry; the rate bars per type are the shares of the per-type
    table (collision, near miss, domain entered)."""
    import matplotlib.axes

    drawn: dict[str, list] = {"hist": [], "bar": []}
    real_hist, real_bar = matplotlib.axes.Axes.hist, matplotlib.axes.Axes.bar

    def hist(self, x, *args, **kw):
        drawn["hist"].append([np.sort(np.asarray(a)) for a in x])
        return real_hist(self, x, *args, **kw)

    def bar(self, x, height, *args, **kw):
        if "yerr" in kw:  # the rate bars (``hist`` draws its own bars without)
            drawn["bar"].append(list(height))
        return real_bar(self, x, height, *args, **kw)

    monkeypatch.setattr(matplotlib.axes.Axes, "hist", hist)
    monkeypatch.setattr(matplotlib.axes.Axes, "bar", bar)
    folder = _synthetic_campaign(tmp_path / "camp")
    report = write_report(folder, worst=0)
    (kept, entered), = drawn["hist"]
    # the last bin ends at max(2 NM, P99 of the ranges) = 2 NM: no range (<= 3000 m) clipped
    np.testing.assert_allclose(kept, np.array([1200.0, 2000.0, 2500.0, 3000.0]) / NM)
    np.testing.assert_allclose(entered, np.array([150.0, 600.0, 700.0, 900.0]) / NM)
    # types in order head-on, crossing give-way, multi
    assert drawn["bar"] == [[1 / 3, 0.0, 0.0], [1 / 3, 1 / 2, 0.0], [2 / 3, 1 / 2, 1.0]]
    by_type = _tables(report.path.read_text())[2]
    for j, column in enumerate((2, 3, 4)):
        shown = [float(row[column].split(" %")[0]) / 100 for row in by_type[1:]]
        np.testing.assert_allclose(shown, drawn["bar"][j], atol=5e-5)


def test_the_worst_of_a_hand_made_table_follow_the_four_rankings(tmp_path):
    """Rankings over encounters 0-5: collision [0]; CPA [0, 1, 3, 5, 4, 2]; blind spot [3];
    compliance by lowest score [0 (0.2), 3 (0.5), 1 (0.8), 4 (1.0)] (2 and 5 ungraded). In
    turn: 0, 1, 3, then compliance skips 0, 3, 1 and takes 4; then only CPA is left: 5, 2."""
    rows = completed({k: np.asarray(v) for k, v in _synthetic_columns().items()})
    picks = worst_encounters(rows, 10)
    assert [p.encounter for p in picks] == [0, 1, 3, 4, 5, 2]
    assert [p.reasons for p in picks] == [
        ["collision"], ["smallest CPA"], ["blind spot"], ["lowest compliance"],
        ["smallest CPA"], ["smallest CPA"]]
    np.testing.assert_array_equal([p.compliance for p in picks],
                                  [0.2, 0.8, 0.5, 1.0, np.nan, np.nan])
    five = picks[4]
    assert (five.min_range_m, five.t_min_range_s, five.kind) == (900.0, 150.0, "multi")
    assert picks[2].blind_spot == "give_way" and not picks[2].collision
    assert [p.encounter for p in worst_encounters(rows, 3)] == [0, 1, 3]


def _reference_worst(rows: dict, k: int) -> list[tuple[int, list[str], float]]:
    """The documented choice written out with plain loops: per encounter its smallest range,
    any collision, any blind spot and lowest graded score; four rankings (ties by index);
    take in turn the next encounter not yet taken from each."""
    per: dict[int, dict] = {}
    for i, e in enumerate(rows["encounter"].tolist()):
        d = per.setdefault(e, {"range": math.inf, "col": False, "blind": False, "low": None})
        d["range"] = min(d["range"], float(rows["min_range_m"][i]))
        d["col"] |= bool(rows["collision"][i])
        d["blind"] |= bool(rows["blind_spot"][i])
        for side in ("compliance_i", "compliance_j"):
            s = float(rows[side][i])
            if not math.isnan(s):
                d["low"] = s if d["low"] is None else min(d["low"], s)
    by_range = sorted(per, key=lambda e: (per[e]["range"], e))
    rankings = [[e for e in by_range if per[e]["col"]], by_range,
                [e for e in by_range if per[e]["blind"]],
                sorted((e for e in per if per[e]["low"] is not None),
                       key=lambda e: (per[e]["low"], e))]
    taken: list[tuple[int, list[str], float]] = []
    names = ["collision", "smallest CPA", "blind spot", "lowest compliance"]
    while len(taken) < k:
        progressed = False
        for name, ranking in zip(names, rankings, strict=True):
            if len(taken) >= k:
                break
            free = [e for e in ranking if e not in [t[0] for t in taken]]
            if free:
                e = free[0]
                reasons = [name] + [r for r, f in (("collision", per[e]["col"]),
                                                   ("blind spot", per[e]["blind"]))
                                    if f and r != name]
                low = per[e]["low"]
                taken.append((e, reasons, math.nan if low is None else low))
                progressed = True
        if not progressed:
            break
    return taken


@pytest.mark.parametrize("seed", range(40))
def test_worst_encounters_match_a_plain_loop_version(seed):
    """Random tables (ranges from a few values so that ties happen, NaN scores, unsorted
    encounter ids with gaps): the same encounters, reasons and scores as the reference."""
    rng = np.random.default_rng(seed)
    n_rows = int(rng.integers(1, 25))
    enc = rng.choice(np.arange(0, 40, 3), size=n_rows)
    score = rng.choice([0.1, 0.5, 0.9, np.nan], size=(2, n_rows))
    blind = rng.random(n_rows) < 0.2
    rows = _rows(encounter=enc, min_range_m=rng.choice([50.0, 300.0, 300.0, 900.0], n_rows),
                 collision=rng.random(n_rows) < 0.15, blind_spot=blind,
                 blind_spot_role=np.where(blind, "give_way", ""), compliance_i=score[0],
                 compliance_j=score[1])
    k = int(rng.integers(0, 10))
    got = [(p.encounter, p.reasons, p.compliance) for p in worst_encounters(rows, k)]
    want = _reference_worst(rows, k)
    assert [g[:2] for g in got] == [w[:2] for w in want]
    np.testing.assert_array_equal([g[2] for g in got], [w[2] for w in want])
    assert len({g[0] for g in got}) == len(got) == min(k, len(set(enc.tolist())))


def test_no_rows_give_no_worst_encounters():
    """An empty table (every encounter diverged) has nothing to pick, whatever ``k``."""
    empty = _rows(encounter=np.array([], dtype=np.int64), min_range_m=np.array([]))
    assert worst_encounters(empty, 5) == []


def test_a_campaign_whose_every_encounter_diverged_gets_a_page_of_dashes(tmp_path):
    """All encounters diverged: no outcome to count, so every rate and quantile is "-", the
    warning names them all, and no worst encounter is replayed (none ran to the end)."""
    pairs = [(*p[:10], True) for p in SYNTHETIC[:3]]
    folder = _synthetic_campaign(tmp_path / "camp", pairs)
    report = write_report(folder, worst=3)
    page = report.path.read_text()
    assert report.worst == []
    outcomes = _tables(page)[0]
    assert [row[1:] for row in outcomes[1:]] == [["0", "-"]] * 4
    assert "P1 / P5 / P50: - / - / - NM" in page
    assert "3 encounters diverged" in page and "below: 0, 1, 2.</p>" in page


def test_encounters_still_closing_at_their_end_are_flagged_on_the_page(tmp_path):
    """Encounters 3 and 5 ended with a pair not past its closest point: the page says their
    smallest range bounds the closest approach from above; without such pairs it says
    nothing (nor for a table from before the column)."""
    folder = tmp_path / "camp"
    folder.mkdir()
    cols = _synthetic_columns()
    cols["cpa_passed"] = ~np.isin(np.arange(len(SYNTHETIC)), [3, 6, 7])  # rows of enc. 3, 5
    write_parquet(folder / "encounters.parquet", cols)
    page = write_report(folder, worst=0).path.read_text()
    assert "2 encounters ended (at <code>max_duration_s</code>) with a pair still closing" in page
    cols["cpa_passed"][:] = True
    write_parquet(folder / "encounters.parquet", cols)
    assert "still closing" not in write_report(folder, worst=0).path.read_text()
    assert "still closing" not in write_report(_synthetic_campaign(tmp_path / "old"),
                                               worst=0).path.read_text()


def test_the_folder_name_is_escaped_on_the_page(tmp_path):
    """A campaign folder named with HTML's special characters shows as text, not markup."""
    folder = _synthetic_campaign(tmp_path / "a<b>&c")
    page = write_report(folder, worst=0).path.read_text()
    assert "<title>trafficsim report: a&lt;b&gt;&amp;c</title>" in page
    assert "<h1>Campaign a&lt;b&gt;&amp;c</h1>" in page and "a<b>" not in page


def test_a_report_drops_only_the_files_it_wrote_for_earlier_picks(tmp_path):
    """Files of an earlier report's picks (``encounter_K`` folder, ``.gif``, ``.png``) go when
    ``K`` is no longer picked; anything else in the folder stays."""
    folder = _synthetic_campaign(tmp_path / "camp")
    encounters = folder / "report" / "encounters"
    (encounters / "encounter_2").mkdir(parents=True)
    (encounters / "encounter_2" / "summary.json").write_text("{}")
    mine = ["encounter_2.gif", "encounter_2.png"]
    others = ["notes.txt", "encounter_2.txt", "encounter_x.gif", "my_encounter_2.gif",
              "encounter_2.png.bak", "encounter_02.gif"]
    for name in mine + others:
        (encounters / name).write_bytes(b"x")
    write_report(folder, worst=0)
    assert sorted(p.name for p in encounters.iterdir()) == sorted(others)


def test_the_report_tables_of_a_run_campaign_agree_with_its_encounters(campaign, tmp_path):
    """On a real campaign: the outcome counts on the page are those counted here, encounter by
    encounter, from ``encounters.parquet``; the types listed add up to every encounter; the
    figures are byte for byte those the campaign drew from its chunks (the same rows read
    back); the page is the same when written twice."""
    _, out = campaign
    report = write_report(out, tmp_path / "rep", worst=0)
    page = report.path.read_text()
    rows = pq.read_table(out / "encounters.parquet").to_pydict()
    per: dict[int, dict] = {}
    for i, e in enumerate(rows["encounter"]):
        d = per.setdefault(e, {"range": math.inf, "collision": False, "domain": False,
                               "blind": False, "type": rows["encounter_type"][i]})
        d["range"] = min(d["range"], rows["min_range_m"][i])
        d["collision"] |= rows["collision"][i]
        d["domain"] |= rows["domain_violation"][i]
        d["blind"] |= rows["blind_spot"][i]
    n = len(per)
    counts = [sum(d["collision"] for d in per.values()),
              sum(d["range"] < 800.0 and not d["collision"] for d in per.values()),
              sum(d["domain"] for d in per.values()), sum(d["blind"] for d in per.values())]
    outcomes, _, by_type = _tables(page)
    assert [int(row[1]) for row in outcomes[1:]] == counts
    assert [row[2] for row in outcomes[1:]] == [_rate_text(k, n) for k in counts]
    assert sum(int(row[1]) for row in by_type[1:]) == n
    median = float(np.median([d["range"] for d in per.values()])) / NM
    assert f"/ {median:.2f} NM" in page
    summary = json.loads((out / "summary.json").read_text())
    assert summary["collisions"] == counts[0]
    for name in ("cpa_histogram.png", "rates_by_type.png"):
        assert (tmp_path / "rep" / name).read_bytes() == (out / name).read_bytes(), name
    assert write_report(out, tmp_path / "rep", worst=0).path.read_text() == page


def test_a_worst_encounter_is_its_rows_and_its_replay(campaign, tmp_path):
    """The one worst encounter of a real campaign: its smallest range and time are those of its
    closest row in ``encounters.parquet``, its replay folder reports the same smallest range,
    and the page prints it in metres and NM."""
    _, out = campaign
    report = write_report(out, tmp_path / "rep", worst=1)
    (pick,) = report.worst
    rows = pq.read_table(out / "encounters.parquet").to_pydict()
    mine = [i for i, e in enumerate(rows["encounter"]) if e == pick.encounter]
    closest = min(mine, key=lambda i: (rows["min_range_m"][i], i))
    assert pick.min_range_m == rows["min_range_m"][closest]
    assert pick.t_min_range_s == rows["t_cpa_s"][closest]
    assert pick.kind == rows["encounter_type"][closest]
    replay = json.loads((tmp_path / "rep" / "encounters" / f"encounter_{pick.encounter}"
                         / "summary.json").read_text())
    assert min(p["min_range_m"] for p in replay["pairs"]) == pick.min_range_m
    assert replay["encounter"] == pick.encounter
    page = report.path.read_text()
    assert (f"{pick.min_range_m:.0f} m<br>({pick.min_range_m / NM:.2f} NM) at t = "
            f"{pick.t_min_range_s:.0f} s") in page
