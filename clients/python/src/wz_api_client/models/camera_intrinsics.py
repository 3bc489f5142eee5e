from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar, BinaryIO, TextIO, TYPE_CHECKING, Generator

from attrs import define as _attrs_define
from attrs import field as _attrs_field

from ..types import UNSET, Unset

from ..types import UNSET, Unset
from typing import cast
from typing import Literal, cast


T = TypeVar("T", bound="CameraIntrinsics")


@_attrs_define
class CameraIntrinsics:
    """A pinhole camera: its resolution and horizontal field of view, or its calibration.

    A simulated (or roughly known) camera is its resolution and field of view: square pixels,
    the principal point at the image's centre, no distortion. A real camera names its
    calibration (``calibration_file``: OpenCV or ROS ``camera_info`` YAML, relative to the site
    file, see :mod:`wz_shared.camera_calibration`); :func:`load_site` reads it into the focal
    lengths, principal point and distortion below, and the resolution and field of view follow
    from it.

        Attributes:
            calibration_file (None | str | Unset):
            cx_px (float | None | Unset):
            cy_px (float | None | Unset):
            distortion (list[float] | None | Unset):
            fx_px (float | None | Unset):
            fy_px (float | None | Unset):
            height_px (int | Unset):  Default: 1200.
            horizontal_fov_deg (float | Unset):  Default: 90.0.
            kind (Literal['camera'] | Unset):  Default: 'camera'.
            width_px (int | Unset):  Default: 1200.
    """

    calibration_file: None | str | Unset = UNSET
    cx_px: float | None | Unset = UNSET
    cy_px: float | None | Unset = UNSET
    distortion: list[float] | None | Unset = UNSET
    fx_px: float | None | Unset = UNSET
    fy_px: float | None | Unset = UNSET
    height_px: int | Unset = 1200
    horizontal_fov_deg: float | Unset = 90.0
    kind: Literal["camera"] | Unset = "camera"
    width_px: int | Unset = 1200

    def to_dict(self) -> dict[str, Any]:
        calibration_file: None | str | Unset
        if isinstance(self.calibration_file, Unset):
            calibration_file = UNSET
        else:
            calibration_file = self.calibration_file

        cx_px: float | None | Unset
        if isinstance(self.cx_px, Unset):
            cx_px = UNSET
        else:
            cx_px = self.cx_px

        cy_px: float | None | Unset
        if isinstance(self.cy_px, Unset):
            cy_px = UNSET
        else:
            cy_px = self.cy_px

        distortion: list[float] | None | Unset
        if isinstance(self.distortion, Unset):
            distortion = UNSET
        elif isinstance(self.distortion, list):
            distortion = []
            for distortion_type_0_item_data in self.distortion:
                distortion_type_0_item: float
                distortion_type_0_item = distortion_type_0_item_data
                distortion.append(distortion_type_0_item)

        else:
            distortion = self.distortion

        fx_px: float | None | Unset
        if isinstance(self.fx_px, Unset):
            fx_px = UNSET
        else:
            fx_px = self.fx_px

        fy_px: float | None | Unset
        if isinstance(self.fy_px, Unset):
            fy_px = UNSET
        else:
            fy_px = self.fy_px

        height_px = self.height_px

        horizontal_fov_deg = self.horizontal_fov_deg

        kind = self.kind

        width_px = self.width_px

        field_dict: dict[str, Any] = {}

        field_dict.update({})
        if calibration_file is not UNSET:
            field_dict["calibration_file"] = calibration_file
        if cx_px is not UNSET:
            field_dict["cx_px"] = cx_px
        if cy_px is not UNSET:
            field_dict["cy_px"] = cy_px
        if distortion is not UNSET:
            field_dict["distortion"] = distortion
        if fx_px is not UNSET:
            field_dict["fx_px"] = fx_px
        if fy_px is not UNSET:
            field_dict["fy_px"] = fy_px
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

        def _parse_calibration_file(data: object) -> None | str | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(None | str | Unset, data)

        calibration_file = _parse_calibration_file(d.pop("calibration_file", UNSET))

        def _parse_cx_px(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        cx_px = _parse_cx_px(d.pop("cx_px", UNSET))

        def _parse_cy_px(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        cy_px = _parse_cy_px(d.pop("cy_px", UNSET))

        def _parse_distortion(data: object) -> list[float] | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            try:
                if not isinstance(data, list):
                    raise TypeError()
                distortion_type_0 = []
                _distortion_type_0 = data
                for distortion_type_0_item_data in _distortion_type_0:

                    def _parse_distortion_type_0_item(data: object) -> float:
                        return cast(float, data)

                    distortion_type_0_item = _parse_distortion_type_0_item(
                        distortion_type_0_item_data
                    )

                    distortion_type_0.append(distortion_type_0_item)

                return distortion_type_0
            except (TypeError, ValueError, AttributeError, KeyError):
                pass
            return cast(list[float] | None | Unset, data)

        distortion = _parse_distortion(d.pop("distortion", UNSET))

        def _parse_fx_px(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        fx_px = _parse_fx_px(d.pop("fx_px", UNSET))

        def _parse_fy_px(data: object) -> float | None | Unset:
            if data is None:
                return data
            if isinstance(data, Unset):
                return data
            return cast(float | None | Unset, data)

        fy_px = _parse_fy_px(d.pop("fy_px", UNSET))

        height_px = d.pop("height_px", UNSET)

        horizontal_fov_deg = d.pop("horizontal_fov_deg", UNSET)

        kind = cast(Literal["camera"] | Unset, d.pop("kind", UNSET))
        if kind != "camera" and not isinstance(kind, Unset):
            raise ValueError(f"kind must match const 'camera', got '{kind}'")

        width_px = d.pop("width_px", UNSET)

        camera_intrinsics = cls(
            calibration_file=calibration_file,
            cx_px=cx_px,
            cy_px=cy_px,
            distortion=distortion,
            fx_px=fx_px,
            fy_px=fy_px,
            height_px=height_px,
            horizontal_fov_deg=horizontal_fov_deg,
            kind=kind,
            width_px=width_px,
        )

        return camera_intrinsics
