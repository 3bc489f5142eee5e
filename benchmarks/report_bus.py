"""Report sections of the bus and service benchmarks: latency, throughput, alerts, webhooks,
the gateway's live API, recovery after a kill."""

from __future__ import annotations

from typing import Any

from benchmarks.report_format import (
    FRAME_PATHS,
    SMALL_PATHS,
    THROUGHPUT_PATHS,
    base_path,
    fmt_latency,
    fmt_ms,
    fmt_rate,
    fmt_round_range,
    fmt_us,
    md_table,
)


def bus_latency(result: dict[str, Any]) -> list[str]:
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
                f"**{fmt_us(stats['p50'])}**",
                fmt_round_range(entry["round_p50_us"]),
                fmt_us(stats["p90"]),
                fmt_us(stats["p99"]),
                fmt_us(stats["max"]),
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
    lines += [*md_table(header, rows), ""]
    lines += ["### LiDAR frames (131072 points x 4 float32, 2 MB)", ""]
    rows = []
    for name, entry in result["frames"].items():
        stats = entry["one_way_us"]
        rows.append(
            [
                f"`{base_path(name)}`",
                "on" if entry["shm"] else "off",
                FRAME_PATHS.get(base_path(name), ""),
                f"{entry['payload_bytes']:,}",
                f"{stats['n']} ({entry['rounds']})",
                f"**{fmt_latency(stats['p50'])}**",
                fmt_round_range(entry["round_p50_us"]),
                fmt_latency(stats["p90"]),
                fmt_latency(stats["p99"]),
                fmt_latency(stats["max"]),
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
    lines += [*md_table(header, rows), ""]
    lines += ["### Ratios", ""]
    lines += md_table(
        ["Ratio", "Value"], [[name, f"{value:.2f}"] for name, value in result["ratios"].items()]
    )
    return [*lines, ""]


def bus_throughput(result: dict[str, Any]) -> list[str]:
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
                    f"`{base_path(name)}`",
                    "on" if entry["shm"] else "off",
                    THROUGHPUT_PATHS.get(base_path(name), ""),
                    f"{entry['payload_bytes']:,}",
                    f"{entry['rounds']} x {entry['sent_per_round']:,}",
                    f"{entry['lost']} / {entry['extra']} / {entry['out_of_order']}",
                    f"**{fmt_rate(entry['messages_per_s'])}**",
                    ", ".join(fmt_rate(rate) for rate in entry["messages_per_s_rounds"]),
                    f"{entry['megabytes_per_s']:,.1f}",
                    fmt_rate(entry["publisher_messages_per_s"]),
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
    lines += [*md_table(header, rows), ""]
    lines.append(
        "All delivered exactly, in order."
        if result["all_delivered"]
        else "**Some samples were lost, duplicated or out of order (see the table).**"
    )
    lines += ["", "### Ratios", ""]
    lines += md_table(
        ["Ratio", "Value"], [[name, f"{value:.2f}"] for name, value in result["ratios"].items()]
    )
    return [*lines, ""]


def alert_latency(result: dict[str, Any]) -> list[str]:
    lines = [
        "The alert service node as its own process (default site and thresholds), a Zenoh peer "
        "of this one on `tcp/127.0.0.1`. Each sample is a new speeding car: ten 10 Hz track "
        "batches hold the condition, then, once the node has taken them, the batch that "
        "completes the 1 s hold is published; the time runs from that `put_bytes` (payload "
        "encoded beforehand) to the speeding alert's arrival here (receive, decode, every rule "
        f"on every track, encode, publish). {result['samples']} samples per batch size.",
        "",
    ]
    rows = [
        [
            f"{v['tracks_per_batch']} track(s), {v['batch_bytes']:,} B",
            fmt_ms(v["latency_ms"]["p50"]),
            fmt_ms(v["latency_ms"]["p90"]),
            fmt_ms(v["latency_ms"]["p99"]),
            fmt_ms(v["latency_ms"]["max"]),
        ]
        for v in result["variants"].values()
    ]
    lines += md_table(["Batch", "p50", "p90", "p99", "max"], rows)
    return [*lines, ""]


def webhook_latency(result: dict[str, Any]) -> list[str]:
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
    rows = [
        [
            f"{v['subscriptions']} subscription(s)",
            fmt_ms(v["latency_ms"]["p50"]),
            fmt_ms(v["latency_ms"]["p90"]),
            fmt_ms(v["latency_ms"]["p99"]),
            fmt_ms(v["latency_ms"]["max"]),
        ]
        for v in result["variants"].values()
    ]
    lines += md_table(["Subscribers", "p50", "p90", "p99", "max"], rows)
    return [*lines, ""]


def gateway_live(result: dict[str, Any]) -> list[str]:
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
        rows.append(
            [
                name.replace("_", " "),
                f"{fmt_ms(alone['p50'])} / {fmt_ms(alone['p99'])}",
                f"{fmt_ms(loaded['p50'])} / {fmt_ms(loaded['p99'])}",
                f"**{live['requests_per_s']:,.0f}**",
                f"{fmt_ms(live['latency_ms']['p50'])} / {fmt_ms(live['latency_ms']['p99'])}",
                f"{fmt_ms(pages['latency_ms']['p50'])} / {fmt_ms(pages['latency_ms']['p99'])}",
                f"{run['smoothing']['tracks']:.0f} ({fmt_ms(run['smoothing']['mean_ms'])})",
                fmt_ms(run["write_group_mean_ms"]),
            ]
        )
    lines += md_table(
        [
            "Variant",
            "ingest lag alone p50 / p99",
            "ingest lag loaded p50 / p99",
            "live requests/s",
            "live p50 / p99",
            "trajectories page p50 / p99",
            "tracks smoothed (mean time each)",
            "write per group (mean)",
        ],
        rows,
    )
    return [*lines, ""]


def recovery(result: dict[str, Any]) -> list[str]:
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
        rows.append(
            [
                f"`{service}`",
                cell(times["restart_s"]),
                cell(times["status_s"]),
                cell(times["pipeline_s"]),
                f"**{cell(times['recovered_s'])}**",
                "—" if bare.get("recovered_s") is None else f"{bare['recovered_s']:.2f} s",
            ]
        )
    lines += md_table(
        ["Killed", "restart", "status", "pipeline", "recovered", "recovered, no standby"], rows
    )
    lines.append("")
    devices = result["services"].get("alert-service", {}).get("devices_s")
    if devices and devices["median"] is not None:
        lines.append(
            f"- Alert service: its first devices message after the restart "
            f"{cell(devices)} after the kill."
        )
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


def bus_trust(result: dict[str, Any]) -> list[str]:
    lines = [
        "Three processes on loopback as on the trailer's box: `wz router`, this process and a "
        "peer, both clients of the router (every sample crosses it twice). The router runs "
        "`plain` (TCP, no access control: the bus before the trust issue), `tls` (mutual TLS, "
        "a certificate per session, no access control) or `tls+acl` (the deployed "
        "`trailer-router.json5`: mutual TLS and the access control by role, each session "
        "holding the role whose keys it uses). Plain Zenoh sessions, bytes, Python callbacks: "
        f"the transport and the router, not the codec. {result['rounds']} rounds, round-robin "
        "over the variants, fresh processes each; latency over every round's "
        f"{result['pings_per_round']} pings (200 B, one in flight, one-way = round trip / 2), "
        "rates of the median round (each round beside it); every sample counted, in order.",
        "",
    ]
    rows = []
    for name, v in result["variants"].items():
        small, frames = v["small"], v["frames"]
        rows.append(
            [
                f"`{name}`",
                fmt_ms(v["open_ms"]["p50"]),
                f"**{fmt_latency(v['latency_us']['p50'])}**",
                fmt_round_range(v["latency_round_p50_us"]),
                fmt_latency(v["latency_us"]["p99"]),
                f"**{fmt_rate(small['msg_per_s'])}** ({', '.join(fmt_rate(r) for r in small['rounds'])})",
                f"{fmt_rate(frames['msg_per_s'])} ({frames['mb_per_s']:,.0f} MB/s)",
                "yes" if small["in_order"] and frames["in_order"] else "**no**",
            ]
        )
    lines += md_table(
        [
            "Router",
            "Session opening p50",
            "Latency p50",
            "p50 of each round",
            "p99",
            "200 B msg/s (rounds)",
            "2 MB frames/s",
            "All, in order",
        ],
        rows,
    )
    lines += ["", "### Ratios", ""]
    ratio_rows = []
    for name, r in result["ratios"].items():
        if name == "acl_over_tls":
            ratio_rows += [
                [
                    "tls+acl / tls: latency p50 (the access control alone)",
                    f"{r['latency_p50']:.2f}",
                ],
                ["tls+acl / tls: 200 B msg/s", f"{r['small_msg_per_s']:.2f}"],
            ]
            continue
        ratio_rows += [
            [f"{name} / plain: latency p50", f"{r['latency_p50']:.2f}"],
            [f"{name} / plain: latency p99", f"{r['latency_p99']:.2f}"],
            [f"{name} / plain: 200 B msg/s", f"{r['small_msg_per_s']:.2f}"],
            [f"{name} / plain: 2 MB frames/s", f"{r['frames_msg_per_s']:.2f}"],
            [f"{name} / plain: session opening", f"{r['open_p50']:.2f}"],
        ]
    lines += md_table(["Ratio", "Value"], ratio_rows)
    return [*lines, ""]


def alert_flood(result: dict[str, Any]) -> list[str]:
    flood = result["flood"]
    lines = [
        "Four processes on loopback: `wz router`; the gateway node (SQLite, a webhook "
        "subscription to an `http.server` in this process); a flooding tracker putting one-track "
        f"batches (~600 B) at a target of {result['target_rate_hz']:,.0f} a second for "
        f"{result['flood_s']:.0f} s (blocking congestion control); and this process, putting an "
        "alert every 0.5 s from the flood's second second on. *Stored*: from just before the "
        "alert's `put_bytes` to the `received_at` the writer stamped on its row; *webhooked*: "
        "to the receiver having read its signed POST (signature checked). The issue's bound: "
        f"{result['bound_s']:.0f} s for both.",
        "",
    ]
    stored, hooked = result["stored"], result["webhooked"]
    rows = [
        [
            f"{flood['rate_hz']:,.0f} msg/s ({flood['sent']:,} in {flood['seconds']:.1f} s)",
            f"{result['batches_stored']:,} / {result['batches_dropped']:,}",
            f"{len(result['stored_s'])} of {result['alerts']}",
            f"**{fmt_ms(1e3 * stored['p50'])}** (max {fmt_ms(1e3 * stored['max'])})",
            f"**{fmt_ms(1e3 * hooked['p50'])}** (max {fmt_ms(1e3 * hooked['max'])})",
            f"{result['status_max_gap_s']:.2f} s",
            str(result["locked_count"]),
        ]
    ]
    lines += md_table(
        [
            "Flood reached",
            "Track batches stored / dropped",
            "Alerts stored",
            "Stored p50",
            "Webhooked p50",
            "Longest gap in the gateway's status",
            "`database is locked`",
        ],
        rows,
    )
    return [*lines, ""]


def speeding_flood(result: dict[str, Any]) -> list[str]:
    lines = [
        "Five processes on loopback: `wz router`; the alert service node; the gateway node "
        "(SQLite, a webhook subscription to an `http.server` in this process); a source "
        "replaying one old batch of 20 tracks (~11 kB) at a target of "
        f"{result['target_rate_hz']:,.0f} a second for {result['flood_s']:.0f} s (blocking "
        "congestion control, as the tracker's publisher); and this process as the real "
        "tracker, a batch every 0.1 s with one car that speeds up to 70 mph in the 55 mph zone "
        "2 s into the flood. Each time is from the first batch with the car over the limit, "
        "minus the rule's hold time (1 s): *raised*, the alert service's speeding start on the "
        "bus; *stored*, the gateway writer's `received_at`; *webhooked*, its signed POST read "
        f"by the receiver. The issue's bound: {result['bound_s']:.0f} s. *Gate on*: the alert "
        "service sheds batches that carry no news before decoding them (the default); *gate "
        "off*: every batch queued, as before the gate.",
        "",
    ]
    rows = []
    for name in ("gate_on", "gate_off"):
        run = result[name]
        flood = run["flood"]
        shed = ", ".join(
            f"{n:,} {reason}" for reason, n in sorted(run["alert_service_shed"].items())
        )
        invalid = ", ".join(
            f"{n:,} {reason}" for reason, n in sorted(run["alert_service_invalid"].items())
        )

        def late(value: float | None) -> str:
            return "never" if value is None else f"**{fmt_ms(1e3 * value)}**"

        rows.append(
            [
                name.replace("_", " "),
                f"{flood['rate_hz']:,.0f} msg/s ({flood['sent']:,})",
                late(run["raised_s"]),
                late(run["stored_s"]),
                late(run["webhooked_s"]),
                shed or "0",
                invalid or "0",
            ]
        )
    lines += md_table(
        [
            "Alert service",
            "Flood reached",
            "Raised",
            "Stored",
            "Webhooked",
            "Shed (undecoded)",
            "Refused after decoding",
        ],
        rows,
    )
    return [*lines, ""]
