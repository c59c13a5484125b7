#!/bin/sh
# Compile checks that belong to the test suite, not only to CI: the header
# builds as C++ (a C++ renderer must be able to drop it in) warning-free,
# and the implementation exports nothing without the rrv_ prefix.
# Prints one PASS/FAIL line per check, as the C test programs do.
build=${1:-build}
mkdir -p "$build"
cxx=${CXX:-g++}
if command -v "$cxx" >/dev/null 2>&1; then
    printf '#define RRV_IMPLEMENTATION\n#include "rrv.h"\n' > "$build/cxx_check.cpp"
    if out=$("$cxx" -std=c++11 -Wall -Wextra -pedantic -Werror -I. -c "$build/cxx_check.cpp" -o "$build/cxx_check.o" 2>&1)
    then echo "PASS header_compiles_as_cxx"
    else printf '%s\n' "$out" | head -20; echo "FAIL header_compiles_as_cxx"
    fi
else
    echo "FAIL header_compiles_as_cxx ($cxx not found)"
fi
if ${CC:-cc} -std=c99 -O2 -c rrv_impl.c -o "$build/rrv_impl_symbols.o" 2>/dev/null; then
    others=$(nm -g --defined-only "$build/rrv_impl_symbols.o" | awk '{print $3}' | grep -v '^rrv_' || true)
    count=$(nm -g --defined-only "$build/rrv_impl_symbols.o" | awk '{print $3}' | grep -c '^rrv_')
    if [ -z "$others" ] && [ "$count" -gt 0 ]; then echo "PASS exports_only_rrv_symbols ($count symbols)"
    else echo "  exported without the rrv_ prefix: $others"; echo "FAIL exports_only_rrv_symbols"
    fi
else
    echo "FAIL exports_only_rrv_symbols (rrv_impl.c does not compile)"
fi
