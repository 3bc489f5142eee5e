from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.queue_state import QueueState


T = TypeVar("T", bound="QueuePage")


@_attrs_define
class QueuePage:
    """A page of stored queue states (newest first unless asked otherwise).

    Attributes:
        count (int):
        next_cursor (None | str):
        site (str):
        states (list[QueueState]):
    """

    count: int
    next_cursor: None | str
    site: str
    states: list[QueueState]

    def to_dict(self) -> dict[str, Any]:
        from ..models.queue_state import QueueState  # noqa: PLC0415

        count = self.count

        next_cursor: None | str
        next_cursor = self.next_cursor

        site = self.site

        states = []
        for states_item_data in self.states:
            states_item = states_item_data.to_dict()
            states.append(states_item)

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "count": count,
                "next_cursor": next_cursor,
                "site": site,
                "states": states,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.queue_state import QueueState  # noqa: PLC0415

        d = dict(src_dict)
        count = d.pop("count")

        def _parse_next_cursor(data: object) -> None | str:
            if data is None:
                return data
            return cast(None | str, data)

        next_cursor = _parse_next_cursor(d.pop("next_cursor"))

        site = d.pop("site")

        states = []
        _states = d.pop("states")
        for states_item_data in _states:
            states_item = QueueState.from_dict(states_item_data)

            states.append(states_item)

        queue_page = cls(
            count=count,
            next_cursor=next_cursor,
            site=site,
            states=states,
        )

        return queue_page
