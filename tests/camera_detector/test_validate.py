"""Model validation scoring: matching with ignored vehicles, AP and recall by hand-made cases."""

from __future__ import annotations

import math

import pytest

from wz_camera_detector.validate import (
    Outcome,
    PredBox,
    TruthBox,
    at_threshold,
    average_precision,
    match_frame,
    range_bin,
    recall_by_group,
)


def _truth(x0: float, cls: str = "car", range_m: float = 50.0, vis: float = 1.0) -> TruthBox:
    return TruthBox((x0, 100.0, x0 + 40.0, 130.0), cls, range_m, vis)


def _pred(x0: float, score: float, cls: str = "car") -> PredBox:
    return PredBox((x0, 100.0, x0 + 40.0, 130.0), cls, score)


def test_ap_of_perfect_detections_is_one_and_of_none_is_zero() -> None:
    assert average_precision([0.9, 0.8], [True, True], 2) == pytest.approx(1.0)
    assert average_precision([], [], 3) == 0.0
    assert math.isnan(average_precision([0.5], [False], 0))


def test_ap_hand_computed() -> None:
    # Ranked: T, F, T with 3 vehicles: recall 1/3 at precision 1, 2/3 at precision 2/3.
    # Envelope: p = 1 on (0, 1/3], 2/3 on (1/3, 2/3]; AP = 1/3 + 2/9 = 5/9.
    assert average_precision([0.9, 0.8, 0.7], [True, False, True], 3) == pytest.approx(5 / 9)


def test_ap_uses_the_precision_envelope() -> None:
    # F, T, T with 2 vehicles: precision 0, 1/2, 2/3 at recall 0, 1/2, 1; envelope 2/3 everywhere.
    assert average_precision([0.9, 0.8, 0.7], [False, True, True], 2) == pytest.approx(2 / 3)


def test_match_each_vehicle_once_by_score_then_iou() -> None:
    truths = [_truth(0.0), _truth(100.0)]
    preds = [_pred(2.0, 0.6), _pred(0.0, 0.9), _pred(101.0, 0.8), _pred(300.0, 0.7)]
    outcome = match_frame(truths, preds, [True, True])
    # 0.9 takes vehicle 0, 0.8 vehicle 1, 0.7 is nowhere (false), 0.6 is a duplicate (false).
    assert list(zip(outcome.scores, outcome.true, strict=True)) == [
        (0.9, True),
        (0.8, True),
        (0.7, False),
        (0.6, False),
    ]
    assert outcome.n_truth == 2
    assert outcome.hit_scores == [0.9, 0.8]


def test_detection_of_an_ignored_vehicle_is_neither_true_nor_false() -> None:
    truths = [_truth(0.0, range_m=150.0), _truth(100.0, vis=0.2), _truth(200.0)]
    scored = [t.range_m <= 100.0 and t.visibility >= 0.5 for t in truths]
    outcome = match_frame(truths, [_pred(0.0, 0.9), _pred(100.0, 0.8)], scored)
    assert outcome.scores == []
    assert outcome.n_truth == 1
    assert outcome.hit_scores == [-math.inf]  # the scored vehicle was missed
    assert at_threshold(outcome, 0.25)["recall"] == 0.0


def test_iou_below_threshold_is_a_miss_and_a_false_positive() -> None:
    # Shifted 20 px of 40: IoU = 20 * 30 / (2 * 1200 - 600) = 1/3.
    outcome = match_frame([_truth(0.0)], [_pred(20.0, 0.9)], [True])
    assert outcome.true == [False]
    assert outcome.hit_scores == [-math.inf]


def test_by_class_needs_the_same_class() -> None:
    outcome = match_frame([_truth(0.0, "truck")], [_pred(0.0, 0.9, "car")], [True], by_class=True)
    assert outcome.true == [False]
    agnostic = match_frame([_truth(0.0, "truck")], [_pred(0.0, 0.9, "car")], [True])
    assert agnostic.true == [True]


def test_threshold_counts_and_recall_by_range_group() -> None:
    outcome = Outcome()
    truths = [_truth(0.0, range_m=10.0), _truth(100.0, range_m=90.0)]
    groups = [range_bin(t.range_m) for t in truths]
    preds = [_pred(0.0, 0.9), _pred(100.0, 0.1), _pred(300.0, 0.5)]
    outcome.extend(match_frame(truths, preds, [True, True], groups=groups))
    counts = at_threshold(outcome, 0.25)
    assert counts == {
        "precision": 0.5,
        "recall": 0.5,
        "true_positives": 1,
        "false_positives": 1,
        "false_negatives": 1,
    }
    assert recall_by_group(outcome, 0.25) == {
        "0-25 m": {"vehicles": 1, "recall": 1.0},
        "75-100 m": {"vehicles": 1, "recall": 0.0},
    }
    assert range_bin(130.0) == ">100 m"


def test_a_small_far_vehicle_detected_a_pixel_off_is_ignored_not_false() -> None:
    far = TruthBox((100.0, 100.0, 106.0, 105.0), "car", 300.0, 1.0)  # ignored: beyond 100 m
    off = PredBox((101.0, 101.0, 108.0, 107.0), "car", 0.8)  # IoU 0.4, 80 % of the truth covered
    assert match_frame([far], [off], [False]).scores == []
    elsewhere = PredBox((200.0, 100.0, 206.0, 105.0), "car", 0.8)
    assert match_frame([far], [elsewhere], [False]).true == [False]
