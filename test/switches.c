/* The build switches of rrv.h's CONFIGURATION (RRV_NO_SCENE_FILE,
   RRV_NO_NANOVDB, RRV_NO_EXR, RRV_NO_PNG, RRV_NO_CURVED_NEE, and
   RRV_RESEARCH, which keeps what the default build leaves out), built by
   test/compile_checks.sh once with each, once with all and once with none:
   a scene built through the API renders in every build, and each call that
   needs a part left out refuses with RRV_ERROR_UNSUPPORTED and a message
   naming the switch, while the default build still does the same call.
   Prints one line a check and exits nonzero if any failed. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <math.h>
#include <stdio.h>
#include <string.h>

static int failures;

static void check(int ok, const char *what, const rrv_error *err)
{
    if (!ok) {
        ++failures;
        printf("  %s: %s\n", what, err ? err->message : "");
    }
}

/* A refusal of the build, or (built with the part) anything but one. */
static void refused_by(rrv_result r, const rrv_error *err, int left_out, const char *name, const char *what)
{
    if (left_out)
        check(r == RRV_ERROR_UNSUPPORTED && strstr(err->message, name) != NULL, what, err);
    else
        check(r != RRV_ERROR_UNSUPPORTED, what, err);
}

/* The same where the call succeeds with the part built. */
static void refused_or_ok(rrv_result r, const rrv_error *err, int left_out, const char *name, const char *what)
{
    if (left_out) refused_by(r, err, 1, name, what);
    else check(r == RRV_OK, what, err);
}

static int discard(void *user, const void *data, size_t size)
{
    (void)user; (void)data; (void)size;
    return 0;
}

#ifdef RRV_NO_SCENE_FILE
#define LEFT_SCENE_FILE 1
#else
#define LEFT_SCENE_FILE 0
#endif
#ifdef RRV_NO_NANOVDB
#define LEFT_NANOVDB 1
#else
#define LEFT_NANOVDB 0
#endif
#ifdef RRV_NO_EXR
#define LEFT_EXR 1
#else
#define LEFT_EXR 0
#endif
#ifdef RRV_NO_PNG
#define LEFT_PNG 1
#else
#define LEFT_PNG 0
#endif
#ifdef RRV_NO_CURVED_NEE
#define LEFT_CURVED_NEE 1
#else
#define LEFT_CURVED_NEE 0
#endif
#ifdef RRV_RESEARCH
#define LEFT_RESEARCH 0
#else
#define LEFT_RESEARCH 1
#endif

/* A Luneburg lens under a small quad light over a floor: clear and lit
   by a small light, the scene the default rule gives to eikonal's
   shooting where the solvers are built. */
static rrv_scene *lens_scene(rrv_error *err)
{
    rrv_scene *scene = NULL;
    rrv_camera camera;
    rrv_settings settings;
    rrv_shape light, floor_quad;
    rrv_medium lens;
    rrv_field ior;
    int lens_index;
    memset(&camera, 0, sizeof camera);
    memset(&settings, 0, sizeof settings);
    memset(&light, 0, sizeof light);
    memset(&floor_quad, 0, sizeof floor_quad);
    memset(&lens, 0, sizeof lens);
    memset(&ior, 0, sizeof ior);
    camera.eye.z = 4;
    camera.width = 8;
    camera.height = 8;
    settings.spp = 2;
    light.kind = RRV_SHAPE_QUAD; /* emitting down: cross(e1, e2) = -y */
    light.p0.x = -0.15; light.p0.y = 2; light.p0.z = -0.15;
    light.e1.x = 0.3;
    light.e2.z = 0.3;
    light.L[0] = light.L[1] = light.L[2] = 50;
    floor_quad.kind = RRV_SHAPE_QUAD;
    floor_quad.p0.x = -4; floor_quad.p0.y = -1.5; floor_quad.p0.z = 4;
    floor_quad.e1.x = 8;
    floor_quad.e2.z = -8;
    strcpy(lens.name, "lens");
    lens.lo.x = lens.lo.y = lens.lo.z = -1;
    lens.hi.x = lens.hi.y = lens.hi.z = 1;
    ior.kind = RRV_FIELD_LUNEBURG;
    ior.radius = 1;
    if (rrv_scene_create(&scene, err) != RRV_OK || rrv_scene_set_camera(scene, &camera, err) != RRV_OK ||
        rrv_scene_set_settings(scene, &settings, err) != RRV_OK ||
        rrv_scene_add_shape(scene, &light, NULL, err) != RRV_OK ||
        rrv_scene_add_shape(scene, &floor_quad, NULL, err) != RRV_OK ||
        rrv_scene_add_medium(scene, &lens, &lens_index, err) != RRV_OK ||
        rrv_scene_set_field(scene, lens_index, RRV_MEDIUM_IOR, &ior, err) != RRV_OK ||
        rrv_scene_prepare(scene, err) != RRV_OK) {
        rrv_scene_free(scene);
        return NULL;
    }
    return scene;
}

/* A scene whose second line names a part: parsed where the parser is
   built, and refused at that line where the part is left out. */
static void scene_file_refuses(const char *render_line, int left_out, const char *name, const char *what)
{
    char text[256];
    rrv_scene *parsed = NULL;
    rrv_error err;
    rrv_result r;
    memset(&err, 0, sizeof err);
    snprintf(text, sizeof text, "camera eye 0 0 4 look 0 0 0 fov 40 resolution 8 8\n%s", render_line);
    r = rrv_scene_parse(text, strlen(text), "switches.rrv", NULL, NULL, &parsed, &err);
    if (LEFT_SCENE_FILE)
        refused_by(r, &err, 1, "RRV_NO_SCENE_FILE", what);
    else
        refused_or_ok(r, &err, left_out, name, what);
    check(!left_out || LEFT_SCENE_FILE || err.line == 2, what, &err);
    rrv_scene_free(parsed);
}

int main(void)
{
    rrv_error err;
    rrv_scene *scene;
    float sum[8 * 8 * 3], rgb[3] = {1, 2, 3};
    double total = 0;
    int i, finite = 1;
    rrv_result r;

    memset(&err, 0, sizeof err);
    memset(sum, 0, sizeof sum);
    scene = lens_scene(&err);
    check(scene != NULL, "api_scene_builds", &err);
    if (!scene) return 1;
    r = rrv_render_rect(scene, 0, 0, 8, 8, 0, 2, sum, 8, NULL, &err);
    for (i = 0; i < 8 * 8 * 3; ++i) {
        finite = finite && isfinite(sum[i]);
        total += sum[i];
    }
    check(r == RRV_OK && finite && total > 0, "api_scene_renders", &err);
    /* where no solver is built the clear, small-light scene is refractive */
    check(rrv_scene_integrator(scene) ==
              (LEFT_CURVED_NEE ? RRV_INTEGRATOR_REFRACTIVE : RRV_INTEGRATOR_EIKONAL),
          "default_integrator_follows_the_solvers", NULL);

    /* nee shoot asked for: set_settings, prepare after an edit, and a
       render after an edit past prepare each refuse it */
    {
        rrv_settings s = scene->settings;
        s.nee = RRV_NEE_SHOOT;
        refused_or_ok(rrv_scene_set_settings(scene, &s, &err), &err, LEFT_CURVED_NEE, "RRV_NO_CURVED_NEE",
                   "set_settings_nee_shoot");
        scene->settings.nee = RRV_NEE_MANIFOLD;
        refused_or_ok(rrv_scene_prepare(scene, &err), &err, LEFT_CURVED_NEE, "RRV_NO_CURVED_NEE",
                   "prepare_nee_manifold");
        scene->settings.nee = RRV_NEE_DEFAULT;
        check(rrv_scene_prepare(scene, &err) == RRV_OK, "prepare_nee_default", &err);
        scene->settings.nee = RRV_NEE_SHOOT;
        refused_or_ok(rrv_render_rect(scene, 0, 0, 1, 1, 0, 1, sum, 1, NULL, &err), &err, LEFT_CURVED_NEE,
                   "RRV_NO_CURVED_NEE", "render_nee_shoot");
        scene->settings.nee = RRV_NEE_DEFAULT;
    }
    /* the midpoint scheme and the leapfrog stepper, likewise, unless
       RRV_RESEARCH keeps them: then the lens renders with each */
    {
        rrv_settings s = scene->settings;
        s.integrator = RRV_INTEGRATOR_REFRACTIVE;
        s.refraction = RRV_REFRACTION_MIDPOINT;
        refused_or_ok(rrv_scene_set_settings(scene, &s, &err), &err, LEFT_RESEARCH, "RRV_RESEARCH",
                      "set_settings_midpoint");
        scene->settings = s;
        refused_or_ok(rrv_scene_prepare(scene, &err), &err, LEFT_RESEARCH, "RRV_RESEARCH", "prepare_midpoint");
        s.integrator = RRV_INTEGRATOR_EIKONAL;
        s.refraction = RRV_REFRACTION_DEFAULT;
        scene->settings = s;
        check(rrv_scene_prepare(scene, &err) == RRV_OK, "prepare_eikonal", &err);
        scene->settings.stepper = RRV_STEPPER_LEAPFROG;
        memset(sum, 0, sizeof sum);
        refused_or_ok(rrv_render_rect(scene, 0, 0, 8, 8, 0, 1, sum, 8, NULL, &err), &err, LEFT_RESEARCH,
                      "RRV_RESEARCH", "render_leapfrog");
        for (i = 0, total = 0; i < 8 * 8 * 3; ++i) total += sum[i];
        check(LEFT_RESEARCH || (isfinite(total) && total > 0), "leapfrog_renders", NULL);
    }
    rrv_scene_free(scene);

    /* the scene file's own refusals, with their line */
    scene_file_refuses("render nee shoot integrator eikonal\n", LEFT_CURVED_NEE, "RRV_NO_CURVED_NEE",
                       "scene_file_nee_shoot");
    scene_file_refuses("render refraction midpoint integrator refractive\n", LEFT_RESEARCH, "RRV_RESEARCH",
                       "scene_file_midpoint");
    {
        rrv_grid grid;
        refused_by(rrv_grid_read_memory("", 0, "g.vol", 0, 1, &grid, &err), &err, LEFT_SCENE_FILE,
                   "RRV_NO_SCENE_FILE", "grid_read_memory");
    }
    {
        rrv_nanovdb grid;
        rrv_medium m;
        rrv_field f;
        memset(&grid, 0, sizeof grid);
        refused_by(rrv_nanovdb_read_memory("", 0, "g.nvdb", "density", 0, &grid, &err), &err, LEFT_NANOVDB,
                   "RRV_NO_NANOVDB", "nanovdb_read_memory");
        rrv_nanovdb_free(&grid);
        /* a NANOVDB field cannot come from a validated grid there */
        scene = NULL;
        memset(&m, 0, sizeof m);
        memset(&f, 0, sizeof f);
        m.hi.x = m.hi.y = m.hi.z = 1;
        f.kind = RRV_FIELD_NANOVDB;
        if (LEFT_NANOVDB && rrv_scene_create(&scene, &err) == RRV_OK &&
            rrv_scene_add_medium(scene, &m, &i, &err) == RRV_OK)
            refused_by(rrv_scene_set_field(scene, i, RRV_MEDIUM_DENSITY, &f, &err), &err, 1, "RRV_NO_NANOVDB",
                       "nanovdb_field");
        rrv_scene_free(scene);
    }
    refused_or_ok(rrv_write_exr_to(discard, NULL, rgb, 1, 1, NULL, &err), &err, LEFT_EXR, "RRV_NO_EXR",
               "write_exr_to");
    {
        float *back = NULL;
        int w, h;
        static const unsigned char junk[8] = {0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0};
        refused_by(rrv_read_exr_memory(junk, sizeof junk, "x.exr", &back, &w, &h, NULL, &err), &err, LEFT_EXR,
                   "RRV_NO_EXR", "read_exr_memory");
        rrv_free(back);
    }
    refused_or_ok(rrv_write_png_to(discard, NULL, rgb, 1, 1, 0.0, &err), &err, LEFT_PNG, "RRV_NO_PNG",
               "write_png_to");
    check(rrv_write_pfm_to(discard, NULL, rgb, 1, 1, &err) == RRV_OK, "write_pfm_to", &err);
    return failures ? 1 : 0;
}
