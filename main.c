/* rrv: the command-line tool and the reference client of rrv.h.

   The library never prints and never starts threads; this file is the only
   place that does either, so it also shows how a client is meant to split a
   render across threads and machines (tiles through rrv_render_rect, a
   pixel's samples added in one fixed tree, so the image does not depend on
   the split: see "the sample tree"). */
#define _XOPEN_SOURCE 700 /* POSIX 2008 with realpath */
#include "rrv.h"

#include <ctype.h>
#include <errno.h>
#include <float.h>
#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#ifndef RRV_THREADS
#define RRV_THREADS 0
#endif
#if RRV_THREADS
#include <pthread.h>
#endif

enum { EXIT_OK = 0, EXIT_USAGE = 1, EXIT_INPUT = 2, EXIT_IO = 3 };

/* Returned by option parsers when --help was asked for and printed. */
#define HELP_SHOWN (-1)

#define TILE_SIZE 16
#define MAX_THREADS 1024

/* ---- messages -------------------------------------------------------------- */

static const char usage_text[] =
    "usage: rrv COMMAND [ARGS]\n"
    "\n"
    "rrv renders participating media with a spatially varying index of\n"
    "refraction (heat haze, shock fronts, hot-air caustics).\n"
    "\n"
    "commands:\n"
    "  render SCENE -o OUT.pfm [options]   render a scene to a PFM or EXR (and PNG)\n"
    "  diff A.pfm B.pfm                    compare an image with a reference\n"
    "  merge OUT PART...                   merge the parts of a split render\n"
    "  farm slurm SCENE -o OUT --tiles N   write Slurm jobs rendering tiles, then merging\n"
    "  info SCENE                          describe a scene and its memory use\n"
    "  trace SCENE --ray OX OY OZ DX DY DZ trace rays through the refractive media\n"
    "  help [COMMAND]                      show this or a command's help\n"
    "\n"
    "options:\n"
    "  -h, --help      show help (also after a command: rrv render --help)\n"
    "  --version       print the version\n"
    "\n"
    "exit status: 0 ok, 1 usage error, 2 bad input (scene, grid or image),\n"
    "3 cannot write the output.\n";

static const char render_help[] =
    "usage: rrv render SCENE -o OUT.pfm|OUT.exr [options]\n"
    "\n"
    "Renders SCENE into a float RGB PFM or an OpenEXR image, chosen by the\n"
    "extension of OUT (.pfm or .exr). Every output is written to a new\n"
    "temporary file in its folder and renamed into place, so a failed run never\n"
    "clobbers an image. An output that is the scene or a file it reads, the\n"
    "other output, or an existing non-regular file (a folder, a device) is\n"
    "refused.\n"
    "\n"
    "options:\n"
    "  -o, --output OUT       the image to write (required): OUT.pfm or OUT.exr\n"
    "  --exr-half             EXR channels as 16-bit half (the default; finite\n"
    "                         values beyond 65504 are clamped to it)\n"
    "  --exr-float            EXR channels as 32-bit float\n"
    "  --exr-compression C    EXR compression: zip (default) or none\n"
    "  --png OUT.png          also write an 8-bit sRGB preview\n"
    "  --exposure E           scale the preview by 2^E (default 0)\n"
    "  --spp N                samples per pixel (default: the scene's)\n"
    "  --seed S               random seed, an integer >= 0 (default: the scene's)\n"
    "  --integrator NAME      classic, refractive or eikonal (default: the scene's;\n"
    "                         without one, chosen from the scene: rrv info says)\n"
    "  --nee MODE             refractive, eikonal: light sampling, shoot\n"
    "                         (the default; eikonal: connections solved along\n"
    "                         bent rays; refractive: as aim), aim (shadow rays\n"
    "                         aimed at the light and bent as camera rays are:\n"
    "                         unbiased, cheap, no focusing), manifold (a chain\n"
    "                         of refraction vertices solved by Newton; slow;\n"
    "                         scene keys manifoldgauge, manifoldtrials), none\n"
    "                         (lights count only where the bent path hits them:\n"
    "                         unbiased, noisier) or straight (straight shadow\n"
    "                         rays: fast, biased near refracting media)\n"
    "  --sampler NAME         pcg or sobol (Owen-scrambled, per pixel); default:\n"
    "                         the scene's, else sobol\n"
    "  --transmittance NAME   shadow rays' estimator: march (unbiased ray\n"
    "                         marching), residual (ratio tracking above the\n"
    "                         majorant grid's minorant) or ratio; default: the\n"
    "                         scene's, else ratio (residual for the shadow rays\n"
    "                         of emission NEE)\n"
    "  --noise-threshold E    adaptive sampling: stop a pixel once the standard\n"
    "                         error of its mean is below E times the mean\n"
    "                         (checked at 32, 64, ... up to --spp; 0 = off, the\n"
    "                         default: the scene's); not with --tile or --samples\n"
    "  --threads T            worker threads (default: the number of online CPUs)\n"
    "  --crop X0 Y0 X1 Y1     render only pixels [X0,X1) x [Y0,Y1), row 0 at the\n"
    "                         top; the output is the size of the crop (an EXR\n"
    "                         keeps the full frame as its display window and\n"
    "                         the crop's place as its data window)\n"
    "  --tile I/N|I/CxR       render a part: tile I (from 0) of N bands of rows,\n"
    "                         or of a C by R grid numbered row by row from the\n"
    "                         top left; bounds at floor(k * size / count)\n"
    "  --samples A:B          render a part: samples A..B-1 of every pixel; A:B\n"
    "                         must be a block of the sample tree (0:N halves\n"
    "                         at the largest power of two below N, and so on)\n"
    "  --resume               keep OUT if it already is this complete part\n"
    "  --max-grid-mb N        refuse grids, scene and OBJ files over N MiB\n"
    "                         (default 2048)\n"
    "  -q, --quiet            no progress bar and no summary\n"
    "%s"
    "\n"
    "The image is bit-identical for any thread count, and crops of a render\n"
    "match the same pixels of the full image. A part (--tile, --samples) is a\n"
    "float EXR of sample sums with its tile as data window and an rrvPart\n"
    "attribute saying what it holds; `rrv merge` makes the full image of parts,\n"
    "bit-identical to one render.\n";

static const char diff_help[] =
    "usage: rrv diff A.pfm B.pfm\n"
    "\n"
    "Compares image A with the reference B (same size; PFM, or OpenEXR by the\n"
    "extension .exr: scanline RGB, uncompressed, RLE or ZIP) and prints one\n"
    "`key: value` per line:\n"
    "  rmse             sqrt(mean((a-b)^2)) over pixels and channels\n"
    "  relmse           mean((a-b)^2 / (b^2 + 0.01)), B being the reference\n"
    "  mae              mean(|a-b|)\n"
    "  max_abs_error    the largest |a-b|\n"
    "  max_abs_pixel    its pixel as X Y (row 0 at the top)\n"
    "  max_abs_channel  its channel: r, g or b\n"
    "  nonfinite        values that are NaN or infinite in A or B\n"
    "Exits 2 if an image cannot be read or the sizes differ.\n";

static const char info_help[] =
    "usage: rrv info SCENE [--max-grid-mb N]\n"
    "\n"
    "Loads SCENE and prints its resolution, render settings, the counts of\n"
    "materials, shapes, lights and media (with each medium's box, fields and\n"
    "whether it refracts), the BVH size, and the memory the scene holds plus\n"
    "what a full-frame render buffer would need.\n"
    "\n"
    "options:\n"
    "  --max-grid-mb N   refuse grids, scene and OBJ files over N MiB\n"
    "                    (default 2048)\n";

static const char trace_help[] =
    "usage: rrv trace SCENE --ray OX OY OZ DX DY DZ [options]\n"
    "\n"
    "Walks a ray through the scene's refractive media (absorption and\n"
    "scattering ignored) and prints CSV on stdout: the header\n"
    "x,y,z,dx,dy,dz,events and one row per walk with where and in which\n"
    "direction the ray left the last medium. In a scene where nothing\n"
    "refracts the ray goes straight, and a note on stderr says so.\n"
    "\n"
    "options:\n"
    "  --ray OX OY OZ DX DY DZ   origin and direction (required; the direction\n"
    "                            is normalised)\n"
    "  --integrator NAME         refractive or eikonal (default: the scene's,\n"
    "                            or refractive if that is classic)\n"
    "  --n N                     number of walks, numbered 0..N-1 (default 1)\n"
    "  --seed S                  random seed (default: the scene's)\n"
    "  --path                    print every vertex instead, as rows\n"
    "                            walk,x,y,z,dx,dy,dz\n"
    "  --max-grid-mb N           refuse grids, scene and OBJ files over N MiB\n"
    "%s";

static void print_library_error(const rrv_error *err)
{
    const char *message = err->message[0] ? err->message : rrv_result_string(err->code);
    if (err->line > 0)
        fprintf(stderr, "%s:%d: %s\n", err->file, err->line, message);
    else if (err->file[0])
        fprintf(stderr, "%s: %s\n", err->file, message);
    else
        fprintf(stderr, "rrv: %s\n", message);
}

/* Walks a command's arguments; remembers the command for the --help hint. */
typedef struct arg_cursor {
    int argc;
    char **argv;
    int index;
    const char *command;
} arg_cursor;

#if defined(__GNUC__) || defined(__clang__)
__attribute__((format(printf, 2, 3)))
#endif
static int usage_error(const arg_cursor *args, const char *fmt, ...)
{
    va_list ap;
    fputs("rrv: ", stderr);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    if (args && args->command)
        fprintf(stderr, "\nrun \"rrv %s --help\" for usage\n", args->command);
    else
        fputs("\nrun \"rrv --help\" for usage\n", stderr);
    return EXIT_USAGE;
}

/* "did you mean" for an unknown flag: the nearest "--name" in the command's
   help texts, compared without leading dashes by optimal string alignment
   (Levenshtein plus a swap of neighbours), within two edits and fewer than
   half the longer name; ties go to the first in the help. Names over 32
   bytes are no typo. The library's scene parser has its own, for keys. */
static int edit_distance(const char *a, size_t an, const char *b, size_t bn)
{
    int d[33][33];
    size_t i, j;
    if (an > 32 || bn > 32) return INT_MAX;
    for (i = 0; i <= an; ++i)
        for (j = 0; j <= bn; ++j) {
            int best = i == 0 || j == 0 ? (int)(i + j) : d[i - 1][j - 1] + (a[i - 1] != b[j - 1]);
            if (i > 0 && d[i - 1][j] + 1 < best) best = d[i - 1][j] + 1;
            if (j > 0 && d[i][j - 1] + 1 < best) best = d[i][j - 1] + 1;
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] && d[i - 2][j - 2] + 1 < best)
                best = d[i - 2][j - 2] + 1;
            d[i][j] = best;
        }
    return d[an][bn];
}

/* 1 when b is a nearer candidate for the typo a than the best so far. */
static int nearer(const char *a, size_t an, const char *b, size_t bn, int *best_d)
{
    int d = edit_distance(a, an, b, bn);
    if (bn == 0 || d >= *best_d || (size_t)(2 * d) >= (an > bn ? an : bn)) return 0;
    *best_d = d;
    return 1;
}

static const char *flag_hint(const char *arg, const char *help, const char *more, char hint[80])
{
    const char *texts[2], *best = NULL, *s;
    size_t an, n, best_n = 0;
    int t, best_d = 3;
    while (*arg == '-') ++arg;
    an = strlen(arg);
    texts[0] = help;
    texts[1] = more;
    for (t = 0; t < 2; ++t)
        for (s = texts[t]; s && (s = strstr(s, "--")) != NULL; s += 2 + n) {
            for (n = 0; isalnum((unsigned char)s[2 + n]) || s[2 + n] == '-'; ++n) {}
            if (nearer(arg, an, s + 2, n, &best_d)) {
                best = s;
                best_n = n + 2;
            }
        }
    hint[0] = '\0';
    if (best) snprintf(hint, 80, " (did you mean \"%.*s\"?)", (int)best_n, best);
    return hint;
}

/* "did you mean" for an unknown command: the commands are the indented
   words under "commands:" in the usage text, so the hint cannot drift
   from the help. */
static const char *command_hint(const char *arg, char hint[80])
{
    const char *s = strstr(usage_text, "commands:\n"), *best = NULL;
    size_t an = strlen(arg), n, best_n = 0;
    int best_d = 3;
    hint[0] = '\0';
    if (!s) return hint;
    for (s = strchr(s, '\n') + 1; s[0] == ' ' && s[1] == ' '; s = strchr(s, '\n') + 1) {
        s += 2;
        for (n = 0; islower((unsigned char)s[n]); ++n) {}
        if (nearer(arg, an, s, n, &best_d)) {
            best = s;
            best_n = n;
        }
    }
    if (best) snprintf(hint, 80, " (did you mean \"%.*s\"?)", (int)best_n, best);
    return hint;
}

/* ---- strict number parsing ----------------------------------------------------
   strtol and friends accept leading spaces, trailing junk and (for unsigned)
   a minus sign; a typo in a flag must not silently become a number. */

static int parse_long(const char *text, long lo, long hi, long *out)
{
    char *end;
    long value;
    if (!isdigit((unsigned char)text[0]) && !(text[0] == '-' || text[0] == '+')) return 0;
    errno = 0;
    value = strtol(text, &end, 10);
    if (end == text || *end || errno == ERANGE || value < lo || value > hi) return 0;
    *out = value;
    return 1;
}

static int parse_u64(const char *text, uint64_t *out)
{
    char *end;
    unsigned long long value;
    if (!isdigit((unsigned char)text[0])) return 0;
    errno = 0;
    value = strtoull(text, &end, 10);
    if (*end || errno == ERANGE) return 0;
#if ULLONG_MAX > UINT64_MAX
    if (value > UINT64_MAX) return 0;
#endif
    *out = (uint64_t)value;
    return 1;
}

static int parse_double(const char *text, double *out)
{
    char *end;
    double value;
    /* Decimal only: strtod would also take "0x1p3", "inf" and "nan". */
    if (!text[0] || text[strspn(text, "0123456789+-.eE")] != '\0') return 0;
    errno = 0;
    value = strtod(text, &end);
    if (end == text || *end || errno == ERANGE || !isfinite(value)) return 0;
    *out = value;
    return 1;
}

/* The next argument as the value of `flag`; `what` says what was expected.
   A value that starts with "-" and is not a number (--exposure -1 is one)
   is taken for a forgotten value followed by an option: `--png -q` would
   otherwise write a file called "-q". A file of such a name is "./-q". */
static int take_value(arg_cursor *args, const char *flag, const char *what, const char **text)
{
    const char *next;
    double number;
    if (args->index + 1 >= args->argc) {
        usage_error(args, "%s needs %s", flag, what);
        return 0;
    }
    next = args->argv[args->index + 1];
    if (next[0] == '-' && !parse_double(next, &number)) {
        usage_error(args, "%s needs %s, got the option \"%s\" (for a file of that name write \"./%s\")", flag,
                    what, next, next);
        return 0;
    }
    *text = args->argv[++args->index];
    return 1;
}

static int take_int(arg_cursor *args, const char *flag, long lo, long hi, const char *what,
                    int *out)
{
    const char *text;
    long value;
    if (!take_value(args, flag, what, &text)) return 0;
    if (parse_long(text, lo, LONG_MAX, &value) && value > hi) {
        usage_error(args, "%s must be at most %ld, got \"%s\"", flag, hi, text);
        return 0;
    }
    if (!parse_long(text, lo, hi, &value)) {
        usage_error(args, "%s needs %s, got \"%s\"", flag, what, text);
        return 0;
    }
    *out = (int)value;
    return 1;
}

static int take_u64(arg_cursor *args, const char *flag, const char *what, uint64_t *out)
{
    const char *text;
    if (!take_value(args, flag, what, &text)) return 0;
    if (!parse_u64(text, out)) {
        usage_error(args, "%s needs %s, got \"%s\"", flag, what, text);
        return 0;
    }
    return 1;
}

static int take_double(arg_cursor *args, const char *flag, const char *what, double *out)
{
    const char *text;
    if (!take_value(args, flag, what, &text)) return 0;
    if (!parse_double(text, out)) {
        usage_error(args, "%s needs %s, got \"%s\"", flag, what, text);
        return 0;
    }
    return 1;
}

static int take_grid_limit(arg_cursor *args, size_t *max_grid_bytes)
{
    const char *what = "a positive number of MiB";
    uint64_t mib;
    if (!take_u64(args, "--max-grid-mb", what, &mib)) return 0;
    if (mib == 0 || mib > SIZE_MAX / ((size_t)1 << 20)) {
        usage_error(args, "--max-grid-mb needs %s, got \"%s\"", what, args->argv[args->index]);
        return 0;
    }
    *max_grid_bytes = (size_t)mib << 20;
    return 1;
}

/* By rrv_integrator's values: DEFAULT (0) is never named on the command line. */
static const char *const integrator_names[] = {"default", "classic", "refractive", "eikonal"};

static int take_integrator(arg_cursor *args, int allow_classic, rrv_integrator *out)
{
    const char *what = allow_classic ? "classic, refractive or eikonal" : "refractive or eikonal";
    const char *text;
    int i;
    if (!take_value(args, "--integrator", what, &text)) return 0;
    for (i = allow_classic ? RRV_INTEGRATOR_CLASSIC : RRV_INTEGRATOR_REFRACTIVE; i <= RRV_INTEGRATOR_EIKONAL; ++i) {
        if (strcmp(text, integrator_names[i]) == 0) {
            *out = (rrv_integrator)i;
            return 1;
        }
    }
    usage_error(args, "--integrator needs %s, got \"%s\"", what, text);
    return 0;
}

static const char *integrator_name(rrv_integrator integrator)
{
    return (unsigned)integrator <= RRV_INTEGRATOR_EIKONAL ? integrator_names[integrator] : "unknown";
}

static int is_flag(const char *arg) { return arg[0] == '-' && arg[1] != '\0'; }
static int is_help_flag(const char *arg)
{
    return strcmp(arg, "--help") == 0 || strcmp(arg, "-h") == 0;
}

/* ---- time and human-readable numbers ------------------------------------------ */

static double seconds_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void format_duration(double seconds, char *buf, size_t size)
{
    if (!(seconds >= 0)) seconds = 0;
    if (seconds < 60)
        snprintf(buf, size, "%.1fs", seconds);
    else if (seconds < 3600)
        snprintf(buf, size, "%dm%02ds", (int)(seconds / 60), (int)fmod(seconds, 60));
    else
        snprintf(buf, size, "%dh%02dm", (int)(seconds / 3600), (int)fmod(seconds / 60, 60));
}

static void format_count(double value, char *buf, size_t size)
{
    if (value >= 1e9)
        snprintf(buf, size, "%.3gG", value / 1e9);
    else if (value >= 1e6)
        snprintf(buf, size, "%.3gM", value / 1e6);
    else if (value >= 1e3)
        snprintf(buf, size, "%.3gk", value / 1e3);
    else
        snprintf(buf, size, "%.3g", value);
}

static void format_bytes(double bytes, char *buf, size_t size)
{
    static const char *const units[] = {"bytes", "KiB", "MiB", "GiB", "TiB"};
    int unit = 0;
    while (bytes >= 1024 && unit < 4) {
        bytes /= 1024;
        ++unit;
    }
    if (unit == 0)
        snprintf(buf, size, "%.0f bytes", bytes);
    else
        snprintf(buf, size, "%.2f %s", bytes, units[unit]);
}

/* ---- output files --------------------------------------------------------------
   The library's file writers are plain C; the tool writes through
   rrv_write_pfm_to with POSIX calls instead so that it can create its
   temporary file exclusively (mkstemp), tell a device or a folder from a
   file (stat) and compare files by identity rather than by spelling. */

/* Catches a mistyped output folder before the render rather than after it. */
static int output_folder_writable(const char *path)
{
    const char *slash = strrchr(path, '/');
    char folder[4096];
    size_t length;
    if (!slash) return access(".", W_OK | X_OK) == 0;
    length = slash == path ? 1 : (size_t)(slash - path);
    if (length >= sizeof folder) return 1; /* let the writer decide */
    memcpy(folder, path, length);
    folder[length] = '\0';
    return access(folder, W_OK | X_OK) == 0;
}

static const char *file_kind_name(mode_t mode)
{
    if (S_ISDIR(mode)) return "a directory";
    if (S_ISCHR(mode)) return "a character device";
    if (S_ISBLK(mode)) return "a block device";
    if (S_ISFIFO(mode)) return "a FIFO";
    if (S_ISSOCK(mode)) return "a socket";
    if (S_ISLNK(mode)) return "a symbolic link";
    return "not a regular file";
}

/* An existing output must be a regular file: renaming over a device node, a
   FIFO or a socket would replace it with an image (rename refuses folders,
   but the message should say why). stat follows symbolic links, so a link
   to a device is refused too. */
static int check_output_target(const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0) return 1; /* new file, or the writer reports it */
    if (S_ISREG(st.st_mode)) return 1;
    fprintf(stderr, "rrv: refusing to write \"%s\": it is %s, not a regular file\n", path,
            file_kind_name(st.st_mode));
    return 0;
}

/* A script is refused even behind a link that points at a regular file:
   the farm folder may be shared, and a link planted there says someone
   meant the user to write elsewhere (the rename would replace the link, not
   follow it, but the user should know). */
static int check_script_target(const char *path)
{
    struct stat st;
    if (lstat(path, &st) == 0 && S_ISLNK(st.st_mode)) {
        fprintf(stderr, "rrv: refusing to write \"%s\": it is %s, not a regular file\n", path,
                file_kind_name(st.st_mode));
        return 0;
    }
    return check_output_target(path);
}

static int check_output(const char *path)
{
    if (!check_output_target(path)) return 0;
    if (output_folder_writable(path)) return 1;
    fprintf(stderr, "rrv: cannot write \"%s\": %s\n", path, strerror(errno));
    return 0;
}

/* The folder part of path ("." for a bare name) and a pointer to the name. */
static int split_path(const char *path, char *folder, size_t cap, const char **name)
{
    const char *slash = strrchr(path, '/');
    size_t length;
    if (!slash) {
        if (cap < 2) return 0;
        strcpy(folder, ".");
        *name = path;
        return 1;
    }
    length = slash == path ? 1 : (size_t)(slash - path);
    if (length >= cap) return 0;
    memcpy(folder, path, length);
    folder[length] = '\0';
    *name = slash + 1;
    return 1;
}

/* 1 when a and b name one file. Existing files are compared by device and
   inode (hard links, symbolic links, "./a" and "a"); a file that does not
   exist yet by its folder's real path and its name. */
static int same_file(const char *a, const char *b)
{
    struct stat sa, sb;
    int has_a = stat(a, &sa) == 0, has_b = stat(b, &sb) == 0;
    char folder_a[4096], folder_b[4096], *real_a, *real_b;
    const char *name_a, *name_b;
    int same;
    if (has_a && has_b) return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
    if (has_a != has_b) return 0;
    if (strcmp(a, b) == 0) return 1;
    if (!split_path(a, folder_a, sizeof folder_a, &name_a) ||
        !split_path(b, folder_b, sizeof folder_b, &name_b) || strcmp(name_a, name_b) != 0)
        return 0;
    real_a = realpath(folder_a, NULL);
    real_b = realpath(folder_b, NULL);
    same = real_a && real_b && strcmp(real_a, real_b) == 0;
    free(real_a);
    free(real_b);
    return same;
}

/* The files a scene load read, collected through rrv_load_options.on_input. */
typedef struct input_list {
    char **paths;
    int count, capacity;
    int out_of_memory;
} input_list;

static void record_input(void *user, const char *path)
{
    input_list *list = (input_list *)user;
    char *copy;
    if (list->count == list->capacity) {
        int capacity = list->capacity ? 2 * list->capacity : 8;
        char **grown = (char **)realloc(list->paths, (size_t)capacity * sizeof *grown);
        if (!grown) {
            list->out_of_memory = 1;
            return;
        }
        list->paths = grown;
        list->capacity = capacity;
    }
    copy = (char *)malloc(strlen(path) + 1);
    if (!copy) {
        list->out_of_memory = 1;
        return;
    }
    strcpy(copy, path);
    list->paths[list->count++] = copy;
}

static void free_inputs(input_list *list)
{
    int i;
    for (i = 0; i < list->count; ++i) free(list->paths[i]);
    free(list->paths);
    memset(list, 0, sizeof *list);
}

/* Refuses an output that already exists as one of the scene's inputs. */
static int check_output_not_input(const char *output, const input_list *inputs)
{
    struct stat out_st, in_st;
    int i;
    if (stat(output, &out_st) != 0) return 1; /* an input exists, so this is none */
    for (i = 0; i < inputs->count; ++i) {
        if (stat(inputs->paths[i], &in_st) != 0) continue;
        if (in_st.st_dev == out_st.st_dev && in_st.st_ino == out_st.st_ino) {
            if (i == 0)
                fprintf(stderr, "rrv: refusing to write \"%s\": it is the scene file\n", output);
            else
                fprintf(stderr, "rrv: refusing to write \"%s\": the scene reads it (as \"%s\")\n",
                        output, inputs->paths[i]);
            return 0;
        }
    }
    return 1;
}

enum { OUTPUT_PFM, OUTPUT_PNG, OUTPUT_EXR, OUTPUT_SCRIPT };

typedef struct pending_output {
    const char *path;
    int format;                 /* OUTPUT_* */
    const rrv_exr_options *exr; /* for OUTPUT_EXR */
    const char *script;         /* for OUTPUT_SCRIPT: the text, written executable */
    char temp[4096 + 32]; /* "" when no temporary file exists; room for a folder and ".rrv.XXXXXX" */
} pending_output;

static int fwrite_callback(void *user, const void *data, size_t size)
{
    return fwrite(data, 1, size, (FILE *)user) == size ? 0 : 1;
}

static void remove_temp(pending_output *out)
{
    if (out->temp[0]) unlink(out->temp);
    out->temp[0] = '\0';
}

/* Writes the image to a new temporary file in the output's folder: mkstemp
   picks a name no other file has, so neither a file called "<out>.tmp" nor a
   second render to the same output is touched. On failure nothing is left. */
static int write_temp(pending_output *out, const float *image, int width, int height,
                      double exposure)
{
    char folder[4096];
    const char *name;
    mode_t mask;
    FILE *file;
    rrv_result result;
    int fd, ok;
    out->temp[0] = '\0';
    if (!split_path(out->path, folder, sizeof folder, &name) ||
        snprintf(out->temp, sizeof out->temp, "%s/.%s.XXXXXX", folder, name) >= (int)sizeof out->temp) {
        out->temp[0] = '\0';
        fprintf(stderr, "rrv: cannot write \"%s\": the path is too long\n", out->path);
        return 0;
    }
    fd = mkstemp(out->temp);
    if (fd < 0 && errno == ENAMETOOLONG) { /* a long name: a short temporary one */
        snprintf(out->temp, sizeof out->temp, "%s/.rrv.XXXXXX", folder);
        fd = mkstemp(out->temp);
    }
    if (fd < 0) {
        fprintf(stderr, "rrv: cannot write \"%s\": cannot create a temporary file in \"%s\": %s\n",
                out->path, folder, strerror(errno));
        out->temp[0] = '\0';
        return 0;
    }
    /* mkstemp makes the file private (0600); an image gets the usual
       permissions, as if it had been created with fopen (a script those of
       chmod +x). */
    mask = umask(0);
    umask(mask);
    if (fchmod(fd, (out->format == OUTPUT_SCRIPT ? 0777 : 0666) & ~mask) != 0 || !(file = fdopen(fd, "wb"))) {
        fprintf(stderr, "rrv: cannot write \"%s\": %s\n", out->path, strerror(errno));
        close(fd);
        remove_temp(out);
        return 0;
    }
    if (out->format == OUTPUT_SCRIPT)
        result = fwrite_callback(file, out->script, strlen(out->script)) == 0 ? RRV_OK : RRV_ERROR_IO;
    else if (out->format == OUTPUT_PNG)
        result = rrv_write_png_to(fwrite_callback, file, image, width, height, exposure, NULL);
    else if (out->format == OUTPUT_EXR)
        result = rrv_write_exr_to(fwrite_callback, file, image, width, height, out->exr, NULL);
    else
        result = rrv_write_pfm_to(fwrite_callback, file, image, width, height, NULL);
    errno = 0;
    ok = result == RRV_OK && fflush(file) == 0 && fsync(fileno(file)) == 0;
    if (!ok && result == RRV_OK && errno == EINVAL) ok = 1; /* no fsync here, e.g. a pipe fs */
    if (fclose(file) != 0) ok = 0;
    if (!ok) {
        fprintf(stderr, "rrv: cannot write \"%s\": %s\n", out->path,
                result == RRV_ERROR_MEMORY ? "out of memory"
                : result == RRV_ERROR_ARGUMENT ? "the image is too wide for this format"
                : errno ? strerror(errno) : "writing failed");
        remove_temp(out);
        return 0;
    }
    return 1;
}

/* Writes every output to its temporary file first and renames them into
   place only when all were written, so a failure (a full disk, say) keeps
   every old output. Signals that would end the process are held meanwhile,
   so an interrupt does not strand a temporary file. */
static int write_outputs(pending_output *outputs, int count, const float *image, int width,
                         int height, double exposure)
{
    sigset_t hold, previous;
    int i, ok = 1;
    sigemptyset(&hold);
    sigaddset(&hold, SIGINT);
    sigaddset(&hold, SIGTERM);
    sigaddset(&hold, SIGHUP);
    sigaddset(&hold, SIGQUIT);
    sigprocmask(SIG_BLOCK, &hold, &previous);
    for (i = 0; i < count && ok; ++i) ok = write_temp(&outputs[i], image, width, height, exposure);
    /* Checked again: a device may have appeared at the path since the start. */
    for (i = 0; i < count && ok; ++i)
        ok = outputs[i].format == OUTPUT_SCRIPT ? check_script_target(outputs[i].path)
                                                : check_output_target(outputs[i].path);
    for (i = 0; i < count && ok; ++i) {
        if (rename(outputs[i].temp, outputs[i].path) != 0) {
            fprintf(stderr, "rrv: cannot write \"%s\": cannot rename the temporary file: %s\n",
                    outputs[i].path, strerror(errno));
            ok = 0;
            break;
        }
        outputs[i].temp[0] = '\0';
    }
    for (i = 0; i < count; ++i) remove_temp(&outputs[i]);
    sigprocmask(SIG_SETMASK, &previous, NULL);
    return ok;
}

static int finish_stdout(int code)
{
    if (fflush(stdout) != 0 || ferror(stdout)) {
        fprintf(stderr, "rrv: cannot write to standard output: %s\n", strerror(errno));
        return code == EXIT_OK ? EXIT_IO : code;
    }
    return code;
}

static int default_thread_count(void);

/* The set-up's progress on a terminal: a scene of heavy noise can spend a
   minute in its bakes and majorant grids (each one rrv_load_options.
   parallel_for call, a task a slice), and a silent minute looks like a
   hang. A line appears once a call has run a second, with that call's
   slices and the time they leave (a step: one grid, baked or bounded); the
   load clears it. */
typedef struct setup_meter {
    int show;           /* stderr is a terminal and the render is not -q */
    int call;           /* parallel_for calls so far */
    int drawn;          /* a line is on the terminal */
    double call_start, last_draw;
} setup_meter;
static setup_meter setup_progress;

static void setup_progress_start(void)
{
    ++setup_progress.call;
    setup_progress.call_start = seconds_now();
}

/* A task of count finished, done in all; with the pool's lock held. */
static void setup_progress_step(int done, int count)
{
    double now, elapsed;
    char elapsed_text[32], eta_text[32];
    if (!setup_progress.show) return;
    now = seconds_now();
    elapsed = now - setup_progress.call_start;
    if (elapsed < 1.0 || now - setup_progress.last_draw < 0.1 || done >= count) return;
    setup_progress.last_draw = now;
    format_duration(elapsed, elapsed_text, sizeof elapsed_text);
    format_duration(elapsed * (count - done) / done, eta_text, sizeof eta_text);
    fprintf(stderr, "\rpreparing the scene: step %d, %d of %d slices, elapsed %s, eta %s   ", setup_progress.call,
            done, count, elapsed_text, eta_text);
    fflush(stderr);
    setup_progress.drawn = 1;
}

static void setup_progress_clear(void)
{
    if (setup_progress.drawn) fprintf(stderr, "\r%78s\r", "");
    setup_progress.drawn = 0;
    setup_progress.call = 0;
}

#if RRV_THREADS
/* The tasks of one rrv_load_options.parallel_for call, handed out in turn. */
typedef struct setup_pool {
    void (*task)(void *, int);
    void *ctx;
    int count, next, done;
    pthread_mutex_t lock;
} setup_pool;

static void *setup_worker(void *arg)
{
    setup_pool *pool = (setup_pool *)arg;
    int finished = 0;
    for (;;) {
        int i;
        pthread_mutex_lock(&pool->lock);
        if (finished) setup_progress_step(++pool->done, pool->count);
        i = pool->next++;
        pthread_mutex_unlock(&pool->lock);
        if (i >= pool->count) return NULL;
        pool->task(pool->ctx, i);
        finished = 1;
    }
}
#endif

/* rrv_load_options.parallel_for: the scene's bakes on `*(int *)user`
   threads, this one among them; serially when threads cannot start. The
   count lives as long as the process, since the scene keeps the pointer for
   the prepare that the refraction options may ask for again. */
static int setup_threads = 1;

static void setup_parallel_for(void *user, int count, void (*task)(void *, int), void *ctx)
{
    int threads = *(const int *)user, i;
#if RRV_THREADS
    pthread_t ids[MAX_THREADS];
    setup_pool pool;
    int started = 0;
#endif
    setup_progress_start();
#if RRV_THREADS
    if (threads > count) threads = count;
    if (threads > 1 && pthread_mutex_init(&pool.lock, NULL) == 0) {
        pool.task = task;
        pool.ctx = ctx;
        pool.count = count;
        pool.next = 0;
        pool.done = 0;
        while (started < threads - 1 && pthread_create(&ids[started], NULL, setup_worker, &pool) == 0) ++started;
        setup_worker(&pool);
        for (i = 0; i < started; ++i) pthread_join(ids[i], NULL);
        pthread_mutex_destroy(&pool.lock);
        return;
    }
#endif
    (void)threads;
    for (i = 0; i < count; ++i) {
        task(ctx, i);
        setup_progress_step(i + 1, count);
    }
}

/* inputs, if not NULL, collects every file the load read, the scene first.
   threads: for the set-up, 0 = the number of online CPUs. */
static int load_scene(const char *path, size_t max_grid_bytes, input_list *inputs,
                      rrv_scene **scene, int threads)
{
    rrv_load_options options;
    rrv_error err;
    int loaded;
    memset(&options, 0, sizeof options);
    memset(&err, 0, sizeof err);
    options.max_grid_bytes = max_grid_bytes;
    setup_threads = threads > 0 ? threads : default_thread_count();
    options.parallel_for = setup_parallel_for;
    options.parallel_for_user = &setup_threads;
    if (inputs) {
        options.on_input = record_input;
        options.on_input_user = inputs;
    }
    *scene = NULL;
    loaded = rrv_scene_load(path, &options, scene, &err) == RRV_OK;
    setup_progress_clear();
    if (!loaded) {
        print_library_error(&err);
        return 0;
    }
    if (inputs && inputs->out_of_memory) {
        fprintf(stderr, "rrv: out of memory\n");
        rrv_scene_free(*scene);
        *scene = NULL;
        return 0;
    }
    return 1;
}

/* ---- the tiled render ---------------------------------------------------------- */

typedef struct render_job {
    const rrv_scene *scene;
    int x0, y0, x1, y1; /* the rectangle to render */
    int sample_begin, sample_end; /* a block of the sample tree (see sum_samples) */
    float *sum;         /* the rectangle's sums, row 0 = its top row */
    int stride;
    double noise_threshold; /* > 0: adaptive, each pixel's count in counts */
    int *counts;
    int spp_min, spp_median, spp_max; /* adaptive: of counts, for the summary */
    double spp_mean;
    int tiles_x, tile_count;
    long tile_stride; /* see "honest progress" */
    double *tile_seconds; /* the time each tile took, negative until it is done */
    int show_progress;
    double start_time;

    /* Shared between workers; guarded by `lock` when threads run. */
    int next_tile, tiles_done;
    rrv_result failure;
    rrv_error failure_error; /* the library's message for it (empty: none) */
    rrv_render_stats stats;
    double last_progress_time;
#if RRV_THREADS
    int use_lock;
    pthread_mutex_t lock;
#endif
} render_job;

static void job_lock(render_job *job)
{
#if RRV_THREADS
    if (job->use_lock) pthread_mutex_lock(&job->lock);
#else
    (void)job;
#endif
}

static void job_unlock(render_job *job)
{
#if RRV_THREADS
    if (job->use_lock) pthread_mutex_unlock(&job->lock);
#else
    (void)job;
#endif
}

#define PROGRESS_BAR_WIDTH 30

/* ---- honest progress -------------------------------------------------------------
   The ETA extrapolates the time per finished tile, which is only honest if the
   finished tiles are a fair sample of the image: in row order a sky above a
   fire finishes fast and the ETA at 20 % is a fraction of the truth. Tiles are
   therefore handed out along a rank-1 lattice: turn k renders the tile of
   row-major index k * stride mod count, with stride = r * tiles_x + c chosen so
   that one turn moves about tiles_x / rho columns and tiles_y / rho^2 rows, rho
   the plastic number (1.3247...). That is the two-dimensional analogue of the
   golden ratio's additive sequence (Roberts' R2), so both the tiles done and the
   tiles left are spread nearly evenly over rows and columns at every turn; a
   single golden stride spreads the rows but, on a grid whose width divides into
   the stride's remainder, samples some columns twice. stride is coprime to
   count, so every tile comes once. The order changes nothing in the image:
   each pixel's samples depend only on the pixel. */

static long gcd_long(long a, long b)
{
    while (b) {
        long t = a % b;
        a = b;
        b = t;
    }
    return a;
}

static long tile_stride(int tiles_x, int tiles_y)
{
    const double rho = 1.324717957244746;
    long count = (long)tiles_x * tiles_y;
    long stride = (long)(tiles_y / (rho * rho)) * tiles_x + (long)(tiles_x / rho + 0.5);
    if (count <= 1) return 0;
    stride %= count;
    if (stride < 1) stride = 1;
    while (gcd_long(stride, count) != 1) stride = stride % count + 1; /* 1 is coprime to all */
    return stride;
}

static int tile_for_turn(long turn, long count, long stride)
{
    return count > 1 ? (int)(turn % count * stride % count) : 0;
}

/* Seconds left. cost[t] is the seconds tile t took, or negative while it is
   not done. A tile left is predicted to cost the mean of the tiles done next
   to it (or, where none is, within two tiles; else the mean of all done): a
   flame's tiles then predict their neighbours', which a mean over the whole
   image would spread over the sky. The predicted seconds are scaled by the
   elapsed time over the seconds done, which holds for any number of threads.
   Negative while nothing is done. */
static double eta_seconds(const double *cost, int tiles_x, int count, double elapsed)
{
    int tiles_y = tiles_x > 0 ? count / tiles_x : 0, t, dx, dy, done = 0;
    double done_seconds = 0, mean, left = 0;
    for (t = 0; t < count; ++t)
        if (cost[t] >= 0) {
            done_seconds += cost[t];
            ++done;
        }
    if (done == 0 || done_seconds <= 0) return -1;
    mean = done_seconds / done;
    for (t = 0; t < count; ++t) {
        int x = t % tiles_x, y = t / tiles_x, near = 0, reach;
        double near_seconds = 0;
        if (cost[t] >= 0) continue;
        for (reach = 1; reach <= 2 && !near; ++reach)
            for (dy = -reach; dy <= reach; ++dy)
                for (dx = -reach; dx <= reach; ++dx) {
                    int nx = x + dx, ny = y + dy;
                    if (nx < 0 || ny < 0 || nx >= tiles_x || ny >= tiles_y) continue;
                    if (cost[ny * tiles_x + nx] < 0) continue;
                    near_seconds += cost[ny * tiles_x + nx];
                    ++near;
                }
        left += near ? near_seconds / near : mean;
    }
    return elapsed * left / done_seconds;
}

/* Called with the lock held. Redraws at most ten times a second because
   a terminal that scrolls slower than the render would slow it down. */
static void draw_progress(render_job *job, int force)
{
    char bar[PROGRESS_BAR_WIDTH + 1], elapsed_text[32], eta_text[32];
    double now, elapsed, fraction, left;
    int filled, i;
    if (!job->show_progress) return;
    now = seconds_now();
    /* eta_seconds looks at every tile: a huge image redraws less often */
    if (!force && now - job->last_progress_time < (job->tile_count > 65536 ? 1.0 : 0.1)) return;
    elapsed = now - job->start_time;
    fraction = job->tile_count ? (double)job->tiles_done / job->tile_count : 1;
    filled = (int)(fraction * PROGRESS_BAR_WIDTH);
    job->last_progress_time = now;
    for (i = 0; i < PROGRESS_BAR_WIDTH; ++i) bar[i] = i < filled ? '#' : '.';
    bar[PROGRESS_BAR_WIDTH] = '\0';
    format_duration(elapsed, elapsed_text, sizeof elapsed_text);
    left = !job->tiles_done ? -1
           : job->tile_seconds ? eta_seconds(job->tile_seconds, job->tiles_x, job->tile_count, elapsed)
                               : elapsed * (1 - fraction) / fraction;
    if (left >= 0)
        format_duration(left, eta_text, sizeof eta_text);
    else
        snprintf(eta_text, sizeof eta_text, "?");
    fprintf(stderr, "\r[%s] %5.1f%%  elapsed %s  eta %s   ", bar, 100 * fraction,
            elapsed_text, eta_text);
    fflush(stderr);
}

static void add_stats(rrv_render_stats *into, const rrv_render_stats *from)
{
    into->samples += from->samples;
    into->paths += from->paths;
    into->events += from->events;
    into->nonfinite += from->nonfinite;
    into->paths_cut += from->paths_cut;
    into->cut_tracking += from->cut_tracking;
    into->solves += from->solves;
    into->solves_converged += from->solves_converged;
    into->solve_iterations += from->solve_iterations;
    into->solve_segments += from->solve_segments;
    into->solve_connections += from->solve_connections;
    into->solve_trials += from->solve_trials;
    into->solves_unsupported += from->solves_unsupported;
    into->aim_shots += from->aim_shots;
    into->aim_missed += from->aim_missed;
    into->cone_shots += from->cone_shots;
    into->cone_counted += from->cone_counted;
    into->cut_samples += from->cut_samples;
    into->trapped_paths += from->trapped_paths;
}

/* ---- the sample tree ------------------------------------------------------------
   Float addition is not associative, so a pixel's sum could only be split
   between machines bit-identically if every split added in the same order.
   rrv therefore sums a pixel's samples in one fixed binary tree: a block of
   samples [a, b) with more than one sample is the float sum of [a, m) and
   [m, b), m - a the largest power of two below b - a; a single sample is the
   library's sum of that sample alone. A render of the whole range and the
   merge of any blocks of this tree (sample_block_ok) then do the very same
   additions, so a split render is bit-identical to a single one. */

static int sample_split(int a, int b)
{
    int half = 1;
    while (half < (b - a) - half) half *= 2;
    return a + half;
}

/* Whether [a, b) is a block of the tree over [0, total). */
static int sample_block_ok(int a, int b, int total)
{
    int lo = 0, hi = total;
    if (a < 0 || b > total || a >= b) return 0;
    while (lo != a || hi != b) {
        int mid;
        if (hi - lo < 2) return 0;
        mid = sample_split(lo, hi);
        if (b <= mid) hi = mid;
        else if (a >= mid) lo = mid;
        else return 0;
    }
    return 1;
}

/* out[c] += add[c], saturated as the library saturates its sums. */
static float add_saturated(float a, float b)
{
    float v = a + b;
    return v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : v;
}

/* How many levels of scratch a tree over n samples needs. */
static int sample_tree_depth(int n)
{
    int depth = 1;
    while (n > 1) {
        n = (n + 1) / 2;
        ++depth;
    }
    return depth;
}

/* Sums samples [a, b) of pixels [x0,x1) x [y0,y1) into out (zero on entry)
   by the sample tree; scratch holds one TILE_SIZE^2 RGB buffer a level. */
static rrv_result sum_samples(const rrv_scene *scene, int x0, int y0, int x1, int y1, int a, int b,
                              float *out, int stride, float *scratch, rrv_render_stats *stats, rrv_error *err)
{
    int w = x1 - x0, h = y1 - y0, mid, x, y, c;
    rrv_result result;
    if (b - a == 1) return rrv_render_rect(scene, x0, y0, x1, y1, a, b, out, stride, stats, err);
    mid = sample_split(a, b);
    result = sum_samples(scene, x0, y0, x1, y1, a, mid, out, stride, scratch + 3 * TILE_SIZE * TILE_SIZE, stats, err);
    if (result != RRV_OK) return result;
    memset(scratch, 0, (size_t)w * (size_t)h * 3 * sizeof *scratch);
    result = sum_samples(scene, x0, y0, x1, y1, mid, b, scratch, w, scratch + 3 * TILE_SIZE * TILE_SIZE, stats, err);
    if (result != RRV_OK) return result;
    for (y = 0; y < h; ++y)
        for (x = 0; x < w; ++x)
            for (c = 0; c < 3; ++c) {
                float *o = out + 3 * ((size_t)y * (size_t)stride + (size_t)x) + c;
                *o = add_saturated(*o, scratch[3 * ((size_t)y * (size_t)w + (size_t)x) + c]);
            }
    return RRV_OK;
}

static void *render_worker(void *arg)
{
    render_job *job = (render_job *)arg;
    rrv_render_stats stats;
    float *scratch = (float *)malloc((size_t)sample_tree_depth(job->sample_end - job->sample_begin) * 3 *
                                     TILE_SIZE * TILE_SIZE * sizeof *scratch);
    memset(&stats, 0, sizeof stats);
    if (!scratch) {
        job_lock(job);
        if (job->failure == RRV_OK) job->failure = RRV_ERROR_MEMORY;
        job_unlock(job);
        return NULL;
    }
    for (;;) {
        int tile, tx0, ty0, tx1, ty1;
        double started;
        rrv_result result;
        rrv_error err;
        job_lock(job);
        tile = job->failure == RRV_OK ? job->next_tile++ : job->tile_count;
        job_unlock(job);
        if (tile >= job->tile_count) break;
        tile = tile_for_turn(tile, job->tile_count, job->tile_stride);

        tx0 = job->x0 + (tile % job->tiles_x) * TILE_SIZE;
        ty0 = job->y0 + (tile / job->tiles_x) * TILE_SIZE;
        tx1 = tx0 + TILE_SIZE < job->x1 ? tx0 + TILE_SIZE : job->x1;
        ty1 = ty0 + TILE_SIZE < job->y1 ? ty0 + TILE_SIZE : job->y1;
        started = job->tile_seconds ? seconds_now() : 0;
        if (job->noise_threshold > 0)
            result = rrv_render_rect_adaptive(
                job->scene, tx0, ty0, tx1, ty1, job->sample_end, job->noise_threshold,
                job->sum + 3 * ((size_t)(ty0 - job->y0) * job->stride + (size_t)(tx0 - job->x0)), job->stride,
                job->counts + (size_t)(ty0 - job->y0) * job->stride + (size_t)(tx0 - job->x0), &stats, &err);
        else
            result = sum_samples(job->scene, tx0, ty0, tx1, ty1, job->sample_begin, job->sample_end,
                                 job->sum + 3 * ((size_t)(ty0 - job->y0) * job->stride + (size_t)(tx0 - job->x0)),
                                 job->stride, scratch, &stats, &err);

        job_lock(job);
        if (result != RRV_OK) {
            if (job->failure == RRV_OK) {
                job->failure = result;
                job->failure_error = err;
            }
        } else {
            if (job->tile_seconds) job->tile_seconds[tile] = seconds_now() - started;
            job->tiles_done++;
            draw_progress(job, 0);
        }
        job_unlock(job);
    }
    free(scratch);
    job_lock(job);
    add_stats(&job->stats, &stats);
    job_unlock(job);
    return NULL;
}

static void run_render_job(render_job *job, int thread_count)
{
#if RRV_THREADS
    pthread_t *threads = NULL;
    int started = 0, i;
    if (thread_count > 1) {
        job->use_lock = pthread_mutex_init(&job->lock, NULL) == 0;
        if (job->use_lock) threads = (pthread_t *)malloc((size_t)(thread_count - 1) * sizeof *threads);
    }
    /* Fewer threads than asked (no memory, no lock, a failed create) is still
       a correct render, only a slower one. */
    if (threads) {
        for (i = 0; i < thread_count - 1; ++i) {
            if (pthread_create(&threads[started], NULL, render_worker, job) != 0) break;
            ++started;
        }
    }
    render_worker(job);
    for (i = 0; i < started; ++i) pthread_join(threads[i], NULL);
    free(threads);
    if (job->use_lock) pthread_mutex_destroy(&job->lock);
    job->use_lock = 0;
#else
    (void)thread_count;
    render_worker(job);
#endif
}

static int default_thread_count(void)
{
    long cpus = sysconf(_SC_NPROCESSORS_ONLN);
    if (cpus < 1) return 1;
    return cpus > MAX_THREADS ? MAX_THREADS : (int)cpus;
}

/* ---- refraction settings shared by render and trace ------------------------- */

typedef struct refraction_options {
    double bend_tolerance, mu_eta, step;
    int has_bend_tolerance, has_mu_eta, has_step;
    int refraction, has_refraction; /* rrv_refraction_scheme */
    int stepper, has_stepper;       /* rrv_stepper */
    int majorant_cells, has_majorant_cells;
    int ior_cubic, has_ior_interp;
} refraction_options;

static const char refraction_help[] =
    "  --refraction NAME      refractive scheme: comb (default) or poisson (the\n"
    "                         seed paper: at null events)\n"
    "  --bend-tolerance RAD   refractive: bending per refraction event, which\n"
    "                         sets the event rate (default: the scene's, 0.01)\n"
    "  --mu-eta RATE          refractive: a fixed refraction event rate, 1/m\n"
    "                         (0: automatic from the tolerance)\n"
    "  --step H               eikonal: step length in metres (default 0.01)\n"
    "  --stepper NAME         eikonal: rk4 (the default; leapfrog and the scheme\n"
    "                         midpoint only in a build with RRV_RESEARCH)\n"
    "  --majorant-cells N     majorant grid cells per axis, 1 = one global\n"
    "                         majorant (default: automatic)\n"
    "  --ior-interp NAME      IOR grids: trilinear (default) or cubic (C2\n"
    "                         B-spline: second-order comb on grids, ~1.4x/kick)\n";

/* Takes one refraction option at the cursor; 1 taken, 0 not ours, -1 error. */
static int take_refraction_option(arg_cursor *args, refraction_options *opt)
{
    static const char *const schemes[] = {"default", "poisson", "midpoint", "comb"};
    static const char *const steppers[] = {"default", "leapfrog", "rk4"};
    const char *arg = args->argv[args->index], *text;
    int i;
    if (strcmp(arg, "--bend-tolerance") == 0) {
        if (!take_double(args, arg, "an angle in [1e-4, 1] radians", &opt->bend_tolerance)) return -1;
        if (!(opt->bend_tolerance >= 1e-4 && opt->bend_tolerance <= 1))
            return usage_error(args, "--bend-tolerance must be in [1e-4, 1], got %g", opt->bend_tolerance), -1;
        opt->has_bend_tolerance = 1;
    } else if (strcmp(arg, "--mu-eta") == 0) {
        if (!take_double(args, arg, "a rate >= 0 per metre", &opt->mu_eta)) return -1;
        if (!(opt->mu_eta >= 0 && opt->mu_eta <= 1e6))
            return usage_error(args, "--mu-eta must be in [0, 1e6], got %g", opt->mu_eta), -1;
        opt->has_mu_eta = 1;
    } else if (strcmp(arg, "--step") == 0) {
        if (!take_double(args, arg, "a length > 0 in metres", &opt->step)) return -1;
        if (!(opt->step >= 1e-6 && opt->step <= 1e6))
            return usage_error(args, "--step must be in [1e-6, 1e6] metres, got %g", opt->step), -1;
        opt->has_step = 1;
    } else if (strcmp(arg, "--majorant-cells") == 0) {
        if (!take_int(args, arg, 1, 256, "an integer in [1, 256]", &opt->majorant_cells)) return -1;
        opt->has_majorant_cells = 1;
    } else if (strcmp(arg, "--ior-interp") == 0) {
        if (!take_value(args, arg, "trilinear or cubic", &text)) return -1;
        if (strcmp(text, "trilinear") != 0 && strcmp(text, "cubic") != 0)
            return usage_error(args, "--ior-interp needs trilinear or cubic, got \"%s\"", text), -1;
        opt->ior_cubic = text[0] == 'c';
        opt->has_ior_interp = 1;
    } else if (strcmp(arg, "--refraction") == 0 || strcmp(arg, "--stepper") == 0) {
        int is_scheme = arg[2] == 'r';
        const char *const *names = is_scheme ? schemes : steppers;
        int count = is_scheme ? 4 : 3;
        if (!take_value(args, arg, is_scheme ? "comb, poisson or midpoint" : "rk4 or leapfrog", &text)) return -1;
        for (i = 0; i < count; ++i)
            if (strcmp(text, names[i]) == 0) break;
        if (i == count)
            return usage_error(args, "%s needs %s, got \"%s\"", arg,
                               is_scheme ? "comb, poisson or midpoint" : "rk4 or leapfrog", text), -1;
#ifndef RRV_RESEARCH
        /* refused here, before any output is opened, as the library would */
        if (i == (is_scheme ? RRV_REFRACTION_MIDPOINT : RRV_STEPPER_LEAPFROG))
            return usage_error(args, "%s %s is a research variant, not in this build (define RRV_RESEARCH); use %s",
                               arg, text, is_scheme ? "comb or poisson" : "rk4"), -1;
#endif
        if (is_scheme) { opt->refraction = i; opt->has_refraction = 1; }
        else { opt->stepper = i; opt->has_stepper = 1; }
    } else {
        return 0;
    }
    return 1;
}

/* Applies the options; the majorant grid is rebuilt when its size changed. */
static int apply_refraction_options(rrv_scene *scene, const refraction_options *opt)
{
    rrv_error err;
    if (opt->has_bend_tolerance) scene->settings.bend_tolerance = opt->bend_tolerance;
    if (opt->has_mu_eta) scene->settings.mu_eta = opt->mu_eta;
    if (opt->has_step) scene->settings.step = opt->step;
    if (opt->has_refraction) scene->settings.refraction = (rrv_refraction_scheme)opt->refraction;
    if (opt->has_stepper) scene->settings.stepper = (rrv_stepper)opt->stepper;
    if (opt->has_ior_interp)
        scene->settings.ior_interpolation = opt->ior_cubic ? RRV_IOR_INTERP_CUBIC : RRV_IOR_INTERP_TRILINEAR;
    if (opt->has_majorant_cells || opt->has_ior_interp) {
        if (opt->has_majorant_cells) scene->settings.majorant_cells = opt->majorant_cells;
        memset(&err, 0, sizeof err);
        if (rrv_scene_prepare(scene, &err) != RRV_OK) {
            print_library_error(&err);
            return 0;
        }
    }
    return 1;
}

/* ---- parts: partial renders for a farm ------------------------------------------
   A part is a float OpenEXR file whose data window is its rectangle in the
   display window of the full image and whose pixels are the tree sums (not
   means) of a block of samples; an "rrvPart" string attribute says what it
   holds, in the lines PART_FORMAT prints. */

#define PART_ATTRIBUTE "rrvPart"
#define PART_FORMAT "rrv part 1\nhash %s\nimage %d %d\ntile %s\nrect %d %d %d %d\nsamples %d %d\nspp %d\n"

typedef struct part_info {
    char hash[17], tile[32];
    int width, height, rect[4]; /* rect: x0 y0 x1 y1 */
    int sample_begin, sample_end, spp;
} part_info;

static int format_part(const part_info *part, char *text, size_t size)
{
    return snprintf(text, size, PART_FORMAT, part->hash, part->width, part->height, part->tile, part->rect[0],
                    part->rect[1], part->rect[2], part->rect[3], part->sample_begin, part->sample_end,
                    part->spp) < (int)size;
}

/* Parses an attribute value; only the exact form format_part writes. */
static int parse_part(const char *value, size_t size, part_info *part)
{
    char text[1024], again[1024];
    if (size == 0 || size >= sizeof text || memchr(value, '\0', size)) return 0;
    memcpy(text, value, size);
    text[size] = '\0';
    memset(part, 0, sizeof *part);
    if (sscanf(text, "rrv part 1\nhash %16s\nimage %d %d\ntile %31s\nrect %d %d %d %d\nsamples %d %d\nspp %d",
               part->hash, &part->width, &part->height, part->tile, &part->rect[0], &part->rect[1],
               &part->rect[2], &part->rect[3], &part->sample_begin, &part->sample_end, &part->spp) != 11)
        return 0;
    if (!format_part(part, again, sizeof again) || strcmp(again, text) != 0) return 0;
    return part->width > 0 && part->height > 0 && part->rect[0] >= 0 && part->rect[1] >= 0 &&
           part->rect[0] < part->rect[2] && part->rect[1] < part->rect[3] && part->rect[2] <= part->width &&
           part->rect[3] <= part->height && sample_block_ok(part->sample_begin, part->sample_end, part->spp);
}

/* "I/N" (band I of N bands of rows, columns 1) or "I/CxR" (tile I of a C by
   R grid, row by row from the top left). */
static int parse_tile(const char *text, int *index, int *columns, int *rows)
{
    long i, a, b = 1;
    int grid = 0;
    char *end;
    if (!isdigit((unsigned char)text[0])) return 0;
    errno = 0;
    i = strtol(text, &end, 10);
    if (*end != '/' || !isdigit((unsigned char)end[1])) return 0;
    a = strtol(end + 1, &end, 10);
    if (*end == 'x') {
        if (!isdigit((unsigned char)end[1])) return 0;
        b = strtol(end + 1, &end, 10);
        grid = 1;
    }
    /* Each count at most 65536, so their product fits a long long; "1x0"
       is no grid (it was once read as one band). */
    if (*end || errno || a < 1 || a > 65536 || b < 1 || b > 65536 || (long long)a * b <= i ||
        i > INT_MAX)
        return 0;
    *index = (int)i;
    *columns = grid ? (int)a : 1;
    *rows = grid ? (int)b : (int)a;
    return 1;
}

static int parse_range(const char *text, int *a, int *b)
{
    long lo, hi;
    char *end;
    if (!isdigit((unsigned char)text[0])) return 0;
    errno = 0;
    lo = strtol(text, &end, 10);
    if (*end != ':' || !isdigit((unsigned char)end[1])) return 0;
    hi = strtol(end + 1, &end, 10);
    if (*end || errno || lo >= hi || hi > (1L << 24)) return 0;
    *a = (int)lo;
    *b = (int)hi;
    return 1;
}

/* Tile index of a columns x rows grid: column and row bounds split the
   image as evenly as integers allow (floor(k * size / count)). */
static void tile_rect(int index, int columns, int rows, int width, int height, int rect[4])
{
    int cx = index % columns, cy = index / columns;
    rect[0] = (int)((long long)cx * width / columns);
    rect[2] = (int)((long long)(cx + 1) * width / columns);
    rect[1] = (int)((long long)cy * height / rows);
    rect[3] = (int)((long long)(cy + 1) * height / rows);
}

typedef struct hasher { uint64_t h; } hasher;
static void hash_bytes(hasher *hs, const void *data, size_t size)
{
    const unsigned char *p = (const unsigned char *)data;
    size_t i;
    for (i = 0; i < size; ++i) hs->h = (hs->h ^ p[i]) * 0x100000001b3ULL; /* FNV-1a */
}

/* A hash of what decides the pixels: every file the scene read (by content,
   so machines may mount it at other paths), the settings after the command
   line's overrides, and rrv's version. 0 when a file cannot be read. */
static int scene_hash(const input_list *inputs, const rrv_scene *scene, char out[17])
{
    hasher hs;
    char text[512];
    unsigned char buf[65536];
    const rrv_settings *st = &scene->settings;
    int i;
    hs.h = 0xcbf29ce484222325ULL;
    for (i = 0; i < inputs->count; ++i) {
        FILE *f;
        size_t n;
        uint64_t total = 0;
        rrv_error err;
        if (rrv_open_read(inputs->paths[i], &f, NULL, &err) != RRV_OK) return 0;
        while ((n = fread(buf, 1, sizeof buf, f)) > 0) {
            hash_bytes(&hs, buf, n);
            total += n;
        }
        if (ferror(f)) {
            fclose(f);
            return 0;
        }
        fclose(f);
        snprintf(text, sizeof text, "|file %d: %" PRIu64 " bytes|", i, total);
        hash_bytes(&hs, text, strlen(text));
    }
    /* Every field of rrv_settings, not only those the command line sets
       today: a field left out lets parts of different renders merge (the
       sampler once was). All but noise_threshold, which is 0 in every
       part (render refuses a part with one) and so tells none apart. */
    snprintf(text, sizeof text,
             "rrv %d.%d.%d spp %d depth %d seed %" PRIu64 " integrator %d nee %d bend %.17g mu_eta %.17g "
             "step %.17g refraction %d stepper %d ambient %.17g majorant %d ior %d bake %d gauge %d trials %d "
             "drop %.17g sampler %d emission %d solver %d transmittance %d equiangular %d lights %d",
             RRV_VERSION_MAJOR, RRV_VERSION_MINOR, RRV_VERSION_PATCH, st->spp, st->max_depth, (uint64_t)st->seed,
             (int)st->integrator, (int)st->nee, st->bend_tolerance, st->mu_eta, st->step, (int)st->refraction,
             (int)st->stepper, st->ambient_ior, st->majorant_cells, (int)st->ior_interpolation,
             st->max_bake_samples, (int)st->manifold_gauge, st->manifold_trials, st->manifold_drop,
             /* the default is sobol: parts that name it and parts that do not agree */
             (int)(st->sampler == RRV_SAMPLER_DEFAULT ? RRV_SAMPLER_SOBOL : st->sampler), (int)st->emission_nee,
             (int)st->manifold_solver, (int)st->transmittance, (int)st->equiangular, (int)st->light_sampler);
    hash_bytes(&hs, text, strlen(text));
    snprintf(out, 17, "%016" PRIx64, hs.h);
    return 1;
}

/* An OpenEXR part is at most what rrv_read_exr reads: 2 GiB. */
#define PART_FILE_MAX ((uint64_t)1 << 31)

/* Reads a part file whole: opened as the library opens every input (a
   regular file only, never blocking on a FIFO), refused by its size before
   anything is allocated, its first 8 bytes alone when they are no OpenEXR
   magic (the reader then says so), and never more than the size it had
   when opened. NULL with the reason in why. */
static unsigned char *slurp(const char *path, size_t *size, char *why, size_t why_size)
{
    static const unsigned char magic[4] = {0x76, 0x2f, 0x31, 0x01};
    unsigned char *data;
    uint64_t bytes;
    size_t have;
    rrv_error err;
    FILE *f;
    if (rrv_open_read(path, &f, &bytes, &err) != RRV_OK) {
        snprintf(why, why_size, "%s", err.message);
        return NULL;
    }
    if (bytes == UINT64_MAX || bytes > PART_FILE_MAX) {
        fclose(f);
        snprintf(why, why_size, bytes == UINT64_MAX ? "cannot tell its size" : "larger than %" PRIu64 " bytes",
                 PART_FILE_MAX);
        return NULL;
    }
    data = (unsigned char *)malloc(bytes > 8 ? (size_t)bytes : 8);
    if (!data) {
        fclose(f);
        snprintf(why, why_size, "out of memory for %" PRIu64 " bytes", bytes);
        return NULL;
    }
    have = fread(data, 1, bytes < 8 ? (size_t)bytes : 8, f);
    if (have == 8 && memcmp(data, magic, 4) == 0) have += fread(data + 8, 1, (size_t)bytes - 8, f);
    if (ferror(f)) {
        snprintf(why, why_size, "%s", strerror(errno));
        free(data);
        fclose(f);
        return NULL;
    }
    fclose(f);
    *size = have;
    return data;
}

/* Loads a part: its description and (if sums is not NULL) its pixel sums.
   Prints the problem (naming the file) and returns 0 when it is no part. */
static int load_part(const char *path, part_info *part, float **sums, const char *command)
{
    size_t size = 0, value_size;
    char why[sizeof ((rrv_error *)0)->message];
    unsigned char *data = slurp(path, &size, why, sizeof why);
    const char *type;
    const void *value;
    float *rgb = NULL;
    int w, h, ok = 0;
    rrv_exr_options info;
    rrv_error err;
    if (sums) *sums = NULL;
    if (!data) {
        fprintf(stderr, "rrv: %s: \"%s\": cannot read: %s\n", command, path, why);
        return 0;
    }
    memset(&err, 0, sizeof err);
    memset(&info, 0, sizeof info);
    if (rrv_read_exr_memory(data, size, path, &rgb, &w, &h, &info, &err) != RRV_OK) {
        fprintf(stderr, "rrv: %s: \"%s\": not a complete OpenEXR part: %s\n", command, path,
                err.message[0] ? err.message : rrv_result_string(err.code));
    } else if (rrv_exr_find_attribute(data, size, PART_ATTRIBUTE, &type, &value, &value_size) != RRV_OK) {
        fprintf(stderr, "rrv: %s: \"%s\": not a part (no %s attribute): render parts with --tile or --samples\n",
                command, path, PART_ATTRIBUTE);
    } else if (strcmp(type, "string") != 0 || !parse_part((const char *)value, value_size, part) ||
               info.pixel != RRV_EXR_FLOAT || info.display_width != part->width ||
               info.display_height != part->height || info.x != part->rect[0] || info.y != part->rect[1] ||
               w != part->rect[2] - part->rect[0] || h != part->rect[3] - part->rect[1]) {
        fprintf(stderr, "rrv: %s: \"%s\": a damaged part: its %s attribute does not describe its pixels\n",
                command, path, PART_ATTRIBUTE);
    } else {
        ok = 1;
    }
    free(data);
    if (ok && sums) *sums = rgb;
    else rrv_free(rgb);
    return ok;
}

/* ---- rrv render ---------------------------------------------------------------- */

typedef struct render_options {
    const char *scene_path, *pfm_path, *png_path;
    int spp, has_spp;
    uint64_t seed;
    int has_seed;
    rrv_integrator integrator;
    int has_integrator;
    rrv_nee nee;
    int has_nee;
    rrv_sampler sampler;
    int has_sampler;
    rrv_transmittance transmittance;
    int has_transmittance;
    double noise_threshold;
    int has_noise_threshold;
    int threads;
    double exposure;
    int crop[4], has_crop;
    int tile_index, tile_columns, tile_rows, has_tile; /* --tile I/N (rows) or I/CxR */
    int sample_begin, sample_end, has_samples;         /* --samples A:B */
    int resume;
    size_t max_grid_bytes;
    int quiet;
    int output_format;      /* OUTPUT_PFM or OUTPUT_EXR, from the extension of -o */
    rrv_exr_options exr;
    const char *exr_flag;   /* the last --exr-* option given, for a PFM output's error */
    refraction_options refraction;
} render_options;

/* Whether path ends in ext, ignoring case (".EXR" is an EXR). */
static int has_extension(const char *path, const char *ext)
{
    size_t n = strlen(path), e = strlen(ext), i;
    if (n <= e) return 0;
    for (i = 0; i < e; ++i)
        if (tolower((unsigned char)path[n - e + i]) != ext[i]) return 0;
    return 1;
}

#if defined(RRV_NO_EXR) || defined(RRV_NO_PNG) || defined(RRV_NO_CURVED_NEE)
/* What the options ask of a part this build of the library leaves out
   (rrv.h, CONFIGURATION), said before a render rather than after it. */
static const char *left_out_of_build(const render_options *opt)
{
#ifdef RRV_NO_EXR
    if (opt->output_format == OUTPUT_EXR) return "OpenEXR output is disabled (RRV_NO_EXR): -o OUT.pfm";
#endif
#ifdef RRV_NO_PNG
    if (opt->png_path) return "PNG output is disabled (RRV_NO_PNG): drop --png";
#endif
#ifdef RRV_NO_CURVED_NEE
    if (opt->has_nee && (opt->nee == RRV_NEE_SHOOT || opt->nee == RRV_NEE_MANIFOLD))
        return "--nee shoot and manifold are disabled (RRV_NO_CURVED_NEE): --nee aim";
#endif
    (void)opt;
    return NULL;
}
#endif

static int parse_render_options(int argc, char **argv, render_options *opt)
{
    arg_cursor args;
    int taken;
    args.argc = argc;
    args.argv = argv;
    args.command = "render";
    memset(opt, 0, sizeof *opt);
    for (args.index = 0; args.index < argc; ++args.index) {
        const char *arg = argv[args.index];
        if (is_help_flag(arg)) {
            printf(render_help, refraction_help);
            return HELP_SHOWN;
        } else if (strcmp(arg, "-o") == 0 || strcmp(arg, "--output") == 0) {
            if (!take_value(&args, arg, "an output path", &opt->pfm_path)) return EXIT_USAGE;
        } else if (strcmp(arg, "--png") == 0) {
            if (!take_value(&args, arg, "an output path", &opt->png_path)) return EXIT_USAGE;
        } else if (strcmp(arg, "--exr-half") == 0 || strcmp(arg, "--exr-float") == 0) {
            opt->exr.pixel = arg[6] == 'f' ? RRV_EXR_FLOAT : RRV_EXR_HALF;
            opt->exr_flag = arg;
        } else if (strcmp(arg, "--exr-compression") == 0) {
            const char *text;
            if (!take_value(&args, arg, "zip or none", &text)) return EXIT_USAGE;
            if (strcmp(text, "zip") == 0) opt->exr.compression = RRV_EXR_ZIP;
            else if (strcmp(text, "none") == 0) opt->exr.compression = RRV_EXR_NO_COMPRESSION;
            else return usage_error(&args, "--exr-compression needs zip or none, got \"%s\"", text);
            opt->exr_flag = arg;
        } else if (strcmp(arg, "--spp") == 0) {
            if (!take_int(&args, arg, 1, 1L << 24, "a positive integer",
                          &opt->spp))
                return EXIT_USAGE;
            opt->has_spp = 1;
        } else if (strcmp(arg, "--seed") == 0) {
            if (!take_u64(&args, arg, "an integer >= 0", &opt->seed)) return EXIT_USAGE;
            opt->has_seed = 1;
        } else if (strcmp(arg, "--integrator") == 0) {
            if (!take_integrator(&args, 1, &opt->integrator)) return EXIT_USAGE;
            opt->has_integrator = 1;
        } else if (strcmp(arg, "--nee") == 0) {
            const char *mode;
            if (!take_value(&args, arg, "none, straight, shoot, manifold or aim", &mode)) return EXIT_USAGE;
            if (strcmp(mode, "none") == 0) opt->nee = RRV_NEE_NONE;
            else if (strcmp(mode, "straight") == 0) opt->nee = RRV_NEE_STRAIGHT;
            else if (strcmp(mode, "shoot") == 0) opt->nee = RRV_NEE_SHOOT;
            else if (strcmp(mode, "manifold") == 0) opt->nee = RRV_NEE_MANIFOLD;
            else if (strcmp(mode, "aim") == 0) opt->nee = RRV_NEE_AIM;
            else return usage_error(&args, "--nee needs none, straight, shoot, manifold or aim, got \"%s\"", mode);
            opt->has_nee = 1;
        } else if (strcmp(arg, "--sampler") == 0) {
            const char *name;
            if (!take_value(&args, arg, "pcg or sobol", &name)) return EXIT_USAGE;
            if (strcmp(name, "pcg") == 0) opt->sampler = RRV_SAMPLER_PCG;
            else if (strcmp(name, "sobol") == 0) opt->sampler = RRV_SAMPLER_SOBOL;
            else return usage_error(&args, "--sampler needs pcg or sobol, got \"%s\"", name);
            opt->has_sampler = 1;
        } else if (strcmp(arg, "--transmittance") == 0) {
            const char *name;
            if (!take_value(&args, arg, "ratio, residual or march", &name)) return EXIT_USAGE;
            if (strcmp(name, "ratio") == 0) opt->transmittance = RRV_TRANSMITTANCE_RATIO;
            else if (strcmp(name, "residual") == 0) opt->transmittance = RRV_TRANSMITTANCE_RESIDUAL;
            else if (strcmp(name, "march") == 0) opt->transmittance = RRV_TRANSMITTANCE_MARCH;
            else return usage_error(&args, "--transmittance needs ratio, residual or march, got \"%s\"", name);
            opt->has_transmittance = 1;
        } else if (strcmp(arg, "--noise-threshold") == 0) {
            if (!take_double(&args, arg, "a relative error >= 0 (0: off)", &opt->noise_threshold)) return EXIT_USAGE;
            if (!(opt->noise_threshold >= 0 && opt->noise_threshold <= 1e6))
                return usage_error(&args, "--noise-threshold needs a relative error in [0, 1e6] (0: off), got %g",
                                   opt->noise_threshold);
            opt->has_noise_threshold = 1;
        } else if (strcmp(arg, "--threads") == 0) {
            if (!take_int(&args, arg, 1, MAX_THREADS, "a positive integer",
                          &opt->threads))
                return EXIT_USAGE;
        } else if (strcmp(arg, "--exposure") == 0) {
            if (!take_double(&args, arg, "a number", &opt->exposure)) return EXIT_USAGE;
        } else if (strcmp(arg, "--crop") == 0) {
            int i;
            for (i = 0; i < 4; ++i)
                if (!take_int(&args, arg, 0, INT_MAX, "four pixel coordinates X0 Y0 X1 Y1",
                              &opt->crop[i]))
                    return EXIT_USAGE;
            opt->has_crop = 1;
        } else if (strcmp(arg, "--tile") == 0) {
            const char *text;
            if (!take_value(&args, arg, "I/N or I/CxR", &text)) return EXIT_USAGE;
            if (!parse_tile(text, &opt->tile_index, &opt->tile_columns, &opt->tile_rows))
                return usage_error(&args, "--tile needs I/N (tile I of N bands of rows) or I/CxR (tile I of a "
                                   "C by R grid), 0 <= I < N, got \"%s\"", text);
            opt->has_tile = 1;
        } else if (strcmp(arg, "--samples") == 0) {
            const char *text;
            if (!take_value(&args, arg, "A:B", &text)) return EXIT_USAGE;
            if (!parse_range(text, &opt->sample_begin, &opt->sample_end))
                return usage_error(&args, "--samples needs A:B, sample indices 0 <= A < B, got \"%s\"", text);
            opt->has_samples = 1;
        } else if (strcmp(arg, "--resume") == 0) {
            opt->resume = 1;
        } else if (strcmp(arg, "--max-grid-mb") == 0) {
            if (!take_grid_limit(&args, &opt->max_grid_bytes)) return EXIT_USAGE;
        } else if (strcmp(arg, "-q") == 0 || strcmp(arg, "--quiet") == 0) {
            opt->quiet = 1;
        } else if ((taken = take_refraction_option(&args, &opt->refraction)) != 0) {
            if (taken < 0) return EXIT_USAGE;
        } else if (is_flag(arg)) {
            char hint[80];
            return usage_error(&args, "render: unknown option \"%s\"%s", arg,
                               flag_hint(arg, render_help, refraction_help, hint));
        } else if (opt->scene_path) {
            return usage_error(&args, "render: unexpected argument \"%s\"", arg);
        } else {
            opt->scene_path = arg;
        }
    }
    args.index = argc;
    if (!opt->scene_path) return usage_error(&args, "render needs a scene file");
    if (!opt->pfm_path) return usage_error(&args, "render needs an output file: -o OUT.pfm");
    /* An unknown extension is refused in command_render, after the checks
       that say more (the output is a folder, or one of the scene's inputs). */
    opt->output_format = has_extension(opt->pfm_path, ".exr")   ? OUTPUT_EXR
                         : has_extension(opt->pfm_path, ".pfm") ? OUTPUT_PFM
                                                                : -1;
    if (opt->exr_flag && opt->output_format != OUTPUT_EXR)
        return usage_error(&args, "%s needs an .exr output, not \"%s\"", opt->exr_flag, opt->pfm_path);
#if defined(RRV_NO_EXR) || defined(RRV_NO_PNG) || defined(RRV_NO_CURVED_NEE)
    if (left_out_of_build(opt)) return usage_error(&args, "%s", left_out_of_build(opt));
#endif
    if (opt->has_tile || opt->has_samples) {
        if (opt->output_format != OUTPUT_EXR)
            return usage_error(&args, "a part (--tile, --samples) is an OpenEXR file: -o PART.exr, not \"%s\"",
                               opt->pfm_path);
        if (opt->has_crop) return usage_error(&args, "--crop cannot be combined with --tile or --samples");
        if (opt->noise_threshold > 0)
            return usage_error(&args, "--noise-threshold cannot be combined with %s: a part holds sums of one "
                               "sample count, an adaptive pixel its own", opt->has_samples ? "--samples" : "--tile");
        if (opt->png_path) return usage_error(&args, "--png cannot be combined with --tile or --samples: "
                                              "preview the merged image");
        if (opt->exr_flag && strcmp(opt->exr_flag, "--exr-half") == 0)
            return usage_error(&args, "a part holds float sums: --exr-half cannot be combined with --tile or --samples");
        /* Sums must survive exactly: float, whatever the default. */
        opt->exr.pixel = RRV_EXR_FLOAT;
    } else if (opt->resume) {
        return usage_error(&args, "--resume needs --tile or --samples");
    }
    return EXIT_OK;
}

static const char *const face_names[7] = {"-x", "+x", "-y", "+y", "-z", "+z", "sphere"};

/* Where the light samples go (LIGHT SAMPLING in rrv.h's manual): each
   light shape's share and the sky's, from the running sums the power
   sampler picks by (every choice alike under uniform), and the emissive
   media's where they share the draw. */
static void print_light_samples(const rrv_scene *scene)
{
    static const char *const kinds[] = {"sphere", "quad", "triangle"};
    int choices = scene->light_count + (scene->environment.kind != RRV_ENV_NONE ? 1 : 0), i;
    int uniform = !scene->light_power;
    double total = !uniform && scene->light_cdf ? scene->light_cdf[choices - 1] : 0;
    if (!uniform && !scene->light_count && scene->emitters && scene->sky_weight == 0) {
        /* no light shape: the emissive media take the samples, the sky none */
        printf("light samples (power): the emissive media 100 %%%s\n",
               choices ? ", sky 0 % (its light left to the paths' own directions)" : "");
        return;
    }
    if (!choices || (!uniform && !(total > 0))) return;
    printf("light samples (%s):", uniform ? "uniform" : "power");
    /* beside light shapes the emissive media take a share of the same draw:
       by power, or under classic at each vertex by power over squared
       distance (the scene's share by power then only guides the eye) */
    if (scene->emit_share > 0)
        printf(" the emissive media %.3g %%%s,", 100 * scene->emit_share,
               rrv_scene_integrator(scene) == RRV_INTEGRATOR_CLASSIC ? " by power (a vertex's share: by power over "
                                                                       "squared distance)"
                                                                     : "");
    for (i = 0; i < choices; ++i) {
        double p = uniform ? 1.0 / choices
                           : (1.0 - scene->emit_share) *
                                 (scene->light_cdf[i] - (i ? scene->light_cdf[i - 1] : 0.0)) / total;
        if (i < scene->light_count) {
            int kind = (int)scene->shapes[scene->lights[i]].kind;
            printf("%s shape %d (%s) %.3g %%", i ? "," : "", scene->lights[i],
                   kind >= 0 && kind < 3 ? kinds[kind] : "shape", 100 * p);
        } else {
            printf("%s sky %.3g %%%s", i ? "," : "", 100 * p,
                   p > 0 ? "" : " (its light left to the paths' own directions)");
        }
    }
    if (scene->emitters && scene->settings.emission_nee == RRV_EMISSION_NEE_ON)
        printf("; the emissive media a draw of their own");
    printf("\n");
}

/* The largest IOR jump over every medium's faces, its medium and face, and
   how many faces jump: a sharp interface (glass) the user may not have meant. */
static double largest_face_jump(const rrv_scene *scene, int *medium, int *face, int *faces)
{
    double worst = 0, jump[7];
    int i, f;
    *medium = *face = -1;
    *faces = 0;
    for (i = 0; i < scene->medium_count; ++i) {
        rrv_medium_face_jumps(scene, i, jump);
        for (f = 0; f < 7; ++f) {
            if (jump[f] <= 0) continue;
            ++*faces;
            if (jump[f] > worst) {
                worst = jump[f];
                *medium = i;
                *face = f;
            }
        }
    }
    return worst;
}

static void print_face_jump_summary(const rrv_scene *scene)
{
    int medium, face, faces;
    double jump = largest_face_jump(scene, &medium, &face, &faces);
    if (!(jump > 0)) return;
    fprintf(stderr, "sharp IOR faces: eta jumps by %.3g at the %s %s of medium \"%s\"", jump, face_names[face],
            face == 6 ? "surface" : "face", scene->media[medium].name);
    if (faces > 1) fprintf(stderr, " (and at %d more faces)", faces - 1);
    if (jump <= RRV_SMOOTH_JUMP)
        fputs(": refracted and reflected there as glass; curved nee takes a jump this small as smooth\n", stderr);
    else
        fputs(": refracted and reflected there as glass; nee shoot and aim refract there, manifold does not\n", stderr);
}

/* `rrv info`'s ambient IOR, and where an `ambient` statement set one that
   misses the first gas medium's own at its ambient state (what the
   ambient would be without the statement), that IOR too: a value rounded
   in the scene file (1.029 for 1.0292) makes glass of a plume's faces,
   which chains do not cross. */
static void print_ambient(const rrv_scene *scene)
{
    int i;
    printf("ambient ior: %.9g", scene->ambient_ior);
    if (scene->settings.ambient_ior == 0) {
        puts(scene->ambient_ior != 1 ? " (the gas at its ambient state)" : "");
        return;
    }
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double gas = 1.0 + (m->eta_ref - 1.0) * m->ior_scale;
        if (!m->ior_from_gas) continue;
        if (fabs(gas - scene->ambient_ior) > RRV_SMOOTH_JUMP)
            printf(" (set; the gas of medium \"%s\" at its ambient state is %.9g)", m->name, gas);
        break;
    }
    putchar('\n');
}

/* The light sampling a prepared scene renders with, as `nee` names it
   (the refractive integrator's shoot aims; the manifold's solver named). */
static const char *nee_label(const rrv_scene *scene)
{
    switch (rrv_scene_nee(scene)) {
    case RRV_NEE_NONE: return "none";
    case RRV_NEE_STRAIGHT: return "straight";
    case RRV_NEE_SHOOT: return rrv_scene_integrator(scene) == RRV_INTEGRATOR_REFRACTIVE ? "aim" : "shoot";
    case RRV_NEE_MANIFOLD:
        return scene->settings.manifold_solver == RRV_MANIFOLD_SOLVER_LM ? "manifold, Levenberg-Marquardt"
                                                                          : "manifold, dogleg";
    case RRV_NEE_AIM: return "aim";
    default: return "unknown";
    }
}

static void print_render_summary(int width, int height, int spp, double seconds, const char *nee,
                                 const rrv_render_stats *stats)
{
    char samples_rate[32], paths_rate[32];
    double rate_time = seconds > 1e-9 ? seconds : 1e-9;
    format_count((double)stats->samples / rate_time, samples_rate, sizeof samples_rate);
    format_count((double)stats->paths / rate_time, paths_rate, sizeof paths_rate);
    fprintf(stderr, "rendered %dx%d at %d spp in %.2f s: %s samples/s, %s paths/s", width,
            height, spp, seconds, samples_rate, paths_rate);
    if (stats->nonfinite > 0)
        fprintf(stderr, " (%" PRIu64 " non-finite samples discarded)", stats->nonfinite);
    /* A cut path is a biased sample: never leave it unsaid. */
    if (stats->paths_cut > 0)
        fprintf(stderr, " (%" PRIu64 " paths cut at a work bound, %" PRIu64 " of them in tracking, %" PRIu64
                " at the sample's)", stats->paths_cut, stats->cut_tracking, stats->cut_samples);
    if (stats->trapped_paths > 0) fprintf(stderr, " (%" PRIu64 " of them trapped in a refracting medium)", stats->trapped_paths);
    if (stats->solves > 0) {
        double n = (double)stats->solves, conv = (double)stats->solves_converged;
        fprintf(stderr, "; curved nee (%s): %" PRIu64 " solves, %.1f%% converged, %.1f iterations, %.2f solves a connection, "
                "%.0f segments a chain", nee, stats->solves, 100.0 * conv / n, (double)stats->solve_iterations / n,
                stats->solve_connections ? (double)stats->solve_trials / (double)stats->solve_connections : 0.0,
                conv > 0 ? (double)stats->solve_segments / conv : 0.0);
    }
    if (stats->aim_shots > 0)
        fprintf(stderr, "; aimed nee: %" PRIu64 " bent shadow rays, %.1f%% turned off their light", stats->aim_shots,
                100.0 * (double)stats->aim_missed / (double)stats->aim_shots);
    if (stats->cone_shots > 0)
        fprintf(stderr, "; %" PRIu64 " rays drawn toward strong refraction, %.2f%% landed on a light past a weak chord",
                stats->cone_shots, 100.0 * (double)stats->cone_counted / (double)stats->cone_shots);
    if (stats->solves_unsupported > 0)
        fprintf(stderr, "; %" PRIu64 " vertices had no curved nee (the poisson and midpoint schemes cannot aim, "
                "manifold needs an IOR with a known Hessian): their curved connections were left to forward paths",
                stats->solves_unsupported);
    fputc('\n', stderr);
}

/* What the steps of a command return to go on; every other value is the
   command's exit code. */
#define GO_ON (-2)

/* rrv render, step 1: the outputs checked, the scene loaded (and its input
   files listed) and the options applied. GO_ON with *scene, or the exit
   code with nothing left allocated. Output problems are found before a
   long load or render, except that only the load knows which files the
   scene reads. */
static int render_load(render_options *opt, const arg_cursor *args, input_list *inputs, rrv_scene **scene)
{
    int ok;
    memset(inputs, 0, sizeof *inputs);
    *scene = NULL;
    if (opt->png_path && same_file(opt->pfm_path, opt->png_path))
        return usage_error(args, "-o and --png name the same file \"%s\"", opt->png_path);
    if (!check_output(opt->pfm_path) || (opt->png_path && !check_output(opt->png_path)))
        return EXIT_IO;
    setup_progress.show = !opt->quiet && isatty(2);
    if (!load_scene(opt->scene_path, opt->max_grid_bytes, inputs, scene, opt->threads)) {
        free_inputs(inputs);
        *scene = NULL;
        return EXIT_INPUT;
    }
    ok = check_output_not_input(opt->pfm_path, inputs) &&
         (!opt->png_path || check_output_not_input(opt->png_path, inputs));
    if (ok && opt->output_format >= 0) {
        rrv_scene *s = *scene;
        if (opt->has_spp) s->settings.spp = opt->spp;
        if (opt->has_seed) s->settings.seed = opt->seed;
        if (opt->has_integrator) s->settings.integrator = opt->integrator;
        if (opt->has_nee) s->settings.nee = opt->nee;
        if (opt->has_sampler) s->settings.sampler = opt->sampler;
        if (opt->has_transmittance) s->settings.transmittance = opt->transmittance;
        if (opt->has_noise_threshold) s->settings.noise_threshold = opt->noise_threshold;
        if (apply_refraction_options(s, &opt->refraction)) return GO_ON;
    }
    free_inputs(inputs);
    rrv_scene_free(*scene);
    *scene = NULL;
    if (!ok) return EXIT_USAGE;
    if (opt->output_format < 0)
        return usage_error(args, "cannot tell the format of \"%s\": the output must end in .pfm or .exr",
                           opt->pfm_path);
    return EXIT_INPUT;
}

/* rrv render --resume: EXIT_OK when the output already is this very part
   (a re-submitted array renders only what is missing), else GO_ON. */
static int render_keep_part(const render_options *opt, const part_info *part)
{
    FILE *probe;
    rrv_error probe_err;
    part_info have;
    /* opened as every input is: the output check refused a FIFO there,
       and one put in its place since must not block */
    if (rrv_open_read(opt->pfm_path, &probe, NULL, &probe_err) != RRV_OK) return GO_ON;
    fclose(probe);
    if (load_part(opt->pfm_path, &have, NULL, "render --resume") && memcmp(&have, part, sizeof *part) == 0) {
        if (!opt->quiet)
            fprintf(stderr, "rrv: \"%s\" is complete (tile %s, samples %d:%d): kept\n", opt->pfm_path, part->tile,
                    part->sample_begin, part->sample_end);
        return EXIT_OK;
    }
    if (!opt->quiet) fprintf(stderr, "rrv: \"%s\" is not this part: rendering it again\n", opt->pfm_path);
    return GO_ON;
}

/* rrv render, step 2 for a part (--tile, --samples): its tile and sample
   block checked against the scene, described in *part and part_text, and
   its rectangle made the crop. GO_ON, or the exit code. */
static int render_plan_part(render_options *opt, const arg_cursor *args, input_list *inputs,
                            const rrv_scene *scene, part_info *part, char *part_text, size_t cap)
{
    int width = scene->camera.width, height = scene->camera.height, ok = scene_hash(inputs, scene, part->hash);
    free_inputs(inputs);
    if (!ok) {
        fprintf(stderr, "rrv: %s: cannot read the scene's files again to hash them: %s\n", opt->scene_path,
                strerror(errno));
        return EXIT_INPUT;
    }
    if (!opt->has_tile) {
        opt->tile_index = 0;
        opt->tile_columns = opt->tile_rows = 1;
    }
    if (opt->tile_columns > width || opt->tile_rows > height)
        return usage_error(args, "--tile %d/%dx%d: the %dx%d image has too few %s for that many tiles",
                           opt->tile_index, opt->tile_columns, opt->tile_rows, width, height,
                           opt->tile_columns > width ? "columns" : "rows");
    if (!opt->has_samples) {
        opt->sample_begin = 0;
        opt->sample_end = scene->settings.spp;
    }
    if (!sample_block_ok(opt->sample_begin, opt->sample_end, scene->settings.spp)) {
        int n = scene->settings.spp, m = sample_split(0, n);
        if (opt->sample_end > n)
            return usage_error(args, "--samples %d:%d: the render has only %d samples a pixel", opt->sample_begin,
                               opt->sample_end, n);
        return usage_error(args, "--samples %d:%d is not a block of the sample tree of %d samples "
                           "(0:%d splits into 0:%d and %d:%d, each block of more than one sample at its "
                           "start plus the largest power of two below its length)",
                           opt->sample_begin, opt->sample_end, n, n, m, m, n);
    }
    part->width = width;
    part->height = height;
    tile_rect(opt->tile_index, opt->tile_columns, opt->tile_rows, width, height, part->rect);
    if (opt->tile_columns == 1) snprintf(part->tile, sizeof part->tile, "%d/%d", opt->tile_index, opt->tile_rows);
    else snprintf(part->tile, sizeof part->tile, "%d/%dx%d", opt->tile_index, opt->tile_columns, opt->tile_rows);
    part->sample_begin = opt->sample_begin;
    part->sample_end = opt->sample_end;
    part->spp = scene->settings.spp;
    format_part(part, part_text, cap);
    if (opt->resume && render_keep_part(opt, part) == EXIT_OK) return EXIT_OK;
    memcpy(opt->crop, part->rect, sizeof opt->crop);
    return GO_ON;
}

/* rrv render, step 2 for an image: every sample, and the crop (the whole
   frame without --crop) checked. GO_ON, or the exit code. */
static int render_plan_image(render_options *opt, const arg_cursor *args, input_list *inputs,
                             const rrv_scene *scene)
{
    int width = scene->camera.width, height = scene->camera.height;
    free_inputs(inputs);
    opt->sample_begin = 0;
    opt->sample_end = scene->settings.spp;
    if (!opt->has_crop) {
        opt->crop[0] = opt->crop[1] = 0;
        opt->crop[2] = width;
        opt->crop[3] = height;
    } else if (opt->crop[0] >= opt->crop[2] || opt->crop[1] >= opt->crop[3] || opt->crop[2] > width ||
               opt->crop[3] > height) {
        return usage_error(args,
                           "--crop %d %d %d %d is not a nonempty rectangle inside the %dx%d "
                           "image (X0 < X1 <= %d, Y0 < Y1 <= %d)",
                           opt->crop[0], opt->crop[1], opt->crop[2], opt->crop[3], width, height, width,
                           height);
    }
    return GO_ON;
}

static int compare_ints(const void *pa, const void *pb)
{
    int a = *(const int *)pa, b = *(const int *)pb;
    return (a > b) - (a < b);
}

/* The minimum, median, maximum and mean of an adaptive render's sample
   counts (sorted in place: they are not needed afterwards). */
static void count_summary(int *counts, size_t n, render_job *job)
{
    size_t i;
    double total = 0;
    qsort(counts, n, sizeof *counts, compare_ints);
    for (i = 0; i < n; ++i) total += counts[i];
    job->spp_min = counts[0];
    job->spp_median = counts[n / 2];
    job->spp_max = counts[n - 1];
    job->spp_mean = total / (double)n;
}

/* rrv render, step 3: the crop's samples rendered on the threads into a
   new *image, the sums for a part, else their mean. GO_ON, or the exit
   code with *image NULL. */
static int render_run(const render_options *opt, const rrv_scene *scene, int is_part, render_job *job,
                      float **image, double *seconds)
{
    int crop_width = opt->crop[2] - opt->crop[0], crop_height = opt->crop[3] - opt->crop[1], x, y, c;
    int thread_count;
    size_t sum_count = (size_t)crop_width * (size_t)crop_height * 3;
    double threshold = is_part ? 0 : scene->settings.noise_threshold;
    float *sum = (float *)calloc(sum_count, sizeof *sum);
    int *counts = threshold > 0 ? (int *)malloc(sum_count / 3 * sizeof *counts) : NULL;
    *image = (float *)malloc(sum_count * sizeof **image);
    if (!sum || !*image || (threshold > 0 && !counts)) {
        fprintf(stderr, "rrv: out of memory for a %dx%d framebuffer\n", crop_width, crop_height);
        free(sum);
        free(counts);
        free(*image);
        *image = NULL;
        return EXIT_INPUT;
    }
    memset(job, 0, sizeof *job);
    job->noise_threshold = threshold;
    job->counts = counts;
    job->scene = scene;
    job->x0 = opt->crop[0];
    job->y0 = opt->crop[1];
    job->x1 = opt->crop[2];
    job->y1 = opt->crop[3];
    job->sample_begin = opt->sample_begin;
    job->sample_end = opt->sample_end;
    job->sum = sum;
    job->stride = crop_width;
    job->tiles_x = (crop_width + TILE_SIZE - 1) / TILE_SIZE;
    job->tile_count = job->tiles_x * ((crop_height + TILE_SIZE - 1) / TILE_SIZE);
    job->tile_stride = tile_stride(job->tiles_x, job->tile_count / job->tiles_x);
    job->failure = RRV_OK;
    job->failure_error.message[0] = '\0';
    setup_progress_clear(); /* a prepare again for the command line's options may have drawn */
    job->show_progress = !opt->quiet && isatty(2);
    if (job->show_progress) {
        job->tile_seconds = (double *)malloc((size_t)job->tile_count * sizeof *job->tile_seconds);
        for (x = 0; job->tile_seconds && x < job->tile_count; ++x) job->tile_seconds[x] = -1;
    }
    thread_count = opt->threads > 0 ? opt->threads : default_thread_count();
    if (thread_count > job->tile_count) thread_count = job->tile_count;

    job->start_time = seconds_now();
    job->last_progress_time = job->start_time;
    run_render_job(job, thread_count);
    *seconds = seconds_now() - job->start_time;
    if (job->show_progress) {
        draw_progress(job, 1);
        /* The summary line takes the bar's place. */
        fprintf(stderr, "\r%*s\r", PROGRESS_BAR_WIDTH + 48, "");
    }
    free(job->tile_seconds);
    job->tile_seconds = NULL;

    if (job->failure != RRV_OK) {
        fprintf(stderr, "rrv: %s: render failed: %s\n", opt->scene_path,
                job->failure_error.message[0] ? job->failure_error.message : rrv_result_string(job->failure));
        free(sum);
        free(counts);
        job->counts = NULL;
        free(*image);
        *image = NULL;
        return EXIT_INPUT;
    }
    /* A part keeps its sums; an image is their mean, an adaptive pixel's
       over its own count. */
    for (y = 0; y < crop_height; ++y)
        for (x = 0; x < crop_width; ++x)
            for (c = 0; c < 3; ++c) {
                size_t i = 3 * ((size_t)y * crop_width + x) + c;
                float n = counts ? (float)counts[i / 3] : (float)scene->settings.spp;
                (*image)[i] = is_part ? sum[i] : sum[i] / n;
            }
    free(sum);
    if (counts) {
        count_summary(counts, (size_t)crop_width * crop_height, job);
        free(counts);
        job->counts = NULL;
    }
    return GO_ON;
}

/* rrv render, step 4: the outputs written (a crop in its place in the
   frame, a part with its description) and the summary printed. */
static int render_write(render_options *opt, const rrv_scene *scene, const part_info *part,
                        const char *part_text, const float *image, const render_job *job, double seconds)
{
    pending_output outputs[2];
    int is_part = opt->has_tile || opt->has_samples, code;
    int crop_width = opt->crop[2] - opt->crop[0], crop_height = opt->crop[3] - opt->crop[1];
    memset(outputs, 0, sizeof outputs);
    outputs[0].path = opt->pfm_path;
    outputs[0].format = opt->output_format;
    outputs[0].exr = &opt->exr;
    outputs[1].path = opt->png_path;
    outputs[1].format = OUTPUT_PNG;
    opt->exr.display_width = scene->camera.width;
    opt->exr.display_height = scene->camera.height;
    opt->exr.x = opt->crop[0];
    opt->exr.y = opt->crop[1];
    if (is_part) {
        opt->exr.text_name = PART_ATTRIBUTE;
        opt->exr.text = part_text;
    }
    code = write_outputs(outputs, opt->png_path ? 2 : 1, image, crop_width, crop_height, opt->exposure) ? EXIT_OK
                                                                                                      : EXIT_IO;
    if (code == EXIT_OK && !opt->quiet) {
        if (is_part)
            fprintf(stderr, "part %s: tile %s, samples %d:%d of %d: ", opt->pfm_path, part->tile,
                    part->sample_begin, part->sample_end, part->spp);
        print_render_summary(crop_width, crop_height, opt->sample_end - opt->sample_begin, seconds, nee_label(scene),
                             &job->stats);
        if (job->noise_threshold > 0)
            fprintf(stderr, "adaptive: noise threshold %g, spp a pixel min %d, median %d, max %d, mean %.1f (%.1f%% "
                    "of %d)\n", job->noise_threshold, job->spp_min, job->spp_median, job->spp_max, job->spp_mean,
                    100.0 * job->spp_mean / scene->settings.spp, scene->settings.spp);
        print_face_jump_summary(scene);
    }
    return code;
}

/* rrv render: parse the options, load and check (steps 1 and 2), render
   and write (3 and 4). */
static int command_render(int argc, char **argv)
{
    render_options opt;
    rrv_scene *scene = NULL;
    render_job job;
    input_list inputs;
    float *image = NULL;
    int code;
    double seconds = 0;
    part_info part;
    char part_text[1024];
    arg_cursor args;

    code = parse_render_options(argc, argv, &opt);
    if (code == HELP_SHOWN) return EXIT_OK;
    if (code != EXIT_OK) return code;
    memset(&args, 0, sizeof args);
    args.command = "render";
    code = render_load(&opt, &args, &inputs, &scene);
    if (code != GO_ON) return code;
    memset(&part, 0, sizeof part);
    if ((opt.has_tile || opt.has_samples) && scene->settings.noise_threshold > 0) {
        code = usage_error(&args, "the scene's `render noisethreshold %g` cannot be combined with %s (parts are "
                           "uniform: add --noise-threshold 0)", scene->settings.noise_threshold,
                           opt.has_samples ? "--samples" : "--tile");
        free_inputs(&inputs);
        rrv_scene_free(scene);
        return code;
    }
    if (opt.has_tile || opt.has_samples)
        code = render_plan_part(&opt, &args, &inputs, scene, &part, part_text, sizeof part_text);
    else
        code = render_plan_image(&opt, &args, &inputs, scene);
    if (code == GO_ON) code = render_run(&opt, scene, opt.has_tile || opt.has_samples, &job, &image, &seconds);
    if (code == GO_ON) code = render_write(&opt, scene, &part, part_text, image, &job, seconds);
    free(image);
    rrv_scene_free(scene);
    return code;
}

/* ---- rrv merge ------------------------------------------------------------------- */

static const char merge_help[] =
    "usage: rrv merge OUT.exr|OUT.pfm PART.exr... [options]\n"
    "       rrv merge --status PART.exr...\n"
    "\n"
    "Merges the parts that `rrv render --tile I/N` and `--samples A:B` wrote\n"
    "into the image a single render would have written, bit for bit. The\n"
    "parts must come from the same scene and settings, their tiles must cover\n"
    "the image exactly once (one tile layout), and at every tile their sample\n"
    "blocks must not overlap and must add up to all samples. Any problem (a\n"
    "missing, unreadable, truncated, foreign or overlapping part) is reported\n"
    "and nothing is written (exit 2). OUT is written to a new temporary file\n"
    "and renamed into place.\n"
    "\n"
    "options:\n"
    "  --status         do not merge: print each part's tile and samples, or\n"
    "                   why it is missing; exit 0 only if every part is there\n"
    "  --exr-half       EXR channels as 16-bit half (the default, as render)\n"
    "  --exr-float      EXR channels as 32-bit float\n"
    "  -q, --quiet      no summary\n";

typedef struct merge_part {
    const char *path;
    part_info info;
    float *sums;
} merge_part;

static int rects_intersect(const int a[4], const int b[4])
{
    return a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
}

/* The first pixel, row by row, that none of the (non-overlapping) parts
   covers, found from the rectangles alone: a part may claim an image of
   INT_MAX x INT_MAX, and a map of its pixels would be that many bytes.
   The first hole's row is 0 or a rectangle's bottom edge (the row above it
   is all covered, by a rectangle that ends there), so only those rows are
   swept, each over the rectangles that meet it sorted by their left edge:
   O(n^2 log n) for n parts. 0 when every pixel is covered or out of memory
   (*x, *y are -1 then). */
static int find_hole(merge_part *const *parts, int count, int width, int height, int *x, int *y)
{
    int *rows = (int *)malloc((size_t)(count + 1) * sizeof *rows);
    int *lefts = (int *)malloc((size_t)(count > 0 ? count : 1) * 2 * sizeof *lefts);
    int row_count = 0, i, r, found = 0;
    *x = *y = -1;
    if (!rows || !lefts) {
        free(rows);
        free(lefts);
        return 0;
    }
    rows[row_count++] = 0;
    for (i = 0; i < count; ++i)
        if (parts[i]->info.rect[3] < height) rows[row_count++] = parts[i]->info.rect[3];
    qsort(rows, (size_t)row_count, sizeof *rows, compare_ints);
    for (r = 0; r < row_count && !found; ++r) {
        int n = 0, reach = 0, k;
        if (r > 0 && rows[r] == rows[r - 1]) continue;
        for (i = 0; i < count; ++i) {
            const int *rect = parts[i]->info.rect;
            if (rect[1] <= rows[r] && rows[r] < rect[3]) {
                lefts[2 * n] = rect[0];
                lefts[2 * n + 1] = rect[2];
                ++n;
            }
        }
        qsort(lefts, (size_t)n, 2 * sizeof *lefts, compare_ints); /* by the left edge */
        for (k = 0; k < n && lefts[2 * k] <= reach; ++k)
            if (lefts[2 * k + 1] > reach) reach = lefts[2 * k + 1];
        if (reach < width) {
            *x = reach;
            *y = rows[r];
            found = 1;
        }
    }
    free(rows);
    free(lefts);
    return found;
}

/* The tree sum of samples [a, b) of the parts of one tile (all with the
   same rectangle) into out; tmp is a scratch buffer per level. */
static void merge_block(merge_part *const *tile, int count, int a, int b, float *out, float **tmp,
                        size_t values)
{
    int i, mid;
    size_t k;
    for (i = 0; i < count; ++i)
        if (tile[i]->info.sample_begin == a && tile[i]->info.sample_end == b) {
            memcpy(out, tile[i]->sums, values * sizeof *out);
            return;
        }
    /* Coverage was checked, so the block is made of smaller ones. */
    mid = sample_split(a, b);
    merge_block(tile, count, a, mid, out, tmp + 1, values);
    merge_block(tile, count, mid, b, tmp[0], tmp + 1, values);
    for (k = 0; k < values; ++k) out[k] = add_saturated(out[k], tmp[0][k]);
}

static int compare_by_rect_then_samples(const void *pa, const void *pb)
{
    const merge_part *a = *(merge_part *const *)pa, *b = *(merge_part *const *)pb;
    int i;
    for (i = 0; i < 4; ++i) {
        int ka = i < 2 ? a->info.rect[1 - i] : a->info.rect[i], kb = i < 2 ? b->info.rect[1 - i] : b->info.rect[i];
        if (ka != kb) return ka < kb ? -1 : 1;
    }
    return a->info.sample_begin < b->info.sample_begin ? -1 : a->info.sample_begin > b->info.sample_begin;
}

static int merge_status(char **paths, int count)
{
    int i, present = 0;
    for (i = 0; i < count; ++i) {
        part_info info;
        struct stat st;
        if (stat(paths[i], &st) != 0 && errno == ENOENT) {
            printf("%s: missing\n", paths[i]);
            continue;
        }
        if (!load_part(paths[i], &info, NULL, "merge --status")) {
            printf("%s: not a usable part (see above)\n", paths[i]);
            continue;
        }
        ++present;
        printf("%s: tile %s (pixels %d,%d-%d,%d), samples %d:%d, %d of %d samples, scene %s\n", paths[i],
               info.tile, info.rect[0], info.rect[1], info.rect[2], info.rect[3], info.sample_begin,
               info.sample_end, info.sample_end - info.sample_begin, info.spp, info.hash);
    }
    printf("%d of %d parts present\n", present, count);
    return present == count ? EXIT_OK : EXIT_INPUT;
}

/* rrv merge, loading: every part read, none the output or another part's
   file, all of one scene and settings. 1, or 0 once a message is printed. */
static int merge_load_parts(const char *out_path, char **paths, int count, merge_part *parts, merge_part **order)
{
    int i, j;
    for (i = 0; i < count; ++i) {
        parts[i].path = paths[i];
        order[i] = &parts[i];
        if (same_file(out_path, paths[i])) {
            fprintf(stderr, "rrv: merge: refusing to write \"%s\": it is one of the parts\n", out_path);
            return 0;
        }
        for (j = 0; j < i; ++j)
            if (same_file(paths[i], paths[j])) {
                fprintf(stderr, "rrv: merge: \"%s\" and \"%s\" are the same file\n", paths[j], paths[i]);
                return 0;
            }
        if (!load_part(paths[i], &parts[i].info, &parts[i].sums, "merge")) return 0;
        if (i > 0 && (strcmp(parts[i].info.hash, parts[0].info.hash) != 0 ||
                      parts[i].info.width != parts[0].info.width || parts[i].info.height != parts[0].info.height ||
                      parts[i].info.spp != parts[0].info.spp)) {
            fprintf(stderr, "rrv: merge: \"%s\" is from another scene or settings than \"%s\" (%dx%d, %d spp "
                    "and %dx%d, %d spp; their hashes differ)\n", paths[i], paths[0],
                    parts[i].info.width, parts[i].info.height, parts[i].info.spp,
                    parts[0].info.width, parts[0].info.height, parts[0].info.spp);
            return 0;
        }
    }
    return 1;
}

/* rrv merge, checking the parts in order (by rectangle, then samples):
   equal rectangles form one tile and different ones do not meet, each
   tile's sample ranges run 0..spp unbroken, and the tiles cover the
   frame. 1, or 0 once a message is printed. */
static int merge_check_layout(merge_part **order, int count, int width, int height, int spp)
{
    long long area = 0;
    int i, j;
    for (i = 0; i < count; ++i)
        for (j = i + 1; j < count; ++j) {
            const part_info *a = &order[i]->info, *b = &order[j]->info;
            int same_rect = memcmp(a->rect, b->rect, sizeof a->rect) == 0;
            if (!rects_intersect(a->rect, b->rect)) continue;
            if (!same_rect) {
                fprintf(stderr, "rrv: merge: \"%s\" (tile %s) and \"%s\" (tile %s) overlap: tiles of different "
                        "layouts share pixels; merge the parts of one layout\n", order[i]->path, a->tile,
                        order[j]->path, b->tile);
                return 0;
            }
            if (a->sample_begin < b->sample_end && b->sample_begin < a->sample_end) {
                fprintf(stderr, "rrv: merge: \"%s\" and \"%s\" overlap: both hold samples %d:%d of tile %s\n",
                        order[i]->path, order[j]->path,
                        a->sample_begin > b->sample_begin ? a->sample_begin : b->sample_begin,
                        a->sample_end < b->sample_end ? a->sample_end : b->sample_end, a->tile);
                return 0;
            }
        }
    for (i = 0; i < count; i = j) {
        int next = 0;
        for (j = i; j < count && memcmp(order[j]->info.rect, order[i]->info.rect, sizeof order[i]->info.rect) == 0; ++j) {
            if (order[j]->info.sample_begin != next) break;
            next = order[j]->info.sample_end;
        }
        if (next != spp || (j < count && memcmp(order[j]->info.rect, order[i]->info.rect,
                                                sizeof order[i]->info.rect) == 0)) {
            int gap_end = j < count && memcmp(order[j]->info.rect, order[i]->info.rect,
                                              sizeof order[i]->info.rect) == 0 ? order[j]->info.sample_begin : spp;
            fprintf(stderr, "rrv: merge: samples %d:%d of tile %s (pixels %d,%d-%d,%d) are in no part: a sample "
                    "range is missing\n", next, gap_end, order[i]->info.tile, order[i]->info.rect[0],
                    order[i]->info.rect[1], order[i]->info.rect[2], order[i]->info.rect[3]);
            return 0;
        }
        area += (long long)(order[i]->info.rect[2] - order[i]->info.rect[0]) *
                (order[i]->info.rect[3] - order[i]->info.rect[1]);
    }
    if (area != (long long)width * height) {
        /* Tiles do not overlap, so less area means a hole: find a pixel in it. */
        int x, y;
        if (!find_hole(order, count, width, height, &x, &y)) {
            fprintf(stderr, "rrv: out of memory\n");
            return 0;
        }
        fprintf(stderr, "rrv: merge: pixel %d,%d is in no part: a tile is missing (the parts cover %lld of %dx%d "
                "pixels)\n", x, y, area, width, height);
        return 0;
    }
    return 1;
}

/* rrv merge, summing: each tile's parts added in the sample tree (as one
   render adds them) and divided by spp into a new image, or NULL once a
   message is printed. */
static float *merge_sum(merge_part **order, int count, int width, int height, int spp)
{
    float *image = NULL, *tile_sum = NULL, *tmp[32];
    int i, j, k, levels, ok = 0;
    memset(tmp, 0, sizeof tmp);
    if ((uint64_t)width * (uint64_t)height > SIZE_MAX / (3 * sizeof *image)) {
        fprintf(stderr, "rrv: out of memory for a %dx%d image\n", width, height);
        return NULL;
    }
    image = (float *)malloc((size_t)width * (size_t)height * 3 * sizeof *image);
    tile_sum = (float *)malloc((size_t)width * (size_t)height * 3 * sizeof *tile_sum);
    levels = sample_tree_depth(spp);
    if (!image || !tile_sum) {
        fprintf(stderr, "rrv: out of memory for a %dx%d image\n", width, height);
        goto done;
    }
    for (i = 0; i < count; i = j) {
        const int *r = order[i]->info.rect;
        int w = r[2] - r[0], h = r[3] - r[1], x, y, c;
        size_t values = (size_t)w * (size_t)h * 3;
        for (j = i; j < count && memcmp(order[j]->info.rect, r, 4 * sizeof *r) == 0; ++j) {}
        for (k = 0; k < levels; ++k) {
            free(tmp[k]);
            tmp[k] = (float *)malloc(values * sizeof *tmp[k]);
            if (!tmp[k]) {
                fprintf(stderr, "rrv: out of memory\n");
                goto done;
            }
        }
        merge_block(order + i, j - i, 0, spp, tile_sum, tmp, values);
        for (y = 0; y < h; ++y)
            for (x = 0; x < w; ++x)
                for (c = 0; c < 3; ++c)
                    image[3 * ((size_t)(r[1] + y) * width + (size_t)(r[0] + x)) + c] =
                        tile_sum[3 * ((size_t)y * w + x) + c] / (float)spp;
    }
    ok = 1;
done:
    for (k = 0; k < 32; ++k) free(tmp[k]);
    free(tile_sum);
    if (!ok) {
        free(image);
        image = NULL;
    }
    return image;
}

/* rrv merge: parse the options (--status reports and stops), check the
   output, then load, check and sum the parts and write the image. */
static int command_merge(int argc, char **argv)
{
    arg_cursor args;
    const char *out_path = NULL;
    char **paths;
    merge_part *parts = NULL, **order = NULL;
    float *image = NULL;
    int path_count = 0, status = 0, quiet = 0, i, code = EXIT_INPUT, format;
    rrv_exr_options exr;
    pending_output output;
    int width, height, spp;

    memset(&args, 0, sizeof args);
    args.argc = argc;
    args.argv = argv;
    args.command = "merge";
    memset(&exr, 0, sizeof exr);
    paths = (char **)malloc((size_t)(argc > 0 ? argc : 1) * sizeof *paths);
    if (!paths) {
        fprintf(stderr, "rrv: out of memory\n");
        return EXIT_INPUT;
    }
    for (args.index = 0; args.index < argc; ++args.index) {
        const char *arg = argv[args.index];
        if (is_help_flag(arg)) {
            fputs(merge_help, stdout);
            free(paths);
            return EXIT_OK;
        } else if (strcmp(arg, "--status") == 0) {
            status = 1;
        } else if (strcmp(arg, "--exr-half") == 0 || strcmp(arg, "--exr-float") == 0) {
            exr.pixel = arg[6] == 'f' ? RRV_EXR_FLOAT : RRV_EXR_HALF;
        } else if (strcmp(arg, "-q") == 0 || strcmp(arg, "--quiet") == 0) {
            quiet = 1;
        } else if (is_flag(arg)) {
            char hint[80];
            free(paths);
            return usage_error(&args, "merge: unknown option \"%s\"%s", arg, flag_hint(arg, merge_help, NULL, hint));
        } else if (!status && !out_path) {
            out_path = arg;
        } else {
            paths[path_count++] = argv[args.index];
        }
    }
    if (status) {
        /* --status may come after the first part */
        if (out_path) {
            memmove(paths + 1, paths, (size_t)path_count * sizeof *paths);
            paths[0] = (char *)out_path;
            ++path_count;
        }
        if (path_count == 0) {
            free(paths);
            return usage_error(&args, "merge --status needs at least one part");
        }
        code = merge_status(paths, path_count);
        free(paths);
        return code;
    }
    if (!out_path || path_count == 0) {
        free(paths);
        return usage_error(&args, "merge needs an output and at least one part: rrv merge OUT.exr PART.exr...");
    }
    format = has_extension(out_path, ".exr") ? OUTPUT_EXR : has_extension(out_path, ".pfm") ? OUTPUT_PFM : -1;
    if (format < 0) {
        free(paths);
        return usage_error(&args, "cannot tell the format of \"%s\": the output must end in .pfm or .exr", out_path);
    }
    if (!check_output(out_path)) {
        free(paths);
        return EXIT_IO;
    }

    parts = (merge_part *)calloc((size_t)path_count, sizeof *parts);
    order = (merge_part **)calloc((size_t)path_count, sizeof *order);
    if (!parts || !order) {
        fprintf(stderr, "rrv: out of memory\n");
        goto done;
    }
    if (!merge_load_parts(out_path, paths, path_count, parts, order)) goto done;
    width = parts[0].info.width;
    height = parts[0].info.height;
    spp = parts[0].info.spp;
    qsort(order, (size_t)path_count, sizeof *order, compare_by_rect_then_samples);
    if (!merge_check_layout(order, path_count, width, height, spp) ||
        !(image = merge_sum(order, path_count, width, height, spp)))
        goto done;

    memset(&output, 0, sizeof output);
    output.path = out_path;
    output.format = format;
    output.exr = &exr;
    code = write_outputs(&output, 1, image, width, height, 0) ? EXIT_OK : EXIT_IO;
    if (code == EXIT_OK && !quiet)
        fprintf(stderr, "merged %d parts into %s: %dx%d, %d spp\n", path_count, out_path, width, height, spp);
done:
    if (parts)
        for (i = 0; i < path_count; ++i) rrv_free(parts[i].sums);
    free(parts);
    free(order);
    free(image);
    free(paths);
    return code;
}

/* ---- rrv farm slurm ---------------------------------------------------------------- */

static const char farm_help[] =
    "usage: rrv farm slurm SCENE -o OUT.exr --tiles N|CxR [options] [-- RENDER OPTIONS]\n"
    "\n"
    "Writes the Slurm jobs that render SCENE as tiles and merge them into OUT:\n"
    "  DIR/render.sbatch  a job array, task I renders tile I/N (or I/CxR) to\n"
    "                     DIR/parts/tile_I.exr with --resume, so a task whose\n"
    "                     part is already complete ends at once\n"
    "  DIR/merge.sbatch   rrv merge OUT DIR/parts/tile_0.exr ...\n"
    "  DIR/submit.sh      submits both, the merge with --dependency=afterok on\n"
    "                     the array; run it again to resume after a failure\n"
    "Paths in the scripts are absolute; the scene, rrv and DIR must be on a\n"
    "file system every node sees. Options after -- go to every rrv render.\n"
    "The scene is loaded first: at most as many tile columns and rows as the\n"
    "image has, at most 10000 tiles, and OUT must not be one of its files.\n"
    "DIR, P and T must not hold a newline, % or hetjob (no #SBATCH form).\n"
    "\n"
    "options:\n"
    "  -o, --output OUT      the merged image (required; .exr or .pfm)\n"
    "  --tiles N|CxR         N bands of rows or a C by R grid (required)\n"
    "  --dir DIR             where the scripts, parts and logs go (default OUT.farm)\n"
    "  --partition P         sbatch --partition\n"
    "  --cpus-per-task C     sbatch --cpus-per-task and rrv render --threads\n"
    "  --time T              sbatch --time limit of each task, e.g. 2:00:00\n"
    "  --rrv PATH            the rrv the nodes run (default: this one)\n";

/* The most tiles a farm has: one array task and one merge argument each.
   Slurm's default MaxArraySize takes 1001 tasks; a cluster may set more or
   fewer, and sbatch says so when it refuses the array. */
#define FARM_MAX_TILES 10000
/* The merge's arguments (every part's path) stay under 1 MiB: Linux gives
   execve a quarter of the stack, 2 MiB with the usual 8 MiB. */
#define FARM_MAX_MERGE_ARGS (1L << 20)

/* What rrv farm writes into its scripts, every path absolute. */
typedef struct farm_plan {
    const char *dir, *rrv, *scene, *output;
    const char *dir_label;              /* how messages name dir's option */
    const char *partition, *time_limit; /* NULL: not asked for */
    int cpus;                           /* 0: not asked for */
    int columns, rows;                  /* 1 x N: N bands of rows */
    char **extra;                       /* the render options after -- */
    int extra_count;
} farm_plan;

enum { FARM_RENDER, FARM_MERGE, FARM_SUBMIT, FARM_SCRIPTS };
static const char *const farm_script_name[FARM_SCRIPTS] = { "render.sbatch", "merge.sbatch", "submit.sh" };

/* The one quoting of values in the scripts' shell commands: single quotes,
   inside which the shell expands nothing and a newline is just a byte; a '
   becomes '\'' (close, an escaped quote, open). Every byte but NUL, which
   no argument can hold, survives it. */
static void put_quoted(FILE *f, const char *text)
{
    fputc('\'', f);
    for (; *text; ++text) {
        if (*text == '\'') fputs("'\\''", f);
        else fputc(*text, f);
    }
    fputc('\'', f);
}

/* An #SBATCH line is a comment to the shell but is read by sbatch, which
   splits it at blanks, ends it at an unquoted #, takes '...' and "..." as
   groups and a backslash as "the next byte as it is". So a value goes in
   double quotes with " and \ escaped; farm_directive_problem refused first what
   no quoting carries. */
static void put_directive(FILE *f, const char *option, const char *value)
{
    fprintf(f, "#SBATCH --%s=\"", option);
    for (; *value; ++value) {
        if (*value == '"' || *value == '\\') fputc('\\', f);
        fputc(*value, f);
    }
    fputs("\"\n", f);
}

/* A value in a message, with the bytes a terminal would not show (or would
   act on) escaped. */
static void print_escaped(FILE *f, const char *text)
{
    for (; *text; ++text) {
        unsigned char c = (unsigned char)*text;
        if (c == '\n') fputs("\\n", f);
        else if (c == '"' || c == '\\') fprintf(f, "\\%c", c);
        else if (c < 0x20 || c == 0x7f) fprintf(f, "\\x%02x", c);
        else fputc(c, f);
    }
}

/* What no #SBATCH value can hold, or NULL: a newline ends the line, and
   what follows would be a command to the shell; sbatch expands % in file
   names (%a, %j, ...), so a % in the folder would send the logs elsewhere
   (refused in --partition and --time too: one rule for every directive);
   and a line holding "hetjob" (or the older "packjob") anywhere starts a
   new component of a heterogeneous job. */
static const char *farm_directive_problem(const char *value)
{
    const char *p;
    for (p = value ? value : ""; *p; ++p) {
        if (*p == '\n') return "a newline";
        if (*p == '%') return "'%'";
        if (strncasecmp(p, "hetjob", 6) == 0) return "\"hetjob\"";
        if (strncasecmp(p, "packjob", 7) == 0) return "\"packjob\"";
    }
    return NULL;
}

/* 1 when every value of the plan has a form in the scripts; else says which
   option and which character, and returns 0. */
static int farm_plan_ok(const farm_plan *plan)
{
    const char *labels[3], *values[3], *what;
    int i;
    labels[0] = plan->dir_label;
    values[0] = plan->dir;
    labels[1] = "--partition";
    values[1] = plan->partition;
    labels[2] = "--time";
    values[2] = plan->time_limit;
    for (i = 0; i < 3; ++i)
        if ((what = farm_directive_problem(values[i])) != NULL) {
            fprintf(stderr, "rrv: farm: %s \"", labels[i]);
            print_escaped(stderr, values[i]);
            fprintf(stderr, "\" holds %s, which has no safe form in a #SBATCH line\n", what);
            return 0;
        }
    return 1;
}

/* dir/name as a new string. */
static char *join_path(const char *dir, const char *name)
{
    char *out = (char *)malloc(strlen(dir) + strlen(name) + 2);
    if (out) sprintf(out, "%s/%s", dir, name);
    return out;
}

static int put_quoted_path(FILE *f, const char *dir, const char *name)
{
    char *path = join_path(dir, name);
    if (path) put_quoted(f, path);
    free(path);
    return path != NULL;
}

static int put_directive_path(FILE *f, const char *option, const char *dir, const char *name)
{
    char *path = join_path(dir, name);
    if (path) put_directive(f, option, path);
    free(path);
    return path != NULL;
}

/* The text of one of the plan's scripts (FARM_*), or NULL when out of
   memory. Every value reaches the shell through put_quoted and sbatch
   through put_directive; farm_plan_ok must have accepted the plan. */
static char *farm_script(const farm_plan *plan, int which)
{
    char *text = NULL, name[64], tiles[32];
    size_t size = 0;
    int i, ok = 1, count = plan->columns * plan->rows;
    FILE *f = open_memstream(&text, &size);
    if (!f) return NULL;
    if (plan->columns == 1) snprintf(tiles, sizeof tiles, "%d", plan->rows);
    else snprintf(tiles, sizeof tiles, "%dx%d", plan->columns, plan->rows);
    if (which == FARM_RENDER) {
        fprintf(f, "#!/bin/sh\n# Written by rrv farm slurm: task I renders tile I of %s as a part.\n", tiles);
        fprintf(f, "#SBATCH --job-name=rrv-tiles\n#SBATCH --array=0-%d\n", count - 1);
        ok &= put_directive_path(f, "output", plan->dir, "logs/tile_%a.log");
        if (plan->partition) put_directive(f, "partition", plan->partition);
        if (plan->cpus) fprintf(f, "#SBATCH --cpus-per-task=%d\n", plan->cpus);
        if (plan->time_limit) put_directive(f, "time", plan->time_limit);
        fputs("set -eu\ni=${SLURM_ARRAY_TASK_ID:?run through sbatch or set SLURM_ARRAY_TASK_ID}\n", f);
        fputs("# --resume: a part already complete is kept; the part is written to a\n"
              "# temporary file and renamed, so a killed task leaves no half part.\nexec ", f);
        put_quoted(f, plan->rrv);
        fputs(" render ", f);
        put_quoted(f, plan->scene);
        fputs(" -o ", f);
        ok &= put_quoted_path(f, plan->dir, "parts/tile_");
        fprintf(f, "\"$i\"'.exr' --tile \"$i\"/%s --resume", tiles);
        if (plan->cpus) fprintf(f, " --threads %d", plan->cpus);
        for (i = 0; i < plan->extra_count; ++i) {
            fputc(' ', f);
            put_quoted(f, plan->extra[i]);
        }
        fputc('\n', f);
    } else if (which == FARM_MERGE) {
        fprintf(f, "#!/bin/sh\n# Written by rrv farm slurm: merges the %d parts (after the array, afterok).\n",
                count);
        fputs("#SBATCH --job-name=rrv-merge\n", f);
        ok &= put_directive_path(f, "output", plan->dir, "logs/merge.log");
        if (plan->partition) put_directive(f, "partition", plan->partition);
        fputs("set -eu\nexec ", f);
        put_quoted(f, plan->rrv);
        fputs(" merge ", f);
        put_quoted(f, plan->output);
        for (i = 0; i < count; ++i) {
            snprintf(name, sizeof name, "parts/tile_%d.exr", i);
            fputs(" \\\n    ", f);
            ok &= put_quoted_path(f, plan->dir, name);
        }
        fputc('\n', f);
    } else {
        fputs("#!/bin/sh\n# Written by rrv farm slurm: submits the tiles and the merge that waits for them.\n"
              "# Run it again after a failure: complete parts are kept.\nset -eu\n", f);
        fputs("array=$(sbatch --parsable ", f);
        ok &= put_quoted_path(f, plan->dir, "render.sbatch");
        fputs(")\narray=${array%%;*}\nmerge=$(sbatch --parsable --dependency=afterok:\"$array\" ", f);
        ok &= put_quoted_path(f, plan->dir, "merge.sbatch");
        fprintf(f, ")\necho \"tiles: job $array (%d tasks); merge: job ${merge%%%%;*}\"\n", count);
    }
    if (ferror(f)) ok = 0;
    if (fclose(f) != 0 || !text) ok = 0;
    if (!ok) {
        free(text);
        return NULL;
    }
    return text;
}

/* An absolute path for a file that may not exist yet (its folder must). */
static char *absolute_path(const char *path)
{
    char folder[4096], *real, *out;
    const char *name;
    if (!split_path(path, folder, sizeof folder, &name)) return NULL;
    real = realpath(folder, NULL);
    if (!real) return NULL;
    out = (char *)malloc(strlen(real) + strlen(name) + 2);
    if (out) sprintf(out, "%s/%s", strcmp(real, "/") == 0 ? "" : real, name);
    free(real);
    return out;
}

static int make_folder(const char *path)
{
    if (mkdir(path, 0777) == 0 || errno == EEXIST) return 1;
    fprintf(stderr, "rrv: farm: cannot create \"%s\": %s\n", path, strerror(errno));
    return 0;
}

/* What rrv farm slurm asks for and, as it goes, what it resolved and
   built; farm_job_free releases what it owns. */
typedef struct farm_job {
    farm_plan plan;
    const char *scene_path, *out_path, *tiles_text, *dir_arg, *rrv_arg;
    long long count;          /* tiles */
    size_t max_grid_bytes;    /* of the render options */
    int noise_threshold_set;  /* the render options give --noise-threshold (0: the scene's) */
    char *scene, *out, *dir, *real_dir, *rrv_path, *dir_copy;
    char *paths[FARM_SCRIPTS + 2]; /* the scripts, then parts/ and logs/ */
    char *text[FARM_SCRIPTS];
    char default_dir[4200];
    input_list inputs;
} farm_job;

static void farm_job_free(farm_job *f)
{
    int i;
    for (i = 0; i < FARM_SCRIPTS; ++i) free(f->text[i]);
    for (i = 0; i < FARM_SCRIPTS + 2; ++i) free(f->paths[i]);
    free_inputs(&f->inputs);
    free(f->scene);
    free(f->out);
    free(f->dir);
    free(f->real_dir);
    free(f->dir_copy);
    free(f->rrv_path);
}

/* rrv farm slurm, step 1: the options parsed and checked, the render
   options after -- too (here, not on every node; they also say how large
   a grid the scene may load). GO_ON, or the exit code. */
static int farm_parse(int argc, char **argv, arg_cursor *args, farm_job *f)
{
    int index, i, code, extra = argc;
    char **render_argv;
    render_options ropt;
    if (argc > 0 && is_help_flag(argv[0])) {
        fputs(farm_help, stdout);
        return EXIT_OK;
    }
    if (argc == 0 || strcmp(argv[0], "slurm") != 0)
        return usage_error(args, "farm needs a scheduler: rrv farm slurm SCENE -o OUT --tiles N");
    for (args->index = 1; args->index < argc; ++args->index) {
        const char *arg = argv[args->index];
        if (is_help_flag(arg)) {
            fputs(farm_help, stdout);
            return EXIT_OK;
        } else if (strcmp(arg, "--") == 0) {
            extra = args->index + 1;
            break;
        } else if (strcmp(arg, "-o") == 0 || strcmp(arg, "--output") == 0) {
            if (!take_value(args, arg, "an output path", &f->out_path)) return EXIT_USAGE;
        } else if (strcmp(arg, "--tiles") == 0) {
            if (!take_value(args, arg, "N or CxR", &f->tiles_text)) return EXIT_USAGE;
        } else if (strcmp(arg, "--dir") == 0) {
            if (!take_value(args, arg, "a folder", &f->dir_arg)) return EXIT_USAGE;
        } else if (strcmp(arg, "--partition") == 0) {
            if (!take_value(args, arg, "a partition name", &f->plan.partition)) return EXIT_USAGE;
        } else if (strcmp(arg, "--time") == 0) {
            if (!take_value(args, arg, "a time limit", &f->plan.time_limit)) return EXIT_USAGE;
        } else if (strcmp(arg, "--rrv") == 0) {
            if (!take_value(args, arg, "a path to rrv", &f->rrv_arg)) return EXIT_USAGE;
        } else if (strcmp(arg, "--cpus-per-task") == 0) {
            if (!take_int(args, arg, 1, MAX_THREADS, "a positive integer", &f->plan.cpus)) return EXIT_USAGE;
        } else if (is_flag(arg)) {
            char hint[80];
            return usage_error(args, "farm: unknown option \"%s\"%s (render options go after --)", arg,
                               flag_hint(arg, farm_help, NULL, hint));
        } else if (f->scene_path) {
            return usage_error(args, "farm: unexpected argument \"%s\"", arg);
        } else {
            f->scene_path = arg;
        }
    }
    args->index = argc;
    if (!f->scene_path) return usage_error(args, "farm slurm needs a scene file");
    if (!f->out_path) return usage_error(args, "farm slurm needs the merged image: -o OUT.exr");
    if (!f->tiles_text) return usage_error(args, "farm slurm needs --tiles N or --tiles CxR");
    {
        char tile_text[64];
        snprintf(tile_text, sizeof tile_text, "0/%s", f->tiles_text);
        if (strlen(f->tiles_text) > 40 || !parse_tile(tile_text, &index, &f->plan.columns, &f->plan.rows))
            return usage_error(args, "--tiles needs N or CxR, positive integers, got \"%s\"", f->tiles_text);
    }
    f->count = (long long)f->plan.columns * f->plan.rows;
    if (f->count > FARM_MAX_TILES)
        return usage_error(args, "--tiles %s makes %lld tiles; a farm has at most %d", f->tiles_text, f->count,
                           FARM_MAX_TILES);
    if (!has_extension(f->out_path, ".exr") && !has_extension(f->out_path, ".pfm"))
        return usage_error(args, "cannot tell the format of \"%s\": the output must end in .pfm or .exr",
                           f->out_path);
    for (i = extra; i < argc; ++i)
        if (strcmp(argv[i], "-o") == 0 || strcmp(argv[i], "--output") == 0 || strcmp(argv[i], "--tile") == 0 ||
            strcmp(argv[i], "--samples") == 0 || strcmp(argv[i], "--resume") == 0 ||
            strcmp(argv[i], "--png") == 0 || strcmp(argv[i], "--crop") == 0)
            return usage_error(args, "farm: %s is set by the farm, not a render option to pass", argv[i]);
    f->plan.extra = argv + extra;
    f->plan.extra_count = argc - extra;
    render_argv = (char **)malloc((size_t)(f->plan.extra_count + 3) * sizeof *render_argv);
    if (!render_argv) {
        fprintf(stderr, "rrv: out of memory\n");
        return EXIT_IO;
    }
    render_argv[0] = (char *)f->scene_path;
    render_argv[1] = (char *)"-o";
    render_argv[2] = (char *)"farm.exr";
    for (i = 0; i < f->plan.extra_count; ++i) render_argv[3 + i] = f->plan.extra[i];
    code = parse_render_options(f->plan.extra_count + 3, render_argv, &ropt);
    free(render_argv);
    if (code == HELP_SHOWN) return EXIT_OK;
    if (code != EXIT_OK) return code;
    /* the farm's parts are tiles, which hold sums of one sample count */
    if (ropt.noise_threshold > 0)
        return usage_error(args, "farm: --noise-threshold cannot be combined with the farm's --tile parts");
    f->noise_threshold_set = ropt.has_noise_threshold;
    f->max_grid_bytes = ropt.max_grid_bytes;
    return GO_ON;
}

/* rrv farm slurm, step 2: every path resolved and every value checked
   before anything is written; as rrv render does, the scene's camera
   bounds the tiles and an output that is one of the scene's files is
   refused. GO_ON, or the exit code. */
static int farm_check(const arg_cursor *args, farm_job *f)
{
    rrv_scene *loaded = NULL;
    int i, width, height;
    snprintf(f->default_dir, sizeof f->default_dir, "%s.farm", f->out_path);
    f->plan.dir_label = f->dir_arg ? "--dir" : "the farm folder (-o OUT.farm)";
    if (!f->dir_arg) f->dir_arg = f->default_dir;
    f->dir_copy = (char *)malloc(strlen(f->dir_arg) + 1);
    if (!f->dir_copy) return EXIT_IO;
    strcpy(f->dir_copy, f->dir_arg);
    for (i = (int)strlen(f->dir_copy) - 1; i > 0 && f->dir_copy[i] == '/'; --i) f->dir_copy[i] = '\0';
    f->scene = realpath(f->scene_path, NULL);
    if (!f->scene) {
        fprintf(stderr, "rrv: %s: cannot read scene file: %s\n", f->scene_path, strerror(errno));
        return EXIT_INPUT;
    }
    f->out = absolute_path(f->out_path);
    f->dir = realpath(f->dir_copy, NULL);
    if (!f->dir) f->dir = absolute_path(f->dir_copy);
    f->rrv_path = f->rrv_arg ? realpath(f->rrv_arg, NULL) : realpath("/proc/self/exe", NULL);
    if (!f->out || !f->dir || !f->rrv_path) {
        fprintf(stderr, "rrv: farm: cannot resolve %s: %s\n",
                !f->out ? f->out_path : !f->dir ? f->dir_arg : "the rrv program", strerror(errno));
        return EXIT_IO;
    }
    f->plan.dir = f->dir;
    f->plan.rrv = f->rrv_path;
    f->plan.scene = f->scene;
    f->plan.output = f->out;
    if (!farm_plan_ok(&f->plan)) return EXIT_USAGE;
    if (!check_output_target(f->out_path)) return EXIT_IO;
    if (!load_scene(f->scene_path, f->max_grid_bytes, &f->inputs, &loaded, 0)) return EXIT_INPUT;
    width = loaded->camera.width;
    height = loaded->camera.height;
    if (loaded->settings.noise_threshold > 0 && !f->noise_threshold_set) {
        double threshold = loaded->settings.noise_threshold;
        rrv_scene_free(loaded);
        return usage_error(args, "farm: the scene's `render noisethreshold %g` cannot be combined with the farm's "
                           "--tile parts (pass -- --noise-threshold 0)", threshold);
    }
    rrv_scene_free(loaded);
    if (!check_output_not_input(f->out_path, &f->inputs)) return EXIT_USAGE;
    if (f->plan.columns > width || f->plan.rows > height)
        return usage_error(args, "--tiles %s: the %dx%d image has too few %s for that many tiles", f->tiles_text,
                           width, height, f->plan.columns > width ? "columns" : "rows");
    if (f->count * (long long)(strlen(f->dir) + 32) + (long long)strlen(f->out) > FARM_MAX_MERGE_ARGS)
        return usage_error(args, "--tiles %s: the merge of %lld parts in \"%s\" would take more than %ld bytes "
                           "of arguments: fewer tiles or a shorter --dir", f->tiles_text, f->count, f->dir,
                           FARM_MAX_MERGE_ARGS);
    return GO_ON;
}

/* rrv farm slurm, step 3: the scripts made, their folder with parts/ and
   logs/ created, the scripts written (each through a temporary file) and
   the submit command printed. EXIT_OK or EXIT_IO. */
static int farm_write(farm_job *f)
{
    pending_output outputs[FARM_SCRIPTS];
    int i, created = 0;
    for (i = 0; i < FARM_SCRIPTS; ++i)
        if (!(f->paths[i] = join_path(f->dir, farm_script_name[i]))) return EXIT_IO;
    if (!(f->paths[FARM_SCRIPTS] = join_path(f->dir, "parts")) || !(f->paths[FARM_SCRIPTS + 1] = join_path(f->dir, "logs")))
        return EXIT_IO;
    for (i = 0; i < FARM_SCRIPTS; ++i)
        if (!check_script_target(f->paths[i])) return EXIT_IO;
    for (i = 0; i < FARM_SCRIPTS; ++i)
        if (!(f->text[i] = farm_script(&f->plan, i))) {
            fprintf(stderr, "rrv: out of memory\n");
            return EXIT_IO;
        }

    if (mkdir(f->dir, 0777) == 0) created = 1;
    else if (errno != EEXIST) {
        fprintf(stderr, "rrv: farm: cannot create \"%s\": %s\n", f->dir, strerror(errno));
        return EXIT_IO;
    }
    /* The folder may have been a link (or became one): its real path must be
       the one the scripts name. */
    f->real_dir = realpath(f->dir, NULL);
    if (!f->real_dir || strcmp(f->real_dir, f->dir) != 0) {
        fprintf(stderr, "rrv: farm: \"%s\" changed while the scripts were written (now \"%s\")\n", f->dir,
                f->real_dir ? f->real_dir : strerror(errno));
        if (created) rmdir(f->dir);
        return EXIT_IO;
    }
    if (!make_folder(f->paths[FARM_SCRIPTS]) || !make_folder(f->paths[FARM_SCRIPTS + 1])) return EXIT_IO;
    memset(outputs, 0, sizeof outputs);
    for (i = 0; i < FARM_SCRIPTS; ++i) {
        outputs[i].path = f->paths[i];
        outputs[i].format = OUTPUT_SCRIPT;
        outputs[i].script = f->text[i];
    }
    if (!write_outputs(outputs, FARM_SCRIPTS, NULL, 0, 0, 0)) return EXIT_IO;
    printf("wrote %s/render.sbatch (%lld tasks), %s/merge.sbatch, %s/submit.sh\nsubmit with: sh ", f->dir,
           f->count, f->dir, f->dir);
    put_quoted(stdout, f->paths[FARM_SUBMIT]);
    putchar('\n');
    return EXIT_OK;
}

/* rrv farm slurm: parse (step 1), check (2), write the scripts (3). */
static int command_farm(int argc, char **argv)
{
    arg_cursor args;
    farm_job f;
    int code;
    memset(&args, 0, sizeof args);
    memset(&f, 0, sizeof f);
    f.plan.columns = 1;
    args.argc = argc;
    args.argv = argv;
    args.command = "farm";
    code = farm_parse(argc, argv, &args, &f);
    if (code == GO_ON) code = farm_check(&args, &f);
    if (code == GO_ON) code = farm_write(&f);
    farm_job_free(&f);
    return code;
}

/* ---- rrv diff -------------------------------------------------------------------- */

static int command_diff(int argc, char **argv)
{
    arg_cursor args;
    const char *paths[2] = {NULL, NULL};
    float *images[2] = {NULL, NULL};
    int widths[2], heights[2], count = 0, i, code = EXIT_OK;
    static const char channel_names[] = "rgb";

    args.argc = argc;
    args.argv = argv;
    args.command = "diff";
    for (args.index = 0; args.index < argc; ++args.index) {
        const char *arg = argv[args.index];
        if (is_help_flag(arg)) {
            fputs(diff_help, stdout);
            return EXIT_OK;
        } else if (is_flag(arg)) {
            char hint[80];
            return usage_error(&args, "diff: unknown option \"%s\"%s", arg, flag_hint(arg, diff_help, NULL, hint));
        } else if (count == 2) {
            return usage_error(&args, "diff: unexpected argument \"%s\"", arg);
        } else {
            paths[count++] = arg;
        }
    }
    if (count != 2) return usage_error(&args, "diff needs two images: A.pfm B.pfm");

    for (i = 0; i < 2 && code == EXIT_OK; ++i) {
        rrv_error err;
        memset(&err, 0, sizeof err);
        /* An EXR is compared over its data window (a crop as rendered). */
        if ((has_extension(paths[i], ".exr")
                 ? rrv_read_exr(paths[i], &images[i], &widths[i], &heights[i], NULL, &err)
                 : rrv_read_pfm(paths[i], &images[i], &widths[i], &heights[i], &err)) != RRV_OK) {
            print_library_error(&err);
            code = EXIT_INPUT;
        }
    }
    if (code == EXIT_OK && (widths[0] != widths[1] || heights[0] != heights[1])) {
        fprintf(stderr, "rrv: diff: size mismatch: %s is %dx%d, %s is %dx%d\n", paths[0],
                widths[0], heights[0], paths[1], widths[1], heights[1]);
        code = EXIT_INPUT;
    }
    if (code == EXIT_OK) {
        size_t n = (size_t)widths[0] * (size_t)heights[0] * 3, k, worst = 0, nonfinite = 0;
        double squared = 0, relative = 0, absolute = 0, worst_error = 0;
        for (k = 0; k < n; ++k) {
            double a = images[0][k], b = images[1][k], d = a - b, e = fabs(d);
            squared += d * d;
            relative += d * d / (b * b + 1e-2);
            absolute += e;
            if (!isfinite(a) || !isfinite(b)) ++nonfinite;
            /* A NaN is the worst error there is, so it wins the maximum. */
            if (e > worst_error || (isnan(e) && !isnan(worst_error))) {
                worst_error = e;
                worst = k;
            }
        }
        printf("width: %d\nheight: %d\n", widths[0], heights[0]);
        printf("rmse: %.9g\n", n ? sqrt(squared / (double)n) : 0.0);
        printf("relmse: %.9g\n", n ? relative / (double)n : 0.0);
        printf("mae: %.9g\n", n ? absolute / (double)n : 0.0);
        printf("max_abs_error: %.9g\n", worst_error);
        printf("max_abs_pixel: %d %d\n", (int)(worst / 3 % (size_t)widths[0]),
               (int)(worst / 3 / (size_t)widths[0]));
        printf("max_abs_channel: %c\n", channel_names[worst % 3]);
        printf("nonfinite: %lu\n", (unsigned long)nonfinite);
    }
    rrv_free(images[0]);
    rrv_free(images[1]);
    return code;
}

/* ---- rrv info -------------------------------------------------------------------- */

static const char *field_kind_name(rrv_field_kind kind)
{
    static const char *const names[] = {"none",  "constant", "blobs",   "noise", "grid",
                                        "luneburg", "fisheye", "slab", "shell", "nanovdb"};
    return (unsigned)kind < sizeof names / sizeof names[0] ? names[kind] : "unknown";
}

static void print_field(const char *label, const rrv_field *field)
{
    printf(", %s %s", label, field_kind_name(field->kind));
    if (field->kind == RRV_FIELD_GRID)
        printf(" %dx%dx%d", field->grid.nx, field->grid.ny, field->grid.nz);
    if (field->kind == RRV_FIELD_GRID && field->grid.channels != 1)
        printf("x%d", field->grid.channels);
    if (field->kind == RRV_FIELD_BLOBS) printf(" (%d)", field->blob_count);
}

/* One line a NanoVDB grid: what it holds, where, and what it costs. */
static void print_nanovdb(const char *label, const rrv_field *field)
{
    const rrv_nanovdb *g = &field->nanovdb;
    char text[64];
    if (field->kind != RRV_FIELD_NANOVDB) return;
    format_bytes((double)g->size, text, sizeof text);
    printf("    %s grid \"%s\": %s, %" PRIu64 " active voxels, index %" PRId64 " %" PRId64 " %" PRId64
           " .. %" PRId64 " %" PRId64 " %" PRId64 ", world %g %g %g .. %g %g %g, values %g .. %g"
           " (background %g), %s\n",
           label, g->name, rrv_nanovdb_type_name(g->type), g->active_voxels, g->active_lo[0],
           g->active_lo[1], g->active_lo[2], g->active_hi[0], g->active_hi[1], g->active_hi[2], g->lo.x,
           g->lo.y, g->lo.z, g->hi.x, g->hi.y, g->hi.z, g->value_min, g->value_max, g->background, text);
}

/* The coefficients, and how the channels group for free flights: a user
   whose render is slow on a strongly chromatic medium sees why. */
static void print_extinction(const rrv_medium *medium)
{
    static const char names[3] = {'R', 'G', 'B'};
    int group[3], groups = rrv_medium_channel_groups(medium, group), k, c;
    printf("    sigma_a %g %g %g, sigma_s %g %g %g, scale %g, g %g: extinction %g %g %g a unit of density",
           medium->sigma_a[0], medium->sigma_a[1], medium->sigma_a[2], medium->sigma_s[0], medium->sigma_s[1],
           medium->sigma_s[2], medium->scale, medium->g, (medium->sigma_a[0] + medium->sigma_s[0]) * medium->scale,
           (medium->sigma_a[1] + medium->sigma_s[1]) * medium->scale,
           (medium->sigma_a[2] + medium->sigma_s[2]) * medium->scale);
    if (groups > 1) {
        printf(", %d channel groups (", groups);
        for (k = 0; k < groups; ++k) {
            if (k) printf(" | ");
            for (c = 0; c < 3; ++c)
                if (group[c] == k) putchar(names[c]);
        }
        printf(": each walks with its own majorant)");
    }
    putchar('\n');
}

static void print_medium(const rrv_scene *scene, int index)
{
    const rrv_medium *medium = &scene->media[index];
    double jump[7];
    int f, any = 0;
    printf("  %s: box %g %g %g .. %g %g %g", medium->name, medium->lo.x, medium->lo.y,
           medium->lo.z, medium->hi.x, medium->hi.y, medium->hi.z);
    print_field("density", &medium->density);
    if (medium->temperature.kind != RRV_FIELD_NONE) print_field("temperature", &medium->temperature);
    if (medium->pressure.kind != RRV_FIELD_NONE) print_field("pressure", &medium->pressure);
    if (medium->ior.kind != RRV_FIELD_NONE)
        printf(", refracts (ior %s)", field_kind_name(medium->ior.kind));
    else if (medium->ior_from_gas)
        printf(", refracts (ior from gas temperature and pressure)");
    else
        printf(", does not refract");
    if (medium->ior.kind == RRV_FIELD_GRID)
        printf(" grid %dx%dx%d", medium->ior.grid.nx, medium->ior.grid.ny, medium->ior.grid.nz);
    putchar('\n');
    if (rrv_medium_face_jumps(scene, index, jump) > 0) {
        printf("    sharp IOR faces (eta jumps by):");
        for (f = 0; f < 7; ++f)
            if (jump[f] > 0) printf("%s %s %.3g", any++ ? "," : "", face_names[f], jump[f]);
        putchar('\n');
    }
    if (medium->density.kind != RRV_FIELD_NONE) print_extinction(medium);
    print_nanovdb("density", &medium->density);
    print_nanovdb("temperature", &medium->temperature);
    print_nanovdb("pressure", &medium->pressure);
    print_nanovdb("ior", &medium->ior);
}

static int command_info(int argc, char **argv)
{
    arg_cursor args;
    const char *scene_path = NULL;
    size_t max_grid_bytes = 0;
    rrv_scene *scene;
    int kind_counts[3] = {0, 0, 0}, i;
    char text[64];

    args.argc = argc;
    args.argv = argv;
    args.command = "info";
    for (args.index = 0; args.index < argc; ++args.index) {
        const char *arg = argv[args.index];
        if (is_help_flag(arg)) {
            fputs(info_help, stdout);
            return EXIT_OK;
        } else if (strcmp(arg, "--max-grid-mb") == 0) {
            if (!take_grid_limit(&args, &max_grid_bytes)) return EXIT_USAGE;
        } else if (is_flag(arg)) {
            char hint[80];
            return usage_error(&args, "info: unknown option \"%s\"%s", arg, flag_hint(arg, info_help, NULL, hint));
        } else if (scene_path) {
            return usage_error(&args, "info: unexpected argument \"%s\"", arg);
        } else {
            scene_path = arg;
        }
    }
    if (!scene_path) return usage_error(&args, "info needs a scene file");
    if (!load_scene(scene_path, max_grid_bytes, NULL, &scene, 0)) return EXIT_INPUT;

    for (i = 0; i < scene->shape_count; ++i)
        if ((unsigned)scene->shapes[i].kind < 3) kind_counts[scene->shapes[i].kind]++;

    printf("scene: %s\n", scene->path[0] ? scene->path : scene_path);
    printf("resolution: %dx%d\n", scene->camera.width, scene->camera.height);
    printf("spp: %d\n", scene->settings.spp);
    printf("max_depth: %d\n", scene->settings.max_depth);
    printf("seed: %" PRIu64 "\n", scene->settings.seed);
    if (scene->settings.integrator == RRV_INTEGRATOR_DEFAULT)
        printf("integrator: %s (the default for this scene)\n", integrator_name(rrv_scene_integrator(scene)));
    else
        printf("integrator: %s\n", integrator_name(scene->settings.integrator));
    if (rrv_scene_integrator(scene) != RRV_INTEGRATOR_CLASSIC)
        printf("nee: %s%s\n", nee_label(scene),
               scene->settings.nee == RRV_NEE_DEFAULT ? " (the default for this scene)" : "");
    if (rrv_scene_integrator(scene) == RRV_INTEGRATOR_EIKONAL) {
        if (scene->settings.step > 0)
            printf("step: %g m\n", scene->settings.step);
        else
            printf("step: placed by the field (a turn of %g rad a step at most)\n", scene->settings.bend_tolerance);
    }
    print_ambient(scene);
    printf("materials: %d\n", scene->material_count);
    printf("shapes: %d (%d spheres, %d quads, %d triangles)\n", scene->shape_count,
           kind_counts[RRV_SHAPE_SPHERE], kind_counts[RRV_SHAPE_QUAD],
           kind_counts[RRV_SHAPE_TRIANGLE]);
    printf("lights: %d\n", scene->light_count);
    print_light_samples(scene);
    {
        int sides;
        double guide = rrv_scene_bounce_guide(scene, &sides);
        if (guide > 0)
            printf("first bounces: %.3g %% toward the %d lit side%s of surfaces the emissive media light\n",
                   100 * guide, sides, sides == 1 ? "" : "s");
    }
    printf("media: %d\n", scene->medium_count);
    for (i = 0; i < scene->medium_count; ++i) print_medium(scene, i);
    printf("bvh_nodes: %d\n", scene->bvh_node_count);
    format_bytes((double)scene->bytes, text, sizeof text);
    printf("scene_memory: %s\n", text);
    format_bytes((double)scene->grid_bytes, text, sizeof text);
    printf("grid_memory: %s\n", text);
    format_bytes((double)scene->camera.width * scene->camera.height * 3 * sizeof(float), text,
                 sizeof text);
    printf("framebuffer: %s\n", text);
    rrv_scene_free(scene);
    return EXIT_OK;
}

/* ---- rrv trace ------------------------------------------------------------------- */

typedef struct trace_printer {
    uint64_t walk;
} trace_printer;

static void print_trace_vertex(void *user, rrv_vec3 position, rrv_vec3 direction)
{
    const trace_printer *printer = (const trace_printer *)user;
    printf("%" PRIu64 ",%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", printer->walk, position.x, position.y,
           position.z, direction.x, direction.y, direction.z);
}

/* Whether any medium bends light, by the library's own rule: the default
   integrator is classic exactly where nothing refracts (an IOR equal to the
   ambient one throughout included), so ask it with the scene's choice unset. */
static int scene_refracts(rrv_scene *scene)
{
    rrv_integrator chosen = scene->settings.integrator;
    int refracts;
    scene->settings.integrator = RRV_INTEGRATOR_DEFAULT;
    refracts = rrv_scene_integrator(scene) != RRV_INTEGRATOR_CLASSIC;
    scene->settings.integrator = chosen;
    return refracts;
}

static int command_trace(int argc, char **argv)
{
    arg_cursor args;
    const char *scene_path = NULL;
    size_t max_grid_bytes = 0;
    double ray[6];
    int has_ray = 0, has_integrator = 0, has_seed = 0, print_path = 0, i, code = EXIT_OK;
    rrv_integrator integrator = RRV_INTEGRATOR_REFRACTIVE;
    uint64_t seed = 0, walks = 1, walk;
    rrv_scene *scene;
    rrv_vec3 origin, direction;
    double length;
    refraction_options refraction;
    int taken;

    memset(&refraction, 0, sizeof refraction);
    args.argc = argc;
    args.argv = argv;
    args.command = "trace";
    for (args.index = 0; args.index < argc; ++args.index) {
        const char *arg = argv[args.index];
        if (is_help_flag(arg)) {
            printf(trace_help, refraction_help);
            return EXIT_OK;
        } else if (strcmp(arg, "--ray") == 0) {
            for (i = 0; i < 6; ++i)
                if (!take_double(&args, arg, "six numbers OX OY OZ DX DY DZ", &ray[i]))
                    return EXIT_USAGE;
            has_ray = 1;
        } else if (strcmp(arg, "--integrator") == 0) {
            if (!take_integrator(&args, 0, &integrator)) return EXIT_USAGE;
            has_integrator = 1;
        } else if (strcmp(arg, "--n") == 0) {
            if (!take_u64(&args, arg, "a positive integer", &walks)) return EXIT_USAGE;
            if (walks == 0)
                return usage_error(&args, "--n needs a positive integer, got \"0\"");
        } else if (strcmp(arg, "--seed") == 0) {
            if (!take_u64(&args, arg, "an integer >= 0", &seed)) return EXIT_USAGE;
            has_seed = 1;
        } else if (strcmp(arg, "--path") == 0) {
            print_path = 1;
        } else if (strcmp(arg, "--max-grid-mb") == 0) {
            if (!take_grid_limit(&args, &max_grid_bytes)) return EXIT_USAGE;
        } else if ((taken = take_refraction_option(&args, &refraction)) != 0) {
            if (taken < 0) return EXIT_USAGE;
        } else if (is_flag(arg)) {
            char hint[80];
            return usage_error(&args, "trace: unknown option \"%s\"%s", arg,
                               flag_hint(arg, trace_help, refraction_help, hint));
        } else if (scene_path) {
            return usage_error(&args, "trace: unexpected argument \"%s\"", arg);
        } else {
            scene_path = arg;
        }
    }
    if (!scene_path) return usage_error(&args, "trace needs a scene file");
    if (!has_ray) return usage_error(&args, "trace needs a ray: --ray OX OY OZ DX DY DZ");
    length = sqrt(ray[3] * ray[3] + ray[4] * ray[4] + ray[5] * ray[5]);
    if (!(length > 0) || !isfinite(length))
        return usage_error(&args, "--ray needs a nonzero, finite direction");
    origin.x = ray[0];
    origin.y = ray[1];
    origin.z = ray[2];
    direction.x = ray[3] / length;
    direction.y = ray[4] / length;
    direction.z = ray[5] / length;

    if (!load_scene(scene_path, max_grid_bytes, NULL, &scene, 0)) return EXIT_INPUT;
    if (!apply_refraction_options(scene, &refraction)) {
        rrv_scene_free(scene);
        return EXIT_INPUT;
    }
    if (!has_integrator && rrv_scene_integrator(scene) != RRV_INTEGRATOR_CLASSIC)
        integrator = rrv_scene_integrator(scene);
    if (!has_seed) seed = scene->settings.seed;
    if (!scene_refracts(scene))
        fprintf(stderr, "rrv: trace: %s has no refracting medium; the ray goes straight\n", scene_path);

    puts(print_path ? "walk,x,y,z,dx,dy,dz" : "x,y,z,dx,dy,dz,events");
    for (walk = 0; walk < walks; ++walk) {
        trace_printer printer;
        rrv_trace_result result;
        rrv_error err;
        printer.walk = walk;
        memset(&result, 0, sizeof result);
        memset(&err, 0, sizeof err);
        if (rrv_trace_ray(scene, integrator, origin, direction, seed, walk,
                          print_path ? print_trace_vertex : NULL, &printer, &result,
                          &err) != RRV_OK) {
            fflush(stdout);
            print_library_error(&err);
            code = EXIT_INPUT;
            break;
        }
        if (!print_path)
            printf("%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%" PRIu64 "\n", result.position.x,
                   result.position.y, result.position.z, result.direction.x,
                   result.direction.y, result.direction.z, result.events);
    }
    rrv_scene_free(scene);
    return code;
}

/* ---- main ------------------------------------------------------------------------ */

static int show_help(const char *command)
{
    if (!command) {
        fputs(usage_text, stdout);
    } else if (strcmp(command, "render") == 0) {
        printf(render_help, refraction_help);
    } else if (strcmp(command, "diff") == 0) {
        fputs(diff_help, stdout);
    } else if (strcmp(command, "merge") == 0) {
        fputs(merge_help, stdout);
    } else if (strcmp(command, "farm") == 0) {
        fputs(farm_help, stdout);
    } else if (strcmp(command, "info") == 0) {
        fputs(info_help, stdout);
    } else if (strcmp(command, "trace") == 0) {
        printf(trace_help, refraction_help);
    } else {
        char hint[80];
        return usage_error(NULL, "help: unknown command \"%s\"%s", command, command_hint(command, hint));
    }
    return EXIT_OK;
}

int main(int argc, char **argv)
{
    const char *command;
    int code;
    if (argc < 2) {
        fputs(usage_text, stderr);
        return EXIT_USAGE;
    }
    command = argv[1];
    if (is_help_flag(command) || strcmp(command, "help") == 0) {
        if (argc > 3) return usage_error(NULL, "help takes at most one command");
        code = show_help(argc == 3 ? argv[2] : NULL);
    } else if (strcmp(command, "--version") == 0) {
        printf("rrv %d.%d.%d%s\n", RRV_VERSION_MAJOR, RRV_VERSION_MINOR, RRV_VERSION_PATCH,
               RRV_THREADS ? "" : " (without threads)");
        code = EXIT_OK;
    } else if (strcmp(command, "render") == 0) {
        code = command_render(argc - 2, argv + 2);
    } else if (strcmp(command, "diff") == 0) {
        code = command_diff(argc - 2, argv + 2);
    } else if (strcmp(command, "merge") == 0) {
        code = command_merge(argc - 2, argv + 2);
    } else if (strcmp(command, "farm") == 0) {
        code = command_farm(argc - 2, argv + 2);
    } else if (strcmp(command, "info") == 0) {
        code = command_info(argc - 2, argv + 2);
    } else if (strcmp(command, "trace") == 0) {
        code = command_trace(argc - 2, argv + 2);
    } else if (is_flag(command)) {
        char hint[80];
        code = usage_error(NULL, "unknown option \"%s\"%s", command, flag_hint(command, usage_text, NULL, hint));
    } else {
        char hint[80];
        code = usage_error(NULL, "unknown command \"%s\"%s", command, command_hint(command, hint));
    }
    return finish_stdout(code);
}
