"""The scoring protocol, checked on hand-made frames."""

from __future__ import annotations

import math

import pytest

from wz_lidar_detector.detection import BoxDetection
from wz_lidar_detector.evaluation import Scorer, TruthVehicle, percentile
from wz_shared.messages import VehicleClass


def det(x: float, y: float) -> BoxDetection:
    return BoxDetection(
        (x, y, 0.0), (4.5, 1.8, 1.5), 0.0, VehicleClass.CAR, 50, ((0.1, 0.0), (0.0, 0.1))
    )


def truth(x: float, y: float, visibility: float = 1.0, vid: str = "v") -> TruthVehicle:
    return TruthVehicle(vid, (x, y, 0.0), (4.6, 1.8, 1.5), 0.0, visibility, 100)


def test_hits_misses_false_alarms_and_bins() -> None:
    scorer = Scorer()
    truths = [
        truth(20.0, 0.0, vid="near"),
        truth(70.0, 3.0, vid="far"),
        truth(100.0, 0.0, vid="missed"),
    ]
    detections = [det(21.5, 0.3), det(70.0, 3.0), det(45.0, -10.0)]
    scorer.add_frame(detections, truths)
    near, mid, far, farthest = scorer.bins
    assert (near.scored, near.hits, near.detections, near.false_alarms) == (1, 1, 1, 0)
    assert near.centre_errors_m == [pytest.approx(math.hypot(1.5, 0.3))]
    assert (mid.scored, mid.detections, mid.false_alarms) == (0, 1, 1)  # the one at 45 m
    assert (far.scored, far.hits) == (1, 1)
    assert (farthest.scored, farthest.hits, farthest.detections) == (1, 0, 0)
    total = scorer.total()
    assert total.recall == pytest.approx(2 / 3)
    assert total.precision == pytest.approx(2 / 3)


def test_dont_care_vehicles_neither_help_nor_hurt() -> None:
    scorer = Scorer()
    occluded = truth(30.0, 0.0, visibility=0.1, vid="occluded")
    distant = truth(150.0, 0.0, vid="distant")
    scorer.add_frame([det(30.0, 0.0), det(150.0, 0.0), det(30.5, 0.2)], [occluded, distant])
    total = scorer.total()
    assert (total.scored, total.detections, total.false_alarms) == (0, 0, 0)


def test_a_split_vehicle_costs_precision_not_recall() -> None:
    scorer = Scorer()
    scorer.add_frame([det(20.0, 0.0), det(21.8, 0.0)], [truth(20.5, 0.0)])
    total = scorer.total()
    assert total.recall == 1.0
    assert (total.detections, total.false_alarms) == (2, 1)


def test_detection_outside_the_footprint_margin_does_not_count() -> None:
    scorer = Scorer(margin_m=0.5)
    scorer.add_frame([det(20.0, 2.0)], [truth(20.0, 0.0)])  # 2 m across: 1.1 m outside the side
    total = scorer.total()
    assert (total.hits, total.false_alarms) == (0, 1)
    assert math.isnan(percentile([], 50))


def test_heading_prior_from_the_site_road() -> None:
    from wz_lidar_detector.node import road_heading_in_sensor_frame
    from wz_shared.site import DEFAULT_SITE_PATH, Pose, load_site

    site = load_site(DEFAULT_SITE_PATH)
    mount = site.sensor("lidar-mast")
    # The road runs north at the mast; the sensor looks south: travel is along its -x axis.
    assert abs(math.cos(road_heading_in_sensor_frame(site, mount)) + 1.0) < 1e-9
    turned = mount.model_copy(update={"pose": Pose(x_m=7.5, y_m=980.0, z_m=6.0, yaw_deg=0.0)})
    assert road_heading_in_sensor_frame(site, turned) == pytest.approx(math.pi / 2, abs=1e-6)
