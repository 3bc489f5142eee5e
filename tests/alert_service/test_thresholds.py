"""The ``alerts:`` section of the site file and the zone the rules read from the site."""

from __future__ import annotations

from typing import Any

import pytest
import yaml

from tests.alert_service.helpers import SITE
from wz_alert_service.engine import TRACK_RULES, rule_timing
from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import AlertType
from wz_shared.site import (
    DEFAULT_SITE_PATH,
    MPH_TO_MPS,
    AlertRules,
    AreaKind,
    Site,
    SiteFileError,
)


def default_raw() -> dict[str, Any]:
    raw = yaml.safe_load(DEFAULT_SITE_PATH.read_text(encoding="utf-8"))
    assert isinstance(raw, dict)
    return raw


def test_default_site_states_every_threshold_explicitly() -> None:
    raw = default_raw()["alerts"]
    assert set(raw) == set(AlertRules.model_fields)
    # The file repeats the defaults except where this site differs: its approach and its sign.
    assert SITE.alerts == AlertRules(approach_length_m=1400.0, devices={"sign_station_m": 500.0})


def test_site_without_alerts_section_gets_the_defaults() -> None:
    raw = default_raw()
    del raw["alerts"]
    site = Site.model_validate(raw)
    assert site.alerts == AlertRules()
    assert site.alerts.speeding.margin_mph == 5.0
    assert site.alerts.aggressive_approach.comfortable_decel_mps2 == 3.4
    assert site.alerts.hard_braking.decel_g == 0.4
    assert (site.alerts.short_ttc.critical_ttc_s, site.alerts.short_ttc.warning_ttc_s) == (0.5, 1.0)
    assert site.alerts.short_ttc.max_ttc_s == 1.5


def test_partial_alerts_section_keeps_the_other_defaults() -> None:
    raw = default_raw()
    raw["alerts"] = {"speeding": {"margin_mph": 10.0}}
    site = Site.model_validate(raw)
    assert site.alerts.speeding.margin_mph == 10.0
    assert site.alerts.speeding.hold_s == 1.0
    assert site.alerts.queue == AlertRules().queue


@pytest.mark.parametrize(
    ("section", "reason"),
    [
        ({"speeding": {"margin_mph": 10.0, "critical_excess_mph": 5.0}}, "critical_excess_mph"),
        ({"hard_braking": {"decel_g": 0.3, "critical_decel_g": 0.2}}, "critical_decel_g"),
        ({"hard_braking": {"decel_g": 0.1, "hysteresis_g": 0.1}}, "hysteresis_g"),
        ({"short_ttc": {"critical_ttc_s": 1.2, "warning_ttc_s": 1.0}}, "critical_ttc_s"),
        ({"aggressive_approach": {"critical_decel_mps2": 2.0}}, "critical_decel_mps2"),
        ({"queue": {"min_vehicles": 0}}, "min_vehicles"),
        ({"speeding": {"margin_kph": 5.0}}, "margin_kph"),
        ({"late_merge": {"distance_m": -1.0}}, "distance_m"),
    ],
    ids=[
        "speed-bands",
        "braking-bands",
        "braking-hysteresis",
        "ttc-bins",
        "decel-bands",
        "no-vehicles",
        "unknown-key",
        "negative-distance",
    ],
)
def test_bad_thresholds_are_refused_naming_the_field(section: dict[str, Any], reason: str) -> None:
    raw = default_raw()
    raw["alerts"] = section
    with pytest.raises(ValueError, match=reason):
        Site.model_validate(raw)


def test_alert_rules_are_frozen() -> None:
    with pytest.raises(ValueError):
        SITE.alerts.speeding.margin_mph = 1.0  # type: ignore[misc]


def test_every_alert_type_has_its_rule_section() -> None:
    for alert_type in AlertType:
        assert rule_timing(SITE.alerts, alert_type) is getattr(SITE.alerts, alert_type.value)
    assert set(TRACK_RULES) == set(AlertType) - {AlertType.QUEUE}


def test_zone_of_the_default_site() -> None:
    zone = ZoneGeometry.from_site(SITE)
    # approach = [1700 - 1400, 1700)
    assert (zone.approach_start_m, zone.approach_end_m) == (300.0, 1700.0)
    assert (zone.taper_start_m, zone.taper_end_m) == (1000.0, 1201.0)
    assert (zone.work_space_start_m, zone.activity_start_m) == (1201.0, 1300.0)
    assert zone.advance_warning_m == 300.0
    assert zone.zone_limit_mps == 55.0 * MPH_TO_MPS
    # lane 1: centre 1.83, width 3.66 -> [0, 3.66)
    assert zone.closed_lane_index == 1
    assert (zone.closed_low_m, zone.closed_high_m) == pytest.approx((0.0, 3.66), abs=1e-12)
    assert zone.merge_direction == "RIGHT"
    assert zone.sign_station_m == 500.0
    assert zone.in_approach(300.0) and zone.in_approach(1699.999) and not zone.in_approach(1700.0)


def test_zone_defaults_and_a_right_lane_closure() -> None:
    raw = default_raw()
    del raw["alerts"]
    raw["closed_lane_index"] = 0
    zone = ZoneGeometry.from_site(Site.model_validate(raw))
    assert zone.approach_start_m == 1700.0 - 1500.0
    assert zone.sign_station_m == 300.0  # the advance-warning area's start
    assert zone.merge_direction == "LEFT"
    assert (zone.closed_low_m, zone.closed_high_m) == pytest.approx((-3.66, 0.0), abs=1e-12)


def test_zone_needs_a_taper_and_an_activity_area() -> None:
    site = SITE.model_copy(
        update={"work_zone": [a for a in SITE.work_zone if a.kind is not AreaKind.TRANSITION]}
    )
    with pytest.raises(SiteFileError, match="transition"):
        ZoneGeometry.from_site(site)
