"""The WZDx 4.2 WorkZoneFeed: valid against the official schema (offline, the vendored CC0
files), the work zone's extent, lanes, closed side and reduced limit from the site file alone,
on the default site and on generated sites of either closure side; served over HTTP."""

from __future__ import annotations

import itertools
import math
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.gateway.helpers import READ_KEY, SITE, gateway_settings, live_server, open_storage
from tests.gateway.test_wzdx import feed_of as device_feed_of
from tests.gateway.test_wzdx import wzdx_validator
from wz_gateway.sites import load_sites
from wz_gateway.storage import Storage
from wz_gateway.wzdx import work_zone_event_id
from wz_gateway.wzdx_workzone import extent_m, work_zone_feed
from wz_shared.site import DEFAULT_SITE_PATH, Schedule, Site
from wz_shared.site_generator import generate_site

T0_UNIX = 1_795_000_000.0
EARTH_RADIUS_M = 6_371_008.8


def assert_valid(feed: dict[str, Any]) -> None:
    validator = wzdx_validator("WorkZoneFeed.json")
    errors = sorted(validator.iter_errors(feed), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:10])


def length_m(coordinates: list[list[float]]) -> float:
    """Great-circle length of a lon/lat polyline [m]."""
    total = 0.0
    for (lon1, lat1), (lon2, lat2) in itertools.pairwise(coordinates):
        p1, p2 = math.radians(lat1), math.radians(lat2)
        dp, dl = p2 - p1, math.radians(lon2 - lon1)
        a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
        total += 2 * EARTH_RADIUS_M * math.asin(math.sqrt(a))
    return total


def feed_of(site: Site) -> dict[str, Any]:
    return work_zone_feed(site, now=T0_UNIX + 60.0, served_since=T0_UNIX, publisher="Test DOT")


def test_the_default_sites_work_zone_is_a_valid_road_event() -> None:
    feed = feed_of(SITE)
    assert_valid(feed)
    (event,) = feed["features"]
    assert event["id"] == work_zone_event_id(SITE)
    props = event["properties"]
    assert props["core_details"]["event_type"] == "work-zone"
    # Two lanes, the left one (site index 1, WZDx order 1) closed: traffic merges right.
    assert props["lanes"] == [
        {"order": 1, "lane_number": 1, "status": "closed", "type": "general"},
        {"order": 2, "lane_number": 2, "status": "open", "type": "general"},
    ]
    assert props["vehicle_impact"] == "some-lanes-closed-merge-right"
    # 55 mph in the zone below 70 mph upstream: 88.5 km/h.
    assert props["reduced_speed_limit_kph"] == pytest.approx(55 * 1.609344, abs=0.1)
    assert props["start_date"] == "2026-11-18T11:06:40Z"  # served_since
    assert props["end_date"] == "2026-12-16T11:06:40Z"  # 28 days on
    assert props["is_start_position_verified"] is False
    start, end = extent_m(SITE)
    # The line follows the road: its length is the extent's within 1 %.
    line = event["geometry"]["coordinates"]
    assert length_m(line) == pytest.approx(end - start, rel=0.01)


def test_a_sites_schedule_gives_the_events_dates_and_their_verification() -> None:
    """The site file's schedule, in UTC whole seconds, verified as it says; the time the
    gateway began serving plays no part. The feed still validates."""
    schedule = Schedule(
        start=datetime(2026, 5, 4, 7, 0, 0, tzinfo=timezone(timedelta(hours=-5))),
        end=datetime(2026, 6, 26, 19, 30, 15, 600_000, tzinfo=UTC),
        start_verified=True,
    )
    feed = feed_of(SITE.model_copy(update={"schedule": schedule}))
    assert_valid(feed)
    props = feed["features"][0]["properties"]
    assert props["start_date"] == "2026-05-04T12:00:00Z"
    assert props["end_date"] == "2026-06-26T19:30:15Z"
    assert (props["is_start_date_verified"], props["is_end_date_verified"]) == (True, False)
    both = schedule.model_copy(update={"end_verified": True})
    props = feed_of(SITE.model_copy(update={"schedule": both}))["features"][0]["properties"]
    assert (props["is_start_date_verified"], props["is_end_date_verified"]) == (True, True)


def test_without_a_schedule_the_event_runs_four_weeks_from_serving_unverified() -> None:
    assert SITE.schedule is None
    feed = work_zone_feed(SITE, now=T0_UNIX + 60.0, served_since=T0_UNIX + 3600.0, publisher="P")
    assert_valid(feed)
    props = feed["features"][0]["properties"]
    assert (props["start_date"], props["end_date"]) == (
        "2026-11-18T12:06:40Z",
        "2026-12-16T12:06:40Z",
    )
    assert (props["is_start_date_verified"], props["is_end_date_verified"]) == (False, False)


@pytest.mark.parametrize("seed", [9301, 9302, 9303, 9304, 9305, 9306])
def test_generated_sites_of_either_side_give_valid_feeds(seed: int) -> None:
    """Seeds never used before: the closure side, lane count and curvature vary."""
    site = generate_site(seed)
    feed = feed_of(site)
    assert_valid(feed)
    props = feed["features"][0]["properties"]
    closed = [lane for lane in props["lanes"] if lane["status"] == "closed"]
    assert len(closed) == 1 and len(props["lanes"]) == len(site.lanes)
    leftmost = site.closed_lane_index == max(lane.index for lane in site.lanes)
    rightmost = site.closed_lane_index == 0
    expected = (
        "some-lanes-closed-merge-right"
        if leftmost and not rightmost
        else "some-lanes-closed-merge-left"
        if rightmost and not leftmost
        else props["vehicle_impact"]
    )
    assert props["vehicle_impact"] == expected
    start, end = extent_m(site)
    line = feed["features"][0]["geometry"]["coordinates"]
    assert length_m(line) == pytest.approx(end - start, rel=0.01)


def test_the_gateway_serves_the_feed(tmp_path: Path) -> None:
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    with live_server(settings, storage) as url:
        response = httpx.get(
            f"{url}/v1/wzdx/work-zone-feed", headers={"X-API-Key": READ_KEY}, timeout=10.0
        )
        refused = httpx.get(f"{url}/v1/wzdx/work-zone-feed", timeout=10.0)
        unknown = httpx.get(
            f"{url}/v1/wzdx/work-zone-feed",
            params={"site": "nowhere"},
            headers={"X-API-Key": READ_KEY},
            timeout=10.0,
        )
    storage.close()
    assert response.status_code == 200, response.text
    assert_valid(response.json())
    assert response.json()["features"][0]["id"] == work_zone_event_id(SITE)
    assert refused.status_code == 401 and unknown.status_code == 404


def test_the_gateway_serves_a_site_files_schedule(tmp_path: Path) -> None:
    """From the site file as the gateway loads it to the served feed (and ``/v1/site``)."""
    path = tmp_path / "site.yaml"
    path.write_text(
        DEFAULT_SITE_PATH.read_text(encoding="utf-8")
        + "schedule:\n  start: 2026-05-04T07:00:00-05:00\n  end: 2026-06-26T19:00:00-05:00\n"
        "  end_verified: true\n",
        encoding="utf-8",
    )
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    with live_server(settings, storage, site=load_sites([path])) as url:
        feed = httpx.get(
            f"{url}/v1/wzdx/work-zone-feed", headers={"X-API-Key": READ_KEY}, timeout=10.0
        )
        site = httpx.get(f"{url}/v1/site", headers={"X-API-Key": READ_KEY}, timeout=10.0)
    storage.close()
    assert feed.status_code == 200, feed.text
    assert_valid(feed.json())
    props = feed.json()["features"][0]["properties"]
    assert (props["start_date"], props["end_date"]) == (
        "2026-05-04T12:00:00Z",
        "2026-06-27T00:00:00Z",
    )
    assert (props["is_start_date_verified"], props["is_end_date_verified"]) == (False, True)
    assert site.json()["schedule"] == {
        "start": "2026-05-04T07:00:00-05:00",
        "end": "2026-06-26T19:00:00-05:00",
        "start_verified": False,
        "end_verified": True,
    }


def test_every_device_names_the_work_zone(tmp_path: Path) -> None:
    """The DeviceFeed's devices and the WorkZoneFeed's event are tied by the event's id."""
    store: Storage = open_storage(gateway_settings(tmp_path))
    devices = device_feed_of(store, T0_UNIX)
    store.close()
    assert devices["features"]
    for feature in devices["features"]:
        core = feature["properties"]["core_details"]
        assert core["road_event_ids"] == [work_zone_event_id(SITE)], core
