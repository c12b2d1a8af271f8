"""Output-error fit: batched Jacobian, bounds, recovery of a simulated ship."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.errors import InputError
from trafficsim.identify import output_error, preprocess, replay
from trafficsim.identify.parameters import Parametrisation
from trafficsim.io.trialdata import from_arrays
from trafficsim.ships import manoeuvres
from trafficsim.ships.library import load_ship


@pytest.fixture(scope="module")
def cargo_runs() -> tuple[dict, list[preprocess.Kinematics]]:
    """Two zig-zags (10/10, 20/20) of the Nomoto cargo ship, fixes sigma 1 m, compass 0.2 deg."""
    spec = load_ship("cargo")
    rng = np.random.default_rng(11)
    trials = []
    for rudder in (10.0, 20.0):
        track, _ = manoeuvres.zigzag(spec, rudder, dt=1.0)
        n = track["t_s"].size
        track = {**track, "north_m": track["north_m"] + rng.normal(0, 1.0, n),
                 "east_m": track["east_m"] + rng.normal(0, 1.0, n),
                 "heading_deg": track["heading_deg"] + rng.normal(0, 0.2, n)}
        trials.append(from_arrays(f"zz{rudder:.0f}", track))
    return spec, preprocess.smooth_runs(trials, 160.93, 7.7)


def test_batched_jacobian_equals_central_differences(cargo_runs) -> None:
    """All columns from one replay equal serial central differences (to FD accuracy)."""
    spec, runs = cargo_runs
    param = Parametrisation.of(spec)
    win = replay.windows_from_runs(runs, 100.0)
    res = output_error.Residuals(param, win)
    x = param.initial() * np.array([1.1, 0.9, 1.2, 1.05, 0.8])
    r0 = res(x[None])[0]
    h = output_error.fd_steps(x, x, param.lower, param.upper, 1e-6)
    jac = output_error.jacobian(res, x, r0, h)
    assert jac.shape == (res.m, 5)
    for j in range(5):
        step = 1e-4 * abs(x[j])
        xp, xm = x.copy(), x.copy()
        xp[j] += step
        xm[j] -= step
        central = (res(xp[None])[0] - res(xm[None])[0]) / (2 * step)
        scale = np.abs(central).max()
        assert np.abs(jac[:, j] - central).max() < 2e-3 * scale


def test_fit_recovers_the_turning_of_a_simulated_ship(cargo_runs) -> None:
    """From a start 20-50 % off, the five Nomoto coefficients fitted to two noisy zig-zags
    give the 35 deg turning circle within 3 %; the weighted residual falls to the noise level
    (RMS about 1) and the nominal intervals are finite."""
    spec, runs = cargo_runs
    param = Parametrisation.of(spec)
    win = replay.windows_from_runs(runs, 100.0)
    start = param.initial() * np.array([1.3, 0.7, 1.5, 1.2, 0.8])
    fit = output_error.fit(param, win, x0=start)
    assert fit.cost < 0.1 * fit.cost0 and fit.rms < 1.5
    assert np.all(np.isfinite(fit.ci95)) and np.all(fit.std > 0)
    np.testing.assert_allclose(np.diag(fit.corr), 1.0)
    _, true = manoeuvres.turning_circle(spec, 35.0)
    _, got = manoeuvres.turning_circle(param.specs(fit.x[None])[0], 35.0)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
        assert got[key] == pytest.approx(true[key], rel=0.03), key
    assert len(fit.history_cost) >= fit.nfev and fit.history_cost[0] == pytest.approx(fit.cost0)


def test_bounds_hold(cargo_runs) -> None:
    """With K' bounded below its true value the solution sits on the bound, not beyond."""
    spec, runs = cargo_runs
    param = Parametrisation.of(spec, ["K_prime", "T_prime"], {"K_prime": (1.0, 3.0)})
    win = replay.windows_from_runs(runs, 100.0)
    fit = output_error.fit(param, win, x0=np.array([2.0, 4.0]), max_nfev=30)
    assert fit.x[0] == pytest.approx(3.0) and param.lower[0] <= fit.x[0] <= param.upper[0]


def test_parametrisation_checks_names_and_bounds() -> None:
    spec = load_ship("kvlcc2")
    with pytest.raises(InputError, match=r"unknown coefficient 'Y_vv'.*did you mean"):
        Parametrisation.of(spec, ["Y_vv"])
    with pytest.raises(InputError, match="not fitted"):
        Parametrisation.of(spec, ["Y_v"], {"N_r": (-1.0, 0.0)})
    with pytest.raises(InputError, match="empty bounds"):
        Parametrisation.of(spec, ["Y_v"], {"Y_v": (0.0, -1.0)})
    p = Parametrisation.of(spec)
    assert p.names == ("R0", "X_vr", "Y_v", "Y_r", "N_v", "N_r", "f_alpha")
    specs = p.specs(np.stack([p.initial(), p.initial() * 2]))
    assert specs[1]["coefficients"]["Y_v"] == 2 * spec["coefficients"]["Y_v"]
    assert specs[1]["coefficients"]["k_0"] == spec["coefficients"]["k_0"]
    assert spec["coefficients"]["Y_v"] == -0.315  # the base ship is not touched
