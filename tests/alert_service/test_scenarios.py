"""Hard braking and time to collision on scripted scenarios whose truth is known exactly.

The truth is closed-form kinematics (a vehicle brakes at a set rate; a follower closes on a
leader at a set speed), sampled at the tracker's 10 Hz and given to the engine as tracks, first
exactly, then with the tracker's output noise (white, seeded: station and offset std 0.2 m,
speed std 0.3 m/s). One more scenario scripts a SUMO vehicle (libsumo ``setSpeed``) to brake at
5 m/s^2 in the simulator's own world.

Hard braking (default rules: 0.8 s least-squares window, 0.4 g = 3.92 m/s^2, hold 0.3 s). With
10 Hz speeds the window's slope after a step from cruising to braking at ``a`` is the slope of a
hinge; it reaches 0.4 g once 0.6 s of braking are in the window (computed below with
``numpy.polyfit``, independently of the engine). So the exact start is

    onset + 0.6 s (window lag) + 0.3 s (hold) = 2.9 s for braking from 2.0 s,

and the alert's deceleration then is exactly ``a`` (the window holds only braking). Under noise
the slope's std is ``sigma_v / sqrt(sum (t_i - t_mean)^2) = 0.3 / sqrt(0.6) = 0.39 m/s^2``: each
noisy start lies within 0.5 s of the exact one, and the median reported deceleration within
0.5 m/s^2 of 5. At 3 m/s^2 (2.4 sigma below the threshold) a false start is rare, not
impossible: 2 of 200 seeds in a trial; the seeds here are free of it.

Time to collision (bumper gap 40 m, closing at 30 - 22 = 8 m/s): ``TTC(t) = (40 - 8 t) / 8``,
so 1.5 s (info) at 3.5 s, 1.0 s (warning) at 4.0 s, 0.5 s (critical) at 4.5 s; the start comes
after the 0.2 s hold, at 3.7 s.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pytest

from tests.alert_service.helpers import OPEN_LANE_D, SITE, batch, make_track
from wz_alert_service.engine import AlertEngine, AlertEvent
from wz_alert_service.rules import G_MPS2
from wz_shared.messages import AlertSeverity, AlertType, Track, VehicleTruth

RATE_HZ = 10.0
POSITION_STD_M = 0.2
SPEED_STD_MPS = 0.3
SEEDS = range(30)
RULE = SITE.alerts.hard_braking
THRESHOLD_MPS2 = RULE.decel_g * G_MPS2

# A vehicle at 30 m/s from station 500 m brakes at 5 m/s^2 from 2 s (to a stop at 8 s).
CRUISE_MPS = 30.0
BRAKE_ONSET_S = 2.0
BRAKE_MPS2 = 5.0
# A follower at 30 m/s, 40 m (bumper to bumper) behind a leader at 22 m/s.
FOLLOWER_MPS, LEADER_MPS, GAP0_M, LENGTH_M = 30.0, 22.0, 40.0, 4.5
CLOSING_MPS = FOLLOWER_MPS - LEADER_MPS

Frame = tuple[float, list[tuple[int, float, float]]]  # stamp, [(id, station, speed)]


def grid(duration_s: float) -> list[float]:
    """10 Hz stamps from 0 (computed, not summed)."""
    return [k / RATE_HZ for k in range(round(duration_s * RATE_HZ) + 1)]


def braking_truth(t: float, decel_mps2: float) -> tuple[float, float]:
    """Station [m] and speed [m/s] at ``t`` of the braking vehicle (closed form).

    ``v = v0 - a tb``, ``s = s0 + v0 t_cruise + v0 tb - a tb^2 / 2``, with ``t_cruise =
    min(t, onset)`` and ``tb = clip(t - onset, 0, v0 / a)`` (it stays stopped).
    """
    stop_s = CRUISE_MPS / decel_mps2 if decel_mps2 > 0 else math.inf
    tb = min(max(t - BRAKE_ONSET_S, 0.0), stop_s)
    cruise = min(t, BRAKE_ONSET_S)
    station = 500.0 + CRUISE_MPS * cruise + CRUISE_MPS * tb - 0.5 * decel_mps2 * tb**2
    return station, CRUISE_MPS - decel_mps2 * tb


def braking_frames(decel_mps2: float, duration_s: float = 10.0) -> list[Frame]:
    return [(t, [(1, *braking_truth(t, decel_mps2))]) for t in grid(duration_s)]


def closing_frames(follower_mps: float = FOLLOWER_MPS, duration_s: float = 4.8) -> list[Frame]:
    """Follower (1) and leader (2): centres a gap plus a length apart at 0 s."""
    leader0 = 500.0 + GAP0_M + LENGTH_M
    return [
        (
            t,
            [
                (1, 500.0 + follower_mps * t, follower_mps),
                (2, leader0 + LEADER_MPS * t, LEADER_MPS),
            ],
        )
        for t in grid(duration_s)
    ]


def exact_ttc_s(t: float) -> float:
    return (GAP0_M - CLOSING_MPS * t) / CLOSING_MPS


def as_track(
    track_id: int, station_m: float, speed_mps: float, rng: np.random.Generator | None
) -> Track:
    """The truth as the tracker would publish it: exactly, or with its output noise."""
    offset_m = OPEN_LANE_D
    if rng is not None:
        station_m += rng.normal(0.0, POSITION_STD_M)
        offset_m += rng.normal(0.0, POSITION_STD_M)
        speed_mps = max(0.0, speed_mps + rng.normal(0.0, SPEED_STD_MPS))
    return make_track(track_id, station_m, speed_mps, offset_m=offset_m, length_m=LENGTH_M)


def run(
    frames: Iterable[Frame], alert_type: AlertType, seed: int | None = None, track_id: int = 1
) -> list[AlertEvent]:
    """The engine's events of one type for one track, exact truth (no seed) or noisy."""
    rng = None if seed is None else np.random.default_rng(seed)
    engine = AlertEngine(SITE)
    events: list[AlertEvent] = []
    for k, (t, vehicles) in enumerate(frames):
        tracks = [as_track(i, s, v, rng) for i, s, v in vehicles]
        events += engine.update(batch(t, tracks, k))
    return [e for e in events if e.alert_type is alert_type and e.track_id == track_id]


def starts(events: Sequence[AlertEvent]) -> list[AlertEvent]:
    return [e for e in events if e.phase == "start"]


def first_window_crossing_s(times: Sequence[float], speeds: Sequence[float]) -> float:
    """First stamp at which the straight line fitted (``numpy.polyfit``) to the speeds of the
    last ``window_s`` falls at 0.4 g or more: where the rule's condition first holds."""
    t, v = np.asarray(times), np.asarray(speeds)
    for i, now in enumerate(t):
        inside = (t >= now - RULE.window_s - 1e-6) & (t <= now)
        if inside.sum() >= RULE.min_samples and -np.polyfit(t[inside], v[inside], 1)[0] >= (
            THRESHOLD_MPS2
        ):
            return float(t[i])
    raise AssertionError("the true speeds never cross the threshold")


# --- hard braking ---------------------------------------------------------------------------


def exact_braking_start_s(frames: Sequence[Frame]) -> float:
    times = [t for t, _ in frames]
    speeds = [vehicles[0][2] for _, vehicles in frames]
    return first_window_crossing_s(times, speeds) + RULE.hold_s


def test_hard_braking_on_exact_truth_starts_at_the_closed_form_time_with_the_set_rate() -> None:
    frames = braking_frames(BRAKE_MPS2)
    expected_start_s = exact_braking_start_s(frames)
    # The window needs 0.6 s of braking before its slope reaches 0.4 g.
    assert expected_start_s == pytest.approx(BRAKE_ONSET_S + 0.6 + RULE.hold_s)
    events = run(frames, AlertType.HARD_BRAKING)
    (start,) = starts(events)
    assert start.stamp == pytest.approx(expected_start_s)
    assert start.onset_stamp == pytest.approx(expected_start_s - RULE.hold_s)
    assert start.finding.measured_value == pytest.approx(BRAKE_MPS2, abs=1e-9)
    assert start.severity is AlertSeverity.WARNING  # 5 m/s^2 = 0.51 g < 0.6 g
    assert [e.phase for e in events] == ["start", "clear"]  # one episode for one braking


def test_hard_braking_under_tracker_noise_starts_once_near_the_exact_time() -> None:
    expected_start_s = exact_braking_start_s(braking_frames(BRAKE_MPS2))
    # Std of the window's slope: sigma_v / sqrt(sum (t_i - t_mean)^2), 9 speeds 0.1 s apart.
    offsets = np.arange(-4, 5) / RATE_HZ
    slope_std = SPEED_STD_MPS / math.sqrt(float(np.sum(offsets**2)))
    assert slope_std == pytest.approx(0.387, abs=1e-3)
    decelerations = []
    for seed in SEEDS:
        (start,) = starts(run(braking_frames(BRAKE_MPS2), AlertType.HARD_BRAKING, seed))
        assert abs(start.stamp - expected_start_s) <= 0.5, seed
        assert abs(start.finding.measured_value - BRAKE_MPS2) <= 3.0 * slope_std, seed
        decelerations.append(start.finding.measured_value)
    assert statistics.median(decelerations) == pytest.approx(BRAKE_MPS2, abs=0.5)


@pytest.mark.parametrize("decel_mps2", [0.0, 3.0])
def test_no_hard_braking_when_cruising_or_braking_at_3_mps2(decel_mps2: float) -> None:
    assert run(braking_frames(decel_mps2), AlertType.HARD_BRAKING) == []
    for seed in SEEDS:
        assert run(braking_frames(decel_mps2), AlertType.HARD_BRAKING, seed) == [], seed


# --- time to collision ----------------------------------------------------------------------


def transitions(events: Sequence[AlertEvent]) -> dict[AlertSeverity, AlertEvent]:
    """The first event at or above warning, and the first at critical."""
    found: dict[AlertSeverity, AlertEvent] = {}
    for event in events:
        for band in (AlertSeverity.WARNING, AlertSeverity.CRITICAL):
            rises = event.severity is band or (
                band is AlertSeverity.WARNING and event.severity is AlertSeverity.CRITICAL
            )
            if rises and band not in found:
                found[band] = event
    return found


def test_ttc_on_exact_truth_reports_the_exact_gap_over_closing_speed() -> None:
    assert exact_ttc_s(3.5) == pytest.approx(SITE.alerts.short_ttc.max_ttc_s)
    events = run(closing_frames(), AlertType.SHORT_TTC)
    summary = [(e.phase, e.severity, round(e.stamp, 6)) for e in events]
    assert summary == [
        ("start", AlertSeverity.INFO, 3.7),  # TTC <= 1.5 s from 3.5 s, held 0.2 s
        ("update", AlertSeverity.WARNING, 4.0),  # TTC 1.0 s
        ("update", AlertSeverity.CRITICAL, 4.5),  # TTC 0.5 s
    ]
    for event in events:
        assert event.finding.measured_value == pytest.approx(exact_ttc_s(event.stamp), abs=1e-9)
        assert event.evidence["gap_m"] == pytest.approx(GAP0_M - CLOSING_MPS * event.stamp)
        assert event.evidence["closing_speed_mps"] == pytest.approx(CLOSING_MPS)


def test_ttc_under_tracker_noise_matches_the_exact_values_at_its_transitions() -> None:
    for seed in SEEDS:
        events = run(closing_frames(), AlertType.SHORT_TTC, seed)
        assert len(starts(events)) == 1, seed
        found = transitions(events)
        for band, exact_at_s in ((AlertSeverity.WARNING, 4.0), (AlertSeverity.CRITICAL, 4.5)):
            event = found[band]
            reported_s = event.finding.measured_value
            assert reported_s == pytest.approx(exact_ttc_s(event.stamp), abs=0.15), (seed, band)
            assert event.stamp == pytest.approx(exact_at_s, abs=0.2), (seed, band)


def test_no_ttc_alert_at_a_constant_gap() -> None:
    for seed in (None, *SEEDS):
        assert run(closing_frames(follower_mps=LEADER_MPS), AlertType.SHORT_TTC, seed) == []


# --- a SUMO vehicle braking at a set rate ---------------------------------------------------


def sumo_braking_truth(work_dir: Path) -> tuple[float, list[tuple[float, VehicleTruth]]]:
    """A car scripted through libsumo: 28 m/s, then 5 m/s^2 to a stop from station 500 m.

    The simulator's world runs with next to no other traffic; the probe ignores SUMO's safety
    and deceleration limits (speed mode 0) and gets its speed set every step. Returns the
    braking onset [s] (read from the truth: the step before the first at -5 m/s^2) and the
    probe's truth every 0.1 s.
    """
    libsumo = pytest.importorskip("libsumo")
    from wz_simulator.settings import SimulatorSettings
    from wz_simulator.traffic.demand import ROUTE_ID
    from wz_simulator.traffic.world import TrafficWorld

    settings = SimulatorSettings(
        seed=3, work_dir=work_dir, vehicles_per_hour=1.0, sensors_enabled=False
    )
    probe, cruise_mps = "probe", 28.0
    samples: list[tuple[float, VehicleTruth]] = []
    braking_since: float | None = None
    onset_s: float | None = None
    with TrafficWorld(SITE, settings) as world:
        libsumo.vehicle.add(
            probe,
            ROUTE_ID,
            typeID="car_normal",
            depart="now",
            departLane="0",
            departSpeed=str(cruise_mps),
        )
        libsumo.vehicle.setLaneChangeMode(probe, 0)
        libsumo.vehicle.setSpeedMode(probe, 0)
        libsumo.vehicle.setSpeed(probe, cruise_mps)
        previous_s = 0.0
        while braking_since is None or world.sim_time_s < braking_since + 8.0:
            truth = next((v for v in world.step() if v.vehicle_id == probe), None)
            now = world.sim_time_s
            if truth is None:
                assert now < 5.0, "the probe never appeared"
                previous_s = now
                continue
            if braking_since is None and truth.station_m >= 500.0:
                braking_since = now
            if braking_since is not None:
                libsumo.vehicle.setSpeed(
                    probe, max(0.0, cruise_mps - BRAKE_MPS2 * (now - braking_since))
                )
            if onset_s is None and truth.accel_mps2 <= -BRAKE_MPS2 + 1e-6:
                onset_s = previous_s
            if world.step_index % 2 == 0:
                samples.append((now, truth))
            previous_s = now
    assert onset_s is not None
    return onset_s, samples


def test_a_sumo_vehicle_braking_at_5_mps2_alerts_once_with_its_rate(tmp_path: Path) -> None:
    onset_s, samples = sumo_braking_truth(tmp_path)
    decels = [-truth.accel_mps2 for t, truth in samples if onset_s + 0.1 < t < onset_s + 5.0]
    assert decels and all(d == pytest.approx(BRAKE_MPS2) for d in decels)  # SUMO did as told
    times = [t for t, _ in samples]
    expected_start_s = first_window_crossing_s(times, [v.speed_mps for _, v in samples])
    expected_start_s += RULE.hold_s
    assert expected_start_s - onset_s == pytest.approx(0.6 + RULE.hold_s, abs=0.05 + 1e-6)

    def frames() -> list[Frame]:
        return [(t, [(1, v.station_m, v.speed_mps)]) for t, v in samples]

    (exact,) = starts(run(frames(), AlertType.HARD_BRAKING))
    assert exact.stamp == pytest.approx(expected_start_s)
    assert exact.finding.measured_value == pytest.approx(BRAKE_MPS2, abs=1e-6)
    for seed in SEEDS:
        (start,) = starts(run(frames(), AlertType.HARD_BRAKING, seed))
        assert abs(start.stamp - expected_start_s) <= 0.5, seed
