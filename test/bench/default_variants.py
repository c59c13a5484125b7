#!/usr/bin/env python3
"""The default nee against shoot on heat shadows it was not tuned on.

Writes random variants of scenes/heat_shadow.rrv (80 x 60): a temperature
grid of 2 to 6 compact bumps over 300 K (as scenes/tools/make_heat_shadow.py
writes, bump centres, sizes and peak rises drawn per variant; 32^3 to 64^3;
some with noise on the hot cells), `iorscale` 60 to 200, a quad or
triangle light 0.1 to 0.5 m of the same power. Renders each with no `nee`
key (the default: chains where the bend bound allows, else shoot) and
with `--nee shoot`, one thread, several seeds, and prints each mode's CPU
time, pixel variance across the seeds, largest pixel and 99.9th
percentile (fireflies), the least share of converged solves, and the
efficiency ratio 1 / (CPU x variance) of the default over shoot.

    python3 test/bench/default_variants.py BUILD/rrv [--variants 0,1,2,3,4,5] [--seeds 4] [--spp 8]

Not a test: nothing here can fail on a number."""
import os, random, re, subprocess, sys, tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "scenes", "tools"))
import make_heat_shadow  # noqa: E402  (its gridvol writer)
from nee_bench import read_pfm  # noqa: E402


def arg(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def write_grid(path, n, lo, hi, bumps, noise, seed):
    rng = random.Random(seed)

    def temperature(p):
        t = make_heat_shadow.bumps_temperature(p, bumps)
        if noise and t > 300.5:
            t += noise * (rng.random() - 0.5) * (t - 300) / 900
        return t
    make_heat_shadow.write_gridvol(path, n, lo, hi, temperature)


def variant(v, folder):
    r = random.Random(100 + v)
    bumps = [((r.uniform(-0.25, 0.25), r.uniform(2.2, 3.4), r.uniform(-0.25, 0.25)), r.uniform(0.2, 0.65),
              r.uniform(300, 1400)) for _ in range(r.randint(2, 6))]
    n = r.choice([32, 48, 64])
    noise = r.choice([0.0, 0.0, 60.0])
    write_grid(os.path.join(folder, "g%d.vol" % v), n, (-1.1, 1.6, -1.1), (1.1, 3.8, 1.1), bumps, noise, v)
    scale = r.choice([60, 100, 150, 200])
    side = r.choice([0.1, 0.25, 0.5])
    if r.choice(["quad", "quad", "tri"]) == "quad":
        light = "quad origin %g 4.2 %g  u %g 0 0  v 0 0 %g  L %g %g %g" % ((-side / 2, -side / 2, side, side) +
                                                                         (37.5 / side / side,) * 3)
        kind = "quad"
    else:
        light = "triangle p0 %g 4.2 %g p1 %g 4.2 %g p2 %g 4.2 %g L %g %g %g" % (
            (-side / 2, -side / 2, side / 2, -side / 2, 0, side / 2) + (75 / side / side,) * 3)
        kind = "triangle"
    text = ("camera eye 0 1.2 -2.6  look 0 0 0.2  up 0 1 0  fov 40  resolution 80 60\n"
            "render spp 16  maxdepth 1  seed 1\n"
            "material white diffuse albedo 0.8 0.8 0.8\n"
            "quad origin -4 0 -4  u 8 0 0  v 0 0 8  material white\n%s\n"
            "medium plume box -1.1 1.6 -1.1 1.1 3.8 1.1  sigma_a 0 0 0  sigma_s 0 0 0\n"
            "temperature plume grid g%d.vol blackbody off\n"
            "ior plume gas iorscale %d\n") % (light, v, scale)
    scene = os.path.join(folder, "s%d.rrv" % v)
    with open(scene, "w") as f:
        f.write(text)
    return scene, "%d bumps, %d^3%s, iorscale %d, %s %g m" % (len(bumps), n, ", noise" if noise else "", scale,
                                                              kind, side)


def pixels(path):
    """A render's pixels, each the mean of its three channels."""
    v = read_pfm(path)
    return [sum(v[3 * i:3 * i + 3]) / 3 for i in range(len(v) // 3)]


def render(rrv, scene, extra, seed, spp, out):
    p = subprocess.Popen([rrv, "render", scene, "-o", out, "--spp", str(spp), "--seed", str(seed), "--threads", "1"] +
                         extra, stderr=subprocess.PIPE)
    err = p.stderr.read().decode()
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit("render failed: %s\n%s" % (scene, err))
    m = re.search(r"([\d.]+)% converged", err)
    return ru.ru_utime + ru.ru_stime, float(m.group(1)) if m else 100.0


def seed_runs(rrv, scene, extra, seeds, spp, folder, tag):
    """Renders of scene at each seed: the mean CPU s, the pixel variance
    across the seeds (averaged over the pixels), the largest pixel and the
    99.9th percentile of all, the least share of converged solves and the
    mean pixel."""
    cpu, images, converged = 0.0, [], 100.0
    for k in seeds:
        out = os.path.join(folder, "%s_%d.pfm" % (tag, k))
        c, conv = render(rrv, scene, extra, k, spp, out)
        cpu += c
        converged = min(converged, conv)
        images.append(pixels(out))
    n, m = len(images[0]), len(images)
    means = [sum(im[i] for im in images) / m for i in range(n)]
    var = sum(sum((im[i] - means[i]) ** 2 for im in images) / (m - 1) for i in range(n)) / n
    values = sorted(x for im in images for x in im)
    return cpu / m, var, values[-1], values[int(0.999 * len(values))], converged, sum(means) / n


def main():
    rrv = os.path.abspath(sys.argv[1])
    seeds = range(200, 200 + int(arg("--seeds", "4")))
    spp = int(arg("--spp", "8"))
    folder = tempfile.mkdtemp(prefix="default_variants_")
    print("| variant | default nee | default: CPU s, variance, max, p99.9, converged | shoot: the same "
          "| default over shoot | mean, default over shoot |")
    print("|---|---|---|---|---|---|")
    for v in map(int, arg("--variants", "0,1,2,3,4,5").split(",")):
        scene, what = variant(v, folder)
        info = subprocess.run([rrv, "info", scene], stdout=subprocess.PIPE, text=True).stdout
        chosen = re.search(r"nee: (\w+)", info)
        b = seed_runs(rrv, scene, [], seeds, spp, folder, "%d_default" % v)
        a = seed_runs(rrv, scene, ["--nee", "shoot"], seeds, spp, folder, "%d_shoot" % v)
        cell = lambda r: "%.2f, %.3g, %.2f, %.2f, %.1f %%" % r[:5]
        print("| %d: %s | %s | %s | %s | %.2fx | %+.2f %% |" % (v, what, chosen.group(1) if chosen else "?", cell(b),
                                                               cell(a), (a[0] * a[1]) / (b[0] * b[1]),
                                                               100 * (b[5] / a[5] - 1)), flush=True)


if __name__ == "__main__":
    main()
