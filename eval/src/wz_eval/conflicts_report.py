"""Traffic conflicts (SSAM's surrogate safety measures, :mod:`wz_gateway.conflicts`) found in
the fused tracks the tracker published and in the simulation's truth, for ``wz eval``.

The report counts the conflicts of each SSAM type on both and writes SSAM's conflict table of
each (``conflicts-tracks.csv``, ``conflicts-truth.csv``) beside ``eval.json``. Truth vehicles
have their true size, heading and acceleration; tracks their estimated size (a car's where the
tracker has none) and accelerations from their speeds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from wz_gateway.conflicts import (
    Conflict,
    ConflictSettings,
    Trajectories,
    count_by_type,
    find_conflicts,
    ssam_csv,
    trajectories,
)
from wz_shared.messages import TrackBatch, VehicleTruth

TRACKS_CSV = "conflicts-tracks.csv"
TRUTH_CSV = "conflicts-truth.csv"


def track_trajectories(batches: Sequence[TrackBatch]) -> Trajectories:
    """Every published track state, the track id as the vehicle id."""
    rows = [(b.stamp, t) for b in batches for t in b.tracks]
    return trajectories(
        [str(t.track_id) for _, t in rows],
        [stamp for stamp, _ in rows],
        [t.x_m for _, t in rows],
        [t.y_m for _, t in rows],
        [t.vx_mps for _, t in rows],
        [t.vy_mps for _, t in rows],
        [t.heading_rad for _, t in rows],
        length_m=[t.length_m for _, t in rows],
        width_m=[t.width_m for _, t in rows],
        lane_index=[t.lane_index for _, t in rows],
    )


def truth_trajectories(truth: Sequence[tuple[float, Sequence[VehicleTruth]]]) -> Trajectories:
    """Every true vehicle state, velocity from speed and heading."""
    rows = [(stamp, v) for stamp, vehicles in truth for v in vehicles]
    return trajectories(
        [v.vehicle_id for _, v in rows],
        [stamp for stamp, _ in rows],
        [v.x_m for _, v in rows],
        [v.y_m for _, v in rows],
        [v.speed_mps * math.cos(v.heading_rad) for _, v in rows],
        [v.speed_mps * math.sin(v.heading_rad) for _, v in rows],
        [v.heading_rad for _, v in rows],
        length_m=[v.length_m for _, v in rows],
        width_m=[v.width_m for _, v in rows],
        lane_index=[v.lane_index for _, v in rows],
        accel_mps2=[v.accel_mps2 for _, v in rows],
    )


def _summary(conflicts: Sequence[Conflict]) -> dict[str, Any]:
    ttc = [c.ttc_s for c in conflicts]
    pet = [c.pet_s for c in conflicts if c.pet_s is not None]
    return {
        "count": len(conflicts),
        "by_type": count_by_type(conflicts),
        "min_ttc_s": round(min(ttc), 3) if ttc else None,
        "min_pet_s": round(min(pet), 3) if pet else None,
    }


def conflict_report(
    batches: Sequence[TrackBatch],
    truth: Sequence[tuple[float, Sequence[VehicleTruth]]],
    out_dir: Path | None = None,
    settings: ConflictSettings | None = None,
) -> dict[str, Any]:
    """Conflicts by type on the tracks and on the truth; SSAM's tables written in ``out_dir``
    (none written when it is None)."""
    settings = settings or ConflictSettings()
    on_tracks = find_conflicts(track_trajectories(batches), settings)
    on_truth = find_conflicts(truth_trajectories(truth), settings)
    report: dict[str, Any] = {
        "max_ttc_s": settings.max_ttc_s,
        "max_pet_s": settings.max_pet_s,
        "tracks": _summary(on_tracks),
        "truth": _summary(on_truth),
    }
    if out_dir is not None:
        (out_dir / TRACKS_CSV).write_text(ssam_csv(on_tracks, "tracks"), encoding="utf-8")
        (out_dir / TRUTH_CSV).write_text(ssam_csv(on_truth, "truth"), encoding="utf-8")
        report["ssam_csv"] = {"tracks": TRACKS_CSV, "truth": TRUTH_CSV}
    return report
