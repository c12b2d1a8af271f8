"""Sizes at a DPI (and the DPIs refused, with the message), the colours derived from each ship's,
and the fixed GIF palette holding every colour of the drawing."""

import dataclasses
import re

import numpy as np
import pytest

from trafficsim.render import style as st


def test_the_default_is_96_dpi_at_scale_one():
    assert st.Style().dpi == 96.0 and st.Style().scale == 1.0
    assert st.Style(300.0).scale == pytest.approx(300.0 / 96.0)


@pytest.mark.parametrize("dpi", [10.0, 10, 72.0, 1200.0])
def test_dpis_from_10_to_1200_are_accepted(dpi):
    assert st.Style(dpi).dpi == dpi


@pytest.mark.parametrize("dpi", [9.99, 0.0, -96.0, 1200.01, 1e6, float("inf"), float("-inf"),
                                 float("nan")])
def test_dpis_outside_10_to_1200_are_refused_with_the_range(dpi):
    with pytest.raises(ValueError, match=re.escape(
            f"expected 10 to 1200 dots per inch, got {dpi}")) as err:
        st.Style(dpi)
    assert str(err.value) == f"expected 10 to 1200 dots per inch, got {dpi}"


def test_a_style_cannot_be_changed_after_its_checks():
    style = st.Style(96.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        style.dpi = 5000.0  # type: ignore[misc]


@pytest.mark.parametrize(("dpi", "size", "px"), [
    (96.0, 6.0, 6), (192.0, 6.0, 12), (300.0, 2.0, 6), (72.0, 10.0, 8), (1200.0, 1.5, 19)])
def test_pixel_sizes_scale_with_the_dpi(dpi, size, px):
    assert st.Style(dpi).px(size) == px


@pytest.mark.parametrize(("dpi", "size"), [(10.0, 2.0), (96.0, 0.4), (96.0, 0.0), (96.0, -3.0)])
def test_pixel_sizes_are_at_least_one(dpi, size):
    assert st.Style(dpi).px(size) == 1


def test_pixel_sizes_are_whole_numbers():
    assert isinstance(st.Style(150.0).px(7.0), int)
    assert isinstance(st.Style(150.0).font_px(9.0), int)


@pytest.mark.parametrize(("dpi", "points", "px"), [
    (72.0, 9.0, 9), (96.0, 9.0, 12), (96.0, 7.5, 10), (300.0, 10.0, 42), (1200.0, 12.0, 200)])
def test_font_heights_are_points_at_the_dpi(dpi, points, px):
    # 1 pt = 1/72 inch, whatever the 96-DPI base of the other sizes
    assert st.Style(dpi).font_px(points) == px


@pytest.mark.parametrize(("dpi", "points"), [(10.0, 9.0), (40.0, 7.5), (96.0, 1.0)])
def test_font_heights_are_at_least_six_pixels(dpi, points):
    assert st.Style(dpi).font_px(points) == 6


def test_ship_colours_are_distinct_and_repeat_after_the_last():
    n = len(st.SHIPS)
    assert n == 8 and len(set(st.SHIPS)) == n
    assert [st.ship_colour(k) for k in range(n)] == list(st.SHIPS)
    assert st.ship_colour(n) == st.SHIPS[0] and st.ship_colour(2 * n + 3) == st.SHIPS[3]


def test_shade_moves_a_share_of_the_way_in_whole_steps():
    assert st.shade((0, 100, 255), (100, 0, 255), 0.0) == (0, 100, 255)
    assert st.shade((0, 100, 255), (100, 0, 255), 1.0) == (100, 0, 255)
    assert st.shade((0, 100, 255), (100, 0, 255), 0.25) == (25, 75, 255)
    mixed = st.shade((10, 20, 30), (255, 255, 255), 0.4)
    assert mixed == (108, 114, 120) and all(isinstance(c, int) for c in mixed)


def test_estimates_are_darker_and_domains_faded_towards_the_sea():
    assert st.SHIPS[1] == (205, 45, 45) and st.SHIPS[7] == (10, 160, 175)
    assert st.estimate_colour(1) == (113, 25, 25)  # 0.55 of the ship's colour
    assert st.domain_colour(7) == (121, 200, 211)  # halfway to SEA (232, 240, 247)
    n = len(st.SHIPS)
    assert st.estimate_colour(n + 1) == st.estimate_colour(1)
    assert st.domain_colour(n + 7) == st.domain_colour(7)


def _palette_colours() -> set[tuple[int, int, int]]:
    return {tuple(c) for c in st.gif_palette().tolist()}


def test_gif_palette_is_256_rgb_bytes_the_same_every_time():
    palette = st.gif_palette()
    assert palette.shape == (256, 3) and palette.dtype == np.uint8
    np.testing.assert_array_equal(palette, st.gif_palette())


def _style_colours() -> list[tuple[int, int, int]]:
    named = [st.SEA, st.PANEL, st.INK, st.FAINT, st.ROUTE, st.GNSS, st.TRACK, st.CPA_NEAR,
             st.CPA_FAR, st.COLLISION, (0, 0, 0)]
    return named + [f(k) for k in range(len(st.SHIPS))
                    for f in (st.ship_colour, st.estimate_colour, st.domain_colour)]


def test_gif_palette_holds_every_style_colour_exactly():
    held = _palette_colours()
    assert not [c for c in _style_colours() if c not in held]


def test_gif_palette_lists_the_style_colours_first():
    style = set(_style_colours())
    first = {tuple(c) for c in st.gif_palette()[:len(style)].tolist()}
    assert first == style


def test_gif_palette_holds_text_blended_into_its_backgrounds():
    held = _palette_colours()
    for text in (st.INK, st.FAINT, st.CPA_NEAR, *st.SHIPS):
        for back in (st.SEA, st.PANEL):
            for share in np.linspace(0.1, 0.9, 8):
                assert st.shade(text, back, share) in held, (text, back, share)


def test_gif_palette_holds_a_grey_ramp_and_a_colour_cube():
    held = _palette_colours()
    greys = [round(g) for g in np.linspace(0.0, 255.0, 16)]
    assert greys[:3] == [0, 17, 34] and greys[-1] == 255
    assert all((g, g, g) in held for g in greys)
    assert all((r, g, b) in held for r in (0, 128, 255) for g in (0, 128, 255)
               for b in (0, 128, 255))


def test_gif_palette_pads_with_its_last_colour():
    palette = st.gif_palette()
    distinct = len(_palette_colours())
    assert distinct < 256  # room to spare, so the padding is exercised
    np.testing.assert_array_equal(palette[distinct:], np.repeat(palette[distinct - 1:distinct],
                                                                256 - distinct, axis=0))
    assert len({tuple(c) for c in palette[:distinct].tolist()}) == distinct


@pytest.mark.parametrize("k", range(len(st.SHIPS)))
def test_derived_colours_lie_between_the_ship_and_their_target(k):
    """The estimate is 0.45 of the way to black (each channel within half a step of 0.55 of
    the ship's); the domain 0.5 of the way to the sea: each channel between the two ends."""
    ship = st.ship_colour(k)
    for c, e in zip(ship, st.estimate_colour(k), strict=True):
        assert abs(e - 0.55 * c) <= 0.5 + 1e-9 and e <= c
    for c, d, s in zip(ship, st.domain_colour(k), st.SEA, strict=True):
        assert min(c, s) <= d <= max(c, s) and abs(d - (c + s) / 2) <= 0.5


def test_gif_palette_indices_of_style_colours_are_distinct():
    """Each distinct style colour has its own palette entry (a GIF pixel's index names one
    colour): the first entries are the style colours without repeats."""
    palette = [tuple(c) for c in st.gif_palette().tolist()]
    distinct = list(dict.fromkeys(palette))
    assert palette[:len(distinct)] == distinct
