"""The fusion tracker's settings: the tracker core's (:class:`TrackerSettings`) and the node's
(:class:`FusionTrackerSettings`, env prefix ``WZ_FUSION_``, the core's under
``WZ_FUSION_TRACKER__*``). Metres, seconds and radians of the site frame.

Each field says why it has its value in one line; the measurements behind the values are in
``docs/fusion-tracker.md``, "How the settings were chosen" (one link per group below).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_settings import SettingsConfigDict

from wz_shared.motion import ProcessNoise
from wz_shared.settings import ServiceSettings

#: The motion model's process noise is defined once, in :class:`wz_shared.motion.ProcessNoise`.
_NOISE = ProcessNoise()


class TrackerSettings(BaseModel):
    """Parameters of :class:`~wz_fusion_tracker.tracker.MultiTargetTracker`."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- motion model: docs/fusion-tracker.md#settings-motion-model ---
    #: Acceleration std along travel [m/s^2]: follows drivers braking hard at the closure.
    sigma_along_mps2: float = Field(default=_NOISE.sigma_along_mps2, gt=0.0)
    #: Acceleration std across travel [m/s^2]: lets a track follow a late, sharp merge.
    sigma_across_mps2: float = Field(default=_NOISE.sigma_across_mps2, gt=0.0)
    #: Largest change of velocity across the road the process noise allows over one
    #: prediction, however long [m/s]: about a lane change's peak sideways speed. The
    #: acceleration across is held for a whole prediction step, so over a track's second of
    #: coasting ``sigma_across`` alone let it move 1.5 m across (1 sigma) and take a car one
    #: lane over; with this, ``sigma_across`` is ``min(sigma_across, this / dt)`` (unchanged
    #: up to a third of a second). 0 turns it off.
    max_across_speed_change_mps: float = Field(default=1.0, ge=0.0)
    #: "cv" (one model) or "imm" (steady + manoeuvre, :mod:`wz_fusion_tracker.imm`); the IMM
    #: cut the speed error but cost identity switches, so "cv".
    motion_model: Literal["cv", "imm"] = "cv"
    #: IMM steady mode's acceleration std along the road [m/s^2]: lane keeping.
    imm_steady_sigma_along_mps2: float = Field(default=0.5, gt=0.0)
    #: ... and across it [m/s^2].
    imm_steady_sigma_across_mps2: float = Field(default=0.3, gt=0.0)
    #: IMM: mean time a vehicle stays steady before it manoeuvres [s].
    imm_steady_sojourn_s: float = Field(default=10.0, gt=0.0)
    #: IMM: mean time a manoeuvre lasts [s].
    imm_manoeuvre_sojourn_s: float = Field(default=2.0, gt=0.0)
    #: Without a road heading, below this speed a track's own heading is not trusted and its
    #: process noise is isotropic (``sigma_along`` both ways) [m/s].
    heading_min_speed_mps: float = Field(default=_NOISE.heading_min_speed_mps, ge=0.0)

    # --- association: docs/fusion-tracker.md#settings-association ---
    #: Pairs with a larger squared Mahalanobis distance are never associated: chi-square
    #: 99.9 %, 2 dof [-].
    gate_chi2: float = Field(default=13.8, gt=0.0)
    #: Cost reduction [-2 ln likelihood] where the sensor's own local track id continues the
    #: track: likelihood ratio e^2 = 7.4, breaks near-ties only.
    local_track_id_bonus: float = Field(default=4.0, ge=0.0)
    #: Huber threshold [sigmas]: a heavy-tailed outlier moves a track by about this much;
    #: 0 turns it off.
    huber_k: float = Field(default=2.5, ge=0.0)

    # --- channels ---
    #: Sensor ids whose unmatched detections start tracks; None: every sensor.
    track_start_sensor_ids: tuple[str, ...] | None = None

    # --- life cycle: docs/fusion-tracker.md#settings-life-cycle ---
    #: Updates (the first included) within ``confirm_window_s`` that confirm a track.
    confirm_hits: int = Field(default=5, ge=1)
    #: Window over which ``confirm_hits`` are counted [s].
    confirm_window_s: float = Field(default=1.0, gt=0.0)
    #: Earliest confirmation after the first detection [s]: 3 hits in 50 ms cannot tell a
    #: vehicle from a burst of noise.
    confirm_min_age_s: float = Field(default=0.2, ge=0.0)
    #: A tentative track not updated for longer than this is deleted [s].
    tentative_max_age_s: float = Field(default=0.5, gt=0.0)
    #: A confirmed track not updated for longer than this reports "coasting" [s].
    coasting_after_s: float = Field(default=0.3, ge=0.0)
    #: A confirmed track not updated for longer than this is deleted [s].
    max_coast_s: float = Field(default=1.5, gt=0.0)
    #: ... unless a sensor that saw it has gone silent (an outage, not a vehicle gone): then
    #: it coasts up to this [s].
    max_outage_coast_s: float = Field(default=5.0, gt=0.0)
    #: Coast confirmed tracks across stretches no sensor sees (the mast's blind cone; the
    #: tracker's ``in_sensor_gap``) instead of ending them. Off: on generated site 9600 it
    #: made things worse (MOTA 0.862 -> 0.815): a track coasting at a speed 1.5 m/s low and
    #: with the lateral velocity of the taper's merge drifts a lane over in 1.5 s, and its
    #: widened gate then takes another vehicle (docs/fusion-tracker.md).
    coast_sensor_gaps: bool = False
    #: ... and then up to this [s]: an 80 m gap at 20 m/s.
    max_gap_coast_s: float = Field(default=4.0, gt=0.0)
    #: A sensor with no batch for this long is silent [s].
    sensor_silent_after_s: float = Field(default=0.5, gt=0.0)
    #: A deleted confirmed track stays *lost* this long [s], so a vehicle hidden behind a truck
    #: gets its old id back (see ``hand_over_*``); 0 turns it off.
    lost_memory_s: float = Field(default=3.0, ge=0.0)
    #: A lost track predicted (along the road, at its speed) in a stretch no sensor sees is
    #: remembered until ``lost_memory_s`` after it has left it, up to this long in all [s]
    #: (the tracker's ``in_sensor_gap``): a vehicle crossing a mast's blind cone, 50 m at
    #: 11 m/s, is out of sight 4.5 s and comes back as a young track the hand-over gives its
    #: old id. 0 turns it off. Not published and taking no measurement, unlike
    #: ``coast_sensor_gaps``.
    max_gap_memory_s: float = Field(default=12.0, ge=0.0)
    #: A confirmed track not updated for ``max_coast_s`` whose predicted position other
    #: tracked vehicles hide from every sensor that covers it (a car beside or behind a truck:
    #: sight lines through their boxes, the tracker's ``hidden_from_sensors``) coasts up to
    #: this [s]; 0 turns it off.
    max_occlusion_coast_s: float = Field(default=0.0, ge=0.0)
    #: A lost track still hidden so is remembered up to this long [s], for the hand-over when
    #: the vehicle shows again; 0 turns it off.
    max_occlusion_memory_s: float = Field(default=0.0, ge=0.0)

    # --- timing ---
    #: Batches are held this long behind the newest stamp seen, then processed in order [s].
    reorder_window_s: float = Field(default=0.15, ge=0.0)
    #: A sensor is a track's source in a snapshot if it updated it within this before it [s].
    sources_window_s: float = Field(default=0.25, ge=0.0)

    # --- identity: docs/fusion-tracker.md#settings-identity ---
    #: A confirmed track not updated for this long may be re-acquired outside its gate [s].
    reacquire_after_s: float = Field(default=0.2, ge=0.0)
    #: Re-acquisition reach along the track [m]: a following car is at least ~6 m behind;
    #: 0 turns it off.
    reacquire_along_m: float = Field(default=4.0, ge=0.0)
    #: Re-acquisition reach across the track [m]: the next lane is 3.6 m over.
    reacquire_across_m: float = Field(default=1.2, ge=0.0)
    #: A re-acquired track's velocity may change by what this acceleration over its gap
    #: explains, not more [m/s^2] (a car's hardest braking on a dry road); 0: by the whole
    #: innovation over the gap.
    reacquire_max_accel_mps2: float = Field(default=8.0, ge=0.0)
    #: A track younger than this may hand its vehicle back to a coasting or lost one [s];
    #: 0 turns it off.
    hand_over_age_s: float = Field(default=1.0, ge=0.0)
    #: Hand-over reach along the road [m]; 0 turns the hand-over off.
    hand_over_along_m: float = Field(default=10.0, ge=0.0)
    #: Hand-over reach across the road [m]: one lane (3.6 m) over, for a merge while unseen.
    hand_over_across_m: float = Field(default=4.5, ge=0.0)
    #: Largest change of speed while unseen that may explain a young track's speed and place
    #: [m/s^2]: a car that braked behind a truck; 0 turns it off.
    hand_over_max_accel_mps2: float = Field(default=4.0, ge=0.0)
    #: Slack on that kinematic test's displacement [m].
    hand_over_kinematic_slack_m: float = Field(default=2.0, ge=0.0)
    #: A young track's velocity is alike within ``merge_velocity_difference_mps`` plus this
    #: many of its own standard deviations: a LiDAR that first sees a vehicle coming out of
    #: its blind cone places the part it sees, growing, and the young track starts at half
    #: the speed, with a std of 5-6 m/s that says so. 0: the tolerance alone.
    hand_over_velocity_sigmas: float = Field(default=2.0, ge=0.0)
    #: At a hand-over, the old track's speed along the road, predicted over its gap with the
    #: process noise, is fused with the young track's by their variances, the young track's
    #: birth prior (``initial_speed_mps``) taken out: a LiDAR's first boxes of a vehicle
    #: coming out of its blind cone tell little of its speed, and the young track's is mostly
    #: that prior. False: the old track takes the young one's state as it is.
    hand_over_fuses_speed: bool = True
    #: An old track sliding across the road faster than this follows no vehicle and is not
    #: handed one [m/s]: a lane change peaks at 1-1.5 m/s.
    hand_over_max_lateral_speed_mps: float = Field(default=2.5, gt=0.0)
    #: A box this much shorter or longer than its track is re-centred with the track's length
    #: (a LiDAR completing a semitrailer seen end-on as a car) [m]; 0 turns it off.
    reference_point_min_m: float = Field(default=1.5, ge=0.0)
    #: An unmatched measurement this near a confirmed track [squared Mahalanobis] is its
    #: outlier and starts no track: the next lane is about 11 sigma away.
    spawn_gate_chi2: float = Field(default=60.0, ge=0.0)
    #: An unmatched measurement less well located than this (largest std of R) starts no
    #: track [m]: a camera alone ranges the horizon tens of metres off; 0 turns it off.
    spawn_max_std_m: float = Field(default=4.0, ge=0.0)
    #: Two tracks closer than this, moving alike, are one vehicle: the younger is deleted [m];
    #: adjacent lanes are 3.6 m apart. 0 turns merging off.
    merge_distance_m: float = Field(default=2.5, ge=0.0)
    #: ... and their velocities differ by less than this [m/s].
    merge_velocity_difference_mps: float = Field(default=4.0, gt=0.0)
    #: A young track inside a tracked truck's or bus's footprint grown by this all round,
    #: moving alike, is part of it and is deleted [m]; negative turns it off.
    truck_merge_margin_m: float = -1.0

    # --- initialisation ---
    #: Std of a new track's unknown velocity (along the road, with a road prior) [m/s].
    initial_velocity_std_mps: float = Field(default=15.0, gt=0.0)
    #: With a road heading hook: std of a new track's velocity across the road [m/s].
    initial_across_velocity_std_mps: float = Field(default=2.0, gt=0.0)
    #: With a road heading hook and no radar speed: a new track's speed along the road [m/s].
    initial_speed_mps: float = 0.0

    # --- radar speed: docs/fusion-tracker.md#settings-radar-speed ---
    #: Use a detection's ``speed_mps`` when a road heading hook is given.
    use_speed_measurements: bool = True
    #: Std of a radar speed along the road [m/s].
    speed_std_mps: float = Field(default=0.5, gt=0.0)
    #: A radar speed beyond this squared normalised innovation is not used (chi-square
    #: 99.9 %, 1 dof): a wrong echo once dragged a track by 9 m/s [-].
    speed_gate_chi2: float = Field(default=10.8, gt=0.0)
    #: A pair whose radar speed is beyond this of the track's is forbidden (about 4 m/s for a
    #: settled track; loose, for braking tracks lag): a speeder in the next lane [-]; 0: off.
    speed_association_chi2: float = Field(default=50.0, ge=0.0)

    # --- bookkeeping ---
    #: Measured lengths and widths kept per track for their running median.
    size_window: int = Field(default=50, ge=1)
    #: Updates kept per track for smoothing (the oldest are dropped).
    max_history: int = Field(default=2000, ge=1)
    #: Histories of deleted confirmed tracks kept until popped (the oldest are dropped).
    max_finished_histories: int = Field(default=1000, ge=0)

    @model_validator(mode="after")
    def _check_life_cycle(self) -> TrackerSettings:
        if self.coasting_after_s >= self.max_coast_s:
            raise ValueError(
                f"coasting_after_s ({self.coasting_after_s}) must be below max_coast_s "
                f"({self.max_coast_s}): a track coasts before it is deleted"
            )
        return self

    def may_start_tracks(self, sensor_id: str) -> bool:
        """Whether unmatched detections of ``sensor_id`` start tracks."""
        return self.track_start_sensor_ids is None or sensor_id in self.track_start_sensor_ids


class FusionTrackerSettings(ServiceSettings):
    """The node's settings; the tracker's own under ``tracker`` (``WZ_FUSION_TRACKER__*``)."""

    model_config = SettingsConfigDict(
        env_prefix="WZ_FUSION_", extra="ignore", env_nested_delimiter="__"
    )

    #: Data time between two published track batches [s].
    output_period_s: Annotated[float, Field(gt=0.0, le=10.0)] = 0.1
    #: Publish tentative tracks too (default: confirmed and coasting only).
    publish_tentative: bool = False
    #: With no batch for this long (wall time), the tracker's clock moves on by itself [s].
    idle_advance_after_s: Annotated[float, Field(gt=0.0)] = 0.5
    #: A bias map (:mod:`wz_fusion_tracker.calibration`, JSON) of this site: each sensor's
    #: calibrated lateral bias is removed from its detections. None: none removed.
    bias_map: Path | None = None
    tracker: TrackerSettings = Field(default_factory=TrackerSettings)
