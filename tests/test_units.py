"""Unit conversions at the edges: knots, nautical miles, compass degrees."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trafficsim.units import KN, NM, compass_deg, from_kn, to_kn

FINITE = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)


def test_definitions() -> None:
    """1 kn = 1852 m per hour; 1 NM = 1852 m."""
    assert NM == 1852.0
    assert math.isclose(from_kn(3600.0), 1852.0, rel_tol=1e-15)
    assert KN == 1852.0 / 3600.0


@given(FINITE)
def test_knots_round_trip_scalars_and_arrays(speed_kn: float) -> None:
    assert math.isclose(to_kn(from_kn(speed_kn)), speed_kn, rel_tol=1e-15, abs_tol=1e-300)
    arr = from_kn(np.array([speed_kn, 2 * speed_kn]))
    assert isinstance(arr, np.ndarray) and arr.shape == (2,)
    assert arr[0] == from_kn(speed_kn)  # scalar and array paths agree to the bit
    assert isinstance(from_kn(int(speed_kn)), float)


@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e4, max_value=1e4))
def test_compass_degrees_lie_in_zero_to_360(angle_rad: float) -> None:
    deg = compass_deg(np.array([angle_rad]))[0]
    assert 0.0 <= deg < 360.0
    # the same direction: the difference is a whole number of turns
    assert abs(math.remainder(deg - math.degrees(angle_rad), 360.0)) < 1e-9 * max(
        1.0, abs(math.degrees(angle_rad)))


def test_compass_degrees_of_tiny_negative_angles_and_quadrants() -> None:
    out = compass_deg(np.array([-1e-17, -0.0, 0.0, math.pi / 2, -math.pi / 2, math.pi,
                                2 * math.pi]))
    np.testing.assert_allclose(out, [0.0, 0.0, 0.0, 90.0, 270.0, 180.0, 0.0], atol=1e-12)
    assert float(compass_deg(-1e-17)) == 0.0  # (360 - 1e-15 deg rounds to 360)
    assert 359.9 < float(compass_deg(-1e-15)) < 360.0


def test_scalar_array_and_list_inputs() -> None:
    """0-d arrays and numpy scalars give Python floats; lists and arrays give arrays of the
    same shape; an empty list gives an empty array; values agree with ``x * 1852 / 3600``."""
    for value in (np.float32(2.5), np.float64(2.5), np.array(2.5), 2.5, 2):
        out = from_kn(value)
        assert type(out) is float and out == pytest.approx(float(value) * 1852.0 / 3600.0,
                                                           rel=1e-15)
        assert type(to_kn(value)) is float
    grid = np.arange(6.0).reshape(2, 3)
    np.testing.assert_allclose(from_kn(grid), grid * 1852.0 / 3600.0, rtol=1e-15)
    np.testing.assert_allclose(to_kn(grid.tolist()), grid * 3600.0 / 1852.0, rtol=1e-15)
    assert from_kn([]).shape == (0,) and to_kn(np.zeros((0, 2))).shape == (0, 2)


def test_compass_degrees_at_exact_multiples_of_a_turn() -> None:
    """Whole turns either way are 0 (never 360); every quadrant boundary maps where it
    should; shape is kept; NaN stays NaN (no direction)."""
    turns = np.array([2 * math.pi * k for k in range(-5, 6)])
    out = compass_deg(turns)
    assert np.all((out >= 0.0) & (out < 360.0))
    np.testing.assert_allclose(np.minimum(out, 360.0 - out), 0.0, atol=1e-9)
    assert float(compass_deg(2 * math.pi)) == 0.0 and float(compass_deg(-2 * math.pi)) == 0.0
    quads = np.array([[math.pi / 2, 3 * math.pi / 2], [-3 * math.pi / 2, 5 * math.pi / 2]])
    np.testing.assert_allclose(compass_deg(quads), [[90.0, 270.0], [90.0, 90.0]], atol=1e-12)
    assert np.isnan(compass_deg(np.array([np.nan]))[0])
    # just below a whole turn stays just below 360
    assert 359.0 < float(compass_deg(2 * math.pi - 1e-9)) < 360.0


@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6))
def test_meters_per_second_round_trip(speed_mps: float) -> None:
    """m/s -> kn -> m/s returns the speed to within two ulps."""
    assert math.isclose(from_kn(to_kn(speed_mps)), speed_mps, rel_tol=5e-16, abs_tol=1e-300)
