/* libFuzzer harness for the PFM reader (rrv_read_pfm_memory, which `rrv
   diff` and rrv_read_pfm use) and, on what it accepts, the PFM and PNG
   writers: `make fuzz`, then `make fuzz-run`, or by hand on a scratch copy
   of some seeds, e.g.
       mkdir -p /tmp/pfm-seeds && ./rrv render scenes/smoke.rrv --spp 1 -o /tmp/pfm-seeds/a.pfm
       ./build-fuzz/fuzz_pfm -max_total_time=60 /tmp/pfm-seeds
   Contract checked: a failure says something and hands back no image; an
   accepted image fits in the input (so a hostile header can never make the
   reader allocate more than the file holds), and writing it as PFM and
   reading that back gives the same bits, NaN payloads included. */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include <stdlib.h>

typedef struct sink {
    unsigned char *data;
    size_t size, capacity;
} sink;

static int sink_write(void *user, const void *data, size_t size)
{
    sink *s = (sink *)user;
    if (size > s->capacity - s->size) {
        size_t cap = s->capacity ? s->capacity : 256;
        unsigned char *grown;
        while (cap - s->size < size) cap *= 2;
        grown = (unsigned char *)realloc(s->data, cap);
        if (!grown) return 1;
        s->data = grown;
        s->capacity = cap;
    }
    memcpy(s->data + s->size, data, size);
    s->size += size;
    return 0;
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size)
{
    float *rgb = NULL, *again = NULL;
    int w = -1, h = -1, w2 = 0, h2 = 0;
    rrv_error err;
    sink pfm = {NULL, 0, 0}, png = {NULL, 0, 0};
    size_t floats;
    double exposure;
    rrv_result r = rrv_read_pfm_memory(data, size, "fuzz.pfm", &rgb, &w, &h, &err);
    if (r != RRV_OK) {
        if (rgb != NULL || w != 0 || h != 0 || err.code != r || err.message[0] == '\0' ||
            memchr(err.message, 0, sizeof err.message) == NULL)
            abort();
        return 0;
    }
    /* grey images store 1 float a pixel, colour 3; both must fit in the input */
    if (!rgb || w <= 0 || h <= 0 || (size_t)w * (size_t)h * (data[1] == 'F' ? 12u : 4u) > size) abort();
    floats = (size_t)w * (size_t)h * 3;
    if (rrv_write_pfm_to(sink_write, &pfm, rgb, w, h, NULL) != RRV_OK) abort();
    if (rrv_read_pfm_memory(pfm.data, pfm.size, "again.pfm", &again, &w2, &h2, &err) != RRV_OK) abort();
    if (w2 != w || h2 != h || memcmp(rgb, again, floats * sizeof(float)) != 0) abort();
    /* Any exposure the image itself suggests, so odd gains are tried too. */
    exposure = isfinite(rgb[0]) ? rgb[0] : 0.0;
    if (rrv_write_png_to(sink_write, &png, rgb, w, h, exposure, NULL) != RRV_OK) abort();
    if (png.size < 8 + 25 + 12 || memcmp(png.data + 1, "PNG", 3) != 0) abort();
    free(pfm.data);
    free(png.data);
    rrv_free(rgb);
    rrv_free(again);
    return 0;
}
