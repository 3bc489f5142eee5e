"""What the camera draws of a box: its faces, the decals painted on them, and how a vehicle's
boxes fit together (which box is a cabin, a wheel, a panel).

Pure geometry and tables (no rendering): :class:`BoxArrays` holds boxes as arrays,
:func:`build_quads` turns them into the quads (faces, then decals) the renderer in
:mod:`wz_simulator.sensors.camera` shades, sorts and fills, and :func:`vehicle_structure`
decides each box's drawing group, layer and decal roles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from wz_shared.arrays import F64, Bool, IntP
from wz_simulator.sensors.scene import BOX_CORNER_SIGNS, BOX_FACES, Box, Material

_FACE_CORNERS = np.array(BOX_FACES, dtype=np.intp)  # (6, 4)
FACE_BOTTOM, FACE_TOP, FACE_RIGHT, FACE_FRONT, FACE_LEFT, FACE_BACK = range(6)


@dataclass(frozen=True)
class BoxArrays:
    """Boxes as arrays (B = number of boxes)."""

    centers: F64  # (B, 3) [m]
    sizes: F64  # (B, 3) length, width, height [m]
    yaws: F64  # (B,) [rad]
    materials: IntP  # (B,)
    colors_rgb: F64  # (B, 3) 0-255
    labels: IntP  # (B,)

    @classmethod
    def from_boxes(cls, boxes: Sequence[Box]) -> BoxArrays:
        count = len(boxes)
        return cls(
            centers=np.array([b.center_xyz_m for b in boxes], dtype=np.float64).reshape(count, 3),
            sizes=np.array([b.size_lwh_m for b in boxes], dtype=np.float64).reshape(count, 3),
            yaws=np.array([b.yaw_rad for b in boxes], dtype=np.float64),
            materials=np.array([int(b.material) for b in boxes], dtype=np.intp),
            colors_rgb=np.array([b.color_rgb for b in boxes], dtype=np.float64).reshape(count, 3),
            labels=np.array([b.label for b in boxes], dtype=np.intp),
        )

    def take(self, order: IntP) -> BoxArrays:
        return BoxArrays(
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


LAMP_KINDS = (int(DecalKind.HEADLAMP), int(DecalKind.TAILLAMP))
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
LAMP_GLOW_RGB = {
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
LAYER_WHEEL, LAYER_BASE, LAYER_STACKED, LAYER_ATTACHED = 0, 1, 2, 3
_THIN_M = 0.15  # a GLASS or LIGHT box thinner than this is a panel on a body
TIRE, GLASS, LIGHT = int(Material.TIRE), int(Material.GLASS), int(Material.LIGHT)


@dataclass(frozen=True)
class Quads:
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


def build_quads(
    arrays: BoxArrays, face_rgb: F64, roles: IntP, decal_filter: Bool | None = None
) -> Quads:
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
    return Quads(
        site=np.concatenate([face_site, decal_site]),
        normal=np.concatenate([face_normal, face_normal[decal_face]]),
        base_rgb=np.concatenate([face_rgb.reshape(count * 6, 3), _DECAL_RGB[decal_kind]]),
        kind=np.concatenate([np.full(count * 6, -1, dtype=np.intp), decal_kind]),
        face=np.concatenate([face_index, decal_face]),
        sub=np.concatenate([np.zeros(count * 6, dtype=np.intp), decal_sub]),
    )


def vehicle_structure(
    arrays: BoxArrays, starts: IntP, ends: IntP
) -> tuple[IntP, IntP, IntP, Bool, F64]:
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
    tire = materials == TIRE
    glass_panel = (materials == GLASS) & thin
    light_panel = (materials == LIGHT) & thin
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
        LAYER_WHEEL,
        np.where(body, np.where(is_stacked, LAYER_STACKED, LAYER_BASE), LAYER_ATTACHED),
    )
    # The body colour: the largest painted body box of the vehicle.
    volume = np.prod(arrays.sizes, axis=1)
    score = np.where(body & (materials != GLASS), volume, np.where(body, 0.0, -1.0))
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
    allowed[np.ix_(own_light, np.array(LAMP_KINDS))] = False
    return base, layer, roles, allowed, body_rgb
