"""Colours, line widths and font sizes of a frame, and the fixed palette of GIF frames.

Sizes are given at 96 DPI and scaled with the chosen DPI, so a picture keeps its look in inches
when it is drawn with more pixels. Lines are drawn without antialiasing (only text is
antialiased): a frame is then made of the colours below and of text blended into its
backgrounds, which the fixed GIF palette holds exactly or nearly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Colour = tuple[int, int, int]

SEA: Colour = (232, 240, 247)
PANEL: Colour = (255, 255, 255)
INK: Colour = (25, 25, 30)
FAINT: Colour = (130, 136, 145)
ROUTE: Colour = (110, 110, 120)
GNSS: Colour = (70, 70, 70)
TRACK: Colour = (35, 35, 35)
CPA_NEAR: Colour = (200, 20, 30)  # CPA inside the near-miss range
CPA_FAR: Colour = (225, 120, 0)
COLLISION: Colour = (200, 20, 30)
#: one colour per ship, in the run's ship order (repeats after the last)
SHIPS: tuple[Colour, ...] = ((30, 90, 200), (205, 45, 45), (20, 150, 70), (150, 80, 190),
                             (235, 140, 20), (120, 80, 60), (215, 90, 170), (10, 160, 175))
BASE_DPI = 96.0


def ship_colour(k: int) -> Colour:
    return SHIPS[k % len(SHIPS)]


def shade(colour: Colour, towards: Colour, share: float) -> Colour:
    """``colour`` moved ``share`` of the way to ``towards``."""
    return tuple(round(c + share * (t - c)) for c, t in zip(colour, towards, strict=True))


def estimate_colour(k: int) -> Colour:
    """The estimated track: the ship's colour darkened."""
    return shade(ship_colour(k), (0, 0, 0), 0.45)


def domain_colour(k: int) -> Colour:
    """The ship domain: the ship's colour faded towards the sea."""
    return shade(ship_colour(k), SEA, 0.5)


#: dots per inch a frame may be drawn at (far beyond, text and legend surfaces of tens of
#: thousands of pixels make SDL fail)
DPI_RANGE = (10.0, 1200.0)


@dataclass(frozen=True)
class Style:
    """Pixel sizes at a DPI (within :data:`DPI_RANGE`)."""

    dpi: float = BASE_DPI

    def __post_init__(self) -> None:
        if not DPI_RANGE[0] <= self.dpi <= DPI_RANGE[1]:
            raise ValueError(f"expected {DPI_RANGE[0]:g} to {DPI_RANGE[1]:g} dots per inch, "
                             f"got {self.dpi}")

    @property
    def scale(self) -> float:
        return self.dpi / BASE_DPI

    def px(self, size_at_96: float) -> int:
        """A length in pixels, at least 1."""
        return max(1, round(size_at_96 * self.scale))

    def font_px(self, points: float) -> int:
        """Font height in pixels of a size in points (1 pt = 1/72 inch), at least 6."""
        return max(6, round(points * self.dpi / 72.0))


def _colours() -> list[Colour]:
    fixed = [SEA, PANEL, INK, FAINT, ROUTE, GNSS, TRACK, CPA_NEAR, CPA_FAR, (0, 0, 0)]
    for k in range(len(SHIPS)):
        fixed += [ship_colour(k), estimate_colour(k), domain_colour(k)]
    return fixed


def gif_palette() -> np.ndarray:
    """``(256, 3)`` uint8: every style colour exactly, then each text colour blended into each
    background in eight steps, a grey ramp, and a colour cube for anything else."""
    colours = _colours()
    for text in (INK, FAINT, CPA_NEAR, *SHIPS):
        for back in (SEA, PANEL):
            colours += [shade(text, back, s) for s in np.linspace(0.1, 0.9, 8)]
    colours += [(g, g, g) for g in np.linspace(0, 255, 16).round().astype(int)]
    unique = list(dict.fromkeys(colours))
    cube = [(r, g, b) for r in (0, 128, 255) for g in (0, 128, 255) for b in (0, 128, 255)]
    unique += [c for c in cube if c not in unique]
    if len(unique) > 256:
        raise AssertionError(f"GIF palette holds {len(unique)} colours (at most 256)")
    unique += [unique[-1]] * (256 - len(unique))
    return np.array(unique, dtype=np.uint8)
