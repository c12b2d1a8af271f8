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
