"""A container health probe: has the service's loop gone round lately?

A node run with ``WZ_HEALTH_FILE`` set (``ServiceSettings.health_file``) has its
:class:`~wz_shared.service.ServiceRuntime` set that file's modification time, each time it
has published a :class:`~wz_shared.messages.ServiceStatus` (every ``WZ_STATUS_PERIOD_S``), to
the time its loop last went round (:meth:`~wz_shared.service.ServiceRuntime.beat`), and remove
it on a clean stop. A blocked loop, a stopped process (SIGSTOP) or a dead status thread all age
the file. A container's healthcheck then runs::

    python -m wz_shared.health /tmp/wz-health --max-age-s 6

which exits 0 when the file was touched within the last ``max_age_s`` seconds, else 1 with one
line on stderr saying why. It reads one file's modification time: no bus session, no import of
zenoh, so it costs a few milliseconds every interval.

While the service waits for the bus (no router reachable yet, :mod:`wz_shared.reach`), the file
holds one line saying why (``waiting for the bus: tls/router:7447: name not resolved ...``),
rewritten every few seconds: the check fails with that line, so ``docker inspect`` /
``podman healthcheck run`` and ``wz status --health-dir`` show the cause. Once the service
is on the bus, the next touch empties the file.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

#: Default age beyond which a heartbeat is stale [s]: the 5 s stall limit of a loop
#: (``WZ_STALL_AFTER_S``) plus a status period of 1 s, so a blocked loop is unhealthy within
#: 6 s and a loop that is only slow is not.
DEFAULT_MAX_AGE_S = 6.0


def touch(path: Path, at_s: float | None = None) -> None:
    """Mark the service alive at ``at_s`` (wall-clock seconds; default now): create ``path``
    (and its folder) and set its modification time to that."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.touch(exist_ok=True)
    if path.stat().st_size:  # a reason left by mark_waiting: the service is on the bus now
        path.write_bytes(b"")
    os.utime(path, None if at_s is None else (at_s, at_s))


def mark_waiting(path: Path, reason: str) -> None:
    """Say in ``path`` why the service is not working yet (``reason``: one line), now."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".part")
    partial.write_text(reason.replace("\n", " ") + "\n", encoding="utf-8")
    partial.replace(path)


def waiting_reason(path: Path) -> str | None:
    """What the service wrote while waiting (:func:`mark_waiting`), or None."""
    try:
        if not path.stat().st_size:
            return None
        return path.read_text(encoding="utf-8", errors="replace").strip() or None
    except FileNotFoundError:
        return None


def heartbeat_problem(path: Path, max_age_s: float, now_s: float | None = None) -> str | None:
    """Why the heartbeat at ``path`` is not fresh, or None when it is.

    Parameters
    ----------
    path
        The heartbeat file.
    max_age_s
        Largest accepted age of its modification time [s].
    now_s
        Wall-clock time to compare against [s since the epoch]; default now.
    """
    try:
        modified_s = path.stat().st_mtime
    except FileNotFoundError:
        return f"no heartbeat file {path} (service not started, or stopped)"
    reason = waiting_reason(path)
    if reason is not None:
        return reason
    age_s = (time.time() if now_s is None else now_s) - modified_s
    if age_s > max_age_s:
        return f"heartbeat {path} is {age_s:.1f} s old (limit {max_age_s:g} s)"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m wz_shared.health",
        description="Exit 0 when the service's heartbeat file is fresh, else 1.",
    )
    parser.add_argument("path", type=Path, help="the heartbeat file (the node's WZ_HEALTH_FILE)")
    parser.add_argument(
        "--max-age-s",
        type=float,
        default=DEFAULT_MAX_AGE_S,
        help=f"largest accepted age [s] (default {DEFAULT_MAX_AGE_S:g})",
    )
    args = parser.parse_args(argv)
    problem = heartbeat_problem(args.path, args.max_age_s)
    if problem is not None:
        sys.stderr.write(f"unhealthy: {problem}\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
