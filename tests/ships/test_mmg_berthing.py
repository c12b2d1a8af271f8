"""The ``mmg_berthing`` family (Miyauchi et al. 2022 low-speed MMG model) on the Esso Osaka
model's MMG parameter folder, read at run time: the kernel against an independent scalar
transcription of its equations, the closed-form cross-flow integrals, physics sanity (rest,
straight run, turn, going astern), continuity across u = 0 and n = 0, the engine's batch step,
and the hull effects."""

from __future__ import annotations

import copy
import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.conftest import SHARED
from trafficsim import effects
from trafficsim.batch import build_batch
from trafficsim.engine import Simulation
from trafficsim.errors import InputError
from trafficsim.io.scenario import load_scenario
from trafficsim.run import scenario_setups
from trafficsim.ships import base
from trafficsim.ships.base import PSI, RPS, RUDDER, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.ships.mmg_berthing import FAMILY, J_FADE, J_RAMP, cross_flow

FOLDER = SHARED / "data" / "esso-osaka-mmg" / "python_module" / "input_csv"
pytestmark = pytest.mark.skipif(not FOLDER.is_dir(), reason="MMG parameter folder not present")


@pytest.fixture(scope="module")
def spec() -> dict[str, Any]:
    return load_ship(str(FOLDER))


def _accel(spec: dict[str, Any], states: np.ndarray) -> np.ndarray:
    """``(3, k)`` accelerations at ``states`` ``(k, 5)`` = u, v, r, n, delta."""
    states = np.atleast_2d(states)
    k = states.shape[0]
    x = np.zeros((base.N_STATE, k))
    x[U], x[V], x[R], x[RPS], x[RUDDER] = states.T
    params = FAMILY.build([spec] * k)
    return np.array(base.accelerations(FAMILY, params, x, base.Env()))


def _run(spec: dict[str, Any], seconds: float, rudder_rad: float, rps: float,
         speed: float = 0.0) -> np.ndarray:
    """State history ``(steps + 1, 8)`` with constant orders (engine lag from the spec)."""
    params, act = FAMILY.build([spec]), base.Actuators.from_specs([spec])
    x = np.zeros((base.N_STATE, 1))
    x[U] = speed
    rows = [x[:, 0].copy()]
    for _ in range(round(seconds / 0.5)):
        x = base.step(FAMILY, params, act, x, np.array([rudder_rad]), np.array([rps]),
                      base.Env(), 0.5, 5)
        rows.append(x[:, 0].copy())
    return np.array(rows)


# --- an independent scalar transcription of the module's equations, numerical cross-flow ---

def _written_out(spec: dict[str, Any], u: float, v: float, r: float, n: float,
                 delta: float) -> tuple[float, float, float]:
    """The equations of :mod:`trafficsim.ships.mmg_berthing` written out literally for one
    state outside its regularised bands (|J| < J_FADE, |J_s| > J_RAMP near u = 0), SI units,
    the cross-flow integrals by a fine trapezoidal rule."""
    c, p = spec["coefficients"], spec["particulars"]
    rho = p["water_density_kgpm3"]
    L, d, D = p["length_m"], p["draught_m"], p["propeller_diameter_m"]
    pitch = p["propeller_pitch_ratio"] * D
    m = rho * p["displacement_m3"]
    xg = p["lcg_m"]
    h1, h2 = 0.5 * rho * L * d, 0.5 * rho * L * L * d
    big_u = math.hypot(u, v)
    beta = math.atan2(v, u)
    xs = np.linspace(-L / 2, L / 2, 20001)
    wy = (v + c["C_rY"] * r * xs)
    wn = (v + c["C_rN"] * r * xs)
    y_cf = 0.5 * rho * d * c["C_D"] * np.trapezoid(np.abs(wy) * wy, xs)
    n_cf = 0.5 * rho * d * c["C_D"] * np.trapezoid(np.abs(wn) * wn * xs, xs)
    xh = h1 * ((c["X_0F"] + (c["X_0A"] - c["X_0F"]) * abs(beta) / math.pi) * u * big_u
               + c["X_vr"] * v * r * L)
    yh = h1 * (c["Y_v"] * v * abs(u) + c["Y_r"] * r * L * u) - y_cf
    nh = h2 * (c["N_v"] * v * u + c["N_r"] * r * L * abs(u)) - n_cf
    # propeller
    bp = (v + c["x_P"] * L * r) / big_u
    one_m_w = min(max(1 - (c["w_P0"] - c["tau_P"] * abs(bp) - c["C_P"] * bp * bp), 1e-12),
                  1.0) if u > 0 else 1.0
    js = u / (n * D)
    a = [c[f"a_P{i}"] for i in range(8)]
    b = [c[f"b_P{i}"] for i in range(8)]
    if n >= 0:
        j = one_m_w * js
        kt = c["k_0"] + c["k_1"] * j + c["k_2"] * j * j
        xp = (1 - c["t_P"]) * rho * n * n * D**4 * kt
        yp = npp = 0.0
        if u < 0:
            yp = h1 * (n * pitch) ** 2 * (a[5] * js**2 + a[6] * js + a[7])
            npp = h2 * (n * pitch) ** 2 * (b[5] * js**2 + b[6] * js + b[7])
    else:
        kt = c["c_P1"] + c["c_P2"] * js if js >= c["c_P3"] else c["c_P0"]
        xp = rho * n * n * D**4 * kt
        i0, j0 = (2, 3) if js < -0.35 else ((0, 1) if js <= -0.06 else (4, None))
        yp = h1 * (n * D) ** 2 * (a[i0] + (a[j0] * js if j0 else 0.0))
        npp = h2 * (n * D) ** 2 * (b[i0] + (b[j0] * js if j0 else 0.0))
    # rudder
    eta = D / p["rudder_height_m"]
    eps, kappa = c["epsilon"], c["k_x"] / c["epsilon"]
    up = one_m_w * u
    if n >= 0 and kt > 0:
        ur = eps * math.sqrt(eta * (up + kappa * (math.sqrt(up**2 + 8 * kt * (n * D) ** 2
                                                            / math.pi) - up)) ** 2
                             + (1 - eta) * up**2)
    elif u < 0:
        ur = u
    else:
        p1 = eps * up + n * D * c["k_x_reverse"] * math.sqrt(8 * abs(kt) / math.pi)
        sq = eta * math.copysign(p1**2, p1) + (1 - eta) * (eps * up) ** 2 + c["C_PR"] * u * u
        ur = math.copysign(math.sqrt(abs(sq)), sq)
    beta_r = -(v + c["l_R"] * L * r)
    vr = (c["gamma_R_plus"] if beta_r > 0 else c["gamma_R_minus"]) * beta_r
    fn = 0.5 * rho * p["rudder_area_m2"] * c["f_alpha"] * (ur**2 + vr**2) * math.sin(
        delta - math.atan2(vr, ur))
    a_h = c["a_H"]
    xr = -(1 - c["t_R"]) * fn * math.sin(delta)
    yr = -(1 + a_h) * fn * math.cos(delta)
    nr = -(c["x_R"] + a_h * c["x_H"]) * L * fn * math.cos(delta)
    mx, my, jz = c["m_x"] * h2, c["m_y"] * h2, c["J_z"] * h2 * L * L
    izz = m * (c["k_zz"] * L) ** 2 + xg * xg * m + jz
    X, Y, N = xh + xp + xr, yh + yp + yr, nh + npp + nr
    du = (X + (m + my) * v * r + xg * m * r * r) / (m + mx)
    mat = np.array([[m + my, xg * m], [xg * m, izz]])
    dv, dr = np.linalg.solve(mat, [Y - (m + mx) * u * r, N - xg * m * u * r])
    return du, float(dv), float(dr)


def test_kernel_matches_written_out_equations(spec: dict[str, Any]) -> None:
    rng = np.random.default_rng(4)
    states = np.column_stack([rng.uniform(-0.3, 0.5, 3000), rng.uniform(-0.1, 0.1, 3000),
                              rng.uniform(-0.15, 0.15, 3000), rng.uniform(-20, 20, 3000),
                              rng.uniform(-0.6, 0.6, 3000)])
    js = states[:, 0] / (states[:, 3] * spec["particulars"]["propeller_diameter_m"])
    regular = (np.abs(js) < J_FADE) & (np.abs(js) > J_RAMP)
    states = states[regular][:400]
    got = _accel(spec, states)
    want = np.array([_written_out(spec, *s) for s in states]).T
    scale = np.abs(want).max(axis=1, keepdims=True)
    assert np.all(np.abs(got - want) <= 1e-6 * scale)
    # every quadrant of (u, n) is in the sample
    assert len({(s[0] > 0, s[3] > 0) for s in states}) == 4


def test_cross_flow_closed_form() -> None:
    half = 1.5
    xs = np.linspace(-half, half, 200001)
    for a, b in [(0.05, 0.0), (0.0, 0.1), (0.02, 0.1), (-0.07, 0.03), (0.3, -0.05), (0, 0)]:
        w = a + b * xs
        assert cross_flow(a, b, half, False) == pytest.approx(
            np.trapezoid(np.abs(w) * w, xs), rel=1e-8, abs=1e-14)
        assert cross_flow(a, b, half, True) == pytest.approx(
            np.trapezoid(np.abs(w) * w * xs, xs), rel=1e-8, abs=1e-14)
    # pure sway: L v|v|; pure yaw: no force, moment b|b| L^4 / 32
    assert cross_flow(-0.1, 0.0, half, False) == pytest.approx(-3.0 * 0.01)
    assert cross_flow(0.0, 0.2, half, False) == pytest.approx(0.0, abs=1e-15)
    assert cross_flow(0.0, -0.2, half, True) == pytest.approx(-0.04 * 3.0**4 / 32)


def test_folder_ship_is_the_esso_osaka_model(spec: dict[str, Any]) -> None:
    """Mass and centre of gravity as the FRT-DS-ESSO data set states them (244.6 kg, 0.094 m):
    the folder's mass is non-dimensional with fresh water and its x_lcg is x_G / L."""
    p = spec["particulars"]
    assert spec["model"] == "mmg_berthing"
    assert p["water_density_kgpm3"] * p["displacement_m3"] == pytest.approx(244.6, abs=0.1)
    assert p["lcg_m"] == pytest.approx(0.094, abs=0.001)


def test_at_rest_no_force(spec: dict[str, Any]) -> None:
    rest = np.array([[0.0, 0.0, 0.0, 0.0, d] for d in (-0.6, 0.0, 0.3)])
    assert np.array_equal(_accel(spec, rest), np.zeros((3, 3)))


def test_straight_run_reaches_a_model_scale_speed(spec: dict[str, Any]) -> None:
    """10 rps from rest for 400 s (7 time constants of the surge): a steady 0.3-0.5 m/s
    (Froude number 0.06-0.09 for the 3 m model, between the 0.33 m/s the 10 rps zig-zags of the
    data reach and the 16.7 rps ones' 0.53 m/s), straight, the speed growing with the propeller
    speed."""
    runs = {n: _run(spec, 400.0, 0.0, n) for n in (8.0, 10.0, 12.0)}
    u = {n: run[-1, U] for n, run in runs.items()}
    assert 0.3 < u[10.0] < 0.5
    assert u[8.0] < u[10.0] < u[12.0]
    assert abs(runs[10.0][-1, U] - runs[10.0][-21, U]) < 0.01 * u[10.0]  # steady
    assert np.all(runs[10.0][:, [V, R, PSI]] == 0.0)


def test_positive_rudder_turns_to_starboard(spec: dict[str, Any]) -> None:
    run = _run(spec, 120.0, math.radians(20.0), 10.0, speed=0.35)
    assert run[-1, R] > 0.0 and run[-1, PSI] > math.radians(90.0)
    mirror = _run(spec, 120.0, math.radians(-20.0), 10.0, speed=0.35)
    assert mirror[-1, R] < 0.0


def test_astern_decelerates_and_goes_astern(spec: dict[str, Any]) -> None:
    ahead = _run(spec, 60.0, 0.0, 10.0, speed=0.35)
    params, act = FAMILY.build([spec]), base.Actuators.from_specs([spec])
    x = ahead[-1][:, None].copy()
    speeds = [x[U, 0]]
    for _ in range(240):  # full astern for 120 s with a little rudder
        x = base.step(FAMILY, params, act, x, np.array([0.1]), np.array([-15.0]), base.Env(),
                      0.5, 5)
        speeds.append(x[U, 0])
        assert np.all(np.isfinite(x))
    speeds = np.array(speeds)
    assert speeds[-1] < -0.05
    stop = int(np.argmax(speeds < 0.0))
    assert stop > 0 and np.all(np.diff(speeds[: stop]) < 0.0)  # decelerates until it stops


def test_continuous_across_zero_speed_and_zero_propeller(spec: dict[str, Any]) -> None:
    """No jump where the quadrants meet (u = 0, n = 0); the published model's propeller side
    force, thrust and rudder inflow jump there by 1-5 % of the accelerations below."""
    eps = 1e-9
    vs, rs, ds = (-0.03, 0.0, 0.04), (-0.05, 0.0, 0.08), (-0.3, 0.0, 0.4)
    across_u = [(s * eps, v, r, n, d) for n, v, r, d in
                itertools.product((-15.0, -5.0, 5.0, 15.0), vs, rs, ds) for s in (1, -1)]
    across_n = [(u, v, r, s * eps, d) for u, v, r, d in
                itertools.product((-0.2, -0.05, 0.05, 0.3), vs, rs, ds) for s in (1, -1)]
    for states in (across_u, across_n):
        acc = _accel(spec, np.array(states))
        scale = np.abs(acc).max(axis=1)
        assert np.all(scale > 0.005)
        jump = np.abs(acc[:, 0::2] - acc[:, 1::2]).max(axis=1)
        assert np.all(jump < 1e-5 * scale)


def test_scenario_ship_from_the_folder(tmp_path: Path) -> None:
    """The folder as a scenario ship's type, next to a KVLCC2, in the engine's batch step."""
    path = tmp_path / "berth.yaml"
    path.write_text(f"""schema_version: 1
name: berth
duration_s: 60
dt_s: 1.0
ships:
  - name: model
    type: {FOLDER.resolve()}
    north_m: 0
    east_m: 0
    heading_deg: 0
    speed_kn: 0.6
    behaviour: keep_course
  - name: tanker
    type: kvlcc2
    north_m: 5000
    east_m: 5000
    heading_deg: 180
    behaviour: keep_course
""")
    scn = load_scenario(path)
    setups, env = scenario_setups(scn)
    sim = Simulation.start(build_batch(setups, [env]), scn.dt_s)
    sim.run(60)
    x = sim.batch.x
    assert np.all(np.isfinite(x))
    assert x[base.NORTH, 0] == pytest.approx(0.6 * 1852 / 3600 * 60, rel=0.1)
    assert abs(x[base.EAST, 0]) < 0.5


def test_hull_effects(spec: dict[str, Any]) -> None:
    fouled = effects.apply_spec(spec, effects.check({"resistance": {"scale": 1.5}}))
    assert _run(fouled, 150.0, 0.0, 10.0)[-1, U] < _run(spec, 150.0, 0.0, 10.0)[-1, U] - 0.02
    assert fouled["coefficients"]["X_0A"] == pytest.approx(1.5 * spec["coefficients"]["X_0A"])
    offset = effects.apply_spec(spec, effects.check({"propeller_asymmetry":
                                                     {"rudder_offset_deg": 2.0}}))
    straight = np.array([[0.35, 0.0, 0.0, 10.0, 0.0]])
    assert _accel(spec, straight)[2, 0] == 0.0 and _accel(offset, straight)[2, 0] > 0.0
    shallow = effects.apply_spec(spec, effects.check({"shallow_water":
                                                      {"draught_to_depth": 0.6}}))
    f = effects.shallow_water_factor(0.6, spec)
    assert f > 1.0
    for key in ("Y_v", "Y_r", "N_v", "N_r", "m_y"):
        assert shallow["coefficients"][key] == pytest.approx(f * spec["coefficients"][key])
    # shallow water damps the turn
    turn, turn_shallow = (_run(s, 60.0, math.radians(20.0), 10.0, speed=0.35)[-1, R]
                          for s in (spec, shallow))
    assert 0.0 < turn_shallow < turn
    nomoto = copy.deepcopy(load_ship("catfish"))
    with pytest.raises(InputError, match="mmg and mmg_berthing"):
        effects.apply_spec(nomoto, effects.check({"resistance": {"scale": 1.2}}))


# --- symmetries, hand-worked limits, band edges, switches ---

def _accel_env(spec: dict[str, Any], states: np.ndarray, psi: np.ndarray | float = 0.0,
               env: base.Env | None = None) -> np.ndarray:
    """``_accel`` with a heading and an environment."""
    states = np.atleast_2d(states)
    k = states.shape[0]
    x = np.zeros((base.N_STATE, k))
    x[U], x[V], x[R], x[RPS], x[RUDDER] = states.T
    x[PSI] = psi
    return np.array(base.accelerations(FAMILY, FAMILY.build([spec] * k), x, env or base.Env()))


def _with(spec: dict[str, Any], **coefficients: float) -> dict[str, Any]:
    out = copy.deepcopy(spec)
    out["coefficients"].update(coefficients)
    return out


def _mass(spec: dict[str, Any]) -> tuple[float, np.ndarray]:
    """m + m_x and the sway-yaw mass matrix at midship, from the ship file (module doc)."""
    c, p = spec["coefficients"], spec["particulars"]
    rho, L, d = p["water_density_kgpm3"], p["length_m"], p["draught_m"]
    m = rho * p["displacement_m3"]
    s = 0.5 * rho * L * L * d
    xg = p["lcg_m"]
    izz = m * (c["k_zz"] * L) ** 2 + xg * xg * m + c["J_z"] * s * L * L
    return m + c["m_x"] * s, np.array([[m + c["m_y"] * s, xg * m], [xg * m, izz]])


def test_mirror_symmetry_once_the_propeller_side_force_is_removed(spec: dict[str, Any]) -> None:
    """Without the propeller's side force and moment (a_P*, b_P* = 0: the only terms of a
    single screw that do not mirror) and with gamma_R+/- swapped, mirroring v, r, rudder,
    heading, east current and wind direction mirrors the accelerations in every quadrant of
    (u, n), including the cross-flow drag and the wind."""
    zero = {f"{c}_P{i}": 0.0 for c in "ab" for i in range(8)}
    ship = _with(spec, delta_0=0.01, **zero)
    c = spec["coefficients"]
    mirror = _with(ship, delta_0=-0.01, gamma_R_plus=c["gamma_R_minus"],
                   gamma_R_minus=c["gamma_R_plus"])
    rng = np.random.default_rng(21)
    k = 300
    u, v = rng.uniform(-0.4, 0.6, k), rng.uniform(-0.15, 0.15, k)
    r, n, d = rng.uniform(-0.2, 0.2, k), rng.uniform(-20, 20, k), rng.uniform(-0.6, 0.6, k)
    psi, wf = rng.uniform(0, 2 * np.pi, k), rng.uniform(0, 2 * np.pi, k)
    env = base.Env(current_north_mps=rng.uniform(-.1, .1, k),
                   current_east_mps=rng.uniform(-.1, .1, k),
                   wind_speed_mps=rng.uniform(0, 5, k), wind_from_rad=wf)
    env_m = base.Env(current_north_mps=env.current_north_mps,
                     current_east_mps=-env.current_east_mps,
                     wind_speed_mps=env.wind_speed_mps, wind_from_rad=-wf)
    acc = _accel_env(ship, np.column_stack([u, v, r, n, d]), psi, env)
    mir = _accel_env(mirror, np.column_stack([u, -v, -r, n, -d]), -psi, env_m)
    scale = np.abs(acc).max(axis=1, keepdims=True)
    assert np.all(np.abs(mir * np.array([[1.0], [-1.0], [-1.0]]) - acc) <= 1e-11 * scale)
    # the published a_P, b_P do break it: a single screw turns the ship going astern
    full = _accel_env(spec, np.array([[0.0, 0.0, 0.0, -15.0, 0.0]]))
    assert full[2, 0] != 0.0


def test_cross_flow_symmetries() -> None:
    """Reversing the whole local velocity reverses the integrals; reversing only the yaw part
    (x -> -x) keeps the force and reverses the moment; velocity changing sign exactly at an
    end of the hull is a single piece."""
    rng = np.random.default_rng(1)
    for a, b in zip(rng.normal(0, 0.1, 30), rng.normal(0, 0.2, 30), strict=True):
        for moment in (False, True):
            assert cross_flow(-a, -b, 1.5, moment) == pytest.approx(-cross_flow(a, b, 1.5, moment),
                                                                    rel=1e-12, abs=1e-18)
        assert cross_flow(a, -b, 1.5, False) == pytest.approx(cross_flow(a, b, 1.5, False),
                                                              rel=1e-12, abs=1e-18)
        assert cross_flow(a, -b, 1.5, True) == pytest.approx(-cross_flow(a, b, 1.5, True),
                                                             rel=1e-12, abs=1e-18)
    # a + b x = 0.1 (x + 1.5): zero at the bow end x = -1.5; int 0.01 (x + 1.5)^2 = 0.01 * 27 / 3
    assert cross_flow(0.15, 0.1, 1.5, False) == pytest.approx(0.09, rel=1e-12)


def test_bollard_pull_and_astern_side_force_at_rest_by_hand(spec: dict[str, Any]) -> None:
    """At rest (u = v = r = 0): ahead, X_P = (1 - t_P) rho n^2 D^4 k_0, the rudder in the race
    u_R = eps sqrt(eta) kappa sqrt(8 k_0 / pi) n D; astern (n < 0, J_s = 0 >= c_P3) Hachii's
    X_P = rho n^2 D^4 c_P1, his side force a_P4 and moment b_P4 (J_s > -0.06) times
    1/2 rho L d (n D)^2 and 1/2 rho L^2 d (n D)^2, and no rudder force (u_R = u = 0 in the
    fourth-quadrant blend at u = 0)."""
    c, p = spec["coefficients"], spec["particulars"]
    rho, L, d, D = p["water_density_kgpm3"], p["length_m"], p["draught_m"], \
        p["propeller_diameter_m"]
    mx, M = _mass(spec)
    assert c["c_P3"] <= 0.0
    n, delta = 12.0, 0.35
    eta = D / p["rudder_height_m"]
    kappa = c["k_x"] / c["epsilon"]
    u_r = c["epsilon"] * np.sqrt(eta) * kappa * np.sqrt(8 * c["k_0"] / np.pi) * n * D
    f_n = 0.5 * rho * p["rudder_area_m2"] * c["f_alpha"] * u_r**2 * np.sin(delta)
    X = (1 - c["t_P"]) * rho * n**2 * D**4 * c["k_0"] - (1 - c["t_R"]) * f_n * np.sin(delta)
    Y = -(1 + c["a_H"]) * f_n * np.cos(delta)
    N = -(c["x_R"] + c["a_H"] * c["x_H"]) * L * f_n * np.cos(delta)
    want = np.concatenate([[X / mx], np.linalg.solve(M, [Y, N])])
    np.testing.assert_allclose(_accel(spec, np.array([0, 0, 0, n, delta]))[:, 0], want,
                               rtol=1e-10)
    n = -14.0
    X = rho * n**2 * D**4 * c["c_P1"]
    Y = 0.5 * rho * L * d * (n * D) ** 2 * c["a_P4"]
    N = 0.5 * rho * L**2 * d * (n * D) ** 2 * c["b_P4"]
    want = np.concatenate([[X / mx], np.linalg.solve(M, [Y, N])])
    for delta in (0.0, 0.4):
        np.testing.assert_allclose(_accel(spec, np.array([0, 0, 0, n, delta]))[:, 0], want,
                                   rtol=1e-10)


def test_coasting_ahead_and_astern_by_hand(spec: dict[str, Any]) -> None:
    """Propeller stopped, rudder amidships, no drift: only the resistance acts, X_0F u |u| ahead
    and X_0A u |u| astern (beta = 0 or pi) times 1/2 rho L d; the stopped propeller adds
    nothing (its forces fade to zero at n = 0, module doc)."""
    c, p = spec["coefficients"], spec["particulars"]
    mx, _ = _mass(spec)
    half = 0.5 * p["water_density_kgpm3"] * p["length_m"] * p["draught_m"]
    u = np.array([0.05, 0.4, -0.05, -0.4])
    acc = _accel(spec, np.column_stack([u, 0 * u, 0 * u, 0 * u, 0 * u]))
    coef = np.where(u > 0, c["X_0F"], c["X_0A"])
    np.testing.assert_allclose(acc[0], half * coef * u * np.abs(u) / mx, rtol=1e-12)
    assert np.all(np.sign(acc[0]) == -np.sign(u))
    assert np.all(np.abs(acc[1:]) < 1e-15)


def test_hydrodynamic_accelerations_do_not_depend_on_the_water_density(spec) -> None:
    """Every hydrodynamic force and the mass are proportional to rho (module doc: the density
    sets the mass and all forces), so without wind the accelerations are the same in fresh and
    in salt water."""
    salt = copy.deepcopy(spec)
    salt["particulars"]["water_density_kgpm3"] = 1025.0
    rng = np.random.default_rng(8)
    states = np.column_stack([rng.uniform(-0.3, 0.5, 100), rng.uniform(-0.1, 0.1, 100),
                              rng.uniform(-0.15, 0.15, 100), rng.uniform(-20, 20, 100),
                              rng.uniform(-0.6, 0.6, 100)])
    np.testing.assert_allclose(_accel(salt, states), _accel(spec, states), rtol=1e-11,
                               atol=1e-16)


@pytest.mark.parametrize("where", ["fade", "ramp"])
def test_continuous_at_the_edges_of_the_blending_bands(spec: dict[str, Any], where: str) -> None:
    """At |J| = J_FADE (forces of a propeller ahead start to fade) and |J_s| = J_RAMP (the
    second-quadrant side force and Kitagawa's inflow blend in) the two sides agree."""
    D = spec["particulars"]["propeller_diameter_m"]
    states = []
    for n in (6.0, 15.0):
        for u_sign, v, r, d in itertools.product((1, -1), (-0.03, 0.04), (-0.05, 0.08),
                                                 (-0.3, 0.4)):
            if where == "fade":
                if u_sign > 0:
                    continue  # ahead 1 - w_P depends on v, r; astern J_s = u / (n D) exactly
                js = J_FADE
            else:
                js = J_RAMP
            for n_sign in ((1,) if where == "fade" else (1, -1)):
                for s in (1 - 1e-9, 1 + 1e-9):
                    states.append((u_sign * js * n * D * s, v, r, n_sign * n, d))
    acc = _accel(spec, np.array(states))
    scale = np.abs(acc).max(axis=1)
    jump = np.abs(acc[:, 0::2] - acc[:, 1::2]).max(axis=1)
    assert np.all(jump < 1e-6 * scale)


def test_propeller_fade_ahead_at_the_wake_advance_ratio(spec: dict[str, Any]) -> None:
    """Ahead, the thrust fades beyond J = (1 - w_P) u / (n D) = J_FADE with the wake included:
    straight ahead (beta_P = 0, 1 - w_P = 1 - w_P0) the surge acceleration is continuous there
    and, beyond it, the thrust is q J_FADE / J."""
    c, p = spec["coefficients"], spec["particulars"]
    D, rho = p["propeller_diameter_m"], p["water_density_kgpm3"]
    n = 8.0
    u_edge = J_FADE * n * D / (1 - c["w_P0"])
    acc = _accel(spec, np.array([[u_edge * (1 - 1e-9), 0, 0, n, 0],
                                 [u_edge * (1 + 1e-9), 0, 0, n, 0]]))
    assert acc[0, 0] == pytest.approx(acc[0, 1], rel=1e-7)
    # at J = 2 J_FADE the thrust is half the open-water curve's value there
    u = 2 * u_edge
    coast = _accel(spec, np.array([u, 0, 0, 0, 0]))[0, 0]
    mx, _ = _mass(spec)
    j = 2 * J_FADE
    kt = c["k_0"] + c["k_1"] * j + c["k_2"] * j * j
    thrust = (1 - c["t_P"]) * rho * n**2 * D**4 * kt * (J_FADE / j)
    assert _accel(spec, np.array([u, 0, 0, n, 0]))[0, 0] == pytest.approx(coast + thrust / mx,
                                                                         rel=1e-9)


def test_rudder_astern_switch(spec: dict[str, Any]) -> None:
    """switch_rudder_astern = 0 drops the rudder force for n <= 0 (module doc): the rudder then
    changes nothing; for n > 0 the switch changes nothing."""
    off = _with(spec, switch_rudder_astern=0.0)
    base_states = np.array([[0.3, 0.02, 0.03, n, 0.0] for n in (-12.0, 0.0, 10.0)])
    over = base_states.copy()
    over[:, 4] = 0.4
    a_off, b_off = _accel(off, base_states), _accel(off, over)
    np.testing.assert_array_equal(a_off[:, :2], b_off[:, :2])
    assert np.abs(a_off[:, 2] - b_off[:, 2]).max() > 0.0
    np.testing.assert_array_equal(_accel(spec, over)[:, 2], b_off[:, 2])
    assert np.abs(_accel(spec, over)[:, :2] - b_off[:, :2]).max() > 0.0


@pytest.mark.parametrize("key", ["switch_prop_y", "switch_prop_n", "switch_rudder_astern"])
def test_switch_must_be_zero_or_one(spec: dict[str, Any], key: str) -> None:
    bad = _with(spec, **{key: 0.5})
    bad["name"] = "bad_ship"
    with pytest.raises(InputError, match=rf"coefficients\.{key}: .*must be 0 or 1.*bad_ship"):
        FAMILY.build([spec, bad])


def _write_ship(path: Path, spec: dict[str, Any]) -> None:
    import yaml

    doc = {k: v for k, v in spec.items() if k not in ("path", "mmg_folder", "sensors")}
    doc["name"] = "berthing_file"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


def test_switch_error_names_the_ship_file(spec: dict[str, Any], tmp_path: Path) -> None:
    """Like every other ship-file coefficient error (``base.coefficient``), the bad switch value
    is located: the message names the file."""
    file = tmp_path / "berthing.yaml"
    _write_ship(file, _with(spec, switch_prop_y=2.0))
    with pytest.raises(InputError) as err:  # (the ranges are checked as the file is read)
        load_ship(str(file))
    assert err.value.key == "coefficients.switch_prop_y"
    assert str(file) in str(err.value)


def test_missing_particular_error_names_the_ship_file(spec: dict[str, Any],
                                                      tmp_path: Path) -> None:
    file = tmp_path / "berthing.yaml"
    _write_ship(file, spec)
    ship = load_ship(str(file))
    del ship["particulars"]["propeller_pitch_ratio"]
    with pytest.raises(InputError, match="propeller_pitch_ratio") as err:
        FAMILY.build([ship])
    assert err.value.key == "particulars.propeller_pitch_ratio" and str(file) in str(err.value)


def test_wind_enters_through_the_mass_matrix(spec: dict[str, Any]) -> None:
    """The wind's share of the accelerations is M^-1 (X_A, Y_A, N_A) of the Isherwood loads."""
    from trafficsim.ships import wind

    rng = np.random.default_rng(9)
    k = 20
    states = np.column_stack([rng.uniform(-0.3, 0.5, k), rng.uniform(-0.1, 0.1, k),
                              rng.uniform(-0.15, 0.15, k), rng.uniform(-20, 20, k),
                              rng.uniform(-0.6, 0.6, k)])
    psi = rng.uniform(0, 6, k)
    env = base.Env(wind_speed_mps=rng.uniform(1, 8, k), wind_from_rad=rng.uniform(0, 6.3, k))
    diff = _accel_env(spec, states, psi, env) - _accel_env(spec, states, psi)
    x = np.zeros((base.N_STATE, k))
    x[U], x[V], x[PSI] = states[:, 0], states[:, 1], psi
    xa, ya, na = wind.wind_loads(wind.build([spec] * k), x, env)
    mx, M = _mass(spec)
    want = np.vstack([xa / mx, np.linalg.solve(M, np.vstack([ya, na]))])
    assert np.abs(want).max() > 0.0
    np.testing.assert_allclose(diff, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())
