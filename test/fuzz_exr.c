/* libFuzzer harness for the OpenEXR reader: `make build-fuzz/fuzz_exr`, then
       mkdir -p /tmp/exr-seeds && cp build/exr_check_*.exr /tmp/exr-seeds
       ./build-fuzz/fuzz_exr -max_total_time=60 /tmp/exr-seeds
   (the seeds are the files `make test` writes, from rrv and from OpenEXR).
   A file that reads must round-trip through the writer as FLOAT. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>
#include <string.h>
#include <limits.h>

static int discard(void *user, const void *data, size_t size)
{
    (void)user;
    (void)data;
    (void)size;
    return 0;
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    float *rgb = (float *)&size; /* must be reset */
    int width = -1, height = -1;
    rrv_exr_options info;
    rrv_error err;
    rrv_result r = rrv_read_exr_memory(data, size, "fuzz.exr", &rgb, &width, &height, &info, &err);
    const char *type;
    const void *value;
    size_t value_size;
    /* Any header: a found attribute lies inside the data. */
    if (rrv_exr_find_attribute(data, size, "rrvPart", &type, &value, &value_size) == RRV_OK &&
        ((const unsigned char *)value < data || value_size > size - (size_t)((const unsigned char *)value - data)))
        abort();
    if (r == RRV_OK) {
        size_t i, n;
        if (!rgb || width <= 0 || height <= 0) abort();
        n = (size_t)width * (size_t)height * 3;
        for (i = 0; i < n; ++i) {
            volatile float v = rgb[i]; /* every value was written */
            (void)v;
        }
        info.pixel = RRV_EXR_FLOAT;
        if (width < 4096 && (long long)info.x + width - 1 <= INT_MAX &&
            (long long)info.y + height - 1 <= INT_MAX &&
            rrv_write_exr_to(discard, NULL, rgb, width, height, &info, NULL) != RRV_OK)
            abort();
        rrv_free(rgb);
    } else if (rgb != NULL || width != 0 || height != 0 || err.message[0] == '\0') {
        abort();
    }
    return 0;
}
