"""A warm standby of a service: its imports done ahead of a restart.

``python -m wz_cli.standby MODULE [ARG...]`` imports ``MODULE`` (and so every library it
imports: FastAPI and SQLAlchemy for the gateway, open3d and SUMO for the simulator ...), says
so on stdout (``wz-standby-ready <seconds>``, a line the supervisor takes, not shows), then
waits on stdin. A line there runs the module as ``python -m MODULE ARG...`` would; the end of
stdin (or SIGTERM) ends the standby without running it.

``wz up`` keeps one per service (see :mod:`wz_cli.supervisor`): a crashed service is replaced by
its standby, a new process whose imports, seconds of CPU on a small edge box, are already done.
Nothing else happens before the line: no bus, no settings, no log configuration (the module's
``main()`` does those).
"""

from __future__ import annotations

import importlib
import os
import runpy
import sys
import time

#: The line it writes on stdout once the module is imported, followed by the seconds it took.
READY = "wz-standby-ready"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args:
        sys.stderr.write("usage: python -m wz_cli.standby MODULE [ARG...]\n")
        return 2
    module, module_args = args[0], args[1:]
    started = time.perf_counter()
    importlib.import_module(module)
    sys.stdout.write(f"{READY} {time.perf_counter() - started:.3f}\n")
    sys.stdout.flush()
    if not sys.stdin.readline():  # the supervisor closed stdin: not needed
        return 0
    # From here on the service runs as `python -m MODULE ARG...`: the module itself is run
    # afresh as __main__ (what it imported stays imported), stdin empty as `wz up` gives its
    # services.
    sys.modules.pop(module, None)
    parent, _, name = module.rpartition(".")
    if parent in sys.modules:
        vars(sys.modules[parent]).pop(name, None)
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    sys.argv = [module, *module_args]
    runpy.run_module(module, run_name="__main__", alter_sys=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
