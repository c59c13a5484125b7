/* Next-event estimation in refracting media (rrv_settings.nee).
   `none` is pure forward tracing: a light counts only where the bent path
   hits it, so it is unbiased whatever the IOR; `straight` connects with
   straight shadow rays and is biased there. The tests show both:
   - white furnaces (albedo-1 medium under a uniform sky of radiance 1,
     camera in air) whose medium also carries a Luneburg IOR or a strong
     Gaussian blob of IOR: `none` gives 1 for the comb, Poisson and eikonal
     integrators, `straight` is off by more than 4 standard errors;
   - a lens caustic (square light over a Luneburg lens over a white floor):
     `none` with the comb and `none` with eikonal agree in every block of
     pixels within 4 standard errors, and `straight` misses the caustic;
   - `shoot` (curved connections, eikonal): the furnaces give 1, the
     caustic and fog inside the lens agree with `none` within 4 standard
     errors, and the solver is checked against the closed-form two-point
     problem of the Luneburg lens, finite differences of its Jacobian,
     reciprocity, and the partition of paths between the estimators.
   Fixed seeds; the renders compared are independent (distinct seeds).
   NEE_VERBOSE=1 prints the values. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "scene_builder.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

static int verbose;
#define SAY(...)                                                                                                       \
    do {                                                                                                               \
        if (verbose) printf(__VA_ARGS__);                                                                              \
    } while (0)

typedef struct method {
    rrv_integrator integrator;
    rrv_refraction_scheme scheme;
    const char *name;
} method;

static const method comb = {RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_COMB, "comb"};
static const method poisson = {RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_POISSON, "poisson"};
static const method eikonal = {RRV_INTEGRATOR_EIKONAL, RRV_REFRACTION_DEFAULT, "eikonal"};

static void use(rrv_scene *s, const method *m, rrv_nee nee)
{
    s->settings.integrator = m->integrator;
    s->settings.refraction = m->scheme;
    s->settings.nee = nee;
}

typedef struct stats { double sum, sum2; long n; } stats;
static void stats_add(stats *s, double x) { s->sum += x; s->sum2 += x * x; s->n++; }
static double stats_mean(const stats *s) { return s->n ? s->sum / s->n : 0.0; }
static double stats_se(const stats *s)
{
    double m = stats_mean(s);
    return s->n > 1 ? sqrt(fmax(0.0, s->sum2 / s->n - m * m) / (s->n - 1)) : 0.0;
}

/* Renders pixels [x0,x1) x [y0,y1) one sample index at a time and files
   each pixel sample of the green channel into the stats of its block (bw x
   bh pixels, numbered over the whole image). */
static void block_samples_rect(const rrv_scene *s, int spp, int x0, int y0, int x1, int y1, int bw, int bh,
                               stats *blocks, rrv_render_stats *rs)
{
    int w = x1 - x0, h = y1 - y0, k, x, y, per_row = s->camera.width / bw;
    float *img = (float *)malloc((size_t)w * h * 3 * sizeof(float));
    for (k = 0; k < spp; ++k) {
        memset(img, 0, (size_t)w * h * 3 * sizeof(float));
        rrv_render_rect(s, x0, y0, x1, y1, k, k + 1, img, w, rs, NULL);
        for (y = 0; y < h; ++y)
            for (x = 0; x < w; ++x)
                stats_add(&blocks[((y + y0) / bh) * per_row + (x + x0) / bw], img[3 * (y * w + x) + 1]);
    }
    free(img);
}

static void block_samples(const rrv_scene *s, int spp, int bw, int bh, stats *blocks)
{
    block_samples_rect(s, spp, 0, 0, s->camera.width, s->camera.height, bw, bh, blocks, NULL);
}

/* ---- white furnaces with refraction ------------------------------------------ */

enum { LUNEBURG_IOR, BLOB_IOR };

/* An albedo-1 medium filling the box [-1,1]^3 (optical radius 1) under a
   sky of radiance 1, the camera in air outside: every pixel's expectation
   is exactly 1 whatever the medium's IOR does inside. */
static rrv_scene *furnace_scene(int ior_kind)
{
    rrv_scene *s = tb_scene(6, 6);
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 1.0);
    rrv_error err;
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = 1.0;
    s->camera.fov = 20; /* every pixel looks into the medium */
    s->settings.max_depth = 1000;
    s->settings.step = 0.02;
    s->settings.bend_tolerance = 0.01;
    if (ior_kind == LUNEBURG_IOR) {
        m->ior.kind = RRV_FIELD_LUNEBURG;
        m->ior.center = rrv__v3(0, 0, 0);
        m->ior.radius = 1;
    } else {
        /* eta 2 at the centre: bends rays by tens of degrees; the IOR
           jumps by at most exp(-1 / (2 0.35^2)) = 0.017 at the box faces,
           a sharp interface (Fresnel) */
        rrv_blob *b = tb_blobs(&m->ior, 1);
        b->center = rrv__v3(0.1, -0.05, 0);
        b->radius = 0.35;
        b->weight = 1.0;
    }
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "prepare: %s", err.message);
    return s;
}

static stats furnace_run(rrv_scene *s, const method *m, rrv_nee nee, int spp, uint64_t seed)
{
    stats all = {0, 0, 0};
    use(s, m, nee);
    s->settings.seed = seed;
    block_samples(s, spp, s->camera.width, s->camera.height, &all);
    return all;
}

static void furnace_case(int ior_kind, const char *name, int straight_spp)
{
    static const method *const unbiased[] = {&comb, &poisson, &eikonal};
    rrv_scene *s = furnace_scene(ior_kind);
    stats st;
    double mean, se;
    int i;
    for (i = 0; i < 3; ++i) {
        st = furnace_run(s, unbiased[i], RRV_NEE_NONE, 8, 21 + i);
        mean = stats_mean(&st);
        se = stats_se(&st);
        SAY("  %-8s furnace %-8s nee none:     %.7f se %.1e (%ld samples)\n", name, unbiased[i]->name, mean, se,
            st.n);
        /* Forward tracing in a white furnace returns exactly the sky on every
           path (no roulette while beta = 1), so the standard error is 0 and
           the bound is float rounding. */
        CHECKF(fabs(mean - 1.0) < 4 * se + 1e-6, "%s, %s, nee none: %.7f +- %.1e, expected 1", name,
               unbiased[i]->name, mean, se);
    }
    /* shoot: the sky is left to forward paths wherever a connection would
       touch a refraction support, straight NEE (with MIS) elsewhere */
    st = furnace_run(s, &eikonal, RRV_NEE_SHOOT, 8, 27);
    mean = stats_mean(&st);
    se = stats_se(&st);
    SAY("  %-8s furnace eikonal  nee shoot:    %.7f se %.1e\n", name, mean, se);
    CHECKF(fabs(mean - 1.0) < 4 * se + 1e-6, "%s, eikonal, nee shoot: %.7f +- %.1e, expected 1", name, mean, se);
    st = furnace_run(s, &comb, RRV_NEE_STRAIGHT, straight_spp, 31);
    mean = stats_mean(&st);
    se = stats_se(&st);
    SAY("  %-8s furnace comb     nee straight: %.5f se %.1e (%.1f standard errors off)\n", name, mean, se,
        (mean - 1.0) / se);
    /* documents the bias of straight shadow rays through refracting media */
    CHECKF(fabs(mean - 1.0) > 4 * se, "%s, comb, nee straight: %.5f +- %.1e is within 4 se of 1", name, mean, se);
    rrv_scene_free(s);
}

static void test_furnace_luneburg(void) { furnace_case(LUNEBURG_IOR, "Luneburg", 256); }
static void test_furnace_blob(void) { furnace_case(BLOB_IOR, "blob", 512); }

/* ---- a lens caustic -------------------------------------------------------------- */

/* A 1 m square light at height 3 over a Luneburg lens of radius 0.5 (no
   density) whose bottom is 0.7 above a white floor; the camera looks at the
   floor under the lens from below the lens. Direct light only. */
static const char caustic_text[] =
    "camera eye 0 0.6 -1.8  look 0 0 0.2  up 0 1 0  fov 40  resolution 32 24\n"
    "render maxdepth 1 step 0.01\n"
    "material white diffuse albedo 1 1 1\n"
    "quad origin -3 0 -3  u 6 0 0  v 0 0 6  material white\n"
    "quad origin -0.5 3 -0.5  u 1 0 0  v 0 0 1  L 10 10 10\n"
    "medium lens box -0.5 0.7 -0.5 0.5 1.7 0.5  sigma_a 0 0 0  sigma_s 0 0 0\n"
    "ior lens luneburg center 0 1.2 0 radius 0.5\n";

#define BLOCK 4
#define BLOCKS_X (32 / BLOCK)
#define BLOCKS_Y (24 / BLOCK)
#define NBLOCKS (BLOCKS_X * BLOCKS_Y)

static void test_lens_caustic(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    stats a[NBLOCKS], b[NBLOCKS], c[NBLOCKS];
    int i, peak = 0, compared = 0;
    const int spp = 320;
    if (rrv_scene_parse(caustic_text, sizeof caustic_text - 1, "caustic", NULL, NULL, &s, &err) != RRV_OK) {
        CHECKF(0, "parse: %s", err.message);
        return;
    }
    memset(a, 0, sizeof a);
    memset(b, 0, sizeof b);
    memset(c, 0, sizeof c);
    use(s, &comb, RRV_NEE_NONE);
    s->settings.seed = 1;
    block_samples(s, spp, BLOCK, BLOCK, a);
    use(s, &eikonal, RRV_NEE_NONE);
    s->settings.seed = 2;
    block_samples(s, spp, BLOCK, BLOCK, b);
    use(s, &comb, RRV_NEE_STRAIGHT);
    s->settings.seed = 3;
    block_samples(s, spp, BLOCK, BLOCK, c);
    for (i = 0; i < NBLOCKS; ++i) {
        double d = stats_mean(&a[i]) - stats_mean(&b[i]);
        double se = sqrt(stats_se(&a[i]) * stats_se(&a[i]) + stats_se(&b[i]) * stats_se(&b[i]));
        if (stats_mean(&a[i]) > stats_mean(&a[peak])) peak = i;
        if (se > 0) ++compared;
        CHECKF(fabs(d) <= 4 * se, "block %d,%d: comb %.4f, eikonal %.4f, difference %.4f over 4 se %.4f", i % BLOCKS_X,
               i / BLOCKS_X, stats_mean(&a[i]), stats_mean(&b[i]), d, 4 * se);
    }
    if (verbose) {
        int y, x;
        const stats *maps[3];
        const char *names[3] = {"none, comb", "none, eikonal", "straight, comb"};
        maps[0] = a; maps[1] = b; maps[2] = c;
        for (i = 0; i < 3; ++i) {
            printf("  lens caustic, nee %s (block means):\n", names[i]);
            for (y = 0; y < BLOCKS_Y; ++y) {
                printf("   ");
                for (x = 0; x < BLOCKS_X; ++x) printf(" %.3f", stats_mean(&maps[i][y * BLOCKS_X + x]));
                printf("\n");
            }
        }
    }
    /* the comparison sees most of the image (the sky-free floor) */
    CHECKF(compared >= NBLOCKS * 3 / 4, "only %d of %d blocks have light to compare", compared, NBLOCKS);
    {
        double none = stats_mean(&a[peak]), straight = stats_mean(&c[peak]);
        double se = sqrt(stats_se(&a[peak]) * stats_se(&a[peak]) + stats_se(&c[peak]) * stats_se(&c[peak]));
        SAY("  caustic peak block %d,%d: none %.4f +- %.4f, straight %.4f +- %.4f\n", peak % BLOCKS_X,
            peak / BLOCKS_X, none, stats_se(&a[peak]), straight, stats_se(&c[peak]));
        /* the test is sharp enough to see the caustic at all */
        CHECKF(stats_se(&a[peak]) < 0.1 * none, "caustic block too noisy: %.4f +- %.4f", none, stats_se(&a[peak]));
        CHECKF(fabs(none - straight) > 4 * se && straight < 0.7 * none,
               "straight NEE %.4f should miss the caustic %.4f by far (se %.4f)", straight, none, se);
    }
    rrv_scene_free(s);
}

/* nee shoot (eikonal) against nee none (comb) around the caustic: blocks
   of 4x4 pixels agree within 4 standard errors, and the curved connections
   make the caustic far less noisy than forward tracing does. */
static void test_lens_caustic_shoot(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_render_stats rs;
    stats a[NBLOCKS], b[NBLOCKS];
    int i, bx, by, peak = -1;
    const int x0 = 8, y0 = 8, x1 = 24, y1 = 20;
    if (rrv_scene_parse(caustic_text, sizeof caustic_text - 1, "caustic", NULL, NULL, &s, &err) != RRV_OK) {
        CHECKF(0, "parse: %s", err.message);
        return;
    }
    memset(a, 0, sizeof a);
    memset(b, 0, sizeof b);
    memset(&rs, 0, sizeof rs);
    use(s, &comb, RRV_NEE_NONE);
    s->settings.seed = 4;
    block_samples_rect(s, 640, x0, y0, x1, y1, BLOCK, BLOCK, a, NULL);
    use(s, &eikonal, RRV_NEE_SHOOT);
    s->settings.seed = 5;
    block_samples_rect(s, 24, x0, y0, x1, y1, BLOCK, BLOCK, b, &rs);
    for (by = y0 / BLOCK; by < y1 / BLOCK; ++by) {
        for (bx = x0 / BLOCK; bx < x1 / BLOCK; ++bx) {
            double d, se;
            i = by * BLOCKS_X + bx;
            d = stats_mean(&b[i]) - stats_mean(&a[i]);
            se = sqrt(stats_se(&a[i]) * stats_se(&a[i]) + stats_se(&b[i]) * stats_se(&b[i]));
            if (peak < 0 || stats_mean(&a[i]) > stats_mean(&a[peak])) peak = i;
            SAY("  lens caustic block %d,%d: none %.4f +- %.4f (%ld samples), shoot %.4f +- %.4f (%ld samples)\n", bx, by,
                stats_mean(&a[i]), stats_se(&a[i]), a[i].n, stats_mean(&b[i]), stats_se(&b[i]), b[i].n);
            CHECKF(fabs(d) <= 4 * se, "block %d,%d: none %.4f, shoot %.4f, difference %.4f over 4 se %.4f", bx, by,
                   stats_mean(&a[i]), stats_mean(&b[i]), d, 4 * se);
        }
    }
    SAY("  shoot: %llu solves, %.1f%% converged, %.1f iterations, %.2f trials a connection, %.0f segments a chain\n",
        (unsigned long long)rs.solves, 100.0 * rs.solves_converged / (double)rs.solves,
        rs.solve_iterations / (double)rs.solves, rs.solve_trials / (double)rs.solve_connections,
        rs.solve_segments / (double)rs.solves_converged);
    CHECK(rs.solves > 0 && rs.solve_connections > 0 && rs.solves_unsupported == 0);
    /* the curved connections do the work: per sample, the caustic's
       variance is far below that of forward tracing (measured 23x) */
    {
        double vs = stats_se(&b[peak]) * stats_se(&b[peak]) * (double)b[peak].n;
        double vn = stats_se(&a[peak]) * stats_se(&a[peak]) * (double)a[peak].n;
        SAY("  caustic variance per sample: shoot %.3f, none %.3f\n", vs, vn);
        CHECKF(vs * 5 < vn, "caustic: variance per sample %.3f with shoot, %.3f with none", vs, vn);
    }
    /* The comb cannot shoot: its curved connections are left to forward
       paths, counted, and the image stays unbiased. */
    memset(b, 0, sizeof b);
    memset(&rs, 0, sizeof rs);
    use(s, &comb, RRV_NEE_SHOOT);
    s->settings.seed = 6;
    block_samples_rect(s, 640, x0, y0, x1, y1, BLOCK, BLOCK, b, &rs);
    CHECK(rs.solves == 0 && rs.solves_unsupported > 0);
    for (by = y0 / BLOCK; by < y1 / BLOCK; ++by) {
        for (bx = x0 / BLOCK; bx < x1 / BLOCK; ++bx) {
            double d, se;
            i = by * BLOCKS_X + bx;
            d = stats_mean(&b[i]) - stats_mean(&a[i]);
            se = sqrt(stats_se(&a[i]) * stats_se(&a[i]) + stats_se(&b[i]) * stats_se(&b[i]));
            CHECKF(fabs(d) <= 4 * se, "comb, shoot unsupported: block %d,%d: %.4f vs none %.4f, 4 se %.4f", bx, by,
                   stats_mean(&b[i]), stats_mean(&a[i]), 4 * se);
        }
    }
    rrv_scene_free(s);
}

/* Fog inside the lens (albedo 1, optical radius 0.75) under the same
   light, seen from the side, three bounces: shooting from vertices in the
   medium, most of them inside the refraction support, with the phase
   function, against forward tracing. */
static const char fog_text[] =
    "camera eye 0 1.2 -3  look 0 1.0 0  up 0 1 0  fov 40  resolution 32 24\n"
    "render maxdepth 3 step 0.01\n"
    "material white diffuse albedo 1 1 1\n"
    "quad origin -3 0 -3  u 6 0 0  v 0 0 6  material white\n"
    "quad origin -0.5 3 -0.5  u 1 0 0  v 0 0 1  L 10 10 10\n"
    "medium lens box -0.5 0.7 -0.5 0.5 1.7 0.5  sigma_a 0 0 0  sigma_s 1.5 1.5 1.5\n"
    "density lens constant 1\n"
    "ior lens luneburg center 0 1.2 0 radius 0.5\n";

static void test_fog_in_lens_shoot(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_render_stats rs;
    stats a[NBLOCKS], b[NBLOCKS];
    int i, bx, by;
    const int x0 = 8, y0 = 4, x1 = 24, y1 = 16;
    if (rrv_scene_parse(fog_text, sizeof fog_text - 1, "fog", NULL, NULL, &s, &err) != RRV_OK) {
        CHECKF(0, "parse: %s", err.message);
        return;
    }
    memset(a, 0, sizeof a);
    memset(b, 0, sizeof b);
    memset(&rs, 0, sizeof rs);
    use(s, &eikonal, RRV_NEE_NONE);
    s->settings.seed = 7;
    block_samples_rect(s, 1024, x0, y0, x1, y1, BLOCK, BLOCK, a, NULL);
    use(s, &eikonal, RRV_NEE_SHOOT);
    s->settings.seed = 8;
    block_samples_rect(s, 16, x0, y0, x1, y1, BLOCK, BLOCK, b, &rs);
    for (by = y0 / BLOCK; by < y1 / BLOCK; ++by) {
        for (bx = x0 / BLOCK; bx < x1 / BLOCK; ++bx) {
            double d, se;
            i = by * BLOCKS_X + bx;
            d = stats_mean(&b[i]) - stats_mean(&a[i]);
            se = sqrt(stats_se(&a[i]) * stats_se(&a[i]) + stats_se(&b[i]) * stats_se(&b[i]));
            SAY("  fog block %d,%d: none %.4f +- %.4f, shoot %.4f +- %.4f\n", bx, by, stats_mean(&a[i]), stats_se(&a[i]),
                stats_mean(&b[i]), stats_se(&b[i]));
            CHECKF(fabs(d) <= 4 * se, "fog block %d,%d: none %.4f, shoot %.4f, difference %.4f over 4 se %.4f", bx, by,
                   stats_mean(&a[i]), stats_mean(&b[i]), d, 4 * se);
        }
    }
    SAY("  fog shoot: %llu solves, %.1f%% converged, %llu connections\n", (unsigned long long)rs.solves,
        100.0 * rs.solves_converged / (double)rs.solves, (unsigned long long)rs.solve_connections);
    CHECK(rs.solve_connections > 100);
    rrv_scene_free(s);
}

/* ---- settings ---------------------------------------------------------------------- */

static void test_nee_key(void)
{
    static const char *const texts[] = {"camera eye 0 0 -1 look 0 0 0\nrender nee none\n",
                                        "camera eye 0 0 -1 look 0 0 0\nrender nee straight\n",
                                        "camera eye 0 0 -1 look 0 0 0\nrender spp 1\n"};
    static const rrv_nee expected[] = {RRV_NEE_NONE, RRV_NEE_STRAIGHT, RRV_NEE_DEFAULT};
    int i;
    for (i = 0; i < 3; ++i) {
        rrv_scene *s = NULL;
        rrv_error err;
        rrv_result r = rrv_scene_parse(texts[i], strlen(texts[i]), "nee", NULL, NULL, &s, &err);
        CHECKF(r == RRV_OK, "%s: %s", texts[i], err.message);
        if (r == RRV_OK) CHECKF(s->settings.nee == expected[i], "%s: nee %d", texts[i], (int)s->settings.nee);
        rrv_scene_free(s);
    }
}

static void test_nee_key_rejects_unknown_mode(void)
{
    static const char text[] = "camera eye 0 0 5 look 0 0 0\nrender integrator eikonal nee manifold\n";
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r = rrv_scene_parse(text, sizeof text - 1, "bad_nee.rrv", NULL, NULL, &s, &err);
    CHECK(r == RRV_ERROR_PARSE && s == NULL);
    CHECKF(err.line == 2 && strcmp(err.file, "bad_nee.rrv") == 0 &&
               strcmp(err.message, "render: nee must be one of none|straight|shoot, got \"manifold\"") == 0,
           "%s:%d: %s", err.file, err.line, err.message);
}

/* The classic integrator keeps its (exact) straight NEE whatever `nee` says:
   the same image bit for bit. */
static void test_classic_ignores_nee(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    int w, h;
    size_t n, i;
    float *x, *y;
    if (rrv_scene_parse(caustic_text, sizeof caustic_text - 1, "caustic", NULL, NULL, &s, &err) != RRV_OK) {
        CHECKF(0, "parse: %s", err.message);
        return;
    }
    w = s->camera.width;
    h = s->camera.height;
    n = (size_t)w * h * 3;
    x = (float *)calloc(n, sizeof *x);
    y = (float *)calloc(n, sizeof *y);
    s->settings.integrator = RRV_INTEGRATOR_CLASSIC;
    s->settings.nee = RRV_NEE_STRAIGHT;
    rrv_render_rect(s, 0, 0, w, h, 0, 2, x, w, NULL, NULL);
    s->settings.nee = RRV_NEE_NONE;
    rrv_render_rect(s, 0, 0, w, h, 0, 2, y, w, NULL, NULL);
    for (i = 0; i < n; ++i)
        if (x[i] != y[i]) break;
    CHECKF(i == n, "classic with nee none differs at value %lu", (unsigned long)i);
    free(x);
    free(y);
    rrv_scene_free(s);
}

/* ---- the solver: shooting along bent rays ------------------------------------------ */

/* A Luneburg lens of radius 1 at the origin filling its box, no density. */
static rrv_scene *lens_scene(double step, rrv_stepper stepper)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 0.0);
    rrv_error err;
    m->density.kind = RRV_FIELD_NONE;
    m->ior.kind = RRV_FIELD_LUNEBURG;
    m->ior.center = rrv__v3(0, 0, 0);
    m->ior.radius = 1;
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.step = step;
    s->settings.stepper = stepper;
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "prepare: %s", err.message);
    return s;
}

static void solver_context(rrv__context *ctx, const rrv_scene *s)
{
    memset(ctx, 0, sizeof *ctx);
    ctx->scene = s;
    ctx->eikonal = ctx->bends = 1;
    ctx->eta_camera2 = 1;
}

/* The two-point problem in a Luneburg lens (eta^2 = 2 - r^2, R = 1) has a
   closed form. In the optical parameter d(sigma) = ds / eta, with p = eta
   dx/ds, the ray equation is dx/dsigma = p, dp/dsigma = eta grad eta = -x,
   so x(sigma) = x0 cos(sigma) + p0 sin(sigma) with |p0| = eta(x0). Reaching
   x1 at sigma_1 gives p0 = (x1 - x0 c) / sin(sigma_1), c = cos(sigma_1), and
   |p0|^2 = 2 - |x0|^2 turns into 2c^2 - 2c (x0.x1) + |x0|^2 + |x1|^2 - 2 = 0.
   A change dw0 of the initial direction moves x(sigma_1) by eta0
   sin(sigma_1) dw0; projected on the plane perpendicular to the arriving
   direction w1 that is |det J_perp| = eta0^2 sin^2(sigma_1) |w0.w1|. Of the
   two roots c, the larger is the short arc; the other arc passes the
   ellipse's farthest point, at |x|^2 = 1 + sqrt(1 - |x0 x p0|^2) >= 1, so
   it leaves the lens and the closed form does not describe it. */
typedef struct closed_root { rrv_vec3 w0, w1; double det; int inside; } closed_root;

static closed_root luneburg_root(rrv_vec3 x0, rrv_vec3 x1, double sign)
{
    closed_root r;
    double a = rrv__dot(x0, x1), b = rrv__dot(x0, x0) + rrv__dot(x1, x1) - 2.0;
    double c = 0.5 * (a + sign * sqrt(a * a - 2.0 * b)), sigma = acos(c), sn = sin(sigma);
    rrv_vec3 p0 = rrv__scale(rrv__madd(x1, x0, -c), 1.0 / sn);
    rrv_vec3 p1 = rrv__add(rrv__scale(x0, -sn), rrv__scale(p0, c));
    double eta0 = sqrt(2.0 - rrv__dot(x0, x0));
    int k;
    r.w0 = rrv__normalize(p0);
    r.w1 = rrv__normalize(p1);
    r.det = eta0 * eta0 * sn * sn * fabs(rrv__dot(r.w0, r.w1));
    r.inside = 1;
    for (k = 0; k <= 100; ++k) {
        double t = sigma * k / 100.0;
        rrv_vec3 x = rrv__add(rrv__scale(x0, cos(t)), rrv__scale(p0, sin(t)));
        if (rrv__dot(x, x) >= 0.999) r.inside = 0;
    }
    return r;
}

static void test_luneburg_two_point(void)
{
    static const double pts[3][6] = {{0.3, -0.2, 0.1, -0.25, 0.35, 0.2},
                                     {0.5, 0.0, 0.0, -0.5, 0.1, 0.0},
                                     {0.2, 0.1, -0.3, 0.1, -0.4, 0.5}};
    rrv_scene *s = lens_scene(0.002, RRV_STEPPER_RK4);
    rrv__context ctx;
    rrv__rng rng;
    int i, k;
    solver_context(&ctx, s);
    rrv__rng_seed(&rng, 5, 0, 0);
    for (i = 0; i < 3; ++i) {
        rrv_vec3 x0 = rrv__v3(pts[i][0], pts[i][1], pts[i][2]), x1 = rrv__v3(pts[i][3], pts[i][4], pts[i][5]);
        closed_root want = luneburg_root(x0, x1, 1.0), other = luneburg_root(x0, x1, -1.0);
        int found = 0, converged = 0;
        CHECK(want.inside && !other.inside);
        for (k = 0; k < 40; ++k) {
            rrv__root got;
            if (!rrv__solve_shot(&ctx, x0, x1, NULL, rrv__solver_seed(x0, x1, &rng), &got)) continue;
            ++converged;
            if (rrv__length(rrv__sub(got.w0, want.w0)) < 1e-4) {
                double err_w0 = rrv__length(rrv__sub(got.w0, want.w0));
                double err_w1 = rrv__length(rrv__sub(got.dir, want.w1));
                double err_det = fabs(fabs(got.det) / want.det - 1.0);
                if (!found)
                    SAY("  Luneburg two-point %d: w0 off by %.1e, w1 by %.1e, |det J_perp| %.6f vs %.6f (%.1e), %d "
                        "iterations, %ld segments\n",
                        i, err_w0, err_w1, fabs(got.det), want.det, err_det, got.iterations, got.segments);
                ++found;
                /* RK4 at h = 0.002 is exact to ~1e-11; the endpoint lies on a
                   chord, off the curve by at most kappa h^2 / 8 = 5e-7 (kappa
                   = |grad eta| / eta <= 1), and the arriving direction is the
                   chord's, off the tangent by up to kappa h / 2 = 1e-3 */
                CHECKF(err_w0 < 2e-6 && err_w1 < 1e-3 && err_det < 1e-5, "point %d: w0 %.1e w1 %.1e det %.1e", i,
                       err_w0, err_w1, err_det);
                CHECK(got.curved);
            }
        }
        SAY("  Luneburg two-point %d: %d of 40 random seeds converged, %d to the closed-form root\n", i, converged,
            found);
        CHECKF(found >= 10, "point %d: the closed-form root found from only %d of 40 seeds", i, found);
    }
    rrv_scene_free(s);
}

/* Two Gaussian blobs of IOR (eta up to 1.5) in a box, no density; at the
   box faces they are below 1e-10, no interface. */
static rrv_scene *blob_scene(double step, rrv_stepper stepper)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_medium *m = tb_medium(s, rrv__v3(-2, -2, -2), rrv__v3(2, 2, 2), 0.0, 0.0);
    rrv_blob *b;
    rrv_error err;
    m->density.kind = RRV_FIELD_NONE;
    b = tb_blobs(&m->ior, 2);
    b[0].center = rrv__v3(0.1, -0.05, 0);
    b[0].radius = 0.3;
    b[0].weight = 0.5;
    b[1].center = rrv__v3(-0.2, 0.2, 0.3);
    b[1].radius = 0.2;
    b[1].weight = -0.2;
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.step = step;
    s->settings.stepper = stepper;
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "prepare: %s", err.message);
    return s;
}

/* The Jacobi field carried through the discrete steps against central
   differences of the traced endpoint (both projected on the plane
   perpendicular to the arriving chord, the part that J_perp is). */
static void jacobian_against_differences(rrv_scene *s, rrv_vec3 x0, rrv_vec3 w, rrv_vec3 y, const rrv_vec3 *plane,
                                         const char *name)
{
    rrv__context ctx;
    rrv__shot base;
    rrv_vec3 e1, e2;
    const double eps = 1e-6;
    int j;
    solver_context(&ctx, s);
    rrv__frame(w, &e1, &e2);
    rrv__shoot(&ctx, x0, w, e1, e2, y, plane, NULL, NULL, &base);
    CHECKF(base.status == RRV__SHOT_REACHED, "%s: the shot did not reach y's plane", name);
    if (base.status != RRV__SHOT_REACHED) return;
    for (j = 0; j < 2; ++j) {
        rrv_vec3 ej = j ? e2 : e1, wp = rrv__normalize(rrv__madd(w, ej, eps)), wm = rrv__normalize(rrv__madd(w, ej, -eps));
        rrv_vec3 t1, t2, fd, an;
        rrv__shot plus, minus;
        double err;
        rrv__frame(wp, &t1, &t2);
        rrv__shoot(&ctx, x0, wp, t1, t2, y, plane, NULL, NULL, &plus);
        rrv__frame(wm, &t1, &t2);
        rrv__shoot(&ctx, x0, wm, t1, t2, y, plane, NULL, NULL, &minus);
        fd = rrv__scale(rrv__sub(plus.end, minus.end), 0.5 / eps);
        an = base.de[j];
        if (!plane) { /* the perpendicular plane turns with the path: compare across it */
            fd = rrv__madd(fd, base.dir, -rrv__dot(fd, base.dir));
            an = rrv__madd(an, base.dir, -rrv__dot(an, base.dir));
        }
        err = rrv__length(rrv__sub(fd, an)) / rrv__length(an);
        SAY("  Jacobian %-22s column %d: |J| %.5f, relative difference to central differences %.1e (%ld segments)\n",
            name, j, rrv__length(an), err, base.segments);
        /* central differences at eps = 1e-6 are good to ~1e-8 relative here */
        CHECKF(err < 1e-5, "%s, column %d: Jacobi field %g %g %g, differences %g %g %g", name, j, an.x, an.y, an.z, fd.x,
               fd.y, fd.z);
    }
}

static void test_jacobian_against_differences(void)
{
    rrv_scene *a = blob_scene(0.01, RRV_STEPPER_RK4), *b = blob_scene(0.01, RRV_STEPPER_LEAPFROG);
    rrv_scene *c = lens_scene(0.01, RRV_STEPPER_RK4);
    rrv_vec3 w = rrv__normalize(rrv__v3(0.12, 0.05, 1.0)), light = rrv__normalize(rrv__v3(0.1, -0.2, -1.0));
    jacobian_against_differences(a, rrv__v3(0.05, -0.1, -2.5), w, rrv__v3(0.4, 0.3, 3.0), NULL, "blobs, RK4");
    jacobian_against_differences(b, rrv__v3(0.05, -0.1, -2.5), w, rrv__v3(0.4, 0.3, 3.0), NULL, "blobs, leapfrog");
    jacobian_against_differences(a, rrv__v3(0.2, 0.1, -0.3), w, rrv__v3(0.1, 0.2, 0.6), NULL, "blobs, inside, RK4");
    jacobian_against_differences(c, rrv__v3(0.3, 0.2, -2.0), w, rrv__v3(-0.2, 0.1, 2.0), NULL, "Luneburg, through");
    jacobian_against_differences(c, rrv__v3(0.3, 0.2, -2.0), w, rrv__v3(-0.2, 0.1, 2.0), &light, "Luneburg, light plane");
    jacobian_against_differences(b, rrv__v3(0.05, -0.1, -2.5), w, rrv__v3(0.4, 0.3, 3.0), &light, "blobs, light plane");
    rrv_scene_free(a);
    rrv_scene_free(b);
    rrv_scene_free(c);
}

/* Reciprocity of the connection density. Etendue n^2 dA dw is conserved:
   a pencil from dA0 at x0 (index n0) to dA1 at y (n1) has n0^2 dA0 dw0 =
   n1^2 dA1 dw1 with dw0 = dA1 / |det J(x0 -> y)|, dw1 = dA0 / |det J(y ->
   x0)|, so n1^2 |det J_perp(x0 -> y)| = n0^2 |det J_perp(y -> x0)|. (The
   closed form above agrees: det J = eta_start^2 sin^2(sigma_1) |w0.w1|.)
   The paths there and back agree to the chord's deviation from the curve's
   tangent (kappa h / 2, 1e-3 at h = 0.002), and the densities to 5e-4: the
   two directions are different discretisations of the ray, each ending on
   a chord, whose linear interpolation of the Jacobi field errs by
   O(h^2 |K|), and with the faces cutting different last steps (measured
   from 2e-8 to 2e-4 at h = 0.001 to 0.004, not monotone in h). */
static void reciprocity(rrv_scene *s, rrv_vec3 x0, rrv_vec3 y, const char *name)
{
    rrv__context ctx;
    rrv__root there, back;
    double eta0 = 1.0 + rrv__scene_refractivity(s, x0, NULL), eta1 = 1.0 + rrv__scene_refractivity(s, y, NULL);
    double lhs, rhs;
    solver_context(&ctx, s);
    if (!rrv__solve_shot(&ctx, x0, y, NULL, rrv__normalize(rrv__sub(y, x0)), &there)) {
        CHECKF(0, "%s: no root from x0 to y", name);
        return;
    }
    if (!rrv__solve_shot(&ctx, y, x0, NULL, rrv__scale(there.dir, -1.0), &back)) {
        CHECKF(0, "%s: no root back from y to x0", name);
        return;
    }
    lhs = eta1 * eta1 * fabs(there.det);
    rhs = eta0 * eta0 * fabs(back.det);
    SAY("  reciprocity %-10s eta0 %.4f eta1 %.4f: %.7f vs %.7f (%.1e), paths %.1e apart\n", name, eta0, eta1, lhs, rhs,
        fabs(lhs / rhs - 1.0), rrv__length(rrv__add(back.w0, there.dir)));
    CHECK(rrv__length(rrv__add(back.w0, there.dir)) < 1e-3 && rrv__length(rrv__add(back.dir, there.w0)) < 1e-3);
    CHECKF(fabs(lhs / rhs - 1.0) < 5e-4, "%s: %g vs %g", name, lhs, rhs);
}

static void test_reciprocity(void)
{
    rrv_scene *a = lens_scene(0.002, RRV_STEPPER_RK4), *b = blob_scene(0.002, RRV_STEPPER_RK4);
    reciprocity(a, rrv__v3(0.3, -0.2, 0.1), rrv__v3(-0.25, 0.35, 0.2), "Luneburg");
    reciprocity(a, rrv__v3(0.6, -0.1, -0.5), rrv__v3(0.1, 0.2, 2.0), "Luneburg out");
    reciprocity(b, rrv__v3(0.1, 0.0, -0.1), rrv__v3(0.3, 0.4, 2.5), "blobs");
    rrv_scene_free(a);
    rrv_scene_free(b);
}

/* nee shoot splits the paths from a vertex to a light between three
   estimators, and each path must belong to exactly one: straight NEE takes
   the connections that touch no refraction support, shooting the others
   (curved), and forward paths count only what neither can reach (sharp
   interfaces, the sky, sphere lights). Here, for connections from the floor
   to the light of the caustic scene: where straight NEE may connect, the
   solver's root from the straight seed is that straight path and is not
   counted as curved; where it may not, every root found is curved. */
static void test_partition_is_exclusive(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    rrv__context ctx;
    rrv__rng rng;
    int k, straight = 0, curved = 0;
    if (rrv_scene_parse(caustic_text, sizeof caustic_text - 1, "caustic", NULL, NULL, &s, &err) != RRV_OK) {
        CHECKF(0, "parse: %s", err.message);
        return;
    }
    solver_context(&ctx, s);
    ctx.partition = ctx.shoot = 1;
    rrv__rng_seed(&rng, 3, 0, 0);
    for (k = 0; k < 400; ++k) {
        rrv_vec3 x0 = rrv__v3(4.0 * rrv__uniform(&rng) - 2.0, 1e-5, 4.0 * rrv__uniform(&rng) - 2.0);
        rrv_vec3 y = rrv__v3(rrv__uniform(&rng) - 0.5, 3.0, rrv__uniform(&rng) - 0.5);
        rrv__light_sample ls;
        rrv__root root;
        const rrv_vec3 down = rrv__v3(0, -1, 0); /* the light's normal */
        int allowed, found;
        ls.wi = rrv__normalize(rrv__sub(y, x0));
        ls.dist = rrv__length(rrv__sub(y, x0));
        allowed = rrv__straight_allowed(&ctx, x0, &ls);
        found = rrv__solve_shot(&ctx, x0, y, &down, ls.wi, &root);
        if (allowed) {
            ++straight;
            CHECKF(found && !root.curved && rrv__length(rrv__sub(root.w0, ls.wi)) < 1e-9,
                   "straight connection %d: found %d curved %d", k, found, found ? root.curved : -1);
        } else if (found) {
            ++curved;
            CHECKF(root.curved, "connection %d through a support found a root not counted as curved", k);
        }
    }
    SAY("  partition: %d straight connections, %d curved roots of 400\n", straight, curved);
    CHECK(straight > 50 && curved > 50);
    rrv_scene_free(s);
}

int main(void)
{
    const char *v = getenv("NEE_VERBOSE");
    verbose = v && *v && *v != '0';
    (void)tb_shape; /* the caustic scene is parsed, not built */
    RUN(test_nee_key);
    RUN(test_nee_key_rejects_unknown_mode);
    RUN(test_classic_ignores_nee);
    RUN(test_furnace_luneburg);
    RUN(test_furnace_blob);
    RUN(test_lens_caustic);
    RUN(test_lens_caustic_shoot);
    RUN(test_fog_in_lens_shoot);
    RUN(test_luneburg_two_point);
    RUN(test_jacobian_against_differences);
    RUN(test_reciprocity);
    RUN(test_partition_is_exclusive);
    return CHECK_EXIT_CODE();
}
