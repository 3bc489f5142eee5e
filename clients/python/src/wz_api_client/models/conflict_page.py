from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.conflict import Conflict


T = TypeVar("T", bound="ConflictPage")


@_attrs_define
class ConflictPage:
    """Conflicts of a window (:mod:`wz_gateway.conflicts`), by the time of their minimum TTC;
    ``next_cursor`` fetches the next page.

        Attributes:
            conflicts (list[Conflict]):
            count (int):
            end (float):
            max_pet_s (float):
            max_ttc_s (float):
            next_cursor (None | str):
            site (str):
            start (float):
    """

    conflicts: list[Conflict]
    count: int
    end: float
    max_pet_s: float
    max_ttc_s: float
    next_cursor: None | str
    site: str
    start: float

    def to_dict(self) -> dict[str, Any]:
        from ..models.conflict import Conflict  # noqa: PLC0415

        conflicts = []
        for conflicts_item_data in self.conflicts:
            conflicts_item = conflicts_item_data.to_dict()
            conflicts.append(conflicts_item)

        count = self.count

        end = self.end

        max_pet_s = self.max_pet_s

        max_ttc_s = self.max_ttc_s

        next_cursor: None | str
        next_cursor = self.next_cursor

        site = self.site

        start = self.start

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "conflicts": conflicts,
                "count": count,
                "end": end,
                "max_pet_s": max_pet_s,
                "max_ttc_s": max_ttc_s,
                "next_cursor": next_cursor,
                "site": site,
                "start": start,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.conflict import Conflict  # noqa: PLC0415

        d = dict(src_dict)
        conflicts = []
        _conflicts = d.pop("conflicts")
        for conflicts_item_data in _conflicts:
            conflicts_item = Conflict.from_dict(conflicts_item_data)

            conflicts.append(conflicts_item)

        count = d.pop("count")

        end = d.pop("end")

        max_pet_s = d.pop("max_pet_s")

        max_ttc_s = d.pop("max_ttc_s")

        def _parse_next_cursor(data: object) -> None | str:
            if data is None:
                return data
            return cast(None | str, data)

        next_cursor = _parse_next_cursor(d.pop("next_cursor"))

        site = d.pop("site")

        start = d.pop("start")

        conflict_page = cls(
            conflicts=conflicts,
            count=count,
            end=end,
            max_pet_s=max_pet_s,
            max_ttc_s=max_ttc_s,
            next_cursor=next_cursor,
            site=site,
            start=start,
        )

        return conflict_page
