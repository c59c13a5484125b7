/* Library hygiene: the implementation never prints, exits or aborts (only
   main.c talks to the user), and the header builds as a static copy
   (RRV_STATIC) and included twice without complaint. */
#define RRV_STATIC
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "../rrv.h"
#include "check.h"
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

int main(int argc, char **argv)
{
    (void)argc; (void)argv;
    RUN(test_library_never_prints_or_exits);
    RUN(test_static_build_links);
    return CHECK_EXIT_CODE();
}
