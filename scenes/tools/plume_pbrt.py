#!/usr/bin/env python3
"""Writes scenes/plume.rrv as a pbrt-v4 scene, so that anyone with pbrt-v4
can repeat rrv's comparison with it: the same camera, light, sky and the
same density values at the same points.

  - pbrt-v4's uniformgrid puts its samples at cell centres, rrv's gridvol at
    cell corners: the grid's box is grown by half of rrv's sample spacing
    (scenes/README.md, "Corner-placed against cell-centred samples").
  - pbrt-v4 is left-handed and rrv right-handed: `Scale -1 1 1` before
    LookAt makes pbrt-v4's image the same way round as rrv's.
  - Box filter of radius 0.5, as rrv spreads each sample over its own pixel
    only (pbrt-v4's default is a Gaussian over 3x3 pixels).
  - The quad light is one-sided: its triangles are wound so that pbrt-v4's
    geometric normal is u x v, the side rrv's quad emits to.
  - The medium's boundary is a box of `interface` triangles; its grid
    values outside rrv's unit box are 0, so the box can be the grid's.

usage: plume_pbrt.py [SPP] [OUT.pbrt] [IN.vol] [EXR NAME]
       defaults: 16, plume.pbrt, scenes/assets/plume.vol, plume_pbrt.exr"""
import struct, sys


def read_gridvol(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:3] != b"VOL" or data[3] != 3:
        raise SystemExit("%s: not a version-3 gridvol file" % path)
    encoding, nx, ny, nz, channels = struct.unpack_from("<5i", data, 4)
    box = struct.unpack_from("<6f", data, 24)
    if encoding != 1 or channels != 1:
        raise SystemExit("%s: need one float32 channel" % path)
    count = nx * ny * nz
    values = struct.unpack_from("<%df" % count, data, 48)
    return (nx, ny, nz), box, values


def main():
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 16
    out = sys.argv[2] if len(sys.argv) > 2 else "plume.pbrt"
    grid = sys.argv[3] if len(sys.argv) > 3 else "scenes/assets/plume.vol"
    exr = sys.argv[4] if len(sys.argv) > 4 else "plume_pbrt.exr"
    (nx, ny, nz), box, values = read_gridvol(grid)
    lo, hi = list(box[:3]), list(box[3:])
    res = (nx, ny, nz)
    for a in range(3):
        half = 0.5 * (hi[a] - lo[a]) / (res[a] - 1)
        lo[a] -= half
        hi[a] += half
    w = []
    w.append("# scenes/plume.rrv for pbrt-v4, written by scenes/tools/plume_pbrt.py\n")
    w.append('Scale -1 1 1\n')
    w.append("LookAt 0.5 -2.1 0.55  0.5 0.5 0.45  0 0 1\n")
    w.append('Camera "perspective" "float fov" [40]\n')
    w.append('Sampler "zsobol" "integer pixelsamples" [%d]\n' % spp)
    w.append('Integrator "volpath" "integer maxdepth" [64]\n')
    w.append('PixelFilter "box"\n')
    w.append('Film "rgb" "integer xresolution" [256] "integer yresolution" [256] '
             '"string filename" "%s"\n' % exr)
    w.append("WorldBegin\n")
    w.append('LightSource "infinite" "rgb L" [0.15 0.18 0.25]\n')
    # A 0.5 x 0.5 quad at z = 2.2: origin (1.1, 0.25), u along +y, v along +x.
    o, u, v = (1.1, 0.25, 2.2), (0.0, 0.5, 0.0), (0.5, 0.0, 0.0)
    quad = [o, tuple(o[i] + u[i] for i in range(3)), tuple(o[i] + u[i] + v[i] for i in range(3)),
            tuple(o[i] + v[i] for i in range(3))]
    w.append("AttributeBegin\n")
    w.append('AreaLightSource "diffuse" "rgb L" [40 40 40]\n')
    w.append('Shape "trianglemesh" "integer indices" [0 1 2 0 2 3] "point3 P" [%s]\n'
             % " ".join("%.9g" % c for p in quad for c in p))
    w.append("AttributeEnd\n")
    w.append('MakeNamedMedium "plume" "string type" "uniformgrid" '
             '"rgb sigma_a" [0.5 0.5 0.5] "rgb sigma_s" [4.5 4.5 4.5] "float scale" [20] "float g" [0] '
             '"integer nx" [%d] "integer ny" [%d] "integer nz" [%d] ' % res)
    w.append('"point3 p0" [%.9g %.9g %.9g] "point3 p1" [%.9g %.9g %.9g]\n' % tuple(lo + hi))
    w.append('"float density" [\n')
    for i in range(0, len(values), 16):
        w.append(" ".join("%.9g" % x for x in values[i:i + 16]) + "\n")
    w.append("]\n")
    corners = [(x, y, z) for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
    faces = [0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
             2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5]
    w.append("AttributeBegin\n")
    w.append('MediumInterface "plume" ""\n')
    w.append('Material "interface"\n')
    w.append('Shape "trianglemesh" "integer indices" [%s] "point3 P" [%s]\n'
             % (" ".join(map(str, faces)), " ".join("%.9g" % c for p in corners for c in p)))
    w.append("AttributeEnd\n")
    with open(out, "w") as f:
        f.write("".join(w))


if __name__ == "__main__":
    main()
