"""A detection's covariance is checked where it crosses the bus: finite, symmetric, positive
definite, variances at most MAX_VARIANCE_M2, with a test that cannot overflow."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from wz_shared.codec import DecodeError, decode_json, encode_json
from wz_shared.messages import MAX_VARIANCE_M2, Detection, DetectionBatch


def detection(covariance: list[float]) -> Detection:
    return Detection(x_m=1.0, y_m=2.0, covariance_m2=covariance)


@given(
    std_x=st.floats(1e-4, 1e5),
    std_y=st.floats(1e-4, 1e5),
    correlation=st.floats(-0.999, 0.999),
    angle=st.floats(-math.pi, math.pi),
)
@settings(max_examples=300, deadline=None)
def test_a_rotated_covariance_passes(
    std_x: float, std_y: float, correlation: float, angle: float
) -> None:
    """R C R^T of a valid C, symmetrised as the producers do, is accepted unchanged."""
    c = np.array([[std_x**2, correlation * std_x * std_y], [correlation * std_x * std_y, std_y**2]])
    r = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    p = r @ c @ r.T
    p = 0.5 * (p + p.T)
    if np.linalg.eigvalsh(p)[0] <= 1e-12 * np.trace(p):
        return  # rounded to singular: not what this property is about
    values = [float(v) for v in p.reshape(4)]
    assert detection(values).covariance_m2 == values


@pytest.mark.parametrize(
    "covariance",
    [
        [0.04, 0.0, 0.0, 0.04],
        [1.0, 0.999, 0.999, 1.0],
        [MAX_VARIANCE_M2, 0.0, 0.0, 1e-6],
        [2.0, -1.0, -1.0 + 1e-12, 3.0],  # rounding left on a symmetric matrix
    ],
)
def test_good_covariances_pass(covariance: list[float]) -> None:
    assert detection(covariance).covariance_m2 == covariance


@pytest.mark.parametrize(
    ("covariance", "says"),
    [
        ([1.0, 0.0, 0.0, -1.0], "positive"),  # a negative variance
        ([0.0, 0.0, 0.0, 1.0], "positive"),  # a zero variance
        ([1.0, 1.0, 1.0, 1.0], "positive definite"),  # singular
        ([1.0, 2.0, 2.0, 1.0], "positive definite"),  # |sxy| > sqrt(sxx syy)
        ([1.0, 0.5, -0.5, 1.0], "not symmetric"),
        ([1.0, 0.1, 0.2, 1.0], "not symmetric"),
        ([1e308, 0.0, 0.0, 1e308], "at most"),  # would pass a det > 0 test (inf > 0)
        ([1e308, 1e308, 1e308, 1e308], "at most"),  # singular, det = inf - inf = nan
        ([MAX_VARIANCE_M2 * 1.5, 0.0, 0.0, 1.0], "at most"),
        ([1.0, 1e308, 1e308, 1.0], "positive definite"),
        ([1.0, 1e308, -1e308, 1.0], "not symmetric"),  # sxy - syx overflows to inf
        ([float("nan"), 0.0, 0.0, 1.0], "finite"),
        ([1.0, float("inf"), float("inf"), 1.0], "finite"),
        ([1.0, 0.0, 1.0], "at least 4"),
    ],
)
def test_bad_covariances_are_refused_with_what_is_wrong(covariance: list[float], says: str) -> None:
    with pytest.raises(ValidationError) as caught:
        detection(covariance)
    error = caught.value.errors()[0]
    assert error["loc"][0] == "covariance_m2"
    assert says in str(caught.value)


def test_a_batch_with_a_bad_covariance_does_not_decode() -> None:
    """On the bus: the batch is refused as invalid (the node counts it), never handed on."""
    good = DetectionBatch(
        site="s",
        source_id="lidar",
        stamp=1.0,
        frame_index=0,
        detections=[detection([0.04, 0.0, 0.0, 0.04])],
    )
    payload = encode_json(good).replace(b"[0.04,0.0,0.0,0.04]", b"[1e308,0.0,0.0,1e308]")
    assert b"1e308" in payload
    with pytest.raises(DecodeError, match="covariance_m2") as caught:
        decode_json(payload, DetectionBatch)
    assert caught.value.reason == "invalid"
