"""``wz recording foxglove IN.mcap OUT.mcap``: a recording that Foxglove can show.

The output holds every channel of the input as it was (``wz replay`` replays it the same) and,
beside them, channels in Foxglove's own message schemas, encoded as protobuf (the schemas of
PyPI's ``foxglove-schemas-protobuf``, MIT): LiDAR frames as ``foxglove.PointCloud``, camera
frames as ``foxglove.CompressedImage``, tracks, truth, alerts and the site's road geometry as
``foxglove.SceneUpdate``, sensor poses as ``foxglove.FrameTransform`` and positions as
``foxglove.LocationFix`` (see :mod:`wz_cli.foxglove_scene` for the topics and frames).
Protobuf keeps a point cloud's packed floats as bytes; JSON would carry them base64-encoded,
a third larger.

Each Foxglove message has the ``log_time`` and ``publish_time`` of the bus message it shows;
the site's static scene has those of the recording's first message. A schema's data is the
``FileDescriptorSet`` of its ``.proto`` file and every file it imports, which is what Foxglove
reads to decode a protobuf channel.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING

from google.protobuf.descriptor import FileDescriptor
from google.protobuf.descriptor_pb2 import FileDescriptorProto, FileDescriptorSet
from google.protobuf.message import Message as ProtoMessage
from mcap.records import Schema

from wz_cli.common import CliError, emit, format_table
from wz_cli.foxglove_scene import (
    FoxgloveMessage,
    FoxgloveScene,
    camera_topic,
    compressed_image,
    lidar_topic,
    point_cloud,
)
from wz_cli.recording import (
    RecordedMessage,
    RecordingError,
    RecordingReader,
    RecordingWriter,
    describe_report,
    recording_metadata,
)
from wz_shared import codec
from wz_shared.messages import (
    Alert,
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    TrackBatch,
)
from wz_shared.site import Site

if TYPE_CHECKING:  # the C implementation's descriptor type, as the stubs name it
    from google._upb._message import FileDescriptor as UpbFileDescriptor

log = logging.getLogger(__name__)

PROTOBUF_ENCODING = "protobuf"
#: Exit code of a conversion whose input recording was incomplete (everything readable kept).
EXIT_INCOMPLETE = 3


def file_descriptor_set(message: ProtoMessage) -> bytes:
    """The serialized ``FileDescriptorSet`` of a message's type: its ``.proto`` file and every
    file it imports, each after its imports."""
    files = FileDescriptorSet()
    seen: set[str] = set()

    def add(file: FileDescriptor | UpbFileDescriptor) -> None:
        if file.name in seen:
            return
        seen.add(file.name)
        for dependency in file.dependencies:
            add(dependency)
        proto = FileDescriptorProto()
        file.CopyToProto(proto)
        files.file.append(proto)

    add(message.DESCRIPTOR.file)
    return bytes(files.SerializeToString())


_SCHEMAS: dict[str, Schema] = {}


def protobuf_schema(message: ProtoMessage) -> Schema:
    """The MCAP schema of a protobuf message's type (id 0: the writer assigns ids)."""
    name = message.DESCRIPTOR.full_name
    if name not in _SCHEMAS:
        _SCHEMAS[name] = Schema(
            id=0, name=name, encoding=PROTOBUF_ENCODING, data=file_descriptor_set(message)
        )
    return _SCHEMAS[name]


@dataclass
class ConversionReport:
    """What a conversion wrote: bus messages copied, Foxglove messages per topic, and the
    bus messages that had nothing to show (invalid payloads), per kind."""

    copied: int = 0
    foxglove: Counter[str] = field(default_factory=Counter)
    not_shown: Counter[str] = field(default_factory=Counter)


def foxglove_messages(scene: FoxgloveScene, message: RecordedMessage) -> list[FoxgloveMessage]:
    """The Foxglove messages that show one recorded bus message (none for other kinds).

    Raises
    ------
    codec.DecodeError
        The payload is not a valid message of its recorded kind.
    """
    payload = message.payload
    if message.kind == "lidar_frame":
        lidar = codec.decode_frame(payload, LidarFrameMeta)
        return [
            FoxgloveMessage(
                lidar_topic(lidar.meta.source_id), point_cloud(lidar.meta, lidar.points())
            )
        ]
    if message.kind == "camera_frame":
        camera = codec.decode_frame(payload, CameraFrameMeta)
        image = compressed_image(camera.meta, bytes(camera.payload))
        return [FoxgloveMessage(camera_topic(camera.meta.source_id), image)]
    if message.kind == "track_batch":
        return scene.tracks(codec.decode_json(payload, TrackBatch))
    if message.kind == "alert":
        return scene.alert(codec.decode_json(payload, Alert))
    if message.kind == "ground_truth":
        return scene.truth(codec.decode_json(payload, GroundTruth))
    return []


def convert_stream(
    source: IO[bytes], target: IO[bytes], site: Site | None
) -> tuple[ConversionReport, RecordingReader]:
    """Copy a recording from ``source`` into ``target`` with Foxglove channels added.

    Returns the conversion's report and the reader (its ``report`` says whether the input was
    complete and where it stopped).

    Raises
    ------
    RecordingError
        ``source`` is no MCAP recording at all.
    """
    reader = RecordingReader(source)
    scene = FoxgloveScene(site)
    report = ConversionReport()
    messages = reader.messages()
    first = next(messages, None)  # reads the input's metadata record, which comes first
    metadata = {**reader.report.metadata, "foxglove": "wz recording foxglove"}
    if site is not None:
        metadata["foxglove_site"] = site.site_id
    writer = RecordingWriter(target, metadata=recording_metadata(metadata))

    def write(shown: FoxgloveMessage, log_time_ns: int, publish_time_ns: int) -> None:
        writer.add_encoded(
            shown.topic,
            protobuf_schema(shown.message),
            PROTOBUF_ENCODING,
            shown.message.SerializeToString(),
            log_time_ns=log_time_ns,
            publish_time_ns=publish_time_ns,
        )
        report.foxglove[shown.topic] += 1

    if first is not None:
        for shown in scene.static(first.publish_time_ns * 1e-9):
            write(shown, first.log_time_ns, first.publish_time_ns)
    for message in _chain(first, messages):
        writer.add(message.topic, message.payload, message.log_time_ns)
        report.copied += 1
        try:
            shown_list = foxglove_messages(scene, message)
        except codec.DecodeError as exc:
            report.not_shown[f"{message.kind} ({exc.reason})"] += 1
            continue
        for shown in shown_list:
            write(shown, message.log_time_ns, message.publish_time_ns)
    writer.finish()
    return report, reader


def _chain(
    first: RecordedMessage | None, rest: Iterator[RecordedMessage]
) -> Iterator[RecordedMessage]:
    if first is not None:
        yield first
        yield from rest


def run_convert(in_path: Path, out_path: Path, site: Site | None, *, overwrite: bool) -> int:
    """``wz recording foxglove``: convert, print a summary; 0, or 3 for an incomplete input."""
    if in_path.resolve() == out_path.resolve():
        raise CliError("the output must be another file than the input", 1)
    try:
        source = in_path.open("rb")
    except OSError as exc:
        raise CliError(f"cannot read {in_path}: {exc}", 1) from exc
    try:
        target = out_path.open("wb" if overwrite else "xb")
    except FileExistsError as exc:
        source.close()
        raise CliError(f"{out_path} exists: choose another name or pass --overwrite", 1) from exc
    except OSError as exc:
        source.close()
        raise CliError(f"cannot write {out_path}: {exc}", 1) from exc
    with source, target:
        try:
            report, reader = convert_stream(source, target, site)
        except RecordingError as exc:
            target.close()
            out_path.unlink(missing_ok=True)
            raise CliError(f"{in_path} is not a recording that can be converted: {exc}", 1) from exc
    for line in summary_lines(report, reader, out_path):
        emit(line)
    return 0 if reader.report.complete else EXIT_INCOMPLETE


def summary_lines(report: ConversionReport, reader: RecordingReader, out_path: Path) -> list[str]:
    """What ``wz recording foxglove`` prints."""
    lines = [
        f"input: {describe_report(reader.report)}",
        f"wrote {out_path}: {report.copied} bus message(s) copied, "
        f"{sum(report.foxglove.values())} Foxglove message(s) added",
    ]
    lines.extend(
        format_table(
            ("FOXGLOVE TOPIC", "MESSAGES"),
            [(t, str(n)) for t, n in sorted(report.foxglove.items())],
        )
    )
    lines.extend(
        f"not shown (invalid payload): {n} {what}" for what, n in sorted(report.not_shown.items())
    )
    lines.extend(f"skipped in the input: {problem}" for problem in reader.report.skipped)
    return lines
