"""The fast path: background models, L-shape box fitting, and the pipeline on synthetic scenes.

The scene: a sensor 5 m above flat ground, a 3 m wall 20 m to its left, open sky above; upright
boxes for vehicles (0.2-0.4 m above the ground, as bodies are). A small organized range image
(32 beams x 480 columns) is ray cast exactly, with seeded range noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from wz_lidar_detector.background import (
    BackgroundFileError,
    GroundGrid,
    RangeBackgroundSettings,
    RangeImageBackground,
    ShapeMismatchError,
    VoxelBackground,
    learn_background_from_frames,
    load_background,
)
from wz_lidar_detector.boxfit import BoxFitSettings, fit_box, hidden_front_m
from wz_lidar_detector.detection import PointFrame
from wz_lidar_detector.fast import FastPipeline, FastSettings, euclidean_clusters
from wz_lidar_detector.node import fitted_to_mount
from wz_lidar_detector.settings import LidarDetectorSettings
from wz_shared.messages import VehicleClass
from wz_shared.site_generator import generate_site

ROWS, COLUMNS = 32, 480
SENSOR_HEIGHT_M = 5.0
WALL_Y_M, WALL_TOP_Z_M = 20.0, -2.0
MAX_RANGE_M = 120.0
NOISE_M = 0.01


@dataclass(frozen=True)
class Box:
    x_m: float
    y_m: float
    heading_rad: float
    length_m: float
    width_m: float
    bottom_z_m: float
    top_z_m: float


CAR = Box(15.0, 8.0, 0.0, 4.5, 1.8, -4.8, -3.5)
TRUCK = Box(32.0, 12.0, 0.03, 16.5, 2.5, -4.6, -1.2)  # a tractor-semitrailer, 3.8 m high


def _directions() -> np.ndarray:
    elevation = np.radians(np.linspace(2.0, -30.0, ROWS))[:, None]
    azimuth = np.radians(np.linspace(60.0, -60.0, COLUMNS))[None, :]
    return np.stack(
        np.broadcast_arrays(
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ),
        axis=-1,
    ).reshape(-1, 3)


DIRECTIONS = _directions()


def _box_range(box: Box) -> np.ndarray:
    """Range [m] along each ray to an upright box (slab test in the box frame); inf on a miss."""
    c, s = math.cos(box.heading_rad), math.sin(box.heading_rad)
    centre = np.array([box.x_m, box.y_m, 0.5 * (box.bottom_z_m + box.top_z_m)])
    half = np.array([box.length_m, box.width_m, box.top_z_m - box.bottom_z_m]) / 2
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # sensor -> box frame
    origin = rotation @ -centre
    direction = DIRECTIONS @ rotation.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - origin) / direction
        t2 = (half - origin) / direction
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (far >= near) & (near > 0)
    return np.where(hit, near, np.inf)


def _cast(boxes: list[Box], rng: np.random.Generator) -> tuple[PointFrame, np.ndarray]:
    """An organized frame of the scene and, per slot, the index of the box hit (-1: none)."""
    dz, dy = DIRECTIONS[:, 2], DIRECTIONS[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        ground = np.where(dz < 0, -SENSOR_HEIGHT_M / dz, np.inf)
        wall = np.where(dy > 0, WALL_Y_M / dy, np.inf)
    wall_z = wall * dz
    wall = np.where((wall_z >= -SENSOR_HEIGHT_M) & (wall_z <= WALL_TOP_Z_M), wall, np.inf)
    ranges = np.stack([ground, wall] + [_box_range(box) for box in boxes], axis=1)
    nearest = np.argmin(ranges, axis=1)
    distance = ranges[np.arange(len(ranges)), nearest]
    distance = distance + rng.normal(0.0, NOISE_M, len(distance))
    returned = distance <= MAX_RANGE_M
    points = np.full((len(DIRECTIONS), 4), np.nan, dtype=np.float32)
    points[returned, :3] = DIRECTIONS[returned] * distance[returned, None]
    points[returned, 3] = 0.5
    label = np.where(returned & (nearest >= 2), nearest - 2, -1)
    return PointFrame(points=points, rows=ROWS, columns=COLUMNS), label


def _learning_frames(rng: np.random.Generator, count: int = 30) -> list[PointFrame]:
    """Frames with one car passing through at 4 m per frame."""
    return [
        _cast([Box(-40.0 + 4.0 * k, 9.0, 0.0, 4.5, 1.8, -4.8, -3.5)], rng)[0] for k in range(count)
    ]


@pytest.fixture(scope="module")
def scene() -> tuple[list[PointFrame], PointFrame, np.ndarray]:
    rng = np.random.default_rng(7)
    learning = _learning_frames(rng)
    frame, label = _cast([CAR, TRUCK], rng)
    return learning, frame, label


@pytest.fixture(scope="module")
def range_background(
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
) -> RangeImageBackground:
    return RangeImageBackground.learn(scene[0])


# --------------------------------------------------------------------------------------------
# Range-image background
# --------------------------------------------------------------------------------------------


def test_range_background_ignores_passing_car_and_marks_open_sky(
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
    range_background: RangeImageBackground,
) -> None:
    rng = np.random.default_rng(1)
    empty_frame, _ = _cast([], rng)
    truth = np.linalg.norm(empty_frame.points[:, :3], axis=1).reshape(ROWS, COLUMNS)
    model = range_background.background_range_m
    returned = np.isfinite(truth)
    # Every slot that sees the static scene has the static range (the passing car is ignored),
    # to within half its margin: the learning counts ranges in bins one margin wide...
    assert np.all(np.isfinite(model[returned]))
    margin = np.maximum(0.3, 0.01 * truth[returned])
    assert np.all(np.abs(model[returned] - truth[returned]) <= 0.5 * margin + 3 * NOISE_M)
    # ... and slots that never return are open sky.
    assert np.all(np.isinf(model[~returned]))
    # Nothing of an empty frame is foreground.
    assert range_background.foreground_mask(empty_frame).sum() == 0


def test_range_background_needs_a_surface_that_shows() -> None:
    nan = math.nan
    ranges = np.array(
        [
            # A wall at 50 m, a vehicle in front of it in 3 of 10 frames: the wall.
            [50, 20, 50, 50, 21, 50, 50, 22, 50, 50],
            # Nothing there; traffic crosses the ray in 4 frames at ever different ranges.
            [nan, 30, nan, 32, nan, nan, 35, nan, 38, nan],
            # A dark surface at 60 m that returns in 3 frames out of 10: still background.
            [60, nan, nan, 60, nan, nan, nan, 60, nan, nan],
            # Never a return.
            [nan] * 10,
        ]
    )
    directions = np.array([[1.0, 0, 0], [0, 1.0, 0], [0.6, 0.8, 0], [0, 0, 1.0]])
    frames = [
        PointFrame(
            np.column_stack([directions * ranges[:, k : k + 1], np.zeros(4)]).astype(np.float32),
            rows=2,
            columns=2,
        )
        for k in range(ranges.shape[1])
    ]
    model = RangeImageBackground.learn(frames).background_range_m.reshape(-1)
    assert model[0] == pytest.approx(50.0, abs=0.25)
    assert np.isinf(model[1])
    assert model[2] == pytest.approx(60.0, abs=0.3)
    assert np.isinf(model[3])


def test_range_background_foreground_is_the_vehicles(
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
    range_background: RangeImageBackground,
) -> None:
    _, frame, label = scene
    mask = range_background.foreground_mask(frame)
    vehicle = label >= 0
    assert vehicle.sum() > 300
    # The neighbour check costs the returns that lie on a neighbouring slot's background: on
    # this coarse sensor (32 beams, 0.75 deg columns) the lowest row of each body, whose range
    # is the road's in the beam below: under 5 %.
    recall = (mask & vehicle).sum() / vehicle.sum()
    assert recall > 0.95
    plain = RangeImageBackground(
        range_background.background_range_m,
        range_background.settings.model_copy(update={"neighbour_slots": False}),
    )
    assert (plain.foreground_mask(frame) & vehicle).sum() / vehicle.sum() > 0.99
    assert (mask & ~vehicle).sum() <= 2
    # The truck's top stands against the sky above the wall: open-sky slots give foreground.
    sky = np.isinf(range_background.background_range_m.reshape(-1))
    assert (mask & sky).sum() > 0


def test_fast_pipeline_finds_both_vehicles_with_centres(
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
    range_background: RangeImageBackground,
) -> None:
    _, frame, label = scene
    settings = FastSettings(heading_prior_rad=0.0, update_background=False)
    result = FastPipeline(settings, range_background).detect(frame)
    assert list(result.timings_s) == ["foreground", "cluster", "boxes"]
    assert len(result.detections) == 2
    by_class = {d.object_class: d for d in result.detections}
    assert set(by_class) == {VehicleClass.CAR, VehicleClass.TRUCK}
    for truth, detection in (
        (CAR, by_class[VehicleClass.CAR]),
        (TRUCK, by_class[VehicleClass.TRUCK]),
    ):
        error = math.hypot(
            detection.center_xyz_m[0] - truth.x_m, detection.center_xyz_m[1] - truth.y_m
        )
        assert error < 0.3, (detection, truth)
        # Height from the background's ground (z = -5), not from the lowest return.
        assert detection.size_lwh_m[2] == pytest.approx(truth.top_z_m + SENSOR_HEIGHT_M, abs=0.25)
        covariance = np.array(detection.covariance_xy_m2)
        assert np.allclose(covariance, covariance.T)
        assert np.all(np.linalg.eigvalsh(covariance) > 0)
    # Nearly all vehicle returns are in the two boxes (a roof fragment that one coarse beam
    # sees apart from the body is dropped as lower than 0.4 m, not reported as a third vehicle).
    in_boxes = sum(d.num_points for d in result.detections)
    assert in_boxes >= 0.95 * (result.foreground & (label >= 0)).sum()


def test_update_reveals_a_parked_vehicle_that_left() -> None:
    rng = np.random.default_rng(3)
    parked = Box(20.0, 10.0, 0.0, 4.5, 1.8, -4.8, -3.5)
    learning = [_cast([parked], rng)[0] for _ in range(5)]
    settings = RangeBackgroundSettings(reveal_frames=3)
    background = RangeImageBackground.learn(learning, settings)
    with_parked, label = _cast([parked], rng)
    assert background.foreground_mask(with_parked).sum() == 0  # part of the background
    for _ in range(settings.reveal_frames):
        background.update(_cast([], rng)[0])  # it left: its slots now see farther
    mask = background.foreground_mask(_cast([parked], rng)[0])
    assert mask.sum() >= 0.9 * (label >= 0).sum()  # back again: foreground


# --------------------------------------------------------------------------------------------
# Voxel background
# --------------------------------------------------------------------------------------------


def test_voxel_background_from_frames(
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
) -> None:
    learning, frame, label = scene
    unorganized = [PointFrame.unorganized(f.points[np.isfinite(f.points[:, 0])]) for f in learning]
    # The ground (z = -5) lies on a voxel face: its returns split between two voxels, each
    # occupied in about half the frames, which the default 0.3 keeps.
    background = VoxelBackground.from_frames(unorganized, 0.5)
    mask = background.foreground_mask(frame)
    vehicle = label >= 0
    # Vehicle returns in the ground's voxels (the lowest 0.3 m of a body) are lost.
    assert (mask & vehicle).sum() / vehicle.sum() > 0.7
    # Ground returns whose range noise straddles voxel faces at grazing angles are occupied in
    # too few frames: isolated speckle, which clustering drops (two detections below).
    returns = np.isfinite(frame.points[:, 0])
    assert (mask & ~vehicle).sum() <= 0.005 * returns.sum()
    # The dense bit table and the searchsorted fallback agree.
    fallback = VoxelBackground(background.keys, background.voxel_m, max_table_bytes=0)
    assert np.array_equal(fallback.foreground_mask(frame), mask)
    result = FastPipeline(FastSettings(heading_prior_rad=0.0), background).detect(frame)
    assert len(result.detections) == 2
    # Ground from the lowest background voxels: within half a voxel of z = -5.
    assert background.ground_z_m(np.array([[15.0, 8.0]]))[0] == pytest.approx(-5.0, abs=0.3)


def test_voxel_background_from_points_and_dilation() -> None:
    wall = np.column_stack([np.linspace(0.0, 10.0, 200), np.full(200, 5.0), np.full(200, 1.0)])
    plain = VoxelBackground.from_points(wall, 0.5)
    dilated = VoxelBackground.from_points(wall, 0.5, dilate=True)
    near_wall = PointFrame.unorganized([[5.0, 5.4, 1.0], [5.0, 4.6, 1.0], [5.0, 7.0, 1.0]])
    assert plain.foreground_mask(near_wall).tolist() == [False, True, True]
    assert dilated.foreground_mask(near_wall).tolist() == [False, False, True]
    assert dilated.num_voxels > plain.num_voxels


# --------------------------------------------------------------------------------------------
# Save / load, shapes, empty frames
# --------------------------------------------------------------------------------------------


def test_save_load_round_trip(
    tmp_path: Path,
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
    range_background: RangeImageBackground,
) -> None:
    _, frame, _ = scene
    range_path = tmp_path / "range.npz"
    range_background.save(range_path)
    loaded = RangeImageBackground.load(range_path, rows=ROWS, columns=COLUMNS)
    assert np.array_equal(loaded.background_range_m, range_background.background_range_m)
    assert np.array_equal(loaded.foreground_mask(frame), range_background.foreground_mask(frame))
    assert loaded.settings == range_background.settings
    assert isinstance(load_background(range_path), RangeImageBackground)

    voxel = VoxelBackground.from_points(frame.points[np.isfinite(frame.points[:, 0]), :3], 0.4)
    voxel_path = tmp_path / "voxel"  # no suffix: used as given
    voxel.save(voxel_path)
    loaded_voxel = VoxelBackground.load(voxel_path, voxel_m=0.4)
    assert np.array_equal(loaded_voxel.keys, voxel.keys)
    assert np.array_equal(loaded_voxel.foreground_mask(frame), voxel.foreground_mask(frame))

    with pytest.raises(BackgroundFileError, match="64x480"):
        RangeImageBackground.load(range_path, rows=64)
    with pytest.raises(BackgroundFileError, match=r"0\.4 m, expected 0\.5 m"):
        VoxelBackground.load(voxel_path, voxel_m=0.5)
    with pytest.raises(BackgroundFileError, match="'voxel' background, expected 'range_image'"):
        RangeImageBackground.load(voxel_path)
    with np.load(range_path) as archive:
        arrays = {name: archive[name] for name in archive.files}
    old = tmp_path / "old.npz"
    np.savez(old, **{**arrays, "format_version": np.array(1)})
    with pytest.raises(BackgroundFileError, match="format version 1"):
        RangeImageBackground.load(old)
    broken = tmp_path / "broken.npz"
    broken.write_bytes(range_path.read_bytes()[:100])
    with pytest.raises(BackgroundFileError, match="not a readable"):
        load_background(broken)


def test_frame_of_another_layout_raises(
    range_background: RangeImageBackground,
) -> None:
    other = PointFrame(
        points=np.zeros((ROWS * (COLUMNS + 1), 4), np.float32), rows=ROWS, columns=COLUMNS + 1
    )
    with pytest.raises(ShapeMismatchError, match="rebuild the background"):
        range_background.foreground_mask(other)
    with pytest.raises(ShapeMismatchError):
        range_background.foreground_mask(PointFrame.unorganized(np.zeros((5, 3))))


def test_empty_and_all_nan_frames_give_empty_results(
    range_background: RangeImageBackground,
) -> None:
    all_nan = PointFrame(
        points=np.full((ROWS * COLUMNS, 4), np.nan, np.float32), rows=ROWS, columns=COLUMNS
    )
    result = FastPipeline(FastSettings(), range_background).detect(all_nan)
    assert result.detections == []
    assert result.foreground.shape == (ROWS * COLUMNS,) and not result.foreground.any()

    voxel = VoxelBackground.from_points(np.zeros((1, 3)), 0.5)
    empty = PointFrame.unorganized(np.zeros((0, 4)))
    result = FastPipeline(FastSettings(), voxel).detect(empty)
    assert result.detections == [] and result.foreground.shape == (0,)


def test_learn_background_from_frames_picks_the_model(
    scene: tuple[list[PointFrame], PointFrame, np.ndarray],
) -> None:
    learning = scene[0][:3]
    assert isinstance(learn_background_from_frames(learning), RangeImageBackground)
    clouds = [PointFrame.unorganized(f.points[np.isfinite(f.points[:, 0])]) for f in learning]
    assert isinstance(learn_background_from_frames(clouds), VoxelBackground)


# --------------------------------------------------------------------------------------------
# Clustering and box fitting
# --------------------------------------------------------------------------------------------


def test_euclidean_clusters_split_at_the_gap() -> None:
    rng = np.random.default_rng(5)
    first = rng.uniform([0, 0, 0], [4, 2, 1.5], (300, 3))
    second = rng.uniform([6, 0, 0], [10, 2, 1.5], (300, 3))  # 2 m gap
    labels = euclidean_clusters(np.vstack([first, second]), 0.25, 1.0)
    assert len(set(labels[:300].tolist())) == 1 and len(set(labels[300:].tolist())) == 1
    assert labels[0] != labels[300]


def _visible_faces(
    centre: tuple[float, float], heading: float, length: float, width: float, faces: str
) -> np.ndarray:
    """Points on a rectangle's faces that turn towards the sensor (at the origin).

    ``faces`` is "visible" (every face facing the sensor: an L or one face) or "near_end" (only
    the end face nearer the sensor).
    """
    rng = np.random.default_rng(11)
    axes = np.array(
        [[math.cos(heading), math.sin(heading)], [-math.sin(heading), math.cos(heading)]]
    )
    centre_xy = np.array(centre)
    points = []
    for axis, (half_along, half_across) in enumerate(
        ((length / 2, width / 2), (width / 2, length / 2))
    ):
        for sign in (-1.0, 1.0):
            normal = sign * axes[axis]
            face_middle = centre_xy + half_along * normal
            if np.dot(-face_middle, normal) <= 0:
                continue  # faces away from the sensor
            if faces == "near_end" and axis != 0:
                continue
            offsets = np.arange(-half_across, half_across + 1e-9, 0.05)
            points.append(face_middle + offsets[:, None] * axes[1 - axis])
    xy = np.vstack(points) + rng.normal(0.0, 0.01, (sum(len(p) for p in points), 2))
    z = rng.uniform(-4.5, -3.6, len(xy))
    return np.column_stack([xy, z])


def test_l_shape_fit_recovers_centre_and_heading() -> None:
    centre, heading = (20.0, 8.0), math.radians(10.0)
    points = _visible_faces(centre, heading, 4.6, 1.9, "visible")
    fit = fit_box(points)
    assert fit.faces_seen == 2
    assert math.hypot(fit.center_xyz_m[0] - centre[0], fit.center_xyz_m[1] - centre[1]) < 0.05
    heading_error = (fit.heading_rad - heading + math.pi / 2) % math.pi - math.pi / 2
    assert abs(math.degrees(heading_error)) < 1.0
    # The fit adds back half a column step at each edge (a scanner's outermost columns fall
    # inside the edges); these synthetic faces, sampled every 0.05 m, include their edges.
    assert fit.size_lwh_m[:2] == pytest.approx((4.6, 1.9), abs=0.05 + 0.05)
    assert fit.object_class == VehicleClass.CAR


def test_one_face_with_prior_is_completed_away_from_the_sensor() -> None:
    centre, heading, length = (40.0, 6.0), 0.0, 4.6
    points = _visible_faces(centre, heading, length, 1.8, "near_end")
    fit = fit_box(points, heading_prior_rad=0.02, heading_tolerance_rad=math.radians(20))
    # The whole end face is seen (1.8 m, less the noise): the width is not grown beyond it
    # by more than the noise.
    fit_error = math.hypot(fit.center_xyz_m[0] - centre[0], fit.center_xyz_m[1] - centre[1])
    centroid = points[:, :2].mean(axis=0)
    centroid_error = math.hypot(centroid[0] - centre[0], centroid[1] - centre[1])
    assert fit.faces_seen == 1 and fit.completed_lw[0]
    assert fit.size_lwh_m[1] == pytest.approx(1.8 + 0.05, abs=0.03)  # + a sample step
    assert fit_error < 0.3
    assert centroid_error == pytest.approx(length / 2, abs=0.1)
    assert fit_error < 0.2 * centroid_error
    # The unseen dimension (the length, along x here) is the uncertain one.
    covariance = fit.covariance_xy_m2
    assert covariance[0, 0] > 1.5 * covariance[1, 1]
    # An L of the same car gives a smaller covariance along the length.
    l_fit = fit_box(_visible_faces((40.0, 6.0), 0.0, 4.6, 1.8, "visible"), heading_prior_rad=0.0)
    assert l_fit.covariance_xy_m2[0, 0] < covariance[0, 0]


def test_far_points_link_over_wider_gaps() -> None:
    def pair(range_m: float) -> np.ndarray:
        # Two runs of points 1.3 m apart across the line of sight.
        run = np.column_stack([np.full(5, range_m), np.arange(5) * 0.3, np.zeros(5)])
        return np.vstack([run, run + np.array([0.0, 2.5, 0.0])])

    for range_m, linked in ((10.0, False), (100.0, True)):
        labels = euclidean_clusters(pair(range_m), 0.25, 1.0, eps_range_fraction=0.015)
        assert bool(labels[0] == labels[-1]) is linked, range_m
    assert len(set(euclidean_clusters(pair(100.0), 0.25, 1.0).tolist())) == 2


def test_ground_grid_falls_back_to_nearby_cells() -> None:
    # Ground seen only in rings 20 m apart, as a sensor sees it far away.
    ring_x = np.repeat([80.0, 100.0], 11)
    ring_y = np.tile(np.linspace(-5.0, 5.0, 11), 2)
    grid = GroundGrid.from_points(np.column_stack([ring_x, ring_y, np.full(22, -6.0)]))
    heights = grid.lookup(np.array([[80.2, 0.3], [90.0, 0.0], [200.0, 0.0]]))
    assert heights[0] == -6.0  # a known cell
    assert heights[1] == pytest.approx(-6.0)  # between rings: the nearest known cells
    assert np.isnan(heights[2])  # nothing within 30 m


def test_fragment_inside_a_fitted_box_is_absorbed() -> None:
    # A car's rear and the first 2.8 m of its side; 1.3 m farther along the side, a fragment
    # (a side at a grazing angle breaks into columns far apart).
    car = _visible_faces((20.0, 8.0), 0.0, 4.6, 1.8, "visible")
    main = car[car[:, 0] < 20.5]
    fragment = np.column_stack([np.linspace(21.8, 22.2, 6), np.full(6, 7.1), np.full(6, -4.0)])
    ground = np.column_stack(
        [
            np.repeat(np.arange(0.0, 40.0), 20),
            np.tile(np.arange(-10.0, 10.0), 40),
            np.full(800, -5.0),
        ]
    )
    background = VoxelBackground.from_points(ground, 0.5)
    frame = PointFrame.unorganized(np.vstack([main, fragment]))
    settings = FastSettings(heading_prior_rad=0.0)
    result = FastPipeline(settings, background).detect(frame)
    assert len(result.detections) == 1
    assert result.detections[0].num_points == len(main) + len(fragment)


def test_heavy_vehicle_length_is_completed_only_when_seen_end_on() -> None:
    def tall(points: np.ndarray) -> np.ndarray:
        points = points.copy()
        points[:, 2] = np.linspace(-4.5, -1.0, len(points))  # 3.5 m of a 4 m high body
        return points

    # Seen end-on far away: the length is hidden, a semitrailer's is assumed.
    end_on = tall(_visible_faces((60.0, 5.0), 0.0, 16.5, 2.5, "near_end"))
    fit = fit_box(end_on, heading_prior_rad=0.0, ground_z_m=-5.0)
    assert fit.object_class == VehicleClass.TRUCK
    assert fit.size_lwh_m[0] == pytest.approx(16.0)
    assert fit.center_xyz_m[0] == pytest.approx(60.0 - 8.25 + 8.0, abs=0.1)
    # A 7 m box truck beside the mast shows its whole side: its length is what is visible.
    beside = tall(_visible_faces((3.0, 8.0), 0.0, 7.0, 2.5, "visible"))
    fit = fit_box(beside, heading_prior_rad=0.0, ground_z_m=-5.0)
    assert fit.size_lwh_m[0] == pytest.approx(7.0, abs=0.05)
    assert math.hypot(fit.center_xyz_m[0] - 3.0, fit.center_xyz_m[1] - 8.0) < 0.05


def test_a_vehicle_cut_by_the_lowest_beam_is_placed_from_its_far_end(
    range_background: RangeImageBackground,
) -> None:
    # A car coming out of the blind cone under the sensor: the lowest beam (-30 degrees, 5 m
    # up) reaches its roof (3.5 m below the sensor) 6.1 m out and the road 8.7 m out, so of a
    # car 3.5-8 m ahead and 3 m aside, only the 2.7 m beyond 5.3 m ahead are seen. Its far end
    # (8 m) is a face seen whole: the box is completed from it towards the sensor, and its
    # centre is the car's.
    cut_car = Box(5.75, 3.0, 0.0, 4.5, 1.8, -4.8, -3.5)
    frame, _ = _cast([cut_car, CAR], np.random.default_rng(3))
    settings = FastSettings(heading_prior_rad=0.0, update_background=False)
    detections = FastPipeline(settings, range_background).detect(frame).detections
    assert len(detections) == 2
    near = min(detections, key=lambda d: d.center_xyz_m[0])
    far = max(detections, key=lambda d: d.center_xyz_m[0])
    assert near.completed_from_far_end and not far.completed_from_far_end
    assert near.center_xyz_m[0] == pytest.approx(5.75, abs=0.2)
    along = np.array([math.cos(near.heading_rad), math.sin(near.heading_rad)])
    assert along @ np.array(near.covariance_xy_m2) @ along < 1.0
    # The car 17 m out, clear of the lowest beam, keeps its box's own covariance.
    assert np.array(far.covariance_xy_m2).max() < 1.0
    # Completed from the cut edge instead (the setting off), the box stands on that edge, a
    # metre and more ahead of the car, and its centre gets fov_cut_std_m along the car (a
    # track may take it; none starts from it).
    edge = FastPipeline(
        settings.model_copy(update={"fov_cut_from_far_end": False}), range_background
    )
    near_edge = min(edge.detect(frame).detections, key=lambda d: d.center_xyz_m[0])
    assert not near_edge.completed_from_far_end
    assert near_edge.center_xyz_m[0] > 5.75 + 1.0
    assert along @ np.array(near_edge.covariance_xy_m2) @ along >= settings.fov_cut_std_m**2
    # Neither: the cut car's covariance is its box's.
    plain = FastPipeline(
        settings.model_copy(update={"fov_cut_std_m": 0.0, "fov_cut_from_far_end": False}),
        range_background,
    )
    near_plain = min(plain.detect(frame).detections, key=lambda d: d.center_xyz_m[0])
    assert np.array(near_plain.covariance_xy_m2).max() < 4.0


def test_a_return_on_a_neighbouring_slots_background_is_not_foreground() -> None:
    """Three columns: a drum at 10 m in the first, the road at 30 m behind in the others. The
    mast's sway turns the middle beam onto the drum's edge: with ``neighbour_slots`` that
    return lies on the first slot's background and is not a vehicle; a car at 20 m is; without
    the check both are foreground."""
    from wz_lidar_detector.background import RangeBackgroundSettings, RangeImageBackground

    def frame(middle_m: float) -> PointFrame:
        ranges = np.array([10.0, middle_m, 30.0])
        azimuth = np.radians([0.0, 0.2, 0.4])
        points = np.column_stack(
            [ranges * np.cos(azimuth), ranges * np.sin(azimuth), np.zeros(3), np.ones(3)]
        ).astype(np.float32)
        sky = np.full((3, 4), np.nan, dtype=np.float32)  # a second beam, above everything
        return PointFrame(points=np.concatenate([points, sky]), rows=2, columns=3)

    learning = [frame(30.0) for _ in range(10)]
    checked = RangeImageBackground.learn(learning)
    plain = RangeImageBackground.learn(learning, RangeBackgroundSettings(neighbour_slots=False))
    assert checked.foreground_mask(frame(10.1))[:3].tolist() == [False, False, False]
    assert checked.foreground_mask(frame(20.0))[:3].tolist() == [False, True, False]
    assert plain.foreground_mask(frame(10.1))[:3].tolist() == [False, True, False]


def test_the_learner_counts_frame_by_frame_in_fixed_memory() -> None:
    """Frames added one at a time give the same model as ``learn``; at most 255 frames (one
    byte per bin); a frame of another layout is refused."""
    from wz_lidar_detector.background import RangeBackgroundLearner

    rng = np.random.default_rng(5)
    frames = _learning_frames(rng, 12)
    learner = RangeBackgroundLearner(ROWS, COLUMNS)
    for frame in frames:
        learner.add(frame)
    assert np.array_equal(
        learner.finish().background_range_m, RangeImageBackground.learn(frames).background_range_m
    )
    with pytest.raises(ShapeMismatchError, match="16x8 slots"):
        learner.add(PointFrame(np.zeros((128, 4), np.float32), rows=16, columns=8))
    while not learner.full:
        learner.add(frames[0])
    assert learner.frames == RangeBackgroundLearner.MAX_FRAMES
    with pytest.raises(ValueError, match="at most 255 frames"):
        learner.add(frames[0])
    # ``learn`` takes 255 of more frames, evenly spread.
    many = RangeImageBackground.learn(frames * 25)  # 300
    assert np.array_equal(
        np.isinf(many.background_range_m), np.isinf(learner.finish().background_range_m)
    )


def test_a_flickering_near_surface_is_background() -> None:
    """A slot that sees a post in 40 % of the learning frames and the ground behind it in the
    rest (a beam the mast's sway swings across the post's edge): by default the post is its
    background; with ``near_support_fraction=1`` the ground is, and the post comes out as
    foreground."""
    from wz_lidar_detector.background import RangeBackgroundSettings, RangeImageBackground
    from wz_lidar_detector.detection import PointFrame

    def frame(post: bool) -> PointFrame:
        points = np.array(
            [(10.0 if post else 30.0, 0.0, -1.0, 1.0), (40.0, 0.0, -2.0, 1.0)], dtype=np.float32
        )
        return PointFrame(points=points, rows=2, columns=1, stamp_s=0.0)

    frames = [frame(i % 5 < 2) for i in range(20)]
    default = RangeImageBackground.learn(frames, RangeBackgroundSettings())
    far = RangeImageBackground.learn(frames, RangeBackgroundSettings(near_support_fraction=1.0))
    post = frame(True)
    assert not default.foreground_mask(post)[0]
    assert far.foreground_mask(post)[0]


def test_a_truck_whose_near_end_a_nearer_truck_hides_is_not_completed_away_from_it(
    range_background: RangeImageBackground,
) -> None:
    """A semitrailer in the far lane, its near end hidden behind a box truck in the near lane
    (a low mast sees over neither): the end of its points nearer the sensor is where the box
    truck's shadow ends, not its face. Completed away from the sensor, the box stood 12 m
    beyond the truck's centre with a 2 m std along it (6 std off), and ran ahead of it as it
    came out of the shadow; grown evenly at both ends, it is within half the truck's length
    and 2 std of its covariance."""
    hidden = Box(40.0, 12.0, 0.0, 16.5, 2.5, -4.6, -1.6)  # 3.4 m high
    occluder = Box(24.0, 8.0, 0.0, 7.0, 2.5, -4.7, -0.9)  # 4.1 m high, 7 m long
    frame, _ = _cast([occluder, hidden], np.random.default_rng(5))
    settings = FastSettings(heading_prior_rad=0.0, update_background=False)
    detections = FastPipeline(settings, range_background).detect(frame).detections
    assert len(detections) == 2
    truck = max(detections, key=lambda d: d.center_xyz_m[1])
    error = truck.center_xyz_m[0] - hidden.x_m
    along_std = math.sqrt(truck.covariance_xy_m2[0][0])
    assert abs(error) < hidden.length_m / 2 and abs(error) < 2.0 * along_std, (error, along_std)
    # The box truck in front, its near end in the clear, is still completed from that end
    # (seen end-on, as a semitrailer: its length is hidden, not its near face).
    front = min(detections, key=lambda d: d.center_xyz_m[1])
    assert front.center_xyz_m[0] - front.size_lwh_m[0] / 2 == pytest.approx(20.5, abs=0.3)


def test_the_beam_spacing_comes_from_the_site_s_lidar_and_says_a_far_car_may_be_a_truck() -> None:
    """A 32-beam LiDAR over 40 deg has its beams 1.29 deg apart, not a 64-beam one's 0.65:
    the front of a semitrailer 80 m off, 1.7 m of it under the highest return, may hide 1.8 m
    more above it. Completed as a car, its box's covariance must reach to a heavy vehicle's
    centre; with the 64-beam spacing it claimed a car to 0.3 m (generated site 9401: a truck's
    box 6 m ahead of it, a second track on the approach)."""
    site = generate_site(9401)
    mount = next(m for m in site.sensors if m.intrinsics.kind == "lidar")
    assert mount.intrinsics.beams == 32
    settings = fitted_to_mount(LidarDetectorSettings(), site, mount)
    box = settings.fast.box
    assert box.beam_spacing_deg == pytest.approx(40.0 / 31.0)
    assert box.angular_resolution_deg == pytest.approx(360.0 / mount.intrinsics.azimuth_steps)
    assert settings.fast.heading_prior_rad is not None
    # Set by hand, a value stays.
    by_hand = LidarDetectorSettings.model_validate({"fast": {"box": {"beam_spacing_deg": 0.4}}})
    assert fitted_to_mount(by_hand, site, mount).fast.box.beam_spacing_deg == 0.4

    front = _visible_faces((80.0, 5.0), 0.0, 16.5, 2.5, "near_end")
    front[:, 2] = np.linspace(-6.7, -5.2, len(front))  # 1.7 m seen above the road at -6.9 m
    along_std = {
        spacing: math.sqrt(
            fit_box(
                front,
                heading_prior_rad=0.0,
                ground_z_m=-6.9,
                settings=box.model_copy(update={"beam_spacing_deg": spacing}),
            ).covariance_xy_m2[0, 0]
        )
        for spacing in (0.65, 40.0 / 31.0)
    }
    assert along_std[0.65] < 0.5
    assert along_std[40.0 / 31.0] >= (16.0 - 4.5) / 2


def _cut_car_points(centre_x: float, ground_z: float, bonnet_seen: bool) -> np.ndarray:
    """The returns a mast's lowest beam gives of a car coming out from under it (moving along
    +x, 3 m aside): the rear of its cabin cut by the beam, the cabin's roof and its front edge
    (the simulator's car: 4.5 x 1.8 x 1.5 m, the cabin 2.25 m long and set back 0.225 m, the
    bonnet's top at 0.87 m); with ``bonnet_seen``, also the bonnet up to the front face."""
    cabin_front = centre_x - 0.225 + 1.125
    along = np.arange(centre_x - 0.6, cabin_front + 1e-9, 0.1)
    across = np.arange(3.0 - 0.7, 3.0 + 0.71, 0.1)
    x, y = np.meshgrid(along, across)
    roof = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, ground_z + 1.5)])
    if not bonnet_seen:
        return roof
    bx, by = np.meshgrid(np.arange(cabin_front, centre_x + 2.25 + 1e-9, 0.1), across)
    bonnet = np.column_stack([bx.ravel(), by.ravel(), np.full(bx.size, ground_z + 0.87)])
    return np.vstack([roof, bonnet])


def test_a_cars_front_hidden_below_its_roof_line_moves_the_box_on() -> None:
    """A car coming out of the blind cone of an 8 m mast whose lowest beam is 11.3 degrees
    down (site 10604's: a 39.7 m cone): the beam meets its roof 32.5 m out, and the roof hides
    the bonnet, 1.35 m of the car ahead of the roof's front edge. Completed from that edge as
    if it were the front, the box stood 1.35 m behind the car (site 10604, session 36). The
    front may lie up to ``hidden_front_car_m`` further on: the box moves on by half of it,
    with that spread in its variance, unless a beam above would have met a front there, or
    the bonnet is seen."""
    ground, centre = -8.0, 32.0
    shallow = (math.radians(-11.3), math.radians(0.65))
    settings = BoxFitSettings()
    roof = _cut_car_points(centre, ground, bonnet_seen=False)
    hidden = hidden_front_m(roof, roof[:, 0], shallow, 2.0, 0.75)
    assert hidden == pytest.approx(2.0)  # the next beam comes 0.75 m down 3.8 m further on
    # Under a steep beam (30 degrees down, beams 0.5 degrees apart: the roof met 11.3 m out)
    # the next beam comes 0.75 m below the roof 1.3 m past its edge: a front further on would
    # have returned it.
    steep = _cut_car_points(10.4, ground, bonnet_seen=False)
    bounded = hidden_front_m(
        steep, steep[:, 0], (math.radians(-30.0), math.radians(0.5)), 2.0, 0.75
    )
    assert 1.0 < bounded < 1.7
    whole = _cut_car_points(centre, ground, bonnet_seen=True)
    assert hidden_front_m(whole, whole[:, 0], shallow, 2.0, 0.75) == 0.0
    tip = whole[whole[:, 0] > centre + 1.6]  # the bonnet's tip alone: no roof line
    assert hidden_front_m(tip, tip[:, 0], shallow, 2.0, 0.75) == 0.0

    def box(points: np.ndarray, **overrides: float) -> tuple[float, float]:
        fit = fit_box(
            points,
            heading_prior_rad=0.0,
            ground_z_m=ground,
            settings=settings.model_copy(update=overrides),
            near_end_cut=True,
            beams_rad=shallow,
        )
        assert fit.completed_from_far_end
        return fit.center_xyz_m[0] - centre, float(fit.covariance_xy_m2[0, 0])

    error_off, variance_off = box(roof, hidden_front_car_m=0.0)
    error_on, variance_on = box(roof)
    assert error_off == pytest.approx(-1.35, abs=0.1)
    assert error_on == pytest.approx(-1.35 + 1.0, abs=0.1)
    assert variance_on == pytest.approx(variance_off + 2.0**2 / 12.0, rel=0.05)
    # The bonnet seen, the far end is the front: the box is the car's either way.
    assert abs(box(whole)[0]) < 0.1
    # Coming towards the sensor (heading the other way), the far end is the rear: nothing
    # moves.
    towards = roof
    fit = fit_box(
        towards, heading_prior_rad=math.pi, ground_z_m=ground, near_end_cut=True, beams_rad=shallow
    )
    plain = fit_box(
        towards,
        heading_prior_rad=math.pi,
        ground_z_m=ground,
        near_end_cut=True,
        settings=settings.model_copy(update={"hidden_front_car_m": 0.0}),
        beams_rad=shallow,
    )
    assert fit.center_xyz_m[0] == pytest.approx(plain.center_xyz_m[0])


def test_a_cut_car_whose_bonnet_is_seen_stays_on_its_front(
    range_background: RangeImageBackground,
) -> None:
    """The simulator's car (a body to 0.87 m, a cabin to 1.5 m set back on it) coming out of
    the blind cone under a 5 m sensor whose lowest beam is 30 degrees down, at 4-8.75 m: so
    steep a beam meets the bonnet, so the far end is the front and no box moves on. At
    4-4.75 m it meets only the bonnet's tip: a test on the share of the height the box shows
    took that for a roof, and the box stood 0.55 m ahead of the car."""
    settings = FastSettings(heading_prior_rad=0.0, update_background=False)
    pipeline = FastPipeline(settings, range_background)
    errors = []
    for centre in np.arange(4.0, 9.0, 0.25):
        car = [
            Box(centre, 3.0, 0.0, 4.5, 1.8, -4.72, -4.13),
            Box(centre - 0.225, 3.0, 0.0, 2.25, 1.58, -4.13, -3.5),
        ]
        frame, _ = _cast(car, np.random.default_rng(3))
        (detection,) = pipeline.detect(frame).detections
        assert detection.completed_from_far_end
        errors.append(detection.center_xyz_m[0] - centre)
    assert max(abs(e) for e in errors) < 0.2
