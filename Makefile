# rrv build. `make` builds ./rrv; `make test` builds and runs every test;
# `make test SAN=1` does the same under AddressSanitizer + UBSan (with
# CC=clang also float-to-int overflow checks, as CI runs it);
# `make THREADS=0` builds without POSIX threads; `make fuzz` builds the
# libFuzzer harnesses (clang) and `make fuzz-run` runs each for a while;
# `make bench` runs the benchmarks (`make bench-quick` a short version);
# `make refs` renders the reference images in test/ref/; `make pictures`
# renders README.md's pictures (scenes/pictures/, minutes each; not in CI).
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

.PHONY: all test fuzz fuzz-run bench bench-quick refs pictures clean
all: rrv

rrv: $(BUILD)/rrv
	cp $(BUILD)/rrv rrv

# The implementation is compiled once per build folder (build/, build-san/)
# into $(BUILD)/rrv_impl.o: the CLI and every test that uses only the public
# API link against it. A test that needs the internals (rrv__ functions,
# or a #define such as RRV_MALLOC or RRV_STATIC before the implementation)
# says so with its own `#define RRV_IMPLEMENTATION` and is compiled whole.
IMPL_OBJ   := $(BUILD)/rrv_impl.o
OWN_IMPL   := $(patsubst test/%.c,$(BUILD)/%,$(shell grep -l '^\#define RRV_IMPLEMENTATION' $(TEST_SRCS)))
LINKED     := $(filter-out $(OWN_IMPL),$(TEST_BINS))
TEST_HDRS  := test/check.h rrv.h $(wildcard parts/*.h) $(wildcard test/*.h)

$(IMPL_OBJ): rrv_impl.c rrv.h $(wildcard parts/*.h) | $(BUILD)
	$(CC) $(CFLAGS_ALL) -c -o $@ rrv_impl.c

$(BUILD)/rrv: main.c $(IMPL_OBJ) | $(BUILD)
	$(CC) $(CFLAGS_ALL) $(THREAD_FLAGS) -o $@ main.c $(IMPL_OBJ) -lm

$(LINKED): $(BUILD)/test_%: test/test_%.c $(TEST_HDRS) $(IMPL_OBJ) | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< $(IMPL_OBJ) -lm $(TEST_LIBS_$*)

$(OWN_IMPL): $(BUILD)/test_%: test/test_%.c $(TEST_HDRS) | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lm $(TEST_LIBS_$*)

# test/internals.c compiles the internal tests it includes as one program
# (one compile of the implementation for all of them); make test runs it
# in their place.
UNITY_SRCS := $(patsubst %,test/%,$(shell sed -n 's/^\#include "\(test_[a-z_0-9]*\.c\)"$$/\1/p' test/internals.c))
UNITY_BINS := $(patsubst test/%.c,$(BUILD)/%,$(UNITY_SRCS))
RUN_BINS   := $(filter-out $(UNITY_BINS),$(TEST_BINS)) $(BUILD)/internals
# (-pthread: test_lm's solve on a thread with a small stack is in it.)
# Without -g outside the sanitizer builds (whose reports want it): debug
# information was 6 of the 16 s of CPU this compile took, and -g does not
# change the code, so the tests run the same instructions either way.
INTERNALS_OPT := $(if $(SANFLAGS),$(OPT),$(filter-out -g,$(OPT)))
$(BUILD)/internals: test/internals.c $(UNITY_SRCS) $(TEST_HDRS) | $(BUILD)
	$(CC) $(WARN) $(INTERNALS_OPT) $(SANFLAGS) $(CFLAGS) -o $@ $< -lm -pthread

# test_eta compiles main.c in (it tests the CLI's progress estimate).
$(BUILD)/test_eta: main.c

# test/exr_check.cpp reads rrv's EXR files with the OpenEXR library (tests
# only); test_exr runs it and fails, saying what to install, when OpenEXR is
# missing and the program could not be built.
EXR_CHECK := $(if $(shell pkg-config --exists OpenEXR 2>/dev/null && echo yes),$(BUILD)/exr_check $(BUILD)/ref_compare)
# Unoptimised: OpenEXR's headers make a -O2 -g build cost 8.8 s of CPU,
# -O0 2.1 s, and test_exr's runs of it took the same time either way (4.7 s:
# the reading is OpenEXR's own, optimised, code).
$(BUILD)/exr_check: test/exr_check.cpp test/check.h rrv.h | $(BUILD)
	$(CXX) -std=c++11 -Wall -Wextra -pedantic -O0 $(SANFLAGS) $(CXXFLAGS) \
	    $(shell pkg-config --cflags OpenEXR) -o $@ $< $(shell pkg-config --libs OpenEXR)
# test/ref_compare.cpp: error and consistency of renders against test/ref/
# (test_refs runs it; the benchmarks too).
$(BUILD)/ref_compare: test/ref_compare.cpp | $(BUILD)
	$(CXX) -std=c++11 -Wall -Wextra -pedantic $(OPT) $(SANFLAGS) $(CXXFLAGS) \
	    $(shell pkg-config --cflags OpenEXR) -o $@ $< $(shell pkg-config --libs OpenEXR)

$(BUILD):
	mkdir -p $(BUILD)

# The measurement programs are built (not run) by make test, so they cannot
# rot unnoticed between benchmark runs: unoptimised (compiled and linked,
# warnings shown, at a fifth of the cost) and as one program,
# test/measures.c (one compile of the implementation for all of them),
# into $(BUILD)/O0/, while make bench uses the optimised $(BUILD)/measure_*
# it builds itself.
MEASURE_CHECKS := $(BUILD)/O0/measures
$(BUILD)/O0/measures: test/measures.c $(wildcard test/measure_*.c) $(TEST_HDRS) | $(BUILD)/O0
	@for f in $(notdir $(wildcard test/measure_*.c)); do \
	    grep -q "^#include \"$$f\"$$" test/measures.c || { echo "test/measures.c does not include $$f"; exit 1; }; done
	$(CC) $(WARN) -O0 $(SANFLAGS) $(CFLAGS) -o $@ $< -lm
$(BUILD)/O0: | $(BUILD)
	mkdir -p $@

# test/compile_checks.sh builds rrv with gcc and with clang to compare
# their renders, and lists the library's exported symbols; the compiler that
# built $(IMPL_OBJ) at the default -O2 -g (the same code as -O2) reuses it.
REUSE_IMPL := $(if $(SANFLAGS)$(CFLAGS)$(filter-out -O2 -g,$(OPT)),,RRV_IMPL_OBJ='$(IMPL_OBJ)' RRV_IMPL_CC='$(CC)')
test: $(BUILD)/rrv $(RUN_BINS) $(EXR_CHECK) $(MEASURE_CHECKS)
	$(REUSE_IMPL) sh test/run_tests.sh $(BUILD) $(RUN_BINS) test/compile_checks.sh test/readme_commands.sh

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
# fuzz_farm includes main.c for its script generator (without threads).
build-fuzz/fuzz_farm: test/fuzz_farm.c main.c rrv.h
	mkdir -p build-fuzz
	$(FUZZ_CC) $(FUZZ_FLAGS) -DRRV_THREADS=0 -o $@ $< -lm

# Runs every harness for FUZZ_SECONDS on scratch copies of its seeds and
# prints executions and findings (saved under build-fuzz/findings).
FUZZ_SECONDS ?= 45
fuzz-run: fuzz
	sh test/fuzz_run.sh $(FUZZ_SECONDS) $(patsubst build-fuzz/fuzz_%,%,$(FUZZ_BINS))

# References of every scene (test/ref/refs.txt: settings, spp); `make refs
# REFS="plume smoke"` renders only those.
refs: $(BUILD)/rrv $(BUILD)/ref_compare
	python3 test/bench/refs.py $(BUILD)/rrv $(BUILD)/ref_compare $(REFS)

# README.md's pictures, with the commands README shows (scenes/tools/pictures.sh);
# `make pictures PICTURES="fire_classic luneburg"` renders only those;
# RRV_PICTURE_FLAGS adds rrv render options (e.g. "--threads 2").
pictures: rrv
	RRV_PICTURE_FLAGS='$(RRV_PICTURE_FLAGS)' sh scenes/tools/pictures.sh $(PICTURES)

bench: $(BUILD)/rrv $(BUILD)/ref_compare $(BUILD)/measure_grin $(BUILD)/measure_tracking
	RRV_BENCH_CC='$(CC)' RRV_BENCH_FLAGS='$(CFLAGS_ALL) $(THREAD_FLAGS)' python3 test/bench/bench.py $(BUILD)
	$(BUILD)/measure_grin

bench-quick: $(BUILD)/rrv $(BUILD)/ref_compare $(BUILD)/measure_tracking
	RRV_BENCH_CC='$(CC)' RRV_BENCH_FLAGS='$(CFLAGS_ALL) $(THREAD_FLAGS)' python3 test/bench/bench.py $(BUILD) --quick

# measure_grin: the convergence study of the refraction schemes (tables in
# test/bench/RESULTS.md); measure_nanovdb: NanoVDB lookups against a dense grid;
# measure_tracking: collisions per second against the grid lookup alone.
$(BUILD)/measure_%: test/measure_%.c rrv.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lm

clean:
	rm -rf build build-san build-fuzz rrv
