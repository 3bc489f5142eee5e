"""Site files: the default site, every kind of bad file, derived geometry and lookups."""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from wz_shared.geometry import GeoFrame, RoadFrame
from wz_shared.site import (
    DEFAULT_SITE_PATH,
    AreaKind,
    Site,
    SiteFileError,
    load_site,
    site_document,
)


def default_raw() -> dict[str, Any]:
    raw = yaml.safe_load(DEFAULT_SITE_PATH.read_text(encoding="utf-8"))
    assert isinstance(raw, dict)
    return raw


def write_site(tmp_path: Path, raw: dict[str, Any]) -> Path:
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(raw), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site(DEFAULT_SITE_PATH)


# --- the default site ------------------------------------------------------------------------


def test_default_site_loads(site: Site) -> None:
    assert site.site_id == "us75-lincoln"
    assert len(site.centerline_xy_m) == 39
    assert [lane.index for lane in site.lanes] == [0, 1]
    assert site.closed_lane_index == 1
    assert site.road_length_m == pytest.approx(2000.0, abs=0.1)
    assert site.speed_limit_mps_at(1100.0) == pytest.approx(55 * 0.44704)


def test_default_site_geometry_is_a_straight_then_a_right_hand_curve(site: Site) -> None:
    frame = site.road_frame
    assert frame.length_m == pytest.approx(site.road_length_m, abs=1e-9)
    assert float(frame.heading_at(700.0)) == pytest.approx(math.pi / 2, abs=1e-12)
    # 600 m of a 1500 m right-hand arc turn the road 0.4 rad clockwise.
    assert float(frame.heading_at(frame.length_m)) == pytest.approx(math.pi / 2 - 0.4, abs=0.01)
    # The mast stands 7.5 m right of the centerline at station 980 m.
    mast = site.sensor("lidar-mast").pose
    station, offset = frame.to_road(mast.x_m, mast.y_m)
    assert (float(station), float(offset)) == pytest.approx((980.0, -7.5), abs=1e-9)


def test_frames_are_built_once_and_do_not_change_the_model(site: Site) -> None:
    assert isinstance(site.road_frame, RoadFrame)
    assert site.road_frame is site.road_frame
    assert isinstance(site.geo_frame, GeoFrame)
    assert site.geo_frame is site.geo_frame
    fresh = load_site(DEFAULT_SITE_PATH)
    assert fresh == site  # the cached frames are not fields
    assert "road_frame" not in site.model_dump()
    assert Site.model_validate_json(site.model_dump_json()) == site


def test_model_copy_drops_the_cached_frames(site: Site) -> None:
    frame = site.road_frame
    shorter = site.model_copy(update={"centerline_xy_m": site.centerline_xy_m[:5]})
    assert shorter.road_frame is not frame
    assert shorter.road_frame.length_m == pytest.approx(400.0)
    assert site.road_frame is frame


# --- bad site files --------------------------------------------------------------------------


def test_missing_field(tmp_path: Path) -> None:
    raw = default_raw()
    del raw["origin"]
    with pytest.raises(SiteFileError, match=r"(?s)origin.*Field required"):
        load_site(write_site(tmp_path, raw))


def test_unknown_field(tmp_path: Path) -> None:
    raw = default_raw()
    raw["lanes"][0]["widht_m"] = 3.5
    with pytest.raises(SiteFileError, match=r"(?s)widht_m.*Extra inputs are not permitted"):
        load_site(write_site(tmp_path, raw))


def test_road_names_and_direction_for_feeds(tmp_path: Path, site: Site) -> None:
    assert (site.road_names, site.road_direction) == (["US-75"], "northbound")
    raw = default_raw()
    del raw["road_names"], raw["road_direction"]
    bare = load_site(write_site(tmp_path, raw))  # optional: older site files still load
    assert (bare.road_names, bare.road_direction) == ([], "unknown")
    raw["road_direction"] = "north"
    with pytest.raises(SiteFileError, match=r"(?s)road_direction.*'northbound'"):
        load_site(write_site(tmp_path, raw))


SCHEDULE = """
schedule:
  start: 2026-05-04T07:00:00-05:00
  end: "2026-06-27T00:00:00Z"
  start_verified: true
"""


def test_a_schedule_gives_the_work_zones_dates(tmp_path: Path, site: Site) -> None:
    """Optional (the default site has none); YAML's own timestamps and quoted ISO 8601 text
    both read, with their offsets; a site document keeps it and drops it when absent."""
    assert site.schedule is None
    assert "schedule" not in site_document(site)
    path = tmp_path / "site.yaml"
    path.write_text(DEFAULT_SITE_PATH.read_text(encoding="utf-8") + SCHEDULE, encoding="utf-8")
    schedule = load_site(path).schedule
    assert schedule is not None
    assert schedule.start == datetime(2026, 5, 4, 12, 0, tzinfo=UTC)
    assert schedule.start.utcoffset() == timedelta(hours=-5)
    assert schedule.end == datetime(2026, 6, 27, 0, 0, tzinfo=UTC)
    assert (schedule.start_verified, schedule.end_verified) == (True, False)
    document = site_document(load_site(path))
    assert document["schedule"]["start"] == "2026-05-04T07:00:00-05:00"
    assert load_site(write_site(tmp_path, document)).schedule == schedule


@pytest.mark.parametrize(
    ("schedule", "message"),
    [
        (
            {"start": "2026-06-27T00:00:00Z", "end": "2026-05-04T07:00:00-05:00"},
            r"schedule: end 2026-05-04T07:00:00-05:00 must be after start 2026-06-27T00:00:00\+00:00",
        ),
        (
            {"start": "2026-05-04T07:00:00Z", "end": "2026-05-04T02:00:00-05:00"},
            r"schedule: end .* must be after start",
        ),
        (
            {"start": "2026-05-04T07:00:00", "end": "2026-06-27T00:00:00Z"},
            r"(?s)schedule\.start\n.*2026-05-04T07:00:00 has no UTC offset",
        ),
        (
            {"start": "2026-05-04T07:00:00Z", "end": "2026-06-27"},
            r"(?s)schedule\.end\n.*2026-06-27T00:00:00 has no UTC offset",
        ),
        ({"start": "2026-05-04T07:00:00Z"}, r"(?s)schedule\.end\n.*Field required"),
    ],
    ids=["end-before-start", "end-at-start", "naive-start", "date-only-end", "no-end"],
)
def test_a_bad_schedule_is_refused_with_the_field_named(
    tmp_path: Path, schedule: dict[str, str], message: str
) -> None:
    raw = default_raw()
    raw["schedule"] = schedule
    with pytest.raises(SiteFileError, match=message):
        load_site(write_site(tmp_path, raw))


def test_nan(tmp_path: Path) -> None:
    raw = default_raw()
    raw["centerline_xy_m"][3][0] = float("nan")
    with pytest.raises(SiteFileError, match=r"(?s)centerline_xy_m\.3\.0.*finite number"):
        load_site(write_site(tmp_path, raw))


def test_bad_yaml(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text("site_id: us75-lincoln\nlanes: [{index: 0\n", encoding="utf-8")
    with pytest.raises(SiteFileError, match="is not valid YAML"):
        load_site(path)


def test_not_a_mapping(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text("- just\n- a list\n", encoding="utf-8")
    with pytest.raises(SiteFileError, match="must hold a mapping"):
        load_site(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SiteFileError, match="cannot read site file"):
        load_site(tmp_path / "nowhere.yaml")


def test_closed_lane_that_does_not_exist(tmp_path: Path) -> None:
    raw = default_raw()
    raw["closed_lane_index"] = 2
    with pytest.raises(SiteFileError, match="closed_lane_index 2 is not a lane of this site"):
        load_site(write_site(tmp_path, raw))


def test_unordered_lanes(tmp_path: Path) -> None:
    raw = default_raw()
    raw["lanes"][0]["center_offset_m"], raw["lanes"][1]["center_offset_m"] = 1.83, -1.83
    with pytest.raises(SiteFileError, match="lane center offsets must increase with lane index"):
        load_site(write_site(tmp_path, raw))


def test_centerline_turning_back(tmp_path: Path) -> None:
    raw = default_raw()
    raw["centerline_xy_m"][5] = [0.0, 395.0]  # vertex 5 folds back onto vertex 4
    with pytest.raises(SiteFileError, match=r"turns by 180\.0 deg at vertex 4"):
        load_site(write_site(tmp_path, raw))


def test_error_names_the_file(tmp_path: Path) -> None:
    raw = default_raw()
    raw["closed_lane_index"] = 7
    path = write_site(tmp_path, raw)
    with pytest.raises(SiteFileError, match=str(path)):
        load_site(path)


# --- lookups ---------------------------------------------------------------------------------


def test_lane_index_at(site: Site) -> None:
    # Lane 0 covers [-3.66, 0), lane 1 covers [0, 3.66).
    offsets = np.array([-5.0, -3.67, -3.66, -1.83, -1e-9, 0.0, 1.83, 3.65, 3.66, 7.5])
    expected = np.array([-1, -1, 0, 0, 0, 1, 1, 1, -1, -1])
    np.testing.assert_array_equal(site.lane_index_at(offsets), expected)
    assert site.lane_index_at(-1.83).shape == ()
    assert int(site.lane_index_at(-1.83)) == 0
    assert site.lane_index_at(np.zeros((2, 3))).shape == (2, 3)


def test_lane_index_at_follows_the_road(site: Site) -> None:
    """A vehicle in the middle of each lane, on the curve, is found in that lane."""
    frame = site.road_frame
    station = np.linspace(1400.0, 1990.0, 50)
    for lane in site.lanes:
        x, y = frame.to_site(station, np.full(station.size, lane.center_offset_m))
        _, offset = frame.to_road(x, y)
        assert np.all(site.lane_index_at(offset) == lane.index)


@pytest.mark.parametrize(
    ("station_m", "expected"),
    [
        (-5.0, None),
        (0.0, None),
        (299.9, None),
        (300.0, AreaKind.ADVANCE_WARNING),
        (999.9, AreaKind.ADVANCE_WARNING),
        (1000.0, AreaKind.TRANSITION),
        (1250.0, AreaKind.BUFFER),
        (1300.0, AreaKind.ACTIVITY),
        (1799.9, AreaKind.TERMINATION),
        (1800.0, None),
        (2500.0, None),
    ],
)
def test_area_at(site: Site, station_m: float, expected: AreaKind | None) -> None:
    assert site.area_at(station_m) == expected


def test_pose_rotation_axes() -> None:
    from wz_shared.site import Pose

    # Facing north (yaw 90): forward is +y, left is -x, up is +z.
    r = Pose(x_m=0, y_m=0, z_m=0, yaw_deg=90.0).rotation()
    np.testing.assert_allclose(r[:, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(r[:, 1], [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(r[:, 2], [0, 0, 1], atol=1e-12)
    # Pitch -10 (looking down): forward dips below the horizon.
    forward = Pose(x_m=0, y_m=0, z_m=6, pitch_deg=-10.0).rotation()[:, 0]
    np.testing.assert_allclose(forward, [np.cos(np.radians(10)), 0, -np.sin(np.radians(10))])
    # Roll +5: the left axis rises (right side down).
    left = Pose(x_m=0, y_m=0, z_m=6, roll_deg=5.0).rotation()[:, 1]
    assert left[2] > 0
    # Always a proper rotation.
    r = Pose(x_m=1, y_m=2, z_m=3, yaw_deg=-93, pitch_deg=-8, roll_deg=2).rotation()
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
