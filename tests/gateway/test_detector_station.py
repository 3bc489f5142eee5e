"""Where the WZDx traffic sensor's virtual loop goes (wz_gateway.wzdx.detector_station_m):
from the site's LiDAR geometry, on generated sites of every layout."""

from __future__ import annotations

import numpy as np
import pytest

from wz_gateway.wzdx import (
    DETECTOR_CAR_REACH_M,
    MAX_LATERAL_SPEED_MPS,
    detector_lane_index,
    detector_lanes,
    detector_station_m,
)
from wz_shared.coverage import lidar_beam_rows
from wz_shared.site import DEFAULT_SITE_PATH, AreaKind, LidarIntrinsics, Site, load_site
from wz_shared.site_generator import generate_site


def _station_of(site: Site, kind: str) -> float:
    mount = next(m for m in site.sensors if m.kind == kind)
    return float(site.road_frame.to_road(mount.pose.x_m, mount.pose.y_m)[0])


def _worst_lane_rows(site: Site, stations: np.ndarray) -> np.ndarray:
    lidars = [m for m in site.sensors if m.kind == "lidar"]
    worst = np.full(stations.shape, np.inf)
    for lane in site.lanes:
        x, y = site.road_frame.to_site(stations, np.full(stations.shape, lane.center_offset_m))
        worst = np.minimum(worst, np.max([lidar_beam_rows(m, x, y) for m in lidars], axis=0))
    return worst


@pytest.mark.parametrize("seed", [11, 23, 4242, 60001, 77777])
def test_the_loop_is_upstream_where_the_lidar_sees_every_lane(seed: int) -> None:
    site = generate_site(seed)
    station = detector_station_m(site)
    assert station <= site.area(AreaKind.TRANSITION).start_station_m
    assert station <= _station_of(site, "lidar") + 1e-6
    around = np.arange(station - DETECTOR_CAR_REACH_M, station + DETECTOR_CAR_REACH_M + 0.5)
    rows = _worst_lane_rows(site, around)
    assert rows.min() >= 1.0, (site.name, station, rows)  # a beam sure to cross each lane's car
    # No other station within 80 m upstream has its worst lane seen better over a car's
    # length either side.
    end = min(_station_of(site, "lidar"), site.area(AreaKind.TRANSITION).start_station_m)
    for other in np.arange(np.floor(end) - 80.0, np.floor(end) - DETECTOR_CAR_REACH_M, 1.0):
        near = np.arange(other - DETECTOR_CAR_REACH_M, other + DETECTOR_CAR_REACH_M + 0.5)
        assert _worst_lane_rows(site, near).min() <= rows.min() + 1e-9, (site.name, other)


def test_an_override_wins_and_a_site_without_a_lidar_counts_30_m_before_its_sensor() -> None:
    site = load_site(DEFAULT_SITE_PATH)
    assert detector_station_m(site, 512.0) == 512.0
    no_lidar = site.model_copy(update={"sensors": [m for m in site.sensors if m.kind != "lidar"]})
    assert detector_station_m(no_lidar) == pytest.approx(_station_of(no_lidar, "camera") - 30.0)


def test_a_lidar_that_puts_no_sure_beam_on_the_far_lane_falls_back_to_30_m() -> None:
    site = load_site(DEFAULT_SITE_PATH)
    sparse = [
        m.model_copy(update={"intrinsics": LidarIntrinsics(beams=2, vertical_min_deg=-40.0)})
        if m.kind == "lidar"
        else m
        for m in site.sensors
    ]
    thin = site.model_copy(update={"sensors": sparse})
    assert detector_station_m(thin) == pytest.approx(_station_of(thin, "lidar") - 30.0)
    assert detector_station_m(site) != pytest.approx(_station_of(site, "lidar") - 30.0)


def test_a_track_just_off_the_outer_lanes_counts_in_them() -> None:
    site = load_site(DEFAULT_SITE_PATH)
    right = min(site.lanes, key=lambda lane: lane.center_offset_m)
    left = max(site.lanes, key=lambda lane: lane.center_offset_m)
    right_edge = right.center_offset_m - right.width_m / 2
    left_edge = left.center_offset_m + left.width_m / 2
    offsets = [
        right.center_offset_m,
        right_edge - 0.4 * right.width_m,  # on the shoulder, within half a lane: the edge lane
        right_edge - 0.6 * right.width_m,  # farther out: none
        left_edge + 0.4 * left.width_m,
        left_edge + 0.6 * left.width_m,
    ]
    got = detector_lane_index(site, offsets).tolist()
    assert got == [right.index, right.index, -1, left.index, -1]
    inside = np.linspace(right_edge + 0.01, left_edge - 0.01, 50)
    assert (detector_lane_index(site, inside) == site.lane_index_at(inside)).all()


def test_a_track_sliding_across_the_road_is_counted_in_no_lane() -> None:
    site = load_site(DEFAULT_SITE_PATH)
    station = np.array([600.0, 600.0, 600.0])
    heading = float(site.road_frame.heading_at(600.0))
    along = np.array([np.cos(heading), np.sin(heading)])
    left = np.array([-np.sin(heading), np.cos(heading)])
    # 25 m/s along the road; lateral 0, a lane change's 1.2 m/s, and a coasting track's 4 m/s.
    lateral = np.array([0.0, 1.2, 2.0 * MAX_LATERAL_SPEED_MPS])
    velocity = 25.0 * along[None, :] + lateral[:, None] * left[None, :]
    offset = np.full(3, site.lanes[0].center_offset_m)
    got = detector_lanes(site, station, offset, velocity[:, 0], velocity[:, 1]).tolist()
    assert got == [site.lanes[0].index, site.lanes[0].index, -1]
