"""Fog and haze (:mod:`wz_camera_detector.contrast`): a frame veiled as fog veils it is flat,
a clear one is not, and only the flat one gets local contrast before the real-camera model."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wz_camera_detector.contrast import FLAT_BELOW, flatness, local_contrast
from wz_camera_detector.node import make_backend
from wz_camera_detector.settings import CameraDetectorSettings
from wz_camera_detector.yolo import YoloOnnxDetector


def clear_scene(height: int = 480, width: int = 640, seed: int = 3) -> np.ndarray:
    """A clear BGR frame with texture at several scales (smoothed noise, lit unevenly)."""
    rng = np.random.default_rng(seed)
    layers = [
        cv2.resize(rng.uniform(0, 1, (height // s, width // s)).astype(np.float32), (width, height))
        for s in (2, 8, 32)
    ]
    grey = 40.0 + 180.0 * (0.5 * layers[0] + 0.3 * layers[1] + 0.2 * layers[2])
    tint = np.array([0.9, 1.0, 1.1], dtype=np.float32)  # B, G, R
    return np.clip(grey[:, :, None] * tint, 0, 255).astype(np.uint8)


def fogged(image: np.ndarray, transmission: float, airlight: float = 210.0) -> np.ndarray:
    """Koschmieder's veil: ``I = J t + A (1 - t)``, ``t`` the transmission."""
    veiled = image.astype(np.float32) * transmission + airlight * (1.0 - transmission)
    return np.clip(veiled, 0, 255).astype(np.uint8)


def test_a_clear_frame_is_not_flat_and_the_same_in_fog_is() -> None:
    clear = clear_scene()
    assert flatness(clear) > 1.5 * FLAT_BELOW
    assert flatness(fogged(clear, 0.5)) < flatness(clear)
    assert flatness(fogged(clear, 0.25)) < FLAT_BELOW


def test_flatness_is_measured_alike_on_larger_frames() -> None:
    clear = clear_scene()
    for width, height in ((1280, 960), (1920, 1440)):
        resized = cv2.resize(clear, (width, height), interpolation=cv2.INTER_LINEAR)
        assert flatness(resized) == pytest.approx(flatness(clear), rel=0.35)
    assert flatness(np.zeros((240, 320, 3), dtype=np.uint8)) == 0.0


def test_local_contrast_gives_a_fogged_frame_its_edges_back() -> None:
    foggy = fogged(clear_scene(), 0.25)
    restored = local_contrast(foggy)
    assert restored.shape == foggy.shape and restored.dtype == np.uint8
    assert flatness(restored) > 2.0 * flatness(foggy)


def test_only_a_flat_frame_gets_local_contrast_before_the_model() -> None:
    detector = make_backend(CameraDetectorSettings())  # the shipped real-camera model
    assert isinstance(detector, YoloOnnxDetector) and detector.flat_below == FLAT_BELOW
    clear = clear_scene()
    detector.detect(clear)
    assert not detector.last_flat and detector.flat_frames == 0
    detector.detect(fogged(clear, 0.25))
    assert detector.last_flat and detector.flat_frames == 1
    detector.detect(clear)
    assert not detector.last_flat and detector.flat_frames == 1


def test_the_simulators_model_and_a_settings_model_are_left_as_they_are_unless_asked() -> None:
    rendered = make_backend(CameraDetectorSettings(), rendered=True)
    assert isinstance(rendered, YoloOnnxDetector) and rendered.flat_below is None
    own = make_backend(CameraDetectorSettings(model_path=rendered.model_path))
    assert isinstance(own, YoloOnnxDetector) and own.flat_below is None
    asked = make_backend(CameraDetectorSettings(fog_contrast="on", flat_below=0.05), rendered=True)
    assert isinstance(asked, YoloOnnxDetector) and asked.flat_below == 0.05
    off = make_backend(CameraDetectorSettings(fog_contrast="off"))
    assert isinstance(off, YoloOnnxDetector) and off.flat_below is None
