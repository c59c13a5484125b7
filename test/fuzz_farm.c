/* libFuzzer harness for rrv farm's script generator: arguments in, scripts
   out. `make fuzz`, then
       mkdir -p /tmp/farm-seeds && ./build-fuzz/fuzz_farm -max_total_time=60 /tmp/farm-seeds
   or `make fuzz-run` for every harness.

   The input is a farm plan: 4 bytes (cpus, columns, rows, which of
   --partition and --time are given), then NUL-separated values: the farm
   folder, rrv, the scene, the output, the partition, the time limit and up
   to 8 render options. NUL is the separator because no argument holds one.

   The plan must be refused exactly when a value that goes into an #SBATCH
   line holds what no such line can carry (said here independently of
   main.c). An accepted plan's three scripts are read back as sbatch and
   sh would read them, with a small reader of the only forms the generator
   may use: comments, #SBATCH lines read by sbatch's rules (blanks split,
   '...' and "..." group, a backslash takes the next byte, an unquoted #
   ends the line), and commands whose words are plain safe bytes, '...'
   (nothing expanded), "..." holding only $name or ${...} expansions, $name,
   ${...} and $(...) of a command of the same forms; a backslash only before
   a newline or a single quote. Any other byte outside quotes, an expansion anywhere else, or
   a word that is not exactly the value meant, aborts. */
#define RRV_IMPLEMENTATION
#define main rrv_cli_main
#include "../main.c"
#undef main

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);

/* A word or a directive argument: bytes with lengths, since an expansion is
   kept as a NUL followed by its text (no value can hold a NUL, so a value
   can never be mistaken for an expansion). */
typedef struct fz_word { char *b; size_t n, cap; } fz_word;

#define FZ_MAX_WORDS 96
#define FZ_MAX_COMMANDS 16
typedef struct fz_cmdline { fz_word *w[FZ_MAX_WORDS]; int n; } fz_cmdline;
typedef struct fz_script {
    fz_cmdline cmd[FZ_MAX_COMMANDS];
    int ncmd;
    fz_word *dir[16]; /* #SBATCH arguments, before the first command */
    int ndir;
} fz_script;

static void fz_fail(const char *why, const char *text)
{
    fprintf(stderr, "fuzz_farm: %s in:\n%s\n", why, text ? text : "");
    abort();
}

static fz_word *fz_new(void)
{
    fz_word *w = (fz_word *)calloc(1, sizeof *w);
    if (!w) abort();
    return w;
}

static void fz_put(fz_word *w, const char *b, size_t n)
{
    if (n == 0) return;
    if (w->n + n > w->cap) {
        w->cap = 2 * (w->n + n) + 16;
        if (!(w->b = (char *)realloc(w->b, w->cap))) abort();
    }
    memcpy(w->b + w->n, b, n);
    w->n += n;
}

static void fz_free(fz_word *w)
{
    if (w) free(w->b);
    free(w);
}

static void fz_puts(fz_word *w, const char *s) { fz_put(w, s, strlen(s)); }
static void fz_expansion(fz_word *w, const char *s, size_t n) { fz_put(w, "", 1); fz_put(w, s, n); }

static void fz_free_script(fz_script *s)
{
    int i, k;
    for (i = 0; i < s->ncmd; ++i)
        for (k = 0; k < s->cmd[i].n; ++k) fz_free(s->cmd[i].w[k]);
    for (i = 0; i < s->ndir; ++i) fz_free(s->dir[i]);
    memset(s, 0, sizeof *s);
}

static int fz_plain(unsigned char c) { return isalnum(c) || strchr("_./=:,+@-", c) != NULL; }
static int fz_name(unsigned char c) { return isalnum(c) || c == '_'; }

/* One #SBATCH line (after the magic word) read as sbatch reads it. */
static void fz_directive(fz_script *s, const char *p, const char *end, const char *text)
{
    const char *q;
    for (q = p; q < end; ++q)
        if (strncasecmp(q, "hetjob", 6) == 0 || strncasecmp(q, "packjob", 7) == 0)
            fz_fail("a #SBATCH line holds hetjob or packjob", text);
    for (;;) {
        fz_word *w;
        char quote = 0;
        while (p < end && isspace((unsigned char)*p)) ++p;
        if (p == end || *p == '#') return;
        if (s->ndir == 16) fz_fail("too many #SBATCH arguments", text);
        w = s->dir[s->ndir++] = fz_new();
        while (p < end && (quote || !isspace((unsigned char)*p))) {
            if (*p == '\\') {
                if (++p == end) fz_fail("a #SBATCH line ends in a backslash", text);
            } else if (quote && *p == quote) {
                quote = 0, ++p;
                continue;
            } else if (!quote && (*p == '"' || *p == '\'')) {
                quote = *p++;
                continue;
            } else if (!quote && *p == '#') {
                return;
            }
            fz_put(w, p++, 1);
        }
        if (quote) fz_fail("an unmatched quote in a #SBATCH line", text);
    }
}

/* ${...}: the braces hold a name and an operator on plain text, no quote,
   expansion or command. */
static const char *fz_braced(const char *p, fz_word *w, const char *text)
{
    const char *start = p;
    p += 2;
    if (!fz_name((unsigned char)*p)) fz_fail("${ without a name", text);
    while (*p && *p != '}') {
        if (strchr("'\"`$\\(){\n", *p)) fz_fail("a quote or expansion inside ${...}", text);
        ++p;
    }
    if (*p != '}') fz_fail("an unclosed ${", text);
    ++p;
    fz_expansion(w, start, (size_t)(p - start));
    return p;
}

/* The words of one command, up to a newline (or, inner, the closing ")"). */
static const char *fz_command(fz_script *s, const char *p, int inner, const char *text)
{
    fz_cmdline c;
    fz_word *w = NULL;
    memset(&c, 0, sizeof c);
    for (;;) {
        unsigned char ch = (unsigned char)*p;
        if (ch == ' ' || ch == '\t' || ch == '\n' || ch == '\0' || (inner && ch == ')')) {
            if (w) {
                if (c.n == FZ_MAX_WORDS) fz_fail("too many words", text);
                c.w[c.n++] = w;
                w = NULL;
            }
            if (ch == ' ' || ch == '\t') {
                ++p;
                continue;
            }
            if (inner && ch != ')') fz_fail("an unclosed $(", text);
            if (ch) ++p;
            break;
        }
        if (!w) w = fz_new();
        if (ch == '\\' && p[1] == '\'') { /* the quote inside '...\''...' */
            fz_put(w, "'", 1);
            p += 2;
        } else if (ch == '\\') {
            if (p[1] != '\n') fz_fail("a backslash not before a newline or a quote", text);
            if (w->n == 0) {
                fz_free(w);
                w = NULL;
            }
            p += 2;
        } else if (ch == '\'') {
            const char *close = strchr(p + 1, '\'');
            if (!close) fz_fail("an unclosed '", text);
            fz_put(w, p + 1, (size_t)(close - p - 1));
            p = close + 1;
        } else if (ch == '"') {
            for (++p; *p != '"'; ) {
                if (!*p) fz_fail("an unclosed \"", text);
                if (*p == '`' || *p == '\\') fz_fail("a backquote or backslash inside \"...\"", text);
                if (*p == '$') {
                    if (p[1] == '{') {
                        p = fz_braced(p, w, text);
                    } else {
                        const char *start = p++;
                        if (!fz_name((unsigned char)*p)) fz_fail("a $ without a name inside \"...\"", text);
                        while (fz_name((unsigned char)*p)) ++p;
                        fz_expansion(w, start, (size_t)(p - start));
                    }
                } else {
                    fz_put(w, p++, 1);
                }
            }
            ++p;
        } else if (ch == '$') {
            if (p[1] == '{') {
                p = fz_braced(p, w, text);
            } else if (p[1] == '(') {
                p = fz_command(s, p + 2, 1, text);
                fz_expansion(w, "$()", 3);
            } else {
                const char *start = p++;
                if (!fz_name((unsigned char)*p)) fz_fail("a bare $", text);
                while (fz_name((unsigned char)*p)) ++p;
                fz_expansion(w, start, (size_t)(p - start));
            }
        } else if (ch == '#' && w->n == 0) {
            fz_fail("a comment after a command", text);
        } else if (fz_plain(ch)) {
            fz_put(w, p++, 1);
        } else {
            char why[64];
            snprintf(why, sizeof why, "byte 0x%02x outside quotes", ch);
            fz_fail(why, text);
        }
    }
    if (c.n) {
        if (s->ncmd == FZ_MAX_COMMANDS) fz_fail("too many commands", text);
        s->cmd[s->ncmd++] = c;
    }
    return p;
}

static void fz_read_script(fz_script *s, const char *text)
{
    const char *p = text;
    memset(s, 0, sizeof *s);
    if (strncmp(text, "#!/bin/sh\n", 10) != 0) fz_fail("no #!/bin/sh", text);
    while (*p) {
        while (*p == ' ' || *p == '\t') ++p;
        if (*p == '#') {
            const char *end = strchr(p, '\n');
            if (!end) fz_fail("a comment without a newline", text);
            if (strncmp(p, "#SBATCH", 7) == 0) {
                if (s->ncmd) fz_fail("an #SBATCH line after a command (sbatch ignores it)", text);
                fz_directive(s, p + 7, end, text);
            } else if (strncmp(p, "#SLURM", 6) == 0) {
                fz_fail("a #SLURM line", text);
            }
            p = end + 1;
        } else if (*p == '\n') {
            ++p;
        } else {
            p = fz_command(s, p, 0, text);
        }
    }
}

/* The words meant, built here from the plan without main.c's helpers. */
typedef struct fz_expect { fz_word *w[FZ_MAX_WORDS]; int n; } fz_expect;

static fz_word *fz_add(fz_expect *e)
{
    if (e->n == FZ_MAX_WORDS) abort();
    return e->w[e->n++] = fz_new();
}

static void fz_add_text(fz_expect *e, const char *a, const char *b)
{
    fz_word *w = fz_add(e);
    fz_puts(w, a);
    if (b) fz_puts(w, b);
}

static void fz_clear(fz_expect *e)
{
    int i;
    for (i = 0; i < e->n; ++i) fz_free(e->w[i]);
    e->n = 0;
}

static int fz_same(const fz_word *a, const fz_word *b)
{
    return a->n == b->n && (a->n == 0 || memcmp(a->b, b->b, a->n) == 0);
}

static void fz_match(fz_word *const *got, int ngot, fz_expect *e, const char *what, const char *text)
{
    int i;
    if (ngot != e->n) {
        fprintf(stderr, "fuzz_farm: %s: %d words, not %d\n", what, ngot, e->n);
        fz_fail("wrong word count", text);
    }
    for (i = 0; i < ngot; ++i)
        if (!fz_same(got[i], e->w[i])) {
            fprintf(stderr, "fuzz_farm: %s: word %d differs\n", what, i);
            fz_fail("a word is not the value meant", text);
        }
    fz_clear(e);
}

static void fz_cmd(const fz_script *s, int i, fz_expect *e, const char *what, const char *text)
{
    if (i >= s->ncmd) fz_fail("a command is missing", text);
    fz_match(s->cmd[i].w, s->cmd[i].n, e, what, text);
}

static void fz_check(const farm_plan *plan, int which, const char *text)
{
    fz_script s;
    fz_expect e;
    fz_word *w;
    char num[64], tiles[32];
    int i, count = plan->columns * plan->rows, c = 0;
    memset(&e, 0, sizeof e);
    fz_read_script(&s, text);
    if (plan->columns == 1) snprintf(tiles, sizeof tiles, "/%d", plan->rows);
    else snprintf(tiles, sizeof tiles, "/%dx%d", plan->columns, plan->rows);
    if (which != FARM_SUBMIT) {
        fz_add_text(&e, which == FARM_RENDER ? "--job-name=rrv-tiles" : "--job-name=rrv-merge", NULL);
        if (which == FARM_RENDER) {
            snprintf(num, sizeof num, "--array=0-%d", count - 1);
            fz_add_text(&e, num, NULL);
        }
        w = fz_add(&e);
        fz_puts(w, "--output=");
        fz_puts(w, plan->dir);
        fz_puts(w, which == FARM_RENDER ? "/logs/tile_%a.log" : "/logs/merge.log");
        if (plan->partition) fz_add_text(&e, "--partition=", plan->partition);
        if (which == FARM_RENDER && plan->cpus) {
            snprintf(num, sizeof num, "--cpus-per-task=%d", plan->cpus);
            fz_add_text(&e, num, NULL);
        }
        if (which == FARM_RENDER && plan->time_limit) fz_add_text(&e, "--time=", plan->time_limit);
    }
    fz_match(s.dir, s.ndir, &e, "#SBATCH", text);
    fz_add_text(&e, "set", NULL);
    fz_add_text(&e, "-eu", NULL);
    fz_cmd(&s, c++, &e, "set", text);
    if (which == FARM_RENDER) {
        const char *task = "${SLURM_ARRAY_TASK_ID:?run through sbatch or set SLURM_ARRAY_TASK_ID}";
        w = fz_add(&e);
        fz_puts(w, "i=");
        fz_expansion(w, task, strlen(task));
        fz_cmd(&s, c++, &e, "i=", text);
        fz_add_text(&e, "exec", NULL);
        fz_add_text(&e, plan->rrv, NULL);
        fz_add_text(&e, "render", NULL);
        fz_add_text(&e, plan->scene, NULL);
        fz_add_text(&e, "-o", NULL);
        w = fz_add(&e);
        fz_puts(w, plan->dir);
        fz_puts(w, "/parts/tile_");
        fz_expansion(w, "$i", 2);
        fz_puts(w, ".exr");
        fz_add_text(&e, "--tile", NULL);
        w = fz_add(&e);
        fz_expansion(w, "$i", 2);
        fz_puts(w, tiles);
        fz_add_text(&e, "--resume", NULL);
        if (plan->cpus) {
            snprintf(num, sizeof num, "%d", plan->cpus);
            fz_add_text(&e, "--threads", NULL);
            fz_add_text(&e, num, NULL);
        }
        for (i = 0; i < plan->extra_count; ++i) fz_add_text(&e, plan->extra[i], NULL);
        fz_cmd(&s, c++, &e, "render", text);
    } else if (which == FARM_MERGE) {
        fz_add_text(&e, "exec", NULL);
        fz_add_text(&e, plan->rrv, NULL);
        fz_add_text(&e, "merge", NULL);
        fz_add_text(&e, plan->output, NULL);
        for (i = 0; i < count; ++i) {
            snprintf(num, sizeof num, "/parts/tile_%d.exr", i);
            fz_add_text(&e, plan->dir, num);
        }
        fz_cmd(&s, c++, &e, "merge", text);
    } else {
        static const char *const names[2] = { "render.sbatch", "merge.sbatch" };
        for (i = 0; i < 2; ++i) {
            fz_add_text(&e, "sbatch", NULL);
            fz_add_text(&e, "--parsable", NULL);
            if (i == 1) {
                w = fz_add(&e);
                fz_puts(w, "--dependency=afterok:");
                fz_expansion(w, "$array", 6);
            }
            w = fz_add(&e);
            fz_puts(w, plan->dir);
            fz_puts(w, "/");
            fz_puts(w, names[i]);
            fz_cmd(&s, c++, &e, "sbatch", text);
            w = fz_add(&e);
            fz_puts(w, i == 0 ? "array=" : "merge=");
            fz_expansion(w, "$()", 3);
            fz_cmd(&s, c++, &e, "job=", text);
            if (i == 0) {
                w = fz_add(&e);
                fz_puts(w, "array=");
                fz_expansion(w, "${array%%;*}", 12);
                fz_cmd(&s, c++, &e, "array=", text);
            }
        }
        fz_add_text(&e, "echo", NULL);
        w = fz_add(&e);
        fz_puts(w, "tiles: job ");
        fz_expansion(w, "$array", 6);
        snprintf(num, sizeof num, " (%d tasks); merge: job ", count);
        fz_puts(w, num);
        fz_expansion(w, "${merge%%;*}", 12);
        fz_cmd(&s, c++, &e, "echo", text);
    }
    if (c != s.ncmd) fz_fail("a command that was not meant", text);
    fz_free_script(&s);
}

/* Said independently of farm_directive_problem: what no #SBATCH value
   carries. */
static int fz_unsafe(const char *v)
{
    const char *p;
    if (!v) return 0;
    for (p = v; *p; ++p)
        if (*p == '\n' || *p == '%' || strncasecmp(p, "hetjob", 6) == 0 || strncasecmp(p, "packjob", 7) == 0)
            return 1;
    return 0;
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    char *copy, *fields[14], *p, *end;
    int nfields = 0, which;
    farm_plan plan;
    const char *what;
    if (size < 4 || size > 1 << 14) return 0;
    copy = (char *)malloc(size - 4 + 1);
    if (!copy) return 0;
    memcpy(copy, data + 4, size - 4);
    copy[size - 4] = '\0';
    for (p = copy, end = copy + (size - 4); nfields < 14;) {
        fields[nfields++] = p;
        p += strlen(p);
        if (p >= end) break;
        ++p;
    }
    while (nfields < 6) fields[nfields++] = (char *)"";
    memset(&plan, 0, sizeof plan);
    plan.cpus = data[0] & 1 ? 1 + data[0] / 2 : 0;
    plan.columns = 1 + data[1] % 8;
    plan.rows = 1 + data[2] % 8;
    plan.dir = fields[0];
    plan.dir_label = "--dir";
    plan.rrv = fields[1];
    plan.scene = fields[2];
    plan.output = fields[3];
    plan.partition = data[3] & 1 ? fields[4] : NULL;
    plan.time_limit = data[3] & 2 ? fields[5] : NULL;
    plan.extra = fields + 6;
    plan.extra_count = nfields - 6;
    what = farm_directive_problem(plan.dir);
    if (!what) what = farm_directive_problem(plan.partition);
    if (!what) what = farm_directive_problem(plan.time_limit);
    if ((what != NULL) != (fz_unsafe(plan.dir) || fz_unsafe(plan.partition) || fz_unsafe(plan.time_limit)))
        fz_fail("the plan's refusal is not what it should be", plan.dir);
    if (!what)
        for (which = 0; which < FARM_SCRIPTS; ++which) {
            char *text = farm_script(&plan, which);
            if (!text) abort();
            if (strlen(text) > 1 << 20) fz_fail("a script over 1 MiB", NULL);
            fz_check(&plan, which, text);
            free(text);
        }
    free(copy);
    return 0;
}
