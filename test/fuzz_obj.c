/* libFuzzer harness for the OBJ parser, reached the way users reach it: a
   fixed scene loads the fuzz input as its mesh file (served from memory).
   `make fuzz`, then `make fuzz-run`, or by hand on a scratch copy of seeds:
       mkdir -p /tmp/obj-seeds && cp test/corpus/bad_obj_line.obj /tmp/obj-seeds
       ./build-fuzz/fuzz_obj -max_total_time=60 /tmp/obj-seeds
   Contract checked: a failure says something; a failure inside the OBJ
   names the OBJ and a line that exists in it; a success holds only
   triangles with finite corners and edges. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>

typedef struct obj_input {
    const unsigned char *data;
    size_t size;
} obj_input;

static int serve_obj(void *user, const char *path, void **data, size_t *size)
{
    const obj_input *in = (const obj_input *)user;
    void *copy = RRV_MALLOC(in->size ? in->size : 1);
    (void)path;
    if (!copy) return 1;
    if (in->size) memcpy(copy, in->data, in->size);
    *data = copy;
    *size = in->size;
    return 0;
}

static int finite3(rrv_vec3 v)
{
    return isfinite(v.x) && isfinite(v.y) && isfinite(v.z);
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    static const char scene_text[] = "camera eye 0 0 5 look 0 0 0\nmesh file \"m.obj\"\n";
    obj_input in;
    rrv_load_options opt;
    rrv_scene *scene = NULL;
    rrv_error err;
    rrv_result r;
    size_t i;
    long lines = 1;
    in.data = data;
    in.size = size;
    memset(&opt, 0, sizeof opt);
    opt.read_file = serve_obj;
    opt.read_file_user = &in;
    r = rrv_scene_parse(scene_text, sizeof scene_text - 1, "fuzz.rrv", "dir", &opt, &scene, &err);
    for (i = 0; i < size; ++i) lines += data[i] == '\n';
    if (r != RRV_OK) {
        if (scene != NULL || err.code != r || err.message[0] == '\0' ||
            memchr(err.message, 0, sizeof err.message) == NULL || memchr(err.file, 0, sizeof err.file) == NULL)
            abort();
        if (strcmp(err.file, "dir/m.obj") == 0) {
            if (err.line < 1 || err.line > lines) abort();
        } else if (strcmp(err.file, "fuzz.rrv") != 0 || err.line != 2) {
            abort(); /* only the mesh statement may fail on the scene's side */
        }
        return 0;
    }
    if (!scene) abort();
    for (i = 0; i < (size_t)scene->shape_count; ++i) {
        const rrv_shape *s = &scene->shapes[i];
        if (s->kind != RRV_SHAPE_TRIANGLE || !finite3(s->p0) || !finite3(s->e1) || !finite3(s->e2)) abort();
    }
    rrv_scene_free(scene);
    return 0;
}
