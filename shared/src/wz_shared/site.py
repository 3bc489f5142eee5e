"""Site description: one YAML file per deployment, validated by pydantic.

A site file describes the road (a centerline polyline in the site frame), its lanes, the
work-zone areas by station, the speed limits, every sensor mount and the alert thresholds. The
simulator builds its SUMO network and sensor models from it; detectors, tracker, alerts and
gateway read the same file, so simulation and deployment share one description.

Frames of reference
-------------------
- Site frame: local ENU metres (x east, y north, z up) anchored at ``origin`` (WGS84).
- Road frame: station ``s`` [m] along the centerline in the direction of travel, and lateral
  offset ``d`` [m] from the centerline, positive to the left of the direction of travel.

The centerline is the reference line of the carriageway (for the default site: the line between
the two lanes). Lanes are given by the offset of their centre from it, so lane 0 (the rightmost,
as in SUMO) of a two-lane road of 3.66 m lanes sits at ``d = -1.83``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from datetime import datetime
from enum import StrEnum
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal, Self

import numpy as np
import numpy.typing as npt
import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from wz_shared.camera_calibration import CalibrationError, read_calibration
from wz_shared.geometry import GeoFrame, RoadFrame

MPH_TO_MPS = 0.44704

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
SiteId = Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,62}$")]
#: The fields a camera's calibration file fills in (:func:`load_site`).
CALIBRATION_FIELDS = ("calibration_file", "fx_px", "fy_px", "cx_px", "cy_px", "distortion")
#: A camera's stated field of view and the one its calibration implies may differ by this [deg].
CALIBRATED_FOV_TOLERANCE_DEG = 1.0
# Site attributes computed once and kept in the instance's __dict__ (functools.cached_property).
_CACHED_FRAMES = ("road_frame", "geo_frame")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class GeoOrigin(_Strict):
    """WGS84 anchor of the site frame's origin (x = y = 0, z = 0 at ``altitude_m``)."""

    latitude_deg: Annotated[float, Field(ge=-90.0, le=90.0)]
    longitude_deg: Annotated[float, Field(ge=-180.0, le=180.0)]
    altitude_m: FiniteFloat = 0.0


class Lane(_Strict):
    """One lane of the carriageway; ``index`` 0 is the rightmost lane (SUMO's convention)."""

    index: Annotated[int, Field(ge=0)]
    center_offset_m: FiniteFloat
    width_m: Annotated[float, Field(gt=2.0, le=6.0)] = 3.66


class AreaKind(StrEnum):
    """Temporary traffic control areas of a work zone (MUTCD Part 6)."""

    ADVANCE_WARNING = "advance_warning"
    TRANSITION = "transition"  # the merging taper
    BUFFER = "buffer"
    ACTIVITY = "activity"
    TERMINATION = "termination"


class WorkZoneArea(_Strict):
    """A stretch of road ``[start_station_m, end_station_m)`` with one role in the work zone."""

    kind: AreaKind
    start_station_m: Annotated[float, Field(ge=0.0)]
    end_station_m: Annotated[float, Field(ge=0.0)]

    @model_validator(mode="after")
    def _ordered(self) -> WorkZoneArea:
        if self.end_station_m <= self.start_station_m:
            raise ValueError(
                f"work-zone area {self.kind}: end_station_m {self.end_station_m} must be greater "
                f"than start_station_m {self.start_station_m}"
            )
        return self


class SpeedLimit(_Strict):
    """Posted limit from ``start_station_m`` to ``end_station_m``."""

    start_station_m: Annotated[float, Field(ge=0.0)]
    end_station_m: Annotated[float, Field(gt=0.0)]
    speed_limit_mph: Annotated[float, Field(gt=0.0, le=90.0)]

    @property
    def speed_limit_mps(self) -> float:
        return self.speed_limit_mph * MPH_TO_MPS


class Pose(_Strict):
    """Sensor pose in the site frame: position [m] and yaw/pitch/roll [deg].

    The sensor frame has x forward, y left, z up. yaw is measured counter-clockwise from the
    site x axis (east); pitch is positive nose-up (a sensor looking down at the road has
    negative pitch); roll is positive right side down (about x). See :meth:`rotation`.
    """

    x_m: FiniteFloat
    y_m: FiniteFloat
    z_m: FiniteFloat
    yaw_deg: FiniteFloat = 0.0
    pitch_deg: FiniteFloat = 0.0
    roll_deg: FiniteFloat = 0.0

    @property
    def position_m(self) -> npt.NDArray[np.float64]:
        """Position in the site frame, shape (3,)."""
        return np.array([self.x_m, self.y_m, self.z_m])

    def rotation(self) -> npt.NDArray[np.float64]:
        """Rotation from the sensor frame to the site frame, shape (3, 3).

        ``p_site = R @ p_sensor + position``; the columns of ``R`` are the sensor's x
        (forward), y (left) and z (up) axes in the site frame. ``R = Rz(yaw) Ry(-pitch)
        Rx(roll)``: the minus makes positive pitch raise the x axis (with y to the left, a
        right-handed ``Ry(+pitch)`` would lower it). Every sensor model uses this one matrix.
        """
        yaw, pitch, roll = (math.radians(a) for a in (self.yaw_deg, self.pitch_deg, self.roll_deg))
        cy, sy = math.cos(yaw), math.sin(yaw)
        cp, sp = math.cos(-pitch), math.sin(-pitch)
        cr, sr = math.cos(roll), math.sin(roll)
        rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
        rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        return np.asarray(rz @ ry @ rx, dtype=np.float64)

    def ground_heading_rad(self) -> float:
        """Site-frame heading of the sensor's x axis projected on the ground [rad], CCW from
        east (the bearing of its boresight on the map)."""
        rotation = self.rotation()
        return math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))


class LidarIntrinsics(_Strict):
    """A spinning multi-beam LiDAR."""

    kind: Literal["lidar"] = "lidar"
    beams: Annotated[int, Field(ge=1, le=256)] = 64
    vertical_min_deg: FiniteFloat = -30.0
    vertical_max_deg: FiniteFloat = 11.0
    azimuth_steps: Annotated[int, Field(ge=16, le=8192)] = 2048
    max_range_m: Annotated[float, Field(gt=0.0)] = 200.0
    range_noise_std_m: Annotated[float, Field(ge=0.0)] = 0.02


class CameraIntrinsics(_Strict):
    """A pinhole camera: its resolution and horizontal field of view, or its calibration.

    A simulated (or roughly known) camera is its resolution and field of view: square pixels,
    the principal point at the image's centre, no distortion. A real camera names its
    calibration (``calibration_file``: OpenCV or ROS ``camera_info`` YAML, relative to the site
    file, see :mod:`wz_shared.camera_calibration`); :func:`load_site` reads it into the focal
    lengths, principal point and distortion below, and the resolution and field of view follow
    from it.
    """

    kind: Literal["camera"] = "camera"
    width_px: Annotated[int, Field(ge=16, le=8192)] = 1200
    height_px: Annotated[int, Field(ge=16, le=8192)] = 1200
    horizontal_fov_deg: Annotated[float, Field(gt=1.0, lt=179.0)] = 90.0
    #: The calibration file this camera was read from (relative to the site file), if any.
    calibration_file: str | None = None
    #: Focal lengths [px] and principal point [px, continuous: the top-left pixel's centre is
    #: (0.5, 0.5)] at ``width_px x height_px``; all four or none (None: from the field of view).
    fx_px: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] | None = None
    fy_px: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] | None = None
    cx_px: FiniteFloat | None = None
    cy_px: FiniteFloat | None = None
    #: Lens distortion ``(k1, k2, p1, p2, k3)``, OpenCV's convention; None: an ideal pinhole.
    distortion: tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat] | None = None

    @model_validator(mode="after")
    def _calibrated_all_or_none(self) -> Self:
        given = [v is not None for v in (self.fx_px, self.fy_px, self.cx_px, self.cy_px)]
        if any(given) and not all(given):
            raise ValueError("camera intrinsics: give fx_px, fy_px, cx_px and cy_px together")
        if self.fx_px is not None:
            fov_deg = math.degrees(2.0 * math.atan(self.width_px / (2.0 * self.fx_px)))
            if abs(fov_deg - self.horizontal_fov_deg) > CALIBRATED_FOV_TOLERANCE_DEG:
                raise ValueError(
                    f"camera intrinsics: horizontal_fov_deg {self.horizontal_fov_deg} does not "
                    f"match fx_px {self.fx_px} at {self.width_px} px ({fov_deg:.2f} deg)"
                )
        return self


class RadarIntrinsics(_Strict):
    """An automotive-style radar reporting targets (range, azimuth, radial speed, RCS)."""

    kind: Literal["radar"] = "radar"
    max_range_m: Annotated[float, Field(gt=0.0)] = 200.0
    horizontal_fov_deg: Annotated[float, Field(gt=1.0, le=360.0)] = 60.0
    range_resolution_m: Annotated[float, Field(gt=0.0)] = 1.5
    azimuth_resolution_deg: Annotated[float, Field(gt=0.0)] = 4.0
    range_noise_std_m: Annotated[float, Field(ge=0.0)] = 0.25
    azimuth_noise_std_deg: Annotated[float, Field(ge=0.0)] = 0.5
    speed_noise_std_mps: Annotated[float, Field(ge=0.0)] = 0.1


SensorIntrinsics = Annotated[
    LidarIntrinsics | CameraIntrinsics | RadarIntrinsics, Field(discriminator="kind")
]


class SensorMount(_Strict):
    """One sensor on the mast: its id (used in bus keys), pose, intrinsics and rate."""

    sensor_id: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,62}$")]
    pose: Pose
    intrinsics: SensorIntrinsics
    rate_hz: Annotated[float, Field(gt=0.0, le=100.0)]

    @property
    def kind(self) -> str:
        return self.intrinsics.kind


class PointSensor(_Strict):
    """A point speed sensor upstream of the mast: what smart-work-zone deployments place every
    quarter to half mile ahead of a lane closure (a side-fire radar or a loop station on its
    own trailer). Each interval it gives, per lane, the vehicles that passed its station, their
    mean speed and the share of the time a vehicle stood over it (occupancy). The alert service
    bounds a queue's back with them where the back is beyond the mast's sensors' reach
    (:mod:`wz_alert_service.queues`); in simulation SUMO's induction loops stand in for them.
    """

    sensor_id: Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,62}$")]
    station_m: Annotated[float, Field(ge=0.0)]
    #: Aggregation interval [s] (20-60 s in deployed systems).
    interval_s: Annotated[float, Field(ge=5.0, le=900.0)] = 30.0


# --- alert thresholds -----------------------------------------------------------------------


class EpisodeTiming(_Strict):
    """How long a rule's condition must hold before an alert starts, and how it ends.

    An episode starts once the condition has held for ``hold_s`` without a break, stays open
    while the (looser) exit condition holds, clears after the exit condition has failed for
    ``clear_s``, and the same track cannot open another episode of the same type for
    ``cooldown_s`` after a clear. ``enabled: false`` switches the rule off at this site.
    """

    enabled: bool = True
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 1.0
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 2.0
    cooldown_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 10.0


class SpeedingRule(EpisodeTiming):
    """Speed over the posted limit at the vehicle's station, within the approach.

    Starts at ``excess >= margin_mph``, stays open while ``excess >= margin_mph -
    hysteresis_mph``; critical from ``critical_excess_mph``. Margins are in mph, like the posted
    limits they are added to.
    """

    #: 5 mph: the usual enforcement tolerance; far above the tracker's speed error (< 1 mph).
    margin_mph: Annotated[float, Field(ge=0.0, le=50.0)] = 5.0
    #: 2 mph: a driver hovering at 5 over must drop to 3 over before the episode can end.
    hysteresis_mph: Annotated[float, Field(ge=0.0, le=20.0)] = 2.0
    #: 15 mph over a work-zone limit: the band many states treat as reckless or excessive.
    critical_excess_mph: Annotated[float, Field(gt=0.0, le=60.0)] = 15.0
    #: 1 s: 20 tracker cycles, so one noisy cycle or a new track's speed settling cannot alert.
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 1.0
    #: Decide on the lowest speed the track's covariance allows at this many standard
    #: deviations (as the hard-braking and short-TTC rules do); 0: on the speed as measured.
    certainty_sigmas: Annotated[float, Field(ge=0.0, le=5.0)] = 0.0

    @model_validator(mode="after")
    def _bands(self) -> SpeedingRule:
        if self.critical_excess_mph < self.margin_mph:
            raise ValueError(
                f"speeding: critical_excess_mph {self.critical_excess_mph} must be at least "
                f"margin_mph {self.margin_mph}"
            )
        return self


class AggressiveApproachRule(EpisodeTiming):
    """Too fast, too close to the taper: the deceleration still needed, or not slowing at all.

    Required deceleration to reach the zone limit ``v_zone`` by the taper start, ``D`` metres
    ahead: ``a = (v^2 - v_zone^2) / (2 D)`` [m/s^2]. Starts at ``a >= comfortable_decel_mps2``
    (stays open down to ``comfortable_decel_mps2 - hysteresis_mps2``), critical from
    ``critical_decel_mps2``; or, past the advance-warning point, when the speed is above the
    zone limit by ``speed_margin_mph`` and its trend over ``trend_window_s`` is above
    ``-not_slowing_decel_mps2`` (the driver has not lifted off).
    """

    #: AASHTO's (Green Book) comfortable deceleration, 11.2 ft/s^2, used for sight distance.
    comfortable_decel_mps2: Annotated[float, Field(gt=0.0, le=15.0)] = 3.4
    #: Half a g: harder than most drivers ever brake on purpose.
    critical_decel_mps2: Annotated[float, Field(gt=0.0, le=15.0)] = 4.9
    hysteresis_mps2: Annotated[float, Field(ge=0.0, le=5.0)] = 0.4
    #: Speed over the zone limit that counts (both conditions), as for speeding.
    speed_margin_mph: Annotated[float, Field(ge=0.0, le=50.0)] = 5.0
    #: Drag and rolling resistance alone slow a car at highway speed by 0.3-0.5 m/s^2, so a
    #: trend above -0.3 m/s^2 means the driver has not even lifted off the accelerator.
    not_slowing_decel_mps2: Annotated[float, Field(ge=0.0, le=5.0)] = 0.3
    #: Least-squares speed trend window: 20 samples at 20 Hz average the speed noise down.
    trend_window_s: Annotated[float, Field(gt=0.0, le=10.0)] = 1.0
    #: Where "past the advance warning" begins [m]; None: the advance-warning area's start.
    advance_warning_station_m: Annotated[float, Field(ge=0.0)] | None = None

    @model_validator(mode="after")
    def _bands(self) -> AggressiveApproachRule:
        if self.critical_decel_mps2 < self.comfortable_decel_mps2:
            raise ValueError(
                f"aggressive_approach: critical_decel_mps2 {self.critical_decel_mps2} must be "
                f"at least comfortable_decel_mps2 {self.comfortable_decel_mps2}"
            )
        return self


class HardBrakingRule(EpisodeTiming):
    """Deceleration from the least-squares slope of the track's speed over ``window_s``.

    Starts at ``-dv/dt >= decel_g * g``, stays open down to ``(decel_g - hysteresis_g) * g``;
    critical from ``critical_decel_g * g`` (g = 9.80665 m/s^2).
    """

    #: 0.4 g: the hard-braking trigger of naturalistic-driving and telematics studies.
    decel_g: Annotated[float, Field(gt=0.0, le=1.5)] = 0.4
    #: 0.6 g: emergency braking, near the limit of a car on wet pavement.
    critical_decel_g: Annotated[float, Field(gt=0.0, le=1.5)] = 0.6
    hysteresis_g: Annotated[float, Field(ge=0.0, le=0.5)] = 0.05
    #: 0.8 s at 20 Hz: 16 speeds, so 0.3 m/s speed noise gives a slope error of ~0.3 m/s^2.
    window_s: Annotated[float, Field(gt=0.0, le=5.0)] = 0.8
    #: Fewest speeds in the window for a slope (and they must span half the window).
    min_samples: Annotated[int, Field(ge=3, le=1000)] = 5
    #: The threshold must stand this many of the slope's standard deviations (from the track's
    #: speed variance) clear of zero, or the track's speed is too uncertain to alert on: 2,
    #: a stop at the threshold told from steady driving at 95 %. 0: every slope as it comes.
    certainty_sigmas: Annotated[float, Field(ge=0.0, le=5.0)] = 2.0
    #: 0.3 s: braking is brief; the window already smooths it.
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.3
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 1.0
    cooldown_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 5.0

    @model_validator(mode="after")
    def _bands(self) -> HardBrakingRule:
        if self.critical_decel_g < self.decel_g:
            raise ValueError(
                f"hard_braking: critical_decel_g {self.critical_decel_g} must be at least "
                f"decel_g {self.decel_g}"
            )
        if self.hysteresis_g >= self.decel_g:
            raise ValueError("hard_braking: hysteresis_g must be below decel_g")
        return self


class LateMergeRule(EpisodeTiming):
    """Still in the closed lane within ``distance_m`` of the taper start (or in the taper).

    Starts when the track's lane is the closed one (or its offset is in the closed lane's band)
    at ``speed >= min_speed_mps``; stays open while the offset is within the band widened by
    ``lateral_hysteresis_m`` and ``speed >= min_speed_mps - speed_hysteresis_mps``. Warning
    before the taper, critical inside it.
    """

    #: 150 m: under 6 s to the taper at 55 mph.
    distance_m: Annotated[float, Field(gt=0.0, le=2000.0)] = 150.0
    #: 30 mph: below it, in congestion, the late ("zipper") merge is what DOTs ask for.
    min_speed_mps: Annotated[float, Field(ge=0.0, le=60.0)] = 13.4
    speed_hysteresis_mps: Annotated[float, Field(ge=0.0, le=10.0)] = 1.0
    #: A centre hovering on the lane line must move 0.3 m into the open lane to end it.
    lateral_hysteresis_m: Annotated[float, Field(ge=0.0, le=2.0)] = 0.3
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.5
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 1.0


class ShortTtcRule(EpisodeTiming):
    """Time to collision with the nearest vehicle ahead in the same lane.

    ``TTC = gap / (v_follower - v_leader)``, ``gap = s_leader - s_follower - (L_f + L_l) / 2``.
    Bins after SSAM (whose default conflict threshold is 1.5 s): info at ``TTC <= max_ttc_s``,
    warning at ``<= warning_ttc_s``, critical at ``<= critical_ttc_s``. Stays open while
    ``TTC <= max_ttc_s + hysteresis_s``. The TTC decided on is the longest the two tracks'
    covariances still allow at ``certainty_sigmas``: the gap widened and the closing speed
    lowered by that many of their standard deviations.
    """

    max_ttc_s: Annotated[float, Field(gt=0.0, le=10.0)] = 1.5
    warning_ttc_s: Annotated[float, Field(gt=0.0, le=10.0)] = 1.0
    critical_ttc_s: Annotated[float, Field(gt=0.0, le=10.0)] = 0.5
    hysteresis_s: Annotated[float, Field(ge=0.0, le=5.0)] = 0.3
    #: Two tracks' speeds differ by a few tenths of a m/s from noise alone.
    min_closing_speed_mps: Annotated[float, Field(ge=0.0, le=10.0)] = 0.5
    #: Length used when the tracker has no estimate: a passenger car.
    default_vehicle_length_m: Annotated[float, Field(gt=0.0, le=30.0)] = 4.5
    #: In a queue the gaps are a few metres and the speeds close: a closing speed within the
    #: tracks' own speed noise is no conflict. 2: 95 % sure, as for hard braking; 0: as measured.
    certainty_sigmas: Annotated[float, Field(ge=0.0, le=5.0)] = 2.0
    #: Both tracks followed at least this long [s]. A vehicle really ahead in the lane came
    #: through the covered approach and has been tracked a while; a track born a second ago
    #: just ahead of another is a ghost (a roadside object the camera took for a stopped car)
    #: or a vehicle whose speed is not known yet: a track is confirmed within 1 s and its
    #: speed rests on positions over about as long again. On the congested development
    #: recordings of sites 9400 and 9700 it took the false short TTC from 17 to 9 and from 5
    #: to 2 in 300 s, the one true episode found kept (docs/alert-service.md). 0: any
    #: confirmed track.
    min_track_age_s: Annotated[float, Field(ge=0.0, le=30.0)] = 2.0
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.2
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 1.0
    cooldown_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 5.0

    @model_validator(mode="after")
    def _bins(self) -> ShortTtcRule:
        if not self.critical_ttc_s <= self.warning_ttc_s <= self.max_ttc_s:
            raise ValueError(
                "short_ttc: need critical_ttc_s <= warning_ttc_s <= max_ttc_s, got "
                f"{self.critical_ttc_s}, {self.warning_ttc_s}, {self.max_ttc_s}"
            )
        return self


class QueueRule(EpisodeTiming):
    """Slow or stopped traffic: ``min_vehicles`` slow vehicles within ``span_m`` of station.

    A vehicle is slow below ``slow_speed_mps`` (below ``slow_speed_mps + speed_hysteresis_mps``
    while a queue is open). One site-level episode, reported at the queue's tail (its most
    upstream slow vehicle); critical when the tail is ``critical_backup_m`` or more upstream of
    the taper start.
    """

    #: About 20 mph: stop-and-go on a 55 mph road, not free flow.
    slow_speed_mps: Annotated[float, Field(gt=0.0, le=40.0)] = 8.9
    speed_hysteresis_mps: Annotated[float, Field(ge=0.0, le=10.0)] = 2.0
    #: Three slow vehicles within 100 m: more than one slow truck, fewer than a full jam.
    min_vehicles: Annotated[int, Field(ge=1, le=100)] = 3
    span_m: Annotated[float, Field(gt=0.0, le=2000.0)] = 100.0
    #: A queued lane is stopped while its queued vehicles' mean speed is below this (HCM's
    #: queued vehicle: under 5 mph); it is slow again above this plus ``speed_hysteresis_mps``.
    stopped_speed_mps: Annotated[float, Field(ge=0.0, le=20.0)] = 2.2
    #: A tail this far upstream of the taper meets drivers still at approach speed.
    critical_backup_m: Annotated[float, Field(ge=0.0, le=10000.0)] = 300.0
    #: A queue is a state of traffic: 3 s filters a platoon braking briefly.
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 3.0
    #: Stop-and-go waves lift a queue's speeds above the threshold for seconds at a time.
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 10.0
    cooldown_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 30.0


class QueueApproachRule(EpisodeTiming):
    """Approaching the back of the lane's queue too fast: the deceleration needed to stop
    behind it.

    For a track upstream of its lane's queue (:mod:`wz_alert_service.queues`) and not slow
    itself, with the queue's back ``s_b``, the track at ``s`` and speed ``v``, the queue's mean
    speed ``u``: the room to stop ``D = s_b - s - stop_spacing_m`` and the deceleration needed
    to come down to ``u`` within it, ``a = (v^2 - u^2) / (2 D)``. Starts at ``a >=
    comfortable_decel_mps2`` (or ``D <= 0`` while still closing), stays open down to
    ``comfortable_decel_mps2 - hysteresis_mps2``; critical from ``critical_decel_mps2``. The
    lead time is ``D / (v - u)``: how long until the track reaches the back at its speed.
    """

    #: AASHTO's (Green Book) comfortable deceleration, 11.2 ft/s^2, as for the taper.
    comfortable_decel_mps2: Annotated[float, Field(gt=0.0, le=15.0)] = 3.4
    #: Half a g: harder than most drivers ever brake on purpose.
    critical_decel_mps2: Annotated[float, Field(gt=0.0, le=15.0)] = 4.9
    hysteresis_mps2: Annotated[float, Field(ge=0.0, le=5.0)] = 0.4
    #: Centre to centre of two stopped cars: a car's length and the 2-3 m drivers leave.
    stop_spacing_m: Annotated[float, Field(ge=0.0, le=50.0)] = 7.5
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.5
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 1.0

    @model_validator(mode="after")
    def _bands(self) -> QueueApproachRule:
        if self.critical_decel_mps2 < self.comfortable_decel_mps2:
            raise ValueError(
                f"queue_approach: critical_decel_mps2 {self.critical_decel_mps2} must be "
                f"at least comfortable_decel_mps2 {self.comfortable_decel_mps2}"
            )
        return self


class IntrusionRule(EpisodeTiming):
    """A vehicle in the closed lane inside the buffer or activity area.

    Starts when the track's offset is in the closed lane's band (or its lane is the closed one)
    between the buffer's start and the activity area's end at ``speed >= min_speed_mps``; stays
    open while the offset is in the band widened by ``lateral_hysteresis_m``. Warning in the
    buffer, critical in the activity area.
    """

    #: About 10 mph: work vehicles creep in the closed lane; errant traffic does not.
    min_speed_mps: Annotated[float, Field(ge=0.0, le=60.0)] = 4.5
    lateral_hysteresis_m: Annotated[float, Field(ge=0.0, le=2.0)] = 0.3
    hold_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.3
    clear_s: Annotated[float, Field(ge=0.0, le=600.0)] = 1.0


class DeviceRules(_Strict):
    """Roadside devices driven by the alerts: a flashing beacon and a message sign."""

    #: Station of the dynamic message sign [m]; None: the advance-warning area's start.
    sign_station_m: Annotated[float, Field(ge=0.0)] | None = None
    #: A new message for the same cause (the queue's distance, slow against stopped) replaces
    #: the sign's only once it has held this long: a message that flickers is not read. A new
    #: cause, a queue turning to stopped and a blank (the episode's own clear time) are at once.
    message_hold_s: Annotated[float, Field(ge=0.0, le=120.0)] = 5.0


class AlertRules(_Strict):
    """Thresholds of the alert service, with units; every rule works in the road frame.

    The approach is the station window ``[activity end - approach_length_m, activity end)``:
    speeding, aggressive approach, hard braking, late merge, short TTC, queue and queue approach look only
    there. Each rule has its own :class:`EpisodeTiming` (hold, clear, cool-down).
    """

    #: MUTCD advance-warning sign spacing on a freeway adds up to ~1.5 km before the taper.
    approach_length_m: Annotated[float, Field(gt=0.0, le=20000.0)] = 1500.0
    speeding: SpeedingRule = Field(default_factory=SpeedingRule)
    aggressive_approach: AggressiveApproachRule = Field(default_factory=AggressiveApproachRule)
    hard_braking: HardBrakingRule = Field(default_factory=HardBrakingRule)
    late_merge: LateMergeRule = Field(default_factory=LateMergeRule)
    short_ttc: ShortTtcRule = Field(default_factory=ShortTtcRule)
    queue: QueueRule = Field(default_factory=QueueRule)
    intrusion: IntrusionRule = Field(default_factory=IntrusionRule)
    queue_approach: QueueApproachRule = Field(default_factory=QueueApproachRule)
    devices: DeviceRules = Field(default_factory=DeviceRules)


class Schedule(_Strict):
    """When the work zone is in place (the contract's or the traffic control plan's dates):
    the WZDx WorkZoneFeed's ``start_date`` and ``end_date``, and whether each is verified
    (``is_start_date_verified``, ``is_end_date_verified``: confirmed by someone at the site).

    Both are ISO 8601 date-times with a UTC offset (``2026-05-04T07:00:00-05:00`` or
    ``...Z``): a time without one names no instant.
    """

    start: datetime
    end: datetime
    start_verified: bool = False
    end_verified: bool = False

    @field_validator("start", "end")
    @classmethod
    def _has_offset(cls, value: datetime) -> datetime:
        if value.tzinfo is None or value.utcoffset() is None:
            raise ValueError(
                f"{value.isoformat()} has no UTC offset: write the date-time with one, e.g. "
                f"{value.strftime('%Y-%m-%dT%H:%M:%S')}-05:00, or Z for UTC"
            )
        return value

    @model_validator(mode="after")
    def _ordered(self) -> Schedule:
        if self.end <= self.start:
            raise ValueError(
                f"schedule: end {self.end.isoformat()} must be after start {self.start.isoformat()}"
            )
        return self


#: The direction of traffic as the road is signed (WZDx ``Direction``), not a compass heading:
#: a northbound route stays northbound through its curves.
RoadDirection = Literal[
    "northbound",
    "eastbound",
    "southbound",
    "westbound",
    "inner-loop",
    "outer-loop",
    "undefined",
    "unknown",
]


class Site(_Strict):
    """One deployment: geometry, work zone, limits and sensors."""

    schema_version: Literal[1] = 1
    site_id: SiteId
    name: str
    #: Public names of the road (``US-75``, ``I-80``) for feeds such as WZDx; empty: ``name``.
    road_names: list[Annotated[str, Field(min_length=1, max_length=100)]] = Field(
        default_factory=list
    )
    road_direction: RoadDirection = "unknown"
    #: When the work zone is in place (the WZDx WorkZoneFeed's dates); None: not known (the
    #: gateway then gives the time it began serving and four weeks on, neither verified).
    schedule: Schedule | None = None
    origin: GeoOrigin
    centerline_xy_m: Annotated[list[tuple[FiniteFloat, FiniteFloat]], Field(min_length=2)]
    lanes: Annotated[list[Lane], Field(min_length=1)]
    closed_lane_index: Annotated[int, Field(ge=0)]
    work_zone: Annotated[list[WorkZoneArea], Field(min_length=1)]
    speed_limits: Annotated[list[SpeedLimit], Field(min_length=1)]
    sensors: list[SensorMount] = Field(default_factory=list)
    #: Point speed sensors upstream (:class:`PointSensor`); none: the mast's sensors alone.
    point_sensors: list[PointSensor] = Field(default_factory=list)
    #: Alert thresholds; a site file without an ``alerts:`` section gets the defaults.
    alerts: AlertRules = Field(default_factory=AlertRules)

    @field_validator("centerline_xy_m")
    @classmethod
    def _distinct_vertices(cls, points: list[tuple[float, float]]) -> list[tuple[float, float]]:
        for i in range(1, len(points)):
            (x0, y0), (x1, y1) = points[i - 1], points[i]
            if math.hypot(x1 - x0, y1 - y0) < 1e-3:
                raise ValueError(f"centerline vertices {i - 1} and {i} coincide")
        RoadFrame(points)  # raises ValueError naming a vertex where the line turns too sharply
        return points

    @model_validator(mode="after")
    def _consistent(self) -> Site:
        indices = sorted(lane.index for lane in self.lanes)
        if indices != list(range(len(self.lanes))):
            raise ValueError(f"lane indices must be 0..{len(self.lanes) - 1}, got {indices}")
        offsets = [lane.center_offset_m for lane in sorted(self.lanes, key=lambda lane: lane.index)]
        if any(b <= a for a, b in itertools.pairwise(offsets)):
            raise ValueError("lane center offsets must increase with lane index (right to left)")
        if self.closed_lane_index >= len(self.lanes):
            raise ValueError(
                f"closed_lane_index {self.closed_lane_index} is not a lane of this site"
            )
        if len(self.lanes) < 2:
            raise ValueError("a lane-drop work zone needs at least two lanes")
        ids = [sensor.sensor_id for sensor in self.sensors]
        if len(ids) != len(set(ids)):
            raise ValueError(f"sensor ids must be unique, got {ids}")
        length = self.road_length_m
        points = [point.sensor_id for point in self.point_sensors]
        if len(set(points)) != len(points) or set(points) & set(ids):
            raise ValueError(f"point sensor ids must be unique among all sensors, got {points}")
        for point in self.point_sensors:
            if point.station_m > length:
                raise ValueError(
                    f"point sensor {point.sensor_id} stands at {point.station_m} m, beyond the "
                    f"centerline's length {length:.1f} m"
                )
        for area in self.work_zone:
            if area.end_station_m > length + 1e-6:
                raise ValueError(
                    f"work-zone area {area.kind} ends at {area.end_station_m} m, beyond the "
                    f"centerline's length {length:.1f} m"
                )
        return self

    # --- derived quantities -------------------------------------------------------------

    @property
    def road_length_m(self) -> float:
        """Length of the centerline polyline [m]."""
        pts = self.centerline_xy_m
        return sum(math.hypot(x1 - x0, y1 - y0) for (x0, y0), (x1, y1) in itertools.pairwise(pts))

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False) -> Self:
        """Copy, dropping the cached frames: ``update`` may change the centerline or origin."""
        copied = super().model_copy(update=update, deep=deep)
        for name in _CACHED_FRAMES:
            copied.__dict__.pop(name, None)
        return copied

    @cached_property
    def road_frame(self) -> RoadFrame:
        """Station/offset frame of the centerline, built on first use and kept."""
        return RoadFrame(self.centerline_xy_m)

    @cached_property
    def geo_frame(self) -> GeoFrame:
        """WGS84 <-> site frame (local ENU at ``origin``), built on first use and kept."""
        return GeoFrame(self.origin.latitude_deg, self.origin.longitude_deg, self.origin.altitude_m)

    def lane_index_at(self, offset_m: npt.ArrayLike) -> npt.NDArray[np.intp]:
        """Lane at each lateral offset.

        Parameters
        ----------
        offset_m : array_like, shape (...)
            Offset d [m] from the centerline, positive to the left.

        Returns
        -------
        ndarray of int, shape (...)
            Index of the lane whose ``[center - width / 2, center + width / 2)`` holds d, or -1
            outside every lane (shoulders, off the road). Where two lanes overlap the lower
            index wins.
        """
        offset = np.asarray(offset_m, dtype=np.float64)
        index = np.full(offset.shape, -1, dtype=np.intp)
        for lane in sorted(self.lanes, key=lambda lane: lane.index, reverse=True):
            half = 0.5 * lane.width_m
            inside = (offset >= lane.center_offset_m - half) & (
                offset < lane.center_offset_m + half
            )
            index[inside] = lane.index
        return index

    def area_at(self, station_m: float) -> AreaKind | None:
        """Work-zone area holding a station [m] (``[start, end)``), or None outside the zone."""
        for area in self.work_zone:
            if area.start_station_m <= station_m < area.end_station_m:
                return area.kind
        return None

    def lane(self, index: int) -> Lane:
        for lane in self.lanes:
            if lane.index == index:
                return lane
        raise KeyError(f"no lane {index} at site {self.site_id}")

    def area(self, kind: AreaKind) -> WorkZoneArea:
        for area in self.work_zone:
            if area.kind == kind:
                return area
        raise KeyError(f"site {self.site_id} has no {kind.value} area")

    def speed_limit_mps_at(self, station_m: float) -> float:
        """Posted speed limit [m/s] at a station; the last limit extends past its end."""
        for limit in self.speed_limits:
            if limit.start_station_m <= station_m < limit.end_station_m:
                return limit.speed_limit_mps
        last = max(self.speed_limits, key=lambda limit: limit.end_station_m)
        first = min(self.speed_limits, key=lambda limit: limit.start_station_m)
        return (last if station_m >= last.end_station_m else first).speed_limit_mps

    def sensor(self, sensor_id: str) -> SensorMount:
        for sensor in self.sensors:
            if sensor.sensor_id == sensor_id:
                return sensor
        raise KeyError(f"no sensor {sensor_id!r} at site {self.site_id}")


class SiteFileError(ValueError):
    """A site file could not be read or is not a valid site description."""


def load_site(path: str | Path) -> Site:
    """Read and validate a site YAML file.

    Raises
    ------
    SiteFileError
        With the file name and every validation problem, worded for a field engineer.
    """
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SiteFileError(f"cannot read site file {path}: {exc}") from exc
    except yaml.YAMLError as exc:
        raise SiteFileError(f"site file {path} is not valid YAML: {exc}") from exc
    if not isinstance(raw, dict):
        raise SiteFileError(f"site file {path} must hold a mapping at the top level")
    try:
        _read_camera_calibrations(raw, path.parent)
    except CalibrationError as exc:
        raise SiteFileError(f"site file {path}: {exc}") from exc
    try:
        return Site.model_validate(raw)
    except ValueError as exc:
        raise SiteFileError(f"site file {path} is not a valid site description:\n{exc}") from exc


def _read_camera_calibrations(raw: dict[str, Any], folder: Path) -> None:
    """Fill in each camera's ``calibration_file`` (relative to ``folder``) in the raw site.

    The calibration gives the resolution, focal lengths, principal point and distortion; a
    resolution also written in the site file must agree with it (a field of view is checked
    by :class:`CameraIntrinsics`).
    """
    sensors = raw.get("sensors")
    for sensor in sensors if isinstance(sensors, list) else []:
        intrinsics = sensor.get("intrinsics") if isinstance(sensor, dict) else None
        if not isinstance(intrinsics, dict) or not intrinsics.get("calibration_file"):
            continue
        name = sensor.get("sensor_id", "?")
        calibration = read_calibration(folder / str(intrinsics["calibration_file"]))
        for key, value in (
            ("width_px", calibration.width_px),
            ("height_px", calibration.height_px),
        ):
            if key in intrinsics and intrinsics[key] != value:
                raise CalibrationError(
                    f"camera {name}: {key} {intrinsics[key]} but its calibration says {value}"
                )
        # A field of view written beside the calibration is checked against fx by the model.
        intrinsics.setdefault("horizontal_fov_deg", calibration.horizontal_fov_deg)
        intrinsics.update(
            width_px=calibration.width_px,
            height_px=calibration.height_px,
            fx_px=calibration.fx_px,
            fy_px=calibration.fy_px,
            cx_px=calibration.cx_px,
            cy_px=calibration.cy_px,
            distortion=list(calibration.distortion),
        )


def site_document(site: Site) -> dict[str, Any]:
    """The site as a site file's mapping (JSON types): an uncalibrated camera without the
    calibration's empty fields and a site without a schedule without ``schedule``, as site
    files are written."""
    data = site.model_dump(mode="json")
    if data.get("schedule", 0) is None:
        del data["schedule"]
    for sensor in data.get("sensors", []):
        intrinsics = sensor.get("intrinsics", {})
        for key in CALIBRATION_FIELDS:
            if intrinsics.get(key, 0) is None:
                del intrinsics[key]
    return data


DEFAULT_SITE_PATH = Path(__file__).resolve().parents[3] / "deploy" / "sites" / "us75-lincoln.yaml"
