"""Markdown for BENCHMARKS.md from the results the benchmarks return (no measuring here)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

SMALL_PATHS = {
    "zenoh": "plain Zenoh publisher and Python callback, bytes, no codec (baseline)",
    "zenoh-fifo": "plain Zenoh, Zenoh's `FifoChannel`, `recv()` on the main thread, no codec",
    "bus-raw": "`Bus`: `put_bytes`, `subscribe_raw` FIFO queue, `recv` on the main thread",
    "bus-callback": "`Bus`: `put` (encode), `on` (decode on Zenoh's thread), no queue",
    "bus-json": "`Bus`: `put` (encode), `subscribe` FIFO queue, `recv` + decode: a service's path",
}
FRAME_PATHS = {
    "zenoh-frames": "plain Zenoh, bytes, Python callback (the echo republishes the received "
    "payload without copying it)",
    "bus-frames": "`encode_lidar_frame` + `put_bytes`, `subscribe_frames` FIFO, `recv` + decode "
    "(the echo decodes and re-encodes)",
}
THROUGHPUT_PATHS = {
    "zenoh": "plain Zenoh `put(bytes)`; a Python callback counts",
    "zenoh-fifo": "plain Zenoh `put(bytes)`; Zenoh's `FifoChannel`, `recv()` on the main thread",
    "bus-raw": "`Bus.put_bytes`; `subscribe_raw` FIFO, `recv` on the main thread",
    "bus-json": "`Bus.put` (encode); `subscribe` FIFO, `recv` + decode",
    "zenoh-frames": "plain Zenoh `put(bytes)` of pre-built payloads; a Python callback counts",
    "bus-frames": "`encode_lidar_frame` + `put_bytes`; `subscribe_frames` FIFO, `recv` + decode",
}


def _us(value: float) -> str:
    return f"{value:.0f} µs" if value >= 100 else f"{value:.1f} µs"


def _ms(value: float) -> str:
    return f"{value:.2f} ms" if value < 10 else f"{value:.1f} ms"


def _latency(value_us: float) -> str:
    return _us(value_us) if value_us < 1000 else _ms(value_us / 1000)


def _rate(value: float) -> str:
    return f"{value:,.0f}"


def _round_range(values_us: list[float]) -> str:
    if len(values_us) == 1:
        return _latency(values_us[0])
    return f"{_latency(min(values_us))} – {_latency(max(values_us))}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def _base_path(name: str) -> str:
    return name.removesuffix("-noshm")


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
    return ["## Machine", "", *_table(["", ""], rows), ""]


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
            f"**{_us(bus['p50'])}** one way (p99 {_us(bus['p99'])}); plain Zenoh "
            f"{_us(raw['p50'])} (p99 {_us(raw['p99'])}): "
            f"**{latency['ratios']['bus-json / zenoh (p50)']:.1f}x**."
        )
        shm = frames["bus-frames"]["one_way_us"]
        noshm = frames["bus-frames-noshm"]["one_way_us"]
        lines.append(
            f"- A 2 MB LiDAR frame through our bus: **{_latency(shm['p50'])}** one way with "
            f"Zenoh's shared memory (p99 {_latency(shm['p99'])}), {_latency(noshm['p50'])} "
            f"without (p99 {_latency(noshm['p99'])})."
        )
    throughput = benchmarks.get("bus_throughput", {}).get("result")
    if throughput:
        small, frames = throughput["small"], throughput["frames"]
        lines.append(
            f"- Throughput, ~200-byte messages: **{_rate(small['bus-json']['messages_per_s'])} "
            f"msg/s** decoded through our bus, {_rate(small['zenoh']['messages_per_s'])} msg/s "
            f"plain Zenoh; 2 MB frames: **{_rate(frames['bus-frames']['messages_per_s'])} "
            f"frames/s** ({frames['bus-frames']['megabytes_per_s']:,.0f} MB/s) with shared "
            f"memory, {_rate(frames['bus-frames-noshm']['messages_per_s'])} without. "
            + ("Nothing lost." if throughput["all_delivered"] else "**Samples were lost.**")
        )
    sumo = benchmarks.get("sumo_step", {}).get("result")
    if sumo:
        stepping = sumo["stepping"]
        ten = sumo["end_to_end"]
        lines.append(
            f"- SUMO step with {stepping['vehicles']['median']:.0f} vehicles: "
            f"**{_ms(stepping['step_ms']['p50'])}** (p99 {_ms(stepping['step_ms']['p99'])}), "
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
            f"**{_ms(lidar['frame_ms']['p50'])}** (target {_ms(targets['lidar_frame_ms'])}), "
            f"camera render {camera['width_px']}x{camera['height_px']} "
            f"**{_ms(camera['render_ms']['p50'])}** (target {_ms(targets['camera_render_ms'])}) "
            f"+ JPEG {_ms(camera['jpeg_ms']['p50'])}, radar scan **{_ms(radar['scan_ms']['p50'])}** "
            f"(target {_ms(targets['radar_scan_ms'])}); the whole simulator with all three: "
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
            f"**{_ms(fast['median_ms'])}**, reference (the paper's pipeline) "
            f"{_ms(reference['median_ms'])}: **{detection['speedup']:.1f}x faster**; recall "
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
            f"far-field tile) **{_ms(inference['steps']['total']['p50_ms'])}** per frame "
            f"(median); the whole per-frame work {_ms(camera['per_frame']['p50_ms'])}; the node "
            f"process fed 10 fps camera and 15 Hz radar returned "
            f"**{service['batches_received']} of {service['frames_sent']}** frames, end-to-end "
            f"p99 {_ms(service['end_to_end_latency']['p99_ms'])}."
        )
    tracker = benchmarks.get("tracker_cycle", {}).get("result")
    if tracker:
        lines.append(
            f"- Fusion tracker, {tracker['vehicles']} tracks and three sensors: a cycle "
            f"**{_ms(tracker['cycle']['median_ms'])}** median, p99 "
            f"{_ms(tracker['cycle']['p99_ms'])}; the 10 Hz snapshot "
            f"{_ms(tracker['snapshot']['median_ms'])}."
        )
    alerts = benchmarks.get("alert_latency", {}).get("result")
    if alerts:
        one, busy = alerts["variants"]["one_track"], alerts["variants"]["51_tracks"]
        lines.append(
            f"- Alert service (the node process on Zenoh): track batch that completes a rule to "
            f"the alert received **{_ms(one['latency_ms']['p50'])}** median, p99 "
            f"{_ms(one['latency_ms']['p99'])} (one track); with "
            f"{busy['tracks_per_batch']} tracks a batch {_ms(busy['latency_ms']['p50'])} "
            f"median, p99 {_ms(busy['latency_ms']['p99'])}."
        )
    hooks = benchmarks.get("webhook_latency", {}).get("result")
    if hooks:
        one, four = hooks["variants"]["one_subscription"], hooks["variants"]["four_subscriptions"]
        lines.append(
            f"- Gateway webhooks (the node process on Zenoh, SQLite): alert published to its "
            f"signed POST at the receiver **{_ms(one['latency_ms']['p50'])}** median, p99 "
            f"{_ms(one['latency_ms']['p99'])}; to four subscribers, the last of them "
            f"{_ms(four['latency_ms']['p50'])} median, p99 {_ms(four['latency_ms']['p99'])}."
        )
    gateway = benchmarks.get("gateway_live", {}).get("result")
    if gateway:
        run = gateway["variants"]["smoothing"]
        live, loaded = run["loaded"]["live"], run["loaded"]
        lines.append(
            f"- Gateway under load (the node process, SQLite; {run['tracks_per_batch']} tracks "
            f"at {run['rate_hz']:.0f} Hz, five ending and smoothed a second): "
            f"`GET /v1/tracks/live` **{live['requests_per_s']:,.0f} requests/s** from "
            f"{run['live_clients']} clients, {_ms(live['latency_ms']['p50'])} median, p99 "
            f"{_ms(live['latency_ms']['p99'])}; batch published to stored "
            f"**{_ms(run['ingest_only']['ingest_lag_ms']['p50'])}** median alone (p99 "
            f"{_ms(run['ingest_only']['ingest_lag_ms']['p99'])}), "
            f"{_ms(loaded['ingest_lag_ms']['p50'])} (p99 {_ms(loaded['ingest_lag_ms']['p99'])}) "
            f"under that load."
        )
    crashes = benchmarks.get("recovery", {}).get("result")
    if crashes:
        services = crashes["services"]
        worst = max(services, key=lambda name: services[name]["recovered_s"]["median"] or 0.0)
        plain = {r["service"]: r["recovered_s"] for r in crashes["without_standby"]
                 if r["recovered_s"] is not None}  # fmt: skip
        slowest = max(plain, key=lambda name: plain[name]) if plain else None
        lines.append(
            f"- `kill -9` of each service of `wz up` in turn: restarted after "
            f"**{_s(_median_of(services, 'restart_s'))}** (median over services), pipeline back "
            f"to the gateway within **{_s(services[worst]['recovered_s']['median'])}** at worst "
            f"({worst}, median of {crashes['rounds']} rounds; target {crashes['target_s']:.0f} "
            f"s); restarted as new interpreters, without the warm standbys, up to "
            f"{_s(plain.get(slowest) if slowest else None)} ({slowest}). "
            + ("The gateway lost nothing it had stored."
               if not any(crashes["gateway_lost"]) else "**The gateway lost stored data.**")
        )  # fmt: skip
    return ["## Summary", "", *lines, ""] if lines else []


def _s(value: float | None) -> str:
    return "—" if value is None else f"{value:.1f} s"


def _median_of(services: dict[str, Any], name: str) -> float | None:
    values = sorted(v[name]["median"] for v in services.values() if v[name]["median"] is not None)
    return values[len(values) // 2] if values else None


# --- per benchmark ----------------------------------------------------------------------------


def _bus_latency(result: dict[str, Any]) -> list[str]:
    lines = [
        "Ping-pong between this process and an echo process over Zenoh on `tcp/127.0.0.1` "
        "(two peers, explicit endpoints, multicast off). The echo republishes each sample on "
        "another key through the same API; one-way latency = round trip / 2. One sample in "
        "flight at a time, after a warm-up. Each hop wakes a waiting thread; on this virtual "
        "machine a thread woken on an idle core also pays that core's wake-up, so medians "
        "are lower when other work keeps the cores busy (and tails higher).",
        "",
        "### Small messages (~200 bytes: a `RadarScan` with one target, or 200 raw bytes)",
        "",
    ]
    rows = []
    for name, entry in result["small"].items():
        stats = entry["one_way_us"]
        rows.append(
            [
                f"`{name}`",
                SMALL_PATHS.get(name, ""),
                str(entry["payload_bytes"]),
                f"{stats['n']} ({entry['rounds']})",
                f"**{_us(stats['p50'])}**",
                _round_range(entry["round_p50_us"]),
                _us(stats["p90"]),
                _us(stats["p99"]),
                _us(stats["max"]),
            ]
        )
    header = [
        "Path",
        "What a sample goes through",
        "Bytes",
        "Samples (rounds)",
        "p50",
        "p50 of each round",
        "p90",
        "p99",
        "max",
    ]
    lines += [*_table(header, rows), ""]
    lines += ["### LiDAR frames (131072 points x 4 float32, 2 MB)", ""]
    rows = []
    for name, entry in result["frames"].items():
        stats = entry["one_way_us"]
        rows.append(
            [
                f"`{_base_path(name)}`",
                "on" if entry["shm"] else "off",
                FRAME_PATHS.get(_base_path(name), ""),
                f"{entry['payload_bytes']:,}",
                f"{stats['n']} ({entry['rounds']})",
                f"**{_latency(stats['p50'])}**",
                _round_range(entry["round_p50_us"]),
                _latency(stats["p90"]),
                _latency(stats["p99"]),
                _latency(stats["max"]),
            ]
        )
    header = [
        "Path",
        "Shared memory",
        "What",
        "Bytes",
        "Samples (rounds)",
        "p50",
        "p50 of each round",
        "p90",
        "p99",
        "max",
    ]
    lines += [*_table(header, rows), ""]
    lines += ["### Ratios", ""]
    lines += _table(
        ["Ratio", "Value"], [[name, f"{value:.2f}"] for name, value in result["ratios"].items()]
    )
    return [*lines, ""]


def _bus_throughput(result: dict[str, Any]) -> list[str]:
    lines = [
        "The peer publishes numbered samples as fast as it can (blocking congestion control, "
        "reliable); this process takes every one, checks the order, and times first to last "
        "arrival. Counts are checked after the peer has stopped: exact, none lost, none extra. "
        "Each path runs in several rounds (fresh processes, round-robin over the paths); the "
        "rates are the median round's, with every round's beside them.",
        "",
    ]
    rows = []
    for table in ("small", "frames"):
        for name, entry in result[table].items():
            rows.append(
                [
                    f"`{_base_path(name)}`",
                    "on" if entry["shm"] else "off",
                    THROUGHPUT_PATHS.get(_base_path(name), ""),
                    f"{entry['payload_bytes']:,}",
                    f"{entry['rounds']} x {entry['sent_per_round']:,}",
                    f"{entry['lost']} / {entry['extra']} / {entry['out_of_order']}",
                    f"**{_rate(entry['messages_per_s'])}**",
                    ", ".join(_rate(rate) for rate in entry["messages_per_s_rounds"]),
                    f"{entry['megabytes_per_s']:,.1f}",
                    _rate(entry["publisher_messages_per_s"]),
                ]
            )
    header = [
        "Path",
        "Shared memory",
        "What",
        "Bytes",
        "Sent",
        "Lost / extra / out of order",
        "Received msg/s",
        "Each round",
        "MB/s",
        "Publisher puts/s",
    ]
    lines += [*_table(header, rows), ""]
    lines.append(
        "All delivered exactly, in order."
        if result["all_delivered"]
        else "**Some samples were lost, duplicated or out of order (see the table).**"
    )
    lines += ["", "### Ratios", ""]
    lines += _table(
        ["Ratio", "Value"], [[name, f"{value:.2f}"] for name, value in result["ratios"].items()]
    )
    return [*lines, ""]


def _sumo_step(result: dict[str, Any]) -> list[str]:
    stepping = result["stepping"]
    vehicles = stepping["vehicles"]
    lines = [
        f"`TrafficWorld` on the default site (libsumo, its own process), "
        f"{stepping['vehicles_per_hour']:.0f} veh/h, step {stepping['step_s']} s, "
        f"`realtime_factor=0`. Warm-up until {stepping['target_vehicles']} vehicles were on the "
        f"road ({stepping['warmup_vehicles']} after {stepping['warmup_sim_s']:.0f} simulated s, "
        f"{stepping['warmup_wall_s']:.1f} s wall), "
        f"then {stepping['steps']} timed steps with {vehicles['min']} / "
        f"{vehicles['median']:.0f} / {vehicles['max']} vehicles (min / median / max).",
        "",
    ]
    step = stepping["step_ms"]
    parts = [
        ("`TrafficWorld.step()` (SUMO step + `VehicleTruth` messages)", stepping["step_ms"]),
        ("of which, re-measured: `site.road_frame.to_road` of the vehicles", stepping["to_road_ms"]),
        ("of which, re-measured: validating the `VehicleTruth`s", stepping["vehicle_truth_validate_ms"]),
        ("for comparison: `VehicleTruth.model_construct` (no validation)", stepping["vehicle_truth_construct_ms"]),
        (
            f"node's extra: `GroundTruth` build + encode "
            f"({stepping['ground_truth_bytes_median'] / 1000:.1f} kB)",
            stepping["ground_truth_build_encode_ms"],
        ),
    ]  # fmt: skip
    rows = [[what, f"**{_ms(s['p50'])}**", _ms(s["p99"]), _ms(s["max"])] for what, s in parts]
    lines += [*_table(["Per step", "p50", "p99", "max"], rows), ""]
    lines += _table(
        ["Derived", "Value"],
        [
            [
                f"real-time factor at a {stepping['step_s']} s step (step / median step time)",
                f"**{stepping['realtime_factor_median']:.0f}x**",
            ],
            [
                "real-time factor over the timed steps (sum of step times)",
                f"{stepping['realtime_factor_overall']:.0f}x",
            ],
            [
                f"share of the {1000 * stepping['step_s']:.0f} ms step budget used (median)",
                f"{100 * step['p50'] / (1000 * stepping['step_s']):.1f} %",
            ],
            ["step time per vehicle (mean)", _us(stepping["per_vehicle_step_us"])],
            ["libsumo start-up, network built in a fresh folder", f"{stepping['startup_s']:.2f} s"],
            ["collisions / teleports during the timed steps", f"{stepping['collisions']} / {stepping['teleports']}"],
        ],
    )  # fmt: skip
    lines += ["", "### Whole runs, end to end", ""]
    rows = [
        [
            f"{run['vehicles_per_hour']:.0f}",
            f"{run['duration_s']:.0f} s",
            f"{run['steps']:,}",
            f"{run['vehicles']['median']:.0f} / {run['vehicles']['max']}",
            f"{run['startup_s']:.2f} s",
            f"{run['stepping_s']:.2f} s",
            f"**{run['total_s']:.2f} s**",
            f"{run['realtime_factor']:.0f}x",
            f"{run['departed']} / {run['arrived']}",
            f"{run['collisions']} / {run['teleports']}",
        ]
        for run in result["end_to_end"]
    ]
    header = [
        "veh/h",
        "Simulated",
        "Steps",
        "Vehicles median / max",
        "Start-up",
        "Stepping",
        "Total",
        "Sim / wall",
        "Departed / arrived",
        "Collisions / teleports",
    ]
    lines += _table(header, rows)
    return [*lines, ""]


def _spread(counts: dict[str, Any]) -> str:
    """min / median / max of a count."""
    return f"{counts['min']} / {counts['median']:.0f} / {counts['max']}"


def _frame_stats(stats: dict[str, float]) -> list[str]:
    return [f"**{_ms(stats['p50'])}**", _ms(stats["p90"]), _ms(stats["p99"]), _ms(stats["max"])]


def _gc(split: dict[str, Any]) -> list[str]:
    """Calls a full garbage collection fell in; the slowest call without one."""
    return [str(split["calls_with_full_gc"]), _ms(split["max_ms_without_full_gc"])]


def _sensors(result: dict[str, Any]) -> list[str]:
    frames, loop, node = result["frames"], result["loop"], result["node"]
    traffic, targets, ratios = frames["traffic"], result["targets"], result["ratios"]
    lidar, camera, radar = frames["lidar"], frames["camera"], frames["radar"]
    lines = [
        f"Default site. Traffic for the per-frame times: `TrafficWorld` at "
        f"{traffic['vehicles_per_hour']:.0f} veh/h (seed {traffic['seed']}), warmed up "
        f"{traffic['warmup_sim_s']:.0f} simulated s (until {traffic['target_in_lidar_range']} "
        f"vehicles were within the LiDAR's range), then the truths of {traffic['steps']} steps "
        f"({traffic['steps'] * traffic['step_s']:.0f} s) kept: "
        f"{_spread(traffic['vehicles_on_road'])} "
        f"vehicles on the 2 km road, {_spread(traffic['vehicles_in_lidar_range'])} within the "
        "LiDAR's 200 m (min / median / max). Frame i is made from the truth of step i, as the "
        f"rig does, after {frames['untimed_frames']} untimed frames. open3d {frames['versions']['open3d']}, OpenCV "
        f"{frames['versions']['opencv']} ({frames['threads']['opencv']} threads), "
        f"{frames['threads']['cores']} cores. Wall times; CPU / wall above 1 means more than "
        "one core at work. A full GC: Python's generation-2 garbage collection ran during the "
        "call (counted with `gc.callbacks`); the slowest call without one is shown beside.",
        "",
    ]
    rows = [
        [
            f"LiDAR frame, {lidar['day']['rays']:,} rays (day)",
            f"**{_ms(lidar['day']['frame_ms']['p50'])}**",
            f"<= {_ms(targets['lidar_frame_ms'])}",
            f"{ratios['lidar_frame_ms']:.2f}",
        ],
        [
            f"camera render {camera['day']['width_px']}x{camera['day']['height_px']} (day)",
            f"**{_ms(camera['day']['render_ms']['p50'])}**",
            f"<= {_ms(targets['camera_render_ms'])}",
            f"{ratios['camera_render_ms']:.2f}",
        ],
        [
            "radar scan (day)",
            f"**{_ms(radar['day']['scan_ms']['p50'])}**",
            f"<= {_ms(targets['radar_scan_ms'])}",
            f"{ratios['radar_scan_ms']:.2f}",
        ],
        [
            "whole simulator, node process over Zenoh (simulated s / wall s)",
            f"**{node['sim_per_wall']:.2f}x**",
            f">= {targets['sim_rate']:.0f}x",
            f"{ratios['sim_rate_node']:.2f}",
        ],
        [
            "whole simulator, `run_loop` in process, no bus",
            f"**{loop['sim_per_wall']:.2f}x**",
            f">= {targets['sim_rate']:.0f}x",
            f"{ratios['sim_rate_loop']:.2f}",
        ],
    ]
    lines += _table(["Median", "Measured", "Target", "Measured / target"], rows)
    lines += [
        "",
        "A time meets its target when measured / target is below 1, the simulation rate when "
        "it is above 1.",
        "",
        "### LiDAR (`LidarModel.scan`)",
        "",
        f"Static scene (`static_scene(site)`: {frames['static_scene']['boxes']} boxes, "
        f"{frames['static_scene']['ground_polygons']} ground polygons) built once in "
        f"{1000 * frames['static_scene']['build_s']:.0f} ms. The model's build casts every ray "
        "at the static scene once; a frame casts only rays that may meet a vehicle.",
        "",
    ]
    rows = [
        [
            name,
            f"{1000 * entry['model_build_s']:.0f} ms",
            f"{entry['frame_ms']['n']}",
            *_frame_stats(entry["frame_ms"]),
            *_gc(entry["frame_gc"]),
            f"{entry['cpu_per_wall']:.2f}",
            f"{entry['rays']:,}",
            f"{entry['returns']['median']:,.0f}",
            _spread(entry["vehicle_points"]),
            _spread(entry["vehicles_hit"]),
        ]
        for name, entry in lidar.items()
    ]
    header = [
        "Weather",
        "Model build",
        "Frames",
        "p50",
        "p90",
        "p99",
        "max",
        "Frames with a full GC",
        "max without",
        "CPU / wall",
        "Rays",
        "Returns (median)",
        "Vehicle points",
        "Vehicles with points",
    ]
    lines += [*_table(header, rows), ""]
    lines += [
        "### Camera (`CameraModel.render`, `encode_jpeg`)",
        "",
        "Vehicles passed: those within 600 m of the camera along the road (the rig's cull); "
        "drawn: those with at least one visible pixel. `vehicle_boxes` builds their boxes "
        "(the rig does it before each render). The model's build renders the static background "
        "once.",
        "",
    ]
    rows = [
        [
            name,
            f"{1000 * entry['model_build_s']:.0f} ms",
            f"{entry['render_ms']['n']}",
            f"{entry['vehicles_passed']['median']:.0f} / {entry['vehicles_drawn']['median']:.0f}",
            _ms(entry["vehicle_boxes_ms"]["p50"]),
            *_frame_stats(entry["render_ms"]),
            *_gc(entry["render_gc"]),
            f"{entry['render_cpu_per_wall']:.2f}",
            f"**{_ms(entry['jpeg_ms']['p50'])}**",
            _ms(entry["jpeg_ms"]["p90"]),
            f"{entry['jpeg_bytes_median'] / 1000:.0f} kB",
        ]
        for name, entry in camera.items()
    ]
    header = [
        "Weather",
        "Model build",
        "Frames",
        "Vehicles passed / drawn",
        "`vehicle_boxes` p50",
        "render p50",
        "p90",
        "p99",
        "max",
        "Renders with a full GC",
        "max without",
        "CPU / wall",
        f"JPEG (q{camera['day']['jpeg_quality']}) p50",
        "p90",
        "JPEG size",
    ]
    lines += [*_table(header, rows), ""]
    lines += [
        "### Radar (`RadarModel.scan`)",
        "",
        "Vehicles in view: in the field of view and range; visible: of those, not occluded.",
        "",
    ]
    rows = [
        [
            name,
            f"{entry['scan_ms']['n']}",
            *_frame_stats(entry["scan_ms"]),
            f"{entry['vehicles_in_view']['median']:.0f} / "
            f"{entry['vehicles_visible']['median']:.0f}",
            _spread(entry["targets"]),
        ]
        for name, entry in radar.items()
    ]
    header = [
        "Weather",
        "Scans",
        "p50",
        "p90",
        "p99",
        "max",
        "Vehicles in view / visible",
        "Targets",
    ]
    lines += [*_table(header, rows), ""]
    lines += [
        "### The whole simulator: SUMO and the three sensors at their rates",
        "",
        f"Both runs: {loop['vehicles_per_hour']:.0f} veh/h, seed {loop['seed']}, "
        f"{loop['weather']}, `realtime_factor=0`, a window of {loop['duration_s']:.0f} "
        f"simulated s after {loop['warmup_sim_s']:.0f} s of warm-up "
        f"({_spread(loop['vehicles_on_road'])} vehicles on the road in the window).",
        "",
        f"- **Node process over Zenoh: {node['sim_per_wall']:.2f}x real time** in the window "
        f"({node['window_wall_s']:.1f} s wall for {node['duration_s']:.0f} simulated s). "
        "`python -m wz_simulator.node` with `WZ_SIM_DURATION_S` = "
        f"{node['warmup_sim_s'] + node['duration_s']:.0f}, publishing on a real Zenoh bus "
        "(default config, shared memory on) to a second process that counts and stamps every "
        "sample (it decodes frame metadata and the truth, and shares the 2 cores). The node "
        "has no warm-up, so its sensors fire from t = 0; the window's wall time is read from "
        "the arrivals of the truths stamped at its ends. Whole run: "
        f"{node['run_sim_per_wall']:.2f}x from the first truth to the last, "
        f"{node['process_wall_s']:.1f} s for the process, of which "
        f"{node['startup_s']:.1f} s start-up (bus, SUMO network, static scene, camera "
        "background) before the first truth.",
        f"- **`run_loop` in process: {loop['sim_per_wall']:.2f}x real time** "
        f"({loop['wall_s']:.1f} s wall, CPU / wall {loop['cpu_per_wall']:.2f}): the node's "
        "loop with a `SensorRig` and callbacks that encode as the node does but publish "
        "nothing; warm-up without sensors, then the rig (built in "
        f"{loop['rig_build_s']:.1f} s) on the window's time. Each part timed where it is "
        "called:",
        "",
    ]
    sim_s = loop["duration_s"]
    rows = [
        [
            entry["what"],
            f"{entry['s']:.2f} s",
            f"{1000 * entry['s'] / sim_s:.0f} ms",
            f"{100 * entry['share']:.1f} %",
        ]
        for entry in loop["split"].values()
    ]
    lines += [
        *_table(["Part", "Wall", "Per simulated s", "Share"], rows),
        "",
        "Frames per sensor: every index from 0 exactly once, no duplicates; a run of T "
        "simulated s has T x rate + 1 frames (the frame at t = 0 and the one at the last step "
        "both fire), a window [start, end) T x rate.",
        "",
    ]
    rows = []
    for sensor_id, in_loop in loop["frames"].items():
        in_node = node["frames"][sensor_id]
        rows.append(
            [
                f"`{sensor_id}`",
                f"{in_loop['rate_hz']:.0f} Hz",
                f"{in_loop['frames']} ({in_loop['expected']})",
                f"{in_node['frames']} ({in_node['expected']}), {in_node['missing']} missing, "
                f"{in_node['duplicates']} duplicated",
                f"{in_node['in_window']} ({in_node['in_window_expected']})",
                f"{in_loop['mb_per_sim_s']:.2f} MB",
            ]
        )
    truth = node["truth_messages"]
    rows.append(
        [
            "truth (`GroundTruth`)",
            "20 Hz",
            f"{loop['truth_messages']} ({loop['steps']})",
            f"{truth['frames']} ({truth['expected']}), {truth['missing']} missing, "
            f"{truth['duplicates']} duplicated",
            "",
            "",
        ]
    )
    header = [
        "Sensor",
        "Rate",
        "`run_loop`: frames (expected)",
        "Node over Zenoh, whole run: received (expected)",
        "In the window (expected)",
        "Payload per simulated s",
    ]
    lines += _table(header, rows)
    lines += [
        "",
        "All frame counts exact."
        if result["frame_counts_exact"]
        else "**Some frame counts are not exact (see the table).**",
    ]
    return [*lines, ""]


def _lidar_detection(result: dict[str, Any]) -> list[str]:
    lines = [
        f"{result['frames']} evaluation frames (default site, mast LiDAR 64 x 2048, 2000 veh/h "
        f"with 20 % trucks); the fast path's range-image background was learned from "
        f"{result['learn_frames']} earlier frames with traffic in them "
        f"({1e3 * result['background_learn_s']:.0f} ms). Both paths on the same frames; scoring "
        "as in `wz_lidar_detector.evaluation` (vehicles within 120 m and >= 30 % visible are "
        "scored; a detection counts when its centre falls in the vehicle's footprint grown by "
        "1 m). The reference path's position is the centroid of its points, as in the paper; "
        "the fast path's is the centre of the box completed from the visible faces.",
        "",
    ]
    header = [
        "Range",
        "Scored",
        "Recall fast",
        "Recall ref.",
        "Precision fast",
        "Precision ref.",
        "Centre err. fast p50 / p95",
        "Centre err. ref. p50 / p95",
    ]
    rows = []
    for fast, ref in zip(result["fast"]["bins"], result["reference"]["bins"], strict=True):
        rows.append([
            f"{fast['range_m']} m" if fast is not result["fast"]["bins"][-1] else
            f"**all ({fast['range_m']} m)**",
            str(fast["scored"]), f"{fast['recall']:.2f}", f"{ref['recall']:.2f}",
            f"{fast['precision']:.2f}", f"{ref['precision']:.2f}",
            f"{fast['centre_error_median_m']:.2f} / {fast['centre_error_p95_m']:.2f} m",
            f"{ref['centre_error_median_m']:.2f} / {ref['centre_error_p95_m']:.2f} m",
        ])  # fmt: skip
    lines += _table(header, rows)
    lines += ["", "Time per frame (both cores available):", ""]
    timing_rows = [
        [name, _ms(result[name]["median_ms"]), _ms(result[name]["p90_ms"]),
         ", ".join(f"{k} {_ms(v)}" for k, v in result[name]["steps_median_ms"].items())]
        for name in ("reference", "fast")
    ]  # fmt: skip
    lines += _table(["Path", "p50", "p90", "Median per step"], timing_rows)
    one = result["one_core"]
    lines += [
        "",
        f"Speed-up of the fast path: **{result['speedup']:.1f}x** (median). On one core "
        f"(`taskset -c 0`, one thread), with {one['points_per_frame']:,}-slot frames, the "
        f"service sustains **{one['frames_per_s']['fast']:.0f} frames/s** on the fast path "
        f"(background updating, as in the node) and {one['frames_per_s']['reference']:.1f} "
        "frames/s on the reference path.",
    ]
    return [*lines, ""]


def _camera_detection(result: dict[str, Any]) -> list[str]:
    inference, per_frame, service = result["inference"], result["per_frame"], result["service"]
    height, width = inference["input_size_px"]
    lines = [
        f"Shipped model `{inference['model']}` (input {width} x {height}, region of interest "
        f"{inference['roi_xyxy_px']} of the 1200 x 1200 frame), ONNX Runtime CPU with 2 threads, "
        f"on {inference['frames']} simulated day frames (default site, 1800 veh/h, 20 % trucks).",
        "",
    ]
    rows = [[name, _ms(v["p50_ms"]), _ms(v["p90_ms"]), _ms(v["max_ms"])]
            for name, v in inference["steps"].items()]  # fmt: skip
    lines += _table(["YOLO step", "p50", "p90", "max"], rows)
    lines += [
        "",
        f"The node's whole per-frame work (`CameraDetector.handle`: JPEG decode, YOLO, image "
        f"tracking, ranging, radar fusion, message), in process: p50 {_ms(per_frame['p50_ms'])}, "
        f"p99 {_ms(per_frame['p99_ms'])}, max {_ms(per_frame['max_ms'])} "
        f"({per_frame['detections_per_frame']:.1f} detections per frame).",
        "",
        f"The node as its own process on Zenoh, fed camera frames at 10 Hz and radar scans at "
        f"15 Hz in real time for {service['span_s']:.0f} s: {service['frames_sent']} frames and "
        f"{service['radar_scans_sent']} scans sent, **{service['batches_received']} detection "
        f"batches back ({service['frames_missing']} frames missing), "
        f"{service['output_rate_hz']:.1f} batches/s**; "
        f"{100 * service['fused_share']:.0f} % of detections carry a radar speed.",
        "",
    ]
    rows = [[name, _ms(service[key]["p50_ms"]), _ms(service[key]["p99_ms"]),
             _ms(service[key]["max_ms"])]
            for name, key in (("node (frame taken -> batch published)", "node_latency"),
                              ("end to end (frame published -> batch received)",
                               "end_to_end_latency"))]  # fmt: skip
    lines += _table(["Latency", "p50", "p99", "max"], rows)
    return [*lines, ""]


def _tracker_cycle(result: dict[str, Any]) -> list[str]:
    sensors = ", ".join(f"{name} {v['rate_hz']:g} Hz" for name, v in result["sensors"].items())
    lines = [
        f"{result['vehicles']} vehicles in 8 lanes, three asynchronous sensors ({sensors}), "
        f"{result['duration_s']:g} s of data; after a 5 s warm-up the tracker holds "
        f"{result['confirmed_tracks_median']:.0f} confirmed tracks. One cycle is one sensor "
        "batch through `MultiTargetTracker.add` (predict, gate, assign, update, start, merge), "
        "the batches in stamp order and no reorder window, so each `add` processes its own "
        "batch; the snapshot is the 10 Hz `tracks(t)` the node publishes. \"Windowed\": the "
        "node's 150 ms reorder window, where an `add` processes the batches it releases "
        "(none, one or two), so per call the times mix batches (the mean is the same work).",
        "",
    ]

    def row(label: str, v: dict[str, Any]) -> list[str]:
        mean = _ms(v["mean_ms"]) if "mean_ms" in v else "-"
        return [label, _ms(v["median_ms"]), mean, _ms(v["p99_ms"]), _ms(v["max_ms"]),
                str(v["samples"])]  # fmt: skip

    rows = [row("all batches", result["cycle"])]
    rows += [row(f"{name} batches", v) for name, v in result["per_sensor"].items()]
    rows.append(row("snapshot (200 tracks)", result["snapshot"]))
    windowed = result.get("windowed")
    if windowed:
        rows.append(row("all `add` calls, windowed (as the node runs)", windowed["cycle"]))
    imm = result.get("imm")
    if imm:  # the IMM motion model (an option), same batches
        for label, key in (("all batches, IMM option", "cycle"), ("snapshot, IMM option", "snapshot")):
            rows.append(row(label, imm[key]))
    correction = result.get("bias_map_correction")
    if correction:  # in the node, before the tracker, with a lateral bias map
        for size in (10, 200):
            rows.append(row(f"lateral bias map on a batch of {size} (node, before `add`)",
                            correction[f"batch_of_{size}"]))  # fmt: skip
    lines += _table(["Step", "median", "mean", "p99", "max", "samples"], rows)
    return [*lines, ""]


def _alert_latency(result: dict[str, Any]) -> list[str]:
    lines = [
        "The alert service node as its own process (default site and thresholds), a Zenoh peer "
        "of this one on `tcp/127.0.0.1`. Each sample is a new speeding car: ten 10 Hz track "
        "batches hold the condition, then, once the node has taken them, the batch that "
        "completes the 1 s hold is published; the time runs from that `put_bytes` (payload "
        "encoded beforehand) to the speeding alert's arrival here (receive, decode, every rule "
        f"on every track, encode, publish). {result['samples']} samples per batch size.",
        "",
    ]
    rows = [[f"{v['tracks_per_batch']} track(s), {v['batch_bytes']:,} B",
             _ms(v["latency_ms"]["p50"]), _ms(v["latency_ms"]["p90"]),
             _ms(v["latency_ms"]["p99"]), _ms(v["latency_ms"]["max"])]
            for v in result["variants"].values()]  # fmt: skip
    lines += _table(["Batch", "p50", "p90", "p99", "max"], rows)
    return [*lines, ""]


def _webhook_latency(result: dict[str, Any]) -> list[str]:
    lines = [
        "The gateway node as its own process (SQLite, default site), a Zenoh peer of this one "
        "on `tcp/127.0.0.1`; the receiver an `http.server` (HTTP/1.1, keep-alive) in this "
        "process on loopback, subscribed through the API. Each sample is one new alert "
        "(encoded beforehand): from its `put_bytes` to the receiver having read the POST "
        "with that alert's `webhook-id` (bus, writer queue, the transaction storing the alert "
        "and its outbox rows, the delivery's claim, signing, HTTP); with four subscriptions, "
        f"to the last of the four. One alert at a time, after {result['warmup']} unmeasured; "
        f"every signature checked. {result['samples']} samples per variant, "
        f"{result['delivered']} events delivered in all.",
        "",
    ]
    rows = [[f"{v['subscriptions']} subscription(s)", _ms(v["latency_ms"]["p50"]),
             _ms(v["latency_ms"]["p90"]), _ms(v["latency_ms"]["p99"]),
             _ms(v["latency_ms"]["max"])]
            for v in result["variants"].values()]  # fmt: skip
    lines += _table(["Subscribers", "p50", "p90", "p99", "max"], rows)
    return [*lines, ""]


def _gateway_live(result: dict[str, Any]) -> list[str]:
    first = next(iter(result["variants"].values()))
    lines = [
        "The gateway node as its own process (SQLite in WAL mode, default site, rate limits "
        "off), a Zenoh peer of this one on `tcp/127.0.0.1`. This process publishes a "
        f"`TrackBatch` of {first['tracks_per_batch']} tracks ({first['batch_bytes']:,} B) at "
        f"{first['rate_hz']:.0f} Hz; each track lives {first['track_life_s']:.0f} s, so "
        f"{first['tracks_per_batch'] / first['track_life_s']:.0f} tracks end a second and "
        "(with smoothing) are RTS-smoothed and stored by the writer thread between groups. "
        "After a warm-up, ingestion alone, then with "
        f"{first['live_clients']} threads asking `GET /v1/tracks/live` back to back and one "
        f"paging `GET /v1/trajectories` ({first['page_points']:,} points a page), each with "
        "its keep-alive `httpx` connection. Ingest lag: from just before a batch's "
        "`put_bytes` to its commit, seen by a watcher process polling the database file "
        "every 0.5 ms. Latency: request sent to body read, in this process (its client "
        "threads share one interpreter, and both processes the machine's cores). Without "
        "smoothing: the same with the track end timeout at an hour (nothing ends).",
        "",
    ]
    rows = []
    for name, run in result["variants"].items():
        alone, loaded = run["ingest_only"]["ingest_lag_ms"], run["loaded"]["ingest_lag_ms"]
        live, pages = run["loaded"]["live"], run["loaded"]["trajectories"]
        rows.append([
            name.replace("_", " "), f"{_ms(alone['p50'])} / {_ms(alone['p99'])}",
            f"{_ms(loaded['p50'])} / {_ms(loaded['p99'])}",
            f"**{live['requests_per_s']:,.0f}**",
            f"{_ms(live['latency_ms']['p50'])} / {_ms(live['latency_ms']['p99'])}",
            f"{_ms(pages['latency_ms']['p50'])} / {_ms(pages['latency_ms']['p99'])}",
            f"{run['smoothing']['tracks']:.0f} ({_ms(run['smoothing']['mean_ms'])})",
            _ms(run["write_group_mean_ms"]),
        ])  # fmt: skip
    lines += _table(["Variant", "ingest lag alone p50 / p99", "ingest lag loaded p50 / p99",
                     "live requests/s", "live p50 / p99", "trajectories page p50 / p99",
                     "tracks smoothed (mean time each)", "write per group (mean)"], rows)  # fmt: skip
    return [*lines, ""]


def _recovery(result: dict[str, Any]) -> list[str]:
    lines = [
        "The real stack as `wz up` runs it (router, simulator with SUMO and its sensors, both "
        "detectors, fusion tracker, alert service, gateway on SQLite; seed "
        f"{result['seed']}, status messages every {result['status_period_s']} s). While the "
        "pipeline is steady (every service running, the gateway's newest track batch fresh "
        "and fed by both sensors, the service's warm standby ready), each service in turn gets "
        "SIGKILL. Times from the kill, on one wall clock: **restart**, the supervisor's "
        "`started <name>` line; **status**, the new process's first status message that is "
        "`running` with data going through it; **pipeline**, the gateway's API (polled every "
        f"{result['poll_period_s']} s) serving a batch received after the restart with a track "
        "fresh from a sensor (from the killed detector's sensor after a detector's kill; after "
        "the alert service's, also its first devices message); **recovered**, the latest of "
        f"these. Median of {result['rounds']} rounds (each round's in brackets), then one "
        "round with each standby killed first, so that the service restarts as a new "
        f"interpreter. The stack was steady {result['ready_s']} s after `wz up`. Method: "
        "`benchmarks/recovery.py`.",
        "",
    ]
    plain = {r["service"]: r for r in result["without_standby"]}

    def cell(times: dict[str, Any]) -> str:
        median = times["median"]
        if median is None:
            return "—"
        each = ", ".join("—" if v is None else f"{v:.2f}" for v in times["values"])
        return f"{median:.2f} s ({each})"

    rows = []
    for service, times in result["services"].items():
        bare = plain.get(service, {})
        rows.append([
            f"`{service}`", cell(times["restart_s"]), cell(times["status_s"]),
            cell(times["pipeline_s"]), f"**{cell(times['recovered_s'])}**",
            "—" if bare.get("recovered_s") is None else f"{bare['recovered_s']:.2f} s",
        ])  # fmt: skip
    lines += _table(["Killed", "restart", "status", "pipeline", "recovered",
                     "recovered, no standby"], rows)  # fmt: skip
    lines.append("")
    devices = result["services"].get("alert-service", {}).get("devices_s")
    if devices and devices["median"] is not None:
        lines.append(f"- Alert service: its first devices message after the restart "
                     f"{cell(devices)} after the kill.")  # fmt: skip
    for index, check in enumerate(result["gateway_stored"]):
        before, after = check["before"], check["after"]
        label = f"round {index + 1}" if index < result["rounds"] else "round without standbys"
        lines.append(
            f"- Gateway, {label}: before its kill {before['track_points']:,} track points, "
            f"{before['track_ids']} track ids, {before['alert_ids']} alert events; after its "
            f"restart {after['track_points']:,}, {after['track_ids']}, {after['alert_ids']}: "
            + ("nothing lost." if not check["lost"] else f"**lost {check['lost']}**.")
        )
    lines.append("")
    return lines


SECTIONS: dict[str, tuple[str, Callable[[dict[str, Any]], list[str]]]] = {
    "bus_latency": ("one-way latency between two processes", _bus_latency),
    "bus_throughput": ("messages per second between two processes", _bus_throughput),
    "sumo_step": ("the simulator's SUMO step", _sumo_step),
    "sensors": ("the simulator's sensor models and the whole simulator", _sensors),
    "lidar_detection": ("the LiDAR detector's two paths: accuracy and speed", _lidar_detection),
    "camera_detection": ("the camera-radar detector: YOLO, per frame, the node at 10 fps",
                         _camera_detection),
    "tracker_cycle": ("the fusion tracker's cycle with 200 tracks and three sensors",
                      _tracker_cycle),
    "alert_latency": ("the alert service: track batch to alert on the bus", _alert_latency),
    "webhook_latency": ("gateway webhooks: alert on the bus to the signed POST at the receiver",
                        _webhook_latency),
    "gateway_live": ("the gateway storing 20 Hz track batches while clients read the live API",
                     _gateway_live),
    "recovery": ("`kill -9` of each service of `wz up`: restart and pipeline recovery",
                 _recovery),
}


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
        if "error" in entry:
            lines += ["**Failed:**", "", "```", entry["error"].rstrip(), "```", ""]
        else:
            lines += section(entry["result"])
    return "\n".join(lines).rstrip() + "\n"
