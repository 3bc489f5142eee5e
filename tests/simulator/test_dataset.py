"""Dataset export and pictures: what `wz dataset` and `wz pictures` write, from real runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

from wz_shared.site import DEFAULT_SITE_PATH, load_site
from wz_simulator.dataset import YOLO_CLASSES, DatasetOptions, export

ROOT = Path(__file__).resolve().parents[2]


def test_export_writes_yolo_labels_and_lidar_boxes(tmp_path: Path) -> None:
    site = load_site(DEFAULT_SITE_PATH)
    options = DatasetOptions(
        out_dir=tmp_path / "ds",
        seed=3,
        weathers=("day", "fog"),
        duration_s=5.0,
        every_s=1.0,
        warmup_s=40.0,
        val_share=0.2,
    )
    manifest = export(site, options, work_dir=tmp_path / "work")
    out = options.out_dir
    assert manifest["counts"] == {
        "images_train": 8,
        "images_val": 2,
        "lidar_train": 8,
        "lidar_val": 2,
    }
    data = yaml.safe_load((out / "data.yaml").read_text())
    assert data["names"] == {i: cls.value for i, cls in enumerate(YOLO_CLASSES)}
    assert (Path(data["path"]) / data["train"]).is_dir()
    labelled = 0
    for image_path in sorted((out / "images").rglob("*.jpg")):
        split = image_path.parent.name
        image = cv2.imread(str(image_path))
        assert image.shape == (1200, 1200, 3)
        label_path = out / "labels" / split / (image_path.stem + ".txt")
        for line in label_path.read_text().splitlines():
            class_id, cx, cy, w, h = line.split()
            assert 0 <= int(class_id) < len(YOLO_CLASSES)
            cx_, cy_, w_, h_ = (float(v) for v in (cx, cy, w, h))
            assert 0 < w_ <= 1 and 0 < h_ <= 1
            assert cx_ - w_ / 2 >= 0 and cx_ + w_ / 2 <= 1 + 1e-6
            assert cy_ - h_ / 2 >= 0 and cy_ + h_ / 2 <= 1 + 1e-6
            assert h_ * 1200 >= options.min_box_px - 1e-6
            labelled += 1
    assert labelled >= 10  # vehicles are in view after the warm-up
    # Truth sidecars: one per image, each vehicle with its range and visible share.
    records = [json.loads(path.read_text()) for path in sorted((out / "truth").rglob("*.json"))]
    assert len(records) == 10
    vehicles = [v for record in records for v in record["vehicles"]]
    assert vehicles and all(0 <= v["visible_fraction"] <= v["visibility"] <= 1 for v in vehicles)
    assert all(0 <= v["in_frame"] <= 1 and v["range_m"] > 0 for v in vehicles)
    assert any(v["in_frame"] == 1.0 for v in vehicles)
    scans = sorted((out / "lidar").rglob("*.npz"))
    assert len(scans) == 10
    with np.load(scans[-1]) as scan:
        assert scan["points"].shape == (64 * 2048, 4)
        assert scan["labels"].shape == (64 * 2048,)
        labels = set(np.unique(scan["labels"])) - {0}
        assert labels <= set(scan["box_labels"].tolist())
        assert scan["box_sizes_lwh_m"].shape == (len(scan["box_labels"]), 3)
    written = json.loads((out / "manifest.json").read_text())
    assert written["site_id"] == site.site_id
    assert sum(written["camera_labels_per_class"].values()) == labelled


def test_wz_pictures_writes_the_documentation_pictures(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "wz_cli.main",
            "pictures",
            "--out",
            str(tmp_path),
            "--warmup-s",
            "45",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    names = sorted(Path(line).name for line in result.stdout.split())
    assert names == ["camera-truth.jpg", "camera-weather.jpg", "lidar-top-view.png"]
    top = cv2.imread(str(tmp_path / "lidar-top-view.png"))
    assert top.shape == (1000, 1000, 3)
    # Vehicle points are drawn in colour: some pixels are neither grey nor background.
    colourful = (top.max(axis=2).astype(int) - top.min(axis=2)) > 60
    assert colourful.sum() > 50
    montage = cv2.imread(str(tmp_path / "camera-weather.jpg"))
    assert montage.shape == (1200, 1200, 3)
