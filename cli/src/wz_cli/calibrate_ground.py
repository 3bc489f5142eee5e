"""``wz calibrate --frame FILE``: the ground plane under a LiDAR from one of its frames.

No site lanes and no traffic needed: :func:`wz_lidar_detector.calibration.fit_ground` (what the
LiDAR detector's self-calibration runs every few seconds) on one frame (PCD, PLY or NPZ, the
sensor's own frame), from a nominal pose: the site file's LiDAR pose with ``--site``, else a
level sensor at ``--height`` (default: the most common level of the returns below the sensor,
which on a road is the road). It gives the sensor's height above the plane and the plane's
tilt seen from the sensor, as pitch and roll.

The plane is the road's surface, not the horizontal: a carriageway has a cross slope (1.5-2 %,
0.9-1.1 deg) and a crown, and a grade along it; the roll and pitch found are the sensor's tilt
*relative to that surface*, which is what the detectors need (the site frame's ground is the
road), not its tilt against gravity. A single frame of a road that is not one plane gives a
fit that depends a little on where it starts: :attr:`GroundReport.spread` is the same fit
from nominal heights ``SPREAD_M`` around the first, to show how much.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from wz_cli.common import CliError
from wz_shared.site import Pose

#: The fit is repeated from nominal heights this much above and below the first [m] (a
#: technician's tape along a mast is good to a decimetre or two).
SPREAD_M = (-0.5, -0.25, 0.25, 0.5)
#: A plane fitted this loosely is no road surface [m].
SUSPECT_RMS_M = 0.25
#: Levels of the returns' heights for the nominal height's guess [m].
LEVEL_BIN_M = 0.25


@dataclass(frozen=True)
class PlaneFit:
    """One fit: from which nominal height, and what it found (None: too few returns)."""

    nominal_height_m: float
    pitch_deg: float | None = None
    roll_deg: float | None = None
    height_m: float | None = None
    points: int = 0
    rms_m: float | None = None


@dataclass
class GroundReport:
    """The ground plane of one frame."""

    path: Path
    returns: int
    in_range: int
    range_m: tuple[float, float]
    nominal: Pose
    #: How the nominal pose was chosen, for people.
    nominal_from: str
    fit: PlaneFit
    spread: list[PlaneFit] = field(default_factory=list)

    def lines(self) -> list[str]:
        fit = self.fit
        out = [
            f"ground plane under the LiDAR of {self.path}: {self.returns} returns, "
            f"{self.in_range} within {self.range_m[0]:g}-{self.range_m[1]:g} m horizontally",
            f"  nominal pose: {self.nominal_from}",
        ]
        if fit.height_m is None:
            out.append(
                "  NO PLANE: fewer than 200 returns within 1.5 m of the nominal ground "
                "(give the sensor's height with --height)"
            )
            return out
        assert fit.pitch_deg is not None and fit.roll_deg is not None and fit.rms_m is not None
        n = self.nominal
        out += [
            f"  height {fit.height_m:.3f} m above the plane (nominal {n.z_m:.2f} m: "
            f"{fit.height_m - n.z_m:+.3f} m)",
            f"  pitch  {fit.pitch_deg:+.3f} deg, nose up + (nominal {n.pitch_deg:+.2f}: "
            f"{fit.pitch_deg - n.pitch_deg:+.3f} deg)",
            f"  roll   {fit.roll_deg:+.3f} deg, right side down + (nominal {n.roll_deg:+.2f}: "
            f"{fit.roll_deg - n.roll_deg:+.3f} deg)",
            f"  points {fit.points} used in the last fit, rms {100 * fit.rms_m:.1f} cm from "
            "the plane",
        ]
        if fit.rms_m > SUSPECT_RMS_M:
            out.append(
                f"  SUSPECT: {100 * fit.rms_m:.0f} cm rms is no road surface (a start far from "
                "the road's level takes what stands on it): give the height with --height"
            )
        found = [s for s in self.spread if s.height_m is not None]
        if found:
            out.append(
                f"  from nominal heights {min(s.nominal_height_m for s in self.spread):.2f}-"
                f"{max(s.nominal_height_m for s in self.spread):.2f} m the fit gives "
                + _span("height", [s.height_m for s in found], "m", 3)
                + ", "
                + _span("pitch", [s.pitch_deg for s in found], "deg", 2)
                + ", "
                + _span("roll", [s.roll_deg for s in found], "deg", 2)
                + f" ({len(found)} of {len(self.spread)} fits)"
            )
        out.append(
            "  the plane is the road's surface: a road's cross slope (1.5-2 %) and crown make "
            "this roll the sensor's tilt against the road, not against gravity"
        )
        return out

    def as_json(self) -> dict[str, Any]:
        return {
            "path": str(self.path),
            "returns": self.returns,
            "in_range": self.in_range,
            "range_m": list(self.range_m),
            "nominal_pose": self.nominal.model_dump(mode="json"),
            "nominal_from": self.nominal_from,
            "fit": self.fit.__dict__,
            "spread": [s.__dict__ for s in self.spread],
        }


def _span(name: str, values: list[float | None], unit: str, digits: int) -> str:
    numbers = [v for v in values if v is not None]
    return f"{name} {min(numbers):.{digits}f} to {max(numbers):.{digits}f} {unit}"


def level_height(xyz: npt.NDArray[np.floating], range_m: tuple[float, float]) -> float | None:
    """The most common level of the returns within ``range_m`` below the sensor (1 m or more
    down) [m above it, positive]: the road, where a road fills the view; None without any."""
    horizontal = np.hypot(xyz[:, 0], xyz[:, 1])
    z = xyz[(horizontal >= range_m[0]) & (horizontal <= range_m[1]), 2]
    z = z[z <= -1.0]
    if len(z) < 200:
        return None
    low = math.floor(float(z.min()) / LEVEL_BIN_M) * LEVEL_BIN_M
    counts, edges = np.histogram(z, bins=np.arange(low, -1.0 + 1e-9, LEVEL_BIN_M))
    best = int(counts.argmax())
    return -float(0.5 * (edges[best] + edges[best + 1]))


def ground_of_frame(
    path: Path,
    *,
    site_pose: Pose | None = None,
    height_m: float | None = None,
    range_m: tuple[float, float] = (4.0, 40.0),
) -> GroundReport:
    """Fit the ground plane of the frame at ``path`` (see the module docstring).

    Raises
    ------
    CliError
        When the file is missing or is no point cloud (exit code 1).
    """
    from wz_lidar_detector.calibration import fit_ground
    from wz_shared.pointcloud_files import read_point_cloud

    if not path.is_file():
        raise CliError(f"no such LiDAR frame: {path}", 1)
    try:
        frame = read_point_cloud(path)
    except (OSError, ValueError) as exc:
        raise CliError(f"cannot read {path} as a point cloud: {exc}", 1) from exc
    xyz = np.asarray(frame.points[:, :3], dtype=np.float64)
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    horizontal = np.hypot(xyz[:, 0], xyz[:, 1])
    in_range = int(((horizontal >= range_m[0]) & (horizontal <= range_m[1])).sum())
    if site_pose is not None:
        nominal = site_pose.model_copy(update={"z_m": height_m or site_pose.z_m})
        nominal_from = (
            f"the site file's LiDAR pose (height {nominal.z_m:.2f} m, pitch "
            f"{nominal.pitch_deg:+.2f} deg, roll {nominal.roll_deg:+.2f} deg)"
        )
    else:
        if height_m is not None:
            nominal_from = f"level, at the height given ({height_m:.2f} m)"
        else:
            height_m = level_height(xyz, range_m)
            if height_m is None:
                raise CliError(
                    f"{path}: too few returns below the sensor within {range_m[0]:g}-"
                    f"{range_m[1]:g} m to guess its height: give it with --height",
                    1,
                )
            nominal_from = (
                f"level, at {height_m:.2f} m: the most common level of the returns below the "
                "sensor (--height to give it)"
            )
        nominal = Pose(x_m=0.0, y_m=0.0, z_m=height_m)

    def fit_from(height: float) -> PlaneFit:
        start = nominal.model_copy(update={"z_m": height})
        found = fit_ground(xyz, start, range_m=range_m)
        if found is None:
            return PlaneFit(height)
        return PlaneFit(
            height,
            found.pitch_deg,
            found.roll_deg,
            found.height_m,
            found.points,
            found.rms_m,
        )

    return GroundReport(
        path=path,
        returns=len(xyz),
        in_range=in_range,
        range_m=range_m,
        nominal=nominal,
        nominal_from=nominal_from,
        fit=fit_from(nominal.z_m),
        spread=[fit_from(nominal.z_m + step) for step in SPREAD_M if nominal.z_m + step > 0.5],
    )
