"""Validation of an identified model: index comparison, measured turning tests, prediction
errors and the standard manoeuvres with the IMO criteria."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from trafficsim.identify import replay, validation
from trafficsim.identify.preprocess import Kinematics
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import load_ship

NAN = float("nan")


def _truth_run(name: str, track: dict[str, np.ndarray]) -> Kinematics:
    """A simulated run whose 'smoothed' motion is the simulation's own truth."""
    trial = from_arrays(name, track)
    smooth = {"north_m": trial.north_m, "east_m": trial.east_m,
              "psi_rad": np.unwrap(trial.psi_rad), "u_mps": trial.u_mps,
              "v_mps": trial.v_mps, "r_radps": trial.r_radps}
    return Kinematics(trial, smooth, {}, {})


def _rudder_run(rudder_deg: np.ndarray, heading_deg: np.ndarray) -> Kinematics:
    """A run that only carries what ``turning_segment`` reads: rudder and smoothed heading."""
    t = np.arange(float(rudder_deg.size))
    trial = from_arrays("r", {"t_s": t, "north_m": t, "east_m": t * 0,
                              "heading_deg": heading_deg, "rudder_deg": rudder_deg,
                              "rpm": t * 0 + 60})
    return Kinematics(trial, {"psi_rad": np.radians(heading_deg)}, {}, {})


# --- compare_manoeuvres ---------------------------------------------------------------------

def test_compare_gives_percent_errors_of_the_reference() -> None:
    ref = {"turning_35_port": {"indices": {"advance_m": 400.0, "transfer_m": 200.0,
                                           "tactical_diameter_m": 0.0,
                                           "steady_diameter_m": NAN, "speed_loss_ratio": 0.5}},
           "zigzag_10_10": {"indices": {"first_overshoot_deg": -4.0, "second_overshoot_deg": 8.0,
                                        "initial_turning_time_s": 50.0}}}
    fit = {"turning_35_port": {"indices": {"advance_m": 410.0, "transfer_m": 190.0,
                                           "tactical_diameter_m": 5.0,
                                           "steady_diameter_m": 700.0, "speed_loss_ratio": 0.9}},
           "zigzag_10_10": {"indices": {"first_overshoot_deg": -5.0, "second_overshoot_deg": 8.0,
                                        "initial_turning_time_s": 45.0}},
           "zigzag_20_20": {"indices": {}}}  # not in the reference: not compared
    out = validation.compare_manoeuvres(fit, ref)
    assert set(out) == {"turning_35_port", "zigzag_10_10"}
    turn, zz = out["turning_35_port"], out["zigzag_10_10"]
    assert set(turn) == set(validation.TURN_KEYS) and set(zz) == set(validation.ZIGZAG_KEYS)
    assert turn["advance_m"] == {"reference": 400.0, "identified": 410.0, "error_pct": 2.5}
    assert turn["transfer_m"]["error_pct"] == pytest.approx(-5.0)
    assert math.isnan(turn["tactical_diameter_m"]["error_pct"])  # zero reference
    assert math.isnan(turn["steady_diameter_m"]["error_pct"])  # no reference value
    # relative to |reference|: a larger negative overshoot is a negative error
    assert zz["first_overshoot_deg"]["error_pct"] == pytest.approx(-25.0)
    assert zz["second_overshoot_deg"]["error_pct"] == 0.0
    assert zz["initial_turning_time_s"]["error_pct"] == pytest.approx(-10.0)


# --- turning_indices ------------------------------------------------------------------------

@pytest.mark.parametrize("side", [1.0, -1.0])
def test_turning_indices_of_an_exact_circle(side: float) -> None:
    """A circle of radius R entered at heading 30 deg: advance = transfer = R, tactical
    diameter 2R, times to 90 and 180 deg (pi/2)/r and pi/r; samples 0.7 deg apart."""
    R, r = 500.0, 0.01  # m, rad/s
    t = np.arange(0.0, 400.0, 1.22)
    psi0 = math.radians(30.0)
    theta = r * t
    along, across = R * np.sin(theta), side * R * (1.0 - np.cos(theta))
    north = 100.0 + along * math.cos(psi0) - across * math.sin(psi0)
    east = -50.0 + along * math.sin(psi0) + across * math.cos(psi0)
    got = validation.turning_indices(t, north, east, psi0 + side * theta)
    assert got["advance_m"] == pytest.approx(R, rel=1e-4)
    assert got["transfer_m"] == pytest.approx(R, rel=1e-4)
    assert got["tactical_diameter_m"] == pytest.approx(2 * R, rel=1e-4)
    assert got["time_to_90_s"] == pytest.approx(0.5 * math.pi / r, rel=1e-9)
    assert got["time_to_180_s"] == pytest.approx(math.pi / r, rel=1e-9)


def test_turning_indices_are_nan_for_changes_never_reached() -> None:
    t = np.arange(100.0)
    theta = np.radians(1.5) * t  # 148.5 deg at the end
    got = validation.turning_indices(t, np.sin(theta), 1 - np.cos(theta), theta)
    assert math.isfinite(got["advance_m"]) and math.isfinite(got["time_to_90_s"])
    assert math.isnan(got["tactical_diameter_m"]) and math.isnan(got["time_to_180_s"])


def test_turning_indices_match_the_turning_circle_manoeuvre() -> None:
    """On the turning-circle track itself (which starts at the execute point) the indices are
    the ones :func:`manoeuvres.turning_circle` reports."""
    track, ind = manoeuvres.turning_circle(load_ship("cargo"), -35.0, turns_deg=200.0)
    got = validation.turning_indices(track["t_s"], track["north_m"], track["east_m"],
                                     np.unwrap(np.radians(track["heading_deg"])))
    for key in ("advance_m", "transfer_m", "tactical_diameter_m", "time_to_90_s",
                "time_to_180_s"):
        assert got[key] == pytest.approx(ind[key], rel=1e-9), key


# --- turning_segment ------------------------------------------------------------------------

def test_turning_segment_is_the_longest_held_stretch() -> None:
    """Rudder 20 deg for 30 samples, back to 0, then 20 deg (+-0.4 deg jitter) for 200
    samples turning 200 deg: the second stretch, end exclusive."""
    rudder = np.zeros(300)
    rudder[10:40] = 20.0
    rudder[60:260] = 20.0 + 0.4 * np.sin(np.arange(200.0))
    heading = np.zeros(300)
    heading[60:260] = np.linspace(0.0, 200.0, 200)
    heading[260:] = 200.0
    assert validation.turning_segment(_rudder_run(rudder, heading)) == (60, 260)


def test_turning_segment_holds_the_most_common_large_angle() -> None:
    """25 deg for 50 samples, -15 deg for 150 samples turning 190 deg to port: the port turn
    (held angle found among samples of 10 deg or more), also when it runs to the end."""
    rudder = np.r_[np.zeros(5), np.full(50, 25.0), np.zeros(5), np.full(150, -15.0)]
    heading = np.r_[np.zeros(60), np.linspace(0.0, -190.0, 150)]
    assert validation.turning_segment(_rudder_run(rudder, heading)) == (60, 210)


@pytest.mark.parametrize("rudder, change", [(20.0, 170.0), (9.0, 360.0)])
def test_no_turning_segment_below_the_thresholds(rudder: float, change: float) -> None:
    """Too little heading change, or a rudder below 10 deg: not a turning test."""
    rud = np.r_[np.zeros(10), np.full(100, rudder)]
    heading = np.r_[np.zeros(10), np.linspace(0.0, change, 100)]
    assert validation.turning_segment(_rudder_run(rud, heading)) is None


# --- measured_turns -------------------------------------------------------------------------

def test_measured_turns_compare_each_model_with_the_measured_turn() -> None:
    """A simulated 20 deg port turn (steering gear lag included) and a 20/20 zig-zag of the
    cargo ship: only the turn counts, executed where the rudder reaches the held angle; the
    true model replays it to 0.05 %, a model with K' 1.5 times too large turns tighter."""
    spec = load_ship("cargo")
    turn, _ = manoeuvres.turning_circle(spec, -20.0, turns_deg=270.0)
    zz, _ = manoeuvres.zigzag(spec, 20.0)
    coeffs = spec["coefficients"]
    keen = dict(spec, coefficients={**coeffs, "K_prime": 1.5 * coeffs["K_prime"]})
    models = replay.model_rows([spec, keen])
    out = validation.measured_turns([_truth_run("zz", zz), _truth_run("turn", turn)], models,
                                    ("true", "keen"), use_wind=False)
    (entry,) = out
    i0 = int(np.argmax(np.abs(turn["rudder_deg"] + 20.0) <= 1.0))
    assert entry["run"] == "turn" and entry["execute_t_s"] == turn["t_s"][i0]
    assert entry["rudder_deg"] == pytest.approx(-20.0, abs=0.01)
    assert entry["rps"] == pytest.approx(turn["rpm"][i0] / 60.0)
    assert entry["approach_speed_mps"] == pytest.approx(
        math.hypot(turn["u_mps"][i0], turn["v_mps"][i0]))
    measured = validation.turning_indices(
        turn["t_s"][i0:], turn["north_m"][i0:], turn["east_m"][i0:],
        np.unwrap(np.radians(turn["heading_deg"]))[i0:])
    assert entry["measured"] == pytest.approx(measured, rel=1e-12)
    for key, m in measured.items():
        true, keen_e = entry["true"][key], entry["keen"][key]
        assert abs(true["error_pct"]) < 0.05, key
        assert keen_e["error_pct"] == pytest.approx(100.0 * (keen_e["value"] - m) / m)
        assert keen_e["error_pct"] < -5.0, key


# --- prediction_errors ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def bulk_windows() -> tuple[dict, replay.Windows, np.ndarray]:
    """Two zig-zags of the bulk carrier cut into 150 s windows, and the true model's replay."""
    spec = load_ship("bulk_carrier")
    runs = [_truth_run(f"zz{a:.0f}", manoeuvres.zigzag(spec, a)[0]) for a in (10.0, 20.0)]
    win = replay.windows_from_runs(runs, 150.0)
    sim, _ = replay.simulate(replay.model_rows([spec]), win)
    return spec, win, sim[0]


def test_prediction_errors_are_the_known_offsets(bulk_windows) -> None:
    """Targets = the true model's own replay plus known offsets per run (run 0: position 3 m
    north 4 m east, surge 0.1 m/s; run 1: sway -0.2 m/s, yaw rate 0.001 rad/s, heading
    0.02 rad, some heading samples missing); each window's first sample is garbage and must
    not count. The RMS errors are then the offsets, pooled by sample count over all runs."""
    spec, win, sim = bulk_windows
    target = sim.copy()
    run0, run1 = win.run == 0, win.run == 1
    target[run0, :, 0] += 3.0
    target[run0, :, 1] += 4.0
    target[run0, :, 3] += 0.1
    target[run1, :, 4] -= 0.2
    target[run1, :, 5] += 0.001
    target[run1, :, 2] += 0.02
    target[np.flatnonzero(run1)[0], 5:9, 2] = np.nan
    target[:, 0, :] += 1e3
    win = dataclasses.replace(win, target=target)
    bad = dict(spec, coefficients={**spec["coefficients"], "c2": 5.0, "b1": 3.0})
    out = validation.prediction_errors(replay.model_rows([spec, bad]), ("true", "bad"), win)
    e0, e1, both = out["true"]["zz10"], out["true"]["zz20"], out["true"]["all"]
    assert (e0["windows"], e1["windows"], both["windows"]) == (run0.sum(), run1.sum(), win.w)
    assert e0["u_rms_mps"] == pytest.approx(0.1, rel=1e-9)
    assert e0["end_position_rms_m"] == pytest.approx(5.0, rel=1e-9)
    assert e0["end_position_max_m"] == pytest.approx(5.0, rel=1e-9)
    assert e0["v_rms_mps"] == pytest.approx(0.0, abs=1e-9)
    assert e0["heading_rms_deg"] == pytest.approx(0.0, abs=1e-9)
    assert e1["v_rms_mps"] == pytest.approx(0.2, rel=1e-9)
    assert e1["r_rms_degps"] == pytest.approx(math.degrees(0.001), rel=1e-9)
    assert e1["heading_rms_deg"] == pytest.approx(math.degrees(0.02), rel=1e-9)
    assert e1["end_position_rms_m"] == pytest.approx(0.0, abs=1e-6)
    # pooled: samples after each window's first, per run
    n0 = int((win.n_samples[run0] - 1).sum())
    n1 = int((win.n_samples[run1] - 1).sum())
    assert both["u_rms_mps"] == pytest.approx(0.1 * math.sqrt(n0 / (n0 + n1)), rel=1e-9)
    assert both["end_position_rms_m"] == pytest.approx(
        5.0 * math.sqrt(run0.sum() / win.w), rel=1e-9)
    assert both["end_position_max_m"] == pytest.approx(5.0, rel=1e-9)
    assert both["diverged_windows"] == 0
    # the diverging candidate is flagged in every window, its errors stay finite
    assert out["bad"]["all"]["diverged_windows"] == win.w
    assert out["bad"]["zz20"]["diverged_windows"] == run1.sum()
    assert math.isfinite(out["bad"]["all"]["end_position_rms_m"])


def test_prediction_errors_skip_runs_without_windows(bulk_windows) -> None:
    spec, win, _ = bulk_windows
    only_second = win.subset(win.run == 1)
    out = validation.prediction_errors(replay.model_rows([spec]), ("m",), only_second)
    assert set(out["m"]) == {"zz20", "all"}
    assert out["m"]["all"] == out["m"]["zz20"]  # one run: "all" is that run
    assert out["m"]["all"]["windows"] == (win.run == 1).sum()


# --- standard_manoeuvres --------------------------------------------------------------------

def test_standard_manoeuvres_and_imo_criteria() -> None:
    """The cargo ship (symmetric Nomoto model) at 12 kn: port and starboard circles alike, the
    indices those of the manoeuvres themselves, and the IMO MSC.137(76) limits: advance 4.5 L,
    tactical diameter 5 L, 10/10 overshoots 5 + L/(2V) and 17.5 + 0.75 L/V deg clipped to
    10..20 and 25..40, 20/20 first overshoot 25 deg."""
    spec = load_ship("cargo")
    out = validation.standard_manoeuvres(spec, 12.0)
    assert set(out) == {"turning_35_starboard", "turning_35_port", "zigzag_10_10",
                        "zigzag_20_20"}
    stb, port = out["turning_35_starboard"], out["turning_35_port"]
    _, direct = manoeuvres.turning_circle(spec, 35.0, 12.0)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
        assert stb["indices"][key] == pytest.approx(direct[key], rel=1e-12)
        assert port["indices"][key] == pytest.approx(stb["indices"][key], rel=1e-9)
    assert stb["indices"]["approach_speed_kn"] == pytest.approx(12.0)
    L = spec["particulars"]["length_m"]
    imo = stb["imo"]
    assert imo["advance_L"]["value"] == pytest.approx(stb["indices"]["advance_m"] / L)
    assert imo["advance_L"]["limit"] == 4.5 and imo["tactical_diameter_L"]["limit"] == 5.0
    l_over_v = L / (12.0 * 1852.0 / 3600.0)
    zz10 = out["zigzag_10_10"]
    assert zz10["indices"]["rudder_deg"] == 10.0 and zz10["indices"]["heading_deg"] == 10.0
    assert zz10["imo"]["first_overshoot_deg"]["limit"] == pytest.approx(
        min(max(5.0 + 0.5 * l_over_v, 10.0), 20.0))
    assert zz10["imo"]["second_overshoot_deg"]["limit"] == pytest.approx(
        min(max(17.5 + 0.75 * l_over_v, 25.0), 40.0))
    zz20 = out["zigzag_20_20"]
    assert set(zz20["imo"]) == {"first_overshoot_deg"}
    assert zz20["imo"]["first_overshoot_deg"]["limit"] == 25.0
    for m in out.values():
        for c in m["imo"].values():
            assert c["pass"] == (c["value"] <= c["limit"])


# --- hand-worked trajectories ---------------------------------------------------------------

def test_turning_indices_of_a_circle_sampled_coarsely_interpolate_between_samples() -> None:
    """Circle of radius 300 m to starboard from heading 0, sampled every 7 deg of turn: at
    90 deg the along/across coordinates are interpolated linearly in heading change between
    the samples at 84 and 91 deg; the result equals that interpolation worked by hand."""
    R = 300.0
    theta = np.radians(np.arange(0.0, 200.0, 7.0))
    north, east = R * np.sin(theta), R * (1 - np.cos(theta))
    t = 10.0 * np.arange(theta.size)
    got = validation.turning_indices(t, north, east, theta)
    # 90 deg lies between 84 (index 12) and 91 (index 13): weight 6/7 of the way
    w = 6.0 / 7.0
    a84, a91 = np.radians(84.0), np.radians(91.0)
    assert got["advance_m"] == pytest.approx(R * ((1 - w) * np.sin(a84) + w * np.sin(a91)))
    assert got["transfer_m"] == pytest.approx(
        R * ((1 - w) * (1 - np.cos(a84)) + w * (1 - np.cos(a91))))
    assert got["time_to_90_s"] == pytest.approx(120.0 + w * 10.0)
    # 180 deg between 175 (index 25) and 182 (index 26): weight 5/7
    w2 = 5.0 / 7.0
    a175, a182 = np.radians(175.0), np.radians(182.0)
    assert got["tactical_diameter_m"] == pytest.approx(
        R * ((1 - w2) * (1 - np.cos(a175)) + w2 * (1 - np.cos(a182))))
    assert got["tactical_diameter_m"] == pytest.approx(2 * R, rel=2e-3)


def test_turning_indices_do_not_depend_on_position_heading_or_side() -> None:
    """The same circle translated, rotated by 250 deg (heading carried across north, so the
    unwrapped heading passes 360) and mirrored to port gives the same indices."""
    R, r = 420.0, 0.008
    t = np.arange(0.0, 450.0, 2.0)
    theta = r * t
    along, across = R * np.sin(theta), R * (1 - np.cos(theta))
    ref = validation.turning_indices(t, along, across, theta)
    for psi0, side in ((np.radians(250.0), 1.0), (np.radians(250.0), -1.0)):
        c, s = np.cos(psi0), np.sin(psi0)
        a, b = along, side * across
        got = validation.turning_indices(t, 1e4 + a * c - b * s, -3e3 + a * s + b * c,
                                         psi0 + side * theta)
        assert got == pytest.approx(ref, rel=1e-9)


def test_zigzag_overshoots_are_those_read_off_the_track() -> None:
    """20/20 zig-zag of the cargo ship from ``standard_manoeuvres``: the first overshoot is
    the largest heading change past +20 deg before the heading swings back below 0, the
    second the largest past -20 deg before it comes back above 0 (read off the track by
    zero crossings, not by the rudder reversals the manoeuvre code uses); the initial turning
    time is when the change first reaches 20 deg."""
    spec = load_ship("cargo")
    out = validation.standard_manoeuvres(spec, 12.0)
    track, _ = manoeuvres.zigzag(spec, 20.0, 20.0, 12.0)
    change = np.degrees(np.unwrap(np.radians(track["heading_deg"])))
    change -= change[0]
    t = track["t_s"]
    peak1 = int(np.argmax(change > 20.0))
    down = peak1 + int(np.argmax(change[peak1:] < 0.0))
    first = change[:down].max() - 20.0
    up = down + int(np.argmax(change[down:] > 0.0))
    second = -change[down:up].min() - 20.0
    ind = out["zigzag_20_20"]["indices"]
    assert ind["first_overshoot_deg"] == pytest.approx(first, abs=0.05)
    assert ind["second_overshoot_deg"] == pytest.approx(second, abs=0.05)
    i = int(np.argmax(change >= 20.0))
    t20 = np.interp(20.0, change[i - 1:i + 1], t[i - 1:i + 1])
    assert ind["initial_turning_time_s"] == pytest.approx(t20 - t[0], abs=0.5)
    assert first > 0.0 and second > 0.0


def test_compare_manoeuvres_of_a_ship_with_itself_is_zero_error() -> None:
    """The identified ship equal to the reference: every finite index has error 0 %, and the
    reference and identified values are the manoeuvres' own."""
    spec = load_ship("cargo")
    man = validation.standard_manoeuvres(spec, 12.0)
    cmp_ = validation.compare_manoeuvres(man, man)
    for name, rows in cmp_.items():
        for key, row in rows.items():
            assert row["reference"] == row["identified"] or math.isnan(row["reference"])
            if math.isfinite(row["reference"]) and row["reference"] != 0.0:
                assert row["error_pct"] == 0.0, (name, key)
            assert row["reference"] == pytest.approx(man[name]["indices"][key], nan_ok=True)


def test_prediction_errors_of_a_perfect_model_are_zero(bulk_windows) -> None:
    """Targets equal to the model's own replay: every RMS and end-of-window error is 0 and no
    window diverges."""
    spec, win, sim = bulk_windows
    win = dataclasses.replace(win, target=sim.copy())
    out = validation.prediction_errors(replay.model_rows([spec]), ("m",), win)
    for e in out["m"].values():
        for key in ("u_rms_mps", "v_rms_mps", "r_rms_degps", "heading_rms_deg",
                    "end_position_rms_m", "end_position_max_m"):
            assert e[key] == 0.0, key
        assert e["diverged_windows"] == 0


def test_prediction_end_error_uses_each_windows_own_last_sample(bulk_windows) -> None:
    """A short last window (fewer samples than the padding): its end error is read at its own
    last sample, not at the padded end (which is NaN)."""
    spec, win, sim = bulk_windows
    short, last = 3, 99
    n_samples = win.n_samples.copy()
    n_samples[short] = last + 1
    target = sim.copy()
    target[short, last + 1:] = np.nan
    target[short, last, 0] += 6.0
    target[short, last, 1] -= 8.0
    win = dataclasses.replace(win, target=target, n_samples=n_samples)
    sel = np.zeros(win.w, dtype=bool)
    sel[short] = True
    out = validation.prediction_errors(replay.model_rows([spec]), ("m",), win.subset(sel))
    e = out["m"]["all"]
    assert e["end_position_max_m"] == pytest.approx(10.0, rel=1e-9)
    assert e["u_rms_mps"] == 0.0
