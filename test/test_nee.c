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
     pixels within 4 standard errors, and `straight` misses the caustic.
   Fixed seeds; the two renders compared are independent (distinct seeds).
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

/* Renders one sample index at a time and files each pixel sample of the
   green channel into the stats of its block (bw x bh pixels). */
static void block_samples(const rrv_scene *s, int spp, int bw, int bh, stats *blocks)
{
    int w = s->camera.width, h = s->camera.height, k, x, y;
    float *img = (float *)malloc((size_t)w * h * 3 * sizeof(float));
    for (k = 0; k < spp; ++k) {
        memset(img, 0, (size_t)w * h * 3 * sizeof(float));
        rrv_render_rect(s, 0, 0, w, h, k, k + 1, img, w, NULL);
        for (y = 0; y < h; ++y)
            for (x = 0; x < w; ++x) stats_add(&blocks[(y / bh) * (w / bw) + x / bw], img[3 * (y * w + x) + 1]);
    }
    free(img);
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
    st = furnace_run(s, &comb, RRV_NEE_STRAIGHT, straight_spp, 31);
    mean = stats_mean(&st);
    se = stats_se(&st);
    SAY("  %-8s furnace comb     nee straight: %.5f se %.1e (%.1f standard errors off)\n", name, mean, se,
        (mean - 1.0) / se);
    /* documents the bias of straight shadow rays through refracting media */
    CHECKF(fabs(mean - 1.0) > 4 * se, "%s, comb, nee straight: %.5f +- %.1e is within 4 se of 1", name, mean, se);
    rrv_scene_free(s);
}

static void test_furnace_luneburg(void) { furnace_case(LUNEBURG_IOR, "Luneburg", 512); }
static void test_furnace_blob(void) { furnace_case(BLOB_IOR, "blob", 1024); }

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
    const int spp = 640;
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
               strcmp(err.message, "render: nee must be one of none|straight, got \"manifold\"") == 0,
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
    rrv_render_rect(s, 0, 0, w, h, 0, 2, x, w, NULL);
    s->settings.nee = RRV_NEE_NONE;
    rrv_render_rect(s, 0, 0, w, h, 0, 2, y, w, NULL);
    for (i = 0; i < n; ++i)
        if (x[i] != y[i]) break;
    CHECKF(i == n, "classic with nee none differs at value %lu", (unsigned long)i);
    free(x);
    free(y);
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
    return CHECK_EXIT_CODE();
}
