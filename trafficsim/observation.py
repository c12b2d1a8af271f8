"""Observations of other ships: radar/ARPA plots and AIS reports feeding one tracker per pair.

Every ordered pair (observer, target) of ships in the same encounter is one track
(:func:`trafficsim.sensors.radar.directed_pairs`). A ship observes with the ``radar`` and
``ais`` of its ``sensors:`` (a ship without an ``ais`` section carries no transponder, one
without ``radar`` has no radar); ``tracker`` tunes its tracker
(:mod:`trafficsim.estimation.tracker`). Radar plots are placed on the chart with the observer's
own estimated position and heading, so own navigation errors reach the tracks.

Random draws: every directed pair has its own ``radar`` and ``ais_rx`` streams, keyed by
(encounter, observer, purpose, target) within the encounter; each ship's ``ais`` stream holds its
transmitter's noise. A pair's numbers therefore depend only on its two ships, never on the rest
of the batch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.estimation import tracker
from trafficsim.noise import NoiseBank
from trafficsim.sensors import ais, radar
from trafficsim.ships.base import EAST, NORTH, PSI


def observes(configs: Sequence[Mapping[str, Any]]) -> bool:
    """Whether any ship carries radar or AIS."""
    return any(c.get("radar") is not None or c.get("ais") is not None for c in configs)


@dataclass
class Observation:
    """Radar, AIS and tracks of every directed pair ``(m,)`` of a batch."""

    obs: np.ndarray  # (m,) observer ship
    tgt: np.ndarray  # (m,) target ship
    radar_p: radar.RadarParams
    radar_s: radar.RadarState
    ais_p: ais.AisParams
    ais_s: ais.AisState
    tracker_p: tracker.TrackerParams
    tracks: tracker.TrackState
    banks: dict[str, NoiseBank]
    has_radar: bool
    has_ais: bool
    settings: tuple[np.ndarray, np.ndarray]  # observers' tracker settings, per pair
    nothing_in_flight: np.ndarray  # (m,) +inf: no AIS report on its way (a batch without AIS)
    ais_reports: ais.AisReports | None = None  # this step's, overwritten at the next

    @classmethod
    def build(cls, configs: Sequence[Mapping[str, Any]], pair_i: np.ndarray,
              pair_j: np.ndarray, seed: int, encounter: Sequence[int],
              ship_in_encounter: np.ndarray) -> Observation:
        """Instruments and tracks for the directed pairs of ``pair_i < pair_j``."""
        obs, tgt = radar.directed_pairs(pair_i, pair_j)
        slot = np.asarray(ship_in_encounter)
        enc = np.asarray(encounter)

        def section(name: str) -> list[dict[str, Any]]:
            return [dict(c[name] or {}) if c.get(name) is not None else {"enabled": False}
                    for c in configs]

        radar_p, ais_p = radar.build(section("radar")), ais.build(section("ais"))

        def pair_bank(purpose: str, dims: int) -> NoiseBank:
            return NoiseBank(seed, enc[obs], slot[obs], purpose, dims, other=slot[tgt])

        banks = {
            "radar": pair_bank(radar.RADAR_PURPOSE, radar.RADAR_NORMAL_DIMS),
            "ais_rx": pair_bank("ais_rx", ais.AIS_RX_NORMAL_DIMS),
            "ais": NoiseBank(seed, enc, slot, ais.AIS_PURPOSE, ais.AIS_TX_NORMAL_DIMS),
        }
        tracker_p = tracker.build([dict(c.get("tracker") or {}) for c in configs])
        return cls(obs=obs, tgt=tgt,
                   radar_p=radar_p, radar_s=radar.init(radar_p), ais_p=ais_p,
                   ais_s=ais.init(ais_p, obs.shape[0]),
                   tracker_p=tracker_p, tracks=tracker.init(obs.shape[0]), banks=banks,
                   has_radar=any(c.get("radar") is not None for c in configs),
                   has_ais=any(c.get("ais") is not None for c in configs),
                   settings=tracker.pair_settings(tracker_p, obs),
                   nothing_in_flight=np.full(obs.shape[0], np.inf))

    def update(self, x: np.ndarray, est: np.ndarray, current_ne: np.ndarray, t_s: float
               ) -> None:
        """Observe at time ``t_s``: ``x`` true ``(8, n)``, ``est`` own estimates ``(6, n)``,
        ``current_ne`` current at each ship ``(2, n)``. Compiled loops over ships and pairs
        (radar scan and plots, AIS transmission and reception, tracker) update the state in
        place; radar and AIS draw their noise at need, only for scans and reports."""
        plots = reports = None
        if self.has_radar:
            self.radar_s, due = radar.scan_due(self.radar_p, self.radar_s, t_s)
            if due.any():  # (between scans there are no plots: the tracker skips radar)
                plots = radar.measure(self.radar_p, due, self.obs, self.tgt, x, est[NORTH],
                                      est[EAST], est[PSI], self.banks["radar"].state, t_s)
        if self.has_ais:
            self.ais_s, reports = ais.step(
                self.ais_p, self.ais_s, t_s, self.obs, self.tgt, x, current_ne,
                self.banks["ais"].state, self.banks["ais_rx"].state, inplace=True,
                out=self.ais_reports)
            self.ais_reports = reports
        self.tracks = tracker.step(
            self.tracker_p, self.tracks, self.obs, t_s, plots, reports, inplace=True,
            settings=self.settings,
            in_flight_s=reports.in_flight_s if reports is not None else self.nothing_in_flight)

    def predicted_tracks(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Tracks predicted to ``t_s``: state ``(m, 4)`` north, east, v_north, v_east and
        ``active`` ``(m,)``."""
        return tracker.predict_state(self.tracks, t_s), self.tracks.active
