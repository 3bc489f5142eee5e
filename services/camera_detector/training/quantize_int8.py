"""Quantise the NanoDet ONNX model to int8 (static, QDQ), calibrated on real traffic frames.

Why: on a CPU with int8 dot-product instructions (x86 VNNI, Arm dot-product) the int8 model runs
about twice as fast as float32 (``BENCHMARKS.md``, ``camera_detection``), and it is a quarter of
the size (4 MB). How: ONNX Runtime's ``quantize_static`` in QDQ form, weights int8 per output
channel, activations uint8, their ranges (MinMax) from calibration frames put through the
detector's own letterbox and normalisation at the model's input size.

The calibration frames are real roadside or overpass pictures in one or more folders (nothing
here is shipped): the shipped model was calibrated on 96 frames, 24 from each of the NGSIM
US-101 camera sequences 1-4 (unlabelled ``images/train`` frames of
https://github.com/IvanGarcia7/NGSIM-Dataset-Annotations; NGSIM video: US DOT FHWA). Frames of
the clips it is scored on (CDnet 2014 highway, GRAM M-30) were kept out. See
``docs/camera-detector.md``.

Run (the project's environment; it has onnxruntime)::

    uv run python services/camera_detector/training/quantize_int8.py \\
        --model nanodet-416.onnx --frames DIR [DIR ...] --per-folder 24 \\
        --out services/camera_detector/src/wz_camera_detector/models/coco-nanodet-g-416-int8.onnx
"""

from __future__ import annotations

import argparse
import logging
import tempfile
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import onnx
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process

from wz_camera_detector import nanodet
from wz_camera_detector.yolo import fit_letterbox

log = logging.getLogger("quantize_int8")

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}


def calibration_frames(folders: list[Path], per_folder: int) -> list[Path]:
    """``per_folder`` images of each folder, evenly spaced in name order."""
    chosen: list[Path] = []
    for folder in folders:
        images = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not images:
            raise SystemExit(f"{folder}: no images")
        picks = np.linspace(0, len(images) - 1, min(per_folder, len(images))).round()
        chosen += [images[int(i)] for i in sorted(set(picks.tolist()))]
    return chosen


class FrameReader(CalibrationDataReader):
    """The calibration frames as the detector feeds them to the model."""

    def __init__(self, frames: list[Path], side: int) -> None:
        self._inputs: Iterator[dict[str, np.ndarray]] = (
            {"images": nanodet.to_tensor(fit_letterbox(_read(p), (side, side), nanodet.PAD_BGR)[0])}
            for p in frames
        )

    def get_next(self) -> dict[str, np.ndarray] | None:
        return next(self._inputs, None)


def _read(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"{path}: not an image")
    return np.asarray(image, dtype=np.uint8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", type=Path, required=True, help="float32 NanoDet .onnx")
    parser.add_argument("--frames", type=Path, nargs="+", required=True, help="image folders")
    parser.add_argument("--per-folder", type=int, default=24)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--conf",
        type=float,
        default=0.35,
        help="the model's operating score threshold, written to its metadata (default 0.35: "
        "chosen on the CDnet 2014 highway clip, docs/camera-detector.md)",
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    source = onnx.load(str(args.model))
    metadata = {entry.key: entry.value for entry in source.metadata_props}
    if metadata.get("wz_architecture") != "nanodet":
        raise SystemExit(f"{args.model}: not a NanoDet model from nanodet_from_npm.py")
    side = int(metadata["wz_input"])
    frames = calibration_frames(args.frames, args.per_folder)
    with tempfile.TemporaryDirectory() as tmp:
        prepared = Path(tmp) / "prepared.onnx"
        # Symbolic shape inference cannot follow the free input height and width.
        quant_pre_process(str(args.model), str(prepared), skip_symbolic_shape=True)
        quantize_static(
            str(prepared),
            str(args.out),
            FrameReader(frames, side),
            quant_format=QuantFormat.QDQ,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            per_channel=True,
            calibrate_method=CalibrationMethod.MinMax,
        )
    quantized = onnx.load(str(args.out))
    del quantized.metadata_props[:]
    metadata["wz_quantization"] = (
        f"int8 static QDQ (weights int8 per channel, activations uint8, MinMax) on "
        f"{len(frames)} frames of {', '.join(str(f) for f in args.frames)}"
    )
    metadata["wz_conf_threshold"] = repr(args.conf)
    for key, value in metadata.items():
        quantized.metadata_props.add(key=key, value=value)
    onnx.save(quantized, str(args.out))
    log.info("wrote %s (%.1f MB) from %d calibration frames", args.out,
             args.out.stat().st_size / 1e6, len(frames))  # fmt: skip


if __name__ == "__main__":
    main()
