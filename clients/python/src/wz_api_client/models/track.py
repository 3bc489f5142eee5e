from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.track_status import TrackStatus
from ..models.vehicle_class import VehicleClass
from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="Track")


@_attrs_define
class Track:
    """One fused track: state in the site frame and its road-frame projection.

    Attributes:
        age_s (float):
        confirmed (bool):
        covariance (list[float]):
        heading_rad (float):
        hits (int):
        lane_index (int):
        offset_m (float):
        sources (list[str]):
        speed_mps (float):
        station_m (float):
        track_id (int):
        vx_mps (float):
        vy_mps (float):
        x_m (float):
        y_m (float):
        last_update_s (float | None | Unset):
        length_m (float | None | Unset):
        object_class (VehicleClass | Unset):
        status (TrackStatus | Unset): Life cycle of a fused track.
        width_m (float | None | Unset):
    """

    age_s: float
    confirmed: bool
    covariance: list[float]
    heading_rad: float
    hits: int
    lane_index: int
    offset_m: float
    sources: list[str]
    speed_mps: float
    station_m: float
    track_id: int
    vx_mps: float
    vy_mps: float
    x_m: float
    y_m: float
    last_update_s: float | None | Unset = UNSET
    length_m: float | None | Unset = UNSET
    object_class: VehicleClass | Unset = UNSET
    status: TrackStatus | Unset = UNSET
    width_m: float | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        age_s = self.age_s

        confirmed = self.confirmed

        covariance = self.covariance

        heading_rad = self.heading_rad

        hits = self.hits

        lane_index = self.lane_index

        offset_m = self.offset_m

        sources = self.sources

        speed_mps = self.speed_mps

        station_m = self.station_m

        track_id = self.track_id

        vx_mps = self.vx_mps

        vy_mps = self.vy_mps

        x_m = self.x_m

        y_m = self.y_m

        last_update_s: float | None | Unset
        if isinstance(self.last_update_s, Unset):
            last_update_s = UNSET
        else:
            last_update_s = self.last_update_s

        length_m: float | None | Unset
        if isinstance(self.length_m, Unset):
            length_m = UNSET
        else:
            length_m = self.length_m

        object_class: str | Unset = UNSET
        if not isinstance(self.object_class, Unset):
            object_class = self.object_class.value

        status: str | Unset = UNSET
        if not isinstance(self.status, Unset):
            status = self.status.value

        width_m: float | None | Unset
        if isinstance(self.width_m, Unset):
            width_m = UNSET
        else:
            width_m = self.width_m

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "age_s": age_s,
                "confirmed": confirmed,
                "covariance": covariance,
                "heading_rad": heading_rad,
                "hits": hits,
                "lane_index": lane_index,
                "offset_m": offset_m,
                "sources": sources,
                "speed_mps": speed_mps,
                "station_m": station_m,
                "track_id": track_id,
                "vx_mps": vx_mps,
                "vy_mps": vy_mps,
                "x_m": x_m,
                "y_m": y_m,
            }
        )
        if last_update_s is not UNSET:
            field_dict["last_update_s"] = last_update_s
        if length_m is not UNSET:
            field_dict["length_m"] = length_m
        if object_class is not UNSET:
            field_dict["object_class"] = object_class
        if status is not UNSET:
            field_dict["status"] = status
        if width_m is not UNSET:
            field_dict["width_m"] = width_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        age_s = d.pop("age_s")

        confirmed = d.pop("confirmed")

        covariance = cast(list[float], d.pop("covariance"))

        heading_rad = d.pop("heading_rad")

        hits = d.pop("hits")

        lane_index = d.pop("lane_index")

        offset_m = d.pop("offset_m")

        sources = cast(list[str], d.pop("sources"))

        speed_mps = d.pop("speed_mps")

        station_m = d.pop("station_m")

        track_id = d.pop("track_id")

        vx_mps = d.pop("vx_mps")

        vy_mps = d.pop("vy_mps")

        x_m = d.pop("x_m")

        y_m = d.pop("y_m")

        def _parse_last_update_s(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        last_update_s = _parse_last_update_s(d.pop("last_update_s", UNSET))

        def _parse_length_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        length_m = _parse_length_m(d.pop("length_m", UNSET))

        _object_class = d.pop("object_class", UNSET)
        object_class: VehicleClass | Unset
        if isinstance(_object_class, Unset):
            object_class = UNSET
        else:
            object_class = VehicleClass(_object_class)

        _status = d.pop("status", UNSET)
        status: TrackStatus | Unset
        if isinstance(_status, Unset):
            status = UNSET
        else:
            status = TrackStatus(_status)

        def _parse_width_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        width_m = _parse_width_m(d.pop("width_m", UNSET))

        track = cls(
            age_s=age_s,
            confirmed=confirmed,
            covariance=covariance,
            heading_rad=heading_rad,
            hits=hits,
            lane_index=lane_index,
            offset_m=offset_m,
            sources=sources,
            speed_mps=speed_mps,
            station_m=station_m,
            track_id=track_id,
            vx_mps=vx_mps,
            vy_mps=vy_mps,
            x_m=x_m,
            y_m=y_m,
            last_update_s=last_update_s,
            length_m=length_m,
            object_class=object_class,
            status=status,
            width_m=width_m,
        )

        return track
