"""Contains all the data models used in inputs/outputs"""

from .aggressive_approach_rule import AggressiveApproachRule
from .alert import Alert
from .alert_evidence import AlertEvidence
from .alert_page import AlertPage
from .alert_phase import AlertPhase
from .alert_rules import AlertRules
from .alert_severity import AlertSeverity
from .alert_type import AlertType
from .api_key_info import ApiKeyInfo
from .api_key_info_origin import ApiKeyInfoOrigin
from .api_key_info_scope import ApiKeyInfoScope
from .area_kind import AreaKind
from .calibration_state import CalibrationState
from .calibration_state_change import CalibrationStateChange
from .camera_intrinsics import CameraIntrinsics
from .conflict import Conflict
from .conflict_conflict_type import ConflictConflictType
from .conflict_page import ConflictPage
from .created_api_key import CreatedApiKey
from .created_api_key_origin import CreatedApiKeyOrigin
from .created_api_key_scope import CreatedApiKeyScope
from .created_webhook import CreatedWebhook
from .created_webhook_phases_type_0_item import CreatedWebhookPhasesType0Item
from .device_rules import DeviceRules
from .geo_origin import GeoOrigin
from .get_alerts_v1_alerts_get_format import GetAlertsV1AlertsGetFormat
from .get_alerts_v1_alerts_get_order import GetAlertsV1AlertsGetOrder
from .get_alerts_v1_alerts_get_phase_type_0_item import (
    GetAlertsV1AlertsGetPhaseType0Item,
)
from .get_conflicts_v1_conflicts_get_format import GetConflictsV1ConflictsGetFormat
from .get_device_feed_v1_wzdx_device_feed_get_response_200 import (
    GetDeviceFeedV1WzdxDeviceFeedGetResponse200,
)
from .get_queue_history_v1_queue_history_get_order import (
    GetQueueHistoryV1QueueHistoryGetOrder,
)
from .get_stream_v1_stream_get_event_type_0_item import (
    GetStreamV1StreamGetEventType0Item,
)
from .get_track_v1_tracks_track_id_get_format import GetTrackV1TracksTrackIdGetFormat
from .get_trajectories_v1_trajectories_get_format import (
    GetTrajectoriesV1TrajectoriesGetFormat,
)
from .get_work_zone_feed_v1_wzdx_work_zone_feed_get_response_200 import (
    GetWorkZoneFeedV1WzdxWorkZoneFeedGetResponse200,
)
from .hard_braking_rule import HardBrakingRule
from .health import Health
from .intrusion_rule import IntrusionRule
from .lane import Lane
from .lane_queue import LaneQueue
from .late_merge_rule import LateMergeRule
from .lidar_intrinsics import LidarIntrinsics
from .live_track import LiveTrack
from .live_tracks import LiveTracks
from .new_api_key import NewApiKey
from .new_api_key_scope import NewApiKeyScope
from .new_webhook import NewWebhook
from .new_webhook_phases_type_0_item import NewWebhookPhasesType0Item
from .point_page import PointPage
from .point_sensor import PointSensor
from .pose import Pose
from .pose_correction import PoseCorrection
from .problem import Problem
from .problem_field import ProblemField
from .queue_approach_rule import QueueApproachRule
from .queue_condition import QueueCondition
from .queue_page import QueuePage
from .queue_rule import QueueRule
from .queue_state import QueueState
from .radar_intrinsics import RadarIntrinsics
from .readiness import Readiness
from .readiness_checks import ReadinessChecks
from .readiness_status import ReadinessStatus
from .schedule import Schedule
from .sensor_calibration import SensorCalibration
from .sensor_calibration_sensor_kind import SensorCalibrationSensorKind
from .sensor_calibration_status import SensorCalibrationStatus
from .sensor_calibration_status_sensor_kind import SensorCalibrationStatusSensorKind
from .sensor_mount import SensorMount
from .short_ttc_rule import ShortTtcRule
from .site import Site
from .site_calibration import SiteCalibration
from .site_queue import SiteQueue
from .site_road_direction import SiteRoadDirection
from .site_summary import SiteSummary
from .speed_limit import SpeedLimit
from .speeding_rule import SpeedingRule
from .track import Track
from .track_point import TrackPoint
from .track_status import TrackStatus
from .trajectory import Trajectory
from .vehicle_class import VehicleClass
from .webhook_event_info import WebhookEventInfo
from .webhook_event_info_state import WebhookEventInfoState
from .webhook_info import WebhookInfo
from .webhook_info_phases_type_0_item import WebhookInfoPhasesType0Item
from .webhook_secret import WebhookSecret
from .webhook_test_event import WebhookTestEvent
from .work_zone_area import WorkZoneArea

__all__ = (
    "AggressiveApproachRule",
    "Alert",
    "AlertEvidence",
    "AlertPage",
    "AlertPhase",
    "AlertRules",
    "AlertSeverity",
    "AlertType",
    "ApiKeyInfo",
    "ApiKeyInfoOrigin",
    "ApiKeyInfoScope",
    "AreaKind",
    "CalibrationState",
    "CalibrationStateChange",
    "CameraIntrinsics",
    "Conflict",
    "ConflictConflictType",
    "ConflictPage",
    "CreatedApiKey",
    "CreatedApiKeyOrigin",
    "CreatedApiKeyScope",
    "CreatedWebhook",
    "CreatedWebhookPhasesType0Item",
    "DeviceRules",
    "GeoOrigin",
    "GetAlertsV1AlertsGetFormat",
    "GetAlertsV1AlertsGetOrder",
    "GetAlertsV1AlertsGetPhaseType0Item",
    "GetConflictsV1ConflictsGetFormat",
    "GetDeviceFeedV1WzdxDeviceFeedGetResponse200",
    "GetQueueHistoryV1QueueHistoryGetOrder",
    "GetStreamV1StreamGetEventType0Item",
    "GetTrackV1TracksTrackIdGetFormat",
    "GetTrajectoriesV1TrajectoriesGetFormat",
    "GetWorkZoneFeedV1WzdxWorkZoneFeedGetResponse200",
    "HardBrakingRule",
    "Health",
    "IntrusionRule",
    "Lane",
    "LaneQueue",
    "LateMergeRule",
    "LidarIntrinsics",
    "LiveTrack",
    "LiveTracks",
    "NewApiKey",
    "NewApiKeyScope",
    "NewWebhook",
    "NewWebhookPhasesType0Item",
    "PointPage",
    "PointSensor",
    "Pose",
    "PoseCorrection",
    "Problem",
    "ProblemField",
    "QueueApproachRule",
    "QueueCondition",
    "QueuePage",
    "QueueRule",
    "QueueState",
    "RadarIntrinsics",
    "Readiness",
    "ReadinessChecks",
    "ReadinessStatus",
    "Schedule",
    "SensorCalibration",
    "SensorCalibrationSensorKind",
    "SensorCalibrationStatus",
    "SensorCalibrationStatusSensorKind",
    "SensorMount",
    "ShortTtcRule",
    "Site",
    "SiteCalibration",
    "SiteQueue",
    "SiteRoadDirection",
    "SiteSummary",
    "SpeedingRule",
    "SpeedLimit",
    "Track",
    "TrackPoint",
    "TrackStatus",
    "Trajectory",
    "VehicleClass",
    "WebhookEventInfo",
    "WebhookEventInfoState",
    "WebhookInfo",
    "WebhookInfoPhasesType0Item",
    "WebhookSecret",
    "WebhookTestEvent",
    "WorkZoneArea",
)
