"""Covariances are checked where they cross the bus: a detection's finite, symmetric, positive
definite, variances at most MAX_VARIANCE_M2; a track's the same but semi-definite (zero: not
known) and its velocity variances at most MAX_VELOCITY_VARIANCE_M2PS2; with tests that cannot
overflow (no determinant)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from tests.alert_service.helpers import make_track
from wz_shared.codec import DecodeError, decode_json, encode_json
from wz_shared.messages import (
    MAX_VARIANCE_M2,
    MAX_VELOCITY_VARIANCE_M2PS2,
    Detection,
    DetectionBatch,
    Track,
    _check_covariance,
    _detection_covariance,
)


def detection(covariance: list[float]) -> Detection:
    return Detection(x_m=1.0, y_m=2.0, covariance_m2=covariance)


@given(
    std_x=st.floats(1e-4, 5e3),
    std_y=st.floats(1e-4, 5e3),
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
        ([1e9, 0.0, 0.0, 1.0], "at most"),  # a std of 31 km: nowhere on a site
        ([float("-inf"), 0.0, 0.0, 1.0], "finite"),
        ([1e-300, 1e-10, 1e-10, 1e-300], "positive definite"),  # r = 1e290
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


@given(values=st.lists(st.floats(-10.0, 10.0), min_size=4, max_size=4))
@settings(max_examples=500, deadline=None)
def test_the_scalar_2x2_check_agrees_with_the_general_one(values: list[float]) -> None:
    """Detections take a scalar path (fast); it must accept exactly what the general check
    (numpy, Cholesky) accepts, variance bounds and symmetry included."""
    values = [values[0] ** 2, values[1], values[1] * (1.0 + values[2] * 1e-10), values[3] ** 2]

    def accepted(check: object) -> bool:
        try:
            check(values)  # type: ignore[operator]
        except ValueError:
            return False
        return True

    general = accepted(
        lambda v: _check_covariance(v, (MAX_VARIANCE_M2, MAX_VARIANCE_M2), definite=True)
    )
    assert accepted(_detection_covariance) == general


def track(covariance: list[float]) -> Track:
    return make_track(1, 100.0, 20.0).model_copy(update={"covariance": covariance})


def tracker_covariance() -> list[float]:
    """A filter's P: positions 0.3 m std, velocities 2 m/s, position-velocity correlated."""
    p = np.diag([0.09, 0.09, 4.0, 4.0])
    p[0, 2] = p[2, 0] = p[1, 3] = p[3, 1] = 0.3
    return [float(v) for v in p.reshape(16)]


def test_good_track_covariances_pass() -> None:
    for covariance in (
        tracker_covariance(),
        [0.0] * 16,  # not known (tracks from ground truth)
        [float(v) for v in np.diag([MAX_VARIANCE_M2, 1.0, MAX_VELOCITY_VARIANCE_M2PS2, 0.0]).flat],
    ):
        assert Track.model_validate({**track(covariance).model_dump()}).covariance == covariance


def _with(changes: dict[int, float]) -> list[float]:
    values = tracker_covariance()
    for index, value in changes.items():
        values[index] = value
    return values


@pytest.mark.parametrize(
    ("covariance", "says"),
    [
        (_with({0: 1e308}), "at most"),  # would pass a det > 0 test
        (_with({0: 1e308, 5: 1e308, 10: 1e308, 15: 1e308}), "at most"),
        (_with({10: 1e7}), "at most"),  # a velocity std of 3 km/s
        (_with({0: -0.09}), "non-negative"),
        (_with({0: float("inf")}), "finite"),
        (_with({3: float("nan")}), "finite"),
        (_with({2: 0.3, 8: 0.2}), "not symmetric"),
        (_with({1: 1e308, 4: -1e308}), "not symmetric"),
        (_with({1: 1e308, 4: 1e308}), "semi-definite"),  # correlation 1e309: inf
        (_with({1: 0.5, 4: 0.5}), "semi-definite"),  # |correlation| = 5.6
        (_with({0: 0.0}), "semi-definite"),  # zero variance, covariance 0.3 with vx
        ([1.0] * 15, "at least 16"),
    ],
)
def test_bad_track_covariances_are_refused(covariance: list[float], says: str) -> None:
    with pytest.raises(ValidationError) as caught:
        Track.model_validate({**track(tracker_covariance()).model_dump(), "covariance": covariance})
    assert caught.value.errors()[0]["loc"][0] == "covariance"
    assert says in str(caught.value)
