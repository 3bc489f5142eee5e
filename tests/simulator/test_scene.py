"""The sensors' scene: vehicle bodies from truth, the static work zone from the site file."""

from __future__ import annotations

import numpy as np
import pytest

from wz_shared.messages import VehicleTruth
from wz_shared.site import DEFAULT_SITE_PATH, AreaKind, load_site
from wz_simulator.sensors.scene import Box, Material, static_scene, vehicle_boxes

SITE = load_site(DEFAULT_SITE_PATH)


def truth(
    vehicle_class: str,
    length: float,
    width: float,
    height: float,
    heading: float = 0.7,
    speed: float = 25.0,
) -> VehicleTruth:
    return VehicleTruth(
        vehicle_id="veh7",
        vehicle_class=vehicle_class,
        x_m=10.0,
        y_m=-4.0,
        heading_rad=heading,
        speed_mps=speed,
        accel_mps2=0.0,
        length_m=length,
        width_m=width,
        height_m=height,
        lane_index=0,
        station_m=0.0,
        offset_m=0.0,
        driver_profile="normal",
    )


def in_vehicle_frame(vehicle: VehicleTruth, points: np.ndarray, dt: float = 0.0) -> np.ndarray:
    c, s = np.cos(vehicle.heading_rad), np.sin(vehicle.heading_rad)
    origin = np.array(
        [vehicle.x_m + vehicle.speed_mps * dt * c, vehicle.y_m + vehicle.speed_mps * dt * s]
    )
    rel = points[:, :2] - origin
    return np.column_stack([rel @ [c, s], rel @ [-s, c], points[:, 2]])


@pytest.mark.parametrize(
    ("cls", "size"),
    [("car", (4.6, 1.8, 1.5)), ("truck", (16.5, 2.6, 4.0)), ("bus", (12, 2.5, 3.2))],
)
def test_vehicle_body_fills_its_truth_box(cls: str, size: tuple[float, float, float]) -> None:
    vehicle = truth(cls, *size)
    for dt in (0.0, 0.04):
        boxes = vehicle_boxes([vehicle], dt_s=dt)
        assert all(box.label == 1 for box in boxes)
        corners = np.vstack([box.corners() for box in boxes])
        local = in_vehicle_frame(vehicle, corners, dt)
        length, width, height = size
        # Within the truth box ...
        assert np.all(np.abs(local[:, 0]) <= 0.5 * length + 1e-9)
        assert np.all(np.abs(local[:, 1]) <= 0.5 * width + 1e-9)
        assert local[:, 2].min() == pytest.approx(0.0) and local[:, 2].max() == pytest.approx(
            height
        )
        # ... and filling it: bumper to bumper, side to side.
        assert local[:, 0].max() - local[:, 0].min() >= length - 1e-6
        assert local[:, 1].max() - local[:, 1].min() == pytest.approx(width)
        materials = {box.material for box in boxes}
        assert {Material.GLASS, Material.TIRE} <= materials


def test_truck_has_a_gap_under_its_trailer() -> None:
    vehicle = truth("truck", 16.5, 2.6, 4.0)
    trailer = max(vehicle_boxes([vehicle]), key=lambda box: box.size_lwh_m[0])
    assert trailer.center_xyz_m[2] - 0.5 * trailer.size_lwh_m[2] == pytest.approx(1.2)


def test_labels_follow_the_truth_order_and_colour_is_stable() -> None:
    a, b = truth("car", 4.6, 1.8, 1.5), truth("truck", 16.5, 2.6, 4.0)
    boxes = vehicle_boxes([a, b])
    assert {box.label for box in boxes} == {1, 2}
    assert (
        vehicle_boxes([a])[0].color_rgb
        == vehicle_boxes([b, a])[[box.label for box in vehicle_boxes([b, a])].index(2)].color_rgb
    )


def test_box_corners_closed_form() -> None:
    box = Box((1.0, 2.0, 0.5), (4.0, 2.0, 1.0), np.pi / 2, Material.METAL, (0, 0, 0))
    corners = box.corners()
    # Length along +y after a 90 degree yaw: x spans +-1 (width), y spans +-2 (length).
    assert corners[:, 0].min() == pytest.approx(0.0) and corners[:, 0].max() == pytest.approx(2.0)
    assert corners[:, 1].min() == pytest.approx(0.0) and corners[:, 1].max() == pytest.approx(4.0)
    assert corners[:, 2].min() == pytest.approx(0.0) and corners[:, 2].max() == pytest.approx(1.0)


def test_static_scene_places_the_work_zone_from_the_site() -> None:
    scene = static_scene(SITE)
    frame = SITE.road_frame
    drums = [box for box in scene.boxes if box.material == Material.DRUM]
    centres = np.array([box.center_xyz_m for box in drums])
    s, d = frame.to_road(centres[:, 0], centres[:, 1])
    taper = SITE.area(AreaKind.TRANSITION)
    in_taper = (s >= taper.start_station_m - 1e-6) & (s <= taper.end_station_m + 1e-6)
    assert in_taper.sum() >= 10
    # The taper's drums run from the closed lane's far edge to the lane line, monotonically.
    order = np.argsort(s[in_taper])
    d_taper = d[in_taper][order]
    assert np.all(np.diff(d_taper) < 0)
    closed = SITE.lane(SITE.closed_lane_index)
    assert d_taper[0] == pytest.approx(closed.center_offset_m + 0.5 * closed.width_m + 0.4)
    assert d_taper[-1] == pytest.approx(0.4)
    # Nothing static stands in the open lane.
    boxes = np.array([box.center_xyz_m for box in scene.boxes])
    _, d_all = frame.to_road(boxes[:, 0], boxes[:, 1])
    open_lane = SITE.lane(0)
    assert not np.any(np.abs(d_all - open_lane.center_offset_m) < 0.5 * open_lane.width_m - 0.3)
    # Concrete barrier along the activity area, guardrail and signs on the right.
    assert any(box.material == Material.CONCRETE for box in scene.boxes)
    assert sum(box.material == Material.SIGN for box in scene.boxes) >= 2
    kinds = {polygon.material for polygon in scene.ground}
    assert kinds == {Material.GRASS, Material.ASPHALT, Material.MARKING}
    assert all(box.label == 0 for box in scene.boxes)


def test_static_scene_is_reproducible() -> None:
    first, second = static_scene(SITE), static_scene(SITE)
    assert first.boxes == second.boxes
