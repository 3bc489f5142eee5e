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


T = TypeVar("T", bound="TrackPoint")


@_attrs_define
class TrackPoint:
    """One stored point of a trajectory: a track at one tracker cycle.

    Attributes:
        heading_rad (float):
        lane_index (int):
        latitude_deg (float):
        longitude_deg (float):
        object_class (VehicleClass):
        offset_m (float):
        speed_mps (float):
        stamp (float):
        station_m (float):
        status (TrackStatus): Life cycle of a fused track.
        track_id (int):
        vx_mps (float):
        vy_mps (float):
        x_m (float):
        y_m (float):
        length_m (float | None | Unset):
        smoothed (bool | Unset):  Default: False.
        width_m (float | None | Unset):
    """

    heading_rad: float
    lane_index: int
    latitude_deg: float
    longitude_deg: float
    object_class: VehicleClass
    offset_m: float
    speed_mps: float
    stamp: float
    station_m: float
    status: TrackStatus
    track_id: int
    vx_mps: float
    vy_mps: float
    x_m: float
    y_m: float
    length_m: float | None | Unset = UNSET
    smoothed: bool | Unset = False
    width_m: float | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        heading_rad = self.heading_rad

        lane_index = self.lane_index

        latitude_deg = self.latitude_deg

        longitude_deg = self.longitude_deg

        object_class = self.object_class.value

        offset_m = self.offset_m

        speed_mps = self.speed_mps

        stamp = self.stamp

        station_m = self.station_m

        status = self.status.value

        track_id = self.track_id

        vx_mps = self.vx_mps

        vy_mps = self.vy_mps

        x_m = self.x_m

        y_m = self.y_m

        length_m: float | None | Unset
        if isinstance(self.length_m, Unset):
            length_m = UNSET
        else:
            length_m = self.length_m

        smoothed = self.smoothed

        width_m: float | None | Unset
        if isinstance(self.width_m, Unset):
            width_m = UNSET
        else:
            width_m = self.width_m

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "heading_rad": heading_rad,
                "lane_index": lane_index,
                "latitude_deg": latitude_deg,
                "longitude_deg": longitude_deg,
                "object_class": object_class,
                "offset_m": offset_m,
                "speed_mps": speed_mps,
                "stamp": stamp,
                "station_m": station_m,
                "status": status,
                "track_id": track_id,
                "vx_mps": vx_mps,
                "vy_mps": vy_mps,
                "x_m": x_m,
                "y_m": y_m,
            }
        )
        if length_m is not UNSET:
            field_dict["length_m"] = length_m
        if smoothed is not UNSET:
            field_dict["smoothed"] = smoothed
        if width_m is not UNSET:
            field_dict["width_m"] = width_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        heading_rad = d.pop("heading_rad")

        lane_index = d.pop("lane_index")

        latitude_deg = d.pop("latitude_deg")

        longitude_deg = d.pop("longitude_deg")

        object_class = VehicleClass(d.pop("object_class"))

        offset_m = d.pop("offset_m")

        speed_mps = d.pop("speed_mps")

        stamp = d.pop("stamp")

        station_m = d.pop("station_m")

        status = TrackStatus(d.pop("status"))

        track_id = d.pop("track_id")

        vx_mps = d.pop("vx_mps")

        vy_mps = d.pop("vy_mps")

        x_m = d.pop("x_m")

        y_m = d.pop("y_m")

        def _parse_length_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        length_m = _parse_length_m(d.pop("length_m", UNSET))

        smoothed = d.pop("smoothed", UNSET)

        def _parse_width_m(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        width_m = _parse_width_m(d.pop("width_m", UNSET))

        track_point = cls(
            heading_rad=heading_rad,
            lane_index=lane_index,
            latitude_deg=latitude_deg,
            longitude_deg=longitude_deg,
            object_class=object_class,
            offset_m=offset_m,
            speed_mps=speed_mps,
            stamp=stamp,
            station_m=station_m,
            status=status,
            track_id=track_id,
            vx_mps=vx_mps,
            vy_mps=vy_mps,
            x_m=x_m,
            y_m=y_m,
            length_m=length_m,
            smoothed=smoothed,
            width_m=width_m,
        )

        return track_point
