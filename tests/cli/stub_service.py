"""Stand-ins for services in the supervisor tests: one that crashes, one that ignores SIGTERM,
one that serves until SIGTERM and says who it is.

Usage: python -m tests.cli.stub_service crash|stubborn|serve [ARG...]
"""

from __future__ import annotations

import os
import signal
import sys
import time

from wz_shared.signals import stop_on_signals


def main() -> None:
    behaviour = sys.argv[1]
    if behaviour == "serve":
        stop = stop_on_signals()
        sys.stdout.write(f"serving: pid {os.getpid()}, args {sys.argv[1:]}\n")
        sys.stdout.flush()
        stop.wait()
        return
    if behaviour == "crash":
        sys.stdout.write("crashing now\n")
        sys.stderr.write("a line on stderr\n")
        raise SystemExit(3)
    if behaviour == "stubborn":
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        sys.stdout.write("ignoring SIGTERM\n")
        sys.stdout.flush()
        while True:
            time.sleep(0.1)
    raise SystemExit(f"unknown behaviour {behaviour}")


if __name__ == "__main__":
    main()
