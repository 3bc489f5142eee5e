"""YOLOv8 ONNX detector: letterbox, decode and NMS against hand-computed values, end to end on a
tiny ONNX model built here, and clear start-up errors for bad models."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import numpy.typing as npt
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from tests.purity import top_level_imports
from wz_camera_detector import yolo
from wz_camera_detector.yolo import (
    ImageDetection,
    Letterbox,
    ModelLoadError,
    YoloOnnxDetector,
    box_iou,
    decode,
    letterbox,
    nms,
)

CLASS_NAMES = ("car", "truck")


def test_core_imports_no_bus_or_web_library() -> None:
    assert top_level_imports(yolo).isdisjoint({"zenoh", "fastapi", "uvicorn", "requests"})


# ----------------------------------------------------------------------------- letterbox


def test_letterbox_landscape_frame_is_scaled_and_padded_top_and_bottom() -> None:
    image = np.zeros((720, 1280, 3), dtype=np.uint8)
    tensor, transform = letterbox(image, (640, 640))

    # r = min(640 / 720, 640 / 1280) = 0.5; 1280x720 -> 640x360; (640 - 360) / 2 = 140.
    assert transform == Letterbox(
        scale=0.5, pad_x=0, pad_y=140, image_width_px=1280, image_height_px=720
    )
    assert tensor.shape == (1, 3, 640, 640)
    assert tensor.dtype == np.float32
    assert tensor.flags.c_contiguous
    gray = np.float32(114 / 255)
    np.testing.assert_array_equal(tensor[0, :, :140, :], gray)
    np.testing.assert_array_equal(tensor[0, :, 500:, :], gray)
    np.testing.assert_array_equal(tensor[0, :, 140:500, :], 0.0)


def test_letterbox_portrait_frame_is_padded_left_and_right() -> None:
    image = np.zeros((640, 480, 3), dtype=np.uint8)
    _, transform = letterbox(image, (640, 640))
    assert (transform.scale, transform.pad_x, transform.pad_y) == (1.0, 80, 0)


def test_letterbox_point_maps_back_exactly() -> None:
    image = np.zeros((720, 1280, 3), dtype=np.uint8)
    _, transform = letterbox(image, (640, 640))
    u_image, v_image = 777.0, 333.0
    # u_input = 0.5 u + 0, v_input = 0.5 v + 140.
    u_input, v_input = 388.5, 306.5
    mapped = transform.to_image([[u_input, v_input, u_input, v_input]])
    np.testing.assert_array_equal(mapped, [[u_image, v_image, u_image, v_image]])


def test_letterbox_to_image_clips_to_the_frame() -> None:
    transform = Letterbox(scale=0.5, pad_x=0, pad_y=140, image_width_px=1280, image_height_px=720)
    mapped = transform.to_image([[-10.0, 100.0, 650.0, 600.0]])
    np.testing.assert_array_equal(mapped, [[0.0, 0.0, 1280.0, 720.0]])


def test_letterbox_converts_bgr_to_rgb_in_unit_range() -> None:
    image = np.zeros((4, 4, 3), dtype=np.uint8)
    image[:, :] = (255, 0, 51)  # BGR: blue 255, red 51
    tensor, _ = letterbox(image, (4, 4))
    np.testing.assert_allclose(tensor[0, 0], 0.2)  # R
    np.testing.assert_array_equal(tensor[0, 1], 0.0)  # G
    np.testing.assert_array_equal(tensor[0, 2], 1.0)  # B


def test_letterbox_refuses_a_non_bgr_frame() -> None:
    with pytest.raises(ValueError, match="BGR uint8"):
        letterbox(np.zeros((4, 4), dtype=np.uint8), (4, 4))


# ----------------------------------------------------------------------------- decode


def test_decode_converts_centre_size_to_corners_and_drops_low_scores() -> None:
    # Three candidates (columns), two classes: rows cx, cy, w, h, score(car), score(truck).
    output = np.array(
        [
            [
                [100.0, 300.0, 50.0],
                [200.0, 320.0, 50.0],
                [40.0, 100.0, 10.0],
                [20.0, 60.0, 10.0],
                [0.9, 0.2, 0.1],
                [0.1, 0.7, 0.2],
            ]
        ],
        dtype=np.float32,
    )
    boxes, scores, class_ids = decode(output, conf_threshold=0.25)
    np.testing.assert_array_equal(
        boxes, [[80.0, 190.0, 120.0, 210.0], [250.0, 290.0, 350.0, 350.0]]
    )
    np.testing.assert_allclose(scores, [0.9, 0.7], rtol=1e-6)
    np.testing.assert_array_equal(class_ids, [0, 1])


def test_decode_of_an_empty_output_gives_empty_arrays() -> None:
    boxes, scores, class_ids = decode(np.zeros((1, 6, 0), dtype=np.float32), 0.25)
    assert boxes.shape == (0, 4)
    assert scores.shape == class_ids.shape == (0,)


def test_decode_refuses_a_wrong_shape() -> None:
    with pytest.raises(ValueError, match=r"\(1, 4 \+ C, N\)"):
        decode(np.zeros((6, 10), dtype=np.float32), 0.25)


# ----------------------------------------------------------------------------- NMS


def test_box_iou_hand_computed() -> None:
    # Intersection 80, union 100 + 80 - 80 = 100.
    np.testing.assert_allclose(
        box_iou([0, 0, 10, 10], [[0, 0, 10, 8], [20, 20, 30, 30]]), [0.8, 0.0]
    )


def test_nms_overlap_0_8_keeps_only_the_best() -> None:
    boxes = [[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 8.0]]  # IoU 0.8
    np.testing.assert_array_equal(nms(boxes, [0.6, 0.9], iou_threshold=0.5), [1])


def test_nms_overlap_0_3_keeps_both_by_score() -> None:
    boxes = [[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 3.0]]  # intersection 30, union 100
    assert box_iou(boxes[0], [boxes[1]])[0] == pytest.approx(0.3)
    np.testing.assert_array_equal(nms(boxes, [0.6, 0.9], iou_threshold=0.5), [1, 0])


def test_nms_never_suppresses_across_classes() -> None:
    boxes = [[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 8.0]]  # IoU 0.8
    kept = nms(boxes, [0.6, 0.9], iou_threshold=0.5, class_ids=[0, 1])
    np.testing.assert_array_equal(kept, [1, 0])


def test_nms_of_nothing_is_nothing() -> None:
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).shape == (0,)


def test_nms_invariants_on_random_boxes() -> None:
    """Kept boxes of a class never overlap above the threshold; every dropped box overlaps a
    better kept box of its class above it; kept indices come by decreasing score."""
    rng = np.random.default_rng(20240611)
    for _ in range(50):
        count = int(rng.integers(1, 40))
        corners = rng.uniform(0.0, 100.0, size=(count, 2))
        sizes = rng.uniform(1.0, 30.0, size=(count, 2))
        boxes = np.hstack([corners, corners + sizes])
        scores = rng.uniform(0.0, 1.0, size=count)
        class_ids = rng.integers(0, 3, size=count)
        threshold = 0.45
        kept = nms(boxes, scores, threshold, class_ids)

        assert np.all(np.diff(scores[kept]) <= 0.0)
        for position, index in enumerate(kept):
            others = kept[position + 1 :]
            same_class = others[class_ids[others] == class_ids[index]]
            assert np.all(box_iou(boxes[index], boxes[same_class]) <= threshold)
        for dropped in sorted(set(range(count)) - set(kept.tolist())):
            rivals = kept[
                (class_ids[kept] == class_ids[dropped]) & (scores[kept] >= scores[dropped])
            ]
            assert np.any(box_iou(boxes[dropped], boxes[rivals]) > threshold)


# ----------------------------------------------------------------------------- detector


def _fixed_output_model(
    path: Path,
    output: npt.NDArray[np.float32],
    input_shape: tuple[int | str, ...] = (1, 3, 640, 640),
) -> Path:
    """A model that ignores its image and always outputs ``output``: ``output + 0 * mean(x)``
    (the input must feed the graph, or ONNX Runtime would prune it)."""
    nodes = [
        helper.make_node("ReduceMean", ["images"], ["image_mean"], keepdims=0),
        helper.make_node("Mul", ["image_mean", "zero"], ["nothing"]),
        helper.make_node("Add", ["fixed_output", "nothing"], ["output0"]),
    ]
    graph = helper.make_graph(
        nodes,
        "fixed_yolo",
        inputs=[helper.make_tensor_value_info("images", TensorProto.FLOAT, list(input_shape))],
        outputs=[helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(output.shape))],
        initializer=[
            numpy_helper.from_array(np.float32(0.0).reshape(()), "zero"),
            numpy_helper.from_array(output.astype(np.float32), "fixed_output"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _hand_made_output() -> npt.NDArray[np.float32]:
    # Columns (candidates) in the 640x640 letterboxed input; rows cx, cy, w, h, car, truck.
    candidates = [
        (100.0, 200.0, 40.0, 20.0, 0.9, 0.05),  # A: car, kept
        (101.0, 200.0, 40.0, 20.0, 0.6, 0.05),  # B: IoU 780 / 820 with A -> suppressed
        (300.0, 320.0, 100.0, 60.0, 0.1, 0.7),  # C: truck, kept
        (400.0, 400.0, 50.0, 50.0, 0.1, 0.2),  # D: below conf 0.25 -> dropped
        (630.0, 150.0, 40.0, 20.0, 0.5, 0.0),  # E: car past the right edge -> clipped
    ]
    return np.array(candidates, dtype=np.float32).T[np.newaxis]


def test_detector_end_to_end_returns_boxes_in_original_pixels(tmp_path: Path) -> None:
    model_path = _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output())
    detector = YoloOnnxDetector(model_path, CLASS_NAMES)
    assert detector.input_size == (640, 640)
    frame = np.random.default_rng(7).integers(0, 256, size=(720, 1280, 3), dtype=np.uint8)

    detections, timings = detector.detect_with_timings(frame)

    # 1280x720 -> scale 0.5, pad_y 140: u = (x - 0) / 0.5, v = (y - 140) / 0.5, then clipped.
    assert detections == [
        ImageDetection((160.0, 100.0, 240.0, 140.0), pytest.approx(0.9), "car"),
        ImageDetection((500.0, 300.0, 700.0, 420.0), pytest.approx(0.7), "truck"),
        ImageDetection((1220.0, 0.0, 1280.0, 40.0), pytest.approx(0.5), "car"),
    ]
    assert min(timings.preprocess_s, timings.inference_s, timings.postprocess_s) >= 0.0
    assert timings.total_s == pytest.approx(
        timings.preprocess_s + timings.inference_s + timings.postprocess_s
    )
    assert detector.detect(frame) == detections


def test_detector_thresholds_and_max_detections(tmp_path: Path) -> None:
    model_path = _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output())
    frame = np.zeros((720, 1280, 3), dtype=np.uint8)
    strict = YoloOnnxDetector(model_path, CLASS_NAMES, conf_threshold=0.65)
    assert [d.score for d in strict.detect(frame)] == pytest.approx([0.9, 0.7])
    loose_iou = YoloOnnxDetector(model_path, CLASS_NAMES, iou_threshold=0.99)
    assert len(loose_iou.detect(frame)) == 4  # B survives
    capped = YoloOnnxDetector(model_path, CLASS_NAMES, max_detections=1)
    assert [d.class_name for d in capped.detect(frame)] == ["car"]


def test_detector_with_dynamic_input_needs_and_uses_input_size(tmp_path: Path) -> None:
    model_path = _fixed_output_model(
        tmp_path / "dynamic.onnx", _hand_made_output(), input_shape=(1, 3, "height", "width")
    )
    with pytest.raises(ModelLoadError, match="dynamic"):
        YoloOnnxDetector(model_path, CLASS_NAMES)
    detector = YoloOnnxDetector(model_path, CLASS_NAMES, input_size=(640, 640))
    assert len(detector.detect(np.zeros((720, 1280, 3), dtype=np.uint8))) == 3


def test_detector_refuses_an_input_size_the_model_does_not_take(tmp_path: Path) -> None:
    model_path = _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output())
    with pytest.raises(ModelLoadError, match="input_size"):
        YoloOnnxDetector(model_path, CLASS_NAMES, input_size=(480, 640))


@pytest.fixture
def no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any connection attempt fails the test: a bad model must never trigger a download."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the detector tried to open a network connection")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)


@pytest.mark.usefixtures("no_network")
def test_missing_model_is_a_clear_error_naming_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "models" / "yolov8n.onnx"
    with pytest.raises(ModelLoadError, match="no such file") as error:
        YoloOnnxDetector(missing, CLASS_NAMES)
    assert str(missing) in str(error.value)
    assert not missing.exists()


@pytest.mark.usefixtures("no_network")
def test_garbage_model_is_a_clear_error_naming_the_file(tmp_path: Path) -> None:
    garbage = tmp_path / "yolov8n.onnx"
    garbage.write_bytes(b"this is not an ONNX protobuf \x00\xff\x13")
    with pytest.raises(ModelLoadError, match="cannot be loaded as an ONNX model") as error:
        YoloOnnxDetector(garbage, CLASS_NAMES)
    assert str(garbage) in str(error.value)


@pytest.mark.usefixtures("no_network")
def test_model_with_the_wrong_class_count_is_a_clear_error(tmp_path: Path) -> None:
    three_classes = np.zeros((1, 4 + 3, 5), dtype=np.float32)
    model_path = _fixed_output_model(tmp_path / "yolo3.onnx", three_classes)
    with pytest.raises(ModelLoadError, match="3 class scores per box but 2 class names") as error:
        YoloOnnxDetector(model_path, CLASS_NAMES)
    assert str(model_path) in str(error.value)


@pytest.mark.usefixtures("no_network")
def test_model_with_an_undeclared_wrong_class_count_is_caught_by_the_test_inference(
    tmp_path: Path,
) -> None:
    model_path = _fixed_output_model(tmp_path / "yolo3.onnx", np.zeros((1, 7, 5), np.float32))
    model = onnx.load(str(model_path))
    output_dims = model.graph.output[0].type.tensor_type.shape.dim
    output_dims[1].dim_param = "rows"  # symbolic: only a run reveals the class count
    onnx.save(model, str(model_path))
    with pytest.raises(ModelLoadError, match="3 class scores per box but 2 class names"):
        YoloOnnxDetector(model_path, CLASS_NAMES)


# ----------------------------------------------------------------------------- model metadata, ROI


def _with_metadata(path: Path, **props: str) -> Path:
    model = onnx.load(str(path))
    for key, value in props.items():
        model.metadata_props.add(key=key, value=value)
    onnx.save(model, str(path))
    return path


def test_class_names_and_roi_come_from_the_model_metadata(tmp_path: Path) -> None:
    model_path = _with_metadata(
        _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output()),
        wz_class_names="car,truck",
        wz_roi_xyxy_px="100,200,740,840",
    )
    detector = YoloOnnxDetector(model_path)
    assert detector.class_names == ("car", "truck")
    assert detector.roi_xyxy_px == (100, 200, 740, 840)

    detections = detector.detect(np.zeros((1000, 1000, 3), dtype=np.uint8))

    # The 640x640 ROI is the input at scale 1, no padding: frame = input + (100, 200).
    assert detections[0] == ImageDetection((180.0, 390.0, 220.0, 410.0), pytest.approx(0.9), "car")
    assert detections[1].box_xyxy_px == (350.0, 490.0, 450.0, 550.0)
    # E (610..650 in the input) is clipped to the ROI's right edge, 740 in the frame.
    assert detections[2].box_xyxy_px == (710.0, 340.0, 740.0, 360.0)


def test_explicit_roi_and_names_override_the_metadata(tmp_path: Path) -> None:
    model_path = _with_metadata(
        _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output()),
        wz_class_names="car,truck",
        wz_roi_xyxy_px="100,200,740,840",
    )
    detector = YoloOnnxDetector(model_path, ("auto", "lorry"), roi_xyxy_px=(0, 0, 1280, 720))
    assert detector.class_names == ("auto", "lorry")
    frame = np.zeros((720, 1280, 3), dtype=np.uint8)
    assert detector.detect(frame)[0].box_xyxy_px == (160.0, 100.0, 240.0, 140.0)


def test_ultralytics_names_metadata_is_read(tmp_path: Path) -> None:
    model_path = _with_metadata(
        _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output()),
        names="{0: 'car', 1: 'truck'}",
    )
    assert YoloOnnxDetector(model_path).class_names == ("car", "truck")


def test_a_model_without_names_needs_them_given(tmp_path: Path) -> None:
    model_path = _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output())
    with pytest.raises(ModelLoadError, match="no class names"):
        YoloOnnxDetector(model_path)


def test_a_frame_smaller_than_the_roi_or_not_bgr_is_refused(tmp_path: Path) -> None:
    model_path = _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output())
    detector = YoloOnnxDetector(model_path, CLASS_NAMES, roi_xyxy_px=(100, 200, 740, 840))
    with pytest.raises(ValueError, match="does not contain the detector's ROI"):
        detector.detect(np.zeros((800, 1000, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        detector.detect(np.zeros((1000, 1000), dtype=np.uint8))
    with pytest.raises(ValueError, match="empty"):
        YoloOnnxDetector(model_path, CLASS_NAMES, roi_xyxy_px=(10, 10, 10, 20))


def test_far_field_tile_adds_magnified_detections_and_drops_cut_ones(tmp_path: Path) -> None:
    model_path = _with_metadata(
        _fixed_output_model(tmp_path / "yolo.onnx", _hand_made_output()),
        wz_class_names="car,truck",
        wz_roi_xyxy_px="0,0,640,640",
        wz_tiles_xyxy_px="600,600,760,760",
    )
    detector = YoloOnnxDetector(model_path)
    assert detector.tiles_xyxy_px == ((600, 600, 760, 760),)
    boxes = {d.box_xyxy_px for d in detector.detect(np.zeros((1000, 1000, 3), dtype=np.uint8))}
    # The ROI gives A, C and E as without a tile; the 160 px tile is magnified 4x into the
    # input, so A and C come again at a quarter size, shifted by (600, 600); the tile's E
    # touches the tile's right edge (a cut vehicle) and is dropped.
    assert boxes == {
        (80.0, 190.0, 120.0, 210.0),
        (250.0, 290.0, 350.0, 350.0),
        (610.0, 140.0, 640.0, 160.0),
        (620.0, 647.5, 630.0, 652.5),
        (662.5, 672.5, 687.5, 687.5),
    }
    with pytest.raises(ValueError, match="tile"):
        YoloOnnxDetector(model_path, tiles_xyxy_px=[(10, 10, 5, 20)])
