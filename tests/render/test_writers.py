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


def _parse_png(data: bytes) -> dict:
    """Chunks of a PNG by tag, each checked against its CRC."""
    import struct
    import zlib

    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, pos = {}, 8
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(tag + body) & 0xFFFFFFFF
        chunks.setdefault(tag, []).append(body)
        pos += 12 + length
    return chunks


def test_encode_png_by_the_specification():
    """IHDR 5 x 3, 8-bit truecolour; pHYs 96 DPI = 96 / 0.0254 = 3779.5 -> 3780 px/m, unit
    metre; the IDAT inflates to each row's filter byte 0 followed by its RGB bytes; IEND
    last and empty; a non-square picture so width and height cannot be swapped unseen."""
    import struct
    import zlib

    from trafficsim.render.writers import encode_png

    rgb = np.random.default_rng(1).integers(0, 256, (3, 5, 3), dtype=np.uint8)
    chunks = _parse_png(encode_png(rgb.tobytes(), (5, 3), 96.0))
    assert list(chunks) == [b"IHDR", b"pHYs", b"IDAT", b"IEND"]
    assert struct.unpack(">IIBBBBB", chunks[b"IHDR"][0]) == (5, 3, 8, 2, 0, 0, 0)
    assert struct.unpack(">IIB", chunks[b"pHYs"][0]) == (3780, 3780, 1)
    raw = np.frombuffer(zlib.decompress(chunks[b"IDAT"][0]), dtype=np.uint8).reshape(3, 16)
    assert raw[:, 0].tolist() == [0, 0, 0]
    np.testing.assert_array_equal(raw[:, 1:].reshape(3, 5, 3), rgb)
    assert chunks[b"IEND"] == [b""]


def test_png_frames_are_numbered_complete_files(tmp_path):
    """Frames k = 0, 1, 2 of a 7 x 4 picture land in frame_00000.png ... in order, decode to
    their pixels, and no temporary file is left."""
    size = (7, 4)
    frames = [np.full((4, 7, 3), k * 40, dtype=np.uint8) for k in range(3)]
    frames[1][2, 5] = (255, 0, 0)
    writer = PngFrames(tmp_path / "out", size, 150.0)
    for f in frames:
        writer.write(f.tobytes())
    paths = writer.close()
    assert [p.name for p in paths] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    for p, f in zip(paths, frames, strict=True):
        with Image.open(p) as image:
            assert image.size == size and image.mode == "RGB"
            np.testing.assert_array_equal(np.asarray(image), f)
            assert image.info["dpi"] == pytest.approx((150, 150), abs=0.05)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [p.name for p in paths]


@pytest.mark.parametrize(("fps", "delay_ms"), [(10.0, 100), (3.0, 330), (30.0, 30),
                                               (200.0, 10)])
def test_gif_frames_sizes_and_delays(tmp_path, fps, delay_ms):
    """GIF delays count hundredths of a second: 1 / fps rounded to 10 ms, at least 10 ms;
    every frame written comes back at the size given, the palette colours exact."""
    size = (6, 4)
    pal = st.gif_palette()
    rng = np.random.default_rng(2)
    frames = [pal[rng.integers(0, 256, size[0] * size[1])].reshape(4, 6, 3) for _ in range(3)]
    writer = GifWriter(tmp_path / "a.gif", size, fps)
    for f in frames:
        writer.write(f.tobytes())
    assert writer.close() == [tmp_path / "a.gif"]
    back = iio.imread(tmp_path / "a.gif", index=None)
    assert back.shape == (3, 4, 6, 3)
    for k in range(3):
        np.testing.assert_array_equal(back[k], frames[k])
    with Image.open(tmp_path / "a.gif") as image:
        assert image.n_frames == 3 and image.info["duration"] == delay_ms


@pytest.mark.parametrize("kind", ["gif", "mp4"])
def test_gif_and_mp4_appear_only_when_complete(tmp_path, kind):
    """Until close, the final name does not exist (frames go to a hidden temporary file in
    the same folder); after close only the final file is there, with the permissions a
    plain open() would give (0666 less the umask), not mkstemp's 0600."""
    size = (16, 8)
    target = tmp_path / f"v.{kind}"
    writer = (GifWriter(target, size, 5.0) if kind == "gif"
              else Mp4Writer(target, size, 5.0))
    for k in range(4):
        writer.write(bytes([k * 60]) * (16 * 8 * 3))
    assert not target.exists()
    assert [p.name.startswith(".v.") for p in tmp_path.iterdir()] == [True]
    writer.close()
    assert list(tmp_path.iterdir()) == [target]
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask
    if kind == "mp4":
        video = _ffmpeg_frames(target, size)
        assert len(video) == 4
        means = [float(f.mean()) for f in video]
        assert means == pytest.approx([0.0, 60.0, 120.0, 180.0], abs=3.0)


def test_palette_map_agrees_with_brute_force():
    """A palette colour maps to its first entry exactly; any other colour to the entry nearest
    (squared RGB distance, first on ties) the centre of its 8 x 8 x 8 cell."""
    from trafficsim.render.writers import PaletteMap

    rng = np.random.default_rng(3)
    pal = rng.integers(0, 256, (256, 3)).astype(np.uint8)
    pal[200] = pal[10]  # a duplicate: the earlier entry wins
    pmap = PaletteMap(pal)
    assert pmap.indices(pal.tobytes()).tolist()[:12] == list(range(12))
    assert pmap.indices(pal[200].tobytes()).tolist() == [10]
    colours = rng.integers(0, 256, (500, 3)).astype(np.uint8)
    centre = (colours.astype(int) // 8) * 8 + 4
    d = ((centre[:, None, :] - pal[None, :, :].astype(int)) ** 2).sum(axis=2)
    expected = np.argmin(d, axis=1)
    exact = {tuple(c): i for i, c in reversed(list(enumerate(pal.tolist())))}
    expected = [exact.get(tuple(c), e) for c, e in zip(colours.tolist(), expected, strict=True)]
    assert pmap.indices(colours.tobytes()).tolist() == expected


def test_open_writer_kinds(tmp_path):
    from trafficsim.render.writers import open_writer

    assert isinstance(open_writer("png", tmp_path / "p", "x", (4, 2), 96.0, 5.0), PngFrames)
    gif = open_writer("gif", tmp_path, "x", (4, 2), 96.0, 5.0)
    assert isinstance(gif, GifWriter) and gif.target.path == tmp_path / "x.gif"
    gif.abort()
    with pytest.raises(ValueError, match="unknown format 'bmp'"):
        open_writer("bmp", tmp_path, "x", (4, 2), 96.0, 5.0)
    assert list(tmp_path.iterdir()) == [tmp_path / "p"]


@pytest.mark.parametrize(("fps", "n"), [(4.0, 5), (3.0, 3), (0.5, 2)])
def test_gif_plays_for_frames_times_the_delay(tmp_path, fps, n):
    """A GIF of ``n`` frames lasts ``n`` times its rounded delay (1 / fps in hundredths):
    4 fps 250 ms, 3 fps 330 ms, 0.5 fps 2000 ms; every frame keeps the size (9 x 5)."""
    size = (9, 5)
    writer = GifWriter(tmp_path / "d.gif", size, fps)
    for k in range(n):
        writer.write(bytes(st.ship_colour(k)) * (9 * 5))
    writer.close()
    delay = {4.0: 250, 3.0: 330, 0.5: 2000}[fps]
    with Image.open(tmp_path / "d.gif") as image:
        assert image.n_frames == n
        total = 0
        for k in range(n):
            image.seek(k)
            assert image.size == size
            assert image.convert("RGB").getpixel((4, 2)) == st.ship_colour(k)
            total += image.info["duration"]
    assert total == n * delay


def test_mp4_has_the_frames_size_and_duration_asked(tmp_path):
    """Six 32 x 16 frames at 12 fps: 0.5 s of video, 12 fps, six frames read back."""
    import imageio_ffmpeg

    writer = Mp4Writer(tmp_path / "v.mp4", (32, 16), 12.0)
    for k in range(6):
        writer.write(bytes([40 * k]) * (32 * 16 * 3))
    assert writer.close() == [tmp_path / "v.mp4"]
    reader = imageio_ffmpeg.read_frames(str(tmp_path / "v.mp4"))
    meta = next(reader)
    assert tuple(meta["size"]) == (32, 16) and meta["fps"] == pytest.approx(12.0)
    assert meta["duration"] == pytest.approx(0.5, abs=0.09)
    frames = [np.frombuffer(f, dtype=np.uint8) for f in reader]
    assert len(frames) == 6
    assert [float(f.mean()) for f in frames] == pytest.approx([0, 40, 80, 120, 160, 200],
                                                              abs=3.0)


def test_write_png_replaces_a_file_whole_and_leaves_it_when_encoding_fails(tmp_path):
    """Writing over an existing PNG gives the new picture and no temporary file; pixels of the
    wrong length fail before anything is written, so the old picture stays."""
    path = tmp_path / "f.png"
    first = np.full((2, 3, 3), 10, dtype=np.uint8)
    second = np.full((2, 3, 3), 200, dtype=np.uint8)
    write_png(path, first.tobytes(), (3, 2), 96.0)
    write_png(path, second.tobytes(), (3, 2), 96.0)
    with Image.open(path) as image:
        np.testing.assert_array_equal(np.asarray(image), second)
    with pytest.raises(ValueError):
        write_png(path, bytes(5), (3, 2), 96.0)
    with Image.open(path) as image:
        np.testing.assert_array_equal(np.asarray(image), second)
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]


def test_png_compression_levels_change_size_not_pixels():
    """Levels 0 and 9 give the same decoded rows; level 0 stores them uncompressed (larger)."""
    from trafficsim.render.writers import encode_png

    rgb = np.zeros((40, 50, 3), dtype=np.uint8)
    rgb[10:20, 5:45] = st.INK
    fast, small = (encode_png(rgb.tobytes(), (50, 40), 96.0, level) for level in (0, 9))
    assert len(fast) > 40 * (3 * 50 + 1) > len(small)
    import io

    for data in (fast, small):
        with Image.open(io.BytesIO(data)) as image:
            np.testing.assert_array_equal(np.asarray(image), rgb)


def test_png_frames_get_the_permissions_of_a_plain_open(tmp_path):
    """PNG frames, like the GIF and MP4 (``_TempTarget.commit``), are 0666 less the umask, so
    other users (a web server showing a report) can read them."""
    umask = os.umask(0)
    os.umask(umask)
    writer = PngFrames(tmp_path, (2, 2), 96.0)
    writer.write(bytes(12))
    (path,) = writer.close()
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


@pytest.mark.parametrize("kind", ["gif", "mp4"])
def test_aborting_before_any_frame_leaves_nothing(tmp_path, kind):
    """A writer opened and aborted at once (the first frame failed to draw) removes its
    temporary file."""
    writer = (GifWriter(tmp_path / "e.gif", (8, 8), 5.0) if kind == "gif"
              else Mp4Writer(tmp_path / "e.mp4", (8, 8), 5.0))
    writer.abort()
    assert list(tmp_path.iterdir()) == []
