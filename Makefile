# Two entry points: `make run` and `make test`. Both bootstrap .venv from pyproject.toml.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test test-fast test-durations soak lint bench bench-console clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

run: $(STAMP)
	$(BIN)/aerobase demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports
	$(BIN)/mypy

# three pytest-xdist workers, a test file each at a time (a file's fixtures stay in one worker; each
# worker has a PostgreSQL database of its own: tests/conftest.py); the slowest tests are listed.
# Three on two cores: with two, a third of the CPU sat idle while tests waited on sockets and
# simulated flights (docs/figures.md, "Other figures", the `make test` row). The files go out longest first,
# by their seconds in a recorded run (tests/schedule.py, tests/durations.json), not xdist's order
PARALLEL ?= -n 3 --dist loadfile --no-loadscope-reorder

test: $(STAMP) lint
	$(BIN)/python -m pytest $(PARALLEL) -m "not soak" --durations=25 $(PYTEST_ARGS)

# `make test`, recording each file's seconds for the order the files are handed out in
test-durations: $(STAMP)
	AEROBASE_RECORD_DURATIONS=tests/durations.json $(BIN)/python -m pytest $(PARALLEL) -m "not soak" -q $(PYTEST_ARGS)

# the soak tests alone, one at a time (they load the machine themselves): issue 46's ten runs of
# the server killed during the landing beside four busy processes (~25 min)
soak: $(STAMP)
	$(BIN)/python -m pytest -m soak -s -q -p no:randomly $(PYTEST_ARGS)

# the inner loop: ruff and the import contracts, then every test not marked slow (under 2 min)
test-fast: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports
	$(BIN)/python -m pytest $(PARALLEL) -m "not slow" -q $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/python bench/telemetry.py

# the operator console's lag in headless Chromium, beside a plain operator socket
bench-console: $(STAMP)
	$(BIN)/python bench/console_lag.py

clean:
	rm -rf $(VENV) var .pytest_cache
