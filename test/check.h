/* A tiny test harness: each test program runs named tests with RUN(fn);
   every CHECK that fails prints where and why, and RUN prints one
   "PASS name" or "FAIL name" line that test/run_tests.sh counts. */
#ifndef RRV_TEST_CHECK_H
#define RRV_TEST_CHECK_H
#include <stdio.h>

static int check__failed_in_test;
static int check__tests_failed;

#define CHECK(cond)                                                            \
    do {                                                                       \
        if (!(cond)) {                                                         \
            check__failed_in_test = 1;                                         \
            printf("  %s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);  \
        }                                                                      \
    } while (0)

/* CHECK with a printf-style explanation of the values involved. */
#define CHECKF(cond, ...)                                                      \
    do {                                                                       \
        if (!(cond)) {                                                         \
            check__failed_in_test = 1;                                         \
            printf("  %s:%d: check failed: %s: ", __FILE__, __LINE__, #cond);  \
            printf(__VA_ARGS__);                                               \
            printf("\n");                                                      \
        }                                                                      \
    } while (0)

#define RUN(fn)                                                                \
    do {                                                                       \
        check__failed_in_test = 0;                                             \
        fn();                                                                  \
        printf("%s %s\n", check__failed_in_test ? "FAIL" : "PASS", #fn);      \
        fflush(stdout);                                                        \
        check__tests_failed += check__failed_in_test;                          \
    } while (0)

#define CHECK_EXIT_CODE() (check__tests_failed ? 1 : 0)
#endif
