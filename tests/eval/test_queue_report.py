"""Scoring each lane's queue against the truth (wz_eval.queue_report): the back's error, the
onset and dissolution delays, false and missed queues, a back beyond the sensors' reach, on
hand-made truth and tracks whose errors are known."""

from __future__ import annotations

import pytest

from tests.alert_service.helpers import SITE, batch, make_track
from wz_eval.queue_report import queue_report
from wz_shared.messages import DriverProfile, TrackBatch, VehicleClass, VehicleTruth

# The default site: approach [300, 1700) m, lane 0 at offset -1.83 m, lane 1 at +1.83 m.


def vehicle(i: int, station_m: float, speed_mps: float, offset_m: float = -1.83) -> VehicleTruth:
    return VehicleTruth(
        vehicle_id=f"v{i}",
        vehicle_class=VehicleClass.CAR,
        x_m=-offset_m,
        y_m=station_m,
        heading_rad=1.5707963267948966,
        speed_mps=speed_mps,
        accel_mps2=0.0,
        length_m=4.5,
        width_m=1.8,
        height_m=1.5,
        lane_index=0 if offset_m < 0 else 1,
        station_m=station_m,
        offset_m=offset_m,
        driver_profile=DriverProfile.NORMAL,
    )


def queued(t: float, start_s: float, end_s: float) -> bool:
    return start_s <= t < end_s


def story(back_m: float) -> tuple[list, list[TrackBatch]]:
    """60 s at 10 Hz. Truth: lane 0 queued (5 stopped cars from ``back_m``) over [10, 40) s.
    Tracks: the same queue 4 m further upstream over [12, 43) s, and a false queue in lane 1
    over [50, 55) s."""
    truth, batches = [], []
    for k in range(600):
        t = 0.1 * k
        vehicles = [
            vehicle(i, back_m + 9.0 * i, 0.5 if queued(t, 10.0, 40.0) else 20.0) for i in range(5)
        ]
        truth.append((t, vehicles))
        tracks = [
            make_track(i, back_m - 4.0 + 9.0 * i, 0.5 if queued(t, 12.0, 43.0) else 20.0)
            for i in range(5)
        ]
        if queued(t, 50.0, 55.0):
            tracks += [make_track(10 + i, 1000.0 + 9.0 * i, 1.0, offset_m=1.83) for i in range(4)]
        batches.append(batch(t, tracks, k))
    return truth, batches


def test_back_error_onset_dissolution_and_false_queues() -> None:
    truth, batches = story(900.0)
    report = queue_report(SITE, batches, truth, 0.0, 59.9)
    assert report["definition"]["stopped_speed_mps"] == SITE.alerts.queue.stopped_speed_mps
    lane0, lane1 = report["lanes"]["0"], report["lanes"]["1"]
    assert lane0["back_error_m"]["median"] == pytest.approx(4.0)
    assert lane0["back_error_m"]["count"] == 28  # 12..39 s: both queued
    assert (lane0["true_episodes"], lane0["detected_episodes"]) == (1, 1)
    assert lane0["onset_delay_s"]["median"] == pytest.approx(2.0)
    assert lane0["dissolution_delay_s"]["median"] == pytest.approx(3.0)
    assert lane0["false_episodes"] == 0 and lane1["false_episodes"] == 1
    assert lane1["false_queued_s"] == pytest.approx(5.0)
    assert report["false_episodes_per_hour"] == pytest.approx(3600.0 / 59.9, rel=1e-3)
    assert report["onset_delay_s"]["max"] == pytest.approx(2.0)


def test_a_back_beyond_the_reach_is_not_scored_as_an_error() -> None:
    # The default site's sensors see a car to about 782 m upstream. The truth is what they can
    # see (a queue from 770 m: its cars from 788 m), its back at the reach; the tracks' back
    # is there too: not scored as an error, flagged beyond the reach.
    truth, batches = story(770.0)
    lane0 = queue_report(SITE, batches, truth, 0.0, 59.9)["lanes"]["0"]
    assert lane0["back_error_m"]["count"] == 0
    assert lane0["beyond_reach_s"] == 28 and lane0["beyond_reach_flagged_s"] == 28
