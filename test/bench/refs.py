#!/usr/bin/env python3
"""`make refs`: renders the reference image of every scene listed in
test/ref/refs.txt into test/ref/NAME.exr (float32, ZIP), from a small copy
of the scene, test/ref/NAME.rrv, written here. The reference is the mean of
CHUNKS renders with seeds 1..CHUNKS; their spread gives the variance of one
sample per pixel, test/ref/NAME_var.exr (test/ref_compare.cpp --merge). The first line of that copy
records a hash of the source scene and of its line in refs.txt, so that
test/test_refs.c can tell a stale reference from a current one. Never edit
the outputs by hand; rerun this.

usage: refs.py RRV_BINARY REF_COMPARE_BINARY [NAME...]   (no NAME: every scene in refs.txt)"""
import os, re, subprocess, sys, time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
REF = os.path.join(ROOT, "test", "ref")
CHUNKS = 8

# Files a scene may name; a relative one is made relative to test/ref/.
PATH_RE = re.compile(r'("[^"]*\.(?:vol|obj|nvdb|vdb|pfm|exr|png)"|[^\s"]+\.(?:vol|obj|nvdb|vdb|pfm|exr|png))(?=\s|$)')


def fnv1a64(data, h=0xCBF29CE484222325):
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def manifest():
    """The entries of refs.txt: (fields, line) per scene."""
    entries = []
    for line in open(os.path.join(REF, "refs.txt")):
        line = line.split("#", 1)[0].split()
        if line:
            entries.append(line)
    return entries


def entry_hash(fields):
    """What test/test_refs.c recomputes: the source scene's bytes, then the
    fields of its line that make the reference (all but TEST_SPP and
    TEST_SEEDS) joined by single spaces."""
    src = open(os.path.join(ROOT, "scenes", fields[0] + ".rrv"), "rb").read()
    return fnv1a64(" ".join(fields[:4] + fields[6:]).encode(), fnv1a64(src))


def derive_scene(fields):
    name, w, h = fields[0], fields[1], fields[2]
    text = open(os.path.join(ROOT, "scenes", name + ".rrv")).read()
    text, n = re.subn(r"\bresolution\s+\d+\s+\d+", "resolution %s %s" % (w, h), text)
    if n != 1:
        sys.exit("refs: scenes/%s.rrv: expected one camera resolution, found %d" % (name, n))
    def rel(m):
        p = m.group(1)
        quoted = p.startswith('"')
        bare = p.strip('"')
        if os.path.isabs(bare):
            return p
        new = os.path.relpath(os.path.join(ROOT, "scenes", bare), REF)
        return '"%s"' % new if quoted or " " in new else new
    lines = []
    for line in text.splitlines():
        code, sep, comment = line.partition("#")
        lines.append(PATH_RE.sub(rel, code) + sep + comment)
    head = ("# fnv1a64 %016x: derived by `make refs` (test/bench/refs.py) from scenes/%s.rrv at\n"
            "# resolution %s x %s; do not edit. Reference: %s spp in %d renders (seeds 1..%d), %s\n"
            % (entry_hash(fields), name, w, h, fields[3], CHUNKS, CHUNKS, " ".join(fields[6:])))
    path = os.path.join(REF, name + ".rrv")
    open(path, "w").write(head + "\n".join(lines) + "\n")
    return path


def main():
    rrv, compare = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    only = sys.argv[3:]
    tmp = os.path.join(ROOT, "build", "refs")
    os.makedirs(tmp, exist_ok=True)
    listed = set()
    for fields in manifest():
        listed.add(fields[0])
        if only and fields[0] not in only:
            continue
        spp = int(fields[3])
        if spp % CHUNKS:
            sys.exit("refs: %s: REF_SPP %d is not a multiple of %d" % (fields[0], spp, CHUNKS))
        scene = derive_scene(fields)
        t0 = time.time()
        chunks = []
        for c in range(CHUNKS):
            chunks.append(os.path.join(tmp, "%s_%d.exr" % (fields[0], c)))
            subprocess.run([rrv, "render", scene, "-o", chunks[-1], "--exr-float", "--spp", str(spp // CHUNKS),
                            "--seed", str(c + 1), "-q"] + fields[6:], check=True)
        wall = time.time() - t0
        out = os.path.join(REF, fields[0] + ".exr")
        subprocess.run([compare, "--merge", out, os.path.join(REF, fields[0] + "_var.exr"), str(spp // CHUNKS)]
                       + chunks, check=True)
        print("refs: %-14s %s x %s, %6s spp, %6.1f s wall (%d threads), %4d KiB  (%s)"
              % (fields[0], fields[1], fields[2], fields[3], wall, os.cpu_count(),
                 os.path.getsize(out) // 1024, " ".join(fields[6:])), flush=True)
    for f in sorted(os.listdir(os.path.join(ROOT, "scenes"))):
        if f.endswith(".rrv") and f[:-4] not in listed:
            print("refs: scenes/%s has no line in test/ref/refs.txt (no reference)" % f)


if __name__ == "__main__":
    main()
