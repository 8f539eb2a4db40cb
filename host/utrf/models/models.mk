# Finger models (issue 5). Included by the top-level Makefile.
#   make bench-models     statics benchmark; rewrites the Models section of docs/benchmarks.md
#   make figures-models   the models page's figures in docs/figures/ (committed)
#   make kinematics-table regenerate firmware/src/generated/kinematics_table.h (committed)
BENCH_TARGETS += bench-models

.PHONY: bench-models figures-models kinematics-table

bench-models: setup
	$(PY) -m utrf.models.bench --update docs/benchmarks.md --json $(BUILD)/bench/models.json

figures-models: setup
	$(PY) -m utrf.models.figures docs/figures

kinematics-table: setup
	$(PY) -m utrf.firmware_table
