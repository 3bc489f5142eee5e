from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import Literal, cast


T = TypeVar("T", bound="CameraIntrinsics")


@_attrs_define
class CameraIntrinsics:
    """A pinhole camera given by its horizontal field of view and resolution.

    Attributes:
        height_px (int | Unset):  Default: 1200.
        horizontal_fov_deg (float | Unset):  Default: 90.0.
        kind (Literal['camera'] | Unset):  Default: 'camera'.
        width_px (int | Unset):  Default: 1200.
    """

    height_px: int | Unset = 1200
    horizontal_fov_deg: float | Unset = 90.0
    kind: Literal["camera"] | Unset = "camera"
    width_px: int | Unset = 1200

    def to_dict(self) -> dict[str, Any]:
        height_px = self.height_px

        horizontal_fov_deg = self.horizontal_fov_deg

        kind = self.kind

        width_px = self.width_px

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if height_px is not UNSET:
            field_dict["height_px"] = height_px
        if horizontal_fov_deg is not UNSET:
            field_dict["horizontal_fov_deg"] = horizontal_fov_deg
        if kind is not UNSET:
            field_dict["kind"] = kind
        if width_px is not UNSET:
            field_dict["width_px"] = width_px

        return field_dict

    @classmethod
    def from_dict(cls: type[T], src_dict: Mapping[str, Any]) -> T:
        d = dict(src_dict)
        height_px = d.pop("height_px", UNSET)

        horizontal_fov_deg = d.pop("horizontal_fov_deg", UNSET)

        kind = cast(Literal["camera"] | Unset, d.pop("kind", UNSET))
        if kind != "camera" and not isinstance(kind, Unset):
            raise ValueError(f"kind must match const 'camera', got '{kind}'")

        width_px = d.pop("width_px", UNSET)

        camera_intrinsics = cls(
            height_px=height_px,
            horizontal_fov_deg=horizontal_fov_deg,
            kind=kind,
            width_px=width_px,
        )

        return camera_intrinsics
