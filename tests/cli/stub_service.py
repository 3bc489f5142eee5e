"""Stand-ins for services in the supervisor test: one that crashes, one that ignores SIGTERM.

Usage: python -m tests.cli.stub_service crash|stubborn
"""

from __future__ import annotations

import signal
import sys
import time


def main() -> None:
    behaviour = sys.argv[1]
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
