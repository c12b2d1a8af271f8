"""Radar and AIS of other ships feed one tracker per directed pair, inside the engine."""

import numpy as np
import pytest

from trafficsim.batch import EncounterEnv, ShipSetup, build_batch
from trafficsim.engine import Simulation
from trafficsim.estimation import tracker
from trafficsim.noise import generator
from trafficsim.observation import Observation, observes
from trafficsim.ships.base import EAST, NORTH, PSI, U
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


# --- Observation driven directly on straight-line truth -------------------------------------

FULL = {"radar": {"sigma_range_m": 25.0, "sigma_bearing_deg": 0.8, "p_detect": 0.7},
        "ais": {"p_receive": 0.6, "latency_s": 3.0}}
#: (north, east, heading deg, speed m/s) of ships a, b, c
MOVES = {"a": (0.0, 0.0, 0.0, 7.0), "b": (5000.0, 2500.0, 200.0, 6.0),
         "c": (-3000.0, 4000.0, 300.0, 5.0)}


def _observe(names, enc, slot, seed=4, steps=90, configs=None, est_offset=(0.0, 0.0)):
    """Ships ``names`` on straight lines observed for ``steps`` 1 s steps; each observer puts
    its plots on the chart with its position estimate moved by ``est_offset`` (m)."""
    n = len(names)
    configs = configs or [FULL] * n
    enc = np.asarray(enc)
    pi, pj = (np.array(a, dtype=np.int64) for a in
              zip(*[(i, j) for i in range(n) for j in range(i + 1, n) if enc[i] == enc[j]],
                  strict=True))
    obs = Observation.build(configs, pi, pj, seed, enc, np.asarray(slot))
    x = np.zeros((8, n))
    for k, name in enumerate(names):
        north, east, hdg, speed = MOVES[name]
        x[NORTH, k], x[EAST, k], x[PSI, k], x[U, k] = north, east, np.radians(hdg), speed
    for t in range(steps):
        est = x[:6].copy()
        est[NORTH] += est_offset[0]
        est[EAST] += est_offset[1]
        obs.update(x, est, np.zeros((2, n)), float(t))
        x[NORTH] += x[U] * np.cos(x[PSI])
        x[EAST] += x[U] * np.sin(x[PSI])
    return obs


def _track_of(obs, observer, target):
    """Row of the directed pair (observer -> target) in the observation's arrays."""
    k = np.flatnonzero((obs.obs == observer) & (obs.tgt == target))
    assert k.size == 1
    return int(k[0])


def _same_tracks(o1, pairs1, o2, pairs2):
    for (a1, b1), (a2, b2) in zip(pairs1, pairs2, strict=True):
        k1, k2 = _track_of(o1, a1, b1), _track_of(o2, a2, b2)
        for f in ("x", "P", "t_s", "active", "n_updates", "gate_failures"):
            np.testing.assert_array_equal(getattr(o1.tracks, f)[k1], getattr(o2.tracks, f)[k2])


def test_pair_tracks_do_not_depend_on_a_third_ship_or_batch_order():
    """Radar (missed detections) and AIS (lost reports) draw per pair and per transmitter:
    the tracks between a and b are bit-identical with a third ship c in the same encounter,
    with the ships listed in another order, and with another encounter placed first in the
    batch (its key unchanged)."""
    alone = _observe(["a", "b"], [0, 0], [0, 1])
    assert alone.tracks.active.all() and (alone.tracks.n_updates > 10).all()
    ab = [(0, 1), (1, 0)]
    third = _observe(["a", "b", "c"], [0, 0, 0], [0, 1, 2])
    _same_tracks(alone, ab, third, ab)
    swapped = _observe(["b", "c", "a"], [0, 0, 0], [1, 2, 0])
    _same_tracks(alone, ab, swapped, [(2, 0), (0, 2)])
    behind = _observe(["c", "a", "b"], [5, 0, 0], [0, 0, 1])
    _same_tracks(alone, ab, behind, [(1, 2), (2, 1)])


def test_the_stream_key_and_seed_change_the_noise():
    """The same pair under another encounter key or another seed gets other numbers (so the
    test above compares streams that matter)."""
    alone = _observe(["a", "b"], [0, 0], [0, 1])
    for other in (_observe(["a", "b"], [1, 1], [0, 1]), _observe(["a", "b"], [0, 0], [0, 1],
                                                                 seed=5)):
        assert not np.array_equal(alone.tracks.x, other.tracks.x)


def test_own_position_error_shifts_radar_tracks_rigidly():
    """Radar plots are placed from the observer's own estimate: an estimate off by (120, -80) m
    (heading exact) moves every plot, and so every radar-only track, by exactly that offset,
    with the same velocity and covariance (the same draws, a translated linear filter)."""
    radar_only = [{"radar": FULL["radar"]}] * 2
    exact = _observe(["a", "b"], [0, 0], [0, 1], configs=radar_only)
    moved = _observe(["a", "b"], [0, 0], [0, 1], configs=radar_only, est_offset=(120.0, -80.0))
    assert exact.tracks.active.all()
    np.testing.assert_allclose(moved.tracks.x[:, :2] - exact.tracks.x[:, :2],
                               np.broadcast_to([120.0, -80.0], (2, 2)), atol=1e-6)
    np.testing.assert_allclose(moved.tracks.x[:, 2:], exact.tracks.x[:, 2:], atol=1e-9)
    np.testing.assert_allclose(moved.tracks.P, exact.tracks.P, rtol=1e-9)


def test_ais_only_tracks_follow_the_transmitter_not_the_observer_estimate():
    """Without radar the tracks come from AIS reports of the target's own GNSS: the
    observer's position error does not move them."""
    ais_only = [{"ais": FULL["ais"]}] * 2
    exact = _observe(["a", "b"], [0, 0], [0, 1], configs=ais_only)
    moved = _observe(["a", "b"], [0, 0], [0, 1], configs=ais_only, est_offset=(120.0, -80.0))
    assert exact.tracks.active.all() and not exact.has_radar and exact.has_ais
    np.testing.assert_array_equal(moved.tracks.x, exact.tracks.x)


@pytest.mark.parametrize("configs, expected", [
    ([{}, {}], False),
    ([{"radar": None, "ais": None}], False),
    ([{}, {"ais": {}}], True),
    ([{"radar": {"p_detect": 0.5}}], True),
    ([], False),
])
def test_observes_needs_a_radar_or_ais_section(configs, expected):
    """An instrument section set to None is absent; an empty section is an instrument with
    its defaults."""
    assert observes(configs) is expected


def test_build_pairs_flags_and_per_ship_instruments():
    """Both directions of every pair (i -> j first); a ship without a radar section has its
    radar disabled, one with an empty section has it enabled; the tracker settings of a
    directed pair are its observer's."""
    configs = [{"radar": {}}, {"ais": {}, "tracker": {"coast_s": 12.0}}, {"radar": None}]
    obs = Observation.build(configs, np.array([0, 0, 1]), np.array([1, 2, 2]), 0,
                            [0, 0, 0], np.array([0, 1, 2]))
    np.testing.assert_array_equal(obs.obs, [0, 0, 1, 1, 2, 2])
    np.testing.assert_array_equal(obs.tgt, [1, 2, 2, 0, 0, 1])
    np.testing.assert_array_equal(obs.radar_p.enabled, [True, False, False])
    np.testing.assert_array_equal(obs.ais_p.enabled, [False, True, False])
    assert obs.has_radar and obs.has_ais
    table, row = obs.settings
    assert table.shape == (2, tracker.N_SETTINGS)  # two distinct settings
    np.testing.assert_array_equal(table[row, tracker.S_COAST] == 12.0, obs.obs == 1)
    assert obs.tracks.x.shape == (6, 4) and not obs.tracks.active.any()


# --- batch composition ------------------------------------------------------------------------


def _encounter(enc, key, n=2, sensors=FULL, filt="none"):
    """Ships of one encounter (stream key ``key``): a, b and optionally c of ``MOVES``-like
    starts, under way."""
    spec = load_ship("container")
    starts = [(0.0, 0.0, 0.0, 14.0), (6000.0, 3000.0, np.pi, 12.0), (-3000.0, 4000.0, 5.0, 10.0)]
    return [ShipSetup(f"s{enc}_{k}", spec, enc, *starts[k][:3], from_kn(starts[k][3]),
                      ship_in_encounter=k, sensors=sensors, stream_encounter=key, filter=filt)
            for k in range(n)]


def _run(ships, steps=60, seed=3):
    envs = [EncounterEnv()] * (max(s.encounter for s in ships) + 1)
    sim = Simulation.start(build_batch(ships, envs), 1.0, seed)
    for _ in range(steps):
        sim.step()
    return sim


def test_encounter_tracks_identical_alone_or_inside_a_larger_batch():
    """An encounter (stream key 7, radar with missed detections and AIS with lost reports,
    3 s latency) run alone and as the third of four encounters whose ships differ in number
    and instruments (one with AIS only, one with a faster radar only, none with the same
    key): its ships' motion and its tracks are bit-identical, since every draw is keyed by
    (encounter key, ship, purpose[, target]) and no loop couples pairs."""
    alone = _run(_encounter(0, 7))
    big = _run(_encounter(0, 1, 3) + _encounter(1, 4, 2, {"ais": {}})
               + _encounter(2, 7) + _encounter(3, 9, 3, {"radar": {"scan_period_s": 2.0}}))
    offset = 5  # the encounter's ships are rows 5, 6 of the big batch
    np.testing.assert_array_equal(alone.batch.x, big.batch.x[:, offset:offset + 2])
    rows = [_track_of(big.obs, o + offset, t + offset)
            for o, t in zip(alone.obs.obs, alone.obs.tgt, strict=True)]
    assert alone.obs.tracks.active.all() and (alone.obs.tracks.n_updates > 5).all()
    for f in ("x", "P", "t_s", "active", "n_updates", "gate_failures"):
        np.testing.assert_array_equal(getattr(alone.obs.tracks, f),
                                      getattr(big.obs.tracks, f)[rows])


def test_an_encounter_without_radar_is_unaffected_by_radars_elsewhere():
    """AIS-only ships a, b tracked alone (the batch has no radar: no scans at all) and next to
    an encounter with radars (scans every step there): the a-b tracks are bit-identical."""
    ais_only = [{"ais": FULL["ais"]}] * 2
    alone = _observe(["a", "b"], [0, 0], [0, 1], configs=ais_only)
    assert not alone.has_radar
    mixed = _observe(["c", "a", "b"], [3, 0, 0], [0, 0, 1],
                     configs=[{"radar": {"scan_period_s": 1.0}}, *ais_only])
    assert mixed.has_radar
    _same_tracks(alone, [(0, 1), (1, 0)], mixed, [(1, 2), (2, 1)])


def test_the_same_seed_gives_the_same_tracks_and_update_is_deterministic():
    """Two builds from the same seed and inputs give bit-identical tracks (no hidden global
    state), and the radar and AIS streams advance only through the observation itself."""
    one = _observe(["a", "b", "c"], [0, 0, 0], [0, 1, 2])
    two = _observe(["a", "b", "c"], [0, 0, 0], [0, 1, 2])
    for f in ("x", "P", "t_s", "active", "n_updates"):
        np.testing.assert_array_equal(getattr(one.tracks, f), getattr(two.tracks, f))
    for name in ("radar", "ais_rx", "ais"):
        np.testing.assert_array_equal(one.banks[name].state, two.banks[name].state)


def test_streams_are_keyed_by_encounter_observer_purpose_and_target():
    """Before any step, each directed pair's ``radar`` and ``ais_rx`` streams are numpy's
    ``SFC64(SeedSequence(seed, spawn_key=(encounter, observer, purpose, target)))`` (slots
    within the encounter) and each ship's ``ais`` stream the same without a target, as
    :func:`trafficsim.noise.generator` builds them: the two directions of a pair differ."""
    obs = _observe(["c", "a", "b"], [5, 2, 2], [0, 1, 0], seed=11, steps=0)
    slot, enc = np.array([0, 1, 0]), np.array([5, 2, 2])
    assert obs.obs.tolist() == [1, 2] and obs.tgt.tolist() == [2, 1]
    for name in ("radar", "ais_rx"):
        for k, (i, j) in enumerate(zip(obs.obs, obs.tgt, strict=True)):
            g = generator(11, enc[i], slot[i], name, other=slot[j])
            np.testing.assert_array_equal(obs.banks[name].state[k],
                                          g.bit_generator.state["state"]["state"])
    for i in range(3):
        g = generator(11, enc[i], slot[i], "ais")
        np.testing.assert_array_equal(obs.banks["ais"].state[i],
                                      g.bit_generator.state["state"]["state"])
    assert not np.array_equal(obs.banks["radar"].state[0], obs.banks["radar"].state[1])



TRACK = {"coast_s": 6.0, "gate_probability": 0.9, "max_gate_failures": 1}


def _in_flight_configs(mixed):
    """Three ships with AIS latencies 13, 5 and 3 s; ``mixed``: the first ignores the stamps
    of the reports it receives and the third has no transponder."""
    configs = [{"radar": {"sigma_range_m": 40.0, "p_detect": 0.7},
                "ais": {"p_receive": 0.6, "latency_s": latency}, "tracker": dict(TRACK)}
               for latency in (13.0, 5.0, 3.0)]
    if mixed:
        configs[0]["tracker"]["latency_compensation"] = False
        configs[2]["ais"]["enabled"] = False
    return configs


@pytest.mark.parametrize(("dt", "mixed"), [(1.0, False), (0.7, False), (2.3, False),
                                           (1.0, True)])
def test_keeping_the_history_only_while_a_report_is_in_flight_changes_no_track(
        monkeypatch, dt, mixed):
    """The tracker keeps the measurements it may have to use again (for a late AIS report)
    only while a report is on its way; its tracks are those of a tracker told nothing, which
    keeps them all, to the bit: with reports late by a plot or two (reprocessed) and by more
    than the history holds (propagated forward), lost reports and missed plots, tracks that
    coast out or fail the gate and restart, steps shorter and longer than 1 s, an observer
    that ignores the stamps and a ship without AIS."""
    configs = _in_flight_configs(mixed)
    n = len(configs)
    pi, pj = np.array([0, 0, 1]), np.array([1, 2, 2])
    told, untold = (Observation.build(configs, pi, pj, 5, np.zeros(n, int), np.arange(n))
                    for _ in range(2))
    tracker_step, late, restarts = tracker.step, [], 0

    def step(params, state, obs, t_s, radar=None, ais=None, **kwargs):
        if state is untold.tracks:
            kwargs["in_flight_s"] = None
        else:
            late.extend((t_s - ais.stamp_s)[ais.valid & (ais.stamp_s < state.t_s)])
        return tracker_step(params, state, obs, t_s, radar, ais, **kwargs)
    monkeypatch.setattr(tracker, "step", step)
    x = np.zeros((8, n))
    # 24 kn (2 s reports), 16 kn (6 s) and 10 kn (10 s), two of them turning slowly
    x[NORTH], x[EAST], x[U] = [0.0, 4000.0, -2500.0], [0.0, 2000.0, 3500.0], [12.5, 8.2, 5.1]
    x[PSI] = np.radians([10.0, 200.0, 300.0])
    for k in range(round(400.0 / dt)):
        active = told.tracks.active.copy()
        for o in (told, untold):
            o.update(x, x[:6].copy(), np.zeros((2, n)), k * dt)
        restarts += np.sum(active & (told.tracks.n_updates == 1))
        for f in ("x", "P", "t_s", "heard_s", "active", "n_updates", "gate_failures"):
            np.testing.assert_array_equal(getattr(told.tracks, f), getattr(untold.tracks, f),
                                          err_msg=f"{f} at {k * dt} s")
        x[NORTH] += dt * x[U] * np.cos(x[PSI])
        x[EAST] += dt * x[U] * np.sin(x[PSI])
        x[PSI] += dt * np.radians([0.4, -0.3, 0.0])
    late = np.array(late)
    assert np.sum(late <= 6.0) > 20 and np.sum(late > 12.0) > 20 and restarts > 5
    assert told.tracks.hist_n.sum() < untold.tracks.hist_n.sum()  # fewer records kept
