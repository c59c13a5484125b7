/* Builds scenes in code for tests that must not depend on the parser. The
   arrays are allocated with malloc, as RRV_MALLOC does by default, so
   rrv_scene_free releases them. */
#ifndef RRV_TEST_SCENE_BUILDER_H
#define RRV_TEST_SCENE_BUILDER_H
#include <stdlib.h>
#include <string.h>

static rrv_scene *tb_scene(int width, int height)
{
    rrv_scene *s = (rrv_scene *)calloc(1, sizeof *s);
    s->camera.eye = rrv__v3(0, 0, -5);
    s->camera.look = rrv__v3(0, 0, 0);
    s->camera.up = rrv__v3(0, 1, 0);
    s->camera.fov = 30;
    s->camera.width = width;
    s->camera.height = height;
    s->settings.spp = 16;
    s->settings.max_depth = 64;
    s->settings.bend_tolerance = 0.002;
    s->settings.step = 0.01;
    s->settings.ambient_ior = 1.0;
    strcpy(s->path, "test");
    s->materials = (rrv_material *)calloc(1, sizeof(rrv_material));
    s->material_count = s->material_capacity = 1;
    s->materials[0].albedo[0] = s->materials[0].albedo[1] = s->materials[0].albedo[2] = 0.5;
    return s;
}

static rrv_medium *tb_medium(rrv_scene *s, rrv_vec3 lo, rrv_vec3 hi, double sigma_a, double sigma_s)
{
    rrv_medium *m;
    s->media = (rrv_medium *)realloc(s->media, (size_t)(s->medium_count + 1) * sizeof(rrv_medium));
    m = &s->media[s->medium_count++];
    s->medium_capacity = s->medium_count;
    memset(m, 0, sizeof *m);
    m->lo = lo;
    m->hi = hi;
    m->sigma_a[0] = m->sigma_a[1] = m->sigma_a[2] = sigma_a;
    m->sigma_s[0] = m->sigma_s[1] = m->sigma_s[2] = sigma_s;
    m->scale = 1;
    m->Lescale = 1;
    m->temperaturescale = 1;
    m->eta_ref = 1.000292;
    m->P_ref = 101325;
    m->T_ref = 300;
    m->ior_scale = 1;
    m->density.kind = RRV_FIELD_CONSTANT;
    m->density.value = 1;
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
