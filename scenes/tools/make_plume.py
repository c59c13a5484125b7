#!/usr/bin/env python3
"""Writes the 64^3 density grid of scenes/plume.rrv (scenes/assets/plume.vol),
a gridvol file (version 3, float32, one channel, corner-placed samples) on the
unit box [0,1]^3 with z up. Plain python3, deterministic: the same bytes on
every machine (IEEE doubles, rounded once to float32 at the end).

The field, at sample (i, j, k) placed at p = (i, j, k) / 63:
  r(z)  = 0.12 + 0.25 z                       cone radius
  d     = distance of (x, y) from the axis (0.5, 0.5)
  base  = max(0, 1 - d / r) * min(1, 3 (1 - z))
  fbm   = sum over octaves o = 0..3 of 0.5^o * noise(4 * 2^o * p + o * 17.31)
          / (1 + 0.5 + 0.25 + 0.125)          in [-1, 1]
  v     = max(0, base * (0.6 + fbm))          clamped at 0
then v is divided by its maximum (peak 1) and the outermost layer of samples
(i, j or k equal to 0 or 63) is set to 0.

noise() is value noise: a value in [-1, 1] at each integer lattice point from
an integer hash of the point, blended trilinearly with quintic fade weights
(6t^5 - 15t^4 + 10t^3), so it is C2 across lattice cells.

usage: make_plume.py [OUT.vol]   (default: scenes/assets/plume.vol)"""
import array, math, os, struct, sys

N = 64
OCTAVES = 4
BASE_FREQUENCY = 4.0
MASK = 0xFFFFFFFF


def hash3(ix, iy, iz):
    """A 32-bit integer hash of a lattice point (multiply-xorshift rounds)."""
    h = (ix * 0x8DA6B343 + iy * 0xD8163841 + iz * 0xCB1AB31F + 0x9E3779B9) & MASK
    h ^= h >> 16
    h = (h * 0x7FEB352D) & MASK
    h ^= h >> 15
    h = (h * 0x846CA68B) & MASK
    h ^= h >> 16
    return h


def lattice(ix, iy, iz):
    return hash3(ix, iy, iz) / 2147483647.5 - 1.0


def fade(t):
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def value_noise(x, y, z):
    fx, fy, fz = math.floor(x), math.floor(y), math.floor(z)
    ix, iy, iz = int(fx), int(fy), int(fz)
    tx, ty, tz = fade(x - fx), fade(y - fy), fade(z - fz)
    c = [[[lattice(ix + a, iy + b, iz + e) for a in (0, 1)] for b in (0, 1)] for e in (0, 1)]
    def lerp(a, b, t):
        return a + (b - a) * t
    y0 = lerp(lerp(c[0][0][0], c[0][0][1], tx), lerp(c[0][1][0], c[0][1][1], tx), ty)
    y1 = lerp(lerp(c[1][0][0], c[1][0][1], tx), lerp(c[1][1][0], c[1][1][1], tx), ty)
    return lerp(y0, y1, tz)


def fbm(x, y, z):
    total, amplitude, norm = 0.0, 1.0, 0.0
    for o in range(OCTAVES):
        f = BASE_FREQUENCY * 2.0 ** o
        # The offset keeps the octaves' lattices from sharing their origin.
        total += amplitude * value_noise(f * x + o * 17.31, f * y + o * 17.31, f * z + o * 17.31)
        norm += amplitude
        amplitude *= 0.5
    return total / norm


def plume_values():
    values = [0.0] * (N * N * N)
    step = 1.0 / (N - 1)
    for k in range(N):
        z = k * step
        r = 0.12 + 0.25 * z
        height = min(1.0, 3.0 * (1.0 - z))
        for j in range(N):
            y = j * step
            for i in range(N):
                x = i * step
                d = math.hypot(x - 0.5, y - 0.5)
                base = max(0.0, 1.0 - d / r) * height
                if base > 0.0:
                    values[(k * N + j) * N + i] = max(0.0, base * (0.6 + fbm(x, y, z)))
    peak = max(values)
    for k in range(N):
        for j in range(N):
            for i in range(N):
                idx = (k * N + j) * N + i
                if i in (0, N - 1) or j in (0, N - 1) or k in (0, N - 1):
                    values[idx] = 0.0
                else:
                    values[idx] /= peak
    return values


def main():
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "scenes", "assets", "plume.vol")
    data = array.array("f", plume_values())
    if sys.byteorder != "little":
        data.byteswap()
    with open(out, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<i", 1) + struct.pack("<3i", N, N, N) + struct.pack("<i", 1))
        f.write(struct.pack("<6f", 0, 0, 0, 1, 1, 1))
        f.write(data.tobytes())


if __name__ == "__main__":
    main()
