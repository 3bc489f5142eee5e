from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.site_road_direction import SiteRoadDirection
from ..types import UNSET, Unset
from typing import cast
from typing import Literal, cast

if TYPE_CHECKING:
    from ..models.alert_rules import AlertRules
    from ..models.geo_origin import GeoOrigin
    from ..models.lane import Lane
    from ..models.point_sensor import PointSensor
    from ..models.schedule import Schedule
    from ..models.sensor_mount import SensorMount
    from ..models.speed_limit import SpeedLimit
    from ..models.work_zone_area import WorkZoneArea


T = TypeVar("T", bound="Site")


@_attrs_define
class Site:
    """One deployment: geometry, work zone, limits and sensors.

    Attributes:
        centerline_xy_m (list[list[float]]):
        closed_lane_index (int):
        lanes (list[Lane]):
        name (str):
        origin (GeoOrigin): WGS84 anchor of the site frame's origin (x = y = 0, z = 0 at ``altitude_m``).
        site_id (str):
        speed_limits (list[SpeedLimit]):
        work_zone (list[WorkZoneArea]):
        alerts (AlertRules | Unset): Thresholds of the alert service, with units; every rule works in the road frame.

            The approach is the station window ``[activity end - approach_length_m, activity end)``:
            speeding, aggressive approach, hard braking, late merge, short TTC, queue and queue approach look only
            there. Each rule has its own :class:`EpisodeTiming` (hold, clear, cool-down).
        point_sensors (list[PointSensor] | Unset):
        road_direction (SiteRoadDirection | Unset):  Default: SiteRoadDirection.UNKNOWN.
        road_names (list[str] | Unset):
        schedule (None | Schedule | Unset):
        schema_version (Literal[1] | Unset):  Default: 1.
        sensors (list[SensorMount] | Unset):
    """

    centerline_xy_m: list[list[float]]
    closed_lane_index: int
    lanes: list[Lane]
    name: str
    origin: GeoOrigin
    site_id: str
    speed_limits: list[SpeedLimit]
    work_zone: list[WorkZoneArea]
    alerts: AlertRules | Unset = UNSET
    point_sensors: list[PointSensor] | Unset = UNSET
    road_direction: SiteRoadDirection | Unset = SiteRoadDirection.UNKNOWN
    road_names: list[str] | Unset = UNSET
    schedule: None | Schedule | Unset = UNSET
    schema_version: Literal[1] | Unset = 1
    sensors: list[SensorMount] | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        from ..models.alert_rules import AlertRules  # noqa: PLC0415
        from ..models.geo_origin import GeoOrigin  # noqa: PLC0415
        from ..models.lane import Lane  # noqa: PLC0415
        from ..models.point_sensor import PointSensor  # noqa: PLC0415
        from ..models.schedule import Schedule  # noqa: PLC0415
        from ..models.sensor_mount import SensorMount  # noqa: PLC0415
        from ..models.speed_limit import SpeedLimit  # noqa: PLC0415
        from ..models.work_zone_area import WorkZoneArea  # noqa: PLC0415

        centerline_xy_m = []
        for centerline_xy_m_item_data in self.centerline_xy_m:
            centerline_xy_m_item = []
            for centerline_xy_m_item_item_data in centerline_xy_m_item_data:
                centerline_xy_m_item_item: float
                centerline_xy_m_item_item = centerline_xy_m_item_item_data
                centerline_xy_m_item.append(centerline_xy_m_item_item)

            centerline_xy_m.append(centerline_xy_m_item)

        closed_lane_index = self.closed_lane_index

        lanes = []
        for lanes_item_data in self.lanes:
            lanes_item = lanes_item_data.to_dict()
            lanes.append(lanes_item)

        name = self.name

        origin = self.origin.to_dict()

        site_id = self.site_id

        speed_limits = []
        for speed_limits_item_data in self.speed_limits:
            speed_limits_item = speed_limits_item_data.to_dict()
            speed_limits.append(speed_limits_item)

        work_zone = []
        for work_zone_item_data in self.work_zone:
            work_zone_item = work_zone_item_data.to_dict()
            work_zone.append(work_zone_item)

        alerts: dict[str, Any] | Unset = UNSET
        if not isinstance(self.alerts, Unset):
            alerts = self.alerts.to_dict()

        point_sensors: list[dict[str, Any]] | Unset = UNSET
        if not isinstance(self.point_sensors, Unset):
            point_sensors = []
            for point_sensors_item_data in self.point_sensors:
                point_sensors_item = point_sensors_item_data.to_dict()
                point_sensors.append(point_sensors_item)

        road_direction: str | Unset = UNSET
        if not isinstance(self.road_direction, Unset):
            road_direction = self.road_direction.value

        road_names: list[str] | Unset = UNSET
        if not isinstance(self.road_names, Unset):
            road_names = self.road_names

        schedule: dict[str, Any] | None | Unset
        if isinstance(self.schedule, Unset):
            schedule = UNSET
        elif isinstance(self.schedule, Schedule):
            schedule = self.schedule.to_dict()
        else:
            schedule = self.schedule

        schema_version = self.schema_version

        sensors: list[dict[str, Any]] | Unset = UNSET
        if not isinstance(self.sensors, Unset):
            sensors = []
            for sensors_item_data in self.sensors:
                sensors_item = sensors_item_data.to_dict()
                sensors.append(sensors_item)

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "centerline_xy_m": centerline_xy_m,
                "closed_lane_index": closed_lane_index,
                "lanes": lanes,
                "name": name,
                "origin": origin,
                "site_id": site_id,
                "speed_limits": speed_limits,
                "work_zone": work_zone,
            }
        )
        if alerts is not UNSET:
            field_dict["alerts"] = alerts
        if point_sensors is not UNSET:
            field_dict["point_sensors"] = point_sensors
        if road_direction is not UNSET:
            field_dict["road_direction"] = road_direction
        if road_names is not UNSET:
            field_dict["road_names"] = road_names
        if schedule is not UNSET:
            field_dict["schedule"] = schedule
        if schema_version is not UNSET:
            field_dict["schema_version"] = schema_version
        if sensors is not UNSET:
            field_dict["sensors"] = sensors

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.alert_rules import AlertRules  # noqa: PLC0415
        from ..models.geo_origin import GeoOrigin  # noqa: PLC0415
        from ..models.lane import Lane  # noqa: PLC0415
        from ..models.point_sensor import PointSensor  # noqa: PLC0415
        from ..models.schedule import Schedule  # noqa: PLC0415
        from ..models.sensor_mount import SensorMount  # noqa: PLC0415
        from ..models.speed_limit import SpeedLimit  # noqa: PLC0415
        from ..models.work_zone_area import WorkZoneArea  # noqa: PLC0415

        d = dict(src_dict)
        centerline_xy_m = []
        _centerline_xy_m = d.pop("centerline_xy_m")
        for centerline_xy_m_item_data in _centerline_xy_m:
            centerline_xy_m_item = []
            _centerline_xy_m_item = centerline_xy_m_item_data
            for centerline_xy_m_item_item_data in _centerline_xy_m_item:

                def _parse_centerline_xy_m_item_item(data: object) -> float:
                    return cast(float, data)

                centerline_xy_m_item_item = _parse_centerline_xy_m_item_item(
                    centerline_xy_m_item_item_data
                )

                centerline_xy_m_item.append(centerline_xy_m_item_item)

            centerline_xy_m.append(centerline_xy_m_item)

        closed_lane_index = d.pop("closed_lane_index")

        lanes = []
        _lanes = d.pop("lanes")
        for lanes_item_data in _lanes:
            lanes_item = Lane.from_dict(lanes_item_data)

            lanes.append(lanes_item)

        name = d.pop("name")

        origin = GeoOrigin.from_dict(d.pop("origin"))

        site_id = d.pop("site_id")

        speed_limits = []
        _speed_limits = d.pop("speed_limits")
        for speed_limits_item_data in _speed_limits:
            speed_limits_item = SpeedLimit.from_dict(speed_limits_item_data)

            speed_limits.append(speed_limits_item)

        work_zone = []
        _work_zone = d.pop("work_zone")
        for work_zone_item_data in _work_zone:
            work_zone_item = WorkZoneArea.from_dict(work_zone_item_data)

            work_zone.append(work_zone_item)

        _alerts = d.pop("alerts", UNSET)
        alerts: AlertRules | Unset
        if isinstance(_alerts, Unset):
            alerts = UNSET
        else:
            alerts = AlertRules.from_dict(_alerts)

        _point_sensors = d.pop("point_sensors", UNSET)
        point_sensors: list[PointSensor] | Unset = UNSET
        if _point_sensors is not UNSET:
            point_sensors = []
            for point_sensors_item_data in _point_sensors:
                point_sensors_item = PointSensor.from_dict(point_sensors_item_data)

                point_sensors.append(point_sensors_item)

        _road_direction = d.pop("road_direction", UNSET)
        road_direction: SiteRoadDirection | Unset
        if isinstance(_road_direction, Unset):
            road_direction = UNSET
        else:
            road_direction = SiteRoadDirection(_road_direction)

        road_names = cast(list[str], d.pop("road_names", UNSET))

        def _parse_schedule(data: object) -> None | Schedule | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, dict):
                    raise TypeError()
                schedule_type_0 = Schedule.from_dict(data)

                return schedule_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(None | Schedule | Unset, data)

        schedule = _parse_schedule(d.pop("schedule", UNSET))

        schema_version = cast(Literal[1] | Unset, d.pop("schema_version", UNSET))
        if schema_version != 1 and not isinstance(schema_version, Unset):
            raise ValueError(
                f"schema_version must match const 1, got '{schema_version}'"
            )

        _sensors = d.pop("sensors", UNSET)
        sensors: list[SensorMount] | Unset = UNSET
        if _sensors is not UNSET:
            sensors = []
            for sensors_item_data in _sensors:
                sensors_item = SensorMount.from_dict(sensors_item_data)

                sensors.append(sensors_item)

        site = cls(
            centerline_xy_m=centerline_xy_m,
            closed_lane_index=closed_lane_index,
            lanes=lanes,
            name=name,
            origin=origin,
            site_id=site_id,
            speed_limits=speed_limits,
            work_zone=work_zone,
            alerts=alerts,
            point_sensors=point_sensors,
            road_direction=road_direction,
            road_names=road_names,
            schedule=schedule,
            schema_version=schema_version,
            sensors=sensors,
        )

        return site
