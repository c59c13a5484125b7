/* Tests of split renders: parts from rrv render --tile/--samples merged by
   rrv merge are byte-identical to one render, in several layouts of tiles and
   sample blocks; every merge error case in test/corpus/merge gives exactly
   its message, exit 2 and no output; rrv farm slurm's scripts run as a
   scheduler would run them (without one: each array task in turn) and
   resume. Runs BUILD/rrv as a child process; argv[1] is the build folder. */
#define _POSIX_C_SOURCE 200809L
#include "../rrv.h"
#include "check.h"

#include <dirent.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define PATH_SIZE 1024

static char rrv_binary[2 * PATH_SIZE + 8], tmp_dir[PATH_SIZE / 2], repo_dir[PATH_SIZE];
static char last_err[8192];

static void *read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    char *data = NULL;
    size_t used = 0, cap = 0, n;
    if (!f) return NULL;
    do {
        if (used + 4097 > cap) {
            char *grown = (char *)realloc(data, cap = 2 * cap + 8192);
            if (!grown) { free(data); fclose(f); return NULL; }
            data = grown;
        }
        n = fread(data + used, 1, 4096, f);
        used += n;
    } while (n == 4096);
    fclose(f);
    data[used] = '\0';
    if (size) *size = used;
    return data;
}

/* Runs a shell command in the scratch folder; stderr goes to last_err. */
static int sh(const char *fmt, const char *a, const char *b)
{
    char command[8 * PATH_SIZE], inner[3 * PATH_SIZE], *err;
    int status;
    snprintf(inner, sizeof inner, fmt, a ? a : "", b ? b : "");
    snprintf(command, sizeof command, "cd '%s' && RRV='%s' && { %s; } 2>err.txt </dev/null", tmp_dir, rrv_binary, inner);
    status = system(command);
    snprintf(inner, sizeof inner, "%s/err.txt", tmp_dir);
    err = (char *)read_file(inner, NULL);
    snprintf(last_err, sizeof last_err, "%s", err ? err : "");
    free(err);
    return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

static const char *in_tmp(const char *name)
{
    static char paths[8][PATH_SIZE];
    static int next;
    char *p = paths[next++ % 8];
    snprintf(p, PATH_SIZE, "%s/%s", tmp_dir, name);
    return p;
}

/* Same file bytes and, decoded, the same pixel bits. */
static int same_image(const char *a, const char *b)
{
    size_t na = 0, nb = 0;
    char *da = (char *)read_file(in_tmp(a), &na), *db = (char *)read_file(in_tmp(b), &nb);
    float *pa = NULL, *pb = NULL;
    int wa = 0, ha = 0, wb = 0, hb = 0, same;
    same = da && db && na == nb && memcmp(da, db, na) == 0;
    if (same && rrv_read_exr_memory(da, na, a, &pa, &wa, &ha, NULL, NULL) == RRV_OK &&
        rrv_read_exr_memory(db, nb, b, &pb, &wb, &hb, NULL, NULL) == RRV_OK)
        same = wa == wb && ha == hb && memcmp(pa, pb, (size_t)wa * ha * 3 * sizeof *pa) == 0;
    else if (same && strstr(a, ".exr"))
        same = 0;
    rrv_free(pa);
    rrv_free(pb);
    free(da);
    free(db);
    return same;
}

/* 13 samples: the tree splits 0:13 into 0:8 and 8:13, 8:13 into 8:12 and
   12:13, so the blocks below are uneven on purpose. */
#define SPP "--spp 13"

static void layouts_merge_to_the_single_render(void)
{
    static const struct {
        const char *name;
        const char *parts[8]; /* rrv render arguments of each part */
    } layouts[] = {
        { "three bands", { "--tile 0/3", "--tile 1/3 --threads 1", "--tile 2/3" } },
        { "a 3x2 grid", { "--tile 0/3x2", "--tile 1/3x2", "--tile 2/3x2", "--tile 3/3x2", "--tile 4/3x2",
                          "--tile 5/3x2" } },
        { "sample blocks", { "--samples 0:8", "--samples 8:12 --threads 1", "--samples 12:13" } },
        { "bands and blocks mixed", { "--tile 0/2 --samples 0:8", "--tile 0/2 --samples 8:13",
                                      "--tile 1/2 --samples 0:4", "--tile 1/2 --samples 4:6",
                                      "--tile 1/2 --samples 6:7", "--tile 1/2 --samples 7:8",
                                      "--tile 1/2 --samples 8:13" } },
        { "one part of everything", { "--tile 0/1" } },
    };
    char args[2 * PATH_SIZE], list[4 * PATH_SIZE], name[64];
    size_t l;
    int i, k;
    CHECKF(sh("\"$RRV\" render tiny.rrv " SPP " -o single.exr -q && \"$RRV\" render tiny.rrv " SPP
              " -o single_float.exr --exr-float -q && \"$RRV\" render tiny.rrv " SPP " -o single.pfm -q",
              NULL, NULL) == 0, "%s", last_err);
    for (i = 0; i < (int)(sizeof layouts / sizeof layouts[0]); ++i) {
        list[0] = '\0';
        for (k = 0; k < 8 && layouts[i].parts[k]; ++k) {
            snprintf(name, sizeof name, "layout%d_%d.exr", i, k);
            snprintf(args, sizeof args, "\"$RRV\" render tiny.rrv " SPP " -q -o %s %s", name, layouts[i].parts[k]);
            CHECKF(sh("%s", args, NULL) == 0, "%s: %s", args, last_err);
            l = strlen(list);
            snprintf(list + l, sizeof list - l, " %s", name);
        }
        snprintf(args, sizeof args, "\"$RRV\" merge -q merged.exr%s && \"$RRV\" merge -q --exr-float "
                 "merged_float.exr%s && \"$RRV\" merge -q merged.pfm%s", list, list, list);
        CHECKF(sh("%s", args, NULL) == 0, "%s: %s", layouts[i].name, last_err);
        CHECKF(same_image("merged.exr", "single.exr"), "%s: half EXR differs from the single render",
               layouts[i].name);
        CHECKF(same_image("merged_float.exr", "single_float.exr"), "%s: float EXR differs", layouts[i].name);
        CHECKF(same_image("merged.pfm", "single.pfm"), "%s: PFM differs", layouts[i].name);
    }
}

static void part_options_are_checked(void)
{
    static const struct { const char *args, *message; } cases[] = {
        { "--samples 2:6", "rrv: --samples 2:6 is not a block of the sample tree of 8 samples (0:8 splits into "
                           "0:4 and 4:8, each block of more than one sample at its start plus the largest power "
                           "of two below its length)\n" },
        { "--samples 0:9", "rrv: --samples 0:9: the render has only 8 samples a pixel\n" },
        { "--samples 3:3", "rrv: --samples needs A:B, sample indices 0 <= A < B, got \"3:3\"\n" },
        { "--tile 4/4", "rrv: --tile needs I/N (tile I of N bands of rows) or I/CxR (tile I of a C by R grid), "
                        "0 <= I < N, got \"4/4\"\n" },
        { "--tile 0/20", "rrv: --tile 0/1x20: the 31x19 image has too few rows for that many tiles\n" },
        { "--tile 0/2 --crop 0 0 4 4", "rrv: --crop cannot be combined with --tile or --samples\n" },
        { "--resume", "rrv: --resume needs --tile or --samples\n" },
    };
    char args[PATH_SIZE];
    int i;
    for (i = 0; i < (int)(sizeof cases / sizeof cases[0]); ++i) {
        char *hint;
        snprintf(args, sizeof args, "\"$RRV\" render tiny.rrv --spp 8 -q -o bad_part.exr %s", cases[i].args);
        CHECKF(sh("%s", args, NULL) == 1, "%s: exit code", cases[i].args);
        hint = strstr(last_err, "run \"rrv render --help\"");
        if (hint) *hint = '\0';
        CHECKF(strcmp(last_err, cases[i].message) == 0, "%s:\n    got      %s    expected %s", cases[i].args,
               last_err, cases[i].message);
        CHECK(access(in_tmp("bad_part.exr"), F_OK) != 0);
    }
    CHECKF(sh("\"$RRV\" render tiny.rrv -q -o part.pfm --tile 0/2", NULL, NULL) == 1, "a PFM part");
}

/* Parts of test/corpus/merge/parts.txt, then each NAME.args: the merge's
   stderr is exactly NAME.expect, the exit status 2, and nothing is written. */
static void merge_errors_match_the_corpus(void)
{
    char corpus[PATH_SIZE + 32], path[2 * PATH_SIZE + 64], line[PATH_SIZE], *text, *expected;
    FILE *list;
    DIR *dir;
    struct dirent *entry;
    size_t size = 0;
    int cases = 0;
    snprintf(corpus, sizeof corpus, "%s/test/corpus/merge", repo_dir);
    CHECKF(sh("cp '%s'/*.rrv . && printf 'not an image\\n' > notes.exr", corpus, NULL) == 0, "%s", last_err);
    snprintf(path, sizeof path, "%s/parts.txt", corpus);
    list = fopen(path, "r");
    CHECKF(list != NULL, "cannot open %s", path);
    if (!list) return;
    while (fgets(line, sizeof line, list)) {
        char *name = strtok(line, " \n"), *rest = strtok(NULL, "\n"), args[2 * PATH_SIZE];
        if (!name || name[0] == '#' || !rest) continue;
        snprintf(args, sizeof args, "\"$RRV\" render %s -q -o %s", rest, name);
        CHECKF(sh("%s", args, NULL) == 0, "%s: %s", args, last_err);
    }
    fclose(list);
    /* A part cut in half, as a node that died while copying it would leave. */
    text = (char *)read_file(in_tmp("t1b.exr"), &size);
    CHECK(text != NULL);
    if (text) {
        FILE *f = fopen(in_tmp("truncated.exr"), "wb");
        CHECK(f && fwrite(text, 1, size / 2, f) == size / 2);
        if (f) fclose(f);
        free(text);
    }
    dir = opendir(corpus);
    CHECK(dir != NULL);
    while (dir && (entry = readdir(dir)) != NULL) {
        size_t n = strlen(entry->d_name);
        char *args;
        if (n < 6 || strcmp(entry->d_name + n - 5, ".args") != 0) continue;
        ++cases;
        snprintf(path, sizeof path, "%s/%s", corpus, entry->d_name);
        args = (char *)read_file(path, NULL);
        snprintf(path, sizeof path, "%s/%.*s.expect", corpus, (int)(n - 5), entry->d_name);
        expected = (char *)read_file(path, NULL);
        CHECKF(args && expected, "%s: no .args or .expect", entry->d_name);
        if (args && expected) {
            args[strcspn(args, "\n")] = '\0';
            CHECKF(sh("rm -f merged_bad.exr; \"$RRV\" merge merged_bad.exr %s", args, NULL) == 2, "%s: exit code",
                   entry->d_name);
            CHECKF(strcmp(last_err, expected) == 0, "%s:\n    got      %s    expected %s", entry->d_name,
                   last_err, expected);
            CHECKF(access(in_tmp("merged_bad.exr"), F_OK) != 0, "%s: an output was written", entry->d_name);
        }
        free(args);
        free(expected);
    }
    if (dir) closedir(dir);
    CHECKF(cases >= 11, "only %d merge cases in %s", cases, corpus);
    CHECK(sh("cp t1a.exr keep_t1a.exr && \"$RRV\" merge t1a.exr t0.exr t1a.exr t1b.exr", NULL, NULL) == 2 &&
          strcmp(last_err, "rrv: merge: refusing to write \"t1a.exr\": it is one of the parts\n") == 0 &&
          same_image("t1a.exr", "keep_t1a.exr"));
    /* The good parts of the same set do merge. */
    CHECKF(sh("\"$RRV\" merge -q merged_ok.exr t0.exr t1a.exr t1b.exr", NULL, NULL) == 0, "%s", last_err);
}

static void status_reports_parts(void)
{
    char *out;
    CHECKF(sh("\"$RRV\" render tiny.rrv -q -o s0.exr --tile 0/2 --samples 0:2", NULL, NULL) == 0, "%s", last_err);
    CHECK(sh("\"$RRV\" merge --status s0.exr s1.exr > status.txt", NULL, NULL) == 2);
    out = (char *)read_file(in_tmp("status.txt"), NULL);
    CHECKF(out && strstr(out, "s0.exr: tile 0/2 (pixels 0,0-31,9), samples 0:2, 2 of 4 samples, scene ") &&
               strstr(out, "s1.exr: missing\n") && strstr(out, "1 of 2 parts present\n"),
           "%s", out ? out : "(no output)");
    free(out);
    CHECK(sh("\"$RRV\" merge --status s0.exr > status.txt", NULL, NULL) == 0);
}

/* The Slurm scripts, run as the scheduler would (each array task with its
   SLURM_ARRAY_TASK_ID), give the single render; run again, every task
   keeps its part; a part of another scene is rendered again. */
static void farm_scripts_render_and_resume(void)
{
    char *script;
    CHECKF(sh("\"$RRV\" farm slurm tiny.rrv -o farm.exr --tiles 2x2 --partition short --dir farm -- " SPP
              " > farm.txt", NULL, NULL) == 0, "%s", last_err);
    script = (char *)read_file(in_tmp("farm/render.sbatch"), NULL);
    CHECKF(script && strstr(script, "#SBATCH --array=0-3\n") && strstr(script, "#SBATCH --partition=short\n") &&
               strstr(script, "--tile \"$i\"/2x2 --resume '--spp' '13'"), "%s", script ? script : "(none)");
    free(script);
    script = (char *)read_file(in_tmp("farm/submit.sh"), NULL);
    CHECKF(script && strstr(script, "--dependency=afterok:\"$array\""), "%s", script ? script : "(none)");
    free(script);
    CHECKF(sh("for i in 0 1 2 3; do SLURM_ARRAY_TASK_ID=$i sh farm/render.sbatch || exit 1; done && "
              "sh farm/merge.sbatch", NULL, NULL) == 0, "%s", last_err);
    CHECK(same_image("farm.exr", "single.exr"));
    /* Resume: complete parts are kept (no rename), a foreign one is redone. */
    CHECKF(sh("cp farm/parts/tile_0.exr keep.exr && \"$RRV\" render other.rrv -q " SPP
              " -o farm/parts/tile_3.exr --tile 3/2x2 && rm farm.exr && "
              "for i in 0 1 2 3; do SLURM_ARRAY_TASK_ID=$i sh farm/render.sbatch || exit 1; done && "
              "sh farm/merge.sbatch && cmp keep.exr farm/parts/tile_0.exr", NULL, NULL) == 0, "%s", last_err);
    CHECKF(strstr(last_err, "farm/parts/tile_0.exr\" is complete (tile 0/2x2, samples 0:13): kept") &&
               strstr(last_err, "tile_3.exr\" is not this part: rendering it again"), "%s", last_err);
    CHECK(same_image("farm.exr", "single.exr"));
}

typedef struct byte_sink { unsigned char data[8192]; size_t size; } byte_sink;
static int sink_write(void *user, const void *data, size_t size)
{
    byte_sink *sink = (byte_sink *)user;
    if (size > sizeof sink->data - sink->size) return 1;
    memcpy(sink->data + sink->size, data, size);
    sink->size += size;
    return 0;
}

/* The writer's string attribute reads back by name, and a header cut
   anywhere is refused rather than read past. */
static void exr_text_attribute_round_trips(void)
{
    static byte_sink sink;
    float rgb[6] = { 1, 2, 3, 4, 5, 6 }, *back = NULL;
    rrv_exr_options opt, info;
    const char *type;
    const void *value;
    size_t size, cut;
    int w, h;
    memset(&opt, 0, sizeof opt);
    opt.pixel = RRV_EXR_FLOAT;
    opt.text_name = "rrvPart";
    opt.text = "line one\nline two\n";
    sink.size = 0;
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 1, &opt, NULL) == RRV_OK);
    CHECK(rrv_exr_find_attribute(sink.data, sink.size, "rrvPart", &type, &value, &size) == RRV_OK &&
          strcmp(type, "string") == 0 && size == strlen(opt.text) && memcmp(value, opt.text, size) == 0);
    CHECK(rrv_exr_find_attribute(sink.data, sink.size, "rrvOther", &type, &value, &size) == RRV_ERROR_FORMAT &&
          value == NULL);
    memset(&info, 0xAB, sizeof info);
    CHECK(rrv_read_exr_memory(sink.data, sink.size, "t.exr", &back, &w, &h, &info, NULL) == RRV_OK && w == 2 &&
          memcmp(back, rgb, sizeof rgb) == 0 && info.text_name == NULL && info.text == NULL);
    rrv_free(back);
    for (cut = 0; cut < 330 && cut < sink.size; ++cut) {
        rrv_result r = rrv_exr_find_attribute(sink.data, cut, "rrvPart", &type, &value, &size);
        CHECKF(r == RRV_ERROR_FORMAT || ((const unsigned char *)value + size <= sink.data + cut),
               "cut at %u", (unsigned)cut);
    }
    opt.text_name = "";
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 1, &opt, NULL) == RRV_ERROR_ARGUMENT);
}

int main(int argc, char **argv)
{
    char command[2 * PATH_SIZE];
    if (argc < 2 || strlen(argv[1]) > sizeof tmp_dir - 16 || !getcwd(repo_dir, sizeof repo_dir)) {
        printf("usage: %s BUILD_DIR (run from the repository root)\n", argv[0]);
        return 2;
    }
    snprintf(rrv_binary, sizeof rrv_binary, "%s/%s/rrv", repo_dir, argv[1]);
    snprintf(tmp_dir, sizeof tmp_dir, "%s/farm_tmp", argv[1]);
    snprintf(command, sizeof command, "rm -rf '%s' && mkdir -p '%s' && cp test/corpus/merge/*.rrv '%s'", tmp_dir,
             tmp_dir, tmp_dir);
    if (system(command) != 0) {
        printf("FAIL setup: cannot make %s\n", tmp_dir);
        return 1;
    }
    RUN(exr_text_attribute_round_trips);
    RUN(layouts_merge_to_the_single_render);
    RUN(part_options_are_checked);
    RUN(merge_errors_match_the_corpus);
    RUN(status_reports_parts);
    RUN(farm_scripts_render_and_resume);
    return CHECK_EXIT_CODE();
}
