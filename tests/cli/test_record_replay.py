"""`wz record` and `wz replay` as processes over a real router: exact counts, pace, truncation."""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
from pathlib import Path

from mcap.reader import make_reader

from tests.cli.bus_tools import Sample, expected_counts, mix
from tests.cli.procs import (
    communicate_while_publishing,
    run_wz,
    running,
    start_helper,
    start_wz,
    wait_for,
)
from wz_cli.recording import RecordingWriter

COUNT = 20  # of every message type and frame kind


def _counter(router: str, total: int, silence_s: float = 5.0) -> subprocess.Popen[str]:
    counter = start_helper(router, "count", str(total), str(silence_s))
    assert counter.stdout is not None
    assert counter.stdout.readline() == "ready\n"
    return counter


def _counts(counter: subprocess.Popen[str]) -> tuple[dict[str, list[object]], float]:
    out, _ = counter.communicate(timeout=60)
    assert counter.returncode == 0
    report = json.loads(out)
    spread_s = float(report.pop("_spread_s"))
    return report, spread_s


def _replayed(stdout: str) -> int:
    match = re.search(r"replayed (\d+) message\(s\)", stdout)
    assert match, stdout
    return int(match[1])


def _record_mix(router: str, out: Path) -> list[Sample]:
    samples = mix(COUNT)
    recording = ("record", str(out), "--max-messages", str(len(samples)), "--connect", router)
    # The publisher starts once its publishers match the recorder's subscription.
    with running(start_wz(*recording)) as recorder:
        stdout, stderr = communicate_while_publishing(recorder, router, "mix", str(COUNT))
    assert recorder.returncode == 0, stderr
    keys = len({key for key, _cls, _payload in samples})
    assert f"recorded {len(samples)} message(s) on {keys} key(s)" in stdout
    return samples


def test_record_then_replay_reproduces_every_message(router: str, tmp_path: Path) -> None:
    out = tmp_path / "bus.mcap"
    samples = _record_mix(router, out)
    expected = expected_counts(samples)

    # A finished, indexed MCAP file: what Foxglove opens.
    with out.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(samples)
    assert {c.topic for c in summary.channels.values()} == set(expected)

    for pace in (["--fast"], ["--rate", "1"]):
        with running(_counter(router, len(samples))) as counter:
            replay = run_wz("replay", str(out), *pace, "--connect", router)
            assert replay.returncode == 0, replay.stderr
            counts, _ = _counts(counter)
        assert counts == expected, pace  # same count and same bytes in the same order, per key
        assert _replayed(replay.stdout) == len(samples)
        assert re.search(r"\nwz/test-site/truth/vehicles +20\n", replay.stdout), replay.stdout


def test_replay_keeps_the_recorded_pace(router: str, tmp_path: Path) -> None:
    out = tmp_path / "paced.mcap"
    samples = mix(1)[:11]
    with out.open("wb") as stream:
        writer = RecordingWriter(stream, metadata={})
        for i, (key, _cls, payload) in enumerate(samples):
            writer.add(key, payload, log_time_ns=i * 200_000_000)  # 0.2 s apart: 2 s in all
        writer.finish()
    spreads = {}
    for pace in ("--fast", "2"):
        args = ["--fast"] if pace == "--fast" else ["--rate", pace]
        with running(_counter(router, len(samples))) as counter:
            assert run_wz("replay", str(out), *args, "--connect", router).returncode == 0
            counts, spreads[pace] = _counts(counter)
        assert sum(n for n, _ in counts.values()) == len(samples)  # type: ignore[misc]
    # 2 s recorded, at twice the pace: 1 s, less the first delivery's head start at most.
    assert spreads["2"] >= 0.8
    assert spreads["--fast"] < 0.5


def _prefix_digests(samples: list[Sample], counts: dict[str, list[object]]) -> None:
    """Each key got the first n of its recorded payloads, in order."""
    for key, (n, digest) in counts.items():
        payloads = [payload for k, _cls, payload in samples if k == key]
        assert isinstance(n, int) and 0 < n <= len(payloads)
        assert hashlib.sha256(b"".join(payloads[:n])).hexdigest() == digest, key


def test_truncated_recording_replays_its_readable_part(router: str, tmp_path: Path) -> None:
    full = tmp_path / "full.mcap"
    samples = _record_mix(router, full)
    cut = tmp_path / "cut.mcap"
    data = full.read_bytes()
    cut.write_bytes(data[: len(data) * 6 // 10])
    with running(_counter(router, len(samples), silence_s=3.0)) as counter:
        replay = run_wz("replay", str(cut), "--fast", "--connect", router)
        counts, _ = _counts(counter)
    assert replay.returncode == 3, replay.stderr
    assert "INCOMPLETE recording: the file is truncated at byte" in replay.stdout
    replayed = _replayed(replay.stdout)
    assert 0 < replayed < len(samples)
    assert sum(n for n, _ in counts.values()) == replayed  # type: ignore[misc]
    _prefix_digests(samples, counts)


def test_recorder_killed_mid_way_leaves_a_replayable_file(router: str, tmp_path: Path) -> None:
    out = tmp_path / "crash.mcap"
    with (
        running(start_helper(router, "stream", "200")) as streamer,
        running(start_wz("record", str(out), "wz/test-site/**", "--connect", router)) as recorder,
    ):
        # Chunks reach the disk every second: wait for some, then crash the recorder.
        wait_for(lambda: out.exists() and out.stat().st_size > 20_000, 30.0, "recorded data")
        os.kill(recorder.pid, signal.SIGKILL)
        assert recorder.wait(10) == -signal.SIGKILL
        streamer.send_signal(signal.SIGTERM)
        assert streamer.wait(10) == 0
    with running(_counter(router, 10**6, silence_s=3.0)) as counter:
        replay = run_wz("replay", str(out), "--fast", "--connect", router)
        counts, _ = _counts(counter)
    assert replay.returncode == 3, replay.stderr
    assert "INCOMPLETE recording" in replay.stdout
    replayed = _replayed(replay.stdout)
    assert replayed > 20
    assert counts["wz/test-site/truth/vehicles"][0] == replayed


def test_record_stops_on_sigint_and_after_its_duration(router: str, tmp_path: Path) -> None:
    interrupted = tmp_path / "interrupted.mcap"
    with running(start_wz("record", str(interrupted), "--connect", router)) as recorder:
        stderr = recorder.stderr
        assert stderr is not None
        wait_for(lambda: "recording wz/**" in stderr.readline(), 30.0, "the recorder")
        recorder.send_signal(signal.SIGINT)
        stdout, _ = recorder.communicate(timeout=30)
    assert recorder.returncode == 0
    assert "recorded 0 message(s)" in stdout
    timed = tmp_path / "timed.mcap"
    result = run_wz("record", str(timed), "--duration", "0.5", "--connect", router)
    assert result.returncode == 0, result.stderr
    for path in (interrupted, timed):
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()  # finished: summary and footer
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 0
    again = run_wz("record", str(timed), "--duration", "0.5", "--connect", router)
    assert again.returncode == 2 and "exists" in again.stderr  # never overwritten by accident
