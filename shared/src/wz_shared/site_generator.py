"""Seeded work-zone sites over what a DOT meets, for testing the pipeline off its default site.

:func:`generate_site` draws one lane-drop work zone from a seed and lays it out the way the
MUTCD (Part 6) and a field technician would:

- the road: 2 lanes dropping to 1 or 3 dropping to 2, the right or the left lane closed, lanes
  3.5-3.66 m wide, any compass bearing; straight, or with a circular curve (radius 500-2000 m,
  either hand) that ends anywhere from 150 m before to 100 m after the mast;
- the limits: 45-70 mph upstream, 35-60 mph in the zone (at least 5 mph lower or equal to the
  upstream limit, in 5 mph steps); the merging taper is ``L = W S`` ft for ``S >= 45`` mph and
  ``W S^2 / 60`` below (MUTCD Table 6C-3, ``W`` the lane width in ft, ``S`` the zone limit);
  the buffer is the stopping sight distance of Table 6C-2 at the zone limit; the advance-warning
  area 500-800 m; the activity area 300-500 m; a 100 m termination;
- the trailer: the mast on the right shoulder, the left shoulder or in the median, 4-10 m high,
  10-80 m upstream of the taper;
- the sensors, with any ids: a LiDAR of 32, 64 or 128 beams from real models' vertical fields
  of view; a camera of a common format (1280x720, 1920x1080, 1280x960, 2048x1536) and 50-100
  degrees, aimed down the approach with the horizon 22-40 % from the top of the frame; a radar
  aimed down the approach;
- upstream point speed sensors every 200-400 m from the mast to the road's start, each
  reporting every 20, 30 or 60 s (drawn after everything else: a seed's other draws are as
  before they came);
- the alert thresholds from the site's limits and layout (:func:`alert_rules_for`).

Everything is a function of the seed (``numpy.random.default_rng``): the same seed gives the
same file on every machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wz_shared.geometry import RoadFrame
from wz_shared.site import (
    MPH_TO_MPS,
    AlertRules,
    AreaKind,
    CameraIntrinsics,
    DeviceRules,
    GeoOrigin,
    Lane,
    LateMergeRule,
    LidarIntrinsics,
    PointSensor,
    Pose,
    RadarIntrinsics,
    RoadDirection,
    SensorMount,
    Site,
    SpeedLimit,
    WorkZoneArea,
)

FT_TO_M = 0.3048

#: MUTCD Table 6C-2: longitudinal buffer space (stopping sight distance) by speed [mph -> ft].
BUFFER_FT_BY_MPH = {
    20: 115,
    25: 155,
    30: 200,
    35: 250,
    40: 305,
    45: 360,
    50: 425,
    55: 495,
    60: 570,
    65: 645,
    70: 730,
    75: 820,
}

#: Common machine-vision and traffic camera formats [px].
CAMERA_FORMATS: tuple[tuple[int, int], ...] = ((1280, 720), (1920, 1080), (1280, 960), (2048, 1536))


@dataclass(frozen=True)
class LidarModel:
    """Vertical geometry of a spinning LiDAR family."""

    name: str
    beams: int
    vertical_min_deg: float
    vertical_max_deg: float
    azimuth_steps: int
    max_range_m: float


#: Real sensors' vertical fields of view (data sheets): Velodyne VLP-32C, Ouster OS1 and OS2
#: (32/64/128 beams), Hesai Pandar64.
LIDAR_MODELS: tuple[LidarModel, ...] = (
    LidarModel("vlp-32c", 32, -25.0, 15.0, 1800, 200.0),
    LidarModel("os1-32", 32, -22.5, 22.5, 1024, 170.0),
    LidarModel("os1-64", 64, -22.5, 22.5, 2048, 170.0),
    LidarModel("os1-128", 128, -22.5, 22.5, 1024, 170.0),
    LidarModel("os2-64", 64, -11.25, 11.25, 2048, 240.0),
    LidarModel("os2-128", 128, -11.25, 11.25, 1024, 240.0),
    LidarModel("pandar64", 64, -25.0, 15.0, 1800, 200.0),
)

#: Compass bearings (clockwise from north) and the WZDx direction each rounds to.
_DIRECTIONS: tuple[tuple[float, RoadDirection], ...] = (
    (0.0, "northbound"),
    (90.0, "eastbound"),
    (180.0, "southbound"),
    (270.0, "westbound"),
)

#: Shape vertex spacing: curves need it denser than straights [m].
_STRAIGHT_STEP_M = 100.0
_CURVE_STEP_M = 20.0


def taper_length_m(lane_width_m: float, speed_mph: float) -> float:
    """Merging taper length [m], MUTCD Table 6C-3 (``W S`` or ``W S^2 / 60``, in feet)."""
    width_ft = lane_width_m / FT_TO_M
    length_ft = width_ft * speed_mph if speed_mph >= 45.0 else width_ft * speed_mph**2 / 60.0
    return length_ft * FT_TO_M


def buffer_length_m(speed_mph: float) -> float:
    """Longitudinal buffer space [m] at a speed, MUTCD Table 6C-2 (rounded up to its row)."""
    row = min((mph for mph in BUFFER_FT_BY_MPH if mph >= speed_mph), default=75)
    return BUFFER_FT_BY_MPH[row] * FT_TO_M


def alert_rules_for(
    *,
    zone_limit_mph: float,
    advance_warning_start_m: float,
    activity_end_m: float,
    taper_start_m: float,
) -> AlertRules:
    """Alert thresholds from a site's limits and layout.

    - the approach runs from the first advance-warning sign to the end of the activity area;
    - late merge: the last 6 s before the taper at the zone limit (150 m at 55 mph, the
      default site's figure), 100 m at least;
    - the message sign 30 % of the way into the advance-warning area (the default site's sign
      stands 200 m into a 700 m area), so drivers read it before they reach the taper.
    Everything else (margins in mph, decelerations in g, TTC in s) is physical and needs no
    site value: :class:`~wz_shared.site.AlertRules`' defaults.
    """
    late_merge_m = max(100.0, round(6.0 * zone_limit_mph * MPH_TO_MPS / 5.0) * 5.0)
    late_merge_m = min(late_merge_m, taper_start_m - advance_warning_start_m)
    sign_m = advance_warning_start_m + 0.3 * (taper_start_m - advance_warning_start_m)
    return AlertRules(
        approach_length_m=round(activity_end_m - advance_warning_start_m, 1),
        late_merge=LateMergeRule(distance_m=late_merge_m),
        devices=DeviceRules(sign_station_m=round(sign_m, 1)),
    )


def _centerline(
    rng: np.random.Generator, length_m: float, mast_station_m: float
) -> tuple[list[tuple[float, float]], str, float]:
    """A centerline polyline of ``length_m`` in a local frame, its description and the bearing
    of its start [deg clockwise from north]."""
    bearing_deg = float(rng.uniform(0.0, 360.0))
    curved = bool(rng.random() < 0.6)
    # Heading as an angle CCW from east, the site frame's convention.
    heading = math.radians(90.0 - bearing_deg)
    if curved:
        radius_m = float(rng.uniform(500.0, 2000.0))
        hand = 1.0 if rng.random() < 0.5 else -1.0  # +1 turns left
        curve_end_m = mast_station_m + float(rng.uniform(-150.0, 100.0))
        # Up to 35 degrees of turn, and no more than the road before the curve's end holds.
        arc_m = min(float(rng.uniform(200.0, 600.0)), math.radians(35.0) * radius_m)
        arc_m = min(arc_m, curve_end_m - 50.0)
        curve_start_m = curve_end_m - arc_m
        description = (
            f"{'left' if hand > 0 else 'right'}-hand curve, radius {radius_m:.0f} m, from "
            f"station {curve_start_m:.0f} to {curve_end_m:.0f} m"
        )
    else:
        radius_m, hand, curve_start_m, curve_end_m = math.inf, 0.0, length_m + 1, length_m + 1
        description = "straight"
    stations = sorted(
        {
            *np.arange(0.0, length_m, _STRAIGHT_STEP_M).tolist(),
            *(
                np.arange(curve_start_m, min(curve_end_m, length_m), _CURVE_STEP_M).tolist()
                if curved
                else []
            ),
            min(curve_end_m, length_m),
            length_m,
        }
    )
    stations = [s for i, s in enumerate(stations) if i == 0 or s - stations[i - 1] >= 1.0]
    k = hand / radius_m if curved else 0.0  # curvature [1/m], positive to the left
    arc_end_m = min(curve_end_m, length_m)

    def heading_at(station: float) -> float:
        return heading + k * (min(max(station, curve_start_m), arc_end_m) - curve_start_m)

    def position(station: float) -> tuple[float, float]:
        # Straight to the curve's start, the arc in closed form, then straight again.
        lead = min(station, curve_start_m)
        x, y = lead * math.cos(heading), lead * math.sin(heading)
        if station > curve_start_m and curved:
            theta = heading_at(station)
            x += (math.sin(theta) - math.sin(heading)) / k
            y -= (math.cos(theta) - math.cos(heading)) / k
            tail = station - arc_end_m
            if tail > 0.0:
                x, y = x + tail * math.cos(theta), y + tail * math.sin(theta)
        return x, y

    points = []
    for station in stations:
        x, y = position(station)
        points.append((round(x, 3), round(y, 3)))
    return points, description, bearing_deg


def _direction(bearing_deg: float) -> RoadDirection:
    best = min(_DIRECTIONS, key=lambda d: abs((bearing_deg - d[0] + 180.0) % 360.0 - 180.0))
    return best[1]


def _yaw_deg(site_xy: tuple[float, float], target_xy: tuple[float, float]) -> float:
    """Yaw [deg CCW from east] of the line of sight from a mount to a point."""
    return math.degrees(math.atan2(target_xy[1] - site_xy[1], target_xy[0] - site_xy[0]))


def _sensor_id(rng: np.random.Generator, kind: str, model: str) -> str:
    words = ("mast", "trailer", "north", "south", "a", "b", "1", "2", "pole", "unit")
    style = int(rng.integers(3))
    word = str(rng.choice(words))
    if style == 0:
        return f"{kind}-{word}"
    if style == 1:
        return f"{model}-{word}"
    return f"{word}-{kind}{int(rng.integers(1, 10))}"


def generate_site(seed: int) -> Site:
    """One seeded work-zone site (see the module's description)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x517E]))
    lanes_n = 2 if rng.random() < 0.6 else 3
    lane_width_m = float(rng.choice([3.5, 3.6, 3.66]))
    closed_side = "right" if rng.random() < 0.5 else "left"
    closed_lane = 0 if closed_side == "right" else lanes_n - 1
    lanes = [
        Lane(
            index=i,
            center_offset_m=round((i - (lanes_n - 1) / 2) * lane_width_m, 3),
            width_m=lane_width_m,
        )
        for i in range(lanes_n)
    ]
    upstream_mph = float(rng.choice([45, 50, 55, 60, 65, 70]))
    zone_choices = [mph for mph in range(35, 65, 5) if mph <= upstream_mph - 5]
    zone_mph = float(rng.choice(zone_choices))

    # Layout along the road [m].
    lead_in_m = 300.0  # upstream limit, before the first sign
    advance_m = float(rng.choice([500.0, 600.0, 700.0, 800.0]))
    advance_start_m = lead_in_m
    taper_start_m = advance_start_m + advance_m
    taper_end_m = taper_start_m + taper_length_m(lane_width_m, zone_mph)
    buffer_end_m = taper_end_m + buffer_length_m(zone_mph)
    activity_end_m = buffer_end_m + float(rng.choice([300.0, 400.0, 500.0]))
    termination_end_m = activity_end_m + 100.0
    length_m = termination_end_m + 200.0
    areas = [
        (AreaKind.ADVANCE_WARNING, advance_start_m, taper_start_m),
        (AreaKind.TRANSITION, taper_start_m, taper_end_m),
        (AreaKind.BUFFER, taper_end_m, buffer_end_m),
        (AreaKind.ACTIVITY, buffer_end_m, activity_end_m),
        (AreaKind.TERMINATION, activity_end_m, termination_end_m),
    ]

    # The trailer.
    mast_station_m = taper_start_m - float(rng.uniform(10.0, 80.0))
    mast_side = str(rng.choice(["right shoulder", "left shoulder", "median"]))
    right_edge = lanes[0].center_offset_m - lane_width_m / 2
    left_edge = lanes[-1].center_offset_m + lane_width_m / 2
    if mast_side == "right shoulder":
        mast_offset_m = right_edge - float(rng.uniform(2.5, 5.0))
    elif mast_side == "left shoulder":
        mast_offset_m = left_edge + float(rng.uniform(2.0, 3.5))
    else:
        mast_offset_m = left_edge + float(rng.uniform(5.0, 12.0))
    height_m = float(rng.uniform(4.0, 10.0))

    centerline, shape, bearing_deg = _centerline(rng, length_m, mast_station_m)
    road = RoadFrame(centerline)
    mast_x, mast_y = road.to_site(mast_station_m, mast_offset_m)
    mast_xy = (float(mast_x), float(mast_y))
    open_lanes = [lane for lane in lanes if lane.index != closed_lane]
    open_centre_m = float(np.mean([lane.center_offset_m for lane in open_lanes]))
    road_centre_m = float(np.mean([lane.center_offset_m for lane in lanes]))

    def road_point(upstream_m: float, offset_m: float) -> tuple[float, float]:
        xy = road.to_site(max(0.0, mast_station_m - upstream_m), offset_m)
        return float(xy[0]), float(xy[1])

    sensors: list[SensorMount] = []
    # LiDAR: level, its azimuth zero down the road.
    model = LIDAR_MODELS[int(rng.integers(len(LIDAR_MODELS)))]
    lidar_yaw = _yaw_deg(mast_xy, road_point(60.0, road_centre_m))
    sensors.append(
        SensorMount(
            sensor_id=_sensor_id(rng, "lidar", model.name),
            pose=Pose(
                x_m=round(mast_xy[0], 3),
                y_m=round(mast_xy[1], 3),
                z_m=round(height_m, 2),
                yaw_deg=round(lidar_yaw, 2),
            ),
            intrinsics=LidarIntrinsics(
                beams=model.beams,
                vertical_min_deg=model.vertical_min_deg,
                vertical_max_deg=model.vertical_max_deg,
                azimuth_steps=model.azimuth_steps,
                max_range_m=model.max_range_m,
            ),
            rate_hz=float(rng.choice([10.0, 20.0])),
        )
    )
    # Camera: aimed at the approach's centre 70-110 m upstream, horizon 22-40 % from the top.
    width_px, height_px = CAMERA_FORMATS[int(rng.integers(len(CAMERA_FORMATS)))]
    hfov_deg = float(rng.uniform(50.0, 100.0))
    focal_px = width_px / 2.0 / math.tan(math.radians(hfov_deg) / 2.0)
    horizon_row = float(rng.uniform(0.22, 0.40)) * height_px
    pitch_deg = -math.degrees(math.atan((height_px / 2.0 - horizon_row) / focal_px))
    camera_yaw = _yaw_deg(mast_xy, road_point(float(rng.uniform(70.0, 110.0)), open_centre_m))
    camera_yaw += float(rng.normal(0.0, 1.0))  # the technician's hand
    # The camera and the radar share a bracket 0.2 m upstream of the LiDAR.
    head_x, head_y = road.to_site(mast_station_m - 0.2, mast_offset_m)
    sensors.append(
        SensorMount(
            sensor_id=_sensor_id(rng, "camera", "cam"),
            pose=Pose(
                x_m=round(float(head_x), 3),
                y_m=round(float(head_y), 3),
                z_m=round(height_m + 0.2, 2),
                yaw_deg=round(camera_yaw, 2),
                pitch_deg=round(pitch_deg, 2),
            ),
            intrinsics=CameraIntrinsics(
                width_px=width_px, height_px=height_px, horizontal_fov_deg=round(hfov_deg, 1)
            ),
            rate_hz=float(rng.choice([10.0, 15.0])),
        )
    )
    # Radar: under the camera, aimed at the approach 100 m upstream.
    radar_yaw = _yaw_deg(mast_xy, road_point(100.0, road_centre_m))
    sensors.append(
        SensorMount(
            sensor_id=_sensor_id(rng, "radar", "radar"),
            pose=Pose(
                x_m=round(float(head_x), 3),
                y_m=round(float(head_y), 3),
                z_m=round(max(2.0, height_m - 1.0), 2),
                yaw_deg=round(radar_yaw, 2),
            ),
            intrinsics=RadarIntrinsics(),
            rate_hz=float(rng.choice([13.0, 15.0, 20.0])),
        )
    )
    ids = [sensor.sensor_id for sensor in sensors]
    if len(set(ids)) != len(ids):  # rare: two draws gave the same name
        sensors = [
            sensor.model_copy(update={"sensor_id": f"{sensor.sensor_id}-{i}"})
            for i, sensor in enumerate(sensors)
        ]

    road_names = [f"SR-{int(rng.integers(1, 999))}"]
    origin = GeoOrigin(
        latitude_deg=round(float(rng.uniform(30.0, 47.0)), 5),
        longitude_deg=round(float(rng.uniform(-120.0, -75.0)), 5),
        altitude_m=round(float(rng.uniform(0.0, 1500.0)), 1),
    )
    # Upstream point speed sensors (drawn last: the draws above stay as they were): one every
    # 200-400 m upstream of the mast to the road's first 50 m, each reporting every 20-60 s.
    # Deployments space them a quarter to half a mile; the simulated approach is shorter.
    spacing_m = float(rng.choice([200.0, 300.0, 400.0]))
    interval_s = float(rng.choice([20.0, 30.0, 60.0]))
    point_stations = np.arange(mast_station_m - spacing_m, 50.0, -spacing_m)
    point_sensors = [
        PointSensor(sensor_id=f"speed-{i + 1}", station_m=round(float(s), 1), interval_s=interval_s)
        for i, s in enumerate(point_stations)
    ]

    return Site(
        site_id=f"gen-{seed}",
        name=(
            f"Generated site {seed}: {lanes_n} to {lanes_n - 1} lanes, {closed_side} lane "
            f"closed, {shape}, {upstream_mph:.0f}/{zone_mph:.0f} mph, mast on the {mast_side} "
            f"{height_m:.1f} m high {taper_start_m - mast_station_m:.0f} m before the taper"
        ),
        road_names=road_names,
        road_direction=_direction(bearing_deg),
        origin=origin,
        centerline_xy_m=centerline,
        lanes=lanes,
        closed_lane_index=closed_lane,
        work_zone=[
            WorkZoneArea(kind=kind, start_station_m=round(start, 1), end_station_m=round(end, 1))
            for kind, start, end in areas
        ],
        speed_limits=[
            SpeedLimit(
                start_station_m=0.0, end_station_m=advance_start_m, speed_limit_mph=upstream_mph
            ),
            SpeedLimit(
                start_station_m=advance_start_m,
                end_station_m=round(termination_end_m, 1),
                speed_limit_mph=zone_mph,
            ),
            SpeedLimit(
                start_station_m=round(termination_end_m, 1),
                end_station_m=round(length_m, 1),
                speed_limit_mph=upstream_mph,
            ),
        ],
        sensors=sensors,
        point_sensors=point_sensors,
        alerts=alert_rules_for(
            zone_limit_mph=zone_mph,
            advance_warning_start_m=advance_start_m,
            activity_end_m=round(activity_end_m, 1),
            taper_start_m=taper_start_m,
        ),
    )
