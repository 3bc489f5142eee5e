"""Issue 25's out-of-sample run: the whole pipeline on 12 generated sites, 300 s each.

``wz eval --sites 12 --seed 9100 --duration-s 300 --warmup-s 60`` (:func:`wz_eval.sites.
run_sites`): sites 9100-9111, seeds no development run used (development: 15, 100-119,
200-247 for the camera model, 3000-3199, 5000-5007, 900-901; 7000-7003 were an earlier
out-of-sample run). Each site is simulated (SUMO, the three sensors, both detectors in one
process), the fused tracks and alerts scored against the truth, one process per core. The
weather cycles day, dusk, rain, fog; 1200-2000 veh/h and 15-30 % trucks are drawn from the
seed. The result: each target's distribution over the sites (how many meet it, median, worst)
and each site's figures. ``--quick``: two sites of 60 s (seed 9100).

It takes about 65 minutes on the 2-core machine of BENCHMARKS.md. ``WZ_BENCH_SITES_FROM=DIR``
takes the ``sites.json`` of a finished run of the same command in ``DIR`` instead of running
it again (it must have the same count, seed, duration and warm-up; the entry says where it
came from and when that file was written).
"""

from __future__ import annotations

import datetime
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from wz_eval.sites import run_sites

COUNT, SEED, DURATION_S, WARMUP_S = 12, 9100, 300.0, 60.0
QUICK = (2, 9100, 60.0, 30.0)


def summary(report: dict[str, Any]) -> dict[str, Any]:
    """What BENCHMARKS.md shows: the distribution and each site's row (no pictures)."""
    keep = (
        "site_id",
        "name",
        "weather",
        "vehicles_per_hour",
        "truck_share",
        "vehicles",
        "figures",
        "failed",
        "missed_upstream",
        "missed_downstream",
        "approach_mota",
        "approach_switches_per_100",
        "covered_downstream",
        "circle_mota",
    )
    return {
        "count": report["count"],
        "seed": report["seed"],
        "duration_s": report["duration_s"],
        "warmup_s": report["warmup_s"],
        "distribution": report["distribution"],
        "sites": [{k: row.get(k) for k in keep} for row in report["sites"]],
        "sites_meeting_every_target": sum(1 for row in report["sites"] if not row["failed"]),
    }


def run(quick: bool) -> dict[str, Any]:
    count, seed, duration_s, warmup_s = QUICK if quick else (COUNT, SEED, DURATION_S, WARMUP_S)
    source = os.environ.get("WZ_BENCH_SITES_FROM")
    if source and not quick:
        path = Path(source) / "sites.json"
        report = json.loads(path.read_text())
        asked = (count, seed, duration_s, warmup_s)
        found = (report["count"], report["seed"], report["duration_s"], report["warmup_s"])
        if found != asked:
            raise ValueError(f"{path}: a run of {found}, not of {asked} (count, seed, s, warm-up)")
        written = datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.UTC)
        result = summary(report)
        result["taken_from"] = {"path": str(path), "written_at": written.isoformat("T", "seconds")}
        return result
    with tempfile.TemporaryDirectory(prefix="wz-bench-sites-") as tmp:
        report = run_sites(count, seed, duration_s, warmup_s, Path(tmp))
    return summary(report)
