/* The transmittance estimators (rrv_settings.transmittance): residual
   ratio tracking and unbiased ray marching against exp(-tau) and against
   ratio tracking, fixed seeds, 4 standard errors; where the minorant is the
   density (a constant) both are exact with no variance at all; and the
   majorant grid's minorant is a lower bound of the density at random
   points of every cell (grids, NanoVDB, blobs, constants). */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "scene_builder.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct tr_tally {
    double n, sum, sq;
} tr_tally;

static void tr_add(tr_tally *t, double x)
{
    t->n += 1;
    t->sum += x;
    t->sq += x * x;
}
static double tr_mean(const tr_tally *t) { return t->sum / t->n; }
static double tr_se(const tr_tally *t)
{
    double m = tr_mean(t);
    return sqrt(fmax(0.0, t->sq / t->n - m * m) / (t->n - 1));
}

static rrv__context tr_context(rrv_scene *s)
{
    rrv__context ctx;
    memset(&ctx, 0, sizeof ctx);
    ctx.scene = s;
    ctx.eta_camera2 = 1;
    return ctx;
}

/* Simpson's rule on 2^16 intervals: the exact optical depth of one channel. */
static double tr_depth(const rrv_medium *m, rrv_vec3 o, rrv_vec3 d, double tmax, int ch)
{
    int i, n = 1 << 16;
    double h = tmax / n, sum = 0;
    for (i = 0; i <= n; ++i) {
        rrv__coeffs c;
        rrv_vec3 p = rrv__madd(o, d, i * h);
        double f = 0;
        if (rrv__inside_box(p, m->lo, m->hi)) {
            rrv__medium_coeffs(m, p, &c);
            f = c.sigma_a[ch] + c.sigma_s[ch];
        }
        sum += f * (i == 0 || i == n ? 1 : i % 2 ? 4 : 2);
    }
    return sum * h / 3.0;
}

static const rrv_transmittance tr_kinds[3] = {RRV_TRANSMITTANCE_RATIO, RRV_TRANSMITTANCE_RESIDUAL,
                                              RRV_TRANSMITTANCE_MARCH};
static const char *tr_names[3] = {"ratio", "residual", "march"};

static void test_homogeneous_slab(void)
{
    /* A slab 0.8 m thick of constant density 2 (a float exactly, so the
       minorant equals the bound) and sigma_t 1.5, crossed at an angle:
       every estimator within 4 standard errors of exp(-sigma d), and
       residual and march with no variance: every estimate exp(-sigma d) to
       1e-12. */
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -0.4), rrv__v3(1, 1, 0.4), 0.5, 1.0);
    rrv_vec3 o = rrv__v3(0.1, -0.2, -2), d = rrv__normalize(rrv__v3(0.3, 0.1, 1));
    double expected, len = 4.0 / d.z;
    rrv__context ctx;
    int e, i;
    m->density.value = 2.0;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    expected = exp(-1.5 * 2.0 * 0.8 / d.z);
    ctx = tr_context(s);
    for (e = 0; e < 3; ++e) {
        rrv__rng rng;
        tr_tally t = {0, 0, 0};
        double worst = 0;
        rrv__rng_seed(&rng, 31, (uint64_t)e, 0);
        s->settings.transmittance = tr_kinds[e];
        for (i = 0; i < 20000; ++i) {
            double T[3];
            rrv__transmittance(&ctx, o, d, len, &rng, T);
            tr_add(&t, T[1]);
            worst = fmax(worst, fabs(T[1] - expected));
        }
        printf("  slab, %-8s %.6f +- %.6f (exp(-sigma d) %.6f), largest error %.3g\n", tr_names[e], tr_mean(&t),
               tr_se(&t), expected, worst);
        CHECKF(fabs(tr_mean(&t) - expected) <= 4 * tr_se(&t) + 1e-12, "%s: %g +- %g, expected %g", tr_names[e],
               tr_mean(&t), tr_se(&t), expected);
        if (e > 0) CHECKF(worst <= 1e-12 * expected, "%s: an estimate %g off exp(-sigma d)", tr_names[e], worst);
    }
    rrv_scene_free(s);
}

static void check_minorant(const char *what, const rrv_medium *m, uint64_t seed, long *positive);

static void test_heterogeneous_grid(void)
{
    /* A 9^3 grid of random densities in [0.1, 0.35] in a
       unit box, with chromatic extinctions (4, 1.6, 24 x density: two
       channel groups, 24 alone). Per ray and channel, residual and march agree with
       ratio tracking's mean and with exp(-tau) (Simpson) within 4 combined
       standard errors; the rays' transmittances lie between 0.02 and 0.9,
       where a bias would show. */
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(0, 0, 0), rrv__v3(1, 1, 1), 0.0, 1.0);
    rrv_grid *g = &m->density.grid;
    const rrv_vec3 origins[3] = {{-1, 0.3, 0.6}, {0.5, 0.5, 0.5}, {0.1, -0.5, 0.2}};
    const rrv_vec3 ends[3] = {{2, 0.7, 0.4}, {0.9, 1.5, 0.8}, {0.8, 1.6, 0.9}};
    rrv__context ctx;
    rrv__rng fill;
    int i, k, e, ch;
    m->sigma_s[0] = 4;
    m->sigma_s[1] = 1.6;
    m->sigma_s[2] = 24;
    m->density.kind = RRV_FIELD_GRID;
    g->nx = g->ny = g->nz = 9;
    g->channels = 1;
    g->lo = rrv__v3(0, 0, 0);
    g->hi = rrv__v3(1, 1, 1);
    g->data = (float *)calloc(9 * 9 * 9, sizeof(float));
    rrv__rng_seed(&fill, 5, 6, 7);
    for (i = 0; i < 9 * 9 * 9; ++i) g->data[i] = (float)(0.1 + 0.25 * rrv__uniform(&fill));
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    {
        /* the control is exercised: cells' minorants are above 0 */
        long positive;
        check_minorant("random grid", m, 13, &positive);
        CHECK(positive > 0);
    }
    CHECK(m->majorant->channel_groups == 2);
    ctx = tr_context(s);
    for (k = 0; k < 3; ++k) {
        rrv_vec3 d = rrv__sub(ends[k], origins[k]);
        double len = rrv__length(d), exact[3];
        tr_tally t[3][3];
        memset(t, 0, sizeof t);
        d = rrv__scale(d, 1.0 / len);
        for (ch = 0; ch < 3; ++ch) exact[ch] = exp(-tr_depth(m, origins[k], d, len, ch));
        for (e = 0; e < 3; ++e) {
            rrv__rng rng;
            rrv__rng_seed(&rng, 41, (uint64_t)(3 * k + e), 0);
            s->settings.transmittance = tr_kinds[e];
            for (i = 0; i < 100000; ++i) {
                double T[3];
                rrv__transmittance(&ctx, origins[k], d, len, &rng, T);
                for (ch = 0; ch < 3; ++ch) tr_add(&t[e][ch], T[ch]);
            }
        }
        for (ch = 0; ch < 3; ++ch) {
            printf("  ray %d channel %d: exp(-tau) %.5f, ratio %.5f +- %.5f, residual %.5f +- %.5f, march %.5f +- %.5f\n",
                   k, ch, exact[ch], tr_mean(&t[0][ch]), tr_se(&t[0][ch]), tr_mean(&t[1][ch]), tr_se(&t[1][ch]),
                   tr_mean(&t[2][ch]), tr_se(&t[2][ch]));
            if (ch != 2) CHECKF(exact[ch] > 0.02 && exact[ch] < 0.9, "ray %d channel %d: T %g", k, ch, exact[ch]);
            for (e = 0; e < 3; ++e)
                CHECKF(fabs(tr_mean(&t[e][ch]) - exact[ch]) <= 4 * tr_se(&t[e][ch]) + 1e-9,
                       "ray %d channel %d %s: %g +- %g, exp(-tau) %g", k, ch, tr_names[e], tr_mean(&t[e][ch]),
                       tr_se(&t[e][ch]), exact[ch]);
            for (e = 1; e < 3; ++e) {
                double se = sqrt(tr_se(&t[e][ch]) * tr_se(&t[e][ch]) + tr_se(&t[0][ch]) * tr_se(&t[0][ch]));
                CHECKF(fabs(tr_mean(&t[e][ch]) - tr_mean(&t[0][ch])) <= 4 * se + 1e-9,
                       "ray %d channel %d %s: %g, ratio %g, se %g", k, ch, tr_names[e], tr_mean(&t[e][ch]),
                       tr_mean(&t[0][ch]), se);
            }
        }
    }
    CHECK(ctx.stats.paths_cut == 0);
    rrv_scene_free(s);
}

/* At 2000 random points of random cells (and every cell's corners) of the
   medium's majorant grid, the density is at least the cell's minorant and
   at most its bound; counts the cells whose minorant is above 0, which the
   caller checks (a minorant of 0 everywhere is a bound that says nothing). */
static void check_minorant(const char *what, const rrv_medium *m, uint64_t seed, long *positive)
{
    const struct rrv__majorant_grid *g = m->majorant;
    size_t cells = (size_t)g->n[0] * g->n[1] * g->n[2], c;
    rrv__rng rng;
    double worst = 0;
    long bad = 0;
    int i;
    *positive = 0;
    for (c = 0; c < cells; ++c) *positive += g->density_min[c] > 0;
    rrv__rng_seed(&rng, seed, 1, 2);
    for (i = 0; i < 20000; ++i) {
        int idx[3], a;
        double p[3];
        rrv__coeffs co;
        double density, scale = m->sigma_a[1] + m->sigma_s[1];
        c = (size_t)(rrv__uniform(&rng) * (double)cells);
        if (c >= cells) c = cells - 1;
        idx[0] = (int)(c % (size_t)g->n[0]);
        idx[1] = (int)(c / (size_t)g->n[0] % (size_t)g->n[1]);
        idx[2] = (int)(c / ((size_t)g->n[0] * g->n[1]));
        for (a = 0; a < 3; ++a) {
            double lo = rrv__axis(g->lo, a) + idx[a] * rrv__axis(g->cell, a);
            double hi = lo + rrv__axis(g->cell, a), u = i % 4 == 0 ? (double)((i >> (2 + a)) & 1) : rrv__uniform(&rng);
            /* clipped to the medium's box, where the walks look */
            lo = fmax(lo, rrv__axis(m->lo, a));
            hi = fmin(hi, rrv__axis(m->hi, a));
            p[a] = lo + u * (hi - lo);
        }
        if (!(p[0] >= m->lo.x && p[0] <= m->hi.x && p[1] >= m->lo.y && p[1] <= m->hi.y && p[2] >= m->lo.z &&
              p[2] <= m->hi.z))
            continue;
        rrv__medium_coeffs(m, rrv__v3(p[0], p[1], p[2]), &co);
        density = (co.sigma_a[1] + co.sigma_s[1]) / scale;
        if (density < g->density_min[c] * (1 - 1e-6) - 1e-12) {
            ++bad;
            worst = fmax(worst, g->density_min[c] - density);
        }
        if (g->density_min[c] > g->density_max[c]) ++bad;
    }
    printf("  %s: %ld of %lu cells with a minorant above 0, %ld points below theirs (worst by %.3g)\n", what,
           *positive, (unsigned long)cells, bad, worst);
    CHECKF(bad == 0, "%s: %ld points below their cell's minorant, worst by %g", what, bad, worst);
}

static void test_minorant_is_a_lower_bound(void)
{
    static const char *scenes[2] = {"scenes/plume.rrv", "scenes/pyro.rrv"};
    rrv_error err;
    long positive;
    int i;
    for (i = 0; i < 2; ++i) {
        rrv_scene *s = NULL;
        CHECKF(rrv_scene_load(scenes[i], NULL, &s, &err) == RRV_OK, "%s: %s", scenes[i], err.message);
        if (!s) continue;
        CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
        check_minorant(scenes[i], &s->media[0], 3 + (uint64_t)i, &positive);
        CHECKF(positive > 0, "%s: no cell with a minorant", scenes[i]);
        rrv_scene_free(s);
    }
    {
        /* blobs: three positive and a negative one over a base */
        rrv_scene *s = tb_scene(4, 4);
        rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.5, 0.5);
        rrv_blob *b = tb_blobs(&m->density, 4);
        m->density.base = 0.4;
        b[0].center = rrv__v3(0, 0, 0), b[0].radius = 0.5, b[0].weight = 3;
        b[1].center = rrv__v3(0.5, -0.3, 0.2), b[1].radius = 0.2, b[1].weight = 5;
        b[2].center = rrv__v3(-0.6, 0.6, -0.1), b[2].radius = 0.8, b[2].weight = 1;
        b[3].center = rrv__v3(0.1, 0.4, 0.5), b[3].radius = 0.3, b[3].weight = -0.3;
        CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
        check_minorant("blobs", m, 9, &positive);
        CHECK(positive > 0);
        rrv_scene_free(s);
    }
}

static void test_choice_parses(void)
{
    /* the scene key and its three words; the default is DEFAULT (ratio) */
    static const char *words[3] = {"ratio", "residual", "march"};
    int i;
    for (i = 0; i < 3; ++i) {
        char text[256];
        rrv_scene *s = NULL;
        rrv_error err;
        snprintf(text, sizeof text,
                 "camera eye 0 0 -5 look 0 0 0 fov 30 resolution 4 4\nrender spp 1 transmittance %s\n", words[i]);
        CHECKF(rrv_scene_parse(text, strlen(text), "t.rrv", NULL, NULL, &s, &err) == RRV_OK, "%s: %s", words[i],
               err.message);
        if (s) CHECK(s->settings.transmittance == tr_kinds[i]);
        rrv_scene_free(s);
    }
}

int main(void)
{
    RUN(test_homogeneous_slab);
    RUN(test_heterogeneous_grid);
    RUN(test_minorant_is_a_lower_bound);
    RUN(test_choice_parses);
    (void)tb_shape;
    return CHECK_EXIT_CODE();
}
