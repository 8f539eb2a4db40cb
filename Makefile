# UTRF-RoboHand: one entry point for set-up, builds, tests, the demo and benchmarks.
# `make demo` and `make test` do their own set-up (tools/setup.sh: apt and pip, idempotent),
# then build and run in a second make: make reads every makefile (and evaluates $(wildcard))
# before any recipe runs, so on a fresh machine this invocation has parsed before the set-up
# installed the Arduino core and simavr. No rule may depend on what set-up installs at parse
# time (firmware/arduino_core.mk lists the core's sources in a sub-make for the same reason).
# Every build step that uses what set-up installs has `| $(NEEDS_SETUP)` (order-only), so
# `make firmware` or `make setup firmware emulator` on a fresh clone sets up first (also with
# -j); the sub-makes after a set-up skip it (SETUP_DONE=1). What a build used that make cannot
# see as a file (MuJoCo's headers, flags) is recorded in a stamp it depends on (harness.mk,
# firmware.mk), so a harness built without MuJoCo is rebuilt once MuJoCo is there.
SHELL := /bin/bash
.DEFAULT_GOAL := help

NEEDS_SETUP := $(if $(SETUP_DONE),,setup)

VENV  := .venv
PY    := $(VENV)/bin/python
BUILD := build

# Each area's fragment appends its build products and benchmark targets to these lists.
TEST_DEPS     :=
DEMO_DEPS     :=
BENCH_TARGETS :=

-include protocol/protocol.mk
-include firmware/firmware.mk
-include host/utrf/emulator/harness/harness.mk
-include tests/fuzz/fuzz.mk
-include tools/tools.mk

.PHONY: help setup test demo bench lint clean test-after-setup demo-after-setup \
        bench-after-setup test-fresh-clone
SUBMAKE = $(MAKE) --no-print-directory SETUP_DONE=1

help:
	@echo "make demo    set up, build the firmware, run the pose demo on the emulated board"
	@echo "make test    set up, build, run the whole suite (pytest drives the C++ tests too)"
	@echo "make test-fresh-clone  a clone of HEAD set up from nothing (new .venv), README's commands"
	@echo "make bench   benchmarks; results in docs/benchmarks.md"
	@echo "make generate  every generated file, rewritten (tests fail when one is stale)"
	@echo "make firmware | flash PORT=/dev/ttyACM0 | lint | hil-readme | figures | clean"

setup:
	@tools/setup.sh

test: setup
	@$(SUBMAKE) test-after-setup
# The suite on every core (pytest-xdist; a module's tests stay on one worker, so its fixtures
# start once): PYTEST_WORKERS=0 runs it in one process.
PYTEST_WORKERS ?= auto
test-after-setup: $(TEST_DEPS)
	$(PY) -m pytest -n $(PYTEST_WORKERS) --dist loadscope $(PYTEST_ARGS)

# Minutes of pip and builds in a clone with a new .venv: its own target, run by .ci/run after
# `make test`, so the suite stays quick.
test-fresh-clone: setup
	UTRF_FRESH_CLONE=1 $(PY) -m pytest tests/packaging/test_fresh_clone.py $(PYTEST_ARGS)

demo: setup
	@$(SUBMAKE) demo-after-setup
demo-after-setup: $(DEMO_DEPS)
	$(PY) -m utrf demo $(DEMO_ARGS)

bench: setup
	@$(SUBMAKE) bench-after-setup
bench-after-setup: $(BENCH_TARGETS)

lint: setup
	$(PY) -m ruff check $(wildcard host tests hil tools protocol)
	$(PY) -m ruff format --check $(wildcard host tests hil tools protocol)

clean:
	rm -rf $(BUILD)
