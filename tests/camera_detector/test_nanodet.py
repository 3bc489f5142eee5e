"""NanoDet's decode, and the shipped COCO model as the detector loads it (real cameras)."""

from __future__ import annotations

import numpy as np
import pytest

from wz_camera_detector import nanodet
from wz_camera_detector.settings import DEFAULT_MODEL_PATH
from wz_camera_detector.yolo import YoloOnnxDetector


def _outputs(side: int, hits: dict[tuple[int, int], tuple[int, float, list[int]]]) -> list:  # type: ignore[type-arg]
    """Zero-score outputs of a ``side x side`` input with ``hits``: (stride, point) -> (class,
    score, the l, t, r, b bins each distance's logits pick)."""
    scores, dists = [], []
    for stride in nanodet.STRIDES:
        points = (side // stride) ** 2
        level_scores = np.zeros((1, points, 80), np.float32)
        level_dists = np.zeros((1, points, 4 * (nanodet.REG_MAX + 1)), np.float32)
        for (hit_stride, point), (class_id, score, bins) in hits.items():
            if hit_stride == stride:
                level_scores[0, point, class_id] = score
                for side_index, bin_index in enumerate(bins):
                    level_dists[0, point, side_index * 11 + bin_index] = 60.0  # softmax ~ one-hot
        scores.append(level_scores)
        dists.append(level_dists)
    return scores + dists


def test_decode_puts_each_point_s_distances_around_its_centre() -> None:
    # Stride 8 on a 64 px input: 8 columns; point 26 is row 3, column 2: centre (20, 28).
    # Stride 32: point 3 is row 1, column 1: centre (48, 48).
    outputs = _outputs(
        64,
        {
            (8, 26): (2, 0.9, [2, 2, 3, 3]),
            (32, 3): (7, 0.6, [1, 1, 0, 0]),
            (16, 5): (0, 0.99, [1, 1, 1, 1]),
        },
    )
    vehicles = np.array([2, 3, 5, 7], dtype=np.intp)
    boxes, scores, classes = nanodet.decode(outputs, (64, 64), 0.35, vehicles)
    # The person (class 0) is not a vehicle: not kept.
    assert classes.tolist() == [2, 7]
    assert scores == pytest.approx([0.9, 0.6])
    assert boxes[0] == pytest.approx([20 - 16, 28 - 16, 20 + 24, 28 + 24], abs=1e-3)
    assert boxes[1] == pytest.approx([48 - 32, 48 - 32, 48, 48], abs=1e-3)
    # Nothing above the threshold: nothing.
    assert len(nanodet.decode(outputs, (64, 64), 0.95, vehicles)[0]) == 0


def test_the_shipped_coco_model_loads_with_its_operating_point() -> None:
    detector = YoloOnnxDetector(DEFAULT_MODEL_PATH, threads=1)
    assert detector.architecture == "nanodet" and detector.free_input
    assert len(detector.class_names) == 80
    assert {"car", "truck", "bus", "motorcycle"} <= set(detector.class_names)
    assert detector.conf_threshold == 0.35
    assert detector.input_size == (416, 416)
    # A region as a square letterbox would scale it, padded to a multiple of 32 only.
    assert detector.region_input_size(720, 1280) == (256, 416)
    assert detector.region_input_size(720, 1280, 1.5) == (1088, 1920)
    # The whole frame of an unknown camera: a pyramid from 1.5 (a 20 px vehicle becomes 30 px;
    # a 4K frame within the pixel cap) halved while above the model's size by sqrt(2), then
    # the model's size. A 320x240 frame is magnified by the model's size already.
    assert detector.pyramid_input_sizes(240, 320) == [(320, 416)]
    assert detector.pyramid_input_sizes(720, 1280) == [(1088, 1920), (544, 960), (256, 416)]
    assert detector.pyramid_input_sizes(1080, 1920) == [
        (1632, 2880),
        (832, 1440),
        (416, 736),
        (256, 416),
    ]
    assert detector.pyramid_input_sizes(2160, 3840) == [
        (1728, 3072),
        (864, 1536),
        (448, 768),
        (256, 416),
    ]
    assert detector.detect(np.full((240, 320, 3), 120, np.uint8)) == []


@pytest.mark.parametrize(
    ("frame_hw", "roi", "inputs"),
    [
        # An unknown camera's frame: the pyramid, largest first.
        ((720, 1280), None, [(1088, 1920), (544, 960), (256, 416)]),
        # A small frame is magnified to the model's size: one size, one pass.
        ((240, 320), None, [(320, 416)]),
        # A region of interest from the road (or --roi): one pass, as the letterbox scales it.
        ((720, 1280), (0, 0, 1280, 720), [(256, 416)]),
    ],
)
def test_the_whole_frame_of_an_unknown_camera_is_run_as_a_pyramid(
    frame_hw: tuple[int, int],
    roi: tuple[int, int, int, int] | None,
    inputs: list[tuple[int, int]],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    detector = YoloOnnxDetector(DEFAULT_MODEL_PATH, threads=1)
    detector.set_regions(roi, ())
    seen: list[tuple[int, int]] = []
    run = detector._run

    def recording(tensor: np.ndarray) -> list[np.ndarray]:
        seen.append((tensor.shape[2], tensor.shape[3]))
        return run(tensor)

    monkeypatch.setattr(detector, "_run", recording)
    detector.detect(np.full((*frame_hw, 3), 120, np.uint8))
    assert seen == inputs


def test_a_middle_pyramid_level_keeps_only_the_vehicles_it_sees_large(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each level decodes a 16 px and a 48 px box (in its input), apart from the other levels'
    boxes, their score naming level and size: the top (small vehicles) and the model's own size
    keep both; the middle level, there for vehicles of middle size, drops the 16 px one (seen
    twice as large by the level above)."""
    detector = YoloOnnxDetector(DEFAULT_MODEL_PATH, threads=1)
    sizes = detector.pyramid_input_sizes(720, 1280)
    assert len(sizes) == 3

    def decode(outputs: list[np.ndarray], input_hw: tuple[int, int]) -> tuple:  # type: ignore[type-arg]
        level = sizes.index(input_hw)
        x = input_hw[1] * (level + 1) / 4.0  # a quarter, half, three quarters of the frame
        boxes = np.array([[x, 0.0, x + 16.0, 16.0], [x, 50.0, x + 48.0, 98.0]], np.float32)
        scores = np.array([0.5 + 0.1 * level, 0.55 + 0.1 * level], np.float32)
        return boxes, scores, np.array([2, 2], np.intp)

    monkeypatch.setattr(detector, "_decode", decode)
    found = detector.detect(np.full((720, 1280, 3), 120, np.uint8))
    assert sorted(round(d.score, 2) for d in found) == [0.5, 0.55, 0.65, 0.7, 0.75]
