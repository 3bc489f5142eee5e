#!/usr/bin/env bash
# Prepare a fresh Debian machine (Python 3.11, root) to run the stack and its tests:
# system packages from apt, uv from PyPI, then the locked workspace into .venv.
# Safe to run again: each step is skipped when already done.
set -euo pipefail
cd "$(dirname "$0")/../.."

# System packages. open3d (LiDAR detector, sensor simulation) needs libusb-1.0-0 to import;
# prometheus (and its promtool) checks and runs the monitoring profile's config and rules;
# chromium drives the gateway page's browser tests; postgresql is the gateway's second database
# (its tests start a throwaway cluster); iproute2 makes the multi-host test networks; systemd
# gives systemd-analyze, which checks the no-container units in deploy/systemd.
APT_PACKAGES=(ca-certificates libusb-1.0-0 libgl1 libgomp1 iproute2 procps chromium postgresql systemd prometheus)
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if ((${#missing[@]})); then
  if [[ $(id -u) -ne 0 ]]; then
    echo "bootstrap: missing system packages: ${missing[*]} (run as root or install them)" >&2
    exit 1
  fi
  echo "bootstrap: apt-get install ${missing[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# uv, pinned, in a private tool venv (works where pip refuses system-wide installs, PEP 668).
UV_VERSION=0.13.9
if ! .tools/bin/uv --version 2>/dev/null | grep -q "$UV_VERSION"; then
  if ! python3 -m venv .tools 2>/dev/null; then
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv
    python3 -m venv .tools
  fi
  .tools/bin/python -m pip install -q --disable-pip-version-check "uv==$UV_VERSION"
fi

# The workspace, exactly as locked, on this machine's Python 3.11 (never a downloaded one).
UV_PYTHON_DOWNLOADS=never .tools/bin/uv sync --frozen --python python3.11 --all-packages
