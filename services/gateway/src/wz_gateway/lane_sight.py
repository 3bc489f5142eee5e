"""Whether the sensors see each lane at the traffic detector, or other vehicles hide it.

The virtual loop (:func:`~wz_gateway.wzdx.detector_station_m`) counts the vehicles the tracks
carry across it. Where a truck in the near lane stands between the mast and the far lane, a car
in the far lane passes unseen, and its lane's count falls short; in a queue beside a closure
the trucks stand there for minutes. So, per lane, this module measures the share of the
interval its loop spot is hidden: every :data:`SAMPLE_PERIOD_S`, the spot (the lane's centre at
the loop, at a car's roof, :data:`~wz_shared.coverage.CAR_HEIGHT_M`) is *hidden* when, from
every sensor that covers it (:class:`~wz_shared.coverage.SiteCoverage`), the sight line passes
through one of the tracked vehicles of that moment (:func:`wz_shared.occlusion.hidden`); a
spot no sensor covers is hidden all the time.

Vehicles arrive independently of the hiding, so about that share of a lane's vehicles pass the
loop unseen; the tracker carries some of them across from where they were seen, but the count
cannot be trusted to the lane target's 5 % once the share exceeds it
(:data:`~wz_gateway.traffic.HIDDEN_SHARE_LIMIT`): the lane's volume is then *unreliable*, and
the WZDx feed withholds it and says why.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64
from wz_shared.coverage import CAR_HEIGHT_M, SiteCoverage, SiteSight
from wz_shared.occlusion import Boxes
from wz_shared.site import Site

#: How often the lanes' sight is sampled [s].
SAMPLE_PERIOD_S = 0.5
#: Vehicles this far beyond the loop or the farthest sensor still count as in the way [m]
#: (half a semitrailer's length: its centre may lie beyond while its body is between).
_REACH_M = 10.0


def sight_station_range(site: Site, detector_station_m: float) -> tuple[float, float]:
    """The stations between the loop and the site's sensors (with a margin): where a vehicle
    may stand in the way of a sensor's view of the loop [m]."""
    frame = site.road_frame
    stations = [detector_station_m] + [
        float(frame.to_road(m.pose.x_m, m.pose.y_m)[0]) for m in site.sensors
    ]
    return min(stations) - _REACH_M, max(stations) + _REACH_M


def lane_hidden_shares(
    site: Site,
    detector_station_m: float,
    stamp: npt.ArrayLike,
    x_m: npt.ArrayLike,
    y_m: npt.ArrayLike,
    heading_rad: npt.ArrayLike,
    length_m: npt.ArrayLike,
    width_m: npt.ArrayLike,
    object_class: Sequence[str],
    start_stamp: float,
    end_stamp: float,
    coverage: SiteCoverage | None = None,
) -> dict[int, float]:
    """Per lane (site index), the share of ``[start_stamp, end_stamp]`` its loop spot was hidden
    from every sensor covering it (module docstring); the track points are every point of
    the window between the loop and the sensors (:func:`sight_station_range`), any order.

    Samples are the points' own stamps, at most one per :data:`SAMPLE_PERIOD_S`; a window with
    no point has no sample, and each lane then counts as seen unless no sensor covers it.
    """
    sight = SiteSight(site, coverage)
    lanes = sorted(site.lanes, key=lambda lane: lane.index)
    xs, ys = site.road_frame.to_site(
        np.full(len(lanes), detector_station_m), np.array([lane.center_offset_m for lane in lanes])
    )
    spots = np.column_stack([xs, ys, np.full(len(lanes), CAR_HEIGHT_M)])
    t = np.asarray(stamp, dtype=np.float64)
    order = np.argsort(t, kind="stable")
    t = t[order]
    samples = _sample_stamps(t, start_stamp, end_stamp)
    covers = sight.covers(spots)  # the spots stand still: once for every sample
    hidden_count = np.zeros(len(lanes))
    if samples.size:
        x, y = np.asarray(x_m, np.float64)[order], np.asarray(y_m, np.float64)[order]
        heading = np.asarray(heading_rad, np.float64)[order]
        length = np.asarray(length_m, np.float64)[order]
        width = np.asarray(width_m, np.float64)[order]
        kinds = np.asarray(object_class, dtype=object)[order]
        firsts = np.searchsorted(t, samples, side="left")
        ends = np.searchsorted(t, samples, side="right")
        for a, b in zip(firsts, ends, strict=True):
            boxes = Boxes.of(x[a:b], y[a:b], heading[a:b], length[a:b], width[a:b], kinds[a:b])
            hidden_count += sight.hidden(spots, boxes, covers)
        shares = hidden_count / samples.size
    else:
        shares = np.zeros(len(lanes))
    shares[~covers.any(axis=0)] = 1.0
    return {lane.index: float(share) for lane, share in zip(lanes, shares, strict=True)}


def _sample_stamps(stamps: F64, start_stamp: float, end_stamp: float) -> F64:
    """The distinct stamps (sorted) inside the window, thinned to one per
    :data:`SAMPLE_PERIOD_S`."""
    inside = np.unique(stamps[(stamps >= start_stamp) & (stamps <= end_stamp)])
    kept: list[float] = []
    for value in inside:
        if not kept or value - kept[-1] >= SAMPLE_PERIOD_S - 1e-9:
            kept.append(float(value))
    return np.array(kept, dtype=np.float64)
