/* The tests of rrv's internals (rrv__ functions and structures) as one
   program, so that the 15,000-line implementation is compiled once for all
   of them instead of once each: make test builds and runs this, not the
   standalone programs, which `make build/test_grin` and the like still
   build. Each test's main is renamed and called in turn with the same
   arguments; it prints its own PASS and FAIL lines, and the check counts
   of check.h add up across them. The library is built with the counting
   allocator of alloc_hook.h, which test_nee and test_parser need and which
   at rest behaves as the default; test_hygiene (RRV_STATIC) stays a
   program of its own. test_emission and test_lm joined in 2026-12: each
   standalone build was another 7 s of CPU compiling the implementation at
   -O2 (test/bench/RESULTS.md, "The cost of `make test`").
   Two files that define the same static name get it renamed here for one
   of them, around its #include (the compiler reports any new clash). */
#define _POSIX_C_SOURCE 200809L
#include "alloc_hook.h"
#define RRV_RESEARCH /* the midpoint scheme and the leapfrog stepper, which the tests here cover too */
#define RRV_IMPLEMENTATION
#include "../rrv.h"

#define main test_bake_cap_main
#define load bake_cap_load
#include "test_bake_cap.c"
#undef main
#undef load

#define main test_boundaries_main
#include "test_boundaries.c"
#undef main

#define main test_budget_main
#include "test_budget.c"
#undef main

#define main test_grin_main
#define prepare grin_prepare
#define set_method grin_set_method
#define trace grin_trace
#define slab_scene grin_slab_scene
#define slab_eta grin_slab_eta
#define stat grin_stat
#include "test_grin.c"
#undef main
#undef prepare
#undef set_method
#undef trace
#undef slab_scene
#undef slab_eta
#undef stat

#define main test_hessian_main
#define prepare hessian_prepare
#include "test_hessian.c"
#undef main
#undef prepare

#define main test_nanovdb_main
#include "test_nanovdb.c"
#undef main

#define main test_render_main
#include "test_render.c"
#undef main

#define main test_nee_main
#define method nee_method
#define stats nee_stats
#define stats_add nee_stats_add
#define stats_mean nee_stats_mean
#define stats_se nee_stats_se
#define solver_context nee_solver_context
#define blob_scene nee_blob_scene
#include "test_nee.c"
#undef main
#undef method
#undef stats
#undef stats_add
#undef stats_mean
#undef stats_se
#undef solver_context
#undef blob_scene

#define main test_transmittance_main
#include "test_transmittance.c"
#undef main

#define main test_emission_main
#define load emission_load
#include "test_emission.c"
#undef main
#undef load

#define main test_equiangular_main
#include "test_equiangular.c"
#undef main

#define main test_lights_main
#include "test_lights.c"
#undef main

/* test_lm.c asks for an older POSIX than the one above; the system headers
   are in by now, so the macro only has to be put back for the files after. */
#undef _POSIX_C_SOURCE
#define main test_lm_main
#include "test_lm.c"
#undef main
#undef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L

#define main test_parser_main
#define put32 parser_put32
#include "test_parser.c"
#undef main
#undef put32

int main(int argc, char **argv)
{
    int failed = 0;
    failed |= test_bake_cap_main();
    failed |= test_boundaries_main(argc, argv);
    failed |= test_budget_main();
    failed |= test_grin_main(argc, argv);
    failed |= test_hessian_main();
    failed |= test_nanovdb_main(argc, argv);
    failed |= test_render_main(argc, argv);
    failed |= test_nee_main();
    failed |= test_emission_main();
    failed |= test_equiangular_main();
    failed |= test_lights_main();
    failed |= test_lm_main();
    failed |= test_parser_main(argc, argv);
    failed |= test_transmittance_main();
    return failed ? 1 : 0;
}
