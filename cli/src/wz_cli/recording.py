"""Bus recordings as MCAP files: the writer of ``wz record``, the reader of ``wz replay``.

No bus here, only bytes and files, so both halves are tested without Zenoh.

Layout of a recording
---------------------
- One channel per concrete key (topic = the key) and payload format. Payloads are stored
  exactly as they travelled on the bus.
- JSON messages: message encoding ``json``, schema named by the message ``kind`` with the
  pydantic model's JSON Schema (``jsonschema``), so Foxglove shows every field.
- Frame envelopes (LiDAR points, camera JPEG): message encoding ``wz-frame``, schema named by
  the frame kind; its data is a JSON document that spells out the envelope layout and holds the
  metadata's JSON Schema (schema encoding ``wz-frame``).
- Anything else (a payload that was not a message of ours): message encoding ``wz-raw``, no
  schema, so a replay reproduces bad input too.
- ``log_time``: when the recorder received the sample [ns since the Unix epoch];
  ``publish_time``: the message's ``stamp`` [ns] where the payload decodes, else ``log_time``.
- A metadata record ``wz-recording`` says what was recorded, from where, and when.

Chunks are uncompressed (no compression library is a dependency) and are flushed to disk at
least every second, so a recorder that crashes loses at most the last second. Its file then
lacks the summary and footer; :class:`RecordingReader` reads files sequentially and needs
neither, and stops cleanly at a truncation, reporting where and why.
"""

from __future__ import annotations

import io
import json
import struct
import zlib
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import IO, Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Metadata, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import get_chunk_data_stream
from mcap.writer import CompressionType, Writer

from wz_shared import codec
from wz_shared.messages import FRAME_MESSAGES, JSON_MESSAGES

JSON_ENCODING = "json"
FRAME_ENCODING = "wz-frame"
RAW_ENCODING = "wz-raw"
JSON_SCHEMA_ENCODING = "jsonschema"
FRAME_SCHEMA_ENCODING = "wz-frame"
METADATA_NAME = "wz-recording"

MCAP_MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEADER = struct.Struct("<BQ")
_CHUNK_HEADER = struct.Struct("<QQQI")  # start time, end time, uncompressed size, crc
#: Largest record the reader accepts [bytes]; a bigger length means a corrupt file.
MAX_RECORD_BYTES = 1 << 31

ENVELOPE_LAYOUT = (
    "A wz frame envelope: bytes 0-3 the magic 'WZF1'; bytes 4-7 the metadata length M "
    "(uint32, little-endian); bytes 8 to 8+M the metadata as UTF-8 JSON (see metadata_schema); "
    "then the payload to the end of the message."
)
FRAME_PAYLOADS = {
    "lidar_frame": (
        "num_points rows of 4 float32, little-endian: x, y, z [m] in the sensor frame "
        "(x forward, y left, z up) and intensity; NaN marks a no-return cell of an organized "
        "frame (rows x columns)"
    ),
    "camera_frame": "the JPEG image, from its SOI marker (FF D8) on",
}


def frame_schema(kind: str) -> bytes:
    """The schema data of a frame channel: the envelope layout and the metadata's JSON Schema."""
    document = {
        "title": f"wz {kind} envelope",
        "description": ENVELOPE_LAYOUT,
        "envelope": {
            "magic": codec.FRAME_MAGIC.decode(),
            "header": "struct '<4sI': magic, metadata length M",
            "metadata": "bytes [8, 8 + M): JSON of the metadata model, with its 'kind' tag",
            "payload": FRAME_PAYLOADS.get(kind, "raw bytes"),
        },
        "metadata_schema": FRAME_MESSAGES[kind].model_json_schema(),
    }
    return json.dumps(document, indent=1).encode()


def json_schema(kind: str) -> bytes:
    return json.dumps(JSON_MESSAGES[kind].model_json_schema()).encode()


# --- writing --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Classified:
    """How a payload is stored: its encoding, its kind (schema name), its stamp [ns]."""

    encoding: str
    kind: str | None
    stamp_ns: int | None
    invalid_reason: str | None


def classify(payload: bytes) -> Classified:
    """Tell the format and kind of a payload, and validate it for its stamp.

    A payload of a known kind that fails validation keeps its kind's channel (a replay puts it
    back where it came from) and is counted as invalid.
    """
    kind = codec.peek_kind(payload)
    if payload[:4] == codec.FRAME_MAGIC:
        frame_cls = FRAME_MESSAGES.get(kind or "")
        if frame_cls is None:
            return Classified(FRAME_ENCODING, None, None, "wrong_kind")
        try:
            stamp = codec.decode_frame(payload, frame_cls).meta.stamp
        except codec.DecodeError as exc:
            return Classified(FRAME_ENCODING, kind, None, exc.reason)
        return Classified(FRAME_ENCODING, kind, round(stamp * 1e9), None)
    json_cls = JSON_MESSAGES.get(kind or "")
    if json_cls is None:
        return Classified(RAW_ENCODING, None, None, "bad_json" if kind is None else "wrong_kind")
    try:
        stamp = codec.decode_json(payload, json_cls).stamp
    except codec.DecodeError as exc:
        return Classified(JSON_ENCODING, kind, None, exc.reason)
    return Classified(JSON_ENCODING, kind, round(stamp * 1e9), None)


class RecordingWriter:
    """Writes bus samples into an MCAP stream; call :meth:`finish` to complete the file."""

    def __init__(
        self,
        stream: IO[bytes],
        *,
        metadata: Mapping[str, str],
        chunk_size_bytes: int = 1 << 20,
        library: str = "wz-cli",
    ) -> None:
        self._writer = Writer(stream, chunk_size=chunk_size_bytes, compression=CompressionType.NONE)
        self._writer.start(profile="", library=library)
        self._writer.add_metadata(METADATA_NAME, dict(metadata))
        self._schemas: dict[tuple[str, str], int] = {}
        self._channels: dict[tuple[str, str, str | None], int] = {}
        self._sequence: Counter[int] = Counter()
        #: Messages written per key.
        self.counts: Counter[str] = Counter()
        #: Invalid payloads written, per (key, reason).
        self.invalid: Counter[tuple[str, str]] = Counter()

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def _schema_id(self, encoding: str, kind: str | None) -> int:
        if kind is None or encoding == RAW_ENCODING:
            return 0  # MCAP: no schema
        if (encoding, kind) not in self._schemas:
            if encoding == FRAME_ENCODING:
                data, schema_encoding = frame_schema(kind), FRAME_SCHEMA_ENCODING
            else:
                data, schema_encoding = json_schema(kind), JSON_SCHEMA_ENCODING
            self._schemas[(encoding, kind)] = self._writer.register_schema(
                name=kind, encoding=schema_encoding, data=data
            )
        return self._schemas[(encoding, kind)]

    def _channel_id(self, key: str, encoding: str, kind: str | None) -> int:
        channel = (key, encoding, kind)
        if channel not in self._channels:
            self._channels[channel] = self._writer.register_channel(
                topic=key,
                message_encoding=encoding,
                schema_id=self._schema_id(encoding, kind),
            )
        return self._channels[channel]

    def add(self, key: str, payload: bytes, log_time_ns: int) -> Classified:
        """Write one sample received on ``key`` at ``log_time_ns``."""
        classified = classify(payload)
        channel_id = self._channel_id(key, classified.encoding, classified.kind)
        self._sequence[channel_id] += 1
        self._writer.add_message(
            channel_id=channel_id,
            log_time=log_time_ns,
            data=payload,
            publish_time=log_time_ns if classified.stamp_ns is None else classified.stamp_ns,
            sequence=self._sequence[channel_id] & 0xFFFFFFFF,
        )
        self.counts[key] += 1
        if classified.invalid_reason is not None:
            self.invalid[(key, classified.invalid_reason)] += 1
        return classified

    def add_encoded(
        self,
        topic: str,
        schema: Schema,
        message_encoding: str,
        data: bytes,
        *,
        log_time_ns: int,
        publish_time_ns: int,
    ) -> None:
        """Write a message that is no bus payload (a Foxglove view of one, say) on its own
        channel: ``schema``'s name, encoding and data are registered once per name."""
        schema_key = (schema.encoding, schema.name)
        if schema_key not in self._schemas:
            self._schemas[schema_key] = self._writer.register_schema(
                name=schema.name, encoding=schema.encoding, data=schema.data
            )
        channel = (topic, message_encoding, schema.name)
        if channel not in self._channels:
            self._channels[channel] = self._writer.register_channel(
                topic=topic,
                message_encoding=message_encoding,
                schema_id=self._schemas[schema_key],
            )
        channel_id = self._channels[channel]
        self._sequence[channel_id] += 1
        self._writer.add_message(
            channel_id=channel_id,
            log_time=log_time_ns,
            data=data,
            publish_time=publish_time_ns,
            sequence=self._sequence[channel_id] & 0xFFFFFFFF,
        )

    def flush(self) -> None:
        """Close the chunk in progress and push it to the file (bounds what a crash loses)."""
        self._writer.flush()  # type: ignore[no-untyped-call]

    def finish(self) -> None:
        """Write the summary, index and footer; the stream stays open."""
        self._writer.finish()  # type: ignore[no-untyped-call]


# --- reading --------------------------------------------------------------------------------


class RecordingError(Exception):
    """A file that cannot be read as a recording at all."""


@dataclass(frozen=True)
class RecordedMessage:
    """One recorded sample."""

    topic: str
    message_encoding: str
    #: The schema name: the message kind, or None for raw payloads.
    kind: str | None
    log_time_ns: int
    publish_time_ns: int
    payload: bytes


@dataclass
class ReadReport:
    """How reading went: messages read, whether the file was complete, where it stopped."""

    messages: int = 0
    #: The footer and closing magic were read: the recorder finished the file.
    complete: bool = False
    #: Why reading stopped before a proper end (None for a complete file).
    problem: str | None = None
    #: Records skipped on the way (unknown channel, failed CRC).
    skipped: list[str] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)


def _opcode_name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.lower()
    except ValueError:
        return f"opcode 0x{opcode:02x}"


class RecordingReader:
    """Reads an MCAP file front to back, without its summary or index.

    A file cut short (a crashed recorder, a partial copy) yields every complete message up to
    the cut, including those of a partly written uncompressed chunk; ``report.problem`` says
    where and why it stopped.
    """

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self.report = ReadReport()

    def messages(self) -> Iterator[RecordedMessage]:
        magic = self._stream.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            raise RecordingError(
                "not an MCAP file (it does not start with the MCAP magic bytes)"
                if magic
                else "the file is empty"
            )
        offset = len(MCAP_MAGIC)
        while True:
            header = self._stream.read(_RECORD_HEADER.size)
            if not header:
                self.report.problem = (
                    f"the file ends at byte {offset} without a footer: the recording was cut "
                    "short (the recorder did not finish it)"
                )
                return
            if len(header) < _RECORD_HEADER.size:
                self.report.problem = (
                    f"the file is truncated inside a record header at byte {offset}"
                )
                return
            opcode, length = _RECORD_HEADER.unpack(header)
            if length > MAX_RECORD_BYTES:
                self.report.problem = (
                    f"corrupt record at byte {offset}: {_opcode_name(opcode)} of {length} bytes"
                )
                return
            body = self._stream.read(length)
            if len(body) < length:
                self.report.problem = (
                    f"the file is truncated at byte {offset + len(header) + len(body)}, inside "
                    f"a {_opcode_name(opcode)} record of {length} bytes that starts at byte "
                    f"{offset}"
                )
                if opcode == Opcode.CHUNK:
                    yield from self._partial_chunk(body)
                return
            if opcode == Opcode.FOOTER:
                closing = self._stream.read(len(MCAP_MAGIC))
                if closing != MCAP_MAGIC:
                    self.report.problem = "the footer is not followed by the closing MCAP magic"
                    return
                self.report.complete = True
                return
            yield from self._record(opcode, body, offset)
            offset += len(header) + length

    def _record(self, opcode: int, body: bytes, offset: int) -> Iterator[RecordedMessage]:
        stream = ReadDataStream(io.BytesIO(body))
        try:
            if opcode == Opcode.SCHEMA:
                schema = Schema.read(stream)
                self._schemas[schema.id] = schema
            elif opcode == Opcode.CHANNEL:
                channel = Channel.read(stream)
                self._channels[channel.id] = channel
            elif opcode == Opcode.MESSAGE:
                message = self._message(McapMessage.read(stream, len(body)), offset)
                if message is not None:
                    yield message
            elif opcode == Opcode.CHUNK:
                yield from self._chunk(Chunk.read(stream), offset)
            elif opcode == Opcode.METADATA:
                metadata = Metadata.read(stream)
                if metadata.name == METADATA_NAME:
                    self.report.metadata = dict(metadata.metadata)
        except (McapError, struct.error, UnicodeDecodeError) as exc:
            self.report.skipped.append(
                f"unreadable {_opcode_name(opcode)} record at byte {offset}: {exc!r}"
            )

    def _message(self, record: McapMessage, offset: int) -> RecordedMessage | None:
        channel = self._channels.get(record.channel_id)
        if channel is None:
            self.report.skipped.append(
                f"message at byte {offset} on channel {record.channel_id}, which was never declared"
            )
            return None
        schema = self._schemas.get(channel.schema_id)
        self.report.messages += 1
        return RecordedMessage(
            topic=channel.topic,
            message_encoding=channel.message_encoding,
            kind=schema.name if schema is not None else None,
            log_time_ns=record.log_time,
            publish_time_ns=record.publish_time,
            payload=record.data,
        )

    def _chunk(self, chunk: Chunk, offset: int) -> Iterator[RecordedMessage]:
        if chunk.compression:
            try:
                data_stream, size = get_chunk_data_stream(chunk)
            except McapError as exc:
                raise RecordingError(
                    f"the chunk at byte {offset} is {chunk.compression}-compressed and cannot be "
                    f"read here ({exc}); re-encode the file without compression "
                    "(`mcap convert` or `mcap recover`)"
                ) from exc
            data: bytes = data_stream.read(size)
        else:
            data = chunk.data
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            self.report.skipped.append(f"chunk at byte {offset} fails its CRC: skipped")
            return
        yield from self._records_in(data, offset, complete=True)

    def _partial_chunk(self, body: bytes) -> Iterator[RecordedMessage]:
        """Salvage the complete records of an uncompressed chunk cut short."""
        try:
            compression_at = _CHUNK_HEADER.size
            (name_length,) = struct.unpack_from("<I", body, compression_at)
            compression = body[compression_at + 4 : compression_at + 4 + name_length]
            records_at = compression_at + 4 + name_length + 8
        except struct.error:
            return
        if compression or len(body) < records_at:
            return
        yield from self._records_in(body[records_at:], 0, complete=False)

    def _records_in(self, data: bytes, offset: int, *, complete: bool) -> Iterator[RecordedMessage]:
        position = 0
        while position + _RECORD_HEADER.size <= len(data):
            opcode, length = _RECORD_HEADER.unpack_from(data, position)
            start = position + _RECORD_HEADER.size
            if start + length > len(data):
                if complete:
                    self.report.skipped.append(f"chunk at byte {offset} ends inside a record")
                return
            yield from self._record(opcode, data[start : start + length], offset)
            position = start + length


def describe_report(report: ReadReport) -> str:
    """One line about how complete a read file was."""
    if report.complete:
        return f"complete recording, {report.messages} message(s)"
    return f"INCOMPLETE recording: {report.problem}; {report.messages} readable message(s) used"


def recording_metadata(fields: Mapping[str, Any]) -> dict[str, str]:
    """Metadata values as the strings MCAP stores."""
    return {
        name: value if isinstance(value, str) else json.dumps(value)
        for name, value in fields.items()
    }
