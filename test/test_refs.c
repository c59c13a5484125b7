/* Every scene against its reference (test/ref/, made by `make refs`): the
   small copy of the scene in test/ref/NAME.rrv is rendered with the
   reference's settings at low spp with TEST_SEEDS fixed seeds, and
   test/ref_compare.cpp --check decides whether the renders agree with the
   reference within their own noise (4-sigma bound on 8x8-pixel block means,
   and on chi^2 over the blocks; see there). A change that biases a
   renderer shows up here; so does a reference gone stale: every reference
   records a hash of its scene and its line in test/ref/refs.txt.
   Needs build/ref_compare, built when OpenEXR is installed; fails without. */
#define _POSIX_C_SOURCE 200809L
#include "check.h"

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_FIELDS 40
#define MAX_ENTRIES 64

static const char *build_dir = "build";

struct entry {
    char line[1024];
    char *field[MAX_FIELDS];
    int fields;
};
static struct entry entries[MAX_ENTRIES];
static int entry_count;

static unsigned long long fnv1a64(const unsigned char *data, size_t n, unsigned long long h)
{
    size_t i;
    for (i = 0; i < n; ++i) h = (h ^ data[i]) * 0x100000001B3ull;
    return h;
}

static int read_manifest(void)
{
    FILE *f = fopen("test/ref/refs.txt", "r");
    char line[1024];
    if (!f) return 0;
    while (fgets(line, sizeof line, f) && entry_count < MAX_ENTRIES) {
        struct entry *e = &entries[entry_count];
        char *hash = strchr(line, '#'), *tok;
        if (hash) *hash = 0;
        strcpy(e->line, line);
        e->fields = 0;
        for (tok = strtok(e->line, " \t\r\n"); tok && e->fields < MAX_FIELDS; tok = strtok(NULL, " \t\r\n"))
            e->field[e->fields++] = tok;
        if (e->fields) ++entry_count;
    }
    fclose(f);
    return 1;
}

static struct entry *find_entry(const char *name)
{
    int i;
    for (i = 0; i < entry_count; ++i)
        if (strcmp(entries[i].field[0], name) == 0) return &entries[i];
    return NULL;
}

static void manifest_lists_every_scene(void)
{
    DIR *dir = opendir("scenes");
    struct dirent *d;
    CHECKF(dir != NULL, "cannot list scenes/");
    if (!dir) return;
    while ((d = readdir(dir)) != NULL) {
        size_t n = strlen(d->d_name);
        char name[256];
        if (n < 5 || n >= sizeof name || strcmp(d->d_name + n - 4, ".rrv") != 0 || d->d_name[0] == '.') continue;
        memcpy(name, d->d_name, n - 4);
        name[n - 4] = 0;
        CHECKF(find_entry(name) != NULL, "scenes/%s has no line in test/ref/refs.txt: add one and run make refs",
               d->d_name);
    }
    closedir(dir);
}

/* The hash test/bench/refs.py writes into the first line of the small scene. */
static int current_hash(const struct entry *e, unsigned long long *out)
{
    char path[512];
    FILE *f;
    unsigned char buf[4096];
    size_t n;
    unsigned long long h = 0xCBF29CE484222325ull;
    int i;
    snprintf(path, sizeof path, "scenes/%s.rrv", e->field[0]);
    f = fopen(path, "rb");
    if (!f) return 0;
    while ((n = fread(buf, 1, sizeof buf, f)) > 0) h = fnv1a64(buf, n, h);
    fclose(f);
    for (i = 0; i < e->fields; ++i) {
        if (i == 4 || i == 5) continue; /* TEST_SPP, TEST_SEEDS: not part of the reference */
        if (i) h = fnv1a64((const unsigned char *)" ", 1, h);
        h = fnv1a64((const unsigned char *)e->field[i], strlen(e->field[i]), h);
    }
    *out = h;
    return 1;
}

static void consistent_with_reference(const struct entry *e)
{
    const char *name = e->field[0];
    char path[512], first[256], command[8192], images[4096] = "", options[2048] = "";
    unsigned long long want = 0, have = 0;
    FILE *f;
    int seeds, i, status;
    if (e->fields < 6) {
        CHECKF(0, "test/ref/refs.txt: line of %s has %d fields, expected at least 6", name, e->fields);
        return;
    }
    CHECKF(current_hash(e, &want), "cannot read scenes/%s.rrv", name);
    snprintf(path, sizeof path, "test/ref/%s.rrv", name);
    f = fopen(path, "r");
    if (!f || !fgets(first, sizeof first, f) || sscanf(first, "# fnv1a64 %llx", &have) != 1) {
        CHECKF(0, "%s is missing or has no hash line: run make refs", path);
        if (f) fclose(f);
        return;
    }
    fclose(f);
    CHECKF(have == want, "the reference of scenes/%s.rrv is stale (the scene or its line in refs.txt changed): "
                         "run make refs", name);
    if (have != want) return;
    seeds = atoi(e->field[5]);
    for (i = 6; i < e->fields; ++i) {
        strcat(options, " ");
        strcat(options, e->field[i]);
    }
    for (i = 0; i < seeds; ++i) {
        char img[512];
        snprintf(img, sizeof img, "%s/refcheck_%s_%d.exr", build_dir, name, i);
        /* Seeds far from the reference's (1), so no render repeats it. */
        snprintf(command, sizeof command,
                 "'%s/rrv' render test/ref/%s.rrv -o '%s' --exr-float --spp %s --seed %d --threads 1 -q%s",
                 build_dir, name, img, e->field[4], 1000 + i, options);
        status = system(command);
        CHECKF(status == 0, "%s exited with status %d", command, status);
        if (status != 0) return;
        strcat(images, " '");
        strcat(images, img);
        strcat(images, "'");
    }
    snprintf(command, sizeof command, "'%s/ref_compare' --check test/ref/%s.exr test/ref/%s_var.exr %s %s%s",
             build_dir, name, name, e->field[3], e->field[4], images);
    fflush(stdout);
    printf("  %s: ", name);
    fflush(stdout);
    status = system(command);
    CHECKF(status == 0, "%s: the renders disagree with the reference (status %d)", name, status);
}

int main(int argc, char **argv)
{
    char program[512];
    FILE *f;
    int i;
    if (argc > 1) build_dir = argv[1];
    if (!read_manifest()) {
        printf("  cannot read test/ref/refs.txt\nFAIL references\n");
        return 1;
    }
    RUN(manifest_lists_every_scene);
    snprintf(program, sizeof program, "%s/ref_compare", build_dir);
    f = fopen(program, "rb");
    if (!f) {
        printf("  %s is missing: OpenEXR was not found when building. Install it "
               "(Debian: apt-get install -y libopenexr-dev openexr) and run make test again\n", program);
        printf("FAIL references\n");
        return 1;
    }
    fclose(f);
    for (i = 0; i < entry_count; ++i) {
        check__failed_in_test = 0;
        consistent_with_reference(&entries[i]);
        printf("%s reference_%s\n", check__failed_in_test ? "FAIL" : "PASS", entries[i].field[0]);
        fflush(stdout);
        check__tests_failed += check__failed_in_test;
    }
    return CHECK_EXIT_CODE();
}
