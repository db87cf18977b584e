# tactile-sl: the two commands a user needs are `make demo` and `make test`.
SHELL := /bin/bash
.DEFAULT_GOAL := help
ENV := TACTILE_SL_NETWORK=loopback source env.sh &&
# pytest processes for `make test` (pytest-xdist; each takes every n-th test domain id)
TEST_WORKERS ?= 2

.PHONY: help setup build test lint typecheck unit demo bags bench clean

help:
	@echo "make demo   - replay the bundled bag through the pipeline and print what came out"
	@echo "              (make demo VIEW=1: also the browser view, address printed)"
	@echo "make test   - lint + the whole test suite (creates .venv and builds on first use)"
	@echo "make unit   - the fast unit tests only (no node processes, nothing slow; < 1 min)"
	@echo "make lint   - ruff and the type checker (mypy; what the pre-commit hooks run)"
	@echo "make setup  - create .venv and colcon build (idempotent)"
	@echo "make bags   - regenerate bags/ from the shipped pattern (deterministic)"
	@echo "make bench  - speed and accuracy benchmarks (figures, not pass/fail)"
	@echo "make clean  - remove build/, install/, log/ (keeps .venv)"

setup:
	@bash tools/setup.sh

build: setup

lint: setup
	@$(ENV) ruff check src tests tools
	@$(ENV) mypy

# mypy over the libraries (files and settings in pyproject.toml; cache in .mypy_cache)
typecheck: setup
	@$(ENV) mypy

# unit tests only (src/<pkg>/test, no processes, no DDS, nothing marked slow); make test runs all
unit: setup
	@$(ENV) python -m pytest -q src -m "not ros and not slow"

# mypy (~60 s on a cold cache) runs beside the unit tests, which come first; its report
# follows pytest's, and either failing fails the target
test: setup
	@$(ENV) ruff check src tests tools
	@$(ENV) { log=$$(mktemp); { mypy >"$$log" 2>&1; echo $$? >"$$log.rc"; } & \
	  python -m pytest -n $(TEST_WORKERS) --dist loadfile src tests; rc=$$?; wait; cat "$$log"; mrc=$$(cat "$$log.rc"); \
	  rm -f "$$log" "$$log.rc"; [ $$rc -eq 0 ] && [ $$mrc -eq 0 ]; }

demo: setup
	@$(ENV) python tools/demo.py $(if $(VIEW),--view)

bags: setup
	@$(ENV) bash tools/make_bags.sh

bench: setup
	@$(ENV) python tools/bench_extraction.py --bag bags/sphere_deep_small.mcap
	@$(ENV) python tools/bench_pipeline.py
	@$(ENV) python tools/bench_pipeline.py --flip 0.05
	@$(ENV) python tools/bench_pipeline.py bags/two_contacts.mcap --carry off --repeat 5
	@$(ENV) python tools/bench_pipeline.py --sequence --carry both
	@$(ENV) python tools/bench_pipeline.py --ros --rate 30 --seconds 10
	@$(ENV) python tools/bench_graph.py
	@$(ENV) python tools/bench_graph.py --rate 6 --seconds 60
	@$(ENV) python tools/bench_graph.py --sensors 2 --seconds 60
	@$(ENV) python tools/bench_rclpy.py
	@$(ENV) python tools/bench_calibration.py
	@$(ENV) nice -n 10 python tools/bench_sweep.py --bound
	@$(ENV) python tools/bench_touch.py
	@$(ENV) python tools/bench_touch.py --no-slip --no-shapes --repeat 1 --light-seeds 11 12 13 14 15 16 --per-draw --bound --bound-pictures out/touch_bound
	@$(ENV) python tools/bench_viewer.py

clean:
	rm -rf build install log
