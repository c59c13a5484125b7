#!/bin/sh
# README.md's shell commands, run as a reader would run them, so that none
# can drift from what rrv does (the `$` examples with outputs and the
# ```rrv recipes are checked by compile_checks.sh):
#   - every `./rrv render` line (the default scene, each picture), at 1 spp
#     on an 8 x 8 crop, its outputs moved into a scratch folder;
#   - the pictures' lines are exactly those scenes/tools/pictures.sh runs;
#   - the farm block, as written, in a folder whose scene.rrv is the default
#     scene at 24 x 16 and 256 spp: the merge must equal one render, byte
#     for byte.
# Not run: `make test` (this is part of it) and GNU parallel over ssh
# (it needs hosts; test_farm.c runs the same tiles).
# Usage: sh test/readme_commands.sh BUILD_DIR (from the repository root).
build=$1
rrv=$(pwd)/$build/rrv
work=$build/readme_commands
rm -rf "$work"; mkdir -p "$work/farm"
awk '/^```sh/ {on = 1; next} /^```/ {on = 0} on' README.md > "$work/blocks.txt"

ok=1; runs=0
sed -n 's/^\(make && \)\{0,1\}\(\.\/rrv render [^#]*\).*/\2/p' "$work/blocks.txt" | sed 's/ *$//' > "$work/renders.txt"
while read -r line; do
    # -o and --png into the scratch folder, then the small render
    args=$(printf '%s\n' "${line#./rrv }" | awk -v dir="$work" '{
        for (i = 1; i <= NF; ++i) {
            if (($i == "-o" || $i == "--png") && i < NF) { n = split($(i + 1), part, "/"); $(i + 1) = dir "/" part[n] }
        }
        print }')
    # shellcheck disable=SC2086
    if ! "$rrv" $args --spp 1 --crop 0 0 8 8 -q >"$work/out.txt" 2>&1; then
        echo "  README.md: $line"; sed 's/^/    /' "$work/out.txt"; ok=0
    fi
    runs=$((runs + 1))
done < "$work/renders.txt"
[ "$runs" -ge 9 ] || { echo "  README.md: only $runs ./rrv render lines found"; ok=0; }

grep '^\./rrv render scenes/pictures/' "$work/renders.txt" > "$work/readme_pictures.txt"
RRV=true sh scenes/tools/pictures.sh | sed 's/^true /.\/rrv /; s/ *$//' > "$work/script_pictures.txt"
if ! diff "$work/script_pictures.txt" "$work/readme_pictures.txt" > "$work/diff.txt"; then
    echo "  README.md's picture commands differ from scenes/tools/pictures.sh's:"; head -8 "$work/diff.txt"; ok=0
fi

sed 's/resolution 480 320/resolution 24 16/; s/spp 32 /spp 256 /' scenes/smoke.rrv > "$work/farm/scene.rrv"
grep '^rrv \(render\|merge\) ' "$work/blocks.txt" | grep -v '\$PWD' | sed 's/  *#.*//' > "$work/farm/commands.txt"
[ "$(wc -l < "$work/farm/commands.txt")" -ge 4 ] || { echo "  README.md: no farm block found"; ok=0; }
(
    cd "$work/farm" || exit 1
    rrv() { "$rrv" "$@"; }
    while read -r line; do
        eval "$line" >/dev/null 2>"err.txt" ||
            { echo "  README.md: $line"; sed 's/^/    /' err.txt; exit 1; }
    done < commands.txt
    "$rrv" render scene.rrv -o one.exr -q && cmp -s out.exr one.exr ||
        { echo "  README.md's farm block: out.exr differs from one render"; exit 1; }
) || ok=0

if [ $ok = 1 ]; then echo "PASS readme_commands_run ($runs renders, the farm block)"
else echo "FAIL readme_commands_run"; fi
