/* Equiangular samples toward lights inside media (render equiangular): the
   density and its sampler, the three MIS weights, and renders with and
   without them. Stochastic checks use fixed seeds and a bound of 4
   standard errors. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Fog in a box holding a small sphere light, a quad light facing down and
   a triangle light, a dense box of smoke inside it (rays through both take
   free flights alone), a sky; the camera looks across the fog under the
   lights, at their glow, and does not see them. %s: more render keys. */
static const char *const fog_lamps =
    "camera eye 0 0.6 -2.8 look 0 0.3 1 up 0 1 0 fov 40 resolution 16 12\n"
    "render spp 1 maxdepth 2 integrator classic %s\n"
    "environment constant L 0.02 0.02 0.03\n"
    "material ground diffuse albedo 0.4 0.4 0.4\n"
    "quad origin -6 0 -6 u 0 0 12 v 12 0 0 material ground\n"
    "sphere center 0.3 2.0 0.2 radius 0.06 L 150 130 110\n"
    "quad origin -0.9 2.4 0.4 u 0.3 0 0 v 0 0 0.3 L 40 30 20\n"
    "triangle p0 -1 1.9 1 p1 -0.7 1.9 1 p2 -0.85 2.3 1 L 20 30 40\n"
    "medium fog box -3 0 -3 3 3 3 sigma_a 0.05 0.05 0.1 sigma_s 0.3 0.4 0.5 g 0.5\n"
    "density fog noise octaves 3 frequency 1.5 seed 4 amplitude 1 base 0.3\n"
    "medium smoke box 0.6 0 -0.4 1.2 0.8 0.4 sigma_a 0.5 0.5 0.5 sigma_s 3 3 3 g -0.2\n"
    "density smoke constant 1\n";

static rrv_scene *load_fog(const char *keys)
{
    char text[2048];
    rrv_scene *s = NULL;
    rrv_error e;
    snprintf(text, sizeof text, fog_lamps, keys);
    if (rrv_scene_parse(text, strlen(text), "fog.rrv", ".", NULL, &s, &e) != RRV_OK) {
        CHECKF(0, "%s:%d: %s", e.file, e.line, e.message);
        return NULL;
    }
    return s;
}

static double uniform01(uint64_t *state)
{
    *state = *state * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(*state >> 11) * (1.0 / 9007199254740992.0);
}

/* The density integrates to one over its span (Simpson, 20,000 panels),
   the sampler's pdf is the density at what it draws, and the draws fall
   into eight equal pieces of the span as often as the density says
   (within 4 standard errors of a binomial count), for a centre beside the
   span, one far off, one near its line. */
static void density_and_sampler_agree(void)
{
    static const double centres[3][3] = {{0.4, 0.3, 1.1}, {30, -12, 4}, {0.2, 1e-3, 0.7}};
    rrv__equi eq;
    int k;
    memset(&eq, 0, sizeof eq);
    eq.on = 1;
    eq.o = rrv__v3(0, 0, 0);
    eq.d = rrv__normalize(rrv__v3(0.3, 0.1, 1.0));
    eq.a = 0.25;
    eq.b = 2.5;
    for (k = 0; k < 3; ++k) {
        rrv_vec3 c = rrv__v3(centres[k][0], centres[k][1], centres[k][2]);
        double integral = 0, h = (eq.b - eq.a) / 20000, bin_p[8] = {0}, worst_z = 0;
        long count[8] = {0};
        uint64_t state = 99 + (uint64_t)k;
        int i, bin, n = 200000;
        for (i = 0; i <= 20000; ++i) {
            double w = (i == 0 || i == 20000) ? 1 : (i % 2 ? 4 : 2);
            double t = eq.a + i * h, p = rrv__equi_pdf(&eq, c, t);
            integral += w * p * h / 3;
            if (i < 20000) bin_p[i * 8 / 20000] += p * h; /* left sums: the bins' shares to 1e-4 */
        }
        CHECKF(fabs(integral - 1) < 1e-8, "centre %d: the density integrates to %.12g", k, integral);
        for (i = 0; i < n; ++i) {
            double t, pdf;
            CHECK(rrv__equi_sample(&eq, c, uniform01(&state), &t, &pdf));
            CHECKF(fabs(pdf - rrv__equi_pdf(&eq, c, t)) <= 1e-9 * pdf, "centre %d: pdf %g at %g, density %g", k, pdf, t,
                   rrv__equi_pdf(&eq, c, t));
            bin = (int)floor((t - eq.a) / (eq.b - eq.a) * 8);
            ++count[bin < 0 ? 0 : bin > 7 ? 7 : bin];
        }
        for (i = 0; i < 8; ++i) {
            double expect = n * bin_p[i], z = (count[i] - expect) / sqrt(expect * (1 - bin_p[i]) + 1e-300);
            CHECKF(fabs(z) <= 4, "centre %d, piece %d: %ld draws, %g expected", k, i, count[i], expect);
            worst_z = fmax(worst_z, fabs(z));
        }
        printf("  centre %d: integral %.10f, worst |z| of the pieces %.2f\n", k, integral, worst_z);
    }
}

/* For a free flight's vertex and an equiangular sample at the same
   distance toward the same light, the three weights (light sample and
   phase sample at the vertex, the equiangular sample) sum to one; on a
   segment without equiangular samples the first two do. */
static void three_weights_sum_to_one(void)
{
    rrv_scene *s = load_fog("equiangular on");
    rrv__context ctx;
    uint64_t state = 7;
    double worst = 0;
    int i;
    if (!s) return;
    memset(&ctx, 0, sizeof ctx);
    ctx.scene = s;
    ctx.equiangular = 2;
    for (i = 0; i < 2000; ++i) {
        rrv__equi eq;
        const rrv_shape *light = &s->shapes[s->lights[i % s->light_count]];
        rrv_vec3 o = rrv__v3(-2.5 + 5 * uniform01(&state), 0.1 + 2.8 * uniform01(&state), -2.9);
        rrv_vec3 d = rrv__normalize(rrv__v3(uniform01(&state) - 0.5, uniform01(&state) - 0.5, 1.0));
        double p_light = 0.01 + 10 * uniform01(&state), p_phase = 0.01 + 10 * uniform01(&state), sum, p_eq, p_ff;
        rrv__equi_segment(&ctx, o, d, 1.0 + 4 * uniform01(&state), &eq);
        if (!eq.on) continue;
        eq.t = eq.a + (eq.b - eq.a) * uniform01(&state);
        p_eq = rrv__equi_pdf(&eq, rrv__light_centre(light), eq.t);
        p_ff = rrv__equi_free_flight(&ctx, &eq, eq.t);
        sum = rrv__equi_vertex_weight(&ctx, &eq, light, 1, p_light, p_phase, 0.0) +
              rrv__equi_vertex_weight(&ctx, &eq, light, 0, p_light, p_phase, 0.0) +
              rrv__equi_weight(p_eq * p_light, p_ff * p_light, p_ff * p_phase, p_eq * p_light);
        worst = fmax(worst, fabs(sum - 1));
        eq.on = 0;
        sum = rrv__equi_vertex_weight(&ctx, &eq, light, 1, p_light, p_phase, 0.0) +
              rrv__equi_vertex_weight(&ctx, &eq, light, 0, p_light, p_phase, 0.0);
        worst = fmax(worst, fabs(sum - 1));
    }
    CHECKF(worst < 1e-12, "weights sum to one within %g", worst);
    rrv_scene_free(s);
}

/* Block means of each channel over `batches` independent sample ranges:
   each 2 x 2 block's mean and standard error, [channel][block]. */
static void channel_blocks(rrv_scene *s, int batches, int spp, double mean[3][4], double se[3][4])
{
    int w = s->camera.width, h = s->camera.height, b, i, k, c;
    float *img = (float *)malloc(sizeof(float) * 3 * (size_t)w * (size_t)h);
    double sum[3][4] = {{0}}, sum2[3][4] = {{0}};
    for (b = 0; b < batches; ++b) {
        double block[3][4] = {{0}};
        memset(img, 0, sizeof(float) * 3 * (size_t)w * (size_t)h);
        CHECK(rrv_render_rect(s, 0, 0, w, h, b * spp, (b + 1) * spp, img, w, NULL, NULL) == RRV_OK);
        for (i = 0; i < w * h; ++i)
            for (c = 0; c < 3; ++c) block[c][(i / w) * 2 / h * 2 + (i % w) * 2 / w] += img[3 * i + c] / spp;
        for (c = 0; c < 3; ++c)
            for (k = 0; k < 4; ++k) {
                sum[c][k] += block[c][k];
                sum2[c][k] += block[c][k] * block[c][k];
            }
    }
    for (c = 0; c < 3; ++c)
        for (k = 0; k < 4; ++k) {
            mean[c][k] = sum[c][k] / batches;
            se[c][k] = sqrt(fmax(sum2[c][k] / batches - mean[c][k] * mean[c][k], 0.0) / (batches - 1));
        }
    free(img);
}

/* With equiangular samples and with free flights alone, the same blocks in
   every channel within 4 standard errors of their difference, each block
   known to 2 %; the two renders take different seeds, and the uniform light
   sampler the sample counts were sized for (test_lights.c compares the
   power sampler, equiangular samples included, with it). */
static void matches_free_flights_in_blocks(void)
{
    rrv_scene *on = load_fog("equiangular on lightsampler uniform seed 5"),
              *off = load_fog("equiangular off lightsampler uniform seed 6");
    double m0[3][4], s0[3][4], m1[3][4], s1[3][4], worst = 0, rel = 0;
    int k, channel;
    if (!on || !off) {
        rrv_scene_free(on);
        rrv_scene_free(off);
        return;
    }
    channel_blocks(off, 16, 160, m0, s0);
    channel_blocks(on, 16, 64, m1, s1);
    for (channel = 0; channel < 3; ++channel)
        for (k = 0; k < 4; ++k) {
            double z = (m1[channel][k] - m0[channel][k]) /
                       sqrt(s0[channel][k] * s0[channel][k] + s1[channel][k] * s1[channel][k]);
            CHECKF(fabs(z) <= 4.0, "channel %d block %d: %g +- %g equiangular, %g +- %g free flights (z = %.2f)", channel,
                   k, m1[channel][k], s1[channel][k], m0[channel][k], s0[channel][k], z);
            worst = fmax(worst, fabs(z));
            rel = fmax(rel, fmax(s0[channel][k] / m0[channel][k], s1[channel][k] / m1[channel][k]));
        }
    CHECKF(rel < 0.02, "the blocks' relative error %g is too large to see a bias", rel);
    printf("  worst |z| %.2f, blocks within %.2f%%\n", worst, 100 * rel);
    rrv_scene_free(on);
    rrv_scene_free(off);
}

/* What rrv_render_rect would set ctx.equiangular to for the scene text, or
   -1 if it does not parse (then e says why). */
static int equiangular_of(const char *text, rrv_error *e)
{
    rrv_scene *s = NULL;
    rrv__context ctx;
    rrv__camera_frame frame;
    int mode = -1;
    if (rrv_scene_parse(text, strlen(text), "out.rrv", ".", NULL, &s, e) != RRV_OK) return -1;
    if (rrv__render_context(s, &ctx, &frame, e) == RRV_OK) mode = ctx.equiangular;
    rrv__solver_release(&ctx);
    rrv_scene_free(s);
    return mode;
}

/* The default aims at lights inside a scattering medium's box only, and
   a scene without one renders as it did (no equiangular samples at all);
   the key's words and its error. */
static void default_and_keys(void)
{
    static const char *const outside =
        "camera eye 0 1 -4 look 0 1 0 up 0 1 0 fov 40 resolution 8 6\n"
        "render spp 1 %s\n"
        "quad origin -1 4 -1 u 2 0 0 v 0 0 2 L 5 5 5\n"
        "medium fog box -1 0 -1 1 2 1 sigma_a 0 0 0 sigma_s 1 1 1\n"
        "density fog constant 1\n";
    char text[2048];
    rrv_scene *s = load_fog("");
    rrv__context ctx;
    rrv_error e;
    if (s) {
        CHECK(s->settings.equiangular == RRV_EQUIANGULAR_DEFAULT);
        memset(&ctx, 0, sizeof ctx);
        ctx.scene = s;
        ctx.equiangular = 1;
        /* the sphere's centre lies in the fog's box, not in the smoke's */
        CHECK(rrv__equi_aims_at(&ctx, &s->shapes[s->lights[0]], &s->media[0]));
        CHECK(!rrv__equi_aims_at(&ctx, &s->shapes[s->lights[0]], &s->media[1]));
        rrv_scene_free(s);
    }
    snprintf(text, sizeof text, fog_lamps, "");
    CHECK(equiangular_of(text, &e) == 1);
    snprintf(text, sizeof text, outside, "");
    CHECK(equiangular_of(text, &e) == 0);
    snprintf(text, sizeof text, outside, "equiangular on");
    CHECK(equiangular_of(text, &e) == 2);
    snprintf(text, sizeof text, outside, "equiangular off");
    CHECK(equiangular_of(text, &e) == 0);
    snprintf(text, sizeof text, outside, "equiangular sometimes");
    CHECK(equiangular_of(text, &e) == -1);
    CHECKF(e.line == 2 && strstr(e.message, "equiangular") != NULL, "%d: %s", e.line, e.message);
}

int main(void)
{
    RUN(density_and_sampler_agree);
    RUN(three_weights_sum_to_one);
    RUN(matches_free_flights_in_blocks);
    RUN(default_and_keys);
    return CHECK_EXIT_CODE();
}
