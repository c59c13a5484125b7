#!/usr/bin/env bash
# Bakes a Mantaflow fire with Blender, converts one frame to NanoVDB and
# renders scenes/pyro.rrv with it: the whole path from a fluid solver to an
# rrv image, and the recipe of scenes/assets/pyro.nvdb.
#
#   scenes/tools/bake_pyro.sh [OUT_DIR]      (default build/pyro)
#
# Needs blender (Debian 12: apt-get install --no-install-recommends blender),
# python3-openvdb (run with Debian's /usr/bin/python3) and libnanovdb-tools.
# Writes OUT_DIR/cache/ (the bake), OUT_DIR/pyro.nvdb and OUT_DIR/pyro.png;
# with --install it copies pyro.nvdb to scenes/assets/. Every step that fails
# stops the script with its message.
set -euo pipefail
cd "$(dirname "$0")/../.."
install=0
if [ "${1:-}" = --install ]; then install=1; shift; fi
out=${1:-build/pyro}
resolution=48
frames=36
frame=24

for tool in blender nanovdb_convert; do
    command -v $tool >/dev/null || { echo "bake_pyro: $tool not found" >&2; exit 1; }
done
/usr/bin/python3 -c 'import pyopenvdb' || { echo "bake_pyro: /usr/bin/python3 lacks pyopenvdb (python3-openvdb)" >&2; exit 1; }
make rrv >/dev/null

rm -rf "$out/cache"
mkdir -p "$out/cache"
echo "== bake: $resolution divisions, $frames frames"
blender -b --factory-startup -P scenes/tools/bake_pyro.py -- "$(realpath "$out/cache")" $resolution $frames \
    > "$out/blender.log" 2>&1 || { tail -20 "$out/blender.log" >&2; echo "bake_pyro: blender failed" >&2; exit 1; }
grep -q "bake_all -> {'FINISHED'}" "$out/blender.log" || { tail -20 "$out/blender.log" >&2; echo "bake_pyro: bake did not finish" >&2; exit 1; }
vdb=$(printf '%s/cache/data/fluid_data_%04d.vdb' "$out" $frame)
[ -s "$vdb" ] || { echo "bake_pyro: $vdb missing" >&2; exit 1; }

# Only the grids the scene reads: flame, velocity, shadow etc. would each
# add a NanoVDB upper node (~270 KiB) to the file.
echo "== convert frame $frame"
/usr/bin/python3 - "$vdb" "$out/pyro.vdb" <<'PY'
import sys
import pyopenvdb as vdb
grids, _ = vdb.readAll(sys.argv[1])
keep = [g for g in grids if g.name in ("density", "temperature")]
if len(keep) != 2:
    sys.exit("bake_pyro: frame lacks density or temperature: %s" % [g.name for g in grids])
vdb.write(sys.argv[2], grids=keep)
PY
nanovdb_convert -f "$out/pyro.vdb" "$out/pyro.nvdb"
# The scene names assets/pyro.nvdb; a copy of it reads the new file.
sed "s|assets/pyro.nvdb|$(realpath "$out/pyro.nvdb")|" scenes/pyro.rrv > "$out/pyro.rrv"

# What the scene relies on: both grids hold data, and the temperature
# reaches a flame's (Blender: 0 ambient, about 1.5-3 in a flame).
info=$(./rrv info "$out/pyro.rrv") || { echo "bake_pyro: rrv cannot read $out/pyro.nvdb" >&2; exit 1; }
echo "$info" | grep grid
echo "$info" | awk '
    / grid "density":/     { d = $5 + 0 }
    / grid "temperature":/ { t = $5 + 0; for (i = 1; i < NF; ++i) if ($i == "values") tmax = $(i + 3) + 0 }
    END {
        if (d < 1000 || t < 1000 || tmax < 1.5 || tmax > 5) {
            printf "bake_pyro: implausible bake: %d density voxels, %d temperature voxels, max temperature %g\n", d, t, tmax > "/dev/stderr"
            exit 1
        }
    }'
if cmp -s "$out/pyro.nvdb" scenes/assets/pyro.nvdb; then
    echo "bake_pyro: the frame is byte-identical to scenes/assets/pyro.nvdb"
else
    echo "bake_pyro: the frame differs from scenes/assets/pyro.nvdb (another Blender build or CPU; not an error)"
fi

echo "== render"
./rrv render "$out/pyro.rrv" -o "$out/pyro.pfm" --png "$out/pyro.png" --spp "${PYRO_SPP:-8}" -q
[ -s "$out/pyro.png" ] || { echo "bake_pyro: no image" >&2; exit 1; }
if [ $install = 1 ]; then cp "$out/pyro.nvdb" scenes/assets/pyro.nvdb; fi
echo "bake_pyro: $out/pyro.png from frame $frame of a fresh bake"
