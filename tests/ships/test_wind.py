"""Wind loads (Isherwood 1972) and their use in the ``mmg`` family."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from trafficsim.control.autopilot import rudder_command
from trafficsim.ships import base, wind
from trafficsim.ships.base import EAST, PSI, RPS, Actuators, Env, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.ships.mmg import FAMILY


def _ship(**particulars: float) -> dict[str, Any]:
    spec = copy.deepcopy(load_ship("kvlcc2"))
    spec["particulars"].update(particulars)
    return spec


def _loads(spec: dict[str, Any], wind_from_deg: float, speed: float = 20.0, heading_deg: float = 0,
           u: float = 0.0) -> tuple[float, float, float]:
    x = np.zeros((base.N_STATE, 1))
    x[PSI], x[U] = np.radians(heading_deg), u
    env = Env(wind_speed_mps=speed, wind_from_rad=np.radians(wind_from_deg))
    return tuple(float(f[0]) for f in wind.wind_loads(wind.build([spec]), x, env))


def test_table_regression_by_hand_at_a_table_angle_and_between() -> None:
    """Isherwood (1972) C_X at 0 deg and C_Y at 90 deg from the windage ratios, by hand."""
    spec = _ship()
    p = spec["particulars"]
    L, B = p["length_m"], p["beam_m"]
    a_l, a_f = p["windage_lateral_area_m2"], p["windage_frontal_area_m2"]
    c, s, a_ss = p["windage_centroid_from_bow_m"], p["windage_perimeter_m"], \
        p["windage_superstructure_area_m2"]
    params = wind.build([spec])
    cx0 = -(2.152 - 5.00 * 2 * a_l / L**2 + 0.243 * 2 * a_f / B**2 - 0.164 * L / B)
    # wind from port (our angle -90 deg): B0 + B2 2A_F/B^2 + B5 C/L at 90 deg, pushes to starboard
    cy90 = 0.889 + 0.138 * 2 * a_f / B**2 - 0.66 * c / L + 0.0 * a_ss + 0.0 * s
    got = wind.coefficients(params, np.radians([0.0, -90.0]))
    assert got[0][0] == pytest.approx(cx0, rel=1e-12)
    assert got[1][1] == pytest.approx(cy90, rel=1e-12)
    # linear interpolation between table angles: 45 deg is the mean of 40 and 50 deg
    mid = wind.coefficients(params, np.radians([45.0, 40.0, 50.0]))
    for coef in mid:
        assert coef[0] == pytest.approx(0.5 * (coef[1] + coef[2]), rel=1e-12)


def test_head_wind_pushes_back_and_stern_wind_pushes_ahead() -> None:
    spec = _ship()
    x_head, y_head, n_head = _loads(spec, 0.0)     # ship heading north, wind from north
    x_stern, _, _ = _loads(spec, 180.0)
    assert x_head < 0.0 < x_stern
    assert y_head == 0.0 and n_head == 0.0


def test_symmetry_side_force_and_moment_odd_surge_even() -> None:
    params = wind.build([_ship()])
    angles = np.radians(np.arange(-180.0, 181.0, 7.5))
    cx_p, cy_p, cn_p = wind.coefficients(params, angles)
    cx_m, cy_m, cn_m = wind.coefficients(params, -angles)
    np.testing.assert_allclose(cy_m, -cy_p, atol=1e-15)
    np.testing.assert_allclose(cn_m, -cn_p, atol=1e-15)
    np.testing.assert_allclose(cx_m, cx_p, atol=1e-15)


def test_beam_wind_from_port_pushes_to_starboard_and_moment_follows_the_centroid() -> None:
    """Isherwood's C5 (centroid term) is negative: a windage centroid aft of midship (KVLCC2's
    aft deckhouse, C/L = 0.6) turns the bow into the wind, one forward of midship away from it."""
    _, y_a, n_a = _loads(_ship(), 270.0)  # heading north, wind from west = from port
    assert y_a > 0.0
    assert n_a < 0.0  # bow to port, into the wind
    _, y_fwd, n_fwd = _loads(_ship(windage_centroid_from_bow_m=0.3 * 320.0), 270.0)
    assert y_fwd > 0.0 and n_fwd > 0.0  # bow to starboard, away from the wind
    _, y_s, n_s = _loads(_ship(), 90.0)  # from starboard: mirror image
    assert y_s == pytest.approx(-y_a) and n_s == pytest.approx(-n_a)


def test_zero_wind_gives_exactly_zero_load_also_under_way_and_in_current() -> None:
    spec = _ship()
    params = wind.build([spec] * 3)
    x = np.zeros((base.N_STATE, 3))
    x[U], x[V], x[PSI] = [7.9, -3.0, 0.0], [0.3, 0.1, 0.0], [0.3, 2.0, 5.0]
    for env in (Env(), Env(wind_speed_mps=np.zeros(3), wind_from_rad=np.array([0.0, 1.0, 4.0]),
                           current_north_mps=0.5, current_east_mps=np.array([-1.0, 0.0, 0.3]))):
        for load in wind.wind_loads(params, x, env):
            assert np.all(load == 0.0)
    # the mmg accelerations are bit-identical with and without a zero-speed wind
    p = FAMILY.build([spec] * 3)
    x[RPS] = 1.7
    calm = np.array(base.accelerations(FAMILY, p, x, Env()))
    zero = np.array(base.accelerations(FAMILY, p, x, Env(wind_speed_mps=np.zeros(3),
                                                    wind_from_rad=np.ones(3))))
    assert np.array_equal(calm, zero)


def test_load_is_the_increment_over_still_air_and_quadratic_in_relative_speed() -> None:
    """Ship at rest: the load is 1/2 rho_a V^2 A C(angle); a 2x wind gives 4x the load."""
    spec = _ship()
    p = spec["particulars"]
    x1 = _loads(spec, 30.0, speed=10.0)
    x2 = _loads(spec, 30.0, speed=20.0)
    np.testing.assert_allclose(x2, 4.0 * np.array(x1), rtol=1e-12)
    cx, _, _ = wind.coefficients(wind.build([spec]), np.radians([30.0]))
    assert x1[0] == pytest.approx(0.5 * base.RHO_AIR * 100.0 * p["windage_frontal_area_m2"] * cx[0])


def test_inline_apparent_wind_matches_base() -> None:
    """wind_loads repeats base.apparent_wind's arithmetic; the angle convention must agree."""
    spec = _ship()
    rng = np.random.default_rng(5)
    n = 50
    x = np.zeros((base.N_STATE, n))
    x[U], x[V], x[PSI] = rng.normal(5, 3, n), rng.normal(0, 1, n), rng.uniform(0, 6.3, n)
    env = Env(wind_speed_mps=rng.uniform(0, 25, n), wind_from_rad=rng.uniform(0, 6.3, n),
              current_north_mps=0.4, current_east_mps=-0.2)
    speed, angle = base.apparent_wind(x, env)
    ug, vg = base.ground_velocity_body(x, env)
    params = wind.build([spec] * n)
    want = np.array(wind.coefficients(params, angle)) * speed**2 \
        - np.array(wind.coefficients(params, np.arctan2(vg, ug))) * (ug**2 + vg**2)
    want *= np.array([params.wind_qx, params.wind_qy, params.wind_qn])
    np.testing.assert_allclose(np.array(wind.wind_loads(params, x, env)), want,
                               rtol=1e-9, atol=1e-6)


def test_ship_without_windage_feels_no_wind() -> None:
    spec = copy.deepcopy(load_ship("kvlcc2"))
    for key in list(spec["particulars"]):
        if key.startswith("windage_"):
            del spec["particulars"][key]
    assert _loads(spec, 45.0) == (0.0, 0.0, 0.0)
    assert wind.build([spec]).wind_qy[0] == 0.0


def _straight(env: Env, seconds: float = 1500.0, hold_heading: bool = False) -> np.ndarray:
    """Final state after ``seconds`` heading north at the 15.5 kn rps, rudder amidships or
    steered by the ship file's autopilot gains to hold north."""
    spec = load_ship("kvlcc2")
    params, act = FAMILY.build([spec]), Actuators.from_specs([spec])
    rps = base.steady_rps_for_speed(FAMILY, params, act, np.array([7.97]))
    gains = spec["autopilot"]
    x = np.zeros((base.N_STATE, 1))
    x[U], x[RPS] = 7.97, rps
    rudder, integral = np.zeros(1), np.zeros(1)
    for _ in range(int(seconds)):
        if hold_heading:
            rudder = rudder_command(np.zeros(1), x[PSI], x[R], integral, gains["kp"],
                                    gains["kd_s"], 0.002, act.rudder_max_rad, 1.0)
        x = base.step(FAMILY, params, act, x, rudder, rps, env, 1.0, 1)
    return x[:, 0]


def test_head_wind_slows_the_ship_and_beam_wind_from_port_drifts_it_east() -> None:
    calm = _straight(Env())
    head = _straight(Env(wind_speed_mps=20.0, wind_from_rad=0.0))
    assert head[U] < calm[U] - 0.05  # 20 m/s head wind costs a VLCC a noticeable speed
    assert calm[V] == 0.0 and calm[EAST] == 0.0
    from_port = Env(wind_speed_mps=20.0, wind_from_rad=np.radians(270.0))
    free = _straight(from_port, seconds=300.0)
    assert free[V] > 0.0  # sway to starboard
    assert free[R] < 0.0  # aft windage centroid: the bow comes up into the wind (to port)
    held = _straight(from_port, hold_heading=True)
    assert abs(np.degrees((held[PSI] + np.pi) % (2 * np.pi) - np.pi)) < 1.0
    assert held[V] > 0.0  # steady leeway to starboard
    east_speed = held[U] * np.sin(held[PSI]) + held[V] * np.cos(held[PSI])
    assert east_speed > 0.005  # heading north: drifting to the east


# --- hand-worked loads, invariances and the edges of the table ---

def _loads_at(spec: dict[str, Any], u=0.0, v=0.0, psi=0.0, env: Env | None = None) -> np.ndarray:
    cols = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=float)) for a in (u, v, psi)))
    x = np.zeros((base.N_STATE, cols[0].size))
    x[U], x[V], x[PSI] = cols
    return np.array(wind.wind_loads(wind.build([spec] * cols[0].size), x, env or Env()))


def test_head_and_following_wind_on_a_moving_ship_by_hand() -> None:
    """Heading north at u = 5 m/s: a head wind W gives X = 1/2 rho_a A_F C_X(0) ((u + W)^2 -
    u^2) (the increment over the ship's own still-air wind); a following wind W > u comes from
    astern at W - u: X = 1/2 rho_a A_F (C_X(180) (W - u)^2 - C_X(0) u^2), and a following wind
    W < u still from ahead at u - W. C_X(0) and C_X(180) from Isherwood's rows by hand."""
    spec = _ship()
    p = spec["particulars"]
    L, B = p["length_overall_m"] if "length_overall_m" in p else p["length_m"], p["beam_m"]
    al, af = 2 * p["windage_lateral_area_m2"] / L**2, 2 * p["windage_frontal_area_m2"] / B**2
    sl, cl = p["windage_perimeter_m"] / L, p["windage_centroid_from_bow_m"] / L
    cx0 = -(2.152 - 5.00 * al + 0.243 * af - 0.164 * L / B)
    cx180 = -(-2.529 + 3.76 * al - 0.174 * af + 0.128 * L / B + 0.0 * sl + 1.55 * cl)
    q = 0.5 * base.RHO_AIR * p["windage_frontal_area_m2"]
    u = 5.0
    head = _loads_at(spec, u=u, env=Env(wind_speed_mps=12.0, wind_from_rad=0.0))[:, 0]
    assert head[0] == pytest.approx(q * cx0 * ((u + 12.0) ** 2 - u**2), rel=1e-12)
    strong = _loads_at(spec, u=u, env=Env(wind_speed_mps=12.0, wind_from_rad=np.pi))[:, 0]
    assert strong[0] == pytest.approx(q * (cx180 * 7.0**2 - cx0 * u**2), rel=1e-9)
    weak = _loads_at(spec, u=u, env=Env(wind_speed_mps=3.0, wind_from_rad=np.pi))[:, 0]
    assert weak[0] == pytest.approx(q * cx0 * (2.0**2 - u**2), rel=1e-12)
    assert weak[0] > 0.0  # less head wind than in still air: the increment pushes ahead
    for load in (head, strong, weak):
        assert abs(load[1]) < 1e-9 * abs(load[0]) and abs(load[2]) < 1e-9 * abs(load[0]) * L


def test_full_regression_with_every_regressor_by_hand() -> None:
    """C_X, C_Y, C_N at 130 deg (a row where A3..A6, B3..B6 and C2..C4 are all non-zero) and at
    125 deg (the mean of the 120 and 130 deg rows), from Isherwood's rows written out here, with
    the documented defaults replaced by explicit values; wind from port, so C_Y and C_N keep the
    table's sign at negative angles."""
    spec = _ship(length_overall_m=330.0, windage_perimeter_m=420.0,
                 windage_centroid_from_bow_m=170.0, windage_mast_groups=3,
                 windage_superstructure_area_m2=1000.0)
    p = spec["particulars"]
    L, B = 330.0, p["beam_m"]
    al, af = 2 * p["windage_lateral_area_m2"] / L**2, 2 * p["windage_frontal_area_m2"] / B**2
    lb, sl, cl, m = L / B, 420.0 / L, 170.0 / L, 3.0
    ss = 1000.0 / p["windage_lateral_area_m2"]
    row = {120: ((0.564, 2.54, 0, 0, -0.748, 0, -0.024), (0.996, 0, 0.184, 0, -0.212, -0.66, 0.34),
                 (0.0801, 0, -0.0311, 0, 0.0740, -0.396)),
           130: ((-0.142, 3.58, 0, 0.047, -0.700, 0, -0.028),
                 (1.014, 0, 0.191, 0, -0.280, -0.69, 0.44),
                 (-0.0189, 0, -0.0488, 0.0101, 0.1128, -0.420))}

    def coef(deg):
        a, b, c = row[deg]
        cx = -(a[0] + a[1] * al + a[2] * af + a[3] * lb + a[4] * sl + a[5] * cl + a[6] * m)
        cy = b[0] + b[1] * al + b[2] * af + b[3] * lb + b[4] * sl + b[5] * cl + b[6] * ss
        cn = c[0] + c[1] * al + c[2] * af + c[3] * lb + c[4] * sl + c[5] * cl
        return np.array([cx, cy, cn])

    got = np.array(wind.coefficients(wind.build([spec]), np.radians([-130.0, -125.0, 130.0])))
    np.testing.assert_allclose(got[:, 0], coef(130), rtol=1e-12)
    np.testing.assert_allclose(got[:, 1], 0.5 * (coef(120) + coef(130)), rtol=1e-12)
    np.testing.assert_allclose(got[:, 2], coef(130) * [1, -1, -1], rtol=1e-12)


def test_documented_defaults_of_the_windage_particulars() -> None:
    """Without L_OA, S, C, M and A_SS the regressors use L_OA = L_pp, S = L_OA, C = L_OA / 2,
    M = 0, A_SS = 0 (module doc table)."""
    spec = _ship()
    for key in ("length_overall_m", "windage_perimeter_m", "windage_centroid_from_bow_m",
                "windage_mast_groups", "windage_superstructure_area_m2"):
        spec["particulars"].pop(key, None)
    p = spec["particulars"]
    w = wind.build([spec])
    L = p["length_m"]
    assert w.wind_al[0] == pytest.approx(2 * p["windage_lateral_area_m2"] / L**2)
    assert w.wind_af[0] == pytest.approx(2 * p["windage_frontal_area_m2"] / p["beam_m"] ** 2)
    assert (w.wind_sl[0], w.wind_cl[0], w.wind_masts[0], w.wind_ss[0]) == (1.0, 0.5, 0.0, 0.0)
    assert w.wind_qn[0] == pytest.approx(0.5 * base.RHO_AIR * p["windage_lateral_area_m2"] * L)


def test_loads_depend_on_the_air_relative_motion_only() -> None:
    """Turning the ship and the wind together changes nothing (the loads are body-frame); a
    current that the water velocity cancels (same velocity over ground) changes nothing either,
    since air and still-air loads both use the motion over ground."""
    spec = _ship()
    rng = np.random.default_rng(6)
    k = 40
    u, v, psi = rng.uniform(-3, 8, k), rng.uniform(-1, 1, k), rng.uniform(0, 2 * np.pi, k)
    ws, wf = rng.uniform(0.5, 25, k), rng.uniform(0, 2 * np.pi, k)
    ref = _loads_at(spec, u, v, psi, Env(wind_speed_mps=ws, wind_from_rad=wf))
    turn = 1.234
    turned = _loads_at(spec, u, v, psi + turn, Env(wind_speed_mps=ws, wind_from_rad=wf + turn))
    np.testing.assert_allclose(turned, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    cn, ce = 0.7, -0.4  # current (earth frame); the water velocity in the body frame offsets it
    du = cn * np.cos(psi) + ce * np.sin(psi)
    dv = -cn * np.sin(psi) + ce * np.cos(psi)
    drift = _loads_at(spec, u - du, v - dv, psi, Env(current_north_mps=cn, current_east_mps=ce,
                                                     wind_speed_mps=ws, wind_from_rad=wf))
    np.testing.assert_allclose(drift, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_mirrored_wind_gives_mirrored_loads() -> None:
    """Wind from psi + a and from psi - a on a ship with mirrored sway: same X, opposite Y and N."""
    spec = _ship()
    rng = np.random.default_rng(7)
    k = 40
    u, v, a = rng.uniform(-3, 8, k), rng.uniform(-1, 1, k), rng.uniform(-np.pi, np.pi, k)
    ws = rng.uniform(0.5, 25, k)
    one = _loads_at(spec, u, v, 0.3, Env(wind_speed_mps=ws, wind_from_rad=0.3 + a))
    two = _loads_at(spec, u, -v, -0.3, Env(wind_speed_mps=ws, wind_from_rad=-0.3 - a))
    np.testing.assert_allclose(two * np.array([[1.0], [-1.0], [-1.0]]), one, rtol=1e-9,
                               atol=1e-9 * np.abs(one).max())


def test_coefficients_are_continuous_at_table_angles_and_finite_at_the_ends() -> None:
    """Linear interpolation: no step at the 10 deg table angles; at exactly +-180 deg the
    table's last row (C_Y = C_N = 0) and at 0 deg C_Y = C_N = 0 exactly."""
    params = wind.build([_ship()])
    tab = np.radians(np.arange(10.0, 180.0, 10.0))
    below = np.array(wind.coefficients(params, tab * (1 - 1e-12)))
    above = np.array(wind.coefficients(params, tab * (1 + 1e-12)))
    np.testing.assert_allclose(below, above, rtol=1e-9, atol=1e-12)
    ends = np.array(wind.coefficients(params, np.array([0.0, np.pi, -np.pi])))
    assert ends[1, 0] == 0.0 and ends[2, 0] == 0.0
    assert np.all(np.abs(ends[1:, 1:]) < 1e-8)
    assert ends[0, 1] == pytest.approx(ends[0, 2], rel=1e-8) and ends[0, 1] > 0.0  # pushes ahead


def test_coefficients_are_periodic_in_the_angle() -> None:
    """An apparent-wind angle and the same angle plus or minus 2 pi are the same direction:
    350 deg is 10 deg from port, -350 deg 10 deg from starboard."""
    params = wind.build([_ship()])
    a = np.radians([10.0, -10.0, 95.0])
    np.testing.assert_allclose(np.array(wind.coefficients(params, a - 2 * np.pi * np.sign(a))),
                               np.array(wind.coefficients(params, a)), rtol=1e-9, atol=1e-12)


def test_no_ships_and_non_finite_states() -> None:
    """An empty fleet gives empty loads; a NaN state or angle gives NaN (not a finite value read
    from the wrong table row)."""
    empty = wind.build([])
    assert all(c.shape == (0,) for c in wind.coefficients(empty, np.zeros(0)))
    assert all(c.shape == (0,) for c in wind.wind_loads(empty, np.zeros((base.N_STATE, 0)),
                                                         Env()))
    params = wind.build([_ship()])
    assert np.all(np.isnan(wind.coefficients(params, np.array([np.nan]))))
    x = np.zeros((base.N_STATE, 1))
    x[U] = np.nan
    assert np.all(np.isnan(wind.wind_loads(params, x, Env(wind_speed_mps=10.0))))
