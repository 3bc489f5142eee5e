"""A roadside pinhole camera: projection, back-projection, and frames a detector can learn from.

Two parts, both pure (no bus, no files):

- :class:`PinholeCamera`: the geometry, defined in :mod:`wz_shared.camera_geometry` (so the
  camera detector ranges with it without depending on the simulator) and re-exported here with
  :func:`backproject_to_ground`, :func:`paper_pixel_angles` and
  :func:`paper_flat_road_ground_point`. The renderer draws with the ideal pinhole (no lens
  distortion).
- :class:`CameraModel`: the renderer. Sky, ground polygons and static boxes are drawn once into
  a background image and depth buffer (the camera does not move); each frame draws only the
  vehicles' boxes, shaded by the sun, far to near (painter's algorithm on faces, faces clipped
  in 3D at the near plane), with windows, wheels, lamps and a little texture, then weather and
  sensor effects. Each frame carries truth labels (2D box, class, visibility) from an id buffer.

Frames and pixels
-----------------
- Site frame: ENU metres. Sensor frame (the mount's pose): x forward, y left, z up.
- Camera (optical) frame: z forward along the optical axis, x right, y down;
  ``p_optical = (-y_sensor, -z_sensor, x_sensor)``.
- Continuous pixel coordinates ``(u, v)``: the image spans ``[0, W] x [0, H]``, ``u`` to the
  right and ``v`` down; pixel (row ``i``, column ``j``) covers ``[j, j + 1) x [i, i + 1)`` and its
  centre is ``(j + 0.5, i + 0.5)``. The principal point is the image centre ``(W / 2, H / 2)``,
  as in the paper's Eq. 1. Truth boxes use the same coordinates (pixel edges).
- Depth: the optical z of a point [m] (distance along the optical axis, not the range).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import IntEnum
from functools import cached_property
from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

# Re-exported (``X as X``): the geometry moved to the shared library, its names stay here.
from wz_shared.camera_geometry import LensDistortion as LensDistortion
from wz_shared.camera_geometry import PinholeCamera as PinholeCamera
from wz_shared.camera_geometry import backproject_to_ground as backproject_to_ground
from wz_shared.camera_geometry import paper_flat_road_ground_point as paper_flat_road_ground_point
from wz_shared.camera_geometry import paper_pixel_angles as paper_pixel_angles
from wz_shared.messages import VehicleClass
from wz_shared.site import SensorMount
from wz_simulator.sensors.scene import (
    BOX_CORNER_SIGNS,
    BOX_FACES,
    Box,
    GroundPolygon,
    Light,
    Material,
    Weather,
)

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]
U8 = npt.NDArray[np.uint8]
I16 = npt.NDArray[np.int16]
I32 = npt.NDArray[np.int32]
IntP = npt.NDArray[np.intp]
BoolA = npt.NDArray[np.bool_]

#: Koschmieder's constant: contrast falls to 2 % at the meteorological visibility.
KOSCHMIEDER = 3.912

_SHIFT = 4  # fractional bits of the fixed-point vertices handed to OpenCV
_ONE = float(1 << _SHIFT)

_FACE_CORNERS = np.array(BOX_FACES, dtype=np.intp)  # (6, 4)
FACE_BOTTOM, FACE_TOP, FACE_RIGHT, FACE_FRONT, FACE_LEFT, FACE_BACK = range(6)

# --- scene geometry in arrays ------------------------------------------------------------------


@dataclass(frozen=True)
class _BoxArrays:
    """Boxes as arrays (B = number of boxes)."""

    centers: F64  # (B, 3) [m]
    sizes: F64  # (B, 3) length, width, height [m]
    yaws: F64  # (B,) [rad]
    materials: IntP  # (B,)
    colors_rgb: F64  # (B, 3) 0-255
    labels: IntP  # (B,)

    @classmethod
    def from_boxes(cls, boxes: Sequence[Box]) -> _BoxArrays:
        count = len(boxes)
        return cls(
            centers=np.array([b.center_xyz_m for b in boxes], dtype=np.float64).reshape(count, 3),
            sizes=np.array([b.size_lwh_m for b in boxes], dtype=np.float64).reshape(count, 3),
            yaws=np.array([b.yaw_rad for b in boxes], dtype=np.float64),
            materials=np.array([int(b.material) for b in boxes], dtype=np.intp),
            colors_rgb=np.array([b.color_rgb for b in boxes], dtype=np.float64).reshape(count, 3),
            labels=np.array([b.label for b in boxes], dtype=np.intp),
        )

    def take(self, order: IntP) -> _BoxArrays:
        return _BoxArrays(
            self.centers[order],
            self.sizes[order],
            self.yaws[order],
            self.materials[order],
            self.colors_rgb[order],
            self.labels[order],
        )

    def axes(self) -> tuple[F64, F64]:
        """Length (heading) and width axes in the site frame, shape (B, 3) each."""
        cos_yaw, sin_yaw = np.cos(self.yaws), np.sin(self.yaws)
        zeros = np.zeros_like(cos_yaw)
        return (
            np.stack([cos_yaw, sin_yaw, zeros], axis=1),
            np.stack([-sin_yaw, cos_yaw, zeros], axis=1),
        )

    def corners(self) -> F64:
        """Corners as :meth:`Box.corners` for all boxes at once, shape (B, 8, 3)."""
        local = 0.5 * BOX_CORNER_SIGNS[None, :, :] * self.sizes[:, None, :]
        ex, ey = self.axes()
        corners: F64 = (
            local[:, :, 0:1] * ex[:, None, :]
            + local[:, :, 1:2] * ey[:, None, :]
            + local[:, :, 2:3] * np.array([0.0, 0.0, 1.0])
            + self.centers[:, None, :]
        )
        return corners

    def face_quads(self) -> tuple[F64, F64]:
        """Face corners, shape (B, 6, 4, 3), and outward unit normals, shape (B, 6, 3)."""
        quads: F64 = self.corners()[:, _FACE_CORNERS]
        ex, ey = self.axes()
        ez = np.zeros_like(ex)
        ez[:, 2] = 1.0
        normals = np.stack([-ez, ez, -ey, ex, ey, -ex], axis=1)
        return quads, normals


class DecalKind(IntEnum):
    """Painted-on detail drawn over a face: windows, lamps, grille, plates, bands."""

    WINDOW = 0
    GLARE = 1  # sky reflection on the upper part of a windshield
    GRILLE = 2
    HEADLAMP = 3
    TAILLAMP = 4
    PLATE = 5
    BAND = 6  # bumper, rocker panel, underride guard
    SEAM = 7  # door line of a trailer
    STRIPE = 8  # retroreflective band of a drum


_LAMP_KINDS = (int(DecalKind.HEADLAMP), int(DecalKind.TAILLAMP))
_WINDOW_KINDS = (int(DecalKind.WINDOW), int(DecalKind.GLARE))
# Base colours (RGB) of decals by day; lamps glow at dusk.
_DECAL_RGB = np.array(
    [
        [38.0, 48.0, 58.0],  # window
        [120.0, 140.0, 160.0],  # glare
        [34.0, 34.0, 37.0],  # grille
        [215.0, 215.0, 205.0],  # headlamp
        [150.0, 22.0, 22.0],  # taillamp
        [225.0, 225.0, 215.0],  # plate
        [48.0, 48.0, 52.0],  # band
        [28.0, 28.0, 30.0],  # seam
        [235.0, 235.0, 235.0],  # stripe
    ]
)
_LAMP_GLOW_RGB = {
    int(DecalKind.HEADLAMP): (255.0, 248.0, 225.0),
    int(DecalKind.TAILLAMP): (255.0, 35.0, 25.0),
}

# Decal templates: (face, s0, s1, t0, t1, kind). s runs along the face's bottom edge (for the
# sides, from the box's -l end to +l on the right face and from +l to -l on the left face), t
# from the bottom up; both in [0, 1].
_W, _G, _GR, _HL, _TL, _PL, _BD, _SM, _ST = (int(k) for k in DecalKind)
_ROLE_LOWER_BODY = np.array(
    [
        (FACE_FRONT, 0.0, 1.0, 0.0, 0.22, _BD),
        (FACE_FRONT, 0.28, 0.72, 0.38, 0.72, _GR),
        (FACE_FRONT, 0.4, 0.6, 0.06, 0.3, _PL),
        (FACE_FRONT, 0.04, 0.22, 0.55, 0.85, _HL),
        (FACE_FRONT, 0.78, 0.96, 0.55, 0.85, _HL),
        (FACE_BACK, 0.0, 1.0, 0.0, 0.22, _BD),
        (FACE_BACK, 0.4, 0.6, 0.3, 0.58, _PL),
        (FACE_BACK, 0.04, 0.2, 0.5, 0.85, _TL),
        (FACE_BACK, 0.8, 0.96, 0.5, 0.85, _TL),
        (FACE_RIGHT, 0.0, 1.0, 0.0, 0.2, _BD),
        (FACE_LEFT, 0.0, 1.0, 0.0, 0.2, _BD),
    ]
)
_ROLE_CABIN = np.array(
    [
        (FACE_FRONT, 0.06, 0.94, 0.1, 0.92, _W),
        (FACE_FRONT, 0.06, 0.94, 0.66, 0.92, _G),
        (FACE_BACK, 0.08, 0.92, 0.14, 0.88, _W),
        (FACE_BACK, 0.08, 0.92, 0.64, 0.88, _G),
        (FACE_RIGHT, 0.06, 0.47, 0.1, 0.88, _W),
        (FACE_RIGHT, 0.53, 0.94, 0.1, 0.88, _W),
        (FACE_LEFT, 0.06, 0.47, 0.1, 0.88, _W),
        (FACE_LEFT, 0.53, 0.94, 0.1, 0.88, _W),
    ]
)
_ROLE_FRONT_UNIT = np.array(
    [
        (FACE_FRONT, 0.06, 0.94, 0.58, 0.9, _W),
        (FACE_FRONT, 0.06, 0.94, 0.78, 0.9, _G),
        (FACE_FRONT, 0.25, 0.75, 0.1, 0.45, _GR),
        (FACE_FRONT, 0.03, 0.18, 0.1, 0.24, _HL),
        (FACE_FRONT, 0.82, 0.97, 0.1, 0.24, _HL),
        (FACE_FRONT, 0.42, 0.58, 0.02, 0.09, _PL),
        (FACE_RIGHT, 0.64, 0.95, 0.58, 0.88, _W),
        (FACE_LEFT, 0.05, 0.36, 0.58, 0.88, _W),
    ]
)
_ROLE_REAR_UNIT = np.array(
    [
        (FACE_BACK, 0.0, 1.0, 0.0, 0.07, _BD),
        (FACE_BACK, 0.495, 0.505, 0.1, 0.97, _SM),
        (FACE_BACK, 0.03, 0.15, 0.09, 0.2, _TL),
        (FACE_BACK, 0.85, 0.97, 0.09, 0.2, _TL),
        (FACE_BACK, 0.42, 0.58, 0.09, 0.2, _PL),
        (FACE_RIGHT, 0.0, 1.0, 0.0, 0.05, _BD),
        (FACE_LEFT, 0.0, 1.0, 0.0, 0.05, _BD),
    ]
)
_ROLE_DRUM = np.array(
    [(face, 0.0, 1.0, t0, t0 + 0.14, _ST) for face in range(2, 6) for t0 in (0.22, 0.55)]
)
ROLE_LOWER_BODY, ROLE_CABIN, ROLE_FRONT_UNIT, ROLE_REAR_UNIT, ROLE_DRUM = 1, 2, 4, 8, 16
_ROLE_TEMPLATES = (
    (ROLE_LOWER_BODY, _ROLE_LOWER_BODY),
    (ROLE_CABIN, _ROLE_CABIN),
    (ROLE_FRONT_UNIT, _ROLE_FRONT_UNIT),
    (ROLE_REAR_UNIT, _ROLE_REAR_UNIT),
    (ROLE_DRUM, _ROLE_DRUM),
)
# Draw layers inside a group (a base box and what belongs to it).
_LAYER_WHEEL, _LAYER_BASE, _LAYER_STACKED, _LAYER_ATTACHED = 0, 1, 2, 3
_THIN_M = 0.15  # a GLASS or LIGHT box thinner than this is a panel on a body
_TIRE, _GLASS, _LIGHT = int(Material.TIRE), int(Material.GLASS), int(Material.LIGHT)


@dataclass(frozen=True)
class _Quads:
    """Faces and decals to draw (Q quads), with what the shader and the sorter need."""

    site: F64  # (Q, 4, 3) corners [m]
    normal: F64  # (Q, 3) outward unit normal
    base_rgb: F64  # (Q, 3) 0-255
    kind: IntP  # (Q,) DecalKind, or -1 for a box face
    face: IntP  # (Q,) index of the (parent) face in the B * 6 faces
    sub: IntP  # (Q,) 0 for a face, 1.. for its decals in drawing order


def _decal_quads(parent: F64, spec: F64) -> F64:
    """Decal corners on parent faces by bilinear interpolation.

    ``parent`` (D, 4, 3) is (a, b, c, d) with a -> b the bottom edge and d -> c the top edge;
    ``spec`` (D, 4) is (s0, s1, t0, t1). Returns (D, 4, 3), wound like the parent.
    """
    a, b, c, d = parent[:, 0], parent[:, 1], parent[:, 2], parent[:, 3]

    def point(s: F64, t: F64) -> F64:
        s2, t2 = s[:, None], t[:, None]
        result: F64 = (1.0 - t2) * ((1.0 - s2) * a + s2 * b) + t2 * ((1.0 - s2) * d + s2 * c)
        return result

    s0, s1, t0, t1 = spec[:, 0], spec[:, 1], spec[:, 2], spec[:, 3]
    return np.stack([point(s0, t0), point(s1, t0), point(s1, t1), point(s0, t1)], axis=1)


def _build_quads(
    arrays: _BoxArrays, face_rgb: F64, roles: IntP, decal_filter: BoolA | None = None
) -> _Quads:
    """Box faces (B * 6, box-major) followed by the decals of each box's roles.

    ``face_rgb`` (B, 6, 3) gives each face's base colour; ``roles`` (B,) the decal roles;
    ``decal_filter`` (B, n_kinds) allows a decal kind on a box (None: all).
    """
    quads, normals = arrays.face_quads()
    count = quads.shape[0]
    face_site = quads.reshape(count * 6, 4, 3)
    face_normal = normals.reshape(count * 6, 3)
    parts_box: list[IntP] = []
    parts_spec: list[F64] = []
    for role, template in _ROLE_TEMPLATES:
        boxes = np.flatnonzero(roles & role)
        if boxes.size == 0:
            continue
        parts_box.append(np.repeat(boxes, template.shape[0]))
        parts_spec.append(np.tile(template, (boxes.size, 1)))
    if parts_box:
        decal_box = np.concatenate(parts_box)
        spec = np.concatenate(parts_spec)
        decal_kind = spec[:, 5].astype(np.intp)
        if decal_filter is not None:
            keep = decal_filter[decal_box, decal_kind]
            decal_box, spec, decal_kind = decal_box[keep], spec[keep], decal_kind[keep]
        decal_face = decal_box * 6 + spec[:, 0].astype(np.intp)
        decal_site = _decal_quads(face_site[decal_face], spec[:, 1:5])
        # Decals of one face keep their template order; sub numbers them 1, 2, ...
        order = np.argsort(decal_face, kind="stable")
        decal_face, decal_site, decal_kind = decal_face[order], decal_site[order], decal_kind[order]
        starts = np.r_[0, np.flatnonzero(np.diff(decal_face)) + 1]
        run = np.arange(decal_face.size) - np.repeat(
            starts, np.diff(np.r_[starts, decal_face.size])
        )
        decal_sub = run + 1
    else:
        decal_face = np.zeros(0, dtype=np.intp)
        decal_site = np.zeros((0, 4, 3))
        decal_kind = np.zeros(0, dtype=np.intp)
        decal_sub = np.zeros(0, dtype=np.intp)
    face_index = np.arange(count * 6, dtype=np.intp)
    return _Quads(
        site=np.concatenate([face_site, decal_site]),
        normal=np.concatenate([face_normal, face_normal[decal_face]]),
        base_rgb=np.concatenate([face_rgb.reshape(count * 6, 3), _DECAL_RGB[decal_kind]]),
        kind=np.concatenate([np.full(count * 6, -1, dtype=np.intp), decal_kind]),
        face=np.concatenate([face_index, decal_face]),
        sub=np.concatenate([np.zeros(count * 6, dtype=np.intp), decal_sub]),
    )


# --- light and weather --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Lighting:
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


def _lighting(weather: Weather) -> _Lighting:
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
    return _Lighting(
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


def _shade(lighting: _Lighting, normals: F64) -> F64:
    """Lambert + hemispheric ambient: per-channel gain for surfaces with these normals.

    ``gain = ambient (0.75 + 0.25 n_z) + sun_rgb max(0, n . s)``; shape (..., 3).
    """
    lambert = np.clip(normals @ lighting.sun_direction, 0.0, None)
    ambient = lighting.ambient * (0.75 + 0.25 * normals[..., 2])
    gain: F64 = ambient[..., None] + lambert[..., None] * lighting.sun_rgb
    return gain


def _atmosphere(lighting: _Lighting, rgb: F64, range_m: F64) -> F64:
    """Haze towards the fog/horizon colour by ``exp(-sigma r)``, and rain's contrast loss.

    ``rgb`` (..., 3), ``range_m`` (...) the distance along the line of sight [m].
    """
    transmission = np.exp(-lighting.extinction_per_m * range_m)[..., None]
    out: F64 = rgb * transmission + lighting.haze_rgb * (1.0 - transmission)
    if lighting.rain_contrast > 0.0:
        out = out * (1.0 - lighting.rain_contrast) + lighting.rain_contrast * 128.0
    return out


# --- clipping and projection -------------------------------------------------------------------


def _clip_polygon(polygon: F64, planes: F64) -> F64:
    """Sutherland-Hodgman clip of a convex polygon (n, 3) to half-spaces ``a . p + d >= 0``.

    ``planes`` is (P, 4) rows (a_x, a_y, a_z, d). Returns (m, 3), m = 0 when nothing is left.
    """
    points = polygon
    for plane in planes:
        if points.shape[0] == 0:
            break
        dist = points @ plane[:3] + plane[3]
        inside = dist >= 0.0
        if inside.all():
            continue
        if not inside.any():
            return np.zeros((0, 3))
        out: list[F64] = []
        count = points.shape[0]
        for i in range(count):
            j = (i + 1) % count
            if inside[i]:
                out.append(points[i])
            if inside[i] != inside[j]:
                t = dist[i] / (dist[i] - dist[j])
                out.append(points[i] + t * (points[j] - points[i]))
        points = np.array(out) if out else np.zeros((0, 3))
    return points


@dataclass(frozen=True)
class _Projected:
    """Quads as OpenCV fixed-point polygons (pixel-centre origin), or None where nothing shows."""

    polygons: list[I32 | None]
    bounds: I32  # (Q, 4) x0, y0, x1, y1 pixel indices (inclusive), meaningless where None


@dataclass(frozen=True, slots=True)
class CameraTruthLabel:
    """Truth for one vehicle in one frame.

    Attributes
    ----------
    vehicle_id
        The vehicle's id in the frame's truth.
    index
        0-based index in the frame's vehicle list (the id buffer's value; box label - 1).
    vehicle_class
        Car, truck, ...
    box_xyxy_px
        Box of the visible pixels ``(x0, y0, x1, y1)`` in continuous pixel coordinates (pixel
        edges, inside ``[0, W] x [0, H]``); None when no pixel is visible.
    full_box_xyxy_px
        Box of the unoccluded silhouette, clipped to the image; None when outside the image.
    visible_pixels
        Pixels where this vehicle is the nearest surface.
    silhouette_pixels
        Pixels of the vehicle rendered alone (inside the image).
    """

    vehicle_id: str
    index: int
    vehicle_class: VehicleClass
    box_xyxy_px: tuple[float, float, float, float] | None
    full_box_xyxy_px: tuple[float, float, float, float] | None
    visible_pixels: int
    silhouette_pixels: int

    @property
    def visibility(self) -> float:
        """``visible_pixels / silhouette_pixels`` (0 when the silhouette is empty)."""
        if self.silhouette_pixels <= 0:
            return 0.0
        return self.visible_pixels / self.silhouette_pixels


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One rendered frame with its truth.

    Attributes
    ----------
    stamp
        Capture time [s].
    image
        BGR image, uint8, shape (H, W, 3).
    labels
        One label per vehicle passed to :meth:`CameraModel.render`, in that order.
    face_buffer
        Index of the vehicle face seen at each pixel (-1: none), shape (H, W); see
        :attr:`id_buffer` for vehicles.
    face_vehicle
        0-based vehicle index of each face, shape (F,).
    """

    stamp: float
    image: U8
    labels: tuple[CameraTruthLabel, ...]
    face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32]
    face_vehicle: I16

    @cached_property
    def id_buffer(self) -> I16:
        """0-based index of the vehicle seen at each pixel, -1 where none; int16 (H, W)."""
        lookup = np.append(self.face_vehicle, np.int16(-1)).astype(np.int16)
        ids: I16 = lookup[self.face_buffer]  # face -1 picks the appended -1
        return ids


class StaticSceneLike(Protocol):
    """The static scene as the scene module builds it: boxes and ground polygons."""

    @property
    def boxes(self) -> Sequence[Box]: ...

    @property
    def ground(self) -> Sequence[GroundPolygon]: ...


def _mask_box(mask: U8, x0: int, y0: int) -> tuple[float, float, float, float]:
    """Pixel-edge box ``(x0, y0, x1, y1)`` of a mask's non-zero pixels, offset by (x0, y0)."""
    x, y, w, h = cv2.boundingRect(mask)
    return (float(x0 + x), float(y0 + y), float(x0 + x + w), float(y0 + y + h))


def _vehicle_class_guess(materials: IntP, sizes: F64) -> VehicleClass:
    if (materials == Material.TRUCK_BODY).any() or float(sizes[:, 0].max()) > 7.5:
        return VehicleClass.TRUCK
    return VehicleClass.CAR


class CameraModel:
    """Renders camera frames of vehicles in front of a fixed, pre-rendered background.

    Parameters
    ----------
    mount
        The camera's mount (pose, intrinsics).
    static_boxes
        Static scene boxes (drums, signs, barriers, guardrail, trailer...), site frame.
    static_ground
        Ground polygons (z = 0), drawn in order (later over earlier); the rest of the ground is
        terrain.
    weather
        Light, rain and fog.
    seed
        Seed of the sensor noise and rain streaks; the same seed and calls give the same frames.
    blur_sigma_px
        Optical blur (Gaussian sigma [px]); 0 for none.
    motion_blur_px
        Length of a horizontal motion blur [px] (mast sway, long exposure); 0 for none.
    noise_std
        Gaussian read noise [digital numbers]; None for the weather's default (2 by day,
        5 at dusk).
    near_m
        Near clipping plane [m].
    """

    def __init__(
        self,
        mount: SensorMount,
        static_boxes: Sequence[Box],
        static_ground: Sequence[GroundPolygon],
        weather: Weather | None = None,
        seed: int = 0,
        *,
        blur_sigma_px: float = 0.6,
        motion_blur_px: float = 0.0,
        noise_std: float | None = None,
        near_m: float = 0.05,
    ) -> None:
        self.camera = PinholeCamera(mount)
        self.weather = weather if weather is not None else Weather()
        self.blur_sigma_px = blur_sigma_px
        self.motion_blur_px = motion_blur_px
        self.near_m = near_m
        self._lighting = _lighting(self.weather)
        if noise_std is not None:
            self._lighting = replace(self._lighting, noise_std=noise_std)
        self._rng = np.random.default_rng(seed)
        cam = self.camera
        width, height = cam.width_px, cam.height_px
        f, cx, cy = cam.focal_px, cam.cx_px, cam.cy_px
        # Clip planes in the optical frame (a . p + d >= 0): near plane, then a guard band of
        # one image size around the image so fixed-point vertices stay small.
        u_min, u_max, v_min, v_max = -width, 2.0 * width, -height, 2.0 * height
        self._clip_planes = np.array(
            [
                [0.0, 0.0, 1.0, -near_m],
                [f, 0.0, cx - u_min, 0.0],
                [-f, 0.0, u_max - cx, 0.0],
                [0.0, f, cy - v_min, 0.0],
                [0.0, -f, v_max - cy, 0.0],
            ]
        )
        # Per-pixel rays (unit optical depth) at pixel centres.
        self._ray_x = ((np.arange(width) + 0.5 - cx) / f).astype(np.float32)
        self._ray_y = ((np.arange(height) + 0.5 - cy) / f).astype(np.float32)
        self._background, self._static_box_depth = self._render_background(
            list(static_boxes), list(static_ground)
        )
        if blur_sigma_px > 0.0:
            cv2.GaussianBlur(self._background, (3, 3), blur_sigma_px, dst=self._background)
        self._static_mask = np.isfinite(self._static_box_depth).astype(np.uint8)
        self._static_integral = cv2.integral(self._static_mask)
        self._silhouette_scratch = np.zeros((height, width), dtype=np.uint8)
        self._noise_pad = 32
        self._noise_pos, self._noise_neg = self._noise_bank()
        self._rain_layers = self._rain_streak_layers()
        self._glow_cache: dict[tuple[int, int], U8] = {}

    @classmethod
    def from_scene(
        cls,
        mount: SensorMount,
        scene: StaticSceneLike,
        weather: Weather | None = None,
        seed: int = 0,
    ) -> CameraModel:
        """A model over a static scene with ``boxes`` and ``ground`` (e.g. ``static_scene``)."""
        return cls(mount, scene.boxes, scene.ground, weather, seed)

    @property
    def background(self) -> U8:
        """The pre-rendered static background (BGR, before sensor effects), (H, W, 3)."""
        return self._background

    @property
    def static_box_depth(self) -> F32:
        """Optical depth [m] of the nearest static box at each pixel (inf: none), (H, W)."""
        return self._static_box_depth

    # --- projection of quads -----------------------------------------------------------------

    def _project_quads(self, quads_site: F64, drawable: BoolA) -> _Projected:
        """Clip (in 3D, where needed) and project quads (Q, 4, 3) to fixed-point polygons."""
        cam = self.camera
        width, height = cam.width_px, cam.height_px
        camera = self.camera.site_to_camera(quads_site)  # (Q, 4, 3)
        z = camera[..., 2]
        planes = self._clip_planes
        # a . p + d for every plane and vertex: clean quads need no clipping.
        plane_dist = camera @ planes[:, :3].T + planes[:, 3]  # (Q, 4, P)
        clean = (plane_dist >= 0.0).all(axis=(1, 2))
        safe_z = np.where(clean[:, None], z, 1.0)
        u = cam.cx_px + cam.focal_px * camera[..., 0] / safe_z
        v = cam.cy_px + cam.focal_px * camera[..., 1] / safe_z
        # Whole quads off one side of the image show nothing.
        offscreen = (
            (u.max(axis=1) < 0)
            | (u.min(axis=1) > width)
            | (v.max(axis=1) < 0)
            | (v.min(axis=1) > height)
        )
        fixed = np.empty((*u.shape, 2), dtype=np.int32)
        fixed[..., 0] = np.rint((u - 0.5) * _ONE)
        fixed[..., 1] = np.rint((v - 0.5) * _ONE)
        bounds = np.empty((quads_site.shape[0], 4), dtype=np.int32)
        bounds[:, 0] = np.floor(u.min(axis=1) - 0.5)
        bounds[:, 1] = np.floor(v.min(axis=1) - 0.5)
        bounds[:, 2] = np.ceil(u.max(axis=1) - 0.5)
        bounds[:, 3] = np.ceil(v.max(axis=1) - 0.5)
        show = drawable & clean & ~offscreen
        polygons: list[I32 | None] = [None] * quads_site.shape[0]
        for q in np.flatnonzero(show).tolist():
            polygons[q] = fixed[q]
        # Quads crossing the near plane or the guard band: clip in 3D, then project.
        fully_out = (plane_dist < 0.0).all(axis=1).any(axis=1)
        for q in np.flatnonzero(drawable & ~clean & ~fully_out).tolist():
            clipped = _clip_polygon(camera[q], planes)
            if clipped.shape[0] < 3:
                continue
            uq = cam.cx_px + cam.focal_px * clipped[:, 0] / clipped[:, 2]
            vq = cam.cy_px + cam.focal_px * clipped[:, 1] / clipped[:, 2]
            if uq.max() < 0 or uq.min() > width or vq.max() < 0 or vq.min() > height:
                continue
            pts = np.empty((uq.size, 2), dtype=np.int32)
            pts[:, 0] = np.rint((uq - 0.5) * _ONE)
            pts[:, 1] = np.rint((vq - 0.5) * _ONE)
            polygons[q] = pts
            bounds[q] = (
                math.floor(uq.min() - 0.5),
                math.floor(vq.min() - 0.5),
                math.ceil(uq.max() - 0.5),
                math.ceil(vq.max() - 0.5),
            )
        np.clip(bounds[:, 0::2], 0, width - 1, out=bounds[:, 0::2])
        np.clip(bounds[:, 1::2], 0, height - 1, out=bounds[:, 1::2])
        return _Projected(polygons, bounds)

    def _front_facing(self, quads: _Quads) -> BoolA:
        centroid = quads.site.mean(axis=1)
        facing: BoolA = np.einsum("qi,qi->q", centroid - self.camera.position_m, quads.normal) < 0.0
        return facing

    def _range_to(self, points_site: F64) -> F64:
        distance: F64 = np.linalg.norm(points_site - self.camera.position_m, axis=-1)
        return distance

    def _face_planes(self, quads_site: F64, normals: F64) -> tuple[F64, F64]:
        """Planes ``n . p = c`` of faces in the optical frame: n (F, 3), c (F,)."""
        normal_cam = normals @ self.camera.rotation_site_from_camera
        offset = np.einsum("fi,fi->f", normal_cam, self.camera.site_to_camera(quads_site[:, 0]))
        return normal_cam, offset

    def _plane_depth(self, normal_cam: F64, offset: F64, rows: IntP, cols: IntP) -> F64:
        """Optical depth of planes at pixel centres: ``z = c / (n . r)``, r = ray of the pixel."""
        denom = (
            normal_cam[:, 0] * self._ray_x[cols]
            + normal_cam[:, 1] * self._ray_y[rows]
            + normal_cam[:, 2]
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = offset / denom
        result: F64 = np.where(denom < -1e-12, depth, np.inf)
        return result

    # --- background ---------------------------------------------------------------------------

    def _render_background(self, boxes: list[Box], ground: list[GroundPolygon]) -> tuple[U8, F32]:
        """Sky, terrain, ground polygons and static boxes with a z-buffer; weather applied."""
        cam = self.camera
        lighting = self._lighting
        width, height = cam.width_px, cam.height_px
        rx = self._ray_x.astype(np.float64)[None, :]
        ry = self._ray_y.astype(np.float64)[:, None]
        rot = cam.rotation_site_from_camera
        dir_z = rot[2, 0] * rx + rot[2, 1] * ry + rot[2, 2]  # site z of the unit-depth ray
        ray_norm = np.sqrt(rx * rx + ry * ry + 1.0)
        elevation = dir_z / ray_norm
        # Sky: horizon colour at and below the horizon, zenith colour overhead.
        blend = np.clip(elevation, 0.0, 1.0) ** 0.6
        rgb = (
            lighting.sky_horizon_rgb * (1.0 - blend)[..., None]
            + lighting.sky_zenith_rgb * blend[..., None]
        )
        # Ground z = 0 where the ray descends: depth t = -C_z / d_z.
        cam_z = float(cam.position_m[2])
        descending = (dir_z < -1e-9) & (cam_z > 0.0)
        ground_depth = np.where(descending, cam_z / np.where(descending, -dir_z, 1.0), np.inf)
        ground_rgb = np.empty((height, width, 3))
        ground_rgb[:] = lighting.terrain_rgb
        material_wet = np.ones((height, width))
        for polygon in ground:
            vertices = np.asarray(polygon.vertices_xy_m, dtype=np.float64)
            if vertices.shape[0] < 3:
                continue
            projected = self._project_polygon(
                np.column_stack([vertices, np.zeros(vertices.shape[0])])
            )
            if projected is None:
                continue
            pts, (x0, y0, x1, y1) = projected
            mask = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
            offset = np.array([x0 << _SHIFT, y0 << _SHIFT], dtype=np.int32)
            cv2.fillPoly(mask, [pts - offset], 1, cv2.LINE_8, _SHIFT)
            inside = mask.astype(bool)
            ground_rgb[y0:y1, x0:x1][inside] = np.asarray(polygon.color_rgb, dtype=np.float64)
            wet = lighting.wet_road if polygon.material == Material.ASPHALT else 1.0
            material_wet[y0:y1, x0:x1][inside] = wet
        # A little texture on the ground (fixed: the camera does not move).
        coarse = self._rng.normal(0.0, 1.0, (height // 4 + 1, width // 4 + 1))
        smooth = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_LINEAR)
        texture = 1.0 + 0.035 * smooth + 0.02 * self._rng.normal(0.0, 1.0, (height, width))
        up = np.array([0.0, 0.0, 1.0])
        ground_gain = _shade(lighting, up) * material_wet[..., None] * texture[..., None]
        rgb = np.where(descending[..., None], ground_rgb * ground_gain, rgb)
        depth = ground_depth.copy()
        box_depth = np.full((height, width), np.inf)
        if boxes:
            self._rasterise_static_boxes(boxes, rgb, box_depth)
        depth = np.minimum(depth, box_depth)
        range_m = depth * ray_norm
        sky = ~np.isfinite(depth)
        hazed = _atmosphere(lighting, rgb, np.where(sky, 0.0, range_m))
        if lighting.foggy:
            hazed[sky] = _atmosphere(lighting, rgb[sky], np.full(int(sky.sum()), np.inf))
        image = np.clip(hazed[..., ::-1], 0.0, 255.0).astype(np.uint8)
        return np.ascontiguousarray(image), box_depth.astype(np.float32)

    def _rasterise_static_boxes(self, boxes: list[Box], rgb: F64, box_depth: F64) -> None:
        """Z-buffered static boxes (exact per-pixel plane depth) into ``rgb`` and ``box_depth``."""
        arrays = _BoxArrays.from_boxes(boxes)
        count = len(boxes)
        roles = np.where(arrays.materials == Material.DRUM, ROLE_DRUM, 0).astype(np.intp)
        face_rgb = np.repeat(arrays.colors_rgb[:, None, :], 6, axis=1)
        quads = _build_quads(arrays, face_rgb, roles)
        facing = self._front_facing(quads)
        projected = self._project_quads(quads.site, facing)
        gain = _shade(self._lighting, quads.normal)
        emissive = (arrays.materials == Material.LIGHT)[quads.face // 6]
        colour = np.where(emissive[:, None], quads.base_rgb, quads.base_rgb * gain)
        normal_cam, offset = self._face_planes(quads.site[: count * 6], quads.normal[: count * 6])
        for q, pts in enumerate(projected.polygons):
            if pts is None:
                continue
            x0, y0, x1, y1 = (int(b) for b in projected.bounds[q])
            if x1 < x0 or y1 < y0:
                continue
            mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), dtype=np.uint8)
            shifted = pts - np.array([x0 << _SHIFT, y0 << _SHIFT], dtype=np.int32)
            cv2.fillConvexPoly(mask, shifted, 1, cv2.LINE_8, _SHIFT)
            rows, cols = np.nonzero(mask)
            if rows.size == 0:
                continue
            rows += y0
            cols += x0
            face = int(quads.face[q])
            depth = self._plane_depth(
                normal_cam[face : face + 1], offset[face : face + 1], rows, cols
            )
            current = box_depth[rows, cols]
            # A decal lies on its face: it wins where that face (or anything as near) is seen.
            nearer = depth <= current + 1e-3 if quads.kind[q] >= 0 else depth < current
            rows, cols = rows[nearer], cols[nearer]
            box_depth[rows, cols] = depth[nearer]
            rgb[rows, cols] = colour[q]

    # --- sensor effects ----------------------------------------------------------------------

    def _noise_bank(self) -> tuple[U8, U8]:
        """Positive and negative parts of a Gaussian noise field larger than the image."""
        shape = (
            self.camera.height_px + self._noise_pad,
            self.camera.width_px + self._noise_pad,
            3,
        )
        std = self._lighting.noise_std
        if std <= 0.0:
            zeros = np.zeros(shape, dtype=np.uint8)
            return zeros, zeros
        noise = self._rng.normal(0.0, std, shape).astype(np.float32)
        positive = np.clip(np.rint(noise), 0, 255).astype(np.uint8)
        negative = np.clip(np.rint(-noise), 0, 255).astype(np.uint8)
        return positive, negative

    def _rain_streak_layers(self) -> list[U8]:
        """A few pre-drawn layers of rain streaks (added to frames in turn, at random)."""
        rain = self._lighting.rain_mm_per_h
        if rain <= 0.0:
            return []
        width, height = self.camera.width_px, self.camera.height_px
        streaks = int(min(4000, 40.0 * rain * width * height / 1.0e6))
        layers = []
        for _ in range(3):
            layer = np.zeros((height, width, 3), dtype=np.uint8)
            xs = self._rng.uniform(0, width, streaks)
            ys = self._rng.uniform(0, height, streaks)
            lengths = self._rng.uniform(0.012, 0.035, streaks) * height
            angle = math.radians(12.0)
            brightness = self._rng.uniform(18.0, 45.0, streaks)
            for x, y, length, level in zip(xs, ys, lengths, brightness, strict=True):
                end = (int(x + length * math.sin(angle)), int(y + length * math.cos(angle)))
                cv2.line(layer, (int(x), int(y)), end, (level, level, level), 1, cv2.LINE_AA)
            if self.blur_sigma_px > 0.0:
                cv2.GaussianBlur(layer, (3, 3), self.blur_sigma_px, dst=layer)
            layers.append(layer)
        return layers

    def _glow_sprite(self, radius_px: int, kind: int) -> U8:
        key = (radius_px, kind)
        sprite = self._glow_cache.get(key)
        if sprite is None:
            axis = np.arange(-3 * radius_px, 3 * radius_px + 1, dtype=np.float64)
            falloff = np.exp(-(axis[:, None] ** 2 + axis[None, :] ** 2) / (2.0 * radius_px**2))
            colour = np.asarray(_LAMP_GLOW_RGB[kind][::-1])
            sprite = np.clip(falloff[..., None] * colour * 0.85, 0, 255).astype(np.uint8)
            self._glow_cache[key] = sprite
        return sprite

    def _add_glow(self, image: U8, column: int, row: int, size_px: float, kind: int) -> None:
        """Add a lamp's glow sprite centred on pixel (row, column), saturating."""
        radius = int(min(48, max(2, round(0.9 * size_px))))
        sprite = self._glow_sprite(radius, kind)
        half = sprite.shape[0] // 2
        x0, y0 = column - half, row - half
        x1, y1 = x0 + sprite.shape[1], y0 + sprite.shape[0]
        ix0, iy0 = max(x0, 0), max(y0, 0)
        ix1, iy1 = min(x1, image.shape[1]), min(y1, image.shape[0])
        if ix1 <= ix0 or iy1 <= iy0:
            return
        roi = image[iy0:iy1, ix0:ix1]
        cv2.add(roi, sprite[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0], dst=roi)

    def _sensor_effects(self, image: U8) -> None:
        """Rain streaks, motion blur and read noise on a whole frame (in place).

        The optical blur is applied to the background once and to each vehicle's region.
        """
        if self._rain_layers:
            layer = self._rain_layers[int(self._rng.integers(len(self._rain_layers)))]
            cv2.add(image, layer, dst=image)
        if self.motion_blur_px >= 1.0:
            length = round(self.motion_blur_px)
            kernel = np.full((1, length), 1.0 / length, dtype=np.float32)
            cv2.filter2D(image, -1, kernel, dst=image)
        if self._lighting.noise_std > 0.0:
            oy, ox = (int(o) for o in self._rng.integers(0, self._noise_pad, 2))
            height, width = image.shape[:2]
            cv2.add(image, self._noise_pos[oy : oy + height, ox : ox + width], dst=image)
            oy, ox = (int(o) for o in self._rng.integers(0, self._noise_pad, 2))
            cv2.subtract(image, self._noise_neg[oy : oy + height, ox : ox + width], dst=image)

    # --- vehicles -----------------------------------------------------------------------------

    @staticmethod
    def _vehicle_structure(
        arrays: _BoxArrays, starts: IntP, ends: IntP
    ) -> tuple[IntP, IntP, IntP, BoolA, F64]:
        """How each vehicle's boxes fit together, for all vehicles at once.

        Boxes are sorted by label; vehicle ``k`` owns boxes ``starts[k]:ends[k]``.

        A body box standing on another body box of the same vehicle (bottom at the other's top,
        centre over its footprint) is stacked on it (a cabin); wheels (TIRE) and thin GLASS or
        LIGHT panels attach to the vehicle's nearest base. A base carrying a cabin gets
        lower-body decals (bumpers, grille, lamps, plates) and the cabin windows; without cabins
        the front-most base gets a windshield, grille and headlamps and the rear-most base tail
        lamps and a door seam. Automatic windows (lamps) are left out where the vehicle has its
        own GLASS (LIGHT) panels.

        Returns
        -------
        base
            (B,) index of the box whose group each box draws in.
        layer
            (B,) drawing layer inside the group (wheels, base, stacked, panels).
        roles
            (B,) bit mask of decal roles.
        allowed
            (B, number of decal kinds) which decal kinds a box may get.
        body_rgb
            (B, 3) the body colour of each box's vehicle (RGB).
        """
        count = arrays.centers.shape[0]
        index = np.arange(count)
        vehicle = np.repeat(np.arange(starts.size), ends - starts)
        materials = arrays.materials
        thin = arrays.sizes.min(axis=1) < _THIN_M
        tire = materials == _TIRE
        glass_panel = (materials == _GLASS) & thin
        light_panel = (materials == _LIGHT) & thin
        body = ~tire & ~glass_panel & ~light_panel
        bottoms = arrays.centers[:, 2] - 0.5 * arrays.sizes[:, 2]
        tops = arrays.centers[:, 2] + 0.5 * arrays.sizes[:, 2]
        same = vehicle[:, None] == vehicle[None, :]
        # stacked[j, i]: body j stands on body i of the same vehicle.
        rel = arrays.centers[:, None, :2] - arrays.centers[None, :, :2]
        cos_i, sin_i = np.cos(arrays.yaws)[None, :], np.sin(arrays.yaws)[None, :]
        along = np.abs(rel[..., 0] * cos_i + rel[..., 1] * sin_i)
        across = np.abs(-rel[..., 0] * sin_i + rel[..., 1] * cos_i)
        over = (along <= 0.5 * arrays.sizes[None, :, 0] + 0.05) & (
            across <= 0.5 * arrays.sizes[None, :, 1] + 0.05
        )
        stacked = same & over & body[:, None] & body[None, :]
        stacked &= bottoms[:, None] >= tops[None, :] - 0.15
        np.fill_diagonal(stacked, False)
        is_stacked = stacked.any(axis=1)
        base = np.where(is_stacked, np.argmax(stacked, axis=1), index)
        for _ in range(3):  # a box on a cabin belongs to the cabin's base
            base = np.where(is_stacked[base], base[base], base)
        is_base = body & ~is_stacked
        # Wheels and panels: the nearest base of their vehicle (themselves if it has none).
        gap = np.linalg.norm(rel, axis=2)
        gap[~(same & is_base[None, :])] = np.inf
        nearest = np.argmin(gap, axis=1)
        attached = ~body & np.isfinite(gap[index, nearest])
        base = np.where(attached, nearest, base)
        layer = np.where(
            tire,
            _LAYER_WHEEL,
            np.where(body, np.where(is_stacked, _LAYER_STACKED, _LAYER_BASE), _LAYER_ATTACHED),
        )
        # The body colour: the largest painted body box of the vehicle.
        volume = np.prod(arrays.sizes, axis=1)
        score = np.where(body & (materials != _GLASS), volume, np.where(body, 0.0, -1.0))
        main = np.lexsort((score, vehicle))[ends - 1]  # (V,) largest score per vehicle
        body_rgb = arrays.colors_rgb[main][vehicle]
        # Roles.
        roles = np.zeros(count, dtype=np.intp)
        has_cabin = np.bincount(vehicle[is_stacked], minlength=starts.size) > 0
        roles[base[is_stacked]] |= ROLE_LOWER_BODY
        roles[is_stacked] |= ROLE_CABIN
        heading_yaw = arrays.yaws[main][vehicle]
        station = arrays.centers[:, 0] * np.cos(heading_yaw) + arrays.centers[:, 1] * np.sin(
            heading_yaw
        )
        units = is_base & ~has_cabin[vehicle]
        for role, sign in ((ROLE_FRONT_UNIT, 1.0), (ROLE_REAR_UNIT, -1.0)):
            pick = np.lexsort((np.where(units, sign * station, -np.inf), vehicle))[ends - 1]
            pick = pick[units[pick]]
            roles[pick] |= role
        allowed = np.ones((count, len(DecalKind)), dtype=bool)
        own_glass = (np.bincount(vehicle[glass_panel], minlength=starts.size) > 0)[vehicle]
        own_light = (np.bincount(vehicle[light_panel], minlength=starts.size) > 0)[vehicle]
        allowed[np.ix_(own_glass, np.array(_WINDOW_KINDS))] = False
        allowed[np.ix_(own_light, np.array(_LAMP_KINDS))] = False
        return base, layer, roles, allowed, body_rgb

    def render(
        self,
        boxes_of_vehicles: Sequence[Box],
        vehicle_ids: Sequence[str],
        stamp: float,
        vehicle_classes: Sequence[VehicleClass] | None = None,
    ) -> CameraFrame:
        """Render one frame of the vehicles in front of the static background.

        Parameters
        ----------
        boxes_of_vehicles
            All vehicles' boxes; a box's ``label`` is the 1-based index of its vehicle in
            ``vehicle_ids``.
        vehicle_ids
            Ids of the vehicles, in label order.
        stamp
            Capture time [s] (carried to the frame).
        vehicle_classes
            Class of each vehicle; None to guess (truck when it has TRUCK_BODY boxes or is
            longer than 7.5 m, else car).

        Returns
        -------
        CameraFrame
            Image (BGR uint8, H x W x 3) and one truth label per vehicle, in ``vehicle_ids``
            order.
        """
        count_vehicles = len(vehicle_ids)
        if vehicle_classes is not None and len(vehicle_classes) != count_vehicles:
            raise ValueError(
                f"{len(vehicle_classes)} vehicle classes for {count_vehicles} vehicle ids"
            )
        cam = self.camera
        image = self._background.copy()
        face_dtype = np.int16 if 6 * len(boxes_of_vehicles) < 32000 else np.int32
        face_buffer = np.full((cam.height_px, cam.width_px), -1, dtype=face_dtype)
        classes = (
            list(vehicle_classes)
            if vehicle_classes is not None
            else [VehicleClass.UNKNOWN] * count_vehicles
        )
        labels: dict[int, CameraTruthLabel] = {}
        face_vehicle = np.zeros(0, dtype=np.int16)
        if boxes_of_vehicles:
            arrays = _BoxArrays.from_boxes(boxes_of_vehicles)
            if arrays.labels.min() < 1 or arrays.labels.max() > count_vehicles:
                raise ValueError(
                    f"vehicle box labels must be 1..{count_vehicles} (one per vehicle id), got "
                    f"{int(arrays.labels.min())}..{int(arrays.labels.max())}"
                )
            arrays = arrays.take(np.argsort(arrays.labels, kind="stable"))
            vehicle_of_box = arrays.labels - 1
            if vehicle_classes is None:
                present = np.unique(vehicle_of_box)
                starts = np.searchsorted(vehicle_of_box, present, side="left")
                ends = np.searchsorted(vehicle_of_box, present, side="right")
                for vehicle, start, end in zip(present.tolist(), starts, ends, strict=True):
                    classes[vehicle] = _vehicle_class_guess(
                        arrays.materials[start:end], arrays.sizes[start:end]
                    )
            labels = self._draw_vehicles(image, face_buffer, arrays, vehicle_ids, classes)
            face_vehicle = np.repeat(vehicle_of_box, 6).astype(np.int16)
        self._sensor_effects(image)
        ordered = tuple(
            labels.get(i) or CameraTruthLabel(vid, i, classes[i], None, None, 0, 0)
            for i, vid in enumerate(vehicle_ids)
        )
        return CameraFrame(stamp, image, ordered, face_buffer, face_vehicle)

    def _draw_vehicles(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        arrays: _BoxArrays,
        vehicle_ids: Sequence[str],
        classes: Sequence[VehicleClass],
    ) -> dict[int, CameraTruthLabel]:
        """Shadows, vehicles (painter's order), static occlusion, truth, lamp glow, blur.

        ``arrays`` holds the boxes sorted by label. Draws into ``image`` and ``face_buffer``;
        returns the labels of vehicles with at least one pixel in the image, by 0-based index.
        """
        count_boxes = arrays.centers.shape[0]
        face_count = count_boxes * 6
        vehicle_of_box = arrays.labels - 1
        present = np.unique(vehicle_of_box)
        starts = np.searchsorted(vehicle_of_box, present, side="left")
        ends = np.searchsorted(vehicle_of_box, present, side="right")
        base, layer, roles, allowed, body_rgb = self._vehicle_structure(arrays, starts, ends)

        # Face colours: the body colour on a GLASS cabin (its windows are decals), dark tyres.
        face_rgb = np.repeat(arrays.colors_rgb[:, None, :], 6, axis=1)
        glass_body = (arrays.materials == _GLASS) & (layer == _LAYER_STACKED)
        face_rgb[glass_body] = body_rgb[glass_body][:, None, :]
        face_rgb[arrays.materials == _TIRE] = (26.0, 26.0, 29.0)
        # A little texture: each face a shade lighter or darker, fixed per vehicle.
        salt = np.array([zlib.crc32(v.encode()) % 100003 for v in vehicle_ids], dtype=np.float64)
        key = (
            salt[vehicle_of_box][:, None]
            + np.arange(6)[None, :] * 7.13
            + (np.arange(count_boxes) - np.repeat(starts, ends - starts))[:, None] * 3.7
        )
        jitter = 1.0 + 0.05 * np.modf(np.sin(key) * 43758.5453)[0]
        quads = _build_quads(arrays, face_rgb * jitter[..., None], roles, allowed)
        box_of_quad = quads.face // 6
        facing = self._front_facing(quads)
        facing[face_count:] = facing[quads.face[face_count:]]
        projected = self._project_quads(quads.site, facing)
        polygons = projected.polygons

        # Shading, lamps, haze.
        lighting = self._lighting
        colour = quads.base_rgb * _shade(lighting, quads.normal)
        emissive = arrays.materials[box_of_quad] == _LIGHT
        colour[emissive] = quads.base_rgb[emissive] * (1.6 if lighting.lamps_on else 0.9)
        lamp = np.isin(quads.kind, _LAMP_KINDS)
        if lighting.lamps_on and lamp.any():
            colour[lamp] = [_LAMP_GLOW_RGB[int(k)] for k in quads.kind[lamp]]
        range_m = self._range_to(quads.site.mean(axis=1))
        colour = _atmosphere(lighting, colour, range_m)
        colour_bgr = np.clip(colour[:, ::-1], 0.0, 255.0).astype(np.uint8).tolist()

        self._draw_shadows(image, arrays, layer, starts, ends)

        # Painter's order: groups (a base box and its wheels, cabin, panels) far to near, then
        # layer (wheels, base, stacked, panels), then faces far to near, then decals in order
        # (a decal sorts with its parent face: quads.face is the face's own quad index).
        group_range = self._range_to(arrays.centers)[base]
        order = np.lexsort(
            (quads.sub, -range_m[quads.face], layer[box_of_quad], -group_range[box_of_quad])
        )
        for q in order.tolist():
            pts = polygons[q]
            if pts is None:
                continue
            cv2.fillConvexPoly(image, pts, colour_bgr[q], cv2.LINE_8, _SHIFT)
            if q < face_count:
                cv2.fillConvexPoly(face_buffer, pts, q, cv2.LINE_8, _SHIFT)

        labels: dict[int, CameraTruthLabel] = {}
        regions: list[tuple[int, int, int, int]] = []
        planes: tuple[F64, F64] | None = None
        scratch = self._silhouette_scratch
        for vehicle, start, end in zip(
            present.tolist(), starts.tolist(), ends.tolist(), strict=True
        ):
            f0, f1 = 6 * start, 6 * end
            shown = [(q, pts) for q in range(f0, f1) if (pts := polygons[q]) is not None]
            if not shown:
                continue
            b = projected.bounds[[q for q, _ in shown]]
            x0, y0 = int(b[:, 0].min()), int(b[:, 1].min())
            x1, y1 = int(b[:, 2].max()) + 1, int(b[:, 3].max()) + 1
            # The silhouette alone: the same polygons, on a scratch mask.
            for _, pts in shown:
                cv2.fillConvexPoly(scratch, pts, 1, cv2.LINE_8, _SHIFT)
            region = scratch[y0:y1, x0:x1]
            silhouette = cv2.countNonZero(region)
            if silhouette == 0:
                continue
            full = _mask_box(region, x0, y0)
            region[:] = 0
            regions.append((x0, y0, x1, y1))
            sub_faces = face_buffer[y0:y1, x0:x1]
            own = (sub_faces >= f0) & (sub_faces < f1)
            if self._static_in(x0, y0, x1, y1):
                if planes is None:
                    planes = self._face_planes(quads.site[:face_count], quads.normal[:face_count])
                self._occlude_by_static(image, face_buffer, own, x0, y0, planes)
            visible = int(np.count_nonzero(own))
            labels[vehicle] = CameraTruthLabel(
                vehicle_ids[vehicle],
                vehicle,
                classes[vehicle],
                _mask_box(own.view(np.uint8), x0, y0) if visible else None,
                full,
                visible,
                silhouette,
            )

        if lighting.lamps_on:
            self._draw_glows(
                image, face_buffer, quads, polygons, np.flatnonzero(lamp), vehicle_of_box
            )
        if self.blur_sigma_px > 0.0:  # the background was blurred once; blur the vehicles
            height, width = face_buffer.shape
            for x0, y0, x1, y1 in regions:
                x0, y0 = max(0, x0 - 2), max(0, y0 - 2)
                x1, y1 = min(width, x1 + 2), min(height, y1 + 2)
                roi = image[y0:y1, x0:x1]
                cv2.GaussianBlur(roi, (3, 3), self.blur_sigma_px, dst=roi)
        return labels

    def _project_polygon(self, polygon_site: F64) -> tuple[I32, tuple[int, int, int, int]] | None:
        """Clip a site polygon (n, 3) in 3D and project it (a concave one stays fillable).

        Returns OpenCV fixed-point vertices and the pixel bounds ``(x0, y0, x1, y1)`` (x1, y1
        exclusive, inside the image), or None when nothing of it shows.
        """
        cam = self.camera
        clipped = _clip_polygon(cam.site_to_camera(polygon_site), self._clip_planes)
        if clipped.shape[0] < 3:
            return None
        u = cam.cx_px + cam.focal_px * clipped[:, 0] / clipped[:, 2]
        v = cam.cy_px + cam.focal_px * clipped[:, 1] / clipped[:, 2]
        x0, x1 = max(0, math.floor(u.min() - 0.5)), min(cam.width_px, math.ceil(u.max() + 0.5))
        y0, y1 = max(0, math.floor(v.min() - 0.5)), min(cam.height_px, math.ceil(v.max() + 0.5))
        if x1 <= x0 or y1 <= y0:
            return None
        pts = np.empty((u.size, 2), dtype=np.int32)
        pts[:, 0] = np.rint((u - 0.5) * _ONE)
        pts[:, 1] = np.rint((v - 0.5) * _ONE)
        return pts, (x0, y0, x1, y1)

    def _draw_shadows(
        self, image: U8, arrays: _BoxArrays, layer: IntP, starts: IntP, ends: IntP
    ) -> None:
        """Darken the ground under each vehicle, and its cast shadow in sunshine.

        Drawn before any vehicle, so vehicles cover it; static boxes (always nearer than the
        ground they stand in front of) are given back their pixels. The shadow is the convex
        hull of the body boxes' footprints and, with a sun high enough, of their top corners
        cast along the sun onto the road; its darkness is the ground's ambient share of light
        (``ambient / (ambient + sun)``), faded by haze with distance.
        """
        lighting = self._lighting
        sun = lighting.sun_direction
        up = np.array([0.0, 0.0, 1.0])
        total = float(_shade(lighting, up).mean())
        sunny = float(lighting.sun_rgb.mean()) > 0.25 and sun[2] > 0.2
        ambient_share = lighting.ambient / total if sunny else 0.7
        body = (layer == _LAYER_BASE) | (layer == _LAYER_STACKED)
        corners = arrays.corners()
        centres = arrays.centers[:, None, :2]
        footprint = centres + 1.08 * (corners[:, :4, :2] - centres)  # a little wider
        if sunny:
            top = corners[:, 4:, :]
            cast = top[..., :2] - top[..., 2:3] / sun[2] * sun[:2]
            outline = np.concatenate([footprint, cast], axis=1)
        else:
            outline = footprint
        for start, end in zip(starts.tolist(), ends.tolist(), strict=True):
            mine = np.flatnonzero(body[start:end]) + start
            if mine.size == 0:
                continue
            points = outline[mine].reshape(-1, 2).astype(np.float32)
            hull = cv2.convexHull(points).reshape(-1, 2).astype(np.float64)
            polygon = np.column_stack([hull, np.zeros(hull.shape[0])])
            projected = self._project_polygon(polygon)
            if projected is None:
                continue
            pts, (x0, y0, x1, y1) = projected
            centre = np.append(arrays.centers[mine, :2].mean(axis=0), 0.0)
            haze = math.exp(-lighting.extinction_per_m * float(self._range_to(centre)))
            darkness = 1.0 - (1.0 - ambient_share) * haze
            mask = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
            offset = np.array([x0 << _SHIFT, y0 << _SHIFT], dtype=np.int32)
            cv2.fillConvexPoly(mask, pts - offset, 1, cv2.LINE_8, _SHIFT)
            roi = image[y0:y1, x0:x1]
            cv2.copyTo(cv2.convertScaleAbs(roi, alpha=darkness), mask, roi)
            if self._static_in(x0, y0, x1, y1):
                cv2.copyTo(self._background[y0:y1, x0:x1], self._static_mask[y0:y1, x0:x1], roi)

    def _static_in(self, x0: int, y0: int, x1: int, y1: int) -> bool:
        """Whether any static box shows in pixels ``[y0, y1) x [x0, x1)`` (integral image)."""
        integral = self._static_integral
        total = integral[y1, x1] - integral[y0, x1] - integral[y1, x0] + integral[y0, x0]
        return bool(total > 0)

    def _occlude_by_static(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        own: BoolA,
        x0: int,
        y0: int,
        planes: tuple[F64, F64],
    ) -> None:
        """Give pixels back to static boxes nearer than the vehicle face drawn there.

        ``own`` (h, w) marks the vehicle's pixels in the region at (x0, y0); updated in place.
        The vehicle's depth at a pixel is that of its face's plane there (exact, not per face).
        """
        height, width = own.shape
        static_depth = self._static_box_depth[y0 : y0 + height, x0 : x0 + width]
        rows, cols = np.nonzero(own & np.isfinite(static_depth))
        if rows.size == 0:
            return
        rows_g, cols_g = rows + y0, cols + x0
        faces = face_buffer[rows_g, cols_g].astype(np.intp)
        normal_cam, offset = planes
        depth = self._plane_depth(normal_cam[faces], offset[faces], rows_g, cols_g)
        hidden = static_depth[rows, cols] < depth
        rows_h, cols_h = rows_g[hidden], cols_g[hidden]
        face_buffer[rows_h, cols_h] = -1
        image[rows_h, cols_h] = self._background[rows_h, cols_h]
        own[rows[hidden], cols[hidden]] = False

    def _draw_glows(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        quads: _Quads,
        polygons: list[I32 | None],
        lamps: IntP,
        vehicle_of_box: IntP,
    ) -> None:
        """Add a glow around each lamp whose vehicle is what its centre pixel shows."""
        height, width = face_buffer.shape
        box_of_quad = quads.face // 6
        for q in lamps.tolist():
            pts = polygons[q]
            if pts is None:
                continue
            centre = pts.mean(axis=0) / _ONE  # OpenCV coordinates (pixel centres at integers)
            column, row = math.floor(centre[0] + 0.5), math.floor(centre[1] + 0.5)
            if not (0 <= column < width and 0 <= row < height):
                continue
            seen = int(face_buffer[row, column])
            if seen < 0 or vehicle_of_box[seen // 6] != vehicle_of_box[box_of_quad[q]]:
                continue
            extent = float(np.ptp(pts, axis=0).max()) / _ONE
            self._add_glow(image, column, row, extent, int(quads.kind[q]))


def encode_jpeg(image: U8, quality: int = 90) -> bytes:
    """JPEG bytes of a BGR uint8 image (H, W, 3); ``quality`` 1-100."""
    if not 1 <= quality <= 100:
        raise ValueError(f"JPEG quality must be 1..100, got {quality}")
    ok, buffer = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} {image.dtype} image as JPEG")
    return bytes(buffer.tobytes())


def draw_truth(image: U8, labels: Sequence[CameraTruthLabel]) -> U8:
    """A copy of ``image`` with each visible vehicle's truth box, id, class and visibility.

    Boxes are green when at least half visible, yellow when less, red below 10 %.
    """
    out = image.copy()
    for label in labels:
        if label.box_xyxy_px is None:
            continue
        x0, y0, x1, y1 = label.box_xyxy_px
        if label.visibility >= 0.5:
            colour = (40, 220, 40)
        elif label.visibility >= 0.1:
            colour = (0, 220, 255)
        else:
            colour = (40, 40, 240)
        top_left = (int(x0), int(y0))
        bottom_right = (max(int(x0), int(x1) - 1), max(int(y0), int(y1) - 1))
        cv2.rectangle(out, top_left, bottom_right, colour, 1, cv2.LINE_8)
        text = f"{label.vehicle_id} {label.vehicle_class.value} {label.visibility:.2f}"
        origin = (int(x0), max(10, int(y0) - 3))
        cv2.putText(out, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(out, text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1, cv2.LINE_AA)
    return out
