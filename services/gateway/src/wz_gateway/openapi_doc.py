"""The gateway's OpenAPI document, as committed in ``services/gateway/openapi.json``.

Usage::

    python -m wz_gateway.openapi_doc --write services/gateway/openapi.json   # after an API change
    python -m wz_gateway.openapi_doc --check services/gateway/openapi.json   # exit 1 if stale

The document is the app's own (``/openapi.json``), built with the default settings and site
(the same routes, parameters and schemas whatever the deployment; only limits such as the page
size differ, and they are the defaults here), on a throw-away SQLite file. A client generator
or a dashboard team reads the committed file; ``tests/gateway/test_openapi.py`` checks that it
is what the code serves.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from wz_gateway.app import create_app
from wz_gateway.auth import new_secret
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_shared.site import DEFAULT_SITE_PATH, load_site


def document() -> dict[str, Any]:
    """The OpenAPI document of the gateway with default settings and the default site (the
    environment's ``WZ_*`` variables are set aside: the document is the code's)."""
    saved = {k: v for k, v in os.environ.items() if k.startswith("WZ_")}
    for name in saved:
        del os.environ[name]
    try:
        return _document()
    finally:
        os.environ.update(saved)


def _document() -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="wz-openapi-") as folder:
        # A key only so that the settings are complete; no key appears in the document.
        settings = GatewaySettings(data_dir=Path(folder), api_keys=[f"admin:{new_secret()}"])
        storage = Storage.open(settings.resolved_database_url())
        try:
            app = create_app(settings, storage, site=load_site(DEFAULT_SITE_PATH))
            return app.openapi()
        finally:
            storage.close()


def render(doc: dict[str, Any]) -> str:
    """Stable text: sorted keys, two-space indent, a final newline (diffs stay readable)."""
    return json.dumps(_ordered(doc), indent=2, ensure_ascii=False) + "\n"


def _ordered(value: Any, parent: str | None = None) -> Any:
    """Keys sorted (a stable diff), except a response's media types: ``application/json``
    first, the one a generated client parses a response as (it takes the first)."""
    if isinstance(value, list):
        return [_ordered(item) for item in value]
    if not isinstance(value, dict):
        return value
    keys = sorted(value)
    if parent == "content" and "application/json" in value:
        keys.remove("application/json")
        keys.insert(0, "application/json")
    return {key: _ordered(value[key], key) for key in keys}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wz_gateway.openapi_doc")
    action = parser.add_mutually_exclusive_group(required=True)
    action.add_argument("--write", type=Path, metavar="FILE", help="write the document there")
    action.add_argument("--check", type=Path, metavar="FILE", help="exit 1 if FILE differs")
    args = parser.parse_args(argv)
    text = render(document())
    if args.write is not None:
        args.write.write_text(text, encoding="utf-8")
        return 0
    try:
        committed = args.check.read_text(encoding="utf-8")
    except OSError as exc:
        sys.stderr.write(f"cannot read {args.check}: {exc}\n")
        return 1
    if committed != text:
        sys.stderr.write(
            f"{args.check} is not the API the code serves: run python -m wz_gateway.openapi_doc "
            f"--write {args.check}\n"
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
