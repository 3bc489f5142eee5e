"""``wz eval``'s conflicts (:mod:`wz_eval.conflicts_report`): the scripted near misses given as
published track batches and as truth give the same conflicts by type, and SSAM's tables."""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from pathlib import Path

import pytest

from tests.gateway.conflict_scenes import (
    LENGTH_M,
    WIDTH_M,
    Row,
    crossing_rows,
    rear_end_rows,
    scene_track,
)
from wz_eval.conflicts_report import conflict_report
from wz_gateway.conflicts import SSAM_COLUMNS
from wz_shared.messages import (
    DriverProfile,
    Track,
    TrackBatch,
    VehicleClass,
    VehicleTruth,
)

IDS = {"lead": 1, "follow": 2, "a": 3, "b": 4}


def _as_published(
    rows: list[Row],
) -> tuple[list[TrackBatch], list[tuple[float, list[VehicleTruth]]]]:
    tracks: dict[float, list[Track]] = defaultdict(list)
    truth: dict[float, list[VehicleTruth]] = defaultdict(list)
    for name, t, x, y, vx, vy, heading, lane in rows:
        speed = math.hypot(vx, vy)
        tracks[float(t)].append(scene_track(IDS[name], x, y, vx, vy, heading, lane))
        truth[float(t)].append(
            VehicleTruth(
                vehicle_id=name,
                vehicle_class=VehicleClass.CAR,
                x_m=x,
                y_m=y,
                heading_rad=heading,
                speed_mps=speed,
                accel_mps2=0.0,
                length_m=LENGTH_M,
                width_m=WIDTH_M,
                height_m=1.5,
                lane_index=lane,
                station_m=y,
                offset_m=-x,
                driver_profile=DriverProfile.NORMAL,
            )
        )
    batches = [
        TrackBatch(site="s", source_id="fusion-tracker", stamp=t, cycle_index=k, tracks=ts)
        for k, (t, ts) in enumerate(sorted(tracks.items()))
    ]
    return batches, sorted(truth.items())


def test_tracks_and_truth_give_the_scripted_conflicts_and_ssam_tables(tmp_path: Path) -> None:
    batches, truth = _as_published(rear_end_rows(y_m=300.0) + crossing_rows())
    report = conflict_report(batches, truth, tmp_path)
    expected = {"rear end": 1, "lane change": 0, "crossing": 1}
    assert report["tracks"]["by_type"] == expected == report["truth"]["by_type"]
    assert report["truth"]["min_ttc_s"] == report["tracks"]["min_ttc_s"] < 1.5
    assert report["tracks"]["min_pet_s"] == pytest.approx(0.5, abs=1e-3)  # the rear end's
    for side in ("tracks", "truth"):
        with (tmp_path / report["ssam_csv"][side]).open(newline="") as f:
            rows = list(csv.DictReader(f))
        assert list(rows[0]) == list(SSAM_COLUMNS)
        assert [row["ConflictType"] for row in rows] == ["rear end", "crossing"]
        assert {row["trjFile"] for row in rows} == {side}
    # the truth's ids are the simulator's, the tracks' the tracker's
    assert rows[0]["FirstVID"] == "lead"


def test_nothing_written_without_a_folder() -> None:
    batches, truth = _as_published(crossing_rows(2.0))
    report = conflict_report(batches, truth)
    assert "ssam_csv" not in report and report["truth"]["count"] == report["tracks"]["count"]
