#!/usr/bin/env python3
"""Adaptive sampling (--noise-threshold) against uniform sampling at equal
CPU time, by RMSE (and relative MSE) against the references of test/ref/ (their resolution).

  python3 test/bench/adaptive.py RRV SCENE:MAXSPP:THRESHOLD... [--rounds R]

For each scene the adaptive render is timed once (one thread, user seconds)
to choose the uniform spp of the same CPU time (a line through timed
64 and 512 spp renders); then R rounds run uniform, adaptive, uniform, adaptive, ... each
round with its own seed (101, 102, ...; the references used 1 to 8). Prints
one line a round and the medians of CPU (user) and wall seconds."""
import os, re, statistics, subprocess, sys, tempfile

def run(rrv, scene, out, args, seed):
    cmd = ['/usr/bin/time', '-f', 'TIME %e %U', 'nice', rrv, 'render', scene, '-o', out, '--exr-float',
           '--threads', '1', '--seed', str(seed)] + args
    p = subprocess.run(cmd, capture_output=True, text=True, check=True)
    wall, user = map(float, re.search(r'TIME (\S+) (\S+)', p.stderr).groups())
    mean = re.search(r'mean ([0-9.]+) \(', p.stderr)
    return wall, user, (float(mean.group(1)) if mean else None), ' '.join(cmd[4:])

def rmse(rrv, out, ref):
    p = subprocess.run([rrv, 'diff', out, ref], capture_output=True, text=True, check=True)
    return (float(re.search(r'^rmse: (\S+)', p.stdout, re.M).group(1)),
            float(re.search(r'^relmse: (\S+)', p.stdout, re.M).group(1)))

def main():
    rrv = sys.argv[1]
    rounds = 2
    specs = []
    args = sys.argv[2:]
    while args:
        a = args.pop(0)
        if a == '--rounds': rounds = int(args.pop(0))
        else: specs.append(a)
    tmp = tempfile.mkdtemp(prefix='rrv_adaptive_')
    for spec in specs:
        name, maxspp, threshold = spec.split(':')
        scene, ref = 'test/ref/%s.rrv' % name, 'test/ref/%s.exr' % name
        out = os.path.join(tmp, name + '.exr')
        adaptive = ['--spp', maxspp, '--noise-threshold', threshold]
        _, t_a, _, _ = run(rrv, scene, out, adaptive, 100)
        # a line through two uniform renders: loading and preparing the
        # scene costs the same at any spp
        _, t_lo, _, _ = run(rrv, scene, out, ['--spp', '64'], 100)
        _, t_hi, _, _ = run(rrv, scene, out, ['--spp', '512'], 100)
        slope = (t_hi - t_lo) / 448.0
        spp = max(1, int(round(64 + (t_a - t_lo) / slope)))
        uniform = ['--spp', str(spp)]
        print('## %s: adaptive %s spp max, threshold %s; uniform %d spp (calibration: adaptive %.2f s, uniform '
              '%.2f s at 64, %.2f s at 512)' % (name, maxspp, threshold, spp, t_a, t_lo, t_hi))
        rows = {'uniform': [], 'adaptive': []}
        for r in range(rounds):
            seed = 101 + r
            for label, extra in (('uniform', uniform), ('adaptive', adaptive)):
                wall, user, mean, cmd = run(rrv, scene, out, extra, seed)
                e, rel = rmse(rrv, out, ref)
                rows[label].append((wall, user, e, rel))
                print('%-8s seed %d: wall %.2f s, cpu %.2f s, rmse %.6g, relmse %.6g%s   (%s)'
                      % (label, seed, wall, user, e, rel, ', mean spp %.1f' % mean if mean else '', cmd))
        for label in ('uniform', 'adaptive'):
            w = statistics.median(x[0] for x in rows[label])
            u = statistics.median(x[1] for x in rows[label])
            e = statistics.median(x[2] for x in rows[label])
            rel = statistics.median(x[3] for x in rows[label])
            print('%-8s median: wall %.2f s, cpu %.2f s, rmse %.6g, relmse %.6g' % (label, w, u, e, rel))
        print()

if __name__ == '__main__':
    main()
