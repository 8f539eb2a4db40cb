# The Arduino core (arduino-core-avr) as a static archive. firmware.mk runs this file as a
# sub-make from a recipe, so its $(wildcard) reads the core's directory when the archive is
# built: on a fresh machine tools/setup.sh installs the core after the top-level make has
# parsed its makefiles, and a list taken at parse time would be empty.
#
# Objects are named <file>.o under OUT: the core's main.cpp never meets ours, and only what
# is referenced is linked (not its Serial, whose UART interrupts would clash with hal/avr's
# driver). Parameters (from firmware.mk): ARDUINO_CORE, OUT, AVR_CC, AVR_CXX, AVR_AR,
# CORE_CFLAGS (C), CORE_CXXFLAGS (C++), CORE_SFLAGS (assembler).

AVR_CC  ?= avr-gcc
AVR_CXX ?= avr-g++
AVR_AR  ?= avr-ar
LIB     := $(OUT)/libarduino_core.a

SRCS := $(wildcard $(ARDUINO_CORE)/*.c $(ARDUINO_CORE)/*.cpp $(ARDUINO_CORE)/*.S)
ifeq ($(strip $(SRCS)),)
$(error no Arduino core sources in $(ARDUINO_CORE): install arduino-core-avr (make setup), or set ARDUINO_AVR)
endif
OBJS := $(patsubst $(ARDUINO_CORE)/%,$(OUT)/%.o,$(SRCS))

$(LIB): $(OBJS)
	@rm -f $@
	@$(AVR_AR) rcs $@ $^
	@echo "arduino core: $(words $^) objects from $(ARDUINO_CORE)"

$(OUT)/%.c.o: $(ARDUINO_CORE)/%.c
	@mkdir -p $(@D)
	@$(AVR_CC) -c $(CORE_CFLAGS) -o $@ $<
$(OUT)/%.cpp.o: $(ARDUINO_CORE)/%.cpp
	@mkdir -p $(@D)
	@$(AVR_CXX) -c $(CORE_CXXFLAGS) -o $@ $<
$(OUT)/%.S.o: $(ARDUINO_CORE)/%.S
	@mkdir -p $(@D)
	@$(AVR_CC) -c $(CORE_SFLAGS) -o $@ $<
