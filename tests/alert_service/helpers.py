"""Hand-made tracks and batches on the default site (us75-lincoln).

The default site's zone, in the road frame: approach [300, 1700) m, taper 1000-1201 m, buffer
1201-1300 m, activity 1300-1700 m; 55 mph (24.5872 m/s) from 300 m; lane 1 (the left lane,
offsets [0, 3.66) m) closed; lane 0 at [-3.66, 0) m; the sign at 500 m.
"""

from __future__ import annotations

from collections.abc import Iterable

from wz_shared.messages import Track, TrackBatch, TrackStatus
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site

SITE: Site = load_site(DEFAULT_SITE_PATH)
OPEN_LANE_D = -1.83
CLOSED_LANE_D = 1.83


def make_track(
    track_id: int,
    station_m: float,
    speed_mps: float,
    *,
    offset_m: float = OPEN_LANE_D,
    lane_index: int | None = None,
    length_m: float | None = None,
    status: TrackStatus = TrackStatus.CONFIRMED,
) -> Track:
    """A track on the straight part of the road (x = -d, y = s), lane from the offset."""
    lane = int(SITE.lane_index_at(offset_m)) if lane_index is None else lane_index
    return Track(
        track_id=track_id,
        x_m=-offset_m,
        y_m=station_m,
        vx_mps=0.0,
        vy_mps=speed_mps,
        covariance=[0.0] * 16,
        station_m=station_m,
        offset_m=offset_m,
        speed_mps=speed_mps,
        heading_rad=1.5707963267948966,
        lane_index=lane,
        age_s=10.0,  # followed a while (the short-TTC rule wants 2 s)
        hits=10,
        confirmed=status is not TrackStatus.TENTATIVE,
        sources=["lidar-mast"],
        status=status,
        length_m=length_m,
    )


def batch(stamp: float, tracks: Iterable[Track], cycle_index: int = 0) -> TrackBatch:
    return TrackBatch(
        site=SITE.site_id,
        source_id="fusion-tracker",
        stamp=stamp,
        cycle_index=cycle_index,
        tracks=list(tracks),
    )


def stamps(duration_s: float, rate_hz: float = 20.0, start_s: float = 0.0) -> list[float]:
    """Batch stamps ``start + k / rate`` (computed, not summed, as a tracker's grid is)."""
    return [start_s + k / rate_hz for k in range(round(duration_s * rate_hz))]
