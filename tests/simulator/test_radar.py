"""Radar model: closed-form geometry, resolution cells, visibility, detection and false alarms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.purity import top_level_imports
from wz_shared.codec import decode_json, encode_json
from wz_shared.messages import DriverProfile, RadarScan, VehicleClass, VehicleTruth
from wz_shared.site import CameraIntrinsics, Pose, RadarIntrinsics, SensorMount
from wz_simulator.sensors import radar as radar_module
from wz_simulator.sensors.radar import RadarModel
from wz_simulator.sensors.scene import Weather

CAR_Z_M = 0.75  # centre height of a 1.5 m tall car
SIZES = {  # length, width, height [m]
    VehicleClass.CAR: (4.5, 1.8, 1.5),
    VehicleClass.TRUCK: (16.0, 2.5, 4.0),
    VehicleClass.MOTORCYCLE: (2.2, 0.8, 1.4),
}


def vehicle(
    vehicle_id: str,
    x_m: float,
    y_m: float,
    heading_rad: float,
    speed_mps: float = 30.0,
    vehicle_class: VehicleClass = VehicleClass.CAR,
) -> VehicleTruth:
    length, width, height = SIZES[vehicle_class]
    return VehicleTruth(
        vehicle_id=vehicle_id,
        vehicle_class=vehicle_class,
        x_m=x_m,
        y_m=y_m,
        z_m=height / 2.0,
        heading_rad=heading_rad,
        speed_mps=speed_mps,
        accel_mps2=0.0,
        length_m=length,
        width_m=width,
        height_m=height,
        lane_index=0,
        station_m=0.0,
        offset_m=0.0,
        driver_profile=DriverProfile.NORMAL,
    )


def mount(
    x_m: float = 0.0,
    y_m: float = 0.0,
    z_m: float = CAR_Z_M,
    yaw_deg: float = 0.0,
    noise: bool = False,
) -> SensorMount:
    stds = (
        {}
        if noise
        else dict(range_noise_std_m=0.0, azimuth_noise_std_deg=0.0, speed_noise_std_mps=0.0)
    )
    return SensorMount(
        sensor_id="radar-test",
        pose=Pose(x_m=x_m, y_m=y_m, z_m=z_m, yaw_deg=yaw_deg),
        intrinsics=RadarIntrinsics(**stds),
        rate_hz=15.0,
    )


def model(
    sensor: SensorMount | None = None,
    seed: int = 7,
    false_alarm_rate_per_scan: float = 0.0,
    weather: Weather | None = None,
) -> RadarModel:
    return RadarModel(
        sensor or mount(),
        weather or Weather(),
        seed,
        site_id="test-site",
        false_alarm_rate_per_scan=false_alarm_rate_per_scan,
    )


def v_cos_angle(truth: VehicleTruth, point_xyz: np.ndarray, sensor_xyz: np.ndarray) -> float:
    """Closed form: speed times the cosine of the angle between velocity and line of sight."""
    velocity = np.array([math.cos(truth.heading_rad), math.sin(truth.heading_rad), 0.0])
    line_of_sight = point_xyz - sensor_xyz
    cos_angle = float(velocity @ line_of_sight / np.linalg.norm(line_of_sight))
    return truth.speed_mps * cos_angle


# --- radial speed ---------------------------------------------------------------------------


def test_head_on_gives_minus_v_receding_plus_v_crossing_zero() -> None:
    radar = model()
    cars = [
        vehicle("approaching", 80.0, 0.0, math.pi, speed_mps=31.0),
        vehicle("receding", 60.0, 20.0, math.atan2(20.0, 60.0), speed_mps=25.0),
        vehicle("crossing", 50.0, -30.0, 0.0, speed_mps=20.0),
    ]
    echoes = radar.echoes(cars)
    assert echoes.radial_speed_mps[0] == pytest.approx(-31.0, abs=1e-12)
    assert echoes.radial_speed_mps[1] == pytest.approx(25.0, abs=1e-12)
    # Crossing the sensor's axis at right angles: no Doppler (reflection from the side face).
    crossing = radar.echoes([vehicle("crossing", 50.0, 0.0, math.pi / 2, speed_mps=20.0)])
    np.testing.assert_allclose(crossing.reflection_xyz_m[0], [49.1, 0.0, CAR_Z_M], atol=1e-12)
    assert crossing.radial_speed_mps[0] == pytest.approx(0.0, abs=1e-9)
    # Through a whole scan with the noise set to zero, the targets carry the same speeds.
    result = radar.scan(cars, stamp=1.0, scan_index=0)
    by_id = {
        ids[0]: t for ids, t in zip(result.target_vehicle_ids, result.scan.targets, strict=True)
    }
    assert by_id["approaching"].radial_speed_mps == pytest.approx(-31.0, abs=1e-12)
    assert by_id["receding"].radial_speed_mps == pytest.approx(25.0, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(5.0, 150.0),
    y=st.floats(-60.0, 60.0),
    heading=st.floats(-math.pi, math.pi),
    speed=st.floats(0.0, 45.0),
    mast_z=st.floats(0.5, 8.0),
    yaw_deg=st.floats(-180.0, 180.0),
)
def test_radial_speed_is_v_cos_angle(
    x: float, y: float, heading: float, speed: float, mast_z: float, yaw_deg: float
) -> None:
    sensor = mount(x_m=3.0, y_m=-4.0, z_m=mast_z, yaw_deg=yaw_deg)
    truth = vehicle("v", x, y, heading, speed_mps=speed)
    echoes = model(sensor).echoes([truth])
    expected = v_cos_angle(truth, echoes.reflection_xyz_m[0], np.array([3.0, -4.0, mast_z]))
    assert echoes.radial_speed_mps[0] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert abs(echoes.radial_speed_mps[0]) <= speed + 1e-12


# --- range and azimuth ----------------------------------------------------------------------


@pytest.mark.parametrize("bearing_offset_deg", [10.0, -20.0, 0.0])
def test_range_azimuth_closed_form_for_approaching_car(bearing_offset_deg: float) -> None:
    sensor_xyz = np.array([10.0, 20.0, 5.0])
    yaw_deg = 30.0
    distance_m = 60.0  # horizontal, sensor to the car's centre
    bearing = math.radians(yaw_deg + bearing_offset_deg)
    car = vehicle(
        "car",
        sensor_xyz[0] + distance_m * math.cos(bearing),
        sensor_xyz[1] + distance_m * math.sin(bearing),
        bearing + math.pi,  # driving straight at the sensor
    )
    radar = model(mount(10.0, 20.0, 5.0, yaw_deg=yaw_deg))
    echoes = radar.echoes([car])
    # The front face's centre is half a length nearer than the car's centre.
    horizontal = distance_m - car.length_m / 2
    expected_range = math.hypot(horizontal, sensor_xyz[2] - car.z_m)
    assert echoes.range_m[0] == pytest.approx(expected_range, abs=1e-9)
    assert echoes.azimuth_rad[0] == pytest.approx(math.radians(bearing_offset_deg), abs=1e-12)
    assert echoes.elevation_rad[0] == pytest.approx(
        math.atan2(car.z_m - sensor_xyz[2], horizontal), abs=1e-12
    )
    assert echoes.radial_speed_mps[0] == pytest.approx(
        -car.speed_mps * horizontal / expected_range, abs=1e-12
    )
    target = radar.scan([car], 0.0, 0).scan.targets[0]
    assert target.range_m == pytest.approx(expected_range, abs=1e-9)
    assert target.azimuth_rad == pytest.approx(math.radians(bearing_offset_deg), abs=1e-12)


def test_broadside_truck_reflects_once_from_the_middle_of_its_side() -> None:
    radar = model(mount(z_m=2.0))
    truck = vehicle("truck", 80.0, 0.0, math.pi / 2, vehicle_class=VehicleClass.TRUCK)
    echoes = radar.echoes([truck])
    np.testing.assert_allclose(echoes.reflection_xyz_m[0], [80.0 - 1.25, 0.0, 2.0], atol=1e-12)
    assert echoes.range_m[0] == pytest.approx(78.75, abs=1e-12)
    assert echoes.azimuth_rad[0] == pytest.approx(0.0, abs=1e-12)
    result = radar.scan([truck], 0.0, 0)
    assert result.target_vehicle_ids == [("truck",)]


def test_sensor_rotation_axes() -> None:
    rotation = Pose(x_m=0, y_m=0, z_m=0, yaw_deg=90.0, pitch_deg=10.0).rotation()
    # Yaw 90 deg: forward is north, tilted up by the positive pitch; left is west.
    np.testing.assert_allclose(
        rotation[:, 0], [0.0, math.cos(math.radians(10)), math.sin(math.radians(10))], atol=1e-12
    )
    np.testing.assert_allclose(rotation[:, 1], [-1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)


# --- resolution cells -----------------------------------------------------------------------


def test_two_cars_in_one_resolution_cell_come_back_as_one_target() -> None:
    radar = model()
    # Side by side at 80 m, 3.66 m apart: 2.6 deg < 4 deg azimuth resolution, same range.
    pair = [vehicle("left", 80.0, 1.83, math.pi), vehicle("right", 80.0, -1.83, math.pi)]
    echoes = radar.echoes(pair)
    assert abs(echoes.azimuth_rad[0] - echoes.azimuth_rad[1]) < math.radians(4.0)
    rcs_sum_m2 = []
    for scan_index in range(300):
        result = radar.scan(pair, 0.0, scan_index)
        assert len(result.scan.targets) <= 1
        if result.scan.targets:
            assert sorted(result.target_vehicle_ids[0]) == ["left", "right"]
            # Reported at the stronger echo's azimuth (here: one of the two, equal strengths).
            azimuth = result.scan.targets[0].azimuth_rad
            assert np.min(np.abs(echoes.azimuth_rad - azimuth)) < 1e-12
            rcs_sum_m2.append(10 ** (result.scan.targets[0].rcs_dbsm / 10))
    assert len(rcs_sum_m2) >= 295
    # Power sum of two head-on cars of 10 dBsm (10 m^2 each), averaged over the fluctuation.
    assert np.mean(rcs_sum_m2) == pytest.approx(20.0, rel=0.15)


@pytest.mark.parametrize(
    ("first", "second"),
    [
        # Two azimuth cells apart: +-4 deg at 30 m, same range.
        ((30.0, 30.0 * math.tan(math.radians(4.0))), (30.0, -30.0 * math.tan(math.radians(4.0)))),
        # Two range cells apart (3 m), 2.6 deg apart in azimuth (within one azimuth cell).
        ((80.0, 1.83), (83.0, -1.83)),
    ],
)
def test_two_cars_two_cells_apart_come_back_as_two_targets(
    first: tuple[float, float], second: tuple[float, float]
) -> None:
    radar = model()
    pair = [vehicle("a", *first, math.pi), vehicle("b", *second, math.pi)]
    assert not radar.echoes(pair).occluded.any()
    counts = [len(radar.scan(pair, 0.0, k).scan.targets) for k in range(20)]
    assert max(counts) == 2
    for k in range(20):
        result = radar.scan(pair, 0.0, k)
        assert all(len(ids) == 1 for ids in result.target_vehicle_ids)


# --- visibility -----------------------------------------------------------------------------


def test_out_of_fov_and_beyond_max_range_give_no_target() -> None:
    radar = model()  # 60 deg field of view, 200 m
    outside_fov = vehicle(
        "side", 50.0 * math.cos(math.radians(35)), 50.0 * math.sin(math.radians(35)), 0.0
    )
    too_far = vehicle("far", 215.0, 0.0, math.pi, vehicle_class=VehicleClass.TRUCK)  # front: 207 m
    behind = vehicle("behind", -40.0, 0.0, 0.0)
    inside = vehicle(
        "edge", 100.0 * math.cos(math.radians(29)), 100.0 * math.sin(math.radians(29)), math.pi
    )
    near_limit = vehicle("limit", 197.0, 0.0, math.pi, vehicle_class=VehicleClass.TRUCK)
    echoes = radar.echoes([outside_fov, too_far, behind, inside, near_limit])
    assert echoes.in_fov.tolist() == [False, True, False, True, True]
    assert echoes.in_range.tolist() == [True, False, True, True, True]
    assert echoes.visible.tolist() == [False, False, False, True, True]
    for k in range(30):
        result = radar.scan([outside_fov, too_far, behind], 0.0, k)
        assert result.scan.targets == []


def test_car_directly_behind_truck_is_missed() -> None:
    radar = model(mount(z_m=5.0))  # a mast radar looking along the approach
    truck = vehicle("truck", 60.0, 0.0, math.pi, vehicle_class=VehicleClass.TRUCK)
    car = vehicle("car", 80.0, 0.0, math.pi)
    echoes = radar.echoes([truck, car])
    assert echoes.occluded.tolist() == [False, True]
    for k in range(30):
        ids = radar.scan([truck, car], 0.0, k).target_vehicle_ids
        assert all("car" not in target_ids for target_ids in ids)
    # Alone, the same car is seen.
    assert radar.echoes([car]).visible.tolist() == [True]


@pytest.mark.parametrize(("gap_m", "occluded"), [(7.0, True), (40.0, False)])
def test_mast_sees_over_a_car_only_with_a_long_enough_gap(gap_m: float, occluded: bool) -> None:
    radar = model(mount(z_m=5.0))
    lead = vehicle("lead", 50.0, 0.0, math.pi)
    follower = vehicle("follower", 50.0 + gap_m, 0.0, math.pi)
    assert radar.echoes([lead, follower]).occluded.tolist() == [False, occluded]


# --- detection, rain ------------------------------------------------------------------------


def test_detection_probability_normalised_on_a_car_at_100_m() -> None:
    radar = model()
    assert radar.detection_probability(10.0, 100.0) == pytest.approx(0.95, abs=1e-12)
    pd = radar.detection_probability([10.0, 10.0, 23.0, 3.0], [50.0, 195.0, 195.0, 100.0])
    assert pd[0] > 0.99 and pd[1] < 0.6 and pd[2] > 0.9 and pd[3] < 0.9
    rainy = model(weather=Weather(rain_mm_per_h=8.0))
    rain_pd = float(rainy.detection_probability(10.0, 150.0)[()])
    dry_pd = float(radar.detection_probability(10.0, 150.0)[()])
    assert dry_pd - 0.1 < rain_pd < dry_pd
    # Empirically: a head-on car at 100 m (front face at 100 m) over many scans.
    car = vehicle("car", 100.0 + 2.25, 0.0, math.pi)
    hits = sum(bool(radar.scan([car], 0.0, k).scan.targets) for k in range(1000))
    assert hits / 1000 == pytest.approx(0.95, abs=0.025)


# --- reproducibility, false alarms, message -------------------------------------------------


def _traffic() -> list[VehicleTruth]:
    return [
        vehicle(f"v{i}", 20.0 + 9.0 * i, (-1.83, 1.83)[i % 2], math.pi, speed_mps=25.0 + i)
        for i in range(20)
    ]


def test_seeded_scans_are_reproducible_and_independent_of_history() -> None:
    traffic = _traffic()
    first = model(mount(noise=True), seed=11, false_alarm_rate_per_scan=1.0)
    second = model(mount(noise=True), seed=11, false_alarm_rate_per_scan=1.0)
    for k in range(5):
        first.scan(traffic, 0.1 * k, k)
    assert first.scan(traffic, 0.5, 5) == second.scan(traffic, 0.5, 5)
    other_seed = model(mount(noise=True), seed=12, false_alarm_rate_per_scan=1.0)
    assert other_seed.scan(traffic, 0.5, 5).scan != second.scan(traffic, 0.5, 5).scan


def test_false_alarm_count_averages_to_the_configured_rate() -> None:
    rate = 2.0
    radar = model(seed=3, false_alarm_rate_per_scan=rate)
    intrinsics = radar.intrinsics
    counts = []
    for k in range(2000):
        result = radar.scan([], 0.0, k)
        assert all(ids == () for ids in result.target_vehicle_ids)
        for target in result.scan.targets:
            assert 0.0 <= target.range_m <= intrinsics.max_range_m
            assert abs(target.azimuth_rad) <= math.radians(intrinsics.horizontal_fov_deg) / 2
            assert abs(target.radial_speed_mps) < 5 * radar.clutter_speed_std_mps
            assert target.rcs_dbsm <= 0.0
        counts.append(len(result.scan.targets))
    # Poisson: the mean of 2000 counts has a standard deviation of sqrt(2 / 2000) = 0.032.
    assert np.mean(counts) == pytest.approx(rate, abs=0.1)
    assert np.var(counts) == pytest.approx(rate, rel=0.15)


def test_scan_validates_and_survives_the_codec() -> None:
    radar = model(
        mount(x_m=7.5, y_m=980.2, z_m=5.0, yaw_deg=-93.0, noise=True), false_alarm_rate_per_scan=3.0
    )
    heading_north = math.pi / 2  # towards the mast, which looks south
    traffic = [
        vehicle(f"v{i}", 7.5 + (-1.83, 1.83)[i % 2], 960.0 - 8.0 * i, heading_north)
        for i in range(12)
    ]
    result = radar.scan(traffic, stamp=12.5, scan_index=3)
    scan = result.scan
    assert scan.site == "test-site" and scan.source_id == "radar-test" and scan.scan_index == 3
    assert len(result.target_vehicle_ids) == len(scan.targets) > 0
    ranges = [t.range_m for t in scan.targets]
    assert ranges == sorted(ranges)
    assert decode_json(encode_json(scan), RadarScan) == scan
    # Approaching traffic: every vehicle target closes in.
    for ids, target in zip(result.target_vehicle_ids, scan.targets, strict=True):
        if ids:
            assert target.radial_speed_mps < 0


def test_rejects_a_non_radar_mount() -> None:
    camera = SensorMount(
        sensor_id="cam", pose=Pose(x_m=0, y_m=0, z_m=5), intrinsics=CameraIntrinsics(), rate_hz=10
    )
    with pytest.raises(ValueError, match="not a radar"):
        RadarModel(camera, Weather(), 0, site_id="test-site")


def test_core_imports_no_io_library() -> None:
    imported = top_level_imports(radar_module)
    assert imported.isdisjoint({"zenoh", "fastapi", "socket", "open3d", "cv2", "libsumo"})
