"""Frames to disk, streamed: each frame is encoded and written when it is drawn, so memory does
not grow with the number of frames.

* :class:`PngFrames`: one PNG per frame (``frame_00000.png`` ...), each written atomically, with
  the DPI in the file (``pHYs``), encoded by :func:`encode_png`;
* :class:`GifWriter`: one animated GIF. The frames share one fixed palette
  (:func:`trafficsim.render.style.gif_palette`, so colours do not flicker between frames; every
  colour of the style comes out exactly), are LZW-encoded one by one by Pillow and appended to
  the file (imageio's GIF writer keeps every frame in memory until it closes);
* :class:`Mp4Writer`: H.264 video through imageio's ffmpeg writer (imageio-ffmpeg ships the
  ffmpeg binary), frames piped to ffmpeg as they come.

A GIF or MP4 is written to a temporary file in the target folder and renamed into place when
it is complete: an interrupted export never leaves a truncated file under the final name.
"""

from __future__ import annotations

import functools
import os
import struct
import tempfile
import zlib
from pathlib import Path
from typing import IO, Protocol

import numpy as np

from trafficsim.io.results import atomic_write, plain_mode
from trafficsim.render.style import gif_palette

FORMATS = ("png", "gif", "mp4")


class FrameWriter(Protocol):
    def write(self, rgb: bytes) -> None:
        """Append one frame (packed RGB rows, top to bottom)."""
        ...

    def close(self) -> list[Path]:
        """Finish; return the files written."""
        ...

    def abort(self) -> None:
        """Drop an unfinished file."""
        ...


class PngFrames:
    """Numbered PNG files in a folder."""

    def __init__(self, out_dir: Path, size_px: tuple[int, int], dpi: float,
                 prefix: str = "frame", compress_level: int = 3) -> None:
        out_dir.mkdir(parents=True, exist_ok=True)
        self.out_dir, self.size, self.dpi = out_dir, size_px, dpi
        self.prefix, self.level = prefix, compress_level
        self.frames = 0

    def path(self, k: int) -> Path:
        return self.out_dir / f"{self.prefix}_{k:05d}.png"

    def write(self, rgb: bytes) -> None:
        write_png(self.path(self.frames), rgb, self.size, self.dpi, self.level)
        self.frames += 1

    def close(self) -> list[Path]:
        return [self.path(k) for k in range(self.frames)]

    def abort(self) -> None:
        pass  # every file written is complete


def encode_png(rgb: bytes, size_px: tuple[int, int], dpi: float, level: int = 3) -> bytes:
    """PNG bytes of packed RGB rows (W3C PNG specification, 2nd ed.: ``IHDR`` 8-bit truecolour,
    ``pHYs`` in pixels per metre, one ``IDAT``, ``IEND``).

    Every row gets filter type 0 (none): on these flat-coloured pictures zlib finds the long
    runs itself, and the bytes come out no larger than with Pillow's per-row adaptive filters
    at a quarter of the time (most of Pillow's time goes to trying the five filters)."""
    w, h = size_px
    rows = np.empty((h, 3 * w + 1), dtype=np.uint8)
    rows[:, 0] = 0
    rows[:, 1:] = np.frombuffer(rgb, dtype=np.uint8).reshape(h, 3 * w)
    per_m = round(dpi / 0.0254)
    return b"".join((b"\x89PNG\r\n\x1a\n",
                     _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)),
                     _chunk(b"pHYs", struct.pack(">IIB", per_m, per_m, 1)),
                     _chunk(b"IDAT", zlib.compress(rows.tobytes(), level)),
                     _chunk(b"IEND", b"")))


def _chunk(tag: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + tag + data
            + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))


def write_png(path: Path, rgb: bytes, size_px: tuple[int, int], dpi: float,
              level: int = 3) -> None:
    """One RGB image as a PNG file, atomically."""
    data = encode_png(rgb, size_px, dpi, level)
    atomic_write(path, lambda fh: fh.write(data))


class _TempTarget:
    """A temporary file next to ``path``, renamed over it by :meth:`commit`."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix,
                                   dir=path.parent)
        os.close(fd)
        self.tmp = Path(tmp)

    def commit(self) -> None:
        with open(self.tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        plain_mode(self.tmp)
        os.replace(self.tmp, self.path)

    def drop(self) -> None:
        self.tmp.unlink(missing_ok=True)


class PaletteMap:
    """RGB pixels to indices of a fixed palette through a table of every 24-bit colour: a
    colour of the palette maps to its own entry (exactly; Pillow's quantizer looks colours up
    at reduced precision and may pick a neighbour), any other colour to the entry nearest the
    centre of its 8 x 8 x 8 cell."""

    def __init__(self, palette: np.ndarray) -> None:
        cell = np.arange(32, dtype=np.int32) * 8 + 4
        centres = np.stack(np.meshgrid(cell, cell, cell, indexing="ij"), axis=-1).reshape(-1, 3)
        pal = palette.astype(np.int32)
        near = np.empty(centres.shape[0], dtype=np.uint8)
        for a in range(0, centres.shape[0], 4096):  # 4096 x 256 distances at a time
            d = ((centres[a:a + 4096, None, :] - pal[None, :, :]) ** 2).sum(axis=2)
            near[a:a + 4096] = np.argmin(d, axis=1)
        lut = near.reshape(32, 32, 32).repeat(8, axis=0).repeat(8, axis=1).repeat(8, axis=2)
        # entries later in the palette must not overwrite an earlier copy of the same colour
        for k in range(pal.shape[0] - 1, -1, -1):
            lut[pal[k, 0], pal[k, 1], pal[k, 2]] = k
        self._lut = lut.ravel()  # (2**24,) uint8, 16 MB

    def indices(self, rgb: bytes) -> np.ndarray:
        """``(n_pixels,)`` uint8 palette index of every pixel of packed RGB."""
        px = np.frombuffer(rgb, dtype=np.uint8).reshape(-1, 3).astype(np.int32)
        return self._lut[(px[:, 0] << 16) | (px[:, 1] << 8) | px[:, 2]]


@functools.cache
def _gif_map() -> PaletteMap:
    return PaletteMap(gif_palette())


class GifWriter:
    """An animated GIF (looping) at ``fps`` frames per second."""

    def __init__(self, path: Path, size_px: tuple[int, int], fps: float) -> None:
        self.target = _TempTarget(path)
        self.size = size_px
        self.delay_ms = max(10, round(100.0 / fps) * 10)  # GIF counts hundredths
        palette = gif_palette()
        self._map = _gif_map()
        self._fh: IO[bytes] = open(self.target.tmp, "wb")  # noqa: SIM115 (closed in close)
        w, h = size_px
        self._fh.write(b"GIF89a" + struct.pack("<HHBBB", w, h, 0xF7, 0, 0))  # 256-colour table
        self._fh.write(palette.tobytes())
        self._fh.write(b"!\xff\x0bNETSCAPE2.0\x03\x01\x00\x00\x00")  # loop forever
        self.frames = 0

    def write(self, rgb: bytes) -> None:
        from PIL import GifImagePlugin, Image

        image = Image.frombytes("P", self.size, self._map.indices(rgb).tobytes())
        for block in GifImagePlugin.getdata(image, duration=self.delay_ms):
            self._fh.write(block)
        self.frames += 1

    def close(self) -> list[Path]:
        self._fh.write(b";")
        self._fh.close()
        self.target.commit()
        return [self.target.path]

    def abort(self) -> None:
        self._fh.close()
        self.target.drop()


class Mp4Writer:
    """H.264 video (yuv420p, so width and height must be even) at ``fps`` frames per second."""

    def __init__(self, path: Path, size_px: tuple[int, int], fps: float, crf: int = 20) -> None:
        import imageio.v2 as iio

        self.target = _TempTarget(path)
        self.size = size_px
        self._writer = iio.get_writer(self.target.tmp, format="FFMPEG", mode="I", fps=fps,
                                      codec="libx264", pixelformat="yuv420p", quality=None,
                                      macro_block_size=2, ffmpeg_log_level="error",
                                      output_params=["-crf", str(crf)])
        self.frames = 0

    def write(self, rgb: bytes) -> None:
        w, h = self.size
        self._writer.append_data(np.frombuffer(rgb, dtype=np.uint8).reshape(h, w, 3))
        self.frames += 1

    def close(self) -> list[Path]:
        self._writer.close()
        self.target.commit()
        return [self.target.path]

    def abort(self) -> None:
        try:
            self._writer.close()
        finally:
            self.target.drop()


def open_writer(fmt: str, out_dir: Path, name: str, size_px: tuple[int, int], dpi: float,
                fps: float) -> FrameWriter:
    """The writer of ``fmt``: PNG frames in ``out_dir``, or ``out_dir/name.gif|mp4``."""
    if fmt == "png":
        return PngFrames(out_dir, size_px, dpi)
    if fmt == "gif":
        return GifWriter(out_dir / f"{name}.gif", size_px, fps)
    if fmt == "mp4":
        return Mp4Writer(out_dir / f"{name}.mp4", size_px, fps)
    raise ValueError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
