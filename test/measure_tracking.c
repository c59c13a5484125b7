/* How far tracking is from the cost of its memory reads, on scenes/plume.rrv,
   and how far the comb's rays land from the eikonal reference's.
   Not a test: make test builds it so it cannot rot;
   `make bench` runs it from the repository root:
     build/measure_tracking [SPP]
     build/measure_tracking --comb SCENE [BEND_TOLERANCE [PLANE [MU_ETA]]]
   The second form traces camera rays (a 32 x 24 lattice of pixels, those
   whose ray bends) through SCENE's refracting media with the comb
   (rrv_trace_ray, REFRACTIVE, 16 walks a ray, the scene's bend tolerance
   unless given) and with eikonal RK4 at h = 0.002 m, the reference, and
   prints the RMS distance between where they cross the plane
   forward . x = PLANE (default, or "-": the far corner of the refracting
   boxes along the camera's forward axis), the RMS angle between their exit
   directions, the mean comb points a ray and the CPU time a comb ray.
   MU_ETA > 0 sets the comb's fixed rate (points a metre, evenly spaced):
   the uniform leapfrog to set a spacing rule against.
   The first form prints
     1. tentative collisions (null and real, rrv_render_stats.events) per
        second of one thread rendering the plume, classic integrator;
     2. the same grid's lookup alone, as the tracker calls it
        (rrv__field_eval on the medium's density), and a bare trilinear
        lookup with the scale factors precomputed (no divisions, no bounds
        test): both at points spread over the plume's support, in a random
        order that defeats the caches as a path's collisions do not, and
        along rays, where consecutive points are close as on a path.
   Times are CPU time of this thread (clock()), the best of 3 runs. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define LOOKUPS (1 << 22)

static double seconds(void) { return (double)clock() / CLOCKS_PER_SEC; }

/* The cheapest trilinear lookup of corner-placed samples: what a lookup
   costs at least (8 reads, 7 lerps). */
static double bare_trilinear(const float *d, int n, double sx, double sy, double sz, rrv_vec3 lo, rrv_vec3 p)
{
    double u = (p.x - lo.x) * sx, v = (p.y - lo.y) * sy, w = (p.z - lo.z) * sz;
    int i = (int)u, j = (int)v, k = (int)w;
    double tx, ty, tz, c00, c10, c01, c11;
    const float *q;
    if (i > n - 2) i = n - 2;
    if (j > n - 2) j = n - 2;
    if (k > n - 2) k = n - 2;
    tx = u - i; ty = v - j; tz = w - k;
    q = d + ((size_t)k * n + j) * n + i;
    c00 = q[0] + tx * (q[1] - q[0]);
    c10 = q[n] + tx * (q[n + 1] - q[n]);
    c01 = q[n * n] + tx * (q[n * n + 1] - q[n * n]);
    c11 = q[n * n + n] + tx * (q[n * n + n + 1] - q[n * n + n]);
    c00 += ty * (c10 - c00);
    c01 += ty * (c11 - c01);
    return c00 + tz * (c01 - c00);
}

typedef struct landing {
    rrv_vec3 forward;
    double plane;
} landing;

static int land(const rrv_trace_result *r, const landing *l, rrv_vec3 *at)
{
    double along = rrv__dot(r->direction, l->forward);
    if (!(along > 1e-6)) return 0;
    *at = rrv__madd(r->position, r->direction, (l->plane - rrv__dot(r->position, l->forward)) / along);
    return 1;
}

#define COMB_WALKS 16

static int comb_error(const char *path, double tolerance, const char *plane, double mu_eta)
{
    rrv_scene *scene = NULL;
    rrv_error err;
    rrv__camera_frame frame;
    landing l;
    double sq_pos = 0, sq_angle = 0, cpu = 0, kicks = 0;
    long rays = 0, walks = 0;
    int px, py, i;
    if (rrv_scene_load(path, NULL, &scene, &err) != RRV_OK) {
        fprintf(stderr, "%s:%d: %s\n", err.file, err.line, err.message);
        return 2;
    }
    if (tolerance > 0) scene->settings.bend_tolerance = tolerance;
    if (mu_eta > 0) scene->settings.mu_eta = mu_eta;
    if (rrv_scene_prepare(scene, &err) != RRV_OK) {
        fprintf(stderr, "%s: %s\n", path, err.message);
        return 2;
    }
    rrv__camera_setup(&scene->camera, &frame);
    l.forward = frame.forward;
    l.plane = -DBL_MAX;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        if (!rrv__medium_refracts(m)) continue;
        l.plane = fmax(l.plane, (l.forward.x > 0 ? m->hi.x : m->lo.x) * l.forward.x +
                                    (l.forward.y > 0 ? m->hi.y : m->lo.y) * l.forward.y +
                                    (l.forward.z > 0 ? m->hi.z : m->lo.z) * l.forward.z);
    }
    if (plane && strcmp(plane, "-") != 0) l.plane = atof(plane);
    for (py = 0; py < 24; ++py)
        for (px = 0; px < 32; ++px) {
            rrv_vec3 d = rrv__camera_ray(&frame, &scene->camera, (px + 0.5) * scene->camera.width / 32.0,
                                         (py + 0.5) * scene->camera.height / 24.0);
            rrv_trace_result ref, comb;
            rrv_vec3 ref_at, comb_at;
            double t;
            int walk;
            scene->settings.step = 0.002;
            scene->settings.stepper = RRV_STEPPER_RK4;
            if (rrv_trace_ray(scene, RRV_INTEGRATOR_EIKONAL, frame.eye, d, 1, 0, NULL, NULL, &ref, &err) != RRV_OK ||
                ref.events == 0 || !land(&ref, &l, &ref_at))
                continue;
            ++rays;
            t = seconds();
            for (walk = 0; walk < COMB_WALKS; ++walk) {
                if (rrv_trace_ray(scene, RRV_INTEGRATOR_REFRACTIVE, frame.eye, d, 1, (uint64_t)walk, NULL, NULL, &comb,
                                  &err) != RRV_OK)
                    continue;
                kicks += (double)comb.events;
                ++walks;
                if (land(&comb, &l, &comb_at)) {
                    rrv_vec3 e = rrv__sub(comb_at, ref_at);
                    double c = rrv__dot(comb.direction, ref.direction);
                    sq_pos += rrv__dot(e, e);
                    c = c > 1 ? 1 : c;
                    sq_angle += acos(c) * acos(c);
                } else {
                    sq_pos += 1.0; /* turned away from the plane: counts as a metre */
                }
            }
            cpu += seconds() - t;
        }
    if (!walks) {
        fprintf(stderr, "measure_tracking: no camera ray of %s bends\n", path);
        return 2;
    }
    printf("| %s | %g | %ld | %.2f | %.3f mm | %.3g mrad | %.2f us |\n", path, scene->settings.bend_tolerance,
           rays, kicks / walks, 1e3 * sqrt(sq_pos / walks), 1e3 * sqrt(sq_angle / walks), cpu / walks * 1e6);
    rrv_scene_free(scene);
    return 0;
}

int main(int argc, char **argv)
{
    rrv_scene *scene = NULL;
    rrv_error err;
    rrv_render_stats stats;
    const rrv_medium *m;
    const rrv_field *density;
    rrv_vec3 *points;
    float *sum;
    double best, t, acc = 0;
    int spp = argc > 1 ? atoi(argv[1]) : 4, w, h, run, order, i;
    uint64_t state = 0x853C49E6748FEA9Bull;
    if (argc > 2 && strcmp(argv[1], "--comb") == 0)
        return comb_error(argv[2], argc > 3 ? atof(argv[3]) : 0, argc > 4 ? argv[4] : NULL,
                          argc > 5 ? atof(argv[5]) : 0);
    if (rrv_scene_load("scenes/plume.rrv", NULL, &scene, &err) != RRV_OK) {
        fprintf(stderr, "%s:%d: %s\n", err.file, err.line, err.message);
        return 2;
    }
    m = &scene->media[0];
    density = rrv__field_of(m, RRV__DENSITY);
    if (density->kind != RRV_FIELD_GRID || density->grid.channels != 1 || density->grid.nx != density->grid.ny ||
        density->grid.nx != density->grid.nz) {
        fprintf(stderr, "measure_tracking: scenes/plume.rrv has no one-channel cubic density grid\n");
        return 2;
    }
    w = scene->camera.width;
    h = scene->camera.height;
    sum = (float *)calloc((size_t)w * h * 3, sizeof *sum);
    points = (rrv_vec3 *)malloc(sizeof *points * LOOKUPS);
    if (!sum || !points) return 2;

    best = 1e30;
    for (run = 0; run < 3; ++run) {
        memset(&stats, 0, sizeof stats);
        t = seconds();
        rrv_render_rect(scene, 0, 0, w, h, 0, spp, sum, w, &stats, NULL);
        t = seconds() - t;
        if (t < best) best = t;
    }
    printf("| tracking: tentative collisions, 1 thread, %dx%d at %d spp | %.1f M/s | %.0f ns each |\n", w, h, spp,
           stats.events / best * 1e-6, best / (double)stats.events * 1e9);

    for (order = 0; order < 2; ++order) {
        const rrv_grid *g = &density->grid;
        double sx = (g->nx - 1) / (g->hi.x - g->lo.x), sy = (g->ny - 1) / (g->hi.y - g->lo.y),
               sz = (g->nz - 1) / (g->hi.z - g->lo.z);
        rrv_vec3 p = rrv__v3(0.5, 0.5, 0.5), dir = rrv__v3(1, 0, 0);
        for (i = 0; i < LOOKUPS; ++i) {
            double r[3];
            int c;
            for (c = 0; c < 3; ++c) {
                state = state * 6364136223846793005ull + 1442695040888963407ull;
                r[c] = (double)(state >> 11) / 9007199254740992.0;
            }
            if (order == 0) {
                /* uniform in the plume's cone's bounding box */
                p = rrv__v3(0.25 + 0.5 * r[0], 0.25 + 0.5 * r[1], 0.02 + 0.96 * r[2]);
            } else {
                /* a walk: steps of ~half a voxel, turning now and then */
                if (r[0] < 0.05 || !rrv__inside_box(p, rrv__v3(0.02, 0.02, 0.02), rrv__v3(0.98, 0.98, 0.98))) {
                    if (!rrv__inside_box(p, rrv__v3(0.02, 0.02, 0.02), rrv__v3(0.98, 0.98, 0.98)))
                        p = rrv__v3(0.5, 0.5, 0.5);
                    dir = rrv__v3(r[0] - 0.5, r[1] - 0.5, r[2] - 0.5);
                }
                p = rrv__add(p, rrv__scale(dir, 0.016 * r[1]));
            }
            points[i] = p;
        }
        for (run = 0; run < 2; ++run) {
            best = 1e30;
            int k;
            for (k = 0; k < 3; ++k) {
                t = seconds();
                if (run == 0)
                    for (i = 0; i < LOOKUPS; ++i) acc += rrv__field_eval(density, points[i], 0, 0.0);
                else
                    for (i = 0; i < LOOKUPS; ++i) acc += bare_trilinear(g->data, g->nx, sx, sy, sz, g->lo, points[i]);
                t = seconds() - t;
                if (t < best) best = t;
            }
            printf("| %s, points %s | %.1f M/s | %.1f ns each |\n",
                   run == 0 ? "rrv's density lookup (rrv__field_eval)" : "bare trilinear (no divisions)",
                   order == 0 ? "in random order" : "along walks", LOOKUPS / best * 1e-6, best / LOOKUPS * 1e9);
        }
    }
    if (acc == 42.0) printf("\n"); /* keeps the lookups from being optimised away */
    free(points);
    free(sum);
    rrv_scene_free(scene);
    return 0;
}
