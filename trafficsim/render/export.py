"""``trafficsim render`` (frames of a finished run) and ``trafficsim run --frames`` (frames
drawn while the run goes), as PNG frames, an animated GIF or an MP4."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.render.data import live_data, load_run
from trafficsim.render.frame import DEFAULT_OPTIONS, FrameOptions, Renderer
from trafficsim.render.writers import FORMATS, FrameWriter, open_writer

#: slowest frame rate (a GIF frame lasts at most 655.35 s; a frame every 100 s is the floor)
MIN_FPS = 0.01


@dataclass(frozen=True)
class Export:
    """What an export wrote."""

    paths: list[Path]
    frames: int
    seconds: float

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


def frame_stride(every_s: float | None, record_every_s: float, key: str = "--every-s",
                 duration_s: float | None = None) -> int:
    """Records between frames for a frame every ``every_s`` (None: every record).

    Raises:
        InputError: ``every_s`` is not a positive whole multiple of the record period, or is
            longer than the run (``duration_s``; a single frame would be drawn).
    """
    if every_s is None:
        return 1
    if duration_s is not None and every_s > max(duration_s, record_every_s) * (1.0 + 1e-9):
        raise InputError(f"expected at most the run's duration ({duration_s:g} s), got "
                         f"{every_s:g} s", key=key)
    ratio = every_s / record_every_s
    if not math.isfinite(ratio) or ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
        raise InputError(f"expected a whole multiple of the run's record period "
                         f"({record_every_s:g} s), got {every_s:g} s", key=key)
    return round(ratio)


def check_options(fmt: str, options: FrameOptions, fps: float) -> None:
    """Reject option combinations no writer can honour (one line each)."""
    if fmt not in FORMATS:
        raise InputError(f"expected one of {', '.join(FORMATS)}, got {fmt!r}", key="--format")
    w, h = options.size_px
    if fmt == "mp4" and (w % 2 or h % 2):
        raise InputError(f"MP4 frames need an even width and height, got {w}x{h} (multiples "
                         "of 16 suit every player)", key="--size")
    if not MIN_FPS <= fps <= 100.0:  # (a GIF holds a frame 655 s at most)
        raise InputError(f"expected {MIN_FPS:g} <= fps <= 100, got {fps:g}", key="--fps")


def _write_all(renderer: Renderer, writer: FrameWriter, records: range,
               progress: bool) -> list[Path]:
    from tqdm import tqdm

    try:
        for k in tqdm(records, unit="frame", disable=not progress, leave=False):
            writer.write(renderer.rgb(k))
    except BaseException:
        writer.abort()
        raise
    return writer.close()


def render_run(run_dir: str | Path, out_dir: str | Path, fmt: str = "png",
               every_s: float | None = None, options: FrameOptions = DEFAULT_OPTIONS,
               fps: float = 10.0, progress: bool = False, name: str | None = None) -> Export:
    """Frames of a run folder into ``out_dir``: ``frame_NNNNN.png`` files, or one
    ``NAME.gif`` / ``NAME.mp4`` (``NAME``: the run folder's name unless given).

    Raises:
        InputError: a missing or incomplete run folder, a bad option (names the flag).
    """
    check_options(fmt, options, fps)
    run_dir = Path(run_dir)
    data = load_run(run_dir)
    stride = frame_stride(every_s, data.record_every_s, duration_s=data.duration_s)
    if options.measurements and not np.isfinite(data.gnss_north_m).any():
        raise InputError(f"applies only to a run with GNSS fixes; {run_dir} has none (no ship "
                         "carries instruments)", key="--measurements")
    renderer = Renderer(data, options)
    t0 = time.perf_counter()
    writer = open_writer(fmt, Path(out_dir), name or run_dir.resolve().name, options.size_px,
                         options.dpi, fps)
    records = range(0, data.count, stride)
    paths = _write_all(renderer, writer, records, progress)
    return Export(paths, len(records), time.perf_counter() - t0)


def render_frame(run_dir: str | Path, path: str | Path, t_s: float,
                 options: FrameOptions = DEFAULT_OPTIONS, window_s: float | None = None
                 ) -> Path:
    """One PNG of a run folder at the record nearest ``t_s``; with ``window_s`` a fixed view
    fits the ships' positions within ``window_s`` of that time only (a close-up)."""
    from trafficsim.render.writers import write_png

    data = load_run(run_dir)
    t = data.t_s[: data.count]
    k = int(np.argmin(np.abs(t - t_s)))
    fit_to = None
    if window_s is not None:
        near = np.abs(t - t[k]) <= window_s
        fit_to = (data.north_m[: data.count][near], data.east_m[: data.count][near])
    renderer = Renderer(data, options, fit_to)
    write_png(Path(path), renderer.rgb(k), options.size_px, options.dpi)
    return Path(path)


def planned_points(sim: Any, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """North and east metres a fixed view fits for frames drawn while a run goes, before the
    tracks are known: the start positions, every route's waypoints, and where each ship without
    a route would be at the end of the run on its present course and speed."""
    from trafficsim.engine import earth_velocity
    from trafficsim.ships.base import EAST, NORTH

    b, x = sim.batch, sim.batch.x
    vel = earth_velocity(x, b.env)
    lone = b.n_waypoints == 0
    north = [x[NORTH], x[NORTH, lone] + vel[0, lone] * duration_s]
    east = [x[EAST], x[EAST, lone] + vel[1, lone] * duration_s]
    for k in np.flatnonzero(~lone):
        north.append(b.waypoints[k, : b.n_waypoints[k], 0])
        east.append(b.waypoints[k, : b.n_waypoints[k], 1])
    return np.concatenate(north), np.concatenate(east)


class LiveFrames:
    """The ``on_record`` hook of :func:`trafficsim.run.run_scenario` that draws a frame every
    ``every_s`` of simulated time as the run goes (into ``out_dir``, as :func:`render_run`).

    Raises (when built):
        InputError: a bad option, an unknown ship to follow, or ``every_s`` not a multiple of
            the scenario's record period.
    """

    def __init__(self, scenario_path: str | Path, out_dir: str | Path, fmt: str = "png",
                 every_s: float | None = None, options: FrameOptions = DEFAULT_OPTIONS,
                 fps: float = 10.0) -> None:
        from trafficsim.io.scenario import load_scenario
        from trafficsim.run import record_steps

        check_options(fmt, options, fps)
        scn = load_scenario(scenario_path)
        names = [ship.name for ship in scn.ships]
        if options.follow is not None and options.follow not in names:
            raise InputError(f"no ship {options.follow!r} in {scenario_path}; ships: "
                             f"{', '.join(names)}", key="--follow")
        self.record_every_s = record_steps(scn) * scn.dt_s
        self.stride = frame_stride(every_s, self.record_every_s, key="--frames-every-s",
                                   duration_s=scn.duration_s)
        self.name, self.duration_s = scn.name, scn.duration_s
        self.out_dir, self.fmt, self.options, self.fps = Path(out_dir), fmt, options, fps
        self.renderer: Renderer | None = None
        self.writer: FrameWriter | None = None
        self.frames = 0

    def __call__(self, rec: Any, sim: Any) -> None:
        if self.renderer is None:
            if self.options.measurements and sim.nav is None:
                raise InputError("applies only to a run with GNSS fixes; no ship of this "
                                 "scenario carries instruments", key="--measurements")
            data = live_data(rec, sim, self.name, self.record_every_s, self.duration_s)
            self.renderer = Renderer(data, self.options, planned_points(sim, self.duration_s))
            self.writer = open_writer(self.fmt, self.out_dir, self.name, self.options.size_px,
                                      self.options.dpi, self.fps)
        assert self.writer is not None
        self.renderer.data.count = rec.count
        k = rec.count - 1
        if k % self.stride == 0:
            self.writer.write(self.renderer.rgb(k))
            self.frames += 1

    def close(self) -> list[Path]:
        """Finish the files (after the run); the paths written."""
        return [] if self.writer is None else self.writer.close()

    def abort(self) -> None:
        """Drop an unfinished GIF or MP4 (the run failed)."""
        if self.writer is not None:
            self.writer.abort()
