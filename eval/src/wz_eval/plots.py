"""Plots of ``wz eval`` like the paper's figures (matplotlib, Agg backend, PNG files).

- ``trajectories.png``: for a few vehicles of the paper table, the position each source gave
  (station along the road vs lateral offset): camera markers, LiDAR crosses, fused line, truth
  dashed (the paper's "fused versus single sensor trajectories").
- ``error_vs_position.png``: for one vehicle, the longitudinal error against its true station,
  per source (the paper's per-vehicle error figure).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from wz_eval.pipeline import PipelineRecord
from wz_eval.scores import Scores
from wz_shared.site import Site

STYLE: dict[str, dict[str, Any]] = {
    "camera": {"marker": "o", "linestyle": "none", "markersize": 3, "color": "tab:blue"},
    "lidar": {"marker": "x", "linestyle": "none", "markersize": 4, "color": "tab:orange"},
    "average": {"marker": ".", "linestyle": "none", "markersize": 3, "color": "tab:pink"},
    "paper_kf": {"linestyle": ":", "linewidth": 1.2, "color": "tab:purple"},
    "fused": {"linestyle": "-", "linewidth": 1.5, "color": "tab:green"},
}


def write_plots(
    out_dir: Path, site: Site, record: PipelineRecord, scores: Scores, report: dict[str, Any]
) -> list[str]:
    """Write the PNGs; their file names (relative to ``out_dir``)."""
    rows = sorted(report["paper_table"], key=lambda r: -r["samples"])
    if not rows:
        return []
    chosen = [row["vehicle_id"] for row in rows[:4]]
    out_dir.mkdir(parents=True, exist_ok=True)
    names = []

    figure, axes = plt.subplots(len(chosen), 1, figsize=(9, 2.4 * len(chosen)), squeeze=False)
    for axis, vehicle_id in zip(axes[:, 0], chosen, strict=True):
        by_source = scores.per_vehicle[vehicle_id]
        truth = sorted(
            {(s, d) for samples in by_source.values() for (_, _, s, d) in samples.values()}
        )
        axis.plot([s for s, _ in truth], [d for _, d in truth], "k--", linewidth=0.8, label="truth")
        for source, style in STYLE.items():
            samples = sorted(by_source.get(source, {}).values(), key=lambda v: v[2])
            if samples:
                axis.plot(
                    [s + lon for lon, _, s, _ in samples],
                    [d + lat for _, lat, _, d in samples],
                    label=source,
                    **style,
                )
        axis.set_title(f"vehicle {vehicle_id}", fontsize=9)
        axis.set_ylabel("offset [m]")
    axes[-1, 0].set_xlabel("station along the road [m]")
    axes[0, 0].legend(fontsize=7, ncol=6, loc="upper left")
    figure.tight_layout()
    figure.savefig(out_dir / "trajectories.png", dpi=110)
    plt.close(figure)
    names.append("trajectories.png")

    vehicle_id = chosen[0]
    figure, axis = plt.subplots(figsize=(8, 3.5))
    for source, style in STYLE.items():
        samples = sorted(
            scores.per_vehicle[vehicle_id].get(source, {}).values(), key=lambda v: v[2]
        )
        if samples:
            line_style: dict[str, Any] = {**style, "linestyle": style.get("linestyle", "-")}
            if line_style["linestyle"] == "none":
                line_style["linestyle"] = "-"
                line_style["linewidth"] = 0.6
            axis.plot(
                [s for _, _, s, _ in samples],
                [lon for lon, _, _, _ in samples],
                label=source,
                **line_style,
            )
    axis.axhline(0.0, color="k", linewidth=0.6)
    axis.set_xlabel("true station [m]")
    axis.set_ylabel("longitudinal error [m]")
    axis.set_title(f"vehicle {vehicle_id}: longitudinal error by source", fontsize=9)
    axis.legend(fontsize=7, ncol=5)
    figure.tight_layout()
    figure.savefig(out_dir / "error_vs_position.png", dpi=110)
    plt.close(figure)
    names.append("error_vs_position.png")
    del site, record
    return names
