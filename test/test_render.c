/* Core renderer tests: math, random numbers, sampling, the BVH, tracking
   estimators against closed-form transmittance, a white furnace, and
   bit-identical tiles. Statistical checks allow 4 standard errors with
   fixed seeds, so a correct estimator fails with probability < 1e-4. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "scene_builder.h"

static void test_vector_math(void)
{
    rrv_vec3 a = rrv__v3(1, 2, 3), b = rrv__v3(-2, 0.5, 4);
    rrv_vec3 c = rrv__cross(a, b);
    rrv__rng rng;
    int i;
    CHECK(fabs(rrv__dot(c, a)) < 1e-12 && fabs(rrv__dot(c, b)) < 1e-12);
    CHECK(fabs(rrv__length(rrv__normalize(b)) - 1) < 1e-15);
    CHECK(rrv__dot(a, b) == -2 + 1 + 12);
    rrv__rng_seed(&rng, 1, 2, 3);
    /* Frames stay orthonormal everywhere, including at the poles where
       naive constructions divide by zero. */
    for (i = 0; i < 10000; ++i) {
        rrv_vec3 n = i == 0 ? rrv__v3(0, 0, -1) : i == 1 ? rrv__v3(0, 0, 1)
                   : rrv__sample_uniform_sphere(rrv__uniform(&rng), rrv__uniform(&rng));
        rrv_vec3 t, s;
        rrv__frame(n, &t, &s);
        CHECKF(fabs(rrv__dot(t, n)) < 1e-12 && fabs(rrv__dot(s, n)) < 1e-12 && fabs(rrv__dot(t, s)) < 1e-12 &&
                   fabs(rrv__length(t) - 1) < 1e-12 && fabs(rrv__length(s) - 1) < 1e-12,
               "n = %g %g %g", n.x, n.y, n.z);
    }
}

static void test_rng(void)
{
    rrv__rng a, b, c;
    double sum = 0, sum2 = 0;
    int i, n = 1000000, same = 0;
    rrv__rng_seed(&a, 7, 100, 5);
    rrv__rng_seed(&b, 7, 100, 5);
    rrv__rng_seed(&c, 7, 100, 6);
    for (i = 0; i < 1000; ++i) {
        uint32_t x = rrv__next_u32(&a), y = rrv__next_u32(&b), z = rrv__next_u32(&c);
        CHECK(x == y);
        same += x == z;
    }
    CHECK(same < 5);
    for (i = 0; i < n; ++i) {
        double u = rrv__uniform(&a);
        CHECK(u >= 0 && u < 1);
        sum += u;
        sum2 += u * u;
    }
    /* mean 1/2 with standard error sqrt(1/12/n); second moment 1/3 */
    CHECKF(fabs(sum / n - 0.5) < 4 * sqrt(1.0 / 12 / n), "mean %g", sum / n);
    CHECKF(fabs(sum2 / n - 1.0 / 3) < 4 * sqrt(4.0 / 45 / n), "second moment %g", sum2 / n);
}

static void test_henyey_greenstein(void)
{
    const double gs[] = {-0.7, 0.0, 0.3, 0.9};
    rrv__rng rng;
    int k, i, n = 400000;
    rrv__rng_seed(&rng, 3, 0, 0);
    for (k = 0; k < 4; ++k) {
        double g = gs[k], integral = 0, integral2 = 0, mean_cos = 0, mean_cos2 = 0;
        rrv_vec3 fwd = rrv__normalize(rrv__v3(0.3, -0.2, 0.9));
        for (i = 0; i < n; ++i) {
            /* The pdf integrates to one: E[p(w) / (1/4pi)] over uniform w. */
            rrv_vec3 w = rrv__sample_uniform_sphere(rrv__uniform(&rng), rrv__uniform(&rng));
            double f = rrv__hg_eval(g, rrv__dot(fwd, w)) * 4 * RRV__PI, c;
            integral += f;
            integral2 += f * f;
            /* Sampled directions have mean cosine g. */
            w = rrv__hg_sample(g, fwd, rrv__uniform(&rng), rrv__uniform(&rng));
            c = rrv__dot(fwd, w);
            mean_cos += c;
            mean_cos2 += c * c;
        }
        integral /= n; integral2 /= n; mean_cos /= n; mean_cos2 /= n;
        CHECKF(fabs(integral - 1) < 4 * sqrt((integral2 - integral * integral) / n) + 1e-12,
               "g=%g integral %g", g, integral);
        CHECKF(fabs(mean_cos - g) < 4 * sqrt((mean_cos2 - mean_cos * mean_cos) / n), "g=%g mean cos %g", g, mean_cos);
    }
}

static void test_bvh_against_brute_force(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv__rng rng;
    rrv_error err;
    int i, rays = 5000, mismatches = 0, hits = 0;
    rrv__rng_seed(&rng, 11, 0, 0);
    for (i = 0; i < 3000; ++i) {
        rrv_shape *sh = tb_shape(s, i < 2800 ? RRV_SHAPE_TRIANGLE : i < 2900 ? RRV_SHAPE_SPHERE : RRV_SHAPE_QUAD);
        rrv_vec3 p = rrv__v3(10 * rrv__uniform(&rng) - 5, 10 * rrv__uniform(&rng) - 5, 10 * rrv__uniform(&rng) - 5);
        if (sh->kind == RRV_SHAPE_SPHERE) {
            sh->center = p;
            sh->radius = 0.05 + 0.3 * rrv__uniform(&rng);
        } else {
            sh->p0 = p;
            sh->e1 = rrv__scale(rrv__sample_uniform_sphere(rrv__uniform(&rng), rrv__uniform(&rng)), 0.6);
            sh->e2 = rrv__scale(rrv__sample_uniform_sphere(rrv__uniform(&rng), rrv__uniform(&rng)), 0.6);
        }
    }
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    for (i = 0; i < rays; ++i) {
        rrv_vec3 o = rrv__v3(14 * rrv__uniform(&rng) - 7, 14 * rrv__uniform(&rng) - 7, 14 * rrv__uniform(&rng) - 7);
        rrv_vec3 d = rrv__sample_uniform_sphere(rrv__uniform(&rng), rrv__uniform(&rng));
        rrv__hit hit, h;
        int k, found = rrv__intersect_scene(s, o, d, DBL_MAX, &hit), brute = -1;
        double tbest = DBL_MAX;
        for (k = 0; k < s->shape_count; ++k)
            if (rrv__intersect_shape(&s->shapes[k], o, d, tbest, &h)) { tbest = h.t; brute = k; }
        if (found != (brute >= 0) || (found && (hit.t != tbest || hit.shape != brute))) ++mismatches;
        hits += found;
    }
    CHECKF(mismatches == 0, "%d of %d rays disagree", mismatches, rays);
    CHECKF(hits > rays / 10, "only %d hits: the test would be weak", hits);
    CHECK(s->bvh_node_count > 100);
    rrv_scene_free(s);
}

/* Mean and standard error of a batch of estimates. */
typedef struct stats { double sum, sum2; long n; } stats;
static void stats_add(stats *s, double x) { s->sum += x; s->sum2 += x * x; s->n++; }
static double stats_mean(const stats *s) { return s->sum / s->n; }
static double stats_se(const stats *s)
{
    double m = stats_mean(s);
    return sqrt(fmax(s->sum2 / s->n - m * m, 0) / s->n);
}

/* A context for calling the tracking functions directly. */
static void tracking_context(rrv__context *ctx, rrv_scene *s)
{
    memset(ctx, 0, sizeof *ctx);
    ctx->scene = s;
    ctx->eta_camera2 = 1;
}

/* Ratio tracking, delta tracking (passing) and the collision estimator of
   emission, every channel against its closed form, where the media's
   channels walk with different majorants (rrv__group_channels). emitted:
   the expected emission gathered along the ray, or NULL. */
static void check_channels(rrv_scene *s, rrv_vec3 o, rrv_vec3 d, double tmax, const double tau[3],
                           const double *emitted, int n, const char *what)
{
    rrv__context ctx;
    rrv__rng rng;
    stats ratio[3], delta[3], glow[3];
    int i, c;
    tracking_context(&ctx, s);
    memset(ratio, 0, sizeof ratio);
    memset(delta, 0, sizeof delta);
    memset(glow, 0, sizeof glow);
    rrv__rng_seed(&rng, 9, 0, 0);
    for (i = 0; i < n; ++i) {
        double T[3], mis;
        rrv__path path;
        rrv__flight flight;
        int outcome;
        rrv__ratio_tracking_transmittance(&ctx, o, d, tmax, &rng, T);
        rrv__path_start(&path, &rng);
        outcome = rrv__refractive_delta_tracking(&ctx, &path, o, d, tmax, &rng, &flight);
        mis = rrv__path_mis(&path);
        for (c = 0; c < 3; ++c) {
            stats_add(&ratio[c], T[c]);
            stats_add(&delta[c], outcome == RRV__FLIGHT_PASSED ? path.beta[c] * mis : 0.0);
            stats_add(&glow[c], path.L[c]);
        }
    }
    for (c = 0; c < 3; ++c) {
        double expected = exp(-tau[c]);
        /* 1e-12: a channel whose transmittance is 0 to double precision */
        CHECKF(fabs(stats_mean(&ratio[c]) - expected) < 4 * stats_se(&ratio[c]) + 1e-12,
               "%s, channel %d: ratio tracking %g +- %g, exp(-tau) %g", what, c, stats_mean(&ratio[c]),
               stats_se(&ratio[c]), expected);
        CHECKF(fabs(stats_mean(&delta[c]) - expected) < 4 * stats_se(&delta[c]) + 1e-12,
               "%s, channel %d: delta tracking %g +- %g, exp(-tau) %g", what, c, stats_mean(&delta[c]),
               stats_se(&delta[c]), expected);
        /* bounds that could not see a 5 % error would prove nothing (a
           channel below 0.05 is tested only for its mean) */
        CHECKF(expected < 0.05 || stats_se(&delta[c]) < 0.0125 * expected, "%s, channel %d: delta se %g too large",
               what, c, stats_se(&delta[c]));
        if (emitted)
            CHECKF(fabs(stats_mean(&glow[c]) - emitted[c]) < 4 * stats_se(&glow[c]),
                   "%s, channel %d: emission %g +- %g, expected %g", what, c, stats_mean(&glow[c]),
                   stats_se(&glow[c]), emitted[c]);
    }
}

/* Checks ratio tracking and delta tracking against exp(-tau) for a ray
   (every channel the same). */
static void check_transmittance(rrv_scene *s, rrv_vec3 o, rrv_vec3 d, double tmax, double tau, const char *what)
{
    const double taus[3] = {tau, tau, tau};
    check_channels(s, o, d, tmax, taus, NULL, 200000, what);
}

static void test_transmittance_homogeneous(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.5, 1.0);
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    /* the ray crosses 2 m of sigma_t = 1.5 */
    check_transmittance(s, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, 3.0, "homogeneous");
    /* stopping inside the box: 0.5 m */
    check_transmittance(s, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), 1.5, 0.75, "homogeneous, partial");
    rrv_scene_free(s);
}

static void test_transmittance_gaussian_blob(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.2, 0.8);
    rrv_blob *b = tb_blobs(&m->density, 1);
    double sigma = 0.3, w = 2.0, tc = 2.1, bperp = 0.15, tau;
    b->center = rrv__v3(0.1, 0, 0);
    b->radius = sigma;
    b->weight = w;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    /* integral of w exp(-|x-c|^2/2s^2) along the ray from t=1 to t=3 */
    tau = w * exp(-bperp * bperp / (2 * sigma * sigma)) * sigma * sqrt(RRV__PI / 2) *
          (erf((3 - tc) / (sigma * sqrt(2.0))) - erf((1 - tc) / (sigma * sqrt(2.0))));
    check_transmittance(s, rrv__v3(-2, 0.15, 0), rrv__v3(1, 0, 0), DBL_MAX, tau, "gaussian blob");
    rrv_scene_free(s);
}

static void test_transmittance_grid_ramp(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
    rrv_grid *g = &m->density.grid;
    int x, y, z;
    m->density.kind = RRV_FIELD_GRID;
    g->nx = 5; g->ny = 3; g->nz = 3; g->channels = 1;
    g->lo = m->lo; g->hi = m->hi;
    g->data = (float *)malloc(5 * 3 * 3 * sizeof(float));
    /* density 1 + x: trilinear interpolation reproduces it exactly */
    for (z = 0; z < 3; ++z)
        for (y = 0; y < 3; ++y)
            for (x = 0; x < 5; ++x) g->data[(z * 3 + y) * 5 + x] = (float)(1.0 + (-1.0 + 0.5 * x));
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECK(fabs(rrv__field_eval(&m->density, rrv__v3(0.3, 0.1, -0.2), 0, 0) - 1.3) < 1e-6);
    check_transmittance(s, rrv__v3(-3, 0.2, 0.1), rrv__v3(1, 0, 0), DBL_MAX, 2.0, "grid ramp along x");
    /* along -x from inside: x from 0.5 down to -1, integral of 1 + x = 1.125 */
    check_transmittance(s, rrv__v3(0.5, 0.2, 0.1), rrv__v3(-1, 0, 0), DBL_MAX, 1.125, "grid ramp from inside");
    rrv_scene_free(s);
}

/* A medium inside one voxel of a grid a million million times its size
   (a grid file's box in the wrong unit): the majorant cells, each far
   thinner than the voxel's 1e-9 sliver, still take the voxel's value.
   They took none, and the medium rendered as empty. */
static void test_transmittance_inside_one_huge_voxel(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
    rrv_grid *g = &m->density.grid;
    int i;
    m->density.kind = RRV_FIELD_GRID;
    g->nx = g->ny = g->nz = 4;
    g->channels = 1;
    g->lo = rrv__v3(-1e12, -1e12, -1e12);
    g->hi = rrv__v3(1e12, 1e12, 1e12);
    g->data = (float *)malloc(64 * sizeof(float));
    for (i = 0; i < 64; ++i) g->data[i] = 0.75f;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    check_transmittance(s, rrv__v3(-3, 0.2, 0.1), rrv__v3(1, 0, 0), DBL_MAX, 1.5, "inside one huge voxel");
    rrv_scene_free(s);
}

/* ---- channel groups: one majorant per group of channels -------------------- */

static void test_channel_groups(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 0.0);
    static const double k[3] = {0.1, 0.5, 2.5};
    double tau[3], emitted[3];
    int c;
    for (c = 0; c < 3; ++c) {
        m->sigma_a[c] = k[c];
        m->Le[c] = 1.0 + c;
        tau[c] = 2 * k[c];
        emitted[c] = m->Le[c] * (1 - exp(-tau[c]));
    }
    m->Lescale = 1;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    /* 5 : 1 apart each: three groups, each walking at its own rate */
    CHECK(m->majorant->channel_groups == 3);
    for (c = 0; c < 3; ++c) CHECK(m->majorant->channel_scale[c] == k[c]);
    check_channels(s, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, tau, emitted, 200000, "three groups");
    /* a segment that ends inside the box (0.5 m of it) */
    for (c = 0; c < 3; ++c) {
        tau[c] = 0.5 * k[c];
        emitted[c] = m->Le[c] * (1 - exp(-tau[c]));
    }
    check_channels(s, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), 1.5, tau, emitted, 200000, "three groups, partial");
    rrv_scene_free(s);

    /* blast.rrv's 2.9 : 2.8 : 2.7 and 1 : 2 : 4 stay one group */
    s = tb_scene(4, 4);
    m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
    m->sigma_s[1] = 2;
    m->sigma_s[2] = 4;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECK(m->majorant->channel_groups == 1 && m->majorant->channel_scale[0] == 4 && m->majorant->channel_scale[1] == 4);
    rrv_scene_free(s);
}

/* Overlapping media, each with groups of its own and a grey one: walkers
   pausing at their cell faces reweight the path for the part each has
   walked, whichever medium's collision comes first. A Gaussian blob makes
   the density bound differ from cell to cell. */
static void test_channel_groups_overlapping_media(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *a = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 0.0);
    rrv_medium *b = tb_medium(s, rrv__v3(0, -1, -1), rrv__v3(2, 1, 1), 0.0, 0.0);
    rrv_medium *grey = tb_medium(s, rrv__v3(0.5, -1, -1), rrv__v3(3, 1, 1), 0.0, 0.3);
    rrv_blob *blob;
    static const double ka[3] = {0.05, 0.2, 0.8}, kb[3] = {1.2, 0.2, 0.2};
    double sigma = 0.3, w = 2.0, tc = 3.1, bperp = 0.15, blob_tau, tau[3];
    int c;
    a = &s->media[0];
    b = &s->media[1];
    grey = &s->media[2];
    for (c = 0; c < 3; ++c) {
        a->sigma_s[c] = ka[c];
        b->sigma_a[c] = kb[c];
    }
    blob = tb_blobs(&b->density, 1);
    blob->center = rrv__v3(1.1, 0, 0);
    blob->radius = sigma;
    blob->weight = w;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECK(a->majorant->channel_groups == 2 && b->majorant->channel_groups == 2 && grey->majorant->channel_groups == 1);
    /* b's blob from t = 2 to 4 (x = 0 to 2), as test_transmittance_gaussian_blob */
    blob_tau = w * exp(-bperp * bperp / (2 * sigma * sigma)) * sigma * sqrt(RRV__PI / 2) *
               (erf((4 - tc) / (sigma * sqrt(2.0))) - erf((2 - tc) / (sigma * sqrt(2.0))));
    for (c = 0; c < 3; ++c) tau[c] = 2 * ka[c] + kb[c] * blob_tau + 0.3 * 2.5;
    check_channels(s, rrv__v3(-2, 0.15, 0), rrv__v3(1, 0, 0), DBL_MAX, tau, NULL, 200000, "overlapping media");
    rrv_scene_free(s);
}

/* The hostile case channel groups exist for (a fuzz input's): sigma_t 0.4,
   6e10 and 0.6 per metre. With one majorant, red and blue walks took 1e10
   collisions a metre and hit the walk's cap; grouped, each channel's walk
   is as long as its own extinction makes it, and the thin channels still
   get their transmittance. */
static void test_channel_groups_bound_work(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 0.0);
    static const double tau[3] = {0.8, 1.2e11, 1.2};
    rrv__context ctx;
    rrv__rng rng;
    int i, n = 20000;
    m->sigma_s[0] = 0.4;
    m->sigma_s[1] = 6e10;
    m->sigma_s[2] = 0.6;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    tracking_context(&ctx, s);
    rrv__rng_seed(&rng, 3, 0, 0);
    for (i = 0; i < n; ++i) {
        double T[3];
        rrv__path path;
        rrv__flight flight;
        rrv__ratio_tracking_transmittance(&ctx, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, &rng, T);
        rrv__path_start(&path, &rng);
        rrv__refractive_delta_tracking(&ctx, &path, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, &rng, &flight);
        if (ctx.stats.events >= 8u * (unsigned)n) break; /* failed already: do not wait for every capped walk */
    }
    /* Per walk pair: red and blue ratio tracking at 0.6 per metre over 2 m
       (1.2 collisions on average), green's ends at its first; delta
       tracking's hero is red or blue two times in three (at most 1.2),
       green its first collision. 8 per pair is far above that mean of
       about 3.5 and far below the 4e6 of one capped walk. */
    CHECKF(ctx.stats.paths_cut == 0 && ctx.stats.events < 8u * (unsigned)n, "%lu events for %d walk pairs, %lu cut",
           (unsigned long)ctx.stats.events, n, (unsigned long)ctx.stats.paths_cut);
    if (ctx.stats.events < 8u * (unsigned)n)
        check_channels(s, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, tau, NULL, 100000, "sigma_t 0.4, 6e10, 0.6");
    rrv_scene_free(s);
}

/* The mean pixel value of an image rendered one sample per call, with its
   standard error over all (pixel, sample) estimates. */
static stats render_statistics(rrv_scene *s, int spp, int channel)
{
    int w = s->camera.width, h = s->camera.height, k, i;
    float *img = (float *)malloc((size_t)w * h * 3 * sizeof(float));
    stats st = {0, 0, 0};
    for (k = 0; k < spp; ++k) {
        memset(img, 0, (size_t)w * h * 3 * sizeof(float));
        rrv_render_rect(s, 0, 0, w, h, k, k + 1, img, w, NULL, NULL);
        for (i = 0; i < w * h; ++i) stats_add(&st, img[3 * i + channel]);
    }
    free(img);
    return st;
}

/* An albedo-1 medium in a uniform environment neither adds nor removes
   light: every pixel sees the environment radiance. */
static void furnace_with(double s0, double s1, double s2, int spp, double max_se, rrv_sampler sampler)
{
    rrv_scene *s = tb_scene(8, 8);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
    int c;
    m->sigma_s[0] = s0; m->sigma_s[1] = s1; m->sigma_s[2] = s2;
    m->g = 0.6;
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = 0.75;
    s->settings.max_depth = 1000;
    s->settings.sampler = sampler;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    for (c = 0; c < 3; ++c) {
        stats st = render_statistics(s, spp, c);
        CHECKF(fabs(stats_mean(&st) - 0.75) < 4 * stats_se(&st), "channel %d: %g +- %g, expected 0.75", c,
               stats_mean(&st), stats_se(&st));
        /* the bound must be tight enough to catch a real energy error */
        CHECKF(stats_se(&st) < max_se, "channel %d: standard error %g too large to test", c, stats_se(&st));
    }
    rrv_scene_free(s);
}

static void furnace(double s0, double s1, double s2, int spp, double max_se)
{
    furnace_with(s0, s1, s2, spp, max_se, RRV_SAMPLER_PCG);
}

static void test_white_furnace(void) { furnace(2.0, 2.0, 2.0, 64, 0.01); }

/* The Sobol sampler's samples are stratified within a pixel, not
   independent, so the standard error taken as if they were overstates the
   error of the mean: the bound is conservative, and still catches a bias. */
static void test_white_furnace_sobol(void) { furnace_with(2.0, 2.0, 2.0, 64, 0.01, RRV_SAMPLER_SOBOL); }

/* The numbers sample `index` of the pixel with scramble key `key` draws
   from one stream at one bounce: the first n of it, into u. */
static void sobol_stream(uint64_t key, uint32_t index, int bounce, int stream, int n, double *u)
{
    rrv__rng rng;
    int b, k;
    rrv__rng_seed(&rng, 1, key, index);
    rrv__sobol_start(&rng, key, index);
    for (b = 0; b < bounce; ++b) rrv__sampler_bounce(&rng);
    rng.stream = stream & 1;
    for (k = 0; k < n; ++k) u[k] = stream & RRV__STREAM_WALK ? rrv__uniform_walk(&rng) : rrv__uniform(&rng);
}

/* Owen-scrambled Sobol pairs named (bounce, stream, k): the first 2^m
   samples of any pixel form a (0,m,2)-net in the pair of dimensions 2j,
   2j+1 of every stream at every bounce, the 40th as well as the camera's
   (each of the 2^m elementary intervals of every shape holds one point),
   so each dimension alone has exactly one point in every interval of
   length 1/2^a, a <= m. */
static void test_sobol_sampler_nets(void)
{
    enum { M = 8, N = 1 << M, K = RRV__SOBOL_BUDGET };
    static const int bounces[] = { 0, 1, 7, 40 };
    static double pts[N][K];
    int pixel, bi, stream, i, k, a, bad = 0;
    for (pixel = 0; pixel < 2; ++pixel)
        for (bi = 0; bi < 4; ++bi)
            for (stream = 0; stream < 4; ++stream) {
                for (i = 0; i < N; ++i)
                    sobol_stream(rrv__mix64(0x5eed + (uint64_t)pixel), (uint32_t)i, bounces[bi], stream, K, pts[i]);
                for (k = 0; k < K; k += 2)
                    for (a = 0; a <= M; ++a) {
                        static int count[N];
                        memset(count, 0, sizeof count);
                        for (i = 0; i < N; ++i) {
                            int cx = (int)(pts[i][k] * (1 << a)), cy = (int)(pts[i][k + 1] * (1 << (M - a)));
                            ++count[(cx << (M - a)) | cy];
                        }
                        for (i = 0; i < N; ++i) bad += count[i] != 1;
                    }
            }
    CHECKF(bad == 0, "%d elementary intervals without exactly one point", bad);
}

/* What a dimension holds depends on its name alone: a stream's numbers are
   the same whatever the other streams drew before or between them (so a
   sample with more free flights does not shift its phase direction), and
   a sample's numbers do not depend on the samples drawn before it. */
static void test_sobol_sampler_names_align(void)
{
    enum { K = 12 };
    double alone[K], mixed[K];
    int k, bounce, differ = 0;
    uint64_t key = rrv__mix64(77);
    for (bounce = 0; bounce < 3; ++bounce) {
        rrv__rng rng;
        int b;
        sobol_stream(key, 13, bounce, RRV__STREAM_DIRECTION, K, alone);
        rrv__rng_seed(&rng, 1, key, 13);
        rrv__sobol_start(&rng, key, 13);
        for (b = 0; b < bounce; ++b) {
            /* earlier bounces draw any number of anything */
            for (k = 0; k < 5 + 3 * b; ++k) rrv__uniform_walk(&rng);
            rrv__uniform(&rng);
            rrv__sampler_bounce(&rng);
        }
        for (k = 0; k < K; ++k) {
            int j;
            for (j = 0; j < k % 4; ++j) rrv__uniform_walk(&rng); /* a walk of k % 4 flights */
            rng.stream = RRV__STREAM_LIGHT;
            for (j = 0; j < k % 3; ++j) rrv__uniform(&rng), rrv__uniform_walk(&rng); /* a light sample */
            rng.stream = RRV__STREAM_DIRECTION;
            mixed[k] = rrv__uniform(&rng);
        }
        for (k = 0; k < K; ++k) differ += alone[k] != mixed[k];
    }
    CHECKF(differ == 0, "%d direction numbers moved with the draws of other streams", differ);
}

/* One sample, over pixels, is uniform, and numbers of different names
   (another bounce, stream, pair, or the pair's other coordinate) are
   uncorrelated: E[uv] = 1/4 within 4 standard errors. Past a stream's
   budget the numbers are PCG32's, uniform too. */
static void test_sobol_sampler_independent(void)
{
    enum { NAMES = 8 };
    /* bounce, stream, k: neighbours in this list differ in one part */
    static const int names[NAMES][3] = { { 0, 0, 0 }, { 0, 0, 1 }, { 0, 1, 1 }, { 1, 1, 1 }, { 1, 2, 1 },
                                         { 1, 3, 1 }, { 1, 3, 3 }, { 1, 3, RRV__SOBOL_BUDGET } };
    int n = 200000, pixel, d;
    double sum[NAMES], prod[NAMES];
    memset(sum, 0, sizeof sum);
    memset(prod, 0, sizeof prod);
    for (pixel = 0; pixel < n; ++pixel) {
        double u[NAMES], v[RRV__SOBOL_BUDGET + 1];
        uint64_t key = rrv__mix64((uint64_t)pixel);
        for (d = 0; d < NAMES; ++d) {
            sobol_stream(key, 5, names[d][0], names[d][1], names[d][2] + 1, v);
            u[d] = v[names[d][2]];
            CHECK(u[d] >= 0 && u[d] < 1);
            sum[d] += u[d];
        }
        for (d = 0; d + 1 < NAMES; ++d) prod[d] += u[d] * u[d + 1];
    }
    for (d = 0; d < NAMES; ++d) {
        /* mean 1/2 (sd sqrt(1/12)); E[u_d u_{d+1}] = 1/4 (sd sqrt(7/144)) */
        CHECKF(fabs(sum[d] / n - 0.5) < 4 * sqrt(1.0 / 12 / n), "name %d: mean %g", d, sum[d] / n);
        if (d + 1 < NAMES)
            CHECKF(fabs(prod[d] / n - 0.25) < 4 * sqrt(7.0 / 144 / n), "names %d, %d: E[uv] %g", d, d + 1,
                   prod[d] / n);
    }
}


/* Chromatic extinction reweights each channel at every collision, so the
   estimate is noisier: more samples for a comparable bound. */
static void test_white_furnace_chromatic(void) { furnace(1.0, 2.0, 4.0, 1024, 0.02); }

static void tiles_are_bit_identical(rrv_sampler sampler)
{
    rrv_scene *s = tb_scene(20, 12);
    rrv_error err;
    rrv_shape *q;
    int w = 20, h = 12, x, y;
    float *full = (float *)calloc((size_t)w * h * 3, sizeof(float));
    float *tiled = (float *)calloc((size_t)w * h * 3, sizeof(float));
    tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.3, 0.7)->g = 0.4;
    q = tb_shape(s, RRV_SHAPE_QUAD);
    q->p0 = rrv__v3(-2, 3, -2); q->e1 = rrv__v3(4, 0, 0); q->e2 = rrv__v3(0, 0, 4);
    q->L[0] = q->L[1] = q->L[2] = 3; /* emits downward: e1 x e2 points -y */
    s->environment.kind = RRV_ENV_GRADIENT;
    s->environment.L[2] = 1; s->environment.L2[0] = 0.5;
    s->settings.sampler = sampler;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    rrv_render_rect(s, 0, 0, w, h, 0, 8, full, w, NULL, NULL);
    for (y = 0; y < h; y += 5)
        for (x = 0; x < w; x += 7)
            rrv_render_rect(s, x, y, x + 7 > w ? w : x + 7, y + 5 > h ? h : y + 5, 0, 8,
                            tiled + 3 * (y * w + x), w, NULL, NULL);
    CHECK(memcmp(full, tiled, (size_t)w * h * 3 * sizeof(float)) == 0);
    {
        /* Samples [0,3) then [3,8) are samples 0..7 too: the sums agree to
           float rounding (two roundings of the parts' sums, one of the
           whole's). A sampler that numbered a range's samples from its
           start would render samples 0..4 twice. */
        int worst = -1;
        double worst_err = 0;
        memset(tiled, 0, (size_t)w * h * 3 * sizeof(float));
        rrv_render_rect(s, 0, 0, w, h, 0, 3, tiled, w, NULL, NULL);
        rrv_render_rect(s, 0, 0, w, h, 3, 8, tiled, w, NULL, NULL);
        for (x = 0; x < w * h * 3; ++x) {
            double e = fabs((double)full[x] - tiled[x]) / (fabs(full[x]) + 1e-30);
            if (e > worst_err) { worst_err = e; worst = x; }
        }
        CHECKF(worst_err < 4 * FLT_EPSILON, "value %d: the ranges' sum %g, the whole's %g", worst,
               worst >= 0 ? tiled[worst] : 0.0, worst >= 0 ? full[worst] : 0.0);
    }
    {
        double total = 0;
        for (x = 0; x < w * h * 3; ++x) total += full[x];
        CHECKF(total > 0, "the image is black: the comparison would be empty");
    }
    free(full);
    free(tiled);
    rrv_scene_free(s);
}

static void test_tiles_are_bit_identical(void)
{
    tiles_are_bit_identical(RRV_SAMPLER_PCG);
    tiles_are_bit_identical(RRV_SAMPLER_SOBOL);
}

static void test_grid_gradient_stencil(void)
{
    /* The fused stencil equals central differences of the trilinear field
       with a one-voxel step wherever both stay inside the grid. */
    rrv_field f;
    rrv__rng rng;
    int i, n = 9, worst_i = -1;
    double worst = 0;
    memset(&f, 0, sizeof f);
    f.kind = RRV_FIELD_GRID;
    f.grid.nx = n; f.grid.ny = n + 2; f.grid.nz = n - 1; f.grid.channels = 1;
    f.grid.lo = rrv__v3(-1, -0.5, 0); f.grid.hi = rrv__v3(1, 1.5, 0.7);
    f.grid.data = (float *)malloc((size_t)(n * (n + 2) * (n - 1)) * sizeof(float));
    rrv__rng_seed(&rng, 9, 0, 0);
    for (i = 0; i < n * (n + 2) * (n - 1); ++i) f.grid.data[i] = (float)rrv__uniform(&rng);
    for (i = 0; i < 20000; ++i) {
        /* stay a voxel and a bit away from every face */
        rrv_vec3 p = rrv__v3(-1 + 0.26 + 1.48 * rrv__uniform(&rng), -0.5 + 0.21 + 1.58 * rrv__uniform(&rng),
                             0.11 + 0.48 * rrv__uniform(&rng));
        rrv_vec3 fused = rrv__grid_gradient(&f.grid, p), ref;
        double hx = 2.0 / (n - 1), hy = 2.0 / (n + 1), hz = 0.7 / (n - 2), e;
        ref.x = (rrv__field_eval(&f, rrv__v3(p.x + hx, p.y, p.z), 0, 0) - rrv__field_eval(&f, rrv__v3(p.x - hx, p.y, p.z), 0, 0)) / (2 * hx);
        ref.y = (rrv__field_eval(&f, rrv__v3(p.x, p.y + hy, p.z), 0, 0) - rrv__field_eval(&f, rrv__v3(p.x, p.y - hy, p.z), 0, 0)) / (2 * hy);
        ref.z = (rrv__field_eval(&f, rrv__v3(p.x, p.y, p.z + hz), 0, 0) - rrv__field_eval(&f, rrv__v3(p.x, p.y, p.z - hz), 0, 0)) / (2 * hz);
        /* absolute: values are in [0,1], so gradients are O(1/voxel) ~ 10 */
        e = rrv__length(rrv__sub(fused, ref));
        if (e > worst) { worst = e; worst_i = i; }
    }
    CHECKF(worst < 1e-9, "difference %g at sample %d", worst, worst_i);
    CHECK(rrv__length(rrv__grid_gradient(&f.grid, rrv__v3(5, 0, 0))) == 0);
    free(f.grid.data);
}

static void test_blackbody(void)
{
    double c300[3], c1500[3], c3000[3], c6500[3];
    rrv__blackbody_rgb(300, c300);
    rrv__blackbody_rgb(1500, c1500);
    rrv__blackbody_rgb(3000, c3000);
    rrv__blackbody_rgb(6500, c6500);
    /* air at ambient temperature does not glow */
    CHECKF(rrv__max3(c300) < 1e-20, "300 K glows: %g %g %g", c300[0], c300[1], c300[2]);
    /* hotter is brighter (peak-normalised like pbrt-v4) and less red */
    CHECK(c1500[1] < c3000[1] && c3000[1] < c6500[1]);
    CHECK(c1500[0] / c1500[1] > c3000[0] / c3000[1] && c3000[0] / c3000[1] > c6500[0] / c6500[1]);
    /* 6500 K is close to the sRGB white point (D65) */
    CHECKF(fabs(c6500[0] / c6500[1] - 1) < 0.1 && fabs(c6500[2] / c6500[1] - 1) < 0.15, "6500 K: %g %g %g",
           c6500[0], c6500[1], c6500[2]);
}

/* ---- work bounds and hostile inputs (BOUNDS in rrv.h) ------------------------ */

/* A furnace around a refracting shell: no extinction, an environment of 1,
   so every sample that is not cut is exactly 1 (no MIS weight, no IOR
   change between camera and environment). */
static rrv_scene *shell_furnace(double amplitude, double step)
{
    rrv_scene *s = tb_scene(40, 30);
    rrv_medium *m = tb_medium(s, rrv__v3(-1.2, -1.2, -1.2), rrv__v3(1.2, 1.2, 1.2), 0.0, 0.0);
    m->ior.kind = RRV_FIELD_SHELL;
    m->ior.center = rrv__v3(0, 0, 0);
    m->ior.radius = 1.1;
    m->ior.thickness = 0.15;
    m->ior.edge = 0.03;
    m->ior.amplitude = amplitude;
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = 1;
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.step = step;
    return s;
}

/* Renders spp samples a pixel and returns how many samples fell short of 1
   (the furnace's value), from the pixel sums. */
static long furnace_shortfall(rrv_scene *s, int spp, rrv_render_stats *st, double *worst)
{
    int w = s->camera.width, h = s->camera.height, i;
    float *img = (float *)calloc((size_t)w * h * 3, sizeof(float));
    double missing = 0;
    memset(st, 0, sizeof *st);
    rrv_render_rect(s, 0, 0, w, h, 0, spp, img, w, st, NULL);
    *worst = 0;
    for (i = 0; i < w * h * 3; i += 3) {
        missing += spp - img[i + 1];
        *worst = fmax(*worst, fabs(img[i] - img[i + 1]) + fabs(img[i + 2] - img[i + 1]));
    }
    free(img);
    return lround(missing);
}

static void test_trapped_eikonal_rays_are_bounded_and_counted(void)
{
    /* The case: the blast scene's shell (3 cm edges) at step 0.1 in
       a furnace must be 1 everywhere, no path cut. */
    rrv_scene *s = shell_furnace(0.03, 0.1);
    rrv_render_stats st;
    rrv_error err;
    double worst;
    long bound, short_samples;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    short_samples = furnace_shortfall(s, 4, &st, &worst);
    CHECKF(short_samples == 0 && st.paths_cut == 0, "%ld samples short, %lu cut", short_samples,
           (unsigned long)st.paths_cut);
    rrv_scene_free(s);
    /* Ten times the amplitude makes a waveguide between the shell's edges:
       RK4 at step 0.1 drifts some camera rays into orbits inside it (no ray
       from outside can follow one physically). Each leg is bounded by the
       scene: 64 + 16 (2 + 4 diag / h) = 2756 steps for this 2.4 m box, not
       the 1e7 of a fixed cap; every sample that is not 1 is a counted cut,
       and there are some (measured 8 of 4800), so the count is tested. */
    s = shell_furnace(0.3, 0.1);
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    bound = rrv__step_bound(s, RRV_INTEGRATOR_EIKONAL);
    CHECKF(bound < 3000, "step bound %ld", bound);
    short_samples = furnace_shortfall(s, 4, &st, &worst);
    CHECKF(st.paths_cut > 0, "no path was cut: the check below would be empty");
    CHECKF((uint64_t)short_samples == st.paths_cut && st.cut_tracking == 0,
           "%ld samples short of 1, %lu paths cut", short_samples, (unsigned long)st.paths_cut);
    CHECKF(worst == 0, "channels differ by %g", worst);
    /* one leg per sample: the events (eikonal steps) stay under the bound */
    CHECKF(st.events <= st.samples * (uint64_t)bound, "%lu events for %lu samples", (unsigned long)st.events,
           (unsigned long)st.samples);
    rrv_scene_free(s);
}

static void test_rays_trapped_in_a_waveguide_end_early_and_are_counted(void)
{
    /* The camera inside the layer of a shell whose IOR rises to 3 (2 cm
       thick, 12.5 mm edges), looking along it within 5 degrees (2 x 2 pixels): every camera
       ray is guided by the layer (eta r cos(angle) at the camera, 2.85,
       exceeds the r <= 1.0 any ray leaving it needs) and circles the
       sphere for good. The comb kicks it at most grad_peak / tolerance
       times a metre, so a ray ended at the trap length takes at most that
       rate times the length in kicks (64 spare); the step bound, which
       ended these rays before, allows over 4 times as many. Every sample
       must be ended as trapped, counted (trapped_paths, also in
       paths_cut), and dark: a furnace of 1 that a trapped ray never sees. */
    rrv_scene *s = tb_scene(2, 2);
    rrv_medium *m = tb_medium(s, rrv__v3(-1.1, -1.1, -1.1), rrv__v3(1.1, 1.1, 1.1), 0.0, 0.0);
    rrv_render_stats st;
    rrv_error err;
    float img[2 * 2 * 3];
    double trap, per_trap;
    long bound;
    int i;
    m->ior.kind = RRV_FIELD_SHELL;
    m->ior.center = rrv__v3(0, 0, 0);
    m->ior.radius = 1.0;
    m->ior.thickness = 0.05;
    m->ior.edge = 0.0125;
    m->ior.amplitude = 2.0;
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = 1;
    s->camera.eye = rrv__v3(0, 0.975, 0);
    s->camera.look = rrv__v3(0, 0.975, -1);
    s->camera.fov = 10;
    s->settings.integrator = RRV_INTEGRATOR_REFRACTIVE;
    s->settings.nee = RRV_NEE_NONE;
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    trap = rrv__trap_length(s);
    CHECKF(fabs(trap - RRV__TRAP_CROSSINGS * 2.2 * sqrt(3.0)) < 1e-12, "trap length %g", trap);
    per_trap = 64 + trap * m->majorant->grad_peak / s->settings.bend_tolerance;
    bound = rrv__step_bound(s, RRV_INTEGRATOR_REFRACTIVE);
    CHECKF(4 * per_trap < (double)bound, "a trap's %g kicks against the step bound's %ld", per_trap, bound);
    memset(&st, 0, sizeof st);
    memset(img, 0, sizeof img);
    CHECK(rrv_render_rect(s, 0, 0, 2, 2, 0, 1, img, 2, &st, NULL) == RRV_OK);
    printf("  %.3g kicks a trapped sample (at most %.3g; the step bound %ld)\n",
           (double)st.events / (double)st.samples, per_trap, bound);
    CHECKF(st.samples == 4 && st.trapped_paths == st.samples && st.paths_cut == st.trapped_paths &&
               st.cut_tracking == 0 && st.cut_samples == 0,
           "%llu samples, %llu trapped, %llu cut", (unsigned long long)st.samples,
           (unsigned long long)st.trapped_paths, (unsigned long long)st.paths_cut);
    CHECKF((double)st.events <= (double)st.samples * per_trap, "%llu kicks for %llu samples",
           (unsigned long long)st.events, (unsigned long long)st.samples);
    for (i = 0; i < 2 * 2 * 3; ++i) CHECKF(img[i] == 0.0f, "pixel value %g", img[i]);
    rrv_scene_free(s);
}

static void test_tracking_walks_are_bounded(void)
{
    /* A majorant of 1e30 over a density of 1e-30: free flights of 1e-30 m
       do not move t at all, the hang an overflowing extinction caused. The
       walk must stop after RRV_MAX_SEGMENT_EVENTS collisions, say so, and
       return the one safe answer, no light. */
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv__context ctx;
    rrv__rng rng;
    rrv__path path;
    rrv__flight flight;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
    double T[3];
    size_t c, cells;
    int outcome;
    m->density.value = 1e-30;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    cells = (size_t)m->majorant->n[0] * m->majorant->n[1] * m->majorant->n[2];
    for (c = 0; c < cells; ++c) m->majorant->density_max[c] = 1e30f;
    m->majorant->density_peak = 1e30f;
    tracking_context(&ctx, s);
    rrv__rng_seed(&rng, 1, 2, 3);
    rrv__ratio_tracking_transmittance(&ctx, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, &rng, T);
    CHECK(T[0] == 0 && T[1] == 0 && T[2] == 0);
    CHECKF(ctx.stats.paths_cut == 1 && ctx.stats.cut_tracking == 1 && ctx.stats.events == RRV_MAX_SEGMENT_EVENTS,
           "cut %lu, events %lu", (unsigned long)ctx.stats.paths_cut, (unsigned long)ctx.stats.events);
    rrv__path_start(&path, &rng);
    outcome = rrv__refractive_delta_tracking(&ctx, &path, rrv__v3(-2, 0.1, 0.2), rrv__v3(1, 0, 0), DBL_MAX, &rng,
                                           &flight);
    CHECK(outcome == RRV__FLIGHT_CUT && ctx.stats.events == 2 * RRV_MAX_SEGMENT_EVENTS);
    rrv_scene_free(s);
}

static void test_majorant_follows_large_voxels(void)
{
    /* One sample of 1e8 in an empty 8^3 grid: the majorant cells follow the
       voxels, each split in 3 (21 an axis: at least 16 across the box),
       and only the 6^3 cells of the 2^3 voxels around the sample carry
       it. With the default 4^3 cells, each two voxels wide and widened by
       the rounding of their corners, rays through 64 voxels of nothing saw
       a majorant of 1e8: ~1e7 null collisions each, 1 s a sample. */
    rrv_scene *s = tb_scene(8, 8);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(0, 0, 0), rrv__v3(1, 1, 1), 0.0, 1.0);
    rrv_grid *g = &m->density.grid;
    const struct rrv__majorant_grid *mg;
    rrv_render_stats st;
    float *img = (float *)calloc(8 * 8 * 3, sizeof(float));
    int x, y, z, loaded = 0;
    m->density.kind = RRV_FIELD_GRID;
    g->nx = g->ny = g->nz = 8;
    g->channels = 1;
    g->lo = m->lo;
    g->hi = m->hi;
    g->data = (float *)calloc(512, sizeof(float));
    g->data[(4 * 8 + 4) * 8 + 4] = 1e8f;
    s->camera.eye = rrv__v3(0.5, 0.5, -3);
    s->camera.look = rrv__v3(0.5, 0.5, 0.5);
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = 1;
    s->settings.max_depth = 8;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    mg = m->majorant;
    CHECKF(mg->n[0] == 21 && mg->n[1] == 21 && mg->n[2] == 21, "%d x %d x %d cells", mg->n[0], mg->n[1], mg->n[2]);
    for (z = 0; z < mg->n[2]; ++z)
        for (y = 0; y < mg->n[1]; ++y)
            for (x = 0; x < mg->n[0]; ++x)
                loaded += mg->density_max[(z * mg->n[1] + y) * mg->n[0] + x] > 0;
    CHECKF(loaded == 216, "%d cells carry the sample", loaded);
    memset(&st, 0, sizeof st);
    rrv_render_rect(s, 0, 0, 8, 8, 0, 16, img, 8, &st, NULL);
    /* measured 4.3e3 events a sample here (with 4^3 cells: 3.3e5, and 80
       of the 1024 paths cut); the check allows 10 times that, none cut */
    CHECKF(st.events < 43000 * st.samples && st.paths_cut == 0, "%lu events in %lu samples, %lu cut",
           (unsigned long)st.events, (unsigned long)st.samples, (unsigned long)st.paths_cut);
    free(img);
    rrv_scene_free(s);
}

static void test_prepare_accounting_and_limits(void)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_error err;
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.1, 0.5);
    rrv_shape *q = tb_shape(s, RRV_SHAPE_QUAD);
    size_t once, twice, coarse;
    q->p0 = rrv__v3(-2, 3, -2); q->e1 = rrv__v3(4, 0, 0); q->e2 = rrv__v3(0, 0, 4);
    q->L[0] = q->L[1] = q->L[2] = 1;
    m->density.kind = RRV_FIELD_NOISE; /* baked by prepare */
    m->density.amplitude = 1;
    m->density.noise.octaves = 3;
    m->density.noise.frequency = 2;
    m->density.noise.lacunarity = 2;
    m->density.noise.gain = 0.5;
    m->density.noise.radius = 1;
    m->ior.kind = RRV_FIELD_LUNEBURG;
    m->ior.radius = 1;
    s->bytes = 1000;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    once = s->bytes;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    twice = s->bytes;
    CHECKF(once == twice && once > 1000, "bytes %lu after one prepare, %lu after three", (unsigned long)once,
           (unsigned long)twice);
    /* 64^3 cells instead of the automatic ones, three floats each (the
       density's majorant and minorant, the gradient's bound; the Luneburg
       sphere is no box support, so no near-flat flags) */
    coarse = s->bytes - (size_t)m->majorant->n[0] * m->majorant->n[1] * m->majorant->n[2] * 3 * sizeof(float);
    s->settings.majorant_cells = 64;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECKF(s->bytes - coarse == (size_t)64 * 64 * 64 * 3 * sizeof(float), "grew by %lu",
           (unsigned long)(s->bytes - coarse));
    /* the grid limit holds for the majorant grid too: 256^3 cells of 8 bytes */
    s->settings.majorant_cells = 256;
    s->max_grid_bytes = (size_t)64 << 20;
    CHECK(rrv_scene_prepare(s, &err) == RRV_ERROR_LIMIT && strstr(err.message, "majorant grid") != NULL);
    /* a failed prepare releases all it built, and its bytes */
    CHECKF(s->bytes == 1000, "bytes %lu after a failed prepare", (unsigned long)s->bytes);
    s->max_grid_bytes = 0;
    s->settings.majorant_cells = 0;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK && s->bytes == once);
    /* a scene built in code gets the loader's refusals: eta below zero */
    m->ior.kind = RRV_FIELD_SLAB;
    m->ior.normal = rrv__v3(0, 1, 0);
    m->ior.gradient = 2;
    CHECK(rrv_scene_prepare(s, &err) == RRV_ERROR_ARGUMENT && strstr(err.message, "IOR from -1 to 3") != NULL);
    rrv_scene_free(s);
}

/* max |grad| of a profile sampled on a 9^3 lattice over a box */
static double sampled_gradient_max(const rrv_field *f, rrv_vec3 lo, rrv_vec3 hi)
{
    double best = 0;
    int i, j, k;
    for (k = 0; k < 9; ++k)
        for (j = 0; j < 9; ++j)
            for (i = 0; i < 9; ++i) {
                rrv_vec3 p = rrv__v3(lo.x + (hi.x - lo.x) * i / 8.0, lo.y + (hi.y - lo.y) * j / 8.0,
                                     lo.z + (hi.z - lo.z) * k / 8.0);
                best = fmax(best, rrv__length(rrv__profile_gradient(f, p)));
            }
    return best;
}

static void test_gradient_bounds_in_closed_form(void)
{
    /* The closed forms bound |grad r| over any box (they replace 64 lookups
       a cell); checked against a 9^3 lattice in 3000 random boxes per kind,
       and tight where the lattice holds the maximiser (within 1e-9). */
    rrv_field f;
    rrv_blob blobs[2];
    rrv__rng rng;
    int kind, i, known, loose = 0;
    rrv__rng_seed(&rng, 4, 0, 0);
    for (kind = 0; kind < 4; ++kind) {
        memset(&f, 0, sizeof f);
        f.center = rrv__v3(0.1, -0.2, 0.05);
        f.radius = 0.8;
        if (kind == 0) f.kind = RRV_FIELD_LUNEBURG;
        if (kind == 1) { f.kind = RRV_FIELD_FISHEYE; f.n0 = 2; }
        if (kind == 2) { f.kind = RRV_FIELD_SHELL; f.thickness = 0.2; f.edge = 0.03; f.amplitude = -0.4; }
        if (kind == 3) {
            f.kind = RRV_FIELD_BLOBS;
            f.blobs = blobs;
            f.blob_count = 2;
            blobs[0].center = rrv__v3(0.2, 0, 0); blobs[0].radius = 0.1; blobs[0].weight = 0.5;
            blobs[1].center = rrv__v3(-0.3, 0.1, 0); blobs[1].radius = 0.3; blobs[1].weight = -1;
        }
        for (i = 0; i < 3000; ++i) {
            rrv_vec3 a = rrv__v3(2 * rrv__uniform(&rng) - 1, 2 * rrv__uniform(&rng) - 1, 2 * rrv__uniform(&rng) - 1);
            rrv_vec3 e = rrv__scale(rrv__v3(rrv__uniform(&rng), rrv__uniform(&rng), rrv__uniform(&rng)), 0.3);
            rrv_vec3 b = rrv__add(a, e);
            double bound = rrv__profile_gradient_bound(&f, a, b, &known), sampled = sampled_gradient_max(&f, a, b);
            CHECK(known);
            if (!(bound >= sampled * (1 - 1e-12))) ++loose;
        }
    }
    CHECKF(loose == 0, "%d boxes where the closed form is below a sampled gradient", loose);
    memset(&f, 0, sizeof f);
    f.kind = RRV_FIELD_CONSTANT;
    CHECK(rrv__profile_gradient_bound(&f, rrv__v3(0, 0, 0), rrv__v3(1, 1, 1), &known) == 0 && known);
}

static void test_hostile_numbers_stay_finite(void)
{
    /* Noise in a box 1e86 wide: lattice coordinates far beyond int (the
       cast was undefined behaviour). */
    double v = rrv__value_noise(rrv__v3(1e86, -3e40, 7.5), 3);
    rrv_scene *s = tb_scene(2, 2);
    rrv_error err;
    float img[12];
    int i, finite = 1;
    CHECK(v >= 0 && v <= 1);
    CHECK(rrv__lattice_coord(-1.0) == 4294967295u && rrv__lattice_coord(1e300) < 4294967296.0);
    /* Pixel sums saturate instead of overflowing to Inf, even when the
       caller's buffer is already near the top of float's range; samples
       above RRV_MAX_SAMPLE are discarded and counted. The radiance is set
       after prepare, as a caller editing a prepared scene could. */
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = RRV_MAX_RADIANCE;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = RRV_MAX_SAMPLE;
    for (i = 0; i < 12; ++i) img[i] = 0.999f * FLT_MAX;
    rrv_render_rect(s, 0, 0, 2, 2, 0, 1 << 20, img, 2, NULL, NULL); /* adds 1e36 a pixel */
    for (i = 0; i < 12; ++i) finite &= img[i] == FLT_MAX;
    CHECK(finite);
    {
        rrv_render_stats st;
        memset(&st, 0, sizeof st);
        for (i = 0; i < 12; ++i) img[i] = 0;
        s->environment.L[1] = 10 * RRV_MAX_SAMPLE;
        rrv_render_rect(s, 0, 0, 2, 2, 0, 8, img, 2, &st, NULL);
        CHECK(st.nonfinite == 32 && img[0] == 0);
    }
    s->environment.L[1] = 2 * RRV_MAX_RADIANCE;
    CHECK(rrv_scene_prepare(s, &err) == RRV_ERROR_ARGUMENT);
    rrv_scene_free(s);
}

static void test_blob_count_is_capped(void)
{
    /* Each blob statement is checked against the limits by summing the
       field; uncapped, a file of blob lines cost the square of its length. */
    const char *head = "camera eye 0 0 5 look 0 0 0\nmedium m box -1 -1 -1 1 1 1\n";
    const char *line = "density m blob center 0 0 0 radius 0.1 weight 0.001\n";
    size_t hn = strlen(head), ln = strlen(line), i, n = RRV_MAX_BLOBS + 1;
    char *text = (char *)malloc(hn + n * ln + 1);
    rrv_scene *s = NULL;
    rrv_error err;
    memcpy(text, head, hn);
    for (i = 0; i < n; ++i) memcpy(text + hn + i * ln, line, ln);
    CHECK(rrv_scene_parse(text, hn + n * ln, "blobs.rrv", NULL, NULL, &s, &err) == RRV_ERROR_LIMIT);
    CHECKF(err.line == 2 + RRV_MAX_BLOBS + 1 && strcmp(err.message, "density: more than 4096 blobs in one field (a grid holds more)") == 0,
           "%d: %s", err.line, err.message);
    CHECK(rrv_scene_parse(text, hn + (n - 1) * ln, "blobs.rrv", NULL, NULL, &s, &err) == RRV_OK);
    CHECK(s && s->media[0].density.blob_count == RRV_MAX_BLOBS);
    rrv_scene_free(s);
    free(text);
}

int main(int argc, char **argv)
{
    (void)argc; (void)argv;
    RUN(test_vector_math);
    RUN(test_rng);
    RUN(test_henyey_greenstein);
    RUN(test_bvh_against_brute_force);
    RUN(test_transmittance_homogeneous);
    RUN(test_transmittance_gaussian_blob);
    RUN(test_transmittance_grid_ramp);
    RUN(test_transmittance_inside_one_huge_voxel);
    RUN(test_channel_groups);
    RUN(test_channel_groups_overlapping_media);
    RUN(test_channel_groups_bound_work);
    RUN(test_white_furnace);
    RUN(test_white_furnace_chromatic);
    RUN(test_white_furnace_sobol);
    RUN(test_sobol_sampler_nets);
    RUN(test_sobol_sampler_names_align);
    RUN(test_sobol_sampler_independent);
    RUN(test_tiles_are_bit_identical);
    RUN(test_grid_gradient_stencil);
    RUN(test_blackbody);
    RUN(test_trapped_eikonal_rays_are_bounded_and_counted);
    RUN(test_rays_trapped_in_a_waveguide_end_early_and_are_counted);
    RUN(test_tracking_walks_are_bounded);
    RUN(test_majorant_follows_large_voxels);
    RUN(test_prepare_accounting_and_limits);
    RUN(test_gradient_bounds_in_closed_form);
    RUN(test_hostile_numbers_stay_finite);
    RUN(test_blob_count_is_capped);
    return CHECK_EXIT_CODE();
}
