import math

import numpy as np
import pytest

from trafficsim.control.autopilot import INTEGRAL_BAND_RAD, rudder_command


def test_rudder_turns_towards_the_desired_heading_and_wraps():
    integ = np.zeros(3)
    cmd = rudder_command(np.radians([10.0, 350.0, 0.0]), np.radians([0.0, 10.0, 0.0]),
                         np.zeros(3), integ, np.ones(3), np.zeros(3), np.zeros(3),
                         np.radians(np.full(3, 35.0)), 1.0)
    assert cmd[0] > 0 and cmd[1] < 0 and cmd[2] == 0  # 350 from 10: turn to port, 20 deg
    assert np.isclose(cmd[1], np.radians(-20.0))


def test_rudder_is_limited_and_damped_by_yaw_rate():
    integ = np.zeros(2)
    cmd = rudder_command(np.radians([90.0, 0.0]), np.zeros(2), np.array([0.0, 0.01]), integ,
                         np.ones(2), np.full(2, 10.0), np.zeros(2), np.radians(np.full(2, 35.0)),
                         1.0)
    assert np.isclose(cmd[0], np.radians(35.0))
    assert cmd[1] < 0


def test_integral_accumulates_only_near_the_target():
    integ = np.zeros(2)
    rudder_command(np.radians([5.0, 40.0]), np.zeros(2), np.zeros(2), integ, np.ones(2),
                   np.zeros(2), np.full(2, 0.01), np.radians(np.full(2, 35.0)), 2.0)
    assert integ[0] > 0 and integ[1] == 0


# --- against a scalar reference loop, wrap boundaries, anti-windup band, closed loop --------

def _reference(psi_d, psi, r, integ, kp, kd, ki, rmax, dt):
    """The docstring's law for one ship: e = wrap(psi_d - psi) to [-pi, pi] by IEEE remainder,
    integral only while |e| < 10 deg, command clipped to +-rmax."""
    e = math.remainder(psi_d - psi, 2.0 * math.pi)
    if abs(e) < math.radians(10.0):
        integ += e * dt
    cmd = kp * e + ki * integ - kd * r
    return min(max(cmd, -rmax), rmax), integ


def test_rudder_command_matches_a_scalar_loop_over_many_steps():
    """300 ships with random gains, limits and headings anywhere on the real line (negative,
    several turns), errors spread across the integral band, 25 steps: commands and integrals
    equal the scalar reference ship by ship."""
    rng = np.random.default_rng(40)
    n = 300
    kp, kd, ki = rng.uniform(0.2, 3.0, n), rng.uniform(0.0, 40.0, n), rng.uniform(0.0, 0.05, n)
    rmax = np.radians(rng.uniform(10.0, 45.0, n))
    integ = rng.normal(0.0, 0.5, n)
    ref_int = integ.copy()
    for _ in range(25):
        psi = rng.uniform(-20.0, 20.0, n)
        psi_d = psi + rng.normal(0.0, 0.3, n) + 2 * np.pi * rng.integers(-3, 4, n)
        r = rng.normal(0.0, 0.02, n)
        cmd = rudder_command(psi_d, psi, r, integ, kp, kd, ki, rmax, 0.5)
        for i in range(n):
            c, ref_int[i] = _reference(psi_d[i], psi[i], r[i], ref_int[i], kp[i], kd[i], ki[i],
                                       rmax[i], 0.5)
            assert cmd[i] == pytest.approx(c, abs=1e-12)
        np.testing.assert_allclose(integ, ref_int, rtol=0, atol=1e-12)
    assert np.any(np.abs(cmd) == rmax) and np.any(np.abs(cmd) < rmax)


@pytest.mark.parametrize("psi_d_deg, psi_deg, err_deg", [
    (5.0, 355.0, 10.0),         # across north to starboard
    (355.0, 5.0, -10.0),        # across north to port
    (0.0, 360.0, 0.0),          # the same heading written two ways
    (360.0, 0.0, 0.0),
    (-3.0, 723.0, -6.0),        # several turns apart
    (179.0, -179.0, -2.0),      # across south
    (90.0, 269.0, -179.0),      # nearly reversed: the shorter way
    (90.0, 271.0, 179.0),
])
def test_heading_error_wraps_to_the_shorter_turn(psi_d_deg, psi_deg, err_deg):
    """With kp = 1 and no other term the command is the wrapped error itself (limit 180 deg)."""
    integ = np.zeros(1)
    cmd = rudder_command(np.radians([psi_d_deg]), np.radians([psi_deg]), np.zeros(1), integ,
                         1.0, 0.0, 0.0, math.pi, 1.0)
    assert cmd[0] == pytest.approx(math.radians(err_deg), abs=1e-12)


def test_integral_band_edges_and_saturation_symmetry():
    """Errors just inside +-10 deg accumulate e dt, just outside nothing; the clip is
    symmetric and per ship; scalar gains broadcast like per-ship arrays."""
    eps = 1e-9
    e = np.array([INTEGRAL_BAND_RAD - eps, -(INTEGRAL_BAND_RAD - eps),
                  INTEGRAL_BAND_RAD + eps, -(INTEGRAL_BAND_RAD + eps)])
    integ = np.zeros(4)
    rudder_command(e, np.zeros(4), np.zeros(4), integ, 1.0, 0.0, 0.0, 1.0, 2.0)
    np.testing.assert_allclose(integ, [2 * e[0], 2 * e[1], 0.0, 0.0], rtol=1e-12)
    integ = np.zeros(2)
    cmd = rudder_command(np.radians([60.0, -60.0]), np.zeros(2), np.zeros(2), integ, 2.0, 0.0,
                         0.0, np.radians([20.0, 30.0]), 1.0)
    np.testing.assert_allclose(cmd, np.radians([20.0, -30.0]), rtol=1e-15)
    integ_a, integ_b = np.full(3, 0.1), np.full(3, 0.1)
    args = (np.array([0.1, -0.05, 2.0]), np.zeros(3), np.array([0.01, 0.0, -0.02]))
    a = rudder_command(*args, integ_a, 1.5, 10.0, 0.01, 0.6, 1.0)
    b = rudder_command(*args, integ_b, np.full(3, 1.5), np.full(3, 10.0), np.full(3, 0.01),
                       np.full(3, 0.6), 1.0)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(integ_a, integ_b)


def test_empty_batch_and_nan_heading_leave_the_integral_alone():
    """No ships: an empty command. A NaN heading estimate is outside the band: the integral
    of that ship is not poisoned, and the other ship's command is unaffected."""
    assert rudder_command(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), 1.0, 0.0, 0.0,
                          0.5, 1.0).shape == (0,)
    integ = np.array([0.3, 0.3])
    cmd = rudder_command(np.array([0.1, 0.1]), np.array([np.nan, 0.0]), np.zeros(2), integ,
                         1.0, 0.0, 0.1, 0.6, 1.0)
    assert integ[0] == 0.3 and integ[1] == pytest.approx(0.3 + 0.1, rel=1e-12)
    assert cmd[1] == pytest.approx(0.1 + 0.1 * 0.4, rel=1e-12)


def _nomoto_closed_loop(psi0_deg, psi_d_deg, ki, bias_rad, seconds=600.0, dt=0.5):
    """First-order Nomoto ship T r' + r = K (delta + bias) under the autopilot (Euler)."""
    K, T = 0.1, 20.0
    psi, r, integ = np.radians([psi0_deg]), np.zeros(1), np.zeros(1)
    track = []
    for _ in range(int(seconds / dt)):
        d = rudder_command(np.radians([psi_d_deg]), psi, r, integ, 2.0, 30.0, ki,
                           math.radians(35.0), dt)
        r = r + dt * (K * (d + bias_rad) - r) / T
        psi = np.mod(psi + dt * r, 2 * np.pi)
        track.append(psi[0])
    return np.array(track)


def test_closed_loop_turns_the_short_way_across_north_and_settles():
    """From 10 deg to 350 deg the ship turns to port through north (never past 20 deg or below
    330 deg) and settles on 350 deg."""
    track = np.degrees(_nomoto_closed_loop(10.0, 350.0, 0.0, 0.0))
    signed = (track + 180.0) % 360.0 - 180.0
    assert signed.max() <= 10.0 + 1e-9 and signed.min() > -30.0
    assert abs(signed[-1] - (-10.0)) < 0.05


def test_integral_removes_the_steady_error_of_a_constant_moment():
    """A constant rudder-equivalent disturbance b: without integral the heading settles
    -b / kp off (kp e = -b at r = 0); with it the error goes to zero."""
    b = math.radians(2.0)
    p_only = _nomoto_closed_loop(40.0, 40.0, 0.0, b, seconds=900.0)
    pid = _nomoto_closed_loop(40.0, 40.0, 0.02, b, seconds=900.0)
    assert math.degrees(p_only[-1]) - 40.0 == pytest.approx(math.degrees(b / 2.0), rel=1e-3)
    assert abs(math.degrees(pid[-1]) - 40.0) < 0.01


# --- hand calculations of the PID law ---------------------------------------------------------


def test_one_step_by_hand():
    """kp 2, ki 0.05 /s, kd 30 s; psi_d 95 deg, psi 90 deg, r 0.004 rad/s, integral 0.2 rad s,
    dt 0.5 s: e = 5 deg = 0.0872665 rad inside the band, integral 0.2 + 0.0436332 = 0.2436332,
    command 2 (0.0872665) + 0.05 (0.2436332) - 30 (0.004) = 0.1745329 + 0.0121817 - 0.12
    = 0.0667146 rad (inside the 35 deg limit)."""
    integ = np.array([0.2])
    cmd = rudder_command(np.radians([95.0]), np.radians([90.0]), np.array([0.004]), integ,
                         2.0, 30.0, 0.05, math.radians(35.0), 0.5)
    e = math.radians(5.0)
    assert integ[0] == pytest.approx(0.2 + 0.5 * e, rel=1e-12)
    assert cmd[0] == pytest.approx(2 * e + 0.05 * (0.2 + 0.5 * e) - 0.12, rel=1e-12)
    assert cmd[0] == pytest.approx(0.0667146, abs=1e-7)


def test_integral_is_frozen_outside_the_band_while_the_command_saturates():
    """A 40 deg error held for 200 steps: the integral keeps its value (no wind-up) and the
    command sits at the limit; once the error is 4 deg it grows by e dt per step again, and
    with ki = 0 the command is kp e alone."""
    integ = np.array([0.05, 0.05])
    rmax = math.radians(30.0)
    for _ in range(200):
        cmd = rudder_command(np.radians([40.0, -40.0]), np.zeros(2), np.zeros(2), integ,
                             1.5, 10.0, 0.02, rmax, 1.0)
        np.testing.assert_array_equal(cmd, [rmax, -rmax])
    np.testing.assert_array_equal(integ, [0.05, 0.05])
    e = math.radians(4.0)
    for k in range(1, 4):
        cmd = rudder_command(np.array([e, -e]), np.zeros(2), np.zeros(2), integ, 1.5, 10.0,
                             0.02, rmax, 1.0)
        np.testing.assert_allclose(integ, [0.05 + k * e, 0.05 - k * e], rtol=1e-12)
    np.testing.assert_allclose(cmd, [1.5 * e + 0.02 * integ[0], -1.5 * e + 0.02 * integ[1]],
                               rtol=1e-12)


def test_derivative_acts_on_yaw_rate_so_a_setpoint_step_gives_no_kick():
    """Derivative on the measured yaw rate, not on the error: stepping psi_d by 3 deg between
    two calls at the same psi and r changes the command by exactly kp x 3 deg (ki = 0), and
    changing r alone by 0.01 rad/s changes it by -kd x 0.01."""
    base_args = dict(kp=0.8, kd_s=25.0, ki_per_s=0.0, rudder_max_rad=1.0, dt=1.0)
    a = rudder_command(np.radians([10.0]), np.radians([12.0]), np.array([0.002]), np.zeros(1),
                       **base_args)
    b = rudder_command(np.radians([13.0]), np.radians([12.0]), np.array([0.002]), np.zeros(1),
                       **base_args)
    c = rudder_command(np.radians([13.0]), np.radians([12.0]), np.array([0.012]), np.zeros(1),
                       **base_args)
    assert b[0] - a[0] == pytest.approx(0.8 * math.radians(3.0), rel=1e-9)
    assert c[0] - b[0] == pytest.approx(-25.0 * 0.01, rel=1e-9)


def test_saturation_clips_exactly_at_each_ships_own_limit_whatever_drives_it():
    """Proportional, integral or damping term alone beyond the limit: the command is exactly
    +-rudder_max of that ship; just inside the limit it is passed through unchanged."""
    rmax = np.radians([10.0, 20.0, 35.0, 35.0])
    integ = np.array([0.0, 50.0, 0.0, 0.0])
    cmd = rudder_command(np.radians([30.0, 0.0, 0.0, 0.0]), np.zeros(4),
                         np.array([0.0, 0.0, 0.5, -0.01]), integ, 1.0, np.array([0, 0, 10, 10.0]),
                         np.array([0.0, 0.1, 0.0, 0.0]), rmax, 1.0)
    np.testing.assert_array_equal(cmd[:3], [rmax[0], rmax[1], -rmax[2]])
    assert cmd[3] == pytest.approx(0.1, rel=1e-12) and cmd[3] < rmax[3]


def test_zero_time_step_leaves_the_integral_and_gives_the_pd_command():
    """dt = 0: e dt = 0, so the integral keeps its value and ki integral uses it."""
    integ = np.array([0.3])
    cmd = rudder_command(np.radians([2.0]), np.zeros(1), np.zeros(1), integ, 1.0, 0.0, 0.1,
                         1.0, 0.0)
    assert integ[0] == 0.3
    assert cmd[0] == pytest.approx(math.radians(2.0) + 0.03, rel=1e-12)
