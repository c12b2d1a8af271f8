"""Ship files: every bundled ship loads; every mistake is reported at its line."""

from pathlib import Path

import pytest

from trafficsim.errors import ShipLibraryError
from trafficsim.ships.base import families
from trafficsim.ships.library import LIBRARY_DIR, find_ship, known_ships, load_ship

KVLCC2 = (LIBRARY_DIR / "kvlcc2.yaml").read_text()


@pytest.mark.parametrize("name", known_ships())
def test_every_bundled_ship_loads_and_names_its_family(name):
    spec = load_ship(name)
    assert spec["name"] == name
    assert spec["model"] in families()
    assert spec["source"].strip(), "every ship file cites its source"
    assert set(spec["coefficients"]) == set(families()[spec["model"]].coefficients)


def _line_of(text: str, needle: str) -> int:
    return next(k for k, line in enumerate(text.splitlines(), 1) if needle in line)


def _broken(tmp_path: Path, old: str, new: str) -> tuple[Path, int]:
    assert old in KVLCC2
    text = KVLCC2.replace(old, new, 1)
    path = tmp_path / "ship.yaml"
    path.write_text(text)
    return path, _line_of(text, new.strip().splitlines()[-1])


def test_unknown_coefficient_is_located_with_a_suggestion(tmp_path):
    path, line = _broken(tmp_path, "  Y_v:", "  Y_vv_typo:")
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert f"ship.yaml:{line}:" in str(err.value) and "Y_vv_typo" in str(err.value)


def test_missing_required_coefficient_is_named(tmp_path):
    path, _ = _broken(tmp_path, "  R0:", "  # R0:")
    with pytest.raises(ShipLibraryError, match="missing required coefficient 'R0'"):
        load_ship(str(path))


def test_unknown_model_family_suggests_the_right_one(tmp_path):
    path, line = _broken(tmp_path, "model: mmg", "model: mgm")
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert f":{line}:" in str(err.value) and "did you mean 'mmg'" in str(err.value)


@pytest.mark.parametrize("old, new, expect", [
    ("  length_m: 320.0", "  length_m: long", "expected a number"),
    ("  rudder_max_deg: 35.0", "  rudder_max_deg: -35.0", "rudder_max_deg"),
    ("service_speed_kn: 15.5", "service_speed_kn: 15.5\nspeed: 3", "unknown key 'speed'"),
    # values that set time steps: a tiny ship or sub-step never finished (or overflowed)
    ("  length_m: 320.0", "  length_m: 1.0e-300", "length_m: must be >= 0.5"),
    ("integration: {max_dt_s: 1.0}", "integration: {max_dt_s: 1.0e-9}",
     "max_dt_s: must be >= 0.001"),
])
def test_bad_values_and_keys_are_located(tmp_path, old, new, expect):
    path, line = _broken(tmp_path, old, new)
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert f"ship.yaml:{line}:" in str(err.value) and expect in str(err.value)


def test_names_and_paths():
    assert find_ship("kvlcc2") == LIBRARY_DIR / "kvlcc2.yaml"
    with pytest.raises(ShipLibraryError, match="did you mean 'catfish'"):
        find_ship("catfsh")
    with pytest.raises(ShipLibraryError, match="not found"):
        find_ship("nowhere/ship.yaml")
    spec = load_ship(str(LIBRARY_DIR / "catfish.yaml"))
    assert spec["model"] == "modular"


def test_a_loaded_ship_is_the_callers_own():
    """Files are parsed once and cached; what a caller changes in the dict it got (nested
    tables included) changes nothing for the next caller."""
    first = load_ship("cargo")
    k = first["coefficients"]["K_prime"]
    first["coefficients"]["K_prime"] = 99.0
    first["particulars"]["length_m"] = 1.0
    again = load_ship("cargo")
    assert again["coefficients"]["K_prime"] == k and again["particulars"]["length_m"] > 1.0
