"""Report sections of the simulation and perception benchmarks: the SUMO step, the sensor
models, the LiDAR and camera detectors, the tracker cycle."""

from __future__ import annotations

from typing import Any

from benchmarks.report_format import (
    fmt_ms,
    fmt_spread,
    fmt_us,
    frame_stats,
    gc_columns,
    md_table,
)


def sumo_step(result: dict[str, Any]) -> list[str]:
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
        (
            "of which, re-measured: `site.road_frame.to_road` of the vehicles",
            stepping["to_road_ms"],
        ),
        (
            "of which, re-measured: validating the `VehicleTruth`s",
            stepping["vehicle_truth_validate_ms"],
        ),
        (
            "for comparison: `VehicleTruth.model_construct` (no validation)",
            stepping["vehicle_truth_construct_ms"],
        ),
        (
            f"node's extra: `GroundTruth` build + encode "
            f"({stepping['ground_truth_bytes_median'] / 1000:.1f} kB)",
            stepping["ground_truth_build_encode_ms"],
        ),
    ]
    rows = [
        [what, f"**{fmt_ms(s['p50'])}**", fmt_ms(s["p99"]), fmt_ms(s["max"])] for what, s in parts
    ]
    lines += [*md_table(["Per step", "p50", "p99", "max"], rows), ""]
    lines += md_table(
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
            ["step time per vehicle (mean)", fmt_us(stepping["per_vehicle_step_us"])],
            ["libsumo start-up, network built in a fresh folder", f"{stepping['startup_s']:.2f} s"],
            [
                "collisions / teleports during the timed steps",
                f"{stepping['collisions']} / {stepping['teleports']}",
            ],
        ],
    )
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
    lines += md_table(header, rows)
    return [*lines, ""]


def sensors(result: dict[str, Any]) -> list[str]:
    frames, loop, node = result["frames"], result["loop"], result["node"]
    traffic, targets, ratios = frames["traffic"], result["targets"], result["ratios"]
    lidar, camera, radar = frames["lidar"], frames["camera"], frames["radar"]
    lines = [
        f"Default site. Traffic for the per-frame times: `TrafficWorld` at "
        f"{traffic['vehicles_per_hour']:.0f} veh/h (seed {traffic['seed']}), warmed up "
        f"{traffic['warmup_sim_s']:.0f} simulated s (until {traffic['target_in_lidar_range']} "
        f"vehicles were within the LiDAR's range), then the truths of {traffic['steps']} steps "
        f"({traffic['steps'] * traffic['step_s']:.0f} s) kept: "
        f"{fmt_spread(traffic['vehicles_on_road'])} "
        f"vehicles on the 2 km road, {fmt_spread(traffic['vehicles_in_lidar_range'])} within the "
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
            f"**{fmt_ms(lidar['day']['frame_ms']['p50'])}**",
            f"<= {fmt_ms(targets['lidar_frame_ms'])}",
            f"{ratios['lidar_frame_ms']:.2f}",
        ],
        [
            f"camera render {camera['day']['width_px']}x{camera['day']['height_px']} (day)",
            f"**{fmt_ms(camera['day']['render_ms']['p50'])}**",
            f"<= {fmt_ms(targets['camera_render_ms'])}",
            f"{ratios['camera_render_ms']:.2f}",
        ],
        [
            "radar scan (day)",
            f"**{fmt_ms(radar['day']['scan_ms']['p50'])}**",
            f"<= {fmt_ms(targets['radar_scan_ms'])}",
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
    lines += md_table(["Median", "Measured", "Target", "Measured / target"], rows)
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
            *frame_stats(entry["frame_ms"]),
            *gc_columns(entry["frame_gc"]),
            f"{entry['cpu_per_wall']:.2f}",
            f"{entry['rays']:,}",
            f"{entry['returns']['median']:,.0f}",
            fmt_spread(entry["vehicle_points"]),
            fmt_spread(entry["vehicles_hit"]),
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
    lines += [*md_table(header, rows), ""]
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
            fmt_ms(entry["vehicle_boxes_ms"]["p50"]),
            *frame_stats(entry["render_ms"]),
            *gc_columns(entry["render_gc"]),
            f"{entry['render_cpu_per_wall']:.2f}",
            f"**{fmt_ms(entry['jpeg_ms']['p50'])}**",
            fmt_ms(entry["jpeg_ms"]["p90"]),
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
    lines += [*md_table(header, rows), ""]
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
            *frame_stats(entry["scan_ms"]),
            f"{entry['vehicles_in_view']['median']:.0f} / "
            f"{entry['vehicles_visible']['median']:.0f}",
            fmt_spread(entry["targets"]),
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
    lines += [*md_table(header, rows), ""]
    lines += [
        "### The whole simulator: SUMO and the three sensors at their rates",
        "",
        f"Both runs: {loop['vehicles_per_hour']:.0f} veh/h, seed {loop['seed']}, "
        f"{loop['weather']}, `realtime_factor=0`, a window of {loop['duration_s']:.0f} "
        f"simulated s after {loop['warmup_sim_s']:.0f} s of warm-up "
        f"({fmt_spread(loop['vehicles_on_road'])} vehicles on the road in the window).",
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
        *md_table(["Part", "Wall", "Per simulated s", "Share"], rows),
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
    lines += md_table(header, rows)
    lines += [
        "",
        "All frame counts exact."
        if result["frame_counts_exact"]
        else "**Some frame counts are not exact (see the table).**",
    ]
    return [*lines, ""]


def lidar_detection(result: dict[str, Any]) -> list[str]:
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
        rows.append(
            [
                f"{fast['range_m']} m"
                if fast is not result["fast"]["bins"][-1]
                else f"**all ({fast['range_m']} m)**",
                str(fast["scored"]),
                f"{fast['recall']:.2f}",
                f"{ref['recall']:.2f}",
                f"{fast['precision']:.2f}",
                f"{ref['precision']:.2f}",
                f"{fast['centre_error_median_m']:.2f} / {fast['centre_error_p95_m']:.2f} m",
                f"{ref['centre_error_median_m']:.2f} / {ref['centre_error_p95_m']:.2f} m",
            ]
        )
    lines += md_table(header, rows)
    lines += ["", "Time per frame (both cores available):", ""]
    timing_rows = [
        [
            name,
            fmt_ms(result[name]["median_ms"]),
            fmt_ms(result[name]["p90_ms"]),
            ", ".join(f"{k} {fmt_ms(v)}" for k, v in result[name]["steps_median_ms"].items()),
        ]
        for name in ("reference", "fast")
    ]
    lines += md_table(["Path", "p50", "p90", "Median per step"], timing_rows)
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


def camera_detection(result: dict[str, Any]) -> list[str]:
    inference, per_frame, service = result["inference"], result["per_frame"], result["service"]
    height, width = inference["input_size_px"]
    lines = [
        f"Shipped model `{inference['model']}` (input {width} x {height}, region of interest "
        f"{inference['roi_xyxy_px']} of the 1200 x 1200 frame), ONNX Runtime CPU with 2 threads, "
        f"on {inference['frames']} simulated day frames (default site, 1800 veh/h, 20 % trucks).",
        "",
    ]
    rows = [
        [name, fmt_ms(v["p50_ms"]), fmt_ms(v["p90_ms"]), fmt_ms(v["max_ms"])]
        for name, v in inference["steps"].items()
    ]
    lines += md_table(["YOLO step", "p50", "p90", "max"], rows)
    lines += [
        "",
        f"The node's whole per-frame work (`CameraDetector.handle`: JPEG decode, YOLO, image "
        f"tracking, ranging, radar fusion, message), in process: p50 {fmt_ms(per_frame['p50_ms'])}, "
        f"p99 {fmt_ms(per_frame['p99_ms'])}, max {fmt_ms(per_frame['max_ms'])} "
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
    rows = [
        [
            name,
            fmt_ms(service[key]["p50_ms"]),
            fmt_ms(service[key]["p99_ms"]),
            fmt_ms(service[key]["max_ms"]),
        ]
        for name, key in (
            ("node (frame taken -> batch published)", "node_latency"),
            ("end to end (frame published -> batch received)", "end_to_end_latency"),
        )
    ]
    lines += md_table(["Latency", "p50", "p99", "max"], rows)
    return [*lines, ""]


def tracker_cycle(result: dict[str, Any]) -> list[str]:
    sensors = ", ".join(f"{name} {v['rate_hz']:g} Hz" for name, v in result["sensors"].items())
    lines = [
        f"{result['vehicles']} vehicles in 8 lanes, three asynchronous sensors ({sensors}), "
        f"{result['duration_s']:g} s of data; after a 5 s warm-up the tracker holds "
        f"{result['confirmed_tracks_median']:.0f} confirmed tracks. One cycle is one sensor "
        "batch through `MultiTargetTracker.add` (predict, gate, assign, update, start, merge), "
        "the batches in stamp order and no reorder window, so each `add` processes its own "
        'batch; the snapshot is the 10 Hz `tracks(t)` the node publishes. "Windowed": the '
        "node's 150 ms reorder window, where an `add` processes the batches it releases "
        "(none, one or two), so per call the times mix batches (the mean is the same work).",
        "",
    ]

    def row(label: str, v: dict[str, Any]) -> list[str]:
        mean = fmt_ms(v["mean_ms"]) if "mean_ms" in v else "-"
        return [
            label,
            fmt_ms(v["median_ms"]),
            mean,
            fmt_ms(v["p99_ms"]),
            fmt_ms(v["max_ms"]),
            str(v["samples"]),
        ]

    rows = [row("all batches", result["cycle"])]
    rows += [row(f"{name} batches", v) for name, v in result["per_sensor"].items()]
    rows.append(row("snapshot (200 tracks)", result["snapshot"]))
    windowed = result.get("windowed")
    if windowed:
        rows.append(row("all `add` calls, windowed (as the node runs)", windowed["cycle"]))
    imm = result.get("imm")
    if imm:  # the IMM motion model (an option), same batches
        for label, key in (
            ("all batches, IMM option", "cycle"),
            ("snapshot, IMM option", "snapshot"),
        ):
            rows.append(row(label, imm[key]))
    queue = result.get("queue_300")
    if queue:  # issue 40: a three-lane queue
        label = (
            f"all batches, a {queue['lanes']}-lane queue of {queue['vehicles']} "
            f"({queue['confirmed_tracks_median']:.0f} confirmed tracks, "
            f"{queue['spacing_m']:g} m apart, creeping at 2 m/s)"
        )
        rows.append(row(label, queue["cycle"]))
        rows.append(row("snapshot, the queue", queue["snapshot"]))
    correction = result.get("bias_map_correction")
    if correction:  # in the node, before the tracker, with a lateral bias map
        for size in (10, 200):
            rows.append(
                row(
                    f"lateral bias map on a batch of {size} (node, before `add`)",
                    correction[f"batch_of_{size}"],
                )
            )
    lines += md_table(["Step", "median", "mean", "p99", "max", "samples"], rows)
    return [*lines, ""]


def generated_sites(result: dict[str, Any]) -> list[str]:
    def cell(value: float | None) -> str:
        return "-" if value is None else f"{value:.3g}"

    taken = result.get("taken_from")
    traffic = result.get("traffic")
    lines = [
        f"`wz eval --sites {result['count']} --seed {result['seed']} --duration-s "
        f"{result['duration_s']:g} --warmup-s {result['warmup_s']:g}"
        f"{'' if traffic is None else ' --traffic ' + traffic}`: "
        f"**{result['sites_meeting_every_target']} of {result['count']} sites meet every target** "
        f"({'issue 25' if traffic is None else 'issue 40'}; the live fused track within 150 m of "
        "the mast where a sensor can see a car; alerts against the same rules on the truth)."
        + (
            f" Figures taken from the run written at {taken['written_at']} "
            f"(`{taken['path']}`), the same command, not re-run."
            if taken
            else ""
        ),
        "",
    ]
    rows = [
        [
            row["target"],
            row["bound"],
            str(row["sites_meeting"]),
            str(row["sites_failing"]),
            str(row["sites_without_value"]),
            cell(row["median"]),
            cell(row["worst"]),
        ]
        for row in result["distribution"]
    ]
    lines += md_table(
        ["target", "bound", "sites meeting", "failing", "no value", "median", "worst"], rows
    )
    names = [row["target"] for row in result["distribution"]]
    site_rows = []
    for site in result["sites"]:
        figures = site["figures"]
        cells = [
            f"**{cell(figures[n]['value'])}**"
            if figures[n]["holds"] is False
            else cell(figures[n]["value"])
            for n in names
        ]
        site_rows.append(
            [
                site["site_id"],
                f"{site['weather']}, {site['vehicles_per_hour']:.0f} veh/h, "
                f"{100 * site['truck_share']:.0f} % trucks",
                *cells,
                cell(site.get("covered_downstream")),
                cell(site.get("circle_mota")),
            ]
        )
    lines += [""]
    lines += md_table(
        ["site", "conditions", *names, "covered downstream", "whole-circle MOTA"], site_rows
    )
    lines += ["", *[f"- {site['site_id']}: {site['name']}" for site in result["sites"]], ""]
    return lines


def camera_models(result: dict[str, Any]) -> list[str]:
    per_frame = result["per_frame_one_core"]
    labels = list(per_frame)
    lines = [
        f"Per frame on one core (the process pinned to one CPU, ONNX Runtime with 1 thread), "
        f"the detector's `detect` on the same {result['frames']} rendered frames of the default "
        "site: with the regions its road gives (what the node runs), and as the whole frame of a "
        "camera the detector knows nothing of, resized. Method: `benchmarks/camera_models.py`.",
        "",
    ]
    cases = list(per_frame[labels[0]]["cases"])
    header = ["case"] + [f"{label} `{per_frame[label]['model']}` p50 / p99" for label in labels]
    rows = [
        [case]
        + [
            f"{fmt_ms(per_frame[label]['cases'][case]['p50_ms'])} / "
            f"{fmt_ms(per_frame[label]['cases'][case]['p99_ms'])}"
            for label in labels
        ]
        for case in cases
    ]
    lines += md_table(header, rows)
    stack = result["stack_cpu_percent"]
    services = sorted({name for usage in stack.values() for name in usage} - {"all"})
    lines += [
        "",
        f"The whole stack (`wz up`, real time, LiDAR 10 Hz, camera 10 Hz, radar 15 Hz), each "
        f"process's CPU in % of one core over {result['stack_window_s']:.0f} s, with each model "
        "in the camera detector:",
        "",
    ]
    rows = [[name] + [f"{stack[label].get(name, 0.0):.1f}" for label in stack] for name in services]
    rows.append(["**all**"] + [f"**{stack[label]['all']:.1f}**" for label in stack])
    lines += md_table(["process", *stack], rows)
    lines.append("")
    return lines


def camera_budget(result: dict[str, Any]) -> list[str]:
    """Issue 41: the camera node at 30 fps, before and now, and the stack's CPU."""
    fps = result["camera_fps"]
    lines = [
        f"Camera at {fps:.0f} fps, 1800 veh/h with 20 % trucks, day; **before** is commit "
        f"`{result['baseline_commit']}` (the detector on every frame, ONNX Runtime on two "
        "threads), checked out in a worktree and run in the same run on the same frames; "
        "**now** is this code (the detector every 0.13 s, its far-field tile at every second "
        "run when it skips frames, optical flow between, one ONNX thread; the LiDAR node's "
        "point checks by column). Before's per-frame figure is its two spinning ONNX threads "
        "on one core. Method: `benchmarks/camera_budget.py`.",
        "",
        "Per frame, one process pinned to one core (`CameraDetector.handle`: decode, detect or "
        "follow, track, range, fuse), CPU time; and the node as its own process pinned to one "
        "core, fed the frames in real time over Zenoh:",
        "",
    ]
    rows = []
    for name, case in result["cases"].items():
        for code in ("before", "now"):
            frame, node = case["per_frame"][code], case["node"][code]
            latency = node["end_to_end"]
            rows.append(
                [
                    f"{name} ({case['camera']}, {case['frames']} frames)",
                    f"**{code}**",
                    f"{fmt_ms(frame['cpu']['p50_ms'])} / {fmt_ms(frame['cpu']['p99_ms'])} / "
                    f"{fmt_ms(frame['cpu']['mean_ms'])}",
                    f"{100 * frame['share_of_one_core']:.0f}",
                    f"{node['batches_received']} of {node['frames_sent']} "
                    f"({node['frames_missing']} missing)",
                    "-"
                    if latency is None
                    else f"{fmt_ms(latency['p50_ms'])} / {fmt_ms(latency['p99_ms'])}",
                    f"{100 * node['node_share_of_one_core']:.0f}",
                ]
            )
    lines += md_table(
        [
            "camera",
            "code",
            "CPU per frame p50 / p99 / mean",
            "% of one core (in process)",
            "node on the bus: batches back",
            "end to end p50 / p99",
            "node's % of one core",
        ],
        rows,
    )
    stack = result["stack_cpu_percent"]
    services = sorted(
        {name for usage in stack.values() for name in usage} - {"all", "all but the simulator"}
    )
    lines += [
        "",
        f"The whole stack (`wz up`, real time, the default site with its camera at {fps:.0f} "
        f"fps, LiDAR 20 Hz, radar 15 Hz), each process's CPU in % of one core over "
        f"{result['stack_window_s']:.0f} s:",
        "",
    ]
    rows = [[name] + [f"{stack[code].get(name, 0.0):.1f}" for code in stack] for name in services]
    rows.append(
        ["**all but the simulator**"]
        + [f"**{stack[code]['all but the simulator']:.1f}**" for code in stack]
    )
    rows.append(["all"] + [f"{stack[code]['all']:.1f}" for code in stack])
    lines += md_table(["process", *stack], rows)
    lines.append("")
    return lines


def self_calibration(result: dict[str, Any]) -> list[str]:
    """Issue 39: each estimator's CPU at its sensor's full rate, and its time to learn."""

    def cell(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    lines = [
        f"Traffic of {result['vehicles_per_hour']:g} veh/h on the default site for "
        f"{result['duration_s']:g} s of sensor time, the sensors turned off their site-file "
        "poses and the camera and radar late (`benchmarks/self_calibration.py`); only the "
        "estimators run (what the detectors feed them), timed by process CPU.",
        "",
        "| sensor | rate [Hz] | CPU [% of one core] | learned after [s] | error at the end |",
        "|---|---|---|---|---|",
    ]
    for name, entry in result["cost"].items():
        errors = ", ".join(f"{k} {v:+.3f}" for k, v in entry["error"].items())
        lines.append(
            f"| {name} | {entry['rate_hz']:g} | "
            f"{100 * entry['cpu_share_of_one_core']:.2f} | "
            f"{cell(entry['learned_after_s'], '.1f')} | {errors} |"
        )
    lines += [
        "",
        f"LiDAR, camera at 10 Hz and radar together: "
        f"**{100 * result['total_cpu_share_of_one_core']:.2f} % of one core** (budget: 5 %).",
        "",
        "| veh/h | LiDAR learned after [s] | camera [s] | radar [s] |",
        "|---|---|---|---|",
    ]
    for row in result["convergence"]:
        lines.append(
            f"| {row['vehicles_per_hour']:g} | {cell(row['lidar_s'], '.1f')} | "
            f"{cell(row['camera_s'], '.1f')} | {cell(row['radar_s'], '.1f')} |"
        )
    return lines


def traffic_sites(result: dict[str, Any]) -> list[str]:
    """Issue 40's 24 sites: each traffic set as :func:`generated_sites` shows it."""
    wall = result.get("wall_s") or {}
    lines = [
        "Wall time on this machine: "
        + (
            ", ".join(f"{name} {seconds / 60.0:.0f} min" for name, seconds in wall.items())
            if wall
            else "not recorded"
        )
        + " (bound: both sets within 2 hours).",
        "",
    ]
    for traffic, entry in result["sets"].items():
        lines += [f"**{traffic}**", "", *generated_sites(entry)]
    return lines


def _cell(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def queue_beyond_reach(result: dict[str, Any]) -> list[str]:
    """Per congested site: how well the point sensors bound a back beyond the reach."""
    lines = [
        f"SUMO alone, {result['duration_s']:.0f} s after {result['warmup_s']:.0f} s of warm-up, "
        f"site seeds from {result['first_seed']}; the mast's tracks are the truth its sensors "
        "see (perfect tracking). The true back stood within the bounds (15 m either side) a "
        f"median {_cell(result['within_share_median'], '.0%')} of the bounded seconds on the "
        f"{result['sites_with_back_beyond']} sites whose back went beyond the reach.",
        "",
        "| site | weather | demand / capacity | sensors, interval | beyond the reach [s] | "
        "bounded | true back within | bounds' width, median [m] | true back past the reach, "
        "median [m] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        lines.append(
            f"| {row['site']} | {row['weather']} | {_cell(row['demand_ratio'], '.2f')} | "
            f"{row['point_sensors']}, {_cell(row['interval_s'], '.0f')} s | {row['beyond_s']} | "
            f"{_cell(row['bounded_share'], '.0%')} | {_cell(row['within_share'], '.0%')} | "
            f"{_cell(row['bound_width_median_m'], '.0f')} | "
            f"{_cell(row['reach_to_back_median_m'], '.0f')} |"
        )
    return [*lines, ""]
