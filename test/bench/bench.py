#!/usr/bin/env python3
"""`make bench` / `make bench-quick`: speed against error. Every figure is a
whole process run by this script, timed with os.wait4 (wall clock, user+sys
CPU time and the peak resident memory of that child); a timing is the median
of RUNS repeats taken in this one invocation, interleaved across methods, so
ratios compare runs made on the same machine at the same time. Error is
against the references in test/ref/ (`make refs`), computed by
build/ref_compare (OpenEXR). Seeds are fixed.

Writes test/bench/results/bench.md (the tables test/bench/RESULTS.md quotes) and
test/bench/results/bench.svg (log CPU time against log RMSE, one panel per
scene, one curve per method), and prints the tables.

usage: bench.py BUILD_DIR [--quick] [--runs N]"""
import math, os, platform, re, statistics, subprocess, sys, time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.join(ROOT, "build", "bench")
# RRV_BENCH_RESULTS: write the results elsewhere (a trial run)
RESULTS = os.environ.get("RRV_BENCH_RESULTS") or os.path.join(ROOT, "test", "bench", "results")
SEED = 11  # not the references' seeds (1..8)


class Timer:
    """Collects repeats of commands and reports medians. os.wait4 must reap
    the child itself to see its rusage, so the process is waited for here."""

    @staticmethod
    def once(cmd):
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        # Read the pipes to the end first (a full pipe would block the child),
        # then reap it with wait4 to get its own resource usage.
        out = p.stdout.read()
        err = p.stderr.read()
        _, status, ru = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            sys.exit("bench: command failed (%d): %s\n%s" % (p.returncode, " ".join(cmd), err.decode(errors="replace")))
        return wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss, out.decode(errors="replace")


def timed(cmds, runs):
    """Runs each command `runs` times, interleaved; returns per command
    (median wall, median user+sys, max peak RSS KiB, last stdout)."""
    res = [[] for _ in cmds]
    for _ in range(runs):
        for i, c in enumerate(cmds):
            res[i].append(Timer.once(c))
    return [(statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs), max(r[2] for r in rs), rs[-1][3])
            for rs in res]


def manifest():
    entries = {}
    for line in open(os.path.join(ROOT, "test", "ref", "refs.txt")):
        f = line.split("#", 1)[0].split()
        if f:
            entries[f[0]] = f
    return entries


class Bench:
    def __init__(self, build, runs, quick):
        self.rrv = os.path.join(build, "rrv")
        self.compare = os.path.join(build, "ref_compare")
        self.build = build
        self.runs = runs
        self.quick = quick
        self.refs = manifest()
        self.md = []
        self.curves = {}  # scene -> [(label, [(cpu s, rmse)])]
        self.count = 0
        self.summary_rows = []

    def out(self, text=""):
        print(text, flush=True)
        self.md.append(text)

    def render_cmd(self, scene, spp, args, threads=1):
        self.count += 1
        img = os.path.join(OUT, "img_%d.exr" % self.count)
        return img, [self.rrv, "render", "test/ref/%s.rrv" % scene, "-o", img, "--exr-float", "--spp", str(spp),
                     "--seed", str(SEED), "--threads", str(threads), "-q"] + args

    def error(self, scene, img):
        out = subprocess.run([self.compare, "test/ref/%s.exr" % scene, img], cwd=ROOT, stdout=subprocess.PIPE,
                             text=True, check=True).stdout
        vals = dict(zip(out.split()[0::2], map(float, out.split()[1::2])))
        return vals["mse"], vals["relmse"]

    def noise_floor(self, scene):
        """The MSE the reference's own noise adds to every error below:
        its per-sample variance over its spp, averaged over pixels."""
        out = subprocess.run([self.compare, "--floor", "test/ref/%s_var.exr" % scene, self.refs[scene][3]], cwd=ROOT,
                             stdout=subprocess.PIPE, text=True, check=True).stdout
        return float(out.split()[-1])

    def ref_args(self, scene):
        return self.refs[scene][6:]

    # ---- error against time ---------------------------------------------------------
    def sweep(self, scene, methods, spps):
        """methods: [(label, args)]; every method at every spp."""
        w, h = self.refs[scene][1], self.refs[scene][2]
        floor = self.noise_floor(scene)
        self.out("### %s (%sx%s; reference: %s spp, %s; its noise adds %.2e to every MSE)\n"
                 % (scene, w, h, self.refs[scene][3], " ".join(self.ref_args(scene)), floor))
        self.out("| method | spp | wall s | user+sys s | peak RSS MiB | MSE | rel. MSE | efficiency 1/(CPU s x MSE) |")
        self.out("|---|---|---|---|---|---|---|---|")
        cases = []
        for method in methods:
            label, args = method[0], method[1]
            for spp in (method[2] if len(method) > 2 else spps):
                img, cmd = self.render_cmd(scene, spp, args)
                cases.append((label, spp, img, cmd))
        res = timed([c[3] for c in cases], self.runs)
        curves = {}
        for (label, spp, img, _), (wall, cpu, rss, _) in zip(cases, res):
            mse, rel = self.error(scene, img)
            curves.setdefault(label, []).append((cpu, math.sqrt(mse)))
            self.out("| %s | %d | %.2f | %.2f | %.1f | %.3e | %.3e | %.3g |"
                     % (label, spp, wall, cpu, rss / 1024, mse, rel, 1 / (cpu * mse) if mse > 0 else float("inf")))
        self.out()
        self.curves[scene] = [(m[0], curves[m[0]]) for m in methods]
        for label in [m[0] for m in methods]:
            pts = sorted(curves[label])
            self.summary_rows.append((scene, label, pts, floor))

    def setting_sweep(self, title, scene, spp, rows):
        """rows: [(setting label, args)] at one spp."""
        self.out("### %s: %s at %d spp\n" % (title, scene, spp))
        self.out("| setting | wall s | user+sys s | MSE | rel. MSE | efficiency |")
        self.out("|---|---|---|---|---|---|")
        cases = [(label,) + self.render_cmd(scene, spp, args) for label, args in rows]
        res = timed([c[2] for c in cases], self.runs)
        for (label, img, _), (wall, cpu, _, _) in zip(cases, res):
            mse, rel = self.error(scene, img)
            self.out("| %s | %.2f | %.2f | %.3e | %.3e | %.3g |" % (label, wall, cpu, mse, rel, 1 / (cpu * mse)))
        self.out()

    def overhead(self, scenes, spp):
        self.out("### Refractive against classic at equal spp (%d spp, 1 thread, reference resolution, nee straight)\n" % spp)
        self.out("| scene | classic user+sys s | refractive user+sys s | ratio | wall ratio |")
        self.out("|---|---|---|---|---|")
        for scene in scenes:
            # straight shadow rays in both: the overhead of refraction's
            # tracking, not of curved NEE (measured in the caustic sweeps)
            pair = [self.render_cmd(scene, spp, ["--integrator", i, "--nee", "straight"])[1]
                    for i in ("classic", "refractive")]
            (cw, cc, _, _), (rw, rc, _, _) = timed(pair, self.runs)
            self.out("| %s | %.2f | %.2f | %.2fx | %.2fx |" % (scene, cc, rc, rc / cc, rw / cw))
        self.out()

    def threads(self):
        self.out("### Threads: scenes/smoke.rrv, 480x320, 16 spp, classic\n")
        self.out("| threads | wall s | user+sys s | speedup (wall) |")
        self.out("|---|---|---|---|")
        img = os.path.join(OUT, "smoke.pfm")
        cmds = [[self.rrv, "render", "scenes/smoke.rrv", "-o", img, "--spp", "16", "--threads", str(t), "-q"]
                for t in (1, 2)]
        res = timed(cmds, self.runs)
        for t, (wall, cpu, _, _) in zip((1, 2), res):
            self.out("| %d | %.2f | %.2f | %.2fx |" % (t, wall, cpu, res[0][0] / wall))
        self.out()

    def majorant_and_memory(self):
        """The majorant grid against one global majorant, and peak memory
        against grid bytes, on grids made by make_grid.py (not stored)."""
        grids = {}
        for name, n, extra in (("dense64.vol", 64, []), ("sparse128.vol", 128, ["--sparse"]), ("dense128.vol", 128, [])):
            path = os.path.join(OUT, name)
            if not os.path.exists(path):
                subprocess.run([sys.executable, os.path.join(ROOT, "test", "bench", "make_grid.py"), path, str(n)]
                               + extra, check=True)
            grids[name] = path
        template = open(os.path.join(ROOT, "test", "bench", "smoke_grid.rrv.in")).read()
        def scene(grid, cells):
            path = os.path.join(OUT, "%s_%d.rrv" % (grid, cells))
            open(path, "w").write(template.replace("@GRID@", grid).replace("@CELLS@", str(cells)))
            return os.path.relpath(path, ROOT)
        img = os.path.join(OUT, "grid.pfm")
        self.out("### Majorant grid against one global majorant (--majorant-cells 1), 256x256, 16 spp, 2 threads\n")
        self.out("| volume | one global majorant wall s (user+sys) | majorant grid wall s (user+sys) | speedup |")
        self.out("|---|---|---|---|")
        for label, grid in (("sparse 128^3 grid, 6 small dense puffs", "sparse128.vol"),
                            ("dense 64^3 smoke column", "dense64.vol")):
            res = timed([[self.rrv, "render", scene(grid, c), "-o", img, "-q"] for c in (1, 0)], self.runs)
            self.out("| %s | %.2f (%.2f) | %.2f (%.2f) | %.1fx |" % (label, res[0][0], res[0][1], res[1][0], res[1][1],
                                                                    res[0][0] / res[1][0]))
        self.out()
        self.out("### Peak memory against grid bytes (1 spp, 256x256)\n")
        self.out("| grid | grid bytes | peak RSS | RSS - grid |")
        self.out("|---|---|---|---|")
        for grid in ("dense64.vol", "dense128.vol"):
            size = (os.path.getsize(grids[grid]) - 48) / 2 ** 20
            rss = timed([[self.rrv, "render", scene(grid, 0), "-o", img, "--spp", "1", "-q"]], 1)[0][2] / 1024
            self.out("| %s | %.1f MiB | %.1f MiB | %.1f MiB |" % (grid, size, rss, rss - size))
        self.out()

    def tracking(self):
        spp = "1" if self.quick else "4"
        out = Timer.once([os.path.join(self.build, "measure_tracking"), spp])[3]
        self.out("### Tracking against its memory reads: scenes/plume.rrv (build/measure_tracking %s)\n" % spp)
        self.out("| what | rate | cost |")
        self.out("|---|---|---|")
        for line in out.splitlines():
            if line.startswith("|"):
                self.out(line)
        self.out()

    def summary(self):
        """One line per curve: the error at the most samples, its efficiency,
        and the log-log slope of MSE against CPU time (-1 for plain Monte
        Carlo once loading is amortised; flatter where a bias or the
        reference's noise floor takes over)."""
        rows = ["| scene | method | CPU s at most spp | RMSE there | efficiency 1/(CPU s x MSE) | slope of log MSE vs log time (last 3 points) |",
                "|---|---|---|---|---|---|"]
        for scene, label, pts, floor in self.summary_rows:
            t, r = pts[-1]
            tail = pts[-3:]
            xs = [math.log(p[0]) for p in tail]
            ys = [math.log(p[1] ** 2) for p in tail]
            mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
            sxx = sum((x - mx) ** 2 for x in xs)
            slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx > 0 else float("nan")
            rows.append("| %s | %s | %.2f | %.3e | %.3g | %.2f |" % (scene, label, t, r, 1 / (t * r * r), slope))
        return rows

    # ---- the plot ---------------------------------------------------------------------
    def svg(self, path):
        panels = [(s, c) for s, c in self.curves.items() if c]
        cols = min(3, len(panels))
        rows = (len(panels) + cols - 1) // cols
        pw, ph = 360, 300
        ml, mr, mt, mb = 62, 12, 28, 44
        colors = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"]
        out = ['<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" font-family="sans-serif" '
               'font-size="11">' % (cols * pw, rows * ph), '<rect width="100%" height="100%" fill="white"/>']
        for n, (scene, curves) in enumerate(panels):
            x0, y0 = (n % cols) * pw + ml, (n // cols) * ph + mt
            w, h = pw - ml - mr, ph - mt - mb
            xs = [math.log10(p[0]) for _, c in curves for p in c]
            ys = [math.log10(p[1]) for _, c in curves for p in c if p[1] > 0]
            xa, xb = math.floor(min(xs) * 2) / 2, math.ceil(max(xs) * 2) / 2
            ya, yb = math.floor(min(ys) * 2) / 2, math.ceil(max(ys) * 2) / 2
            xb, yb = max(xb, xa + 0.5), max(yb, ya + 0.5)
            X = lambda v: x0 + (math.log10(v) - xa) / (xb - xa) * w
            Y = lambda v: y0 + h - (math.log10(v) - ya) / (yb - ya) * h
            out.append('<text x="%d" y="%d" font-weight="bold" font-size="12">%s</text>' % (x0, y0 - 10, scene))
            out.append('<rect x="%d" y="%d" width="%d" height="%d" fill="none" stroke="black"/>' % (x0, y0, w, h))
            e = math.ceil(xa)
            while e <= xb + 1e-9:
                # decade ticks, with 2x and 5x marks between
                for m in (1, 2, 5):
                    v = m * 10 ** e
                    if xa <= math.log10(v) <= xb:
                        x = X(v)
                        out.append('<line x1="%.1f" y1="%d" x2="%.1f" y2="%d" stroke="#ddd"/>' % (x, y0, x, y0 + h))
                        out.append('<text x="%.1f" y="%d" text-anchor="middle">%g</text>' % (x, y0 + h + 14, v))
                e += 1
            e = math.floor(ya)
            while e <= yb + 1e-9:
                for m in (1, 3):
                    v = m * 10 ** e
                    if ya <= math.log10(v) <= yb:
                        y = Y(v)
                        out.append('<line x1="%d" y1="%.1f" x2="%d" y2="%.1f" stroke="#ddd"/>' % (x0, y, x0 + w, y))
                        out.append('<text x="%d" y="%.1f" text-anchor="end">%s</text>' % (x0 - 4, y + 4, "%.0e" % v))
                e += 1
            out.append('<text x="%d" y="%d" text-anchor="middle">CPU time, s (user+sys, 1 thread, log)</text>'
                       % (x0 + w // 2, y0 + h + 32))
            out.append('<text transform="translate(%d,%d) rotate(-90)" text-anchor="middle">RMSE against the '
                       'reference (log)</text>' % (x0 - 48, y0 + h // 2))
            for k, (label, pts) in enumerate(curves):
                col = colors[k % len(colors)]
                pts = [p for p in sorted(pts) if p[1] > 0]
                out.append('<polyline fill="none" stroke="%s" stroke-width="1.5" points="%s"/>'
                           % (col, " ".join("%.1f,%.1f" % (X(t), Y(r)) for t, r in pts)))
                for t, r in pts:
                    out.append('<circle cx="%.1f" cy="%.1f" r="2.5" fill="%s"/>' % (X(t), Y(r), col))
                ly = y0 + h - 10 - 14 * (len(curves) - 1 - k)
                out.append('<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="%s" stroke-width="2"/>'
                           % (x0 + 8, ly - 4, x0 + 26, ly - 4, col))
                out.append('<text x="%d" y="%d">%s</text>' % (x0 + 30, ly, label.replace("&", "&amp;").replace("<", "&lt;")))
        out.append("</svg>")
        open(path, "w").write("\n".join(out) + "\n")


def machine(bench):
    model = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cc = os.environ.get("RRV_BENCH_CC", "cc")
    try:
        version = subprocess.run([cc, "--version"], stdout=subprocess.PIPE, text=True).stdout.splitlines()[0]
    except (OSError, IndexError):
        version = cc
    load = os.getloadavg()
    bench.out("Machine: %s, %d online CPUs; %s; compiler: %s; flags: %s. Load average at start %.2f (other "
              "processes share the cores: compare user+sys with wall). %s run, %d repeats per timing (median), "
              "%s." % (model, os.cpu_count(), platform.platform(), version,
                       os.environ.get("RRV_BENCH_FLAGS", "(not given)"), load[0],
                       "Quick (`make bench-quick`)" if bench.quick else "Full (`make bench`)", bench.runs,
                       time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())))
    bench.out()


def main():
    build = sys.argv[1]
    quick = "--quick" in sys.argv
    runs = 3
    if "--runs" in sys.argv:
        runs = int(sys.argv[sys.argv.index("--runs") + 1])
    os.makedirs(OUT, exist_ok=True)
    os.makedirs(RESULTS, exist_ok=True)
    b = Bench(build, runs, quick)
    t0 = time.time()
    machine(b)
    refs = b.refs
    for scene in ("plume", "luneburg", "fire", "fisheye", "lens_caustic", "fire_caustic", "haze", "heat_shadow"):
        if scene not in refs or not os.path.exists(os.path.join(ROOT, "test", "ref", scene + ".exr")):
            sys.exit("bench: no reference for %s: run make refs" % scene)

    b.out("## Error against time\n")
    b.out("Every render at the reference's resolution, 1 thread, whole process (loading included). MSE over "
          "pixels and channels; relative MSE divides each squared error by ref^2 + 0.01.\n")
    b.sweep("plume", [("classic", ["--integrator", "classic"])], (4, 16, 64, 256) if quick else (1, 4, 16, 64, 256, 1024))
    lune = [("refractive comb, nee none", ["--integrator", "refractive", "--nee", "none"]),
            ("refractive comb, nee straight", ["--integrator", "refractive", "--nee", "straight"]),
            ("eikonal RK4 h=0.05, nee shoot", ["--integrator", "eikonal", "--step", "0.05", "--nee", "shoot"])]
    if not quick:
        lune.append(("refractive poisson, nee none", ["--integrator", "refractive", "--refraction", "poisson",
                                                     "--nee", "none"]))
    b.sweep("luneburg", lune, (1, 4, 16) if quick else (1, 4, 16, 64))
    fire = [("refractive tol 0.05, nee none", ["--integrator", "refractive", "--bend-tolerance", "0.05", "--nee", "none"]),
            ("refractive tol 0.05, nee straight", ["--integrator", "refractive", "--bend-tolerance", "0.05",
                                                   "--nee", "straight"])]
    b.sweep("fire", fire, (2, 8, 32) if quick else (2, 8, 32, 128))
    # curved next-event estimation against forward paths (none) and straight
    # shadow rays on the two caustic scenes
    # (label, args, spps): each mode at the sample counts that give it about
    # the same CPU times, so the curves overlap in time
    lens = [("refractive comb, nee none", ["--integrator", "refractive", "--nee", "none"],
             (16, 64, 256) if quick else (16, 64, 256, 1024)),
            ("refractive comb, nee straight", ["--integrator", "refractive", "--nee", "straight"],
             (4, 16) if quick else (4, 16, 64)),
            ("refractive comb, nee manifold", ["--integrator", "refractive", "--nee", "manifold"],
             (1, 2) if quick else (1, 4, 16)),
            ("refractive comb, nee aim", ["--integrator", "refractive", "--nee", "aim"],
             (16, 64) if quick else (16, 64, 256)),
            ("eikonal RK4, nee shoot", ["--integrator", "eikonal", "--nee", "shoot"],
             (1, 4) if quick else (1, 4, 16)),
            # the paper's refractive ratio tracking with forward paths by MIS
            ("eikonal, nee manifold (dogleg)", ["--integrator", "eikonal", "--nee", "manifold"],
             (1, 4) if quick else (1, 4, 16))]
    b.sweep("lens_caustic", lens, ())
    # the scene states `integrator eikonal` and no nee: its first row is the
    # default nee (chains, the dogleg's)
    fcaustic = [("default nee (the scene's eikonal)", [], (1, 4) if quick else (1, 4, 16)),
                ("eikonal RK4 h=0.05, nee none", ["--integrator", "eikonal", "--nee", "none"],
                 (16, 64, 256) if quick else (64, 256, 1024)),
                ("eikonal RK4 h=0.05, nee straight", ["--integrator", "eikonal", "--nee", "straight"], (4, 16)),
                ("eikonal RK4 h=0.05, nee shoot", ["--integrator", "eikonal", "--nee", "shoot"],
                 (1, 4) if quick else (1, 4, 16)),
                # the paper's refractive ratio tracking, its chain on the eikonal's placed steps
                ("eikonal, nee manifold (dogleg)", ["--integrator", "eikonal", "--nee", "manifold"],
                 (1, 4) if quick else (1, 4, 16)),
                ("refractive comb, nee aim", ["--integrator", "refractive", "--nee", "aim"],
                 (16, 64) if quick else (16, 64, 256))]
    b.sweep("fire_caustic", fcaustic, ())
    # a heat shadow whose temperature is a grid, under a small light; the scene
    # states no integrator, so its first row is what a new user gets
    shadow = [("default (no integrator key)", [], (1, 4) if quick else (1, 4, 16)),
              ("eikonal RK4, nee shoot", ["--integrator", "eikonal", "--nee", "shoot"],
               (1, 4) if quick else (1, 4, 16)),
              ("refractive comb, nee aim", ["--integrator", "refractive", "--nee", "aim"],
               (16, 64) if quick else (16, 64, 256)),
              ("refractive comb, nee manifold", ["--integrator", "refractive", "--nee", "manifold"],
               (1,) if quick else (1, 4)),
              ("eikonal, nee manifold (dogleg)", ["--integrator", "eikonal", "--nee", "manifold"],
               (1, 4) if quick else (1, 4, 16)),
              ("refractive comb, nee none", ["--integrator", "refractive", "--nee", "none"],
               (64, 256) if quick else (64, 256, 1024))]
    b.sweep("heat_shadow", shadow, ())
    # weak heat haze: aimed shadow rays against forward paths and straight ones
    haze = [("refractive comb, nee none", ["--integrator", "refractive", "--nee", "none"],
             (16, 64) if quick else (16, 64, 256)),
            ("refractive comb, nee straight", ["--integrator", "refractive", "--nee", "straight"],
             (16, 64) if quick else (16, 64, 256)),
            ("refractive comb, nee aim (default)", ["--integrator", "refractive", "--nee", "aim"],
             (16, 64) if quick else (16, 64, 256))]
    b.sweep("haze", haze, ())
    if not quick:
        b.sweep("smoke", [("classic", ["--integrator", "classic"])], (1, 4, 16, 64))
        b.sweep("fisheye", [("refractive comb, nee none", ["--integrator", "refractive", "--nee", "none"]),
                            ("eikonal RK4 h=0.01, nee shoot", ["--integrator", "eikonal", "--nee", "shoot"])],
                (1, 4, 16))

    b.out("## Settings\n")
    b.setting_sweep("Refraction tolerance and fixed rate (refractive comb, nee none)", "luneburg", 4 if quick else 16,
                    [("bend tolerance %g" % t, ["--integrator", "refractive", "--nee", "none", "--bend-tolerance", str(t)])
                     for t in ((0.05, 0.01) if quick else (0.1, 0.05, 0.01, 0.002))]
                    + [("mu_eta %g /m" % m, ["--integrator", "refractive", "--nee", "none", "--mu-eta", str(m)])
                       for m in ((30,) if quick else (10, 30, 100))])
    b.setting_sweep("Eikonal step (RK4, nee shoot)", "luneburg", 4 if quick else 16,
                    [("h = %g" % h, ["--integrator", "eikonal", "--stepper", "rk4", "--step", str(h), "--nee", "shoot"])
                     for h in ((0.2, 0.05) if quick else (0.2, 0.05, 0.01))])
    b.setting_sweep("Next-event estimation (eikonal RK4, h = 0.05)", "luneburg", 4 if quick else 16,
                    [("nee %s" % n, ["--integrator", "eikonal", "--step", "0.05", "--nee", n])
                     for n in ("none", "straight", "shoot")])
    b.overhead(("fire", "haze") if quick else ("fire", "haze", "blast"), 16 if quick else 64)
    if not quick:
        b.threads()
        b.majorant_and_memory()
    b.tracking()
    b.out("Bench wall time: %.0f s." % (time.time() - t0))
    summary = ["## Summary\n"] + b.summary() + [""]
    for line in summary:
        print(line)
    b.md[2:2] = summary
    open(os.path.join(RESULTS, "bench.md"), "w").write("\n".join(b.md) + "\n")
    b.svg(os.path.join(RESULTS, "bench.svg"))
    print("bench: wrote %s and bench.svg" % os.path.join(RESULTS, "bench.md"))


if __name__ == "__main__":
    main()
