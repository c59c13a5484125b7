#!/usr/bin/env python3
"""rrv against Blender's Cycles on scenes/plume.rrv: whether the two render
the same image, and the CPU time each needs to reach an RMSE.

Needs Blender (Debian 12's `blender`, 3.4.1, was used), Debian's
python3-openvdb for /usr/bin/python3, and build/ref_compare
(`make build/ref_compare`, OpenEXR). Not part of `make test` or `make bench`.

  python3 test/bench/cycles_compare.py [--blender blender] [--work DIR]
      [--agree-spp 256] [--agree-seeds 8] [--agree-step 0.1] [--block 4]
      [--ref-spp 4096] [--rrv-spp 1,2,...,512] [--cycles-spp 1,2,...,256]
      [--repeats 3] [--seed-offset 0] [--skip-agree] [--skip-timing]

The twin scene is test/bench/cycles_twin.py (run inside Blender), its grid
scenes/tools/plume_vdb.py's .vdb.

Agreement: --agree-seeds Cycles renders of --agree-spp samples at a small
ray-marching step (--agree-step times Cycles' default) of test/ref/plume.rrv
(64 x 64) against rrv's reference there (test/ref/plume.exr, 16384 spp, and
its per-sample variance plume_var.exr). In --block x --block pixel blocks of
R + G + B: the relative difference, and z = difference / its standard error
(Cycles' from the spread of its seeds, rrv's from the variance image).
The same is printed for Cycles at its default step, whose bias shows there.

Timing, at scenes/plume.rrv's 256 x 256, one thread each: an rrv reference
(8 renders of --ref-spp/8 samples, merged by ref_compare with its variance);
then for each spp and repeat, interleaved, rrv at its defaults (sobol),
Cycles at its default step and rrv with --transmittance march, each with its
own seed. rrv's time is its whole process's user+sys (parsing and loading
included). Cycles' is the CPU time of Blender's render call less the scene
sync: sync = (median time at 1 spp) - (time per sample, from the medians at
the largest and the smallest spp). The MSE is the mean over the repeats,
less the reference's own noise (ref_compare --floor). The time to reach an
RMSE comes from log-log interpolation between the sweep's points."""
import argparse, math, os, resource, statistics, struct, subprocess, zlib

from pbrt_compare import mse, time_at  # the same MSE tool and log-log reading

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RRV = os.path.join(ROOT, "rrv")
COMPARE = os.path.join(ROOT, "build", "ref_compare")
TWIN = os.path.join(ROOT, "test", "bench", "cycles_twin.py")
LEVELS = (0.04, 0.02, 0.01, 0.005)


def cpu_of(cmd):
    """user+sys of the child, and its stdout."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), out


def read_exr(path):
    """The channels of a scanline OpenEXR file (no or ZIP compression, half
    or float) as {name: row-major list}, and (width, height)."""
    with open(path, "rb") as f:
        data = f.read()
    if struct.unpack_from("<I", data, 0)[0] != 20000630:
        raise SystemExit(path + ": not an OpenEXR file")
    pos, attrs = 8, {}
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        size = struct.unpack_from("<i", data, type_end + 1)[0]
        attrs[data[pos:name_end].decode()] = data[type_end + 5:type_end + 5 + size]
        pos = type_end + 5 + size
    pos += 1
    channels, raw, c = [], attrs["channels"], 0
    while raw[c] != 0:
        end = raw.index(b"\0", c)
        channels.append((raw[c:end].decode(), struct.unpack_from("<i", raw, end + 1)[0]))
        c = end + 17  # name, NUL, pixel type, pLinear + 3 reserved, x and y sampling
    compression = attrs["compression"][0]
    if compression not in (0, 3):
        raise SystemExit(path + ": only uncompressed or ZIP EXR files")
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    lines = 16 if compression == 3 else 1
    offsets = struct.unpack_from("<%dQ" % ((h + lines - 1) // lines), data, pos)
    planes = {name: [] for name, _ in channels}
    for off in offsets:
        y, size = struct.unpack_from("<2i", data, off)
        chunk = data[off + 8:off + 8 + size]
        rows = min(lines, y0 + h - y)
        if compression == 3 and size < rows * w * sum(2 if t == 1 else 4 for _, t in channels):
            t = bytearray(zlib.decompress(chunk))
            for i in range(1, len(t)):  # undo ZIP's byte predictor, then its split into halves
                t[i] = (t[i - 1] + t[i] - 128) & 255
            chunk = bytearray(len(t))
            chunk[0::2], chunk[1::2] = t[:(len(t) + 1) // 2], t[(len(t) + 1) // 2:]
        p = 0
        for _ in range(rows):
            for name, kind in channels:  # stored in name order, a row each
                fmt, n = ("<%de" % w, 2 * w) if kind == 1 else ("<%df" % w, 4 * w)
                planes[name].extend(struct.unpack_from(fmt, chunk, p))
                p += n
    return planes, (w, h)


def block_sums(plane, size, b):
    """Mean over each b x b block of a per-pixel list."""
    w, h = size
    return [sum(plane[(y + dy) * w + x + dx] for dy in range(b) for dx in range(b)) / (b * b)
            for y in range(0, h, b) for x in range(0, w, b)]


def rgb_sum(path):
    planes, size = read_exr(path)
    return [r + g + b for r, g, b in zip(planes["R"], planes["G"], planes["B"])], size


def twin(a, out, spp, seed, res, step):
    """Renders the Cycles twin; the CPU time of its render call."""
    text = cpu_of([a.blender, "-b", "--factory-startup", "-noaudio", "-P", TWIN, "--", "--vdb", a.vdb,
                   "--out", out, "--spp", str(spp), "--seed", str(seed), "--res", str(res),
                   "--step-rate", str(step), "--threads", "1"])[1]
    return float(text.split("cycles_twin cpu")[1].split()[0])


def agreement(a):
    ref_dir = os.path.join(ROOT, "test", "ref")
    with open(os.path.join(ref_dir, "refs.txt")) as f:
        ref_spp = int(next(l for l in f if l.split()[:1] == ["plume"]).split()[3])
    ref, size = rgb_sum(os.path.join(ref_dir, "plume.exr"))
    b = a.block
    rb = block_sums(ref, size, b)
    # S is the variance of R + G + B of one sample: a block mean's is its
    # mean over the block over the block's pixel count and the samples.
    s_var, _ = read_exr(os.path.join(ref_dir, "plume_var.exr"))
    rv = [v / (b * b) / ref_spp for v in block_sums(s_var["S"], size, b)]
    for step in (a.agree_step, 1.0):
        per_seed = []
        for seed in range(1, a.agree_seeds + 1):
            out = os.path.join(a.work, "agree_step%g_seed%d.exr" % (step, seed))
            if not (a.reuse and os.path.exists(out)):
                twin(a, out, a.agree_spp, 1000 + seed, size[0], step)
            per_seed.append(block_sums(rgb_sum(out)[0], size, b))
        k = len(per_seed)
        cb = [statistics.mean(col) for col in zip(*per_seed)]
        cv = [statistics.variance(col) / k for col in zip(*per_seed)]
        # Blocks of sky alone have no noise in either renderer and agree
        # to rounding; the statistics are over the rest, the plume's.
        live = [i for i in range(len(cb)) if cv[i] + rv[i] > 0]
        z = [(cb[i] - rb[i]) / math.sqrt(cv[i] + rv[i]) for i in live]
        rel = sorted(abs(cb[i] / rb[i] - 1) for i in live)
        total = sum(rb[i] for i in live)
        print("\nCycles at %g x its default step (%d seeds x %d spp) against rrv's %d-spp reference, "
              "the %d of %d blocks of %d x %d pixels that hold smoke:" % (step, k, a.agree_spp, ref_spp,
                                                                          len(live), len(cb), b, b))
        print("  all of them: Cycles / rrv - 1 = %+.3f %% +- %.3f %% (one standard error)"
              % (100 * (sum(cb[i] for i in live) / total - 1),
                 100 * math.sqrt(sum(cv[i] + rv[i] for i in live)) / total))
        print("  |Cycles / rrv - 1| of a block: median %.3f %%, 90th percentile %.3f %%, max %.3f %%"
              % (100 * statistics.median(rel), 100 * rel[int(0.9 * len(rel))], 100 * rel[-1]))
        print("  z = difference / standard error: max |z| %.2f, blocks with |z| > 4: %d, "
              "chi^2 %.1f (mean %d, sd %.1f), mean z %+.3f"
              % (max(map(abs, z)), sum(abs(x) > 4 for x in z), sum(x * x for x in z), len(z),
                 math.sqrt(2 * len(z)), statistics.mean(z)), flush=True)


def slope(points):
    """Least-squares slope of log MSE against log spp."""
    xs, ys = [math.log(s) for s, _ in points], [math.log(e) for _, e in points]
    mx, my = statistics.mean(xs), statistics.mean(ys)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)


def timing(a):
    scene = os.path.join(ROOT, "scenes", "plume.rrv")
    ref, ref_var = os.path.join(a.work, "ref.exr"), os.path.join(a.work, "ref_var.exr")

    def rrv(spp, seed, out, *extra):
        return cpu_of([RRV, "render", scene, "--spp", str(spp), "--seed", str(seed), "--threads", "1",
                       "-o", out, "--exr-float", "-q"] + list(extra))[0]

    if not os.path.exists(ref_var):
        parts = []
        for seed in range(1, 9):
            parts.append(os.path.join(a.work, "ref_part%d.exr" % seed))
            rrv(a.ref_spp // 8, 9000 + seed, parts[-1])
        subprocess.run([COMPARE, "--merge", ref, ref_var, str(a.ref_spp // 8)] + parts, check=True)
        print("reference: rrv, %d spp in 8 renders" % (a.ref_spp // 8 * 8), flush=True)
    out = subprocess.run([COMPARE, "--floor", ref_var, str(a.ref_spp // 8 * 8)], check=True,
                         capture_output=True, text=True).stdout.split()
    floor = float(out[out.index("floor") + 1])
    methods = {"rrv (sobol)": [int(s) for s in a.rrv_spp.split(",")],
               "Cycles": [int(s) for s in a.cycles_spp.split(",")],
               "rrv, march": [int(s) for s in a.rrv_spp.split(",")]}
    short = {"rrv (sobol)": "rrv", "Cycles": "cycles", "rrv, march": "rrv_march"}
    times, errors = {}, {}
    for spp in sorted(set(sum(methods.values(), []))):
        for rep in range(a.repeats):
            seed = a.seed_offset + 100 * spp + rep + 1
            for m, spps in methods.items():
                if spp not in spps:
                    continue
                out = os.path.join(a.work, "%s_%d.exr" % (short[m], spp))
                if m == "Cycles":
                    t = twin(a, out, spp, seed, 256, 1.0)
                else:
                    t = rrv(spp, seed, out, *(["--transmittance", "march"] if "march" in m else []))
                times.setdefault((m, spp), []).append(t)
                errors.setdefault((m, spp), []).append(mse(ref, out))
        print("spp %d done" % spp, flush=True)
    med = {k: statistics.median(v) for k, v in times.items()}
    cs = methods["Cycles"]
    per_sample = (med[("Cycles", cs[-1])] - med[("Cycles", cs[0])]) / (cs[-1] - cs[0])
    sync = med[("Cycles", cs[0])] - cs[0] * per_sample
    print("\nCycles: scene sync %.3f s (taken out below), %.4f s a sample" % (sync, per_sample))
    print("\n| renderer | spp | CPU s (median) | MSE (mean, less the reference's noise %.2e) |" % floor)
    print("|---|---|---|---|")
    curves, spp_curves = {}, {}
    for m, spps in methods.items():
        for spp in spps:
            t = med[(m, spp)] - (sync if m == "Cycles" else 0.0)
            e = statistics.mean(errors[(m, spp)]) - floor
            curves.setdefault(m, []).append((t, e))
            spp_curves.setdefault(m, []).append((spp, e))
            print("| %s | %d | %.3f | %.3e |" % (m, spp, t, e))
    print("\nslope of log MSE against log spp (all points; spp >= 4):")
    for m in methods:
        print("  %s: %.3f; %.3f" % (m, slope(spp_curves[m]), slope([p for p in spp_curves[m] if p[0] >= 4])))
    print("\n| RMSE | Cycles CPU s | rrv (sobol) | Cycles / rrv | rrv, march | Cycles / rrv |")
    print("|---|---|---|---|---|---|")
    for level in LEVELS:
        tc = time_at(curves["Cycles"], level * level)
        tr, tm = time_at(curves["rrv (sobol)"], level * level), time_at(curves["rrv, march"], level * level)
        print("| %.3f | %.2f | %.3f | %.2f | %.3f | %.2f |" % (level, tc, tr, tc / tr, tm, tc / tm))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--blender", default="blender")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "cycles_compare"))
    ap.add_argument("--agree-spp", type=int, default=256)
    ap.add_argument("--agree-seeds", type=int, default=8)
    ap.add_argument("--agree-step", type=float, default=0.1)
    ap.add_argument("--block", type=int, default=4)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--rrv-spp", default="1,2,4,8,16,32,64,128,256,512")
    ap.add_argument("--cycles-spp", default="1,2,4,8,16,32,64,128,256")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed-offset", type=int, default=0, help="added to the sweep's seeds, for a second run")
    ap.add_argument("--skip-agree", action="store_true")
    ap.add_argument("--reuse", action="store_true", help="keep the agreement renders already in --work")
    ap.add_argument("--skip-timing", action="store_true")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    a.vdb = os.path.join(a.work, "plume.vdb")
    subprocess.run(["/usr/bin/python3", os.path.join(ROOT, "scenes", "tools", "plume_vdb.py"),
                    os.path.join(ROOT, "scenes", "assets", "plume.vol"), a.vdb], check=True)
    version = subprocess.run([a.blender, "--version"], capture_output=True, text=True).stdout.split("\n")[0]
    print("%s; rrv %s" % (version, subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                                                   capture_output=True, text=True).stdout.strip()))
    if not a.skip_agree:
        agreement(a)
    if not a.skip_timing:
        timing(a)


if __name__ == "__main__":
    main()
