from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast
import datetime


T = TypeVar("T", bound="Schedule")


@_attrs_define
class Schedule:
    """When the work zone is in place (the contract's or the traffic control plan's dates):
    the WZDx WorkZoneFeed's ``start_date`` and ``end_date``, and whether each is verified
    (``is_start_date_verified``, ``is_end_date_verified``: confirmed by someone at the site).

    Both are ISO 8601 date-times with a UTC offset (``2026-05-04T07:00:00-05:00`` or
    ``...Z``): a time without one names no instant.

        Attributes:
            end (datetime.datetime):
            start (datetime.datetime):
            end_verified (bool | Unset):  Default: False.
            start_verified (bool | Unset):  Default: False.
    """

    end: datetime.datetime
    start: datetime.datetime
    end_verified: bool | Unset = False
    start_verified: bool | Unset = False

    def to_dict(self) -> dict[str, Any]:
        end = self.end.isoformat()

        start = self.start.isoformat()

        end_verified = self.end_verified

        start_verified = self.start_verified

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "end": end,
                "start": start,
            }
        )
        if end_verified is not UNSET:
            field_dict["end_verified"] = end_verified
        if start_verified is not UNSET:
            field_dict["start_verified"] = start_verified

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        end = datetime.datetime.fromisoformat(d.pop("end"))

        start = datetime.datetime.fromisoformat(d.pop("start"))

        end_verified = d.pop("end_verified", UNSET)

        start_verified = d.pop("start_verified", UNSET)

        schedule = cls(
            end=end,
            start=start,
            end_verified=end_verified,
            start_verified=start_verified,
        )

        return schedule
