"""The smoothed trajectory of an ended track: pure, no I/O.

While a track lives, the gateway stores the tracker's estimate at every cycle, which used the
measurements up to that cycle only. When the track has ended, every point can use the whole
track: :func:`smooth_trajectory` runs the RTS smoother of the tracker's motion model
(:func:`wz_shared.motion.rts_smooth`, where the maths is) over the stored states and
covariances, taken as the filter's ``x_k|k``, ``P_k|k``, with the process noise the tracker's
batches carried (stored with the track's life).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64
from wz_shared.motion import ProcessNoise, rts_smooth
from wz_shared.site import Site

# --- a stored trajectory -------------------------------------------------------------------


@dataclass(frozen=True)
class StoredTrajectory:
    """One track life's stored points, oldest first, as arrays of one length n.

    ``covariance`` is (n, 4, 4); ``length_m``/``width_m`` are NaN where the tracker gave none;
    the rest are (n,). ``received_at`` is the gateway's wall clock of each point [Unix s].
    """

    track_id: int
    stamp: F64
    x_m: F64
    y_m: F64
    vx_mps: F64
    vy_mps: F64
    covariance: F64
    latitude_deg: F64
    longitude_deg: F64
    station_m: F64
    offset_m: F64
    lane_index: npt.NDArray[np.int64]
    speed_mps: F64
    heading_rad: F64
    object_class: tuple[str, ...]
    status: tuple[str, ...]
    length_m: F64
    width_m: F64
    received_at: F64

    def __len__(self) -> int:
        return len(self.stamp)


def smooth_trajectory(
    points: StoredTrajectory, site: Site, noise: ProcessNoise
) -> StoredTrajectory:
    """The smoothed trajectory of an ended track: :func:`~wz_shared.motion.rts_smooth` on its
    states with the tracker's process noise ``noise``, then the road frame, lane and WGS84
    position of each smoothed state.

    What hindsight knows better is taken from the last point for every point: the class (the
    tracker's vote over the whole track) and the size. Stamps, status and ``received_at`` are
    kept (retention then deletes a smoothed point with its fused one).
    """
    x = np.column_stack([points.x_m, points.y_m, points.vx_mps, points.vy_mps])
    x_s, P_s = rts_smooth(points.stamp, x, points.covariance, noise)
    station, offset = site.road_frame.to_road(x_s[:, 0], x_s[:, 1])
    lane = np.maximum(np.asarray(site.lane_index_at(offset)), -1).astype(np.int64)
    latitude, longitude, _ = site.geo_frame.to_wgs84(x_s[:, 0], x_s[:, 1])
    n = len(points)
    return replace(
        points,
        x_m=x_s[:, 0],
        y_m=x_s[:, 1],
        vx_mps=x_s[:, 2],
        vy_mps=x_s[:, 3],
        covariance=P_s,
        latitude_deg=np.asarray(latitude, dtype=np.float64),
        longitude_deg=np.asarray(longitude, dtype=np.float64),
        station_m=np.asarray(station, dtype=np.float64),
        offset_m=np.asarray(offset, dtype=np.float64),
        lane_index=lane,
        speed_mps=np.hypot(x_s[:, 2], x_s[:, 3]),
        heading_rad=np.arctan2(x_s[:, 3], x_s[:, 2]),
        object_class=(points.object_class[-1],) * n,
        length_m=np.full(n, points.length_m[-1]),
        width_m=np.full(n, points.width_m[-1]),
    )
