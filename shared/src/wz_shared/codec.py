"""Wire formats: JSON for messages, a binary envelope for frames.

JSON messages are the pydantic model serialised as UTF-8 JSON; its ``"kind"`` tag lets a
recording or a tap tell the type without the key.

A frame travels as one binary envelope::

    offset  size  field
    0       4     magic b"WZF1"
    4       4     metadata length M (uint32, little-endian)
    8       M     metadata: JSON of the frame's metadata model (with "kind")
    8+M     ...   payload: raw float32 points (N x 4, little-endian) or JPEG bytes

Decoding does not copy the payload: points come back as a read-only ``np.ndarray`` view on the
received buffer, JPEG bytes as a ``memoryview``. Encoding copies the payload once, into the
envelope.

Every decode failure raises :class:`DecodeError` with a short ``reason`` (used as the counter
name when a subscriber drops the message) and a message for the log.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np
import numpy.typing as npt
from pydantic import ValidationError

from wz_shared.messages import (
    FRAME_MESSAGES,
    JSON_MESSAGES,
    CameraFrameMeta,
    LidarFrameMeta,
    Message,
    kind_of,
)

FRAME_MAGIC = b"WZF1"
_HEADER = struct.Struct("<4sI")
#: Largest JSON message accepted [bytes]; a track batch of 500 tracks is about 300 kB.
MAX_JSON_BYTES = 4 * 1024 * 1024
#: Largest frame envelope accepted [bytes]: a 4-Mpoint LiDAR frame or a large JPEG.
MAX_FRAME_BYTES = 64 * 1024 * 1024
MAX_FRAME_META_BYTES = 64 * 1024
POINT_DTYPE = np.dtype("<f4")
POINT_FIELDS = 4

M = TypeVar("M", bound=Message)


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected type."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


# --- JSON -----------------------------------------------------------------------------------


def encode_json(message: Message) -> bytes:
    """Serialise a message as UTF-8 JSON (its ``kind`` tag included)."""
    return message.model_dump_json().encode()


def _reason(exc: ValidationError) -> DecodeError:
    """Map a pydantic error to a counter name and a one-line detail for the log."""
    first = exc.errors()[0]
    where = ".".join(str(part) for part in first["loc"])
    detail = f"{exc.error_count()} error(s), first at {where or '<root>'}: {first['msg']}"
    if first["type"] in ("json_invalid", "model_type", "model_attributes_type"):
        reason = "bad_json"
    elif first["loc"][:1] == ("kind",):
        reason = "wrong_kind"
    elif first["loc"][:1] == ("schema_version",):
        reason = "schema_version"
    else:
        reason = "invalid"
    return DecodeError(reason, detail)


def decode_json(
    payload: bytes | bytearray | memoryview, cls: type[M], limit: int = MAX_JSON_BYTES
) -> M:
    """Parse and validate a JSON message of type ``cls``; raise :class:`DecodeError`.

    Parsing and validation run in pydantic-core (no intermediate Python dict).
    """
    if len(payload) > limit:
        raise DecodeError("oversize", f"{len(payload)} bytes exceeds the limit of {limit}")
    try:
        return cls.model_validate_json(
            bytes(payload) if isinstance(payload, memoryview) else payload
        )
    except ValidationError as exc:
        raise _reason(exc) from exc


def peek_kind(payload: bytes | bytearray | memoryview) -> str | None:
    """The ``kind`` of any payload (JSON message or frame envelope), without validating it."""
    view = memoryview(payload)
    if len(view) >= _HEADER.size and bytes(view[:4]) == FRAME_MAGIC:
        (_, meta_len) = _HEADER.unpack_from(view, 0)
        view = view[_HEADER.size : _HEADER.size + min(meta_len, MAX_FRAME_META_BYTES)]
    elif len(view) > MAX_JSON_BYTES:
        return None
    try:
        obj = json.loads(bytes(view))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    kind = obj.get("kind") if isinstance(obj, dict) else None
    return kind if isinstance(kind, str) else None


def decode_any_json(payload: bytes | bytearray | memoryview) -> Message:
    """Parse a JSON message of any registered kind (for taps and recordings)."""
    kind = peek_kind(payload)
    cls = JSON_MESSAGES.get(kind or "")
    if cls is None:
        raise DecodeError("wrong_kind", f"unknown message kind {kind!r}")
    return decode_json(payload, cls)


# --- binary frames --------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame(Generic[M]):
    """A decoded frame: its metadata and a zero-copy view of its payload."""

    meta: M
    payload: memoryview

    def points(self) -> npt.NDArray[np.float32]:
        """LiDAR points as a read-only ``(num_points, 4)`` float32 view (x, y, z, intensity)."""
        return np.frombuffer(self.payload, dtype=POINT_DTYPE).reshape(-1, POINT_FIELDS)


def encode_lidar_frame(meta: LidarFrameMeta, points: npt.ArrayLike) -> bytes:
    """Envelope a LiDAR frame: ``points`` is ``(num_points, 4)`` float32 (x, y, z, intensity).

    NaN is allowed in points (an organized frame marks no-return cells with NaN).
    """
    array = np.ascontiguousarray(points, dtype=POINT_DTYPE)
    if array.ndim != 2 or array.shape[1] != POINT_FIELDS:
        raise ValueError(f"points must have shape (N, 4), got {array.shape}")
    if array.shape[0] != meta.num_points:
        raise ValueError(f"meta.num_points={meta.num_points} but {array.shape[0]} points given")
    return _envelope(meta, array.reshape(-1).view(np.uint8).data)


def encode_camera_frame(meta: CameraFrameMeta, jpeg: bytes | memoryview) -> bytes:
    """Envelope a camera frame (JPEG bytes)."""
    return _envelope(meta, memoryview(jpeg))


def _envelope(meta: Message, payload: memoryview) -> bytes:
    meta_json = encode_json(meta)
    if len(meta_json) > MAX_FRAME_META_BYTES:
        raise ValueError(f"frame metadata of {len(meta_json)} bytes is too large")
    return b"".join((_HEADER.pack(FRAME_MAGIC, len(meta_json)), meta_json, payload))


def decode_frame(payload: bytes | bytearray | memoryview, cls: type[M]) -> Frame[M]:
    """Split and validate a frame envelope of metadata type ``cls``.

    Checks the magic, lengths, metadata schema, and that the payload size matches the metadata
    (``num_points * 16`` bytes for LiDAR; a JPEG start-of-image marker for camera frames).
    """
    view = memoryview(payload).cast("B") if not isinstance(payload, memoryview) else payload
    if len(view) > MAX_FRAME_BYTES:
        raise DecodeError("oversize", f"{len(view)} bytes exceeds the limit of {MAX_FRAME_BYTES}")
    if len(view) < _HEADER.size:
        raise DecodeError("truncated", f"{len(view)} bytes is shorter than the frame header")
    magic, meta_len = _HEADER.unpack_from(view, 0)
    if magic != FRAME_MAGIC:
        raise DecodeError("bad_magic", f"expected {FRAME_MAGIC!r}, got {bytes(magic)!r}")
    if meta_len > MAX_FRAME_META_BYTES:
        raise DecodeError("oversize", f"frame metadata length {meta_len} is too large")
    body_start = _HEADER.size + meta_len
    if len(view) < body_start:
        raise DecodeError(
            "truncated", f"metadata claims {meta_len} bytes, only {len(view) - 8} present"
        )
    meta = decode_json(view[_HEADER.size : body_start], cls, limit=MAX_FRAME_META_BYTES)
    body = view[body_start:]
    if isinstance(meta, LidarFrameMeta):
        expected = meta.num_points * POINT_FIELDS * POINT_DTYPE.itemsize
        if len(body) != expected:
            raise DecodeError(
                "truncated" if len(body) < expected else "size_mismatch",
                f"{meta.num_points} points need {expected} bytes, got {len(body)}",
            )
        if meta.organized and meta.rows * meta.columns != meta.num_points:
            raise DecodeError(
                "invalid", f"organized frame {meta.rows}x{meta.columns} != {meta.num_points}"
            )
    elif isinstance(meta, CameraFrameMeta) and bytes(body[:2]) != b"\xff\xd8":
        raise DecodeError("bad_jpeg", "payload does not start with a JPEG SOI marker")
    return Frame(meta=meta, payload=body)


# --- one entry point for the bus ------------------------------------------------------------


def encode(message: Message) -> bytes:
    """Encode a JSON message (frames need their payload: use ``encode_*_frame``)."""
    if kind_of(type(message)) in FRAME_MESSAGES:
        raise TypeError(f"{type(message).__name__} is frame metadata: use encode_*_frame")
    return encode_json(message)


def is_frame_type(cls: type[Message]) -> bool:
    return kind_of(cls) in FRAME_MESSAGES
