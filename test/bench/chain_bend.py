#!/usr/bin/env python3
"""Where chains (nee manifold) stop beating shoot as a plume bends harder.

Takes README's heat caustic recipe (its second rrv block), sets its
`iorscale` to each value given, and renders the 64 x 48 crop of the
caustic with the eikonal integrator and `nee shoot` and `nee manifold`
(the default solver), one thread, at several seeds. Prints each mode's
mean CPU time, the pixel variance across the seeds (no reference needed),
the efficiency ratio 1 / (CPU x variance) of manifold over shoot, and the
ratio of their means (the chain model's difference from shoot's steps).

    python3 test/bench/chain_bend.py BUILD/rrv [--scales 100,300,450,600,1000]
        [--seeds 6] [--spp 8] [--recipe-box]

By default the box's floor is moved down to y = 0.4, away from the blob,
so that no face is a jump of the IOR (the recipe's own box has one of
~1e-7 at iorscale 350 and above, where chains stop and the default shoots);
--recipe-box keeps the recipe's box. The bend bound rrv's default compares
with 2 rad is printed by `rrv info`'s choice only, so the script prints
the `nee` rrv chooses for each variant.

Not a test: nothing here can fail on a number."""
import os, re, struct, subprocess, sys, tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def arg(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def pfm(path):
    with open(path, "rb") as f:
        f.readline()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        n = w * h * 3
        return struct.unpack(("<" if scale < 0 else ">") + "%df" % n, f.read(4 * n))


def render(rrv, scene, nee, seed, spp, out):
    p = subprocess.Popen([rrv, "render", scene, "-o", out, "--spp", str(spp), "--seed", str(seed), "--threads", "1",
                          "--crop", "48", "40", "112", "88", "-q", "--integrator", "eikonal", "--nee", nee])
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit("render failed: %s %s" % (scene, nee))
    return ru.ru_utime + ru.ru_stime


def main():
    rrv = os.path.abspath(sys.argv[1])
    scales = arg("--scales", "100,300,450,600,1000").split(",")
    seeds = range(101, 101 + int(arg("--seeds", "6")))
    spp = int(arg("--spp", "8"))
    with open(os.path.join(ROOT, "README.md")) as f:
        recipe = re.findall(r"```rrv\n(.*?)```", f.read(), re.S)[1]
    tmp = tempfile.mkdtemp(prefix="chain_bend_")
    print("| iorscale | default nee | shoot: CPU s, pixel variance | manifold: CPU s, pixel variance "
          "| manifold over shoot | mean, manifold over shoot |")
    print("|---|---|---|---|---|---|")
    for s in scales:
        text = re.sub(r"iorscale \S+", "iorscale " + s, recipe)
        if "--recipe-box" not in sys.argv:
            text = text.replace("box -1.3 1.3 -1.3", "box -1.3 0.4 -1.3")
        scene = os.path.join(tmp, "r%s.rrv" % s)
        with open(scene, "w") as f:
            f.write(text)
        info = subprocess.run([rrv, "info", scene], stdout=subprocess.PIPE, text=True).stdout
        chosen = re.search(r"nee: (\S+?),? ", info)
        row = {}
        for nee in ("shoot", "manifold"):
            cpu, images = 0.0, []
            for k in seeds:
                out = os.path.join(tmp, "%s_%s_%d.pfm" % (s, nee, k))
                cpu += render(rrv, scene, nee, k, spp, out)
                images.append(pfm(out))
            n, m = len(images[0]), len(images)
            means = [sum(im[i] for im in images) / m for i in range(n)]
            var = sum(sum((im[i] - means[i]) ** 2 for im in images) / (m - 1) for i in range(n)) / n
            row[nee] = (cpu / m, var, sum(means) / n)
        a, b = row["shoot"], row["manifold"]
        print("| %s | %s | %.2f, %.3g | %.2f, %.3g | %.2fx | %+.2f %% |" %
              (s, chosen.group(1) if chosen else "?", a[0], a[1], b[0], b[1], (a[0] * a[1]) / (b[0] * b[1]),
               100 * (b[2] / a[2] - 1)), flush=True)


if __name__ == "__main__":
    main()
