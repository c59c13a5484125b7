#!/usr/bin/env python3
"""Cost per sample of refraction against classic (README, "Per sample, and
what 1.25x would take"), from the repository root after `make`:

    python3 test/bench/per_sample.py [--rounds N] [--instructions] [SCENE ...]

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
"""
import os
import re
import statistics
import subprocess
import sys
import tempfile

SETTINGS = [
    ("classic", ["--integrator", "classic"]),
    ("no kicks", ["--integrator", "refractive", "--nee", "straight", "--mu-eta", "0.01"]),
    ("refractive", ["--integrator", "refractive", "--nee", "straight"]),
]


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


def main():
    args = sys.argv[1:]
    rounds, count_instructions, scenes = 5, False, []
    while args:
        a = args.pop(0)
        if a == "--rounds" and args:
            rounds = int(args.pop(0))
        elif a == "--instructions":
            count_instructions = True
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
            per = {name: [] for name, _ in SETTINGS}
            for _ in range(rounds):
                for name, flags in SETTINGS:
                    low = cpu_seconds(render_cmd(scene, 1, flags, out))
                    high = cpu_seconds(render_cmd(scene, 17, flags, out))
                    per[name].append((high - low) / 16)
            print(f"{scene}: CPU s a sample, median of {rounds} rounds (ratio to classic: median of the rounds')")
            for name, _ in SETTINGS:
                ratios = [t / c for t, c in zip(per[name], per["classic"]) if c > 0]
                print(f"  {name:11s} {statistics.median(per[name]):.4f}  "
                      f"({statistics.median(ratios):.2f}x)" if ratios else "")
            if count_instructions:
                counts = {}
                for name, flags in SETTINGS:
                    counts[name] = (instructions(render_cmd(scene, 2, flags, out)) -
                                    instructions(render_cmd(scene, 1, flags, out)))
                print(f"{scene}: instructions a sample")
                for name, _ in SETTINGS:
                    print(f"  {name:11s} {counts[name] / 1e6:9.1f} M  ({counts[name] / counts['classic']:.2f}x)")


if __name__ == "__main__":
    main()
