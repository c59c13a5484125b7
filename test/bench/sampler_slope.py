#!/usr/bin/env python3
"""How fast a sampler's error falls with spp: the slope of log MSE against
log spp, least squares over the spp given. Each scene is rendered at the
resolution and settings of its reference (test/ref/refs.txt), one thread,
at every spp and seed; two measures of the error per spp:

  mse   mean over seeds of the MSE against test/ref/NAME.exr (`rrv diff`),
        less the reference's own noise (ref_compare --floor)
  var   the variance across seeds per pixel and channel, averaged: needs no
        reference, so its slope has no floor to take off

    python3 test/bench/sampler_slope.py BUILD/rrv BUILD/ref_compare \
        [--sampler sobol] [--tag NAME] [--scenes plume,pyro] [--seeds 11,12,13,14] [--spp 4,8,...]

Not a test: nothing here can fail on a number."""
import math, os, re, struct, subprocess, sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.join(ROOT, "build", "sampler_slope")


def arg(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def refs():
    table = {}
    for line in open(os.path.join(ROOT, "test/ref/refs.txt")):
        f = line.split()
        if f and not line.startswith("#"):
            table[f[0]] = (int(f[3]), f[6:])
    return table


def read_pfm(path):
    with open(path, "rb") as fh:
        kind = fh.readline().strip()
        w, h = map(int, fh.readline().split())
        scale = float(fh.readline())
        n = w * h * (3 if kind == b"PF" else 1)
        return struct.unpack(("<" if scale < 0 else ">") + "%df" % n, fh.read(4 * n))


def slope(xs, ys):
    lx = [math.log(x) for x in xs]
    ly = [math.log(max(y, 1e-300)) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / sum((a - mx) ** 2 for a in lx)


def main():
    rrv, compare = sys.argv[1], sys.argv[2]
    sampler = arg("--sampler", "sobol")
    tag = arg("--tag", sampler)  # names the images, so two builds can run side by side
    scenes = arg("--scenes", "plume,pyro").split(",")
    seeds = [int(s) for s in arg("--seeds", "11,12,13,14").split(",")]
    spps = [int(s) for s in arg("--spp", "4,8,16,32,64,128,256").split(",")]
    os.makedirs(OUT, exist_ok=True)
    table = refs()
    for scene in scenes:
        ref_spp, opts = table[scene]
        floor = float(subprocess.run([compare, "--floor", "test/ref/%s_var.exr" % scene, str(ref_spp)], cwd=ROOT,
                                     stdout=subprocess.PIPE, text=True, check=True).stdout.split()[1])
        rows = []
        for spp in spps:
            mses, imgs, cpu = [], [], 0.0
            for seed in seeds:
                img = os.path.join(OUT, "%s_%s_%d_%d.pfm" % (scene, tag, spp, seed))
                p = subprocess.Popen([rrv, "render", "test/ref/%s.rrv" % scene, "-o", img, "--spp", str(spp),
                                      "--seed", str(seed), "--threads", "1", "--sampler", sampler, "-q"] + opts,
                                     cwd=ROOT)
                _, status, ru = os.wait4(p.pid, 0)
                if os.waitstatus_to_exitcode(status) != 0:
                    sys.exit("render failed")
                cpu += ru.ru_utime + ru.ru_stime
                out = subprocess.run([rrv, "diff", img, "test/ref/%s.exr" % scene], cwd=ROOT,
                                     stdout=subprocess.PIPE, text=True, check=True).stdout
                mses.append(float(re.search(r"rmse:\s*(\S+)", out).group(1)) ** 2)
                imgs.append(read_pfm(img))
            k, n = len(imgs), len(imgs[0])
            var = 0.0
            for i in range(n):
                m = sum(im[i] for im in imgs) / k
                var += sum((im[i] - m) ** 2 for im in imgs) / (k - 1)
            rows.append((spp, sum(mses) / k - floor, var / n, cpu / k / spp))
        print("%s sampler %s seeds %s floor %.3e" % (scene, sampler, ",".join(map(str, seeds)), floor))
        print("| spp | MSE - floor | variance across seeds | CPU s per spp |")
        print("|---|---|---|---|")
        for spp, e, v, c in rows:
            print("| %d | %.4e | %.4e | %.4f |" % (spp, e, v, c))
        xs = [r[0] for r in rows]
        print("slope: MSE - floor %.3f, variance %.3f\n" % (slope(xs, [r[1] for r in rows]),
                                                             slope(xs, [r[2] for r in rows])))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
