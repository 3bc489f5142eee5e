"""Lane-level counts of the fused tracks against the truth, at the gateway's traffic detector.

The WZDx device feed's traffic sensor (``wz_gateway.wzdx``) reports per lane a volume, an
average speed and an occupancy, counted where the stored tracks cross a virtual loop at
:func:`~wz_gateway.wzdx.detector_station_m`. This module counts the same way twice over one
scored interval: on the track batches the tracker publishes (what the gateway stores) and on
the simulation's truth (every vehicle, 20 Hz), with the gateway's own
:func:`~wz_gateway.traffic.find_crossings` and :func:`~wz_gateway.traffic.summarize`. The
issue's target: each lane's volume within 5 % of the truth count.

A vehicle counts in the lane its centre is in at the crossing, the truth's and the track's
alike (:func:`~wz_gateway.wzdx.detector_lanes`; not SUMO's lane attribute, which switches at
its own point of a lane change); a truth vehicle counted in the other lane by the tracks is a lane error
even when the station totals agree, so the report gives both.

Each lane also carries the share of the interval its loop spot was hidden from the sensors
(:func:`~wz_gateway.lane_sight.lane_hidden_shares`, from the same batches) and whether the
gateway would call its volume reliable: the target holds when every reliable lane is within
5 %, and the report says whether every lane off by more was marked unreliable.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from wz_gateway.lane_sight import lane_hidden_shares, sight_station_range
from wz_gateway.traffic import (
    Crossings,
    LaneTraffic,
    TrafficSummary,
    find_crossings,
    summarize,
)
from wz_gateway.wzdx import detector_lane_index, detector_lanes, detector_station_m, lane_order
from wz_shared.messages import TrackBatch, VehicleTruth
from wz_shared.site import Site

#: The issue's tolerance on each lane's volume [fraction of the truth count].
VOLUME_TOLERANCE = 0.05


def track_crossings(site: Site, batches: Sequence[TrackBatch], station_m: float) -> Crossings:
    """Where the published tracks cross ``station_m``, in the lanes the gateway counts them
    in (:func:`~wz_gateway.wzdx.detector_lanes`)."""
    rows = [
        (t.track_id, b.stamp, t.station_m, t.offset_m, t.vx_mps, t.vy_mps, t.speed_mps,
         t.length_m or np.nan)
        for b in batches
        for t in b.tracks
    ]  # fmt: skip
    ids, stamps, stations, offsets, vx, vy, speeds, lengths = _columns(rows, 8)
    lanes = detector_lanes(site, stations, offsets, vx, vy)
    return find_crossings(ids, stamps, stations, lanes, speeds, lengths, station_m)


def hidden_shares(
    site: Site, batches: Sequence[TrackBatch], station_m: float, start_s: float, end_s: float
) -> dict[int, float]:
    """Each lane's hidden share of ``[start_s, end_s]`` at the loop, from the published tracks
    between the loop and the sensors (as the gateway measures it)."""
    low, high = sight_station_range(site, station_m)
    rows = [
        (b.stamp, t.x_m, t.y_m, t.heading_rad, t.length_m or np.nan, t.width_m or np.nan,
         str(t.object_class))
        for b in batches
        if start_s <= b.stamp <= end_s
        for t in b.tracks
        if low <= t.station_m <= high
    ]  # fmt: skip
    stamps, x, y, heading, length, width, kinds = _columns(rows, 7)
    return lane_hidden_shares(
        site, station_m, stamps, x, y, heading, length, width, list(kinds), start_s, end_s
    )


def truth_crossings(
    site: Site, truth: Sequence[tuple[float, list[VehicleTruth]]], station_m: float
) -> Crossings:
    """Where the simulated vehicles cross ``station_m``, each in the lane its centre is in
    (:func:`~wz_gateway.wzdx.detector_lane_index`, as the tracks are counted): SUMO's own
    lane switches at its own point of a lane change, a loop counts where the vehicle is."""
    numbers: dict[str, int] = {}  # the truth's ids are names; crossings take integers
    rows = [
        (
            numbers.setdefault(v.vehicle_id, len(numbers)),
            stamp,
            v.station_m,
            v.offset_m,
            v.speed_mps,
            v.length_m,
        )
        for stamp, vehicles in truth
        for v in vehicles
    ]
    ids, stamps, stations, offsets, speeds, lengths = _columns(rows, 6)
    lanes = detector_lane_index(site, offsets)
    return find_crossings(ids, stamps, stations, lanes, speeds, lengths, station_m)


def _columns(rows: list[tuple[Any, ...]], n: int) -> list[np.ndarray]:
    if not rows:
        return [np.zeros(0) for _ in range(n)]
    return [np.asarray(column) for column in zip(*rows, strict=True)]


def lane_volume_report(
    site: Site,
    batches: Sequence[TrackBatch],
    truth: Sequence[tuple[float, list[VehicleTruth]]],
    start_s: float,
    end_s: float,
    station_override_m: float | None = None,
) -> dict[str, Any]:
    """Per lane (WZDx order, 1 at the left): the truth's and the tracks' vehicles over
    ``[start_s, end_s]``, the volume error and whether it is within :data:`VOLUME_TOLERANCE`;
    the same for the station and the speeds' mean difference."""
    station = detector_station_m(site, station_override_m)
    lanes = sorted(lane.index for lane in site.lanes)
    shares = hidden_shares(site, batches, station, start_s, end_s)
    measured = summarize(
        track_crossings(site, batches, station), start_s, end_s, lanes, station,
        hidden_shares=shares,
    )  # fmt: skip
    expected = summarize(truth_crossings(site, truth, station), start_s, end_s, lanes, station)
    rows = [
        _row(lane_order(site, got.lane_index), got.vehicles, want.vehicles, got, want)
        for got, want in zip(measured.lanes, expected.lanes, strict=True)
    ]
    rows.sort(key=lambda row: row["lane_order"])
    return {
        "detector_station_m": round(station, 1),
        "interval_s": round(end_s - start_s, 1),
        "lanes": rows,
        "station": _row(None, measured.vehicles, expected.vehicles, measured, expected),
        "tolerance": VOLUME_TOLERANCE,
        # The target: every lane the sensors see within the tolerance, and every lane off by
        # more marked unreliable (the gateway withholds its volume).
        "holds": all(row["holds"] for row in rows if row["reliable"]),
        "off_lanes_marked": all(row["reliable"] is False for row in rows if not row["holds"]),
    }


def _row(
    order: int | None,
    got: int,
    want: int,
    measured: LaneTraffic | TrafficSummary,
    expected: LaneTraffic | TrafficSummary,
) -> dict[str, Any]:
    error = (got - want) / want if want else (0.0 if got == 0 else None)
    speeds = (measured.average_speed_mps, expected.average_speed_mps)
    return {
        "lane_order": order,
        "truth_vehicles": want,
        "track_vehicles": got,
        "truth_volume_vph": round(expected.volume_vph, 1),
        "track_volume_vph": round(measured.volume_vph, 1),
        "volume_error": None if error is None else round(error, 4),
        "speed_difference_mps": (
            None if None in speeds else round(speeds[0] - speeds[1], 2)  # type: ignore[operator]
        ),
        "holds": error is not None and abs(error) <= VOLUME_TOLERANCE,
        "hidden_share": (
            round(measured.hidden_share, 3)
            if isinstance(measured, LaneTraffic) and measured.hidden_share is not None
            else None
        ),
        "reliable": measured.reliable if isinstance(measured, LaneTraffic) else None,
    }
