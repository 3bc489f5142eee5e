"""``wz site``: generate seeded work-zone sites and draw a site's plan.

Usage::

    wz site generate --seed N --out FILE.yaml     # one seeded site (wz_shared.site_generator)
    wz site show FILE.yaml --out site.png         # its plan: road, areas, mast, coverage

The plan is drawn in the site frame (metres, north up): the lanes and their lines, the closed
lane hatched from the taper to the end of the work zone, the work-zone areas' boundaries, the
mast, the LiDAR's range ring and the ring to which it sees a car in clear air (:mod:`wz_shared.coverage`), the radar's wedge and the camera's footprint on the road (the
image's edges projected onto the ground, out to 200 m). A second panel zooms on the mast.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import numpy as np
import yaml

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.patches import Circle

from wz_shared.arrays import F64
from wz_shared.camera_geometry import PinholeCamera
from wz_shared.coverage import lidar_car_ranges_m
from wz_shared.site import AreaKind, RadarIntrinsics, Site, SiteFileError, load_site
from wz_shared.site_generator import generate_site

AREA_COLOURS = {
    AreaKind.ADVANCE_WARNING: "#f2c94c",
    AreaKind.TRANSITION: "#f2994a",
    AreaKind.BUFFER: "#bdbdbd",
    AreaKind.ACTIVITY: "#eb5757",
    AreaKind.TERMINATION: "#6fcf97",
}
SENSOR_COLOURS = {"lidar": "tab:orange", "camera": "tab:blue", "radar": "tab:green"}
#: How far the camera footprint is drawn [m].
CAMERA_RANGE_M = 200.0


def site_yaml(site: Site) -> str:
    """The site as the YAML a site file holds (round-trips through :func:`load_site`)."""
    data = site.model_dump(mode="json", exclude_none=True)
    header = (
        f"# {site.name}\n# Made by `wz site generate`; edit freely, then check with "
        "`wz site show`.\n"
    )
    return header + yaml.safe_dump(data, sort_keys=False, width=100)


def _lane_edges(site: Site) -> list[float]:
    lanes = sorted(site.lanes, key=lambda lane: lane.index)
    edges = [lanes[0].center_offset_m - lanes[0].width_m / 2.0]
    edges += [lane.center_offset_m + lane.width_m / 2.0 for lane in lanes]
    return edges


def _line(site: Site, offset_m: float, start_m: float, end_m: float) -> F64:
    stations = np.linspace(start_m, end_m, max(2, int((end_m - start_m) / 5.0)))
    x, y = site.road_frame.to_site(stations, np.full_like(stations, offset_m))
    return np.column_stack([x, y])


def _camera_footprint(site: Site, mount_index: int) -> F64 | None:
    """The camera's view on the ground: the image border back-projected to z = 0, clipped to
    ``CAMERA_RANGE_M`` (rows above the horizon end there)."""
    mount = site.sensors[mount_index]
    camera = PinholeCamera(mount)
    w, h = camera.width_px, camera.height_px
    border = np.concatenate(
        [
            np.column_stack([np.linspace(0, w, 40), np.full(40, h)]),
            np.column_stack([np.full(40, w), np.linspace(h, 0, 40)]),
            np.column_stack([np.linspace(w, 0, 40), np.zeros(40)]),
            np.column_stack([np.zeros(40), np.linspace(0, h, 40)]),
        ]
    )
    centre = camera.position_m[:2]
    ground = camera.ground_point(border)[:, :2]  # NaN at and above the horizon
    rays = camera.pixel_to_ray(border)[:, :2]
    reach = np.hypot(rays[:, 0], rays[:, 1])
    far = np.isnan(ground[:, 0]) | (np.hypot(*(ground - centre).T) > CAMERA_RANGE_M)
    clipped = centre + CAMERA_RANGE_M * rays / np.where(reach > 1e-9, reach, np.inf)[:, None]
    points = np.where(far[:, None], clipped, ground)[(~far) | (reach > 1e-9)]
    return points if len(points) else None


def _draw(ax: Axes, site: Site, *, zoom: bool) -> None:
    length = site.road_length_m
    closed = site.lane(site.closed_lane_index)
    taper = site.area(AreaKind.TRANSITION)
    zone_end = max(area.end_station_m for area in site.work_zone)
    # Closed lane, hatched from the taper on.
    half = closed.width_m / 2.0
    right = _line(site, closed.center_offset_m - half, taper.start_station_m, zone_end)
    left = _line(site, closed.center_offset_m + half, taper.start_station_m, zone_end)
    polygon = np.concatenate([right, left[::-1]])
    ax.fill(
        polygon[:, 0],
        polygon[:, 1],
        facecolor="none",
        hatch="///",
        edgecolor="tab:red",
        linewidth=0.0,
        label=f"closed lane {closed.index}",
    )
    edges = _lane_edges(site)
    for i, offset in enumerate(edges):
        line = _line(site, offset, 0.0, length)
        outer = i in (0, len(edges) - 1)
        ax.plot(
            line[:, 0],
            line[:, 1],
            color="k",
            linewidth=1.2 if outer else 0.6,
            linestyle="-" if outer else (0, (4, 6)),
        )
    for area in site.work_zone:
        stations = np.array([area.start_station_m])
        lo, hi = edges[0] - 2.0, edges[-1] + 2.0
        x0, y0 = site.road_frame.to_site(stations, np.array([lo]))
        x1, y1 = site.road_frame.to_site(stations, np.array([hi]))
        ax.plot(
            [x0[0], x1[0]],
            [y0[0], y1[0]],
            color=AREA_COLOURS[area.kind],
            linewidth=2.5,
            label=f"{area.kind.value} from {area.start_station_m:.0f} m",
        )
    start = site.road_frame.to_site(np.array([0.0]), np.array([0.0]))
    ax.annotate("traffic", (float(start[0][0]), float(start[1][0])), fontsize=8)
    for index, mount in enumerate(site.sensors):
        colour = SENSOR_COLOURS[mount.kind]
        x, y = mount.pose.x_m, mount.pose.y_m
        if mount.kind == "lidar":
            ring = getattr(mount.intrinsics, "max_range_m", 200.0)
            ax.add_patch(
                Circle(
                    (x, y),
                    ring,
                    fill=False,
                    color=colour,
                    linestyle="--",
                    label=f"{mount.sensor_id} ({ring:.0f} m)",
                )
            )
            car_reach = lidar_car_ranges_m(mount)
            if car_reach is not None:
                ax.add_patch(
                    Circle(
                        (x, y),
                        car_reach[1],
                        fill=False,
                        color=colour,
                        linestyle="-",
                        linewidth=1.2,
                        label=f"{mount.sensor_id}: sees a car to {car_reach[1]:.0f} m (clear air)",
                    )
                )
        elif mount.kind == "radar" and isinstance(mount.intrinsics, RadarIntrinsics):
            heading = mount.pose.ground_heading_rad()
            half_fov = math.radians(mount.intrinsics.horizontal_fov_deg) / 2.0
            angles = np.linspace(heading - half_fov, heading + half_fov, 30)
            reach = mount.intrinsics.max_range_m
            wedge = np.concatenate(
                [
                    [[x, y]],
                    np.column_stack([x + reach * np.cos(angles), y + reach * np.sin(angles)]),
                    [[x, y]],
                ]
            )
            ax.plot(
                wedge[:, 0],
                wedge[:, 1],
                color=colour,
                linewidth=0.8,
                label=f"{mount.sensor_id} ({mount.intrinsics.horizontal_fov_deg:.0f} deg)",
            )
        elif mount.kind == "camera":
            footprint = _camera_footprint(site, index)
            if footprint is not None:
                ax.fill(
                    footprint[:, 0],
                    footprint[:, 1],
                    color=colour,
                    alpha=0.15,
                    label=f"{mount.sensor_id} view (to {CAMERA_RANGE_M:.0f} m)",
                )
    mast = site.sensors[0].pose if site.sensors else None
    if mast is not None:
        ax.plot([mast.x_m], [mast.y_m], marker="^", color="k", markersize=8, label="mast")
    ax.set_aspect("equal")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    if zoom and mast is not None:
        ax.set_xlim(mast.x_m - 220.0, mast.x_m + 220.0)
        ax.set_ylim(mast.y_m - 220.0, mast.y_m + 220.0)
    ax.grid(True, linewidth=0.3)


def draw_site(site: Site, out: Path) -> None:
    """Write the plan picture of ``site`` to ``out`` (PNG)."""
    figure, (whole, near) = plt.subplots(1, 2, figsize=(15, 7.5))
    _draw(whole, site, zoom=False)
    whole.set_title("the site")
    _draw(near, site, zoom=True)
    near.set_title("around the mast (440 m square)")
    handles, labels = near.get_legend_handles_labels()
    near.legend(handles, labels, fontsize=7, loc="upper right")
    figure.suptitle(f"{site.site_id}: {site.name}", fontsize=9)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=110)
    plt.close(figure)


def _seed(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a non-negative integer, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="wz site", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    generate = commands.add_parser("generate", help="write one seeded site file")
    generate.add_argument("--seed", type=_seed, required=True)
    generate.add_argument("--out", type=Path, required=True, help="the site file (.yaml)")
    generate.add_argument("--picture", type=Path, default=None, help="also draw it (PNG)")
    show = commands.add_parser("show", help="draw a site file's plan")
    show.add_argument("site", type=Path)
    show.add_argument("--out", type=Path, required=True, help="the picture (.png)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "generate":
            site = generate_site(args.seed)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(site_yaml(site), encoding="utf-8")
            load_site(args.out)  # what was written reads back
            sys.stdout.write(f"{args.out}: {site.name}\n")
            if args.picture is not None:
                draw_site(site, args.picture)
            return 0
        site = load_site(args.site)
        draw_site(site, args.out)
        sys.stdout.write(f"{args.out}: {site.name}\n")
        return 0
    except (SiteFileError, OSError) as exc:
        sys.stderr.write(f"wz site: {exc}\n")
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
