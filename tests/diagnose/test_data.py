"""Measured runs as replay windows (trafficsim.diagnose.data): manoeuvre phases by hand, the
third-difference noise level in closed form, and the windows' measured channels, phases and
noise levels on small synthetic runs (built directly, no smoother)."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.diagnose.data import CHANNELS, PHASES, dataset, noise_sigma, phases
from trafficsim.identify.preprocess import Kinematics
from trafficsim.io.trialdata import TrialData

APPROACH, EXECUTE, STEADY, CHECKS, PULLOUT = range(5)


def _kin(name: str, n: int, dt: float = 1.0, *, north: np.ndarray | None = None,
         psi: np.ndarray | None = None, rudder_deg: np.ndarray | None = None,
         r_smooth: np.ndarray | None = None, **series: np.ndarray) -> Kinematics:
    """A run of ``n`` samples; unspecified series are simple ramps (smoothed = measured)."""
    t = np.arange(n) * dt
    north = 5.0 * t if north is None else north
    east = 0.5 * t
    psi = np.full(n, 0.2) if psi is None else psi
    rud = np.zeros(n) if rudder_deg is None else np.radians(rudder_deg)
    trial = TrialData(name, "", t, north, east, psi, rud, np.full(n, 1.5), **series)
    r = np.zeros(n) if r_smooth is None else r_smooth
    smooth = {"north_m": north, "east_m": east, "psi_rad": np.unwrap(psi),
              "u_mps": np.full(n, 5.0), "v_mps": np.zeros(n), "r_radps": r}
    return Kinematics(trial, smooth, {}, {})


def _with_third_differences(d3: np.ndarray) -> np.ndarray:
    """A series whose third differences are exactly ``d3``."""
    x = np.asarray(d3, float)
    for _ in range(3):
        x = np.concatenate(([0.0], np.cumsum(x)))
    return x


def _alternating(a: float, n: int) -> np.ndarray:
    """``n`` samples whose ``n - 3`` (even) third differences are ``+a, -a, ...``: median 0,
    median absolute deviation ``a``, so the noise level is ``1.4826 a / sqrt(20)``."""
    assert (n - 3) % 2 == 0
    return _with_third_differences(a * np.resize([1.0, -1.0], n - 3))


def _sigma_of_alternating(a: float) -> float:
    return 1.4826 * a / np.sqrt(20.0)


# --- phases -----------------------------------------------------------------------------------


def test_phases_of_a_hand_worked_manoeuvre() -> None:
    # max |r| = 2 -> yaw-rate threshold 0.2; np.gradient peaks at 1 -> acceleration threshold 0.1
    rudder = np.radians([0, 0, 10, 10, 10, 10, 10, -10, -10, 0, 0, 0])
    r = np.array([0, 0, 0, 1, 2, 2, 2, 1.5, 0.5, 0.5, 0.05, 0])
    expected = [APPROACH, APPROACH, EXECUTE, EXECUTE, EXECUTE, STEADY, STEADY, CHECKS, CHECKS,
                PULLOUT, APPROACH, APPROACH]
    assert phases(rudder, r, 1.0).tolist() == expected


def test_turning_before_the_first_rudder_command_is_approach_not_pullout() -> None:
    rudder = np.radians([0, 0, 0, 15, 15, 0, 0])
    r = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    ph = phases(rudder, r, 1.0)
    assert ph[:3].tolist() == [APPROACH] * 3
    assert ph[5:].tolist() == [PULLOUT] * 2


def test_rudder_below_two_degrees_counts_as_amidships() -> None:
    r = np.array([0.0, 0.0, 0.0, 0.0])
    small = phases(np.radians([0.0, 1.99, 1.99, 1.99]), r, 1.0)
    out = phases(np.radians([0.0, 2.01, 2.01, 2.01]), r, 1.0)
    assert small.tolist() == [APPROACH] * 4
    # rudder out, no yaw rate and no yaw acceleration: neither growing nor against -> steady
    assert out.tolist() == [APPROACH, STEADY, STEADY, STEADY]


def test_missing_rudder_samples_count_as_amidships() -> None:
    r = np.array([0.0, 0.0, 0.5, 1.0, 1.0, 1.0])
    rud = np.radians([0.0, 0.0, 10.0, 10.0, 0.0, 0.0])
    with_nan = rud.copy()
    with_nan[[0, 4]] = np.nan
    assert phases(with_nan, r, 1.0).tolist() == phases(rud, r, 1.0).tolist()


def test_phases_mirror_for_port_and_ignore_scale_of_yaw_rate_and_time_step() -> None:
    t = np.arange(0.0, 200.0, 2.0)
    rudder = np.radians(np.where(t < 30, 0.0, np.where(t < 120, 20.0, np.where(t < 160, -20.0,
                                                                                  0.0))))
    r = np.interp(t, [0, 30, 80, 120, 150, 200], [0, 0, 0.01, 0.01, -0.004, -0.001])
    ref = phases(rudder, r, 2.0)
    assert set(ref.tolist()) == set(range(5))  # every phase appears
    # the thresholds are relative to the run, so units of r and the step size do not matter
    assert phases(-rudder, -r, 2.0).tolist() == ref.tolist()
    assert phases(rudder, 57.3 * r, 2.0).tolist() == ref.tolist()
    assert phases(rudder, r, 0.5).tolist() == ref.tolist()


# --- noise_sigma ------------------------------------------------------------------------------


def test_noise_sigma_closed_form_from_third_differences() -> None:
    x = _alternating(0.3, 41)
    assert np.allclose(np.diff(x, 3), 0.3 * np.resize([1.0, -1.0], 38))
    assert noise_sigma(x) == pytest.approx(_sigma_of_alternating(0.3), rel=1e-12)


def test_noise_sigma_of_white_noise_on_a_quadratic_trend() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(20000) * 0.5
    x = 3.0 + 2.0 * t + 0.01 * t**2 + rng.normal(0.0, 0.4, t.size)
    assert noise_sigma(x) == pytest.approx(0.4, rel=0.03)
    # a pure quadratic has no third differences: only the 1e-9 floor remains
    assert noise_sigma(3.0 + 2.0 * t[:100] + 0.01 * t[:100] ** 2) == pytest.approx(1e-9, abs=1e-9)


def test_noise_sigma_of_an_angle_unwraps_first() -> None:
    rng = np.random.default_rng(1)
    heading = 0.05 * np.arange(2000) + rng.normal(0.0, 0.01, 2000)  # many turns
    wrapped = np.mod(heading, 2 * np.pi)
    assert noise_sigma(wrapped, angle=True) == pytest.approx(noise_sigma(heading), rel=1e-9)
    assert noise_sigma(heading) == pytest.approx(0.01, rel=0.1)


def test_noise_sigma_skips_missing_samples_and_needs_eight() -> None:
    x = _alternating(0.2, 41)
    gappy = np.concatenate((x, [np.nan] * 5, x + 100.0))
    assert noise_sigma(gappy) == pytest.approx(_sigma_of_alternating(0.2), rel=1e-12)
    seven = np.full(20, np.nan)
    seven[:7] = np.arange(7.0)
    assert np.isnan(noise_sigma(seven))


def test_noise_sigma_of_too_short_a_series_is_nan() -> None:
    x = np.random.default_rng(2).normal(0.0, 1.0, 10)
    assert np.isnan(noise_sigma(x))


# --- dataset ----------------------------------------------------------------------------------


def test_dataset_windows_carry_the_measured_channels_at_their_offsets() -> None:
    n = 24  # horizon 5 s at 1 s: windows of 6 samples from 0, 5, 10, 15 and a last one of 4
    # (3 s, at least half the horizon: kept; a last piece of 2 s would be dropped)
    north = np.arange(n) ** 1.5
    u = 5.0 + 0.1 * np.arange(n)
    ds = dataset([_kin("a", n, north=north, u_mps=u)], 5.0)
    assert ds.windows.w == 5 and ds.windows.n == 6
    assert ds.windows.n_samples.tolist() == [6, 6, 6, 6, 4]
    for i, start in enumerate((0, 5, 10, 15, 20)):
        c = ds.windows.n_samples[i]
        assert np.array_equal(ds.target[i, :c, CHANNELS.index("north")],
                              north[start:start + c])
        assert np.array_equal(ds.target[i, :c, CHANNELS.index("u")], u[start:start + c])
    # padding: no target and phase -1
    assert np.isnan(ds.target[4, 4:]).all() and (ds.phase[4, 4:] == -1).all()
    assert (ds.phase[:4] >= 0).all() and (ds.phase[4, :4] >= 0).all()
    assert dataset([_kin("b", 23, north=north[:23], u_mps=u[:23])], 5.0).windows.w == 4


def test_dataset_channels_present_and_absent() -> None:
    n = 21
    ds = dataset([_kin("a", n, u_mps=np.full(n, 5.0))], 5.0)
    assert ds.channels == ("north", "east", "psi", "u")
    for name in ("v", "r", "sog", "cog_psi"):
        j = CHANNELS.index(name)
        assert np.isnan(ds.target[..., j]).all() and np.isnan(ds.sigma[j])


def test_dataset_heading_is_unwrapped_and_drift_angle_wrapped() -> None:
    n = 21
    heading = 0.4 * np.arange(n)  # passes 2 pi twice
    psi = np.mod(heading, 2 * np.pi)
    cog = np.mod(heading + np.where(np.arange(n) % 2, 0.3, -0.3), 2 * np.pi)
    ds = dataset([_kin("a", n, psi=psi, cog_rad=cog, sog_mps=np.full(n, 5.0))], 20.0)
    assert ds.windows.w == 1
    assert np.allclose(ds.target[0, :, CHANNELS.index("psi")], heading)
    drift = ds.target[0, :, CHANNELS.index("cog_psi")]
    assert np.allclose(drift, np.where(np.arange(n) % 2, 0.3, -0.3))


def test_dataset_drift_angle_crossing_pi_wraps_to_minus_pi() -> None:
    n = 21
    psi = np.full(n, 0.1)
    cog = np.full(n, 0.1 + np.radians(190.0))  # 190 deg to starboard is 170 deg to port
    ds = dataset([_kin("a", n, psi=psi, cog_rad=cog, sog_mps=np.full(n, 1.0))], 20.0)
    assert np.allclose(ds.target[0, :, CHANNELS.index("cog_psi")], np.radians(-170.0))


def test_dataset_phases_use_the_smoothed_yaw_rate() -> None:
    n = 41
    t = np.arange(n, dtype=float)
    rudder = np.where(t < 10, 0.0, 20.0)
    r_smooth = np.where(t < 10, 0.0, 0.01 * (1 - np.exp(-(t - 10) / 5.0)))
    kin = _kin("a", n, rudder_deg=rudder, r_smooth=r_smooth, r_radps=np.zeros(n))
    ds = dataset([kin], 10.0)
    expected = phases(np.radians(rudder), r_smooth, 1.0)
    assert not np.array_equal(expected, phases(np.radians(rudder), np.zeros(n), 1.0))
    for i, start in enumerate((0, 10, 20, 30)):
        assert ds.phase[i].tolist() == expected[start:start + 11].tolist()
    assert PHASES[ds.phase[1, 1]] == "execute"


def test_dataset_noise_is_the_median_over_runs() -> None:
    n = 41
    runs = [_kin(name, n, north=_alternating(a, n), **extra)
            for name, a, extra in (("a", 0.1, {"u_mps": _alternating(0.7, n)}), ("b", 0.5, {}),
                                   ("c", 0.2, {}))]
    ds = dataset(runs, 10.0)
    assert ds.sigma[CHANNELS.index("north")] == pytest.approx(_sigma_of_alternating(0.2))
    # u only in run a: its noise alone
    assert ds.sigma[CHANNELS.index("u")] == pytest.approx(_sigma_of_alternating(0.7))
    # east is a straight line: no third differences, the floor
    assert ds.sigma[CHANNELS.index("east")] == pytest.approx(1e-9, abs=1e-9)


def test_dataset_of_two_runs_and_subset() -> None:
    a = _kin("a", 21, north=np.arange(21.0))
    b = _kin("b", 11, dt=2.0, north=100.0 + np.arange(11.0))
    ds = dataset([a, b], 10.0)
    # run a: 11-sample windows from 0 and 10; run b (2 s): 6-sample windows from 0 and 5
    assert ds.windows.run.tolist() == [0, 0, 1, 1]
    assert ds.windows.n_samples.tolist() == [11, 11, 6, 6]
    assert ds.target[3, 0, 0] == 105.0 and np.isnan(ds.target[3, 6:, 0]).all()
    sub = ds.subset(np.array([False, True, False, True]))
    assert sub.windows.w == 2 and sub.runs is ds.runs
    assert np.array_equal(sub.target, ds.target[[1, 3]], equal_nan=True)
    assert np.array_equal(sub.phase, ds.phase[[1, 3]])
    assert sub.windows.t0_s.tolist() == [10.0, 10.0]
    assert sub.channels == ds.channels and sub.sigma is ds.sigma
