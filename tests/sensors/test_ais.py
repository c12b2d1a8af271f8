"""AIS class A reports: ITU-R M.1371-5 reporting intervals, exact quantisation of the message
fields, latency of reception, reception range and probability, noise statistics."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.sensors import assert_bound
from trafficsim.errors import InputError
from trafficsim.noise import independent_streams, peek_normals
from trafficsim.sensors import ais
from trafficsim.sensors.radar import directed_pairs
from trafficsim.ships.base import EAST, N_STATE, NORTH, PSI, R, U, V

KN = 1852.0 / 3600.0
TURN = math.radians(1.0)  # 1 deg/s, well above 5 deg in 30 s


@pytest.mark.parametrize(("sog_kn", "turning", "anchored", "expected_s"), [
    (0.0, False, True, 180.0),      # at anchor, not faster than 3 kn: 3 min
    (3.0, False, True, 180.0),
    (4.0, False, True, 10.0),       # at anchor but moving faster than 3 kn
    (0.0, False, False, 10.0),      # 0-14 kn: 10 s
    (14.0, False, False, 10.0),
    (10.0, True, False, 10.0 / 3),  # 0-14 kn changing course: 3 1/3 s
    (14.1, False, False, 6.0),      # 14-23 kn: 6 s
    (23.0, False, False, 6.0),
    (18.0, True, False, 2.0),       # 14-23 kn changing course: 2 s
    (23.1, False, False, 2.0),      # > 23 kn: 2 s
    (30.0, True, False, 2.0),
])
def test_reporting_interval_itu_table(sog_kn: float, turning: bool, anchored: bool,
                                      expected_s: float) -> None:
    """ITU-R M.1371-5 annex 1 table 1, class A shipborne mobile equipment."""
    got = ais.reporting_interval_s(np.array([sog_kn * KN]), np.array([turning]),
                                   np.array([anchored]))
    assert got[0] == pytest.approx(expected_s)


def _ships(speeds_kn, rates_radps=None, headings=None):
    """Ships sailing straight ahead at ``speeds_kn`` in still water: state, current (zero)
    and ground velocity."""
    n = len(speeds_kn)
    x = np.zeros((N_STATE, n))
    x[PSI] = np.zeros(n) if headings is None else headings
    x[R] = np.zeros(n) if rates_radps is None else rates_radps
    x[U] = np.asarray(speeds_kn, dtype=float) * KN
    return x, np.zeros((2, n)), _ground(x, np.zeros((2, n)))


def _ground(x, current):
    """Ground velocity ``(2, n)``: velocity through the water turned to north/east plus the
    current, as the transmitter works it out."""
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    return np.stack([x[U] * c - x[V] * s + current[0], x[U] * s + x[V] * c + current[1]])


def _sent_times(params, x, current, dt, duration, anchored=None):
    n = x.shape[1]
    state = ais.init(params, 0)
    streams = independent_streams(n)
    times: list[list[float]] = [[] for _ in range(n)]
    for k in range(round(duration / dt)):
        t = k * dt
        state, sent = ais.transmit(params, state, t, x, current, streams, anchored)
        for i in np.flatnonzero(sent):  # test bookkeeping only
            times[i].append(t)
    return times


@pytest.mark.parametrize("dt", [0.1, 1.0])
def test_schedule_mean_interval_follows_the_table(dt: float) -> None:
    speeds = [8.0, 8.0, 18.0, 18.0, 30.0, 1.0]
    rates = [0.0, TURN, 0.0, TURN, 0.0, 0.0]
    anchored = np.array([False, False, False, False, False, True])
    params = ais.build([{"sigma_velocity_mps": 0.0}] * 6)
    x, current, _ = _ships(speeds, rates)
    times = _sent_times(params, x, current, dt, 1800.0, anchored)
    expected = [10.0, 10.0 / 3, 6.0, 2.0, 2.0, 180.0]
    for t, iv in zip(times, expected, strict=True):
        assert t[0] == 0.0
        mean = (t[-1] - t[0]) / (len(t) - 1)
        assert mean == pytest.approx(iv, abs=dt / (len(t) - 1) + 1e-9)
        assert np.diff(t).max() <= iv + dt + 1e-9  # each gap within one step of the interval


def test_rate_increases_at_once_when_turning_starts() -> None:
    params = ais.build([{"sigma_velocity_mps": 0.0}])
    x, current, _ = _ships([10.0])
    state, streams = ais.init(params, 0), independent_streams(1)
    sent_at = []
    for k in range(12):
        x[R] = TURN if k >= 5 else 0.0
        state, sent = ais.transmit(params, state, float(k), x, current, streams)
        if sent[0]:
            sent_at.append(k)
    # 10 s interval from t = 0; the turn from t = 5 pulls the next report to 5 (0 + 3 1/3
    # is already past), then 6.67 -> 7, 10
    assert sent_at == [0, 5, 7, 10]


def test_disabled_transponder_never_reports() -> None:
    params = ais.build([{"enabled": False}])
    x, current, _ = _ships([12.0])
    assert _sent_times(params, x, current, 1.0, 60.0) == [[]]


def test_quantisation_steps_exact() -> None:
    """Position 1/10000 min, SOG 0.1 kn, COG 0.1 deg, heading 1 deg (ITU-R M.1371-5 msg 1)."""
    rng = np.random.default_rng(11)
    n = 2000
    lat = 55.0
    params = ais.build([{"ref_latitude_deg": lat}] * n)
    x = np.zeros((N_STATE, n))
    x[NORTH], x[EAST] = rng.uniform(-2e4, 2e4, (2, n))
    x[PSI] = rng.uniform(0.0, 2 * math.pi, n)
    x[U], x[V] = rng.uniform(0.0, 12.0, n), rng.uniform(-1.0, 1.0, n)
    current = rng.uniform(-1.5, 1.5, (2, n))
    vel = _ground(x, current)
    state, streams = ais.init(params, 0), independent_streams(n, 11)
    draws = peek_normals(streams, ais.AIS_TX_NORMAL_DIMS)
    state, sent = ais.transmit(params, state, 0.0, x, current, streams)
    assert sent.all()
    north, east, sog, cog, hdg = (state.buf[:, state.head[0], k] for k in range(5))

    def on_grid(v: np.ndarray, step: float) -> bool:
        k = v / step
        return bool(np.all(np.abs(k - np.round(k)) < 1e-6))

    east_step = 1852.0 / 10000.0 * math.cos(math.radians(lat))
    assert on_grid(north, 1852.0 / 10000.0)
    assert on_grid(east, east_step)
    assert on_grid(sog, 0.1 * KN)
    assert on_grid(np.degrees(cog), 0.1)
    assert on_grid(np.degrees(hdg), 1.0)
    assert (np.degrees(cog) < 360.0 - 1e-9).all() and (np.degrees(hdg) <= 359.0 + 1e-9).all()
    # rounding to the nearest step: the error is at most half a step
    sp, sv = params.sigma_position_m[0], params.sigma_velocity_mps[0]
    assert np.abs(north - (x[NORTH] + sp * draws[:, 0])).max() <= 0.0926 + 1e-9
    assert np.abs(east - (x[EAST] + sp * draws[:, 1])).max() <= east_step / 2 + 1e-9
    vn, ve = vel[0] + sv * draws[:, 2], vel[1] + sv * draws[:, 3]
    assert np.abs(sog - np.hypot(vn, ve)).max() <= 0.05 * KN + 1e-9


def test_sog_cap_and_cog_wrap() -> None:
    assert ais.quantise_sog(np.array([200.0]))[0] == pytest.approx(102.2 * KN)
    assert ais.quantise_angle(np.array([math.radians(359.97)]), ais.COG_STEP_RAD)[0] == 0.0
    assert ais.quantise_angle(np.array([-math.radians(0.6)]), ais.HEADING_STEP_RAD)[0] == \
        pytest.approx(math.radians(359.0))


@pytest.mark.parametrize(("latency", "dt"), [(3.0, 1.0), (2.5, 1.0), (0.0, 1.0), (4.0, 0.5)])
def test_latency_report_received_later_with_its_time_stamp(latency: float, dt: float) -> None:
    """A report stamped t_r arrives on the first step at or after t_r + latency and holds the
    position of time t_r."""
    params = ais.build([{"latency_s": latency, "sigma_position_m": 0.0,
                         "sigma_velocity_mps": 0.0, "sigma_heading_deg": 0.0}] * 2)
    obs, tgt = directed_pairs(np.array([0]), np.array([1]))
    x, current, vel = _ships([0.0, 12.0], headings=np.array([0.0, 0.0]))
    x[EAST, 1] = 3000.0
    state = ais.init(params, obs.shape[0])
    tx, rx = independent_streams(2), independent_streams(2, 1)
    got = []  # (receive time, stamp, north) for pair 0 -> 1
    for k in range(round(25.0 / dt)):
        t = k * dt
        x[NORTH, 1] = vel[0, 1] * t
        state, rep = ais.step(params, state, t, obs, tgt, x, current, tx, rx)
        if rep.valid[0]:
            got.append((t, rep.stamp_s[0], rep.north_m[0]))
    stamps = [g[1] for g in got]
    assert stamps == [0.0, 10.0, 20.0]
    for t_rx, stamp, north in got:
        assert t_rx == pytest.approx(math.ceil((stamp + latency) / dt - 1e-9) * dt)
        assert north == pytest.approx(vel[0, 1] * stamp, abs=0.0926 + 1e-9)


def test_reception_range_and_probability() -> None:
    n_pairs = 20000
    n = 2 * n_pairs
    params = ais.build([{"p_receive": 0.7, "latency_s": 0.0}] * n)
    x, current, _ = _ships([10.0] * n)
    obs = np.arange(n_pairs)
    tgt = obs + n_pairs
    x[NORTH, tgt] = np.where(obs % 2 == 0, 19.9, 20.1) * 1852.0
    state = ais.init(params, n_pairs)
    tx, rx = independent_streams(n), independent_streams(n_pairs, 5)
    state, rep = ais.step(params, state, 0.0, obs, tgt, x, current, tx, rx)
    assert not rep.valid[obs % 2 == 1].any()  # beyond 20 NM
    frac = rep.valid[obs % 2 == 0].mean()
    assert frac == pytest.approx(0.7, abs=4 * math.sqrt(0.21 / (n_pairs / 2)))
    # a report is consumed whether heard or not: nothing more arrives until the next report
    before = rx.copy()
    _, rep = ais.step(params, state, 1.0, obs, tgt, x, current, tx, rx)
    assert not rep.valid.any()
    np.testing.assert_array_equal(rx, before)  # nothing arrived, nothing drawn


def test_position_and_velocity_noise_statistics() -> None:
    n = 20000
    params = ais.build([{"sigma_position_m": 8.0, "sigma_velocity_mps": 0.3}] * n)
    x, current, _ = _ships([15.0] * n)
    streams = independent_streams(n, 3)
    state, _ = ais.transmit(params, ais.init(params, 0), 0.0, x, current, streams)
    north, east, sog, cog, _ = (state.buf[:, state.head[0], k] for k in range(5))
    assert np.std(north) == pytest.approx(8.0, rel=0.03)
    assert np.std(east) == pytest.approx(8.0, rel=0.03)
    assert np.std(sog) == pytest.approx(0.3, rel=0.05)  # along-track velocity noise
    cog_err = (cog + math.pi) % (2 * math.pi) - math.pi
    assert np.std(cog_err) == pytest.approx(0.3 / (15.0 * KN), rel=0.05)


def test_bad_config_rejected() -> None:
    with pytest.raises(InputError):
        ais.build([{"latency": 2.0}])
    with pytest.raises(InputError):
        ais.build([{"latency_s": 60.0}])
    with pytest.raises(InputError):
        ais.build([{"p_receive": -0.1}])
    with pytest.raises(InputError):
        ais.build([{"enabled": "yes"}])


def _reference_transmit(params, state, t, x, current, draws, anchored):
    """Schedule and content of the module docstring with whole-array numpy operations (the
    compiled loop must give the same numbers). Returns the new arrays and ``sent``."""
    sv = params.sigma_velocity_mps
    vel = _ground(x, current)
    still = (current == 0.0).all(axis=0)  # speed over ground = speed through the water
    true_sog = np.where(still, np.hypot(x[U], x[V]), np.hypot(vel[0], vel[1]))
    vn, ve = vel[0] + sv * draws[:, 2], vel[1] + sv * draws[:, 3]
    sog = np.hypot(vn, ve)
    interval = ais.reporting_interval_s(true_sog, np.abs(x[R]) > params.turn_rate_radps,
                                        anchored)
    pending = np.where(np.isfinite(state.last_tx_s),
                       np.minimum(state.next_tx_s, state.last_tx_s + interval), state.next_tx_s)
    sent = params.enabled & (t >= pending - 1e-9)
    nxt = pending + interval
    behind = nxt <= t + 1e-9  # the schedule restarts from now
    nxt = np.where(behind, t + interval, nxt)
    sp = params.sigma_position_m
    north, east = ais.quantise_position(x[NORTH] + sp * draws[:, 0], x[EAST] + sp * draws[:, 1],
                                        params.east_step_m)
    fields = np.stack([north, east, ais.quantise_sog(sog),
                       ais.quantise_angle(np.arctan2(ve, vn), ais.COG_STEP_RAD),
                       ais.quantise_angle(x[PSI] + params.sigma_heading_rad * draws[:, 4],
                                          ais.HEADING_STEP_RAD)], axis=1)
    head = np.where(sent, (state.head + 1) % ais.AIS_BUFFER, state.head)
    rows = np.flatnonzero(sent)
    buf_t, buf = state.buf_t_s.copy(), state.buf.copy()
    buf_t[rows, head[rows]] = t
    buf[rows, head[rows]] = fields[rows]
    last = np.where(behind, t, pending)
    return (np.where(sent, nxt, pending), np.where(sent, last, state.last_tx_s), head, buf_t,
            buf), sent


def _reference_receive(params, state, t, obs, tgt, x, draws):
    """Newest arrived report per pair, range and reception draw, with numpy (see above)."""
    stamps = state.buf_t_s[tgt]
    arrived = (stamps > state.last_rx_s[:, None]) & (
        stamps + params.latency_s[tgt][:, None] <= t + 1e-9)
    masked = np.where(arrived, stamps, -np.inf)
    slot = np.argmax(masked, axis=1)
    newest = masked[np.arange(obs.shape[0]), slot]
    has = np.isfinite(newest)
    rng = np.hypot(x[NORTH, tgt] - x[NORTH, obs], x[EAST, tgt] - x[EAST, obs])
    valid = (has & params.enabled[obs] & (rng <= params.max_range_m[obs])
             & (draws[:, 0] < params.z_receive[obs]))
    nan = np.where(valid, 1.0, np.nan)
    fields = state.buf[tgt, slot] * nan[:, None]
    last_rx = np.where(has, newest, state.last_rx_s)
    on_way = (stamps > last_rx[:, None]) & ~arrived
    in_flight = np.where(on_way, stamps, np.inf).min(axis=1)
    return valid, newest * nan, fields, last_rx, in_flight


def test_compiled_transmit_and_receive_match_array_formulas() -> None:
    """Ten ships in one group for 90 steps of 0.7 s: speeds across every ITU bin, turning and
    anchored ships, a ship without transponder, latencies, reception ranges and
    probabilities; the pure and the in-place forms agree with each other too, the latter
    writing each step's reports over the last step's."""
    rng = np.random.default_rng(17)
    n = 10
    i, j = np.triu_indices(n, 1)
    obs, tgt = directed_pairs(i, j)
    cfg = [{"latency_s": float(rng.choice([0.0, 1.3, 3.0, 9.0])),
            "p_receive": float(rng.choice([1.0, 0.6])),
            "max_range_nm": float(rng.choice([20.0, 4.0])),
            "first_report_s": float(rng.uniform(0, 5)),
            "ref_latitude_deg": float(rng.uniform(-60, 60)),
            "enabled": k != 3} for k in range(n)]
    params = ais.build(cfg)
    anchored = np.arange(n) % 4 == 0
    pure = ais.init(params, obs.shape[0])
    live = ais.init(params, obs.shape[0])
    x, current, _ = _ships(rng.uniform(0.0, 30.0, n), headings=rng.uniform(0, 2 * math.pi, n))
    x[V] = rng.uniform(-0.5, 0.5, n)
    current[:, n // 2:] = rng.uniform(-1.0, 1.0, (2, n - n // 2))  # half in a current
    x[NORTH], x[EAST] = rng.uniform(-5000, 5000, (2, n))
    tx, rx = independent_streams(n, 17), independent_streams(obs.shape[0], 18)
    tx_live, rx_live = tx.copy(), rx.copy()
    rep_live = None
    n_received = n_on_way = 0
    for k in range(90):
        t = 0.7 * k
        x[R] = np.where(rng.random(n) < 0.3, TURN, 0.0)
        vel = _ground(x, current)
        x[NORTH] += 0.7 * vel[0]
        x[EAST] += 0.7 * vel[1]
        tx_before = tx.copy()
        want, want_sent = _reference_transmit(params, pure, t, x, current,
                                              peek_normals(tx, ais.AIS_TX_NORMAL_DIMS), anchored)
        pure, sent = ais.transmit(params, pure, t, x, current, tx, anchored)
        np.testing.assert_array_equal(sent, want_sent)
        np.testing.assert_array_equal(tx[~sent], tx_before[~sent])  # drawn only to send
        for got, w in zip((pure.next_tx_s, pure.last_tx_s, pure.head, pure.buf_t_s, pure.buf),
                          want, strict=True):
            np.testing.assert_allclose(got, w, rtol=1e-14, atol=0.0)
        valid, stamp, fields, last_rx, in_flight = _reference_receive(
            params, pure, t, obs, tgt, x, peek_normals(rx, ais.AIS_RX_NORMAL_DIMS))
        pure, rep = ais.receive(params, pure, t, obs, tgt, x, rx)
        np.testing.assert_array_equal(rep.valid, valid)
        np.testing.assert_array_equal(rep.stamp_s, stamp)
        got = np.stack([rep.north_m, rep.east_m, rep.sog_mps, rep.cog_rad, rep.heading_rad], 1)
        np.testing.assert_allclose(got, fields, rtol=1e-14, atol=0.0)
        np.testing.assert_array_equal(pure.last_rx_s, last_rx)
        np.testing.assert_array_equal(rep.in_flight_s, in_flight)
        n_on_way += int(np.isfinite(in_flight).sum())
        live, rep_live = ais.step(params, live, t, obs, tgt, x, current, tx_live, rx_live,
                                  anchored, inplace=True, out=rep_live)
        for f in dataclasses.fields(rep):  # (written over the last step's: NaN kept)
            np.testing.assert_array_equal(getattr(rep_live, f.name), getattr(rep, f.name))
        np.testing.assert_array_equal(live.buf, pure.buf)
        n_received += int(valid.sum())
    assert 0 < n_received < 90 * obs.shape[0] and 0 < n_on_way < 90 * obs.shape[0]


@pytest.mark.parametrize("current_mps", [(0.0, 0.0), (0.4, -0.3)])
def test_compiled_schedule_on_the_speed_bin_boundaries(current_mps) -> None:
    """Speeds within a few ulps of 3, 14 and 23 kn, split over north and east at several
    angles, still and in a current: the compiled schedule, with its shortcut for ships that
    surely keep their interval, takes the same interval as the array formulas, step after
    step (the pending reports of 6 and 10 s are pulled forward or kept)."""
    speeds, angles, anchored = [], [], []
    for kn, anchor in ((3.0, True), (14.0, False), (23.0, False)):
        for ulps in range(-4, 5):
            for angle in (0.0, 0.3, math.pi / 4, 2.0):
                speeds.append(kn * KN * (1.0 + ulps * 2.0**-52))
                angles.append(angle)
                anchored.append(anchor)
    n = len(speeds)
    speed, angle = np.array(speeds), np.array(angles)
    x = np.zeros((N_STATE, n))  # heading 0: through the water north/east = surge/sway
    x[U], x[V] = speed * np.cos(angle), speed * np.sin(angle)
    params = ais.build([{"sigma_velocity_mps": 0.0}] * n)
    anchored = np.array(anchored)
    state, streams, current = ais.init(params, 0), independent_streams(n), np.zeros((2, n))
    current[0], current[1] = current_mps
    for t in range(12):
        x[U] *= 1.0 + 2.0**-50 if t % 2 else 1.0 - 2.0**-50  # across the boundaries and back
        want, want_sent = _reference_transmit(params, state, t, x, current,
                                              peek_normals(streams, 5), anchored)
        state, sent = ais.transmit(params, state, t, x, current, streams, anchored)
        np.testing.assert_array_equal(sent, want_sent)
        np.testing.assert_array_equal(state.next_tx_s, want[0])
    assert len(set(state.next_tx_s.tolist())) > 1  # both sides of the boundaries occur


@pytest.mark.parametrize("current_n", [0.5, -0.5, 0.0])
def test_compiled_schedule_in_a_current_along_the_track(current_n) -> None:
    """Ships sailing north with a current along or against them, their speed over ground
    within a few ulps of 14 and 23 kn: the interval follows the speed over ground as the array
    formulas do, step after step (the shortcut allows for the current's speed)."""
    base = np.array([14.0, 23.0]) * KN
    speed = np.concatenate([(base * (1.0 + u * 2.0**-52)) - current_n for u in range(-6, 7)])
    n = speed.size
    x = np.zeros((N_STATE, n))
    x[U] = speed
    params = ais.build([{"sigma_velocity_mps": 0.0}] * n)
    anchored = np.zeros(n, dtype=bool)
    state, streams, current = ais.init(params, 0), independent_streams(n), np.zeros((2, n))
    current[0] = current_n
    for t in range(12):
        x[U] *= 1.0 + 2.0**-50 if t % 2 else 1.0 - 2.0**-50
        want, want_sent = _reference_transmit(params, state, t, x, current,
                                              peek_normals(streams, 5), anchored)
        state, sent = ais.transmit(params, state, t, x, current, streams, anchored)
        np.testing.assert_array_equal(sent, want_sent)
        np.testing.assert_array_equal(state.next_tx_s, want[0])
    assert len(set(state.next_tx_s.tolist())) > 1


def test_reception_range_boundary_matches_array_formulas() -> None:
    """Targets within a few ulps of the 20 NM reception range, in several directions."""
    offsets = [(20.0 * 1852.0 * (1.0 + u * 2.0**-52), a) for u in range(-4, 5)
               for a in (0.0, 0.7, math.pi / 4, 3.0)]
    n_pairs = len(offsets)
    n = 2 * n_pairs
    params = ais.build([{"latency_s": 0.0}] * n)
    x, current, _ = _ships([10.0] * n)
    obs, tgt = np.arange(n_pairs), np.arange(n_pairs) + n_pairs
    x[NORTH, tgt] = [r * math.cos(a) for r, a in offsets]
    x[EAST, tgt] = [r * math.sin(a) for r, a in offsets]
    state, _ = ais.transmit(params, ais.init(params, n_pairs), 0.0, x, current,
                            independent_streams(n))
    rx = independent_streams(n_pairs, 1)
    valid, *_ = _reference_receive(params, state, 0.0, obs, tgt, x, peek_normals(rx, 1))
    _, rep = ais.receive(params, state, 0.0, obs, tgt, x, rx)
    np.testing.assert_array_equal(rep.valid, valid)
    assert 0 < valid.sum() < n_pairs


def _itu_table(kn: float, turning: bool, anchored: bool) -> float:
    """ITU-R M.1371-5 annex 1 table 1 (class A), one ship, written row by row."""
    if anchored:
        return 180.0 if kn <= 3.0 else 10.0
    if kn <= 14.0:
        return 10.0 / 3.0 if turning else 10.0
    if kn <= 23.0:
        return 2.0 if turning else 6.0
    return 2.0


def test_reporting_interval_matches_the_table_row_by_row() -> None:
    """Random speeds (plus the bin edges and a hair either side) in knots, turning and
    anchored flags: the vectorised intervals equal a row-by-row reading of the table."""
    rng = np.random.default_rng(30)
    edges = np.array([0.0, 3.0, 14.0, 23.0])
    kn = np.concatenate([rng.uniform(0.0, 40.0, 3000), edges, edges + 1e-9, edges - 1e-9])
    kn = np.abs(kn)
    turning = rng.random(kn.size) < 0.5
    anchored = rng.random(kn.size) < 0.3
    got = ais.reporting_interval_s(kn * KN, turning, anchored)
    want = [_itu_table(k, t, a) for k, t, a in zip(kn, turning, anchored, strict=True)]
    np.testing.assert_allclose(got, want, rtol=1e-15)
    # a scalar anchored flag applies to every ship
    np.testing.assert_array_equal(ais.reporting_interval_s(np.array([1.0, 10.0]) * KN,
                                                           np.array([True, False]), True),
                                  [180.0, 10.0])


def test_quantisers_round_to_the_nearest_step_and_are_idempotent() -> None:
    rng = np.random.default_rng(31)
    north, east = rng.uniform(-3e4, 3e4, (2, 2000))
    step_e = 0.1852 * math.cos(math.radians(48.0))
    qn, qe = ais.quantise_position(north, east, step_e)
    assert np.abs(qn - north).max() <= 0.1852 / 2 + 1e-9
    assert np.abs(qe - east).max() <= step_e / 2 + 1e-9
    np.testing.assert_array_equal(ais.quantise_position(qn, qe, step_e), (qn, qe))
    sog = rng.uniform(0.0, 50.0, 2000)
    qs = ais.quantise_sog(sog)
    assert np.abs(qs - sog).max() <= 0.05 * KN + 1e-12
    np.testing.assert_array_equal(ais.quantise_sog(qs), qs)
    # angles from several turns either way land in [0, 2 pi), within half a step (mod 2 pi)
    ang = rng.uniform(-20.0, 20.0, 2000)
    for step in (ais.COG_STEP_RAD, ais.HEADING_STEP_RAD):
        qa = ais.quantise_angle(ang, step)
        assert np.all((qa >= 0.0) & (qa < 2 * math.pi - step / 2))
        diff = np.mod(qa - ang + math.pi, 2 * math.pi) - math.pi
        assert np.abs(diff).max() <= step / 2 + 1e-9
        np.testing.assert_allclose(ais.quantise_angle(qa, step), qa, atol=1e-12)
    # by hand: 359.6 deg heading is 0 (360 wraps); -0.4 deg is 0; 0.5 + 1e-6 deg rounds to 1
    np.testing.assert_allclose(
        ais.quantise_angle(np.radians([359.6, -0.4, 0.500001]), ais.HEADING_STEP_RAD),
        np.radians([0.0, 0.0, 1.0]), atol=1e-12)


def test_first_report_time_and_disabled_ships() -> None:
    """The first report goes out on the first step at or after ``first_report_s``; a ship
    without transponder neither sends nor receives, and nothing is drawn for it."""
    params = ais.build([{"first_report_s": 2.5, "latency_s": 0.0},
                        {"enabled": False, "latency_s": 0.0}, {"latency_s": 0.0}])
    x, current, _ = _ships([10.0, 10.0, 10.0])
    x[NORTH] = [0.0, 500.0, 1000.0]
    obs, tgt = directed_pairs(np.array([0, 0, 1]), np.array([1, 2, 2]))
    state = ais.init(params, obs.shape[0])
    tx, rx = independent_streams(3, 2), independent_streams(obs.shape[0], 3)
    first = {}
    heard = np.zeros(obs.shape[0], dtype=int)
    for k in range(25):
        tx_before = tx.copy()
        state, sent = ais.transmit(params, state, 0.5 * k, x, current, tx)
        np.testing.assert_array_equal(tx[1], tx_before[1])
        for i in np.flatnonzero(sent):
            first.setdefault(int(i), 0.5 * k)
        state, rep = ais.receive(params, state, 0.5 * k, obs, tgt, x, rx)
        heard += rep.valid
    assert first == {0: 2.5, 2: 0.0}
    for k, (i, j) in enumerate(zip(obs, tgt, strict=True)):
        assert (heard[k] > 0) == (i != 1 and j != 1), (i, j)


def test_every_receiver_hears_the_same_report() -> None:
    """One noisy report per transmission, heard alike by every receiver (module docstring)."""
    n = 6
    params = ais.build([{"latency_s": 0.0}] * n)
    x, current, _ = _ships([12.0] * n, headings=np.linspace(0.0, 5.0, n))
    x[NORTH] = np.arange(n) * 300.0
    obs = np.arange(1, n)
    tgt = np.zeros(n - 1, dtype=int)
    state, rep = ais.step(params, ais.init(params, n - 1), 0.0, obs, tgt, x, current,
                          independent_streams(n, 4), independent_streams(n - 1, 5))
    assert rep.valid.all()
    for field in (rep.north_m, rep.east_m, rep.sog_mps, rep.cog_rad, rep.heading_rad):
        assert np.unique(field).size == 1
    assert rep.north_m[0] == state.buf[0, state.head[0], 0]


@pytest.mark.parametrize(("latency", "dt"), [
    *[(lat, dt) for lat in (10.0, 13.0) for dt in (0.5, 1.0, 1.5, 1.9)],
    (14.0, 0.5), (14.0, 1.0), (14.0, 1.5), (14.0, 1.9), (14.0, 2.0), (14.0, 5.0),
])
def test_latency_delivers_like_an_unbounded_history(latency: float, dt: float) -> None:
    """A 30 kn target reports every 2 s. At every step the receiver must get the newest report
    stamped after the last one it got, among those with ``stamp + latency <= t`` (module
    docstring), as an unbounded list of sent reports says, and be told the stamp of the
    oldest still on its way; ``build`` accepts latencies up to ``MAX_LATENCY_S`` (14 s) and
    the docstring calls them exact at the highest rate."""
    params = ais.build([{"latency_s": latency}] * 2)
    x, current, _ = _ships([0.0, 30.0])
    x[NORTH, 1] = 200.0
    obs, tgt = np.array([0]), np.array([1])
    state = ais.init(params, 1)
    tx, rx = independent_streams(2, 6), independent_streams(1, 7)
    stamps: list[float] = []
    last = -math.inf
    lost = []
    for k in range(round(80.0 / dt)):
        t = k * dt
        state, sent = ais.transmit(params, state, t, x, current, tx)
        if sent[1]:
            stamps.append(t)
        state, rep = ais.receive(params, state, t, obs, tgt, x, rx)
        arrived = [s for s in stamps if s > last and s + latency <= t + 1e-9]
        want = max(arrived) if arrived else None
        if want is not None:
            last = want
        got = float(rep.stamp_s[0]) if rep.valid[0] else None
        on_way = [s for s in stamps if s > last and s + latency > t + 1e-9]
        if got != want or rep.in_flight_s[0] != min(on_way, default=math.inf):
            lost.append((t, want, got))
    assert len(stamps) >= min(39, round(80.0 / dt) - 1)  # every 2 s, or every step if longer
    assert lost == []


@pytest.mark.parametrize(("cfg", "key"), [
    ({"sigma_position_m": -1.0}, "ais[1].sigma_position_m"),
    ({"sigma_velocity_mps": math.nan}, "ais[1].sigma_velocity_mps"),
    ({"sigma_heading_deg": "big"}, "ais[1].sigma_heading_deg"),
    ({"latency_s": -0.5}, "ais[1].latency_s"),
    ({"first_report_s": math.inf}, "ais[1].first_report_s"),
    ({"max_range_nm": -1.0}, "ais[1].max_range_nm"),
    ({"turn_rate_degps": -0.1}, "ais[1].turn_rate_degps"),
    ({"enabled": 1}, "ais[1].enabled"),
    ({"latency_s": 14.5}, "ais.latency_s"),
    ({"p_receive": 1.5}, "ais.p_receive"),
    ({"ref_latitude_deg": -90.0}, "ais.ref_latitude_deg"),
    ({"mmsi": 123}, "ais[1]"),
])
def test_config_errors_name_the_key(cfg, key) -> None:
    with pytest.raises(InputError) as err:
        ais.build([{}, cfg])
    assert err.value.key == key


@pytest.mark.parametrize(("key", "inside", "beyond", "message"), [
    ("sigma_position_m", 1000.0, 1001.0, "must be <= 1000, got 1001.0"),
    ("sigma_velocity_mps", 10.0, 10.5, "must be <= 10, got 10.5"),
    ("sigma_heading_deg", 30.0, 31.0, "must be <= 30, got 31.0"),
    ("max_range_nm", 200.0, 201.0, "must be <= 200, got 201.0"),
    ("turn_rate_degps", 30.0, 30.5, "must be <= 30, got 30.5"),
])
def test_physical_upper_bounds(key, inside, beyond, message) -> None:
    """Generous bounds no real transponder exceeds (module docstring): just inside is
    accepted, beyond is refused naming the ship and key."""
    assert_bound(ais.build, "ais", key, inside, beyond, message)


# ---------------------------------------------------------------- schedule changes, content


def _sent_steps(params, speed_kn, rate, anchored, steps, dt=1.0, current=None):
    """Step indices at which ship 0 reports; ``speed_kn``, ``rate`` and ``anchored`` are
    functions of the step index."""
    x = np.zeros((N_STATE, 1))
    cur = np.zeros((2, 1)) if current is None else np.asarray(current, dtype=float)
    state, streams, sent_at = ais.init(params, 0), independent_streams(1), []
    for k in range(steps):
        x[U, 0], x[R, 0] = speed_kn(k) * KN, rate(k)
        state, sent = ais.transmit(params, state, k * dt, x, cur, streams,
                                   np.array([anchored(k)]))
        if sent[0]:
            sent_at.append(k)
    return sent_at


def test_rate_increase_after_a_long_gap_sends_no_burst() -> None:
    """A ship at anchor reports every 3 min; it weighs anchor and sails at 10 kn from t = 30 s
    (10 s interval). The pending report is pulled forward to 0 + 10 s, already past, so it
    goes at once (t = 30); the station then reports every 10 s: 40, 50 (the pulled-forward
    schedule 10, 20, 30 never happened and is not replayed one report per step)."""
    params = ais.build([{}])
    got = _sent_steps(params, lambda k: 0.0 if k < 30 else 10.0, lambda k: 0.0,
                      lambda k: k < 30, 60)
    assert got == [0, 30, 40, 50]


def test_turn_starting_late_in_the_interval_keeps_the_turning_rate() -> None:
    """10 kn, report at 0, turning from t = 9 (interval 10 s -> 3 1/3 s): the report pulled to
    3.33 s goes at 9; after it the reports are one turning interval apart, each on the first
    1 s step at or after its time, so no two are closer than 3.33 - 1 = 2.33 s, and
    [9, 29] holds at most 1 + 20 / 3.33 = 7 reports."""
    params = ais.build([{}])
    got = _sent_steps(params, lambda k: 10.0, lambda k: TURN if k >= 9 else 0.0,
                      lambda k: False, 30)
    assert got[:2] == [0, 9]
    assert min(np.diff(got[1:])) >= 10.0 / 3.0 - 1.0
    assert len([k for k in got if k >= 9]) <= 7


def test_speed_up_pulls_the_pending_report_forward_into_the_future() -> None:
    """10 kn (10 s) with a report at 0, then 15 kn (6 s) from t = 3: the pending report moves
    from 10 to 0 + 6 = 6 and the reports follow every 6 s: 0, 6, 12, 18, 24."""
    params = ais.build([{}])
    got = _sent_steps(params, lambda k: 10.0 if k < 3 else 15.0, lambda k: 0.0,
                      lambda k: False, 25)
    assert got == [0, 6, 12, 18, 24]


def test_slowing_down_keeps_the_pending_report_then_lengthens() -> None:
    """15 kn (6 s) with reports at 0 and 6, then 10 kn (10 s) from t = 7: the report already
    scheduled at 12 is kept (only a shorter interval moves it), the next is 12 + 10 = 22."""
    params = ais.build([{}])
    got = _sent_steps(params, lambda k: 15.0 if k < 7 else 10.0, lambda k: 0.0,
                      lambda k: False, 33)
    assert got == [0, 6, 12, 22, 32]


@pytest.mark.parametrize(("factor", "expected"), [(1.0, [0, 10]), (-1.0, [0, 10]),
                                                  (1.0 + 1e-9, [0, 4, 7, 10]),
                                                  (-(1.0 + 1e-9), [0, 4, 7, 10])])
def test_changing_course_threshold_is_strict_and_either_way(factor, expected) -> None:
    """``turn_rate_degps`` 2: a rate of turn of exactly 2 deg/s (either way) is not changing
    course (10 s at 10 kn); a hair above is (3 1/3 s: reports at 0, 3.33 -> 4, 6.67 -> 7, 10)."""
    params = ais.build([{"turn_rate_degps": 2.0}])
    rate = factor * float(params.turn_rate_radps[0])
    got = _sent_steps(params, lambda k: 10.0, lambda k: rate, lambda k: False, 12)
    assert got == expected


def test_first_report_time_is_not_pulled_forward_by_a_turn() -> None:
    """Before the first report there is no last report to count an interval from: a turning
    ship with ``first_report_s`` 8 sends first at 8, then every 3 1/3 s (8, 11.33 -> 12,
    14.67 -> 15, 18)."""
    params = ais.build([{"first_report_s": 8.0}])
    got = _sent_steps(params, lambda k: 10.0, lambda k: TURN, lambda k: False, 19)
    assert got == [8, 12, 15, 18]


@pytest.mark.parametrize(("current_n", "expected"), [(0.3, [0, 6, 12]), (-0.3, [0, 10])])
def test_schedule_follows_speed_over_ground_in_a_current(current_n, expected) -> None:
    """13.8 kn through the water heading north; a 0.3 m/s (0.583 kn) current from astern makes
    14.38 kn over the ground (> 14 kn: 6 s), from ahead 13.22 kn (10 s)."""
    params = ais.build([{"sigma_velocity_mps": 0.0}])
    got = _sent_steps(params, lambda k: 13.8, lambda k: 0.0, lambda k: False, 13,
                      current=[[current_n], [0.0]])
    assert got == expected


def test_report_content_by_hand_in_a_current_at_latitude_60() -> None:
    """No noise; ship at (10 m, 10 m) heading 000 at 10 kn through the water in a 1 m/s east
    current, ``ref_latitude_deg`` 60 (east step 0.1852 cos 60 = 0.0926 m):
    north 10 / 0.1852 = 53.996 -> 54 steps = 10.0008 m; east 10 / 0.0926 = 107.99 -> 108 steps
    = 10.0008 m; SOG hypot(5.1444, 1) = 5.2407 m/s = 10.187 kn -> 10.2 kn; COG
    atan2(1, 5.1444) = 11.001 deg -> 11.0 deg; heading 000 -> 0."""
    params = ais.build([{"sigma_position_m": 0.0, "sigma_velocity_mps": 0.0,
                         "sigma_heading_deg": 0.0, "ref_latitude_deg": 60.0}])
    x = np.zeros((N_STATE, 1))
    x[NORTH], x[EAST], x[U] = 10.0, 10.0, 10.0 * KN
    state, sent = ais.transmit(params, ais.init(params, 0), 0.0, x, np.array([[0.0], [1.0]]),
                               independent_streams(1))
    assert sent[0]
    north, east, sog, cog, hdg = state.buf[0, state.head[0]]
    assert north == pytest.approx(54 * 0.1852, abs=1e-9)
    assert east == pytest.approx(108 * 0.0926, abs=1e-9)
    assert sog == pytest.approx(10.2 * KN, abs=1e-12)
    assert math.degrees(cog) == pytest.approx(11.0, abs=1e-9)
    assert hdg == 0.0


def test_reception_range_is_the_receivers() -> None:
    """Ship 0 hears to 5 NM, ship 1 to 20 NM, 10 NM apart: 1 hears 0, 0 does not hear 1."""
    params = ais.build([{"max_range_nm": 5.0, "latency_s": 0.0},
                        {"max_range_nm": 20.0, "latency_s": 0.0}])
    x = np.zeros((N_STATE, 2))
    x[EAST, 1] = 10.0 * 1852.0
    obs, tgt = directed_pairs(np.array([0]), np.array([1]))
    _, rep = ais.step(params, ais.init(params, 2), 0.0, obs, tgt, x, np.zeros((2, 2)),
                      independent_streams(2), independent_streams(2, 1))
    assert rep.valid.tolist() == [False, True]  # 0 <- 1 out of range; 1 <- 0 heard
    assert rep.stamp_s[1] == 0.0 and np.isnan(rep.stamp_s[0])


def test_reports_never_heard_still_draw_one_number_each() -> None:
    """``p_receive`` 0: nothing is ever received, yet every report that arrives takes one
    normal from the pair's stream (module docstring), so after N arrivals the stream stands
    where N draws would leave it. A 30 kn target reports every 2 s: 10 reports in 0..19 s."""
    params = ais.build([{"p_receive": 0.0, "latency_s": 1.0}] * 2)
    x = np.zeros((N_STATE, 2))
    x[U, 1], x[NORTH, 1] = 30.0 * KN, 500.0
    obs, tgt = np.array([0]), np.array([1])
    state, tx, rx = ais.init(params, 1), independent_streams(2, 8), independent_streams(1, 9)
    rx0 = rx.copy()
    arrived = 0
    for k in range(21):
        state, rep = ais.step(params, state, float(k), obs, tgt, x, np.zeros((2, 2)), tx, rx)
        assert not rep.valid[0]
        arrived += int(k >= 1 and (k - 1) % 2 == 0)  # stamps 0, 2, ... arrive 1 s later
    assert arrived == 10
    np.testing.assert_array_equal(peek_normals(rx, 1)[0, 0], peek_normals(rx0, 11)[0, 10])


def test_delivered_stamps_increase_and_match_the_transmitter_buffer() -> None:
    """Three transmitters with latencies 0, 2.5 and 7 s heard by one receiver over 60 s of
    0.5 s steps: per pair the delivered stamps strictly increase, each is a time at which that
    target sent, it arrived no earlier than stamp + latency and within one step of it (no
    report is lost with p_receive 1 and 2-10 s intervals longer than the step)."""
    lat = [0.0, 2.5, 7.0]
    params = ais.build([{"latency_s": 0.0}] + [{"latency_s": v} for v in lat])
    x = np.zeros((N_STATE, 4))
    x[U, 1:] = np.array([30.0, 18.0, 8.0]) * KN
    x[EAST, 1:] = [300.0, 600.0, 900.0]
    obs, tgt = np.zeros(3, dtype=np.int64), np.array([1, 2, 3])
    state, tx, rx = ais.init(params, 3), independent_streams(4, 10), independent_streams(3, 11)
    sent_at: list[list[float]] = [[], [], [], []]
    got: list[list[tuple[float, float]]] = [[], [], []]
    for k in range(121):
        t = 0.5 * k
        state, sent = ais.transmit(params, state, t, x, np.zeros((2, 4)), tx)
        for i in np.flatnonzero(sent):
            sent_at[i].append(t)
        state, rep = ais.receive(params, state, t, obs, tgt, x, rx)
        for p in np.flatnonzero(rep.valid):
            got[p].append((t, float(rep.stamp_s[p])))
    for p in range(3):
        stamps = [s for _, s in got[p]]
        assert np.all(np.diff(stamps) > 0)
        assert set(stamps) <= set(sent_at[p + 1])
        for t_rx, s in got[p]:
            assert s + lat[p] <= t_rx + 1e-9 < s + lat[p] + 0.5
        # every report whose arrival time has come was delivered
        assert stamps == [s for s in sent_at[p + 1] if s + lat[p] <= 60.0 + 1e-9]
