"""Each rule at its threshold and just either side of it, with the arithmetic in the names.

A rule fires at exactly its threshold. Where the threshold comes from a formula, the zone or
the rule is set so the arithmetic is exact in binary floating point (a 20 m/s zone limit, a
5.0 m/s^2 threshold), or the test computes it with the same operations as the rule.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.alert_service.helpers import CLOSED_LANE_D, OPEN_LANE_D, SITE, make_track
from tests.purity import top_level_imports
from wz_alert_service import devices, engine, rules, zone
from wz_alert_service.rules import (
    G_MPS2,
    aggressive_approach,
    bumper_gap_m,
    hard_braking,
    intrusion,
    late_merge,
    leaders,
    queue,
    queue_extent,
    required_deceleration_mps2,
    short_ttc,
    speed_trend_mps2,
    speeding,
    time_to_collision_s,
)
from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import AlertSeverity, AlertType, Track
from wz_shared.site import MPH_TO_MPS, SpeedLimit

ZONE = ZoneGeometry.from_site(SITE)
RULES = SITE.alerts
LIMIT_55_MPS = 55.0 * MPH_TO_MPS  # 24.5872 m/s
W, C, INFO = AlertSeverity.WARNING, AlertSeverity.CRITICAL, AlertSeverity.INFO


def test_the_core_imports_no_io_library() -> None:
    io_libraries = {"zenoh", "fastapi", "httpx", "requests", "uvicorn", "io", "socket", "yaml"}
    for module in (zone, rules, engine, devices):
        assert top_level_imports(module).isdisjoint(io_libraries), module.__name__


# --- speeding: v >= v_limit + 5 mph; open while v >= v_limit + 3 mph; critical +15 mph ------

# 55 mph + 5 mph = 24.5872 + 2.2352 = 26.8224 m/s, computed as the rule does.
SPEEDING_ENTER_MPS = LIMIT_55_MPS + 5.0 * MPH_TO_MPS


@pytest.mark.parametrize(
    ("speed_mps", "fires"),
    [
        (SPEEDING_ENTER_MPS - 0.01, False),
        (SPEEDING_ENTER_MPS, True),
        (SPEEDING_ENTER_MPS + 0.01, True),
    ],
    ids=["26.8124-below", "26.8224-at", "26.8324-above"],
)
def test_speeding_enters_at_limit_plus_5_mph(speed_mps: float, fires: bool) -> None:
    finding = speeding(make_track(1, 800.0, speed_mps), ZONE, RULES.speeding)
    assert (finding is not None) is fires
    if finding is not None:
        assert finding.alert_type is AlertType.SPEEDING
        assert finding.severity is W
        assert finding.measured_value == speed_mps
        assert finding.threshold_value == SPEEDING_ENTER_MPS
        assert finding.value_unit == "m/s"
        assert finding.evidence["speed_limit_mps"] == LIMIT_55_MPS
        assert finding.track is not None and finding.track_id == 1


# Open: 55 mph + (5 - 2) mph = 24.5872 + 1.34112 = 25.92832 m/s.
SPEEDING_EXIT_MPS = LIMIT_55_MPS + 3.0 * MPH_TO_MPS


@pytest.mark.parametrize(
    ("speed_mps", "holds"),
    [
        (SPEEDING_EXIT_MPS - 0.01, False),
        (SPEEDING_EXIT_MPS, True),
        (SPEEDING_EXIT_MPS + 0.01, True),
    ],
    ids=["25.91832-below", "25.92832-at", "25.93832-above"],
)
def test_open_speeding_stays_open_down_to_limit_plus_3_mph(speed_mps: float, holds: bool) -> None:
    finding = speeding(make_track(1, 800.0, speed_mps), ZONE, RULES.speeding, active=True)
    assert (finding is not None) is holds
    assert speeding(make_track(1, 800.0, speed_mps), ZONE, RULES.speeding) is None


@pytest.mark.parametrize(
    ("excess_mph", "severity"),
    [(14.99, W), (15.0, C), (15.01, C)],
    ids=["+14.99mph-warning", "+15mph-critical", "+15.01mph-critical"],
)
def test_speeding_is_critical_from_15_mph_over(excess_mph: float, severity: AlertSeverity) -> None:
    speed_mps = LIMIT_55_MPS + excess_mph * MPH_TO_MPS
    finding = speeding(make_track(1, 800.0, speed_mps), ZONE, RULES.speeding)
    assert finding is not None and finding.severity is severity


@pytest.mark.parametrize(
    ("station_m", "fires"),
    [(299.99, False), (300.0, True), (1699.99, True), (1700.0, False)],
    ids=["before-approach", "approach-start-300", "approach-end-1699.99", "past-activity-1700"],
)
def test_speeding_only_within_the_approach(station_m: float, fires: bool) -> None:
    # 90 mph is over any limit of the site; only the station window decides.
    finding = speeding(make_track(1, station_m, 90.0 * MPH_TO_MPS), ZONE, RULES.speeding)
    assert (finding is not None) is fires


def test_speeding_can_decide_on_the_speed_the_covariance_makes_sure() -> None:
    """1 m/s over the entry threshold with a speed std of 0.6 m/s: as measured (the default)
    it alerts; at 2 sigma (1.2 m/s) it does not; with a std of 0.4 m/s it does again."""
    rule = RULES.speeding.model_copy(update={"certainty_sigmas": 2.0})
    assert RULES.speeding.certainty_sigmas == 0.0
    track = make_track(1, 800.0, SPEEDING_ENTER_MPS + 1.0)
    loose, tight = _with_stds(track, 0.3, 0.6), _with_stds(track, 0.3, 0.4)
    assert speeding(loose, ZONE, RULES.speeding) is not None
    assert speeding(loose, ZONE, rule) is None
    assert speeding(tight, ZONE, rule) is not None


def test_speeding_uses_the_limit_at_the_station() -> None:
    # At 1500 m the limit is 55 mph; a site with a 70 mph stretch there raises the threshold.
    site = SITE.model_copy(
        update={
            "speed_limits": [
                SpeedLimit(start_station_m=0.0, end_station_m=1400.0, speed_limit_mph=55.0),
                SpeedLimit(start_station_m=1400.0, end_station_m=2000.0, speed_limit_mph=70.0),
            ]
        }
    )
    zone70 = ZoneGeometry.from_site(site)
    speed_mps = 66.0 * MPH_TO_MPS
    assert speeding(make_track(1, 1300.0, speed_mps), zone70, RULES.speeding) is not None
    assert speeding(make_track(1, 1500.0, speed_mps), zone70, RULES.speeding) is None


# --- aggressive approach: a = (v^2 - v_zone^2) / (2 D) ----------------------------------------


def test_required_deceleration_closed_form() -> None:
    # (30^2 - 20^2) / (2 * 50) = 500 / 100 = 5 m/s^2
    assert required_deceleration_mps2(30.0, 20.0, 50.0) == 5.0
    # Already slower than the target: no braking needed (negative).
    assert required_deceleration_mps2(20.0, 30.0, 50.0) == -5.0


# A 20 m/s zone limit and a 5.0 m/s^2 threshold make the arithmetic exact: at 30 m/s the
# threshold is reached D = (900 - 400) / (2 * 5) = 50 m before the taper (station 950 m).
ZONE_20 = dataclasses.replace(ZONE, zone_limit_mps=20.0)
AGGRESSIVE_5 = RULES.aggressive_approach.model_copy(
    update={"comfortable_decel_mps2": 5.0, "critical_decel_mps2": 6.0}
)


@pytest.mark.parametrize(
    ("station_m", "fires"),
    [(949.5, False), (950.0, True), (950.5, True)],
    ids=["D50.5-4.95mps2-below", "D50-5.0mps2-at", "D49.5-5.05mps2-above"],
)
def test_aggressive_approach_enters_at_the_comfortable_deceleration(
    station_m: float, fires: bool
) -> None:
    track = make_track(1, station_m, 30.0)
    finding = aggressive_approach(track, None, ZONE_20, AGGRESSIVE_5)
    assert (finding is not None) is fires
    if finding is not None:
        distance_m = 1000.0 - station_m
        assert finding.measured_value == (900.0 - 400.0) / (2.0 * distance_m)
        assert finding.threshold_value == 5.0
        assert finding.value_unit == "m/s^2"
        assert finding.evidence["distance_to_taper_m"] == distance_m
        assert finding.evidence["not_slowing"] == 0.0
        assert finding.severity is W


def test_aggressive_approach_default_threshold_on_the_default_site() -> None:
    # 30 m/s in the 55 mph zone: D* = (30^2 - 24.5872^2) / (2 * 3.4) = 43.454 m.
    distance_m = (30.0**2 - LIMIT_55_MPS**2) / (2.0 * 3.4)
    rule = RULES.aggressive_approach
    assert (
        aggressive_approach(make_track(1, 1000.0 - distance_m - 0.5, 30.0), None, ZONE, rule)
        is None
    )
    finding = aggressive_approach(make_track(1, 1000.0 - distance_m + 0.5, 30.0), None, ZONE, rule)
    assert finding is not None and finding.measured_value == pytest.approx(3.4, abs=0.05)


@pytest.mark.parametrize(
    ("station_m", "severity"),
    [(1000.0 - 500.0 / 12.0 + 0.01, C), (950.0, W)],
    ids=["D41.66-6.0mps2-critical", "D50-5.0mps2-warning"],
)
def test_aggressive_approach_critical_band(station_m: float, severity: AlertSeverity) -> None:
    finding = aggressive_approach(make_track(1, station_m, 30.0), None, ZONE_20, AGGRESSIVE_5)
    assert finding is not None and finding.severity is severity


def test_aggressive_approach_open_until_deceleration_drops_by_the_hysteresis() -> None:
    # Open: 5.0 - 0.4 = 4.6 m/s^2 -> D = 500 / 9.2 = 54.35 m.
    d_exit_m = 500.0 / (2.0 * 4.6)
    inside = make_track(1, 1000.0 - d_exit_m + 0.01, 30.0)
    outside = make_track(1, 1000.0 - d_exit_m - 0.01, 30.0)
    assert aggressive_approach(inside, None, ZONE_20, AGGRESSIVE_5, active=True) is not None
    assert aggressive_approach(inside, None, ZONE_20, AGGRESSIVE_5) is None
    assert aggressive_approach(outside, None, ZONE_20, AGGRESSIVE_5, active=True) is None


def test_aggressive_approach_only_upstream_of_the_taper() -> None:
    assert (
        aggressive_approach(make_track(1, 1000.0, 40.0), None, ZONE, RULES.aggressive_approach)
        is None
    )


# Not slowing: past the advance-warning point (300 m), at least 55 + 5 mph, trend >= -0.3 m/s^2.
SLOW_ENOUGH = LIMIT_55_MPS + 5.0 * MPH_TO_MPS  # 26.8224 m/s; far from the taper a is small


@pytest.mark.parametrize(
    ("trend_mps2", "fires"),
    [(-0.31, False), (-0.3, True), (0.0, True), (None, False)],
    ids=["-0.31-slowing", "-0.30-at", "0-steady", "no-history"],
)
def test_aggressive_approach_when_not_slowing(trend_mps2: float | None, fires: bool) -> None:
    # 600 m before the taper at 26.8224 m/s: a = (26.8224^2 - 24.5872^2) / 1200 = 0.096 m/s^2.
    finding = aggressive_approach(
        make_track(1, 400.0, SLOW_ENOUGH), trend_mps2, ZONE, RULES.aggressive_approach
    )
    assert (finding is not None) is fires
    if finding is not None:
        assert finding.evidence["not_slowing"] == 1.0
        assert finding.evidence["speed_trend_mps2"] == trend_mps2
        assert finding.severity is W


def test_not_slowing_needs_the_speed_margin_and_the_advance_warning_point() -> None:
    rule = RULES.aggressive_approach
    below_margin = make_track(1, 400.0, SLOW_ENOUGH - 0.01)
    assert aggressive_approach(below_margin, 0.0, ZONE, rule) is None
    # Open: above the zone limit is enough, and the trend may be down to -(0.3 + 0.4) m/s^2.
    assert aggressive_approach(below_margin, -0.7, ZONE, rule, active=True) is not None
    assert aggressive_approach(below_margin, -0.71, ZONE, rule, active=True) is None
    zone_aw = dataclasses.replace(ZONE, advance_warning_m=500.0)
    assert aggressive_approach(make_track(1, 499.9, SLOW_ENOUGH), 0.0, zone_aw, rule) is None
    assert aggressive_approach(make_track(1, 500.0, SLOW_ENOUGH), 0.0, zone_aw, rule) is not None


# --- hard braking: -dv/dt >= 0.4 g = 3.92266 m/s^2; open while >= 0.35 g --------------------


@pytest.mark.parametrize(
    ("decel_mps2", "fires"),
    [(0.4 * G_MPS2 - 0.01, False), (0.4 * G_MPS2, True), (0.4 * G_MPS2 + 0.01, True)],
    ids=["3.91266-below", "3.92266-at", "3.93266-above"],
)
def test_hard_braking_enters_at_0_4_g(decel_mps2: float, fires: bool) -> None:
    finding = hard_braking(make_track(1, 800.0, 20.0), -decel_mps2, ZONE, RULES.hard_braking)
    assert (finding is not None) is fires
    if finding is not None:
        assert finding.measured_value == decel_mps2
        assert finding.threshold_value == 0.4 * G_MPS2
        assert finding.evidence["decel_g"] == pytest.approx(decel_mps2 / G_MPS2)


@pytest.mark.parametrize(
    ("decel_mps2", "holds"),
    [((0.4 - 0.05) * G_MPS2 - 0.01, False), ((0.4 - 0.05) * G_MPS2, True)],
    ids=["3.42233-below", "3.43233-at"],
)
def test_open_hard_braking_stays_open_down_to_0_35_g(decel_mps2: float, holds: bool) -> None:
    finding = hard_braking(
        make_track(1, 800.0, 20.0), -decel_mps2, ZONE, RULES.hard_braking, active=True
    )
    assert (finding is not None) is holds


def test_hard_braking_critical_from_0_6_g_and_needs_a_trend() -> None:
    track = make_track(1, 800.0, 20.0)
    rule = RULES.hard_braking
    finding = hard_braking(track, -0.6 * G_MPS2, ZONE, rule)
    assert finding is not None and finding.severity is C
    finding = hard_braking(track, -0.6 * G_MPS2 + 0.01, ZONE, rule)
    assert finding is not None and finding.severity is W
    assert hard_braking(track, None, ZONE, rule) is None


def test_speed_trend_is_the_least_squares_slope() -> None:
    t = np.arange(16) / 20.0
    # v = 30 - 5 t exactly: slope -5.
    assert speed_trend_mps2(t, 30.0 - 5.0 * t, min_samples=5, min_span_s=0.4) == pytest.approx(
        -5.0, abs=1e-12
    )
    # The same as numpy's degree-1 fit on noisy data.
    v = 30.0 - 5.0 * t + np.random.default_rng(7).normal(0.0, 0.3, t.size)
    assert speed_trend_mps2(t, v, min_samples=5, min_span_s=0.4) == pytest.approx(
        np.polyfit(t, v, 1)[0], abs=1e-12
    )
    # Too few samples, too short a span, or no span at all: no trend.
    assert speed_trend_mps2(t[:4], v[:4], min_samples=5, min_span_s=0.1) is None
    assert speed_trend_mps2(t[:8], v[:8], min_samples=5, min_span_s=0.4) is None  # 0.35 s < 0.4 s
    assert speed_trend_mps2(np.zeros(6), v[:6], min_samples=5, min_span_s=0.0) is None


# --- late merge: closed lane, D <= 150 m before the taper (1000 m), v >= 13.4 m/s ------------


@pytest.mark.parametrize(
    ("station_m", "fires"),
    [(849.99, False), (850.0, True), (850.01, True)],
    ids=["D150.01-below", "D150-at", "D149.99-above"],
)
def test_late_merge_within_150_m_of_the_taper(station_m: float, fires: bool) -> None:
    finding = late_merge(
        make_track(1, station_m, 20.0, offset_m=CLOSED_LANE_D), ZONE, RULES.late_merge
    )
    assert (finding is not None) is fires
    if finding is not None:
        assert finding.measured_value == 1000.0 - station_m
        assert finding.threshold_value == 150.0
        assert finding.severity is W


@pytest.mark.parametrize(
    ("speed_mps", "fires"),
    [(13.39, False), (13.4, True), (13.41, True)],
    ids=["13.39-below", "13.4-at", "13.41-above"],
)
def test_late_merge_needs_13_4_m_s(speed_mps: float, fires: bool) -> None:
    finding = late_merge(
        make_track(1, 900.0, speed_mps, offset_m=CLOSED_LANE_D), ZONE, RULES.late_merge
    )
    assert (finding is not None) is fires


@pytest.mark.parametrize(
    ("offset_m", "fires"),
    [(-0.01, False), (0.0, True), (0.01, True)],
    ids=["d-0.01-open-lane", "d0-lane-line", "d0.01-closed-lane"],
)
def test_late_merge_in_the_closed_lane_band(offset_m: float, fires: bool) -> None:
    finding = late_merge(make_track(1, 900.0, 20.0, offset_m=offset_m), ZONE, RULES.late_merge)
    assert (finding is not None) is fires


def test_late_merge_by_lane_index_and_hysteresis() -> None:
    rule = RULES.late_merge
    # The tracker's lane says closed even if the offset is just outside the band.
    assert (
        late_merge(make_track(1, 900.0, 20.0, offset_m=-0.05, lane_index=1), ZONE, rule) is not None
    )
    # Open: the band widens by 0.3 m: d >= -0.3; the speed may drop to 13.4 - 1.0 = 12.4 m/s.
    assert (
        late_merge(make_track(1, 900.0, 20.0, offset_m=-0.3), ZONE, rule, active=True) is not None
    )
    assert late_merge(make_track(1, 900.0, 20.0, offset_m=-0.31), ZONE, rule, active=True) is None
    assert (
        late_merge(make_track(1, 900.0, 12.4, offset_m=CLOSED_LANE_D), ZONE, rule, active=True)
        is not None
    )
    assert (
        late_merge(make_track(1, 900.0, 12.39, offset_m=CLOSED_LANE_D), ZONE, rule, active=True)
        is None
    )


@pytest.mark.parametrize(
    ("station_m", "severity"),
    [(999.99, W), (1000.0, C), (1200.99, C), (1201.0, None)],
    ids=["before-taper-warning", "taper-start-critical", "taper-end-critical", "past-taper-none"],
)
def test_late_merge_is_critical_in_the_taper(
    station_m: float, severity: AlertSeverity | None
) -> None:
    finding = late_merge(
        make_track(1, station_m, 20.0, offset_m=CLOSED_LANE_D), ZONE, RULES.late_merge
    )
    assert (None if finding is None else finding.severity) is severity


# --- short TTC: gap / closing speed, gap = ds - (L_f + L_l) / 2 ------------------------------


def test_gap_and_ttc_closed_forms() -> None:
    follower = make_track(1, 900.0, 30.0)
    # 919.5 - 900 - (4.5 + 4.5) / 2 = 15 m with the default lengths
    assert bumper_gap_m(follower, make_track(2, 919.5, 20.0), 4.5) == 15.0
    # 919.5 - 900 - (5 + 12) / 2 = 11 m with the tracker's lengths
    assert (
        bumper_gap_m(
            make_track(1, 900.0, 30.0, length_m=5.0), make_track(2, 919.5, 20.0, length_m=12.0), 4.5
        )
        == 11.0
    )
    assert time_to_collision_s(15.0, 10.0) == 1.5
    assert time_to_collision_s(15.0, 0.0) == math.inf
    assert time_to_collision_s(15.0, -1.0) == math.inf


@pytest.mark.parametrize(
    ("gap_m", "severity"),
    [
        (15.01, None),
        (15.0, INFO),
        (14.99, INFO),
        (10.01, INFO),
        (10.0, W),
        (5.01, W),
        (5.0, C),
        (1.0, C),
    ],
    ids=[
        "1.501s-none",
        "1.5s-info",
        "1.499s-info",
        "1.001s-info",
        "1.0s-warning",
        "0.501s-warning",
        "0.5s-critical",
        "0.1s-critical",
    ],
)
def test_short_ttc_bins_at_10_m_s_closing(gap_m: float, severity: AlertSeverity | None) -> None:
    # Follower 30 m/s, leader 20 m/s: closing 10 m/s, TTC = gap / 10.
    follower, leader = make_track(1, 900.0, 30.0), make_track(2, 900.0 + gap_m + 4.5, 20.0)
    finding = short_ttc(follower, leader, ZONE, RULES.short_ttc)
    assert (None if finding is None else finding.severity) is severity
    if finding is not None:
        assert finding.measured_value == pytest.approx(gap_m / 10.0, abs=1e-12)
        assert finding.threshold_value == 1.5
        assert finding.value_unit == "s"
        assert finding.evidence["gap_m"] == pytest.approx(gap_m, abs=1e-12)
        assert finding.evidence["closing_speed_mps"] == 10.0
        assert finding.evidence["leader_track_id"] == 2.0


def test_short_ttc_hysteresis_and_closing_speed() -> None:
    rule = RULES.short_ttc
    follower = make_track(1, 900.0, 30.0)
    # Open: TTC <= 1.5 + 0.3 = 1.8 s: gap 18 m at 10 m/s.
    assert (
        short_ttc(follower, make_track(2, 900.0 + 18.0 + 4.5, 20.0), ZONE, rule, active=True)
        is not None
    )
    assert (
        short_ttc(follower, make_track(2, 900.0 + 18.1 + 4.5, 20.0), ZONE, rule, active=True)
        is None
    )
    # Closing at 0.5 m/s counts, 0.49 m/s does not (gap 0.5 m: TTC 1.0 s and 1.02 s).
    close = make_track(2, 900.0 + 0.5 + 4.5, 29.5)
    assert short_ttc(follower, close, ZONE, rule) is not None
    assert short_ttc(follower, make_track(2, 900.0 + 0.5 + 4.5, 29.51), ZONE, rule) is None
    # Overlapping boxes (gap <= 0) and no leader: no TTC.
    assert short_ttc(follower, make_track(2, 904.5, 10.0), ZONE, rule) is None
    assert short_ttc(follower, None, ZONE, rule) is None


def _with_stds(track: Track, position_std_m: float, speed_std_mps: float) -> Track:
    """The track with an isotropic position and velocity covariance of these stds."""
    diagonal = [position_std_m**2] * 2 + [speed_std_mps**2] * 2
    return track.model_copy(update={"covariance": np.diag(diagonal).reshape(-1).tolist()})


def test_short_ttc_decides_on_the_ttc_the_covariances_make_sure() -> None:
    """In a queue: a follower at 4 m/s 2 m behind a leader at 2.5 m/s. Measured, TTC 1.33 s;
    with speeds known to 0.5 m/s and positions to 0.3 m, 2 sigma leave a closing speed of
    0.09 m/s: nothing sure, no alert. Known to 0.1 m/s and 0.05 m, the TTC is sure to be
    (2 + 2 sqrt(2) 0.05) / (1.5 - 2 sqrt(2) 0.1) = 1.73 s: above 1.5 s, no alert either; a
    faster follower (6 m/s) alerts at that certainty, with the measured TTC in the evidence."""
    rule = RULES.short_ttc
    leader, follower = make_track(2, 906.5, 2.5), make_track(1, 900.0, 4.0)
    assert short_ttc(follower, leader, ZONE, rule) is not None  # as measured, no covariance
    noisy = (_with_stds(follower, 0.3, 0.5), _with_stds(leader, 0.3, 0.5))
    assert short_ttc(*noisy, ZONE, rule) is None
    good = (_with_stds(follower, 0.05, 0.1), _with_stds(leader, 0.05, 0.1))
    assert short_ttc(*good, ZONE, rule) is None
    fast = _with_stds(make_track(1, 900.0, 6.0), 0.05, 0.1)
    finding = short_ttc(fast, good[1], ZONE, rule)
    sure_s = (2.0 + 2.0 * math.sqrt(2.0) * 0.05) / (3.5 - 2.0 * math.sqrt(2.0) * 0.1)
    assert finding is not None and finding.measured_value == pytest.approx(sure_s)
    assert finding.evidence["measured_ttc_s"] == pytest.approx(2.0 / 3.5)
    as_measured = short_ttc(fast, good[1], ZONE, rule.model_copy(update={"certainty_sigmas": 0}))
    assert as_measured is not None and as_measured.measured_value == pytest.approx(2.0 / 3.5)


def test_short_ttc_wants_both_tracks_followed_a_while() -> None:
    """A follower at 26 m/s 20 m behind a "leader" at 3 m/s born 0.6 s ago (on site 9700 a
    camera ghost: no vehicle there): TTC 0.87 s as measured; with ``min_track_age_s`` 2 (the
    default) no alert until both tracks are 2 s old, then one; with 0, at once."""
    rule = RULES.short_ttc
    assert rule.min_track_age_s == 2.0
    follower = make_track(1, 900.0, 26.0).model_copy(update={"age_s": 5.0})
    ghost = make_track(2, 924.5, 3.0).model_copy(update={"age_s": 0.6})
    any_age = rule.model_copy(update={"min_track_age_s": 0.0})
    assert short_ttc(follower, ghost, ZONE, any_age) is not None
    assert short_ttc(follower, ghost, ZONE, rule) is None
    older = ghost.model_copy(update={"age_s": 2.0})
    assert short_ttc(follower, older, ZONE, rule) is not None
    assert short_ttc(follower.model_copy(update={"age_s": 1.9}), older, ZONE, rule) is None


def test_leaders_are_the_nearest_ahead_in_the_same_lane() -> None:
    tracks = [
        make_track(1, 900.0, 30.0),
        make_track(2, 950.0, 30.0),
        make_track(3, 920.0, 30.0, offset_m=CLOSED_LANE_D),  # other lane
        make_track(4, 930.0, 30.0),
        make_track(5, 910.0, 30.0, offset_m=OPEN_LANE_D, lane_index=-1),  # between lanes
        make_track(6, 950.0, 30.0),  # level with 2: neither leads the other
    ]
    lead = {follower: leader.track_id for follower, leader in leaders(tracks).items()}
    assert lead == {1: 4, 4: 2}


# --- queue: 3 vehicles slower than 8.9 m/s within 100 m ---------------------------------------


def test_queue_extent_closed_form() -> None:
    # 0, 50, 100 span 100 m: a queue; 400 and 450 are only two.
    assert queue_extent(
        [450.0, 0.0, 100.0, 50.0, 400.0], min_vehicles=3, span_m=100.0
    ) == rules.QueueExtent(0.0, 100.0, 3)
    assert queue_extent([0.0, 50.0, 100.01], min_vehicles=3, span_m=100.0) is None
    # Overlapping groups join: 0-80 and 40-130 (but 150 - 40 = 110 m would be too far).
    assert queue_extent(
        [0.0, 40.0, 80.0, 130.0], min_vehicles=3, span_m=100.0
    ) == rules.QueueExtent(0.0, 130.0, 4)
    assert queue_extent(
        [0.0, 40.0, 80.0, 150.0], min_vehicles=3, span_m=100.0
    ) == rules.QueueExtent(0.0, 80.0, 3)
    assert queue_extent([5.0], min_vehicles=1, span_m=1.0) == rules.QueueExtent(5.0, 5.0, 1)
    assert queue_extent([], min_vehicles=1, span_m=1.0) is None


@pytest.mark.parametrize(
    ("head_m", "fires"),
    [(1000.01, False), (1000.0, True), (999.99, True)],
    ids=["span100.01-none", "span100-at", "span99.99-queue"],
)
def test_queue_of_three_within_100_m(head_m: float, fires: bool) -> None:
    tracks = [
        make_track(1, 600.0, 0.0),  # a lone stopped vehicle upstream: not part of a queue
        make_track(2, 900.0, 2.0),
        make_track(3, 950.0, 1.0),
        make_track(4, head_m, 3.0),
        make_track(5, 920.0, 25.0),  # free flow in between
    ]
    finding = queue(tracks, ZONE, RULES.queue)
    assert (finding is not None) is fires
    if finding is not None:
        assert finding.alert_type is AlertType.QUEUE
        assert finding.track is None and finding.track_id is None
        assert finding.station_m == 900.0  # the tail: the most upstream queued vehicle
        assert finding.speed_mps == 2.0
        assert finding.evidence["queue_tail_station_m"] == 900.0
        assert finding.evidence["queue_head_station_m"] == head_m
        assert finding.evidence["tail_track_id"] == 2.0
        assert (finding.measured_value, finding.threshold_value) == (3.0, 3.0)
        assert finding.value_unit == "vehicles"


def test_queue_slow_threshold_hysteresis_and_severity() -> None:
    rule = RULES.queue

    def at(speed_mps: float, tail_m: float = 900.0) -> list[Track]:
        return [make_track(i, tail_m + 20.0 * i, speed_mps) for i in range(3)]

    assert queue(at(8.89), ZONE, rule) is not None
    assert queue(at(8.9), ZONE, rule) is None  # slow means v < 8.9 m/s
    assert queue(at(10.89), ZONE, rule, active=True) is not None  # open: v < 8.9 + 2.0
    assert queue(at(10.9), ZONE, rule, active=True) is None
    # Critical when the tail is 300 m or more upstream of the taper (1000 m): tail <= 700 m.
    finding = queue(at(1.0, 700.0), ZONE, rule)
    assert finding is not None and finding.severity is C
    finding = queue(at(1.0, 700.01), ZONE, rule)
    assert finding is not None and finding.severity is W


# --- intrusion: closed lane in the buffer (1201 m) or activity area (1300-1700 m) ------------


@pytest.mark.parametrize(
    ("station_m", "severity"),
    [(1200.99, None), (1201.0, W), (1299.99, W), (1300.0, C), (1699.99, C), (1700.0, None)],
    ids=[
        "taper-none",
        "buffer-start-warning",
        "buffer-end-warning",
        "activity-start-critical",
        "activity-end-critical",
        "termination-none",
    ],
)
def test_intrusion_in_buffer_and_activity_area(
    station_m: float, severity: AlertSeverity | None
) -> None:
    finding = intrusion(
        make_track(1, station_m, 10.0, offset_m=CLOSED_LANE_D), ZONE, RULES.intrusion
    )
    assert (None if finding is None else finding.severity) is severity
    if finding is not None:
        # 1.83 m inside a band [0, 3.66): min(1.83 - 0, 3.66 - 1.83) = 1.83 m
        assert finding.measured_value == pytest.approx(1.83, abs=1e-12)
        assert finding.threshold_value == 0.0


def test_intrusion_thresholds() -> None:
    rule = RULES.intrusion
    assert intrusion(make_track(1, 1400.0, 4.5, offset_m=0.0), ZONE, rule) is not None
    assert intrusion(make_track(1, 1400.0, 4.49, offset_m=0.5), ZONE, rule) is None
    assert intrusion(make_track(1, 1400.0, 10.0, offset_m=-0.01), ZONE, rule) is None
    # Open: any speed (it stopped among the workers), d >= -0.3 m.
    assert intrusion(make_track(1, 1400.0, 0.0, offset_m=-0.3), ZONE, rule, active=True) is not None
    assert intrusion(make_track(1, 1400.0, 0.0, offset_m=-0.31), ZONE, rule, active=True) is None
