"""``trafficsim trial``: one standard manoeuvre of one ship, written as trial data and indices.

``trial.csv`` is in the trial-data CSV format that :mod:`trafficsim.io.trialdata` reads (actual
rudder angle and propeller speed as the measured inputs), so a simulated trial can be fed to
``trafficsim identify`` as it is, or, with ``--sensors``, from the instruments' columns.

With ``--sensors`` the trial also records what the instruments report and what the filters make
of it, beside the truth: the GNSS receiver's output (``gnss_*``: a DGPS receiver, sigma 2 m, with
its internal position-velocity Kalman filter at S_p = 0.01 m^2/s^3 [seed 000]) and the ship's own
navigation estimate (``est_*``: the EKF on the ship's own model, :mod:`trafficsim.navigation`),
so the receiver-filter experiment of [seed 000] is one command.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.estimation import pv
from trafficsim.folders import refuse_other_results
from trafficsim.io.results import write_csv, write_json
from trafficsim.navigation import Navigation, merge_sensors
from trafficsim.ships import manoeuvres
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, Env, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.units import compass_deg, to_kn

#: the command-line flag of each manoeuvre argument
_FLAGS = {"speed_kn": "--speed-kn", "rudder_deg": "--rudder-deg", "heading_deg": "--heading-deg",
          "dt_s": "--dt-s"}
#: receiver filter S_p accepted by ``--sp``, m^2/s^3: from a filter that lags a ship's turn by
#: minutes to one that passes the raw fixes through (the tracking index sqrt(S_p dt^3) / sigma
#: is then 50 at 1 s and 2 m); far beyond, its covariance overflows
SP_RANGE_M2PS3 = (1e-6, 1e4)


def run_trial(ship: str, manoeuvre: str, rudder_deg: float | None, heading_deg: float | None,
              port: bool, speed_kn: float | None, dt_s: float | None, out_dir: Path,
              sensors: bool = False, sp_m2ps3: float = 0.01, seed: int = 0
              ) -> tuple[dict[str, float], dict[str, dict[str, Any]]]:
    """Run the manoeuvre; write ``trial.csv`` (trial-data format) and ``indices.json``.

    A value the manoeuvre rejects is reported under its command-line flag (``--speed-kn``), and
    so is a manoeuvre that does not complete (its indices would be undefined)."""
    refuse_other_results(out_dir, "trial", "a trial")
    if sensors and not SP_RANGE_M2PS3[0] <= sp_m2ps3 <= SP_RANGE_M2PS3[1]:
        raise InputError(f"expected a receiver filter S_p from {SP_RANGE_M2PS3[0]:g} to "
                         f"{SP_RANGE_M2PS3[1]:g} m^2/s^3, got {sp_m2ps3:g}", key="--sp")
    spec = load_ship(ship)
    try:
        if manoeuvre == "turning":
            rudder = rudder_deg if rudder_deg is not None else 35.0
            track, indices = manoeuvres.turning_circle(spec, -rudder if port else rudder,
                                                       speed_kn, dt_s)
        elif manoeuvre == "zigzag":
            rudder = rudder_deg if rudder_deg is not None else 10.0
            track, indices = manoeuvres.zigzag(spec, -rudder if port else rudder, heading_deg,
                                               speed_kn, dt_s)
        else:
            track, indices = manoeuvres.crash_stop(spec, speed_kn, dt_s)
    except InputError as err:
        if err.key in _FLAGS:
            raise InputError(err.message, key=_FLAGS[err.key]) from None
        raise
    _check_completed(manoeuvre, track, indices, spec)
    criteria = manoeuvres.imo_criteria(manoeuvre, indices)
    if sensors:
        track = {**track, **sensor_columns(track, spec, sp_m2ps3, seed)}
    write_csv(out_dir / "trial.csv", track)
    write_json(out_dir / "indices.json", {"ship": spec["name"], "manoeuvre": manoeuvre,
                                          "indices": indices, "imo_msc137": criteria})
    return indices, criteria


def _check_completed(manoeuvre: str, track: Mapping[str, np.ndarray],
                     indices: Mapping[str, float], spec: Mapping[str, Any]) -> None:
    """Raise :class:`InputError` naming the flags to change if the manoeuvre never completed
    within its time limit (an index it needs is undefined)."""
    t_end = float(track["t_s"][-1])
    change = np.degrees(np.abs(np.unwrap(np.radians(track["heading_deg"]))
                               - np.radians(track["heading_deg"][0]))).max()
    if manoeuvre == "turning" and not np.isfinite(indices["steady_diameter_m"]):
        raise InputError(f"the turn did not complete: the heading changed by {change:.3g} deg "
                         f"in {t_end / 3600:.3g} h, not the 540 deg the indices need; give a "
                         "larger rudder angle", key="--rudder-deg")
    if manoeuvre == "zigzag" and not np.isfinite(indices["second_overshoot_deg"]):
        raise InputError(f"the zig-zag did not complete: with {abs(indices['rudder_deg']):g} deg "
                         f"rudder the heading changed by at most {change:.3g} deg in "
                         f"{t_end / 3600:.3g} h; give a smaller --heading-deg than "
                         f"{indices['heading_deg']:g} or a larger --rudder-deg",
                         key="--heading-deg")
    if manoeuvre == "crash-stop" and float(track["u_mps"][-1]) > 0.0:
        raise InputError(f"the crash stop did not complete: '{spec['name']}' was still making "
                         f"{float(track['u_mps'][-1]):.3g} m/s after {t_end / 3600:.3g} h of "
                         "full astern (its ship file's rps_min)", path=spec.get("path"))


def sensor_columns(track: Mapping[str, np.ndarray], spec: Mapping[str, Any],
                   sp_m2ps3: float = 0.01, seed: int = 0) -> dict[str, np.ndarray]:
    """Receiver output and navigation estimate along a recorded true track (trial-data columns).

    The instruments are the ship file's ``sensors`` (default: DGPS 2 m, gyro compass), the
    receiver filter runs at ``sp_m2ps3`` on the raw fixes, as inside a receiver.
    """
    t = np.asarray(track["t_s"])
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    x = np.zeros((8, t.size))
    x[NORTH], x[EAST] = track["north_m"], track["east_m"]
    x[PSI] = np.radians(track["heading_deg"])
    x[U], x[V], x[R] = track["u_mps"], track["v_mps"], np.radians(track["r_degps"])
    x[RUDDER], x[RPS] = np.radians(track["rudder_deg"]), np.asarray(track["rpm"]) / 60.0
    config = merge_sensors(spec.get("sensors"), {"navigation": {"pv_sp_m2ps3": sp_m2ps3}})
    receiver = config.setdefault("gnss", {})
    if "sigma_m" not in receiver and "drms_m" not in receiver:
        receiver["sigma_m"] = 2.0
    nav = Navigation.build([config], ["ekf"], x[:, :1], seed, [0], [0], dt, [spec])
    receiver_p = pv.build([{"sigma_m": float(nav.gnss_p.sigma_m[0]), "sp_m2ps3": sp_m2ps3,
                            "dt_s": dt}])
    vn0, ve0 = _earth_velocity(x[:, 0])
    receiver = pv.init(receiver_p, x[NORTH, :1] - vn0 * dt, x[EAST, :1] - ve0 * dt,
                       np.array([vn0]), np.array([ve0]), converged=True)
    cols = {k: np.full(t.size, np.nan) for k in (
        "gnss_fix_north_m", "gnss_fix_east_m", "gnss_north_m", "gnss_east_m", "gnss_sog_kn",
        "gnss_cog_deg", "compass_heading_deg", "est_north_m", "est_east_m", "est_heading_deg",
        "est_sog_kn", "est_cog_deg", "est_r_degps")}
    for k in range(t.size):  # a recorded track is replayed in time order, one ship
        est = nav.update(x[:, k:k + 1], Env())
        (vn,), (ve,) = nav.ground_velocity(Env())  # with the ekf's current
        fix = nav.fix
        receiver = pv.step(receiver_p, receiver, np.nan_to_num(fix.north_m),
                           np.nan_to_num(fix.east_m), fix.valid)
        sog, cog = pv.velocity_over_ground(receiver)
        row = {
            "gnss_fix_north_m": fix.north_m, "gnss_fix_east_m": fix.east_m,
            "gnss_north_m": receiver.x[:, 0], "gnss_east_m": receiver.x[:, 1],
            "gnss_sog_kn": to_kn(sog), "gnss_cog_deg": compass_deg(cog),
            "compass_heading_deg": compass_deg(nav.heading_meas),
            "est_north_m": est[NORTH], "est_east_m": est[EAST],
            "est_heading_deg": compass_deg(est[PSI]), "est_sog_kn": to_kn(np.hypot(vn, ve)),
            "est_cog_deg": compass_deg(np.arctan2(ve, vn)), "est_r_degps": np.degrees(est[R]),
        }
        for key, value in row.items():
            cols[key][k] = np.asarray(value).reshape(-1)[0]
    return cols


def _earth_velocity(x: np.ndarray) -> tuple[float, float]:
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    return float(x[U] * c - x[V] * s), float(x[U] * s + x[V] * c)
