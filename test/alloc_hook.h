/* The allocator and settings that tests of the internals build the library
   with (include before the implementation): every allocation passes through
   counters, so test_parser can see the largest request (the grid size limit
   must trip before allocating) and refuse the Nth (every failure must be
   clean), and test_nee can refuse one (the render context's chain for nee
   manifold). nee aim aims only where a ray will likely land (RRV__AIM_REACH,
   1 in the header); test_nee's tests of strong media aim everywhere, so that
   the aimed estimator itself is checked where refraction turns most rays
   off. With the counters at rest (-1) and aim_reach 1 the library behaves as
   it does with its own defaults, so the other internal tests share this
   build of it (test/internals.c). */
#ifndef RRV_TEST_ALLOC_HOOK_H
#define RRV_TEST_ALLOC_HOOK_H
#include <stdlib.h>

static long allocations_to_pass = -1; /* malloc: these pass, then one is refused; -1: none is */
static size_t t_largest;              /* largest single request since reset */
static long t_alloc_count;            /* requests since reset */
static long t_fail_at = -1;           /* request index to refuse, -1: none */

static void *t_malloc(size_t n)
{
    if (allocations_to_pass == 0) {
        allocations_to_pass = -1;
        return NULL;
    }
    if (allocations_to_pass > 0) --allocations_to_pass;
    if (t_fail_at >= 0 && t_alloc_count++ == t_fail_at) return NULL;
    if (n > t_largest) t_largest = n;
    return malloc(n);
}
static void *t_realloc(void *p, size_t n)
{
    if (t_fail_at >= 0 && t_alloc_count++ == t_fail_at) return NULL;
    if (n > t_largest) t_largest = n;
    return realloc(p, n);
}
static double aim_reach = 1.0;
#define RRV__AIM_REACH aim_reach
#define RRV_MALLOC(sz) t_malloc(sz)
#define RRV_REALLOC(p, sz) t_realloc(p, sz)
#define RRV_FREE(p) free(p)
#endif
