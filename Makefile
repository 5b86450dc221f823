# Two entry points: `make run` (closed loop, default agent) and `make test`; `make test-slow` runs the
# tests marked slow (pyproject's addopts deselect them by default; a later -m replaces that).
# Both create or refresh .venv themselves; the stamp re-installs when the package metadata changes.
# The install resumes a dropped download and tries three times: rerun-sdk alone is a 170 MB wheel.
# `make test` installs the ray and viz extras too: the suite tests --ray and sweep on a local Ray instance,
# and --record / drivestack view with rerun.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
ARGS ?=
# pytest-xdist: one worker per core of the 2-core CI machine; each test file stays in one worker so
# its module fixtures are built once. `make test PYTEST_WORKERS=` runs serially. On a cold numba cache
# tests/conftest.py first compiles the kernels once, one part a core (tests/kernel_warmup.py).
PYTEST_WORKERS ?= -n 2 --dist loadfile

.PHONY: run test test-slow bench lint clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	for attempt in 1 2 3; do \
	  $(BIN)/python -m pip install --quiet --resume-retries 20 -c constraints.txt -e '.[dev,ray,viz]' && break; \
	  test $$attempt -lt 3 || exit 1; \
	  echo "pip install failed (attempt $$attempt of 3, a dropped download?); retrying in 30 s" >&2; sleep 30; \
	done
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/drivestack run --config configs/highway.yaml --scenario overtaking --beside keep-lane $(ARGS)

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest $(PYTEST_WORKERS)

test-slow: $(STAMP)
	$(BIN)/python -m pytest $(PYTEST_WORKERS) -m slow

bench: $(STAMP)
	$(BIN)/python benchmarks/cli_startup.py
	$(BIN)/python benchmarks/hostile_inputs.py
	$(BIN)/python benchmarks/loop_rate.py
	$(BIN)/python benchmarks/loop_rate.py --cpu
	$(BIN)/python benchmarks/loop_profile.py
	$(BIN)/python benchmarks/loop_profile.py --scenario overtaking
	$(BIN)/python benchmarks/sim_speed.py
	$(BIN)/python benchmarks/oracle_cost.py
	$(BIN)/python benchmarks/record_cost.py
	$(BIN)/python benchmarks/lookahead_cost.py
	$(BIN)/python benchmarks/feasible_spawns.py
	$(BIN)/python benchmarks/grid_speed.py
	$(BIN)/python benchmarks/deepcars_speed.py
	$(BIN)/python benchmarks/deepcars_ceiling.py
	$(BIN)/python benchmarks/train_rate.py
	$(BIN)/python benchmarks/training_worlds.py
	$(BIN)/drivestack track --out runs/bench-track --no-progress
	$(BIN)/python benchmarks/tracking_table.py runs/bench-track
	$(BIN)/python benchmarks/mpc_solve.py
	$(BIN)/python benchmarks/decision_ceiling.py
	$(BIN)/python benchmarks/ray_scaling.py
	$(BIN)/python benchmarks/compare_rate.py
	$(BIN)/python benchmarks/benchmark_time.py

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

clean:
	rm -rf $(VENV) build *.egg-info
