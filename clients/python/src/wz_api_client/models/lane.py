from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset


T = TypeVar("T", bound="Lane")


@_attrs_define
class Lane:
    """One lane of the carriageway; ``index`` 0 is the rightmost lane (SUMO's convention).

    Attributes:
        center_offset_m (float):
        index (int):
        width_m (float | Unset):  Default: 3.66.
    """

    center_offset_m: float
    index: int
    width_m: float | Unset = 3.66

    def to_dict(self) -> dict[str, Any]:
        center_offset_m = self.center_offset_m

        index = self.index

        width_m = self.width_m

        field_dict: dict[str, Any] = {}

        field_dict.update(
            {
                "center_offset_m": center_offset_m,
                "index": index,
            }
        )
        if width_m is not UNSET:
            field_dict["width_m"] = width_m

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        center_offset_m = d.pop("center_offset_m")

        index = d.pop("index")

        width_m = d.pop("width_m", UNSET)

        lane = cls(
            center_offset_m=center_offset_m,
            index=index,
            width_m=width_m,
        )

        return lane
