#!/usr/bin/env python3
"""`make bench`: the measured numbers README quotes. Every timing is a
whole-process wall time, the median of several runs taken in this one
invocation, so ratios compare runs made on the same machine at the same time.

usage: bench.py RRV_BINARY [--runs N] [--quick]"""
import os, re, statistics, subprocess, sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.join(ROOT, "build", "bench")


def run(cmd):
    """Runs cmd under /usr/bin/time; returns (wall s, peak RSS KiB, stderr)."""
    p = subprocess.run(["/usr/bin/time", "-f", "@@%e %M"] + cmd, cwd=ROOT,
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        sys.exit("bench: command failed: %s\n%s" % (" ".join(cmd), p.stderr))
    m = re.search(r"@@([\d.]+) (\d+)", p.stderr)
    return float(m.group(1)), int(m.group(2)), p.stderr


def median_run(cmd, runs):
    results = [run(cmd) for _ in range(runs)]
    walls = [r[0] for r in results]
    return statistics.median(walls), max(r[1] for r in results), results[-1][2]


def rate(stderr, what):
    m = re.search(r"([\d.]+)([kM]?) %s/s" % what, stderr)
    scale = {"": 1, "k": 1e3, "M": 1e6}[m.group(2)]
    return float(m.group(1)) * scale


def scene_from_template(name, grid, cells):
    text = open(os.path.join(ROOT, "test", "bench", "smoke_grid.rrv.in")).read()
    text = text.replace("@GRID@", grid).replace("@CELLS@", str(cells))
    path = os.path.join(OUT, name)
    open(path, "w").write(text)
    return os.path.relpath(path, ROOT)


def main():
    rrv = sys.argv[1]
    runs = 3
    if "--runs" in sys.argv:
        runs = int(sys.argv[sys.argv.index("--runs") + 1])
    os.makedirs(OUT, exist_ok=True)
    for name, n, extra in (("dense64.vol", 64, []), ("sparse128.vol", 128, ["--sparse"]),
                           ("dense128.vol", 128, [])):
        path = os.path.join(OUT, name)
        if not os.path.exists(path):
            subprocess.run([sys.executable, os.path.join(ROOT, "test", "bench", "make_grid.py"), path, str(n)] + extra,
                           check=True)
    img = os.path.join(OUT, "out.pfm")
    print("runs per figure: %d (median wall time)\n" % runs)

    print("## Throughput: scenes/smoke.rrv, 480x320, 16 spp\n")
    print("| threads | wall s | samples/s | paths/s |")
    print("|---|---|---|---|")
    for threads in (1, os.cpu_count()):
        wall, _, err = median_run([rrv, "render", "scenes/smoke.rrv", "-o", img, "--spp", "16",
                                   "--threads", str(threads)], runs)
        print("| %d | %.2f | %.0f | %.0f |" % (threads, wall, rate(err, "samples"), rate(err, "paths")))

    print("\n## Majorant grid vs one global majorant, 256x256, 16 spp\n")
    print("| volume | one global majorant s | majorant grid s | speedup |")
    print("|---|---|---|---|")
    for label, grid in (("sparse 128^3 grid, 6 small dense puffs (32^3 cells)", "sparse128.vol"),
                        ("dense 64^3 smoke column (16^3 cells)", "dense64.vol")):
        walls = []
        for cells in (1, 0):
            scene = scene_from_template("%s_%d.rrv" % (grid, cells), grid, cells)
            walls.append(median_run([rrv, "render", scene, "-o", img, "-q"], runs)[0])
        print("| %s | %.2f | %.2f | %.2fx |" % (label, walls[0], walls[1], walls[0] / walls[1]))

    print("\n## Peak memory against grid bytes (1 spp render, 256x256)\n")
    print("| grid | grid bytes | peak RSS | RSS - grid |")
    print("|---|---|---|---|")
    for grid in ("dense64.vol", "dense128.vol"):
        scene = scene_from_template("mem_" + grid + ".rrv", grid, 0)
        size = os.path.getsize(os.path.join(OUT, grid)) - 48
        _, rss, _ = median_run([rrv, "render", scene, "-o", img, "--spp", "1", "-q"], 1)
        print("| %s | %.1f MiB | %.1f MiB | %.1f MiB |" % (grid, size / 2**20, rss / 1024, rss / 1024 - size / 2**20))

    fire = os.path.join(ROOT, "scenes", "fire.rrv")
    if os.path.exists(fire):
        print("\n## Refraction overhead: scenes/fire.rrv, same spp\n")
        print("| integrator | wall s | ratio to classic |")
        print("|---|---|---|")
        base = None
        for integ in ("classic", "refractive"):
            wall, _, _ = median_run([rrv, "render", "scenes/fire.rrv", "-o", img, "--integrator", integ, "-q"], runs)
            if base is None:
                base = wall
            print("| %s | %.2f | %.2fx |" % (integ, wall, wall / base))

    print("\n## Error against a converged reference: scenes/luneburg.rrv at 64x64\n")
    print("Reference: eikonal RK4, h = 0.01, 1024 spp. RMSE over pixels and channels. At 64 spp")
    print("Monte Carlo noise alone gives ~0.019: the second comb row, with another seed, shows")
    print("how much the RMSE moves with the noise alone.\n")
    lune = os.path.join(OUT, "luneburg64.rrv")
    text = open(os.path.join(ROOT, "scenes", "luneburg.rrv")).read().replace("resolution 320 320", "resolution 64 64")
    open(lune, "w").write(text)
    lune = os.path.relpath(lune, ROOT)
    ref = os.path.join(OUT, "lune_ref.pfm")
    if not os.path.exists(ref):
        run([rrv, "render", lune, "-o", ref, "--integrator", "eikonal", "--stepper", "rk4", "--step", "0.01",
             "--spp", "1024", "-q"])
    def rmse(img):
        out = subprocess.run([rrv, "diff", img, ref], cwd=ROOT, stdout=subprocess.PIPE, text=True).stdout
        return float(re.search(r"rmse: ([\d.e+-]+)", out).group(1))
    print("| integrator | settings | spp | wall s | RMSE |")
    print("|---|---|---|---|---|")
    cases = [("refractive", ["--refraction", "comb"], "comb, default tolerance 0.01", 64),
             ("refractive", ["--refraction", "comb", "--seed", "7"], "comb, default, another seed", 64),
             ("refractive", ["--refraction", "poisson"], "poisson (seed paper), tolerance 0.01", 64),
             ("eikonal", ["--stepper", "rk4", "--step", "0.2"], "RK4, h = 0.2", 64),
             ("eikonal", ["--stepper", "rk4", "--step", "0.05"], "RK4, h = 0.05", 64),
             ("eikonal", ["--stepper", "leapfrog", "--step", "0.01"], "leapfrog, h = 0.01", 64)]
    results = {}
    for integ, flags, label, spp in cases:
        img = os.path.join(OUT, "lune_%d.pfm" % len(results))
        wall, _, _ = median_run([rrv, "render", lune, "-o", img, "--integrator", integ, "--spp", str(spp), "-q"] + flags,
                                runs)
        results[label] = (wall, rmse(img))
        print("| %s | %s | %d | %.2f | %.4f |" % (integ, label, spp, wall, results[label][1]))


if __name__ == "__main__":
    main()
