"""What the camera itself adds to a frame: rain streaks, motion blur, read noise, lamp glow.

Pre-drawn once (a noise field larger than the image, a few layers of rain streaks), then
added to each frame at random offsets, so a frame costs a few saturating adds.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from wz_shared.arrays import U8
from wz_simulator.sensors.camera_light import Lighting
from wz_simulator.sensors.camera_paint import LAMP_GLOW_RGB


class SensorEffects:
    """The sensor's effects for one camera, drawn from ``rng`` (shared with the renderer).

    Parameters
    ----------
    lighting
        The weather's lighting (read noise, rain rate).
    width_px, height_px
        Image size [px].
    rng
        The camera model's generator: the pre-drawn layers and each frame's offsets draw from it.
    blur_sigma_px
        Optical blur of the rain streaks (Gaussian sigma [px]); 0 for none.
    motion_blur_px
        Length of a horizontal motion blur [px]; 0 for none.
    """

    def __init__(
        self,
        lighting: Lighting,
        width_px: int,
        height_px: int,
        rng: np.random.Generator,
        *,
        blur_sigma_px: float,
        motion_blur_px: float,
    ) -> None:
        self.lighting = lighting
        self.width_px, self.height_px = width_px, height_px
        self.blur_sigma_px = blur_sigma_px
        self.motion_blur_px = motion_blur_px
        self._rng = rng
        self._noise_pad = 32
        self._noise_pos, self._noise_neg = self._noise_bank()
        self._rain_layers = self._rain_streak_layers()
        self._glow_cache: dict[tuple[int, int], U8] = {}

    def _noise_bank(self) -> tuple[U8, U8]:
        """Positive and negative parts of a Gaussian noise field larger than the image."""
        shape = (
            self.height_px + self._noise_pad,
            self.width_px + self._noise_pad,
            3,
        )
        std = self.lighting.noise_std
        if std <= 0.0:
            zeros = np.zeros(shape, dtype=np.uint8)
            return zeros, zeros
        noise = self._rng.normal(0.0, std, shape).astype(np.float32)
        positive = np.clip(np.rint(noise), 0, 255).astype(np.uint8)
        negative = np.clip(np.rint(-noise), 0, 255).astype(np.uint8)
        return positive, negative

    def _rain_streak_layers(self) -> list[U8]:
        """A few pre-drawn layers of rain streaks (added to frames in turn, at random)."""
        rain = self.lighting.rain_mm_per_h
        if rain <= 0.0:
            return []
        width, height = self.width_px, self.height_px
        streaks = int(min(4000, 40.0 * rain * width * height / 1.0e6))
        layers = []
        for _ in range(3):
            layer = np.zeros((height, width, 3), dtype=np.uint8)
            xs = self._rng.uniform(0, width, streaks)
            ys = self._rng.uniform(0, height, streaks)
            lengths = self._rng.uniform(0.012, 0.035, streaks) * height
            angle = math.radians(12.0)
            brightness = self._rng.uniform(18.0, 45.0, streaks)
            for x, y, length, level in zip(xs, ys, lengths, brightness, strict=True):
                end = (int(x + length * math.sin(angle)), int(y + length * math.cos(angle)))
                cv2.line(layer, (int(x), int(y)), end, (level, level, level), 1, cv2.LINE_AA)
            if self.blur_sigma_px > 0.0:
                cv2.GaussianBlur(layer, (3, 3), self.blur_sigma_px, dst=layer)
            layers.append(layer)
        return layers

    def _glow_sprite(self, radius_px: int, kind: int) -> U8:
        key = (radius_px, kind)
        sprite = self._glow_cache.get(key)
        if sprite is None:
            axis = np.arange(-3 * radius_px, 3 * radius_px + 1, dtype=np.float64)
            falloff = np.exp(-(axis[:, None] ** 2 + axis[None, :] ** 2) / (2.0 * radius_px**2))
            colour = np.asarray(LAMP_GLOW_RGB[kind][::-1])
            sprite = np.clip(falloff[..., None] * colour * 0.85, 0, 255).astype(np.uint8)
            self._glow_cache[key] = sprite
        return sprite

    def add_glow(self, image: U8, column: int, row: int, size_px: float, kind: int) -> None:
        """Add a lamp's glow sprite centred on pixel (row, column), saturating."""
        radius = int(min(48, max(2, round(0.9 * size_px))))
        sprite = self._glow_sprite(radius, kind)
        half = sprite.shape[0] // 2
        x0, y0 = column - half, row - half
        x1, y1 = x0 + sprite.shape[1], y0 + sprite.shape[0]
        ix0, iy0 = max(x0, 0), max(y0, 0)
        ix1, iy1 = min(x1, image.shape[1]), min(y1, image.shape[0])
        if ix1 <= ix0 or iy1 <= iy0:
            return
        roi = image[iy0:iy1, ix0:ix1]
        cv2.add(roi, sprite[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0], dst=roi)

    def apply(self, image: U8) -> None:
        """Rain streaks, motion blur and read noise on a whole frame (in place).

        The optical blur is applied to the background once and to each vehicle's region.
        """
        if self._rain_layers:
            layer = self._rain_layers[int(self._rng.integers(len(self._rain_layers)))]
            cv2.add(image, layer, dst=image)
        if self.motion_blur_px >= 1.0:
            length = round(self.motion_blur_px)
            kernel = np.full((1, length), 1.0 / length, dtype=np.float32)
            cv2.filter2D(image, -1, kernel, dst=image)
        if self.lighting.noise_std > 0.0:
            oy, ox = (int(o) for o in self._rng.integers(0, self._noise_pad, 2))
            height, width = image.shape[:2]
            cv2.add(image, self._noise_pos[oy : oy + height, ox : ox + width], dst=image)
            oy, ox = (int(o) for o in self._rng.integers(0, self._noise_pad, 2))
            cv2.subtract(image, self._noise_neg[oy : oy + height, ox : ox + width], dst=image)

    # --- vehicles -----------------------------------------------------------------------------
