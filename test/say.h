/* Tests that stay quiet unless asked: SAY prints the measured values only
   when the program's NAME_VERBOSE variable is set to something other than
   0 (say_from_env, at the start of main). */
#ifndef RRV_TEST_SAY_H
#define RRV_TEST_SAY_H
#include <stdio.h>
#include <stdlib.h>

static int verbose;
#define SAY(...)                                                                                                       \
    do {                                                                                                               \
        if (verbose) printf(__VA_ARGS__);                                                                              \
    } while (0)

static void say_from_env(const char *name)
{
    const char *v = getenv(name);
    verbose = v && *v && *v != '0';
}
#endif
