"""``wz detect-camera``: run the camera detector on image or video files, one JSON line per frame.

Usage (``python -m wz_camera_detector.cli``, or ``wz detect-camera``)::

    wz detect-camera FILE... [--model M.onnx] [--backend yolo|background-subtraction]
                     [--site SITE.yaml] [--camera ID] [--conf 0.25] [--roi x0,y0,x1,y1]
                     [--tiles x0,y0,x1,y1;...] [--no-track] [--rate HZ]

Any camera, any resolution. Without ``--site`` (nor ``WZ_SITE_FILE``) it knows nothing of the
camera: it finds vehicles' boxes on the whole frame (or ``--roi``) and gives no road
positions. With ``--site``, the site's camera (``--camera``) must have taken the frames: its
pose and intrinsics (its calibration file, :mod:`wz_shared.camera_calibration`) range each
box, and the road's geometry gives where the detector looks; frames of another size but the
same aspect ratio are the same picture scaled; a frame of another aspect ratio is an error
line naming both sizes.

Images (``.jpg``, ``.jpeg``, ``.png``, ``.bmp``) are taken in the order given as one sequence;
a video file (anything OpenCV's FFmpeg backend opens: ``.mp4``, ``.avi``, ``.mkv`` ...) gives
its frames in order. Each frame gives one line on stdout::

    {"file": "clip.mp4", "frame": 12, "stamp": 1.2, "width": 1200, "height": 1200,
     "detections": [{"box": [x1, y1, x2, y2], "class": "car", "score": 0.91, "track_id": 3,
                     "published": true,
                     "x": 3.94, "y": 902.31, "station": 902.3, "offset": -1.8, "range": 78.1,
                     "paper_x": 4.01, "paper_y": 904.7}, ...],
     "timings_ms": {"detect": 21.3}}

``box`` is in pixels of the frame (edges, continuous). With ``--site``: ``x, y`` [m, site frame] is the vehicle
centre from the calibrated pinhole model of ``--camera`` in ``--site``: the class's typical
outline (a body on wheels), on the road's heading, fitted to the box
(:func:`wz_camera_detector.world.fit_box_to_ground`); ``paper_x, paper_y`` is the paper's
Eq. 1-2 ground point of the box's bottom centre;
``station, offset`` the centre in the road frame; ``range`` its ground distance from the camera.
Positions are null for a box reaching above the horizon, and for a box cut by the edge of the
detector's view (``"cut": true``: its bottom is not its ground contact), as in the node. ``stamp`` is the video's frame time
[s] (``CAP_PROP_POS_MSEC``), for images the position in the sequence divided by the camera's
rate (``--rate`` without a site). ``track_id`` is the image tracker's id. With tracking (the
default) each line is what the node publishes: the detector runs where it is due by the
frames' stamps (``WZ_CAMERA_DETECTION_PERIOD_S``: every frame of a 10 fps clip, every fourth of
a 30 fps one), optical flow follows the boxes between, and a track appears once confirmed
(:mod:`wz_camera_detector.following`); each line holds the tracks the frame updated, tentative
ones too, ``published`` true for those the node would publish (confirmed, and found by the
detector's latest run or cut by the frame's edge); a box is cut to the frame. ``--no-track``:
the detector on every frame on its own, ``track_id`` and ``published`` null. ``timings_ms.detect`` is that frame's
whole image step (the detector's, or flow's).

A file that cannot be read gives ``{"file": ..., "error": "..."}`` (a video that breaks off
gives that after the frames it had); the other files are still processed and the exit code is
then 1. The model and its parameters come from the node's settings (``WZ_CAMERA_*``) unless
given here; the default is the model shipped with the service. Logs go to stderr.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from pydantic import ValidationError

from wz_camera_detector.following import DetectAndFollow, ImageBackend, cut_by_view
from wz_camera_detector.node import CLASS_SHAPES, make_backend, road_heading_at
from wz_camera_detector.settings import CameraDetectorSettings, camera_mount
from wz_camera_detector.world import box_to_ground, fit_box_to_ground, paper_box_to_ground
from wz_camera_detector.yolo import ImageDetection, ModelLoadError
from wz_shared.arrays import U8
from wz_shared.camera_calibration import CalibrationError
from wz_shared.camera_geometry import PinholeCamera, camera_at_size
from wz_shared.logs import configure_logging
from wz_shared.site import SensorMount, Site, SiteFileError, load_site

log = logging.getLogger("wz_camera_detector.cli")

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}
#: Frame rate of an image sequence without a site's camera [Hz].
DEFAULT_RATE_HZ = 10.0


class InputError(Exception):
    """A file that cannot be read: the message names it."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wz detect-camera",
        description="Detect vehicles in image or video files; one JSON line per frame.",
    )
    parser.add_argument("files", nargs="+", type=Path, help="images and/or video files")
    parser.add_argument("--backend", choices=["yolo", "background-subtraction"], default=None)
    parser.add_argument("--model", type=Path, default=None, help="YOLOv8 .onnx file")
    parser.add_argument("--site", type=Path, default=None, help="site file (camera pose)")
    parser.add_argument("--camera", default=None, help="camera id in the site file")
    parser.add_argument("--conf", type=float, default=None, help="minimum score [0-1)")
    parser.add_argument(
        "--roi",
        default=None,
        help="region of interest x0,y0,x1,y1 [px] (default: the site's road in the image)",
    )
    parser.add_argument(
        "--tiles",
        default=None,
        help="far-field tiles x0,y0,x1,y1;... [px], '' for none (default: from the road)",
    )
    parser.add_argument("--no-track", action="store_true", help="no tracking across frames")
    parser.add_argument(
        "--rate",
        type=_positive_rate,
        default=DEFAULT_RATE_HZ,
        help="frame rate of image sequences without --site [Hz] (default %(default)s)",
    )
    return parser


def _positive_rate(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0.0 < value <= 1000.0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a frame rate in (0, 1000] Hz")
    return value


def _settings(args: argparse.Namespace) -> CameraDetectorSettings:
    overrides: dict[str, Any] = {}
    if args.backend is not None:
        overrides["backend"] = args.backend
    if args.model is not None:
        overrides["model_path"] = args.model
    if args.site is not None:
        overrides["site_file"] = args.site
    if args.camera is not None:
        overrides["camera_id"] = args.camera
    if args.conf is not None:
        overrides["conf_threshold"] = args.conf
    if args.roi is not None:
        overrides["roi_xyxy_px"] = _box(args.roi, "--roi")
    if args.tiles is not None:
        overrides["tiles_xyxy_px"] = tuple(
            _box(text, "--tiles") for text in args.tiles.split(";") if text.strip()
        )
    return CameraDetectorSettings(**overrides)


def _box(text: str, option: str) -> tuple[int, int, int, int]:
    """``x0,y0,x1,y1`` [px] -> a box; ValueError in words for the operator."""
    try:
        numbers = [int(v) for v in text.split(",")]
    except ValueError:
        numbers = []
    if len(numbers) != 4 or not (0 <= numbers[0] < numbers[2] and 0 <= numbers[1] < numbers[3]):
        raise ValueError(f"{option} {text!r}: expected x0,y0,x1,y1 pixels with x0 < x1, y0 < y1")
    return numbers[0], numbers[1], numbers[2], numbers[3]


def read_frames(path: Path, rate_hz: float, start_index: int) -> Iterator[tuple[int, float, U8]]:
    """``(frame index, stamp [s], BGR image)`` of an image or each frame of a video.

    Raises
    ------
    InputError
        The file is missing, not an image, or a video that cannot be opened or ends in error.
    """
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.suffix.lower() in IMAGE_SUFFIXES:
        data = np.fromfile(path, dtype=np.uint8)
        image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
        if image is None:
            raise InputError(f"{path}: not a decodable image")
        yield start_index, start_index / rate_hz, np.asarray(image, dtype=np.uint8)
        return
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise InputError(f"{path}: not an image, and OpenCV cannot open it as a video")
        index = 0
        while True:
            ok, image = capture.read()
            if not ok or image is None:
                break
            stamp_s = float(capture.get(cv2.CAP_PROP_POS_MSEC)) / 1e3
            yield index, stamp_s, np.asarray(image, dtype=np.uint8)
            index += 1
        if index == 0:
            raise InputError(f"{path}: a video with no readable frame")
    finally:
        capture.release()


class FrameProcessor:
    """Detect, track and range frames of one camera (the node's steps, without radar)."""

    def __init__(
        self,
        site: Site | None,
        mount: SensorMount | None,
        backend: ImageBackend,
        settings: CameraDetectorSettings,
        track: bool,
    ) -> None:
        self.site = site
        self.mount = mount
        self.backend = backend
        #: With tracking: the node's steps (the detector where due, flow between, tracks).
        self.follow = DetectAndFollow(backend, settings, frozenset(CLASS_SHAPES)) if track else None
        self._cameras: dict[tuple[int, int], PinholeCamera] = {}

    def camera(self, width_px: int, height_px: int) -> PinholeCamera | None:
        """The camera's model at this frame size; None without a site (boxes only).

        Raises
        ------
        CalibrationError
            The frame is not the site camera's picture (another aspect ratio).
        """
        if self.mount is None:
            return None
        camera = self._cameras.get((width_px, height_px))
        if camera is None:
            camera = self._cameras[(width_px, height_px)] = camera_at_size(
                self.mount, width_px, height_px
            )
        return camera

    def process(self, image: U8, stamp_s: float) -> tuple[list[dict[str, Any]], float]:
        """Detections of one frame as JSON-ready dicts, and the detector's time [s]."""
        height, width = image.shape[:2]
        camera = self.camera(width, height)
        rows: list[tuple[ImageDetection, int | None, bool | None]]
        started = time.perf_counter()
        if self.follow is not None:
            step = self.follow.step(image, stamp_s, self.follow.due(stamp_s))
            detect_s = time.perf_counter() - started
            published = {t.local_id for t in step.published}
            rows = [
                (
                    ImageDetection(_clipped(t.box_xyxy_px, width, height), t.score, t.class_name),
                    t.local_id,
                    t.local_id in published,
                )
                for t in step.updated
            ]
        else:
            found = self.backend.detect(image)
            detect_s = time.perf_counter() - started
            rows = [(d, None, None) for d in found if d.class_name in CLASS_SHAPES]
        return [self._record(camera, *row) for row in rows], detect_s

    def _record(
        self,
        camera: PinholeCamera | None,
        detection: ImageDetection,
        track_id: int | None,
        published: bool | None,
    ) -> dict[str, Any]:
        _, shape = CLASS_SHAPES[detection.class_name]
        record: dict[str, Any] = {
            "box": [round(v, 1) for v in detection.box_xyxy_px],
            "class": detection.class_name,
            "score": round(detection.score, 4),
            "track_id": track_id,
            "published": published,
        }
        keys = ("x", "y", "station", "offset", "range", "paper_x", "paper_y")
        if camera is None or self.site is None:
            return record | {"cut": None} | dict.fromkeys(keys)
        contact = box_to_ground(camera, detection.box_xyxy_px, 0.0, 0.0, 0.0)
        mount = camera.mount
        record["cut"] = cut_by_view(
            detection.box_xyxy_px, self.backend, camera.width_px, camera.height_px
        )
        if record["cut"] or not all(math.isfinite(v) for v in contact):
            return record | dict.fromkeys(keys)
        heading = road_heading_at(self.site, *contact)
        x_m, y_m = fit_box_to_ground(camera, detection.box_xyxy_px, heading, shape)
        station, offset = self.site.road_frame.to_road(x_m, y_m)
        paper_x, paper_y = paper_box_to_ground(mount, detection.box_xyxy_px)
        values = (
            x_m,
            y_m,
            float(station),
            float(offset),
            math.hypot(x_m - mount.pose.x_m, y_m - mount.pose.y_m),
            paper_x,
            paper_y,
        )
        return record | {
            k: (round(v, 3) if math.isfinite(v) else None)
            for k, v in zip(keys, values, strict=True)
        }


def _clipped(
    box_xyxy_px: tuple[float, float, float, float], width_px: int, height_px: int
) -> tuple[float, float, float, float]:
    """A track's box cut to the frame (a vehicle leaving it is followed past the edge)."""
    x1, y1, x2, y2 = box_xyxy_px
    return (
        min(max(x1, 0.0), width_px),
        min(max(y1, 0.0), height_px),
        min(max(x2, 0.0), width_px),
        min(max(y2, 0.0), height_px),
    )


def run(files: Sequence[Path], processor: FrameProcessor, rate_hz: float) -> int:
    """Write one line per frame of each file; 1 if any file failed, else 0."""
    status = 0
    image_index = 0
    for path in files:
        try:
            is_image = path.suffix.lower() in IMAGE_SUFFIXES
            for index, stamp_s, image in read_frames(path, rate_hz, image_index):
                detections, detect_s = processor.process(image, stamp_s)
                line = {
                    "file": str(path),
                    "frame": index,
                    "stamp": round(stamp_s, 6),
                    "width": int(image.shape[1]),
                    "height": int(image.shape[0]),
                    "detections": detections,
                    "timings_ms": {"detect": round(detect_s * 1e3, 2)},
                }
                sys.stdout.write(json.dumps(line) + "\n")
                sys.stdout.flush()
                if is_image:
                    image_index += 1
        except (InputError, CalibrationError, ValueError, cv2.error) as exc:
            status = 1
            sys.stdout.write(json.dumps({"file": str(path), "error": str(exc)}) + "\n")
            log.warning("%s", exc)
    return status


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        settings = _settings(args)
        site: Site | None = None
        mount: SensorMount | None = None
        if "site_file" in settings.model_fields_set:
            site = load_site(settings.site_file)
            mount = camera_mount(site, settings.camera_id)
        configure_logging(
            service="detect-camera",
            site=site.site_id if site is not None else "-",
            level=settings.log_level,
        )
        if site is None:
            log.info(
                "no --site: boxes only, on the whole frame (give --site SITE.yaml for road "
                "positions and the road's region of interest)"
            )
        backend = make_backend(settings, site, mount)
    except (ValidationError, SiteFileError, ModelLoadError, ValueError) as exc:
        sys.stderr.write(f"wz detect-camera: {exc}\n")
        return 2
    rate_hz = mount.rate_hz if mount is not None else args.rate
    processor = FrameProcessor(site, mount, backend, settings, track=not args.no_track)
    return run(args.files, processor, rate_hz)


if __name__ == "__main__":
    raise SystemExit(main())
