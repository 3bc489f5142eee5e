from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.new_api_key_scope import NewApiKeyScope


T = TypeVar("T", bound="NewApiKey")


@_attrs_define
class NewApiKey:
    """Ask for a new key (admin).

    Attributes:
        name (str):
        scope (NewApiKeyScope):
    """

    name: str
    scope: NewApiKeyScope

    def to_dict(self) -> dict[str, Any]:
        name = self.name

        scope = self.scope.value

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "name": name,
                "scope": scope,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        name = d.pop("name")

        scope = NewApiKeyScope(d.pop("scope"))

        new_api_key = cls(
            name=name,
            scope=scope,
        )

        return new_api_key
