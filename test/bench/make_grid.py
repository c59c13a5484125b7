#!/usr/bin/env python3
"""Writes a gridvol file (rrv.h, CONVENTIONS: 'VOL', version 3, float32, corner-placed
samples) holding a smoke-like density: a sum of Gaussian puffs along a rising,
drifting column. Used by the benchmarks; the grid is generated, not stored.

usage: make_grid.py OUT.vol N [--sparse]
  N         samples per axis
  --sparse  a few small dense puffs in a mostly empty box (where a majorant
            grid pays off most)"""
import array, math, random, struct, sys

def main():
    out, n = sys.argv[1], int(sys.argv[2])
    sparse = "--sparse" in sys.argv[3:]
    rng = random.Random(7)
    puffs = []
    count = 6 if sparse else 40
    for i in range(count):
        t = i / max(count - 1, 1)
        if sparse:
            c = (rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8))
            puffs.append((c, 0.06, 40.0))
        else:
            c = (0.25 * math.sin(5 * t) + rng.uniform(-0.1, 0.1), -0.8 + 1.6 * t, 0.2 * math.cos(4 * t))
            puffs.append((c, 0.12 + 0.2 * t, 3.0 * (1.0 - 0.6 * t)))
    # Each puff only touches the samples within 4 radii of its centre.
    values = array.array("f", bytes(4 * n * n * n))
    step = 2.0 / (n - 1)
    for (c, r, w) in puffs:
        lo = [max(0, int(math.floor((c[k] - 4 * r + 1) / step))) for k in range(3)]
        hi = [min(n - 1, int(math.ceil((c[k] + 4 * r + 1) / step))) for k in range(3)]
        inv = 0.5 / (r * r)
        for z in range(lo[2], hi[2] + 1):
            dz2 = (-1 + z * step - c[2]) ** 2
            for y in range(lo[1], hi[1] + 1):
                dyz2 = dz2 + (-1 + y * step - c[1]) ** 2
                base = (z * n + y) * n
                for x in range(lo[0], hi[0] + 1):
                    d2 = dyz2 + (-1 + x * step - c[0]) ** 2
                    values[base + x] += w * math.exp(-d2 * inv)
    if sys.byteorder != "little":
        values.byteswap()
    data = values.tobytes()
    with open(out, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<i", 1) + struct.pack("<3i", n, n, n) + struct.pack("<i", 1))
        f.write(struct.pack("<6f", -1, -1, -1, 1, 1, 1))
        f.write(data)

if __name__ == "__main__":
    main()
