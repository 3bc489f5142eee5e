"""The fusion tracker node: every sensor's detections in, fused tracks out.

Run it as ``python -m wz_fusion_tracker.node`` (settings: ``WZ_FUSION_*``, bus ``WZ_BUS_*``). It

- takes :class:`DetectionBatch` messages from ``wz/<site>/detections/*`` (a FIFO: every batch
  counts) and gives each to the :class:`MultiTargetTracker` as the sensor's measurements at the
  batch's stamp (the tracker orders them within its reorder window, so asynchronous sensors
  and slightly late messages are fine);
- each cycle (``output_period_s`` of data time, 10 Hz by default) publishes a
  :class:`TrackBatch` on ``wz/<site>/tracks``: the confirmed and coasting tracks predicted to the
  stamp of the newest measurement processed (the first one at or after the cycle's time on the
  period's grid; the tracker never predicts backwards), with the road frame's station, offset and lane, speed and heading, class and
  size, contributing sensors, age and status, and the process noise the tracker predicted with
  (:func:`process_noise`, for the gateway's smoother); and answers ``wz/<site>/tracks/latest`` queries
  with the newest batch;
- when no detections arrive at all (every sensor silent), moves the tracker's clock on by the
  wall time elapsed since the last batch, so coasting tracks end rather than hang (data time
  follows wall time there; with a simulator faster than real time this is conservative);
- when a sensor's own stamps go back for good (:class:`~wz_shared.timebase.RunWatch`: a
  restarted simulation counts from its start again), starts a new run: a fresh tracker whose
  ids go on from the old one's (ids are never reused), the output grid and the clock taken
  from the new stamps. Without it every batch of the new run would be dropped as late until
  its stamps passed the old run's. The batches before the new run is certain are late.

With ``WZ_FUSION_BIAS_MAP=FILE`` (a bias map of the site, :mod:`wz_fusion_tracker.calibration`)
each sensor's calibrated lateral bias is removed from its detections before the tracker takes
them; a map that cannot be read or is another site's stops the start with what is wrong.

Bad input never stops it; each problem is counted in the status message's ``invalid_counts``
under ``<detections key>|<reason>``: ``wrong_site``, ``late`` (a batch older than the reorder
window: dropped by the tracker). A batch with a covariance that is not symmetric positive
definite does not decode (``Covariance2``): the bus counts it ``invalid``.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

import numpy as np

from wz_fusion_tracker.calibration import BiasMapError, LateralBiasCorrector, load_bias_map
from wz_fusion_tracker.life_cycle import HiddenFromSensors
from wz_fusion_tracker.settings import FusionTrackerSettings, TrackerSettings
from wz_fusion_tracker.tracker import MultiTargetTracker
from wz_fusion_tracker.types import Measurement, TrackState
from wz_shared.arrays import F64
from wz_shared.codec import encode_json
from wz_shared.coverage import SensorGaps, SiteSight
from wz_shared.messages import (
    DetectionBatch,
    Track,
    TrackBatch,
    TrackStatus,
    VehicleClass,
)
from wz_shared.motion import ProcessNoise
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.site import Site
from wz_shared.timebase import RunWatch, SimClock

SERVICE = "fusion-tracker"
log = logging.getLogger("wz_fusion_tracker.node")
Report = Callable[[str, str], None]


def road_heading_hook(site: Site) -> Callable[[float, float], float]:
    """``heading_at(x, y)``: the direction of travel at the point's station [rad]."""
    return site.road_frame.heading_at_point


def road_headings_hook(site: Site) -> Callable[[F64, F64], F64]:
    """``headings_at(xs, ys)``: :func:`road_heading_hook` for arrays of site points [rad]."""
    frame = site.road_frame

    def headings_at(x_m: F64, y_m: F64) -> F64:
        stations, _ = frame.to_road(x_m, y_m)
        return np.asarray(frame.heading_at(stations), dtype=np.float64).reshape(-1)

    return headings_at


def sensor_gaps_hook(site: Site, settings: TrackerSettings) -> SensorGaps | None:
    """The tracker's ``in_sensor_gap``: the site's :class:`SensorGaps` when
    ``coast_sensor_gaps`` or ``max_gap_memory_s`` uses it; None otherwise (nothing to
    build)."""
    wanted = settings.coast_sensor_gaps or settings.max_gap_memory_s > 0.0
    return SensorGaps(site) if wanted else None


def sight_hook(site: Site, settings: TrackerSettings) -> HiddenFromSensors | None:
    """The tracker's ``hidden_from_sensors``: the site's sensors' sight lines through other
    vehicles (:class:`SiteSight`) when ``max_occlusion_coast_s`` or ``max_occlusion_memory_s``
    uses it; None otherwise."""
    if settings.max_occlusion_coast_s <= 0.0 and settings.max_occlusion_memory_s <= 0.0:
        return None
    return SiteSight(site).hidden


def sensor_positions(site: Site) -> dict[str, tuple[float, float]]:
    """Each sensor's site position ``(x_m, y_m)``, for the tracker's reference points."""
    return {mount.sensor_id: (mount.pose.x_m, mount.pose.y_m) for mount in site.sensors}


def to_measurements(
    batch: DetectionBatch, bias: LateralBiasCorrector | None = None
) -> list[Measurement]:
    """The batch's detections as tracker measurements; with ``bias``, each sensor's calibrated
    lateral bias removed. Every covariance is symmetric positive definite already: the message
    schema (:data:`wz_shared.messages.Covariance2`) refuses a batch with one that is not."""
    out = []
    for detection in batch.detections:
        covariance = np.asarray(detection.covariance_m2, dtype=np.float64).reshape(2, 2)
        out.append(
            Measurement(
                x_m=detection.x_m,
                y_m=detection.y_m,
                covariance_m2=covariance,
                sensor_id=batch.source_id,
                object_class=detection.object_class.value,
                score=detection.score,
                length_m=detection.length_m,
                width_m=detection.width_m,
                speed_mps=detection.speed_mps,
                local_track_id=detection.local_track_id,
                time_offset_s=detection.time_offset_s or 0.0,
                completed_from_far_end=detection.completed_from_far_end,
            )
        )
    return out if bias is None else bias.correct(batch.source_id, out)


def bias_corrector(site: Site, settings: FusionTrackerSettings) -> LateralBiasCorrector | None:
    """The corrector of ``settings.bias_map`` (read once); None without a map. A map that
    cannot be used raises :class:`~wz_fusion_tracker.calibration.BiasMapError`."""
    if settings.bias_map is None:
        return None
    bias = LateralBiasCorrector(site, load_bias_map(settings.bias_map, site))
    log.info(
        "lateral bias map %s: corrects %s",
        settings.bias_map,
        ", ".join(bias.sensors()) or "no sensor of this site",
    )
    return bias


def process_noise(settings: TrackerSettings) -> ProcessNoise:
    """The process noise the tracker predicts with (its manoeuvre mode's, with the IMM), as its
    track batches carry it to whoever smooths them."""
    return ProcessNoise(
        settings.sigma_along_mps2, settings.sigma_across_mps2, settings.heading_min_speed_mps
    )


def to_track(site: Site, state: TrackState) -> Track:
    """A tracker snapshot as a bus message, with its road-frame position and lane."""
    station, offset = site.road_frame.to_road(state.x_m, state.y_m)
    lane = int(np.asarray(site.lane_index_at(offset)).reshape(-1)[0])
    try:
        object_class = VehicleClass(state.object_class)
    except ValueError:
        object_class = VehicleClass.UNKNOWN
    covariance = 0.5 * (state.P + state.P.T)
    return Track(
        track_id=state.track_id,
        x_m=state.x_m,
        y_m=state.y_m,
        vx_mps=state.vx_mps,
        vy_mps=state.vy_mps,
        covariance=[float(v) for v in covariance.reshape(-1)],
        station_m=float(station),
        offset_m=float(offset),
        speed_mps=state.speed_mps,
        heading_rad=state.heading_rad,
        lane_index=max(lane, -1),
        object_class=object_class,
        age_s=max(0.0, state.age_s),
        hits=state.hits,
        confirmed=state.status != "tentative",
        sources=list(state.sources),
        status=TrackStatus(state.status),
        length_m=state.length_m or None,
        width_m=state.width_m or None,
        last_update_s=state.stamp_s - state.time_since_update_s,
    )


class FusionCore:
    """What the node does without the bus: batches in, a track batch per output cycle out."""

    def __init__(
        self,
        site: Site,
        settings: FusionTrackerSettings,
        report: Report,
        bias: LateralBiasCorrector | None = None,
    ) -> None:
        self.site = site
        self.settings = settings
        self.report = report
        #: Removes each sensor's calibrated lateral bias: ``bias`` when given (the node's,
        #: read at start), else read from ``settings.bias_map``; None: none removed.
        self.bias = bias if bias is not None else bias_corrector(site, settings)
        #: The stretches no sensor sees between seen road, where tracks coast across.
        self.sensor_gaps = sensor_gaps_hook(site, settings.tracker)
        self.hidden_from_sensors = sight_hook(site, settings.tracker)
        self.tracker = self._new_tracker(first_track_id=1)
        self._process_noise = process_noise(settings.tracker)
        self._next_output_s: float | None = None
        self._cycle = 0
        #: Runs seen: 1, then one more each time a sensor's stamps go back (see the module).
        self.runs = 1
        self._runs_by_sensor: dict[str, RunWatch] = {}

    def _new_tracker(self, first_track_id: int) -> MultiTargetTracker:
        site = self.site
        return MultiTargetTracker(
            self.settings.tracker,
            heading_at=road_heading_hook(site),
            sensor_positions=sensor_positions(site),
            headings_at=road_headings_hook(site),
            first_track_id=first_track_id,
            in_sensor_gap=self.sensor_gaps,
            hidden_from_sensors=self.hidden_from_sensors,
        )

    def _start_new_run(self, batch: DetectionBatch) -> None:
        log.warning(
            "%s's stamps went back to %.3f s: a new run (a restarted simulation); the tracker "
            "starts again, track ids from %d",
            batch.source_id,
            batch.stamp,
            self.tracker.next_track_id,
        )
        self.tracker = self._new_tracker(first_track_id=self.tracker.next_track_id)
        self._next_output_s = None
        # The other sensors' stamps are the old run's until they go back too.
        self._runs_by_sensor = {batch.source_id: self._runs_by_sensor[batch.source_id]}
        self.runs += 1

    def add(self, batch: DetectionBatch) -> list[TrackBatch]:
        """Give one batch to the tracker; the track batches of the cycles now complete."""
        if batch.site != self.site.site_id:
            self.report("wrong_site", f"batch of site {batch.site} from {batch.source_id}")
            return []
        watch = self._runs_by_sensor.setdefault(batch.source_id, RunWatch())
        if watch.observe(batch.stamp) == "new_run":
            self._start_new_run(batch)
        late_before = self.tracker.counters.batches_late
        self.tracker.add(batch.source_id, batch.stamp, to_measurements(batch, self.bias))
        if self.tracker.counters.batches_late > late_before:
            self.report("late", f"{batch.source_id} batch at {batch.stamp:.3f} s is too late")
        return self._outputs()

    def advance_to(self, stamp_s: float) -> list[TrackBatch]:
        """No batch came: the time is ``stamp_s`` anyway."""
        self.tracker.advance_to(stamp_s)
        return self._outputs()

    def _outputs(self) -> list[TrackBatch]:
        processed_s = self.tracker.last_processed_stamp_s
        if processed_s is None or not math.isfinite(processed_s):
            return []
        period = self.settings.output_period_s
        if self._next_output_s is None:
            self._next_output_s = math.ceil(processed_s / period) * period
        if processed_s + 1e-9 < self._next_output_s:
            return []
        # One batch as of the newest processed measurement (the tracker does not predict
        # backwards), then the next cycle on the period's grid.
        self._next_output_s = (math.floor(processed_s / period + 1e-9) + 1) * period
        return [self.snapshot(processed_s)]

    def snapshot(self, stamp_s: float) -> TrackBatch:
        states = self.tracker.tracks(stamp_s)
        if not self.settings.publish_tentative:
            states = [s for s in states if s.status != "tentative"]
        batch = TrackBatch(
            site=self.site.site_id,
            source_id=SERVICE,
            stamp=stamp_s,
            cycle_index=self._cycle,
            tracks=[to_track(self.site, s) for s in states],
            process_noise=self._process_noise,
        )
        self._cycle += 1
        return batch


def run(
    runtime: ServiceRuntime,
    site: Site,
    settings: FusionTrackerSettings,
    clock: SimClock,
    bias: LateralBiasCorrector | None = None,
) -> int:
    """Track until ``runtime.stop``; the number of track batches published."""
    bus = runtime.bus
    detections_key = bus.keys.detections_all

    def report(reason: str, detail: str) -> None:
        bus.stats.count_invalid(detections_key, reason, detail)

    core = FusionCore(site, settings, report, bias)
    batches = bus.subscribe(detections_key, DetectionBatch)
    publisher = bus.publisher(bus.keys.tracks, TrackBatch)
    latest: list[bytes] = []
    bus.serve(bus.keys.tracks_latest, lambda: latest[-1] if latest else None)
    log.info("tracking %s -> %s", detections_key, bus.keys.tracks)
    published = 0
    last_batch_wall = time.monotonic()
    last_data_s: float | None = None
    runs = core.runs
    clock_restarts = False
    while not runtime.stop.is_set():
        batch = batches.recv(0.1)
        runtime.beat(processed=batch is not None)
        now = time.monotonic()
        if batch is not None:
            outputs = core.add(batch)
            if core.runs != runs:  # a new run: its time starts again, at its first output
                runs, last_data_s, clock_restarts = core.runs, None, True
            last_batch_wall, last_data_s = now, max(last_data_s or batch.stamp, batch.stamp)
        elif last_data_s is not None and now - last_batch_wall > settings.idle_advance_after_s:
            outputs = core.advance_to(last_data_s + (now - last_batch_wall))
        else:
            outputs = []
        for output in outputs:
            publisher.put(output)
            latest[:] = [encode_json(output)]
            if clock_restarts:
                clock.restart(output.stamp)
                clock_restarts = False
            else:
                clock.advance_to(output.stamp)
            published += 1
    return published


def main() -> None:
    node = NodeApp(SERVICE, FusionTrackerSettings)
    site = node.load_site()
    with node.fatal(BiasMapError):  # a bad map stops the start, with what is wrong
        bias = bias_corrector(site, node.settings)
    published = node.serve(lambda runtime: run(runtime, site, node.settings, node.clock, bias))
    log.info("stopped after %d track batches", published)


if __name__ == "__main__":
    main()
