#!/usr/bin/env python3
"""Cost per sample of refraction against classic (test/bench/RESULTS.md, "Per sample, and
what 1.25x would take"), from the repository root after `make`:

    python3 test/bench/per_sample.py [--rounds N] [--instructions] [--curve] [SCENE ...]

For each scene (default scenes/fire.rrv and scenes/haze.rrv) it renders
with one thread and the scene's own settings

    classic      --integrator classic
    no kicks     --integrator refractive --nee straight --mu-eta 0.01
    refractive   --integrator refractive --nee straight

at 1 and at 17 spp, in interleaved rounds (every setting once a round), and
prints the CPU time (user+sys) of one sample per pixel: the difference of
the two renders over 16, so the set-up they share drops out. Medians over
the rounds, and each setting's ratio to classic as the median of the
rounds' ratios. With --instructions it also counts instructions under
valgrind (cachegrind, no cache simulation): the whole process at 2 spp
minus at 1 spp, which does not depend on the machine or its load.

With --curve it sweeps refraction's accuracy instead (fire: the bend
tolerance; haze, whose chords are capped at a majorant cell whatever the
tolerance: the fixed rate --mu-eta, evenly spaced kicks) and adds, for
each setting, the kicks a bent ray and the landing error that
build/measure_tracking --comb reports for it (camera rays against eikonal
RK4 at a fine step, where they cross the fire's wall or the haze box's
back face): the per-sample cost of refraction at each accuracy, and the
floor (no kicks) it approaches. Build the tool first: make
build/measure_tracking.
"""
import os
import re
import statistics
import subprocess
import sys
import tempfile

CLASSIC = ["--integrator", "classic"]
REFRACTIVE = ["--integrator", "refractive", "--nee", "straight"]
NO_KICKS = ["--mu-eta", "0.01"]
SETTINGS = [
    ("classic", CLASSIC),
    ("no kicks", REFRACTIVE + NO_KICKS),
    ("refractive", REFRACTIVE),
]

# --curve: (name, render flags, build/measure_tracking --comb arguments after
# the scene: tolerance (0: the scene's), crossing plane, fixed rate)
FIRE_PLANE = "2.5"
CURVES = {
    "scenes/fire.rrv": [("no kicks", NO_KICKS, ["0", FIRE_PLANE, NO_KICKS[1]])] +
    [(f"tolerance {t}", ["--bend-tolerance", t], [t, FIRE_PLANE]) for t in ("0.01", "0.02", "0.05", "0.1", "0.2", "0.5")],
    "scenes/haze.rrv": [("no kicks", NO_KICKS, ["0", "-", NO_KICKS[1]]), ("tolerance 0.01", [], ["0.01"])] +
    [(f"mu_eta {m}", ["--mu-eta", m], ["0", "-", m]) for m in ("32", "16", "8", "4", "2")],
}


def render_cmd(scene, spp, flags, out):
    return ["./rrv", "render", scene, "-o", out, "--threads", "1", "-q", "--spp", str(spp)] + flags


def cpu_seconds(cmd):
    before = os.times()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = os.times()
    return (after.children_user - before.children_user) + (after.children_system - before.children_system)


def instructions(cmd):
    res = subprocess.run(["valgrind", "--tool=cachegrind", "--cache-sim=no", "--cachegrind-out-file=/dev/null"] + cmd,
                         capture_output=True, text=True, check=True)
    m = re.search(r"I\s+refs:\s+([\d,]+)", res.stderr)
    if not m:
        sys.exit("per_sample.py: valgrind printed no instruction count")
    return int(m.group(1).replace(",", ""))


def landing(scene, tracking_args):
    """Kicks a bent ray and landing error, as build/measure_tracking --comb prints them."""
    res = subprocess.run(["build/measure_tracking", "--comb", scene] + tracking_args,
                         capture_output=True, text=True, check=True)
    cells = [c.strip() for c in res.stdout.strip().splitlines()[-1].strip("|").split("|")]
    return f"{cells[3]} | {cells[4]}"


def curve_settings(scene):
    if scene not in CURVES:
        sys.exit(f"per_sample.py: --curve has no sweep for {scene} (it has {', '.join(CURVES)})")
    return [("classic", CLASSIC, None)] + \
        [(name, REFRACTIVE + flags, tracking) for name, flags, tracking in CURVES[scene]]


def main():
    args = sys.argv[1:]
    rounds, count_instructions, curve, scenes = 5, False, False, []
    while args:
        a = args.pop(0)
        if a == "--rounds" and args:
            rounds = int(args.pop(0))
        elif a == "--instructions":
            count_instructions = True
        elif a == "--curve":
            curve = True
        elif a.startswith("-"):
            sys.exit(__doc__)
        else:
            scenes.append(a)
    if rounds < 1:
        sys.exit("per_sample.py: --rounds must be at least 1")
    scenes = scenes or ["scenes/fire.rrv", "scenes/haze.rrv"]
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "x.pfm")
        for scene in scenes:
            settings = curve_settings(scene) if curve else [(name, flags, None) for name, flags in SETTINGS]
            per = {name: [] for name, _, _ in settings}
            for _ in range(rounds):
                for name, flags, _ in settings:
                    low = cpu_seconds(render_cmd(scene, 1, flags, out))
                    high = cpu_seconds(render_cmd(scene, 17, flags, out))
                    per[name].append((high - low) / 16)
            cpu = {}
            for name, _, _ in settings:
                ratios = [t / c for t, c in zip(per[name], per["classic"]) if c > 0]
                cpu[name] = (statistics.median(per[name]), statistics.median(ratios) if ratios else float("nan"))
            counts = {}
            if count_instructions:
                for name, flags, _ in settings:
                    counts[name] = (instructions(render_cmd(scene, 2, flags, out)) -
                                    instructions(render_cmd(scene, 1, flags, out)))
            if curve:
                print(f"{scene}: a sample, CPU medians of {rounds} rounds (ratio: median of the rounds')")
                print("| setting | kicks a bent ray | landing error | CPU s | ratio | instructions | ratio |")
                print("|---|---|---|---|---|---|---|")
                for name, _, tracking in settings:
                    land = landing(scene, tracking) if tracking else "- | -"
                    ins = (f"{counts[name] / 1e6:.0f} M | {counts[name] / counts['classic']:.2f}x" if counts
                           else "- | -")
                    print(f"| {name} | {land} | {cpu[name][0]:.4f} | {cpu[name][1]:.2f}x | {ins} |")
                continue
            print(f"{scene}: CPU s a sample, median of {rounds} rounds (ratio to classic: median of the rounds')")
            for name, _, _ in settings:
                print(f"  {name:11s} {cpu[name][0]:.4f}  ({cpu[name][1]:.2f}x)")
            if counts:
                print(f"{scene}: instructions a sample")
                for name, _, _ in settings:
                    print(f"  {name:11s} {counts[name] / 1e6:9.1f} M  ({counts[name] / counts['classic']:.2f}x)")


if __name__ == "__main__":
    main()
