"""``trafficsim report``: one HTML page for a campaign, with its PNG figures and the worst
encounters as thumbnails and GIFs.

The page (``index.html``) holds the campaign's summary table (rates with Wilson 95 % intervals,
CPA quantiles, mean compliance per rule), the rates by encounter type, the CPA histogram against
the ship domain and the rates figure (drawn by :func:`trafficsim.campaign.figures.write_figures`
into the report folder), and the ``k`` worst encounters. Those are picked in turn from four
rankings, each encounter once: collisions (smallest range first), smallest CPA, blind spots
(smallest range first) and lowest compliance score of any ship. Each is replayed alone
(:func:`trafficsim.campaign.replay.replay_encounter`, the same streams as the campaign) into
``encounters/encounter_K/`` (a run folder), drawn as a GIF of the whole encounter and as a
thumbnail of its closest approach (a close-up of the ships within five minutes of it), and
shown with the commands that replay and render it.
"""

from __future__ import annotations

import html
import math
import shlex
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim import __version__
from trafficsim.campaign.compliance import RULES
from trafficsim.campaign.runner import COLUMNS as WRITTEN
from trafficsim.errors import DataError, InputError
from trafficsim.io.results import read_parquet
from trafficsim.render.frame import FrameOptions
from trafficsim.units import NM

CRITERIA = ("collision", "smallest CPA", "blind spot", "lowest compliance")
GIF_OPTIONS = FrameOptions(size_px=(640, 480), dpi=72.0)
THUMB_OPTIONS = FrameOptions(size_px=(320, 240), dpi=64.0, legend=False, panel=False)
THUMB_WINDOW_S = 300.0  # a thumbnail shows where the ships are within 5 min of the CPA
GIF_FRAMES = 90  # about this many frames per GIF (a frame every whole record period)


@dataclass
class Pick:
    """One of the worst encounters and why it was picked."""

    encounter: int
    kind: str
    min_range_m: float
    t_min_range_s: float
    collision: bool
    blind_spot: str  # the role both ships held, or ""
    compliance: float  # lowest score of any ship (NaN: none graded)
    reasons: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Report:
    path: Path
    worst: list[Pick]
    seconds: float


#: the columns of ``encounters.parquet`` the report reads (written with the types of
#: :data:`trafficsim.campaign.runner.COLUMNS`); ``diverged`` and ``cpa_passed`` may be absent:
#: tables from before them count every encounter as run to the end and past its CPA
READ = ("encounter", "encounter_type", "min_range_m", "t_cpa_s", "collision",
        "domain_violation", "blind_spot", "blind_spot_role", "behaviour_i", "behaviour_j",
        "compliance_i", "compliance_j", *(f"score_rule{r}" for r in RULES))
OPTIONAL = ("diverged", "cpa_passed")
#: what a column of each written type must hold
KINDS = {"int64": "integer", "double": "number", "bool": "bool", "string": "text"}
EXPECTED = {"integer": "whole numbers", "number": "numbers", "bool": "true or false",
            "text": "text"}
RERUN = "run 'trafficsim campaign' on this folder again to write it anew from its chunks"


def read_encounters(campaign_dir: Path) -> dict[str, np.ndarray]:
    """The rows of ``encounters.parquet``, every column the report reads checked.

    Raises:
        InputError: no such folder, a run's folder, or a campaign that has not finished.
        DataError: an ``encounters.parquet`` that does not read, or a column missing, of
            another type, with empty values (numbers may be empty: not graded) or a negative
            encounter index (names the file and the column).
    """
    from trafficsim.folders import results_kind

    path = campaign_dir / "encounters.parquet"
    if not campaign_dir.is_dir():
        raise InputError("no such folder (the output folder of 'trafficsim "
                         "campaign' was expected)", path=str(campaign_dir))
    if not path.is_file() and results_kind(campaign_dir) == "run":
        raise InputError("holds a run's results (of 'trafficsim run' or 'replay'), not a "
                         "campaign's: report needs the output folder of 'trafficsim campaign' "
                         "('trafficsim render' draws a run)", path=str(campaign_dir))
    if not path.is_file():
        finish = ("; run the campaign command again to finish it"
                  if (campaign_dir / "campaign.json").is_file() else "")
        raise InputError("no encounters.parquet here (the output folder of a "
                         f"finished 'trafficsim campaign' was expected{finish})",
                         path=str(campaign_dir))
    table = read_parquet(path, "encounters table")
    for name in (*READ, *OPTIONAL):
        kind = KINDS[WRITTEN[name]]
        if name in table.column_names:
            _check_column(table, path, name, kind)
        elif name not in OPTIONAL:
            raise DataError(f"missing column (expected {EXPECTED[kind]} per ship pair; {RERUN})",
                            path=str(path), key=name)
    rows = {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}
    if np.any(rows["encounter"] < 0):
        raise DataError(f"expected encounter indices >= 0, got {int(rows['encounter'].min())} "
                        f"({RERUN})", path=str(path), key="encounter")
    return rows


def _check_column(table: Any, path: Path, name: str, kind: str) -> None:
    """Raise a DataError naming ``path`` and column ``name`` unless it holds ``kind``."""
    import pyarrow.types as pat

    arrow = table.schema.field(name).type
    ok = {"integer": pat.is_integer, "bool": pat.is_boolean,
          "number": lambda t: pat.is_integer(t) or pat.is_floating(t),
          "text": lambda t: pat.is_string(t) or pat.is_large_string(t)}[kind](arrow)
    if not ok:
        raise DataError(f"expected {EXPECTED[kind]}, got {arrow} values ({RERUN})",
                        path=str(path), key=name)
    if kind != "number" and table.column(name).null_count:
        raise DataError(f"expected {EXPECTED[kind]} in every row, got "
                        f"{table.column(name).null_count} empty values ({RERUN})",
                        path=str(path), key=name)


def worst_encounters(rows: dict[str, np.ndarray], k: int) -> list[Pick]:
    """Up to ``k`` encounters, taken in turn from the rankings of :data:`CRITERIA`."""
    enc = np.asarray(rows["encounter"], dtype=np.int64)
    ids = np.unique(enc)
    if k <= 0 or ids.size == 0:
        return []
    slot = np.searchsorted(ids, enc)
    min_range = np.full(ids.shape, np.inf)
    np.minimum.at(min_range, slot, np.asarray(rows["min_range_m"], dtype=float))
    score = np.fmin(np.asarray(rows["compliance_i"], dtype=float),
                    np.asarray(rows["compliance_j"], dtype=float))
    low = np.full(ids.shape, np.nan)
    np.fmin.at(low, slot, score)
    collision = np.zeros(ids.shape, dtype=bool)
    np.logical_or.at(collision, slot, np.asarray(rows["collision"], dtype=bool))
    blind = np.zeros(ids.shape, dtype=bool)
    np.logical_or.at(blind, slot, np.asarray(rows["blind_spot"], dtype=bool))
    order = np.lexsort((ids, min_range))  # smallest range, then lowest index
    rankings = [order[collision[order]], order, order[blind[order]]]
    graded = np.flatnonzero(np.isfinite(low))
    rankings.append(graded[np.lexsort((ids[graded], low[graded]))])
    picks: dict[int, Pick] = {}
    cursors = [0] * len(rankings)
    while len(picks) < k and any(c < len(r) for c, r in zip(cursors, rankings, strict=True)):
        for c, ranking in enumerate(rankings):
            while cursors[c] < len(ranking) and int(ids[ranking[cursors[c]]]) in picks:
                cursors[c] += 1
            if cursors[c] >= len(ranking) or len(picks) >= k:
                continue
            s = ranking[cursors[c]]
            picks[int(ids[s])] = _pick(rows, enc == ids[s], int(ids[s]), float(low[s]),
                                       CRITERIA[c])
    return list(picks.values())


def _pick(rows: dict[str, np.ndarray], sel: np.ndarray, encounter: int, compliance: float,
          reason: str) -> Pick:
    rng = np.asarray(rows["min_range_m"], dtype=float)[sel]
    closest = int(np.argmin(rng))
    roles = [str(r) for r in np.asarray(rows["blind_spot_role"], dtype=object)[sel] if r]
    pick = Pick(encounter, str(np.asarray(rows["encounter_type"], dtype=object)[sel][0]),
                float(rng[closest]), float(np.asarray(rows["t_cpa_s"], dtype=float)[sel][closest]),
                bool(np.any(np.asarray(rows["collision"], dtype=bool)[sel])),
                roles[0] if roles else "", compliance, [reason])
    for name, flag in (("collision", pick.collision), ("blind spot", bool(pick.blind_spot))):
        if flag and name not in pick.reasons:
            pick.reasons.append(name)
    return pick


def write_report(campaign_dir: str | Path, out_dir: str | Path | None = None, worst: int = 6,
                 progress: bool = False) -> Report:
    """Write the report of the campaign in ``campaign_dir`` into ``out_dir`` (default:
    ``campaign_dir/report``); return where and what it shows.

    Raises:
        InputError: not a finished campaign folder; with ``worst > 0`` a spec that is gone or
            changed since the campaign ran (replays need it). DataError: a damaged
            ``encounters.parquet`` (:func:`read_encounters`), or with ``worst > 0`` one holding
            encounters beyond the spec's ``n_encounters``.
    """
    from tqdm import tqdm

    from trafficsim.campaign.figures import write_figures
    from trafficsim.campaign.replay import campaign_spec, replay_encounter
    from trafficsim.campaign.summary import completed, summarise
    from trafficsim.render.export import render_frame, render_run

    t0 = time.perf_counter()
    campaign_dir = Path(campaign_dir)
    rows = read_encounters(campaign_dir)
    picks = worst_encounters(completed(rows), worst)
    spec = campaign_spec(campaign_dir) if picks else None
    if spec is not None and int(rows["encounter"].max()) >= spec.n_encounters:
        raise DataError(f"encounter {int(rows['encounter'].max())} is not one of the "
                        f"campaign's {spec.n_encounters} (0 .. {spec.n_encounters - 1}, spec "
                        f"{spec.path}): the table is not this campaign's ({RERUN})",
                        path=str(campaign_dir / "encounters.parquet"), key="encounter")
    out = Path(out_dir) if out_dir is not None else campaign_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    figures = write_figures(rows, out)
    _drop_stale(out / "encounters", {p.encounter for p in picks})
    for pick in tqdm(picks, unit="encounter", disable=not progress, leave=False):
        name = f"encounter_{pick.encounter}"
        run_dir = out / "encounters" / name
        summary = replay_encounter(campaign_dir, pick.encounter, run_dir)
        every = summary["record_every_s"]
        frames_every = every * max(1, math.ceil(summary["n_steps"] * summary["dt_s"]
                                                / every / GIF_FRAMES))
        render_run(run_dir, out / "encounters", "gif", frames_every, GIF_OPTIONS, fps=10.0,
                   name=name)
        render_frame(run_dir, out / "encounters" / f"{name}.png", pick.t_min_range_s,
                     THUMB_OPTIONS, window_s=THUMB_WINDOW_S)
    page = _page(campaign_dir, spec, summarise(rows), figures, picks)
    from trafficsim.io.results import atomic_write

    atomic_write(out / "index.html", lambda fh: fh.write(page.encode()))
    return Report(out / "index.html", picks, time.perf_counter() - t0)


def _drop_stale(folder: Path, keep: set[int]) -> None:
    """Remove the replays, GIFs and thumbnails of encounters an earlier report picked and this
    one does not (only names this module writes: ``encounter_K``, ``.gif``, ``.png``)."""
    import shutil

    if not folder.is_dir():
        return
    for item in folder.iterdir():
        stem = item.name.removesuffix(".gif").removesuffix(".png")
        number = stem.removeprefix("encounter_")
        if stem == item.name.split(".")[0] and stem.startswith("encounter_") and \
                number.isdigit() and number == str(int(number)) and int(number) not in keep:
            if item.is_dir():
                shutil.rmtree(item)
            else:
                item.unlink()


def _rate(stat: dict[str, Any]) -> str:
    low, high = stat["ci95"]
    if stat["rate"] is None or (isinstance(stat["rate"], float) and math.isnan(stat["rate"])):
        return "-"
    return f"{100 * stat['rate']:.2f} % ({100 * low:.2f} - {100 * high:.2f} %)"


def _num(value: Any, fmt: str = ".3f") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, fmt)


def _page(campaign_dir: Path, spec: Any, summary: dict[str, Any], figures: list[Path],
          picks: list[Pick]) -> str:
    e = html.escape
    name = spec.name if spec is not None else campaign_dir.name
    head = ["<!DOCTYPE html>", "<html lang='en'><head><meta charset='utf-8'>",
            f"<title>trafficsim report: {e(name)}</title>", f"<style>{_CSS}</style></head>",
            "<body>", f"<h1>Campaign {e(name)}</h1>",
            f"<p>{summary['n_encounters']} encounters from <code>{e(str(campaign_dir))}</code>"
            + (f", seed {spec.seed}, policy {e(spec.policy)}, domain {e(spec.domain)}"
               if spec is not None else "") + f"; report by trafficsim {e(__version__)}.</p>"]
    if summary.get("diverged"):
        listed = ", ".join(str(i) for i in summary["diverged_encounters"][:20])
        more = " ..." if summary["diverged"] > 20 else ""
        head.append(f"<p class='warn'>{summary['diverged']} encounters diverged (a ship's state "
                    f"stopped being finite: check its ship file) and are left out of "
                    f"everything below: {listed}{more}.</p>")
    body = ["<h2>Summary</h2>", "<table><tr><th>outcome</th><th>encounters</th>"
            "<th>rate (95 % interval)</th></tr>"]
    for key, label in (("collision", "collision"), ("near_miss", "near miss (< 800 m)"),
                       ("domain_violation", "ship domain entered"),
                       ("blind_spot", "blind spot (both ships in one role)")):
        body.append(f"<tr><td>{label}</td><td>{summary[key]['count']}</td>"
                    f"<td>{_rate(summary[key])}</td></tr>")
    body.append("</table>")
    cpa = summary["cpa_nm"]
    body.append(f"<p>Smallest range per encounter, P1 / P5 / P50: {_num(cpa['p1'], '.2f')} / "
                f"{_num(cpa['p5'], '.2f')} / {_num(cpa['p50'], '.2f')} NM. Collisions with "
                f"every ship compliant: {summary['collisions_all_compliant']} of "
                f"{summary['encounters_all_compliant']} such encounters.</p>")
    if summary.get("cpa_not_passed"):
        body.append(f"<p class='warn'>{summary['cpa_not_passed']} encounters ended (at "
                    "<code>max_duration_s</code>) with a pair still closing to less than its "
                    "smallest range so far: for them that range bounds the closest approach "
                    "from above.</p>")
    body.append("<table><tr><th>rule</th>" + "".join(
        f"<th>{e(k.replace('rule', 'Rule '))}</th>" for k in summary["compliance"])
        + "</tr><tr><td>mean compliance</td>" + "".join(
        f"<td>{_num(v, '.2f')}</td>" for v in summary["compliance"].values()) + "</tr></table>")
    body += ["<h2>By encounter type</h2>", "<table><tr><th>type</th><th>encounters</th>"
             "<th>collision</th><th>near miss</th><th>domain entered</th><th>blind spot</th>"
             "<th>CPA P50 (NM)</th></tr>"]
    for kind, s in summary["by_type"].items():
        body.append(f"<tr><td>{e(kind.replace('_', ' '))}</td><td>{s['n_encounters']}</td>"
                    + "".join(f"<td>{_rate(s[k])}</td>" for k in
                              ("collision", "near_miss", "domain_violation", "blind_spot"))
                    + f"<td>{_num(s['cpa_nm']['p50'], '.2f')}</td></tr>")
    body.append("</table>")
    body.append("<h2>Figures</h2><div class='figs'>" + "".join(
        f"<a href='{e(p.name)}'><img src='{e(p.name)}' alt='{e(p.stem)}'></a>" for p in figures)
        + "</div><p>Left: smallest range of every ship pair, pairs that entered a ship domain "
        "apart from those that did not, against the collision, near-miss and safe-passing "
        "ranges. Right: rates by encounter type with 95 % intervals.</p>")
    body.append(f"<h2>Worst encounters ({len(picks)})</h2>")
    if picks:
        body.append("<p>Picked in turn by collision, smallest CPA, blind spot and lowest "
                    "compliance score; the thumbnail shows the closest approach, a click plays "
                    "the encounter. Each folder is a run folder of the replay.</p><table>"
                    "<tr><th>picture</th><th>encounter</th><th>smallest range</th>"
                    "<th>outcome</th><th>replay</th></tr>")
    here = shlex.quote(str(campaign_dir))
    for p in picks:
        stem = f"encounters/encounter_{p.encounter}"
        outcome = ["collision" if p.collision else "no collision"]
        if p.blind_spot:
            outcome.append(f"blind spot (both {e(p.blind_spot.replace('_', ' '))})")
        outcome.append(f"lowest compliance {_num(p.compliance, '.2f')}")
        replay = (f"trafficsim replay {here} --encounter {p.encounter} "
                  f"--out out/encounter_{p.encounter}")
        render = f"trafficsim render out/encounter_{p.encounter} --format mp4 --out out/frames"
        body.append(
            f"<tr><td><a href='{stem}.gif'><img src='{stem}.png' alt='encounter "
            f"{p.encounter}'></a></td><td><b>{p.encounter}</b><br>{e(p.kind.replace('_', ' '))}"
            f"<br><i>{e(', '.join(p.reasons))}</i></td><td>{p.min_range_m:.0f} m<br>"
            f"({p.min_range_m / NM:.2f} NM) at t = {p.t_min_range_s:.0f} s</td>"
            f"<td>{'<br>'.join(outcome)}</td><td><code>{e(replay)}</code><br>"
            f"<code>{e(render)}</code><br><a href='{stem}/'>run folder</a> | "
            f"<a href='{stem}.gif'>GIF</a></td></tr>")
    if picks:
        body.append("</table>")
    return "\n".join([*head, *body, "</body></html>", ""])


_CSS = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;"
        "padding:4px 8px;text-align:left;vertical-align:top}th{background:#f0f3f7}"
        ".figs img{width:49%}code{font-size:85%;background:#f4f4f4;padding:1px 3px}"
        ".warn{background:#fff3cd;border:1px solid #e0c36c;padding:6px 10px}")
