from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.sensor_calibration_status import SensorCalibrationStatus


T = TypeVar("T", bound="SiteCalibration")


@_attrs_define
class SiteCalibration:
    """The self-calibration of each sensor of a site: the site file's sensors in its order,
    then any other sensor heard from.

        Attributes:
            sensors (list[SensorCalibrationStatus]):
            site (str):
    """

    sensors: list[SensorCalibrationStatus]
    site: str

    def to_dict(self) -> dict[str, Any]:
        from ..models.sensor_calibration_status import SensorCalibrationStatus  # noqa: PLC0415

        sensors = []
        for sensors_item_data in self.sensors:
            sensors_item = sensors_item_data.to_dict()
            sensors.append(sensors_item)

        site = self.site

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "sensors": sensors,
                "site": site,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.sensor_calibration_status import SensorCalibrationStatus  # noqa: PLC0415

        d = dict(src_dict)
        sensors = []
        _sensors = d.pop("sensors")
        for sensors_item_data in _sensors:
            sensors_item = SensorCalibrationStatus.from_dict(sensors_item_data)

            sensors.append(sensors_item)

        site = d.pop("site")

        site_calibration = cls(
            sensors=sensors,
            site=site,
        )

        return site_calibration
