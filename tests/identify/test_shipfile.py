"""Identified ships written as ship files: exact values back through the library loader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trafficsim.errors import ShipLibraryError
from trafficsim.identify import replay
from trafficsim.identify.shipfile import _value, number, render, text, write_ship_file
from trafficsim.io.yamlio import parse_yaml
from trafficsim.ships.library import known_ships, load_ship


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


@pytest.mark.parametrize("value, expect", [
    (1e-05, "1.0e-05"), (3.0, "3.0"), (3, "3.0"), (-2.5e12, "-2.5e+12"), (0.1, "0.1"),
    (-0.0, "-0.0"), (123456789012.0, "1.23456789e+11"),
])
def test_number_literals(value, expect) -> None:
    """A dot in every mantissa and a signed exponent (what YAML 1.1 needs for a float);
    ten significant digits."""
    assert number(value) == expect


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_number_refuses_non_finite(value) -> None:
    with pytest.raises(ValueError, match="not a finite number"):
        number(value)


@pytest.mark.parametrize("s", ["plain", 'q"uote', "back\\slash", "tab\there", "two\nlines",
                               "ünï ✓", "a: b # c", "- dash", "'single'", "{flow}", "ship 🚢",
                               ""])
def test_text_reads_back_as_the_same_string(s: str) -> None:
    assert parse_yaml(f"x: {text(s)}\n").data["x"] == s


@pytest.mark.parametrize("s", ["a\x85b", "del\x7f", "csi\x9b", "ls\u2028x", "bom\ufeffz"])
def test_text_escapes_characters_yaml_does_not_take_literally(s: str) -> None:
    assert parse_yaml(f"x: {text(s)}\n").data["x"] == s


def test_flow_values() -> None:
    assert _value(True) == "true" and _value(False) == "false" and _value(None) == "null"
    assert _value({"a": 1, "b": [1.5, "x"], "c": {"d": False}}) == (
        '{a: 1.0, b: [1.5, "x"], c: {d: false}}')
    got = parse_yaml(f"v: {_value({'a': 1, 'b': [1.5, 'x'], 'c': {'d': None}})}\n").data["v"]
    assert got == {"a": 1.0, "b": [1.5, "x"], "c": {"d": None}}
    with pytest.raises(TypeError, match="cannot write a object"):
        _value(object())


@pytest.mark.parametrize("ship", known_ships())
def test_every_library_ship_round_trips(tmp_path: Path, ship: str) -> None:
    """Each bundled ship written as it is and read back by the library loader: the same
    particulars, actuators, coefficients, autopilot, integration and sensors."""
    spec = load_ship(ship)
    loaded = write_ship_file(tmp_path / f"{ship}.yaml", spec, spec["name"], "d", "s", {})
    for key in ("model", "service_speed_kn"):
        assert loaded[key] == spec[key]
    for key in ("particulars", "actuators", "coefficients", "autopilot", "integration",
                "sensors"):
        assert loaded.get(key) == pytest.approx(spec.get(key), rel=1e-9), key
    # particulars in the documented order: length, beam, draught first
    lines = (tmp_path / f"{ship}.yaml").read_text().splitlines()
    part = lines.index("particulars:")
    assert [ln.split(":")[0].strip() for ln in lines[part + 1: part + 4]] == [
        "length_m", "beam_m", "draught_m"]


def test_fitted_coefficients_are_marked_with_their_interval(tmp_path: Path) -> None:
    spec = load_ship("cargo")
    body = render(spec, "c", "d", "s", {"K_prime": (2.5, -0.0123), "T_prime": (1.0, 0.5)})
    lines = {ln.split(":")[0].strip(): ln for ln in body.splitlines() if ln.startswith("  ")}
    assert lines["K_prime"] == "  K_prime: 2.5   # identified, nominal 95 % interval +-0.0123"
    assert "identified" in lines["T_prime"] and "+-0.5" in lines["T_prime"]
    assert "#" not in lines["n3_prime"]
    body = render(spec, "c", "d", "s", {"K_prime": (2.5, float("inf"))})
    assert "  K_prime: 2.5   # identified, not determined by the data" in body.splitlines()
    # the value written is the fitted one, not the spec's
    assert parse_yaml(body).data["coefficients"]["K_prime"] == 2.5
    assert render(spec, "c", "d", "s", {}).count("identified") == 0


def test_an_invalid_ship_is_neither_returned_nor_written(tmp_path: Path) -> None:
    """A spec the loader rejects (negative beam) raises the loader's error naming the key and
    says the file was not written; nothing is left in the folder."""
    spec = load_ship("cargo")
    bad = {**spec, "particulars": {**spec["particulars"], "beam_m": -3.0}}
    with pytest.raises(ShipLibraryError) as err:
        write_ship_file(tmp_path / "bad.yaml", bad, "bad", "d", "s", {})
    assert err.value.key == "particulars.beam_m" and err.value.path is None
    assert f"so {tmp_path / 'bad.yaml'} was not written" in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_rewriting_the_same_path_returns_the_new_ship(tmp_path: Path) -> None:
    """Writing twice to one path (identify run again into the same folder, in one process):
    the second call must return what it wrote."""
    spec = load_ship("cargo")
    write_ship_file(tmp_path / "s.yaml", spec, "first", "d", "s", {})
    changed = {**spec, "coefficients": {**spec["coefficients"], "K_prime": 9.0}}
    second = write_ship_file(tmp_path / "s.yaml", changed, "second", "d", "s",
                             {"K_prime": (9.0, 0.1)})
    assert second["name"] == "second" and second["coefficients"]["K_prime"] == 9.0


def test_fitted_full_precision_values_give_the_same_model(tmp_path: Path) -> None:
    """Coefficients as a least-squares fit returns them (full double precision, e.g. 1/3):
    written with ten significant digits and read back, they differ by at most 5e-10
    relative (half a unit in the tenth digit), and the loaded ship replays like the fitted
    spec to that precision."""
    spec = load_ship("bulk_carrier")
    fitted = {"a1": -1.0 / 3.0, "b1": -2.0 / 7.0, "c2": -np.pi / 10.0, "c3": 1e-3 / 3.0}
    spec = {**spec, "coefficients": {**spec["coefficients"], **fitted}}
    loaded = write_ship_file(tmp_path / "fit.yaml", spec, "fit", "d", "s",
                             {k: (v, 0.01) for k, v in fitted.items()})
    for key, v in fitted.items():
        assert loaded["coefficients"][key] == pytest.approx(v, rel=5e-10, abs=0.0)
    rng = np.random.default_rng(0)
    n = 40
    x0 = np.zeros((8, 1))
    x0[3] = 6.0
    inputs = np.stack([np.radians(np.cumsum(rng.normal(0, 2, n))).clip(-0.6, 0.6),
                       np.full(n, 1.4)], axis=-1)[None]
    win = replay.Windows(x0, inputs, np.zeros((1, n, 4)), np.array([2.0]), np.array([n]),
                         np.full((1, n, 6), np.nan), np.zeros(1, int), np.zeros(1), ("w",))
    out, _ = replay.simulate(replay.model_rows([spec, loaded]), win)
    np.testing.assert_allclose(out[1], out[0], rtol=1e-7, atol=1e-6)


def test_written_file_layout_and_no_leftover_temporary_files(tmp_path: Path) -> None:
    """Extra particulars follow length, beam, draught in alphabetical order; empty autopilot or
    sensors are not written; the folder holds only the ship file after the atomic write."""
    spec = load_ship("cargo")
    parts = {**spec["particulars"], "yaw_inertia_kgm2": 1.0, "block_coefficient": 0.7}
    spec = {**spec, "particulars": parts, "autopilot": {}, "sensors": None}
    loaded = write_ship_file(tmp_path / "c.yaml", spec, "c", "d", "s", {})
    body = (tmp_path / "c.yaml").read_text()
    keys = [ln.split(":")[0].strip() for ln in body.splitlines() if ln.startswith("  ")
            and ln.split(":")[0].strip() in parts]
    rest = sorted(k for k in parts if k not in ("length_m", "beam_m", "draught_m"))
    assert keys == ["length_m", "beam_m", "draught_m", *rest]
    assert "autopilot:" not in body and "sensors:" not in body
    assert [p.name for p in tmp_path.iterdir()] == ["c.yaml"]
    assert parse_yaml(body).data["particulars"]["block_coefficient"] == 0.7
    assert loaded["coefficients"] == pytest.approx(spec["coefficients"], rel=1e-10)
