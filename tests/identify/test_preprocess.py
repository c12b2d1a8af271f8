"""Pre-processing of trial runs for identification [seed 001, section 4.1]."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.errors import DataError
from trafficsim.identify import preprocess
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import load_ship


@pytest.fixture(scope="module")
def zigzag() -> dict[str, np.ndarray]:
    track, _ = manoeuvres.zigzag(load_ship("cargo"), 20.0, dt=1.0)
    return track


def test_noise_estimate_from_third_differences(zigzag: dict[str, np.ndarray]) -> None:
    """White noise of 1.5 m on a turning ship's track (1 s samples) is recovered within 10 %;
    the smooth track alone reads as almost noise-free."""
    rng = np.random.default_rng(4)
    noisy = zigzag["north_m"] + rng.normal(0.0, 1.5, zigzag["north_m"].size)
    assert preprocess.noise_from_data(noisy, 1e-3) == pytest.approx(1.5, rel=0.1)
    assert preprocess.noise_from_data(zigzag["north_m"], 1e-3) < 0.01


def test_repeated_samples_become_missing() -> None:
    t = np.arange(8.0)
    north = np.array([0.0, 1.0, 1.0, 1.0, 4.0, 5.0, 6.0, 7.0])
    east = np.array([0.0, 0.0, 0.0, 3.0, 4.0, 4.0, 4.0, 4.0])
    trial = from_arrays("r", {"t_s": t, "north_m": north, "east_m": east,
                              "heading_deg": [0, 1, 2, 2, 4, 5, 6, 7], "rudder_deg": t * 0,
                              "rpm": t * 0 + 60})
    out, counts = preprocess.mask_repeats(trial)
    # position repeats only where north AND east repeat (samples 2); heading at sample 3
    assert counts == {"position": 1, "heading": 1}
    assert np.isnan(out.north_m[2]) and np.isnan(out.east_m[2]) and np.isfinite(out.north_m[3])
    assert np.isnan(out.psi_rad[3]) and out.missing["psi_rad"] == 1


def test_resampling_irregular_times() -> None:
    t = np.array([0.0, 1.0, 2.1, 2.9, 4.0, 5.0, 9.0, 10.0])
    heading = np.mod(350.0 + 5.0 * t, 360.0)
    trial = from_arrays("i", {"t_s": t, "north_m": 2.0 * t, "east_m": -t,
                              "heading_deg": heading, "rudder_deg": t * 0, "rpm": t * 0 + 60})
    out = preprocess.resample_uniform(trial, 1.0)
    np.testing.assert_allclose(out.t_s, np.arange(11.0))
    ok = np.isfinite(out.north_m)
    np.testing.assert_allclose(out.north_m[ok], 2.0 * out.t_s[ok])
    # heading interpolated across north (350 -> 10 deg), not through 180
    np.testing.assert_allclose(np.degrees(np.unwrap(out.psi_rad[ok])), 350.0 + 5.0 * out.t_s[ok])
    assert np.isnan(out.north_m[7]) and ok[5] and ok[9]  # 6..8 s lies in a 4 s gap


def test_resampling_keeps_the_extra_columns() -> None:
    """Columns the reader keeps under their own names (a trial.csv's receiver and filter
    columns) are resampled with the rest, angles in radians unwrapped across north, instead
    of being dropped."""
    t = np.array([0.0, 1.0, 2.1, 2.9, 4.0, 5.0])
    trial = from_arrays("e", {"t_s": t, "north_m": 2.0 * t, "east_m": -t,
                              "heading_deg": t * 0, "rudder_deg": t * 0, "rpm": t * 0 + 60,
                              "gnss_fix_north_m": 3.0 * t,
                              "beam_bearing_rad": np.mod(6.2 + 0.05 * t, 2 * np.pi)})
    assert set(trial.extra) == {"gnss_fix_north_m", "beam_bearing_rad"}
    out = preprocess.resample_uniform(trial, 1.0)
    np.testing.assert_allclose(out.extra["gnss_fix_north_m"], 3.0 * np.arange(6.0))
    np.testing.assert_allclose(np.unwrap(out.extra["beam_bearing_rad"]),
                               6.2 + 0.05 * np.arange(6.0))


def test_batched_smoothing_equals_one_run_at_a_time(zigzag: dict[str, np.ndarray]) -> None:
    """Runs of different lengths smoothed in one padded call give exactly what each gives alone."""
    rng = np.random.default_rng(2)
    tr = {k: v.copy() for k, v in zigzag.items()}
    tr["north_m"] += rng.normal(0.0, 1.0, tr["t_s"].size)
    long = from_arrays("long", tr)
    short = long.take(slice(0, 300))
    settings = preprocess.SmootherSettings(sigma_pos_m=1.0, sigma_heading_rad=0.003)
    both = preprocess.smooth_runs([long, short], 160.0, 7.7, settings)
    alone = [preprocess.smooth_runs([r], 160.0, 7.7, settings)[0] for r in (long, short)]
    for a, b in zip(both, alone, strict=True):
        for key in ("u_mps", "v_mps", "r_radps", "sigma_u_mps", "psi_rad"):
            np.testing.assert_allclose(a.smooth[key], b.smooth[key], rtol=1e-9, atol=1e-12)
    # and the smoothed motion is the truth to within the noise
    k = both[0]
    assert np.sqrt(np.mean((k.smooth["u_mps"] - tr["u_mps"]) ** 2)) < 0.1
    assert np.sqrt(np.mean((k.smooth["r_radps"] - np.radians(tr["r_degps"])) ** 2)) < 3e-4


def test_leading_gaps_are_trimmed_and_hopeless_runs_refused() -> None:
    t = np.arange(10.0)
    north = t.copy()
    north[:3] = np.nan
    trial = from_arrays("g", {"t_s": t, "north_m": north, "east_m": t * 0,
                              "heading_deg": t * 0 + 10, "rudder_deg": t * 0, "rpm": t * 0})
    assert preprocess.first_usable(trial) == 3
    (k,) = preprocess.smooth_runs([trial], 100.0, 5.0)
    assert k.t_s[0] == 3.0 and k.trial.n == 7
    hopeless = trial.with_series(north_m=np.where(t % 2 == 0, np.nan, t))
    with pytest.raises(DataError, match="no two consecutive samples"):
        preprocess.smooth_runs([hopeless], 100.0, 5.0)


def test_a_long_constant_value_is_a_signal_not_a_stale_receiver() -> None:
    t = np.arange(30.0)
    heading = np.where(t < 20, 45.0, 45.0 + (t - 20))  # 20 s steady, then turning
    trial = from_arrays("c", {"t_s": t, "north_m": t, "east_m": t, "heading_deg": heading,
                              "rudder_deg": t * 0, "rpm": t * 0 + 60})
    out, counts = preprocess.mask_repeats(trial)
    assert counts["heading"] == 0 and np.all(np.isfinite(out.psi_rad))


def _trial(t, **cols):
    t = np.asarray(t, float)
    base = {"t_s": t, "north_m": t * 0, "east_m": t * 0, "heading_deg": t * 0,
            "rudder_deg": t * 0, "rpm": t * 0 + 60}
    base.update(cols)
    return from_arrays("x", base)


def test_uniform_sampling_is_left_alone() -> None:
    """Already uniform to 1 %: the very same run comes back (no resampling, no copy)."""
    t = np.arange(10.0) + np.array([0, 0.005, 0, -0.005, 0, 0, 0.009, 0, 0, 0])
    trial = _trial(t, north_m=t)
    assert preprocess.resample_uniform(trial) is trial
    jittery = _trial(t + np.r_[0, 0.02, np.zeros(8)], north_m=t)
    assert preprocess.resample_uniform(jittery) is not jittery


def test_resampling_grid_values_and_gaps() -> None:
    """Grid from the first time at the given step up to the last (floor); values linear in t;
    a grid point exactly one step from a sample is kept, farther is NaN; a series with fewer
    than two finite samples is all NaN; wind direction unwrapped across north."""
    t = np.array([0.0, 1.0, 2.0, 3.0, 7.0, 8.0, 9.5])
    wind_from = np.array([350.0, 355.0, 0.0, 5.0, 25.0, 30.0, 37.5])
    sog = np.full(t.size, np.nan)
    sog[2] = 4.0
    trial = _trial(t, north_m=3.0 * t, east_m=-t, wind_speed_mps=t * 0 + 5,
                   wind_from_deg=wind_from, sog_kn=sog)
    out = preprocess.resample_uniform(trial, 1.0)
    np.testing.assert_array_equal(out.t_s, np.arange(10.0))   # floor(9.5 / 1) + 1 points
    ok = np.isfinite(out.north_m)
    # 4 (1 s from 3) and 6 (1 s from 7) kept; 5 is 2 s from both: NaN
    np.testing.assert_array_equal(ok, [True] * 5 + [False] + [True] * 4)
    np.testing.assert_allclose(out.north_m[ok], 3.0 * out.t_s[ok])
    np.testing.assert_allclose(out.east_m[ok], -out.t_s[ok])
    wf = np.degrees(out.wind_from_rad)
    np.testing.assert_allclose(wf[:4], [350.0, 355.0, 360.0, 365.0])  # not through 180
    assert out.missing["north_m"] == 1 and out.extra == {}
    assert np.all(np.isnan(out.sog_mps)) and out.missing["sog_mps"] == 10


def test_repeats_up_to_five_seconds_are_stale_longer_ones_are_signal() -> None:
    """At 1 s: a value repeated 5 times (5 s) is a receiver that did not update; 6 times is a
    constant signal. Equality is exact; position needs north AND east to repeat."""
    five = np.r_[0.0, 1.0, [2.0] * 6, 3.0, 4.0]          # 2.0 then 5 repeats
    six = np.r_[0.0, 1.0, [2.0] * 7, 3.0, 4.0]           # 6 repeats
    for heading, masked in ((five, 5), (six, 0)):
        t = np.arange(heading.size, dtype=float)
        out, counts = preprocess.mask_repeats(_trial(t, heading_deg=heading, north_m=t))
        assert counts == {"position": 0, "heading": masked}
        assert int(np.isnan(out.psi_rad).sum()) == masked
    # 0.5 s sampling: 10 repeats are 5 s, still stale
    ten = np.r_[0.0, [1.0] * 11, 2.0]
    t = 0.5 * np.arange(ten.size)
    _, counts = preprocess.mask_repeats(_trial(t, heading_deg=ten, north_m=t))
    assert counts["heading"] == 10
    # a longer limit masks the long run too
    t = np.arange(six.size, dtype=float)
    _, counts = preprocess.mask_repeats(_trial(t, heading_deg=six, north_m=t), max_stale_s=6.0)
    assert counts["heading"] == 6


def test_first_usable_sample() -> None:
    t = np.arange(6.0)
    psi = np.array([0.0, np.nan, 1.0, 2.0, 3.0, 4.0])
    north = np.array([np.nan, 1.0, 2.0, np.nan, 4.0, 5.0])
    # finite position and heading at 2, 4, 5: twice in a row first at 4
    assert preprocess.first_usable(_trial(t, heading_deg=psi, north_m=north)) == 4
    assert preprocess.first_usable(_trial(t, north_m=t)) == 0
    trial = _trial(t, heading_deg=t * np.nan)
    trial = trial.__class__(**{**trial.__dict__, "path": "runs/r7.csv"})
    with pytest.raises(DataError, match=r"^runs/r7.csv: no two consecutive samples"):
        preprocess.first_usable(trial)


def test_noise_estimate_ignores_polynomials_and_scales() -> None:
    """Third differences annihilate quadratics: adding one changes nothing (to rounding);
    the estimate scales with the noise; under ten third differences it is the floor."""
    rng = np.random.default_rng(7)
    e = rng.normal(0.0, 0.5, 400)
    t = np.arange(400.0)
    base_ = preprocess.noise_from_data(e, 1e-3)
    assert preprocess.noise_from_data(e + 3.0 + 2.0 * t - 0.01 * t * t, 1e-3) == pytest.approx(
        base_, rel=1e-6)
    assert preprocess.noise_from_data(4.0 * e, 1e-3) == pytest.approx(4.0 * base_)
    assert base_ == pytest.approx(0.5, rel=0.15)
    assert preprocess.noise_from_data(np.arange(12.0), 0.25) == 0.25       # no noise: floor
    assert preprocess.noise_from_data(e[:12], 1e-3) == 1e-3                # 9 differences
    gappy = e.copy()
    gappy[::7] = np.nan
    assert np.isfinite(preprocess.noise_from_data(gappy, 1e-3))


@pytest.mark.parametrize("length, speed, expect", [
    # the module doc's two examples: 225 m at 13 kn and the 3 m model at 0.4 m/s
    (225.0, 13 * 1852 / 3600, (0.0497, 0.0497 / 225, 0.0297)),
    (3.0, 0.4, (0.16 / 12, 0.16 / 36, 0.4 / 3)),
])
def test_automatic_process_noise(length, speed, expect) -> None:
    trial = _trial(np.arange(20.0), north_m=np.arange(20.0))
    s = preprocess.resolve_settings([trial], length, speed, preprocess.SmootherSettings())
    assert s["sigma_acc_mps2"] == pytest.approx(expect[0], rel=2e-3)
    assert s["sigma_yaw_acc_radps2"] == pytest.approx(expect[1], rel=2e-3)
    assert s["alpha_per_s"] == pytest.approx(expect[2], rel=2e-3)
    # noise-free straight track: the floors
    assert s["sigma_pos_m"] == preprocess.MIN_SIGMA_POS_M
    assert s["sigma_heading_rad"] == pytest.approx(preprocess.MIN_SIGMA_HEADING_RAD)
    assert s["mask_repeats"] is True


def test_given_settings_are_kept_and_a_zero_speed_is_floored() -> None:
    trial = _trial(np.arange(20.0))
    given = preprocess.SmootherSettings(sigma_pos_m=2.0, sigma_heading_rad=0.01,
                                        sigma_acc_mps2=0.3, sigma_yaw_acc_radps2=0.002,
                                        alpha_per_s=0.5, mask_repeats=False)
    s = preprocess.resolve_settings([trial], 100.0, 5.0, given)
    assert s == {"sigma_pos_m": 2.0, "sigma_heading_rad": 0.01, "sigma_acc_mps2": 0.3,
                 "sigma_yaw_acc_radps2": 0.002, "alpha_per_s": 0.5, "mask_repeats": False}
    still = preprocess.resolve_settings([trial], 100.0, 0.0, preprocess.SmootherSettings())
    assert still["alpha_per_s"] == pytest.approx(1e-3 / 100.0)


def test_position_noise_is_the_median_over_runs_and_axes() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(300.0)
    runs = [_trial(t, north_m=rng.normal(0, s1, t.size), east_m=rng.normal(0, s2, t.size))
            for s1, s2 in ((1.0, 1.0), (1.0, 8.0))]
    s = preprocess.resolve_settings(runs, 100.0, 5.0, preprocess.SmootherSettings())
    # three axes at sigma 1, one at 8: the median is ~1, the mean would be ~2.75
    assert s["sigma_pos_m"] == pytest.approx(1.0, rel=0.2)


def test_straight_crabbing_run_gives_body_velocities() -> None:
    """Noise-free straight track at 5 m/s on course 40 deg with heading 30 deg, heading written
    in [0, 360): u = 5 cos 10 deg, v = +5 sin 10 deg (moving to starboard of the heading),
    r = 0; and a steady turn through north (350 -> 10 deg) keeps a constant yaw rate."""
    t = np.arange(0.0, 120.0, 1.0)
    chi = np.radians(40.0)
    trial = _trial(t, north_m=5 * np.cos(chi) * t, east_m=5 * np.sin(chi) * t,
                   heading_deg=t * 0 + 30.0)
    (k,) = preprocess.smooth_runs([trial], 100.0, 5.0)
    mid = slice(10, -10)
    np.testing.assert_allclose(k.smooth["u_mps"][mid], 5 * np.cos(np.radians(10)), atol=1e-3)
    np.testing.assert_allclose(k.smooth["v_mps"][mid], 5 * np.sin(np.radians(10)), atol=1e-3)
    np.testing.assert_allclose(k.smooth["r_radps"][mid], 0.0, atol=1e-5)
    heading = np.mod(350.0 + 0.5 * t, 360.0)
    turn = _trial(t, north_m=5 * t, heading_deg=heading)
    (k2,) = preprocess.smooth_runs([turn], 100.0, 5.0)
    np.testing.assert_allclose(k2.smooth["r_radps"][mid], np.radians(0.5), rtol=1e-3)


def test_decimation_to_a_working_interval() -> None:
    """0.5 s data worked at 2 s keeps every 4th sample (after masking repeats); runs of
    different sampling are smoothed in their own groups; Kinematics.decimate thins both."""
    t = np.arange(0.0, 60.0, 0.5)
    fast = _trial(t, north_m=4 * t)
    slow = _trial(np.arange(0.0, 60.0, 3.0), north_m=4 * np.arange(0.0, 60.0, 3.0))
    k_fast, k_slow = preprocess.smooth_runs([fast, slow], 100.0, 4.0, dt_s=2.0)
    np.testing.assert_array_equal(k_fast.t_s, np.arange(0.0, 60.0, 2.0))
    assert k_fast.dt_s == 2.0 and k_slow.dt_s == 3.0 and k_slow.trial.n == 20
    for k in (k_fast, k_slow):
        assert all(v.shape == (k.trial.n,) for v in k.smooth.values())
        np.testing.assert_allclose(k.smooth["u_mps"][3:-3], 4.0, atol=1e-3)
    half = k_fast.decimate(3)
    np.testing.assert_array_equal(half.t_s, k_fast.t_s[::3])
    np.testing.assert_array_equal(half.smooth["u_mps"], k_fast.smooth["u_mps"][::3])
    assert k_fast.decimate(1) is k_fast


def test_repeat_masking_can_be_switched_off_and_is_reported() -> None:
    t = np.arange(40.0)
    north = 4 * t
    north[10:12] = north[9]
    east = t * 0.0
    trial = _trial(t, north_m=north, east_m=east, heading_deg=0.1 * t)
    (on,) = preprocess.smooth_runs([trial], 100.0, 4.0)
    (off,) = preprocess.smooth_runs([trial], 100.0, 4.0,
                                    preprocess.SmootherSettings(mask_repeats=False))
    assert on.repeats_masked == {"position": 2, "heading": 0}
    assert off.repeats_masked == {"position": 0, "heading": 0}
    assert np.isnan(on.trial.north_m[10]) and off.trial.north_m[10] == north[9]
    rep = on.report()
    assert rep["repeats_masked"] == on.repeats_masked and rep["samples"] == 40
    assert rep["nan_counts"] == {"north_m": 2, "east_m": 2}
    assert set(rep["median_sigma"]) == {"sigma_u_mps", "sigma_v_mps", "sigma_r_radps"}


def test_too_short_runs_are_refused() -> None:
    t = np.arange(5.0)
    north = np.array([np.nan, np.nan, 2.0, 3.0, 4.0])
    with pytest.raises(DataError, match="fewer than 4 usable samples"):
        preprocess.smooth_runs([_trial(t, north_m=north, heading_deg=t)], 100.0, 4.0)
    (k,) = preprocess.smooth_runs([_trial(t[:4], north_m=t[:4], heading_deg=t[:4])], 100.0,
                                  4.0)
    assert k.trial.n == 4


def _textbook_rts(z: np.ndarray, dt: float, sigma_r: float, sigma_a: float, alpha: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """One series, plain loops: CA Kalman filter started from two samples, NaN skipped, then
    the RTS smoother with explicit inverses; sample 0 by the backward model prediction."""
    phi = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    q = 2 * alpha * sigma_a**2 * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6],
                                           [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                                           [dt**3 / 6, dt**2 / 2, dt]])
    n, r = z.size, sigma_r**2
    xf, pf = np.zeros((n, 3)), np.zeros((n, 3, 3))
    xp, pp = np.zeros((n, 3)), np.zeros((n, 3, 3))
    xf[1] = [z[1], (z[1] - z[0]) / dt, 0.0]
    pf[1] = [[r, r / dt, 0.0], [r / dt, 2 * r / dt**2, 0.0], [0.0, 0.0, 0.0]]
    h = np.array([1.0, 0.0, 0.0])
    for k in range(2, n):
        xp[k] = phi @ xf[k - 1]
        pp[k] = phi @ pf[k - 1] @ phi.T + q
        if np.isfinite(z[k]):
            gain = pp[k] @ h / (h @ pp[k] @ h + r)
            xf[k] = xp[k] + gain * (z[k] - xp[k, 0])
            pf[k] = (np.eye(3) - np.outer(gain, h)) @ pp[k]
        else:
            xf[k], pf[k] = xp[k], pp[k]
    xs, ps = xf.copy(), pf.copy()
    for k in range(n - 2, 0, -1):
        a = pf[k] @ phi.T @ np.linalg.inv(pp[k + 1])
        xs[k] = xf[k] + a @ (xs[k + 1] - xp[k + 1])
        ps[k] = pf[k] + a @ (ps[k + 1] - pp[k + 1]) @ a.T
    back = np.linalg.inv(phi)
    xs[0] = back @ xs[1]
    ps[0] = back @ (ps[1] + q) @ back.T
    return xs, ps


def test_smoother_equals_a_textbook_rts_smoother_with_gaps() -> None:
    """A turning track with white noise of known size (1.5 m, 0.3 deg) and a masked gap: the
    smoothed position, heading, u, v, r and sigma_r are those of a loop-by-loop CA filter and
    RTS smoother run on each axis, with u, v the ground velocity turned into the body frame;
    and the smoothed track is closer to the truth than the measurements."""
    rng = np.random.default_rng(11)
    dt, n = 2.0, 90
    t = dt * np.arange(n)
    r_true = np.radians(0.4)
    psi_true = np.radians(20.0) + r_true * t
    speed, radius = 6.0, 6.0 / r_true
    north_true = radius * (np.sin(psi_true) - np.sin(psi_true[0]))
    east_true = radius * (np.cos(psi_true[0]) - np.cos(psi_true))
    north = north_true + rng.normal(0.0, 1.5, n)
    east = east_true + rng.normal(0.0, 1.5, n)
    heading = np.degrees(psi_true) + rng.normal(0.0, 0.3, n)
    north[40:44] = np.nan
    heading[60:62] = np.nan
    trial = _trial(t, north_m=north, east_m=east, heading_deg=np.mod(heading, 360.0))
    s = dict(sigma_pos_m=1.5, sigma_heading_rad=np.radians(0.3), sigma_acc_mps2=0.05,
             sigma_yaw_acc_radps2=5e-4, alpha_per_s=0.04)
    (k,) = preprocess.smooth_runs([trial], 100.0, speed,
                                  preprocess.SmootherSettings(mask_repeats=False, **s))
    xn, _ = _textbook_rts(north, dt, s["sigma_pos_m"], s["sigma_acc_mps2"], s["alpha_per_s"])
    xe, _ = _textbook_rts(east, dt, s["sigma_pos_m"], s["sigma_acc_mps2"], s["alpha_per_s"])
    xh, ph = _textbook_rts(np.radians(heading), dt, s["sigma_heading_rad"],
                           s["sigma_yaw_acc_radps2"], s["alpha_per_s"])
    sm = k.smooth
    np.testing.assert_allclose(sm["north_m"], xn[:, 0], rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(sm["east_m"], xe[:, 0], rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(sm["psi_rad"], xh[:, 0], rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(sm["r_radps"], xh[:, 1], rtol=1e-7, atol=1e-11)
    np.testing.assert_allclose(sm["sigma_r_radps"], np.sqrt(ph[:, 1, 1]), rtol=1e-7)
    c, si = np.cos(xh[:, 0]), np.sin(xh[:, 0])
    np.testing.assert_allclose(sm["u_mps"], xn[:, 1] * c + xe[:, 1] * si, atol=1e-8)
    np.testing.assert_allclose(sm["v_mps"], -xn[:, 1] * si + xe[:, 1] * c, atol=1e-8)
    inner = slice(5, -5)
    err_pos = np.hypot(sm["north_m"] - north_true, sm["east_m"] - east_true)[inner]
    assert np.sqrt(np.mean(err_pos**2)) < 0.6 * 1.5 * np.sqrt(2.0)
    assert np.sqrt(np.mean((sm["u_mps"][inner] - speed) ** 2)) < 0.15
    assert np.sqrt(np.mean((sm["r_radps"][inner] - r_true) ** 2)) < 0.1 * r_true


def test_resampling_a_series_with_a_gap_inside_irregular_times() -> None:
    """Irregular samples with a missing north at 3.1 s: the grid point at 3 s interpolates
    between the finite samples at 2.2 s and 4.0 s (0.8 s and 1 s away, within one interval),
    east is unaffected; a grid point more than one interval from the nearest finite north
    sample is NaN even when other series have data there."""
    t = np.array([0.0, 1.1, 2.2, 3.1, 4.0, 5.2, 6.0])
    north = 10.0 * t
    north[3] = np.nan
    east = -2.0 * t
    trial = _trial(t, north_m=north, east_m=east)
    out = preprocess.resample_uniform(trial, 1.0)
    np.testing.assert_array_equal(out.t_s, np.arange(7.0))
    np.testing.assert_allclose(out.north_m, 10.0 * out.t_s)
    np.testing.assert_allclose(out.east_m, -2.0 * out.t_s)
    north2 = north.copy()
    north2[2:5] = np.nan  # finite at 1.1 and 5.2 only: grid 3 is 1.9 s and 2.2 s away
    out2 = preprocess.resample_uniform(_trial(t, north_m=north2, east_m=east), 1.0)
    np.testing.assert_array_equal(np.isnan(out2.north_m),
                                  [False, False, False, True, True, False, False])
    assert np.all(np.isfinite(out2.east_m))


def test_repeats_straddling_a_missing_sample_are_not_masked() -> None:
    """A NaN between two equal headings is not a repeat (a comparison with NaN is False); only
    exact equality with the immediately previous sample counts."""
    t = np.arange(8.0)
    heading = np.array([0.0, 1.0, np.nan, 1.0, 2.0, 2.0 + 1e-9, 3.0, 4.0])
    out, counts = preprocess.mask_repeats(_trial(t, heading_deg=heading, north_m=t))
    assert counts == {"position": 0, "heading": 0}
    assert int(np.isnan(out.psi_rad).sum()) == 1


def test_repeats_are_masked_before_decimation() -> None:
    """0.5 s data worked at 1 s: a position repeated at sample 4 (equal to sample 3, which
    decimation drops) is masked, because masking comes first; after decimation sample 4 is
    sample 2 of the working run and differs from its new predecessor (sample 2 of the data),
    so masking afterwards would have missed it."""
    t = np.arange(0.0, 20.0, 0.5)
    north = 4.0 * t
    north[4] = north[3]
    trial = _trial(t, north_m=north, heading_deg=0.2 * t)
    (k,) = preprocess.smooth_runs([trial], 100.0, 4.0, dt_s=1.0)
    assert k.dt_s == 1.0 and k.repeats_masked == {"position": 1, "heading": 0}
    assert np.isnan(k.trial.north_m[2]) and np.isnan(k.trial.east_m[2])
    assert np.isfinite(k.smooth["north_m"][2])
    assert k.smooth["north_m"][2] == pytest.approx(8.0, abs=0.05)
