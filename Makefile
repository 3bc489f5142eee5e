# The two commands of the README: `make demo` runs the whole pipeline on the simulated work
# zone; `make test` runs every check. Both bootstrap what they need on a fresh Debian machine.
UV := .tools/bin/uv
RUN := UV_PYTHON_DOWNLOADS=never $(UV) run --frozen --python python3.11
export WZ_LOG_FORMAT ?= text

.PHONY: bootstrap demo test lint typecheck pytest bench clean

bootstrap:
	./deploy/host/bootstrap.sh

demo: bootstrap
	$(RUN) wz demo

test: bootstrap lint typecheck pytest

lint:
	$(RUN) ruff check .

typecheck:
	$(RUN) mypy shared/src services/simulator/src services/lidar_detector/src services/camera_detector/src cli/src eval/src services/fusion_tracker/src services/alert_service/src services/gateway/src services/drivers/src

pytest:
	$(RUN) pytest -q

bench: bootstrap
	$(RUN) python -m benchmarks.run

clean:
	rm -rf .venv .tools .pytest_cache .mypy_cache .ruff_cache .hypothesis
