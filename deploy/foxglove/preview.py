"""Draw what a converted recording's Foxglove channels hold (docs/images/foxglove-preview.png).

NOT a Foxglove screenshot: matplotlib draws the decoded Foxglove messages (the point cloud
placed by its FrameTransform, the road and work-zone SceneUpdate, the track and alert
SceneUpdates, the CompressedImage), as a Foxglove-compatible viewer would show them.

Usage::

    python deploy/foxglove/preview.py OUT.png [--recording FOXGLOVE.mcap]

Without ``--recording`` it makes one first: the default site's LiDAR and camera models
(``wz_simulator``, seed 3) see a few vehicles placed on its lanes; tracks are those vehicles
(truth, no tracker), one speeding alert is raised on the fastest; then the recording is
converted as ``wz recording foxglove`` does.
"""

from __future__ import annotations

import argparse
import io
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from google.protobuf import descriptor_pool, message_factory
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from mcap.reader import make_reader
from PIL import Image

from wz_cli.foxglove import convert_stream
from wz_cli.recording import RecordingWriter
from wz_eval.alerts import truth_batches
from wz_shared import codec
from wz_shared.keys import Keys
from wz_shared.messages import Alert, GroundTruth, VehicleTruth
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site
from wz_simulator.sensors.rig import CameraOutput, LidarOutput, SensorRig
from wz_simulator.sensors.scene import Weather

#: (station [m], lane, speed [mph]) of the vehicles placed on the road.
VEHICLES = [(955.0, 0, 52.0), (925.0, 1, 71.0), (890.0, 0, 55.0), (850.0, 1, 49.0)]


def _example_recording(site: Site) -> bytes:
    road = site.road_frame
    vehicles = []
    for i, (station_m, lane, mph) in enumerate(VEHICLES):
        offset_m = site.lane(lane).center_offset_m
        x, y = road.to_site(station_m, offset_m)
        vehicles.append(
            VehicleTruth(
                vehicle_id=f"veh{i}",
                vehicle_class="car",
                x_m=float(x),
                y_m=float(y),
                heading_rad=float(road.heading_at(station_m)),
                speed_mps=mph * 0.44704,
                accel_mps2=0.0,
                length_m=4.6,
                width_m=1.8,
                height_m=1.5,
                lane_index=lane,
                station_m=station_m,
                offset_m=offset_m,
                driver_profile="normal",
            )
        )
    rig = SensorRig(site, Weather(), seed=3, sensor_ids=["lidar-mast", "camera-mast"])
    keys = Keys(site.site_id)
    stamp_s = 1.0
    (batch,), _ = truth_batches(site, [(stamp_s, vehicles)])  # every vehicle a track
    tracks = batch.tracks
    fastest = max(tracks, key=lambda t: t.speed_mps)
    limit_mps = site.speed_limit_mps_at(fastest.station_m)
    alert = Alert(
        site=site.site_id,
        source_id="alert-service",
        stamp=stamp_s,
        alert_id="preview-1",
        alert_type="speeding",
        severity="critical",
        track_id=fastest.track_id,
        station_m=fastest.station_m,
        offset_m=fastest.offset_m,
        speed_mps=fastest.speed_mps,
        measured_value=fastest.speed_mps,
        threshold_value=limit_mps,
        description="speeding (preview)",
        episode_id="speeding-preview",
        value_unit="m/s",
        track=fastest,
    )
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, metadata={"recorder": "deploy/foxglove/preview.py"})
    log_ns = 1_700_000_000_000_000_000
    lidar = rig.capture("lidar-mast", 20, stamp_s, vehicles, stamp_s)
    camera = rig.capture("camera-mast", 10, stamp_s, vehicles, stamp_s)
    assert isinstance(lidar, LidarOutput) and isinstance(camera, CameraOutput)
    payloads = [
        (
            keys.truth,
            codec.encode(
                GroundTruth(
                    site=site.site_id,
                    source_id="simulator",
                    stamp=stamp_s,
                    step_index=20,
                    vehicles=vehicles,
                )
            ),
        ),
        (
            keys.raw_lidar("lidar-mast"),
            codec.encode_lidar_frame(lidar.scan.meta, lidar.scan.points),
        ),
        (keys.raw_camera("camera-mast"), codec.encode_camera_frame(camera.meta, camera.jpeg)),
        (keys.tracks, codec.encode(batch)),
        (keys.alerts("speeding"), codec.encode(alert)),
    ]
    for i, (key, payload) in enumerate(payloads):
        writer.add(key, payload, log_ns + i * 1_000_000)
    writer.finish()
    out = io.BytesIO()
    convert_stream(io.BytesIO(buffer.getvalue()), out, site)
    return out.getvalue()


def _decoded(data: bytes) -> dict[str, list[object]]:
    """Every Foxglove message, decoded with the schema stored in the file, by topic."""
    out: dict[str, list[object]] = {}
    for schema, channel, message in make_reader(io.BytesIO(data)).iter_messages():
        if not channel.topic.startswith("/foxglove/") or schema is None:
            continue
        pool = descriptor_pool.DescriptorPool()
        for file in FileDescriptorSet.FromString(schema.data).file:
            pool.Add(file)
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
        out.setdefault(channel.topic, []).append(cls.FromString(message.data))
    return out


def _matrix(q: object) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w  # type: ignore[attr-defined]
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def draw(data: bytes, out_path: Path) -> None:
    messages = _decoded(data)
    transforms = {t.child_frame_id: t for t in messages["/foxglove/tf"]}  # type: ignore[attr-defined]
    fig, (top, image) = plt.subplots(
        1, 2, figsize=(13, 6.2), gridspec_kw={"width_ratios": [1.1, 1]}
    )
    top.set_facecolor("#15181c")
    for entity in messages["/foxglove/site"][0].entities:  # type: ignore[attr-defined]
        for line in entity.lines:
            top.plot([p.x for p in line.points], [p.y for p in line.points], color="0.85", lw=0.8)
        for triangles in entity.triangles:
            c = triangles.color
            pts = [(p.x, p.y) for p in triangles.points]
            for k in range(0, len(pts), 3):
                top.fill(*zip(*pts[k : k + 3], strict=True), color=(c.r, c.g, c.b, c.a), lw=0)
    for cloud in messages["/foxglove/lidar/lidar-mast"]:
        tf = transforms[cloud.frame_id]  # type: ignore[attr-defined]
        stride = cloud.point_stride // 4  # type: ignore[attr-defined]
        xyz = np.frombuffer(cloud.data, dtype="<f4").reshape(-1, stride)[:, :3]  # type: ignore[attr-defined]
        site_xyz = xyz @ _matrix(tf.rotation).T + [
            tf.translation.x,
            tf.translation.y,
            tf.translation.z,
        ]
        top.scatter(
            site_xyz[:, 0],
            site_xyz[:, 1],
            s=0.4,
            c=site_xyz[:, 2],
            cmap="turbo",
            vmin=-0.5,
            vmax=2.5,
        )
    for update in messages["/foxglove/tracks"] + messages["/foxglove/alerts"]:
        for entity in update.entities:  # type: ignore[attr-defined]
            for cube in entity.cubes:
                p, q = cube.pose.position, cube.pose.orientation
                yaw = 2 * math.atan2(q.z, q.w)
                corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1], [1, 1]]) * [
                    cube.size.x / 2,
                    cube.size.y / 2,
                ]
                rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
                xy = corners @ rot.T + [p.x, p.y]
                top.plot(
                    xy[:, 0], xy[:, 1], color=(cube.color.r, cube.color.g, cube.color.b), lw=1.5
                )
            for sphere in entity.spheres:
                c = sphere.color
                top.scatter(
                    [sphere.pose.position.x],
                    [sphere.pose.position.y],
                    s=160,
                    color=(c.r, c.g, c.b),
                    marker="o",
                    zorder=5,
                )
            for text in entity.texts:
                top.text(
                    text.pose.position.x + 3, text.pose.position.y, text.text, color="w", fontsize=7
                )
    mast = transforms["lidar-mast"].translation
    top.set_xlim(mast.x - 50, mast.x + 30)
    top.set_ylim(mast.y - 150, mast.y + 10)
    top.set_aspect("equal")
    top.set_xlabel("site x (east) [m]")
    top.set_ylabel("site y (north) [m]")
    top.set_title(
        "3D panel content, seen from above:\n/foxglove/lidar, /foxglove/site, /foxglove/tracks, /foxglove/alerts",
        fontsize=9,
    )
    jpeg = messages["/foxglove/camera/camera-mast"][0]
    image.imshow(Image.open(io.BytesIO(jpeg.data)))  # type: ignore[attr-defined]
    image.set_axis_off()
    fix = messages["/foxglove/location/site"][0]
    image.set_title(
        f"Image panel: /foxglove/camera/camera-mast ({jpeg.format})\n"  # type: ignore[attr-defined]
        f"site LocationFix {fix.latitude:.4f}, {fix.longitude:.4f}",  # type: ignore[attr-defined]
        fontsize=9,
    )
    fig.suptitle(
        "NOT a Foxglove screenshot: matplotlib drawing of the decoded Foxglove messages",
        fontsize=10,
    )
    fig.savefig(out_path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--recording", type=Path, help="a converted recording (default: make one)")
    args = parser.parse_args()
    data = (
        args.recording.read_bytes()
        if args.recording
        else _example_recording(load_site(DEFAULT_SITE_PATH))
    )
    draw(data, args.out)


if __name__ == "__main__":
    main()
