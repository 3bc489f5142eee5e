from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="PointSensor")


@_attrs_define
class PointSensor:
    """A point speed sensor upstream of the mast: what smart-work-zone deployments place every
    quarter to half mile ahead of a lane closure (a side-fire radar or a loop station on its
    own trailer). Each interval it gives, per lane, the vehicles that passed its station, their
    mean speed and the share of the time a vehicle stood over it (occupancy). The alert service
    bounds a queue's back with them where the back is beyond the mast's sensors' reach
    (:mod:`wz_alert_service.queues`); in simulation SUMO's induction loops stand in for them.

        Attributes:
            sensor_id (str):
            station_m (float):
            interval_s (float | Unset):  Default: 30.0.
    """

    sensor_id: str
    station_m: float
    interval_s: float | Unset = 30.0

    def to_dict(self) -> dict[str, Any]:
        sensor_id = self.sensor_id

        station_m = self.station_m

        interval_s = self.interval_s

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "sensor_id": sensor_id,
                "station_m": station_m,
            }
        )
        if interval_s is not UNSET:
            field_dict["interval_s"] = interval_s

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        sensor_id = d.pop("sensor_id")

        station_m = d.pop("station_m")

        interval_s = d.pop("interval_s", UNSET)

        point_sensor = cls(
            sensor_id=sensor_id,
            station_m=station_m,
            interval_s=interval_s,
        )

        return point_sensor
