# Firmware for the Arduino MEGA 2560 (Debian's avr-gcc + arduino-core-avr), the host build of
# its core for the tests, flashing and the firmware benchmark. Included by the top Makefile.
#
#   make firmware              build/firmware/utrf.elf and .hex; prints flash and RAM use against
#                              the chip (as the Arduino IDE does) and the project's budgets
#   make flash PORT=/dev/ttyACM0   avrdude over the MEGA's stk500v2 bootloader, 115200 baud
#   make firmware-host         build/firmware/host/libutrf_fw.so: core + host HAL, for pytest
#   make bench-firmware        tick load and memory, appended to docs/benchmarks.md
#                              (FW_REF_ELF=other.elf: its awake cycles beside this build's)
#   make profile-firmware      where the awake cycles go under the twin's traffic, per function
#                              (FW_REF_ELF=other.elf: the CPU time of each ELF alone, side by side)
#   UTRF_BAUD=...              serial baud rate (default 1000000, exact at 16 MHz with U2X)

# FW_DIR: where this file lives (an installed utrf builds from its packaged copy into a cache).
FW_DIR       ?= firmware
FW_SRC       := $(FW_DIR)/src
FW_BUILD     := $(BUILD)/firmware
FW_ELF       := $(FW_BUILD)/utrf.elf
FW_HEX       := $(FW_BUILD)/utrf.hex
FW_HOST_LIB  := $(FW_BUILD)/host/libutrf_fw.so

ARDUINO_AVR     ?= /usr/share/arduino/hardware/arduino/avr
ARDUINO_CORE    := $(ARDUINO_AVR)/cores/arduino
ARDUINO_VARIANT := $(ARDUINO_AVR)/variants/mega

AVR_CC      ?= avr-gcc
AVR_CXX     ?= avr-g++
AVR_AR      ?= avr-ar
AVR_OBJCOPY ?= avr-objcopy
AVR_SIZE    ?= avr-size
HOST_CXX    ?= g++
AVRDUDE     ?= avrdude
# "wiring" is avrdude's stk500v2 with the DTR pulse that resets the MEGA into its bootloader
# (what the Arduino IDE uses for this board); override with AVRDUDE_PROGRAMMER=stk500v2.
AVRDUDE_PROGRAMMER ?= wiring
FLASH_BAUD  ?= 115200

UTRF_BAUD ?= 1000000
FW_TARGET_FLASH := 65536
FW_TARGET_RAM   := 3072

# The same flags platformio.ini gives PlatformIO (keep the two in step).
FW_MCU    := -mmcu=atmega2560 -DF_CPU=16000000L -DARDUINO=10819 -DARDUINO_AVR_MEGA2560 \
             -DARDUINO_ARCH_AVR
# -O2 -mstrict-X for our code: the tick is five PID loops in 16/32-bit arithmetic on an 8-bit
# CPU; measured in simavr (make bench-firmware), -Os costs it ~5 % more cycles and plain -O2
# ~10 % (-mstrict-X keeps member accesses off the X register, which has no displacement).
# Flash is plentiful. The Arduino core keeps -Os.
FW_OPT    := -O2 -mstrict-X -g -ffunction-sections -fdata-sections
ARDUINO_OPT := -Os -g -ffunction-sections -fdata-sections
FW_CXXSTD := -std=gnu++11 -fno-exceptions -fno-threadsafe-statics -fno-rtti
FW_DEFS   := -DUTRF_BAUD=$(UTRF_BAUD)UL
FW_WARN   := -Wall -Wextra
FW_INC    := -I$(ARDUINO_CORE) -I$(ARDUINO_VARIANT)

FW_OWN_SRCS := $(FW_SRC)/utrf_main.cpp $(wildcard $(FW_SRC)/core/*.cpp) \
               $(wildcard $(FW_SRC)/hal/avr/*.cpp)
FW_OWN_OBJS := $(patsubst $(FW_SRC)/%.cpp,$(FW_BUILD)/obj/%.o,$(FW_OWN_SRCS))

# The Arduino core as an archive, built by a sub-make (firmware/arduino_core.mk) that lists
# the core's sources when it runs: nothing here may read what tools/setup.sh installs while
# make parses, since on a fresh machine that is before the set-up has run.
ARDUINO_LIB  := $(FW_BUILD)/arduino-core/libarduino_core.a
ARDUINO_CORE_MAKE = $(MAKE) -s --no-print-directory -f $(FW_DIR)/arduino_core.mk \
  ARDUINO_CORE='$(ARDUINO_CORE)' OUT='$(@D)' AVR_CC='$(AVR_CC)' AVR_CXX='$(AVR_CXX)' \
  AVR_AR='$(AVR_AR)' CORE_CFLAGS='$(FW_MCU) $(ARDUINO_OPT) -std=gnu11 -w $(FW_INC)' \
  CORE_CXXFLAGS='$(FW_MCU) $(ARDUINO_OPT) $(FW_CXXSTD) -DDECIMAL_DIG=9 -w $(FW_INC)' \
  CORE_SFLAGS='$(FW_MCU) -x assembler-with-cpp $(FW_INC)'

# The git commit goes into identify's build_id; rewritten only when it changes.
FW_BUILD_ID := $(FW_BUILD)/build_id.h
FW_GIT_ID   := $(shell git rev-parse --short=8 HEAD 2>/dev/null)

.PHONY: firmware flash firmware-host bench-firmware firmware-size profile-firmware

firmware: $(FW_ELF) $(FW_HEX)
	@$(MAKE) --no-print-directory SETUP_DONE=1 firmware-size

$(FW_BUILD_ID): FORCE_FW_ID
	@mkdir -p $(@D)
	@id='$(FW_GIT_ID)'; v="0x$${id:-0}UL"; \
	 line="#define UTRF_BUILD_ID $$v"; \
	 if [ ! -f $@ ] || [ "$$(cat $@)" != "$$line" ]; then echo "$$line" > $@; fi
.PHONY: FORCE_FW_ID
FORCE_FW_ID:

$(FW_BUILD)/obj/core/dispatch.o: $(FW_BUILD_ID)
$(FW_BUILD)/obj/core/dispatch.o: FW_EXTRA := -include $(FW_BUILD_ID)

# What the objects were compiled with (the compiler's version, the flags): a change rebuilds
# them, as a changed source does (UTRF_BAUD=... on the command line, another avr-gcc).
FW_BUILT_WITH := $(FW_BUILD)/built-with.txt
$(FW_BUILT_WITH): FORCE_FW_ID | $(NEEDS_SETUP)
	@mkdir -p $(@D)
	@new="$$($(AVR_CXX) -dumpversion 2>/dev/null || echo none) $(FW_MCU) $(FW_OPT) $(FW_CXXSTD) \
	 $(FW_WARN) $(FW_DEFS) $(FW_INC) $(ARDUINO_OPT)"; \
	 if [ ! -f $@ ] || [ "$$(cat $@)" != "$$new" ]; then echo "$$new" > $@; fi

$(FW_BUILD)/obj/%.o: $(FW_SRC)/%.cpp $(FW_BUILT_WITH) | $(NEEDS_SETUP)
	@mkdir -p $(@D)
	$(AVR_CXX) -c $(FW_MCU) $(FW_OPT) $(FW_CXXSTD) $(FW_WARN) $(FW_DEFS) $(FW_INC) \
	  $(FW_EXTRA) -MMD -MP -o $@ $<

# Always asked (the sub-make knows the core's files); the archive is rewritten only when an
# object changed, so the ELF is relinked only then.
$(ARDUINO_LIB): FORCE_ARDUINO_CORE | $(NEEDS_SETUP)
	@$(ARDUINO_CORE_MAKE) $@
.PHONY: FORCE_ARDUINO_CORE
FORCE_ARDUINO_CORE:

$(FW_ELF): $(FW_OWN_OBJS) $(ARDUINO_LIB)
	$(AVR_CXX) $(FW_MCU) -Wl,--gc-sections -o $@ $(FW_OWN_OBJS) $(ARDUINO_LIB) -lm

$(FW_HEX): $(FW_ELF)
	$(AVR_OBJCOPY) -O ihex -R .eeprom $< $@

# Flash = .text + .data (the initial values of .data live in flash); RAM = .data + .bss +
# .noinit, static use (the stack comes on top). Reported as the Arduino IDE does, against the
# chip: the MEGA's program space is its 256 KB less the 8 KB bootloader, its RAM 8 KB. Then
# against the project's budgets: 64 KB flash (raised from 48 KB for the written-out finger
# ticks: firmware/README.md, Timing), 3 KB RAM (the rest is the stack's).
MEGA_FLASH := 253952
MEGA_RAM   := 8192
firmware-size: $(FW_ELF)
	@$(AVR_SIZE) -A $(FW_ELF) | awk -v tf=$(FW_TARGET_FLASH) -v tr=$(FW_TARGET_RAM) \
	  -v cf=$(MEGA_FLASH) -v cr=$(MEGA_RAM) \
	  '$$1==".text"{t=$$2} $$1==".data"{d=$$2} $$1==".bss"{b=$$2} $$1==".noinit"{n=$$2} \
	   END { f=t+d; r=d+b+n; \
	     printf "firmware: Sketch uses %d bytes (%d%%) of program storage space. ", \
	       f, int(100*f/cf); \
	     printf "Maximum is %d bytes.\n", cf; \
	     printf "firmware: Global variables use %d bytes (%d%%) of dynamic memory, ", \
	       r, int(100*r/cr); \
	     printf "leaving %d bytes for local variables. Maximum is %d bytes.\n", cr-r, cr; \
	     printf "firmware: the project'"'"'s budgets: flash %d bytes (%.1f%% of %d), ", \
	       f, 100*f/tf, tf; \
	     printf "static RAM %d bytes (data %d + bss %d + noinit %d; %.1f%% of %d)\n", \
	       r, d, b, n, 100*r/tr, tr; \
	     if (f > tf || r > tr) print "firmware: OVER THE PROJECT'"'"'S BUDGET"; \
	     if (f > cf || r > cr) print "firmware: DOES NOT FIT THE ATmega2560" }'
	@grep -h "^// Geometry\|rows, .* bytes; worst" $(FW_SRC)/generated/kinematics_table.h \
	  | sed 's|^// |kinematics table: |'

# utrf flash checks first (the port exists and opens, the bootloader signs on within 2 s) and
# fails in seconds with one line where avrdude alone would hang or retry for 30 s.
flash:
	@if [ -z "$(PORT)" ]; then echo "usage: make flash PORT=/dev/ttyACM0" >&2; exit 2; fi
	@$(MAKE) --no-print-directory setup && $(MAKE) -s --no-print-directory SETUP_DONE=1 $(FW_HEX)
	$(PY) -m utrf flash --port '$(PORT)' --hex $(FW_HEX) --avrdude $(AVRDUDE) \
	  --programmer $(AVRDUDE_PROGRAMMER) --baud $(FLASH_BAUD)

# ---- the core on the host, with the host hardware layer and a C ABI for ctypes ----------------
FW_HOST_SRCS := $(wildcard $(FW_SRC)/core/*.cpp) $(wildcard firmware/test/*.cpp)
FW_HOST_OBJS := $(patsubst %.cpp,$(FW_BUILD)/host/obj/%.o,$(FW_HOST_SRCS))
# Undefined behaviour is an error in the host build the tests run (the AVR build would have
# the same bug): UBSan, every finding fatal (-fno-sanitize-recover), so a test fails on it.
FW_HOST_UBSAN := -fsanitize=undefined -fno-sanitize-recover=all
FW_HOST_FLAGS := -std=gnu++11 -O2 -g -fPIC -fno-exceptions -fno-rtti $(FW_HOST_UBSAN) $(FW_WARN) \
                 -I$(FW_SRC)

firmware-host: $(FW_HOST_LIB)

$(FW_BUILD)/host/obj/%.o: %.cpp firmware/firmware.mk
	@mkdir -p $(@D)
	$(HOST_CXX) -c $(FW_HOST_FLAGS) -MMD -MP -o $@ $<

$(FW_HOST_LIB): $(FW_HOST_OBJS)
	$(HOST_CXX) -shared $(FW_HOST_UBSAN) -o $@ $^ -lm

# ---- checks that need the AVR: the core's arithmetic on the chip -----------------------------
FW_CHECK_ELF := $(FW_BUILD)/check/core_check.elf
FW_CHECK_SRCS := firmware/test/avr/core_check.cpp $(FW_SRC)/core/fixed.cpp \
                 $(FW_SRC)/core/pid.cpp $(FW_SRC)/core/encoder.cpp

firmware-check: $(FW_CHECK_ELF)

# One compile of several sources: -MMD keeps only the last one's dependencies, so the headers
# (the check's sequence among them) are listed here.
$(FW_CHECK_ELF): $(FW_CHECK_SRCS) firmware/test/core_check_seq.h $(wildcard $(FW_SRC)/core/*.h) \
                 $(FW_SRC)/hal/hal.h | $(NEEDS_SETUP)
	@mkdir -p $(@D)
	$(AVR_CXX) $(FW_MCU) $(FW_OPT) $(FW_CXXSTD) $(FW_WARN) -I$(FW_SRC) -Ifirmware/test -MMD -MP \
	  -Wl,--gc-sections -o $@ $(FW_CHECK_SRCS) -lm

-include $(FW_OWN_OBJS:.o=.d) $(FW_HOST_OBJS:.o=.d) $(FW_CHECK_ELF:.elf=.d)

.PHONY: firmware-check
TEST_DEPS     += firmware firmware-host firmware-check
DEMO_DEPS     += firmware
BENCH_TARGETS += bench-firmware

# The tick under traffic runs on the emulator's harness (tools/tick_bench.py over
# libutrf_sim.so; harness.mk's `emulator` builds it).
bench-firmware: firmware firmware-host firmware-check emulator
	$(PY) -m tools.bench_firmware --update docs/benchmarks.md \
	  $(if $(FW_REF_ELF),--reference-elf $(FW_REF_ELF))

# The awake cycles (not asleep in loop()'s idle sleep) of the ELF alone under the grasp hold's
# host traffic, per function, with the 100 Hz stream and the 1 kHz one (tools/fw_profile.py;
# --function NAME [--lines] for one function's instructions or source lines).
profile-firmware: firmware emulator
	$(PY) -m tools.fw_profile --elf $(FW_ELF) --seconds 5 --rate 100 --top 30
	$(PY) -m tools.fw_profile --elf $(FW_ELF) --seconds 5 --rate 1000 --top 30
	$(if $(FW_REF_ELF),$(PY) -m tools.fw_profile --elf $(FW_ELF) --versus $(FW_REF_ELF))

# ---- the PlatformIO build, reproduced with Debian's toolchain (make firmware-pio) -------------
# `pio run` cannot fetch its platform here, so this builds what it would: PlatformIO's atmelavr
# Arduino builder compiles everything at -Os with -flto (C++ also -fpermissive), defines
# ARDUINO=10808 and PLATFORMIO, archives the core with avr-gcc-ar/avr-gcc-ranlib, and links
# with -Os -flto -fuse-linker-plugin; our sources get platformio.ini's build_src_flags after
# its own (read from the file, so the two cannot drift). The core's sources are listed in the
# recipe, not when make parses (a fresh machine installs them during the same run).
# tests/firmware/test_fw_platformio.py builds it, checks it against `make firmware` and boots
# it on the emulated board.
FW_PIO_BUILD := $(FW_BUILD)/pio
FW_PIO_ELF   := $(FW_PIO_BUILD)/utrf.elf
AVR_GCC_AR     ?= avr-gcc-ar
AVR_GCC_RANLIB ?= avr-gcc-ranlib
PIO_DEFS := -mmcu=atmega2560 -DF_CPU=16000000L -DPLATFORMIO=60118 -DARDUINO_AVR_MEGA2560 \
            -DARDUINO=10808 -DARDUINO_ARCH_AVR
PIO_CC_FLAGS  := -Os -Wall -ffunction-sections -fdata-sections -flto
PIO_CXX_FLAGS := -fno-exceptions -fno-threadsafe-statics -fpermissive -std=gnu++11
# avr-gcc 5.4's float.h defines DECIMAL_DIG only for C99 (PlatformIO's avr-gcc 7.3 does not
# need this; the core's WString.cpp does).
PIO_CORE_EXTRA := -DDECIMAL_DIG=9
PIO_LINK_FLAGS := -Os -mmcu=atmega2560 -Wl,--gc-sections -flto -fuse-linker-plugin
PIO_SRC_FLAGS = $(shell sed -n '/^build_src_flags *=/,/^[a-z_]* *=/{/^ /p}' platformio.ini)

.PHONY: firmware-pio
firmware-pio: $(FW_PIO_ELF)

$(FW_PIO_ELF): $(FW_OWN_SRCS) $(wildcard $(FW_SRC)/*.h $(FW_SRC)/*/*.h $(FW_SRC)/*/*/*.h) \
               platformio.ini | $(NEEDS_SETUP)
	@rm -rf $(FW_PIO_BUILD) && mkdir -p $(FW_PIO_BUILD)/core $(FW_PIO_BUILD)/src
	@set -e; for f in $(ARDUINO_CORE)/*.c $(ARDUINO_CORE)/*.cpp $(ARDUINO_CORE)/*.S; do \
	  [ -e "$$f" ] || continue; o=$(FW_PIO_BUILD)/core/$$(basename $$f).o; \
	  case $$f in \
	    *.c) $(AVR_CC) -c -std=gnu11 -fno-fat-lto-objects $(PIO_CC_FLAGS) $(PIO_DEFS) -w \
	           $(FW_INC) -o $$o $$f ;; \
	    *.cpp) $(AVR_CXX) -c $(PIO_CXX_FLAGS) $(PIO_CC_FLAGS) $(PIO_DEFS) $(PIO_CORE_EXTRA) -w \
	           $(FW_INC) -o $$o $$f ;; \
	    *.S) $(AVR_CC) -c -x assembler-with-cpp -flto $(PIO_CC_FLAGS) $(PIO_DEFS) $(FW_INC) \
	           -o $$o $$f ;; \
	  esac; done
	@$(AVR_GCC_AR) rc $(FW_PIO_BUILD)/libFrameworkArduino.a $(FW_PIO_BUILD)/core/*.o
	@$(AVR_GCC_RANLIB) $(FW_PIO_BUILD)/libFrameworkArduino.a
	@set -e; for f in $(FW_OWN_SRCS); do \
	  o=$(FW_PIO_BUILD)/src/$$(echo $$f | tr / _).o; \
	  $(AVR_CXX) -c $(PIO_CXX_FLAGS) $(PIO_CC_FLAGS) $(PIO_DEFS) $(PIO_SRC_FLAGS) $(FW_INC) \
	    -o $$o $$f; done
	$(AVR_CXX) $(PIO_LINK_FLAGS) -o $@ $(FW_PIO_BUILD)/src/*.o \
	  -L$(FW_PIO_BUILD) -Wl,--start-group -lFrameworkArduino -lm -Wl,--end-group
	@echo "firmware-pio: $@ (PlatformIO's flags, Debian's avr-gcc)"
