# Repository maintenance (tools/): what `make generate` regenerates, the benchmarks run from
# here, the docs' figures. Included by the top-level Makefile after the area fragments (the
# client benchmarks use the firmware's and the harness's build products). Every tool runs from
# the repository's root as `python -m tools.NAME`.
#
#   make generate          every generated file: the protocol bindings and README tables, the
#                          golden vectors, the kinematics table, hil/README.md's seed-0 section,
#                          docs/hand.md's table of `utrf` commands (tests fail when any of them
#                          is stale)
#   make kinematics-table  firmware/src/generated/kinematics_table.h from the hand file
#   make hil-readme        hil/README.md's seed-0 section, from the emulated run it reports
#   make figures           the models page's figures in docs/figures/ (committed)
#   make bench-models | bench-client | bench-moves   their sections of docs/benchmarks.md
#   make bench-campaign    campaigns on Dask: 1e6 designs, 1 vs 2 workers, the engine's share

.PHONY: generate kinematics-table hil-readme figures figures-models bench-models \
        bench-client bench-moves bench-campaign

# One after the other: the vectors need the regenerated bindings, the hil section the rebuilt
# firmware.
generate: setup
	@$(SUBMAKE) protocol-generate
	@$(SUBMAKE) kinematics-table
	@$(SUBMAKE) hil-readme
	$(PY) -m tools.cli_doc

kinematics-table: setup
	$(PY) -m tools.kinematics_table

# The firmware it runs has build id 0: the id (the git commit) is in the identify reply, whose
# bytes shift the simulated run's timing, so the table would otherwise change with every commit.
hil-readme: setup
	@$(SUBMAKE) emulator
	@$(SUBMAKE) BUILD=$(BUILD)/id0 FW_GIT_ID= $(BUILD)/id0/firmware/utrf.elf
	$(PY) -m tools.hil_readme --elf $(BUILD)/id0/firmware/utrf.elf

# Pictures, not text: their bytes follow the matplotlib version, so no test compares them and
# `make generate` leaves them alone.
figures: figures-models
figures-models: setup
	$(PY) -m tools.model_figures docs/figures

BENCH_TARGETS += bench-models bench-client bench-moves bench-campaign

# The statics solver and the MuJoCo hand: the "## Models" section.
bench-models: setup
	$(PY) -m tools.bench_models --update docs/benchmarks.md --json $(BUILD)/bench/models.json

# The Hand client: round-trip latency of commands in simulated time, the highest telemetry
# rate with no drops, on the real firmware and the emulated board.
bench-client: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_client $(BENCH_CLIENT_ARGS)

# Moves on the board's clock: tracking over the whole demo and the tick with paths running.
bench-moves: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_moves $(BENCH_MOVES_ARGS)

# Campaigns on Dask (utrf campaign): 1e6 designs, runs an hour on 1 and 2 workers, the
# engine's share of the wall time, twin grasp holds: the "## Campaigns" section.
bench-campaign: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_campaign --update docs/benchmarks.md --json $(BUILD)/bench/campaign.json \
	  $(BENCH_CAMPAIGN_ARGS)

# A firmware A/B (docs/campaigns.md): a second ELF, the same sources with other defaults
# (FW_B_DEFS: -D flags config.cpp reads; by default a 30 % duty cap instead of 80 %): only
# config.cpp is compiled again, the rest is the main build's. build/firmware/b/, never
# committed. `make campaign-ab` runs the two over the same scenarios and writes the verdict
# into docs/campaigns.md; tests/campaign/test_ab.py runs a small one in `make test`.
FW_B_DEFS ?= -DUTRF_DEFAULT_MAX_DUTY=300
FW_B_DIR  := $(FW_BUILD)/b
FW_B_ELF  := $(FW_B_DIR)/utrf.elf
TEST_DEPS += $(FW_B_ELF)
.PHONY: firmware-b campaign-ab FORCE_FW_B
firmware-b: $(FW_B_ELF)
$(FW_B_DIR)/defs.txt: FORCE_FW_B
	@mkdir -p $(@D)
	@if [ ! -f $@ ] || [ "$$(cat $@)" != '$(FW_B_DEFS)' ]; then echo '$(FW_B_DEFS)' > $@; fi
FORCE_FW_B:
$(FW_B_DIR)/config.o: $(FW_SRC)/core/config.cpp $(FW_B_DIR)/defs.txt $(FW_BUILT_WITH) | $(NEEDS_SETUP)
	$(AVR_CXX) -c $(FW_MCU) $(FW_OPT) $(FW_CXXSTD) $(FW_WARN) $(FW_DEFS) $(FW_B_DEFS) $(FW_INC) \
	  -o $@ $<
$(FW_B_ELF): $(filter-out %/core/config.o,$(FW_OWN_OBJS)) $(FW_B_DIR)/config.o $(ARDUINO_LIB)
	$(AVR_CXX) $(FW_MCU) -Wl,--gc-sections -o $@ $^ -lm
AB_SCENARIOS ?= 40
campaign-ab: setup $(EMU_LIB) $(FW_ELF) $(FW_B_ELF)
	$(PY) -m tools.campaign_ab --a $(FW_ELF) --b $(FW_B_ELF) --b-defs='$(FW_B_DEFS)' \
	  --scenarios $(AB_SCENARIOS) --update docs/campaigns.md

# Seeded builds of the twin brought up: faults against findings, then the demo's tracking goal
# on the fixable ones, into docs/bringup.md. BUILDS=50 by default, on Dask (WORKERS= local
# processes, default one a core); resumable: the builds already in the JSON-lines file are
# skipped (delete it to start again).
.PHONY: bringup-campaign
BUILDS ?= 50
bringup-campaign: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	@mkdir -p $(BUILD)/bench
	$(PY) -m tools.bringup_campaign --builds $(BUILDS) --update docs/bringup.md \
	  --json $(BUILD)/bench/bringup-campaign.jsonl $(if $(WORKERS),--workers $(WORKERS))

# The dashboard's goals (docs/dashboard.md): sample-to-pixels latency, the server's CPU, the
# page's frame rate, in headless chromium against `utrf emulate`: the "## Dashboard" section.
BENCH_TARGETS += bench-dashboard
.PHONY: bench-dashboard bench-recording
bench-dashboard: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_dashboard --update docs/benchmarks.md $(BENCH_DASHBOARD_ARGS)

# A 10-minute recording at 1 kHz loses no sample: the "## Recording" section. Not part of
# `make bench` (it takes 10 minutes); BENCH_RECORDING_ARGS="--seconds 60" for a shorter one.
bench-recording: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_recording --update docs/benchmarks.md $(BENCH_RECORDING_ARGS)
