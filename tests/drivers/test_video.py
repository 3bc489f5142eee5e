"""Video files (a real MJPG AVI written here) and stream URLs to JPEG camera images."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from wz_drivers.records import FieldDataError, Problems
from wz_drivers.video import read_video, redact_url

T0 = 1_700_000_000.0
FPS = 10.0
WIDTH, HEIGHT = 64, 48
FRAMES = 6


def frame_level(index: int) -> int:
    """The grey level of frame ``index``: tells decoded frames apart through JPEG twice."""
    return 20 + 35 * index


def write_avi(path: Path, frames: int = FRAMES, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), FPS, (WIDTH, HEIGHT))
    assert writer.isOpened()
    for index in range(frames):
        image = np.full((HEIGHT, WIDTH, 3), frame_level(index), dtype=np.int16)
        image += rng.integers(-3, 4, size=image.shape, dtype=np.int16)  # a little texture
        writer.write(image.clip(0, 255).astype(np.uint8))
    writer.release()
    return path


def decoded(jpeg: bytes) -> npt.NDArray[np.uint8]:
    image = cv2.imdecode(np.frombuffer(jpeg, dtype=np.uint8), cv2.IMREAD_COLOR)
    assert image is not None
    return np.asarray(image, dtype=np.uint8)


def test_file_stamped_from_start_time_and_container_clock(tmp_path: Path) -> None:
    video = write_avi(tmp_path / "camera.avi")
    problems = Problems()
    images = list(read_video(video, problems, start_unix_s=T0, jpeg_quality=80))
    assert not problems.errors
    assert len(images) == FRAMES
    np.testing.assert_allclose([i.stamp for i in images], T0 + np.arange(FRAMES) / FPS, atol=1e-6)
    for index, image in enumerate(images):
        assert (image.width_px, image.height_px) == (WIDTH, HEIGHT)
        assert image.jpeg[:2] == b"\xff\xd8"  # a JPEG
        assert abs(decoded(image.jpeg).mean() - frame_level(index)) < 3.0
        assert image.where == f"{video} (frame {index})"


def test_file_stamped_from_sidecar_csv_with_bad_rows(tmp_path: Path) -> None:
    video = write_avi(tmp_path / "camera.avi")
    sidecar = tmp_path / "camera.csv"
    # Frame 3's time is not a number; frame 4's goes back; frame 5 has no row.
    sidecar.write_text(
        f"frame,time_unix_s\n0,{T0}\n1,{T0 + 0.04}\n2,{T0 + 0.09}\n3,oops\n4,{T0 + 0.05}\n"
    )
    problems = Problems()
    images = list(read_video(video, problems, timestamps=sidecar))
    assert [i.stamp for i in images] == [T0, T0 + 0.04, T0 + 0.09]
    assert [round(decoded(i.jpeg).mean()) for i in images] == pytest.approx(
        [frame_level(k) for k in range(3)], abs=3
    )
    assert [str(e) for e in problems.errors] == [
        f"{sidecar}:5: time 'oops' of frame 3 is not a Unix time [s]: frame skipped",
        f"{sidecar}:6: time 1700000000.050000 of frame 4 is not after 1700000000.090000 "
        "(frame 2): frame skipped",
        f"{video} (frame 5): no row in {sidecar}: frame skipped",
    ]


def test_sidecar_without_frame_column_raises(tmp_path: Path) -> None:
    video = write_avi(tmp_path / "camera.avi", frames=2)
    sidecar = tmp_path / "camera.csv"
    sidecar.write_text("index,time_unix_s\n0,1\n")
    with pytest.raises(FieldDataError, match=r"camera.csv:1: missing columns: frame \(frame\)"):
        list(read_video(video, Problems(), timestamps=sidecar))


def test_files_opencv_cannot_read_raise(tmp_path: Path) -> None:
    junk = tmp_path / "junk.avi"
    junk.write_bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    with pytest.raises(FieldDataError, match="OpenCV cannot open it as a video"):
        list(read_video(junk, Problems(), start_unix_s=T0))
    with pytest.raises(FieldDataError, match="no such file"):
        list(read_video(tmp_path / "absent.mp4", Problems(), start_unix_s=T0))
    video = write_avi(tmp_path / "camera.avi", frames=1)
    with pytest.raises(FieldDataError, match="no time for the frames"):
        list(read_video(video, Problems()))


def test_stream_url_nothing_answers_raises_quickly(port: int) -> None:
    url = f"rtsp://operator:secret@127.0.0.1:{port}/stream1"  # port: nothing listens there
    started = time.monotonic()
    with pytest.raises(FieldDataError, match="cannot open the stream") as caught:
        list(read_video(url, Problems(), open_timeout_s=2.0, read_timeout_s=2.0))
    assert time.monotonic() - started < 5.0
    assert "secret" not in str(caught.value)
    assert caught.value.path == f"rtsp://operator:***@127.0.0.1:{port}/stream1"


def test_stream_url_silent_server_times_out() -> None:
    # A server that takes the connection (the kernel's backlog) and never says a word.
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        url = f"rtsp://127.0.0.1:{server.getsockname()[1]}/stream1"
        started = time.monotonic()
        with pytest.raises(FieldDataError, match="nothing answered within 1 s"):
            list(read_video(url, Problems(), open_timeout_s=1.0, read_timeout_s=1.0))
        assert 0.9 < time.monotonic() - started < 4.0


def test_stream_refuses_file_only_arguments_and_bad_quality(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="wall clock"):
        list(read_video("rtsp://127.0.0.1:9/x", Problems(), start_unix_s=T0))
    with pytest.raises(ValueError, match="jpeg_quality"):
        list(read_video(tmp_path / "a.avi", Problems(), start_unix_s=T0, jpeg_quality=0))
    assert redact_url("http://cam.local:8080/mjpg") == "http://cam.local:8080/mjpg"
    assert redact_url("rtsp://u:p@[fe80::1]:554/s") == "rtsp://u:***@[fe80::1]:554/s"
