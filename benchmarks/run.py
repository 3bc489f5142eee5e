"""Run the benchmarks and write ``BENCHMARKS.md`` and ``benchmarks/results.json``.

Usage (from the repository root)::

    uv run python -m benchmarks.run [--only NAME] [--quick] [--report-only]

Benchmarks run one after the other, never in parallel. ``--only NAME`` runs one and keeps the
others' results from the previous ``results.json`` (when it was written on this same machine).
``--quick`` takes fewer samples (a smoke test; quote full runs only). ``--report-only``
rewrites ``BENCHMARKS.md`` from ``results.json`` without measuring.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import json
import logging
import os
import platform
import resource
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks import (
    alert_flood,
    alert_latency,
    bus_latency,
    bus_throughput,
    bus_trust,
    camera_budget,
    camera_detection,
    camera_models,
    gateway_live,
    generated_sites,
    lidar_detection,
    queue_beyond_reach,
    recovery,
    report,
    self_calibration,
    sensors,
    speeding_flood,
    sumo_step,
    tracker_cycle,
    traffic_sites,
    webhook_latency,
)
from benchmarks.common import ROOT

log = logging.getLogger("benchmarks")

BENCHMARKS: dict[str, Callable[[bool], dict[str, Any]]] = {
    "bus_latency": bus_latency.run,
    "bus_throughput": bus_throughput.run,
    "bus_trust": bus_trust.run,
    "sumo_step": sumo_step.run,
    "sensors": sensors.run,
    "lidar_detection": lidar_detection.run,
    "camera_detection": camera_detection.run,
    "camera_models": camera_models.run,
    "camera_budget": camera_budget.run,
    "tracker_cycle": tracker_cycle.run,
    "alert_latency": alert_latency.run,
    "alert_flood": alert_flood.run,
    "speeding_flood": speeding_flood.run,
    "gateway_live": gateway_live.run,
    "webhook_latency": webhook_latency.run,
    "recovery": recovery.run,
    "generated_sites": generated_sites.run,
    "traffic_sites": traffic_sites.run,
    "queue_beyond_reach": queue_beyond_reach.run,
    "self_calibration": self_calibration.run,
}
RESULTS_PATH = ROOT / "benchmarks" / "results.json"
MARKDOWN_PATH = ROOT / "BENCHMARKS.md"


def _read_key_values(path: Path, separator: str) -> dict[str, str]:
    values: dict[str, str] = {}
    if not path.exists():
        return values
    for line in path.read_text().splitlines():
        key, found, value = line.partition(separator)
        if found and key.strip() not in values:
            values[key.strip()] = value.strip().strip('"')
    return values


def _version(distribution: str) -> str:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def machine_info() -> dict[str, Any]:
    """CPU, cores, memory, OS and the versions the numbers depend on."""
    cpu = _read_key_values(Path("/proc/cpuinfo"), ":")
    memory = _read_key_values(Path("/proc/meminfo"), ":")
    os_release = _read_key_values(Path("/etc/os-release"), "=")
    mem_kib = int(memory.get("MemTotal", "0 kB").split()[0])
    return {
        "cpu_model": cpu.get("model name", platform.processor() or "unknown"),
        "cores": os.cpu_count(),
        "cores_usable": len(os.sched_getaffinity(0)),
        "memory_gib": round(mem_kib / 2**20, 1),
        "os": os_release.get("PRETTY_NAME", platform.system()),
        "kernel": platform.release(),
        "python": platform.python_version(),
        "versions": {
            name: _version(name)
            for name in ("eclipse-zenoh", "numpy", "pydantic", "eclipse-sumo", "libsumo")
        },
    }


def _cpu_times() -> tuple[int, int]:
    """(idle, total) jiffies of all CPUs, from /proc/stat."""
    fields = [int(value) for value in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    idle = fields[3] + fields[4]  # idle + iowait
    return idle, sum(fields)


def other_cpu_busy(interval_s: float = 1.0) -> float:
    """Fraction of all cores busy during ``interval_s`` while this process sleeps."""
    idle_0, total_0 = _cpu_times()
    time.sleep(interval_s)
    idle_1, total_1 = _cpu_times()
    return 1.0 - (idle_1 - idle_0) / max(1, total_1 - total_0)


def _busy_and_own_cpu_s() -> tuple[float, float]:
    """CPU seconds all cores have been busy since boot; CPU seconds of this process and of its
    finished children (the benchmarks' peers and SUMO processes)."""
    idle, total = _cpu_times()
    own = sum(
        usage.ru_utime + usage.ru_stime
        for usage in (
            resource.getrusage(resource.RUSAGE_SELF),
            resource.getrusage(resource.RUSAGE_CHILDREN),
        )
    )
    return (total - idle) / os.sysconf("SC_CLK_TCK"), own


def _previous_results(machine: dict[str, Any]) -> dict[str, Any]:
    """Benchmarks of the last results.json. Those measured on another machine or setup are
    kept with that machine named in their entry (``machine``): the report says so in their
    section, so that no figure is read as this machine's."""
    if not RESULTS_PATH.exists():
        return {}
    previous = json.loads(RESULTS_PATH.read_text())
    kept: dict[str, Any] = previous.get("benchmarks", {})
    if previous.get("machine") != machine:
        log.warning("%s was written on another machine or setup: its entries are labelled so",
                    RESULTS_PATH)  # fmt: skip
        for entry in kept.values():
            entry.setdefault("machine", previous.get("machine"))
    return kept


def run_one(name: str, quick: bool) -> dict[str, Any]:
    """Run one benchmark; a failure is recorded, not raised, so the others still run."""
    log.info("%s: starting%s", name, " (quick)" if quick else "")
    measured_at = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    start = time.perf_counter()
    busy = other_cpu_busy()
    if busy > 0.1:
        log.warning(
            "%.0f %% of the CPU is busy with other work: the numbers will suffer", 100 * busy
        )
    entry: dict[str, Any] = {"measured_at": measured_at, "quick": quick, "cpu_busy_before": busy}
    busy_0, own_0 = _busy_and_own_cpu_s()
    started = time.perf_counter()
    try:
        entry["result"] = BENCHMARKS[name](quick)
    except Exception:
        log.exception("%s failed", name)
        entry["error"] = traceback.format_exc(limit=5)
    busy_1, own_1 = _busy_and_own_cpu_s()
    capacity_s = (time.perf_counter() - started) * (os.cpu_count() or 1)
    # What other processes used of the machine while this benchmark ran.
    entry["cpu_other_during"] = max(0.0, ((busy_1 - busy_0) - (own_1 - own_0)) / capacity_s)
    entry["wall_s"] = round(time.perf_counter() - start, 1)
    log.info(
        "%s: done in %.1f s; other work used %.0f %% of the CPU meanwhile",
        name,
        entry["wall_s"],
        100 * entry["cpu_other_during"],
    )
    return entry


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.run", description=__doc__)
    parser.add_argument("--only", choices=sorted(BENCHMARKS), help="run this benchmark only")
    parser.add_argument("--quick", action="store_true", help="fewer samples (smoke test)")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="measure nothing: rewrite BENCHMARKS.md from the existing results.json",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    if args.report_only:
        MARKDOWN_PATH.write_text(report.render(json.loads(RESULTS_PATH.read_text())))
        log.info("wrote %s from %s", MARKDOWN_PATH.name, RESULTS_PATH.relative_to(ROOT))
        return 0

    machine = machine_info()
    entries = _previous_results(machine) if args.only else {}
    for name in [args.only] if args.only else list(BENCHMARKS):
        entries[name] = run_one(name, args.quick)

    results = {
        "generated_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "command": "uv run python -m benchmarks.run"
        + (f" --only {args.only}" if args.only else "")
        + (" --quick" if args.quick else ""),
        "machine": machine,
        "benchmarks": {name: entries[name] for name in BENCHMARKS if name in entries},
    }
    RESULTS_PATH.write_text(json.dumps(results, indent=2) + "\n")
    MARKDOWN_PATH.write_text(report.render(results))
    log.info("wrote %s and %s", MARKDOWN_PATH.name, RESULTS_PATH.relative_to(ROOT))
    return 1 if any("error" in entry for entry in entries.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
