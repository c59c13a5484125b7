/* Smoke test of every example scene: each .rrv file in scenes/ and in
   scenes/pictures/ (README's pictures, which make pictures renders) is loaded,
   shrunk to a tiny image at 2 spp, and rendered with every integrator
   (classic, refractive, eikonal). Each render must succeed, give only finite
   pixels (and discard no nonfinite sample), not be all black, and take no
   runaway number of events (a path stuck in a medium). The folder
   is scanned, so a new scene is covered without touching this file.
   Run from the repository root; argv[1] is the build folder (unused). */
#define _POSIX_C_SOURCE 200809L
#include "../rrv.h"
#include "check.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define SCENE_DIR "scenes"
/* The picture scenes are checked here, cheaply, so that they cannot rot
   between the (minutes long, not in CI) renders of make pictures; they have
   no references in test/ref (test_refs scans scenes/ alone). */
#define PICTURE_DIR "scenes/pictures"
#define MAX_SCENES 256
#define MIN_SCENES 4
#define TEST_WIDTH 24
#define TEST_HEIGHT 16
#define TEST_SPP 2
#define MAX_EVENTS_PER_SAMPLE 20000

static char scene_names[MAX_SCENES][256]; /* "scenes/NAME.rrv", "scenes/pictures/NAME.rrv" */
static int scene_count;

static int compare_names(const void *a, const void *b)
{
    return strcmp((const char *)a, (const char *)b);
}

/* Adds the *.rrv files of folder to scene_names; hidden files (a leading
   dot) are skipped. Returns 0 if the folder cannot be read. */
static int add_scenes(const char *folder)
{
    DIR *dir = opendir(folder);
    struct dirent *e;
    size_t prefix = strlen(folder) + 1;
    if (!dir) return 0;
    while ((e = readdir(dir)) != NULL) {
        size_t n = strlen(e->d_name);
        if (e->d_name[0] == '.' || n < 5 || prefix + n >= sizeof scene_names[0]) continue;
        if (strcmp(e->d_name + n - 4, ".rrv") != 0) continue;
        if (scene_count == MAX_SCENES) break;
        memcpy(scene_names[scene_count], folder, prefix - 1);
        scene_names[scene_count][prefix - 1] = '/';
        memcpy(scene_names[scene_count] + prefix, e->d_name, n + 1);
        ++scene_count;
    }
    closedir(dir);
    return 1;
}

/* Fills scene_names with the scenes of SCENE_DIR and PICTURE_DIR, sorted.
   Returns 0 if either folder cannot be read. */
static int find_scenes(void)
{
    int ok;
    scene_count = 0;
    ok = add_scenes(SCENE_DIR);
    ok = add_scenes(PICTURE_DIR) && ok;
    qsort(scene_names, (size_t)scene_count, sizeof scene_names[0], compare_names);
    return ok;
}

static const char *integrator_name(rrv_integrator integrator)
{
    switch (integrator) {
    case RRV_INTEGRATOR_CLASSIC: return "classic";
    case RRV_INTEGRATOR_REFRACTIVE: return "refractive";
    default: return "eikonal";
    }
}

/* Renders one scene with one integrator and checks the image. */
static void check_render(rrv_scene *scene, const char *name, rrv_integrator integrator)
{
    const int w = TEST_WIDTH, h = TEST_HEIGHT;
    float *sum = (float *)calloc((size_t)w * h * 3, sizeof *sum);
    rrv_render_stats stats;
    rrv_result res;
    size_t i, bad = 0, first_bad = 0;
    double total = 0;
    clock_t start;
    memset(&stats, 0, sizeof stats);
    CHECK(sum != NULL);
    if (!sum) return;
    scene->settings.integrator = integrator;
    start = clock();
    res = rrv_render_rect(scene, 0, 0, w, h, 0, TEST_SPP, sum, w, &stats, NULL);
    printf("  %-32s %-10s %7.2f s  %10lu events\n", name, integrator_name(integrator),
           (double)(clock() - start) / CLOCKS_PER_SEC, (unsigned long)stats.events);
    CHECKF(res == RRV_OK, "%s, %s: rrv_render_rect returned %s", name, integrator_name(integrator),
           rrv_result_string(res));
    for (i = 0; i < (size_t)w * h * 3; ++i) {
        double v = sum[i];
        if (!isfinite(v)) {
            if (!bad) first_bad = i;
            ++bad;
        } else {
            total += v;
        }
    }
    CHECKF(bad == 0, "%s, %s: %lu nonfinite values, the first at pixel %lu", name, integrator_name(integrator),
           (unsigned long)bad, (unsigned long)(first_bad / 3));
    CHECKF(stats.nonfinite == 0, "%s, %s: %lu nonfinite samples discarded", name, integrator_name(integrator),
           (unsigned long)stats.nonfinite);
    CHECKF(stats.samples == (uint64_t)w * h * TEST_SPP, "%s, %s: %lu samples taken, expected %lu", name,
           integrator_name(integrator), (unsigned long)stats.samples, (unsigned long)w * h * TEST_SPP);
    /* A sample takes tens to thousands of events on these scenes; far more
       means paths that never leave a medium (they run to the step limit). */
    CHECKF(stats.events <= (uint64_t)MAX_EVENTS_PER_SAMPLE * stats.samples,
           "%s, %s: %lu events for %lu samples, runaway paths", name, integrator_name(integrator),
           (unsigned long)stats.events, (unsigned long)stats.samples);
    /* Never black: even a light seen only through a refracting medium (as
       in fire_caustic) is sampled by the default nee with every integrator
       (with refractive, shoot aims bent shadow rays at it). */
    CHECKF(total > 0, "%s, %s: the image is all black", name, integrator_name(integrator));
    free(sum);
}

static void test_every_scene_renders(void)
{
    static const rrv_integrator integrators[] = {RRV_INTEGRATOR_CLASSIC, RRV_INTEGRATOR_REFRACTIVE,
                                                 RRV_INTEGRATOR_EIKONAL};
    int s, k;
    CHECKF(find_scenes(), "cannot open the folder %s or %s (run from the repository root)", SCENE_DIR, PICTURE_DIR);
    CHECKF(scene_count >= MIN_SCENES, "found %d scenes in %s, expected at least %d", scene_count, SCENE_DIR,
           MIN_SCENES);
    for (s = 0; s < scene_count; ++s) {
        const char *path = scene_names[s];
        rrv_scene *scene = NULL;
        rrv_error err;
        rrv_result res;
        res = rrv_scene_load(path, NULL, &scene, &err);
        CHECKF(res == RRV_OK, "%s:%d: %s", err.file, err.line, err.message);
        if (res != RRV_OK) continue;
        scene->camera.width = TEST_WIDTH;
        scene->camera.height = TEST_HEIGHT;
        scene->settings.spp = TEST_SPP;
        res = rrv_scene_prepare(scene, &err);
        CHECKF(res == RRV_OK, "%s: prepare after shrinking: %s", path, err.message);
        if (res == RRV_OK)
            for (k = 0; k < 3; ++k) check_render(scene, path, integrators[k]);
        rrv_scene_free(scene);
    }
}

int main(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    RUN(test_every_scene_renders);
    return CHECK_EXIT_CODE();
}
