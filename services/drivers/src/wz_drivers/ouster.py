"""Ouster LiDAR through ouster-sdk: recordings (pcap with its metadata JSON, OSF), live sensors,
and Ouster recordings made from simulated sweeps.

Each complete scan becomes one :class:`~wz_drivers.records.LidarSweep`, organized like the
simulator's frames, so the LiDAR detector takes a real Ouster and the simulated mast LiDAR alike.

Frames of reference
-------------------
Ouster documents two frames. The *lidar* frame has its origin on the spin axis at the height of
the beams and its x axis towards the external connector; the *sensor* frame (the one printed on
the housing) has x pointing away from the connector, y left, z up, origin at the centre of the
base. ``lidar_to_sensor_transform`` of the metadata takes the first to the second (a half turn
about z and a lift along z, 36.18 mm on an OS-1). Points are returned in the **sensor frame**:
``XYZLut(info, use_extrinsics=False)`` applies ``lidar_to_sensor_transform`` (and the beam
origin offset ``lidar_origin_to_beam_origin_mm``) and *not* ``sensor_to_body``, the user
extrinsics: the site file's mount pose of the sensor plays that part downstream. The site
file's pose of an Ouster is thus the pose of the centre of its base, x away from the connector.

Range image
-----------
Row ``i`` is beam ``i`` (row 0 the highest, as Ouster numbers its beams and as the simulator
orders its rows); column ``j`` is measurement block ``j``, fired at ``timestamp[j]``. Its
encoder angle puts column 0 towards the connector (behind the sensor), column ``W/4`` to the
left, ``W/2`` forwards: the azimuth of column ``j`` in the sensor frame is ``pi - 2 pi j / W``
(plus the beam's small ``beam_azimuth_angles`` offset), the head spinning clockwise seen from
above - the simulator's convention exactly. Columns are kept *staggered* (measurement order, as
ouster-sdk stores them): every pixel of a column fired at the column's time, so column ``j``
fired at ``stamp + sweep_duration_s * j / W`` as :class:`~wz_shared.messages.LidarFrameMeta`
says. (The destaggered image of Ouster's viewers shifts each row by ``pixel_shift_by_row``
columns so that a column is one azimuth; with non-zero beam azimuth offsets its columns no
longer fired at one time.)

Points and intensity
--------------------
``points`` is ``(rows * columns, 4)`` float32, row-major: x, y, z [m] and intensity. A pixel
with no return (RANGE 0) or in a column the sensor did not send (status not valid, outside the
azimuth window) is NaN in all four, as the simulator writes no-return cells and as the
detector reads them (a zero point would be a return at the sensor itself). Intensity is the
calibrated REFLECTIVITY channel divided by 100: 0..1 for diffuse targets (Ouster's 0..100 %
reflectivity), above 1 for retroreflectors (Ouster's 101..255 band, not linear), the same
scale as the simulator's range-compensated reflectivity. NaN when the lidar profile has no
REFLECTIVITY. Dual-return profiles: the strongest return (RANGE) only, not RANGE2.

Time
----
``stamp`` is the time of column 0 [Unix s]: the timestamp of the first valid column, which is
column 0 in any full-azimuth recording (with an azimuth window, extrapolated back from the
first valid column at the sweep's column rate). ``sweep_duration_s`` is the column rate
measured from the first to the last valid column, times the columns. A sensor timed by PTP
stamps its columns in Unix time (TAI-UTC aside, as configured on the grandmaster); one on its
internal oscillator (Ouster's default ``TIME_FROM_INTERNAL_OSC``) counts from power-on: then
the capture time of the scan's first valid packet (pcap record time, or the host's receive
time live) replaces the clock, to within the network latency (and the capture times'
resolution, 1 us in a classic pcap), and the column timestamps still give the sweep's duration.

Bad data
--------
A pcap is read packet by packet (``PcapPacketSource``) and batched into scans
(``FrameBatcher``), so that every bad packet is named: a lidar packet of the wrong size or
another sensor's id, or one failing its CRC (profiles with a CRC footer), is reported to the
:class:`~wz_drivers.records.Problems` and left out; a scan that misses packets is reported and
skipped (packets lost in capture; not reported again when it lacks a packet already reported);
packets the batcher drops because their frame id or time goes back (a sensor restart, packets
out of order) are reported once per run, and so is a scan whose stamp does not follow the
last one's; the partial first scan (recording started mid-rotation) and partial last scan are
skipped silently. A file cut in the middle of a packet, or a pcap record header that makes no sense
(the rest of the file is then unreadable), is reported once, naming the pcap record (the
frame number Wireshark shows). A missing file, a file that is not a pcap, a missing or invalid
metadata file, or a recording with not one packet of the metadata's sensor raises
:class:`~wz_drivers.records.FieldDataError`.
"""

from __future__ import annotations

import json
import logging
import math
import os
import struct
from collections.abc import Iterable, Iterator
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Literal

import numpy as np
import numpy.typing as npt

# ouster.sdk.core and ouster.sdk.pcap re-export these without ``as`` (mypy --strict refuses
# such implicit re-exports): they are imported from the modules that define them.
from ouster.sdk._bindings.client import (
    FrameBatcher,
    FrameSetSource,
    LidarFrame,
    LidarMode,
    LidarPacket,
    Packet,
    PacketFormat,
    PacketValidationFailure,
    SensorInfo,
    TimestampMode,
    UDPProfileLidar,
    XYZLut,
    frame_to_packets,
    parse_and_validate_metadata,
)
from ouster.sdk._bindings.pcap import PcapPacketSource
from ouster.sdk.core.data import ChanField
from ouster.sdk.open_source import SourceURLException, open_source
from ouster.sdk.pcap.pcap import record

from wz_drivers.records import FieldDataError, LidarSweep, Problems
from wz_shared.arrays import F64

log = logging.getLogger(__name__)


#: Column timestamps below this (2000-01-01, in ns) count from power-on, not from 1970.
_UNIX_2000_NS = 946_684_800 * 10**9
#: Ouster's lidar modes (columns per frame, frames per second).
STANDARD_MODES: frozenset[tuple[int, int]] = frozenset(
    {(512, 10), (512, 20), (1024, 10), (1024, 20), (2048, 10), (4096, 5)}
)
#: Beam counts of the OS sensors.
STANDARD_CHANNELS: frozenset[int] = frozenset({16, 32, 64, 128})
#: Lidar UDP profiles :func:`write_ouster_pcap` can write (both carry REFLECTIVITY).
WritableProfile = Literal["RNG19_RFL8_SIG16_NIR16", "LEGACY"]
TimestampModeName = Literal["TIME_FROM_PTP_1588", "TIME_FROM_INTERNAL_OSC"]
#: Pcap magic numbers (classic, microsecond and nanosecond; either byte order) and pcapng's.
_PCAP_MAGIC = {
    b"\xd4\xc3\xb2\xa1": "<",
    b"\xa1\xb2\xc3\xd4": ">",
    b"\x4d\x3c\xb2\xa1": "<",
    b"\xa1\xb2\x3c\x4d": ">",
}
_PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
#: pcapng block types that hold one packet: obsolete packet, simple packet, enhanced packet.
_PCAPNG_PACKET_BLOCKS = frozenset({2, 3, 6})


# --- reading ------------------------------------------------------------------------------


def load_metadata(path: Path) -> SensorInfo:
    """Parse and validate an Ouster sensor metadata JSON file.

    Raises
    ------
    FieldDataError
        The file is missing or unreadable, not JSON, or not valid sensor metadata (the
        message lists ouster-sdk's critical issues).
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FieldDataError(path, f"cannot read the Ouster metadata file: {exc}") from exc
    try:
        info, issues = parse_and_validate_metadata(text)
    except RuntimeError as exc:  # ouster-sdk's JSON parser
        raise FieldDataError(path, f"not Ouster sensor metadata JSON: {exc}") from exc
    if info is None:
        critical = "; ".join(str(entry) for entry in issues.critical) or "rejected by ouster-sdk"
        raise FieldDataError(path, f"invalid Ouster sensor metadata: {critical}")
    return info


def read_ouster(path: Path, metadata: Path | None, problems: Problems) -> Iterator[LidarSweep]:
    """The sweeps of an Ouster recording, one per complete scan, in file order.

    Parameters
    ----------
    path : Path
        A pcap (classic or pcapng) of the sensor's lidar UDP packets, or an OSF file.
    metadata : Path or None
        The sensor metadata JSON recorded with a pcap (``None``: ``<path stem>.json`` beside
        it, as ouster-cli names it). Ignored for OSF, which carries its own.
    problems : Problems
        Receives a :class:`FieldDataError` per bad packet or skipped scan (see the module
        docstring); the reading goes on.

    Returns
    -------
    iterator of LidarSweep
        Organized ``rows = beams`` x ``columns = columns_per_frame`` sweeps in the sensor
        frame; ``where`` is ``"<path> (scan <n>, frame id <id>)"``, n counting from 1 every
        scan the file starts, complete or not.

    Raises
    ------
    FieldDataError
        At once: the file is missing or not a pcap / OSF, or the metadata is missing or
        invalid. While iterating: not one lidar packet of this sensor in the pcap.
    """
    if not path.is_file():
        raise FieldDataError(path, "no such Ouster recording")
    if path.suffix.lower() == ".osf":
        if metadata is not None:
            log.info("%s: OSF carries its own metadata; %s not used", path, metadata)
        try:
            source = open_source(str(path), collate=False, sensor_idx=0)
        except (SourceURLException, RuntimeError) as exc:
            raise FieldDataError(path, f"ouster-sdk cannot read this OSF: {exc}") from exc
        if len(source.sensor_info) != 1:
            log.warning("%s: %d sensors; reading the first", path, len(source.sensor_info))
        return _frame_sweeps(source, str(path), problems)
    if metadata is None:
        metadata = path.with_suffix(".json")
        if not metadata.is_file():
            raise FieldDataError(
                path, f"no sensor metadata given and no {metadata.name} beside the recording"
            )
    info = load_metadata(metadata)
    with path.open("rb") as stream:
        magic = stream.read(4)
    if magic not in _PCAP_MAGIC and magic != _PCAPNG_MAGIC:
        raise FieldDataError(path, "not a pcap file (nor OSF): unknown magic number")
    return _read_pcap(path, info, problems)


def open_live(
    hostname: str, problems: Problems, *, lidar_port: int | None = None
) -> Iterator[LidarSweep]:
    """Sweeps of a live Ouster sensor, as they come (blocks until the next complete scan).

    ouster-sdk connects to the sensor by its HTTP API, fetches its metadata, and sets it to
    send its UDP packets to this host; the scans are converted exactly as a recording's. An
    incomplete scan (packets dropped on the network) is reported to ``problems`` and skipped.
    Internal-oscillator timestamps are replaced by the host's receive time (see the module
    docstring): time the sensor by PTP for column times in Unix time.

    Parameters
    ----------
    hostname : str
        The sensor's hostname or IP address.
    problems : Problems
        Receives the skipped scans.
    lidar_port : int, optional
        UDP port to receive lidar packets on (ouster-sdk's choice when omitted).

    Raises
    ------
    FieldDataError
        The sensor cannot be reached or configured.
    """
    options: dict[str, int] = {} if lidar_port is None else {"lidar_port": lidar_port}
    try:
        source = open_source(hostname, collate=False, sensor_idx=0, **options)
    except (SourceURLException, RuntimeError) as exc:
        raise FieldDataError(hostname, f"cannot open the Ouster sensor: {exc}") from exc
    return _frame_sweeps(source, hostname, problems)


def _frame_sweeps(source: FrameSetSource, where: str, problems: Problems) -> Iterator[LidarSweep]:
    """Sweeps of a frame source of one sensor (OSF, live), incomplete scans reported."""
    with closing(source):
        converter = _ScanConverter(source.sensor_info[0], where)
        for scan_number, frame_set in enumerate(source, start=1):
            frame = frame_set[0]
            if frame is None:
                continue
            sweep = converter.checked(frame, scan_number, problems)
            if sweep is not None:
                yield sweep


def _read_pcap(path: Path, info: SensorInfo, problems: Problems) -> Iterator[LidarSweep]:
    try:
        source = PcapPacketSource(str(path), sensor_info=[info])
    except RuntimeError as exc:
        raise FieldDataError(path, f"ouster-sdk cannot read this pcap: {exc}") from exc
    converter = _ScanConverter(info, str(path))
    batcher = FrameBatcher(info)
    frame = LidarFrame(info)
    packet_format = PacketFormat(info)
    lidar_packets = 0  # lidar packets read (good or bad): the number errors give
    rejected = 0  # packets ouster-sdk itself dropped (wrong size or sensor id)
    scans = 0
    pending = 0  # packets batched into the scan not yet released
    explained = False  # the pending scan lacks a packet already reported
    stale = _StalePackets(path)
    with closing(source):
        try:
            for _, packet in source:
                if not isinstance(packet, LidarPacket):
                    continue
                lidar_packets += 1
                dropped = source.size_error_count + source.id_error_count
                if dropped > rejected:
                    problems.add(
                        FieldDataError(
                            path,
                            f"{dropped - rejected} packet(s) before this one have the wrong "
                            "size or another sensor's id for this metadata; left out",
                            line=lidar_packets,
                            unit="lidar packet",
                        )
                    )
                    rejected, explained = dropped, True
                fault = _packet_fault(packet, info, packet_format)
                if fault is not None:
                    problems.add(
                        FieldDataError(path, fault, line=lidar_packets, unit="lidar packet")
                    )
                    explained = True
                    continue
                pending += 1
                released = batcher.batch(packet, frame)
                if batcher.dropped_packets() > stale.count:
                    stale.add(lidar_packets, batcher.dropped_packets())
                    pending -= 1
                else:
                    stale.report(problems)
                if not released:
                    continue
                scans += 1
                # The batcher releases a scan when its last packet arrives or, if that was
                # lost, when the next scan's first packet does (and batches that one).
                pending = 0 if converter.complete(frame) else 1
                if scans == 1 and converter.starts_mid_rotation(frame):
                    log.info(
                        "%s: partial first scan (recording started mid-rotation) skipped", path
                    )
                elif explained and not converter.complete(frame):
                    log.debug("%s: scan %d skipped (bad packet reported)", path, scans)
                else:
                    sweep = converter.checked(frame, scans, problems)
                    if sweep is not None:
                        yield sweep
                explained = False
                frame = LidarFrame(info)
        except RuntimeError as exc:
            problems.add(
                FieldDataError(
                    path,
                    f"ouster-sdk stopped reading: {exc}",
                    line=lidar_packets,
                    unit="lidar packet",
                )
            )
    stale.report(problems)
    dropped = source.size_error_count + source.id_error_count
    damage = _pcap_damage(path)
    if lidar_packets == 0 and damage is not None:
        raise FieldDataError(
            path, f"{damage[1]}, before any whole lidar packet", line=damage[0], unit="pcap record"
        )
    if lidar_packets == 0:
        raise FieldDataError(
            path,
            "not one lidar packet of the metadata's sensor"
            + (f" ({dropped} of the wrong size or another sensor's id)" if dropped else "")
            + ": is the metadata file the one recorded with this pcap?",
        )
    if dropped > rejected:
        problems.add(
            FieldDataError(
                path,
                f"{dropped - rejected} packet(s) at the end have the wrong size or another "
                "sensor's id for this metadata; left out",
            )
        )
    if damage is not None:
        record, what = damage
        problems.add(
            FieldDataError(
                path, f"{what}; the scan it cut is skipped", line=record, unit="pcap record"
            )
        )
    elif pending:
        log.info("%s: partial last scan (recording stopped mid-rotation) skipped", path)


class _StalePackets:
    """Runs of packets ouster-sdk's scan batcher drops (their scan's frame id or time goes
    back), each reported once."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.count = 0  # dropped so far (the batcher's counter)
        self._first: int | None = None  # first packet of the open run
        self._last = 0

    def add(self, packet_number: int, count: int) -> None:
        self._first = packet_number if self._first is None else self._first
        self._last, self.count = packet_number, count

    def report(self, problems: Problems) -> None:
        if self._first is None:
            return
        problems.add(
            FieldDataError(
                self.path,
                f"lidar packets {self._first}..{self._last} dropped by ouster-sdk's "
                "scan batcher: their frame id or time goes back (sensor restarted, or packets out "
                "of order)",
                line=self._first,
                unit="lidar packet",
            )
        )
        self._first = None


def _packet_fault(packet: LidarPacket, info: SensorInfo, packet_format: PacketFormat) -> str | None:
    """Why a lidar packet cannot be used, or None."""
    failure = packet.validate(info, packet_format)
    if failure == PacketValidationFailure.PACKET_SIZE:
        return f"lidar packet of {len(packet.buf)} bytes, not {packet_format.lidar_packet_size}"
    if failure == PacketValidationFailure.ID:
        return "lidar packet of another sensor (init_id / serial number differ from metadata)"
    crc = packet.crc()
    if crc is not None and crc != packet.calculate_crc():
        return "lidar packet fails its CRC check (corrupt data)"
    return None


def _pcap_damage(path: Path) -> tuple[int, str] | None:
    """The first structural fault of a pcap or pcapng file: (1-based record, what), or None.

    Only the record (block) headers are read: a record longer than the bytes left means the
    file was cut inside it; a classic pcap record longer than the snapshot length means its
    header is garbage (ouster-sdk stops reading there).
    """
    size = path.stat().st_size
    with path.open("rb") as stream:
        head = stream.read(24)
        if head[:4] == _PCAPNG_MAGIC:
            return _pcapng_damage(stream, head, size)
        order = _PCAP_MAGIC.get(head[:4])
        if order is None or len(head) < 24:
            return None
        snap_length = struct.unpack(order + "I", head[16:20])[0]
        offset, record = 24, 0
        while offset < size:
            record += 1
            header = stream.read(16)
            if len(header) < 16:
                return record, f"file ends inside the header of pcap record {record}"
            captured = struct.unpack(order + "IIII", header)[2]
            if captured > max(snap_length, 1 << 18):
                return record, (
                    f"pcap record header claims {captured} bytes (garbage): the "
                    "rest of the file cannot be read"
                )
            if offset + 16 + captured > size:
                return record, (
                    f"file ends inside a packet: {size - offset - 16} of "
                    f"{captured} bytes (truncated recording)"
                )
            offset += 16 + captured
            stream.seek(offset)
    return None


def _pcapng_damage(stream: BinaryIO, head: bytes, size: int) -> tuple[int, str] | None:
    """As :func:`_pcap_damage` for pcapng; the number is the packet's (packet blocks only,
    as Wireshark numbers them), the one a damaged block of any kind would have come before."""
    if len(head) < 12:
        return 1, "file ends inside the pcapng section header"
    order = "<" if head[8:12] == b"\x4d\x3c\x2b\x1a" else ">"
    offset, packets = 0, 0
    while offset < size:
        stream.seek(offset)
        header = stream.read(8)
        if len(header) < 8:
            return packets + 1, "file ends inside a pcapng block header (truncated recording)"
        block_type, length = struct.unpack(order + "II", header)
        if length < 12 or length % 4:
            return packets + 1, f"pcapng block length {length} (garbage): the rest is unreadable"
        if offset + length > size:
            return packets + 1, (
                f"file ends inside a block: {size - offset} of {length} bytes (truncated recording)"
            )
        packets += block_type in _PCAPNG_PACKET_BLOCKS
        offset += length
    return None


class _ScanConverter:
    """Ouster scans of one sensor to :class:`LidarSweep` (the conversion the module describes)."""

    def __init__(self, info: SensorInfo, where: str) -> None:
        self.info = info
        self.where = where
        self.rows = info.format.pixels_per_column
        self.columns = info.format.columns_per_frame
        self.columns_per_packet = info.format.columns_per_packet
        self.window = info.format.column_window
        self.fps = info.format.fps
        self.xyz_lut = XYZLut(info, use_extrinsics=False)
        self._clock_noted = False
        self._last_stamp_s = -math.inf

    def complete(self, frame: LidarFrame) -> bool:
        return bool(frame.complete(self.window))

    def starts_mid_rotation(self, frame: LidarFrame) -> bool:
        """Incomplete only at its start: its valid columns run unbroken to the window's end."""
        valid = np.flatnonzero(np.asarray(frame.status) & 1)
        return (
            not self.complete(frame)
            and len(valid) > 0
            and int(valid[-1]) == self.window[1]
            and len(valid) == int(valid[-1] - valid[0]) + 1
        )

    def checked(self, frame: LidarFrame, scan_number: int, problems: Problems) -> LidarSweep | None:
        """The sweep of a scan; None, reported, for one incomplete, without a valid column, or
        whose time goes back."""
        if not self.complete(frame):
            valid = int(np.count_nonzero(np.asarray(frame.status) & 1))
            what = f"incomplete: {valid} of {self.columns} columns (packets lost)"
            sweep = None
        else:
            sweep = self.sweep(frame, scan_number)
            what = "no valid column"
        if sweep is not None and sweep.stamp <= self._last_stamp_s:
            what = f"time goes back: {sweep.stamp:.6f} s after {self._last_stamp_s:.6f} s"
            sweep = None
        if sweep is None:
            problems.add(
                FieldDataError(
                    self.where,
                    f"scan (frame id {frame.frame_id}) {what}; skipped",
                    line=scan_number,
                    unit="scan",
                )
            )
            return None
        self._last_stamp_s = sweep.stamp
        return sweep

    def sweep(self, frame: LidarFrame, scan_number: int) -> LidarSweep | None:
        """One scan as a sweep (None if not one column is valid)."""
        valid_column = (np.asarray(frame.status) & 1).astype(bool)
        valid_index = np.flatnonzero(valid_column)
        if len(valid_index) == 0:
            return None
        first, last = int(valid_index[0]), int(valid_index[-1])
        timestamp_ns = np.asarray(frame.timestamp, dtype=np.int64)
        if last > first:
            column_period_ns = (timestamp_ns[last] - timestamp_ns[first]) / (last - first)
            sweep_duration_s = float(column_period_ns * self.columns * 1e-9)
        else:
            column_period_ns = 1e9 / (self.fps * self.columns)
            sweep_duration_s = 1.0 / self.fps
        first_ns = int(timestamp_ns[first])
        if first_ns < _UNIX_2000_NS:
            first_ns += self._clock_offset_ns(frame, timestamp_ns, first)
        stamp_s = (first_ns - round(column_period_ns * first)) * 1e-9

        xyz_m = np.asarray(self.xyz_lut(frame))  # (rows, columns, 3), sensor frame
        range_mm = np.asarray(frame.field(ChanField.RANGE))
        image = np.empty((self.rows, self.columns, 4), dtype=np.float32)
        image[..., :3] = xyz_m
        if frame.has_field(ChanField.REFLECTIVITY):
            image[..., 3] = np.asarray(frame.field(ChanField.REFLECTIVITY)) / np.float32(100)
        else:
            image[..., 3] = np.nan
        image[(range_mm == 0) | ~valid_column[None, :]] = np.nan
        return LidarSweep(
            stamp=stamp_s,
            points=image.reshape(-1, 4),
            rows=self.rows,
            columns=self.columns,
            organized=True,
            where=f"{self.where} (scan {scan_number}, frame id {frame.frame_id})",
            sweep_duration_s=sweep_duration_s,
        )

    def _clock_offset_ns(
        self, frame: LidarFrame, timestamp_ns: npt.NDArray[np.int64], first: int
    ) -> int:
        """Unix time minus sensor time [ns], from the capture time of the first valid packet.

        The packet left the sensor after its last column fired; its capture time stands for
        that column's time (network latency aside). 0 when no capture time is known.
        """
        packet = first // self.columns_per_packet
        capture_ns = int(np.asarray(frame.packet_timestamp, dtype=np.int64)[packet])
        known = capture_ns >= _UNIX_2000_NS
        if not self._clock_noted:
            self._clock_noted = True
            log.log(
                logging.INFO if known else logging.WARNING,
                "%s: the sensor's clock is not Unix time (internal oscillator?): stamps %s",
                self.where,
                "from packet capture times"
                if known
                else "left in sensor time (no capture times either)",
            )
        if not known:
            return 0
        last_column = min((packet + 1) * self.columns_per_packet, self.columns) - 1
        return capture_ns - int(timestamp_ns[last_column])


# --- writing ------------------------------------------------------------------------------


@dataclass(frozen=True)
class OusterRecording:
    """What :func:`write_ouster_pcap` wrote.

    Attributes
    ----------
    scans, packets
        Scans and lidar packets (pcap records) written.
    points_in
        Returns offered (finite x, y, z) over all sweeps.
    points_written
        Returns in the range images: ``points_in`` less those outside the vertical field or
        the profile's range, and less those that shared a pixel with a nearer one.
    """

    scans: int
    packets: int
    points_in: int
    points_written: int


def synthetic_sensor_info(
    *,
    channels: int,
    columns_per_frame: int,
    vertical_min_deg: float,
    vertical_max_deg: float,
    rate_hz: int,
    udp_profile: WritableProfile = "RNG19_RFL8_SIG16_NIR16",
    timestamp_mode: TimestampModeName = "TIME_FROM_PTP_1588",
    serial_number: int = 992_000_000_001,
    init_id: int = 0x5A5A5,
    lidar_port: int = 7502,
    azimuth_window_deg: tuple[float, float] = (0.0, 360.0),
) -> SensorInfo:
    """Metadata of an idealised OS-1 whose pixels are the simulator's rays.

    Beam ``i`` at altitude ``vertical_max_deg - i * (vertical_max_deg - vertical_min_deg) /
    (channels - 1)`` (evenly spaced, highest first, as the simulator's beams), beam azimuth
    offsets 0 (so ``pixel_shift_by_row`` is 0: staggered and destaggered images coincide), beam
    origin on the spin axis (``lidar_origin_to_beam_origin_mm`` 0) and the lidar origin at the
    sensor origin (``lidar_to_sensor_transform`` the half turn about z of every Ouster, without
    the 36.18 mm lift of a real OS-1): every ray leaves the sensor origin, like the
    simulator's. Serial number, firmware and ``user_data`` say the recording is synthetic.
    ``azimuth_window_deg``: the sensor's azimuth window (Ouster's ``azimuth_window``, encoder
    angles in the lidar frame, where column ``j`` is at ``360 j / W`` deg and looks at
    ``180 - 360 j / W`` deg in the sensor frame): only the packets of those columns are sent,
    as a roadside unit set to the approach does (a smaller recording).

    Raises
    ------
    ValueError
        ``channels`` or ``(columns_per_frame, rate_hz)`` is not an Ouster mode, or the
        vertical field is empty.
    """
    if channels not in STANDARD_CHANNELS:
        raise ValueError(f"channels must be one of {sorted(STANDARD_CHANNELS)}, not {channels}")
    if (columns_per_frame, rate_hz) not in STANDARD_MODES:
        modes = ", ".join(f"{c}x{f}" for c, f in sorted(STANDARD_MODES))
        raise ValueError(f"{columns_per_frame}x{rate_hz} is not an Ouster lidar mode ({modes})")
    if not vertical_max_deg > vertical_min_deg:
        raise ValueError("vertical_max_deg must exceed vertical_min_deg")
    mode = LidarMode(f"{columns_per_frame}x{rate_hz}")
    profile = UDPProfileLidar.from_string(udp_profile)
    if profile is None:
        raise ValueError(f"unknown lidar UDP profile {udp_profile!r}")
    info = SensorInfo.from_default(mode)
    data_format = info.format
    data_format.pixels_per_column = channels
    data_format.udp_profile_lidar = profile
    data_format.pixel_shift_by_row = [0] * channels
    first, last = azimuth_window_deg
    if not 0.0 <= first < last <= 360.0:
        raise ValueError(f"azimuth window {azimuth_window_deg} is not 0 <= start < end <= 360")
    per_packet = data_format.columns_per_packet
    # Whole packets: the window's columns rounded out to packet boundaries.
    data_format.column_window = (
        math.floor(first / 360.0 * columns_per_frame / per_packet) * per_packet,
        min(
            columns_per_frame, math.ceil(last / 360.0 * columns_per_frame / per_packet) * per_packet
        )
        - 1,
    )
    info.format = data_format
    info.beam_altitude_angles = np.linspace(vertical_max_deg, vertical_min_deg, channels).tolist()
    info.beam_azimuth_angles = [0.0] * channels
    info.lidar_origin_to_beam_origin_mm = 0.0
    info.beam_to_lidar_transform = np.eye(4)
    info.lidar_to_sensor_transform = np.diag([-1.0, -1.0, 1.0, 1.0])
    info.sn = serial_number
    info.init_id = init_id
    info.prod_line = f"OS-1-{channels}"
    info.prod_pn = "SIMULATED"
    info.fw_rev = "v2.5.3"
    info.user_data = (
        "synthetic: written by wz_drivers.ouster.write_ouster_pcap from simulated sweeps"
    )
    config = info.config
    config.lidar_mode = mode
    config.udp_profile_lidar = profile
    config.udp_port_lidar = lidar_port
    config.udp_port_imu = lidar_port + 1
    config.timestamp_mode = TimestampMode.__members__[timestamp_mode]
    config.azimuth_window = (round(first * 1000), round(last * 1000))
    info.config = config
    return info


def write_ouster_pcap(
    sweeps: Iterable[LidarSweep],
    out_pcap: Path,
    out_metadata: Path,
    *,
    channels: int = 64,
    columns_per_frame: int = 1024,
    vertical_min_deg: float = -30.0,
    vertical_max_deg: float = 11.0,
    rate_hz: int = 20,
    udp_profile: WritableProfile = "RNG19_RFL8_SIG16_NIR16",
    timestamp_mode: TimestampModeName = "TIME_FROM_PTP_1588",
    lidar_port: int = 7502,
    azimuth_window_deg: tuple[float, float] = (0.0, 360.0),
) -> OusterRecording:
    """Write sweeps (e.g. simulated) as an Ouster recording: a pcap of lidar UDP packets and
    its sensor metadata JSON, which :func:`read_ouster`, ouster-sdk and Ouster's tools read.

    No real Ouster recording can be had here, so one is made from the simulator:

    1. Give the simulated mast LiDAR an Ouster geometry: ``beams`` = ``channels`` (64),
       ``azimuth_steps`` = ``columns_per_frame`` (1024), the site's vertical field (-30 to
       +11 deg) and ``rate_hz`` 20 (or 10), and simulate its sweeps
       (``LidarModel.scan``). Each sweep becomes ``LidarSweep(stamp=scan.meta.stamp,
       points=scan.points, rows=scan.meta.rows, columns=scan.meta.columns, organized=True,
       where=..., sweep_duration_s=scan.meta.sweep_duration_s)``.
    2. The metadata is :func:`synthetic_sensor_info`'s idealised OS-1-64 in mode
       ``{columns_per_frame}x{rate_hz}``, lidar profile ``RNG19_RFL8_SIG16_NIR16`` (single
       return; 19-bit range in mm, to 524 m; calibrated reflectivity; signal; near-IR), with
       beams and columns placed exactly on the simulator's rays.
    3. Each sweep's returns (rows with finite x, y, z; NaN rows are no-returns; organized or
       not) are binned into a range image: taken to the lidar frame (half turn about z),
       beam = the nearest beam altitude to the point's elevation, column = the nearest
       encoder angle to its azimuth (column ``j`` looks at ``pi - 2 pi j / W`` in the sensor
       frame); points more than half a beam spacing outside the vertical field, or beyond
       the profile's range, are dropped; of several points in one pixel the nearest is kept.
       RANGE = the point's distance [mm, rounded]; REFLECTIVITY = intensity x 100 (rounded,
       0..255; the simulator's intensity is the calibrated reflectivity, 0..1); SIGNAL =
       REFLECTIVITY x 100 x (10 m / range)^2 clipped to 16 bits (an illustrative photon count:
       the return falls with the square of the range); NEAR_IR 0. A simulated point on its
       own ray lands in its own pixel, so a recording of step 1 holds the simulated ranges to
       within 0.5 mm.
    4. Column ``j`` of a sweep is stamped ``stamp + j / (rate_hz * W)`` (ns; status valid,
       measurement id ``j``), frame id the sweep's index (mod 2^16). With
       ``TIME_FROM_PTP_1588`` column timestamps are Unix time; with
       ``TIME_FROM_INTERNAL_OSC`` they count from a power-on one hour before the first sweep,
       as a sensor on its own clock does, and only the capture times are Unix time.
    5. ouster-sdk turns each scan into lidar packets (``frame_to_packets``, 16 columns a
       packet; a CRC footer with RNG19_RFL8_SIG16_NIR16, none with LEGACY) and writes them (``pcap.record``) as UDP datagrams 127.0.0.1 ->
       127.0.0.1 on ``lidar_port``, each captured at the Unix time of its last column.

    Unlike a field capture: no IMU packets, no capture jitter or loss, no IP fragmentation
    (one pcap record per datagram), a single return, idealised beams, and NEAR_IR and SIGNAL
    that are not measured.

    Parameters
    ----------
    sweeps : iterable of LidarSweep
        In time order (stamps increasing), points in the sensor frame.
    out_pcap, out_metadata : Path
        Files to write (replaced).
    channels, columns_per_frame, rate_hz
        Beams and the lidar mode (``1024x20``, ``1024x10``, ``2048x10``, ...).
    vertical_min_deg, vertical_max_deg
        Altitudes of the lowest and highest beams [deg].
    udp_profile, timestamp_mode, lidar_port, azimuth_window_deg
        As above (:func:`synthetic_sensor_info`).

    Returns
    -------
    OusterRecording
        Counts of scans, packets and points written.

    Raises
    ------
    ValueError
        Not an Ouster mode, no sweeps, stamps not increasing, or points not (N, 4).
    """
    info = synthetic_sensor_info(
        channels=channels,
        columns_per_frame=columns_per_frame,
        vertical_min_deg=vertical_min_deg,
        vertical_max_deg=vertical_max_deg,
        rate_hz=rate_hz,
        udp_profile=udp_profile,
        timestamp_mode=timestamp_mode,
        lidar_port=lidar_port,
        azimuth_window_deg=azimuth_window_deg,
    )
    packet_format = PacketFormat(info)
    counts = {"scans": 0, "points_in": 0, "points_written": 0, "packets": 0}

    def packets() -> Iterator[Packet]:
        boot_ns: int | None = None
        previous_stamp = -math.inf
        for sweep in sweeps:
            if not sweep.stamp > previous_stamp:
                raise ValueError(f"{sweep.where}: sweep stamps must increase")
            previous_stamp = sweep.stamp
            if boot_ns is None:
                boot_ns = round(sweep.stamp * 1e9) - 3600 * 10**9
            frame, offered, written = _sweep_to_frame(sweep, info, packet_format, counts["scans"])
            unix_ns = np.asarray(frame.timestamp, dtype=np.int64).copy()
            if timestamp_mode == "TIME_FROM_INTERNAL_OSC":
                frame.timestamp[:] = (unix_ns - boot_ns).astype(np.uint64)
            scan_packets = frame_to_packets(frame, packet_format, info.init_id, info.sn)
            per_packet = info.format.columns_per_packet
            window_first, window_last = info.format.column_window
            sent = 0
            for index, packet in enumerate(scan_packets):
                first_column = index * per_packet
                last_column = min(first_column + per_packet, columns_per_frame) - 1
                if last_column < window_first or first_column > window_last:
                    continue  # outside the azimuth window: the sensor does not send it
                packet.host_timestamp = int(unix_ns[last_column])
                sent += 1
                yield packet
            counts["scans"] += 1
            counts["packets"] += sent
            counts["points_in"] += offered
            counts["points_written"] += written

    out_pcap.parent.mkdir(parents=True, exist_ok=True)
    try:
        record(packets(), str(out_pcap), lidar_port=lidar_port, imu_port=lidar_port + 1)
    except BaseException:
        out_pcap.unlink(missing_ok=True)
        raise
    if counts["scans"] == 0:
        out_pcap.unlink(missing_ok=True)
        raise ValueError("no sweeps to write")
    text = json.dumps(json.loads(info.to_json_string()), indent=2) + "\n"
    temporary = out_metadata.with_name(out_metadata.name + ".tmp")
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, out_metadata)
    log.info(
        "wrote %s (%d scans, %d packets) and %s",
        out_pcap,
        counts["scans"],
        counts["packets"],
        out_metadata,
    )
    return OusterRecording(**counts)


def _sweep_to_frame(
    sweep: LidarSweep, info: SensorInfo, packet_format: PacketFormat, index: int
) -> tuple[LidarFrame, int, int]:
    """One sweep as a filled LidarFrame (Unix column timestamps); returns offered and written."""
    points = np.asarray(sweep.points)
    if points.ndim != 2 or points.shape[1] != 4:
        raise ValueError(f"{sweep.where}: points must be (N, 4), not {points.shape}")
    columns = info.format.columns_per_frame
    finite = np.isfinite(points[:, :3]).all(axis=1)
    range_mm, reflectivity, written = bin_range_image(
        points[finite],
        altitudes_deg=np.asarray(info.beam_altitude_angles, dtype=np.float64),
        columns=columns,
        lidar_to_sensor=np.asarray(info.lidar_to_sensor_transform, dtype=np.float64),
        max_range_mm=packet_format.field_value_mask(ChanField.RANGE),
    )
    frame = LidarFrame(info)
    frame.field(ChanField.RANGE)[:] = range_mm
    frame.field(ChanField.REFLECTIVITY)[:] = reflectivity
    with np.errstate(divide="ignore"):
        signal = reflectivity * 100.0 * (1e4 / np.maximum(range_mm, 1)) ** 2
    frame.field(ChanField.SIGNAL)[:] = np.where(range_mm > 0, np.clip(signal, 1, 65535), 0)
    frame.field(ChanField.NEAR_IR)[:] = 0
    period_ns = 10**9 / info.format.fps
    start_ns = round(sweep.stamp * 1e9)
    column = np.arange(columns, dtype=np.int64)
    frame.timestamp[:] = (
        start_ns + np.round(column * period_ns / columns).astype(np.int64)
    ).astype(np.uint64)
    frame.measurement_id[:] = column.astype(np.uint16)
    frame.status[:] = 1
    frame.frame_id = index % (packet_format.max_frame_id + 1)
    return frame, int(np.count_nonzero(finite)), written


def bin_range_image(
    points: npt.ArrayLike,
    *,
    altitudes_deg: F64,
    columns: int,
    lidar_to_sensor: F64,
    max_range_mm: int,
) -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.uint8], int]:
    """Bin returns into an Ouster range image (beam azimuth offsets and beam origin offset 0).

    Parameters
    ----------
    points : array_like, shape (N, 4)
        x, y, z [m] in the sensor frame (finite) and intensity (0..1 reflectivity; NaN: 0).
    altitudes_deg : ndarray, shape (rows,)
        Beam altitudes [deg], evenly spaced, highest first.
    columns : int
        Columns per frame W; column ``j`` has encoder angle ``2 pi j / W`` in the lidar frame
        (x towards the connector, clockwise seen from above).
    lidar_to_sensor : ndarray, shape (4, 4)
        Ouster's lidar-to-sensor transform (translation in mm).
    max_range_mm : int
        Largest range the profile can carry.

    Returns
    -------
    range_mm : ndarray of uint32, shape (rows, columns)
        Distance from the lidar origin [mm], 0 where no point fell.
    reflectivity : ndarray of uint8, shape (rows, columns)
        Intensity x 100, rounded and clipped to 0..255.
    written : int
        Pixels filled.
    """
    array = np.asarray(points, dtype=np.float64).reshape(-1, 4)
    rows = len(altitudes_deg)
    rotation, translation_mm = lidar_to_sensor[:3, :3], lidar_to_sensor[:3, 3]
    # p_sensor = R p_lidar + t  =>  p_lidar = R^T (p_sensor - t), in mm.
    lidar_mm = (array[:, :3] * 1000.0 - translation_mm) @ rotation
    distance_mm = np.linalg.norm(lidar_mm, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        elevation_deg = np.degrees(np.arcsin(np.clip(lidar_mm[:, 2] / distance_mm, -1.0, 1.0)))
    # XYZLut: x = r cos(alt) cos(theta), y = -r cos(alt) sin(theta), theta = 2 pi j / W.
    encoder_rad = np.mod(np.arctan2(-lidar_mm[:, 1], lidar_mm[:, 0]), 2.0 * np.pi)
    column = np.rint(encoder_rad * columns / (2.0 * np.pi)).astype(np.intp) % columns
    spacing_deg = (altitudes_deg[0] - altitudes_deg[-1]) / max(rows - 1, 1)
    row_real = (altitudes_deg[0] - elevation_deg) / spacing_deg
    range_mm = np.rint(distance_mm)
    keep = (
        np.isfinite(row_real)
        & (row_real > -0.5)
        & (row_real < rows - 0.5)
        & (range_mm >= 1)
        & (range_mm <= max_range_mm)
    )
    row = np.rint(row_real[keep]).astype(np.intp)
    pixel = row * columns + column[keep]
    kept_range = range_mm[keep]
    intensity = np.nan_to_num(array[keep, 3], nan=0.0)
    # The nearest point of each pixel: sort by pixel, then range; the first of each run wins.
    order = np.lexsort((kept_range, pixel))
    first = np.ones(len(order), dtype=bool)
    first[1:] = pixel[order][1:] != pixel[order][:-1]
    winner = order[first]
    range_image = np.zeros(rows * columns, dtype=np.uint32)
    reflectivity = np.zeros(rows * columns, dtype=np.uint8)
    range_image[pixel[winner]] = kept_range[winner].astype(np.uint32)
    reflectivity[pixel[winner]] = np.clip(np.rint(intensity[winner] * 100.0), 0, 255).astype(
        np.uint8
    )
    return (
        range_image.reshape(rows, columns),
        reflectivity.reshape(rows, columns),
        len(winner),
    )
