"""What the API shows that is assembled from several stored things: the live tracks, the
sensors' self-calibration and the WZDx device feed. Reads storage, calls the pure cores (:mod:`wz_gateway.traffic`,
:mod:`wz_gateway.wzdx`), returns values.

Time: stamps are capture times; in simulation they count from the start of the run, so the
feed dates them by the newest track batch's arrival: ``unix = stamp + (received_at - stamp)``
of that batch (:func:`stamp_offset_s`); stamps already in Unix time (after 2001) are kept.
"""

from __future__ import annotations

import logging
from typing import Any, TypeVar

import numpy as np
from pydantic import ValidationError

from wz_gateway.lane_sight import lane_hidden_shares, sight_station_range
from wz_gateway.models import (
    CalibrationStateChange,
    LiveTrack,
    LiveTracks,
    SensorCalibrationStatus,
    SiteCalibration,
)
from wz_gateway.storage import Storage
from wz_gateway.store_types import LatestRow
from wz_gateway.traffic import TrafficSummary, find_crossings, summarize
from wz_gateway.wzdx import (
    CalibrationRules,
    DeviceHealth,
    FeedInputs,
    combine,
    detector_lanes,
    detector_station_m,
    device_feed,
    device_link_health,
    frames_health,
    freshness,
    service_health,
    traffic_mast,
)
from wz_shared.keys import Keys
from wz_shared.messages import (
    BEACON_DEVICE,
    SIGN_DEVICE,
    Message,
    PointSensorReading,
    RoadsideDeviceState,
    SensorCalibration,
    ServiceStatus,
    TrackBatch,
)
from wz_shared.site import Site

log = logging.getLogger(__name__)
M = TypeVar("M", bound=Message)

#: Stamps at or above this are Unix time (2001-09-09), below it simulation time.
UNIX_STAMP_MIN = 1e9
#: Services whose status the feed reads (their names in ``wz up`` and on the bus).
LIDAR_SERVICE = "lidar-detector"
CAMERA_SERVICE = "camera-detector"
ALERT_SERVICE = "alert-service"
DEVICE_DRIVER = "device-driver"
#: Points this far either side of the detector are read to find crossings [m].
_CROSSING_REACH_M = 60.0


def stamp_offset_s(tracks: LatestRow | None) -> float:
    """Unix time minus capture stamp, from the newest track batch (0 for Unix stamps)."""
    if tracks is None or tracks.stamp >= UNIX_STAMP_MIN:
        return 0.0
    return tracks.received_at - tracks.stamp


def live_tracks(storage: Storage, site: Site, now: float) -> LiveTracks:
    """The newest track batch, with WGS84 positions; empty before the first."""
    row = storage.latest(site.site_id, "tracks")
    if row is None:
        return LiveTracks(site=site.site_id, stamp=None, cycle_index=None, age_s=None, tracks=[])
    batch = TrackBatch.model_validate_json(row.body)
    tracks: list[LiveTrack] = []
    if batch.tracks:
        latitude, longitude, _ = site.geo_frame.to_wgs84(
            np.array([t.x_m for t in batch.tracks]), np.array([t.y_m for t in batch.tracks])
        )
        tracks = [
            LiveTrack(**t.model_dump(), latitude_deg=float(lat), longitude_deg=float(lon))
            for t, lat, lon in zip(batch.tracks, latitude, longitude, strict=True)
        ]
    return LiveTracks(
        site=site.site_id,
        stamp=batch.stamp,
        cycle_index=batch.cycle_index,
        age_s=max(0.0, now - row.received_at),
        tracks=tracks,
    )


def _statuses(storage: Storage, site: Site) -> dict[str, tuple[ServiceStatus, float]]:
    found: dict[str, tuple[ServiceStatus, float]] = {}
    for service, row in storage.latest_statuses(site.site_id).items():
        try:
            found[service] = (ServiceStatus.model_validate_json(row.body), row.received_at)
        except ValidationError:  # written by an older gateway: not worth failing the feed
            log.warning("stored status of %s is unreadable; ignored", service)
    return found


def _by_sensor(rows: dict[str, LatestRow], model: type[M]) -> dict[str, tuple[M, float]]:
    """Stored latest messages by sensor id, with when each arrived [Unix s]."""
    found: dict[str, tuple[M, float]] = {}
    for sensor_id, row in rows.items():
        try:
            found[sensor_id] = (model.model_validate_json(row.body), row.received_at)
        except ValidationError:  # written by another version: not worth failing the answer
            log.warning("stored %s of %s is unreadable; ignored", model.__name__, sensor_id)
    return found


def calibrations(storage: Storage, site: Site) -> dict[str, tuple[SensorCalibration, float]]:
    """Each sensor's newest self-calibration at ``site`` and when it arrived [Unix s]."""
    return _by_sensor(storage.latest_calibrations(site.site_id), SensorCalibration)


def point_readings(storage: Storage, site: Site) -> dict[str, tuple[PointSensorReading, float]]:
    """Each upstream point speed sensor's newest reading at ``site`` and when it arrived."""
    return _by_sensor(storage.latest_point_readings(site.site_id), PointSensorReading)


def site_calibration(
    storage: Storage, site: Site, *, now: float, stale_after_s: float, changes: int
) -> SiteCalibration:
    """Every sensor's self-calibration: the site file's sensors in order (those never heard
    from without a message), then any other sensor heard from; with its newest ``changes``
    changes of state."""
    latest = calibrations(storage, site)
    history = storage.calibration_changes(site.site_id, per_sensor=changes)
    kinds = {sensor.sensor_id: sensor.kind for sensor in site.sensors}
    for sensor_id, (heard, _) in latest.items():
        kinds.setdefault(sensor_id, heard.sensor_kind)
    sensors = []
    for sensor_id, kind in kinds.items():
        message, received_at = latest.get(sensor_id) or (None, None)
        age_s = None if received_at is None else max(0.0, now - received_at)
        sensors.append(
            SensorCalibrationStatus(
                sensor_id=sensor_id,
                sensor_kind=kind,
                calibration=message,
                received_at=received_at,
                age_s=age_s,
                stale=age_s is not None and age_s > stale_after_s,
                changes=[
                    CalibrationStateChange(
                        state=change.state,
                        previous_state=change.previous_state,
                        stamp=change.stamp,
                        state_since_s=change.state_since_s,
                        detail=change.detail,
                        received_at=change.received_at,
                    )
                    for change in history.get(sensor_id, [])
                ],
            )
        )
    return SiteCalibration(site=site.site_id, sensors=sensors)


def traffic_summary(
    storage: Storage,
    site: Site,
    tracks: LatestRow | None,
    interval_s: float,
    detector_override_m: float | None,
) -> TrafficSummary | None:
    """Counts over the newest ``interval_s`` of stamps (shorter at the start of a run)."""
    if tracks is None:
        return None
    end = tracks.stamp
    start = max(end - interval_s, 0.0)
    run_start = storage.latest(site.site_id, "run_start")
    if run_start is not None and run_start.stamp <= end:
        start = max(start, run_start.stamp)  # the current run only
    if end - start < 1.0:
        return None
    station = detector_station_m(site, detector_override_m)
    sight_from, sight_to = sight_station_range(site, station)
    points = storage.traffic_points(
        site.site_id,
        start - 5.0,
        end,
        min(station - _CROSSING_REACH_M, sight_from),
        max(station + _CROSSING_REACH_M, sight_to),
        received_since=None if run_start is None else run_start.received_at,
    )
    crossings = find_crossings(
        points.track_id,
        points.stamp,
        points.station_m,
        detector_lanes(site, points.station_m, points.offset_m, points.vx_mps, points.vy_mps),
        points.speed_mps,
        points.length_m,
        station,
    )
    lanes = sorted(lane.index for lane in site.lanes)
    in_sight = (points.station_m >= sight_from) & (points.station_m <= sight_to)
    hidden_shares = lane_hidden_shares(
        site,
        station,
        points.stamp[in_sight],
        points.x_m[in_sight],
        points.y_m[in_sight],
        points.heading_rad[in_sight],
        points.length_m[in_sight],
        points.width_m[in_sight],
        [kind for kind, keep in zip(points.object_class, in_sight, strict=True) if keep],
        start,
        end,
    )
    return summarize(crossings, start, end, lanes, station, hidden_shares=hidden_shares)


def device_feed_of(
    storage: Storage,
    site: Site,
    *,
    now: float,
    publisher: str,
    stale_after_s: float,
    traffic_interval_s: float,
    detector_station_override_m: float | None = None,
    contact_email: str | None = None,
    calibration_rules: CalibrationRules | None = None,
) -> dict[str, Any]:
    """The site's WZDx 4.2 DeviceFeed as of ``now`` (wall clock, Unix s)."""
    keys = Keys(site.site_id)
    tracks = storage.latest(site.site_id, "tracks")
    statuses = _statuses(storage, site)
    devices_row = storage.latest(site.site_id, "devices")
    devices = (
        None if devices_row is None else RoadsideDeviceState.model_validate_json(devices_row.body)
    )
    mast = traffic_mast(site)
    traffic_parts: list[DeviceHealth] = [
        freshness(
            "track batches", None if tracks is None else tracks.received_at, now, stale_after_s
        ),
    ]
    if mast is not None and mast.kind == "lidar":
        traffic_parts.append(
            frames_health(
                LIDAR_SERVICE,
                statuses.get(LIDAR_SERVICE),
                keys.raw_lidar(mast.sensor_id),
                now,
                stale_after_s,
                missing="warning",
            )
        )
    cameras = {
        sensor.sensor_id: frames_health(
            CAMERA_SERVICE,
            statuses.get(CAMERA_SERVICE),
            keys.raw_camera(sensor.sensor_id),
            now,
            stale_after_s,
        )
        for sensor in site.sensors
        if sensor.kind == "camera"
    }
    inputs = FeedInputs(
        site=site,
        now=now,
        publisher=publisher,
        traffic=traffic_summary(
            storage, site, tracks, traffic_interval_s, detector_station_override_m
        ),
        traffic_health=combine(*traffic_parts),
        cameras=cameras,
        devices=devices,
        devices_health=service_health(
            ALERT_SERVICE, statuses.get(ALERT_SERVICE), now, stale_after_s
        ),
        sign_health=device_link_health(
            DEVICE_DRIVER, statuses.get(DEVICE_DRIVER), SIGN_DEVICE, now, stale_after_s
        ),
        beacon_health=device_link_health(
            DEVICE_DRIVER, statuses.get(DEVICE_DRIVER), BEACON_DEVICE, now, stale_after_s
        ),
        stamp_offset_s=stamp_offset_s(tracks),
        traffic_interval_s=traffic_interval_s,
        contact_email=contact_email,
        calibrations=calibrations(storage, site),
        point_readings=point_readings(storage, site),
        calibration_rules=calibration_rules or CalibrationRules(),
    )
    return device_feed(inputs)


def merge_device_feeds(feeds: list[dict[str, Any]]) -> dict[str, Any]:
    """One DeviceFeed of several sites' (a central gateway): their features, and one data
    source per site in ``feed_info`` (each feature's ``data_source_id`` names its own)."""
    if len(feeds) == 1:
        return feeds[0]
    merged = {**feeds[0], "feed_info": dict(feeds[0]["feed_info"])}
    merged["feed_info"]["data_sources"] = [
        source for feed in feeds for source in feed["feed_info"]["data_sources"]
    ]
    merged["features"] = [feature for feed in feeds for feature in feed["features"]]
    return merged
