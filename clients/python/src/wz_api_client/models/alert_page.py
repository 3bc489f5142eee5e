from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast

if TYPE_CHECKING:
    from ..models.alert import Alert


T = TypeVar("T", bound="AlertPage")


@_attrs_define
class AlertPage:
    """A page of alert events (newest first unless asked otherwise); ``site`` is ``*`` for
    every site's.

        Attributes:
            alerts (list[Alert]):
            count (int):
            next_cursor (None | str):
            site (str):
    """

    alerts: list[Alert]
    count: int
    next_cursor: None | str
    site: str

    def to_dict(self) -> dict[str, Any]:
        from ..models.alert import Alert  # noqa: PLC0415

        alerts = []
        for alerts_item_data in self.alerts:
            alerts_item = alerts_item_data.to_dict()
            alerts.append(alerts_item)

        count = self.count

        next_cursor: None | str
        next_cursor = self.next_cursor

        site = self.site

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "alerts": alerts,
                "count": count,
                "next_cursor": next_cursor,
                "site": site,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        from ..models.alert import Alert  # noqa: PLC0415

        d = dict(src_dict)
        alerts = []
        _alerts = d.pop("alerts")
        for alerts_item_data in _alerts:
            alerts_item = Alert.from_dict(alerts_item_data)

            alerts.append(alerts_item)

        count = d.pop("count")

        def _parse_next_cursor(data: object) -> None | str:
            if data is None:
                return data
            return cast(None | str, data)

        next_cursor = _parse_next_cursor(d.pop("next_cursor"))

        site = d.pop("site")

        alert_page = cls(
            alerts=alerts,
            count=count,
            next_cursor=next_cursor,
            site=site,
        )

        return alert_page
