"""The paper's pipeline (reference path): synthetic scenes with known answers, every step's
switch, degenerate input, and the real freeway frame.

Synthetic scenes: a sensor 5 m above a flat road (z = -5 m in the sensor frame) with noise, and
box-shaped vehicles sampled on the faces the sensor sees (top, and the sides turned towards it),
from a 0.3 m sill up, as a roadside LiDAR sees them.
"""

from __future__ import annotations

import ast
import importlib.util
import inspect
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from pydantic import ValidationError

from tests.purity import top_level_imports
from wz_lidar_detector import reference as reference_module
from wz_lidar_detector.detection import BoxDetection, DetectionResult, PointFrame
from wz_lidar_detector.reference import (
    STEP_NAMES,
    ReferencePipeline,
    ReferenceSettings,
    class_from_size,
)
from wz_shared.arrays import F64
from wz_shared.messages import VehicleClass

GROUND_Z_M = -5.0  # the road, 5 m below the sensor
SPACING_M = 0.12  # between sampled points on a vehicle face
REAL = Path(__file__).resolve().parents[2] / "samples" / "real-freeway-lidar"
# The real frame ships in samples/real-freeway-lidar (its README: source and use).


@dataclass(frozen=True)
class Vehicle:
    center_xy_m: tuple[float, float]
    size_lwh_m: tuple[float, float, float]
    heading_rad: float = 0.0
    sill_m: float = 0.3  # the lowest point seen, above the road


CAR = Vehicle((14.0, -4.0), (4.5, 1.8, 1.5), heading_rad=0.3)
TRUCK = Vehicle((32.0, 5.0), (16.5, 2.6, 4.0))


def face_grid(extent_a: float, extent_b: float) -> F64:
    """``(n, 2)`` grid of points on a ``extent_a`` x ``extent_b`` face, centred on 0."""
    a = np.arange(-0.5 * extent_a + 0.5 * SPACING_M, 0.5 * extent_a, SPACING_M)
    b = np.arange(-0.5 * extent_b + 0.5 * SPACING_M, 0.5 * extent_b, SPACING_M)
    grid: F64 = np.stack(np.meshgrid(a, b, indexing="ij"), axis=-1).reshape(-1, 2)
    return grid


def visible_points(vehicle: Vehicle, rng: np.random.Generator) -> F64:
    """Points ``(n, 3)`` on the faces of ``vehicle`` that turn towards the sensor at the origin."""
    length, width, height = vehicle.size_lwh_m
    side_height = height - vehicle.sill_m
    mid_z = vehicle.sill_m + 0.5 * side_height
    # (outward normal, points) in the vehicle's frame: x along the heading, z up from the road
    faces: list[tuple[tuple[float, float, float], F64]] = []
    top = face_grid(length, width)
    faces.append(((0.0, 0.0, 1.0), np.column_stack([top, np.full(len(top), height)])))
    for sign in (1.0, -1.0):
        side = face_grid(length, side_height)
        faces.append(
            (
                (0.0, sign, 0.0),
                np.column_stack(
                    [side[:, 0], np.full(len(side), sign * 0.5 * width), side[:, 1] + mid_z]
                ),
            )
        )
        end = face_grid(width, side_height)
        faces.append(
            (
                (sign, 0.0, 0.0),
                np.column_stack(
                    [np.full(len(end), sign * 0.5 * length), end[:, 0], end[:, 1] + mid_z]
                ),
            )
        )
    c, s = math.cos(vehicle.heading_rad), math.sin(vehicle.heading_rad)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    offset = np.array([*vehicle.center_xy_m, GROUND_Z_M])
    seen = []
    for normal, local in faces:
        world = local @ rotation.T + offset
        if float(np.asarray(normal) @ rotation.T @ (-world.mean(axis=0))) > 0.0:
            seen.append(world)
    points = np.concatenate(seen)
    noisy: F64 = points + rng.normal(0.0, 0.01, points.shape)
    return noisy


def ground_points(rng: np.random.Generator, spacing_m: float = 0.4) -> F64:
    """The road: x -5..60 m, y -15..15 m, z = -5 m with 2 cm noise, ``(n, 3)``."""
    x, y = np.meshgrid(np.arange(-5.0, 60.0, spacing_m), np.arange(-15.0, 15.0, spacing_m))
    z = GROUND_Z_M + rng.normal(0.0, 0.02, x.size)
    ground: F64 = np.column_stack([x.ravel(), y.ravel(), z])
    return ground


def scene(
    vehicles: tuple[Vehicle, ...] = (CAR, TRUCK), *, with_ground: bool = True, seed: int = 0
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int64]]:
    """Points ``(N, 4)`` (intensity 0.2 on the road, 0.5 on vehicles) and the owner of each
    point (0: road, k: the k-th vehicle)."""
    rng = np.random.default_rng(seed)
    parts = [ground_points(rng)] if with_ground else [np.zeros((0, 3))]
    owners = [np.zeros(len(parts[0]), dtype=np.int64)]
    for k, vehicle in enumerate(vehicles, start=1):
        parts.append(visible_points(vehicle, rng))
        owners.append(np.full(len(parts[-1]), k, dtype=np.int64))
    xyz = np.concatenate(parts)
    owner = np.concatenate(owners)
    intensity = np.where(owner == 0, 0.2, 0.5)
    return np.column_stack([xyz, intensity]).astype(np.float32), owner


def detect(points: npt.ArrayLike, **settings: object) -> DetectionResult:
    pipeline = ReferencePipeline(ReferenceSettings.model_validate(settings))
    return pipeline.detect(PointFrame.unorganized(points))


def by_x(result: DetectionResult) -> list[BoxDetection]:
    return sorted(result.detections, key=lambda detection: detection.center_xyz_m[0])


def heading_error(a: float, b: float) -> float:
    """Difference of two box headings [rad], modulo pi."""
    return abs((a - b + 0.5 * math.pi) % math.pi - 0.5 * math.pi)


@pytest.fixture(scope="module")
def car_and_truck() -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], DetectionResult]:
    points, owner = scene()
    return points, owner, detect(points)


# --- the two-vehicle scene ----------------------------------------------------------------------


def test_finds_the_car_and_the_truck_at_the_centroid_of_their_points(
    car_and_truck: tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], DetectionResult],
) -> None:
    points, owner, result = car_and_truck
    assert len(result.detections) == 2
    car, truck = by_x(result)
    for detection, label, vehicle in ((car, 1, CAR), (truck, 2, TRUCK)):
        seen = points[owner == label, :3].astype(np.float64)
        centroid = seen.mean(axis=0)
        # The position is the centroid of the points seen, not the box centre: the two differ
        # by far more than the voxel tolerance here, since only the near faces are seen.
        box_centre = np.array([*vehicle.center_xy_m, GROUND_Z_M + 0.5 * vehicle.size_lwh_m[2]])
        assert np.linalg.norm(centroid - box_centre) > 0.3
        np.testing.assert_allclose(detection.center_xyz_m, centroid, atol=0.5 * 0.2)
        length, width, height = vehicle.size_lwh_m
        np.testing.assert_allclose(
            detection.size_lwh_m, (length, width, height - vehicle.sill_m), atol=0.3
        )
        assert heading_error(detection.heading_rad, vehicle.heading_rad) < 0.03
        assert -0.5 * math.pi < detection.heading_rad <= 0.5 * math.pi
        assert detection.score == 1.0
    assert (car.object_class, truck.object_class) == (VehicleClass.CAR, VehicleClass.TRUCK)


def test_foreground_is_the_vehicles_points(
    car_and_truck: tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], DetectionResult],
) -> None:
    _, owner, result = car_and_truck
    assert result.foreground.shape == owner.shape
    assert result.foreground.dtype == np.bool_
    # Outlier removal trims the sparse voxels along a face's lower edge (about 2 %).
    assert result.foreground[owner > 0].mean() > 0.97
    assert result.foreground[owner == 0].mean() < 0.01
    # Each input return counts for exactly one detection.
    assert sum(d.num_points for d in result.detections) == result.foreground.sum()


def test_every_step_is_timed_in_order(
    car_and_truck: tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], DetectionResult],
) -> None:
    _, _, result = car_and_truck
    assert tuple(result.timings_s) == STEP_NAMES
    assert all(seconds >= 0.0 for seconds in result.timings_s.values())


def test_covariance_is_isotropic_and_grows_with_range(
    car_and_truck: tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], DetectionResult],
) -> None:
    _, _, result = car_and_truck
    settings = ReferenceSettings()
    variances = []
    for detection in by_x(result):
        x, y, _ = detection.center_xyz_m
        sigma = settings.position_std_m + settings.position_std_growth_m_per_m * math.hypot(x, y)
        (xx, xy), (yx, yy) = detection.covariance_xy_m2
        assert xx == pytest.approx(sigma**2) and yy == pytest.approx(sigma**2)
        assert xy == yx == 0.0
        variances.append(xx)
    assert variances[0] < variances[1]


# --- switches -----------------------------------------------------------------------------------


@pytest.mark.parametrize("step", [name for name in STEP_NAMES])
def test_a_switched_off_step_is_not_run(step: str) -> None:
    points, _ = scene()
    result = detect(points, **{f"enable_{step}": False})
    expected = [name for name in STEP_NAMES if name != step]
    if step == "ground":  # no plane, and no fallback height: the height filter cannot run
        expected.remove("height")
    assert list(result.timings_s) == expected
    if step == "boxes":
        assert result.detections == []
        assert result.foreground.sum() > 0
    if step in ("roi", "intensity", "voxel", "outliers", "merge", "height"):
        assert len(result.detections) == 2


def test_without_voxels_and_outlier_removal_foreground_and_centroids_are_exact() -> None:
    points, owner = scene()
    result = detect(points, enable_voxel=False, enable_outliers=False)
    np.testing.assert_array_equal(result.foreground, owner > 0)
    car, truck = by_x(result)
    for detection, label in ((car, 1), (truck, 2)):
        centroid = points[owner == label, :3].astype(np.float64).mean(axis=0)
        np.testing.assert_allclose(detection.center_xyz_m, centroid, atol=1e-6)
        assert detection.num_points == (owner == label).sum()
    # With voxels but no outlier removal, every return of a clustered voxel is foreground.
    np.testing.assert_array_equal(detect(points, enable_outliers=False).foreground, owner > 0)


def test_ground_step_alone_removes_the_road() -> None:
    """With the height filter off, RANSAC alone must keep the road out of the detections."""
    points, _ = scene()
    result = detect(points, enable_height=False)
    assert len(result.detections) == 2
    road_only, _ = scene(())
    assert detect(road_only, enable_height=False).detections == []
    assert not detect(road_only).foreground.any()


def test_height_filter_uses_the_fallback_ground_without_a_plane() -> None:
    points, _ = scene()
    result = detect(points, enable_ground=False, fallback_ground_z_m=GROUND_Z_M)
    assert "ground" not in result.timings_s and "height" in result.timings_s
    assert [d.object_class for d in by_x(result)] == [VehicleClass.CAR, VehicleClass.TRUCK]


def test_no_level_plane_no_ground_removed() -> None:
    """A wall alone (a vertical plane): RANSAC runs, finds no road, the height filter is
    skipped, and the wall is left for the clusterer."""
    y, z = np.meshgrid(np.arange(-5.0, 5.0, 0.1), np.arange(-4.0, -1.0, 0.1))
    wall = np.column_stack([np.full(y.size, 20.0), y.ravel(), z.ravel()])
    result = detect(wall)
    assert "ground" in result.timings_s and "height" not in result.timings_s
    assert len(result.detections) == 1
    assert result.detections[0].size_lwh_m[0] == pytest.approx(9.9, abs=0.25)


def test_missing_intensity_skips_the_intensity_filter() -> None:
    points, _ = scene()
    result = detect(points[:, :3], min_intensity=0.3)
    assert "intensity" not in result.timings_s
    assert len(result.detections) == 2


def test_intensity_filter_drops_weak_returns_and_keeps_those_without() -> None:
    points, owner = scene()
    points[owner == 2, 3] = 0.05  # a dark truck
    result = detect(points, min_intensity=0.1)
    assert [d.object_class for d in result.detections] == [VehicleClass.CAR]
    points[owner == 2, 3] = np.nan  # no intensity on the truck's returns: kept
    assert len(detect(points, min_intensity=0.1).detections) == 2


def test_roi_crops_by_box_and_by_range() -> None:
    points, _ = scene()
    assert [d.object_class for d in detect(points, roi_x_max_m=20.0).detections] == [
        VehicleClass.CAR
    ]
    assert [d.object_class for d in detect(points, roi_max_range_m=20.0).detections] == [
        VehicleClass.CAR
    ]


# --- merge --------------------------------------------------------------------------------------


def split_car() -> F64:
    """A 4.6 m car abeam the sensor (its top and near side seen) in two parts: a 1.1 m shadow
    (a pole in front of it) across its middle, wider than DBSCAN's reach, so DBSCAN makes two
    clusters whose centroids are 2.85 m apart."""
    car = Vehicle((2.0, -6.0), (4.6, 1.8, 1.5))
    points, owner = scene((car,))
    along = points[:, 0] - car.center_xy_m[0]
    shadow = (owner == 1) & (np.abs(along) < 0.55)
    kept: F64 = points[~shadow]
    return kept


def test_merge_joins_two_parts_of_one_vehicle() -> None:
    points = split_car()
    apart = detect(points, enable_merge=False)
    assert len(apart.detections) == 2
    merged = detect(points)
    assert len(merged.detections) == 1
    only = merged.detections[0]
    assert only.size_lwh_m[0] == pytest.approx(4.6, abs=0.3)
    assert only.object_class == VehicleClass.CAR
    assert only.num_points == sum(d.num_points for d in apart.detections)


def test_merge_keeps_vehicles_side_by_side_apart() -> None:
    """Two cars abreast in adjacent 3.6 m lanes stay two detections."""
    near = Vehicle((20.0, -4.0), (4.6, 1.8, 1.5))
    far = Vehicle((20.0, -7.6), (4.6, 1.8, 1.5))
    points, _ = scene((near, far))
    result = detect(points)
    assert len(result.detections) == 2
    lateral = sorted(d.center_xyz_m[1] for d in result.detections)
    assert lateral[1] - lateral[0] > 3.0


def test_centroid_linkage_does_not_chain_single_linkage_does() -> None:
    """Three small blobs 2.8 m apart in a row: centroid linkage joins two of them (the third is
    then 4.2 m from their centroid), single linkage chains all three."""
    rng = np.random.default_rng(5)
    centres = np.array([[20.0 + 2.8 * k, 0.0, -3.0] for k in range(3)])
    blobs = np.concatenate([rng.uniform(-0.25, 0.25, (60, 3)) + centre for centre in centres])
    common = {"enable_ground": False, "enable_voxel": False}
    assert len(detect(blobs, enable_merge=False, **common).detections) == 3
    assert len(detect(blobs, merge_linkage="centroid", **common).detections) == 2
    assert len(detect(blobs, merge_linkage="single", **common).detections) == 1


def test_cluster_size_limits() -> None:
    points, _ = scene()
    result = detect(points, max_cluster_points=1000)  # the truck has more voxels than that
    assert [d.object_class for d in result.detections] == [VehicleClass.CAR]
    car_returns = result.detections[0].num_points
    assert result.foreground.sum() == car_returns


# --- degenerate input ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "points",
    [
        np.zeros((0, 4)),
        np.full((50, 4), np.nan),
        np.array([[10.0, 0.0, -4.0, 1.0], [10.1, 0.0, -4.0, 1.0], [10.0, 0.1, -4.0, 1.0]]),
        np.array([[10.0, 0.0, -4.0], [10.1, 0.0, -4.0], [10.0, 0.1, -4.0]]),
        np.array([[np.nan, 0.0, 0.0, 1.0], [np.inf, 1.0, 1.0, 1.0]]),
    ],
    ids=["empty", "all-nan", "three-points", "three-points-no-intensity", "non-finite"],
)
def test_degenerate_frames_give_empty_results(points: F64) -> None:
    result = detect(points)
    assert result.detections == []
    assert result.foreground.shape == (len(points),)
    assert not result.foreground.any()


def test_nan_slots_of_an_organized_frame_are_dropped() -> None:
    points, _ = scene()
    holes = np.full((len(points), 4), np.nan, dtype=np.float32)
    organized = np.empty((2 * len(points), 4), dtype=np.float32)
    organized[0::2], organized[1::2] = points, holes
    frame = PointFrame(points=organized, rows=2, columns=len(points))
    result = ReferencePipeline(ReferenceSettings()).detect(frame)
    assert len(result.detections) == 2
    assert not result.foreground[1::2].any()
    np.testing.assert_array_equal(result.foreground[0::2], detect(points).foreground)


@pytest.mark.parametrize("shape", [(10,), (10, 2), (10, 5), (2, 3, 4)])
def test_bad_shapes_are_refused(shape: tuple[int, ...]) -> None:
    frame = PointFrame(points=np.zeros(shape, dtype=np.float32), rows=1, columns=10)
    with pytest.raises(ValueError, match=r"shape \(N, 4\)"):
        ReferencePipeline(ReferenceSettings()).detect(frame)


def test_settings_refuse_inverted_limits_and_unknown_fields() -> None:
    with pytest.raises(ValidationError, match="height"):
        ReferenceSettings(min_height_m=5.0, max_height_m=4.5)
    with pytest.raises(ValidationError, match="roi_x"):
        ReferenceSettings(roi_x_min_m=10.0, roi_x_max_m=0.0)
    with pytest.raises(ValidationError):
        ReferenceSettings.model_validate({"voxel_size": 0.1})
    with pytest.raises(ValidationError):
        ReferenceSettings(voxel_size_m=0.0)


def test_same_frame_same_result() -> None:
    points, _ = scene(seed=3)
    first, second = detect(points), detect(points)
    assert first.detections == second.detections
    np.testing.assert_array_equal(first.foreground, second.foreground)


# --- classes ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("size", "expected"),
    [
        ((4.6, 1.8, 1.5), VehicleClass.CAR),
        ((5.5, 2.0, 2.3), VehicleClass.CAR),  # a van
        ((1.8, 0.3, 1.2), VehicleClass.MOTORCYCLE),  # a far car's back looks the same: partial
        ((2.2, 0.8, 1.3), VehicleClass.MOTORCYCLE),
        ((16.5, 2.6, 4.0), VehicleClass.TRUCK),
        ((7.0, 2.4, 3.2), VehicleClass.TRUCK),
        ((2.5, 0.4, 3.5), VehicleClass.TRUCK),  # a tall vehicle seen end-on
        ((12.0, 2.5, 3.2), VehicleClass.BUS),
        ((12.0, 2.5, 4.0), VehicleClass.TRUCK),
        ((16.0, 0.4, 0.8), VehicleClass.UNKNOWN),  # a barrier: long and low
        ((40.0, 1.0, 1.5), VehicleClass.UNKNOWN),  # longer than any vehicle
        ((0.5, 0.3, 1.7), VehicleClass.UNKNOWN),  # a post or a person
        ((3.0, 1.5, 0.2), VehicleClass.UNKNOWN),  # flat: road left over
        ((math.nan, 1.0, 1.0), VehicleClass.UNKNOWN),
    ],
)
def test_class_from_size(size: tuple[float, float, float], expected: VehicleClass) -> None:
    assert class_from_size(*size) == expected


# --- the real frame -----------------------------------------------------------------------------

# Centroids [m] of the vehicles in that paper's own foreground (filtered.pcd) near the road:
# DBSCAN (1.5 m, 5 points) clusters of it with 18 points or more.
REAL_VEHICLES_XY_M = [
    (-4.7, 6.7),
    (-2.2, 4.2),
    (8.6, 11.0),
    (41.7, 11.2),
    (74.1, 6.9),
    (64.3, 3.2),
    (124.6, 2.1),
    (60.9, -4.7),
    (98.2, -8.5),
    (27.7, -3.9),
    (70.7, -8.5),
    (110.3, -11.8),
    (96.1, -12.7),
    (73.1, -13.0),
    (1.1, -10.8),
    (0.0, -7.2),
]


def read_ascii_pcd(path: Path) -> npt.NDArray[np.float32]:
    """x, y, z, intensity of an ASCII PCD with the usual 11 header lines (``nan`` kept)."""
    header = path.read_text(encoding="ascii").splitlines()[:11]
    assert (
        header[2].split() == ["FIELDS", "x", "y", "z", "intensity"] and header[-1] == "DATA ascii"
    )
    points: npt.NDArray[np.float32] = np.loadtxt(path, skiprows=11, dtype=np.float32)
    return points


def read_binary_xyz_pcd(path: Path) -> npt.NDArray[np.float32]:
    """x, y, z of a binary PCD of three float32 fields."""
    raw = path.read_bytes()
    start = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    points: npt.NDArray[np.float32] = np.frombuffer(raw[start:], dtype="<f4").reshape(-1, 3)
    return points


def test_real_freeway_frame_finds_each_vehicle_once() -> None:
    points = read_ascii_pcd(REAL / "rawdata.pcd")
    assert points.shape == (144_000, 4)
    frame = PointFrame(points=points, rows=80, columns=1800)
    result = ReferencePipeline(ReferenceSettings()).detect(frame)
    assert tuple(result.timings_s) == STEP_NAMES
    centres = np.array([d.center_xyz_m[:2] for d in result.detections])
    for x, y in REAL_VEHICLES_XY_M:
        near = np.hypot(centres[:, 0] - x, centres[:, 1] - y) < 1.5
        assert near.sum() == 1, f"vehicle near ({x}, {y}): {near.sum()} detections"
    # Nearly all of that paper's foreground on the road is foreground here too.
    reference = read_binary_xyz_pcd(REAL / "filtered.pcd")
    on_road = reference[(np.abs(reference[:, 1]) < 20.0) & (reference[:, 0] < 135.0)]
    ours = points[result.foreground, :3]
    ours_keys = {tuple(p) for p in ours.round(3).tolist()}
    agreed = sum(tuple(p) in ours_keys for p in on_road.round(3).tolist())
    assert agreed > 0.95 * len(on_road)


# --- purity -------------------------------------------------------------------------------------


def test_without_open3d_the_reference_path_says_what_to_install(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """open3d is the optional extra ``reference`` (the edge box's image leaves it out): the
    pipeline refuses to start without it, naming the extra and the fast path."""
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "open3d" else find_spec(name, *a),
    )
    with pytest.raises(
        ModuleNotFoundError, match=r"wz-lidar-detector\[reference\].*WZ_LIDAR_PATH=fast"
    ):
        ReferencePipeline(ReferenceSettings())


def test_the_core_does_no_io() -> None:
    """A pure core: numpy, scipy, open3d, pydantic and the project's models; no bus, no files."""
    imported = top_level_imports(reference_module)
    assert imported <= {
        "__future__",
        "importlib",  # only to say open3d is missing (an optional extra)
        "math",
        "time",
        "typing",
        "numpy",
        "scipy",
        "open3d",
        "pydantic",
        "wz_shared",
        "wz_lidar_detector",
    }
    tree = ast.parse(inspect.getsource(reference_module))
    calls = {
        node.func.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    }
    assert "open" not in calls and "print" not in calls
