#!/usr/bin/python3
"""Known-answer OpenVDB files for test/test_nanovdb.c, written at test time.

Run with Debian's own python3 (python3-openvdb installs pyopenvdb there):
    /usr/bin/python3 test/make_vdb.py OUTDIR
then convert with `nanovdb_convert -f OUTDIR/fields.vdb OUTDIR/fields.nvdb`
(test_nanovdb does both). Writes into OUTDIR:

  fields.vdb      grids "density" (a Gaussian blob plus a linear ramp) and
                  "temperature" (a hot core over 300), each dense over its own
                  index box with an offset origin, under one affine transform
                  with non-unit, unequal voxel sizes and a translation.
  density.vol     the same density as a gridvol (corner-placed samples on the
  temperature.vol world positions of the voxels), the answer key: voxel
                  (i0 + x, j0 + y, k0 + z) is gridvol sample (x, y, z).
  sparse.vdb      grid "sparse": background 0.5, two small blobs far apart
                  (negative coordinates too) and constant regions that
                  OpenVDB stores as tiles at every level (a root tile, a
                  lower-node tile in an upper node, leaf-sized tiles).
  sparse.bin      probes of sparse.vdb as read back by OpenVDB itself:
                  int32 count, then count x (int32 i, j, k, float32 value).
  layout.txt      index origins and dimensions of the dense grids.
"""
import os
import struct
import sys

import numpy as np
import pyopenvdb as vdb

# index -> world: world = diag(0.05, 0.04, 0.06) ijk + (0.3, -0.2, 0.1)
VOXEL = (0.05, 0.04, 0.06)
SHIFT = (0.3, -0.2, 0.1)
DENSITY_ORIGIN, DENSITY_DIMS = (-5, 3, 10), (40, 36, 28)
TEMPERATURE_ORIGIN, TEMPERATURE_DIMS = (7, -9, 0), (20, 24, 18)


def transform():
    m = [[VOXEL[0], 0, 0, 0], [0, VOXEL[1], 0, 0], [0, 0, VOXEL[2], 0],
         [SHIFT[0], SHIFT[1], SHIFT[2], 1]]
    return vdb.createLinearTransform(m)


def lattice(origin, dims):
    """World positions of the voxels of a dense block, as float64 arrays."""
    axes = [SHIFT[a] + VOXEL[a] * (origin[a] + np.arange(dims[a])) for a in range(3)]
    return np.meshgrid(*axes, indexing="ij")


def density_field():
    x, y, z = lattice(DENSITY_ORIGIN, DENSITY_DIMS)
    c = (0.6, 0.6, 1.5)
    r2 = (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2
    blob = 3.0 * np.exp(-r2 / (2 * 0.3 ** 2))
    ramp = 0.2 + 0.5 * (x - x.min()) / (x.max() - x.min()) + 0.1 * (z - z.min())
    return (blob + ramp).astype(np.float32)


def temperature_field():
    x, y, z = lattice(TEMPERATURE_ORIGIN, TEMPERATURE_DIMS)
    c = (0.75, -0.3, 0.6)
    r2 = (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2
    return (300.0 + 1200.0 * np.exp(-r2 / (2 * 0.2 ** 2)) + 40.0 * y).astype(np.float32)


def dense_grid(name, values, origin, background):
    g = vdb.FloatGrid(background)
    g.copyFromArray(values, ijk=origin)
    g.name = name
    g.transform = transform()
    g.gridClass = vdb.GridClass.FOG_VOLUME
    return g


def write_gridvol(path, values, origin):
    nx, ny, nz = values.shape
    lo = [SHIFT[a] + VOXEL[a] * origin[a] for a in range(3)]
    hi = [SHIFT[a] + VOXEL[a] * (origin[a] + values.shape[a] - 1) for a in range(3)]
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<i", 1) + struct.pack("<3i", nx, ny, nz)
                + struct.pack("<i", 1) + struct.pack("<6f", *(lo + hi)))
        # gridvol runs x fastest: index (z*ny + y)*nx + x
        f.write(np.ascontiguousarray(values.transpose(2, 1, 0)).astype("<f4").tobytes())


def sparse_grid():
    g = vdb.FloatGrid(0.5)
    g.name = "sparse"
    g.transform = vdb.createLinearTransform(voxelSize=0.1)
    rng = np.random.default_rng(12)
    g.copyFromArray(rng.uniform(1.0, 2.0, (9, 7, 5)).astype(np.float32), ijk=(-300, -40, 500))
    g.copyFromArray(rng.uniform(-1.0, 0.0, (6, 6, 6)).astype(np.float32), ijk=(1000, 2000, -3000))
    g.fill((4096, 0, 0), (8191, 4095, 4095), 3.0)     # a whole upper node: a root tile
    g.fill((0, 0, 0), (127, 127, 127), 2.0)           # a whole lower node: an upper-node tile
    g.fill((200, 200, 200), (215, 207, 207), 4.0)     # two leaves: lower-node tiles
    g.fill((-8, -8, -8), (-8, -8, -8), 7.0)           # one voxel next to the origin
    return g


def sparse_probes(g):
    acc = g.getAccessor()
    pts = set()
    for (o, d) in (((-300, -40, 500), (9, 7, 5)), ((1000, 2000, -3000), (6, 6, 6))):
        for i in range(o[0] - 2, o[0] + d[0] + 2):
            for j in range(o[1] - 2, o[1] + d[1] + 2):
                for k in range(o[2] - 2, o[2] + d[2] + 2):
                    pts.add((i, j, k))
    rng = np.random.default_rng(7)
    for lo, hi in (((4090, -5, -5), (8200, 4100, 4100)), ((-5, -5, -5), (133, 133, 133)),
                   ((195, 195, 195), (220, 212, 212)), ((-12, -12, -12), (-4, -4, -4)),
                   ((-9000, -9000, -9000), (9000, 9000, 9000))):
        for p in rng.integers(lo, hi, size=(400, 3)):
            pts.add(tuple(int(v) for v in p))
    for p in ((-8, -8, -8), (0, 0, 0), (127, 127, 127), (128, 127, 127), (4096, 0, 0),
              (8191, 4095, 4095), (8192, 0, 0), (4095, 0, 0), (-1, -1, -1),
              (2**31 - 1, 2**31 - 1, 2**31 - 1), (-2**31, -2**31, -2**31)):
        pts.add(p)
    pts = sorted(pts)
    out = bytearray(struct.pack("<i", len(pts)))
    for p in pts:
        out += struct.pack("<3if", p[0], p[1], p[2], acc.getValue(p))
    return bytes(out)


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    density, temperature = density_field(), temperature_field()
    grids = [dense_grid("density", density, DENSITY_ORIGIN, 0.0),
             dense_grid("temperature", temperature, TEMPERATURE_ORIGIN, 300.0)]
    vdb.write(os.path.join(out, "fields.vdb"), grids=grids)
    write_gridvol(os.path.join(out, "density.vol"), density, DENSITY_ORIGIN)
    write_gridvol(os.path.join(out, "temperature.vol"), temperature, TEMPERATURE_ORIGIN)
    g = sparse_grid()
    vdb.write(os.path.join(out, "sparse.vdb"), grids=[g])
    with open(os.path.join(out, "sparse.bin"), "wb") as f:
        f.write(sparse_probes(g))
    with open(os.path.join(out, "layout.txt"), "w") as f:
        f.write("density %d %d %d %d %d %d\n" % (DENSITY_ORIGIN + DENSITY_DIMS))
        f.write("temperature %d %d %d %d %d %d\n" % (TEMPERATURE_ORIGIN + TEMPERATURE_DIMS))
        f.write("voxel %.17g %.17g %.17g shift %.17g %.17g %.17g\n" % (VOXEL + SHIFT))


if __name__ == "__main__":
    main()
