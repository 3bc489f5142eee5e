"""Pictures a person can look at: what the simulated sensors see, with their truth.

``wz pictures --out docs/images`` (or ``python -m wz_simulator.pictures``) runs the work zone
for a warm-up and writes, from one instant:

- ``camera-truth.jpg``: the mast camera's frame with each vehicle's truth box, id, class and
  visibility fraction;
- ``camera-weather.jpg``: the same instant under day, dusk, rain and fog (2 x 2);
- ``lidar-top-view.png``: the LiDAR frame from above, static returns grey, each vehicle's points
  in its own colour with its truth box outlined, rings every 25 m.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from wz_shared.logs import configure_logging
from wz_shared.messages import VehicleTruth
from wz_shared.site import Site, load_site
from wz_simulator.sensors.camera import draw_truth
from wz_simulator.sensors.lidar import LidarScan
from wz_simulator.sensors.rig import CameraOutput, LidarOutput, SensorRig
from wz_simulator.sensors.scene import WEATHER_PRESETS, StaticScene, static_scene
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

log = logging.getLogger(__name__)

#: Distinct colours (BGR) for vehicle labels.
PALETTE = np.array(
    [
        (75, 25, 230),
        (75, 180, 60),
        (25, 225, 255),
        (200, 130, 0),
        (48, 130, 245),
        (180, 30, 145),
        (240, 240, 70),
        (230, 50, 240),
        (60, 245, 210),
        (212, 190, 250),
        (128, 128, 0),
        (255, 190, 220),
        (40, 110, 170),
        (200, 250, 255),
        (0, 0, 128),
        (195, 255, 170),
        (0, 128, 128),
        (180, 215, 255),
        (128, 0, 0),
    ],
    dtype=np.uint8,
)


def lidar_top_view(
    scan: LidarScan, size_px: int = 1000, extent_m: float = 100.0
) -> npt.NDArray[np.uint8]:
    """A bird's-eye image of a LiDAR frame in its sensor frame (x forward up, y left left).

    Parameters
    ----------
    scan
        The frame (points in the sensor frame, labels, truth boxes).
    size_px
        Image side [px].
    extent_m
        Half-width of the square shown around the sensor [m].
    """
    image = np.full((size_px, size_px, 3), 18, dtype=np.uint8)
    scale = size_px / (2.0 * extent_m)
    centre = size_px / 2.0

    def to_px(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
        # Sensor x (forward) points up the image, y (left) to the left.
        return np.column_stack([centre - y * scale, centre - x * scale]).astype(np.int32)

    for radius_m in range(25, int(extent_m * 1.5), 25):
        cv2.circle(image, (int(centre), int(centre)), int(radius_m * scale), (60, 60, 60), 1)
        cv2.putText(
            image,
            f"{radius_m} m",
            (int(centre) + 4, int(centre - radius_m * scale) - 4),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.4,
            (110, 110, 110),
            1,
            cv2.LINE_AA,
        )
    points = scan.points
    valid = np.isfinite(points[:, 0])
    xy = to_px(points[valid, 0].astype(np.float64), points[valid, 1].astype(np.float64))
    labels = scan.labels[valid]
    inside = (xy[:, 0] >= 0) & (xy[:, 0] < size_px) & (xy[:, 1] >= 0) & (xy[:, 1] < size_px)
    xy, labels = xy[inside], labels[inside]
    static = labels == 0
    image[xy[static, 1], xy[static, 0]] = (150, 150, 150)
    moving = ~static
    colours = PALETTE[(labels[moving] - 1) % len(PALETTE)]
    for dy in (0, 1):  # 2x2 dots so vehicle points stand out
        for dx in (0, 1):
            ys = np.clip(xy[moving, 1] + dy, 0, size_px - 1)
            xs = np.clip(xy[moving, 0] + dx, 0, size_px - 1)
            image[ys, xs] = colours
    for box in scan.boxes:
        colour = tuple(int(c) for c in PALETTE[(box.label - 1) % len(PALETTE)])
        length, width, _ = box.size_lwh_m
        cx, cy, _ = box.center_sensor_m
        c, s = np.cos(box.yaw_sensor_rad), np.sin(box.yaw_sensor_rad)
        local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [0.5 * length, 0.5 * width]
        corners = local @ np.array([[c, s], [-s, c]]) + [cx, cy]
        polygon = to_px(corners[:, 0], corners[:, 1])
        cv2.polylines(image, [polygon], True, colour, 1, cv2.LINE_AA)
        if box.num_points:
            x0, y0 = polygon.min(axis=0)
            cv2.putText(
                image,
                f"{box.vehicle_id} ({box.num_points})",
                (int(x0), int(y0) - 3),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.35,
                colour,
                1,
                cv2.LINE_AA,
            )
    cv2.drawMarker(image, (int(centre), int(centre)), (255, 255, 255), cv2.MARKER_CROSS, 12)
    cv2.putText(
        image,
        "forward (sensor x)",
        (int(centre) + 8, 16),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.45,
        (200, 200, 200),
        1,
        cv2.LINE_AA,
    )
    return image


def simulate_instant(
    site: Site, seed: int, warmup_s: float, vehicles_per_hour: float
) -> tuple[list[VehicleTruth], float]:
    """Truth after ``warmup_s`` of simulated traffic (as fast as possible)."""
    settings = SimulatorSettings(
        seed=seed,
        realtime_factor=0.0,
        sensors_enabled=False,
        vehicles_per_hour=vehicles_per_hour,
        truck_share=0.25,
        duration_s=warmup_s,
    )
    vehicles: list[VehicleTruth] = []
    with TrafficWorld(site, settings) as world:
        while not world.finished:
            vehicles = world.step()
        return vehicles, world.sim_time_s


def write_pictures(
    site: Site,
    out_dir: Path,
    seed: int = 5,
    warmup_s: float = 75.0,
    vehicles_per_hour: float = 2000.0,
    scene: StaticScene | None = None,
) -> list[Path]:
    """Write the three pictures; return their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    vehicles, now_s = simulate_instant(site, seed, warmup_s, vehicles_per_hour)
    scene = scene if scene is not None else static_scene(site)
    camera_id = next(m.sensor_id for m in site.sensors if m.kind == "camera")
    lidar_id = next(m.sensor_id for m in site.sensors if m.kind == "lidar")
    written = []
    tiles = []
    for weather in ("day", "dusk", "rain", "fog"):
        rig = SensorRig(
            site, WEATHER_PRESETS[weather], seed, sensor_ids=[camera_id, lidar_id], scene=scene
        )
        camera = rig.capture(camera_id, 0, now_s, vehicles, now_s)
        assert isinstance(camera, CameraOutput)
        if weather == "day":
            path = out_dir / "camera-truth.jpg"
            cv2.imwrite(
                str(path),
                draw_truth(camera.frame.image, list(camera.frame.labels)),
                [cv2.IMWRITE_JPEG_QUALITY, 88],
            )
            written.append(path)
            lidar = rig.capture(lidar_id, 0, now_s, vehicles, now_s)
            assert isinstance(lidar, LidarOutput)
            path = out_dir / "lidar-top-view.png"
            cv2.imwrite(str(path), lidar_top_view(lidar.scan))
            written.append(path)
        tile = cv2.resize(camera.frame.image, (600, 600), interpolation=cv2.INTER_AREA)
        cv2.putText(
            tile, weather, (16, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.1, (255, 255, 255), 2, cv2.LINE_AA
        )
        tiles.append(tile)
    montage = np.vstack([np.hstack(tiles[:2]), np.hstack(tiles[2:])])
    path = out_dir / "camera-weather.jpg"
    cv2.imwrite(str(path), montage, [cv2.IMWRITE_JPEG_QUALITY, 85])
    written.append(path)
    return written


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="wz pictures",
        description="Write pictures of what the simulated sensors see, with their truth.",
    )
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    parser.add_argument("--site", type=Path, default=SimulatorSettings().site_file)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--warmup-s", type=float, default=75.0)
    args = parser.parse_args(argv)
    site = load_site(args.site)
    configure_logging(service="pictures", site=site.site_id)
    for path in write_pictures(site, args.out, seed=args.seed, warmup_s=args.warmup_s):
        sys.stdout.write(f"{path}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
