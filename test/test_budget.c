/* Work bounds on hostile densities. The majorant grid bounds the density
   at every point (random coarse grids, boxes, cell counts, with and
   without refraction), exactly where a cell holds part of a voxel; tracking
   through a coarse grid whose box is not the medium's stays unbiased
   (ratio and delta tracking against exp(-tau) to 4 standard errors, fixed
   seeds); and renders of 2^3 grids with a huge value in a corner, an edge
   or a face (what the render fuzzer found) take a bounded number of
   tracking events. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "scene_builder.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Gives the medium a grid density of nx x ny x nz samples over [lo, hi]
   (values left 0 for the caller). */
static float *set_grid(rrv_medium *m, int nx, int ny, int nz, rrv_vec3 lo, rrv_vec3 hi)
{
    rrv_grid *g = &m->density.grid;
    m->density.kind = RRV_FIELD_GRID;
    g->nx = nx;
    g->ny = ny;
    g->nz = nz;
    g->channels = 1;
    g->lo = lo;
    g->hi = hi;
    g->data = (float *)calloc((size_t)nx * ny * nz, sizeof(float));
    return g->data;
}

static double uniform_in(rrv__rng *rng, double a, double b) { return a + (b - a) * rrv__uniform(rng); }


/* The majorant cell holding p, clamped into the grid, as the tracking
   walks find it: the index into the per-cell arrays. */
static size_t cell_of(const struct rrv__majorant_grid *g, rrv_vec3 p)
{
    size_t idx[3];
    int a;
    for (a = 0; a < 3; ++a) {
        double c = (rrv__axis(p, a) - rrv__axis(g->lo, a)) * rrv__axis(g->inv_cell, a);
        idx[a] = !(c >= 0) ? 0 : c >= g->n[a] - 1 ? (size_t)(g->n[a] - 1) : (size_t)c;
    }
    return (idx[2] * (size_t)g->n[1] + idx[1]) * (size_t)g->n[0] + idx[0];
}
/* A point of the box, with each coordinate moved onto one of the grid's
   inner voxel planes one time in three: the corners of the cells' parts
   lie there, where a bound taken from fewer points would first fail. */
static rrv_vec3 probe_point(rrv__rng *rng, rrv_vec3 lo, rrv_vec3 hi, const rrv_grid *g)
{
    double p[3];
    int a;
    for (a = 0; a < 3; ++a) {
        int voxels = (a == 0 ? g->nx : a == 1 ? g->ny : g->nz) - 1;
        double glo = rrv__axis(g->lo, a), ghi = rrv__axis(g->hi, a);
        p[a] = uniform_in(rng, rrv__axis(lo, a), rrv__axis(hi, a));
        if (voxels > 1 && rrv__uniform(rng) < 1.0 / 3.0) {
            int i = 1 + (int)(rrv__uniform(rng) * (voxels - 1));
            double plane = glo + i * (ghi - glo) / voxels;
            if (plane > rrv__axis(lo, a) && plane < rrv__axis(hi, a)) p[a] = plane;
        }
    }
    return rrv__v3(p[0], p[1], p[2]);
}

static void test_majorant_bounds_density_everywhere(void)
{
    /* 300 random media: 2..5 samples an axis, half of them 0 and the rest
       spread over 13 decades (scaled under the optical-depth limit), the
       grid's box overlapping the medium's anyhow; a quarter refract (their
       cells stay on the medium's box), a quarter force the cell count, a
       quarter cap it as the fuzzers do. At 4000 points each, the density
       must never exceed its cell's bound by more than two known slivers:
       the lookup's own rounding (trilinear weights in double put a value a
       few ulps above the sample it equals, and where a cell spans several
       voxels its bound is that sample, unpadded, as it always was: 1e-15
       allows 4 ulps), and rrv__grid_span's rule that a cell reaching less
       than 1e-9 of a voxel into a neighbour does not take its samples (a
       point on a cell's face whose lookup rounds into the next voxel sees
       a fraction ~1e-15 of a sample there: 1e-9 of the grid's peak). */
    rrv__rng rng;
    int trial, violations = 0, checked = 0, refused = 0, refined = 0;
    rrv__rng_seed(&rng, 11, 0, 0);
    for (trial = 0; trial < 300; ++trial) {
        rrv_scene *s = tb_scene(4, 4);
        rrv_error err;
        rrv_vec3 lo = rrv__v3(uniform_in(&rng, -2, 0), uniform_in(&rng, -2, 0), uniform_in(&rng, -2, 0));
        rrv_vec3 hi = rrv__v3(lo.x + uniform_in(&rng, 0.1, 3), lo.y + uniform_in(&rng, 0.1, 3),
                              lo.z + uniform_in(&rng, 0.1, 3));
        rrv_vec3 ext = rrv__sub(hi, lo), glo, ghi;
        rrv_medium *m = tb_medium(s, lo, hi, 0.5, 0.5);
        int nx = 2 + (int)(rrv__uniform(&rng) * 4), ny = 2 + (int)(rrv__uniform(&rng) * 4);
        int nz = 2 + (int)(rrv__uniform(&rng) * 4), i, count = nx * ny * nz, kind = trial % 4;
        float *v;
        double peak = 0, limit, grid_peak;
        const struct rrv__majorant_grid *g;
        glo = rrv__v3(lo.x + ext.x * uniform_in(&rng, -0.5, 0.6), lo.y + ext.y * uniform_in(&rng, -0.5, 0.6),
                      lo.z + ext.z * uniform_in(&rng, -0.5, 0.6));
        ghi = rrv__v3(glo.x + ext.x * uniform_in(&rng, 0.05, 1.2), glo.y + ext.y * uniform_in(&rng, 0.05, 1.2),
                      glo.z + ext.z * uniform_in(&rng, 0.05, 1.2));
        v = set_grid(m, nx, ny, nz, glo, ghi);
        for (i = 0; i < count; ++i) {
            v[i] = rrv__uniform(&rng) < 0.5 ? 0.0f : (float)pow(10.0, uniform_in(&rng, -3, 10));
            peak = fmax(peak, v[i]);
        }
        limit = 1e11 / rrv__length(ext);
        if (peak > limit)
            for (i = 0; i < count; ++i) v[i] = (float)(v[i] * (limit / peak));
        for (grid_peak = 0, i = 0; i < count; ++i) grid_peak = fmax(grid_peak, v[i]);
        if (kind == 1) {
            m->ior.kind = RRV_FIELD_SLAB;
            m->ior.base = 0.01;
            m->ior.gradient = 0.01;
            m->ior.normal = rrv__v3(1, 0, 0);
            m->ior.center = lo;
        }
        if (kind == 2) s->settings.majorant_cells = 1 + (int)(rrv__uniform(&rng) * 20);
        if (kind == 3) s->settings.max_bake_samples = 16;
        if (rrv_scene_prepare(s, &err) != RRV_OK) {
            ++refused;
            printf("  trial %d refused: %s\n", trial, err.message);
            rrv_scene_free(s);
            continue;
        }
        g = m->majorant;
        refined += g->n[0] > 16 || g->n[1] > 16 || g->n[2] > 16 || g->lo.x != lo.x;
        for (i = 0; i < 4000; ++i) {
            rrv_vec3 p = probe_point(&rng, lo, hi, &m->density.grid);
            size_t c = cell_of(g, p);
            double density = rrv__field_eval(&m->density, p, 0, 0.0);
            if (!(density <= g->density_max[c] * (1 + 1e-15) + 1e-9 * grid_peak)) {
                if (violations < 5)
                    printf("  trial %d: density %.17g at (%.17g %.17g %.17g) above its cell's bound %.17g\n", trial,
                           density, p.x, p.y, p.z, (double)g->density_max[c]);
                ++violations;
            }
            ++checked;
        }
        rrv_scene_free(s);
    }
    CHECKF(violations == 0, "%d of %d points above their cell's bound", violations, checked);
    CHECKF(refused == 0, "%d media refused", refused);
    /* the cases the test is about: cells finer than 16 or moved onto the grid */
    CHECKF(refined > 30, "only %d media with refined cells", refined);
}

static void test_majorant_of_a_coarse_grid_is_tight(void)
{
    /* A 2^3 grid of 1e10 in one corner, 0 elsewhere, filling the medium:
       its one voxel split into 16 cells an axis, each bounding the
       trilinear field by its value at the cell's corner nearest the hot
       one. The cell at the far corner gets 1e10 (1/16)^3; the max of the
       samples (the old bound) gave it 1e10. */
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(0, 0, 0), rrv__v3(1, 1, 1), 0.5, 0.5);
    const struct rrv__majorant_grid *g;
    double far, expected = 1e10 / 4096.0, mid;
    float *v = set_grid(m, 2, 2, 2, m->lo, m->hi);
    v[0] = 1e10f;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    g = m->majorant;
    CHECKF(g->n[0] == 16 && g->n[1] == 16 && g->n[2] == 16, "%d x %d x %d cells", g->n[0], g->n[1], g->n[2]);
    far = g->density_max[(size_t)16 * 16 * 16 - 1];
    /* up to the bound's margin for rounding (1e-9 of the samples' max) */
    CHECKF(far >= expected && far <= (expected + 10.0) * (1 + 3e-7), "far cell %.9g, expected %.9g", far, expected);
    /* the cell at (8, 0, 0): its nearest corner is at u = 1/2 */
    mid = g->density_max[8];
    CHECKF(mid >= 0.5e10 && mid <= (0.5e10 + 10.0) * (1 + 3e-7), "cell (8, 0, 0) %.9g, expected 5e9", mid);
    rrv_scene_free(s);
}

static void test_finer_cells_never_cost_a_refusal(void)
{
    /* The same grid under a grid limit of 4 KiB: 16^3 cells (16 KiB) would
       break it, so the medium keeps the automatic 4^3 and still loads. */
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(0, 0, 0), rrv__v3(1, 1, 1), 0.5, 0.5);
    float *v = set_grid(m, 2, 2, 2, m->lo, m->hi);
    v[0] = 1e10f;
    s->max_grid_bytes = 4096;
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    CHECKF(m->majorant->n[0] == 4 && m->majorant->n[1] == 4 && m->majorant->n[2] == 4, "%d x %d x %d cells",
           m->majorant->n[0], m->majorant->n[1], m->majorant->n[2]);
    rrv_scene_free(s);
}

/* Mean and standard error of a batch of estimates. */
typedef struct tally { double sum, sum2; long n; } tally;
static void tally_add(tally *t, double x) { t->sum += x; t->sum2 += x * x; t->n++; }
static double tally_mean(const tally *t) { return t->sum / t->n; }
static double tally_se(const tally *t)
{
    double mean = tally_mean(t);
    return sqrt(fmax(t->sum2 / t->n - mean * mean, 0) / t->n);
}

/* The optical depth along o + t d, t in [0, tmax], by Simpson's rule on
   2^16 intervals (the field is cubic in t inside a voxel and the rule is
   exact for cubics, so only the few intervals across voxel faces err). */
static double optical_depth(const rrv_medium *m, rrv_vec3 o, rrv_vec3 d, double tmax)
{
    int i, n = 1 << 16;
    double h = tmax / n, sum = 0;
    for (i = 0; i <= n; ++i) {
        rrv_vec3 p = rrv__madd(o, d, i * h);
        double f = rrv__inside_box(p, m->lo, m->hi) ? rrv__field_eval(&m->density, p, 0, 0.0) : 0.0;
        sum += f * (i == 0 || i == n ? 1 : i % 2 ? 4 : 2);
    }
    return sum * h / 3.0 * (m->sigma_a[1] + m->sigma_s[1]);
}

static void test_tracking_through_a_coarse_grid_is_unbiased(void)
{
    /* A 2^3 grid of 400 in one corner (and 3 in the opposite one) inside a
       larger medium, its box not on the medium's: the cells are moved onto
       the grid's faces (the first starts outside the medium) and split 16
       an axis. Ratio and delta tracking must match exp(-tau) within 4
       standard errors for rays through the nearly empty side. */
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.2, 0.8);
    float *v = set_grid(m, 2, 2, 2, rrv__v3(-0.55, -0.6, -0.45), rrv__v3(0.7, 0.5, 0.5));
    const rrv_vec3 origins[2] = {{-2, 0.45, 0.45}, {-2, -1.6, 0.493}};
    const rrv_vec3 dirs[2] = {{1, 0, 0}, {0.8, 0.6, 0}};
    rrv__context ctx;
    int k;
    v[0] = 400.0f;
    v[7] = 3.0f;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECKF(m->majorant->lo.x < m->lo.x && m->majorant->n[0] > 16, "cells from %g, %d an axis", m->majorant->lo.x,
           m->majorant->n[0]);
    memset(&ctx, 0, sizeof ctx);
    ctx.scene = s;
    ctx.eta_camera2 = 1;
    for (k = 0; k < 2; ++k) {
        rrv__rng rng;
        tally ratio = {0, 0, 0}, delta = {0, 0, 0};
        double tau = optical_depth(m, origins[k], dirs[k], 5.0), expected = exp(-tau);
        int i, n = 200000;
        rrv__rng_seed(&rng, 7, k, 0);
        for (i = 0; i < n; ++i) {
            double T[3];
            rrv__path path;
            rrv__flight flight;
            int outcome;
            rrv__ratio_tracking_transmittance(&ctx, origins[k], dirs[k], 5.0, &rng, T);
            tally_add(&ratio, T[1]);
            rrv__path_start(&path, &rng);
            outcome = rrv__refractive_delta_tracking(&ctx, &path, origins[k], dirs[k], 5.0, &rng, &flight);
            tally_add(&delta, outcome == RRV__FLIGHT_PASSED ? path.beta[1] * rrv__path_mis(&path) : 0.0);
        }
        printf("  ray %d: tau %.4f, ratio tracking %.4f +- %.4f, delta tracking %.4f +- %.4f\n", k, tau,
               tally_mean(&ratio), tally_se(&ratio), tally_mean(&delta), tally_se(&delta));
        /* a ray whose transmittance is neither 0 nor 1 tests something */
        CHECKF(tau > 0.2 && tau < 3, "ray %d: tau %g", k, tau);
        CHECKF(fabs(tally_mean(&ratio) - expected) < 4 * tally_se(&ratio), "ray %d: ratio tracking %g +- %g, exp(-tau) %g",
               k, tally_mean(&ratio), tally_se(&ratio), expected);
        CHECKF(fabs(tally_mean(&delta) - expected) < 4 * tally_se(&delta), "ray %d: delta tracking %g +- %g, exp(-tau) %g",
               k, tally_mean(&delta), tally_se(&delta), expected);
    }
    CHECKF(ctx.stats.paths_cut == 0, "%lu walks cut", (unsigned long)ctx.stats.paths_cut);
    rrv_scene_free(s);
}

/* A 2^3 grid over [-1, 1]^3 ramping along x from 0 on the face x = -1 to
   `peak` on x = 1: the density at x is peak (x + 1) / 2 on every line. */
static rrv_medium *ramp_medium(rrv_scene *s, double peak, const double sigma_a[3], const double sigma_s[3])
{
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.5, 0.5);
    float *v = set_grid(m, 2, 2, 2, m->lo, m->hi);
    int i;
    for (i = 0; i < 8; ++i) v[i] = i & 1 ? (float)peak : 0.0f;
    for (i = 0; i < 3; ++i) {
        m->sigma_a[i] = sigma_a[i];
        m->sigma_s[i] = sigma_s[i];
    }
    return m;
}

static void test_tracking_through_a_steep_ramp_is_unbiased(void)
{
    /* The render fuzzer's ramp, 0 to 7e10 across a 2 m voxel, under cells
       of 1/16 of it: a crossing of the first cell holds an optical depth of
       up to 5e8 at its bound, far over RRV__SPLIT_DEPTH, so these walks go
       in pieces with bounds of their own. Along a line the density is
       linear in t, so the optical depth has a closed form: a ray entering
       the thin face at x = -1 with direction component dx has
       tau(s) = k peak dx s^2 / 4 after s metres; a ray parallel to the face
       at x0 has k peak (x0 + 1) / 2 per metre. Three rays: in through the
       thin face, out through it (the density falling along the ray), and
       parallel to it 1.4e-11 m inside (a box of no width across x); each
       with grey extinction, and with three channel groups (k 1, 0.1, 0.01:
       ratio tracking walks each group, delta tracking pauses at every
       piece to reweight). Ratio and delta tracking must match exp(-tau)
       per channel within 4 standard errors (20000 walks, fixed seeds: a
       majorant 10 % low in the pieces still fails it; 50000 cost 4.7 s
       more of make test's CPU),
       and take few tentative collisions (with the cell's bound as the
       majorant, ~1e5 a walk on the first ray). */
    static const double grey_a[3] = {0.2, 0.2, 0.2}, grey_s[3] = {0.8, 0.8, 0.8};
    static const double chroma_a[3] = {0.2, 0.02, 0.002}, chroma_s[3] = {0.8, 0.08, 0.008};
    const double peak = (double)(float)7e10, dx = 0.6;
    int spectrum, k;
    for (spectrum = 0; spectrum < 2; ++spectrum) {
        rrv_scene *s = tb_scene(4, 4);
        rrv_error err;
        rrv_medium *m = ramp_medium(s, peak, spectrum ? chroma_a : grey_a, spectrum ? chroma_s : grey_s);
        rrv__context ctx;
        CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
        CHECKF(m->majorant->channel_groups == (spectrum ? 3 : 1), "%d channel groups", m->majorant->channel_groups);
        memset(&ctx, 0, sizeof ctx);
        ctx.scene = s;
        ctx.eta_camera2 = 1;
        for (k = 0; k < 3; ++k) {
            /* s0: the length inside the medium that gives the first channel tau 1.5 */
            double s0 = sqrt(4.0 * 1.5 / (peak * dx)), x0 = -1 + 1.4e-11, tau0, tmax, steps;
            rrv_vec3 o, d;
            rrv__rng rng;
            tally ratio[3], delta[3];
            int i, ch, n = 20000;
            uint64_t events0 = ctx.stats.events;
            if (k == 0) { /* in through the thin face from 0.5 m outside */
                d = rrv__v3(dx, 0.8, 0);
                o = rrv__madd(rrv__v3(-1, 0.1, 0.2), d, -0.5 / dx);
                tmax = 0.5 / dx + s0;
                tau0 = peak * dx * s0 * s0 / 4;
            } else if (k == 1) { /* out through it, from s0 inside */
                d = rrv__v3(-dx, -0.8, 0);
                o = rrv__madd(rrv__v3(-1, 0.1, 0.2), d, -s0);
                tmax = s0 + 0.5;
                tau0 = peak * dx * s0 * s0 / 4;
            } else { /* parallel to it, across the box */
                d = rrv__v3(0, 1, 0);
                o = rrv__v3(x0, -1.5, 0.3);
                tmax = 3;
                tau0 = peak * (x0 + 1) / 2 * 2;
            }
            memset(ratio, 0, sizeof ratio);
            memset(delta, 0, sizeof delta);
            rrv__rng_seed(&rng, 23, (uint64_t)(3 * spectrum + k), 0);
            for (i = 0; i < n; ++i) {
                double T[3];
                rrv__path path;
                rrv__flight flight;
                int outcome;
                rrv__ratio_tracking_transmittance(&ctx, o, d, tmax, &rng, T);
                rrv__path_start(&path, &rng);
                outcome = rrv__refractive_delta_tracking(&ctx, &path, o, d, tmax, &rng, &flight);
                for (ch = 0; ch < 3; ++ch) {
                    tally_add(&ratio[ch], T[ch]);
                    tally_add(&delta[ch], outcome == RRV__FLIGHT_PASSED ? path.beta[ch] * rrv__path_mis(&path) : 0.0);
                }
            }
            steps = (double)(ctx.stats.events - events0) / (2.0 * n);
            for (ch = 0; ch < 3; ++ch) {
                double kc = m->sigma_a[ch] + m->sigma_s[ch], expected = exp(-tau0 * kc);
                printf("  %s ray %d channel %d: exp(-tau) %.4f, ratio tracking %.4f +- %.4f, delta tracking %.4f +- "
                       "%.4f\n", spectrum ? "chromatic" : "grey", k, ch, expected, tally_mean(&ratio[ch]),
                       tally_se(&ratio[ch]), tally_mean(&delta[ch]), tally_se(&delta[ch]));
                CHECKF(fabs(tally_mean(&ratio[ch]) - expected) < 4 * tally_se(&ratio[ch]) + 1e-12,
                       "%s ray %d channel %d: ratio tracking %g +- %g, exp(-tau) %g", spectrum ? "chromatic" : "grey",
                       k, ch, tally_mean(&ratio[ch]), tally_se(&ratio[ch]), expected);
                CHECKF(fabs(tally_mean(&delta[ch]) - expected) < 4 * tally_se(&delta[ch]) + 1e-12,
                       "%s ray %d channel %d: delta tracking %g +- %g, exp(-tau) %g", spectrum ? "chromatic" : "grey",
                       k, ch, tally_mean(&delta[ch]), tally_se(&delta[ch]), expected);
            }
            /* tau 1.5 is a few collisions a walk at a rate that follows the
               density; the parallel ray pays the bound's floor, 1e-9 of the
               voxel's samples (rrv__grid_bound's margin for rounding: 70 a
               metre here, 140 across the box) */
            printf("  %s ray %d: %.2f tentative collisions a walk\n", spectrum ? "chromatic" : "grey", k, steps);
            CHECKF(steps < (k < 2 ? 10 : 10 + 2e-9 * peak * 2), "%s ray %d: %g tentative collisions a walk",
                   spectrum ? "chromatic" : "grey", k, steps);
        }
        CHECKF(ctx.stats.paths_cut == 0, "%lu walks cut", (unsigned long)ctx.stats.paths_cut);
        rrv_scene_free(s);
    }
}

static void test_hostile_coarse_grids_take_bounded_work(void)
{
    /* The shapes the render fuzzer found: a 2^3 grid in a 2 m box, 7e10 on
       one corner, edge or face and 0 elsewhere (extinction 7e10: an
       optical depth of 2.4e11 across the box, a quarter of what rrv
       accepts), seen from its empty side and lit by a sphere behind it,
       8 bounces, 4x4 pixels of 4 samples. With every cell bounded by the
       samples' max these took 4e6 to 1.1e7 events a sample, with walks cut;
       with cells on parts of the voxel, 1.3e5 (corner), 1.8e5 (edge) and
       2.8e5 (face: the render fuzzer's input, test/fuzz_regressions/
       render-render-gridvol-2cubed-face-7e10.bin), a path that scattered in
       the thin layer where the density rises from 0 paying the cell's
       bound for leaving it. With crossings split into pieces that follow
       the density (rrv__majorant_piece), measured 28, 25 and 28. The check
       allows 1000 a sample and no cut walk. */
    static const int hot[3][8] = {{1, 0, 0, 0, 0, 0, 0, 0}, {1, 1, 0, 0, 0, 0, 0, 0}, {1, 1, 1, 1, 0, 0, 0, 0}};
    static const char *names[3] = {"corner", "edge", "face"};
    int shape;
    for (shape = 0; shape < 3; ++shape) {
        rrv_scene *s = tb_scene(4, 4);
        rrv_error err;
        rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
        rrv_shape *light = tb_shape(s, RRV_SHAPE_SPHERE);
        rrv_render_stats st;
        float img[4 * 4 * 3];
        float *v = set_grid(m, 2, 2, 2, m->lo, m->hi);
        int i;
        for (i = 0; i < 8; ++i) v[i] = hot[shape][i] ? 7e10f : 0.0f;
        light->center = rrv__v3(0, 0, -2);
        light->radius = 1;
        light->L[0] = light->L[1] = light->L[2] = 2;
        s->camera.eye = rrv__v3(0, 0, 5);
        s->camera.look = rrv__v3(0, 0, 0);
        s->settings.max_depth = 8;
        CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
        memset(&st, 0, sizeof st);
        CHECK(rrv_render_rect(s, 0, 0, 4, 4, 0, 4, img, 4, &st, NULL) == RRV_OK);
        printf("  %s: %.0f events a sample\n", names[shape], (double)st.events / (double)st.samples);
        CHECKF(st.events < 1000 * st.samples && st.paths_cut == 0, "%s: %lu events in %lu samples, %lu cut",
               names[shape], (unsigned long)st.events, (unsigned long)st.samples, (unsigned long)st.paths_cut);
        rrv_scene_free(s);
    }
}

/* A closed white sphere (albedo 1: Russian roulette never ends a path)
   filled with a weak IOR slab, rendered by the eikonal integrator at its
   smallest accepted step, 1e-6 m, and no light sampling: every leg is a
   chord of ~1 m, 1e6 steps, under its bound of 1e7, and nothing ends a
   path before max_depth. */
static rrv_scene *white_sphere_of_tiny_steps(int max_depth)
{
    rrv_scene *s = tb_scene(2, 1);
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 0.0);
    rrv_shape *room = tb_shape(s, RRV_SHAPE_SPHERE);
    int c;
    m->ior.kind = RRV_FIELD_SLAB;
    m->ior.base = 0.01;
    m->ior.gradient = 0.01;
    m->ior.normal = rrv__v3(0, 1, 0);
    m->ior.center = rrv__v3(0, 0, 0);
    room->center = rrv__v3(0, 0, 0);
    room->radius = 0.9;
    for (c = 0; c < 3; ++c) s->materials[0].albedo[c] = 1.0;
    s->camera.eye = rrv__v3(0, 0, -0.5);
    s->camera.look = rrv__v3(0, 0, 1);
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.step = 1e-6;
    s->settings.nee = RRV_NEE_NONE;
    s->settings.max_depth = max_depth;
    return s;
}

static void test_a_sample_of_long_legs_is_cut_at_its_work_bound(void)
{
    /* Two legs (max_depth 1) take E steps a sample, uncut; 1025 legs would
       take ~512 E, over 50 times RRV_MAX_SAMPLE_WORK (measured: E = 2.7e6,
       so 1.4e9 steps, minutes a sample).
       With max_depth 1024 every sample must be cut at the sample's bound
       (no leg at its own), counted, its steps (events here: no tracking)
       at most the bound and at least a quarter of it (each step is a loop
       iteration and an event, so the cut comes at half). */
    rrv_scene *s = white_sphere_of_tiny_steps(1);
    rrv_render_stats st;
    rrv_error err;
    float img[2 * 1 * 3];
    double two_legs;
    int i;
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    CHECKF(rrv__step_bound(s, RRV_INTEGRATOR_EIKONAL) == RRV_MAX_SEGMENT_STEPS, "step bound %ld",
           rrv__step_bound(s, RRV_INTEGRATOR_EIKONAL));
    CHECKF(rrv__sample_bound(s, RRV_INTEGRATOR_EIKONAL) == (uint64_t)RRV_MAX_SAMPLE_WORK, "sample bound %llu",
           (unsigned long long)rrv__sample_bound(s, RRV_INTEGRATOR_EIKONAL));
    memset(&st, 0, sizeof st);
    memset(img, 0, sizeof img);
    CHECK(rrv_render_rect(s, 0, 0, 2, 1, 0, 1, img, 2, &st, NULL) == RRV_OK);
    two_legs = (double)st.events / (double)st.samples;
    printf("  max_depth 1: %.3g steps a sample, %llu cut\n", two_legs, (unsigned long long)st.paths_cut);
    CHECKF(st.samples == 2 && st.paths_cut == 0, "%llu samples, %llu cut", (unsigned long long)st.samples,
           (unsigned long long)st.paths_cut);
    CHECKF(two_legs * 512 > 50.0 * RRV_MAX_SAMPLE_WORK, "two legs take only %g steps", two_legs);
    rrv_scene_free(s);

    s = white_sphere_of_tiny_steps(1024);
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    memset(&st, 0, sizeof st);
    memset(img, 0, sizeof img);
    CHECK(rrv_render_rect(s, 0, 0, 2, 1, 0, 1, img, 2, &st, NULL) == RRV_OK);
    printf("  max_depth 1024: %.3g steps a sample, %llu of %llu samples cut at the sample's bound\n",
           (double)st.events / (double)st.samples, (unsigned long long)st.cut_samples,
           (unsigned long long)st.samples);
    CHECKF(st.samples == 2 && st.cut_samples == st.samples && st.paths_cut == st.cut_samples &&
               st.cut_tracking == 0,
           "%llu samples, %llu cut, %llu of them at the sample's bound", (unsigned long long)st.samples,
           (unsigned long long)st.paths_cut, (unsigned long long)st.cut_samples);
    CHECKF(st.events <= st.samples * (uint64_t)RRV_MAX_SAMPLE_WORK &&
               st.events >= st.samples * (uint64_t)(RRV_MAX_SAMPLE_WORK / 4),
           "%llu steps in %llu samples", (unsigned long long)st.events, (unsigned long long)st.samples);
    /* what the cut samples gathered is kept: no light here, so 0, finite */
    for (i = 0; i < 6; ++i) CHECKF(img[i] == 0.0f, "pixel value %g", img[i]);
    rrv_scene_free(s);
}

static void test_a_deep_path_between_surfaces_alone_is_not_cut(void)
{
    /* No medium: the scene's term is the vertices' own iterations, so a
       white room at max_depth 1024 (1025 legs of one iteration, nothing
       to track) must render uncut with every integrator. */
    static const rrv_integrator integrators[3] = {RRV_INTEGRATOR_CLASSIC, RRV_INTEGRATOR_REFRACTIVE,
                                                  RRV_INTEGRATOR_EIKONAL};
    int k;
    for (k = 0; k < 3; ++k) {
        rrv_scene *s = tb_scene(2, 1);
        rrv_shape *room = tb_shape(s, RRV_SHAPE_SPHERE);
        rrv_render_stats st;
        rrv_error err;
        float img[2 * 1 * 3];
        int c;
        room->center = rrv__v3(0, 0, 0);
        room->radius = 0.9;
        for (c = 0; c < 3; ++c) s->materials[0].albedo[c] = 1.0;
        s->camera.eye = rrv__v3(0, 0, -0.5);
        s->camera.look = rrv__v3(0, 0, 1);
        s->settings.integrator = integrators[k];
        s->settings.max_depth = 1024;
        CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
        memset(&st, 0, sizeof st);
        memset(img, 0, sizeof img);
        CHECK(rrv_render_rect(s, 0, 0, 2, 1, 0, 4, img, 2, &st, NULL) == RRV_OK);
        CHECKF(st.samples == 8 && st.paths_cut == 0, "integrator %d: %llu samples, %llu cut", k,
               (unsigned long long)st.samples, (unsigned long long)st.paths_cut);
        rrv_scene_free(s);
    }
}

int main(void)
{
    (void)tb_blobs; /* scene_builder.h's, unused here */
    RUN(test_majorant_bounds_density_everywhere);
    RUN(test_majorant_of_a_coarse_grid_is_tight);
    RUN(test_finer_cells_never_cost_a_refusal);
    RUN(test_tracking_through_a_coarse_grid_is_unbiased);
    RUN(test_tracking_through_a_steep_ramp_is_unbiased);
    RUN(test_hostile_coarse_grids_take_bounded_work);
    RUN(test_a_sample_of_long_legs_is_cut_at_its_work_bound);
    RUN(test_a_deep_path_between_surfaces_alone_is_not_cut);
    return CHECK_EXIT_CODE();
}
