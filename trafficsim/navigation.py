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
  rudder and rpm, updated with the GNSS fix, the compass and (if fitted) a speed log through the
  water (a log over ground, Doppler bottom track, is not used: the filter's log measures the
  surge through the water, and taking the one for the other would pull the current estimate
  towards zero); its noise settings default to the instruments' (``ekf:`` overrides any of
  them).

In both filters gross GNSS errors are
  gated [seed 002, 6.6] (``gate``: on the normalised innovation, ``gate_sigma`` standard
  deviations, default 5; or, with ``window_diameter_m`` and no ``gate_sigma``, on the fix's
  distance from the prediction, the thesis' window; ``reopen_factor``, ``max_rejections``,
  :mod:`trafficsim.estimation.gating`); after several consecutive rejections the filter restarts
  on the fix.

Instruments (``sensors:`` of the ship file, overridden key by key by the scenario): ``gnss``,
``compass``, ``log``, ``actuators`` (rudder and rpm feedback) and ``waves`` (wave-frequency
motion seen by GNSS and compass), each as documented in its module under
:mod:`trafficsim.sensors`. Random draws come from keyed streams (:mod:`trafficsim.noise`).
Every setting has physical bounds (each module gives them and their reasons; here the
``navigation`` spectral densities, :data:`MAX_PV_SP` and :data:`MAX_HEADING_SP`), and where the
ship file is known the GNSS and radar antennas and the log's transducer must lie on board
(:func:`check_on_board`).

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

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.estimation import adaptive, ekf, fusion, gating, pv
from trafficsim.geometry import cos_sin
from trafficsim.jit import kernel
from trafficsim.noise import NoiseBank, normal_from, uniform_from
from trafficsim.sensors import (
    actuators,
    check_keys,
    column,
    compass,
    gnss,
    mod_2pi_scalar,
    rotate_body_to_earth,
    speed_log,
    waves,
    wrap_2pi_scalar,
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
#: largest S_p, m^2/s^3: a filter that passes 2 m fixes through at 1 s steps (tracking index
#: sqrt(S_p dt^3) / sigma = 50; far beyond, its covariance overflows), the top of ``trafficsim
#: trial --sp``; seed 000 tries 0.001-0.1. The ``gnss_lag`` effect's shortest lag, 0.2 s, needs
#: 2500 at those fixes and steps (:func:`trafficsim.effects.pv_sp`)
MAX_PV_SP = 10_000
#: largest heading-filter spectral density, rad^2/s^3: the same tracking index 50 for a 1 deg
#: compass at 1 s steps (0.76; a ship's yaw acceleration stays below 0.1 rad/s^2)
MAX_HEADING_SP = 1
#: the sections and keys of instruments fitted at a body position, checked against the hull
LEVER_KEYS = {**{name: ("antenna_x_m", "antenna_y_m") for name in ("gnss", *EXTRA_GNSS, "radar")},
              "log": ("lever_x_m", "lever_y_m")}


def merge_sensors(ship_defaults: Mapping[str, Any] | None,
                  overrides: Mapping[str, Any] | None) -> dict[str, dict[str, Any]]:
    """Sensor configs of one ship: the ship file's, overridden key by key by the scenario's."""
    out: dict[str, dict[str, Any]] = {k: dict(v or {}) for k, v in (ship_defaults or {}).items()}
    for name, cfg in (overrides or {}).items():
        out.setdefault(name, {}).update(cfg or {})
    return out


def _gate_params(configs: Sequence[Mapping[str, Any]]) -> gating.GateParams:
    """The ships' gates, a bad one an input error: a position window where
    ``window_diameter_m`` is given, else ``gate_sigma`` (default :data:`DEFAULT_GATE_SIGMA`);
    unknown keys, and both windows at once, are refused."""
    check_keys([c or {} for c in configs], gating.KEYS, "gate")
    for i, c in enumerate(configs):
        if c and "window_diameter_m" in c and "gate_sigma" in c:
            raise InputError("give either window_diameter_m (a position window) or gate_sigma "
                             "(a window on the normalised innovation), not both",
                             key=f"gate[{i}]")
    try:
        return gating.build([c if c and "window_diameter_m" in c
                             else {"gate_sigma": DEFAULT_GATE_SIGMA, **(c or {})}
                             for c in configs])
    except (TypeError, ValueError) as err:
        raise InputError(str(err), key="gate") from None


def check_sensor_config(config: Mapping[str, Any], filter_name: str = "none",
                        spec: Mapping[str, Any] | None = None) -> None:
    """Raise :class:`InputError` (with the offending key) if a ship's sensor config is invalid;
    with ``filter_name`` (and the ship file ``spec`` for the ekf) also what suits that filter."""
    for name in config:
        if name not in SENSOR_KEYS:
            raise InputError(f"unknown sensor '{name}'; expected one of {', '.join(SENSOR_KEYS)}",
                             key=name)
    # filter "none": every instrument and setting is built and checked; whether a setting suits
    # the ship's filter (adaptive R needs the ekf) is checked when the run starts
    Navigation.build([dict(config)], [filter_name], np.zeros((8, 1)), 0, [0], [0], 1.0,
                     None if spec is None else [spec])
    if config.get("ekf") is not None:  # (built for ekf ships only when a run starts)
        try:
            ekf.build([{"gnss_sigma_m": 1.0, "compass_sigma_deg": 1.0, "log_sigma_mps": 0.1,
                        **dict(config["ekf"])}])
        except (TypeError, ValueError) as err:
            raise InputError(str(err), key="ekf") from None
    from trafficsim.estimation import tracker
    from trafficsim.sensors import ais, radar

    for name, module in (("radar", radar), ("ais", ais), ("tracker", tracker)):
        if config.get(name) is not None:
            module.build([dict(config[name])])
    if spec is not None:
        check_on_board(config, spec)


def check_on_board(config: Mapping[str, Any], spec: Mapping[str, Any]) -> None:
    """Raise :class:`InputError` naming the key if a GNSS or radar antenna or the speed log's
    transducer lies outside the box of the hull outline, ``|x| <= L/2`` and ``|y| <= B/2``
    from the reference point (:func:`trafficsim.geometry.hull_outlines` spans exactly that),
    with ``L`` and ``B`` the ship file's ``particulars``. The settings must be valid numbers
    already (:func:`check_sensor_config` builds them first)."""
    length = float(spec["particulars"]["length_m"])
    beam = float(spec["particulars"]["beam_m"])
    for name, keys in LEVER_KEYS.items():
        section = config.get(name) or {}
        for key, half in zip(keys, (0.5 * length, 0.5 * beam), strict=True):
            raw = section.get(key)
            value = 0.0 if raw is None else float(raw)
            if abs(value) > half:
                part = "length L" if key.endswith("x_m") else "beam B"
                raise InputError(
                    f"must lie on board, within +-{half:g} m of the reference point (half the "
                    f"{part} of the ship's hull, L = {length:g} m, B = {beam:g} m), got "
                    f"{value:g}", key=f"{name}[0].{key}")


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
    log_fitted: np.ndarray | None = None  # (n,) bool, the ship carries a speed log
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
    _tables: Any = field(default=None, repr=False, compare=False)  # _StepTables, at first step

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
                               + waves.WAVE_NORMAL_DIMS, block_steps=1).next()
        a, b = gnss.GNSS_NORMAL_DIMS, gnss.GNSS_NORMAL_DIMS + compass.COMPASS_NORMAL_DIMS
        multi = _Receivers.build(configs, gnss_p, dt, seed, encounter, ship_in_encounter)
        pv_sigma = gnss_p.sigma_m
        if multi.idx.size:  # the filter starts converged for the fix of all receivers
            pv_sigma = pv_sigma.copy()
            pv_sigma[multi.idx] = np.sqrt(multi.var)
        # (a perfect receiver, sigma 0, is floored as the compass is for its gain below)
        column(nav_cfg, "pv_sp_m2ps3", DEFAULT_PV_SP, "navigation", minimum=0.0, strictly=True,
               maximum=MAX_PV_SP)
        try:
            pv_p = pv.build([{"sigma_m": max(float(s), 1e-6),
                              "sp_m2ps3": c.get("pv_sp_m2ps3", DEFAULT_PV_SP), "dt_s": dt}
                             for s, c in zip(pv_sigma, nav_cfg, strict=True)])
        except InputError as err:
            raise InputError(err.message, key="navigation.pv_sp_m2ps3") from None
        # filters start converged one step before the first fix, so the first update
        # predicts to the time of the first fix
        vel = _earth_velocity(x)
        pv_s = pv.init(pv_p, x[NORTH] - vel[0] * dt, x[EAST] - vel[1] * dt, vel[0], vel[1],
                       converged=True)
        heading_sp = column(nav_cfg, "heading_sp_rad2ps3", DEFAULT_HEADING_SP, "navigation",
                            minimum=0.0, strictly=True, maximum=MAX_HEADING_SP)
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
                raise InputError(f"needs filter: ekf, got filter: {f}",
                                 key=f"navigation[{i}].adaptive_window_steps")
        adapt_rows = adapt_p = adapt_s = None
        rows = [j for j, i in enumerate(ekf_idx) if adapt_cfg[i] is not None]
        if rows:
            adapt_rows = np.array(rows, dtype=np.int64)
            adapt_p = adaptive.build([adapt_cfg[ekf_idx[j]] for j in rows], "gnss")
            adapt_s = adaptive.start(adapt_p, np.eye(2)[None] * ekf_p.gnss_var_m2[adapt_rows,
                                                                                None, None])
        ekf_multi = np.flatnonzero(np.isin(ekf_idx, multi.idx))
        log_fitted = np.array([c.get("log") is not None for c in configs], dtype=bool)
        return cls(
            filter_pv=np.array([f == "pv" for f in filters], dtype=bool),
            gnss_p=gnss_p, gnss_s=gnss.init(gnss_p, init_draws[:, :a]),
            compass_p=compass_p, compass_s=compass.init(compass_p, init_draws[:, a:b]),
            log_p=speed_log.build(section("log")), act_p=actuators.build(section("actuators")),
            waves_p=waves_p, waves_s=waves.init(waves_p, init_draws[:, b:]),
            pv_p=pv_p, pv_s=pv_s, heading_gain=heading_gain,
            gate_p=_gate_params(section("gate")),
            gate_rejections=gating.init_state(n),
            heading_est=np.stack([x[PSI] - x[R] * dt, x[R].copy()]), banks=banks, dt=dt,
            est=est,
            ekf_idx=ekf_idx, ekf_p=ekf_p, ekf_model=ekf_model, ekf_s=ekf_s,
            ekf_rejections=gating.init_state(ekf_idx.size),
            has_waves=any(c.get("waves") for c in configs),
            has_log=bool(log_fitted.any()), log_fitted=log_fitted,
            has_actuator_sensors=any(c.get("actuators") is not None for c in configs),
            extra=multi.extra, multi_idx=multi.idx, fusion_p=multi.params,
            fusion_sigma=multi.sigma, fusion_var=multi.var,
            ekf_multi=ekf_multi if ekf_multi.size else None,
            ekf_multi_rows=np.searchsorted(multi.idx, ekf_idx[ekf_multi]),
            adapt_rows=adapt_rows, adapt_p=adapt_p, adapt_s=adapt_s)

    def update(self, x: np.ndarray, env: Env) -> np.ndarray:
        """Measure the true state ``x`` ``(8, n)``, update the filters; returns ``est`` (6, n).

        The per-ship arithmetic of waves, GNSS, compass, the heading filter and the pv filter
        with its gate runs in two compiled loops over ships (:func:`_sense`, :func:`_pv_filter`)
        on per-ship constants gathered once; the instruments' and filters' memories (``waves_s``,
        ``gnss_s``, ``compass_s``, ``heading_est``, ``pv_s``, ``gate_rejections``) are advanced
        in place, the readings (``fix``, ``heading_meas``) and ``est`` are new arrays every
        step. The optional log and actuator sensors, further receivers, their fusion and the
        ekf keep their vectorised modules.
        """
        t = self._step_tables()
        n = x.shape[1]
        wave_streams, wave_psi, wave_ne = _NO_STREAMS, _NO_ROW, _NO_ROWS
        if self.has_waves:
            wave_streams, wave_psi, wave_ne = self.banks["waves"].state, t.wave_psi, t.wave_ne
        gs, ws, heading = self.gnss_s, self.waves_s, self.heading_est
        valid, gross = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        fix_n, fix_e, heading_meas = np.empty(n), np.empty(n), np.empty(n)
        drift = self.compass_s.drift_rad
        _sense(x, self.dt, self.has_waves, self.gnss_p.has_lever_arm,
               self.compass_p.has_deviation, t.wave, t.gnss, t.arm, t.compass, t.deviation,
               t.every, t.bandpass, ws.z1, ws.z2, wave_streams, gs.counter, gs.up, gs.gm_m,
               gs.last_m, self.banks["gnss"].state, self.banks["gnss_gross"].state, drift,
               self.banks["compass"].state, heading,
               ws.z1, ws.z2, wave_psi, wave_ne, gs.counter, gs.up, gs.gm_m, gs.last_m, fix_n,
               fix_e, valid, gross, drift, heading_meas, heading)
        self.fix = gnss.GnssFix(north_m=fix_n, east_m=fix_e, valid=valid, gross=gross)
        self.heading_meas = heading_meas
        if self.extra:
            self._measure_extra_receivers(x, wave_ne if self.has_waves else None,
                                          wave_psi if self.has_waves else None)
        if self.has_log:  # recorded only: the filters here do not use the log or rudder/rpm
            self.log_meas = speed_log.measure(self.log_p, x, env, self.banks["log"].next())
        if self.has_actuator_sensors:
            self.act_meas = actuators.measure(self.act_p, x, self.banks["actuators"].next())

        # position: the receiver's PV filter on the fix moved to the reference point, or the
        # fused fix (at the reference point already) of the ships with several receivers
        fused_n = fused_e = fused_sigma = _NO_ROW
        fused_valid = _NO_FLAGS
        if self.multi_idx.size:
            rows = np.arange(self.multi_idx.size)
            self.fused = self._fuse(rows, heading[0, self.multi_idx])
            fused_n = np.ascontiguousarray(self.fused.position[:, 0])
            fused_e = np.ascontiguousarray(self.fused.position[:, 1])
            fused_valid = np.ascontiguousarray(self.fused.valid)
            fused_sigma = np.sqrt(self._fused_variance(self.fused, rows))
        est = np.empty((N_EST, n))
        ps = self.pv_s
        _pv_filter(x, self.gnss_p.has_lever_arm, t.arm, t.filt, t.max_rejections,
                   self.filter_pv, t.multi_row, fix_n, fix_e, valid, heading, fused_n, fused_e,
                   fused_valid, fused_sigma, ps.x, ps.P, self.gate_rejections, ps.x, ps.P,
                   self.gate_rejections, est)
        self.est = est
        if self.ekf_idx is not None and self.ekf_idx.size:
            self.est[:, self.ekf_idx] = self._ekf_update(x, env)
        return self.est

    def ground_velocity(self, env: Env) -> np.ndarray:
        """``(2, n)`` each ship's estimate of its velocity over ground at the last
        :meth:`update`, north and east, m/s: the ``pv`` filter's (its ``u, v`` are over
        ground), the ``ekf``'s velocity through the water plus its estimate of the current, the
        truth (``est`` is the true state) plus ``env``'s current without a filter. The pv
        ships' is the filter's velocity state itself (``est``'s ``u, v`` are it turned to the
        body frame)."""
        est = self.est
        vel = self.pv_s.x[:, pv.VEL_N:pv.VEL_E + 1].T.copy()  # (the other ships' replaced)
        none = ~self.filter_pv
        if none.any():
            psi, u, v = est[PSI, none], est[U, none], est[V, none]
            c, s = np.cos(psi), np.sin(psi)
            vel[0, none], vel[1, none] = u * c - v * s, u * s + v * c
        if self.ekf_idx is not None and self.ekf_idx.size:
            none[self.ekf_idx] = False
            vel[0, self.ekf_idx] += self.ekf_s.x[:, ekf.XCN]
            vel[1, self.ekf_idx] += self.ekf_s.x[:, ekf.XCE]
        vel[0, none] += _take(env.current_north_mps, none)
        vel[1, none] += _take(env.current_east_mps, none)
        return vel

    def _step_tables(self) -> _StepTables:
        """Per-ship constants of the compiled step, gathered once (again only if a parameter
        set is replaced)."""
        key = (self.gnss_p, self.compass_p, self.waves_p, self.pv_p, self.gate_p,
               self.heading_gain, self.multi_idx)
        tables = self._tables
        if tables is None or len(tables.key) != len(key) or any(
                a is not b for a, b in zip(tables.key, key, strict=True)):
            tables = self._tables = _StepTables.gather(self, key)
        return tables

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
        gate_p = _take_gate(self.gate_p, i)
        d = np.where(gate_p.metres, gating.distance(innov),
                     gating.normalised_distance(innov, s_pos))
        d = np.where(valid, d, np.nan)
        g = gating.gate(gate_p, d, self.ekf_rejections)
        self.ekf_rejections = g.rejections
        # the log only on the ships that carry one through the water (another ship's log must
        # not count; a log over ground measures something else, module docstring)
        with_log = (self.log_fitted[i] & ~self.log_p.ground[i] if self.log_meas is not None
                    else np.zeros(i.size, bool))
        mask = np.stack([g.accept, g.accept, np.ones(i.size, bool), with_log], axis=1)
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



# columns of the per-ship tables of _StepTables (one short row per ship and instrument, so a
# ship's constants of one instrument share a cache line and absent parts are never read)
_W11, _W12, _W21, _W22, _WL11, _WL21, _WL22, _WG_YAW, _WG_SURGE, _WG_SWAY = range(10)
if (_WG_SURGE - _WG_YAW, _WG_SWAY - _WG_YAW) != (waves.SURGE, waves.SWAY):
    raise ImportError("the wave gain columns must follow the channel order")
_G_SIGMA, _G_GM_A, _G_GM_Q, _G_GROSS_P, _G_GROSS_M, _G_P_START, _G_P_END = range(7)
_C_SIGMA, _C_BIAS, _C_DRIFT_A, _C_DRIFT_Q, _H_ALPHA, _H_BETA = range(6)
_F_SIGMA, _F_SP, _F_DT, _F_THRESHOLD, _F_REOPEN, _F_METRES = range(6)
# stand-ins for the arrays of an absent part (never indexed)
_NO_STREAMS = np.zeros((0, 4), dtype=np.uint64)
_NO_ROW = np.zeros(0)
_NO_ROWS = np.zeros((2, 0))
_NO_FLAGS = np.zeros(0, dtype=bool)
_TWO_PI = 2.0 * math.pi


@dataclass
class _StepTables:
    """Per-ship constants of :func:`_sense` and :func:`_pv_filter`, one row per ship."""

    key: tuple[Any, ...]  # the parameter objects they were gathered from
    wave: np.ndarray  # (n, 10) transition, noise factor and gains (_W*)
    gnss: np.ndarray  # (n, 7) receiver 1 (_G_*)
    arm: np.ndarray  # (n, 2) antenna lever arm x, y, m
    compass: np.ndarray  # (n, 6) compass and heading filter (_C_*, _H_*)
    deviation: np.ndarray  # (n, 5) deviation coefficients A..E, rad
    filt: np.ndarray  # (n, 5) pv filter and gate (_F_*)
    every: np.ndarray  # (n,) int64 GNSS fix interval, steps
    bandpass: np.ndarray  # (n,) bool wave output z2 (else z1)
    max_rejections: np.ndarray  # (n,) int64
    multi_row: np.ndarray  # (n,) int64 row in multi_idx, -1 for one receiver
    wave_psi: np.ndarray  # (n,) scratch: wave-induced yaw of this step, rad
    wave_ne: np.ndarray  # (2, n) scratch: wave-induced displacement north, east, m

    @classmethod
    def gather(cls, nav: Navigation, key: tuple[Any, ...]) -> _StepTables:
        g, c, w, p, gate = nav.gnss_p, nav.compass_p, nav.waves_p, nav.pv_p, nav.gate_p
        n = g.sigma_m.shape[0]

        def table(*columns: np.ndarray) -> np.ndarray:
            return np.ascontiguousarray(np.stack([np.reshape(v, n) for v in columns], axis=1),
                                        dtype=float)

        multi_row = np.full(n, -1, dtype=np.int64)
        multi_row[nav.multi_idx] = np.arange(nav.multi_idx.size)
        return cls(
            key=key,
            wave=table(w.phi11, w.phi12, w.phi21, w.phi22, w.l11, w.l21, w.l22,
                       w.gain[:, waves.YAW], w.gain[:, waves.SURGE], w.gain[:, waves.SWAY]),
            gnss=table(g.sigma_m, g.gm_a, g.gm_q, g.gross_prob, g.gross_size_m, g.p_start,
                       g.p_end),
            arm=table(g.antenna_x_m, g.antenna_y_m),
            compass=table(c.sigma_rad, c.bias_rad, c.drift_a, c.drift_q, nav.heading_gain[:, 0],
                          nav.heading_gain[:, 1]),
            deviation=table(c.dev_a, c.dev_b, c.dev_c, c.dev_d, c.dev_e),
            filt=table(p.sigma_m, p.sp, p.dt_s, gate.threshold, gate.reopen_factor,
                       gate.metres),
            every=np.ascontiguousarray(g.every, dtype=np.int64),
            bandpass=np.ascontiguousarray(np.reshape(w.bandpass, n), dtype=bool),
            max_rejections=np.ascontiguousarray(gate.max_rejections, dtype=np.int64),
            multi_row=multi_row, wave_psi=np.empty(n), wave_ne=np.empty((2, n)))


@kernel
def _sense(x: np.ndarray, dt: float, has_waves: bool, lever: bool, deviation: bool,
           wtab: np.ndarray, gtab: np.ndarray, arm: np.ndarray, ctab: np.ndarray,
           dev: np.ndarray, every: np.ndarray, bandpass: np.ndarray, z1: np.ndarray,
           z2: np.ndarray, wave_streams: np.ndarray, counter0: np.ndarray, up0: np.ndarray,
           gm0: np.ndarray, last0: np.ndarray, gnss_streams: np.ndarray,
           gross_streams: np.ndarray, drift0: np.ndarray, compass_streams: np.ndarray,
           heading0: np.ndarray,
           z1_out: np.ndarray, z2_out: np.ndarray, wave_psi: np.ndarray, wave_ne: np.ndarray,
           counter: np.ndarray, up: np.ndarray, gm: np.ndarray, last: np.ndarray,
           fix_n: np.ndarray, fix_e: np.ndarray, valid: np.ndarray, gross: np.ndarray,
           drift: np.ndarray, heading_meas: np.ndarray, heading: np.ndarray) -> None:
    """One step of waves, GNSS receiver 1, compass and the compass heading filter, per ship.

    The arithmetic, in the same order, of :func:`trafficsim.sensors.waves.step`,
    :func:`~trafficsim.sensors.waves.heading_offset`,
    :func:`~trafficsim.sensors.waves.position_offset`, :func:`trafficsim.sensors.gnss.step`,
    :func:`trafficsim.sensors.compass.step` and the alpha-beta heading filter of
    :class:`Navigation` (steady-state gain of :func:`trafficsim.estimation.pv.steady_state_gain`
    [seed 000, eq 5]). ``x`` ``(8, n)`` truth; ``wtab`` ... ``dev`` the constants of
    :class:`_StepTables`; state
    arrays ``*0`` in, the new ones and the readings out (shapes of the modules' states);
    ``heading0``/``heading`` ``(2, n)`` heading (rad) and yaw rate (rad/s) estimates.

    Draws, at need, straight from each ship's streams (``*_streams`` ``(n, 4)``, advanced in
    place): ``waves`` two normals per channel whose output is on (non-zero sigma) where the
    ship's sea is on (the state of a channel without output decays undriven);
    ``gnss_gross`` a uniform for the outage chain (where outages start or one
    is on), one for the gross-error test (valid fixes, ``gross_prob > 0``) and one for a gross
    error's direction; ``gnss`` the Gauss-Markov error's two normals (where it is on), then the
    white noise's two (valid fixes); ``compass`` the drift's normal (where on), then the white
    noise's.
    """
    for i in range(x.shape[1]):
        psi = x[PSI, i]
        wpsi = wn = we = 0.0
        if has_waves:  # z <- Phi z + L e per channel, then the outputs [seed 004, eqs 16-17]
            driven = wtab[i, _WL11] != 0.0 or wtab[i, _WL21] != 0.0 or wtab[i, _WL22] != 0.0
            for j in range(waves.N_CHANNELS):
                e1 = e2 = 0.0
                if driven and wtab[i, _WG_YAW + j] != 0.0:  # (a channel without gain: no output)
                    e1 = normal_from(wave_streams, i)
                    e2 = normal_from(wave_streams, i)
                a1, a2 = z1[i, j], z2[i, j]
                z1_out[i, j] = wtab[i, _W11] * a1 + wtab[i, _W12] * a2 + wtab[i, _WL11] * e1
                z2_out[i, j] = (wtab[i, _W21] * a1 + wtab[i, _W22] * a2 + wtab[i, _WL21] * e1
                                + wtab[i, _WL22] * e2)
            zz = z2_out if bandpass[i] else z1_out
            wpsi = wtab[i, _WG_YAW] * zz[i, waves.YAW]
            surge = wtab[i, _WG_SURGE] * zz[i, waves.SURGE]
            sway = wtab[i, _WG_SWAY] * zz[i, waves.SWAY]
            c, s = cos_sin(psi)
            wn, we = surge * c - sway * s, surge * s + sway * c
            wave_psi[i], wave_ne[0, i], wave_ne[1, i] = wpsi, wn, we
        hull = psi + wpsi if has_waves else psi
        c_hull = s_hull = 0.0
        if lever or deviation:  # one cos and sin of the hull heading for both
            c_hull, s_hull = cos_sin(hull)

        # GNSS: outage chain, Gauss-Markov error, gross error, antenna with its lever arm
        if up0[i]:  # the outage chain moves only where outages start (or one is on)
            up_i = gtab[i, _G_P_START] <= 0.0 or uniform_from(gross_streams, i) >= gtab[
                i, _G_P_START]
        else:
            up_i = uniform_from(gross_streams, i) < gtab[i, _G_P_END]
        valid_i = counter0[i] == 0 and up_i
        gm_q = gtab[i, _G_GM_Q]
        gm_n, gm_e = gtab[i, _G_GM_A] * gm0[i, 0], gtab[i, _G_GM_A] * gm0[i, 1]
        if gm_q != 0.0:
            gm_n = gm_n + gm_q * normal_from(gnss_streams, i)
            gm_e = gm_e + gm_q * normal_from(gnss_streams, i)
        sigma = gtab[i, _G_SIGMA]
        white_n = white_e = 0.0
        if valid_i and sigma != 0.0:
            white_n = sigma * normal_from(gnss_streams, i)
            white_e = sigma * normal_from(gnss_streams, i)
        gross_i = (valid_i and gtab[i, _G_GROSS_P] > 0.0
                   and uniform_from(gross_streams, i) < gtab[i, _G_GROSS_P])
        jump = gtab[i, _G_GROSS_M] if gross_i else 0.0
        north, east = x[NORTH, i], x[EAST, i]
        if lever:  # p + R(psi) r_a [seed 003, eq 5]
            ax, ay = arm[i, 0], arm[i, 1]
            north = north + (ax * c_hull - ay * s_hull)
            east = east + (ax * s_hull + ay * c_hull)
        if has_waves:
            north, east = north + wn, east + we
        north = north + white_n + gm_n
        east = east + white_e + gm_e
        if gross_i:
            direction = _TWO_PI * uniform_from(gross_streams, i)
            north, east = north + jump * math.cos(direction), east + jump * math.sin(direction)
        if valid_i:
            last[i, 0], last[i, 1] = north, east
        else:
            last[i, 0], last[i, 1] = last0[i, 0], last0[i, 1]
        fix_n[i], fix_e[i] = last[i, 0], last[i, 1]
        counter[i] = (counter0[i] + 1) % every[i]
        up[i], valid[i], gross[i] = up_i, valid_i, gross_i
        gm[i, 0], gm[i, 1] = gm_n, gm_e

        # compass: bias, Gauss-Markov drift, white noise, deviation curve
        d = ctab[i, _C_DRIFT_A] * drift0[i]
        if ctab[i, _C_DRIFT_Q] != 0.0:
            d = d + ctab[i, _C_DRIFT_Q] * normal_from(compass_streams, i)
        reading = hull + ctab[i, _C_BIAS] + d
        if ctab[i, _C_SIGMA] != 0.0:
            reading = reading + ctab[i, _C_SIGMA] * normal_from(compass_streams, i)
        if deviation:
            s, c = s_hull, c_hull
            s2, c2 = 2.0 * s * c, c * c - s * s
            reading = reading + (dev[i, 0] + dev[i, 1] * s + dev[i, 2] * c
                                 + dev[i, 3] * s2 + dev[i, 4] * c2)
        reading = wrap_2pi_scalar(reading)
        drift[i], heading_meas[i] = d, reading

        # heading: steady-state alpha-beta filter on the compass
        psi_pred = heading0[0, i] + heading0[1, i] * dt
        innov = wrap_2pi_scalar(reading - psi_pred + math.pi) - math.pi
        heading[0, i] = mod_2pi_scalar(psi_pred + ctab[i, _H_ALPHA] * innov)
        heading[1, i] = heading0[1, i] + ctab[i, _H_BETA] * innov


@kernel
def _pv_filter(x: np.ndarray, lever: bool, arm: np.ndarray, tab: np.ndarray,
               max_rejections: np.ndarray,
               filter_pv: np.ndarray, multi_row: np.ndarray, fix_n: np.ndarray,
               fix_e: np.ndarray, valid: np.ndarray, heading: np.ndarray, fused_n: np.ndarray,
               fused_e: np.ndarray, fused_valid: np.ndarray, fused_sigma: np.ndarray,
               x0: np.ndarray, P0: np.ndarray, rejections0: np.ndarray, x_out: np.ndarray,
               P_out: np.ndarray, rejections: np.ndarray, est: np.ndarray) -> None:
    """Per ship: the fix moved to the reference point [seed 003, eq 5] (or the fused fix of
    ``multi_row``), pv predict [seed 000, eqs 3-4], the gate [seed 002, 6.6], pv update
    [seed 000, recursion steps 2-3], restart on a genuine jump and the estimate.

    The arithmetic, in the same order, of :func:`trafficsim.sensors.gnss.to_reference_point`,
    :func:`trafficsim.estimation.pv.predict`, :func:`trafficsim.estimation.gating.gate` on
    :func:`~trafficsim.estimation.gating.normalised_distance` (or
    :func:`~trafficsim.estimation.gating.distance` for a window in metres) and
    :func:`trafficsim.estimation.pv.update`. ``heading`` ``(2, n)`` the heading filter's
    output; ``fused_*`` ``(m,)`` rows of the ships with several receivers (m; m2 as sigma);
    ``est`` ``(6, n)`` out: the pv estimate of the ``filter_pv`` ships, truth for the others.
    The heading's cosine and sine come from :func:`trafficsim.geometry.cos_sin` (no libm call).
    """
    for i in range(x.shape[1]):
        psi = heading[0, i]
        ref_n, ref_e, ok, sigma = fix_n[i], fix_e[i], valid[i], tab[i, _F_SIGMA]
        c = s = 0.0
        if lever or filter_pv[i]:  # for the lever arm and the body-frame velocity
            c, s = cos_sin(psi)
        if lever:
            ax, ay = arm[i, 0], arm[i, 1]
            ref_n, ref_e = ref_n - (ax * c - ay * s), ref_e - (ax * s + ay * c)
        k = multi_row[i]
        if k >= 0:
            ref_n, ref_e, ok, sigma = fused_n[k], fused_e[k], fused_valid[k], fused_sigma[k]
        dt, q = tab[i, _F_DT], tab[i, _F_SP]
        x_out[i, pv.POS_N] = x0[i, pv.POS_N] + dt * x0[i, pv.VEL_N]
        x_out[i, pv.POS_E] = x0[i, pv.POS_E] + dt * x0[i, pv.VEL_E]
        x_out[i, pv.VEL_N] = x0[i, pv.VEL_N]
        x_out[i, pv.VEL_E] = x0[i, pv.VEL_E]
        for a in range(2):
            pp, pv_, vv = P0[i, a, pv.POS, pv.POS], P0[i, a, pv.POS, pv.VEL], P0[i, a, pv.VEL,
                                                                                  pv.VEL]
            P_out[i, a, pv.POS, pv.POS] = pp + 2.0 * dt * pv_ + dt * dt * vv + q * dt**3 / 3.0
            P_out[i, a, pv.POS, pv.VEL] = pv_ + dt * vv + 0.5 * q * dt * dt
            P_out[i, a, pv.VEL, pv.POS] = P_out[i, a, pv.POS, pv.VEL]
            P_out[i, a, pv.VEL, pv.VEL] = vv + q * dt
        r = sigma * sigma
        # gate on the normalised innovation, or on the distance for a window in metres
        d = math.nan
        if ok:
            nu_n, nu_e = ref_n - x_out[i, pv.POS_N], ref_e - x_out[i, pv.POS_E]
            if tab[i, _F_METRES]:
                d = math.sqrt(nu_n * nu_n + nu_e * nu_e)
            else:
                d = math.sqrt(nu_n * nu_n / (P_out[i, pv.AXIS_NORTH, pv.POS, pv.POS] + r)
                              + nu_e * nu_e / (P_out[i, pv.AXIS_EAST, pv.POS, pv.POS] + r))
        window = tab[i, _F_THRESHOLD]  # reopen_factor ** 0 = 1, also for an infinite factor
        if rejections0[i]:
            window = window * tab[i, _F_REOPEN] ** float(rejections0[i])
        have = not math.isnan(d)  # (as gating.gate: only NaN means no fix)
        accept = have and d <= window
        reject = have and not accept
        count = 0 if accept else rejections0[i] + (1 if reject else 0)
        restart = reject and count >= max_rejections[i]
        rejections[i] = 0 if restart else count
        if accept:
            pv.update_axis(x_out, P_out, i, 0, r, ref_n)
            pv.update_axis(x_out, P_out, i, 1, r, ref_e)
        if restart:  # genuine jump: restart on the fix, keep the velocity
            x_out[i, pv.POS_N], x_out[i, pv.POS_E] = ref_n, ref_e
        if filter_pv[i]:
            vn, ve = x_out[i, pv.VEL_N], x_out[i, pv.VEL_E]
            est[0, i], est[1, i], est[2, i] = x_out[i, pv.POS_N], x_out[i, pv.POS_E], psi
            est[3, i], est[4, i], est[5, i] = vn * c + ve * s, -vn * s + ve * c, heading[1, i]
        else:
            for row in range(N_EST):
                est[row, i] = x[row, i]


def _adaptive_configs(nav_cfg: Sequence[Mapping[str, Any]]) -> list[dict[str, Any] | None]:
    """Per ship the settings of :func:`trafficsim.estimation.adaptive.build` from the
    ``adaptive_*`` keys of ``navigation`` (None: adaptive R off), checked."""
    out: list[dict[str, Any] | None] = []
    for i, c in enumerate(nav_cfg):
        cfg = {key[len("adaptive_"):]: value for key, value in c.items()
               if key.startswith("adaptive_")}
        if cfg and "window_steps" not in cfg:
            raise InputError("adaptive_* keys need adaptive_window_steps",
                             key=f"navigation[{i}]")
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
                             params.max_rejections[idx], params.metres[idx])
