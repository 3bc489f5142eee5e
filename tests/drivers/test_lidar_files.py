"""PCD / PLY / NPZ frame files and folders to LiDAR sweeps (real files in tmp_path)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from wz_drivers.lidar_files import read_frame, read_frame_folder, time_from_name
from wz_drivers.records import FieldDataError, Problems

# The shared data folder sits beside the checkout (as for wz_lidar_detector.real_frame).
REAL_FRAME = Path(__file__).resolve().parents[2] / "samples/real-freeway-lidar/rawdata.pcd"
T0 = 1_700_000_000.0


def organized_points(rows: int, columns: int, seed: int = 0) -> npt.NDArray[np.float32]:
    """``(rows * columns, 4)`` x y z intensity with a few NaN (no-return) slots."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-50.0, 50.0, size=(rows * columns, 4)).astype(np.float32)
    points[:, 3] = rng.integers(0, 256, size=rows * columns)
    points[rng.choice(rows * columns, size=rows * columns // 5, replace=False), :3] = np.nan
    return points


def write_pcd(
    path: Path,
    points: npt.NDArray[np.float32],
    *,
    rows: int = 1,
    data: str = "ascii",
    fields: tuple[str, ...] = ("x", "y", "z", "intensity"),
) -> Path:
    """A PCD v0.7 file as PCL writes it (float32 fields)."""
    count = len(points)
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(fields)}\nSIZE {' '.join('4' for _ in fields)}\n"
        f"TYPE {' '.join('F' for _ in fields)}\nCOUNT {' '.join('1' for _ in fields)}\n"
        f"WIDTH {count // rows}\nHEIGHT {rows}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {count}\n"
        f"DATA {data}\n"
    )
    if data == "ascii":
        body = "".join(" ".join(f"{v:.7g}" for v in row) + "\n" for row in points).encode()
    else:
        body = np.ascontiguousarray(points, dtype="<f4").tobytes()
    path.write_bytes(header.encode() + body)
    return path


def write_ply(
    path: Path, points: npt.NDArray[np.float32], *, binary: bool, big_endian: bool = False
) -> Path:
    properties = ["x", "y", "z", "intensity"][: points.shape[1]]
    fmt = "ascii" if not binary else "binary_big_endian" if big_endian else "binary_little_endian"
    header = (
        f"ply\nformat {fmt} 1.0\ncomment seeded\n"
        f"element vertex {len(points)}\n"
        + "".join(f"property float {name}\n" for name in properties)
        + "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
    )
    if binary:
        body = np.ascontiguousarray(points, dtype=">f4" if big_endian else "<f4").tobytes()
    else:
        body = "".join(" ".join(f"{v:.7g}" for v in row) + "\n" for row in points).encode()
    path.write_bytes(header.encode() + body)
    return path


# --- the real 80-beam frame -----------------------------------------------------------------


def test_real_frame_keeps_organization_values_and_no_return_slots() -> None:
    assert REAL_FRAME.is_file(), f"the real frame is missing: {REAL_FRAME}"
    sweep = read_frame(REAL_FRAME)
    # Header: WIDTH 1800, HEIGHT 80, POINTS 144000, fields x y z intensity (README).
    assert (sweep.rows, sweep.columns, sweep.organized) == (80, 1800, True)
    assert sweep.points.shape == (144_000, 4) and sweep.points.dtype == np.float32
    returns = np.isfinite(sweep.points[:, :3]).all(axis=1)
    assert returns.sum() == 95_026  # "about 95,000 real returns"
    assert np.isnan(sweep.points[~returns, :3]).all()  # no-return slots stay NaN, in place
    # The first return is point 9366 (row 5, column 366): data line 9366 after 11 header lines.
    lines = REAL_FRAME.read_text().splitlines()
    assert lines[11 + 9366] == "-28.49471 17.04936 -3.363432 37"
    np.testing.assert_array_equal(np.flatnonzero(returns)[:2], [9366, 9446])
    np.testing.assert_allclose(
        sweep.points[9366], [-28.49471, 17.04936, -3.363432, 37.0], rtol=1e-6
    )
    np.testing.assert_allclose(
        sweep.points.reshape(80, 1800, 4)[5, 446],
        [-28.54152, 17.21296, -3.376043, 111.0],
        rtol=1e-6,
    )
    assert np.nanmax(sweep.points[:, 3]) == 251.0  # intensity in the sensor's 0-255 scale
    assert sweep.stamp == 0.0 and sweep.where == str(REAL_FRAME)


# --- single files ---------------------------------------------------------------------------


@pytest.mark.parametrize("data", ["ascii", "binary"])
def test_organized_pcd_round_trip(tmp_path: Path, data: str) -> None:
    points = organized_points(4, 30, seed=1)
    points[7, :3] = 0.0  # a driver's (0, 0, 0) no-return marker
    sweep = read_frame(write_pcd(tmp_path / f"{T0 + 0.25}.pcd", points, rows=4, data=data))
    assert (sweep.rows, sweep.columns, sweep.organized) == (4, 30, True)
    assert sweep.stamp == T0 + 0.25  # from the file name
    expected = points.copy()
    expected[7, :3] = np.nan
    np.testing.assert_allclose(sweep.points, expected, rtol=1e-6, equal_nan=True)


def test_unorganized_pcd_drops_no_return_points_and_fills_missing_intensity(
    tmp_path: Path,
) -> None:
    points = organized_points(1, 40, seed=2)[:, :3]
    sweep = read_frame(write_pcd(tmp_path / "a.pcd", points, fields=("x", "y", "z")))
    finite = np.isfinite(points).all(axis=1)
    assert (sweep.rows, sweep.columns, sweep.organized) == (1, 0, False)
    np.testing.assert_allclose(sweep.points[:, :3], points[finite], rtol=1e-6)
    assert np.isnan(sweep.points[:, 3]).all()


@pytest.mark.parametrize(("binary", "big_endian"), [(False, False), (True, False), (True, True)])
def test_ply_vertices(tmp_path: Path, binary: bool, big_endian: bool) -> None:
    points = np.random.default_rng(4).uniform(-20, 20, size=(25, 4)).astype(np.float32)
    path = write_ply(tmp_path / "cloud.ply", points, binary=binary, big_endian=big_endian)
    sweep = read_frame(path)
    np.testing.assert_allclose(sweep.points, points, rtol=1e-6)
    no_intensity = read_frame(write_ply(tmp_path / "xyz.ply", points[:, :3], binary=binary))
    assert np.isnan(no_intensity.points[:, 3]).all()


def test_npz_frames_flat_and_organized(tmp_path: Path) -> None:
    points = organized_points(3, 10, seed=5)
    np.savez(tmp_path / "flat.npz", points=points, stamp=np.float64(T0 + 1.5))
    flat = read_frame(tmp_path / "flat.npz")
    assert flat.stamp == T0 + 1.5 and not flat.organized
    assert len(flat.points) == np.isfinite(points[:, :3]).all(axis=1).sum()
    np.savez(tmp_path / "image.npz", points=points.reshape(3, 10, 4))
    image = read_frame(tmp_path / "image.npz", stamp=T0)
    assert (image.rows, image.columns, image.organized) == (3, 10, True)
    np.testing.assert_array_equal(image.points, points)


def test_file_names_carrying_times() -> None:
    assert time_from_name(Path("1700000000.123456789.pcd")) == pytest.approx(T0 + 0.123456789)
    assert time_from_name(Path("lidar_1700000000250000000.pcd")) == T0 + 0.25  # ns
    assert time_from_name(Path("1700000000250.ply")) == T0 + 0.25  # ms
    assert time_from_name(Path("sensor2_1700000000.npz")) == T0
    assert time_from_name(Path("000123.pcd")) is None  # a frame counter is not a time
    assert time_from_name(Path("frame.pcd")) is None


# --- malformed files ------------------------------------------------------------------------


def test_a_malformed_file_is_a_field_data_error_naming_it(tmp_path: Path) -> None:
    """The parser (wz_shared.pointcloud_files, tested with the LiDAR detector) says what is
    wrong; here it arrives as the drivers' FieldDataError, naming the file."""
    path = write_pcd(tmp_path / "cut.pcd", organized_points(2, 10, seed=8), rows=2, data="binary")
    path.write_bytes(path.read_bytes()[:-40])
    with pytest.raises(FieldDataError, match="truncated") as caught:
        read_frame(path)
    assert caught.value.path == str(path)
    points = organized_points(1, 5, seed=9)[:, [0, 1, 3]]
    with pytest.raises(FieldDataError, match="z"):
        read_frame(write_pcd(tmp_path / "noz.pcd", points, fields=("x", "y", "intensity")))


def test_not_a_point_cloud(tmp_path: Path) -> None:
    (tmp_path / "notes.pcd").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00binary junk")
    with pytest.raises(FieldDataError, match=r"notes\.pcd"):
        read_frame(tmp_path / "notes.pcd")
    with pytest.raises(FieldDataError, match="no such file"):
        read_frame(tmp_path / "missing.pcd")


# --- folders --------------------------------------------------------------------------------


def test_folder_with_timestamps_csv_reports_and_skips_bad_frames(tmp_path: Path) -> None:
    frames = tmp_path / "frames"
    frames.mkdir()
    for index in range(1, 7):
        write_pcd(
            frames / f"{index:06d}.pcd",
            organized_points(2, 8, seed=index),
            rows=2,
            data="binary" if index % 2 else "ascii",
        )
    # Frame 3 truncated; frame 5's time goes back; frame 6 has no row.
    path3 = frames / "000003.pcd"
    path3.write_bytes(path3.read_bytes()[:-10])
    (frames / "README.txt").write_text("not a frame")
    csv_path = tmp_path / "timestamps.csv"
    csv_path.write_text(
        "file,time_unix_s\n"
        f"000001.pcd,{T0}\n000002.pcd,{T0 + 0.1}\n000003.pcd,{T0 + 0.2}\n"
        f"000004.pcd,{T0 + 0.3}\n000005.pcd,{T0 + 0.25}\n"
    )
    problems = Problems()
    sweeps = list(read_frame_folder(frames, problems, timestamps=csv_path))
    assert [Path(s.where).name for s in sweeps] == ["000001.pcd", "000002.pcd", "000004.pcd"]
    assert [s.stamp for s in sweeps] == [T0, T0 + 0.1, T0 + 0.3]
    np.testing.assert_allclose(
        sweeps[1].points, organized_points(2, 8, seed=2), rtol=1e-6, equal_nan=True
    )
    messages = [str(error) for error in problems.errors]
    assert len(messages) == 3, messages
    assert messages[0].startswith(f"{path3}: header says 16 points")
    assert messages[1].startswith(
        f"{csv_path}:6: time 1700000000.250000 of 000005.pcd is not "
        "after 1700000000.300000 (000004.pcd)"
    )
    assert messages[2] == f"{frames / '000006.pcd'}: no row in {csv_path}: frame skipped"


def test_folder_times_from_names_and_npz_stamps(tmp_path: Path) -> None:
    rng_points = organized_points(1, 12, seed=10)
    write_pcd(tmp_path / "scan_1700000000.5.pcd", rng_points)
    write_pcd(tmp_path / "scan_1700000000.25.pcd", rng_points)  # .25 sorts before .5
    write_ply(tmp_path / "scan_1700000001000000000.ply", rng_points[:4], binary=True)  # ns
    np.savez(tmp_path / "scan_later.npz", points=rng_points, stamp=np.float64(T0 + 2))
    write_pcd(tmp_path / "scan_noname.pcd", rng_points)
    problems = Problems()
    sweeps = list(read_frame_folder(tmp_path, problems))
    assert [s.stamp for s in sweeps] == [T0 + 0.25, T0 + 0.5, T0 + 1.0, T0 + 2.0]
    assert [str(e) for e in problems.errors] == [
        f"{tmp_path / 'scan_noname.pcd'}: no time in the file name: frame skipped"
    ]


def test_folder_without_any_time_or_frames_raises(tmp_path: Path) -> None:
    write_pcd(tmp_path / "000001.pcd", organized_points(1, 4, seed=11))
    with pytest.raises(FieldDataError, match="no time for the frames"):
        list(read_frame_folder(tmp_path, Problems()))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FieldDataError, match="no frame files"):
        list(read_frame_folder(empty, Problems()))
    with pytest.raises(FieldDataError, match="no such folder"):
        list(read_frame_folder(tmp_path / "absent", Problems()))


def test_timestamps_csv_without_time_column_raises(tmp_path: Path) -> None:
    write_pcd(tmp_path / "000001.pcd", organized_points(1, 4, seed=12))
    (tmp_path / "times.csv").write_text("file,stamp\n000001.pcd,1\n")
    with pytest.raises(FieldDataError, match=r"times.csv:1: missing columns: time \(time_unix_s"):
        list(read_frame_folder(tmp_path, Problems(), timestamps=tmp_path / "times.csv"))
