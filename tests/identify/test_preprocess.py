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
