"""Optical flow between detections (:mod:`wz_camera_detector.flow`): boxes followed on synthetic
frames whose motion is known exactly."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wz_camera_detector.flow import BoxFlow, FlowSettings
from wz_camera_detector.following import DetectAndFollow
from wz_camera_detector.settings import CameraDetectorSettings
from wz_camera_detector.yolo import ImageDetection

HEIGHT, WIDTH = 240, 320


def textured_patch(height: int, width: int, seed: int = 0) -> np.ndarray:
    """A patch with texture at every scale (smoothed noise), grey uint8."""
    rng = np.random.default_rng(seed)
    noise = rng.uniform(0, 255, (height, width)).astype(np.float32)
    return np.clip(cv2.GaussianBlur(noise, (0, 0), 1.5) * 2.0 - 128.0, 0, 255).astype(np.uint8)


def scene(
    patch: np.ndarray, x: float, y: float, size: tuple[int, int] = (HEIGHT, WIDTH)
) -> np.ndarray:
    """A flat grey road with ``patch`` placed with its top left corner at (x, y) [px]
    (sub-pixel, by an affine warp): the frame and the patch's box."""
    image = np.full(size, 90, dtype=np.uint8)
    matrix = np.float32([[1, 0, x], [0, 1, y]])
    mask = np.full(patch.shape, 255, dtype=np.uint8)
    warped = cv2.warpAffine(patch, matrix, (size[1], size[0]), flags=cv2.INTER_LINEAR)
    inside = cv2.warpAffine(mask, matrix, (size[1], size[0]), flags=cv2.INTER_LINEAR)
    return np.where(inside > 127, warped, image).astype(np.uint8)


def box_at(x: float, y: float, patch: np.ndarray) -> tuple[float, float, float, float]:
    return (x, y, x + patch.shape[1], y + patch.shape[0])


def test_a_moving_textured_box_is_followed_to_a_fraction_of_a_pixel() -> None:
    patch = textured_patch(30, 50)
    flow = BoxFlow(FlowSettings())
    first = flow.follow(scene(patch, 100.0, 80.0), [box_at(100.0, 80.0, patch)])
    assert np.isnan(first).all()  # nothing to follow from on the first frame
    followed = flow.follow(scene(patch, 106.4, 82.7), [box_at(100.0, 80.0, patch)])
    np.testing.assert_allclose(followed[0], box_at(106.4, 82.7, patch), atol=0.5)


def test_a_growing_box_is_followed_with_its_scale() -> None:
    """A vehicle nearing the camera: its picture grows 10 % between two frames."""
    patch = textured_patch(40, 60, seed=1)
    bigger = cv2.resize(patch, (66, 44), interpolation=cv2.INTER_LINEAR)
    flow = BoxFlow(FlowSettings())
    flow.follow(scene(patch, 120.0, 100.0), [])
    # The same centre (150, 120), 10 % larger, then moved by (4, 3).
    followed = flow.follow(scene(bigger, 121.0, 101.0), [box_at(120.0, 100.0, patch)])
    np.testing.assert_allclose(followed[0], (121.0, 101.0, 187.0, 145.0), atol=1.5)


def test_the_guess_lets_a_fast_box_be_found() -> None:
    """Motion beyond LK's reach at its pyramid is found when the guess (the tracker's velocity)
    starts it near; without the guess the box is lost or misplaced, never followed to the right
    place by chance."""
    patch = textured_patch(20, 24, seed=2)  # followed at full resolution (under 24 px tall)
    settings = FlowSettings(pyramid_levels=1)  # reach about 15 px
    moved = box_at(160.0, 100.0, patch)
    start = box_at(100.0, 100.0, patch)
    guessed = BoxFlow(settings)
    guessed.follow(scene(patch, 100.0, 100.0), [])
    found = guessed.follow(scene(patch, 160.0, 100.0), [start], guess_shift_px=[(58.0, 1.0)])
    np.testing.assert_allclose(found[0], moved, atol=0.5)
    blind = BoxFlow(settings)
    blind.follow(scene(patch, 100.0, 100.0), [])
    lost = blind.follow(scene(patch, 160.0, 100.0), [start])
    assert np.isnan(lost[0]).all() or np.abs(lost[0] - np.array(moved)).max() > 5.0


def test_a_box_on_a_flat_road_is_lost() -> None:
    """Nothing to lock on (a box the detector drew on the empty road): lost, not invented."""
    road = np.full((HEIGHT, WIDTH), 90, dtype=np.uint8)
    flow = BoxFlow(FlowSettings())
    flow.follow(road, [])
    assert np.isnan(flow.follow(road.copy(), [(100.0, 80.0, 150.0, 110.0)])).all()


def test_a_box_leaving_the_frame_is_followed_by_its_visible_part() -> None:
    patch = textured_patch(40, 60, seed=3)
    flow = BoxFlow(FlowSettings())
    flow.follow(scene(patch, 290.0, 100.0), [])  # 30 of its 60 px in the frame
    followed = flow.follow(scene(patch, 296.0, 101.0), [box_at(290.0, 100.0, patch)])
    np.testing.assert_allclose(followed[0], box_at(296.0, 101.0, patch), atol=1.0)


def test_a_large_plain_vehicle_is_followed_by_its_edges() -> None:
    """A near truck, 160 px tall, painted in one colour with a darker window band: no texture
    inside at full resolution. It is followed at the pyramid level where it is small, by its
    corners and edges."""
    size = (480, 640)
    truck = np.full((160, 220), 200, dtype=np.uint8)
    truck[20:50, 20:200] = 60  # windows
    truck[120:135, 10:60] = 30  # a wheel arch
    flow = BoxFlow(FlowSettings())
    flow.follow(scene(truck, 200.0, 150.0, size), [])
    followed = flow.follow(scene(truck, 209.0, 155.0, size), [box_at(200.0, 150.0, truck)])
    np.testing.assert_allclose(followed[0], box_at(209.0, 155.0, truck), atol=2.0)


def test_a_crop_offset_is_taken_into_account() -> None:
    """The node gives flow its region of interest only, with the crop's corner."""
    patch = textured_patch(30, 40, seed=4)
    full_before, full_after = scene(patch, 150.0, 120.0), scene(patch, 155.0, 118.0)
    flow = BoxFlow(FlowSettings())
    flow.follow(full_before[100:, 100:], [], origin_px=(100, 100))
    followed = flow.follow(
        full_after[100:, 100:], [box_at(150.0, 120.0, patch)], origin_px=(100, 100)
    )
    np.testing.assert_allclose(followed[0], box_at(155.0, 118.0, patch), atol=0.5)


def test_another_picture_is_not_followed_from_the_last() -> None:
    """A frame of another size, another crop, or after restart: no flow from the one before."""
    patch = textured_patch(30, 40, seed=5)
    box = [box_at(150.0, 120.0, patch)]
    flow = BoxFlow(FlowSettings())
    flow.follow(scene(patch, 150.0, 120.0), [])
    assert np.isnan(flow.follow(scene(patch, 152.0, 120.0, (240, 330)), box)).all()
    assert np.isnan(
        flow.follow(scene(patch, 152.0, 120.0, (240, 330)), box, origin_px=(1, 0))
    ).all()
    flow.restart()
    assert np.isnan(flow.follow(scene(patch, 152.0, 120.0, (240, 330)), box)).all()
    followed = flow.follow(scene(patch, 154.0, 120.0, (240, 330)), [box_at(152.0, 120.0, patch)])
    np.testing.assert_allclose(followed[0], box_at(154.0, 120.0, patch), atol=0.5)


def test_a_small_box_is_moved_but_keeps_its_size() -> None:
    """A far car's box 16 px tall: flow moves it, the detector's size stays (a few points a few
    pixels apart do not measure a scale)."""
    patch = textured_patch(16, 24, seed=6)
    bigger = cv2.resize(patch, (26, 17), interpolation=cv2.INTER_LINEAR)
    flow = BoxFlow(FlowSettings())
    flow.follow(scene(patch, 100.0, 100.0), [])
    followed = flow.follow(scene(bigger, 102.0, 100.5), [box_at(100.0, 100.0, patch)])[0]
    assert followed[2] - followed[0] == pytest.approx(24.0) and followed[3] - followed[
        1
    ] == pytest.approx(16.0)
    assert (followed[0] + followed[2]) / 2.0 == pytest.approx(102.0 + 13.0, abs=1.0)


class ScriptedDetector:
    """Stands in for the model where the test needs it to miss: the boxes it is given for
    each frame, in order (the frames themselves are real moving pictures for flow)."""

    def __init__(self, boxes_per_frame: list[list[tuple[float, float, float, float]]]) -> None:
        self.boxes_per_frame = boxes_per_frame
        self.frame = 0

    def detect(self, image: np.ndarray) -> list[ImageDetection]:
        boxes = self.boxes_per_frame[self.frame]
        self.frame += 1
        return [ImageDetection(box, 0.9, "car") for box in boxes]


def test_on_a_frame_the_detector_ran_on_flow_carries_only_the_misses_the_edge_explains() -> None:
    """A whole box the detector missed (mostly a vehicle hidden by another: flow would follow
    what hides it) coasts on its motion; a box the frame's edge cuts (a vehicle leaving, which
    the detector loses) is carried by flow, and published."""
    whole, leaving = textured_patch(30, 50, seed=1), textured_patch(30, 50, seed=2)
    step_px = 6.0

    def frame(index: int) -> tuple[np.ndarray, list[tuple[float, float, float, float]]]:
        x_whole, x_leaving = 100.0 + step_px * index, 262.0 + step_px * index
        image = scene(leaving, x_leaving, 150.0)
        image = np.where(scene(whole, x_whole, 60.0) != 90, scene(whole, x_whole, 60.0), image)
        boxes = [box_at(x_whole, 60.0, whole), box_at(x_leaving, 150.0, leaving)]
        return image.astype(np.uint8), [(x1, y1, min(x2, WIDTH), y2) for x1, y1, x2, y2 in boxes]

    frames = [frame(index) for index in range(5)]
    # found on frames 0-3 (confirmed at the third), missed both on frame 4
    detector = ScriptedDetector([boxes for _, boxes in frames[:4]] + [[]])
    images = DetectAndFollow(detector, CameraDetectorSettings(), frozenset({"car"}))
    for index, (image, _) in enumerate(frames):
        step = images.step(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR), index / 10.0, detect=True)
    assert step.detections == []
    by_box = {round(track.box_xyxy_px[0]): track for track in images.tracker.tracks()}
    assert len(by_box) == 2
    whole_track = min(by_box.items())[1]
    leaving_track = max(by_box.items())[1]
    # the cut one: flow's box, published
    assert [track.local_id for track in step.updated] == [leaving_track.local_id]
    assert step.updated[0].followed and step.published == step.updated
    assert abs(leaving_track.box_xyxy_px[0] - (262.0 + 4 * step_px)) < 1.0
    # the whole one: not carried by flow, coasting where its motion puts it
    assert whole_track.misses == 1
    assert abs(whole_track.box_xyxy_px[0] - (100.0 + 4 * step_px)) < 2.0
