/* The measurement programs (test/measure_*.c) as one program, which make
   test builds unoptimised (and never runs) so that they cannot rot between
   benchmark runs: the implementation is compiled once for all five instead
   of once each (7.3 s of CPU at -O0 with gcc, 1.5 s each). make bench still
   builds each on its own, optimised. measure_nanovdb's _POSIX_C_SOURCE
   comes first, as it must before any system header; a name two files
   define is renamed here around the second's #include. */
#define _POSIX_C_SOURCE 200809L
#define RRV_RESEARCH /* the midpoint scheme and the leapfrog stepper, which the tables measure too */
#define RRV_IMPLEMENTATION
#include "../rrv.h"

#define main measure_grin_main
#include "measure_grin.c"
#undef main

#define main measure_nanovdb_main
#include "measure_nanovdb.c"
#undef main

#define main measure_png_main
#include "measure_png.c"
#undef main

#define main measure_tracking_main
#include "measure_tracking.c"
#undef main

#define main measure_transmittance_main
#define seconds transmittance_seconds
#define cmp_double transmittance_cmp_double
#define median transmittance_median
#include "measure_transmittance.c"
#undef main
#undef seconds
#undef cmp_double
#undef median

int main(int argc, char **argv)
{
    /* built to be compiled and linked, not run: make bench runs each */
    (void)measure_grin_main;
    (void)measure_nanovdb_main;
    (void)measure_png_main;
    (void)measure_tracking_main;
    (void)measure_transmittance_main;
    (void)argc;
    (void)argv;
    return 0;
}
