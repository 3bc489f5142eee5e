"""Markdown for BENCHMARKS.md from the results the benchmarks return (no measuring here).

This module writes the head (interference, summary, machine) and puts the sections together;
the sections live in :mod:`benchmarks.report_bus` and :mod:`benchmarks.report_sensors`, the
shared formatting in :mod:`benchmarks.report_format`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from benchmarks.report_bus import (
    alert_flood,
    alert_latency,
    bus_latency,
    bus_throughput,
    bus_trust,
    gateway_live,
    recovery,
    speeding_flood,
    webhook_latency,
)
from benchmarks.report_format import (
    fmt_latency,
    fmt_ms,
    fmt_rate,
    fmt_s,
    fmt_us,
    md_table,
    median_of,
)
from benchmarks.report_sensors import (
    camera_budget,
    camera_detection,
    camera_models,
    generated_sites,
    lidar_detection,
    queue_beyond_reach,
    self_calibration,
    sensors,
    sumo_step,
    tracker_cycle,
    traffic_sites,
)

# --- machine and summary ----------------------------------------------------------------------


def _machine(machine: dict[str, Any]) -> list[str]:
    versions = machine["versions"]
    rows = [
        ["CPU", f"{machine['cpu_model']}"],
        ["Cores", f"{machine['cores']} ({machine['cores_usable']} usable by this process)"],
        ["Memory", f"{machine['memory_gib']} GiB"],
        ["OS", f"{machine['os']}, kernel {machine['kernel']}"],
        ["Python", machine["python"]],
        ["Zenoh (eclipse-zenoh)", versions["eclipse-zenoh"]],
        ["numpy", versions["numpy"]],
        ["pydantic", versions["pydantic"]],
        ["SUMO (eclipse-sumo / libsumo)", f"{versions['eclipse-sumo']} / {versions['libsumo']}"],
    ]
    return ["## Machine", "", *md_table(["", ""], rows), ""]


def _interference(benchmarks: dict[str, Any]) -> list[str]:
    """A warning when other work shared the machine during a benchmark."""
    shares = {
        name: entry["cpu_other_during"]
        for name, entry in benchmarks.items()
        if entry.get("cpu_other_during", 0.0) > 0.1
    }
    if not shares:
        return []
    listed = ", ".join(f"`{name}` {100 * share:.0f} %" for name, share in shares.items())
    return [
        f"> **Other work shared this machine during the run** ({listed} of its CPU): on 2 "
        "cores that inflates the tails (p99, max) most and the medians less. Prefer a run on "
        "an idle machine.",
        "",
    ]


def _summary(benchmarks: dict[str, Any]) -> list[str]:
    lines: list[str] = []
    latency = benchmarks.get("bus_latency", {}).get("result")
    if latency:
        small, frames = latency["small"], latency["frames"]
        bus, raw = small["bus-json"]["one_way_us"], small["zenoh"]["one_way_us"]
        lines.append(
            f"- A ~200-byte JSON message between two processes through our bus: "
            f"**{fmt_us(bus['p50'])}** one way (p99 {fmt_us(bus['p99'])}); plain Zenoh "
            f"{fmt_us(raw['p50'])} (p99 {fmt_us(raw['p99'])}): "
            f"**{latency['ratios']['bus-json / zenoh (p50)']:.1f}x**."
        )
        shm = frames["bus-frames"]["one_way_us"]
        noshm = frames["bus-frames-noshm"]["one_way_us"]
        lines.append(
            f"- A 2 MB LiDAR frame through our bus: **{fmt_latency(shm['p50'])}** one way with "
            f"Zenoh's shared memory (p99 {fmt_latency(shm['p99'])}), {fmt_latency(noshm['p50'])} "
            f"without (p99 {fmt_latency(noshm['p99'])})."
        )
    throughput = benchmarks.get("bus_throughput", {}).get("result")
    if throughput:
        small, frames = throughput["small"], throughput["frames"]
        lines.append(
            f"- Throughput, ~200-byte messages: **{fmt_rate(small['bus-json']['messages_per_s'])} "
            f"msg/s** decoded through our bus, {fmt_rate(small['zenoh']['messages_per_s'])} msg/s "
            f"plain Zenoh; 2 MB frames: **{fmt_rate(frames['bus-frames']['messages_per_s'])} "
            f"frames/s** ({frames['bus-frames']['megabytes_per_s']:,.0f} MB/s) with shared "
            f"memory, {fmt_rate(frames['bus-frames-noshm']['messages_per_s'])} without. "
            + ("Nothing lost." if throughput["all_delivered"] else "**Samples were lost.**")
        )
    sumo = benchmarks.get("sumo_step", {}).get("result")
    if sumo:
        stepping = sumo["stepping"]
        ten = sumo["end_to_end"]
        lines.append(
            f"- SUMO step with {stepping['vehicles']['median']:.0f} vehicles: "
            f"**{fmt_ms(stepping['step_ms']['p50'])}** (p99 {fmt_ms(stepping['step_ms']['p99'])}), "
            f"{stepping['realtime_factor_median']:.0f}x real time at a "
            f"{stepping['step_s']} s step; "
            + "; ".join(
                f"{run['duration_s'] / 60:.0f} simulated minutes at "
                f"{run['vehicles_per_hour']:.0f} veh/h in {run['total_s']:.1f} s"
                for run in ten
            )
            + "."
        )
    sensors = benchmarks.get("sensors", {}).get("result")
    if sensors:
        lidar = sensors["frames"]["lidar"]["day"]
        camera = sensors["frames"]["camera"]["day"]
        radar = sensors["frames"]["radar"]["day"]
        targets = sensors["targets"]
        lines.append(
            f"- Sensors with {sensors['frames']['traffic']['vehicles_in_lidar_range']['median']:.0f} "
            f"vehicles within the LiDAR's range (day): LiDAR frame ({lidar['rays']:,} rays) "
            f"**{fmt_ms(lidar['frame_ms']['p50'])}** (target {fmt_ms(targets['lidar_frame_ms'])}), "
            f"camera render {camera['width_px']}x{camera['height_px']} "
            f"**{fmt_ms(camera['render_ms']['p50'])}** (target {fmt_ms(targets['camera_render_ms'])}) "
            f"+ JPEG {fmt_ms(camera['jpeg_ms']['p50'])}, radar scan **{fmt_ms(radar['scan_ms']['p50'])}** "
            f"(target {fmt_ms(targets['radar_scan_ms'])}); the whole simulator with all three: "
            f"**{sensors['node']['sim_per_wall']:.1f}x real time** as a node process over Zenoh, "
            f"{sensors['loop']['sim_per_wall']:.1f}x in process (target "
            f"{targets['sim_rate']:.0f}x); "
            + (
                "frame counts exact."
                if sensors["frame_counts_exact"]
                else "**frame counts not exact** (see the section)."
            )
        )
    detection = benchmarks.get("lidar_detection", {}).get("result")
    if detection:
        fast, reference = detection["fast"], detection["reference"]
        f_all, r_all = fast["bins"][-1], reference["bins"][-1]
        lines.append(
            f"- LiDAR detector on {detection['frames']} simulated 131k-ray frames: fast path "
            f"**{fmt_ms(fast['median_ms'])}**, reference (the paper's pipeline) "
            f"{fmt_ms(reference['median_ms'])}: **{detection['speedup']:.1f}x faster**; recall "
            f"{f_all['recall']:.2f} vs {r_all['recall']:.2f}, precision {f_all['precision']:.2f} "
            f"vs {r_all['precision']:.2f}, centre error median "
            f"{f_all['centre_error_median_m']:.2f} m vs {r_all['centre_error_median_m']:.2f} m "
            f"(vehicles within 120 m, >= 30 % visible); one core sustains "
            f"{detection['one_core']['frames_per_s']['fast']:.0f} frames/s (fast) and "
            f"{detection['one_core']['frames_per_s']['reference']:.1f} frames/s (reference)."
        )
    camera = benchmarks.get("camera_detection", {}).get("result")
    if camera:
        inference, service = camera["inference"], camera["service"]
        lines.append(
            f"- Camera detector: YOLO (shipped model, {inference['input_size_px'][1]} px, ROI and "
            f"far-field tile) **{fmt_ms(inference['steps']['total']['p50_ms'])}** per frame "
            f"(median); the whole per-frame work {fmt_ms(camera['per_frame']['p50_ms'])}; the node "
            f"process fed 10 fps camera and 15 Hz radar returned "
            f"**{service['batches_received']} of {service['frames_sent']}** frames, end-to-end "
            f"p99 {fmt_ms(service['end_to_end_latency']['p99_ms'])}."
        )
    models = benchmarks.get("camera_models", {}).get("result")
    if models:
        old, new = (
            models["per_frame_one_core"][label]["cases"] for label in models["per_frame_one_core"]
        )
        stack = list(models["stack_cpu_percent"].values())
        lines.append(
            f"- Camera models on one core, the default site's ROI and tile: the real-camera COCO "
            f"model (int8) **{fmt_ms(new['default site, ROI + tile']['p50_ms'])}** per frame, "
            f"the simulator-trained one {fmt_ms(old['default site, ROI + tile']['p50_ms'])} "
            f"(median); a 320x240 frame whole {fmt_ms(new['whole frame 320x240']['p50_ms'])}; "
            f"the whole stack at full sensor rates {stack[1]['all']:.0f} % vs "
            f"{stack[0]['all']:.0f} % of one core (2 cores: saturated)."
        )
    budget = benchmarks.get("camera_budget", {}).get("result")
    if budget:
        case = next(iter(budget["cases"].values()))
        now, before = case["per_frame"]["now"], case["per_frame"]["before"]
        stack = budget["stack_cpu_percent"]
        lines.append(
            f"- The camera at {budget['camera_fps']:.0f} fps on one core (default site): "
            f"**{fmt_ms(now['cpu']['p50_ms'])}** median CPU per frame "
            f"({fmt_ms(before['cpu']['p50_ms'])} before), {case['node']['now']['frames_missing']} "
            f"of {case['node']['now']['frames_sent']} frames dropped, end-to-end p99 "
            f"{fmt_ms(case['node']['now']['end_to_end']['p99_ms'])}; the stack but the "
            f"simulator **{stack['now']['all but the simulator']:.0f} %** of one core "
            f"({stack['before']['all but the simulator']:.0f} % before)."
        )
    tracker = benchmarks.get("tracker_cycle", {}).get("result")
    if tracker:
        lines.append(
            f"- Fusion tracker, {tracker['vehicles']} tracks and three sensors: a cycle "
            f"**{fmt_ms(tracker['cycle']['median_ms'])}** median, p99 "
            f"{fmt_ms(tracker['cycle']['p99_ms'])}; the 10 Hz snapshot "
            f"{fmt_ms(tracker['snapshot']['median_ms'])}."
        )
    alerts = benchmarks.get("alert_latency", {}).get("result")
    if alerts:
        one, busy = alerts["variants"]["one_track"], alerts["variants"]["51_tracks"]
        lines.append(
            f"- Alert service (the node process on Zenoh): track batch that completes a rule to "
            f"the alert received **{fmt_ms(one['latency_ms']['p50'])}** median, p99 "
            f"{fmt_ms(one['latency_ms']['p99'])} (one track); with "
            f"{busy['tracks_per_batch']} tracks a batch {fmt_ms(busy['latency_ms']['p50'])} "
            f"median, p99 {fmt_ms(busy['latency_ms']['p99'])}."
        )
    trust = benchmarks.get("bus_trust", {}).get("result")
    if trust:
        deployed, plain = trust["variants"]["tls+acl"], trust["variants"]["plain"]
        ratios = trust["ratios"]["tls+acl"]
        lines.append(
            f"- The deployed bus (mutual TLS and access control, through the router) against "
            f"the plain one: latency **{fmt_latency(deployed['latency_us']['p50'])}** vs "
            f"{fmt_latency(plain['latency_us']['p50'])} median (x{ratios['latency_p50']:.2f}); "
            f"200 B messages **{fmt_rate(deployed['small']['msg_per_s'])}**/s vs "
            f"{fmt_rate(plain['small']['msg_per_s'])}/s (x{ratios['small_msg_per_s']:.2f}); "
            f"2 MB frames x{ratios['frames_msg_per_s']:.2f}."
        )
    speeding = benchmarks.get("speeding_flood", {}).get("result")
    if speeding:
        on, off = speeding["gate_on"], speeding["gate_off"]

        def late(value: float | None) -> str:
            return "never" if value is None else fmt_ms(1e3 * value)

        lines.append(
            f"- A speeding car inside a replay flood ({speeding['target_rate_hz']:,.0f} batches "
            f"a second of 20 tracks): its alert stored **{late(on['stored_s'])}** and webhooked "
            f"**{late(on['webhooked_s'])}** past the rule's hold time with the alert service's "
            f"gate, {late(off['stored_s'])} and {late(off['webhooked_s'])} without it (bound "
            f"{speeding['bound_s']:.0f} s)."
        )
    flood = benchmarks.get("alert_flood", {}).get("result")
    if flood:
        lines.append(
            f"- Alerts first: during {flood['flood']['rate_hz']:,.0f} track batches a second, "
            f"an alert stored **{fmt_ms(1e3 * flood['stored']['max'])}** and webhooked "
            f"**{fmt_ms(1e3 * flood['webhooked']['max'])}** after its publication at worst "
            f"(bound {flood['bound_s']:.0f} s); {flood['locked_count']} locked-database errors."
        )
    hooks = benchmarks.get("webhook_latency", {}).get("result")
    if hooks:
        one, four = hooks["variants"]["one_subscription"], hooks["variants"]["four_subscriptions"]
        lines.append(
            f"- Gateway webhooks (the node process on Zenoh, SQLite): alert published to its "
            f"signed POST at the receiver **{fmt_ms(one['latency_ms']['p50'])}** median, p99 "
            f"{fmt_ms(one['latency_ms']['p99'])}; to four subscribers, the last of them "
            f"{fmt_ms(four['latency_ms']['p50'])} median, p99 {fmt_ms(four['latency_ms']['p99'])}."
        )
    gateway = benchmarks.get("gateway_live", {}).get("result")
    if gateway:
        run = gateway["variants"]["smoothing"]
        live, loaded = run["loaded"]["live"], run["loaded"]
        lines.append(
            f"- Gateway under load (the node process, SQLite; {run['tracks_per_batch']} tracks "
            f"at {run['rate_hz']:.0f} Hz, five ending and smoothed a second): "
            f"`GET /v1/tracks/live` **{live['requests_per_s']:,.0f} requests/s** from "
            f"{run['live_clients']} clients, {fmt_ms(live['latency_ms']['p50'])} median, p99 "
            f"{fmt_ms(live['latency_ms']['p99'])}; batch published to stored "
            f"**{fmt_ms(run['ingest_only']['ingest_lag_ms']['p50'])}** median alone (p99 "
            f"{fmt_ms(run['ingest_only']['ingest_lag_ms']['p99'])}), "
            f"{fmt_ms(loaded['ingest_lag_ms']['p50'])} (p99 {fmt_ms(loaded['ingest_lag_ms']['p99'])}) "
            f"under that load."
        )
    crashes = benchmarks.get("recovery", {}).get("result")
    if crashes:
        services = crashes["services"]
        worst = max(services, key=lambda name: services[name]["recovered_s"]["median"] or 0.0)
        plain = {
            r["service"]: r["recovered_s"]
            for r in crashes["without_standby"]
            if r["recovered_s"] is not None
        }
        slowest = max(plain, key=lambda name: plain[name]) if plain else None
        lines.append(
            f"- `kill -9` of each service of `wz up` in turn: restarted after "
            f"**{fmt_s(median_of(services, 'restart_s'))}** (median over services), pipeline back "
            f"to the gateway within **{fmt_s(services[worst]['recovered_s']['median'])}** at worst "
            f"({worst}, median of {crashes['rounds']} rounds; target {crashes['target_s']:.0f} "
            f"s); restarted as new interpreters, without the warm standbys, up to "
            f"{fmt_s(plain.get(slowest) if slowest else None)} ({slowest}). "
            + (
                "The gateway lost nothing it had stored."
                if not any(crashes["gateway_lost"])
                else "**The gateway lost stored data.**"
            )
        )
    sites = benchmarks.get("generated_sites", {}).get("result")
    if sites:
        worst = {row["target"]: row for row in sites["distribution"]}
        mota = worst.get("MOTA")
        lines.append(
            f"- The whole pipeline on {sites['count']} generated sites never used in "
            f"development ({sites['duration_s']:.0f} s each): **{sites['sites_meeting_every_target']}"
            f" of {sites['count']}** meet every target of issue 25"
            + (
                f"; MOTA >= 0.95 on {mota['sites_meeting']} (median {mota['median']:.3g})."
                if mota and mota["median"] is not None
                else "."
            )
        )
    return ["## Summary", "", *lines, ""] if lines else []


SECTIONS: dict[str, tuple[str, Callable[[dict[str, Any]], list[str]]]] = {
    "bus_latency": ("one-way latency between two processes", bus_latency),
    "bus_throughput": ("messages per second between two processes", bus_throughput),
    "bus_trust": ("the bus's mutual TLS and access control against the plain bus", bus_trust),
    "sumo_step": ("the simulator's SUMO step", sumo_step),
    "sensors": ("the simulator's sensor models and the whole simulator", sensors),
    "lidar_detection": ("the LiDAR detector's two paths: accuracy and speed", lidar_detection),
    "camera_detection": (
        "the camera-radar detector: YOLO, per frame, the node at 10 fps",
        camera_detection,
    ),
    "camera_models": (
        "the camera detector's two models on one core, and the stack's CPU with each",
        camera_models,
    ),
    "camera_budget": (
        "the edge box's budget: the camera node at 30 fps on one core, and the stack with a "
        "30 fps camera, this code beside the code before it (issue 41)",
        camera_budget,
    ),
    "tracker_cycle": (
        "the fusion tracker's cycle with 200 tracks and three sensors",
        tracker_cycle,
    ),
    "alert_latency": ("the alert service: track batch to alert on the bus", alert_latency),
    "alert_flood": (
        "alerts first: an alert stored and webhooked during a flood of track batches",
        alert_flood,
    ),
    "speeding_flood": (
        "a speeding car inside a flood of track batches: alerted, stored, webhooked in time",
        speeding_flood,
    ),
    "webhook_latency": (
        "gateway webhooks: alert on the bus to the signed POST at the receiver",
        webhook_latency,
    ),
    "gateway_live": (
        "the gateway storing 20 Hz track batches while clients read the live API",
        gateway_live,
    ),
    "recovery": ("`kill -9` of each service of `wz up`: restart and pipeline recovery", recovery),
    "generated_sites": (
        "the whole pipeline on 12 generated sites it was never tuned on (issue 25)",
        generated_sites,
    ),
    "traffic_sites": (
        "the whole pipeline on 24 generated sites it was never tuned on, 12 in free flow and "
        "12 congested (issue 40)",
        traffic_sites,
    ),
    "queue_beyond_reach": (
        "a queue's back beyond the mast's reach bounded by upstream point speed sensors, on "
        "the 12 congested sites (issue 40)",
        queue_beyond_reach,
    ),
    "self_calibration": (
        "the sensors' self-calibration: CPU at full rates, time to learn against traffic",
        self_calibration,
    ),
}


def _other_machines(results: dict[str, Any]) -> list[str]:
    """A warning naming the benchmarks whose figures come from another machine than this
    file's (``--only`` run on a new machine keeps the others, labelled)."""
    names = [
        name
        for name, entry in results["benchmarks"].items()
        if entry.get("machine") and entry["machine"] != results["machine"]
    ]
    if not names:
        return []
    return [
        f"> **Measured on another machine** than the one below: {', '.join(names)} (each "
        "section names its machine). Compare figures only within one machine.",
        "",
    ]


def render(results: dict[str, Any]) -> str:
    """The whole BENCHMARKS.md."""
    lines = [
        "# Benchmarks",
        "",
        f"Written by `{results['command']}` at {results['generated_at']} (UTC); do not edit: "
        "run it again. Raw numbers: `benchmarks/results.json`. Each benchmark is a module "
        "in `benchmarks/` with its method in its docstring.",
        "",
        *_interference(results["benchmarks"]),
        *_other_machines(results),
        *_summary(results["benchmarks"]),
        *_machine(results["machine"]),
    ]
    for name, entry in results["benchmarks"].items():
        title, section = SECTIONS[name]
        lines += [f"## `{name}`: {title}", ""]
        lines += [
            f"Measured {entry['measured_at']}, "
            f"{'**quick run** (fewer samples)' if entry['quick'] else 'full run'}, "
            f"{entry['wall_s']} s. Share of the machine's CPU used by other work just before: "
            f"{100 * entry['cpu_busy_before']:.0f} %, during: "
            f"{100 * entry.get('cpu_other_during', float('nan')):.0f} %.",
            "",
        ]
        other = entry.get("machine")
        if other and other != results["machine"]:
            lines += [
                f"**Measured on another machine**: {other.get('cpu_model', '?')}, "
                f"{other.get('cores', '?')} cores, {other.get('memory_gib', '?')} GiB "
                "(not this file's; compare only within this section).",
                "",
            ]
        if "error" in entry:
            lines += ["**Failed:**", "", "```", entry["error"].rstrip(), "```", ""]
        else:
            lines += section(entry["result"])
    return "\n".join(lines).rstrip() + "\n"
