"""Own-ship navigation: instruments -> filter -> the estimate that guidance and autopilot use.

Decisions are taken on estimates, outcomes measured on truth. Per ship the scenario chooses
``filter``:

* ``none``: perfect knowledge, the estimate is the true state (instruments are still simulated
  and recorded if configured);
* ``pv``: the GNSS position-velocity Kalman filter [seed 000, eqs 1-5] gives position and
  velocity over ground (the antenna fix is moved to the reference point with the estimated
  heading [seed 003, eq 5]); heading and yaw rate come from a steady-state alpha-beta filter on
  the compass (the same closed-form gain, :func:`trafficsim.estimation.pv.steady_state_gain`,
  with the heading noise and an angular acceleration spectral density ``heading_sp_rad2ps3``).
  ``u, v`` of the estimate are the over-ground velocity in the body frame;
* ``ekf``: the extended Kalman filter on the ship's own model with current estimation
  [seed 002, ch 4.4, 5.3, 7, 7.3] (:mod:`trafficsim.estimation.ekf`), driven by the measured
  rudder and rpm, updated with the GNSS fix, the compass and (if fitted) the speed log; its
  noise settings default to the instruments' (``ekf:`` overrides any of them).

In both filters gross GNSS errors are
  gated [seed 002, 6.6] on the normalised innovation (``gate``: ``gate_sigma``, default 5, or
  ``window_diameter_m``; ``reopen_factor``, ``max_rejections``,
  :mod:`trafficsim.estimation.gating`); after several consecutive rejections the filter restarts
  on the fix.

Instruments (``sensors:`` of the ship file, overridden key by key by the scenario): ``gnss``,
``compass``, ``log``, ``actuators`` (rudder and rpm feedback) and ``waves`` (wave-frequency
motion seen by GNSS and compass), each as documented in its module under
:mod:`trafficsim.sensors`. Random draws come from keyed streams (:mod:`trafficsim.noise`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.estimation import ekf, gating, pv
from trafficsim.noise import NoiseBank
from trafficsim.sensors import (
    actuators,
    compass,
    gnss,
    rotate_body_to_earth,
    speed_log,
    waves,
    wrap_pi,
)
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, Env, R, U, V

FILTERS = ("none", "pv", "ekf")
SENSOR_KEYS = ("gnss", "compass", "log", "actuators", "waves", "gate", "navigation", "ekf",
               "radar", "ais", "tracker")
DEFAULT_GATE_SIGMA = 5.0  # normalised innovation; a fix beyond 5 sigma is a gross error
#: estimate rows: the estimate has the first six rows of the ship state
N_EST = 6
DEFAULT_HEADING_SP = 1e-5  # rad^2/s^3, angular acceleration spectral density of the heading filter
DEFAULT_PV_SP = 0.01  # m^2/s^3, the best S_p of [seed 000]


def merge_sensors(ship_defaults: Mapping[str, Any] | None,
                  overrides: Mapping[str, Any] | None) -> dict[str, dict[str, Any]]:
    """Sensor configs of one ship: the ship file's, overridden key by key by the scenario's."""
    out: dict[str, dict[str, Any]] = {k: dict(v or {}) for k, v in (ship_defaults or {}).items()}
    for name, cfg in (overrides or {}).items():
        out.setdefault(name, {}).update(cfg or {})
    return out


def check_sensor_config(config: Mapping[str, Any]) -> None:
    """Raise :class:`InputError` (with the offending key) if a ship's sensor config is invalid."""
    for name in config:
        if name not in SENSOR_KEYS:
            raise InputError(f"unknown sensor '{name}'; expected one of {', '.join(SENSOR_KEYS)}",
                             key=name)
    Navigation.build([dict(config)], ["pv"], np.zeros((8, 1)), 0, [0], [0], 1.0)
    from trafficsim.estimation import tracker
    from trafficsim.sensors import ais, radar

    for name, module in (("radar", radar), ("ais", ais), ("tracker", tracker)):
        if config.get(name) is not None:
            module.build([dict(config[name])])


@dataclass
class Navigation:
    """Instruments and filters of every ship, struct-of-arrays.

    ``est`` is ``(6, n)``: north, east (m), heading (rad), u, v (m/s), r (rad/s).
    """

    filter_pv: np.ndarray  # (n,) bool, ships using the pv filter (else perfect knowledge)
    gnss_p: gnss.GnssParams
    gnss_s: gnss.GnssState
    compass_p: compass.CompassParams
    compass_s: compass.CompassState
    log_p: speed_log.LogParams
    act_p: actuators.ActuatorSensorParams
    waves_p: waves.WaveParams
    waves_s: waves.WaveState
    pv_p: pv.PVParams
    pv_s: pv.PVState
    gate_p: gating.GateParams
    gate_rejections: np.ndarray  # (n,) consecutive rejected fixes
    heading_gain: np.ndarray  # (n, 2) alpha, beta (1/s) of the heading filter
    heading_est: np.ndarray  # (2, n) heading (rad), yaw rate (rad/s)
    banks: dict[str, NoiseBank]
    dt: float
    est: np.ndarray
    ekf_idx: np.ndarray | None = None  # ships using the ekf filter
    ekf_p: Any = None  # ekf.EkfParams of those ships
    ekf_model: Any = None  # ekf.ShipModel of those ships
    ekf_s: Any = None  # ekf.EkfState of those ships
    ekf_rejections: np.ndarray | None = None
    has_waves: bool = False
    has_log: bool = False
    has_actuator_sensors: bool = False
    fix: gnss.GnssFix | None = None
    heading_meas: np.ndarray | None = None
    log_meas: speed_log.LogReading | None = None
    act_meas: actuators.ActuatorReading | None = None

    @classmethod
    def build(cls, configs: Sequence[Mapping[str, Any]], filters: Sequence[str], x: np.ndarray,
              seed: int, encounter: Sequence[int], ship_in_encounter: Sequence[int],
              dt: float, specs: Sequence[Mapping[str, Any]] | None = None) -> Navigation:
        """Instruments and filters for ``n`` ships.

        Args:
            configs: per-ship sensor configs (:func:`merge_sensors`).
            filters: per-ship filter name, one of :data:`FILTERS`.
            x: ``(8, n)`` initial true state (filters start converged on it).
            seed, encounter, ship_in_encounter: key the random streams.
            specs: ship files (needed by the ``ekf`` filter, which runs the ship's own model).
        """
        for f in filters:
            if f not in FILTERS:
                raise InputError(f"unknown filter '{f}'; expected one of {', '.join(FILTERS)}",
                                 key="filter")

        def section(name: str) -> list[dict[str, Any]]:
            return [dict(c.get(name) or {}) for c in configs]

        nav_cfg = section("navigation")
        for c in nav_cfg:
            unknown = set(c) - {"pv_sp_m2ps3", "heading_sp_rad2ps3"}
            if unknown:
                raise InputError(f"unknown key(s) {sorted(unknown)}; expected pv_sp_m2ps3, "
                                 "heading_sp_rad2ps3", key="navigation")
        gnss_p = gnss.build(section("gnss"), dt)
        compass_p = compass.build(section("compass"), dt)
        waves_p = waves.build(section("waves"), dt)
        n = x.shape[1]
        banks = {
            purpose: NoiseBank(seed, encounter, ship_in_encounter, purpose, dims, kind)
            for purpose, dims, kind in (
                (gnss.GNSS_NORMAL_PURPOSE, gnss.GNSS_NORMAL_DIMS, "normal"),
                (gnss.GNSS_UNIFORM_PURPOSE, gnss.GNSS_UNIFORM_DIMS, "uniform"),
                (compass.COMPASS_PURPOSE, compass.COMPASS_NORMAL_DIMS, "normal"),
                (speed_log.LOG_PURPOSE, speed_log.LOG_NORMAL_DIMS, "normal"),
                (actuators.ACTUATOR_PURPOSE, actuators.ACTUATOR_NORMAL_DIMS, "normal"),
                (waves.WAVE_PURPOSE, waves.WAVE_NORMAL_DIMS, "normal"),
            )
        }
        init_draws = NoiseBank(seed, encounter, ship_in_encounter, "initial",
                               gnss.GNSS_NORMAL_DIMS + compass.COMPASS_NORMAL_DIMS
                               + waves.WAVE_NORMAL_DIMS).next()
        a, b = gnss.GNSS_NORMAL_DIMS, gnss.GNSS_NORMAL_DIMS + compass.COMPASS_NORMAL_DIMS
        pv_p = pv.build([{"sigma_m": s, "sp_m2ps3": c.get("pv_sp_m2ps3", DEFAULT_PV_SP),
                          "dt_s": dt} for s, c in zip(gnss_p.sigma_m, nav_cfg, strict=True)])
        # filters start converged one step before the first fix, so the first update
        # predicts to the time of the first fix
        vel = _earth_velocity(x)
        pv_s = pv.init(pv_p, x[NORTH] - vel[0] * dt, x[EAST] - vel[1] * dt, vel[0], vel[1],
                       converged=True)
        heading_sp = np.array([c.get("heading_sp_rad2ps3", DEFAULT_HEADING_SP) for c in nav_cfg])
        heading_gain = pv.steady_state_gain(np.maximum(compass_p.sigma_rad, 1e-6), heading_sp, dt)
        heading_gain = np.asarray(heading_gain).reshape(n, 2)
        est = x[:N_EST].copy()
        ekf_idx = np.flatnonzero([f == "ekf" for f in filters])
        ekf_p = ekf_model = ekf_s = None
        if ekf_idx.size:
            if specs is None:
                raise InputError("the ekf filter needs the ships' model files", key="filter")
            log_p = speed_log.build(section("log"))
            ekf_cfg = [{"gnss_sigma_m": float(gnss_p.sigma_m[i]),
                        "compass_sigma_deg": float(np.degrees(compass_p.sigma_rad[i])),
                        "log_sigma_mps": float(log_p.sigma_mps[i]),
                        **(configs[i].get("ekf") or {})} for i in ekf_idx]
            try:
                ekf_p = ekf.build(ekf_cfg)
            except ValueError as err:
                raise InputError(str(err), key="ekf") from None
            ekf_model = ekf.ShipModel.from_specs([specs[i] for i in ekf_idx])
            xe = x[:, ekf_idx]
            ekf_s = ekf.initial_state(ekf_p, xe[NORTH] - vel[0, ekf_idx] * dt,
                                      xe[EAST] - vel[1, ekf_idx] * dt, xe[PSI] - xe[R] * dt,
                                      xe[U], xe[V], xe[R])
        return cls(
            filter_pv=np.array([f == "pv" for f in filters]),
            gnss_p=gnss_p, gnss_s=gnss.init(gnss_p, init_draws[:, :a]),
            compass_p=compass_p, compass_s=compass.init(compass_p, init_draws[:, a:b]),
            log_p=speed_log.build(section("log")), act_p=actuators.build(section("actuators")),
            waves_p=waves_p, waves_s=waves.init(waves_p, init_draws[:, b:]),
            pv_p=pv_p, pv_s=pv_s, heading_gain=heading_gain,
            gate_p=gating.build([c or {"gate_sigma": DEFAULT_GATE_SIGMA}
                                 for c in section("gate")]),
            gate_rejections=gating.init_state(n),
            heading_est=np.stack([x[PSI] - x[R] * dt, x[R].copy()]), banks=banks, dt=dt,
            est=est, ekf_idx=ekf_idx, ekf_p=ekf_p, ekf_model=ekf_model, ekf_s=ekf_s,
            ekf_rejections=gating.init_state(ekf_idx.size),
            has_waves=any(c.get("waves") for c in configs),
            has_log=any(c.get("log") is not None for c in configs),
            has_actuator_sensors=any(c.get("actuators") is not None for c in configs))

    def update(self, x: np.ndarray, env: Env) -> np.ndarray:
        """Measure the true state ``x`` ``(8, n)``, update the filters; returns ``est`` (6, n)."""
        wave_psi = wave_ne = None
        if self.has_waves:
            self.waves_s = waves.step(self.waves_p, self.waves_s, self.banks["waves"].next())
            wave_psi = waves.heading_offset(self.waves_p, self.waves_s)
            wave_ne = waves.position_offset(self.waves_p, self.waves_s, x[PSI])
        self.gnss_s, self.fix = gnss.step(self.gnss_p, self.gnss_s, x, self.banks["gnss"].next(),
                                          self.banks["gnss_gross"].next(), wave_ne, wave_psi)
        self.compass_s, self.heading_meas = compass.step(
            self.compass_p, self.compass_s, x[PSI], self.banks["compass"].next(), wave_psi)
        if self.has_log:  # recorded only: the filters here do not use the log or rudder/rpm
            self.log_meas = speed_log.measure(self.log_p, x, env, self.banks["log"].next())
        if self.has_actuator_sensors:
            self.act_meas = actuators.measure(self.act_p, x, self.banks["actuators"].next())

        # heading: steady-state alpha-beta on the compass
        psi, r = self.heading_est
        psi_pred = psi + r * self.dt
        innov = wrap_pi(self.heading_meas - psi_pred)
        psi_new = np.mod(psi_pred + self.heading_gain[:, 0] * innov, 2 * np.pi)
        r_new = r + self.heading_gain[:, 1] * innov
        self.heading_est = np.stack([psi_new, r_new])

        # position: the receiver's PV filter on the fix moved to the reference point
        ref_n, ref_e = gnss.to_reference_point(self.gnss_p, self.fix.north_m, self.fix.east_m,
                                               psi_new)
        pred = pv.predict(self.pv_p, self.pv_s)
        innov = np.stack([ref_n - pred.x[:, 0], ref_e - pred.x[:, 1]], axis=1)
        s_innov = pred.P[:, :, 0, 0] + (self.pv_p.sigma_m ** 2)[:, None]
        d = np.where(self.fix.valid, gating.normalised_distance(innov, s_innov), np.nan)
        g = gating.gate(self.gate_p, d, self.gate_rejections)
        self.gate_rejections = g.rejections
        self.pv_s = pv.update(self.pv_p, pred, np.nan_to_num(ref_n), np.nan_to_num(ref_e),
                              g.accept)
        if g.restart.any():  # genuine jump: restart on the fix, keep the velocity
            x_pv = self.pv_s.x.copy()
            x_pv[g.restart, 0], x_pv[g.restart, 1] = ref_n[g.restart], ref_e[g.restart]
            self.pv_s = pv.PVState(x_pv, self.pv_s.P)
        vn, ve = self.pv_s.x[:, 2], self.pv_s.x[:, 3]
        c, s = np.cos(psi_new), np.sin(psi_new)
        filtered = np.stack([self.pv_s.x[:, 0], self.pv_s.x[:, 1], psi_new,
                             vn * c + ve * s, -vn * s + ve * c, r_new])
        self.est = np.where(self.filter_pv[None, :], filtered, x[:N_EST])
        if self.ekf_idx is not None and self.ekf_idx.size:
            self.est[:, self.ekf_idx] = self._ekf_update(x, env)
        return self.est

    def _ekf_update(self, x: np.ndarray, env: Env) -> np.ndarray:
        """Predict with the measured rudder and rpm, gate the fix, update; estimate (6, k)."""
        i = self.ekf_idx
        if self.act_meas is not None:
            rudder, rps = self.act_meas.rudder_rad[i], self.act_meas.rps[i]
        else:
            rudder, rps = x[RUDDER, i], x[RPS, i]
        wind = _take(env.wind_speed_mps, i), _take(env.wind_from_rad, i)
        pred = ekf.predict(self.ekf_p, self.ekf_model, self.ekf_s, rudder, rps, self.dt,
                           wind_speed_mps=wind[0], wind_from_rad=wind[1])
        dn, de = rotate_body_to_earth(pred.x[:, 2], self.gnss_p.antenna_x_m[i],
                                      self.gnss_p.antenna_y_m[i])
        z = np.stack([self.fix.north_m[i] - dn, self.fix.east_m[i] - de, self.heading_meas[i],
                      self.log_meas.u_mps[i] if self.log_meas is not None
                      else np.zeros(i.size)], axis=1)
        valid = self.fix.valid[i]
        innov = z[:, :2] - pred.x[:, :2]
        s_pos = pred.P[:, :2, :2] + np.eye(2)[None] * self.ekf_p.gnss_var_m2[:, None, None]
        d = np.where(valid, gating.normalised_distance(innov, s_pos), np.nan)
        g = gating.gate(_take_gate(self.gate_p, i), d, self.ekf_rejections)
        self.ekf_rejections = g.rejections
        mask = np.stack([g.accept, g.accept, np.ones(i.size, bool),
                         np.full(i.size, self.log_meas is not None)], axis=1)
        state, _ = ekf.update(self.ekf_p, pred, np.nan_to_num(z), mask)
        if g.restart.any():  # genuine jump: restart the position on the fix
            xs = state.x.copy()
            xs[g.restart, 0], xs[g.restart, 1] = z[g.restart, 0], z[g.restart, 1]
            state = ekf.EkfState(xs, state.P)
        self.ekf_s = state
        return state.x[:, :N_EST].T


def _earth_velocity(x: np.ndarray) -> np.ndarray:
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    return np.stack([x[U] * c - x[V] * s, x[U] * s + x[V] * c])


def _take(value: Any, idx: np.ndarray) -> Any:
    return value[idx] if isinstance(value, np.ndarray) and value.ndim else value


def _take_gate(params: gating.GateParams, idx: np.ndarray) -> gating.GateParams:
    return gating.GateParams(params.threshold[idx], params.reopen_factor[idx],
                             params.max_rejections[idx])
