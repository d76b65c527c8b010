# SteelPath: `make serve` runs the service with its embedded defaults,
# `make test` installs what the tests need and runs the whole suite.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: serve test test-fast install install-test system-test-deps lint bench clean docker-clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

install: $(BIN)/python
	$(BIN)/pip install --quiet -e .

serve: install
	$(BIN)/steelpath serve

install-test: $(BIN)/python
	$(BIN)/pip install --quiet -e '.[test]'

# Debian's Chromium drives the browser test; the PostgreSQL tests start a server of
# Debian's postgresql package (initdb in a temp dir); tests/docker starts dockerd
# (docker.io) when none runs, builds stand-in base images with debootstrap where
# Docker Hub cannot be reached, and runs docker/compose.yml with docker-compose.
SYSTEM_TEST_PACKAGES := chromium docker-compose postgresql docker.io debootstrap
system-test-deps:
	@if ! command -v chromium >/dev/null 2>&1 || ! command -v docker-compose >/dev/null 2>&1 || ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 \
	    || ! command -v dockerd >/dev/null 2>&1 || ! command -v debootstrap >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(SYSTEM_TEST_PACKAGES) >/dev/null; \
	  else \
	    echo "a system package the tests need is missing: run 'sudo apt-get install $(SYSTEM_TEST_PACKAGES)'" >&2; exit 1; \
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

# What tests/docker keeps between runs as a cache: the stand-in base images and
# the product image's build layers.
docker-clean: install-test
	$(BIN)/python -m tests.support.docker_standins --clean
	docker image prune -f
