"""The layers of a frame, one function each, drawn with pygame in this order: routes, tracks
(true, estimated, GNSS fixes), ship domains, CPA vectors and ranges, hulls with speed vectors,
other ships' tracks as the focus ship holds them, labels, then the parts that do not move
(legend, scale bar, north arrow) and the panel (time, decisions, collisions).

Pixel transforms are numpy over all points of a layer at once; only the drawing calls loop.
"""

from __future__ import annotations

import itertools
import math
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import numpy as np

from trafficsim.colregs import domains
from trafficsim.geometry import cpa, hull_outlines
from trafficsim.render import style as st
from trafficsim.render.data import RunData
from trafficsim.render.view import CLIP_PX, View, nice_length_m, pixel_points
from trafficsim.units import NM

#: bearings at which a ship domain's boundary is drawn
DOMAIN_BEARINGS = np.radians(np.arange(0.0, 360.0, 5.0))
SPEED_VECTOR_S = 360.0  # speed vectors show 6 minutes of travel, as on a radar display
CPA_HORIZON_S = 1800.0  # CPA vectors of pairs that close within 30 minutes
CPA_NEAR_M = 800.0  # near-miss range: the CPA vector turns red inside it
CPA_SHOWN_M = 2.0 * NM  # CPA vectors of pairs passing closer than this
MAX_CPA_PAIRS = 3  # at most this many CPA vectors (smallest CPA first)
RANGE_LABEL_PX = 80.0  # the present range is labelled when its line is at least this long
SMALL_HULL_PX = 8.0  # hulls shorter than this get a ring so the ship stays visible


class Text:
    """Fonts at the style's DPI and a small cache of recently rendered strings (names, roles and
    legend entries come back frame after frame; times and distances mostly do not)."""

    CACHE = 256

    def __init__(self, pg: Any, style: st.Style) -> None:
        # pygame's built-in font draws at about 0.69 of the requested size
        self.pg = pg
        self.fonts = {"small": pg.font.Font(None, round(style.font_px(7.5) / 0.6875)),
                      "normal": pg.font.Font(None, round(style.font_px(9) / 0.6875))}
        self._cache: OrderedDict[tuple, Any] = OrderedDict()

    def render(self, text: str, colour: st.Colour, size: str = "normal",
               background: st.Colour | None = None) -> Any:
        key = (text, colour, size, background)
        surf = self._cache.get(key)
        if surf is None:
            surf = self.fonts[size].render(text, True, colour, background)
            self._cache[key] = surf
            if len(self._cache) > self.CACHE:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        return surf

    def height(self, size: str = "normal") -> int:
        return self.fonts[size].get_linesize()


def _clip(p0: np.ndarray, p1: np.ndarray, w: float, h: float, pad: float
          ) -> tuple[float, float] | None:
    """Parameters ``(t0, t1)`` of the part of segment ``p0 -> p1`` inside the padded view
    (Liang-Barsky), or None."""
    d = p1 - p0
    t0, t1 = 0.0, 1.0
    for p, q in ((-d[0], p0[0] + pad), (d[0], w + pad - p0[0]), (-d[1], p0[1] + pad),
                 (d[1], h + pad - p0[1])):
        if p == 0.0:
            if q < 0.0:
                return None
            continue
        r = q / p
        if p < 0.0:
            t0 = max(t0, r)
        else:
            t1 = min(t1, r)
        if t0 > t1:
            return None
    return t0, t1


def dashed_line(pg: Any, surf: Any, colour: st.Colour, p0: Sequence[float],
                p1: Sequence[float], dash_px: float, width: int = 1) -> None:
    """A dashed line; dashes keep their place along the segment when it is clipped."""
    a, b = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    w, h = surf.get_size()
    span = _clip(a, b, w, h, 2.0 * dash_px)
    length = float(np.hypot(*(b - a)))
    if span is None or length == 0.0:
        return
    first = math.floor(span[0] * length / (2.0 * dash_px))
    starts = np.arange(first * 2.0 * dash_px, span[1] * length, 2.0 * dash_px)
    ends = np.minimum(starts + dash_px, length)
    u = (b - a) / length
    for s, e in zip((a + starts[:, None] * u).tolist(), (a + ends[:, None] * u).tolist(),
                    strict=True):
        pg.draw.line(surf, colour, s, e, width)


def draw_routes(pg: Any, surf: Any, view: View, style: st.Style, data: RunData) -> None:
    """Each ship's planned route from its start point through its waypoints (dashed), with a
    ring at every waypoint."""
    dash, ring = style.px(6), style.px(3)
    for k in range(data.ships.n):
        route = data.ships.routes[k]
        if route.shape[0] == 0:
            continue
        north = np.concatenate([[data.north_m[0, k]], route[:, 0]])
        east = np.concatenate([[data.east_m[0, k]], route[:, 1]])
        x, y = view.to_px(north, east, clip=False)  # (each leg is clipped to the view)
        for j in range(len(x) - 1):
            dashed_line(pg, surf, st.ROUTE, (x[j], y[j]), (x[j + 1], y[j + 1]), dash)
        for px, py in zip(x[1:].tolist(), y[1:].tolist(), strict=True):
            if -ring <= px <= surf.get_width() + ring and -ring <= py <= surf.get_height() + ring:
                pg.draw.circle(surf, st.ROUTE, (px, py), ring, 1)


Path = tuple[list, list | None]  # a polyline's int pixel points, or its clipped segments


def _path(view: View, north_m: np.ndarray, east_m: np.ndarray, w: int, h: int) -> Path:
    """A track as int pixel points (:meth:`View.points`) or, when a point lies beyond
    :data:`CLIP_PX` (where clipping each coordinate would bend the line), each segment clipped
    to the view instead (:func:`_clip`; None for a segment wholly outside): the line keeps its
    bearing however far off its ends lie."""
    x, y = view.to_px(north_m, east_m, clip=False)
    if x.size == 0 or not max(np.abs(x).max(), np.abs(y).max()) > CLIP_PX:
        return pixel_points(x, y).tolist(), None  # (within CLIP_PX: View.points' points)
    ends = np.stack([x, y], axis=-1)
    segments: list = []
    for a, b in itertools.pairwise(ends):
        span = _clip(a, b, w, h, 1.0)
        if span is None:
            segments.append(None)
            continue
        p0, p1 = (np.floor(a + t * (b - a)).astype(np.int64).tolist() for t in span)
        segments.append((p0, p1))
    return [], segments


def _draw_path(pg: Any, surf: Any, colour: st.Colour, path: Path, width: int,
               segment: int | None = None) -> None:
    """The whole polyline ``path`` (:func:`_path`), or only its ``segment`` (into point
    ``segment + 1``)."""
    points, segments = path
    if segments is None:
        if segment is None:
            pg.draw.lines(surf, colour, False, points, width)
        else:
            pg.draw.line(surf, colour, points[segment], points[segment + 1], width)
        return
    for piece in segments if segment is None else segments[segment:segment + 1]:
        if piece is not None:
            pg.draw.line(surf, colour, piece[0], piece[1], width)


def _dots(pg: Any, surf: Any, pts: np.ndarray, colour: st.Colour, size: int) -> None:
    """Square dots of ``size`` pixels at ``(k, 2)`` int pixel points, set through a numpy
    view of the surface (one vectorised write instead of a call per dot)."""
    w, h = surf.get_size()
    offs = np.arange(size) - size // 2
    xs = (pts[:, 0, None, None] + offs[None, :, None]).repeat(size, axis=2).ravel()
    ys = (pts[:, 1, None, None] + offs[None, None, :]).repeat(size, axis=1).ravel()
    keep = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
    if keep.any():
        pixels = pg.surfarray.pixels3d(surf)
        pixels[xs[keep], ys[keep]] = colour
        del pixels  # unlocks the surface


def draw_tracks(pg: Any, surf: Any, view: View, style: st.Style, data: RunData, k0: int,
                k1: int, measurements: bool, stepwise: bool = False) -> None:
    """Records ``k0 .. k1`` (inclusive) of every ship's true track, its estimated track (ships
    with a filter) and, with ``measurements``, its valid GNSS fixes.

    ``stepwise``: draw record by record (each ship's segment into the record and its fix, then
    the next record), so that drawing ``0 .. k`` at once or in consecutive pieces ``0 .. j``,
    ``j .. k`` runs the same drawing calls in the same order and gives the same pixels; a fixed
    view relies on it to add each frame's new records to a kept surface. Otherwise each layer
    is one polyline per ship (faster)."""
    rows = slice(k0, k1 + 1)
    n = data.ships.n
    width, dot = style.px(2), style.px(2)
    w, h = surf.get_size()
    true = [_path(view, data.north_m[rows, j], data.east_m[rows, j], w, h) for j in range(n)]
    est = [_path(view, data.est_north_m[rows, j], data.est_east_m[rows, j], w, h)
           if data.has_estimate[j] else None for j in range(n)]
    fixes = []
    for j in range(n):
        if not measurements:
            fixes.append(None)
            continue
        ok = ((data.gnss_valid[rows, j] == 1) & np.isfinite(data.gnss_north_m[rows, j])
              & np.isfinite(data.gnss_east_m[rows, j]))
        pts = np.zeros((ok.shape[0], 2), dtype=np.int64)
        pts[ok] = view.points(data.gnss_north_m[rows, j][ok], data.gnss_east_m[rows, j][ok])
        fixes.append((ok, pts))
    if not stepwise:
        for j in range(n):
            if k1 > k0:
                if est[j] is not None:
                    _draw_path(pg, surf, st.estimate_colour(j), est[j], 1)
                _draw_path(pg, surf, st.ship_colour(j), true[j], width)
            if fixes[j] is not None and fixes[j][0].any():
                _dots(pg, surf, fixes[j][1][fixes[j][0]], st.GNSS, dot)
        return
    half = dot // 2
    # record k0 itself was drawn by the piece before this one (unless it is the first record)
    for r in range(0 if k0 == 0 else 1, k1 - k0 + 1):
        for j in range(n):
            if r > 0:
                if est[j] is not None:
                    _draw_path(pg, surf, st.estimate_colour(j), est[j], 1, r - 1)
                _draw_path(pg, surf, st.ship_colour(j), true[j], width, r - 1)
            if fixes[j] is not None and fixes[j][0][r]:
                x, y = fixes[j][1][r]
                pg.draw.rect(surf, st.GNSS, (x - half, y - half, dot, dot))


def draw_domains(pg: Any, surf: Any, view: View, style: st.Style, data: RunData, k: int
                 ) -> None:
    """Every ship's domain (the run's domain model, sized by its length and speed through the
    water; Coldwell's head-on and crossing shape, as the domain-violation metric uses) at
    record ``k``, turned with the ship's heading."""
    n_ships, nb = data.ships.n, DOMAIN_BEARINGS.shape[0]
    bearing = np.tile(DOMAIN_BEARINGS, n_ships)
    r = domains.boundary_distance_m(data.domain, bearing, np.repeat(data.ships.length_m, nb),
                                    np.repeat(np.maximum(data.u_mps[k], 0.0), nb))
    psi = np.repeat(data.psi_rad[k], nb) + bearing
    north = np.repeat(data.north_m[k], nb) + r * np.cos(psi)
    east = np.repeat(data.east_m[k], nb) + r * np.sin(psi)
    pts = view.points(north, east).reshape(n_ships, nb, 2)
    for s in range(n_ships):
        pg.draw.polygon(surf, st.domain_colour(s), pts[s].tolist(), style.px(1))


def cpa_pairs(data: RunData, k: int) -> list[tuple[int, int, float, float]]:
    """Pairs closing within :data:`CPA_HORIZON_S` to a CPA under :data:`CPA_SHOWN_M` at record
    ``k`` on straight tracks, as ``(i, j, dcpa_m, tcpa_s)``, smallest CPA first (at most
    :data:`MAX_CPA_PAIRS`)."""
    n = data.ships.n
    if n < 2:
        return []
    i, j = np.triu_indices(n, k=1)
    dn, de = data.north_m[k, j] - data.north_m[k, i], data.east_m[k, j] - data.east_m[k, i]
    dvn, dve = data.vn_mps[k, j] - data.vn_mps[k, i], data.ve_mps[k, j] - data.ve_mps[k, i]
    dcpa, tcpa = cpa(dn, de, dvn, dve)
    keep = np.flatnonzero((tcpa > 0.0) & (tcpa <= CPA_HORIZON_S) & (dcpa < CPA_SHOWN_M))
    keep = keep[np.argsort(dcpa[keep], kind="stable")][:MAX_CPA_PAIRS]
    return [(int(i[p]), int(j[p]), float(dcpa[p]), float(tcpa[p])) for p in keep]


def draw_cpa(pg: Any, surf: Any, view: View, style: st.Style, text: Text, data: RunData,
             k: int) -> None:
    """For each closing pair: the present range (thin line, labelled), where each ship will be
    at the closest point of approach (dashed), and the CPA vector between those points,
    labelled with its distance and time (red inside the near-miss range)."""
    dash = style.px(4)
    for i, j, dcpa, tcpa in cpa_pairs(data, k):
        n0 = data.north_m[k, [i, j]]
        e0 = data.east_m[k, [i, j]]
        n1 = n0 + data.vn_mps[k, [i, j]] * tcpa
        e1 = e0 + data.ve_mps[k, [i, j]] * tcpa
        x0, y0 = view.to_px(n0, e0)
        x1, y1 = view.to_px(n1, e1)
        colour = st.CPA_NEAR if dcpa < CPA_NEAR_M else st.CPA_FAR
        pg.draw.line(surf, st.FAINT, (x0[0], y0[0]), (x0[1], y0[1]), 1)
        if math.hypot(x0[1] - x0[0], y0[1] - y0[0]) >= RANGE_LABEL_PX:
            rng = math.hypot(n0[1] - n0[0], e0[1] - e0[0])
            label = text.render(f"{rng / NM:.2f} NM", st.FAINT, "small")
            surf.blit(label, (0.5 * (x0[0] + x0[1]) - label.get_width() - style.px(4),
                              0.5 * (y0[0] + y0[1])))
        for s in range(2):
            dashed_line(pg, surf, colour, (x0[s], y0[s]), (x1[s], y1[s]), dash)
        pg.draw.line(surf, colour, (x1[0], y1[0]), (x1[1], y1[1]), style.px(2))
        for s in range(2):
            pg.draw.circle(surf, colour, (x1[s], y1[s]), style.px(2.5))
        label = text.render(f"CPA {dcpa / NM:.2f} NM in {tcpa / 60.0:.1f} min", colour,
                            "small")
        surf.blit(label, (0.5 * (x1[0] + x1[1]) + style.px(4), 0.5 * (y1[0] + y1[1])))


def draw_other_tracks(pg: Any, surf: Any, view: View, style: st.Style, data: RunData, k: int,
                      focus: int) -> None:
    """The tracks the focus ship holds of the other ships (radar and AIS): a square at the
    tracked position and the tracked velocity as a 6-minute vector."""
    tr = data.tracks
    if tr is None:
        return
    sel = np.flatnonzero((tr.observer == focus) & (tr.tracked[k] == 1))
    if sel.size == 0:
        return
    n, e = tr.north_m[k, sel], tr.east_m[k, sel]
    ok = np.isfinite(n) & np.isfinite(e)
    sel, n, e = sel[ok], n[ok], e[ok]
    x0, y0 = view.to_px(n, e)
    x1, y1 = view.to_px(n + tr.vn_mps[k, sel] * SPEED_VECTOR_S,
                        e + tr.ve_mps[k, sel] * SPEED_VECTOR_S)
    half = style.px(5)
    for a, b, c, d in zip(x0.tolist(), y0.tolist(), x1.tolist(), y1.tolist(), strict=True):
        pg.draw.rect(surf, st.TRACK, (a - half, b - half, 2 * half + 1, 2 * half + 1), 1)
        pg.draw.line(surf, st.TRACK, (a, b), (c, d), 1)


def draw_hulls(pg: Any, surf: Any, view: View, style: st.Style, data: RunData, k: int) -> None:
    """Hull outlines to scale (filled in the ship's colour, outlined in ink), each with its
    6-minute speed vector over ground; a ring around hulls too small to see."""
    s = data.ships
    outline = hull_outlines(data.north_m[k], data.east_m[k], data.psi_rad[k], s.length_m,
                            s.beam_m)
    pts = view.points(outline[..., 0], outline[..., 1])  # (n, 6, 2)
    x0, y0 = view.to_px(data.north_m[k], data.east_m[k])
    x1, y1 = view.to_px(data.north_m[k] + data.vn_mps[k] * SPEED_VECTOR_S,
                        data.east_m[k] + data.ve_mps[k] * SPEED_VECTOR_S)
    length_px = s.length_m / view.m_per_px
    for j in range(s.n):
        colour = st.ship_colour(j)
        pg.draw.line(surf, colour, (x0[j], y0[j]), (x1[j], y1[j]), style.px(1.5))
        if length_px[j] < SMALL_HULL_PX:
            pg.draw.circle(surf, colour, (x0[j], y0[j]), style.px(6), style.px(1.5))
        poly = pts[j, :-1].tolist()
        pg.draw.polygon(surf, colour, poly)
        if length_px[j] >= 3.0 * SMALL_HULL_PX:
            pg.draw.polygon(surf, st.INK, poly, 1)


def draw_labels(surf: Any, view: View, style: st.Style, text: Text, data: RunData, k: int,
                roles: Sequence[str]) -> None:
    """Name, role and speed over ground next to each ship."""
    x, y = view.to_px(data.north_m[k], data.east_m[k])
    sog_kn = np.hypot(data.vn_mps[k], data.ve_mps[k]) / (NM / 3600.0)
    dx, line = style.px(10), text.height("small")
    for j, name in enumerate(data.ships.names):
        surf.blit(text.render(name, st.ship_colour(j)), (x[j] + dx, y[j] - line - style.px(2)))
        surf.blit(text.render(f"{roles[j]} | {sog_kn[j]:.1f} kn", st.INK, "small"),
                  (x[j] + dx, y[j]))


def scale_bar(pg: Any, view: View, style: st.Style, text: Text, width_px: int) -> Any:
    """A scale bar of a round length near a fifth of ``width_px``, ticked at both ends and in
    the middle, its length written above (transparent surface)."""
    length_m, label = nice_length_m(view.m_per_px, 0.2 * width_px)
    bar = round(length_m / view.m_per_px)
    lab = text.render(label, st.INK, "small")
    tick, lw = style.px(5), style.px(2)
    surf = pg.Surface((max(bar + lw + 1, lab.get_width()), tick + lab.get_height() + lw),
                      pg.SRCALPHA)
    y0 = surf.get_height() - lw
    pg.draw.line(surf, st.INK, (0, y0), (bar, y0), lw)
    for xt in (0, bar // 2, bar):
        pg.draw.line(surf, st.INK, (xt, y0), (xt, y0 - tick), style.px(1.5))
    surf.blit(lab, (max(0, bar // 2 - lab.get_width() // 2), 0))
    return surf


def north_arrow(pg: Any, style: st.Style, text: Text) -> Any:
    """An arrow pointing north with an N above it (transparent surface)."""
    arrow, half = style.px(28), style.px(7)
    n_lab = text.render("N", st.INK)
    surf = pg.Surface((max(2 * half + 1, n_lab.get_width()), arrow + n_lab.get_height() + 1),
                      pg.SRCALPHA)
    top, mid = n_lab.get_height(), surf.get_width() // 2
    pg.draw.polygon(surf, st.INK, [(mid, top), (mid + half, top + arrow),
                                   (mid, top + 0.7 * arrow), (mid - half, top + arrow)])
    surf.blit(n_lab, (mid - n_lab.get_width() // 2, 0))
    return surf


def legend(pg: Any, style: st.Style, text: Text,
           items: Sequence[tuple[str, str, st.Colour]]) -> Any:
    """The legend box: ``items`` are ``(kind, label, colour)`` with kind ``line``, ``thin``,
    ``dash``, ``dot``, ``square``, ``hull`` or ``ring``."""
    px = style.px
    line_h = text.height("small") + px(2)
    sample = px(22)
    labels = [text.render(label, st.INK, "small", st.PANEL) for _, label, _ in items]
    box_w = sample + px(6) + max(lab.get_width() for lab in labels) + 2 * px(6)
    box_h = line_h * len(items) + 2 * px(4)
    surf = pg.Surface((box_w, box_h))
    surf.fill(st.PANEL)
    pg.draw.rect(surf, st.FAINT, (0, 0, box_w, box_h), 1)
    for row, ((kind, _, colour), lab) in enumerate(zip(items, labels, strict=True)):
        ly = px(4) + row * line_h + line_h // 2
        lx = px(6)
        if kind in ("line", "thin"):
            pg.draw.line(surf, colour, (lx, ly), (lx + sample, ly), px(2) if kind == "line" else 1)
        elif kind == "dash":
            dashed_line(pg, surf, colour, (lx, ly), (lx + sample, ly), px(4))
        elif kind == "dot":
            pg.draw.rect(surf, colour, (lx + sample // 2 - 1, ly - 1, px(2), px(2)))
        elif kind == "square":
            half = px(4)
            pg.draw.rect(surf, colour, (lx + sample // 2 - half, ly - half, 2 * half + 1,
                                        2 * half + 1), 1)
        elif kind == "ring":
            pg.draw.ellipse(surf, colour, (lx, ly - px(4), sample, px(8)), 1)
        else:  # hull
            pg.draw.polygon(surf, colour, [(lx, ly - px(3)), (lx + 0.8 * sample, ly - px(3)),
                                           (lx + sample, ly), (lx + 0.8 * sample, ly + px(3)),
                                           (lx, ly + px(3))])
        surf.blit(lab, (lx + sample + px(6), ly - lab.get_height() // 2))
    return surf


def draw_panel(pg: Any, surf: Any, style: st.Style, text: Text, lines: Sequence[
               tuple[str, st.Colour]]) -> None:
    """Lines of text in a box at the top left (time stamp, decisions, collisions)."""
    if not lines:
        return
    pad, gap = style.px(12), style.px(4)
    rendered = [text.render(t, c, "normal" if row == 0 else "small", st.PANEL)
                for row, (t, c) in enumerate(lines)]
    box_w = max(r.get_width() for r in rendered) + 2 * gap
    box_h = sum(r.get_height() for r in rendered) + 2 * gap
    pg.draw.rect(surf, st.PANEL, (pad, pad, box_w, box_h))
    pg.draw.rect(surf, st.FAINT, (pad, pad, box_w, box_h), 1)
    y = pad + gap
    for r in rendered:
        surf.blit(r, (pad + gap, y))
        y += r.get_height()
