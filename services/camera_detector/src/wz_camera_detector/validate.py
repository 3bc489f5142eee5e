"""Validate a camera model on a `wz dataset` folder: AP50 and recall by distance, visibility, weather.

``python -m wz_camera_detector.validate --model M.onnx --data DIR [DIR...]`` runs the service's own
pipeline (:class:`YoloOnnxDetector`: ROI crop, letterbox, ONNX Runtime, decode, NMS) on every
camera frame of the folders' ``val`` split and scores it against the truth sidecars that
``wz dataset`` writes (``truth/val/*.json``: each vehicle's visible box, visibility and ground
range from the camera).

Which vehicles count. A vehicle is *scored* when its ground range is at most ``--max-range-m``
and at least ``--min-visibility`` of it is visible: the renderer's unoccluded share of its
silhouette times the share of its projected box inside the frame (``visible_fraction`` in the
sidecar; a car passing under the camera, mostly out of the picture, is not scored). The other vehicles in view are *ignored*: a detection matching one of them is
neither a true nor a false positive (the usual "don't care" treatment of KITTI and COCO
crowd regions), and missing one costs nothing.

Matching. Per frame, detections by decreasing score each take the unmatched scored vehicle of
highest IoU (at least ``--iou``, 0.5); a detection left over that overlaps an ignored vehicle
(IoU at least ``--iou``, or half of the smaller box covered: a vehicle 300 m out is a 5 px box,
where one pixel of error costs half the IoU) is dropped; any other is a false positive. ``vehicles`` scores are class-agnostic
(a car found as a truck still counts); per-class scores ask for the class too.

AP is the area under the precision envelope over all recall points (VOC 2010+ / ultralytics
"continuous"), from detections down to score 0.001. Recall and precision are also given at the
service's operating threshold (``--conf``, default the service's 0.25).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from wz_camera_detector.regions import detector_regions
from wz_camera_detector.settings import camera_mount
from wz_camera_detector.yolo import YoloOnnxDetector, box_iou
from wz_shared.arrays import F64
from wz_shared.site import load_site

#: Distance bins of the report [m].
RANGE_BINS_M: tuple[tuple[float, float], ...] = ((0, 25), (25, 50), (50, 75), (75, 100))


@dataclass(frozen=True)
class TruthBox:
    box_xyxy_px: tuple[float, float, float, float]
    class_name: str
    range_m: float
    visibility: float


@dataclass(frozen=True)
class PredBox:
    box_xyxy_px: tuple[float, float, float, float]
    class_name: str
    score: float


@dataclass
class Outcome:
    """Matched detections of a set of frames, for AP and recall.

    ``scores`` and ``true`` hold every non-ignored detection (its score, and whether it matched
    a scored vehicle); ``n_truth`` is the number of scored vehicles; ``hit_scores`` the best
    matching score of each scored vehicle (``-inf`` when none matched), for recall by group.
    """

    scores: list[float] = field(default_factory=list)
    true: list[bool] = field(default_factory=list)
    n_truth: int = 0
    truth_groups: list[str] = field(default_factory=list)
    hit_scores: list[float] = field(default_factory=list)

    def extend(self, other: Outcome) -> None:
        self.scores += other.scores
        self.true += other.true
        self.n_truth += other.n_truth
        self.truth_groups += other.truth_groups
        self.hit_scores += other.hit_scores


#: A detection overlapping an ignored vehicle by this share of the smaller box is ignored.
IGNORE_OVERLAP = 0.5


def _overlap_of_smaller(box: tuple[float, float, float, float], boxes: F64) -> F64:
    """Intersection over the smaller box's area, of ``box`` with each of ``boxes`` (K, 4)."""
    x0 = np.maximum(box[0], boxes[:, 0])
    y0 = np.maximum(box[1], boxes[:, 1])
    x1 = np.minimum(box[2], boxes[:, 2])
    y1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    smaller = np.maximum(np.minimum(area, areas), 1e-9)
    result: F64 = inter / smaller
    return result


def match_frame(
    truths: Sequence[TruthBox],
    preds: Sequence[PredBox],
    scored: Sequence[bool],
    iou_threshold: float = 0.5,
    by_class: bool = False,
    groups: Sequence[str] | None = None,
) -> Outcome:
    """Greedy matching of one frame's detections to its vehicles (module docstring).

    Parameters
    ----------
    truths
        The vehicles in view.
    preds
        The detections (any order).
    scored
        Per vehicle: scored (True) or ignored (False).
    iou_threshold
        Least IoU of a match.
    by_class
        A match also needs the same class.
    groups
        A label per vehicle (e.g. its distance bin), kept with each scored vehicle's outcome.
    """
    if len(scored) != len(truths):
        raise ValueError(f"{len(truths)} vehicles but {len(scored)} scored flags")
    outcome = Outcome()
    order = sorted(range(len(preds)), key=lambda i: -preds[i].score)
    truth_boxes = np.array([t.box_xyxy_px for t in truths], dtype=np.float64).reshape(-1, 4)
    best_score = np.full(len(truths), -math.inf)
    taken = np.zeros(len(truths), dtype=bool)
    for index in order:
        pred = preds[index]
        if len(truths):
            ious = box_iou(np.array(pred.box_xyxy_px, dtype=np.float64), truth_boxes)
        else:
            ious = np.zeros(0)
        if by_class:
            same = np.array([t.class_name == pred.class_name for t in truths], dtype=bool)
            ious = np.where(same, ious, 0.0)
        candidates = np.where(np.array(scored, dtype=bool) & ~taken, ious, -1.0)
        best = int(np.argmax(candidates)) if len(candidates) else -1
        if best >= 0 and candidates[best] >= iou_threshold:
            taken[best] = True
            best_score[best] = pred.score
            outcome.scores.append(pred.score)
            outcome.true.append(True)
            continue
        ignored = np.array([not s for s in scored], dtype=bool)
        if len(ious) and np.any(
            ignored
            & (
                (ious >= iou_threshold)
                | (_overlap_of_smaller(pred.box_xyxy_px, truth_boxes) >= IGNORE_OVERLAP)
            )
        ):
            continue  # a "don't care" vehicle: neither true nor false
        outcome.scores.append(pred.score)
        outcome.true.append(False)
    for i, is_scored in enumerate(scored):
        if is_scored:
            outcome.n_truth += 1
            outcome.hit_scores.append(float(best_score[i]))
            outcome.truth_groups.append(groups[i] if groups is not None else "all")
    return outcome


def average_precision(scores: Sequence[float], true: Sequence[bool], n_truth: int) -> float:
    """Area under the precision envelope over recall (all points); nan without truth."""
    if n_truth == 0:
        return math.nan
    if not scores:
        return 0.0
    order = np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable")
    hits = np.asarray(true, dtype=np.float64)[order]
    tp = np.cumsum(hits)
    fp = np.cumsum(1.0 - hits)
    recall = tp / n_truth
    precision = tp / np.maximum(tp + fp, 1e-12)
    # Envelope: precision made non-increasing from the right; then sum over recall steps.
    r = np.concatenate(([0.0], recall, [recall[-1]]))
    p = np.concatenate(([1.0], precision, [0.0]))
    p = np.flip(np.maximum.accumulate(np.flip(p)))
    steps = np.where(r[1:] != r[:-1])[0]
    return float(np.sum((r[steps + 1] - r[steps]) * p[steps + 1]))


def at_threshold(outcome: Outcome, conf: float) -> dict[str, float | int]:
    """Precision, recall and counts of the detections scoring at least ``conf``."""
    true = np.asarray(outcome.true, dtype=bool)
    keep = np.asarray(outcome.scores, dtype=np.float64) >= conf
    tp = int(np.sum(true & keep))
    fp = int(np.sum(~true & keep))
    fn = outcome.n_truth - tp
    return {
        "precision": tp / (tp + fp) if tp + fp else math.nan,
        "recall": tp / outcome.n_truth if outcome.n_truth else math.nan,
        "true_positives": tp,
        "false_positives": fp,
        "false_negatives": fn,
    }


def recall_by_group(outcome: Outcome, conf: float) -> dict[str, dict[str, float | int]]:
    """Per group label: scored vehicles and the share found at ``conf``."""
    found: dict[str, list[bool]] = defaultdict(list)
    for group, hit in zip(outcome.truth_groups, outcome.hit_scores, strict=True):
        found[group].append(hit >= conf)
    return {
        group: {"vehicles": len(hits), "recall": sum(hits) / len(hits)}
        for group, hits in sorted(found.items())
    }


def range_bin(range_m: float) -> str:
    for lo, hi in RANGE_BINS_M:
        if lo <= range_m <= hi:
            return f"{lo:g}-{hi:g} m"
    return f">{RANGE_BINS_M[-1][1]:g} m"


def read_truth(path: Path) -> list[TruthBox]:
    """The vehicles of one ``truth/<split>/*.json`` sidecar."""
    record = json.loads(path.read_text())
    return [
        TruthBox(
            box_xyxy_px=(
                float(v["box_xyxy_px"][0]),
                float(v["box_xyxy_px"][1]),
                float(v["box_xyxy_px"][2]),
                float(v["box_xyxy_px"][3]),
            ),
            class_name=str(v["class"]),
            range_m=float(v["range_m"]),
            # the share one can see: unoccluded and inside the frame (older sidecars: the
            # renderer's visibility, which ignores the part outside the frame)
            visibility=float(v.get("visible_fraction", v["visibility"])),
        )
        for v in record["vehicles"]
    ]


def frames(folders: Iterable[Path], split: str) -> list[tuple[Path, Path]]:
    """``(image, truth)`` pairs of the split, sorted by name; images without truth skipped."""
    pairs = []
    for folder in folders:
        for image in sorted((folder / "images" / split).glob("*.jpg")):
            truth = folder / "truth" / split / f"{image.stem}.json"
            if truth.exists():
                pairs.append((image, truth))
    return pairs


def validate(
    detector: YoloOnnxDetector,
    pairs: Sequence[tuple[Path, Path]],
    max_range_m: float = 100.0,
    min_visibility: float = 0.5,
    iou_threshold: float = 0.5,
    conf: float = 0.25,
) -> dict[str, object]:
    """Score the detector on the frames (module docstring); the report as a dict."""
    agnostic = Outcome()
    per_class: dict[str, Outcome] = defaultdict(Outcome)
    per_weather: dict[str, Outcome] = defaultdict(Outcome)
    inference_ms: list[float] = []
    for image_path, truth_path in pairs:
        image = cv2.imread(str(image_path), cv2.IMREAD_COLOR)
        if image is None:
            raise ValueError(f"{image_path}: not a readable image")
        truths = read_truth(truth_path)
        found, timings = detector.detect_with_timings(np.asarray(image, dtype=np.uint8))
        inference_ms.append(timings.total_s * 1e3)
        preds = [PredBox(d.box_xyxy_px, d.class_name, d.score) for d in found]
        scored = [t.range_m <= max_range_m and t.visibility >= min_visibility for t in truths]
        groups = [range_bin(t.range_m) for t in truths]
        frame_outcome = match_frame(truths, preds, scored, iou_threshold, groups=groups)
        agnostic.extend(frame_outcome)
        per_weather[image_path.name.split("-")[0]].extend(frame_outcome)
        for class_name in {t.class_name for t in truths} | {p.class_name for p in preds}:
            class_scored = [
                s and t.class_name == class_name for s, t in zip(scored, truths, strict=True)
            ]
            class_preds = [p for p in preds if p.class_name == class_name]
            per_class[class_name].extend(
                match_frame(truths, class_preds, class_scored, iou_threshold, by_class=True)
            )
    report: dict[str, object] = {
        "frames": len(pairs),
        "criteria": {
            "max_range_m": max_range_m,
            "min_visibility": min_visibility,
            "iou": iou_threshold,
            "conf": conf,
        },
        "vehicles": {
            "scored": agnostic.n_truth,
            "map50": average_precision(agnostic.scores, agnostic.true, agnostic.n_truth),
            **at_threshold(agnostic, conf),
            "recall_by_range": recall_by_group(agnostic, conf),
        },
        "classes": {
            name: {
                "scored": outcome.n_truth,
                "ap50": average_precision(outcome.scores, outcome.true, outcome.n_truth),
                **at_threshold(outcome, conf),
            }
            for name, outcome in sorted(per_class.items())
            if outcome.n_truth
        },
        "weather": {
            name: {
                "scored": outcome.n_truth,
                "map50": average_precision(outcome.scores, outcome.true, outcome.n_truth),
                **at_threshold(outcome, conf),
            }
            for name, outcome in sorted(per_weather.items())
        },
        "detect_ms_median": float(np.median(inference_ms)) if inference_ms else math.nan,
    }
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m wz_camera_detector.validate", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument(
        "--data",
        type=Path,
        nargs="+",
        required=True,
        help="wz dataset folders (their truth sidecars)",
    )
    parser.add_argument("--split", default="val")
    parser.add_argument("--max-range-m", type=float, default=100.0)
    parser.add_argument("--min-visibility", type=float, default=0.5)
    parser.add_argument("--iou", type=float, default=0.5)
    parser.add_argument("--conf", type=float, default=0.25)
    parser.add_argument("--json", type=Path, default=None, help="also write the report here")
    parser.add_argument(
        "--site",
        type=Path,
        default=None,
        help="the frames' site file: the detector looks where the road's geometry says "
        "(as the service does); default: the model's metadata regions",
    )
    args = parser.parse_args(argv)
    pairs = frames(args.data, args.split)
    if not pairs:
        parser.error(f"no {args.split} frames with truth sidecars in {args.data}")
    detector = YoloOnnxDetector(args.model, conf_threshold=0.001, max_detections=300)
    if args.site is not None:
        site = load_site(args.site)
        regions = detector_regions(site, camera_mount(site, None), max(detector.input_size))
        detector.set_regions(regions.roi_xyxy_px, regions.tiles_xyxy_px)
    started = time.perf_counter()
    report = validate(detector, pairs, args.max_range_m, args.min_visibility, args.iou, args.conf)
    report["model"] = str(args.model)
    report["regions"] = {
        "roi_xyxy_px": detector.roi_xyxy_px,
        "tiles_xyxy_px": detector.tiles_xyxy_px,
    }
    report["data"] = [str(p) for p in args.data]
    report["seconds"] = round(time.perf_counter() - started, 1)
    text = json.dumps(report, indent=2)
    if args.json is not None:
        args.json.write_text(text + "\n")
    sys.stdout.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
