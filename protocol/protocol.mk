# Protocol: the host build of the firmware's framing and generated codec, for the pytest suite.
# Included by the top-level Makefile.

PROTO_HOST_LIB  := $(BUILD)/host/libutrf_proto.so
PROTO_LIB_SRCS  := firmware/src/core/framing.cpp tests/protocol/cpp/shim.cpp
PROTO_LIB_HDRS  := firmware/src/core/framing.h firmware/src/generated/protocol_messages.h
PROTO_HOST_CXX  ?= g++
PROTO_HOST_FLAGS := -std=gnu++11 -O2 -g -Wall -Wextra -Werror -fPIC -shared

$(PROTO_HOST_LIB): $(PROTO_LIB_SRCS) $(PROTO_LIB_HDRS) protocol/protocol.mk
	@mkdir -p $(dir $@)
	$(PROTO_HOST_CXX) $(PROTO_HOST_FLAGS) -o $@ $(PROTO_LIB_SRCS)

TEST_DEPS += $(PROTO_HOST_LIB)
BENCH_TARGETS += protocol-bench

.PHONY: protocol-generate protocol-bench

# Regenerate the bindings, the README tables, the golden vectors and the fuzzers' seeds (which
# follow from the vectors) from protocol/spec.toml
# (part of `make generate`, tools/tools.mk).
protocol-generate: setup
	$(PY) -m protocol.generate
	$(PY) -m protocol.make_vectors
	$(PY) tests/fuzz/make_seeds.py

protocol-bench: setup $(PROTO_HOST_LIB)
	$(PY) -m tools.bench_protocol
