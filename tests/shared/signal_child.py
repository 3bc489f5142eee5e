"""A process for the signal tests: stops on SIGTERM while its main thread spins on the event.

Usage: python -m tests.shared.signal_child

It installs :func:`wz_shared.signals.stop_on_signals`, prints ``ready``, then calls
``stop.wait(0)`` in a loop, as a service's loop waits on its stop event: most of the time the
main thread holds the event's lock, where a handler that set the event would hang it for good.
Once stopped it goes on spinning for 1 s more (the test's SIGTERMs keep coming), prints
``stopped`` and exits 0.
"""

from __future__ import annotations

import sys
import time

from wz_shared.signals import stop_on_signals

#: How long it keeps spinning after the stop, taking signals [s].
AFTER_STOP_S = 1.0


def main() -> None:
    stop = stop_on_signals()
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    stopped_at: float | None = None
    while stopped_at is None or time.monotonic() - stopped_at < AFTER_STOP_S:
        if stop.wait(0) and stopped_at is None:
            stopped_at = time.monotonic()
    sys.stdout.write("stopped\n")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
