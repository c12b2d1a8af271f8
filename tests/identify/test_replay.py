"""Replay of ship models with measured inputs: against a plain per-window reference, the
truth, and in batches."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.identify import preprocess, replay
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships import base, manoeuvres
from trafficsim.ships.library import load_ship


def _reference(spec: dict, x0: np.ndarray, inputs: np.ndarray, env: np.ndarray, dt: float,
               substeps: int) -> np.ndarray:
    """Textbook RK4 of one ship with first-order-hold inputs via ``base.accelerations``."""
    family = base.families()[spec["model"]]
    params = family.build([spec])

    def deriv(x: np.ndarray, k: int, f: float) -> np.ndarray:
        xs = np.zeros((8, 1))
        xs[:6, 0] = x
        xs[6, 0] = (1 - f) * inputs[k, 0] + f * inputs[k + 1, 0]
        xs[7, 0] = (1 - f) * inputs[k, 1] + f * inputs[k + 1, 1]
        e = base.Env(env[k, 0], env[k, 1], env[k, 2], env[k, 3])
        du, dv, dr = base.accelerations(family, params, xs, e)
        c, s = np.cos(x[2]), np.sin(x[2])
        return np.array([x[3] * c - x[4] * s + env[k, 0], x[3] * s + x[4] * c + env[k, 1],
                         x[5], du[0], dv[0], dr[0]])

    out = [x0[:6].copy()]
    x = x0[:6].copy()
    h = dt / substeps
    for k in range(inputs.shape[0] - 1):
        for s in range(substeps):
            f0, fm, f1 = s / substeps, (s + 0.5) / substeps, (s + 1) / substeps
            k1 = deriv(x, k, f0)
            k2 = deriv(x + 0.5 * h * k1, k, fm)
            k3 = deriv(x + 0.5 * h * k2, k, fm)
            k4 = deriv(x + h * k3, k, f1)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(x.copy())
    return np.array(out)


def _windows(rng: np.random.Generator, w: int, n: int, dt: float, speed: float, rps: float
             ) -> replay.Windows:
    x0 = np.zeros((8, w))
    x0[0] = rng.normal(0, 100, w)
    x0[2] = rng.uniform(0, 2 * np.pi, w)
    x0[3] = speed * rng.uniform(0.8, 1.1, w)
    x0[4] = rng.normal(0, 0.05 * speed, w)
    x0[5] = rng.normal(0, 0.002, w)
    inputs = np.zeros((w, n, 2))
    inputs[..., 0] = np.radians(np.cumsum(rng.normal(0, 3, (w, n)), axis=1)).clip(-0.6, 0.6)
    inputs[..., 1] = rps * rng.uniform(0.7, 1.1, (w, n))
    env = np.zeros((w, n, 4))
    env[..., 2] = rng.uniform(0, 15, (w, n))
    env[..., 3] = rng.uniform(0, 2 * np.pi, (w, n))
    return replay.Windows(x0, inputs, env, np.full(w, dt), np.array([n, n - 7][:w]),
                          np.full((w, n, 6), np.nan), np.arange(w), np.zeros(w),
                          tuple(f"w{i}" for i in range(w)))


@pytest.mark.parametrize("ship", ["kvlcc2", "cargo", "bulk_carrier", "catfish"])
def test_replay_equals_a_plain_rk4_reference(ship: str) -> None:
    """Every family, with wind and time-varying inputs, 2 windows of different lengths: the
    compiled replay equals a per-window RK4 written with numpy (to rounding)."""
    spec = load_ship(ship)
    rng = np.random.default_rng(7)
    speed = spec["service_speed_kn"] * 1852 / 3600
    rps = float(spec["actuators"]["rps_max"]) * 0.8
    win = _windows(rng, 2, 25, 2.0, speed, rps)
    models = replay.model_rows([spec])
    sub = int(replay.substeps(models, win)[0, 0])
    out, diverged = replay.simulate(models, win)
    assert not diverged.any()
    for w in range(2):
        n = win.n_samples[w]
        ref = _reference(spec, win.x0[:, w], win.inputs[w, :n], win.env[w, :n], 2.0, sub)
        np.testing.assert_allclose(out[0, w, :n], ref, rtol=1e-9, atol=1e-9)
        assert np.all(np.isnan(out[0, w, n:]))


def test_batches_are_independent() -> None:
    """k models x W windows in one call equal each model on each window alone."""
    specs = [load_ship("kvlcc2"), load_ship("container"), load_ship("bulk_carrier")]
    rng = np.random.default_rng(3)
    win = _windows(rng, 2, 30, 1.0, 7.0, 1.2)
    models = replay.model_rows(specs)
    out, _ = replay.simulate(models, win)
    for m, spec in enumerate(specs):
        for w in range(2):
            one, _ = replay.simulate(replay.model_rows([spec]), win.subset(np.arange(2) == w))
            np.testing.assert_array_equal(out[m, w], one[0, 0])


def test_replaying_the_measured_inputs_reproduces_the_trial() -> None:
    """A 20/20 zig-zag of the KVLCC2 (steering gear and engine lags in the truth) replayed from
    its first state with the recorded rudder and rpm: heading within 0.2 deg and position
    within 0.5 % of the distance run over 20 minutes."""
    spec = load_ship("kvlcc2")
    track, _ = manoeuvres.zigzag(spec, 20.0, dt=1.0)
    trial = from_arrays("zz", track)
    smooth = {"north_m": trial.north_m, "east_m": trial.east_m,
              "psi_rad": np.unwrap(trial.psi_rad),
              "u_mps": trial.u_mps, "v_mps": trial.v_mps, "r_radps": trial.r_radps}
    run = preprocess.Kinematics(trial, smooth, {}, {})
    win = replay.windows_from_runs([run], None)
    out, _ = replay.simulate(replay.model_rows([spec]), win)
    sim = out[0, 0]
    dist = np.sum(np.hypot(np.diff(trial.north_m), np.diff(trial.east_m)))
    assert np.degrees(np.abs(sim[:, 2] - np.unwrap(trial.psi_rad)).max()) < 0.2
    assert np.hypot(sim[:, 0] - trial.north_m, sim[:, 1] - trial.east_m).max() < 0.005 * dist
    # cut into 100 s windows, each from its own measured state: errors smaller still
    win = replay.windows_from_runs([run], 100.0)
    assert win.w >= (trial.n - 1) // 100 and np.all(win.n_samples <= 101)
    out, _ = replay.simulate(replay.model_rows([spec]), win)
    err = np.abs(out[0, :, :, 2] - win.target[:, :, 2])
    assert np.nanmax(np.degrees(err)) < 0.1


def test_a_diverging_candidate_is_frozen_and_flagged() -> None:
    spec = load_ship("bulk_carrier")
    bad = dict(spec, coefficients={**spec["coefficients"], "c2": 5.0, "b1": 3.0})
    rng = np.random.default_rng(1)
    win = _windows(rng, 2, 400, 2.0, 6.0, 1.4)
    out, diverged = replay.simulate(replay.model_rows([spec, bad]), win)
    assert not diverged[0].any() and diverged[1].all()
    valid = win.valid()
    assert np.all(np.isfinite(out[1][valid]))
