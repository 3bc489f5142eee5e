"""The work zone as the rules see it: stations, the zone limit and the closed lane's band.

Everything here is read once from the site file (:class:`wz_shared.site.Site` and its
``alerts:`` section) and kept in a frozen :class:`ZoneGeometry`, so a rule never searches the
site per track.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wz_shared.site import AlertRules, AreaKind, Site, SiteFileError


@dataclass(frozen=True)
class ZoneGeometry:
    """Stations [m] and lanes of the work zone, in the road frame (s along, d left).

    Attributes
    ----------
    site : Site
        The site (for the posted limit at a station).
    rules : AlertRules
        The thresholds.
    approach_start_m, approach_end_m : float
        The approach ``[activity end - approach_length_m, activity end)``.
    advance_warning_m : float
        Where "past the advance warning" begins (aggressive approach).
    taper_start_m, taper_end_m : float
        The merging taper (the transition area).
    work_space_start_m : float
        Start of the buffer (the activity area's start where there is no buffer).
    activity_start_m : float
        Start of the activity area; ``approach_end_m`` is its end.
    zone_limit_mps : float
        Posted limit at the taper start [m/s].
    closed_lane_index : int
        The closed lane.
    closed_low_m, closed_high_m : float
        The closed lane's offset band ``[low, high)`` [m].
    merge_direction : {"RIGHT", "LEFT"}
        Where traffic in the closed lane must go: right when the closed lane is left of every
        open lane.
    sign_station_m : float
        The message sign and beacon.
    """

    site: Site
    rules: AlertRules
    approach_start_m: float
    approach_end_m: float
    advance_warning_m: float
    taper_start_m: float
    taper_end_m: float
    work_space_start_m: float
    activity_start_m: float
    zone_limit_mps: float
    closed_lane_index: int
    closed_low_m: float
    closed_high_m: float
    merge_direction: Literal["RIGHT", "LEFT"]
    sign_station_m: float

    @classmethod
    def from_site(cls, site: Site, rules: AlertRules | None = None) -> ZoneGeometry:
        """Read the zone from a site; ``rules`` default to the site's ``alerts:`` section.

        Raises
        ------
        SiteFileError
            When the site has no transition or no activity area (no rule can place itself).
        """
        rules = site.alerts if rules is None else rules
        kinds = {area.kind for area in site.work_zone}
        missing = [k.value for k in (AreaKind.TRANSITION, AreaKind.ACTIVITY) if k not in kinds]
        if missing:
            raise SiteFileError(
                f"site {site.site_id}: the alert rules need a {' and an '.join(missing)} area "
                "in work_zone"
            )
        taper = site.area(AreaKind.TRANSITION)
        activity = site.area(AreaKind.ACTIVITY)
        work_space_start = (
            site.area(AreaKind.BUFFER).start_station_m
            if AreaKind.BUFFER in kinds
            else activity.start_station_m
        )
        advance_start = (
            site.area(AreaKind.ADVANCE_WARNING).start_station_m
            if AreaKind.ADVANCE_WARNING in kinds
            else max(0.0, taper.start_station_m - rules.approach_length_m)
        )
        advance_warning = rules.aggressive_approach.advance_warning_station_m
        sign = rules.devices.sign_station_m
        closed = site.lane(site.closed_lane_index)
        open_offsets = [lane.center_offset_m for lane in site.lanes if lane is not closed]
        return cls(
            site=site,
            rules=rules,
            approach_start_m=max(0.0, activity.end_station_m - rules.approach_length_m),
            approach_end_m=activity.end_station_m,
            advance_warning_m=advance_start if advance_warning is None else advance_warning,
            taper_start_m=taper.start_station_m,
            taper_end_m=taper.end_station_m,
            work_space_start_m=work_space_start,
            activity_start_m=activity.start_station_m,
            zone_limit_mps=site.speed_limit_mps_at(taper.start_station_m),
            closed_lane_index=closed.index,
            closed_low_m=closed.center_offset_m - 0.5 * closed.width_m,
            closed_high_m=closed.center_offset_m + 0.5 * closed.width_m,
            merge_direction="RIGHT" if closed.center_offset_m > max(open_offsets) else "LEFT",
            sign_station_m=advance_start if sign is None else sign,
        )

    def in_approach(self, station_m: float) -> bool:
        """Whether a station lies in the approach ``[approach_start_m, approach_end_m)``."""
        return self.approach_start_m <= station_m < self.approach_end_m

    def speed_limit_mps_at(self, station_m: float) -> float:
        """Posted limit [m/s] at a station (the site's speed limits)."""
        return self.site.speed_limit_mps_at(station_m)

    def in_closed_lane(self, offset_m: float, widen_m: float = 0.0) -> bool:
        """Whether an offset d [m] lies in the closed lane's band, widened by ``widen_m`` a side.

        ``closed_low_m - widen_m <= d < closed_high_m + widen_m``.
        """
        return self.closed_low_m - widen_m <= offset_m < self.closed_high_m + widen_m

    def depth_in_closed_lane_m(self, offset_m: float) -> float:
        """How far inside the closed lane's band an offset lies [m], negative outside.

        ``min(d - low, high - d)``: the distance to the band's nearer edge.
        """
        return min(offset_m - self.closed_low_m, self.closed_high_m - offset_m)
