/* Tests of the scene file section: every example in scenes/README.md parses,
   every malformed input in test/corpus/ fails with its exact message, the
   gridvol reader applies every rule of the gridvol format (rrv.h, CONVENTIONS), and the OBJ loader
   triangulates and reports errors by OBJ line. Run from the repository root
   with the build folder as the only argument.

   The library is built here with a counting allocator so the tests can see
   the largest allocation (the grid size limit must trip before allocating)
   and make the Nth allocation fail (every failure must be clean). */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <dirent.h>
#include <float.h>
#include <locale.h>

#include "alloc_hook.h" /* counts allocations, refuses the Nth on request */
#define RRV_RESEARCH /* the midpoint scheme and the leapfrog stepper, which this tests too */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"

/* ---- helpers ------------------------------------------------------------ */

static const char *t_build_dir = "build"; /* argv[1]: scratch files go here */

static char *read_text(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    char *buf;
    long n;
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    buf = (char *)malloc((size_t)n + 1);
    if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    if (buf) {
        buf[n] = '\0';
        if (size) *size = (size_t)n;
    }
    return buf;
}

/* A tiny in-memory file system for the read_file callback. */
typedef struct memfile {
    const char *path;
    const void *data;
    size_t size;
} memfile;
typedef struct memfs {
    const memfile *files;
    int count;
    int reads;
} memfs;

static int memfs_read(void *user, const char *path, void **data, size_t *size)
{
    memfs *fs = (memfs *)user;
    int i;
    fs->reads++;
    for (i = 0; i < fs->count; ++i)
        if (strcmp(fs->files[i].path, path) == 0) {
            void *copy = RRV_MALLOC(fs->files[i].size + 1);
            if (!copy) return 1;
            memcpy(copy, fs->files[i].data, fs->files[i].size);
            *data = copy;
            *size = fs->files[i].size;
            return 0;
        }
    return 1;
}

static rrv_result parse_str(const char *text, const rrv_load_options *opt, rrv_scene **s,
                            rrv_error *err)
{
    return rrv_scene_parse(text, strlen(text), "t.rrv", "dir", opt, s, err);
}

/* Parses `text` expecting failure with `code` at `line` with `message`. */
static void expect_error(const char *text, rrv_result code, int line, const char *message)
{
    rrv_scene *s = (rrv_scene *)1;
    rrv_error err;
    rrv_result r = parse_str(text, NULL, &s, &err);
    CHECKF(r == code, "got %s for %s", rrv_result_string(r), text);
    CHECK(s == NULL);
    CHECKF(err.line == line, "line %d, expected %d: %s", err.line, line, err.message);
    CHECKF(strcmp(err.message, message) == 0, "message \"%s\", expected \"%s\"", err.message, message);
    CHECK(strcmp(err.file, "t.rrv") == 0);
}

/* gridvol bytes built by hand, little endian whatever the host. */
typedef struct gridbuf {
    unsigned char b[4096];
    size_t n;
} gridbuf;

static void put32(gridbuf *g, uint32_t u)
{
    g->b[g->n++] = (unsigned char)(u & 255);
    g->b[g->n++] = (unsigned char)((u >> 8) & 255);
    g->b[g->n++] = (unsigned char)((u >> 16) & 255);
    g->b[g->n++] = (unsigned char)(u >> 24);
}
static void putf(gridbuf *g, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    put32(g, u);
}
static void grid_header(gridbuf *g, int32_t nx, int32_t ny, int32_t nz, int32_t ch,
                        const float box[6])
{
    int i;
    g->n = 0;
    g->b[g->n++] = 'V';
    g->b[g->n++] = 'O';
    g->b[g->n++] = 'L';
    g->b[g->n++] = 3;
    put32(g, 1);
    put32(g, (uint32_t)nx);
    put32(g, (uint32_t)ny);
    put32(g, (uint32_t)nz);
    put32(g, (uint32_t)ch);
    for (i = 0; i < 6; ++i) putf(g, box[i]);
}
static const float unit_box[6] = {0, 0, 0, 1, 1, 1};

/* A valid 2x2x2 grid with values v0 + i/8. */
static void grid_valid(gridbuf *g, float v0)
{
    int i;
    grid_header(g, 2, 2, 2, 1, unit_box);
    for (i = 0; i < 8; ++i) putf(g, v0 + (float)i / 8.0f);
}

static void expect_grid_error(const gridbuf *g, size_t limit, int nonneg, rrv_result code,
                              const char *message)
{
    rrv_grid grid;
    rrv_error err;
    rrv_result r = rrv_grid_read_memory(g->b, g->n, "x.vol", limit, nonneg, &grid, &err);
    CHECKF(r == code, "got %s, expected %s (%s)", rrv_result_string(r), rrv_result_string(code), err.message);
    CHECK(grid.data == NULL);
    CHECKF(strcmp(err.message, message) == 0, "message \"%s\", expected \"%s\"", err.message, message);
    CHECK(strcmp(err.file, "x.vol") == 0 && err.line == 0);
    if (r == RRV_OK) rrv_free(grid.data);
}

/* ---- (a) the README examples ------------------------------------------- */

static void test_readme_examples(void)
{
    static const char *const statements[] = {
        "camera", "render", "ambient", "material", "sphere", "quad", "triangle", "mesh",
        "environment", "medium", "density", "temperature", "pressure", "ior"};
    static const char *const kinds[] = {" constant ", " blob ", " noise ", " grid ", " luneburg ",
                                        " fisheye ", " slab ", " shell ", " gas ", " checker ",
                                        " gradient ", " points ", " file "};
    int seen[sizeof statements / sizeof *statements] = {0};
    int seen_kind[sizeof kinds / sizeof *kinds] = {0};
    size_t size, i;
    char *md = read_text("scenes/README.md", &size);
    char *p;
    int blocks = 0;
    CHECKF(md != NULL, "cannot read scenes/README.md (run from the repository root)");
    if (!md) return;
    p = md;
    while ((p = strstr(p, "\n```rrv\n")) != NULL) {
        char *body = p + 8, *end = strstr(body, "\n```"), *text, *line;
        size_t n;
        int has_camera = 0;
        rrv_scene *s = NULL;
        rrv_error err;
        rrv_result r;
        CHECK(end != NULL);
        if (!end) break;
        n = (size_t)(end - body) + 1;
        /* blocks without a camera get one in front, as the README says */
        for (line = body; line < end; line = strchr(line, '\n') + 1) {
            for (i = 0; i < sizeof statements / sizeof *statements; ++i) {
                size_t k = strlen(statements[i]);
                if (strncmp(line, statements[i], k) == 0 && line[k] == ' ') seen[i] = 1;
            }
            if (strncmp(line, "camera ", 7) == 0) has_camera = 1;
        }
        text = (char *)malloc(n + 64);
        sprintf(text, "%s", has_camera ? "" : "camera eye 0 1 5 look 0 1 0\n");
        memcpy(text + strlen(text), body, n);
        {
            size_t len = (has_camera ? 0 : strlen("camera eye 0 1 5 look 0 1 0\n")) + n;
            char save = text[len];
            text[len] = '\0';
            for (i = 0; i < sizeof kinds / sizeof *kinds; ++i)
                if (strstr(text, kinds[i])) seen_kind[i] = 1;
            text[len] = save;
            /* the text is deliberately not NUL-terminated at `len` */
            r = rrv_scene_parse(text, len, "scenes/README.md", "scenes", NULL, &s, &err);
        }
        ++blocks;
        CHECKF(r == RRV_OK, "README block %d: %s:%d: %s", blocks, err.file, err.line, err.message);
        rrv_scene_free(s);
        free(text);
        p = end;
    }
    CHECKF(blocks >= 20, "only %d rrv blocks", blocks);
    for (i = 0; i < sizeof statements / sizeof *statements; ++i)
        CHECKF(seen[i], "no README example of \"%s\"", statements[i]);
    for (i = 0; i < sizeof kinds / sizeof *kinds; ++i)
        CHECKF(seen_kind[i], "no README example of kind \"%s\"", kinds[i]);
    free(md);
}

/* ---- (b) the malformed corpus ------------------------------------------- */

static const struct corpus_case {
    const char *name;
    rrv_result code;
} corpus_cases[] = {
    {"albedo_mix", RRV_ERROR_PARSE},       {"bad_choice", RRV_ERROR_PARSE},
    {"sphere_huge", RRV_ERROR_PARSE},      {"box_huge", RRV_ERROR_PARSE},
    {"emissionnee_choice", RRV_ERROR_PARSE}, {"cellcentered_choice", RRV_ERROR_PARSE},
    {"bad_obj_line", RRV_ERROR_PARSE},     {"blob_mix", RRV_ERROR_PARSE},
    {"box_empty", RRV_ERROR_PARSE},        {"camera_up_parallel", RRV_ERROR_PARSE},
    {"duplicate_camera", RRV_ERROR_PARSE}, {"duplicate_key", RRV_ERROR_PARSE},
    {"duplicate_material", RRV_ERROR_PARSE}, {"extra_value", RRV_ERROR_PARSE},
    {"field_twice", RRV_ERROR_PARSE},      {"grid_bad_magic", RRV_ERROR_FORMAT},
    {"nanovdb_bad_magic", RRV_ERROR_FORMAT}, {"nanovdb_no_grids", RRV_ERROR_FORMAT},
    {"nanovdb_truncated", RRV_ERROR_FORMAT}, {"nanovdb_version", RRV_ERROR_FORMAT},
    {"nanovdb_zip", RRV_ERROR_FORMAT},
    {"grid_bad_version", RRV_ERROR_FORMAT}, {"grid_channels", RRV_ERROR_FORMAT},
    {"grid_empty_box", RRV_ERROR_FORMAT},  {"grid_encoding", RRV_ERROR_FORMAT},
    {"grid_huge", RRV_ERROR_LIMIT},        {"grid_infinite_box", RRV_ERROR_FORMAT},
    {"grid_nan", RRV_ERROR_FORMAT},        {"grid_negative", RRV_ERROR_FORMAT},
    {"grid_small_res", RRV_ERROR_FORMAT},  {"grid_three_channel_T", RRV_ERROR_FORMAT},
    {"grid_truncated", RRV_ERROR_FORMAT},  {"ior_only_kind", RRV_ERROR_PARSE},
    {"mesh_index_range", RRV_ERROR_PARSE}, {"missing_grid_file", RRV_ERROR_IO},
    {"missing_obj_file", RRV_ERROR_IO},    {"missing_required", RRV_ERROR_PARSE},
    {"missing_value", RRV_ERROR_PARSE},    {"missing_value_mid", RRV_ERROR_PARSE},
    {"no_camera", RRV_ERROR_PARSE},        {"not_a_number", RRV_ERROR_PARSE},
    {"not_finite", RRV_ERROR_PARSE},       {"not_integer", RRV_ERROR_PARSE},
    {"obj_index_range", RRV_ERROR_PARSE},  {"obj_short_face", RRV_ERROR_PARSE},
    {"obj_vertex_range", RRV_ERROR_PARSE}, {"bom_then_error", RRV_ERROR_PARSE},
    {"quad_parallel", RRV_ERROR_PARSE},    {"range_albedo", RRV_ERROR_PARSE},
    {"range_ambient", RRV_ERROR_PARSE},    {"range_fov", RRV_ERROR_PARSE},
    {"range_g", RRV_ERROR_PARSE},          {"range_octaves", RRV_ERROR_PARSE},
    {"range_radius", RRV_ERROR_PARSE},     {"range_resolution", RRV_ERROR_PARSE},
    {"range_spp", RRV_ERROR_PARSE},        {"temperature_constant", RRV_ERROR_PARSE},
    {"undefined_material", RRV_ERROR_PARSE}, {"undefined_medium", RRV_ERROR_PARSE},
    {"unknown_key", RRV_ERROR_PARSE},      {"unknown_statement", RRV_ERROR_PARSE},
    {"unterminated_quote", RRV_ERROR_PARSE},
    {"misspelt_statement", RRV_ERROR_PARSE}, {"misspelt_key", RRV_ERROR_PARSE},
    {"misspelt_choice", RRV_ERROR_PARSE},  {"far_statement", RRV_ERROR_PARSE},
    {"misspelt_material", RRV_ERROR_PARSE},
    {"hex_number", RRV_ERROR_PARSE},       {"nan_number", RRV_ERROR_PARSE},
    {"nul_byte", RRV_ERROR_PARSE},         {"control_byte", RRV_ERROR_PARSE},
    {"too_many_media", RRV_ERROR_LIMIT},   {"camera_far", RRV_ERROR_PARSE},
    {"camera_up_zero", RRV_ERROR_PARSE},   {"grid_is_directory", RRV_ERROR_IO},
    {"obj_is_directory", RRV_ERROR_IO},    {"obj_nul_byte", RRV_ERROR_PARSE},
    /* refused by the limits of BOUNDS (rrv.h) */
    {"bound_ambient", RRV_ERROR_PARSE},    {"bound_bendtolerance", RRV_ERROR_PARSE},
    {"bound_dense_grid", RRV_ERROR_PARSE}, {"bound_extinction", RRV_ERROR_PARSE},
    {"bound_fisheye", RRV_ERROR_PARSE},    {"bound_gas_cold", RRV_ERROR_PARSE}, {"bound_gas_cold_grid", RRV_ERROR_PARSE}, {"bound_gas_pressure", RRV_ERROR_PARSE},
    {"bound_ior_alternating", RRV_ERROR_PARSE}, {"bound_ior_blob", RRV_ERROR_PARSE},
    {"bound_ior_nonpositive", RRV_ERROR_PARSE}, {"bound_ior_shell", RRV_ERROR_PARSE},
    {"bound_ior_slab", RRV_ERROR_PARSE},   {"bound_light", RRV_ERROR_PARSE},
    {"bound_medium_emission", RRV_ERROR_PARSE}, {"bound_mueta", RRV_ERROR_PARSE},
    {"bound_sigma_overflow", RRV_ERROR_PARSE}, {"bound_step", RRV_ERROR_PARSE},
};
#define CORPUS_COUNT (int)(sizeof corpus_cases / sizeof *corpus_cases)

static void test_corpus(void)
{
    int i;
    for (i = 0; i < CORPUS_COUNT; ++i) {
        char path[256], expect_path[256], got[1024];
        char *expect;
        rrv_scene *s = NULL;
        rrv_error err;
        rrv_result r;
        size_t n;
        sprintf(path, "test/corpus/%s.rrv", corpus_cases[i].name);
        sprintf(expect_path, "test/corpus/%s.expect", corpus_cases[i].name);
        expect = read_text(expect_path, &n);
        CHECKF(expect != NULL, "missing %s", expect_path);
        if (!expect) continue;
        while (n > 0 && (expect[n - 1] == '\n' || expect[n - 1] == '\r')) expect[--n] = '\0';
        r = rrv_scene_load(path, NULL, &s, &err);
        CHECKF(r == corpus_cases[i].code, "%s: got %s, expected %s", path, rrv_result_string(r),
               rrv_result_string(corpus_cases[i].code));
        CHECK(s == NULL);
        /* the CLI's format: no line number where none applies */
        if (err.line > 0)
            sprintf(got, "%s:%d: %s", err.file, err.line, err.message);
        else
            sprintf(got, "%s: %s", err.file, err.message);
        CHECKF(strcmp(got, expect) == 0, "\n    got      %s\n    expected %s", got, expect);
        free(expect);
    }
}

/* Every .rrv in the corpus has an .expect and a row in the table above. */
static void test_corpus_complete(void)
{
    DIR *d = opendir("test/corpus");
    struct dirent *e;
    int files = 0;
    CHECK(d != NULL);
    if (!d) return;
    while ((e = readdir(d)) != NULL) {
        size_t n = strlen(e->d_name);
        int i, found = 0;
        if (n < 5 || strcmp(e->d_name + n - 4, ".rrv") != 0) continue;
        ++files;
        for (i = 0; i < CORPUS_COUNT; ++i)
            if (strlen(corpus_cases[i].name) == n - 4 && strncmp(corpus_cases[i].name, e->d_name, n - 4) == 0)
                found = 1;
        CHECKF(found, "test/corpus/%s has no row in corpus_cases", e->d_name);
    }
    closedir(d);
    CHECKF(files == CORPUS_COUNT, "%d .rrv files, %d table rows", files, CORPUS_COUNT);
}

/* ---- scene semantics ------------------------------------------------------ */

static void test_defaults_and_values(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    const char *text =
        "camera eye 1 2 3 look 0 0 0\n"
        "sphere center 0 0 0 radius 2 L 1 2 3 scale 2\n"
        "material m checker\n"
        "quad origin 0 0 0 u 1 0 0 v 0 0 1 material m\n"
        "medium a box 0 0 0 1 2 4 albedo 0.25 0.5 1 sigma_t 4 4 4\n"
        "density a noise\n"
        "temperature a constant 500 temperatureoffset 100 temperaturescale 2 blackbody off\n"
        "ior a slab normal 0 2 0 gradient 0.1 iorscale 3\n"
        "medium b box -1 -1 -1 1 1 1\n"
        "temperature b blob center 0 0 0 radius 1\n"
        "temperature b blob center 1 0 0 radius 1 weight 2 base 7\n"
        "pressure b blob center 0 0 0 radius 1 base 5\n"
        "ior b gas T_ref 290\n"
        "environment constant\n";
    rrv_result r = parse_str(text, NULL, &s, &err);
    CHECKF(r == RRV_OK, "%s:%d: %s", err.file, err.line, err.message);
    if (r != RRV_OK) return;
    CHECK(s->camera.fov == 40 && s->camera.width == 320 && s->camera.height == 240);
    CHECK(s->camera.up.y == 1 && s->camera.eye.z == 3);
    CHECK(s->settings.spp == 16 && s->settings.max_depth == 32 && s->settings.seed == 0);
    CHECK(s->settings.integrator == RRV_INTEGRATOR_DEFAULT && s->settings.stepper == RRV_STEPPER_DEFAULT);
    CHECK(s->settings.refraction == RRV_REFRACTION_DEFAULT && s->settings.majorant_cells == 0);
    CHECK(s->settings.bend_tolerance == 0.01 && s->settings.mu_eta == 0 && s->settings.step == 0);
    /* no `ambient`: the air around gas b, at its ambient state, iorscale 1 */
    CHECK(s->settings.ambient_ior == 0 && s->ambient_ior == 1.0 + (1.000292 - 1.0));
    CHECK(s->shape_count == 2 && s->material_count == 2);
    CHECK(strcmp(s->materials[s->shapes[0].material].name, "default") == 0);
    CHECK(s->materials[0].albedo[1] == 0.5);
    CHECK(s->shapes[0].L[0] == 2 && s->shapes[0].L[2] == 6 && s->shapes[0].radius == 2);
    CHECK(s->materials[1].kind == RRV_MATERIAL_CHECKER && s->materials[1].albedo[0] == 0.8 &&
          s->materials[1].albedo2[2] == 0.2 && s->materials[1].checker_scale == 1);
    CHECK(s->shapes[1].kind == RRV_SHAPE_QUAD && s->shapes[1].material == 1 && s->shapes[1].L[0] == 0);
    CHECK(s->medium_count == 2);
    {
        const rrv_medium *a = &s->media[0], *b = &s->media[1];
        CHECK(a->sigma_s[0] == 1 && a->sigma_a[0] == 3 && a->sigma_s[2] == 4 && a->sigma_a[2] == 0);
        CHECK(a->scale == 1 && a->g == 0 && a->Lescale == 1 && a->Le[0] == 0);
        CHECK(a->density.kind == RRV_FIELD_NOISE && a->density.noise.octaves == 5 &&
              a->density.noise.frequency == 1 && a->density.noise.lacunarity == 2 &&
              a->density.noise.gain == 0.5 && a->density.noise.threshold == 0 &&
              a->density.noise.falloff == RRV_FALLOFF_SPHERE && a->density.amplitude == 1 &&
              a->density.base == 0);
        CHECK(a->density.noise.center.x == 0.5 && a->density.noise.center.y == 1 &&
              a->density.noise.center.z == 2 && a->density.noise.radius == 0.5);
        CHECK(a->temperature.kind == RRV_FIELD_CONSTANT && a->temperature.value == 500 &&
              a->temperatureoffset == 100 && a->temperaturescale == 2 && a->blackbody_emission == 0);
        CHECK(a->ior.kind == RRV_FIELD_SLAB && a->ior.normal.y == 1 && a->ior.normal.x == 0 &&
              a->ior.gradient == 0.1 && a->ior_scale == 3 && a->ior.center.y == 1);
        CHECK(a->eta_ref == 1.000292 && a->P_ref == 101325 && a->T_ref == 300 && !a->ior_from_gas);
        CHECK(b->temperature.kind == RRV_FIELD_BLOBS && b->temperature.blob_count == 2 &&
              b->temperature.base == 300 && b->temperature.blobs[1].weight == 2 &&
              b->temperature.blobs[0].weight == 1 && b->blackbody_emission == 1);
        CHECK(b->pressure.kind == RRV_FIELD_BLOBS && b->pressure.base == 5);
        CHECK(b->ior.kind == RRV_FIELD_NONE && b->ior_from_gas == 1 && b->T_ref == 290);
        CHECK(b->sigma_a[0] == 1 && b->sigma_s[0] == 1 && b->density.kind == RRV_FIELD_NONE);
    }
    CHECK(s->environment.kind == RRV_ENV_CONSTANT && s->environment.L[1] == 1);
    CHECK(s->bytes >= sizeof *s + 2 * sizeof(rrv_shape) + 2 * sizeof(rrv_medium) && s->grid_bytes == 0);
    CHECK(strcmp(s->path, "t.rrv") == 0);
    rrv_scene_free(s);
}

static void test_render_and_seed(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r = parse_str("camera eye 0 0 1 look 0 0 0 up 0 0 1e-3 fov 10 resolution 7 5\n"
                             "render spp 16777216 maxdepth 1024 seed 18446744073709551615 "
                             "integrator eikonal stepper rk4 step 0.5 mueta 3 bendtolerance 1\n"
                             "ambient ior 1.5\n",
                             NULL, &s, &err);
    /* up 0 0 1e-3 is parallel to the view: must fail */
    CHECK(r == RRV_ERROR_PARSE && strcmp(err.message, "camera: up is parallel to the view direction") == 0);
    r = parse_str("camera eye 0 0 1 look 0 0 0 fov 10 resolution 7 5\n"
                  "render spp 16777216 maxdepth 1024 seed 18446744073709551615 "
                  "integrator eikonal stepper rk4 step 0.5 mueta 3 bendtolerance 1 refraction midpoint "
                  "majorantcells 256\n"
                  "ambient ior 1.5\n",
                  NULL, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r != RRV_OK) return;
    CHECK(s->camera.width == 7 && s->camera.height == 5 && s->camera.fov == 10);
    CHECK(s->settings.spp == 16777216 && s->settings.max_depth == 1024);
    CHECK(s->settings.seed == UINT64_MAX);
    CHECK(s->settings.integrator == RRV_INTEGRATOR_EIKONAL && s->settings.stepper == RRV_STEPPER_RK4);
    CHECK(s->settings.step == 0.5 && s->settings.mu_eta == 3 && s->settings.bend_tolerance == 1);
    CHECK(s->settings.ambient_ior == 1.5);
    CHECK(s->settings.refraction == RRV_REFRACTION_MIDPOINT && s->settings.majorant_cells == 256);
    rrv_scene_free(s);
    r = parse_str("camera eye 0 0 1 look 0 0 0\nrender stepper leapfrog refraction poisson integrator refractive\n",
                  NULL, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r != RRV_OK) return;
    CHECK(s->settings.stepper == RRV_STEPPER_LEAPFROG && s->settings.refraction == RRV_REFRACTION_POISSON &&
          s->settings.integrator == RRV_INTEGRATOR_REFRACTIVE);
    rrv_scene_free(s);
    r = parse_str("camera eye 0 0 1 look 0 0 0\nrender refraction comb stepper default\n", NULL, &s, &err);
    CHECK(r == RRV_OK && s->settings.refraction == RRV_REFRACTION_COMB && s->settings.stepper == RRV_STEPPER_DEFAULT);
    rrv_scene_free(s);
    r = parse_str("camera eye 0 0 1 look 0 0 0\nrender sampler sobol\n", NULL, &s, &err);
    CHECK(r == RRV_OK && s->settings.sampler == RRV_SAMPLER_SOBOL);
    rrv_scene_free(s);
    r = parse_str("camera eye 0 0 1 look 0 0 0\nrender sampler pcg\n", NULL, &s, &err);
    CHECK(r == RRV_OK && s->settings.sampler == RRV_SAMPLER_PCG);
    rrv_scene_free(s);
}

static void test_statement_errors(void)
{
    const char *cam = "camera eye 0 0 5 look 0 0 0\n";
    char buf[512];
#define WITH_CAM(x) (sprintf(buf, "%s%s", cam, x), buf)
    expect_error(WITH_CAM("render seed 18446744073709551616\n"), RRV_ERROR_PARSE, 2,
                 "render: seed must be in [0, 18446744073709551615], got 18446744073709551616");
    expect_error(WITH_CAM("render seed -1\n"), RRV_ERROR_PARSE, 2,
                 "render: seed must be in [0, 18446744073709551615], got -1");
    expect_error(WITH_CAM("render spp 99999999999999999999999\n"), RRV_ERROR_PARSE, 2,
                 "render: spp must be in [1, 16777216], got 99999999999999999999999");
    expect_error(WITH_CAM("render twice\n"), RRV_ERROR_PARSE, 2, "render: unknown key \"twice\"");
    expect_error(WITH_CAM("render\nrender\n"), RRV_ERROR_PARSE, 3, "render given twice");
    expect_error(WITH_CAM("render majorantcells 257\n"), RRV_ERROR_PARSE, 2,
                 "render: majorantcells must be in [0, 256], got 257");
    expect_error(WITH_CAM("render stepper euler\n"), RRV_ERROR_PARSE, 2,
                 "render: stepper must be one of default|leapfrog|rk4, got \"euler\"");
    expect_error(WITH_CAM("render bendtolerance 0\n"), RRV_ERROR_PARSE, 2,
                 "render: bendtolerance must be in (0, 1], got 0");
    expect_error(WITH_CAM("sphere center 0 0 0 radius nan\n"), RRV_ERROR_PARSE, 2,
                 "sphere: radius must be finite, got nan");
    expect_error(WITH_CAM("sphere center 0 0 0 radius 1e999\n"), RRV_ERROR_PARSE, 2,
                 "sphere: radius must be finite, got 1e999");
    expect_error(WITH_CAM("sphere center 0 0 0 radius 1 material\n"), RRV_ERROR_PARSE, 2,
                 "sphere: \"material\" needs a value");
    expect_error(WITH_CAM("sphere center 0 0 0 radius 1 L 1 1 1 scale 1e300 L 1 1 1\n"), RRV_ERROR_PARSE, 2,
                 "sphere: \"L\" given twice");
    expect_error(WITH_CAM("sphere center 0 0 0 radius 1 L 1e300 1 1 scale 1e300\n"), RRV_ERROR_PARSE, 2,
                 "sphere: L times scale is not finite");
    expect_error(WITH_CAM("triangle p0 0 0 0 p1 1 1 1 p2 2 2 2\n"), RRV_ERROR_PARSE, 2,
                 "triangle: the points are collinear (zero area)");
    expect_error(WITH_CAM("quad origin 1e150 0 0 u 1e150 0 0 v 0 1 0\n"), RRV_ERROR_PARSE, 2,
                 "quad: a corner must be in [-1e+150, 1e+150], got 2e+150");
    expect_error(WITH_CAM("material\n"), RRV_ERROR_PARSE, 2, "material: missing name");
    expect_error(WITH_CAM("material m\n"), RRV_ERROR_PARSE, 2, "material: missing kind (diffuse or checker)");
    expect_error(WITH_CAM("material m glossy\n"), RRV_ERROR_PARSE, 2,
                 "material: unknown kind \"glossy\" (expected diffuse or checker)");
    expect_error(WITH_CAM("material m diffuse albedo2 1 1 1\n"), RRV_ERROR_PARSE, 2,
                 "material: unknown key \"albedo2\" (did you mean \"albedo\"?)");
    /* kinds and choices get the hint too; a quoted keyword does not (the quotes are the fault) */
    expect_error(WITH_CAM("material m difuse\n"), RRV_ERROR_PARSE, 2,
                 "material: unknown kind \"difuse\" (expected diffuse or checker) (did you mean \"diffuse\"?)");
    expect_error(WITH_CAM("medium g box -1 -1 -1 1 1 1\nior g sheel\n"), RRV_ERROR_PARSE, 3,
                 "ior: unknown kind \"sheel\" (expected constant, blob, noise, grid, nanovdb, luneburg, fisheye, "
                 "slab, shell or gas) (did you mean \"shell\"?)");
    expect_error(WITH_CAM("render stepper rk\n"), RRV_ERROR_PARSE, 2,
                 "render: stepper must be one of default|leapfrog|rk4, got \"rk\" (did you mean \"rk4\"?)");
    expect_error(WITH_CAM("\"render\" spp 2\n"), RRV_ERROR_PARSE, 2, "unknown statement \"render\"");
    /* a swap of neighbours is one edit, so a short word still gets its hint */
    expect_error(WITH_CAM("iro g constant 1.3\n"), RRV_ERROR_PARSE, 2, "unknown statement \"iro\" (did you mean \"ior\"?)");
    /* two edits from "quad", but not fewer than half its length: no hint */
    expect_error(WITH_CAM("qd\n"), RRV_ERROR_PARSE, 2, "unknown statement \"qd\"");
    expect_error(WITH_CAM("material a234567890123456789012345678901234567890123456789012345678901234 diffuse\n"),
                 RRV_ERROR_PARSE, 2,
                 /* quoted tokens are clipped to 60 characters in messages */
                 "material: name \"a23456789012345678901234567890123456789012345678901234567890\" "
                 "must be 1 to 63 printable characters");
    expect_error(WITH_CAM("environment constant\nenvironment constant\n"), RRV_ERROR_PARSE, 3,
                 "environment given twice");
    expect_error(WITH_CAM("environment gradient top 1 1 1\n"), RRV_ERROR_PARSE, 2,
                 "environment: missing \"bottom\"");
    expect_error(WITH_CAM("environment sky\n"), RRV_ERROR_PARSE, 2,
                 "environment: unknown kind \"sky\" (expected constant or gradient)");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1\n"), RRV_ERROR_PARSE, 2, "medium: \"box\" needs 6 numbers, got 5");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\nmedium m box 0 0 0 1 1 1\n"), RRV_ERROR_PARSE, 3,
                 "medium \"m\" defined twice");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1 albedo 1 1 1\n"), RRV_ERROR_PARSE, 2,
                 "medium: \"albedo\" needs \"sigma_t\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1 sigma_t 1 1 1\n"), RRV_ERROR_PARSE, 2,
                 "medium: \"sigma_t\" needs \"albedo\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m constant 1 2\n"), RRV_ERROR_PARSE, 3,
                 "density: \"constant\" needs 1 number, got 2");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m constant\n"), RRV_ERROR_PARSE, 3,
                 "density: \"constant\" needs 1 number, got 0");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m constant x\n"), RRV_ERROR_PARSE, 3,
                 "density: expected a number for \"constant\", got \"x\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m constant -1\n"), RRV_ERROR_PARSE, 3,
                 "density: constant must be >= 0, got -1");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\npressure m constant 0\n"), RRV_ERROR_PARSE, 3,
                 "pressure: constant must be > 0, got 0");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m grid\n"), RRV_ERROR_PARSE, 3,
                 "density: \"grid\" needs a file path");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m\n"), RRV_ERROR_PARSE, 3,
                 "density: missing kind (constant, blob, noise, grid or nanovdb)");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m noise octaves 2.5\n"), RRV_ERROR_PARSE, 3,
                 "density: octaves must be an integer, got 2.5");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m noise falloff cube\n"), RRV_ERROR_PARSE, 3,
                 "density: falloff must be one of none|sphere|plume, got \"cube\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ndensity m noise iorscale 2\n"), RRV_ERROR_PARSE, 3,
                 "density: unknown key \"iorscale\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\nior m gas\nior m constant 0.1\n"), RRV_ERROR_PARSE, 4,
                 "ior: given twice for medium \"m\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\nior m slab normal 0 0 0 gradient 1\n"), RRV_ERROR_PARSE, 3,
                 "ior: slab normal must be nonzero");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\nior m shell radius 1 thickness 0.1\n"), RRV_ERROR_PARSE, 3,
                 "ior: missing \"amplitude\"");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\nior m constant -1\n"), RRV_ERROR_PARSE, 3,
                 "ior: constant (the refractivity eta - 1) must be > -1, got -1");
    expect_error(WITH_CAM("medium m box 0 0 0 1 1 1\ntemperature m constant 300 temperaturescale 0\n"),
                 RRV_ERROR_PARSE, 3, "temperature: temperaturescale must be > 0, got 0");
    expect_error(WITH_CAM("mesh points 0 0 0 1 0 0 0 1 0\n"), RRV_ERROR_PARSE, 2,
                 "mesh: \"indices\" needs a multiple of 3 integers, got 0");
    expect_error(WITH_CAM("mesh points 0 0 0 1 0 0 0 1 indices 0 1 2\n"), RRV_ERROR_PARSE, 2,
                 "mesh: \"points\" needs a multiple of 3 numbers, got 8");
    expect_error(WITH_CAM("mesh points 0 0 0 1 0 0 0 1 0 indices 0 1 -2\n"), RRV_ERROR_PARSE, 2,
                 "mesh: indices must be in [0, 2147483647], got -2");
    expect_error(WITH_CAM("mesh points 0 0 0 indices 0 0 0 file a.obj\n"), RRV_ERROR_PARSE, 2,
                 "mesh: give \"file\" or \"points\", not both");
    expect_error(WITH_CAM("mesh\n"), RRV_ERROR_PARSE, 2, "mesh: missing \"file\" or \"points\"");
    expect_error(WITH_CAM("mesh points x\n"), RRV_ERROR_PARSE, 2, "mesh: expected a number for \"points\", got \"x\"");
    expect_error(WITH_CAM("sphere center 0 0 0 radius 1 \"radius\" 2\n"), RRV_ERROR_PARSE, 2,
                 "sphere: unknown key \"radius\"");
    expect_error("", RRV_ERROR_PARSE, 0, "no camera statement");
    expect_error("camera eye 0 0 0 look 0 0 0\n", RRV_ERROR_PARSE, 1,
                 "camera: eye and look must be distinct finite points");
    expect_error("camera look 0 0 0\n", RRV_ERROR_PARSE, 1, "camera: missing \"eye\"");
#undef WITH_CAM
}

/* Comments, tabs, CRLF, quotes and a text that is not NUL-terminated. */
static void test_lexing(void)
{
    const char *text = "# comment\r\n\tcamera\teye 0 0 5 look 0 0 0 # trailing\r\n"
                       "material \"two words\" diffuse\r\n"
                       "sphere center 0 0 0 radius 12 material \"two words\"";
    rrv_scene *s = NULL;
    rrv_error err;
    /* stop the buffer right after "radius 1": the 2 must not be read */
    size_t cut = (size_t)(strstr(text, "radius 12") - text) + 8;
    rrv_result r = rrv_scene_parse(text, cut, "t.rrv", NULL, NULL, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(s->shape_count == 1 && s->shapes[0].radius == 1);
        CHECK(strcmp(s->materials[s->shapes[0].material].name, "default") == 0);
        rrv_scene_free(s);
    }
    r = rrv_scene_parse(text, strlen(text), "t.rrv", NULL, NULL, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(s->shapes[0].radius == 12 && strcmp(s->materials[s->shapes[0].material].name, "two words") == 0);
        rrv_scene_free(s);
    }
    {
        /* a UTF-8 byte order mark before the first statement is not part of it */
        static const char marked[] = "\xEF\xBB\xBF" "camera eye 0 0 5 look 0 0 0\nsphere center 0 0 0 radius 1\n";
        r = rrv_scene_parse(marked, sizeof marked - 1, "t.rrv", NULL, NULL, &s, &err);
        CHECKF(r == RRV_OK, "%s", err.message);
        if (r == RRV_OK) rrv_scene_free(s);
        /* only there: one after it is an unknown byte of the statement */
        r = rrv_scene_parse(marked, 2, "t.rrv", NULL, NULL, &s, &err);
        CHECK(r == RRV_ERROR_PARSE && s == NULL && err.line == 1);
    }
    r = rrv_scene_parse(NULL, 0, NULL, NULL, NULL, &s, &err);
    CHECK(r == RRV_ERROR_PARSE && s == NULL && strcmp(err.message, "no camera statement") == 0);
    r = rrv_scene_parse(NULL, 3, "t.rrv", NULL, NULL, &s, &err);
    CHECK(r == RRV_ERROR_ARGUMENT);
    r = rrv_scene_load("test/corpus/no_such_scene.rrv", NULL, &s, &err);
    CHECK(r == RRV_ERROR_IO && s == NULL && strcmp(err.file, "test/corpus/no_such_scene.rrv") == 0 && err.line == 0);
}

/* Numbers are decimal only, and their values are those of C's strtod in the
   "C" locale whatever the host's locale. */
static void test_number_syntax(void)
{
    static const char *const good[] = {"1", "-2.5", "+3", ".5", "5.", "1e3", "1E+03", "-0.1",
                                       "0.1", "2.2250738585072014e-308", "1.7976931348623157e308",
                                       "4.9e-324", "123456789012345678901234567890"};
    static const char *const bad[] = {"0x1p3", "0X10", "0x", "1e", "e5", ".", "+", "-", "1.2.3",
                                      "1,5", "1e+", "infinit", "nanx", "1f", "1d", "--1",
                                      "1e5.5", "0b1", "nan(1)", "1 "};
    static const char *const nonfinite[] = {"inf", "-Infinity", "NaN", "+INF", "1e400"};
    size_t i;
    for (i = 0; i < sizeof good / sizeof *good; ++i) {
        rrv__sf_tok t;
        double v = 0;
        t.p = good[i];
        t.n = strlen(good[i]);
        t.quoted = 0;
        CHECKF(rrv__sf_tok_number(&t, &v) && v == strtod(good[i], NULL), "\"%s\" gave %.17g",
               good[i], v);
    }
    for (i = 0; i < sizeof bad / sizeof *bad; ++i) {
        rrv__sf_tok t;
        double v = 0;
        t.p = bad[i];
        t.n = strlen(bad[i]);
        t.quoted = 0;
        CHECKF(!rrv__sf_tok_number(&t, &v), "\"%s\" was taken as the number %.17g", bad[i], v);
    }
    for (i = 0; i < sizeof nonfinite / sizeof *nonfinite; ++i) {
        rrv__sf_tok t;
        double v = 0;
        t.p = nonfinite[i];
        t.n = strlen(nonfinite[i]);
        t.quoted = 0;
        CHECKF(rrv__sf_tok_number(&t, &v) && !(v >= -DBL_MAX && v <= DBL_MAX),
               "\"%s\" is not recognised as a non-finite number", nonfinite[i]);
    }
    expect_error("camera eye 0 0 0x5 look 0 0 0\n", RRV_ERROR_PARSE, 1,
                 "camera: expected a number for \"eye\", got \"0x5\"");
}

/* Selects a decimal-comma LC_NUMERIC: an installed one, or one built with
   localedef into the build folder (glibc reads it through LOCPATH). */
static int use_comma_locale(const char *build)
{
    static const char *const names[] = {"de_DE.UTF-8", "de_DE.utf8", "de_DE", "fr_FR.UTF-8",
                                        "fr_FR.utf8", "nl_NL.UTF-8", "ru_RU.UTF-8"};
    char dir[512], command[2048];
    size_t i;
    for (i = 0; i < sizeof names / sizeof *names; ++i)
        if (setlocale(LC_NUMERIC, names[i]) && strcmp(localeconv()->decimal_point, ",") == 0)
            return 1;
    snprintf(dir, sizeof dir, "%s/locale", build);
    snprintf(command, sizeof command,
             "mkdir -p '%s' && { [ -d '%s/de_DE.UTF-8' ] || localedef -i de_DE -f UTF-8 "
             "'%s/de_DE.UTF-8'; } >/dev/null 2>&1",
             dir, dir, dir);
    if (system(command) != 0) return 0;
    setenv("LOCPATH", dir, 1);
    return setlocale(LC_NUMERIC, "de_DE.UTF-8") && strcmp(localeconv()->decimal_point, ",") == 0;
}

/* A host program in a decimal-comma locale still loads scenes, to the bit. */
static void test_locale_independence(void)
{
    static const char text[] = "camera eye 0.1 -2.5 1e-3 look 0 0 0 fov 37.5\n"
                               "sphere center 0.30000000000000004 0 0 radius 1.25e-1\n";
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r;
    if (!use_comma_locale(t_build_dir)) {
        printf("  no decimal-comma locale and no localedef: only the syntax tests ran\n");
        return;
    }
    CHECKF(strtod("1.5", NULL) == 1.0, "the locale does not change strtod (%g)", strtod("1.5", NULL));
    r = parse_str(text, NULL, &s, &err);
    setlocale(LC_NUMERIC, "C");
    CHECKF(r == RRV_OK, "in a decimal-comma locale: %s", err.message);
    if (r != RRV_OK) return;
    CHECK(s->camera.eye.x == 0.1 && s->camera.eye.y == -2.5 && s->camera.eye.z == 1e-3);
    CHECK(s->camera.fov == 37.5);
    CHECK(s->shapes[0].center.x == 0.30000000000000004 && s->shapes[0].radius == 0.125);
    rrv_scene_free(s);
}

/* A file holding `text`, then (if size is larger) a hole up to size bytes. */
static int write_sparse(const char *path, const char *text, long size)
{
    FILE *f = fopen(path, "wb");
    int ok;
    if (!f) return 0;
    ok = fputs(text, f) >= 0;
    if (ok && size > (long)strlen(text)) ok = fseek(f, size - 1, SEEK_SET) == 0 && fputc(0, f) == 0;
    return fclose(f) == 0 && ok;
}

/* Paths, inputs and odd files: "C:" is a drive only on Windows, every file
   read is reported through on_input, and a folder or an endless device as
   the scene gets a message after a bounded read. */
typedef struct seen_inputs {
    char paths[4][256];
    int count;
} seen_inputs;

static void note_input(void *user, const char *path)
{
    seen_inputs *seen = (seen_inputs *)user;
    if (seen->count < 4) snprintf(seen->paths[seen->count], 256, "%s", path);
    seen->count++;
}

static void test_paths_and_inputs(void)
{
    static const char tri[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    static const memfile files[] = {{"dir/C:tri.obj", tri, sizeof tri - 1},
                                    {"dir/\\tri.obj", tri, sizeof tri - 1}};
    memfs fs = {files, 2, 0};
    seen_inputs seen;
    rrv_load_options opt;
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r;
    char path[600];
    FILE *f;

    memset(&opt, 0, sizeof opt);
    memset(&seen, 0, sizeof seen);
    opt.read_file = memfs_read;
    opt.read_file_user = &fs;
    opt.on_input = note_input;
    opt.on_input_user = &seen;
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file C:tri.obj\nmesh file \\tri.obj\n", &opt,
                  &s, &err);
#ifdef _WIN32
    CHECK(r == RRV_ERROR_IO);
#else
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(seen.count == 2 && strcmp(seen.paths[0], "dir/C:tri.obj") == 0 &&
          strcmp(seen.paths[1], "dir/\\tri.obj") == 0);
#endif
    rrv_scene_free(s);
    s = NULL;

    /* stdio: the scene, then its grid, spelled as opened */
    snprintf(path, sizeof path, "%s/t_inputs.rrv", t_build_dir);
    f = fopen(path, "wb");
    CHECK(f != NULL);
    if (f) {
        fputs("camera eye 0 0 5 look 0 0 0\nmedium m box -1 -1 -1 1 1 1\n"
              "density m grid ../scenes/assets/tiny.vol\n", f);
        fclose(f);
        memset(&opt, 0, sizeof opt);
        memset(&seen, 0, sizeof seen);
        opt.on_input = note_input;
        opt.on_input_user = &seen;
        r = rrv_scene_load(path, &opt, &s, &err);
        CHECKF(r == RRV_OK, "%s", err.message);
        CHECK(seen.count == 2 && strcmp(seen.paths[0], path) == 0);
        snprintf(path, sizeof path, "%s/../scenes/assets/tiny.vol", t_build_dir);
        CHECKF(strcmp(seen.paths[1], path) == 0, "grid seen as %s", seen.paths[1]);
        rrv_scene_free(s);
        s = NULL;

        /* the file size limit also bounds scene files */
        snprintf(path, sizeof path, "%s/t_inputs.rrv", t_build_dir);
        memset(&opt, 0, sizeof opt);
        opt.max_grid_bytes = 20;
        r = rrv_scene_load(path, &opt, &s, &err);
        CHECKF(r == RRV_ERROR_LIMIT && strcmp(err.message, "scene file is larger than the limit of 20 bytes") == 0,
               "%s: %s", rrv_result_string(r), err.message);
        remove(path);
    }

    /* a folder as the scene: a message, and no allocation of its claimed size */
    t_largest = 0;
    r = rrv_scene_load("test/corpus", NULL, &s, &err);
    CHECKF(r == RRV_ERROR_IO && strcmp(err.message, "cannot read scene file: is a directory") == 0,
           "%s: %s", rrv_result_string(r), err.message);
    CHECKF(t_largest <= ((size_t)1 << 20), "largest allocation %lu", (unsigned long)t_largest);
#ifndef _WIN32
    /* an endless device is not a regular file: refused before a byte is read */
    t_largest = 0;
    r = rrv_scene_load("/dev/zero", NULL, &s, &err);
    CHECKF(r == RRV_ERROR_IO && err.line == 0 &&
               strcmp(err.message, "cannot read scene file: not a regular file") == 0,
           "%s: %s", rrv_result_string(r), err.message);
    CHECKF(t_largest <= ((size_t)1 << 20), "largest allocation %lu", (unsigned long)t_largest);

    /* files over the limit are refused by their size, before a byte is
       read: a 128 MiB NanoVDB file (sparse, so it costs no disk) and a
       scene as large, under a limit of 64 MiB, each allocate nothing near
       it (they were read up to the limit first) */
    {
        char nvdb[600], scene[600];
        rrv_load_options opt;
        snprintf(nvdb, sizeof nvdb, "%s/t_big.nvdb", t_build_dir);
        snprintf(scene, sizeof scene, "%s/t_big.rrv", t_build_dir);
        memset(&opt, 0, sizeof opt);
        opt.max_grid_bytes = (size_t)64 << 20;
        CHECK(write_sparse(nvdb, "NanoVDB0", (long)128 << 20));
        CHECK(write_sparse(scene, "camera eye 0 0 5 look 0 0 0\nmedium m box -1 -1 -1 1 1 1\n"
                                  "density m nanovdb t_big.nvdb\n", 0));
        t_largest = 0;
        r = rrv_scene_load(scene, &opt, &s, &err);
        CHECKF(r == RRV_ERROR_LIMIT && err.line == 3 &&
                   strcmp(err.message, "NanoVDB file \"t_big.nvdb\": the file is larger than the limit of 67108864 "
                                       "bytes (raise it with --max-grid-mb N)") == 0,
               "%s: %d: %s", rrv_result_string(r), err.line, err.message);
        CHECKF(t_largest <= ((size_t)1 << 20), "largest allocation %lu", (unsigned long)t_largest);
        CHECK(write_sparse(scene, "camera eye 0 0 5 look 0 0 0\n", (long)128 << 20));
        t_largest = 0;
        r = rrv_scene_load(scene, &opt, &s, &err);
        CHECKF(r == RRV_ERROR_LIMIT && strcmp(err.message, "scene file is larger than the limit of 67108864 bytes") == 0,
               "%s: %s", rrv_result_string(r), err.message);
        CHECKF(t_largest <= ((size_t)1 << 20), "largest allocation %lu", (unsigned long)t_largest);
        remove(nvdb);
        remove(scene);
    }
#endif
    CHECK(s == NULL);
}

/* The view-up test scales before squaring: a far camera loads, and a truly
   parallel up is still refused at that distance. */
static void test_far_camera(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r = parse_str("camera eye 0 0 1e150 look 0 0 -1e150\n", NULL, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    rrv_scene_free(s);
    expect_error("camera eye 0 1e150 0 look 0 0 0\n", RRV_ERROR_PARSE, 1,
                 "camera: up is parallel to the view direction");
    expect_error("camera eye 0 1e-150 1e-300 look 0 0 0 up 0 1 0\n", RRV_ERROR_PARSE, 1,
                 "camera: up is parallel to the view direction");
    r = parse_str("camera eye 1e-300 0 0 look 0 0 0\n", NULL, &s, &err);
    CHECKF(r == RRV_OK, "a tiny view vector: %s", err.message);
    rrv_scene_free(s);
}

/* ---- (c) the grid reader -------------------------------------------------- */

static void test_grid_valid(void)
{
    const float box[6] = {-1.0f, 0.0f, 2.0f, 1.0f, 0.5f, 3.0f};
    gridbuf g;
    rrv_grid grid;
    rrv_error err;
    rrv_result r;
    int i;
    /* 1 channel, 3 x 2 x 2, every value distinct and exactly representable */
    grid_header(&g, 3, 2, 2, 1, box);
    for (i = 0; i < 12; ++i) putf(&g, (float)i * 0.25f - 1.0f);
    r = rrv_grid_read_memory(g.b, g.n, "a.vol", 0, 0, &grid, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(grid.nx == 3 && grid.ny == 2 && grid.nz == 2 && grid.channels == 1);
        /* corner placement: lo and hi are the first and last sample positions */
        CHECK(grid.lo.x == -1 && grid.lo.y == 0 && grid.lo.z == 2);
        CHECK(grid.hi.x == 1 && grid.hi.y == 0.5 && grid.hi.z == 3);
        for (i = 0; i < 12; ++i) CHECK(grid.data[i] == (float)i * 0.25f - 1.0f);
        /* sample (x=2, y=1, z=1) sits at index (1*2 + 1)*3 + 2 = 11 */
        CHECK(grid.data[(1 * 2 + 1) * 3 + 2] == 1.75f);
        rrv_free(grid.data);
    }
    /* 3 channels: channel is the fastest index */
    grid_header(&g, 2, 2, 2, 3, unit_box);
    for (i = 0; i < 24; ++i) putf(&g, (float)(i / 3) + 0.1f * (float)(i % 3));
    r = rrv_grid_read_memory(g.b, g.n, "b.vol", 0, 1, &grid, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(grid.channels == 3 && grid.nx == 2);
        for (i = 0; i < 24; ++i) CHECK(grid.data[i] == (float)(i / 3) + 0.1f * (float)(i % 3));
        CHECK(grid.data[3 * 7 + 2] == 7.0f + 0.2f);
        rrv_free(grid.data);
    }
    /* negative values are fine when not a density; -0 is fine for densities */
    grid_valid(&g, -0.5f);
    r = rrv_grid_read_memory(g.b, g.n, "c.vol", 0, 0, &grid, &err);
    CHECK(r == RRV_OK && grid.data[0] == -0.5f);
    if (r == RRV_OK) rrv_free(grid.data);
    grid_valid(&g, 0.0f);
    g.n = 48;
    putf(&g, -0.0f);
    g.n = 80;
    r = rrv_grid_read_memory(g.b, g.n, "c.vol", 0, 1, &grid, &err);
    CHECK(r == RRV_OK);
    if (r == RRV_OK) rrv_free(grid.data);
    /* the same bytes through a file: the stdio reader and a callback agree */
    {
        memfile files[1];
        memfs fs;
        rrv_load_options opt;
        size_t size;
        char *data = read_text("scenes/assets/tiny.vol", &size);
        CHECK(data != NULL);
        r = rrv_grid_read("scenes/assets/tiny.vol", NULL, 1, &grid, &err);
        CHECKF(r == RRV_OK, "%s", err.message);
        if (r == RRV_OK) {
            CHECK(grid.nx == 2 && grid.ny == 2 && grid.nz == 2 && grid.channels == 1 && grid.lo.x == -0.5 &&
                  grid.hi.z == 0.5 && grid.data[7] == 0.875f);
            rrv_free(grid.data);
        }
        files[0].path = "mem/tiny.vol";
        files[0].data = data;
        files[0].size = size;
        fs.files = files;
        fs.count = 1;
        fs.reads = 0;
        memset(&opt, 0, sizeof opt);
        opt.read_file = memfs_read;
        opt.read_file_user = &fs;
        r = rrv_grid_read("mem/tiny.vol", &opt, 1, &grid, &err);
        CHECK(r == RRV_OK && fs.reads == 1 && grid.data && grid.data[1] == 0.125f);
        if (r == RRV_OK) rrv_free(grid.data);
        r = rrv_grid_read("mem/none.vol", &opt, 1, &grid, &err);
        CHECK(r == RRV_ERROR_IO && strcmp(err.file, "mem/none.vol") == 0);
        free(data);
    }
    r = rrv_grid_read("test/corpus/grid_nan.vol", NULL, 1, &grid, &err);
    CHECK(r == RRV_ERROR_FORMAT && strcmp(err.message, "value 3 (x=1 y=1 z=0) is NaN") == 0 &&
          strcmp(err.file, "test/corpus/grid_nan.vol") == 0);
    r = rrv_grid_read("test/corpus/grid_truncated.vol", NULL, 1, &grid, &err);
    CHECK(r == RRV_ERROR_FORMAT && strcmp(err.message, "expected 32 bytes of samples, found 20") == 0);
    r = rrv_grid_read("test/corpus/no_such.vol", NULL, 1, &grid, &err);
    CHECK(r == RRV_ERROR_IO);
}

static void test_grid_rejections(void)
{
    const float empty_x[6] = {1, 0, 0, 1, 1, 1}, inverted_z[6] = {0, 0, 2, 1, 1, 1};
    float nan_box[6] = {0, 0, 0, 1, 1, 1};
    gridbuf g;
    int i;
    grid_valid(&g, 0);
    g.b[2] = 'X';
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "not a gridvol file: it does not start with \"VOL\"");
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "not a gridvol file: it does not start with \"VOL\"");
    g.n = 2;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "not a gridvol file: it does not start with \"VOL\"");
    grid_valid(&g, 0);
    g.n = 30;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "truncated header: the file has 30 bytes, the header needs 48");
    grid_valid(&g, 0);
    g.b[3] = 4;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "unsupported gridvol version 4 (expected 3)");
    grid_valid(&g, 0);
    g.b[4] = 2;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "unsupported encoding 2 (only 1 = float32 is supported)");
    grid_header(&g, 2, 1, 2, 1, unit_box);
    for (i = 0; i < 4; ++i) putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "resolution 2 x 1 x 2: yres is 1, must be >= 2");
    grid_header(&g, 2, 2, -5, 1, unit_box);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "resolution 2 x 2 x -5: zres is -5, must be >= 2");
    grid_header(&g, 2, 2, 2, 2, unit_box);
    for (i = 0; i < 16; ++i) putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "2 channels: expected 1 or 3");
    grid_header(&g, 2, 2, 2, 0, unit_box);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "0 channels: expected 1 or 3");
    grid_header(&g, 2, 2, 2, 1, empty_x);
    for (i = 0; i < 8; ++i) putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "bounding box is empty: xmin 1 is not below xmax 1");
    grid_header(&g, 2, 2, 2, 1, inverted_z);
    for (i = 0; i < 8; ++i) putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "bounding box is empty: zmin 2 is not below zmax 1");
    nan_box[4] = (float)strtod("nan", NULL);
    grid_header(&g, 2, 2, 2, 1, nan_box);
    for (i = 0; i < 8; ++i) putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "bounding box is not finite (ymax is NaN)");
    nan_box[4] = 1;
    nan_box[0] = -(float)strtod("inf", NULL);
    grid_header(&g, 2, 2, 2, 1, nan_box);
    for (i = 0; i < 8; ++i) putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "bounding box is not finite (xmin is infinite)");
    /* byte count: too few and too many */
    grid_valid(&g, 0);
    g.n -= 1;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "expected 32 bytes of samples, found 31");
    grid_valid(&g, 0);
    putf(&g, 0);
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "expected 32 bytes of samples, found 36");
    /* values */
    grid_valid(&g, 0);
    g.n = 48 + 4 * 6;
    put32(&g, 0x7fc00000u);
    g.n = 80;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "value 6 (x=0 y=1 z=1) is NaN");
    grid_valid(&g, 0);
    g.n = 48 + 4 * 1;
    put32(&g, 0xff800000u);
    g.n = 80;
    expect_grid_error(&g, 0, 0, RRV_ERROR_FORMAT, "value 1 (x=1 y=0 z=0) is infinite");
    grid_header(&g, 2, 2, 2, 3, unit_box);
    for (i = 0; i < 24; ++i) putf(&g, i == 17 ? -2.0f : 1.0f);
    expect_grid_error(&g, 0, 1, RRV_ERROR_FORMAT,
                      "value 17 (x=1 y=0 z=1 c=2) is negative (-2), densities must be >= 0");
}

static void test_grid_limits(void)
{
    gridbuf g;
    rrv_grid grid;
    rrv_error err;
    rrv_result r;
    /* a header claiming 100000^3 samples with no data: the limit trips, and
       nothing near that size is ever requested from the allocator */
    grid_header(&g, 100000, 100000, 100000, 1, unit_box);
    t_largest = 0;
    expect_grid_error(&g, 1000, 0, RRV_ERROR_LIMIT,
                      "100000 x 100000 x 100000 x 1 samples need 4000000000000000 bytes, over the limit "
                      "of 1000 bytes (raise it with --max-grid-mb N)");
    CHECKF(t_largest < 4096, "largest allocation %lu", (unsigned long)t_largest);
    /* the default limit (0) also refuses it */
    t_largest = 0;
    r = rrv_grid_read_memory(g.b, g.n, "x.vol", 0, 0, &grid, &err);
    CHECK(r == RRV_ERROR_LIMIT && strstr(err.message, "limit of 2147483648 bytes") != NULL);
    CHECK(t_largest < 4096);
    /* products that overflow 64 bits */
    grid_header(&g, 2147483647, 2147483647, 2147483647, 3, unit_box);
    expect_grid_error(&g, 1000, 0, RRV_ERROR_LIMIT,
                      "2147483647 x 2147483647 x 2147483647 x 3 samples: the byte count overflows");
    grid_header(&g, 2147483647, 2147483647, 4, 1, unit_box);
    r = rrv_grid_read_memory(g.b, g.n, "x.vol", (size_t)-1, 0, &grid, &err);
    CHECK(r == RRV_ERROR_LIMIT && grid.data == NULL);
    CHECK(t_largest < 4096);
    /* exactly at the limit passes, one byte under fails */
    grid_valid(&g, 0);
    r = rrv_grid_read_memory(g.b, g.n, "x.vol", 32, 0, &grid, &err);
    CHECK(r == RRV_OK);
    if (r == RRV_OK) rrv_free(grid.data);
    expect_grid_error(&g, 31, 0, RRV_ERROR_LIMIT,
                      "2 x 2 x 2 x 1 samples need 32 bytes, over the limit of 31 bytes (raise it with --max-grid-mb N)");
    /* the stdio reader applies the limit before reading the samples */
    {
        rrv_load_options opt;
        memset(&opt, 0, sizeof opt);
        opt.max_grid_bytes = 16;
        r = rrv_grid_read("scenes/assets/tiny.vol", &opt, 1, &grid, &err);
        CHECK(r == RRV_ERROR_LIMIT && grid.data == NULL);
    }
    r = rrv_grid_read_memory(NULL, 5, "x.vol", 0, 0, &grid, &err);
    CHECK(r == RRV_ERROR_ARGUMENT);
}

/* Grids inside scenes: errors at the scene line, the limit from options,
   grid_bytes accounting, channel rules per field. */
static void test_grid_in_scene(void)
{
    gridbuf g1, g3;
    memfile files[2];
    memfs fs;
    rrv_load_options opt;
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r;
    int i;
    grid_valid(&g1, 0);
    grid_header(&g3, 2, 2, 2, 3, unit_box);
    for (i = 0; i < 24; ++i) putf(&g3, 1);
    files[0].path = "dir/one.vol";
    files[0].data = g1.b;
    files[0].size = g1.n;
    files[1].path = "/abs/three.vol";
    files[1].data = g3.b;
    files[1].size = g3.n;
    fs.files = files;
    fs.count = 2;
    fs.reads = 0;
    memset(&opt, 0, sizeof opt);
    opt.read_file = memfs_read;
    opt.read_file_user = &fs;
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmedium m box 0 0 0 1 1 1\n"
                  "density m grid /abs/three.vol\ntemperature m grid one.vol\nior m grid \"one.vol\"\n",
                  &opt, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(s->media[0].density.kind == RRV_FIELD_GRID && s->media[0].density.grid.channels == 3);
        CHECK(s->media[0].temperature.grid.data[7] == 0.875f);
        CHECK(s->grid_bytes == 24 * 4 + 8 * 4 + 8 * 4);
        CHECK(s->bytes >= s->grid_bytes + sizeof *s);
        rrv_scene_free(s);
    }
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmedium m box 0 0 0 1 1 1\n\npressure m grid /abs/three.vol\n",
                  &opt, &s, &err);
    CHECK(r == RRV_ERROR_FORMAT && s == NULL && err.line == 4 &&
          strcmp(err.message, "grid \"/abs/three.vol\": pressure grids need 1 channel, found 3") == 0);
    opt.max_grid_bytes = 64;
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmedium m box 0 0 0 1 1 1\ndensity m grid /abs/three.vol\n",
                  &opt, &s, &err);
    CHECK(r == RRV_ERROR_LIMIT && err.line == 3 && strcmp(err.file, "t.rrv") == 0 &&
          strcmp(err.message, "grid \"/abs/three.vol\": 2 x 2 x 2 x 3 samples need 96 bytes, over the limit "
                              "of 64 bytes (raise it with --max-grid-mb N)") == 0);
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmedium m box 0 0 0 1 1 1\ndensity m grid two.vol\n",
                  &opt, &s, &err);
    CHECK(r == RRV_ERROR_IO && err.line == 3 && strcmp(err.message, "cannot read grid file \"two.vol\"") == 0);
}

/* ---- (d) OBJ ------------------------------------------------------------------ */

static void test_obj(void)
{
    static const char quad[] = "# a unit quad in z = 0\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n"
                               "vt 0 0\ng quad\nusemtl none\ns off\nf 1 2 3 4\n";
    static const char forms[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                "f 1/1/1 2/2/2 3/3/3\nf 1//1 2//1 4//1\nf -4 -2 -1\nf 1/5 3/5 4/5\n"
                                "f 1 2 2\n"; /* degenerate: skipped */
    static const char bad_index[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3\nf 1 2 -4\n";
    static const char bad_index2[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 0 3\n";
    static const char bad_token[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x/1\n";
    static const char bad_v[] = "v 0 0\n";
    /* a byte order mark, then a vertex that scale 1e10 takes past the world */
    static const char far_v[] = "\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1e141 0\nf 1 2 3\n";
    memfile files[7];
    memfs fs;
    rrv_load_options opt;
    rrv_scene *s = NULL;
    rrv_error err;
    rrv_result r;
    files[0].path = "dir/quad.obj"; files[0].data = quad; files[0].size = sizeof quad - 1;
    files[1].path = "dir/forms.obj"; files[1].data = forms; files[1].size = sizeof forms - 1;
    files[2].path = "dir/bad.obj"; files[2].data = bad_index; files[2].size = sizeof bad_index - 1;
    files[3].path = "dir/bad2.obj"; files[3].data = bad_index2; files[3].size = sizeof bad_index2 - 1;
    files[4].path = "dir/tok.obj"; files[4].data = bad_token; files[4].size = sizeof bad_token - 1;
    files[5].path = "dir/v.obj"; files[5].data = bad_v; files[5].size = sizeof bad_v - 1;
    fs.files = files;
    files[6].path = "dir/far.obj"; files[6].data = far_v; files[6].size = sizeof far_v - 1;
    fs.count = 7;
    fs.reads = 0;
    memset(&opt, 0, sizeof opt);
    opt.read_file = memfs_read;
    opt.read_file_user = &fs;
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file quad.obj translate 10 0 0 scale 2 L 1 2 3\n", &opt, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(s->shape_count == 2);
        CHECK(s->shapes[0].kind == RRV_SHAPE_TRIANGLE && s->shapes[1].kind == RRV_SHAPE_TRIANGLE);
        /* fan: (1,2,3) and (1,3,4), scaled by 2 then moved by 10 in x */
        CHECK(s->shapes[0].p0.x == 10 && s->shapes[0].e1.x == 2 && s->shapes[0].e1.y == 0 &&
              s->shapes[0].e2.x == 2 && s->shapes[0].e2.y == 2);
        CHECK(s->shapes[1].p0.x == 10 && s->shapes[1].e1.x == 2 && s->shapes[1].e1.y == 2 &&
              s->shapes[1].e2.x == 0 && s->shapes[1].e2.y == 2);
        CHECK(s->shapes[0].L[1] == 2 && s->shapes[1].L[2] == 3); /* L not scaled by the geometry scale */
        rrv_scene_free(s);
    }
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file forms.obj\n", &opt, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(s->shape_count == 4);
        /* f -4 -2 -1 with 4 vertices is (1, 3, 4) */
        CHECK(s->shapes[2].p0.x == 0 && s->shapes[2].e1.y == 1 && s->shapes[2].e2.z == 1);
        CHECK(s->shapes[3].e1.y == 1 && s->shapes[3].e2.z == 1);
        rrv_scene_free(s);
    }
    r = parse_str("camera eye 0 0 5 look 0 0 0\n\nmesh file bad.obj\n", &opt, &s, &err);
    CHECK(r == RRV_ERROR_PARSE && s == NULL && strcmp(err.file, "dir/bad.obj") == 0 && err.line == 6 &&
          strcmp(err.message, "f: vertex index -4 is out of range (3 vertices so far)") == 0);
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file bad2.obj\n", &opt, &s, &err);
    CHECK(r == RRV_ERROR_PARSE && err.line == 4 &&
          strcmp(err.message, "f: vertex index 0 is out of range (3 vertices so far)") == 0);
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file tok.obj\n", &opt, &s, &err);
    CHECK(r == RRV_ERROR_PARSE && err.line == 4 && strcmp(err.message, "f: expected a vertex index, got \"x/1\"") == 0);
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file v.obj\n", &opt, &s, &err);
    CHECK(r == RRV_ERROR_PARSE && err.line == 1 && strcmp(err.message, "v needs 3 coordinates, got 2") == 0);
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file far.obj\n", &opt, &s, &err);
    CHECKF(r == RRV_OK, "%s", err.message); /* the mark is skipped, 1e141 is inside */
    if (r == RRV_OK) {
        CHECK(s->shape_count == 1 && s->shapes[0].e2.y == 1e141);
        rrv_scene_free(s);
    }
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file far.obj scale 1e10\n", &opt, &s, &err);
    CHECKF(r == RRV_ERROR_PARSE && s == NULL && strcmp(err.file, "dir/far.obj") == 0 && err.line == 3 &&
               strcmp(err.message, "v (after scale and translate): a corner must be in "
                                   "[-1e+150, 1e+150], got 1e+151") == 0,
           "%s:%d: %s", err.file, err.line, err.message);
    r = parse_str("camera eye 0 0 5 look 0 0 0\nmesh file missing.obj\n", &opt, &s, &err);
    CHECK(r == RRV_ERROR_IO && err.line == 2 && strcmp(err.file, "t.rrv") == 0 &&
          strcmp(err.message, "cannot read OBJ file \"missing.obj\"") == 0);
    /* the real asset through stdio, last line without a newline handled too */
    {
        static const char t[] = "camera eye 0 0 5 look 0 0 0\nmesh file assets/tetra.obj";
        r = rrv_scene_parse(t, sizeof t - 1, "x.rrv", "scenes", NULL, &s, &err);
    }
    CHECKF(r == RRV_OK, "%s", err.message);
    if (r == RRV_OK) {
        CHECK(s->shape_count == 4);
        rrv_scene_free(s);
    }
}

/* Every allocation failing in turn: each must give RRV_ERROR_MEMORY (or
   succeed) and leak nothing (the sanitizer build checks leaks). */
static void test_allocation_failures(void)
{
    static const char text[] =
        "camera eye 0 0 5 look 0 0 0\nmaterial m diffuse\nsphere center 0 0 0 radius 1 material m\n"
        "mesh file assets/tetra.obj\nmedium a box 0 0 0 1 1 1\ndensity a blob center 0 0 0 radius 1\n"
        "density a blob center 0 0 0 radius 1\ndensity a blob center 0 0 0 radius 1\n"
        "density a blob center 0 0 0 radius 1\ndensity a blob center 0 0 0 radius 1\n"
        "temperature a grid assets/tiny.vol\n";
    long n;
    int ok = 0;
    for (n = 0; n < 200 && !ok; ++n) {
        rrv_scene *s = NULL;
        rrv_error err;
        rrv_result r;
        t_alloc_count = 0;
        t_fail_at = n;
        r = rrv_scene_parse(text, sizeof text - 1, "t.rrv", "scenes", NULL, &s, &err);
        t_fail_at = -1;
        if (r == RRV_OK) {
            ok = 1;
            CHECK(s->media[0].density.blob_count == 5);
            rrv_scene_free(s);
        } else {
            CHECKF(r == RRV_ERROR_MEMORY || r == RRV_ERROR_IO, "failing allocation %ld gave %s: %s", n,
                   rrv_result_string(r), err.message);
            CHECK(s == NULL);
        }
    }
    CHECK(ok);
}

int main(int argc, char **argv)
{
    if (argc > 1) t_build_dir = argv[1];
    RUN(test_readme_examples);
    RUN(test_corpus);
    RUN(test_corpus_complete);
    RUN(test_defaults_and_values);
    RUN(test_render_and_seed);
    RUN(test_statement_errors);
    RUN(test_lexing);
    RUN(test_number_syntax);
    RUN(test_locale_independence);
    RUN(test_paths_and_inputs);
    RUN(test_far_camera);
    RUN(test_grid_valid);
    RUN(test_grid_rejections);
    RUN(test_grid_limits);
    RUN(test_grid_in_scene);
    RUN(test_obj);
    RUN(test_allocation_failures);
    return CHECK_EXIT_CODE();
}
