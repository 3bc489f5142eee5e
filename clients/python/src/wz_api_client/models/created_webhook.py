from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.alert_severity import AlertSeverity
from ..models.created_webhook_phases_type_0_item import CreatedWebhookPhasesType0Item
from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="CreatedWebhook")


@_attrs_define
class CreatedWebhook:
    """A subscription just made: its signing secret (``whsec_...``) is shown this once.

    Attributes:
        created_at (float):
        description (str):
        event_types (list[str]):
        secret (str):
        subscription_id (str):
        url (str):
        disabled_at (float | None | Unset):
        disabled_reason (None | str | Unset):
        min_severity (AlertSeverity | None | Unset):
        phases (list[CreatedWebhookPhasesType0Item] | None | Unset):
        previous_secret_until (float | None | Unset):
    """

    created_at: float
    description: str
    event_types: list[str]
    secret: str
    subscription_id: str
    url: str
    disabled_at: float | None | Unset = UNSET
    disabled_reason: None | str | Unset = UNSET
    min_severity: AlertSeverity | None | Unset = UNSET
    phases: list[CreatedWebhookPhasesType0Item] | None | Unset = UNSET
    previous_secret_until: float | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        created_at = self.created_at

        description = self.description

        event_types = self.event_types

        secret = self.secret

        subscription_id = self.subscription_id

        url = self.url

        disabled_at: float | None | Unset
        if isinstance(self.disabled_at, Unset):
            disabled_at = UNSET
        else:
            disabled_at = self.disabled_at

        disabled_reason: None | str | Unset
        if isinstance(self.disabled_reason, Unset):
            disabled_reason = UNSET
        else:
            disabled_reason = self.disabled_reason

        min_severity: None | str | Unset
        if isinstance(self.min_severity, Unset):
            min_severity = UNSET
        elif isinstance(self.min_severity, AlertSeverity):
            min_severity = self.min_severity.value
        else:
            min_severity = self.min_severity

        phases: list[str] | None | Unset
        if isinstance(self.phases, Unset):
            phases = UNSET
        elif isinstance(self.phases, list):
            phases = []
            for phases_type_0_item_data in self.phases:
                phases_type_0_item = phases_type_0_item_data.value
                phases.append(phases_type_0_item)

        else:
            phases = self.phases

        previous_secret_until: float | None | Unset
        if isinstance(self.previous_secret_until, Unset):
            previous_secret_until = UNSET
        else:
            previous_secret_until = self.previous_secret_until

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "created_at": created_at,
                "description": description,
                "event_types": event_types,
                "secret": secret,
                "subscription_id": subscription_id,
                "url": url,
            }
        )
        if disabled_at is not UNSET:
            field_dict["disabled_at"] = disabled_at
        if disabled_reason is not UNSET:
            field_dict["disabled_reason"] = disabled_reason
        if min_severity is not UNSET:
            field_dict["min_severity"] = min_severity
        if phases is not UNSET:
            field_dict["phases"] = phases
        if previous_secret_until is not UNSET:
            field_dict["previous_secret_until"] = previous_secret_until

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        created_at = d.pop("created_at")

        description = d.pop("description")

        event_types = cast(list[str], d.pop("event_types"))

        secret = d.pop("secret")

        subscription_id = d.pop("subscription_id")

        url = d.pop("url")

        def _parse_disabled_at(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        disabled_at = _parse_disabled_at(d.pop("disabled_at", UNSET))

        def _parse_disabled_reason(data: object) -> None | str | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(None | str | Unset, data)

        disabled_reason = _parse_disabled_reason(d.pop("disabled_reason", UNSET))

        def _parse_min_severity(data: object) -> AlertSeverity | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, str):
                    raise TypeError()
                min_severity_type_0 = AlertSeverity(data)

                return min_severity_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(AlertSeverity | None | Unset, data)

        min_severity = _parse_min_severity(d.pop("min_severity", UNSET))

        def _parse_phases(
            data: object,
        ) -> list[CreatedWebhookPhasesType0Item] | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, list):
                    raise TypeError()
                phases_type_0 = []
                _phases_type_0 = data
                for phases_type_0_item_data in _phases_type_0:
                    phases_type_0_item = CreatedWebhookPhasesType0Item(
                        phases_type_0_item_data
                    )

                    phases_type_0.append(phases_type_0_item)

                return phases_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(list[CreatedWebhookPhasesType0Item] | None | Unset, data)

        phases = _parse_phases(d.pop("phases", UNSET))

        def _parse_previous_secret_until(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        previous_secret_until = _parse_previous_secret_until(
            d.pop("previous_secret_until", UNSET)
        )

        created_webhook = cls(
            created_at=created_at,
            description=description,
            event_types=event_types,
            secret=secret,
            subscription_id=subscription_id,
            url=url,
            disabled_at=disabled_at,
            disabled_reason=disabled_reason,
            min_severity=min_severity,
            phases=phases,
            previous_secret_until=previous_secret_until,
        )

        return created_webhook
