"""A screenshot of a running gateway's live page, for the docs: with ``wz up`` running,

    python -m tests.gateway.screenshot http://127.0.0.1:8000/ docs/images/gateway-live.png

waits until the page shows at least ``--tracks`` vehicles and ``--alerts`` alerts (traffic
comes in waves), and ``--when`` holds, then captures it with headless Chromium (:mod:`tests.gateway.browser`).
"""

from __future__ import annotations

import argparse
import logging
import tempfile
from pathlib import Path

from tests.gateway.browser import chromium

log = logging.getLogger("screenshot")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", help="the gateway's page, e.g. http://127.0.0.1:8000/")
    parser.add_argument("out", type=Path, help="the PNG to write")
    parser.add_argument("--tracks", type=int, default=6, help="least vehicles on the page")
    parser.add_argument("--alerts", type=int, default=1, help="least alerts in the list")
    parser.add_argument(
        "--when",
        default="true",
        help="and this JavaScript condition, e.g. "
        "'window.wzLive.tracks.some(t => t.speed_mps > 27)'",
    )
    parser.add_argument("--timeout", type=float, default=600.0, help="give up after [s]")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("httpx").setLevel(logging.WARNING)
    with tempfile.TemporaryDirectory() as profile, chromium(Path(profile)) as page:
        page.call("Page.navigate", url=args.url)
        page.wait_for(
            f"document.body && Number(document.body.dataset.trackCount) >= {args.tracks}"
            f" && Number(document.body.dataset.alertCount) >= {args.alerts}"
            f" && ({args.when})",
            f"{args.tracks} tracks and {args.alerts} alerts",
            args.timeout,
        )
        page.screenshot(args.out)
        errors = page.errors()
    log.info("wrote %s%s", args.out, f"; the page's errors: {errors}" if errors else "")


if __name__ == "__main__":
    main()
