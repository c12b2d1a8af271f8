"""Standard manoeuvres: the indices are read off the track correctly, and the IMO limits."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from trafficsim.errors import InputError
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn


def test_turning_indices_agree_with_the_track_geometry():
    spec = load_ship("cargo")
    track, ind = manoeuvres.turning_circle(spec, rudder_deg=20.0)
    # steady part: the circle through the last points has the steady diameter
    n, e = track["north_m"][-200:], track["east_m"][-200:]
    A = np.column_stack([2 * n, 2 * e, np.ones_like(n)])
    cn, ce, c = np.linalg.lstsq(A, n**2 + e**2, rcond=None)[0]
    radius = np.sqrt(c + cn**2 + ce**2)
    assert ind["steady_diameter_m"] == pytest.approx(2 * radius, rel=0.01)
    # steady turn: D = 2 U / r
    u, r = from_kn(track["sog_kn"][-1]), np.radians(track["r_degps"][-1])
    assert ind["steady_diameter_m"] == pytest.approx(2 * u / r, rel=0.01)
    assert ind["transfer_m"] < ind["tactical_diameter_m"] < 1.5 * ind["steady_diameter_m"]
    assert 0 < ind["time_to_90_s"] < ind["time_to_180_s"]
    assert 0.3 < ind["speed_loss_ratio"] <= 1.0


def test_port_and_starboard_turns_mirror_for_a_symmetric_model():
    spec = load_ship("cargo")
    _, stbd = manoeuvres.turning_circle(spec, rudder_deg=35.0)
    track, port = manoeuvres.turning_circle(spec, rudder_deg=-35.0)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m"):
        assert port[key] == pytest.approx(stbd[key], rel=1e-6)
    assert track["east_m"][len(track["east_m"]) // 8] < 0  # a port turn goes west from north


def test_zigzag_reverses_the_rudder_at_the_heading_limit():
    spec = load_ship("container")
    track, ind = manoeuvres.zigzag(spec, rudder_deg=10.0)
    change = np.unwrap(np.radians(track["heading_deg"])) - np.radians(track["heading_deg"][0])
    flips = np.flatnonzero(np.diff(np.sign(track["rudder_deg"][1:])) != 0)
    assert flips.size >= 3
    # first reversal command at 10 deg of heading change
    assert ind["initial_turning_time_s"] > 0
    first_swing = np.degrees(change[: flips[1] + 2])  # until the second reversal
    assert first_swing.max() == pytest.approx(10.0 + ind["first_overshoot_deg"], abs=1e-9)
    assert 0 < ind["first_overshoot_deg"] < ind["second_overshoot_deg"] + 10


def test_crash_stop_needs_astern_power():
    with pytest.raises(InputError, match="cannot go astern"):
        manoeuvres.crash_stop(load_ship("catfish"))
    _, ind = manoeuvres.crash_stop(load_ship("kvlcc2"))
    assert 0 < ind["head_reach_m"] <= ind["track_reach_m"]
    assert ind["time_to_stop_s"] > 60
    # Nomoto traffic: quadratic surge gives stopping distances of real merchant ships (5-15 L)
    _, ind = manoeuvres.crash_stop(load_ship("cargo"))
    assert 5.0 < ind["track_reach_m"] / ind["length_m"] < 15.0


@pytest.mark.parametrize("l_over_v, first, second", [
    (5.0, 10.0, 25.0), (20.0, 15.0, 32.5), (40.0, 20.0, 40.0)])
def test_imo_overshoot_limits_depend_on_l_over_v(l_over_v, first, second):
    """MSC.137(76) 5.3.3: 10/10 first overshoot 10 deg below L/V = 10 s, 20 deg above 30 s,
    5 + 0.5 L/V between; second overshoot 25 / 40 deg, 17.5 + 0.75 L/V between."""
    length = 100.0
    speed_kn = length / l_over_v / from_kn(1.0)
    ind = {"length_m": length, "approach_speed_kn": speed_kn, "rudder_deg": 10.0,
           "heading_deg": 10.0, "initial_turning_distance_L": 2.0, "first_overshoot_deg": 12.0,
           "second_overshoot_deg": 30.0}
    crit = manoeuvres.imo_criteria("zigzag", ind)
    assert crit["first_overshoot_deg"]["limit"] == pytest.approx(first)
    assert crit["second_overshoot_deg"]["limit"] == pytest.approx(second)
    assert crit["first_overshoot_deg"]["pass"] == (first >= 12.0)


def test_imo_turning_and_stopping_limits():
    crit = manoeuvres.imo_criteria("turning", {"length_m": 100.0, "advance_m": 460.0,
                                               "tactical_diameter_m": 480.0})
    assert not crit["advance_L"]["pass"] and crit["tactical_diameter_L"]["pass"]
    crit = manoeuvres.imo_criteria("crash-stop", {"length_m": 100.0, "track_reach_m": 1400.0})
    assert crit["track_reach_L"]["pass"] and crit["track_reach_L"]["limit"] == 15.0


# ---------------------------------------------------------------------------------------------
# indices against closed forms and an independent integration of the same linear Nomoto ship


def _nomoto(k_prime=1.0, t_prime=2.0, rate_degps=2.32, rudder_tau_s=1.0, engine_tau_s=20.0,
            max_dt_s=1.0, length_m=100.0, speed_kn=10.0):
    """A linear (n3' = 0) Nomoto ship built on the cargo file: at constant propeller speed it
    keeps its speed exactly and never sways, so its track follows from the heading alone."""
    spec = load_ship("cargo")
    spec["particulars"]["length_m"] = length_m
    spec["service_speed_kn"] = speed_kn
    spec["coefficients"].update(K_prime=k_prime, T_prime=t_prime, n3_prime=0.0)
    spec["actuators"].update(rudder_rate_degps=rate_degps, rudder_tau_s=rudder_tau_s,
                             engine_tau_s=engine_tau_s)
    spec["integration"] = {"max_dt_s": max_dt_s}
    return spec


def _reference(spec, segments, marks=()):
    """Nomoto steering at constant speed U integrated by scipy from straight ahead:
    ``delta' = clip((order - delta) / tau, +-rate)``, ``r' = (K' U / L delta - r) U / (T' L)``,
    ``psi' = r``, ``n' = U cos psi``, ``e' = U sin psi``. ``segments`` is a list of
    ``(order_rad, event)``: each runs until its event ``event(t, y)`` crosses zero upwards;
    ``marks`` are further events recorded on the way (``t_events[1:]``). Returns the solution
    of each segment."""
    c, a = spec["coefficients"], spec["actuators"]
    L, U = spec["particulars"]["length_m"], from_kn(spec["service_speed_kn"])
    K, T = c["K_prime"] * U / L, c["T_prime"] * L / U
    tau, rate = a["rudder_tau_s"], math.radians(a["rudder_rate_degps"])

    y, t0, sols = np.zeros(5), 0.0, []
    for order, event in segments:
        def rhs(t, s, order=order):
            d = min(max((order - s[4]) / tau, -rate), rate)
            return [U * math.cos(s[2]), U * math.sin(s[2]), s[3], (K * s[4] - s[3]) / T, d]
        event.terminal, event.direction = True, 1.0
        sol = solve_ivp(rhs, (t0, t0 + 1e5), y, method="DOP853", rtol=1e-11, atol=1e-9,
                        events=[event, *marks])
        sols.append(sol)
        t0, y = sol.t[-1], sol.y[:, -1]
    return sols


def test_turning_indices_of_a_nomoto_ship_agree_with_an_independent_integration():
    """Advance and transfer at 90 deg, tactical diameter at 180 deg, times to 90 and 180 deg,
    and the steady diameter (track points 180 deg apart on the steady circle) equal those read
    off a scipy integration of the same equations by their ITTC definitions; the steady
    diameter is also the closed form ``2 U / r = 2 L / (K' delta)``; the speed is kept."""
    spec = _nomoto()
    rudder = 20.0
    _, ind = manoeuvres.turning_circle(spec, rudder_deg=rudder)

    levels = (90.0, 180.0, 360.0, 540.0)
    (sol,) = _reference(spec, [(math.radians(rudder),
                                lambda t, y: y[2] - math.radians(541.0))],
                        marks=[lambda t, y, lv=lv: y[2] - math.radians(lv) for lv in levels])
    ref = {lv: (sol.t_events[k + 1][0], sol.y_events[k + 1][0]) for k, lv in enumerate(levels)}
    assert ind["advance_m"] == pytest.approx(ref[90.0][1][0], rel=1e-4)
    assert ind["transfer_m"] == pytest.approx(ref[90.0][1][1], rel=1e-4)
    assert ind["tactical_diameter_m"] == pytest.approx(ref[180.0][1][1], rel=1e-4)
    assert ind["time_to_90_s"] == pytest.approx(ref[90.0][0], rel=1e-4)
    assert ind["time_to_180_s"] == pytest.approx(ref[180.0][0], rel=1e-4)
    p360, p540 = ref[360.0][1], ref[540.0][1]
    steady = math.hypot(p360[0] - p540[0], p360[1] - p540[1])
    assert ind["steady_diameter_m"] == pytest.approx(steady, rel=1e-4)
    assert ind["steady_diameter_m"] == pytest.approx(2 * 100.0 / math.radians(rudder),
                                                     rel=1e-3)
    assert ind["speed_loss_ratio"] == pytest.approx(1.0, abs=1e-9)
    assert ind["approach_speed_kn"] == pytest.approx(10.0, rel=1e-9)


def test_a_ship_without_lags_turns_on_a_perfect_circle():
    """Rudder and yaw lags of a fraction of a second: the track is a circle of radius
    ``R = L / (K' delta)`` from the execute point, so advance = transfer = R, tactical and
    steady diameter = 2 R, and 90 deg take a quarter circle at the approach speed."""
    spec = _nomoto(t_prime=0.005, rate_degps=90.0, rudder_tau_s=0.01, max_dt_s=0.01)
    _, ind = manoeuvres.turning_circle(spec, rudder_deg=-20.0)
    radius = 100.0 / math.radians(20.0)  # 286.5 m
    speed = from_kn(10.0)
    assert ind["advance_m"] == pytest.approx(radius, rel=5e-3)
    assert ind["transfer_m"] == pytest.approx(radius, rel=5e-3)
    assert ind["tactical_diameter_m"] == pytest.approx(2 * radius, rel=5e-3)
    assert ind["steady_diameter_m"] == pytest.approx(2 * radius, rel=5e-3)
    assert ind["time_to_90_s"] == pytest.approx(0.5 * math.pi * radius / speed, rel=5e-3)
    assert ind["time_to_180_s"] == pytest.approx(math.pi * radius / speed, rel=5e-3)


def test_zigzag_indices_agree_with_an_independent_integration():
    """A 10/10 zig-zag of the linear Nomoto ship: initial turning time, distance run by then
    (``U t`` at constant speed, in ship lengths) and both overshoots (the heading's extreme
    after each reversal beyond the heading limit) equal those of a scipy integration that
    reverses the rudder exactly at the heading limit. Steps of 0.05 s: a reversal is seen at
    most one step late."""
    spec = _nomoto()
    dt = 0.05
    _, ind = manoeuvres.zigzag(spec, rudder_deg=10.0, dt=dt, reversals=2)
    lim, rud = math.radians(10.0), math.radians(10.0)
    sols = _reference(spec, [
        (rud, lambda t, y: y[2] - lim),  # to the first reversal
        (-rud, lambda t, y: -y[3]),  # until the heading peaks
        (-rud, lambda t, y: -y[2] - lim),  # to the second reversal
        (rud, lambda t, y: y[3]),  # until the heading's trough
    ])
    t_init = sols[0].t[-1]
    first = math.degrees(sols[1].y[2, -1]) - 10.0
    second = -math.degrees(sols[3].y[2, -1]) - 10.0
    speed = from_kn(10.0)
    assert ind["initial_turning_time_s"] == pytest.approx(t_init, abs=dt)
    assert ind["initial_turning_distance_L"] == pytest.approx(speed * t_init / 100.0,
                                                              abs=speed * dt / 100.0)
    r_max = 0.5  # deg/s, a bound on the yaw rate at the reversals (0.36 and 0.45 deg/s)
    assert ind["first_overshoot_deg"] == pytest.approx(first, abs=2 * r_max * dt)
    assert ind["second_overshoot_deg"] == pytest.approx(second, abs=4 * r_max * dt)
    assert first > 1.0 and second > first


def test_crash_stop_of_a_nomoto_ship_against_the_quadratic_surge_closed_form():
    """With the engine reversed at once, ``du/dt = -(u_a^2 + u^2) / (2 U_s T_u)`` (astern
    steady speed ``u_a = U_s n_min / n_s``) stops the ship after ``t = 2 U_s T_u
    atan(U_s / u_a) / u_a`` having run ``U_s T_u ln(1 + U_s^2 / u_a^2)`` straight ahead."""
    spec = _nomoto(engine_tau_s=0.05, max_dt_s=0.02)
    track, ind = manoeuvres.crash_stop(spec)
    c = spec["coefficients"]
    us, tu = from_kn(10.0), c["surge_tau_s"]
    ua = us * -spec["actuators"]["rps_min"] / c["rps_service"]  # 0.5 U_s
    t_stop = 2 * us * tu * math.atan(us / ua) / ua
    reach = us * tu * math.log(1 + (us / ua) ** 2)
    dt = track["t_s"][1] - track["t_s"][0]
    assert t_stop <= ind["time_to_stop_s"] <= t_stop + dt + 0.1
    assert ind["head_reach_m"] == pytest.approx(reach, rel=1e-3)
    assert ind["track_reach_m"] == pytest.approx(ind["head_reach_m"], rel=1e-12)
    assert ind["lateral_deviation_m"] == pytest.approx(0.0, abs=1e-9)


def test_track_has_the_trial_data_columns_and_units():
    """Every column, equal lengths, time from 0 in steps of dt, rpm = 60 rps, SOG in knots,
    COG = heading for a ship that does not sway (no current), heading in degrees."""
    spec = _nomoto()
    track, _ = manoeuvres.turning_circle(spec, rudder_deg=15.0, dt=0.5, turns_deg=90.0)
    keys = {"t_s", "north_m", "east_m", "heading_deg", "rudder_deg", "rpm", "u_mps", "v_mps",
            "r_degps", "sog_kn", "cog_deg"}
    assert set(track) == keys
    n = len(track["t_s"])
    assert all(len(v) == n for v in track.values())
    np.testing.assert_allclose(track["t_s"], 0.5 * np.arange(n), atol=1e-9)
    np.testing.assert_allclose(track["sog_kn"], 10.0, rtol=1e-9)
    np.testing.assert_allclose(track["rpm"], 60.0 * 1.3333 * 10.0 / 10.0, rtol=1e-9)
    np.testing.assert_allclose(np.cos(np.radians(track["cog_deg"] - track["heading_deg"])), 1.0,
                               atol=1e-12)
    assert track["heading_deg"][-2] < 90.0 <= track["heading_deg"][-1]
    assert track["rudder_deg"][0] == 0.0 and 0.0 < track["rudder_deg"][-1] <= 15.0


@pytest.mark.parametrize("kwargs, key", [
    ({"dt": 0.0}, "dt_s"), ({"dt": 5e-4}, "dt_s"), ({"dt": 60.5}, "dt_s"),
    ({"dt": float("nan")}, "dt_s"), ({"speed_kn": 30.5}, "speed_kn"),
    ({"speed_kn": float("nan")}, "speed_kn"), ({"rudder_deg": 35.5}, "rudder_deg"),
    ({"rudder_deg": -36.0}, "rudder_deg"), ({"rudder_deg": float("nan")}, "rudder_deg"),
])
def test_bad_manoeuvre_arguments_are_input_errors_naming_the_argument(kwargs, key):
    """Time step outside [1 ms, 60 s], approach faster than twice the service speed (15 kn
    for cargo), rudder beyond the 35 deg limit, or NaN: ``InputError`` with the argument."""
    with pytest.raises(InputError) as info:
        manoeuvres.turning_circle(load_ship("cargo"), **kwargs)
    assert info.value.key == key
    if "speed_kn" not in kwargs:
        with pytest.raises(InputError) as info:
            manoeuvres.zigzag(load_ship("cargo"), **kwargs)
        assert info.value.key == key


def test_limits_of_the_time_step_and_speed_are_accepted():
    """A turn's dt up to L/U is accepted (beyond it refused; a crash stop takes up to 60 s).
    An approach speed the engine cannot hold is refused naming the speed it holds at full
    power: with the quadratic surge that is ``rps_max / rps_service`` x 10 kn = 13.33 kn;
    just below it the ship approaches at that speed."""
    cargo = load_ship("cargo")
    most = cargo["particulars"]["length_m"] / from_kn(cargo["service_speed_kn"])
    _, ind = manoeuvres.turning_circle(cargo, dt=most, turns_deg=90.0)
    assert ind["time_to_90_s"] > 0
    with pytest.raises(InputError, match="expected at most L/U"):
        manoeuvres.turning_circle(cargo, dt=1.01 * most, turns_deg=90.0)
    spec = _nomoto()
    top_kn = 10.0 * spec["actuators"]["rps_max"] / spec["coefficients"]["rps_service"]
    with pytest.raises(InputError) as err:
        manoeuvres.turning_circle(spec, speed_kn=20.0, dt=0.5, turns_deg=90.0)
    assert err.value.key == "speed_kn" and f"it makes {top_kn:.2f} kn, got 20 kn" in str(err.value)
    _, ind = manoeuvres.turning_circle(spec, speed_kn=top_kn - 0.01, dt=0.5, turns_deg=90.0)
    assert ind["approach_speed_kn"] == pytest.approx(top_kn - 0.01, rel=1e-6)


def test_zigzag_to_port_first_mirrors_or_is_refused():
    """A -10/-10 zig-zag (first rudder to port) of a port-starboard symmetric model either
    mirrors the starboard one (same indices) or is refused as an ``InputError``; it must not
    return indices of a manoeuvre that never happened."""
    spec = load_ship("cargo")
    _, stbd = manoeuvres.zigzag(spec, rudder_deg=10.0)
    try:
        _, port = manoeuvres.zigzag(spec, rudder_deg=-10.0)
    except InputError:
        return
    for key in ("initial_turning_time_s", "first_overshoot_deg", "second_overshoot_deg"):
        assert port[key] == pytest.approx(stbd[key], rel=1e-6), key


# ---------------------------------------------------------------------------------------------
# IMO criteria at their boundaries


def _zigzag_indices(l_over_v, rud=10.0, head=10.0, first=10.0, second=25.0, dist=2.5):
    length = 100.0
    return {"length_m": length, "approach_speed_kn": length / l_over_v / from_kn(1.0),
            "rudder_deg": rud, "heading_deg": head, "initial_turning_distance_L": dist,
            "first_overshoot_deg": first, "second_overshoot_deg": second}


def test_imo_limits_are_continuous_at_l_over_v_10_and_30_and_a_value_at_the_limit_passes():
    """5 + 0.5 x 10 = 10 and 5 + 0.5 x 30 = 20; 17.5 + 0.75 x 10 = 25 and 17.5 + 0.75 x 30 =
    40: the piecewise limits join. A value equal to the limit passes ("should not exceed");
    a NaN index (the manoeuvre never got there) fails."""
    for lv, first, second in ((10.0, 10.0, 25.0), (30.0, 20.0, 40.0)):
        crit = manoeuvres.imo_criteria("zigzag", _zigzag_indices(lv, first=first,
                                                                 second=second))
        assert crit["first_overshoot_deg"]["limit"] == pytest.approx(first, rel=1e-12)
        assert crit["second_overshoot_deg"]["limit"] == pytest.approx(second, rel=1e-12)
        assert crit["initial_turning_distance_L"]["pass"]
    crit = manoeuvres.imo_criteria("zigzag", _zigzag_indices(5.0, first=10.0, second=25.0))
    assert crit["first_overshoot_deg"]["pass"] and crit["second_overshoot_deg"]["pass"]
    crit = manoeuvres.imo_criteria("zigzag", _zigzag_indices(5.0, first=float("nan"),
                                                             dist=2.5001))
    assert not crit["first_overshoot_deg"]["pass"]
    assert not crit["initial_turning_distance_L"]["pass"]
    crit = manoeuvres.imo_criteria("turning", {"length_m": 200.0, "advance_m": 900.0,
                                               "tactical_diameter_m": 1000.0})
    assert crit["advance_L"]["value"] == 4.5 and crit["advance_L"]["pass"]
    assert crit["tactical_diameter_L"]["value"] == 5.0 and crit["tactical_diameter_L"]["pass"]


def test_imo_criteria_for_other_zigzags_and_kinds():
    """20/20: only the first overshoot, limited to 25 deg; other zig-zags and unknown kinds
    have no criterion in MSC.137(76)."""
    crit = manoeuvres.imo_criteria("zigzag", _zigzag_indices(20.0, rud=20.0, head=20.0,
                                                             first=25.0))
    assert set(crit) == {"first_overshoot_deg"}
    assert crit["first_overshoot_deg"]["limit"] == 25.0 and crit["first_overshoot_deg"]["pass"]
    assert manoeuvres.imo_criteria("zigzag", _zigzag_indices(20.0, rud=20.0, head=10.0)) == {}
    assert manoeuvres.imo_criteria("spiral", {"length_m": 100.0}) == {}


def test_zigzag_to_port_first_is_the_mirror_image_and_zero_is_refused():
    """Port first (-10/10) on a symmetric ship: the heading history is the starboard one
    mirrored, the indices the same, and the IMO criteria are those of the 10/10 test; a zero
    rudder or heading angle (a zig-zag that never reverses) is an input error."""
    spec = load_ship("cargo")
    stbd_track, stbd = manoeuvres.zigzag(spec, rudder_deg=10.0)
    port_track, port = manoeuvres.zigzag(spec, rudder_deg=-10.0)
    change = np.unwrap(np.radians(stbd_track["heading_deg"]))
    mirrored = np.unwrap(np.radians(port_track["heading_deg"]))
    np.testing.assert_allclose(mirrored - mirrored[0], -(change - change[0]), atol=1e-9)
    assert port["rudder_deg"] == -10.0
    assert set(manoeuvres.imo_criteria("zigzag", port)) == set(
        manoeuvres.imo_criteria("zigzag", stbd))
    for key, kwargs in (("rudder_deg", {"rudder_deg": 0.0}),
                        ("heading_deg", {"rudder_deg": 10.0, "heading_deg": 0.0})):
        with pytest.raises(InputError) as info:
            manoeuvres.zigzag(spec, **kwargs)
        assert info.value.key == key


@pytest.mark.parametrize("speed_kn", [0.0, -3.0, 1e-6, 1.49])
def test_an_approach_speed_below_a_tenth_of_the_service_speed_is_refused(speed_kn):
    """A standard manoeuvre needs headway: below 10 % of the service speed (1.5 kn for cargo;
    1e-6 kn gave NaN advance and tactical diameter) the indices are not defined, so it is an
    input error under ``speed_kn``; 10 % itself is accepted."""
    with pytest.raises(InputError, match=r"at least 0\.1 times the service speed of 'cargo' "
                                         r"\(15 kn\)") as info:
        manoeuvres.turning_circle(load_ship("cargo"), speed_kn=speed_kn)
    assert info.value.key == "speed_kn"
    _, ind = manoeuvres.turning_circle(load_ship("cargo"), speed_kn=1.5, turns_deg=90.0)
    assert np.isfinite(ind["advance_m"])


@pytest.mark.parametrize("heading_deg", [400.0, 170.0, 90.5, 0.99, 1e-9, -400.0])
def test_a_zigzag_heading_change_outside_1_to_90_deg_is_refused(heading_deg):
    """Below 1 deg the rudder reverses within a time step (1e-9 deg gave an 'initial turning
    time' of 4e-7 s), beyond 90 deg the manoeuvre is a turn: an input error under
    ``heading_deg``; 1 and 90 deg are accepted."""
    with pytest.raises(InputError, match="expected a heading change from 1 to 90 deg") as info:
        manoeuvres.zigzag(load_ship("fishing"), 10.0, heading_deg)
    assert info.value.key == "heading_deg"
    for ok in (1.0, 90.0):
        _, ind = manoeuvres.zigzag(load_ship("fishing"), 10.0, ok)
        assert np.isfinite(ind["second_overshoot_deg"])


# ---------------------------------------------------------------------------------------------
# a drifting ship (response family) against scipy, mirror images, argument checks


def _response_rhs(spec, rps, order_rad):
    """[seed 001, eq 2] in the paper's units (deg, deg/s, rpm) with the module's two guards,
    plus kinematics and the rate-limited first-order steering gear; SI state
    (north, east, psi, u, v, r, rudder), engine held at ``rps``."""
    c, a = spec["coefficients"], spec["actuators"]
    fade_speed = c.get("rudder_fade_speed_mps", 1.0)
    tau, rate = a["rudder_tau_s"], math.radians(a["rudder_rate_degps"])
    n = 60.0 * rps

    def rhs(t, s):
        _, _, psi, u, v, r, d = s
        rd, dd = math.degrees(r), math.degrees(d)
        f = min(1.0, (u / fade_speed) ** 2)
        du = (c["a1"] * u * abs(u) + c["a2"] * v * v + c["a3"] * rd * rd + c["a5"] * v * rd
              + f * (c["a4"] * dd * dd + c["a6"] * v * dd + c["a7"] * rd * dd)
              + c["a8"] * u * n + c["a9"] * n * n)
        dv = c["b1"] * v + c["b2"] * rd + c["b4"] * u * rd + f * c["b3"] * dd
        dr = math.radians(c["c1"] * v + c["c2"] * rd + f * c["c3"] * dd)
        ddelta = min(max((order_rad - d) / tau, -rate), rate)
        return [u * math.cos(psi) - v * math.sin(psi), u * math.sin(psi) + v * math.cos(psi),
                r, du, dv, dr, ddelta]

    return rhs


def test_turning_indices_of_a_drifting_ship_agree_with_an_independent_integration():
    """Bulk carrier (response family, it drifts and loses speed in the turn), 25 deg from
    8 kn: advance, transfer, tactical diameter and the times to 90 and 180 deg equal those of
    scipy's integration of the paper's polynomial in its own units, read at the exact
    heading-change events; the speed loss is the ground speed at the end over the approach."""
    spec = load_ship("bulk_carrier")
    c = spec["coefficients"]
    u0 = from_kn(8.0)
    a1, a8, a9 = c["a1"], c["a8"], c["a9"]
    rpm = u0 * (-a8 + math.sqrt(a8 * a8 - 4 * a1 * a9)) / (2 * a9)  # steady straight run
    _, ind = manoeuvres.turning_circle(spec, rudder_deg=25.0, speed_kn=8.0, dt=0.5,
                                       turns_deg=180.0)
    events = []
    for level in (90.0, 180.0):
        def ev(t, s, level=level):
            return s[2] - math.radians(level)
        events.append(ev)
    events[-1].terminal = True
    sol = solve_ivp(_response_rhs(spec, rpm / 60.0, math.radians(25.0)), (0.0, 5000.0),
                    [0.0, 0.0, 0.0, u0, 0.0, 0.0, 0.0], method="DOP853", rtol=1e-11,
                    atol=1e-10, events=events)
    (t90,), (t180,) = sol.t_events
    (y90,), (y180,) = sol.y_events
    assert ind["time_to_90_s"] == pytest.approx(t90, rel=1e-4)
    assert ind["time_to_180_s"] == pytest.approx(t180, rel=1e-4)
    assert ind["advance_m"] == pytest.approx(y90[0], rel=1e-4)
    assert ind["transfer_m"] == pytest.approx(y90[1], rel=1e-4)
    assert ind["tactical_diameter_m"] == pytest.approx(y180[1], rel=1e-4)
    # the run stops on the first step at or beyond 180 deg: ground speed then over approach
    assert ind["speed_loss_ratio"] == pytest.approx(math.hypot(y180[3], y180[4]) / u0,
                                                    rel=1e-3)
    assert ind["approach_speed_kn"] == pytest.approx(8.0, rel=1e-9)


def test_zigzag_to_port_first_is_the_mirror_image_of_starboard_first():
    """A symmetric ship (Nomoto container): the port-first 20/20 zig-zag gives the same
    indices (measured to port) and the east coordinates of its track are negated."""
    spec = load_ship("container")
    tr_s, stbd = manoeuvres.zigzag(spec, rudder_deg=20.0, dt=0.5)
    tr_p, port = manoeuvres.zigzag(spec, rudder_deg=-20.0, heading_deg=-20.0, dt=0.5)
    for key in ("initial_turning_time_s", "initial_turning_distance_L", "first_overshoot_deg",
                "second_overshoot_deg"):
        assert port[key] == pytest.approx(stbd[key], rel=1e-9), key
    assert port["rudder_deg"] == -20.0 and port["heading_deg"] == 20.0
    np.testing.assert_allclose(tr_p["east_m"], -tr_s["east_m"], atol=1e-6)
    np.testing.assert_allclose(tr_p["rudder_deg"], -tr_s["rudder_deg"], atol=1e-9)
    # both sides meet the same IMO 20/20 criterion
    crit_p = manoeuvres.imo_criteria("zigzag", port)["first_overshoot_deg"]
    crit_s = manoeuvres.imo_criteria("zigzag", stbd)["first_overshoot_deg"]
    assert (crit_p["limit"], crit_p["pass"]) == (crit_s["limit"], crit_s["pass"]) == (25.0, True)


def test_zigzag_overshoots_read_independently_from_the_track():
    """Overshoots recomputed from the heading and rudder columns alone: the rudder's sign
    changes mark the reversals; the first overshoot is the heading's maximum between the first
    two, the second the depth of its minimum between the second and third, beyond 10 deg."""
    spec = load_ship("fishing")
    track, ind = manoeuvres.zigzag(spec, rudder_deg=10.0, dt=0.25)
    head = np.degrees(np.unwrap(np.radians(track["heading_deg"])))
    head -= head[0]
    rud = track["rudder_deg"]
    flips = np.flatnonzero(np.diff(np.sign(rud - 0.0)[1:]) != 0) + 1  # rudder moves next step
    # the command reverses one step before the actual rudder changes sign
    rev = [np.flatnonzero(head >= 10.0)[0]]
    rev.append(rev[0] + np.flatnonzero(head[rev[0]:] <= -10.0)[0])
    rev.append(rev[1] + np.flatnonzero(head[rev[1]:] >= 10.0)[0])
    assert flips.size >= 3
    assert ind["first_overshoot_deg"] == pytest.approx(head[rev[0]:rev[1] + 1].max() - 10.0,
                                                       abs=1e-9)
    assert ind["second_overshoot_deg"] == pytest.approx(-head[rev[1]:rev[2] + 1].min() - 10.0,
                                                        abs=1e-9)
    t = track["t_s"]
    i = rev[0]
    t_init = t[i - 1] + (10.0 - head[i - 1]) / (head[i] - head[i - 1]) * (t[i] - t[i - 1])
    assert ind["initial_turning_time_s"] == pytest.approx(t_init, rel=1e-12)


@pytest.mark.parametrize("kwargs, key", [
    ({"speed_kn": 0.0}, "speed_kn"), ({"speed_kn": -3.0}, "speed_kn"),
    ({"rudder_deg": 0.0}, "rudder_deg"), ({"heading_deg": 0.0}, "heading_deg"),
    ({"heading_deg": float("nan")}, "heading_deg"),
])
def test_zigzag_rejects_zero_angles_and_speeds(kwargs, key):
    """A zig-zag needs a rudder angle and a heading limit other than 0 and an approach speed
    above 0: ``InputError`` naming the argument."""
    with pytest.raises(InputError) as info:
        manoeuvres.zigzag(load_ship("cargo"), **kwargs)
    assert info.value.key == key


def test_crash_stop_refuses_a_response_ship_and_an_engine_without_astern():
    """The response family has no astern thrust; a Nomoto ship whose rps_min is 0 cannot go
    astern either: both ``InputError`` saying so."""
    with pytest.raises(InputError, match="cannot go astern"):
        manoeuvres.crash_stop(load_ship("bulk_carrier"))
    spec = _nomoto()
    spec["actuators"]["rps_min"] = 0.0
    with pytest.raises(InputError, match="cannot go astern"):
        manoeuvres.crash_stop(spec)


def test_crash_stop_from_a_lower_speed_matches_the_closed_form():
    """From 6 kn (not the service speed) the stop follows the same quadratic surge closed form
    with u0 in place of U_s: ``t = 2 U_s T_u atan(u0/u_a) / u_a``,
    reach ``U_s T_u ln(1 + u0^2/u_a^2)``."""
    spec = _nomoto(engine_tau_s=0.05, max_dt_s=0.02)
    track, ind = manoeuvres.crash_stop(spec, speed_kn=6.0)
    c = spec["coefficients"]
    us, tu, u0 = from_kn(10.0), c["surge_tau_s"], from_kn(6.0)
    ua = us * -spec["actuators"]["rps_min"] / c["rps_service"]
    t_stop = 2 * us * tu * math.atan(u0 / ua) / ua
    reach = us * tu * math.log(1 + (u0 / ua) ** 2)
    dt = track["t_s"][1] - track["t_s"][0]
    assert t_stop <= ind["time_to_stop_s"] <= t_stop + dt + 0.1
    assert ind["head_reach_m"] == pytest.approx(reach, rel=2e-3)
    assert ind["approach_speed_kn"] == pytest.approx(6.0, rel=1e-9)
