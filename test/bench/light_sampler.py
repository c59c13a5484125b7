#!/usr/bin/env python3
"""The light samplers side by side (render lightsampler power|uniform) on
the reference scenes that have both a sky and a light shape: the mean MSE
of R + G + B against test/ref/NAME.exr (less the reference's own noise,
from NAME_var.exr), the CPU time, and efficiency 1 / (MSE x CPU).

  python3 test/bench/light_sampler.py [--seeds 4] [--rounds 2] [NAME[:SPP] ...]

Each scene renders at its test/ref size with the scene's own defaults
(integrator and all) but the light sampler, one thread, --seeds renders of
SPP samples a sampler, the samplers interleaved render by render and the
whole repeated --rounds times with new seeds. The mean column is the
image's sum over the reference's, less 1 (a bias shows there)."""
import argparse, os, re, resource, statistics, subprocess, sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cycles_compare import read_exr  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
REF = os.path.join(ROOT, "test", "ref")
RRV = os.path.join(ROOT, "rrv")
SCENES = ["smoke:16", "plume:32", "pyro:8", "fire:8", "blast:4", "haze:16", "fisheye:2", "luneburg:2"]
SAMPLERS = ("uniform", "power")


def rgb_sum(path):
    planes, _ = read_exr(path)
    return [r + g + b for r, g, b in zip(planes["R"], planes["G"], planes["B"])]


def scene_with(text, sampler):
    """The scene text with `lightsampler` added to its render statement."""
    if re.search(r"^render ", text, re.M):
        return re.sub(r"^render ", "render lightsampler %s " % sampler, text, count=1, flags=re.M)
    return text + "\nrender lightsampler %s\n" % sampler


def measure(name, spp, a, out):
    ref = rgb_sum(os.path.join(REF, name + ".exr"))
    with open(os.path.join(REF, "refs.txt")) as f:
        ref_spp = int(next(l for l in f if l.split()[:1] == [name]).split()[3])
    var = read_exr(os.path.join(REF, name + "_var.exr"))[0]["S"]
    floor = sum(var) / len(var) / ref_spp
    with open(os.path.join(REF, name + ".rrv")) as f:
        text = f.read()
    got = {v: {"mse": [], "cpu": 0.0, "mean": []} for v in SAMPLERS}
    paths = {}
    try:
        for v in SAMPLERS:
            # beside the reference's scene, so that its relative paths hold
            paths[v] = os.path.join(REF, "_light_sampler_%s.rrv" % v)
            with open(paths[v], "w") as f:
                f.write(scene_with(text, v))
        for r in range(a.rounds):
            for s in range(a.seeds):
                for v in SAMPLERS:
                    before = resource.getrusage(resource.RUSAGE_CHILDREN)
                    subprocess.run([RRV, "render", paths[v], "--spp", str(spp), "--seed", str(1000 * r + s + 100),
                                    "--threads", "1", "-o", out], check=True, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
                    after = resource.getrusage(resource.RUSAGE_CHILDREN)
                    img = rgb_sum(out)
                    g = got[v]
                    g["cpu"] += after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
                    g["mse"].append(sum((x - y) ** 2 for x, y in zip(img, ref)) / len(ref) - floor)
                    g["mean"].append(sum(img) / sum(ref) - 1)
    finally:
        for p in paths.values():
            if os.path.exists(p):
                os.remove(p)
    eff = {}
    for v in SAMPLERS:
        g = got[v]
        n = len(g["mse"])
        m = statistics.mean(g["mse"])
        eff[v] = 1 / (m * g["cpu"])
        print("| %s | %s | %d | %.3e +- %.1e | %.2f | %.3g | %+.4f +- %.4f |" %
              (name, v, spp, m, statistics.stdev(g["mse"]) / n ** 0.5, g["cpu"], eff[v], statistics.mean(g["mean"]),
               statistics.stdev(g["mean"]) / n ** 0.5), flush=True)
    print("| %s | power / uniform | | | | **%.2fx** | |" % (name, eff["power"] / eff["uniform"]), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    out = os.path.join(ROOT, "build", "light_sampler.exr")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    print("| scene | sampler | spp | MSE (less the reference's noise) | CPU s | efficiency | mean / reference - 1 |")
    print("|---|---|---|---|---|---|---|")
    for item in a.scenes:
        name, _, spp = item.partition(":")
        measure(name, int(spp or 16), a, out)


if __name__ == "__main__":
    main()
