from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.live_track import LiveTrack


T = TypeVar("T", bound="LiveTracks")


@_attrs_define
class LiveTracks:
    """The newest track batch the gateway received; empty before the first.

    Attributes:
        age_s (float | None):
        cycle_index (int | None):
        site (str):
        stamp (float | None):
        tracks (list[LiveTrack]):
    """

    age_s: float | None
    cycle_index: int | None
    site: str
    stamp: float | None
    tracks: list[LiveTrack]

    def to_dict(self) -> dict[str, Any]:
        from ..models.live_track import LiveTrack  # noqa: PLC0415

        age_s: float | None
        age_s = self.age_s

        cycle_index: int | None
        cycle_index = self.cycle_index

        site = self.site

        stamp: float | None
        stamp = self.stamp

        tracks = []
        for tracks_item_data in self.tracks:
            tracks_item = tracks_item_data.to_dict()
            tracks.append(tracks_item)

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "age_s": age_s,
                "cycle_index": cycle_index,
                "site": site,
                "stamp": stamp,
                "tracks": tracks,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.live_track import LiveTrack  # noqa: PLC0415

        d = dict(src_dict)

        def _parse_age_s(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        age_s = _parse_age_s(d.pop("age_s"))

        def _parse_cycle_index(data: object) -> int | None:
            if data is None:
                return data
            return cast(int | None, data)

        cycle_index = _parse_cycle_index(d.pop("cycle_index"))

        site = d.pop("site")

        def _parse_stamp(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        stamp = _parse_stamp(d.pop("stamp"))

        tracks = []
        _tracks = d.pop("tracks")
        for tracks_item_data in _tracks:
            tracks_item = LiveTrack.from_dict(tracks_item_data)

            tracks.append(tracks_item)

        live_tracks = cls(
            age_s=age_s,
            cycle_index=cycle_index,
            site=site,
            stamp=stamp,
            tracks=tracks,
        )

        return live_tracks
