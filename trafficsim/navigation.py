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

Several GNSS receivers: ``gnss2`` (and ``gnss3``) take the same keys as ``gnss`` (own sigma,
antenna lever arm, Gauss-Markov error, gross errors, outages, rate) and are measured by the same
:mod:`trafficsim.sensors.gnss` model with their own random streams (purposes ``gnss2``,
``gnss2_gross``, ...). ``fusion: {correlation: rho}`` (default 0, in [0, 1)) is the correlation
of any two receivers' errors on that ship (common-mode error). For a ship with more than one
receiver, each fix is moved to the reference point with the filter's heading [seed 003, eq 5] and
the fixes of this step are fused by the minimum-variance weight matrices with cross-covariances
[seed 003, eqs 2-4] (:func:`trafficsim.estimation.fusion.fuse`; the receivers' ``sigma_m`` give
the covariances, a Gauss-Markov part is not modelled, as for one receiver). The filter then sees
the fused fix with its covariance ``P_f``: the ekf uses ``P_f`` as the GNSS block of ``R``, the
pv filter its per-axis variance as the measurement variance of the step (``P_f = p I`` exactly,
because the receivers are isotropic and the correlation one scalar); the gates use the same.
A receiver without a fix this step drops out of the fusion; with no fix from any receiver the
filter only predicts. ``gnss`` stays receiver 1 (``Navigation.fix`` is its reading);
``Navigation.fused`` is the last fused fix of the ships with several receivers.

Adaptive GNSS noise (``ekf`` only): ``navigation: {adaptive_window_steps: N}`` turns on the
innovation-based estimate of the GNSS measurement covariance over the last ``N`` update steps
(:mod:`trafficsim.estimation.adaptive`, the adaptive filtering idea of [seed 004]); once
``adaptive_min_samples`` (default ``N // 2``, at least 3) accepted fixes are in the window the
estimate replaces the configured (or fused) GNSS block of ``R`` in the gate and the update.
``adaptive_floor_sigma_m`` (default 0.1 m) bounds it from below. Default: off.

Ships without these keys run exactly the code path, and produce bit for bit the results, they had
before the keys existed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.estimation import adaptive, ekf, fusion, gating, pv
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
#: further GNSS receivers a ship may carry, in their fusion slot order after ``gnss`` (slot 0);
#: each has the noise purposes ``<name>`` and ``<name>_gross`` in :data:`trafficsim.noise.PURPOSES`
EXTRA_GNSS = ("gnss2", "gnss3")
SENSOR_KEYS = ("gnss", "compass", "log", "actuators", "waves", "gate", "navigation", "ekf",
               "radar", "ais", "tracker", *EXTRA_GNSS, "fusion")
#: keys of the ``navigation`` section
NAVIGATION_KEYS = ("pv_sp_m2ps3", "heading_sp_rad2ps3", "adaptive_window_steps",
                   "adaptive_min_samples", "adaptive_floor_sigma_m")
#: keys of the ``fusion`` section
FUSION_KEYS = ("correlation",)
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
    # filter "none": every instrument and setting is built and checked; whether a setting suits
    # the ship's filter (adaptive R needs the ekf) is checked when the run starts
    Navigation.build([dict(config)], ["none"], np.zeros((8, 1)), 0, [0], [0], 1.0)
    from trafficsim.estimation import tracker
    from trafficsim.sensors import ais, radar

    for name, module in (("radar", radar), ("ais", ais), ("tracker", tracker)):
        if config.get(name) is not None:
            module.build([dict(config[name])])


@dataclass
class ExtraReceiver:
    """A further GNSS receiver (``gnss2``, ...) on the ships that carry it.

    ``idx`` ``(k,)``: those ships' indices in the batch; ``rows`` ``(k,)``: their rows in the
    fusion tables (:attr:`Navigation.multi_idx`); ``slot``: its fusion slot (1, 2, ...).
    """

    name: str
    idx: np.ndarray
    rows: np.ndarray
    slot: int
    params: gnss.GnssParams
    state: gnss.GnssState
    normals: NoiseBank
    uniforms: NoiseBank
    fix: gnss.GnssFix | None = None


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
    ekf_qc: np.ndarray | None = None  # process noise density of the ekf ships (formed once)
    has_waves: bool = False
    has_log: bool = False
    has_actuator_sensors: bool = False
    fix: gnss.GnssFix | None = None
    heading_meas: np.ndarray | None = None
    log_meas: speed_log.LogReading | None = None
    act_meas: actuators.ActuatorReading | None = None
    # several receivers (empty / None when no ship has gnss2, ...)
    extra: list[ExtraReceiver] = field(default_factory=list)
    multi_idx: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fusion_p: fusion.FusionParams | None = None  # (m, k) tables of the ships in multi_idx
    fusion_sigma: np.ndarray | None = None  # (m, 2k, 2k) joint covariance of their fixes, m2
    fusion_var: np.ndarray | None = None  # (m,) per-axis variance of the fix of all receivers
    receiver_fixes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (m, k) N, E, valid
    fused: fusion.Fused | None = None  # last fused fix of the ships in multi_idx
    ekf_multi: np.ndarray | None = None  # rows of ekf_idx with several receivers
    ekf_multi_rows: np.ndarray | None = None  # ... and their rows in multi_idx
    # adaptive GNSS noise of the ekf (None when no ship uses it)
    adapt_rows: np.ndarray | None = None  # rows of ekf_idx with adaptive R
    adapt_p: adaptive.AdaptiveParams | None = None
    adapt_s: adaptive.AdaptiveState | None = None
    ekf_innovation: ekf.Innovation | None = None  # last ekf update's innovations (diagnostic)

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
            unknown = set(c) - set(NAVIGATION_KEYS)
            if unknown:
                raise InputError(f"unknown key(s) {sorted(unknown)}; expected some of "
                                 f"{', '.join(NAVIGATION_KEYS)}", key="navigation")
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
        multi = _Receivers.build(configs, gnss_p, dt, seed, encounter, ship_in_encounter)
        pv_sigma = gnss_p.sigma_m
        if multi.idx.size:  # the filter starts converged for the fix of all receivers
            pv_sigma = pv_sigma.copy()
            pv_sigma[multi.idx] = np.sqrt(multi.var)
        pv_p = pv.build([{"sigma_m": s, "sp_m2ps3": c.get("pv_sp_m2ps3", DEFAULT_PV_SP),
                          "dt_s": dt} for s, c in zip(pv_sigma, nav_cfg, strict=True)])
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
        adapt_cfg = _adaptive_configs(nav_cfg)
        for i, (f, c) in enumerate(zip(filters, adapt_cfg, strict=True)):
            if c is not None and f == "pv":
                raise InputError(f"ship {i}: adaptive_window_steps needs filter: ekf",
                                 key="navigation")
        adapt_rows = adapt_p = adapt_s = None
        rows = [j for j, i in enumerate(ekf_idx) if adapt_cfg[i] is not None]
        if rows:
            adapt_rows = np.array(rows, dtype=np.int64)
            adapt_p = adaptive.build([adapt_cfg[ekf_idx[j]] for j in rows], "gnss")
            adapt_s = adaptive.start(adapt_p, np.eye(2)[None] * ekf_p.gnss_var_m2[adapt_rows,
                                                                                None, None])
        ekf_multi = np.flatnonzero(np.isin(ekf_idx, multi.idx))
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
            has_actuator_sensors=any(c.get("actuators") is not None for c in configs),
            extra=multi.extra, multi_idx=multi.idx, fusion_p=multi.params,
            fusion_sigma=multi.sigma, fusion_var=multi.var,
            ekf_multi=ekf_multi if ekf_multi.size else None,
            ekf_multi_rows=np.searchsorted(multi.idx, ekf_idx[ekf_multi]),
            adapt_rows=adapt_rows, adapt_p=adapt_p, adapt_s=adapt_s)

    def update(self, x: np.ndarray, env: Env) -> np.ndarray:
        """Measure the true state ``x`` ``(8, n)``, update the filters; returns ``est`` (6, n)."""
        wave_psi = wave_ne = None
        if self.has_waves:
            self.waves_s = waves.step(self.waves_p, self.waves_s, self.banks["waves"].next())
            wave_psi = waves.heading_offset(self.waves_p, self.waves_s)
            wave_ne = waves.position_offset(self.waves_p, self.waves_s, x[PSI])
        self.gnss_s, self.fix = gnss.step(self.gnss_p, self.gnss_s, x, self.banks["gnss"].next(),
                                          self.banks["gnss_gross"].next(), wave_ne, wave_psi)
        if self.extra:
            self._measure_extra_receivers(x, wave_ne, wave_psi)
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
        fix_valid, pv_p = self.fix.valid, self.pv_p
        if self.multi_idx.size:  # several receivers: the fused fix and its variance
            mi = self.multi_idx
            self.fused = self._fuse(np.arange(mi.size), psi_new[mi])
            ref_n, ref_e, fix_valid = ref_n.copy(), ref_e.copy(), fix_valid.copy()
            ref_n[mi], ref_e[mi] = self.fused.position[:, 0], self.fused.position[:, 1]
            fix_valid[mi] = self.fused.valid
            sigma = pv_p.sigma_m.copy()
            sigma[mi] = np.sqrt(self._fused_variance(self.fused, np.arange(mi.size)))
            pv_p = replace(pv_p, sigma_m=sigma)
        pred = pv.predict(pv_p, self.pv_s)
        innov = np.stack([ref_n - pred.x[:, 0], ref_e - pred.x[:, 1]], axis=1)
        s_innov = pred.P[:, :, 0, 0] + (pv_p.sigma_m ** 2)[:, None]
        d = np.where(fix_valid, gating.normalised_distance(innov, s_innov), np.nan)
        g = gating.gate(self.gate_p, d, self.gate_rejections)
        self.gate_rejections = g.rejections
        self.pv_s = pv.update(pv_p, pred, np.nan_to_num(ref_n), np.nan_to_num(ref_e),
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
        if self.ekf_qc is None:
            self.ekf_qc = ekf.process_noise_density(self.ekf_p)
        pred = ekf.predict(self.ekf_p, self.ekf_model, self.ekf_s, rudder, rps, self.dt,
                           wind_speed_mps=wind[0], wind_from_rad=wind[1],
                           process_noise=self.ekf_qc)
        dn, de = rotate_body_to_earth(pred.x[:, 2], self.gnss_p.antenna_x_m[i],
                                      self.gnss_p.antenna_y_m[i])
        z = np.stack([self.fix.north_m[i] - dn, self.fix.east_m[i] - de, self.heading_meas[i],
                      self.log_meas.u_mps[i] if self.log_meas is not None
                      else np.zeros(i.size)], axis=1)
        valid = self.fix.valid[i]
        gnss_cov = None  # (k, 2, 2) GNSS block of R when it is not the configured one
        if self.ekf_multi is not None:  # several receivers: the fused fix and its covariance
            em = self.ekf_multi
            fused = self._fuse(self.ekf_multi_rows, pred.x[em, 2])
            z[em, 0], z[em, 1] = fused.position[:, 0], fused.position[:, 1]
            valid = valid.copy()
            valid[em] = fused.valid
            gnss_cov = np.eye(2)[None] * self.ekf_p.gnss_var_m2[:, None, None]
            # no fix from any receiver: no update; any finite covariance keeps R invertible
            gnss_cov[em] = np.where(fused.valid[:, None, None], fused.cov, np.eye(2)[None]
                                    * self.fusion_var[self.ekf_multi_rows, None, None])
        if self.adapt_rows is not None:  # adapted R where its window holds enough fixes
            ready = self.adapt_s.count >= self.adapt_p.min_samples
            if ready.any():
                if gnss_cov is None:
                    gnss_cov = np.eye(2)[None] * self.ekf_p.gnss_var_m2[:, None, None]
                gnss_cov[self.adapt_rows[ready]] = self.adapt_s.R[ready]
        innov = z[:, :2] - pred.x[:, :2]
        if gnss_cov is None:
            s_pos = pred.P[:, :2, :2] + np.eye(2)[None] * self.ekf_p.gnss_var_m2[:, None, None]
            R_meas = None
        else:
            s_pos = pred.P[:, :2, :2] + gnss_cov
            R_meas = ekf.measurement_covariance(self.ekf_p, gnss_cov_m2=gnss_cov)
        d = np.where(valid, gating.normalised_distance(innov, s_pos), np.nan)
        g = gating.gate(_take_gate(self.gate_p, i), d, self.ekf_rejections)
        self.ekf_rejections = g.rejections
        mask = np.stack([g.accept, g.accept, np.ones(i.size, bool),
                         np.full(i.size, self.log_meas is not None)], axis=1)
        state, self.ekf_innovation = ekf.update(self.ekf_p, pred, np.nan_to_num(z), mask, R_meas)
        if self.adapt_rows is not None:
            nu, hph, ok = adaptive.innovation_group(self.ekf_innovation.nu,
                                                    self.ekf_innovation.hph, mask,
                                                    (ekf.ZN, ekf.ZE))
            a = self.adapt_rows
            self.adapt_s = adaptive.step(self.adapt_p, self.adapt_s, nu[a], hph[a], ok[a])
        if g.restart.any():  # genuine jump: restart the position on the fix
            xs = state.x.copy()
            xs[g.restart, 0], xs[g.restart, 1] = z[g.restart, 0], z[g.restart, 1]
            state = ekf.EkfState(xs, state.P)
        self.ekf_s = state
        return state.x[:, :N_EST].T

    def _measure_extra_receivers(self, x: np.ndarray, wave_ne: np.ndarray | None,
                                 wave_psi: np.ndarray | None) -> None:
        """Step ``gnss2``, ... on the ships carrying them; collect every receiver's antenna fix
        of the ships with several receivers into :attr:`receiver_fixes` ``(m, k)``."""
        mi = self.multi_idx
        m, k = self.fusion_p.sigma_m.shape
        north, east = np.full((m, k), np.nan), np.full((m, k), np.nan)
        valid = np.zeros((m, k), dtype=bool)
        north[:, 0], east[:, 0], valid[:, 0] = (self.fix.north_m[mi], self.fix.east_m[mi],
                                                self.fix.valid[mi])
        for rec in self.extra:  # one vectorised step per receiver name, not per ship
            j = rec.idx
            rec.state, rec.fix = gnss.step(
                rec.params, rec.state, x[:, j], rec.normals.next(), rec.uniforms.next(),
                None if wave_ne is None else wave_ne[:, j],
                None if wave_psi is None else wave_psi[j])
            north[rec.rows, rec.slot], east[rec.rows, rec.slot] = rec.fix.north_m, rec.fix.east_m
            valid[rec.rows, rec.slot] = rec.fix.valid
        self.receiver_fixes = north, east, valid

    def _fuse(self, rows: np.ndarray, heading: np.ndarray) -> fusion.Fused:
        """Fused fix at the reference point of the ships ``multi_idx[rows]``, moved with
        ``heading`` ``(len(rows),)`` rad [seed 003, eqs 2-5]."""
        north, east, valid = self.receiver_fixes
        p = self.fusion_p
        ref_n, ref_e = fusion.to_reference_point(north[rows], east[rows], heading[:, None],
                                                 p.offset_x_m[rows], p.offset_y_m[rows])
        return fusion.fuse(np.stack([ref_n, ref_e], axis=-1), self.fusion_sigma[rows],
                           valid[rows] & p.present[rows])

    def _fused_variance(self, fused: fusion.Fused, rows: np.ndarray) -> np.ndarray:
        """Per-axis variance (m2, ``(len(rows),)``) of a fused fix: ``P_f = p I`` for isotropic
        receivers; without any fix (no update) the all-receiver value keeps the algebra finite."""
        var = 0.5 * (fused.cov[:, 0, 0] + fused.cov[:, 1, 1])
        return np.where(fused.valid, var, self.fusion_var[rows])


@dataclass
class _Receivers:
    """The further receivers of a batch and the fusion tables of the ships carrying any."""

    extra: list[ExtraReceiver]
    idx: np.ndarray  # (m,) ships with several receivers
    params: fusion.FusionParams | None
    sigma: np.ndarray | None  # (m, 2k, 2k) joint covariance, m2
    var: np.ndarray  # (m,) per-axis variance of the fusion of all receivers, m2

    @classmethod
    def build(cls, configs: Sequence[Mapping[str, Any]], gnss_p: gnss.GnssParams, dt: float,
              seed: int, encounter: Sequence[int], ship_in_encounter: Sequence[int]
              ) -> _Receivers:
        for c in configs:
            fcfg = c.get("fusion")
            if fcfg is None:
                continue
            unknown = set(fcfg) - set(FUSION_KEYS)
            if unknown:
                raise InputError(f"unknown key(s) {sorted(unknown)}; expected "
                                 f"{', '.join(FUSION_KEYS)}", key="fusion")
            if not any(name in c for name in EXTRA_GNSS):
                raise InputError("fusion needs a second receiver (gnss2)", key="fusion")
        has = np.array([[name in c for name in EXTRA_GNSS] for c in configs],
                       dtype=bool).reshape(len(configs), len(EXTRA_GNSS))
        idx = np.flatnonzero(has.any(axis=1))
        if not idx.size:
            return cls([], idx, None, None, np.zeros(0))
        names = [name for j, name in enumerate(EXTRA_GNSS) if has[:, j].any()]
        m, k = idx.size, 1 + len(names)
        sigma, ox, oy = np.ones((m, k)), np.zeros((m, k)), np.zeros((m, k))
        present = np.zeros((m, k), dtype=bool)
        # offsets of fusion are antenna -> reference point, the antenna's position negated
        sigma[:, 0], present[:, 0] = gnss_p.sigma_m[idx], True
        ox[:, 0], oy[:, 0] = -gnss_p.antenna_x_m[idx], -gnss_p.antenna_y_m[idx]
        enc, sie = np.asarray(encounter), np.asarray(ship_in_encounter)
        extra = []
        for slot, name in enumerate(names, start=1):
            ships = np.flatnonzero(has[:, EXTRA_GNSS.index(name)])
            try:
                params = gnss.build([dict(configs[i].get(name) or {}) for i in ships], dt)
            except InputError as err:  # the gnss module names its section "gnss"
                raise InputError(err.message, key=(err.key or "gnss").replace(
                    "gnss", name, 1)) from None
            normals = NoiseBank(seed, enc[ships], sie[ships], name, gnss.GNSS_NORMAL_DIMS)
            uniforms = NoiseBank(seed, enc[ships], sie[ships], f"{name}_gross",
                                 gnss.GNSS_UNIFORM_DIMS, "uniform")
            # the receiver's own stream starts it (the shared "initial" stream is left as is)
            state = gnss.init(params, normals.next())
            rows = np.searchsorted(idx, ships)
            sigma[rows, slot], present[rows, slot] = params.sigma_m, True
            ox[rows, slot], oy[rows, slot] = -params.antenna_x_m, -params.antenna_y_m
            extra.append(ExtraReceiver(name, ships, rows, slot, params, state, normals,
                                       uniforms))
        for slot, name in enumerate(("gnss", *names)):  # the fusion weighs by 1 / sigma^2
            if np.any(sigma[present[:, slot], slot] <= 0.0):
                raise InputError("each receiver of a ship with several needs sigma_m > 0",
                                 key=name)
        rho = np.array([float((configs[i].get("fusion") or {}).get("correlation", 0.0))
                        for i in idx])
        if np.any(~np.isfinite(rho) | (rho < 0.0) | (rho >= 1.0)):
            raise InputError("correlation must be in [0, 1)", key="fusion")
        params = fusion.FusionParams(sigma, ox, oy, present, rho)
        joint = fusion.joint_covariance(fusion.receiver_covariance(params), rho)
        full = fusion.fuse(np.zeros((m, k, 2)), joint, present)
        var = 0.5 * (full.cov[:, 0, 0] + full.cov[:, 1, 1])
        return cls(extra, idx, params, joint, var)


def _adaptive_configs(nav_cfg: Sequence[Mapping[str, Any]]) -> list[dict[str, Any] | None]:
    """Per ship the settings of :func:`trafficsim.estimation.adaptive.build` from the
    ``adaptive_*`` keys of ``navigation`` (None: adaptive R off), checked."""
    out: list[dict[str, Any] | None] = []
    for i, c in enumerate(nav_cfg):
        cfg = {key[len("adaptive_"):]: value for key, value in c.items()
               if key.startswith("adaptive_")}
        if cfg and "window_steps" not in cfg:
            raise InputError(f"ship {i}: adaptive_* keys need adaptive_window_steps",
                             key="navigation")
        if cfg:
            try:
                adaptive.build([cfg], "gnss")
            except (ValueError, TypeError) as err:  # its messages name the keys unprefixed
                raise InputError(f"adaptive settings: {err}", key="navigation") from None
        out.append(cfg or None)
    return out


def _earth_velocity(x: np.ndarray) -> np.ndarray:
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    return np.stack([x[U] * c - x[V] * s, x[U] * s + x[V] * c])


def _take(value: Any, idx: np.ndarray) -> Any:
    return value[idx] if isinstance(value, np.ndarray) and value.ndim else value


def _take_gate(params: gating.GateParams, idx: np.ndarray) -> gating.GateParams:
    return gating.GateParams(params.threshold[idx], params.reopen_factor[idx],
                             params.max_rejections[idx])
