/* Emissive media as lights (render emissionnee) and the NanoVDB cell-centred
   placement (nanovdb ... cellcentered on). Stochastic checks use fixed
   seeds and a bound of 4 standard errors. Run from the repository root. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A flame (scenes/fire.rrv's soot, fewer tongues) beside a diffuse wall and
   floor, no other light: test/bench/campfire.rrv, small. */
static const char *const campfire =
    "camera eye 1.2 1.1 -4.2 look 0.2 0.55 0.6 up 0 1 0 fov 45 resolution 24 18\n"
    "render spp 1 maxdepth 2 seed 1 integrator %s %s\n"
    "material wall diffuse albedo 0.7 0.7 0.68\n"
    "material ground diffuse albedo 0.5 0.48 0.45\n"
    "quad origin -5 0 1.2 u 10 0 0 v 0 5 0 material wall\n"
    "quad origin -5 0 -6 u 0 0 7.2 v 10 0 0 material ground\n"
    "medium flame box -0.6 0 -0.6 0.6 1.3 0.6 sigma_a 4 4 4 sigma_s 0.2 0.2 0.2 Lescale 14\n"
    "density flame blob center 0 0.1 0 radius 0.17 weight 1.5\n"
    "density flame blob center 0.1 0.28 0.04 radius 0.12 weight 1.3\n"
    "density flame blob center -0.11 0.27 -0.03 radius 0.12 weight 1.3\n"
    "density flame blob center 0 0.42 0 radius 0.11 weight 1.3\n"
    "density flame blob center 0.04 0.78 0 radius 0.055 weight 1\n"
    "temperature flame blob center 0 0.4 0 radius 0.75 weight 2500 base 0 blackbody on\n"
    "%s";

static rrv_scene *load(const char *fmt, const char *a, const char *b, const char *c)
{
    char text[4096];
    rrv_scene *s = NULL;
    rrv_error e;
    snprintf(text, sizeof text, fmt, a, b, c);
    if (rrv_scene_parse(text, strlen(text), "emission.rrv", ".", NULL, &s, &e) != RRV_OK) {
        CHECKF(0, "%s:%d: %s", e.file, e.line, e.message);
        return NULL;
    }
    return s;
}

/* A context as rrv_render_rect sets one up for these scenes. */
static void context_for(const rrv_scene *s, rrv__context *ctx, int bends)
{
    memset(ctx, 0, sizeof *ctx);
    ctx->scene = s;
    ctx->bends = bends;
    ctx->sample_lights = 1;
    ctx->emission = 1;
    ctx->eta_camera2 = 1;
    ctx->thermal_scale = 1;
}

/* At sampled points the two MIS weights of every connection sum to one,
   each side computing its own: the sample's weight from the density it
   drew with, the forward path's from its lookup of the same point. The
   density is one: over uniform points of the box E[p(y)] volume = 1. And
   the sampler draws by it: each cluster of cells as often as the density
   the lookup gives it (within 4 standard errors of the binomial count). */
static void weights_sum_to_one(void)
{
    rrv_scene *s = load(campfire, "classic", "", "");
    const struct rrv__emitters *e;
    rrv__context ctx;
    rrv__rng rng;
    int i, bad = 0, vertex, count = 0;
    if (!s) return;
    CHECK(s->emitters != NULL);
    if (!s->emitters) { rrv_scene_free(s); return; }
    e = s->emitters;
    CHECK(e->count == 1 && e->clusters == 64 && e->clusters <= 64);
    context_for(s, &ctx, 0);
    rrv__rng_seed(&rng, 11, 12, 13);
    for (vertex = 0; vertex < 2; ++vertex) {
        double sum = 0, sum2 = 0, mean, se, box;
        int hits[64] = {0}, c;
        double share[64], q[RRV__EMIT_KEEP];
        rrv__vertex_bsdf v;
        rrv__path path;
        rrv_vec3 x, lo = s->media[0].lo, ext = rrv__sub(s->media[0].hi, s->media[0].lo);
        const int n = 200000;
        memset(&v, 0, sizeof v);
        memset(&path, 0, sizeof path);
        if (vertex == 0) {
            /* on the floor beside the flame */
            v.surface = 1;
            v.n = rrv__v3(0, 1, 0);
            x = rrv__v3(0.9, 1e-6, -0.4);
        } else {
            /* scattering inside it */
            v.g = 0.3;
            v.d_in = rrv__normalize(rrv__v3(0.2, 1, -0.1));
            x = rrv__v3(0.05, 0.35, 0.02);
        }
        rrv__emission_from_vertex(&ctx, &path.emit, x, &v, vertex ? NULL : q);
        for (i = 0; i < n; ++i) {
            double u[5], p_nee, p_fwd, pdf_dir, r, w_nee, w_fwd;
            rrv__coeffs cf;
            rrv_vec3 y;
            int mi, k, idx[3];
            const rrv__emitter_grid *g = &e->grid[0];
            for (k = 0; k < 5; ++k) u[k] = rrv__uniform(&rng);
            mi = rrv__emitter_sample(e, &path.emit, vertex ? NULL : q, u, &y);
            if (mi < 0) { CHECK(mi >= 0); break; }
            /* its cluster, from the cell it lies in */
            for (k = 0; k < 3; ++k) {
                idx[k] = (int)((rrv__axis(y, k) - rrv__axis(lo, k)) / rrv__axis(g->cell, k));
                if (idx[k] > g->n[k] - 1) idx[k] = g->n[k] - 1;
                idx[k] /= RRV__EMIT_BLOCK;
            }
            ++hits[(idx[2] * g->nc[1] + idx[1]) * g->nc[0] + idx[0]];
            rrv__medium_coeffs(&s->media[mi], y, &cf);
            if (!rrv__emission_densities(&ctx, &path.emit, mi, y, &cf, &p_nee, &p_fwd, &pdf_dir, &r)) continue;
            ++count;
            w_nee = rrv__emission_mis(p_nee, p_fwd);
            w_fwd = rrv__emission_forward_weight(&ctx, &path, &s->media[mi], y, &cf);
            if (!(fabs(w_nee + w_fwd - 1.0) <= 1e-12) && bad++ < 3)
                CHECKF(0, "at %g %g %g: w_nee %.17g + w_fwd %.17g", y.x, y.y, y.z, w_nee, w_fwd);
        }
        {
            /* each cluster's probability from the lookup, which is constant in a cell */
            const rrv__emitter_grid *g = &e->grid[0];
            int ix, iy, iz;
            for (c = 0; c < 64; ++c) share[c] = 0;
            for (iz = 0; iz < g->n[2]; ++iz)
                for (iy = 0; iy < g->n[1]; ++iy)
                    for (ix = 0; ix < g->n[0]; ++ix) {
                        rrv_vec3 y = rrv__v3(lo.x + (ix + 0.5) * g->cell.x, lo.y + (iy + 0.5) * g->cell.y,
                                             lo.z + (iz + 0.5) * g->cell.z);
                        share[((iz / RRV__EMIT_BLOCK) * g->nc[1] + iy / RRV__EMIT_BLOCK) * g->nc[0] + ix / RRV__EMIT_BLOCK] +=
                            rrv__emission_pdf(e, 0, &path.emit, y) / g->inv_volume;
                    }
        }
        for (c = 0; c < 64; ++c) {
            double P = share[c];
            double sd = sqrt(n * P * (1 - P));
            CHECKF(fabs(hits[c] - n * P) <= 4 * sd + 1e-9, "vertex %d cluster %d: %d draws, expected %g +- %g",
                   vertex, c, hits[c], n * P, sd);
        }
        box = ext.x * ext.y * ext.z;
        for (i = 0; i < n; ++i) {
            rrv_vec3 y = rrv__v3(lo.x + ext.x * rrv__uniform(&rng), lo.y + ext.y * rrv__uniform(&rng),
                                 lo.z + ext.z * rrv__uniform(&rng));
            double p = rrv__emission_pdf(e, 0, &path.emit, y) * box;
            sum += p;
            sum2 += p * p;
        }
        mean = sum / n;
        se = sqrt((sum2 / n - mean * mean) / n);
        CHECKF(fabs(mean - 1.0) <= 4 * se, "vertex %d: the density integrates to %g +- %g", vertex, mean, se);
    }
    CHECK(bad == 0);
    CHECK(count > 100000);
    {
        /* a vertex scattering inside the emitter's box samples nothing and
           leaves the path's next emission at weight 1, not at the weight of
           the vertex before it */
        rrv__vertex_bsdf v;
        rrv__path path;
        rrv__coeffs cf;
        rrv_vec3 y = rrv__v3(0.0, 0.2, 0.0);
        memset(&v, 0, sizeof v);
        memset(&path, 0, sizeof path);
        v.surface = 1;
        v.n = rrv__v3(0, 1, 0);
        rrv__emission_from_vertex(&ctx, &path.emit, rrv__v3(0.9, 1e-6, -0.4), &v, NULL);
        rrv__medium_coeffs(&s->media[0], y, &cf);
        CHECK(rrv__emission_forward_weight(&ctx, &path, &s->media[0], y, &cf) < 1.0);
        v.surface = 0;
        v.d_in = rrv__v3(0, 1, 0);
        rrv__emission_nee(&ctx, &path, rrv__v3(0.05, 0.35, 0.02), &v, &rng);
        CHECK(path.emit.on == 0);
        CHECK(rrv__emission_forward_weight(&ctx, &path, &s->media[0], y, &cf) == 1.0);
    }
    rrv_scene_free(s);
}

/* The density the forward paths and the aim read (rrv__emission_pdf) is the
   one the sampler draws by, two levels of clusters and all. From surface
   and medium vertices, some whose plane cuts the flame (super-clusters
   partly behind it), of the campfire and of it with a second emitter whose
   grid splits unevenly into clusters and super-clusters: the sum of the
   density over every cell (times the cell's volume) is, to rounding
   (1e-12), the probability that the sampler picks anything (short of 1 by
   the super-clusters whose clusters of weight all lie behind a surface),
   and here 1 (every cluster has weight, so a super-cluster in front has a
   cluster in front); each cluster is drawn, and nothing is drawn, as
   often as those masses say (within 4 standard errors of the binomial
   count, plus 2 draws), and so are the cells expected 5 times or more
   (Pearson's X^2 within 4 standard deviations of its chi^2). The density is the same read before and after the
   sampler keeps a super-cluster's norm. */
static void density_matches_the_sampler(void)
{
    static const char *const ember =
        "medium ember box 1.0 0 -1.6 1.75 0.3 -0.6 sigma_a 2 2 2 sigma_s 0 0 0 Le 1 0.5 0.2 Lescale 3\n"
        "density ember blob center 1.3 0.1 -1.2 radius 0.2 weight 1\n"
        "density ember blob center 1.6 0.15 -0.8 radius 0.15 weight 0.6\n";
    int scene;
    for (scene = 0; scene < 2; ++scene) {
        rrv_scene *s = load(campfire, "classic", "", scene ? ember : "");
        const struct rrv__emitters *e;
        rrv__context ctx;
        rrv__rng rng;
        rrv__path path;
        int vertex, worst_cluster = -1, cells_checked = 0;
        double worst = 0, worst_cell = 0;
        if (!s) return;
        /* one path for every vertex: what it keeps of one must not leak
           into the next */
        memset(&path, 0, sizeof path);
        e = s->emitters;
        CHECK(e != NULL && e->count == 1 + scene);
        if (!e || e->count != 1 + scene) { rrv_scene_free(s); return; }
        /* the ember's 24 x 10 x 32 cells: 3 x 2 x 4 clusters, 2 x 1 x 2 super-clusters */
        if (scene) CHECK(e->clusters == 64 + 24 && e->supers == 8 + 4 && e->grid[1].ns[0] == 2 && e->grid[1].ns[1] == 1);
        context_for(s, &ctx, 0);
        rrv__rng_seed(&rng, 31, 32, 33 + scene);
        for (vertex = 0; vertex < 7; ++vertex) {
            rrv__vertex_bsdf v;
            rrv_vec3 x;
            const int n = 100000;
            double *mass = (double *)calloc((size_t)e->clusters, sizeof *mass), total = 0, expected = 0;
            int *hits = (int *)calloc((size_t)e->clusters, sizeof *hits), none = 0, i, c, k, grid;
            double *cell_mass = (double *)calloc(e->cells, sizeof *cell_mass);
            int *cell_hits = (int *)calloc(e->cells, sizeof *cell_hits);
            size_t cell;
            if (!mass || !hits || !cell_mass || !cell_hits) {
                free(mass); free(hits); free(cell_mass); free(cell_hits);
                CHECK(0);
                break;
            }
            memset(&v, 0, sizeof v);
            v.surface = vertex < 4 || vertex == 6;
            switch (vertex) {
            case 0: /* the floor beside the flame */
                v.n = rrv__v3(0, 1, 0); x = rrv__v3(0.9, 1e-6, -0.4); break;
            case 1: /* the wall behind it */
                v.n = rrv__v3(0, 0, -1); x = rrv__v3(0.2, 0.8, 1.2 - 1e-6); break;
            case 2: /* a surface whose plane cuts the flame through its middle */
                v.n = rrv__normalize(rrv__v3(-1, 0.3, 0.2)); x = rrv__v3(0.05, 0.7, 0.1); break;
            case 3: /* and one that sees little of it */
                v.n = rrv__normalize(rrv__v3(0.3, -1, 0.1)); x = rrv__v3(-0.4, 1.25, -0.5); break;
            case 4: /* scattering in the air beside the flame */
                v.g = 0.3; v.d_in = rrv__normalize(rrv__v3(0.2, 1, -0.1)); x = rrv__v3(-0.9, 0.3, 0.2); break;
            case 5: /* and inside its box */
                v.g = -0.2; v.d_in = rrv__normalize(rrv__v3(1, 0, 0.3)); x = rrv__v3(0.05, 0.35, 0.02); break;
            default: /* facing away from the flame's part x < 0.04, whose
                        super-clusters' bounding spheres reach in front of
                        the surface while all their clusters lie behind it */
                v.n = rrv__v3(1, 0, 0); x = rrv__v3(0.22, 0.33, -0.3); break;
            }
            rrv__emission_from_vertex(&ctx, &path.emit, x, &v, NULL);
            /* the density's mass per cluster, summed over the cells (the
               density is constant in a cell), before any draw */
            for (grid = 0; grid < e->count; ++grid) {
                const rrv__emitter_grid *g = &e->grid[grid];
                int ix, iy, iz;
                for (iz = 0; iz < g->n[2]; ++iz)
                    for (iy = 0; iy < g->n[1]; ++iy)
                        for (ix = 0; ix < g->n[0]; ++ix) {
                            rrv_vec3 y = rrv__v3(g->lo.x + (ix + 0.5) * g->cell.x, g->lo.y + (iy + 0.5) * g->cell.y,
                                                 g->lo.z + (iz + 0.5) * g->cell.z);
                            c = g->first_cluster + ((iz / RRV__EMIT_BLOCK) * g->nc[1] + iy / RRV__EMIT_BLOCK) * g->nc[0] +
                                ix / RRV__EMIT_BLOCK;
                            cell = g->first + ((size_t)iz * (size_t)g->n[1] + (size_t)iy) * (size_t)g->n[0] + (size_t)ix;
                            cell_mass[cell] = rrv__emission_pdf(e, g->medium, &path.emit, y) / g->inv_volume;
                            mass[c] += cell_mass[cell];
                        }
            }
            for (c = 0; c < e->clusters; ++c) total += mass[c];
            /* what the sampler can pick: each super-cluster's share unless
               all its clusters are behind the surface */
            for (c = 0; c < e->supers; ++c) {
                const rrv__emit_cluster *sc = &e->super[c];
                size_t m;
                double front = 0;
                for (m = sc->begin; m < sc->end; ++m) front += rrv__emit_cluster_g(&e->cluster[e->member[m]], &path.emit);
                if (sc->weight > 0 && front > 0) expected += sc->weight * rrv__emit_cluster_g(sc, &path.emit);
            }
            expected /= path.emit.S;
            CHECKF(fabs(total - expected) <= 1e-12, "scene %d vertex %d: the density sums to %.17g, draws %.17g",
                   scene, vertex, total, expected);
            CHECKF(fabs(total - 1.0) <= 1e-12, "scene %d vertex %d: the density sums to %.17g", scene, vertex, total);
            for (i = 0; i < n; ++i) {
                double u[5], p_before, p_after;
                rrv_vec3 y;
                int mi, idx[3];
                const rrv__emitter_grid *g;
                for (k = 0; k < 5; ++k) u[k] = rrv__uniform(&rng);
                if (i % 1000 == 999) path.emit.known = 0;
                mi = rrv__emitter_sample(e, &path.emit, NULL, u, &y);
                if (mi < 0) { ++none; continue; }
                g = &e->grid[e->of_medium[mi]];
                for (k = 0; k < 3; ++k) {
                    idx[k] = (int)((rrv__axis(y, k) - rrv__axis(g->lo, k)) / rrv__axis(g->cell, k));
                    if (idx[k] > g->n[k] - 1) idx[k] = g->n[k] - 1;
                }
                ++cell_hits[g->first + ((size_t)idx[2] * (size_t)g->n[1] + (size_t)idx[1]) * (size_t)g->n[0] +
                            (size_t)idx[0]];
                for (k = 0; k < 3; ++k) idx[k] /= RRV__EMIT_BLOCK;
                ++hits[g->first_cluster + (idx[2] * g->nc[1] + idx[1]) * g->nc[0] + idx[0]];
                if (i < 2000) {
                    /* the kept norm is the norm */
                    p_after = rrv__emission_pdf(e, mi, &path.emit, y);
                    path.emit.known = 0;
                    p_before = rrv__emission_pdf(e, mi, &path.emit, y);
                    CHECKF(p_before == p_after && p_before > 0, "scene %d vertex %d: density %.17g, kept %.17g",
                           scene, vertex, p_before, p_after);
                    if (p_before != p_after) break;
                }
            }
            for (c = 0; c <= e->clusters; ++c) {
                double P = c < e->clusters ? mass[c] : fmax(1.0 - total, 0.0);
                int got = c < e->clusters ? hits[c] : none;
                /* 2 draws more for the counts near 0 the normal misjudges */
                double sd = sqrt(n * P * (1 - P)), z = (fabs(got - n * P) - 2.0) / (sd > 0 ? sd : 1e-300);
                CHECKF(z <= 4.0, "scene %d vertex %d %s %d: %d draws, expected %g +- %g", scene, vertex,
                       c < e->clusters ? "cluster" : "nothing", c, got, n * P, sd);
                if (z > worst) { worst = z; worst_cluster = c; }
            }
            {
                /* and the cells the sampler should pick at least 5 times in
                   n: Pearson's X^2 over them, about chi^2 with as many
                   degrees of freedom (mean k, standard deviation sqrt(2k)) */
                double X2 = 0, z;
                int cells_in = 0;
                for (cell = 0; cell < e->cells; ++cell) {
                    double expect = n * cell_mass[cell];
                    if (!(expect >= 5.0)) continue;
                    ++cells_in;
                    X2 += (cell_hits[cell] - expect) * (cell_hits[cell] - expect) / expect;
                }
                z = (X2 - cells_in) / sqrt(2.0 * cells_in);
                CHECKF(cells_in > 100 && z <= 4.0, "scene %d vertex %d: X^2 %g over %d cells", scene, vertex, X2,
                       cells_in);
                if (z > worst_cell) worst_cell = z;
                cells_checked += cells_in;
            }
            free(mass);
            free(hits);
            free(cell_mass);
            free(cell_hits);
        }
        printf("  scene %d: worst |z| %.2f (cluster %d); cells (%d): worst X^2 z %.2f\n", scene, worst, worst_cluster,
               cells_checked, worst_cell);
        rrv_scene_free(s);
    }
}

/* The aim's density of directions (rrv__emission_dir_density) is the
   density of the directions to the sampled points whose chords meet
   refracting air: over the sphere it integrates to the share of samples
   whose chords do (a box of hot air over part of the flame, from a floor
   point and from a point in the air beside the flame). Both sides by
   Monte Carlo, within 4 standard errors of their difference. */
static void aim_density_integrates_to_its_share(void)
{
    static const char *const haze =
        "medium haze box -1.3 0.5 -1.0 1.3 3.4 1.0 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature haze noise octaves 2 frequency 2.5 seed 5 falloff plume center 0 1.5 0 radius 0.9 "
        "amplitude 600 base 0 temperatureoffset -300 blackbody off\n"
        "ior haze gas iorscale 300\n"
        "ambient ior 1.0876\n";
    rrv_scene *s = load(campfire, "refractive", "", haze);
    rrv__context ctx;
    rrv__rng rng;
    int vertex;
    if (!s) return;
    context_for(s, &ctx, 1);
    rrv__rng_seed(&rng, 21, 22, 23);
    for (vertex = 0; vertex < 2; ++vertex) {
        rrv__vertex_bsdf v;
        rrv__path path;
        const int n = 200000;
        double share, share_se, sum = 0, sum2 = 0, mean, se, z;
        int i, met = 0;
        memset(&v, 0, sizeof v);
        memset(&path, 0, sizeof path);
        if (vertex == 0) {
            v.surface = 1;
            v.n = rrv__v3(0, 1, 0);
            rrv__emission_from_vertex(&ctx, &path.emit, rrv__v3(0.9, 1e-6, -0.4), &v, NULL);
        } else {
            v.g = 0.3;
            v.d_in = rrv__v3(0, 1, 0);
            rrv__emission_from_vertex(&ctx, &path.emit, rrv__v3(-0.9, 0.3, 0.2), &v, NULL);
        }
        for (i = 0; i < n; ++i) {
            double u[5];
            rrv_vec3 y;
            int k;
            for (k = 0; k < 5; ++k) u[k] = rrv__uniform(&rng);
            if (rrv__emitter_sample(s->emitters, &path.emit, NULL, u, &y) >= 0 &&
                rrv__chord_meets_refraction(s, path.emit.x, y))
                ++met;
        }
        share = (double)met / n;
        share_se = sqrt(share * (1 - share) / n);
        for (i = 0; i < n; ++i) {
            double zc = 1 - 2 * rrv__uniform(&rng), phi = 2 * 3.14159265358979323846 * rrv__uniform(&rng);
            double rho = sqrt(fmax(0.0, 1 - zc * zc));
            rrv_vec3 w = rrv__v3(rho * cos(phi), rho * sin(phi), zc);
            double p = rrv__emission_dir_density(s, &path.emit, w) * 4 * 3.14159265358979323846;
            sum += p;
            sum2 += p * p;
        }
        mean = sum / n;
        se = sqrt(fmax(sum2 / n - mean * mean, 0.0) / n);
        z = (mean - share) / sqrt(se * se + share_se * share_se);
        CHECKF(fabs(z) <= 4.0, "vertex %d: the density integrates to %g +- %g, the share is %g +- %g", vertex, mean, se,
               share, share_se);
        CHECKF(share > 0.05 && share < 0.95, "vertex %d: share %g does not test the clipping at r*", vertex, share);
        {
            /* the aim's and the forward path's weights of the same
               direction sum to one (the forward path reaching y along w) */
            int bad = 0, tried = 0;
            for (i = 0; i < 20000; ++i) {
                double u[5], p_aim, w_aim, w_fwd, r;
                rrv__coeffs cf;
                rrv_vec3 y, w;
                int k, mi;
                for (k = 0; k < 5; ++k) u[k] = rrv__uniform(&rng);
                mi = rrv__emitter_sample(s->emitters, &path.emit, NULL, u, &y);
                if (mi < 0 || !rrv__chord_meets_refraction(s, path.emit.x, y)) continue;
                r = rrv__length(rrv__sub(y, path.emit.x));
                w = rrv__scale(rrv__sub(y, path.emit.x), 1.0 / r);
                p_aim = rrv__emission_dir_density(s, &path.emit, w);
                w_aim = rrv__emission_aim_weight(&path.emit, w, p_aim);
                path.emit.w0 = path.bender.line_d = w;
                path.emit.p_w0 = -1.0;
                rrv__medium_coeffs(&s->media[mi], y, &cf);
                w_fwd = rrv__emission_forward_weight(&ctx, &path, &s->media[mi], y, &cf);
                ++tried;
                if (!(p_aim > 0 && fabs(w_aim + w_fwd - 1.0) <= 1e-12) && bad++ < 3)
                    CHECKF(0, "vertex %d: p_aim %g, w_aim %.17g + w_fwd %.17g", vertex, p_aim, w_aim, w_fwd);
            }
            CHECK(bad == 0 && tried > 500);
        }
        printf("  vertex %d: integral %.4f +- %.4f, share %.4f +- %.4f\n", vertex, mean, se, share, share_se);
    }
    rrv_scene_free(s);
}

#include "blocks.h"

/* The flame lights the wall and floor: with emission NEE the same blocks as
   the forward paths alone, within 4 standard errors of their difference,
   on the classic integrator and on the refractive one with a refracting box
   of hot air over the flame (straight connections only outside it), the
   same box with an ambient IOR of 1 (its faces sharp, jumps of 0.088: an
   aimed walk stops at one, and a path that crossed one keeps weight 1),
   and
   under a night sky, where by default the flame takes the light samples
   the sky would have had (and without emission NEE the sky takes them). */
/* The bounce's guide (rrv__build_guide): from vertices on the campfire's
   wall and floor, its density integrates to one over the sphere (uniform
   directions), and the directions it draws have the moments that density
   gives them (each side estimated by Monte Carlo, within 4 standard errors
   of their difference). The campfire's renders take it: the context's mix
   is the default's, its absorbing flame's albedo taken out. */
static void guide_density_matches_the_sampler(void)
{
    rrv_scene *s = load(campfire, "classic", "", "");
    const struct rrv__emitters *e;
    rrv__context ctx;
    rrv__camera_frame frame;
    rrv_error err;
    rrv__rng rng;
    int vertex;
    if (!s) return;
    e = s->emitters;
    CHECK(e != NULL && e->guide_count == 2);
    if (!e || e->guide_count < 1) { rrv_scene_free(s); return; }
    CHECK(rrv__render_context(s, &ctx, &frame, &err) == RRV_OK);
    CHECKF(fabs(ctx.guide_mix - RRV__GUIDE_MIX * (1.0 - 0.6 / 12.6)) <= 1e-12, "the mix %g", ctx.guide_mix);
    rrv__solver_release(&ctx);
    rrv__rng_seed(&rng, 41, 42, 43);
    for (vertex = 0; vertex < 4; ++vertex) {
        /* on the wall (shape 0, facing the flame) and the floor (shape 1) */
        const int shape = vertex & 1;
        const rrv_vec3 x = shape ? rrv__v3(vertex < 2 ? 1.1 : -0.3, 1e-6, vertex < 2 ? -0.9 : 0.9)
                                 : rrv__v3(vertex < 2 ? 0.7 : -1.5, vertex < 2 ? 0.3 : 2.0, 1.2 - 1e-6);
        const rrv_vec3 n = shape ? rrv__v3(0, 1, 0) : rrv__v3(0, 0, -1);
        double q[RRV__GUIDE_PATCHES], Q = rrv__guide_weights(e, x, n, shape, q);
        double sum = 0, sum2 = 0, mom_u[3] = {0, 0, 0}, mom_u2[3] = {0, 0, 0}, mom_g[3] = {0, 0, 0}, mom_g2[3] = {0, 0, 0};
        const int N = 400000;
        int i, a, worst_axis = 0;
        double mean, se, worst = 0;
        CHECK(Q > 0);
        if (!(Q > 0)) continue;
        for (i = 0; i < N; ++i) {
            /* uniform on the sphere: the integral of the density, and of
               the density times each axis */
            double z = 1.0 - 2.0 * rrv__uniform(&rng), phi = 2.0 * RRV__PI * rrv__uniform(&rng), r = sqrt(fmax(0.0, 1.0 - z * z));
            rrv_vec3 w = rrv__v3(r * cos(phi), r * sin(phi), z), g;
            double p = 4.0 * RRV__PI * rrv__guide_density(e, x, q, Q, w);
            sum += p;
            sum2 += p * p;
            for (a = 0; a < 3; ++a) {
                mom_u[a] += p * rrv__axis(w, a);
                mom_u2[a] += p * p * rrv__axis(w, a) * rrv__axis(w, a);
            }
            /* drawn by the guide */
            g = rrv__guide_sample(e, x, q, Q, rrv__uniform(&rng), rrv__uniform(&rng), rrv__uniform(&rng));
            for (a = 0; a < 3; ++a) {
                mom_g[a] += rrv__axis(g, a);
                mom_g2[a] += rrv__axis(g, a) * rrv__axis(g, a);
            }
        }
        mean = sum / N;
        se = sqrt((sum2 / N - mean * mean) / N);
        CHECKF(fabs(mean - 1.0) <= 4.0 * se && se < 0.02, "vertex %d: the density integrates to %g +- %g", vertex, mean, se);
        for (a = 0; a < 3; ++a) {
            double mu = mom_u[a] / N, mg = mom_g[a] / N;
            double s2 = (mom_u2[a] / N - mu * mu) / N + (mom_g2[a] / N - mg * mg) / N, z = (mu - mg) / sqrt(s2);
            CHECKF(fabs(z) <= 4.0, "vertex %d, axis %d: E[w] %g by the density, %g drawn (z = %.2f)", vertex, a, mu, mg, z);
            if (fabs(z) > worst) { worst = fabs(z); worst_axis = a; }
        }
        printf("  vertex %d: the density integrates to %.4f +- %.4f; moments' worst |z| %.2f (axis %d)\n", vertex, mean, se,
               worst, worst_axis);
    }
    rrv_scene_free(s);
}

static void nee_matches_forward_in_blocks(void)
{
    static const char *const haze =
        "medium haze box -1.3 0.9 -1.0 1.3 3.4 1.0 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature haze noise octaves 2 frequency 2.5 seed 5 falloff plume center 0 1.5 0 radius 0.9 "
        "amplitude 600 base 0 temperatureoffset -300 blackbody off\n"
        "ior haze gas iorscale 300\n"
        "ambient ior 1.0876\n";
    static const char *const around =
        "medium haze box -1.3 -0.01 0.0 1.3 3.4 1.0 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature haze noise octaves 2 frequency 2.5 seed 5 falloff plume center 0 1.0 0.5 radius 0.9 "
        "amplitude 600 base 0 temperatureoffset -300 blackbody off\n"
        "ior haze gas iorscale 300\n"
        "ambient ior 1.0876\n";
    static const char *const sharp =
        "medium haze box -1.3 0.9 -1.0 1.3 3.4 1.0 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature haze noise octaves 2 frequency 2.5 seed 5 falloff plume center 0 1.5 0 radius 0.9 "
        "amplitude 600 base 0 temperatureoffset -300 blackbody off\n"
        "ior haze gas iorscale 300\n"
        "ambient ior 1\n";
    static const char *const sky = "environment constant L 0.03 0.04 0.08\n";
    /* a light facing down, about as strong as the flame and near enough
       that the paths hit it often: the default shares each vertex's light
       draw between the two */
    static const char *const fill = "quad origin -1 1.8 -2 u 2.5 0 0 v 0 0 2.5 L 0.4 0.4 0.4\n";
    static const char *const fill_haze =
        "quad origin 1 2.2 -1.5 u 1 0 0 v 0 0 1 L 2 2 2\n"
        "medium haze box -1.3 0.9 -1.0 1.3 3.4 1.0 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature haze noise octaves 2 frequency 2.5 seed 5 falloff plume center 0 1.5 0 radius 0.9 "
        "amplitude 600 base 0 temperatureoffset -300 blackbody off\n"
        "ior haze gas iorscale 300\n"
        "ambient ior 1.0876\n";
    /* the light's centre in fog: equiangular samples toward it, whose
       weights read the flame's share at their points */
    static const char *const fill_fog =
        "quad origin 0.65 1.6 -1.8 u 0.3 0 0 v 0 0 0.3 L 20 20 20\n"
        "medium fog box 0.0 0.4 -2.5 1.6 2.0 -0.8 sigma_a 0.05 0.05 0.05 sigma_s 0.8 0.8 0.8\n"
        "density fog constant 1\n";
    int variant, k;
    for (variant = 0; variant < 8; ++variant) {
        const char *integrator = variant == 1 || variant == 2 || variant == 4 || variant == 6 ? "refractive" : "classic";
        const char *extra = variant == 7   ? fill_fog
                            : variant == 6 ? fill_haze
                            : variant == 5 ? fill
                            : variant == 4 ? sharp
                            : variant == 3 ? sky
                            : variant == 2 ? around
                            : variant      ? haze
                                           : "";
        rrv_scene *on = load(campfire, integrator, "", extra);
        rrv_scene *off = load(campfire, integrator, "emissionnee off", extra);
        double m_on[BW * BH], s_on[BW * BH], m_off[BW * BH], s_off[BW * BH], worst = 0, rel = 0;
        if (!on || !off) { rrv_scene_free(on); rrv_scene_free(off); return; }
        if (variant == 3) {
            rrv__context ctx;
            rrv__camera_frame frame;
            rrv_error e;
            CHECK(rrv__render_context(on, &ctx, &frame, &e) == RRV_OK && ctx.emission && rrv__light_pick_none(on));
            rrv__solver_release(&ctx);
            CHECK(rrv__render_context(off, &ctx, &frame, &e) == RRV_OK && !ctx.emission &&
                  rrv__light_prob(off, NULL, 0.0) == 1.0);
            rrv__solver_release(&ctx);
        }
        if (variant == 5) {
            /* the scene's share is the flame's power over the light's and
               its own; a draw below a share goes to the flame, the light
               keeps the rest; the classic integrator's share at a vertex
               follows power over squared distance: more of the draw to
               the flame at the floor beside it than high up near the
               light, the scene's share where the curved estimators read it */
            rrv__context ctx;
            rrv__camera_frame frame;
            rrv_error e;
            rrv__light_draw draw = {0, 0.5, 0.5, 0};
            rrv__emit_from near_flame, near_light;
            double share, light = 2.5 * 2.5 * 0.4, p_near, p_far;
            CHECK(rrv__render_context(on, &ctx, &frame, &e) == RRV_OK && ctx.emission && !ctx.bends);
            share = on->emitters->power / (on->emitters->power + light);
            CHECKF(share > 0.2 && share < 0.8 && fabs(on->emit_share - share) <= 1e-15 * share,
                   "the flame's share %g, expected %g", on->emit_share, share);
            draw.emit_share = share;
            CHECK(fabs(rrv__light_prob(on, &on->shapes[on->lights[0]], share) - (1.0 - share)) <= 1e-15);
            draw.u = share * (1.0 - 1e-9);
            CHECK(rrv__light_pick(on, &draw) == -1);
            draw.u = share + (1.0 - share) * 1e-9;
            CHECK(rrv__light_pick(on, &draw) == 0);
            memset(&near_flame, 0, sizeof near_flame);
            memset(&near_light, 0, sizeof near_light);
            near_flame.x = rrv__v3(0.8, 0.3, 0.0);
            near_light.x = rrv__v3(1.5, 2.1, -1.0);
            near_flame.S = rrv__emission_norm(on->emitters, &near_flame, NULL);
            near_light.S = rrv__emission_norm(on->emitters, &near_light, NULL);
            p_near = rrv__vertex_emit_share(&ctx, &near_flame);
            p_far = rrv__vertex_emit_share(&ctx, &near_light);
            CHECKF(p_near > 0.75 && p_far < 0.4 && rrv__vertex_emit_share(&ctx, NULL) == 0.0,
                   "the flame's share of a draw: %g beside it, %g beside the light", p_near, p_far);
            ctx.bends = 1;
            CHECK(rrv__vertex_emit_share(&ctx, &near_flame) == share && rrv__vertex_emit_share(&ctx, NULL) == share);
            rrv__solver_release(&ctx);
            CHECK(rrv__render_context(off, &ctx, &frame, &e) == RRV_OK && !ctx.emission && off->emit_share == 0.0);
            rrv__solver_release(&ctx);
        }
        {
            /* every variant's first bounce is guided but the sky's */
            rrv__context ctx;
            rrv__camera_frame frame;
            rrv_error e;
            CHECK(rrv__render_context(on, &ctx, &frame, &e) == RRV_OK);
            CHECKF(variant == 3 ? ctx.guide_mix == 0.0 : ctx.guide_mix >= RRV__GUIDE_LEAST, "variant %d: the guide's mix %g",
                   variant, ctx.guide_mix);
            printf("  (guide mix %.2f)", ctx.guide_mix);
            rrv__solver_release(&ctx);
        }
        block_stats(on, 16, 16, m_on, s_on);
        block_stats(off, 16, 128, m_off, s_off);
        for (k = 0; k < BW * BH; ++k) {
            double z = (m_on[k] - m_off[k]) / sqrt(s_on[k] * s_on[k] + s_off[k] * s_off[k]);
            CHECKF(fabs(z) <= 4.0, "%s %d block %d: %g +- %g with emission NEE, %g +- %g without (z = %.2f)",
                   integrator, variant, k, m_on[k], s_on[k], m_off[k], s_off[k], z);
            worst = fmax(worst, fabs(z));
            rel = fmax(rel, s_off[k] / m_off[k]);
        }
        /* resolving power: a bias of a tenth would show */
        CHECKF(rel < 0.025, "%s: the forward blocks' relative error %g is too large to see a bias", integrator, rel);
        printf("  %s%s: worst |z| %.2f, forward blocks within %.1f%%\n", integrator,
               variant == 7   ? ", beside a light in fog (equiangular samples)"
               : variant >= 5 ? ", beside a light that shares the draw"
               : variant == 4 ? ", hot air with sharp faces"
               : variant == 3 ? ", under a sky"
               : variant == 2 ? ", hot air behind the flame's front half"
               : variant      ? ", hot air over the flame"
                              : "",
               worst, 100 * rel);
        rrv_scene_free(on);
        rrv_scene_free(off);
    }
}

/* Where the flame shares a vertex's light draw with a light whose centre
   lies in fog, the three techniques toward that light (A: a free flight's
   light sample, B: its phase sample hitting the light, C: the equiangular
   sample, whose own pick never goes to the flame) weigh every point of a
   segment through the fog to a sum of one, whatever the flame's share
   there. */
static void shared_draw_weights_sum_to_one(void)
{
    static const char *const fog =
        "quad origin 0.65 1.6 -1.8 u 0.3 0 0 v 0 0 0.3 L 20 20 20\n"
        "medium fog box 0.0 0.4 -2.5 1.6 2.0 -0.8 sigma_a 0.05 0.05 0.05 sigma_s 0.8 0.8 0.8\n"
        "density fog constant 1\n";
    rrv_scene *s = load(campfire, "classic", "", fog);
    rrv__context ctx;
    rrv__camera_frame frame;
    rrv_error e;
    rrv__equi eq;
    const rrv_shape *light;
    rrv_vec3 o = rrv__v3(0.05, 0.5, -2.45), d;
    double worst = 0, most = 0;
    int k;
    if (!s) return;
    CHECK(rrv__render_context(s, &ctx, &frame, &e) == RRV_OK && ctx.emission && ctx.equiangular &&
          s->emit_share > 0);
    light = &s->shapes[s->lights[0]];
    d = rrv__normalize(rrv__sub(rrv__v3(1.55, 1.95, -0.85), o));
    rrv__equi_segment(&ctx, o, d, 3.0, &eq);
    CHECK(eq.on);
    for (k = 0; eq.on && k < 3000; ++k) {
        double t = eq.a + (k / 3 + 0.5) / 1000.0 * (eq.b - eq.a), share, p_light = 0.3 + k % 7, p_phase = 0.1 + 0.2 * (k % 5);
        double w_a, w_b, w_c;
        share = rrv__point_emit_share(&ctx, rrv__madd(o, d, t));
        most = fmax(most, share);
        if (k % 3 == 1) share = 0.5;
        if (k % 3 == 2) share = 0.9;
        eq.t = t;
        w_a = rrv__equi_vertex_weight(&ctx, &eq, light, 1, p_light * (1.0 - share), p_phase, share);
        w_b = rrv__equi_vertex_weight(&ctx, &eq, light, 0, p_light * (1.0 - share), p_phase, share);
        w_c = rrv__equi_own_weight(&ctx, &eq, rrv__light_centre(light), t, p_light, p_phase, share);
        worst = fmax(worst, fabs(w_a + w_b + w_c - 1.0));
    }
    CHECKF(worst <= 1e-12, "the three weights miss one by %g", worst);
    CHECKF(most > 0.01, "the flame's share in the fog is only %g", most);
    printf("  weights within %.1e of one; the flame's share in the fog up to %.3f\n", worst, most);
    rrv__solver_release(&ctx);
    rrv_scene_free(s);
}

/* The blackbody's table against the sum it replaces: every channel of XYZ
   within 1e-6 relative (the interpolation's error is about 2e-7 at its
   worst, near the table's hot end) at 20,000 temperatures spread evenly in
   log T from 100 K to past the table's top, plus its ends; linear sRGB
   within 1e-6 of the luminance; nothing at or below 100 K, the exact sum
   above the table. */
static void blackbody_table_matches_the_sum(void)
{
    struct rrv__blackbody *bb = (struct rrv__blackbody *)malloc(sizeof *bb);
    double worst = 0, worst_T = 0;
    int i, a, bad = 0;
    if (!bb) { CHECK(bb != NULL); return; }
    rrv__blackbody_table_fill(bb);
    for (i = 0; i <= 20002; ++i) {
        double T = i == 20001 ? 100.000001 : i == 20002 ? 999999.9 : 100.0 * pow(2e4, i / 20000.0);
        double exact[3], table[3], rgb_exact[3], rgb_table[3];
        rrv__blackbody_xyz(T, exact);
        rrv__blackbody_lookup_xyz(bb, T, table);
        for (a = 0; a < 3; ++a) {
            double rel = fabs(table[a] / exact[a] - 1.0);
            if (!(rel <= worst)) { worst = rel; worst_T = T; }
        }
        rrv__blackbody_rgb(T, rgb_exact);
        rrv__blackbody_lookup(bb, T, rgb_table);
        for (a = 0; a < 3; ++a)
            if (!(fabs(rgb_table[a] - rgb_exact[a]) <= 1e-6 * exact[1]) && bad++ < 3)
                CHECKF(0, "%.9g K channel %d: table %.17g, sum %.17g", T, a, rgb_table[a], rgb_exact[a]);
    }
    CHECKF(worst <= 1e-6, "XYZ off by %.3g relative at %.9g K", worst, worst_T);
    CHECK(bad == 0);
    printf("  worst relative error %.2g at %.0f K\n", worst, worst_T);
    {
        double z[3], hot[3], exact[3];
        rrv__blackbody_lookup_xyz(bb, 100.0, z);
        CHECK(z[0] == 0 && z[1] == 0 && z[2] == 0);
        rrv__blackbody_lookup_xyz(bb, 3e6, hot);
        rrv__blackbody_xyz(3e6, exact);
        CHECK(memcmp(hot, exact, sizeof hot) == 0);
    }
    free(bb);
}

/* In a medium that emits, a real collision scatters with the albedo as a
   weight (and the roulette spares the vertex) where elsewhere it absorbs
   or scatters by chance: two unbiased estimators of the same light. A
   chromatic, scattering medium under a light, once emitting nothing and
   once emitting 1e-20 (no light to see, the weighting on): in every
   channel, blocks within 4 standard errors of their difference, each block
   known to 2 %. */
static void albedo_weighting_is_unbiased(void)
{
    static const char *const fmt =
        "camera eye 0 1.4 -3 look 0 0.5 0 up 0 1 0 fov 40 resolution 16 12\n"
        "render spp 1 maxdepth 8 seed 3 integrator classic%s\n"
        "material floor diffuse albedo 0.8 0.8 0.8\n"
        "quad origin -3 0 -3 u 0 0 6 v 6 0 0 material floor\n"
        "quad origin -0.5 2.5 -0.5 u 1 0 0 v 0 0 1 L 6 6 6\n"
        "medium m box -0.8 0 -0.8 0.8 1.6 0.8 sigma_a 1.5 0.8 0.3 sigma_s 0.6 1.4 2.2 %s\n"
        "density m blob center 0 0.7 0 radius 0.6 weight 1.5\n";
    rrv_scene *plain = load(fmt, "", "", ""), *weighted = load(fmt, "", "Le 1e-20 1e-20 1e-20 Lescale 1", "");
    double m0[BW * BH], s0[BW * BH], m1[BW * BH], s1[BW * BH], worst = 0, rel = 0;
    int k, channel;
    if (!plain || !weighted) { rrv_scene_free(plain); rrv_scene_free(weighted); return; }
    for (channel = 0; channel < 3; ++channel) {
        block_stats_of(plain, channel, 16, 32, m0, s0);
        block_stats_of(weighted, channel, 16, 32, m1, s1);
        for (k = 0; k < BW * BH; ++k) {
            double z = (m1[k] - m0[k]) / sqrt(s0[k] * s0[k] + s1[k] * s1[k]);
            CHECKF(fabs(z) <= 4.0, "channel %d block %d: %g +- %g weighted, %g +- %g by chance (z = %.2f)", channel, k,
                   m1[k], s1[k], m0[k], s0[k], z);
            worst = fmax(worst, fabs(z));
            rel = fmax(rel, fmax(s0[k] / m0[k], s1[k] / m1[k]));
        }
    }
    CHECKF(rel < 0.02, "the blocks' relative error %g is too large to see a bias", rel);
    printf("  worst |z| %.2f, blocks within %.2f%%\n", worst, 100 * rel);
    rrv_scene_free(plain);
    rrv_scene_free(weighted);
}

/* A uniformly emitting, purely absorbing slab of optical depth tau above a
   white diffuse floor (a box 200 m wide, 1 m thick, 1 m up: its edges are
   89.4 degrees from the zenith, which costs cos^2 = 1e-4 of the
   irradiance). The floor's radiance is E / pi = Le (1 - 2 E_3(tau)), E_3
   the exponential integral, 2 E_3(tau) = 2 int_0^1 mu exp(-tau / mu) d mu,
   which the test integrates by Simpson's rule. With emission NEE and
   without: within 4 standard errors. */
static void slab_irradiance_closed_form(void)
{
    static const char *const slab =
        "camera eye 0 0.5 -1 look 0 0 0 up 0 1 0 fov 0.01 resolution 1 1\n"
        "render spp 1 maxdepth 1 seed 5 integrator classic %s\n"
        "material white diffuse albedo 1 1 1\n"
        "quad origin -300 0 -300 u 0 0 600 v 600 0 0 material white\n"
        "medium slab box -100 1 -100 100 2 100 sigma_a %s sigma_s 0 0 0 Le 1 1 1 Lescale 1\n"
        "density slab constant 1\n%s";
    const double tau = 0.7;
    double e3 = 0, expect, h = 1.0 / 20000;
    int i, variant;
    char sa[64];
    for (i = 0; i <= 20000; ++i) {
        double mu = i * h, f = mu > 0 ? mu * exp(-tau / mu) : 0.0;
        e3 += f * (i == 0 || i == 20000 ? 1 : i % 2 ? 4 : 2);
    }
    e3 *= h / 3;
    expect = 1.0 - 2.0 * e3;
    snprintf(sa, sizeof sa, "%g %g %g", tau, tau, tau);
    for (variant = 0; variant < 2; ++variant) {
        rrv_scene *s = load(slab, variant ? "emissionnee off" : "", sa, "");
        const int batches = 32, spp = 4096;
        double sum = 0, sum2 = 0, mean, se;
        int b;
        if (!s) return;
        for (b = 0; b < batches; ++b) {
            float px[3] = {0, 0, 0};
            double v;
            CHECK(rrv_render_rect(s, 0, 0, 1, 1, b * spp, (b + 1) * spp, px, 1, NULL, NULL) == RRV_OK);
            v = (px[0] + px[1] + px[2]) / (3.0 * spp);
            sum += v;
            sum2 += v * v;
        }
        mean = sum / batches;
        se = sqrt(fmax(sum2 / batches - mean * mean, 0.0) / (batches - 1));
        CHECKF(fabs(mean - expect) <= 4 * se, "%s: %.6f +- %.6f, closed form %.6f", variant ? "forward" : "nee", mean,
               se, expect);
        CHECKF(se < 0.01 * expect, "%s: standard error %g too large to test", variant ? "forward" : "nee", se);
        printf("  %s: %.5f +- %.5f (closed form %.5f)\n", variant ? "forward only" : "emission nee", mean, se, expect);
        rrv_scene_free(s);
    }
}

/* The emission cells a thick medium hides weigh less: in a uniformly
   emitting cube of optical depth 8 across (its own 32^3 emission cells,
   so every cell would weigh the same), a cell's pmf over the middle
   cell's is the mean over six axis directions of exp(-depth from its
   centre out of the cube), floored at 0.02, over the middle cell's:
   computed here from the depths alone. An overlapping smoke box (a
   second medium, no emission) adds its depth on the cells it covers. */
static void hidden_cells_weigh_less(void)
{
    static const char *const cube =
        "camera eye 0 0.5 -3 look 0 0.5 0 up 0 1 0 fov 40 resolution 4 4\n"
        "render spp 1 maxdepth 1 seed 5 integrator classic\n"
        "material white diffuse albedo 1 1 1\n"
        "quad origin -3 0 -3 u 0 0 6 v 6 0 0 material white\n"
        "medium glow box -0.5 0 -0.5 0.5 1 0.5 sigma_a 8 8 8 sigma_s 0 0 0 Le 1 1 1 Lescale 1\n"
        "density glow constant 1\n%s";
    static const char *const smoke = "medium smoke box -0.5 0 -0.5 0.5 1 0 sigma_a 0 0 0 sigma_s 4 4 4\n"
                                     "density smoke constant 1\n";
    int variant;
    for (variant = 0; variant < 2; ++variant) {
        rrv_scene *s = load(cube, variant ? smoke : "", "", "");
        const struct rrv__emitters *e;
        double worst = 0, ref = 0;
        int x, y, z, k;
        if (!s) return;
        e = s->emitters;
        CHECK(e && e->count == 1 && e->grid[0].n[0] == 32 && e->grid[0].n[1] == 32 && e->grid[0].n[2] == 32);
        if (!e || e->count != 1 || e->grid[0].n[0] != 32) { rrv_scene_free(s); return; }
        for (k = 0; k < 2; ++k)
            for (z = 0; z < 32; ++z)
                for (y = 0; y < 32; ++y)
                    for (x = 0; x < 32; ++x) {
                        /* extinction per cell length (1/32 m): the glow's 8,
                           the smoke's 4 over z < 0 (cells 0 to 15) */
                        const int at[3] = {x, y, z};
                        double seen = 0, want, got;
                        int a, j;
                        for (a = 0; a < 3; ++a) {
                            double down = 0, up = 0;
                            for (j = 0; j < 32; ++j) {
                                double sigma = 8.0 + (variant && (a == 2 ? j : at[2]) < 16 ? 4.0 : 0.0);
                                if (j < at[a]) down += sigma / 32;
                                if (j > at[a]) up += sigma / 32;
                                if (j == at[a]) { down += sigma / 64; up += sigma / 64; }
                            }
                            seen += exp(-down) + exp(-up);
                        }
                        want = seen / 6 > 0.02 ? seen / 6 : 0.02;
                        if (k == 0) {
                            /* the first pass finds the middle cell's weight */
                            if (x == 16 && y == 16 && z == 16) ref = want;
                            continue;
                        }
                        got = e->pmf[(size_t)(z * 32 + y) * 32 + x] / e->pmf[(size_t)(16 * 32 + 16) * 32 + 16];
                        worst = fmax(worst, fabs(got / (want / ref) - 1));
                    }
        printf("  %s: cells' weights against the depths' within %.1e; a face's centre %.2f, a corner %.2f, the "
               "middle 1\n", variant ? "with smoke" : "the cube alone", worst,
               e->pmf[(size_t)(16 * 32 + 16) * 32] / e->pmf[(size_t)(16 * 32 + 16) * 32 + 16],
               e->pmf[0] / e->pmf[(size_t)(16 * 32 + 16) * 32 + 16]);
        CHECKF(worst < 1e-6, "%s: a cell's weight %.2e off the depths'", variant ? "with smoke" : "alone", worst);
        rrv_scene_free(s);
    }
}

/* `cellcentered on` is the same grid shifted by half a voxel: every lookup
   at p equals the plain grid's at p - map * 0.5 (to rounding), the map and
   data untouched; without the key, or with `off`, nothing moves. */
static void cell_centered_is_half_voxel_shift(void)
{
    static const char *const fmt =
        "camera eye 0.5 -3 1 look 0.5 0.5 1 up 0 0 1 resolution 8 8\n"
        "medium fire box 0 0 0 1 1 2 sigma_a 1 1 1 sigma_s 1 1 1\n"
        "density fire nanovdb scenes/assets/pyro.nvdb %s%s%s\n";
    rrv_scene *plain = load(fmt, "", "", ""), *off = load(fmt, "cellcentered off", "", "");
    rrv_scene *centred = load(fmt, "cellcentered on", "", "");
    const rrv_nanovdb *a, *b;
    rrv__rng rng;
    double o[3];
    int i, j, bad = 0, inside = 0;
    if (!plain || !off || !centred) goto done;
    a = &plain->media[0].density.nanovdb;
    b = &centred->media[0].density.nanovdb;
    CHECK(memcmp(&off->media[0].density.nanovdb.translation, a->translation, sizeof a->translation) == 0);
    CHECK(off->media[0].density.nanovdb.lo.x == a->lo.x && off->media[0].density.nanovdb.hi.z == a->hi.z);
    for (j = 0; j < 3; ++j) {
        o[j] = 0.5 * (a->map[3 * j] + a->map[3 * j + 1] + a->map[3 * j + 2]);
        CHECK(b->translation[j] == a->translation[j] + o[j]);
    }
    CHECK(memcmp(a->map, b->map, sizeof a->map) == 0);
    CHECK(fabs(b->lo.x - (a->lo.x + o[0])) <= 1e-12 && fabs(b->hi.z - (a->hi.z + o[2])) <= 1e-12);
    rrv__rng_seed(&rng, 1, 2, 3);
    for (i = 0; i < 100000; ++i) {
        rrv_vec3 p = rrv__v3(-0.1 + 1.2 * rrv__uniform(&rng), -0.1 + 1.2 * rrv__uniform(&rng),
                             -0.1 + 2.2 * rrv__uniform(&rng));
        rrv_vec3 q = rrv__v3(p.x - o[0], p.y - o[1], p.z - o[2]);
        double vb = rrv_nanovdb_sample(b, p), va = rrv_nanovdb_sample(a, q);
        /* the scene's own lookup (density through the field) too */
        double fb = rrv__field_eval(&centred->media[0].density, p, 0, 0.0);
        if (va > 0) ++inside;
        if (!(fabs(va - vb) <= 1e-12 * (1 + fabs(va))) && bad++ < 3)
            CHECKF(0, "at %g %g %g: cell-centred %.17g, shifted %.17g", p.x, p.y, p.z, vb, va);
        if (rrv__inside_box(p, centred->media[0].lo, centred->media[0].hi) &&
            !(fabs(fb - vb) <= 1e-12 * (1 + fabs(vb))) && bad++ < 3)
            CHECKF(0, "field at %g %g %g: %.17g, grid %.17g", p.x, p.y, p.z, fb, vb);
    }
    CHECK(bad == 0);
    CHECK(inside > 1000);
done:
    rrv_scene_free(plain);
    rrv_scene_free(off);
    rrv_scene_free(centred);
}

/* The scene keys and their refusals. */
static void keys_and_messages(void)
{
    static const char *const fmt = "camera eye 0 0 -3 look 0 0 0\nrender %s\n%s%s";
    rrv_scene *s = load(fmt, "emissionnee off", "", "");
    char text[512];
    rrv_error e;
    if (s) CHECK(s->settings.emission_nee == RRV_EMISSION_NEE_OFF);
    rrv_scene_free(s);
    s = load(fmt, "emissionnee on", "", "");
    if (s) CHECK(s->settings.emission_nee == RRV_EMISSION_NEE_ON);
    rrv_scene_free(s);
    s = NULL;
    snprintf(text, sizeof text, fmt, "emissionnee maybe", "", "");
    CHECK(rrv_scene_parse(text, strlen(text), "k.rrv", ".", NULL, &s, &e) == RRV_ERROR_PARSE);
    CHECKF(strstr(e.message, "emissionnee") != NULL, "%s", e.message);
    snprintf(text, sizeof text, fmt, "", "medium m box 0 0 0 1 1 1\n",
             "density m nanovdb scenes/assets/pyro.nvdb cellcentered yes\n");
    CHECK(rrv_scene_parse(text, strlen(text), "k.rrv", ".", NULL, &s, &e) == RRV_ERROR_PARSE);
    CHECKF(e.line == 4 && strstr(e.message, "cellcentered") != NULL, "%d: %s", e.line, e.message);
}

int main(void)
{
    RUN(weights_sum_to_one);
    RUN(density_matches_the_sampler);
    RUN(aim_density_integrates_to_its_share);
    RUN(guide_density_matches_the_sampler);
    RUN(nee_matches_forward_in_blocks);
    RUN(shared_draw_weights_sum_to_one);
    RUN(slab_irradiance_closed_form);
    RUN(hidden_cells_weigh_less);
    RUN(blackbody_table_matches_the_sum);
    RUN(albedo_weighting_is_unbiased);
    RUN(cell_centered_is_half_voxel_shift);
    RUN(keys_and_messages);
    return CHECK_EXIT_CODE();
}
