"""Which coefficients an identification fits: default subsets, bounds, starting values and the
candidate ship specs / kernel rows built from parameter vectors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trafficsim.errors import InputError
from trafficsim.identify.parameters import (
    BOUNDS,
    DEFAULT_FIT,
    Parametrisation,
    check_physical,
    default_bounds,
)
from trafficsim.identify.replay import model_rows
from trafficsim.ships.base import families
from trafficsim.ships.library import load_ship

INF = math.inf


def test_default_subsets_and_bounds_name_declared_coefficients() -> None:
    """A misspelt name in the tables would silently never be fitted or bounded."""
    fams = families()
    for model, names in DEFAULT_FIT.items():
        assert set(names) <= set(fams[model].coefficients), model
        assert len(set(names)) == len(names), model
    for model, table in BOUNDS.items():
        assert set(table) <= set(fams[model].coefficients), model
        assert all(lo < hi for lo, hi in table.values()), model


@pytest.mark.parametrize("ship, expected", [
    ("cargo", ("K_prime", "T_prime", "n3_prime", "rps_service", "surge_tau_s")),
    ("bulk_carrier", ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3",
                      "b4", "c1", "c2", "c3")),
    ("kvlcc2", ("R0", "X_vr", "Y_v", "Y_r", "N_v", "N_r", "f_alpha")),
])
def test_documented_default_subsets(ship: str, expected: tuple[str, ...]) -> None:
    assert Parametrisation.of(load_ship(ship)).names == expected


def test_berthing_subset_fits_resistance_ahead_instead_of_r0() -> None:
    p = Parametrisation.of({"model": "mmg_berthing", "coefficients": {}})
    assert p.names == ("X_0F", "X_vr", "Y_v", "Y_r", "N_v", "N_r", "f_alpha")
    # the low-speed model's resistance coefficient is negative
    assert (p.lower[0], p.upper[0]) == (-0.5, 0.0)
    assert p.model == "mmg_berthing" and p.p == 7


def test_family_without_default_subset_fits_every_coefficient() -> None:
    spec = load_ship("catfish")  # modular family: no documented subset
    p = Parametrisation.of(spec)
    assert p.names == tuple(families()["modular"].coefficients)
    assert np.all(p.lower == -INF) and np.all(p.upper == INF)


def test_response_bounds_keep_only_damping_signs() -> None:
    """a1, b1, c2 bounded above by zero; every other response coefficient unbounded."""
    p = Parametrisation.of(load_ship("bulk_carrier"))
    signed = {"a1", "b1", "c2"}
    for name, lo, hi in zip(p.names, p.lower, p.upper, strict=True):
        assert lo == -INF, name
        assert hi == (0.0 if name in signed else INF), name


def test_user_bounds_replace_defaults_of_named_coefficients_only() -> None:
    p = Parametrisation.of(load_ship("cargo"), ["T_prime", "K_prime"], {"K_prime": (1.0, 3.0)})
    assert p.names == ("T_prime", "K_prime")  # user order kept
    np.testing.assert_array_equal(p.lower, [0.02, 1.0])
    np.testing.assert_array_equal(p.upper, [200.0, 3.0])


def test_initial_is_the_base_value_clipped_into_the_bounds() -> None:
    spec = load_ship("cargo")
    k, t = spec["coefficients"]["K_prime"], spec["coefficients"]["T_prime"]
    above = Parametrisation.of(spec, ["K_prime", "T_prime"], {"K_prime": (2 * k, 3 * k)})
    np.testing.assert_array_equal(above.initial(), [2 * k, t])
    below = Parametrisation.of(spec, ["K_prime", "T_prime"], {"T_prime": (0.1 * t, 0.5 * t)})
    np.testing.assert_array_equal(below.initial(), [k, 0.5 * t])


@pytest.mark.parametrize("ship", ["cargo", "bulk_carrier", "kvlcc2", "kvlcc2_l7"])
def test_library_ships_start_inside_the_default_bounds(ship: str) -> None:
    """The default starting point is the base ship itself, not a clipped copy of it."""
    spec = load_ship(ship)
    p = Parametrisation.of(spec)
    np.testing.assert_array_equal(p.initial(), [spec["coefficients"][n] for n in p.names])


def test_unknown_name_without_close_match_has_no_hint() -> None:
    with pytest.raises(InputError, match="unknown coefficient 'zzz'") as err:
        Parametrisation.of(load_ship("cargo"), ["zzz"])
    assert "did you mean" not in str(err.value) and err.value.key == "--fit"


def test_a_name_listed_twice_is_refused() -> None:
    with pytest.raises(InputError, match="listed twice") as err:
        Parametrisation.of(load_ship("cargo"), ["K_prime", "T_prime", "K_prime"])
    assert err.value.key == "--fit"


@pytest.mark.parametrize("bounds", [(1.0, 1.0), (float("nan"), 2.0), (2.0, 1.0)])
def test_bounds_must_leave_room(bounds: tuple[float, float]) -> None:
    with pytest.raises(InputError, match="empty bounds for K_prime") as err:
        Parametrisation.of(load_ship("cargo"), ["K_prime"], {"K_prime": bounds})
    assert err.value.key == "--bounds"


@pytest.mark.parametrize("name, bounds, expect", [
    ("K_prime", (-5.0, -1.0), "K_prime=-5:-1 reaches outside the physical range of K_prime, "
                              "which must be > 0 (rudder gain; positive rudder turns to "
                              "starboard), got -5; give bounds inside it"),
    ("T_prime", (1.0, float("inf")), None),
    ("n3_prime", (-1.0, 10.0), "n3_prime=-1:10 reaches outside the physical range of n3_prime, "
                               "which must be >= 0"),
    ("surge_tau_s", (0.0, 10.0), "surge_tau_s=0:10 reaches outside"),
])
def test_user_bounds_stay_inside_the_physical_range(name, bounds, expect) -> None:
    """User bounds reaching where no ship file can hold the coefficient are refused before any
    fit (else the fit could end there and the ship file would be invalid)."""
    if expect is None:
        check_physical("nomoto", {name: bounds})
        return
    with pytest.raises(InputError) as err:
        check_physical("nomoto", {name: bounds})
    assert err.value.key == "--bounds" and str(err.value).startswith(f"--bounds: {expect}")


def test_base_spec_is_copied_not_referenced() -> None:
    spec = load_ship("cargo")
    k = spec["coefficients"]["K_prime"]
    p = Parametrisation.of(spec, ["K_prime"])
    spec["coefficients"]["K_prime"] = 99.0  # changing the caller's spec afterwards ...
    assert p.initial()[0] == k  # ... does not move the starting point
    assert p.specs(np.array([[k]]))[0]["coefficients"]["K_prime"] == k


def test_specs_set_fitted_values_and_keep_the_rest() -> None:
    spec = load_ship("cargo")
    p = Parametrisation.of(spec, ["K_prime", "surge_tau_s"])
    thetas = np.array([[1.0, 30.0], [2.0, 40.0], [3.0, 50.0]])
    out = p.specs(thetas)
    assert len(out) == 3
    for s, (k, tau) in zip(out, thetas, strict=True):
        c = s["coefficients"]
        assert (c["K_prime"], c["surge_tau_s"]) == (k, tau)
        assert isinstance(c["K_prime"], float)
        assert c["T_prime"] == spec["coefficients"]["T_prime"]
        assert s["particulars"] == spec["particulars"] and s["name"] == spec["name"]
    out[0]["coefficients"]["T_prime"] = -1.0  # candidates do not share coefficient dicts
    assert out[1]["coefficients"]["T_prime"] == spec["coefficients"]["T_prime"]
    assert p.spec["coefficients"]["T_prime"] == spec["coefficients"]["T_prime"]


def test_specs_of_a_single_vector() -> None:
    p = Parametrisation.of(load_ship("cargo"), ["K_prime"])
    (only,) = p.specs(np.array([2.5]))
    assert only["coefficients"]["K_prime"] == 2.5


def test_rows_pack_the_candidates_like_hand_edited_ship_files() -> None:
    """Row i of ``rows`` is what the replay packs for the base ship with row i of ``thetas``
    written into its coefficients by hand."""
    p = Parametrisation.of(load_ship("kvlcc2"), ["Y_v", "N_r"])
    thetas = np.array([[-0.3, -0.05], [-0.5, -0.1]])
    rows = p.rows(thetas)
    assert rows.k == 2
    for i, (y_v, n_r) in enumerate(thetas):
        by_hand = load_ship("kvlcc2")
        by_hand["coefficients"]["Y_v"] = y_v
        by_hand["coefficients"]["N_r"] = n_r
        ref = model_rows([by_hand])
        np.testing.assert_array_equal(rows.params[i], ref.params[0])
        assert rows.codes[i] == ref.codes[0] and rows.max_dt_s[i] == ref.max_dt_s[0]
    assert not np.array_equal(rows.params[0], rows.params[1])


@pytest.mark.parametrize("ship", ["cargo", "bulk_carrier", "kvlcc2"])
def test_rows_at_the_base_values_are_the_base_ship(ship: str) -> None:
    """Packing the base ship's own values of the default subset gives exactly the base ship's
    row (nothing else changes when a candidate equals the start)."""
    spec = load_ship(ship)
    p = Parametrisation.of(spec)
    x = np.array([spec["coefficients"][n] for n in p.names], dtype=float)
    assert np.all((p.lower <= x) & (x <= p.upper))
    np.testing.assert_array_equal(p.initial(), x)
    rows = p.rows(np.vstack([x, x]))
    base_row = model_rows([spec])
    np.testing.assert_array_equal(rows.params, np.repeat(base_row.params, 2, axis=0))


def test_changing_one_fitted_value_changes_only_the_packed_row_of_that_candidate() -> None:
    """Three candidates, the second with T' doubled: rows 0 and 2 equal the base ship's,
    row 1 differs; the base spec held by the parametrisation keeps its value."""
    spec = load_ship("cargo")
    p = Parametrisation.of(spec, ["K_prime", "T_prime"])
    x = p.initial()
    thetas = np.vstack([x, x * [1.0, 2.0], x])
    rows = p.rows(thetas)
    base_row = model_rows([spec]).params[0]
    np.testing.assert_array_equal(rows.params[0], base_row)
    np.testing.assert_array_equal(rows.params[2], base_row)
    assert not np.array_equal(rows.params[1], base_row)
    assert p.spec["coefficients"]["T_prime"] == spec["coefficients"]["T_prime"]


def test_one_sided_user_bounds_and_clipping_at_them() -> None:
    """User bounds (K' in [3, inf)) replace the defaults; a base value below the lower bound
    starts at the bound; bounds of the other fitted names stay the defaults."""
    spec = load_ship("cargo")
    k = spec["coefficients"]["K_prime"]
    p = Parametrisation.of(spec, ["K_prime", "T_prime"], {"K_prime": (k + 1.0, INF)})
    assert p.lower[0] == k + 1.0 and p.upper[0] == INF
    assert (p.lower[1], p.upper[1]) == default_bounds("nomoto", "T_prime")
    assert p.initial()[0] == k + 1.0
    assert p.initial()[1] == spec["coefficients"]["T_prime"]
