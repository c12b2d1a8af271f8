"""Command line: ``trafficsim run | campaign | explain | trial | identify | diagnose |
validate | render | report | replay``.

Every user error ends as one line on stderr (``trafficsim: error: file:line: key: message``) and
exit code 2, never a traceback. Heavy imports happen inside the commands so ``--help`` is fast.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from trafficsim import __version__
from trafficsim.errors import InputError, TrafficsimError

if TYPE_CHECKING:
    from trafficsim.render.frame import FrameOptions

EXIT_USER_ERROR = 2
#: largest smoother noise ``identify`` accepts: position (m) and heading (deg)
MAX_SIGMA_POS_M, MAX_SIGMA_HEADING_DEG = 1000.0, 90.0


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad flag in one line and exits 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _positive(kind: type) -> object:
    def parse(text: str) -> float | int:
        try:
            value = kind(text)
        except ValueError:
            what = "a whole number" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {what}, got '{text}'") from None
        if not value > 0 or not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a positive number, got '{text}'")
        return value

    parse.__name__ = kind.__name__
    return parse


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got '{text}'")
    return value


def _out_dir(text: str) -> Path:
    """An output folder: an empty name would write into the working directory."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder name, got an empty one (the results "
                                         "would land in the working directory; write '.' to "
                                         "mean it)")
    return Path(text)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="trafficsim", description="Fast-time multi-ship traffic and "
                "collision-avoidance simulator.")
    p.add_argument("--version", action="version", version=f"trafficsim {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="simulate a scenario file")
    run.add_argument("scenario", type=Path, help="scenario YAML file")
    run.add_argument("--out", type=_out_dir, required=True, help="output folder")
    frames = run.add_argument_group("frames drawn as the run goes (into OUT/frames)")
    frames.add_argument("--frames", nargs="?", const="png", default=None,
                        choices=["png", "gif", "mp4"],
                        help="draw frames while the run goes: png (default), gif or mp4")
    frames.add_argument("--frames-every-s", type=_positive(float), default=None,
                        help="a frame every this many simulated seconds (a multiple of the "
                             "record period; default: every record)")
    _frame_flags(frames)
    run.set_defaults(func=_cmd_run)

    camp = sub.add_parser("campaign", help="Monte Carlo campaign of random encounters "
                          "(resumes an unfinished one in the same --out)")
    camp.add_argument("spec", type=Path, help="campaign spec YAML file")
    camp.add_argument("--out", type=_out_dir, required=True, help="output folder")
    camp.add_argument("--workers", type=_positive(int), default=None,
                      help="local worker processes (default: all cores)")
    camp.add_argument("--executor", choices=["local", "dask"], default="local",
                      help="local processes (default) or a Dask cluster")
    camp.add_argument("--address", default=None,
                      help="Dask scheduler address (with --executor dask)")
    camp.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    camp.set_defaults(func=_cmd_campaign)

    why = sub.add_parser("explain", help="why a ship of a run did what it did")
    why.add_argument("run_dir", type=Path, help="output folder of 'trafficsim run'")
    why.add_argument("--ship", required=True, help="ship name")
    why.add_argument("--at-s", type=_finite, default=None,
                     help="explain the decisions at this time (default: the last change)")
    why.set_defaults(func=_cmd_explain)

    trial = sub.add_parser("trial", help="standard manoeuvre of one ship with IMO indices")
    trial.add_argument("ship", help="ship type from the library (e.g. kvlcc2) or ship-file path")
    trial.add_argument("--manoeuvre", required=True, choices=["turning", "zigzag", "crash-stop"])
    trial.add_argument("--rudder-deg", type=_positive(float), default=None,
                       help="rudder angle (turning: 35, zigzag: 10 by default)")
    trial.add_argument("--heading-deg", type=_positive(float), default=None,
                       help="zig-zag heading change, 1 to 90 deg (default: equal to the rudder "
                            "angle)")
    trial.add_argument("--port", action="store_true",
                       help="turn to port (turning circle) or put the first rudder to port "
                            "(zig-zag)")
    trial.add_argument("--speed-kn", type=_positive(float), default=None,
                       help="approach speed, 0.1 to 2 times the ship's service speed and one "
                            "its engine holds (default: the service speed)")
    trial.add_argument("--dt-s", type=_positive(float), default=None,
                       help="time step (default: 1 s, shorter for small ships)")
    trial.add_argument("--sensors", action="store_true",
                       help="also record GNSS receiver output (gnss_*) and the navigation "
                            "estimate (est_*) beside the truth")
    trial.add_argument("--sp", type=_positive(float), default=None,
                       help="with --sensors: receiver filter spectral amplitude S_p, m^2/s^3, "
                            "1e-6 to 1e4 (default 0.01)")
    trial.add_argument("--seed", type=_non_negative_int, default=None,
                       help="with --sensors: seed of the instrument noise (default 0)")
    trial.add_argument("--out", type=_out_dir, required=True, help="output folder")
    trial.set_defaults(func=_cmd_trial)

    ident = sub.add_parser("identify", help="fit a ship model to trial runs; writes a ship "
                           "file, a convergence plot and a validation report")
    ident.add_argument("--model", required=True,
                       choices=["response", "nomoto", "mmg", "mmg_berthing"])
    ident.add_argument("--data", type=Path, nargs="+", required=True, metavar="RUN",
                       help="training runs: trial-data CSV or FRT-DS-ESSO files, or folders")
    ident.add_argument("--holdout", type=Path, nargs="+", default=[], metavar="RUN",
                       help="held-out runs for the prediction error")
    ident.add_argument("--base", required=True,
                       help="ship type or ship file giving particulars, actuators and every "
                            "coefficient not fitted (an mmg ship for --model mmg)")
    ident.add_argument("--out", type=_out_dir, required=True, help="output folder")
    ident.add_argument("--method", choices=["oe", "ekf", "ekf+oe"], default=None,
                       help="output error, augmented EKF (response only) or EKF then output "
                            "error (default: ekf+oe for response, oe otherwise)")
    ident.add_argument("--fit", type=_names, default=None, metavar="NAME,...",
                       help="coefficients to fit (default: the model's documented subset)")
    ident.add_argument("--bounds", type=_bound, nargs="+", default=[], metavar="NAME=LO:HI",
                       help="bounds of fitted coefficients")
    ident.add_argument("--horizon-s", type=_positive(float), default=None,
                       help="replay window length (default 3 L/U; from two working intervals "
                            "to the longest run)")
    ident.add_argument("--dt-s", type=_positive(float), default=None,
                       help="working sampling interval (default: the data's, thinned to "
                            "L/(20 U); from the data's interval to L/U)")
    ident.add_argument("--wind", choices=["auto", "ignore"], default="auto",
                       help="use measured wind when the model has wind loads (default auto; "
                            "ignore only for such a model and runs with wind)")
    ident.add_argument("--reference", default=None,
                       help="known ship to compare the standard manoeuvres with "
                            "(simulated trials)")
    ident.add_argument("--name", default=None, help="name of the identified ship")
    ident.add_argument("--max-nfev", type=_positive(int), default=None,
                       help="most model evaluations of the output-error fit (default 60)")
    ident.add_argument("--columns", type=_mapping, default=None, metavar="NAME=COLUMN,...",
                       help="read trial-data columns from other columns of the CSV files, "
                            "e.g. north_m=gnss_fix_north_m,east_m=gnss_fix_east_m,"
                            "heading_deg=compass_heading_deg (trial --sensors output)")
    ident.add_argument("--sigma-pos-m", type=_positive(float), default=None,
                       help="position noise for the smoother (default: from the data)")
    ident.add_argument("--sigma-heading-deg", type=_positive(float), default=None,
                       help="heading noise for the smoother (default: from the data)")
    ident.set_defaults(func=_cmd_identify)

    diag = sub.add_parser("diagnose", help="sim-to-real gap: where it lies, which effect "
                          "causes it, how far it shrinks (or --self-test N)")
    diag.add_argument("--ship", default=None,
                      help="base model: library name, ship file or MMG parameter folder")
    diag.add_argument("--data", type=Path, nargs="+", default=[],
                      help="training runs (trial-data CSV or FRT-DS-ESSO files, or folders)")
    diag.add_argument("--holdout", type=Path, nargs="+", default=[],
                      help="held-out runs (default: alternate windows of --data)")
    diag.add_argument("--out", type=_out_dir, default=None, help="output folder")
    diag.add_argument("--effects", nargs="+", default=None,
                      help="candidate effects, each once (default: every effect of the "
                           "library that acts on the ship's model)")
    diag.add_argument("--horizon-s", type=_positive(float), default=None,
                      help="replay window length (default 3 L/U; bounds as identify)")
    diag.add_argument("--dt-s", type=_positive(float), default=None,
                      help="working sampling interval (default and bounds: as identify)")
    diag.add_argument("--refit", nargs="?", const="default", default=None,
                      metavar="NAME,...",
                      help="base coefficients fitted on the training runs jointly with every "
                      "candidate, the base included (no value: identify's default subset)")
    diag.add_argument("--self-test", type=_positive(int), default=None, metavar="N",
                      help="N trials with a random hidden effect; prints the confusion matrix")
    diag.add_argument("--seed", type=_non_negative_int, default=None,
                      help="self-test seed (default 0)")
    diag.add_argument("--no-progress", action="store_true",
                      help="no progress lines on stderr")
    diag.set_defaults(func=_cmd_diagnose)

    val = sub.add_parser("validate", help="check scenario, ship, rules or campaign files "
                         "without running them")
    val.add_argument("files", type=Path, nargs="+")
    val.set_defaults(func=_cmd_validate)

    ren = sub.add_parser("render", help="pictures of a run: PNG frames, GIF or MP4 (headless)")
    ren.add_argument("run_dir", type=Path, help="output folder of 'trafficsim run' or 'replay'")
    ren.add_argument("--format", choices=["png", "gif", "mp4"], default="png",
                     help="numbered PNG frames (default), one animated GIF or one MP4")
    ren.add_argument("--every-s", type=_positive(float), default=None,
                     help="a frame every this many simulated seconds (a multiple of the "
                          "run's record period; default: every record)")
    ren.add_argument("--out", type=_out_dir, required=True, help="output folder")
    _frame_flags(ren)
    ren.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    ren.set_defaults(func=_cmd_render)

    rep = sub.add_parser("report", help="HTML report of a campaign with figures and the worst "
                         "encounters as GIFs")
    rep.add_argument("campaign_dir", type=Path, help="output folder of 'trafficsim campaign'")
    rep.add_argument("--worst", type=_non_negative_int, default=6,
                     help="how many of the worst encounters to replay and draw (default 6)")
    rep.add_argument("--out", type=_out_dir, default=None,
                     help="report folder (default: CAMPAIGN_DIR/report)")
    rep.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    rep.set_defaults(func=_cmd_report)

    rpl = sub.add_parser("replay", help="re-simulate one encounter of a campaign into a run "
                         "folder")
    rpl.add_argument("campaign_dir", type=Path, help="output folder of 'trafficsim campaign'")
    rpl.add_argument("--encounter", type=_non_negative_int, required=True,
                     help="encounter index (the 'encounter' column of encounters.parquet)")
    rpl.add_argument("--out", type=_out_dir, required=True, help="output folder (a run folder)")
    rpl.add_argument("--record-every-s", type=_positive(float), default=None,
                     help="record period (a multiple of the campaign's step; default 5 s)")
    rpl.set_defaults(func=_cmd_replay)
    return p


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got '{text}'") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got '{text}'")
    return value


def _dpi(text: str) -> float:
    from trafficsim.render.style import DPI_RANGE

    value = _positive(float)(text)
    if not DPI_RANGE[0] <= value <= DPI_RANGE[1]:
        raise argparse.ArgumentTypeError(f"expected {DPI_RANGE[0]:g} to {DPI_RANGE[1]:g} dots "
                                         f"per inch, got '{text}'")
    return value


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels (e.g. 960x720), "
                                         f"got '{text}'") from None
    if not (64 <= w <= 8192 and 64 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"expected 64 to 8192 pixels each way, got '{text}'")
    return w, h


#: ``run``'s frame flags and their value when not given (None, or False for a switch): given
#: without ``--frames`` they would do nothing
_RUN_FRAME_FLAGS = {"--frames-every-s": None, "--size": None, "--dpi": None, "--follow": None,
                    "--range-nm": None, "--measurements": False, "--fps": None}


def _frame_flags(group: argparse._ActionsContainer) -> None:
    """How frames look (``render`` and ``run --frames``)."""
    group.add_argument("--size", type=_size, default=None,
                       help="frame size WIDTHxHEIGHT in pixels (default 960x720)")
    group.add_argument("--dpi", type=_dpi, default=None,
                       help="dots per inch, 10 to 1200: text and lines scale with it "
                            "(default 96)")
    group.add_argument("--follow", default=None, metavar="SHIP",
                       help="follow this ship (default: a fixed view that fits every ship)")
    group.add_argument("--range-nm", type=_positive(float), default=None,
                       help="with --follow: distance from the ship to the view's edge "
                            "(default 3)")
    group.add_argument("--measurements", action="store_true", help="draw the raw GNSS fixes")
    group.add_argument("--fps", type=_positive(float), default=None,
                       help="GIF and MP4 frames per second (default 10)")


def _only_with(flag: str, given: bool, applies: bool, needs: str) -> None:
    """Refuse a flag given where it would do nothing (rather than ignore it)."""
    if given and not applies:
        raise InputError(f"applies only {needs}", key=flag)


def _fps(args: argparse.Namespace, fmt: str) -> float:
    """Frames per second of a GIF or MP4 (``--fps``, default 10)."""
    _only_with("--fps", args.fps is not None, fmt != "png", "to GIF and MP4 frames")
    return 10.0 if args.fps is None else args.fps


def _frame_options(args: argparse.Namespace) -> FrameOptions:
    from trafficsim.render.frame import MAX_RANGE_NM, MIN_RANGE_NM, FrameOptions

    _only_with("--range-nm", args.range_nm is not None, args.follow is not None, "with --follow")
    if args.range_nm is not None and not MIN_RANGE_NM <= args.range_nm <= MAX_RANGE_NM:
        raise InputError(f"expected a view range of {MIN_RANGE_NM:g} to {MAX_RANGE_NM:g} NM "
                         f"(the width of the scenario frame), got {args.range_nm:g}",
                         key="--range-nm")
    return FrameOptions(size_px=FrameOptions.size_px if args.size is None else args.size,
                        dpi=FrameOptions.dpi if args.dpi is None else args.dpi, follow=args.follow,
                        range_nm=3.0 if args.range_nm is None else args.range_nm,
                        measurements=args.measurements)


def _cmd_run(args: argparse.Namespace) -> int:
    from trafficsim.run import run_scenario

    for flag, default in _RUN_FRAME_FLAGS.items():
        _only_with(flag, getattr(args, flag[2:].replace("-", "_")) != default,
                   args.frames is not None, "with --frames (png, gif or mp4)")
    hook = None
    if args.frames is not None:
        from trafficsim.render.export import LiveFrames

        hook = LiveFrames(args.scenario, args.out / "frames", args.frames, args.frames_every_s,
                          _frame_options(args), _fps(args, args.frames))
    try:
        summary = run_scenario(args.scenario, args.out, hook)
    except BaseException:
        if hook is not None:
            hook.abort()
        raise
    frame_files = [] if hook is None else hook.close()
    print(f"{summary['scenario']}: {summary['n_ships']} ships, {summary['duration_s']:g} s "
          f"simulated in {summary['wall_time_s']:.2f} s "
          f"({summary['ship_steps_per_s']:,.0f} ship-steps/s)")
    for pair in summary["pairs"]:
        flag = ("  COLLISION" if pair["collision"] else
                "  domain entered" if pair.get("domain_violation") else "")
        print(f"  {pair['ship_a']} - {pair['ship_b']}: min range {pair['min_range_m']:.0f} m "
              f"at t = {pair['t_min_range_s']:.0f} s{flag}")
    for spot in summary.get("blind_spots", []):
        print(f"  BLIND SPOT: {spot['ship']} and {spot['other']} both {spot['role']} "
              f"from t = {spot['from_s']:.0f} s")
    files = ["trajectories.parquet", "tracks.parquet", "decisions.parquet", "summary.json"]
    print("results: " + ", ".join(str(args.out / f) for f in files if (args.out / f).exists()))
    if hook is not None:
        where = frame_files[0] if args.frames != "png" else args.out / "frames"
        print(f"frames: {hook.frames} ({args.frames}) in {where}")
    return 0


def _cmd_campaign(args: argparse.Namespace) -> int:
    from trafficsim.campaign.execute import run_campaign

    _only_with("--address", args.address is not None, args.executor == "dask",
               "with --executor dask")
    _only_with("--workers", args.workers is not None, args.executor == "local",
               "to local processes (a Dask cluster has its own workers)")
    s = run_campaign(args.spec, args.out, args.workers, args.executor, args.address,
                     progress=not args.no_progress)
    rate = s["ship_steps_per_s"]
    print(f"{s['campaign']}: {s['n_encounters']} encounters, {s['collisions']} with a collision "
          f"({s['collisions_all_compliant']} of {s['encounters_all_compliant']} with every ship "
          f"compliant), near misses {s['near_miss']['count']}, domain entered "
          f"{s['domain_violation']['count']}, blind spots {s['blind_spot']['count']}")
    print(f"  CPA P1/P5/P50: {s['cpa_nm']['p1']:.2f} / {s['cpa_nm']['p5']:.2f} / "
          f"{s['cpa_nm']['p50']:.2f} NM"
          + (f"; {rate:,.0f} ship-steps/s" if rate else ""))
    if s["cpa_not_passed"]:
        print(f"  {s['cpa_not_passed']} encounters still closing at their end (max_duration_s): "
              f"their smallest range so far counts as their CPA")
    if s["diverged"]:
        listed = ", ".join(str(i) for i in s["diverged_encounters"][:10])
        print(f"  DIVERGED: {s['diverged']} encounters (a ship's state stopped being finite: "
              f"check its ship file), left out of the figures above: {listed}"
              + (" ..." if s["diverged"] > 10 else ""))
    print(f"results: {args.out / 'encounters.parquet'}, {args.out / 'summary.json'}, "
          f"{args.out / 'cpa_histogram.png'}, {args.out / 'rates_by_type.png'}")
    return 0


def _cmd_explain(args: argparse.Namespace) -> int:
    from trafficsim.colregs.explain import explain_run

    print(explain_run(args.run_dir, args.ship, args.at_s))
    return 0


def _cmd_trial(args: argparse.Namespace) -> int:
    from trafficsim.trial import run_trial

    m = args.manoeuvre
    _only_with("--rudder-deg", args.rudder_deg is not None, m != "crash-stop",
               "to --manoeuvre turning or zigzag")
    _only_with("--heading-deg", args.heading_deg is not None, m == "zigzag",
               "to --manoeuvre zigzag")
    _only_with("--port", args.port, m != "crash-stop", "to --manoeuvre turning or zigzag")
    for flag, value in (("--sp", args.sp), ("--seed", args.seed)):
        _only_with(flag, value is not None, args.sensors, "with --sensors")
    indices, criteria = run_trial(args.ship, m, args.rudder_deg, args.heading_deg, args.port,
                                  args.speed_kn, args.dt_s, args.out, args.sensors,
                                  0.01 if args.sp is None else args.sp,
                                  0 if args.seed is None else args.seed)
    for key, value in indices.items():
        print(f"  {key}: {value:.4g}")
    for key, c in criteria.items():
        verdict = "pass" if c["pass"] else "FAIL"
        print(f"  IMO {key}: {c['value']:.3g} (limit {c['limit']:.3g}) {verdict}")
    print(f"results: {args.out / 'trial.csv'}, {args.out / 'indices.json'}")
    return 0


def _names(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected coefficient names separated by commas, "
                                         f"got '{text}'")
    return names


def _mapping(text: str) -> dict[str, str]:
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        if not (sep and key.strip() and value.strip()):
            raise argparse.ArgumentTypeError(f"expected NAME=COLUMN,... got '{text}'")
        out[key.strip()] = value.strip()
    return out


def _bound(text: str) -> tuple[str, float, float]:
    name, sep, rng = text.partition("=")
    lo, sep2, hi = rng.partition(":")
    try:
        if not (sep and sep2 and name.strip()) or math.isnan(float(lo)) or math.isnan(float(hi)):
            raise ValueError
        return name.strip(), float(lo), float(hi)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=LOW:HIGH (numbers; -inf and inf for "
                                         f"no bound), got '{text}'") from None


def _cmd_identify(args: argparse.Namespace) -> int:
    import numpy as np

    from trafficsim.identify.command import identify
    from trafficsim.identify.preprocess import SmootherSettings
    from trafficsim.identify.report import interval_text

    for flag, value, most in (("--sigma-pos-m", args.sigma_pos_m, MAX_SIGMA_POS_M),
                              ("--sigma-heading-deg", args.sigma_heading_deg,
                               MAX_SIGMA_HEADING_DEG)):
        if value is not None and value > most:
            raise InputError(f"expected a noise of at most {most:g}, got {value:g} (a "
                             "measurement that noisy says nothing of the track)", key=flag)
    smoother = SmootherSettings(
        sigma_pos_m=args.sigma_pos_m,
        sigma_heading_rad=None if args.sigma_heading_deg is None
        else float(np.radians(args.sigma_heading_deg)))
    output_error = args.method != "ekf"
    _only_with("--max-nfev", args.max_nfev is not None, output_error,
               "to the output-error fit (--method oe or ekf+oe)")
    _only_with("--bounds", bool(args.bounds), output_error,
               "to the output-error fit (--method oe or ekf+oe)")
    bounds = {name: (lo, hi) for name, lo, hi in args.bounds}
    rep = identify(args.model, args.data, args.out, args.base, args.holdout, args.method,
                   args.fit, bounds, args.horizon_s, args.dt_s, args.wind, args.reference,
                   args.name, 60 if args.max_nfev is None else args.max_nfev,
                   smoother=smoother, columns=args.columns)
    fit = rep["fit"]
    if fit is not None:
        print(f"{rep['model']} model: output-error cost {fit['cost_initial']:.4g} -> "
              f"{fit['cost_final']:.4g} in {fit['evaluations']} evaluations "
              f"({fit['elapsed_s']:.1f} s)")
        for name, c in fit["coefficients"].items():
            print(f"  {name}: {c['value']:.5g} (95 % {interval_text(c)}; windows clustered "
                  f"{interval_text(c, 'ci95_clustered')})")
    elif rep["ekf"] is not None:
        for name, c in rep["ekf"]["coefficients"].items():
            print(f"  {name}: {c['value']:.5g} (std {c['std']:.3g})")
    for role, by_model in rep["validation"]["prediction"].items():
        e, e0 = by_model["identified"]["all"], by_model["start"]["all"]
        print(f"  {role}: end-of-window position error RMS {e['end_position_rms_m']:.3g} m "
              f"(start model {e0['end_position_rms_m']:.3g} m), heading RMS "
              f"{e['heading_rms_deg']:.3g} deg ({e0['heading_rms_deg']:.3g} deg)")
    comparison = rep["validation"]["reference_comparison"]
    if comparison:
        turn = comparison["turning_35_starboard"]
        print("  35 deg turn vs reference: " + ", ".join(
            f"{k} {v['error_pct']:+.2f} %" for k, v in turn.items()
            if k != "steady_diameter_m"))
    out = args.out
    print(f"results: {out / 'ship.yaml'}, {out / 'convergence.png'}, {out / 'report.json'}, "
          f"{out / 'report.md'}")
    return 0


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from trafficsim.diagnose import command
    from trafficsim.diagnose.report import parameter_text

    testing = args.self_test is not None
    for flag, given in (("--ship", args.ship is not None), ("--data", bool(args.data)),
                        ("--holdout", bool(args.holdout)), ("--effects", args.effects is not None),
                        ("--horizon-s", args.horizon_s is not None),
                        ("--dt-s", args.dt_s is not None), ("--refit", args.refit is not None)):
        _only_with(flag, given, not testing, "without --self-test (the self-test makes its "
                   "own ship and runs)")
    _only_with("--seed", args.seed is not None, testing, "with --self-test")
    if testing:
        from trafficsim.diagnose.selftest import confusion_text

        res = command.self_test(args.self_test, args.out, 0 if args.seed is None else args.seed,
                                progress=not args.no_progress)
        print(confusion_text(res))
        print(f"{res['n']} trials in {res['elapsed_s']:.1f} s")
        return 0
    if args.ship is None or not args.data or args.out is None:
        raise InputError("diagnose needs --ship, --data and --out (or --self-test N)",
                         key="--ship")
    rep = command.diagnose(args.ship, args.data, args.out, args.holdout, args.horizon_s,
                           args.dt_s, args.effects, args.refit, progress=not args.no_progress)
    print(rep["verdict"])
    for i, r in enumerate(rep["ranking"][:5], 1):
        par = parameter_text(r["parameters"])
        print(f"  {i}. {r['effect']}: held-out shrinkage {100 * r['shrinkage_holdout']:.0f} % "
              f"(train {100 * r['shrinkage_train']:.0f} %); {par}")
    if "confirmation" in rep:
        print(f"  {rep['confirmation']['text']}")
    print(f"results: {args.out / 'report.md'}, {args.out / 'report.json'} "
          f"({rep['elapsed_s']:.1f} s)")
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    from trafficsim.validate import validate_files

    return validate_files(args.files)


def _cmd_render(args: argparse.Namespace) -> int:
    from trafficsim.render.export import render_run

    done = render_run(args.run_dir, args.out, args.format, args.every_s, _frame_options(args),
                      _fps(args, args.format), progress=not args.no_progress)
    where = done.paths[0] if args.format != "png" else args.out
    print(f"{done.frames} frames in {done.seconds:.1f} s ({done.frames_per_s:.0f} frames/s): "
          f"{where}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from trafficsim.folders import refuse_other_results
    from trafficsim.render.report import write_report

    if args.out is not None:
        refuse_other_results(args.out, "report", "a report")
    rep = write_report(args.campaign_dir, args.out, args.worst, progress=not args.no_progress)
    print(f"report with {len(rep.worst)} worst encounters in {rep.seconds:.1f} s: {rep.path}")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from trafficsim.campaign.replay import replay_encounter

    summary = replay_encounter(args.campaign_dir, args.encounter, args.out,
                               args.record_every_s)
    print(f"{summary['scenario']} ({summary['encounter_type']}): {summary['n_ships']} ships, "
          f"{summary['duration_s']:g} s")
    for pair in summary["pairs"]:
        flag = "  COLLISION" if pair["collision"] else ""
        print(f"  {pair['ship_a']} - {pair['ship_b']}: min range {pair['min_range_m']:.0f} m "
              f"at t = {pair['t_min_range_s']:.0f} s{flag}")
    print(f"results: {args.out} (render it: trafficsim render {args.out} --format gif "
          f"--out {args.out / 'frames'})")
    return 0


def one_line(err: Exception) -> str:
    """An error's message on one line: an error listing several problems, one per line (a
    rules file's), gives its first and their count (``trafficsim validate`` lists all)."""
    first, *rest = str(err).splitlines() or [""]
    if not rest:
        return first
    return f"{first} (and {len(rest)} more error{'s' if len(rest) > 1 else ''}; " \
           "'trafficsim validate' lists them all)"


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except TrafficsimError as err:
        if isinstance(err, InputError):
            from trafficsim.io.yamlio import locate

            locate(err)  # (an error raised after its file was read has no line yet)
        print(f"trafficsim: error: {one_line(err)}", file=sys.stderr)
        return EXIT_USER_ERROR if isinstance(err, InputError) else 1
    except BrokenPipeError:  # output piped into a command that stopped reading
        sys.stderr.close()
        return 0
    except MemoryError:
        print(f"trafficsim: error: out of memory in '{args.command}' (fewer ships, a shorter "
              "run or a machine with more memory)", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as err:  # e.g. an --out folder that cannot be written
        where = f"{err.filename}: " if err.filename else ""
        print(f"trafficsim: error: {where}{err.strerror or err}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("trafficsim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
