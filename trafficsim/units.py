"""Unit conversions at the edges (files, CLI, reports). Inside, everything is SI and radians."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

KN = 1852.0 / 3600.0  # m/s per knot
NM = 1852.0  # metres per nautical mile


def from_kn(speed_kn: ArrayLike) -> np.ndarray | float:
    """Knots to m/s."""
    if isinstance(speed_kn, float | int):  # (the scalar case without numpy's dispatch)
        return float(speed_kn) * KN
    return np.asarray(speed_kn, dtype=float) * KN if np.ndim(speed_kn) else float(speed_kn) * KN


def to_kn(speed_mps: ArrayLike) -> np.ndarray | float:
    """m/s to knots."""
    return np.asarray(speed_mps, dtype=float) / KN if np.ndim(speed_mps) else float(speed_mps) / KN


def compass_deg(angle_rad: ArrayLike) -> np.ndarray:
    """Radians to compass degrees in [0, 360) (a tiny negative angle, whose remainder rounds
    up to 360, is 0)."""
    deg = np.mod(np.degrees(angle_rad), 360.0)
    return np.where(deg >= 360.0, 0.0, deg)
