"""A traffic radar reporting a target list (range, azimuth, radial speed, RCS), as a pure core.

The model stands in for the radar of a roadside radar-camera rig (the Omnisight unit of the
paper's field tests): each scan it reports one target per resolved, detected vehicle echo plus a
few clutter false alarms, in the sensor frame. It takes the frame's ground truth and returns a
:class:`~wz_shared.messages.RadarScan` with, for evaluation, the vehicle ids behind each target.

One scan, step by step (:meth:`RadarModel.scan`):

1. **Echoes** (:meth:`RadarModel.echoes`, no randomness). Each vehicle reflects from one point:
   the centre of its *nearest visible face* (of the two faces of its box footprint that face the
   radar, the end face and the side face, the one whose centre is nearer), at the height of the
   box centre (``VehicleTruth.z_m``). An approaching truck thus gives one target at its front, a
   truck passing broadside one at the middle of its side. From that point:

   - range: the slant (3D) distance from the sensor [m] (a mast radar measures slant range);
   - azimuth: ``atan2(y_s, x_s)`` in the sensor frame, counter-clockwise from the sensor's x axis;
   - radial speed: ``v · cos(angle between velocity and line of sight)``, i.e. the projection of
     the velocity ``v (cos heading, sin heading, 0)`` on the unit line of sight from the sensor,
     positive moving away (approaching traffic is negative);
   - mean RCS [dBsm]: a per-class value (car 10, truck 23, bus 20, motorcycle 3) plus an aspect
     term ``aspect_rcs_gain_db · |sin(aspect)|`` (head-on or tail-on: the class value; broadside:
     the class value plus the gain), where the aspect is the angle between the vehicle's heading
     and its line of sight to the radar.

2. **Visibility.** An echo is lost outside the horizontal field of view
   (``|azimuth| <= horizontal_fov / 2``), beyond ``max_range_m``, or when occluded. Occlusion
   rule: each vehicle box has an angular extent seen from the sensor, an azimuth interval and an
   elevation interval (over its 8 corners). A nearer vehicle (smaller echo range) shadows the
   fraction ``(azimuth overlap / azimuth extent) · (elevation overlap / elevation extent)`` of
   it; a vehicle of which at least ``occlusion_fraction`` (default one half) lies in the shadow
   of a *single* nearer vehicle is missed. A car right behind a truck is missed; a car behind
   another car, seen from a 5 m mast, stays visible once the gap is long enough for the beam to
   pass over the roof. No elevation field-of-view limit is applied.

3. **Resolution cells.** The radar cannot separate echoes that are closer than one range
   resolution *and* one azimuth resolution (strictly less than each). Visible echoes are merged
   greedily, strongest first: the strongest takes every remaining echo within one cell of it.
   A merged target reports the strongest echo's range, azimuth and radial speed, and the power
   sum of the members' RCS. Its truth association lists every member vehicle.

4. **Detection** (Swerling I, square-law detector). The mean SNR of an echo follows the radar
   equation, ``SNR = SNR_ref · (σ / σ_car) · (R_ref / R)^4 · L_rain``, normalised so that a car
   (head-on, ``σ_car`` = 10 dBsm) at ``reference_range_m`` (100 m) is detected with probability
   ``reference_detection_probability`` (0.95). With a detection threshold ``T = -ln(P_fa)`` in
   noise-power units (``cell_false_alarm_probability``), the received power of a Swerling I
   target is exponential with mean ``1 + SNR``, so ``P_d = P_fa^(1 / (1 + SNR))`` exactly. The
   model draws that power ``P`` (one exponential draw, the scan-to-scan fluctuation), detects
   when ``P > T``, and reports ``RCS = (P - 1) / (SNR_ref / σ_car · (R_ref / R)^4)``: the RCS the
   radar would infer from the received power (unbiased over all scans, biased high near the
   detection limit as in a real radar, and lowered by rain that the radar does not know about).
   For a merged cell the mean SNRs add.

   Rain: two-way specific attenuation ``γ = k · rain^α`` [dB/km] (ITU-R P.838 at 77 GHz,
   ``k ≈ 1.0``, ``α ≈ 0.75``: about 5 dB/km at 8 mm/h, so about 2 dB at 200 m), and extra clutter
   false alarms (``rain_false_alarms_per_mm_h``). Fog and light do not affect the radar.

5. **Noise.** Gaussian noise with the intrinsics' standard deviations on range (clipped at 0),
   azimuth and radial speed of every detected target.

6. **False alarms.** A Poisson number per scan with mean ``false_alarm_rate_per_scan`` (plus the
   rain term), uniform in range ``[0, max_range_m]`` and azimuth within the field of view, RCS
   uniform in ``clutter_rcs_dbsm ± 5`` dB, radial speed ``N(0, clutter_speed_std_mps)``
   (stationary clutter seen through the speed noise). This rate is the model's knob: it is not
   derived from ``cell_false_alarm_probability``, which sets only the detection threshold.

Targets are reported in increasing range. Randomness is drawn from a generator seeded by
``(seed, scan_index)``: a scan depends only on the seed, its index and its inputs, not on the
scans before it, so a replay or a rebuilt model (new weather) reproduces it.

Frames: positions in the site frame (ENU metres); the sensor frame is x forward, y left, z up,
rotated from the site frame by the mount's yaw (counter-clockwise from east), pitch (positive
nose-up) and roll (positive right side down, about x), applied as ``Rz(yaw) Ry(-pitch) Rx(roll)``
with right-handed elementary rotations.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64, Bool
from wz_shared.messages import RadarScan, RadarTarget, VehicleClass, VehicleTruth
from wz_shared.sensor_mounts import intrinsics_of
from wz_shared.site import RadarIntrinsics, SensorMount
from wz_simulator.sensors.scene import Weather

#: Mean RCS by vehicle class, seen head-on or tail-on [dBsm].
CLASS_RCS_DBSM: Mapping[VehicleClass, float] = MappingProxyType(
    {
        VehicleClass.CAR: 10.0,
        VehicleClass.TRUCK: 23.0,
        VehicleClass.BUS: 20.0,
        VehicleClass.MOTORCYCLE: 3.0,
        VehicleClass.UNKNOWN: 10.0,
    }
)
#: Two-way rain attenuation ``γ = k · rain^α`` [dB/km] at 77 GHz (ITU-R P.838, rounded).
RAIN_ATTENUATION_K_DB_PER_KM = 1.0
RAIN_ATTENUATION_ALPHA = 0.75
#: Half-width of the uniform spread of clutter RCS around ``clutter_rcs_dbsm`` [dB].
CLUTTER_RCS_SPREAD_DB = 5.0
#: Ranges below this are clamped in the radar equation [m] (keeps R^-4 finite).
_MIN_SNR_RANGE_M = 1.0


def _wrap_rad(angle_rad: F64) -> F64:
    """Wrap angles to [-pi, pi)."""
    wrapped: F64 = (angle_rad + np.pi) % (2.0 * np.pi) - np.pi
    return wrapped


def _interval_overlap(low_a: F64, high_a: F64, low_b: F64, high_b: F64) -> F64:
    """Length of the intersection of intervals ``[low_a, high_a]`` and ``[low_b, high_b]``."""
    overlap: F64 = np.clip(np.minimum(high_a, high_b) - np.maximum(low_a, low_b), 0.0, None)
    return overlap


@dataclass(frozen=True)
class RadarEchoes:
    """Noise-free echoes of one frame's vehicles, one row per vehicle (input order).

    Attributes
    ----------
    vehicle_ids
        Vehicle ids, length N.
    reflection_xyz_m
        Reflection point (centre of the nearest visible face) in the site frame [m], (N, 3).
    range_m
        Slant range from the sensor to the reflection point [m], (N,).
    azimuth_rad
        Azimuth in the sensor frame, counter-clockwise from its x axis [rad], (N,).
    elevation_rad
        Elevation in the sensor frame, positive up [rad], (N,).
    radial_speed_mps
        Velocity projected on the line of sight, positive moving away [m/s], (N,).
    mean_rcs_dbsm
        Class RCS plus the aspect term, before fluctuation [dBsm], (N,).
    mean_snr
        Mean signal-to-noise ratio (linear, rain loss included), (N,).
    in_fov, in_range, occluded
        Visibility flags, (N,).
    """

    vehicle_ids: tuple[str, ...]
    reflection_xyz_m: F64
    range_m: F64
    azimuth_rad: F64
    elevation_rad: F64
    radial_speed_mps: F64
    mean_rcs_dbsm: F64
    mean_snr: F64
    in_fov: Bool
    in_range: Bool
    occluded: Bool

    @property
    def visible(self) -> Bool:
        """Echoes the radar can see: in the field of view, in range and not occluded, (N,)."""
        visible: Bool = self.in_fov & self.in_range & ~self.occluded
        return visible


@dataclass(frozen=True)
class RadarScanResult:
    """One simulated scan and its truth association.

    Attributes
    ----------
    scan
        The message to publish.
    target_vehicle_ids
        Parallel to ``scan.targets``: the ids of the vehicles each target came from (more than
        one where echoes merged in one resolution cell); an empty tuple for a false alarm.
    """

    scan: RadarScan
    target_vehicle_ids: list[tuple[str, ...]]


class RadarModel:
    """Simulated traffic radar: vehicle truth in, target list out.

    Parameters
    ----------
    mount : SensorMount
        Sensor id, pose and :class:`RadarIntrinsics` (range, field of view, resolutions, noise).
    weather : Weather
        Rain rate lowers SNR and adds clutter; the rest is ignored.
    seed : int
        Seed of the scan generators (each scan draws from ``(seed, scan_index)``).
    site_id : str
        Site of the published scans.
    false_alarm_rate_per_scan : float
        Mean number of clutter false alarms per scan in dry weather.
    rain_false_alarms_per_mm_h : float
        Extra false alarms per scan per mm/h of rain.
    reference_range_m : float
        Range [m] at which a head-on car is detected with ``reference_detection_probability``.
    reference_detection_probability : float
        Detection probability of a head-on car at ``reference_range_m``, in (0, 1).
    cell_false_alarm_probability : float
        Probability that noise alone crosses the threshold in one cell; sets the threshold.
    occlusion_fraction : float
        Shadowed fraction of a vehicle's angular extent, by one nearer vehicle, from which it
        is missed, in (0, 1].
    aspect_rcs_gain_db : float
        RCS gain of a broadside view over a head-on one [dB].
    class_rcs_dbsm : Mapping[VehicleClass, float] or None
        Head-on RCS per class [dBsm]; ``CLASS_RCS_DBSM`` when None.
    clutter_rcs_dbsm : float
        Centre of the clutter RCS distribution [dBsm].
    clutter_speed_std_mps : float
        Standard deviation of the clutter radial speed [m/s].
    """

    def __init__(
        self,
        mount: SensorMount,
        weather: Weather,
        seed: int,
        *,
        site_id: str,
        false_alarm_rate_per_scan: float = 0.5,
        rain_false_alarms_per_mm_h: float = 0.05,
        reference_range_m: float = 100.0,
        reference_detection_probability: float = 0.95,
        cell_false_alarm_probability: float = 1e-6,
        occlusion_fraction: float = 0.5,
        aspect_rcs_gain_db: float = 3.0,
        class_rcs_dbsm: Mapping[VehicleClass, float] | None = None,
        clutter_rcs_dbsm: float = -10.0,
        clutter_speed_std_mps: float = 0.3,
    ) -> None:
        intrinsics = intrinsics_of(mount, RadarIntrinsics, "RadarModel needs radar intrinsics")
        if false_alarm_rate_per_scan < 0 or rain_false_alarms_per_mm_h < 0:
            raise ValueError("false-alarm rates must be non-negative")
        if not 0.0 < reference_detection_probability < 1.0:
            raise ValueError("reference_detection_probability must lie in (0, 1)")
        if not 0.0 < cell_false_alarm_probability < reference_detection_probability:
            raise ValueError(
                "cell_false_alarm_probability must lie in (0, reference_detection_probability)"
            )
        if reference_range_m <= 0:
            raise ValueError("reference_range_m must be positive")
        if not 0.0 < occlusion_fraction <= 1.0:
            raise ValueError("occlusion_fraction must lie in (0, 1]")
        self.mount = mount
        self.intrinsics = intrinsics
        self.weather = weather
        self.seed = seed
        self.site_id = site_id
        self.false_alarm_rate_per_scan = false_alarm_rate_per_scan
        self.rain_false_alarms_per_mm_h = rain_false_alarms_per_mm_h
        self.reference_range_m = reference_range_m
        self.occlusion_fraction = occlusion_fraction
        self.aspect_rcs_gain_db = aspect_rcs_gain_db
        self.class_rcs_dbsm = dict(CLASS_RCS_DBSM if class_rcs_dbsm is None else class_rcs_dbsm)
        self.clutter_rcs_dbsm = clutter_rcs_dbsm
        self.clutter_speed_std_mps = clutter_speed_std_mps

        pose = mount.pose
        self.position_m: F64 = np.array([pose.x_m, pose.y_m, pose.z_m])
        self.rotation: F64 = pose.rotation()
        # Threshold T in noise-power units: P_fa = exp(-T).
        self.threshold = -math.log(cell_false_alarm_probability)
        # Swerling I: P_d = exp(-T / (1 + SNR))  =>  SNR_ref = T / -ln(P_d,ref) - 1.
        self.reference_snr = self.threshold / -math.log(reference_detection_probability) - 1.0
        self.reference_rcs_m2 = 10.0 ** (self.class_rcs_dbsm[VehicleClass.CAR] / 10.0)
        self.half_fov_rad = math.radians(self.intrinsics.horizontal_fov_deg) / 2.0
        self.azimuth_resolution_rad = math.radians(self.intrinsics.azimuth_resolution_deg)
        self.azimuth_noise_std_rad = math.radians(self.intrinsics.azimuth_noise_std_deg)

    def turn_to(self, rotation: F64) -> None:
        """Turn the radar to ``rotation`` (sensor to site, (3, 3)), its position kept: the next
        scans see the road from there (a real mast's sway, settling or a bump, see
        :mod:`~wz_simulator.sensors.mast`). Exact: nothing is cached from the orientation."""
        self.rotation = np.array(rotation, dtype=np.float64)

    # --- radar equation ----------------------------------------------------------------

    @property
    def rain_attenuation_db_per_m(self) -> float:
        """Two-way rain attenuation [dB/m] for the current weather (0 when dry)."""
        rain = max(self.weather.rain_mm_per_h, 0.0)
        one_way_db_per_km = RAIN_ATTENUATION_K_DB_PER_KM * math.pow(rain, RAIN_ATTENUATION_ALPHA)
        return 2.0 * one_way_db_per_km / 1000.0

    def _snr_per_m2(self, range_m: F64) -> F64:
        """Mean SNR per square metre of RCS, without rain loss: ``SNR_ref/σ_car (R_ref/R)^4``."""
        ratio = self.reference_range_m / np.maximum(range_m, _MIN_SNR_RANGE_M)
        snr: F64 = (self.reference_snr / self.reference_rcs_m2) * ratio**4
        return snr

    def mean_snr(self, rcs_dbsm: npt.ArrayLike, range_m: npt.ArrayLike) -> F64:
        """Mean SNR (linear) of a target by the radar equation, rain loss included.

        Parameters
        ----------
        rcs_dbsm : array_like, shape (...)
            Mean radar cross-section [dBsm].
        range_m : array_like, shape (...)
            Range [m].

        Returns
        -------
        ndarray, shape (...)
            ``SNR_ref · (σ / σ_car) · (R_ref / R)^4 · 10^(-γ R / 10)``.
        """
        rcs_m2 = 10.0 ** (np.asarray(rcs_dbsm, dtype=np.float64) / 10.0)
        range_arr = np.asarray(range_m, dtype=np.float64)
        rain_gain = 10.0 ** (-self.rain_attenuation_db_per_m * range_arr / 10.0)
        snr: F64 = rcs_m2 * self._snr_per_m2(range_arr) * rain_gain
        return snr

    def detection_probability(self, rcs_dbsm: npt.ArrayLike, range_m: npt.ArrayLike) -> F64:
        """Probability of detecting a lone, visible Swerling I target.

        ``rcs_dbsm`` [dBsm] and ``range_m`` [m] are as in :meth:`mean_snr`.

        Returns
        -------
        ndarray, shape (...)
            ``P_d = exp(-T / (1 + SNR))`` with ``T = -ln(P_fa)``.
        """
        pd: F64 = np.exp(-self.threshold / (1.0 + self.mean_snr(rcs_dbsm, range_m)))
        return pd

    # --- geometry ----------------------------------------------------------------------

    def echoes(self, vehicles: Sequence[VehicleTruth]) -> RadarEchoes:
        """Noise-free echo of every vehicle and whether the radar can see it.

        Parameters
        ----------
        vehicles : sequence of VehicleTruth, length N
            The frame's ground truth (site frame, box centres).

        Returns
        -------
        RadarEchoes
            One row per vehicle, in input order (see the module docstring for the model).
        """
        n = len(vehicles)
        fields = np.array(
            [
                (v.x_m, v.y_m, v.z_m, v.heading_rad, v.speed_mps, v.length_m, v.width_m, v.height_m)
                for v in vehicles
            ],
            dtype=np.float64,
        ).reshape(n, 8)
        center_xy = fields[:, 0:2]
        center_z, heading, speed = fields[:, 2], fields[:, 3], fields[:, 4]
        half_length, half_width, half_height = (
            0.5 * fields[:, 5],
            0.5 * fields[:, 6],
            0.5 * fields[:, 7],
        )
        cos_h, sin_h = np.cos(heading), np.sin(heading)

        # Sensor position in each vehicle's box frame (x along the heading, y to its left).
        to_sensor = self.position_m[:2] - center_xy
        u_x = to_sensor[:, 0] * cos_h + to_sensor[:, 1] * sin_h
        u_y = -to_sensor[:, 0] * sin_h + to_sensor[:, 1] * cos_h
        # The two faces turned to the sensor: the end face at x = ±L/2, the side face at ±W/2.
        end_x = np.where(u_x >= 0.0, half_length, -half_length)
        side_y = np.where(u_y >= 0.0, half_width, -half_width)
        end_nearer = (u_x - end_x) ** 2 + u_y**2 <= u_x**2 + (u_y - side_y) ** 2
        face_x = np.where(end_nearer, end_x, 0.0)
        face_y = np.where(end_nearer, 0.0, side_y)
        reflection = np.column_stack(
            (
                center_xy[:, 0] + face_x * cos_h - face_y * sin_h,
                center_xy[:, 1] + face_x * sin_h + face_y * cos_h,
                center_z,
            )
        )

        # Slant range, azimuth and elevation in the sensor frame.
        line_of_sight = reflection - self.position_m
        local = line_of_sight @ self.rotation  # rows: R^T (p - p_s)
        range_m = np.sqrt(np.einsum("ij,ij->i", line_of_sight, line_of_sight))
        azimuth = np.arctan2(local[:, 1], local[:, 0])
        elevation = np.arctan2(local[:, 2], np.hypot(local[:, 0], local[:, 1]))

        # v cos(angle) = v_vec · LOS / |LOS|, with v_vec = v (cos h, sin h, 0).
        safe_range = np.maximum(range_m, 1e-9)
        radial_speed = (
            speed * (cos_h * line_of_sight[:, 0] + sin_h * line_of_sight[:, 1]) / safe_range
        )

        # Aspect: |sin| of the angle between the heading and the line to the sensor.
        abs_sin_aspect = np.abs(u_y) / np.maximum(np.hypot(u_x, u_y), 1e-9)
        class_rcs = np.array([self.class_rcs_dbsm[v.vehicle_class] for v in vehicles], dtype=float)
        mean_rcs_dbsm = class_rcs + self.aspect_rcs_gain_db * abs_sin_aspect

        in_fov = np.abs(azimuth) <= self.half_fov_rad + 1e-12
        in_range = range_m <= self.intrinsics.max_range_m
        occluded = self._occluded(
            center_xy, center_z, cos_h, sin_h, half_length, half_width, half_height, range_m
        )
        return RadarEchoes(
            vehicle_ids=tuple(v.vehicle_id for v in vehicles),
            reflection_xyz_m=reflection,
            range_m=range_m,
            azimuth_rad=azimuth,
            elevation_rad=elevation,
            radial_speed_mps=radial_speed,
            mean_rcs_dbsm=mean_rcs_dbsm,
            mean_snr=self.mean_snr(mean_rcs_dbsm, range_m),
            in_fov=in_fov,
            in_range=in_range,
            occluded=occluded,
        )

    def _occluded(
        self,
        center_xy: F64,
        center_z: F64,
        cos_h: F64,
        sin_h: F64,
        half_length: F64,
        half_width: F64,
        half_height: F64,
        echo_range_m: F64,
    ) -> Bool:
        """Vehicles mostly in the shadow of one nearer vehicle, shape (N,).

        Each box's angular extent is its azimuth and elevation interval over its 8 corners;
        ``shadow[i, j]`` is the fraction of j's extent (azimuth overlap fraction times elevation
        overlap fraction) covered by i, counted only where i's echo range is below j's.
        """
        n = center_xy.shape[0]
        if n < 2:
            return np.zeros(n, dtype=bool)
        signs_l = np.array([-1.0, 1.0, 1.0, -1.0])
        signs_w = np.array([-1.0, -1.0, 1.0, 1.0])
        along = signs_l * half_length[:, None]  # (N, 4)
        across = signs_w * half_width[:, None]
        corner_x = center_xy[:, 0:1] + along * cos_h[:, None] - across * sin_h[:, None]
        corner_y = center_xy[:, 1:2] + along * sin_h[:, None] + across * cos_h[:, None]
        bottom = np.broadcast_to((center_z - half_height)[:, None], (n, 4))
        top = np.broadcast_to((center_z + half_height)[:, None], (n, 4))
        corners = np.stack(
            (
                np.concatenate((corner_x, corner_x), axis=1),
                np.concatenate((corner_y, corner_y), axis=1),
                np.concatenate((bottom, top), axis=1),
            ),
            axis=-1,
        )  # (N, 8, 3)
        local = (corners - self.position_m) @ self.rotation
        corner_az = np.arctan2(local[..., 1], local[..., 0])
        corner_el = np.arctan2(local[..., 2], np.hypot(local[..., 0], local[..., 1]))
        # Azimuths relative to each box's first corner, so an extent across ±pi stays whole.
        reference_az = corner_az[:, 0]
        relative_az = _wrap_rad(corner_az - reference_az[:, None])
        az_low, az_high = relative_az.min(axis=1), relative_az.max(axis=1)
        el_low, el_high = corner_el.min(axis=1), corner_el.max(axis=1)

        # Pairwise, in j's azimuth reference: rows i (occluder), columns j (occluded).
        shift = _wrap_rad(reference_az[:, None] - reference_az[None, :])
        az_overlap = _interval_overlap(
            shift + az_low[:, None], shift + az_high[:, None], az_low[None, :], az_high[None, :]
        )
        el_overlap = _interval_overlap(
            el_low[:, None], el_high[:, None], el_low[None, :], el_high[None, :]
        )
        az_extent = np.maximum(az_high - az_low, 1e-12)
        el_extent = np.maximum(el_high - el_low, 1e-12)
        shadow = (az_overlap / az_extent[None, :]) * (el_overlap / el_extent[None, :])
        nearer = echo_range_m[:, None] < echo_range_m[None, :]
        shadow = np.where(nearer, shadow, 0.0)
        occluded: Bool = shadow.max(axis=0) >= self.occlusion_fraction
        return occluded

    def _resolution_cells(self, echoes: RadarEchoes) -> list[npt.NDArray[np.intp]]:
        """Group visible echoes the radar cannot separate; each group's first index is its peak.

        Greedy, strongest first: the strongest ungrouped echo takes every ungrouped echo less
        than one range resolution and one azimuth resolution away from it.
        """
        visible = np.flatnonzero(echoes.visible)
        order = visible[np.argsort(-echoes.mean_snr[visible], kind="stable")]
        if order.size == 0:
            return []
        ranges = echoes.range_m[order]
        azimuths = echoes.azimuth_rad[order]
        same_cell = (
            np.abs(ranges[:, None] - ranges[None, :]) < self.intrinsics.range_resolution_m
        ) & (np.abs(_wrap_rad(azimuths[:, None] - azimuths[None, :])) < self.azimuth_resolution_rad)
        if not same_cell.sum() > order.size:  # every echo alone in its cell (the common case)
            return [order[k : k + 1] for k in range(order.size)]
        free = np.ones(order.size, dtype=bool)
        cells: list[npt.NDArray[np.intp]] = []
        for k in range(order.size):
            if not free[k]:
                continue
            members = np.flatnonzero(same_cell[k] & free)  # includes k, the strongest
            free[members] = False
            cells.append(order[members])
        return cells

    # --- one scan ----------------------------------------------------------------------

    def scan(
        self, vehicles: Sequence[VehicleTruth], stamp: float, scan_index: int
    ) -> RadarScanResult:
        """Simulate one radar scan.

        Parameters
        ----------
        vehicles : sequence of VehicleTruth
            Ground truth at the capture time.
        stamp : float
            Capture time [s].
        scan_index : int
            Index of the scan (>= 0); with the seed, it selects the random draws.

        Returns
        -------
        RadarScanResult
            The scan (targets in increasing range) and, per target, its vehicle ids (empty for
            a false alarm).
        """
        rng = np.random.default_rng((self.seed, scan_index))
        intrinsics = self.intrinsics
        echoes = self.echoes(vehicles)
        cells = self._resolution_cells(echoes)

        n_cells = len(cells)
        sizes = np.array([cell.size for cell in cells], dtype=np.intp)
        starts = np.cumsum(sizes) - sizes
        members = np.concatenate(cells) if cells else np.zeros(0, dtype=np.intp)
        peak = members[starts]
        cell_snr = np.add.reduceat(echoes.mean_snr[members], starts) if n_cells else np.zeros(0)
        # Swerling I: received power (noise units) is exponential with mean 1 + SNR.
        power = (1.0 + cell_snr) * rng.standard_exponential(n_cells)
        detected = power > self.threshold
        range_noise = rng.normal(0.0, intrinsics.range_noise_std_m, n_cells)
        azimuth_noise = rng.normal(0.0, self.azimuth_noise_std_rad, n_cells)
        speed_noise = rng.normal(0.0, intrinsics.speed_noise_std_mps, n_cells)

        peak_range = echoes.range_m[peak]
        # The RCS the radar infers from the received power, unaware of rain loss.
        rcs_m2 = (power - 1.0) / self._snr_per_m2(peak_range)
        target_range = np.maximum(peak_range + range_noise, 0.0)[detected]
        target_azimuth = _wrap_rad(echoes.azimuth_rad[peak] + azimuth_noise)[detected]
        target_speed = (echoes.radial_speed_mps[peak] + speed_noise)[detected]
        target_rcs = 10.0 * np.log10(np.maximum(rcs_m2, 1e-12))[detected]
        ids = echoes.vehicle_ids
        target_ids = [
            tuple(ids[i] for i in cell) for cell, hit in zip(cells, detected, strict=True) if hit
        ]

        # Clutter false alarms: Poisson count, uniform in range and azimuth, near-zero speed.
        rate = self.false_alarm_rate_per_scan + self.rain_false_alarms_per_mm_h * max(
            self.weather.rain_mm_per_h, 0.0
        )
        n_false = int(rng.poisson(rate))
        false_range = rng.uniform(0.0, intrinsics.max_range_m, n_false)
        false_azimuth = rng.uniform(-self.half_fov_rad, self.half_fov_rad, n_false)
        false_speed = rng.normal(0.0, self.clutter_speed_std_mps, n_false)
        false_rcs = self.clutter_rcs_dbsm + rng.uniform(
            -CLUTTER_RCS_SPREAD_DB, CLUTTER_RCS_SPREAD_DB, n_false
        )

        all_range = np.concatenate((target_range, false_range))
        all_azimuth = np.concatenate((target_azimuth, false_azimuth))
        all_speed = np.concatenate((target_speed, false_speed))
        all_rcs = np.concatenate((target_rcs, false_rcs))
        all_ids = target_ids + [()] * n_false
        order = np.argsort(all_range, kind="stable")
        targets = [
            RadarTarget(range_m=r, azimuth_rad=a, radial_speed_mps=s, rcs_dbsm=c)
            for r, a, s, c in zip(
                all_range[order].tolist(),
                all_azimuth[order].tolist(),
                all_speed[order].tolist(),
                all_rcs[order].tolist(),
                strict=True,
            )
        ]
        scan = RadarScan(
            site=self.site_id,
            source_id=self.mount.sensor_id,
            stamp=stamp,
            scan_index=scan_index,
            targets=targets,
        )
        return RadarScanResult(scan=scan, target_vehicle_ids=[all_ids[i] for i in order.tolist()])
