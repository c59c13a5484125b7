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
import os, re, subprocess, sys, tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from default_variants import arg, seed_runs  # noqa: E402


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
        crop = ["--crop", "48", "40", "112", "88", "--integrator", "eikonal", "--nee"]
        a = seed_runs(rrv, scene, crop + ["shoot"], seeds, spp, tmp, "%s_shoot" % s)
        b = seed_runs(rrv, scene, crop + ["manifold"], seeds, spp, tmp, "%s_manifold" % s)
        print("| %s | %s | %.2f, %.3g | %.2f, %.3g | %.2fx | %+.2f %% |" %
              (s, chosen.group(1) if chosen else "?", a[0], a[1], b[0], b[1], (a[0] * a[1]) / (b[0] * b[1]),
               100 * (b[5] / a[5] - 1)), flush=True)


if __name__ == "__main__":
    main()
