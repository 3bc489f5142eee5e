"""Scoring detections against truth boxes: recall, precision and centre error by range.

The protocol (used for both paths, on the same frames):

- A truth vehicle is *scored* when its centre is within ``max_range_m`` of the sensor
  (horizontal distance) and at least ``min_visibility`` of it is visible (points it returned in
  the frame over points it returns alone). Vehicles outside that set are *don't care*: a
  detection on them is neither a hit nor a false alarm.
- A detection *covers* a truth vehicle when the detection's centre falls inside the vehicle's
  footprint grown by ``margin_m`` on every side. Detections and vehicles are paired one to one
  by Hungarian assignment on centre distance among covering pairs.
- Recall = paired scored vehicles / scored vehicles; precision = paired scored detections /
  (detections minus those paired with don't-care vehicles). A detection that covers no vehicle
  is a false alarm.
- Centre error: horizontal distance from the paired detection's centre to the truth centre.

Everything is in the sensor frame. Pure numpy/scipy; no I/O.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from wz_lidar_detector.detection import BoxDetection

DEFAULT_RANGE_BINS_M: tuple[float, ...] = (0.0, 30.0, 60.0, 90.0, 120.0)


@dataclass(frozen=True)
class TruthVehicle:
    """A vehicle's true box in the sensor frame and how visible it is in this frame."""

    vehicle_id: str
    center_xyz_m: tuple[float, float, float]
    size_lwh_m: tuple[float, float, float]
    heading_rad: float
    visibility: float
    num_points: int


@dataclass
class RangeBinScore:
    """Counts of one range bin."""

    low_m: float
    high_m: float
    scored: int = 0
    hits: int = 0
    detections: int = 0  # detections counted for precision (don't-care pairs excluded)
    false_alarms: int = 0
    centre_errors_m: list[float] = field(default_factory=list)

    @property
    def recall(self) -> float:
        return self.hits / self.scored if self.scored else float("nan")

    @property
    def precision(self) -> float:
        return (
            (self.detections - self.false_alarms) / self.detections
            if self.detections
            else (float("nan"))
        )


def _covers(detection_xy: np.ndarray, truth: TruthVehicle, margin_m: float) -> bool:
    dx = detection_xy[0] - truth.center_xyz_m[0]
    dy = detection_xy[1] - truth.center_xyz_m[1]
    c, s = np.cos(truth.heading_rad), np.sin(truth.heading_rad)
    along, across = dx * c + dy * s, -dx * s + dy * c
    length, width, _ = truth.size_lwh_m
    return bool(abs(along) <= 0.5 * length + margin_m and abs(across) <= 0.5 * width + margin_m)


@dataclass
class Scorer:
    """Accumulates scores over frames.

    Parameters
    ----------
    max_range_m
        Vehicles farther than this are not scored [m].
    min_visibility
        Vehicles less visible than this are not scored.
    margin_m
        How far outside a vehicle's footprint a detection centre may fall and still cover it.
    range_bins_m
        Edges of the range bins the table is given in.
    """

    max_range_m: float = 120.0
    min_visibility: float = 0.3
    margin_m: float = 1.0
    range_bins_m: tuple[float, ...] = DEFAULT_RANGE_BINS_M
    bins: list[RangeBinScore] = field(init=False)

    def __post_init__(self) -> None:
        edges = self.range_bins_m
        self.bins = [RangeBinScore(lo, hi) for lo, hi in itertools.pairwise(edges)]

    def _bin(self, range_m: float) -> RangeBinScore | None:
        for score in self.bins:
            if score.low_m <= range_m < score.high_m:
                return score
        return None

    def add_frame(self, detections: Sequence[BoxDetection], truths: Sequence[TruthVehicle]) -> None:
        """Score one frame."""
        det_xy = np.array([d.center_xyz_m[:2] for d in detections], dtype=float).reshape(-1, 2)
        truth_xy = np.array([t.center_xyz_m[:2] for t in truths], dtype=float).reshape(-1, 2)
        truth_range = np.hypot(truth_xy[:, 0], truth_xy[:, 1])
        scored = np.array(
            [
                r <= self.max_range_m and t.visibility >= self.min_visibility and t.num_points > 0
                for t, r in zip(truths, truth_range, strict=True)
            ],
            dtype=bool,
        )
        covers = np.array(
            [[_covers(det_xy[i], t, self.margin_m) for t in truths] for i in range(len(det_xy))],
            dtype=bool,
        ).reshape(len(det_xy), len(truths))
        distance = np.linalg.norm(det_xy[:, None, :] - truth_xy[None, :, :], axis=2)
        cost = np.where(covers, distance, 1e6)
        rows, cols = linear_sum_assignment(cost) if cost.size else (np.array([]), np.array([]))
        paired_truth_of_det: dict[int, int] = {
            int(r): int(c) for r, c in zip(rows, cols, strict=True) if covers[r, c]
        }
        for j in range(len(truths)):
            if not scored[j]:
                continue
            score = self._bin(float(truth_range[j]))
            if score is None:
                continue
            score.scored += 1
            pairs = [i for i, c in paired_truth_of_det.items() if c == j]
            if pairs:
                score.hits += 1
                score.centre_errors_m.append(float(distance[pairs[0], j]))
        for i in range(len(det_xy)):
            paired = paired_truth_of_det.get(i)
            if paired is not None and not scored[paired]:
                continue  # a detection of a don't-care vehicle
            if paired is None and covers[i].any() and not scored[covers[i]].any():
                continue  # a second detection on a don't-care vehicle
            det_range = float(np.hypot(*det_xy[i]))
            if det_range > self.max_range_m:
                continue
            bin_range = det_range if paired is None else float(truth_range[paired])
            score = self._bin(bin_range)
            if score is None:
                continue
            score.detections += 1
            if paired is None:
                score.false_alarms += 1

    def total(self) -> RangeBinScore:
        """All bins together."""
        total = RangeBinScore(self.range_bins_m[0], self.range_bins_m[-1])
        for score in self.bins:
            total.scored += score.scored
            total.hits += score.hits
            total.detections += score.detections
            total.false_alarms += score.false_alarms
            total.centre_errors_m.extend(score.centre_errors_m)
        return total


def percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else float("nan")
