from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.track_point import TrackPoint


T = TypeVar("T", bound="Trajectory")


@_attrs_define
class Trajectory:
    """One track's stored points, oldest first, a page at a time.

    Attributes:
        count (int):
        next_cursor (None | str):
        points (list[TrackPoint]):
        site (str):
        track_id (int):
    """

    count: int
    next_cursor: None | str
    points: list[TrackPoint]
    site: str
    track_id: int

    def to_dict(self) -> dict[str, Any]:
        from ..models.track_point import TrackPoint  # noqa: PLC0415

        count = self.count

        next_cursor: None | str
        next_cursor = self.next_cursor

        points = []
        for points_item_data in self.points:
            points_item = points_item_data.to_dict()
            points.append(points_item)

        site = self.site

        track_id = self.track_id

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "count": count,
                "next_cursor": next_cursor,
                "points": points,
                "site": site,
                "track_id": track_id,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.track_point import TrackPoint  # noqa: PLC0415

        d = dict(src_dict)
        count = d.pop("count")

        def _parse_next_cursor(data: object) -> None | str:
            if data is None:
                return data
            return cast(None | str, data)

        next_cursor = _parse_next_cursor(d.pop("next_cursor"))

        points = []
        _points = d.pop("points")
        for points_item_data in _points:
            points_item = TrackPoint.from_dict(points_item_data)

            points.append(points_item)

        site = d.pop("site")

        track_id = d.pop("track_id")

        trajectory = cls(
            count=count,
            next_cursor=next_cursor,
            points=points,
            site=site,
            track_id=track_id,
        )

        return trajectory
