"""The 3D scene every sensor model sees: a list of oriented boxes on a flat ground.

One description serves all sensors: the LiDAR ray-casts the boxes' triangles, the camera shades
and rasterises their faces, the radar takes vehicle boxes as targets. A box is the unit because
everything on a work-zone approach is well described by a few of them: a car is a lower body
and a cabin, a semi-trailer truck a tractor and a trailer, a drum a short upright box, a
guardrail a run of thin boxes. Ground and lane markings are flat (z = 0) polygons.

Frames: all positions are in the site frame (ENU metres); a box's yaw is counter-clockwise from
the site x axis, its length along that heading.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import numpy.typing as npt


class Material(IntEnum):
    """Surface kinds: each sensor maps them to its own response (reflectivity, colour, RCS)."""

    ASPHALT = 0
    MARKING = 1  # retroreflective paint
    GRASS = 2
    CAR_PAINT = 3
    GLASS = 4
    TIRE = 5
    TRUCK_BODY = 6
    LIGHT = 7  # head/tail lamps
    DRUM = 8  # orange-and-white channelizing drum (retroreflective bands)
    CONCRETE = 9  # barrier
    SIGN = 10  # retroreflective sign face
    METAL = 11  # guardrail, poles, trailer, mast
    VEGETATION = 12


#: Label of static scene parts (vehicles get 1, 2, ... in the order of the frame's truth).
STATIC_LABEL = 0


@dataclass(frozen=True)
class Box:
    """An oriented box standing on (or above) the ground.

    Attributes
    ----------
    center_xyz_m
        Centre of the box in the site frame [m], shape (3,).
    size_lwh_m
        Length (along ``yaw_rad``), width and height [m], shape (3,).
    yaw_rad
        Heading of the length axis, counter-clockwise from the site x axis [rad].
    material
        What the surface is made of.
    color_rgb
        Base colour for the camera, 0-255.
    label
        ``STATIC_LABEL`` for the scene, else the 1-based index of the vehicle in the frame's truth.
    """

    center_xyz_m: tuple[float, float, float]
    size_lwh_m: tuple[float, float, float]
    yaw_rad: float
    material: Material
    color_rgb: tuple[int, int, int]
    label: int = STATIC_LABEL

    def corners(self) -> npt.NDArray[np.float64]:
        """The 8 corners in the site frame, shape (8, 3).

        Order: bottom face (-l,-w), (+l,-w), (+l,+w), (-l,+w), then the top face in the same
        order (half sizes, in the box frame before rotation).
        """
        half_l, half_w, half_h = (0.5 * s for s in self.size_lwh_m)
        local = np.array(
            [
                [-half_l, -half_w, -half_h],
                [half_l, -half_w, -half_h],
                [half_l, half_w, -half_h],
                [-half_l, half_w, -half_h],
                [-half_l, -half_w, half_h],
                [half_l, -half_w, half_h],
                [half_l, half_w, half_h],
                [-half_l, half_w, half_h],
            ]
        )
        cos_yaw, sin_yaw = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        rotation = np.array([[cos_yaw, -sin_yaw, 0.0], [sin_yaw, cos_yaw, 0.0], [0.0, 0.0, 1.0]])
        return local @ rotation.T + np.asarray(self.center_xyz_m)


#: Faces of a box as corner indices, counter-clockwise seen from outside: bottom, top, then the
#: sides -w (right), +l (front), +w (left), -l (back).
BOX_FACES: tuple[tuple[int, int, int, int], ...] = (
    (0, 3, 2, 1),
    (4, 5, 6, 7),
    (0, 1, 5, 4),
    (1, 2, 6, 5),
    (2, 3, 7, 6),
    (3, 0, 4, 7),
)


@dataclass(frozen=True)
class GroundPolygon:
    """A flat polygon on the ground (z = 0): road surface, shoulder, lane marking, grass."""

    vertices_xy_m: npt.NDArray[np.float64]  # (N, 2), counter-clockwise
    material: Material
    color_rgb: tuple[int, int, int]


class Light(IntEnum):
    DAY = 0
    DUSK = 1


@dataclass(frozen=True)
class Weather:
    """Conditions every sensor model reads.

    Attributes
    ----------
    light
        Day or dusk (the camera darkens, lamps glow; LiDAR and radar do not care).
    rain_mm_per_h
        Rain rate [mm/h]: LiDAR extinction and spurious near returns, camera streaks and
        contrast loss, a little radar clutter.
    fog_visibility_m
        Meteorological visibility [m] (``inf`` when clear): LiDAR extinction coefficient
        3.912 / visibility (Koschmieder), camera haze towards the fog colour.
    """

    light: Light = Light.DAY
    rain_mm_per_h: float = 0.0
    fog_visibility_m: float = float("inf")

    @property
    def name(self) -> str:
        parts = ["dusk" if self.light == Light.DUSK else "day"]
        if self.rain_mm_per_h > 0:
            parts.append("rain")
        if np.isfinite(self.fog_visibility_m):
            parts.append("fog")
        return "-".join(parts)


#: Named presets for settings, datasets and tests.
WEATHER_PRESETS: dict[str, Weather] = {
    "day": Weather(),
    "dusk": Weather(light=Light.DUSK),
    "rain": Weather(rain_mm_per_h=8.0),
    "fog": Weather(fog_visibility_m=150.0),
}
