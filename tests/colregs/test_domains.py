import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from trafficsim.colregs import domains
from trafficsim.colregs.domains import (
    DOMAINS,
    boundary_distance_m,
    contains,
    domain_code,
    time_to_entry_s,
)
from trafficsim.errors import InputError

NM = 1852.0
KN = 1852.0 / 3600.0
L = 100.0


def _deg(*bearings_deg: float) -> np.ndarray:
    return np.radians(np.array(bearings_deg, dtype=float))


def _boundary(kind: str, bearings_deg: list[float], length: float = L, speed: float = 6.0,
              overtaking: bool = False) -> np.ndarray:
    n = len(bearings_deg)
    return boundary_distance_m(kind, _deg(*bearings_deg), np.full(n, length), np.full(n, speed),
                               np.full(n, overtaking))


# ---------------------------------------------------------------------------------------------
# Hand numbers
# ---------------------------------------------------------------------------------------------

def test_coldwell_crossing_ellipse_along_the_body_axes():
    # ellipse ((x - 1.1L)/5L)^2 + ((y - 0.75L)/2.5L)^2 = 1 cut by the axes through own ship
    ahead = 1.1 + 5.0 * math.sqrt(1.0 - 0.3**2)  # y = 0: ((0 - 0.75)/2.5)^2 = 0.09
    astern = 5.0 * math.sqrt(1.0 - 0.3**2) - 1.1
    stbd = 0.75 + 2.5 * math.sqrt(1.0 - 0.22**2)  # x = 0: (1.1/5)^2 = 0.0484
    port = 2.5 * math.sqrt(1.0 - 0.22**2) - 0.75
    got = _boundary("coldwell", [0, 90, 180, 270]) / L
    assert got == pytest.approx([ahead, stbd, astern, port], rel=1e-12)
    assert got == pytest.approx([5.8697, 3.1887, 3.6697, 1.6887], abs=1e-4)


def test_coldwell_extents_are_6_1_3_9_3_25_1_75_lengths():
    b = np.linspace(0.0, 2 * np.pi, 200_001)
    r = boundary_distance_m("coldwell", b, np.full(b.size, L), np.zeros(b.size))
    x, y = r * np.cos(b) / L, r * np.sin(b) / L
    assert x.max() == pytest.approx(6.1, abs=1e-6)
    assert x.min() == pytest.approx(-3.9, abs=1e-6)
    assert y.max() == pytest.approx(3.25, abs=1e-6)
    assert y.min() == pytest.approx(-1.75, abs=1e-6)
    # the extreme points themselves, just inside and just outside
    pts_in = np.array([[6.099, 0.75], [-3.899, 0.75], [1.1, 3.249], [1.1, -1.749]]) * L
    pts_out = np.array([[6.101, 0.75], [-3.901, 0.75], [1.1, 3.251], [1.1, -1.751]]) * L
    for pts, want in ((pts_in, True), (pts_out, False)):
        got = contains("coldwell", pts[:, 0], pts[:, 1], np.full(4, L), np.zeros(4))
        assert got.tolist() == [want] * 4


def test_coldwell_overtaking_is_a_centred_6_by_1_75_ellipse():
    got = _boundary("coldwell", [0, 90, 180, 270], overtaking=True) / L
    assert got == pytest.approx([6.0, 1.75, 6.0, 1.75], rel=1e-12)
    # at 45 deg: r = (cos^2/6^2 + sin^2/1.75^2)^(-1/2)
    want = (0.5 / 36.0 + 0.5 / 1.75**2) ** -0.5
    assert _boundary("coldwell", [45], overtaking=True)[0] / L == pytest.approx(want, rel=1e-12)


def test_overtaking_flag_per_pair():
    b = _deg(0.0, 0.0)
    got = boundary_distance_m("coldwell", b, np.full(2, L), np.zeros(2), np.array([False, True]))
    assert got / L == pytest.approx([5.8697, 6.0], abs=1e-4)


def test_goodwin_sectors_and_radii_do_not_depend_on_length_or_speed():
    bearings = [0.0, 45.0, 112.4, 112.6, 180.0, 247.4, 247.6, 300.0, 359.9]
    want = np.array([0.85, 0.85, 0.85, 0.45, 0.45, 0.45, 0.70, 0.70, 0.70]) * NM
    for length, speed in ((50.0, 0.0), (400.0, 10.0)):
        assert _boundary("goodwin", bearings, length, speed) == pytest.approx(want, rel=1e-12)


def test_fujii_is_a_centred_ellipse_with_semi_axes_4_by_1_6_lengths():
    got = _boundary("fujii", [0, 90, 180, 270, 45]) / L
    r45 = 1.0 / math.sqrt(0.5 / 16.0 + 0.5 / 1.6**2)  # 2.1009 L
    assert got == pytest.approx([4.0, 1.6, 4.0, 1.6, r45], rel=1e-12)
    assert r45 == pytest.approx(2.1009, abs=1e-4)


def test_kijima_radii_at_12_knots():
    # log10(12) = 1.079181; k_AD = 10^(0.3591 * 1.079181 + 0.0952) = 10^0.482734 = 3.03902;
    # k_DT = 10^(0.5441 * 1.079181 - 0.0795) = 10^0.507682 = 3.21871;
    # s = sqrt(3.03902^2 + 1.60936^2) = 3.43885
    fore, aft = 1 + 1.34 * 3.43885, 1 + 0.67 * 3.43885  # 5.60806, 3.30403
    stbd, port = 0.2 + 3.21871, 0.2 + 0.75 * 3.21871  # 3.41871, 2.61403
    got = _boundary("kijima", [0, 90, 180, 270], speed=12.0 * KN) / L
    assert got == pytest.approx([fore, stbd, aft, port], rel=2e-5)
    # quarter-ellipse between the bow and the starboard beam
    r45 = 1.0 / math.sqrt(0.5 / fore**2 + 0.5 / stbd**2)
    assert _boundary("kijima", [45], speed=12.0 * KN)[0] / L == pytest.approx(r45, rel=2e-5)


def test_kijima_at_rest_is_one_length_fore_and_aft_and_a_fifth_abeam():
    got = _boundary("kijima", [0, 90, 180, 270], speed=0.0) / L
    assert got == pytest.approx([1.0, 0.2, 1.0, 0.2], rel=1e-12)


def test_kijima_grows_with_speed():
    r = np.array([_boundary("kijima", [0, 90, 180, 270], speed=v * KN) for v in (4, 8, 16)])
    assert (np.diff(r, axis=0) > 0).all()


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------

def test_registry_suggests_the_closest_name_on_a_typo():
    with pytest.raises(InputError) as err:
        boundary_distance_m("goodwn", 0.0, L, 0.0)
    assert err.value.key == "domain"
    assert "did you mean 'goodwin'" in str(err.value)
    with pytest.raises(InputError, match="did you mean 'coldwell'"):
        contains("Coldwell", 0.0, 0.0, L, 0.0)
    with pytest.raises(InputError, match="known domains"):
        time_to_entry_s("ellipse", 0.0, 0.0, 0.0, 0.0, L, 0.0, None, 60.0)


def test_every_registered_domain_has_a_code_and_contains_own_ship():
    for kind in DOMAINS:
        assert DOMAINS[domain_code(kind)] == kind
        assert bool(contains(kind, 0.0, 0.0, L, 5.0))
        r = boundary_distance_m(kind, np.linspace(-7, 7, 1001), np.full(1001, L),
                                np.full(1001, 5.0))
        assert np.isfinite(r).all() and (r > 0).all()


def test_scalars_broadcast():
    got = boundary_distance_m("fujii", _deg(0.0, 90.0), L, 0.0)
    assert got == pytest.approx([400.0, 160.0])
    assert np.shape(contains("fujii", 10.0, 0.0, L, 0.0)) == ()


# ---------------------------------------------------------------------------------------------
# Time to entry: hand cases
# ---------------------------------------------------------------------------------------------

def _entry(kind, x, y, vx, vy, length=L, speed=6.0, overtaking=False, horizon=3600.0):
    a = np.atleast_1d
    return time_to_entry_s(kind, a(float(x)), a(float(y)), a(float(vx)), a(float(vy)),
                           a(float(length)), a(float(speed)), a(overtaking), horizon)[0]


def test_entry_time_dead_ahead_closing():
    ahead = (1.1 + 5.0 * math.sqrt(0.91)) * L
    assert _entry("coldwell", 2000.0, 0.0, -10.0, 0.0) == pytest.approx((2000.0 - ahead) / 10.0)


def test_entry_time_zero_inside_and_inf_when_missing_or_beyond_the_horizon():
    assert _entry("coldwell", 100.0, 50.0, 5.0, 5.0) == 0.0
    assert _entry("coldwell", 2000.0, 1000.0, -10.0, 0.0) == math.inf  # passes wide to starboard
    assert _entry("coldwell", 2000.0, 0.0, 10.0, 0.0) == math.inf  # opening
    assert _entry("coldwell", 2000.0, 0.0, -10.0, 0.0, horizon=100.0) == math.inf
    assert _entry("coldwell", 2000.0, 0.0, 0.0, 0.0) == math.inf  # no relative motion
    assert _entry("coldwell", 100.0, 0.0, 0.0, 0.0) == 0.0
    for kind in DOMAINS:  # a negative look-ahead sees nothing ahead, even right next to it
        assert _entry(kind, 2.0 * NM, 0.0, -20.0, 0.0, horizon=-1.0) == math.inf


def test_goodwin_entry_respects_the_sectors():
    # a target crossing astern from starboard to port 700 m behind own ship: out of the
    # 0.85 NM starboard sector (it would need y > 700 tan 67.5 = 1690 m, i.e. range > 1829 m),
    # it enters the 0.45 NM astern circle where y^2 = (0.45 NM)^2 - 700^2
    y_in = math.sqrt((0.45 * NM) ** 2 - 700.0**2)
    assert _entry("goodwin", -700.0, 2000.0, 0.0, -5.0) == pytest.approx((2000.0 - y_in) / 5.0)
    # 1000 m behind: beyond the astern radius, and where the starboard or port sector is
    # reached the range exceeds its radius, so never inside (a circle of the largest radius
    # would say otherwise)
    assert _entry("goodwin", -1000.0, 3000.0, 0.0, -5.0) == math.inf
    # abeam to starboard, closing: enters at 0.85 NM
    assert _entry("goodwin", 0.0, 2 * NM, 0.0, -5.0) == pytest.approx(1.15 * NM / 5.0)


def test_kijima_entry_on_the_port_quarter():
    fore, aft, port = _boundary("kijima", [0, 180, 270], speed=12 * KN)
    # approaching along the port beam (x = 0 line), enters at R_port
    assert _entry("kijima", 0.0, -3000.0, 0.0, 4.0, speed=12 * KN) == pytest.approx(
        (3000.0 - port) / 4.0)
    # approaching from dead astern: enters at R_aft
    assert _entry("kijima", -3000.0, 0.0, 5.0, 0.0, speed=12 * KN) == pytest.approx(
        (3000.0 - aft) / 5.0)
    # running down the port side 200 m off, parallel to the bow line: the larger starboard
    # quarter-ellipses never apply; enters the fore-port quarter at x^2/R_fore^2 + y^2/R_port^2 = 1
    x_in = fore * math.sqrt(1.0 - (200.0 / port) ** 2)
    assert _entry("kijima", 3000.0, -200.0, -6.0, 0.0, speed=12 * KN) == pytest.approx(
        (3000.0 - x_in) / 6.0)


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------

kinds = st.sampled_from(DOMAINS)
coord = st.floats(-6000.0, 6000.0, allow_nan=False)
lengths = st.floats(20.0, 400.0)
speeds = st.floats(0.0, 15.0)


@settings(max_examples=400, deadline=None)
@given(kinds, coord, coord, lengths, speeds, st.booleans())
def test_contains_agrees_with_boundary_distance(kind, x, y, length, speed, overtaking):
    r = math.hypot(x, y)
    b = float(boundary_distance_m(kind, math.atan2(y, x), length, speed, overtaking))
    inside = bool(contains(kind, x, y, length, speed, overtaking))
    if abs(r - b) > 1e-9 * max(b, 1.0):
        assert inside == (r < b)


def _track_margin(kind, x, y, vx, vy, length, speed, overtaking, t):
    """Range minus boundary distance along the line of sight at times ``t`` (< 0 inside)."""
    px, py = x + vx * t, y + vy * t
    n = t.size
    b = boundary_distance_m(kind, np.arctan2(py, px), np.full(n, length), np.full(n, speed),
                            np.full(n, overtaking))
    return np.hypot(px, py) - b


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kinds, coord, coord, st.floats(-3000.0, 3000.0), st.floats(-3000.0, 3000.0),
       st.one_of(st.floats(-2400.0, -120.0), st.floats(120.0, 2400.0)), lengths, speeds,
       st.booleans())
@example("kijima", 32.0, 1.0, 32.0, 0.0, 120.0, 32.0, 0.0, False)  # tangent at the bow point
def test_time_to_entry_agrees_with_brute_force_stepping(kind, x, y, aim_x, aim_y, t_aim,
                                                        length, speed, overtaking):
    # aim the straight track at a point near own ship (passed in the past when t_aim < 0), so
    # that many cases enter the domain
    vx, vy = (aim_x - x) / t_aim, (aim_y - y) / t_aim
    horizon = 1800.0
    dt = 0.05
    t = np.arange(0.0, horizon + dt / 2, dt)
    n = t.size
    hit = contains(kind, x + vx * t, y + vy * t, np.full(n, length), np.full(n, speed),
                   np.full(n, overtaking))
    got = float(time_to_entry_s(kind, x, y, vx, vy, length, speed, overtaking, horizon))
    assert 0.0 <= got <= horizon or got == math.inf
    if hit.any() and got == math.inf:
        # only a touch: the track meets the boundary (contains() counts it) but never goes
        # inside, e.g. a line tangent to the domain's foremost point
        assert _track_margin(kind, x, y, vx, vy, length, speed, overtaking,
                             t[hit]).min() >= -1e-6 * length
    elif hit.any():
        first = t[np.argmax(hit)]
        assert first - dt - 1e-6 <= got <= first + 1e-9
    elif math.isfinite(got):
        # only a graze shorter than the step: the track must reach the boundary at `got`
        near = np.linspace(max(got - dt, 0.0), min(got + dt, horizon), 2001)
        margin = _track_margin(kind, x, y, vx, vy, length, speed, overtaking, near)
        assert margin.min() <= 1e-6 * length
    if got == 0.0:
        assert hit[0]


@pytest.mark.parametrize("kind", DOMAINS)
def test_time_to_entry_on_many_tracks_across_sectors_and_quadrants(kind):
    """Tracks from a ring around own ship towards points spread over the domain, many of them
    crossing a sector edge or a body axis before they enter, against fine time stepping."""
    rng = np.random.default_rng(11)
    n, horizon, dt = 1500, 900.0, 0.25
    length = rng.uniform(60.0, 300.0, n)
    speed = rng.uniform(0.0, 9.0, n)
    overtaking = rng.random(n) < 0.3
    reach = 1.3 * np.max([boundary_distance_m(kind, np.full(n, b), length, speed, overtaking)
                          for b in np.radians(np.arange(0.0, 360.0, 5.0))], axis=0)
    ang, aim_ang = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n)
    x0 = reach * rng.uniform(1.0, 2.5, n) * np.cos(ang)
    y0 = reach * rng.uniform(1.0, 2.5, n) * np.sin(ang)
    ax, ay = reach * 0.9 * np.cos(aim_ang), reach * 0.9 * np.sin(aim_ang)
    t_aim = rng.uniform(200.0, 1200.0, n)
    vx, vy = (ax - x0) / t_aim, (ay - y0) / t_aim
    got = time_to_entry_s(kind, x0, y0, vx, vy, length, speed, overtaking, horizon)
    t = np.arange(0.0, horizon + dt / 2, dt)
    rep = lambda a: np.repeat(a, t.size)  # noqa: E731
    tt = np.tile(t, n)
    hit = contains(kind, rep(x0) + rep(vx) * tt, rep(y0) + rep(vy) * tt, rep(length),
                   rep(speed), rep(overtaking)).reshape(n, t.size)
    any_hit = hit.any(axis=1)
    first = np.where(any_hit, t[np.argmax(hit, axis=1)], np.inf)
    assert any_hit.mean() > 0.3  # the test exercises entries
    ok = np.where(any_hit, (got <= first + 1e-9) & (got >= first - dt - 1e-6), np.isinf(got))
    for i in np.flatnonzero(~ok):
        # allowed only for a graze shorter than the step: the track reaches the boundary there
        assert math.isfinite(got[i]) and not any_hit[i], (i, got[i], first[i])
        near = np.linspace(max(got[i] - dt, 0.0), min(got[i] + dt, horizon), 2001)
        margin = _track_margin(kind, x0[i], y0[i], vx[i], vy[i], length[i], speed[i],
                               overtaking[i], near)
        assert margin.min() <= 1e-6 * length[i]



# ---------------------------------------------------------------------------------------------
# Dimensions of shared/reference/colregs.md section 3, scaling and symmetry
# ---------------------------------------------------------------------------------------------

def _kijima_radii(v_kn: float) -> tuple[float, float, float, float]:
    """(fore, aft, stbd, port) in ship lengths, straight from colregs.md section 3 (log10 and
    powers of ten, not the module's exp / ln form)."""
    if v_kn == 0.0:
        k_ad = k_dt = 0.0
    else:
        k_ad = 10.0 ** (0.3591 * math.log10(v_kn) + 0.0952)
        k_dt = 10.0 ** (0.5441 * math.log10(v_kn) - 0.0795)
    s = math.sqrt(k_ad**2 + (k_dt / 2.0) ** 2)
    return 1.0 + 1.34 * s, 1.0 + 0.67 * s, 0.2 + k_dt, 0.2 + 0.75 * k_dt


@pytest.mark.parametrize("v_kn", [0.5, 1.0, 3.0, 7.5, 14.0, 22.0, 30.0])
def test_kijima_radii_follow_the_reference_formulas(v_kn):
    fore, aft, stbd, port = _kijima_radii(v_kn)
    got = _boundary("kijima", [0, 90, 180, 270], length=180.0, speed=v_kn * KN) / 180.0
    assert got == pytest.approx([fore, stbd, aft, port], rel=1e-12)
    # at 1 kn: log10 V = 0, k_AD = 10^0.0952 = 1.24509, k_DT = 10^-0.0795 = 0.83272;
    # sqrt(1.24509^2 + 0.41636^2) = 1.31286
    if v_kn == 1.0:
        assert stbd == pytest.approx(1.03272, abs=1e-5)
        assert port == pytest.approx(0.2 + 0.75 * 0.83272, abs=1e-5)
        assert fore == pytest.approx(1.0 + 1.34 * 1.31286, abs=1e-5)
        assert aft == pytest.approx(1.0 + 0.67 * 1.31286, abs=1e-5)


@pytest.mark.parametrize("bearing_deg", [30.0, 150.0, 210.0, 300.0])
def test_kijima_quarter_ellipses_between_the_axes(bearing_deg):
    """In each quadrant the boundary is the quarter-ellipse with that quadrant's radii:
    r = (cos^2 / a^2 + sin^2 / b^2)^(-1/2)."""
    fore, aft, stbd, port = _kijima_radii(10.0)
    b = math.radians(bearing_deg)
    a_ = fore if math.cos(b) > 0 else aft
    b_ = stbd if math.sin(b) > 0 else port
    want = (math.cos(b) ** 2 / a_**2 + math.sin(b) ** 2 / b_**2) ** -0.5
    got = _boundary("kijima", [bearing_deg], speed=10.0 * KN)[0] / L
    assert got == pytest.approx(want, rel=1e-12)


def test_kijima_speed_sign_does_not_matter():
    b = np.radians(np.arange(0.0, 360.0, 15.0))
    n = b.size
    fwd = boundary_distance_m("kijima", b, np.full(n, L), np.full(n, 6.0))
    back = boundary_distance_m("kijima", b, np.full(n, L), np.full(n, -6.0))
    np.testing.assert_array_equal(fwd, back)


@pytest.mark.parametrize("kind", ["coldwell", "fujii", "kijima"])
def test_length_scaled_domains_scale_with_length(kind):
    """Coldwell, Fujii and Kijima are multiples of L: doubling L doubles every distance
    (at a fixed speed); Coldwell and Fujii do not depend on speed at all."""
    b = np.radians(np.arange(0.0, 360.0, 7.5))
    n = b.size
    for ov in (False, True):
        one = boundary_distance_m(kind, b, np.full(n, 120.0), np.full(n, 5.0), np.full(n, ov))
        two = boundary_distance_m(kind, b, np.full(n, 240.0), np.full(n, 5.0), np.full(n, ov))
        np.testing.assert_allclose(two, 2.0 * one, rtol=1e-12)
        if kind != "kijima":
            other_speed = boundary_distance_m(kind, b, np.full(n, 120.0), np.full(n, 11.0),
                                              np.full(n, ov))
            np.testing.assert_allclose(other_speed, one, rtol=1e-12)


def test_symmetries_of_the_shapes():
    """Fujii and the Coldwell overtaking ellipse are centred: r(b) = r(-b) = r(180 - b). The
    Coldwell crossing ellipse is offset to starboard and Kijima's starboard radius exceeds its
    port one (0.2 + k_DT > 0.2 + 0.75 k_DT): both reach farther at b than at -b, 0 < b < 180."""
    b = np.radians(np.arange(1.0, 180.0, 3.0))
    n = b.size
    Ls, v = np.full(n, L), np.full(n, 5.0)
    for kind, ov in (("fujii", False), ("coldwell", True)):
        r = boundary_distance_m(kind, b, Ls, v, np.full(n, ov))
        np.testing.assert_allclose(boundary_distance_m(kind, -b, Ls, v, np.full(n, ov)), r,
                                   rtol=1e-12)
        np.testing.assert_allclose(boundary_distance_m(kind, np.pi - b, Ls, v, np.full(n, ov)),
                                   r, rtol=1e-12)
    stbd = boundary_distance_m("coldwell", b, Ls, v)
    port = boundary_distance_m("coldwell", -b, Ls, v)
    assert (stbd > port).all()
    assert (boundary_distance_m("kijima", b, Ls, v) > boundary_distance_m("kijima", -b, Ls, v)
            ).all()


def test_bearings_wrap():
    """A bearing and the same bearing plus whole turns give the same distance."""
    b = np.radians(np.arange(0.0, 360.0, 10.0)) + 0.01
    n = b.size
    for kind in DOMAINS:
        r = boundary_distance_m(kind, b, np.full(n, L), np.full(n, 5.0))
        for k in (-2, 1, 3):
            np.testing.assert_allclose(
                boundary_distance_m(kind, b + 2 * np.pi * k, np.full(n, L), np.full(n, 5.0)), r,
                rtol=1e-9)


def test_goodwin_edges_belong_to_the_first_sector_clockwise_from_the_bow():
    """The bow (0 deg) and the 112.5 deg edge are in the starboard sector (0.85 NM); the
    247.5 deg edge is in the astern sector (0.45 NM)."""
    got = _boundary("goodwin", [0.0, 112.5, 247.5]) / NM
    assert got == pytest.approx([0.85, 0.85, 0.45], rel=1e-12)
    c1, s1 = math.cos(math.radians(112.5)), math.sin(math.radians(112.5))
    c2, s2 = math.cos(math.radians(247.5)), math.sin(math.radians(247.5))
    # points on the edges (power-of-two multiples of the edge unit vectors: exactly on them)
    assert bool(contains("goodwin", 1024.0 * c1, 1024.0 * s1, L, 0.0))  # 1024 m < 0.85 NM
    assert not bool(contains("goodwin", 1024.0 * c2, 1024.0 * s2, L, 0.0))  # > 0.45 NM
    assert bool(contains("goodwin", 512.0 * c2, 512.0 * s2, L, 0.0))
    assert bool(contains("goodwin", 1500.0, 0.0, L, 0.0))  # dead ahead, 0.81 NM


def test_goodwin_entry_time_on_the_247_5_edge_agrees_with_contains():
    """A point 1024 m out exactly on the 247.5 deg edge, not moving relative to own ship: it is
    outside (contains: the astern sector, 833 m), so it never enters: +inf, not 0."""
    c2, s2 = math.cos(math.radians(247.5)), math.sin(math.radians(247.5))
    x, y = 1024.0 * c2, 1024.0 * s2
    assert not bool(contains("goodwin", x, y, L, 0.0))
    assert float(time_to_entry_s("goodwin", x, y, 0.0, 0.0, L, 0.0, None, 600.0)) == math.inf


def test_boundary_points_count_as_inside():
    """The boundary is inside: Fujii's bow point (4 L, 0) and beam point (0, 1.6 L) exactly;
    a relative 1e-9 beyond is outside."""
    pts = np.array([[4.0 * L, 0.0], [0.0, 1.6 * L], [-4.0 * L, 0.0], [0.0, -1.6 * L]])
    assert contains("fujii", pts[:, 0], pts[:, 1], L, 0.0).all()
    out = pts * (1.0 + 1e-9)
    assert not contains("fujii", out[:, 0], out[:, 1], L, 0.0).any()


def test_entry_time_at_the_horizon_boundary():
    """Closing from 2000 m dead ahead at 10 m/s on Fujii's 4 L = 400 m bow point: entry after
    160 s. A horizon of 160.000001 s sees it, 159.999 s does not."""
    assert _entry("fujii", 2000.0, 0.0, -10.0, 0.0, horizon=160.000001) == pytest.approx(160.0)
    assert _entry("fujii", 2000.0, 0.0, -10.0, 0.0, horizon=159.999) == math.inf
    assert _entry("fujii", 2000.0, 0.0, -10.0, 0.0, horizon=math.inf) == pytest.approx(160.0)
    assert _entry("fujii", 2000.0, 0.0, -10.0, 0.0, horizon=math.nan) == math.inf


def test_entry_through_the_side_of_an_ellipse():
    """Fujii (4 L x 1.6 L semi-axes), a track parallel to the bow line 80 m to starboard
    (y = 0.8 L), closing at 5 m/s from 1000 m ahead: enters where x = 4 L sqrt(1 - 0.5^2) =
    346.41 m, i.e. after (1000 - 346.41) / 5 = 130.72 s; 200 m off (y = 2 L > 1.6 L) never."""
    x_in = 4.0 * L * math.sqrt(1.0 - 0.25)
    assert _entry("fujii", 1000.0, 80.0, -5.0, 0.0) == pytest.approx((1000.0 - x_in) / 5.0)
    assert _entry("fujii", 1000.0, 200.0, -5.0, 0.0) == math.inf
    # already past own ship and opening: never
    assert _entry("fujii", -1000.0, 80.0, -5.0, 0.0) == math.inf


def test_output_shapes_and_bad_shapes():
    assert np.shape(boundary_distance_m("goodwin", 0.3, L, 1.0)) == ()
    assert np.shape(time_to_entry_s("goodwin", 5000.0, 0.0, -5.0, 0.0, L, 1.0, False,
                                    1000.0)) == ()
    assert boundary_distance_m("fujii", np.zeros(0), np.zeros(0), np.zeros(0)).shape == (0,)
    got = contains("fujii", np.array([0.0, 1e5]), 0.0, L, 0.0, np.array([True, False]))
    assert got.tolist() == [True, False]
    with pytest.raises(InputError) as err:
        boundary_distance_m("fujii", np.zeros((2, 2)), L, 0.0)
    assert err.value.key == "pairs"


# ---------------------------------------------------------------------------------------------
# The published shapes point by point, reach, straight runs at own ship, invariances
# ---------------------------------------------------------------------------------------------

def _published_points(kind: str, length: float, speed: float, overtaking: bool, t: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Boundary points (x forward, y starboard) written from colregs.md section 3, by the
    parametric form of each shape (not through the module's ray formula)."""
    if kind == "coldwell" and not overtaking:
        return 1.1 * length + 5.0 * length * np.cos(t), 0.75 * length + 2.5 * length * np.sin(t)
    if kind == "coldwell":
        return 6.0 * length * np.cos(t), 1.75 * length * np.sin(t)
    if kind == "fujii":
        return 4.0 * length * np.cos(t), 1.6 * length * np.sin(t)
    if kind == "goodwin":
        deg = np.degrees(t) % 360.0
        r = np.where(deg < 112.5, 0.85, np.where(deg < 247.5, 0.45, 0.70)) * NM
        return r * np.cos(t), r * np.sin(t)
    fore, aft, stbd, port = (length * r for r in _kijima_radii(speed / KN))
    c, s = np.cos(t), np.sin(t)
    return np.where(c >= 0, fore, aft) * c, np.where(s >= 0, stbd, port) * s


@pytest.mark.parametrize(("kind", "overtaking"), [
    ("coldwell", False), ("coldwell", True), ("fujii", False), ("goodwin", False),
    ("kijima", False)])
def test_points_of_the_published_shapes_lie_on_the_boundary(kind, overtaking):
    """720 points around each published shape (sector edges of Goodwin left out): the
    boundary distance along each point's bearing is its range, the point scaled by 1 - 1e-9
    is inside and by 1 + 1e-9 outside."""
    length, speed = 130.0, 9.0 * KN
    t = np.radians(np.arange(0.25, 360.0, 0.5))
    if kind == "goodwin":
        t = t[np.minimum(np.abs(np.degrees(t) - 112.5), np.abs(np.degrees(t) - 247.5)) > 0.1]
    x, y = _published_points(kind, length, speed, overtaking, t)
    n = x.size
    args = (np.full(n, length), np.full(n, speed), np.full(n, overtaking))
    r = boundary_distance_m(kind, np.arctan2(y, x), *args)
    np.testing.assert_allclose(r, np.hypot(x, y), rtol=1e-9)
    assert contains(kind, x * (1 - 1e-9), y * (1 - 1e-9), *args).all()
    assert not contains(kind, x * (1 + 1e-9), y * (1 + 1e-9), *args).any()


@pytest.mark.parametrize("kind", DOMAINS)
def test_reach_holds_the_whole_domain(kind):
    """The circle of radius reach_m (the cheap rejection of time_to_entry) holds every
    boundary point on a 0.05 deg bearing grid; for the shapes centred on own ship (Goodwin,
    Kijima, Fujii, Coldwell overtaking) it is the farthest boundary point itself."""
    b = np.radians(np.arange(0.0, 360.0, 0.05))
    for length, speed, ov in ((40.0, 0.0, False), (150.0, 6.0, True), (350.0, 14.0, False)):
        r = boundary_distance_m(kind, b, np.full(b.size, length), np.full(b.size, speed),
                                np.full(b.size, ov))
        prm = domains.ship_params(domain_code(kind), length, speed, ov)
        reach = domains.reach_m(domain_code(kind), prm)
        assert r.max() <= reach * (1.0 + 1e-12)
        if kind in ("goodwin", "kijima", "fujii") or ov:
            # centred shapes: the reach is the farthest boundary point itself
            assert reach == pytest.approx(r.max(), rel=1e-6)


@pytest.mark.parametrize("kind", DOMAINS)
def test_a_track_straight_at_own_ship_enters_at_the_boundary_of_its_bearing(kind):
    """A point 5000 m out on bearing b running straight at own ship at 7 m/s enters when its
    range falls to the boundary distance on that bearing: t = (5000 - R(b)) / 7, whatever
    sector or quadrant b lies in."""
    deg = np.arange(1.5, 360.0, 7.0)
    b = np.radians(deg)
    n = b.size
    length, speed = np.full(n, 120.0), np.full(n, 8.0)
    for ov in (False, True):
        R = boundary_distance_m(kind, b, length, speed, np.full(n, ov))
        x, y = 5000.0 * np.cos(b), 5000.0 * np.sin(b)
        got = time_to_entry_s(kind, x, y, -7.0 * np.cos(b), -7.0 * np.sin(b), length, speed,
                              np.full(n, ov), 3600.0)
        np.testing.assert_allclose(got, (5000.0 - R) / 7.0, rtol=1e-9)


@pytest.mark.parametrize(("kind", "ov"), [("fujii", False), ("coldwell", True)])
def test_port_starboard_mirror_of_centred_shapes(kind, ov):
    """Fujii and the Coldwell overtaking ellipse are symmetric about the bow line: a track
    mirrored port for starboard (y, vy negated) enters at the same time and a point mirrored
    is inside exactly when the point is."""
    rng = np.random.default_rng(31)
    n = 3000
    x, y = rng.uniform(-3000, 3000, n), rng.uniform(-3000, 3000, n)
    vx, vy = rng.uniform(-9, 9, n), rng.uniform(-9, 9, n)
    args = (np.full(n, 150.0), np.full(n, 5.0), np.full(n, ov))
    a = time_to_entry_s(kind, x, y, vx, vy, *args, 1800.0)
    b = time_to_entry_s(kind, x, -y, vx, -vy, *args, 1800.0)
    fin = np.isfinite(a)
    assert (np.isfinite(b) == fin).all()
    assert fin.mean() > 0.05
    np.testing.assert_allclose(b[fin], a[fin], rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(contains(kind, x, y, *args), contains(kind, x, -y, *args))


@pytest.mark.parametrize("kind", ["coldwell", "fujii", "kijima"])
def test_entry_time_is_unchanged_when_ship_and_geometry_scale_together(kind):
    """Coldwell, Fujii and (at a fixed speed) Kijima are multiples of L: scaling L, the
    position and the relative velocity by 2.5 gives the same entry times (times are lengths
    over speeds)."""
    rng = np.random.default_rng(37)
    n = 2000
    x, y = rng.uniform(-2500, 2500, n), rng.uniform(-2500, 2500, n)
    vx, vy = rng.uniform(-6, 6, n), rng.uniform(-6, 6, n)
    ov, sp = rng.random(n) < 0.5, np.full(n, 5.0)
    a = time_to_entry_s(kind, x, y, vx, vy, np.full(n, 80.0), sp, ov, 1800.0)
    k = 2.5
    b = time_to_entry_s(kind, k * x, k * y, k * vx, k * vy, np.full(n, k * 80.0), sp, ov,
                        1800.0)
    fin = np.isfinite(a)
    assert fin.mean() > 0.05
    assert (np.isfinite(b) == fin).mean() > 0.999
    both = fin & np.isfinite(b)
    np.testing.assert_allclose(b[both], a[both], rtol=1e-7, atol=1e-7)


def test_horizon_per_pair_and_infinite():
    """horizon_s may differ per pair: the same track (entry at 160 s on Fujii's bow point)
    is seen by a 200 s look-ahead, not by a 100 s one; an infinite look-ahead sees an entry
    however late (1e6 s away at 1e-3 m/s)."""
    got = time_to_entry_s("fujii", np.array([2000.0, 2000.0, 400.0 + 1000.0]), 0.0,
                          np.array([-10.0, -10.0, -1e-3]), 0.0, L, 0.0, None,
                          np.array([200.0, 100.0, math.inf]))
    assert got[0] == pytest.approx(160.0)
    assert got[1] == math.inf
    assert got[2] == pytest.approx(1e6, rel=1e-9)


@pytest.mark.parametrize("kind", [domains.COLDWELL, domains.FUJII, domains.GOODWIN,
                                  domains.KIJIMA])
def test_reach_bound_holds_the_domain_at_every_length_and_speed(kind: int) -> None:
    """The metrics skip sizing a domain beyond ``reach_bound_m``: it must not be below the
    reach at any speed, and (but for Kijima, which grows with speed) be the reach itself within
    its margin."""
    for length in (1.0, 7.3, 120.0, 399.9):
        bound = domains.reach_bound_m(kind, length)
        for speed in (0.0, 0.5, 5.0, 12.0, 40.0):
            reach = domains.reach_m(kind, domains.ship_params(kind, length, speed, False))
            assert bound >= reach * (1.0 + 1e-9)
            if kind != domains.KIJIMA:
                assert bound <= reach * (1.0 + 2e-6)
    assert domains.reach_bound_m(domains.KIJIMA, 100.0) == math.inf
