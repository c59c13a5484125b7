/* The render's ETA against the truth, on every scene in scenes/: each tile of
   the scene's own image is rendered at TRUTH_SPP samples and its work counted;
   at every turn from 10 % to 90 % of the tiles, in the CLI's tile order, the
   ETA the progress bar would show (eta_seconds of the tiles done) must be
   within 25 % of the work the remaining tiles really took. The work is the
   library's deterministic count of what it did (samples, paths and tracking
   events, from rrv_render_stats), not a clock: the test must not depend on
   what else the machine runs. The scenes are the uneven cases: a sky above a
   flame or a floor under a caustic costs a few percent of the rows that hold
   the medium. In row order the same check fails on most of them.

   The CLI's own functions (tile_stride, tile_for_turn, eta_seconds) are what
   is tested, so main.c is compiled in with its main renamed (and linked with
   the library as the CLI is). argv[1] is the build folder (unused). */
#define main rrv_cli_main
#include "../main.c"
#undef main
#include "check.h"


#define ETA_TOLERANCE 0.25
/* A tile's work grows with its samples in proportion; one sample a pixel
   already holds a tile's unevenness (16 x 16 pixels' paths), and at 1 spp
   every scene's worst error moved by at most 4.5 points from 4 spp's
   (plume 23.9 -> 22.8 %, lens_caustic 12.1 -> 16.6 %) while the row-order
   mutation still fails on every scene (36-648 %) at a quarter of the cost. */
#define TRUTH_SPP 1

static const char *const scene_files[] = {
    "scenes/blast.rrv",        "scenes/fire.rrv",     "scenes/fire_caustic.rrv",
    "scenes/fisheye.rrv",      "scenes/haze.rrv",     "scenes/lens_caustic.rrv",
    "scenes/heat_shadow.rrv",  "scenes/luneburg.rrv", "scenes/plume.rrv",
    "scenes/pyro.rrv",         "scenes/smoke.rrv",
};

/* The work of each tile (indexed by tile, not turn) at samples [0, TRUTH_SPP). */
static double *tile_costs(const rrv_scene *scene, int *count)
{
    int w = scene->camera.width, h = scene->camera.height;
    int tiles_x = (w + TILE_SIZE - 1) / TILE_SIZE, tiles_y = (h + TILE_SIZE - 1) / TILE_SIZE, t;
    float *sum = (float *)malloc(3 * TILE_SIZE * TILE_SIZE * sizeof *sum);
    double *cost = (double *)malloc((size_t)tiles_x * tiles_y * sizeof *cost);
    *count = tiles_x * tiles_y;
    if (!sum || !cost) {
        free(sum);
        free(cost);
        return NULL;
    }
    for (t = 0; t < *count; ++t) {
        int x0 = (t % tiles_x) * TILE_SIZE, y0 = (t / tiles_x) * TILE_SIZE;
        int x1 = x0 + TILE_SIZE < w ? x0 + TILE_SIZE : w, y1 = y0 + TILE_SIZE < h ? y0 + TILE_SIZE : h;
        rrv_render_stats stats;
        memset(&stats, 0, sizeof stats);
        memset(sum, 0, 3 * TILE_SIZE * TILE_SIZE * sizeof *sum);
        rrv_render_rect(scene, x0, y0, x1, y1, 0, TRUTH_SPP, sum, TILE_SIZE, &stats, NULL);
        cost[t] = (double)(stats.samples + stats.paths + stats.events + stats.solve_iterations + stats.aim_shots);
    }
    free(sum);
    return cost;
}

/* The worst |ETA - truth| / truth over turns 10 % .. 90 % in the CLI's order. */
static double worst_eta_error(const double *cost, int tiles_x, int count, int *worst_turn)
{
    long stride = tile_stride(tiles_x, count / tiles_x);
    int turn, first = (count + 9) / 10, last = count - (count + 9) / 10;
    double total = 0, done = 0, worst = 0;
    double *seen = (double *)malloc((size_t)count * sizeof *seen);
    if (!seen) return HUGE_VAL;
    for (turn = 0; turn < count; ++turn) {
        total += cost[turn];
        seen[turn] = -1;
    }
    for (turn = 0; turn < last; ++turn) {
        int tile = tile_for_turn(turn, count, stride);
        done += cost[tile];
        seen[tile] = cost[tile];
        if (turn + 1 >= first) {
            double truth = total - done, eta = eta_seconds(seen, tiles_x, count, done);
            double error = fabs(eta - truth) / truth;
            if (error > worst) {
                worst = error;
                *worst_turn = turn + 1;
            }
        }
    }
    free(seen);
    return worst;
}

static void tile_order_is_a_permutation(void)
{
    static const int grids[][2] = {{1, 1}, {2, 1}, {1, 3}, {3, 5}, {8, 6}, {10, 8}, {16, 16},
                                   {20, 15}, {30, 20}, {1024, 1024}, {1000, 3}};
    size_t i;
    for (i = 0; i < sizeof grids / sizeof grids[0]; ++i) {
        int n = grids[i][0] * grids[i][1], k, repeats = 0;
        unsigned char *seen = (unsigned char *)calloc((size_t)n, 1);
        long stride = tile_stride(grids[i][0], grids[i][1]);
        CHECK(seen != NULL);
        for (k = 0; seen && k < n; ++k) {
            int t = tile_for_turn(k, n, stride);
            CHECKF(t >= 0 && t < n, "turn %d of %d gives tile %d", k, n, t);
            if (t >= 0 && t < n) repeats += seen[t]++ != 0;
        }
        CHECKF(repeats == 0, "%d of %d tiles handed out twice", repeats, n);
        free(seen);
    }
}

static void eta_within_a_quarter_on_every_scene(void)
{
    size_t i;
    for (i = 0; i < sizeof scene_files / sizeof scene_files[0]; ++i) {
        rrv_scene *scene = NULL;
        rrv_error err;
        rrv_load_options options;
        double *cost, worst;
        int count, worst_turn = 0;
        memset(&options, 0, sizeof options);
        if (rrv_scene_load(scene_files[i], &options, &scene, &err) != RRV_OK) {
            CHECKF(0, "%s: %s:%d: %s", scene_files[i], err.file, err.line, err.message);
            continue;
        }
        cost = tile_costs(scene, &count);
        CHECK(cost != NULL);
        if (cost) {
            worst = worst_eta_error(cost, (scene->camera.width + TILE_SIZE - 1) / TILE_SIZE, count, &worst_turn);
            printf("  %-24s %4d tiles: worst ETA error from 10 %% on %5.1f %% (at %.0f %%)\n", scene_files[i],
                   count, 100 * worst, 100.0 * worst_turn / count);
            CHECKF(worst <= ETA_TOLERANCE, "%s: the ETA is off by %.0f %% of the remaining time",
                   scene_files[i], 100 * worst);
        }
        free(cost);
        rrv_scene_free(scene);
    }
}

int main(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    RUN(tile_order_is_a_permutation);
    RUN(eta_within_a_quarter_on_every_scene);
    return CHECK_EXIT_CODE();
}
