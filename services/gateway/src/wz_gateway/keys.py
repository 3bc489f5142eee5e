"""Make an API key: ``python -m wz_gateway.keys [read|admin]`` prints ``<scope>:<secret>``,
ready for ``WZ_GATEWAY_API_KEYS`` (keep it out of version control)."""

from __future__ import annotations

import sys

from wz_gateway.auth import SCOPES, new_secret


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    scope = args[0] if args else "admin"
    if scope not in SCOPES or len(args) > 1:
        sys.stderr.write(f"usage: python -m wz_gateway.keys [{'|'.join(SCOPES)}]\n")
        return 2
    sys.stdout.write(f"{scope}:{new_secret()}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
