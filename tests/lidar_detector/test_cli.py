"""``wz detect-lidar``: one JSON line per file, both paths, the site frame, bad files."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.lidar_detector.test_node import COLUMNS, ROWS, site_of_sensor_xy, synthetic_points
from wz_lidar_detector.background import RangeImageBackground
from wz_lidar_detector.cli import run
from wz_lidar_detector.detection import PointFrame

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT / "samples" / "real-freeway-lidar"
CUT = Path(__file__).resolve().parent / "data" / "rawdata-cut.pcd"
# The real frame ships in samples/real-freeway-lidar (its README: source and use).


def wz(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wz_cli.main", "detect-lidar", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def lines(stdout: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in stdout.splitlines()]


def on_road(detection: dict[str, Any]) -> bool:
    """Within the real frame's carriageway (along +x, about -10 to 130 m; README)."""
    return -10 < detection["x"] < 130 and abs(detection["y"]) < 25


def test_real_frame_reference_then_fast_path(tmp_path: Path) -> None:
    truncated = tmp_path / "truncated.pcd"
    truncated.write_bytes(CUT.read_bytes()[:-500])
    result = wz(str(REAL / "rawdata.pcd"), str(truncated), str(CUT))
    assert result.returncode == 1, result.stderr
    raw, bad, cut = lines(result.stdout)
    assert raw["file"] == str(REAL / "rawdata.pcd") and raw["stamp"] == 0.0
    assert (raw["path"], raw["frame"], raw["rows"], raw["columns"]) == (
        "reference",
        "sensor",
        80,
        1800,
    )
    vehicles = [d for d in raw["detections"] if on_road(d) and d["class"] != "unknown"]
    assert len(vehicles) >= 5  # "about a dozen vehicles in the carriageway"
    keys = {"x", "y", "z", "length", "width", "height", "heading", "class", "points", "score"}
    assert keys <= set(vehicles[0])
    assert bad == {"file": str(truncated), "error": bad["error"]}
    assert "header says 240 points, data has" in bad["error"] and str(truncated) in bad["error"]
    assert cut["rows"] == 8 and "error" not in cut  # the files after a bad one still run

    result = wz(str(REAL / "rawdata.pcd"), "--background", str(REAL / "background.pcd"))
    assert result.returncode == 0, result.stderr
    (fast,) = lines(result.stdout)
    assert fast["path"] == "fast" and set(fast["timings_ms"]) >= {"foreground", "cluster"}
    vehicles = [d for d in fast["detections"] if on_road(d)]
    assert len(vehicles) >= 5
    assert fast["foreground_points"] < 0.3 * fast["points"]  # the background is subtracted


def test_saved_background_and_site_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frames = [PointFrame(synthetic_points(None, seed=i), ROWS, COLUMNS) for i in range(3)]
    RangeImageBackground.learn(frames).save(tmp_path / "learned.npz")
    car = synthetic_points((20.0, 6.0), seed=4).reshape(ROWS, COLUMNS, 4)
    np.savez(tmp_path / "car.npz", points=car, stamp_s=np.array(3.25))
    argv = [str(tmp_path / "car.npz"), "--background", str(tmp_path / "learned.npz")]
    assert run([*argv, "--frame", "site", "--sensor", "lidar-mast"]) == 0
    (line,) = lines(capsys.readouterr().out)
    assert (line["stamp"], line["path"], line["frame"]) == (3.25, "fast", "site")
    (detection,) = line["detections"]
    assert math.dist((detection["x"], detection["y"]), site_of_sensor_xy(20.0, 6.0)) < 1.5
    assert detection["class"] == "car" and abs(math.cos(detection["heading"])) < 0.2
    # The same frame in the sensor frame with the reference path.
    assert run([str(tmp_path / "car.npz")]) == 0
    (line,) = lines(capsys.readouterr().out)
    assert line["path"] == "reference" and line["frame"] == "sensor"
    assert [round(d["y"]) for d in line["detections"]] == [6]


def test_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv, message in (
        ([str(CUT), "--path", "fast"], "the fast path needs --background"),
        ([str(CUT), "--path", "reference", "--background", str(CUT)], "for the fast path"),
        ([str(CUT), "--frame", "site", "--sensor", "camera-mast"], "not a LiDAR"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            run(argv)
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err
    frames = [PointFrame(synthetic_points(None, rows=4, columns=64), 4, 64)]
    saved = tmp_path / "saved.npz"
    RangeImageBackground.learn(frames).save(saved)
    for content in (b"PK not a zip", saved.read_bytes()[:-300]):
        broken = tmp_path / "background.npz"
        broken.write_bytes(content)
        assert run([str(CUT), "--background", str(broken)]) == 1
        (line,) = lines(capsys.readouterr().out)
        assert line["file"] == str(broken) and line["error"].startswith("background: ")
    # A saved background of another layout: an error line for the frame, exit 1.
    assert run([str(CUT), "--background", str(saved)]) == 1
    (line,) = lines(capsys.readouterr().out)
    assert line["file"] == str(CUT) and "detection failed" in line["error"]
