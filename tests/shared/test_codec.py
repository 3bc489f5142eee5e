"""Every message round-trips its codec; malformed payloads are rejected with a reason."""

from __future__ import annotations

import json
import math
from typing import get_args, get_origin

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from tests.shared.samples import TINY_JPEG, camera_frame, json_samples, lidar_frame
from wz_shared import codec
from wz_shared.messages import (
    FRAME_MESSAGES,
    JSON_MESSAGES,
    Alert,
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    Message,
)

# Finite floats that survive JSON (the codec writes what pydantic writes).
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


IDENT = st.from_regex(r"[A-Za-z0-9][A-Za-z0-9_.:-]{0,20}", fullmatch=True)
#: A 2x2 covariance (Covariance2 must be symmetric positive definite): variances, correlation.
COVARIANCE2 = st.tuples(st.floats(1e-3, 1e6), st.floats(1e-3, 1e6), st.floats(-0.99, 0.99)).map(
    lambda v: [v[0], v[2] * (v[0] * v[1]) ** 0.5, v[2] * (v[0] * v[1]) ** 0.5, v[1]]
)

#: A track's 4x4 covariance (Covariance4: symmetric positive semi-definite): its variances.
COVARIANCE4 = st.tuples(*[st.floats(0.0, 1e6)] * 4).map(
    lambda v: [v[i] if i == j else 0.0 for i in range(4) for j in range(4)]
)


def _has_pattern(annotation: object) -> bool:
    return "pattern=" in repr(annotation)


def _strategy_for(cls: type[BaseModel]) -> st.SearchStrategy[BaseModel]:
    """Build models from their annotations.

    Hypothesis reads pydantic's numeric bounds but not its string patterns or allow_inf_nan:
    identifiers get a regex strategy, floats a finite one, nested models recurse.
    """
    st.register_type_strategy(float, finite)
    overrides: dict[str, st.SearchStrategy[object]] = {}
    for name, field in cls.model_fields.items():
        if name in ("kind", "schema_version"):
            continue
        if any(getattr(meta, "pattern", None) for meta in field.metadata):
            overrides[name] = IDENT
        elif name == "covariance_m2":
            overrides[name] = COVARIANCE2
        elif name == "covariance":  # a track's: positive semi-definite
            overrides[name] = COVARIANCE4
        elif isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
            overrides[name] = _strategy_for(field.annotation)
        elif get_origin(field.annotation) is list:
            (item,) = get_args(field.annotation)
            if isinstance(item, type) and issubclass(item, BaseModel):
                overrides[name] = st.lists(_strategy_for(item), max_size=3)
            elif _has_pattern(item):
                overrides[name] = st.lists(IDENT, max_size=3)
    return st.builds(cls, **overrides)


@pytest.mark.parametrize("cls", list(JSON_MESSAGES.values()), ids=list(JSON_MESSAGES))
@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(data=st.data())
def test_json_roundtrip_property(cls: type[Message], data: st.DataObject) -> None:
    message = data.draw(_strategy_for(cls))
    assert codec.decode_json(codec.encode_json(message), cls) == message
    assert codec.decode_any_json(codec.encode_json(message)) == message


def test_every_message_kind_is_registered() -> None:
    kinds = {sample.kind for sample in json_samples()}
    assert kinds == set(JSON_MESSAGES)
    assert set(FRAME_MESSAGES) == {"lidar_frame", "camera_frame"}


@settings(max_examples=40, deadline=None)
@given(
    num_points=st.integers(min_value=0, max_value=3000),
    index=st.integers(min_value=0, max_value=10_000),
    with_nan=st.booleans(),
)
def test_lidar_frame_roundtrip_property(num_points: int, index: int, with_nan: bool) -> None:
    meta, points = lidar_frame(index, num_points)
    if with_nan and num_points:
        points[::7] = np.nan  # organized frames mark no-return cells with NaN
    envelope = codec.encode_lidar_frame(meta, points)
    frame = codec.decode_frame(envelope, LidarFrameMeta)
    assert frame.meta == meta
    np.testing.assert_array_equal(frame.points(), points)


def test_lidar_decode_does_not_copy_points() -> None:
    meta, points = lidar_frame(1, 131_072)  # a 2 MB frame
    envelope = bytearray(codec.encode_lidar_frame(meta, points))
    decoded = codec.decode_frame(envelope, LidarFrameMeta).points()
    # The points are a view on the received buffer: writing the buffer shows through.
    envelope[-4:] = np.float32(123.5).tobytes()
    assert decoded[-1, 3] == np.float32(123.5)


@settings(max_examples=40, deadline=None)
@given(jpeg_tail=st.binary(max_size=5000), index=st.integers(min_value=0, max_value=10**6))
def test_camera_frame_roundtrip_property(jpeg_tail: bytes, index: int) -> None:
    meta, _ = camera_frame(index)
    jpeg = TINY_JPEG[:2] + jpeg_tail
    frame = codec.decode_frame(codec.encode_camera_frame(meta, jpeg), CameraFrameMeta)
    assert frame.meta == meta
    assert bytes(frame.payload) == jpeg


# --- malformed input ------------------------------------------------------------------------


def _alert_json(**changes: object) -> bytes:
    alert = next(m for m in json_samples() if isinstance(m, Alert))
    obj = json.loads(codec.encode_json(alert))
    obj.update(changes)
    return json.dumps(obj).encode()


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"{not json", "bad_json"),
        (b"[1, 2, 3]", "bad_json"),
        (b"\xff\xfe\x00", "bad_json"),
        (_alert_json(schema_version=2), "schema_version"),
        (_alert_json(kind="track_batch"), "wrong_kind"),
        (_alert_json(station_m=math.nan), "invalid"),
        (_alert_json(station_m="Infinity"), "invalid"),
        (_alert_json(unexpected_field=1), "invalid"),
        (_alert_json(severity="apocalyptic"), "invalid"),
        (b" " * (codec.MAX_JSON_BYTES + 1), "oversize"),
    ],
    ids=[
        "bad-json",
        "not-object",
        "not-utf8",
        "schema-version",
        "wrong-kind",
        "nan",
        "infinity",
        "extra-field",
        "bad-enum",
        "oversize",
    ],
)
def test_malformed_json_rejected_with_reason(payload: bytes, reason: str) -> None:
    with pytest.raises(codec.DecodeError) as caught:
        codec.decode_json(payload, Alert)
    assert caught.value.reason == reason


def test_nan_written_by_json_is_rejected() -> None:
    """Python's json writes NaN as a bare token: pydantic's parser must refuse it."""
    payload = _alert_json().replace(b'"station_m": 500.0', b'"station_m": NaN')
    assert b"NaN" in payload
    with pytest.raises(codec.DecodeError):
        codec.decode_json(payload, Alert)


def test_ground_truth_rejects_nan_vehicle_speed() -> None:
    truth = next(m for m in json_samples() if isinstance(m, GroundTruth))
    obj = json.loads(codec.encode_json(truth))
    obj["vehicles"][0]["speed_mps"] = float("nan")
    with pytest.raises(codec.DecodeError) as caught:
        codec.decode_json(json.dumps(obj).encode(), GroundTruth)
    assert caught.value.reason == "invalid"


@pytest.mark.parametrize("cut", [0, 3, 7, 20, -1, -16, -1000])
def test_truncated_lidar_frame_rejected(cut: int) -> None:
    meta, points = lidar_frame(3, 512)
    envelope = codec.encode_lidar_frame(meta, points)
    with pytest.raises(codec.DecodeError) as caught:
        codec.decode_frame(envelope[:cut], LidarFrameMeta)
    assert caught.value.reason in {"truncated", "bad_json", "bad_magic"}


def test_frame_with_extra_bytes_rejected() -> None:
    meta, points = lidar_frame(3, 16)
    with pytest.raises(codec.DecodeError) as caught:
        codec.decode_frame(codec.encode_lidar_frame(meta, points) + b"\0" * 16, LidarFrameMeta)
    assert caught.value.reason == "size_mismatch"


def test_frame_bad_magic_and_oversize_metadata() -> None:
    meta, points = lidar_frame(3, 16)
    envelope = bytearray(codec.encode_lidar_frame(meta, points))
    envelope[:4] = b"XXXX"
    with pytest.raises(codec.DecodeError, match="bad_magic"):
        codec.decode_frame(envelope, LidarFrameMeta)
    envelope[:8] = codec.FRAME_MAGIC + (10**9).to_bytes(4, "little")
    with pytest.raises(codec.DecodeError, match="oversize"):
        codec.decode_frame(envelope, LidarFrameMeta)


def test_camera_frame_must_be_jpeg() -> None:
    meta, _ = camera_frame(0)
    with pytest.raises(codec.DecodeError) as caught:
        codec.decode_frame(codec.encode_camera_frame(meta, b"\x89PNG...."), CameraFrameMeta)
    assert caught.value.reason == "bad_jpeg"


def test_json_message_is_not_a_frame() -> None:
    alert = json_samples()[4]
    with pytest.raises(codec.DecodeError, match="bad_magic"):
        codec.decode_frame(codec.encode_json(alert), LidarFrameMeta)


def test_encode_refuses_mismatched_points() -> None:
    meta, points = lidar_frame(0, 10)
    with pytest.raises(ValueError, match="num_points"):
        codec.encode_lidar_frame(meta, points[:5])
    with pytest.raises(ValueError, match="shape"):
        codec.encode_lidar_frame(meta, points[:, :3])


def test_peek_kind() -> None:
    assert codec.peek_kind(codec.encode_json(json_samples()[0])) == "radar_scan"
    meta, points = lidar_frame(0, 4)
    assert codec.peek_kind(codec.encode_lidar_frame(meta, points)) == "lidar_frame"
    assert codec.peek_kind(b"garbage") is None
