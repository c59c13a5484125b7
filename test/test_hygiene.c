/* Library hygiene: the implementation never prints, exits or aborts (only
   main.c talks to the user), and the header builds as a static copy
   (RRV_STATIC) and included twice without complaint. */
#define RRV_STATIC
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "../rrv.h"
#include "check.h"
#include <ctype.h>
#include <stdlib.h>
#include <string.h>

static char *read_all(const char *path)
{
    FILE *f = fopen(path, "rb");
    long n;
    char *text;
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    text = (char *)malloc((size_t)n + 1);
    if (fread(text, 1, (size_t)n, f) != (size_t)n) n = 0;
    text[n] = '\0';
    fclose(f);
    return text;
}

/* Blanks out comments and string literals so only code is searched. */
static void strip_comments_and_strings(char *s)
{
    char *p = s;
    while (*p) {
        if (p[0] == '/' && p[1] == '*') {
            char *end = strstr(p + 2, "*/");
            char *stop = end ? end + 2 : p + strlen(p);
            memset(p, ' ', (size_t)(stop - p));
            p = stop;
        } else if (p[0] == '/' && p[1] == '/') {
            while (*p && *p != '\n') *p++ = ' ';
        } else if (*p == '"') {
            *p++ = ' ';
            while (*p && *p != '"') {
                if (*p == '\\' && p[1]) *p++ = ' ';
                *p++ = ' ';
            }
            if (*p) *p++ = ' ';
        } else {
            ++p;
        }
    }
}

static void test_library_never_prints_or_exits(void)
{
    static const char *const forbidden[] = {"printf(", "fprintf(", "puts(", "putchar(", "perror(",
                                            "exit(", "abort(", "stderr", "stdout"};
    char *text = read_all("rrv.h"), *impl;
    size_t i;
    CHECK(text != NULL);
    if (!text) return;
    impl = strstr(text, "#ifdef RRV_IMPLEMENTATION");
    CHECK(impl != NULL);
    if (!impl) { free(text); return; }
    strip_comments_and_strings(impl);
    for (i = 0; i < sizeof forbidden / sizeof *forbidden; ++i) {
        const char *hit = strstr(impl, forbidden[i]);
        /* snprintf/vsnprintf format into buffers and are allowed */
        while (hit && hit > impl && (hit[-1] == 'n' || hit[-1] == 'v' || hit[-1] == '_' || hit[-1] == 's'))
            hit = strstr(hit + 1, forbidden[i]);
        CHECKF(hit == NULL, "the implementation uses %s", forbidden[i]);
    }
    free(text);
}

static void test_static_build_links(void)
{
    /* With RRV_STATIC every public function is static to this file; calling
       one proves the definitions are here and usable. */
    CHECK(strcmp(rrv_result_string(RRV_OK), "ok") == 0);
    CHECK(strcmp(rrv_result_string((rrv_result)999), "unknown result") == 0);
    CHECK(rrv_crc32(0, "123456789", 9) == 0xCBF43926u);
}

/* The manual's FUNCTIONS list names every public function, so an embedder
   reading only the first screen misses none. */
static void test_manual_lists_every_function(void)
{
    char *text = read_all("rrv.h"), *list, *end, *p;
    int count = 0;
    CHECK(text != NULL);
    if (!text) return;
    list = strstr(text, "FUNCTIONS (");
    end = list ? strstr(list, "CONFIGURATION (") : NULL;
    CHECKF(list && end, "rrv.h has no FUNCTIONS section before CONFIGURATION");
    if (list && end) {
        for (p = strstr(text, "\nRRV_DEF "); p; p = strstr(p + 1, "\nRRV_DEF ")) {
            char name[64];
            const char *paren = strchr(p, '('), *start = paren;
            size_t n;
            if (!paren) break;
            while (start > p && (start[-1] == '_' || isalnum((unsigned char)start[-1]))) --start;
            n = (size_t)(paren - start);
            if (n == 0 || n >= sizeof name) continue;
            memcpy(name, start, n);
            name[n] = '\0';
            ++count;
            {
                /* as a whole word inside the list */
                const char *q = list;
                int found = 0;
                while ((q = strstr(q, name)) != NULL && q < end) {
                    char after = q[n];
                    if (!(after == '_' || isalnum((unsigned char)after))) { found = 1; break; }
                    q += n;
                }
                CHECKF(found, "%s is not in the manual's FUNCTIONS list", name);
            }
        }
    }
    CHECKF(count > 20, "found only %d public functions", count);
    free(text);
}

/* The manual before the declarations stays one reading: at most 200
   lines, with the sections an embedder looks for, in this order. */
static void test_manual_fits_before_the_declarations(void)
{
    static const char *const sections[] = {"---- example ----", "INTEGRATORS (",
                                           "NEXT-EVENT ESTIMATION (", "READING MAP (",
                                           "USAGE\n", "FUNCTIONS (", "CONFIGURATION (",
                                           "CONVENTIONS ("};
    char *text = read_all("rrv.h"), *guard, *at;
    int lines = 0;
    size_t i;
    CHECK(text != NULL);
    if (!text) return;
    guard = strstr(text, "\n#ifndef RRV_H_INCLUDED");
    CHECKF(guard != NULL, "rrv.h has no include guard");
    if (guard) {
        for (at = text; at <= guard; ++at) lines += *at == '\n'; /* lines above the guard */
        CHECKF(lines <= 200, "the manual is %d lines before the declarations (at most 200)", lines);
        for (at = text, i = 0; i < sizeof sections / sizeof *sections; ++i) {
            char *found = strstr(at, sections[i]);
            CHECKF(found && found < guard, "the manual has no \"%s\" after the previous section",
                   sections[i]);
            if (found) at = found;
        }
    }
    free(text);
}

int main(int argc, char **argv)
{
    (void)argc; (void)argv;
    RUN(test_library_never_prints_or_exits);
    RUN(test_static_build_links);
    RUN(test_manual_lists_every_function);
    RUN(test_manual_fits_before_the_declarations);
    return CHECK_EXIT_CODE();
}
