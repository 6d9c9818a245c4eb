# The two quick-start commands: `make demo` (the main job) and `make test` (the whole suite).
# For the edit-test loop, `make check`: the fast tier (every test not marked slow: the unit
# tests and the quick integration tests; tests/conftest.py says which are slow).
# Each first installs rhbl and its dependencies into a virtual environment of its own, $(VENV),
# made from $(PYTHON): the interpreter itself is never installed into, so a system python3 that
# is "externally managed" (PEP 668, Debian 12, Ubuntu 24.04) works as well as any other.
#   make PYTHON=python3.12 demo      build the environment from another interpreter
#   make VENV=$VIRTUAL_ENV test       install into (and use) an environment you already have
#   make demo DEMO_ARGS='--scenario maze'
#   make compose-test                 docker/compose.yaml in real containers (podman or Docker)
#   make test TEST_WORKERS=1          the suite in one process (TEST_WORKERS=auto: one per core)
#   RHBL_TEST_PATIENCE=3 make test    every wait's deadline three times longer (a slow machine)
#
# The tests run on TEST_WORKERS processes (pytest-xdist, default 3), a test module on one
# worker (--dist loadfile: a module's server, browser and ordered steps stay together). Most of
# the suite's time is spent waiting on real processes (a lock-step server, a teacher's
# demonstration in sim time, a container build), not computing in the test process, so three
# workers cut it even on the 2-core machine. Measured here, 2026-12-06, nothing else running:
# the whole suite (1479 tests) on 3 workers 9 min 28 s, on 2 workers 11 min 27 s (one more
# agent's experiments running); `make check` (1192 tests) on 2 workers 1 min 58 s. The two
# slowest tests (containers 212 s, quick start 123 s) run beside the rest; TEST_WORKERS=1
# gives back the one-process run.
PYTHON ?= python3
VENV ?= .venv
DEMO_ARGS ?=
COMPOSE_TEST_ARGS ?=
BIN := $(VENV)/bin
# installed once per change of pyproject.toml, setup.py or the compiled kernels' source (the
# install compiles them ahead of time where a C compiler is found); removing $(VENV) starts
# afresh
STAMP := $(VENV)/.rhbl-installed
KERNEL_SOURCES := setup.py rhbl/_layout.py rhbl/_kernels.py server/_laser_kernels.py \
                  client/behaviour/_payload_layout.py client/behaviour/_payload_kernels.py
# the environment's commands (hadolint, shellcheck, rhbl) first on PATH for the tests
RUN := PATH="$(abspath $(BIN)):$$PATH"

$(STAMP): pyproject.toml $(KERNEL_SOURCES)
	@bash scripts/make-venv.sh "$(PYTHON)" "$(VENV)"
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[dev]'
	@touch $(STAMP)
	@echo "make: rhbl is installed in the virtual environment $(VENV)/ ($(BIN)/rhbl;" \
	      "'. $(BIN)/activate' puts it on your PATH)"

install: $(STAMP)

demo: $(STAMP)
	$(RUN) $(BIN)/rhbl demo $(DEMO_ARGS)

TEST_WORKERS ?= 3
PYTEST := $(RUN) $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

test: $(STAMP)
	$(PYTEST) tests

check: $(STAMP)
	$(PYTEST) -m "not slow" tests

lint: $(STAMP)
	$(RUN) $(BIN)/ruff check .

# builds the images, runs the compose scenario, checks it from outside, removes what it made
# (as root on Debian, scripts/ci-containers.sh first installs podman, runc and mmdebstrap)
compose-test: $(STAMP)
	@bash scripts/ci-containers.sh
	$(RUN) $(BIN)/python docker/compose_test.py $(COMPOSE_TEST_ARGS)

.PHONY: install demo test check lint compose-test
