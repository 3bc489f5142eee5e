from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset


T = TypeVar("T", bound="SiteSummary")


@_attrs_define
class SiteSummary:
    """One site a gateway serves.

    Attributes:
        default (bool):
        name (str):
        site_id (str):
    """

    default: bool
    name: str
    site_id: str

    def to_dict(self) -> dict[str, Any]:
        default = self.default

        name = self.name

        site_id = self.site_id

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "default": default,
                "name": name,
                "site_id": site_id,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        default = d.pop("default")

        name = d.pop("name")

        site_id = d.pop("site_id")

        site_summary = cls(
            default=default,
            name=name,
            site_id=site_id,
        )

        return site_summary
