from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset


T = TypeVar("T", bound="SpeedLimit")


@_attrs_define
class SpeedLimit:
    """Posted limit from ``start_station_m`` to ``end_station_m``.

    Attributes:
        end_station_m (float):
        speed_limit_mph (float):
        start_station_m (float):
    """

    end_station_m: float
    speed_limit_mph: float
    start_station_m: float

    def to_dict(self) -> dict[str, Any]:
        end_station_m = self.end_station_m

        speed_limit_mph = self.speed_limit_mph

        start_station_m = self.start_station_m

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "end_station_m": end_station_m,
                "speed_limit_mph": speed_limit_mph,
                "start_station_m": start_station_m,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        end_station_m = d.pop("end_station_m")

        speed_limit_mph = d.pop("speed_limit_mph")

        start_station_m = d.pop("start_station_m")

        speed_limit = cls(
            end_station_m=end_station_m,
            speed_limit_mph=speed_limit_mph,
            start_station_m=start_station_m,
        )

        return speed_limit
