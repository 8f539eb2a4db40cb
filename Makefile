# UTRF-RoboHand: one entry point for set-up, builds, tests, the demo and benchmarks.
# `make demo` and `make test` do their own set-up (tools/setup.sh: apt and pip, idempotent).
SHELL := /bin/bash
.DEFAULT_GOAL := help

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
-include host/utrf/models/models.mk
-include host/utrf/hand/hand.mk
-include tests/fuzz/fuzz.mk

.PHONY: help setup test demo bench lint clean

help:
	@echo "make demo    set up, build the firmware, run the pose demo on the emulated board"
	@echo "make test    set up, build, run the whole suite (pytest drives the C++ tests too)"
	@echo "make bench   benchmarks; results in docs/benchmarks.md"
	@echo "make firmware | flash PORT=/dev/ttyACM0 | lint | generate | clean"

setup:
	@tools/setup.sh

test: setup $(TEST_DEPS)
	$(PY) -m pytest $(PYTEST_ARGS)

demo: setup $(DEMO_DEPS)
	$(PY) -m utrf demo $(DEMO_ARGS)

bench: setup $(BENCH_TARGETS)

lint: setup
	$(PY) -m ruff check $(wildcard host tests hil tools protocol)
	$(PY) -m ruff format --check $(wildcard host tests hil tools protocol)

clean:
	rm -rf $(BUILD)
