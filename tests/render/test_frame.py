"""Frames: ships where the view transform puts them, in their colours; frames that show
something; the same input giving the same picture however it is reached."""

import numpy as np
import pytest

from tests.render.conftest import Ship
from trafficsim.errors import InputError
from trafficsim.render import style as st
from trafficsim.render.data import load_run
from trafficsim.render.frame import FrameOptions, Renderer, clock
from trafficsim.units import NM

BARE = FrameOptions(size_px=(400, 300), legend=False, panel=False)


def _pixel(frame: np.ndarray, x: float, y: float) -> tuple:
    return tuple(int(c) for c in frame[int(np.floor(y)), int(np.floor(x))])


def _metres_to_px(north, east, centre_n, centre_e, m_per_px, origin):
    return origin[0] + (east - centre_e) / m_per_px, origin[1] - (north - centre_n) / m_per_px


def test_ships_are_drawn_at_their_pixels_in_their_colours(synthetic_run):
    ships = [Ship("a", 500.0, -300.0, 30.0, length_m=200.0, beam_m=40.0),
             Ship("b", 1500.0, 700.0, 250.0, length_m=150.0, beam_m=25.0)]
    renderer = Renderer(load_run(synthetic_run(ships, 3)), BARE)
    frame = renderer.array(2)
    # the fitted view, worked out by hand: both ships within the smallest extent (1 NM), 6 %
    # margins, centred between them in a 400 x 300 frame
    scale = NM / (0.88 * 300)
    assert renderer.view.m_per_px == pytest.approx(scale)
    for k, s in enumerate(ships):
        x, y = _metres_to_px(s.north_m, s.east_m, 1000.0, 200.0, scale, (200.0, 150.0))
        assert _pixel(frame, x, y) == st.ship_colour(k)
        psi = np.radians(s.heading_deg)
        ahead = 0.35 * s.length_m  # forward of the reference point, inside the bow taper
        xb, yb = _metres_to_px(s.north_m + ahead * np.cos(psi), s.east_m + ahead * np.sin(psi),
                               1000.0, 200.0, scale, (200.0, 150.0))
        assert _pixel(frame, xb, yb) == st.ship_colour(k)
        # to port, three beams off: open sea (labels are drawn to the right of the ship)
        side = 3.0 * s.beam_m
        xp, yp = _metres_to_px(s.north_m - side * np.sin(psi), s.east_m + side * np.cos(psi)
                               * -1.0, 1000.0, 200.0, scale, (200.0, 150.0))
        assert _pixel(frame, xp, yp) == st.SEA


def test_a_ship_followed_stays_at_the_centre_of_the_chart(synthetic_run):
    ships = [Ship("a", 0.0, 0.0, 90.0, speed_kn=20.0, length_m=300.0, beam_m=50.0),
             Ship("b", 4000.0, 0.0, 180.0, speed_kn=10.0)]
    run = synthetic_run(ships, 30)
    renderer = Renderer(load_run(run), FrameOptions(size_px=(400, 300), follow="a",
                                                    range_nm=1.0, legend=False, panel=False))
    assert renderer.view.m_per_px == pytest.approx(NM / 150.0)
    for k in (0, 12, 29):
        assert _pixel(renderer.array(k), 200, 150) == st.ship_colour(0)
    with pytest.raises(InputError, match="no ship 'c'"):
        Renderer(load_run(run), FrameOptions(follow="c"))


def test_frames_are_not_blank(synthetic_run):
    ships = [Ship("a", 0.0, 0.0, 45.0, speed_kn=15.0), Ship("b", 3000.0, 0.0, 135.0, 15.0)]
    renderer = Renderer(load_run(synthetic_run(ships, 60)), FrameOptions(size_px=(480, 360)))
    first, last = renderer.array(0), renderer.array(59)
    for frame in (first, last):
        colours = {tuple(c) for c in frame.reshape(-1, 3)[::7]}
        assert len(colours) > 20
        assert st.ship_colour(0) in colours and st.ship_colour(1) in colours
        assert st.INK in colours  # panel, legend, scale bar
        assert np.mean(np.any(frame != st.SEA, axis=2)) > 0.02
    assert np.mean(np.any(first != last, axis=2)) > 0.005  # the ships moved


@pytest.mark.parametrize("follow", [None, "a"])
def test_the_same_input_gives_the_same_picture(synthetic_run, follow):
    ships = [Ship("a", 0.0, 0.0, 10.0, speed_kn=12.0), Ship("b", 2500.0, 1500.0, 200.0, 9.0)]
    run = synthetic_run(ships, 40, turn_degps=0.2)
    options = FrameOptions(size_px=(320, 240), follow=follow, measurements=True)
    one, two = Renderer(load_run(run), options), Renderer(load_run(run), options)
    sequence = [one.array(k) for k in range(40)]
    # a fresh renderer drawing one frame alone, and the first going backwards
    for k in (0, 17, 39):
        np.testing.assert_array_equal(two.array(k), sequence[k])
    np.testing.assert_array_equal(one.array(5), sequence[5])


def test_dpi_scales_text_and_boxes(synthetic_run):
    ships = [Ship("a", 0.0, 0.0, 45.0, speed_kn=15.0), Ship("b", 3000.0, 0.0, 135.0, 15.0)]
    run = synthetic_run(ships, 20)

    def white(size, dpi):  # pixels of the panel and legend boxes
        frame = Renderer(load_run(run), FrameOptions(size_px=size, dpi=dpi)).array(19)
        return np.sum(np.all(frame == st.PANEL, axis=2))

    base = white((480, 360), 96.0)
    assert white((960, 720), 96.0) == base  # more pixels, same DPI: boxes keep their size
    assert white((960, 720), 192.0) == pytest.approx(4 * base, rel=0.1)  # twice each way


def test_a_ship_alone_at_rest(synthetic_run):
    renderer = Renderer(load_run(synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 1)), BARE)
    assert renderer.view.m_per_px == pytest.approx(NM / (0.88 * 300))  # the smallest extent
    assert _pixel(renderer.array(0), 200, 150) == st.ship_colour(0)


def test_clock():
    assert clock(0.0) == "0:00:00" and clock(3725.4) == "1:02:05"


@pytest.mark.parametrize("dpi", [9.9, 1201.0, 20000.0, float("nan")])
def test_a_dpi_out_of_range_is_refused_before_drawing(synthetic_run, dpi):
    """Far beyond 1200 DPI the text and legend surfaces grow past what SDL survives."""
    run = load_run(synthetic_run([Ship("a", 0.0, 0.0, 45.0, speed_kn=15.0)], 5))
    with pytest.raises(ValueError, match="dots per inch"):
        Renderer(run, FrameOptions(dpi=dpi))
    assert st.Style(1200.0).font_px(12) == 200


def test_frames_outside_the_records_are_refused_and_shapes_follow_the_size(synthetic_run):
    renderer = Renderer(load_run(synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 4)),
                        FrameOptions(size_px=(210, 130), legend=False, panel=False))
    for k in (-1, 4):
        with pytest.raises(IndexError, match=r"record .* outside 0 \.\. 3"):
            renderer.draw(k)
    frame = renderer.array(3)
    assert frame.shape == (130, 210, 3) and frame.dtype == np.uint8
    assert len(renderer.rgb(3)) == 210 * 130 * 3


def test_fixed_view_fits_every_record_inside_the_chart_area(synthetic_run):
    """With the panel and legend on, the fitted view keeps every true position of every record
    inside the chart area left of the legend and below the panel: the view's centre is the
    middle of that area, so it sits left of and below the middle of the frame."""
    ships = [Ship("a", 0.0, 0.0, 45.0, speed_kn=15.0), Ship("b", 3000.0, 0.0, 135.0, 15.0)]
    data = load_run(synthetic_run(ships, 30))
    renderer = Renderer(data, FrameOptions(size_px=(480, 360)))
    view = renderer.view
    assert view.origin_x_px < 240.0 and view.origin_y_px > 180.0
    left, top = 0.0, 2.0 * view.origin_y_px - 360.0
    right = 2.0 * view.origin_x_px
    x, y = view.to_px(data.north_m, data.east_m)
    assert np.all((x >= left) & (x <= right) & (y >= top) & (y <= 360.0))


def test_fit_to_overrides_the_points_a_fixed_view_shows(synthetic_run):
    """``fit_to`` replaces the records' positions: a 10 km square centred on (5 km, 5 km) in a
    frame without panel or legend gives the view ``fit`` makes of those points."""
    data = load_run(synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 3))
    square = (np.array([0.0, 10000.0]), np.array([0.0, 10000.0]))
    renderer = Renderer(data, BARE, fit_to=square)
    assert renderer.view.m_per_px == pytest.approx(10000.0 / (0.88 * 300))
    assert (renderer.view.centre_north_m, renderer.view.centre_east_m) == (5000.0, 5000.0)


def test_followed_ship_is_drawn_at_the_chart_centre_with_panel_and_legend(synthetic_run):
    """Following ship 'b' with the panel and legend on: 'b' sits on the view's origin (the
    middle of the chart area, below the panel) at every frame, while the other ship moves
    on the screen."""
    ships = [Ship("a", 0.0, 0.0, 90.0, speed_kn=20.0, length_m=300.0, beam_m=50.0),
             Ship("b", 1000.0, 500.0, 0.0, speed_kn=12.0, length_m=300.0, beam_m=50.0)]
    data = load_run(synthetic_run(ships, 20))
    renderer = Renderer(data, FrameOptions(size_px=(480, 360), follow="b", range_nm=1.0))
    view = renderer.view
    assert view.origin_y_px > 180.0  # the panel band pushes the chart down
    assert view.m_per_px == pytest.approx(NM / (0.5 * min(2 * view.origin_x_px,
                                                          2 * (360 - view.origin_y_px))))
    for k in (0, 10, 19):
        assert _pixel(renderer.array(k), view.origin_x_px, view.origin_y_px) == \
            st.ship_colour(1)


def test_a_followed_hull_is_at_the_centre_pointing_along_its_heading(synthetic_run):
    """Following 'a' (heading 60 deg, 250 m x 40 m) at 0.25 NM in 320 x 240 px: 463 m over
    120 px. At every frame the point 0.35 L ahead along the heading is in the ship's colour,
    three beams to port (bearing 330 deg, away from the labels on the right) is sea; the
    other ship sits at its offset from 'a' divided by the scale."""
    ships = [Ship("a", 0.0, 0.0, 60.0, speed_kn=12.0, length_m=250.0, beam_m=40.0),
             Ship("b", 150.0, -250.0, 60.0, speed_kn=12.0, length_m=250.0, beam_m=40.0)]
    options = FrameOptions(size_px=(320, 240), follow="a", range_nm=0.25, legend=False,
                           panel=False, domains=False)
    renderer = Renderer(load_run(synthetic_run(ships, 8)), options)
    scale = 0.25 * NM / 120.0
    assert renderer.view.m_per_px == pytest.approx(scale)
    psi = np.radians(60.0)
    for k in (0, 4, 7):
        frame = renderer.array(k)
        for north, east, colour in (
                (0.35 * 250.0 * np.cos(psi), 0.35 * 250.0 * np.sin(psi), st.ship_colour(0)),
                (120.0 * np.cos(psi - np.pi / 2), 120.0 * np.sin(psi - np.pi / 2), st.SEA),
                (150.0, -250.0, st.ship_colour(1))):
            x, y = 160.0 + east / scale, 120.0 - north / scale
            assert _pixel(frame, x, y) == colour, (k, north, east)


def test_a_fixed_view_draws_a_moving_hull_where_its_record_puts_it(synthetic_run):
    """A ship sailing south-west at 15 kn: at each frame its hull centre (the record's
    position through the fitted view, computed by hand) is in its colour, and its position
    of the first record is no longer (only the 2 px track is left there, in the same colour,
    so the pixel two beams off the old hull centre is sea)."""
    ships = [Ship("a", 0.0, 0.0, 225.0, speed_kn=15.0, length_m=200.0, beam_m=40.0)]
    data = load_run(synthetic_run(ships, 40, every_s=10.0))
    renderer = Renderer(data, BARE)
    v = renderer.view
    # 390 s at 15 kn is 3009.9 m south-west: spans 2128.3 m each way, 0.88 * 300 px high
    span = 15.0 * 1852.0 / 3600.0 * 390.0 / np.sqrt(2.0)
    assert v.m_per_px == pytest.approx(span / 264.0)
    assert (v.centre_north_m, v.centre_east_m) == pytest.approx((-span / 2, -span / 2))
    for k in (0, 20, 39):
        n, e = data.north_m[k, 0], data.east_m[k, 0]
        x, y = _metres_to_px(n, e, -span / 2, -span / 2, v.m_per_px, (200.0, 150.0))
        assert _pixel(renderer.array(k), x, y) == st.ship_colour(0)
    frame = renderer.array(39)
    beam = 2.0 * 40.0 / v.m_per_px  # north-west of the start, off the track
    assert _pixel(frame, 200.0 + 132.0 - beam / np.sqrt(2), 150.0 - 132.0 - beam / np.sqrt(2)) \
        == st.SEA


@pytest.mark.parametrize(("t_s", "text"), [(59.5, "0:01:00"), (3599.6, "1:00:00"),
                                           (86399.0, "23:59:59"), (90000.0, "25:00:00"),
                                           (0.49, "0:00:00")])
def test_clock_rounds_to_the_second_and_carries(t_s, text):
    """Seconds round first, then carry into minutes and hours (3599.6 s is one hour, not
    0:59:60); hours do not wrap at a day."""
    assert clock(t_s) == text


def test_the_array_is_the_rgb_bytes_row_by_row(synthetic_run):
    """``array(k)[y, x]`` is the pixel ``(x, y)`` of the surface ``draw(k)`` returns, and
    ``rgb(k)`` the same rows packed (top row first)."""
    renderer = Renderer(load_run(synthetic_run([Ship("a", 0.0, 0.0, 30.0, 8.0)], 3)),
                        FrameOptions(size_px=(90, 70), legend=False, panel=False))
    surf = renderer.draw(2)
    pixels = [tuple(surf.get_at((x, y)))[:3] for y in (0, 35, 69) for x in (0, 44, 89)]
    arr = renderer.array(2)
    assert [tuple(int(c) for c in arr[y, x]) for y in (0, 35, 69) for x in (0, 44, 89)] == \
        pixels
    assert renderer.rgb(2) == arr.tobytes()
