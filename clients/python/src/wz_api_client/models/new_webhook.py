from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..models.alert_severity import AlertSeverity
from ..models.new_webhook_phases_type_0_item import NewWebhookPhasesType0Item
from ..types import UNSET, Unset
from typing import cast


T = TypeVar("T", bound="NewWebhook")


@_attrs_define
class NewWebhook:
    """Subscribe a URL to alert events (admin). Each event is POSTed as signed JSON (Standard
    Webhooks); the secret to check the signatures is in the answer, once.

        Attributes:
            url (str): http(s) URL the events are POSTed to; its host must resolve to public addresses unless the settings
                allow others
            description (str | Unset):  Default: ''.
            event_types (list[str] | Unset): `alert.*` for every alert, or `alert.<type>` (`alert.speeding`...)
            min_severity (AlertSeverity | None | Unset):
            phases (list[NewWebhookPhasesType0Item] | None | Unset):
    """

    url: str
    description: str | Unset = ""
    event_types: list[str] | Unset = UNSET
    min_severity: AlertSeverity | None | Unset = UNSET
    phases: list[NewWebhookPhasesType0Item] | None | Unset = UNSET

    def to_dict(self) -> dict[str, Any]:
        url = self.url

        description = self.description

        event_types: list[str] | Unset = UNSET
        if not isinstance(self.event_types, Unset):
            event_types = self.event_types

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

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "url": url,
            }
        )
        if description is not UNSET:
            field_dict["description"] = description
        if event_types is not UNSET:
            field_dict["event_types"] = event_types
        if min_severity is not UNSET:
            field_dict["min_severity"] = min_severity
        if phases is not UNSET:
            field_dict["phases"] = phases

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        url = d.pop("url")

        description = d.pop("description", UNSET)

        event_types = cast(list[str], d.pop("event_types", UNSET))

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
        ) -> list[NewWebhookPhasesType0Item] | None | Unset:
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
                    phases_type_0_item = NewWebhookPhasesType0Item(
                        phases_type_0_item_data
                    )

                    phases_type_0.append(phases_type_0_item)

                return phases_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(list[NewWebhookPhasesType0Item] | None | Unset, data)

        phases = _parse_phases(d.pop("phases", UNSET))

        new_webhook = cls(
            url=url,
            description=description,
            event_types=event_types,
            min_severity=min_severity,
            phases=phases,
        )

        return new_webhook
