/* Variance times cost of the shadow rays' transmittance estimators, ratio
   tracking against residual ratio tracking (rrv_settings.transmittance).
   Not a test: make test builds it so it cannot rot. From the repository
   root:
     build/measure_transmittance SCENE [RAYS [ESTIMATES [ROUNDS]]]
   Shadow rays as the path tracer casts them: each from a point of the
   scene's first medium drawn with density proportional to its extinction
   (where scattering vertices fall), toward a uniform point of the scene's
   first area light, straight and to the light (refraction's chords are
   such straight pieces too). Each ray's transmittance is estimated
   ESTIMATES times by each estimator, the estimators alternating ray by ray;
   per estimator it prints the mean over rays of the per-ray sample
   variance, the CPU time (clock()) and the tentative collisions an
   estimate, and their product variance x seconds, whose ratio is the
   efficiency ratio. ROUNDS repeats the whole (new rays each round) and
   the medians are printed last. Channel 1 (green) is the one tallied. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double seconds(void) { return (double)clock() / CLOCKS_PER_SEC; }

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

#define MAX_ROUNDS 64
#define NE 3
static const rrv_transmittance kinds[NE] = {RRV_TRANSMITTANCE_RATIO, RRV_TRANSMITTANCE_RESIDUAL, RRV_TRANSMITTANCE_MARCH};
static const char *names[NE] = {"ratio", "residual", "march"};

int main(int argc, char **argv)
{
    const char *path = argc > 1 ? argv[1] : "scenes/plume.rrv";
    int rays = argc > 2 ? atoi(argv[2]) : 2000, estimates = argc > 3 ? atoi(argv[3]) : 64;
    int rounds = argc > 4 ? atoi(argv[4]) : 5, round, e, i;
    rrv_scene *scene = NULL;
    rrv_error err;
    const rrv_shape *light = NULL;
    const rrv_medium *m;
    rrv__context ctx;
    rrv__rng rng;
    double eff[NE][MAX_ROUNDS], var_r[NE][MAX_ROUNDS], cpu_r[NE][MAX_ROUNDS], ev_r[NE][MAX_ROUNDS], mean_r[NE][MAX_ROUNDS];
    if (rounds < 1 || rounds > MAX_ROUNDS || rays < 1 || estimates < 2) {
        fprintf(stderr, "usage: measure_transmittance SCENE [RAYS [ESTIMATES [ROUNDS <= %d]]]\n", MAX_ROUNDS);
        return 2;
    }
    if (rrv_scene_load(path, NULL, &scene, &err) != RRV_OK || rrv_scene_prepare(scene, &err) != RRV_OK) {
        fprintf(stderr, "%s:%d: %s\n", err.file, err.line, err.message);
        return 2;
    }
    for (i = 0; i < scene->shape_count && !light; ++i)
        if (scene->shapes[i].kind == RRV_SHAPE_QUAD && rrv__max3(scene->shapes[i].L) > 0) light = &scene->shapes[i];
    if (!light || scene->medium_count < 1) {
        fprintf(stderr, "%s: needs a quad light and a medium\n", path);
        return 2;
    }
    m = &scene->media[0];
    memset(&ctx, 0, sizeof ctx);
    ctx.scene = scene;
    ctx.eta_camera2 = 1;
    rrv__rng_seed(&rng, 2026, 12, 3);
    for (round = 0; round < rounds; ++round) {
        double sum_var[NE] = {0, 0, 0}, cpu[NE] = {0, 0, 0}, sum_mean[NE] = {0, 0, 0};
        uint64_t events[NE] = {0, 0, 0};
        int r;
        for (r = 0; r < rays; ++r) {
            rrv_vec3 o, y, d;
            double len;
            for (;;) {
                rrv__coeffs c;
                o = rrv__v3(m->lo.x + rrv__uniform(&rng) * (m->hi.x - m->lo.x),
                            m->lo.y + rrv__uniform(&rng) * (m->hi.y - m->lo.y),
                            m->lo.z + rrv__uniform(&rng) * (m->hi.z - m->lo.z));
                rrv__medium_coeffs(m, o, &c);
                if (rrv__uniform(&rng) * m->majorant->density_peak * m->majorant->sigma_t_max <
                    c.sigma_a[1] + c.sigma_s[1])
                    break;
            }
            y = rrv__add(light->p0, rrv__add(rrv__scale(light->e1, rrv__uniform(&rng)),
                                             rrv__scale(light->e2, rrv__uniform(&rng))));
            d = rrv__sub(y, o);
            len = rrv__length(d);
            d = rrv__scale(d, 1.0 / len);
            /* alternate which estimator goes first, so neither owns the warm cache */
            for (e = 0; e < NE; ++e) {
                int which = (r + e) % NE;
                double s1 = 0, s2 = 0, t0;
                uint64_t ev0 = ctx.stats.events;
                int k;
                scene->settings.transmittance = kinds[which];
                t0 = seconds();
                for (k = 0; k < estimates; ++k) {
                    double T[3];
                    rrv__transmittance(&ctx, o, d, len * (1.0 - 1e-6), &rng, T);
                    s1 += T[1];
                    s2 += T[1] * T[1];
                }
                cpu[which] += seconds() - t0;
                events[which] += ctx.stats.events - ev0;
                sum_mean[which] += s1 / estimates;
                sum_var[which] += (s2 - s1 * s1 / estimates) / (estimates - 1);
            }
        }
        for (e = 0; e < NE; ++e) {
            double n = (double)rays * estimates;
            var_r[e][round] = sum_var[e] / rays;
            cpu_r[e][round] = cpu[e] / n;
            ev_r[e][round] = (double)events[e] / n;
            mean_r[e][round] = sum_mean[e] / rays;
            eff[e][round] = var_r[e][round] * cpu_r[e][round];
        }
        printf("round %d:", round);
        for (e = 0; e < NE; ++e)
            printf(" %s var %.5g cpu %.4g us lookups %.3g mean %.5f (%.4f) |", names[e], var_r[e][round],
                   1e6 * cpu_r[e][round], ev_r[e][round], mean_r[e][round], eff[e][round] / eff[0][round]);
        printf("\n");
    }
    printf("%s: medians of %d rounds, %d rays x %d estimates:\n", path, rounds, rays, estimates);
    for (e = 0; e < NE; ++e) {
        double q[MAX_ROUNDS];
        for (i = 0; i < rounds; ++i) q[i] = eff[e][i] / eff[0][i];
        printf("  %-8s mean %.5f  variance %.5g  cpu/estimate %.4g us  lookups/estimate %.4g  var x cpu %.5g"
               "  / ratio's %.4f\n",
               names[e], median(mean_r[e], rounds), median(var_r[e], rounds), 1e6 * median(cpu_r[e], rounds),
               median(ev_r[e], rounds), median(eff[e], rounds), median(q, rounds));
    }
    rrv_scene_free(scene);
    return 0;
}
