"""The report of ``wz eval``: the paper table's summary, issue 6's targets checked on the
report (``must_show``) and the Markdown page (``eval.md``). Pure: dictionaries in, rows and
text out (the scoring itself is :mod:`wz_eval.fusion`)."""

from __future__ import annotations

from typing import Any

#: Alerts are scored against the truth of the vehicles within this of the mast [m]: the
#: radar's reach, where the first tracks start (the fused tracks run beyond ``max_range_m``).
ALERT_TRUTH_RANGE_M = 200.0
#: A lateral loss to the average by less than this per sample is a tie at the centimetre
#: (reported apart in the paper table's summary) [m].
TIE_M_PER_SAMPLE = 0.01
#: Issue 6's must-show targets, checked by :func:`must_show`. The issue names no number for a
#: dropout's "bounded error": these bounds are this project's reading (about 30 % above what
#: seed 7 measured: 0.78 / 0.23 m with the LiDAR silent, 0.75 / 0.09 m with the camera).
TARGETS: dict[str, float] = {
    "rmse_longitudinal_m": 0.5,
    "rmse_lateral_m": 0.3,
    "rmse_speed_mps": 0.5,
    "mota": 0.95,
    "id_switches_per_100_vehicles": 1.0,
    "paper_table_vehicles": 10,
    "paper_table_share": 0.9,
    "dropout_rmse_longitudinal_m": 1.0,
    "dropout_rmse_lateral_m": 0.3,
}


def table_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """How often the fused track beats each other source, per axis; and, of its lateral losses
    to the average, how many are by less than :data:`TIE_M_PER_SAMPLE` per sample."""
    out: dict[str, Any] = {"vehicles": len(rows)}
    for other in ("camera", "lidar", "average", "paper_kf"):
        for axis in ("longitudinal_m", "lateral_m"):
            wins = sum(1 for r in rows if r["fused"][axis] < r[other][axis])
            out[f"fused_below_{other}_{axis}"] = wins
    for fused in ("fused", "fused_smoothed", "fused_stored"):
        out[f"{fused}_below_camera_lidar_average_both_axes"] = sum(
            1
            for r in rows
            if all(
                r[fused][a] < r[o][a]
                for o in ("camera", "lidar", "average")
                for a in ("longitudinal_m", "lateral_m")
            )
        )
        out[f"{fused}_lateral_losses_to_average_within_1cm"] = sum(
            1
            for r in rows
            if 0.0
            <= r[fused]["lateral_m"] - r["average"]["lateral_m"]
            < TIE_M_PER_SAMPLE * r["samples"]
        )
    return out


def must_show(report: dict[str, Any]) -> list[dict[str, Any]]:
    """Issue 6's targets (:data:`TARGETS`) checked on this report: one row per check, with
    ``value``, ``target`` and ``holds`` (None where the run cannot tell: no dropout asked for,
    a range other than 150 m). The paper table is checked for the live track and for the two
    hindsight versions, each on its own row."""
    rows: list[dict[str, Any]] = []

    def add(check: str, value: float | None, target: str, holds: bool | None) -> None:
        rows.append({"check": check, "value": value, "target": target, "holds": holds})

    at_150 = abs(report["max_range_m"] - 150.0) < 1e-9
    fused = report["sources"]["fused"]
    for axis in ("longitudinal_m", "lateral_m", "speed_mps"):
        value, limit = fused[f"rmse_{axis}"], TARGETS[f"rmse_{axis}"]
        add(
            f"fused RMSE {axis.split('_')[0]} within 150 m",
            value,
            f"<= {limit:g}",
            None if not at_150 or value is None else value <= limit,
        )
    add("MOTA", report["mota"], f">= {TARGETS['mota']:g}", report["mota"] >= TARGETS["mota"])
    per_100 = report["id_switches_per_100_vehicles"]
    add(
        "identity switches per 100 vehicles",
        per_100,
        f"<= {TARGETS['id_switches_per_100_vehicles']:g}",
        per_100 <= TARGETS["id_switches_per_100_vehicles"],
    )
    summary = report["paper_table_summary"]
    vehicles = summary["vehicles"]
    for fused_source, label in (
        ("fused", "live"),
        ("fused_stored", "stored"),
        ("fused_smoothed", "smoothed"),
    ):
        wins = summary[f"{fused_source}_below_camera_lidar_average_both_axes"]
        share = wins / vehicles if vehicles else None
        # The paper's tables are offline, so the table is read on the stored trajectories
        # (what /v1/trajectories serves, issue 25); the live and smoothed rows are shown, not
        # held to it (the live track is held to the RMSE, MOTA and switch targets).
        held = fused_source == "fused_stored"
        add(
            f"paper table, {label} track below camera, LiDAR and average on both axes "
            f"({wins} of {vehicles} vehicles)",
            share,
            f">= {TARGETS['paper_table_share']:g} of >= {TARGETS['paper_table_vehicles']}"
            + ("" if held else " (shown, not a target)"),
            None
            if share is None or not held
            else vehicles >= TARGETS["paper_table_vehicles"]
            and share >= TARGETS["paper_table_share"],
        )
    lane_volumes = report.get("lane_volumes")
    if lane_volumes:
        worst = max(
            (
                abs(row["volume_error"])
                for row in lane_volumes["lanes"]
                if row["volume_error"] is not None and row.get("reliable") is not False
            ),
            default=None,
        )
        add(
            "lane volume at the WZDx traffic detector, worst seen lane's error vs truth",
            worst,
            f"<= {lane_volumes['tolerance']:g}",
            lane_volumes["holds"],
        )
        if "off_lanes_marked" in lane_volumes:
            off = sum(1 for row in lane_volumes["lanes"] if not row["holds"])
            add(
                "lanes off by more marked unreliable (hidden by vehicles)",
                off,
                "all",
                lane_volumes["off_lanes_marked"],
            )
    for dropout in report["dropouts"]:
        name = f"{dropout['sensor_id']} silent {dropout['duration_s']:g} s"
        lon, lat = dropout["fused_rmse_longitudinal_m"], dropout["fused_rmse_lateral_m"]
        bounded = (
            lon is not None
            and lat is not None
            and lon <= TARGETS["dropout_rmse_longitudinal_m"]
            and lat <= TARGETS["dropout_rmse_lateral_m"]
        )
        add(
            f"{name}: fused RMSE lon / lat inside it",
            None if lon is None else max(lon, lat),
            f"<= {TARGETS['dropout_rmse_longitudinal_m']:g} / "
            f"{TARGETS['dropout_rmse_lateral_m']:g}",
            bounded,
        )
        switches = dropout["id_switches_from_start_to_2s_after"]
        add(f"{name}: identity switches to 2 s after", switches, "0", switches == 0)
    return rows


def _conditions(report: dict[str, Any]) -> str:
    """The run's weather and traffic, as a sentence (empty for a report without them)."""
    c = report.get("conditions")
    if not c:
        return ""
    demand = f"{c['vehicles_per_hour']:.0f} vehicles/h"
    if c.get("demand_ratio") is not None:  # asked as a share of capacity
        demand = (
            f"demand {c['share_of_capacity']:.2f} of the closure's capacity "
            f"({c['capacity_vph']:.0f} veh/h, so {demand}"
            + (", the ramp's peak)" if c.get("demand_profile") == "ramp" else ")")
        )
    return (
        f" Weather {c['weather']}, {demand}, "
        f"{100 * c['truck_share']:g} % trucks, {100 * c['aggressive_share']:g} % aggressive."
    )


def mount_error_lines(report: dict[str, Any]) -> list[str]:
    """The drawn mast model (``wz eval --mount-errors``) as Markdown: one row per sensor, a line
    per mast and the bump; nothing for a run on the nominal poses."""
    drawn = report.get("mount_errors")
    if not drawn:
        return []
    lines = [
        "",
        "Sensors rendered as a real mast's (`--mount-errors`, drawn from the seed; the "
        "detectors and the tracker kept the site file's poses):",
        "",
        "| sensor | yaw [deg] | pitch [deg] | roll [deg] | east [m] | north [m] | up [m] | "
        "clock late [ms] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for sensor, e in drawn["sensors"].items():
        lines.append(
            f"| {sensor} | {e['yaw_deg']:+.2f} | {e['pitch_deg']:+.2f} | {e['roll_deg']:+.2f} | "
            f"{e['dx_m']:+.2f} | {e['dy_m']:+.2f} | {e['dz_m']:+.2f} | "
            f"{1000.0 * e['clock_offset_s']:.0f} |"
        )
    lines.append("")
    for mast in drawn["masts"]:
        sway, settling = mast["sway"], mast["settling"]
        lines.append(
            f"- Mast of {', '.join(mast['sensors'])}: sway at its top (z {mast['top_z_m']:g} m) "
            f"lean {sway['lean_amplitude_deg']:.3f} deg towards {sway['bearing_deg']:.0f} deg, "
            f"twist {sway['twist_amplitude_deg']:.3f} deg, period {sway['period_s']:.2f} s; "
            f"settling {settling['rate_deg_per_h']:.3f} deg/h towards "
            f"{settling['bearing_deg']:.0f} deg."
        )
    bump = drawn.get("bump")
    if bump is not None:
        lines.append(
            f"- Bump: {bump['sensor_id']} turned {bump['yaw_deg']:+.2f} deg at simulation "
            f"time {bump['at_s']:g} s."
        )
    return lines


def calibration_lines(report: dict[str, Any]) -> list[str]:
    """What each sensor learned of its pose and clock, against the drawn truth where the run
    had a real mast (``--mount-errors``): one row per sensor."""
    learned = report.get("calibration") or {}
    if not learned:
        return []
    drawn = (report.get("mount_errors") or {}).get("sensors", {})
    lines = [
        "",
        "Self-calibration at the end of the run (learned; drawn truth in brackets where the "
        "sensors were a real mast's):",
        "",
        "| sensor | state | yaw [deg] | pitch [deg] | roll [deg] | across/east [m] | "
        "north [m] | up [m] | clock late [ms] | samples |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def pair(
        value: float,
        truth: dict[str, float] | None,
        key: str,
        scale: float = 1.0,
        digits: int = 2,
    ) -> str:
        text = f"{scale * value:+.{digits}f}"
        if truth is not None:
            text += f" ({scale * truth[key]:+.{digits}f})"
        return text

    for sensor, entry in learned.items():
        c = entry["correction"]
        e = drawn.get(sensor)
        lines.append(
            f"| {sensor} | {entry['state']} | {pair(c['yaw_deg'], e, 'yaw_deg')} | "
            f"{pair(c['pitch_deg'], e, 'pitch_deg')} | {pair(c['roll_deg'], e, 'roll_deg')} | "
            f"{pair(c['x_m'], e, 'dx_m')} | {pair(c['y_m'], e, 'dy_m')} | "
            f"{pair(c['z_m'], e, 'dz_m')} | "
            f"{pair(entry['clock_offset_s'], e, 'clock_offset_s', 1000.0, 0)} | "
            f"{entry['samples']} |"
        )
    return lines


def _undisturbed(bump: dict[str, Any]) -> str:
    minutes = bump.get("false_alerts_by_undisturbed_minute") or []
    if not minutes:
        return ""
    return (
        f"; the {len(minutes)} other whole minutes: {sum(minutes) / len(minutes):.2f} a minute, "
        f"{min(minutes)} to {max(minutes)}"
    )


def bump_lines(report: dict[str, Any]) -> list[str]:
    """The knocked sensor's story (``--bump``): flagged, learned again, false alerts, errors."""
    bump = report.get("bump")
    if not bump:
        return []

    def cell(value: float | None, fmt: str = ".2f") -> str:
        return "-" if value is None else format(value, fmt)

    lines = [
        "",
        f"Bump: {bump['sensor_id']} turned {bump['yaw_deg']:+.1f} deg at {bump['at_s']:g} s. "
        f"Flagged after {cell(bump['flagged_after_s'], '.1f')} s, calibrated again after "
        f"{cell(bump['calibrated_again_after_s'], '.1f')} s. False alerts in the minute after: "
        f"{bump['false_alerts_minute_after']} (before it: "
        f"{cell(bump['false_alerts_per_minute_before'])} a minute{_undisturbed(bump)}).",
    ]
    for name in ("before", "from_5_min_after"):
        w = bump.get(name)
        if w:
            lines.append(
                f"- {name.replace('_', ' ')} ({w['from_s']:g}-{w['to_s']:g} s): fused RMSE "
                f"{cell(w['fused_rmse_longitudinal_m'])} / {cell(w['fused_rmse_lateral_m'])} m, "
                f"{w['id_switches']} identity switches, {w['false_alerts']} false alerts."
            )
    return lines


def markdown(report: dict[str, Any]) -> str:
    cell = _cell

    def ratio(value: float | None) -> str:  # three places: 0.946 must not read as 0.95
        return "-" if value is None else f"{value:.3f}"

    lines = [
        f"# Evaluation: `{report['site']}`, seed {report['seed']}, {report['duration_s']:g} "
        f"simulated s, vehicles within {report['max_range_m']:g} m of the mast",
        "",
        f"{report['vehicles']} vehicles. MOTA **{report['mota']:.3f}**, IDF1 "
        f"**{report['idf1']:.3f}**, identity switches {report['id_switches']} "
        f"({report['id_switches_per_100_vehicles']:.2f} per 100 vehicles). Lateral bias map "
        f"given to the tracker: {report.get('bias_map') or 'none'}.{_conditions(report)}",
        *mount_error_lines(report),
        *calibration_lines(report),
        *bump_lines(report),
        "",
        "| source | RMSE longitudinal [m] | RMSE lateral [m] | RMSE speed [m/s] | matched | "
        "missed |",
        "|---|---|---|---|---|---|",
    ]
    for source, row in report["sources"].items():
        lines.append(
            f"| {source} | {cell(row['rmse_longitudinal_m'])} | "
            f"{cell(row['rmse_lateral_m'])} | {cell(row['rmse_speed_mps'])} | "
            f"{row['matched']} | {row['missed_vehicles']} |"
        )
    summary = report["paper_table_summary"]
    lines += [
        "",
        f"Paper-style table ({summary['vehicles']} vehicles through the window; "
        "cumulative absolute error [m] over the common samples; lon / lat):",
        "",
        "| vehicle | samples | camera | LiDAR | average | paper KF | fused | fused, smoothed "
        "| fused, stored |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in report["paper_table"][:25]:
        cells = [
            f"{row[s]['longitudinal_m']:.1f} / {row[s]['lateral_m']:.1f}"
            for s in (
                "camera",
                "lidar",
                "average",
                "paper_kf",
                "fused",
                "fused_smoothed",
                "fused_stored",
            )
        ]
        lines.append(f"| {row['vehicle_id']} | {row['samples']} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Fused below the other sources (vehicles): "
        + ", ".join(
            f"{k.removeprefix('fused_below_')} {v}" for k, v in summary.items() if k != "vehicles"
        ),
        "",
    ]
    lines += [
        "",
        "Issue 6's targets on this run (`must_show`; - : this run cannot tell, or shown but "
        "not a target). The live track is held to the RMSE, MOTA and switch targets; the paper's "
        "tables are offline, so the paper table is held on the stored trajectories (what "
        "`/v1/trajectories` serves: the published states smoothed as the gateway smooths them).",
        "",
        "| check | value | target | holds |",
        "|---|---|---|---|",
    ]
    for row in report.get("must_show", []):
        holds = {True: "yes", False: "**no**", None: "-"}[row["holds"]]
        value = row["value"]
        shown = str(value) if isinstance(value, int) else ratio(value)
        lines.append(f"| {row['check']} | {shown} | {row['target']} | {holds} |")
    lines += _lane_volume_lines(report.get("lane_volumes"))
    coverage, circle = report.get("coverage"), report.get("circle")
    if coverage is not None and circle is not None:
        reach = ", ".join(
            f"{sensor} {span[0]:g} to {span[1]:g} m" if span else f"{sensor} nowhere"
            for sensor, span in coverage["per_sensor_reach_m"].items()
        )
        lines += [
            "",
            f"Scored region: {report.get('scored_region', 'circle')}. The sensors cover "
            f"{100 * coverage['covered_share_upstream']:.0f} % of the road upstream of the mast "
            f"inside the circle and {100 * coverage['covered_share_downstream']:.0f} % "
            f"downstream (where a car is sure to be seen; along the road, from the mast: "
            f"{reach}). Over the whole circle, covered or not: MOTA {ratio(circle['mota'])}, "
            f"{circle['id_switches_per_100_vehicles']:.1f} identity switches per 100 vehicles.",
        ]
    approach = report.get("approach")
    if approach is not None:
        lines += [
            "",
            f"On the approach alone (upstream of the mast, which every sensor faces): MOTA "
            f"{ratio(approach['mota'])}, {approach['id_switches_per_100_vehicles']:.1f} identity "
            "switches per 100 vehicles.",
        ]
    by_station = report.get("fused_by_station", [])
    if by_station:
        lines += [
            "",
            "| from the mast [m] | vehicle samples | missed | speed RMSE [m/s] | lateral RMSE [m] |",
            "|---|---|---|---|---|",
        ]
        for row in by_station:
            low, high = row["from_mast_m"]
            lines.append(
                f"| {low:+.0f} to {high:+.0f} | {row['vehicle_samples']} | "
                f"{ratio(row['missed_share'])} | {cell(row['rmse_speed_mps'])} | "
                f"{cell(row['rmse_lateral_m'])} |"
            )
    stretch = report.get("mast_stretch")
    if stretch and stretch.get("ratio") is not None:
        lines += [
            "",
            f"Speed within {stretch['within_m']:.0f} m of the mast (where the camera and radar "
            f"hand over to the LiDAR): RMSE {stretch['rmse_speed_mps']:.2f} m/s, "
            f"{stretch['ratio']:.2f} times the approach's {stretch['approach_rmse_speed_mps']:.2f}"
            f" m/s further upstream.",
        ]
    lines += _queue_lines(report.get("queue"))
    lines += [
        "",
        "Alerts (the alert service on the fused tracks against the same rules on the "
        "truth of the vehicles a sensor saw; in brackets, on every vehicle within "
        f"{ALERT_TRUTH_RANGE_M:.0f} m, hidden ones included):",
        "",
        "| alert | precision | recall | TP | FP | FN | median lead time [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    everything = report.get("alerts_all_in_range", {})
    for alert_type, row in report.get("alerts", {}).items():
        other = everything.get(alert_type, {})
        lines.append(
            f"| {alert_type} | {ratio(row.get('precision'))} "
            f"({ratio(other.get('precision'))}) | {ratio(row.get('recall'))} "
            f"({ratio(other.get('recall'))}) | {row.get('true_positives')} | "
            f"{row.get('false_positives')} | {row.get('false_negatives')} "
            f"({other.get('false_negatives')}) | {cell(row.get('lead_time_s'))} |"
        )
    lines.append("")
    for plot in report.get("plots", []):
        lines.append(f"![{plot}]({plot})")
    return "\n".join(lines) + "\n"


def _cell(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _queue_lines(queue: dict[str, Any] | None) -> list[str]:
    """Each lane's queue against the truth (:mod:`wz_eval.queue_report`)."""
    cell = _cell
    if not queue or (not queue["true_episodes"] and not queue["false_episodes"]):
        return []
    d = queue["definition"]
    lines = [
        "",
        f"Queues (a lane queued while {d['min_vehicles']} of its vehicles under "
        f"{d['slow_speed_mps']:g} m/s stand within {d['span_m']:g} m; stopped under "
        f"{d['stopped_speed_mps']:g} m/s; the same estimate on every vehicle's truth, "
        f"compared each {d['step_s']:g} s):",
        "",
        "| lane | reach [m] | queued s true / est. | back error median / p90 [m] | beyond reach s "
        "(flagged) | episodes found | onset delay median / max [s] | dissolution delay "
        "median [s] | false episodes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for lane, row in queue["lanes"].items():
        back, onset = row["back_error_m"], row["onset_delay_s"]
        lines.append(
            f"| {lane} | {row['reach_station_m']:g} | {row['true_queued_s']} / "
            f"{row['estimated_queued_s']} | {cell(back['median'])} / {cell(back['p90'])} | "
            f"{row['beyond_reach_s']} ({row['beyond_reach_flagged_s']}) | "
            f"{row['detected_episodes']} of {row['true_episodes']} | {cell(onset['median'])} / "
            f"{cell(onset['max'])} | {cell(row['dissolution_delay_s']['median'])} | "
            f"{row['false_episodes']} |"
        )
    return lines


def _lane_volume_lines(lane_volumes: dict[str, Any] | None) -> list[str]:
    """The WZDx traffic detector's counts per lane against the truth (empty without them)."""
    if not lane_volumes:
        return []
    lines = [
        "",
        f"Lane volumes at the WZDx traffic detector (station "
        f"{lane_volumes['detector_station_m']:g} m, {lane_volumes['interval_s']:g} s; lanes "
        "in WZDx order, 1 at the left; tolerance "
        f"{100 * lane_volumes['tolerance']:g} % of the truth):",
        "",
        "| lane | truth vehicles | track vehicles | error | truth / track veh/h | "
        "speed difference [m/s] | hidden | volume |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in [*lane_volumes["lanes"], lane_volumes["station"]]:
        error = row["volume_error"]
        speed = row["speed_difference_mps"]
        share = row.get("hidden_share")
        reliable = row.get("reliable")
        lines.append(
            f"| {row['lane_order'] or 'all'} | {row['truth_vehicles']} | "
            f"{row['track_vehicles']} | {'-' if error is None else f'{100 * error:+.1f} %'} | "
            f"{row['truth_volume_vph']:g} / {row['track_volume_vph']:g} | "
            f"{'-' if speed is None else f'{speed:+.2f}'} | "
            f"{'-' if share is None else f'{100 * share:.0f} %'} | "
            f"{'-' if reliable is None else ('reliable' if reliable else 'unreliable')} |"
        )
    return lines
