"""ROI crops of the training data: labels re-expressed in the crop, by hand-computed cases."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from wz_camera_detector.train_data import Roi, crop_label_lines, prepare_roi_dataset


def _line(cls: int, x0: float, y0: float, x1: float, y1: float, w: int, h: int) -> str:
    return f"{cls} {(x0 + x1) / 2 / w} {(y0 + y1) / 2 / h} {(x1 - x0) / w} {(y1 - y0) / h}"


def _box(line: str, w: int, h: int) -> tuple[int, list[float]]:
    cls, cx, cy, bw, bh = line.split()
    fx, fy, fw, fh = float(cx) * w, float(cy) * h, float(bw) * w, float(bh) * h
    return int(cls), [fx - fw / 2, fy - fh / 2, fx + fw / 2, fy + fh / 2]


def test_box_inside_the_roi_moves_by_the_roi_origin() -> None:
    roi = Roi(400, 400, 1200, 1200)
    lines = [_line(1, 500, 600, 700, 650, 1200, 1200)]
    (out,) = crop_label_lines(lines, (1200, 1200), roi)
    cls, box = _box(out, 800, 800)
    assert cls == 1
    assert box == pytest.approx([100, 200, 300, 250], abs=1e-3)


def test_box_mostly_outside_is_dropped_and_half_inside_is_clipped() -> None:
    roi = Roi(400, 400, 1200, 1200)
    mostly_out = _line(0, 300, 500, 420, 540, 1200, 1200)  # 20 of 120 px wide inside
    half_in = _line(0, 370, 500, 450, 540, 1200, 1200)  # 50 of 80 px inside: kept
    tiny = _line(0, 600, 600, 602, 640, 1200, 1200)  # 2 px wide
    out = crop_label_lines([mostly_out, half_in, tiny, ""], (1200, 1200), roi)
    assert len(out) == 1
    assert _box(out[0], 800, 800)[1] == pytest.approx([0, 100, 50, 140], abs=1e-3)


def test_malformed_label_line_is_an_error() -> None:
    with pytest.raises(ValueError, match="5 fields"):
        crop_label_lines(["0 0.5 0.5 0.1"], (100, 100), Roi(0, 0, 50, 50))


def test_roi_parse_and_validation() -> None:
    assert Roi.parse("480, 440,1200,1160").as_tuple() == (480, 440, 1200, 1160)
    with pytest.raises(ValueError, match="x0,y0,x1,y1"):
        Roi.parse("1,2,3")
    with pytest.raises(ValueError, match="empty"):
        Roi(10, 0, 10, 5)


def _fake_dataset(root: Path, prefix: str) -> None:
    for split in ("train", "val"):
        for folder in ("images", "labels", "truth"):
            (root / folder / split).mkdir(parents=True)
        image = np.full((120, 160, 3), 90, dtype=np.uint8)
        image[60:80, 100:140] = 250
        cv2.imwrite(str(root / "images" / split / f"{prefix}-{split}.jpg"), image)
        (root / "labels" / split / f"{prefix}-{split}.txt").write_text(
            _line(0, 100, 60, 140, 80, 160, 120) + "\n"
        )
        (root / "truth" / split / f"{prefix}-{split}.json").write_text(json.dumps({"vehicles": []}))
    (root / "data.yaml").write_text(
        "path: x\ntrain: images/train\nval: images/val\nnames:\n  0: car\n  1: truck\n"
    )
    (root / "manifest.json").write_text(json.dumps({"seed": prefix}))


def test_prepare_merges_sources_crops_images_and_keeps_truth(tmp_path: Path) -> None:
    _fake_dataset(tmp_path / "a", "a")
    _fake_dataset(tmp_path / "b", "b")
    roi = Roi(80, 40, 160, 120)
    counts = prepare_roi_dataset([tmp_path / "a", tmp_path / "b"], tmp_path / "out", roi)

    assert counts == {"images_train": 2, "labels_train": 2, "images_val": 2, "labels_val": 2}
    crop = cv2.imread(str(tmp_path / "out" / "images" / "val" / "b-val.jpg"))
    assert crop.shape == (80, 80, 3)
    label = (tmp_path / "out" / "labels" / "val" / "b-val.txt").read_text().strip()
    assert _box(label, 80, 80)[1] == pytest.approx([20, 20, 60, 40], abs=1e-3)
    assert (tmp_path / "out" / "truth" / "train" / "a-train.json").exists()
    data_yaml = (tmp_path / "out" / "data.yaml").read_text()
    assert "names:\n  0: car\n  1: truck\n" in data_yaml
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert manifest["roi_xyxy_px"] == [80, 40, 160, 120]
    assert [m["seed"] for m in manifest["sources"]] == ["a", "b"]


def test_prepare_refuses_a_roi_larger_than_the_frames(tmp_path: Path) -> None:
    _fake_dataset(tmp_path / "a", "a")
    with pytest.raises(ValueError, match="exceeds 160x120"):
        prepare_roi_dataset([tmp_path / "a"], tmp_path / "out", Roi(0, 0, 200, 100))
