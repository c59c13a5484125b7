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

/* Checks ratio tracking and delta tracking against exp(-tau) for a ray. */
static void check_transmittance(rrv_scene *s, rrv_vec3 o, rrv_vec3 d, double tmax, double tau, const char *what)
{
    rrv__context ctx;
    rrv__rng rng;
    stats ratio = {0, 0, 0}, delta = {0, 0, 0};
    double expected = exp(-tau);
    int i, n = 200000;
    memset(&ctx, 0, sizeof ctx);
    ctx.scene = s;
    ctx.eta_camera2 = 1;
    rrv__rng_seed(&rng, 5, 0, 0);
    for (i = 0; i < n; ++i) {
        double T[3];
        rrv__path path;
        rrv__flight flight;
        int outcome;
        rrv__ratio_tracking_transmittance(&ctx, o, d, tmax, &rng, T);
        stats_add(&ratio, T[1]);
        rrv__path_start(&path, &rng);
        outcome = rrv__sample_free_flight_path(&ctx, &path, o, d, tmax, &rng, &flight);
        stats_add(&delta, outcome == RRV__FLIGHT_PASSED ? path.beta[1] * rrv__path_mis(&path) : 0.0);
    }
    CHECKF(fabs(stats_mean(&ratio) - expected) < 4 * stats_se(&ratio), "%s: ratio tracking %g +- %g, exp(-tau) %g",
           what, stats_mean(&ratio), stats_se(&ratio), expected);
    CHECKF(fabs(stats_mean(&delta) - expected) < 4 * stats_se(&delta), "%s: delta tracking %g +- %g, exp(-tau) %g",
           what, stats_mean(&delta), stats_se(&delta), expected);
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

/* The mean pixel value of an image rendered one sample per call, with its
   standard error over all (pixel, sample) estimates. */
static stats render_statistics(rrv_scene *s, int spp, int channel)
{
    int w = s->camera.width, h = s->camera.height, k, i;
    float *img = (float *)malloc((size_t)w * h * 3 * sizeof(float));
    stats st = {0, 0, 0};
    for (k = 0; k < spp; ++k) {
        memset(img, 0, (size_t)w * h * 3 * sizeof(float));
        rrv_render_rect(s, 0, 0, w, h, k, k + 1, img, w, NULL);
        for (i = 0; i < w * h; ++i) stats_add(&st, img[3 * i + channel]);
    }
    free(img);
    return st;
}

/* An albedo-1 medium in a uniform environment neither adds nor removes
   light: every pixel sees the environment radiance. */
static void furnace(double s0, double s1, double s2, int spp, double max_se)
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

static void test_white_furnace(void) { furnace(2.0, 2.0, 2.0, 64, 0.01); }

/* Chromatic extinction reweights each channel at every collision, so the
   estimate is noisier: more samples for a comparable bound. */
static void test_white_furnace_chromatic(void) { furnace(1.0, 2.0, 4.0, 1024, 0.02); }

static void test_tiles_are_bit_identical(void)
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
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    rrv_render_rect(s, 0, 0, w, h, 0, 8, full, w, NULL);
    for (y = 0; y < h; y += 5)
        for (x = 0; x < w; x += 7)
            rrv_render_rect(s, x, y, x + 7 > w ? w : x + 7, y + 5 > h ? h : y + 5, 0, 8,
                            tiled + 3 * (y * w + x), w, NULL);
    CHECK(memcmp(full, tiled, (size_t)w * h * 3 * sizeof(float)) == 0);
    {
        double total = 0;
        for (x = 0; x < w * h * 3; ++x) total += full[x];
        CHECKF(total > 0, "the image is black: the comparison would be empty");
    }
    free(full);
    free(tiled);
    rrv_scene_free(s);
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
    RUN(test_white_furnace);
    RUN(test_white_furnace_chromatic);
    RUN(test_tiles_are_bit_identical);
    RUN(test_grid_gradient_stencil);
    RUN(test_blackbody);
    return CHECK_EXIT_CODE();
}
