"""Ouster recordings through the real ouster-sdk: simulated sweeps written as an Ouster pcap
and its metadata JSON, read back by ``read_ouster`` and by ouster-sdk's own readers; damaged
copies (cut mid-packet, a corrupt packet) and bad metadata.

Tolerances
----------
A simulated point lies on its own ray, and the recording's beams and columns are the
simulator's rays, so a point comes back on the same ray; only its range is quantised: Ouster's
RANGE is whole millimetres, rounded, so |error| <= 0.5 mm, plus float32 rounding of the
coordinates (< 10 um within 200 m): 0.51 mm. Intensity goes through REFLECTIVITY, whole
percent: <= 0.005. Stamps: column timestamps are whole nanoseconds and a float64 Unix time
has a 0.24 us step, so within 1 us (2 us where they come from a pcap's capture times, whole
microseconds). Points off the rays move to the nearest pixel (beam by elevation, column by
azimuth), checked against the simulator's ray convention, independently of the writer.
"""

from __future__ import annotations

import math
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from ouster.sdk import open_source, osf
from ouster.sdk.core import ChanField, SensorInfo, parse_and_validate_metadata

from wz_drivers.ouster import (
    OusterRecording,
    bin_range_image,
    read_ouster,
    synthetic_sensor_info,
    write_ouster_pcap,
)
from wz_drivers.records import FieldDataError, LidarSweep, Problems
from wz_shared.site import LidarIntrinsics, Pose, SensorMount
from wz_simulator.sensors.lidar import LidarModel
from wz_simulator.sensors.scene import Box, Material, Weather, vehicle_boxes

T0 = 1_700_000_000.0123
RATE_HZ = 20
BEAMS, COLUMNS = 64, 1024
SWEEPS = 3
PACKETS_PER_SCAN = COLUMNS // 16
XYZ_TOLERANCE_M = 0.5e-3 + 10e-6
INTENSITY_TOLERANCE = 0.005 + 1e-6


def simulated_sweeps(count: int = SWEEPS) -> list[LidarSweep]:
    """The simulator's mast LiDAR (5 m up, 64 x 1024, 20 Hz, 2 cm range noise, seeded) over the
    base ground plane, a concrete block and a retroreflective sign, as sweeps."""
    mount = SensorMount(
        sensor_id="mast-lidar",
        pose=Pose(x_m=0.0, y_m=0.0, z_m=5.0),
        intrinsics=LidarIntrinsics(beams=BEAMS, azimuth_steps=COLUMNS, range_noise_std_m=0.02),
        rate_hz=RATE_HZ,
    )
    boxes = [
        Box((20.0, 3.0, 1.0), (4.0, 2.0, 2.0), 0.3, Material.CONCRETE, (128, 128, 128)),
        Box((-15.0, -8.0, 2.0), (2.0, 6.0, 4.0), 0.0, Material.SIGN, (255, 128, 0)),
    ]
    model = LidarModel(mount, boxes, [], Weather(), 7, boxes_for=vehicle_boxes)
    sweeps = []
    for index in range(count):
        scan = model.scan([], T0 + index / RATE_HZ, index)
        sweeps.append(
            LidarSweep(
                stamp=scan.meta.stamp,
                points=scan.points,
                rows=scan.meta.rows,
                columns=scan.meta.columns,
                organized=True,
                where=f"simulated sweep {index}",
                sweep_duration_s=scan.meta.sweep_duration_s,
            )
        )
    return sweeps


@pytest.fixture(scope="module")
def sweeps() -> list[LidarSweep]:
    return simulated_sweeps()


@pytest.fixture(scope="module")
def recording(
    sweeps: list[LidarSweep], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, Path, OusterRecording]:
    folder = tmp_path_factory.mktemp("ouster")
    pcap_path, metadata_path = folder / "mast.pcap", folder / "mast.json"
    written = write_ouster_pcap(
        sweeps,
        pcap_path,
        metadata_path,
        channels=BEAMS,
        columns_per_frame=COLUMNS,
        vertical_min_deg=-30.0,
        vertical_max_deg=11.0,
        rate_hz=RATE_HZ,
    )
    return pcap_path, metadata_path, written


def copy_recording(
    recording: tuple[Path, Path, OusterRecording], folder: Path
) -> tuple[Path, Path]:
    pcap_path, metadata_path, _ = recording
    return (
        Path(shutil.copy(pcap_path, folder / "copy.pcap")),
        Path(shutil.copy(metadata_path, folder / "copy.json")),
    )


def pcap_records(path: Path) -> list[tuple[int, int]]:
    """(offset of the data, length) of each record of a classic little-endian pcap."""
    data = path.read_bytes()
    assert data[:4] == b"\xd4\xc3\xb2\xa1"
    records, offset = [], 24
    while offset < len(data):
        length = struct.unpack("<I", data[offset + 8 : offset + 12])[0]
        records.append((offset + 16, length))
        offset += 16 + length
    return records


def drop_records(path: Path, numbers: set[int]) -> None:
    """Rewrite a pcap without the records of these (1-based) numbers, as a capture that lost
    them would be."""
    data = path.read_bytes()
    kept = [
        data[offset - 16 : offset + length]
        for number, (offset, length) in enumerate(pcap_records(path), start=1)
        if number not in numbers
    ]
    path.write_bytes(data[:24] + b"".join(kept))


def assert_same_sweep(read: LidarSweep, simulated: LidarSweep) -> None:
    assert (read.rows, read.columns, read.organized) == (BEAMS, COLUMNS, True)
    assert read.points.dtype == np.float32 and read.points.shape == (BEAMS * COLUMNS, 4)
    assert abs(read.stamp - simulated.stamp) < 1e-6
    assert read.sweep_duration_s == pytest.approx(1.0 / RATE_HZ, abs=1e-7)
    no_return = np.isnan(simulated.points[:, 0])
    # No-returns stay NaN (x, y, z and intensity) in the same pixels; every return comes back.
    assert np.array_equal(np.isnan(read.points).any(axis=1), no_return)
    assert np.isnan(read.points[no_return]).all()
    error_m = np.linalg.norm(read.points[~no_return, :3] - simulated.points[~no_return, :3], axis=1)
    assert error_m.max() <= XYZ_TOLERANCE_M
    intensity_error = np.abs(read.points[~no_return, 3] - simulated.points[~no_return, 3])
    assert intensity_error.max() <= INTENSITY_TOLERANCE


# --- round trip ---------------------------------------------------------------------------


def test_simulated_sweeps_round_trip_through_an_ouster_pcap(
    sweeps: list[LidarSweep], recording: tuple[Path, Path, OusterRecording]
) -> None:
    pcap_path, metadata_path, written = recording
    returns = sum(int(np.isfinite(s.points[:, 0]).sum()) for s in sweeps)
    assert written == OusterRecording(SWEEPS, SWEEPS * PACKETS_PER_SCAN, returns, returns)
    # The scene gives near and far returns, diffuse and retroreflective ones.
    ranges = np.linalg.norm(sweeps[0].points[:, :3], axis=1)
    assert np.nanmin(ranges) < 12.0 and np.nanmax(ranges) > 40.0
    assert np.nanmax(sweeps[0].points[:, 3]) > 0.5

    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(problems) == 0
    assert len(read) == SWEEPS
    for index, (got, simulated) in enumerate(zip(read, sweeps, strict=True)):
        assert_same_sweep(got, simulated)
        assert got.where == f"{pcap_path} (scan {index + 1}, frame id {index})"
    # Without a metadata path, the JSON beside the pcap (same stem) is used.
    assert len(list(read_ouster(pcap_path, None, Problems()))) == SWEEPS


def test_ouster_sdk_reads_the_recording_in_its_own_frame_convention(
    sweeps: list[LidarSweep], recording: tuple[Path, Path, OusterRecording]
) -> None:
    pcap_path, metadata_path, _ = recording
    info, issues = parse_and_validate_metadata(metadata_path.read_text())
    assert info is not None and not issues.critical
    assert (info.prod_line, str(info.config.lidar_mode)) == ("OS-1-64", "1024x20")
    assert str(info.format.udp_profile_lidar) == "RNG19_RFL8_SIG16_NIR16"

    source = open_source(str(pcap_path), meta=[str(metadata_path)], collate=False, sensor_idx=0)
    frames = [frame_set[0] for frame_set in source]
    source.close()
    assert len(frames) == SWEEPS
    for frame, simulated in zip(frames, sweeps, strict=True):
        assert frame is not None and frame.complete()
        range_mm = frame.field(ChanField.RANGE).astype(np.float64)
        # Ouster's column 0 looks towards the connector (sensor -x), column W/2 away from it
        # (+x): the simulator's column j at azimuth pi - 2 pi j / W, pixel for pixel.
        xyz_m = simulated.points[:, :3].astype(np.float64)
        expected_mm = np.linalg.norm(xyz_m, axis=1).reshape(BEAMS, COLUMNS) * 1e3
        returned = np.isfinite(expected_mm)
        assert np.array_equal(range_mm > 0, returned)
        assert np.abs(range_mm[returned] - expected_mm[returned]).max() <= 0.5 + 1e-3
        assert int(frame.timestamp[0]) == pytest.approx(simulated.stamp * 1e9, abs=1e3)


def test_internal_oscillator_stamps_come_from_capture_times(
    sweeps: list[LidarSweep], tmp_path: Path
) -> None:
    pcap_path, metadata_path = tmp_path / "osc.pcap", tmp_path / "osc.json"
    write_ouster_pcap(
        sweeps, pcap_path, metadata_path, rate_hz=RATE_HZ, timestamp_mode="TIME_FROM_INTERNAL_OSC"
    )
    source = open_source(str(pcap_path), meta=[str(metadata_path)], collate=False, sensor_idx=0)
    first = next(iter(source))[0]
    source.close()
    assert first is not None and int(first.timestamp[0]) == 3600 * 10**9  # since power-on
    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(problems) == 0 and len(read) == SWEEPS
    # A classic pcap keeps capture times in whole microseconds: stamps within 1 us of that.
    for got, simulated in zip(read, sweeps, strict=True):
        assert abs(got.stamp - simulated.stamp) < 2e-6
        assert got.sweep_duration_s == pytest.approx(1.0 / RATE_HZ, abs=1e-7)


def test_the_legacy_profile_round_trips_too(sweeps: list[LidarSweep], tmp_path: Path) -> None:
    pcap_path, metadata_path = tmp_path / "legacy.pcap", tmp_path / "legacy.json"
    write_ouster_pcap(sweeps[:1], pcap_path, metadata_path, udp_profile="LEGACY")
    problems = Problems()
    (read,) = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(problems) == 0
    assert_same_sweep(read, sweeps[0])


def test_an_azimuth_window_sends_a_quarter_of_the_packets_and_reads_back(
    sweeps: list[LidarSweep], tmp_path: Path
) -> None:
    """Encoder angles 135..225 deg: +-45 deg about the sensor's boresight (column j looks at
    180 - 360 j / W deg), a quarter of the packets; the returns there come back as they were,
    the rest is no return."""
    pcap_path, metadata_path = tmp_path / "window.pcap", tmp_path / "window.json"
    written = write_ouster_pcap(sweeps, pcap_path, metadata_path, azimuth_window_deg=(135.0, 225.0))
    assert written.packets == SWEEPS * PACKETS_PER_SCAN // 4
    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(problems) == 0 and len(read) == SWEEPS
    for got, simulated in zip(read, sweeps, strict=True):
        assert got.stamp == pytest.approx(simulated.stamp, abs=1e-6)
        azimuth = np.degrees(np.arctan2(simulated.points[:, 1], simulated.points[:, 0]))
        inside = np.isfinite(simulated.points[:, 0]) & (np.abs(azimuth) < 44.0)
        returned = np.isfinite(got.points[:, 0])
        assert returned.sum() >= inside.sum() > 0
        got_azimuth = np.degrees(np.arctan2(got.points[returned, 1], got.points[returned, 0]))
        assert np.abs(got_azimuth).max() <= 45.0 + 360.0 / COLUMNS
        np.testing.assert_allclose(
            got.points[inside, :3], simulated.points[inside, :3], atol=XYZ_TOLERANCE_M
        )
    with pytest.raises(ValueError, match="azimuth window"):
        write_ouster_pcap(
            sweeps, tmp_path / "bad.pcap", tmp_path / "bad.json", azimuth_window_deg=(200.0, 100.0)
        )


def test_an_osf_made_by_ouster_sdk_reads_the_same(
    recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path, _ = recording
    osf_path = tmp_path / "mast.osf"
    info = SensorInfo(metadata_path.read_text())
    source = open_source(str(pcap_path), meta=[str(metadata_path)], collate=False, sensor_idx=0)
    writer = osf.Writer(str(osf_path), info)
    for frame_set in source:
        writer.save(0, frame_set[0])
    writer.close()
    source.close()
    from_pcap = list(read_ouster(pcap_path, metadata_path, Problems()))
    problems = Problems()
    from_osf = list(read_ouster(osf_path, None, problems))
    assert len(problems) == 0 and len(from_osf) == SWEEPS
    for a, b in zip(from_osf, from_pcap, strict=True):
        assert a.stamp == b.stamp and (a.rows, a.columns) == (b.rows, b.columns)
        np.testing.assert_array_equal(a.points, b.points)


# --- binning ------------------------------------------------------------------------------


def test_points_off_the_rays_land_in_the_nearest_pixel(tmp_path: Path) -> None:
    """Random points (seeded), unorganized, in a 1024 x 10 recording: each pixel holds the
    nearest point whose direction is nearest to that pixel's ray (the simulator's ray
    convention), at that point's range, on the pixel's ray."""
    rng = np.random.default_rng(42)
    count, columns, step_deg = 20_000, 1024, 41.0 / 63
    azimuth = rng.uniform(-math.pi, math.pi, count)
    elevation = np.radians(rng.uniform(-33.0, 14.0, count))  # some beyond the field
    distance = rng.uniform(1.0, 150.0, count)
    points = np.column_stack(
        [
            distance * np.cos(elevation) * np.cos(azimuth),
            distance * np.cos(elevation) * np.sin(azimuth),
            distance * np.sin(elevation),
            rng.uniform(0.0, 1.0, count),
        ]
    ).astype(np.float32)
    sweep = LidarSweep(stamp=T0, points=points, rows=1, columns=0, organized=False, where="random")
    written = write_ouster_pcap([sweep], tmp_path / "r.pcap", tmp_path / "r.json", rate_hz=10)
    (read,) = list(read_ouster(tmp_path / "r.pcap", tmp_path / "r.json", Problems()))

    # Expected, from the float32 points as written: row by elevation, column by azimuth.
    p = points[:, :3].astype(np.float64)
    r = np.linalg.norm(p, axis=1)
    row = np.rint((11.0 - np.degrees(np.arcsin(p[:, 2] / r))) / step_deg)
    column = np.rint((math.pi - np.arctan2(p[:, 1], p[:, 0])) * columns / (2 * math.pi)) % columns
    inside = (row >= 0) & (row < BEAMS)
    pixel = (row * columns + column)[inside].astype(np.intp)
    nearest = np.full(BEAMS * columns, np.inf)
    np.minimum.at(nearest, pixel, r[inside])
    filled = np.isfinite(nearest)
    assert written.points_in == count and written.points_written == int(filled.sum())
    assert 0 < int((~inside).sum()) < count  # points outside the field were offered, and dropped

    got = read.points.astype(np.float64)
    assert np.array_equal(np.isfinite(got[:, 0]), filled)
    got_range = np.linalg.norm(got[filled, :3], axis=1)
    assert np.abs(got_range - nearest[filled]).max() <= 0.5e-3 + 1e-5
    # On the pixel's ray: elevation of the beam, azimuth pi - 2 pi j / W.
    beam = np.radians(11.0 - step_deg * (np.flatnonzero(filled) // columns))
    ray_azimuth = math.pi - 2 * math.pi * (np.flatnonzero(filled) % columns) / columns
    ray = np.column_stack(
        [np.cos(beam) * np.cos(ray_azimuth), np.cos(beam) * np.sin(ray_azimuth), np.sin(beam)]
    )
    assert np.abs(got[filled, :3] - ray * got_range[:, None]).max() <= 2e-5


def test_binning_keeps_the_nearest_point_of_a_pixel() -> None:
    info = synthetic_sensor_info(
        channels=16,
        columns_per_frame=512,
        vertical_min_deg=-15.0,
        vertical_max_deg=15.0,
        rate_hz=10,
    )
    # Three points on one ray, ahead (+x: column W/2) on beam 7 (+1 deg of 15 .. -15).
    altitudes = np.asarray(info.beam_altitude_angles)
    up = math.radians(float(altitudes[7]))
    direction = np.array([math.cos(up), 0.0, math.sin(up)])
    points = np.array(
        [[*(direction * 30.0), 0.2], [*(direction * 12.0), 0.9], [*(direction * 50.0), 0.4]]
    )
    range_mm, reflectivity, written = bin_range_image(
        points,
        altitudes_deg=altitudes,
        columns=512,
        lidar_to_sensor=np.asarray(info.lidar_to_sensor_transform),
        max_range_mm=(1 << 19) - 1,
    )
    assert written == 1 and range_mm[7, 256] == 12_000 and reflectivity[7, 256] == 90
    assert np.count_nonzero(range_mm) == 1


def test_writer_refuses_what_no_ouster_records(sweeps: list[LidarSweep], tmp_path: Path) -> None:
    out = (tmp_path / "x.pcap", tmp_path / "x.json")
    with pytest.raises(ValueError, match="lidar mode"):
        write_ouster_pcap(sweeps, *out, columns_per_frame=1000)
    with pytest.raises(ValueError, match="lidar mode"):
        write_ouster_pcap(sweeps, *out, rate_hz=15)
    with pytest.raises(ValueError, match="channels"):
        write_ouster_pcap(sweeps, *out, channels=48)
    with pytest.raises(ValueError, match="increase"):
        write_ouster_pcap([sweeps[1], sweeps[0]], *out)
    with pytest.raises(ValueError, match="no sweeps"):
        write_ouster_pcap([], *out)
    assert not out[0].exists() and not out[1].exists()


# --- damaged recordings -------------------------------------------------------------------


def test_a_pcap_cut_mid_packet_keeps_the_scans_before_and_reports_the_cut(
    sweeps: list[LidarSweep], recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path = copy_recording(recording, tmp_path)
    records = pcap_records(pcap_path)
    cut_record = 2 * PACKETS_PER_SCAN + 20  # 1-based: the 20th packet of the third scan
    offset, length = records[cut_record - 1]
    pcap_path.write_bytes(pcap_path.read_bytes()[: offset + length // 2])

    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(read) == 2
    for got, simulated in zip(read, sweeps[:2], strict=True):
        assert_same_sweep(got, simulated)
    assert len(problems) == 1
    (error,) = problems.errors
    assert error.path == str(pcap_path) and error.line == cut_record
    assert "truncated" in error.reason
    assert problems.summary() == {str(pcap_path): 1}


def test_a_corrupt_packet_is_reported_and_its_scan_skipped(
    sweeps: list[LidarSweep], recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path = copy_recording(recording, tmp_path)
    records = pcap_records(pcap_path)
    bad_packet = PACKETS_PER_SCAN + 30  # in the second scan
    offset, length = records[bad_packet - 1]
    data = bytearray(pcap_path.read_bytes())
    data[offset + length // 2] ^= 0xFF  # a range bit flipped: the packet's CRC fails
    pcap_path.write_bytes(bytes(data))

    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert [got.where.rsplit("(", 1)[1] for got in read] == [
        "scan 1, frame id 0)",
        "scan 3, frame id 2)",
    ]
    assert_same_sweep(read[1], sweeps[2])
    (error,) = problems.errors
    assert error.path == str(pcap_path) and error.line == bad_packet and "CRC" in error.reason


def test_a_capture_started_mid_rotation_skips_its_partial_first_scan_quietly(
    sweeps: list[LidarSweep], recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path = copy_recording(recording, tmp_path)
    drop_records(pcap_path, set(range(1, 11)))
    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(problems) == 0 and len(read) == 2
    for got, simulated in zip(read, sweeps[1:], strict=True):
        assert_same_sweep(got, simulated)


def test_a_packet_lost_in_capture_skips_its_scan_and_reports_it(
    sweeps: list[LidarSweep], recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path = copy_recording(recording, tmp_path)
    drop_records(pcap_path, {PACKETS_PER_SCAN + 30})
    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(read) == 2
    assert_same_sweep(read[0], sweeps[0])
    assert_same_sweep(read[1], sweeps[2])
    (error,) = problems.errors
    assert error.path == str(pcap_path) and error.line == 2
    assert f"{COLUMNS - 16} of {COLUMNS} columns" in error.reason
    assert str(error).startswith(f"{pcap_path} (scan 2)")


def test_a_pcap_cut_inside_its_first_packet_raises(
    recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path = copy_recording(recording, tmp_path)
    offset, _ = pcap_records(pcap_path)[0]
    pcap_path.write_bytes(pcap_path.read_bytes()[: offset + 100])
    with pytest.raises(FieldDataError, match="before any whole lidar packet") as raised:
        list(read_ouster(pcap_path, metadata_path, Problems()))
    assert raised.value.path == str(pcap_path) and raised.value.line == 1


def test_scans_whose_time_goes_back_are_reported(
    recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, metadata_path = copy_recording(recording, tmp_path)
    data = pcap_path.read_bytes()
    pcap_path.write_bytes(data + data[24:])  # the same scans again: the clock jumps back
    problems = Problems()
    read = list(read_ouster(pcap_path, metadata_path, problems))
    assert len(read) == SWEEPS
    (error,) = problems.errors  # ouster-sdk's batcher drops the repeated packets: one report
    assert error.line == SWEEPS * PACKETS_PER_SCAN + 1 and "goes back" in error.reason
    assert f"..{2 * SWEEPS * PACKETS_PER_SCAN} dropped" in error.reason


def test_packets_of_another_sensor_are_refused(
    recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, _, _ = recording
    other = synthetic_sensor_info(
        channels=BEAMS,
        columns_per_frame=COLUMNS,
        vertical_min_deg=-30.0,
        vertical_max_deg=11.0,
        rate_hz=RATE_HZ,
        serial_number=123,
        init_id=77,
    )
    metadata_path = tmp_path / "other.json"
    metadata_path.write_text(other.to_json_string())
    with pytest.raises(FieldDataError, match="not one lidar packet") as raised:
        list(read_ouster(pcap_path, metadata_path, Problems()))
    assert raised.value.path == str(pcap_path)


# --- unreadable as a whole ----------------------------------------------------------------


def test_missing_or_invalid_metadata_raises_naming_it(
    recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    pcap_path, _, _ = recording
    missing = tmp_path / "missing.json"
    with pytest.raises(FieldDataError) as raised:
        read_ouster(pcap_path, missing, Problems())
    assert raised.value.path == str(missing)

    lone = Path(shutil.copy(pcap_path, tmp_path / "lone.pcap"))
    with pytest.raises(FieldDataError, match=r"lone\.json") as raised:
        read_ouster(lone, None, Problems())
    assert raised.value.path == str(lone)

    for name, text in {"cut.json": '{"beam_intrinsics": {', "empty.json": "{}"}.items():
        bad = tmp_path / name
        bad.write_text(text)
        with pytest.raises(FieldDataError) as raised:
            read_ouster(pcap_path, bad, Problems())
        assert raised.value.path == str(bad)
    assert "columns_per_frame" in raised.value.reason  # ouster-sdk's validator says what lacks


def test_a_file_that_is_not_a_recording_raises(
    recording: tuple[Path, Path, OusterRecording], tmp_path: Path
) -> None:
    _, metadata_path, _ = recording
    with pytest.raises(FieldDataError, match="no such"):
        read_ouster(tmp_path / "absent.pcap", metadata_path, Problems())
    text = tmp_path / "notes.pcap"
    text.write_text("not a capture\n")
    with pytest.raises(FieldDataError, match="not a pcap") as raised:
        read_ouster(text, metadata_path, Problems())
    assert raised.value.path == str(text)
