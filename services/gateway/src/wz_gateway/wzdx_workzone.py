"""The WZDx 4.2 WorkZoneFeed of a site: the work zone itself as a road event. Pure, no I/O.

One ``work-zone`` road event per site, from the site file alone:

- its **extent**: from the start of the transition (the merging taper, where the lane
  impact begins) to the end of the termination area, as a LineString along the road's
  centreline (a point every ``STEP_M`` and at every vertex of the centreline between);
- its **lanes**, WZDx order (1 at the left): the closed lane ``closed``, the others ``open``;
  ``vehicle_impact`` says which side traffic merges to;
- the **reduced speed limit**: the posted limit in the activity area, when it is lower than
  the limit upstream of the whole work zone (km/h, WZDx's unit);
- its **dates**: the site file's ``schedule`` (:class:`~wz_shared.site.Schedule`, in UTC)
  when it has one, each verified as the schedule says; without one the feed knows no
  contract dates, so ``start_date`` is the first moment the gateway served the site
  (``served_since``) and ``end_date`` is ``planned_days`` later (a trailer stays a few
  weeks), neither verified (``is_*_date_verified: false``). The positions come from the site
  file (surveyed, not from a GPS at the cones: not verified).

The DeviceFeed's devices name this event in their ``road_event_ids``
(:func:`work_zone_event_id`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wz_gateway.wzdx import (
    CC0_LICENSE,
    MPS_TO_KPH,
    UPDATE_FREQUENCY_S,
    WZDX_VERSION,
    data_source_id,
    lane_order,
    rfc3339,
    work_zone_event_id,
)
from wz_shared.site import AreaKind, Site

#: Spacing of the event's geometry along the road [m]: a curve's chord error stays under
#: a decimetre for radii above 300 m.
STEP_M = 50.0
#: A day [s].
DAY_S = 86400.0


def extent_m(site: Site) -> tuple[float, float]:
    """Stations [m] where the event begins (taper start) and ends (termination end)."""
    start = site.area(AreaKind.TRANSITION).start_station_m
    end = max(area.end_station_m for area in site.work_zone)
    return float(start), float(end)


def geometry(site: Site) -> dict[str, Any]:
    """The event's LineString along the centreline, lon/lat (WGS 84, 7 decimals)."""
    start, end = extent_m(site)
    frame = site.road_frame
    stations = np.concatenate(
        [
            np.arange(start, end, STEP_M),
            [s for s in frame.vertex_stations_m if start < s < end],
            [end],
        ]
    )
    coordinates = []
    for station in np.unique(stations):
        x, y = frame.to_site(float(station), 0.0)
        latitude, longitude, _ = site.geo_frame.to_wgs84(float(x), float(y))
        coordinates.append([round(float(longitude), 7), round(float(latitude), 7)])
    return {"type": "LineString", "coordinates": coordinates}


def lanes(site: Site) -> list[dict[str, Any]]:
    """WZDx lanes, left to right: the closed one ``closed``, the others ``open``."""
    out = []
    for lane in sorted(site.lanes, key=lambda lane: lane_order(site, lane.index)):
        order = lane_order(site, lane.index)
        out.append(
            {
                "order": order,
                "lane_number": order,
                "status": "closed" if lane.index == site.closed_lane_index else "open",
                "type": "general",
            }
        )
    return out


def vehicle_impact(site: Site) -> str:
    """``some-lanes-closed-merge-left`` when the closed lane is right of an open one (traffic
    moves left), ``-merge-right`` when left of one, ``all-lanes-closed`` for a one-lane road."""
    open_indices = [lane.index for lane in site.lanes if lane.index != site.closed_lane_index]
    if not open_indices:
        return "all-lanes-closed"
    closed = site.closed_lane_index
    if all(index > closed for index in open_indices):
        return "some-lanes-closed-merge-left"  # index 0 is the rightmost lane
    if all(index < closed for index in open_indices):
        return "some-lanes-closed-merge-right"
    return "some-lanes-closed-split"


def reduced_speed_limit_kph(site: Site) -> float | None:
    """The activity area's posted limit [km/h] when it is below the limit upstream of the
    whole work zone (before its advance-warning area, where the reduction is usually posted)."""
    zone_start = min(area.start_station_m for area in site.work_zone)
    upstream = site.speed_limit_mps_at(max(0.0, zone_start - 1.0))
    activity = site.area(AreaKind.ACTIVITY)
    zone = site.speed_limit_mps_at(0.5 * (activity.start_station_m + activity.end_station_m))
    if zone >= upstream - 1e-6:
        return None
    return round(zone * MPS_TO_KPH, 1)


def dates(site: Site, served_since: float, planned_days: float) -> dict[str, Any]:
    """The event's ``start_date``, ``end_date`` and whether each is verified: the site's
    schedule, or without one from ``served_since`` for ``planned_days``, unverified."""
    schedule = site.schedule
    if schedule is None:
        return {
            "start_date": rfc3339(served_since),
            "end_date": rfc3339(served_since + planned_days * DAY_S),
            "is_start_date_verified": False,
            "is_end_date_verified": False,
        }
    return {
        "start_date": rfc3339(schedule.start.timestamp()),
        "end_date": rfc3339(schedule.end.timestamp()),
        "is_start_date_verified": schedule.start_verified,
        "is_end_date_verified": schedule.end_verified,
    }


def work_zone_feed(
    site: Site,
    *,
    now: float,
    served_since: float,
    publisher: str,
    planned_days: float = 28.0,
    contact_email: str | None = None,
) -> dict[str, Any]:
    """The WZDx 4.2 WorkZoneFeed of ``site`` (a JSON-ready dict); ``served_since`` and
    ``planned_days`` give its dates only when the site has no ``schedule`` (:func:`dates`)."""
    properties: dict[str, Any] = {
        "core_details": {
            "event_type": "work-zone",
            "data_source_id": data_source_id(site),
            "road_names": list(site.road_names) or [site.name],
            "direction": site.road_direction,
            "name": site.name,
            "description": (
                f"Lane {lane_order(site, site.closed_lane_index)} closed (from the left); "
                "monitored by a trailer-mounted sensor mast upstream of the taper"
            ),
            "update_date": rfc3339(now),
        },
        **dates(site, served_since, planned_days),
        "is_start_position_verified": False,
        "is_end_position_verified": False,
        "location_method": "channel-device-method",
        "vehicle_impact": vehicle_impact(site),
        "lanes": lanes(site),
    }
    limit = reduced_speed_limit_kph(site)
    if limit is not None:
        properties["reduced_speed_limit_kph"] = limit
    source: dict[str, Any] = {
        "data_source_id": data_source_id(site),
        "organization_name": publisher,
        "update_date": rfc3339(now),
        "update_frequency": UPDATE_FREQUENCY_S,
        "location_method": "channel-device-method",
    }
    feed_info: dict[str, Any] = {
        "publisher": publisher,
        "version": WZDX_VERSION,
        "license": CC0_LICENSE,
        "update_date": rfc3339(now),
        "update_frequency": UPDATE_FREQUENCY_S,
        "data_sources": [source],
    }
    if contact_email:
        feed_info["contact_email"] = contact_email
        source["contact_email"] = contact_email
    feature = {
        "id": work_zone_event_id(site),
        "type": "Feature",
        "properties": properties,
        "geometry": geometry(site),
    }
    return {"feed_info": feed_info, "type": "FeatureCollection", "features": [feature]}
