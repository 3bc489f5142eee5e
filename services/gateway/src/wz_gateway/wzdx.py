"""The WZDx 4.2 DeviceFeed of a site: pure, no I/O.

A DeviceFeed is a GeoJSON FeatureCollection of FieldDevice features. This site's are:

- a **traffic sensor** at the LiDAR mast: volume, average speed and occupancy per lane over
  the newest collection interval, counted at a virtual detector from the fused trajectories
  (:mod:`wz_gateway.traffic`);
- each **camera** on the mast;
- the **flashing beacon** and the **dynamic message sign** that the alert service drives,
  at the sign's station on the right shoulder.

Each device's ``device_status`` comes from how fresh its data is (:func:`freshness`): ``ok``,
``error`` when its data or its service's status stopped arriving (``status_messages`` says
which and for how long), ``warning`` when part of it is missing (a LiDAR with no frames behind
a tracker that still runs), ``unknown`` before anything arrived. A sensor's self-calibration
(:func:`calibration_health`) makes its device ``warning`` at least while the sensor is
``bumped`` (knocked: its pose is being learned again and its detections weigh less), or
``prior`` or ``learning`` for longer than :attr:`CalibrationRules.learning_warning_s`: WZDx's
"functional but impaired". A camera is its own device; the LiDARs and the radars count
through the traffic sensor, whose counts come from their fused tracks. Units are WZDx's:
km/h, vehicles per hour, percent; dates are RFC 3339 UTC.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from wz_gateway.traffic import LaneTraffic, TrafficSummary
from wz_shared.coverage import lidar_beam_rows
from wz_shared.messages import (
    BEACON_DEVICE,
    SIGN_DEVICE,
    AlertType,
    CalibrationState,
    PointSensorReading,
    RoadsideDeviceState,
    SensorCalibration,
    ServiceState,
    ServiceStatus,
)
from wz_shared.site import AreaKind, Lane, SensorMount, Site

WZDX_VERSION = "4.2"
CC0_LICENSE = "https://creativecommons.org/publicdomain/zero/1.0/"
#: How often the feed's content changes [s] (it is computed on each request; the traffic
#: sensor's interval moves with every tracker cycle).
UPDATE_FREQUENCY_S = 1
MPS_TO_KPH = 3.6
#: The sign and beacon stand this far right of the right lane's edge [m].
SHOULDER_OFFSET_M = 3.0
#: A track sliding across the road faster than this follows no vehicle [m/s]: a lane change
#: peaks at 1-1.5 m/s (the tracker's ``hand_over_max_lateral_speed_mps``).
MAX_LATERAL_SPEED_MPS = 2.5
#: Spacing of the stations :func:`detector_station_m` tries [m].
DETECTOR_SEARCH_STEP_M = 1.0
#: Every lane must be seen this far either side of the detector's station [m]: a car's length
#: (4.5 m) and a little.
DETECTOR_CAR_REACH_M = 5.0
_NAMESPACE = uuid.UUID("6f0f3a3e-5b7e-4c55-9d0a-2a7f4f1c9b21")
_WORK_ZONE_NAMESPACE = uuid.UUID("0b1e9a57-61c3-4d0e-8a8e-5c1f7b3d2a90")

DeviceStatus = Literal["ok", "warning", "error", "unknown"]
_RANK: dict[DeviceStatus, int] = {"ok": 0, "unknown": 1, "warning": 2, "error": 3}


@dataclass(frozen=True)
class DeviceHealth:
    """A device's status, why, and when its information was last confirmed (Unix s)."""

    status: DeviceStatus
    messages: tuple[str, ...] = ()
    updated_at: float = 0.0


def freshness(
    what: str,
    received_at: float | None,
    now: float,
    stale_after_s: float,
    *,
    stale: DeviceStatus = "error",
) -> DeviceHealth:
    """``ok`` if ``what`` arrived within ``stale_after_s`` of ``now`` (wall clock [s])."""
    if received_at is None:
        return DeviceHealth("unknown", (f"no {what} received yet",), now)
    age_s = now - received_at
    if age_s > stale_after_s:
        return DeviceHealth(stale, (f"no {what} for {age_s:.0f} s",), received_at)
    return DeviceHealth("ok", (), received_at)


def combine(*healths: DeviceHealth) -> DeviceHealth:
    """The worst status of several, with every message; dated by the oldest confirmation."""
    worst = max(healths, key=lambda h: _RANK[h.status])
    messages = tuple(m for h in healths for m in h.messages)
    return DeviceHealth(worst.status, messages, min(h.updated_at for h in healths))


def service_health(
    service: str, status: tuple[ServiceStatus, float] | None, now: float, stale_after_s: float
) -> DeviceHealth:
    """Whether ``service`` reports its status (``status`` is the newest and its arrival) and
    its loop goes round (a ``stalled`` status: the process lives, its work does not)."""
    health = freshness(
        f"status from {service}", None if status is None else status[1], now, stale_after_s
    )
    if health.status == "ok" and status is not None and status[0].state == ServiceState.STALLED:
        age_s = status[0].loop_age_s or 0.0
        return DeviceHealth("error", (f"{service} stalled: no work for {age_s:.0f} s",), status[1])
    return health


def device_link_health(
    service: str,
    status: tuple[ServiceStatus, float] | None,
    device: str,
    now: float,
    stale_after_s: float,
) -> DeviceHealth | None:
    """Whether a real field device answers its driver (``service``'s status names it under
    ``device``: :data:`~wz_shared.messages.SIGN_DEVICE`,
    :data:`~wz_shared.messages.BEACON_DEVICE`); None where no driver reports one (the device
    is the alert service's state alone, as in simulation)."""
    if status is None or device not in status[0].devices:
        return None
    alive = service_health(service, status, now, stale_after_s)
    if alive.status != "ok":
        return alive
    link = status[0].devices[device]
    if link.reachable is False:
        since = "" if link.answer_age_s is None else f" (last answer {link.answer_age_s:.0f} s ago)"
        return DeviceHealth(
            "error", (f"{device} at {link.address} not answering: {link.detail}{since}",), status[1]
        )
    if link.reachable is None:
        return DeviceHealth(
            "unknown", (f"{device} at {link.address} not contacted yet",), status[1]
        )
    return alive


def frames_health(
    service: str,
    status: tuple[ServiceStatus, float] | None,
    key: str,
    now: float,
    stale_after_s: float,
    *,
    missing: DeviceStatus = "error",
) -> DeviceHealth:
    """Whether ``service`` is alive and receives frames on ``key`` (from its status)."""
    alive = service_health(service, status, now, stale_after_s)
    if alive.status != "ok" or status is None:
        return DeviceHealth(
            missing if alive.status == "error" else alive.status, alive.messages, alive.updated_at
        )
    if status[0].received_hz.get(key, 0.0) <= 0.0:
        return DeviceHealth(missing, (f"{service} receives no frames on {key}",), status[1])
    return alive


@dataclass(frozen=True)
class CalibrationRules:
    """When a sensor's self-calibration makes its device ``warning``.

    Attributes
    ----------
    stale_after_s : float
        A calibration received longer ago than this is not judged [s of wall clock]: the
        device's freshness already says when its detector stopped.
    learning_warning_s : float
        ``prior`` or ``learning`` for longer than this is a warning [s of the sensor's time].
    """

    stale_after_s: float = 30.0
    learning_warning_s: float = 900.0


def calibration_health(
    sensor_id: str,
    calibration: tuple[SensorCalibration, float] | None,
    now: float,
    rules: CalibrationRules,
) -> DeviceHealth | None:
    """What the sensor's newest self-calibration (and its arrival [Unix s]) says of its
    device, or None when it says nothing (calibrated, still learning within
    ``rules.learning_warning_s``, none received, or received too long ago)."""
    if calibration is None:
        return None
    message, received_at = calibration
    if now - received_at > rules.stale_after_s:
        return None
    in_state_s = max(0.0, message.stamp - message.state_since_s)
    name = f"{message.sensor_kind} {sensor_id}"
    why = f" ({message.detail})" if message.detail else ""
    if message.state == CalibrationState.BUMPED:
        return DeviceHealth(
            "warning",
            (
                f"{name} moved {_duration(in_state_s)} ago{why}: its pose is being re-learned; "
                "its detections are down-weighted",
            ),
            received_at,
        )
    if in_state_s <= rules.learning_warning_s:
        return None
    if message.state == CalibrationState.LEARNING:
        return DeviceHealth(
            "warning",
            (
                f"{name} still learning its pose after {_duration(in_state_s)}{why}: its "
                "detections are down-weighted until it is calibrated",
            ),
            received_at,
        )
    if message.state == CalibrationState.PRIOR:
        return DeviceHealth(
            "warning",
            (
                f"{name} has learned nothing of its pose in {_duration(in_state_s)}{why}: the "
                "site file's pose is used",
            ),
            received_at,
        )
    return None


def _duration(seconds: float) -> str:
    """``40 s``, ``12 min``, ``3 h``."""
    if seconds < 120.0:
        return f"{seconds:.0f} s"
    if seconds < 7200.0:
        return f"{seconds / 60.0:.0f} min"
    return f"{seconds / 3600.0:.0f} h"


@dataclass(frozen=True)
class FeedInputs:
    """Everything the feed shows, gathered by the caller.

    ``stamp_to_unix`` maps a capture stamp to Unix time (in simulation the stamps count from
    the start of the run); ``now`` is the wall clock [Unix s].
    """

    site: Site
    now: float
    publisher: str
    traffic: TrafficSummary | None
    traffic_health: DeviceHealth
    cameras: dict[str, DeviceHealth]
    devices: RoadsideDeviceState | None
    devices_health: DeviceHealth
    #: The real sign's and beacon relay's links, from their driver's status (None: no driver
    #: reports one).
    sign_health: DeviceHealth | None = None
    beacon_health: DeviceHealth | None = None
    stamp_offset_s: float = 0.0
    traffic_interval_s: float = 300.0
    contact_email: str | None = None
    #: Each sensor's newest self-calibration and its arrival [Unix s], by sensor id.
    calibrations: dict[str, tuple[SensorCalibration, float]] = field(default_factory=dict)
    calibration_rules: CalibrationRules = field(default_factory=CalibrationRules)
    #: Each upstream point speed sensor's newest reading and its arrival [Unix s], by id.
    point_readings: dict[str, tuple[PointSensorReading, float]] = field(default_factory=dict)

    def calibration_health(self, sensor_id: str) -> DeviceHealth | None:
        """:func:`calibration_health` of one sensor."""
        return calibration_health(
            sensor_id, self.calibrations.get(sensor_id), self.now, self.calibration_rules
        )


def rfc3339(unix_s: float) -> str:
    """``2025-06-12T14:03:07Z`` (UTC, whole seconds)."""
    return datetime.fromtimestamp(unix_s, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def device_id(site: Site, name: str) -> str:
    """A stable UUID for a device of a site (RFC 4122 version 5)."""
    return str(uuid.uuid5(_NAMESPACE, f"{site.site_id}/{name}"))


def work_zone_event_id(site: Site) -> str:
    """The id of the site's work-zone road event (the WorkZoneFeed's,
    :mod:`wz_gateway.wzdx_workzone`), which every device names: stable, a UUID (RFC 4122)."""
    return str(uuid.uuid5(_WORK_ZONE_NAMESPACE, f"{site.site_id}/work-zone"))


def data_source_id(site: Site) -> str:
    return str(uuid.uuid5(_NAMESPACE, f"{site.site_id}/gateway"))


def _point(site: Site, x_m: float, y_m: float) -> dict[str, Any]:
    latitude, longitude, _ = site.geo_frame.to_wgs84(x_m, y_m)
    return {"type": "Point", "coordinates": [round(float(longitude), 7), round(float(latitude), 7)]}


def _core(
    site: Site, device_type: str, name: str, health: DeviceHealth, description: str
) -> dict[str, Any]:
    core: dict[str, Any] = {
        "device_type": device_type,
        "data_source_id": data_source_id(site),
        "device_status": health.status,
        "update_date": rfc3339(health.updated_at),
        "has_automatic_location": False,
        "road_direction": site.road_direction,
        "road_names": list(site.road_names) or [site.name],
        "name": name,
        "description": description,
        "is_moving": False,
        "road_event_ids": [work_zone_event_id(site)],
    }
    if health.messages:
        core["status_messages"] = list(health.messages)
    return core


def traffic_mast(site: Site) -> SensorMount | None:
    """The mount the traffic sensor is reported at: the first LiDAR, else the first sensor."""
    lidars = [s for s in site.sensors if s.kind == "lidar"]
    candidates = lidars or site.sensors
    return candidates[0] if candidates else None


def detector_station_m(site: Site, override_m: float | None = None) -> float:
    """Station of the virtual traffic detector, a loop across every lane [m].

    It goes where the site's LiDARs see a car in *every* lane best: of the stations upstream
    of the taper (every lane still open) and of the LiDAR (where the camera and radar, facing
    the traffic, see too), the one where the lane seen worst gets the most
    beam rows from its best LiDAR (:func:`~wz_shared.coverage.lidar_beam_rows`, a car at the
    lane's centre). The tracker acquires vehicles as they come into the LiDAR's view, so a
    loop there counts vehicles it has followed for a while; one placed where the far lane
    falls between two beams, or before the LiDAR's view, counts only what the camera kept.
    On the generated sites checked that is 9-46 m upstream of the mast: nearer, the near
    lane drops under the beams' fan. Without a LiDAR, or where none reaches a lane: 30 m upstream of the first
    sensor. ``override_m`` (the gateway's setting) wins.
    """
    if override_m is not None:
        return override_m
    best = _best_lidar_station_m(site)
    if best is not None:
        return best
    mast = traffic_mast(site)
    if mast is None:
        return site.area(AreaKind.ADVANCE_WARNING).start_station_m
    station, _ = site.road_frame.to_road(mast.pose.x_m, mast.pose.y_m)
    return max(0.0, float(station) - 30.0)


def _best_lidar_station_m(site: Site) -> float | None:
    """The station of :func:`detector_station_m`'s LiDAR rule; None if no LiDAR sees every
    lane anywhere upstream of the taper."""
    lidars = [mount for mount in site.sensors if mount.kind == "lidar"]
    if not lidars:
        return None
    frame = site.road_frame
    mast_m = max(float(frame.to_road(m.pose.x_m, m.pose.y_m)[0]) for m in lidars)
    end_m = min(site.area(AreaKind.TRANSITION).start_station_m, mast_m, frame.length_m)
    stations = np.arange(0.0, end_m + 1e-9, DETECTOR_SEARCH_STEP_M)
    worst_lane = np.full(stations.shape, np.inf)
    for lane in site.lanes:
        x, y = frame.to_site(stations, np.full(stations.shape, lane.center_offset_m))
        rows = np.max([lidar_beam_rows(mount, x, y) for mount in lidars], axis=0)
        worst_lane = np.minimum(worst_lane, rows)
    # The least over a car's length either side: the loop must be seen all across a passing
    # car, and the best single station often sits at the edge where the near lane drops
    # under the beams' fan.
    reach = round(DETECTOR_CAR_REACH_M / DETECTOR_SEARCH_STEP_M)
    padded = np.pad(worst_lane, reach, constant_values=0.0)
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * reach + 1)
    robust = windows.min(axis=1)
    best = int(np.argmax(robust))
    if not robust[best] >= 1.0:  # no station where a beam is sure to cross every lane's car
        return None
    return float(stations[best])


def detector_lanes(
    site: Site,
    station_m: npt.ArrayLike,
    offset_m: npt.ArrayLike,
    vx_mps: npt.ArrayLike,
    vy_mps: npt.ArrayLike,
) -> npt.NDArray[np.intp]:
    """The lane the loop counts each track point in (:func:`detector_lane_index`), or none
    (-1) for a point sliding across the road faster than
    :data:`MAX_LATERAL_SPEED_MPS`: a coasting track whose velocity points off the road
    follows no vehicle, and would be counted in each lane it slides through."""
    velocity = np.stack([np.asarray(vx_mps, np.float64), np.asarray(vy_mps, np.float64)], -1)
    across = np.einsum("...k,...k->...", velocity, site.road_frame.normal_at(station_m))
    lanes = detector_lane_index(site, offset_m)
    lanes[np.abs(across) > MAX_LATERAL_SPEED_MPS] = -1
    return lanes


def detector_lane_index(site: Site, offset_m: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """The lane a loop across the road counts a vehicle at each offset in [site index].

    The lane holding the offset (:meth:`~wz_shared.site.Site.lane_index_at`); a vehicle up to
    half a lane outside the outermost lanes counts in that lane, since a loop covers its lanes
    whole and a track's lateral error is largest at the far edge (a LiDAR there sees only the
    vehicle's near face); beyond that, none (-1).
    """
    offset = np.asarray(offset_m, dtype=np.float64)
    index = site.lane_index_at(offset)
    for lane in (min(site.lanes, key=_right_edge), max(site.lanes, key=_left_edge)):
        half = 0.5 * lane.width_m
        beyond = (index < 0) & (np.abs(offset - lane.center_offset_m) < 2.0 * half)
        index[beyond] = lane.index
    return index


def _right_edge(lane: Lane) -> float:
    return lane.center_offset_m - 0.5 * lane.width_m


def _left_edge(lane: Lane) -> float:
    return lane.center_offset_m + 0.5 * lane.width_m


def lane_order(site: Site, lane_index: int) -> int:
    """WZDx numbers lanes from 1 at the left; the site from 0 at the right."""
    return len(site.lanes) - lane_index


def _round(value: float) -> float:
    return round(value, 1)


def traffic_sensor_feature(inputs: FeedInputs) -> dict[str, Any] | None:
    site = inputs.site
    mast = traffic_mast(site)
    if mast is None:
        return None
    summary = inputs.traffic
    if summary is not None:
        start = summary.start_stamp + inputs.stamp_offset_s
        end = summary.end_stamp + inputs.stamp_offset_s
    else:
        start, end = inputs.now - inputs.traffic_interval_s, inputs.now
    # The LiDARs and radars have no device of their own: their tracks make the counts.
    calibration = [
        health
        for sensor in site.sensors
        if sensor.kind != "camera"
        and (health := inputs.calibration_health(sensor.sensor_id)) is not None
    ]
    health = combine(inputs.traffic_health, *calibration)
    hidden = [] if summary is None else [lane for lane in summary.lanes if not lane.reliable]
    if hidden:
        health = combine(health, _hidden_lanes_health(site, hidden, inputs.now))
    properties: dict[str, Any] = {
        "core_details": _core(
            site,
            "traffic-sensor",
            f"Traffic sensor at {mast.sensor_id}",
            health,
            "Volumes, speeds and occupancy per lane, counted at a virtual loop detector from "
            "the fused LiDAR, camera and radar trajectories"
            + ("" if summary is None else f" (station {summary.detector_station_m:.0f} m)"),
        ),
        "collection_interval_start_date": rfc3339(start),
        "collection_interval_end_date": rfc3339(end),
    }
    if summary is not None:
        if summary.average_speed_mps is not None:
            properties["average_speed_kph"] = _round(summary.average_speed_mps * MPS_TO_KPH)
        if not hidden:  # the station's figures add up every lane's
            properties["volume_vph"] = _round(summary.volume_vph)
            properties["occupancy_percent"] = _round(summary.occupancy_percent)
        lane_data = []
        for lane in sorted(summary.lanes, key=lambda lane: lane_order(site, lane.lane_index)):
            entry: dict[str, Any] = {"lane_order": lane_order(site, lane.lane_index)}
            if lane.reliable:  # a hidden lane's count and occupancy fall short: withheld
                entry["volume_vph"] = _round(lane.volume_vph)
                entry["occupancy_percent"] = _round(lane.occupancy_percent)
            if lane.average_speed_mps is not None:
                entry["average_speed_kph"] = _round(lane.average_speed_mps * MPS_TO_KPH)
            lane_data.append(entry)
        properties["lane_data"] = lane_data
    return {
        "id": device_id(site, f"traffic-sensor/{mast.sensor_id}"),
        "type": "Feature",
        "properties": properties,
        "geometry": _point(site, mast.pose.x_m, mast.pose.y_m),
    }


#: A point sensor's reading is current for this many of its intervals after it ended.
POINT_FRESH_INTERVALS = 2.5


def point_sensor_features(inputs: FeedInputs) -> list[dict[str, Any]]:
    """A WZDx traffic sensor for each upstream point speed sensor of the site file, from its
    newest reading: per lane the volume (the interval's count per hour), the mean speed and
    the occupancy; the station's the lanes' sum, their count-weighted speed and mean
    occupancy. ``unknown`` before any reading; ``error`` once the newest is older than
    :data:`POINT_FRESH_INTERVALS` intervals (the sensor or its link has failed)."""
    site = inputs.site
    features = []
    for sensor in site.point_sensors:
        heard = inputs.point_readings.get(sensor.sensor_id)
        properties: dict[str, Any]
        if heard is None:
            health = DeviceHealth("unknown", ("no reading heard yet",), inputs.now)
            start, end = inputs.now - sensor.interval_s, inputs.now
        else:
            reading, received_at = heard
            age_s = inputs.now - received_at
            health = DeviceHealth("ok", (), received_at)
            if age_s > POINT_FRESH_INTERVALS * sensor.interval_s:
                health = DeviceHealth("error", (f"no reading for {_duration(age_s)}",), received_at)
            end = reading.stamp + inputs.stamp_offset_s
            start = end - reading.interval_s
        properties = {
            "core_details": _core(
                site,
                "traffic-sensor",
                f"Point speed sensor {sensor.sensor_id}",
                health,
                f"Upstream point speed sensor at station {sensor.station_m:.0f} m: per lane, "
                f"the vehicles passing, their mean speed and the occupancy every "
                f"{sensor.interval_s:.0f} s",
            ),
            "collection_interval_start_date": rfc3339(start),
            "collection_interval_end_date": rfc3339(end),
        }
        if heard is not None:
            properties.update(_point_lane_data(site, heard[0]))
        x, y = site.road_frame.to_site(sensor.station_m, 0.0)
        features.append(
            {
                "id": device_id(site, f"point-sensor/{sensor.sensor_id}"),
                "type": "Feature",
                "properties": properties,
                "geometry": _point(site, float(x), float(y)),
            }
        )
    return features


def _point_lane_data(site: Site, reading: PointSensorReading) -> dict[str, Any]:
    """A point sensor's reading as a WZDx traffic sensor's station and ``lane_data`` figures."""
    per_hour = 3600.0 / reading.interval_s
    lanes = sorted(reading.lanes, key=lambda lane: lane_order(site, lane.lane_index))
    lane_data = []
    for lane in lanes:
        entry: dict[str, Any] = {
            "lane_order": lane_order(site, lane.lane_index),
            "volume_vph": _round(lane.vehicle_count * per_hour),
            "occupancy_percent": _round(lane.occupancy_percent),
        }
        if lane.mean_speed_mps is not None:
            entry["average_speed_kph"] = _round(lane.mean_speed_mps * MPS_TO_KPH)
        lane_data.append(entry)
    out: dict[str, Any] = {"lane_data": lane_data}
    count = sum(lane.vehicle_count for lane in lanes)
    if lanes:
        out["volume_vph"] = _round(count * per_hour)
        out["occupancy_percent"] = _round(
            sum(lane.occupancy_percent for lane in lanes) / len(lanes)
        )
    if count:
        speed = sum(lane.vehicle_count * (lane.mean_speed_mps or 0.0) for lane in lanes) / count
        out["average_speed_kph"] = _round(speed * MPS_TO_KPH)
    return out


def _hidden_lanes_health(site: Site, lanes: list[LaneTraffic], now: float) -> DeviceHealth:
    """A warning for lanes whose loop spot other vehicles hid longer than
    :data:`~wz_gateway.traffic.HIDDEN_SHARE_LIMIT` of the interval: their volume and
    occupancy are withheld, and the station's with them (:mod:`wz_gateway.lane_sight`)."""
    messages = tuple(
        f"lane {lane_order(site, lane.lane_index)} volume withheld: hidden from the sensors "
        f"{100.0 * (lane.hidden_share or 0.0):.0f} % of the interval (by other vehicles, or out "
        "of view)"
        for lane in sorted(lanes, key=lambda lane: lane_order(site, lane.lane_index))
    )
    return DeviceHealth("warning", messages, now)


def camera_features(inputs: FeedInputs) -> list[dict[str, Any]]:
    site = inputs.site
    features = []
    for camera in (s for s in site.sensors if s.kind == "camera"):
        health = inputs.cameras.get(camera.sensor_id, DeviceHealth("unknown", (), inputs.now))
        calibration = inputs.calibration_health(camera.sensor_id)
        if calibration is not None:
            health = combine(health, calibration)
        features.append(
            {
                "id": device_id(site, f"camera/{camera.sensor_id}"),
                "type": "Feature",
                "properties": {
                    "core_details": _core(
                        site,
                        "camera",
                        f"Camera {camera.sensor_id}",
                        health,
                        "Mast camera watching the approach to the work zone",
                    ),
                },
                "geometry": _point(site, camera.pose.x_m, camera.pose.y_m),
            }
        )
    return features


def sign_position(site: Site) -> tuple[float, float]:
    """Site-frame position [m] of the sign and beacon: on the right shoulder at their station."""
    station = site.alerts.devices.sign_station_m
    if station is None:
        station = site.area(AreaKind.ADVANCE_WARNING).start_station_m
    right = min(site.lanes, key=lambda lane: lane.index)
    offset = right.center_offset_m - right.width_m / 2.0 - SHOULDER_OFFSET_M
    x, y = site.road_frame.to_site(station, offset)
    return float(x), float(y)


def _beacon_function(devices: RoadsideDeviceState | None) -> str:
    if devices is not None and devices.cause is AlertType.QUEUE:
        return "queue-warning"
    return "reduced-speed"


def multi(text: str) -> str:
    """Sign text as a MULTI string (NTCIP 1203): lines joined with ``[nl]``, brackets doubled."""
    escaped = text.replace("[", "[[").replace("]", "]]")
    return "[nl]".join(line.strip() for line in escaped.splitlines())


def roadside_features(inputs: FeedInputs) -> list[dict[str, Any]]:
    site = inputs.site
    geometry = _point(site, *sign_position(site))
    devices = inputs.devices
    health = inputs.devices_health
    if devices is None and health.status == "ok":
        health = DeviceHealth("unknown", ("no device state received yet",), health.updated_at)
    beacon_health = (
        health if inputs.beacon_health is None else combine(health, inputs.beacon_health)
    )
    beacon = {
        "id": device_id(site, BEACON_DEVICE),
        "type": "Feature",
        "properties": {
            "core_details": _core(
                site,
                BEACON_DEVICE,
                "Flashing beacon",
                beacon_health,
                "Flashes while an alert concerns drivers approaching the work zone",
            ),
            "function": _beacon_function(devices),
            "is_flashing": bool(devices is not None and devices.beacon_on),
        },
        "geometry": geometry,
    }
    sign_health = health if inputs.sign_health is None else combine(health, inputs.sign_health)
    sign = {
        "id": device_id(site, SIGN_DEVICE),
        "type": "Feature",
        "properties": {
            "core_details": _core(
                site,
                SIGN_DEVICE,
                "Portable message sign",
                sign_health,
                "Shows the warning of the highest-priority open alert",
            ),
            "message_multi_string": multi(devices.sign_text) if devices is not None else "",
        },
        "geometry": geometry,
    }
    return [beacon, sign]


def device_feed(inputs: FeedInputs) -> dict[str, Any]:
    """The WZDx 4.2 DeviceFeed (a JSON-ready dict)."""
    site = inputs.site
    features: list[dict[str, Any]] = []
    traffic = traffic_sensor_feature(inputs)
    if traffic is not None:
        features.append(traffic)
    features += point_sensor_features(inputs)
    features += camera_features(inputs)
    features += roadside_features(inputs)
    source: dict[str, Any] = {
        "data_source_id": data_source_id(site),
        "organization_name": inputs.publisher,
        "update_date": rfc3339(inputs.now),
        "update_frequency": UPDATE_FREQUENCY_S,
    }
    feed_info: dict[str, Any] = {
        "publisher": inputs.publisher,
        "version": WZDX_VERSION,
        "license": CC0_LICENSE,
        "update_date": rfc3339(inputs.now),
        "update_frequency": UPDATE_FREQUENCY_S,
        "data_sources": [source],
    }
    if inputs.contact_email:
        feed_info["contact_email"] = inputs.contact_email
        source["contact_email"] = inputs.contact_email
    return {"feed_info": feed_info, "type": "FeatureCollection", "features": features}
