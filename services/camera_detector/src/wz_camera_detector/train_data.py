"""Training data for the camera model: `wz dataset` frames cropped to the camera's region of interest.

A fixed roadside camera sees the road in a known part of its image: here, the approach lanes
fill the lower right of the frame and the sky the top half. The detector runs on that region of
interest (ROI) only, letterboxed to the model's input, so a small model at a modest input size
keeps the far vehicles (about 15 px wide at 100 m in the 1200 px frame) large enough to find.
The model is trained on the same crops. This module turns a ``wz dataset`` folder into such a
dataset: images cropped to the ROI, YOLO labels re-expressed in the crop, the truth sidecars
kept for evaluation by distance (``truth/``), and ultralytics' ``data.yaml``.

Pure numpy/OpenCV: it runs in the service's environment and in the training one.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

#: A label box clipped by the ROI is kept when at least this share of its area remains.
MIN_KEPT_AREA_SHARE = 0.5
#: A label box smaller than this (either side, px of the crop) is dropped.
MIN_BOX_SIDE_PX = 3.0


@dataclass(frozen=True)
class Roi:
    """Region of interest ``[x0, x1) x [y0, y1)`` in pixels of the full image."""

    x0: int
    y0: int
    x1: int
    y1: int

    def __post_init__(self) -> None:
        if not (0 <= self.x0 < self.x1 and 0 <= self.y0 < self.y1):
            raise ValueError(f"ROI {self.as_tuple()} is empty or negative")

    @property
    def width(self) -> int:
        return self.x1 - self.x0

    @property
    def height(self) -> int:
        return self.y1 - self.y0

    def as_tuple(self) -> tuple[int, int, int, int]:
        return (self.x0, self.y0, self.x1, self.y1)

    @classmethod
    def parse(cls, text: str) -> Roi:
        """``"x0,y0,x1,y1"`` -> Roi."""
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 4:
            raise ValueError(f"ROI {text!r}: expected x0,y0,x1,y1")
        x0, y0, x1, y1 = (int(p) for p in parts)
        return cls(x0, y0, x1, y1)

    def fits(self, width_px: int, height_px: int) -> bool:
        return self.x1 <= width_px and self.y1 <= height_px


def crop_label_lines(lines: list[str], image_size: tuple[int, int], roi: Roi) -> list[str]:
    """YOLO label lines of a full image re-expressed in the ROI crop.

    Parameters
    ----------
    lines
        ``class cx cy w h`` lines, normalised to the full image.
    image_size
        Full image ``(width, height)`` [px].
    roi
        The crop.

    Returns
    -------
    The lines, normalised to the crop, of the boxes that keep at least
    :data:`MIN_KEPT_AREA_SHARE` of their area inside it and are at least
    :data:`MIN_BOX_SIDE_PX` on each side there.
    """
    width, height = image_size
    out = []
    for line in lines:
        fields = line.split()
        if not fields:
            continue
        if len(fields) != 5:
            raise ValueError(f"label line {line!r}: expected 5 fields")
        cls_id = int(fields[0])
        cx, cy, w, h = (float(v) for v in fields[1:])
        x0, x1 = (cx - w / 2) * width, (cx + w / 2) * width
        y0, y1 = (cy - h / 2) * height, (cy + h / 2) * height
        area = max(x1 - x0, 0.0) * max(y1 - y0, 0.0)
        cx0, cx1 = max(x0, roi.x0) - roi.x0, min(x1, roi.x1) - roi.x0
        cy0, cy1 = max(y0, roi.y0) - roi.y0, min(y1, roi.y1) - roi.y0
        cw, ch = cx1 - cx0, cy1 - cy0
        if cw < MIN_BOX_SIDE_PX or ch < MIN_BOX_SIDE_PX or area <= 0:
            continue
        if cw * ch < MIN_KEPT_AREA_SHARE * area:
            continue
        out.append(
            f"{cls_id} {(cx0 + cx1) / 2 / roi.width:.6f} {(cy0 + cy1) / 2 / roi.height:.6f} "
            f"{cw / roi.width:.6f} {ch / roi.height:.6f}"
        )
    return out


def prepare_roi_dataset(
    sources: list[Path],
    dest: Path,
    roi: Roi,
    tiles: tuple[Roi, ...] = (),
    *,
    max_side_px: int | None = None,
    jpeg_quality: int = 95,
) -> dict[str, int]:
    """Write the ROI-cropped union of the ``wz dataset`` folders ``sources`` to ``dest``.

    Each frame gives its ROI crop and, for each of ``tiles`` (the detector's far-field tiles),
    that crop too (``<stem>-tile<i>.jpg``), so the model also learns the magnified far field it
    sees through a tile. Returns counts of images and labels per split. The class names of the
    first source's ``data.yaml`` are kept (all sources must have the same); the manifests are
    gathered in ``dest/manifest.json`` with the ROI and tiles. With ``max_side_px`` (the
    model's input side) a larger crop is shrunk to it before it is written: the letterbox
    would shrink it the same way, and the dataset is smaller (labels are relative, unchanged).
    """
    if not sources:
        raise ValueError("no source dataset")
    names = _names_block((sources[0] / "data.yaml").read_text())
    for source in sources[1:]:
        if _names_block((source / "data.yaml").read_text()) != names:
            raise ValueError(f"{source}: class names differ from {sources[0]}")
    counts: dict[str, int] = {}
    for split in ("train", "val"):
        images = sorted(p for s in sources for p in (s / "images" / split).glob("*.jpg"))
        if len({p.name for p in images}) != len(images):
            raise ValueError(f"{split}: the same image name in two sources (use other seeds)")
        (dest / "images" / split).mkdir(parents=True, exist_ok=True)
        (dest / "labels" / split).mkdir(parents=True, exist_ok=True)
        n_labels = 0
        for image_path in images:
            source = image_path.parents[2]
            image = cv2.imread(str(image_path), cv2.IMREAD_COLOR)
            if image is None:
                raise ValueError(f"{image_path}: not a readable image")
            height, width = image.shape[:2]
            if not roi.fits(width, height):
                raise ValueError(f"{image_path}: ROI {roi.as_tuple()} exceeds {width}x{height}")
            label_path = source / "labels" / split / f"{image_path.stem}.txt"
            lines = label_path.read_text().splitlines() if label_path.exists() else []
            for suffix, region in [("", roi)] + [(f"-tile{i}", t) for i, t in enumerate(tiles)]:
                if not region.fits(width, height):
                    raise ValueError(
                        f"{image_path}: region {region.as_tuple()} exceeds {width}x{height}"
                    )
                crop = np.ascontiguousarray(image[region.y0 : region.y1, region.x0 : region.x1])
                stem = f"{image_path.stem}{suffix}"
                side = max(crop.shape[:2])
                written = crop
                if max_side_px is not None and side > max_side_px:
                    scale = max_side_px / side
                    size = (round(crop.shape[1] * scale), round(crop.shape[0] * scale))
                    written = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
                cv2.imwrite(
                    str(dest / "images" / split / f"{stem}.jpg"),
                    written,
                    [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality],
                )
                cropped = crop_label_lines(lines, (width, height), region)
                n_labels += len(cropped)
                (dest / "labels" / split / f"{stem}.txt").write_text(
                    "".join(f"{line}\n" for line in cropped)
                )
        counts[f"images_{split}"] = len(images) * (1 + len(tiles))
        counts[f"labels_{split}"] = n_labels
        for source in sources:
            truth = source / "truth" / split
            if truth.is_dir():
                shutil.copytree(truth, dest / "truth" / split, dirs_exist_ok=True)
    (dest / "data.yaml").write_text(
        f"# ROI {roi.as_tuple()} crops of {', '.join(str(s) for s in sources)}\n"
        f"path: {dest.resolve()}\ntrain: images/train\nval: images/val\n{names}"
    )
    manifests = [
        json.loads((s / "manifest.json").read_text())
        for s in sources
        if (s / "manifest.json").exists()
    ]
    manifest = {
        "roi_xyxy_px": list(roi.as_tuple()),
        "tiles_xyxy_px": [list(t.as_tuple()) for t in tiles],
        "counts": counts,
        "sources": manifests,
    }
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return counts


def _names_block(data_yaml: str) -> str:
    """The ``names:`` block of a data.yaml written by ``wz dataset``."""
    lines = data_yaml.splitlines()
    for index, line in enumerate(lines):
        if line.startswith("names:"):
            block = [line]
            block += [following for following in lines[index + 1 :] if following.startswith("  ")]
            return "\n".join(block) + "\n"
    raise ValueError("data.yaml has no names block")
