from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.area_kind import AreaKind


T = TypeVar("T", bound="WorkZoneArea")


@_attrs_define
class WorkZoneArea:
    """A stretch of road ``[start_station_m, end_station_m)`` with one role in the work zone.

    Attributes:
        end_station_m (float):
        kind (AreaKind): Temporary traffic control areas of a work zone (MUTCD Part 6).
        start_station_m (float):
    """

    end_station_m: float
    kind: AreaKind
    start_station_m: float

    def to_dict(self) -> dict[str, Any]:
        end_station_m = self.end_station_m

        kind = self.kind.value

        start_station_m = self.start_station_m

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "end_station_m": end_station_m,
                "kind": kind,
                "start_station_m": start_station_m,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        end_station_m = d.pop("end_station_m")

        kind = AreaKind(d.pop("kind"))

        start_station_m = d.pop("start_station_m")

        work_zone_area = cls(
            end_station_m=end_station_m,
            kind=kind,
            start_station_m=start_station_m,
        )

        return work_zone_area
