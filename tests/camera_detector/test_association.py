"""Camera-radar association and fusion: conversion of radar targets against the simulator's
echoes and a hand-computed covariance, the gate and global nearest neighbour, fused accuracy
over 200 seeded trials (radar range, camera bearing), camera-only, radar-only and clutter."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_camera_detector import association
from wz_camera_detector.association import (
    AssociationSettings,
    CameraObject,
    FusedObject,
    associate,
    fuse_camera_radar,
    gate_distances,
    radar_targets_to_site,
    to_detection,
)
from wz_shared.messages import Detection, RadarScan, RadarTarget, VehicleClass, VehicleTruth
from wz_shared.site import CameraIntrinsics, Pose, RadarIntrinsics, SensorMount
from wz_simulator.sensors.radar import RadarModel
from wz_simulator.sensors.scene import WEATHER_PRESETS

SETTINGS = AssociationSettings()
TARGET_HEIGHT_M = SETTINGS.target_height_m
ROAD_HEADING_RAD = math.pi / 2.0  # traffic drives north, towards the mast
VEHICLE_SPEED_MPS = 25.0
# The default site's radar: on the mast, 5 m up, looking south.
RADAR_INTRINSICS = RadarIntrinsics()
RADAR = SensorMount(
    sensor_id="radar-mast",
    pose=Pose(x_m=7.5, y_m=980.2, z_m=5.0, yaw_deg=-93.0),
    intrinsics=RADAR_INTRINSICS,
    rate_hz=15.0,
)
RANGE_STD_M = RADAR_INTRINSICS.range_noise_std_m
AZIMUTH_STD_RAD = math.radians(RADAR_INTRINSICS.azimuth_noise_std_deg)
# The camera on the same mast ranges poorly along its line of sight, well across it.
CAMERA_RANGE_STD_M = 3.0
CAMERA_LATERAL_STD_M = 0.15
# Two approaching vehicles: 60 m and 75 m out, one in each lane.
TRUTH_XY_M = ((5.5, 920.0), (9.5, 905.0))


def bearing_from_radar(x_m: float, y_m: float) -> float:
    return math.atan2(y_m - RADAR.pose.y_m, x_m - RADAR.pose.x_m)


def horizontal_range(x_m: float, y_m: float) -> float:
    return math.hypot(x_m - RADAR.pose.x_m, y_m - RADAR.pose.y_m)


def wrap(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def polar_covariance(bearing_rad: float, along_std_m: float, across_std_m: float) -> np.ndarray:
    u = np.array([math.cos(bearing_rad), math.sin(bearing_rad)])
    n = np.array([-math.sin(bearing_rad), math.cos(bearing_rad)])
    return along_std_m**2 * np.outer(u, u) + across_std_m**2 * np.outer(n, n)


def radar_target(
    x_m: float,
    y_m: float,
    rng: np.random.Generator | None = None,
    radial_speed_mps: float | None = None,
    rcs_dbsm: float = 10.0,
) -> RadarTarget:
    """What the radar measures of a ground point at the reflection height, optionally noisy."""
    rho = horizontal_range(x_m, y_m)
    slant = math.hypot(rho, RADAR.pose.z_m - TARGET_HEIGHT_M)
    azimuth = wrap(bearing_from_radar(x_m, y_m) - math.radians(RADAR.pose.yaw_deg))
    if radial_speed_mps is None:
        # A vehicle heading north: v_r = v (cos h, sin h) . line of sight, horizontal part only.
        radial_speed_mps = VEHICLE_SPEED_MPS * math.sin(bearing_from_radar(x_m, y_m)) * rho / slant
    if rng is not None:
        slant += rng.normal(0.0, RANGE_STD_M)
        azimuth += rng.normal(0.0, AZIMUTH_STD_RAD)
    return RadarTarget(
        range_m=slant, azimuth_rad=azimuth, radial_speed_mps=radial_speed_mps, rcs_dbsm=rcs_dbsm
    )


def camera_object(
    local_id: int, x_m: float, y_m: float, rng: np.random.Generator | None = None
) -> CameraObject:
    """A camera ground point, noisy mostly along the line of sight from the (shared) mast."""
    bearing = bearing_from_radar(x_m, y_m)
    covariance = polar_covariance(bearing, CAMERA_RANGE_STD_M, CAMERA_LATERAL_STD_M)
    if rng is not None:
        x_m, y_m = rng.multivariate_normal([x_m, y_m], covariance)
    return CameraObject(
        local_id=local_id,
        x_m=float(x_m),
        y_m=float(y_m),
        covariance_m2=covariance,
        object_class=VehicleClass.CAR,
        score=0.9,
    )


def scan_of(*targets: RadarTarget) -> RadarScan:
    return RadarScan(
        site="us75", source_id="radar-mast", stamp=1.0, scan_index=0, targets=list(targets)
    )


def assert_spd(covariance: np.ndarray) -> None:
    assert covariance.shape == (2, 2)
    np.testing.assert_allclose(covariance, covariance.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(covariance) > 0.0)


def by_source(fused: list[FusedObject], source: str) -> list[FusedObject]:
    return [obj for obj in fused if obj.source == source]


def test_core_imports_no_io_library() -> None:
    assert top_level_imports(association).isdisjoint({"zenoh", "fastapi", "uvicorn", "requests"})


# ----------------------------------------------------------------------------- conversion


def simulated_echo(
    x_m: float, y_m: float, speed_mps: float, heading_rad: float, mount: SensorMount = RADAR
) -> tuple[RadarTarget, np.ndarray]:
    """The simulator's noise-free target of a car at ``(x_m, y_m)``, and its reflection point."""
    truth = VehicleTruth(
        vehicle_id="car-1",
        vehicle_class=VehicleClass.CAR,
        x_m=x_m,
        y_m=y_m,
        z_m=0.75,
        heading_rad=heading_rad,
        speed_mps=speed_mps,
        accel_mps2=0.0,
        length_m=4.5,
        width_m=1.8,
        height_m=1.5,
        lane_index=1,
        station_m=0.0,
        offset_m=0.0,
        driver_profile="normal",
    )
    echoes = RadarModel(mount, WEATHER_PRESETS["day"], seed=0, site_id="us75").echoes([truth])
    target = RadarTarget(
        range_m=float(echoes.range_m[0]),
        azimuth_rad=float(echoes.azimuth_rad[0]),
        radial_speed_mps=float(echoes.radial_speed_mps[0]),
        rcs_dbsm=10.0,
    )
    return target, echoes.reflection_xyz_m[0]


def test_conversion_inverts_the_simulated_echo() -> None:
    """The simulator's noise-free echo converts back onto its reflection point."""
    target, reflection = simulated_echo(6.0, 910.0, 20.0, math.pi / 2.0)
    settings = AssociationSettings(target_height_m=float(reflection[2]))
    (point,) = radar_targets_to_site([target], RADAR, settings)
    np.testing.assert_allclose([point.x_m, point.y_m], reflection[:2], atol=1e-9)


@pytest.mark.parametrize("distance_m", [12.0, 20.0, 40.0, 120.0])
def test_speed_from_the_simulated_echo_near_and_far_from_a_high_mast(distance_m: float) -> None:
    """The along-road speed from the simulator's radial speed is the vehicle's, near the mast too.

    The radial speed lies along the slant line of sight; a level car 12 m out from a radar 5 m up
    has ``cos e`` = 0.94 (0.90 for the echo at 0.75 m). Leaving it out read 23.2 m/s for 25.
    The line is the radar's own bearing of the echo: near the mast a camera box seen from above
    is off across, and a camera object 1 m aside of it does not move the speed."""
    target, reflection = simulated_echo(
        5.5, RADAR.pose.y_m - distance_m, VEHICLE_SPEED_MPS, ROAD_HEADING_RAD
    )
    settings = AssociationSettings(
        target_height_m=float(reflection[2]), min_radar_only_speed_mps=0.0
    )
    (obj,) = fuse_camera_radar(
        [camera_object(0, float(reflection[0]) + 1.0, float(reflection[1]))],
        scan_of(target),
        RADAR,
        settings,
        ROAD_HEADING_RAD,
    )
    assert obj.source == "camera+radar"
    assert obj.speed_mps == pytest.approx(VEHICLE_SPEED_MPS, rel=2e-3)
    (radar_only,) = fuse_camera_radar([], scan_of(target), RADAR, settings, ROAD_HEADING_RAD)
    assert radar_only.speed_mps == pytest.approx(VEHICLE_SPEED_MPS, rel=2e-3)


def test_radar_covariance_matches_hand_computation() -> None:
    """Level radar looking east, target dead ahead: R = diag((sr r/rho)^2, (rho sa)^2)."""
    mount = SensorMount(
        sensor_id="radar-east",
        pose=Pose(x_m=0.0, y_m=0.0, z_m=4.0),
        intrinsics=RadarIntrinsics(range_noise_std_m=0.5, azimuth_noise_std_deg=1.0),
        rate_hz=10.0,
    )
    settings = AssociationSettings(target_height_m=0.0)
    target = RadarTarget(range_m=5.0, azimuth_rad=0.0, radial_speed_mps=0.0, rcs_dbsm=0.0)
    (point,) = radar_targets_to_site([target], mount, settings)
    assert (point.x_m, point.y_m) == pytest.approx((3.0, 0.0))  # 3-4-5 triangle
    expected = np.diag([(0.5 * 5.0 / 3.0) ** 2, (3.0 * math.radians(1.0)) ** 2])
    np.testing.assert_allclose(point.covariance_m2, expected, atol=1e-12)


def test_a_camera_mount_is_refused() -> None:
    camera = SensorMount(
        sensor_id="camera-mast", pose=RADAR.pose, intrinsics=CameraIntrinsics(), rate_hz=10.0
    )
    with pytest.raises(ValueError, match="not a radar"):
        radar_targets_to_site([radar_target(*TRUTH_XY_M[0])], camera)


# ----------------------------------------------------------------------------- association


def test_global_nearest_neighbour_beats_greedy() -> None:
    # Greedy would take (0, 0) first and pay 1 + 10; the global optimum pays 2 + 2.
    distances = np.array([[1.0, 2.0], [2.0, 10.0]])
    assert associate(distances, gate_chi2=13.82) == [(0, 1), (1, 0)]


@pytest.mark.parametrize(("rival_d2", "paired"), [(7.1, True), (6.9, False)])
def test_a_pair_with_an_unpaired_rival_within_the_margin_is_dropped(
    rival_d2: float, paired: bool
) -> None:
    # One box, two echoes (two cars side by side, one hidden from the camera): the box fits
    # echo 0 at d^2 = 1; echo 1, left unpaired, at ``rival_d2``; margin 6.
    distances = np.array([[1.0, rival_d2]])
    assert associate(distances, 13.82, ambiguity_margin_chi2=6.0) == ([(0, 0)] if paired else [])
    assert associate(distances, 13.82) == [(0, 0)]  # no check: the nearest, as before
    # The same from the echo's side: two boxes, one echo.
    assert associate(distances.T, 13.82, ambiguity_margin_chi2=6.0) == ([(0, 0)] if paired else [])
    # A rival the assignment paired elsewhere is no rival (two cars one after the other).
    both = np.array([[1.0, 2.0], [2.0, 1.0]])
    assert associate(both, 13.82, ambiguity_margin_chi2=6.0) == [(0, 0), (1, 1)]


def test_gate_forbids_pairs_beyond_it() -> None:
    distances = np.array([[1.0, 20.0], [20.0, 30.0]])
    assert associate(distances, gate_chi2=13.82) == [(0, 0)]
    assert associate(np.zeros((0, 3)), gate_chi2=13.82) == []


def test_pair_beyond_the_gate_stays_apart() -> None:
    """Same range, 6 degrees off in azimuth (about 6 m across at 60 m): never paired."""
    x_m, y_m = TRUTH_XY_M[0]
    camera = camera_object(0, x_m, y_m)
    target = radar_target(x_m, y_m)
    off_gate = target.model_copy(update={"azimuth_rad": target.azimuth_rad + math.radians(6.0)})
    points = radar_targets_to_site([off_gate], RADAR, SETTINGS)
    distances = gate_distances([camera], points, SETTINGS.reflection_extent_std_m)
    assert distances[0, 0] > SETTINGS.gate_chi2
    fused = fuse_camera_radar([camera], scan_of(off_gate), RADAR, SETTINGS, ROAD_HEADING_RAD)
    assert sorted(obj.source for obj in fused) == ["camera", "radar"]


def test_two_vehicles_fused_more_accurately_than_either_sensor() -> None:
    """200 seeded trials: right pairs every time; fused range beats the camera's, fused
    bearing beats the radar's (median error ratios)."""
    rng = np.random.default_rng(20240611)
    camera_range_errors, fused_range_errors = [], []
    radar_bearing_errors, fused_bearing_errors = [], []
    for _ in range(200):
        cameras = [camera_object(7 + k, x, y, rng) for k, (x, y) in enumerate(TRUTH_XY_M)]
        # The radar lists targets in increasing range; list them reversed to test the pairing.
        targets = [radar_target(x, y, rng) for x, y in reversed(TRUTH_XY_M)]
        fused = fuse_camera_radar(cameras, scan_of(*targets), RADAR, SETTINGS, ROAD_HEADING_RAD)
        assert [obj.source for obj in fused] == ["camera+radar", "camera+radar"]
        assert [(obj.camera_local_id, obj.radar_target_index) for obj in fused] == [(7, 1), (8, 0)]
        points = radar_targets_to_site(targets, RADAR, SETTINGS)
        for k, (x, y) in enumerate(TRUTH_XY_M):
            true_range, true_bearing = horizontal_range(x, y), bearing_from_radar(x, y)
            obj, camera, radar = fused[k], cameras[k], points[1 - k]
            assert_spd(obj.covariance_m2)
            assert obj.object_class == VehicleClass.CAR
            assert obj.speed_mps == pytest.approx(VEHICLE_SPEED_MPS, abs=0.5)
            camera_range_errors.append(abs(horizontal_range(camera.x_m, camera.y_m) - true_range))
            fused_range_errors.append(abs(horizontal_range(obj.x_m, obj.y_m) - true_range))
            radar_bearing_errors.append(abs(wrap(radar.bearing_rad - true_bearing)))
            fused_bearing_errors.append(
                abs(wrap(bearing_from_radar(obj.x_m, obj.y_m) - true_bearing))
            )
    range_ratio = np.median(fused_range_errors) / np.median(camera_range_errors)
    bearing_ratio = np.median(fused_bearing_errors) / np.median(radar_bearing_errors)
    # Expected about 0.25 / 3 ~= 0.08 and 0.15 / (65 m x 0.5 deg) ~= 0.26.
    assert range_ratio < 0.2
    assert bearing_ratio < 0.5


def test_fused_covariance_takes_radar_range_and_camera_bearing() -> None:
    x_m, y_m = TRUTH_XY_M[0]
    (obj,) = fuse_camera_radar(
        [camera_object(0, x_m, y_m)], scan_of(radar_target(x_m, y_m)), RADAR, SETTINGS
    )
    bearing, rho = bearing_from_radar(x_m, y_m), horizontal_range(x_m, y_m)
    slant = math.hypot(rho, RADAR.pose.z_m - TARGET_HEIGHT_M)
    range_std = math.hypot(RANGE_STD_M * slant / rho, SETTINGS.centre_std_m)
    expected = polar_covariance(bearing, range_std, CAMERA_LATERAL_STD_M)
    np.testing.assert_allclose(obj.covariance_m2, expected, rtol=1e-9, atol=1e-12)
    # Without a road heading, the speed is the radial speed's horizontal magnitude: |v_r| / cos e.
    expected_speed = VEHICLE_SPEED_MPS * abs(math.sin(bearing))
    assert obj.speed_mps == pytest.approx(expected_speed, rel=1e-3)


# ----------------------------------------------------------------------------- leftovers


def test_moving_radar_target_far_from_cameras_becomes_radar_only() -> None:
    camera = camera_object(3, *TRUTH_XY_M[0])
    far = radar_target(8.0, 850.0, radial_speed_mps=-20.0)
    fused = fuse_camera_radar([camera], scan_of(far), RADAR, SETTINGS, ROAD_HEADING_RAD)
    (radar_only,) = by_source(fused, "radar")
    assert radar_only.object_class == VehicleClass.UNKNOWN
    assert radar_only.camera_local_id is None
    assert radar_only.radar_target_index == 0
    assert radar_only.score == SETTINGS.radar_only_score
    # The echo (8, 850) is the centre of the face nearest the radar (north, up the road): the
    # front of a car-sized vehicle heading north, whose centre is half a length behind it.
    assert (radar_only.x_m, radar_only.y_m) == pytest.approx((8.0, 850.0 - 2.3), abs=1e-6)
    bearing = bearing_from_radar(8.0, 850.0)
    assert radar_only.speed_mps is not None and radar_only.speed_mps > 19.0
    assert_spd(radar_only.covariance_m2)
    along = np.array([math.cos(bearing), math.sin(bearing)])
    assert along @ radar_only.covariance_m2 @ along > SETTINGS.radar_only_size_std_m**2


def test_a_second_echo_of_a_truck_is_not_a_vehicle_of_its_own() -> None:
    # A 16.5 m truck, 40 m out, heading north (towards the mast): the radar sees its side
    # from the cab to the trailer's end. One echo pairs with the camera's box; the others lie
    # on the truck's footprint and are dropped, not turned into cars ahead of its centre.
    x_m, y_m = 5.5, 940.0
    truck = dataclasses.replace(
        camera_object(1, x_m, y_m),
        object_class=VehicleClass.TRUCK,
        heading_rad=ROAD_HEADING_RAD,
        length_m=16.5,
        width_m=2.6,
    )
    face = radar_target(x_m, y_m + 8.0, radial_speed_mps=-20.0)  # the front, paired
    middle = radar_target(x_m + 1.2, y_m - 1.0, radial_speed_mps=-20.0)  # on the body
    trailer = radar_target(x_m + 1.2, y_m - 6.0, radial_speed_mps=-20.0)  # on the body
    behind = radar_target(x_m, y_m - 20.0, radial_speed_mps=-20.0)  # a car behind it
    fused = fuse_camera_radar(
        [truck], scan_of(face, middle, trailer, behind), RADAR, SETTINGS, ROAD_HEADING_RAD
    )
    (paired,) = by_source(fused, "camera+radar")
    assert paired.object_class == VehicleClass.TRUCK and paired.radar_target_index == 0
    (radar_only,) = by_source(fused, "radar")
    assert radar_only.radar_target_index == 3
    # Without a footprint (no heading or size known), every leftover echo stays.
    bare = camera_object(1, x_m, y_m)
    fused = fuse_camera_radar(
        [bare], scan_of(face, middle, trailer, behind), RADAR, SETTINGS, ROAD_HEADING_RAD
    )
    assert {1, 2} <= {f.radar_target_index for f in by_source(fused, "radar")}


def test_a_radar_only_objects_unknown_length_lies_along_the_road() -> None:
    # Seen across the road (the echo beside the mast), the size guess widens the variance
    # along the road, where the vehicle's length lies, not along the line of sight.
    beside = radar_target(RADAR.pose.x_m - 12.0, RADAR.pose.y_m - 10.0, radial_speed_mps=-15.0)
    (radar_only,) = fuse_camera_radar([], scan_of(beside), RADAR, SETTINGS, ROAD_HEADING_RAD)
    road = np.array([math.cos(ROAD_HEADING_RAD), math.sin(ROAD_HEADING_RAD)])
    assert road @ radar_only.covariance_m2 @ road >= SETTINGS.radar_only_size_std_m**2


@pytest.mark.parametrize(
    ("radial_speed_mps", "rcs_dbsm"), [(0.1, 10.0), (-0.5, 10.0), (-20.0, -10.0)]
)
def test_still_or_weak_radar_target_is_dropped(radial_speed_mps: float, rcs_dbsm: float) -> None:
    far = radar_target(8.0, 850.0, radial_speed_mps=radial_speed_mps, rcs_dbsm=rcs_dbsm)
    assert fuse_camera_radar([], scan_of(far), RADAR, SETTINGS, ROAD_HEADING_RAD) == []


def test_camera_object_without_radar_stays_camera_only() -> None:
    camera = camera_object(5, *TRUTH_XY_M[1])
    (obj,) = fuse_camera_radar([camera], scan_of(), RADAR, SETTINGS, ROAD_HEADING_RAD)
    assert obj.source == "camera"
    assert (obj.x_m, obj.y_m) == (camera.x_m, camera.y_m)
    np.testing.assert_array_equal(obj.covariance_m2, camera.covariance_m2)
    assert obj.speed_mps is None
    assert obj.radar_target_index is None
    assert obj.camera_local_id == 5


def test_speed_is_none_when_the_line_of_sight_crosses_the_road() -> None:
    # A vehicle beside the mast: the radar looks across the road, radial speed says nothing.
    x_m, y_m = RADAR.pose.x_m + 30.0, RADAR.pose.y_m
    settings = AssociationSettings(min_radar_only_speed_mps=0.0)
    target = radar_target(x_m, y_m, radial_speed_mps=-2.0)
    (obj,) = fuse_camera_radar([], scan_of(target), RADAR, settings, ROAD_HEADING_RAD)
    assert obj.speed_mps is None


# ----------------------------------------------------------------------------- message


def test_every_source_gives_a_valid_detection() -> None:
    rng = np.random.default_rng(7)
    cameras = [camera_object(0, *TRUTH_XY_M[0], rng), camera_object(1, 30.0, 800.0)]
    targets = [radar_target(*TRUTH_XY_M[0], rng), radar_target(8.0, 850.0, radial_speed_mps=-20.0)]
    fused = fuse_camera_radar(cameras, scan_of(*targets), RADAR, SETTINGS, ROAD_HEADING_RAD)
    assert sorted(obj.source for obj in fused) == ["camera", "camera+radar", "radar"]
    for obj in fused:
        detection = to_detection(obj)
        assert Detection.model_validate_json(detection.model_dump_json()) == detection
        assert detection.covariance_m2 == pytest.approx(obj.covariance_m2.reshape(4).tolist())
        assert detection.object_class == obj.object_class
        assert detection.local_track_id == obj.camera_local_id
        assert detection.speed_mps == obj.speed_mps


# ----------------------------------------------------------------------------- reflection setback


def test_the_echo_is_on_the_near_face_and_the_fused_point_at_the_centre() -> None:
    """A truck heading straight at the radar: the echo is L/2 nearer than its centre. With its
    size and heading the fused point is the centre; without, it is the face, 8 m short."""
    length_m, width_m = 16.5, 2.6
    x_m, y_m = TRUTH_XY_M[0]
    bearing = bearing_from_radar(x_m, y_m)
    heading = bearing + math.pi  # approaching head-on
    face_x = x_m - 0.5 * length_m * math.cos(bearing)
    face_y = y_m - 0.5 * length_m * math.sin(bearing)
    truck = CameraObject(
        local_id=1,
        x_m=x_m,
        y_m=y_m,
        covariance_m2=polar_covariance(bearing, CAMERA_RANGE_STD_M, CAMERA_LATERAL_STD_M),
        object_class=VehicleClass.TRUCK,
        score=0.9,
        heading_rad=heading,
        length_m=length_m,
        width_m=width_m,
    )
    radar_xy = (RADAR.pose.x_m, RADAR.pose.y_m)
    assert association.face_offset((x_m, y_m), radar_xy, heading, length_m, width_m) == (
        pytest.approx(face_x - x_m, abs=1e-9),
        pytest.approx(face_y - y_m, abs=1e-9),
    )
    scan = scan_of(radar_target(face_x, face_y))

    (fused,) = by_source(fuse_camera_radar([truck], scan, RADAR, SETTINGS), "camera+radar")
    assert (fused.x_m, fused.y_m) == (pytest.approx(x_m, abs=1e-6), pytest.approx(y_m, abs=1e-6))

    no_size = CameraObject(1, x_m, y_m, truck.covariance_m2, VehicleClass.TRUCK, 0.9)
    (short,) = fuse_camera_radar([no_size], scan, RADAR, SETTINGS)
    assert (short.x_m, short.y_m) == (
        pytest.approx(face_x, abs=1e-6),
        pytest.approx(face_y, abs=1e-6),
    )


def test_the_nearer_face_is_the_end_or_the_side() -> None:
    """A 4.6 x 1.8 m car heading east at the origin: seen from far to the north, its side; from
    far at 45 degrees, its end (its centre, 2.3 m along, is nearer than the side's at 0.9 m
    across); from 5 m north and 1 m ahead, alongside, its side again."""

    def offset(sensor_xy: tuple[float, float]) -> tuple[float, float]:
        return association.face_offset((0.0, 0.0), sensor_xy, 0.0, 4.6, 1.8)

    assert offset((0.0, 100.0)) == pytest.approx((0.0, 0.9))
    assert offset((100.0, 100.0)) == pytest.approx((2.3, 0.0))
    assert offset((-100.0, -90.0)) == pytest.approx((-2.3, 0.0))
    assert offset((1.0, 5.0)) == pytest.approx((0.0, 0.9))


def test_the_centre_from_an_echo_inverts_the_face_model() -> None:
    """From every side and distance, the centre found from a vehicle's nearest-face echo is the
    vehicle's centre (the inverse of :func:`face_offsets`), or, seen broadside where a side's
    centre and an end's a half-length on both fit, one of the two it names."""
    rng = np.random.default_rng(3)
    unambiguous = 0
    for _ in range(500):
        heading = float(rng.uniform(-math.pi, math.pi))
        length, width = float(rng.uniform(3.5, 17.0)), float(rng.uniform(1.6, 2.6))
        angle, distance = float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(2.0, 200.0))
        sensor = (distance * math.cos(angle), distance * math.sin(angle))
        centre = (float(rng.uniform(-5.0, 5.0)), float(rng.uniform(-5.0, 5.0)))
        dx, dy = association.face_offset(centre, sensor, heading, length, width)
        found, (gx, gy) = association.centre_from_echo(
            (centre[0] + dx, centre[1] + dy), sensor, heading, length, width
        )
        if math.hypot(sensor[0] - centre[0], sensor[1] - centre[1]) <= 0.5 * length + 1.0:
            continue  # beside or under the sensor: no face is "nearest" the same way
        if (gx, gy) == (0.0, 0.0):
            assert found == pytest.approx(centre, abs=1e-6)
            unambiguous += 1
        else:  # two centres fit: the truth is one of them, the midpoint -+ the half-gap
            assert centre in (
                pytest.approx((found[0] + gx, found[1] + gy), abs=1e-6),
                pytest.approx((found[0] - gx, found[1] - gy), abs=1e-6),
            )
    assert unambiguous > 400


# A traffic radar on its own pole beside the road, 8 m up and 9 m aside of the near lane
# (generated site 10602): near it, the line of sight crosses the road at a steep angle.
SIDE_RADAR = SensorMount(
    sensor_id="radar-pole",
    pose=Pose(x_m=-3.3, y_m=980.2, z_m=8.0, yaw_deg=-60.0),
    intrinsics=RADAR_INTRINSICS,
    rate_hz=15.0,
)


@pytest.mark.parametrize("mount", [RADAR, SIDE_RADAR], ids=["mast", "pole"])
@pytest.mark.parametrize("distance_m", [12.0, 20.0, 40.0, 120.0])
def test_position_from_the_simulated_echo_near_and_far(
    mount: SensorMount, distance_m: float
) -> None:
    """The simulator's echo of a car is the centre of its face nearest the radar; the centre
    found from it, alone or paired with a camera object at the car's centre, is the car's.

    Moving the echo along the line of sight by the face's half-length (as before 2026-11-30)
    put radar-only objects 0.9 m across the road and 0.4 m along it 15-20 m before a pole
    radar 9 m aside (generated site 10602): a car's front face is not on that line."""
    x_m, y_m = 5.5, mount.pose.y_m - distance_m
    target, reflection = simulated_echo(x_m, y_m, VEHICLE_SPEED_MPS, ROAD_HEADING_RAD, mount)
    settings = AssociationSettings(
        target_height_m=float(reflection[2]), min_radar_only_speed_mps=0.0
    )
    (radar_only,) = fuse_camera_radar([], scan_of(target), mount, settings, ROAD_HEADING_RAD)
    # the car is 4.5 m long, a radar-only object is taken for a 4.6 m one
    assert (radar_only.x_m, radar_only.y_m) == pytest.approx((x_m, y_m), abs=0.06)
    camera = CameraObject(
        0, x_m, y_m, np.diag([4.0, 0.04]), VehicleClass.CAR, 0.9, ROAD_HEADING_RAD, 4.5, 1.8
    )
    (fused,) = fuse_camera_radar([camera], scan_of(target), mount, settings, ROAD_HEADING_RAD)
    assert fused.source == "camera+radar"
    assert (fused.x_m, fused.y_m) == pytest.approx((x_m, y_m), abs=1e-6)


def test_radar_range_is_carried_to_the_frame_time_with_the_radial_speed() -> None:
    x_m, y_m = TRUTH_XY_M[0]
    target = radar_target(x_m, y_m, radial_speed_mps=-20.0)
    camera = camera_object(0, x_m, y_m)
    (now,) = fuse_camera_radar([camera], scan_of(target), RADAR, SETTINGS)
    (later,) = fuse_camera_radar([camera], scan_of(target), RADAR, SETTINGS, dt_s=0.05)
    rho = horizontal_range(x_m, y_m)
    slant = math.hypot(rho, RADAR.pose.z_m - TARGET_HEIGHT_M)
    moved_m = horizontal_range(now.x_m, now.y_m) - horizontal_range(later.x_m, later.y_m)
    # The slant range shrinks 1 m in 50 ms at 20 m/s; the echo moves level, so the horizontal
    # range shrinks by slant / rho of that (rho^2 = slant^2 - h^2).
    assert moved_m == pytest.approx(20.0 * 0.05 * slant / rho, rel=1e-6)
