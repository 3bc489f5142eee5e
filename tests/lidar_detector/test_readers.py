"""Point-cloud file readers: the real freeway frame, round trips of every format, and bad files.

The writers here are written from the format specifications, independently of the readers, so a
round trip checks one against the other.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from wz_shared.pointcloud_files import (
    PointCloudFileError,
    lzf_decompress,
    read_npz,
    read_pcd,
    read_ply,
    read_point_cloud,
)

REAL = Path(__file__).resolve().parents[2] / "samples" / "real-freeway-lidar"
CUT = Path(__file__).resolve().parent / "data" / "rawdata-cut.pcd"
# The real frame ships in samples/real-freeway-lidar (its README: source and use).
Fields = Sequence[tuple[str, str, int]]  # (name, PCD TYPE, SIZE)
XYZI: Fields = (("x", "F", 4), ("y", "F", 4), ("z", "F", 4), ("intensity", "F", 4))


def cloud(count: int, seed: int = 0) -> npt.NDArray[np.float32]:
    """``(count, 4)`` float32 x, y, z, intensity with a few NaN points."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-50.0, 50.0, size=(count, 4)).astype(np.float32)
    points[:, 3] = rng.integers(0, 255, count)
    points[::5, :3] = np.nan
    return points


def lzf_literals(raw: bytes) -> bytes:
    """A valid LZF stream of literal runs only (the simplest encoder the format allows)."""
    out = bytearray()
    for start in range(0, len(raw), 32):
        chunk = raw[start : start + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def write_pcd(
    path: Path,
    columns: dict[str, npt.NDArray[np.generic]],
    fields: Fields,
    data: str,
    *,
    width: int | None = None,
    height: int = 1,
    header_points: int | None = None,
) -> Path:
    """A PCD v0.7 file of ``columns`` (one array per field name) as ``fields`` say."""
    count = len(next(iter(columns.values())))
    width = count // height if width is None else width
    numpy_types = {"F": "f", "I": "i", "U": "u"}
    dtypes = [np.dtype(f"<{numpy_types[kind]}{size}") for _, kind, size in fields]
    header = "\n".join(
        [
            "# .PCD v0.7 - Point Cloud Data file format",
            "VERSION 0.7",
            "FIELDS " + " ".join(name for name, _, _ in fields),
            "SIZE " + " ".join(str(size) for _, _, size in fields),
            "TYPE " + " ".join(kind for _, kind, _ in fields),
            "COUNT " + " ".join("1" for _ in fields),
            f"WIDTH {width}",
            f"HEIGHT {height}",
            "VIEWPOINT 0 0 0 1 0 0 0",
            f"POINTS {count if header_points is None else header_points}",
            f"DATA {data}",
            "",
        ]
    ).encode()
    arrays = [columns[name].astype(dt) for (name, _, _), dt in zip(fields, dtypes, strict=True)]
    if data == "ascii":
        body = "".join(
            " ".join("nan" if np.isnan(v) else str(v) for v in row) + "\n"
            for row in zip(*(a.tolist() for a in arrays), strict=True)
        ).encode()
    elif data == "binary":
        record = np.dtype([(f"f{i}", dt) for i, dt in enumerate(dtypes)])
        table = np.empty(count, dtype=record)
        for i, array in enumerate(arrays):
            table[f"f{i}"] = array
        body = table.tobytes()
    else:
        raw = b"".join(array.tobytes() for array in arrays)
        compressed = lzf_literals(raw)
        body = struct.pack("<II", len(compressed), len(raw)) + compressed
    path.write_bytes(header + body)
    return path


def xyzi(points: npt.NDArray[np.float32]) -> dict[str, npt.NDArray[np.generic]]:
    return {name: points[:, i] for i, name in enumerate(("x", "y", "z", "intensity"))}


def write_ply(
    path: Path, points: npt.NDArray[np.float32], fmt: str, *, faces: bool = False
) -> Path:
    names = ("x", "y", "z", "intensity")
    header = [f"ply\nformat {fmt} 1.0\ncomment written by the tests\n"]
    header.append(f"element vertex {len(points)}\n")
    header += [f"property float {name}\n" for name in names]
    if faces:
        header.append("element face 1\nproperty list uchar int vertex_indices\n")
    header.append("end_header\n")
    if fmt == "ascii":
        body = "".join(" ".join(str(v) for v in row) + "\n" for row in points.tolist())
        body += "3 0 1 2\n" if faces else ""
        data = body.encode()
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        data = points.astype(order + "f4").tobytes()
        data += struct.pack(order + "B3i", 3, 0, 1, 2) if faces else b""
    path.write_bytes("".join(header).encode() + data)
    return path


def assert_same(actual: npt.NDArray[np.float32], expected: npt.NDArray[np.float32]) -> None:
    np.testing.assert_array_equal(np.isnan(actual), np.isnan(expected))
    np.testing.assert_allclose(actual, expected, rtol=1e-6, equal_nan=True)


# --- the real freeway frame -----------------------------------------------------------------


def test_real_organized_ascii_frame() -> None:
    frame = read_point_cloud(REAL / "rawdata.pcd")
    assert (frame.rows, frame.columns) == (80, 1800) and frame.organized
    assert frame.points.shape == (144_000, 4) and frame.points.dtype == np.float32
    returns = np.isfinite(frame.points[:, 0])
    assert 90_000 < returns.sum() < 100_000  # "about 95,000 real returns"
    assert np.isfinite(frame.points[:, 3]).all()  # intensity 0 on no-return slots, not NaN
    # The sensor is mounted high: ground returns lie metres below it.
    assert np.nanmedian(frame.points[returns, 2]) < -3.0
    # The cut shipped with the tests is rows 40-47, columns 1200-1229 of this frame.
    cut = read_pcd(CUT)
    image = frame.points.reshape(80, 1800, 4)
    assert_same(cut.points.reshape(8, 30, 4), image[40:48, 1200:1230])


def test_real_background_ascii_and_filtered_binary() -> None:
    background = read_point_cloud(REAL / "background.pcd")
    assert (background.rows, background.columns) == (1, 90_059) and not background.organized
    assert np.isfinite(background.points[:, :3]).all() and np.isnan(background.points[:, 3]).all()
    filtered = read_point_cloud(REAL / "filtered.pcd")
    assert filtered.points.shape == (13_152, 4) and np.isfinite(filtered.points[:, :3]).all()
    # The foreground the paper found is a subset of the raw frame's returns.
    raw = read_point_cloud(REAL / "rawdata.pcd").points
    raw_keys = {tuple(p) for p in raw[np.isfinite(raw[:, 0]), :3].tolist()}
    assert sum(tuple(p) in raw_keys for p in filtered.points[:200, :3].tolist()) == 200


def test_shipped_cut_is_organized_with_nan_kept() -> None:
    frame = read_pcd(CUT)
    assert (frame.rows, frame.columns, frame.organized) == (8, 30, True)
    assert 0 < np.isnan(frame.points[:, 0]).sum() < 240
    assert frame.points[0].tolist() == pytest.approx([14.52667, -2.688548, -3.554469, 4.0])


# --- round trips ----------------------------------------------------------------------------


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
def test_pcd_round_trip_organized(tmp_path: Path, data: str) -> None:
    points = cloud(6 * 10, seed=1)
    path = write_pcd(tmp_path / f"{data}.pcd", xyzi(points), XYZI, data, width=10, height=6)
    frame = read_pcd(path)
    assert (frame.rows, frame.columns, frame.organized) == (6, 10, True)
    assert_same(frame.points, points)


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
def test_pcd_fields_in_any_order_with_others_ignored(tmp_path: Path, data: str) -> None:
    points = cloud(25, seed=2)
    columns = {**xyzi(points), "ring": np.arange(25) % 4, "rgb": np.arange(25, dtype=np.float32)}
    fields: Fields = (
        ("rgb", "F", 4),
        ("intensity", "U", 2),
        ("z", "F", 8),
        ("ring", "U", 1),
        ("y", "F", 4),
        ("x", "F", 4),
    )
    points[:, 3] = np.floor(points[:, 3])
    frame = read_pcd(write_pcd(tmp_path / "any.pcd", columns, fields, data))
    assert (frame.rows, frame.columns) == (1, 25)
    assert_same(frame.points, points)


def test_pcd_without_intensity_reads_nan_intensity(tmp_path: Path) -> None:
    points = cloud(12, seed=3)
    fields = XYZI[:3]
    frame = read_pcd(write_pcd(tmp_path / "xyz.pcd", xyzi(points), fields, "binary"))
    assert np.isnan(frame.points[:, 3]).all()
    assert_same(frame.points[:, :3], points[:, :3])


def test_open3d_binary_compressed_pcd_and_binary_ply(tmp_path: Path) -> None:
    """A real LZF encoder (Open3D's) with back references, not only literal runs."""
    o3d = pytest.importorskip("open3d")
    rng = np.random.default_rng(4)
    xyz = rng.normal(0.0, 20.0, size=(3000, 3)).astype(np.float32)
    xyz[::3] = xyz[0]  # repeats make the encoder emit back references
    intensity = rng.random((3000, 1)).astype(np.float32)
    pc = o3d.t.geometry.PointCloud(o3d.core.Tensor(xyz))
    pc.point["intensity"] = o3d.core.Tensor(intensity)
    o3d.t.io.write_point_cloud(str(tmp_path / "c.pcd"), pc, write_ascii=False, compressed=True)
    o3d.t.io.write_point_cloud(str(tmp_path / "c.ply"), pc, write_ascii=False)
    assert b"DATA binary_compressed" in (tmp_path / "c.pcd").read_bytes()[:400]
    for name in ("c.pcd", "c.ply"):
        frame = read_point_cloud(tmp_path / name)
        np.testing.assert_array_equal(frame.points[:, :3], xyz)
        np.testing.assert_array_equal(frame.points[:, 3], intensity[:, 0])


def test_lzf_back_references_by_hand() -> None:
    # "abc", then a back reference of length 7 (2 + 5) at distance 3: overlapping repeat.
    stream = bytes([2]) + b"abc" + bytes([(5 << 5) | 0, 2])
    assert lzf_decompress(stream, 10) == b"abcabcabca"
    # A long reference: length field 7 plus an extra byte 10 -> 7 + 10 + 2 = 19 bytes.
    stream = bytes([0]) + b"z" + bytes([(7 << 5) | 0, 10, 0])
    assert lzf_decompress(stream, 20) == b"z" * 20
    with pytest.raises(ValueError, match="before the start"):
        lzf_decompress(bytes([(1 << 5) | 0, 5]), 3)
    with pytest.raises(ValueError, match="expected 8"):
        lzf_decompress(bytes([2]) + b"abc", 8)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_round_trip(tmp_path: Path, fmt: str) -> None:
    points = cloud(40, seed=5)
    frame = read_ply(write_ply(tmp_path / "c.ply", points, fmt, faces=True))
    assert (frame.rows, frame.columns) == (1, 40)
    assert_same(frame.points, points)


def test_npz_layouts(tmp_path: Path) -> None:
    points = cloud(6 * 8, seed=6)
    # The simulator's dataset export: (N, 4) points and a stamp; organized by the hint only.
    np.savez_compressed(
        tmp_path / "sim.npz", points=points, labels=np.zeros(48, np.int32), stamp_s=np.array(12.35)
    )
    frame = read_npz(tmp_path / "sim.npz")
    assert (frame.rows, frame.columns, frame.stamp_s) == (1, 48, pytest.approx(12.35))
    assert_same(frame.points, points)
    hinted = read_point_cloud(tmp_path / "sim.npz", shape_hint=(6, 8))
    assert (hinted.rows, hinted.columns) == (6, 8)
    assert read_npz(tmp_path / "sim.npz", shape_hint=(5, 8)).rows == 1  # does not fit: ignored
    # An image (rows, columns, 4), and rows/columns scalars.
    np.savez(tmp_path / "image.npz", points=points.reshape(6, 8, 4))
    assert (read_npz(tmp_path / "image.npz").rows, read_npz(tmp_path / "image.npz").columns) == (
        6,
        8,
    )
    np.savez(tmp_path / "shaped.npz", points=points, rows=6, columns=8)
    assert read_npz(tmp_path / "shaped.npz").organized
    # Separate arrays, 2-D for an organized frame, without intensity.
    np.savez(tmp_path / "xyz.npz", **{k: points[:, i].reshape(6, 8) for i, k in enumerate("xyz")})
    frame = read_npz(tmp_path / "xyz.npz")
    assert (frame.rows, frame.columns) == (6, 8) and np.isnan(frame.points[:, 3]).all()
    assert_same(frame.points[:, :3], points[:, :3])


# --- bad files ------------------------------------------------------------------------------


def test_truncated_ascii_pcd_names_both_counts(tmp_path: Path) -> None:
    points = cloud(144, seed=7)
    path = write_pcd(tmp_path / "t.pcd", xyzi(points), XYZI, "ascii", width=12, height=12)
    header, body = path.read_text().split("DATA ascii\n")
    path.write_text(header + "DATA ascii\n" + "\n".join(body.split("\n")[:12]))
    with pytest.raises(PointCloudFileError, match="header says 144 points, data has 12") as info:
        read_point_cloud(path)
    assert str(path) in str(info.value) and info.value.path == path


def test_truncated_binary_and_compressed_pcd(tmp_path: Path) -> None:
    points = cloud(100, seed=8)
    binary = write_pcd(tmp_path / "b.pcd", xyzi(points), XYZI, "binary")
    binary.write_bytes(binary.read_bytes()[:-200])
    with pytest.raises(PointCloudFileError, match="header says 100 points, data has 87"):
        read_pcd(binary)
    compressed = write_pcd(tmp_path / "c.pcd", xyzi(points), XYZI, "binary_compressed")
    compressed.write_bytes(compressed.read_bytes()[:-10])
    with pytest.raises(PointCloudFileError, match="truncated"):
        read_pcd(compressed)
    compressed.write_bytes(compressed.read_bytes()[: compressed.read_bytes().index(b"DATA")])
    with pytest.raises(PointCloudFileError, match="ends inside the header"):
        read_pcd(compressed)


def test_wrong_field_counts(tmp_path: Path) -> None:
    points = cloud(10, seed=9)
    path = write_pcd(tmp_path / "w.pcd", xyzi(points), XYZI, "ascii")
    text = path.read_text()
    path.write_text(text.replace("SIZE 4 4 4 4", "SIZE 4 4 4"))
    with pytest.raises(PointCloudFileError, match=r"4 FIELDS .* but 3 SIZE values"):
        read_pcd(path)
    lines = text.split("\n")
    lines[14] = " ".join(lines[14].split()[:3])  # one data line loses its intensity
    path.write_text("\n".join(lines))
    with pytest.raises(PointCloudFileError, match="data line 4 has 3 values, expected 4"):
        read_pcd(path)
    lines[11] = "1 2 abc 4"
    path.write_text("\n".join(lines))
    with pytest.raises(PointCloudFileError, match="data line 1 is not numbers: '1 2 abc 4'"):
        read_pcd(path)
    ply = write_ply(tmp_path / "w.ply", points, "ascii")
    ply_lines = ply.read_text().split("\n")
    ply_lines[-3] = "1 2 3"
    ply.write_text("\n".join(ply_lines))
    with pytest.raises(PointCloudFileError, match="vertex 9 has 3 values, expected 4"):
        read_ply(ply)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("FIELDS x y z intensity", "FIELDS a y z intensity"), "no x field"),
        (("DATA ascii", "DATA zipped"), "DATA 'zipped'"),
        (("POINTS 10", "POINTS 11"), "POINTS 11 is not WIDTH x HEIGHT"),
        (("WIDTH 10", "WIDTH ten"), "WIDTH 'ten' is not an integer"),
        (("TYPE F F F F", "TYPE F F F X"), "TYPE X with SIZE 4"),
        (("VERSION 0.7", "COLOUR red"), "is not PCD"),
    ],
)
def test_bad_pcd_header(tmp_path: Path, change: tuple[str, str], message: str) -> None:
    path = write_pcd(tmp_path / "h.pcd", xyzi(cloud(10)), XYZI, "ascii")
    path.write_text(path.read_text().replace(*change))
    with pytest.raises(PointCloudFileError, match=message):
        read_pcd(path)


def test_not_a_point_cloud(tmp_path: Path) -> None:
    garbage = tmp_path / "frame.pcd"
    garbage.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(PointCloudFileError, match=r"not ASCII|not PCD"):
        read_point_cloud(garbage)
    with pytest.raises(PointCloudFileError, match="cannot read"):
        read_point_cloud(tmp_path / "missing.pcd")
    bad_zip = tmp_path / "bad.npz"
    bad_zip.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(PointCloudFileError, match="not a readable NPZ"):
        read_point_cloud(bad_zip)
    np.savez(tmp_path / "empty.npz", labels=np.zeros(3))
    with pytest.raises(PointCloudFileError, match="no points array"):
        read_point_cloud(tmp_path / "empty.npz")
    np.savez(tmp_path / "flat.npz", points=np.zeros(12))
    with pytest.raises(PointCloudFileError, match=r"points has shape \(12,\)"):
        read_point_cloud(tmp_path / "flat.npz")
    unknown = tmp_path / "cloud.xyz"
    unknown.write_text("1 2 3\n")
    with pytest.raises(PointCloudFileError, match="not a PCD, PLY or NPZ"):
        read_point_cloud(unknown)
    ply = write_ply(tmp_path / "t.ply", cloud(50), "binary_little_endian")
    ply.write_bytes(ply.read_bytes()[:-64])
    with pytest.raises(PointCloudFileError, match="header says 50 points, data has 46"):
        read_point_cloud(ply)
