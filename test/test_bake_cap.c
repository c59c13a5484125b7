/* rrv_load_options.max_bake_samples: the noise bake and the majorant grid
   shrink to the cap, the default (0) keeps the full bake, and the cap stays
   with the scene when it is prepared again. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"

/* A 2.8 x 3 x 2.8 m puff: at the default its finest octave asks for more
   than 128 samples on the long axis, so the default cap of 128 applies. */
static const char puff[] =
    "camera eye 0 1.4 -4.6 look 0 1 0\n"
    "medium smoke box -1.4 0 -1.4 1.4 3 1.4 sigma_s 7 7 7\n"
    "density smoke noise octaves 5 frequency 1.4 threshold 0.3 seed 7 amplitude 2.5\n";
static const char puff_cells[] =
    "camera eye 0 1.4 -4.6 look 0 1 0\n"
    "render majorantcells 64\n"
    "medium smoke box -1.4 0 -1.4 1.4 3 1.4 sigma_s 7 7 7\n"
    "density smoke noise octaves 5 frequency 1.4 threshold 0.3 seed 7 amplitude 2.5\n";

static rrv_scene *load(const char *text, size_t size, int cap)
{
    rrv_load_options opt;
    rrv_scene *scene = NULL;
    rrv_error err;
    memset(&opt, 0, sizeof opt);
    opt.max_bake_samples = cap;
    if (rrv_scene_parse(text, size, "puff.rrv", NULL, &opt, &scene, &err) != RRV_OK) {
        printf("  %s:%d: %s\n", err.file, err.line, err.message);
        return NULL;
    }
    return scene;
}

static const rrv_grid *baked_density(const rrv_scene *s)
{
    return &s->media[0].majorant->baked[RRV__DENSITY].grid;
}

static void test_default_bake_is_full(void)
{
    rrv_scene *s = load(puff, sizeof puff - 1, 0);
    CHECK(s != NULL);
    if (!s) return;
    CHECK(s->settings.max_bake_samples == 0);
    CHECKF(baked_density(s)->ny == 128, "ny %d", baked_density(s)->ny);
    CHECK(baked_density(s)->nx > 64 && baked_density(s)->nz > 64);
    rrv_scene_free(s);
}

static void test_cap_shrinks_bake_and_majorant(void)
{
    rrv_scene *s = load(puff, sizeof puff - 1, 16);
    const rrv_grid *g;
    int a;
    CHECK(s != NULL);
    if (!s) return;
    g = baked_density(s);
    /* the long axis takes the cap, the others at most that */
    CHECKF(g->ny == 16 && g->nx <= 16 && g->nz <= 16 && g->nx >= 2, "%d %d %d", g->nx, g->ny, g->nz);
    for (a = 0; a < 3; ++a) CHECK(s->media[0].majorant->n[a] <= 16);
    /* prepared again (as `rrv render --majorant-cells` does), the cap holds */
    s->settings.majorant_cells = 64;
    CHECK(rrv_scene_prepare(s, NULL) == RRV_OK);
    CHECK(baked_density(s)->ny == 16);
    for (a = 0; a < 3; ++a) CHECK(s->media[0].majorant->n[a] == 16);
    rrv_scene_free(s);
}

static void test_cap_bounds_forced_majorant_cells(void)
{
    rrv_scene *s = load(puff_cells, sizeof puff_cells - 1, 8);
    int a;
    CHECK(s != NULL);
    if (!s) return;
    for (a = 0; a < 3; ++a) CHECK(s->media[0].majorant->n[a] == 8);
    rrv_scene_free(s);
    s = load(puff_cells, sizeof puff_cells - 1, 0);
    CHECK(s != NULL);
    if (!s) return;
    for (a = 0; a < 3; ++a) CHECK(s->media[0].majorant->n[a] == 64);
    rrv_scene_free(s);
}

/* A cap below 2 still bakes a lattice (two samples, the box corners). */
static void test_smallest_cap(void)
{
    rrv_scene *s = load(puff, sizeof puff - 1, 1);
    const rrv_grid *g;
    CHECK(s != NULL);
    if (!s) return;
    g = baked_density(s);
    CHECKF(g->nx == 2 && g->ny == 2 && g->nz == 2, "%d %d %d", g->nx, g->ny, g->nz);
    CHECK(s->media[0].majorant->n[0] == 1);
    rrv_scene_free(s);
}

int main(void)
{
    RUN(test_default_bake_is_full);
    RUN(test_cap_shrinks_bake_and_majorant);
    RUN(test_cap_bounds_forced_majorant_cells);
    RUN(test_smallest_cap);
    return CHECK_EXIT_CODE();
}
