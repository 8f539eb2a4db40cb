# The emulated board: the simavr harness (a shared library loaded by utrf.emulator through
# ctypes) and its own test fixture (a small AVR program). Included by the top-level Makefile.

EMU_DIR      := host/utrf/emulator/harness
FW_SRC       ?= firmware/src
EMU_BUILD    := $(BUILD)/emulator
EMU_LIB      := $(EMU_BUILD)/libutrf_sim.so
EMU_FIXTURE  := $(EMU_BUILD)/fixture.elf
EMU_SRCS     := $(wildcard $(EMU_DIR)/*.c)
EMU_HDRS     := $(wildcard $(EMU_DIR)/*.h) $(FW_SRC)/board_pins.h

# simavr's and avr-libc's headers are -isystem/-idirafter: -Wall -Wextra judge our code only.
EMU_CC       ?= cc
EMU_CFLAGS   := -std=gnu11 -O2 -g -fPIC -Wall -Wextra -Wshadow \
                -isystem /usr/include/simavr -idirafter /usr/lib/avr/include -I$(FW_SRC)
EMU_LDLIBS   := -lsimavr -lelf -lpthread -ldl -lm
# MuJoCo's headers from the mujoco package (the MuJoCo plant, mjplant.c); libmujoco itself is
# found at run time, the one the package loaded. Without the package the plant says so. Looked
# up when the recipe runs (on a fresh clone the set-up installs it during this make) and
# recorded in EMU_CONFIG with the flags: a change of either rebuilds the harness.
EMU_CONFIG   := $(EMU_BUILD)/built-with.txt
MUJOCO_FIND  := import mujoco, os; \
  inc = os.path.join(os.path.dirname(mujoco.__file__), 'include'); \
  print(inc if os.path.isfile(os.path.join(inc, 'mujoco', 'mujoco.h')) else '', \
        mujoco.__version__)

FIXTURE_CFLAGS := -mmcu=atmega2560 -DF_CPU=16000000UL -Os -std=gnu99 -Wall -Wextra \
                  -Ifirmware/src

TEST_DEPS     += $(EMU_LIB) $(EMU_FIXTURE)
DEMO_DEPS     += $(EMU_LIB)
BENCH_TARGETS += bench-emulator bench-twin

.PHONY: emulator bench-emulator bench-twin

emulator: $(EMU_LIB) $(EMU_FIXTURE)

# Always asked; rewritten only when what the harness is built with changed.
$(EMU_CONFIG): FORCE_EMU_CONFIG | $(NEEDS_SETUP)
	@mkdir -p $(@D)
	@set -- $$($(PY) -c "$(MUJOCO_FIND)" 2>/dev/null); \
	 new="mujoco_include=$${1:-none} mujoco_version=$${2:-none} cc=$(EMU_CC) cflags=$(EMU_CFLAGS)"; \
	 if [ ! -f $@ ] || [ "$$(cat $@)" != "$$new" ]; then echo "$$new" > $@; fi
.PHONY: FORCE_EMU_CONFIG
FORCE_EMU_CONFIG:

# Read from EMU_CONFIG when the recipe runs (after EMU_CONFIG is made).
EMU_MJ_INC    = $(shell sed -n 's/^mujoco_include=\([^ ]*\) .*/\1/p' $(EMU_CONFIG))
EMU_MJ_FLAGS  = $(if $(filter none,$(EMU_MJ_INC)),,-DUTRF_WITH_MUJOCO -isystem $(EMU_MJ_INC))

$(EMU_LIB): $(EMU_SRCS) $(EMU_HDRS) $(EMU_DIR)/harness.mk $(EMU_CONFIG)
	@mkdir -p $(@D)
	@$(if $(EMU_MJ_FLAGS),true,echo "emulator: building the harness without MuJoCo (no mujoco \
	  package for $(PY))")
	$(EMU_CC) $(EMU_CFLAGS) $(EMU_MJ_FLAGS) -shared -o $@ $(EMU_SRCS) $(EMU_LDLIBS)

$(EMU_FIXTURE): tests/emulator/fixtures/fixture.c firmware/src/board_pins.h $(EMU_DIR)/harness.mk \
                | $(NEEDS_SETUP)
	@mkdir -p $(@D)
	avr-gcc $(FIXTURE_CFLAGS) -o $@ $<

# The real-time factor and the control tick's CPU load, on the real firmware (firmware.mk's
# `firmware` target builds it); results into docs/benchmarks.md, between the emulator markers.
bench-emulator: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_emulator $(BENCH_EMULATOR_ARGS)

# The twin's throughput against f500c49 (issue 20): a 120 s grasp hold in fresh processes, this
# checkout and a throwaway worktree of the reference under build/ (built by its own make),
# alternately; each engine alone too. Results into docs/benchmarks.md, between the twin markers.
bench-twin: setup $(EMU_LIB) $(filter firmware,$(DEMO_DEPS))
	$(PY) -m tools.bench_twin $(BENCH_TWIN_ARGS)
