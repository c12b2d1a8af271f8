"""PNG frames, GIF and MP4 on disk: readable, the right frames, DPI in the PNGs, fixed palette
colours kept exactly in the GIF, nothing half-written, and memory flat over 1,000 frames."""

import gc
import os
import tracemalloc
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from tests.render.conftest import Ship
from trafficsim.render import style as st
from trafficsim.render.data import load_run
from trafficsim.render.export import render_run
from trafficsim.render.frame import FrameOptions, Renderer
from trafficsim.render.writers import GifWriter, Mp4Writer, PngFrames, write_png

SMALL = FrameOptions(size_px=(320, 240), dpi=72.0)


def _ships():
    return [Ship("a", 0.0, 0.0, 45.0, speed_kn=15.0, length_m=300.0, beam_m=50.0),
            Ship("b", 3000.0, 0.0, 135.0, speed_kn=15.0, length_m=300.0, beam_m=50.0)]


def test_png_frames_hold_the_pixels_and_the_dpi(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 12)
    done = render_run(run, tmp_path / "png", "png", every_s=15.0, options=SMALL)
    assert done.frames == 4 and [p.name for p in done.paths] == [
        f"frame_0000{k}.png" for k in range(4)]
    renderer = Renderer(load_run(run), SMALL)
    for k, path in enumerate(done.paths):
        with Image.open(path) as image:
            assert image.size == (320, 240)
            assert image.info["dpi"] == pytest.approx((72, 72), abs=0.05)  # stored per metre
            np.testing.assert_array_equal(np.asarray(image.convert("RGB")),
                                          renderer.array(3 * k))
    assert not [p for p in (tmp_path / "png").iterdir() if p.name.startswith(".")]


def test_gif_keeps_the_style_colours_and_is_the_same_every_time(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 20)
    one = render_run(run, tmp_path / "one", "gif", options=SMALL, fps=5.0, name="enc")
    two = render_run(run, tmp_path / "two", "gif", options=SMALL, fps=5.0, name="enc")
    assert one.paths == [tmp_path / "one" / "enc.gif"] and one.frames == 20
    assert one.paths[0].read_bytes() == two.paths[0].read_bytes()
    frames = iio.imread(one.paths[0], index=None)
    assert frames.shape == (20, 240, 320, 3)
    with Image.open(one.paths[0]) as image:
        assert image.info["duration"] == 200 and image.info["loop"] == 0
    renderer = Renderer(load_run(run), SMALL)
    for k in (0, 19):
        exact = renderer.array(k)
        palette_colours = {tuple(c) for c in st.gif_palette().tolist()}
        held = np.array([tuple(p) in palette_colours for p in exact.reshape(-1, 3).tolist()])
        gif = frames[k].reshape(-1, 3)
        # every pixel drawn in a style colour comes back exactly (text blends nearly)
        np.testing.assert_array_equal(gif[held], exact.reshape(-1, 3)[held])
        assert held.mean() > 0.9


def test_mp4_plays_the_frames(synthetic_run, tmp_path):
    run = synthetic_run(_ships(), 16)
    done = render_run(run, tmp_path, "mp4", every_s=10.0, options=SMALL, fps=8.0)
    video = iio.imread(done.paths[0], plugin="pyav") if _has_pyav() else _ffmpeg_frames(
        done.paths[0], (320, 240))
    assert len(video) == 8 and video[0].shape == (240, 320, 3)
    renderer = Renderer(load_run(run), SMALL)
    for k in (0, 7):  # lossy: close, not equal
        assert np.abs(video[k].astype(float) - renderer.array(2 * k)).mean() < 6.0


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


def _ffmpeg_frames(path: Path, size: tuple[int, int]) -> list[np.ndarray]:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert tuple(meta["size"]) == size
    return [np.frombuffer(f, dtype=np.uint8).reshape(size[1], size[0], 3) for f in reader]


def test_an_unfinished_gif_or_mp4_leaves_nothing_behind(tmp_path):
    rgb = bytes(320 * 240 * 3)
    for writer in (GifWriter(tmp_path / "x.gif", (320, 240), 10.0),
                   Mp4Writer(tmp_path / "x.mp4", (320, 240), 10.0)):
        writer.write(rgb)
        writer.abort()
    assert list(tmp_path.iterdir()) == []
    write_png(tmp_path / "p.png", rgb, (320, 240), 96.0)
    assert os.stat(tmp_path / "p.png").st_size > 0


def _rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.parametrize("kind", ["gif", "png"])
def test_a_thousand_frames_do_not_grow_memory(synthetic_run, tmp_path, kind):
    size = (320, 240)
    run = synthetic_run(_ships(), 1000, every_s=2.0, turn_degps=0.1)
    renderer = Renderer(load_run(run), FrameOptions(size_px=size, measurements=True))
    writer = (GifWriter(tmp_path / "m.gif", size, 25.0) if kind == "gif"
              else PngFrames(tmp_path / "png", size, 96.0))
    rss = []
    tracemalloc.start()
    try:
        for k in range(1000):
            writer.write(renderer.rgb(k))
            if k in (299, 649):  # after the caches (recent text, free lists) filled, and later
                gc.collect()  # Pillow's GIF encoder leaves a small class per call to the GC
                rss.append(_rss_bytes())
                if k == 299:
                    py0 = tracemalloc.get_traced_memory()[0]
        gc.collect()
        rss.append(_rss_bytes())
        py1 = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    writer.close()
    # a leak grows memory in both halves of the last 700 frames: keeping even the encoded GIF
    # data (about 5 kB a frame here) would add 1.9 MB to each; the allocator may take one
    # step of its own (2 MiB seen) in one half, so the smaller half's growth is the test
    halves = (rss[1] - rss[0], rss[2] - rss[1])
    assert min(halves) < 1_000_000, rss
    assert max(halves) < 3 * 2**20, rss
    assert py1 - py0 < 150_000, (py0, py1)  # under 215 bytes a frame
    if kind == "gif":
        assert len(iio.imread(tmp_path / "m.gif", index=None)) == 1000
    else:
        assert len(list((tmp_path / "png").glob("frame_*.png"))) == 1000
