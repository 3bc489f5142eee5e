"""Every message on the bus, as pydantic v2 models.

Each message carries ``schema_version``, ``site``, ``source_id`` (the sensor id for raw data and
detections, the service name otherwise) and ``stamp``: the capture time in seconds (simulation
time in simulation, sensor time in the field). Units are in the field names.

Frames (LiDAR points, camera JPEG bytes) travel as a binary envelope: the metadata model below as
JSON, then the raw bytes (see :mod:`wz_shared.codec`). Everything else travels as JSON.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated, Literal

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from wz_shared.motion import ProcessNoise

SCHEMA_VERSION: Literal[1] = 1

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
PosFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
Identifier = Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.:-]{0,127}$")]
#: The largest variance a position covariance may hold [m^2]: a standard deviation of 10 km.
#: A site spans a few km and its sensors reach a few hundred metres, so a detection or track
#: that uncertain places the vehicle nowhere on the site: a producer's fault (an information
#: matrix inverted near zero, a filter that diverged), not a measurement. The bound also keeps
#: the trackers' products (``H P H^T + R``, Mahalanobis distances, smoothing gains) far from
#: overflowing.
MAX_VARIANCE_M2 = 1e8
#: The largest variance a velocity may hold [m^2/s^2]: a standard deviation of 1 km/s, thirty
#: times any road speed (tracks start at 15 m/s).
MAX_VELOCITY_VARIANCE_M2PS2 = 1e6
#: How far the two off-diagonal entries may differ, relative to the larger (or 1 m^2) [-].
SYMMETRY_TOLERANCE = 1e-9
#: A track covariance may be singular (zero: tracks from ground truth) but not indefinite:
#: its correlation matrix's smallest eigenvalue must be above minus this [-].
SEMIDEFINITE_TOLERANCE = 1e-9


def _check_covariance(
    values: list[float], max_variances: tuple[float, ...], *, definite: bool
) -> list[float]:
    """``values`` (an n x n matrix, row-major) unchanged if a covariance, else ValueError.

    Checked, in this order: finite entries; variances (the diagonal) positive (``definite``)
    or non-negative, and at most ``max_variances``; symmetric within
    :data:`SYMMETRY_TOLERANCE`; then positive definite (Cholesky) or semi-definite
    (eigenvalues), tested on the correlation matrix ``C = D^-1/2 P D^-1/2``, whose entries
    are those of ``P`` over ``sqrt(P_ii) sqrt(P_jj)``: no product of two variances is formed,
    so ``1e308`` cannot overflow into a determinant that passes (``inf > 0``).
    """
    n = len(max_variances)
    matrix = np.asarray(values, dtype=np.float64).reshape(n, n)
    if not np.all(np.isfinite(matrix)):
        raise ValueError(f"covariance {values}: every entry must be finite")
    diagonal = np.diag(matrix)
    low_ok = diagonal > 0.0 if definite else diagonal >= 0.0
    if not np.all(low_ok & (diagonal <= np.asarray(max_variances))):
        bounds = ", ".join(f"{b:g}" for b in max_variances)
        raise ValueError(
            f"covariance {values}: the variances (the diagonal) must be "
            f"{'positive' if definite else 'non-negative'} and at most {bounds}"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        asymmetry = np.abs(matrix - matrix.T)
        scale = np.maximum(1.0, np.maximum(np.abs(matrix), np.abs(matrix.T)))
    if not np.all(asymmetry <= SYMMETRY_TOLERANCE * scale):
        raise ValueError(f"covariance {values}: not symmetric")
    std = np.sqrt(diagonal)
    shown = std > 0.0
    if np.any(matrix[~shown, :]) or np.any(matrix[:, ~shown]):
        raise ValueError(
            f"covariance {values}: not positive semi-definite (a zero variance with a "
            "non-zero covariance)"
        )
    kept = np.flatnonzero(shown)
    sub = matrix[np.ix_(kept, kept)]
    sub = 0.5 * sub + 0.5 * sub.T  # no overflow
    with np.errstate(over="ignore", invalid="ignore"):
        upper = np.triu(sub / std[kept][:, None] / std[kept][None, :], 1)
    # A correlation matrix's diagonal is 1 exactly; sqrt(P_ii)^2 is not always P_ii, and a
    # diagonal a rounding off 1 would move the Cholesky pivot of a nearly singular P.
    correlation = upper + upper.T + np.eye(kept.size)
    if not np.all(np.isfinite(correlation)):
        raise ValueError(
            f"covariance {values}: not positive definite (|P_ij| above sqrt(P_ii P_jj))"
        )
    if definite:
        try:
            np.linalg.cholesky(correlation)
        except np.linalg.LinAlgError:
            raise ValueError(
                f"covariance {values}: not positive definite (no Cholesky factor; "
                "|sxy| must be below sqrt(sxx*syy))"
            ) from None
    elif kept.size and np.linalg.eigvalsh(correlation)[0] < -SEMIDEFINITE_TOLERANCE:
        raise ValueError(f"covariance {values}: not positive semi-definite")
    return values


def _detection_covariance(values: list[float]) -> list[float]:
    """The 2x2 case of :func:`_check_covariance` in scalars (detections are many: ~2 us, not
    ~90): the Cholesky factor of the correlation matrix [[1, r], [r, 1]] exists when the
    pivot ``1 - r^2`` is positive, ``r = sxy / (sqrt(sxx) sqrt(syy))``."""
    sxx, sxy, syx, syy = values
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"covariance {values}: every entry must be finite")
    if not (0.0 < sxx <= MAX_VARIANCE_M2 and 0.0 < syy <= MAX_VARIANCE_M2):
        raise ValueError(
            f"covariance {values}: the variances (the diagonal) must be positive and at most "
            f"{MAX_VARIANCE_M2:g}, {MAX_VARIANCE_M2:g}"
        )
    if not abs(sxy - syx) <= SYMMETRY_TOLERANCE * max(1.0, abs(sxy), abs(syx)):
        raise ValueError(f"covariance {values}: not symmetric")
    r = (0.5 * sxy + 0.5 * syx) / math.sqrt(sxx) / math.sqrt(syy)
    if not 1.0 - r * r > 0.0:
        raise ValueError(
            f"covariance {values}: not positive definite (no Cholesky factor; "
            "|sxy| must be below sqrt(sxx*syy))"
        )
    return values


def _track_covariance(values: list[float]) -> list[float]:
    """A track's 4x4 covariance (x, y, vx, vy), checked in scalars (a batch carries up to a few
    hundred: ~6 us each, where :func:`_check_covariance`'s eigenvalues take ~70): finite;
    variances non-negative and at most :data:`MAX_VARIANCE_M2` (position) and
    :data:`MAX_VELOCITY_VARIANCE_M2PS2` (velocity); symmetric; every 2x2 principal minor
    non-negative (``|P_ij| <= sqrt(P_ii) sqrt(P_jj)``, with no product of two variances
    formed, so nothing overflows). Those bound every correlation by one. The whole matrix's
    semi-definiteness (eigenvalues) is not checked on the wire: a consumer needs entries it can
    compute with, and the tracker's own filter keeps its matrices semi-definite."""
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"covariance {values}: every entry must be finite")
    position, velocity = MAX_VARIANCE_M2, MAX_VELOCITY_VARIANCE_M2PS2
    bounds = (position, position, velocity, velocity)
    std = []
    for i in range(4):
        variance = values[5 * i]
        if not 0.0 <= variance <= bounds[i]:
            raise ValueError(
                f"covariance {values}: the variances (the diagonal) must be non-negative and "
                f"at most {', '.join(f'{b:g}' for b in bounds)}"
            )
        std.append(math.sqrt(variance))
    for i in range(4):
        for j in range(i + 1, 4):
            a, b = values[4 * i + j], values[4 * j + i]
            if not abs(a - b) <= SYMMETRY_TOLERANCE * max(1.0, abs(a), abs(b)):
                raise ValueError(f"covariance {values}: not symmetric")
            if abs(a) > std[i] * std[j] * (1.0 + SEMIDEFINITE_TOLERANCE):
                raise ValueError(
                    f"covariance {values}: not positive semi-definite (|P_ij| above "
                    "sqrt(P_ii P_jj))"
                )
    return values


#: A 2x2 covariance [[sxx, sxy], [syx, syy]] in the site frame [m^2], flattened row-major:
#: finite, symmetric, positive definite, variances at most :data:`MAX_VARIANCE_M2`.
Covariance2 = Annotated[
    list[FiniteFloat],
    Field(min_length=4, max_length=4),
    AfterValidator(_detection_covariance),
]
#: A track's 4x4 covariance of (x, y, vx, vy) [m^2, m^2/s, m^2/s^2], flattened row-major:
#: finite, symmetric, positive semi-definite (all zero: not known, e.g. from ground truth),
#: variances at most :data:`MAX_VARIANCE_M2` and :data:`MAX_VELOCITY_VARIANCE_M2PS2`.
Covariance4 = Annotated[
    list[FiniteFloat],
    Field(min_length=16, max_length=16),
    AfterValidator(_track_covariance),
]


class Message(BaseModel):
    """Fields common to every message on the bus.

    Each concrete message adds a ``kind`` tag (a one-value literal) so a payload names its type.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    schema_version: Literal[1] = SCHEMA_VERSION
    site: Identifier
    source_id: Identifier
    stamp: NonNegFloat


# --- raw sensor data ------------------------------------------------------------------------


class LidarFrameMeta(Message):
    """Metadata of a LiDAR frame; the points follow as float32 rows (x, y, z, intensity).

    Points are in the sensor frame [m] (x forward, y left, z up). An organized frame has
    ``rows * columns == num_points`` (beams x azimuth steps, no-return cells as NaN); an
    unorganized one has ``rows == 1``. ``stamp`` is the start of the sweep; column ``j`` fired at
    ``stamp + sweep_duration_s * j / columns``.
    """

    kind: Literal["lidar_frame"] = "lidar_frame"
    frame_index: Annotated[int, Field(ge=0)]
    rows: Annotated[int, Field(ge=1, le=4096)]
    columns: Annotated[int, Field(ge=0, le=1 << 20)]
    num_points: Annotated[int, Field(ge=0, le=1 << 22)]
    sweep_duration_s: NonNegFloat = 0.0
    organized: bool = True
    #: Optional per-point vehicle ids travel separately (truth labels), never here.
    fields: tuple[Literal["x"], Literal["y"], Literal["z"], Literal["intensity"]] = (
        "x",
        "y",
        "z",
        "intensity",
    )


class CameraFrameMeta(Message):
    """Metadata of a camera frame; JPEG bytes follow."""

    kind: Literal["camera_frame"] = "camera_frame"
    frame_index: Annotated[int, Field(ge=0)]
    width_px: Annotated[int, Field(ge=1, le=16384)]
    height_px: Annotated[int, Field(ge=1, le=16384)]
    encoding: Literal["jpeg"] = "jpeg"
    #: Drawn by the simulator, not taken by a camera (the detector picks its model by it).
    rendered: bool = False


class RadarTarget(BaseModel):
    """One radar target in the sensor frame."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    range_m: NonNegFloat
    azimuth_rad: FiniteFloat
    radial_speed_mps: FiniteFloat  # positive when moving away from the sensor
    rcs_dbsm: FiniteFloat


class RadarScan(Message):
    kind: Literal["radar_scan"] = "radar_scan"
    scan_index: Annotated[int, Field(ge=0)]
    targets: list[RadarTarget]


# --- ground truth (simulation only) ---------------------------------------------------------


class VehicleClass(StrEnum):
    CAR = "car"
    TRUCK = "truck"
    MOTORCYCLE = "motorcycle"
    BUS = "bus"
    UNKNOWN = "unknown"


class DriverProfile(StrEnum):
    """Driving style given to a simulated vehicle; aggressive drivers are labelled for scoring."""

    NORMAL = "normal"
    AGGRESSIVE = "aggressive"


class VehicleTruth(BaseModel):
    """True state of one vehicle: its geometric centre in the site and road frames."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    vehicle_id: Identifier
    vehicle_class: VehicleClass
    x_m: FiniteFloat
    y_m: FiniteFloat
    z_m: FiniteFloat = 0.0
    heading_rad: FiniteFloat  # counter-clockwise from the site x axis (east)
    speed_mps: NonNegFloat
    accel_mps2: FiniteFloat
    length_m: PosFloat
    width_m: PosFloat
    height_m: PosFloat
    lane_index: Annotated[int, Field(ge=-1)]  # -1 when between lanes / on a junction
    station_m: FiniteFloat
    offset_m: FiniteFloat
    driver_profile: DriverProfile


class GroundTruth(Message):
    kind: Literal["ground_truth"] = "ground_truth"
    step_index: Annotated[int, Field(ge=0)]
    vehicles: list[VehicleTruth]


# --- perception -----------------------------------------------------------------------------


class Detection(BaseModel):
    """One detected object in the site frame, with its measurement covariance."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    x_m: FiniteFloat
    y_m: FiniteFloat
    covariance_m2: Covariance2
    object_class: VehicleClass = VehicleClass.UNKNOWN
    score: Annotated[float, Field(ge=0.0, le=1.0)] = 1.0
    length_m: NonNegFloat | None = None
    width_m: NonNegFloat | None = None
    height_m: NonNegFloat | None = None
    heading_rad: FiniteFloat | None = None
    # Radar (or image-plane tracking) may give speed; None where the sensor cannot.
    speed_mps: FiniteFloat | None = None
    local_track_id: Annotated[int, Field(ge=0)] | None = None
    # When the object was captured, after the batch's stamp [s]: a spinning LiDAR's columns
    # fire across its sweep (50 ms at 20 Hz), so a vehicle's points are up to a sweep later
    # than the frame's stamp (1.5 m at 30 m/s). None: at the stamp.
    time_offset_s: Annotated[float, Field(ge=-1.0, le=1.0, allow_inf_nan=False)] | None = None
    # The box's length was completed from its end away from the sensor, towards it: the near
    # end was not seen (a LiDAR's field of view cuts a vehicle going into or out of the blind
    # cone under its mast). A tracker that knows the vehicle's length moves the centre towards
    # the sensor, not away. False: completed away from the sensor, or not at all.
    completed_from_far_end: bool = False


class DetectionBatch(Message):
    """All detections of one sensor frame (possibly none)."""

    kind: Literal["detection_batch"] = "detection_batch"
    frame_index: Annotated[int, Field(ge=0)]
    detections: list[Detection]
    latency_s: NonNegFloat = 0.0  # processing time from frame receipt to publication


# --- tracking -------------------------------------------------------------------------------


class TrackStatus(StrEnum):
    """Life cycle of a fused track."""

    TENTATIVE = "tentative"  # started, not yet confirmed by enough updates
    CONFIRMED = "confirmed"  # updated recently
    COASTING = "coasting"  # confirmed, but no measurement for a while: predicted only


class Track(BaseModel):
    """One fused track: state in the site frame and its road-frame projection."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    track_id: Annotated[int, Field(ge=0)]
    x_m: FiniteFloat
    y_m: FiniteFloat
    vx_mps: FiniteFloat
    vy_mps: FiniteFloat
    covariance: Covariance4
    station_m: FiniteFloat
    offset_m: FiniteFloat
    speed_mps: NonNegFloat
    heading_rad: FiniteFloat
    lane_index: Annotated[int, Field(ge=-1)]
    object_class: VehicleClass = VehicleClass.UNKNOWN
    age_s: NonNegFloat
    hits: Annotated[int, Field(ge=0)]
    confirmed: bool
    sources: list[Identifier]  # sensors that updated this track in the cycle
    status: TrackStatus = TrackStatus.CONFIRMED
    length_m: PosFloat | None = None  # estimated from the measurements' sizes
    width_m: PosFloat | None = None
    last_update_s: FiniteFloat | None = None  # stamp of the newest measurement used


def _positive_process_noise(noise: ProcessNoise) -> ProcessNoise:
    stds = (noise.sigma_along_mps2, noise.sigma_across_mps2)
    if not all(math.isfinite(v) and v > 0.0 for v in stds) or not (
        math.isfinite(noise.heading_min_speed_mps) and noise.heading_min_speed_mps >= 0.0
    ):
        raise ValueError("process noise: stds must be finite and > 0, the speed finite and >= 0")
    return noise


class TrackBatch(Message):
    """The fused tracks of one tracker cycle, and the process noise the tracker predicted them
    with (:class:`~wz_shared.motion.ProcessNoise`; absent in older recordings: the model's
    defaults, the tracker's), which whoever smooths them uses."""

    kind: Literal["track_batch"] = "track_batch"
    cycle_index: Annotated[int, Field(ge=0)]
    tracks: list[Track]
    process_noise: Annotated[ProcessNoise, AfterValidator(_positive_process_noise)] = ProcessNoise()


# --- alerts ---------------------------------------------------------------------------------


class AlertType(StrEnum):
    SPEEDING = "speeding"
    AGGRESSIVE_APPROACH = "aggressive_approach"
    HARD_BRAKING = "hard_braking"
    LATE_MERGE = "late_merge"
    SHORT_TTC = "short_ttc"
    INTRUSION = "intrusion"
    QUEUE = "queue"
    #: Approaching the back of a lane's queue too fast to stop behind it comfortably.
    QUEUE_APPROACH = "queue_approach"


class AlertSeverity(StrEnum):
    INFO = "info"
    WARNING = "warning"
    CRITICAL = "critical"


#: Where an alert stands in its episode: the condition started (after its hold time), rose in
#: severity, or has been false for its clear time (or the track was lost).
AlertPhase = Literal["start", "update", "clear"]


class Alert(Message):
    """One event of an alert episode: its start, an update (severity rose) or its clear.

    An episode is one stretch of time over which one rule's condition held for one track (or,
    for a queue, for the site: ``track_id`` None). Its messages share ``episode_id``; each has
    its own ``alert_id``. ``stamp`` is the capture time of the track batch that decided this
    event; ``onset_stamp`` the capture time at which the condition first held (a start comes
    the rule's hold time after it). Published reliably, never dropped.

    ``measured_value`` and ``threshold_value`` are in ``value_unit`` (m/s, m/s^2, s, m or
    vehicles); ``evidence`` holds the rule's other numbers, each key ending in its unit
    (``speed_limit_mps``, ``gap_m``...); ``track`` is a snapshot of the track at ``stamp``.
    A clear carries the episode's peak severity and its last measurements.
    """

    kind: Literal["alert"] = "alert"
    alert_id: Identifier
    alert_type: AlertType
    severity: AlertSeverity
    track_id: Annotated[int, Field(ge=0)] | None = None
    station_m: FiniteFloat
    offset_m: FiniteFloat
    speed_mps: NonNegFloat | None = None
    measured_value: FiniteFloat  # in the unit of the rule (m/s, m/s^2, s, m, vehicles)
    threshold_value: FiniteFloat
    description: Annotated[str, Field(max_length=500)]
    phase: AlertPhase = "start"
    episode_id: Identifier | None = None
    onset_stamp: NonNegFloat | None = None
    value_unit: Annotated[str, Field(max_length=16)] = ""
    evidence: dict[Annotated[str, Field(max_length=64)], FiniteFloat] = Field(default_factory=dict)
    track: Track | None = None


class RoadsideDeviceState(Message):
    """What the flashing beacon and the dynamic message sign upstream of the taper show.

    Published by the alert service on ``wz/<site>/devices/state`` whenever it changes (the
    gateway puts it in its WZDx device feed). ``stamp`` is the capture time of the track batch
    that decided it. The beacon flashes while an alert that concerns approaching drivers is
    open upstream of the end of the activity area; ``sign_text`` is the sign's one message
    (upper case, empty when blank) and ``cause`` the alert type behind it.
    """

    kind: Literal["roadside_devices"] = "roadside_devices"
    beacon_on: bool
    sign_text: Annotated[str, Field(max_length=64)]
    cause: AlertType | None = None
    #: The queue's tail [m] when the sign shows a queue.
    queue_tail_station_m: FiniteFloat | None = None

    def shows_same_as(self, other: RoadsideDeviceState | None) -> bool:
        """Whether ``other`` shows the same to drivers (every field but the stamp)."""
        return other is not None and self.model_dump(exclude={"stamp"}) == other.model_dump(
            exclude={"stamp"}
        )


class QueueCondition(StrEnum):
    """A lane's traffic as the queue estimate sees it (thresholds: the site's ``alerts.queue``)."""

    FREE = "free"
    SLOW = "slow"
    STOPPED = "stopped"


class LaneQueue(BaseModel):
    """One lane's queue now (:class:`QueueState`).

    A lane is queued while ``min_vehicles`` of its slow vehicles stand within ``span_m`` of
    station (the site's queue rule, per lane); stopped while their mean speed is below
    ``stopped_speed_mps``. Stations are along the road [m]; the back is the queue's most
    upstream queued vehicle, the head its most downstream one.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    lane_index: Annotated[int, Field(ge=0)]
    condition: QueueCondition
    #: The most upstream queued vehicle [m]; None while the lane is free.
    back_station_m: FiniteFloat | None = None
    #: The queue reaches the sensors' upstream reach in this lane: its back is at least that far
    #: upstream (``back_station_m`` is where it leaves the sensors' sight), not measured.
    back_beyond_reach: bool = False
    head_station_m: FiniteFloat | None = None
    #: ``head - back`` [m]; 0 while free.
    length_m: NonNegFloat = 0.0
    vehicle_count: Annotated[int, Field(ge=0)] = 0
    #: Mean speed of the queued vehicles [m/s].
    mean_speed_mps: NonNegFloat | None = None
    #: The back's speed along the road over the last seconds [m/s]: negative while the queue
    #: grows upstream (a shock wave's speed), positive while it dissolves; None until known.
    back_speed_mps: FiniteFloat | None = None
    #: How far upstream the site's sensors see a car in this lane [m]: a back here or beyond is
    #: "beyond" (``back_beyond_reach``).
    reach_station_m: FiniteFloat
    #: Where the back is beyond the reach and the site has point sensors upstream
    #: (:class:`PointSensorReading`): the back stands downstream of this station, where the
    #: nearest point sensor upstream of the queue reads the lane free [m]; None: no sensor
    #: bounds it (none upstream, or every one reads the lane queued).
    back_upstream_bound_m: FiniteFloat | None = None
    #: ... and upstream of this one [m]: the farthest upstream point sensor that reads the lane
    #: queued in an unbroken run from the reach, or the reach itself. None while the back is
    #: measured by the tracks (``back_beyond_reach`` false).
    back_downstream_bound_m: FiniteFloat | None = None


class QueueState(Message):
    """Every lane's queue at one instant, from the alert service's tracks: on
    ``wz/<site>/queue`` once a second of track stamps, and at once when a lane's condition
    changes. ``stamp`` is the track batch's capture time."""

    kind: Literal["queue_state"] = "queue_state"
    lanes: list[LaneQueue]

    @property
    def condition(self) -> QueueCondition:
        """The worst lane's condition (stopped over slow over free)."""
        order = list(QueueCondition)
        return max(
            (lane.condition for lane in self.lanes), key=order.index, default=QueueCondition.FREE
        )

    @property
    def back_station_m(self) -> float | None:
        """The most upstream back of every queued lane [m]; None when every lane is free."""
        backs = [lane.back_station_m for lane in self.lanes if lane.back_station_m is not None]
        return min(backs) if backs else None


class PointLaneReading(BaseModel):
    """One lane of a :class:`PointSensorReading`: over the interval, the vehicles that passed
    the sensor's station, their mean speed and the occupancy."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    lane_index: Annotated[int, Field(ge=0)]
    vehicle_count: Annotated[int, Field(ge=0)]
    #: Mean speed of the vehicles that passed [m/s]; None when none passed.
    mean_speed_mps: NonNegFloat | None = None
    #: Share of the interval a vehicle stood over the station [%].
    occupancy_percent: Annotated[float, Field(ge=0.0, le=100.0, allow_inf_nan=False)]


class PointSensorReading(Message):
    """One interval of an upstream point speed sensor (:class:`wz_shared.site.PointSensor`) on
    ``wz/<site>/points/<sensor>``: ``stamp`` is the interval's end, ``source_id`` the sensor."""

    kind: Literal["point_sensor_reading"] = "point_sensor_reading"
    station_m: NonNegFloat
    interval_s: Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
    lanes: list[PointLaneReading]


class ActiveAlerts(Message):
    """The open alert episodes and the roadside devices now: the answer to a query on
    ``wz/<site>/alerts/active``, for a consumer that joins late.

    ``alerts`` holds, per open episode, its newest published event (a start or an update), in
    the alert service's order (by rule, then track).
    """

    kind: Literal["active_alerts"] = "active_alerts"
    alerts: list[Alert]
    devices: RoadsideDeviceState


# --- service health -------------------------------------------------------------------------


class ServiceState(StrEnum):
    STARTING = "starting"
    RUNNING = "running"
    DEGRADED = "degraded"
    #: The process is alive but its loop has not moved for longer than its stall limit.
    STALLED = "stalled"
    STOPPING = "stopping"


#: The message sign's name among a driver's :attr:`ServiceStatus.devices` (WZDx's device type).
SIGN_DEVICE = "dynamic-message-sign"
#: The flashing beacon's (its relay's) name there, also WZDx's device type.
BEACON_DEVICE = "flashing-beacon"


class DeviceLink(BaseModel):
    """Whether a service reaches a field device it drives (a message sign, a beacon relay).

    ``reachable`` is None until the first exchange; ``shows`` is what the device itself last
    reported showing (a sign's message, ``on``/``off`` for a beacon), read back from it.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    address: Annotated[str, Field(max_length=256)]
    reachable: bool | None = None
    detail: Annotated[str, Field(max_length=512)] = ""
    shows: Annotated[str, Field(max_length=512)] | None = None
    #: Seconds since the device last answered (None: never).
    answer_age_s: NonNegFloat | None = None


class ServiceStatus(Message):
    """Periodic health of a service: message rates, latencies and drops per kind."""

    kind: Literal["service_status"] = "service_status"
    service: Identifier
    state: ServiceState
    uptime_s: NonNegFloat
    pid: Annotated[int, Field(ge=0)]
    published_hz: dict[str, NonNegFloat] = Field(default_factory=dict)
    received_hz: dict[str, NonNegFloat] = Field(default_factory=dict)
    latency_p50_ms: dict[str, NonNegFloat] = Field(default_factory=dict)
    invalid_counts: dict[str, Annotated[int, Field(ge=0)]] = Field(default_factory=dict)
    dropped_counts: dict[str, Annotated[int, Field(ge=0)]] = Field(default_factory=dict)
    #: Samples shed before decoding, ``"<key>|<reason>"`` -> count (``stale``,
    #: ``superseded``: a flood or a replay on a stamped stream, :mod:`wz_shared.shedding`).
    shed_counts: dict[str, Annotated[int, Field(ge=0)]] = Field(default_factory=dict)
    #: Seconds since the service's own loop last went round (None: not yet started); past
    #: its stall limit the state is ``stalled``, whatever the status thread still says.
    loop_age_s: NonNegFloat | None = None
    #: Seconds since it last processed an input (a frame, a batch, a message; None: none yet).
    input_age_s: NonNegFloat | None = None
    #: The field devices the service drives, by name (``dynamic-message-sign``).
    devices: dict[Identifier, DeviceLink] = Field(default_factory=dict)


# --- self-calibration -----------------------------------------------------------------------

#: Largest pose correction a sensor's self-calibration may apply: a technician's set-up leaves
#: at most about 3 deg of yaw, 1.5 deg of pitch and roll and 0.5 m of position (issue 39); past
#: these bounds the evidence, not the mount, is wrong, and a survey is due.
MAX_YAW_CORRECTION_DEG = 6.0
MAX_TILT_CORRECTION_DEG = 3.0
MAX_POSITION_CORRECTION_M = 1.0
#: Largest clock offset a sensor's self-calibration may learn [s].
MAX_CLOCK_OFFSET_S = 0.5

_Yaw = Annotated[
    float, Field(ge=-MAX_YAW_CORRECTION_DEG, le=MAX_YAW_CORRECTION_DEG, allow_inf_nan=False)
]
_Tilt = Annotated[
    float, Field(ge=-MAX_TILT_CORRECTION_DEG, le=MAX_TILT_CORRECTION_DEG, allow_inf_nan=False)
]
_Shift = Annotated[
    float, Field(ge=-MAX_POSITION_CORRECTION_M, le=MAX_POSITION_CORRECTION_M, allow_inf_nan=False)
]


class CalibrationState(StrEnum):
    """Where a sensor's self-calibration stands."""

    #: Nothing learned yet: the site file's pose and a zero clock offset are used.
    PRIOR = "prior"
    #: Evidence is being gathered; what is applied may still move.
    LEARNING = "learning"
    #: Every observable part of the pose and the clock is learned within its uncertainty.
    CALIBRATED = "calibrated"
    #: A sudden change (the sensor was knocked): its detections are down-weighted while the
    #: pose is learned again.
    BUMPED = "bumped"


class PoseCorrection(BaseModel):
    """What is added to the site file's pose: angles [deg] and a shift in the site frame [m].

    A ``*_std`` of None means the data did not constrain that part (it stays the site file's):
    a straight road tells nothing of a sensor's position along it.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    yaw_deg: _Yaw = 0.0
    pitch_deg: _Tilt = 0.0
    roll_deg: _Tilt = 0.0
    x_m: _Shift = 0.0
    y_m: _Shift = 0.0
    z_m: _Shift = 0.0
    yaw_std_deg: NonNegFloat | None = None
    pitch_std_deg: NonNegFloat | None = None
    roll_std_deg: NonNegFloat | None = None
    x_std_m: NonNegFloat | None = None
    y_std_m: NonNegFloat | None = None
    z_std_m: NonNegFloat | None = None


class SensorCalibration(Message):
    """One sensor's self-calibration: its pose correction, its clock offset, its state.

    Published by the service that makes the sensor's measurements (``source_id`` is the
    sensor), on a change of state and every few seconds; ``stamp`` is the sensor time of the
    newest evidence. The detector applies it where it measures: the published detections are
    already in the corrected pose and on the corrected clock (``stamp - clock_offset_s``).
    """

    kind: Literal["sensor_calibration"] = "sensor_calibration"
    sensor_kind: Literal["lidar", "camera", "radar"]
    state: CalibrationState
    #: Stamp at which the state was entered [s].
    state_since_s: NonNegFloat
    correction: PoseCorrection = Field(default_factory=PoseCorrection)
    #: The sensor's stamps are this late against the LiDAR's (reference) clock [s].
    clock_offset_s: Annotated[
        float, Field(ge=-MAX_CLOCK_OFFSET_S, le=MAX_CLOCK_OFFSET_S, allow_inf_nan=False)
    ] = 0.0
    clock_offset_std_s: NonNegFloat | None = None
    #: Measurements behind the estimate (matched vehicles, ground points, ...).
    samples: Annotated[int, Field(ge=0)] = 0
    #: Why the state is what it is, for people (``yaw moved 2.1 deg within 12 s``).
    detail: Annotated[str, Field(max_length=500)] = ""


def kind_of(cls: type[Message]) -> str:
    """The ``kind`` tag of a message type (its short name in logs, recordings and the codec)."""
    default = cls.model_fields["kind"].default
    assert isinstance(default, str), f"{cls.__name__} has no kind tag"
    return default


#: Every JSON message type, by kind.
JSON_MESSAGES: dict[str, type[Message]] = {
    kind_of(cls): cls
    for cls in (
        RadarScan,
        GroundTruth,
        DetectionBatch,
        TrackBatch,
        Alert,
        RoadsideDeviceState,
        ActiveAlerts,
        ServiceStatus,
        SensorCalibration,
    )
}
#: Frame metadata types that travel in the binary envelope, by kind.
FRAME_MESSAGES: dict[str, type[Message]] = {
    kind_of(cls): cls for cls in (LidarFrameMeta, CameraFrameMeta)
}
