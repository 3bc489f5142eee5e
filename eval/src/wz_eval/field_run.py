"""The pipeline on a field log, in one process: detectors, then the fusion tracker.

:func:`run_log` reads every source of a field log (:mod:`wz_drivers.log`) in stamp order and
runs the nodes' own per-frame code on it: the LiDAR detector's fast path on each sweep
(learning its background from the first ``learn_frames`` sweeps), a radar-camera unit's object
lists as detections, and the production tracker (:class:`MultiTargetTracker`, as the fusion
node runs it) sampled at 10 Hz. Each source's clock may be off: ``offsets_s`` (source clock
minus the reference clock, as :mod:`wz_eval.field` estimates them against the GPS) are taken
off its stamps before fusion, so the tracker fuses what was seen at the same moment.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wz_drivers.gps import gps_track, read_gps
from wz_drivers.log import FieldLog, load_log
from wz_drivers.records import FieldDataError, LidarSweep, ObjectList, Problems
from wz_drivers.sources import lidar_meta, merged_records, objects_to_detections
from wz_eval.field import (
    FieldSettings,
    SourceObservations,
    associate,
    estimate_clock_offset,
    evaluate_field,
    markdown_table,
    plot_field,
)
from wz_fusion_tracker.calibration import (
    BiasMap,
    BiasMapError,
    LateralBiasCorrector,
    fit_bias_map,
    load_bias_map,
    write_bias_map,
)
from wz_fusion_tracker.node import (
    road_heading_hook,
    road_headings_hook,
    sensor_gaps_hook,
    sensor_positions,
    sight_hook,
    to_measurements,
)
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.tracker import MultiTargetTracker
from wz_lidar_detector.node import LidarDetector
from wz_lidar_detector.settings import LidarDetectorSettings
from wz_shared.logs import configure_logging
from wz_shared.messages import DetectionBatch

log = logging.getLogger(__name__)
#: The fused tracks' name in the report.
FUSED = "fused"

#: The fused tracks are sampled at the fusion node's publication rate [Hz].
SAMPLE_HZ = 10.0


@dataclass(frozen=True)
class Observation:
    """One position a source reported [site frame, m] at a stamp [Unix s, source clock]."""

    stamp: float
    x_m: float
    y_m: float
    object_id: int | None = None


@dataclass
class FieldRun:
    """What :func:`run_log` saw and produced."""

    detections: dict[str, list[DetectionBatch]] = field(default_factory=dict)
    fused: list[Observation] = field(default_factory=list)
    problems: Problems = field(default_factory=Problems)
    detector_problems: dict[str, int] = field(default_factory=dict)
    wall_s: float = 0.0

    def observations(self, sensor_id: str) -> list[Observation]:
        """Every detection of one source, flattened, each at its own capture time (a spinning
        LiDAR's objects are seen up to a sweep after the frame's stamp)."""
        return [
            Observation(b.stamp + (d.time_offset_s or 0.0), d.x_m, d.y_m, d.local_track_id)
            for b in self.detections.get(sensor_id, [])
            for d in b.detections
        ]


def detect(field_log: FieldLog, *, learn_frames: int = 20) -> FieldRun:
    """Run the detectors over the log: each source's :class:`DetectionBatch` list."""
    started = time.perf_counter()
    run = FieldRun()

    def report(reason: str, detail: str) -> None:
        run.detector_problems[reason] = run.detector_problems.get(reason, 0) + 1

    detectors: dict[str, LidarDetector] = {}
    settings = LidarDetectorSettings.model_validate({"path": "fast", "learn_frames": learn_frames})
    for source in field_log.sources:
        run.detections[source.sensor_id] = []
        if source.kind == "lidar":
            mount = next(m for m in field_log.site.sensors if m.sensor_id == source.sensor_id)
            detectors[source.sensor_id] = LidarDetector(
                field_log.site.site_id, mount, settings, report
            )
        elif source.kind == "camera":
            raise FieldDataError(
                field_log.folder / "log.yaml",
                f"source {source.sensor_id} is a camera video: "
                "the in-process evaluation reads LiDAR and object lists; replay a video on the "
                "bus through the camera detector (wz replay)",
            )
    site = field_log.site
    for item in merged_records(field_log, run.problems):  # the records: no envelope round trip
        sensor = item.source.sensor_id
        if isinstance(item.record, ObjectList):
            run.detections[sensor].append(
                objects_to_detections(item.record, item.mount, site, item.index)
            )
            continue
        assert isinstance(item.record, LidarSweep)
        meta = lidar_meta(item.record, sensor, site, item.index)
        batch = detectors[sensor].handle(meta, item.record.points, time.monotonic())
        if batch is not None:
            run.detections[sensor].append(batch)
    run.wall_s = time.perf_counter() - started
    return run


def fuse(
    field_log: FieldLog,
    run: FieldRun,
    offsets_s: Mapping[str, float] | None = None,
    tracker_settings: TrackerSettings | None = None,
    bias_map: BiasMap | None = None,
) -> list[Observation]:
    """The production tracker over every source's detections, stamps corrected by
    ``offsets_s`` and, with a ``bias_map``, each sensor's lateral bias removed; the confirmed
    tracks every 1/``SAMPLE_HZ`` s (reference clock)."""
    site = field_log.site
    bias = None if bias_map is None else LateralBiasCorrector(site, bias_map)
    offsets = dict(offsets_s or {})
    batches = sorted(
        (
            b.model_copy(update={"stamp": b.stamp - offsets.get(sensor, 0.0)})
            for sensor, sensor_batches in run.detections.items()
            for b in sensor_batches
        ),
        key=lambda b: (b.stamp, b.source_id),
    )
    if not batches:
        return []
    settings = tracker_settings or TrackerSettings()
    tracker = MultiTargetTracker(
        settings,
        heading_at=road_heading_hook(site),
        sensor_positions=sensor_positions(site),
        headings_at=road_headings_hook(site),
        in_sensor_gap=sensor_gaps_hook(site, settings),
        hidden_from_sensors=sight_hook(site, settings),
    )
    fused: list[Observation] = []
    position = 0
    first, last = batches[0].stamp, batches[-1].stamp
    for k in range(math.floor((last - first) * SAMPLE_HZ) + 1):
        sample_s = first + k / SAMPLE_HZ
        while position < len(batches) and batches[position].stamp <= sample_s + 1e-9:
            batch = batches[position]
            tracker.add(batch.source_id, batch.stamp, to_measurements(batch, bias))
            position += 1
        tracker.flush()
        tracker.advance_to(sample_s)
        fused += [
            Observation(sample_s, s.x_m, s.y_m, s.track_id)
            for s in tracker.tracks(sample_s)
            if s.status != "tentative"
        ]
    return fused


def _observations(items: list[Observation]) -> SourceObservations:
    return SourceObservations(
        times_s=np.array([o.stamp for o in items], dtype=np.float64),
        x_m=np.array([o.x_m for o in items], dtype=np.float64),
        y_m=np.array([o.y_m for o in items], dtype=np.float64),
        ids=np.array([-1 if o.object_id is None else o.object_id for o in items], dtype=np.int64),
    )


def evaluate_log(
    field_log: FieldLog,
    truth_path: Path | None = None,
    *,
    out_dir: Path | None = None,
    settings: FieldSettings | None = None,
    bias_map: BiasMap | None = None,
    bias_min_samples: int = 30,
) -> dict[str, Any]:
    """The paper's field validation on a log: each source and the fused tracks against the
    GPS track; the report as a dict (``table``: markdown), the plot under ``out_dir``.

    Each source's clock offset to the GPS is estimated from its own detections first; the
    tracker then fuses the detections with those offsets taken off (and ``bias_map``'s
    lateral bias removed, when given), and the fused track is scored on the GPS clock (offset
    0, given). ``measured_bias_map`` in the report is each sensor's lateral bias against the
    probe (:func:`~wz_fusion_tracker.calibration.fit_bias_map`, cells of at least
    ``bias_min_samples`` errors): a calibration drive's map, for the fusion node.
    """
    truth_path = truth_path or field_log.truth_path()
    if truth_path is None:
        raise FieldDataError(field_log.folder / "log.yaml", "no truth: give --truth GPS_FILE")
    truth_spec = field_log.manifest.truth
    gps_problems = Problems()
    track = gps_track(
        list(read_gps(truth_path, gps_problems)),
        field_log.site,
        antenna_forward_m=truth_spec.antenna_forward_m if truth_spec else 0.0,
        antenna_left_m=truth_spec.antenna_left_m if truth_spec else 0.0,
    )
    run = detect(field_log)
    road = field_log.site.road_frame
    per_source = {
        source.sensor_id: _observations(run.observations(source.sensor_id))
        for source in field_log.sources
    }
    offsets = {
        name: estimate_clock_offset(track, observations, road, settings).offset_s
        for name, observations in per_source.items()
        if len(observations.times_s)
    }
    run.fused = fuse(field_log, run, offsets, bias_map=bias_map)
    sources = {**per_source, FUSED: _observations(run.fused)}
    result = evaluate_field(track, sources, road, settings, clock_offsets_s={FUSED: 0.0})
    measured = fit_bias_map(
        field_log.site,
        [
            (name, float(station), float(offset), float(error))
            for name, source in result.sources.items()
            if name != FUSED
            for station, offset, error in zip(
                source.association.truth_station_m,
                source.association.truth_offset_m,
                source.association.lateral_error_m,
                strict=True,
            )
        ],
        min_samples=bias_min_samples,
        source=f"field log {field_log.folder}",
    )
    # The same, on the stretch every source saw the probe on: each on the same ground.
    spans = []
    for name, observations in sources.items():
        association = associate(track, observations, road, offsets.get(name, 0.0), settings)
        if len(association):
            spans.append(
                (float(association.truth_station_m.min()), float(association.truth_station_m.max()))
            )
    common = None
    if len(spans) == len(sources) and max(a for a, _ in spans) < min(b for _, b in spans):
        window = (max(a for a, _ in spans), min(b for _, b in spans))
        common = evaluate_field(
            track,
            sources,
            road,
            replace(settings or FieldSettings(), station_window_m=window),
            clock_offsets_s={FUSED: 0.0},
        )
    report: dict[str, Any] = {
        "log": str(field_log.folder),
        "site": field_log.site.site_id,
        "truth": str(truth_path),
        "gps_fixes": len(track),
        "sources": {s.sensor_id: {"kind": s.kind, "format": s.format} for s in field_log.sources},
        "detections": {name: len(batches) for name, batches in run.detections.items()},
        "skipped_records": {**run.problems.summary(), **gps_problems.summary()},
        "detector_problems": run.detector_problems,
        "result": result.to_dict(),
        "table": markdown_table(result),
        "common": None if common is None else common.to_dict(),
        "common_table": None if common is None else markdown_table(common),
        "wall_s": run.wall_s,
        "bias_map": None if bias_map is None else bias_map.source,
        "measured_bias_map": measured.model_dump(mode="json"),
    }
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        plot = plot_field(result, out_dir / "field.png")
        report["plots"] = [plot.name]
    return report


def markdown(report: dict[str, Any]) -> str:
    fused = report["result"]["sources"][FUSED]
    lines = [
        f"# Field validation: `{report['log']}` against `{report['truth']}`",
        "",
        f"Site `{report['site']}`; {report['gps_fixes']} GPS fixes; detections per source: "
        + ", ".join(f"{k} {v}" for k, v in report["detections"].items())
        + ".",
        "",
        "Each source over all it saw of the probe:",
        "",
        report["table"],
        "",
        f"Fused track: {fused['distinct_ids']} track id(s), {fused['id_changes']} change(s) "
        f"on the probe; longest gap {fused['longest_gap_s']:.2f} s.",
        "",
    ]
    if report["common_table"]:
        window = report["common"]["station_window_m"]
        lines += [
            f"On the stretch every source saw the probe on (stations {window[0]:.0f} to "
            f"{window[1]:.0f} m):",
            "",
            report["common_table"],
            "",
        ]
    if report["skipped_records"]:
        lines += [
            "Records skipped: "
            + ", ".join(f"{k}: {v}" for k, v in report["skipped_records"].items()),
            "",
        ]
    lines += [f"![{plot}]({plot})" for plot in report.get("plots", [])]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``wz eval --log LOG_DIR [--truth GPS_FILE]`` (from :func:`wz_eval.cli.main`)."""
    parser = argparse.ArgumentParser(
        prog="wz eval --log", description="the paper's field validation on a field log"
    )
    parser.add_argument("--log", type=Path, required=True, metavar="LOG_DIR")
    parser.add_argument(
        "--truth",
        type=Path,
        default=None,
        metavar="GPS_FILE",
        help="NMEA or CSV (default: the log's truth)",
    )
    parser.add_argument("--out", type=Path, default=Path("runs/field-eval"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument(
        "--bias-map",
        type=Path,
        default=None,
        metavar="FILE",
        help="remove each sensor's lateral bias (a map of this site) before the tracker",
    )
    parser.add_argument(
        "--write-bias-map",
        type=Path,
        default=None,
        metavar="FILE",
        help="write each sensor's lateral bias against the probe: a calibration drive's map",
    )
    parser.add_argument(
        "--bias-min-samples",
        type=int,
        default=30,
        metavar="N",
        help="a map's cell needs at least N errors (default 30)",
    )
    args = parser.parse_args(argv)
    configure_logging(service="eval", site="-", level="WARNING")
    try:
        field_log = load_log(args.log)
        bias_map = None if args.bias_map is None else load_bias_map(args.bias_map, field_log.site)
        report = evaluate_log(
            field_log,
            args.truth,
            out_dir=args.out,
            bias_map=bias_map,
            bias_min_samples=args.bias_min_samples,
        )
    except (FieldDataError, BiasMapError) as exc:
        sys.stderr.write(f"wz eval: {exc}\n")
        return 1
    if args.write_bias_map is not None:
        write_bias_map(args.write_bias_map, BiasMap.model_validate(report["measured_bias_map"]))
    (args.json or args.out / "field-eval.json").write_text(
        json.dumps(report, indent=2, default=str) + "\n"
    )
    text = markdown(report)
    (args.out / "field-eval.md").write_text(text)
    sys.stdout.write(text)
    return 0
