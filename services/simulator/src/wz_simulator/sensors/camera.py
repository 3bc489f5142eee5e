"""A roadside pinhole camera: the renderer of frames a detector can learn from.

The camera is made of rooms, all pure (no bus, no files):

- :mod:`wz_shared.camera_geometry`: :class:`PinholeCamera`, the geometry (shared so that the
  camera detector ranges with it without depending on the simulator), re-exported here with
  :func:`backproject_to_ground`, :func:`paper_pixel_angles` and
  :func:`paper_flat_road_ground_point`. The renderer draws with the ideal pinhole (no lens
  distortion).
- :mod:`~wz_simulator.sensors.camera_projection`: clipping in 3D and projection of quads to
  OpenCV fixed-point polygons; per-pixel plane depth.
- :mod:`~wz_simulator.sensors.camera_paint`: what is drawn of a box: faces, decals (windows,
  lamps, plates...), and how a vehicle's boxes fit together.
- :mod:`~wz_simulator.sensors.camera_light`: what the weather means for the picture (sun, sky,
  haze, rain, lamps).
- :mod:`~wz_simulator.sensors.camera_effects`: rain streaks, motion blur, read noise, lamp glow.
- :mod:`~wz_simulator.sensors.camera_frame`: the frame and its truth labels, JPEG encoding,
  the truth overlay.
- here, :class:`CameraModel`: the renderer. Sky, ground polygons and static boxes are drawn
  once into a background image and depth buffer (the camera does not move); each frame draws
  only the vehicles' boxes, shaded by the sun, far to near (painter's algorithm on faces, faces
  clipped in 3D at the near plane), with windows, wheels, lamps and a little texture, then
  weather and sensor effects. Each frame carries truth labels (2D box, class, visibility) from
  an id buffer.

Frames and pixels
-----------------
- Site frame: ENU metres. Sensor frame (the mount's pose): x forward, y left, z up.
- Camera (optical) frame: z forward along the optical axis, x right, y down;
  ``p_optical = (-y_sensor, -z_sensor, x_sensor)``.
- Continuous pixel coordinates ``(u, v)``: the image spans ``[0, W] x [0, H]``, ``u`` to the
  right and ``v`` down; pixel (row ``i``, column ``j``) covers ``[j, j + 1) x [i, i + 1)`` and its
  centre is ``(j + 0.5, i + 0.5)``. The principal point is the image centre ``(W / 2, H / 2)``,
  as in the paper's Eq. 1. Truth boxes use the same coordinates (pixel edges).
- Depth: the optical z of a point [m] (distance along the optical axis, not the range).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import replace
from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F32, F64, I32, U8, Bool, IntP

# Re-exported (``X as X``): the geometry moved to the shared library, the frame and its truth
# to camera_frame; their names stay here.
from wz_shared.camera_geometry import LensDistortion as LensDistortion
from wz_shared.camera_geometry import PinholeCamera as PinholeCamera
from wz_shared.camera_geometry import backproject_to_ground as backproject_to_ground
from wz_shared.camera_geometry import paper_flat_road_ground_point as paper_flat_road_ground_point
from wz_shared.camera_geometry import paper_pixel_angles as paper_pixel_angles
from wz_shared.messages import VehicleClass
from wz_shared.site import SensorMount
from wz_simulator.sensors.camera_effects import SensorEffects
from wz_simulator.sensors.camera_frame import CameraFrame as CameraFrame
from wz_simulator.sensors.camera_frame import CameraTruthLabel as CameraTruthLabel
from wz_simulator.sensors.camera_frame import draw_truth as draw_truth
from wz_simulator.sensors.camera_frame import encode_jpeg as encode_jpeg
from wz_simulator.sensors.camera_frame import mask_box
from wz_simulator.sensors.camera_light import KOSCHMIEDER as KOSCHMIEDER
from wz_simulator.sensors.camera_light import atmosphere, lighting_for, shade
from wz_simulator.sensors.camera_paint import (
    GLASS,
    LAMP_GLOW_RGB,
    LAMP_KINDS,
    LAYER_BASE,
    LAYER_STACKED,
    LIGHT,
    ROLE_DRUM,
    TIRE,
    BoxArrays,
    Quads,
    build_quads,
    vehicle_structure,
)
from wz_simulator.sensors.camera_projection import ONE, SHIFT, Projector
from wz_simulator.sensors.scene import Box, GroundPolygon, Material, Weather


class StaticSceneLike(Protocol):
    """The static scene as the scene module builds it: boxes and ground polygons."""

    @property
    def boxes(self) -> Sequence[Box]: ...

    @property
    def ground(self) -> Sequence[GroundPolygon]: ...


def vehicle_class_guess(materials: IntP, sizes: F64) -> VehicleClass:
    if (materials == Material.TRUCK_BODY).any() or float(sizes[:, 0].max()) > 7.5:
        return VehicleClass.TRUCK
    return VehicleClass.CAR


class CameraModel:
    """Renders camera frames of vehicles in front of a fixed, pre-rendered background.

    Parameters
    ----------
    mount
        The camera's mount (pose, intrinsics).
    static_boxes
        Static scene boxes (drums, signs, barriers, guardrail, trailer...), site frame.
    static_ground
        Ground polygons (z = 0), drawn in order (later over earlier); the rest of the ground is
        terrain.
    weather
        Light, rain and fog.
    seed
        Seed of the sensor noise and rain streaks; the same seed and calls give the same frames.
    blur_sigma_px
        Optical blur (Gaussian sigma [px]); 0 for none.
    motion_blur_px
        Length of a horizontal motion blur [px] (mast sway, long exposure); 0 for none.
    noise_std
        Gaussian read noise [digital numbers]; None for the weather's default (2 by day,
        5 at dusk).
    near_m
        Near clipping plane [m].
    """

    def __init__(
        self,
        mount: SensorMount,
        static_boxes: Sequence[Box],
        static_ground: Sequence[GroundPolygon],
        weather: Weather | None = None,
        seed: int = 0,
        *,
        blur_sigma_px: float = 0.6,
        motion_blur_px: float = 0.0,
        noise_std: float | None = None,
        near_m: float = 0.05,
    ) -> None:
        # The renderer draws an ideal pinhole (a calibrated camera's focal lengths and principal
        # point, not its lens distortion): truth boxes and pixels agree with each other.
        self.camera = PinholeCamera(mount, LensDistortion())
        #: Rotation from the sensor frame to the site frame of the mount drawn from, (3, 3).
        self.rotation: F64 = mount.pose.rotation()
        self.weather = weather if weather is not None else Weather()
        self.blur_sigma_px = blur_sigma_px
        self.motion_blur_px = motion_blur_px
        self.near_m = near_m
        self._lighting = lighting_for(self.weather)
        if noise_std is not None:
            self._lighting = replace(self._lighting, noise_std=noise_std)
        self._rng = np.random.default_rng(seed)
        self._projector = Projector(self.camera, near_m)
        width, height = self.camera.width_px, self.camera.height_px
        self._background, self._static_box_depth = self._render_background(
            list(static_boxes), list(static_ground)
        )
        if blur_sigma_px > 0.0:
            cv2.GaussianBlur(self._background, (3, 3), blur_sigma_px, dst=self._background)
        self._static_mask = np.isfinite(self._static_box_depth).astype(np.uint8)
        self._static_integral = cv2.integral(self._static_mask)
        self._silhouette_scratch = np.zeros((height, width), dtype=np.uint8)
        # After the background: the effects' pre-drawn layers draw from the same generator.
        self._effects = SensorEffects(
            self._lighting,
            width,
            height,
            self._rng,
            blur_sigma_px=blur_sigma_px,
            motion_blur_px=motion_blur_px,
        )

    @classmethod
    def from_scene(
        cls,
        mount: SensorMount,
        scene: StaticSceneLike,
        weather: Weather | None = None,
        seed: int = 0,
    ) -> CameraModel:
        """A model over a static scene with ``boxes`` and ``ground`` (e.g. ``static_scene``)."""
        return cls(mount, scene.boxes, scene.ground, weather, seed)

    @property
    def background(self) -> U8:
        """The pre-rendered static background (BGR, before sensor effects), (H, W, 3)."""
        return self._background

    @property
    def static_box_depth(self) -> F32:
        """Optical depth [m] of the nearest static box at each pixel (inf: none), (H, W)."""
        return self._static_box_depth

    # --- background ---------------------------------------------------------------------------

    def _render_background(self, boxes: list[Box], ground: list[GroundPolygon]) -> tuple[U8, F32]:
        """Sky, terrain, ground polygons and static boxes with a z-buffer; weather applied."""
        cam = self.camera
        lighting = self._lighting
        width, height = cam.width_px, cam.height_px
        rx = self._projector.ray_x.astype(np.float64)[None, :]
        ry = self._projector.ray_y.astype(np.float64)[:, None]
        rot = cam.rotation_site_from_camera
        dir_z = rot[2, 0] * rx + rot[2, 1] * ry + rot[2, 2]  # site z of the unit-depth ray
        ray_norm = np.sqrt(rx * rx + ry * ry + 1.0)
        elevation = dir_z / ray_norm
        # Sky: horizon colour at and below the horizon, zenith colour overhead.
        blend = np.clip(elevation, 0.0, 1.0) ** 0.6
        rgb = (
            lighting.sky_horizon_rgb * (1.0 - blend)[..., None]
            + lighting.sky_zenith_rgb * blend[..., None]
        )
        # Ground z = 0 where the ray descends: depth t = -C_z / d_z.
        cam_z = float(cam.position_m[2])
        descending = (dir_z < -1e-9) & (cam_z > 0.0)
        ground_depth = np.where(descending, cam_z / np.where(descending, -dir_z, 1.0), np.inf)
        ground_rgb = np.empty((height, width, 3))
        ground_rgb[:] = lighting.terrain_rgb
        material_wet = np.ones((height, width))
        for polygon in ground:
            vertices = np.asarray(polygon.vertices_xy_m, dtype=np.float64)
            if vertices.shape[0] < 3:
                continue
            projected = self._projector.project_polygon(
                np.column_stack([vertices, np.zeros(vertices.shape[0])])
            )
            if projected is None:
                continue
            pts, (x0, y0, x1, y1) = projected
            mask = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
            offset = np.array([x0 << SHIFT, y0 << SHIFT], dtype=np.int32)
            cv2.fillPoly(mask, [pts - offset], 1, cv2.LINE_8, SHIFT)
            inside = mask.astype(bool)
            ground_rgb[y0:y1, x0:x1][inside] = np.asarray(polygon.color_rgb, dtype=np.float64)
            wet = lighting.wet_road if polygon.material == Material.ASPHALT else 1.0
            material_wet[y0:y1, x0:x1][inside] = wet
        # A little texture on the ground (fixed: the camera does not move).
        coarse = self._rng.normal(0.0, 1.0, (height // 4 + 1, width // 4 + 1))
        smooth = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_LINEAR)
        texture = 1.0 + 0.035 * smooth + 0.02 * self._rng.normal(0.0, 1.0, (height, width))
        up = np.array([0.0, 0.0, 1.0])
        ground_gain = shade(lighting, up) * material_wet[..., None] * texture[..., None]
        rgb = np.where(descending[..., None], ground_rgb * ground_gain, rgb)
        depth = ground_depth.copy()
        box_depth = np.full((height, width), np.inf)
        if boxes:
            self._rasterise_static_boxes(boxes, rgb, box_depth)
        depth = np.minimum(depth, box_depth)
        range_m = depth * ray_norm
        sky = ~np.isfinite(depth)
        hazed = atmosphere(lighting, rgb, np.where(sky, 0.0, range_m))
        if lighting.foggy:
            hazed[sky] = atmosphere(lighting, rgb[sky], np.full(int(sky.sum()), np.inf))
        image = np.clip(hazed[..., ::-1], 0.0, 255.0).astype(np.uint8)
        return np.ascontiguousarray(image), box_depth.astype(np.float32)

    def _rasterise_static_boxes(self, boxes: list[Box], rgb: F64, box_depth: F64) -> None:
        """Z-buffered static boxes (exact per-pixel plane depth) into ``rgb`` and ``box_depth``."""
        arrays = BoxArrays.from_boxes(boxes)
        count = len(boxes)
        roles = np.where(arrays.materials == Material.DRUM, ROLE_DRUM, 0).astype(np.intp)
        face_rgb = np.repeat(arrays.colors_rgb[:, None, :], 6, axis=1)
        quads = build_quads(arrays, face_rgb, roles)
        facing = self._projector.front_facing(quads)
        projected = self._projector.project_quads(quads.site, facing)
        gain = shade(self._lighting, quads.normal)
        emissive = (arrays.materials == Material.LIGHT)[quads.face // 6]
        colour = np.where(emissive[:, None], quads.base_rgb, quads.base_rgb * gain)
        normal_cam, offset = self._projector.face_planes(
            quads.site[: count * 6], quads.normal[: count * 6]
        )
        for q, pts in enumerate(projected.polygons):
            if pts is None:
                continue
            x0, y0, x1, y1 = (int(b) for b in projected.bounds[q])
            if x1 < x0 or y1 < y0:
                continue
            mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), dtype=np.uint8)
            shifted = pts - np.array([x0 << SHIFT, y0 << SHIFT], dtype=np.int32)
            cv2.fillConvexPoly(mask, shifted, 1, cv2.LINE_8, SHIFT)
            rows, cols = np.nonzero(mask)
            if rows.size == 0:
                continue
            rows += y0
            cols += x0
            face = int(quads.face[q])
            depth = self._projector.plane_depth(
                normal_cam[face : face + 1], offset[face : face + 1], rows, cols
            )
            current = box_depth[rows, cols]
            # A decal lies on its face: it wins where that face (or anything as near) is seen.
            nearer = depth <= current + 1e-3 if quads.kind[q] >= 0 else depth < current
            rows, cols = rows[nearer], cols[nearer]
            box_depth[rows, cols] = depth[nearer]
            rgb[rows, cols] = colour[q]

    # --- vehicles -----------------------------------------------------------------------------

    def render(
        self,
        boxes_of_vehicles: Sequence[Box],
        vehicle_ids: Sequence[str],
        stamp: float,
        vehicle_classes: Sequence[VehicleClass] | None = None,
        *,
        rotation: F64 | None = None,
    ) -> CameraFrame:
        """Render one frame of the vehicles in front of the static background.

        Parameters
        ----------
        boxes_of_vehicles
            All vehicles' boxes; a box's ``label`` is the 1-based index of its vehicle in
            ``vehicle_ids``.
        vehicle_ids
            Ids of the vehicles, in label order.
        stamp
            Capture time [s] (carried to the frame).
        vehicle_classes
            Class of each vehicle; None to guess (truck when it has TRUCK_BODY boxes or is
            longer than 7.5 m, else car).
        rotation
            The camera's true orientation at capture (sensor to site, (3, 3)) when it has
            turned from :attr:`rotation` (a real mast's sway and settling, see
            :mod:`~wz_simulator.sensors.mast`): the frame is drawn from the mount, then turned
            (:meth:`_turned`) before the sensor effects. None: as mounted.

        Returns
        -------
        CameraFrame
            Image (BGR uint8, H x W x 3) and one truth label per vehicle, in ``vehicle_ids``
            order.
        """
        count_vehicles = len(vehicle_ids)
        if vehicle_classes is not None and len(vehicle_classes) != count_vehicles:
            raise ValueError(
                f"{len(vehicle_classes)} vehicle classes for {count_vehicles} vehicle ids"
            )
        cam = self.camera
        image = self._background.copy()
        face_dtype = np.int16 if 6 * len(boxes_of_vehicles) < 32000 else np.int32
        face_buffer = np.full((cam.height_px, cam.width_px), -1, dtype=face_dtype)
        classes = (
            list(vehicle_classes)
            if vehicle_classes is not None
            else [VehicleClass.UNKNOWN] * count_vehicles
        )
        labels: dict[int, CameraTruthLabel] = {}
        face_vehicle = np.zeros(0, dtype=np.int16)
        if boxes_of_vehicles:
            arrays = BoxArrays.from_boxes(boxes_of_vehicles)
            if arrays.labels.min() < 1 or arrays.labels.max() > count_vehicles:
                raise ValueError(
                    f"vehicle box labels must be 1..{count_vehicles} (one per vehicle id), got "
                    f"{int(arrays.labels.min())}..{int(arrays.labels.max())}"
                )
            arrays = arrays.take(np.argsort(arrays.labels, kind="stable"))
            vehicle_of_box = arrays.labels - 1
            if vehicle_classes is None:
                present = np.unique(vehicle_of_box)
                starts = np.searchsorted(vehicle_of_box, present, side="left")
                ends = np.searchsorted(vehicle_of_box, present, side="right")
                for vehicle, start, end in zip(present.tolist(), starts, ends, strict=True):
                    classes[vehicle] = vehicle_class_guess(
                        arrays.materials[start:end], arrays.sizes[start:end]
                    )
            labels = self._draw_vehicles(image, face_buffer, arrays, vehicle_ids, classes)
            face_vehicle = np.repeat(vehicle_of_box, 6).astype(np.int16)
        if rotation is not None:
            image, face_buffer, labels = self._turned(
                image, face_buffer, labels, face_vehicle, rotation
            )
        self._effects.apply(image)
        ordered = tuple(
            labels.get(i) or CameraTruthLabel(vid, i, classes[i], None, None, 0, 0)
            for i, vid in enumerate(vehicle_ids)
        )
        return CameraFrame(stamp, image, ordered, face_buffer, face_vehicle)

    def _turned(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        labels: dict[int, CameraTruthLabel],
        face_vehicle: npt.NDArray[np.int16],
        rotation: F64,
    ) -> tuple[U8, npt.NDArray[np.int16] | npt.NDArray[np.int32], dict[int, CameraTruthLabel]]:
        """The frame as the camera turned to ``rotation`` (sensor to site) sees it.

        A pinhole turning about its centre sees the same rays, re-sorted: a pixel ``x`` of the
        mount's view is at ``x' ~ K R'^T R K^-1 x`` in the turned one (``R, R'``: optical to
        site, before and after; ``K`` the intrinsics), exact for everything in view, near or
        far. The image is resampled bilinearly, the borders newly in view repeat the edge's
        pixels (a pixel or two for a mast's sway), the face buffer takes the nearest face and
        the truth boxes the bounding box of their turned corners, clipped to the image; the
        visible pixels are counted again, the silhouette's are kept (a turn of a fraction of a
        degree keeps areas).
        """
        cam = self.camera
        width, height = cam.width_px, cam.height_px
        optical_turned = rotation @ self.rotation.T @ cam.rotation_site_from_camera
        homography = cam.K @ optical_turned.T @ cam.rotation_site_from_camera @ np.linalg.inv(cam.K)
        # OpenCV puts pixel centres at integers, the continuous coordinates at + 0.5.
        centre = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
        opencv = np.linalg.inv(centre) @ homography @ centre
        turned_image: U8 = np.asarray(
            cv2.warpPerspective(
                image,
                opencv,
                (width, height),
                flags=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            ),
            dtype=np.uint8,
        )
        turned_faces = face_buffer.copy()
        cv2.warpPerspective(
            face_buffer,
            opencv,
            (width, height),
            dst=turned_faces,
            flags=cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=-1,
        )
        if not labels:
            return turned_image, turned_faces, labels
        lookup = np.append(face_vehicle, np.int16(-1)).astype(np.intp)
        visible = np.bincount(lookup[turned_faces].ravel() + 1, minlength=len(face_vehicle) + 1)

        def turned_box(
            box: tuple[float, float, float, float] | None,
        ) -> tuple[float, float, float, float] | None:
            if box is None:
                return None
            x0, y0, x1, y1 = box
            corners = np.array([[x0, y0, 1.0], [x1, y0, 1.0], [x1, y1, 1.0], [x0, y1, 1.0]])
            mapped = corners @ homography.T
            xy = mapped[:, :2] / mapped[:, 2:3]
            left, right = (float(np.clip(v, 0.0, width)) for v in (xy[:, 0].min(), xy[:, 0].max()))
            top, bottom = (float(np.clip(v, 0.0, height)) for v in (xy[:, 1].min(), xy[:, 1].max()))
            return (left, top, right, bottom) if right > left and bottom > top else None

        turned_labels = {}
        for index, label in labels.items():
            count = int(visible[index + 1])
            turned_labels[index] = replace(
                label,
                box_xyxy_px=turned_box(label.box_xyxy_px) if count else None,
                full_box_xyxy_px=turned_box(label.full_box_xyxy_px),
                visible_pixels=count,
            )
        return turned_image, turned_faces, turned_labels

    def _draw_vehicles(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        arrays: BoxArrays,
        vehicle_ids: Sequence[str],
        classes: Sequence[VehicleClass],
    ) -> dict[int, CameraTruthLabel]:
        """Shadows, vehicles (painter's order), static occlusion, truth, lamp glow, blur.

        ``arrays`` holds the boxes sorted by label. Draws into ``image`` and ``face_buffer``;
        returns the labels of vehicles with at least one pixel in the image, by 0-based index.
        """
        count_boxes = arrays.centers.shape[0]
        face_count = count_boxes * 6
        vehicle_of_box = arrays.labels - 1
        present = np.unique(vehicle_of_box)
        starts = np.searchsorted(vehicle_of_box, present, side="left")
        ends = np.searchsorted(vehicle_of_box, present, side="right")
        base, layer, roles, allowed, body_rgb = vehicle_structure(arrays, starts, ends)

        # Face colours: the body colour on a GLASS cabin (its windows are decals), dark tyres.
        face_rgb = np.repeat(arrays.colors_rgb[:, None, :], 6, axis=1)
        glass_body = (arrays.materials == GLASS) & (layer == LAYER_STACKED)
        face_rgb[glass_body] = body_rgb[glass_body][:, None, :]
        face_rgb[arrays.materials == TIRE] = (26.0, 26.0, 29.0)
        # A little texture: each face a shade lighter or darker, fixed per vehicle.
        salt = np.array([zlib.crc32(v.encode()) % 100003 for v in vehicle_ids], dtype=np.float64)
        key = (
            salt[vehicle_of_box][:, None]
            + np.arange(6)[None, :] * 7.13
            + (np.arange(count_boxes) - np.repeat(starts, ends - starts))[:, None] * 3.7
        )
        jitter = 1.0 + 0.05 * np.modf(np.sin(key) * 43758.5453)[0]
        quads = build_quads(arrays, face_rgb * jitter[..., None], roles, allowed)
        box_of_quad = quads.face // 6
        facing = self._projector.front_facing(quads)
        facing[face_count:] = facing[quads.face[face_count:]]
        projected = self._projector.project_quads(quads.site, facing)
        polygons = projected.polygons

        # Shading, lamps, haze.
        lighting = self._lighting
        colour = quads.base_rgb * shade(lighting, quads.normal)
        emissive = arrays.materials[box_of_quad] == LIGHT
        colour[emissive] = quads.base_rgb[emissive] * (1.6 if lighting.lamps_on else 0.9)
        lamp = np.isin(quads.kind, LAMP_KINDS)
        if lighting.lamps_on and lamp.any():
            colour[lamp] = [LAMP_GLOW_RGB[int(k)] for k in quads.kind[lamp]]
        range_m = self._projector.range_to(quads.site.mean(axis=1))
        colour = atmosphere(lighting, colour, range_m)
        colour_bgr = np.clip(colour[:, ::-1], 0.0, 255.0).astype(np.uint8).tolist()

        self._draw_shadows(image, arrays, layer, starts, ends)

        # Painter's order: groups (a base box and its wheels, cabin, panels) far to near, then
        # layer (wheels, base, stacked, panels), then faces far to near, then decals in order
        # (a decal sorts with its parent face: quads.face is the face's own quad index).
        group_range = self._projector.range_to(arrays.centers)[base]
        order = np.lexsort(
            (quads.sub, -range_m[quads.face], layer[box_of_quad], -group_range[box_of_quad])
        )
        for q in order.tolist():
            pts = polygons[q]
            if pts is None:
                continue
            cv2.fillConvexPoly(image, pts, colour_bgr[q], cv2.LINE_8, SHIFT)
            if q < face_count:
                cv2.fillConvexPoly(face_buffer, pts, q, cv2.LINE_8, SHIFT)

        labels: dict[int, CameraTruthLabel] = {}
        regions: list[tuple[int, int, int, int]] = []
        planes: tuple[F64, F64] | None = None
        scratch = self._silhouette_scratch
        for vehicle, start, end in zip(
            present.tolist(), starts.tolist(), ends.tolist(), strict=True
        ):
            f0, f1 = 6 * start, 6 * end
            shown = [(q, pts) for q in range(f0, f1) if (pts := polygons[q]) is not None]
            if not shown:
                continue
            b = projected.bounds[[q for q, _ in shown]]
            x0, y0 = int(b[:, 0].min()), int(b[:, 1].min())
            x1, y1 = int(b[:, 2].max()) + 1, int(b[:, 3].max()) + 1
            # The silhouette alone: the same polygons, on a scratch mask.
            for _, pts in shown:
                cv2.fillConvexPoly(scratch, pts, 1, cv2.LINE_8, SHIFT)
            region = scratch[y0:y1, x0:x1]
            silhouette = cv2.countNonZero(region)
            if silhouette == 0:
                continue
            full = mask_box(region, x0, y0)
            region[:] = 0
            regions.append((x0, y0, x1, y1))
            sub_faces = face_buffer[y0:y1, x0:x1]
            own = (sub_faces >= f0) & (sub_faces < f1)
            if self._static_in(x0, y0, x1, y1):
                if planes is None:
                    planes = self._projector.face_planes(
                        quads.site[:face_count], quads.normal[:face_count]
                    )
                self._occlude_by_static(image, face_buffer, own, x0, y0, planes)
            visible = int(np.count_nonzero(own))
            labels[vehicle] = CameraTruthLabel(
                vehicle_ids[vehicle],
                vehicle,
                classes[vehicle],
                mask_box(own.view(np.uint8), x0, y0) if visible else None,
                full,
                visible,
                silhouette,
            )

        if lighting.lamps_on:
            self._draw_glows(
                image, face_buffer, quads, polygons, np.flatnonzero(lamp), vehicle_of_box
            )
        if self.blur_sigma_px > 0.0:  # the background was blurred once; blur the vehicles
            height, width = face_buffer.shape
            for x0, y0, x1, y1 in regions:
                x0, y0 = max(0, x0 - 2), max(0, y0 - 2)
                x1, y1 = min(width, x1 + 2), min(height, y1 + 2)
                roi = image[y0:y1, x0:x1]
                cv2.GaussianBlur(roi, (3, 3), self.blur_sigma_px, dst=roi)
        return labels

    def _draw_shadows(
        self, image: U8, arrays: BoxArrays, layer: IntP, starts: IntP, ends: IntP
    ) -> None:
        """Darken the ground under each vehicle, and its cast shadow in sunshine.

        Drawn before any vehicle, so vehicles cover it; static boxes (always nearer than the
        ground they stand in front of) are given back their pixels. The shadow is the convex
        hull of the body boxes' footprints and, with a sun high enough, of their top corners
        cast along the sun onto the road; its darkness is the ground's ambient share of light
        (``ambient / (ambient + sun)``), faded by haze with distance.
        """
        lighting = self._lighting
        sun = lighting.sun_direction
        up = np.array([0.0, 0.0, 1.0])
        total = float(shade(lighting, up).mean())
        sunny = float(lighting.sun_rgb.mean()) > 0.25 and sun[2] > 0.2
        ambient_share = lighting.ambient / total if sunny else 0.7
        body = (layer == LAYER_BASE) | (layer == LAYER_STACKED)
        corners = arrays.corners()
        centres = arrays.centers[:, None, :2]
        footprint = centres + 1.08 * (corners[:, :4, :2] - centres)  # a little wider
        if sunny:
            top = corners[:, 4:, :]
            cast = top[..., :2] - top[..., 2:3] / sun[2] * sun[:2]
            outline = np.concatenate([footprint, cast], axis=1)
        else:
            outline = footprint
        for start, end in zip(starts.tolist(), ends.tolist(), strict=True):
            mine = np.flatnonzero(body[start:end]) + start
            if mine.size == 0:
                continue
            points = outline[mine].reshape(-1, 2).astype(np.float32)
            hull = cv2.convexHull(points).reshape(-1, 2).astype(np.float64)
            polygon = np.column_stack([hull, np.zeros(hull.shape[0])])
            projected = self._projector.project_polygon(polygon)
            if projected is None:
                continue
            pts, (x0, y0, x1, y1) = projected
            centre = np.append(arrays.centers[mine, :2].mean(axis=0), 0.0)
            haze = math.exp(-lighting.extinction_per_m * float(self._projector.range_to(centre)))
            darkness = 1.0 - (1.0 - ambient_share) * haze
            mask = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
            offset = np.array([x0 << SHIFT, y0 << SHIFT], dtype=np.int32)
            cv2.fillConvexPoly(mask, pts - offset, 1, cv2.LINE_8, SHIFT)
            roi = image[y0:y1, x0:x1]
            cv2.copyTo(cv2.convertScaleAbs(roi, alpha=darkness), mask, roi)
            if self._static_in(x0, y0, x1, y1):
                cv2.copyTo(self._background[y0:y1, x0:x1], self._static_mask[y0:y1, x0:x1], roi)

    def _static_in(self, x0: int, y0: int, x1: int, y1: int) -> bool:
        """Whether any static box shows in pixels ``[y0, y1) x [x0, x1)`` (integral image)."""
        integral = self._static_integral
        total = integral[y1, x1] - integral[y0, x1] - integral[y1, x0] + integral[y0, x0]
        return bool(total > 0)

    def _occlude_by_static(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        own: Bool,
        x0: int,
        y0: int,
        planes: tuple[F64, F64],
    ) -> None:
        """Give pixels back to static boxes nearer than the vehicle face drawn there.

        ``own`` (h, w) marks the vehicle's pixels in the region at (x0, y0); updated in place.
        The vehicle's depth at a pixel is that of its face's plane there (exact, not per face).
        """
        height, width = own.shape
        static_depth = self._static_box_depth[y0 : y0 + height, x0 : x0 + width]
        rows, cols = np.nonzero(own & np.isfinite(static_depth))
        if rows.size == 0:
            return
        rows_g, cols_g = rows + y0, cols + x0
        faces = face_buffer[rows_g, cols_g].astype(np.intp)
        normal_cam, offset = planes
        depth = self._projector.plane_depth(normal_cam[faces], offset[faces], rows_g, cols_g)
        hidden = static_depth[rows, cols] < depth
        rows_h, cols_h = rows_g[hidden], cols_g[hidden]
        face_buffer[rows_h, cols_h] = -1
        image[rows_h, cols_h] = self._background[rows_h, cols_h]
        own[rows[hidden], cols[hidden]] = False

    def _draw_glows(
        self,
        image: U8,
        face_buffer: npt.NDArray[np.int16] | npt.NDArray[np.int32],
        quads: Quads,
        polygons: list[I32 | None],
        lamps: IntP,
        vehicle_of_box: IntP,
    ) -> None:
        """Add a glow around each lamp whose vehicle is what its centre pixel shows."""
        height, width = face_buffer.shape
        box_of_quad = quads.face // 6
        for q in lamps.tolist():
            pts = polygons[q]
            if pts is None:
                continue
            centre = pts.mean(axis=0) / ONE  # OpenCV coordinates (pixel centres at integers)
            column, row = math.floor(centre[0] + 0.5), math.floor(centre[1] + 0.5)
            if not (0 <= column < width and 0 <= row < height):
                continue
            seen = int(face_buffer[row, column])
            if seen < 0 or vehicle_of_box[seen // 6] != vehicle_of_box[box_of_quad[q]]:
                continue
            extent = float(np.ptp(pts, axis=0).max()) / ONE
            self._effects.add_glow(image, column, row, extent, int(quads.kind[q]))
