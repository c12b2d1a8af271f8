"""Candidate sim-to-real effects: one registry, one implementation each, used by the engine and
by ``trafficsim diagnose`` alike.

Each effect is a small parametric term that any scenario can switch on per ship (``effects:``
of a ship entry, see :mod:`trafficsim.io.scenario`) and that the diagnosis fits to trial data
through exactly the same functions. Parameter keys carry their unit; every effect has an "off"
value of each parameter at which it changes nothing (a ship without ``effects`` runs the code
path, and gives bit for bit the results, it had before effects existed).

=====================  ==================================================  =====================
effect                 parameters (off value)                              where it acts
=====================  ==================================================  =====================
``current``            ``north_mps``, ``east_mps`` (0): water velocity     kinematics (env)
``wind``               ``north_mps``, ``east_mps`` (0): air velocity over  Isherwood loads (env)
                       ground, "towards" (a true wind from ``atan2(-e,
                       -n)`` at ``hypot(n, e)`` m/s)
``gnss_lag``           ``tau_s`` (0): the receiver's PV filter with        position, SOG, COG
                       ``S_p = sigma^2 dt / tau^4`` (:mod:`trafficsim.
                       estimation.pv`; its gains depend on ``dt / tau``
                       only)
``lever_arm``          ``x_m``, ``y_m`` (0): GNSS antenna in the body      position, SOG, COG
                       frame [seed 003, eq 5]
``compass_bias``       ``bias_deg``, ``deviation_b_deg``,                  heading
                       ``deviation_c_deg`` (0): ``A + B sin psi + C cos
                       psi`` (:mod:`trafficsim.sensors.compass`)
``steering_lag``       ``tau_s`` (0), ``rate_degps``: the rudder the hull  rudder
                       feels follows the LOGGED rudder (an order, or an
                       indicator ahead of the gear) by a first-order lag
                       with a rate limit
``resistance``         ``scale`` (1): hull resistance times scale: ``R0'``  hull (``mmg``,
                       (``mmg``), ``X_0F`` and ``X_0A`` ahead and astern   ``mmg_berthing``)
                       (``mmg_berthing``)
``propeller_asymmetry``  ``rudder_offset_deg`` (0): neutral rudder angle   hull (``mmg``,
                       ``delta_0`` (the hull feels ``delta + delta_0``)    ``mmg_berthing``)
``shallow_water``      ``draught_to_depth`` (0): ``T/h``, corrections of   hull (``mmg``,
                       the linear hull derivatives and the sway added      ``mmg_berthing``)
                       mass (:func:`shallow_water_factor`)
``ais_latency``        ``latency_s`` (0): every reported channel is the    all reported channels
                       truth ``latency_s`` earlier (reception time stamp);
                       AIS quantisation is part of the data's noise
=====================  ==================================================  =====================

In a scenario: ``current`` and ``wind`` add to the encounter's environment for that ship;
``lever_arm``, ``compass_bias`` and ``ais_latency`` add to the ship's instruments
(``gnss.antenna_x_m/y_m``, ``compass.bias_deg`` and the B and C terms of ``deviation_deg``,
``ais.latency_s``), and ``gnss_lag`` sets its receiver filter (``navigation.pv_sp_m2ps3``
for the scenario's step); ``steering_lag`` sets the steering gear (``actuators.rudder_tau_s`` and
``rudder_rate_degps``: the logged rudder is then the order); ``resistance``,
``propeller_asymmetry`` and ``shallow_water`` change the ship's hull coefficients, for the two
families with a hull model of the MMG kind (:data:`HULL_FAMILIES`). In ``mmg_berthing`` (the
low-speed model of Miyauchi et al. 2022) they act on the same quantities as in ``mmg``: the
surge resistance (there one coefficient ahead and one astern, both scaled), the neutral rudder
angle, and the linear derivatives ``Y_v, Y_r, N_v, N_r`` with the sway added mass; its
cross-flow drag, like ``mmg``'s cubic terms, is left unchanged by shallow water (Kijima's
correction is for the linear derivatives). The other families (``nomoto``, ``response``,
``modular``) have no such hull terms, so these effects are refused for them.
"""

from __future__ import annotations

import copy
import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.io.yamlio import finite_number, shown

#: at most this many fixed-point steps to undo a compass deviation (each gains a digit or so)
_DEVIATION_ITERATIONS = 60


@dataclass(frozen=True)
class Param:
    """One effect parameter: scenario key (with unit), off value, fit bounds and start.

    ``per_length``: bounds are fractions of the ship length (lever arm).
    """

    key: str
    off: float
    lower: float
    upper: float
    start: float
    per_length: bool = False


@dataclass(frozen=True)
class Effect:
    """A candidate effect: name, parameters, where it acts, how its size is measured."""

    name: str
    kind: str  # "environment", "hull", "rudder" or "measurement"
    params: tuple[Param, ...]
    summary: str

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(p.key for p in self.params)

    def off(self) -> dict[str, float]:
        return {p.key: p.off for p in self.params}

    def magnitude(self, values: Mapping[str, float]) -> float:
        """Size of the effect (self-test): speed, time, length, angle or ``|scale - 1|``."""
        v = [float(values[k]) for k in self.keys]
        if self.name in ("current", "wind", "lever_arm", "compass_bias"):
            return float(np.sqrt(np.sum(np.square(v))))
        if self.name == "resistance":
            return abs(v[0] - 1.0)
        return abs(v[0])


REGISTRY: dict[str, Effect] = {e.name: e for e in (
    Effect("current", "environment", (Param("north_mps", 0.0, -3.0, 3.0, 0.0),
                                      Param("east_mps", 0.0, -3.0, 3.0, 0.0)),
           "uniform sea current (water velocity over ground)"),
    Effect("wind", "environment", (Param("north_mps", 0.0, -40.0, 40.0, 0.5),
                                   Param("east_mps", 0.0, -40.0, 40.0, 0.5)),
           "uniform wind (air velocity over ground), Isherwood loads"),
    Effect("gnss_lag", "measurement", (Param("tau_s", 0.0, 0.2, 200.0, 5.0),),
           "GNSS receiver position-velocity filter lag"),
    Effect("lever_arm", "measurement", (Param("x_m", 0.0, -0.5, 0.5, 0.0, True),
                                        Param("y_m", 0.0, -0.25, 0.25, 0.0, True)),
           "GNSS antenna lever arm"),
    Effect("compass_bias", "measurement", (Param("bias_deg", 0.0, -20.0, 20.0, 0.0),
                                           Param("deviation_b_deg", 0.0, -20.0, 20.0, 0.0),
                                           Param("deviation_c_deg", 0.0, -20.0, 20.0, 0.0)),
           "compass bias and deviation"),
    Effect("steering_lag", "rudder", (Param("tau_s", 0.0, 0.05, 60.0, 2.0),
                                      Param("rate_degps", 90.0, 0.1, 90.0, 10.0)),
           "steering lag and rate limit behind the logged rudder"),
    Effect("resistance", "hull", (Param("scale", 1.0, 0.2, 5.0, 1.0),),
           "hull resistance change (R0' scale)"),
    Effect("propeller_asymmetry", "hull", (Param("rudder_offset_deg", 0.0, -10.0, 10.0, 0.0),),
           "propeller asymmetry (neutral rudder angle)"),
    Effect("shallow_water", "hull", (Param("draught_to_depth", 0.0, 0.0, 0.9, 0.2),),
           "shallow water (T/h)"),
    Effect("ais_latency", "measurement", (Param("latency_s", 0.0, 0.0, 60.0, 1.0),),
           "report latency (reception time stamps)"),
)}
NAMES = tuple(REGISTRY)
#: effects whose parameters are conditions of each run (the weather of the day), not of the
#: ship: the diagnosis fits one value per run (training and held-out runs alike)
PER_RUN = tuple(n for n, e in REGISTRY.items() if e.kind == "environment")


def check(effects: Mapping[str, Any] | None, where: str = "effects") -> dict[str, dict[str, float]]:
    """Validate an ``effects:`` mapping; missing keys take their off value.

    Raises:
        InputError: unknown effect or key (with a suggestion), or a value that is not a
            finite number; ``key`` names the offending entry.
    """
    out: dict[str, dict[str, float]] = {}
    for name, values in (effects or {}).items():
        if name not in REGISTRY:
            close = difflib.get_close_matches(str(name), NAMES, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise InputError(f"unknown effect '{name}'{hint}; expected one of "
                             f"{', '.join(NAMES)}", key=f"{where}.{name}")
        eff = REGISTRY[name]
        values = {} if values is None else values
        if not isinstance(values, Mapping):
            raise InputError(f"expected a mapping of {', '.join(eff.keys)}, got {values!r}",
                             key=f"{where}.{name}")
        full = eff.off()
        for key, value in values.items():
            if key not in eff.keys:
                close = difflib.get_close_matches(str(key), eff.keys, n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise InputError(f"unknown key '{key}' of effect '{name}'{hint}; expected "
                                 f"some of {', '.join(eff.keys)}", key=f"{where}.{name}.{key}")
            number = finite_number(value)
            if number is None:
                raise InputError(f"expected a finite number, got {shown(value)}",
                                 key=f"{where}.{name}.{key}")
            full[key] = number
        _check_range(name, full, f"{where}.{name}")
        out[str(name)] = full
    return out


#: fastest current and wind an effect may add, m/s: a scenario environment's caps (10 kn, 60 m/s)
MAX_CURRENT_MPS, MAX_WIND_MPS = 10.0 * 1852.0 / 3600.0, 60.0
#: largest compass error term and neutral rudder angle, deg
MAX_COMPASS_DEG, MAX_RUDDER_OFFSET_DEG = 180.0, 90.0


def _check_range(name: str, v: Mapping[str, float], where: str) -> None:
    if name in ("current", "wind"):
        most = MAX_CURRENT_MPS if name == "current" else MAX_WIND_MPS
        speed = math.hypot(v["north_mps"], v["east_mps"])
        if speed > most:
            key = "north_mps" if abs(v["north_mps"]) >= abs(v["east_mps"]) else "east_mps"
            cap = " = 10 kn" if name == "current" else ""
            raise InputError(f"expected a {name} of at most {most:.4g} m/s{cap} (the scenario "
                             f"environment's cap), got {speed:g} m/s", key=f"{where}.{key}")
    if name == "compass_bias":
        for key, value in v.items():
            if abs(value) > MAX_COMPASS_DEG:
                raise InputError(f"expected -{MAX_COMPASS_DEG:g} to {MAX_COMPASS_DEG:g} deg, "
                                 f"got {value:g}", key=f"{where}.{key}")
    if name == "propeller_asymmetry" and abs(v["rudder_offset_deg"]) >= MAX_RUDDER_OFFSET_DEG:
        raise InputError(f"expected a neutral rudder angle within +-{MAX_RUDDER_OFFSET_DEG:g} "
                         f"deg, got {v['rudder_offset_deg']:g}", key=f"{where}.rudder_offset_deg")
    if name in ("gnss_lag", "steering_lag", "ais_latency"):
        key = "latency_s" if name == "ais_latency" else "tau_s"
        if v[key] < 0.0:
            raise InputError(f"must be >= 0, got {v[key]:g}", key=f"{where}.{key}")
    if name == "steering_lag" and v["rate_degps"] <= 0.0:
        raise InputError(f"must be > 0, got {v['rate_degps']:g}", key=f"{where}.rate_degps")
    if name == "resistance" and v["scale"] <= 0.0:
        raise InputError(f"must be > 0, got {v['scale']:g}", key=f"{where}.scale")
    if name == "shallow_water" and not 0.0 <= v["draught_to_depth"] < 0.95:
        raise InputError(f"must be in [0, 0.95), got {v['draught_to_depth']:g}",
                         key=f"{where}.draught_to_depth")


def bounds(name: str, length_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit bounds and start ``(lower, upper, start)`` of an effect's parameters for a ship."""
    ps = REGISTRY[name].params
    scale = np.array([length_m if p.per_length else 1.0 for p in ps])
    return (np.array([p.lower for p in ps]) * scale, np.array([p.upper for p in ps]) * scale,
            np.array([p.start for p in ps]) * scale)


def start_grid(name: str, length_m: float, speed_mps: float | None = None) -> np.ndarray:
    """``(g, p)`` coarse grid of starting values of an effect's fit (the cost of a delay,
    lag or direction has local minima; the best grid point starts the least squares).

    With the ship's speed ``speed_mps`` the current and wind radii scale with it (0.03 and
    0.075 U; 1.25 and 3.1 U, the values of the KVLCC2 at 15.5 kn); without it they are the
    KVLCC2's (0.25, 0.6 m/s; 10, 25 m/s).
    """
    ang = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)

    def circle(radii: Sequence[float]) -> np.ndarray:
        pts = [[0.0, 0.0]] + [[r * np.cos(a), r * np.sin(a)] for r in radii for a in ang]
        return np.array(pts)

    if name == "current":
        return circle((0.25, 0.6) if speed_mps is None else (0.03 * speed_mps,
                                                             0.075 * speed_mps))
    if name == "wind":
        return circle((10.0, 25.0) if speed_mps is None else (1.25 * speed_mps,
                                                              3.1 * speed_mps))
    if name == "lever_arm":
        return np.array([[x * length_m, y * length_m] for x in (-0.3, 0.0, 0.3)
                         for y in (-0.05, 0.0, 0.05)])
    if name == "compass_bias":
        return np.array([[b, 0.0, 0.0] for b in (-5.0, -2.5, 0.0, 2.5, 5.0)])
    if name == "steering_lag":
        return np.array([[t, r] for t in (1.0, 3.0, 6.0, 10.0, 15.0, 25.0)
                         for r in (1.0, 3.0, 10.0)])
    one = {"gnss_lag": (1.0, 2.0, 4.0, 8.0, 12.0, 18.0, 27.0, 40.0, 60.0, 100.0),
           "resistance": (0.5, 0.7, 0.85, 1.0, 1.2, 1.5, 2.0, 3.0),
           "propeller_asymmetry": (-4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0),
           "shallow_water": (0.0, 0.2, 0.4, 0.6, 0.8),
           "ais_latency": (0.0, 1.0, 2.0, 4.0, 6.0, 8.0, 11.0, 15.0, 20.0, 30.0)}[name]
    return np.array(one)[:, None]


# ---------------------------------------------------------------------------------------------
# hull and steering: the ship spec


def shallow_water_factor(draught_to_depth: float, spec: Mapping[str, Any]) -> float:
    """Shallow-water factor of the linear hull derivatives, ``1 / (1 - xi)^n - xi``.

    ``xi = T / h``, ``n = 0.40 C_B B / T`` with the block coefficient ``C_B`` from the
    displacement: the correction of the sway damping ``Y'_v`` in Kijima, Nakiri, Tsutsui and
    Matsunaga (1990), "Prediction method of ship manoeuvrability in deep and shallow waters",
    MARSIM & ICSM 90, Tokyo. Applying the same factor to ``Y'_r``, ``N'_v``, ``N'_r`` and the
    sway added mass is this package's simplification (Kijima gives separate polynomial fits for
    those); it keeps the effect one parameter and makes the signature of shallow water -- more
    damping, wider turns, smaller overshoots -- grow with ``T/h`` as measured.
    """
    xi = float(draught_to_depth)
    if xi == 0.0:
        return 1.0
    p = spec["particulars"]
    length, beam, draught = float(p["length_m"]), float(p["beam_m"]), float(p["draught_m"])
    cb = float(p.get("displacement_m3", 0.8 * length * beam * draught)) / (length * beam * draught)
    n = 0.40 * cb * beam / draught
    return 1.0 / (1.0 - xi) ** n - xi


_HULL_EFFECTS = ("resistance", "propeller_asymmetry", "shallow_water")
#: families whose hull coefficients the hull effects change, and the resistance coefficients
HULL_FAMILIES = {"mmg": ("R0",), "mmg_berthing": ("X_0F", "X_0A")}


def apply_spec(spec: Mapping[str, Any], effects: Mapping[str, Mapping[str, float]]
               ) -> dict[str, Any]:
    """The ship spec with the hull and steering effects of ``effects`` applied (a copy)."""
    hull = [n for n in _HULL_EFFECTS if n in effects]
    if not hull and "steering_lag" not in effects:
        return dict(spec)
    out = copy.deepcopy(dict(spec))
    if hull and out["model"] not in HULL_FAMILIES:
        raise InputError(f"effect '{hull[0]}' acts on the hull model of the "
                         f"{' and '.join(HULL_FAMILIES)} families; ship '{out.get('name')}' is "
                         f"a '{out['model']}' model", key=f"effects.{hull[0]}")
    c = out.get("coefficients", {})
    if "resistance" in effects:
        for key in HULL_FAMILIES[out["model"]]:
            c[key] = float(c[key]) * effects["resistance"]["scale"]
    if "propeller_asymmetry" in effects:
        c["delta_0"] = float(c.get("delta_0", 0.0)) + math.radians(
            effects["propeller_asymmetry"]["rudder_offset_deg"])
    if "shallow_water" in effects:
        f = shallow_water_factor(effects["shallow_water"]["draught_to_depth"], out)
        for key in ("Y_v", "Y_r", "N_v", "N_r", "m_y"):
            c[key] = float(c[key]) * f
    if "steering_lag" in effects:
        s = effects["steering_lag"]
        if s["tau_s"] > 0.0:
            act = out["actuators"]
            act["rudder_tau_s"] = s["tau_s"]
            act["rudder_rate_degps"] = min(s["rate_degps"], 90.0)
    out["coefficients"] = c
    return out


def steering(effects: Mapping[str, Mapping[str, float]]) -> tuple[float, float]:
    """Steering gear behind the logged rudder ``(tau_s, rate_radps)``; ``tau_s = 0``: none."""
    s = effects.get("steering_lag")
    if s is None or s["tau_s"] <= 0.0:
        return 0.0, 0.0
    return s["tau_s"], math.radians(s["rate_degps"])


# ---------------------------------------------------------------------------------------------
# environment


def environment_offset(effects: Mapping[str, Mapping[str, float]]) -> np.ndarray:
    """``(4,)`` current north, east and air velocity north, east (towards) over ground, m/s."""
    c = effects.get("current", {})
    w = effects.get("wind", {})
    return np.array([c.get("north_mps", 0.0), c.get("east_mps", 0.0),
                     w.get("north_mps", 0.0), w.get("east_mps", 0.0)])


def add_wind(speed_mps: np.ndarray, from_rad: np.ndarray, north_mps: np.ndarray,
             east_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True wind ``(speed, from)`` plus an air velocity (towards) -> ``(speed, from)``."""
    an = -np.asarray(speed_mps) * np.cos(from_rad) + north_mps
    ae = -np.asarray(speed_mps) * np.sin(from_rad) + east_mps
    return np.hypot(an, ae), np.mod(np.arctan2(-ae, -an), 2.0 * np.pi)


# ---------------------------------------------------------------------------------------------
# instruments


def apply_sensors(sensors: Mapping[str, Any], effects: Mapping[str, Mapping[str, float]],
                  dt_s: float) -> dict[str, dict[str, Any]]:
    """Instrument configs with the measurement effects applied (a copy): antenna offset,
    compass bias and deviation and AIS latency added to the ship's own (an effect at its off
    values changes nothing); ``gnss_lag`` sets the receiver filter for steps of ``dt_s``."""
    out = {k: dict(v) for k, v in sensors.items()}
    if "lever_arm" in effects and any(effects["lever_arm"].values()):
        g = out.setdefault("gnss", {})
        g["antenna_x_m"] = float(g.get("antenna_x_m", 0.0)) + effects["lever_arm"]["x_m"]
        g["antenna_y_m"] = float(g.get("antenna_y_m", 0.0)) + effects["lever_arm"]["y_m"]
    if "compass_bias" in effects and any(effects["compass_bias"].values()):
        e = effects["compass_bias"]
        c = out.setdefault("compass", {})
        c["bias_deg"] = float(c.get("bias_deg", 0.0)) + e["bias_deg"]
        if e["deviation_b_deg"] or e["deviation_c_deg"]:
            if c.get("kind", "gyro") != "magnetic":
                raise InputError("compass deviation needs a magnetic compass (sensors.compass."
                                 "kind: magnetic)", key="effects.compass_bias")
            dev = [float(d) for d in c.get("deviation_deg", [0.0] * 5)]
            dev[1] += e["deviation_b_deg"]
            dev[2] += e["deviation_c_deg"]
            c["deviation_deg"] = dev
    if "ais_latency" in effects and effects["ais_latency"]["latency_s"]:
        a = out.setdefault("ais", {})
        a["latency_s"] = float(a.get("latency_s", 2.0)) + effects["ais_latency"]["latency_s"]
    if "gnss_lag" in effects and effects["gnss_lag"]["tau_s"] > 0.0:
        sigma = float(out.get("gnss", {}).get("sigma_m", 2.0))
        out.setdefault("navigation", {})["pv_sp_m2ps3"] = pv_sp(effects["gnss_lag"]["tau_s"],
                                                               sigma, dt_s)
    return out


def pv_sp(tau_s: float, sigma_m: float, dt_s: float) -> float:
    """Acceleration spectral density ``S_p`` (m^2/s^3) of a PV filter stepping ``dt_s`` with
    time scale ``tau``: ``S_p = sigma^2 dt / tau^4``; the filter's tracking index
    ``sqrt(S_p dt^3) / sigma`` [seed 000] is then ``(dt / tau)^2``, whatever ``sigma``, so its
    lag in seconds does not depend on the sampling interval."""
    return float(sigma_m) ** 2 * float(dt_s) / float(tau_s) ** 4


def true_start(x0: np.ndarray, effects: Mapping[str, Mapping[str, float]],
               current_ne: tuple[Any, Any] = (0.0, 0.0)) -> np.ndarray:
    """True state ``(8, W)`` at the start of each window from the MEASURED one.

    ``x0`` holds the state smoothed from the measured position and heading (over-ground
    velocities of the antenna, body frame of the measured heading). Report latency is not
    undone here: the measured start is the truth ``latency`` earlier, and the replay starts
    there (:meth:`trafficsim.diagnose.fit.EffectResiduals.delayed`). Undone, in order: compass
    error, antenna lever arm (``p = p_a - R(psi) r_a``, ``v = v_a - r x r_a``), and the
    current (the model's
    ``u, v`` are through the water: over-ground minus current; ``current_ne`` north and east,
    scalars or ``(W,)`` per window, plus the ``current`` effect).
    """
    x = np.array(x0, dtype=float, copy=True)
    if "compass_bias" in effects:
        # heading, and the smoothed velocities from the measured body frame to the true one;
        # the error is a function of the TRUE heading: psi = psi_m - e(psi) by fixed-point
        # iteration (a contraction: |de/dpsi| <= |B| + |C|, a few tenths at most)
        measured = x[2].copy()
        e = compass_error(measured, effects["compass_bias"])
        for _ in range(_DEVIATION_ITERATIONS):
            e_next = compass_error(measured - e, effects["compass_bias"])
            settled = np.all(np.abs(e_next - e) <= 1e-13)
            e = e_next
            if settled:
                break
        x[2] = measured - e
        c, s = np.cos(e), np.sin(e)
        x[3], x[4] = x[3] * c - x[4] * s, x[3] * s + x[4] * c
    if "lever_arm" in effects:
        xa, ya = effects["lever_arm"]["x_m"], effects["lever_arm"]["y_m"]
        c, s = np.cos(x[2]), np.sin(x[2])
        x[0] -= xa * c - ya * s
        x[1] -= xa * s + ya * c
        x[3] += x[5] * ya
        x[4] -= x[5] * xa
    cn = current_ne[0] + effects.get("current", {}).get("north_mps", 0.0)
    ce = current_ne[1] + effects.get("current", {}).get("east_mps", 0.0)
    if np.any(cn) or np.any(ce):
        c, s = np.cos(x[2]), np.sin(x[2])
        x[3] -= cn * c + ce * s
        x[4] -= -cn * s + ce * c
    return x


def compass_error(psi: np.ndarray, values: Mapping[str, float]) -> np.ndarray:
    """Compass error ``A + B sin psi + C cos psi`` (rad) by the compass model's deviation."""
    from trafficsim.sensors import compass

    kind = "magnetic" if values["deviation_b_deg"] or values["deviation_c_deg"] else "gyro"
    cfg: dict[str, Any] = {"kind": kind, "bias_deg": values["bias_deg"]}
    if kind == "magnetic":
        cfg["deviation_deg"] = [0.0, values["deviation_b_deg"], values["deviation_c_deg"], 0.0,
                                0.0]
    p = compass.build([cfg], 1.0)
    return p.bias_rad[0] + compass.deviation(p, np.asarray(psi))


def measure(truth: np.ndarray, dt_s: np.ndarray,
            values: Sequence[Mapping[str, Mapping[str, float]]],
            current_ne: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """What the instruments report of replayed truths, ``(k, W, N)`` per channel.

    Args:
        truth: ``(k, W, N, 6)`` replayed north, east, psi, u, v, r (velocities through the
            water, :data:`trafficsim.identify.replay.OUTPUTS`).
        dt_s: ``(W,)`` sampling interval of each window.
        values: per model its effects (:func:`check` form).
        current_ne: ``(W, 2)`` current of each window, or ``(k, W, 2)`` per model and window
            (e.g. a current fitted per run), added to the ``current`` effect; default none.

    Returns:
        ``north, east`` (antenna, receiver output), ``psi`` (compass), ``u, v`` (over-ground
        velocity of the antenna in the compass's body frame), ``r``, ``sog``, ``cog``.
    """
    from trafficsim.sensors import rotate_body_to_earth

    k, w, n = truth.shape[:3]
    north, east, psi, u, v, r = (truth[..., j] for j in range(6))
    cur = np.zeros((k, w, 2))
    if current_ne is not None:
        cn = np.asarray(current_ne, dtype=float)
        cur += cn if cn.ndim == 3 else cn[None, :, :]
    off = np.array([environment_offset(e)[:2] for e in values])
    cur += off[:, None, :]
    vn, ve = rotate_body_to_earth(psi, u, v)
    vn = vn + cur[..., 0:1]
    ve = ve + cur[..., 1:2]
    pn, pe = north.copy(), east.copy()
    arm = np.array([[e.get("lever_arm", {}).get("x_m", 0.0),
                     e.get("lever_arm", {}).get("y_m", 0.0)] for e in values])
    if np.any(arm):
        xa, ya = arm[:, 0, None, None], arm[:, 1, None, None]
        dn, de = rotate_body_to_earth(psi, xa + 0.0 * psi, ya + 0.0 * psi)
        pn, pe = pn + dn, pe + de
        wn, we = rotate_body_to_earth(psi, -r * ya, r * xa)
        vn, ve = vn + wn, ve + we
    taus = np.array([e.get("gnss_lag", {}).get("tau_s", 0.0) for e in values])
    if np.any(taus > 0.0):
        pn, pe, vn, ve = _receiver_filter(pn, pe, vn, ve, taus, dt_s, n)
    head = psi.copy()
    for i, e in enumerate(values):
        if "compass_bias" in e:
            head[i] = psi[i] + compass_error(psi[i], e["compass_bias"])
    c, s = np.cos(head), np.sin(head)
    out = {"north": pn, "east": pe, "psi": head, "u": vn * c + ve * s, "v": -vn * s + ve * c,
           "r": r.copy(), "sog": np.hypot(vn, ve), "cog": np.arctan2(ve, vn)}
    lat = np.array([e.get("ais_latency", {}).get("latency_s", 0.0) for e in values])
    if np.any(lat > 0.0):
        shift = lat[:, None] / np.asarray(dt_s, float)[None, :]  # (k, W) samples
        out["cog"] = np.unwrap(out["cog"], axis=-1)
        out["psi"] = np.unwrap(out["psi"], axis=-1)  # (a wrapped heading crosses north)
        out = {key: delay(val, shift) for key, val in out.items()}
        out["psi"] = np.mod(out["psi"], 2.0 * np.pi)
    out["cog"] = np.mod(out["cog"], 2.0 * np.pi)
    return out


def delay(series: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``series`` ``(k, W, N)`` seen ``shift`` ``(k, W)`` samples late (linear interpolation;
    before the first sample, linear extrapolation from the first two)."""
    n = series.shape[-1]
    pos = np.arange(n)[None, None, :] - shift[..., None]
    i0 = np.clip(np.floor(pos).astype(np.int64), 0, max(n - 2, 0))
    frac = pos - i0
    a = np.take_along_axis(series, i0, axis=-1)
    b = np.take_along_axis(series, np.minimum(i0 + 1, n - 1), axis=-1)
    return a + frac * (b - a)


def _receiver_filter(pn: np.ndarray, pe: np.ndarray, vn: np.ndarray, ve: np.ndarray,
                     taus: np.ndarray, dt_s: np.ndarray, n: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The receiver's PV filter (:mod:`trafficsim.estimation.pv`) over each window, started
    converged on the true position and velocity, for the models with ``tau > 0``."""
    from trafficsim.estimation import pv

    w = pn.shape[1]
    on = np.flatnonzero(taus > 0.0)
    pn, pe, vn, ve = pn.copy(), pe.copy(), vn.copy(), ve.copy()
    sigma = 1.0  # the gains depend on dt / tau only (pv_sp)
    cfgs = [{"sigma_m": sigma, "sp_m2ps3": pv_sp(taus[i], sigma, float(d)), "dt_s": float(d)}
            for i in on for d in dt_s]
    params = pv.build(cfgs)
    m = on.size * w
    state = pv.init(params, pn[on, :, 0].reshape(m) - vn[on, :, 0].reshape(m) * np.repeat(
        np.asarray(dt_s, float)[None, :], on.size, 0).reshape(m),
        pe[on, :, 0].reshape(m) - ve[on, :, 0].reshape(m) * np.repeat(
            np.asarray(dt_s, float)[None, :], on.size, 0).reshape(m),
        vn[on, :, 0].reshape(m), ve[on, :, 0].reshape(m), converged=True)
    valid = np.ones(m, dtype=bool)
    for j in range(n):
        zn, ze = pn[on, :, j].reshape(m), pe[on, :, j].reshape(m)
        ok = np.isfinite(zn) & np.isfinite(ze)
        state = pv.step(params, state, np.nan_to_num(zn), np.nan_to_num(ze), valid & ok)
        x = state.x.reshape(on.size, w, 4)
        pn[on, :, j], pe[on, :, j] = x[..., pv.POS_N], x[..., pv.POS_E]
        vn[on, :, j], ve[on, :, j] = x[..., pv.VEL_N], x[..., pv.VEL_E]
    return pn, pe, vn, ve
