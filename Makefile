# SteelPath: `make serve` runs the service with its embedded defaults,
# `make test` installs what the tests need and runs the whole suite.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: serve test test-fast install install-test system-test-deps lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

install: $(BIN)/python
	$(BIN)/pip install --quiet -e .

serve: install
	$(BIN)/steelpath serve

install-test: $(BIN)/python
	$(BIN)/pip install --quiet -e '.[test]'

# Debian's Chromium drives the browser test; docker-compose validates docker/compose.yml;
# the PostgreSQL tests start a server of Debian's postgresql package (initdb in a temp dir).
system-test-deps:
	@if ! command -v chromium >/dev/null 2>&1 || ! command -v docker-compose >/dev/null 2>&1 || ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium docker-compose postgresql >/dev/null; \
	  else \
	    echo "chromium, docker-compose or postgresql is missing: run 'sudo apt-get install chromium docker-compose postgresql'" >&2; exit 1; \
	  fi; \
	fi

lint: install-test
	$(BIN)/ruff check .
	$(BIN)/mypy

test: install-test system-test-deps lint
	$(BIN)/pytest

# The edit loop: unit tests (no slow, browser or integration tests), then one
# fault-matrix cell per fault (the cheap demo.route kind) and the registry check.
test-fast: install-test
	$(BIN)/pytest -q -m "not slow and not browser and not integration"
	$(BIN)/pytest -q tests/api/test_fault_matrix.py -k "demo.route or registered"

bench: install-test
	for b in tests/benchmarks/bench_*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache *.egg-info
