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
# found at run time, the one the package loaded. Without the package the plant says so.
MUJOCO_INC   := $(shell $(PY) -c "import mujoco, os; print(os.path.join(os.path.dirname(mujoco.__file__), 'include'))" 2>/dev/null)
ifneq ($(wildcard $(MUJOCO_INC)/mujoco/mujoco.h),)
EMU_CFLAGS   += -DUTRF_WITH_MUJOCO -isystem $(MUJOCO_INC)
endif

FIXTURE_CFLAGS := -mmcu=atmega2560 -DF_CPU=16000000UL -Os -std=gnu99 -Wall -Wextra \
                  -Ifirmware/src

TEST_DEPS     += $(EMU_LIB) $(EMU_FIXTURE)
DEMO_DEPS     += $(EMU_LIB)
BENCH_TARGETS += bench-emulator bench-twin

.PHONY: emulator bench-emulator bench-twin

emulator: $(EMU_LIB) $(EMU_FIXTURE)

$(EMU_LIB): $(EMU_SRCS) $(EMU_HDRS) $(EMU_DIR)/harness.mk
	@mkdir -p $(@D)
	$(EMU_CC) $(EMU_CFLAGS) -shared -o $@ $(EMU_SRCS) $(EMU_LDLIBS)

$(EMU_FIXTURE): tests/emulator/fixtures/fixture.c firmware/src/board_pins.h $(EMU_DIR)/harness.mk
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
