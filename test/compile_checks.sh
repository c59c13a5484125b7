#!/bin/sh
# Compile checks that belong to the test suite, not only to CI: the header
# builds as C++ (a C++ renderer must be able to drop it in) warning-free,
# and the implementation exports nothing without the rrv_ prefix.
# Prints one PASS/FAIL line per check, as the C test programs do.
build=${1:-build}
mkdir -p "$build"
cxx=${CXX:-g++}
# Whether two compiler commands are the same compiler: their predefined
# macros (version, target, defaults) agree. `--version`'s first line names
# the command (cc and gcc differ there), so it is no test of that.
same_compiler() {
    [ "$(echo | "$1" -dM -E - 2>/dev/null | sort)" = "$(echo | "$2" -dM -E - 2>/dev/null | sort)" ]
}
if command -v "$cxx" >/dev/null 2>&1; then
    printf '#define RRV_IMPLEMENTATION\n#include "rrv.h"\n' > "$build/cxx_check.cpp"
    # (g++'s -fsyntax-only still instantiates and checks everything a C++
    # compile of the header could object to, at a third of the CPU time)
    if out=$("$cxx" -std=c++11 -Wall -Wextra -pedantic -Werror -I. -fsyntax-only "$build/cxx_check.cpp" 2>&1)
    then echo "PASS header_compiles_as_cxx"
    else printf '%s\n' "$out" | head -20; echo "FAIL header_compiles_as_cxx"
    fi
else
    echo "FAIL header_compiles_as_cxx ($cxx not found)"
fi
# The exported symbols are the same at any optimisation level: the object
# make test built is read when it says where it is, else an unoptimised one.
symbols_obj=${RRV_IMPL_OBJ:-}
if [ -z "$symbols_obj" ] || [ ! -f "$symbols_obj" ]; then
    symbols_obj=$build/rrv_impl_symbols.o
    ${CC:-cc} -std=c99 -O0 -c rrv_impl.c -o "$symbols_obj" 2>/dev/null || symbols_obj=
fi
if [ -n "$symbols_obj" ]; then
    others=$(nm -g --defined-only "$symbols_obj" | awk '{print $3}' | grep -v '^rrv_' || true)
    count=$(nm -g --defined-only "$symbols_obj" | awk '{print $3}' | grep -c '^rrv_')
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
# The parts a build can leave out (rrv.h, CONFIGURATION): each switch
# alone, all five together (also without stdio) and none, and RRV_RESEARCH
# (which keeps what the others' default build refuses), warning-free with
# both compilers, each linking test/switches.c, which renders a scene built
# through the API and checks that every call needing a part left out
# refuses naming its switch, and that the default build does not. The
# combinations with every stub are built by gcc at -O1, for the warnings
# that need its flow analysis (one showed only there); the rest at -O0, so
# the eighteen compiles of the implementation stay cheap. clang builds and
# runs every combination (its -O0 build costs a third of gcc's); gcc checks
# the others with its front end alone, which misses only what clang's
# reports (an unused static function: gcc warns of it when it compiles).
all_switches="-DRRV_NO_SCENE_FILE -DRRV_NO_NANOVDB -DRRV_NO_EXR -DRRV_NO_PNG -DRRV_NO_CURVED_NEE"
ok=1; count=0
for c in gcc clang; do
    command -v "$c" >/dev/null 2>&1 || { echo "  $c not found"; ok=0; continue; }
    for flags in "" -DRRV_NO_SCENE_FILE -DRRV_NO_NANOVDB -DRRV_NO_EXR -DRRV_NO_PNG -DRRV_NO_CURVED_NEE \
                 -DRRV_RESEARCH "$all_switches" "$all_switches -DRRV_NO_STDIO"; do
        count=$((count + 1))
        opt=-O0
        case "$c $flags" in
            "gcc $all_switches"*) opt=-O1 ;;
            gcc*)
                if ! out=$("$c" -std=c99 -Wall -Wextra -pedantic -Werror $flags -I. -fsyntax-only test/switches.c 2>&1)
                then printf '%s\n' "$out" | head -10; echo "  $c $flags: does not compile"; ok=0
                fi
                continue ;;
        esac
        if ! out=$("$c" -std=c99 -Wall -Wextra -pedantic -Werror $opt $flags -I. -o "$build/switches_check" test/switches.c -lm 2>&1)
        then printf '%s\n' "$out" | head -10; echo "  $c $flags: does not build"; ok=0; continue
        fi
        if ! out=$("$build/switches_check" 2>&1)
        then printf '%s\n' "$out" | head -10; echo "  $c $flags: test/switches.c failed"; ok=0
        fi
    done
done
if [ $ok = 1 ]; then echo "PASS build_switches_compile_and_refuse ($count compiles)"; else echo "FAIL build_switches_compile_and_refuse"; fi
# The implementation after the user's own system headers under strict C99
# (glibc then declares no fdopen: rrv.h must declare it itself), and the
# plain-C file I/O of RRV_NO_POSIX, with both compilers.
printf '#include <stdio.h>\n#include <stdlib.h>\n#include <string.h>\n#define RRV_IMPLEMENTATION\n#include "rrv.h"\n' > "$build/after_includes_check.c"
ok=1
for c in ${CC:-cc} gcc clang; do
    command -v "$c" >/dev/null 2>&1 || continue
    # (cc is usually gcc itself: the same compile twice would check nothing more)
    if [ "$c" != "${CC:-cc}" ] && command -v "${CC:-cc}" >/dev/null 2>&1 && same_compiler "$c" "${CC:-cc}"; then continue; fi
    # (the front end finds an undeclared fdopen; clang's also an unused
    # function, so gcc compiles only when it is the one compiler)
    only=-fsyntax-only
    case $c in gcc*|cc) command -v clang >/dev/null 2>&1 || only=-c ;; esac
    for flags in "" "-DRRV_NO_POSIX"; do
        if ! out=$("$c" -std=c99 -Wall -Wextra -pedantic -Werror $flags -I. $only "$build/after_includes_check.c" -o "$build/after_includes_check.o" 2>&1)
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
        # make test passes the object it built at -O2 -g and its compiler:
        # the same code as a -O2 compile, so that compiler links it.
        impl=rrv_impl.c
        if [ -n "${RRV_IMPL_OBJ:-}" ] && [ -f "$RRV_IMPL_OBJ" ] && same_compiler "$c" "${RRV_IMPL_CC:-cc}"; then
            impl=$RRV_IMPL_OBJ
        fi
        # The other compiler builds unoptimised: the order in which it
        # evaluates arguments is its own at any level, and without FMA in
        # the baseline x86-64 or -ffast-math the arithmetic is the same, so
        # the bytes must be too (a -O2 build cost 5 s more of CPU than the
        # -O0 build and its slower renders together).
        level=-O2
        [ "$impl" = rrv_impl.c ] && level=-O0
        $c -std=c99 $level -DRRV_THREADS=0 -o "$build/rrv_$c" main.c "$impl" -lm 2>/dev/null || ok=0
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
# Functions of main.c and rrv.h stay at most 150 lines (a command is split
# into parse, check and act steps): a body runs from a "{" alone at the
# start of a line to the next "}" alone, both files' layout of every
# function; a count of too few bodies means that layout changed and the
# check would pass vacuously.
long=""
for file in main.c:50 rrv.h:400; do
    name=${file%%:*}
    long=$long$(awk -v file="$name" -v least="${file##*:}" '/^[A-Za-z]/ {sig = $0}
            /^\{$/ {start = NR; fn = sig}
            /^\}$/ && start {n++; if (NR - start + 1 > 150) printf "  %s:%d: %s: %d lines\n", file, start, fn, NR - start + 1; start = 0}
            END {if (n < least) printf "  %s: only %d function bodies found\n", file, n}' "$name")
done
if [ -z "$long" ]; then echo "PASS functions_at_most_150_lines"
else printf '%s\n' "$long"; echo "FAIL functions_at_most_150_lines"
fi
# The header's first line names the version its macros define (one source
# of truth for the number), and README.md stays a manual: at most 400 lines.
major=$(sed -n 's/^#define RRV_VERSION_MAJOR \([0-9]*\)$/\1/p' rrv.h)
minor=$(sed -n 's/^#define RRV_VERSION_MINOR \([0-9]*\)$/\1/p' rrv.h)
patch=$(sed -n 's/^#define RRV_VERSION_PATCH \([0-9]*\)$/\1/p' rrv.h)
if [ -n "$major$minor$patch" ] && head -1 rrv.h | grep -q "^/\* rrv\.h $major\.$minor\.$patch "
then echo "PASS header_names_its_version ($major.$minor.$patch)"
else echo "  line 1 of rrv.h: $(head -1 rrv.h)"; echo "FAIL header_names_its_version (macros say $major.$minor.$patch)"
fi
lines=$(wc -l < README.md)
if [ "$lines" -le 400 ]; then echo "PASS readme_is_a_manual ($lines lines)"
else echo "  README.md has $lines lines; measurements belong in test/bench/RESULTS.md"; echo "FAIL readme_is_a_manual"
fi
# Every `$ ./rrv ...` line in a code block of README.md is run (with this
# build's rrv) and must print exactly the lines that follow it.
awk '/^ *```/ {if (inblock) print ""; inblock = !inblock; next}
     inblock { sub(/^ +/, ""); print }' README.md > "$build/readme_blocks.txt"
ok=1; count=0; cmd=""; : > "$build/readme_expected.txt"
check_readme_command() {
    [ -n "$cmd" ] || return 0
    count=$((count + 1))
    run=$(printf '%s' "$cmd" | sed "s#^\./rrv #$build/rrv #")
    if ! sh -c "$run" > "$build/readme_actual.txt" 2>&1 || ! cmp -s "$build/readme_expected.txt" "$build/readme_actual.txt"; then
        echo "  README.md: \$ $cmd"; diff "$build/readme_expected.txt" "$build/readme_actual.txt" | head -6; ok=0
    fi
}
while IFS= read -r line; do
    case $line in
        '$ '*) check_readme_command; cmd=${line#\$ }; : > "$build/readme_expected.txt" ;;
        '') check_readme_command; cmd="" ;;
        *) [ -n "$cmd" ] && printf '%s\n' "$line" >> "$build/readme_expected.txt" ;;
    esac
done < "$build/readme_blocks.txt"
check_readme_command
if [ $ok = 1 ] && [ $count -gt 0 ]; then echo "PASS readme_outputs_are_true ($count commands)"
else echo "FAIL readme_outputs_are_true"
fi
# Every ```rrv block of README.md (the recipes) is a whole scene that loads
# and renders (one sample of a 16 x 16 corner, so only cheaply).
rm -f "$build"/readme_scene_*
awk '/^```rrv$/ {on = 1; n++; f = sprintf("'"$build"'/readme_scene_%d.rrv", n); printf "" > f; next}
     /^```$/ {on = 0}
     on {print >> f}' README.md
ok=1; count=0
for scene in "$build"/readme_scene_*.rrv; do
    [ -e "$scene" ] || continue
    count=$((count + 1))
    "$build/rrv" render "$scene" -o "${scene%.rrv}.pfm" --spp 1 --crop 0 0 16 16 -q || { echo "  README.md: the scene of $scene does not render"; ok=0; }
done
if [ $ok = 1 ] && [ $count -gt 0 ]; then echo "PASS readme_scenes_render ($count scenes)"
else echo "FAIL readme_scenes_render"
fi
