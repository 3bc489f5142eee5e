"""The engine: hold, clear and cool-down times, hysteresis (no alert storms), lost tracks,
hard braking on a noisy scripted profile, TTC of a closing follower, the queue's tail, the
messages, and the invariant "never two open episodes per track and type" (hypothesis)."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.alert_service.helpers import SITE, batch, make_track, stamps
from wz_alert_service.engine import AlertEngine, AlertEvent
from wz_alert_service.rules import G_MPS2
from wz_shared import codec
from wz_shared.messages import Alert, AlertSeverity, AlertType, Track, TrackStatus
from wz_shared.site import MPH_TO_MPS

LIMIT_55_MPS = 55.0 * MPH_TO_MPS


def run(
    engine: AlertEngine, times: Sequence[float], tracks_at: Callable[[float], list[Track]]
) -> list[AlertEvent]:
    events: list[AlertEvent] = []
    for k, t in enumerate(times):
        events.extend(engine.update(batch(t, tracks_at(t), k)))
    return events


def of_type(events: Sequence[AlertEvent], alert_type: AlertType) -> list[AlertEvent]:
    return [e for e in events if e.alert_type is alert_type]


def phases(events: Sequence[AlertEvent]) -> list[tuple[str, float]]:
    return [(e.phase, round(e.stamp, 6)) for e in events]


def only(alert_type: AlertType) -> AlertEngine:
    """An engine with every rule but one switched off."""
    update = {
        t.value: getattr(SITE.alerts, t.value).model_copy(update={"enabled": t is alert_type})
        for t in AlertType
    }
    return AlertEngine(SITE, SITE.alerts.model_copy(update=update))


def speeder(
    speed_of: Callable[[float], float], station_m: float = 500.0
) -> Callable[[float], list[Track]]:
    return lambda t: [make_track(1, station_m, speed_of(t))]


# --- hold, clear, cool-down -------------------------------------------------------------------

FAST = LIMIT_55_MPS + 8.0 * MPH_TO_MPS  # 8 mph over: speeding
LEGAL = LIMIT_55_MPS  # at the limit


def test_speeding_starts_after_hold_clears_after_clear_time_and_cools_down() -> None:
    engine = only(AlertType.SPEEDING)

    def speed(t: float) -> float:
        # fast for [0, 5), legal for [5, 8), fast again from 8 s on
        return FAST if t < 5.0 - 1e-9 or t >= 8.0 - 1e-9 else LEGAL

    events = run(engine, stamps(25.0), speeder(speed))
    # hold 1 s: start at 1.0 (onset 0.0); clear 2 s after the first legal batch (5.0): 7.0;
    # cool-down 10 s: no pending before 17.0, so the next start is at 18.0.
    assert phases(events) == [("start", 1.0), ("clear", 7.0), ("start", 18.0)]
    first, clear, second = events
    assert first.onset_stamp == 0.0 and first.evidence["held_s"] == pytest.approx(1.0)
    assert clear.episode_id == first.episode_id and clear.sequence == 1
    assert clear.evidence["duration_s"] == pytest.approx(7.0)
    assert clear.evidence["track_lost"] == 0.0
    assert second.episode_id != first.episode_id and second.onset_stamp == pytest.approx(17.0)
    assert [e.alert_id for e in events] == [
        "speeding-1-1-0",
        "speeding-1-1-1",
        "speeding-1-2-0",
    ]


def test_a_break_shorter_than_the_hold_restarts_it() -> None:
    engine = only(AlertType.SPEEDING)
    # fast except one legal batch at 0.5 s: the hold restarts at 0.55 and ends at 1.55.
    events = run(engine, stamps(3.0), speeder(lambda t: LEGAL if abs(t - 0.5) < 1e-9 else FAST))
    assert phases(events) == [("start", 1.55)]
    assert events[0].onset_stamp == pytest.approx(0.55)


def test_a_track_that_disappears_clears_at_once() -> None:
    engine = only(AlertType.SPEEDING)
    events = run(
        engine, stamps(3.0), lambda t: [make_track(1, 500.0, FAST)] if t < 2.0 - 1e-9 else []
    )
    assert phases(events) == [("start", 1.0), ("clear", 2.0)]
    assert events[1].evidence["track_lost"] == 1.0
    assert "track lost" in events[1].description
    assert engine.active() == []


def test_an_alert_starts_only_on_a_measured_track_not_a_coasting_one() -> None:
    # Fast throughout; the track coasts over [0.9, 1.3): the hold is met at 1.0 while coasting,
    # so the alert waits for the next measured batch (1.3), its onset still the hold's start.
    engine = only(AlertType.SPEEDING)

    def coasting_between(start_s: float, end_s: float) -> Callable[[float], list[Track]]:
        def tracks(t: float) -> list[Track]:
            status = (
                TrackStatus.COASTING
                if start_s - 1e-9 <= t < end_s - 1e-9
                else TrackStatus.CONFIRMED
            )
            return [make_track(1, 500.0, FAST, status=status)]

        return tracks

    events = run(engine, stamps(3.0), coasting_between(0.9, 1.3))
    assert phases(events) == [("start", 1.3)]
    assert events[0].onset_stamp == 0.0
    # A track that meets the hold while coasting and is then deleted never alerts: the
    # short-lived track a wrong camera-radar pairing starts, coasting to its end.
    events = run(
        only(AlertType.SPEEDING),
        stamps(3.0),
        lambda t: (
            []
            if t >= 1.5 - 1e-9
            else [
                make_track(
                    1,
                    500.0,
                    FAST,
                    status=TrackStatus.COASTING if t >= 0.6 - 1e-9 else TrackStatus.CONFIRMED,
                )
            ]
        ),
    )
    assert events == []
    # Once open, coasting neither clears nor holds back the episode.
    events = run(only(AlertType.SPEEDING), stamps(3.0), coasting_between(1.5, 2.5))
    assert phases(events) == [("start", 1.0)]


def test_tentative_tracks_are_not_evaluated() -> None:
    engine = only(AlertType.SPEEDING)
    tentative = make_track(1, 500.0, FAST, status=TrackStatus.TENTATIVE)
    assert run(engine, stamps(3.0), lambda t: [tentative]) == []


def test_an_out_of_order_batch_is_ignored_and_counted() -> None:
    engine = only(AlertType.SPEEDING)
    run(engine, stamps(1.5), speeder(lambda t: FAST))
    assert engine.update(batch(0.5, [make_track(1, 500.0, LEGAL)])) == []
    assert engine.counters.batches_out_of_order == 1
    assert engine.counters.batches == 30 and engine.counters.starts == 1
    assert len(engine.active()) == 1


def test_severity_rise_gives_one_update_and_the_clear_carries_the_peak() -> None:
    engine = only(AlertType.SPEEDING)
    very_fast = LIMIT_55_MPS + 20.0 * MPH_TO_MPS

    def speed(t: float) -> float:
        # warning, critical, warning again, critical again, legal
        bands = [FAST, very_fast, FAST, very_fast, LEGAL]
        return bands[min(int(t // 2.0 + 1e-9), 4)]

    events = run(engine, stamps(14.0), speeder(speed))
    assert phases(events) == [("start", 1.0), ("update", 2.0), ("clear", 10.0)]
    assert [e.severity for e in events] == [
        AlertSeverity.WARNING,
        AlertSeverity.CRITICAL,
        AlertSeverity.CRITICAL,
    ]
    assert [e.sequence for e in events] == [0, 1, 2]


# --- hysteresis: no alert storms ---------------------------------------------------------------


def oscillating(
    centre_mph: float, amplitude_mph: float, period_s: float
) -> Callable[[float], float]:
    """``v(t) = limit + (centre + amplitude sin(2 pi t / period)) mph``."""
    return lambda t: (
        LIMIT_55_MPS
        + (centre_mph + amplitude_mph * math.sin(2.0 * math.pi * t / period_s)) * MPH_TO_MPS
    )


def test_speed_oscillating_around_the_threshold_gives_one_episode() -> None:
    # 4 to 6 mph over (enter at 5, exit below 3), period 4 s: above 5 mph for 2 s of every 4.
    engine = only(AlertType.SPEEDING)
    events = run(engine, stamps(60.0), speeder(oscillating(5.0, 1.0, 4.0)))
    assert [e.phase for e in events] == ["start"]
    assert len(engine.active()) == 1


def test_speed_oscillating_around_the_exit_threshold_keeps_one_episode() -> None:
    # Started at 8 mph over, then 2 to 4 mph over with a period of 1 s: below the exit
    # threshold (3 mph) for 0.5 s at a time, never for the 2 s clear time.
    engine = only(AlertType.SPEEDING)
    swing = oscillating(3.0, 1.0, 1.0)
    events = run(engine, stamps(60.0), speeder(lambda t: FAST if t < 2.0 else swing(t)))
    assert [e.phase for e in events] == ["start"]


def test_without_hysteresis_the_same_oscillation_is_a_storm() -> None:
    """The control: with equal enter/exit thresholds and no hold, clear or cool-down time,
    the oscillation of the test above opens an episode every period."""
    speeding = SITE.alerts.speeding.model_copy(
        update={"hysteresis_mph": 0.0, "hold_s": 0.0, "clear_s": 0.0, "cooldown_s": 0.0}
    )
    rules = SITE.alerts.model_copy(
        update={
            "speeding": speeding,
            **{
                t.value: getattr(SITE.alerts, t.value).model_copy(update={"enabled": False})
                for t in AlertType
                if t is not AlertType.SPEEDING
            },
        }
    )
    events = run(AlertEngine(SITE, rules), stamps(60.0), speeder(oscillating(5.0, 1.0, 4.0)))
    assert sum(e.phase == "start" for e in events) == 15


def test_lane_flicker_at_the_lane_line_gives_one_late_merge() -> None:
    # At 20 m/s from 880 m: in the closed lane (d = 1.83) for 1 s, then riding the lane line
    # for 3 s, its offset jittering within 0.05 +- 0.2 m (lanes 0 and 1 alternate batch by
    # batch), then in the open lane (d = -1.83) from 4 s.
    engine = only(AlertType.LATE_MERGE)
    times = stamps(6.0)
    rng = np.random.default_rng(3)
    jitter = {round(t, 6): float(rng.uniform(-0.2, 0.2)) for t in times}

    def tracks(t: float) -> list[Track]:
        if t < 1.0 - 1e-9:
            offset_m = 1.83
        elif t < 4.0 - 1e-9:
            offset_m = 0.05 + jitter[round(t, 6)]
        else:
            offset_m = -1.83
        return [make_track(1, 880.0 + 20.0 * t, 20.0, offset_m=offset_m)]

    # hold 0.5 s: start at 0.5; clear 1 s after the first batch in the open lane: 5.0.
    assert phases(run(engine, times, tracks)) == [("start", 0.5), ("clear", 5.0)]


# --- hard braking on a scripted constant-deceleration profile ---------------------------------

BRAKE_START_S, BRAKE_END_S, DECEL_MPS2 = 2.0, 5.0, 5.0  # 0.51 g, from 30 m/s to 15 m/s


def braking_speed(t: float) -> float:
    """30 m/s, then -5 m/s^2 from 2 s to 5 s, then 15 m/s."""
    return 30.0 - DECEL_MPS2 * min(max(t - BRAKE_START_S, 0.0), BRAKE_END_S - BRAKE_START_S)


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_hard_braking_detected_on_a_noisy_profile(seed: int) -> None:
    engine = only(AlertType.HARD_BRAKING)
    times = stamps(10.0)
    noise = np.random.default_rng(seed).normal(0.0, 0.3, len(times))  # speed noise 0.3 m/s
    speeds = {
        round(t, 6): max(0.0, braking_speed(t) + n) for t, n in zip(times, noise, strict=True)
    }
    measured: list[float] = []
    events: list[AlertEvent] = []
    for k, t in enumerate(times):
        events.extend(engine.update(batch(t, [make_track(1, 600.0, speeds[round(t, 6)])], k)))
        if BRAKE_START_S + 1.0 <= t < BRAKE_END_S and engine.active():
            measured.append(engine.active()[0].finding.measured_value)
    assert [e.phase for e in events] == ["start", "clear"]
    start, clear = events
    # The 0.8 s window crosses 0.4 g about 0.6 s into the braking; then the 0.3 s hold.
    assert BRAKE_START_S + 0.3 <= start.stamp <= BRAKE_START_S + 1.2
    # Once the window lies inside the braking, the rate is 5 m/s^2 within 0.5 m/s^2 (a window
    # of 16 speeds with 0.3 m/s noise has a slope error of about 0.33 m/s^2, 1 sigma).
    assert len(measured) == 40
    assert float(np.mean(measured)) == pytest.approx(DECEL_MPS2, abs=0.2)
    assert max(abs(m - DECEL_MPS2) for m in measured) < 1.2
    # Clears 1 s after the window's slope fell under 0.35 g, after the braking ended at 5 s.
    assert BRAKE_END_S <= clear.stamp <= BRAKE_END_S + 2.0


def _measured(track: Track, speed_std_mps: float) -> Track:
    """``track`` with the tracker's velocity covariance of a speed known to ``speed_std``."""
    covariance = np.zeros((4, 4))
    covariance[:2, :2] = np.eye(2) * 0.1
    covariance[2:, 2:] = np.eye(2) * speed_std_mps**2
    return track.model_copy(update={"covariance": covariance.reshape(-1).tolist()})


@pytest.mark.parametrize(("speed_std_mps", "alerts"), [(0.3, True), (2.0, False)])
def test_hard_braking_needs_a_speed_measured_well_enough_to_tell_it(
    speed_std_mps: float, alerts: bool
) -> None:
    """The same 5 m/s^2 in the speeds: a track whose speed is known to 0.3 m/s (seen by the
    camera and radar) is braking; one known to 2 m/s (a far vehicle a few LiDAR beams see,
    whose box jumps when the detector changes its mind about its length) swings by that much
    on its own, and its 0.8 s slope (std 3.5 m/s^2) cannot tell 0.4 g from steady driving."""
    engine = only(AlertType.HARD_BRAKING)
    events = run(
        engine,
        stamps(4.0),
        lambda t: [_measured(make_track(1, 600.0, braking_speed(t)), speed_std_mps)],
    )
    assert [e.phase for e in events] == (["start"] if alerts else [])


def test_hard_braking_exact_rate_without_noise() -> None:
    engine = only(AlertType.HARD_BRAKING)
    events = run(engine, stamps(4.0), lambda t: [make_track(1, 600.0, braking_speed(t))])
    assert [e.phase for e in events] == ["start"]
    assert engine.active()[0].finding.measured_value == pytest.approx(DECEL_MPS2, abs=1e-9)
    assert engine.active()[0].finding.measured_value / G_MPS2 == pytest.approx(0.5099, abs=1e-4)


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_moderate_braking_is_not_hard_braking(seed: int) -> None:
    # 3 m/s^2 (0.31 g) with the same noise: no alert.
    engine = only(AlertType.HARD_BRAKING)
    times = stamps(10.0)
    noise = np.random.default_rng(seed).normal(0.0, 0.3, len(times))
    speeds = {
        round(t, 6): 30.0 - 3.0 * min(max(t - 2.0, 0.0), 4.0) + n
        for t, n in zip(times, noise, strict=True)
    }
    assert run(engine, times, lambda t: [make_track(1, 600.0, speeds[round(t, 6)])]) == []


# --- short TTC: a follower closing at a set speed -------------------------------------------------


def test_ttc_of_a_follower_closing_at_5_m_s() -> None:
    # Leader at 15 m/s, follower at 20 m/s, gap 20 m at t = 0: TTC(t) = (20 - 5 t) / 5 = 4 - t.
    engine = only(AlertType.SHORT_TTC)

    def tracks(t: float) -> list[Track]:
        follower = make_track(1, 600.0 + 20.0 * t, 20.0)
        leader = make_track(2, 600.0 + 24.5 + 15.0 * t, 15.0)  # 20 m + (4.5 + 4.5) / 2
        return [follower, leader]

    events = run(engine, stamps(3.7), tracks)
    # TTC <= 1.5 s from t = 2.5 s; hold 0.2 s: start at 2.7 s with TTC 1.3 s (gap 6.5 m).
    # Warning from TTC 1.0 s (t = 3.0), critical from 0.5 s (t = 3.5).
    assert phases(events) == [("start", 2.7), ("update", 3.0), ("update", 3.5)]
    assert [e.finding.measured_value for e in events] == pytest.approx([1.3, 1.0, 0.5], abs=1e-9)
    assert [e.severity.value for e in events] == ["info", "warning", "critical"]
    assert events[0].onset_stamp == pytest.approx(2.5)
    assert events[0].evidence["gap_m"] == pytest.approx(6.5, abs=1e-9)
    assert events[0].evidence["closing_speed_mps"] == pytest.approx(5.0)
    assert events[0].track_id == 1


# --- queue --------------------------------------------------------------------------------------


def test_queue_episode_reports_the_tail_and_follows_it_upstream() -> None:
    engine = only(AlertType.QUEUE)

    def tracks(t: float) -> list[Track]:
        stopped = [make_track(i, 950.0 - 10.0 * i, 0.0) for i in range(1, 4)]  # 940, 930, 920
        # a car approaching at 20 m/s joins the queue at 910 m at t = 5 s
        joiner = (
            make_track(9, 810.0 + 20.0 * t, 20.0) if t < 5.0 - 1e-9 else make_track(9, 910.0, 0.0)
        )
        return [*stopped, joiner]

    events = run(engine, stamps(8.0), tracks)
    assert phases(events) == [("start", 3.0)]
    start = events[0]
    assert start.track_id is None and start.finding.track is None
    assert start.finding.station_m == 920.0
    assert start.evidence["queue_tail_station_m"] == 920.0
    assert start.episode_id == "queue-site-1"
    active = engine.active()
    assert len(active) == 1 and active[0].finding.station_m == 910.0
    assert active[0].finding.measured_value == 4.0


# --- messages -------------------------------------------------------------------------------------


def test_events_become_valid_alert_messages() -> None:
    engine = AlertEngine(SITE, id_prefix="alerts.1700000000")
    # 8 mph over, then slowing at 1 m/s^2 from 4 s to the limit.
    events = run(engine, stamps(10.0), speeder(lambda t: max(LEGAL, FAST - max(0.0, t - 4.0))))
    assert {e.alert_type for e in events} == {AlertType.SPEEDING, AlertType.AGGRESSIVE_APPROACH}
    for event in events:
        message = event.to_message(SITE.site_id, "alert-service")
        assert isinstance(message, Alert)
        assert codec.decode_json(codec.encode_json(message), Alert) == message
        assert message.alert_id.startswith("alerts.1700000000-")
        assert message.episode_id == event.episode_id and message.phase == event.phase
        assert message.track is not None and message.track.track_id == 1
        assert (
            message.evidence[
                "speed_limit_mps" if event.alert_type is AlertType.SPEEDING else "zone_limit_mps"
            ]
            == LIMIT_55_MPS
        )
        assert message.value_unit in {"m/s", "m/s^2"}
    with pytest.raises(ValueError, match="id_prefix"):
        AlertEngine(SITE, id_prefix="bad prefix/")


# --- the invariant: never two open episodes for one (track, type) -----------------------------

SPEEDS = st.sampled_from([0.0, 5.0, 20.0, LIMIT_55_MPS, LIMIT_55_MPS + 2.5, FAST, 40.0])
STEP = st.tuples(
    st.booleans(),  # track 1 present
    SPEEDS,
    st.booleans(),  # track 2 present
    SPEEDS,
    st.sampled_from([-1.83, -0.1, 0.1, 1.83]),  # track 2's offset
)


@settings(max_examples=150, deadline=None)
@given(steps=st.lists(STEP, min_size=1, max_size=120), dt_s=st.sampled_from([0.05, 0.1, 0.5]))
def test_episodes_never_overlap_and_respect_the_cool_down(
    steps: list[tuple[bool, float, bool, float, float]], dt_s: float
) -> None:
    engine = AlertEngine(SITE)
    events: list[AlertEvent] = []
    for k, (has_1, speed_1, has_2, speed_2, offset_2) in enumerate(steps):
        t = k * dt_s
        tracks = []
        if has_1:
            tracks.append(make_track(1, 900.0 + 2.0 * t, speed_1))
        if has_2:
            tracks.append(make_track(2, 905.0 + 2.0 * t, speed_2, offset_m=offset_2))
        events.extend(engine.update(batch(t, tracks, k)))
        keys = [(a.track_id, a.alert_type) for a in engine.active()]
        assert len(keys) == len(set(keys))
    by_key: defaultdict[tuple[int | None, AlertType], list[AlertEvent]] = defaultdict(list)
    for event in events:
        by_key[(event.track_id, event.alert_type)].append(event)
    assert len({e.episode_id for e in events if e.phase == "start"}) == sum(
        e.phase == "start" for e in events
    )
    for (_, alert_type), key_events in by_key.items():
        open_episode: str | None = None
        last_clear_s = -math.inf
        cooldown_s = getattr(SITE.alerts, alert_type.value).cooldown_s
        for event in key_events:
            if event.phase == "start":
                assert open_episode is None, "a second episode opened before the first cleared"
                assert event.onset_stamp >= last_clear_s + cooldown_s - 1e-6
                open_episode = event.episode_id
            else:
                assert event.episode_id == open_episode
                if event.phase == "clear":
                    open_episode, last_clear_s = None, event.stamp


def test_a_speed_corrected_after_an_outage_is_no_hard_braking() -> None:
    """A track coasts 0.6 s (its last measurement stays at 1.0 s), then its first measurement
    corrects the speed by -3.5 m/s at once: the error its prediction gathered, not a vehicle
    braking at 0.45 g. The trend starts again from that measurement (issue 25)."""
    engine = only(AlertType.HARD_BRAKING)
    events: list[AlertEvent] = []
    for k, t in enumerate(stamps(4.0)):
        measured_s = t if t < 1.0 or t >= 1.6 else 1.0
        speed = 25.0 if t < 1.6 else 21.5
        track = make_track(1, 600.0 + 20.0 * t, speed).model_copy(
            update={"last_update_s": measured_s}
        )
        events.extend(engine.update(batch(t, [track], k)))
    assert events == []


def test_hard_braking_measured_without_a_break_still_alerts_with_measurement_stamps() -> None:
    """The same engine on a track measured every cycle (last_update_s = stamp) through a
    0.51 g stop: the outage rule leaves it alone."""
    engine = only(AlertType.HARD_BRAKING)

    def tracks(t: float) -> list[Track]:
        track = make_track(1, 600.0, braking_speed(t))
        return [track.model_copy(update={"last_update_s": t})]

    events = run(engine, stamps(4.0), tracks)
    assert [e.phase for e in events] == ["start"]
    assert engine.active()[0].finding.measured_value == pytest.approx(DECEL_MPS2, abs=1e-9)
