"""A rendered camera frame and its truth: per-vehicle labels (2D box, class, visibility),
JPEG encoding, and a debugging overlay of the truth boxes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
import numpy.typing as npt

from wz_shared.arrays import I16, U8
from wz_shared.messages import VehicleClass


@dataclass(frozen=True, slots=True)
class CameraTruthLabel:
    """Truth for one vehicle in one frame.

    Attributes
    ----------
    vehicle_id
        The vehicle's id in the frame's truth.
    index
        0-based index in the frame's vehicle list (the id buffer's value; box label - 1).
    vehicle_class
        Car, truck, ...
    box_xyxy_px
        Box of the visible pixels ``(x0, y0, x1, y1)`` in continuous pixel coordinates (pixel
        edges, inside ``[0, W] x [0, H]``); None when no pixel is visible.
    full_box_xyxy_px
        Box of the unoccluded silhouette, clipped to the image; None when outside the image.
    visible_pixels
        Pixels where this vehicle is the nearest surface.
    silhouette_pixels
        Pixels of the vehicle rendered alone (inside the image).
    """

    vehicle_id: str
    index: int
    vehicle_class: VehicleClass
    box_xyxy_px: tuple[float, float, float, float] | None
    full_box_xyxy_px: tuple[float, float, float, float] | None
    visible_pixels: int
    silhouette_pixels: int

    @property
    def visibility(self) -> float:
        """``visible_pixels / silhouette_pixels`` (0 when the silhouette is empty)."""
        if self.silhouette_pixels <= 0:
            return 0.0
        return self.visible_pixels / self.silhouette_pixels


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One rendered frame with its truth.

    Attributes
    ----------
    stamp
        Capture time [s].
    image
        BGR image, uint8, shape (H, W, 3).
    labels
        One label per vehicle passed to :meth:`CameraModel.render`, in that order.
    face_buffer
        Index of the vehicle face seen at each pixel (-1: none), shape (H, W); see
        :attr:`id_buffer` for vehicles.
    face_vehicle
        0-based vehicle index of each face, shape (F,).
    """

    stamp: float
    image: U8
    labels: tuple[CameraTruthLabel, ...]
    face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32]
    face_vehicle: I16

    @cached_property
    def id_buffer(self) -> I16:
        """0-based index of the vehicle seen at each pixel, -1 where none; int16 (H, W)."""
        lookup = np.append(self.face_vehicle, np.int16(-1)).astype(np.int16)
        ids: I16 = lookup[self.face_buffer]  # face -1 picks the appended -1
        return ids


def mask_box(mask: U8, x0: int, y0: int) -> tuple[float, float, float, float]:
    """Pixel-edge box ``(x0, y0, x1, y1)`` of a mask's non-zero pixels, offset by (x0, y0)."""
    x, y, w, h = cv2.boundingRect(mask)
    return (float(x0 + x), float(y0 + y), float(x0 + x + w), float(y0 + y + h))


def encode_jpeg(image: U8, quality: int = 90) -> bytes:
    """JPEG bytes of a BGR uint8 image (H, W, 3); ``quality`` 1-100."""
    if not 1 <= quality <= 100:
        raise ValueError(f"JPEG quality must be 1..100, got {quality}")
    ok, buffer = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} {image.dtype} image as JPEG")
    return bytes(buffer.tobytes())


def draw_truth(image: U8, labels: Sequence[CameraTruthLabel]) -> U8:
    """A copy of ``image`` with each visible vehicle's truth box, id, class and visibility.

    Boxes are green when at least half visible, yellow when less, red below 10 %.
    """
    out = image.copy()
    for label in labels:
        if label.box_xyxy_px is None:
            continue
        x0, y0, x1, y1 = label.box_xyxy_px
        if label.visibility >= 0.5:
            colour = (40, 220, 40)
        elif label.visibility >= 0.1:
            colour = (0, 220, 255)
        else:
            colour = (40, 40, 240)
        top_left = (int(x0), int(y0))
        bottom_right = (max(int(x0), int(x1) - 1), max(int(y0), int(y1) - 1))
        cv2.rectangle(out, top_left, bottom_right, colour, 1, cv2.LINE_8)
        text = f"{label.vehicle_id} {label.vehicle_class.value} {label.visibility:.2f}"
        origin = (int(x0), max(10, int(y0) - 3))
        cv2.putText(out, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(out, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1, cv2.LINE_AA)
    return out
