"""The paper's method (Saba et al. 2025, section 3), runnable on per-sensor object lists.

The pipeline, as the paper describes it:

1. **Per-sensor smoothing** (:func:`smooth_sensor_tracks`): each sensor's own object track (the
   sequence of positions the sensor reports under one object id) is filtered forward by a
   constant-velocity Kalman filter with that sensor's ``R`` (Eq. 7-10).
2. **Nearest-distance matching** (:func:`match_nearest`): at each frame, camera and LiDAR
   objects are paired by increasing distance, greedily, each used once, pairs farther apart
   than ``max_match_distance_m`` refused.
3. **Kalman late fusion** (:class:`PaperFusion`): one filter per fused object; at each frame it
   is predicted to the frame's time (Eq. 11-12) and updated with the camera measurement, then
   with the LiDAR one (Eq. 13-16, two sequential updates into one posterior).
4. **Baseline** (:func:`simple_average`): the midpoint of the matched camera and LiDAR positions.

What the paper leaves open, decided here:

* **Frames.** The paper's simulated sensors are synchronous. Here observations of both sensors
  are grouped into frames by time: sorted by stamp, a frame takes every observation within
  ``frame_tolerance_s`` of its first one, and its time is that first stamp (so with the default
  1 ms tolerance a frame is "one timestamp"; asynchronous field data need a tolerance of about
  half the slower sensor's period, and then a measurement's own time is approximated by the
  frame's).
* **Fused identity.** A match links the camera object id and the LiDAR object id to one fused
  object, for good: later observations of either id update that object even when the other
  sensor does not see it that frame. Links are never broken or merged; a match between two ids
  already linked to different fused objects is ignored (each updates its own).
* **Unmatched objects.** An observation left unmatched updates the fused object its id is linked
  to with that one sensor alone (the paper's field-data behaviour: "the measurement-update step
  relies solely on that sensor's output"); an unlinked one starts a fused object of its own.
* **Initialisation.** A fused object starts at its first measurement (position covariance the
  sensor's ``R``, velocity zero with std ``initial_velocity_std_mps``); a matched pair starts at
  the camera measurement and is then updated with the LiDAR one, which is the same posterior as
  updating an uninformative prior with both.

Nothing here does I/O.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from wz_fusion_tracker.kalman import KalmanFilter
from wz_shared.arrays import F64
from wz_shared.motion import ProcessNoise

SensorRole = Literal["camera", "lidar"]
PositiveFloat = Annotated[float, Field(gt=0.0)]


class PaperFusionSettings(BaseModel):
    """Parameters of the paper's pipeline; metres and seconds of the site frame."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Sensor id whose observations play the camera's role.
    camera_sensor_id: str = Field(default="camera-mast", min_length=1)
    #: Sensor id whose observations play the LiDAR's role.
    lidar_sensor_id: str = Field(default="lidar-mast", min_length=1)
    #: Std of the white acceleration of Eq. 9, for smoothing and fusion [m/s^2].
    sigma_a_mps2: float = Field(default=2.0, gt=0.0)
    #: Std of a camera position along site x and y; ``R = diag(std^2)`` (isotropic default) [m].
    camera_std_xy_m: tuple[PositiveFloat, PositiveFloat] = (1.0, 1.0)
    #: Std of a LiDAR position along site x and y [m].
    lidar_std_xy_m: tuple[PositiveFloat, PositiveFloat] = (0.3, 0.3)
    #: Camera and LiDAR objects farther apart than this are never matched [m].
    max_match_distance_m: float = Field(default=3.0, gt=0.0)
    #: Std of the unknown velocity of a new filter [m/s].
    initial_velocity_std_mps: float = Field(default=15.0, gt=0.0)
    #: Observations within this of a frame's first stamp belong to that frame [s].
    frame_tolerance_s: float = Field(default=1e-3, ge=0.0)
    #: Smooth each sensor's object tracks before matching and fusion (the paper does).
    smooth_per_sensor: bool = True

    @model_validator(mode="after")
    def _check_sensors(self) -> PaperFusionSettings:
        if self.camera_sensor_id == self.lidar_sensor_id:
            raise ValueError(
                f"camera_sensor_id and lidar_sensor_id are both {self.camera_sensor_id!r}: "
                "the two roles need two sensors"
            )
        return self

    def role_of(self, sensor_id: str) -> SensorRole:
        """The role (``"camera"`` or ``"lidar"``) of ``sensor_id``; ValueError for another id."""
        if sensor_id == self.camera_sensor_id:
            return "camera"
        if sensor_id == self.lidar_sensor_id:
            return "lidar"
        raise ValueError(
            f"sensor {sensor_id!r} is neither the camera ({self.camera_sensor_id!r}) nor the "
            f"LiDAR ({self.lidar_sensor_id!r}) of the paper's settings"
        )

    def measurement_covariance(self, role: SensorRole) -> F64:
        """``R = diag(std_x^2, std_y^2)`` of a role [m^2], shape (2, 2)."""
        std_x, std_y = self.camera_std_xy_m if role == "camera" else self.lidar_std_xy_m
        return np.diag([std_x**2, std_y**2])


@dataclass(frozen=True, slots=True)
class Observation:
    """One sensor's position of one of its objects at one time.

    Attributes
    ----------
    stamp_s
        Measurement time [s].
    object_id
        The sensor's own id of the object (its local track id).
    x_m, y_m
        Position in the site frame [m].
    """

    stamp_s: float
    object_id: int
    x_m: float
    y_m: float


@dataclass(frozen=True, slots=True)
class FusedEstimate:
    """The fused state of one object at one frame.

    Attributes
    ----------
    stamp_s
        The frame's time [s].
    fused_id
        Id of the fused object, from 1, never reused.
    camera_object_id, lidar_object_id
        The sensor object ids linked to it (None: never matched with that sensor).
    x_m, y_m, vx_mps, vy_mps
        Posterior state [m, m/s].
    P
        Posterior covariance, shape (4, 4).
    roles
        Roles whose measurement updated it this frame, in update order.
    average_xy_m
        The simple average of this frame's matched camera and LiDAR positions [m] (the
        baseline), None when the object was not matched this frame.
    """

    stamp_s: float
    fused_id: int
    camera_object_id: int | None
    lidar_object_id: int | None
    x_m: float
    y_m: float
    vx_mps: float
    vy_mps: float
    P: F64
    roles: tuple[SensorRole, ...]
    average_xy_m: tuple[float, float] | None


def _initial_filter(
    x_m: float, y_m: float, R: F64, initial_velocity_std_mps: float
) -> KalmanFilter:
    """``x = [z, 0, 0]``, ``P = blockdiag(R, sigma_v^2 I)``."""
    P = np.zeros((4, 4))
    P[:2, :2] = R
    P[2, 2] = P[3, 3] = initial_velocity_std_mps**2
    return KalmanFilter([x_m, y_m, 0.0, 0.0], P)


def smooth_object_tracks(
    observations: Sequence[Observation],
    R: F64,
    sigma_a_mps2: float,
    initial_velocity_std_mps: float,
) -> list[Observation]:
    """Forward Kalman filtering of each object's track of one sensor (paper section 3.1).

    Per object id, by increasing stamp: the first observation initialises
    ``x = [x, y, 0, 0]``, ``P = blockdiag(R, sigma_v^2 I)``; each later one predicts by
    ``dt`` (Eq. 8-9, isotropic ``sigma_a``) and updates with ``z = [x, y]`` and ``R``
    (Eq. 10, 13-16). The filtered position replaces the measured one.

    Parameters
    ----------
    observations
        One sensor's observations, any order, several objects mixed.
    R
        The sensor's position covariance [m^2], shape (2, 2).
    sigma_a_mps2
        Acceleration std [m/s^2].
    initial_velocity_std_mps
        Std of the unknown initial velocity [m/s].

    Returns
    -------
    smoothed
        The observations in the input order, positions filtered.
    """
    noise = ProcessNoise.isotropic(sigma_a_mps2)
    by_object: dict[int, list[int]] = defaultdict(list)
    for index, observation in enumerate(observations):
        by_object[observation.object_id].append(index)
    smoothed: list[Observation | None] = [None] * len(observations)
    for indices in by_object.values():
        indices.sort(key=lambda i: observations[i].stamp_s)
        first = observations[indices[0]]
        kf = _initial_filter(first.x_m, first.y_m, R, initial_velocity_std_mps)
        previous_s = first.stamp_s
        for index in indices:
            observation = observations[index]
            if index != indices[0]:
                kf.predict(observation.stamp_s - previous_s, noise)
                kf.update([observation.x_m, observation.y_m], R)
            previous_s = observation.stamp_s
            smoothed[index] = Observation(
                observation.stamp_s, observation.object_id, float(kf.x[0]), float(kf.x[1])
            )
    return [observation for observation in smoothed if observation is not None]


def smooth_sensor_tracks(
    observations_by_sensor: Mapping[str, Sequence[Observation]], settings: PaperFusionSettings
) -> dict[str, list[Observation]]:
    """:func:`smooth_object_tracks` for each sensor with that sensor's ``R`` and ``sigma_a``.

    Parameters
    ----------
    observations_by_sensor
        Sensor id -> its observations; ids must be the settings' camera or LiDAR.
    settings
        Noise parameters.

    Returns
    -------
    smoothed
        Sensor id -> its observations in the input order, positions filtered.
    """
    return {
        sensor_id: smooth_object_tracks(
            observations,
            settings.measurement_covariance(settings.role_of(sensor_id)),
            settings.sigma_a_mps2,
            settings.initial_velocity_std_mps,
        )
        for sensor_id, observations in observations_by_sensor.items()
    }


def match_nearest(
    camera_objects: Sequence[Observation],
    lidar_objects: Sequence[Observation],
    max_distance_m: float,
) -> list[tuple[int, int]]:
    """Nearest-distance matching of camera and LiDAR objects at one frame (paper section 3.2).

    Greedy by increasing Euclidean distance ``d = |p_camera - p_lidar|``: the closest pair of
    all is matched first, both objects are then used up, and so on, until no pair closer than
    ``max_distance_m`` is left. Equal distances are taken in (camera index, LiDAR index)
    order. Greedy is what "nearest distance" means here; it can differ from the globally
    optimal assignment when objects are closer together than the sensors' errors.

    Parameters
    ----------
    camera_objects, lidar_objects
        The frame's objects of each sensor.
    max_distance_m
        Pairs farther apart than this are never matched [m].

    Returns
    -------
    pairs
        ``(camera_index, lidar_index)`` by increasing distance; each index at most once.
    """
    if not camera_objects or not lidar_objects:
        return []
    camera_xy = np.array([[o.x_m, o.y_m] for o in camera_objects])
    lidar_xy = np.array([[o.x_m, o.y_m] for o in lidar_objects])
    distance_m = np.linalg.norm(camera_xy[:, None, :] - lidar_xy[None, :, :], axis=-1)
    order = np.argsort(distance_m, axis=None, kind="stable")
    used_camera: set[int] = set()
    used_lidar: set[int] = set()
    pairs: list[tuple[int, int]] = []
    for flat in order:
        camera_index, lidar_index = divmod(int(flat), len(lidar_objects))
        if distance_m[camera_index, lidar_index] > max_distance_m:
            break
        if camera_index in used_camera or lidar_index in used_lidar:
            continue
        used_camera.add(camera_index)
        used_lidar.add(lidar_index)
        pairs.append((camera_index, lidar_index))
    return pairs


def simple_average(
    camera_objects: Sequence[Observation],
    lidar_objects: Sequence[Observation],
    pairs: Sequence[tuple[int, int]],
) -> F64:
    """The baseline: the midpoint ``(p_camera + p_lidar) / 2`` of each matched pair [m].

    Parameters
    ----------
    camera_objects, lidar_objects
        The frame's objects of each sensor.
    pairs
        ``(camera_index, lidar_index)`` pairs, e.g. from :func:`match_nearest`.

    Returns
    -------
    midpoints
        Shape (len(pairs), 2) [m].
    """
    midpoints = np.empty((len(pairs), 2))
    for row, (camera_index, lidar_index) in enumerate(pairs):
        camera, lidar = camera_objects[camera_index], lidar_objects[lidar_index]
        midpoints[row] = ((camera.x_m + lidar.x_m) / 2.0, (camera.y_m + lidar.y_m) / 2.0)
    return midpoints


@dataclass(slots=True)
class _FusedObject:
    fused_id: int
    kf: KalmanFilter
    stamp_s: float
    camera_object_id: int | None = None
    lidar_object_id: int | None = None


class PaperFusion:
    """Kalman late fusion of matched camera and LiDAR objects (module docstring, Eq. 11-16).

    Feed it frame by frame with :meth:`step` (stamps non-decreasing), or all at once with
    :meth:`run`.

    Parameters
    ----------
    settings
        Noise, matching distance and sensor roles.
    """

    def __init__(self, settings: PaperFusionSettings) -> None:
        self.settings = settings
        self._noise = ProcessNoise.isotropic(settings.sigma_a_mps2)
        self._R: dict[SensorRole, F64] = {
            "camera": settings.measurement_covariance("camera"),
            "lidar": settings.measurement_covariance("lidar"),
        }
        self._objects: dict[int, _FusedObject] = {}
        self._by_camera_id: dict[int, int] = {}
        self._by_lidar_id: dict[int, int] = {}
        self._next_id = 1
        self._last_stamp_s = -math.inf

    def step(
        self,
        stamp_s: float,
        camera_objects: Sequence[Observation],
        lidar_objects: Sequence[Observation],
    ) -> list[FusedEstimate]:
        """Fuse one frame: match, then predict and update each fused object seen.

        For each fused object with measurements this frame::

            x_p = F x,  P_p = F P F^T + Q                      (Eq. 11-12, dt from its last frame)
            camera: y = z_c - H x_p, S = H P_p H^T + R_c,      (Eq. 13-16)
                    K = P_p H^T S^-1, x = x_p + K y, P = (I - K H) P_p (Joseph form)
            lidar:  the same with z_l, R_l, from the camera's posterior

        Parameters
        ----------
        stamp_s
            The frame's time [s], not before the previous frame's.
        camera_objects, lidar_objects
            The frame's observations of each sensor (their stamps are not used).

        Returns
        -------
        estimates
            One per fused object updated this frame, by increasing ``fused_id``.

        Raises
        ------
        ValueError
            ``stamp_s`` is before the previous frame's.
        """
        if stamp_s < self._last_stamp_s:
            raise ValueError(
                f"frame at {stamp_s:.6f} s is before the previous one ({self._last_stamp_s:.6f} s)"
            )
        self._last_stamp_s = stamp_s
        pairs = match_nearest(camera_objects, lidar_objects, self.settings.max_match_distance_m)
        midpoints = simple_average(camera_objects, lidar_objects, pairs)
        # Per fused object: its measurements this frame, camera first, and the pair's midpoint.
        updates: dict[int, list[tuple[SensorRole, Observation]]] = defaultdict(list)
        averages: dict[int, tuple[float, float]] = {}
        matched_camera: set[int] = set()
        matched_lidar: set[int] = set()
        for (camera_index, lidar_index), midpoint in zip(pairs, midpoints, strict=True):
            camera, lidar = camera_objects[camera_index], lidar_objects[lidar_index]
            fused_id = self._link_pair(camera.object_id, lidar.object_id)
            if fused_id is None:
                continue  # ids linked to two different fused objects: each updates its own
            matched_camera.add(camera_index)
            matched_lidar.add(lidar_index)
            updates[fused_id] += [("camera", camera), ("lidar", lidar)]
            averages[fused_id] = (float(midpoint[0]), float(midpoint[1]))
        for index, camera in enumerate(camera_objects):
            if index not in matched_camera:
                fused_id = self._by_camera_id.get(camera.object_id)
                if fused_id is None:
                    fused_id = self._new_object(camera_object_id=camera.object_id)
                updates[fused_id].insert(0, ("camera", camera))
        for index, lidar in enumerate(lidar_objects):
            if index not in matched_lidar:
                fused_id = self._by_lidar_id.get(lidar.object_id)
                if fused_id is None:
                    fused_id = self._new_object(lidar_object_id=lidar.object_id)
                updates[fused_id].append(("lidar", lidar))

        estimates = []
        for fused_id in sorted(updates):
            fused = self._objects[fused_id]
            roles = self._update_object(fused, stamp_s, updates[fused_id])
            estimates.append(
                FusedEstimate(
                    stamp_s=stamp_s,
                    fused_id=fused_id,
                    camera_object_id=fused.camera_object_id,
                    lidar_object_id=fused.lidar_object_id,
                    x_m=float(fused.kf.x[0]),
                    y_m=float(fused.kf.x[1]),
                    vx_mps=float(fused.kf.x[2]),
                    vy_mps=float(fused.kf.x[3]),
                    P=fused.kf.P.copy(),
                    roles=roles,
                    average_xy_m=averages.get(fused_id),
                )
            )
        return estimates

    def run(
        self, observations_by_sensor: Mapping[str, Sequence[Observation]]
    ) -> list[FusedEstimate]:
        """Group the observations into frames (module docstring) and :meth:`step` through them.

        Parameters
        ----------
        observations_by_sensor
            Sensor id (the settings' camera or LiDAR) -> its observations, any order.

        Returns
        -------
        estimates
            Every frame's estimates, by frame time then ``fused_id``.
        """
        tagged: list[tuple[float, SensorRole, Observation]] = []
        for sensor_id, observations in observations_by_sensor.items():
            role = self.settings.role_of(sensor_id)
            tagged += [(o.stamp_s, role, o) for o in observations]
        tagged.sort(key=lambda item: item[0])
        estimates: list[FusedEstimate] = []
        start = 0
        while start < len(tagged):
            frame_s = tagged[start][0]
            end = start
            while end < len(tagged) and tagged[end][0] <= frame_s + self.settings.frame_tolerance_s:
                end += 1
            frame = tagged[start:end]
            estimates += self.step(
                frame_s,
                [o for _, role, o in frame if role == "camera"],
                [o for _, role, o in frame if role == "lidar"],
            )
            start = end
        return estimates

    def _new_object(
        self, camera_object_id: int | None = None, lidar_object_id: int | None = None
    ) -> int:
        fused_id = self._next_id
        self._next_id += 1
        self._objects[fused_id] = _FusedObject(
            fused_id=fused_id,
            kf=KalmanFilter(np.zeros(4), np.eye(4)),  # replaced at its first update
            stamp_s=math.nan,
            camera_object_id=camera_object_id,
            lidar_object_id=lidar_object_id,
        )
        if camera_object_id is not None:
            self._by_camera_id[camera_object_id] = fused_id
        if lidar_object_id is not None:
            self._by_lidar_id[lidar_object_id] = fused_id
        return fused_id

    def _link_pair(self, camera_object_id: int, lidar_object_id: int) -> int | None:
        """The fused object of a matched pair, linking an unlinked id; None on a conflict."""
        by_camera = self._by_camera_id.get(camera_object_id)
        by_lidar = self._by_lidar_id.get(lidar_object_id)
        if by_camera is None and by_lidar is None:
            return self._new_object(camera_object_id, lidar_object_id)
        if by_camera is not None and by_lidar is not None:
            return by_camera if by_camera == by_lidar else None
        fused_id = by_camera if by_camera is not None else by_lidar
        assert fused_id is not None
        fused = self._objects[fused_id]
        if by_camera is None:
            if fused.camera_object_id is not None:
                return None  # its fused object already has another camera id
            fused.camera_object_id = camera_object_id
            self._by_camera_id[camera_object_id] = fused_id
        else:
            if fused.lidar_object_id is not None:
                return None
            fused.lidar_object_id = lidar_object_id
            self._by_lidar_id[lidar_object_id] = fused_id
        return fused_id

    def _update_object(
        self,
        fused: _FusedObject,
        stamp_s: float,
        measurements: Sequence[tuple[SensorRole, Observation]],
    ) -> tuple[SensorRole, ...]:
        roles: list[SensorRole] = []
        for role, observation in measurements:
            z = (observation.x_m, observation.y_m)
            if math.isnan(fused.stamp_s):
                fused.kf = _initial_filter(
                    z[0], z[1], self._R[role], self.settings.initial_velocity_std_mps
                )
            else:
                # Eq. 11-12 (dt = 0 for the second sensor of a frame), then Eq. 13-16
                fused.kf.predict(stamp_s - fused.stamp_s, self._noise)
                fused.kf.update(z, self._R[role])
            fused.stamp_s = stamp_s
            roles.append(role)
        return tuple(roles)


def run_paper_pipeline(
    observations_by_sensor: Mapping[str, Sequence[Observation]], settings: PaperFusionSettings
) -> list[FusedEstimate]:
    """The whole method: per-sensor smoothing (if ``settings.smooth_per_sensor``), then
    :meth:`PaperFusion.run` on a fresh :class:`PaperFusion`.

    Parameters
    ----------
    observations_by_sensor
        Sensor id -> its raw observations.
    settings
        The pipeline's parameters.

    Returns
    -------
    estimates
        Every frame's fused estimates (each carrying the simple-average baseline when matched).
    """
    if settings.smooth_per_sensor:
        observations_by_sensor = smooth_sensor_tracks(observations_by_sensor, settings)
    return PaperFusion(settings).run(observations_by_sensor)
