"""What smoothing does to a stored trajectory (the smoother itself, against filterpy, and its
invariants: tests/shared/test_motion.py)."""

from __future__ import annotations

import numpy as np

from tests.gateway.helpers import SITE
from tests.gateway.tracking import filtered_car
from wz_gateway.smoothing import StoredTrajectory, smooth_trajectory
from wz_shared.motion import ProcessNoise, rts_smooth


def test_a_smoothed_trajectory_gets_its_road_position_lane_and_wgs84_again() -> None:
    car = filtered_car(seed=8, count=120)
    n = len(car.stamps_s)
    station, offset = SITE.road_frame.to_road(car.x_filt[:, 0], car.x_filt[:, 1])
    latitude, longitude, _ = SITE.geo_frame.to_wgs84(car.x_filt[:, 0], car.x_filt[:, 1])
    stored = StoredTrajectory(
        track_id=5,
        stamp=car.stamps_s,
        x_m=car.x_filt[:, 0],
        y_m=car.x_filt[:, 1],
        vx_mps=car.x_filt[:, 2],
        vy_mps=car.x_filt[:, 3],
        covariance=car.P_filt,
        latitude_deg=latitude,
        longitude_deg=longitude,
        station_m=station,
        offset_m=offset,
        lane_index=SITE.lane_index_at(offset).astype(np.int64),
        speed_mps=np.hypot(car.x_filt[:, 2], car.x_filt[:, 3]),
        heading_rad=np.arctan2(car.x_filt[:, 3], car.x_filt[:, 2]),
        object_class=("unknown",) * (n - 1) + ("car",),
        status=("tentative",) + ("confirmed",) * (n - 1),
        length_m=np.r_[np.full(n - 1, np.nan), 4.4],
        width_m=np.r_[np.full(n - 1, np.nan), 1.8],
        received_at=1000.0 + car.stamps_s,
    )
    noise = ProcessNoise(1.0, 0.5)
    smoothed = smooth_trajectory(stored, SITE, noise)
    x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, noise)
    assert np.array_equal(smoothed.x_m, x_s[:, 0]) and np.array_equal(smoothed.vy_mps, x_s[:, 3])
    s, d = SITE.road_frame.to_road(x_s[:, 0], x_s[:, 1])
    np.testing.assert_allclose(smoothed.station_m, s, atol=1e-9)
    np.testing.assert_allclose(smoothed.offset_m, d, atol=1e-9)
    assert np.array_equal(smoothed.lane_index, SITE.lane_index_at(d))
    lat, lon, _ = SITE.geo_frame.to_wgs84(x_s[:, 0], x_s[:, 1])
    np.testing.assert_allclose(smoothed.latitude_deg, lat, atol=1e-12)
    np.testing.assert_allclose(smoothed.longitude_deg, lon, atol=1e-12)
    np.testing.assert_allclose(smoothed.speed_mps, np.hypot(x_s[:, 2], x_s[:, 3]), atol=1e-12)
    # hindsight: the last class and size for every point; stamps, status, arrival kept
    assert set(smoothed.object_class) == {"car"}
    assert np.all(smoothed.length_m == 4.4) and np.all(smoothed.width_m == 1.8)
    assert smoothed.status == stored.status
    assert np.array_equal(smoothed.stamp, stored.stamp)
    assert np.array_equal(smoothed.received_at, stored.received_at)
