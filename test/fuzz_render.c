/* libFuzzer harness that renders: each input is loaded as a scene (as in
   fuzz_scene.c, see test/fuzz_files.h) and rendered at 4x4 pixels, one
   sample each, at most 8 bounces. The pixels cycle through the three
   integrators (starting with the scene's), the refraction schemes and the
   eikonal steppers, so every input reaches every one of them. Flagged
   (__builtin_trap, so libFuzzer saves the input):
   - a pixel that is not finite: finite inputs must give finite images;
   - rrv_render_rect refusing a scene that loaded;
   - runaway work, checked after every pixel: more than FUZZ_MAX_EVENTS
     tracking events, refraction kicks and eikonal steps in all (2e6, 125k
     a sample: the busiest scene in scenes/, fisheye, takes 1796 here, and
     scenes/blast.rrv with its IOR shell jumping by 30, not 0.03, over 3 cm
     takes 4e5), or, for work the event count misses, more than
     FUZZ_RENDER_SECONDS of CPU time (10 s; the slowest scene in scenes/,
     fire, takes 0.22 s of CPU under the sanitizers).
     Events are the primary bound because they do not depend on the
     machine or its load. A sample that never returns is caught by
     libFuzzer's -timeout instead (`make fuzz-run` passes 20 s).
   `make fuzz`, then `make fuzz-run`, or by hand:
       rm -rf /tmp/render-seeds && cp -r scenes /tmp/render-seeds
       ./build-fuzz/fuzz_render -max_total_time=60 -timeout=20 /tmp/render-seeds */
/* the research variants too (rrv.h, RRV_RESEARCH): their code is fuzzed as
   the default build's is */
#define RRV_RESEARCH
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "fuzz_files.h"
#include <time.h>

#ifndef FUZZ_MAX_EVENTS
#define FUZZ_MAX_EVENTS 2000000u
#endif
#ifndef FUZZ_RENDER_SECONDS
#define FUZZ_RENDER_SECONDS 10.0
#endif
#define FUZZ_SIZE 4
#define FUZZ_MAX_DEPTH 8

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    fuzz_files files;
    rrv_load_options opt;
    rrv_scene *scene = NULL;
    rrv_error err;
    rrv_render_stats stats;
    clock_t start;
    int x, y, c, integrator, scheme, stepper;
    size_t text_size = fuzz_split(data, size, &files, &opt);
    rrv_result r = rrv_scene_parse((const char *)data, text_size, "fuzz.rrv", "dir", &opt, &scene, &err);
    if (r != RRV_OK) {
        if (!fuzz_error_ok(r, scene, &err)) __builtin_trap();
        return 0;
    }
    /* Only the image shrinks: preparation does not depend on the camera's
       resolution, and fewer bounces bound the work of honest scenes. */
    scene->camera.width = FUZZ_SIZE;
    scene->camera.height = FUZZ_SIZE;
    if (scene->settings.max_depth > FUZZ_MAX_DEPTH) scene->settings.max_depth = FUZZ_MAX_DEPTH;
    integrator = (int)scene->settings.integrator;
    scheme = (int)scene->settings.refraction;
    stepper = (int)scene->settings.stepper;
    memset(&stats, 0, sizeof stats);
    start = clock();
    for (y = 0; y < FUZZ_SIZE; ++y)
        for (x = 0; x < FUZZ_SIZE; ++x) {
            float pixel[3] = {0, 0, 0};
            int k = y * FUZZ_SIZE + x;
            /* only rrv_render_rect reads these, so no new prepare is needed */
            scene->settings.integrator = (rrv_integrator)((integrator + k) % 4);
            scene->settings.refraction = (rrv_refraction_scheme)((scheme + k / 3) % 4);
            scene->settings.stepper = (rrv_stepper)((stepper + k / 3) % 3);
            if (rrv_render_rect(scene, x, y, x + 1, y + 1, 0, 1, pixel, 1, &stats, NULL) != RRV_OK) __builtin_trap();
            for (c = 0; c < 3; ++c)
                if (!isfinite(pixel[c])) __builtin_trap();
            if (stats.events > FUZZ_MAX_EVENTS) __builtin_trap();
            if ((double)(clock() - start) > FUZZ_RENDER_SECONDS * CLOCKS_PER_SEC) __builtin_trap();
        }
    if (stats.samples != FUZZ_SIZE * FUZZ_SIZE) __builtin_trap();
    rrv_scene_free(scene);
    return 0;
}
