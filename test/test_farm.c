/* Tests of split renders: parts from rrv render --tile/--samples merged by
   rrv merge are byte-identical to one render, in several layouts of tiles and
   sample blocks; every merge error case in test/corpus/merge gives exactly
   its message, exit 2 and no output; rrv farm slurm's scripts run as a
   scheduler would run them (without one: each array task in turn) and
   resume. Runs BUILD/rrv as a child process; argv[1] is the build folder. */
#define _XOPEN_SOURCE 700 /* POSIX 2008 with realpath */
#include "../rrv.h"
#include "check.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
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
        { "--tile 0/1x0", "rrv: --tile needs I/N (tile I of N bands of rows) or I/CxR (tile I of a C by R grid), "
                          "0 <= I < N, got \"0/1x0\"\n" },
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
    CHECKF(script && strstr(script, "#SBATCH --array=0-3\n") && strstr(script, "#SBATCH --partition=\"short\"\n") &&
               strstr(script, "--tile \"$i\"/2x2 --resume '--spp' '13'\n"), "%s", script ? script : "(none)");
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

/* Runs argv (argv[0] a path, or "sh") in the scratch folder without a shell
   in between, so hostile names reach it byte for byte; stubs, if not NULL,
   is put first on PATH. stdout goes to run_out.txt, stderr to last_err. */
static int run(const char *const *argv, const char *stubs)
{
    char out_path[PATH_SIZE + 32], err_path[PATH_SIZE + 32], *err;
    int status;
    pid_t pid;
    snprintf(out_path, sizeof out_path, "%s/run_out.txt", tmp_dir);
    snprintf(err_path, sizeof err_path, "%s/run_err.txt", tmp_dir);
    fflush(stdout);
    pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        char path[4 * PATH_SIZE];
        int in = open("/dev/null", O_RDONLY), out = open(out_path, O_WRONLY | O_CREAT | O_TRUNC, 0644),
            er = open(err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (in < 0 || out < 0 || er < 0 || dup2(in, 0) < 0 || dup2(out, 1) < 0 || dup2(er, 2) < 0 ||
            chdir(tmp_dir) != 0)
            _exit(127);
        if (stubs) {
            snprintf(path, sizeof path, "%s:%s", stubs, getenv("PATH") ? getenv("PATH") : "/usr/bin:/bin");
            setenv("PATH", path, 1);
        }
        execvp(argv[0], (char *const *)argv);
        _exit(127);
    }
    if (waitpid(pid, &status, 0) != pid) return -1;
    err = (char *)read_file(err_path, NULL);
    snprintf(last_err, sizeof last_err, "%s", err ? err : "");
    free(err);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

static int write_text(const char *path, const char *text, int mode)
{
    FILE *f = fopen(path, "w");
    int ok = f && fputs(text, f) >= 0;
    if (f && fclose(f) != 0) ok = 0;
    return ok && chmod(path, (mode_t)mode) == 0;
}

/* Whether a payload ran: it makes a file called PWNED in the folder it
   runs in, which is the scratch folder or below it. */
static int payload_ran(void)
{
    char command[PATH_SIZE + 64];
    snprintf(command, sizeof command, "find '%s' -name PWNED | grep -q .", tmp_dir);
    return system(command) == 0;
}

/* Where sbatch is installed (CI installs Slurm): the #SBATCH arguments it
   reads from script, as it logs them at -vvv before it would contact a
   controller; --mem with --mem-per-cpu makes it stop right there (a
   made-up slurm.conf, no daemon). Returns 0 when sbatch is not installed. */
static int sbatch_reads(const char *script, const char *const *expected, int count)
{
    const char *which[] = { "sh", "-c", "command -v sbatch", NULL };
    char conf[PATH_SIZE + 32], env[PATH_SIZE + 48], *line, *end;
    const char *argv[] = { "env", env, "sbatch", "-vvv", "--mem=1", "--mem-per-cpu=1", script, NULL };
    int found = 0;
    if (run(which, NULL) != 0) return 0;
    snprintf(conf, sizeof conf, "%s/dummy_slurm.conf", tmp_dir);
    CHECK(write_text(conf, "ClusterName=t\nSlurmctldHost=localhost(127.0.0.1)\nSlurmctldPort=26999\n"
                           "NodeName=localhost CPUs=1 State=UNKNOWN\nPartitionName=p Nodes=localhost Default=YES\n",
                     0644));
    CHECK(realpath(conf, env + 11) != NULL);
    memcpy(env, "SLURM_CONF=", 11);
    run(argv, NULL);
    for (line = last_err; (line = strstr(line, "Found in script, argument \"")) != NULL; line = end) {
        line += strlen("Found in script, argument \"");
        end = strchr(line, '\n');
        if (!end) break;
        CHECKF(found < count && end - line == (long)strlen(expected[found]) + 1 &&
                   memcmp(line, expected[found], strlen(expected[found])) == 0 && end[-1] == '"',
               "sbatch read argument %d of %s as %.*s", found, script, (int)(end - line), line);
        ++found;
    }
    CHECKF(found == count, "sbatch read %d #SBATCH arguments of %s, not %d: %s", found, script, count, last_err);
    return 1;
}

#define PAYLOAD "$(touch PWNED)`touch PWNED`';touch PWNED;'\";touch PWNED;\""

/* rrv farm slurm with names that hold shell syntax, quotes, blanks, a
   leading dash and bytes that are no UTF-8, in the output, the farm folder,
   the scene, the rrv program and the folder above them all; submit.sh runs
   with a stand-in sbatch that runs each script at once (each array task
   with SLURM_ARRAY_TASK_ID). No payload runs and the merge is the single
   render. */
static void farm_scripts_take_hostile_names(void)
{
    static const char sbatch_stub[] =
        "#!/bin/sh\n"
        "# sbatch for tests: runs the script now, an array's tasks in turn, and\n"
        "# prints a job id as --parsable does.\n"
        "script=\n"
        "for a in \"$@\"; do case $a in -*) ;; *) script=$a ;; esac; done\n"
        "[ -f \"$script\" ] || { echo \"sbatch stub: no script in $*\" >&2; exit 1; }\n"
        "last=$(sed -n 's/^#SBATCH --array=0-\\([0-9]*\\)$/\\1/p' \"$script\")\n"
        "if [ -n \"$last\" ]; then\n"
        "    i=0\n"
        "    while [ \"$i\" -le \"$last\" ]; do\n"
        "        SLURM_ARRAY_TASK_ID=$i sh \"$script\" >&2 || exit 1\n"
        "        i=$((i + 1))\n"
        "    done\n"
        "else\n"
        "    sh \"$script\" >&2 || exit 1\n"
        "fi\n"
        "echo \"$$;test\"\n";
    static const char srun_stub[] = "#!/bin/sh\nexec \"$@\"\n";
    static const char *const top = "top " PAYLOAD " \xff\xfe";
    char stubs[PATH_SIZE], path[4 * PATH_SIZE], rrv_copy[4 * PATH_SIZE], scene[4 * PATH_SIZE],
        out[4 * PATH_SIZE], dir[4 * PATH_SIZE + 16], submit[4 * PATH_SIZE + 32];
    int k;
    CHECKF(realpath(tmp_dir, stubs) != NULL, "%s", tmp_dir);
    strcat(stubs, "/stubs");
    CHECK(mkdir(stubs, 0777) == 0 || errno == EEXIST);
    snprintf(path, sizeof path, "%s/sbatch", stubs);
    CHECK(write_text(path, sbatch_stub, 0755));
    snprintf(path, sizeof path, "%s/srun", stubs);
    CHECK(write_text(path, srun_stub, 0755));
    CHECK(mkdir(in_tmp(top), 0777) == 0);
    /* The rrv the nodes run, copied under a hostile name (a link would be
       resolved to the real program). */
    snprintf(rrv_copy, sizeof rrv_copy, "%s/-rrv " PAYLOAD, top);
    {
        const char *cp[] = { "cp", rrv_binary, rrv_copy, NULL };
        CHECKF(run(cp, NULL) == 0, "%s", last_err);
    }
    snprintf(scene, sizeof scene, "%s/-scene " PAYLOAD ".rrv", top);
    {
        const char *cp[] = { "cp", "tiny.rrv", scene, NULL };
        CHECKF(run(cp, NULL) == 0, "%s", last_err);
    }
    for (k = 0; k < 2; ++k) {
        /* 0: the default folder next to the output; 1: --dir, with a
           leading dash, a blank and the payload. */
        const char *farm[24];
        int n = 0;
        snprintf(out, sizeof out, "./%s/-out %d " PAYLOAD " \xc3\x28.exr", top, k);
        if (k == 0) snprintf(dir, sizeof dir, "%s.farm", out);
        else snprintf(dir, sizeof dir, "./%s/-dir " PAYLOAD " \xff", top);
        farm[n++] = rrv_binary;
        farm[n++] = "farm";
        farm[n++] = "slurm";
        farm[n++] = scene;
        farm[n++] = "-o";
        farm[n++] = out;
        farm[n++] = "--tiles";
        farm[n++] = k == 0 ? "3" : "2x2";
        farm[n++] = "--partition";
        farm[n++] = "p \"q\" 'r' #s \\t " PAYLOAD;
        farm[n++] = "--time";
        farm[n++] = "1:00 " PAYLOAD;
        farm[n++] = "--rrv";
        farm[n++] = rrv_copy;
        if (k == 1) {
            farm[n++] = "--dir";
            farm[n++] = dir;
        }
        farm[n++] = "--";
        farm[n++] = "--spp";
        farm[n++] = "13";
        farm[n] = NULL;
        CHECKF(run(farm, NULL) == 0, "farm %d: %s", k, last_err);
        {
            char render[4 * PATH_SIZE + 32], output[4 * PATH_SIZE + 64], real_dir[PATH_SIZE * 4],
                full[6 * PATH_SIZE];
            const char *args[6];
            snprintf(full, sizeof full, "%s/%s", tmp_dir, dir);
            CHECK(realpath(full, real_dir) != NULL);
            snprintf(render, sizeof render, "%s/render.sbatch", real_dir);
            snprintf(output, sizeof output, "--output=%s/logs/tile_%%a.log", real_dir);
            args[0] = "--job-name=rrv-tiles";
            args[1] = k == 0 ? "--array=0-2" : "--array=0-3";
            args[2] = output;
            args[3] = "--partition=p \"q\" 'r' #s \\t " PAYLOAD;
            args[4] = "--time=1:00 " PAYLOAD;
            if (!sbatch_reads(render, args, 5) && k == 0)
                printf("(sbatch is not installed: not asked how it reads the #SBATCH lines)\n");
        }
        snprintf(submit, sizeof submit, "%s/submit.sh", dir);
        {
            const char *sh_submit[] = { "sh", submit, NULL };
            CHECKF(run(sh_submit, stubs) == 0, "submit %d: %s", k, last_err);
        }
        CHECKF(!payload_ran(), "a payload ran in farm %d", k);
        CHECKF(same_image(out, "single.exr"), "farm %d: the merge differs from the single render", k);
    }
}

/* What the farm refuses, each with its exact message and exit status and
   nothing written: values that no #SBATCH line can carry, tile counts the
   image or the farm cannot take, options the farm sets, an output that is
   one of the scene's files, and a script target that is not a regular
   file. TMP in a message stands for the scratch folder's real path. */
#define LONG_NAME "a-folder-name-long-enough-that-ten-thousand-part-paths-in-it-pass-one-mebibyte-of-arguments"
static void farm_refusals_write_nothing(void)
{
    static const struct {
        const char *args[8]; /* after "rrv farm slurm tiny.rrv"; NULL ends */
        int status;
        const char *message;
        const char *absent;  /* must not exist afterwards */
    } cases[] = {
        { { "-o", "r1.exr", "--tiles", "2", "--dir", "d1\nx" }, 1,
          "rrv: farm: --dir \"TMP/d1\\nx\" holds a newline, which has no safe form in a #SBATCH line\n", "d1\nx" },
        { { "-o", "r2\n.exr", "--tiles", "2" }, 1,
          "rrv: farm: the farm folder (-o OUT.farm) \"TMP/r2\\n.exr.farm\" holds a newline, which has no safe "
          "form in a #SBATCH line\n", "r2\n.exr.farm" },
        { { "-o", "r3.exr", "--tiles", "2", "--dir", "d3%a" }, 1,
          "rrv: farm: --dir \"TMP/d3%a\" holds '%', which has no safe form in a #SBATCH line\n", "d3%a" },
        { { "-o", "r4%j.exr", "--tiles", "2" }, 1,
          "rrv: farm: the farm folder (-o OUT.farm) \"TMP/r4%j.exr.farm\" holds '%', which has no safe form in "
          "a #SBATCH line\n", "r4%j.exr.farm" },
        { { "-o", "r5.exr", "--tiles", "2", "--partition", "p\n#SBATCH --wrap=touch PWNED" }, 1,
          "rrv: farm: --partition \"p\\n#SBATCH --wrap=touch PWNED\" holds a newline, which has no safe form in a "
          "#SBATCH line\n", "r5.exr.farm" },
        { { "-o", "r6.exr", "--tiles", "2", "--time", "1:00\ntouch PWNED" }, 1,
          "rrv: farm: --time \"1:00\\ntouch PWNED\" holds a newline, which has no safe form in a #SBATCH line\n",
          "r6.exr.farm" },
        { { "-o", "r7.exr", "--tiles", "2", "--partition", "a%b" }, 1,
          "rrv: farm: --partition \"a%b\" holds '%', which has no safe form in a #SBATCH line\n", "r7.exr.farm" },
        { { "-o", "r8.exr", "--tiles", "2", "--dir", "HetJob" }, 1,
          "rrv: farm: --dir \"TMP/HetJob\" holds \"hetjob\", which has no safe form in a #SBATCH line\n",
          "HetJob" },
        { { "-o", "r9.exr", "--tiles", "2", "--partition", "x\x01packjob" }, 1,
          "rrv: farm: --partition \"x\\x01packjob\" holds \"packjob\", which has no safe form in a #SBATCH "
          "line\n", "r9.exr.farm" },
        { { "-o", "r10.exr", "--tiles", "1x0" }, 1,
          "rrv: --tiles needs N or CxR, positive integers, got \"1x0\"\n", "r10.exr.farm" },
        { { "-o", "r11.exr", "--tiles", "65536x65536" }, 1,
          "rrv: --tiles 65536x65536 makes 4294967296 tiles; a farm has at most 10000\n", "r11.exr.farm" },
        { { "-o", "r12.exr", "--tiles", "65536x32767" }, 1,
          "rrv: --tiles 65536x32767 makes 2147418112 tiles; a farm has at most 10000\n", "r12.exr.farm" },
        { { "-o", "r13.exr", "--tiles", "20" }, 1,
          "rrv: --tiles 20: the 31x19 image has too few rows for that many tiles\n", "r13.exr.farm" },
        { { "-o", "r14.exr", "--tiles", "32x1" }, 1,
          "rrv: --tiles 32x1: the 31x19 image has too few columns for that many tiles\n", "r14.exr.farm" },
        { { "-o", "r15.exr", "--tiles", "2", "--", "--samples", "0:1" }, 1,
          "rrv: farm: --samples is set by the farm, not a render option to pass\n", "r15.exr.farm" },
        { { "-o", "r16.exr", "--tiles", "2", "--", "--spp", "0" }, 1,
          "rrv: --spp needs a positive integer, got \"0\"\n", "r16.exr.farm" },
        { { "-o", "tiny.pfm", "--tiles", "2" }, 1, "rrv: refusing to write \"tiny.pfm\": it is the scene file\n",
          "tiny.pfm.farm" },
        { { "-o", "grid.exr", "--tiles", "2" }, 1,
          "rrv: refusing to write \"grid.exr\": the scene reads it (as \"grid.vol\")\n", "grid.exr.farm" },
        { { "-o", "r19.exr", "--tiles", "100x100", "--dir", LONG_NAME }, 1,
          "rrv: --tiles 100x100: the merge of 10000 parts in \"TMP/" LONG_NAME "\" would take more than 1048576 "
          "bytes of arguments: fewer tiles or a shorter --dir\n", LONG_NAME },
    };
    char real[PATH_SIZE], expected[2 * PATH_SIZE], *at;
    int i, k;
    CHECK(realpath(tmp_dir, real) != NULL);
    /* tiny.pfm is a scene (the extension is only a name); grid.exr is a link
       to the grid that grid.rrv reads; big.rrv is 10000 pixels wide. */
    CHECK(sh("cp tiny.rrv tiny.pfm && cp '%s/scenes/assets/tiny.vol' grid.vol && ln -sf grid.vol grid.exr && "
             "sed 's/^density fog constant .*/density fog grid grid.vol/' tiny.rrv > grid.rrv && "
             "sed 's/resolution 31 19/resolution 10000 100/' tiny.rrv > big.rrv", repo_dir, NULL) == 0);
    for (i = 0; i < (int)(sizeof cases / sizeof cases[0]); ++i) {
        const char *argv[16];
        int n = 0;
        argv[n++] = rrv_binary;
        argv[n++] = "farm";
        argv[n++] = "slurm";
        argv[n++] = strcmp(cases[i].args[1], "tiny.pfm") == 0   ? "tiny.pfm"
                    : strcmp(cases[i].args[1], "grid.exr") == 0 ? "grid.rrv"
                    : strcmp(cases[i].args[1], "r19.exr") == 0  ? "big.rrv"
                                                                : "tiny.rrv";
        for (k = 0; k < 8 && cases[i].args[k]; ++k) argv[n++] = cases[i].args[k];
        argv[n] = NULL;
        expected[0] = '\0';
        for (at = (char *)cases[i].message; *at;) {
            char *tmp = strstr(at, "TMP");
            size_t l = strlen(expected);
            if (!tmp) {
                snprintf(expected + l, sizeof expected - l, "%s", at);
                break;
            }
            snprintf(expected + l, sizeof expected - l, "%.*s%s", (int)(tmp - at), at, real);
            at = tmp + 3;
        }
        CHECKF(run(argv, NULL) == cases[i].status, "case %d: exit status (%s)", i, last_err);
        at = strstr(last_err, "run \"rrv ");
        if (at) *at = '\0';
        CHECKF(strcmp(last_err, expected) == 0, "case %d:\n    got      %s    expected %s", i, last_err,
               expected);
        CHECKF(access(in_tmp(cases[i].absent), F_OK) != 0, "case %d: \"%s\" was written", i, cases[i].absent);
    }
    /* A link, a FIFO or a folder standing at a script's path: refused,
       nothing written, the link's target untouched. */
    {
        static const char *const setups[] = {
            "mkdir -p lnk.exr.farm && echo keep > kept.txt && ln -sf ../kept.txt lnk.exr.farm/submit.sh",
            "mkdir -p fifo.exr.farm && rm -f fifo.exr.farm/render.sbatch && mkfifo fifo.exr.farm/render.sbatch",
            "mkdir -p dir.exr.farm/merge.sbatch",
        };
        static const char *const messages[] = {
            "rrv: refusing to write \"TMP/lnk.exr.farm/submit.sh\": it is a symbolic link, not a regular file\n",
            "rrv: refusing to write \"TMP/fifo.exr.farm/render.sbatch\": it is a FIFO, not a regular file\n",
            "rrv: refusing to write \"TMP/dir.exr.farm/merge.sbatch\": it is a directory, not a regular file\n",
        };
        for (i = 0; i < 3; ++i) {
            const char *argv[] = { rrv_binary, "farm", "slurm", "tiny.rrv", "-o", NULL, "--tiles", "2", NULL };
            char out[32], name[64];
            snprintf(out, sizeof out, "%s", i == 0 ? "lnk.exr" : i == 1 ? "fifo.exr" : "dir.exr");
            argv[5] = out;
            CHECKF(sh("%s", setups[i], NULL) == 0, "%s", last_err);
            snprintf(expected, sizeof expected, "%s", messages[i]);
            at = strstr(expected, "TMP");
            if (at) {
                char tail[PATH_SIZE];
                snprintf(tail, sizeof tail, "%s", at + 3);
                snprintf(at, sizeof expected - (size_t)(at - expected), "%s%s", real, tail);
            }
            CHECKF(run(argv, NULL) == 3, "script target %d: exit status (%s)", i, last_err);
            CHECKF(strcmp(last_err, expected) == 0, "script target %d:\n    got      %s    expected %s", i,
                   last_err, expected);
            for (k = 0; k < 3; ++k) {
                static const char *const scripts[] = { "render.sbatch", "merge.sbatch", "submit.sh" };
                struct stat st;
                snprintf(name, sizeof name, "%s.farm/%s", out, scripts[k]);
                CHECKF(lstat(in_tmp(name), &st) != 0 || !S_ISREG(st.st_mode), "%s was written", name);
            }
        }
        CHECK(sh("test \"$(cat kept.txt)\" = keep && test -L lnk.exr.farm/submit.sh", NULL, NULL) == 0);
    }
}

/* Every command-line option that changes pixels enters a part's hash: a
   part rendered with one of them does not merge with parts rendered
   without it (--sampler once did). --threads, which changes nothing, still
   merges, so the refusals are the options' doing. */
static void render_options_enter_the_hash(void)
{
    static const char *const options[] = {
        "--sampler pcg", "--seed 9", "--integrator refractive", "--integrator eikonal", "--nee aim",
        "--bend-tolerance 0.02", "--mu-eta 3", "--step 0.02", "--refraction poisson",
        "--majorant-cells 2", "--ior-interp cubic",
    };
    char args[2 * PATH_SIZE];
    int i;
    CHECKF(sh("\"$RRV\" render tiny.rrv -q -o h0.exr --tile 0/2 && \"$RRV\" render tiny.rrv -q -o h1a.exr "
              "--tile 1/2 --samples 0:2 && \"$RRV\" render tiny.rrv -q -o h1b.exr --tile 1/2 --samples 2:4 "
              "--threads 1 && \"$RRV\" merge -q h.exr h0.exr h1a.exr h1b.exr", NULL, NULL) == 0,
           "%s", last_err);
    for (i = 0; i < (int)(sizeof options / sizeof options[0]); ++i) {
        snprintf(args, sizeof args, "\"$RRV\" render tiny.rrv -q -o h1b_opt.exr --tile 1/2 --samples 2:4 %s",
                 options[i]);
        CHECKF(sh("%s", args, NULL) == 0, "%s: %s", options[i], last_err);
        CHECKF(sh("\"$RRV\" merge -q h_opt.exr h0.exr h1a.exr h1b_opt.exr", NULL, NULL) == 2 &&
               strstr(last_err, "their hashes differ"), "%s: the merge did not refuse the part: %s", options[i],
               last_err);
    }
    /* naming the default sampler changes nothing */
    CHECKF(sh("\"$RRV\" render tiny.rrv -q -o h1b_opt.exr --tile 1/2 --samples 2:4 --sampler sobol && "
              "\"$RRV\" merge -q h_opt.exr h0.exr h1a.exr h1b_opt.exr", NULL, NULL) == 0,
           "--sampler sobol: %s", last_err);
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
    RUN(render_options_enter_the_hash);
    RUN(status_reports_parts);
    RUN(farm_scripts_render_and_resume);
    RUN(farm_scripts_take_hostile_names);
    RUN(farm_refusals_write_nothing);
    return CHECK_EXIT_CODE();
}
