#!/usr/bin/env python3
"""Which integrator and light sampling a scene without an `integrator` key
should get: efficiency 1 / (CPU s x MSE) of each unbiased mode on the bench
scenes, against the references in test/ref/ (read by `rrv diff`, so no
OpenEXR is needed). One thread, fixed seed; the spp of a mode doubles until
one render takes --seconds of CPU, and that render's error counts. MSE has
the reference's own noise (test/bench/results/bench.md) taken off.

    python3 test/bench/default_choice.py BUILD/rrv [--seconds 2] [--scenes a,b] [--modes m1,m2] [--seed 11]

A scene is a name in test/ref/ or SCENE.rrv:REFERENCE.pfm|exr (a variant:
its reference's own noise is not taken off).

Not a test: nothing here can fail on a number."""
import os, re, subprocess, sys, time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.join(ROOT, "build", "default_choice")
SEED = 11  # not the references' (1..8)
# the MSE each reference's own noise adds (bench.md, ref_compare --floor)
FLOOR = {"luneburg": 1.14e-4, "fire": 4.50e-4, "lens_caustic": 9.07e-4, "fire_caustic": 5.36e-6,
         "haze": 3.06e-5, "plume": 4.32e-7, "heat_shadow": 5.79e-6}
MODES = {
    "default": [],  # the scene with its `integrator` key removed (keyless())
    "refractive+aim": ["--integrator", "refractive", "--nee", "aim"],
    "refractive+none": ["--integrator", "refractive", "--nee", "none"],
    "eikonal+shoot": ["--integrator", "eikonal", "--nee", "shoot"],
    "eikonal+none": ["--integrator", "eikonal", "--nee", "none"],
    "refractive+manifold": ["--integrator", "refractive", "--nee", "manifold"],
    "eikonal+manifold": ["--integrator", "eikonal", "--nee", "manifold"],
}


def run(cmd):
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = p.stdout.read(), p.stderr.read()
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit("failed: %s\n%s" % (" ".join(cmd), err.decode()))
    return ru.ru_utime + ru.ru_stime, err.decode()


def paths(scene):
    """A bench scene by name, or SCENE.rrv:REFERENCE (a variant with its own reference)."""
    if ":" in scene:
        return scene.split(":", 1)
    return "test/ref/%s.rrv" % scene, "test/ref/%s.exr" % scene


def mse(rrv, img, scene):
    out = subprocess.run([rrv, "diff", img, paths(scene)[1]], cwd=ROOT, stdout=subprocess.PIPE,
                         text=True, check=True).stdout
    return float(re.search(r"rmse:\s*(\S+)", out).group(1)) ** 2


def keyless(scene):
    """The scene with its `integrator` key removed, beside the references'
    folder depth so that its relative paths still hold: what a new user
    who writes no key gets."""
    path = os.path.join(OUT, "keyless_" + os.path.basename(paths(scene)[0]))
    with open(os.path.join(ROOT, paths(scene)[0])) as f:
        text = re.sub(r"(?m)^(render\b.*?)\s+integrator\s+\S+", r"\1", f.read())
    with open(path, "w") as f:
        f.write(text)
    return path


def measure(rrv, scene, args, seconds, default=False):
    spp = 1
    path = keyless(scene) if default else paths(scene)[0]
    while True:
        img = os.path.join(OUT, "%s.pfm" % os.path.basename(paths(scene)[0]))
        cpu, err = run([rrv, "render", path, "-o", img, "--spp", str(spp), "--seed", str(SEED),
                        "--threads", "1"] + args)
        if cpu >= seconds or spp >= 1 << 16:
            break
        spp = max(spp * 2, int(spp * seconds / max(cpu, 1e-3) * 0.7))
    ref = os.path.basename(paths(scene)[1])
    floor = FLOOR.get(ref[:-4], 0.0) if paths(scene)[1] == "test/ref/" + ref else 0.0
    e = mse(rrv, img, scene) - floor
    summary = err.strip().splitlines()[-1] if err.strip() else ""
    return spp, cpu, e, summary


def main():
    global SEED
    rrv = sys.argv[1]
    if "--seed" in sys.argv: SEED = int(sys.argv[sys.argv.index("--seed") + 1])
    seconds = float(sys.argv[sys.argv.index("--seconds") + 1]) if "--seconds" in sys.argv else 2.0
    scenes = ["lens_caustic", "fire_caustic", "haze", "fire", "luneburg", "heat_shadow"]
    if "--scenes" in sys.argv: scenes = sys.argv[sys.argv.index("--scenes") + 1].split(",")
    modes = list(MODES)
    if "--modes" in sys.argv: modes = sys.argv[sys.argv.index("--modes") + 1].split(",")
    os.makedirs(OUT, exist_ok=True)
    print("| scene | mode | spp | CPU s | MSE - floor | efficiency |")
    print("|---|---|---|---|---|---|")
    for scene in scenes:
        for m in modes:
            spp, cpu, e, summary = measure(rrv, scene, MODES[m], seconds, m == "default")
            print("| %s | %s | %d | %.2f | %.3e | %.3g |" % (scene, m, spp, cpu, e, 1 / (cpu * e) if e > 0 else float("inf")),
                  flush=True)
            if "-v" in sys.argv: print("    " + summary[:300], flush=True)


if __name__ == "__main__":
    main()
