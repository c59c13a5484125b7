/* Which light next-event estimation samples (render lightsampler): the
   pick's frequencies against the probabilities the estimators divide by,
   the sky's share, and renders with the power and the uniform sampler.
   Stochastic checks use fixed seeds and a bound of 4 standard errors. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "blocks.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A diffuse floor in thin smoke under a sky, lit by a quad, a sphere and a
   triangle of different powers. %s: more render keys. */
static const char *const lights_scene =
    "camera eye 0 1.2 -3 look 0 0.4 0 up 0 1 0 fov 40 resolution 12 8\n"
    "render spp 1 maxdepth 3 integrator classic %s\n"
    "environment gradient top 0.3 0.35 0.45 bottom 0.05 0.05 0.05\n"
    "material ground diffuse albedo 0.5 0.5 0.5\n"
    "quad origin -4 0 -4 u 0 0 8 v 8 0 0 material ground\n"
    "quad origin -0.8 2.0 -0.3 u 0.5 0 0 v 0 0 0.5 L 20 20 20\n"
    "sphere center 0.7 1.2 0.3 radius 0.1 L 60 50 40\n"
    "triangle p0 -1 1.5 1 p1 -0.8 1.9 1 p2 -0.6 1.5 1 L 5 6 8\n"
    "medium haze box -2 0 -2 2 1.5 2 sigma_a 0.1 0.1 0.1 sigma_s 0.5 0.5 0.5 g 0.3\n"
    "density haze constant 1\n";

static rrv_scene *lights_load(const char *text_format, const char *keys)
{
    char text[2048];
    rrv_scene *s = NULL;
    rrv_error e;
    snprintf(text, sizeof text, text_format, keys);
    if (rrv_scene_parse(text, strlen(text), "lights.rrv", ".", NULL, &s, &e) != RRV_OK) {
        CHECKF(0, "%s:%d: %s", e.file, e.line, e.message);
        return NULL;
    }
    return s;
}

/* The probabilities sum to one; under power each light shape's is its
   area times its mean radiance over the sum, the sky's 0; under uniform
   every choice's is 1 / choices; and 200,000 picks from evenly spread u
   fall on each choice as often as its probability says (within 4
   standard errors of a binomial count, the u a fixed-seed LCG's). */
static void picks_follow_the_probabilities(void)
{
    int mode;
    for (mode = 0; mode < 2; ++mode) {
        rrv_scene *s = lights_load(lights_scene, mode ? "lightsampler uniform" : "");
        int choices, i, n = 200000, count[8] = {0};
        double sum = 0, power = 0;
        uint64_t state = 12345;
        if (!s) return;
        choices = rrv__light_choices(s);
        CHECK(choices == 4 && s->light_count == 3);
        for (i = 0; i < s->light_count; ++i) {
            const rrv_shape *l = &s->shapes[s->lights[i]];
            power += rrv__shape_area(l) * (l->L[0] + l->L[1] + l->L[2]) / 3.0;
        }
        for (i = 0; i < choices; ++i) {
            const rrv_shape *l = i < s->light_count ? &s->shapes[s->lights[i]] : NULL;
            double p = rrv__light_prob(s, l, 0.0), want;
            if (mode) want = 1.0 / choices;
            else want = l ? rrv__shape_area(l) * (l->L[0] + l->L[1] + l->L[2]) / 3.0 / power : 0.0;
            CHECKF(fabs(p - want) <= 1e-12 * want, "mode %d choice %d: probability %.17g, expected %.17g", mode, i, p,
                   want);
            sum += p;
        }
        CHECKF(fabs(sum - 1) < 1e-12, "mode %d: probabilities sum to %.17g", mode, sum);
        for (i = 0; i < n; ++i) {
            rrv__light_draw draw = {0, 0, 0, 0};
            int pick;
            state = state * 6364136223846793005ULL + 1442695040888963407ULL;
            draw.u = (double)(state >> 11) * (1.0 / 9007199254740992.0);
            draw.u1 = draw.u2 = 0.5;
            pick = rrv__light_pick(s, &draw);
            CHECK(pick >= 0 && pick < choices);
            if (pick >= 0 && pick < choices) ++count[pick];
        }
        for (i = 0; i < choices; ++i) {
            double p = rrv__light_prob(s, i < s->light_count ? &s->shapes[s->lights[i]] : NULL, 0.0);
            double sd = sqrt(n * p * (1 - p)), z = sd > 0 ? (count[i] - n * p) / sd : count[i] - n * p;
            CHECKF(fabs(z) <= 4.0, "mode %d choice %d: %d picks of %d, probability %g (z = %.2f)", mode, i, count[i], n,
                   p, z);
        }
        rrv_scene_free(s);
    }
}

/* The solid angle light shape l subtends from x: on a sphere exactly, on a
   quad or triangle by the midpoint rule on a 400 x 400 grid of its
   parameters (cosine at the light over squared distance, 0 where the
   light faces away: quads and triangles emit on the side of e1 x e2). */
static double lights_solid_angle(const rrv_shape *l, rrv_vec3 x)
{
    const int n = 400;
    double sum = 0;
    int i, j;
    if (l->kind == RRV_SHAPE_SPHERE) {
        rrv_vec3 c = rrv__sub(l->center, x);
        double sin2 = l->radius * l->radius / rrv__dot(c, c);
        return 2.0 * RRV__PI * (1.0 - sqrt(1.0 - sin2));
    }
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) {
            double a = (i + 0.5) / n, b = (j + 0.5) / n, area = rrv__length(rrv__cross(l->e1, l->e2)) / ((double)n * n);
            rrv_vec3 q, d, nq = rrv__normalize(rrv__cross(l->e1, l->e2));
            double r2;
            if (l->kind == RRV_SHAPE_TRIANGLE && a + b > 1) continue;
            q = rrv__madd(rrv__madd(l->p0, l->e1, a), l->e2, b);
            d = rrv__sub(q, x);
            r2 = rrv__dot(d, d);
            sum += area * fmax(-rrv__dot(nq, d), 0.0) / (sqrt(r2) * r2);
        }
    return sum;
}

/* The light sample's density, selection included, is the one its draws
   follow: over many draws the mean of [the draw names light i] / pdf is
   the solid angle light i subtends (within 4 standard errors), under
   both samplers, and the sky's 4 pi where it is sampled. */
static void densities_integrate_to_solid_angles(void)
{
    int mode;
    for (mode = 0; mode < 2; ++mode) {
        rrv_scene *s = lights_load(lights_scene, mode ? "lightsampler uniform" : "");
        rrv_vec3 x = rrv__v3(0, 0.5, 0);
        int choices, i, k, n = 400000;
        double sum[4] = {0}, sum2[4] = {0};
        uint64_t state = 777;
        if (!s) return;
        choices = rrv__light_choices(s);
        for (k = 0; k < n; ++k) {
            rrv__light_draw draw = {0, 0, 0, 0};
            rrv__light_sample ls;
            double *u[3];
            int pick;
            u[0] = &draw.u, u[1] = &draw.u1, u[2] = &draw.u2;
            for (i = 0; i < 3; ++i) {
                state = state * 6364136223846793005ULL + 1442695040888963407ULL;
                *u[i] = (double)(state >> 11) * (1.0 / 9007199254740992.0);
            }
            pick = rrv__light_pick(s, &draw);
            if (pick < 0 || !rrv__sample_light(s, x, &draw, &ls) || !(ls.pdf > 0)) continue;
            sum[pick] += 1.0 / ls.pdf;
            sum2[pick] += 1.0 / (ls.pdf * ls.pdf);
        }
        for (i = 0; i < choices; ++i) {
            double want = i < s->light_count ? lights_solid_angle(&s->shapes[s->lights[i]], x)
                                             : (rrv__light_prob(s, NULL, 0.0) > 0 ? 4.0 * RRV__PI : 0.0);
            double mean = sum[i] / n, se = sqrt(fmax(sum2[i] / n - mean * mean, 0.0) / (n - 1));
            CHECKF(fabs(mean - want) <= 4.0 * se + 1e-12, "mode %d choice %d: %g +- %g, solid angle %g", mode, i, mean,
                   se, want);
        }
        rrv_scene_free(s);
    }
}

/* A sky alone is still sampled (all of it, by scattering vertices), and
   the light sample's density is the same the path's weight divides by. */
static void a_sky_alone_is_sampled(void)
{
    static const char *const sky_only = "camera eye 0 1 -3 look 0 0 0 up 0 1 0 fov 40 resolution 4 4\n"
                                        "render spp 1 %s\n"
                                        "environment constant L 0.3 0.3 0.3\n"
                                        "material ground diffuse albedo 0.5 0.5 0.5\n"
                                        "quad origin -4 0 -4 u 0 0 8 v 8 0 0 material ground\n";
    rrv_scene *s = lights_load(sky_only, "");
    rrv__light_draw draw = {0.7, 0.3, 0.6, 0};
    rrv__light_sample ls;
    if (!s) return;
    CHECK(rrv__light_choices(s) == 1);
    CHECK(rrv__light_prob(s, NULL, 0.0) == 1.0);
    CHECK(rrv__light_pick(s, &draw) == 0);
    CHECK(rrv__sample_light(s, rrv__v3(0, 0.5, 0), &draw, &ls) && ls.dist == DBL_MAX);
    CHECKF(fabs(ls.pdf - RRV__INV_4PI) < 1e-15, "pdf %.17g", ls.pdf);
    rrv_scene_free(s);
}

/* The blocks of two renders of one scene, by the power and by the uniform
   sampler, within 4 standard errors of their difference, each block known
   to 1.5 %; frees both (either may be NULL, a scene that did not load). */
static void power_against_uniform(rrv_scene *power, rrv_scene *uniform, int spp, const char *name)
{
    double m0[BW * BH], s0[BW * BH], m1[BW * BH], s1[BW * BH], worst = 0, rel = 0;
    int k;
    if (power && uniform) {
        block_stats(uniform, 16, spp, m0, s0);
        block_stats(power, 16, spp, m1, s1);
        for (k = 0; k < BW * BH; ++k) {
            double z = (m1[k] - m0[k]) / sqrt(s0[k] * s0[k] + s1[k] * s1[k]);
            CHECKF(fabs(z) <= 4.0, "%s block %d: %g +- %g power, %g +- %g uniform (z = %.2f)", name ? name : "", k,
                   m1[k], s1[k], m0[k], s0[k], z);
            worst = fmax(worst, fabs(z));
            rel = fmax(rel, fmax(s0[k] / m0[k], s1[k] / m1[k]));
        }
        CHECKF(rel < 0.015, "the blocks' relative error %g is too large to see a bias", rel);
        printf("  %s%sworst |z| %.2f, blocks within %.2f%%\n", name ? name : "", name ? ": " : "", worst, 100 * rel);
    }
    rrv_scene_free(power);
    rrv_scene_free(uniform);
}

/* A sky alone (no light shape, no emitter): a diffuse surface draws
   nothing (rrv__sky_alone) and its cosine lobe finds the sky with weight
   one, so a floor open to a constant sky renders exactly albedo x L in
   every sample; under the uniform sampler, or beside a light shape, the
   rule is off. */
static void a_sky_alone_leaves_surfaces_to_their_lobe(void)
{
    static const char *const sky_only = "camera eye 0 1 -3 look 0 0 0 up 0 1 0 fov 40 resolution 8 8\n"
                                        "render spp 1 maxdepth 1 %s\n"
                                        "environment constant L 0.3 0.3 0.3\n"
                                        "material ground diffuse albedo 0.5 0.5 0.5\n"
                                        "quad origin -40 0 -40 u 0 0 80 v 80 0 0 material ground\n";
    rrv_scene *s = lights_load(sky_only, ""), *u = lights_load(sky_only, "lightsampler uniform");
    rrv_scene *lit = lights_load(sky_only, "\nsphere center 0 3 0 radius 0.1 L 5 5 5");
    float img[8 * 8 * 3];
    int i, exact = 0;
    double worst = 0;
    if (s && u && lit) {
        CHECK(rrv__sky_alone(s) && !rrv__sky_alone(u) && !rrv__sky_alone(lit));
        memset(img, 0, sizeof img);
        CHECK(rrv_render_rect(s, 0, 0, 8, 8, 0, 16, img, 8, NULL, NULL) == RRV_OK);
        /* the lower half sees the floor only */
        for (i = 8 * 4 * 3; i < 8 * 8 * 3; ++i) {
            double e = fabs(img[i] / 16.0 - 0.15);
            worst = fmax(worst, e);
            exact += e <= 1e-6;
        }
        CHECKF(exact == 8 * 4 * 3, "%d of 96 floor values exact, worst off by %g", exact, worst);
        printf("  the floor's pixels within %.1e of albedo x sky\n", worst);
    }
    rrv_scene_free(s);
    rrv_scene_free(u);
    rrv_scene_free(lit);
}

/* Under a sky alone, a floor and a wall (which hide part of it from each
   other) in fog (whose vertices still draw the sky), classic and through
   hot air: the power sampler (surfaces leave the sky to their lobe) and
   the uniform one (every vertex draws it) render the same blocks within
   4 standard errors of their difference. */
static void a_sky_alone_matches_uniform_in_blocks(void)
{
    static const char *const sky_room =
        "camera eye 0 1.2 -3 look 0 0.6 0 up 0 1 0 fov 45 resolution 12 8\n"
        "render spp 1 maxdepth 4 integrator %s %s\n"
        "environment gradient top 0.4 0.45 0.6 bottom 0.05 0.05 0.05\n"
        "material ground diffuse albedo 0.5 0.5 0.5\n"
        "quad origin -4 0 -4 u 0 0 8 v 8 0 0 material ground\n"
        "quad origin -4 0 1 u 8 0 0 v 0 3 0 material ground\n"
        "medium fog box -1 0 -1 1 1.2 0.5 sigma_a 0.1 0.1 0.1 sigma_s 0.6 0.6 0.6 g 0.3\n"
        "density fog constant 1\n"
        "%s";
    static const char *const hot =
        "medium air box -1.5 0.2 -1.5 1.5 2.5 0.9 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature air blob center 0 1 -0.2 radius 0.4 weight 300 base 300\n"
        "ior air gas iorscale 100\n";
    int variant;
    for (variant = 0; variant < 2; ++variant) {
        char format[2048];
        rrv_scene *power, *uniform;
        /* the render line's keys stay to fill */
        snprintf(format, sizeof format, sky_room, variant ? "refractive" : "classic", "%s", variant ? hot : "");
        power = lights_load(format, "seed 4");
        uniform = lights_load(format, "lightsampler uniform seed 5");
        if (power && uniform) CHECK(rrv__sky_alone(power) && !rrv__sky_alone(uniform));
        power_against_uniform(power, uniform, 64, variant ? "refractive, hot air" : "classic");
    }
}

/* The power sampler (no sky samples beside the light shapes) and the
   uniform one render the same blocks within 4 standard errors of their
   difference, each block known to 1.5 %; different seeds. */
static void power_matches_uniform_in_blocks(void)
{
    power_against_uniform(lights_load(lights_scene, "seed 3"), lights_load(lights_scene, "lightsampler uniform seed 4"),
                          480, NULL);
}

/* The pick and the densities are those the scene was prepared with: a
   sampler changed in the settings since moves neither (they would
   disagree, and the estimate be biased, if one followed the setting and
   the other the prepared table), and preparing again takes it up. */
static void prepared_sampler_holds(void)
{
    rrv_scene *s = lights_load(lights_scene, "");
    rrv__light_draw draw = {0.3, 0.5, 0.5, 0};
    double p0, p1;
    rrv_error e;
    int pick;
    if (!s) return;
    p0 = rrv__light_prob(s, &s->shapes[s->lights[0]], 0.0);
    pick = rrv__light_pick(s, &draw);
    s->settings.light_sampler = RRV_LIGHT_SAMPLER_UNIFORM;
    CHECK(rrv__light_prob(s, &s->shapes[s->lights[0]], 0.0) == p0 && rrv__light_pick(s, &draw) == pick);
    CHECK(rrv__light_prob(s, NULL, 0.0) == 0.0);
    CHECK(rrv_scene_prepare(s, &e) == RRV_OK);
    p1 = rrv__light_prob(s, &s->shapes[s->lights[0]], 0.0);
    CHECKF(p1 == 0.25 && rrv__light_prob(s, NULL, 0.0) == 0.25, "after prepare: %g, sky %g", p1, rrv__light_prob(s, NULL, 0.0));
    rrv_scene_free(s);
}

/* The key's default, its words and its error. */
static void lights_default_and_keys(void)
{
    rrv_scene *s = lights_load(lights_scene, "");
    rrv_error e;
    char text[2048];
    if (s) {
        CHECK(s->settings.light_sampler == RRV_LIGHT_SAMPLER_POWER);
        rrv_scene_free(s);
    }
    s = lights_load(lights_scene, "lightsampler power");
    if (s) {
        CHECK(s->settings.light_sampler == RRV_LIGHT_SAMPLER_POWER);
        rrv_scene_free(s);
    }
    snprintf(text, sizeof text, lights_scene, "lightsampler bvh");
    s = NULL;
    CHECK(rrv_scene_parse(text, strlen(text), "lights.rrv", ".", NULL, &s, &e) != RRV_OK);
    CHECKF(e.line == 2 && strstr(e.message, "lightsampler") != NULL, "%d: %s", e.line, e.message);
    rrv_scene_free(s);
}

int main(void)
{
    RUN(picks_follow_the_probabilities);
    RUN(densities_integrate_to_solid_angles);
    RUN(a_sky_alone_is_sampled);
    RUN(a_sky_alone_leaves_surfaces_to_their_lobe);
    RUN(a_sky_alone_matches_uniform_in_blocks);
    RUN(power_matches_uniform_in_blocks);
    RUN(prepared_sampler_holds);
    RUN(lights_default_and_keys);
    return CHECK_EXIT_CODE();
}
