"""`kill -9` of each service of `wz up` in turn: the supervisor restarts it, the pipeline is back
within 5 s, and the gateway loses nothing it stored.

The real stack (`wz up` as a subprocess: router, simulator with SUMO and its sensors, both
detectors, fusion tracker, alert service, gateway on a SQLite file under ``tmp_path``; seed 3),
measured by :mod:`benchmarks.recovery`, whose docstring defines each time. In short, after the
SIGKILL of a service, **recovered** is the later of: its status from the new process, running
with data going through it, seen on the bus; and the gateway's API serving a track batch it
received after the restart with a track fresh from a sensor (after a detector's kill, from that
detector's sensor; after the alert service's, also its first devices message). Each kill waits
for a steady pipeline with the service's warm standby ready, as `wz up` is ~20 s after it
starts. `python -m benchmarks.run --only recovery` runs the same for the figures in
docs/deployment.md.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchmarks.recovery import (
    READY_TIMEOUT_S,
    SERVICES,
    TARGET_S,
    Stack,
    one_round,
)


# Recovery times on the whole stack: measured with nothing else running (`make pytest` runs
# the serial tests after the parallel ones); beside another worker's tests the simulator took
# 6.1 s to come back.
@pytest.mark.serial
@pytest.mark.slow
def test_each_service_killed_comes_back_within_5_s_and_the_gateway_loses_nothing(
    tmp_path: Path,
) -> None:
    with Stack(tmp_path) as stack:
        stack.wait_steady(READY_TIMEOUT_S)
        recoveries, stored = one_round(stack)
        code = stack.close()
    log = stack.log_path.read_text()
    table = "\n".join(str(r.as_dict()) for r in recoveries)
    assert [r.service for r in recoveries] == list(SERVICES)
    for recovery in recoveries:
        # Restarted by the supervisor: a new process, after the crash's announced backoff.
        assert recovery.exit_seen == "killed by SIGKILL (signal 9)", table
        assert recovery.new_pid != recovery.killed_pid
        assert recovery.backoff_s == 0.5
        assert recovery.from_standby, table
        assert re.search(
            rf"started {recovery.service} \(pid {recovery.new_pid}\) from its warm "
            r"standby, restart #1",
            log,
        )
        # Back, and the pipeline through it to the gateway, within the target.
        assert recovery.recovered_s is not None and recovery.recovered_s <= TARGET_S, table
        assert recovery.restart_s < recovery.recovered_s
        assert recovery.batch_tracks >= 1
    # The simulator came back as a new run (its stamps start again after its warm-up), and
    # the tracker followed it there instead of dropping its batches as late.
    simulator = recoveries[0]
    assert simulator.batch_stamp is not None and simulator.batch_stamp < 60.0 + TARGET_S, table
    assert "a new run (a restarted simulation)" in log
    # Nothing the gateway had stored was lost to its kill.
    assert stored["lost"] == {}, stored
    before, after = stored["before"], stored["after"]
    assert before["alert_ids"] >= 1 and before["track_points"] >= 1, stored
    for kind in ("track_points", "track_ids", "alert_ids"):
        assert before[kind] <= after[kind], stored
    assert after["track_points"] > before["track_points"], stored  # and it stores again
    assert code == 0, stack.log_tail()
    assert "Traceback" not in log, log[-4000:]
