"""NanoDet's input and output: the COCO-pretrained detector for real cameras.

The model (``models/coco-nanodet-g-416-int8.onnx``, made by ``training/nanodet_from_npm.py``
and ``training/quantize_int8.py``) is RangiLyu's NanoDet-g, trained on COCO's real photographs;
its ONNX metadata says ``wz_architecture: nanodet``. Its I/O:

- input ``images``: float32 (1, 3, H, W), H and W multiples of 32 (trained at 416), BGR,
  ``(pixel - MEAN_BGR) / STD_BGR``;
- outputs ``scores_s{s}`` (1, N_s, 80): class probabilities (after a sigmoid), and
  ``boxdist_s{s}`` (1, N_s, 44): for left, top, right and bottom, 11 logits of the distance
  from the point to that side in strides (generalized focal loss's distribution), for the
  strides s = 8, 16, 32, ``N_s = (H / s) (W / s)``.

Point ``i`` of stride ``s`` is column ``i mod (W / s)``, row ``i div (W / s)``, centred at
``((column + 0.5) s, (row + 0.5) s)`` (the GFL head of NanoDet before NanoDet-Plus); each
distance is the expectation ``sum_k softmax(logits)_k k s``.
"""

from __future__ import annotations

import numpy as np

from wz_shared.arrays import F32, U8, IntP

#: Normalisation of the BGR input (the model's training pipeline).
MEAN_BGR = np.array([103.53, 116.28, 123.675], dtype=np.float32)
STD_BGR = np.array([57.375, 57.12, 58.395], dtype=np.float32)
#: Letterbox padding: the mean colour, i.e. zero after normalisation.
PAD_BGR = (104, 116, 124)
STRIDES = (8, 16, 32)
#: Largest distance bin (11 bins: 0..10 strides).
REG_MAX = 10


def output_names(strides: tuple[int, ...] = STRIDES) -> list[str]:
    """The model's outputs in the order :func:`decode` takes them."""
    return [f"scores_s{s}" for s in strides] + [f"boxdist_s{s}" for s in strides]


def to_tensor(canvas_bgr: U8) -> F32:
    """A letterboxed BGR canvas (h, w, 3) to the normalised NCHW input (1, 3, h, w)."""
    normalised = (canvas_bgr.astype(np.float32) - MEAN_BGR) / STD_BGR
    tensor: F32 = np.ascontiguousarray(normalised.transpose(2, 0, 1)[np.newaxis])
    return tensor


def decode(
    outputs: list[F32],
    input_hw: tuple[int, int],
    conf_threshold: float,
    keep_classes: IntP | None = None,
) -> tuple[F32, F32, IntP]:
    """Scored, classed boxes in input pixels (before NMS), as :func:`yolo.decode` gives them.

    Parameters
    ----------
    outputs
        The model's outputs in :func:`output_names` order.
    input_hw
        The input's ``(h, w)`` [px].
    conf_threshold
        Minimum class score (``score > conf``).
    keep_classes
        Class indices to keep (None: all); each point takes its best kept class.
    """
    height, width = input_hw
    levels = len(outputs) // 2
    bins = np.arange(REG_MAX + 1, dtype=np.float32)
    all_boxes, all_scores, all_classes = [], [], []
    for level, stride in enumerate(STRIDES[:levels]):
        scores = np.asarray(outputs[level], dtype=np.float32)[0]
        if keep_classes is not None:
            scores = scores[:, keep_classes]
        best = np.argmax(scores, axis=1)
        best_score = scores.max(axis=1)
        points = np.flatnonzero(best_score > conf_threshold)
        if points.size == 0:
            continue
        columns = width // stride
        centres = np.stack(
            [(points % columns + 0.5) * stride, (points // columns + 0.5) * stride], axis=1
        ).astype(np.float32)
        logits = np.asarray(outputs[levels + level], dtype=np.float32)[0][points]
        logits = logits.reshape(-1, 4, REG_MAX + 1)
        weights = np.exp(logits - logits.max(axis=2, keepdims=True))
        distances = (weights / weights.sum(axis=2, keepdims=True)) @ bins * np.float32(stride)
        boxes = np.concatenate([centres - distances[:, :2], centres + distances[:, 2:]], axis=1)
        upper = np.array([width, height, width, height], dtype=np.float32)
        all_boxes.append(np.clip(boxes, 0.0, upper))
        all_scores.append(best_score[points])
        classes = best[points] if keep_classes is None else keep_classes[best[points]]
        all_classes.append(classes)
    if not all_boxes:
        return np.zeros((0, 4), np.float32), np.zeros(0, np.float32), np.zeros(0, np.intp)
    return (
        np.concatenate(all_boxes).astype(np.float32),
        np.concatenate(all_scores).astype(np.float32),
        np.concatenate(all_classes).astype(np.intp),
    )
