"""The renderer: keeps what does not change between frames and draws one frame per record.

With a fixed view (every ship fitted) the sea, the routes and the tracks drawn so far live on
one kept surface: a frame adds the records since the previous frame to it, copies it, then
draws what moves. With a view that follows a ship everything on the chart moves, so the
chart layers are drawn afresh each frame. The overlay (scale bar, north arrow, legend) is drawn
once either way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.render import layers
from trafficsim.render import style as st
from trafficsim.render.data import RunData
from trafficsim.render.decisions import words
from trafficsim.render.headless import pygame
from trafficsim.render.view import fit, follow
from trafficsim.units import NM

#: closest view of a followed ship, NM (closer, a hull is drawn millions of pixels long)
MIN_RANGE_NM = 0.01
#: farthest view, NM: the width of the scenario frame (2,000 km, ships within 1,000 km of the
#: origin each way), beyond which a view shows nothing more
MAX_RANGE_NM = 1080.0


@dataclass(frozen=True)
class FrameOptions:
    """How frames look.

    Attributes:
        size_px: width and height in pixels.
        dpi: dots per inch; line widths and text scale with it (sizes are given at 96 DPI).
        follow: name of the ship the view follows (None: a fixed view that fits every ship).
        range_nm: with ``follow``, the distance from the ship to the nearer edge of the view.
        measurements: draw the raw GNSS fixes.
        domains: draw the ship domains.
        legend: draw the legend (in a column on the right).
        panel: draw the panel with time, decisions and collisions (in a band at the top).
    """

    size_px: tuple[int, int] = (960, 720)
    dpi: float = 96.0
    follow: str | None = None
    range_nm: float = 3.0
    measurements: bool = False
    domains: bool = True
    legend: bool = True
    panel: bool = True


DEFAULT_OPTIONS = FrameOptions()


def clock(t_s: float) -> str:
    """``h:mm:ss`` of a time in seconds."""
    whole = round(t_s)
    return f"{whole // 3600}:{whole % 3600 // 60:02d}:{whole % 60:02d}"


class Renderer:
    """Draws the frames of one run; frames may be asked in any order (in order is fastest)."""

    def __init__(self, data: RunData, options: FrameOptions = DEFAULT_OPTIONS,
                 fit_to: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """``fit_to``: north and east metres a fixed view shows (default: every record's
        true position)."""
        self.pg = pg = pygame()
        self.data, self.options = data, options
        self.style = style = st.Style(options.dpi)
        self.text = layers.Text(pg, style)
        w, h = options.size_px
        self.focus = 0
        if options.follow is not None:
            if options.follow not in data.ships.names:
                raise InputError(f"no ship {options.follow!r} in this run; ships: "
                                 f"{', '.join(data.ships.names)}", key="--follow")
            self.focus = data.ships.names.index(options.follow)
        # layout: the legend in a column on the right, the panel in a band at the top, the
        # chart (and the view's centre) in what is left
        pad = style.px(12)
        self.overlay: list[tuple[Any, tuple[int, int]]] = []
        right = w
        if options.legend:
            box = layers.legend(pg, style, self.text, self._legend())
            right = max(w // 2, w - box.get_width() - pad)
            self.overlay.append((box, (w - pad - box.get_width(), h - pad - box.get_height())))
        top = pad + self._panel_height() if options.panel else 0
        area = (0, top, right, h - top)
        if options.follow is not None:
            self.view = follow(options.range_nm * NM, w, h, area)
        else:
            north, east = fit_to if fit_to is not None else (data.north_m[: data.count],
                                                             data.east_m[: data.count])
            self.view = fit(north, east, w, h, area=area)
        bar = layers.scale_bar(pg, self.view, style, self.text, right)
        arrow = layers.north_arrow(pg, style, self.text)
        self.overlay += [(bar, (pad, h - pad - bar.get_height())),
                         (arrow, (w - pad - arrow.get_width(), top + pad))]
        self._frame = pg.Surface((w, h))
        self._chart: Any = None  # fixed view: sea, routes and tracks up to record _drawn
        self._drawn = -1

    def _panel_height(self) -> int:
        """Height of the panel with the time line and one decision line per deciding ship."""
        deciding = sum(b != "keep_course" for b in self.data.ships.behaviours)
        lines = 1 + (deciding if self.data.decisions is not None else 0)
        return (self.text.height() + (lines - 1) * self.text.height("small")
                + 2 * self.style.px(4))

    def _legend(self) -> list[tuple[str, str, st.Colour]]:
        d, o = self.data, self.options
        items: list[tuple[str, str, st.Colour]] = [("hull", "hull to scale", st.ship_colour(0)),
                                                   ("line", "true track", st.ship_colour(0))]
        if d.has_estimate.any():
            items.append(("thin", "estimated track", st.estimate_colour(0)))
        if o.measurements:
            items.append(("dot", "GNSS fix", st.GNSS))
        if d.tracks is not None:
            items.append(("square", f"tracked by {d.ships.names[self.focus]}", st.TRACK))
        if any(r.shape[0] for r in d.ships.routes):
            items.append(("dash", "route", st.ROUTE))
        if o.domains:
            items.append(("ring", f"ship domain ({d.domain})", st.domain_colour(0)))
        items.append(("line", f"CPA < {layers.CPA_NEAR_M / NM:.2f} NM", st.CPA_NEAR))
        items.append(("thin", "speed vector, 6 min", st.ship_colour(0)))
        return items

    def _chart_to(self, k: int) -> Any:
        """The fixed view's kept chart with the tracks drawn up to record ``k``."""
        pg = self.pg
        if self._chart is None or k < self._drawn:
            self._chart = pg.Surface(self.options.size_px)
            self._chart.fill(st.SEA)
            layers.draw_routes(pg, self._chart, self.view, self.style, self.data)
            self._drawn = 0
            layers.draw_tracks(pg, self._chart, self.view, self.style, self.data, 0, 0,
                               self.options.measurements, stepwise=True)
        if k > self._drawn:
            layers.draw_tracks(pg, self._chart, self.view, self.style, self.data, self._drawn,
                               k, self.options.measurements, stepwise=True)
            self._drawn = k
        return self._chart

    def draw(self, k: int) -> Any:
        """The frame of record ``k`` (a pygame Surface owned by the renderer: copy it or write
        it out before the next call)."""
        if not 0 <= k < self.data.count:
            raise IndexError(f"record {k} outside 0 .. {self.data.count - 1}")
        pg, d, style, frame = self.pg, self.data, self.style, self._frame
        if self.options.follow is None:
            view = self.view
            frame.blit(self._chart_to(k), (0, 0))
        else:
            view = self.view.centred_on(d.north_m[k, self.focus], d.east_m[k, self.focus])
            frame.fill(st.SEA)
            layers.draw_routes(pg, frame, view, style, d)
            layers.draw_tracks(pg, frame, view, style, d, 0, k, self.options.measurements)
        if self.options.domains:
            layers.draw_domains(pg, frame, view, style, d, k)
        layers.draw_cpa(pg, frame, view, style, self.text, d, k)
        layers.draw_hulls(pg, frame, view, style, d, k)
        layers.draw_other_tracks(pg, frame, view, style, d, k, self.focus)
        decisions = d.decisions.at(float(d.t_s[k])) if d.decisions is not None else {}
        layers.draw_labels(frame, view, style, self.text, d, k, self._roles(decisions))
        for part, place in self.overlay:
            frame.blit(part, place)
        if self.options.panel:
            layers.draw_panel(pg, frame, style, self.text, self._panel(k, decisions))
        return frame

    def _roles(self, decisions: dict) -> list[str]:
        roles = []
        for name, behaviour in zip(self.data.ships.names, self.data.ships.behaviours,
                                   strict=True):
            if name in decisions:
                dec = decisions[name]
                roles.append(words(dec.role) if dec.has_role else "no role")
            else:
                roles.append("keeps course" if behaviour == "keep_course" else "no role")
        return roles

    def _panel(self, k: int, decisions: dict) -> list[tuple[str, st.Colour]]:
        d = self.data
        t = float(d.t_s[k])
        lines = [(f"{d.name}   t = {clock(t)} ({t:.0f} s)", st.INK)]
        for name in d.ships.names:
            if name in decisions:
                lines.append((decisions[name].line(name), st.INK))
        c = d.collisions
        hit = np.flatnonzero(np.isfinite(c.t_s) & (c.t_s <= t + 1e-9))
        for p in hit:
            lines.append((f"COLLISION {d.ships.names[c.ship_a[p]]} - "
                          f"{d.ships.names[c.ship_b[p]]} at t = {c.t_s[p]:.0f} s",
                          st.COLLISION))
        return lines

    def rgb(self, k: int) -> bytes:
        """Frame ``k`` as packed RGB bytes (rows top to bottom)."""
        return self.pg.image.tobytes(self.draw(k), "RGB")

    def array(self, k: int) -> np.ndarray:
        """Frame ``k`` as a ``(height, width, 3)`` uint8 array (a copy)."""
        w, h = self.options.size_px
        return np.frombuffer(self.rgb(k), dtype=np.uint8).reshape(h, w, 3).copy()

