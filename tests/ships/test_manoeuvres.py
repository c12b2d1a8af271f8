"""Standard manoeuvres: the indices are read off the track correctly, and the IMO limits."""

import numpy as np
import pytest

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
