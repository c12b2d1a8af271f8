"""Identified ships written as ship files: exact values back through the library loader."""

from __future__ import annotations

from pathlib import Path

import pytest

from trafficsim.identify.shipfile import number, write_ship_file
from trafficsim.io.yamlio import parse_yaml
from trafficsim.ships.library import load_ship


@pytest.mark.parametrize("value", [1e-05, -7.8174e-06, 3.0, 0.0, 12345678.9, -2.5e12, 0.1])
def test_numbers_read_back_as_the_same_floats(value: float) -> None:
    """PyYAML reads '1e-05' as a string; the writer's literals are floats, to 10 digits."""
    got = parse_yaml(f"x: {number(value)}\n").data["x"]
    assert isinstance(got, float) and got == pytest.approx(value, rel=1e-10, abs=0.0)


def test_written_ship_loads_with_its_coefficients(tmp_path: Path) -> None:
    spec = load_ship("bulk_carrier")
    coeffs = {**spec["coefficients"], "a4": 1e-05, "c3": 2.5e-4}
    spec = {**spec, "coefficients": coeffs,
            "sensors": {"gnss": {"sigma_m": 1.5}, "compass": {"sigma_deg": 0.3}}}
    loaded = write_ship_file(tmp_path / "s.yaml", spec, 'quote "this"', "desc: with colon",
                             "src\nline two", {"a4": (1e-05, 2e-06)})
    assert loaded["name"] == 'quote "this"' and loaded["source"] == "src\nline two"
    assert loaded["coefficients"] == pytest.approx(coeffs, rel=1e-10)
    assert loaded["sensors"]["gnss"]["sigma_m"] == 1.5
    assert "# identified" in (tmp_path / "s.yaml").read_text()
