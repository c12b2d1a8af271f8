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
    ("  length_m: 320.0", "  length_m: 320.0\n  lenght_m: 3",
     "particulars.lenght_m: unknown key 'lenght_m' (did you mean 'length_m'?)"),
    ("  length_m: 320.0", "  length_m: 320.0\n  keel_depth: 3", "known particulars: length_m"),
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


@pytest.mark.parametrize("old, new, expect", [
    ("model: mmg", "model: [mmg", "invalid YAML"),
    ("schema_version: 1", "schema_version: 2", "schema_version: expected 1, got 2"),
    ("  beam_m: 58.0", "  beam_m: true", "particulars.beam_m: expected a number"),
    ("  Y_v: -0.315", "  Y_v: lots", "coefficients.Y_v: expected a number"),
    ("  Y_v: -0.315", "  Y_v: .nan", "coefficients.Y_v: expected a finite number"),
    ("  Y_v: -0.315", "  Y_v: -.inf", "coefficients.Y_v: expected a finite number"),
    ("  beam_m: 58.0", "  beam_m: 58.0\n  beam_m: 59.0", "duplicate key 'beam_m'"),
    ("name: kvlcc2", "name: ''", "name: must not be empty"),
    ("  rudder_rate_degps: 2.32", "  rudder_rate_degps: 0.0", "rudder_rate_degps"),
    ("  rps_min: -1.33", "  rps_min: 0.5", "rps_min"),
    ("service_speed_kn: 15.5", "service_speed_kn: 61", "service_speed_kn"),
    ("integration: {max_dt_s: 1.0}", "integration: {max_dt_s: 1.0, substeps: 3}",
     "unknown key 'substeps'"),
    ("integration: {max_dt_s: 1.0}", "integration: {max_dt_s: 1.0}\nsensors: {gnsss: {}}",
     "unknown sensor 'gnsss'"),
    ("integration: {max_dt_s: 1.0}",  # (a ship file's own instruments lie on its own hull)
     "integration: {max_dt_s: 1.0}\nsensors:\n  gnss:\n    antenna_y_m: 29.5",
     "sensors.gnss.antenna_y_m: must lie on board, within +-29 m of the reference point (half "
     "the beam B of the ship's hull, L = 320 m, B = 58 m), got 29.5"),
    ("integration: {max_dt_s: 1.0}",
     "integration: {max_dt_s: 1.0}\nsensors:\n  radar:\n    antenna_x_m: -161",
     "sensors.radar.antenna_x_m: must lie on board, within +-160 m"),
])
def test_more_bad_files_are_located_ship_file_errors(tmp_path, old, new, expect):
    """Syntax, schema version, wrong types, non-finite and out-of-range values, duplicate
    keys, unknown keys and sensors: a ``ShipLibraryError`` (an ``InputError``, a
    ``ValueError``) at the offending line of the file."""
    from trafficsim.errors import InputError

    path, line = _broken(tmp_path, old, new)
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert isinstance(err.value, InputError) and isinstance(err.value, ValueError)
    assert err.value.path is not None and Path(err.value.path).name == "ship.yaml"
    assert expect in str(err.value)
    if "invalid YAML" not in expect:
        assert err.value.line == line, str(err.value)


@pytest.mark.parametrize("text, expect", [
    ("", "file is empty"), ("- a\n- b\n", "must be a mapping"),
    ("schema_version: 1\nname: x\n", "missing required key")])
def test_files_that_are_not_ship_files(tmp_path, text, expect):
    path = tmp_path / "ship.yaml"
    path.write_text(text)
    with pytest.raises(ShipLibraryError, match=expect) as err:
        load_ship(str(path))
    assert "ship.yaml" in str(err.value)


@pytest.mark.parametrize("old, new", [
    ("  displacement_m3: 312600.0", "  displacement_m3: .nan"),
    ("  propeller_diameter_m: 9.86", "  propeller_diameter_m: .inf")])
def test_non_finite_extra_particulars_are_refused(tmp_path, old, new):
    """Every particular the models read must be a finite number, as the declared ones are."""
    path, line = _broken(tmp_path, old, new)
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert err.value.line == line and "finite" in str(err.value)


def test_optional_coefficients_and_sections_take_their_defaults(tmp_path):
    """Coefficients with a family default may be left out (Nomoto's n3' = 0, MMG's
    k_zz = 0.25 and delta_0 = 0); without ``integration`` and ``autopilot`` the documented
    defaults apply (max_dt_s 1 s; kp 1, kd_s 0, ki_per_s 0)."""
    cargo = (LIBRARY_DIR / "cargo.yaml").read_text()
    text = "\n".join(line for line in cargo.splitlines()
                     if not line.startswith(("  n3_prime", "autopilot", "integration")))
    path = tmp_path / "plain.yaml"
    path.write_text(text + "\n")
    spec = load_ship(str(path))
    assert spec["coefficients"]["n3_prime"] == 0.0
    assert spec["integration"] == {"max_dt_s": 1.0}
    assert spec["autopilot"] == {"kp": 1.0, "kd_s": 0.0, "ki_per_s": 0.0}
    path, _ = _broken(tmp_path, "  k_zz: 0.25", "  # k_zz")
    spec = load_ship(str(path))
    assert spec["coefficients"]["k_zz"] == 0.25 and spec["coefficients"]["delta_0"] == 0.0
    assert spec["path"] == str(path.resolve())
    assert spec["coefficients"]["Y_v"] == -0.315 and spec["particulars"]["length_m"] == 320.0


def test_paths_relative_to_a_base_folder_yml_files_and_parameter_folders(tmp_path):
    """A relative path resolves against ``base_dir``; ``.yml`` marks a path too; a folder is
    a ship only with ``MMG_params.csv`` in it (else "not found" names the marker file)."""
    sub = tmp_path / "ships"
    sub.mkdir()
    (sub / "mine.yml").write_text(KVLCC2.replace("name: kvlcc2", "name: mine"))
    assert find_ship("ships/mine.yml", tmp_path) == (sub / "mine.yml").resolve()
    assert load_ship("ships/mine.yml", tmp_path)["name"] == "mine"
    assert find_ship(str(sub / "mine.yml")) == (sub / "mine.yml").resolve()
    with pytest.raises(ShipLibraryError, match=r"MMG_params\.csv"):
        find_ship(str(sub) + "/")
    (sub / "MMG_params.csv").write_text("")
    assert find_ship(str(sub) + "/") == sub.resolve()
    with pytest.raises(ShipLibraryError, match="not found"):
        find_ship("mine.yml", tmp_path)


def test_an_unknown_ship_named_by_a_flag_names_the_flag():
    """``flag``: the command-line option that named the ship is the error's key (first in the
    message); without a flag there is none."""
    with pytest.raises(ShipLibraryError, match="did you mean 'kvlcc2'") as err:
        load_ship("kvlc2", flag="--ship")
    assert err.value.key == "--ship" and str(err.value).startswith("--ship: ")
    with pytest.raises(ShipLibraryError) as err:
        load_ship("kvlc2")
    assert err.value.key is None
    with pytest.raises(ShipLibraryError, match="unknown ship 'zzzzzz'; known ships"):
        find_ship("zzzzzz")


def test_a_ship_file_rewritten_on_disk_is_read_again(tmp_path):
    """Caching must not outlive the file: after the file changes (new content, newer
    modification time), loading it gives the new content, as ``write_ship_file`` relies on
    when it returns the file "as loaded" right after writing it."""
    import os

    path = tmp_path / "ship.yaml"
    path.write_text(KVLCC2)
    assert load_ship(str(path))["coefficients"]["Y_v"] == -0.315
    path.write_text(KVLCC2.replace("  Y_v: -0.315", "  Y_v: -0.4"))
    later = path.stat().st_mtime + 10.0
    os.utime(path, (later, later))
    assert load_ship(str(path))["coefficients"]["Y_v"] == -0.4


@pytest.mark.parametrize("drop, kept", [("windage_frontal_area_m2", "windage_lateral_area_m2"),
                                        ("windage_lateral_area_m2", "windage_frontal_area_m2")])
def test_one_windage_area_without_the_other_is_refused(tmp_path, drop, kept):
    """One area alone would silently mean no wind at all (trafficsim.ships.wind): refused at
    the area given, naming the one missing."""
    text = "".join(t for t in KVLCC2.splitlines(keepends=True) if drop not in t)
    path = tmp_path / "ship.yaml"
    path.write_text(text)
    with pytest.raises(ShipLibraryError, match=f"{kept} is given without {drop}") as err:
        load_ship(str(path))
    assert err.value.line == _line_of(text, kept) and err.value.key == f"particulars.{kept}"


# --- values outside their physical range, every family ---------------------------------------

_G = "(volume of displacement)"


@pytest.mark.parametrize("ship, old, new, key, expect", [
    # mmg (kvlcc2): particulars, windage and the coefficients with a clear range
    ("kvlcc2", "  rudder_area_m2: 112.5", "  rudder_area_m2: -112.5", "particulars.rudder_area_m2",
     "must be > 0 (rudder area), got -112.5"),
    ("kvlcc2", "  displacement_m3: 312600.0", "  displacement_m3: 0", "particulars.displacement_m3",
     f"must be > 0 {_G}, got 0"),
    ("kvlcc2", "  displacement_m3: 312600.0", "  displacement_m3: -5",
     "particulars.displacement_m3", f"must be > 0 {_G}, got -5"),
    ("kvlcc2", "  propeller_diameter_m: 9.86", "  propeller_diameter_m: 0",
     "particulars.propeller_diameter_m", "must be > 0 (propeller diameter), got 0"),
    ("kvlcc2", "  rudder_height_m: 15.80", "  rudder_height_m: 0", "particulars.rudder_height_m",
     "must be > 0 (rudder span), got 0"),
    ("kvlcc2", "  windage_mast_groups: 1", "  windage_mast_groups: -3",
     "particulars.windage_mast_groups",
     "must be a whole number >= 0 (number of mast groups), got -3"),
    ("kvlcc2", "  windage_mast_groups: 1", "  windage_mast_groups: 1.5",
     "particulars.windage_mast_groups",
     "must be a whole number >= 0 (number of mast groups), got 1.5"),
    ("kvlcc2", "  windage_perimeter_m: 400.0", "  windage_perimeter_m: 0",
     "particulars.windage_perimeter_m", "must be > 0 (perimeter of the lateral windage), got 0"),
    ("kvlcc2", "  windage_centroid_from_bow_m: 192.0", "  windage_centroid_from_bow_m: 330",
     "particulars.windage_centroid_from_bow_m", "must be <= the length overall (320 m), got 330"),
    ("kvlcc2", "  windage_superstructure_area_m2: 900.0",
     "  windage_superstructure_area_m2: 4000", "particulars.windage_superstructure_area_m2",
     "must be <= windage_lateral_area_m2 (3844 m2, of which it is a part), got 4000"),
    ("kvlcc2", "  w_P0: 0.40", "  w_P0: 1.0", "coefficients.w_P0",
     "must be < 1 (wake fraction; 1 - w_P0 scales the propeller inflow), got 1"),
    ("kvlcc2", "  t_P: 0.220", "  t_P: 1.0", "coefficients.t_P",
     "must be < 1 (thrust deduction fraction), got 1"),
    ("kvlcc2", "  t_R: 0.387", "  t_R: 1.2", "coefficients.t_R",
     "must be < 1 (rudder drag deduction fraction), got 1.2"),
    ("kvlcc2", "  k_zz: 0.25", "  k_zz: 0", "coefficients.k_zz",
     "must be > 0 and < 1 (yaw radius of gyration / length), got 0"),
    ("kvlcc2", "  m_y: 0.223", "  m_y: -0.223", "coefficients.m_y",
     "must be >= 0 (added mass, non-dimensional), got -0.223"),
    ("kvlcc2", "  R0: 0.022", "  R0: -0.022", "coefficients.R0",
     "must be > 0 (resistance coefficient), got -0.022"),
    ("kvlcc2", "  k_0: 0.2931", "  k_0: 0", "coefficients.k_0",
     "must be > 0 (open-water thrust coefficient at J = 0), got 0"),
    ("kvlcc2", "  epsilon: 1.09", "  epsilon: 0", "coefficients.epsilon",
     "must be > 0 (ratio of the rudder and propeller wakes), got 0"),
    ("kvlcc2", "  f_alpha: 2.747", "  f_alpha: -2.747", "coefficients.f_alpha",
     "must be > 0 (rudder lift gradient coefficient), got -2.747"),
    ("kvlcc2", "  gamma_R_plus: 0.640", "  gamma_R_plus: -0.64", "coefficients.gamma_R_plus",
     "must be >= 0 (flow-straightening coefficient), got -0.64"),
    ("kvlcc2", "  C_2_plus: 1.6", "  C_2_plus: 0", "coefficients.C_2_plus",
     "must be > 0 (wake ratio at large drift angles), got 0"),
    ("kvlcc2", "  astern_thrust_ratio: 0.7", "  astern_thrust_ratio: -0.7",
     "coefficients.astern_thrust_ratio", "must be >= 0 (astern / ahead bollard thrust), got -0.7"),
    # nomoto (container)
    ("container", "  surge_tau_s: 72.8", "  surge_tau_s: 0", "coefficients.surge_tau_s",
     "must be > 0 (surge time constant), got 0"),
    ("container", "  surge_tau_s: 72.8", "  surge_tau_s: -72.8", "coefficients.surge_tau_s",
     "must be > 0 (surge time constant), got -72.8"),
    ("container", "  rps_service: 1.8015", "  rps_service: 0", "coefficients.rps_service",
     "must be > 0 (propeller speed at the service speed), got 0"),
    ("container", "  rps_service: 1.8015", "  rps_service: -1.8", "coefficients.rps_service",
     "must be > 0 (propeller speed at the service speed), got -1.8"),
    ("container", "  K_prime: 2.850", "  K_prime: 0", "coefficients.K_prime",
     "must be > 0 (rudder gain; positive rudder turns to starboard), got 0"),
    ("container", "  rps_max: 1.965", "  rps_max: 0.5", "actuators.rps_max",
     "must be >= coefficients.rps_service (1.8015, the propeller speed at the service speed), "
     "got 0.5"),
    ("container", "  displacement_m3: 21222.0", "  displacement_m3: 0",
     "particulars.displacement_m3", f"must be > 0 {_G}, got 0"),
    # modular (catfish)
    ("catfish", "  mass_kg: 8500.0", "  mass_kg: 0", "particulars.mass_kg",
     "must be > 0 (mass), got 0"),
    ("catfish", "  X_uu: -269.84", "  X_uu: 269.84", "coefficients.X_uu",
     "must be < 0 (resistance coefficient, negative), got 269.84"),
    ("catfish", "  X_nn: 0.2772", "  X_nn: -0.2772", "coefficients.X_nn",
     "must be > 0 (propeller thrust coefficient), got -0.2772"),
    ("catfish", "  N_rdot: -0.001464", "  N_rdot: 0.001464", "coefficients.N_rdot",
     "must be <= 0 (yaw added inertia derivative, -J_z), got 0.001464"),
    ("kvlcc2", "  lcg_m: 11.2", "  lcg_m: -1000", "particulars.lcg_m",
     "must lie within half the length of midship (|lcg_m| <= 160 m), got -1000"),
    # response (bulk_carrier)
    ("bulk_carrier", "  block_coefficient: 0.85", "  block_coefficient: 1.5",
     "particulars.block_coefficient", "must be > 0 and <= 1 (block coefficient), got 1.5"),
    ("bulk_carrier", "  c3: 1.9627e-4", "  c3: 1.9627e-4\n  rudder_fade_speed_mps: 0",
     "coefficients.rudder_fade_speed_mps",
     "must be > 0 (speed below which the rudder fades; 0 would turn a ship at rest), got 0"),
])
def test_a_value_outside_its_physical_range_is_located(tmp_path, ship, old, new, key, expect):
    """Zero or negative masses, lengths, areas, time constants and propeller speeds, fractions
    not below 1, a fractional number of masts, a service speed beyond the engine: each gave
    NaN trials or a diverged run; now a located error at the value's line."""
    text = (LIBRARY_DIR / f"{ship}.yaml").read_text()
    assert old in text
    text = text.replace(old, new, 1)
    path = tmp_path / "ship.yaml"
    path.write_text(text)
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert err.value.key == key and err.value.message == expect
    assert err.value.line == _line_of(text, new.strip().splitlines()[-1])
    assert err.value.path == str(path.resolve())


def test_every_value_out_of_range_is_listed(tmp_path):
    """``trafficsim validate`` lists them all: the first by line names how many more."""
    path, _ = _broken(tmp_path, "  t_P: 0.220", "  t_P: 1.0")
    path.write_text(path.read_text().replace("  w_P0: 0.40", "  w_P0: 1.0")
                    .replace("  rudder_area_m2: 112.5", "  rudder_area_m2: 0"))
    with pytest.raises(ShipLibraryError) as err:
        load_ship(str(path))
    assert [e.key for e in err.value.errors] == [
        "particulars.rudder_area_m2", "coefficients.t_P", "coefficients.w_P0"]
    assert str(err.value).endswith("got 0 (and 2 more errors)")


@pytest.mark.parametrize("command", [
    ["validate", "{ship}"], ["validate", "{scenario}"], ["run", "{scenario}", "--out", "{out}"],
    ["trial", "{ship}", "--manoeuvre", "turning", "--out", "{out}"],
    ["campaign", "{campaign}", "--out", "{out}", "--workers", "1", "--no-progress"],
], ids=lambda c: f"{c[0]}-{c[1][1:-1]}")
def test_every_command_refuses_a_value_out_of_range(tmp_path, capsys, command):
    """A zero surge time constant passed ``validate`` and gave an all-NaN trial, a diverged run
    and 'DIVERGED' campaign encounters; now every command exits 2 with the located line."""
    from trafficsim import cli

    text = (LIBRARY_DIR / "container.yaml").read_text()
    ship = tmp_path / "ship.yaml"
    ship.write_text(text.replace("  surge_tau_s: 72.8", "  surge_tau_s: 0"))
    scenario = tmp_path / "s.yaml"
    scenario.write_text("schema_version: 1\nname: s\nduration_s: 60\nships:\n"
                        "  - {name: a, type: ship.yaml, north_m: 0, east_m: 0, heading_deg: 0}\n")
    campaign = tmp_path / "c.yaml"
    campaign.write_text("schema_version: 1\nname: c\nn_encounters: 2\nduration_s: 1800\n"
                        "policy: no_avoidance\nship_types: {ship.yaml: 1}\n")
    args = [a.format(ship=ship, scenario=scenario, campaign=campaign, out=tmp_path / "o")
            for a in command]
    assert cli.main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    line = _line_of(ship.read_text(), "surge_tau_s: 0")
    assert err[-1].endswith(f"{ship}:{line}: coefficients.surge_tau_s: must be > 0 "
                            "(surge time constant), got 0")
