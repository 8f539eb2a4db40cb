# The Hand client: its benchmarks (round-trip latency of commands in simulated time, the
# highest telemetry rate with no drops) on the real firmware and the emulated board.
# Included by the top-level Makefile after the firmware and harness fragments.

BENCH_TARGETS += bench-client

.PHONY: bench-client

# Results into docs/benchmarks.md, between the client markers.
bench-client: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) tools/bench_client.py $(BENCH_CLIENT_ARGS)

# Moves on the board's clock: tracking over the whole demo and the tick with paths running.
BENCH_TARGETS += bench-moves

.PHONY: bench-moves

bench-moves: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) tools/bench_moves.py $(BENCH_MOVES_ARGS)
