"""Settings of the simulator service (env prefix ``WZ_SIM_``), units in the names."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, model_validator
from pydantic_settings import SettingsConfigDict

from wz_shared.settings import ServiceSettings


def _default_work_dir() -> Path:
    return Path(tempfile.gettempdir()) / "wz-simulator"


class SimulatorSettings(ServiceSettings):
    """What the simulator runs: site, seed, step, traffic demand, pacing and duration.

    ``site_file`` (inherited) defaults to the shared default site. Build it in ``main()``; tests
    pass values as keyword arguments.
    """

    model_config = SettingsConfigDict(env_prefix="WZ_SIM_", extra="ignore")

    #: Seed of SUMO and of the demand generator.
    seed: int = 42
    #: Simulation step, the truth rate's period [s] (0.05 s = 20 Hz).
    step_s: Annotated[float, Field(gt=0.0, le=1.0)] = 0.05
    #: Arrival flow over all lanes [veh/h].
    vehicles_per_hour: Annotated[float, Field(gt=0.0, le=10000.0)] = 1400.0
    #: Demand as a share of the closure's capacity (:func:`wz_shared.capacity.
    #: closure_capacity_vph`, HCM's work-zone lanes with this truck share): 0.5-0.85 flows
    #: freely, 1.05-1.3 queues. Set, it replaces ``vehicles_per_hour`` [-].
    demand_ratio: Annotated[float, Field(gt=0.0, le=3.0)] | None = None
    #: ``steady``: the flow throughout. ``ramp``: ``ramp_base_ratio`` of capacity, then up to
    #: the flow over ``ramp_rise_s`` from ``ramp_start_s``, held ``ramp_hold_s``, down over
    #: ``ramp_fall_s`` and the base after: a queue forms and dissolves.
    demand_profile: Literal["steady", "ramp"] = "steady"
    ramp_base_ratio: Annotated[float, Field(gt=0.0, le=3.0)] = 0.6
    ramp_start_s: Annotated[float, Field(ge=0.0)] = 60.0
    ramp_rise_s: Annotated[float, Field(gt=0.0)] = 30.0
    ramp_hold_s: Annotated[float, Field(ge=0.0)] = 120.0
    ramp_fall_s: Annotated[float, Field(gt=0.0)] = 30.0
    #: Drivers keep work-zone headways from the taper on: each adds the same time headway
    #: (:func:`~wz_simulator.traffic.demand.work_zone_tau_increase`) so that the open lanes
    #: carry HCM's work-zone capacity. Off: open-road headways through the zone (some 2300
    #: veh/h a lane, so a lane drop hardly ever queues). ``wz eval`` turns it on with
    #: ``--demand-ratio``.
    work_zone_headways: bool = False
    #: Fraction of semi-trailer trucks [-].
    truck_share: Annotated[float, Field(ge=0.0, le=1.0)] = 0.15
    #: Fraction of aggressive drivers [-].
    aggressive_share: Annotated[float, Field(ge=0.0, le=1.0)] = 0.15
    #: Simulated seconds per wall-clock second; 1.0 = real time, 0 = as fast as possible.
    realtime_factor: Annotated[float, Field(ge=0.0)] = 1.0
    #: Simulated time to run [s]; 0 = forever.
    duration_s: Annotated[float, Field(ge=0.0)] = 0.0
    #: The node first simulates this long as fast as it can, publishing nothing, sensors off,
    #: so that it starts (and restarts) on a road in steady traffic rather than an empty one
    #: [s]; stamps then start here and it counts toward ``duration_s``. 0 = start on an empty
    #: road. ``wz up`` sets 60 (the road's 1.8 km at 70 mph take about a minute).
    warmup_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 0.0
    #: Lane changes move sideways at each vehicle type's lateral speed (about 3.7 s for a
    #: normal car, 2 s for an aggressive one); False = SUMO's instantaneous jump to the lane.
    continuous_lane_changes: bool = True
    #: A vehicle blocked this long is teleported (and counted) [s]; 0 = never.
    teleport_after_s: Annotated[float, Field(ge=0.0)] = 120.0
    #: Simulate and publish the site's sensors (LiDAR, camera, radar); off: truth only.
    sensors_enabled: bool = True
    #: Weather preset of the sensor models: day, dusk, rain or fog.
    weather: Literal["day", "dusk", "rain", "fog"] = "day"
    #: JPEG quality of published camera frames (1-100).
    jpeg_quality: Annotated[int, Field(ge=1, le=100)] = 90
    #: Folder for the SUMO network cache and route files.
    work_dir: Path = Field(default_factory=_default_work_dir)
    #: A real mast (:mod:`wz_simulator.sensors.mast`): each sensor rendered from its true pose
    #: (set-up error, sway, settling) with its own late clock, drawn from ``seed``; the bus
    #: still carries the site file's poses. False: every sensor exactly where the site says.
    mount_errors: bool = False
    #: Knock this sensor round its mast at ``bump_at_s`` (needs ``mount_errors``); None: no bump.
    bump_sensor: str | None = None
    #: Simulation time of the bump [s] (stamps; the warm-up counts).
    bump_at_s: Annotated[float, Field(ge=0.0)] | None = None
    #: Yaw of the bump [deg] (counter-clockwise seen from above).
    bump_yaw_deg: Annotated[float, Field(ge=-45.0, le=45.0)] = 2.0

    @model_validator(mode="after")
    def _bump_needs_the_mast(self) -> SimulatorSettings:
        if self.bump_sensor is not None and not self.mount_errors:
            raise ValueError("WZ_SIM_BUMP_SENSOR needs WZ_SIM_MOUNT_ERRORS=true (the mast model)")
        if (self.bump_sensor is None) != (self.bump_at_s is None):
            raise ValueError("set WZ_SIM_BUMP_SENSOR and WZ_SIM_BUMP_AT_S together, or neither")
        return self
