"""Scoring alerts against truth on hand-made truth and alerts: a true positive, false positives
(a legal driver, a ghost, a duplicate), a false negative, and the lead time to the taper exactly.

The default site: approach [300, 1700) m, taper start 1000 m, 55 mph (24.59 m/s) from 300 m;
speeding from 60 mph (26.82 m/s) held 1 s. Truth at 20 Hz for 21 s, every vehicle in lane 0:

- ``A`` (aggressive), 29 m/s from 400 m: speeding from 0 s (start 1.0 s); at the taper start at
  600 / 29 = 20.69 s;
- ``B`` (normal), 30 m/s from 300 m: speeding from 0 s, never alerted (a false negative);
  reaches 930 m by 21 s, not the taper;
- ``C`` (normal), 24 m/s from 600 m: legal; at the taper start at 16.67 s.
"""

from __future__ import annotations

import math

import pytest

from tests.alert_service.helpers import SITE
from wz_alert_service.engine import AlertEvent
from wz_alert_service.rules import Finding
from wz_eval.alerts import (
    observed_truth,
    run_alert_engine,
    score_alerts,
    summary_lines,
    taper_arrivals,
    track_follows,
    truth_batches,
    truth_episodes,
)
from wz_shared.messages import (
    Alert,
    AlertPhase,
    AlertSeverity,
    AlertType,
    Detection,
    DetectionBatch,
    DriverProfile,
    VehicleClass,
    VehicleTruth,
)

VEHICLES = {  # id: (start station [m], speed [m/s], profile)
    "A": (400.0, 29.0, DriverProfile.AGGRESSIVE),
    "B": (300.0, 30.0, DriverProfile.NORMAL),
    "C": (600.0, 24.0, DriverProfile.NORMAL),
}
OFFSET_M = -1.83
A_AT_TAPER_S = (1000.0 - 400.0) / 29.0


def car_at(
    vehicle_id: str,
    station_m: float,
    speed_mps: float,
    profile: DriverProfile = DriverProfile.NORMAL,
    accel_mps2: float = 0.0,
) -> VehicleTruth:
    """A car in lane 0 at ``station_m`` (the road runs north along x = -OFFSET_M)."""
    return VehicleTruth(
        vehicle_id=vehicle_id,
        vehicle_class=VehicleClass.CAR,
        x_m=-OFFSET_M,
        y_m=station_m,
        heading_rad=math.pi / 2,
        speed_mps=speed_mps,
        accel_mps2=accel_mps2,
        length_m=4.5,
        width_m=1.8,
        height_m=1.5,
        lane_index=0,
        station_m=station_m,
        offset_m=OFFSET_M,
        driver_profile=profile,
    )


def truth_at(t: float) -> list[VehicleTruth]:
    return [
        car_at(vehicle_id, s0 + v * t, v, profile)
        for vehicle_id, (s0, v, profile) in VEHICLES.items()
    ]


TRUTH = [(k / 20.0, truth_at(k / 20.0)) for k in range(21 * 20 + 1)]


def station(vehicle_id: str, t: float) -> float:
    s0, v, _ = VEHICLES[vehicle_id]
    return s0 + v * t


def alert(
    episode: str,
    stamp: float,
    station_m: float,
    phase: AlertPhase = "start",
    alert_type: AlertType = AlertType.SPEEDING,
) -> Alert:
    return Alert(
        site=SITE.site_id,
        source_id="alert-service",
        stamp=stamp,
        alert_id=f"{episode}-{phase}",
        alert_type=alert_type,
        severity=AlertSeverity.WARNING,
        track_id=7,
        station_m=station_m,
        offset_m=OFFSET_M + 0.3,
        speed_mps=29.0,
        measured_value=29.0,
        threshold_value=26.8,
        description="test",
        phase=phase,
        episode_id=episode,
        onset_stamp=stamp - 1.0,
    )


def test_truth_episodes_are_the_rules_on_the_true_kinematics() -> None:
    speeding = [e for e in truth_episodes(SITE, TRUTH) if e.alert_type is AlertType.SPEEDING]
    assert sorted((e.vehicle_id, e.onset_s, e.start_s, e.end_s) for e in speeding) == [
        ("A", 0.0, pytest.approx(1.0), math.inf),
        ("B", 0.0, pytest.approx(1.0), math.inf),
    ]
    assert taper_arrivals(TRUTH, 1000.0) == {
        "A": pytest.approx(A_AT_TAPER_S, abs=1e-9),  # between two steps: interpolated
        "C": pytest.approx(400.0 / 24.0, abs=1e-9),
    }
    batches, vehicle_of = truth_batches(SITE, TRUTH)
    assert len(batches) == len(TRUTH) and sorted(vehicle_of.values()) == ["A", "B", "C"]


def test_a_true_positive_false_positives_and_a_false_negative() -> None:
    events = [
        alert("ep-a", 1.5, station("A", 1.5) + 0.5),  # A, 0.58 m off: a true positive
        alert("ep-c", 5.0, station("C", 5.0) - 1.0),  # C drives legally: a false positive
        alert("ep-ghost", 6.0, 2000.0),  # no vehicle within 3 m: a false positive
        alert("ep-a2", 10.0, station("A", 10.0)),  # A again, same truth episode: a duplicate
        alert("ep-a2", 12.0, station("A", 12.0), phase="clear"),
    ]
    report = score_alerts(SITE, TRUTH, events)
    speeding = report["speeding"]
    assert {
        k: speeding[k]
        for k in (
            "true_positives",
            "false_positives",
            "false_negatives",
            "duplicates",
            "alerts",
            "truth_episodes",
        )
    } == {
        "true_positives": 1,
        "false_positives": 3,
        "false_negatives": 1,
        "duplicates": 1,
        "alerts": 4,
        "truth_episodes": 2,
    }
    assert speeding["precision"] == pytest.approx(1 / 4)
    assert speeding["recall"] == pytest.approx(1 / 2)
    # A reaches the taper start (1000 m) at 600 / 29 s; its alert started at 1.5 s.
    assert speeding["lead_time_s"] == pytest.approx(A_AT_TAPER_S - 1.5, abs=1e-9)
    assert speeding["lead_time_aggressive_s"] == pytest.approx(A_AT_TAPER_S - 1.5, abs=1e-9)
    assert speeding["lead_time_samples"] == 1
    assert speeding["truth_lead_time_s"] == pytest.approx(A_AT_TAPER_S - 1.0, abs=1e-9)
    # No late-merge truth and no late-merge alert: nothing to score.
    assert report["late_merge"]["precision"] is None and report["late_merge"]["recall"] is None
    assert set(report) == {t.value for t in AlertType}
    assert summary_lines(report)[0].startswith("speeding: precision 0.25, recall 0.50, TP 1")


def test_an_alert_outside_the_slack_of_the_truth_episode_does_not_match() -> None:
    # B's truth episode is open from 0 s to the end; a hard-braking alert on B has no truth.
    events = [alert("ep-b", 3.0, station("B", 3.0), alert_type=AlertType.HARD_BRAKING)]
    braking = score_alerts(SITE, TRUTH, events)["hard_braking"]
    assert (braking["true_positives"], braking["false_positives"]) == (0, 1)
    assert braking["precision"] == 0.0 and braking["recall"] is None


def test_the_engine_on_perfect_tracks_scores_perfectly() -> None:
    batches, _ = truth_batches(SITE, TRUTH)
    events = run_alert_engine(SITE, batches)
    assert all(isinstance(e, AlertEvent) for e in events)
    report = score_alerts(SITE, TRUTH, events)
    scored = {name: e for name, e in report.items() if e["truth_episodes"]}
    assert {"speeding", "aggressive_approach"} <= set(scored)
    for entry in scored.values():
        assert (entry["precision"], entry["recall"], entry["duplicates"]) == (1.0, 1.0, 0)
    # AlertEvents and their messages score alike.
    messages = [e.to_message(SITE.site_id, "alert-service") for e in events]
    assert score_alerts(SITE, TRUTH, messages) == report
    assert isinstance(events[0].finding, Finding)


def test_an_alert_is_about_the_vehicle_its_track_followed() -> None:
    """A track that starts 4 m beside A (a far camera box that took in the next lane) and then
    follows A: its alert is A's, not a ghost, once the scorer knows what the track followed."""
    batches, vehicle_of = truth_batches(SITE, TRUTH)
    track_of_a = next(track for track, vehicle in vehicle_of.items() if vehicle == "A")
    follows = track_follows(batches, TRUTH)
    assert {vehicle for _, vehicle in follows[track_of_a]} == {"A"}
    assert len(follows[track_of_a]) == len(TRUTH)  # every cycle
    off_start = alert("ep-a", 1.5, station("A", 1.5) + 4.0).model_copy(
        update={"track_id": track_of_a}
    )
    clear = alert("ep-a", 8.0, station("A", 8.0), phase="clear").model_copy(
        update={"track_id": track_of_a}
    )
    by_position = score_alerts(SITE, TRUTH, [off_start, clear])["speeding"]
    assert (by_position["true_positives"], by_position["false_positives"]) == (0, 1)
    by_track = score_alerts(SITE, TRUTH, [off_start, clear], follows=follows)["speeding"]
    assert (by_track["true_positives"], by_track["false_positives"]) == (1, 0)
    # A track that followed C during the episode makes the same alert C's: a false positive.
    track_of_c = next(track for track, vehicle in vehicle_of.items() if vehicle == "C")
    on_c = [e.model_copy(update={"track_id": track_of_c}) for e in (off_start, clear)]
    assert score_alerts(SITE, TRUTH, on_c, follows=follows)["speeding"]["false_positives"] == 1


def detections_of(vehicle_id: str, stamps: list[float]) -> list[DetectionBatch]:
    return [
        DetectionBatch(
            site=SITE.site_id,
            source_id="lidar-mast",
            stamp=t,
            frame_index=i,
            detections=[
                Detection(
                    x_m=-OFFSET_M + 0.2,
                    y_m=station(vehicle_id, t) + 0.5,
                    covariance_m2=[0.1, 0.0, 0.0, 0.1],
                    object_class=VehicleClass.CAR,
                    score=0.9,
                )
            ],
        )
        for i, t in enumerate(stamps)
    ]


def test_observed_truth_keeps_the_vehicles_a_sensor_saw_recently() -> None:
    """B is hidden until 12 s (a truck beside it), then seen every 0.1 s; A is seen throughout;
    C never. The truth keeps A always, B from 12 s (and 1 s after its last sighting), never C."""
    seen = detections_of("A", [k / 10.0 for k in range(211)]) + detections_of(
        "B", [12.0 + k / 10.0 for k in range(50)]
    )
    observed = dict(observed_truth(TRUTH, seen))
    ids = {t: {v.vehicle_id for v in vehicles} for t, vehicles in observed.items()}
    assert ids[5.0] == {"A"} and ids[12.0] == {"A", "B"} and ids[17.9] == {"A", "B"}
    assert ids[18.0] == {"A"}, "B's last detection at 16.9 s is more than 1 s old"
    assert all("C" not in vehicles for vehicles in ids.values())
    # Scored on what the sensors saw, B's speeding before 12 s is no longer a miss the chain
    # could have avoided: B's episode starts only once it is seen for the rule's hold.
    speeding = [
        e
        for e in truth_episodes(SITE, list(observed.items()))
        if e.alert_type is AlertType.SPEEDING
    ]
    assert sorted((e.vehicle_id, round(e.onset_s, 2)) for e in speeding) == [
        ("A", 0.0),
        ("B", 12.0),
    ]


def _braking_twice_at(t: float) -> VehicleTruth:
    """``D``: 25 m/s from 300 m, braking at 5 m/s^2 over 2-3 s and again over 6-7 s (down to
    20, then 15 m/s): the second within the hard-braking rule's 5 s cooldown of the first."""

    def speed(u: float) -> float:
        return 25.0 - 5.0 * (min(max(u - 2.0, 0.0), 1.0) + min(max(u - 6.0, 0.0), 1.0))

    steps = max(1, round(t / 0.01))
    station_m = 300.0 + sum(speed((k + 0.5) * t / steps) for k in range(steps)) * t / steps
    braking = 2.0 <= t < 3.0 or 6.0 <= t < 7.0
    return car_at("D", station_m, speed(t), accel_mps2=-5.0 if braking else 0.0)


def test_an_alert_on_a_braking_the_truths_cooldown_hid_is_not_false() -> None:
    """A car brakes hard twice, 4 s apart. On the truth the rule raises the first and its
    5 s cooldown hides the second; an engine that missed the first and alerted on the second
    was right: the alert counts apart (``true_within_truth_cooldown``), in the precision
    and not as a found episode. An alert on the same car while it drives steadily is false."""
    frames = [(k / 20.0, [_braking_twice_at(k / 20.0)]) for k in range(12 * 20 + 1)]
    truths = [e for e in truth_episodes(SITE, frames) if e.alert_type is AlertType.HARD_BRAKING]
    assert [e.vehicle_id for e in truths] == ["D"] and truths[0].start_s < 3.5

    def at(s: float) -> float:
        return _braking_twice_at(s).station_m

    second = [
        alert("ep-d", 6.6, at(6.6), alert_type=AlertType.HARD_BRAKING),
        alert("ep-d", 7.8, at(7.8), phase="clear", alert_type=AlertType.HARD_BRAKING),
    ]
    braking = score_alerts(SITE, frames, second)["hard_braking"]
    assert (braking["true_positives"], braking["false_positives"]) == (0, 0)
    assert braking["true_within_truth_cooldown"] == 1 and braking["alerts"] == 1
    assert braking["precision"] == 1.0 and braking["recall"] == 0.0
    steady = [alert("ep-x", 11.5, at(11.5), alert_type=AlertType.HARD_BRAKING)]
    braking = score_alerts(SITE, frames, steady)["hard_braking"]
    assert braking["false_positives"] == 1 and braking["true_within_truth_cooldown"] == 0
