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

import functools
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import numpy.typing as npt

from wz_shared.geometry import RoadFrame
from wz_shared.messages import VehicleTruth
from wz_shared.site import AreaKind, Site


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


#: Corners of a box as signs of its half sizes (length, width, height), in :meth:`Box.corners`
#: order: the bottom face (-l,-w), (+l,-w), (+l,+w), (-l,+w), then the top face likewise.
BOX_CORNER_SIGNS = np.array(
    [
        [-1, -1, -1],
        [1, -1, -1],
        [1, 1, -1],
        [-1, 1, -1],
        [-1, -1, 1],
        [1, -1, 1],
        [1, 1, 1],
        [-1, 1, 1],
    ],
    dtype=np.float64,
)
BOX_CORNER_SIGNS.setflags(write=False)

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
        local = BOX_CORNER_SIGNS * (0.5 * np.asarray(self.size_lwh_m))
        cos_yaw, sin_yaw = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        rotation = np.array([[cos_yaw, -sin_yaw, 0.0], [sin_yaw, cos_yaw, 0.0], [0.0, 0.0, 1.0]])
        return np.asarray(local @ rotation.T + np.asarray(self.center_xyz_m), dtype=np.float64)


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
    #: Layer height [m]: grass below asphalt below paint, so coplanar surfaces never tie.
    z_m: float = 0.0


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


# --- vehicles ---------------------------------------------------------------------------------

#: Body colours [RGB] drawn per vehicle (seeded by its id, so a vehicle keeps its colour).
CAR_COLORS: tuple[tuple[int, int, int], ...] = (
    (200, 200, 205),  # silver
    (30, 30, 35),  # black
    (235, 235, 235),  # white
    (150, 20, 25),  # red
    (25, 50, 120),  # blue
    (90, 90, 95),  # grey
    (20, 70, 40),  # green
    (180, 150, 90),  # beige
)
TRAILER_COLORS: tuple[tuple[int, int, int], ...] = ((235, 235, 230), (200, 200, 195), (170, 40, 30))
TIRE_RGB = (25, 25, 25)
GLASS_RGB = (40, 55, 70)


def _palette_index(vehicle_id: str, size: int) -> int:
    return sum(vehicle_id.encode()) * 2654435761 % 2**32 % size


def _part(
    x: float,
    y: float,
    cos_h: float,
    sin_h: float,
    heading: float,
    label: int,
    along_m: float,
    across_m: float,
    z0_m: float,
    z1_m: float,
    length_m: float,
    width_m: float,
    material: Material,
    rgb: tuple[int, int, int],
) -> Box:
    """A box of a vehicle given in the vehicle's frame (along/across its heading)."""
    cx = x + along_m * cos_h - across_m * sin_h
    cy = y + along_m * sin_h + across_m * cos_h
    return Box(
        (cx, cy, 0.5 * (z0_m + z1_m)),
        (length_m, width_m, z1_m - z0_m),
        heading,
        material,
        rgb,
        label,
    )


def vehicle_boxes(vehicles: Sequence[VehicleTruth], dt_s: float = 0.0) -> list[Box]:
    """Bodies of the vehicles as boxes, each moved ``dt_s`` along its heading at its speed.

    A car is a lower body, a glass cabin with a roof and four wheels; a semi-trailer truck a
    tractor cab with a windscreen, a box trailer on a gap above the road, and wheels. Lamps,
    grilles and plates are the camera's decals on these faces (too small for the LiDAR to
    resolve). Labels are 1-based indices into ``vehicles``.

    Parameters
    ----------
    vehicles
        Truth of the frame (centre on the ground plane's vertical, heading CCW from east).
    dt_s
        Time offset [s] from the truth's stamp (the LiDAR places vehicles at each column's time).
    """
    boxes: list[Box] = []
    for index, vehicle in enumerate(vehicles, start=1):
        heading = vehicle.heading_rad
        cos_h, sin_h = float(np.cos(heading)), float(np.sin(heading))
        x = vehicle.x_m + vehicle.speed_mps * dt_s * cos_h
        y = vehicle.y_m + vehicle.speed_mps * dt_s * sin_h
        length, width, height = vehicle.length_m, vehicle.width_m, vehicle.height_m
        part = functools.partial(_part, x, y, cos_h, sin_h, heading, index)

        half = 0.5 * length
        axles: tuple[float, ...]
        wheel_d = min(1.0, 0.45 * height) if vehicle.vehicle_class == "truck" else 0.64
        if vehicle.vehicle_class in ("truck", "bus"):
            body_rgb = TRAILER_COLORS[_palette_index(vehicle.vehicle_id, len(TRAILER_COLORS))]
            cab_rgb = CAR_COLORS[_palette_index(vehicle.vehicle_id[::-1], len(CAR_COLORS))]
            cab_length = min(2.6, 0.3 * length) if vehicle.vehicle_class == "truck" else length
            cab_top = 0.85 * height if vehicle.vehicle_class == "truck" else height
            cab_center = half - 0.5 * cab_length
            cab_width = 0.96 * width if vehicle.vehicle_class == "truck" else width
            boxes.append(
                part(
                    cab_center,
                    0.0,
                    0.5,
                    cab_top,
                    cab_length,
                    cab_width,
                    Material.TRUCK_BODY,
                    cab_rgb,
                )
            )
            boxes.append(
                part(
                    half - 0.03,
                    0.0,
                    0.55 * cab_top,
                    0.92 * cab_top,
                    0.06,
                    width * 0.85,
                    Material.GLASS,
                    GLASS_RGB,
                )
            )
            if vehicle.vehicle_class == "truck":
                trailer_length = length - cab_length - 0.6
                trailer_center = -half + 0.5 * trailer_length
                boxes.append(
                    part(
                        trailer_center,
                        0.0,
                        1.2,
                        height,
                        trailer_length,
                        width,
                        Material.TRUCK_BODY,
                        body_rgb,
                    )
                )
                axles = (half - 0.8, half - cab_length - 0.2, -half + 2.2, -half + 1.0)
            else:
                axles = (half - 2.5, -half + 2.5)
        else:
            body_rgb = CAR_COLORS[_palette_index(vehicle.vehicle_id, len(CAR_COLORS))]
            sill, belt = 0.28, 0.58 * height
            boxes.append(part(0.0, 0.0, sill, belt, length, width, Material.CAR_PAINT, body_rgb))
            cabin_length = 0.5 * length
            boxes.append(
                part(
                    -0.05 * length,
                    0.0,
                    belt,
                    0.94 * height,
                    cabin_length,
                    0.88 * width,
                    Material.GLASS,
                    GLASS_RGB,
                )
            )
            boxes.append(
                part(
                    -0.05 * length,
                    0.0,
                    0.94 * height,
                    height,
                    cabin_length * 0.9,
                    0.86 * width,
                    Material.CAR_PAINT,
                    body_rgb,
                )
            )
            axles = (half - 0.85 * min(1.0, length / 4.6), -half + 0.85 * min(1.0, length / 4.6))
        for along in axles:
            for side in (-1.0, 1.0):
                boxes.append(
                    part(
                        along,
                        side * (0.5 * width - 0.14),
                        0.0,
                        wheel_d,
                        wheel_d,
                        0.26,
                        Material.TIRE,
                        TIRE_RGB,
                    )
                )
    return boxes


# --- the static scene -------------------------------------------------------------------------

ASPHALT_RGB = (68, 68, 72)
GRASS_RGB = (78, 112, 58)
WHITE_PAINT_RGB = (230, 230, 225)
YELLOW_PAINT_RGB = (225, 185, 40)
DRUM_RGB = (240, 105, 20)
CONCRETE_RGB = (178, 176, 170)
SIGN_RGB = (245, 140, 10)
METAL_RGB = (150, 152, 156)
VEGETATION_RGB = (48, 86, 40)

RIGHT_SHOULDER_M = 3.0
LEFT_SHOULDER_M = 1.2
LINE_WIDTH_M = 0.15
#: US broken lane line: 10 ft stripe, 30 ft gap.
DASH_M, GAP_M = 3.05, 9.15


@dataclass(frozen=True)
class StaticScene:
    """What does not move: ground polygons and boxes (furniture, roadside)."""

    boxes: list[Box]
    ground: list[GroundPolygon]


def _strip(
    frame: RoadFrame, s0: float, s1: float, d_right: float, d_left: float, step_m: float = 10.0
) -> npt.NDArray[np.float64]:
    """A polygon between offsets ``d_right < d_left`` from station s0 to s1, CCW."""
    count = max(2, int(np.ceil((s1 - s0) / step_m)) + 1)
    stations = np.linspace(s0, s1, count)
    xr, yr = frame.to_site(stations, np.full(count, d_right))
    xl, yl = frame.to_site(stations[::-1], np.full(count, d_left))
    return np.column_stack([np.concatenate([xr, xl]), np.concatenate([yr, yl])])


def _upright(
    frame: RoadFrame,
    station_m: float,
    offset_m: float,
    size_lwh_m: tuple[float, float, float],
    z0_m: float,
    material: Material,
    rgb: tuple[int, int, int],
) -> Box:
    """A box standing at (station, offset), its length along the road."""
    x, y = frame.to_site(station_m, offset_m)
    heading = float(frame.heading_at(station_m))
    return Box((float(x), float(y), z0_m + 0.5 * size_lwh_m[2]), size_lwh_m, heading, material, rgb)


def static_scene(
    site: Site, center_station_m: float | None = None, radius_m: float = 450.0, seed: int = 7
) -> StaticScene:
    """Build the work zone's static scene from the site file.

    Ground: grass, the carriageway with shoulders, edge lines and broken lane lines where both
    lanes are open. Furniture from the work-zone areas: advance-warning signs, an arrow board at
    the start of the taper, drums along the taper (spacing S ft at S mph, MUTCD 6F.63) and the
    buffer, a concrete barrier along the activity area, drums closing the termination taper.
    Roadside: guardrail on the right, light poles, vegetation bands, and the sensor trailer.
    Furniture and roadside are kept within ``radius_m`` of ``center_station_m`` (default: the
    first sensor's station), the stretch the sensors see.
    """
    frame = site.road_frame
    length = frame.length_m
    if center_station_m is None:
        if site.sensors:
            pose = site.sensors[0].pose
            center_station_m = float(frame.to_road(pose.x_m, pose.y_m)[0])
        else:
            center_station_m = 0.5 * length
    lo = max(0.0, center_station_m - radius_m)
    hi = min(length, center_station_m + radius_m)
    rng = np.random.default_rng(seed)

    lanes = sorted(site.lanes, key=lambda lane: lane.index)
    right_edge = lanes[0].center_offset_m - 0.5 * lanes[0].width_m
    left_edge = lanes[-1].center_offset_m + 0.5 * lanes[-1].width_m
    ground = [
        GroundPolygon(
            _strip(frame, lo, hi, right_edge - 60.0, left_edge + 60.0, 25.0),
            Material.GRASS,
            GRASS_RGB,
            z_m=-0.03,
        ),
        GroundPolygon(
            _strip(frame, lo, hi, right_edge - RIGHT_SHOULDER_M, left_edge + LEFT_SHOULDER_M),
            Material.ASPHALT,
            ASPHALT_RGB,
            0.0,
        ),
    ]

    def line(s0: float, s1: float, d: float, rgb: tuple[int, int, int]) -> None:
        if s1 - s0 > 0.1:
            polygon = _strip(frame, s0, s1, d - 0.5 * LINE_WIDTH_M, d + 0.5 * LINE_WIDTH_M)
            ground.append(GroundPolygon(polygon, Material.MARKING, rgb, z_m=0.005))

    taper = site.area(AreaKind.TRANSITION)
    closed = site.lane(site.closed_lane_index)
    line(lo, hi, right_edge, WHITE_PAINT_RGB)
    line(lo, hi, left_edge, YELLOW_PAINT_RGB)
    reopen = _reopen_station(site)
    for lane_a, lane_b in itertools.pairwise(lanes):
        d_line = 0.5 * (lane_a.center_offset_m + lane_b.center_offset_m)
        for start, stop in ((lo, min(hi, taper.end_station_m)), (max(lo, reopen), hi)):
            s = start - (start % (DASH_M + GAP_M))
            while s < stop:
                line(max(s, start), min(s + DASH_M, stop), d_line, WHITE_PAINT_RGB)
                s += DASH_M + GAP_M

    boxes: list[Box] = []

    def add(
        station: float,
        offset: float,
        size: tuple[float, float, float],
        z0: float,
        material: Material,
        rgb: tuple[int, int, int],
    ) -> None:
        if lo <= station <= hi:
            boxes.append(_upright(frame, station, offset, size, z0, material, rgb))

    # Channelizing drums: the taper moves them across the closed lane, spaced S ft (S in mph).
    limit_mph = site.speed_limit_mps_at(taper.start_station_m) / 0.44704
    spacing = limit_mph * 0.3048
    closed_sign = 1.0 if closed.center_offset_m > 0 else -1.0
    far_edge = closed.center_offset_m + closed_sign * 0.5 * closed.width_m
    near_edge = closed.center_offset_m - closed_sign * 0.5 * closed.width_m
    drum = (0.6, 0.6, 1.0)
    count = max(2, round((taper.end_station_m - taper.start_station_m) / spacing) + 1)
    for k in range(count):
        f = k / (count - 1)
        station = taper.start_station_m + f * (taper.end_station_m - taper.start_station_m)
        offset = far_edge + f * (near_edge - far_edge) + closed_sign * 0.4
        add(station, offset, drum, 0.0, Material.DRUM, DRUM_RGB)
    for kind, gap in ((AreaKind.BUFFER, 2 * spacing), (AreaKind.TERMINATION, spacing)):
        try:
            area = site.area(kind)
        except KeyError:
            continue
        # The taper's last drum stands at the buffer's start: continue one gap after it.
        for station in np.arange(area.start_station_m + gap, area.end_station_m, gap):
            f = 0.0
            if kind == AreaKind.TERMINATION:
                f = (station - area.start_station_m) / (area.end_station_m - area.start_station_m)
            offset = near_edge + closed_sign * 0.4 + f * (far_edge - near_edge)
            add(float(station), offset, drum, 0.0, Material.DRUM, DRUM_RGB)
    try:
        activity = site.area(AreaKind.ACTIVITY)
        for station in np.arange(activity.start_station_m + 3.0, activity.end_station_m, 6.1):
            add(
                float(station),
                near_edge + closed_sign * 0.5,
                (6.0, 0.6, 0.81),
                0.0,
                Material.CONCRETE,
                CONCRETE_RGB,
            )
    except KeyError:
        pass
    # Arrow board at the start of the taper, on the closed lane's shoulder.
    board_offset = far_edge + closed_sign * 1.0
    add(taper.start_station_m - 10.0, board_offset, (2.4, 1.8, 1.0), 0.3, Material.METAL, METAL_RGB)
    add(
        taper.start_station_m - 9.0,
        board_offset,
        (0.15, 2.4, 1.2),
        2.2,
        Material.SIGN,
        (20, 20, 20),
    )
    # Advance-warning signs on the right shoulder, facing traffic.
    try:
        warning = site.area(AreaKind.ADVANCE_WARNING)
        sign_offset = right_edge - RIGHT_SHOULDER_M - 0.8
        for f in (0.0, 0.4, 0.75):
            station = warning.start_station_m + f * (
                warning.end_station_m - warning.start_station_m
            )
            add(station, sign_offset, (0.1, 0.1, 2.1), 0.0, Material.METAL, METAL_RGB)
            add(station, sign_offset, (0.08, 1.2, 1.2), 2.1, Material.SIGN, SIGN_RGB)
    except KeyError:
        pass
    # Roadside: guardrail (posts every 1.9 m, a W-beam in 4 m pieces), light poles, vegetation.
    rail_offset = right_edge - RIGHT_SHOULDER_M - 2.3
    for station in np.arange(lo, hi, 4.0):
        add(float(station) + 2.0, rail_offset, (4.0, 0.3, 0.33), 0.55, Material.METAL, METAL_RGB)
    for station in np.arange(lo, hi, 1.905):
        add(float(station), rail_offset - 0.2, (0.15, 0.15, 0.75), 0.0, Material.METAL, METAL_RGB)
    for station in np.arange(lo - lo % 60.0, hi, 60.0):
        add(float(station), rail_offset - 1.5, (0.3, 0.3, 10.0), 0.0, Material.METAL, METAL_RGB)
    for station in np.arange(lo, hi, 20.0):
        for side_offset in (rail_offset - 8.0, left_edge + LEFT_SHOULDER_M + 14.0):
            height = float(rng.uniform(2.5, 7.0))
            depth = float(rng.uniform(6.0, 12.0))
            offset = side_offset - 0.5 * depth if side_offset < 0 else side_offset + 0.5 * depth
            add(
                float(station) + 10.0,
                offset,
                (20.0, depth, height),
                0.0,
                Material.VEGETATION,
                VEGETATION_RGB,
            )
    # The sensor trailer and its mast (the mast stops below the lowest sensor).
    if site.sensors:
        poses = [sensor.pose for sensor in site.sensors]
        x, y = poses[0].x_m, poses[0].y_m
        trailer_station, trailer_offset = (float(v) for v in frame.to_road(x, y))
        lowest = min(pose.z_m for pose in poses)
        add(trailer_station, trailer_offset - 0.3, (4.0, 2.0, 0.9), 0.4, Material.METAL, METAL_RGB)
        boxes.append(
            Box(
                (x, y, 0.5 * (lowest - 0.6)),
                (0.25, 0.25, lowest - 0.6),
                0.0,
                Material.METAL,
                METAL_RGB,
            )
        )
    return StaticScene(boxes=boxes, ground=ground)


def _reopen_station(site: Site) -> float:
    """Where the closed lane opens again (end of the termination area), or beyond the road."""
    try:
        return site.area(AreaKind.TERMINATION).end_station_m
    except KeyError:
        return float("inf")
