"""``wz eval-camera --video FILE --truth TRUTH``: the camera detector scored on real video.

The detector of ``wz detect-camera`` (the service's backend, no site: the whole frame or
``--roi``) runs on every frame that has truth, and its vehicle boxes are matched to the true
ones. Truth, one of:

- **MOT** text (``frame,id,x,y,w,h,conf,...``, MOTChallenge's layout, frames from 1; a line
  with ``conf`` 0 marks a region to ignore);
- **YOLO** text, a folder of ``<image stem>.txt`` (``class cx cy w h``, normalised);
- **motion masks**, a folder of PNGs as CDnet's (``gt000470.png``: 255 moving, 170 unknown,
  85 outside the region of interest, 50 shadow, 0 static): each 8-connected blob of 255 is a
  vehicle's box; unknown and outside pixels are ignored; a ``temporalROI.txt`` beside the
  folder limits the frames scored.

Frames: a video's frames count from 1; a folder of images is taken in name order, each image's
frame number being the digits of its name (``in000470.jpg``: 470, ``401.jpg``: 401).

Scoring (PASCAL VOC's rule): per frame, detections by decreasing score each take the unmatched
true box of highest IoU, if at least ``--iou`` (0.5). A motion blob may hold several touching
vehicles (far away, in a queue): a detection lying at least 70 % inside a blob it does not
match is one of them, true (``in_blob``), and the blob is found. Only vehicles at least ``--min-height``
pixels tall (20) count: a detection matched to a smaller vehicle, lying mostly (half its area)
on ignored pixels or in an ignored region, or itself smaller and unmatched, is neither true nor
false. Recall by true box height, precision by detected box height (bins of
:data:`HEIGHT_BINS_PX`: ``<20``, ``20-40``, ``40-80``, ``80-160``, ``160+`` px, lowest first), and
pictures of the frames with the most misses and false boxes (truth green, found blue, missed
orange, false red).
Recall is also split between vehicles wholly inside the frame and those its edge cuts (a true
box within :data:`EDGE_MARGIN_PX` of it: entering or leaving).

``--tracked`` scores, beside the detector on every frame, what the node publishes
(:class:`~wz_camera_detector.following.DetectAndFollow`: the detector where it is due at the
clip's frame rate, optical flow between, the image tracker's published tracks, clipped to the
frame): every frame of the clip goes through it in order, and the frames with truth are scored
(under ``published`` in the JSON).
Writes ``video-eval.json`` and ``video-eval.md`` in ``--out``.
"""

from __future__ import annotations

import argparse
import bisect
import itertools
import json
import logging
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wz_camera_detector.cli import IMAGE_SUFFIXES
from wz_camera_detector.following import DetectAndFollow, ImageBackend
from wz_camera_detector.node import CLASS_SHAPES, make_backend
from wz_camera_detector.settings import CameraDetectorSettings
from wz_camera_detector.yolo import ModelLoadError, YoloOnnxDetector, box_iou
from wz_shared.arrays import F64, U8
from wz_shared.logs import configure_logging

log = logging.getLogger("wz_eval.camera_video")

#: Box heights [px] the figures are given by: the edges of the bins, each bin from its lower
#: edge up to (not including) the next; a bin below the first edge and an open one from the last.
HEIGHT_BINS_PX = (20.0, 40.0, 80.0, 160.0)
#: The bins' names, lowest first (the order of the summary's and the table's rows): ``<20``,
#: ``20-40``, ``40-80``, ``80-160``, ``160+``.
HEIGHT_BIN_NAMES = (
    f"<{HEIGHT_BINS_PX[0]:.0f}",
    *(f"{low:.0f}-{high:.0f}" for low, high in itertools.pairwise(HEIGHT_BINS_PX)),
    f"{HEIGHT_BINS_PX[-1]:.0f}+",
)
#: Motion-mask values (CDnet): moving, unknown (a blob's blurred edge), outside the ROI.
MASK_MOVING, MASK_UNKNOWN, MASK_OUTSIDE = 255, 170, 85
#: A blob smaller than this [px^2] is noise, not a vehicle.
MIN_BLOB_AREA_PX = 20
#: A detection lying on ignored pixels or regions for this share of its area is not scored.
IGNORED_SHARE = 0.5
#: A detection lying this much inside a motion blob it does not match by IoU is one of the
#: touching vehicles the blob holds (a mask cannot part them).
IN_BLOB_SHARE = 0.7
#: A true box this close to the frame's edge [px] is a vehicle cut by it (entering or leaving).
EDGE_MARGIN_PX = 2.0
#: The frame rate of an image folder when ``--fps`` does not say [Hz].
DEFAULT_FOLDER_FPS = 30.0


class TruthError(ValueError):
    """Truth that cannot be read; the message names the file."""


@dataclass
class FrameTruth:
    """One frame's true vehicle boxes ``(x1, y1, x2, y2)`` [px], and what is ignored."""

    boxes: F64
    ignore_boxes: F64 = field(default_factory=lambda: np.zeros((0, 4)))
    ignore_mask: np.ndarray | None = None  # bool (H, W): pixels that are not scored
    #: The boxes are motion blobs: one may hold several touching vehicles.
    blobs: bool = False


def _frame_number(path: Path) -> int | None:
    digits = re.findall(r"\d+", path.stem)
    return int(digits[-1]) if digits else None


def read_frames(video: Path) -> Iterator[tuple[int, U8]]:
    """``(frame number, BGR image)`` of a video file (from 1) or an image folder (by name)."""
    if video.is_dir():
        images = sorted(p for p in video.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        for path in images:
            number = _frame_number(path)
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if number is None or image is None:
                log.warning("%s: no frame number in its name, or not an image; skipped", path)
                continue
            yield number, np.asarray(image, dtype=np.uint8)
        return
    capture = cv2.VideoCapture(str(video))
    if not capture.isOpened():
        raise TruthError(f"{video}: neither an image folder nor a video OpenCV can open")
    try:
        number = 0
        while True:
            ok, image = capture.read()
            if not ok or image is None:
                break
            number += 1
            yield number, np.asarray(image, dtype=np.uint8)
    finally:
        capture.release()


def read_truth(path: Path) -> dict[int, FrameTruth] | YoloTruth:
    """Truth by frame number (MOT file, mask folder), or a YOLO folder read per image size."""
    if path.is_file():
        return _read_mot(path)
    if not path.is_dir():
        raise TruthError(f"{path}: no such file or folder")
    if any(path.glob("*.txt")):
        return YoloTruth(path)
    masks = sorted(p for p in path.iterdir() if p.suffix.lower() == ".png")
    if not masks:
        raise TruthError(f"{path}: neither YOLO .txt files nor mask .png files in it")
    return _read_masks(path, masks)


def _read_mot(path: Path) -> dict[int, FrameTruth]:
    boxes: dict[int, list[list[float]]] = {}
    ignored: dict[int, list[list[float]]] = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split(",")[:7]]
            frame, (x, y, w, h) = int(values[0]), values[2:6]
        except (ValueError, IndexError) as exc:
            raise TruthError(f"{path}:{number}: not a MOT line (frame,id,x,y,w,h,...)") from exc
        if not (np.isfinite([x, y, w, h]).all() and w > 0 and h > 0):
            raise TruthError(f"{path}:{number}: box {x, y, w, h} is not finite and positive")
        target = ignored if len(values) > 6 and values[6] == 0 else boxes
        target.setdefault(frame, []).append([x, y, x + w, y + h])
    frames = set(boxes) | set(ignored)
    return {
        frame: FrameTruth(
            np.array(boxes.get(frame, []), dtype=np.float64).reshape(-1, 4),
            np.array(ignored.get(frame, []), dtype=np.float64).reshape(-1, 4),
        )
        for frame in frames
    }


class YoloTruth:
    """A folder of YOLO label files, read for each image (the labels are normalised)."""

    def __init__(self, folder: Path) -> None:
        #: Label file by frame number (the digits of its name), indexed once.
        self.files = {
            number: path
            for path in sorted(folder.glob("*.txt"))
            if (number := _frame_number(path)) is not None
        }

    def for_image(self, number: int, width: int, height: int) -> FrameTruth | None:
        path = self.files.get(number)
        if path is None:
            return None
        rows = []
        for line in path.read_text(encoding="utf-8").splitlines():
            parts = line.split()
            if len(parts) < 5:
                continue
            try:
                cx, cy, w, h = (float(v) for v in parts[1:5])
            except ValueError as exc:
                raise TruthError(f"{path}: not a YOLO line: {line!r}") from exc
            rows.append(
                [
                    (cx - w / 2) * width,
                    (cy - h / 2) * height,
                    (cx + w / 2) * width,
                    (cy + h / 2) * height,
                ]
            )
        return FrameTruth(np.array(rows, dtype=np.float64).reshape(-1, 4))


def _read_masks(folder: Path, masks: list[Path]) -> dict[int, FrameTruth]:
    first, last = 0, 10**9
    temporal = folder.parent / "temporalROI.txt"
    if temporal.is_file():
        first, last = (int(v) for v in temporal.read_text(encoding="utf-8").split()[:2])
    truth: dict[int, FrameTruth] = {}
    for path in masks:
        number = _frame_number(path)
        if number is None or not first <= number <= last:
            continue
        mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise TruthError(f"{path}: not a readable mask image")
        truth[number] = mask_truth(mask)
    return truth


def mask_truth(mask: np.ndarray) -> FrameTruth:
    """A motion mask's vehicles: the boxes of 8-connected blobs of moving pixels (pixel edges)."""
    moving = (mask == MASK_MOVING).astype(np.uint8)
    count, _, stats, _ = cv2.connectedComponentsWithStats(moving, connectivity=8)
    boxes = [
        [float(x), float(y), float(x + w), float(y + h)]
        for x, y, w, h, area in stats[1:count]
        if area >= MIN_BLOB_AREA_PX
    ]
    ignore = (mask == MASK_UNKNOWN) | (mask == MASK_OUTSIDE)
    return FrameTruth(
        np.array(boxes, dtype=np.float64).reshape(-1, 4), ignore_mask=ignore, blobs=True
    )


@dataclass
class FrameScore:
    """One frame's outcome: true boxes found or missed, detections true or false."""

    found: list[tuple[F64, F64]] = field(default_factory=list)  # (truth, detection)
    missed: list[F64] = field(default_factory=list)
    false: list[F64] = field(default_factory=list)
    #: Detections of one vehicle of a blob holding several (motion-mask truth only).
    in_blob: list[F64] = field(default_factory=list)
    #: The frame's (width, height) [px]: which true boxes the frame's edge cuts.
    size: tuple[int, int] = (0, 0)


def score_frame(
    detections: F64, scores: F64, truth: FrameTruth, iou_min: float, min_height_px: float
) -> FrameScore:
    """Match one frame's detections to its truth (module docstring)."""
    outcome = FrameScore()
    heights = truth.boxes[:, 3] - truth.boxes[:, 1]
    counted = heights >= min_height_px
    taken = np.zeros(len(truth.boxes), dtype=bool)
    for index in np.argsort(-scores, kind="stable"):
        box = detections[index]
        iou = box_iou(box, truth.boxes) if len(truth.boxes) else np.zeros(0)
        iou[taken] = -1.0
        best = int(np.argmax(iou)) if len(iou) else -1
        if best >= 0 and iou[best] >= iou_min:
            taken[best] = True
            if counted[best]:
                outcome.found.append((truth.boxes[best], box))
            continue
        if box[3] - box[1] < min_height_px or _on_ignored(box, truth):
            continue
        inside = _share_inside(box, truth.boxes) if truth.blobs else np.zeros(0)
        if len(inside) and inside.max() >= IN_BLOB_SHARE:
            # One of the touching vehicles a motion blob holds: true, and the blob is found.
            blob = int(np.argmax(inside))
            if counted[blob] and not taken[blob]:
                outcome.found.append((truth.boxes[blob], box))
            else:
                outcome.in_blob.append(box)
            taken[blob] = True
            continue
        outcome.false.append(box)
    outcome.missed = [truth.boxes[i] for i in np.flatnonzero(counted & ~taken)]
    return outcome


def cut_by_frame(box: F64, size: tuple[int, int]) -> bool:
    """Whether a true box touches the frame's edge (within :data:`EDGE_MARGIN_PX`): a vehicle
    entering or leaving, only part of it in view."""
    width, height = size
    margin = EDGE_MARGIN_PX
    return bool(
        box[0] <= margin
        or box[1] <= margin
        or box[2] >= width - margin
        or box[3] >= height - margin
    )


def _share_inside(box: F64, boxes: F64) -> F64:
    """The share of ``box``'s area inside each of ``boxes``."""
    ix = np.clip(np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0]), 0, None)
    iy = np.clip(np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1]), 0, None)
    share: F64 = ix * iy / max((box[2] - box[0]) * (box[3] - box[1]), 1e-9)
    return share


def _on_ignored(box: F64, truth: FrameTruth) -> bool:
    if len(truth.ignore_boxes) and _share_inside(box, truth.ignore_boxes).max() >= IGNORED_SHARE:
        return True
    if truth.ignore_mask is not None:
        x1, y1 = max(int(box[0]), 0), max(int(box[1]), 0)
        x2, y2 = int(np.ceil(box[2])), int(np.ceil(box[3]))
        window = truth.ignore_mask[y1:y2, x1:x2]
        return bool(window.size) and float(window.mean()) >= IGNORED_SHARE
    return False


def _bin_of(height: float) -> str:
    """The name of the bin of :data:`HEIGHT_BINS_PX` that a box ``height`` px tall falls in."""
    return HEIGHT_BIN_NAMES[bisect.bisect_right(HEIGHT_BINS_PX, height)]


def summarise(scores: list[FrameScore]) -> dict[str, Any]:
    """Recall and precision overall and by box height."""
    by_bin: dict[str, dict[str, int]] = {}

    def count(box: F64, key: str) -> None:
        bucket = by_bin.setdefault(
            _bin_of(float(box[3] - box[1])), {"tp": 0, "fn": 0, "fp": 0, "tp_det": 0}
        )
        bucket[key] += 1

    for frame in scores:
        for truth, detection in frame.found:
            count(truth, "tp")
            count(detection, "tp_det")
        for box in frame.missed:
            count(box, "fn")
        for box in frame.in_blob:
            count(box, "tp_det")
        for box in frame.false:
            count(box, "fp")
    tp = sum(len(f.found) for f in scores)
    fn = sum(len(f.missed) for f in scores)
    cut_tp = sum(cut_by_frame(truth, f.size) for f in scores for truth, _ in f.found)
    cut_fn = sum(cut_by_frame(box, f.size) for f in scores for box in f.missed)
    fp = sum(len(f.false) for f in scores)
    in_blob = sum(len(f.in_blob) for f in scores)
    bins = {
        name: {
            "vehicles": b["tp"] + b["fn"],
            "recall": _ratio(b["tp"], b["tp"] + b["fn"]),
            "detections": b["tp_det"] + b["fp"],
            "precision": _ratio(b["tp_det"], b["tp_det"] + b["fp"]),
        }
        for name, b in sorted(by_bin.items(), key=lambda item: HEIGHT_BIN_NAMES.index(item[0]))
    }
    return {
        "frames": len(scores),
        "vehicles": tp + fn,
        "found": tp,
        "missed": fn,
        "false": fp,
        "in_blob": in_blob,
        "recall": _ratio(tp, tp + fn),
        "precision": _ratio(tp + in_blob, tp + in_blob + fp),
        "vehicles_inside_frame": tp + fn - cut_tp - cut_fn,
        "recall_inside_frame": _ratio(tp - cut_tp, tp + fn - cut_tp - cut_fn),
        "vehicles_cut_by_edge": cut_tp + cut_fn,
        "recall_cut_by_edge": _ratio(cut_tp, cut_tp + cut_fn),
        "by_height_px": bins,
    }


def _ratio(numerator: int, denominator: int) -> float | None:
    return round(numerator / denominator, 4) if denominator else None


def _detect(backend: ImageBackend, image: U8) -> tuple[F64, F64]:
    found = [d for d in backend.detect(image) if d.class_name in CLASS_SHAPES]
    boxes = np.array([d.box_xyxy_px for d in found], dtype=np.float64).reshape(-1, 4)
    return boxes, np.array([d.score for d in found], dtype=np.float64)


def _picture(image: U8, truth: FrameTruth, outcome: FrameScore) -> U8:
    canvas = image.copy()

    def draw(box: F64, colour: tuple[int, int, int], width: int = 1) -> None:
        x1, y1, x2, y2 = (round(float(v)) for v in box)
        cv2.rectangle(canvas, (x1, y1), (x2 - 1, y2 - 1), colour, width)

    for box in truth.boxes:
        draw(box, (0, 200, 0))
    for _, detection in outcome.found:
        draw(detection, (255, 128, 0))
    for box in outcome.missed:
        draw(box, (0, 165, 255), 2)
    for box in outcome.false:
        draw(box, (0, 0, 255), 2)
    return canvas


def evaluate(
    video: Path,
    truth_path: Path,
    backend: ImageBackend,
    iou_min: float = 0.5,
    min_height_px: float = 20.0,
    pictures: int = 0,
    out: Path | None = None,
    follow: DetectAndFollow | None = None,
    fps: float | None = None,
) -> dict[str, Any]:
    """Score ``backend`` on every frame of ``video`` that has truth (module docstring).

    With ``follow``, what the node publishes is scored instead: every frame goes through
    ``follow`` in order (the detector where it is due at ``fps``, optical flow between, the
    image tracker), and the published tracks' boxes, clipped to the frame, are matched on the
    frames that have truth (by the track's latest detection score).
    """
    truth = read_truth(truth_path)
    scores: list[FrameScore] = []
    worst: list[tuple[int, int, U8]] = []
    rate = fps if fps is not None else _frame_rate(video)
    first: int | None = None
    for number, image in read_frames(video):
        if isinstance(truth, YoloTruth):
            frame_truth = truth.for_image(number, image.shape[1], image.shape[0])
        else:
            frame_truth = truth.get(number)
        if follow is not None:
            first = number if first is None else first
            boxes, box_scores = _followed(follow, image, (number - first) / rate)
        elif frame_truth is None:
            continue
        else:
            boxes, box_scores = _detect(backend, image)
        if frame_truth is None:
            continue
        outcome = score_frame(boxes, box_scores, frame_truth, iou_min, min_height_px)
        outcome.size = (image.shape[1], image.shape[0])
        scores.append(outcome)
        errors = len(outcome.missed) + len(outcome.false)
        if pictures and errors:
            worst.append((errors, number, _picture(image, frame_truth, outcome)))
            worst = sorted(worst, key=lambda item: (-item[0], item[1]))[:pictures]
    if not scores:
        raise TruthError(f"no frame of {video} has truth in {truth_path}")
    summary = summarise(scores)
    if follow is not None:
        summary["tracked"] = {"fps": rate, "detector_runs": follow.detections_run}
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        prefix = "tracked-" if follow is not None else ""
        for errors, number, picture in worst:
            cv2.imwrite(str(out / f"{prefix}frame-{number:06d}-{errors}-errors.jpg"), picture)
    return summary


def _frame_rate(video: Path) -> float:
    """A video file's frame rate (its container's), or :data:`DEFAULT_FOLDER_FPS`."""
    if video.is_dir():
        return DEFAULT_FOLDER_FPS
    capture = cv2.VideoCapture(str(video))
    try:
        rate = float(capture.get(cv2.CAP_PROP_FPS))
    finally:
        capture.release()
    return rate if rate > 0.0 else DEFAULT_FOLDER_FPS


def _followed(follow: DetectAndFollow, image: U8, stamp_s: float) -> tuple[F64, F64]:
    """The boxes the node would publish for this frame, clipped to it, and their scores."""
    step = follow.step(image, stamp_s, follow.due(stamp_s))
    height, width = image.shape[:2]
    boxes = np.array([t.box_xyxy_px for t in step.published], dtype=np.float64).reshape(-1, 4)
    boxes = np.clip(boxes, 0.0, [width, height, width, height])
    return boxes, np.array([t.score for t in step.published], dtype=np.float64)


def markdown(summary: dict[str, Any], title: str) -> str:
    lines = [
        f"# {title}",
        "",
        f"{summary['frames']} frames, {summary['vehicles']} vehicles: recall "
        f"{summary['recall']}, precision {summary['precision']} ({summary['found']} found, "
        f"{summary['missed']} missed, {summary['false']} false, {summary['in_blob']} more "
        "vehicles of merged motion blobs)",
        "",
        f"Vehicles wholly inside the frame: {summary['vehicles_inside_frame']}, recall "
        f"{summary['recall_inside_frame']}; cut by the frame's edge: "
        f"{summary['vehicles_cut_by_edge']}, recall {summary['recall_cut_by_edge']}.",
        "",
        "| box height [px] | vehicles | recall | detections | precision |",
        "|---|---|---|---|---|",
    ]
    if "fog_step" in summary:
        fog = summary["fog_step"]
        lines[6:6] = [
            f"Fog step: {fog['flat_frames']} of {summary['frames']} frames flat (flatness "
            f"below {fog['flat_below']:g}), given local contrast before the model.",
            "",
        ]
    for name, row in summary["by_height_px"].items():
        lines.append(
            f"| {name} | {row['vehicles']} | {row['recall']} | {row['detections']} | "
            f"{row['precision']} |"
        )
    return "\n".join(lines) + "\n"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The real-video options of ``wz eval-camera``."""
    parser.add_argument("--video", type=Path, help="video file or image folder (real video)")
    parser.add_argument("--truth", type=Path, help="MOT file, YOLO folder or mask folder")
    parser.add_argument("--model", type=Path, default=None, help="detector .onnx file")
    parser.add_argument("--backend", choices=["yolo", "background-subtraction"], default=None)
    parser.add_argument("--conf", type=float, default=None, help="minimum score [0-1)")
    parser.add_argument("--iou", type=float, default=0.5, help="IoU of a match (default 0.5)")
    parser.add_argument("--min-height", type=float, default=20.0, help="[px] (default 20)")
    parser.add_argument("--pictures", type=int, default=12, help="frames drawn (default 12)")
    parser.add_argument(
        "--tracked",
        action="store_true",
        help="also score what the node publishes: the detector where it is due, optical flow "
        "between, the image tracker's published tracks (every frame, in order)",
    )
    parser.add_argument(
        "--fps",
        type=float,
        default=None,
        help=f"the clip's frame rate for --tracked [Hz] (default: the video's own; an image "
        f"folder {DEFAULT_FOLDER_FPS:g})",
    )


def run(args: argparse.Namespace) -> int:
    """``wz eval-camera --video ... --truth ...``: 0, or 2 with the reason on stderr."""
    configure_logging(service="eval-camera", site="-", level="INFO")
    if (
        args.truth is None
        or not 0.0 < args.iou <= 1.0
        or args.min_height < 0
        or (args.fps is not None and not 0.0 < args.fps <= 1000.0)
    ):
        sys.stderr.write(
            "wz eval-camera: --video needs --truth; --iou in (0, 1]; --min-height >= 0; "
            "--fps in (0, 1000]\n"
        )
        return 2
    overrides: dict[str, Any] = {}
    if args.model is not None:
        overrides["model_path"] = args.model
    if args.backend is not None:
        overrides["backend"] = args.backend
    if args.conf is not None:
        overrides["conf_threshold"] = args.conf
    try:
        settings = CameraDetectorSettings(**overrides)
        backend = make_backend(settings)
        out = Path(args.out)
        summary = evaluate(
            args.video, args.truth, backend, args.iou, args.min_height, args.pictures, out
        )
        if isinstance(backend, YoloOnnxDetector) and backend.flat_below is not None:
            # the fog step (contrast.py): how many frames were flat and got local contrast
            summary["fog_step"] = {
                "flat_below": backend.flat_below,
                "flat_frames": backend.flat_frames,
            }
        if args.tracked:
            follow = DetectAndFollow(make_backend(settings), settings, frozenset(CLASS_SHAPES))
            summary["published"] = evaluate(
                args.video,
                args.truth,
                follow.backend,
                args.iou,
                args.min_height,
                args.pictures,
                out,
                follow=follow,
                fps=args.fps,
            )
    except (TruthError, ModelLoadError, ValueError, OSError) as exc:
        sys.stderr.write(f"wz eval-camera: {exc}\n")
        return 2
    summary["video"] = str(args.video)
    summary["truth"] = str(args.truth)
    (out / "video-eval.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    text = markdown(summary, f"Camera detector on {args.video.name}, every frame")
    if "published" in summary:
        text += "\n" + markdown(
            summary["published"],
            f"What the node publishes on {args.video.name} (detector where due at "
            f"{summary['published']['tracked']['fps']:g} fps, flow between, tracked)",
        )
    (out / "video-eval.md").write_text(text, encoding="utf-8")
    sys.stdout.write(text)
    return 0
