/* Tests of the NanoVDB reader against files made at test time by the real
   tools: test/make_vdb.py (Debian's python3-openvdb) writes .vdb files and
   their answer keys, nanovdb_convert (libnanovdb-tools) turns them into
   .nvdb, nanovdb_validate checks them. Without those tools every test here
   FAILS and says what to install. argv[1] is the build folder. */
#define _POSIX_C_SOURCE 200809L
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"

#include <errno.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/types.h>

#define INSTALL_HINT "install them: apt-get install python3-openvdb libnanovdb-tools"

static char dir[512];
static const char *build_dir = "build";
static int tools_ok;

static const char *path_in(const char *name)
{
    static char paths[16][700];
    static int next;
    char *p = paths[next++ % 16];
    snprintf(p, sizeof paths[0], "%s/%s", dir, name);
    return p;
}

static int run(const char *fmt, const char *a, const char *b)
{
    char cmd[2048];
    snprintf(cmd, sizeof cmd, fmt, a, b);
    return system(cmd);
}

static unsigned char *slurp(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    unsigned char *data;
    long n;
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    data = (unsigned char *)malloc(n > 0 ? (size_t)n : 1);
    if (data && fread(data, 1, (size_t)n, f) != (size_t)n) {
        free(data);
        data = NULL;
    }
    fclose(f);
    *size = (size_t)n;
    return data;
}

/* The known-answer files; every test needs them. */
static void make_files(void)
{
    static const char *const variants[][2] = {
        {"", "fields.nvdb"}, {"--fp16", "fields_fp16.nvdb"}, {"--fp8", "fields_fp8.nvdb"},
        {"--fp4", "fields_fp4.nvdb"}, {"--fpN -a 0.001", "fields_fpn.nvdb"}, {"-z", "fields_zip.nvdb"}};
    char opts[64];
    size_t i;
    CHECKF(run("/usr/bin/python3 -c 'import pyopenvdb, numpy' 2>/dev/null%s%s", "", "") == 0,
           "Debian's python3-openvdb is missing; " INSTALL_HINT);
    CHECKF(run("command -v nanovdb_convert >/dev/null && command -v nanovdb_validate >/dev/null%s%s", "", "") == 0,
           "nanovdb_convert/nanovdb_validate are missing; " INSTALL_HINT);
    if (check__failed_in_test) return;
    CHECKF(run("/usr/bin/python3 test/make_vdb.py '%s'%s", dir, "") == 0, "test/make_vdb.py failed");
    for (i = 0; i < sizeof variants / sizeof variants[0]; ++i) {
        char out[700];
        snprintf(opts, sizeof opts, "-f %s", variants[i][0]);
        snprintf(out, sizeof out, "'%s' '%s'", path_in("fields.vdb"), path_in(variants[i][1]));
        CHECKF(run("nanovdb_convert %s %s >/dev/null", opts, out) == 0, "nanovdb_convert %s failed", opts);
        if (i < 5)
            CHECKF(run("nanovdb_validate -v '%s' | grep -q passed%s", path_in(variants[i][1]), "") == 0,
                   "nanovdb_validate rejects %s", variants[i][1]);
    }
    CHECKF(run("nanovdb_convert -f '%s' '%s' >/dev/null", path_in("sparse.vdb"), path_in("sparse.nvdb")) == 0,
           "nanovdb_convert sparse.vdb failed");
    CHECKF(run("nanovdb_validate -v '%s' | grep -q passed%s", path_in("sparse.nvdb"), "") == 0,
           "nanovdb_validate rejects sparse.nvdb");
    tools_ok = !check__failed_in_test;
}

/* Index origin of the dense grid `name` (layout.txt). */
static int origin_of(const char *name, int o[3])
{
    FILE *f = fopen(path_in("layout.txt"), "r");
    char word[32];
    int d[3], found = 0;
    if (!f) return 0;
    while (fscanf(f, "%31s %d %d %d %d %d %d", word, &o[0], &o[1], &o[2], &d[0], &d[1], &d[2]) == 7)
        if (strcmp(word, name) == 0) { found = 1; break; }
    fclose(f);
    return found;
}

static int load(const char *file, const char *grid, rrv_nanovdb *g)
{
    rrv_error e;
    rrv_result r = rrv_nanovdb_read(path_in(file), grid, NULL, g, &e);
    CHECKF(r == RRV_OK, "%s grid %s: %s", file, grid, e.message);
    return r == RRV_OK;
}

/* Every voxel of each dense grid against the gridvol answer key: exact for
   float grids; for quantised ones within half a quantum of the widest leaf
   (NanoVDB rounds each value to the nearest of 2^bits levels spanning its
   leaf's range, which is at most the grid's range), or the FpN tolerance. */
static void check_voxels(const char *file, double levels, double tolerance)
{
    static const char *const names[2] = {"density", "temperature"};
    int n;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    for (n = 0; n < 2; ++n) {
        char vol[32];
        rrv_nanovdb g;
        rrv_grid v;
        rrv_error e;
        int o[3], x, y, z, bad = 0;
        double bound, worst = 0;
        snprintf(vol, sizeof vol, "%s.vol", names[n]);
        if (!load(file, names[n], &g)) continue;
        CHECK(origin_of(names[n], o));
        CHECKF(rrv_grid_read(path_in(vol), NULL, 0, &v, &e) == RRV_OK, "%s", e.message);
        bound = levels > 0 ? 0.5 * (g.value_max - g.value_min) / levels * (1 + 1e-6) : 0;
        if (tolerance > bound) bound = tolerance;
        for (z = 0; z < v.nz; ++z)
            for (y = 0; y < v.ny; ++y)
                for (x = 0; x < v.nx; ++x) {
                    double want = v.data[((size_t)z * v.ny + y) * v.nx + x];
                    double got = rrv_nanovdb_voxel(&g, o[0] + x, o[1] + y, o[2] + z);
                    double err = fabs(got - want);
                    if (err > worst) worst = err;
                    if (err > bound && bad++ < 3)
                        CHECKF(0, "%s %s voxel %d %d %d: %.9g, expected %.9g", file, names[n], o[0] + x, o[1] + y,
                               o[2] + z, got, want);
                }
        /* a shell one voxel outside the data is the background (quantised:
           the inactive voxels of a leaf are quantised too) */
        for (x = -1; x <= v.nx; ++x)
            for (y = -1; y <= v.ny; ++y)
                for (z = -1; z <= v.nz; z += v.nz + 1) {
                    double err = fabs(rrv_nanovdb_voxel(&g, o[0] + x, o[1] + y, o[2] + z) - g.background);
                    if (err > bound && bad++ < 3)
                        CHECKF(0, "%s %s voxel %d %d %d is not the background", file, names[n], o[0] + x, o[1] + y, o[2] + z);
                }
        CHECKF(bad == 0, "%s %s: %d voxels off by more than %g (worst %g)", file, names[n], bad, bound, worst);
        rrv_free(v.data);
        rrv_nanovdb_free(&g);
    }
}

static void float_voxels_exact(void) { check_voxels("fields.nvdb", 0, 0); }
static void fp16_voxels_within_quantum(void) { check_voxels("fields_fp16.nvdb", 65535, 0); }
static void fp8_voxels_within_quantum(void) { check_voxels("fields_fp8.nvdb", 255, 0); }
static void fp4_voxels_within_quantum(void) { check_voxels("fields_fp4.nvdb", 15, 0); }
/* FpN meets -a 0.001 unless even 16 bits cannot */
static void fpn_voxels_within_tolerance(void) { check_voxels("fields_fpn.nvdb", 65535, 0.001); }

/* Probes of the sparse grid (tiles at every level, negative coordinates,
   far corners) as OpenVDB itself reads them back. */
static void sparse_probes_exact(void)
{
    rrv_nanovdb g;
    size_t size, i, count;
    unsigned char *b;
    int bad = 0;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    if (!load("sparse.nvdb", "sparse", &g)) return;
    b = slurp(path_in("sparse.bin"), &size);
    CHECK(b != NULL && size >= 4);
    if (!b) return;
    count = rrv__nv_u32(b);
    CHECK(size == 4 + 16 * count && count > 4000);
    for (i = 0; i < count && 4 + 16 * i + 16 <= size; ++i) {
        const unsigned char *p = b + 4 + 16 * i;
        int32_t x = rrv__nv_s32(rrv__nv_u32(p)), y = rrv__nv_s32(rrv__nv_u32(p + 4)), z = rrv__nv_s32(rrv__nv_u32(p + 8));
        double want = rrv__nv_f32(p + 12), got = rrv_nanovdb_voxel(&g, x, y, z);
        if (got != want && bad++ < 5) CHECKF(0, "voxel %d %d %d: %.9g, expected %.9g", x, y, z, got, want);
    }
    CHECKF(bad == 0, "%d of %d probes differ", bad, (int)count);
    CHECK(g.background == 0.5 && g.root_tiles >= 3);
    free(b);
    rrv_nanovdb_free(&g);
}

/* The map: index points sit at map * ijk + translation, and between them
   the field is the trilinear blend, so inside the data it equals the
   gridvol answer key (whose corner samples sit on the same points) within
   float rounding of the positions. */
static void world_placement_matches_gridvol(void)
{
    rrv_nanovdb g;
    rrv_grid v;
    rrv_error e;
    rrv__rng rng;
    int i, bad = 0;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    if (!load("fields.nvdb", "density", &g)) return;
    CHECKF(rrv_grid_read(path_in("density.vol"), NULL, 0, &v, &e) == RRV_OK, "%s", e.message);
    CHECK(fabs(g.map[0] - 0.05) < 1e-15 && fabs(g.map[4] - 0.04) < 1e-15 && fabs(g.map[8] - 0.06) < 1e-15);
    CHECK(fabs(g.translation[0] - 0.3) < 1e-15 && fabs(g.translation[1] + 0.2) < 1e-15);
    rrv__rng_seed(&rng, 3, 4, 5);
    for (i = 0; i < 20000; ++i) {
        rrv_vec3 p = rrv__v3(v.lo.x + (v.hi.x - v.lo.x) * rrv__uniform(&rng), v.lo.y + (v.hi.y - v.lo.y) * rrv__uniform(&rng),
                             v.lo.z + (v.hi.z - v.lo.z) * rrv__uniform(&rng));
        double a = rrv_nanovdb_sample(&g, p), b = rrv__grid_sample(&v, p, 0, 0.0);
        if (!(fabs(a - b) <= 1e-5 * fabs(b)) && bad++ < 3) CHECKF(0, "at %g %g %g: %.9g vs gridvol %.9g", p.x, p.y, p.z, a, b);
        if (i < 2000) {
            /* interior: the two second-order stencils are the same */
            rrv_vec3 ga, gb;
            if (p.x - v.lo.x < 0.06 || v.hi.x - p.x < 0.06 || p.y - v.lo.y < 0.05 || v.hi.y - p.y < 0.05 ||
                p.z - v.lo.z < 0.07 || v.hi.z - p.z < 0.07)
                continue;
            ga = rrv__nv_gradient(&g, p);
            gb = rrv__grid_gradient(&v, p);
            if (!(rrv__length(rrv__sub(ga, gb)) <= 1e-4 * rrv__length(gb) + 1e-6) && bad++ < 3)
                CHECKF(0, "gradient at %g %g %g: %g %g %g vs %g %g %g", p.x, p.y, p.z, ga.x, ga.y, ga.z, gb.x, gb.y, gb.z);
        }
    }
    CHECK(bad == 0);
    /* beyond one voxel past the data only the background is left */
    CHECK(rrv_nanovdb_sample(&g, rrv__v3(g.hi.x + 1e-9, 1.0, 1.5)) == 0.0);
    rrv_free(v.data);
    rrv_nanovdb_free(&g);
}

/* The majorant bound is a bound: values at random points of random boxes
   never exceed it (delta tracking stays unbiased), and over the whole data
   it is the grid's maximum. */
static void bound_is_an_upper_bound(void)
{
    static const char *const files[2] = {"fields.nvdb", "sparse.nvdb"};
    static const char *const grids[2] = {"density", "sparse"};
    rrv__rng rng;
    int f, i, j, bad = 0;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    rrv__rng_seed(&rng, 9, 9, 9);
    for (f = 0; f < 2; ++f) {
        rrv_nanovdb g;
        rrv_vec3 ext;
        if (!load(files[f], grids[f], &g)) continue;
        ext = rrv__sub(g.hi, g.lo);
        CHECK(rrv__nv_bound(&g, g.lo, g.hi) == g.value_max);
        for (i = 0; i < 300; ++i) {
            double s = (f ? 0.02 : 0.2) * rrv__uniform(&rng), bound;
            rrv_vec3 lo = rrv__v3(g.lo.x + ext.x * rrv__uniform(&rng), g.lo.y + ext.y * rrv__uniform(&rng),
                                  g.lo.z + ext.z * rrv__uniform(&rng));
            rrv_vec3 hi = rrv__add(lo, rrv__scale(ext, s));
            bound = rrv__nv_bound(&g, lo, hi);
            for (j = 0; j < 200; ++j) {
                rrv_vec3 p = rrv__v3(lo.x + (hi.x - lo.x) * rrv__uniform(&rng), lo.y + (hi.y - lo.y) * rrv__uniform(&rng),
                                     lo.z + (hi.z - lo.z) * rrv__uniform(&rng));
                double v = rrv_nanovdb_sample(&g, p);
                if (v > bound && bad++ < 3) CHECKF(0, "%s: %g above the bound %g", files[f], v, bound);
            }
        }
        rrv_nanovdb_free(&g);
    }
    CHECK(bad == 0);
}

static void render(const char *density, float *sum, int *w, int *h)
{
    char text[1024];
    rrv_scene *s = NULL;
    rrv_error e;
    rrv_grid v;
    CHECKF(rrv_grid_read(path_in("density.vol"), NULL, 0, &v, &e) == RRV_OK, "%s", e.message);
    snprintf(text, sizeof text,
             "camera eye 1.05 0.6 -3 look 1.05 0.6 1.5 fov 40 resolution 24 16\n"
             "render spp 8 maxdepth 8 seed 3 integrator classic majorantcells 1\n"
             "environment constant L 1 1 1\n"
             "quad origin -2 -2 4 u 6 0 0 v 0 6 0 L 2 2 2\n"
             "medium m box %.17g %.17g %.17g %.17g %.17g %.17g sigma_a 0.4 0.4 0.4 sigma_s 1.5 1.5 1.5\n"
             "density m %s\n",
             v.lo.x, v.lo.y, v.lo.z, v.hi.x, v.hi.y, v.hi.z, density);
    rrv_free(v.data);
    CHECKF(rrv_scene_parse(text, strlen(text), "nv.rrv", dir, NULL, &s, &e) == RRV_OK, "%s", e.message);
    if (!s) return;
    *w = s->camera.width;
    *h = s->camera.height;
    memset(sum, 0, sizeof(float) * 3 * 24 * 16);
    CHECK(rrv_render_rect(s, 0, 0, *w, *h, 0, s->settings.spp, sum, *w, NULL, NULL) == RRV_OK);
    rrv_scene_free(s);
}

/* A render of the .nvdb equals a render of the same field as gridvol:
   same random numbers, one global majorant (both the grid's maximum), and
   densities that agree to float rounding, so only a tracking decision
   within ~1e-7 of its threshold could differ. */
static void render_equals_gridvol(void)
{
    static float a[3 * 24 * 16], b[3 * 24 * 16];
    int w = 0, h = 0, i, bad = 0;
    double total = 0;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    render("nanovdb fields.nvdb", a, &w, &h);
    render("grid density.vol", b, &w, &h);
    for (i = 0; i < 3 * w * h; ++i) {
        total += a[i];
        if (!(fabs(a[i] - b[i]) <= 1e-5 * (fabs(a[i]) + fabs(b[i]))) && bad++ < 3)
            CHECKF(0, "pixel value %d: %.9g vs gridvol %.9g", i, a[i], b[i]);
    }
    CHECK(bad == 0 && total > 0);
}

static void render_haze(const char *temperature, float *sum, int *w, int *h)
{
    char text[1400];
    rrv_scene *s = NULL;
    rrv_error e;
    rrv_grid v;
    CHECKF(rrv_grid_read(path_in("temperature.vol"), NULL, 0, &v, &e) == RRV_OK, "%s", e.message);
    snprintf(text, sizeof text,
             "camera eye 1.1 -0.2 -3 look 1.1 -0.2 1.5 fov 30 resolution 24 16\n"
             "render spp 4 maxdepth 4 seed 5 integrator refractive\n"
             "environment constant L 0.2 0.2 0.2\n"
             "material wall checker albedo 0.9 0.9 0.9 albedo2 0.1 0.1 0.1 checkerscale 0.05\n"
             "quad origin -1 -2 2 u 0 4 0 v 4 0 0 material wall\n"
             "quad origin -1 -2 -4 u 4 0 0 v 0 4 0 L 3 3 3\n"
             "medium m box %.17g %.17g %.17g %.17g %.17g %.17g sigma_a 0.05 0.05 0.05 sigma_s 0 0 0\n"
             "density m constant 1\n"
             "temperature m %s blackbody off\n"
             "ior m gas iorscale 20\n",
             v.lo.x + 1.5 * 0.05, v.lo.y + 1.5 * 0.04, v.lo.z + 1.5 * 0.06, v.hi.x - 1.5 * 0.05,
             v.hi.y - 1.5 * 0.04, v.hi.z - 1.5 * 0.06, temperature);
    rrv_free(v.data);
    CHECKF(rrv_scene_parse(text, strlen(text), "haze.rrv", dir, NULL, &s, &e) == RRV_OK, "%s", e.message);
    if (!s) return;
    *w = s->camera.width;
    *h = s->camera.height;
    CHECK(s->media[0].majorant && s->media[0].majorant->refraction.data != NULL);
    memset(sum, 0, sizeof(float) * 3 * 24 * 16);
    CHECK(rrv_render_rect(s, 0, 0, *w, *h, 0, s->settings.spp, sum, *w, NULL, NULL) == RRV_OK);
    rrv_scene_free(s);
}

/* Heat haze from a temperature grid: the refractivity is baked on the
   grid's index points in both cases, so inside the grid (the medium box is
   1.5 voxels in from the gridvol box, whose faces take one-sided
   differences where NanoVDB's background continues the field) the
   refractive renders agree to the rounding of the lattice positions
   (NanoVDB's map in double against gridvol's float box); a ray bent 1e-9
   rad differently still lands on the same checker square unless it grazes
   an edge. */
static void refractive_render_equals_gridvol(void)
{
    static float a[3 * 24 * 16], b[3 * 24 * 16];
    int w = 0, h = 0, i, bad = 0;
    double total = 0;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    render_haze("nanovdb fields.nvdb", a, &w, &h);
    render_haze("grid temperature.vol", b, &w, &h);
    for (i = 0; i < 3 * w * h; ++i) {
        total += a[i];
        if (!(fabs(a[i] - b[i]) <= 1e-4 * (fabs(a[i]) + fabs(b[i]))) && bad++ < 3)
            CHECKF(0, "pixel value %d: %.9g vs gridvol %.9g", i, a[i], b[i]);
    }
    CHECK(bad == 0 && total > 0);
}

/* The scene statements: grid chosen by name, the statement's own name by
   default, a clear message for a missing grid and for compressed files. */
static void scene_statements_and_messages(void)
{
    static const struct { const char *line, *message; } cases[] = {
        {"density m nanovdb fields.nvdb grid smoke",
         "NanoVDB file \"fields.nvdb\": no grid named \"smoke\" (the file has \"density\", \"temperature\")"},
        {"density m nanovdb fields_zip.nvdb",
         "NanoVDB file \"fields_zip.nvdb\": the grids are ZIP-compressed; rrv reads uncompressed files: re-convert with nanovdb_convert without -z/-b"},
        {"density m nanovdb nothing.nvdb", "cannot read NanoVDB file \"nothing.nvdb\": no such file"},
        {"density m nanovdb", "density: \"nanovdb\" needs a file path"},
        {"density m nanovdb fields.nvdb grid", "density: \"grid\" needs a value"},
        {"pressure m nanovdb fields.nvdb",
         "NanoVDB file \"fields.nvdb\": no grid named \"pressure\" (the file has \"density\", \"temperature\")"},
    };
    char text[512];
    rrv_scene *s = NULL;
    rrv_error e;
    size_t i;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    snprintf(text, sizeof text, "camera eye 0 0 -5 look 0 0 0\nmedium m box 0 0 0 2 2 2\ndensity m nanovdb fields.nvdb\n"
                                "temperature m nanovdb fields_fp16.nvdb temperaturescale 1\n");
    CHECKF(rrv_scene_parse(text, strlen(text), "nv.rrv", dir, NULL, &s, &e) == RRV_OK, "%s", e.message);
    if (s) {
        CHECK(s->media[0].density.kind == RRV_FIELD_NANOVDB && strcmp(s->media[0].density.nanovdb.name, "density") == 0);
        CHECK(s->media[0].temperature.nanovdb.type == RRV_NANOVDB_FP16 &&
              strcmp(s->media[0].temperature.nanovdb.name, "temperature") == 0);
        CHECK(s->grid_bytes == s->media[0].density.nanovdb.size + s->media[0].temperature.nanovdb.size);
        rrv_scene_free(s);
    }
    for (i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        snprintf(text, sizeof text, "medium m box 0 0 0 2 2 2\n%s\ncamera eye 0 0 -5 look 0 0 0\n", cases[i].line);
        s = NULL;
        CHECKF(rrv_scene_parse(text, strlen(text), "nv.rrv", dir, NULL, &s, &e) != RRV_OK && s == NULL, "%s", cases[i].line);
        CHECKF(e.line == 2 && strcmp(e.message, cases[i].message) == 0, "%s: got \"%s\" at line %d", cases[i].line,
               e.message, e.line);
    }
}

/* Newer files: "NanoVDB2" segment headers, and bare grid buffers one after
   the other (grids starting "NanoVDB1"), made from the real file by
   changing only the magic numbers. */
static void newer_magics(void)
{
    unsigned char *file, *bare;
    size_t size, at = 0, used = 0;
    int grids = 0;
    rrv_nanovdb g;
    rrv_error e;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    file = slurp(path_in("fields.nvdb"), &size);
    CHECK(file != NULL);
    if (!file) return;
    bare = (unsigned char *)malloc(size);
    /* each segment here holds one grid: header, metadata, name, buffer */
    while (at + 16 <= size && bare) {
        size_t meta = at + 16, name = rrv__nv_u32(file + meta + 136), grid = meta + 176 + name;
        size_t gs = (size_t)rrv__nv_u64(file + meta);
        CHECK(rrv__nv_u32(file + at + 12) == 1 && grid + gs <= size);
        if (grid + gs > size) break;
        memcpy(file + at, "NanoVDB2", 8);
        memcpy(bare + used, file + grid, gs);
        memcpy(bare + used, "NanoVDB1", 8);
        used += gs;
        at = grid + gs;
        ++grids;
    }
    CHECK(grids == 2);
    CHECKF(rrv_nanovdb_read_memory(file, size, "new.nvdb", "temperature", 0, &g, &e) == RRV_OK, "%s", e.message);
    if (g.buffer) {
        CHECK(rrv_nanovdb_voxel(&g, 7, -9, 0) != g.background);
        rrv_nanovdb_free(&g);
    }
    CHECKF(rrv_nanovdb_read_memory(bare, used, "bare.nvdb", "temperature", 0, &g, &e) == RRV_OK, "%s", e.message);
    if (g.buffer) {
        rrv_nanovdb d;
        CHECKF(rrv_nanovdb_read_memory(bare, used, "bare.nvdb", "density", 0, &d, &e) == RRV_OK, "%s", e.message);
        CHECK(d.buffer && rrv_nanovdb_voxel(&d, -5, 3, 10) != rrv_nanovdb_voxel(&g, -5, 3, 10));
        rrv_nanovdb_free(&d);
        rrv_nanovdb_free(&g);
    }
    CHECK(rrv_nanovdb_read_memory(bare, used, "bare.nvdb", "smoke", 0, &g, &e) == RRV_ERROR_FORMAT &&
          strcmp(e.message, "no grid named \"smoke\" (the file has \"density\", \"temperature\")") == 0);
    {
        /* a name from the file reaches a message or a caller's printf only as
           printable text: an escape sequence, a C1 control (C2 9B) and a cut
           sequence (C3) become '?', well-formed UTF-8 (C3 A9) stays */
        static const char hostile[] = "\x1b[31m\xc2\x9b\xc3\xa9x\xc3";
        memcpy(bare + 40, hostile, sizeof hostile);
        CHECKF(rrv_nanovdb_read_memory(bare, used, "bare.nvdb", "smoke", 0, &g, &e) == RRV_ERROR_FORMAT &&
                   strcmp(e.message, "no grid named \"smoke\" (the file has \"?[31m??\xc3\xa9x?\", "
                                     "\"temperature\")") == 0,
               "%s", e.message);
        CHECKF(rrv_nanovdb_read_memory(bare, used, "bare.nvdb", hostile, 0, &g, &e) == RRV_OK, "%s", e.message);
        if (g.buffer) {
            CHECK(strcmp(g.name, "?[31m??\xc3\xa9x?") == 0);
            rrv_nanovdb_free(&g);
        }
    }
    CHECK(rrv_nanovdb_read_memory(bare, used - 1, "bare.nvdb", "temperature", 0, &g, &e) == RRV_ERROR_FORMAT);
    /* a file cut short in a later grid is damaged, whichever grid is asked for */
    CHECKF(rrv_nanovdb_read_memory(bare, used - 1, "bare.nvdb", "\x1b[31m\xc2\x9b\xc3\xa9x\xc3", 0, &g, &e) ==
               RRV_ERROR_FORMAT, "%s", e.message);
    CHECKF(rrv_nanovdb_read_memory(file, size - 1, "new.nvdb", "density", 0, &g, &e) == RRV_ERROR_FORMAT &&
               strstr(e.message, "grid 0 of the segment at byte") != NULL,
           "%s", e.message);
    free(bare);
    free(file);
}

/* `rrv info` lists each grid with its type, voxel count, bounds, values
   and memory. */
static void info_lists_grids(void)
{
    static const char *const want[] = {
        "    density grid \"density\": float, 40320 active voxels, index -5 3 10 .. 34 38 37, world -0.15 -0.24 0.52 .. 2.3 1.4 2.5, values 0 .. 3.41237 (background 0), 846.34 KiB\n",
        "    temperature grid \"temperature\": fp16, 8640 active voxels, index 7 -9 0 .. 26 14 17, world 0.25 -0.88 0.04 .. 1.9 0.44 1.54, values 277.602 .. 1476.86 (background 300), 647.59 KiB\n"};
    char cmd[1600];
    size_t size, i;
    unsigned char *out;
    FILE *f;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    f = fopen(path_in("info.rrv"), "w");
    if (f) {
        fputs("camera eye 1 0.6 -3 look 1 0.6 1.5\nmedium m box 0 0 0 2 2 2\ndensity m nanovdb fields.nvdb\n"
              "temperature m nanovdb fields_fp16.nvdb\n", f);
        fclose(f);
    }
    snprintf(cmd, sizeof cmd, "%s/rrv info '%s' > '%s'", build_dir, path_in("info.rrv"), path_in("info.txt"));
    CHECKF(system(cmd) == 0, "%s failed", cmd);
    out = slurp(path_in("info.txt"), &size);
    CHECK(out != NULL);
    if (!out) return;
    {
        unsigned char *grown = (unsigned char *)realloc(out, size + 1);
        CHECK(grown != NULL);
        if (!grown) { free(out); return; }
        out = grown;
    }
    out[size] = 0;
    for (i = 0; i < 2; ++i) CHECKF(strstr((const char *)out, want[i]) != NULL, "no line %s in:\n%s", want[i], (const char *)out);
    free(out);
}

static void put64(unsigned char *b, uint64_t v)
{
    int i;
    for (i = 0; i < 8; ++i) b[i] = (unsigned char)(v >> (8 * i));
}

static void put32(unsigned char *b, uint32_t v)
{
    int i;
    for (i = 0; i < 4; ++i) b[i] = (unsigned char)(v >> (8 * i));
}

static void expect_message(const unsigned char *data, size_t size, const char *grid, const char *message)
{
    rrv_nanovdb g;
    rrv_error e;
    rrv_result r = rrv_nanovdb_read_memory(data, size, "bad.nvdb", grid, 0, &g, &e);
    CHECKF(r != RRV_OK && g.buffer == NULL, "read a corrupt file (expected: %s)", message);
    CHECKF(strcmp(e.message, message) == 0 && strcmp(e.file, "bad.nvdb") == 0, "got \"%s\", expected \"%s\"",
           e.message, message);
    if (r == RRV_OK) rrv_nanovdb_free(&g);
}

/* Real files corrupted in chosen places give exact messages; truncated at
   every length and with random bytes flipped they are refused or read,
   never read outside the buffer (this test runs under ASan with SAN=1). */
static void hostile_files(void)
{
    unsigned char *file, *copy;
    size_t size, n, grid, meta = 16, root, upper;
    rrv_nanovdb g;
    rrv_error e;
    char msg[256];
    rrv__rng rng;
    int i;
    if (!tools_ok) { CHECKF(0, "the known-answer files are missing; " INSTALL_HINT); return; }
    file = slurp(path_in("fields.nvdb"), &size);
    CHECK(file != NULL && size > 2000);
    if (!file) return;
    copy = (unsigned char *)malloc(size);
    grid = meta + 176 + rrv__nv_u32(file + meta + 136); /* the first grid's buffer */
    root = grid + RRV__NV_GRID + rrv__nv_u64(file + grid + RRV__NV_GRID + 24);
    upper = grid + RRV__NV_GRID + rrv__nv_u64(file + grid + RRV__NV_GRID + 16);

    memcpy(copy, file, size);
    copy[0] = 'X';
    expect_message(copy, size, "density", "not a NanoVDB file: it does not start with \"NanoVDB0\", \"NanoVDB1\" or \"NanoVDB2\"");
    expect_message(file, 12, "density", "the file ends inside the segment header at byte 0");
    memcpy(copy, file, size);
    put32(copy + 8, 31u << 21);
    expect_message(copy, size, "density", "NanoVDB version 31.0.0: rrv reads 32.x files");
    memcpy(copy, file, size);
    copy[14] = 2;
    expect_message(copy, size, "density",
                   "the grids are BLOSC-compressed; rrv reads uncompressed files: re-convert with nanovdb_convert without -z/-b");
    expect_message(file, grid + 1000, "density",
                   "grid 0 of the segment at byte 0 needs 866656 bytes, the file has 1000 left");
    memcpy(copy, file, size);
    put32(copy + grid + 636, 2);
    expect_message(copy, size, "density", "grid \"density\" holds double values; rrv reads float, fp4, fp8, fp16 and fpN grids");
    memcpy(copy, file, size);
    put64(copy + grid + 456, 0); /* the inverse's first entry */
    expect_message(copy, size, "density",
                   "grid \"density\": its index-to-world map is not finite and invertible, or its stored inverse does not match it");
    memcpy(copy, file, size);
    put64(copy + root + RRV__NV_ROOT + 8, 12345);
    snprintf(msg, sizeof msg, "grid \"density\": a root tile points to byte %llu, which is not one of its 2 upper nodes",
             (unsigned long long)(root - grid + 12345));
    expect_message(copy, size, "density", msg);
    memcpy(copy, file, size);
    put32(copy + root + 24, 1u << 30);
    expect_message(copy, size, "density", "grid \"density\": its root's 1073741824 tiles do not fit in its 866656 bytes");
    memcpy(copy, file, size);
    put32(copy + grid + RRV__NV_GRID + 32, 1000000); /* leaf count */
    snprintf(msg, sizeof msg, "grid \"density\": its 1000000 leaves at byte %llu do not fit in its 866656 bytes",
             (unsigned long long)(RRV__NV_GRID + rrv__nv_u64(file + grid + RRV__NV_GRID)));
    expect_message(copy, size, "density", msg);
    {
        /* a NaN in the first leaf's first value */
        size_t leaf = grid + RRV__NV_GRID + rrv__nv_u64(file + grid + RRV__NV_GRID);
        int64_t o[3];
        memcpy(copy, file, size);
        put32(copy + leaf + RRV__NV_LEAF_DATA, 0x7fc00000u);
        for (i = 0; i < 3; ++i) o[i] = rrv__nv_s32(rrv__nv_u32(file + leaf + 4 * (size_t)i)) & ~7;
        snprintf(msg, sizeof msg, "grid \"density\": a voxel value at index %lld %lld %lld is not finite",
                 (long long)o[0], (long long)o[1], (long long)o[2]);
        expect_message(copy, size, "density", msg);
    }
    CHECKF(rrv_nanovdb_read_memory(file, size, "ok.nvdb", "density", size / 2, &g, &e) == RRV_ERROR_LIMIT &&
               strstr(e.message, "over the limit") != NULL,
           "%s", e.message);
    (void)upper;

    /* every truncation of the headers and the first nodes, then sampled ones */
    for (n = 0; n < size; n += n < 4096 ? 1 : 997) {
        rrv_result r = rrv_nanovdb_read_memory(file, n, "cut.nvdb", "temperature", 0, &g, &e);
        CHECKF(r != RRV_OK && e.message[0], "a file cut to %llu bytes was read", (unsigned long long)n);
        if (r == RRV_OK) rrv_nanovdb_free(&g);
    }
    /* random corruption anywhere in the headers and tree */
    rrv__rng_seed(&rng, 77, 0, 0);
    for (i = 0; i < 400; ++i) {
        int k;
        rrv_result r;
        memcpy(copy, file, size);
        for (k = 0; k < 8; ++k) {
            size_t at = (size_t)(rrv__uniform(&rng) * (k < 4 ? 12000.0 : (double)size));
            copy[at < size ? at : size - 1] ^= (unsigned char)(1u + (unsigned)(rrv__uniform(&rng) * 255));
        }
        r = rrv_nanovdb_read_memory(copy, size, "flip.nvdb", "density", 0, &g, &e);
        if (r == RRV_OK) {
            rrv__rng probe;
            int j;
            rrv__rng_seed(&probe, 5, (uint64_t)i, 0);
            for (j = 0; j < 200; ++j) {
                rrv_vec3 p = rrv__v3(g.lo.x + (g.hi.x - g.lo.x) * rrv__uniform(&probe),
                                     g.lo.y + (g.hi.y - g.lo.y) * rrv__uniform(&probe),
                                     g.lo.z + (g.hi.z - g.lo.z) * rrv__uniform(&probe));
                double v = rrv_nanovdb_sample(&g, p);
                CHECK(v >= g.value_min && v <= g.value_max);
            }
            CHECK(rrv__nv_bound(&g, g.lo, g.hi) <= g.value_max);
            rrv_nanovdb_free(&g);
        } else {
            CHECK(e.message[0] != '\0' && g.buffer == NULL);
        }
    }
    free(copy);
    free(file);
}

int main(int argc, char **argv)
{
    if (argc > 1) build_dir = argv[1];
    snprintf(dir, sizeof dir, "%s/nanovdb_tmp", build_dir);
    if (mkdir(dir, 0777) != 0 && errno != EEXIST) {
        printf("FAIL cannot create %s: %s\n", dir, strerror(errno));
        return 1;
    }
    RUN(make_files);
    RUN(float_voxels_exact);
    RUN(fp16_voxels_within_quantum);
    RUN(fp8_voxels_within_quantum);
    RUN(fp4_voxels_within_quantum);
    RUN(fpn_voxels_within_tolerance);
    RUN(sparse_probes_exact);
    RUN(world_placement_matches_gridvol);
    RUN(bound_is_an_upper_bound);
    RUN(render_equals_gridvol);
    RUN(refractive_render_equals_gridvol);
    RUN(scene_statements_and_messages);
    RUN(info_lists_grids);
    RUN(newer_magics);
    RUN(hostile_files);
    return CHECK_EXIT_CODE();
}
