# Fuzzing, the noisy line's and the safety rules' campaigns, the soak and the mutation check
# (issue 13). Included by the top Makefile.
#
#   make fuzz            each harness for FUZZ_SECONDS (default 600) -> build/fuzz/results.json
#   make fuzz FUZZ_RUNS=1000000   each to that many executions instead
#   make fuzz-build      the libFuzzer binaries (Debian's clang, ASan + UBSan)
#   make soak            the served emulator at real time for SOAK_SECONDS (default 1800),
#                        then its section of docs/reliability.md
#   make mutants         each safety rule disabled in turn: a test must fail
#   make reliability-doc docs/reliability.md from the runs' results

FUZZ_DIR    := tests/fuzz
FUZZ_BUILD  := $(BUILD)/fuzz
FUZZ_CXX    ?= clang++
# UB aborts (no recovery), so a finding is a crash libFuzzer keeps.
FUZZ_SAN    := -fsanitize=address,undefined -fno-sanitize-recover=all
FUZZ_FLAGS  := -std=gnu++11 -g -O1 -fno-omit-frame-pointer -Wall -Wextra \
               -I$(FW_SRC) -Ifirmware/test $(FUZZ_SAN)
FUZZ_LIB_SRCS := $(wildcard $(FW_SRC)/core/*.cpp) firmware/test/hal_host.cpp firmware/test/capi.cpp
FUZZ_LIB_OBJS := $(patsubst %.cpp,$(FUZZ_BUILD)/obj/%.o,$(FUZZ_LIB_SRCS))
FUZZ_HARNESSES := raw struct
FUZZ_BINS   := $(addprefix $(FUZZ_BUILD)/fuzz_,$(FUZZ_HARNESSES))
FUZZ_SECONDS ?= 600
FUZZ_RUNS    ?=
SOAK_SECONDS ?= 1800

.PHONY: fuzz fuzz-build soak mutants reliability-doc

fuzz-build: $(FUZZ_BINS)

$(FUZZ_BUILD)/obj/%.o: %.cpp | $(NEEDS_SETUP)
	@mkdir -p $(@D)
	$(FUZZ_CXX) -c $(FUZZ_FLAGS) -fsanitize=fuzzer-no-link -MMD -MP -o $@ $<

$(FUZZ_BUILD)/fuzz_%: $(FUZZ_DIR)/fuzz_%.cpp $(FUZZ_DIR)/fuzz_board.h $(FUZZ_LIB_OBJS)
	@mkdir -p $(@D)
	$(FUZZ_CXX) $(FUZZ_FLAGS) -fsanitize=fuzzer -MMD -MP -o $@ $< $(FUZZ_LIB_OBJS) -lm

# The same harnesses built with g++ and its sanitizers, without libFuzzer: the corpus replay
# under g++'s UBSan too (tests/fuzz/replay_main.cpp).
REPLAY_CXX   ?= g++
REPLAY_FLAGS := -std=gnu++11 -g -O1 -Wall -Wextra -I$(FW_SRC) -Ifirmware/test \
                -fsanitize=address,undefined -fno-sanitize-recover=all
REPLAY_BINS  := $(addprefix $(FUZZ_BUILD)/replay_,$(FUZZ_HARNESSES))
REPLAY_LIB_OBJS := $(patsubst %.cpp,$(FUZZ_BUILD)/gobj/%.o,$(FUZZ_LIB_SRCS))

$(FUZZ_BUILD)/gobj/%.o: %.cpp
	@mkdir -p $(@D)
	$(REPLAY_CXX) -c $(REPLAY_FLAGS) -MMD -MP -o $@ $<

$(FUZZ_BUILD)/replay_%: $(FUZZ_DIR)/fuzz_%.cpp $(FUZZ_DIR)/replay_main.cpp $(FUZZ_DIR)/fuzz_board.h \
                        $(REPLAY_LIB_OBJS)
	@mkdir -p $(@D)
	$(REPLAY_CXX) $(REPLAY_FLAGS) -o $@ $< $(FUZZ_DIR)/replay_main.cpp $(REPLAY_LIB_OBJS) -lm

fuzz-build: $(REPLAY_BINS)

-include $(FUZZ_LIB_OBJS:.o=.d) $(FUZZ_BINS:=.d) $(REPLAY_LIB_OBJS:.o=.d)

fuzz: setup fuzz-build
	$(PY) $(FUZZ_DIR)/runfuzz.py $(if $(FUZZ_RUNS),--runs $(FUZZ_RUNS),--seconds $(FUZZ_SECONDS))

# The soak's section of docs/reliability.md is written whether it passed or not; make then
# fails with the soak.
soak: setup firmware
	$(PY) -m tools.soak --seconds $(SOAK_SECONDS); status=$$?; \
	$(PY) -m tools.reliability_doc --only soak && exit $$status

mutants: setup firmware firmware-host
	$(PY) tools/mutants.py

reliability-doc: setup
	$(PY) -m tools.reliability_doc

TEST_DEPS += fuzz-build
