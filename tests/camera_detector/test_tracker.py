"""Image-plane tracker: stable ids through noise, gaps, low scores and crossings; the Kalman
filter against a hand-computed first update; the association gate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_camera_detector import tracker as tracker_module
from wz_camera_detector.tracker import (
    ImageTrack,
    ImageTracker,
    ImageTrackerSettings,
    iou_matrix,
    match_by_iou,
)
from wz_camera_detector.yolo import ImageDetection

FRAME_PERIOD_S = 1.0 / 30.0


def box(
    cx: float, cy: float, w: float = 80.0, h: float = 50.0
) -> tuple[float, float, float, float]:
    return (cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0)


def detection(
    cx: float, cy: float, score: float = 0.9, class_name: str = "car", w: float = 80.0
) -> ImageDetection:
    return ImageDetection(box_xyxy_px=box(cx, cy, w), score=score, class_name=class_name)


def noisy_box(
    rng: np.random.Generator, cx: float, cy: float, noise_px: float
) -> tuple[float, float, float, float]:
    x1, y1, x2, y2 = (edge + float(rng.normal(0.0, noise_px)) for edge in box(cx, cy))
    return (x1, y1, x2, y2)


def centre(track: ImageTrack) -> tuple[float, float]:
    x1, y1, x2, y2 = track.box_xyxy_px
    return ((x1 + x2) / 2.0, (y1 + y2) / 2.0)


def assert_unique_ids(tracks: list[ImageTrack]) -> None:
    ids = [track.local_id for track in tracks]
    assert len(ids) == len(set(ids))


def test_core_imports_no_bus_or_web_library() -> None:
    assert top_level_imports(tracker_module).isdisjoint({"zenoh", "fastapi", "uvicorn", "requests"})


# ----------------------------------------------------------------------------- settings


def test_settings_refuse_low_threshold_above_high() -> None:
    with pytest.raises(ValueError, match="low_score_threshold"):
        ImageTrackerSettings(low_score_threshold=0.6, high_score_threshold=0.5)


# ----------------------------------------------------------------------------- association


def test_iou_matrix_matches_hand_computed_values() -> None:
    # Two 10x10 boxes offset by 5 px: intersection 50, union 150.
    iou = iou_matrix([[0, 0, 10, 10]], [[5, 0, 15, 10], [20, 20, 30, 30]])
    np.testing.assert_allclose(iou, [[1.0 / 3.0, 0.0]])
    assert iou_matrix(np.zeros((0, 4)), [[0, 0, 1, 1]]).shape == (0, 1)


def test_match_by_iou_is_optimal_and_gated() -> None:
    iou = np.array([[0.9, 0.0], [0.8, 0.1]])
    # Hungarian on 1 - IoU pairs (0, 0) and (1, 1); the gate at 0.2 then drops (1, 1).
    assert match_by_iou(iou, 0.2) == [(0, 0)]
    # Greedy (row 0 takes its best, 0.6) totals 0.6 + 0.3; the optimum swaps: 0.5 + 0.55.
    iou = np.array([[0.6, 0.5], [0.55, 0.3]])
    assert match_by_iou(iou, 0.2) == [(0, 1), (1, 0)]
    assert match_by_iou(np.zeros((0, 3)), 0.2) == []


# ----------------------------------------------------------------------------- Kalman filter


def test_first_update_matches_hand_computed_kalman_gain() -> None:
    settings = ImageTrackerSettings(min_hits=1)
    tracker = ImageTracker(settings)
    dt, shift_px = 0.1, 6.0
    tracker.update([detection(200.0, 100.0)], stamp_s=1.0)
    (track,) = tracker.update([detection(200.0 + shift_px, 100.0)], stamp_s=1.0 + dt)

    # Per axis, (position, velocity) with P0 = diag(sz^2, sv^2) predicted over dt:
    # P11 = sz^2 + dt^2 sv^2 + sa^2 dt^4 / 4, P21 = dt sv^2 + sa^2 dt^3 / 2, S = P11 + sz^2.
    sz2 = settings.measurement_noise_px**2
    sv2 = settings.initial_velocity_std_px_per_s**2
    sa2 = settings.process_noise_accel_px_per_s2**2
    p11 = sz2 + dt**2 * sv2 + sa2 * dt**4 / 4.0
    p21 = dt * sv2 + sa2 * dt**3 / 2.0
    s = p11 + sz2
    assert track.velocity_px_per_s[0] == pytest.approx(p21 / s * shift_px, rel=1e-12)
    assert track.velocity_px_per_s[1] == pytest.approx(0.0, abs=1e-12)
    assert centre(track)[0] == pytest.approx(200.0 + p11 / s * shift_px, rel=1e-12)
    assert track.hits == 2
    assert track.age_s == pytest.approx(dt)
    assert track.time_since_update_s == 0.0


# ----------------------------------------------------------------------------- scenarios


def test_two_vehicles_keep_ids_and_velocity_converges() -> None:
    rng = np.random.default_rng(7)
    tracker = ImageTracker(ImageTrackerSettings())
    starts = {"A": (100.0, 300.0), "B": (1100.0, 500.0)}
    velocities = {"A": (240.0, 30.0), "B": (-180.0, -12.0)}
    ids: dict[str, set[int]] = {"A": set(), "B": set()}
    last: dict[str, ImageTrack] = {}

    for frame in range(50):
        t = frame * FRAME_PERIOD_S
        truth = {
            name: (
                starts[name][0] + velocities[name][0] * t,
                starts[name][1] + velocities[name][1] * t,
            )
            for name in starts
        }
        detections = [
            ImageDetection(
                box_xyxy_px=noisy_box(rng, *truth[name], noise_px=1.0),
                score=float(rng.uniform(0.6, 0.95)),
                class_name="car",
            )
            for name in ("B", "A")
        ]
        tracks = tracker.update(detections, stamp_s=10.0 + t)
        assert len(tracks) == 2
        assert_unique_ids(tracks)
        for track in tracks:
            name = min(truth, key=lambda n: math.dist(truth[n], centre(track)))
            ids[name].add(track.local_id)
            last[name] = track

    assert ids == {"A": {1}, "B": {2}} or ids == {"A": {2}, "B": {1}}
    for name, (vu, vv) in velocities.items():
        estimate = last[name].velocity_px_per_s
        error = math.hypot(estimate[0] - vu, estimate[1] - vv)
        assert error < 0.05 * math.hypot(vu, vv), (name, estimate)
        assert last[name].confirmed
        assert last[name].hits == 50


def run_single(
    tracker: ImageTracker, frames: range, speed_px_per_s: float = 150.0, score: float = 0.9
) -> list[list[ImageTrack]]:
    return [
        tracker.update(
            [detection(200.0 + speed_px_per_s * frame * FRAME_PERIOD_S, 300.0, score)],
            stamp_s=frame * FRAME_PERIOD_S,
        )
        for frame in frames
    ]


def test_short_gap_resumes_the_same_id() -> None:
    tracker = ImageTracker(ImageTrackerSettings(max_age_s=0.5))
    before = run_single(tracker, range(20))
    # 10 frames (0.33 s < 0.5 s) without a detection: the track coasts on its velocity.
    for frame in range(20, 30):
        assert tracker.update([], stamp_s=frame * FRAME_PERIOD_S) == []
    (coasting,) = tracker.tracks()
    assert coasting.time_since_update_s == pytest.approx(10 * FRAME_PERIOD_S)
    after = run_single(tracker, range(30, 40))
    assert {t.local_id for frame in before + after for t in frame} == {1}
    assert after[-1][0].hits == 30


def test_long_gap_starts_a_new_id_never_reusing_the_old() -> None:
    tracker = ImageTracker(ImageTrackerSettings(max_age_s=0.5))
    before = run_single(tracker, range(20))
    # 20 frames (0.67 s > 0.5 s): the old track is deleted.
    for frame in range(20, 40):
        tracker.update([], stamp_s=frame * FRAME_PERIOD_S)
    assert tracker.tracks() == []
    after = run_single(tracker, range(40, 50))
    assert {t.local_id for frame in before for t in frame} == {1}
    assert {t.local_id for frame in after for t in frame} == {2}
    assert not after[0][0].confirmed
    assert after[-1][0].confirmed


def test_low_score_detection_continues_a_track_but_never_starts_one() -> None:
    tracker = ImageTracker(ImageTrackerSettings(high_score_threshold=0.5, low_score_threshold=0.1))
    # Low scores alone: nothing starts.
    assert all(frame == [] for frame in run_single(tracker, range(5), score=0.3))
    assert tracker.tracks() == []
    # Below the low threshold: ignored altogether.
    run_single(tracker, range(5, 8), score=0.05)
    assert tracker.tracks() == []

    run_single(tracker, range(8, 15), score=0.9)
    continued = run_single(tracker, range(15, 25), score=0.3)
    assert all(len(frame) == 1 and frame[0].local_id == 1 for frame in continued)
    assert continued[-1][0].score == pytest.approx(0.3)
    assert continued[-1][0].hits == 17


def test_low_score_detection_does_not_keep_a_tentative_track() -> None:
    tracker = ImageTracker(ImageTrackerSettings(min_hits=3))
    run_single(tracker, range(1), score=0.9)
    assert run_single(tracker, range(1, 3), score=0.3) == [[], []]
    # The tentative track missed a frame (its low-score detection does not count): deleted.
    assert tracker.tracks() == []


def test_one_frame_false_positive_leaves_no_track() -> None:
    tracker = ImageTracker(ImageTrackerSettings(min_hits=3))
    (spawned,) = tracker.update([detection(500.0, 200.0)], stamp_s=0.0)
    assert not spawned.confirmed
    tracker.update([], stamp_s=FRAME_PERIOD_S)
    assert tracker.tracks() == []


def test_crossing_vehicles_of_different_classes_keep_their_ids() -> None:
    rng = np.random.default_rng(11)
    tracker = ImageTracker(ImageTrackerSettings())
    seen: dict[str, set[int]] = {"car": set(), "truck": set()}
    for frame in range(60):
        t = frame * FRAME_PERIOD_S
        # They meet at u = 640 at t = 1 s, their boxes overlapping with IoU 0.5 there.
        car_u, truck_u = 340.0 + 300.0 * t, 940.0 - 300.0 * t
        detections = [
            ImageDetection(
                box_xyxy_px=box(car_u + rng.normal(0, 1), 300.0 + rng.normal(0, 1), h=60.0),
                score=0.9,
                class_name="car",
            ),
            ImageDetection(
                box_xyxy_px=box(truck_u + rng.normal(0, 1), 320.0 + rng.normal(0, 1), h=60.0),
                score=0.8,
                class_name="truck",
            ),
        ]
        tracks = tracker.update(detections, stamp_s=t)
        assert len(tracks) == 2
        assert_unique_ids(tracks)
        for track in tracks:
            truth_u = car_u if track.class_name == "car" else truck_u
            assert abs(centre(track)[0] - truth_u) < 10.0
            seen[track.class_name].add(track.local_id)
    assert seen == {"car": {1}, "truck": {2}}


def test_class_is_the_majority_over_the_history() -> None:
    tracker = ImageTracker(ImageTrackerSettings(min_hits=1))
    classes = ["truck", "car", "car", "truck", "car", "truck", "truck"]
    names = []
    for frame, class_name in enumerate(classes):
        (track,) = tracker.update(
            [detection(300.0, 300.0, class_name=class_name)], stamp_s=frame * FRAME_PERIOD_S
        )
        names.append(track.class_name)
    # Ties go to the most recent class of the tied ones.
    assert names == ["truck", "car", "car", "truck", "car", "truck", "truck"]


def test_out_of_order_and_repeated_stamps_are_refused() -> None:
    tracker = ImageTracker(ImageTrackerSettings())
    tracker.update([detection(300.0, 300.0)], stamp_s=5.0)
    with pytest.raises(ValueError, match="out-of-order"):
        tracker.update([detection(300.0, 300.0)], stamp_s=4.9)
    with pytest.raises(ValueError, match="out-of-order"):
        tracker.update([detection(300.0, 300.0)], stamp_s=5.0)
    with pytest.raises(ValueError, match="finite"):
        tracker.update([], stamp_s=math.nan)
    # A refused frame changes nothing: the next good frame continues the track.
    (track,) = tracker.update([detection(301.0, 300.0)], stamp_s=5.1)
    assert (track.local_id, track.hits) == (1, 2)


def test_empty_frames_are_fine() -> None:
    tracker = ImageTracker(ImageTrackerSettings())
    assert tracker.tracks() == []
    assert tracker.update([], stamp_s=0.0) == []
    assert tracker.update([], stamp_s=0.1) == []
    (track,) = tracker.update([detection(300.0, 300.0)], stamp_s=0.2)
    assert track.local_id == 1
    assert tracker.update([], stamp_s=0.3) == []


def test_ids_are_never_reused_under_random_clutter() -> None:
    rng = np.random.default_rng(3)
    tracker = ImageTracker(ImageTrackerSettings(min_hits=2, max_age_s=0.2))
    retired: set[int] = set()
    live_before: set[int] = set()
    for frame in range(200):
        count = int(rng.integers(0, 6))
        detections = [
            detection(
                float(rng.uniform(0, 1280)), float(rng.uniform(0, 720)), float(rng.uniform(0, 1))
            )
            for _ in range(count)
        ]
        tracks = tracker.update(detections, stamp_s=frame * FRAME_PERIOD_S)
        assert_unique_ids(tracks)
        assert len(tracks) <= count
        live = {track.local_id for track in tracker.tracks()}
        assert live.isdisjoint(retired)
        retired |= live_before - live
        live_before = live


# ------------------------------------------------------- frames the detector skips (flow)


def moving(frame: int, speed_px_per_s: float = 300.0) -> float:
    """The centre column of a vehicle crossing at ``speed_px_per_s``, at ``frame`` [px]."""
    return 200.0 + speed_px_per_s * frame * FRAME_PERIOD_S


def test_flow_carries_tracks_between_detections_and_they_are_reported_followed() -> None:
    """The detector on every fourth frame of 30 fps, flow's boxes on the others: the track
    follows the vehicle on every frame, marked followed where flow moved it."""
    tracker = ImageTracker(ImageTrackerSettings())
    for frame in range(40):
        stamp = frame * FRAME_PERIOD_S
        if frame % 4 == 0:
            reported = tracker.update([detection(moving(frame), 300.0)], stamp)
        else:
            (previous,) = tracker.tracks()
            reported = tracker.update(None, stamp, {previous.local_id: box(moving(frame), 300.0)})
        (track,) = reported
        assert track.followed == (frame % 4 != 0)
        assert centre(track)[0] == pytest.approx(moving(frame), abs=2.0)
    assert track.local_id == 1
    assert track.hits == 10  # detections only
    assert track.velocity_px_per_s[0] == pytest.approx(300.0, rel=0.05)


def test_a_track_flow_loses_coasts_and_is_not_reported() -> None:
    tracker = ImageTracker(ImageTrackerSettings())
    tracker.update([detection(moving(0), 300.0)], 0.0)
    assert tracker.update(None, FRAME_PERIOD_S, {}) == []
    (coasting,) = tracker.tracks()
    assert not coasting.followed


def test_confirmed_at_two_detections_when_flow_followed_it_between() -> None:
    settings = ImageTrackerSettings(min_hits=3, min_hits_followed=2)
    followed = ImageTracker(settings)
    followed.update([detection(moving(0), 300.0)], 0.0)
    for frame in (1, 2, 3):
        (previous,) = followed.tracks()
        followed.update(
            None, frame * FRAME_PERIOD_S, {previous.local_id: box(moving(frame), 300.0)}
        )
    (second,) = followed.update([detection(moving(4), 300.0)], 4 * FRAME_PERIOD_S)
    assert second.hits == 2 and second.confirmed

    # Detections on consecutive frames (nothing between for flow to check): three as before.
    every_frame = ImageTracker(settings)
    results = [
        every_frame.update([detection(moving(f), 300.0)], f * FRAME_PERIOD_S) for f in range(3)
    ]
    assert [frame[0].confirmed for frame in results] == [False, False, True]

    # Flow lost it on one frame between: the two detections alone do not confirm it.
    lost = ImageTracker(settings)
    lost.update([detection(moving(0), 300.0)], 0.0)
    lost.update(None, FRAME_PERIOD_S, {})
    (track,) = lost.update([detection(moving(2), 300.0)], 2 * FRAME_PERIOD_S)
    assert track.hits == 2 and not track.confirmed


def test_a_tentative_track_waits_for_the_detector_and_dies_when_it_misses() -> None:
    """Frames the detector skips do not delete a tentative track; a run that misses it does,
    unless it lies in a far-field tile that run skipped."""
    tracker = ImageTracker(ImageTrackerSettings())
    tracker.update([detection(500.0, 200.0)], 0.0)
    tracker.update(None, FRAME_PERIOD_S)  # no flow either: it coasts, still there
    assert len(tracker.tracks()) == 1
    tile = (450.0, 150.0, 560.0, 260.0)
    tracker.update([], 2 * FRAME_PERIOD_S, unsearched=[tile])
    assert len(tracker.tracks()) == 1
    tracker.update([], 3 * FRAME_PERIOD_S)
    assert tracker.tracks() == []


def test_misses_count_the_detector_runs_since_the_last_detection() -> None:
    tracker = ImageTracker(ImageTrackerSettings(min_hits=1))
    tracker.update([detection(moving(0), 300.0)], 0.0)
    for frame in (1, 2):  # runs that do not find it
        (previous,) = tracker.tracks()
        (track,) = tracker.update(
            [], frame * FRAME_PERIOD_S, {previous.local_id: box(moving(frame), 300.0)}
        )
        assert track.followed and track.misses == frame
    (found,) = tracker.update([detection(moving(3), 300.0)], 3 * FRAME_PERIOD_S)
    assert found.misses == 0 and not found.followed


def test_flow_does_not_keep_a_track_alive_past_max_age() -> None:
    """Flow follows a false box on the background as well as a vehicle: the track still dies
    max_age_s after its last detection."""
    tracker = ImageTracker(ImageTrackerSettings(min_hits=1, max_age_s=0.3))
    tracker.update([detection(400.0, 300.0)], 0.0)
    frame = 1
    while frame * FRAME_PERIOD_S <= 0.3:
        (previous,) = tracker.tracks()
        tracker.update(None, frame * FRAME_PERIOD_S, {previous.local_id: box(400.0, 300.0)})
        frame += 1
    tracker.update(None, frame * FRAME_PERIOD_S, {1: box(400.0, 300.0)})
    assert tracker.tracks() == []


def test_after_flow_a_detection_takes_over() -> None:
    """Flow measures motion from the previous box, so its error stays in every box after it:
    a detection after some flow frames moves the track most of the way to itself (an
    independent measurement of each flow box would hold the track halfway)."""
    tracker = ImageTracker(ImageTrackerSettings(min_hits=1))
    for frame in range(12):
        tracker.update([detection(400.0, 300.0)], frame * FRAME_PERIOD_S)
    for frame in range(12, 15):  # flow drifts 6 px to the left
        (previous,) = tracker.tracks()
        tracker.update(None, frame * FRAME_PERIOD_S, {previous.local_id: box(394.0, 300.0)})
    (track,) = tracker.update([detection(400.0, 300.0)], 15 * FRAME_PERIOD_S)
    assert centre(track)[0] > 394.0 + 0.75 * 6.0


# -------------------------------------------------------- vehicles entering through the edge

VIEW = (0.0, 0.0, 640.0, 480.0)


def entering(width: float, score: float = 0.9) -> ImageDetection:
    """A car coming in through the view's right edge: ``width`` px of it in view."""
    return ImageDetection(
        box_xyxy_px=(640.0 - width, 200.0, 640.0, 240.0), score=score, class_name="car"
    )


def test_a_vehicle_growing_out_of_the_edge_is_confirmed_at_its_second_detection() -> None:
    tracker = ImageTracker(ImageTrackerSettings(min_hits=3))
    tracker.update([entering(20.0)], 0.0, view_xyxy_px=VIEW)
    (track,) = tracker.update([entering(32.0)], 0.1, view_xyxy_px=VIEW)
    assert track.hits == 2 and track.confirmed
    # The same two detections away from the edge: three are needed.
    inside = ImageTracker(ImageTrackerSettings(min_hits=3))
    inside.update([detection(300.0, 220.0, w=20.0)], 0.0, view_xyxy_px=VIEW)
    (track,) = inside.update([detection(300.0, 220.0, w=32.0)], 0.1, view_xyxy_px=VIEW)
    assert track.hits == 2 and not track.confirmed


def test_an_entering_vehicle_flow_follows_out_of_the_edge_is_confirmed_before_a_second_detection() -> (
    None
):
    tracker = ImageTracker(ImageTrackerSettings(min_frames_entering=2))
    tracker.update([entering(20.0)], 0.0, view_xyxy_px=VIEW)
    (first,) = tracker.update(
        None, FRAME_PERIOD_S, {1: entering(26.0).box_xyxy_px}, view_xyxy_px=VIEW
    )
    assert not first.confirmed  # one frame of flow
    (second,) = tracker.update(
        None, 2 * FRAME_PERIOD_S, {1: entering(32.0).box_xyxy_px}, view_xyxy_px=VIEW
    )
    assert second.followed and second.confirmed


def test_a_box_at_the_edge_that_does_not_grow_out_of_it_is_not_confirmed_early() -> None:
    """A vehicle leaving (its box shrinking into the edge), or something that stays put at it."""
    for widths in ((30.0, 24.0, 18.0), (30.0, 30.0, 30.0)):
        tracker = ImageTracker(ImageTrackerSettings(min_hits=3))
        tracker.update([entering(widths[0])], 0.0, view_xyxy_px=VIEW)
        for frame, width in enumerate(widths[1:], start=1):
            (track,) = tracker.update(
                None, frame * FRAME_PERIOD_S, {1: entering(width).box_xyxy_px}, view_xyxy_px=VIEW
            )
        assert not track.confirmed  # (a second detection confirms it: flow followed it)
