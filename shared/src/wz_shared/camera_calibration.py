"""Camera calibration files: OpenCV's FileStorage YAML and ROS ``camera_info`` YAML.

A real camera is calibrated once (a checkerboard, ``cv2.calibrateCamera`` or ROS's
``camera_calibration``); the result is a file beside the site file, named by the camera's
``intrinsics.calibration_file``. :func:`read_calibration` reads either format into a
:class:`CameraCalibration`:

- **ROS** ``camera_info`` YAML (``camera_calibration``'s ``ost.yaml``): ``image_width``,
  ``image_height``, ``camera_matrix: {rows: 3, cols: 3, data: [...]}``, ``distortion_model``
  (``plumb_bob``, or ``rational_polynomial`` with k4-k6 zero) and
  ``distortion_coefficients: {data: [k1, k2, p1, p2, k3]}``.
- **OpenCV** FileStorage YAML (``cv::FileStorage``, as the OpenCV calibration sample writes it):
  a ``%YAML:1.0`` header, ``image_width``, ``image_height`` and ``!!opencv-matrix`` nodes
  ``camera_matrix`` and ``distortion_coefficients`` (``{rows, cols, dt, data}``).

Pixel convention: OpenCV and ROS put the centre of the top-left pixel at ``(0, 0)``; this
project's continuous pixel coordinates put it at ``(0.5, 0.5)``
(:mod:`wz_shared.camera_geometry`), so the principal point is shifted by half a pixel on
reading. Pure Python and PyYAML: no OpenCV needed to read a calibration.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

#: OpenCV's FileStorage header (``%YAML:1.0``), which PyYAML's directive parser refuses.
_OPENCV_HEADER = re.compile(r"^%YAML[: ]1\.0\s*$", re.MULTILINE)
#: Distortion coefficients this project's lens model has (OpenCV's first five).
LENS_COEFFICIENTS = 5
#: A frame whose aspect ratio differs from the calibration's by more than this share does not
#: fit it (a scaled stream keeps the aspect; a cropped one does not;
#: :func:`wz_shared.camera_geometry.camera_at_size`).
ASPECT_TOLERANCE = 0.01


class CalibrationError(ValueError):
    """A calibration file that cannot be read or used; the message names the file."""


@dataclass(frozen=True, slots=True)
class CameraCalibration:
    """A camera's intrinsics at its calibrated resolution, in this project's pixel convention.

    Attributes
    ----------
    width_px, height_px
        Image size the calibration was made at [px].
    fx_px, fy_px
        Focal lengths [px].
    cx_px, cy_px
        Principal point [px, continuous: the top-left pixel's centre is (0.5, 0.5)].
    distortion
        ``(k1, k2, p1, p2, k3)`` in OpenCV's Brown-Conrady convention.
    """

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    distortion: tuple[float, float, float, float, float]

    @property
    def horizontal_fov_deg(self) -> float:
        """Horizontal field of view of the ideal pinhole [deg] (``2 atan(W / 2 fx)``)."""
        return math.degrees(2.0 * math.atan(self.width_px / (2.0 * self.fx_px)))


class _OpenCvLoader(yaml.SafeLoader):
    """PyYAML's safe loader that reads ``!!opencv-matrix`` nodes as plain mappings."""


def _opencv_matrix(loader: yaml.SafeLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    return loader.construct_mapping(node, deep=True)


_OpenCvLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)


def read_calibration(path: str | Path) -> CameraCalibration:
    """Read an OpenCV or ROS calibration YAML file.

    Raises
    ------
    CalibrationError
        The file is missing or not YAML, lacks a field, has a matrix of the wrong shape, a
        non-positive focal length, a skewed matrix, or distortion terms this project's lens
        model does not have (k4-k6, a fisheye model). The message names the file and the field.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"camera calibration {path}: cannot be read ({exc})") from exc
    text = _OPENCV_HEADER.sub("", text, count=1)
    try:
        raw = yaml.load(text, Loader=_OpenCvLoader)
    except yaml.YAMLError as exc:
        raise CalibrationError(f"camera calibration {path}: not valid YAML ({exc})") from exc
    if not isinstance(raw, Mapping):
        raise CalibrationError(f"camera calibration {path}: expected a mapping at the top level")
    try:
        return _calibration(raw)
    except CalibrationError as exc:
        raise CalibrationError(f"camera calibration {path}: {exc}") from None


def _calibration(raw: Mapping[str, Any]) -> CameraCalibration:
    width, height = _positive_int(raw, "image_width"), _positive_int(raw, "image_height")
    matrix = _matrix(raw, "camera_matrix", 9)
    fx, skew, cx, zero_a, fy, cy, zero_b, zero_c, one = matrix
    if not (fx > 0.0 and fy > 0.0):
        raise CalibrationError(f"camera_matrix has a focal length <= 0 (fx {fx}, fy {fy})")
    if abs(skew) > 1e-6 * fx or zero_a or zero_b or zero_c or one != 1.0:
        raise CalibrationError(
            "camera_matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got "
            f"{list(matrix)}"
        )
    model = str(raw.get("distortion_model", "plumb_bob"))
    if model not in ("plumb_bob", "rational_polynomial"):
        raise CalibrationError(
            f"distortion_model {model!r} is not supported (plumb_bob or rational_polynomial "
            "with k4-k6 zero: OpenCV's k1, k2, p1, p2, k3)"
        )
    coefficients: list[float] = []
    if raw.get("distortion_coefficients") is not None:
        coefficients = list(_matrix(raw, "distortion_coefficients", None))
    extra = coefficients[LENS_COEFFICIENTS:]
    if any(value != 0.0 for value in extra):
        raise CalibrationError(
            f"distortion_coefficients {coefficients}: terms beyond k1, k2, p1, p2, k3 "
            "(rational or thin-prism) are not supported; recalibrate with OpenCV's default model"
        )
    coefficients = (coefficients + [0.0] * LENS_COEFFICIENTS)[:LENS_COEFFICIENTS]
    k1, k2, p1, p2, k3 = coefficients
    return CameraCalibration(
        width_px=width,
        height_px=height,
        fx_px=fx,
        fy_px=fy,
        cx_px=cx + 0.5,
        cy_px=cy + 0.5,
        distortion=(k1, k2, p1, p2, k3),
    )


def _positive_int(raw: Mapping[str, Any], key: str) -> int:
    value = raw.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise CalibrationError(f"{key} must be a positive integer, got {value!r}")
    return value


def _matrix(raw: Mapping[str, Any], key: str, size: int | None) -> tuple[float, ...]:
    """The ``data`` of a ``{rows, cols, data}`` node (ROS or OpenCV) as finite floats."""
    node = raw.get(key)
    data = node.get("data") if isinstance(node, Mapping) else node
    if not isinstance(data, Sequence) or isinstance(data, str):
        raise CalibrationError(f"{key} must be a matrix with a data list, got {node!r}")
    try:
        values = tuple(float(v) for v in data)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"{key} holds a value that is not a number: {data!r}") from exc
    if not all(math.isfinite(v) for v in values):
        raise CalibrationError(f"{key} holds a value that is not finite: {data!r}")
    if size is not None and len(values) != size:
        raise CalibrationError(f"{key} must hold {size} numbers, got {len(values)}")
    return values
