"""Where a site's sensors can see a car (wz_shared.coverage): from the sensors' geometry."""

from __future__ import annotations

import math

import numpy as np

from wz_shared.coverage import (
    CAR_HEIGHT_M,
    SiteCoverage,
    camera_covers,
    lidar_car_ranges_m,
    lidar_covers,
    radar_covers,
)
from wz_shared.site import (
    DEFAULT_SITE_PATH,
    LidarIntrinsics,
    Pose,
    RadarIntrinsics,
    SensorMount,
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


def test_a_dense_lidar_covers_to_its_range_and_no_further() -> None:
    mount = _lidar(128, -11.25, 11.25, 5.0, max_range_m=120.0)
    assert lidar_covers(mount, [0.0, 119.0], [100.0, 0.0]).all()
    assert not lidar_covers(mount, [121.0], [0.0])[0]


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
    # Downstream the LiDAR alone, as far as a car is sure to be hit (64 beams 6 m up: 131 m).
    reach = lidar_car_ranges_m(mast)
    assert reach is not None and 120.0 < reach[1] < 140.0
    down = mast.pose.y_m + np.array([60.0, reach[1] - 5.0, reach[1] + 10.0])
    assert coverage(np.full(3, lane_x), down).tolist() == [True, True, False]
