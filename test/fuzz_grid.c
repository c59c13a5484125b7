/* libFuzzer harness for the gridvol reader: `make fuzz`, then
       rm -rf /tmp/grid-seeds && cp -r test/corpus /tmp/grid-seeds
       ./build-fuzz/fuzz_grid -max_total_time=60 /tmp/grid-seeds
   The limit is small so hostile headers are refused before allocating. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    rrv_grid grid;
    rrv_error err;
    int nonnegative;
    for (nonnegative = 0; nonnegative < 2; ++nonnegative) {
        rrv_result r = rrv_grid_read_memory(data, size, "fuzz.vol", 1 << 16, nonnegative, &grid, &err);
        if (r == RRV_OK) {
            size_t i, n = (size_t)grid.nx * (size_t)grid.ny * (size_t)grid.nz * (size_t)grid.channels;
            if (!grid.data || grid.nx < 2 || grid.ny < 2 || grid.nz < 2 ||
                (grid.channels != 1 && grid.channels != 3) || n * 4 + 48 != size ||
                !(grid.lo.x < grid.hi.x && grid.lo.y < grid.hi.y && grid.lo.z < grid.hi.z))
                abort();
            for (i = 0; i < n; ++i)
                if (grid.data[i] != grid.data[i] || (nonnegative && grid.data[i] < 0)) abort();
            rrv_free(grid.data);
        } else if (grid.data != NULL || err.message[0] == '\0') {
            abort();
        }
    }
    return 0;
}
