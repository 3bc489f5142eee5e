"""``wz eval``: the whole pipeline on the simulated work zone, scored against truth.

Usage (the command line is :mod:`wz_eval.cli`'s)::

    wz eval [--site FILE] [--duration-s 600] [--seed 7] [--max-range-m 150]
            [--drop SENSOR@START+SECONDS ...] [--bias-map FILE] [--write-bias-map FILE]
            [--json FILE] [--out DIR]

:func:`evaluate` runs SUMO, the three sensors and both detectors in one process (:mod:`wz_eval.pipeline`), then
feeds the detections, in stamp order, to

- the production tracker (:class:`MultiTargetTracker`, as the fusion node runs it), sampled at
  10 Hz (every camera frame time) after taking every batch up to that time: ``fused``;
- the paper's method (:func:`run_paper_pipeline`: per-sensor Kalman smoothing, nearest-distance
  matching, sequential camera-then-LiDAR updates): ``paper_kf``, and its simple average of the
  matched pair: ``average``. The paper's sensors came with their own object ids; here each
  detection gets the id of the vehicle it is nearest to (within the gate): an oracle identity,
  which can only favour the baseline.

and scores, for vehicles within ``--max-range-m`` of the mast, each source at its own times in
the road frame (:mod:`wz_eval.metrics`): ``camera`` (camera alone: the calibrated pinhole
position before radar fusion), ``lidar`` (the LiDAR detector's boxes), ``radar`` (radar echo
points alone), ``camera_radar`` (the camera channel's published detections), ``average``,
``paper_kf`` and ``fused``; and two hindsight versions of the fused tracks: ``fused_smoothed``
(Rauch-Tung-Striebel over each track's own update history, the best a smoother of these
updates gives) and ``fused_stored`` (the 10 Hz published states smoothed as the gateway smooths
an ended track: what ``/v1/trajectories`` serves).

Multi-object tracking scores of ``fused`` (py-motmetrics: MOTA, IDF1, identity switches) use
the confirmed and coasting tracks against the vehicles in range, matched within 3 m.

The fused track is scored inside the circle *where a sensor of the site can see a car*
(:mod:`wz_shared.coverage`, from the sensors' geometry and the run's weather: the camera's
picture, the radar's wedge, and as far as a car's paint returns to the LiDAR and its beams are
sure to hit one; a 32-beam LiDAR reaches about 65 m, so on such a site most of the circle
downstream of the mast is seen by nothing, and fog of 150 m visibility stops any LiDAR at about
45 m). No
tracker can be held to what no sensor sees; ``coverage`` gives the share covered and each
sensor's reach, and ``circle`` the MOT figures over the whole circle, so nothing is hidden.
``EvalOptions.covered_only=False`` scores the whole circle.

``paper_table`` reproduces the paper's Tables 1-2: for vehicles seen through the whole station
window (default 40-100 m upstream of the mast, like the paper's short segment), the cumulative
absolute longitudinal and lateral error over the camera frames in the window where every
source has the vehicle, per source.

``must_show``: issue 6's targets (:data:`wz_eval.fusion_report.TARGETS`) checked on this run, one row each
(:func:`must_show`), also in ``eval.md``.

``alerts``: the alert service run on the fused tracks (as the node publishes them) and scored
with :func:`wz_eval.alerts.score_alerts` against the same rules run on the truth of the
vehicles within 200 m of the mast that a sensor saw (:func:`wz_eval.alerts.observed_truth`);
``alerts_all_in_range`` scores them against every vehicle within 200 m, hidden ones included.

``--write-bias-map FILE`` writes the lateral bias of the LiDAR's and the camera-radar channel's
detections this run measured (:func:`~wz_fusion_tracker.calibration.fit_bias_map`; also in the
report as ``measured_bias_map``); ``--bias-map FILE`` removes such a map's bias from the
detections before the tracker takes them (as the fusion node does with
``WZ_FUSION_BIAS_MAP``). Take the map from a run of another seed: fitted and scored on the same
run, it would be scored on its own training data. The sources scored alone (``camera``,
``lidar``, ``average``, ...) are the detectors' outputs as published, uncorrected.

``--mount-errors`` renders the sensors as a real mast's (:mod:`wz_simulator.sensors.mast`:
each sensor's set-up error, late clock, the mast's sway and settling, drawn from the seed) while
the detectors and the tracker keep the site file's poses; ``--bump camera-mast@300:2`` also
knocks that sensor round by 2 deg 300 s after the warm-up. The report's ``mount_errors`` gives
what was drawn (None without).

``--drop lidar-mast@300+2`` removes that sensor's batches from 300 s to 302 s after the warm-up
(a dropout); the report then gives, per dropout, the fused error and identity switches inside
the window.

Writes ``DIR/eval.json`` (or ``--json``), ``DIR/eval.md``, PNG plots and SSAM's conflict tables of
the tracks and of the truth within the alerts' range (:mod:`wz_eval.conflicts_report`) in ``DIR``.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from wz_camera_detector.settings import camera_mount
from wz_eval.alerts import observed_truth, run_alert_engine, score_alerts, track_follows
from wz_eval.by_station import StationBreakdown
from wz_eval.conflicts_report import conflict_report
from wz_eval.coverage_report import coverage_report, weather_coverage
from wz_eval.fusion_report import ALERT_TRUTH_RANGE_M, must_show, table_summary
from wz_eval.lane_counts import lane_volume_report
from wz_eval.metrics import TruthIndex, in_range, match
from wz_eval.pipeline import PipelineOptions, PipelineRecord, demand_conditions, run_pipeline
from wz_eval.queue_report import queue_report
from wz_eval.scores import SOURCE_GATE_M, SOURCES, Scores
from wz_fusion_tracker.calibration import BiasMap, LateralBiasCorrector, fit_bias_map
from wz_fusion_tracker.node import (
    process_noise,
    road_heading_hook,
    road_headings_hook,
    sensor_gaps_hook,
    sensor_positions,
    sight_hook,
    to_measurements,
    to_track,
)
from wz_fusion_tracker.paper import (
    FusedEstimate,
    Observation,
    PaperFusionSettings,
    run_paper_pipeline,
)
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.smoothing import smooth_history
from wz_fusion_tracker.tracker import MultiTargetTracker
from wz_fusion_tracker.types import TrackHistory, TrackState
from wz_lidar_detector.settings import lidar_mount
from wz_shared.arrays import F64
from wz_shared.coverage import SiteCoverage
from wz_shared.messages import DetectionBatch, TrackBatch, VehicleTruth
from wz_shared.motion import rts_smooth
from wz_shared.site import Site
from wz_simulator.sensors.mast import Bump

log = logging.getLogger("wz_eval.fusion")

#: Gate for matching a track to a vehicle in the MOT metrics [m].
MOT_GATE_M = 3.0
#: Width of the "don't care" band at the scored region's edge [m] (see :func:`scored_region`).
EDGE_MARGIN_M = 10.0


@dataclass(frozen=True)
class Dropout:
    sensor_id: str
    start_s: float  # after the warm-up
    duration_s: float

    @classmethod
    def parse(cls, text: str) -> Dropout:
        """``SENSOR@START+SECONDS``."""
        try:
            sensor, rest = text.split("@")
            start, duration = rest.split("+")
            return cls(sensor, float(start), float(duration))
        except ValueError as exc:
            raise ValueError(f"--drop {text!r}: expected SENSOR@START+SECONDS") from exc


@dataclass(frozen=True)
class EvalOptions:
    seed: int = 7
    duration_s: float = 600.0
    warmup_s: float = 60.0
    max_range_m: float = 150.0
    window_upstream_m: tuple[float, float] = (40.0, 100.0)
    dropouts: tuple[Dropout, ...] = ()
    camera_model: Path | None = None
    #: Traffic and weather of the simulated run (:class:`~wz_eval.pipeline.PipelineOptions`).
    vehicles_per_hour: float = 1400.0
    #: Demand as a share of the closure's capacity (replaces ``vehicles_per_hour``); None: off.
    demand_ratio: float | None = None
    #: ``steady`` or ``ramp`` (:func:`wz_eval.pipeline.ramp_settings`).
    demand_profile: str = "steady"
    weather: str = "day"
    truck_share: float = 0.15
    aggressive_share: float = 0.2
    tracker: TrackerSettings = field(default_factory=TrackerSettings)
    paper: PaperFusionSettings = field(default_factory=PaperFusionSettings)
    #: Each sensor's lateral bias, removed from its detections before the tracker takes them
    #: (as the fusion node does with ``WZ_FUSION_BIAS_MAP``); None: none removed.
    bias_map: BiasMap | None = None
    #: Score the fused tracks only where a sensor can see a car (:mod:`wz_shared.coverage`)
    #: inside the circle; False: the whole circle. Either way the report has both MOTAs.
    covered_only: bool = True
    #: Render the sensors as a real mast's (:mod:`wz_simulator.sensors.mast`); the services
    #: keep the site file's poses.
    mount_errors: bool = False
    #: A sensor knocked round at a simulation time (needs ``mount_errors``).
    bump: Bump | None = None
    #: The sensors learn their poses and clocks from the warm-up's traffic (on, as in the
    #: services); False: the site file's poses and the stamps as they come.
    self_calibration: bool = True


def pipeline_options(options: EvalOptions) -> PipelineOptions:
    """What to simulate for an evaluation: its seed, length, traffic, weather and camera model."""
    return PipelineOptions(
        seed=options.seed,
        duration_s=options.duration_s,
        warmup_s=options.warmup_s,
        weather=options.weather,
        vehicles_per_hour=options.vehicles_per_hour,
        demand_ratio=options.demand_ratio,
        demand_profile=options.demand_profile,
        truck_share=options.truck_share,
        aggressive_share=options.aggressive_share,
        camera_model=options.camera_model,
        mount_errors=options.mount_errors,
        bump=options.bump,
        self_calibration=options.self_calibration,
    )


def _progress(sim_s: float, total_s: float) -> None:
    """A progress bar on a terminal; a line every 10 % otherwise (logs, CI)."""
    done = min(1.0, sim_s / total_s) if total_s > 0 else 1.0
    if sys.stderr.isatty():
        bar = "#" * int(30 * done)
        sys.stderr.write(
            f"\r  simulating [{bar:<30}] {100 * done:5.1f} % "
            f"({sim_s:.0f}/{total_s:.0f} s)" + ("\n" if done >= 1.0 else "")
        )
    elif int(10 * done) != int(10 * min(1.0, (sim_s - 1.0) / total_s)):
        sys.stderr.write(f"simulating: {100 * done:.0f} % ({sim_s:.0f}/{total_s:.0f} s)\n")
    sys.stderr.flush()


def _silent(sensor_id: str, stamp_s: float, dropouts: Sequence[Dropout], warmup_s: float) -> bool:
    """Whether ``sensor_id`` is in one of the dropouts at ``stamp_s``."""
    return any(
        sensor_id == d.sensor_id
        and warmup_s + d.start_s <= stamp_s < warmup_s + d.start_s + d.duration_s
        for d in dropouts
    )


def _dropped(batch: DetectionBatch, dropouts: Sequence[Dropout], warmup_s: float) -> bool:
    return _silent(batch.source_id, batch.stamp, dropouts, warmup_s)


def _oracle_observations(
    frames: Sequence[tuple[float, Sequence[tuple[float, float]]]],
    truth: TruthIndex,
    site: Site,
    centre: tuple[float, float],
    max_range_m: float,
    ids: dict[str, int],
) -> list[Observation]:
    """A sensor's positions with the id of the vehicle each is nearest to (see the docstring)."""
    observations = []
    for stamp, points in frames:
        vehicles = truth.at(stamp)
        if vehicles is None or not points:
            continue
        vehicles = in_range(site, vehicles, centre, max_range_m + 20.0)
        est = np.array(points, dtype=np.float64).reshape(-1, 2)
        tru = np.array([(v.x_m, v.y_m) for v in vehicles], dtype=np.float64).reshape(-1, 2)
        for e, t in match(est, tru, SOURCE_GATE_M):
            number = ids.setdefault(vehicles[t].vehicle_id, len(ids) + 1)
            observations.append(Observation(stamp, number, float(est[e, 0]), float(est[e, 1])))
    return observations


def camera_id(record: PipelineRecord) -> str:
    return camera_mount(record.site, None).sensor_id


def evaluate(
    site: Site,
    options: EvalOptions,
    record: PipelineRecord | None = None,
    plots_dir: Path | None = None,
) -> dict[str, Any]:
    """Run (or take) the pipeline record and score every source (module docstring)."""
    if record is None:
        record = run_pipeline(site, pipeline_options(options), progress=_progress)
    started = time.perf_counter()
    truth = TruthIndex(record.truth)
    mast = lidar_mount(site, None).pose
    centre = (mast.x_m, mast.y_m)
    cam_id = camera_id(record)
    lidar_id = lidar_mount(site, None).sensor_id
    scores = Scores()

    def vehicles_at(stamp_s: float) -> list[VehicleTruth] | None:
        found = truth.at(stamp_s)
        return None if found is None else in_range(site, found, centre, options.max_range_m)

    # --- each sensor alone, at its own times
    for batch in record.batches:
        if _dropped(batch, options.dropouts, options.warmup_s):
            continue
        vehicles = vehicles_at(batch.stamp)
        if vehicles is None:
            continue
        source = "lidar" if batch.source_id == lidar_id else "camera_radar"
        scores.add(
            site,
            source,
            batch.stamp,
            [(d.x_m, d.y_m, d.speed_mps) for d in batch.detections],
            vehicles,
            [d.time_offset_s for d in batch.detections],
        )

    def _silenced(stamp_s: float) -> bool:
        """The camera is in a dropout at ``stamp_s`` (its camera-only positions go too)."""
        return _silent(cam_id, stamp_s, options.dropouts, options.warmup_s)

    for stamp, points in record.camera_only:
        if (vehicles := vehicles_at(stamp)) is not None and not _silenced(stamp):
            scores.add(site, "camera", stamp, [(p.x_m, p.y_m, None) for p in points], vehicles)
    for stamp, points in record.radar_only:
        if (vehicles := vehicles_at(stamp)) is not None:
            scores.add(site, "radar", stamp, [(p.x_m, p.y_m, None) for p in points], vehicles)

    # --- the production tracker, sampled at every camera frame time
    tracker = MultiTargetTracker(
        options.tracker,
        heading_at=road_heading_hook(site),
        sensor_positions=sensor_positions(site),
        headings_at=road_headings_hook(site),
        in_sensor_gap=sensor_gaps_hook(site, options.tracker),
        hidden_from_sensors=sight_hook(site, options.tracker),
    )
    bias = None if options.bias_map is None else LateralBiasCorrector(site, options.bias_map)
    mot = _MotAccumulator()
    mast_station_m = float(site.road_frame.to_road(*centre)[0])
    by_station = StationBreakdown(mast_station_m)
    # The approach alone (upstream of the mast): what the sensors face.
    mot_approach = _MotAccumulator()
    # The whole circle, covered or not: what the coverage leaves out.
    mot_circle = _MotAccumulator()
    in_weather = weather_coverage(site, options.weather)
    coverage = in_weather if options.covered_only else None
    sample_times = [stamp for stamp, _ in record.camera_only]
    batches = [b for b in record.batches if not _dropped(b, options.dropouts, options.warmup_s)]
    position = 0
    tracker_s = 0.0
    samples_out_of_order = 0
    fused_samples: list[tuple[float, float, float]] = []
    mot_times: list[float] = []
    scored_ids: list[tuple[float, list[int], list[VehicleTruth]]] = []
    alert_batches: list[TrackBatch] = []
    histories: list[TrackHistory] = []
    # what the gateway stores: every published state, per track id
    stored: dict[int, list[TrackState]] = defaultdict(list)
    for sample_s in sample_times:
        t0 = time.perf_counter()
        while position < len(batches) and batches[position].stamp <= sample_s + 1e-9:
            batch = batches[position]
            tracker.add(batch.source_id, batch.stamp, to_measurements(batch, bias))
            position += 1
        tracker.flush()
        processed_s = tracker.last_processed_stamp_s
        if processed_s is not None and sample_s < processed_s:
            # The camera's learned clock offset grew between two frames: this frame's stamp
            # lies before one already taken. The tracker node's reorder window takes such a
            # batch; the tracks are not sampled back in time (counted, not scored).
            samples_out_of_order += 1
            tracker_s += time.perf_counter() - t0
            continue
        tracker.advance_to(sample_s)
        published = [s for s in tracker.tracks(sample_s) if s.status != "tentative"]
        for state in published:
            stored[state.track_id].append(state)
        tracker_s += time.perf_counter() - t0
        # what the node would publish, for the alert service
        alert_batches.append(
            TrackBatch(
                site=site.site_id,
                source_id="fusion-tracker",
                stamp=sample_s,
                cycle_index=len(alert_batches),
                tracks=[to_track(site, s) for s in published],
                process_noise=process_noise(options.tracker),
            )
        )
        states = [
            s
            for s in published
            if math.hypot(s.x_m - centre[0], s.y_m - centre[1])
            <= options.max_range_m + EDGE_MARGIN_M
        ]
        found = truth.at(sample_s)
        if found is None:
            continue
        nearby = in_range(site, found, centre, options.max_range_m + EDGE_MARGIN_M)
        mot_circle.update(*scored_region(nearby, states, centre, options.max_range_m))
        vehicles, states = scored_region(nearby, states, centre, options.max_range_m, coverage)
        matched = scores.add(
            site, "fused", sample_s, [(s.x_m, s.y_m, s.speed_mps) for s in states], vehicles
        )
        by_station.add(vehicles, matched, [s.speed_mps for s in states])
        fused_samples.extend((sample_s, lon, lat) for _, _, lon, lat in matched)
        mot.update(vehicles, states)
        mot_approach.update(*approach_region(site, vehicles, states, mast_station_m))
        mot_times.append(sample_s)
        scored_ids.append((sample_s, [s.track_id for s in states], vehicles))
        histories.extend(tracker.pop_finished_histories())

    # --- the same tracks, RTS-smoothed over their whole update history
    histories.extend(tracker.pop_finished_histories())
    histories.extend(tracker.unfinished_histories())
    smoothed = smoothed_positions(histories)
    for sample_s, track_ids, scored_vehicles in scored_ids:
        smoothed_estimates = [
            xy
            for track_id in track_ids
            if (xy := smoothed_at(smoothed, track_id, sample_s)) is not None
        ]
        scores.add(site, "fused_smoothed", sample_s, smoothed_estimates, scored_vehicles)
    # --- the published states as the gateway smooths them when a track ends
    stored_smoothed = gateway_smoothed(stored, options.tracker)
    for sample_s, track_ids, scored_vehicles in scored_ids:
        stored_estimates = [
            xy
            for track_id in track_ids
            if (xy := smoothed_at(stored_smoothed, track_id, sample_s)) is not None
        ]
        scores.add(site, "fused_stored", sample_s, stored_estimates, scored_vehicles)

    # --- the paper's method, with oracle per-sensor identities
    ids: dict[str, int] = {}
    camera_frames = [
        (stamp, [(p.x_m, p.y_m) for p in points])
        for stamp, points in record.camera_only
        if not _silenced(stamp)
    ]
    lidar_frames = [
        (b.stamp, [(d.x_m, d.y_m) for d in b.detections])
        for b in batches
        if b.source_id == lidar_id
    ]
    observations = {
        options.paper.camera_sensor_id: _oracle_observations(
            camera_frames, truth, site, centre, options.max_range_m, ids
        ),
        options.paper.lidar_sensor_id: _oracle_observations(
            lidar_frames, truth, site, centre, options.max_range_m, ids
        ),
    }
    # The camera's learned clock offset takes its frames off the LiDAR's grid: a frame of the
    # paper's method takes what lies within half a LiDAR period of its first stamp
    # (wz_fusion_tracker.paper, "Frames"), and each camera sample is scored at the frame that
    # holds it, at the frame's time.
    half_period_s = frame_match_tolerance_s(site)
    paper_settings = options.paper.model_copy(
        update={"frame_tolerance_s": max(options.paper.frame_tolerance_s, half_period_s)}
    )
    estimates = run_paper_pipeline(observations, paper_settings)
    by_stamp: dict[float, list[FusedEstimate]] = defaultdict(list)
    for estimate in estimates:
        by_stamp[round(estimate.stamp_s, 4)].append(estimate)
    frame_times = np.array(sorted(by_stamp), dtype=float)
    nearest = _nearest_within(np.array(sample_times, dtype=float), frame_times, half_period_s)
    for index in nearest:
        if index < 0:
            continue
        stamp = float(frame_times[index])
        frame = by_stamp[stamp]
        vehicles = vehicles_at(stamp)
        if vehicles is None or not frame:
            continue
        scores.add(
            site,
            "paper_kf",
            stamp,
            [(e.x_m, e.y_m, math.hypot(e.vx_mps, e.vy_mps)) for e in frame],
            vehicles,
        )
        averages = [
            (e.average_xy_m[0], e.average_xy_m[1], None)
            for e in frame
            if e.average_xy_m is not None
        ]
        scores.add(site, "average", stamp, averages, vehicles)

    # --- the alert service on the fused tracks, scored against the same rules on the truth
    alert_truth = [
        (stamp, in_range(site, vehicles, centre, ALERT_TRUTH_RANGE_M))
        for stamp, vehicles in record.truth
    ]
    alert_events = run_alert_engine(site, alert_batches)
    follows = track_follows(alert_batches, alert_truth)
    alerts = score_alerts(site, observed_truth(alert_truth, batches), alert_events, follows=follows)
    alerts_all_in_range = score_alerts(site, alert_truth, alert_events, follows=follows)

    report = {
        "site": site.site_id,
        "seed": options.seed,
        "duration_s": options.duration_s,
        "warmup_s": options.warmup_s,
        "conditions": {
            "weather": record.options.weather,
            **demand_conditions(site, record.options),
            "truck_share": record.options.truck_share,
            "aggressive_share": record.options.aggressive_share,
        },
        "max_range_m": options.max_range_m,
        # What the sensors were rendered with; nothing of it reached the services.
        "mount_errors": None if record.mast is None else record.mast.describe(),
        # What each sensor learned of its pose and clock (the self-calibration, on by default).
        "calibration": {
            sensor: {
                **message.model_dump(
                    mode="json",
                    include={"sensor_kind", "state", "correction", "clock_offset_s", "samples"},
                ),
                "clock_offset_std_s": message.clock_offset_std_s,
                "history": record.calibration_history.get(sensor, []),
            }
            for sensor, message in record.calibrations.items()
        },
        "vehicles": len(
            {
                v.vehicle_id
                for _, vs in record.truth
                for v in vs
                if math.hypot(v.x_m - centre[0], v.y_m - centre[1]) <= options.max_range_m
            }
        ),
        **{
            f"rmse_{axis}": {s: scores.errors[s].summary()[f"rmse_{axis}"] for s in SOURCES}
            for axis in ("longitudinal_m", "lateral_m", "speed_mps")
        },
        "sources": {s: scores.errors[s].summary() for s in SOURCES},
        **mot.summary(len(record.truth)),
        "id_switch_events": mot.switch_events(mot_times, mast_station_m),
        "approach": mot_approach.summary(len(record.truth)),
        "scored_region": "covered" if options.covered_only else "circle",
        "coverage": coverage_report(in_weather, centre, options.max_range_m),
        "circle": mot_circle.summary(len(record.truth)),
        "paper_table": paper_table(site, scores, centre, options.window_upstream_m),
        "alerts": alerts,
        "alerts_all_in_range": alerts_all_in_range,
        # SSAM's conflicts on the published tracks and the same truth (CSV tables beside)
        "conflicts": conflict_report(alert_batches, alert_truth, plots_dir),
        "fused_by_station": by_station.report(),
        "mast_stretch": by_station.mast_stretch(),
        # each lane's queue against the same estimate on every simulated vehicle's truth
        "queue": (
            queue_report(
                site,
                alert_batches,
                record.truth,
                *_scored_interval(record),
                in_weather,
                getattr(record, "point_readings", []),  # recordings from before them lack it
            )
            if record.truth
            else None
        ),
        "lane_volumes": (
            lane_volume_report(site, alert_batches, record.truth, *_scored_interval(record))
            if record.truth
            else None
        ),
        "dropouts": [
            _dropout_report(d, options.warmup_s, fused_samples, mot, mot_times)
            for d in options.dropouts
        ],
        "bump": (
            None
            if options.bump is None
            else _bump_report(
                options.bump, record, options.warmup_s, alerts, fused_samples, mot, mot_times
            )
        ),
        "pipeline_problems": record.problems,
        "samples_out_of_order": samples_out_of_order,
        "timing": {
            "pipeline_wall_s": round(record.wall_s, 1),
            "tracker_s": round(tracker_s, 2),
            "scoring_wall_s": round(time.perf_counter() - started, 1),
        },
    }
    report["paper_table_summary"] = table_summary(report["paper_table"])
    report["must_show"] = must_show(report)
    report["bias_map"] = None if options.bias_map is None else options.bias_map.source
    report["measured_bias_map"] = fit_bias_map(
        site,
        _sensor_errors(scores, {"lidar": lidar_id, "camera_radar": cam_id}),
        source=f"wz eval seed {options.seed}, {options.duration_s:g} s",
    ).model_dump(mode="json")
    if plots_dir is not None:
        from wz_eval.plots import write_plots

        report["plots"] = write_plots(plots_dir, site, record, scores, report)
    return report


def _scored_interval(record: PipelineRecord) -> tuple[float, float]:
    """First and last truth stamp: the scored interval, after the warm-up."""
    return record.truth[0][0], record.truth[-1][0]


def _sensor_errors(
    scores: Scores, sensor_of_source: dict[str, str]
) -> list[tuple[str, float, float, float]]:
    """``(sensor id, true station, true offset, lateral error)`` of every matched detection of
    the given sources (as scored, uncorrected), for :func:`fit_bias_map`."""
    return [
        (sensor_of_source[source], station, offset, lateral)
        for by_source in scores.per_vehicle.values()
        for source, samples in by_source.items()
        if source in sensor_of_source
        for _, lateral, station, offset in samples.values()
    ]


def smoothed_positions(histories: Sequence[TrackHistory]) -> dict[int, tuple[F64, F64]]:
    """Per track id: its update stamps and RTS-smoothed states (``smooth_history``: the
    priors the tracker stored, each run of one filter's updates on its own)."""
    out: dict[int, tuple[F64, F64]] = {}
    for history in histories:
        if len(history.stamps_s) == 0 or np.any(np.diff(history.stamps_s) < 0.0):
            continue
        x_smooth, _ = smooth_history(history)
        out[history.track_id] = (history.stamps_s, x_smooth)
    return out


def gateway_smoothed(
    stored: dict[int, list[TrackState]], settings: TrackerSettings
) -> dict[int, tuple[F64, F64]]:
    """Per track id: the stamps and states of its published snapshots smoothed as the gateway
    smooths a stored trajectory (:func:`wz_shared.motion.rts_smooth`, the priors recomputed
    with the tracker's process noise): what a researcher gets from
    ``/v1/trajectories``. Unlike ``fused_smoothed`` (RTS over the tracker's own update
    history), the snapshots are 10 Hz predictions from the latest update, not every update."""
    out: dict[int, tuple[F64, F64]] = {}
    noise = process_noise(settings)
    for track_id, states in stored.items():
        stamps = np.array([s.stamp_s for s in states])
        x = np.array([[s.x_m, s.y_m, s.vx_mps, s.vy_mps] for s in states])
        P = np.array([s.P for s in states])
        x_smooth, _ = rts_smooth(stamps, x, P, noise)
        out[track_id] = (stamps, x_smooth)
    return out


def smoothed_at(
    smoothed: dict[int, tuple[F64, F64]], track_id: int, stamp_s: float
) -> tuple[float, float, float | None] | None:
    """Track ``track_id``'s smoothed position at ``stamp_s`` (its latest smoothed state
    before, carried at constant velocity) and speed, or None."""
    found = smoothed.get(track_id)
    if found is None:
        return None
    stamps, states = found
    index = int(np.searchsorted(stamps, stamp_s + 1e-9, side="right")) - 1
    if index < 0:
        return None
    x = states[index]
    dt = stamp_s - float(stamps[index])
    return (float(x[0] + x[2] * dt), float(x[1] + x[3] * dt), float(math.hypot(x[2], x[3])))


def scored_region(
    vehicles: Sequence[VehicleTruth],
    states: Sequence[TrackState],
    centre: tuple[float, float],
    max_range_m: float,
    coverage: SiteCoverage | None = None,
) -> tuple[list[VehicleTruth], list[TrackState]]:
    """The vehicles and tracks scored at one instant: those within ``max_range_m`` and, with
    ``coverage``, where a sensor of the site can see a car (:mod:`wz_shared.coverage`).

    The region's edge is a "don't care" band, as in KITTI's and MOTChallenge's ignore regions:
    a track just inside the edge whose vehicle is just outside is neither a match nor a false
    positive, and a track just outside whose vehicle is inside still matches it. So the
    vehicles and tracks within ``max_range_m + EDGE_MARGIN_M`` are paired (nearest first,
    within the MOT gate); a track paired with a vehicle outside the region is left out, as is
    an unpaired track outside it.
    """

    points = [(v.x_m, v.y_m) for v in vehicles] + [(s.x_m, s.y_m) for s in states]
    seen: set[tuple[float, float]] | None = None
    if coverage is not None and points:
        xy = np.array(points, dtype=np.float64)
        seen = {p for p, c in zip(points, coverage(xy[:, 0], xy[:, 1]), strict=True) if c}

    def inside(x_m: float, y_m: float) -> bool:
        within = math.hypot(x_m - centre[0], y_m - centre[1]) <= max_range_m
        return within and (seen is None or (x_m, y_m) in seen)

    return _region(vehicles, states, lambda v: inside(v.x_m, v.y_m), inside)


def _region(
    vehicles: Sequence[VehicleTruth],
    states: Sequence[TrackState],
    holds: Callable[[VehicleTruth], bool],
    inside: Callable[[float, float], bool],
) -> tuple[list[VehicleTruth], list[TrackState]]:
    """The vehicles a region ``holds`` and the tracks that go with them: a track paired with
    a vehicle (nearest first, within the MOT gate) goes where its vehicle is, an unpaired one
    where it is (``inside`` at its position)."""
    est = np.array([(s.x_m, s.y_m) for s in states], dtype=np.float64).reshape(-1, 2)
    tru = np.array([(v.x_m, v.y_m) for v in vehicles], dtype=np.float64).reshape(-1, 2)
    partner = {e: t for e, t in match(est, tru, MOT_GATE_M)}
    kept_states = [
        s
        for e, s in enumerate(states)
        if (holds(vehicles[partner[e]]) if e in partner else inside(s.x_m, s.y_m))
    ]
    return [v for v in vehicles if holds(v)], kept_states


def approach_region(
    site: Site,
    vehicles: Sequence[VehicleTruth],
    states: Sequence[TrackState],
    mast_station_m: float,
) -> tuple[list[VehicleTruth], list[TrackState]]:
    """Of the scored vehicles and tracks, those of the approach: upstream of the mast, where
    traffic comes from and every sensor of the trailer faces. A track paired with a vehicle
    (nearest first, within the MOT gate) goes where its vehicle is; an unpaired one where it is.
    """

    def upstream(x_m: float, y_m: float) -> bool:
        return float(site.road_frame.to_road(x_m, y_m)[0]) <= mast_station_m

    return _region(vehicles, states, lambda v: v.station_m <= mast_station_m, upstream)


def _dropout_report(
    dropout: Dropout,
    warmup_s: float,
    fused_samples: Sequence[tuple[float, float, float]],
    mot: _MotAccumulator,
    mot_times: Sequence[float],
) -> dict[str, Any]:
    """The fused track during a dropout: its errors, and identity switches from its start to
    2 s after its end (a track lost in the gap would show as a switch when taken up again)."""
    start = warmup_s + dropout.start_s
    end = start + dropout.duration_s
    inside = [(lon, lat) for t, lon, lat in fused_samples if start <= t < end]
    lon = np.array([v[0] for v in inside])
    lat = np.array([v[1] for v in inside])
    return {
        **vars(dropout),
        "fused_samples": len(inside),
        "fused_rmse_longitudinal_m": float(np.sqrt(np.mean(lon**2))) if len(lon) else None,
        "fused_rmse_lateral_m": float(np.sqrt(np.mean(lat**2))) if len(lat) else None,
        "fused_max_abs_error_m": float(np.max(np.hypot(lon, lat))) if len(lon) else None,
        "id_switches_from_start_to_2s_after": mot.switches_between(mot_times, start, end + 2.0),
    }


def _bump_report(
    bump: Bump,
    record: PipelineRecord,
    warmup_s: float,
    alerts: dict[str, dict[str, Any]],
    fused_samples: Sequence[tuple[float, float, float]],
    mot: _MotAccumulator,
    mot_times: Sequence[float],
) -> dict[str, Any]:
    """A knocked sensor (issue 39): when its self-calibration flagged it and learned it again,
    the false alerts in the minute after the knock against an undisturbed minute before it,
    and the fused track's errors and identity switches before the knock and from five
    minutes after it."""
    at = bump.at_s
    end = max((t for t, _ in record.truth), default=at)
    history = record.calibration_history.get(bump.sensor_id, [])
    flagged = next((t for t, state, _ in history if state == "bumped" and t >= at), None)
    again = (
        next((t for t, state, _ in history if state == "calibrated" and t > flagged), None)
        if flagged is not None
        else None
    )
    stamps = [t for entry in alerts.values() for t in entry.get("false_positive_stamps_s", [])]
    before_minutes = max((at - warmup_s) / 60.0, 0.0)

    def window(start: float, stop: float) -> dict[str, Any]:
        inside = [(lon, lat) for t, lon, lat in fused_samples if start <= t < stop]
        lon = np.array([v[0] for v in inside])
        lat = np.array([v[1] for v in inside])
        return {
            "from_s": round(start, 1),
            "to_s": round(stop, 1),
            "fused_samples": len(inside),
            "fused_rmse_longitudinal_m": float(np.sqrt(np.mean(lon**2))) if len(lon) else None,
            "fused_rmse_lateral_m": float(np.sqrt(np.mean(lat**2))) if len(lat) else None,
            "id_switches": mot.switches_between(mot_times, start, stop),
            "false_alerts": sum(start <= t < stop for t in stamps),
        }

    return {
        **vars(bump),
        "flagged_after_s": None if flagged is None else round(flagged - at, 2),
        "calibrated_again_after_s": None if again is None else round(again - at, 2),
        "false_alerts_minute_after": sum(at <= t < at + 60.0 for t in stamps),
        "false_alerts_per_minute_before": (
            round(sum(warmup_s <= t < at for t in stamps) / before_minutes, 2)
            if before_minutes > 0
            else None
        ),
        # Every whole undisturbed minute of the scored run, on the knock's minute grid (one
        # minute before it holds a handful of alerts: too few to compare with alone).
        "false_alerts_by_undisturbed_minute": [
            sum(start <= t < start + 60.0 for t in stamps)
            for start in _undisturbed_minutes(at, warmup_s, end)
        ],
        "before": window(warmup_s, at),
        "from_5_min_after": window(at + 300.0, end) if end > at + 300.0 else None,
    }


def _undisturbed_minutes(at_s: float, from_s: float, to_s: float) -> list[float]:
    """Starts of the whole minutes within [``from_s``, ``to_s``] before and after the minute
    from ``at_s``, on its grid."""
    before = [at_s - 60.0 * k for k in range(1, int((at_s - from_s) // 60.0) + 1)]
    after = [at_s + 60.0 * k for k in range(1, int((to_s - at_s) // 60.0))]
    return sorted(before) + after


#: Identity switches listed in the report (where each happened).
MAX_SWITCH_EVENTS = 30


class _MotAccumulator:
    """py-motmetrics over the sampled confirmed and coasting tracks."""

    def __init__(self) -> None:
        import motmetrics

        self._mm = motmetrics
        self.acc = motmetrics.MOTAccumulator(auto_id=True)
        self._numbers: dict[str, int] = {}  # motmetrics wants numeric object ids
        #: Per frame, each object's vehicle: where a switch happened.
        self._where: list[dict[int, VehicleTruth]] = []

    def switch_events(
        self, frame_times: Sequence[float], mast_station_m: float
    ) -> list[dict[str, Any]]:
        """Where and when the first :data:`MAX_SWITCH_EVENTS` identity switches happened: the
        vehicle, its station from the mast (negative upstream) and lane offset."""
        events = self.acc.mot_events
        switches = events[events.Type == "SWITCH"]
        out: list[dict[str, Any]] = []
        for (frame, _), row in switches.iterrows():
            if len(out) >= MAX_SWITCH_EVENTS:
                break
            vehicle = self._where[int(frame)][int(row.OId)]
            out.append(
                {
                    "stamp_s": round(frame_times[int(frame)], 2),
                    "vehicle_id": vehicle.vehicle_id,
                    "from_mast_m": round(vehicle.station_m - mast_station_m, 1),
                    "offset_m": round(vehicle.offset_m, 2),
                    "track_id": int(row.HId),
                }
            )
        return out

    def switches_between(self, frame_times: Sequence[float], start_s: float, end_s: float) -> int:
        """Identity switches in frames stamped within ``[start_s, end_s]``."""
        events = self.acc.mot_events
        switches = events[events.Type == "SWITCH"]
        frames = switches.index.get_level_values(0)
        return int(sum(1 for f in frames if start_s <= frame_times[int(f)] <= end_s))

    def update(self, vehicles: Sequence[VehicleTruth], states: Sequence[TrackState]) -> None:
        gt = np.array([(v.x_m, v.y_m) for v in vehicles], dtype=np.float64).reshape(-1, 2)
        hyp = np.array([(s.x_m, s.y_m) for s in states], dtype=np.float64).reshape(-1, 2)
        distances = self._mm.distances.norm2squared_matrix(gt, hyp, max_d2=MOT_GATE_M**2)
        objects = [self._numbers.setdefault(v.vehicle_id, len(self._numbers) + 1) for v in vehicles]
        self._where.append(dict(zip(objects, vehicles, strict=True)))
        self.acc.update(objects, [s.track_id for s in states], distances)

    def summary(self, _: int) -> dict[str, Any]:
        metrics = self._mm.metrics.create()
        frame = metrics.compute(
            self.acc,
            metrics=[
                "mota",
                "motp",
                "idf1",
                "num_switches",
                "num_unique_objects",
                "num_false_positives",
                "num_misses",
                "num_objects",
                "mostly_tracked",
            ],
            name="fused",
        )
        row = frame.loc["fused"]
        vehicles = int(row["num_unique_objects"])
        switches = int(row["num_switches"])
        return {
            "mota": float(row["mota"]),
            "idf1": float(row["idf1"]),
            "id_switches": switches,
            "id_switches_per_100_vehicles": 100.0 * switches / vehicles if vehicles else 0.0,
            "mot_detail": {
                "motp_m": math.sqrt(float(row["motp"])) if row["motp"] == row["motp"] else None,
                "objects": int(row["num_objects"]),
                "false_positives": int(row["num_false_positives"]),
                "misses": int(row["num_misses"]),
                "vehicles_scored": vehicles,
                "mostly_tracked": int(row["mostly_tracked"]),
            },
        }


def frame_match_tolerance_s(site: Site) -> float:
    """How far apart [s] a camera frame and a LiDAR sample may be and still be one frame: just
    under half the fastest LiDAR's period (1 ms without a LiDAR)."""
    rates = [m.rate_hz for m in site.sensors if m.kind == "lidar"]
    return 0.999 * 0.5 / max(rates) if rates else 1e-3


def _nearest_within(
    reference: npt.NDArray[np.float64], stamps: npt.NDArray[np.float64], tolerance_s: float
) -> npt.NDArray[np.intp]:
    """For each reference stamp, the index of the nearest of ``stamps`` (sorted) within
    ``tolerance_s``; -1 where none is."""
    if stamps.size == 0:
        return np.full(reference.shape, -1, dtype=np.intp)
    right = np.clip(np.searchsorted(stamps, reference), 0, stamps.size - 1)
    left = np.clip(right - 1, 0, stamps.size - 1)
    nearer = np.where(
        np.abs(stamps[left] - reference) <= np.abs(stamps[right] - reference), left, right
    )
    return np.where(np.abs(stamps[nearer] - reference) <= tolerance_s, nearer, -1)


def paper_table(
    site: Site, scores: Scores, centre: tuple[float, float], window_upstream_m: tuple[float, float]
) -> list[dict[str, Any]]:
    """Per vehicle: cumulative |error| over the window's common times, per source (Tables 1-2).

    The fused tracks, the paper's filter, the average and the camera are sampled at the camera's
    frame times; the LiDAR at its own. A LiDAR sample counts for a camera frame when it is the
    nearest within half a LiDAR period: the camera's clock, once its offset is learned (the
    self-calibration), no longer ticks on the LiDAR's grid.
    """
    mast_station = float(site.road_frame.to_road(*centre)[0])
    lo, hi = mast_station - window_upstream_m[1], mast_station - window_upstream_m[0]
    compared = ("camera", "lidar", "average", "paper_kf", "fused", "fused_smoothed", "fused_stored")
    tolerance_s = frame_match_tolerance_s(site)
    rows = []
    for vehicle_id, by_source in sorted(scores.per_vehicle.items()):
        in_window = {
            source: sorted(
                (t, errors)
                for t, errors in by_source.get(source, {}).items()
                if lo <= errors[2] <= hi
            )
            for source in compared
        }
        reference = np.array([t for t, _ in in_window["fused"]], dtype=float)
        picked: dict[str, npt.NDArray[np.intp]] = {}
        for source in compared:
            stamps = np.array([t for t, _ in in_window[source]], dtype=float)
            picked[source] = _nearest_within(reference, stamps, tolerance_s)
        common = np.all([index >= 0 for index in picked.values()], axis=0)
        if reference.size == 0 or int(common.sum()) < 5:
            continue
        row: dict[str, Any] = {"vehicle_id": vehicle_id, "samples": int(common.sum())}
        for source in compared:
            samples = [in_window[source][k][1] for k in picked[source][common]]
            row[source] = {
                "longitudinal_m": float(sum(abs(e[0]) for e in samples)),
                "lateral_m": float(sum(abs(e[1]) for e in samples)),
            }
        rows.append(row)
    return rows
