"""Radar object lists: CSV and JSON Lines files in tmp_path, and a real UDP socket on loopback."""

from __future__ import annotations

import json
import math
import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from wz_drivers.radar import listen_udp, read_objects
from wz_drivers.records import FieldDataError, ObjectList, Problems
from wz_shared.messages import VehicleClass

T0 = 1_700_000_000.0


def test_csv_range_azimuth_grouped_by_time(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    ranges = rng.uniform(5.0, 150.0, size=5)
    azimuths = rng.uniform(-40.0, 40.0, size=5)
    rows = [
        (T0, 1, ranges[0], azimuths[0], 27.5, "Car", 4.6, 1.9),
        (T0, 2, ranges[1], azimuths[1], 22.0, "semi-truck", 16.0, 2.5),
        (T0 + 0.05, 1, ranges[2], azimuths[2], "", "", "", ""),
        (T0 + 0.1, 7, ranges[3], azimuths[3], 30.1, "pedestrian", "", ""),
        (T0 + 0.1, 8, ranges[4], azimuths[4], 12.0, "Motorbike", 2.1, 0.8),
    ]
    path = tmp_path / "unit.csv"
    path.write_text(
        "Time,Object_ID,range_m,azimuth_deg,speed_mps,class,length_m,width_m,rcs_dbsm\n"
        + "".join(",".join(str(v) for v in row) + ",3.5\n" for row in rows)
    )
    problems = Problems()
    reports = list(read_objects(path, problems))
    assert not problems.errors
    assert [r.stamp for r in reports] == [T0, T0 + 0.05, T0 + 0.1]
    assert [len(r.objects) for r in reports] == [2, 1, 2]
    assert [r.where for r in reports] == [f"{path}:2", f"{path}:4", f"{path}:5"]
    objects = [o for r in reports for o in r.objects]
    for obj, range_m, azimuth_deg in zip(objects, ranges, azimuths, strict=True):
        # Azimuth counter-clockwise from the boresight: positive azimuth is to the left (+y).
        assert obj.x_m == pytest.approx(range_m * math.cos(math.radians(azimuth_deg)))
        assert obj.y_m == pytest.approx(range_m * math.sin(math.radians(azimuth_deg)))
        assert math.hypot(obj.x_m, obj.y_m) == pytest.approx(range_m)
    assert [o.object_id for o in objects] == [1, 2, 1, 7, 8]
    assert [o.object_class for o in objects] == [
        VehicleClass.CAR,
        VehicleClass.TRUCK,
        VehicleClass.UNKNOWN,
        VehicleClass.UNKNOWN,
        VehicleClass.MOTORCYCLE,
    ]
    assert (objects[0].speed_mps, objects[0].length_m, objects[0].width_m) == (27.5, 4.6, 1.9)
    assert (objects[2].speed_mps, objects[2].length_m) == (None, None)


def test_csv_position_straight_ahead_and_to_the_left(tmp_path: Path) -> None:
    path = tmp_path / "polar.csv"
    path.write_text(f"time_unix_s,range_m,azimuth_deg\n{T0},50,0\n{T0 + 1},20,90\n")
    ahead, left = (r.objects[0] for r in read_objects(path, Problems()))
    assert (ahead.x_m, ahead.y_m) == pytest.approx((50.0, 0.0))
    assert (left.x_m, left.y_m) == pytest.approx((0.0, 20.0), abs=1e-12)


def test_csv_bad_rows_are_reported_and_skipped(tmp_path: Path) -> None:
    path = tmp_path / "unit.csv"
    path.write_text(
        "time,id,x_m,y_m,class\n"
        f"{T0},1,40.0,-1.5,bus\n"  # line 2
        f"{T0},2,abc,2.0,car\n"  # 3: not a number
        f"{T0 + 0.1},3,nan,2.0,car\n"  # 4: NaN
        f"{T0 + 0.1},4,35.0,1.0\n"  # 5: a cell short
        f"{T0 + 0.1},5,35.0,1.0,truck\n"  # 6
        f"{T0 + 0.05},6,30.0,1.0,car\n"  # 7: goes back
        f"{T0 + 0.2},,,,\n"  # 8: a report with no objects
        f",7,30.0,1.0,car\n"  # 9: no time
        f"{T0 + 0.3},-2,30.0,1.0,car\n"  # 10: negative id
    )
    problems = Problems()
    reports = list(read_objects(path, problems))
    assert [(r.stamp, len(r.objects)) for r in reports] == [(T0, 1), (T0 + 0.1, 1), (T0 + 0.2, 0)]
    assert reports[0].objects[0].object_class == VehicleClass.BUS
    assert [str(e) for e in problems.errors] == [
        f"{path}:3: x_m 'abc' is not a number: row skipped",
        f"{path}:4: x_m is nan: row skipped",
        f"{path}:5: 4 cells, the header has 5: row skipped",
        f"{path}:7: time 1700000000.050000 goes back from 1700000000.100000 (line 6): skipped",
        f"{path}:9: no time: row skipped",
        f"{path}:10: id '-2' is not an integer >= 0: row skipped",
    ]


def test_csv_negative_range_is_skipped(tmp_path: Path) -> None:
    path = tmp_path / "polar.csv"
    path.write_text(f"time,range_m,azimuth_deg\n{T0},-3,10\n{T0 + 1},30,10\n")
    problems = Problems()
    assert len(list(read_objects(path, problems))) == 1
    assert [e.line for e in problems.errors] == [2]
    assert "range_m -3.0 is negative" in problems.errors[0].reason


def test_csv_missing_columns_raise_naming_what_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "unit.csv"
    path.write_text(f"timestamp,x_m,range_m\n{T0},1,2\n")
    with pytest.raises(FieldDataError) as caught:
        list(read_objects(path, Problems()))
    assert str(caught.value) == (
        f"{path}:1: missing columns: time (time_unix_s or time); position (x_m and y_m, or "
        "range_m and azimuth_deg); header: timestamp,x_m,range_m"
    )
    with pytest.raises(FieldDataError, match="no such file"):
        list(read_objects(tmp_path / "absent.csv", Problems()))
    (tmp_path / "empty.csv").write_text("\n")
    with pytest.raises(FieldDataError, match="empty file"):
        list(read_objects(tmp_path / "empty.csv", Problems()))


def test_json_lines_reports(tmp_path: Path) -> None:
    lines = [
        {
            "time": T0,
            "objects": [
                {
                    "id": 4,
                    "x_m": 60.0,
                    "y_m": 3.5,
                    "speed_mps": 25.0,
                    "class": "truck",
                    "length_m": 12.0,
                    "width_m": 2.5,
                },
                {"object_id": 5, "range_m": 10.0, "azimuth_deg": -90.0},
            ],
        },
        {"time_unix_s": T0 + 0.05, "objects": []},
        {"time": T0 + 0.05, "objects": [{"x_m": 1.0, "y_m": 2.0, "class": "Bus"}]},  # merged
        {"time": T0 + 0.1, "objects": [{"x_m": "n/a", "y_m": 2.0}, {"x_m": 9.0, "y_m": 0.0}]},
        {"objects": [{"x_m": 1.0, "y_m": 1.0}]},  # no time
        {"time": T0, "objects": []},  # goes back
    ]
    path = tmp_path / "unit.jsonl"
    path.write_text("\n".join(json.dumps(line) for line in lines) + "\n\nnot json\n")
    problems = Problems()
    reports = list(read_objects(path, problems))
    assert [(r.stamp, len(r.objects)) for r in reports] == [(T0, 2), (T0 + 0.05, 1), (T0 + 0.1, 1)]
    truck, side = reports[0].objects
    assert (truck.object_id, truck.object_class, truck.length_m) == (4, VehicleClass.TRUCK, 12.0)
    assert side.object_id == 5
    assert (side.x_m, side.y_m) == pytest.approx((0.0, -10.0), abs=1e-12)
    assert reports[1].objects[0].object_class == VehicleClass.BUS
    assert reports[1].where == f"{path}:2"
    assert [(e.line, e.reason) for e in problems.errors] == [
        (4, "object 0: x_m 'n/a' is not a number: object skipped"),
        (5, "no time (time_unix_s or time): report skipped"),
        (6, "time 1700000000.000000 goes back from 1700000000.100000 (line 4): skipped"),
        (8, "not JSON: Expecting value: line 1 column 1 (char 0): report skipped"),
    ]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_udp_datagrams_on_loopback() -> None:
    port = free_udp_port()
    stop = threading.Event()
    problems = Problems()
    reports = listen_udp("127.0.0.1", port, problems, stop=stop, poll_s=0.05)  # bound now
    datagrams = [
        json.dumps({"time": T0, "objects": [{"id": 1, "x_m": 20.0, "y_m": -2.0}]}).encode(),
        b"\xff not json",
        json.dumps({"objects": [{"range_m": 30.0, "azimuth_deg": 0.0, "class": "car"}]}).encode(),
        json.dumps({"time": T0 - 5.0, "objects": []}).encode(),  # goes back (before arrival)
        json.dumps({"time": 4e9, "objects": [{"x_m": 5.0, "y_m": 0.0}, {"y_m": 1.0}]}).encode(),
    ]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for datagram in datagrams:
            sender.sendto(datagram, ("127.0.0.1", port))
        source = f"udp 127.0.0.1:{sender.getsockname()[1]} -> 127.0.0.1:{port}"
        received: list[ObjectList] = []
        watchdog = threading.Timer(5.0, stop.set)  # a lost datagram must not hang the test
        watchdog.start()
        try:
            for report in reports:
                received.append(report)
                if len(received) == 3:
                    stop.set()
        finally:
            watchdog.cancel()
    assert [len(r.objects) for r in received] == [1, 1, 1]
    assert received[0].stamp == T0 and received[0].objects[0].object_id == 1
    assert T0 < received[1].stamp < 4e9  # stamped at arrival: no time in the report
    assert received[1].objects[0].object_class == VehicleClass.CAR
    assert received[1].objects[0].x_m == pytest.approx(30.0)
    assert received[2].stamp == 4e9 and received[2].where == f"{source} (datagram 5)"
    assert [str(e) for e in problems.errors] == [
        f"{source} (datagram 2): not JSON: 'utf-8' codec can't decode byte 0xff in position 0: "
        "invalid start byte: datagram skipped",
        f"{source} (datagram 4): time 1699999995.000000 goes back from "
        f"{received[1].stamp:.6f}: datagram skipped",
        f"{source} (datagram 5): object 1: no x_m: object skipped",
    ]


def test_udp_port_in_use_raises() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(FieldDataError, match=f"udp://127.0.0.1:{port}: cannot listen"):
            listen_udp("127.0.0.1", port, Problems(), stop=threading.Event())
