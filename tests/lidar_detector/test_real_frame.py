"""The real freeway frame: vehicles found as separate detections, foreground as the dataset's."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from wz_lidar_detector.real_frame import DEFAULT_DATA, run


def test_real_frame_vehicles_and_foreground_agree_with_the_reference(tmp_path: Path) -> None:
    assert (DEFAULT_DATA / "rawdata.pcd").is_file(), f"the real frame is missing: {DEFAULT_DATA}"
    picture = tmp_path / "real.png"
    summary = run(DEFAULT_DATA, picture)
    # That dataset's own foreground (filtered.pcd) near the road is ours, and ours is theirs.
    assert summary["filtered_within_0.3m_of_fast_foreground"] >= 0.95
    assert summary["fast_foreground_within_0.3m_of_filtered"] >= 0.95
    # About a dozen to sixteen vehicles on the carriageway, each once: no two centres closer
    # than a car's width apart.
    on_road = summary["fast_detections_on_road"]
    assert 12 <= len(on_road) <= 18
    xy = np.array([[d["x"], d["y"]] for d in on_road])
    gaps = np.linalg.norm(xy[:, None] - xy[None, :], axis=2) + np.eye(len(xy)) * 1e9
    assert gaps.min() > 1.5
    assert cv2.imread(str(picture)).shape[2] == 3
