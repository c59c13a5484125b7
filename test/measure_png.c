/* PNG sizes before and after rrv's deflate. Not a test (make test only
   builds it):
     build/measure_png scenes/images/[a-z]*.png
   Each 8-bit RGB PNG is inflated by test/inflate.h and unfiltered, its
   bytes are turned back into the linear floats they encode, rrv_write_png_to
   writes them again, and the new file is decoded the same way and compared
   pixel by pixel with the old one. It prints both sizes and the deflate
   block types of each. With --rewrite it replaces each file by the new one
   (only when the pixels are identical). */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "inflate.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct bytes {
    unsigned char *data;
    size_t size, capacity;
} bytes;

static int append(void *user, const void *data, size_t size)
{
    bytes *b = (bytes *)user;
    if (b->size + size > b->capacity) {
        size_t capacity = 2 * (b->size + size);
        unsigned char *grown = (unsigned char *)realloc(b->data, capacity);
        if (!grown) return 1;
        b->data = grown;
        b->capacity = capacity;
    }
    memcpy(b->data + b->size, data, size);
    b->size += size;
    return 0;
}

static uint32_t be32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

static int paeth(int a, int b, int c)
{
    int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
    if (pa <= pb && pa <= pc) return a;
    return pb <= pc ? b : c;
}

/* The RGB bytes of an 8-bit RGB PNG (rows top first), or NULL. */
static unsigned char *decode(const unsigned char *p, size_t size, int *width, int *height, int blocks[3])
{
    size_t pos = 8, z_size = 0, stride, raw_size;
    unsigned char *z = (unsigned char *)malloc(size), *raw, *rgb;
    int x, y;
    *width = *height = 0;
    if (!z || size < 8 || memcmp(p, "\211PNG\r\n\032\n", 8) != 0) { free(z); return NULL; }
    while (pos + 12 <= size) {
        uint32_t length = be32(p + pos);
        if (length > size - pos - 12) break;
        if (memcmp(p + pos + 4, "IHDR", 4) == 0 && length == 13) {
            if (p[pos + 16] != 8 || p[pos + 17] != 2 || p[pos + 20] != 0) { free(z); return NULL; }
            *width = (int)be32(p + pos + 8);
            *height = (int)be32(p + pos + 12);
        } else if (memcmp(p + pos + 4, "IDAT", 4) == 0) {
            memcpy(z + z_size, p + pos + 8, length);
            z_size += length;
        }
        pos += 12 + length;
    }
    if (*width <= 0 || *height <= 0) { free(z); return NULL; }
    stride = 1 + 3 * (size_t)*width;
    raw_size = stride * (size_t)*height;
    raw = (unsigned char *)malloc(raw_size + 1);
    rgb = (unsigned char *)malloc(raw_size);
    if (!raw || !rgb || zlib_inflate_blocks(z, z_size, raw, raw_size + 1, blocks) != raw_size) {
        free(z); free(raw); free(rgb);
        return NULL;
    }
    for (y = 0; y < *height; ++y) {
        unsigned char *row = raw + (size_t)y * stride, *out = rgb + (size_t)y * (stride - 1);
        const unsigned char *up = y > 0 ? out - (stride - 1) : NULL;
        int filter = row[0];
        for (x = 0; x < (int)stride - 1; ++x) {
            int a = x >= 3 ? out[x - 3] : 0, b = up ? up[x] : 0, c = x >= 3 && up ? up[x - 3] : 0;
            int predicted = filter == 0 ? 0 : filter == 1 ? a : filter == 2 ? b
                          : filter == 3 ? (a + b) / 2 : paeth(a, b, c);
            out[x] = (unsigned char)(row[1 + x] + predicted);
        }
    }
    free(z);
    free(raw);
    return rgb;
}

int main(int argc, char **argv)
{
    size_t before = 0, after = 0;
    int i, rewrite = 0, failures = 0;
    for (i = 1; i < argc; ++i) {
        bytes old = { NULL, 0, 0 }, fresh = { NULL, 0, 0 };
        unsigned char chunk[65536], *pixels = NULL, *again = NULL;
        int width, height, width2, height2, old_blocks[3] = { 0, 0, 0 }, new_blocks[3] = { 0, 0, 0 };
        float *rgb = NULL;
        size_t n, k;
        FILE *f;
        if (strcmp(argv[i], "--rewrite") == 0) { rewrite = 1; continue; }
        f = fopen(argv[i], "rb");
        if (!f) { fprintf(stderr, "%s: cannot open\n", argv[i]); ++failures; continue; }
        while ((n = fread(chunk, 1, sizeof chunk, f)) > 0) append(&old, chunk, n);
        fclose(f);
        pixels = decode(old.data, old.size, &width, &height, old_blocks);
        if (pixels) rgb = (float *)malloc(3 * (size_t)width * (size_t)height * sizeof *rgb);
        if (!pixels || !rgb) {
            fprintf(stderr, "%s: not an 8-bit RGB PNG this tool reads\n", argv[i]);
            ++failures;
        } else {
            /* the linear value at the centre of each byte's sRGB interval */
            for (k = 0; k < 3 * (size_t)width * (size_t)height; ++k) {
                double e = pixels[k] / 255.0;
                rgb[k] = (float)(e <= 0.04045 ? e / 12.92 : pow((e + 0.055) / 1.055, 2.4));
            }
            if (rrv_write_png_to(append, &fresh, rgb, width, height, 0.0, NULL) == RRV_OK)
                again = decode(fresh.data, fresh.size, &width2, &height2, new_blocks);
            if (!again || width2 != width || height2 != height
                || memcmp(again, pixels, 3 * (size_t)width * (size_t)height) != 0) {
                fprintf(stderr, "%s: the rewritten PNG does not hold the same pixels\n", argv[i]);
                ++failures;
            } else {
                printf("%-38s %4dx%-4d %8lu B (%d stored, %d fixed, %d dynamic) -> %8lu B (%d stored, %d fixed, %d dynamic)\n",
                       argv[i], width, height, (unsigned long)old.size, old_blocks[0], old_blocks[1], old_blocks[2],
                       (unsigned long)fresh.size, new_blocks[0], new_blocks[1], new_blocks[2]);
                before += old.size;
                after += fresh.size;
                if (rewrite) {
                    f = fopen(argv[i], "wb");
                    if (!f || fwrite(fresh.data, 1, fresh.size, f) != fresh.size) ++failures;
                    if (f && fclose(f) != 0) ++failures;
                }
            }
        }
        free(old.data);
        free(fresh.data);
        free(pixels);
        free(again);
        free(rgb);
    }
    if (before > 0)
        printf("total %lu B -> %lu B (%.1f%%)\n", (unsigned long)before, (unsigned long)after, 100.0 * (double)after / (double)before);
    return failures ? 1 : 0;
}
