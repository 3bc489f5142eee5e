"""The stamp gate: what a flood or a replay loses before decoding, and what it must not."""

from __future__ import annotations

import pytest

from wz_shared.codec import encode_json
from wz_shared.messages import TrackBatch
from wz_shared.shedding import StampGate, peek_stamp
from wz_shared.timebase import RunWatch


def consume(gate: StampGate, stamp: float, accepted: bool = True) -> str | None:
    """The gate's verdict on a batch of ``stamp``; one let in is settled as the consumer
    would (``accepted``, or refused)."""
    reason = gate.check(payload(stamp))
    if reason is None:
        gate.settle(stamp, accepted)
    return reason


def payload(stamp: float, cycle: int = 0) -> bytes:
    return encode_json(
        TrackBatch(site="s", source_id="fusion-tracker", stamp=stamp, cycle_index=cycle, tracks=[])
    )


@pytest.mark.parametrize("stamp", [0.0, 0.1, 12.345678, 1.75e9, 3e-05])
def test_the_stamp_is_read_off_the_bytes(stamp: float) -> None:
    assert peek_stamp(payload(stamp)) == stamp


@pytest.mark.parametrize(
    "raw", [b"", b"not json", b'{"stamp": "x"}', b'{"stamp": NaN}', b'{"stamp":1e999}']
)
def test_an_unreadable_stamp_is_none_and_admitted(raw: bytes) -> None:
    assert peek_stamp(raw) is None
    assert StampGate(0.005).check(raw) is None


def test_a_tracker_at_20_hz_loses_nothing() -> None:
    gate = StampGate(0.005)
    assert all(consume(gate, k / 20.0) is None for k in range(400))


def test_duplicates_are_stale_and_a_fast_stream_is_thinned_to_the_interval() -> None:
    gate = StampGate(0.005)
    assert gate.check(payload(10.0)) is None
    assert gate.check(payload(10.0)) == "stale"  # again, before the consumer took the first
    gate.settle(10.0, accepted=True)
    assert consume(gate, 10.0) == "stale"
    assert consume(gate, 9.99) == "stale"
    # 20,000 batches a second of advancing stamps: one per 5 ms of stamp time gets by.
    verdicts = [consume(gate, 10.0 + k * 5e-5) for k in range(1, 20_001)]
    admitted = verdicts.count(None)
    assert 195 <= admitted <= 201
    assert set(verdicts) == {None, "superseded"}


def test_a_replayed_old_batch_among_the_real_stream_gets_by_at_most_once_per_real_batch() -> None:
    """The flood of one old batch (stamp 1 s) between a real tracker's batches at 10 Hz from
    100 s: every real batch is admitted; of the 2000 replays between two real batches, one."""
    gate = StampGate(0.005)
    real_admitted = replays_admitted = 0
    for k in range(30):
        real_admitted += consume(gate, 100.0 + k / 10.0) is None
        # Refused by the consumer (out of order) when let in.
        replays_admitted += sum(consume(gate, 1.0, accepted=False) is None for _ in range(2000))
    assert real_admitted == 30
    assert replays_admitted <= 30


def test_a_new_run_gets_through_and_is_confirmed_downstream() -> None:
    """The simulation restarts: its stamps from 0 again, counting up. The gate admits them,
    so the consumer's own RunWatch (fed what the gate admits) confirms the new run, and the
    gate then thins the new run as the old."""
    gate = StampGate(0.005)
    downstream = RunWatch()
    for k in range(50):
        assert consume(gate, 500.0 + k / 10.0) is None
        downstream.observe(500.0 + k / 10.0)
    verdicts = []
    for k in range(5):
        stamp = k / 10.0
        verdict = downstream.observe(stamp)
        verdicts.append(verdict)
        assert consume(gate, stamp, accepted=verdict != "behind") is None
    assert verdicts[:3] == ["behind", "behind", "new_run"] and verdicts[3:] == ["run", "run"]
    assert consume(gate, 0.4) == "stale"
    assert consume(gate, 0.401) == "superseded"


def test_a_batch_refused_after_all_is_not_the_newest() -> None:
    """A batch of another site (or undecodable) with the next stamp: refused by the consumer,
    so the real batch of that stamp right after it gets in."""
    gate = StampGate(0.005)
    assert consume(gate, 2.9) is None
    assert consume(gate, 3.0, accepted=False) is None
    assert consume(gate, 3.0) is None
    garbled = payload(3.1)[:-5]
    assert gate.check(garbled) is None
    gate.refused(garbled)
    assert consume(gate, 3.1) is None


def test_a_negative_interval_is_refused() -> None:
    with pytest.raises(ValueError, match="min_interval_s"):
        StampGate(-1.0)
