# rrv build. `make` builds ./rrv; `make test` builds and runs every test;
# `make test SAN=1` does the same under AddressSanitizer + UBSan (with
# CC=clang also float-to-int overflow checks, as CI runs it);
# `make THREADS=0` builds without POSIX threads; `make fuzz` builds the
# libFuzzer harnesses (clang) and `make fuzz-run` runs each for a while;
# `make bench` runs the benchmarks (`make bench-quick` a short version);
# `make refs` renders the reference images in test/ref/.
CC      ?= cc
OPT     ?= -O2 -g
WARN    := -std=c99 -Wall -Wextra -pedantic
THREADS ?= 1
SAN     ?= 0

ifeq ($(THREADS),0)
THREAD_FLAGS := -DRRV_THREADS=0
else
THREAD_FLAGS := -DRRV_THREADS=1 -pthread
endif

ifeq ($(SAN),1)
BUILD   := build-san
SANFLAGS := -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
# gcc's UBSan does not check float-to-int conversions that overflow; clang's
# does, so CI runs `make test SAN=1 CC=clang`.
ifneq ($(findstring clang,$(shell $(CC) --version 2>/dev/null)),)
SANFLAGS += -fsanitize=float-cast-overflow
endif
else
BUILD   := build
SANFLAGS :=
endif

CFLAGS_ALL = $(WARN) $(OPT) $(SANFLAGS) $(CFLAGS)
TEST_SRCS  := $(wildcard test/test_*.c)
TEST_BINS  := $(patsubst test/%.c,$(BUILD)/%,$(TEST_SRCS))
# test_lm runs a solve on a thread with a small stack
TEST_LIBS_lm := -pthread

.PHONY: all test fuzz fuzz-run bench bench-quick refs clean
all: rrv

rrv: $(BUILD)/rrv
	cp $(BUILD)/rrv rrv

$(BUILD)/rrv: main.c rrv_impl.c rrv.h $(wildcard parts/*.h) | $(BUILD)
	$(CC) $(CFLAGS_ALL) $(THREAD_FLAGS) -o $@ main.c rrv_impl.c -lm

$(BUILD)/test_%: test/test_%.c test/check.h rrv.h $(wildcard parts/*.h) $(wildcard test/*.h) | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lm $(TEST_LIBS_$*)

# test/exr_check.cpp reads rrv's EXR files with the OpenEXR library (tests
# only); test_exr runs it and fails, saying what to install, when OpenEXR is
# missing and the program could not be built.
EXR_CHECK := $(if $(shell pkg-config --exists OpenEXR 2>/dev/null && echo yes),$(BUILD)/exr_check $(BUILD)/ref_compare)
$(BUILD)/exr_check: test/exr_check.cpp test/check.h rrv.h | $(BUILD)
	$(CXX) -std=c++11 -Wall -Wextra -pedantic $(OPT) $(SANFLAGS) $(CXXFLAGS) \
	    $(shell pkg-config --cflags OpenEXR) -o $@ $< $(shell pkg-config --libs OpenEXR)
# test/ref_compare.cpp: error and consistency of renders against test/ref/
# (test_refs runs it; the benchmarks too).
$(BUILD)/ref_compare: test/ref_compare.cpp | $(BUILD)
	$(CXX) -std=c++11 -Wall -Wextra -pedantic $(OPT) $(SANFLAGS) $(CXXFLAGS) \
	    $(shell pkg-config --cflags OpenEXR) -o $@ $< $(shell pkg-config --libs OpenEXR)

$(BUILD):
	mkdir -p $(BUILD)

# The measurement programs are built (not run) by make test, so they cannot
# rot unnoticed between benchmark runs.
MEASURE_BINS := $(patsubst test/%.c,$(BUILD)/%,$(wildcard test/measure_*.c))

test: $(BUILD)/rrv $(TEST_BINS) $(EXR_CHECK) $(MEASURE_BINS)
	sh test/run_tests.sh $(BUILD) $(TEST_BINS) test/compile_checks.sh

# Every test/fuzz_*.c is a harness. UBSan findings abort (no recovery), so
# libFuzzer saves the input instead of printing and going on; clang also
# checks float-to-int conversions that overflow.
FUZZ_CC    ?= clang
FUZZ_FLAGS := -std=c99 -Wall -Wextra -g -O1 -fsanitize=fuzzer,address,undefined,float-cast-overflow \
              -fno-sanitize-recover=all
FUZZ_BINS  := $(patsubst test/%.c,build-fuzz/%,$(wildcard test/fuzz_*.c))
fuzz: $(FUZZ_BINS)
build-fuzz/fuzz_%: test/fuzz_%.c rrv.h test/fuzz_files.h
	mkdir -p build-fuzz
	$(FUZZ_CC) $(FUZZ_FLAGS) -o $@ $< -lm

# Runs every harness for FUZZ_SECONDS on scratch copies of its seeds and
# prints executions and findings (saved under build-fuzz/findings).
FUZZ_SECONDS ?= 45
fuzz-run: fuzz
	sh test/fuzz_run.sh $(FUZZ_SECONDS) $(patsubst build-fuzz/fuzz_%,%,$(FUZZ_BINS))

# References of every scene (test/ref/refs.txt: settings, spp); `make refs
# REFS="plume smoke"` renders only those.
refs: $(BUILD)/rrv $(BUILD)/ref_compare
	python3 test/bench/refs.py $(BUILD)/rrv $(BUILD)/ref_compare $(REFS)

bench: $(BUILD)/rrv $(BUILD)/ref_compare $(BUILD)/measure_grin $(BUILD)/measure_tracking
	RRV_BENCH_CC='$(CC)' RRV_BENCH_FLAGS='$(CFLAGS_ALL) $(THREAD_FLAGS)' python3 test/bench/bench.py $(BUILD)
	$(BUILD)/measure_grin

bench-quick: $(BUILD)/rrv $(BUILD)/ref_compare $(BUILD)/measure_tracking
	RRV_BENCH_CC='$(CC)' RRV_BENCH_FLAGS='$(CFLAGS_ALL) $(THREAD_FLAGS)' python3 test/bench/bench.py $(BUILD) --quick

# measure_grin: the convergence study of the refraction schemes (tables in
# README); measure_nanovdb: NanoVDB lookups against a dense grid;
# measure_tracking: collisions per second against the grid lookup alone.
$(BUILD)/measure_%: test/measure_%.c rrv.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lm

clean:
	rm -rf build build-san build-fuzz rrv
