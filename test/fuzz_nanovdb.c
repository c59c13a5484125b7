/* libFuzzer harness for the NanoVDB reader: `make fuzz`, then seed it with
   real files (test_nanovdb leaves them in the folder build/nanovdb_tmp)
   and the corpus headers:
       rm -rf /tmp/nvdb-seeds && mkdir /tmp/nvdb-seeds
       cp build/nanovdb_tmp/fields*.nvdb test/corpus/nanovdb_bad_magic.nvdb /tmp/nvdb-seeds
       ./build-fuzz/fuzz_nanovdb -max_len=2000000 -max_total_time=60 /tmp/nvdb-seeds
   Whatever the input, a read either fails with a message or gives a grid
   whose every lookup stays inside its buffer (ASan) and within the value
   range the reader reported. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    static const char *const names[3] = {"density", "temperature", "sparse"};
    int n;
    for (n = 0; n < 3; ++n) {
        rrv_nanovdb g;
        rrv_error err;
        rrv_result r = rrv_nanovdb_read_memory(data, size, "fuzz.nvdb", names[n], 1 << 26, &g, &err);
        if (r == RRV_OK) {
            uint32_t h = (uint32_t)size * 2654435761u;
            int i;
            double bound = rrv__nv_bound(&g, g.lo, g.hi);
            if (!g.buffer || bound > g.value_max || bound < g.background) abort();
            for (i = 0; i < 64; ++i) {
                double t[3], v;
                int a;
                for (a = 0; a < 3; ++a) {
                    h = h * 1664525u + 1013904223u;
                    t[a] = (double)(h >> 8) / 16777216.0;
                }
                v = rrv_nanovdb_sample(&g, rrv__v3(g.lo.x + (g.hi.x - g.lo.x) * t[0], g.lo.y + (g.hi.y - g.lo.y) * t[1],
                                                   g.lo.z + (g.hi.z - g.lo.z) * t[2]));
                if (!(v >= g.value_min && v <= g.value_max)) abort();
                v = rrv_nanovdb_voxel(&g, g.data_lo[0] + (int64_t)(h % 64u), g.data_lo[1] + (int64_t)(h % 8u),
                                      g.data_lo[2] + (int64_t)(h % 16u));
                if (!(v >= g.value_min && v <= g.value_max)) abort();
            }
            rrv_nanovdb_free(&g);
        } else if (err.message[0] == '\0') {
            abort();
        }
    }
    return 0;
}
