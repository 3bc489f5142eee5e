"""Bus messages as Foxglove's message schemas (protobuf), so Foxglove and Lichtblick show them.

Pure conversion, no files: :class:`FoxgloveScene` turns one decoded bus message into the
Foxglove messages that show it, and a site into the static scene (road, work zone, sensor
frames, geodetic origin). :mod:`wz_cli.foxglove` writes them into a recording.

Frames of reference
-------------------
- ``site``: the site frame (local ENU metres at the site's geodetic origin, z up); tracks,
  alerts and the road geometry are drawn in it.
- ``<sensor id>``: each sensor's own frame (x forward, y left, z up), placed in ``site`` by a
  ``foxglove.FrameTransform`` from the site file's mount pose; point clouds and images are in it.

Topics (all under :data:`TOPIC_PREFIX`)
---------------------------------------
``/foxglove/lidar/<sensor>`` ``PointCloud``, ``/foxglove/camera/<sensor>``
``CompressedImage``, ``/foxglove/tracks`` and ``/foxglove/alerts`` and ``/foxglove/truth``
``SceneUpdate``, ``/foxglove/site`` ``SceneUpdate`` (road geometry), ``/foxglove/tf``
``FrameTransform``, ``/foxglove/location/site`` and ``/foxglove/location/tracks``
``LocationFix``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from foxglove_schemas_protobuf.ArrowPrimitive_pb2 import ArrowPrimitive
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.TriangleListPrimitive_pb2 import TriangleListPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.duration_pb2 import Duration
from google.protobuf.message import Message as ProtoMessage
from google.protobuf.timestamp_pb2 import Timestamp

from wz_shared import codec
from wz_shared.messages import (
    Alert,
    AlertSeverity,
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    Track,
    TrackBatch,
    TrackStatus,
)
from wz_shared.site import AreaKind, Site

TOPIC_PREFIX = "/foxglove"
SITE_FRAME = "site"
TF_TOPIC = f"{TOPIC_PREFIX}/tf"
SITE_TOPIC = f"{TOPIC_PREFIX}/site"
TRACKS_TOPIC = f"{TOPIC_PREFIX}/tracks"
TRUTH_TOPIC = f"{TOPIC_PREFIX}/truth"
ALERTS_TOPIC = f"{TOPIC_PREFIX}/alerts"
SITE_LOCATION_TOPIC = f"{TOPIC_PREFIX}/location/site"
TRACKS_LOCATION_TOPIC = f"{TOPIC_PREFIX}/location/tracks"


def lidar_topic(sensor_id: str) -> str:
    return f"{TOPIC_PREFIX}/lidar/{sensor_id}"


def camera_topic(sensor_id: str) -> str:
    return f"{TOPIC_PREFIX}/camera/{sensor_id}"


#: Bytes per point of a LiDAR frame (x, y, z, intensity as float32), ours and Foxglove's.
POINT_STRIDE_BYTES = codec.POINT_FIELDS * codec.POINT_DTYPE.itemsize
#: A track without a size estimate is drawn as a passenger car [m].
DEFAULT_LENGTH_M, DEFAULT_WIDTH_M, DEFAULT_HEIGHT_M = 4.5, 1.8, 1.5
#: How long an alert marker stays without a newer event of its episode [s].
ALERT_MARKER_LIFETIME_S = 30.0
#: Spacing of the road-line vertices along the centerline [m]: curves stay smooth.
ROAD_LINE_STEP_M = 5.0
MPS_TO_MPH = 1.0 / 0.44704

_STATUS_COLOURS = {
    TrackStatus.TENTATIVE: (0.6, 0.6, 0.6, 0.5),
    TrackStatus.CONFIRMED: (0.1, 0.6, 1.0, 0.7),
    TrackStatus.COASTING: (0.9, 0.8, 0.2, 0.5),
}
_SEVERITY_COLOURS = {
    AlertSeverity.INFO: (0.2, 0.8, 1.0, 0.9),
    AlertSeverity.WARNING: (1.0, 0.6, 0.0, 0.9),
    AlertSeverity.CRITICAL: (1.0, 0.1, 0.1, 0.95),
}
_AREA_COLOURS = {
    AreaKind.ADVANCE_WARNING: (1.0, 0.9, 0.2, 0.25),
    AreaKind.TRANSITION: (1.0, 0.5, 0.0, 0.6),
    AreaKind.BUFFER: (1.0, 0.3, 0.0, 0.45),
    AreaKind.ACTIVITY: (0.9, 0.1, 0.1, 0.55),
    AreaKind.TERMINATION: (0.3, 0.9, 0.3, 0.3),
}


@dataclass(frozen=True)
class FoxgloveMessage:
    """One message for a Foxglove channel: its topic and protobuf message."""

    topic: str
    message: ProtoMessage


# --- small builders -------------------------------------------------------------------------


def timestamp(stamp_s: float) -> Timestamp:
    """A protobuf timestamp of a bus stamp [s]."""
    whole = math.floor(stamp_s)
    return Timestamp(seconds=whole, nanos=min(round((stamp_s - whole) * 1e9), 999_999_999))


def _colour(rgba: tuple[float, float, float, float]) -> Color:
    return Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def yaw_quaternion(yaw_rad: float) -> Quaternion:
    """Rotation by ``yaw_rad`` about z (counter-clockwise from the site x axis)."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw_rad), w=math.cos(0.5 * yaw_rad))


def rotation_quaternion(rotation: npt.NDArray[np.float64]) -> Quaternion:
    """The unit quaternion of a 3x3 rotation matrix (Shepperd's method, numerically stable)."""
    m = rotation
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        w, x, y, z = (
            0.25 * s,
            (m[2, 1] - m[1, 2]) / s,
            (m[0, 2] - m[2, 0]) / s,
            (m[1, 0] - m[0, 1]) / s,
        )
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (
            (m[2, 1] - m[1, 2]) / s,
            0.25 * s,
            (m[0, 1] + m[1, 0]) / s,
            (m[0, 2] + m[2, 0]) / s,
        )
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (
            (m[0, 2] - m[2, 0]) / s,
            (m[0, 1] + m[1, 0]) / s,
            0.25 * s,
            (m[1, 2] + m[2, 1]) / s,
        )
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (
            (m[1, 0] - m[0, 1]) / s,
            (m[0, 2] + m[2, 0]) / s,
            (m[1, 2] + m[2, 1]) / s,
            0.25 * s,
        )
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def _pose(x_m: float, y_m: float, z_m: float, yaw_rad: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x_m, y=y_m, z=z_m), orientation=yaw_quaternion(yaw_rad))


def _text(x_m: float, y_m: float, z_m: float, text: str, size: float = 14.0) -> TextPrimitive:
    return TextPrimitive(
        pose=_pose(x_m, y_m, z_m),
        billboard=True,
        font_size=size,
        scale_invariant=True,
        color=_colour((1.0, 1.0, 1.0, 1.0)),
        text=text,
    )


# --- frames ---------------------------------------------------------------------------------


def point_cloud(meta: LidarFrameMeta, points: npt.NDArray[np.float32]) -> PointCloud:
    """A LiDAR frame as ``foxglove.PointCloud`` in the sensor's frame.

    Parameters
    ----------
    meta : LidarFrameMeta
        The frame's metadata (stamp [s], sensor id).
    points : ndarray of float32, shape (num_points, 4)
        x, y, z [m] in the sensor frame and intensity; rows with a NaN coordinate (no-return
        cells of an organized frame) are left out.

    Returns
    -------
    PointCloud
        ``data`` packs the kept rows as they are (4 little-endian float32, stride 16 bytes).
    """
    kept = points[np.isfinite(points[:, :3]).all(axis=1)]
    fields = [
        PackedElementField(name=name, offset=4 * i, type=PackedElementField.FLOAT32)
        for i, name in enumerate(meta.fields)
    ]
    return PointCloud(
        timestamp=timestamp(meta.stamp),
        frame_id=meta.source_id,
        pose=_pose(0.0, 0.0, 0.0),
        point_stride=POINT_STRIDE_BYTES,
        fields=fields,
        data=np.ascontiguousarray(kept, dtype=codec.POINT_DTYPE).tobytes(),
    )


def compressed_image(meta: CameraFrameMeta, jpeg: bytes) -> CompressedImage:
    """A camera frame as ``foxglove.CompressedImage``: the JPEG bytes as they are."""
    return CompressedImage(
        timestamp=timestamp(meta.stamp), frame_id=meta.source_id, data=jpeg, format=meta.encoding
    )


# --- the scene ------------------------------------------------------------------------------


class FoxgloveScene:
    """Foxglove messages for bus messages, with a site's geometry where one is given.

    Parameters
    ----------
    site : Site or None
        The site of the recording: the road and work zone, the sensor mounts (transforms), the
        geodetic origin (location fixes) and the road frame (alert positions). None: frames,
        tracks and truth only.
    """

    def __init__(self, site: Site | None) -> None:
        self.site = site

    def _site_matches(self, site_id: str) -> bool:
        return self.site is not None and self.site.site_id == site_id

    # --- static ---

    def static(self, stamp_s: float) -> list[FoxgloveMessage]:
        """The site's scene at ``stamp_s`` [s]: sensor transforms, road geometry, origin fix."""
        if self.site is None:
            return []
        out = [FoxgloveMessage(TF_TOPIC, t) for t in self.sensor_transforms(stamp_s)]
        out.append(FoxgloveMessage(SITE_TOPIC, self.road_scene(stamp_s)))
        origin = self.site.origin
        out.append(
            FoxgloveMessage(
                SITE_LOCATION_TOPIC,
                LocationFix(
                    timestamp=timestamp(stamp_s),
                    frame_id=SITE_FRAME,
                    latitude=origin.latitude_deg,
                    longitude=origin.longitude_deg,
                    altitude=origin.altitude_m,
                    position_covariance_type=LocationFix.UNKNOWN,
                ),
            )
        )
        return out

    def sensor_transforms(self, stamp_s: float) -> list[FrameTransform]:
        """``site`` -> each sensor's frame, from the site file's mount poses."""
        assert self.site is not None
        return [
            FrameTransform(
                timestamp=timestamp(stamp_s),
                parent_frame_id=SITE_FRAME,
                child_frame_id=sensor.sensor_id,
                translation=Vector3(x=sensor.pose.x_m, y=sensor.pose.y_m, z=sensor.pose.z_m),
                rotation=rotation_quaternion(sensor.pose.rotation()),
            )
            for sensor in self.site.sensors
        ]

    def road_scene(self, stamp_s: float) -> SceneUpdate:
        """Lane lines, the closed lane through the taper, buffer and activity area, labels."""
        assert self.site is not None
        site = self.site
        road = site.road_frame
        stations = np.append(np.arange(0.0, road.length_m, ROAD_LINE_STEP_M), road.length_m)
        lines = []
        edges = sorted(
            {
                lane.center_offset_m + side * 0.5 * lane.width_m
                for lane in site.lanes
                for side in (-1, 1)
            }
        )
        for offset_m in edges:
            x, y = road.to_site(stations, np.full_like(stations, offset_m))
            lines.append(
                LinePrimitive(
                    type=LinePrimitive.LINE_STRIP,
                    pose=_pose(0.0, 0.0, 0.0),
                    thickness=0.15,
                    color=_colour((0.9, 0.9, 0.9, 1.0)),
                    points=[
                        Point3(x=float(a), y=float(b), z=0.0) for a, b in zip(x, y, strict=True)
                    ],
                )
            )
        entities = [
            SceneEntity(timestamp=timestamp(stamp_s), frame_id=SITE_FRAME, id="road", lines=lines)
        ]
        closed = site.lane(site.closed_lane_index)
        inner, outer = sorted(
            (
                closed.center_offset_m - 0.5 * closed.width_m,
                closed.center_offset_m + 0.5 * closed.width_m,
            ),
            key=lambda d: abs(d - float(np.mean([lane.center_offset_m for lane in site.lanes]))),
        )
        for area in site.work_zone:
            triangles = self._area_triangles(
                area.kind, area.start_station_m, area.end_station_m, inner, outer
            )
            mid_x, mid_y = road.to_site(0.5 * (area.start_station_m + area.end_station_m), outer)
            entities.append(
                SceneEntity(
                    timestamp=timestamp(stamp_s),
                    frame_id=SITE_FRAME,
                    id=f"area-{area.kind.value}",
                    triangles=[
                        TriangleListPrimitive(
                            pose=_pose(0.0, 0.0, 0.02),
                            color=_colour(_AREA_COLOURS[area.kind]),
                            points=triangles,
                        )
                    ],
                    texts=[
                        _text(float(mid_x), float(mid_y), 2.0, area.kind.value.replace("_", " "))
                    ],
                )
            )
        return SceneUpdate(entities=entities)

    def _area_triangles(
        self, kind: AreaKind, start_m: float, end_m: float, inner_m: float, outer_m: float
    ) -> list[Point3]:
        """Triangles covering the closed lane over ``[start_m, end_m]``.

        The transition area is the merging taper: closed from nothing at its start (the road
        edge) to the full lane at its end; the termination area tapers back open. Other areas
        are the whole lane's band.
        """
        assert self.site is not None
        road = self.site.road_frame
        stations = np.append(np.arange(start_m, end_m, ROAD_LINE_STEP_M), end_m)
        fraction = (stations - start_m) / (end_m - start_m)
        if kind == AreaKind.TRANSITION:
            near = outer_m + (inner_m - outer_m) * fraction
        elif kind == AreaKind.TERMINATION:
            near = inner_m + (outer_m - inner_m) * fraction
        else:
            near = np.full_like(stations, inner_m)
        ax, ay = road.to_site(stations, np.full_like(stations, outer_m))
        bx, by = road.to_site(stations, near)
        points: list[Point3] = []
        for i in range(len(stations) - 1):
            quad = [(ax[i], ay[i]), (bx[i], by[i]), (bx[i + 1], by[i + 1]), (ax[i + 1], ay[i + 1])]
            for j in (0, 1, 2, 0, 2, 3):
                points.append(Point3(x=float(quad[j][0]), y=float(quad[j][1]), z=0.0))
        return points

    # --- per message ---

    def tracks(self, batch: TrackBatch) -> list[FoxgloveMessage]:
        """A cube, a velocity arrow and a label per track (the previous batch's removed), and
        a location fix per confirmed track where the site's origin is known."""
        entities = [self._track_entity(batch.stamp, track) for track in batch.tracks]
        update = SceneUpdate(
            deletions=[
                SceneEntityDeletion(timestamp=timestamp(batch.stamp), type=SceneEntityDeletion.ALL)
            ],
            entities=entities,
        )
        out = [FoxgloveMessage(TRACKS_TOPIC, update)]
        if self._site_matches(batch.site):
            assert self.site is not None
            confirmed = [t for t in batch.tracks if t.confirmed]
            if confirmed:
                lat, lon, alt = self.site.geo_frame.to_wgs84(
                    [t.x_m for t in confirmed], [t.y_m for t in confirmed]
                )
                for i, track in enumerate(confirmed):
                    out.append(
                        FoxgloveMessage(
                            TRACKS_LOCATION_TOPIC,
                            LocationFix(
                                timestamp=timestamp(batch.stamp),
                                frame_id=f"track-{track.track_id}",
                                latitude=float(lat[i]),
                                longitude=float(lon[i]),
                                altitude=float(alt[i]),
                                heading=math.degrees(0.5 * math.pi - track.heading_rad) % 360.0,
                                position_covariance=_position_covariance(track),
                                position_covariance_type=LocationFix.DIAGONAL_KNOWN,
                            ),
                        )
                    )
        return out

    def _track_entity(self, stamp_s: float, track: Track) -> SceneEntity:
        length_m = track.length_m or DEFAULT_LENGTH_M
        width_m = track.width_m or DEFAULT_WIDTH_M
        heading = (
            math.atan2(track.vy_mps, track.vx_mps) if track.speed_mps > 0.5 else track.heading_rad
        )
        colour = _colour(_STATUS_COLOURS[track.status])
        return SceneEntity(
            timestamp=timestamp(stamp_s),
            frame_id=SITE_FRAME,
            id=f"track-{track.track_id}",
            cubes=[
                CubePrimitive(
                    pose=_pose(track.x_m, track.y_m, 0.5 * DEFAULT_HEIGHT_M, track.heading_rad),
                    size=Vector3(x=length_m, y=width_m, z=DEFAULT_HEIGHT_M),
                    color=colour,
                )
            ],
            arrows=[
                ArrowPrimitive(
                    pose=_pose(track.x_m, track.y_m, DEFAULT_HEIGHT_M, heading),
                    shaft_length=max(0.1, track.speed_mps * 0.5),  # where it is in 0.5 s
                    shaft_diameter=0.2,
                    head_length=0.8,
                    head_diameter=0.6,
                    color=colour,
                )
            ],
            texts=[
                _text(
                    track.x_m,
                    track.y_m,
                    DEFAULT_HEIGHT_M + 1.5,
                    f"#{track.track_id} {track.speed_mps * MPS_TO_MPH:.0f} mph",
                )
            ],
        )

    def truth(self, truth: GroundTruth) -> list[FoxgloveMessage]:
        """The simulated vehicles as wire-frame boxes (true size and heading)."""
        entities = [
            SceneEntity(
                timestamp=timestamp(truth.stamp),
                frame_id=SITE_FRAME,
                id=f"truth-{vehicle.vehicle_id}",
                cubes=[
                    CubePrimitive(
                        pose=_pose(
                            vehicle.x_m,
                            vehicle.y_m,
                            vehicle.z_m + 0.5 * vehicle.height_m,
                            vehicle.heading_rad,
                        ),
                        size=Vector3(x=vehicle.length_m, y=vehicle.width_m, z=vehicle.height_m),
                        color=_colour((0.3, 1.0, 0.3, 0.25)),
                    )
                ],
            )
            for vehicle in truth.vehicles
        ]
        deletion = SceneEntityDeletion(
            timestamp=timestamp(truth.stamp), type=SceneEntityDeletion.ALL
        )
        return [FoxgloveMessage(TRUTH_TOPIC, SceneUpdate(deletions=[deletion], entities=entities))]

    def alert(self, alert: Alert) -> list[FoxgloveMessage]:
        """A marker per open alert episode (a sphere coloured by severity and a label); a
        clear removes it. Placed at the track's position, or at the alert's station and
        offset where the site is known; otherwise nothing to draw."""
        entity_id = f"alert-{alert.episode_id or alert.alert_id}"
        if alert.phase == "clear":
            deletion = SceneEntityDeletion(
                timestamp=timestamp(alert.stamp), type=SceneEntityDeletion.MATCHING_ID, id=entity_id
            )
            return [FoxgloveMessage(ALERTS_TOPIC, SceneUpdate(deletions=[deletion]))]
        position = self._alert_position(alert)
        if position is None:
            return []
        x_m, y_m = position
        colour = _colour(_SEVERITY_COLOURS[alert.severity])
        entity = SceneEntity(
            timestamp=timestamp(alert.stamp),
            frame_id=SITE_FRAME,
            id=entity_id,
            lifetime=Duration(seconds=int(ALERT_MARKER_LIFETIME_S)),
            spheres=[
                SpherePrimitive(
                    pose=_pose(x_m, y_m, 4.0), size=Vector3(x=1.5, y=1.5, z=1.5), color=colour
                )
            ],
            texts=[
                _text(x_m, y_m, 6.0, f"{alert.alert_type.value} ({alert.severity.value})", 16.0)
            ],
        )
        return [FoxgloveMessage(ALERTS_TOPIC, SceneUpdate(entities=[entity]))]

    def _alert_position(self, alert: Alert) -> tuple[float, float] | None:
        if alert.track is not None:
            return alert.track.x_m, alert.track.y_m
        if self._site_matches(alert.site):
            assert self.site is not None
            x, y = self.site.road_frame.to_site(alert.station_m, alert.offset_m)
            return float(x), float(y)
        return None


def _position_covariance(track: Track) -> Sequence[float]:
    """East/north/up covariance [m^2], row-major 3x3, diagonal: the track's x, y variances."""
    return [track.covariance[0], 0.0, 0.0, 0.0, track.covariance[5], 0.0, 0.0, 0.0, 0.0]
