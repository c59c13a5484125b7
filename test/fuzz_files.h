/* What the scene harnesses (fuzz_scene.c, fuzz_render.c) share: how one
   fuzz input becomes a scene text plus the files it asks for, served from
   memory so the disk is never touched.

   The input is scene text; if it holds a NUL byte, the bytes after the first
   NUL are served as the contents of every file the scene asks for, so OBJ
   and grid parsing are fuzzed through the scene too. Without a NUL, paths
   ending in .vol get a fixed valid grid and .obj a fixed tetrahedron.

   Load options keep preparation cheap: grids of at most 64 KiB (hostile
   headers are refused before allocating) and bakes of at most
   FUZZ_BAKE_SAMPLES samples (and majorant cells) per axis, so a noise field
   costs 16^3 evaluations instead of up to 128^3. */
#ifndef FUZZ_FILES_H
#define FUZZ_FILES_H
#include <stdlib.h>
#include <string.h>

#define FUZZ_BAKE_SAMPLES 16

typedef struct fuzz_files {
    const unsigned char *attached; /* NULL: serve the fixed files */
    size_t attached_size;
} fuzz_files;

static const unsigned char fuzz_tiny_grid[48 + 32] = {
    'V', 'O', 'L', 3, 1, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x80, 0x3f, 0, 0, 0x80, 0x3f, 0, 0, 0x80, 0x3f,
    /* samples 0, 0.5, 1, 0.5, 0, 0.5, 1, 0.5 */
    0, 0, 0, 0, 0, 0, 0, 0x3f, 0, 0, 0x80, 0x3f, 0, 0, 0, 0x3f,
    0, 0, 0, 0, 0, 0, 0, 0x3f, 0, 0, 0x80, 0x3f, 0, 0, 0, 0x3f};
static const char fuzz_tiny_obj[] =
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1/1 2/2 4/4 3\nf -1 -2 -3\n";

static int fuzz_ends_with(const char *s, const char *tail)
{
    size_t n = strlen(s), k = strlen(tail);
    return n >= k && memcmp(s + n - k, tail, k) == 0;
}

/* rrv_read_file_func serving a copy of `src` (the library frees it). */
static int fuzz_serve(const void *src, size_t n, void **data, size_t *size)
{
    void *copy = RRV_MALLOC(n ? n : 1);
    if (!copy) return 1;
    if (n) memcpy(copy, src, n);
    *data = copy;
    *size = n;
    return 0;
}

static int fuzz_read(void *user, const char *path, void **data, size_t *size)
{
    const fuzz_files *f = (const fuzz_files *)user;
    if (f->attached) return fuzz_serve(f->attached, f->attached_size, data, size);
    if (fuzz_ends_with(path, ".vol")) return fuzz_serve(fuzz_tiny_grid, sizeof fuzz_tiny_grid, data, size);
    if (fuzz_ends_with(path, ".obj")) return fuzz_serve(fuzz_tiny_obj, sizeof fuzz_tiny_obj - 1, data, size);
    return 1;
}

/* Splits the input at its first NUL and fills the load options. Returns the
   length of the scene text. */
static size_t fuzz_split(const unsigned char *data, size_t size, fuzz_files *files, rrv_load_options *opt)
{
    const unsigned char *nul = (const unsigned char *)memchr(data, 0, size);
    size_t text_size = nul ? (size_t)(nul - data) : size;
    files->attached = nul ? nul + 1 : NULL;
    files->attached_size = nul ? size - text_size - 1 : 0;
    memset(opt, 0, sizeof *opt);
    opt->max_grid_bytes = 1 << 16;
    opt->max_bake_samples = FUZZ_BAKE_SAMPLES;
    opt->read_file = fuzz_read;
    opt->read_file_user = files;
    return text_size;
}

/* The error contract: a failure always says something, in NUL-terminated
   fields, with the code it returned, and hands back no scene. */
static int fuzz_error_ok(rrv_result r, const rrv_scene *scene, const rrv_error *err)
{
    return scene == NULL && err->code == r && err->message[0] != '\0' &&
           memchr(err->message, 0, sizeof err->message) != NULL &&
           memchr(err->file, 0, sizeof err->file) != NULL && err->line >= 0;
}
#endif
