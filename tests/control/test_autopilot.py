import numpy as np

from trafficsim.control.autopilot import rudder_command


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
