#!/usr/bin/python3
"""Writes scenes/assets/plume.vol as an OpenVDB file (one float grid named
`density`) that Blender's Cycles renders with the same values at the same
points as rrv.

rrv's gridvol sample (i, j, k) sits at (i, j, k) / 63 on the unit box.
Cycles interpolates an OpenVDB grid as if voxel ijk sat at map(ijk + 0.5)
(scenes/README.md, "Where each tool puts a grid's values"), so the map is
x / 63 - 1/126: a voxel size of 1/63 and a translation of half a voxel
toward the origin. With --corner the translation is left out, which is
OpenVDB's own placement (map(ijk)), for tools that follow it.

Every one of the 64^3 voxels is written active, zeros included: Cycles
bounds a volume by its active voxels, and the box they make, grown by
half a voxel, covers the unit box, outside of which the field is 0 anyway
(the outermost samples are 0).

Needs Debian's python3-openvdb, so run it with /usr/bin/python3.

usage: plume_vdb.py [IN.vol] [OUT.vdb] [--corner]
       defaults: scenes/assets/plume.vol, plume.vdb"""
import os, sys

import pyopenvdb

from plume_pbrt import read_gridvol  # the same .vol reader, beside this file


def main():
    args = [a for a in sys.argv[1:] if a != "--corner"]
    corner = "--corner" in sys.argv[1:]
    src = args[0] if args else os.path.join(os.path.dirname(__file__), "..", "assets", "plume.vol")
    out = args[1] if len(args) > 1 else "plume.vdb"
    (nx, ny, nz), box, values = read_gridvol(src)
    spacing = [(box[3 + a] - box[a]) / (n - 1) for a, n in enumerate((nx, ny, nz))]
    if len(set(spacing)) != 1:
        raise SystemExit("%s: needs the same sample spacing on every axis" % src)
    h = spacing[0]
    shift = 0.0 if corner else 0.5 * h
    grid = pyopenvdb.FloatGrid(0.0)
    grid.name = "density"
    grid.transform = pyopenvdb.createLinearTransform(
        [[h, 0, 0, 0], [0, h, 0, 0], [0, 0, h, 0], [box[0] - shift, box[1] - shift, box[2] - shift, 1]])
    acc = grid.getAccessor()
    # gridvol order: x fastest, then y, then z.
    n = 0
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                acc.setValueOn((i, j, k), values[n])
                n += 1
    pyopenvdb.write(out, grids=[grid])


if __name__ == "__main__":
    main()
