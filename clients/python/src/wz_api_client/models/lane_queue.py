from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.queue_condition import QueueCondition
from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="LaneQueue")


@_attrs_define
class LaneQueue:
    """One lane's queue now (:class:`QueueState`).

    A lane is queued while ``min_vehicles`` of its slow vehicles stand within ``span_m`` of
    station (the site's queue rule, per lane); stopped while their mean speed is below
    ``stopped_speed_mps``. Stations are along the road [m]; the back is the queue's most
    upstream queued vehicle, the head its most downstream one.

        Attributes:
            condition (QueueCondition): A lane's traffic as the queue estimate sees it (thresholds: the site's
                ``alerts.queue``).
            lane_index (int):
            reach_station_m (float):
            back_beyond_reach (bool | Unset):  Default: False.
            back_downstream_bound_m (float | None | Unset):
            back_speed_mps (float | None | Unset):
            back_station_m (float | None | Unset):
            back_upstream_bound_m (float | None | Unset):
            head_station_m (float | None | Unset):
            length_m (float | Unset):  Default: 0.0.
            mean_speed_mps (float | None | Unset):
            vehicle_count (int | Unset):  Default: 0.
    """

    condition: QueueCondition
    lane_index: int
    reach_station_m: float
    back_beyond_reach: bool | Unset = False
    back_downstream_bound_m: float | None | Unset = UNSET
    back_speed_mps: float | None | Unset = UNSET
    back_station_m: float | None | Unset = UNSET
    back_upstream_bound_m: float | None | Unset = UNSET
    head_station_m: float | None | Unset = UNSET
    length_m: float | Unset = 0.0
    mean_speed_mps: float | None | Unset = UNSET
    vehicle_count: int | Unset = 0

    def to_dict(self) -> dict[str, Any]:
        condition = self.condition.value

        lane_index = self.lane_index

        reach_station_m = self.reach_station_m

        back_beyond_reach = self.back_beyond_reach

        back_downstream_bound_m: float | None | Unset
        if isinstance(self.back_downstream_bound_m, Unset):
            back_downstream_bound_m = UNSET
        else:
            back_downstream_bound_m = self.back_downstream_bound_m

        back_speed_mps: float | None | Unset
        if isinstance(self.back_speed_mps, Unset):
            back_speed_mps = UNSET
        else:
            back_speed_mps = self.back_speed_mps

        back_station_m: float | None | Unset
        if isinstance(self.back_station_m, Unset):
            back_station_m = UNSET
        else:
            back_station_m = self.back_station_m

        back_upstream_bound_m: float | None | Unset
        if isinstance(self.back_upstream_bound_m, Unset):
            back_upstream_bound_m = UNSET
        else:
            back_upstream_bound_m = self.back_upstream_bound_m

        head_station_m: float | None | Unset
        if isinstance(self.head_station_m, Unset):
            head_station_m = UNSET
        else:
            head_station_m = self.head_station_m

        length_m = self.length_m

        mean_speed_mps: float | None | Unset
        if isinstance(self.mean_speed_mps, Unset):
            mean_speed_mps = UNSET
        else:
            mean_speed_mps = self.mean_speed_mps

        vehicle_count = self.vehicle_count

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "condition": condition,
                "lane_index": lane_index,
                "reach_station_m": reach_station_m,
            }
        )
        if back_beyond_reach is not UNSET:
            field_dict["back_beyond_reach"] = back_beyond_reach
        if back_downstream_bound_m is not UNSET:
            field_dict["back_downstream_bound_m"] = back_downstream_bound_m
        if back_speed_mps is not UNSET:
            field_dict["back_speed_mps"] = back_speed_mps
        if back_station_m is not UNSET:
            field_dict["back_station_m"] = back_station_m
        if back_upstream_bound_m is not UNSET:
            field_dict["back_upstream_bound_m"] = back_upstream_bound_m
        if head_station_m is not UNSET:
            field_dict["head_station_m"] = head_station_m
        if length_m is not UNSET:
            field_dict["length_m"] = length_m
        if mean_speed_mps is not UNSET:
            field_dict["mean_speed_mps"] = mean_speed_mps
        if vehicle_count is not UNSET:
            field_dict["vehicle_count"] = vehicle_count

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        condition = QueueCondition(d.pop("condition"))

        lane_index = d.pop("lane_index")

        reach_station_m = d.pop("reach_station_m")

        back_beyond_reach = d.pop("back_beyond_reach", UNSET)

        def _parse_back_downstream_bound_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        back_downstream_bound_m = _parse_back_downstream_bound_m(
            d.pop("back_downstream_bound_m", UNSET)
        )

        def _parse_back_speed_mps(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        back_speed_mps = _parse_back_speed_mps(d.pop("back_speed_mps", UNSET))

        def _parse_back_station_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        back_station_m = _parse_back_station_m(d.pop("back_station_m", UNSET))

        def _parse_back_upstream_bound_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        back_upstream_bound_m = _parse_back_upstream_bound_m(
            d.pop("back_upstream_bound_m", UNSET)
        )

        def _parse_head_station_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        head_station_m = _parse_head_station_m(d.pop("head_station_m", UNSET))

        length_m = d.pop("length_m", UNSET)

        def _parse_mean_speed_mps(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        mean_speed_mps = _parse_mean_speed_mps(d.pop("mean_speed_mps", UNSET))

        vehicle_count = d.pop("vehicle_count", UNSET)

        lane_queue = cls(
            condition=condition,
            lane_index=lane_index,
            reach_station_m=reach_station_m,
            back_beyond_reach=back_beyond_reach,
            back_downstream_bound_m=back_downstream_bound_m,
            back_speed_mps=back_speed_mps,
            back_station_m=back_station_m,
            back_upstream_bound_m=back_upstream_bound_m,
            head_station_m=head_station_m,
            length_m=length_m,
            mean_speed_mps=mean_speed_mps,
            vehicle_count=vehicle_count,
        )

        return lane_queue
