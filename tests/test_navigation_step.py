"""The compiled own-ship step of :class:`trafficsim.navigation.Navigation` against the vectorised
numpy formulation it replaced (kept below as the reference, fed by the at-need draw rule), step
by step: same draws, same readings, same filter states and estimates to floating-point
round-off."""

from dataclasses import replace

import numpy as np
import pytest

from trafficsim.estimation import gating, pv
from trafficsim.navigation import N_EST, Navigation
from trafficsim.noise import normal_from, uniform_from
from trafficsim.sensors import actuators, compass, gnss, speed_log, waves, wrap_pi
from trafficsim.ships.base import EAST, NORTH, PSI, Env, R, U, V
from trafficsim.ships.library import load_ship


def draws_at_need(nav: Navigation) -> dict[str, np.ndarray]:
    """This step's numbers for the modules' ``step`` functions, drawn one by one from the
    navigation's streams by the at-need rule of :func:`trafficsim.navigation._sense`; a number
    not drawn gets a value that leaves the module's result as the skipped term would (zero
    noise, a clean fix, the receiver kept up)."""
    n = nav.gnss_p.sigma_m.shape[0]
    g, c, w = nav.gnss_p, nav.compass_p, nav.waves_p
    st = {k: nav.banks[k].state for k in ("waves", "gnss", "gnss_gross", "compass")}
    wave = np.zeros((n, waves.WAVE_NORMAL_DIMS))
    normals = np.zeros((n, gnss.GNSS_NORMAL_DIMS))
    uniforms = np.tile([1.0, 0.0, 0.5], (n, 1))  # no gross error, any direction, stays up
    comp = np.zeros((n, compass.COMPASS_NORMAL_DIMS))
    for i in range(n):
        if nav.has_waves and (w.l11[i] != 0 or w.l21[i] != 0 or w.l22[i] != 0):
            for j in range(waves.N_CHANNELS):
                if w.gain[i, j] != 0:
                    wave[i, 2 * j] = normal_from(st["waves"], i)
                    wave[i, 2 * j + 1] = normal_from(st["waves"], i)
        if not nav.gnss_s.up[i] or g.p_start[i] > 0:
            uniforms[i, 2] = uniform_from(st["gnss_gross"], i)
        up = (uniforms[i, 2] >= g.p_start[i]) if nav.gnss_s.up[i] else (
            uniforms[i, 2] < g.p_end[i])
        valid = nav.gnss_s.counter[i] == 0 and up
        if g.gm_q[i] != 0:
            normals[i, 2:] = normal_from(st["gnss"], i), normal_from(st["gnss"], i)
        if valid and g.sigma_m[i] != 0:
            normals[i, :2] = normal_from(st["gnss"], i), normal_from(st["gnss"], i)
        if valid and g.gross_prob[i] > 0:
            uniforms[i, 0] = uniform_from(st["gnss_gross"], i)
            if uniforms[i, 0] < g.gross_prob[i]:
                uniforms[i, 1] = uniform_from(st["gnss_gross"], i)
        if np.reshape(c.drift_q, n)[i] != 0:
            comp[i, 1] = normal_from(st["compass"], i)
        if np.reshape(c.sigma_rad, n)[i] != 0:
            comp[i, 0] = normal_from(st["compass"], i)
    return {"waves": wave, "gnss": normals, "gnss_gross": uniforms, "compass": comp}


def reference_update(nav: Navigation, x: np.ndarray, env: Env) -> gating.GateResult:
    """The numpy formulation of :meth:`Navigation.update` (dozens of array operations); returns
    the pv filter's gate outcome (the estimate is ``nav.est``)."""
    wave_psi = wave_ne = None
    draws = draws_at_need(nav)
    if nav.has_waves:
        nav.waves_s = waves.step(nav.waves_p, nav.waves_s, draws["waves"])
        wave_psi = waves.heading_offset(nav.waves_p, nav.waves_s)
        wave_ne = waves.position_offset(nav.waves_p, nav.waves_s, x[PSI])
    nav.gnss_s, nav.fix = gnss.step(nav.gnss_p, nav.gnss_s, x, draws["gnss"],
                                    draws["gnss_gross"], wave_ne, wave_psi)
    if nav.extra:
        nav._measure_extra_receivers(x, wave_ne, wave_psi)
    nav.compass_s, nav.heading_meas = compass.step(
        nav.compass_p, nav.compass_s, x[PSI], draws["compass"], wave_psi)
    if nav.has_log:
        nav.log_meas = speed_log.measure(nav.log_p, x, env, nav.banks["log"].next())
    if nav.has_actuator_sensors:
        nav.act_meas = actuators.measure(nav.act_p, x, nav.banks["actuators"].next())
    psi, r = nav.heading_est
    psi_pred = psi + r * nav.dt
    innov = wrap_pi(nav.heading_meas - psi_pred)
    psi_new = np.mod(psi_pred + nav.heading_gain[:, 0] * innov, 2 * np.pi)
    r_new = r + nav.heading_gain[:, 1] * innov
    nav.heading_est = np.stack([psi_new, r_new])
    ref_n, ref_e = gnss.to_reference_point(nav.gnss_p, nav.fix.north_m, nav.fix.east_m,
                                           psi_new)
    fix_valid, pv_p = nav.fix.valid, nav.pv_p
    if nav.multi_idx.size:
        mi = nav.multi_idx
        nav.fused = nav._fuse(np.arange(mi.size), psi_new[mi])
        ref_n, ref_e, fix_valid = ref_n.copy(), ref_e.copy(), fix_valid.copy()
        ref_n[mi], ref_e[mi] = nav.fused.position[:, 0], nav.fused.position[:, 1]
        fix_valid[mi] = nav.fused.valid
        sigma = pv_p.sigma_m.copy()
        sigma[mi] = np.sqrt(nav._fused_variance(nav.fused, np.arange(mi.size)))
        pv_p = replace(pv_p, sigma_m=sigma)
    pred = pv.predict(pv_p, nav.pv_s)
    innov = np.stack([ref_n - pred.x[:, 0], ref_e - pred.x[:, 1]], axis=1)
    s_innov = pred.P[:, :, 0, 0] + (pv_p.sigma_m ** 2)[:, None]
    d = np.where(fix_valid, gating.normalised_distance(innov, s_innov), np.nan)
    g = gating.gate(nav.gate_p, d, nav.gate_rejections)
    nav.gate_rejections = g.rejections
    nav.pv_s = pv.update(pv_p, pred, np.nan_to_num(ref_n), np.nan_to_num(ref_e), g.accept)
    if g.restart.any():
        x_pv = nav.pv_s.x.copy()
        x_pv[g.restart, 0], x_pv[g.restart, 1] = ref_n[g.restart], ref_e[g.restart]
        nav.pv_s = pv.PVState(x_pv, nav.pv_s.P)
    vn, ve = nav.pv_s.x[:, 2], nav.pv_s.x[:, 3]
    c, s = np.cos(psi_new), np.sin(psi_new)
    filtered = np.stack([nav.pv_s.x[:, 0], nav.pv_s.x[:, 1], psi_new,
                         vn * c + ve * s, -vn * s + ve * c, r_new])
    nav.est = np.where(nav.filter_pv[None, :], filtered, x[:N_EST])
    if nav.ekf_idx is not None and nav.ekf_idx.size:
        nav.est[:, nav.ekf_idx] = nav._ekf_update(x, env)
    return g


ROUGH_GNSS = {"sigma_m": 3.0, "gross_prob": 0.15, "gross_size_m": 120.0, "gm_sigma_m": 1.5,
              "gm_tau_s": 60.0, "dropout_rate_per_h": 120.0, "dropout_mean_s": 6.0,
              "antenna_x_m": 40.0, "antenna_y_m": -6.0}
SEA = {"heading_sigma_deg": 1.5, "surge_sigma_m": 0.8, "sway_sigma_m": 1.2, "peak_period_s": 7.0}


def _fleet() -> tuple[list[dict], list[str]]:
    """Ships covering every branch: gross errors, outages, slow fixes, lever arms, waves of both
    forms (one without surge), magnetic deviation and drift, log and actuator sensors, two and
    three receivers with correlation, tight gates (restarts), a fully reopening gate, filters
    none / pv / ekf."""
    mag = {"kind": "magnetic", "deviation_deg": [0.5, 2.0, -1.0, 0.7, 0.3],
           "drift_sigma_deg": 0.8, "drift_tau_s": 120.0, "bias_deg": 0.4}
    tight = {"gate_sigma": 3.0, "max_rejections": 2}
    ships = [
        ({}, "pv"),
        ({"gnss": ROUGH_GNSS, "compass": mag, "waves": SEA, "gate": tight}, "pv"),
        ({"gnss": {**ROUGH_GNSS, "rate_hz": 0.5}, "waves": {**SEA, "form": "lowpass"},
          "gnss2": {"sigma_m": 1.0, "antenna_x_m": -30.0, "gross_prob": 0.1},
          "gnss3": {"sigma_m": 4.0, "antenna_y_m": 8.0, "dropout_rate_per_h": 300.0},
          "fusion": {"correlation": 0.3}, "gate": tight}, "pv"),
        ({"log": {"kind": "doppler", "lever_x_m": 5.0},
          "actuators": {"rudder_sigma_deg": 0.5, "rudder_resolution_deg": 0.5,
                        "shaft_sigma_rpm": 1.0}, "gnss": ROUGH_GNSS}, "none"),
        ({"gnss": {"antenna_x_m": 12.0}, "gnss2": {**ROUGH_GNSS, "antenna_x_m": -20.0},
          "compass": {"sigma_deg": 2.0}}, "pv"),
        ({"gnss": {**ROUGH_GNSS, "gross_prob": 0.3}, "gate": {"gate_sigma": 4.0,
                                                               "reopen_factor": float("inf")}},
         "pv"),
        ({"gnss": ROUGH_GNSS, "waves": {**SEA, "surge_sigma_m": 0.0}, "gate": tight,
          "navigation": {"pv_sp_m2ps3": 0.05, "heading_sp_rad2ps3": 1e-4}}, "pv"),
        ({"gnss": ROUGH_GNSS, "gnss2": {"sigma_m": 1.5}, "compass": mag}, "ekf"),
        ({"gnss": ROUGH_GNSS, "compass": {"sigma_deg": 0.5}}, "ekf"),
    ]
    return [dict(s) for s, _ in ships], [f for _, f in ships]


def _truth(n: int, rng: np.random.Generator) -> np.ndarray:
    x = np.zeros((8, n))
    x[NORTH], x[EAST] = rng.uniform(-3e3, 3e3, n), rng.uniform(-3e3, 3e3, n)
    x[PSI], x[U], x[V], x[R] = rng.uniform(0, 2 * np.pi, n), 6.0, 0.2, 0.004
    x[6], x[7] = 0.05, 1.5  # rudder, rps
    return x


def _advance(x: np.ndarray, k: int, dt: float) -> None:
    """Turning ships, the rate of turn changing sign; genuine position jumps at steps 150, 151
    and 260 (the filters must restart on them)."""
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    x[NORTH] += (x[U] * c - x[V] * s) * dt
    x[EAST] += (x[U] * s + x[V] * c) * dt
    x[R] = 0.01 * np.sin(0.02 * k + np.arange(x.shape[1]))
    x[PSI] = np.mod(x[PSI] + x[R] * dt, 2 * np.pi)
    if k in (150, 260):
        x[NORTH] += 400.0
    if k == 151:
        x[EAST, ::2] -= 300.0


def _states(nav: Navigation) -> dict[str, np.ndarray]:
    out = {"est": nav.est, "pv_x": nav.pv_s.x, "pv_P": nav.pv_s.P,
           "rejections": nav.gate_rejections, "heading_est": nav.heading_est,
           "heading_meas": nav.heading_meas, "fix_n": nav.fix.north_m, "fix_e": nav.fix.east_m,
           "fix_valid": nav.fix.valid, "gross": nav.fix.gross, "counter": nav.gnss_s.counter,
           "up": nav.gnss_s.up, "gm": nav.gnss_s.gm_m, "last": nav.gnss_s.last_m,
           "drift": nav.compass_s.drift_rad, "z1": nav.waves_s.z1, "z2": nav.waves_s.z2}
    if nav.fused is not None:
        out["fused"] = nav.fused.position
    if nav.log_meas is not None:
        out["log_u"] = nav.log_meas.u_mps
    if nav.act_meas is not None:
        out["rudder"] = nav.act_meas.rudder_rad
    if nav.ekf_s is not None:
        out["ekf_x"] = nav.ekf_s.x
    return out


@pytest.mark.parametrize("plain", [False, True], ids=["every-branch", "plain"])
def test_compiled_step_matches_the_numpy_formulation(plain):
    configs, filters = _fleet()
    if plain:  # no waves, no lever arm, no deviation, one receiver: the skipped branches
        configs = [{"gnss": {"sigma_m": 2.0, "gross_prob": 0.1, "dropout_rate_per_h": 200.0}}] * 6
        filters = ["pv", "pv", "none", "pv", "pv", "pv"]
    n, dt = len(configs), 1.0
    specs = [load_ship("container")] * n
    x = _truth(n, np.random.default_rng(4))
    ours, ref = (Navigation.build(configs, filters, x, 11, np.arange(n) // 3, np.arange(n) % 3,
                                  dt, specs) for _ in range(2))
    env = Env(current_north_mps=0.2, current_east_mps=-0.1)
    seen = {"restart": 0, "rejected": 0, "gross": 0, "invalid": 0}
    for k in range(400):
        _advance(x, k, dt)
        g = reference_update(ref, x, env)
        ours.update(x, env)
        a, b = _states(ours), _states(ref)
        assert a.keys() == b.keys()
        for name in a:
            if a[name].dtype.kind in "bi":
                np.testing.assert_array_equal(a[name], b[name], err_msg=f"{name} step {k}")
            else:
                np.testing.assert_allclose(a[name], b[name], rtol=1e-12, atol=1e-9,
                                           err_msg=f"{name} step {k}")
        seen["restart"] += int(np.sum(g.restart))
        seen["rejected"] += int(np.sum(g.rejections > 0))
        seen["gross"] += int(np.sum(ref.fix.gross))
        seen["invalid"] += int(np.sum(~ref.fix.valid))
    assert all(v > 0 for v in seen.values()), seen  # every path was exercised


def test_replaced_parameters_are_gathered_again():
    """The per-ship tables follow a replaced parameter set (here a larger GNSS noise)."""
    configs, filters = [{"gnss": {"sigma_m": 2.0}}] * 3, ["pv"] * 3
    x = _truth(3, np.random.default_rng(1))
    ours, ref = (Navigation.build(configs, filters, x, 2, [0, 0, 1], [0, 1, 0], 1.0)
                 for _ in range(2))
    env = Env()
    for k in range(30):
        if k == 10:
            for nav in (ours, ref):
                nav.gnss_p = replace(nav.gnss_p, sigma_m=np.full(3, 8.0))
                nav.pv_p = replace(nav.pv_p, sigma_m=np.full(3, 8.0))
        _advance(x, k, 1.0)
        reference_update(ref, x, env)
        ours.update(x, env)
        np.testing.assert_allclose(ours.est, ref.est, rtol=1e-12, atol=1e-9)
