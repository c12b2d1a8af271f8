"""Map projection of a frame: north/east metres to pixels, north up.

Pixel ``x`` grows to the east and ``y`` downwards (screen convention); the view's centre point
lies on the pixel corner ``(origin_x_px, origin_y_px)`` (the middle of the chart area, which
leaves room for the panel and the legend), and a point maps to the pixel ``floor(x), floor(y)``.
One scale for both axes, so hull outlines and domains keep their shape.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from trafficsim.units import NM

#: largest pixel coordinate handed to the drawing calls (far points are clipped to this)
CLIP_PX = 1.0e6


@dataclass(frozen=True)
class View:
    """A north-up view: ``m_per_px`` metres per pixel around a centre point, which is drawn
    at pixel ``(origin_x_px, origin_y_px)``."""

    width_px: int
    height_px: int
    centre_north_m: float
    centre_east_m: float
    m_per_px: float
    origin_x_px: float
    origin_y_px: float

    def to_px(self, north_m: np.ndarray, east_m: np.ndarray, clip: bool = True
              ) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (float) of points; any shape, NaN stays NaN. Each coordinate is
        clipped to +-:data:`CLIP_PX` (what pygame can take), which bends a line to a point
        beyond it; ``clip=False`` gives the exact coordinates, for a caller that clips its
        segments to the view itself."""
        x = (np.asarray(east_m, dtype=float) - self.centre_east_m) / self.m_per_px + \
            self.origin_x_px
        y = self.origin_y_px - (np.asarray(north_m, dtype=float) - self.centre_north_m) / \
            self.m_per_px
        if not clip:
            return x, y
        return np.clip(x, -CLIP_PX, CLIP_PX), np.clip(y, -CLIP_PX, CLIP_PX)

    def points(self, north_m: np.ndarray, east_m: np.ndarray) -> np.ndarray:
        """``(k, 2)`` int pixel points (x, y) of ``(k,)`` finite north/east arrays."""
        return pixel_points(*self.to_px(north_m, east_m))

    def to_m(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """North/east metres of pixel coordinates (the inverse of :meth:`to_px`)."""
        east = (np.asarray(x_px, dtype=float) - self.origin_x_px) * self.m_per_px
        north = (self.origin_y_px - np.asarray(y_px, dtype=float)) * self.m_per_px
        return north + self.centre_north_m, east + self.centre_east_m

    def centred_on(self, north_m: float, east_m: float) -> View:
        """The same scale and size centred elsewhere."""
        return replace(self, centre_north_m=float(north_m), centre_east_m=float(east_m))


def pixel_points(x_px: np.ndarray, y_px: np.ndarray) -> np.ndarray:
    """``(k, 2)`` int pixel points of ``(k,)`` float pixel coordinates (floored)."""
    return np.stack([np.floor(x_px), np.floor(y_px)], axis=-1).astype(np.int64)


Area = tuple[int, int, int, int]  # left, top, width, height in pixels


def fit(north_m: np.ndarray, east_m: np.ndarray, width_px: int, height_px: int,
        margin: float = 0.06, min_extent_m: float = NM, area: Area | None = None) -> View:
    """The view that shows every finite point inside the chart ``area`` (default: the whole
    frame) with ``margin`` (share of each side) left free.

    ``min_extent_m``: the smallest span shown (a ship alone or at rest is not blown up)."""
    left, top, w, h = area if area is not None else (0, 0, width_px, height_px)
    n = np.asarray(north_m, dtype=float).ravel()
    e = np.asarray(east_m, dtype=float).ravel()
    ok = np.isfinite(n) & np.isfinite(e)
    if not ok.any():
        n, e, ok = np.zeros(1), np.zeros(1), np.ones(1, dtype=bool)
    n, e = n[ok], e[ok]
    span_n = max(float(n.max() - n.min()), min_extent_m)
    span_e = max(float(e.max() - e.min()), min_extent_m)
    free = 1.0 - 2.0 * margin
    scale = max(span_e / (free * w), span_n / (free * h))
    return View(width_px, height_px, 0.5 * float(n.max() + n.min()),
                0.5 * float(e.max() + e.min()), scale, left + 0.5 * w, top + 0.5 * h)


def follow(range_m: float, width_px: int, height_px: int, area: Area | None = None) -> View:
    """A view ``range_m`` from its centre to the nearer edge of the chart ``area`` (centre
    point set per frame)."""
    left, top, w, h = area if area is not None else (0, 0, width_px, height_px)
    return View(width_px, height_px, 0.0, 0.0, range_m / (0.5 * min(w, h)), left + 0.5 * w,
                top + 0.5 * h)


def nice_length_m(m_per_px: float, target_px: float) -> tuple[float, str]:
    """A round length near ``target_px`` pixels for the scale bar, and its label
    (nautical miles from 0.1 NM up, metres below)."""
    want = m_per_px * target_px
    for nm in (50.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.5, 0.25, 0.1):
        if nm * NM <= want:
            return nm * NM, f"{nm:g} NM"
    for m in (100.0, 50.0, 20.0, 10.0, 5.0, 2.0, 1.0):
        if m <= want:
            return m, f"{m:g} m"
    return 1.0, "1 m"
