#!/usr/bin/env python3
"""Writes the 48^3 temperature grid of scenes/heat_shadow.rrv
(scenes/assets/heat_shadow.vol): a gridvol file (version 3, float32, one
channel, corner-placed samples) over the medium's box, x and z in
[-1.1, 1.1], y (up) in [1.6, 3.8]. Plain python3, deterministic.

The field is hot air rising from a fire below the box: 300 K (the ambient
state) plus four compact bumps stacked along a leaning column,
  T = 300 + sum_i w_i * max(0, 1 - (d_i / R_i)^2)^3,
d_i the distance from bump i's centre, R_i its support radius. Each bump is
C2 and exactly zero beyond R_i, and no bump reaches the box's faces, so the
IOR at the faces is the ambient one: the box is no glass (rrv.h's manual,
"AMBIENT IOR"). Unlike a blob field, the gradient comes from the trilinear
grid, as it does for a simulation's temperature.

usage: make_heat_shadow.py [OUT.vol]   (default: scenes/assets/heat_shadow.vol)"""
import array, os, struct, sys

N = 48
LO = (-1.1, 1.6, -1.1)
HI = (1.1, 3.8, 1.1)
# centre, support radius, peak rise in kelvin
BUMPS = [((0.0, 2.5, 0.0), 0.66, 900.0),
         ((0.12, 2.85, 0.05), 0.48, 700.0),
         ((-0.1, 3.05, -0.04), 0.39, 600.0),
         ((0.05, 3.3, 0.02), 0.3, 500.0)]


def bumps_temperature(p, bumps):
    """300 K plus each bump's rise times (1 - d^2)^3 within its support
    (also test/bench/default_variants.py's)."""
    t = 300.0
    for (c, radius, rise) in bumps:
        d2 = sum((p[a] - c[a]) ** 2 for a in range(3)) / (radius * radius)
        if d2 < 1.0:
            t += rise * (1.0 - d2) ** 3
    return t


def temperature(p):
    return bumps_temperature(p, BUMPS)


def write_gridvol(out, n, lo, hi, field):
    """field(p) at n^3 corner-placed samples over [lo, hi], as a gridvol
    file (also test/bench/default_variants.py's writer)."""
    values = []
    for k in range(n):
        z = lo[2] + (hi[2] - lo[2]) * k / (n - 1)
        for j in range(n):
            y = lo[1] + (hi[1] - lo[1]) * j / (n - 1)
            for i in range(n):
                x = lo[0] + (hi[0] - lo[0]) * i / (n - 1)
                values.append(field((x, y, z)))
    data = array.array("f", values)
    if sys.byteorder != "little":
        data.byteswap()
    with open(out, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<i", 1) + struct.pack("<3i", n, n, n) + struct.pack("<i", 1))
        f.write(struct.pack("<6f", *(lo + hi)))
        f.write(data.tobytes())


def main():
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "scenes", "assets", "heat_shadow.vol")
    write_gridvol(out, N, LO, HI, temperature)


if __name__ == "__main__":
    main()
