"""``wz eval --sites N --seed S``: the pipeline on N generated sites, one report.

Site ``i`` (0-based) is :func:`~wz_shared.site_generator.generate_site` of seed ``S + i``,
simulated with the same seed under conditions that cycle and vary with it: the weather day,
dusk, rain, fog in turn, 15-30 % trucks, and the demand drawn from the seed by ``--traffic``:

- ``volume`` (the default, as before): 1200-2000 veh/h whatever the site's lanes;
- ``free-flow``: 0.5-0.85 of the closure's capacity (:mod:`wz_shared.capacity`), steady;
- ``congested``: a ramp (:func:`wz_eval.pipeline.ramp_settings`) peaking at 1.05-1.3 of it, so
  a queue forms from the taper and dissolves inside the scored time.
 Sites run in
parallel, one process per core (``--jobs``). Each site's folder holds its site file, its plan
picture and its ``wz eval`` report; ``sites.json`` and ``sites.md`` hold, per site and in
distribution, the accuracy, tracking and alert figures against the targets of
:data:`SITE_TARGETS`, and the worst site's figures and picture. ``--resume`` reuses the sites
that a run cut short already finished in ``--out`` (same site file, seed, conditions and
durations), so a long run can be taken up again. ``--mount-errors`` renders every site's
sensors as a real mast's (:mod:`wz_simulator.sensors.mast`, drawn from the site's seed), as
``wz eval --mount-errors`` does; each site's report states what was drawn.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import statistics
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from wz_eval.arguments import not_negative, positive

log = logging.getLogger("wz_eval.sites")

WEATHER_CYCLE = ("day", "dusk", "rain", "fog")
#: Scoring is over 5 minutes for the false hard-braking rate [s].
FIVE_MINUTES_S = 300.0


@dataclass(frozen=True)
class Target:
    """One figure of a site's report and its bound."""

    name: str
    value: Callable[[dict[str, Any]], float | None]
    bound: float
    at_most: bool

    def holds(self, value: float | None) -> bool | None:
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return None
        return value <= self.bound if self.at_most else value >= self.bound

    @property
    def text(self) -> str:
        return f"{'<=' if self.at_most else '>='} {self.bound:g}"


def _alert(kind: str, figure: str) -> Callable[[dict[str, Any]], float | None]:
    def value(report: dict[str, Any]) -> float | None:
        row = report.get("alerts", {}).get(kind, {})
        number = row.get(figure)
        if number is None and row.get("truth_episodes", 0) == 0 and row.get("alerts", 0) == 0:
            return None  # no episode either way: precision and recall cannot tell
        return None if number is None else float(number)

    return value


def _false_hard_braking(report: dict[str, Any]) -> float | None:
    row = report.get("alerts", {}).get("hard_braking", {})
    if "false_positives" not in row:
        return None
    return float(row["false_positives"]) * FIVE_MINUTES_S / float(report["duration_s"])


def _queue(key: str, figure: str) -> Callable[[dict[str, Any]], float | None]:
    """A figure of the queue's scoring (:mod:`wz_eval.queue_report`); None without a queue."""

    def value(report: dict[str, Any]) -> float | None:
        number = ((report.get("queue") or {}).get(key) or {}).get(figure)
        return None if number is None else float(number)

    return value


def _fused(key: str) -> Callable[[dict[str, Any]], float | None]:
    def value(report: dict[str, Any]) -> float | None:
        number = report["sources"]["fused"].get(key)
        return None if number is None else float(number)

    return value


#: The site issue's targets (issue 25's must-show list), each on every site.
SITE_TARGETS: tuple[Target, ...] = (
    Target("fused RMSE longitudinal [m]", _fused("rmse_longitudinal_m"), 0.5, True),
    Target("fused RMSE lateral [m]", _fused("rmse_lateral_m"), 0.3, True),
    Target("fused RMSE speed [m/s]", _fused("rmse_speed_mps"), 0.5, True),
    Target("MOTA", lambda r: float(r["mota"]), 0.95, False),
    Target(
        "switches / 100 vehicles", lambda r: float(r["id_switches_per_100_vehicles"]), 1.0, True
    ),
    Target("speeding precision", _alert("speeding", "precision"), 0.9, False),
    Target("speeding recall", _alert("speeding", "recall"), 0.9, False),
    Target("late-merge precision", _alert("late_merge", "precision"), 0.9, False),
    Target("late-merge recall", _alert("late_merge", "recall"), 0.9, False),
    Target("false hard braking / 5 min", _false_hard_braking, 1.0, True),
    Target(
        "mast-stretch speed / approach",
        lambda r: (r.get("mast_stretch") or {}).get("ratio"),
        1.5,
        True,
    ),
    Target("queue back error median [m]", _queue("back_error_m", "median"), 15.0, True),
    Target("queue onset delay median [s]", _queue("onset_delay_s", "median"), 10.0, True),
    Target("queue-approach precision", _alert("queue_approach", "precision"), 0.9, False),
    Target("queue-approach recall", _alert("queue_approach", "recall"), 0.9, False),
)

#: The demand sets of ``--traffic``: demand over capacity drawn in this range, and its profile.
TRAFFIC_SETS: dict[str, tuple[tuple[float, float], str]] = {
    "free-flow": ((0.5, 0.85), "steady"),
    "congested": ((1.05, 1.3), "ramp"),
}


@dataclass(frozen=True)
class SiteJob:
    """One generated site's run."""

    index: int
    seed: int
    weather: str
    vehicles_per_hour: float
    truck_share: float
    duration_s: float
    warmup_s: float
    out_dir: Path
    #: Reuse this site's ``eval.json`` in ``out_dir`` when it is of this very job (see
    #: :func:`finished_report`): a run cut short goes on where it stopped.
    resume: bool = False
    #: Render the sensors as a real mast's (``wz eval --mount-errors``).
    mount_errors: bool = False
    #: Demand as a share of the closure's capacity (replaces ``vehicles_per_hour``); None: off.
    demand_ratio: float | None = None
    demand_profile: str = "steady"


def plan_jobs(
    count: int,
    seed: int,
    duration_s: float,
    warmup_s: float,
    out_dir: Path,
    resume: bool = False,
    mount_errors: bool = False,
    traffic: str = "volume",
) -> list[SiteJob]:
    """The runs of ``--sites count --seed seed``: site seeds ``seed .. seed + count - 1``."""
    if traffic != "volume" and traffic not in TRAFFIC_SETS:
        raise ValueError(f"traffic {traffic!r}: volume, {', '.join(TRAFFIC_SETS)}")
    jobs = []
    for index in range(count):
        site_seed = seed + index
        rng = np.random.default_rng(np.random.SeedSequence([site_seed, 0xC0D]))
        ratio_rng = np.random.default_rng(np.random.SeedSequence([site_seed, 0xCA9]))
        ratio_range, profile = TRAFFIC_SETS.get(traffic, ((0.0, 0.0), "steady"))
        ratio = None if traffic == "volume" else round(float(ratio_rng.uniform(*ratio_range)), 2)
        jobs.append(
            SiteJob(
                index=index,
                seed=site_seed,
                weather=WEATHER_CYCLE[index % len(WEATHER_CYCLE)],
                vehicles_per_hour=float(round(rng.uniform(1200.0, 2000.0) / 50.0) * 50.0),
                truck_share=round(float(rng.uniform(0.15, 0.30)), 2),
                duration_s=duration_s,
                warmup_s=warmup_s,
                out_dir=out_dir / f"gen-{site_seed}",
                resume=resume,
                mount_errors=mount_errors,
                demand_ratio=ratio,
                demand_profile=profile,
            )
        )
    return jobs


def run_job(job: SiteJob) -> dict[str, Any]:
    """Generate, draw, simulate and score one site; its summary row (also in its folder)."""
    from wz_eval.fusion import EvalOptions, evaluate
    from wz_eval.site_tool import draw_site, site_yaml
    from wz_shared.site_generator import generate_site

    site = generate_site(job.seed)
    if job.resume and (report := finished_report(job, site_yaml(site))) is not None:
        return {**summarise(site.site_id, site.name, job, report), "resumed": True}
    job.out_dir.mkdir(parents=True, exist_ok=True)
    (job.out_dir / "site.yaml").write_text(site_yaml(site), encoding="utf-8")
    draw_site(site, job.out_dir / "site.png")
    options = EvalOptions(
        seed=job.seed,
        duration_s=job.duration_s,
        warmup_s=job.warmup_s,
        weather=job.weather,
        vehicles_per_hour=job.vehicles_per_hour,
        demand_ratio=job.demand_ratio,
        demand_profile=job.demand_profile,
        truck_share=job.truck_share,
        mount_errors=job.mount_errors,
    )
    report = evaluate(site, options, plots_dir=job.out_dir)
    (job.out_dir / "eval.json").write_text(json.dumps(report, indent=2, default=str) + "\n")
    return summarise(site.site_id, site.name, job, report)


def finished_report(job: SiteJob, site_text: str) -> dict[str, Any] | None:
    """The ``eval.json`` a run of this very job left in its folder, or None: the same site
    file, seed, scored and warm-up seconds, weather, demand, truck share and mast model (all
    seeded, so a run of the same code gives the same figures)."""
    try:
        saved_site = (job.out_dir / "site.yaml").read_text(encoding="utf-8")
        report: dict[str, Any] = json.loads((job.out_dir / "eval.json").read_text())
    except (OSError, ValueError):
        return None
    conditions = report.get("conditions", {})
    same = (
        saved_site == site_text
        and report.get("seed") == job.seed
        and report.get("duration_s") == job.duration_s
        and report.get("warmup_s") == job.warmup_s
        and conditions.get("weather") == job.weather
        and conditions.get("demand_ratio") == job.demand_ratio
        and (
            job.demand_ratio is not None
            or conditions.get("vehicles_per_hour") == job.vehicles_per_hour
        )
        and conditions.get("demand_profile", "steady") == job.demand_profile
        and conditions.get("truck_share") == job.truck_share
        and (report.get("mount_errors") is not None) == job.mount_errors
    )
    return report if same else None


def summarise(site_id: str, name: str, job: SiteJob, report: dict[str, Any]) -> dict[str, Any]:
    """One row of the sites report: the conditions and each target's value and verdict."""
    figures = {}
    for target in SITE_TARGETS:
        value = target.value(report)
        figures[target.name] = {"value": value, "holds": target.holds(value)}
    return {
        "site_id": site_id,
        "name": name,
        "missed_upstream": _missed(report, upstream=True),
        "approach_mota": report.get("approach", {}).get("mota"),
        "approach_switches_per_100": report.get("approach", {}).get("id_switches_per_100_vehicles"),
        "missed_downstream": _missed(report, upstream=False),
        "covered_downstream": report.get("coverage", {}).get("covered_share_downstream"),
        "circle_mota": report.get("circle", {}).get("mota"),
        "seed": job.seed,
        "weather": job.weather,
        "vehicles_per_hour": report.get("conditions", {}).get(
            "vehicles_per_hour", job.vehicles_per_hour
        ),
        "demand_ratio": job.demand_ratio,
        "demand_profile": job.demand_profile,
        "truck_share": job.truck_share,
        "mount_errors": job.mount_errors,
        "duration_s": job.duration_s,
        "vehicles": report.get("vehicles"),
        "figures": figures,
        "failed": [n for n, f in figures.items() if f["holds"] is False],
        "picture": f"{job.out_dir.name}/site.png",
        "pipeline_problems": report.get("pipeline_problems", {}),
    }


def _missed(report: dict[str, Any], *, upstream: bool) -> float | None:
    """Share of the scored vehicle samples upstream (or downstream) of the mast with no track."""
    rows = [
        row
        for row in report.get("fused_by_station", [])
        if (row["from_mast_m"][1] <= 0.0) == upstream
    ]
    samples = sum(int(row["vehicle_samples"]) for row in rows)
    if not samples:
        return None
    missed = sum(float(row["missed_share"]) * int(row["vehicle_samples"]) for row in rows)
    return missed / samples


def distribution(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per target: how many sites meet it, the median and the worst value."""
    out = []
    for target in SITE_TARGETS:
        values = [r["figures"][target.name]["value"] for r in rows]
        known = [v for v in values if v is not None]
        verdicts = [r["figures"][target.name]["holds"] for r in rows]
        worst = (max if target.at_most else min)(known) if known else None
        out.append(
            {
                "target": target.name,
                "bound": target.text,
                "sites_meeting": sum(1 for v in verdicts if v is True),
                "sites_failing": sum(1 for v in verdicts if v is False),
                "sites_without_value": sum(1 for v in verdicts if v is None),
                "median": statistics.median(known) if known else None,
                "worst": worst,
            }
        )
    return out


def worst_site(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The site failing most targets (ties: the lowest MOTA)."""
    if not rows:
        return None
    return max(rows, key=lambda r: (len(r["failed"]), -r["figures"]["MOTA"]["value"]))


def _cell(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def markdown(report: dict[str, Any]) -> str:
    rows = report["sites"]
    lines = [
        f"# `wz eval --sites {len(rows)} --seed {report['seed']}"
        f"{' --mount-errors' if report.get('mount_errors') else ''}"
        f"{' --traffic ' + report['traffic'] if report.get('traffic', 'volume') != 'volume' else ''}`",
        "",
        f"{len(rows)} generated sites, {report['duration_s']:.0f} s scored each after a "
        f"{report['warmup_s']:.0f} s warm-up"
        + (
            ", the sensors rendered as a real mast's (`--mount-errors`: each site's eval.json "
            "gives what was drawn)"
            if report.get("mount_errors")
            else ""
        )
        + "; the live fused track within 150 m of the mast "
        "where a sensor of the site can see a car (wz_shared.coverage: downstream, as far as "
        "the LiDAR's beams are sure to hit one); alerts scored against the same rules on the "
        "truth. A site meets the bar when every figure holds ('-': the run cannot tell, e.g. "
        "no late merge happened). The last columns are not targets: the share of vehicle "
        "samples with no track upstream and downstream of the mast, MOTA and switches on the "
        "approach alone (upstream of the mast, which every sensor faces; downstream only the "
        "LiDAR sees), the share of the road downstream inside the circle that a sensor covers, "
        "and MOTA over the whole circle, covered or not.",
        "",
        "| target | bound | sites meeting | failing | no value | median | worst |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in report["distribution"]:
        lines.append(
            f"| {row['target']} | {row['bound']} | {row['sites_meeting']} | "
            f"{row['sites_failing']} | {row['sites_without_value']} | {_cell(row['median'])} | "
            f"{_cell(row['worst'])} |"
        )
    names = [t.name for t in SITE_TARGETS]
    lines += [
        "",
        "| site | conditions | vehicles | "
        + " | ".join(names)
        + " | missed up / downstream | approach MOTA / switches | covered downstream "
        "| whole-circle MOTA |",
        "|---|---|---|" + "---|" * len(names) + "---|---|---|---|",
    ]
    for row in rows:
        cells = []
        for name in names:
            figure = row["figures"][name]
            text = _cell(figure["value"])
            cells.append(f"**{text}**" if figure["holds"] is False else text)
        conditions = (
            f"{row['weather']}, {row['vehicles_per_hour']:.0f} veh/h"
            + (
                f" ({row['demand_ratio']:.2f} of capacity{', ramp' if row.get('demand_profile') == 'ramp' else ''})"
                if row.get("demand_ratio") is not None
                else ""
            )
            + ", "
            f"{100 * row['truck_share']:.0f} % trucks"
        )
        missed = f"{_cell(row.get('missed_upstream'))} / {_cell(row.get('missed_downstream'))}"
        approach = (
            f"{_cell(row.get('approach_mota'))} / {_cell(row.get('approach_switches_per_100'))}"
        )
        lines.append(
            f"| {row['site_id']} | {conditions} | {row['vehicles']} | "
            + " | ".join(cells)
            + f" | {missed} | {approach} | {_cell(row.get('covered_downstream'))}"
            f" | {_cell(row.get('circle_mota'))} |"
        )
    lines.append("")
    for row in rows:
        lines.append(f"- {row['site_id']}: {row['name']}")
    worst = report.get("worst_site")
    if worst is not None:
        failed = ", ".join(worst["failed"]) or "none"
        lines += [
            "",
            f"Worst site: {worst['site_id']} (fails: {failed}).",
            "",
            f"![{worst['site_id']}]({worst['picture']})",
        ]
    return "\n".join(lines) + "\n"


def run_sites(
    count: int,
    seed: int,
    duration_s: float,
    warmup_s: float,
    out_dir: Path,
    jobs: int | None = None,
    resume: bool = False,
    mount_errors: bool = False,
    traffic: str = "volume",
) -> dict[str, Any]:
    """Run the sites (in parallel), write ``sites.json`` and ``sites.md`` in ``out_dir``;
    ``resume``: reuse the sites a run cut short already finished there; ``mount_errors``: each
    site's sensors a real mast's."""
    plan = plan_jobs(count, seed, duration_s, warmup_s, out_dir, resume, mount_errors, traffic)
    workers = max(1, min(count, jobs or os.cpu_count() or 1))
    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(run_job, job): job for job in plan}
        for future in as_completed(futures):
            job = futures[future]
            row = future.result()
            rows.append(row)
            sys.stderr.write(
                f"site {job.seed} {'taken from its eval.json' if row.get('resumed') else 'done'}"
                f" ({len(rows)}/{count}): "
                f"fails {', '.join(row['failed']) or 'nothing'}\n"
            )
    rows.sort(key=lambda r: r["seed"])
    report = {
        "seed": seed,
        "count": count,
        "duration_s": duration_s,
        "warmup_s": warmup_s,
        "mount_errors": mount_errors,
        "traffic": traffic,
        "sites": rows,
        "distribution": distribution(rows),
        "worst_site": worst_site(rows),
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "sites.json").write_text(json.dumps(report, indent=2, default=str) + "\n")
    (out_dir / "sites.md").write_text(markdown(report))
    return report


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="wz eval --sites", description=__doc__.split("\n")[0])
    parser.add_argument("--sites", type=int, required=True, help="how many generated sites")
    parser.add_argument("--seed", type=int, default=1000, help="the first site's seed")
    parser.add_argument("--duration-s", type=positive, default=300.0, help="scored [s]")
    parser.add_argument("--warmup-s", type=not_negative, default=60.0, help="before it [s]")
    parser.add_argument("--jobs", type=int, default=None, help="processes (default: cores)")
    parser.add_argument("--out", type=Path, default=Path("runs/sites"))
    parser.add_argument(
        "--resume",
        action="store_true",
        help="reuse each site's eval.json already in --out from a run of the same site, seed, "
        "conditions and durations (a run cut short goes on where it stopped)",
    )
    parser.add_argument(
        "--mount-errors",
        action="store_true",
        help="render each site's sensors as a real mast's (set-up errors, late clocks, sway, "
        "settling, drawn from the site's seed), as wz eval --mount-errors does",
    )
    parser.add_argument(
        "--traffic",
        choices=("volume", *TRAFFIC_SETS),
        default="volume",
        help="volume: 1200-2000 veh/h; free-flow: 0.5-0.85 of the closure's capacity, steady; "
        "congested: a ramp peaking at 1.05-1.3 of it (a queue forms and dissolves)",
    )
    args = parser.parse_args(argv)
    if args.sites < 1:
        parser.error(f"--sites must be at least 1, got {args.sites}")
    if args.seed < 0:
        parser.error(f"--seed must be non-negative, got {args.seed}")
    if args.jobs is not None and args.jobs < 1:
        parser.error(f"--jobs must be at least 1, got {args.jobs}")
    report = run_sites(
        args.sites,
        args.seed,
        args.duration_s,
        args.warmup_s,
        args.out,
        args.jobs,
        args.resume,
        args.mount_errors,
        args.traffic,
    )
    sys.stdout.write(markdown(report))
    failing = sum(1 for row in report["sites"] if row["failed"])
    return 0 if failing == 0 else 1
