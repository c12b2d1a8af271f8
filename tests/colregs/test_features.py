import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from trafficsim.colregs.domains import boundary_distance_m, contains, time_to_entry_s
from trafficsim.colregs.features import (
    INDEX,
    NAMES,
    Features,
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


def test_features_written_into_a_given_array():
    """``out`` receives the same values as a fresh array (its rows are the features' values);
    an array of another shape or layout is refused."""
    rng = np.random.default_rng(4)
    cols = [rng.uniform(-3000, 3000, 5) for _ in range(4)] + [rng.uniform(0, 6, 5),
                                                             np.full(5, 150.0)]
    cols += [rng.uniform(-3000, 3000, 5) for _ in range(4)] + [np.full(5, 120.0)]
    want = pair_features(*cols, "coldwell", 5.0, 600.0).values
    table = np.full((len(NAMES) + 3, 5), -1.0)
    got = pair_features(*cols, "coldwell", 5.0, 600.0, out=table[: len(NAMES)])
    assert np.shares_memory(got.values, table)
    np.testing.assert_array_equal(table[: len(NAMES)], want)
    assert (table[len(NAMES):] == -1.0).all()
    for bad in (np.empty((len(NAMES), 4)), np.empty((5, len(NAMES))).T):
        with pytest.raises(ValueError, match="out must be"):
            pair_features(*cols, "coldwell", 5.0, 600.0, out=bad)


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


# ---------------------------------------------------------------------------------------------
# Conventions (NED: heading 0 = north, clockwise; body x forward, y starboard) by hand
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("heading_deg", "other", "bearing"), [
    # own heading east: north is on the port beam, south on the starboard beam, west astern
    (90.0, (1.0, 0.0), -90.0),
    (90.0, (0.0, 1.0), 0.0),
    (90.0, (-1.0, 0.0), 90.0),
    (90.0, (0.0, -1.0), 180.0),
    # own heading 225 (south-west): a ship due south lies 45 deg on the port bow,
    # one due west 45 deg on the starboard bow, one north-east dead astern
    (225.0, (-1.0, 0.0), -45.0),
    (225.0, (0.0, -1.0), 45.0),
    (225.0, (1.0, 1.0), 180.0),
    # heading 350: a ship due north is 10 deg on the starboard bow (across the 0/360 wrap)
    (350.0, (1.0, 0.0), 10.0),
])
def test_relative_bearing_in_ned(heading_deg, other, bearing):
    """Relative bearing = true bearing of the other minus own heading, folded to (-180, 180]."""
    f = one(ship(course_deg=heading_deg), ship(north_nm=other[0], east_nm=other[1]))
    assert angle_close(f["bearing_deg"], bearing, 1e-9)
    assert -180.0 < f["bearing_deg"] <= 180.0
    assert f["bearing_abs_deg"] == pytest.approx(abs(bearing), abs=1e-9)


def test_aspect_is_measured_from_the_other_ships_course_over_ground():
    """Other at the origin steering 045 at 10 kn; own ship 1 NM due south-east of her (true
    bearing 135 from her) lies 90 deg on her starboard beam, 1 NM due north-west lies on her
    port beam (-90), 1 NM north-east dead ahead (0); the other's heading is not an input."""
    other = ship(course_deg=45.0, speed_kn=10.0)
    d = 1.0 / math.sqrt(2.0)
    for (n, e), want in (((-d, d), 90.0), ((d, -d), -90.0), ((d, d), 0.0), ((-d, -d), 180.0)):
        f = one(ship(north_nm=n, east_nm=e, course_deg=200.0), other)
        assert angle_close(f["aspect_deg"], want, 1e-9), (n, e)
        assert f["aspect_abs_deg"] == pytest.approx(abs(want), abs=1e-9)


def test_course_difference_sign_and_wrap():
    """course_diff = other COG - own COG in (-180, 180]: 350 - 010 = -20, 010 - 350 = +20,
    090 - 000 = +90 (other steers to own starboard), 270 - 000 = -90."""
    for own_c, oth_c, want in ((10.0, 350.0, -20.0), (350.0, 10.0, 20.0), (0.0, 90.0, 90.0),
                               (0.0, 270.0, -90.0), (30.0, 210.0, 180.0)):
        f = one(ship(course_deg=own_c), ship(north_nm=3.0, course_deg=oth_c))
        assert angle_close(f["course_diff_deg"], want, 1e-9), (own_c, oth_c)
        assert -180.0 < f["course_diff_deg"] <= 180.0
        assert f["course_diff_abs_deg"] == pytest.approx(abs(want), abs=1e-9)


def test_bow_line_follows_the_heading_not_the_course_over_ground():
    """Own heading north but drifting east at 5 m/s (no speed ahead); a stopped ship 1000 m
    north and 3000 m east. Body frame = (north, east): y = 3000 m closing at 5 m/s, so it
    crosses the bow line after 600 s = 10 min, 1000 m ahead (0.54 NM); a bow line along the
    course over ground (east) would instead run through the target."""
    own = dict(n=0.0, e=0.0, vn=0.0, ve=5.0, h=0.0, L=100.0)
    other = dict(n=1000.0, e=3000.0, vn=0.0, ve=0.0, h=0.0, L=100.0)
    f = one(own, other)
    assert f["bct_min"] == pytest.approx(10.0)
    assert f["bcr_nm"] == pytest.approx(1000.0 / NM)
    assert f["bearing_deg"] == pytest.approx(math.degrees(math.atan2(3000.0, 1000.0)))
    # courses over ground: own east (the velocity), the stopped other parallel to it
    assert f["course_diff_deg"] == pytest.approx(0.0, abs=1e-12)
    # p . v = 3000 * (-5) = -15000, |v|^2 = 25: TCPA 600 s; DCPA = |p x v| / |v| = 1000 m
    assert f["tcpa_min"] == pytest.approx(10.0)
    assert f["dcpa_nm"] == pytest.approx(1000.0 / NM)


def test_course_fallbacks_at_the_speed_threshold():
    """Below 0.1 m/s a velocity is not a course: own course = heading, other course = own
    course; at 0.1 m/s and above the velocity direction counts."""
    slow, fast = 0.0999, 0.1001
    # own heading 090 but creeping north: below the threshold its course is 090
    own = dict(n=0.0, e=0.0, vn=slow, ve=0.0, h=math.pi / 2, L=100.0)
    other = dict(n=2000.0, e=0.0, vn=0.0, ve=-5.0, h=0.0, L=100.0)  # steering west
    assert one(own, other)["course_diff_deg"] == pytest.approx(180.0)
    own["vn"] = fast  # now its course over ground is north
    assert one(own, other)["course_diff_deg"] == pytest.approx(-90.0)
    # the other creeping south: taken parallel to own course (000) below, 180 above
    own = dict(n=0.0, e=0.0, vn=5.0, ve=0.0, h=0.0, L=100.0)
    other = dict(n=2000.0, e=0.0, vn=-slow, ve=0.0, h=0.0, L=100.0)
    g = one(own, other)
    assert g["course_diff_deg"] == pytest.approx(0.0, abs=1e-12)
    assert g["aspect_deg"] == pytest.approx(180.0)  # own ship dead astern of a "parallel" ship
    other["vn"] = -fast
    g = one(own, other)
    assert g["course_diff_deg"] == pytest.approx(180.0) and g["aspect_deg"] == pytest.approx(0.0)


def test_speed_ratio_at_the_stopped_threshold():
    """Stopped = below 1e-6 m/s: both stopped 1, only own stopped +inf, else the plain ratio."""
    def ratio(own_v, oth_v):
        return one(dict(n=0.0, e=0.0, vn=own_v, ve=0.0, h=0.0, L=100.0),
                   dict(n=500.0, e=0.0, vn=oth_v, ve=0.0, h=0.0, L=100.0))["speed_ratio"]
    assert ratio(0.0, 0.0) == 1.0
    assert ratio(5e-7, 9e-7) == 1.0
    assert ratio(5e-7, 2.0) == math.inf
    assert ratio(4.0, 0.0) == 0.0
    assert ratio(2e-6, 3e-6) == pytest.approx(1.5)
    assert ratio(4.0, 6.0) == pytest.approx(1.5)


def _scene(rng, n):
    return (rng.uniform(-9000, 9000, n), rng.uniform(-9000, 9000, n), rng.uniform(-8, 8, n),
            rng.uniform(-8, 8, n), rng.uniform(-7, 7, n), rng.uniform(50, 300, n),
            rng.uniform(-9000, 9000, n), rng.uniform(-9000, 9000, n), rng.uniform(-8, 8, n),
            rng.uniform(-8, 8, n))


def _rotate(a, b, turn):
    """(north, east) components turned clockwise by ``turn`` rad."""
    c, s = math.cos(turn), math.sin(turn)
    return c * a - s * b, s * a + c * b


def _call(cols, domain="coldwell"):
    on, oe, ovn, ove, h, L, tn, te, tvn, tve = cols
    return pair_features(on, oe, ovn, ove, h, L, tn, te, tvn, tve, L, domain, 4.0, 1800.0)


@pytest.mark.parametrize("domain", ["coldwell", "fujii", "goodwin", "kijima"])
def test_rotating_and_shifting_the_whole_scene_changes_no_feature(domain):
    """Every feature is relative: rotating every position, velocity and heading about a point
    by the same angle, then shifting the scene, leaves them all unchanged (angles mod 360)."""
    rng = np.random.default_rng(5)
    n = 4000
    cols = _scene(rng, n)
    base = _call(cols, domain).values
    on, oe, ovn, ove, h, L, tn, te, tvn, tve = cols
    for turn, shift in ((0.7, (1.0e4, -3.0e3)), (-2.9, (-5.0e4, 2.0e4)), (math.pi, (0, 0))):
        (on2, oe2), (tn2, te2) = _rotate(on, oe, turn), _rotate(tn, te, turn)
        moved = (on2 + shift[0], oe2 + shift[1], *_rotate(ovn, ove, turn), h + turn, L,
                 tn2 + shift[0], te2 + shift[1], *_rotate(tvn, tve, turn))
        got = _call(moved, domain).values
        angles = [INDEX[k] for k in ("bearing_deg", "aspect_deg", "course_diff_deg")]
        for row, name in enumerate(NAMES):
            a, b = base[row], got[row]
            if row in angles:
                diff = (a - b + 180.0) % 360.0 - 180.0
                assert np.abs(diff).max() < 1e-6, name
            elif name in ("time_to_domain_min", "bct_min", "tcpa_min", "bcr_nm"):
                fin = np.isfinite(a)
                assert (np.isfinite(b) == fin).mean() > 0.999, name
                both = fin & np.isfinite(b)
                np.testing.assert_allclose(b[both], a[both], rtol=1e-6, atol=1e-6, err_msg=name)
            else:
                np.testing.assert_allclose(b, a, rtol=1e-7, atol=1e-7, err_msg=name)


def test_heading_wrapped_by_whole_turns_gives_the_same_features():
    rng = np.random.default_rng(9)
    cols = list(_scene(rng, 2000))
    base = _call(cols).values
    for k in (-3, 1, 5):
        cols2 = list(cols)
        cols2[4] = cols[4] + 2.0 * math.pi * k
        np.testing.assert_allclose(_call(cols2).values, base, rtol=1e-9, atol=1e-9)


def test_one_vectorised_call_equals_pair_by_pair_calls():
    rng = np.random.default_rng(13)
    cols = _scene(rng, 40)
    allv = _call(cols).values
    for i in range(40):
        single = _call(tuple(c[i:i + 1] for c in cols)).values[:, 0]
        np.testing.assert_array_equal(single, allv[:, i])


def test_unknown_own_state_gives_nan_features_too():
    """NaN own heading or own velocity: every feature but visibility is NaN (so every
    comparison a rules file makes on them is false)."""
    for key in ("h", "vn", "n"):
        own = ship()
        own[key] = math.nan
        f = one(own, ship(north_nm=1.0), visibility_nm=0.7)
        assert all(math.isnan(v) for k, v in f.items() if k != "visibility_nm"), key
        assert f["visibility_nm"] == 0.7


def test_time_to_domain_at_the_horizon():
    """Head-on closing at 24 kn from 6 NM with a 200 m ship: the Coldwell domain dead ahead is
    5.8697 L; entry after (6 NM - 5.8697 L) / 24 kn. A horizon a hair longer sees it, a hair
    shorter does not."""
    L = 200.0
    t_entry = (6.0 * NM - (1.1 + 5.0 * math.sqrt(0.91)) * L) / (24.0 * KN)
    pair = (ship(length_m=L), ship(north_nm=6.0, course_deg=180.0))
    f = one(*pair, horizon_s=t_entry + 1e-6)
    assert f["time_to_domain_min"] == pytest.approx(t_entry / 60.0, rel=1e-9)
    assert f["predicted_domain_entry"] == 1.0
    f = one(*pair, horizon_s=t_entry - 1e-6)
    assert f["time_to_domain_min"] == math.inf and f["predicted_domain_entry"] == 0.0


def test_time_to_domain_zero_only_inside_on_a_goodwin_sector_edge():
    """Other ship 1024 m out exactly on the 247.5 deg edge (a power-of-two multiple of the edge's
    unit vector, so it lies on the edge in floating point), no relative motion. The module
    docstring: an edge belongs to the first sector clockwise from the bow, the astern one
    (0.45 NM = 833 m): the ship is outside, so time_to_domain_min must be +inf, not 0."""
    c, s = math.cos(math.radians(247.5)), math.sin(math.radians(247.5))
    own = dict(n=0.0, e=0.0, vn=0.0, ve=5.0, h=0.0, L=100.0)
    other = dict(n=1024.0 * c, e=1024.0 * s, vn=0.0, ve=5.0, h=0.0, L=100.0)
    f = one(own, other, domain="goodwin", horizon_s=600.0)
    assert f["domain_nm"] == pytest.approx(0.45)
    assert f["range_to_domain_nm"] > 0.0
    assert f["time_to_domain_min"] == math.inf


def test_zero_range_measures_the_domain_along_the_bow():
    """The other ship exactly at own position: range 0, the domain distance is taken dead
    ahead (Coldwell crossing ellipse: 1.1 L + 5 L sqrt(1 - 0.3^2) = 5.8697 L), so the other is
    inside (range_to_domain = -5.8697 L) and the entry time is 0."""
    L = 120.0
    f = one(ship(length_m=L), ship(course_deg=90.0))
    ahead = (1.1 + 5.0 * math.sqrt(0.91)) * L
    assert f["range_nm"] == 0.0
    assert f["domain_nm"] == pytest.approx(ahead / NM)
    assert f["range_to_domain_nm"] == pytest.approx(-ahead / NM)
    assert f["time_to_domain_min"] == 0.0 and f["predicted_domain_entry"] == 1.0
    assert f["bearing_deg"] == 0.0 and f["dcpa_nm"] == 0.0 and f["tcpa_min"] == 0.0


# ---------------------------------------------------------------------------------------------
# Port / starboard mirror, bow crossings on sampled tracks, wrap at north, degenerate cases
# ---------------------------------------------------------------------------------------------

_SIDE_ANGLES = ("bearing_deg", "aspect_deg", "course_diff_deg")
_DOMAIN_ROWS = ("domain_nm", "range_to_domain_nm", "time_to_domain_min",
                "predicted_domain_entry")


def _mirror(cols):
    """The scene reflected in the north axis: east -> -east, headings and courses negated."""
    on, oe, ovn, ove, h, L, tn, te, tvn, tve = cols
    return on, -oe, ovn, -ove, -h, L, tn, -te, tvn, -tve


@pytest.mark.parametrize("domain", ["coldwell", "fujii", "goodwin", "kijima"])
def test_mirror_image_swaps_port_and_starboard(domain):
    """Reflecting the whole scene port for starboard negates every side angle (bearing,
    aspect, course difference; 180 stays 180, the fold is (-180, 180]) and leaves every
    distance, time and speed as it was. Fujii's ellipse is symmetric about the bow line, so
    its domain features are unchanged too; the other domains are lopsided (Coldwell offset to
    starboard, Goodwin 0.85 / 0.70 NM, Kijima R_stbd > R_port) and are not compared."""
    rng = np.random.default_rng(17)
    cols = _scene(rng, 4000)
    a = _call(cols, domain).values
    b = _call(_mirror(cols), domain).values
    for name in NAMES:
        r = INDEX[name]
        if name in _SIDE_ANGLES:
            d = (a[r] + b[r] + 180.0) % 360.0 - 180.0
            assert np.abs(d).max() < 1e-9, name
            assert (b[r] > -180.0).all() and (b[r] <= 180.0).all(), name
        elif name in _DOMAIN_ROWS and domain != "fujii":
            continue
        else:
            same = (a[r] == b[r]) | np.isclose(a[r], b[r], rtol=1e-9, atol=1e-9)
            assert same.all(), name


def test_mirror_of_imazu_case_2_is_a_crossing_from_port():
    """Imazu case 2 (TS 6 NM east steering 270) mirrored: TS 6 NM west steering 090. Own ship
    sees her 45 deg on the port bow, she sees own ship 45 deg on her starboard bow; DCPA 0,
    TCPA 30 min and the bow crossing at own ship's position after 30 min as in case 2."""
    f = one(ship(**OS), ship(east_nm=-6.0, course_deg=90.0))
    assert f["bearing_deg"] == pytest.approx(-45.0)
    assert f["aspect_deg"] == pytest.approx(45.0)
    assert f["course_diff_deg"] == pytest.approx(90.0)
    assert f["dcpa_nm"] == pytest.approx(0.0, abs=1e-9)
    assert f["tcpa_min"] == pytest.approx(30.0)
    assert f["bct_min"] == pytest.approx(30.0) and f["bcr_nm"] == pytest.approx(0.0, abs=1e-9)


def test_bow_crossing_against_sampled_tracks():
    """The bow crossing from the relative track itself: in own body frame (x forward, y to
    starboard) the other ship moves on a straight line; bct is where its sampled y changes sign
    (linear interpolation between 1 s samples of a +-2 h window) and bcr its x there. A track
    whose y never changes sign over a window far longer than |bct| must have bct = +inf."""
    rng = np.random.default_rng(23)
    n = 300
    cols = _scene(rng, n)
    f = _call(cols)
    on, oe, ovn, ove, h, _, tn, te, tvn, tve = cols
    c, s = np.cos(h), np.sin(h)
    pn, pe, vn, ve = tn - on, te - oe, tvn - ovn, tve - ove
    x, y = c * pn + s * pe, -s * pn + c * pe
    vx, vy = c * vn + s * ve, -s * vn + c * ve
    t = np.arange(-7200.0, 7200.0 + 0.5, 1.0)
    checked = 0
    for i in range(n):
        yt = y[i] + vy[i] * t
        flip = np.flatnonzero(np.sign(yt[:-1]) != np.sign(yt[1:]))
        bct_s, bcr_m = f["bct_min"][i] * 60.0, f["bcr_nm"][i] * NM
        if flip.size == 0:
            assert not abs(bct_s) < 7000.0, i
            continue
        k = flip[0]
        t0 = t[k] + yt[k] / (yt[k] - yt[k + 1])  # linear y: exact up to rounding
        assert bct_s == pytest.approx(t0, abs=1e-6 * max(1.0, abs(t0))), i
        assert bcr_m == pytest.approx(x[i] + vx[i] * t0, rel=1e-6, abs=1e-3), i
        checked += 1
    assert checked > 100


def test_crossing_ahead_and_astern_by_hand_on_a_turned_heading():
    """Own heading 060 at 10 kn; a stopped ship 2 NM ahead on the bow line and 1 NM to
    starboard of it. Relative motion is own velocity reversed, straight astern along the bow
    line, so the other never crosses it (bcr = bct = +inf). Give the other 10 kn on course 330
    (due port across own bow): she crosses the bow line when she has covered the 1 NM, after
    6 min, when own ship has run 1 NM: 2 - 1 = 1 NM ahead."""
    h = 60.0
    b = math.radians(h)
    fwd, stbd = (math.cos(b), math.sin(b)), (-math.sin(b), math.cos(b))
    pos = (2.0 * fwd[0] + 1.0 * stbd[0], 2.0 * fwd[1] + 1.0 * stbd[1])
    own = ship(course_deg=h, speed_kn=10.0)
    f = one(own, ship(north_nm=pos[0], east_nm=pos[1], speed_kn=0.0))
    assert f["bcr_nm"] == math.inf and f["bct_min"] == math.inf
    assert f["bearing_deg"] == pytest.approx(math.degrees(math.atan2(1.0, 2.0)))
    g = one(own, ship(north_nm=pos[0], east_nm=pos[1], course_deg=h - 90.0, speed_kn=10.0))
    assert g["bct_min"] == pytest.approx(6.0)
    assert g["bcr_nm"] == pytest.approx(1.0)
    assert g["course_diff_deg"] == pytest.approx(-90.0)
    # from astern of the bow line (2 NM abaft own ship) the crossing is 3 NM astern
    back = (-2.0 * fwd[0] + stbd[0], -2.0 * fwd[1] + stbd[1])
    k = one(own, ship(north_nm=back[0], east_nm=back[1], course_deg=h - 90.0, speed_kn=10.0))
    assert k["bct_min"] == pytest.approx(6.0) and k["bcr_nm"] == pytest.approx(-3.0)


@pytest.mark.parametrize(("heading_deg", "true_bearing_deg", "want"), [
    (359.9, 0.05, 0.15), (359.9, 359.8, -0.1), (0.1, 359.95, -0.15), (0.1, 0.2, 0.1),
    (-0.1, 0.05, 0.15), (720.1, 359.95, -0.15), (179.9, 180.05, 0.15), (180.1, 179.95, -0.15),
])
def test_relative_bearing_across_north_and_south(heading_deg, true_bearing_deg, want):
    """A target a fraction of a degree across north (or south) from own heading: the relative
    bearing is the small signed difference, never about +-360 (headings of -0.1 and 720.1 deg
    are the same as 359.9 and 0.1)."""
    b = math.radians(true_bearing_deg)
    f = one(ship(course_deg=heading_deg), ship(north_nm=2.0 * math.cos(b),
                                                east_nm=2.0 * math.sin(b)))
    assert f["bearing_deg"] == pytest.approx(want, abs=1e-9)
    assert f["bearing_abs_deg"] == pytest.approx(abs(want), abs=1e-9)


def test_courses_across_north_give_small_differences():
    """Own COG 359 and the other's 001 differ by +2 deg (the other is 2 deg to starboard of
    own course); aspect of a ship dead ahead of her across north: own ship 3 NM on her course
    000.5 sees nothing odd: aspect 0."""
    f = one(ship(course_deg=359.0), ship(north_nm=3.0, course_deg=1.0))
    assert f["course_diff_deg"] == pytest.approx(2.0)
    b = math.radians(0.5)
    g = one(ship(north_nm=3.0 * math.cos(b), east_nm=3.0 * math.sin(b), course_deg=200.0),
            ship(course_deg=0.5))
    assert g["aspect_deg"] == pytest.approx(0.0, abs=1e-9)


def test_same_position_moving_apart():
    """Both ships at one point, own north at 12 kn, the other east at 12 kn: the closest point
    is now (tcpa 0, dcpa 0); the other is on own bow line now (bct 0 at bcr 0); courses 90 deg
    apart; the other is inside every domain (time to domain 0)."""
    for domain in ("coldwell", "fujii", "goodwin", "kijima"):
        f = one(ship(), ship(course_deg=90.0), domain=domain)
        assert f["range_nm"] == 0.0
        assert f["tcpa_min"] == 0.0 and f["dcpa_nm"] == 0.0
        assert f["bct_min"] == 0.0 and f["bcr_nm"] == 0.0
        assert f["course_diff_deg"] == pytest.approx(90.0)
        assert f["range_to_domain_nm"] < 0.0 and f["time_to_domain_min"] == 0.0


@pytest.mark.parametrize("abeam_nm", [0.3, -0.3, 2.0])
def test_parallel_courses_in_company(abeam_nm):
    """Same course and speed, the other abeam (starboard for +): no relative motion, so no
    CPA (tcpa +inf, dcpa = range), no bow crossing, speed ratio 1, bearing +-90, and she is
    inside the domain now or never enters it."""
    f = one(ship(course_deg=30.0), dict(ship(course_deg=30.0),
                                        n=-abeam_nm * NM * math.sin(math.radians(30.0)),
                                        e=abeam_nm * NM * math.cos(math.radians(30.0))))
    assert f["range_nm"] == pytest.approx(abs(abeam_nm))
    assert f["tcpa_min"] == math.inf and f["dcpa_nm"] == pytest.approx(abs(abeam_nm))
    assert f["bcr_nm"] == math.inf and f["bct_min"] == math.inf
    assert f["speed_ratio"] == pytest.approx(1.0)
    assert f["bearing_deg"] == pytest.approx(math.copysign(90.0, abeam_nm))
    assert f["course_diff_deg"] == pytest.approx(0.0, abs=1e-9)
    assert f["time_to_domain_min"] in (0.0, math.inf)
    assert (f["time_to_domain_min"] == 0.0) == (f["range_to_domain_nm"] <= 0.0)


def test_parallel_courses_at_different_speeds_never_cross_the_bow_line():
    """Same course, the other 0.5 NM to starboard and faster: she runs parallel to own bow
    line (no crossing, bcr = +inf), the CPA is abeam at 0.5 NM when she draws level (1 NM
    astern, 6 kn faster: 10 min)."""
    own = ship(course_deg=0.0)
    f = one(own, ship(north_nm=-1.0, east_nm=0.5, speed_kn=18.0))
    assert f["bcr_nm"] == math.inf and f["bct_min"] == math.inf
    assert f["tcpa_min"] == pytest.approx(10.0)
    assert f["dcpa_nm"] == pytest.approx(0.5)
    assert f["speed_ratio"] == pytest.approx(1.5)


def test_no_relative_motion_threshold():
    """Relative speed squared at or below 1e-12 m^2/s^2 is no relative motion (tcpa +inf,
    dcpa = range); a relative speed of 2e-6 m/s closing head-on from 1000 m is motion:
    tcpa = 1000 / 2e-6 s, dcpa 0."""
    own = dict(n=0.0, e=0.0, vn=0.0, ve=0.0, h=0.0, L=100.0)
    still = one(own, dict(n=1000.0, e=0.0, vn=-0.9e-6, ve=0.0, h=0.0, L=100.0))
    assert still["tcpa_min"] == math.inf
    assert still["dcpa_nm"] == pytest.approx(1000.0 / NM)
    moving = one(own, dict(n=1000.0, e=0.0, vn=-2e-6, ve=0.0, h=0.0, L=100.0))
    assert moving["tcpa_min"] == pytest.approx(1000.0 / 2e-6 / 60.0)
    assert moving["dcpa_nm"] == pytest.approx(0.0, abs=1e-12)


def test_bow_crossing_threshold():
    """Relative speed across the bow line at most 1e-6 m/s never crosses it (+inf); 1e-4 m/s
    does: a ship 100 m to starboard, 500 m ahead, closing sideways at 1e-4 m/s crosses after
    1e6 s at 500 m ahead (no relative motion along the bow line)."""
    own = dict(n=0.0, e=0.0, vn=0.0, ve=0.0, h=0.0, L=100.0)
    f = one(own, dict(n=500.0, e=100.0, vn=0.0, ve=-0.9e-6, h=0.0, L=100.0))
    assert f["bcr_nm"] == math.inf and f["bct_min"] == math.inf
    g = one(own, dict(n=500.0, e=100.0, vn=0.0, ve=-1e-4, h=0.0, L=100.0))
    assert g["bct_min"] == pytest.approx(1e6 / 60.0)
    assert g["bcr_nm"] == pytest.approx(500.0 / NM)


@pytest.mark.parametrize(("other_kn", "overtaking"), [(12.0, False), (12.5, True), (11.5, False)])
def test_coldwell_overtaking_needs_the_ship_astern_to_be_faster(other_kn, overtaking):
    """A ship 1 NM dead astern on own course: the Coldwell overtaking ellipse (6 L astern)
    applies only when she is faster (Rule 13, "coming up with"); at equal or lower speed own
    ship gets the crossing ellipse, 5 L sqrt(1 - 0.3^2) - 1.1 L = 3.6697 L astern."""
    L = 100.0
    f = one(ship(length_m=L), ship(north_nm=-1.0, speed_kn=other_kn))
    want = 6.0 * L if overtaking else (5.0 * math.sqrt(0.91) - 1.1) * L
    assert f["domain_nm"] == pytest.approx(want / NM)


def test_coldwell_overtaking_seen_from_the_overtaking_ship_needs_the_beam_sector():
    """Own ship (12 kn) 1 NM from a 6 kn ship that steers north, seen from her 112.6 deg and
    112.4 deg off her bow: beyond 112.5 own ship is overtaking her (aspect > 112.5 and own
    faster), so own domain is the 6 L x 1.75 L overtaking ellipse; at 112.4 it is not."""
    L = 100.0
    for theta, overtaking in ((112.6, True), (112.4, False), (-112.6, True)):
        th = math.radians(theta)
        own = ship(north_nm=math.cos(th), east_nm=math.sin(th), course_deg=0.0, length_m=L)
        f = one(own, ship(speed_kn=6.0))
        assert abs(f["aspect_deg"]) == pytest.approx(abs(theta))
        b = math.radians(f["bearing_deg"])
        if overtaking:
            want = (math.cos(b) ** 2 / 36.0 + math.sin(b) ** 2 / 1.75**2) ** -0.5 * L
        else:
            want = float(boundary_distance_m("coldwell", b, L, 12.0 * KN, False))
        assert f["domain_nm"] * NM == pytest.approx(want, rel=1e-9), theta


def test_goodwin_edge_point_domain_agrees_with_contains():
    """Own heading north, both ships stopped, the other 859 m out on the 112.5 deg edge between
    the starboard (0.85 NM) and astern (0.45 NM) sectors. The domain module places this point
    inside (the edge belongs to the starboard sector, and 859 m < 1574 m) and the feature's
    time to domain is 0; range_to_domain_nm must then be <= 0 (the module docstring: inside
    exactly when range_to_domain_nm <= 0, "the two features never disagree")."""
    c1, s1 = math.cos(math.radians(112.5)), math.sin(math.radians(112.5))
    x, y = 859.0 * c1, 859.0 * s1
    still = dict(vn=0.0, ve=0.0, h=0.0, L=100.0)
    f = one(dict(still, n=0.0, e=0.0), dict(still, n=x, e=y), domain="goodwin")
    assert bool(contains("goodwin", x, y, 100.0, 0.0))
    assert f["time_to_domain_min"] == 0.0
    assert f["range_to_domain_nm"] <= 0.0
    assert f["domain_nm"] == pytest.approx(0.85)


def test_speed_ratio_at_exactly_the_stopped_speed():
    """STOPPED_MPS is "the speed below which a ship counts as stopped": at exactly 1e-6 m/s
    (sqrt(1e-6^2) is exactly 1e-6) a ship is not stopped. Own ship at 1e-6 m/s and the other
    at 3e-6 m/s: the plain ratio 3; own ship at rest and the other at exactly 1e-6 m/s: own
    ship stopped and the other not, +inf."""
    def ratio(own_v, oth_v):
        return one(dict(n=0.0, e=0.0, vn=own_v, ve=0.0, h=0.0, L=100.0),
                   dict(n=500.0, e=0.0, vn=oth_v, ve=0.0, h=0.0, L=100.0))["speed_ratio"]
    assert math.sqrt(1e-6 * 1e-6) == 1e-6
    assert ratio(1e-6, 3e-6) == pytest.approx(3.0)
    assert ratio(0.0, 1e-6) == math.inf
