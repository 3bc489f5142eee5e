"""A speeding car inside a flood of track batches, on real processes: the alert service sheds
the flood before decoding it, so the car's alert is raised, stored by the gateway and
webhooked within 1 s of the rule's hold time. The processes and the measuring are the
``speeding_flood`` benchmark's (``benchmarks/speeding_flood.py``: 20,000 replayed batches of
20 tracks a second for 10 s, the real tracker's batches at 10 Hz); the benchmark also runs
the alert service without its gate, for comparison (webhooked 1.4 and 2.1 s past the hold in
two runs on this machine)."""

from __future__ import annotations

from pathlib import Path

from benchmarks.alert_flood import RATE_HZ
from benchmarks.speeding_flood import BOUND_S, speeding_run


def test_a_speeding_car_inside_a_flood_is_alerted_stored_and_webhooked_in_time(
    tmp_path: Path,
) -> None:
    result = speeding_run(10.0, True, tmp_path)
    # The flood was one: most of the target rate reached, and the gate shed it.
    assert result["flood"]["rate_hz"] >= 0.5 * RATE_HZ, result["flood"]
    assert result["alert_service_shed"].get("stale", 0) >= 0.5 * result["flood"]["sent"]
    for what in ("raised_s", "stored_s", "webhooked_s"):
        assert result[what] is not None, f"{what}: never ({result})"
        assert result[what] <= BOUND_S, f"{what} {result[what]:.2f} s past the hold ({result})"
