/* Adaptive sampling (rrv_render_rect_adaptive, rrv render --noise-threshold):
   sums and counts that do not depend on how the image is split, a pixel
   of equal samples stopping at the first check, a smaller threshold never
   taking fewer samples, threshold 0 being the uniform render bit for bit,
   and the refusal of parts. Runs BUILD/rrv for the command-line cases;
   argv[1] is the build folder. Every render has a fixed seed. */
#define _POSIX_C_SOURCE 200809L
#include "../rrv.h"
#include "check.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>

#define PATH_SIZE 1024

static char rrv_binary[PATH_SIZE], tmp_dir[PATH_SIZE / 2], scene_path[PATH_SIZE], key_scene_path[PATH_SIZE];
static char captured_stderr[PATH_SIZE];

/* Fog lit by a small light over a floor: noisy pixels, and a sky that is
   not constant, so pixels stop at different counts. */
static const char fog_scene[] =
    "camera eye 0 1 -4 look 0 0.8 0 fov 45 resolution 24 16\n"
    "render spp 256 seed 7 maxdepth 8\n"
    "environment gradient top 0.35 0.42 0.55 bottom 0.08 0.07 0.06\n"
    "material grey diffuse albedo 0.6 0.6 0.6\n"
    "quad origin -2 0 -2 u 0 0 4 v 4 0 0 material grey\n"
    "quad origin -0.5 2.5 -0.5 u 1 0 0 v 0 0 1 L 8 8 8\n"
    "medium fog box -1 0 -1 1 2 1 sigma_a 0.2 0.2 0.2 sigma_s 0.6 0.6 0.6\n"
    "density fog constant 0.8\n";

static const char *tmp_path(const char *name)
{
    static char paths[16][PATH_SIZE];
    static int next;
    char *path = paths[next++ % 16];
    snprintf(path, PATH_SIZE, "%s/%s", tmp_dir, name);
    return path;
}

static int write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    int ok;
    if (!f) return 0;
    ok = fputs(text, f) >= 0;
    return fclose(f) == 0 && ok;
}

static int file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

static char last_stderr[8192];

/* Runs `rrv ARGUMENTS` and returns its exit status (-1: it did not exit). */
static int rrv(const char *arguments)
{
    char command[4 * PATH_SIZE];
    int status;
    FILE *f;
    size_t n;
    snprintf(command, sizeof command, "'%s' %s >/dev/null 2>'%s' </dev/null", rrv_binary, arguments,
             captured_stderr);
    status = system(command);
    last_stderr[0] = '\0';
    if ((f = fopen(captured_stderr, "rb")) != NULL) {
        n = fread(last_stderr, 1, sizeof last_stderr - 1, f);
        last_stderr[n] = '\0';
        fclose(f);
    }
    return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

static rrv_scene *load(const char *text)
{
    rrv_scene *scene = NULL;
    rrv_error err;
    if (rrv_scene_parse(text, strlen(text), "adaptive.rrv", NULL, NULL, &scene, &err) != RRV_OK) {
        printf("  cannot parse the scene: %s\n", err.message);
        return NULL;
    }
    return scene;
}

/* The whole image as rectangles of tw x th (the last ones clipped). */
static int render_tiled(const rrv_scene *scene, int tw, int th, int spp, double threshold, float *sum, int *counts)
{
    int w = scene->camera.width, h = scene->camera.height, x, y;
    rrv_error err;
    for (y = 0; y < h; y += th)
        for (x = 0; x < w; x += tw) {
            int x1 = x + tw < w ? x + tw : w, y1 = y + th < h ? y + th : h;
            if (rrv_render_rect_adaptive(scene, x, y, x1, y1, spp, threshold, sum + 3 * ((size_t)y * w + x), w,
                                         counts + (size_t)y * w + x, NULL, &err) != RRV_OK) {
                printf("  render failed: %s\n", err.message);
                return 0;
            }
        }
    return 1;
}

/* One call, 16 x 16 tiles, 5 x 3 tiles and single pixels: the same sums
   and counts, bit for bit; and some pixels stopped early, some did not. */
static void split_renders_are_identical(void)
{
    static const int layouts[][2] = {{24, 16}, {16, 16}, {5, 3}, {1, 1}};
    rrv_scene *scene = load(fog_scene);
    float sum[4][24 * 16 * 3];
    int counts[4][24 * 16], i, early = 0, full = 0;
    if (!scene) {
        CHECK(0);
        return;
    }
    for (i = 0; i < 4; ++i) CHECK(render_tiled(scene, layouts[i][0], layouts[i][1], 256, 0.05, sum[i], counts[i]));
    for (i = 1; i < 4; ++i) {
        CHECKF(memcmp(sum[0], sum[i], sizeof sum[0]) == 0, "sums of %dx%d tiles differ", layouts[i][0], layouts[i][1]);
        CHECKF(memcmp(counts[0], counts[i], sizeof counts[0]) == 0, "counts of %dx%d tiles differ", layouts[i][0],
               layouts[i][1]);
    }
    for (i = 0; i < 24 * 16; ++i) {
        early += counts[0][i] < 256;
        full += counts[0][i] == 256;
    }
    CHECKF(early > 0 && full > 0, "%d pixels stopped early, %d ran to 256: the test splits nothing", early, full);
    rrv_scene_free(scene);
}

/* Under a constant sky every sample is exactly 1: their variance, and so
   the error, is 0, and every pixel stops at the first check, 32 samples, with a
   sum of exactly 32 whatever the (positive) threshold. */
static void equal_samples_stop_at_the_first_check(void)
{
    static const char sky[] = "camera eye 0 0 -3 look 0 0 0 resolution 8 6\nrender spp 1024 seed 3\n"
                              "environment constant L 1 1 1\n";
    rrv_scene *scene = load(sky);
    float sum[8 * 6 * 3];
    int counts[8 * 6], i, wrong = 0;
    if (!scene) {
        CHECK(0);
        return;
    }
    CHECK(render_tiled(scene, 8, 6, 1024, 1e-9, sum, counts));
    for (i = 0; i < 8 * 6; ++i) wrong += counts[i] != 2 * RRV_ADAPTIVE_BLOCK || sum[3 * i] != 32.0f;
    CHECKF(wrong == 0, "%d of 48 pixels did not stop at 32 samples with a sum of 32 (first: %d samples, sum %g)",
           wrong, counts[0], sum[0]);
    rrv_scene_free(scene);
}

/* Thresholds 0.2 > 0.05 > 0.01 > 0.002: no pixel takes fewer samples at a
   smaller one (each check sees the same sums whatever the threshold), and
   each step changes some pixel, so the comparison is not vacuous. */
static void smaller_threshold_never_takes_fewer_samples(void)
{
    static const double thresholds[] = {0.2, 0.05, 0.01, 0.002};
    rrv_scene *scene = load(fog_scene);
    float sum[24 * 16 * 3];
    int counts[4][24 * 16], t, i;
    if (!scene) {
        CHECK(0);
        return;
    }
    for (t = 0; t < 4; ++t) CHECK(render_tiled(scene, 24, 16, 256, thresholds[t], sum, counts[t]));
    for (t = 1; t < 4; ++t) {
        int fewer = 0, more = 0;
        for (i = 0; i < 24 * 16; ++i) {
            fewer += counts[t][i] < counts[t - 1][i];
            more += counts[t][i] > counts[t - 1][i];
        }
        CHECKF(fewer == 0, "%d pixels took fewer samples at threshold %g than at %g", fewer, thresholds[t],
               thresholds[t - 1]);
        CHECKF(more > 0, "no pixel took more samples at %g than at %g", thresholds[t], thresholds[t - 1]);
    }
    rrv_scene_free(scene);
}

/* Reads a PFM the CLI wrote, row 0 at the top as rendered. */
static float *read_image(const char *path, int *w, int *h)
{
    float *rgb = NULL;
    rrv_error err;
    if (rrv_read_pfm(path, &rgb, w, h, &err) != RRV_OK) {
        printf("  cannot read %s: %s\n", path, err.message);
        return NULL;
    }
    return rgb;
}

/* Threshold 0 renders every sample in the tree main.c sums by: the
   library's sum / spp is the uniform CLI render's image bit for bit. And
   the CLI's adaptive image is the library's sum / count, for --threads 1
   and 2 and for a crop off the 16-pixel tiles. */
static void cli_matches_the_library(void)
{
    rrv_scene *scene = load(fog_scene);
    float sum[24 * 16 * 3], *image = NULL;
    int counts[24 * 16], w = 0, h = 0, i, x, y, off = 0;
    char args[3 * PATH_SIZE];
    if (!scene) {
        CHECK(0);
        return;
    }
    /* 200: a last block [128, 200) shorter than its sibling */
    CHECK(render_tiled(scene, 7, 5, 200, 0, sum, counts));
    snprintf(args, sizeof args, "render '%s' -o '%s' --spp 200 -q --threads 2", scene_path, tmp_path("u.pfm"));
    CHECKF(rrv(args) == 0, "%s", last_stderr);
    if ((image = read_image(tmp_path("u.pfm"), &w, &h)) != NULL && w == 24 && h == 16)
        for (i = 0; i < 24 * 16 * 3; ++i) off += counts[i / 3] != 200 || image[i] != sum[i] / 200.0f;
    CHECKF(image && off == 0, "%d values of the threshold-0 render are not the uniform render's", off);
    rrv_free(image);

    CHECK(render_tiled(scene, 24, 16, 256, 0.05, sum, counts));
    for (i = 0; i < 3; ++i) {
        static const char *const extra[] = {"--threads 1", "--threads 2", "--crop 3 5 24 16 --threads 2"};
        int x0 = i == 2 ? 3 : 0, y0 = i == 2 ? 5 : 0;
        snprintf(args, sizeof args, "render '%s' -o '%s' --noise-threshold 0.05 -q %s", scene_path,
                 tmp_path("a.pfm"), extra[i]);
        CHECKF(rrv(args) == 0, "%s", last_stderr);
        off = 0;
        image = read_image(tmp_path("a.pfm"), &w, &h);
        CHECKF(image && w == 24 - x0 && h == 16 - y0, "%s: a %dx%d image", extra[i], w, h);
        if (image && w == 24 - x0 && h == 16 - y0)
            for (y = 0; y < h; ++y)
                for (x = 0; x < w; ++x) {
                    size_t p = (size_t)(y + y0) * 24 + (size_t)(x + x0);
                    int c;
                    for (c = 0; c < 3; ++c) off += image[3 * ((size_t)y * w + x) + c] != sum[3 * p + c] / (float)counts[p];
                }
        CHECKF(off == 0, "%s: %d values differ from the library's sum / count", extra[i], off);
        rrv_free(image);
    }
    rrv_scene_free(scene);
}

/* Parts hold sums of one sample count: --noise-threshold with --samples or
   --tile, or a scene's noisethreshold with them, is a usage error (exit 1)
   naming the flags, with nothing written, in rrv render and rrv farm;
   --noise-threshold 0 lifts it. */
static void parts_are_refused(void)
{
    static const char *const cases[][3] = {
        {"scene", "--samples 0:128 --noise-threshold 0.05", "--samples"},
        {"scene", "--tile 0/2 --noise-threshold 0.05", "--tile"},
        {"key", "--samples 0:128", "--samples"},
        {"key", "--tile 1/2", "--tile"},
    };
    char args[3 * PATH_SIZE];
    int i;
    for (i = 0; i < 4; ++i) {
        const char *scene = cases[i][0][0] == 's' ? scene_path : key_scene_path;
        const char *out = tmp_path("part.exr");
        int code;
        remove(out);
        snprintf(args, sizeof args, "render '%s' -o '%s' -q %s", scene, out, cases[i][1]);
        code = rrv(args);
        CHECKF(code == 1, "%s: exit %d, not 1", cases[i][1], code);
        CHECKF(strstr(last_stderr, cases[i][2]) && strstr(last_stderr, cases[i][0][0] == 's' ? "--noise-threshold"
                                                                                              : "noisethreshold"),
               "%s: the message does not name the flags: %s", cases[i][1], last_stderr);
        CHECKF(!file_exists(out), "%s: a part was written", cases[i][1]);
    }
    /* the farm's parts are tiles: refused before anything is written */
    for (i = 0; i < 2; ++i) {
        int code;
        snprintf(args, sizeof args, "farm slurm '%s' -o '%s' --tiles 2%s", i ? key_scene_path : scene_path,
                 tmp_path("farm.exr"), i ? "" : " -- --noise-threshold 0.05");
        code = rrv(args);
        CHECKF(code == 1 && strstr(last_stderr, i ? "noisethreshold" : "--noise-threshold") &&
                   strstr(last_stderr, "--tile"), "farm %d: exit %d: %s", i, code, last_stderr);
        CHECKF(!file_exists(tmp_path("farm.exr.farm")), "farm %d: its folder was made", i);
    }
    snprintf(args, sizeof args, "render '%s' -o '%s' -q --samples 0:128 --noise-threshold 0", key_scene_path,
             tmp_path("part.exr"));
    CHECKF(rrv(args) == 0 && file_exists(tmp_path("part.exr")), "--noise-threshold 0 did not lift it: %s",
           last_stderr);
}

/* The library refuses what it cannot render, naming itself. */
static void bad_arguments_are_refused(void)
{
    rrv_scene *scene = load(fog_scene);
    float sum[3];
    int count = -1;
    rrv_error err;
    if (!scene) {
        CHECK(0);
        return;
    }
    CHECK(rrv_render_rect_adaptive(scene, 0, 0, 1, 1, 64, -0.1, sum, 1, &count, NULL, &err) == RRV_ERROR_ARGUMENT);
    CHECK(strstr(err.message, "rrv_render_rect_adaptive") != NULL);
    CHECK(rrv_render_rect_adaptive(scene, 0, 0, 1, 1, 0, 0.1, sum, 1, &count, NULL, &err) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_render_rect_adaptive(scene, 0, 0, 1, 1, 64, 0.1, sum, 1, NULL, NULL, &err) == RRV_ERROR_ARGUMENT);
    CHECK(count == -1);
    rrv_scene_free(scene);
}

int main(int argc, char **argv)
{
    char key_scene[sizeof fog_scene + 64];
    if (argc < 2 || strlen(argv[1]) > sizeof tmp_dir - 32) {
        printf("usage: %s BUILD_DIR\n", argv[0]);
        return 2;
    }
    snprintf(rrv_binary, sizeof rrv_binary, "%s/rrv", argv[1]);
    snprintf(tmp_dir, sizeof tmp_dir, "%s/adaptive_tmp", argv[1]);
    snprintf(scene_path, sizeof scene_path, "%s/fog.rrv", tmp_dir);
    snprintf(key_scene_path, sizeof key_scene_path, "%s/fog_key.rrv", tmp_dir);
    snprintf(captured_stderr, sizeof captured_stderr, "%s/stderr.txt", tmp_dir);
    if (mkdir(tmp_dir, 0777) != 0 && errno != EEXIST) {
        printf("FAIL cannot create %s: %s\n", tmp_dir, strerror(errno));
        return 1;
    }
    /* the same scene with `render ... noisethreshold 0.05` */
    snprintf(key_scene, sizeof key_scene, "%s", fog_scene);
    {
        char *line = strstr(key_scene, "maxdepth 8\n");
        if (line) strcpy(line, "maxdepth 8 noisethreshold 0.05\n");
        if (line) strcat(key_scene, strstr(fog_scene, "environment"));
    }
    if (!file_exists(rrv_binary) || !write_text(scene_path, fog_scene) || !write_text(key_scene_path, key_scene)) {
        printf("FAIL setup: %s missing or %s not writable\n", rrv_binary, tmp_dir);
        return 1;
    }
    RUN(split_renders_are_identical);
    RUN(equal_samples_stop_at_the_first_check);
    RUN(smaller_threshold_never_takes_fewer_samples);
    RUN(cli_matches_the_library);
    RUN(parts_are_refused);
    RUN(bad_arguments_are_refused);
    return CHECK_EXIT_CODE();
}
