/* libFuzzer harness for the scene parser: `make fuzz`, then
       rm -rf /tmp/scene-seeds && cp -r test/corpus /tmp/scene-seeds
       ./build-fuzz/fuzz_scene -max_total_time=60 /tmp/scene-seeds
   (a scratch copy, so the fuzzer never writes into the repository).
   The input is scene text; if it holds a NUL byte, the bytes after the first
   NUL are served as the contents of every file the scene asks for, so OBJ
   and grid parsing are fuzzed through the scene too. Without a NUL, paths
   ending in .vol get a fixed valid grid and .obj a fixed tetrahedron. The
   disk is never touched. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>

typedef struct fuzz_files {
    const unsigned char *attached; /* NULL: serve the fixed files */
    size_t attached_size;
} fuzz_files;

static const unsigned char tiny_grid[48 + 32] = {
    'V', 'O', 'L', 3, 1, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x80, 0x3f, 0, 0, 0x80, 0x3f, 0, 0, 0x80, 0x3f,
    /* samples 0, 0.5, 1, 0.5, 0, 0.5, 1, 0.5 */
    0, 0, 0, 0, 0, 0, 0, 0x3f, 0, 0, 0x80, 0x3f, 0, 0, 0, 0x3f,
    0, 0, 0, 0, 0, 0, 0, 0x3f, 0, 0, 0x80, 0x3f, 0, 0, 0, 0x3f};
static const char tiny_obj[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1/1 2/2 4/4 3\nf -1 -2 -3\n";

static int ends_with(const char *s, const char *tail)
{
    size_t n = strlen(s), k = strlen(tail);
    return n >= k && memcmp(s + n - k, tail, k) == 0;
}

static int fuzz_read(void *user, const char *path, void **data, size_t *size)
{
    fuzz_files *f = (fuzz_files *)user;
    const void *src;
    size_t n;
    void *copy;
    if (f->attached) {
        src = f->attached;
        n = f->attached_size;
    } else if (ends_with(path, ".vol")) {
        src = tiny_grid;
        n = sizeof tiny_grid;
    } else if (ends_with(path, ".obj")) {
        src = tiny_obj;
        n = sizeof tiny_obj - 1;
    } else {
        return 1;
    }
    copy = RRV_MALLOC(n ? n : 1);
    if (!copy) return 1;
    memcpy(copy, src, n);
    *data = copy;
    *size = n;
    return 0;
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    fuzz_files files;
    rrv_load_options opt;
    rrv_scene *scene = NULL;
    rrv_error err;
    rrv_result r;
    const unsigned char *nul = (const unsigned char *)memchr(data, 0, size);
    size_t text_size = nul ? (size_t)(nul - data) : size;
    files.attached = nul ? nul + 1 : NULL;
    files.attached_size = nul ? size - text_size - 1 : 0;
    memset(&opt, 0, sizeof opt);
    opt.max_grid_bytes = 1 << 16;
    opt.read_file = fuzz_read;
    opt.read_file_user = &files;
    r = rrv_scene_parse((const char *)data, text_size, "fuzz.rrv", "dir", &opt, &scene, &err);
    /* contract checks: a failure always says something and returns no scene */
    if (r != RRV_OK) {
        if (scene != NULL || err.code != r || err.message[0] == '\0' ||
            memchr(err.message, 0, sizeof err.message) == NULL || memchr(err.file, 0, sizeof err.file) == NULL)
            abort();
    } else {
        if (scene == NULL || scene->grid_bytes > scene->bytes) abort();
        rrv_scene_free(scene);
    }
    return 0;
}
