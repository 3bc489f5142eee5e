"""Formatting shared by the report's sections: units, Markdown tables, path names."""

from __future__ import annotations

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


def fmt_us(value: float) -> str:
    return f"{value:.0f} µs" if value >= 100 else f"{value:.1f} µs"


def fmt_ms(value: float) -> str:
    return f"{value:.2f} ms" if value < 10 else f"{value:.1f} ms"


def fmt_latency(value_us: float) -> str:
    return fmt_us(value_us) if value_us < 1000 else fmt_ms(value_us / 1000)


def fmt_rate(value: float) -> str:
    return f"{value:,.0f}"


def fmt_round_range(values_us: list[float]) -> str:
    if len(values_us) == 1:
        return fmt_latency(values_us[0])
    return f"{fmt_latency(min(values_us))} – {fmt_latency(max(values_us))}"


def md_table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def base_path(name: str) -> str:
    return name.removesuffix("-noshm")


def fmt_s(value: float | None) -> str:
    return "—" if value is None else f"{value:.1f} s"


def median_of(services: dict[str, Any], name: str) -> float | None:
    values = sorted(v[name]["median"] for v in services.values() if v[name]["median"] is not None)
    return values[len(values) // 2] if values else None


def fmt_spread(counts: dict[str, Any]) -> str:
    """min / median / max of a count."""
    return f"{counts['min']} / {counts['median']:.0f} / {counts['max']}"


def frame_stats(stats: dict[str, float]) -> list[str]:
    return [
        f"**{fmt_ms(stats['p50'])}**",
        fmt_ms(stats["p90"]),
        fmt_ms(stats["p99"]),
        fmt_ms(stats["max"]),
    ]


def gc_columns(split: dict[str, Any]) -> list[str]:
    """Calls a full garbage collection fell in; the slowest call without one."""
    return [str(split["calls_with_full_gc"]), fmt_ms(split["max_ms_without_full_gc"])]
