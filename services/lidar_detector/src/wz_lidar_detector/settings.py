"""Settings of the LiDAR detector service (env prefix ``WZ_LIDAR_``), units in the names.

Nested settings of the two detection cores are read with ``__`` between the levels, e.g.
``WZ_LIDAR_REFERENCE__VOXEL_SIZE_M=0.3`` or ``WZ_LIDAR_FAST__...``; a whole block may also be
given as JSON (``WZ_LIDAR_REFERENCE='{"dbscan_eps_m": 1.2}'``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from wz_lidar_detector.background import RangeBackgroundSettings
from wz_lidar_detector.calibration import LidarCalibrationSettings
from wz_lidar_detector.fast import FastSettings
from wz_lidar_detector.reference import ReferenceSettings
from wz_shared.sensor_mounts import mount_of_kind
from wz_shared.settings import ServiceSettings
from wz_shared.site import SensorMount, Site


class LidarDetectorSettings(ServiceSettings):
    """Which sensor the node serves, which detection path it runs, and the path's parameters.

    ``site_file`` (inherited) gives the sensor's pose. Build it in ``main()``; tests pass values
    as keyword arguments.
    """

    model_config = SettingsConfigDict(
        env_prefix="WZ_LIDAR_", extra="ignore", env_nested_delimiter="__"
    )

    #: The LiDAR to serve (its frames on ``raw/lidar/<id>``); default: the site's first LiDAR.
    sensor_id: str | None = None
    #: ``fast``: background model learned at start-up, then foreground clustering;
    #: ``reference``: the paper's pipeline frame by frame (no learning).
    path: Literal["fast", "reference"] = "fast"
    #: Fast path: a saved background (.npz) to load at start-up; when the file does not exist
    #: the node learns one and saves it there. None: learn at every start.
    background_file: Path | None = None
    #: Fast path: frames to learn the background from before detecting [frames].
    learn_frames: Annotated[int, Field(ge=1, le=10_000)] = 20
    #: Fast path, organized frames: after the quick learning, go on learning for this long
    #: [s] and then replace the background (0: do not). It must span several periods of a
    #: mast's sway (1-4 s); see :meth:`BackgroundLearner.refine`.
    refine_span_s: Annotated[float, Field(ge=0.0, le=3600.0)] = 20.0
    #: Frames sampled, evenly in time, over ``refine_span_s``.
    refine_frames: Annotated[int, Field(ge=1, le=255)] = 100
    #: Fast path, organized frames: the per-slot range background's parameters.
    range_background: RangeBackgroundSettings = Field(default_factory=RangeBackgroundSettings)
    #: Fast path, unorganized frames and background clouds: voxel edge of the occupancy
    #: background [m], and the fraction of the learning frames a voxel must be occupied in.
    voxel_m: Annotated[float, Field(gt=0.0)] = 0.5
    voxel_min_occupancy_fraction: Annotated[float, Field(gt=0.0, le=1.0)] = 0.5
    #: A point farther than this from the sensor on any axis is a corrupt return [m]; it is
    #: dropped (set to no return) and the frame counted under ``absurd_coordinates``.
    max_abs_coordinate_m: Annotated[float, Field(gt=0.0)] = 1.0e4
    #: Std added along a box's length when the vehicle is nearer than the lowest beam can see
    #: it whole (under the mast: the box slides along the vehicle) [m].
    near_field_std_m: Annotated[float, Field(ge=0.0)] = 1.5
    #: ... and across it [m].
    near_field_across_std_m: Annotated[float, Field(ge=0.0)] = 1.0
    reference: ReferenceSettings = Field(default_factory=ReferenceSettings)
    #: The sensor's pose learned from the road and its traffic (issue 39), on by default.
    calibration: LidarCalibrationSettings = Field(default_factory=LidarCalibrationSettings)
    fast: FastSettings = Field(default_factory=FastSettings)


def lidar_mount(site: Site, sensor_id: str | None) -> SensorMount:
    """The mount of ``sensor_id`` (default: the site's first LiDAR).

    Raises
    ------
    ValueError
        When the site has no such sensor, or it is not a LiDAR, in words for the operator.
    """
    return mount_of_kind(site, sensor_id, "lidar", "WZ_LIDAR_SENSOR_ID", kind_name="LiDAR")
