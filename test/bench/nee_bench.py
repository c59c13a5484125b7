#!/usr/bin/env python3
"""Equal-time error of the next-event estimators on the lens caustic.

Renders a crop of scenes/lens_caustic.rrv (eikonal integrator, one thread)
with every `nee` mode, each for about the same CPU time, and reports the
RMSE against a converged `nee none` reference, the efficiency 1 / (time x
MSE), and the solver's statistics from the render summary. Time is user +
sys CPU time of the render process (the machine may be shared, so wall
time is printed beside it but not used).

    python3 test/bench/nee_bench.py [--seconds 20] [--ref-spp 4096] [--light 0.25]
        [--modes none,straight,shoot,aim] [--old PATH] [--old-modes shoot] [--ref-nee shoot]
        [--scene fire_caustic] [--crop 48 40 112 88] [--seed 11]

--light S replaces the scene's 1 m square light by an S m square one with
the same centre and power (radiance scaled by 1 / S^2): the smaller the
light, the sharper the caustic. Modes "none pcg" and "shoot pcg" are
those with the PCG sampler instead of the default Sobol one (the
reference keeps the default). --modes runs only the named modes; --old
also renders `shoot` (or the modes of --old-modes) with another build
(rows "..., old build"), to compare versions on one reference. --scene
takes another scene of scenes/ (its light is kept unless --light is
given, which only the lens caustic supports), --crop another crop. --seed
seeds the modes' renders (11 by default): repeated runs must take other
seeds, or they repeat the same samples and their errors are not
independent (a firefly in one is in all). --ref-nee renders the reference with
another unbiased mode: with a small light `none` converges too slowly to
serve (its RMSE is printed), and `shoot` is checked against `none` by
test/test_nee.c.

Not a test: nothing here can fail on a number. The reference is the mean of
two independent `none` renders; half their RMS difference is its own error,
printed so the RMSEs below can be read against it.
"""
import argparse
import os
import re
import resource
import struct
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RRV = os.path.join(ROOT, "rrv")
SCENE = os.path.join(ROOT, "scenes", "lens_caustic.rrv")
CROP = ["32", "24", "96", "72"]

MODES = [
    ("none", "none", ""),
    ("straight", "straight", ""),
    ("shoot", "shoot", ""),
    ("none pcg", "none", "sampler pcg"),
    ("shoot pcg", "shoot", "sampler pcg"),
    ("aim", "aim", ""),
    ("manifold chord", "manifold", "manifoldgauge chord"),
    ("manifold chord dogleg", "manifold", "manifoldgauge chord manifoldsolver dogleg"),
    ("manifold iso", "manifold", "manifoldgauge iso"),
    ("manifold chord M=1", "manifold", "manifoldgauge chord manifoldtrials 1"),
    ("manifold chord M=4", "manifold", "manifoldgauge chord manifoldtrials 4"),
    # the chain without the comb planes across which eta changes by less than
    # the drop (biased: the planes' bending is left out of the connection)
    ("manifold dogleg drop 1e-5", "manifold", "manifoldgauge chord manifoldsolver dogleg manifolddrop 0.00001"),
    ("manifold dogleg drop 1e-4", "manifold", "manifoldgauge chord manifoldsolver dogleg manifolddrop 0.0001"),
]


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        data = f.read()
    fmt = ("<" if scale < 0 else ">") + "f" * (len(data) // 4)
    vals = struct.unpack(fmt, data)
    assert kind == b"PF" and len(vals) == 3 * w * h
    return vals


def scene_with(extra, workdir, light=1.0):
    """The lens caustic with the render statement extended by `extra`, its
    1 m light replaced by a `light` m one of the same power."""
    with open(SCENE) as f:
        text = f.read()
    text = re.sub(r"^(render .*)$", lambda m: m.group(1) + " " + extra, text, count=1, flags=re.M)
    # the copy lives in a temporary folder: files the scene reads by a
    # relative path (its grids in assets/) are named from the scene's folder
    text = re.sub(r"(\s)(assets/\S+)", lambda m: m.group(1) + os.path.join(os.path.dirname(SCENE), m.group(2)), text)
    if light != 1.0:
        quad = "quad origin -0.5 3 -0.5  u 1 0 0  v 0 0 1  L 10 10 10"
        assert quad in text, "the light of scenes/lens_caustic.rrv changed"
        h, L = 0.5 * light, 10.0 / (light * light)
        text = text.replace(quad, "quad origin %.17g 3 %.17g  u %.17g 0 0  v 0 0 %.17g  L %.17g %.17g %.17g" %
                            (-h, -h, light, light, L, L, L))
    path = os.path.join(workdir, "scene_%d_%g.rrv" % (abs(hash(extra)), light))
    with open(path, "w") as f:
        f.write(text)
    return path


def render(scene, nee, spp, seed, out, rrv=RRV):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([rrv, "render", scene, "-o", out, "--spp", str(spp), "--seed", str(seed), "--nee", nee,
                        "--integrator", "eikonal", "--threads", "1", "--crop"] + CROP,
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ""


def rmse(a, b):
    n = len(a)
    return (sum((x - y) ** 2 for x, y in zip(a, b)) / n) ** 0.5


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=20.0, help="CPU seconds per mode")
    ap.add_argument("--ref-spp", type=int, default=4096, help="spp of each of the two reference renders")
    ap.add_argument("--light", type=float, default=1.0, help="side of the square light, m (power kept)")
    ap.add_argument("--modes", default="", help="comma-separated mode names to run (default: all)")
    ap.add_argument("--ref-nee", default="none", help="the unbiased mode that renders the reference")
    ap.add_argument("--old", default="", help="another rrv binary whose shoot is measured too")
    ap.add_argument("--old-modes", default="shoot", help="comma-separated modes the --old binary renders")
    ap.add_argument("--scene", default="lens_caustic", help="a scene of scenes/ (without .rrv)")
    ap.add_argument("--crop", nargs=4, default=None, help="x0 y0 x1 y1 of the crop rendered")
    ap.add_argument("--seed", type=int, default=11, help="seed of the modes' renders (not the reference's)")
    args = ap.parse_args()
    global SCENE, CROP
    SCENE = os.path.join(ROOT, "scenes", args.scene + ".rrv")
    if args.crop:
        CROP = list(args.crop)
    wanted = [m for m in args.modes.split(",") if m]
    for m in wanted:
        if m not in [name for name, _, _ in MODES]:
            sys.exit("nee_bench: unknown mode %r" % m)
    work = tempfile.mkdtemp(prefix="nee_bench_")
    plain = scene_with("", work, args.light)
    refs = []
    for seed in (1001, 1002):
        out = os.path.join(work, "ref%d.pfm" % seed)
        cpu, wall, _ = render(plain, args.ref_nee, args.ref_spp, seed, out)
        refs.append(read_pfm(out))
        print("reference %s %d spp seed %d: %.1f s cpu" % (args.ref_nee, args.ref_spp, seed, cpu), flush=True)
    ref = [(x + y) / 2 for x, y in zip(*refs)]
    ref_mse = (rmse(*refs) / 2) ** 2
    print("reference own RMSE ~ %.4f (half the RMS difference of its two halves)" % ref_mse ** 0.5)
    print()
    print("RMSE against the reference; MSE* = MSE minus the reference's own, used for the efficiency")
    print("| mode | spp | cpu s | wall s | RMSE | efficiency 1/(s MSE*) | solver |")
    print("|---|---|---|---|---|---|---|")
    runs = [(name, nee, extra, RRV) for name, nee, extra in MODES if not wanted or name in wanted]
    if args.old:
        for m in args.old_modes.split(","):
            for name, nee, extra in MODES:
                if name == m:
                    runs.append((name + ", old build", nee, extra, args.old))
    for name, nee, extra, rrv in runs:
        scene = scene_with(extra, work, args.light)
        out = os.path.join(work, "probe.pfm")
        cpu, _, _ = render(scene, nee, 1, 7, out, rrv)  # calibrate: CPU seconds per spp
        spp = max(1, int(args.seconds / max(cpu, 1e-3)))
        out = os.path.join(work, "mode.pfm")
        cpu, wall, summary = render(scene, nee, spp, args.seed, out, rrv)
        e = rmse(read_pfm(out), ref)
        solver = summary.split("; ", 1)[1] if "; " in summary else ""
        mse = max(e * e - ref_mse, 1e-30)
        print("| %s | %d | %.1f | %.1f | %.4f | %.3g | %s |" % (name, spp, cpu, wall, e, 1.0 / (cpu * mse), solver),
              flush=True)


if __name__ == "__main__":
    sys.exit(main())
