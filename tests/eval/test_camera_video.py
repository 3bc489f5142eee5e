"""``wz eval-camera --video --truth``: the camera detector scored against box or mask truth.

A fixed-output ONNX model (the same three boxes on every frame: car A, truck C, car E at the
frame's top right) makes every outcome known in advance: the truth is drawn around them.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import onnx
import pytest

from tests.camera_detector.test_contrast import clear_scene, fogged
from tests.camera_detector.test_yolo import _fixed_output_model, _hand_made_output
from wz_eval.camera import main
from wz_eval.camera_video import FrameScore, _bin_of, markdown, summarise

A = (160.0, 100.0, 240.0, 140.0)  # car, 40 px tall (1280x720 frames)
C = (500.0, 300.0, 700.0, 420.0)  # truck, 120 px tall
E = (1220.0, 0.0, 1280.0, 40.0)  # car, 40 px tall


@pytest.fixture
def model(tmp_path: Path) -> Path:
    path = _fixed_output_model(tmp_path / "fixed.onnx", _hand_made_output())
    proto = onnx.load(str(path))
    proto.metadata_props.add(key="wz_class_names", value="car,truck")
    onnx.save(proto, str(path))
    return path


def _video(path: Path, frames: int) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (1280, 720))
    assert writer.isOpened()
    for _ in range(frames):
        writer.write(np.full((720, 1280, 3), 100, dtype=np.uint8))
    writer.release()
    return path


def _mot(box: tuple[float, ...], frame: int, conf: int = 1) -> str:
    x1, y1, x2, y2 = box
    return f"{frame},-1,{x1},{y1},{x2 - x1},{y2 - y1},{conf},-1,-1,-1"


def test_box_truth_counts_found_missed_false_and_ignored(tmp_path: Path, model: Path) -> None:
    truth = tmp_path / "gt.txt"
    truth.write_text(
        "\n".join(
            [
                # Frame 1: A found; a missed van; C false; E inside a region marked ignore (conf 0).
                _mot(A, 1),
                _mot((800.0, 500.0, 900.0, 560.0), 1),
                _mot((1200.0, 0.0, 1280.0, 50.0), 1, conf=0),
                # Frame 2: A and C found; a vehicle 15 px tall missed but too small to count;
                # E in the ignored region again.
                _mot(A, 2),
                _mot((505.0, 305.0, 700.0, 420.0), 2),
                _mot((300.0, 600.0, 320.0, 615.0), 2),
                _mot((1200.0, 0.0, 1280.0, 50.0), 2, conf=0),
                # Frame 4 has truth but the video has 3 frames; frame 3 has none: not scored.
                _mot(A, 4),
            ]
        )
        + "\n",
        encoding="utf-8",
    )
    out = tmp_path / "out"
    video = _video(tmp_path / "clip.avi", 3)
    argv = ["--model", str(model), "--video", str(video), "--truth", str(truth)]
    assert main([*argv, "--out", str(out)]) == 0
    summary = json.loads((out / "video-eval.json").read_text(encoding="utf-8"))
    assert (summary["frames"], summary["vehicles"]) == (2, 4)
    assert (summary["found"], summary["missed"], summary["false"]) == (3, 1, 1)
    assert summary["recall"] == 0.75 and summary["precision"] == 0.75
    assert summary["by_height_px"]["40-80"] == {
        "vehicles": 3,
        "recall": pytest.approx(2 / 3, abs=1e-4),
        "detections": 2,
        "precision": 1.0,
    }
    # The worst frame drawn: frame 1, one miss and one false box.
    assert [p.name for p in out.glob("*.jpg")] == ["frame-000001-2-errors.jpg"]


def test_mask_truth_parts_merged_blobs_ignores_unknown_pixels(tmp_path: Path, model: Path) -> None:
    images, masks = tmp_path / "input", tmp_path / "groundtruth"
    images.mkdir()
    masks.mkdir()
    for number in (1, 2, 3):
        cv2.imwrite(str(images / f"in{number:06d}.jpg"), np.zeros((720, 1280, 3), np.uint8))
        mask = np.zeros((720, 1280), np.uint8)
        mask[95:145, 150:330] = 255  # A and a car beside it, touching: one blob
        mask[300:420, 500:700] = 50  # C on a shadow: not a vehicle
        mask[0:40, 1215:1280] = 170  # E on unknown pixels: not scored
        cv2.imwrite(str(masks / f"gt{number:06d}.png"), mask)
    (tmp_path / "temporalROI.txt").write_text("2 3\n", encoding="utf-8")
    out = tmp_path / "out"
    argv = ["--model", str(model), "--video", str(images), "--truth", str(masks)]
    assert main([*argv, "--out", str(out), "--pictures", "0"]) == 0
    summary = json.loads((out / "video-eval.json").read_text(encoding="utf-8"))
    # Frames 2-3 only: the blob found through A (70 % inside it), C false, E not scored.
    assert (summary["frames"], summary["found"], summary["missed"]) == (2, 2, 0)
    assert (summary["false"], summary["in_blob"]) == (2, 0)
    assert not list(out.glob("*.jpg"))


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--truth", "{missing}"], "no such file or folder"),
        (["--truth", "{bad}"], "not a MOT line"),
        ([], "--video needs --truth"),
    ],
)
def test_bad_truth_is_a_clear_error(
    tmp_path: Path,
    model: Path,
    arguments: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bad = tmp_path / "bad.txt"
    bad.write_text("1,-1,10,10,x,20\n", encoding="utf-8")
    video = _video(tmp_path / "clip.avi", 1)
    filled = [a.format(missing=tmp_path / "none.txt", bad=bad) for a in arguments]
    argv = ["--model", str(model), "--video", str(video), *filled, "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("height_px", "name"),
    [
        (15.0, "<20"),
        (20.0, "20-40"),
        (39.0, "20-40"),
        (40.0, "40-80"),
        (159.0, "80-160"),
        (160.0, "160+"),
    ],
)
def test_a_box_falls_in_the_bin_of_its_height(height_px: float, name: str) -> None:
    """Each bin from its lower edge up to the next; below the first edge its own bin (a box
    under 20 px is not in the open top bin)."""
    assert _bin_of(height_px) == name


def test_the_summary_and_its_table_give_the_bins_lowest_first() -> None:
    def box(height_px: float) -> npt.NDArray[np.float64]:
        return np.array([0.0, 100.0, 30.0, 100.0 + height_px])

    frame = FrameScore(
        found=[(box(200.0), box(190.0))],
        missed=[box(15.0), box(50.0)],
        false=[box(100.0), box(25.0)],
    )
    summary = summarise([frame])
    assert list(summary["by_height_px"]) == ["<20", "20-40", "40-80", "80-160", "160+"]
    assert summary["by_height_px"]["<20"] == {
        "vehicles": 1,
        "recall": 0.0,
        "detections": 0,
        "precision": None,
    }
    assert summary["by_height_px"]["160+"] == {
        "vehicles": 1,
        "recall": 1.0,
        "detections": 1,
        "precision": 1.0,
    }
    lines = markdown(summary, "t").splitlines()
    rows = [line.split(" | ")[0] for line in lines[lines.index("|---|---|---|---|---|") + 1 :]]
    assert rows == ["| <20", "| 20-40", "| 40-80", "| 80-160", "| 160+"]


def test_recall_is_split_between_vehicles_inside_the_frame_and_those_its_edge_cuts() -> None:
    frame = FrameScore(
        found=[
            (np.array([0.0, 50.0, 40.0, 90.0]), np.array([1.0, 50.0, 40.0, 90.0])),  # left edge
            (np.array([100.0, 50.0, 140.0, 90.0]), np.array([100.0, 50.0, 140.0, 90.0])),
        ],
        missed=[np.array([280.0, 200.0, 319.0, 240.0]), np.array([150.0, 60.0, 190.0, 100.0])],
        size=(320, 240),
    )
    summary = summarise([frame])
    assert summary["vehicles_inside_frame"] == 2 and summary["recall_inside_frame"] == 0.5
    assert summary["vehicles_cut_by_edge"] == 2 and summary["recall_cut_by_edge"] == 0.5
    assert "cut by the frame's edge: 2, recall 0.5" in markdown(summary, "t")


def test_tracked_scores_what_the_node_publishes(tmp_path: Path, model: Path) -> None:
    """``--tracked``: every frame through the node's steps at the clip's rate (10 fps: the
    detector on each frame); a track is published from its third detection, so A, found on
    each of five frames by the detector alone, is published on the last three."""
    truth = tmp_path / "gt.txt"
    truth.write_text("\n".join(_mot(A, frame) for frame in range(1, 6)) + "\n", encoding="utf-8")
    out = tmp_path / "out"
    video = _video(tmp_path / "clip.avi", 5)
    argv = ["--model", str(model), "--video", str(video), "--truth", str(truth), "--tracked"]
    assert main([*argv, "--out", str(out), "--pictures", "0"]) == 0
    summary = json.loads((out / "video-eval.json").read_text(encoding="utf-8"))
    assert (summary["found"], summary["missed"]) == (5, 0)
    published = summary["published"]
    assert published["tracked"] == {"fps": 10.0, "detector_runs": 5}
    assert (published["found"], published["missed"]) == (3, 2)
    assert "What the node publishes" in (out / "video-eval.md").read_text(encoding="utf-8")


def test_the_real_camera_models_fog_step_is_counted_in_the_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The shipped real-camera model (no ``--model``) on fogged frames: each is flat and gets
    local contrast, and the report says how many; ``WZ_CAMERA_FOG_CONTRAST=off`` turns it off."""
    frames, labels = tmp_path / "frames", tmp_path / "labels"
    frames.mkdir()
    labels.mkdir()
    for index in range(3):
        cv2.imwrite(str(frames / f"{index:04d}.png"), fogged(clear_scene(seed=index), 0.25))
        (labels / f"{index:04d}.txt").write_text("", encoding="utf-8")
    argv = ["--video", str(frames), "--truth", str(labels), "--pictures", "0"]
    assert main([*argv, "--out", str(tmp_path / "on")]) == 0
    summary = json.loads((tmp_path / "on" / "video-eval.json").read_text(encoding="utf-8"))
    assert summary["frames"] == 3
    assert summary["fog_step"] == {"flat_below": 0.06, "flat_frames": 3}
    report = (tmp_path / "on" / "video-eval.md").read_text(encoding="utf-8")
    assert "Fog step: 3 of 3 frames flat" in report
    monkeypatch.setenv("WZ_CAMERA_FOG_CONTRAST", "off")
    assert main([*argv, "--out", str(tmp_path / "off")]) == 0
    summary = json.loads((tmp_path / "off" / "video-eval.json").read_text(encoding="utf-8"))
    assert "fog_step" not in summary
