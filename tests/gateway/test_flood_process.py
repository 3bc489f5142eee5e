"""Alerts first, on real processes: during a flood of 20,000 track batches a second on the
tracks key (a runaway or hostile tracker), an alert is stored and delivered to a webhook within
1 s, the gateway keeps publishing its status, and webhook dispatch never meets a locked
database. The processes and the measuring are the ``alert_flood`` benchmark's
(``benchmarks/alert_flood.py``), here with a 3 s flood and four alerts (the benchmark: 10 s and
sixteen) to keep the suite short; the bound checked is the same."""

from __future__ import annotations

from pathlib import Path

from benchmarks.alert_flood import BOUND_S, RATE_HZ, flood_run


def test_an_alert_during_a_track_flood_is_stored_and_webhooked_within_1_s(
    tmp_path: Path,
) -> None:
    result = flood_run(3.0, 4, tmp_path / "data", tmp_path / "gateway.log")
    # The flood was one: most of the target rate reached, far more than the writer stores.
    assert result["flood"]["rate_hz"] >= 0.5 * RATE_HZ, result["flood"]
    assert result["batches_dropped"] > 0 and result["batches_stored"] > 0
    assert len(result["stored_s"]) == 4 and len(result["webhooked_s"]) == 4, result
    assert max(result["stored_s"]) <= BOUND_S, result["stored_s"]
    assert max(result["webhooked_s"]) <= BOUND_S, result["webhooked_s"]
    assert result["status_max_gap_s"] is not None and result["status_max_gap_s"] <= 2.5
    assert result["locked_count"] == 0, result["locked_lines"]
