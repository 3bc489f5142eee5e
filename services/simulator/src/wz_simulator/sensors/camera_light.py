"""What the weather means for the camera's picture: sun, sky, haze, rain, lamps and noise.

:func:`lighting_for` turns a :class:`~wz_simulator.sensors.scene.Weather` into a
:class:`Lighting`; :func:`shade` lights a surface by its normal (Lambert + hemispheric
ambient) and :func:`atmosphere` hazes a colour by its distance (Koschmieder) and rain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wz_shared.arrays import F64
from wz_simulator.sensors.scene import Light, Weather

#: Koschmieder's constant: contrast falls to 2 % at the meteorological visibility.
KOSCHMIEDER = 3.912


@dataclass(frozen=True)
class Lighting:
    """What the weather means for the picture (colours RGB 0-255, intensities unitless)."""

    sun_direction: F64  # (3,) unit vector towards the sun, site frame
    sun_rgb: F64  # (3,) diffuse intensity per channel
    ambient: float
    sky_zenith_rgb: F64
    sky_horizon_rgb: F64
    terrain_rgb: F64
    haze_rgb: F64
    extinction_per_m: float
    foggy: bool
    rain_contrast: float  # fraction blended towards grey
    wet_road: float  # darkening of asphalt (1 = dry)
    lamps_on: bool
    noise_std: float  # [digital numbers]
    rain_mm_per_h: float


def _sun(azimuth_deg: float, elevation_deg: float) -> F64:
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def lighting_for(weather: Weather) -> Lighting:
    dusk = weather.light == Light.DUSK
    rain = weather.rain_mm_per_h
    foggy = bool(np.isfinite(weather.fog_visibility_m))
    if dusk:
        sun_direction = _sun(200.0, 4.0)
        sun_rgb = np.array([0.16, 0.1, 0.06])
        ambient = 0.3
        zenith, horizon = np.array([18.0, 24.0, 52.0]), np.array([120.0, 78.0, 66.0])
        terrain = np.array([40.0, 48.0, 34.0])
    else:
        sun_direction = _sun(210.0, 48.0)
        sun_rgb = np.array([0.62, 0.6, 0.56])
        ambient = 0.5
        zenith, horizon = np.array([68.0, 128.0, 205.0]), np.array([196.0, 214.0, 232.0])
        terrain = np.array([92.0, 112.0, 66.0])
    if rain > 0.0:  # overcast: no direct sun, flatter sky
        sun_rgb = sun_rgb * 0.2
        ambient = ambient * 1.25
        grey = np.full(3, float(horizon.mean()))
        zenith = 0.3 * zenith + 0.7 * grey * 0.85
        horizon = 0.3 * horizon + 0.7 * grey
    # Clear air still hazes the far ground a little (visibility ~ 20 km); rain and fog more.
    extinction = KOSCHMIEDER / 20000.0
    if rain > 0.0:
        extinction += KOSCHMIEDER * rain**0.6 / 4000.0
    if foggy:
        extinction += KOSCHMIEDER / weather.fog_visibility_m
    fog_rgb = np.array([72.0, 72.0, 80.0]) if dusk else np.array([200.0, 203.0, 207.0])
    return Lighting(
        sun_direction=sun_direction,
        sun_rgb=sun_rgb,
        ambient=ambient,
        sky_zenith_rgb=fog_rgb if foggy else zenith,
        sky_horizon_rgb=fog_rgb if foggy else horizon,
        terrain_rgb=terrain,
        haze_rgb=fog_rgb if foggy else horizon,
        extinction_per_m=extinction,
        foggy=foggy,
        rain_contrast=0.18 if rain > 0.0 else 0.0,
        wet_road=0.72 if rain > 0.0 else 1.0,
        lamps_on=dusk,
        noise_std=5.0 if dusk else 2.0,
        rain_mm_per_h=rain,
    )


def shade(lighting: Lighting, normals: F64) -> F64:
    """Lambert + hemispheric ambient: per-channel gain for surfaces with these normals.

    ``gain = ambient (0.75 + 0.25 n_z) + sun_rgb max(0, n . s)``; shape (..., 3).
    """
    lambert = np.clip(normals @ lighting.sun_direction, 0.0, None)
    ambient = lighting.ambient * (0.75 + 0.25 * normals[..., 2])
    gain: F64 = ambient[..., None] + lambert[..., None] * lighting.sun_rgb
    return gain


def atmosphere(lighting: Lighting, rgb: F64, range_m: F64) -> F64:
    """Haze towards the fog/horizon colour by ``exp(-sigma r)``, and rain's contrast loss.

    ``rgb`` (..., 3), ``range_m`` (...) the distance along the line of sight [m].
    """
    transmission = np.exp(-lighting.extinction_per_m * range_m)[..., None]
    out: F64 = rgb * transmission + lighting.haze_rgb * (1.0 - transmission)
    if lighting.rain_contrast > 0.0:
        out = out * (1.0 - lighting.rain_contrast) + lighting.rain_contrast * 128.0
    return out
