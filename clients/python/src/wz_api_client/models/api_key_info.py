from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.api_key_info_origin import ApiKeyInfoOrigin
from ..models.api_key_info_scope import ApiKeyInfoScope
from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="ApiKeyInfo")


@_attrs_define
class ApiKeyInfo:
    """A stored API key, without its secret.

    Attributes:
        created_at (float):
        key_id (str):
        name (str):
        origin (ApiKeyInfoOrigin):
        scope (ApiKeyInfoScope):
        dev_mode (bool | Unset):  Default: False.
        revoked_at (float | None | Unset):
    """

    created_at: float
    key_id: str
    name: str
    origin: ApiKeyInfoOrigin
    scope: ApiKeyInfoScope
    dev_mode: bool | Unset = False
    revoked_at: float | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        created_at = self.created_at

        key_id = self.key_id

        name = self.name

        origin = self.origin.value

        scope = self.scope.value

        dev_mode = self.dev_mode

        revoked_at: float | None | Unset
        if isinstance(self.revoked_at, Unset):
            revoked_at = UNSET
        else:
            revoked_at = self.revoked_at

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "created_at": created_at,
                "key_id": key_id,
                "name": name,
                "origin": origin,
                "scope": scope,
            }
        )
        if dev_mode is not UNSET:
            field_dict["dev_mode"] = dev_mode
        if revoked_at is not UNSET:
            field_dict["revoked_at"] = revoked_at

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        created_at = d.pop("created_at")

        key_id = d.pop("key_id")

        name = d.pop("name")

        origin = ApiKeyInfoOrigin(d.pop("origin"))

        scope = ApiKeyInfoScope(d.pop("scope"))

        dev_mode = d.pop("dev_mode", UNSET)

        def _parse_revoked_at(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        revoked_at = _parse_revoked_at(d.pop("revoked_at", UNSET))

        api_key_info = cls(
            created_at=created_at,
            key_id=key_id,
            name=name,
            origin=origin,
            scope=scope,
            dev_mode=dev_mode,
            revoked_at=revoked_at,
        )

        return api_key_info
