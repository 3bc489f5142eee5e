"""The lateral bias map: fitted from errors against truth, removed from a sensor's detections
across the road (on the straight and on the curve), refused when it is malformed or another
site's; and the fusion core and ``wz eval`` taking it."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wz_fusion_tracker.calibration import (
    BiasCell,
    BiasMap,
    BiasMapError,
    LateralBiasCorrector,
    fit_bias_map,
    load_bias_map,
    write_bias_map,
)
from wz_fusion_tracker.node import FusionCore
from wz_fusion_tracker.settings import FusionTrackerSettings
from wz_fusion_tracker.types import Measurement
from wz_shared.messages import Detection, DetectionBatch, TrackBatch
from wz_shared.site import DEFAULT_SITE_PATH, load_site

ROOT = Path(__file__).resolve().parents[2]
SITE = load_site(DEFAULT_SITE_PATH)
MAST_STATION = float(SITE.road_frame.to_road(7.5, 980.0)[0])  # the LiDAR's station


def measurement_at(station_m: float, offset_m: float, sensor: str = "lidar-mast") -> Measurement:
    x, y = SITE.road_frame.to_site(station_m, offset_m)
    return Measurement(x_m=float(x), y_m=float(y), covariance_m2=np.eye(2) * 0.04, sensor_id=sensor)


def road(m: Measurement) -> tuple[float, float]:
    station, offset = SITE.road_frame.to_road(m.x_m, m.y_m)
    return float(station), float(offset)


def test_fit_recovers_each_cells_median_and_leaves_thin_cells_out() -> None:
    rng = np.random.default_rng(3)
    errors = []
    # lane 0, 60-50 m upstream: bias +0.05 with a heavy tail the median ignores
    for _ in range(200):
        lateral = 0.05 + rng.normal(0.0, 0.02) + (3.0 if rng.random() < 0.1 else 0.0)
        errors.append(("lidar-mast", MAST_STATION - 55.0 + rng.uniform(-4, 4), -1.83, lateral))
    # lane 1, same bin: -0.03
    errors += [
        ("lidar-mast", MAST_STATION - 55.0, 1.83, -0.03 + rng.normal(0, 0.01)) for _ in range(100)
    ]
    # too few for a cell; a sensor the site does not have; off the road; a NaN
    errors += [("lidar-mast", MAST_STATION - 95.0, -1.83, 0.5)] * 29
    errors += [("lidar-elsewhere", MAST_STATION - 55.0, -1.83, 0.5)] * 50
    errors += [("lidar-mast", MAST_STATION - 55.0, -9.0, 0.5)] * 50
    errors += [("lidar-mast", MAST_STATION - 55.0, -1.83, math.nan)] * 50
    bias_map = fit_bias_map(SITE, errors, bin_m=10.0, min_samples=30, source="test")
    assert list(bias_map.sensors) == ["lidar-mast"]
    cells = {(c.lane_index, c.relative_station_m): c for c in bias_map.sensors["lidar-mast"]}
    assert set(cells) == {(0, -60.0), (1, -60.0)}
    assert cells[(0, -60.0)].lateral_bias_m == pytest.approx(0.05, abs=0.01)
    assert cells[(0, -60.0)].samples == 200
    assert cells[(1, -60.0)].lateral_bias_m == pytest.approx(-0.03, abs=0.005)
    assert bias_map.site_id == SITE.site_id and bias_map.source == "test"


def one_cell_map(
    bias_m: float, relative_station_m: float = -60.0, lane: int = 0, sensor: str = "lidar-mast"
) -> BiasMap:
    return BiasMap(
        site_id=SITE.site_id,
        bin_m=10.0,
        sensors={
            sensor: [
                BiasCell(
                    lane_index=lane,
                    relative_station_m=relative_station_m,
                    lateral_bias_m=bias_m,
                    samples=100,
                )
            ]
        },
    )


def test_correction_moves_across_the_road_by_minus_the_cells_bias() -> None:
    corrector = LateralBiasCorrector(SITE, one_cell_map(0.08))
    inside = measurement_at(MAST_STATION - 55.0, -1.75)
    other_bin = measurement_at(MAST_STATION - 45.0, -1.75)
    other_lane = measurement_at(MAST_STATION - 55.0, 1.9)
    shoulder = measurement_at(MAST_STATION - 55.0, -6.0)
    out = corrector.correct("lidar-mast", [inside, other_bin, other_lane, shoulder])
    station, offset = road(out[0])
    assert station == pytest.approx(MAST_STATION - 55.0, abs=1e-6)
    assert offset == pytest.approx(-1.75 - 0.08, abs=1e-6)
    assert out[0].covariance_m2 is inside.covariance_m2 and out[0].sensor_id == "lidar-mast"
    assert out[1:] == [other_bin, other_lane, shoulder]  # the same objects, untouched
    # another sensor's measurements, and none at all
    assert corrector.correct("camera-mast", [inside]) == [inside]
    assert corrector.correct("lidar-mast", []) == []


def test_correction_follows_the_road_on_the_curve() -> None:
    """On the curve (stations past 1400 m) across the road is not along x: the measurement moves
    along the road's normal, its station unchanged."""
    relative = 1550.0 - MAST_STATION  # 570 m downstream, on the 1500 m radius curve
    corrector = LateralBiasCorrector(SITE, one_cell_map(-0.2, relative_station_m=relative))
    before = measurement_at(1555.0, -1.83)
    (after,) = corrector.correct("lidar-mast", [before])
    station, offset = road(after)
    assert station == pytest.approx(1555.0, abs=1e-6)
    assert offset == pytest.approx(-1.83 + 0.2, abs=1e-6)
    heading = SITE.road_frame.heading_at_point(before.x_m, before.y_m)
    moved = np.array([after.x_m - before.x_m, after.y_m - before.y_m])
    left = np.array([-math.sin(heading), math.cos(heading)])
    assert moved @ left == pytest.approx(0.2, abs=1e-6)  # 0.2 m to the left
    assert abs(moved[0]) > 0.01 and abs(moved[1]) > 0.01  # neither x nor y alone


def test_another_sites_map_and_malformed_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(BiasMapError, match="site 'elsewhere'"):
        LateralBiasCorrector(SITE, one_cell_map(0.1).model_copy(update={"site_id": "elsewhere"}))
    good = tmp_path / "good.json"
    write_bias_map(good, one_cell_map(0.1))
    assert load_bias_map(good) == one_cell_map(0.1)
    bad = {
        "missing.json": None,
        "truncated.json": good.read_text()[:40],
        "binary.json": b"\xff\xfe\x00",
        "nan.json": good.read_text().replace("0.1", "NaN"),
        "huge.json": good.read_text().replace("0.1", "7.5"),
        "off-grid.json": good.read_text().replace("-60.0", "-55.0"),
        "extra.json": json.dumps({**json.loads(good.read_text()), "sensor": 1}),
    }
    for name, content in bad.items():
        path = tmp_path / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        elif content is not None:
            path.write_text(content)
        with pytest.raises(BiasMapError, match=name):
            load_bias_map(path)
    doubled = json.loads(good.read_text())
    doubled["sensors"]["lidar-mast"] *= 2
    (tmp_path / "doubled.json").write_text(json.dumps(doubled))
    with pytest.raises(BiasMapError, match="two cells"):
        load_bias_map(tmp_path / "doubled.json")


def lidar_batch(k: int, offset_m: float) -> DetectionBatch:
    """One car in lane 0 at 25 m/s, 90-15 m upstream of the mast, seen at ``offset_m``."""
    t = 0.05 * k
    x, y = SITE.road_frame.to_site(MAST_STATION - 90.0 + 25.0 * t, offset_m)
    detection = Detection(
        x_m=float(x), y_m=float(y), covariance_m2=[0.04, 0.0, 0.0, 0.04], object_class="car"
    )
    return DetectionBatch(
        site=SITE.site_id, source_id="lidar-mast", stamp=t, frame_index=k, detections=[detection]
    )


def test_fusion_core_removes_the_bias_of_its_map(tmp_path: Path) -> None:
    """A LiDAR that sees a car 0.15 m left of where it drives: with the map, the track is on
    the car's line; without it, 0.15 m off."""
    cells = [
        BiasCell(lane_index=0, relative_station_m=-10.0 * k, lateral_bias_m=0.15, samples=100)
        for k in range(1, 11)
    ]
    path = tmp_path / "bias.json"
    write_bias_map(path, BiasMap(site_id=SITE.site_id, sensors={"lidar-mast": cells}))
    offsets = {}
    for name, settings in (
        ("plain", FusionTrackerSettings()),
        ("mapped", FusionTrackerSettings(bias_map=path)),
    ):
        core = FusionCore(SITE, settings, report=lambda r, d: None)
        outputs: list[TrackBatch] = []
        for k in range(60):
            outputs += core.add(lidar_batch(k, -1.83 + 0.15))
        (track,) = outputs[-1].tracks
        offsets[name] = track.offset_m
    assert offsets["plain"] == pytest.approx(-1.68, abs=0.02)
    assert offsets["mapped"] == pytest.approx(-1.83, abs=0.02)


def test_the_node_will_not_start_with_a_bad_map(tmp_path: Path) -> None:
    path = tmp_path / "bias.json"
    path.write_text('{"site_id": "us75-lincoln", "sensors": {"lidar-mast": [{"lane_index": 0')
    env = {"PATH": "/usr/bin:/bin", "WZ_FUSION_BIAS_MAP": str(path)}
    result = subprocess.run(
        [sys.executable, "-m", "wz_fusion_tracker.node"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode != 0
    assert "bias map" in result.stderr and "not JSON" in result.stderr
