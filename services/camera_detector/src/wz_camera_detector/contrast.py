"""Fog and haze on real pixels: a flat frame gets local contrast before the model.

Fog and haze lay a veil of scattered light over the scene (Koschmieder: the object's own
radiance falls as ``exp(-beta d)`` and the airlight rises in its place), so a vehicle 100 m
away is a faint, flat patch. A detector trained on COCO's clear photographs scores such
patches low. Contrast-limited adaptive histogram equalisation (CLAHE, Zuiderveld 1994) on
the frame's lightness stretches each region's own grey levels, and gives the faint vehicles
their edges back.

CLAHE on every frame costs precision on clear ones (it sharpens clutter into boxes), so it
runs only on a *flat* frame: one whose edges are weak for its brightness, measured as

    flatness = mean |Laplacian| / mean grey       (grey frame at 640 px on its long side)

(:func:`flatness`). Measured on real frames (2026-11-29, docs/camera-detector.md, "Fog and
haze"): every frame of three clear-day roadside clips scored 0.091 or more (CDnet highway
median 0.134, GRAM M-30 in light haze 0.096, AI City c010 0.174), 95 % of DAWN's 300 fog,
haze and mist photographs less than 0.06 (median 0.018). :data:`FLAT_BELOW` sits between,
with a factor 1.5 to the clear, hazy M-30. On DAWN fog (the held-out half) CLAHE raised
recall from 0.43 to 0.54 for a point of precision; on the clear clips it cost 1-3 points of
precision, which the gate keeps off them.

Nothing here does I/O.
"""

from __future__ import annotations

import cv2
import numpy as np

from wz_shared.arrays import U8

#: A frame whose :func:`flatness` is below this is flat (fog, haze, mist): see the module
#: docstring for where it sits among real frames.
FLAT_BELOW = 0.06
#: The long side [px] the frame is measured at: the statistic depends on resolution (a
#: Laplacian of a sharper picture is larger), so frames of any size are measured alike.
MEASURE_LONG_SIDE_PX = 640
#: CLAHE's contrast limit (OpenCV's clip limit: a histogram bin is clipped at this many times
#: the mean bin) and its grid of regions over the frame.
CLAHE_CLIP_LIMIT = 2.0
CLAHE_GRID = (8, 8)


def flatness(image: U8) -> float:
    """``mean |Laplacian| / mean grey`` of ``image`` (BGR or grey) scaled to
    :data:`MEASURE_LONG_SIDE_PX` on its long side (3x3 Laplacian); 0 for a black frame."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    height, width = grey.shape[:2]
    scale = MEASURE_LONG_SIDE_PX / max(height, width)
    if scale != 1.0:  # up or down: a small frame's edges are spread as a large one's
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    mean = float(np.mean(grey))
    if mean <= 0.0:
        return 0.0
    laplacian = cv2.Laplacian(grey, cv2.CV_32F)
    return float(np.mean(np.abs(laplacian))) / mean


def local_contrast(image_bgr: U8) -> U8:
    """CLAHE on the lightness (L of CIE Lab) of a BGR frame, its colours kept."""
    lab = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2LAB)
    clahe = cv2.createCLAHE(clipLimit=CLAHE_CLIP_LIMIT, tileGridSize=CLAHE_GRID)
    lab[:, :, 0] = clahe.apply(np.ascontiguousarray(lab[:, :, 0]))
    out: U8 = np.asarray(cv2.cvtColor(lab, cv2.COLOR_LAB2BGR), dtype=np.uint8)
    return out
