from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from typing import cast


T = TypeVar("T", bound="WebhookSecret")


@_attrs_define
class WebhookSecret:
    """A new signing secret; the previous one also signs until ``previous_secret_until``.

    Attributes:
        previous_secret_until (float | None):
        secret (str):
        subscription_id (str):
    """

    previous_secret_until: float | None
    secret: str
    subscription_id: str

    def to_dict(self) -> dict[str, Any]:
        previous_secret_until: float | None
        previous_secret_until = self.previous_secret_until

        secret = self.secret

        subscription_id = self.subscription_id

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "previous_secret_until": previous_secret_until,
                "secret": secret,
                "subscription_id": subscription_id,
            }
        )

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)

        def _parse_previous_secret_until(data: object) -> float | None:
            if data is None:
                return data
            return cast(float | None, data)

        previous_secret_until = _parse_previous_secret_until(
            d.pop("previous_secret_until")
        )

        secret = d.pop("secret")

        subscription_id = d.pop("subscription_id")

        webhook_secret = cls(
            previous_secret_until=previous_secret_until,
            secret=secret,
            subscription_id=subscription_id,
        )

        return webhook_secret
