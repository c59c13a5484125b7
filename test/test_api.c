/* The scene-building API: zero means the scene format's defaults, every
   refusal names its object, rrv_scene_prepare holds hand-edited scenes to
   the same checks and may be called again, a scene built in code renders
   bit-identically to the same scene parsed from text, the file-read
   callback gets every buffer back through its release pair, and
   rrv_render_rect says what is wrong. Run from the repository root. */
#include "../rrv.h"
#include "check.h"
#include "vec3.h"
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static rrv_scene *new_scene(void)
{
    rrv_scene *s = NULL;
    rrv_camera cam;
    rrv_error err;
    memset(&cam, 0, sizeof cam);
    CHECK(rrv_scene_create(&s, &err) == RRV_OK);
    cam.eye.z = 5;
    cam.width = 8;
    cam.height = 6;
    CHECK(rrv_scene_set_camera(s, &cam, &err) == RRV_OK);
    return s;
}

static void expect_message(rrv_result r, const rrv_error *err, rrv_result code, const char *message)
{
    CHECKF(r == code, "result %d, expected %d (%s)", (int)r, (int)code, err->message);
    CHECKF(strcmp(err->message, message) == 0, "got \"%s\", expected \"%s\"", err->message, message);
}

static void test_zero_means_default(void)
{
    rrv_scene *s = new_scene();
    rrv_settings set;
    rrv_material mat;
    rrv_medium med;
    rrv_field noise;
    rrv_error err;
    int i;
    memset(&set, 0, sizeof set);
    memset(&mat, 0, sizeof mat);
    memset(&med, 0, sizeof med);
    memset(&noise, 0, sizeof noise);
    CHECK(s->camera.fov == 40 && s->camera.up.y == 1 && s->camera.width == 8);
    CHECK(rrv_scene_set_settings(s, &set, &err) == RRV_OK);
    CHECK(s->settings.spp == 16 && s->settings.max_depth == 32 && s->settings.bend_tolerance == 0.01 &&
          s->settings.step == 0 && s->settings.ambient_ior == 0 &&
          s->settings.integrator == RRV_INTEGRATOR_DEFAULT);
    mat.kind = RRV_MATERIAL_CHECKER;
    CHECK(rrv_scene_add_material(s, &mat, &i, &err) == RRV_OK && i == 0);
    CHECK(s->materials[0].albedo[1] == 0.8 && s->materials[0].albedo2[2] == 0.2 &&
          s->materials[0].checker_scale == 1 && strcmp(s->materials[0].name, "material 0") == 0);
    med.lo = tv3(-1, -2, -3);
    med.hi = tv3(1, 2, 5);
    CHECK(rrv_scene_add_medium(s, &med, &i, &err) == RRV_OK && i == 0);
    CHECK(s->media[0].scale == 1 && s->media[0].sigma_a[2] == 1 && s->media[0].sigma_s[0] == 1 &&
          s->media[0].Lescale == 1 && s->media[0].eta_ref == 1.000292 && s->media[0].P_ref == 101325 &&
          s->media[0].T_ref == 300 && s->media[0].ior_scale == 1 && s->media[0].temperaturescale == 1);
    noise.kind = RRV_FIELD_NOISE;
    CHECK(rrv_scene_set_field(s, 0, RRV_MEDIUM_TEMPERATURE, &noise, &err) == RRV_OK);
    {
        const rrv_field *f = &s->media[0].temperature;
        CHECK(f->noise.octaves == 5 && f->noise.frequency == 1 && f->noise.lacunarity == 2 &&
              f->noise.gain == 0.5 && f->amplitude == 1 && f->base == 300);
        CHECK(f->noise.center.x == 0 && f->noise.center.y == 0 && f->noise.center.z == 1);
        CHECK(f->noise.radius == 1); /* half the smallest side */
    }
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    /* no gas medium: the ambient IOR is 1 */
    CHECK(s->ambient_ior == 1);
    rrv_scene_free(s);
}

/* A clear plume of hot air (blobs that have fallen to ~1e-30 K at the
   faces) under a 0.2 m light 2.5 m away, iorscale 100, no `ambient ior`:
   the scene the default integrator and the face-jump report are tested on.
   `extra` is appended (a light, a smoke, an ambient or render line). */
static rrv_scene *plume_scene(const char *extra, int with_ior)
{
    char text[2048];
    rrv_scene *s = NULL;
    rrv_error err;
    snprintf(text, sizeof text,
             "camera eye 0 0.8 -3 look 0 0.6 0 resolution 8 6\n"
             "render spp 2 maxdepth 2 seed 3 %s\n"
             "material white diffuse\n"
             "quad origin -2 0 -2 u 0 0 4 v 4 0 0 material white\n"
             "quad origin -0.1 3.5 -0.1 u 0.2 0 0 v 0 0 0.2 L 50 50 50\n"
             "medium plume box -0.5 0.5 -0.5 0.5 1.5 0.5 sigma_a 0 0 0 sigma_s 0 0 0\n"
             "temperature plume blob center 0 1 0 radius 0.06 weight 600 base 300\n"
             "%s\n%s\n",
             strncmp(extra, "render:", 7) == 0 ? extra + 7 : "", with_ior ? "ior plume gas iorscale 100" : "",
             strncmp(extra, "render:", 7) == 0 ? "" : extra);
    CHECKF(rrv_scene_parse(text, strlen(text), "plume", NULL, NULL, &s, &err) == RRV_OK, "%s", err.message);
    return s;
}

static int same_render(rrv_scene *a, rrv_scene *b)
{
    float ia[8 * 6 * 3], ib[8 * 6 * 3];
    memset(ia, 0, sizeof ia);
    memset(ib, 0, sizeof ib);
    CHECK(rrv_render_rect(a, 0, 0, 8, 6, 0, 2, ia, 8, NULL, NULL) == RRV_OK);
    CHECK(rrv_render_rect(b, 0, 0, 8, 6, 0, 2, ib, 8, NULL, NULL) == RRV_OK);
    return memcmp(ia, ib, sizeof ia) == 0;
}

/* No integrator key: classic where nothing refracts (the same render bit
   for bit), eikonal where a clear refracting medium without a sharp
   sphere rim sees a small light (a box's sharp faces, which shots refract
   at, allowed: glass too), the comb otherwise (a large light, a smoke in
   the plume's box, an explicit nee other than shoot or manifold). No nee
   key: with eikonal, chains (manifold) where the refracting media are
   clear and weak and nothing is a sharp face or rim; shoot otherwise (the
   comb aims). */
static void test_default_integrator(void)
{
    struct {
        const char *extra;
        int ior;
        rrv_integrator expect;
        rrv_nee nee;
    } cases[] = {
        {"", 0, RRV_INTEGRATOR_CLASSIC, RRV_NEE_SHOOT},
        {"", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        {"render:nee shoot", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
        {"render:nee aim", 1, RRV_INTEGRATOR_REFRACTIVE, RRV_NEE_AIM},
        {"render:nee manifold", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        /* a 4 m light at 2.5 m (1.6 rad) besides the small one: one small light is enough */
        {"quad origin -2 3.5 -2 u 4 0 0 v 0 0 4 L 1 1 1", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        /* a sphere light beside the quad: chains still (eikonal's shoot at spheres) */
        {"sphere center 1 3 0 radius 0.1 L 50 50 50", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        /* the hot blob at iorscale 1000: ~5 rad of bend (0.5 at 100), where
           shots beat chains, as on the Luneburg lens */
        {"", 5, RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
        /* the 4 m light alone: not small */
        {"4", 3, RRV_INTEGRATOR_REFRACTIVE, RRV_NEE_SHOOT},
        /* a 1.5 m light alone (0.6 of its 2.5 m): small, where shooting
           measured 2.3x aiming (test/bench/RESULTS.md); a 2 m one (0.8) not */
        {"1.5", 3, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        {"2", 3, RRV_INTEGRATOR_REFRACTIVE, RRV_NEE_SHOOT},
        /* smoke over the plume's box: thin (optical depth 0.35 across it)
           under the small light, shots as if clear (but no chains, which
           connect only surfaces); dense (35), the comb's aimed rays */
        {"medium smoke box -1 0 -1 1 2 1\ndensity smoke constant 0.1", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
        {"medium smoke box -1 0 -1 1 2 1\ndensity smoke constant 10", 1, RRV_INTEGRATOR_REFRACTIVE, RRV_NEE_SHOOT},
        /* soot as dense that only absorbs (a flame's) is no smoke: it makes
           no vertex that connects, and aimed rays miss the small light's
           caustic through it as through clear air; one that scatters a
           tenth as much is smoke again */
        {"medium smoke box -1 0 -1 1 2 1 sigma_a 1 1 1 sigma_s 0 0 0\ndensity smoke constant 10", 1,
         RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
        {"medium smoke box -1 0 -1 1 2 1 sigma_a 1 1 1 sigma_s 0.5 0.5 0.5\ndensity smoke constant 10", 1,
         RRV_INTEGRATOR_REFRACTIVE, RRV_NEE_SHOOT},
        /* a 1.2 m light alone (0.48 of its 2.5 m): small over a clear
           plume, not under thin smoke, where aimed rays seldom miss it */
        {"1.2", 3, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        {"1.2", 8, RRV_INTEGRATOR_REFRACTIVE, RRV_NEE_SHOOT},
        /* a smoke that does not touch the plume's box keeps it clear */
        {"medium smoke box 2 0 -1 3 2 1\ndensity smoke constant 0.1", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        /* the IOR of a bare gas box equals the ambient one it sets: inert */
        {"", 2, RRV_INTEGRATOR_CLASSIC, RRV_NEE_SHOOT},
        /* an ambient of 1 makes the plume's faces jumps, which shots refract at */
        {"ambient ior 1", 1, RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
        /* a glass box under a small light: shots refract at its faces */
        {"", 4, RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
        /* a narrower blob whose Gaussian tail leaves a reported jump of
           2.2e-7 at every face, which chains take as smooth (up to 1e-6);
           a wider one leaves 1.9e-6, which they do not */
        {"", 6, RRV_INTEGRATOR_EIKONAL, RRV_NEE_MANIFOLD},
        {"", 7, RRV_INTEGRATOR_EIKONAL, RRV_NEE_SHOOT},
    };
    int k;
    for (k = 0; k < (int)(sizeof cases / sizeof cases[0]); ++k) {
        rrv_scene *s, *t;
        rrv_integrator got;
        rrv_nee nee;
        rrv_error err;
        if (cases[k].ior == 4) {
            static const char glass[] = "camera eye 0 0.8 -3 look 0 0.6 0 resolution 8 6\n"
                                        "quad origin -0.1 3.5 -0.1 u 0.2 0 0 v 0 0 0.2 L 50 50 50\n"
                                        "medium glass box -0.5 0.5 -0.5 0.5 1.5 0.5 sigma_a 0 0 0 sigma_s 0 0 0\n"
                                        "ior glass constant 1.5\n";
            CHECKF(rrv_scene_parse(glass, sizeof glass - 1, "glass", NULL, NULL, &s, &err) == RRV_OK, "%s", err.message);
        } else if (cases[k].ior >= 2) {
            char text[512];
            double side = cases[k].ior == 3 || cases[k].ior == 8 ? atof(cases[k].extra) : 0.2;
            /* ior 2: a bare gas box under a small light; 3: a hot blob in
               it under one light of the given side, 2.5 m from its centre;
               5: the blob under the small light at iorscale 1000; 6 and 7:
               blobs of radius 0.1 and 0.11 in place of 0.06; 8: as 3, in
               thin smoke */
            static const char *blob[] = {"", "temperature plume blob center 0 1 0 radius 0.06 weight 600 base 300\n",
                                         "temperature plume blob center 0 1 0 radius 0.1 weight 600 base 300\n",
                                         "temperature plume blob center 0 1 0 radius 0.11 weight 600 base 300\n"};
            int which = cases[k].ior == 2 ? 0 : cases[k].ior == 6 || cases[k].ior == 7 ? cases[k].ior - 4 : 1;
            snprintf(text, sizeof text,
                     "camera eye 0 0.8 -3 look 0 0.6 0 resolution 8 6\n"
                     "quad origin %g 3.5 %g u %g 0 0 v 0 0 %g L 50 50 50\n"
                     "medium plume box -0.5 0.5 -0.5 0.5 1.5 0.5 sigma_a 0 0 0 sigma_s 0 0 0\n"
                     "%s"
                     "ior plume gas iorscale %d\n%s",
                     -side / 2, -side / 2, side, side,
                     blob[which], cases[k].ior == 5 ? 1000 : 100,
                     cases[k].ior == 8 ? "medium smoke box -1 0 -1 1 2 1\ndensity smoke constant 0.1\n" : "");
            CHECKF(rrv_scene_parse(text, strlen(text), "bare", NULL, NULL, &s, &err) == RRV_OK, "%s", err.message);
        } else {
            s = plume_scene(cases[k].extra, cases[k].ior);
        }
        if (!s) continue;
        got = rrv_scene_integrator(s);
        nee = rrv_scene_nee(s);
        if (cases[k].ior == 6 || cases[k].ior == 7) {
            /* the tails' jumps are reported either way: above a float's rounding */
            double jump[7], worst = rrv_medium_face_jumps(s, 0, jump);
            CHECKF(cases[k].ior == 6 ? worst > 1e-7 && worst < 1e-6 : worst > 1e-6 && worst < 1e-5,
                   "case %d: the blob's tail jumps by %g at the faces", k, worst);
        }
        CHECKF(got == cases[k].expect, "case %d (%s): integrator %d, expected %d", k, cases[k].extra, (int)got,
               (int)cases[k].expect);
        CHECKF(nee == cases[k].nee, "case %d (%s): nee %d, expected %d", k, cases[k].extra, (int)nee,
               (int)cases[k].nee);
        /* the render is the chosen integrator's and nee's, draw for draw */
        t = cases[k].ior >= 2 ? NULL : plume_scene(cases[k].extra, cases[k].ior);
        if (t) {
            t->settings.integrator = cases[k].expect;
            t->settings.nee = cases[k].nee;
            CHECKF(same_render(s, t), "case %d: the default render differs from integrator %d, nee %d", k,
                   (int)cases[k].expect, (int)cases[k].nee);
            rrv_scene_free(t);
        }
        rrv_scene_free(s);
    }
}

/* No silent glass: with no `ambient ior` the ambient IOR is the gas's at
   its ambient state (1 + 100 x 2.92e-4), so the plume's faces, at 300 K,
   have no jump; `ambient ior 1` makes every face a jump of 0.0292. */
static void test_face_jumps(void)
{
    double jump[7];
    rrv_scene *s = plume_scene("", 1);
    int f;
    if (!s) return;
    CHECKF(fabs(s->ambient_ior - 1.0292) < 1e-12 && s->settings.ambient_ior == 0, "ambient %.17g",
           s->ambient_ior);
    CHECK(rrv_medium_face_jumps(s, 0, jump) == 0);
    for (f = 0; f < 7; ++f) CHECKF(jump[f] == 0, "face %d jumps by %g", f, jump[f]);
    CHECK(rrv_medium_face_jumps(s, 1, jump) == 0 && rrv_medium_face_jumps(s, -1, jump) == 0);
    CHECK(rrv_medium_face_jumps(NULL, 0, jump) == 0);
    rrv_scene_free(s);
    s = plume_scene("ambient ior 1", 1);
    if (!s) return;
    CHECK(s->ambient_ior == 1);
    CHECKF(fabs(rrv_medium_face_jumps(s, 0, jump) - 0.0292) < 1e-9, "largest jump %.17g", jump[0]);
    for (f = 0; f < 6; ++f) CHECKF(fabs(jump[f] - 0.0292) < 1e-9, "face %d jumps by %.17g", f, jump[f]);
    CHECK(jump[6] == 0); /* no profile sphere */
    rrv_scene_free(s);
    /* a Luneburg lens meets the ambient IOR at its sphere and, outside
       it, in its box: only rounding (~1e-8) is left there, no glass */
    {
        static const char lens[] = "camera eye 0 0 -3 look 0 0 0 resolution 8 6\n"
                                   "medium lens box -0.5 -0.5 -0.5 0.5 0.5 0.5 sigma_a 0 0 0 sigma_s 0 0 0\n"
                                   "ior lens luneburg radius 0.5\n";
        rrv_error err;
        CHECKF(rrv_scene_parse(lens, strlen(lens), "lens", NULL, NULL, &s, &err) == RRV_OK, "%s", err.message);
        if (!s) return;
        CHECKF(rrv_medium_face_jumps(s, 0, jump) == 0, "faces jump by %g %g %g %g %g %g, sphere %g", jump[0], jump[1],
               jump[2], jump[3], jump[4], jump[5], jump[6]);
        rrv_scene_free(s);
    }
}

static void test_refusals_name_the_object(void)
{
    rrv_scene *s = new_scene();
    rrv_camera cam;
    rrv_medium med;
    rrv_shape quad;
    rrv_field f;
    rrv_material mat;
    rrv_error err;
    int i;
    memset(&cam, 0, sizeof cam);
    CHECK(rrv_scene_set_camera(s, &cam, &err) == RRV_ERROR_ARGUMENT);
    expect_message(RRV_ERROR_ARGUMENT, &err, RRV_ERROR_ARGUMENT,
                   "camera: eye and look must be distinct finite points");
    cam.eye.z = 1;
    cam.fov = 180;
    expect_message(rrv_scene_set_camera(s, &cam, &err), &err, RRV_ERROR_ARGUMENT,
                   "camera: fov must be in (0, 180), got 180");
    cam.fov = 0;
    cam.up = tv3(0, 0, 2);
    expect_message(rrv_scene_set_camera(s, &cam, &err), &err, RRV_ERROR_ARGUMENT,
                   "camera: up is parallel to the view direction");
    CHECK(s->camera.eye.z == 5); /* a refused camera changes nothing */

    memset(&med, 0, sizeof med);
    strcpy(med.name, "smoke");
    med.lo = tv3(1, -1, -1);
    med.hi = tv3(-1, 1, 1);
    expect_message(rrv_scene_add_medium(s, &med, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "medium \"smoke\": box is empty along x (1 is not below -1)");
    med.lo.x = -1;
    med.hi.x = 1;
    med.g = 1;
    expect_message(rrv_scene_add_medium(s, &med, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "medium \"smoke\": g must be in (-1, 1), got 1");
    med.g = 0;
    med.scale = -1;
    expect_message(rrv_scene_add_medium(s, &med, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "medium \"smoke\": scale must be >= 0, got -1");
    CHECK(s->medium_count == 0);
    med.scale = 0;
    CHECK(rrv_scene_add_medium(s, &med, &i, &err) == RRV_OK && i == 0);
    expect_message(rrv_scene_add_medium(s, &med, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "medium \"smoke\" defined twice");

    memset(&f, 0, sizeof f);
    f.kind = RRV_FIELD_CONSTANT;
    f.value = -1;
    expect_message(rrv_scene_set_field(s, 0, RRV_MEDIUM_DENSITY, &f, &err), &err, RRV_ERROR_ARGUMENT,
                   "density of medium \"smoke\": constant must be >= 0, got -1");
    f.kind = RRV_FIELD_LUNEBURG;
    f.radius = 1;
    expect_message(rrv_scene_set_field(s, 0, RRV_MEDIUM_PRESSURE, &f, &err), &err, RRV_ERROR_ARGUMENT,
                   "pressure of medium \"smoke\": IOR profiles belong in the ior field");

    memset(&mat, 0, sizeof mat);
    mat.albedo[1] = 1.5;
    expect_message(rrv_scene_add_material(s, &mat, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "material \"material 0\": albedo must be in [0, 1], got 1.5");

    memset(&quad, 0, sizeof quad);
    quad.kind = RRV_SHAPE_QUAD;
    quad.e1 = tv3(1, 0, 0);
    quad.e2 = tv3(2, 0, 0);
    expect_message(rrv_scene_add_shape(s, &quad, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "shape 0 (quad): u and v are parallel (zero area)");
    quad.e2 = tv3(0, 1, 0);
    quad.material = 3;
    expect_message(rrv_scene_add_shape(s, &quad, &i, &err), &err, RRV_ERROR_ARGUMENT,
                   "shape 0 (quad): material 3 is not one of the scene's 1");
    quad.material = 0; /* the grey default, made by the first shape that needs it */
    CHECK(rrv_scene_add_shape(s, &quad, &i, &err) == RRV_OK && i == 0);
    CHECK(strcmp(s->materials[0].name, "default") == 0 && s->materials[0].albedo[0] == 0.5);
    rrv_scene_free(s);
}

/* Values no file can spell (an enum out of range, a negative sky) are
   refused as well, by name. */
static void test_code_only_refusals(void)
{
    rrv_scene *s = new_scene();
    rrv_settings set;
    rrv_environment sky;
    rrv_shape sh;
    rrv_field f;
    rrv_medium med;
    rrv_error err;
    memset(&set, 0, sizeof set);
    memset(&sky, 0, sizeof sky);
    memset(&sh, 0, sizeof sh);
    memset(&f, 0, sizeof f);
    memset(&med, 0, sizeof med);
    set.integrator = (rrv_integrator)7;
    expect_message(rrv_scene_set_settings(s, &set, &err), &err, RRV_ERROR_ARGUMENT,
                   "settings: integrator 7 is not one of rrv_integrator");
    set.integrator = RRV_INTEGRATOR_CLASSIC;
    set.bend_tolerance = 1e-5;
    expect_message(rrv_scene_set_settings(s, &set, &err), &err, RRV_ERROR_ARGUMENT,
                   "settings: bendtolerance must be at least 0.0001, got 1e-05");
    set.bend_tolerance = 0;
    set.ambient_ior = 11;
    expect_message(rrv_scene_set_settings(s, &set, &err), &err, RRV_ERROR_ARGUMENT,
                   "settings: ambient: ior must be at most 10, got 11");
    sky.kind = RRV_ENV_CONSTANT;
    CHECK(rrv_scene_set_environment(s, &sky, &err) == RRV_OK && s->environment.L[1] == 1);
    sky.kind = RRV_ENV_GRADIENT;
    sky.L2[2] = -1;
    expect_message(rrv_scene_set_environment(s, &sky, &err), &err, RRV_ERROR_ARGUMENT,
                   "environment: radiance must be >= 0, got -1");
    sh.kind = (rrv_shape_kind)9;
    expect_message(rrv_scene_add_shape(s, &sh, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "shape 0 (triangle): kind 9 is not one of rrv_shape_kind");
    sh.kind = RRV_SHAPE_SPHERE;
    sh.radius = 1;
    sh.L[0] = 1e30;
    expect_message(rrv_scene_add_shape(s, &sh, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "shape 0 (sphere): L times scale must be at most 1e+20, got 1e+30");
    med.lo = tv3(-1, -1, -1);
    med.hi = tv3(1, 1, 1);
    CHECK(rrv_scene_add_medium(s, &med, NULL, &err) == RRV_OK);
    f.kind = (rrv_field_kind)99;
    expect_message(rrv_scene_set_field(s, 0, RRV_MEDIUM_IOR, &f, &err), &err, RRV_ERROR_ARGUMENT,
                   "ior of medium \"medium 0\": kind 99 is not one of rrv_field_kind");
    f.kind = RRV_FIELD_SLAB;
    f.gradient = 0.1;
    expect_message(rrv_scene_set_field(s, 0, RRV_MEDIUM_IOR, &f, &err), &err, RRV_ERROR_ARGUMENT,
                   "ior of medium \"medium 0\": slab normal must be nonzero");
    f.normal = tv3(0, 3, 4);
    CHECK(rrv_scene_set_field(s, 0, RRV_MEDIUM_IOR, &f, &err) == RRV_OK);
    CHECK(fabs(s->media[0].ior.normal.y - 0.6) < 1e-15 && fabs(s->media[0].ior.normal.z - 0.8) < 1e-15);
    f.kind = RRV_FIELD_CONSTANT;
    f.value = 0;
    expect_message(rrv_scene_set_field(s, 0, RRV_MEDIUM_PRESSURE, &f, &err), &err, RRV_ERROR_ARGUMENT,
                   "pressure of medium \"medium 0\": constant must be > 0, got 0");
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    rrv_scene_free(s);
}

static void test_prepare_checks_hand_edits(void)
{
    rrv_scene *s = new_scene();
    rrv_medium med;
    rrv_error err;
    memset(&med, 0, sizeof med);
    med.lo = tv3(-1, -1, -1);
    med.hi = tv3(1, 1, 1);
    CHECK(rrv_scene_add_medium(s, &med, NULL, &err) == RRV_OK);
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    s->camera.look = s->camera.eye;
    expect_message(rrv_scene_prepare(s, &err), &err, RRV_ERROR_ARGUMENT,
                   "camera: eye and look must be distinct finite points");
    s->camera.look = tv3(0, 0, 0);
    s->camera.fov = 0;
    expect_message(rrv_scene_prepare(s, &err), &err, RRV_ERROR_ARGUMENT,
                   "camera: fov must be in (0, 180), got 0");
    s->camera.fov = 180;
    CHECK(rrv_scene_prepare(s, &err) == RRV_ERROR_ARGUMENT);
    s->camera.fov = 40;
    s->media[0].hi.y = -2;
    expect_message(rrv_scene_prepare(s, &err), &err, RRV_ERROR_ARGUMENT,
                   "medium \"medium 0\": box is empty along y (-1 is not below -2)");
    s->media[0].hi.y = 1;
    s->media[0].sigma_a[0] = -1;
    expect_message(rrv_scene_prepare(s, &err), &err, RRV_ERROR_ARGUMENT,
                   "medium \"medium 0\": sigma_a must be >= 0, got -1");
    s->media[0].sigma_a[0] = 0; /* an explicit zero, set after adding */
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK && s->media[0].sigma_a[0] == 0);
    rrv_scene_free(s);
}

/* The same scene as text and in code: every default and every stored value
   must agree, so the two render bit-identically. */
static const char scene_text[] =
    "camera eye 0 0.5 4 look 0 0 0 fov 35 resolution 12 9\n"
    "render integrator refractive spp 2 seed 7\n"
    "environment gradient top 1 1 1 bottom 0.1 0.1 0.2\n"
    "material red diffuse albedo 0.8 0.2 0.2\n"
    "quad origin -3 -1 -3 u 6 0 0 v 0 0 6 material red\n"
    "sphere center 0 3 0 radius 0.5 L 4 4 4\n"
    "medium puff box -1 -1 -1 1 1 1 sigma_a 0.5 0.5 0.5\n"
    "density puff noise octaves 3\n"
    "ior puff luneburg radius 0.9\n";

static rrv_scene *scene_in_code(void)
{
    rrv_scene *s = NULL;
    rrv_camera cam;
    rrv_settings set;
    rrv_environment sky;
    rrv_material red;
    rrv_shape quad, light;
    rrv_medium puff;
    rrv_field density, ior;
    rrv_error err;
    int m;
    memset(&cam, 0, sizeof cam);
    memset(&set, 0, sizeof set);
    memset(&sky, 0, sizeof sky);
    memset(&red, 0, sizeof red);
    memset(&quad, 0, sizeof quad);
    memset(&light, 0, sizeof light);
    memset(&puff, 0, sizeof puff);
    memset(&density, 0, sizeof density);
    memset(&ior, 0, sizeof ior);
    cam.eye = tv3(0, 0.5, 4);
    cam.fov = 35;
    cam.width = 12;
    cam.height = 9;
    set.integrator = RRV_INTEGRATOR_REFRACTIVE;
    set.spp = 2;
    set.seed = 7;
    sky.kind = RRV_ENV_GRADIENT;
    sky.L[0] = sky.L[1] = sky.L[2] = 1;
    sky.L2[0] = sky.L2[1] = 0.1;
    sky.L2[2] = 0.2;
    strcpy(red.name, "red");
    red.albedo[0] = 0.8;
    red.albedo[1] = red.albedo[2] = 0.2;
    quad.kind = RRV_SHAPE_QUAD;
    quad.p0 = tv3(-3, -1, -3);
    quad.e1 = tv3(6, 0, 0);
    quad.e2 = tv3(0, 0, 6);
    light.kind = RRV_SHAPE_SPHERE;
    light.center = tv3(0, 3, 0);
    light.radius = 0.5;
    light.material = 1; /* the parser made "default" second */
    light.L[0] = light.L[1] = light.L[2] = 4;
    strcpy(puff.name, "puff");
    puff.lo = tv3(-1, -1, -1);
    puff.hi = tv3(1, 1, 1);
    puff.sigma_a[0] = puff.sigma_a[1] = puff.sigma_a[2] = 0.5;
    /* in code a zero sigma_s beside a nonzero sigma_a is a zero; the file's
       unsaid sigma_s is 1 */
    puff.sigma_s[0] = puff.sigma_s[1] = puff.sigma_s[2] = 1;
    density.kind = RRV_FIELD_NOISE;
    density.noise.octaves = 3;
    density.noise.falloff = RRV_FALLOFF_SPHERE;
    ior.kind = RRV_FIELD_LUNEBURG;
    ior.radius = 0.9;
    if (rrv_scene_create(&s, &err) != RRV_OK || rrv_scene_set_camera(s, &cam, &err) != RRV_OK ||
        rrv_scene_set_settings(s, &set, &err) != RRV_OK ||
        rrv_scene_set_environment(s, &sky, &err) != RRV_OK ||
        rrv_scene_add_material(s, &red, NULL, &err) != RRV_OK ||
        rrv_scene_add_shape(s, &quad, NULL, &err) != RRV_OK) {
        CHECKF(0, "%s", err.message);
        return s;
    }
    {
        rrv_material grey;
        memset(&grey, 0, sizeof grey);
        strcpy(grey.name, "default");
        CHECK(rrv_scene_add_material(s, &grey, NULL, &err) == RRV_OK);
    }
    CHECK(rrv_scene_add_shape(s, &light, NULL, &err) == RRV_OK);
    CHECK(rrv_scene_add_medium(s, &puff, &m, &err) == RRV_OK);
    CHECK(rrv_scene_set_field(s, m, RRV_MEDIUM_DENSITY, &density, &err) == RRV_OK);
    CHECK(rrv_scene_set_field(s, m, RRV_MEDIUM_IOR, &ior, &err) == RRV_OK);
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    return s;
}

static float *render(const rrv_scene *s)
{
    int w = s->camera.width, h = s->camera.height;
    float *sum = (float *)calloc((size_t)w * h * 3, sizeof *sum);
    rrv_error err;
    CHECKF(rrv_render_rect(s, 0, 0, w, h, 0, s->settings.spp, sum, w, NULL, &err) == RRV_OK, "%s",
           err.message);
    return sum;
}

static void test_code_and_file_agree(void)
{
    rrv_scene *parsed = NULL, *built = scene_in_code();
    rrv_error err;
    float *a, *b;
    size_t n;
    CHECKF(rrv_scene_parse(scene_text, sizeof scene_text - 1, "agree.rrv", NULL, NULL, &parsed, &err) ==
               RRV_OK,
           "%s", err.message);
    if (!parsed || !built) return;
    CHECK(parsed->material_count == built->material_count && parsed->shape_count == built->shape_count);
    CHECK(memcmp(&parsed->settings, &built->settings, sizeof parsed->settings) == 0);
    CHECK(memcmp(&parsed->camera, &built->camera, sizeof parsed->camera) == 0);
    n = (size_t)parsed->camera.width * parsed->camera.height * 3;
    a = render(parsed);
    b = render(built);
    CHECK(memcmp(a, b, n * sizeof *a) == 0);
    {
        double total = 0;
        size_t i;
        for (i = 0; i < n; ++i) total += a[i];
        CHECK(total > 0); /* the comparison is of an image, not of zeros */
    }
    free(a);
    free(b);
    rrv_scene_free(parsed);
    rrv_scene_free(built);
}

static void test_prepare_twice(void)
{
    rrv_scene *s = scene_in_code();
    rrv_error err;
    size_t bytes = s->bytes, n = (size_t)s->camera.width * s->camera.height * 3;
    float *a = render(s), *b;
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECK(rrv_scene_prepare(s, &err) == RRV_OK);
    CHECK(s->bytes == bytes);
    b = render(s);
    CHECK(memcmp(a, b, n * sizeof *a) == 0);
    free(a);
    free(b);
    rrv_scene_free(s);
}

static void test_render_rect_errors(void)
{
    rrv_scene *s = scene_in_code();
    rrv_medium extra;
    float sum[3 * 12 * 9];
    rrv_error err;
    expect_message(rrv_render_rect(s, 0, 0, 13, 9, 0, 1, sum, 13, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: pixels [0,13) x [0,9) are not inside the 12 x 9 image");
    expect_message(rrv_render_rect(s, 0, 0, 12, 9, 0, 1, sum, 11, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: stride 11 is below the rectangle's width 12");
    expect_message(rrv_render_rect(s, 0, 0, 12, 9, 2, 1, sum, 12, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: samples [2,1) are not a range of indices in [0, 16777216)");
    /* the bound the header states: indices below RRV_MAX_SPP, the spp bound */
    expect_message(rrv_render_rect(s, 0, 0, 12, 9, RRV_MAX_SPP, RRV_MAX_SPP + 1, sum, 12, NULL, &err), &err,
                   RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: samples [16777216,16777217) are not a range of indices in [0, 16777216)");
    expect_message(rrv_render_rect(s, 0, 0, 12, 9, INT_MAX - 1, INT_MAX, sum, 12, NULL, &err), &err,
                   RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: samples [2147483646,2147483647) are not a range of indices in [0, 16777216)");
    memset(sum, 0, sizeof sum);
    CHECK(rrv_render_rect(s, 0, 0, 1, 1, RRV_MAX_SPP - 1, RRV_MAX_SPP, sum, 1, NULL, &err) == RRV_OK);
    memset(&extra, 0, sizeof extra);
    extra.lo = tv3(2, 2, 2);
    extra.hi = tv3(3, 3, 3);
    CHECK(rrv_scene_add_medium(s, &extra, NULL, &err) == RRV_OK);
    CHECK(rrv_render_rect(s, 0, 0, 12, 9, 0, 1, sum, 12, NULL, &err) == RRV_ERROR_ARGUMENT);
    CHECK(strstr(err.message, "not prepared") != NULL);
    CHECK(rrv_render_rect(s, 0, 0, 12, 9, 0, 1, sum, 12, NULL, NULL) == RRV_ERROR_ARGUMENT);
    rrv_scene_free(s);
}

/* A scene made in code and never prepared is refused, whatever it holds
   (one with neither shapes nor media rendered its sky and returned RRV_OK),
   and so is one edited after rrv_scene_prepare; preparing makes it render. */
static void test_unprepared_scene_is_refused(void)
{
    rrv_scene *s = NULL;
    rrv_environment sky;
    rrv_settings settings;
    rrv_camera cam;
    float sum[3 * 4] = {0};
    rrv_error err;
    int i;
    memset(&sky, 0, sizeof sky);
    sky.kind = RRV_ENV_CONSTANT;
    sky.L[0] = sky.L[1] = sky.L[2] = 1;
    memset(&cam, 0, sizeof cam);
    cam.eye.z = 4;
    cam.width = cam.height = 2;
    CHECK(rrv_scene_create(&s, &err) == RRV_OK);
    if (!s) return;
    CHECK(rrv_scene_set_camera(s, &cam, &err) == RRV_OK);
    CHECK(rrv_scene_set_environment(s, &sky, &err) == RRV_OK);
    expect_message(rrv_render_rect(s, 0, 0, 2, 2, 0, 1, sum, 2, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: the scene is not prepared (call rrv_scene_prepare after editing it)");
    for (i = 0; i < 12; ++i) CHECK(sum[i] == 0);
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    CHECKF(rrv_render_rect(s, 0, 0, 2, 2, 0, 1, sum, 2, NULL, &err) == RRV_OK, "%s", err.message);
    CHECKF(sum[0] > 0.5f, "the sky gave %g", sum[0]);
    settings = s->settings;
    CHECK(rrv_scene_set_settings(s, &settings, &err) == RRV_OK);
    expect_message(rrv_render_rect(s, 0, 0, 2, 2, 0, 1, sum, 2, NULL, &err), &err, RRV_ERROR_ARGUMENT,
                   "rrv_render_rect: the scene is not prepared (call rrv_scene_prepare after editing it)");
    rrv_scene_free(s);
}

static void test_fields_and_meshes_are_copied(void)
{
    rrv_scene *s = new_scene();
    rrv_medium med;
    rrv_field f;
    rrv_blob blobs[2];
    rrv_shape proto;
    rrv_error err;
    /* a square of two triangles, a degenerate third dropped */
    static const double points[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    static const int tris[] = {0, 1, 2, 0, 2, 3, 0, 1, 1};
    static const int bad[] = {0, 1, 4};
    memset(&med, 0, sizeof med);
    memset(&f, 0, sizeof f);
    memset(blobs, 0, sizeof blobs);
    memset(&proto, 0, sizeof proto);
    med.lo = tv3(-1, -1, -1);
    med.hi = tv3(1, 1, 1);
    CHECK(rrv_scene_add_medium(s, &med, NULL, &err) == RRV_OK);
    blobs[0].radius = blobs[1].radius = 0.3;
    blobs[1].weight = 2;
    f.kind = RRV_FIELD_BLOBS;
    f.blobs = blobs;
    f.blob_count = 2;
    CHECK(rrv_scene_set_field(s, 0, RRV_MEDIUM_DENSITY, &f, &err) == RRV_OK);
    blobs[0].radius = -5; /* the caller's array, not the scene's */
    CHECK(s->media[0].density.blobs != blobs && s->media[0].density.blobs[0].radius == 0.3);
    CHECK(s->media[0].density.blobs[0].weight == 1 && s->media[0].density.blobs[1].weight == 2);
    CHECK(rrv_scene_add_triangles(s, &proto, points, 4, tris, 3, &err) == RRV_OK);
    CHECK(s->shape_count == 2 && s->shapes[1].kind == RRV_SHAPE_TRIANGLE);
    expect_message(rrv_scene_add_triangles(s, &proto, points, 4, bad, 1, &err), &err, RRV_ERROR_ARGUMENT,
                   "mesh: index 4 is out of range (4 points)");
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "%s", err.message);
    rrv_scene_free(s);
}

/* read_file hands out buffers of its own (16 bytes into a block, so that
   RRV_FREE on one would be caught); release_file must get each back. */
typedef struct files {
    int reads, releases;
} files;

static const unsigned char *grid_bytes(size_t *size)
{
    static unsigned char g[48 + 8 * 4];
    static const float box[6] = {-1, -1, -1, 1, 1, 1};
    int i;
    memset(g, 0, sizeof g);
    memcpy(g, "VOL", 3);
    g[3] = 3;
    g[4] = 1;                                 /* float32 */
    g[8] = 2, g[12] = 2, g[16] = 2, g[20] = 1; /* 2 x 2 x 2, 1 channel */
    for (i = 0; i < 6; ++i) {
        uint32_t u;
        memcpy(&u, &box[i], 4);
        g[24 + 4 * i] = (unsigned char)u, g[25 + 4 * i] = (unsigned char)(u >> 8);
        g[26 + 4 * i] = (unsigned char)(u >> 16), g[27 + 4 * i] = (unsigned char)(u >> 24);
    }
    for (i = 0; i < 8; ++i) {
        float v = 0.5f;
        uint32_t u;
        memcpy(&u, &v, 4);
        g[48 + 4 * i] = (unsigned char)u, g[49 + 4 * i] = (unsigned char)(u >> 8);
        g[50 + 4 * i] = (unsigned char)(u >> 16), g[51 + 4 * i] = (unsigned char)(u >> 24);
    }
    *size = sizeof g;
    return g;
}

static int files_read(void *user, const char *path, void **data, size_t *size)
{
    static const char scene[] = "camera eye 0 0 5 look 0 0 0 resolution 4 3\n"
                                "mesh file tri.obj\n"
                                "medium m box -1 -1 -1 1 1 1\n"
                                "density m grid g.vol\n";
    static const char obj[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    static const char broken[] = "camera eye 0 0 5 look 0 0 0\nmesh file tri.obj\nmesh file gone.obj\n";
    files *fs = (files *)user;
    const void *src;
    size_t n;
    unsigned char *block;
    if (strcmp(path, "dir/s.rrv") == 0)
        src = scene, n = sizeof scene - 1;
    else if (strcmp(path, "dir/broken.rrv") == 0)
        src = broken, n = sizeof broken - 1;
    else if (strcmp(path, "dir/tri.obj") == 0)
        src = obj, n = sizeof obj - 1;
    else if (strcmp(path, "dir/g.vol") == 0)
        src = grid_bytes(&n);
    else
        return 1;
    block = (unsigned char *)malloc(n + 16);
    if (!block) return 1;
    memcpy(block + 16, src, n);
    *data = block + 16;
    *size = n;
    fs->reads++;
    return 0;
}

static void files_release(void *user, void *data)
{
    ((files *)user)->releases++;
    free((unsigned char *)data - 16);
}

static void test_read_release_pair(void)
{
    files fs = {0, 0};
    rrv_load_options opt;
    rrv_scene *s = NULL;
    rrv_error err;
    memset(&opt, 0, sizeof opt);
    opt.read_file = files_read;
    opt.release_file = files_release;
    opt.read_file_user = &fs;
    CHECKF(rrv_scene_load("dir/s.rrv", &opt, &s, &err) == RRV_OK, "%s", err.message);
    CHECK(fs.reads == 3 && fs.releases == 3);
    CHECK(s && s->shape_count == 1 && s->media[0].density.kind == RRV_FIELD_GRID);
    rrv_scene_free(s);
    /* a load that fails halfway gives back what it read too */
    fs.reads = fs.releases = 0;
    CHECK(rrv_scene_load("dir/broken.rrv", &opt, &s, &err) == RRV_ERROR_IO && s == NULL);
    CHECK(err.line == 3 && fs.reads == 2 && fs.releases == 2);
}

/* The channel groups rrv_medium_channel_groups reports: channels within 4x
   of their group's densest share it, numbered from the densest. */
static void test_channel_groups_reported(void)
{
    rrv_medium m;
    int group[3];
    memset(&m, 0, sizeof m);
    m.scale = 2;
    m.sigma_a[0] = m.sigma_a[1] = m.sigma_a[2] = 1;
    CHECK(rrv_medium_channel_groups(&m, group) == 1 && group[0] == 0 && group[1] == 0 && group[2] == 0);
    /* 1 : 4 is one group (4x is the span), 1 : 4.01 two */
    m.sigma_a[1] = 4;
    CHECK(rrv_medium_channel_groups(&m, group) == 1 && group[0] == 0 && group[1] == 0 && group[2] == 0);
    m.sigma_a[1] = 4.01;
    CHECK(rrv_medium_channel_groups(&m, group) == 2 && group[1] == 0 && group[0] == 1 && group[2] == 1);
    /* the fuzz input that made groups: 0.4, 6e10, 0.6 (sigma_s counts too) */
    m.sigma_a[0] = 0.4; m.sigma_a[1] = 0; m.sigma_a[2] = 0.6;
    m.sigma_s[1] = 6e10;
    CHECK(rrv_medium_channel_groups(&m, group) == 2 && group[1] == 0 && group[0] == 1 && group[2] == 1);
    /* 0.1, 0.5, 2.5: each 5x the next, three groups, blue densest */
    m.sigma_s[1] = 0;
    m.sigma_a[0] = 0.1; m.sigma_a[1] = 0.5; m.sigma_a[2] = 2.5;
    CHECK(rrv_medium_channel_groups(&m, group) == 3 && group[2] == 0 && group[1] == 1 && group[0] == 2);
    /* a channel without extinction joins no denser group */
    m.sigma_a[0] = 0; m.sigma_a[1] = 1; m.sigma_a[2] = 1;
    CHECK(rrv_medium_channel_groups(&m, group) == 2 && group[1] == 0 && group[2] == 0 && group[0] == 1);
}

/* Renders text's 6 x 4 image at 2 spp into out (72 floats); 0 if refused. */
static int render_small(const char *text, float *out)
{
    rrv_scene *s = NULL;
    rrv_error err;
    int ok;
    memset(out, 0, 72 * sizeof *out);
    if (rrv_scene_parse(text, strlen(text), "small.rrv", NULL, NULL, &s, &err) != RRV_OK) {
        printf("  refused: %s\n", err.message);
        return 0;
    }
    ok = rrv_render_rect(s, 0, 0, 6, 4, 0, 2, out, 6, NULL, &err) == RRV_OK;
    rrv_scene_free(s);
    return ok;
}

/* A camera frame is directions only, so eye and look 1e-305 apart (whose
   difference squares to 0) and an up of 1e-300 must give the image of
   the same eye looking the same way with unit vectors. Before, the
   frame kept the unnormalisable vectors: camera rays 1e-305 long, whose
   walks ran to their caps (a fuzz_render finding). */
static void test_tiny_camera_vectors(void)
{
    static const char body[] =
        "render spp 2 maxdepth 4 seed 3 integrator refractive\n"
        "environment constant L 0.2 0.3 0.4\n"
        "quad origin -1 -1 -3 u 2 0 0 v 0 2 0 L 5 5 5\n"
        "medium m box -1 -1 -2 1 1 1 sigma_a 0.2 0.2 0.2 sigma_s 0.5 0.5 0.5\n"
        "density m constant 1\n"
        "ior m shell radius 1.5 thickness 0.5 edge 0.2 amplitude 0.3\n";
    char tiny[1024], plain[1024];
    float a[72], b[72];
    int i, same = 1, finite = 1;
    snprintf(tiny, sizeof tiny, "camera eye 0 0 1e-305 look 0 0 0 up 0 1e-300 0 fov 40 resolution 6 4\n%s", body);
    snprintf(plain, sizeof plain, "camera eye 0 0 1e-305 look 0 0 -1 up 0 1 0 fov 40 resolution 6 4\n%s", body);
    CHECK(render_small(tiny, a));
    CHECK(render_small(plain, b));
    for (i = 0; i < 72; ++i) {
        same &= a[i] == b[i];
        finite &= isfinite(a[i]);
    }
    CHECK(same);
    CHECK(finite);
}

int main(void)
{
    RUN(test_zero_means_default);
    RUN(test_default_integrator);
    RUN(test_face_jumps);
    RUN(test_refusals_name_the_object);
    RUN(test_code_only_refusals);
    RUN(test_prepare_checks_hand_edits);
    RUN(test_code_and_file_agree);
    RUN(test_prepare_twice);
    RUN(test_render_rect_errors);
    RUN(test_unprepared_scene_is_refused);
    RUN(test_fields_and_meshes_are_copied);
    RUN(test_read_release_pair);
    RUN(test_channel_groups_reported);
    RUN(test_tiny_camera_vectors);
    return CHECK_EXIT_CODE();
}
