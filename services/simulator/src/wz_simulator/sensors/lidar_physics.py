"""The physics of a LiDAR return: materials, weather extinction, detection, dropouts, noise.

Physics of one return
---------------------

1. Apparent reflectivity, reported as the point's intensity (0..1, range-compensated like the
   calibrated reflectivity channel of common sensors)::

       intensity = rho_m * cos(theta)^k_m * exp(-2 alpha r)

   with ``rho_m`` the material's diffuse reflectivity at 905 nm and ``k_m`` its angular exponent
   (:data:`MATERIAL_RESPONSE`: 1 for Lambertian surfaces; close to 0 for retroreflective
   marking paint, drums and signs, which send light back towards the source at any incidence).
   ``exp(-2 alpha r)`` is the two-way transmission through fog and rain, which the sensor
   cannot compensate.
2. Detection: the received power follows the LiDAR equation for an extended target,
   ``P ~ intensity / r^2``. Sensors are specified by the range at which a target of a given
   reflectivity is just detected (datasheet convention: 80 % at ``max_range_m``), so a return is
   detected when ``intensity * (max_range / r)^2 >= range_spec_reflectivity``, and when
   ``min_range_m <= r <= max_range_m``. In clear weather a 10 % target is thus seen to about
   ``max_range / sqrt(8)`` (71 m at 200 m), a grazing road surface much less far.
3. Dropouts: a detected return is lost with probability ``dropout_probability`` + a grazing
   term rising linearly in ``cos(theta)`` from 0 at ``grazing_onset_deg`` to
   ``grazing_dropout_probability`` at 90 deg incidence + the material's extra (glass transmits
   or mirrors most of the beam).
4. Range noise: Gaussian, ``range_noise_std_m`` of the intrinsics, along the beam (Box-Muller
   on float32 uniforms, exact to 5.8 standard deviations).

Weather (``alpha`` [1/m], the sum of both terms):

- Fog: Koschmieder, ``alpha = 3.912 / V * (lambda / 550 nm)^-q`` for visibility V, with the
  size-distribution exponent q of Kim et al. (2001): q = 1.6 (V > 50 km), 1.3 (6-50 km),
  0.16 V + 0.34 (1-6 km), V - 0.5 (0.5-1 km), 0 below 0.5 km (fog droplets scatter all
  wavelengths alike). At 100 m visibility alpha = 0.039 /m: a 35 % target (concrete) at
  normal incidence is lost beyond 34 m.
- Rain: the empirical rain attenuation of free-space-optics link budgets, ``gamma = 1.076
  R^0.67`` dB/km for rain rate R [mm/h] (as commonly cited from Carbonneau and Wisely, 1998),
  ``alpha = gamma / 4343``: 1.0e-3 /m at 8 mm/h, where an 80 % target is seen to 169 m
  instead of 200 and a 10 % one to 66 m instead of 71: rain hurts a LiDAR far less than fog.
  The coefficients are settings (power laws such as ``0.01 R^0.6`` are used elsewhere, with
  various units). Raindrops close to the sensor also return light: a Poisson number of spurious
  points per frame, mean ``rain_clutter_per_mm_h * R``, on uniformly drawn beams at ranges
  uniform in ``[rain_clutter_min_range_m, rain_clutter_max_range_m]``, weak (intensity uniform
  in 0.01-0.1), labelled 0; each replaces its beam's return when nearer.

Randomness: every frame draws from ``numpy.random.default_rng((seed, frame_index))``, so a frame
depends only on the seed, its index and its inputs, never on the frames before it (a replay or a
rebuilt model reproduces it). Draw order: dropouts, range noise, rain clutter."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from wz_shared.arrays import F32, I32, Bool, IntP
from wz_shared.site import LidarIntrinsics
from wz_simulator.sensors.scene import Material


@dataclass(frozen=True)
class SurfaceResponse:
    """How a material returns a 905 nm beam.

    Attributes
    ----------
    reflectivity
        Diffuse reflectivity at normal incidence, 0..1 (retroreflectors are given 1).
    angular_exponent
        The return scales as ``cos(incidence) ** angular_exponent``: 1 for a Lambertian surface,
        near 0 for a retroreflector.
    extra_dropout_probability
        Added to the dropout probability of every return from this material.
    """

    reflectivity: float
    angular_exponent: float = 1.0
    extra_dropout_probability: float = 0.0


#: Response per material: typical NIR reflectivities (asphalt 5-15 %, paint 20-50 %, vegetation
#: and grass 30-50 %, retroreflective sheeting and beads far above any diffuse surface).
MATERIAL_RESPONSE: Mapping[Material, SurfaceResponse] = MappingProxyType(
    {
        Material.ASPHALT: SurfaceResponse(0.08),
        Material.MARKING: SurfaceResponse(0.7, angular_exponent=0.1),
        Material.GRASS: SurfaceResponse(0.35),
        Material.CAR_PAINT: SurfaceResponse(0.3),
        Material.GLASS: SurfaceResponse(0.05, extra_dropout_probability=0.5),
        Material.TIRE: SurfaceResponse(0.03),
        Material.TRUCK_BODY: SurfaceResponse(0.45),
        Material.LIGHT: SurfaceResponse(0.6, angular_exponent=0.3),
        Material.DRUM: SurfaceResponse(0.9, angular_exponent=0.2),
        Material.CONCRETE: SurfaceResponse(0.35),
        Material.SIGN: SurfaceResponse(1.0, angular_exponent=0.2),
        Material.METAL: SurfaceResponse(0.4),
        Material.VEGETATION: SurfaceResponse(0.45),
    }
)

#: Koschmieder's constant: visibility is where contrast falls to 2 % (-ln 0.02).
KOSCHMIEDER = 3.912
#: dB per neper-ish: ``gamma [dB/km] / (10 log10 e) / 1000 = alpha [1/m]``.
_DB_PER_KM_TO_PER_M = 1.0 / (10.0 * math.log10(math.e) * 1000.0)


@dataclass(frozen=True)
class LidarPhysics:
    """Settings of the LiDAR model (units in the names).

    Attributes
    ----------
    sectors
        Equal runs of columns over which the rays that may meet each vehicle are chosen
        (1..azimuth_steps): more sectors give tighter windows, and more of them.
    min_range_m
        Blind zone: geometry nearer than this is not seen (rays start there).
    dropout_probability
        Chance that any detected return is lost.
    grazing_dropout_probability
        Extra chance of loss at 90 deg incidence, falling linearly in cos(incidence) to 0 at
        ``grazing_onset_deg``.
    grazing_onset_deg
        Incidence angle where the grazing dropout starts [deg].
    range_spec_reflectivity
        Reflectivity detected just at ``max_range_m`` (datasheet convention, 0.8); 0 turns the
        detection threshold off (every hit within range returns).
    wavelength_nm
        Laser wavelength (fog extinction depends on it above 0.5 km visibility).
    rain_attenuation_db_per_km
        ``a`` of the rain attenuation ``gamma = a R^b`` [dB/km], R in mm/h.
    rain_attenuation_exponent
        ``b`` of the same.
    rain_clutter_per_mm_h
        Mean spurious raindrop returns per frame per mm/h of rain.
    rain_clutter_min_range_m, rain_clutter_max_range_m
        Range interval of the spurious returns [m].
    raycast_threads
        Threads open3d may use per cast (0: all cores).
    base_ground_material
        Material of the base ground plane (seen where no ground polygon lies).
    """

    sectors: int = 32
    min_range_m: float = 0.5
    dropout_probability: float = 0.001
    grazing_dropout_probability: float = 0.5
    grazing_onset_deg: float = 75.0
    range_spec_reflectivity: float = 0.8
    wavelength_nm: float = 905.0
    rain_attenuation_db_per_km: float = 1.076
    rain_attenuation_exponent: float = 0.67
    rain_clutter_per_mm_h: float = 1.0
    rain_clutter_min_range_m: float = 5.0
    rain_clutter_max_range_m: float = 15.0
    raycast_threads: int = 0
    base_ground_material: Material = Material.GRASS

    @classmethod
    def ideal(cls, sectors: int = 32) -> LidarPhysics:
        """Geometry only: no dropouts, no detection threshold, no rain clutter.

        Weather extinction still scales the intensity; range noise comes from the intrinsics.
        """
        return cls(
            sectors=sectors,
            dropout_probability=0.0,
            grazing_dropout_probability=0.0,
            range_spec_reflectivity=0.0,
            rain_clutter_per_mm_h=0.0,
        )

    def validate(self, intrinsics: LidarIntrinsics) -> None:
        """Raise ValueError naming the first setting that does not fit these intrinsics."""
        if not 1 <= self.sectors <= intrinsics.azimuth_steps:
            raise ValueError(f"sectors must lie in [1, {intrinsics.azimuth_steps}]")
        if not 0.0 <= self.min_range_m < intrinsics.max_range_m:
            raise ValueError("min_range_m must lie in [0, max_range_m)")
        for name in ("dropout_probability", "grazing_dropout_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1]")
        if not 0.0 <= self.grazing_onset_deg < 90.0:
            raise ValueError("grazing_onset_deg must lie in [0, 90)")
        if self.range_spec_reflectivity < 0 or self.rain_clutter_per_mm_h < 0:
            raise ValueError("range_spec_reflectivity and rain_clutter_per_mm_h must be >= 0")
        if not 0.0 <= self.rain_clutter_min_range_m <= self.rain_clutter_max_range_m:
            raise ValueError("rain clutter ranges must satisfy 0 <= min <= max")


def fog_extinction_per_m(visibility_m: float, wavelength_nm: float = 905.0) -> float:
    """Fog extinction coefficient [1/m] from the meteorological visibility [m].

    Koschmieder with Kim et al.'s (2001) wavelength exponent q(V); 0 for infinite visibility.
    """
    if not math.isfinite(visibility_m):
        return 0.0
    if visibility_m <= 0:
        raise ValueError("fog visibility must be positive")
    v_km = visibility_m / 1000.0
    if v_km > 50.0:
        q = 1.6
    elif v_km > 6.0:
        q = 1.3
    elif v_km > 1.0:
        q = 0.16 * v_km + 0.34
    elif v_km > 0.5:
        q = v_km - 0.5
    else:
        q = 0.0
    return float(KOSCHMIEDER / visibility_m * (wavelength_nm / 550.0) ** -q)


def rain_extinction_per_m(
    rain_mm_per_h: float, coefficient_db_per_km: float = 1.076, exponent: float = 0.67
) -> float:
    """Rain extinction coefficient [1/m]: ``gamma = a R^b`` [dB/km] converted to nepers per m."""
    if rain_mm_per_h <= 0:
        return 0.0
    return float(coefficient_db_per_km * rain_mm_per_h**exponent * _DB_PER_KM_TO_PER_M)


@dataclass(frozen=True)
class Returns:
    """Returns of a subset of rays: indices into the frame and their physics."""

    ray_index: IntP
    range_m: F32
    intensity: F32
    detected: Bool
    dropout_probability: F32
    labels: I32


def empty_returns() -> Returns:
    """No returns (no ray met a vehicle)."""
    return Returns(
        ray_index=np.empty(0, dtype=np.intp),
        range_m=np.empty(0, dtype=np.float32),
        intensity=np.empty(0, dtype=np.float32),
        detected=np.empty(0, dtype=bool),
        dropout_probability=np.empty(0, dtype=np.float32),
        labels=np.empty(0, dtype=np.int32),
    )


class ReturnPhysics:
    """Intensity, detection and dropout of hits, for one sensor in one weather.

    Parameters
    ----------
    physics
        The model settings.
    extinction_per_m
        Weather extinction ``alpha`` [1/m] (fog plus rain).
    max_range_m
        The sensor's maximum range [m] (datasheet: 80 % reflectivity detected there).
    """

    def __init__(self, physics: LidarPhysics, extinction_per_m: float, max_range_m: float) -> None:
        self.physics = physics
        self.extinction_per_m = extinction_per_m
        self.max_range_m = max_range_m
        self.material_reflectivity = np.array(
            [MATERIAL_RESPONSE[m].reflectivity for m in Material], dtype=np.float32
        )
        self.material_exponent = np.array(
            [MATERIAL_RESPONSE[m].angular_exponent for m in Material], dtype=np.float32
        )
        self.material_dropout = np.array(
            [MATERIAL_RESPONSE[m].extra_dropout_probability for m in Material], dtype=np.float32
        )
        self.grazing_onset_cos = math.cos(math.radians(physics.grazing_onset_deg))

    def response(self, range_m: F32, cos_incidence: F32, material: IntP) -> Returns:
        """Intensity, detection and dropout probability of hits (see the module docstring).

        ``range_m``, ``cos_incidence`` and ``material`` are parallel, shape (n,); the returned
        ``ray_index`` and ``labels`` are left empty.
        """
        physics = self.physics
        intensity = np.take(self.material_reflectivity, material) * np.power(
            cos_incidence, np.take(self.material_exponent, material)
        )
        if self.extinction_per_m > 0:
            intensity *= np.exp(np.float32(-2.0 * self.extinction_per_m) * range_m)
        detected = (range_m >= physics.min_range_m) & (range_m <= self.max_range_m)
        if physics.range_spec_reflectivity > 0:
            # intensity (R_max / r)^2 >= rho_spec, without dividing by r.
            detected &= intensity * np.float32(self.max_range_m**2) >= np.float32(
                physics.range_spec_reflectivity
            ) * np.square(range_m)
        grazing = np.clip(1.0 - cos_incidence / np.float32(self.grazing_onset_cos), 0.0, 1.0)
        dropout = np.minimum(
            np.float32(physics.dropout_probability)
            + np.float32(physics.grazing_dropout_probability) * grazing
            + np.take(self.material_dropout, material),
            np.float32(1.0),
        )
        empty = np.empty(0, dtype=np.intp)
        return Returns(empty, range_m, intensity, detected, dropout, np.empty(0, dtype=np.int32))


def incidence_cosine(directions: F32, normals: F32) -> F32:
    """|cos| of the angle between unit ray directions and unit normals, both (n, 3); (n,)."""
    cosine: F32 = np.minimum(np.abs(np.einsum("ij,ij->i", directions, normals)), np.float32(1.0))
    return cosine


def standard_normal(rng: np.random.Generator, count: int) -> F32:
    """``count`` standard normal float32 draws by Box-Muller on float32 uniforms.

    Exact in distribution up to 5.8 sigma (the largest ``sqrt(-2 ln u)`` of a float32 u);
    about twice as fast as numpy's float32 ziggurat on this kind of machine.
    """
    half = (count + 1) // 2
    uniform = rng.random(2 * half, dtype=np.float32)
    radius = np.sqrt(np.float32(-2.0) * np.log1p(-uniform[:half]))  # 1 - u lies in (0, 1]
    angle = np.float32(2.0 * np.pi) * uniform[half:]
    normal = np.empty(2 * half, dtype=np.float32)
    np.multiply(radius, np.cos(angle), out=normal[:half])
    np.multiply(radius, np.sin(angle), out=normal[half:])
    return normal[:count]
