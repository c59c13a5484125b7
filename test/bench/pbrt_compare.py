#!/usr/bin/env python3
"""rrv against pbrt-v4 on scenes/plume.rrv: CPU time to reach an MSE.

Needs a pbrt-v4 build (CPU, any recent commit) and build/ref_compare
(`make build/ref_compare`, OpenEXR). Neither pbrt-v4 nor its scene is part
of rrv: scenes/tools/plume_pbrt.py writes the same scene for pbrt-v4.

  python3 test/bench/pbrt_compare.py --pbrt /path/to/pbrt [--ref-spp 4096]
         [--spp 1,2,4,...,256] [--repeats 3] [--work DIR]

Steps: an rrv reference at --ref-spp (one thread); then for each spp and
repeat, interleaved, rrv (pcg), pbrt-v4 (zsobol, its default) and rrv
(sobol), each one thread with its own seed; the whole process's user+sys
time (median of the repeats) and the MSE against the reference (mean of the
repeats) less the reference's own noise (rrv's 1-spp MSE over --ref-spp).
The time each needs for an MSE level comes from log-log interpolation
between the sweep's points. Also prints the MSE between the rrv reference
and a pbrt-v4 one (--pbrt-ref-spp, 0 to skip) beside what their noise
alone would give, to show that the two converge to the same image."""
import argparse, math, os, resource, statistics, subprocess, sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run_timed(cmd):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def mse(ref, img):
    out = subprocess.run([os.path.join(ROOT, "build", "ref_compare"), ref, img], check=True,
                         capture_output=True, text=True).stdout.split()
    return float(out[out.index("mse") + 1])


def time_at(points, level):
    points = sorted(p for p in points if p[1] > 0)
    for (t0, e0), (t1, e1) in zip(points, points[1:]):
        if e0 >= level >= e1 and e0 > e1:
            a = (math.log(level) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + a * (math.log(t1) - math.log(t0)))
    return float("nan")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pbrt", required=True)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--pbrt-ref-spp", type=int, default=1024)
    ap.add_argument("--spp", default="1,2,4,8,16,32,64,128,256")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--work", default="build/pbrt_compare")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    rrv, scene = os.path.join(ROOT, "rrv"), os.path.join(ROOT, "scenes", "plume.rrv")
    grid = os.path.join(ROOT, "scenes", "assets", "plume.vol")
    tool = os.path.join(ROOT, "scenes", "tools", "plume_pbrt.py")
    ref = os.path.join(a.work, "ref.exr")

    def rrv_cmd(spp, seed, out, sampler="pcg"):
        return [rrv, "render", scene, "--spp", str(spp), "--seed", str(seed), "--sampler", sampler,
                "--threads", "1", "-o", out, "--exr-float", "-q"]

    def pbrt_scene(spp, out):
        path = os.path.join(a.work, "plume_%d.pbrt" % spp)
        subprocess.run([sys.executable, tool, str(spp), path, grid, out], check=True)
        return path

    print("reference: rrv, %d spp" % a.ref_spp, flush=True)
    run_timed(rrv_cmd(a.ref_spp, 1001, ref))
    times, errors = {}, {}
    methods = ("rrv pcg", "pbrt-v4 zsobol", "rrv sobol")
    for spp in [int(s) for s in a.spp.split(",")]:
        pout = os.path.join(a.work, "pbrt_%d.exr" % spp)
        pscene = pbrt_scene(spp, pout)
        for rep in range(a.repeats):
            seed = 10 * spp + rep + 1
            for m in methods:
                if m == "pbrt-v4 zsobol":
                    out, cmd = pout, [a.pbrt, "--nthreads", "1", "--quiet", "--seed", str(seed), pscene]
                else:
                    out = os.path.join(a.work, "%s_%d.exr" % (m.split()[1], spp))
                    cmd = rrv_cmd(spp, seed, out, m.split()[1])
                times.setdefault((m, spp), []).append(run_timed(cmd))
                errors.setdefault((m, spp), []).append(mse(ref, out))
        print("spp %d done" % spp, flush=True)
    floor = statistics.mean(errors[("rrv pcg", min(s for _, s in errors))]) / a.ref_spp
    print("\n| method | spp | CPU s (median) | MSE (mean, less the reference's noise %.2e) |" % floor)
    print("|---|---|---|---|")
    curves = {}
    for (m, spp) in sorted(times, key=lambda k: (methods.index(k[0]), k[1])):
        t, e = statistics.median(times[(m, spp)]), statistics.mean(errors[(m, spp)]) - floor
        curves.setdefault(m, []).append((t, e))
        print("| %s | %d | %.3f | %.3e |" % (m, spp, t, e))
    print("\n| MSE | pbrt-v4 CPU s | rrv pcg | ratio | rrv sobol | ratio |")
    print("|---|---|---|---|---|---|")
    for level in (1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5):
        tp = time_at(curves["pbrt-v4 zsobol"], level)
        tr, ts = time_at(curves["rrv pcg"], level), time_at(curves["rrv sobol"], level)
        print("| %.1e | %.2f | %.2f | %.3f | %.2f | %.3f |" % (level, tp, tr, tr / tp, ts, ts / tp))
    if a.pbrt_ref_spp > 0:
        pref = os.path.join(a.work, "pbrt_ref.exr")
        run_timed([a.pbrt, "--nthreads", "1", "--quiet", "--seed", "77", pbrt_scene(a.pbrt_ref_spp, pref)])
        p1 = statistics.mean(errors[("pbrt-v4 zsobol", min(s for _, s in errors))])
        print("\nrrv reference against pbrt-v4's at %d spp: MSE %.3e; their noise alone, at most "
              "%.3e (pbrt-v4's 1-spp MSE over its spp, plus rrv's floor)"
              % (a.pbrt_ref_spp, mse(ref, pref), p1 / a.pbrt_ref_spp + floor))


if __name__ == "__main__":
    main()
