"""``wz detect-camera`` on real image and video files, with a tiny fixed-output ONNX model."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import onnx
import pytest

from tests.camera_detector.test_yolo import _fixed_output_model, _hand_made_output
from wz_camera_detector.cli import main
from wz_shared.site import DEFAULT_SITE_PATH


@pytest.fixture
def model(tmp_path: Path) -> Path:
    path = _fixed_output_model(tmp_path / "fixed.onnx", _hand_made_output())
    proto = onnx.load(str(path))
    proto.metadata_props.add(key="wz_class_names", value="car,truck")
    proto.metadata_props.add(key="wz_roi_xyxy_px", value="480,440,1200,1160")
    onnx.save(proto, str(path))
    return path


#: The region the fixed-output model's boxes were written for, given by hand (it overrides
#: the one the road's geometry gives), with no far-field tile.
HAND_ROI = ["--roi", "480,440,1200,1160", "--tiles", ""]


def _image(tmp_path: Path, name: str) -> Path:
    path = tmp_path / name
    image = np.random.default_rng(3).integers(0, 255, size=(1200, 1200, 3), dtype=np.uint8)
    assert cv2.imwrite(str(path), image)
    return path


def test_images_give_one_line_per_frame_with_boxes_and_world_positions(
    tmp_path: Path, model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = [_image(tmp_path, f"f{i}.jpg") for i in range(3)]
    arguments = ["--model", str(model), "--backend", "yolo", "--site", str(DEFAULT_SITE_PATH)]
    assert main([*arguments, *HAND_ROI, *map(str, files)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line["frame"] for line in lines] == [0, 1, 2]
    assert [line["stamp"] for line in lines] == pytest.approx([0.0, 0.1, 0.2])  # 10 Hz camera
    first = lines[0]["detections"]
    assert [d["class"] for d in first] == ["car", "truck", "car"]
    # The ROI is 720 px into a 640 input: scale 8/9, no padding; A's box starts at
    # (480 + 80 * 9/8, 440 + 190 * 9/8).
    assert first[0]["box"] == pytest.approx([570.0, 653.75, 615.0, 676.25], abs=0.06)
    for detection in first[:2]:
        assert not detection["cut"]
        assert all(math.isfinite(detection[k]) for k in ("x", "y", "paper_x", "paper_y"))
        assert 0.0 < detection["range"] < 60.0
    # E reaches the ROI's right edge: cut by the view, so not ranged (as in the node).
    assert first[2]["cut"] and first[2]["x"] is None
    # The tracker gives ids; the same boxes keep their ids. A 10 Hz camera: the detector runs
    # on every frame, and a track is published (what the node would publish) at its third.
    assert [d["track_id"] for d in lines[2]["detections"]] == [d["track_id"] for d in first]
    assert [[d["published"] for d in line["detections"]] for line in lines] == [
        [False, False, False],
        [False, False, False],
        [True, True, True],
    ]


def test_a_bad_file_is_a_line_with_the_error_and_exit_code_1(
    tmp_path: Path, model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(b"\xff\xd8\xff not really a jpeg")
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((100, 100, 3), dtype=np.uint8))
    good = _image(tmp_path, "good.jpg")
    code = main(
        [
            "--model",
            str(model),
            "--backend",
            "yolo",
            *HAND_ROI,
            str(broken),
            str(small),
            str(tmp_path / "missing.jpg"),
            str(good),
        ]
    )
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert code == 1
    assert "not a decodable image" in lines[0]["error"]
    assert "does not contain the detector's ROI" in lines[1]["error"]
    assert "no such file" in lines[2]["error"]
    assert lines[3]["file"] == str(good) and len(lines[3]["detections"]) == 3


def test_a_video_file_gives_its_frames_with_their_times(
    tmp_path: Path, model: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (1200, 1200))
    assert writer.isOpened()
    for _ in range(4):
        writer.write(np.full((1200, 1200, 3), 80, dtype=np.uint8))
    writer.release()
    assert main(["--model", str(model), "--backend", "yolo", "--no-track", str(video)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line["frame"] for line in lines] == [0, 1, 2, 3]
    assert [line["stamp"] for line in lines] == pytest.approx([0.0, 0.2, 0.4, 0.6])
    assert all(d["track_id"] is None for d in lines[0]["detections"])


def test_a_missing_model_is_a_start_up_error(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "wz_cli.main",
            "detect-camera",
            "--backend",
            "yolo",
            "--model",
            str(tmp_path / "none.onnx"),
            str(tmp_path / "x.jpg"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 2
    assert "no such file" in result.stderr and "never downloads" in result.stderr


@pytest.mark.parametrize(
    "arguments",
    [["--roi", "480,440,1200"], ["--roi", "10,10,5,20"], ["--tiles", "0,0,a,b"]],
)
def test_a_bad_roi_or_tile_is_a_start_up_error(
    tmp_path: Path, model: Path, arguments: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    image = _image(tmp_path, "f.jpg")
    assert main(["--model", str(model), *arguments, str(image)]) == 2
    assert "expected x0,y0,x1,y1" in capsys.readouterr().err


@pytest.mark.parametrize(("width", "height"), [(320, 240), (1280, 720), (1920, 1080)])
def test_any_resolution_runs_without_options(
    tmp_path: Path, width: int, height: int, capsys: pytest.CaptureFixture[str]
) -> None:
    """No site, no model, no ROI: the shipped COCO model on the whole frame of any camera."""
    video = tmp_path / f"clip-{width}x{height}.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (width, height))
    assert writer.isOpened()
    rng = np.random.default_rng(width)
    for _ in range(3):
        writer.write(rng.integers(90, 110, size=(height, width, 3), dtype=np.uint8))
    writer.release()
    assert main([str(video)]) == 0
    captured = capsys.readouterr()
    lines = [json.loads(line) for line in captured.out.splitlines()]
    assert [line["frame"] for line in lines] == [0, 1, 2]
    assert all((line["width"], line["height"]) == (width, height) for line in lines)
    assert all(line["detections"] == [] for line in lines)  # noise is not a vehicle
    assert "coco-nanodet-g-416-int8.onnx" in captured.err and "no --site" in captured.err


def test_a_frame_the_site_camera_cannot_have_taken_is_an_error_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    image = tmp_path / "wide.jpg"
    cv2.imwrite(str(image), np.zeros((240, 320, 3), np.uint8))  # the site's camera is square
    half = tmp_path / "half.jpg"
    cv2.imwrite(str(half), np.zeros((600, 600, 3), np.uint8))  # the same picture, scaled
    assert main(["--site", str(DEFAULT_SITE_PATH), str(image), str(half)]) == 1
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert "320x240 frame does not fit the calibration made at 1200x1200" in lines[0]["error"]
    assert lines[1]["width"] == 600 and "error" not in lines[1]
