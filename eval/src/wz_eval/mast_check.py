"""``wz eval --mast-check SURVEYED DISPLACED``: does the pipeline hold on a real mast (issue 39)?

Two ``wz eval`` reports of the same site and seed: one with the sensors exactly where the site
file says, one with them rendered as a real mast's (``--mount-errors``: set-up errors, late
clocks, sway, settling), both with the self-calibration on as in the services. Each argument is
a report (``eval.json``) or a ``wz eval --sites`` folder (its sites matched by site id); a
pair is held to issue 39's margins:

- fused RMSE longitudinal, lateral and speed within 10 % of the surveyed run's (with a floor of
  2 cm and 0.02 m/s: 10 % of a few centimetres is below what one run can tell);
- MOTA within 0.02 of it, identity switches at most 1 per 100 vehicles more;
- every alert type's precision and recall within 0.05 (where both runs define them);
- each sensor's learned yaw and pitch within 0.2 deg of the drawn error and its clock offset
  within 20 ms (the LiDAR's clock is the reference: not held).

The output is a Markdown table per pair and a JSON summary (``--json``); the exit status is 0
when every held figure holds, 1 otherwise, 2 on a usage error.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: Issue 39's margins.
RMSE_RATIO = 0.10
RMSE_FLOOR = {"longitudinal": 0.02, "lateral": 0.02, "speed": 0.02}
MOTA_MARGIN = 0.02
SWITCHES_MARGIN = 1.0
ALERT_MARGIN = 0.05
ANGLE_MARGIN_DEG = 0.2
CLOCK_MARGIN_S = 0.02


def _fused(report: dict[str, Any]) -> dict[str, float | None]:
    """The live fused track's RMSE within the scored circle (``must_show``'s figures)."""
    rows = {row["check"]: row.get("value") for row in report.get("must_show", [])}
    out: dict[str, float | None] = {}
    for axis in ("longitudinal", "lateral", "speed"):
        key = next((name for name in rows if name.startswith(f"fused RMSE {axis}")), None)
        out[axis] = rows.get(key) if key else None
    return out


def check_pair(surveyed: dict[str, Any], displaced: dict[str, Any]) -> list[dict[str, Any]]:
    """Every held figure of one pair: name, surveyed, displaced, bound, holds."""
    checks: list[dict[str, Any]] = []

    def add(
        name: str, base: float | None, value: float | None, bound: str, ok: bool | None
    ) -> None:
        checks.append(
            {"name": name, "surveyed": base, "displaced": value, "bound": bound, "holds": ok}
        )

    base_rmse, rmse = _fused(surveyed), _fused(displaced)
    for axis in ("longitudinal", "lateral", "speed"):
        b, v = base_rmse[axis], rmse[axis]
        limit = None if b is None else max(b * (1 + RMSE_RATIO), b + RMSE_FLOOR[axis])
        add(
            f"fused RMSE {axis}",
            b,
            v,
            "-" if limit is None else f"<= {limit:.3f}",
            None if (limit is None or v is None) else v <= limit,
        )
    b, v = surveyed.get("mota"), displaced.get("mota")
    add(
        "MOTA",
        b,
        v,
        "-" if b is None else f">= {b - MOTA_MARGIN:.3f}",
        None if b is None or v is None else v >= b - MOTA_MARGIN,
    )
    b, v = (
        surveyed.get("id_switches_per_100_vehicles"),
        displaced.get("id_switches_per_100_vehicles"),
    )
    add(
        "identity switches per 100 vehicles",
        b,
        v,
        "-" if b is None else f"<= {b + SWITCHES_MARGIN:.2f}",
        None if b is None or v is None else v <= b + SWITCHES_MARGIN,
    )
    for alert, entry in sorted(surveyed.get("alerts", {}).items()):
        other = displaced.get("alerts", {}).get(alert, {})
        for figure in ("precision", "recall"):
            b, v = entry.get(figure), other.get(figure)
            if b is None and v is None:
                continue
            add(
                f"{alert} {figure}",
                b,
                v,
                "-" if b is None else f">= {b - ALERT_MARGIN:.3f}",
                None if b is None or v is None else v >= b - ALERT_MARGIN,
            )
    drawn = (displaced.get("mount_errors") or {}).get("sensors", {})
    for sensor, learned in sorted((displaced.get("calibration") or {}).items()):
        truth = drawn.get(sensor)
        if truth is None:
            continue
        c = learned["correction"]
        kind = learned.get("sensor_kind")
        pairs = [("yaw", c["yaw_deg"], truth["yaw_deg"])]
        if kind != "radar":  # a radar's scan is a plane: its pitch is not what it measures
            pairs.append(("pitch", c["pitch_deg"], truth["pitch_deg"]))
        for name, value, true in pairs:
            error = abs(value - true)
            add(
                f"{sensor} {name} learned - drawn [deg]",
                true,
                value,
                f"|error| <= {ANGLE_MARGIN_DEG}",
                error <= ANGLE_MARGIN_DEG,
            )
        if kind != "lidar":
            error = abs(learned["clock_offset_s"] - truth["clock_offset_s"])
            add(
                f"{sensor} clock learned - drawn [s]",
                truth["clock_offset_s"],
                learned["clock_offset_s"],
                f"|error| <= {CLOCK_MARGIN_S}",
                error <= CLOCK_MARGIN_S,
            )
    return checks


def _reports(path: Path) -> dict[str, dict[str, Any]]:
    """Reports by site id: one ``eval.json``, or every site of a ``wz eval --sites`` folder."""
    if path.is_file():
        report = json.loads(path.read_text())
        return {str(report["site"]): report}
    found: dict[str, dict[str, Any]] = {}
    for file in sorted(path.glob("*/eval.json")):
        report = json.loads(file.read_text())
        found[str(report["site"])] = report
    if not found:
        raise FileNotFoundError(f"{path}: no eval.json in it or under it")
    return found


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)


def markdown(results: dict[str, list[dict[str, Any]]]) -> str:
    lines = ["# Issue 39: the pipeline on a real mast against the surveyed one", ""]
    held = sum(1 for checks in results.values() if all(c["holds"] is not False for c in checks))
    lines.append(f"{held} of {len(results)} sites hold every figure.")
    for site, checks in results.items():
        lines += [
            "",
            f"## {site}",
            "",
            "| figure | surveyed (drawn) | displaced (learned) | bound | holds |",
            "|---|---|---|---|---|",
        ]
        for c in checks:
            mark = "-" if c["holds"] is None else ("yes" if c["holds"] else "**no**")
            lines.append(
                f"| {c['name']} | {_cell(c['surveyed'])} | {_cell(c['displaced'])} | "
                f"{c['bound']} | {mark} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="wz eval --mast-check",
        description="Hold a real mast's run (--mount-errors) to the surveyed run's figures "
        "(issue 39's margins).",
    )
    parser.add_argument("--mast-check", nargs=2, metavar=("SURVEYED", "DISPLACED"), type=Path)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    surveyed_path, displaced_path = args.mast_check
    try:
        surveyed, displaced = _reports(surveyed_path), _reports(displaced_path)
    except (OSError, ValueError, KeyError) as exc:
        sys.stderr.write(f"wz eval --mast-check: {exc}\n")
        return 2
    common = sorted(set(surveyed) & set(displaced))
    if not common:
        sys.stderr.write("wz eval --mast-check: the two hold no site in common\n")
        return 2
    if any(not displaced[s].get("mount_errors") for s in common):
        sys.stderr.write("wz eval --mast-check: the second report is not a --mount-errors run\n")
        return 2
    results = {site: check_pair(surveyed[site], displaced[site]) for site in common}
    sys.stdout.write(markdown(results))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0 if all(c["holds"] is not False for cs in results.values() for c in cs) else 1
