#!/usr/bin/env python3
"""Writes the small gridvol files the parser tests and the corpus use.

Run from the repository root: python3 test/corpus/make_grids.py
The outputs are committed too; rerun this only to change them.
gridvol layout (rrv.h manual, CONVENTIONS): "VOL", version byte, int32 encoding, int32
xres yres zres, int32 channels, float32 box (xmin ymin zmin xmax ymax zmax),
then float32 samples, index ((z*yres + y)*xres + x)*channels + c, all
little endian.
"""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def header(res=(2, 2, 2), channels=1, box=(0, 0, 0, 1, 1, 1), magic=b"VOL", version=3,
           encoding=1):
    return (magic + bytes([version]) + struct.pack("<i", encoding) + struct.pack("<3i", *res)
            + struct.pack("<i", channels) + struct.pack("<6f", *box))


def samples(values):
    return struct.pack("<%df" % len(values), *values)


def write(path, data):
    with open(path, "wb") as f:
        f.write(data)


def corpus(name, data):
    write(os.path.join(HERE, name + ".vol"), data)


def main():
    eight = [i / 8.0 for i in range(8)]
    # scenes/assets/tiny.vol: a 2x2x2 density ramp, 0 at one corner to 0.875
    write(os.path.join(ROOT, "scenes", "assets", "tiny.vol"),
          header(box=(-0.5, -0.5, -0.5, 0.5, 0.5, 0.5)) + samples(eight))
    corpus("grid_truncated", header() + samples(eight)[:20])
    corpus("grid_nan", header() + samples(eight[:3] + [float("nan")] + eight[4:]))
    corpus("grid_negative", header() + samples(eight[:5] + [-0.25] + eight[6:]))
    # 100000^3 floats: only the header exists, the limit must trip first
    corpus("grid_huge", header(res=(100000, 100000, 100000)))
    corpus("grid_bad_magic", header(magic=b"VOX") + samples(eight))
    corpus("grid_bad_version", header(version=2) + samples(eight))
    corpus("grid_channels", header(channels=2) + samples(eight * 2))
    corpus("grid_empty_box", header(box=(0, 0, 0, 1, 0, 1)) + samples(eight))
    corpus("grid_small_res", header(res=(1, 2, 2)) + samples(eight[:4]))
    corpus("grid_encoding", header(encoding=2) + samples(eight))
    corpus("grid_infinite_box", header(box=(0, 0, 0, float("inf"), 1, 1)) + samples(eight))
    corpus("grid_three_channel_T", header(channels=3) + samples([300.0] * 24))
    # valid files whose values the work bounds refuse (BOUNDS in rrv.h)
    corpus("bound_dense", header() + samples([3e38] * 8))
    corpus("bound_ior_alternating", header() + samples([1e9, 0.0] * 4))
    corpus("bound_ior_nonpositive", header() + samples([-1.0, -2.0] * 4))
    # a temperature grid in kelvin whose cold corner is at 0 K
    corpus("bound_gas_cold_grid", header() + samples([0.0, 300.0, 310.0, 320.0] * 2))


if __name__ == "__main__":
    main()
