#!/bin/sh
# Runs libFuzzer harnesses for a bounded time each and reports executions and
# findings: `make fuzz-run` (FUZZ_SECONDS=45), or by hand after `make fuzz`:
#     sh test/fuzz_run.sh SECONDS HARNESS...      e.g. 30 pfm obj
# Each harness fuzzes a scratch copy of its seeds (the repository is never
# written), in fork mode so that one finding does not end the run: every
# crash, sanitizer report and timeout is saved under build-fuzz/findings/
# as HARNESS-crash-*, HARNESS-timeout-*, ... and the first line of its
# report is printed, with the input itself (base64) when it is small. Exit status: 1 if a harness listed in FUZZ_GATING
# (default: all given) found something or could not run, else 0.
set -u
seconds=$1
shift
gating=${FUZZ_GATING-$*}
findings=build-fuzz/findings
rm -rf "$findings"
mkdir -p "$findings"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT INT TERM

# float32 bytes for the PFM seeds, as octal escapes for printf
le_one='\000\000\200\077'
le_half='\000\000\000\077'
le_nan='\000\000\300\177'
le_inf='\000\000\200\177'
be_one='\077\200\000\000'
be_two='\100\000\000\000'

# Scene seeds: every scene and corpus case, and each corpus case that loads
# a file again with that file attached after a NUL (test/fuzz_files.h).
scene_seeds() {
    cp scenes/*.rrv test/corpus/*.rrv "$1"/
    for f in test/corpus/*.rrv; do
        for ext in obj vol; do
            if [ -e "${f%.rrv}.$ext" ]; then
                { cat "$f"; printf '\000'; cat "${f%.rrv}.$ext"; } > "$1/$(basename "${f%.rrv}")-$ext"
            fi
        done
    done
    for asset in scenes/assets/*.obj; do
        { printf 'camera eye 0 0 5 look 0 0 0\nmesh file a.obj L 1 1 1\n\000'; cat "$asset"; } \
            > "$1/asset-$(basename "$asset")"
    done
    for asset in scenes/assets/*.vol; do
        { printf 'camera eye 0 0 5 look 0 0 0\nsphere center 0 0 -2 radius 1 L 2 2 2\n'
          printf 'medium m box -1 -1 -1 1 1 1 sigma_s 3 3 3\ndensity m grid a.vol\n\000'
          cat "$asset"; } > "$1/asset-$(basename "$asset")"
    done
}

seeds() {
    mkdir -p "$2"
    case $1 in
    scene|render) scene_seeds "$2" ;;
    grid) cp test/corpus/*.vol scenes/assets/*.vol "$2"/ ;;
    obj) cp test/corpus/*.obj scenes/assets/*.obj "$2"/ ;;
    pfm)
        printf "PF\n2 2\n-1.0\n$le_one$le_half$le_one$le_half$le_one$le_half$le_one$le_half$le_one$le_half$le_one$le_half" > "$2/color-le.pfm"
        printf "Pf\n3 1\n1.0\n$be_one$be_two$be_one" > "$2/grey-be.pfm"
        printf "PF 1 1 -1\n$le_nan$le_inf$le_half" > "$2/nonfinite.pfm"
        printf "Pf\r\n1\t2\r\n-0.5e1\r$le_one$le_half" > "$2/spaces.pfm"
        ;;
    # the files make test wrote (rrv's and OpenEXR's EXRs; real NanoVDB
    # files from OpenVDB's tools), in whichever build folder holds them
    exr) cp build*/exr_check_*.exr "$2"/ 2>/dev/null || { echo "fuzz_run.sh: run make test first (no EXR seeds)" >&2; return 1; } ;;
    nanovdb)
        cp test/corpus/nanovdb_*.nvdb "$2"/
        cp build*/nanovdb_tmp/*.nvdb "$2"/ 2>/dev/null || true
        ;;
    # 4 bytes (cpus, columns, rows, partition/time given), then the values
    # separated by NUL (test/fuzz_farm.c)
    farm)
        printf '\003\001\002\003/tmp/a b.farm\000/usr/bin/rrv\000/s/scene.rrv\000/o/out.exr\000short\0002:00:00\000--spp\00016' > "$2/plain"
        printf '\000\003\000\000/x/$(touch PWNED) `id` '"'"'q'"'"' "d"\000/r/-rrv\000/s/\377\376.rrv\000/o/\n.exr\000' > "$2/hostile"
        printf '\001\000\000\002/x/50%%\000/r\000/s\000/o\000p\0001:00\nid\000' > "$2/refused"
        ;;
    *) echo "fuzz_run.sh: no seeds for harness '$1'" >&2; return 1 ;;
    esac
}

status=0
for h in "$@"; do
    bin=build-fuzz/fuzz_$h
    work=$scratch/$h
    mkdir -p "$work/artifacts"
    gates=no
    for g in $gating; do [ "$g" = "$h" ] && gates=yes; done
    if [ ! -x "$bin" ] || ! seeds "$h" "$work/seeds"; then
        echo "fuzz_$h: cannot run"
        [ $gates = yes ] && status=1
        continue
    fi
    dict=
    case $h in scene|render) dict=-dict=test/fuzz_scene.dict ;; obj) dict=-dict=test/fuzz_obj.dict ;;
    pfm) dict=-dict=test/fuzz_pfm.dict ;; esac
    # -timeout (wall clock): an input running this long hangs (fuzz_render
    # flags runaway work itself, after 2e6 events or 10 s of CPU, so this
    # only catches a sample that never returns, with room for a busy
    # machine). -rss_limit_mb: grids are capped at 64 KiB, so honest
    # inputs stay far below it.
    timeout=20
    "$bin" $dict -fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
        -max_total_time="$seconds" -timeout=$timeout -rss_limit_mb=2048 \
        -artifact_prefix="$work/artifacts/" "$work/seeds" > "$work/log" 2>&1
    rc=$?
    execs=$(grep -o '^#[0-9]*' "$work/log" | tail -n 1 | tr -d '#')
    found=0
    for a in "$work"/artifacts/*; do
        [ -e "$a" ] || continue
        found=$((found + 1))
        cp "$a" "$findings/$h-$(basename "$a")"
    done
    echo "fuzz_$h: ${execs:-0} executions in ${seconds} s, $found findings (gates CI: $gates)"
    # with findings, fork mode exits with the status of the last one
    if [ $rc -ne 0 ] && [ $found -eq 0 ]; then
        echo "  libFuzzer exited with status $rc; the end of its log:"
        tail -n 5 "$work/log" | sed 's/^/    /'
        [ $gates = yes ] && status=1
    fi
    shown=0
    for a in "$work"/artifacts/*; do
        [ -e "$a" ] || continue
        [ $shown -lt 5 ] || { echo "  ... (more in $findings)"; break; }
        shown=$((shown + 1))
        case $(basename "$a") in
        timeout-*) why="runs past -timeout ($timeout s)" ;;
        *)
            report=$("$bin" -timeout=$timeout "$a" 2>&1)
            why=$(printf '%s\n' "$report" | grep -m 1 -E 'runtime error|ERROR: AddressSanitizer' |
                  sed 's/^.*rrv\.h/rrv.h/')
            # a harness check (abort or trap): name it by its source line
            at=$(printf '%s\n' "$report" | grep -m 1 -o "fuzz_$h\.c:[0-9]*")
            if [ -z "$why" ] && [ -n "$at" ]; then
                why="check at test/$at failed: $(sed -n "${at#*:}p" "test/fuzz_$h.c" | sed 's/^ *//')"
            fi
            ;;
        esac
        echo "  $findings/$h-$(basename "$a"): ${why:-see its report with $bin FILE}"
        # CI logs outlive the build folder: small inputs are printed whole
        if [ "$(wc -c < "$a")" -le 2048 ]; then
            echo "    base64 (decode with base64 -d): $(base64 < "$a" | tr -d '\n')"
        fi
    done
    [ $found -gt 0 ] && [ $gates = yes ] && status=1
done
exit $status
