import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from trafficsim.colregs.domains import boundary_distance_m, time_to_entry_s
from trafficsim.colregs.features import (
    INDEX,
    NAMES,
    Features,
    fast_atan2,
    feature_index,
    pair_features,
)
from trafficsim.errors import InputError
from trafficsim.geometry import cpa

NM = 1852.0
KN = 1852.0 / 3600.0
IMAZU = Path(__file__).resolve().parents[3] / "shared" / "reference" / "imazu.yaml"


def ship(north_nm=0.0, east_nm=0.0, course_deg=0.0, speed_kn=12.0, heading_deg=None,
         length_m=100.0):
    c = math.radians(course_deg)
    h = math.radians(course_deg if heading_deg is None else heading_deg)
    v = speed_kn * KN
    return dict(n=north_nm * NM, e=east_nm * NM, vn=v * math.cos(c), ve=v * math.sin(c), h=h,
                L=length_m)


def features(pairs, domain="coldwell", visibility_nm=5.0, horizon_s=3600.0) -> Features:
    """Features of directed pairs given as a list of (own, other) ship dicts."""
    col = lambda who, key: np.array([p[who][key] for p in pairs], dtype=float)  # noqa: E731
    return pair_features(col(0, "n"), col(0, "e"), col(0, "vn"), col(0, "ve"), col(0, "h"),
                         col(0, "L"), col(1, "n"), col(1, "e"), col(1, "vn"), col(1, "ve"),
                         col(1, "L"), domain, visibility_nm, horizon_s)


def one(own, other, **kw) -> dict[str, float]:
    f = features([(own, other)], **kw)
    return {name: float(f[name][0]) for name in NAMES}


def angle_close(a, b, tol=1e-9):
    return abs((a - b + 180.0) % 360.0 - 180.0) <= tol


# ---------------------------------------------------------------------------------------------
# Hand-computed encounters
# ---------------------------------------------------------------------------------------------

def test_head_on():
    L = 200.0
    f = one(ship(length_m=L), ship(north_nm=6.0, course_deg=180.0), horizon_s=3600.0)
    assert f["range_nm"] == pytest.approx(6.0)
    assert f["bearing_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["aspect_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["course_diff_deg"] == pytest.approx(180.0)
    assert f["dcpa_nm"] == pytest.approx(0.0, abs=1e-12)
    assert f["tcpa_min"] == pytest.approx(15.0)  # 6 NM at 24 kn closing
    assert f["bcr_nm"] == math.inf and f["bct_min"] == math.inf  # runs along the bow line
    assert f["speed_ratio"] == pytest.approx(1.0)
    assert f["own_speed_kn"] == pytest.approx(12.0) and f["other_speed_kn"] == pytest.approx(12.0)
    ahead = (1.1 + 5.0 * math.sqrt(1.0 - 0.3**2)) * L  # Coldwell crossing ellipse, dead ahead
    assert f["domain_nm"] == pytest.approx(ahead / NM)
    assert f["range_to_domain_nm"] == pytest.approx(6.0 - ahead / NM)
    assert f["time_to_domain_min"] == pytest.approx((6.0 * NM - ahead) / (24.0 * KN) / 60.0)
    assert f["predicted_domain_entry"] == 1.0
    assert f["visibility_nm"] == 5.0
    # a horizon shorter than the entry time: no predicted entry
    f = one(ship(length_m=L), ship(north_nm=6.0, course_deg=180.0), horizon_s=600.0)
    assert f["time_to_domain_min"] == math.inf and f["predicted_domain_entry"] == 0.0


def test_crossing_from_starboard_at_90_degrees():
    # other 5 NM north, 4 NM east, steering west at 12 kn; own north at 12 kn
    f = one(ship(), ship(north_nm=5.0, east_nm=4.0, course_deg=270.0))
    assert f["range_nm"] == pytest.approx(math.hypot(5.0, 4.0))
    assert f["bearing_deg"] == pytest.approx(math.degrees(math.atan2(4.0, 5.0)))  # 38.66
    # own ship seen from the other: direction (-5, -4) is 218.66 deg true, its course 270
    assert f["aspect_deg"] == pytest.approx(math.degrees(math.atan2(-4.0, -5.0)) + 360 - 270)
    assert f["aspect_deg"] == pytest.approx(-51.34, abs=0.01)
    assert f["course_diff_deg"] == pytest.approx(-90.0)
    # p = (5, 4) NM, v = (-12, -12) kn: p.v = -108, |v|^2 = 288, |p x v| = 12
    assert f["tcpa_min"] == pytest.approx(108.0 / 288.0 * 60.0)  # 22.5 min
    assert f["dcpa_nm"] == pytest.approx(12.0 / math.sqrt(288.0))  # 0.7071 NM
    # crosses the bow line after 4 NM / 12 kn = 20 min, when own ship has run 4 of its 5 NM
    assert f["bct_min"] == pytest.approx(20.0)
    assert f["bcr_nm"] == pytest.approx(1.0)
    assert f["speed_ratio"] == pytest.approx(1.0)
    # domain along the line of sight: ray r (cos b, sin b) on the Coldwell crossing ellipse
    b = math.atan2(4.0, 5.0)
    r = np.roots([(math.cos(b) / 500) ** 2 + (math.sin(b) / 250) ** 2,
                  -2 * (110 * math.cos(b) / 500**2 + 75 * math.sin(b) / 250**2),
                  (110 / 500) ** 2 + (75 / 250) ** 2 - 1]).max()
    assert f["domain_nm"] == pytest.approx(r / NM)


def test_crossing_astern_has_negative_bow_crossing_range():
    # other 3 NM north, 4 NM east steering west at 12 kn: crosses own bow line after 20 min,
    # when own ship is at 4 NM, i.e. 1 NM astern of own ship
    f = one(ship(), ship(north_nm=3.0, east_nm=4.0, course_deg=270.0))
    assert f["bct_min"] == pytest.approx(20.0)
    assert f["bcr_nm"] == pytest.approx(-1.0)


def test_overtaking_uses_coldwell_overtaking_domain():
    L = 150.0
    own = ship(length_m=L)
    slow = ship(north_nm=1.0, speed_kn=6.0)
    f = one(own, slow)
    assert f["bearing_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["aspect_deg"] == pytest.approx(180.0, abs=1e-9)
    assert f["course_diff_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["tcpa_min"] == pytest.approx(10.0)  # 1 NM at 6 kn closing
    assert f["speed_ratio"] == pytest.approx(0.5)
    assert f["domain_nm"] == pytest.approx(6.0 * L / NM)  # overtaking ellipse, 6 L ahead
    assert f["time_to_domain_min"] == pytest.approx((NM - 6.0 * L) / (6.0 * KN) / 60.0)
    # the same two ships seen from the slower one: being overtaken, the faster one astern
    g = one(dict(slow, L=L), own)
    assert g["bearing_deg"] == pytest.approx(180.0, abs=1e-9)
    assert g["aspect_deg"] == pytest.approx(0.0, abs=1e-9)
    assert g["domain_nm"] == pytest.approx(6.0 * L / NM)  # 6 L astern
    assert g["speed_ratio"] == pytest.approx(2.0)
    # a faster ship ahead is not overtaken: crossing ellipse astern of it (3.67 L)
    h = one(dict(slow, L=L), ship(north_nm=-1.0, speed_kn=3.0))
    assert h["domain_nm"] == pytest.approx((5.0 * math.sqrt(1.0 - 0.3**2) - 1.1) * L / NM)


def test_goodwin_domain_feature_by_sector():
    own = ship()
    f = features([(own, ship(north_nm=2.0, east_nm=0.5)), (own, ship(north_nm=-2.0)),
                  (own, ship(east_nm=-2.0))], domain="goodwin")
    assert f["domain_nm"] == pytest.approx([0.85, 0.45, 0.70])


def test_stopped_ships_and_no_relative_motion():
    # own stopped heading east; other stopped 1 NM north: course from heading, other parallel
    own = ship(speed_kn=0.0, course_deg=90.0)
    f = one(own, ship(north_nm=1.0, speed_kn=0.0))
    assert f["bearing_deg"] == pytest.approx(-90.0)
    assert f["course_diff_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["aspect_deg"] == pytest.approx(90.0)  # own ship south of an east-lying target
    assert f["tcpa_min"] == math.inf and f["dcpa_nm"] == pytest.approx(1.0)
    assert f["bct_min"] == math.inf and f["bcr_nm"] == math.inf
    assert f["speed_ratio"] == 1.0
    assert f["time_to_domain_min"] == math.inf and f["predicted_domain_entry"] == 0.0
    # own stopped, other moving: infinite ratio; in company at equal velocity: no CPA
    assert one(own, ship(north_nm=1.0))["speed_ratio"] == math.inf
    g = one(ship(), ship(east_nm=0.5))
    assert g["tcpa_min"] == math.inf and g["dcpa_nm"] == pytest.approx(0.5)
    # already inside the domain: entry time 0
    h = one(ship(length_m=200.0), ship(north_nm=0.2, speed_kn=0.0))
    assert h["time_to_domain_min"] == 0.0 and h["range_to_domain_nm"] < 0.0


def test_bearing_is_relative_to_heading_and_course_diff_to_course_over_ground():
    # own heading 010 but drifting: course over ground 000; other 1 NM north on 000
    own = ship(course_deg=0.0, heading_deg=10.0)
    f = one(own, ship(north_nm=1.0))
    assert f["bearing_deg"] == pytest.approx(-10.0)
    assert f["course_diff_deg"] == pytest.approx(0.0, abs=1e-12)


def test_angles_in_half_open_range():
    # dead astern gives +180, never -180
    f = one(ship(), ship(north_nm=-1.0, course_deg=180.0))
    assert f["bearing_deg"] == pytest.approx(180.0, abs=1e-9)
    assert f["course_diff_deg"] == pytest.approx(180.0, abs=1e-9)


# ---------------------------------------------------------------------------------------------
# Imazu (colregs.md section 1): everything meets at the origin after 30 min
# ---------------------------------------------------------------------------------------------

OS = dict(north_nm=-6.0, east_nm=0.0, course_deg=0.0, speed_kn=12.0)


def test_imazu_case_1_head_on():
    f = one(ship(**OS), ship(north_nm=6.0, course_deg=180.0))
    assert f["range_nm"] == pytest.approx(12.0)
    assert f["dcpa_nm"] == pytest.approx(0.0, abs=1e-12)
    assert f["tcpa_min"] == pytest.approx(30.0)
    assert f["bearing_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["aspect_deg"] == pytest.approx(0.0, abs=1e-9)


def test_imazu_case_2_crossing_give_way():
    f = one(ship(**OS), ship(east_nm=6.0, course_deg=270.0))
    assert f["range_nm"] == pytest.approx(6.0 * math.sqrt(2.0))
    assert f["dcpa_nm"] == pytest.approx(0.0, abs=1e-9)
    assert f["tcpa_min"] == pytest.approx(30.0)
    assert f["bearing_deg"] == pytest.approx(45.0)
    assert f["aspect_deg"] == pytest.approx(-45.0)
    assert f["bct_min"] == pytest.approx(30.0) and f["bcr_nm"] == pytest.approx(0.0, abs=1e-9)


def _imazu_cases():
    if not IMAZU.exists():
        return []
    from trafficsim.io.yamlio import load_yaml

    return load_yaml(IMAZU).data["cases"]


@pytest.mark.skipif(not IMAZU.exists(), reason="shared reference imazu.yaml not present")
@pytest.mark.parametrize("case", _imazu_cases(), ids=lambda c: f"case{c['id']}")
def test_imazu_all_cases_against_the_reference_table(case):
    o = case["own_ship"]
    own = ship(o["y_nm"], o["x_nm"], o["course_deg"], o["speed_kn"])
    targets = case["targets"]
    f = features([(own, ship(t["y_nm"], t["x_nm"], t["course_deg"], t["speed_kn"]))
                  for t in targets])
    for k, t in enumerate(targets):
        d = t["derived"]
        # the table's positions are rounded to 1e-3 NM
        assert f["dcpa_nm"][k] == pytest.approx(d["dcpa_nm"], abs=5e-3)
        assert f["tcpa_min"][k] == pytest.approx(d["tcpa_min"], abs=0.1)
        assert f["range_nm"][k] == pytest.approx(d["range_nm"], abs=1e-3)
        assert angle_close(f["bearing_deg"][k], d["rel_bearing_from_os_deg"], 0.1)
        assert angle_close(f["aspect_deg"][k], d["aspect_os_seen_from_ts_deg"], 0.1)


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------

# micro-metre (per second) resolution: squares of sub-normal numbers would underflow
pos = st.floats(-20_000.0, 20_000.0, allow_nan=False).map(lambda v: round(v, 6))
vel = st.floats(-12.0, 12.0, allow_nan=False).map(lambda v: round(v, 6))
hdg = st.floats(-4.0, 10.0, allow_nan=False)
length = st.floats(30.0, 400.0)


@settings(max_examples=300, deadline=None)
@given(pos, pos, vel, vel, pos, pos, vel, vel, length, length, st.sampled_from(
    ["coldwell", "fujii", "goodwin", "kijima"]))
def test_pair_reversal_symmetry(n1, e1, vn1, ve1, n2, e2, vn2, ve2, l1, l2, domain):
    s1 = dict(n=n1, e=e1, vn=vn1, ve=ve1, h=math.atan2(ve1, vn1), L=l1)
    s2 = dict(n=n2, e=e2, vn=vn2, ve=ve2, h=math.atan2(ve2, vn2), L=l2)
    f = features([(s1, s2), (s2, s1)], domain=domain)
    for name in ("range_nm", "dcpa_nm", "tcpa_min"):
        assert f[name][0] == pytest.approx(f[name][1], rel=1e-9, abs=1e-9)
    assert np.isnan(f.values).sum() == 0
    if math.hypot(vn1, ve1) > 0.2 and math.hypot(vn2, ve2) > 0.2 and math.hypot(n2 - n1,
                                                                                e2 - e1) > 1:
        # heading = course over ground: what one sees as bearing, the other sees as aspect
        assert angle_close(f["bearing_deg"][0], f["aspect_deg"][1], 1e-7)
        assert angle_close(f["aspect_deg"][0], f["bearing_deg"][1], 1e-7)
        assert angle_close(f["course_diff_deg"][0], -f["course_diff_deg"][1], 1e-7)


@settings(max_examples=200, deadline=None)
@given(pos, pos, vel, vel, pos, pos, vel, vel)
def test_dcpa_tcpa_against_brute_force_minimisation(n1, e1, vn1, ve1, n2, e2, vn2, ve2):
    pn, pe, vn, ve = n2 - n1, e2 - e1, vn2 - vn1, ve2 - ve1
    assume(math.hypot(vn, ve) > 0.05)
    f = features([(dict(n=n1, e=e1, vn=vn1, ve=ve1, h=0.3, L=100.0),
                   dict(n=n2, e=e2, vn=vn2, ve=ve2, h=0.0, L=100.0))])
    dcpa_m, tcpa_s = f["dcpa_nm"][0] * NM, f["tcpa_min"][0] * 60.0
    rng = lambda t: np.hypot(pn + vn * t, pe + ve * t)  # noqa: E731
    t = np.linspace(-1e6, 1e6, 200_001)  # 10 s steps
    t0 = t[np.argmin(rng(t))]
    fine = np.linspace(t0 - 10.0, t0 + 10.0, 200_001)  # 1e-4 s steps
    r_min = rng(fine).min()
    # no sampled range is below the DCPA, and the grid gets within one step of it
    assert dcpa_m <= r_min + 1e-6
    assert r_min - dcpa_m <= math.hypot(vn, ve) * 1e-4 + 1e-6
    assert rng(np.array([tcpa_s]))[0] == pytest.approx(dcpa_m, rel=1e-9, abs=1e-6)
    if abs(tcpa_s) < 9e5:
        assert rng(np.array([tcpa_s]))[0] <= r_min + 1e-6
    # and the same numbers as the metrics' numpy CPA
    d_ref, t_ref = cpa(np.array([pn]), np.array([pe]), np.array([vn]), np.array([ve]))
    assert dcpa_m == pytest.approx(d_ref[0], rel=1e-9, abs=1e-6)
    assert tcpa_s == pytest.approx(t_ref[0], rel=1e-9, abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(pos, pos, vel, vel, hdg, pos, pos, vel, vel, length,
       st.sampled_from(["coldwell", "fujii", "goodwin", "kijima"]))
def test_domain_features_match_the_domain_module(n1, e1, vn1, ve1, h, n2, e2, vn2, ve2, L,
                                                 domain):
    f = features([(dict(n=n1, e=e1, vn=vn1, ve=ve1, h=h, L=L),
                   dict(n=n2, e=e2, vn=vn2, ve=ve2, h=0.0, L=100.0))], domain=domain,
                 horizon_s=1800.0)
    # own body frame, by rotating the earth-frame relative motion by -heading
    c, s = math.cos(h), math.sin(h)
    pn, pe, vn, ve = n2 - n1, e2 - e1, vn2 - vn1, ve2 - ve1
    x, y, vx, vy = c * pn + s * pe, -s * pn + c * pe, c * vn + s * ve, -s * vn + c * ve
    sog1, sog2 = math.hypot(vn1, ve1), math.hypot(vn2, ve2)
    overtaking = ((f["bearing_abs_deg"][0] > 112.5 and sog2 > sog1)
                  or (f["aspect_abs_deg"][0] > 112.5 and sog1 > sog2))
    los = math.atan2(y, x) if (x, y) != (0.0, 0.0) else 0.0  # along the bow at zero range
    want_dom = boundary_distance_m(domain, los, L, sog1, overtaking)
    assert f["domain_nm"][0] * NM == pytest.approx(float(want_dom), rel=1e-9)
    want_t = time_to_entry_s(domain, x, y, vx, vy, L, sog1, overtaking, 1800.0)
    got_t = f["time_to_domain_min"][0] * 60.0
    assert got_t == pytest.approx(float(want_t), rel=1e-7, abs=1e-6) or (
        got_t == math.inf and want_t == math.inf)
    assert f["predicted_domain_entry"][0] == float(math.isfinite(got_t))
    assert f["range_to_domain_nm"][0] == pytest.approx(f["range_nm"][0] - f["domain_nm"][0],
                                                       abs=1e-12)


@settings(max_examples=300, deadline=None)
@given(pos, pos, vel, vel, pos, pos, vel, vel, hdg, st.sampled_from(
    ["coldwell", "fujii", "goodwin", "kijima"]))
def test_inside_now_means_zero_time_to_domain(n1, e1, vn1, ve1, n2, e2, vn2, ve2, h, domain):
    f = features([(dict(n=n1, e=e1, vn=vn1, ve=ve1, h=h, L=300.0),
                   dict(n=n2 * 0.1, e=e2 * 0.1, vn=vn2, ve=ve2, h=0.0, L=100.0))],
                 domain=domain)
    assert (f["range_to_domain_nm"][0] <= 0.0) == (f["time_to_domain_min"][0] == 0.0)
    assert not np.isnan(f.values).any()


# ---------------------------------------------------------------------------------------------
# The angle kernel
# ---------------------------------------------------------------------------------------------

def test_fast_atan2_matches_the_library_everywhere():
    rng = np.random.default_rng(7)
    n = 200_000
    y = rng.normal(size=n) * 10.0 ** rng.uniform(-9, 9, n)
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-9, 9, n)
    err = max(abs(fast_atan2(a, b) - math.atan2(a, b)) for a, b in zip(y, x, strict=True))
    assert err < 2e-15
    # the axes, the diagonals and the octant edges
    for deg in np.arange(-180.0, 180.01, 22.5):
        a = math.radians(deg)
        assert fast_atan2(math.sin(a), math.cos(a)) == pytest.approx(math.atan2(math.sin(a),
                                                                               math.cos(a)),
                                                                    abs=2e-15)
    assert fast_atan2(0.0, -1.0) == math.pi and fast_atan2(0.0, 0.0) == 0.0
    assert math.isnan(fast_atan2(math.nan, 1.0)) and math.isnan(fast_atan2(1.0, math.nan))


@settings(max_examples=500, deadline=None)
@given(st.floats(-1e12, 1e12, allow_nan=False), st.floats(-1e12, 1e12, allow_nan=False))
def test_fast_atan2_property(y, x):
    assume(x != 0.0 or y != 0.0)
    assert fast_atan2(y, x) == pytest.approx(math.atan2(y, x), abs=2e-15)


# ---------------------------------------------------------------------------------------------
# API
# ---------------------------------------------------------------------------------------------

def test_names_index_and_views():
    assert len(set(NAMES)) == len(NAMES)
    assert {n: i for i, n in enumerate(NAMES)} == INDEX
    f = features([(ship(), ship(north_nm=1.0)), (ship(), ship(east_nm=2.0))])
    assert f.values.shape == (len(NAMES), 2) and f.values.dtype == np.float64
    assert f.n_pairs == 2
    row = f["range_nm"]
    assert np.shares_memory(row, f.values)
    assert row.tolist() == pytest.approx([1.0, 2.0])
    assert set(f.as_dict()) == set(NAMES)


def test_unknown_feature_suggests_a_name():
    f = features([(ship(), ship(north_nm=1.0))])
    with pytest.raises(InputError, match="did you mean 'dcpa_nm'") as err:
        f["dcpa_mn"]
    assert err.value.key == "feature"
    with pytest.raises(InputError, match="did you mean 'tcpa_min'"):
        feature_index("tcpa")


def test_bad_domain_and_shapes():
    with pytest.raises(InputError, match="did you mean 'kijima'"):
        features([(ship(), ship(north_nm=1.0))], domain="kijma")
    z = np.zeros(3)
    with pytest.raises(InputError, match=r"\(m,\) arrays"):
        pair_features(z, z, z, z, z, np.ones(3), z, z, z, z, np.ones(2), "fujii", 5.0, 60.0)


def test_unknown_other_state_gives_nan_features():
    unknown = dict(n=math.nan, e=math.nan, vn=math.nan, ve=math.nan, h=0.0, L=100.0)
    f = features([(ship(), unknown), (ship(), ship(north_nm=1.0))], visibility_nm=2.0)
    nan_rows = [n for n in NAMES if n != "visibility_nm"]
    assert all(math.isnan(f[n][0]) for n in nan_rows)
    assert f["visibility_nm"][0] == 2.0
    assert not np.isnan(f.values[:, 1]).any()


def test_visibility_per_pair_and_empty_input():
    f = features([(ship(), ship(north_nm=1.0)), (ship(), ship(east_nm=2.0))],
                 visibility_nm=np.array([0.5, 3.0]))
    assert f["visibility_nm"].tolist() == [0.5, 3.0]
    z = np.zeros(0)
    assert pair_features(z, z, z, z, z, z, z, z, z, z, z, "goodwin", 5.0, 60.0).values.shape == (
        len(NAMES), 0)
