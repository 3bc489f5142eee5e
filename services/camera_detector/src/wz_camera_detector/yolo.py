"""YOLOv8 image detector on ONNX Runtime: letterbox, decode, non-maximum suppression.

The model is a YOLOv8 detector exported by ultralytics to ONNX:

- input ``images``: float32, shape (1, 3, h, w), RGB in [0, 1], the frame letterboxed into
  ``h x w`` (aspect kept, centred, gray 114 padding);
- output ``output0``: float32, shape (1, 4 + C, N): for each of ``N`` candidates the box centre
  and size ``cx, cy, w, h`` [px of the letterboxed input], then ``C`` per-class scores in
  [0, 1] (YOLOv8 has no objectness row).

Pixel coordinates are continuous, as in :mod:`wz_shared.camera_geometry`: the image spans
``[0, W] x [0, H]``, ``u`` to the right and ``v`` down, so a box ``(x1, y1, x2, y2)`` is given by
its pixel edges. Ranging a detection on the road (the paper's Eq. 1-2) is not done here: that
geometry lives in :mod:`wz_shared.camera_geometry` and :mod:`wz_camera_detector.world`.

The model is read from a local file only: a missing, unreadable or mismatched model is a
:class:`ModelLoadError` at start-up, never a download.

A model trained by ``services/camera_detector/training/train.py`` describes itself in its ONNX
metadata: ``wz_class_names`` (comma-separated, in class order) and ``wz_roi_xyxy_px`` (the region
of interest of the camera frame it was trained on: the detector crops the frame to it before
letterboxing). Explicit arguments override both. ultralytics' own ``names`` entry is used for
the class names of other YOLOv8 exports.
"""

from __future__ import annotations

import ast
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import onnxruntime as ort

from wz_camera_detector import nanodet
from wz_camera_detector.contrast import flatness, local_contrast
from wz_shared.arrays import F32, F64, U8, IntP

#: A far-field tile's box closer than this to the tile's edge is a cut vehicle [px].
TILE_EDGE_MARGIN_PX = 2.0

#: Minimum class score of a model that names none (ultralytics' predict default).
DEFAULT_CONF_THRESHOLD = 0.25

#: Gray level of the letterbox padding (ultralytics' convention).
PAD_GRAY = 114

#: A free-size input is padded to a multiple of this (the model's largest stride) [px].
INPUT_STRIDE_PX = 32
#: The top of the whole-frame pyramid of an unknown camera: a vehicle of the 20 px the detector
#: is asked to find becomes 30 px, near four cells of the finest (8 px) stride, from where a
#: COCO-trained detector finds small vehicles reliably. Tuning clip GRAM M-30, recall of
#: vehicles 20-40 px tall with a second pass at 0.75 / 1.0 / 1.25 / 1.5 / 2.0: 0.79 / 0.85 /
#: 0.89 / 0.89 / 0.87.
SMALL_VEHICLE_SCALE = 30.0 / 20.0

#: The small-vehicle pass is never larger than this many input pixels (a 1920x1080 frame at
#: :data:`SMALL_VEHICLE_SCALE` is 4.7 million): a 4K frame is scaled down to it, so that the
#: network's activations stay within a few hundred MB.
MAX_INPUT_PIXELS = 3072 * 1728

#: A pyramid level between the top and the model's own size keeps only boxes at least this tall
#: in its input [px]: a smaller vehicle is twice as large, and better boxed, in the level above
#: (the scale-normalised idea of SNIP, Singh and Davis 2018, applied at inference). GRAM M-30
#: (tuning): precision 0.90 -> 0.94 for the same recall.
LEVEL_MIN_BOX_PX = 32.0

#: Model families the detector reads (ONNX metadata ``wz_architecture``; none: yolov8).
ARCHITECTURES = ("yolov8", "nanodet")
#: Class names that are vehicles (a COCO model's other 76 classes are not looked at).
VEHICLE_CLASSES = frozenset({"car", "vehicle", "truck", "bus", "motorcycle"})

_BOX_ROWS = 4  # cx, cy, w, h

logger = logging.getLogger(__name__)

Box = tuple[int, int, int, int]
#: ``(width, height) -> (ROI or None, far-field tiles)`` [px] for frames of that size.
RegionsForSize = Callable[[int, int], tuple[Box | None, Sequence[Box]]]


class ModelLoadError(RuntimeError):
    """The detector model cannot be used: missing, unreadable, or not the expected model."""


@dataclass(frozen=True, slots=True)
class Letterbox:
    """How a frame was fitted into the network input, and its inverse.

    ``u_input = scale * u_image + pad_x`` and ``v_input = scale * v_image + pad_y`` [px].

    Attributes
    ----------
    scale
        Input pixels per image pixel (the same on both axes; the aspect ratio is kept).
    pad_x, pad_y
        Padding on the left and top of the input [px of the input].
    image_width_px, image_height_px
        Size of the original frame [px], for clipping boxes mapped back to it.
    """

    scale: float
    pad_x: int
    pad_y: int
    image_width_px: int
    image_height_px: int

    def to_image(self, boxes_xyxy: npt.ArrayLike) -> F64:
        """Map boxes from the letterboxed input back to the original frame.

        Parameters
        ----------
        boxes_xyxy
            Boxes ``(x1, y1, x2, y2)`` [px of the input], shape (K, 4).

        Returns
        -------
        boxes_xyxy_px
            The same boxes [px of the original frame], shape (K, 4), clipped to
            ``[0, W] x [0, H]``.
        """
        boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        pad = np.array([self.pad_x, self.pad_y, self.pad_x, self.pad_y], dtype=np.float64)
        mapped = (boxes - pad) / self.scale
        upper = np.array(
            [self.image_width_px, self.image_height_px, self.image_width_px, self.image_height_px],
            dtype=np.float64,
        )
        clipped: F64 = np.clip(mapped, 0.0, upper)
        return clipped


def letterbox(image_bgr: U8, size: tuple[int, int]) -> tuple[F32, Letterbox]:
    """Fit a frame into the network input: resize keeping the aspect, pad centred with gray 114.

    The scale is ``r = min(h / H, w / W)``; the resized frame is ``round(W r) x round(H r)``
    and the padding is split evenly (the extra pixel of an odd split goes right/bottom).

    Parameters
    ----------
    image_bgr
        Frame, shape (H, W, 3), uint8, BGR (OpenCV order).
    size
        Network input size ``(h, w)`` [px].

    Returns
    -------
    tensor
        Network input, shape (1, 3, h, w), float32, RGB in [0, 1], C-contiguous.
    transform
        The :class:`Letterbox` mapping input pixels back to the frame.
    """
    canvas, transform = fit_letterbox(image_bgr, size, (PAD_GRAY, PAD_GRAY, PAD_GRAY))
    return yolo_tensor(canvas), transform


def yolo_tensor(canvas_bgr: U8) -> F32:
    """A letterboxed BGR canvas (h, w, 3) as YOLOv8's input: (1, 3, h, w), RGB in [0, 1]."""
    chw = canvas_bgr[:, :, ::-1].transpose(2, 0, 1)  # BGR -> RGB, HWC -> CHW
    tensor: F32 = np.ascontiguousarray(chw, dtype=np.float32)[np.newaxis] / np.float32(255.0)
    return tensor


def fit_letterbox(
    image_bgr: U8, size: tuple[int, int], pad_bgr: tuple[int, int, int]
) -> tuple[U8, Letterbox]:
    """The frame resized (aspect kept) and centred on an ``h x w`` canvas of ``pad_bgr``.

    See :func:`letterbox` for the rule; the canvas stays uint8 BGR (H, W, 3).
    """
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3 or image_bgr.dtype != np.uint8:
        raise ValueError(
            f"expected a BGR uint8 frame of shape (H, W, 3), got {image_bgr.dtype} "
            f"of shape {image_bgr.shape}"
        )
    input_h, input_w = size
    image_h, image_w = image_bgr.shape[:2]
    scale = min(input_h / image_h, input_w / image_w)
    resized_w = min(input_w, round(image_w * scale))
    resized_h = min(input_h, round(image_h * scale))
    pad_x = (input_w - resized_w) // 2
    pad_y = (input_h - resized_h) // 2

    if (resized_w, resized_h) == (image_w, image_h):
        resized = image_bgr
    else:
        resized = np.asarray(
            cv2.resize(image_bgr, (resized_w, resized_h), interpolation=cv2.INTER_LINEAR),
            dtype=np.uint8,
        )
    canvas = np.empty((input_h, input_w, 3), dtype=np.uint8)
    canvas[:] = pad_bgr
    canvas[pad_y : pad_y + resized_h, pad_x : pad_x + resized_w] = resized
    transform = Letterbox(
        scale=scale, pad_x=pad_x, pad_y=pad_y, image_width_px=image_w, image_height_px=image_h
    )
    return canvas, transform


def decode(output: npt.ArrayLike, conf_threshold: float) -> tuple[F32, F32, IntP]:
    """Turn the raw YOLOv8 output into scored, classed boxes (before NMS).

    Each candidate takes its best class; candidates whose best score is not above
    ``conf_threshold`` are dropped (ultralytics' rule, ``score > conf``).

    Parameters
    ----------
    output
        Raw model output, shape (1, 4 + C, N): rows ``cx, cy, w, h`` [px of the input], then
        ``C`` class scores.
    conf_threshold
        Minimum class score, in [0, 1).

    Returns
    -------
    boxes_xyxy
        Boxes ``(x1, y1, x2, y2)`` [px of the input], shape (K, 4), float32.
    scores
        Best class score of each box, shape (K,), float32.
    class_ids
        Index of that class, shape (K,).
    """
    raw = np.asarray(output, dtype=np.float32)
    if raw.ndim != 3 or raw.shape[0] != 1 or raw.shape[1] <= _BOX_ROWS:
        raise ValueError(f"expected a YOLOv8 output of shape (1, 4 + C, N), got {raw.shape}")
    candidates = raw[0].T  # (N, 4 + C)
    class_scores = candidates[:, _BOX_ROWS:]
    class_ids: IntP = np.argmax(class_scores, axis=1).astype(np.intp)
    scores: F32 = np.take_along_axis(class_scores, class_ids[:, np.newaxis], axis=1)[:, 0]
    keep = scores > conf_threshold

    cxcywh = candidates[keep, :_BOX_ROWS]
    half_size = cxcywh[:, 2:4] / np.float32(2.0)
    boxes: F32 = np.concatenate(
        [cxcywh[:, 0:2] - half_size, cxcywh[:, 0:2] + half_size], axis=1
    ).astype(np.float32)
    return boxes, scores[keep], class_ids[keep]


def box_iou(box_xyxy: npt.ArrayLike, boxes_xyxy: npt.ArrayLike) -> F64:
    """Intersection over union of one box with many.

    ``IoU = area(A and B) / (area(A) + area(B) - area(A and B))``, areas from pixel edges.

    Parameters
    ----------
    box_xyxy
        One box ``(x1, y1, x2, y2)`` [px], shape (4,).
    boxes_xyxy
        Other boxes [px], shape (K, 4).

    Returns
    -------
    iou
        Shape (K,), in [0, 1]; 0 where the union is empty.
    """
    box = np.asarray(box_xyxy, dtype=np.float64)
    boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    inter_w = np.clip(np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0]), 0.0, None)
    inter_h = np.clip(np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1]), 0.0, None)
    intersection = inter_w * inter_h
    area = max(box[2] - box[0], 0.0) * max(box[3] - box[1], 0.0)
    areas = np.clip(boxes[:, 2] - boxes[:, 0], 0.0, None) * np.clip(
        boxes[:, 3] - boxes[:, 1], 0.0, None
    )
    union = area + areas - intersection
    iou: F64 = np.divide(intersection, union, out=np.zeros_like(intersection), where=union > 0.0)
    return iou


def nms(
    boxes_xyxy: npt.ArrayLike,
    scores: npt.ArrayLike,
    iou_threshold: float,
    class_ids: npt.ArrayLike | None = None,
) -> IntP:
    """Greedy non-maximum suppression.

    Take the best-scoring box left, keep it, drop every remaining box whose IoU with it is above
    ``iou_threshold``; repeat. With ``class_ids``, boxes of different classes never suppress
    each other: each class is shifted to its own region of the plane (by a multiple of the span
    of all coordinates plus one) so that boxes of different classes cannot overlap.

    Parameters
    ----------
    boxes_xyxy
        Boxes ``(x1, y1, x2, y2)`` [px], shape (K, 4).
    scores
        Scores, shape (K,).
    iou_threshold
        IoU above which the lower-scoring box is suppressed, in [0, 1].
    class_ids
        Optional class index of each box, shape (K,): suppression per class.

    Returns
    -------
    kept
        Indices into the inputs of the boxes kept, shape (M,), by decreasing score (ties keep
        input order).
    """
    boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
    score_values = np.asarray(scores, dtype=np.float64).reshape(-1)
    if len(score_values) != len(boxes):
        raise ValueError(f"{len(boxes)} boxes but {len(score_values)} scores")
    if len(boxes) == 0:
        return np.zeros(0, dtype=np.intp)
    if class_ids is not None:
        classes = np.asarray(class_ids, dtype=np.float64).reshape(-1)
        if len(classes) != len(boxes):
            raise ValueError(f"{len(boxes)} boxes but {len(classes)} class ids")
        span = float(boxes.max() - boxes.min()) + 1.0
        boxes = boxes + (classes * span)[:, np.newaxis]

    order: IntP = np.argsort(-score_values, kind="stable")
    kept: list[int] = []
    while len(order) > 0:
        best = int(order[0])
        kept.append(best)
        rest = order[1:]
        order = rest[box_iou(boxes[best], boxes[rest]) <= iou_threshold]
    return np.array(kept, dtype=np.intp)


@dataclass(frozen=True, slots=True)
class ImageDetection:
    """One object found in a frame.

    Attributes
    ----------
    box_xyxy_px
        Box ``(x1, y1, x2, y2)`` [px of the original frame], pixel edges, clipped to the frame.
    score
        Class score, in [0, 1].
    class_name
        One of the detector's ``class_names``.
    """

    box_xyxy_px: tuple[float, float, float, float]
    score: float
    class_name: str


@dataclass(frozen=True, slots=True)
class DetectionTimings:
    """Wall-clock time of each step of one :meth:`YoloOnnxDetector.detect_with_timings` [s]."""

    preprocess_s: float
    inference_s: float
    postprocess_s: float

    @property
    def total_s(self) -> float:
        """Sum of the three steps [s]."""
        return self.preprocess_s + self.inference_s + self.postprocess_s


def _static_dim(dim: object) -> int | None:
    """An ONNX dimension as an int, or None where it is symbolic or unknown."""
    return dim if isinstance(dim, int) and dim > 0 else None


class YoloOnnxDetector:
    """A YOLOv8 ONNX model on ONNX Runtime's CPU provider.

    Parameters
    ----------
    model_path
        Local ``.onnx`` file; nothing is ever downloaded.
    class_names
        Class names in the model's class order; their number must match the model's ``C``.
        Default: from the model's metadata (``wz_class_names``, else ultralytics' ``names``).
    input_size
        Network input ``(h, w)`` [px]. Default: read from the model (required if the model's
        spatial input dimensions are dynamic; must agree with them if they are static).
    conf_threshold
        Minimum class score of a detection, in [0, 1). Default: the model's metadata
        ``wz_conf_threshold`` (its operating point, chosen on data it is not scored on), else
        :data:`DEFAULT_CONF_THRESHOLD`.
    iou_threshold
        IoU above which a lower-scoring box of the same class is suppressed, in [0, 1].
    threads
        ONNX Runtime intra-op threads.
    max_detections
        At most this many detections per frame (the best-scoring ones).
    roi_xyxy_px
        Region of interest ``(x0, y0, x1, y1)`` [px of the frame]: the frame is cropped to it
        before letterboxing; boxes are returned in the whole frame's pixels. Default: the
        model's ``wz_roi_xyxy_px`` metadata, else the whole frame.
    tiles_xyxy_px
        Extra regions, each run through the model on its own (an extra inference each) and
        merged by NMS with the ROI's detections: a small far-field tile is magnified by the
        letterbox, so distant vehicles reach the sizes the model finds reliably. A tile's box
        touching the tile's edge is dropped (a cut vehicle, seen whole in the ROI). Default:
        the model's ``wz_tiles_xyxy_px`` metadata (``x0,y0,x1,y1;...``), else none.
    flat_below
        A frame whose flatness (:func:`~wz_camera_detector.contrast.flatness`) is below this
        (fog, haze) gets local contrast (CLAHE on its lightness) before the model; None
        (the default): never.

    Raises
    ------
    ModelLoadError
        The file is missing or unreadable, is not a valid ONNX model, or its input/output shapes
        or class count do not match what is expected. The message names the file.
    """

    def __init__(
        self,
        model_path: Path | str,
        class_names: Sequence[str] | None = None,
        input_size: tuple[int, int] | None = None,
        conf_threshold: float | None = None,
        iou_threshold: float = 0.5,
        threads: int = 2,
        max_detections: int = 300,
        roi_xyxy_px: tuple[int, int, int, int] | None = None,
        tiles_xyxy_px: Sequence[tuple[int, int, int, int]] | None = None,
        flat_below: float | None = None,
    ) -> None:
        if class_names is not None and not class_names:
            raise ValueError("class_names is empty: give the model's class names in its order")
        if conf_threshold is not None and not 0.0 <= conf_threshold < 1.0:
            raise ValueError(f"conf_threshold must be in [0, 1), got {conf_threshold}")
        if not 0.0 <= iou_threshold <= 1.0:
            raise ValueError(f"iou_threshold must be in [0, 1], got {iou_threshold}")
        if threads < 1 or max_detections < 1:
            raise ValueError(
                f"threads and max_detections must be >= 1, got {threads}, {max_detections}"
            )
        self.model_path = Path(model_path)
        self.iou_threshold = iou_threshold
        #: A frame whose :func:`~wz_camera_detector.contrast.flatness` is below this (fog,
        #: haze) gets local contrast before the model; None: never.
        self.flat_below = flat_below
        #: Whether the latest frame was flat (and so given local contrast).
        self.last_flat = False
        #: Frames given local contrast so far.
        self.flat_frames = 0
        self.max_detections = max_detections

        self._session = self._open_session(threads)
        self.metadata: dict[str, str] = dict(self._session.get_modelmeta().custom_metadata_map)
        self.conf_threshold = (
            conf_threshold if conf_threshold is not None else self._metadata_conf_threshold()
        )
        #: ``yolov8`` (ultralytics' export, the default) or ``nanodet`` (metadata
        #: ``wz_architecture``): how the input is made and the output read.
        self.architecture = self.metadata.get("wz_architecture", "yolov8")
        if self.architecture not in ARCHITECTURES:
            raise self._fail(
                f"its metadata wz_architecture {self.architecture!r} is not one of {ARCHITECTURES}"
            )
        self.class_names = (
            tuple(class_names) if class_names is not None else self._metadata_class_names()
        )
        self.roi_xyxy_px: tuple[int, int, int, int] | None = None
        self.tiles_xyxy_px: tuple[tuple[int, int, int, int], ...] = ()
        self.set_regions(
            roi_xyxy_px if roi_xyxy_px is not None else self._metadata_roi(),
            tiles_xyxy_px if tiles_xyxy_px is not None else self._metadata_tiles(),
        )
        self.input_size = self._check_input(input_size)
        #: A model whose input height and width are free (NanoDet) gets each region at its own
        #: aspect (padded to a multiple of :data:`INPUT_STRIDE_PX` only), not a square.
        self.free_input = self.architecture == "nanodet" and self._free_input_dims
        #: Vehicle classes only (NanoDet's COCO has 80), suppressed across classes: a COCO
        #: model often gives one vehicle both a car and a truck box.
        self._keep_classes: IntP | None = None
        self.class_agnostic_nms = self.architecture == "nanodet"
        if self.architecture == "nanodet":
            self._keep_classes = np.array(
                [i for i, name in enumerate(self.class_names) if name in VEHICLE_CLASSES],
                dtype=np.intp,
            )
        self._regions_for: RegionsForSize | None = None
        self._regions_size: tuple[int, int] | None = None
        self._check_output()
        logger.info(
            "loaded YOLO model %s: input %dx%d, %d classes",
            self.model_path,
            self.input_size[1],
            self.input_size[0],
            len(self.class_names),
        )

    def set_regions(
        self,
        roi_xyxy_px: tuple[int, int, int, int] | None,
        tiles_xyxy_px: Sequence[tuple[int, int, int, int]],
    ) -> None:
        """Look at ``roi_xyxy_px`` (None: the whole frame) and these far-field tiles [px].

        Raises
        ------
        ValueError
            For an empty or negative box.
        """
        for tile in tiles_xyxy_px:
            if not (0 <= tile[0] < tile[2] and 0 <= tile[1] < tile[3]):
                raise ValueError(f"tile {tile} is empty or negative")
        if roi_xyxy_px is not None:
            x0, y0, x1, y1 = roi_xyxy_px
            if not (0 <= x0 < x1 and 0 <= y0 < y1):
                raise ValueError(f"ROI {roi_xyxy_px} is empty or negative")
        self.roi_xyxy_px = roi_xyxy_px
        self.tiles_xyxy_px = tuple(tiles_xyxy_px)

    def follow_frame_size(self, regions_for: RegionsForSize, size: tuple[int, int]) -> None:
        """Look where ``regions_for(width, height)`` says, for each frame size met.

        A camera may stream another size than its site file says (a scaled picture): the
        regions are computed again, once per size, at the first frame of that size. ``size``
        ``(width, height)`` [px]: the frames expected, whose regions are set now.
        """
        self._regions_for = regions_for
        self._regions_size = None
        self._fit_regions(*size)

    def _fit_regions(self, width_px: int, height_px: int) -> None:
        if self._regions_for is None or self._regions_size == (width_px, height_px):
            return
        roi, tiles = self._regions_for(width_px, height_px)
        self.set_regions(roi, tiles)
        self._regions_size = (width_px, height_px)

    def _metadata_class_names(self) -> tuple[str, ...]:
        text = self.metadata.get("wz_class_names")
        if text:
            return tuple(name.strip() for name in text.split(","))
        text = self.metadata.get("names")
        if text:
            try:
                names = ast.literal_eval(text)
                return tuple(str(names[index]) for index in sorted(names))
            except (ValueError, SyntaxError, TypeError) as error:
                raise self._fail(f"its metadata names {text!r} cannot be read") from error
        raise self._fail("it has no class names in its metadata: give class_names explicitly")

    def _metadata_conf_threshold(self) -> float:
        text = self.metadata.get("wz_conf_threshold")
        if not text:
            return DEFAULT_CONF_THRESHOLD
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not 0.0 <= value < 1.0:
            raise self._fail(f"its metadata wz_conf_threshold {text!r} is not in [0, 1)")
        return value

    def _metadata_tiles(self) -> tuple[tuple[int, int, int, int], ...]:
        text = self.metadata.get("wz_tiles_xyxy_px")
        if not text:
            return ()
        try:
            tiles = []
            for part in text.split(";"):
                x0, y0, x1, y1 = (int(v) for v in part.split(","))
                tiles.append((x0, y0, x1, y1))
        except ValueError as error:
            raise self._fail(f"its metadata tiles {text!r} are not x0,y0,x1,y1;...") from error
        return tuple(tiles)

    def _metadata_roi(self) -> tuple[int, int, int, int] | None:
        text = self.metadata.get("wz_roi_xyxy_px")
        if not text:
            return None
        try:
            x0, y0, x1, y1 = (int(v) for v in text.split(","))
        except ValueError as error:
            raise self._fail(f"its metadata ROI {text!r} is not x0,y0,x1,y1") from error
        return (x0, y0, x1, y1)

    def crop(self, image_bgr: U8) -> tuple[U8, tuple[int, int]]:
        """The frame cut to the ROI (a view), and the ROI's origin ``(x0, y0)`` [px].

        Raises
        ------
        ValueError
            The frame is not an (H, W, 3) image, or does not contain the ROI.
        """
        if image_bgr.ndim != 3 or image_bgr.shape[2] != 3 or image_bgr.size == 0:
            raise ValueError(f"expected an (H, W, 3) image, got shape {image_bgr.shape}")
        if self.roi_xyxy_px is None:
            return image_bgr, (0, 0)
        x0, y0, x1, y1 = self.roi_xyxy_px
        height, width = image_bgr.shape[:2]
        if x1 > width or y1 > height:
            raise ValueError(
                f"frame {width}x{height} does not contain the detector's ROI {self.roi_xyxy_px}"
            )
        return image_bgr[y0:y1, x0:x1], (x0, y0)

    def _fail(self, reason: str) -> ModelLoadError:
        return ModelLoadError(f"camera detector model {self.model_path}: {reason}")

    def _open_session(self, threads: int) -> ort.InferenceSession:
        if not self.model_path.is_file():
            raise self._fail(
                "no such file; export the YOLOv8 model to ONNX and set the model path setting "
                "to it (the detector never downloads a model)"
            )
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        # Threads waiting for work sleep instead of spinning: a spinning pool burns a core
        # between frames that the rest of the edge box's stack needs.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        options.log_severity_level = 3  # errors only: the reason is in our exception
        try:
            return ort.InferenceSession(
                str(self.model_path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as error:  # onnxruntime raises its own pybind exception types
            raise self._fail(f"cannot be loaded as an ONNX model ({error})") from error

    def _check_input(self, input_size: tuple[int, int] | None) -> tuple[int, int]:
        inputs = self._session.get_inputs()
        if len(inputs) != 1:
            raise self._fail(f"expected 1 input (images), found {len(inputs)}")
        model_input = inputs[0]
        shape = list(model_input.shape)
        if model_input.type != "tensor(float)" or len(shape) != 4:
            raise self._fail(
                f"expected a float32 input of shape (1, 3, h, w), found {model_input.type} {shape}"
            )
        batch, channels, height, width = (_static_dim(dim) for dim in shape)
        self._free_input_dims = height is None and width is None
        if batch not in (None, 1) or channels not in (None, 3):
            raise self._fail(f"expected an input of shape (1, 3, h, w), found {shape}")
        self._input_name: str = model_input.name
        if input_size is None and (height is None or width is None) and "wz_input" in self.metadata:
            side = int(self.metadata["wz_input"])
            input_size = (side, side)
        if input_size is None:
            if height is None or width is None:
                raise self._fail(
                    f"its input size is dynamic ({shape}): give input_size=(h, w) explicitly"
                )
            return height, width
        if (height is not None and height != input_size[0]) or (
            width is not None and width != input_size[1]
        ):
            raise self._fail(f"its input is {shape} but input_size={input_size} was asked for")
        return input_size

    def _check_output(self) -> None:
        outputs = self._session.get_outputs()
        if not outputs:
            raise self._fail("the model has no output")
        if self.architecture == "nanodet":
            self._check_nanodet_output([output.name for output in outputs])
            return
        self._output_names: list[str] = [outputs[0].name]
        expected_rows = _BOX_ROWS + len(self.class_names)
        declared_rows = _static_dim(outputs[0].shape[1]) if len(outputs[0].shape) == 3 else None
        if declared_rows is not None and declared_rows != expected_rows:
            raise self._fail(self._class_count_message(declared_rows))
        # Shapes may be symbolic: one run on a blank input settles them (and warms up).
        output = self._test_run()[0]
        if output.ndim != 3 or output.shape[0] != 1:
            raise self._fail(f"expected an output of shape (1, 4 + C, N), found {output.shape}")
        if output.shape[1] != expected_rows:
            raise self._fail(self._class_count_message(output.shape[1]))

    def _check_nanodet_output(self, names: list[str]) -> None:
        expected = nanodet.output_names()
        if sorted(names) != sorted(expected):
            raise self._fail(f"a NanoDet model must output {expected}, found {names}")
        self._output_names = expected
        scores = self._test_run()[0]
        if scores.ndim != 3 or scores.shape[2] != len(self.class_names):
            raise self._fail(
                f"it scores {scores.shape[-1]} classes but {len(self.class_names)} class names "
                "were given"
            )

    def _test_run(self) -> list[F32]:
        """One inference on a blank input (settles symbolic shapes, warms up)."""
        height, width = self.input_size
        blank = np.full((height, width, 3), PAD_GRAY, dtype=np.uint8)
        try:
            return self._run(self._tensor(blank))
        except Exception as error:  # onnxruntime raises its own pybind exception types
            raise self._fail(f"a test inference failed ({error})") from error

    def _class_count_message(self, rows: int) -> str:
        return (
            f"it outputs {rows - _BOX_ROWS} class scores per box but {len(self.class_names)} "
            f"class names were given ({', '.join(self.class_names)})"
        )

    def _run(self, tensor: F32) -> list[F32]:
        outputs = self._session.run(self._output_names, {self._input_name: tensor})
        return [np.asarray(output, dtype=np.float32) for output in outputs]

    def _tensor(self, canvas_bgr: U8) -> F32:
        """A letterboxed BGR canvas as the model's input."""
        if self.architecture == "nanodet":
            return nanodet.to_tensor(canvas_bgr)
        return yolo_tensor(canvas_bgr)

    def _pad_bgr(self) -> tuple[int, int, int]:
        return nanodet.PAD_BGR if self.architecture == "nanodet" else (PAD_GRAY,) * 3

    def _decode(self, outputs: list[F32], input_hw: tuple[int, int]) -> tuple[F32, F32, IntP]:
        if self.architecture == "nanodet":
            return nanodet.decode(outputs, input_hw, self.conf_threshold, self._keep_classes)
        return decode(outputs[0], self.conf_threshold)

    def region_input_size(
        self, height_px: int, width_px: int, scale: float | None = None
    ) -> tuple[int, int]:
        """The model input ``(h, w)`` [px] a region of ``height x width`` pixels is fitted into.

        A fixed-size model: its input. A model with a free input size: the region scaled by
        ``scale``, by default as the square letterbox would scale it (its long side to the
        model's size), padded only to a multiple of :data:`INPUT_STRIDE_PX`.
        """
        if not self.free_input:
            return self.input_size
        if scale is None:
            scale = self._fit_scale(height_px, width_px)
        stride = INPUT_STRIDE_PX
        return (
            max(stride, math.ceil(height_px * scale / stride) * stride),
            max(stride, math.ceil(width_px * scale / stride) * stride),
        )

    def _fit_scale(self, height_px: int, width_px: int) -> float:
        """The scale the square letterbox gives a region: its long side to the model's size."""
        return min(self.input_size[0] / height_px, self.input_size[1] / width_px)

    def pyramid_input_sizes(self, height_px: int, width_px: int) -> list[tuple[int, int]]:
        """The inputs [px] the whole frame of an unknown camera is run at, largest first.

        An image pyramid: the frame enlarged by :data:`SMALL_VEHICLE_SCALE` (a vehicle 20 px
        tall becomes 30 px; within :data:`MAX_INPUT_PIXELS`), then halved level by level while
        a level stays more than a factor sqrt(2) above the model's own size, and the frame at
        the model's own size: each vehicle is near COCO's usual sizes at one level at least,
        and the boxes of all levels are merged by NMS. A fixed-size model: its input alone.
        Tuning clips, against two passes (the model's size and 0.75): recall on GRAM M-30 0.855
        -> 0.924, on four NGSIM views +2 to +24 points, a near-field junction and CDnet
        unchanged, precision within 3 points (docs/camera-detector.md).
        """
        fit = self.region_input_size(height_px, width_px)
        if not self.free_input:
            return [fit]
        fit_scale = self._fit_scale(height_px, width_px)
        level = min(SMALL_VEHICLE_SCALE, math.sqrt(MAX_INPUT_PIXELS / (height_px * width_px)))
        sizes = []
        while level > fit_scale * math.sqrt(2.0):
            sizes.append(self.region_input_size(height_px, width_px, level))
            level /= 2.0
        return [*sizes, fit]

    def detect(self, image_bgr: U8, tiles: bool = True) -> list[ImageDetection]:
        """Detect objects in one frame.

        Parameters
        ----------
        image_bgr
            Frame, shape (H, W, 3), uint8, BGR.
        tiles
            Run the far-field tiles too (False: the ROI, or the whole frame, alone).

        Returns
        -------
        detections
            By decreasing score, boxes in the frame's pixels.
        """
        detections, _ = self.detect_with_timings(image_bgr, tiles)
        return detections

    def detect_with_timings(
        self, image_bgr: U8, tiles: bool = True
    ) -> tuple[list[ImageDetection], DetectionTimings]:
        """:meth:`detect`, plus how long each step took.

        Parameters
        ----------
        image_bgr
            Frame, shape (H, W, 3), uint8, BGR.
        tiles
            Run the far-field tiles too.

        Returns
        -------
        detections
            By decreasing score, boxes in the frame's pixels.
        timings
            Crop + letterbox, inference, and decode + NMS + mapping back [s].

        Raises
        ------
        ValueError
            The frame is not an (H, W, 3) image or does not contain the ROI.
        """
        if image_bgr.ndim == 3:
            self._fit_regions(image_bgr.shape[1], image_bgr.shape[0])
        started = time.perf_counter()
        contrast_s = 0.0
        self.last_flat = False
        if self.flat_below is not None and image_bgr.ndim == 3 and image_bgr.shape[2] == 3:
            # Fog or haze: the frame's lightness given local contrast (contrast.py).
            self.last_flat = flatness(image_bgr) < self.flat_below
            if self.last_flat:
                self.flat_frames += 1
                image_bgr = local_contrast(image_bgr)
            contrast_s = time.perf_counter() - started
        region, origin = self.crop(image_bgr)  # checks the frame's shape
        height, width = image_bgr.shape[:2]
        for tile in self.tiles_xyxy_px:
            if tile[2] > width or tile[3] > height:
                raise ValueError(f"frame does not contain the detector's tile {tile}")
        # The ROI, then each far-field tile: each letterboxed and run on its own. The whole
        # frame of a camera the detector knows nothing of (no ROI): an image pyramid, from a
        # 20 px vehicle at 30 px (far, small ones) to the model's own size (near ones); a level
        # between the two keeps only boxes at least LEVEL_MIN_BOX_PX tall in its input: it is
        # there for vehicles of middle size, a smaller one is seen larger, and boxed better,
        # by the level above. Each pass: pixels, origin, is a tile, input size, least box height.
        if self.roi_xyxy_px is None:
            sizes = self.pyramid_input_sizes(region.shape[0], region.shape[1])
        else:
            sizes = [self.region_input_size(region.shape[0], region.shape[1])]
        passes = [
            (region, origin, False, size, LEVEL_MIN_BOX_PX if 0 < level < len(sizes) - 1 else 0.0)
            for level, size in enumerate(sizes)
        ] + [
            (
                image_bgr[ty0:ty1, tx0:tx1],
                (tx0, ty0),
                True,
                self.region_input_size(ty1 - ty0, tx1 - tx0),
                0.0,
            )
            for tx0, ty0, tx1, ty1 in (self.tiles_xyxy_px if tiles else ())
        ]
        preprocess_s, inference_s, postprocess_s = contrast_s, 0.0, 0.0
        all_boxes, all_scores, all_classes = [], [], []
        for pixels, (x0, y0), is_tile, input_hw, min_box_px in passes:
            started = time.perf_counter()
            canvas, transform = fit_letterbox(pixels, input_hw, self._pad_bgr())
            tensor = self._tensor(canvas)
            preprocess_s += time.perf_counter() - started
            started = time.perf_counter()
            outputs = self._run(tensor)
            inference_s += time.perf_counter() - started
            started = time.perf_counter()
            input_boxes, scores, class_ids = self._decode(outputs, input_hw)
            if min_box_px:
                tall = input_boxes[:, 3] - input_boxes[:, 1] >= min_box_px
                input_boxes, scores, class_ids = input_boxes[tall], scores[tall], class_ids[tall]
            boxes = transform.to_image(input_boxes)
            if is_tile:
                # A box touching the tile's edge is a cut vehicle: the ROI sees it whole.
                margin = TILE_EDGE_MARGIN_PX
                tile_h, tile_w = pixels.shape[:2]
                inside = (
                    (boxes[:, 0] > margin)
                    & (boxes[:, 1] > margin)
                    & (boxes[:, 2] < tile_w - margin)
                    & (boxes[:, 3] < tile_h - margin)
                )
                boxes, scores, class_ids = boxes[inside], scores[inside], class_ids[inside]
            all_boxes.append(boxes + np.array([x0, y0, x0, y0], dtype=np.float64))
            all_scores.append(scores)
            all_classes.append(class_ids)
            postprocess_s += time.perf_counter() - started
        started = time.perf_counter()
        boxes_px = np.concatenate(all_boxes)
        scores = np.concatenate(all_scores)
        class_ids = np.concatenate(all_classes)
        by_class = None if self.class_agnostic_nms else class_ids
        kept = nms(boxes_px, scores, self.iou_threshold, by_class)[: self.max_detections]
        boxes_px = boxes_px[kept]
        detections = [
            ImageDetection(
                box_xyxy_px=(float(box[0]), float(box[1]), float(box[2]), float(box[3])),
                score=float(score),
                class_name=self.class_names[int(class_id)],
            )
            for box, score, class_id in zip(boxes_px, scores[kept], class_ids[kept], strict=True)
        ]
        postprocess_s += time.perf_counter() - started
        timings = DetectionTimings(
            preprocess_s=preprocess_s, inference_s=inference_s, postprocess_s=postprocess_s
        )
        return detections, timings
