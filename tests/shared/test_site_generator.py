"""The site generator: seeded, valid, and over the ranges a DOT meets (issue 25, item 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wz_shared.camera_geometry import PinholeCamera
from wz_shared.site import AreaKind, CameraIntrinsics, LidarIntrinsics, Site
from wz_shared.site_generator import (
    CAMERA_FORMATS,
    buffer_length_m,
    generate_site,
    taper_length_m,
)

SEEDS = range(40)


@pytest.fixture(scope="module")
def sites() -> list[Site]:
    return [generate_site(seed) for seed in SEEDS]


def test_a_seed_gives_the_same_site_and_another_seed_another() -> None:
    assert generate_site(5) == generate_site(5)
    assert generate_site(5) != generate_site(6)


def test_mutcd_taper_and_buffer_lengths() -> None:
    # 12 ft lane: L = W S = 660 ft at 55 mph; W S^2 / 60 = 245 ft at 35 mph.
    assert taper_length_m(12 * 0.3048, 55.0) == pytest.approx(660 * 0.3048)
    assert taper_length_m(12 * 0.3048, 35.0) == pytest.approx(12 * 35**2 / 60 * 0.3048)
    assert buffer_length_m(55.0) == pytest.approx(495 * 0.3048)
    assert buffer_length_m(52.0) == pytest.approx(495 * 0.3048)  # rounded up to the 55 row


def test_sites_cover_the_layouts_a_dot_meets(sites: list[Site]) -> None:
    drops = {(len(s.lanes), "right" if s.closed_lane_index == 0 else "left") for s in sites}
    assert drops == {(2, "right"), (2, "left"), (3, "right"), (3, "left")}
    sides = {s.name.split("mast on the ")[1].split(" ")[0] for s in sites}
    assert sides == {"right", "left", "median"}
    assert any("curve" in s.name for s in sites) and any("straight" in s.name for s in sites)
    formats = {
        (m.intrinsics.width_px, m.intrinsics.height_px)
        for s in sites
        for m in s.sensors
        if isinstance(m.intrinsics, CameraIntrinsics)
    }
    assert formats == set(CAMERA_FORMATS)
    beams = {m.intrinsics.beams for s in sites for m in s.sensors if m.kind == "lidar"}
    assert beams == {32, 64, 128}
    assert len({m.sensor_id for s in sites for m in s.sensors}) > 30  # any sensor ids


def test_each_site_is_within_the_ranges(sites: list[Site]) -> None:
    for site in sites:
        upstream = site.speed_limits[0].speed_limit_mph
        zone = site.speed_limits[1].speed_limit_mph
        assert 45 <= upstream <= 70 and 35 <= zone <= 60 and zone < upstream
        taper = site.area(AreaKind.TRANSITION)
        width = site.lane(0).width_m
        assert taper.end_station_m - taper.start_station_m == pytest.approx(
            taper_length_m(width, zone), abs=0.1
        )
        mast = site.sensors[0].pose
        station, offset = site.road_frame.to_road(mast.x_m, mast.y_m)
        assert 10.0 - 0.1 <= taper.start_station_m - float(station) <= 80.0 + 0.1
        lanes = sorted(site.lanes, key=lambda lane: lane.index)
        right = lanes[0].center_offset_m - width / 2
        left = lanes[-1].center_offset_m + width / 2
        assert float(offset) < right - 2.0 or float(offset) > left + 2.0  # off the road
        assert 4.0 <= mast.z_m <= 10.0
        assert site.alerts.approach_length_m == pytest.approx(
            site.area(AreaKind.ACTIVITY).end_station_m
            - site.area(AreaKind.ADVANCE_WARNING).start_station_m,
            abs=0.1,
        )
        camera = next(m for m in site.sensors if m.kind == "camera")
        assert 50.0 <= camera.intrinsics.horizontal_fov_deg <= 100.0  # type: ignore[union-attr]


def test_curves_are_gentle_enough(sites: list[Site]) -> None:
    for site in sites:
        xy = np.asarray(site.centerline_xy_m)
        steps = np.diff(xy, axis=0)
        headings = np.unwrap(np.arctan2(steps[:, 1], steps[:, 0]))
        lengths = np.hypot(steps[:, 0], steps[:, 1])
        # turn between two chords over the mean of their lengths: the curvature, <= 1/500 m
        curvature = np.abs(np.diff(headings)) / (0.5 * (lengths[1:] + lengths[:-1]))
        assert curvature.max() <= 1.0 / 500.0 + 1e-6, site.site_id


def test_every_sensor_sees_the_approach(sites: list[Site]) -> None:
    """A technician aims the camera down the approach: every lane 40-150 m upstream of the
    mast is in the picture, and within the LiDAR's range."""
    for site in sites:
        camera_mount = next(m for m in site.sensors if m.kind == "camera")
        camera = PinholeCamera(camera_mount)
        mast_station, _ = site.road_frame.to_road(camera_mount.pose.x_m, camera_mount.pose.y_m)
        for upstream in (40.0, 80.0, 150.0):
            for lane in site.lanes:
                x, y = site.road_frame.to_site(float(mast_station) - upstream, lane.center_offset_m)
                uv, depth = camera.project(np.array([[float(x), float(y), 0.75]]))
                assert depth[0] > 0, (site.site_id, upstream, lane.index)
                u, v = uv[0]
                assert 0 <= u <= camera.width_px and 0 <= v <= camera.height_px, (
                    site.site_id,
                    upstream,
                    lane.index,
                    (u, v),
                )
        lidar = next(m for m in site.sensors if isinstance(m.intrinsics, LidarIntrinsics))
        assert lidar.intrinsics.max_range_m >= 150.0  # type: ignore[union-attr]
        assert math.isfinite(lidar.pose.yaw_deg)
