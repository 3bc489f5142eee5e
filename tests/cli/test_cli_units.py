"""The `wz` parts that need no bus: backoff, stack list, tap lines, MCAP writing and reading."""

from __future__ import annotations

import dataclasses
import io
import json
import signal
from pathlib import Path

import pytest
from mcap.reader import make_reader

from tests.cli.bus_tools import JUNK_KEY, mix, tap_mix
from tests.shared.samples import json_samples
from wz_cli.common import CliError, tcp_address
from wz_cli.main import build_parser
from wz_cli.record import distinct_key_exprs
from wz_cli.recording import (
    FRAME_ENCODING,
    JSON_ENCODING,
    RAW_ENCODING,
    RecordingError,
    RecordingReader,
    RecordingWriter,
    classify,
)
from wz_cli.stack import STACK, StackOptions, select
from wz_cli.supervisor import Backoff, describe_exit
from wz_cli.tap import describe
from wz_shared import codec
from wz_shared.messages import JSON_MESSAGES, Alert, GroundTruth

ROOT = Path(__file__).resolve().parents[2]

# --- supervisor -----------------------------------------------------------------------------


def test_backoff_doubles_to_the_cap_and_resets_after_a_good_run() -> None:
    backoff = Backoff()
    delays = [backoff.delay_after_exit(uptime_s=1.0) for _ in range(9)]
    assert delays == [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0, 30.0]
    assert backoff.delay_after_exit(uptime_s=30.0) == 0.5  # stayed up 30 s: healthy again
    assert backoff.delay_after_exit(uptime_s=29.9) == 1.0


def test_exit_descriptions_name_the_signal() -> None:
    assert describe_exit(0) == "exited with code 0"
    assert describe_exit(3) == "exited with code 3"
    assert describe_exit(-signal.SIGKILL) == "killed by SIGKILL (signal 9)"


def test_tcp_endpoints_are_parsed_for_the_readiness_check() -> None:
    assert tcp_address("tcp/127.0.0.1:7447") == ("127.0.0.1", 7447)
    assert tcp_address("tcp/[::1]:7447#iface=lo") == ("::1", 7447)
    assert tcp_address("tcp/localhost:80") == ("localhost", 80)
    assert tcp_address("udp/127.0.0.1:7447") is None
    assert tcp_address("tcp/127.0.0.1:99999") is None
    assert tcp_address("tcp/127.0.0.1") is None


def test_stack_selection_and_child_environment(tmp_path: Path) -> None:
    assert [spec.name for spec in select(None)] == [
        spec.name for spec in STACK if spec.name not in ("drivers", "device-driver")
    ]
    assert [spec.name for spec in select(["drivers", "gateway"])] == ["drivers", "gateway"]
    assert [spec.name for spec in select(["simulator"])] == ["simulator"]
    with pytest.raises(ValueError, match="no service named nope"):
        select(["nope"])
    simulator = select(["simulator"])[0]
    site_file = tmp_path / "site.yaml"
    options = StackOptions("tcp/127.0.0.1:7999", site_file, realtime_factor=2.5, seed=7)
    env = simulator.child_env({"PATH": "/bin", "WZ_BUS_MODE": "router"}, options)
    assert env["PATH"] == "/bin"
    assert env["WZ_BUS_MODE"] == "peer"
    assert env["WZ_BUS_CONNECT_ENDPOINTS"] == "tcp/127.0.0.1:7999"
    assert env["WZ_SITE_FILE"] == env["WZ_SIM_SITE_FILE"] == str(site_file.resolve())
    assert env["WZ_LOG_FORMAT"] == "json"
    assert (env["WZ_SIM_REALTIME_FACTOR"], env["WZ_SIM_SEED"]) == ("2.5", "7")
    names = [spec.name for spec in STACK]
    assert len(set(names)) == len(names)
    # Defaults unless set: the simulator's warm-up.
    assert env["WZ_SIM_WARMUP_S"] == "60"
    assert simulator.child_env({"WZ_SIM_WARMUP_S": "0"}, options)["WZ_SIM_WARMUP_S"] == "0"
    # State kept across restarts: under the run's state folder, unless set.
    lidar = select(["lidar-detector"])[0]
    assert "WZ_LIDAR_BACKGROUND_FILE" not in lidar.child_env({}, options)
    with_state = dataclasses.replace(options, state_dir=tmp_path / "state")
    assert lidar.child_env({}, with_state)["WZ_LIDAR_BACKGROUND_FILE"] == str(
        (tmp_path / "state").resolve() / "lidar-detector" / "background.npz"
    )
    mine = {"WZ_LIDAR_BACKGROUND_FILE": "/var/lib/bg.npz"}
    assert lidar.child_env(mine, with_state)["WZ_LIDAR_BACKGROUND_FILE"] == "/var/lib/bg.npz"
    assert all(spec.standby for spec in STACK if not spec.optional)


def test_overlapping_key_expressions_are_recorded_once() -> None:
    assert distinct_key_exprs(["wz/a/**", "wz/**", "wz/b/x"]) == ["wz/**"]
    assert distinct_key_exprs(["wz/a/**", "wz/b/**", "wz/a/**"]) == ["wz/a/**", "wz/b/**"]
    with pytest.raises(CliError, match="overlap"):
        distinct_key_exprs(["wz/a/*", "wz/*/b"])
    with pytest.raises(CliError, match="not a valid key expression"):
        distinct_key_exprs(["wz//x"])


def test_parser_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    for argv in (
        ["tap", "wz//bad"],
        ["tap", "wz/**", "--count", "0"],
        ["replay", "x.mcap", "--fast", "--rate", "2"],
        ["replay", "x.mcap", "--rate", "0"],
    ):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        assert exc.value.code == 2
    capsys.readouterr()


# --- tap lines ------------------------------------------------------------------------------


def test_tap_lines_for_every_case() -> None:
    lines = [describe(key, payload, width=120) for key, _cls, payload in tap_mix()]
    assert lines[0] == (
        "wz/test-site/truth/vehicles  ground_truth  "
        "stamp=10.150 step=3 vehicles=1 first=veh3 30.0 m/s"
    )
    assert lines[1] == (
        "wz/test-site/raw/lidar/lidar-mast  lidar_frame  "
        "#4 stamp=0.200 source=lidar-mast points=32 (1x32)"
    )
    assert lines[2] == (
        "wz/test-site/raw/camera/camera-mast  camera_frame  "
        "#5 stamp=0.500 source=camera-mast 1200x1200 jpeg=4 B"
    )
    assert lines[3].startswith('wz/test-site/alerts/speeding  alert  {"schema_version":1,')
    assert len(lines[3]) == 120 and lines[3].endswith("…")
    assert lines[4].startswith("wz/test-site/alerts/speeding  alert  <invalid: schema_version:")
    assert lines[5].startswith(f"{JUNK_KEY}  ?  <invalid: bad_json:")
    assert lines[6].startswith(
        "wz/test-site/raw/lidar/lidar-mast  lidar_frame  <invalid: truncated:"
    )


def test_tap_json_mode_prints_whole_messages() -> None:
    alert = next(m for m in json_samples() if isinstance(m, Alert))
    line = describe("k", codec.encode(alert), full_json=True, width=20)
    key, kind, text = line.split("  ", 2)
    assert (key, kind) == ("k", "alert")
    assert Alert.model_validate_json(text) == alert
    frame_line = describe("k", tap_mix()[1][2], full_json=True, width=20)
    assert frame_line.endswith("+512 B payload") and '"frame_index":4' in frame_line


# --- recordings -----------------------------------------------------------------------------


def _record(samples: list[tuple[str, bytes]], flush_every: int = 0) -> bytes:
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, metadata={"key_exprs": '["wz/**"]'}, chunk_size_bytes=2048)
    for i, (key, payload) in enumerate(samples):
        writer.add(key, payload, log_time_ns=1_000_000_000 + i * 1000)
        if flush_every and i % flush_every == flush_every - 1:
            writer.flush()
    writer.finish()
    return buffer.getvalue()


def _samples() -> list[tuple[str, bytes]]:
    return [(key, payload) for key, _cls, payload in mix(3)]


def test_recording_is_a_standard_mcap_with_schemas_per_kind() -> None:
    samples = _samples()
    data = _record(samples)
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(samples)
    channels = {(c.topic, c.message_encoding) for c in summary.channels.values()}
    assert ("wz/test-site/truth/vehicles", JSON_ENCODING) in channels
    assert ("wz/test-site/raw/lidar/lidar-mast", FRAME_ENCODING) in channels
    assert (JUNK_KEY, RAW_ENCODING) in channels
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(JSON_MESSAGES) | {"lidar_frame", "camera_frame"} == set(schemas)
    truth_schema = json.loads(schemas["ground_truth"].data)
    assert schemas["ground_truth"].encoding == "jsonschema"
    assert truth_schema == GroundTruth.model_json_schema()
    lidar_schema = json.loads(schemas["lidar_frame"].data)
    assert "WZF1" in lidar_schema["description"]
    assert lidar_schema["metadata_schema"]["title"] == "LidarFrameMeta"
    # Every message comes back in order, with its stamp as publish time.
    decoded = [(channel.topic, message.data) for _, channel, message in reader.iter_messages()]
    assert decoded == samples
    truth = next(
        m
        for _, c, m in make_reader(io.BytesIO(data)).iter_messages()
        if c.topic.endswith("vehicles")
    )
    assert truth.publish_time == 10_000_000_000


def test_classification_counts_invalid_payloads_on_their_kind() -> None:
    alert = codec.encode(next(m for m in json_samples() if isinstance(m, Alert)))
    assert classify(alert).encoding == JSON_ENCODING and classify(alert).invalid_reason is None
    broken = alert.replace(b'"station_m":500.0', b'"station_m":"far"')
    assert classify(broken).kind == "alert" and classify(broken).invalid_reason == "invalid"
    assert classify(b"\x00junk").encoding == RAW_ENCODING


def test_reader_reads_a_complete_recording() -> None:
    samples = _samples()
    reader = RecordingReader(io.BytesIO(_record(samples)))
    messages = list(reader.messages())
    assert [(m.topic, m.payload) for m in messages] == samples
    assert reader.report.complete and reader.report.problem is None
    assert reader.report.metadata == {"key_exprs": '["wz/**"]'}
    assert [m.log_time_ns for m in messages] == sorted(m.log_time_ns for m in messages)


@pytest.mark.parametrize("flush_every", [0, 5])
def test_every_prefix_of_a_recording_replays_a_prefix_of_its_messages(flush_every: int) -> None:
    """Cut anywhere (a crash, a partial copy): never garbage, never a hole, always a report."""
    samples = _samples()
    data = _record(samples, flush_every)
    read_before = 0
    # Every 7th byte: cuts fall inside every kind of record, at many offsets within each
    # (cutting at every byte takes 10 times as long).
    for cut in [*range(8, len(data), 7), len(data) - 1]:
        reader = RecordingReader(io.BytesIO(data[:cut]))
        got = [(m.topic, m.payload) for m in reader.messages()]
        assert got == samples[: len(got)], f"cut at {cut}"
        assert len(got) >= read_before  # more file, never fewer messages
        read_before = len(got)
        assert not reader.report.complete and reader.report.problem, f"cut at {cut}"
    assert read_before == len(samples)  # all messages are in before the summary begins


def test_truncation_is_reported_with_its_place() -> None:
    data = _record(_samples())
    reader = RecordingReader(io.BytesIO(data[: len(data) // 2]))
    list(reader.messages())
    assert reader.report.problem is not None and "truncated at byte" in reader.report.problem


def test_reader_refuses_what_is_not_mcap() -> None:
    with pytest.raises(RecordingError, match="not an MCAP file"):
        list(RecordingReader(io.BytesIO(b"this is a text file")).messages())
    with pytest.raises(RecordingError, match="empty"):
        list(RecordingReader(io.BytesIO(b"")).messages())


def test_router_config_file_is_loopback_router_without_multicast() -> None:
    from wz_cli.router import LOCAL_ROUTER_CONFIG, router_config

    assert LOCAL_ROUTER_CONFIG == ROOT / "deploy" / "zenoh" / "router-local.json5"
    config = router_config(["tcp/127.0.0.1:7999"], LOCAL_ROUTER_CONFIG)
    assert json.loads(config.get_json("mode")) == "router"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7999"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    default = router_config(None, None)
    assert json.loads(default.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]


def test_status_shows_what_a_service_shed_by_reason_with_its_drops() -> None:
    """`wz status`: the DROPPED column counts a ring's overwritten samples and the samples shed
    undecoded, naming the shedding's reasons; a service that shed nothing shows its drops."""
    from wz_cli.status import ServiceView, render_table
    from wz_shared.messages import ServiceState, ServiceStatus

    status = ServiceStatus(
        site="s",
        source_id="alert-service",
        stamp=1.0,
        service="alert-service",
        state=ServiceState.RUNNING,
        uptime_s=10.0,
        pid=7,
        received_hz={"wz/s/tracks": 20000.0, "wz/s/raw/camera/c": 10.0},
        invalid_counts={"wz/s/tracks|out_of_order": 3},
        dropped_counts={"wz/s/raw/camera/c": 2},
        shed_counts={"wz/s/tracks|stale": 1000, "wz/s/tracks|superseded": 5},
    )
    view = ServiceView("alert-service", True, status, 0.1, expected=True)
    lines = render_table("s", [view])
    tracks = next(line for line in lines if "wz/s/tracks" in line)
    camera = next(line for line in lines if "wz/s/raw/camera/c" in line)
    assert "1005 (stale, superseded)" in tracks and "3 (out_of_order)" in tracks
    assert camera.rstrip().endswith("2")
