#!/usr/bin/env python3
"""Refracting media under thin smoke: which of the comb with aimed shadow
rays (`--integrator refractive --nee aim`) and the eikonal march with
shooting (`--integrator eikonal --nee shoot`) renders a scene more
efficiently, and what the default picks (test/bench/RESULTS.md, "Heat
shadows in thin fog"). From the repository root after `make`:

    python3 test/bench/thin_smoke.py ./rrv [--spp 64] [--seeds 6] [--only NAME,...]

Each variant is a scene of scenes/ with its smoke or fog changed (below),
rendered small with one thread at --spp by every mode and --seeds seeds
(100, 101, ...; pcg, so the seeds are independent), the modes taking
turns. Efficiency is 1 / (median CPU s x the pixel variance across the
seeds), which needs no reference. The image means (+- their standard
error across seeds) must agree between modes; where one mode's light
arrives as rare fireflies (aimed rays missing a small light's caustic)
its variance is underestimated at low spp and its mean comes out low, so
the spp must be high enough for the means to agree before its efficiency
counts.
"""
import argparse, os, re, resource, statistics, subprocess, sys, tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nee_bench import read_pfm  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SCENES = os.path.join(ROOT, "scenes")
MODES = {
    "refractive+aim": ["--integrator", "refractive", "--nee", "aim"],
    "eikonal+shoot": ["--integrator", "eikonal", "--nee", "shoot"],
}


def variant(base, edits):
    text = open(os.path.join(SCENES, base)).read()
    text = re.sub(r"assets/", SCENES + "/assets/", text)
    text = re.sub(r"\bintegrator \w+", "", text)
    for old, new in edits:
        if old is None:
            text += "\n" + new + "\n"
            continue
        if old not in text:
            sys.exit("%s: %r not found" % (base, old))
        text = text.replace(old, new)
    return text


HAZE_SMOKE = "sigma_a 0.5 0.5 0.5  sigma_s 4.5 4.5 4.5  scale 20"
FLAME = "sigma_a 4 4 4  sigma_s 0.2 0.2 0.2"
FOG = "medium fog box -4 0 -4 4 4.5 4 sigma_a 0 0 0 sigma_s {s} {s} {s}\ndensity fog constant 1"
VARIANTS = [
    # a heat shadow (a temperature grid under a 0.25 m light) in fog of three densities
    ("heat_shadow_fog_0.05", "heat_shadow.rrv", [("resolution 160 120", "resolution 64 48"), (None, FOG.format(s=0.05))]),
    ("heat_shadow_fog_0.25", "heat_shadow.rrv", [("resolution 160 120", "resolution 64 48"), (None, FOG.format(s=0.25))]),
    ("heat_shadow_fog_1", "heat_shadow.rrv", [("resolution 160 120", "resolution 64 48"), (None, FOG.format(s=1))]),
    # the haze with its smoke 1/100, 3/100, 1/10 and 1 times as dense
    ("haze_smoke_0.2", "haze.rrv", [("resolution 256 256", "resolution 64 64"), (HAZE_SMOKE, HAZE_SMOKE.replace("scale 20", "scale 0.2"))]),
    ("haze_smoke_0.6", "haze.rrv", [("resolution 256 256", "resolution 64 64"), (HAZE_SMOKE, HAZE_SMOKE.replace("scale 20", "scale 0.6"))]),
    ("haze_smoke_2", "haze.rrv", [("resolution 256 256", "resolution 64 64"), (HAZE_SMOKE, HAZE_SMOKE.replace("scale 20", "scale 2"))]),
    ("haze", "haze.rrv", [("resolution 256 256", "resolution 64 64")]),
    # the fire with a flame ten times thinner, at its own iorscale 500 and at 100
    ("fire_thin_flame", "fire.rrv", [("resolution 320 240", "resolution 80 60"), (FLAME, "sigma_a 0.4 0.4 0.4  sigma_s 0.02 0.02 0.02")]),
    ("fire_thin_flame_weak", "fire.rrv", [("resolution 320 240", "resolution 80 60"), (FLAME, "sigma_a 0.4 0.4 0.4  sigma_s 0.02 0.02 0.02"),
                                          ("iorscale 500", "iorscale 100"), ("ambient ior 1.146", "ambient ior 1.0292")]),
]


def render(rrv, scene, out, spp, seed, flags):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.check_call([rrv, "render", scene, "-o", out, "-q", "--threads", "1", "--spp", str(spp),
                           "--seed", str(seed), "--sampler", "pcg"] + flags)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, read_pfm(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("rrv")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--only", default="")
    a = ap.parse_args()
    only = set(a.only.split(",")) if a.only else None
    tmp = tempfile.mkdtemp(prefix="rrv_thin_smoke_")
    print("| scene | default picks | mode | CPU s | pixel variance | mean +- se | efficiency |")
    print("|---|---|---|---|---|---|---|")
    for name, base, edits in VARIANTS:
        if only and name not in only:
            continue
        scene = os.path.join(tmp, name + ".rrv")
        open(scene, "w").write(variant(base, edits))
        info = subprocess.run([a.rrv, "info", scene], capture_output=True, text=True, check=True).stdout
        pick = re.search(r"^integrator: (\w+)", info, re.M).group(1)
        runs = {m: ([], []) for m in MODES}
        for s in range(a.seeds):
            for m, flags in MODES.items():
                t, img = render(a.rrv, scene, os.path.join(tmp, "out.pfm"), a.spp, 100 + s, flags)
                runs[m][0].append(t)
                runs[m][1].append(img)
        for m in MODES:
            times, imgs = runs[m]
            n, size = len(imgs), len(imgs[0])
            var = sum(statistics.variance([im[i] for im in imgs]) for i in range(size)) / size
            means = [sum(im) / size for im in imgs]
            cpu = statistics.median(times)
            eff = 1.0 / (cpu * var) if var > 0 else float("inf")
            print("| %s | %s | %s | %.2f | %.3e | %.5f +- %.5f | %.3g |" % (
                name, pick, m, cpu, var, statistics.mean(means), statistics.stdev(means) / n ** 0.5, eff))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
