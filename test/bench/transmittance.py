#!/usr/bin/env python3
"""Whole-render efficiency 1 / (CPU s x MSE) of the transmittance estimators
(`--transmittance ratio|march|residual`) against the references in
test/ref/ (read by `rrv diff`). Equal spp, one thread; the estimators take
turns (A, B, A, B, ...) with seeds 11, 12, ... so each pair sees the same
seed and the same machine load; medians over the rounds. MSE has the
reference's own noise (default_choice.py's FLOOR) taken off.

    python3 test/bench/transmittance.py BUILD/rrv [--rounds 5] [--scenes plume:256,pyro:16]
        [--modes ratio,march]

A scene entry is NAME:SPP; the render options are the reference's
(test/ref/refs.txt) except that `--nee none` is dropped, so shadow rays are
cast (the scene's own NEE, unbiased for every scene here).

Not a test: nothing here can fail on a number."""
import os, re, statistics, subprocess, sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.join(ROOT, "build", "transmittance")
FLOOR = {"haze": 3.06e-5, "plume": 4.32e-7}


def ref_options(name):
    for line in open(os.path.join(ROOT, "test", "ref", "refs.txt")):
        f = line.split("#", 1)[0].split()
        if f and f[0] == name:
            opts = f[6:]
            if "--nee" in opts:
                i = opts.index("--nee")
                del opts[i:i + 2]
            return opts
    sys.exit("no %s in refs.txt" % name)


def run(cmd):
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.read()
    err = p.stderr.read()
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit("failed: %s\n%s" % (" ".join(cmd), err.decode()))
    return ru.ru_utime + ru.ru_stime


def mse(rrv, img, name):
    out = subprocess.run([rrv, "diff", img, "test/ref/%s.exr" % name], cwd=ROOT, stdout=subprocess.PIPE,
                         text=True, check=True).stdout
    return float(re.search(r"rmse:\s*(\S+)", out).group(1)) ** 2 - FLOOR.get(name, 0.0)


def main():
    rrv = sys.argv[1]
    arg = lambda k, d: sys.argv[sys.argv.index(k) + 1] if k in sys.argv else d
    rounds = int(arg("--rounds", "5"))
    scenes = [s.split(":") for s in arg("--scenes", "plume:256,pyro:16,haze:64").split(",")]
    modes = arg("--modes", "ratio,march").split(",")
    os.makedirs(OUT, exist_ok=True)
    print("| scene | spp | estimator | CPU s | MSE - floor | efficiency | / ratio's |")
    print("|---|---|---|---|---|---|---|")
    for name, spp in scenes:
        cpu = {m: [] for m in modes}
        err = {m: [] for m in modes}
        for r in range(rounds):
            for i in range(len(modes)):
                m = modes[(r + i) % len(modes)]
                img = os.path.join(OUT, "%s_%s.pfm" % (name, m))
                cpu[m].append(run([rrv, "render", "test/ref/%s.rrv" % name, "-o", img, "--spp", spp, "--seed",
                                   str(11 + r), "--threads", "1", "--transmittance", m] + ref_options(name)))
                err[m].append(mse(rrv, img, name))
        eff = {m: statistics.median(1.0 / (c * e) for c, e in zip(cpu[m], err[m])) for m in modes}
        for m in modes:
            print("| %s | %s | %s | %.3f | %.4g | %.4g | %.3f |" % (
                name, spp, m, statistics.median(cpu[m]), statistics.median(err[m]), eff[m],
                eff[m] / eff[modes[0]]), flush=True)


if __name__ == "__main__":
    main()
