/* Lookup cost of a NanoVDB grid against a dense gridvol grid of the same
   data. Not a test (make test does not run it): after make test has left
   the known-answer files in build/nanovdb_tmp,
     cc -std=c99 -O2 -o build/measure_nanovdb test/measure_nanovdb.c -lm
     build/measure_nanovdb build/nanovdb_tmp
   Both fields are sampled (trilinear, and the gradient stencil) at the same
   random points inside the data, in interleaved rounds; it prints the
   median CPU (user + sys, clock()) and wall time a lookup. */
#define _POSIX_C_SOURCE 200809L
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>
#include <time.h>

#define POINTS 1000000
#define ROUNDS 9

static double wall(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp);
    return v[n / 2];
}

int main(int argc, char **argv)
{
    static const char *const files[] = {"fields.nvdb", "fields_fp16.nvdb", "fields_fpn.nvdb"};
    char path[600];
    rrv_grid dense;
    rrv_nanovdb g[3];
    rrv_error e;
    rrv_vec3 *pts;
    double cpu[4][ROUNDS], wl[4][ROUNDS], sink = 0;
    int i, r, k;
    rrv__rng rng;
    const char *dir = argc > 1 ? argv[1] : "build/nanovdb_tmp";
    snprintf(path, sizeof path, "%s/density.vol", dir);
    if (rrv_grid_read(path, NULL, 0, &dense, &e) != RRV_OK) { printf("%s: %s\n", e.file, e.message); return 1; }
    for (k = 0; k < 3; ++k) {
        snprintf(path, sizeof path, "%s/%s", dir, files[k]);
        if (rrv_nanovdb_read(path, "density", NULL, &g[k], &e) != RRV_OK) { printf("%s: %s\n", e.file, e.message); return 1; }
    }
    pts = (rrv_vec3 *)malloc(POINTS * sizeof *pts);
    rrv__rng_seed(&rng, 1, 2, 3);
    for (i = 0; i < POINTS; ++i)
        pts[i] = rrv__v3(dense.lo.x + (dense.hi.x - dense.lo.x) * rrv__uniform(&rng),
                         dense.lo.y + (dense.hi.y - dense.lo.y) * rrv__uniform(&rng),
                         dense.lo.z + (dense.hi.z - dense.lo.z) * rrv__uniform(&rng));
    for (int pass = 0; pass < 2; ++pass) {
        for (r = 0; r < ROUNDS; ++r)
            for (k = 0; k < 4; ++k) {
                clock_t c0 = clock();
                double w0 = wall();
                for (i = 0; i < POINTS; ++i) {
                    if (pass == 0)
                        sink += k == 0 ? rrv__grid_sample(&dense, pts[i], 0, 0.0) : rrv_nanovdb_sample(&g[k - 1], pts[i]);
                    else
                        sink += k == 0 ? rrv__grid_gradient(&dense, pts[i]).x : rrv__nv_gradient(&g[k - 1], pts[i]).x;
                }
                wl[k][r] = (wall() - w0) / POINTS * 1e9;
                cpu[k][r] = (double)(clock() - c0) / CLOCKS_PER_SEC / POINTS * 1e9;
            }
        printf("%s, %d points x %d interleaved rounds, median ns a lookup (cpu / wall):\n",
               pass == 0 ? "trilinear value" : "gradient (central differences)", POINTS, ROUNDS);
        printf("  dense gridvol     %6.1f / %6.1f\n", median(cpu[0], ROUNDS), median(wl[0], ROUNDS));
        for (k = 1; k < 4; ++k)
            printf("  nanovdb %-9s %6.1f / %6.1f  (%.2fx dense)\n", rrv_nanovdb_type_name(g[k - 1].type),
                   median(cpu[k], ROUNDS), median(wl[k], ROUNDS), median(cpu[k], ROUNDS) / median(cpu[0], ROUNDS));
    }
    printf("memory: dense %zu bytes, nanovdb float %zu, fp16 %zu, fpN %zu (checksum %g)\n",
           (size_t)dense.nx * dense.ny * dense.nz * 4, g[0].size, g[1].size, g[2].size, sink);
    return 0;
}
