/* Builds scenes in code for tests that must not depend on the parser,
   through the public scene-building API, so the defaults are the library's
   own. Shapes and blobs are appended raw for the caller to fill in (a
   zeroed sphere would be refused by rrv_scene_add_shape); rrv_scene_prepare
   checks them. The arrays use malloc, as RRV_MALLOC does by default, so
   rrv_scene_free releases them. */
#ifndef RRV_TEST_SCENE_BUILDER_H
#define RRV_TEST_SCENE_BUILDER_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "vec3.h"

static void tb_must(rrv_result r, const rrv_error *err)
{
    if (r != RRV_OK) {
        fprintf(stderr, "scene_builder: %s\n", err->message);
        abort();
    }
}

static rrv_scene *tb_scene(int width, int height)
{
    rrv_scene *s;
    rrv_camera cam;
    rrv_settings set;
    rrv_material grey;
    rrv_error err;
    memset(&cam, 0, sizeof cam);
    memset(&set, 0, sizeof set);
    memset(&grey, 0, sizeof grey);
    tb_must(rrv_scene_create(&s, &err), &err);
    cam.eye = tv3(0, 0, -5);
    cam.fov = 30;
    cam.width = width;
    cam.height = height;
    tb_must(rrv_scene_set_camera(s, &cam, &err), &err);
    set.max_depth = 64;
    set.bend_tolerance = 0.002;
    tb_must(rrv_scene_set_settings(s, &set, &err), &err);
    strcpy(grey.name, "grey"); /* albedo 0.5, the default */
    tb_must(rrv_scene_add_material(s, &grey, NULL, &err), &err);
    strcpy(s->path, "test");
    return s;
}

/* A box of constant density 1. Coefficients that are both zero are set
   after adding: to rrv_scene_add_medium they would mean the default. */
static rrv_medium *tb_medium(rrv_scene *s, rrv_vec3 lo, rrv_vec3 hi, double sigma_a, double sigma_s)
{
    rrv_medium desc;
    rrv_field density;
    rrv_error err;
    rrv_medium *m;
    int i, c;
    memset(&desc, 0, sizeof desc);
    memset(&density, 0, sizeof density);
    desc.lo = lo;
    desc.hi = hi;
    tb_must(rrv_scene_add_medium(s, &desc, &i, &err), &err);
    density.kind = RRV_FIELD_CONSTANT;
    density.value = 1;
    tb_must(rrv_scene_set_field(s, i, RRV_MEDIUM_DENSITY, &density, &err), &err);
    m = &s->media[i];
    for (c = 0; c < 3; ++c) {
        m->sigma_a[c] = sigma_a;
        m->sigma_s[c] = sigma_s;
    }
    return m;
}

static rrv_shape *tb_shape(rrv_scene *s, rrv_shape_kind kind)
{
    rrv_shape *sh;
    s->shapes = (rrv_shape *)realloc(s->shapes, (size_t)(s->shape_count + 1) * sizeof(rrv_shape));
    sh = &s->shapes[s->shape_count++];
    s->shape_capacity = s->shape_count;
    memset(sh, 0, sizeof *sh);
    sh->kind = kind;
    return sh;
}

static rrv_blob *tb_blobs(rrv_field *f, int count)
{
    f->kind = RRV_FIELD_BLOBS;
    f->blobs = (rrv_blob *)calloc((size_t)count, sizeof(rrv_blob));
    f->blob_count = count;
    return f->blobs;
}
#endif
