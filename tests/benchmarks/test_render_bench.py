"""Frames per second of ``trafficsim render`` at 960 x 720: drawing alone (fixed view and a view
that follows a ship) and drawing plus encoding (PNG, GIF, MP4), on three ships with estimated
tracks, GNSS fixes, domains and CPA vectors.

Run with ``make bench``; the figures printed go in the README.
"""

from pathlib import Path

import pytest

from tests.render.conftest import Ship, write_run
from trafficsim.render.data import load_run
from trafficsim.render.frame import FrameOptions, Renderer
from trafficsim.render.writers import open_writer

FRAMES = 100
SIZE = (960, 720)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    ships = [Ship("own", 0.0, 0.0, 20.0, speed_kn=14.0, length_m=200.0, beam_m=32.0),
             Ship("west", 1500.0, -3000.0, 100.0, speed_kn=12.0),
             Ship("north", 5000.0, 800.0, 190.0, speed_kn=10.0, length_m=300.0, beam_m=50.0)]
    return write_run(tmp_path_factory.mktemp("bench") / "run", ships, FRAMES, every_s=5.0,
                     turn_degps=0.05)


@pytest.mark.parametrize("follow", [None, "own"])
def test_draw(benchmark, run, follow):
    data = load_run(run)
    options = FrameOptions(size_px=SIZE, follow=follow, measurements=True)

    def frames(renderer):
        for k in range(FRAMES):
            renderer.draw(k)

    benchmark.pedantic(frames, setup=lambda: ((Renderer(data, options),), {}), rounds=3,
                       warmup_rounds=1)
    _report(benchmark, f"draw, {'follow' if follow else 'fixed'} view")


@pytest.mark.parametrize("fmt", ["png", "gif", "mp4"])
def test_draw_and_encode(benchmark, run, tmp_path, fmt):
    data = load_run(run)
    options = FrameOptions(size_px=SIZE, measurements=True)

    def frames(renderer, writer):
        for k in range(FRAMES):
            writer.write(renderer.rgb(k))
        writer.close()

    def setup():
        return (Renderer(data, options),
                open_writer(fmt, tmp_path / fmt, "bench", SIZE, 96.0, 10.0)), {}

    benchmark.pedantic(frames, setup=setup, rounds=3, warmup_rounds=1)
    _report(benchmark, f"draw + {fmt}")


def _report(benchmark, what: str) -> None:
    if benchmark.stats is not None:  # None under --benchmark-disable
        fps = FRAMES / benchmark.stats.stats.mean
        benchmark.extra_info["frames_per_s"] = fps
        print(f"\n{what}: {fps:,.0f} frames/s at {SIZE[0]}x{SIZE[1]}")
