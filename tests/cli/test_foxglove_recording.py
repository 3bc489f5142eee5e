"""`wz recording foxglove`: a recording Foxglove can show, checked as Foxglove reads it.

A recording of the project's own messages (the record/replay mix: LiDAR frames, camera JPEGs,
tracks, alerts, truth, junk) plus an organized LiDAR frame with no-return cells is converted by
the real `wz` process. The output is read with the `mcap` library (summary, every chunk's
CRC), each Foxglove channel's schema is decoded from the file itself (the FileDescriptorSet
Foxglove reads) and compared with Foxglove's published one, and every message is decoded with
it and checked against the bus message it shows.
"""

from __future__ import annotations

import io
import math
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf import descriptor_pool, message_factory
from google.protobuf.descriptor_pb2 import DescriptorProto, FileDescriptorSet
from google.protobuf.message import Message as ProtoMessage
from mcap.reader import make_reader
from mcap.records import Chunk, Footer
from mcap.stream_reader import StreamReader

from tests.cli.bus_tools import KEYS, mix
from tests.cli.procs import run_wz
from tests.shared.samples import SITE, lidar_frame
from wz_cli.foxglove_scene import rotation_quaternion
from wz_cli.recording import RecordingReader, RecordingWriter
from wz_shared import codec
from wz_shared.messages import (
    Alert,
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    TrackBatch,
)
from wz_shared.site import DEFAULT_SITE_PATH, Pose, load_site

COUNT = 4  # of every message type and frame kind
#: Foxglove's schema of each Foxglove topic (by prefix).
EXPECTED_SCHEMAS = {
    "/foxglove/lidar/": PointCloud,
    "/foxglove/camera/": CompressedImage,
    "/foxglove/tracks": SceneUpdate,
    "/foxglove/truth": SceneUpdate,
    "/foxglove/alerts": SceneUpdate,
    "/foxglove/site": SceneUpdate,
    "/foxglove/tf": FrameTransform,
    "/foxglove/location/": LocationFix,
}


def _organized_lidar(i: int) -> bytes:
    """An organized 4 x 64 frame whose every third cell is a no-return (NaN)."""
    _, points = lidar_frame(i, 256, seed=7)
    points[::3, :3] = np.nan
    meta = LidarFrameMeta(
        site=SITE,
        source_id="lidar-mast",
        stamp=0.05 * i + 0.01,
        frame_index=1000 + i,
        rows=4,
        columns=64,
        num_points=256,
        organized=True,
    )
    return codec.encode_lidar_frame(meta, points)


def _bus_samples() -> list[tuple[str, bytes]]:
    samples = [(key, payload) for key, _cls, payload in mix(COUNT)]
    samples += [(KEYS.raw_lidar("lidar-mast"), _organized_lidar(i)) for i in range(2)]
    return samples


@pytest.fixture(scope="module")
def site_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default site's geometry under the samples' site id."""
    site = load_site(DEFAULT_SITE_PATH).model_copy(update={"site_id": SITE})
    path = tmp_path_factory.mktemp("site") / "site.yaml"
    path.write_text(yaml.safe_dump(site.model_dump(mode="json")))
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "bus.mcap"
    with path.open("wb") as stream:
        writer = RecordingWriter(stream, metadata={"recorder": "test"}, chunk_size_bytes=8192)
        for i, (key, payload) in enumerate(_bus_samples()):
            writer.add(key, payload, log_time_ns=1_700_000_000_000_000_000 + i * 10_000_000)
        writer.finish()
    return path


@pytest.fixture(scope="module")
def converted(recording: Path, site_file: Path) -> Path:
    out = recording.with_name("foxglove.mcap")
    result = run_wz("recording", "foxglove", str(recording), str(out), "--site", str(site_file))
    assert result.returncode == 0, result.stderr
    assert "complete recording" in result.stdout and "Foxglove message(s) added" in result.stdout
    return out


def _classes_from_file(schema_data: bytes, name: str) -> type[ProtoMessage]:
    """The message class that the schema stored in the file describes (as Foxglove builds it)."""
    files = FileDescriptorSet.FromString(schema_data)
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:  # each after its imports, or the pool refuses it
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def _proto(cls: type[ProtoMessage]) -> DescriptorProto:
    proto = DescriptorProto()
    cls.DESCRIPTOR.CopyToProto(proto)
    return proto


def _expected_schema(topic: str) -> type[ProtoMessage]:
    matches = [cls for prefix, cls in EXPECTED_SCHEMAS.items() if topic.startswith(prefix)]
    assert len(matches) == 1, f"unexpected Foxglove topic {topic}"
    return matches[0]


def _stamp_s(message: ProtoMessage) -> float:
    """The message's timestamp [s]; a scene update's is that of its entities or deletions."""
    if message.DESCRIPTOR.full_name == "foxglove.SceneUpdate":
        stamps = {_stamp_s(m) for m in [*message.entities, *message.deletions]}  # type: ignore[attr-defined]
        assert len(stamps) == 1, stamps
        return stamps.pop()
    stamp = message.timestamp  # type: ignore[attr-defined]
    return float(stamp.seconds + stamp.nanos * 1e-9)


def test_converted_recording_is_a_valid_mcap_with_intact_chunks(
    recording: Path, converted: Path
) -> None:
    data = converted.read_bytes()
    summary = make_reader(io.BytesIO(data), validate_crcs=True).get_summary()
    assert summary is not None and summary.statistics is not None
    chunks = 0
    footer = None
    for record in StreamReader(io.BytesIO(data), emit_chunks=True, validate_crcs=True).records:
        if isinstance(record, Chunk):
            chunks += 1
            assert record.uncompressed_crc == zlib.crc32(record.data)
        elif isinstance(record, Footer):
            footer = record
    assert footer is not None and footer.summary_start > 0
    assert chunks == len(summary.chunk_indexes) == summary.statistics.chunk_count >= 1
    indexed = sum(summary.statistics.channel_message_counts.values())
    assert indexed == summary.statistics.message_count
    # Every bus channel is still there, byte for byte: replay needs them.
    originals = list(RecordingReader(recording.open("rb")).messages())
    reader = RecordingReader(converted.open("rb"))
    kept = [m for m in reader.messages() if not m.topic.startswith("/foxglove/")]
    assert reader.report.complete
    assert [(m.topic, m.kind, m.log_time_ns, m.payload) for m in kept] == [
        (m.topic, m.kind, m.log_time_ns, m.payload) for m in originals
    ]


def test_every_foxglove_message_decodes_with_the_official_schema(
    recording: Path, converted: Path
) -> None:
    source = {
        m.log_time_ns: m for m in RecordingReader(recording.open("rb")).messages()
    }  # one bus message per log time
    reader = make_reader(converted.open("rb"), validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None
    topics = set()
    for channel in summary.channels.values():
        if not channel.topic.startswith("/foxglove/"):
            continue
        topics.add(channel.topic)
        schema = summary.schemas[channel.schema_id]
        official = _expected_schema(channel.topic)
        assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
        assert schema.name == official.DESCRIPTOR.full_name
        # The schema in the file is Foxglove's own, field for field.
        assert _proto(_classes_from_file(schema.data, schema.name)) == _proto(official)
    assert topics == {
        "/foxglove/lidar/lidar-mast",
        "/foxglove/camera/camera-mast",
        "/foxglove/tracks",
        "/foxglove/truth",
        "/foxglove/alerts",
        "/foxglove/site",
        "/foxglove/tf",
        "/foxglove/location/site",
        "/foxglove/location/tracks",
    }

    site = load_site(DEFAULT_SITE_PATH)
    counts: dict[str, int] = {}
    frames: set[str] = set()
    transforms: set[str] = set()
    for schema, channel, message in reader.iter_messages():
        if not channel.topic.startswith("/foxglove/"):
            continue
        assert schema is not None
        decoded = _classes_from_file(schema.data, schema.name).FromString(message.data)
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
        bus = source.get(message.log_time)
        if channel.topic in ("/foxglove/tf", "/foxglove/site", "/foxglove/location/site"):
            _check_static(channel.topic, decoded, site, transforms)
            continue
        assert bus is not None, channel.topic
        assert message.publish_time == bus.publish_time_ns
        assert math.isclose(_stamp_s(decoded), bus.publish_time_ns * 1e-9, abs_tol=2e-9)
        if schema.name == "foxglove.PointCloud":
            frames.add(decoded.frame_id)  # type: ignore[attr-defined]
            _check_point_cloud(decoded, bus.payload)
        elif schema.name == "foxglove.CompressedImage":
            frames.add(decoded.frame_id)  # type: ignore[attr-defined]
            frame = codec.decode_frame(bus.payload, CameraFrameMeta)
            assert decoded.format == "jpeg"  # type: ignore[attr-defined]
            assert decoded.data == bytes(frame.payload)  # type: ignore[attr-defined]
        elif channel.topic == "/foxglove/tracks":
            _check_tracks(decoded, codec.decode_json(bus.payload, TrackBatch))
        elif channel.topic == "/foxglove/truth":
            truth = codec.decode_json(bus.payload, GroundTruth)
            assert [e.id for e in decoded.entities] == [  # type: ignore[attr-defined]
                f"truth-{v.vehicle_id}" for v in truth.vehicles
            ]
        elif channel.topic == "/foxglove/alerts":
            alert = codec.decode_json(bus.payload, Alert)
            (entity,) = decoded.entities  # type: ignore[attr-defined]
            assert entity.id == f"alert-{alert.episode_id}" and entity.frame_id == "site"
            assert alert.alert_type.value in entity.texts[0].text
        elif channel.topic == "/foxglove/location/tracks":
            batch = codec.decode_json(bus.payload, TrackBatch)
            lat, lon, _ = site.geo_frame.to_wgs84(batch.tracks[0].x_m, batch.tracks[0].y_m)
            assert decoded.latitude == pytest.approx(float(lat), abs=1e-9)  # type: ignore[attr-defined]
            assert decoded.longitude == pytest.approx(float(lon), abs=1e-9)  # type: ignore[attr-defined]
    # Every sensor frame a message is in has a transform into the site frame.
    assert frames <= transforms and frames == {"lidar-mast", "camera-mast"}
    assert counts["/foxglove/lidar/lidar-mast"] == COUNT + 2  # the broken frames are not shown
    assert counts["/foxglove/camera/camera-mast"] == COUNT
    assert counts["/foxglove/tracks"] == counts["/foxglove/alerts"] == COUNT
    assert counts["/foxglove/site"] == counts["/foxglove/location/site"] == 1


def _check_point_cloud(cloud: ProtoMessage, payload: bytes) -> None:
    frame = codec.decode_frame(payload, LidarFrameMeta)
    points = frame.points()
    finite = points[np.isfinite(points[:, :3]).all(axis=1)]
    stride = cloud.point_stride  # type: ignore[attr-defined]
    data = cloud.data  # type: ignore[attr-defined]
    assert stride == 16 and len(data) % stride == 0
    assert len(data) // stride == len(finite)
    if frame.meta.organized:
        assert len(finite) < len(points)  # the no-return cells are left out
    fields = {f.name: f for f in cloud.fields}  # type: ignore[attr-defined]
    assert {"x", "y", "z"} <= set(fields)
    for name, column in (("x", 0), ("y", 1), ("z", 2), ("intensity", 3)):
        field = fields[name]
        assert field.type == PackedElementField.FLOAT32 and field.offset + 4 <= stride
        values = np.frombuffer(data, dtype="<f4").reshape(-1, stride // 4)[:, field.offset // 4]
        np.testing.assert_array_equal(values, finite[:, column])
    assert cloud.frame_id == frame.meta.source_id  # type: ignore[attr-defined]


def _check_tracks(update: ProtoMessage, batch: TrackBatch) -> None:
    assert [d.type for d in update.deletions] == [1]  # type: ignore[attr-defined]  # ALL
    entities = update.entities  # type: ignore[attr-defined]
    assert [e.id for e in entities] == [f"track-{t.track_id}" for t in batch.tracks]
    for entity, track in zip(entities, batch.tracks, strict=True):
        (cube,) = entity.cubes
        assert (cube.pose.position.x, cube.pose.position.y) == (track.x_m, track.y_m)
        assert cube.size.x > 0 and cube.size.y > 0 and cube.size.z > 0
        assert len(entity.arrows) == 1 and f"#{track.track_id}" in entity.texts[0].text


def _check_static(topic: str, decoded: ProtoMessage, site: object, transforms: set[str]) -> None:
    from wz_shared.site import Site

    assert isinstance(site, Site)
    if topic == "/foxglove/tf":
        transforms.add(decoded.child_frame_id)  # type: ignore[attr-defined]
        assert decoded.parent_frame_id == "site"  # type: ignore[attr-defined]
        pose = site.sensor(decoded.child_frame_id).pose  # type: ignore[attr-defined]
        t, q = decoded.translation, decoded.rotation  # type: ignore[attr-defined]
        assert (t.x, t.y, t.z) == (pose.x_m, pose.y_m, pose.z_m)
        np.testing.assert_allclose(_matrix(q.x, q.y, q.z, q.w), pose.rotation(), atol=1e-12)
    elif topic == "/foxglove/location/site":
        assert decoded.latitude == site.origin.latitude_deg  # type: ignore[attr-defined]
        assert decoded.longitude == site.origin.longitude_deg  # type: ignore[attr-defined]
    else:
        ids = {e.id for e in decoded.entities}  # type: ignore[attr-defined]
        assert {"road", "area-transition", "area-activity"} <= ids
        road = next(e for e in decoded.entities if e.id == "road")  # type: ignore[attr-defined]
        assert len(road.lines) == len(site.lanes) + 1  # the lane edges
        taper = next(e for e in decoded.entities if e.id == "area-transition")  # type: ignore[attr-defined]
        assert len(taper.triangles[0].points) % 3 == 0 and taper.triangles[0].points


def _matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The rotation matrix of a unit quaternion (closed form)."""
    assert math.isclose(x * x + y * y + z * z + w * w, 1.0, abs_tol=1e-12)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@pytest.mark.parametrize(
    "angles", [(0, 0, 0), (-90, 0, 0), (180, 0, 0), (-95, -14, 0), (170, 80, -179), (90, 179, 91)]
)
def test_sensor_rotation_quaternion_matches_the_pose_matrix(
    angles: tuple[float, float, float],
) -> None:
    pose = Pose(x_m=0, y_m=0, z_m=0, yaw_deg=angles[0], pitch_deg=angles[1], roll_deg=angles[2])
    q = rotation_quaternion(pose.rotation())
    np.testing.assert_allclose(_matrix(q.x, q.y, q.z, q.w), pose.rotation(), atol=1e-12)


def test_truncated_recording_converts_its_readable_part_with_a_clear_message(
    recording: Path, site_file: Path, tmp_path: Path
) -> None:
    data = recording.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    out = tmp_path / "out.mcap"
    result = run_wz("recording", "foxglove", str(cut), str(out), "--site", str(site_file))
    assert result.returncode == 3, result.stderr
    assert "Traceback" not in result.stderr
    assert "INCOMPLETE recording: the file is truncated at byte" in result.stdout
    # What could be read is in a complete file.
    summary = make_reader(out.open("rb"), validate_crcs=True).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count > 0


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"not an mcap file at all", "not an MCAP file"),
        (b"", "the file is empty"),
    ],
)
def test_input_that_is_no_recording_is_refused_without_a_traceback(
    tmp_path: Path, site_file: Path, content: bytes, message: str
) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    out = tmp_path / "out.mcap"
    result = run_wz("recording", "foxglove", str(bad), str(out), "--site", str(site_file))
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert message in result.stderr and "is not a recording that can be converted" in result.stderr
    assert not out.exists()


def test_a_bad_site_file_is_refused_before_anything_is_written(
    recording: Path, tmp_path: Path
) -> None:
    site = tmp_path / "site.yaml"
    site.write_text("site_id: [unclosed")
    out = tmp_path / "out.mcap"
    result = run_wz("recording", "foxglove", str(recording), str(out), "--site", str(site))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "not valid YAML" in result.stderr and "--no-site" in result.stderr
    assert not out.exists()


def test_the_conversion_in_process_writes_what_the_command_wrote(
    recording: Path, converted: Path, site_file: Path
) -> None:
    """``convert_stream`` (the command's core, here in this process) adds the same Foxglove
    messages per topic as `wz recording foxglove` did, and copies every bus message."""
    from collections import Counter

    from wz_cli.foxglove import convert_stream
    from wz_shared.site import load_site

    with recording.open("rb") as source:
        report, reader = convert_stream(source, io.BytesIO(), load_site(site_file))
    assert reader.report.complete
    assert set(report.not_shown) <= {"lidar_frame (truncated)"}  # the fixture's cut frames
    assert report.copied == len(list(RecordingReader(recording.open("rb")).messages()))
    written = Counter(
        m.topic
        for m in RecordingReader(converted.open("rb")).messages()
        if m.topic.startswith("/foxglove/")
    )
    assert report.foxglove == written and sum(written.values()) > 0
