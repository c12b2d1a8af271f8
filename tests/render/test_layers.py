"""The layers of a frame, each drawn alone on a sea-coloured surface through a hand-made view:
north up, east right, to scale, in the style's colours, where the metres say (pixel positions
worked out by hand here). Text is drawn by some layers but never inspected (it differs between
pygame builds)."""

import math

import numpy as np
import pytest

from trafficsim.render import layers
from trafficsim.render import style as st
from trafficsim.render.data import Collisions, RunData, Ships, Tracks
from trafficsim.render.headless import pygame as headless_pygame
from trafficsim.render.view import View
from trafficsim.units import NM

STYLE = st.Style()
SHIP0, SHIP1 = st.ship_colour(0), st.ship_colour(1)


@pytest.fixture
def pg(monkeypatch):
    for key, value in (("SDL_VIDEODRIVER", "dummy"), ("SDL_AUDIODRIVER", "dummy"),
                       ("PYGAME_HIDE_SUPPORT_PROMPT", "1")):  # restored after the test
        monkeypatch.setenv(key, value)
    return headless_pygame()


def _sea(pg, w=200, h=200):
    surf = pg.Surface((w, h))
    surf.fill(st.SEA)
    return surf


def _at(surf, x, y) -> tuple:
    return tuple(surf.get_at((math.floor(x), math.floor(y))))[:3]


def _view(m_per_px=10.0, origin=(100.0, 100.0), size=(200, 200)) -> View:
    """Metres ``(0, 0)`` on the pixel corner ``origin``."""
    return View(size[0], size[1], 0.0, 0.0, m_per_px, origin[0], origin[1])


def _grid(value, shape):
    return np.broadcast_to(np.asarray(value, dtype=float), shape).copy()


def _data(north, east, heading_deg=0.0, vn=0.0, ve=0.0, length_m=100.0, beam_m=20.0,
          routes=None, est=None, gnss=None, gnss_valid=True, domain="coldwell",
          tracks=None) -> RunData:
    """Run data of ``(R, n)`` true positions (scalars or ``(n,)`` broadcast where given)."""
    north = np.atleast_2d(np.asarray(north, dtype=float))
    east = np.atleast_2d(np.asarray(east, dtype=float))
    shape = north.shape
    n = shape[1]
    names = [f"s{j}" for j in range(n)]
    ships = Ships(names, _grid(length_m, (n,)), _grid(beam_m, (n,)), ["keep_course"] * n,
                  routes if routes is not None else [np.zeros((0, 2))] * n)
    est_n, est_e = (north, east) if est is None else est
    gnss_n, gnss_e = (north, east) if gnss is None else gnss
    vn, ve = _grid(vn, shape), _grid(ve, shape)
    return RunData(
        name="t", ships=ships, domain=domain, record_every_s=1.0,
        t_s=np.arange(shape[0], dtype=float), north_m=north, east_m=east,
        psi_rad=np.radians(_grid(heading_deg, shape)), u_mps=np.hypot(vn, ve), vn_mps=vn,
        ve_mps=ve, est_north_m=_grid(est_n, shape), est_east_m=_grid(est_e, shape),
        gnss_north_m=_grid(gnss_n, shape), gnss_east_m=_grid(gnss_e, shape),
        gnss_valid=_grid(gnss_valid, shape).astype(bool),
        has_estimate=np.any(np.hypot(_grid(est_n, shape) - north, _grid(est_e, shape) - east)
                            > 1e-6, axis=0),
        collisions=Collisions(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)),
        tracks=tracks, count=shape[0])


def _changed(pg, surf) -> np.ndarray:
    """``(w, h)`` bool: pixels no longer sea-coloured."""
    return np.any(pg.surfarray.array3d(surf) != np.array(st.SEA), axis=2)


# -- hulls ------------------------------------------------------------------------------------

@pytest.mark.parametrize("heading", [0.0, 30.0, 90.0, 200.0, 315.0])
def test_hull_is_to_scale_and_turned_clockwise_from_north(pg, heading):
    # 200 m x 40 m at 2 m/px: 100 px long, 20 px wide, centred on pixel (100, 100)
    surf = _sea(pg)
    layers.draw_hulls(pg, surf, _view(2.0), STYLE,
                      _data(0.0, 0.0, heading, length_m=200.0, beam_m=40.0), 0)
    psi = math.radians(heading)
    fwd = (math.sin(psi), -math.cos(psi))  # pixels per pixel ahead: east is +x, north is -y
    stbd = (math.cos(psi), math.sin(psi))

    def at(ahead_px, starboard_px):
        return _at(surf, 100 + ahead_px * fwd[0] + starboard_px * stbd[0],
                   100 + ahead_px * fwd[1] + starboard_px * stbd[1])

    for ahead, side in ((40, 0), (-45, 0), (0, 5), (0, -5), (-40, 5), (-40, -5)):
        assert at(ahead, side) == SHIP0, (ahead, side)
    for ahead, side in ((56, 0), (-56, 0), (0, 16), (0, -16), (45, 8)):
        assert at(ahead, side) == st.SEA, (ahead, side)


def test_large_hulls_are_outlined_in_ink(pg):
    surf = _sea(pg)
    # heading north, 200 m at 2 m/px: bow point at pixel (100, 50), starboard side at x = 110
    layers.draw_hulls(pg, surf, _view(2.0), STYLE,
                      _data(0.0, 0.0, 0.0, length_m=200.0, beam_m=40.0), 0)
    assert _at(surf, 100, 50) == st.INK
    assert _at(surf, 110, 120) == st.INK and _at(surf, 90, 120) == st.INK
    assert _at(surf, 100, 100) == SHIP0


@pytest.mark.parametrize(("length_m", "inked"), [(240.0, True), (230.0, False)])
def test_the_ink_outline_starts_at_24_pixels_of_hull(pg, length_m, inked):
    surf = _sea(pg)
    layers.draw_hulls(pg, surf, _view(10.0), STYLE,
                      _data(0.0, 0.0, 0.0, length_m=length_m, beam_m=60.0), 0)
    assert _at(surf, 100, 88) == (st.INK if inked else SHIP0)  # the bow point


@pytest.mark.parametrize(("length_m", "ring"), [(70.0, True), (80.0, False)])
def test_hulls_under_8_pixels_get_a_ring(pg, length_m, ring):
    surf = _sea(pg)
    layers.draw_hulls(pg, surf, _view(10.0), STYLE,
                      _data(0.0, 0.0, 0.0, length_m=length_m, beam_m=10.0), 0)
    changed = _changed(pg, surf)
    # a ring of radius 6 px, 2 px wide, around the 1 px wide hull on column 100
    ring_px = changed[92:97, 100].any() and changed[104:109, 100].any()
    ring_px = ring_px and changed[100, 92:97].any() and changed[100, 104:109].any()
    assert ring_px == ring
    assert not changed[97:99, 100].any() and not changed[102:104, 100].any()
    assert not changed[110:, :].any() and not changed[:90, :].any()


@pytest.mark.parametrize(("vn", "ve", "end"), [(2.5, 0.0, (100, 10)), (0.0, 2.5, (190, 100)),
                                               (-2.5, 0.0, (100, 190)), (0.0, -2.5, (10, 100))])
def test_speed_vector_shows_six_minutes_of_travel(pg, vn, ve, end):
    # 2.5 m/s for 360 s is 900 m: 90 px at 10 m/px
    surf = _sea(pg)
    heading = math.degrees(math.atan2(ve, vn))
    layers.draw_hulls(pg, surf, _view(10.0), STYLE,
                      _data(0.0, 0.0, heading, vn=vn, ve=ve, length_m=100.0, beam_m=10.0), 0)
    dx, dy = (end[0] - 100) / 90, (end[1] - 100) / 90
    assert _at(surf, 100 + 70 * dx, 100 + 70 * dy) == SHIP0
    assert _at(surf, 100 + 89 * dx, 100 + 89 * dy) == SHIP0
    assert _at(surf, 100 + 94 * dx, 100 + 94 * dy) == st.SEA
    # nothing the other way beyond the hull, nor off to the side
    assert _at(surf, 100 - 30 * dx, 100 - 30 * dy) == st.SEA
    assert _at(surf, 100 + 50 * dx + 4 * dy, 100 + 50 * dy + 4 * dx) == st.SEA


def test_hulls_take_their_ships_colours(pg):
    surf = _sea(pg)
    data = _data([[0.0, 0.0, 500.0]], [[-500.0, 500.0, 0.0]], length_m=200.0, beam_m=50.0)
    layers.draw_hulls(pg, surf, _view(10.0), STYLE, data, 0)
    assert _at(surf, 50, 100) == st.ship_colour(0)
    assert _at(surf, 150, 100) == st.ship_colour(1)
    assert _at(surf, 100, 50) == st.ship_colour(2)


# -- tracks -----------------------------------------------------------------------------------

def _eastbound(n_records=3, offset_north=100.0, **kw) -> RunData:
    """One ship sailing east along north 0 from east -500 m in 500 m records; its estimate
    ``offset_north`` metres north of the truth."""
    east = (-500.0 + 500.0 * np.arange(n_records))[:, None]
    north = np.zeros_like(east)
    return _data(north, east, 90.0, ve=5.0, est=(north + offset_north, east), **kw)


@pytest.mark.parametrize("stepwise", [False, True])
def test_true_and_estimated_tracks(pg, stepwise):
    surf = _sea(pg)
    layers.draw_tracks(pg, surf, _view(10.0), STYLE, _eastbound(), 0, 2, False, stepwise)
    # the truth on row 100 from x 50 to 150, 2 px wide; the estimate 10 px north, 1 px wide
    for x in (50, 75, 100, 149):
        assert _at(surf, x, 100) == SHIP0
        assert _at(surf, x, 90) == st.estimate_colour(0)
    assert _at(surf, 100, 89) == st.SEA and _at(surf, 100, 91) == st.SEA
    assert _at(surf, 100, 95) == st.SEA and _at(surf, 100, 103) == st.SEA
    assert _at(surf, 45, 100) == st.SEA and _at(surf, 155, 100) == st.SEA


def test_tracks_draw_only_the_records_asked_for(pg):
    surf = _sea(pg)
    layers.draw_tracks(pg, surf, _view(10.0), STYLE, _eastbound(), 1, 2, False)
    assert _at(surf, 75, 100) == st.SEA and _at(surf, 125, 100) == SHIP0


def test_ships_without_a_filter_draw_no_estimate(pg):
    surf = _sea(pg)
    data = _eastbound()
    data.has_estimate[:] = False
    layers.draw_tracks(pg, surf, _view(10.0), STYLE, data, 0, 2, False)
    assert not _changed(pg, surf)[:, :98].any()


@pytest.mark.parametrize("stepwise", [False, True])
def test_gnss_fixes_are_dots_at_valid_fixes_only(pg, stepwise):
    # fixes 300 m south of the track: at pixels (50, 130), (100, 130) and (150, 130)
    data = _eastbound(offset_north=0.0, gnss=(np.full((3, 1), -300.0),
                                              (-500.0 + 500.0 * np.arange(3))[:, None]))
    data.gnss_valid[1, 0] = False
    data.gnss_north_m[2, 0] = np.nan
    surf = _sea(pg)
    layers.draw_tracks(pg, surf, _view(10.0), STYLE, data, 0, 2, True, stepwise)
    changed = _changed(pg, surf)[:, 110:]
    # one 2 x 2 dot: pixels x 49..50, y 129..130
    assert changed.sum() == 4 and changed[49:51, 19:21].all()
    assert _at(surf, 50, 130) == st.GNSS
    quiet = _sea(pg)
    layers.draw_tracks(pg, quiet, _view(10.0), STYLE, data, 0, 2, False, stepwise)
    assert not _changed(pg, quiet)[:, 110:].any()


def test_tracks_drawn_in_pieces_match_tracks_drawn_at_once(pg):
    rng = np.random.default_rng(1)
    t = np.arange(13)[:, None]
    north = np.hstack([40.0 * t, 600.0 - 25.0 * t]) + rng.normal(0.0, 3.0, (13, 2))
    east = np.hstack([-500.0 + 60.0 * t, 300.0 - 50.0 * t])
    data = _data(north, east, est=(north + rng.normal(0.0, 30.0, north.shape), east),
                 gnss=(north + rng.normal(0.0, 40.0, north.shape), east))
    data.gnss_valid[::3] = False
    whole, pieces = _sea(pg), _sea(pg)
    view = _view(7.3, (101.4, 99.6))
    layers.draw_tracks(pg, whole, view, STYLE, data, 0, 12, True, stepwise=True)
    for k0, k1 in ((0, 0), (0, 4), (4, 5), (5, 12)):
        layers.draw_tracks(pg, pieces, view, STYLE, data, k0, k1, True, stepwise=True)
    np.testing.assert_array_equal(pg.surfarray.array3d(pieces), pg.surfarray.array3d(whole))
    assert _changed(pg, whole).sum() > 300


@pytest.mark.parametrize(("dpi", "rows"), [(48.0, 1), (96.0, 2), (192.0, 4)])
def test_track_width_scales_with_dpi(pg, dpi, rows):
    surf = _sea(pg)
    layers.draw_tracks(pg, surf, _view(10.0), st.Style(dpi), _eastbound(), 0, 2, False)
    column = _changed(pg, surf)[100, 95:]  # below the estimate
    assert column.sum() == rows


def test_dots_are_squares_clipped_to_the_surface(pg):
    surf = _sea(pg, 20, 20)
    layers._dots(pg, surf, np.array([[10, 10], [0, 0], [19, 19]]), st.GNSS, 3)
    changed = _changed(pg, surf)
    assert changed[9:12, 9:12].all()
    assert changed[0:2, 0:2].all() and changed[18:20, 18:20].all()
    assert changed.sum() == 9 + 4 + 4
    assert _at(surf, 10, 10) == st.GNSS


# -- dashed lines -----------------------------------------------------------------------------

def test_dashed_line_alternates_dash_and_gap(pg):
    surf = _sea(pg, 100, 10)
    layers.dashed_line(pg, surf, st.ROUTE, (0, 5), (60, 5), 5)
    row = _changed(pg, surf)[:, 5]
    for start in range(0, 60, 10):
        assert row[start + 1:start + 5].all() and not row[start + 7:start + 9].any()
    assert not row[62:].any() and _changed(pg, surf).sum() == row.sum()


@pytest.mark.parametrize("p0", [(-1000.0, 5.0), (-37.0, 5.0), (-1006.5, 5.0)])
def test_dashes_keep_their_place_when_the_line_is_clipped(pg, p0):
    # the same line drawn whole on a wide surface and clipped on a narrow one
    shift = 1200.0
    wide, narrow = _sea(pg, 1400, 10), _sea(pg, 100, 10)
    layers.dashed_line(pg, wide, st.ROUTE, (p0[0] + shift, 5), (90.0 + shift, 5), 7)
    layers.dashed_line(pg, narrow, st.ROUTE, p0, (90.0, 5), 7)
    np.testing.assert_array_equal(_changed(pg, narrow), _changed(pg, wide)[1200:1300])
    assert _changed(pg, narrow).any()


def test_dashed_lines_outside_the_surface_or_of_no_length_draw_nothing(pg):
    surf = _sea(pg, 100, 100)
    layers.dashed_line(pg, surf, st.ROUTE, (-500, -50), (500, -50), 4)
    layers.dashed_line(pg, surf, st.ROUTE, (150, -500), (150, 500), 4)
    layers.dashed_line(pg, surf, st.ROUTE, (50, 50), (50, 50), 4)
    assert not _changed(pg, surf).any()


def test_clip_keeps_the_part_inside_the_padded_view():
    t = layers._clip(np.array([-10.0, 5.0]), np.array([110.0, 5.0]), 100.0, 50.0, 0.0)
    assert t == pytest.approx((10.0 / 120.0, 110.0 / 120.0))
    t = layers._clip(np.array([-10.0, 5.0]), np.array([110.0, 5.0]), 100.0, 50.0, 5.0)
    assert t == pytest.approx((5.0 / 120.0, 115.0 / 120.0))
    assert layers._clip(np.array([10.0, 5.0]), np.array([20.0, 30.0]), 100.0, 50.0,
                        0.0) == (0.0, 1.0)
    assert layers._clip(np.array([10.0, -5.0]), np.array([90.0, -5.0]), 100.0, 50.0, 0.0) is None
    assert layers._clip(np.array([-10.0, 5.0]), np.array([5.0, -10.0]), 40.0, 40.0,
                        0.0) is None  # passes the corner


# -- routes -----------------------------------------------------------------------------------

def test_routes_are_dashed_from_the_start_with_rings_at_waypoints(pg):
    # start (0, 0) at pixel (100, 100); waypoints 500 m north (100, 50), then 500 m east
    surf = _sea(pg)
    route = np.array([[500.0, 0.0], [500.0, 500.0]])
    layers.draw_routes(pg, surf, _view(10.0), STYLE, _data(0.0, 0.0, routes=[route]))
    changed = _changed(pg, surf)
    assert _at(surf, 100, 97) == st.ROUTE  # first dash (6 px) from the start, northwards
    assert not changed[100, 89:94].any()  # first gap
    assert _at(surf, 100, 85) == st.ROUTE
    assert _at(surf, 115, 50) == st.ROUTE  # the leg east
    for x, y in ((100, 50), (150, 50)):  # rings of radius 3 px
        assert changed[x - 4:x - 1, y].any() and changed[x, y - 4:y - 1].any()
    assert not changed[103:106, 100].any() and not changed[95:98, 100].any()  # no ring at start
    assert not changed[:, 55:95][:99].any() and not changed[:, 55:95][102:].any()
    assert not changed[155:].any() and not changed[:, 55:][102:].any()


def test_ships_without_a_route_draw_none(pg):
    surf = _sea(pg)
    layers.draw_routes(pg, surf, _view(10.0), STYLE, _data(0.0, 0.0))
    assert not _changed(pg, surf).any()


# -- domains ----------------------------------------------------------------------------------

def test_domain_is_drawn_at_its_size_turned_with_the_heading(pg):
    # Goodwin's domain: 0.85 NM to starboard, 0.45 NM astern, 0.70 NM to port, whatever the
    # ship; heading east, starboard is south. At 20 m/px from pixel (120, 120):
    surf = _sea(pg, 240, 240)
    data = _data(0.0, 0.0, 90.0, ve=5.0, domain="goodwin")
    layers.draw_domains(pg, surf, _view(20.0, (120.0, 120.0), (240, 240)), STYLE, data, 0)
    colour = st.domain_colour(0)
    south, north, west = 120 + 0.85 * NM / 20, 120 - 0.70 * NM / 20, 120 - 0.45 * NM / 20
    assert _at(surf, 120, south) == colour
    assert _at(surf, 120, north) == colour
    assert _at(surf, west, 120) == colour
    for x, y in ((120, south + 3), (120, south - 3), (120, north - 3), (120, north + 3),
                 (west - 3, 120), (west + 3, 120), (120, 120)):
        assert _at(surf, x, y) == st.SEA, (x, y)


# -- CPA --------------------------------------------------------------------------------------

def _pair(b_north, b_east, a_vn=5.0, b_vn=-5.0, b_ve=0.0) -> RunData:
    """Ship a at the origin heading north, ship b elsewhere."""
    return _data([[0.0, b_north]], [[0.0, b_east]], [[0.0, 180.0]],
                 vn=[[a_vn, b_vn]], ve=[[0.0, b_ve]])


def test_cpa_of_a_head_on_pair_worked_out_by_hand():
    # closing at 10 m/s from 2 km: CPA in 200 s, 150 m apart
    (i, j, dcpa, tcpa), = layers.cpa_pairs(_pair(2000.0, 150.0), 0)
    assert (i, j) == (0, 1)
    assert dcpa == pytest.approx(150.0) and tcpa == pytest.approx(200.0)


@pytest.mark.parametrize(("b", "why"), [
    ((-2000.0, 150.0), "opening"),
    ((19_000.0, 150.0), "CPA after 30 minutes"),
    ((2000.0, 2.0 * NM), "CPA of 2 NM"),
])
def test_pairs_not_shown(b, why):
    assert layers.cpa_pairs(_pair(*b), 0) == [], why


def test_at_most_three_cpa_pairs_smallest_first():
    # four ships closing on the first from the north at 10 m/s, offsets east 400, 100, 900, 250
    east = [0.0, 400.0, 100.0, 900.0, 250.0]
    data = _data([[0.0, 2000.0, 2000.0, 2000.0, 2000.0]], [east],
                 vn=[[5.0, -5.0, -5.0, -5.0, -5.0]])
    got = layers.cpa_pairs(data, 0)
    assert [(i, j) for i, j, _, _ in got] == [(0, 2), (0, 4), (0, 1)]
    assert [d for _, _, d, _ in got] == pytest.approx([100.0, 250.0, 400.0])
    assert layers.cpa_pairs(_data(0.0, 0.0), 0) == []


@pytest.mark.parametrize(("b_east", "colour"), [(600.0, st.CPA_NEAR), (799.0, st.CPA_NEAR),
                                                (800.0, st.CPA_FAR), (1000.0, st.CPA_FAR)])
def test_cpa_points_and_vector_in_the_colour_of_the_range(pg, b_east, colour):
    # a heading north at 5 m/s meets b (600 m north) in 60 s, both 300 m north then. At 20 m/px
    # from pixel (60, 150): a now at (60, 150), at the CPA at (60, 135); b's CPA point east.
    surf = _sea(pg, 300, 200)
    text = layers.Text(pg, STYLE)
    view = _view(20.0, (60.0, 150.0), (300, 200))
    layers.draw_cpa(pg, surf, view, STYLE, text, _pair(600.0, b_east), 0)
    assert _at(surf, 60, 135) == colour  # a's CPA point
    assert _at(surf, 68, 135) == colour  # the CPA vector (the label starts 4 px past its middle)
    # a's dashes (4 px, 4 px gaps) towards its CPA point
    assert _at(surf, 60, 146) == _at(surf, 60, 141) == colour
    assert _at(surf, 60, 145) == _at(surf, 60, 143) == st.SEA
    assert _at(surf, 60, 125) == st.SEA and _at(surf, 55, 150) == st.SEA


def _range_label_px(pg, range_px: float) -> np.ndarray:
    """Pixels changed left of the line of a pair closing head-on ``range_px`` apart (drawn
    vertically from pixel (150, 250) upwards at 20 m/px): only the range label draws there."""
    surf = _sea(pg, 300, 300)
    data = _data([[0.0, 20.0 * range_px]], [[0.0, 0.0]], [[0.0, 180.0]], vn=[[5.0, -5.0]])
    layers.draw_cpa(pg, surf, _view(20.0, (150.0, 250.0), (300, 300)), STYLE,
                    layers.Text(pg, STYLE), data, 0)
    return np.argwhere(_changed(pg, surf)[:147])


@pytest.mark.parametrize("range_px", [60.0, 79.0])
def test_a_short_present_range_is_not_labelled(pg, range_px):
    assert _range_label_px(pg, range_px).size == 0


@pytest.mark.parametrize("range_px", [81.0, 100.0, 150.0])
def test_a_long_present_range_is_labelled_left_of_its_middle(pg, range_px):
    label = _range_label_px(pg, range_px)
    assert label.size > 0
    middle_y = 250.0 - range_px / 2
    assert label[:, 0].max() <= 150 - 4 and label[:, 1].min() >= math.floor(middle_y)
    assert label[:, 1].max() < middle_y + 30


def test_a_present_range_of_exactly_80_px_is_labelled(pg):
    assert _range_label_px(pg, layers.RANGE_LABEL_PX).size > 0


def test_no_cpa_drawn_for_a_pair_opening(pg):
    surf = _sea(pg)
    layers.draw_cpa(pg, surf, _view(20.0), STYLE, layers.Text(pg, STYLE),
                    _pair(-600.0, 100.0), 0)
    assert not _changed(pg, surf).any()


def test_labels_are_drawn_to_the_right_of_each_ship(pg):
    # ships at pixels (60, 60) and (60, 160): name above the ship's row, role and speed on it
    surf = _sea(pg, 300, 220)
    text = layers.Text(pg, STYLE)
    data = _data([[400.0, -600.0]], [[-400.0, -400.0]], ve=[[5.0, 0.0]])
    layers.draw_labels(surf, _view(10.0, (100.0, 100.0), (300, 220)), STYLE, text, data, 0,
                       ["give way", "stand on"])
    changed = _changed(pg, surf)
    assert not changed[:70].any()  # nothing left of ship + 10 px
    line = text.height("small")
    for y in (60, 160):
        rows = changed[70:, y - line - 2:y + line + 2]
        assert rows[:, :line + 2].any() and rows[:, line + 2:].any()  # name, then role
    assert not changed[:, 60 + line + 2:160 - line - 2].any()


# -- tracks held by the focus ship ------------------------------------------------------------

def _tracks(tracked=(1, 1, 0)) -> Tracks:
    """Ship 0 tracks ship 1 at (0, 300) moving north at 2.5 m/s; ship 1 tracks ship 0 at
    (-500, -500); ship 0 tracks ship 2 at (500, -500) but holds no track of it."""
    one = np.ones((1, 3))
    return Tracks(np.array([0, 1, 0]), np.array([1, 0, 2]), one * [[0.0, -500.0, 500.0]],
                  one * [[300.0, -500.0, -500.0]], one * [[2.5, 0.0, 0.0]], one * 0.0,
                  np.array([tracked]))


def test_tracks_the_focus_ship_holds_are_squares_with_speed_vectors(pg):
    surf = _sea(pg)
    data = _data([[0.0, 0.0, 0.0]], [[0.0, 300.0, -500.0]], tracks=_tracks())
    layers.draw_other_tracks(pg, surf, _view(10.0), STYLE, data, 0, focus=0)
    # the square: 11 x 11 px around pixel (130, 100), hollow
    for x, y in ((125, 102), (135, 102), (130, 105), (127, 95), (125, 95), (135, 105)):
        assert _at(surf, x, y) == st.TRACK, (x, y)
    assert _at(surf, 128, 102) == st.SEA and _at(surf, 132, 98) == st.SEA
    assert _at(surf, 123, 102) == st.SEA and _at(surf, 130, 107) == st.SEA
    # 900 m in 6 minutes: the vector ends 90 px north
    assert _at(surf, 130, 50) == st.TRACK and _at(surf, 130, 11) == st.TRACK
    assert _at(surf, 130, 7) == st.SEA
    # ship 1's track of ship 0 and the track not held: not drawn
    changed = _changed(pg, surf)
    assert not changed[:120].any() and changed.sum() < 150


def test_no_tracks_or_none_held_draw_nothing(pg):
    surf = _sea(pg)
    data = _data([[0.0, 0.0, 0.0]], [[0.0, 300.0, -500.0]], tracks=_tracks((0, 1, 0)))
    layers.draw_other_tracks(pg, surf, _view(10.0), STYLE, data, 0, focus=0)
    data.tracks = None
    layers.draw_other_tracks(pg, surf, _view(10.0), STYLE, data, 0, focus=0)
    assert not _changed(pg, surf).any()


def test_tracks_without_a_position_are_skipped(pg):
    surf = _sea(pg)
    tracks = _tracks()
    tracks.north_m[0, 0] = np.nan
    data = _data([[0.0, 0.0, 0.0]], [[0.0, 300.0, -500.0]], tracks=tracks)
    layers.draw_other_tracks(pg, surf, _view(10.0), STYLE, data, 0, focus=0)
    assert not _changed(pg, surf).any()


# -- the parts that do not move ---------------------------------------------------------------

def _opaque_ink(surf, x, y) -> bool:
    return tuple(surf.get_at((x, y))) == (*st.INK, 255)


def _clear(surf, x, y) -> bool:
    return surf.get_at((x, y)).a == 0


@pytest.mark.parametrize(("m_per_px", "width", "bar_px"), [(NM / 100.0, 1000, 200),
                                                           (1.0, 600, 100),
                                                           (NM / 40.0, 1000, 200)])
def test_scale_bar_is_a_round_length_to_scale(pg, m_per_px, width, bar_px):
    # a fifth of 1000 px at 100 px/NM is 2 NM; of 600 px at 1 m/px 120 m, rounded to 100 m;
    # of 1000 px at 40 px/NM 5 NM, 200 px
    text = layers.Text(pg, STYLE)
    surf = layers.scale_bar(pg, _view(m_per_px), STYLE, text, width)
    y0 = surf.get_height() - STYLE.px(2)
    for x in (0, bar_px // 3, bar_px):
        assert _opaque_ink(surf, x, y0), x
    assert _clear(surf, bar_px + 2, y0)
    for x in (0, bar_px // 2, bar_px):  # ticks 5 px high at both ends and in the middle
        assert _opaque_ink(surf, x, y0 - 4), x
    assert _clear(surf, bar_px // 4, y0 - 4) and _clear(surf, 0, y0 - 7)


def test_north_arrow_points_up(pg):
    surf = layers.north_arrow(pg, STYLE, layers.Text(pg, STYLE))
    arrow, half = 28, 7
    top, mid = surf.get_height() - arrow - 1, surf.get_width() // 2
    alpha = pg.surfarray.array_alpha(surf)

    def width(row):
        return int(np.count_nonzero(alpha[:, top + row]))

    assert width(2) < width(8) < width(16)
    assert width(16) == pytest.approx(2 * half * 16 / arrow, abs=2)
    assert _opaque_ink(surf, mid, top + 15)
    assert _clear(surf, mid, top + arrow - 2)  # the notch at the tail
    assert width(arrow - 2) >= 2
    assert _clear(surf, 0, top + 2) and _clear(surf, surf.get_width() - 1, top + 2)


def test_legend_draws_each_kind_of_sample(pg):
    colours = [(200, 0, 0), (0, 200, 0), (0, 0, 200), (200, 200, 0), (0, 200, 200),
               (200, 0, 200), (100, 50, 0)]
    kinds = ["line", "thin", "dash", "dot", "square", "hull", "ring"]
    text = layers.Text(pg, STYLE)
    surf = layers.legend(pg, STYLE, text, [(k, k, c) for k, c in zip(kinds, colours,
                                                                        strict=True)])
    line_h = text.height("small") + 2
    assert surf.get_height() == 7 * line_h + 8
    w, h = surf.get_size()
    for x, y in ((0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1), (w // 2, 0)):
        assert _at(surf, x, y) == st.FAINT
    lx = 6
    ly = [4 + row * line_h + line_h // 2 for row in range(7)]

    def at(dx, row, dy=0):
        return _at(surf, lx + dx, ly[row] + dy)

    line, thin, dash, dot, square, hull, ring = range(7)
    assert at(0, line) == at(11, line) == at(22, line) == at(11, line, 1) == colours[line]
    assert at(11, line, 2) == at(11, line, -1) == st.PANEL
    assert at(11, thin) == colours[thin] and at(11, thin, -1) == at(11, thin, 1) == st.PANEL
    assert at(1, dash) == at(9, dash) == at(17, dash) == colours[dash]
    assert at(6, dash) == at(14, dash) == at(22, dash) == st.PANEL
    assert at(10, dot, -1) == at(11, dot) == colours[dot] and at(13, dot) == st.PANEL
    assert at(7, square) == at(15, square) == at(11, square, 4) == colours[square]
    assert at(11, square) == st.PANEL and at(5, square) == st.PANEL
    assert at(11, hull) == at(2, hull, 2) == colours[hull] and at(11, hull, 4) == st.PANEL
    assert colours[ring] in [at(0, ring, dy) for dy in range(-2, 2)]
    assert at(11, ring) == st.PANEL and at(-1, ring) == st.PANEL


def test_panel_is_a_framed_white_box_at_the_top_left(pg):
    surf = _sea(pg, 400, 200)
    text = layers.Text(pg, STYLE)
    lines = [("run  t = 0:00:00", st.INK), ("a second line", st.INK), ("third", st.COLLISION)]
    layers.draw_panel(pg, surf, STYLE, text, lines)
    heights = [text.render(t, c, "normal" if r == 0 else "small", st.PANEL).get_height()
               for r, (t, c) in enumerate(lines)]
    bottom = 12 + sum(heights) + 8 - 1
    assert _at(surf, 12, 12) == st.FAINT and _at(surf, 12, bottom) == st.FAINT
    assert _at(surf, 13, 13) == st.PANEL and _at(surf, 13, bottom - 1) == st.PANEL
    assert _at(surf, 11, 11) == st.SEA and _at(surf, 12, bottom + 1) == st.SEA
    empty = _sea(pg, 400, 200)
    layers.draw_panel(pg, empty, STYLE, text, [])
    assert not _changed(pg, empty).any()


def test_text_is_cached_per_string_colour_size_and_background(pg):
    text = layers.Text(pg, STYLE)
    a = text.render("a", st.INK)
    assert text.render("a", st.INK) is a
    others = [text.render("a", st.FAINT), text.render("a", st.INK, "small"),
              text.render("a", st.INK, background=st.PANEL), text.render("b", st.INK)]
    assert all(o is not a for o in others)
    assert text.render("a", st.INK) is a


def test_text_cache_drops_the_least_recently_used(pg):
    text = layers.Text(pg, STYLE)
    text.CACHE = 2
    a, b = text.render("a", st.INK), text.render("b", st.INK)
    text.render("a", st.INK)  # used again: now b is the oldest
    text.render("c", st.INK)
    assert text.render("a", st.INK) is a
    assert text.render("b", st.INK) is not b



# -- lines to points far off the view -----------------------------------------------------------

def _far_leg(pg, kind):
    """A leg from (0, 0) to (10 km N, 20 km E) at 0.01 m/px from pixel (100, 100): the far end
    is 2,000,000 px east and 1,000,000 px north, beyond the clip."""
    surf = _sea(pg)
    view = _view(0.01)
    if kind == "route":
        data = _data(0.0, 0.0, routes=[np.array([[10000.0, 20000.0]])])
        layers.draw_routes(pg, surf, view, STYLE, data)
    else:
        data = _data([[0.0], [10000.0]], [[0.0], [20000.0]])
        layers.draw_tracks(pg, surf, view, STYLE, data, 0, 1, False,
                           stepwise=kind == "track_stepwise")
    return surf


@pytest.mark.parametrize("kind", ["route", "track", "track_stepwise"])
def test_a_line_to_a_far_point_keeps_its_bearing(pg, kind):
    """The leg climbs 1 px for every 2 px east (10 km north over 20 km east): at column 180
    it passes row 100 - 80 / 2 = 60, and nothing is drawn near the 45-degree row 20 the
    clipped end (1e6, -999900) would give."""
    changed = _changed(pg, _far_leg(pg, kind))
    near_true = changed[170:191, 50:71].any()
    assert near_true and not changed[170:191, :40].any()


@pytest.mark.parametrize("heading", [37.0, 251.0])
def test_hull_and_speed_vector_move_with_the_ship_pixel_for_pixel(pg, heading):
    """A ship 256 m east and 128 m south of another at 8 m/px is drawn 32 px right and 16 px
    lower, the same pixels shifted (hull, outline and speed vector)."""
    view = _view(8.0, (80.0, 90.0), (220, 220))
    kw = dict(heading_deg=heading, vn=3.0 * math.cos(math.radians(heading)),
              ve=3.0 * math.sin(math.radians(heading)), length_m=400.0, beam_m=64.0)
    a, b = _sea(pg, 220, 220), _sea(pg, 220, 220)
    layers.draw_hulls(pg, a, view, STYLE, _data(0.0, 0.0, **kw), 0)
    layers.draw_hulls(pg, b, view, STYLE, _data(-128.0, 256.0, **kw), 0)
    pa, pb = pg.surfarray.array3d(a), pg.surfarray.array3d(b)
    np.testing.assert_array_equal(pb[32:, 16:], pa[:-32, :-16])
    assert _changed(pg, a).sum() > 200


def test_cpa_pairs_agree_with_brute_force_and_ignore_ship_order():
    """DCPA and TCPA of three ships on straight tracks against the smallest distance found by
    stepping every pair 0.05 s at a time over the horizon; listing the ships in reverse
    order gives the same pairs (indices mapped back)."""
    north = np.array([0.0, 1500.0, -400.0])
    east = np.array([0.0, 900.0, 1200.0])
    vn, ve = np.array([4.0, -3.0, 2.0]), np.array([1.0, -2.5, -3.5])
    got = layers.cpa_pairs(_data([north], [east], vn=[vn], ve=[ve]), 0)
    t = np.arange(0.0, layers.CPA_HORIZON_S, 0.05)
    assert got
    for i, j, dcpa, tcpa in got:
        d = np.hypot(north[j] - north[i] + (vn[j] - vn[i]) * t,
                     east[j] - east[i] + (ve[j] - ve[i]) * t)
        assert dcpa == pytest.approx(d.min(), abs=0.01)
        assert tcpa == pytest.approx(t[np.argmin(d)], abs=0.05)
    rev = layers.cpa_pairs(_data([north[::-1]], [east[::-1]], vn=[vn[::-1]], ve=[ve[::-1]]), 0)
    back = sorted((min(2 - i, 2 - j), max(2 - i, 2 - j), round(d, 6), round(t, 6))
                  for i, j, d, t in rev)
    assert back == sorted((i, j, round(d, 6), round(t, 6)) for i, j, d, t in got)
