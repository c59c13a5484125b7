/* Tests of the rrv command-line tool: exit codes, error messages, that a
   failed run never clobbers an image, rrv diff's numbers, and that a render
   does not depend on the thread count or on being split into crops.
   Runs BUILD/rrv as a child process; argv[1] is the build folder. */
#define _POSIX_C_SOURCE 200809L
#include "../rrv.h"
#include "check.h"

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#define PATH_SIZE 1024
#define OUTPUT_SIZE 65536

static char rrv_binary[PATH_SIZE];
static char tmp_dir[PATH_SIZE / 2]; /* room for a file name in PATH_SIZE */
static char tiny_scene[PATH_SIZE];
static char bad_scene[PATH_SIZE];
static char captured_stdout[PATH_SIZE], captured_stderr[PATH_SIZE];

/* What one run of the tool did. */
typedef struct run_result {
    int code; /* exit status, or -1 if it did not exit normally */
    char out[OUTPUT_SIZE];
    char err[OUTPUT_SIZE];
} run_result;

static run_result last_run;

/* Static storage so a test can build several paths without buffers of its own. */
static const char *tmp_path(const char *name)
{
    static char paths[32][PATH_SIZE];
    static int next;
    char *path = paths[next++ % 32];
    snprintf(path, PATH_SIZE, "%s/%s", tmp_dir, name);
    return path;
}

static void *read_whole_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    char *data = NULL;
    size_t capacity = 0, used = 0;
    if (!f) return NULL;
    for (;;) {
        size_t n;
        if (used + 4096 + 1 > capacity) {
            char *grown;
            capacity = capacity * 2 + 8192;
            grown = (char *)realloc(data, capacity);
            if (!grown) {
                free(data);
                fclose(f);
                return NULL;
            }
            data = grown;
        }
        n = fread(data + used, 1, 4096, f);
        used += n;
        if (n < 4096) break;
    }
    fclose(f);
    data[used] = '\0';
    if (size) *size = used;
    return data;
}

static int write_whole_file(const char *path, const void *data, size_t size)
{
    FILE *f = fopen(path, "wb");
    int ok;
    if (!f) return 0;
    ok = fwrite(data, 1, size, f) == size;
    return fclose(f) == 0 && ok;
}

static int write_text(const char *path, const char *text)
{
    return write_whole_file(path, text, strlen(text));
}

/* A hard link, so that two names share one inode. */
static int link_or_copy(const char *from, const char *to) { return link(from, to) == 0; }

static int file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

static void copy_capture(const char *path, char *into)
{
    size_t size = 0;
    char *data = (char *)read_whole_file(path, &size);
    into[0] = '\0';
    if (!data) return;
    if (size >= OUTPUT_SIZE) size = OUTPUT_SIZE - 1;
    memcpy(into, data, size);
    into[size] = '\0';
    free(data);
}

/* Runs `PREFIX rrv ARGUMENTS` (shell fragments) and fills last_run. */
static int rrv_prefixed(const char *prefix, const char *arguments)
{
    char command[4 * PATH_SIZE];
    int status;
    snprintf(command, sizeof command, "%s '%s' %s >'%s' 2>'%s' </dev/null", prefix, rrv_binary,
             arguments, captured_stdout, captured_stderr);
    status = system(command);
    last_run.code = status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    copy_capture(captured_stdout, last_run.out);
    copy_capture(captured_stderr, last_run.err);
    return last_run.code;
}

/* Runs `rrv ARGUMENTS` (a shell fragment) and fills last_run. */
static int rrv(const char *arguments) { return rrv_prefixed("", arguments); }

/* Files in tmp_dir that look like a writer's temporary file: rrv's (".NAME.XXXXXX")
   or the library's ("NAME.XXXXXXXX.tmp"), but not `own`, a "<out>.tmp" a test
   made to see that it survives. */
static int count_stray_temps(const char *own)
{
    DIR *dir = opendir(tmp_dir);
    struct dirent *entry;
    int count = 0;
    if (!dir) return -1;
    while ((entry = readdir(dir)) != NULL) {
        const char *name = entry->d_name;
        size_t n = strlen(name);
        if (strcmp(name, ".") == 0 || strcmp(name, "..") == 0) continue;
        if (own && strcmp(name, own) == 0) continue;
        if (name[0] == '.' || (n > 4 && strcmp(name + n - 4, ".tmp") == 0)) ++count;
    }
    closedir(dir);
    return count;
}

static int text_file_is(const char *path, const char *text)
{
    size_t size = 0;
    char *data = (char *)read_whole_file(path, &size);
    int same = data && size == strlen(text) && memcmp(data, text, size) == 0;
    free(data);
    return same;
}

static void strip_trailing_space(char *text)
{
    size_t n = strlen(text);
    while (n > 0 && (text[n - 1] == '\n' || text[n - 1] == '\r' || text[n - 1] == ' ')) text[--n] = '\0';
}

/* The value after "key: " at the start of a line of `text`, or NULL. */
static const char *find_key(const char *text, const char *key)
{
    size_t key_length = strlen(key);
    const char *line = text;
    while (line && *line) {
        if (strncmp(line, key, key_length) == 0 && line[key_length] == ':' &&
            line[key_length + 1] == ' ')
            return line + key_length + 2;
        line = strchr(line, '\n');
        if (line) ++line;
    }
    return NULL;
}

static double key_number(const char *text, const char *key)
{
    const char *value = find_key(text, key);
    return value ? strtod(value, NULL) : NAN;
}

static int near(double a, double b) { return fabs(a - b) <= 1e-6 * (fabs(b) + 1e-9); }

/* ---- PFM by hand, so these tests do not lean on the library under test ---- */

static int write_pfm_by_hand(const char *path, const float *rgb, int width, int height)
{
    FILE *f = fopen(path, "wb");
    int x, y, c, ok;
    if (!f) return 0;
    fprintf(f, "PF\n%d %d\n-1.0\n", width, height);
    for (y = height - 1; y >= 0; --y) /* PFM rows run bottom to top */
        for (x = 0; x < width; ++x)
            for (c = 0; c < 3; ++c) {
                uint32_t bits;
                unsigned char bytes[4];
                memcpy(&bits, &rgb[3 * (y * width + x) + c], 4);
                bytes[0] = (unsigned char)bits;
                bytes[1] = (unsigned char)(bits >> 8);
                bytes[2] = (unsigned char)(bits >> 16);
                bytes[3] = (unsigned char)(bits >> 24);
                fwrite(bytes, 1, 4, f);
            }
    ok = !ferror(f);
    return fclose(f) == 0 && ok;
}

/* Reads the little-endian colour PFMs rrv writes; rows come back top first. */
static float *read_pfm_by_hand(const char *path, int *width, int *height)
{
    size_t size = 0, offset, count, i;
    unsigned char *data = (unsigned char *)read_whole_file(path, &size);
    float *rgb;
    double scale;
    int header_length = 0, x, y, c;
    if (!data) return NULL;
    if (sscanf((const char *)data, "PF\n%d %d\n%lf%n", width, height, &scale, &header_length) != 3 ||
        *width <= 0 || *height <= 0 || scale >= 0) {
        free(data);
        return NULL;
    }
    offset = (size_t)header_length + 1; /* the single newline after the scale */
    count = (size_t)*width * (size_t)*height * 3;
    if (size != offset + 4 * count) {
        free(data);
        return NULL;
    }
    rgb = (float *)malloc(count * sizeof *rgb);
    if (!rgb) {
        free(data);
        return NULL;
    }
    i = offset;
    for (y = *height - 1; y >= 0; --y)
        for (x = 0; x < *width; ++x)
            for (c = 0; c < 3; ++c, i += 4) {
                uint32_t bits = (uint32_t)data[i] | (uint32_t)data[i + 1] << 8 |
                                (uint32_t)data[i + 2] << 16 | (uint32_t)data[i + 3] << 24;
                memcpy(&rgb[3 * ((size_t)y * *width + x) + c], &bits, 4);
            }
    free(data);
    return rgb;
}

static int files_identical(const char *a, const char *b)
{
    size_t size_a = 0, size_b = 0;
    char *data_a = (char *)read_whole_file(a, &size_a), *data_b = (char *)read_whole_file(b, &size_b);
    int same = data_a && data_b && size_a == size_b && memcmp(data_a, data_b, size_a) == 0;
    free(data_a);
    free(data_b);
    return same;
}

/* ---- tests ------------------------------------------------------------------ */

static void help_exits_zero(void)
{
    static const char *const commands[] = {"--help", "-h", "help", "help render",
                                           "render --help", "diff --help", "info --help",
                                           "trace --help", "help trace"};
    size_t i;
    for (i = 0; i < sizeof commands / sizeof commands[0]; ++i) {
        char arguments[256];
        snprintf(arguments, sizeof arguments, "%s", commands[i]);
        CHECKF(rrv(arguments) == 0, "rrv %s exited %d", commands[i], last_run.code);
        CHECKF(strstr(last_run.out, "usage") != NULL, "rrv %s printed no usage on stdout",
               commands[i]);
        CHECKF(last_run.err[0] == '\0', "rrv %s wrote to stderr: %s", commands[i], last_run.err);
    }
    rrv("diff --help");
    CHECKF(strstr(last_run.out, "reference") != NULL, "diff --help does not say B is the reference");
    CHECK(rrv("--version") == 0);
    CHECK(strncmp(last_run.out, "rrv ", 4) == 0);
}

static void expect_usage_error(const char *arguments)
{
    rrv(arguments);
    CHECKF(last_run.code == 1, "rrv %s exited %d, not 1; stderr: %s", arguments, last_run.code,
           last_run.err);
    CHECKF(strstr(last_run.err, "--help") != NULL || strstr(last_run.err, "usage") != NULL,
           "rrv %s gave no hint to --help: %s", arguments, last_run.err);
}

static void usage_errors_exit_one(void)
{
    static const char *const render_flags[] = {
        "--bogus", "--spp 0", "--spp abc", "--spp 3x", "--spp", "--spp -2", "--threads -1",
        "--threads 0", "--seed -3", "--seed 1.5", "--exposure nan", "--exposure", "--exposure 0x1p1",
        "--exposure inf", "--integrator magic",
        "--max-grid-mb 0", "--crop 0 0 8", "--crop 0 0 100 100", "--crop 5 5 5 10",
        "--crop 0 0 24 17", "--crop -1 0 4 4", "--crop a 0 4 4", "extra_positional.rrv"};
    const char *out = tmp_path("usage_out.pfm");
    char arguments[2 * PATH_SIZE];
    size_t i;

    expect_usage_error("frobnicate");
    expect_usage_error("--frobnicate");
    CHECK(rrv("") == 1);
    remove(out);
    for (i = 0; i < sizeof render_flags / sizeof render_flags[0]; ++i) {
        snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q %s", tiny_scene, out,
                 render_flags[i]);
        expect_usage_error(arguments);
    }
    CHECKF(!file_exists(out), "a usage error wrote %s", out);

    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --spp abc", tiny_scene, out);
    rrv(arguments);
    CHECKF(strstr(last_run.err, "rrv: --spp needs a positive integer") != NULL &&
               strstr(last_run.err, "\"abc\"") != NULL,
           "unexpected message: %s", last_run.err);

    snprintf(arguments, sizeof arguments, "render '%s'", tiny_scene); /* no -o */
    expect_usage_error(arguments);
    snprintf(arguments, sizeof arguments, "render -o '%s'", out); /* no scene */
    expect_usage_error(arguments);
    expect_usage_error("diff only_one.pfm");
    expect_usage_error("diff a.pfm b.pfm c.pfm");
    expect_usage_error("info");
    snprintf(arguments, sizeof arguments, "info '%s' --spp 3", tiny_scene);
    expect_usage_error(arguments);
    snprintf(arguments, sizeof arguments, "trace '%s'", tiny_scene); /* no --ray */
    expect_usage_error(arguments);
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 0 0 1 0", tiny_scene);
    expect_usage_error(arguments);
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 0 0 0 0 0", tiny_scene);
    expect_usage_error(arguments);
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 0 0 0 0 1 --integrator classic",
             tiny_scene);
    expect_usage_error(arguments);
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 0 0 0 0 1 --n 0", tiny_scene);
    expect_usage_error(arguments);
}

static int compare_names(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

static void corpus_errors_match_expect(void)
{
    DIR *dir = opendir("test/corpus");
    char *names[1024];
    int count = 0, i;
    struct dirent *entry;
    CHECKF(dir != NULL, "cannot open test/corpus: %s", strerror(errno));
    if (!dir) return;
    while ((entry = readdir(dir)) != NULL && count < 1024) {
        size_t n = strlen(entry->d_name);
        if (n > 4 && strcmp(entry->d_name + n - 4, ".rrv") == 0) {
            names[count] = (char *)malloc(n + 1);
            if (names[count]) memcpy(names[count++], entry->d_name, n + 1);
        }
    }
    closedir(dir);
    CHECKF(count > 0, "test/corpus holds no .rrv files");
    qsort(names, (size_t)count, sizeof names[0], compare_names);

    for (i = 0; i < count; ++i) {
        char scene[PATH_SIZE], expect_path[PATH_SIZE], arguments[2 * PATH_SIZE];
        char *expected;
        snprintf(scene, sizeof scene, "test/corpus/%s", names[i]);
        snprintf(expect_path, sizeof expect_path, "test/corpus/%.*s.expect",
                 (int)strlen(names[i]) - 4, names[i]);
        expected = (char *)read_whole_file(expect_path, NULL);
        CHECKF(expected != NULL, "%s has no %s", scene, expect_path);
        if (!expected) continue;
        strip_trailing_space(expected);
        snprintf(arguments, sizeof arguments, "info '%s'", scene);
        rrv(arguments);
        strip_trailing_space(last_run.err);
        CHECKF(last_run.code == 2, "rrv info %s exited %d, not 2", scene, last_run.code);
        CHECKF(strcmp(last_run.err, expected) == 0,
               "rrv info %s:\n    stderr:   %s\n    expected: %s", scene, last_run.err, expected);
        free(expected);
    }

    if (count > 0) {
        const char *out = tmp_path("corpus_out.pfm");
        char arguments[2 * PATH_SIZE];
        remove(out);
        snprintf(arguments, sizeof arguments, "render 'test/corpus/%s' -o '%s' -q", names[0], out);
        CHECKF(rrv(arguments) == 2, "rrv %s exited %d, not 2", arguments, last_run.code);
        CHECKF(!file_exists(out) && count_stray_temps(NULL) == 0, "a failed render wrote %s", out);
    }
    for (i = 0; i < count; ++i) free(names[i]);
}

static void failed_render_keeps_existing_output(void)
{
    static const char good[] = "a good image from an earlier render";
    const char *out = tmp_path("keep.pfm");
    char arguments[3 * PATH_SIZE];
    size_t size = 0;
    char *after;

    CHECK(write_text(out, good));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", bad_scene, out);
    CHECKF(rrv(arguments) == 2, "bad scene: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", tmp_path("missing.rrv"), out);
    CHECKF(rrv(arguments) == 2, "missing scene: exit %d", last_run.code);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q --crop 0 0 99 99", tiny_scene,
             out);
    CHECKF(rrv(arguments) == 1, "bad crop: exit %d", last_run.code);

    after = (char *)read_whole_file(out, &size);
    CHECKF(after && size == strlen(good) && memcmp(after, good, size) == 0,
           "%s was changed by a failed render", out);
    free(after);
}

static void unwritable_output_exits_three(void)
{
    char arguments[3 * PATH_SIZE];
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", tiny_scene,
             tmp_path("no_such_dir/out.pfm"));
    CHECKF(rrv(arguments) == 3, "exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(last_run.err[0] != '\0');
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' -q", tiny_scene,
             tmp_path("png_dir_missing.pfm"), tmp_path("no_such_dir/out.png"));
    CHECKF(rrv(arguments) == 3, "exit %d, stderr %s", last_run.code, last_run.err);
}

/* An output that is an input, or the other output, is refused before the
   render, whatever its spelling; the file is left as it was. */
static void output_that_is_an_input_is_refused(void)
{
    static const char tri[] = "v -1 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    const char *scene = tmp_path("inputs.rrv"), *obj = tmp_path("inputs.obj");
    const char *grid = tmp_path("inputs.vol"), *link = tmp_path("inputs_link.rrv");
    const char *same = tmp_path("same.pfm"), *same_link = tmp_path("same_link.png");
    char scene_text[PATH_SIZE], arguments[4 * PATH_SIZE], *grid_before = NULL;
    size_t grid_size = 0, after_size = 0;
    static const char *const spellings[] = {"%s", "%s/./inputs.rrv", "%s/../cli_tmp/inputs.rrv"};
    size_t i;

    grid_before = (char *)read_whole_file("scenes/assets/tiny.vol", &grid_size);
    CHECK(grid_before != NULL && write_whole_file(grid, grid_before, grid_size));
    CHECK(write_text(obj, tri));
    snprintf(scene_text, sizeof scene_text,
             "camera eye 0 0 -3 look 0 0 0 resolution 8 8\nrender spp 1\n"
             "mesh file inputs.obj L 1 1 1\nmedium m box -1 -1 -1 1 1 1 sigma_s 1 1 1\n"
             "density m grid inputs.vol\n");
    CHECK(write_text(scene, scene_text));
    remove(link);
    CHECK(link_or_copy(scene, link));

    for (i = 0; i < sizeof spellings / sizeof *spellings; ++i) {
        char out[PATH_SIZE];
        if (i == 0)
            snprintf(out, sizeof out, "%s", scene);
        else
            snprintf(out, sizeof out, spellings[i], tmp_dir);
        snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", scene, out);
        CHECKF(rrv(arguments) == 1, "-o %s: exit %d, stderr %s", out, last_run.code, last_run.err);
        CHECKF(strstr(last_run.err, "it is the scene file") != NULL, "%s", last_run.err);
        snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' -q", scene,
                 tmp_path("inputs_out.pfm"), out);
        CHECKF(rrv(arguments) == 1, "--png %s: exit %d, stderr %s", out, last_run.code, last_run.err);
    }
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", scene, link); /* a hard link */
    CHECKF(rrv(arguments) == 1, "hard link: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", scene, obj);
    CHECKF(rrv(arguments) == 1 && strstr(last_run.err, "the scene reads it") != NULL,
           "OBJ: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", scene, grid);
    CHECKF(rrv(arguments) == 1 && strstr(last_run.err, "the scene reads it") != NULL,
           "grid: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(text_file_is(scene, scene_text) && text_file_is(obj, tri));
    {
        char *after = (char *)read_whole_file(grid, &after_size);
        CHECK(after && after_size == grid_size && memcmp(after, grid_before, grid_size) == 0);
        free(after);
    }

    /* -o and --png naming one file, existing or not */
    remove(same);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s/./same.pfm' -q", scene,
             same, tmp_dir);
    CHECKF(rrv(arguments) == 1 && strstr(last_run.err, "name the same file") != NULL,
           "a new file twice: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(!file_exists(same));
    CHECK(write_text(same, "old"));
    remove(same_link);
    CHECK(link_or_copy(same, same_link));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' -q", scene, same,
             same_link);
    CHECKF(rrv(arguments) == 1 && strstr(last_run.err, "name the same file") != NULL,
           "a hard-linked pair: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(text_file_is(same, "old"));
    CHECK(count_stray_temps(NULL) == 0);

    /* the scene renders fine to a file of its own */
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", scene, tmp_path("inputs_out.pfm"));
    CHECKF(rrv(arguments) == 0, "exit %d, stderr %s", last_run.code, last_run.err);
    free(grid_before);
    remove(link);
    remove(same);
    remove(same_link);
}

/* An existing output that is not a regular file is refused, not replaced. */
static void non_regular_output_is_refused(void)
{
    const char *folder = tmp_path("out_folder"), *fifo = tmp_path("out_fifo");
    const char *sym = tmp_path("out_symlink_to_fifo"), *ok = tmp_path("non_regular_ok.pfm");
    char arguments[4 * PATH_SIZE];
    struct stat st;

    mkdir(folder, 0777);
    remove(fifo);
    remove(sym);
    CHECK(mkfifo(fifo, 0666) == 0);
    CHECK(symlink("out_fifo", sym) == 0);

    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", tiny_scene, folder);
    CHECKF(rrv(arguments) == 3 && strstr(last_run.err, "it is a directory, not a regular file"),
           "folder: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(stat(folder, &st) == 0 && S_ISDIR(st.st_mode));
    /* a FIFO: refused without opening it (opening would block the test) */
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' -q", tiny_scene, ok, fifo);
    CHECKF(rrv(arguments) == 3 && strstr(last_run.err, "it is a FIFO, not a regular file"),
           "FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(stat(fifo, &st) == 0 && S_ISFIFO(st.st_mode));
    CHECK(!file_exists(ok));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", tiny_scene, sym);
    CHECKF(rrv(arguments) == 3, "symbolic link to a FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(lstat(sym, &st) == 0 && S_ISLNK(st.st_mode));
    CHECK(count_stray_temps(NULL) == 0);
    rmdir(folder);
    remove(fifo);
    remove(sym);
}

/* The temporary file is new and unique: a file called "<out>.tmp" survives,
   two renders to one output at once both succeed, the output gets the usual
   permissions, and a write that fails part way keeps the old outputs. */
static void temporary_files_are_private(void)
{
    const char *out = tmp_path("temp_out.pfm"), *png = tmp_path("temp_out.png");
    const char *own = tmp_path("temp_out.pfm.tmp"), *single = tmp_path("temp_single.pfm");
    char arguments[4 * PATH_SIZE];
    struct stat st;
    int i;

    remove(out);
    remove(png);
    CHECK(write_text(own, "someone else's file"));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' -q", tiny_scene, out, png);
    CHECKF(rrv_prefixed("umask 022;", arguments) == 0, "exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(text_file_is(own, "someone else's file"));
    CHECK(count_stray_temps("temp_out.pfm.tmp") == 0);
    CHECKF(stat(out, &st) == 0 && (st.st_mode & 0777) == 0644, "mode %o", (unsigned)(st.st_mode & 0777));

    /* two at once, three times */
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q --threads 1", tiny_scene, single);
    CHECK(rrv(arguments) == 0);
    for (i = 0; i < 3; ++i) {
        char both[6 * PATH_SIZE];
        remove(out);
        snprintf(both, sizeof both,
                 "render '%s' -o '%s' -q --threads 1 & '%s' render '%s' -o '%s' -q --threads 1; "
                 "r=$?; wait $! && exit $r",
                 tiny_scene, out, rrv_binary, tiny_scene, out);
        CHECKF(rrv(both) == 0, "two renders at once: exit %d, stderr %s", last_run.code, last_run.err);
        CHECK(files_identical(out, single));
        CHECK(count_stray_temps("temp_out.pfm.tmp") == 0);
    }

    /* a file size limit makes the write fail part way: the old files stay */
    CHECK(write_text(out, "old image"));
    CHECK(write_text(png, "old preview"));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' -q", tiny_scene, out, png);
    rrv_prefixed("trap '' XFSZ; ulimit -f 2;", arguments);
    CHECKF(last_run.code == 3 && strstr(last_run.err, "cannot write") != NULL,
           "over a file size limit: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(text_file_is(out, "old image") && text_file_is(png, "old preview"));
    CHECK(count_stray_temps("temp_out.pfm.tmp") == 0);
    remove(own);
    remove(out);
    remove(png);
    remove(single);
}

/* Inputs without end or that are folders get a message, not a hang. */
static void odd_inputs_get_messages(void)
{
    char arguments[2 * PATH_SIZE];
    CHECKF(rrv("info test/corpus") == 2 &&
               strcmp(last_run.err, "test/corpus: cannot read scene file: is a directory\n") == 0,
           "exit %d, stderr %s", last_run.code, last_run.err);
    CHECKF(rrv("info /dev/zero") == 2 &&
               strcmp(last_run.err, "/dev/zero: cannot read scene file: not a regular file\n") == 0,
           "exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "diff /dev/zero '%s'", tiny_scene);
    CHECKF(rrv(arguments) == 2 && strstr(last_run.err, "/dev/zero: cannot open: not a regular file") != NULL,
           "exit %d, stderr %s", last_run.code, last_run.err);
    CHECKF(rrv("diff test/corpus test/corpus") == 2 &&
               strstr(last_run.err, "test/corpus: cannot open: is a directory") != NULL,
           "exit %d, stderr %s", last_run.code, last_run.err);
}

/* A FIFO without a writer blocks a plain fopen forever: wherever rrv reads a
   file (the scene, every kind of file a scene names, a merge part, the
   --resume probe, diff's images) it is refused at once with the file's name
   ("not a regular file"), and so is /dev/zero, which merge read to 2 GiB
   before. Every run has a timeout, so a reader that blocks fails the test
   (exit 124) instead of hanging it. */
static void fifo_inputs_are_refused(void)
{
    const char *fifo = tmp_path("in_fifo"), *scene = tmp_path("fifo_scene.rrv");
    const char *out = tmp_path("fifo_out.exr"), *fifo_exr = tmp_path("fifo_part.exr");
    static const struct {
        const char *statement, *expect;
    } named[] = {
        {"density m grid in_fifo", "cannot read grid file \"in_fifo\": not a regular file"},
        {"density m nanovdb in_fifo", "cannot read NanoVDB file \"in_fifo\": not a regular file"},
        {"density m nanovdb /dev/zero", "cannot read NanoVDB file \"/dev/zero\": not a regular file"},
        {"ior m grid in_fifo", "cannot read grid file \"in_fifo\": not a regular file"},
        {"mesh file in_fifo", "cannot read OBJ file \"in_fifo\": not a regular file"},
    };
    char arguments[4 * PATH_SIZE], want[4 * PATH_SIZE], text[512];
    struct stat st;
    size_t i;
    remove(fifo);
    remove(out);
    CHECK(mkfifo(fifo, 0600) == 0);

    snprintf(arguments, sizeof arguments, "info '%s'", fifo);
    snprintf(want, sizeof want, "%s: cannot read scene file: not a regular file\n", fifo);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 2 && strcmp(last_run.err, want) == 0,
           "info FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' -q", fifo, out);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 2 && strcmp(last_run.err, want) == 0,
           "render FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 0 5 0 0 -1", fifo);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 2 && strcmp(last_run.err, want) == 0,
           "trace FIFO: exit %d, stderr %s", last_run.code, last_run.err);

    for (i = 0; i < sizeof named / sizeof named[0]; ++i) {
        snprintf(text, sizeof text, "camera eye 0 0 5 look 0 0 0\nmedium m box -1 -1 -1 1 1 1\n%s\n",
                 named[i].statement);
        CHECK(write_text(scene, text));
        snprintf(arguments, sizeof arguments, "info '%s'", scene);
        snprintf(want, sizeof want, "%s:3: %s\n", scene, named[i].expect);
        CHECKF(rrv_prefixed("timeout 20", arguments) == 2 && strcmp(last_run.err, want) == 0,
               "%s: exit %d, stderr %s", named[i].statement, last_run.code, last_run.err);
    }

    snprintf(arguments, sizeof arguments, "merge '%s' '%s'", out, fifo);
    snprintf(want, sizeof want, "rrv: merge: \"%s\": cannot read: not a regular file\n", fifo);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 2 && strcmp(last_run.err, want) == 0,
           "merge FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(!file_exists(out));
    snprintf(arguments, sizeof arguments, "merge --status '%s'", fifo);
    CHECKF(rrv_prefixed("timeout 20", arguments) != 0 && strstr(last_run.err, "not a regular file") != NULL,
           "merge --status FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "merge '%s' /dev/zero", out);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 2 &&
               strcmp(last_run.err, "rrv: merge: \"/dev/zero\": cannot read: not a regular file\n") == 0,
           "merge /dev/zero: exit %d, stderr %s", last_run.code, last_run.err);
    snprintf(arguments, sizeof arguments, "diff '%s' '%s'", fifo, fifo);
    snprintf(want, sizeof want, "%s: cannot open: not a regular file", fifo);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 2 && strstr(last_run.err, want) != NULL,
           "diff FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    /* --resume looks at an existing output before rendering: a FIFO there is
       refused by the output check first */
    remove(fifo_exr);
    CHECK(mkfifo(fifo_exr, 0600) == 0);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --tile 0/1 --resume -q", tiny_scene, fifo_exr);
    CHECKF(rrv_prefixed("timeout 20", arguments) == 3 && strstr(last_run.err, "it is a FIFO, not a regular file"),
           "--resume onto a FIFO: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(stat(fifo_exr, &st) == 0 && S_ISFIFO(st.st_mode));
    remove(fifo);
    remove(fifo_exr);
    remove(scene);
}

/* A part may claim any image size: one of INT_MAX x INT_MAX pixels holding
   a 2 x 2 tile made the hole search allocate a byte per pixel (4.6e18:
   "out of memory", an abort under AddressSanitizer). The hole is found from
   the rectangles alone, and the first one is named. */
static void merge_of_a_huge_claimed_image(void)
{
    const char *part = tmp_path("huge_part.exr"), *out = tmp_path("huge_merged.exr");
    float pixels[2 * 2 * 3] = {0};
    char attribute[512], arguments[4 * PATH_SIZE];
    rrv_exr_options exr;
    rrv_error err;
    memset(&exr, 0, sizeof exr);
    exr.pixel = RRV_EXR_FLOAT;
    exr.display_width = exr.display_height = INT_MAX;
    exr.text_name = "rrvPart";
    snprintf(attribute, sizeof attribute,
             "rrv part 1\nhash 0123456789abcdef\nimage %d %d\ntile 0/1\nrect 0 0 2 2\nsamples 0 1\nspp 1\n",
             INT_MAX, INT_MAX);
    exr.text = attribute;
    remove(out);
    CHECKF(rrv_write_exr(part, pixels, 2, 2, &exr, &err) == RRV_OK, "%s", err.message);
    snprintf(arguments, sizeof arguments, "merge '%s' '%s'", out, part);
    CHECKF(rrv_prefixed("timeout 60", arguments) == 2 &&
               strcmp(last_run.err, "rrv: merge: pixel 2,0 is in no part: a tile is missing (the parts cover 4 of "
                                    "2147483647x2147483647 pixels)\n") == 0,
           "exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(!file_exists(out));
    remove(part);
}

/* An option whose value is missing must not take the next option as a file
   name (`--png -q` wrote a file called "-q"); "./-q" names such a file, and
   negative numbers are still values. */
static void option_values_are_not_options(void)
{
    const char *out = tmp_path("dash_out.pfm"), *png = tmp_path("dash_out.png");
    char arguments[8 * PATH_SIZE], here[PATH_SIZE];
    remove(out);
    remove(png);
    remove("-q");
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png -q", tiny_scene, out);
    CHECKF(rrv(arguments) == 1 &&
               strstr(last_run.err, "rrv: --png needs an output path, got the option \"-q\" (for a file of that "
                                    "name write \"./-q\")") == last_run.err,
           "--png -q: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(!file_exists("-q") && !file_exists(out));
    snprintf(arguments, sizeof arguments, "render '%s' -o -q", tiny_scene);
    CHECKF(rrv(arguments) == 1 && strstr(last_run.err, "got the option \"-q\""),
           "-o -q: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(!file_exists("-q"));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' --exposure -1 --crop 0 0 2 2 -q",
             tiny_scene, out, png);
    CHECKF(rrv(arguments) == 0, "--exposure -1: exit %d, stderr %s", last_run.code, last_run.err);
    CHECK(file_exists(out) && file_exists(png));
    remove(out);
    CHECK(getcwd(here, sizeof here) != NULL);
    snprintf(arguments, sizeof arguments, "cd '%s' && '%s%s%s' render '%s%s%s' -o ./-q.pfm --crop 0 0 2 2 -q",
             tmp_dir, rrv_binary[0] == '/' ? "" : here, rrv_binary[0] == '/' ? "" : "/", rrv_binary,
             tiny_scene[0] == '/' ? "" : here, tiny_scene[0] == '/' ? "" : "/", tiny_scene);
    CHECKF(system(arguments) == 0 && file_exists(tmp_path("-q.pfm")), "./-q.pfm was not written");
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --seed -1", tiny_scene, out);
    CHECKF(rrv(arguments) == 1 && strstr(last_run.err, "--seed needs"),
           "--seed -1: exit %d, stderr %s", last_run.code, last_run.err);
    remove(tmp_path("-q.pfm"));
    remove("-q"); /* what the defect wrote */
    remove(out);
    remove(png);
}

static void diff_reports_known_errors(void)
{
    /* 2x2 images, rows top first. B is the reference. */
    static const float a[12] = {1, 2, 3, 4, 5, 6, 0.5f, 0, 0, 7, 8, 9};
    static const float b[12] = {1, 2, 3, 4, 2, 6, 1.5f, 0, 0, 7, 8, 9};
    static const float small[3] = {1, 2, 3};
    const char *path_a = tmp_path("diff_a.pfm"), *path_b = tmp_path("diff_b.pfm");
    const char *path_small = tmp_path("diff_small.pfm"), *path_junk = tmp_path("diff_junk.pfm");
    char arguments[3 * PATH_SIZE];
    double expected_relmse = (9.0 / (4.0 + 1e-2) + 1.0 / (2.25 + 1e-2)) / 12.0;
    const char *pixel;

    CHECK(write_pfm_by_hand(path_a, a, 2, 2));
    CHECK(write_pfm_by_hand(path_b, b, 2, 2));
    CHECK(write_pfm_by_hand(path_small, small, 1, 1));
    CHECK(write_text(path_junk, "PF\n2 2\n-1.0\nshort"));

    snprintf(arguments, sizeof arguments, "diff '%s' '%s'", path_a, path_a);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(key_number(last_run.out, "rmse") == 0, "%s", last_run.out);
    CHECKF(key_number(last_run.out, "max_abs_error") == 0, "%s", last_run.out);

    snprintf(arguments, sizeof arguments, "diff '%s' '%s'", path_a, path_b);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(near(key_number(last_run.out, "rmse"), sqrt(10.0 / 12.0)), "%s", last_run.out);
    CHECKF(near(key_number(last_run.out, "relmse"), expected_relmse), "%s", last_run.out);
    CHECKF(near(key_number(last_run.out, "mae"), 4.0 / 12.0), "%s", last_run.out);
    CHECKF(near(key_number(last_run.out, "max_abs_error"), 3.0), "%s", last_run.out);
    pixel = find_key(last_run.out, "max_abs_pixel");
    CHECKF(pixel && strncmp(pixel, "1 0\n", 4) == 0, "%s", last_run.out);
    pixel = find_key(last_run.out, "max_abs_channel");
    CHECKF(pixel && strncmp(pixel, "g\n", 2) == 0, "%s", last_run.out);

    snprintf(arguments, sizeof arguments, "diff '%s' '%s'", path_a, path_small);
    CHECKF(rrv(arguments) == 2, "size mismatch: exit %d", last_run.code);
    CHECK(last_run.err[0] != '\0');
    snprintf(arguments, sizeof arguments, "diff '%s' '%s'", path_a, path_junk);
    CHECKF(rrv(arguments) == 2, "truncated PFM: exit %d", last_run.code);
    snprintf(arguments, sizeof arguments, "diff '%s' '%s'", tmp_path("missing.pfm"), path_a);
    CHECKF(rrv(arguments) == 2, "missing PFM: exit %d", last_run.code);
}

static void render_is_deterministic(void)
{
    static const int crops[4][4] = {{0, 0, 10, 7}, {10, 0, 24, 7}, {0, 7, 10, 16}, {10, 7, 24, 16}};
    const char *one = tmp_path("det_1.pfm"), *two = tmp_path("det_2.pfm");
    const char *five = tmp_path("det_5.pfm"), *png = tmp_path("det.png");
    char arguments[3 * PATH_SIZE];
    float *full;
    int width = 0, height = 0, i;

    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --png '%s' --threads 1", tiny_scene,
             one, png);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strstr(last_run.err, "rendered 24x16 at 4 spp in ") != NULL, "summary: %s", last_run.err);
    CHECKF(strchr(last_run.err, '\r') == NULL, "progress bar drawn when stderr is not a terminal");
    {
        size_t size = 0;
        unsigned char *data = (unsigned char *)read_whole_file(png, &size);
        CHECKF(data && size > 8 && memcmp(data, "\x89PNG", 4) == 0, "%s is not a PNG", png);
        free(data);
    }
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --threads 2 -q", tiny_scene, two);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(last_run.err[0] == '\0', "-q still printed: %s", last_run.err);
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --threads 5 -q", tiny_scene, five);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(files_identical(one, two), "1 and 2 threads differ");
    CHECKF(files_identical(one, five), "1 and 5 threads differ");

    full = read_pfm_by_hand(one, &width, &height);
    CHECKF(full && width == 24 && height == 16, "%s is not a 24x16 PFM", one);
    if (!full || width != 24 || height != 16) {
        free(full);
        return;
    }
    for (i = 0; i < 4; ++i) {
        const int *crop = crops[i];
        const char *part = tmp_path("det_crop.pfm");
        float *tile;
        int tile_width = 0, tile_height = 0, x, y;
        snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --threads 3 -q --crop %d %d %d %d",
                 tiny_scene, part, crop[0], crop[1], crop[2], crop[3]);
        CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
        tile = read_pfm_by_hand(part, &tile_width, &tile_height);
        CHECKF(tile && tile_width == crop[2] - crop[0] && tile_height == crop[3] - crop[1],
               "crop %d is %dx%d", i, tile_width, tile_height);
        if (tile && tile_width == crop[2] - crop[0] && tile_height == crop[3] - crop[1]) {
            int same = 1;
            for (y = 0; y < tile_height; ++y)
                for (x = 0; x < tile_width; ++x)
                    same &= memcmp(&tile[3 * (y * tile_width + x)],
                                   &full[3 * ((y + crop[1]) * width + x + crop[0])],
                                   3 * sizeof(float)) == 0;
            CHECKF(same, "crop %d %d %d %d differs from the full render", crop[0], crop[1],
                   crop[2], crop[3]);
        }
        free(tile);
    }
    free(full);

    snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --spp 2 --seed 9", tiny_scene, two);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strstr(last_run.err, "at 2 spp") != NULL, "--spp not applied: %s", last_run.err);
}

/* A flame beside a light shape shares each vertex's light draw with it by
   power, unless the scene asks for a draw of the flame's own. */
static void info_names_the_emitters_share(void)
{
    CHECKF(rrv("info scenes/fire.rrv") == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strstr(last_run.out, "\nlight samples (power): the emissive media 4.62 %, shape 2 (quad) 95.4 %, sky 0 % "
                                "(its light left to the paths' own directions)\n") != NULL,
           "%s", last_run.out);
    CHECKF(strstr(last_run.out, "first bounces:") == NULL, "%s", last_run.out);
    CHECKF(rrv("info scenes/pictures/fire.rrv") == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strstr(last_run.out, "\nlight samples (power): shape 2 (quad) 100 %, sky 0 % (its light left to the "
                                "paths' own directions); the emissive media a draw of their own\n") != NULL,
           "%s", last_run.out);
    /* a draw of the flame's own beside a light guides no bounce; nor
       does a share of 4.6 % (below); the campfire's flame lights all,
       less its albedo's 4.8 % */
    CHECKF(strstr(last_run.out, "first bounces:") == NULL, "%s", last_run.out);
    CHECKF(rrv("info test/bench/campfire.rrv") == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strstr(last_run.out, "\nfirst bounces: 47.6 % toward the 2 lit sides of surfaces the emissive media "
                                "light\n") != NULL,
           "%s", last_run.out);
}

static void info_describes_scene(void)
{
    char arguments[2 * PATH_SIZE];
    snprintf(arguments, sizeof arguments, "info '%s'", tiny_scene);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strstr(last_run.out, "resolution: 24x16\n") != NULL, "%s", last_run.out);
    CHECKF(key_number(last_run.out, "spp") == 4, "%s", last_run.out);
    CHECKF(key_number(last_run.out, "shapes") == 2, "%s", last_run.out);
    CHECKF(key_number(last_run.out, "lights") == 1, "%s", last_run.out);
    /* where the light samples go: the one light shape takes them all */
    CHECKF(strstr(last_run.out, "\nlight samples (power): shape 1 (quad) 100 %") != NULL, "%s", last_run.out);
    CHECKF(key_number(last_run.out, "media") == 1, "%s", last_run.out);
    CHECKF(strstr(last_run.out, "fog: box") != NULL, "%s", last_run.out);
    /* the coefficients, and no channel groups for a grey medium */
    CHECKF(strstr(last_run.out, "sigma_a 0.2 0.2 0.2, sigma_s 0.6 0.6 0.6, scale 1") != NULL, "%s", last_run.out);
    CHECKF(strstr(last_run.out, "channel groups") == NULL, "%s", last_run.out);
    CHECKF(find_key(last_run.out, "framebuffer") != NULL, "%s", last_run.out);
    CHECKF(find_key(last_run.out, "bvh_nodes") != NULL, "%s", last_run.out);
    CHECKF(find_key(last_run.out, "scene_memory") != NULL, "%s", last_run.out);
    /* a scene that does not refract has no nee to name */
    CHECKF(strstr(last_run.out, "\nnee: ") == NULL, "%s", last_run.out);
}

/* No silent glass: a plume of hot air (iorscale 100) whose faces sit at
   300 K has no IOR jump without an `ambient ior` line (the ambient is the
   same gas at 300 K), and `rrv info` and the render summary say nothing;
   `ambient ior 1` makes every face glass, and both say so. A narrower,
   stronger blob whose Gaussian tail leaves 6.5e-7 at the faces: both
   report it, and chains, which take a jump up to 1e-6 as smooth, still
   solve through it. `rrv info` and the render summary name the nee each
   takes. */
static void face_jumps_are_reported(void)
{
    static const char plume[] =
        "camera eye 0 0.8 -3 look 0 0.6 0 resolution 8 6\n"
        "render spp 1 maxdepth 1\n"
        "quad origin -0.1 3.5 -0.1 u 0.2 0 0 v 0 0 0.2 L 50 50 50\n"
        "quad origin -2 0 -2 u 0 0 4 v 4 0 0\n"
        "medium plume box -0.5 0.5 -0.5 0.5 1.5 0.5 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature plume blob center 0 1 0 radius 0.06 weight 600 base 300\n"
        "ior plume gas iorscale 100\n";
    static const char tail[] =
        "camera eye 0 0.8 -3 look 0 0.6 0 resolution 8 6\n"
        "render spp 1 maxdepth 1\n"
        "quad origin -0.1 3.5 -0.1 u 0.2 0 0 v 0 0 0.2 L 50 50 50\n"
        "quad origin -2 0 -2 u 0 0 4 v 4 0 0\n"
        "medium plume box -0.5 0.5 -0.5 0.5 1.5 0.5 sigma_a 0 0 0 sigma_s 0 0 0\n"
        "temperature plume blob center 0 1 0 radius 0.1 weight 600 base 300\n"
        "ior plume gas iorscale 300\n";
    static const char tail_summary[] =
        "sharp IOR faces: eta jumps by 6.53e-07 at the +y face of medium \"plume\" (and at 5 more faces): "
        "refracted and reflected there as glass; curved nee takes a jump this small as smooth\n";
    static const char summary[] =
        "sharp IOR faces: eta jumps by 0.0292 at the -x face of medium \"plume\" (and at 5 more faces): "
        "refracted and reflected there as glass; nee shoot and aim refract there, manifold does not\n";
    char text[1024], arguments[3 * PATH_SIZE];
    const char *scene = tmp_path("plume.rrv"), *out = tmp_path("plume.pfm"), *line;
    int glass;
    for (glass = 0; glass < 3; ++glass) {
        snprintf(text, sizeof text, "%s%s", glass == 2 ? tail : plume, glass == 1 ? "ambient ior 1\n" : "");
        CHECK(write_text(scene, text));
        snprintf(arguments, sizeof arguments, "info '%s'", scene);
        CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
        CHECKF((strstr(last_run.out, glass == 2 ? "ambient ior: 1.0876 (the gas at its ambient state)\n"
                                                : "ambient ior: 1.0292 (the gas at its ambient state)\n") != NULL) ==
                   (glass != 1),
               "%s", last_run.out);
        /* an ambient set off the gas's own: info names the gas's */
        CHECKF((strstr(last_run.out, "ambient ior: 1 (set; the gas of medium \"plume\" at its ambient state is "
                                     "1.0292)\n") != NULL) == (glass == 1),
               "%s", last_run.out);
        CHECKF((strstr(last_run.out, "    sharp IOR faces (eta jumps by): -x 0.0292, +x 0.0292, -y 0.0292, "
                                     "+y 0.0292, -z 0.0292, +z 0.0292\n") != NULL) == (glass == 1),
               "%s", last_run.out);
        CHECKF((strstr(last_run.out, "    sharp IOR faces (eta jumps by): -x 6.53e-07, +x 6.53e-07, -y 6.53e-07, "
                                     "+y 6.53e-07, -z 6.53e-07, +z 6.53e-07\n") != NULL) == (glass == 2),
               "%s", last_run.out);
        /* and the nee it takes: chains through clear weak heat and past a
           tail's jump, shots where a face is glass */
        CHECKF(strstr(last_run.out, glass == 1 ? "\nnee: shoot (the default for this scene)\n"
                                               : "\nnee: manifold, dogleg (the default for this scene)\n") != NULL,
               "%s", last_run.out);
        snprintf(arguments, sizeof arguments, "render '%s' -o '%s' --threads 1", scene, out);
        CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
        line = strstr(last_run.err, "sharp IOR");
        CHECKF(glass ? line && strcmp(line, glass == 2 ? tail_summary : summary) == 0 : !line, "%s", last_run.err);
        CHECKF(strstr(last_run.err, glass == 1 ? "; curved nee (shoot): " : "; curved nee (manifold, dogleg): ") != NULL,
               "%s", last_run.err);
    }
}

/* rrv_trace_ray may still be unimplemented: then the tool must fail cleanly. */
static void trace_prints_csv(void)
{
    char arguments[2 * PATH_SIZE];
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 1 -3 0 0 1 --n 3", tiny_scene);
    rrv(arguments);
    CHECKF(last_run.code == 0 || last_run.code == 2, "exit %d", last_run.code);
    if (last_run.code == 0) {
        const char *row = last_run.out;
        int rows = 0;
        CHECKF(strncmp(row, "x,y,z,dx,dy,dz,events\n", 22) == 0, "%s", last_run.out);
        while ((row = strchr(row, '\n')) != NULL && *++row) {
            int commas = 0;
            const char *p;
            for (p = row; *p && *p != '\n'; ++p) commas += *p == ',';
            CHECKF(commas == 6, "row %d: %.80s", rows, row);
            ++rows;
        }
        CHECKF(rows == 3, "%d rows, not 3", rows);
        snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 1 -3 0 0 1 --path", tiny_scene);
        CHECK(rrv(arguments) == 0);
        CHECKF(strncmp(last_run.out, "walk,x,y,z,dx,dy,dz\n", 20) == 0, "%s", last_run.out);
    } else {
        CHECKF(last_run.err[0] != '\0', "exit 2 without a message");
    }
}

/* A misspelt flag gets the nearest one from the command's help (the
   refraction options' help included), a misspelt command the nearest
   command; a word near nothing gets no hint. */
static void unknown_flags_get_a_hint(void)
{
    static const struct {
        const char *arguments, *line;
    } cases[] = {
        {"render s.rrv -o o.pfm --sp 4", "rrv: render: unknown option \"--sp\" (did you mean \"--spp\"?)\n"},
        {"render s.rrv -o o.pfm -spp 4", "rrv: render: unknown option \"-spp\" (did you mean \"--spp\"?)\n"},
        {"render s.rrv -o o.pfm --refractoin comb",
         "rrv: render: unknown option \"--refractoin\" (did you mean \"--refraction\"?)\n"},
        {"trace s.rrv --rya 0 0 0 0 0 1", "rrv: trace: unknown option \"--rya\" (did you mean \"--ray\"?)\n"},
        {"--versoin", "rrv: unknown option \"--versoin\" (did you mean \"--version\"?)\n"},
        {"render s.rrv -o o.pfm --xyzzy", "rrv: render: unknown option \"--xyzzy\"\n"},
        {"trace s.rrv --x", "rrv: trace: unknown option \"--x\"\n"},
        {"rendr s.rrv -o o.pfm", "rrv: unknown command \"rendr\" (did you mean \"render\"?)\n"},
        {"mrege a.pfm b.pfm", "rrv: unknown command \"mrege\" (did you mean \"merge\"?)\n"},
        {"help trcae", "rrv: help: unknown command \"trcae\" (did you mean \"trace\"?)\n"},
        {"xyzzy", "rrv: unknown command \"xyzzy\"\n"},
    };
    size_t i;
    for (i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        size_t n = strlen(cases[i].line);
        CHECKF(rrv(cases[i].arguments) == 1, "%s: exit %d", cases[i].arguments, last_run.code);
        CHECKF(strncmp(last_run.err, cases[i].line, n) == 0, "%s: %s", cases[i].arguments, last_run.err);
    }
}

/* The research variants (rrv.h, RRV_RESEARCH) are not in the CLI's build:
   its flags refuse them as usage errors, before any output is opened, and
   a scene naming one is refused with its file and line. */
static void research_variants_are_refused(void)
{
    static const struct {
        const char *flags, *line;
    } cases[] = {
        {"--refraction midpoint", "rrv: --refraction midpoint is a research variant, not in this build (define "
                                  "RRV_RESEARCH); use comb or poisson\n"},
        {"--stepper leapfrog",
         "rrv: --stepper leapfrog is a research variant, not in this build (define RRV_RESEARCH); use rk4\n"},
    };
    char arguments[3 * PATH_SIZE], expected[2 * PATH_SIZE];
    const char *scene = tmp_path("midpoint.rrv"), *out = tmp_path("midpoint.pfm");
    size_t i;
    remove(out);
    for (i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        snprintf(arguments, sizeof arguments, "render '%s' -o '%s' %s", tiny_scene, out, cases[i].flags);
        CHECKF(rrv(arguments) == 1, "%s: exit %d", cases[i].flags, last_run.code);
        CHECKF(strncmp(last_run.err, cases[i].line, strlen(cases[i].line)) == 0, "%s", last_run.err);
        CHECKF(!file_exists(out), "%s: the output was written", cases[i].flags);
    }
    CHECK(write_text(scene, "camera eye 0 0 -3 look 0 0 0\nrender refraction midpoint\n"));
    snprintf(arguments, sizeof arguments, "render '%s' -o '%s'", scene, out);
    CHECKF(rrv(arguments) == 2, "exit %d: %s", last_run.code, last_run.err);
    snprintf(expected, sizeof expected,
             "%s:2: render: refraction midpoint is a research variant, not in this build (define RRV_RESEARCH); "
             "use comb or poisson\n", scene);
    CHECKF(strstr(last_run.err, expected) != NULL, "%s", last_run.err);
    CHECKF(!file_exists(out), "a refused scene's output was written");
}

/* A scene that bends nothing: the straight ray, exit 0, and one line saying why. */
static void trace_says_when_nothing_refracts(void)
{
    char arguments[2 * PATH_SIZE], note[2 * PATH_SIZE];
    const char *glass = tmp_path("glass.rrv");
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 1 -3 0 0 1", tiny_scene);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(strcmp(last_run.out, "x,y,z,dx,dy,dz,events\n0,1,-3,0,0,1,0\n") == 0, "%s", last_run.out);
    snprintf(note, sizeof note, "rrv: trace: %s has no refracting medium; the ray goes straight\n", tiny_scene);
    CHECKF(strcmp(last_run.err, note) == 0, "%s", last_run.err);

    CHECK(write_text(glass, "camera eye 0 0 -3 look 0 0 0\n"
                            "medium glass box -1 -1 -1 1 1 1\n"
                            "ior glass constant 1.3\n"));
    snprintf(arguments, sizeof arguments, "trace '%s' --ray 0 0 -3 0 0 1", glass);
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    CHECKF(last_run.err[0] == '\0', "a refracting scene got: %s", last_run.err);

    /* the scene's own integrator choice does not make it refract */
    CHECK(write_text(glass, "camera eye 0 0 -3 look 0 0 0\n"
                            "render integrator refractive\n"
                            "medium fog box -1 -1 -1 1 1 1\n"
                            "density fog constant 1\n"));
    CHECKF(rrv(arguments) == 0, "exit %d: %s", last_run.code, last_run.err);
    snprintf(note, sizeof note, "rrv: trace: %s has no refracting medium; the ray goes straight\n", glass);
    CHECKF(strcmp(last_run.err, note) == 0, "%s", last_run.err);
}

static int write_scenes(void)
{
    /* Quad edges u x v point the light down onto the floor. */
    static const char tiny[] =
        "# 24x16, 4 spp: small enough to render many times in a test\n"
        "camera eye 0 1 -4 look 0 0.8 0 fov 45 resolution 24 16\n"
        "render spp 4 seed 7 maxdepth 8\n"
        "environment constant L 0.05 0.05 0.05\n"
        "material grey diffuse albedo 0.6 0.6 0.6\n"
        "quad origin -2 0 -2 u 0 0 4 v 4 0 0 material grey\n"
        "quad origin -0.5 2.5 -0.5 u 1 0 0 v 0 0 1 L 8 8 8\n"
        "medium fog box -1 0 -1 1 2 1 sigma_a 0.2 0.2 0.2 sigma_s 0.6 0.6 0.6\n"
        "density fog constant 0.8\n";
    static const char bad[] =
        "camera eye 0 0 -3 look 0 0 0\n"
        "sphere center 0 0 0 radius -1\n";
    return write_text(tiny_scene, tiny) && write_text(bad_scene, bad);
}

int main(int argc, char **argv)
{
    char command[2 * PATH_SIZE];
    if (argc < 2 || strlen(argv[1]) > sizeof tmp_dir - 16) {
        printf("usage: %s BUILD_DIR (a path under %d bytes)\n", argv[0], (int)sizeof tmp_dir - 16);
        return 2;
    }
    snprintf(rrv_binary, sizeof rrv_binary, "%s/rrv", argv[1]);
    snprintf(tmp_dir, sizeof tmp_dir, "%s/cli_tmp", argv[1]);
    snprintf(tiny_scene, sizeof tiny_scene, "%s/tiny.rrv", tmp_dir);
    snprintf(bad_scene, sizeof bad_scene, "%s/bad.rrv", tmp_dir);
    snprintf(captured_stdout, sizeof captured_stdout, "%s/run_stdout.txt", tmp_dir);
    snprintf(captured_stderr, sizeof captured_stderr, "%s/run_stderr.txt", tmp_dir);
    if (mkdir(tmp_dir, 0777) != 0 && errno != EEXIST) {
        printf("FAIL cannot create %s: %s\n", tmp_dir, strerror(errno));
        return 1;
    }
    if (!file_exists(rrv_binary) || !write_scenes()) {
        printf("FAIL setup: %s missing or %s not writable\n", rrv_binary, tmp_dir);
        return 1;
    }
    /* A stale directory of this name would hide the exit-3 case. */
    snprintf(command, sizeof command, "rm -rf '%s/no_such_dir'", tmp_dir);
    if (system(command) != 0) printf("  could not clear %s/no_such_dir\n", tmp_dir);

    RUN(help_exits_zero);
    RUN(usage_errors_exit_one);
    RUN(corpus_errors_match_expect);
    RUN(failed_render_keeps_existing_output);
    RUN(unwritable_output_exits_three);
    RUN(output_that_is_an_input_is_refused);
    RUN(non_regular_output_is_refused);
    RUN(temporary_files_are_private);
    RUN(odd_inputs_get_messages);
    RUN(fifo_inputs_are_refused);
    RUN(option_values_are_not_options);
    RUN(merge_of_a_huge_claimed_image);
    RUN(diff_reports_known_errors);
    RUN(render_is_deterministic);
    RUN(info_describes_scene);
    RUN(info_names_the_emitters_share);
    RUN(face_jumps_are_reported);
    RUN(trace_prints_csv);
    RUN(unknown_flags_get_a_hint);
    RUN(research_variants_are_refused);
    RUN(trace_says_when_nothing_refracts);
    return CHECK_EXIT_CODE();
}
