/* libFuzzer harness for the scene parser: `make fuzz`, then
       rm -rf /tmp/scene-seeds && cp -r test/corpus /tmp/scene-seeds
       ./build-fuzz/fuzz_scene -max_total_time=60 /tmp/scene-seeds
   (a scratch copy, so the fuzzer never writes into the repository), or
   `make fuzz-run` for every harness. How an input becomes a scene and its
   files: test/fuzz_files.h. Loading includes rrv_scene_prepare, with the
   bake capped so that a noise field does not dominate the time. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "fuzz_files.h"

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    fuzz_files files;
    rrv_load_options opt;
    rrv_scene *scene = NULL;
    rrv_error err;
    size_t text_size = fuzz_split(data, size, &files, &opt);
    rrv_result r = rrv_scene_parse((const char *)data, text_size, "fuzz.rrv", "dir", &opt, &scene, &err);
    if (r != RRV_OK) {
        if (!fuzz_error_ok(r, scene, &err)) abort();
    } else {
        if (scene == NULL || scene->grid_bytes > scene->bytes) abort();
        rrv_scene_free(scene);
    }
    return 0;
}
