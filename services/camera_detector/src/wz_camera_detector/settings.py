"""Settings of the camera-radar detector service (env prefix ``WZ_CAMERA_``), units in the names.

Nested blocks are read with ``__`` between the levels, e.g.
``WZ_CAMERA_BACKGROUND__MIN_BLOB_AREA_PX=16`` or ``WZ_CAMERA_TRACKER__MIN_HITS=1``; a whole
block may also be given as JSON (``WZ_CAMERA_ASSOCIATION='{"gate_chi2": 9.21}'``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from wz_camera_detector.association import AssociationSettings
from wz_camera_detector.background import BackgroundSubtractionSettings
from wz_camera_detector.calibration import SensorCalibrationSettings
from wz_camera_detector.contrast import FLAT_BELOW
from wz_camera_detector.flow import FlowSettings
from wz_camera_detector.tracker import ImageTrackerSettings
from wz_shared.sensor_mounts import mount_of_kind
from wz_shared.settings import ServiceSettings
from wz_shared.site import SensorMount, Site

MODELS = Path(__file__).resolve().parent / "models"
#: The model for real cameras: NanoDet-g, pretrained on COCO's photographs, int8
#: (``training/nanodet_from_npm.py``, ``training/quantize_int8.py``; docs/camera-detector.md).
DEFAULT_MODEL_PATH = MODELS / "coco-nanodet-g-416-int8.onnx"
#: The model for the simulator's rendered frames: YOLOv8-pico trained on them
#: (``training/README.md``). A COCO model finds few of the renders' low-polygon vehicles.
SIMULATION_MODEL_PATH = MODELS / "wz-vehicles-pico-480.onnx"


def shipped_model(rendered: bool) -> Path:
    """The shipped model for real camera frames, or for the simulator's renders."""
    return SIMULATION_MODEL_PATH if rendered else DEFAULT_MODEL_PATH


#: ``radar_id`` value that turns fusion off (camera-only detections).
NO_RADAR = "none"


class CameraDetectorSettings(ServiceSettings):
    """Which camera (and radar) the node serves, its image backend and the fusion parameters.

    ``site_file`` (inherited) gives the mounts. Build it in ``main()``; tests pass values as
    keyword arguments.
    """

    model_config = SettingsConfigDict(
        env_prefix="WZ_CAMERA_", extra="ignore", env_nested_delimiter="__"
    )

    #: The camera to serve (frames on ``raw/camera/<id>``); default: the site's first camera.
    camera_id: str | None = None
    #: The radar to fuse with (scans on ``raw/radar/<id>``); default: the site's first radar,
    #: camera-only when the site has none; ``"none"``: camera-only.
    radar_id: str | None = None
    #: Image backend: ``yolo`` (a local ONNX detector, YOLOv8 or NanoDet, ``model_path``;
    #: never downloaded) or ``background-subtraction`` (no model, learns the empty road first;
    #: class "vehicle").
    backend: Literal["background-subtraction", "yolo"] = "yolo"
    #: The detector's ``.onnx`` file; default (None): the shipped model for the frames, the
    #: COCO-pretrained one for a camera's, the simulator-trained one for the simulator's
    #: rendered frames (:func:`shipped_model`; see docs/camera-detector.md).
    model_path: Path | None = None
    #: The model's class names, in its class order (yolo); default: the model's metadata.
    #: Classes that are not vehicles (anything but car, vehicle, truck, bus, motorcycle) are
    #: ignored.
    class_names: tuple[str, ...] | None = None
    #: Region of interest ``(x0, y0, x1, y1)`` [px] the YOLO model looks at (the frame is
    #: cropped to it); default: the site's road projected into the camera's image
    #: (:mod:`wz_camera_detector.regions`).
    roi_xyxy_px: tuple[int, int, int, int] | None = None
    #: Far-field tiles ``x0, y0, x1, y1`` [px], each letterboxed on its own (yolo); default:
    #: from the road's geometry with the ROI; ``()`` for none.
    tiles_xyxy_px: tuple[tuple[int, int, int, int], ...] | None = None
    #: Minimum class score of a detection [0-1]; default: the model's own operating point
    #: (its metadata's ``wz_conf_threshold``: 0.35 for the COCO model), else 0.25.
    conf_threshold: Annotated[float, Field(ge=0.0, lt=1.0)] | None = None
    #: Put the objects of a frame the model skipped (boxes optical flow carried) on the bus:
    #: False (the default) publishes that frame's batch empty. A flow box holds its last
    #: detection's ranging error, so the fusion tracker would take one error as several
    #: independent measurements: on the default site with its camera at 30 fps (``wz eval``,
    #: 120 s) that gave 235 and 722 false track-frames on seeds 7 and 11, 65 and 202 without.
    publish_followed: bool = False
    #: Fog and haze (yolo, ``contrast.py``): a frame whose flatness is below ``flat_below``
    #: gets local contrast (CLAHE on its lightness) before the model. ``auto``: for the
    #: shipped real-camera model (trained on COCO's clear photographs), not for the
    #: simulator's (trained on the renders' own fog) nor a model of the settings; ``on``: for
    #: any model; ``off``: never.
    fog_contrast: Literal["auto", "on", "off"] = "auto"
    flat_below: Annotated[float, Field(gt=0.0)] = FLAT_BELOW
    #: A radar scan is fused with a frame when their stamps differ by at most this [s].
    radar_max_age_s: Annotated[float, Field(ge=0.0)] = 0.1
    #: Publish only confirmed image tracks (``tracker.min_hits`` detections); False: every
    #: track updated by the frame, tentative ones included.
    confirmed_only: bool = True
    #: Camera ground-position error, std across the line of sight:
    #: ``lateral_std_m + lateral_std_per_m * range`` [m] (a pixel column is a precise bearing;
    #: measured in simulation, camera+radar lateral RMSE 0.11-0.18 m at 50-125 m: the values
    #: keep some margin for a real camera's calibration).
    lateral_std_m: Annotated[float, Field(gt=0.0)] = 0.15
    lateral_std_per_m: Annotated[float, Field(ge=0.0)] = 0.0025
    #: Near the mast the box is a vehicle seen from above, its side and roof in view, and its
    #: middle column no longer the vehicle's centre (measured: 1.3 m lateral RMSE within
    #: 25 m): ``near_lateral_std_m * max(0, 1 - range / near_range_m)`` is added [m].
    near_lateral_std_m: Annotated[float, Field(ge=0.0)] = 1.3
    near_range_m: Annotated[float, Field(gt=0.0)] = 25.0
    #: Camera-only objects ranged beyond this are not published [m]: ranging by the box's
    #: bottom row is meaningless near the horizon (radar-paired objects keep the radar's range).
    max_range_m: Annotated[float, Field(gt=0.0)] = 200.0
    #: ... and along it: ``range_std_m + range_std_per_m * range`` [m] (flat-road ranging from
    #: a pixel row: road slope, pitch and the assumed vehicle size grow with range).
    range_std_m: Annotated[float, Field(gt=0.0)] = 1.0
    range_std_per_m: Annotated[float, Field(ge=0.0)] = 0.03
    background: BackgroundSubtractionSettings = Field(default_factory=BackgroundSubtractionSettings)
    #: The detector runs on a frame when this long has passed since it last ran (less half a
    #: frame's interval), and optical flow follows the boxes on the frames between [s]; 0: on
    #: every frame. The default runs it on each frame of a 10 fps camera and on every fourth
    #: of a 30 fps one (7.5 Hz): a vehicle's first detection waits at most this long, it is
    #: confirmed at its second when flow followed it between (``tracker.min_hits_followed``).
    #: The background backend runs on every frame (it learns the road from each).
    detection_period_s: Annotated[float, Field(ge=0.0, le=2.0)] = 0.13
    #: The YOLO backend's far-field tiles run at every this many detections (the ROI at each)
    #: when the detector skips frames: a far vehicle moves a few pixels a frame and flow
    #: follows it between. While it runs on every frame (a 10 fps camera) the tiles run at each
    #: (every other one let the ROI's coarse boxes of far cars range them: on the default
    #: site, seed 7, MOTA 0.978 -> 0.958 and 15 -> 223 false track-frames).
    tiles_every: Annotated[int, Field(ge=1, le=10)] = 2
    #: Optical flow between detections (Median Flow, :mod:`wz_camera_detector.flow`).
    flow: FlowSettings = Field(default_factory=FlowSettings)
    #: ONNX Runtime's threads for the model (intra-op; its thread pool does not spin): one
    #: core for the camera, the box's other core for the rest of the stack.
    onnx_threads: Annotated[int, Field(ge=1, le=64)] = 1
    #: Frames the node's queue holds while it works on one (the newest kept): a frame the
    #: detector runs on takes longer than a 30 fps frame's interval, the frames after it wait
    #: and are followed by flow in a few milliseconds each.
    frame_queue: Annotated[int, Field(ge=1, le=64)] = 4
    tracker: ImageTrackerSettings = Field(default_factory=ImageTrackerSettings)
    association: AssociationSettings = Field(default_factory=AssociationSettings)
    #: The camera's and the radar's pose and clock learned against the LiDAR's vehicles
    #: (issue 39), on by default; needs the LiDAR's detections on the bus.
    calibration: SensorCalibrationSettings = Field(default_factory=SensorCalibrationSettings)


def camera_mount(site: Site, camera_id: str | None) -> SensorMount:
    """The mount of ``camera_id`` (default: the site's first camera).

    Raises
    ------
    ValueError
        When the site has no such sensor, or it is not a camera, in words for the operator.
    """
    return mount_of_kind(site, camera_id, "camera", "WZ_CAMERA_CAMERA_ID")


def radar_mount(site: Site, radar_id: str | None) -> SensorMount | None:
    """The mount of ``radar_id``; default: the site's first radar, None when it has none;
    None for ``"none"``.

    Raises
    ------
    ValueError
        When a named sensor does not exist or is not a radar.
    """
    if radar_id is not None and radar_id.lower() == NO_RADAR:
        return None
    if radar_id is None and not any(mount.kind == "radar" for mount in site.sensors):
        return None
    return mount_of_kind(site, radar_id, "radar", "WZ_CAMERA_RADAR_ID")
