#!/usr/bin/env python3
"""Fire as a light: efficiency 1 / (CPU s x MSE) of emission NEE against
paths alone on test/bench/campfire.rrv, over the wall and floor (the pixels
that do not see the flame), one thread, runs interleaved (on, off, on, ...),
medians. The reference of each maxdepth is a render with emission NEE at
--ref-spp samples; the mask, the flame alone (the scene without its quads).

    python3 test/bench/campfire.py ./rrv --depths 1 2 32 --reps 5

--hot-air puts the flame in a box of hot, refracting air (the refractive
integrator; every connection to the flame then goes through refraction).
--sky "R G B" puts it under a constant sky of that radiance: "paths only"
then samples the sky as a light, the default gives the flame its samples.
--scene PATH takes another flame beside a wall and floor, such as
test/bench/smoky_campfire.rrv (the NanoVDB fire of scenes/pyro.rrv in its
own dense smoke). --fill L adds a 0.4 m square light of radiance L above and beside the flame
(facing down): the default then shares each vertex's light draw between
the flame and the light by power, `emissionnee on` gives the flame a draw
of its own; both are measured against paths alone.
"""
import argparse, os, re, resource, statistics, subprocess, sys, tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from nee_bench import read_pfm  # noqa: E402

HOT_AIR = """medium air box -1.3 -0.01 -1.0 1.3 3.4 1.0 sigma_a 0 0 0 sigma_s 0 0 0
temperature air noise octaves 2 frequency 2.5 seed 5 falloff plume center 0 1.0 0 radius 0.9 amplitude 600 base 0 temperatureoffset -300 blackbody off
ior air gas iorscale 300
ambient ior 1.0876
"""


def render(rrv, scene, out, spp, seed, threads=None):
    cmd = [rrv, 'render', scene, '-o', out, '-q', '--spp', str(spp), '--seed', str(seed)]
    if threads:
        cmd += ['--threads', str(threads)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.check_call(cmd)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('rrv')
    ap.add_argument('--depths', type=int, nargs='+', default=[1, 2, 32])
    ap.add_argument('--reps', type=int, default=5)
    ap.add_argument('--ref-spp', type=int, default=2048)
    ap.add_argument('--spp-on', type=int, default=16)
    ap.add_argument('--spp-off', type=int, default=96)
    ap.add_argument('--hot-air', action='store_true')
    ap.add_argument('--sky', default='', help='a constant sky\'s radiance, "R G B"')
    ap.add_argument('--extra', default='', help='more render keys for the NEE runs, e.g. "transmittance residual"')
    ap.add_argument('--fill', type=float, default=0, help='a fill light of this radiance beside the flame')
    ap.add_argument('--scene', default=os.path.join(HERE, 'campfire.rrv'),
                    help='another flame beside a wall and floor (test/bench/smoky_campfire.rrv)')
    a = ap.parse_args()
    text = open(a.scene).read()
    # the variants are written elsewhere: grid paths become absolute
    base = os.path.dirname(os.path.abspath(a.scene))
    text = re.sub(r'\b(nanovdb|grid) (?!/)(\S+)', lambda m: m.group(1) + ' ' + os.path.normpath(os.path.join(base, m.group(2))), text)
    if a.hot_air:
        text = text.replace('integrator classic', 'integrator refractive') + HOT_AIR
    if a.sky:
        text += 'environment constant L %s\n' % a.sky
    if a.fill:
        text += 'quad origin 2.5 3 -2  u 0.4 0 0  v 0 0 0.4  L %g %g %g\n' % (a.fill, a.fill, a.fill)
    tmp = tempfile.mkdtemp(prefix='campfire')
    flame = os.path.join(tmp, 'flame.rrv')
    with open(flame, 'w') as f:
        f.write(re.sub(r'(?m)^(quad|environment) .*\n', '', text))
    render(a.rrv, flame, os.path.join(tmp, 'mask.pfm'), 64, 1)
    mask = read_pfm(os.path.join(tmp, 'mask.pfm'))
    lit = [i for i in range(len(mask) // 3) if mask[3 * i] + mask[3 * i + 1] + mask[3 * i + 2] == 0]
    modes = ('default', 'on', 'off') if a.fill else ('on', 'off')
    if a.fill:
        print('| maxdepth | default (a shared draw), %d spp: MSE, CPU s | on (a draw of its own), %d spp: MSE, CPU s '
              '| paths only, %d spp: MSE, CPU s | efficiency over paths: default, on |' % (a.spp_on, a.spp_on, a.spp_off))
        print('|---|---|---|---|---|')
    else:
        print('| maxdepth | NEE, %d spp: MSE, CPU s | paths only, %d spp: MSE, CPU s | efficiency, NEE over paths |'
              % (a.spp_on, a.spp_off))
        print('|---|---|---|---|')
    for depth in a.depths:
        scenes = {}
        for mode in modes:
            keys = 'maxdepth %d' % depth + ('' if mode == 'default' else ' emissionnee %s' % mode) + \
                (' ' + a.extra if mode != 'off' and a.extra else '')
            scenes[mode] = os.path.join(tmp, 'd%d_%s.rrv' % (depth, mode))
            with open(scenes[mode], 'w') as f:
                f.write(re.sub(r'maxdepth \d+', keys, text, count=1))
        ref_path = os.path.join(tmp, 'ref%d.pfm' % depth)
        render(a.rrv, scenes['on'], ref_path, a.ref_spp, 1)
        ref = read_pfm(ref_path)
        runs = {m: [] for m in modes}
        for k in range(a.reps):
            for mode in modes:
                spp = a.spp_off if mode == 'off' else a.spp_on
                out = os.path.join(tmp, 'run.pfm')
                t = render(a.rrv, scenes[mode], out, spp, 100 + k, threads=1)
                img = read_pfm(out)
                mse = sum((img[3 * i + c] - ref[3 * i + c]) ** 2 for i in lit for c in range(3)) / (3 * len(lit))
                runs[mode].append((t, mse))
        med = {m: (statistics.median(r[1] for r in runs[m]), statistics.median(r[0] for r in runs[m])) for m in runs}
        ratio = {m: (med['off'][0] * med['off'][1]) / (med[m][0] * med[m][1]) for m in modes if m != 'off'}
        if a.fill:
            print('| %d | %.3g, %.3f | %.3g, %.3f | %.3g, %.3f | **%.2fx**, %.2fx |'
                  % (depth, med['default'][0], med['default'][1], med['on'][0], med['on'][1], med['off'][0],
                     med['off'][1], ratio['default'], ratio['on']))
        else:
            print('| %d | %.3g, %.3f | %.3g, %.3f | **%.2fx** |' % (depth, med['on'][0], med['on'][1], med['off'][0],
                                                                 med['off'][1], ratio['on']))


if __name__ == '__main__':
    main()
