/* Known answers for every integrator and refraction scheme (the way
   pbrt-v4's integrators_test runs each integrator over scenes whose radiance
   is known): white furnaces, grey and chromatic; refractive furnaces, where
   non-absorbing refractive media under a uniform sky show exactly the sky,
   and a camera at the centre of a Luneburg lens sees it (eta_c / 1)^2 = 2
   times as bright; scenes without an IOR rendered bit for bit alike by all
   integrators; and a diffuse floor under a light of each shape, whose
   radiance is albedo / pi times the light's closed-form irradiance.
   Every check holds to 4 standard errors with fixed seeds; where every
   pixel has the same expectation, pixel samples are the independent
   estimates. INTEGRATORS_VERBOSE=1 prints the values. */
#include "../rrv.h"
#include "check.h"
#include "say.h"
#include "scene_builder.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>


typedef struct method {
    rrv_integrator integrator;
    rrv_refraction_scheme scheme;
    const char *name;
} method;

static const method methods[] = {
    {RRV_INTEGRATOR_CLASSIC, RRV_REFRACTION_DEFAULT, "classic"},
    {RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_COMB, "comb"},
    {RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_POISSON, "poisson"},
#ifdef RRV_RESEARCH /* the library and the tests are built with the same flags */
    {RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_MIDPOINT, "midpoint"},
#endif
    {RRV_INTEGRATOR_EIKONAL, RRV_REFRACTION_DEFAULT, "eikonal"},
};
#define METHOD_COUNT ((int)(sizeof methods / sizeof methods[0]))
#define PI 3.14159265358979323846

static void use(rrv_scene *s, const method *m)
{
    s->settings.integrator = m->integrator;
    s->settings.refraction = m->scheme;
}

static void prepare(rrv_scene *s)
{
    rrv_error err;
    rrv_result r = rrv_scene_prepare(s, &err);
    CHECKF(r == RRV_OK, "prepare: %s", err.message);
}

typedef struct stats { double sum, sum2; long n; } stats;
static void stats_add(stats *s, double x) { s->sum += x; s->sum2 += x * x; s->n++; }
static double stats_mean(const stats *s) { return s->sum / s->n; }
static double stats_se(const stats *s)
{
    double m = stats_mean(s);
    return sqrt(fmax(0.0, s->sum2 / s->n - m * m) / (s->n - 1));
}

/* Every sample of every pixel as one estimate, for one channel: valid where
   every pixel has the same expectation. */
static stats pixel_samples_cut(rrv_scene *s, int spp, int channel, rrv_render_stats *rs)
{
    int w = s->camera.width, h = s->camera.height, k, i;
    float *img = (float *)malloc((size_t)w * h * 3 * sizeof(float));
    stats st = {0, 0, 0};
    /* independent samples, as the standard error assumes (a Sobol
       sampler's are stratified within a pixel), whatever the default */
    s->settings.sampler = RRV_SAMPLER_PCG;
    for (k = 0; k < spp; ++k) {
        memset(img, 0, (size_t)w * h * 3 * sizeof(float));
        rrv_render_rect(s, 0, 0, w, h, k, k + 1, img, w, rs, NULL);
        for (i = 0; i < w * h; ++i) stats_add(&st, img[3 * i + channel]);
    }
    free(img);
    return st;
}

static stats pixel_samples(rrv_scene *s, int spp, int channel) { return pixel_samples_cut(s, spp, channel, NULL); }

/* Checks every channel's mean against `expected` for every method. */
static void expect_everywhere(rrv_scene *s, const char *scene_name, const double expected[3], int spp,
                              double max_relative_se)
{
    int i, c;
    for (i = 0; i < METHOD_COUNT; ++i) {
        use(s, &methods[i]);
        for (c = 0; c < 3; ++c) {
            stats st = pixel_samples(s, spp, c);
            double mean = stats_mean(&st), se = stats_se(&st);
            SAY("  %-24s %-8s channel %d: %.5f se %.1e (expected %.5f)\n", scene_name, methods[i].name, c, mean, se,
                expected[c]);
            CHECKF(fabs(mean - expected[c]) < 4 * se + 1e-6 * expected[c], "%s, %s, channel %d: %g +- %g, expected %g",
                   scene_name, methods[i].name, c, mean, se, expected[c]);
            /* a bound this loose could not see an energy error */
            CHECKF(se < max_relative_se * expected[c], "%s, %s: standard error %g too large to test", scene_name,
                   methods[i].name, se);
        }
    }
}

static rrv_scene *sky_scene(int size, double L)
{
    rrv_scene *s = tb_scene(size, size);
    s->environment.kind = RRV_ENV_CONSTANT;
    s->environment.L[0] = s->environment.L[1] = s->environment.L[2] = L;
    s->settings.max_depth = 1000;
    s->settings.seed = 11;
    return s;
}

/* ---- white furnaces ----------------------------------------------------------- */

static void furnace(double s0, double s1, double s2, int spp, double max_rel_se, const char *name)
{
    rrv_scene *s = sky_scene(6, 0.75);
    rrv_medium *m = tb_medium(s, tv3(-1, -1, -1), tv3(1, 1, 1), 0.0, 1.0);
    static const double expected[3] = {0.75, 0.75, 0.75};
    m->sigma_s[0] = s0; m->sigma_s[1] = s1; m->sigma_s[2] = s2;
    m->g = 0.6;
    prepare(s);
    expect_everywhere(s, name, expected, spp, max_rel_se);
    rrv_scene_free(s);
}

static void test_white_furnace_every_integrator(void) { furnace(2.0, 2.0, 2.0, 48, 0.02, "white furnace"); }

static void test_chromatic_furnace_every_integrator(void)
{
    furnace(1.0, 2.0, 4.0, 256, 0.03, "chromatic furnace");
}

/* 1 : 10 : 100 puts each channel in a group of its own (rrv__group_channels):
   each hero walks with its own majorant and the path is reweighted by the
   others' majorant transmittances. */
static void test_channel_group_furnace_every_integrator(void)
{
    furnace(0.2, 2.0, 20.0, 256, 0.03, "channel-group furnace");
}

/* ---- refractive furnaces ------------------------------------------------------ */

static void test_refractive_furnace_lens(void)
{
    /* A Luneburg lens and a fish-eye beside it, no density: every camera ray
       bends, and ends in the sky, so every sample is exactly the sky's 0.5,
       save samples whose path was cut at a work bound, which are 0: the
       image mean must be 0.5 (1 - cut / samples) exactly. Only the midpoint
       scheme cuts any: its Snell events with the chord-midpoint normal turn
       some rays into orbits near the fish-eye's turning points (measured
       7 of 256 camera paths, each cut after ~9e4 events, where the comb and
       Poisson need ~2e3). */
    rrv_scene *s = sky_scene(8, 0.5);
    rrv_medium *a, *b;
    static const double expected[3] = {0.5, 0.5, 0.5};
    tb_medium(s, tv3(-1.2, -0.6, -0.6), tv3(0, 0.6, 0.6), 0, 0);
    tb_medium(s, tv3(0, -0.6, -0.6), tv3(1.2, 0.6, 0.6), 0, 0);
    a = &s->media[0]; /* after both: adding a medium may move the array */
    b = &s->media[1];
    a->density.kind = b->density.kind = RRV_FIELD_NONE;
    a->ior.kind = RRV_FIELD_LUNEBURG;
    a->ior.center = tv3(-0.6, 0, 0);
    a->ior.radius = 0.55;
    b->ior.kind = RRV_FIELD_FISHEYE;
    b->ior.center = tv3(0.6, 0, 0);
    b->ior.radius = 0.55;
    b->ior.n0 = 1.6;
    s->settings.step = 0.02;
    prepare(s);
    (void)expected;
    {
        int i;
        for (i = 0; i < METHOD_COUNT; ++i) {
            rrv_render_stats rs;
            stats st;
            double want;
            memset(&rs, 0, sizeof rs);
            use(s, &methods[i]);
            st = pixel_samples_cut(s, 4, 0, &rs);
            want = 0.5 * (1.0 - (double)rs.paths_cut / (double)rs.samples);
            SAY("  lens furnace %-8s %.6f, %llu of %llu paths cut (expected %.6f)\n", methods[i].name,
                stats_mean(&st), (unsigned long long)rs.paths_cut, (unsigned long long)rs.samples, want);
            CHECKF(fabs(stats_mean(&st) - want) < 1e-6, "%s: %g, expected %g with %llu of %llu paths cut",
                   methods[i].name, stats_mean(&st), want, (unsigned long long)rs.paths_cut,
                   (unsigned long long)rs.samples);
            if (methods[i].scheme != RRV_REFRACTION_MIDPOINT)
                CHECKF(rs.paths_cut == 0, "%s cut %llu paths", methods[i].name, (unsigned long long)rs.paths_cut);
            else
                CHECKF(rs.paths_cut * 20 < rs.samples, "midpoint cut %llu of %llu paths",
                       (unsigned long long)rs.paths_cut, (unsigned long long)rs.samples);
        }
    }
    rrv_scene_free(s);
}

/* A default build refuses the research variants (rrv.h, RRV_RESEARCH),
   naming the switch, wherever settings reach the library: the checked
   setter, prepare, and rrv_render_rect for settings edited after prepare;
   a build with the switch renders them. */
static void test_research_variants(void)
{
    static const struct { rrv_refraction_scheme scheme; rrv_stepper stepper; const char *name; } variants[] = {
        {RRV_REFRACTION_MIDPOINT, RRV_STEPPER_DEFAULT, "refraction midpoint"},
        {RRV_REFRACTION_DEFAULT, RRV_STEPPER_LEAPFROG, "stepper leapfrog"},
    };
    int k;
    for (k = 0; k < 2; ++k) {
        rrv_scene *s = sky_scene(4, 0.5);
        rrv_settings settings = s->settings;
        rrv_error err;
        float img[4 * 4 * 3];
        rrv_result set, prepared, rendered;
        prepare(s);
        settings.integrator = variants[k].stepper ? RRV_INTEGRATOR_EIKONAL : RRV_INTEGRATOR_REFRACTIVE;
        settings.refraction = variants[k].scheme;
        settings.stepper = variants[k].stepper;
        memset(&err, 0, sizeof err);
        set = rrv_scene_set_settings(s, &settings, &err);
#ifdef RRV_RESEARCH
        CHECKF(set == RRV_OK, "%s: %s", variants[k].name, err.message);
#else
        CHECKF(set == RRV_ERROR_UNSUPPORTED && strstr(err.message, variants[k].name) &&
                   strstr(err.message, "RRV_RESEARCH"),
               "%s: set_settings %d: %s", variants[k].name, (int)set, err.message);
#endif
        /* set by hand, as a caller may: prepare checks them, and a render after prepare */
        s->settings = settings;
        memset(&err, 0, sizeof err);
        prepared = rrv_scene_prepare(s, &err);
        s->settings = settings;
        if (prepared != RRV_OK) {
            s->settings.refraction = RRV_REFRACTION_DEFAULT;
            s->settings.stepper = RRV_STEPPER_DEFAULT;
            prepare(s);
            s->settings = settings;
        }
        memset(img, 0, sizeof img);
        memset(&err, 0, sizeof err);
        rendered = rrv_render_rect(s, 0, 0, 4, 4, 0, 1, img, 4, NULL, &err);
#ifdef RRV_RESEARCH
        CHECKF(prepared == RRV_OK && rendered == RRV_OK && img[0] == 0.5f, "%s: %d %d %g: %s", variants[k].name,
               (int)prepared, (int)rendered, img[0], err.message);
#else
        CHECKF(prepared == RRV_ERROR_UNSUPPORTED, "%s: prepare %d", variants[k].name, (int)prepared);
        CHECKF(rendered == RRV_ERROR_UNSUPPORTED && strstr(err.message, "RRV_RESEARCH") && img[0] == 0,
               "%s: render %d: %s", variants[k].name, (int)rendered, err.message);
#endif
        rrv_scene_free(s);
    }
}

static void test_refractive_furnace_sharp_box(void)
{
    /* A box of constant IOR 1.5: its faces refract and reflect (Fresnel),
       which moves light around but neither makes nor loses any. */
    rrv_scene *s = sky_scene(8, 0.5);
    rrv_medium *m = tb_medium(s, tv3(-0.7, -0.5, -0.6), tv3(0.7, 0.5, 0.6), 0, 0);
    static const double expected[3] = {0.5, 0.5, 0.5};
    m->density.kind = RRV_FIELD_NONE;
    m->ior.kind = RRV_FIELD_CONSTANT;
    m->ior.value = 0.5;
    prepare(s);
    expect_everywhere(s, "sharp box furnace", expected, 4, 1e-6);
    rrv_scene_free(s);
}

static void test_camera_inside_luneburg(void)
{
    /* At the lens centre eta = sqrt(2); basic radiance L / eta^2 is
       invariant along rays, so the sky (at eta 1) looks 2 times as bright. */
    rrv_scene *s = sky_scene(6, 0.5);
    rrv_medium *m = tb_medium(s, tv3(-1, -1, -1), tv3(1, 1, 1), 0, 0);
    static const double expected[3] = {1.0, 1.0, 1.0};
    int i, c;
    m->density.kind = RRV_FIELD_NONE;
    m->ior.kind = RRV_FIELD_LUNEBURG;
    m->ior.center = tv3(0, 0, 0);
    m->ior.radius = 1;
    s->camera.eye = tv3(0, 0, 0);
    s->camera.look = tv3(0, 0, 1);
    s->camera.fov = 90;
    s->settings.step = 0.02;
    prepare(s);
    for (i = 1; i < METHOD_COUNT; ++i) {
        use(s, &methods[i]);
        for (c = 0; c < 3; ++c) {
            stats st = pixel_samples(s, 2, c);
            SAY("  camera in a Luneburg lens %-8s channel %d: %.7f\n", methods[i].name, c, stats_mean(&st));
            CHECKF(fabs(stats_mean(&st) - expected[c]) < 1e-6, "%s: %g, expected %g", methods[i].name,
                   stats_mean(&st), expected[c]);
        }
    }
    rrv_scene_free(s);
}

/* ---- scenes without an IOR ---------------------------------------------------- */

static void test_no_ior_renders_alike(void)
{
    /* Smoke over a floor under a quad light and a sky, no IOR anywhere:
       the refractive and eikonal integrators must do exactly what classic
       does, sample for sample. */
    rrv_scene *s = sky_scene(10, 0.3);
    rrv_medium *m = tb_medium(s, tv3(-1, 0, -1), tv3(1, 1.5, 1), 0.3, 2.0);
    rrv_shape *floor_quad, *light;
    rrv_blob *b = tb_blobs(&m->density, 1);
    size_t n = 10 * 10 * 3;
    float *ref = (float *)calloc(n, sizeof(float)), *img = (float *)calloc(n, sizeof(float));
    int i;
    b->center = tv3(0, 0.7, 0);
    b->radius = 0.4;
    b->weight = 2;
    tb_shape(s, RRV_SHAPE_QUAD);
    tb_shape(s, RRV_SHAPE_QUAD);
    floor_quad = &s->shapes[0]; /* after both: adding a shape may move the array */
    light = &s->shapes[1];
    floor_quad->p0 = tv3(-4, 0, -4);
    floor_quad->e1 = tv3(0, 0, 8);
    floor_quad->e2 = tv3(8, 0, 0);
    light->p0 = tv3(-0.5, 3, -0.5);
    light->e1 = tv3(1, 0, 0);
    light->e2 = tv3(0, 0, 1);
    light->L[0] = light->L[1] = light->L[2] = 5;
    s->camera.eye = tv3(0, 1.5, -5);
    s->camera.look = tv3(0, 0.6, 0);
    s->camera.fov = 35;
    s->settings.max_depth = 16;
    prepare(s);
    use(s, &methods[0]);
    rrv_render_rect(s, 0, 0, 10, 10, 0, 8, ref, 10, NULL, NULL);
    for (i = 1; i < METHOD_COUNT; ++i) {
        memset(img, 0, n * sizeof(float));
        use(s, &methods[i]);
        rrv_render_rect(s, 0, 0, 10, 10, 0, 8, img, 10, NULL, NULL);
        CHECKF(memcmp(img, ref, n * sizeof(float)) == 0, "%s renders a scene without IOR differently from classic",
               methods[i].name);
    }
    free(ref);
    free(img);
    rrv_scene_free(s);
}

/* ---- a light of each shape over a diffuse floor -------------------------------- */

/* Irradiance at a point below the corner of a parallel rectangle of sides
   a, b at height h, for radiance L: pi L times the form factor. */
static double corner_rectangle_irradiance(double L, double a, double b, double h)
{
    double X = a / h, Y = b / h, sx = sqrt(1 + X * X), sy = sqrt(1 + Y * Y);
    return L * 0.5 * (X / sx * atan(Y / sx) + Y / sy * atan(X / sy));
}

/* The floor point at the origin, seen through a tiny field of view from
   the side; a light above it. Returns the pixel's statistics per sample. */
static void light_shape_case(rrv_shape_kind kind, const char *name)
{
    rrv_scene *s = tb_scene(1, 1);
    rrv_shape *floor_quad = tb_shape(s, RRV_SHAPE_QUAD);
    const double albedo = 0.6, L = 4, h = 1.5, half = 0.5;
    double E, expected;
    int i;
    s->camera.eye = tv3(0, 2, -3);
    s->camera.look = tv3(0, 0, 0);
    s->camera.fov = 0.01;
    /* one bounce: lights are diffuse surfaces too, and light the floor sends
       back off them is not in the closed form */
    s->settings.max_depth = 1;
    s->settings.seed = 5;
    s->materials[0].albedo[0] = s->materials[0].albedo[1] = s->materials[0].albedo[2] = albedo;
    floor_quad->p0 = tv3(-5, 0, -5);
    floor_quad->e1 = tv3(0, 0, 10);
    floor_quad->e2 = tv3(10, 0, 0);
    if (kind == RRV_SHAPE_SPHERE) {
        /* E = pi L sin^2(alpha), sin(alpha) = R / distance */
        rrv_shape *sph = tb_shape(s, RRV_SHAPE_SPHERE);
        sph->center = tv3(0, h, 0);
        sph->radius = 0.4;
        sph->L[0] = sph->L[1] = sph->L[2] = L;
        E = PI * L * (0.4 / h) * (0.4 / h);
    } else if (kind == RRV_SHAPE_QUAD) {
        /* a square centred above: four corner rectangles */
        rrv_shape *q = tb_shape(s, RRV_SHAPE_QUAD);
        q->p0 = tv3(-half, h, -half);
        q->e1 = tv3(2 * half, 0, 0);
        q->e2 = tv3(0, 0, 2 * half); /* e1 x e2 = -y: emits down */
        q->L[0] = q->L[1] = q->L[2] = L;
        E = 4 * corner_rectangle_irradiance(L, half, half, h);
    } else {
        /* the square cut along a diagonal through its centre: the half-turn
           about the vertical axis maps one triangle onto the other, so each
           gives half the square's irradiance */
        rrv_shape *t = tb_shape(s, RRV_SHAPE_TRIANGLE);
        t->p0 = tv3(-half, h, -half);
        t->e1 = tv3(2 * half, 0, 0);
        t->e2 = tv3(2 * half, 0, 2 * half);
        t->L[0] = t->L[1] = t->L[2] = L;
        E = 2 * corner_rectangle_irradiance(L, half, half, h);
    }
    expected = albedo / PI * E;
    prepare(s);
    for (i = 0; i < METHOD_COUNT; ++i) {
        stats st;
        use(s, &methods[i]);
        st = pixel_samples(s, 20000, 0);
        SAY("  %-8s light, %-8s: %.5f se %.1e (expected %.5f)\n", name, methods[i].name, stats_mean(&st),
            stats_se(&st), expected);
        CHECKF(fabs(stats_mean(&st) - expected) < 4 * stats_se(&st), "%s light, %s: %g +- %g, expected %g", name,
               methods[i].name, stats_mean(&st), stats_se(&st), expected);
        CHECKF(stats_se(&st) < 0.01 * expected, "%s light: standard error %g too large to test", name,
               stats_se(&st));
    }
    rrv_scene_free(s);
}

static void test_sphere_light_irradiance(void) { light_shape_case(RRV_SHAPE_SPHERE, "sphere"); }
static void test_quad_light_irradiance(void) { light_shape_case(RRV_SHAPE_QUAD, "quad"); }
static void test_triangle_light_irradiance(void) { light_shape_case(RRV_SHAPE_TRIANGLE, "triangle"); }

int main(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    say_from_env("INTEGRATORS_VERBOSE");
    RUN(test_white_furnace_every_integrator);
    RUN(test_chromatic_furnace_every_integrator);
    RUN(test_channel_group_furnace_every_integrator);
    RUN(test_refractive_furnace_lens);
    RUN(test_research_variants);
    RUN(test_refractive_furnace_sharp_box);
    RUN(test_camera_inside_luneburg);
    RUN(test_no_ior_renders_alike);
    RUN(test_sphere_light_irradiance);
    RUN(test_quad_light_irradiance);
    RUN(test_triangle_light_irradiance);
    return CHECK_EXIT_CODE();
}
