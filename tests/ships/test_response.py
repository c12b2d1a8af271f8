"""Tests of the ``response`` family [seed 001, eq 2, tables 1-2] and its ship file."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from trafficsim.ships import base, manoeuvres, response
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, Actuators, Env, U, V
from trafficsim.ships.base import R as YAW
from trafficsim.ships.library import load_ship
from trafficsim.ships.response import FAMILY, ResponseParams

KNOT = 1852.0 / 3600.0


@pytest.fixture(scope="module")
def spec() -> dict:
    return load_ship("bulk_carrier")


def _ratio(c: dict) -> float:
    """Steady straight speed per rpm, (m/s)/rpm: root of a1 x^2 + a8 x + a9 = 0 [seed 001, eq 2]."""
    a1, a8, a9 = c["a1"], c["a8"], c["a9"]
    return float((-a8 - np.sqrt(a8 * a8 - 4.0 * a1 * a9)) / (2.0 * a1))


def _run(specs: list[dict], x0: np.ndarray, command, dt: float, t_end: float) -> np.ndarray:
    """Integrate ``specs`` from ``x0`` with ``command(t) -> (rudder_rad, rps)``; returns history."""
    params = FAMILY.build(specs)
    act = Actuators.from_specs(specs)
    x = x0.copy()
    out = [x.copy()]
    for k in range(round(t_end / dt)):
        rud, rps = command(k * dt)
        x = base.step(FAMILY, params, act, x, rud, rps, Env(), dt)
        out.append(x.copy())
    return np.array(out)


def test_printed_a1_sign_has_no_straight_equilibrium(spec: dict) -> None:
    """Table 1 prints a1 = +1.4347e-4: then du/dt > 0 at every speed (no steady straight run);
    with the resistance sign, a1 < 0, the root is u = 0.0781 (m/s)/rpm."""
    c = spec["coefficients"]
    assert c["a1"] == pytest.approx(-1.4347e-4)
    printed = -c["a1"]
    assert c["a8"] ** 2 - 4.0 * printed * c["a9"] < 0.0  # no real root: du/dt never 0
    u = np.linspace(0.0, 30.0, 301)
    n = 60.0
    assert np.all(printed * u * u + c["a8"] * u * n + c["a9"] * n * n > 0.0)
    assert _ratio(c) == pytest.approx(0.0781, abs=5e-5)


def test_si_conversion_matches_paper_polynomial(spec: dict) -> None:
    """SI accelerations equal [seed 001, eq 2] evaluated in the paper's units (deg, deg/s, rpm)."""
    c = spec["coefficients"]
    rng = np.random.default_rng(1)
    x = np.zeros((base.N_STATE, 50))
    x[U] = rng.uniform(2.0, 8.0, 50)
    x[V] = rng.uniform(-1.0, 1.0, 50)
    x[YAW] = rng.uniform(-0.02, 0.02, 50)
    x[RUDDER] = rng.uniform(-0.6, 0.6, 50)
    x[RPS] = rng.uniform(0.3, 1.6, 50)
    du, dv, dr = base.accelerations(FAMILY, FAMILY.build([spec] * 50), x, Env())
    u, v, r, d, n = x[U], x[V], np.degrees(x[YAW]), np.degrees(x[RUDDER]), 60.0 * x[RPS]
    f1 = (c["a1"] * u**2 + c["a2"] * v**2 + c["a3"] * r**2 + c["a4"] * d**2 + c["a5"] * v * r
          + c["a6"] * v * d + c["a7"] * r * d + c["a8"] * u * n + c["a9"] * n**2)
    f2 = c["b1"] * v + c["b2"] * r + c["b3"] * d + c["b4"] * u * r
    f3 = c["c1"] * v + c["c2"] * r + c["c3"] * d  # deg/s2
    np.testing.assert_allclose(du, f1, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(dv, f2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.degrees(dr), f3, rtol=1e-12, atol=1e-15)


def test_positive_rudder_turns_to_starboard(spec: dict) -> None:
    """c3 > 0 with c2 < 0: positive helm gives a positive (starboard) yaw rate; no flip."""
    assert spec["coefficients"]["c3"] > 0 and spec["coefficients"]["c2"] < 0
    x0 = np.zeros((base.N_STATE, 1))
    x0[U], x0[RPS] = 6.0, 6.0 / _ratio(spec["coefficients"]) / 60.0
    hist = _run([spec], x0, lambda t: (np.array([0.2]), x0[RPS].copy()), 1.0, 120.0)
    assert hist[-1, YAW, 0] > 0.0
    assert hist[-1, V, 0] < 0.0  # drift outwards (to port) in a starboard turn


def test_steady_straight_speed(spec: dict) -> None:
    """At 56 rpm (the table 2 condition) the ship settles at u = 0.0781 x 56 = 4.37 m/s."""
    rpm = 56.0
    expected = _ratio(spec["coefficients"]) * rpm
    x0 = np.zeros((base.N_STATE, 1))
    x0[U], x0[RPS] = 2.0, rpm / 60.0
    hist = _run([spec], x0, lambda t: (np.zeros(1), np.array([rpm / 60.0])), 2.0, 4000.0)
    assert hist[-1, U, 0] == pytest.approx(expected, rel=1e-3)
    params, act = FAMILY.build([spec]), Actuators.from_specs([spec])
    rps = base.steady_rps_for_speed(FAMILY, params, act, np.array([expected]))
    assert rps[0] * 60.0 == pytest.approx(rpm, rel=1e-6)
    # service speed is reachable below rps_max
    service = spec["service_speed_kn"] * KNOT
    assert service / _ratio(spec["coefficients"]) / 60.0 < spec["actuators"]["rps_max"]


def test_turning_indices_against_table2(spec: dict) -> None:
    """[seed 001, table 2]: the identified model's turning circle ("Simulated": advance 805,
    transfer 525, diameter 978 m; the target ship's "Measured" 790/500/980 differ by up to 5 %).

    The paper states neither the approach speed nor the rudder angle of its turning test, so
    both are fitted here to the advance and the transfer; the diameter is then a prediction and
    must come within 5 % (the paper's own largest model error). "Diameter" is read as the
    tactical diameter (transfer at 180 deg), about twice the transfer as in the table.
    """
    ratio = _ratio(spec["coefficients"])

    def indices(rudder_deg: float, rpm: float) -> dict:
        return manoeuvres.turning_circle(spec, rudder_deg=rudder_deg, speed_kn=ratio * rpm / KNOT,
                                         dt=1.0, turns_deg=200.0)[1]

    def misfit(p: np.ndarray) -> list[float]:
        ind = indices(*p)
        return [ind["advance_m"] / 805.0 - 1.0, ind["transfer_m"] / 525.0 - 1.0]

    fit = least_squares(misfit, [22.0, 45.0], diff_step=1e-3)
    rudder_deg, rpm = fit.x
    assert 10.0 < rudder_deg < 35.0 and 0.0 < ratio * rpm / KNOT <= spec["service_speed_kn"]
    ind = indices(rudder_deg, rpm)
    assert ind["advance_m"] == pytest.approx(805.0, rel=1e-3)
    assert ind["transfer_m"] == pytest.approx(525.0, rel=1e-3)
    assert ind["tactical_diameter_m"] == pytest.approx(978.0, rel=0.05)


def test_mirror_symmetry(spec: dict) -> None:
    x0 = np.zeros((base.N_STATE, 2))
    x0[U], x0[RPS] = 6.0, 1.3

    def command(t: float) -> tuple[np.ndarray, np.ndarray]:
        d = np.radians(25.0) * np.sign(np.sin(t / 90.0) + 0.3)
        return np.array([d, -d]), np.array([1.3, 1.3])

    hist = _run([spec, spec], x0, command, 1.0, 900.0)
    a, b = hist[:, :, 0], hist[:, :, 1]
    np.testing.assert_allclose(a[:, NORTH], b[:, NORTH], atol=1e-6)
    np.testing.assert_allclose(a[:, EAST], -b[:, EAST], atol=1e-6)
    np.testing.assert_allclose(a[:, U], b[:, U], atol=1e-9)
    np.testing.assert_allclose(a[:, V], -b[:, V], atol=1e-9)
    np.testing.assert_allclose(a[:, YAW], -b[:, YAW], atol=1e-12)
    psi_a = (a[:, PSI] + np.pi) % (2 * np.pi) - np.pi
    psi_b = (b[:, PSI] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(psi_a, -psi_b, atol=1e-9)


def test_stable_at_dt_one_second(spec: dict) -> None:
    """Hard-over turns, engine stops, astern orders and restarts at dt = 1 s stay bounded."""
    rng = np.random.default_rng(7)
    n = 20
    x0 = np.zeros((base.N_STATE, n))
    x0[U] = rng.uniform(0.0, 7.0, n)
    rud = rng.choice([-0.61, -0.2, 0.0, 0.3, 0.61], size=(40, n))
    rps = rng.choice([-1.0, 0.0, 0.5, 1.0, 1.58], size=(40, n))

    def command(t: float) -> tuple[np.ndarray, np.ndarray]:
        k = int(t // 120.0)
        return rud[k], rps[k]

    hist = _run([spec] * n, x0, command, 1.0, 4799.0)
    assert np.all(np.isfinite(hist))
    assert np.abs(hist[:, U]).max() < 8.0
    assert np.abs(hist[:, V]).max() < 2.0
    assert np.abs(hist[:, YAW]).max() < np.radians(2.0)


def test_no_astern_and_no_motion_at_rest(spec: dict) -> None:
    """The n^2 form cannot reverse thrust: negative rps acts as a stopped engine; a ship at rest
    with helm on does not turn (rudder terms fade out with speed)."""
    assert FAMILY.supports_astern is False
    assert spec["actuators"]["rps_min"] == 0.0
    x = np.zeros((base.N_STATE, 2))
    x[U] = 3.0
    x[RPS] = [-1.0, 0.0]
    du, dv, dr = base.accelerations(FAMILY, FAMILY.build([spec, spec]), x, Env())
    assert du[0] == du[1] < 0.0
    x = np.zeros((base.N_STATE, 1))
    x[RUDDER] = 0.6
    du, dv, dr = base.accelerations(FAMILY, FAMILY.build([spec]), x, Env())
    assert du[0] == dv[0] == dr[0] == 0.0


def test_vectorised_equals_single(spec: dict) -> None:
    other = copy.deepcopy(spec)
    other["coefficients"]["c3"] *= 1.5
    specs = [spec, other, spec]
    x0 = np.zeros((base.N_STATE, 3))
    x0[U] = [3.0, 5.0, 6.5]
    x0[RPS] = [0.8, 1.1, 1.4]

    def command(t: float) -> tuple[np.ndarray, np.ndarray]:
        return np.array([0.3, -0.2, 0.1]) * np.cos(t / 60.0), np.array([0.8, 1.1, 1.4])

    together = _run(specs, x0, command, 1.0, 300.0)
    for i, s in enumerate(specs):
        alone = _run([s], x0[:, i:i + 1],
                     lambda t, i=i: tuple(c[i:i + 1] for c in command(t)), 1.0, 300.0)
        np.testing.assert_allclose(together[:, :, i], alone[:, :, 0], rtol=1e-12, atol=1e-12)


def test_kernel_columns_follow_params_fields() -> None:
    """The kernel's column constants index the packed row in ResponseParams field order."""
    for i, f in enumerate(dataclasses.fields(ResponseParams)):
        assert getattr(response, "_" + f.name.upper()) == i, f.name
    assert not hasattr(FAMILY, "accelerations")  # one implementation: the compiled kernel


# ----------------------------------------------------------------------- guards and stability


def _accel(spec: dict, x: np.ndarray) -> np.ndarray:
    return np.array(base.accelerations(FAMILY, FAMILY.build([spec] * x.shape[1]), x, Env()))


def test_rudder_fade_is_quadratic_below_the_fade_speed_and_one_above(spec: dict) -> None:
    """Rudder terms (a4, a6, a7, b3, c3) x min(1, (u/u_fade)^2): the part of each acceleration
    due to the rudder (with-rudder minus no-rudder, v = r = 0) at u = u_fade/2 is 1/4 of the
    polynomial's, at -u_fade/2 too, at u_fade and 2 u_fade it is all of it."""
    c = spec["coefficients"]
    fade = c.get("rudder_fade_speed_mps", 1.0)
    D = 180.0 / np.pi
    d = 0.3
    for u, factor in ((0.5 * fade, 0.25), (-0.5 * fade, 0.25), (fade, 1.0), (2 * fade, 1.0),
                      (0.0, 0.0)):
        x = np.zeros((base.N_STATE, 2))
        x[U], x[RUDDER] = u, [d, 0.0]
        a = _accel(spec, x)
        delta = a[:, 0] - a[:, 1]
        want = np.array([c["a4"] * (D * d) ** 2, c["b3"] * D * d, c["c3"] * D * d / D])
        np.testing.assert_allclose(delta, factor * want, rtol=1e-12, atol=1e-18)


def test_resistance_opposes_motion_astern(spec: dict) -> None:
    """a1 u|u| (a1 < 0): moving astern with the engine stopped, du > 0 and equal in size to
    the ahead case, du(-u) = -du(u)."""
    x = np.zeros((base.N_STATE, 2))
    x[U] = [2.5, -2.5]
    du = _accel(spec, x)[0]
    assert du[1] > 0.0 and du[1] == pytest.approx(-du[0], rel=1e-15)
    assert du[0] == pytest.approx(spec["coefficients"]["a1"] * 2.5**2, rel=1e-12)


def test_straight_line_stability_changes_sign_at_7_72_mps(spec: dict) -> None:
    """The sway-yaw part is stable while b1 c2 - (b2 + b4 u) c1 > 0, i.e. u < 7.72 m/s (module
    docstring): the eigenvalues of the (v, r) Jacobian, taken from the kernel by differences,
    all have negative real part at 7.6 m/s and one is positive at 7.85 m/s. The ship file's
    rps_max keeps the steady straight speed below the boundary."""
    c = spec["coefficients"]
    boundary = (c["b1"] * c["c2"] / c["c1"] - c["b2"]) / c["b4"]
    assert boundary == pytest.approx(7.72, abs=0.005)
    for u, stable in ((7.6, True), (7.85, False)):
        x = np.zeros((base.N_STATE, 1))
        x[U] = u
        jac = np.zeros((2, 2))
        for k, row in enumerate((V, YAW)):
            xp, xm = x.copy(), x.copy()
            xp[row] += 1e-6
            xm[row] -= 1e-6
            jac[:, k] = (_accel(spec, xp)[1:, 0] - _accel(spec, xm)[1:, 0]) / 2e-6
        assert (np.linalg.eigvals(jac).real.max() < 0.0) == stable, u
    top = _ratio(c) * 60.0 * spec["actuators"]["rps_max"]
    assert top < boundary


def test_turning_circle_port_mirrors_starboard(spec: dict) -> None:
    """The polynomial is odd in (v, r, delta) for dv, dr and even for du: a port turn is the
    starboard turn mirrored, so the manoeuvre indices are equal and the track is reflected."""
    tr_s, stbd = manoeuvres.turning_circle(spec, rudder_deg=20.0, dt=2.0, turns_deg=200.0)
    tr_p, port = manoeuvres.turning_circle(spec, rudder_deg=-20.0, dt=2.0, turns_deg=200.0)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m", "time_to_90_s",
                "time_to_180_s", "speed_loss_ratio"):
        assert port[key] == pytest.approx(stbd[key], rel=1e-9), key
    np.testing.assert_allclose(tr_p["east_m"], -tr_s["east_m"], atol=1e-6)
    np.testing.assert_allclose(tr_p["north_m"], tr_s["north_m"], atol=1e-6)


def test_steady_rps_for_speed_equals_a_scipy_root_and_caps(spec: dict) -> None:
    """brentq of the paper-unit surge polynomial at straight running (independent of the SI
    conversion) agrees with the compiled bisection; a speed above the full-power speed returns
    rps_max, and speed 0 returns 0."""
    from scipy.optimize import brentq

    c, a = spec["coefficients"], spec["actuators"]
    speeds = np.array([0.0, 2.0, 5.5, 7.3, 9.0])
    n = len(speeds)
    got = base.steady_rps_for_speed(FAMILY, FAMILY.build([spec] * n),
                                    Actuators.from_specs([spec] * n), speeds)
    for u, g in zip(speeds[1:4], got[1:4], strict=True):
        rpm = brentq(lambda m, u=u: c["a1"] * u * u + c["a8"] * u * m + c["a9"] * m * m,
                     0.0, 200.0, xtol=1e-13)
        assert g == pytest.approx(rpm / 60.0, rel=1e-9)
    assert got[0] == pytest.approx(0.0, abs=1e-12)
    assert got[4] == pytest.approx(a["rps_max"], rel=1e-12)


@pytest.mark.parametrize("fade", [0.0, -1.0, float("nan")])
def test_a_fade_speed_that_is_not_positive_is_refused(spec: dict, fade: float) -> None:
    """u / u_fade is 0/0 at rest with a zero fade speed (the rudder then acts fully, and a
    ship at rest with helm on turns): refused, naming the ship file and the key."""
    from trafficsim.errors import ShipLibraryError

    bad = copy.deepcopy(spec)
    bad["coefficients"]["rudder_fade_speed_mps"] = fade
    with pytest.raises(ShipLibraryError, match="rudder_fade_speed_mps > 0") as err:
        FAMILY.build([bad])
    assert err.value.key == "coefficients.rudder_fade_speed_mps"
    assert err.value.path == spec.get("path")
