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
# An embedded or sandboxed build without FILE* I/O (RRV_NO_STDIO) must stay
# warning-free too: its code paths differ, so nothing else compiles them.
printf '#define RRV_NO_STDIO\n#define RRV_IMPLEMENTATION\n#include "rrv.h"\n' > "$build/nostdio_check.c"
if out=$(${CC:-cc} -std=c99 -Wall -Wextra -pedantic -Werror -I. -c "$build/nostdio_check.c" -o "$build/nostdio_check.o" 2>&1)
then echo "PASS header_compiles_without_stdio"
else printf '%s\n' "$out" | head -20; echo "FAIL header_compiles_without_stdio"
fi
# The implementation after the user's own system headers under strict C99
# (glibc then declares no fdopen: rrv.h must declare it itself), and the
# plain-C file I/O of RRV_NO_POSIX, with both compilers.
printf '#include <stdio.h>\n#include <stdlib.h>\n#include <string.h>\n#define RRV_IMPLEMENTATION\n#include "rrv.h"\n' > "$build/after_includes_check.c"
ok=1
for c in ${CC:-cc} gcc clang; do
    command -v "$c" >/dev/null 2>&1 || continue
    for flags in "" "-DRRV_NO_POSIX"; do
        if ! out=$("$c" -std=c99 -Wall -Wextra -pedantic -Werror $flags -I. -c "$build/after_includes_check.c" -o "$build/after_includes_check.o" 2>&1)
        then printf '%s\n' "$out" | head -10; echo "  $c $flags"; ok=0
        fi
    done
done
if [ $ok = 1 ]; then echo "PASS header_compiles_after_user_includes"; else echo "FAIL header_compiles_after_user_includes"; fi
# gcc and clang once drew random numbers in different orders (two draws as
# arguments of one call): both builds must render the same bytes.
if command -v gcc >/dev/null 2>&1 && command -v clang >/dev/null 2>&1; then
    ok=1
    for c in gcc clang; do
        $c -std=c99 -O2 -DRRV_THREADS=0 -o "$build/rrv_$c" main.c rrv_impl.c -lm 2>/dev/null || ok=0
    done
    if [ $ok = 1 ]; then
        for scene in smoke fire; do
            for c in gcc clang; do
                "$build/rrv_$c" render scenes/$scene.rrv -o "$build/compiler_$c.pfm" --spp 2 --crop 120 80 152 112 -q || ok=0
            done
            cmp -s "$build/compiler_gcc.pfm" "$build/compiler_clang.pfm" || { echo "  scenes/$scene.rrv differs between gcc and clang builds"; ok=0; }
        done
    fi
    if [ $ok = 1 ]; then echo "PASS gcc_and_clang_render_alike"; else echo "FAIL gcc_and_clang_render_alike"; fi
else
    echo "FAIL gcc_and_clang_render_alike (needs both gcc and clang)"
fi
# The example on the manual's first screen, exactly as printed there: cut
# out between its rulers, built as C99 and as C++ (warning-free) and run.
awk '/^   ---- end of example/ {on = 0} on {print} /^   ---- example ----/ {on = 1}' rrv.h > "$build/manual_example.c"
ok=1
if [ "$(wc -l < "$build/manual_example.c")" -lt 20 ]; then echo "  no example between the rulers in rrv.h"; ok=0; fi
cp "$build/manual_example.c" "$build/manual_example.cpp"
${CC:-cc} -std=c99 -Wall -Wextra -pedantic -Werror -I. -o "$build/manual_example_c" "$build/manual_example.c" -lm || ok=0
if command -v "$cxx" >/dev/null 2>&1; then
    "$cxx" -std=c++11 -Wall -Wextra -pedantic -Werror -I. -o "$build/manual_example_cxx" "$build/manual_example.cpp" -lm || ok=0
else
    echo "  $cxx not found"; ok=0
fi
# 64 x 48 pixels of 12 bytes after the 19-byte header "PF\n64 48\n-1.000000\n"
# or whatever header rrv writes: the size must at least hold the pixels.
for prog in manual_example_c manual_example_cxx; do
    [ -x "$build/$prog" ] || { ok=0; continue; }
    rm -f "$build/lens.pfm"
    (cd "$build" && "./$prog") || { echo "  $prog failed"; ok=0; continue; }
    size=$(wc -c < "$build/lens.pfm" 2>/dev/null || echo 0)
    [ "$size" -gt $((64 * 48 * 12)) ] || { echo "  $prog wrote $size bytes"; ok=0; }
done
if [ $ok = 1 ]; then echo "PASS manual_example_builds_and_runs"; else echo "FAIL manual_example_builds_and_runs"; fi
