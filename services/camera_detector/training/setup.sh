#!/usr/bin/env bash
# Create the camera model's training environment in .train/ at the repository root.
# CPU only: torch 2.13.0 (this machine's registry serves the CPU build; elsewhere add
# --extra-index-url https://download.pytorch.org/whl/cpu), ultralytics without its
# dependency on torchvision, and our torchvision stand-in (torchvision.ops.nms only).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
python3.11 -m venv "$root/.train"
"$root/.train/bin/pip" install -q torch==2.13.0
"$root/.train/bin/pip" install -q --no-deps ultralytics==8.4.190
"$root/.train/bin/pip" install -q -r "$here/requirements.txt"
"$root/.train/bin/pip" install -q "$here/torchvision-standin"
"$root/.train/bin/python" -c "import torch, torchvision, ultralytics; print('torch', torch.__version__, 'torchvision', torchvision.__version__, 'ultralytics', ultralytics.__version__)"
