"""Where a site's sensors can see a car (wz_shared.coverage): from the sensors' geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wz_shared.coverage import (
    CAR_HEIGHT_M,
    CAR_REFLECTIVITY,
    SensorGaps,
    SiteCoverage,
    _bounded_runs,
    camera_covers,
    camera_fog_range_m,
    lidar_beam_rows,
    lidar_car_ranges_m,
    lidar_covers,
    lidar_detection_range_m,
    radar_covers,
)
from wz_shared.site import (
    DEFAULT_SITE_PATH,
    LidarIntrinsics,
    Pose,
    RadarIntrinsics,
    SensorMount,
    Site,
    load_site,
)


def _lidar(
    beams: int, low: float, high: float, z_m: float, max_range_m: float = 200.0
) -> SensorMount:
    return SensorMount(
        sensor_id="l",
        pose=Pose(x_m=0.0, y_m=0.0, z_m=z_m),
        intrinsics=LidarIntrinsics(
            beams=beams, vertical_min_deg=low, vertical_max_deg=high, max_range_m=max_range_m
        ),
        rate_hz=10.0,
    )


def test_a_lidar_covers_a_car_while_its_beams_are_closer_than_the_car_subtends() -> None:
    mount = _lidar(32, -25.0, 15.0, 5.0)  # VLP-32C-like: 40 / 31 = 1.29 degrees apart
    spacing = 40.0 / 31.0
    r = np.arange(20.0, 150.0, 0.25)
    span = np.degrees(np.arctan(5.0 / r) - np.arctan((5.0 - CAR_HEIGHT_M) / r))
    far = float(r[span >= spacing].max())  # the farthest range the car spans a beam spacing
    assert 60.0 < far < 72.0
    assert lidar_covers(mount, [far - 1.0], [0.0])[0]
    assert not lidar_covers(mount, [far + 1.0], [0.0])[0]
    # Twice the beams over the same fan: about twice as far.
    dense = _lidar(64, -25.0, 15.0, 5.0)
    near, farther = lidar_car_ranges_m(dense) or (0.0, 0.0)
    assert 1.8 * far < farther < 2.2 * far
    # Under the sensor, below its lowest beam: the blind cone (the -25 degree beam passes a
    # car's roof, 3.5 m under the sensor, at 7.5 m).
    assert 7.5 <= near < 9.0
    assert not lidar_covers(dense, [3.0], [0.0])[0]


def test_beam_rows_count_the_beam_spacings_a_car_spans_inside_the_fan() -> None:
    mount = _lidar(32, -25.0, 15.0, 5.0)
    spacing = 40.0 / 31.0
    # At 30 m the car spans atan(5/30) - atan(3.5/30) = 2.79 degrees: 2.16 spacings.
    expected = math.degrees(math.atan(5.0 / 30.0) - math.atan(3.5 / 30.0)) / spacing
    assert lidar_beam_rows(mount, [30.0], [0.0])[0] == pytest.approx(expected)
    # At 9 m the car's foot is under the fan (-29.1 degrees): only from -25 degrees up to its
    # roof (-21.3 degrees) counts.
    top = (25.0 - math.degrees(math.atan(3.5 / 9.0))) / spacing
    assert lidar_beam_rows(mount, [9.0], [0.0])[0] == pytest.approx(top)
    # Under the sensor, the whole car below the fan; beyond the paint's reach: none.
    assert lidar_beam_rows(mount, [2.0, 500.0], [0.0, 0.0]).tolist() == [0.0, 0.0]
    assert (lidar_beam_rows(mount, [30.0, 80.0], [0.0, 0.0]) >= 1.0).tolist() == (
        lidar_covers(mount, [30.0, 80.0], [0.0, 0.0]).tolist()
    )


def test_a_dense_lidar_covers_as_far_as_a_cars_paint_returns() -> None:
    mount = _lidar(128, -11.25, 11.25, 5.0, max_range_m=200.0)
    # Datasheet convention: 80 % reflectivity at 200 m, so paint of 30 % to 200 sqrt(0.3 / 0.8).
    reach = 200.0 * math.sqrt(CAR_REFLECTIVITY / 0.8)
    assert lidar_detection_range_m(200.0) == pytest.approx(reach)
    assert lidar_covers(mount, [0.0, reach - 1.0], [100.0, 0.0]).all()
    assert not lidar_covers(mount, [reach + 1.0], [0.0])[0]
    # Fog of 150 m visibility (Koschmieder, 3.912 / 150 per metre): the two-way loss
    # exp(-2 alpha r) brings it in to where 0.3 exp(-2 alpha r) (200 / r)^2 = 0.8.
    alpha = 3.912 / 150.0
    foggy = lidar_detection_range_m(200.0, alpha)
    assert 0.3 * math.exp(-2 * alpha * foggy) * (200.0 / foggy) ** 2 == pytest.approx(0.8)
    assert 35.0 < foggy < 50.0
    assert lidar_covers(mount, [foggy - 1.0], [0.0], alpha)[0]
    assert not lidar_covers(mount, [foggy + 1.0], [0.0], alpha)[0]
    # A camera finds a car in fog to where its contrast falls to 5 %: exp(-3.912 r / V).
    assert math.exp(-3.912 * camera_fog_range_m(150.0) / 150.0) == pytest.approx(0.05)
    assert camera_fog_range_m(math.inf) == math.inf


def test_radar_covers_its_wedge_only() -> None:
    mount = SensorMount(
        sensor_id="r",
        pose=Pose(x_m=0.0, y_m=0.0, z_m=5.0, yaw_deg=90.0),  # boresight north
        intrinsics=RadarIntrinsics(max_range_m=200.0, horizontal_fov_deg=60.0),
        rate_hz=20.0,
    )
    inside = math.tan(math.radians(29.0)) * 100.0
    outside = math.tan(math.radians(31.0)) * 100.0
    assert radar_covers(mount, [0.0, inside, -inside], [150.0, 100.0, 100.0]).all()
    assert not radar_covers(mount, [outside], [100.0])[0]
    assert not radar_covers(mount, [0.0], [-50.0])[0]  # behind
    assert not radar_covers(mount, [0.0], [201.0])[0]  # too far


def test_on_the_default_site_the_approach_is_covered_and_the_far_downstream_is_not() -> None:
    site = load_site(DEFAULT_SITE_PATH)  # straight road along y, traffic northbound
    mast = next(m for m in site.sensors if m.kind == "lidar")
    coverage = SiteCoverage(site)
    camera = next(m for m in site.sensors if m.kind == "camera")
    lane_x = site.lanes[0].center_offset_m
    up = np.array([mast.pose.y_m - d for d in (30.0, 80.0, 140.0)])
    # Upstream, the camera sees the approach; behind it (downstream), it does not.
    assert camera_covers(camera, np.full(3, lane_x), up).all()
    assert not camera_covers(camera, [lane_x], [mast.pose.y_m + 60.0])[0]
    assert coverage(np.full(3, lane_x), up).all()
    # Downstream the LiDAR alone, as far as it sees a car (64 beams 6 m up put one on it to
    # 131 m; its paint returns to 122 m of a 200 m sensor).
    reach = lidar_car_ranges_m(mast)
    assert reach is not None and 120.0 < reach[1] < 125.0
    down = mast.pose.y_m + np.array([60.0, reach[1] - 5.0, reach[1] + 10.0])
    assert coverage(np.full(3, lane_x), down).tolist() == [True, True, False]
    # In fog the LiDAR sees less than half as far; the radar still covers the approach.
    fog = SiteCoverage(site, lidar_extinction_per_m=3.912 / 150.0, visibility_m=150.0)
    assert fog(np.full(3, lane_x), down).tolist() == [False, False, False]
    assert fog(np.full(3, lane_x), up).all()


SITE = load_site(DEFAULT_SITE_PATH)


def _with_lidar_height(site: Site, z_m: float) -> Site:
    """The site with its LiDAR (and nothing else) raised to ``z_m``."""
    sensors = [
        m.model_copy(update={"pose": m.pose.model_copy(update={"z_m": z_m})})
        if m.kind == "lidar"
        else m
        for m in site.sensors
    ]
    return site.model_copy(update={"sensors": sensors})


def test_sensor_gaps_are_the_unseen_stretches_between_seen_road() -> None:
    unseen = np.array([1, 1, 0, 0, 1, 1, 1, 0, 1, 1, 1, 1, 1, 0, 1], dtype=bool)
    # the leading and trailing runs are not bounded; the 5-long run is longer than 4
    assert _bounded_runs(unseen, 4).tolist() == [
        False, False, False, False, True, True, True, False,
        False, False, False, False, False, False, False,
    ]  # fmt: skip
    # a mast high above the road: its LiDAR's blind cone is a gap; a low one leaves none
    high = _with_lidar_height(SITE, 12.0)
    gaps = SensorGaps(high)
    spans = gaps.spans_m(0)
    assert spans, "a 12 m mast leaves an unseen stretch under it"
    (lidar,) = [m for m in high.sensors if m.kind == "lidar"]
    mast_station = float(high.road_frame.to_road(lidar.pose.x_m, lidar.pose.y_m)[0])
    assert any(a - 5.0 <= mast_station <= b + 40.0 for a, b in spans)
    a, b = spans[0]
    x, y = high.road_frame.to_site(0.5 * (a + b), high.lanes[0].center_offset_m)
    assert gaps(float(x), float(y))
    x, y = high.road_frame.to_site(a - 50.0, high.lanes[0].center_offset_m)
    assert not gaps(float(x), float(y))
    x, y = high.road_frame.to_site(0.5 * (a + b), 30.0)  # off the road
    assert not gaps(float(x), float(y))
