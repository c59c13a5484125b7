#!/usr/bin/env python3
"""Eikonal steps placed by the field (no `step` given) against fixed steps:
efficiency 1 / (CPU s x MSE) of `--integrator eikonal --nee shoot` on the
bench scenes, MSE against test/ref/ less the reference's own noise (as
default_choice.py), one thread, runs interleaved (fixed, placed, fixed,
...), medians. "fixed" is --step 0.01, the length every step had before;
"placed" gives no step. A scene with its own step (fire_caustic: 0.05) is
rendered without it as "placed", and with it as a third row.

    python3 test/bench/placed_steps.py BUILD/rrv [--spp 32] [--reps 3] [--scenes a,b]

Not a test: nothing here can fail on a number."""
import argparse, os, re, statistics, subprocess, sys, tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from default_choice import FLOOR  # noqa: E402

SEED = 11


def render(rrv, scene, out, spp, flags):
    cmd = [rrv, "render", scene, "-o", out, "-q", "--spp", str(spp), "--seed", str(SEED), "--threads", "1",
           "--integrator", "eikonal", "--nee", "shoot"] + flags
    p = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    if p.returncode != 0:
        sys.exit("failed: %s\n%s" % (" ".join(cmd), p.stderr.decode()))


def cpu_of(fn):
    before = os.times()
    result = fn()
    after = os.times()
    return after.children_user - before.children_user + after.children_system - before.children_system, result


def mse(rrv, img, scene):
    out = subprocess.run([rrv, "diff", img, "test/ref/%s.exr" % scene], cwd=ROOT, stdout=subprocess.PIPE,
                         check=True).stdout.decode()
    rmse = float(re.search(r"^rmse: (\S+)", out, re.M).group(1))
    return max(rmse * rmse - FLOOR.get(scene, 0.0), 1e-12)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("rrv")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--scenes", default="heat_shadow,fire_caustic,haze,fire")
    a = ap.parse_args()
    rrv = os.path.abspath(a.rrv)
    tmp = tempfile.mkdtemp(prefix="placed_steps")
    print("| scene | steps | spp | CPU s | MSE | efficiency | over fixed 0.01 |")
    print("|---|---|---|---|---|---|---|")
    for scene in a.scenes.split(","):
        text = open(os.path.join(ROOT, "test/ref/%s.rrv" % scene)).read()
        own = re.search(r"(?m)^render .*\bstep (\S+)", text)
        stepless = os.path.join(ROOT, "test/ref/%s.placed.rrv" % scene)
        with open(stepless, "w") as f:
            f.write(re.sub(r"\bstep \S+", "", text))
        variants = [("fixed 0.01", stepless, ["--step", "0.01"]), ("placed", stepless, [])]
        if own:
            variants.append(("the scene's %s" % own.group(1), stepless, ["--step", own.group(1)]))
        runs = {name: [] for name, _, _ in variants}
        try:
            for _ in range(a.reps):
                for name, path, flags in variants:
                    out = os.path.join(tmp, "out.pfm")
                    t, _ = cpu_of(lambda: render(rrv, path, out, a.spp, flags))
                    runs[name].append((t, mse(rrv, out, scene)))
        finally:
            os.remove(stepless)
        eff = {}
        for name, _, _ in variants:
            t = statistics.median(r[0] for r in runs[name])
            m = statistics.median(r[1] for r in runs[name])
            eff[name] = 1.0 / (t * m)
            print("| %s | %s | %d | %.2f | %.3g | %.3g | %.2fx |" % (scene, name, a.spp, t, m, eff[name],
                                                                    eff[name] / eff["fixed 0.01"]))


if __name__ == "__main__":
    main()
