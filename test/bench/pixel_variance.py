#!/usr/bin/env python3
"""Two builds of rrv on one scene, interleaved (A, B, A, B, ...), one
thread: the median CPU time of a render and the variance of each pixel over
the seeds, averaged over the pixels; efficiency 1 / (CPU s x variance).

    python3 test/bench/pixel_variance.py OLD/rrv ./rrv scenes/pyro.rrv --spp 16 --seeds 6
"""
import argparse, os, statistics, sys, tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from campfire import render  # noqa: E402
from nee_bench import read_pfm  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('a')
    ap.add_argument('b')
    ap.add_argument('scene')
    ap.add_argument('--spp', type=int, default=16)
    ap.add_argument('--seeds', type=int, default=6)
    args = ap.parse_args()
    out = os.path.join(tempfile.mkdtemp(prefix='pixvar'), 'v.pfm')
    runs = {'A': ([], []), 'B': ([], [])}
    for seed in range(args.seeds):
        for name, rrv in (('A', args.a), ('B', args.b)):
            runs[name][0].append(render(rrv, args.scene, out, args.spp, 50 + seed, threads=1))
            runs[name][1].append(read_pfm(out))
    cost = {}
    for name, (times, images) in runs.items():
        n = len(images[0])
        var = sum(statistics.variance([im[i] for im in images]) for i in range(n)) / n
        mean = sum(sum(im) for im in images) / (len(images) * n)
        cost[name] = statistics.median(times) * var
        print('%s: CPU %.2f s, pixel variance %.4g, mean %.5f, efficiency %.4g' %
              (name, statistics.median(times), var, mean, 1 / cost[name]))
    print('B over A: efficiency %.2fx' % (cost['A'] / cost['B']))


if __name__ == '__main__':
    main()
