"""Unit conversions at the edges: knots, nautical miles, compass degrees."""

from __future__ import annotations

import math

import numpy as np
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
