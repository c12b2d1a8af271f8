"""Radar and AIS of other ships feed one tracker per directed pair, inside the engine."""

import numpy as np

from trafficsim.batch import EncounterEnv, ShipSetup, build_batch
from trafficsim.engine import Simulation
from trafficsim.ships.base import EAST, NORTH
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn

RADAR = {"radar": {"sigma_range_m": 30.0, "sigma_bearing_deg": 1.0}}


def _ships(sensors_a, sensors_b, enc=0, extra=()):
    spec = load_ship("container")
    a = ShipSetup("a", spec, enc, 0.0, 0.0, 0.0, from_kn(14.0), ship_in_encounter=0,
                  sensors=sensors_a)
    b = ShipSetup("b", spec, enc, 6000.0, 3000.0, np.pi, from_kn(12.0), ship_in_encounter=1,
                  sensors=sensors_b)
    return [a, b, *extra]


def _errors(ships, steps=400, seed=2):
    envs = [EncounterEnv()] * (max(s.encounter for s in ships) + 1)
    sim = Simulation.start(build_batch(ships, envs), 1.0, seed)
    errs = []
    for _ in range(steps):
        sim.step()
        xp, active = sim.obs.predicted_tracks(sim.t_s)
        x = sim.batch.x
        err = np.hypot(xp[:, 0] - x[NORTH, sim.obs.tgt], xp[:, 1] - x[EAST, sim.obs.tgt])
        errs.append(np.where(active, err, np.nan))
    return sim, np.array(errs)


def test_tracks_are_much_better_than_single_radar_plots():
    sim, errs = _errors(_ships(RADAR, RADAR))
    assert sim.obs is not None and sim.obs.obs.shape == (2,)
    late = errs[200:]
    assert np.isfinite(late).mean() > 0.95
    # a plot at ~6 km with 1 deg bearing noise is off by ~100 m; the track by far less
    assert np.nanmedian(late) < 40.0


def test_a_ship_without_radar_or_ais_sees_nothing():
    sim, errs = _errors(_ships(RADAR, {}), steps=100)
    a_tracks_b = sim.obs.obs == 0
    assert np.isfinite(errs[50:, a_tracks_b]).all()
    assert np.isnan(errs[:, ~a_tracks_b]).all()


def test_pair_noise_does_not_depend_on_other_encounters():
    _, alone = _errors(_ships(RADAR, RADAR), steps=60)
    spec = load_ship("container")
    other = [ShipSetup(f"o{k}", spec, 1, 0.0, 1000.0 * k, 0.0, 6.0, ship_in_encounter=k,
                       sensors=RADAR) for k in range(3)]
    sim, mixed = _errors(_ships(RADAR, RADAR, extra=other), steps=60)
    first = (sim.obs.obs < 2) & (sim.obs.tgt < 2)
    np.testing.assert_array_equal(alone, mixed[:, first])


def test_predicted_tracks_move_each_track_along_its_velocity():
    sim, _ = _errors(_ships(RADAR, RADAR), steps=30)
    tracks = sim.obs.tracks
    t = sim.t_s + 4.0
    xp, active = sim.obs.predicted_tracks(t)
    assert active.all()
    np.testing.assert_allclose(xp[:, :2], tracks.x[:, :2]
                               + (t - tracks.t_s)[:, None] * tracks.x[:, 2:], rtol=1e-15)
    np.testing.assert_array_equal(xp[:, 2:], tracks.x[:, 2:])
