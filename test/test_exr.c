/* Tests of the OpenEXR writer at the byte level: the magic and version, every
   header attribute, the offset table against the chunks, pixels decoded
   here from uncompressed and ZIP files (with an inflate written for this
   test, sharing nothing with the library's deflate), the float-to-half
   conversion exhaustively, argument and I/O errors, the file form, the CLI's
   choice of format, and the reader (round trips, damaged files). Last,
   test/exr_check.cpp reads the files with the OpenEXR library itself; that
   test fails when OpenEXR was missing at build time. */
#if defined(__unix__) || defined(__APPLE__)
#define _POSIX_C_SOURCE 200809L
#endif
#include "../rrv.h"
#include "check.h"
#include "inflate.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#if defined(__unix__) || defined(__APPLE__)
#include <sys/wait.h>
#endif

static const char *build_dir = ".";
/* Output pointers start here so a test can see that a failing call reset them. */
static float not_reset_value;

/* ---- helpers ------------------------------------------------------------------ */

typedef struct byte_sink {
    unsigned char *data;
    size_t size, capacity, fail_after;
    int calls;
} byte_sink;

static int sink_write(void *user, const void *data, size_t size)
{
    byte_sink *s = (byte_sink *)user;
    ++s->calls;
    if (s->size + size > s->fail_after) return 1;
    if (s->size + size > s->capacity) {
        size_t capacity = s->capacity ? s->capacity : 256;
        unsigned char *bigger;
        while (capacity < s->size + size) capacity *= 2;
        bigger = (unsigned char *)realloc(s->data, capacity);
        if (!bigger) return 1;
        s->data = bigger;
        s->capacity = capacity;
    }
    memcpy(s->data + s->size, data, size);
    s->size += size;
    return 0;
}

static void sink_init(byte_sink *s, size_t fail_after)
{
    memset(s, 0, sizeof *s);
    s->fail_after = fail_after;
}

static uint32_t u32le(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static int32_t i32le(const unsigned char *p)
{
    uint32_t u = u32le(p);
    return u <= 0x7FFFFFFFu ? (int32_t)u : -(int32_t)(0xFFFFFFFFu - u) - 1;
}

static float float_of_bits(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static uint32_t bits_of_float(float f)
{
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    return bits;
}

/* A half's value computed from its fields in double, independently of the
   library's bit manipulation. */
static double half_value(uint16_t h)
{
    int exponent = (h >> 10) & 31, mantissa = h & 1023;
    double sign = (h & 0x8000) ? -1.0 : 1.0;
    if (exponent == 31) return mantissa ? NAN : sign * INFINITY;
    if (exponent == 0) return sign * ldexp((double)mantissa, -24);
    return sign * ldexp(1024.0 + mantissa, exponent - 25);
}

static uint32_t lcg_state = 2024u;
static uint32_t lcg_next(void)
{
    lcg_state = lcg_state * 1664525u + 1013904223u;
    return lcg_state >> 8;
}

/* Ramps (compressible), noise rows, and the values at the conversion's edges. */
static float *make_image(int width, int height)
{
    static const float specials[] = { 0.0f, -0.0f, 65504.0f, 65520.0f, 1e30f, 5.9604645e-8f,
                                      2.9802322e-8f, 1.0004883f, 0.1f };
    size_t n = (size_t)width * (size_t)height * 3, i;
    float *rgb = (float *)malloc(n * sizeof *rgb);
    if (!rgb) return NULL;
    for (i = 0; i < n; ++i) {
        size_t pixel = i / 3, x = pixel % (size_t)width, y = pixel / (size_t)width;
        if (y == 0 && x < sizeof specials / sizeof specials[0]) rgb[i] = specials[x];
        else if (y % 5 == 2) rgb[i] = (float)lcg_next() / 16777216.0f * 8.0f - 1.0f;
        else rgb[i] = (float)(i % 3 + 1) * 0.3f + (float)x / (float)width + 0.02f * (float)y;
    }
    return rgb;
}

/* ---- a parser of what rrv writes ------------------------------------------------ */

typedef struct parsed_exr {
    int ok;
    int pixel_type; /* 1 HALF, 2 FLOAT */
    int compression;
    int32_t data[4], display[4];
    int attributes;
    size_t header_end;
    float *rgb; /* the data window, row 0 at the top */
    int width, height;
    int raw_chunks, compressed_chunks;
} parsed_exr;

static const unsigned char *find_attribute(const unsigned char *p, size_t size, const char *name,
                                           const char *type, uint32_t value_size)
{
    size_t pos = 8;
    while (pos < size && p[pos] != 0) {
        const char *n = (const char *)p + pos, *t;
        uint32_t len;
        pos += strlen(n) + 1;
        t = (const char *)p + pos;
        pos += strlen(t) + 1;
        len = u32le(p + pos);
        pos += 4;
        if (strcmp(n, name) == 0) return strcmp(t, type) == 0 && len == value_size ? p + pos : NULL;
        pos += len;
    }
    return NULL;
}

/* Checks structure with CHECKs and decodes the pixels into out->rgb. */
static void parse_exr(const unsigned char *p, size_t size, parsed_exr *out)
{
    const unsigned char *v;
    size_t pos = 8, value_bytes, line_bytes, chunk_count, expected_offset, i;
    int lines_per_chunk, c, k;
    unsigned char *raw = NULL, *tmp = NULL;
    memset(out, 0, sizeof *out);
    CHECK(size > 8 && p[0] == 0x76 && p[1] == 0x2f && p[2] == 0x31 && p[3] == 0x01);
    CHECK(u32le(p + 4) == 2); /* version 2, no flags: single-part scanline */
    if (size <= 8) return;
    /* Every attribute, each exactly once, none unknown. */
    while (pos < size && p[pos] != 0) {
        const char *name = (const char *)p + pos, *type;
        size_t nlen = strnlen(name, size - pos);
        CHECK(nlen > 0 && nlen < 32 && pos + nlen < size);
        pos += nlen + 1;
        type = (const char *)p + pos;
        pos += strnlen(type, size - pos) + 1;
        CHECK(pos + 4 <= size);
        pos += 4 + u32le(p + pos);
        ++out->attributes;
        CHECKF(strcmp(name, "channels") == 0 || strcmp(name, "compression") == 0 ||
                   strcmp(name, "dataWindow") == 0 || strcmp(name, "displayWindow") == 0 ||
                   strcmp(name, "lineOrder") == 0 || strcmp(name, "pixelAspectRatio") == 0 ||
                   strcmp(name, "screenWindowCenter") == 0 || strcmp(name, "screenWindowWidth") == 0,
               "unexpected attribute %s", name);
    }
    CHECK(out->attributes == 8);
    CHECK(pos < size);
    out->header_end = pos + 1;

    v = find_attribute(p, size, "channels", "chlist", 3 * 18 + 1);
    CHECK(v != NULL);
    if (!v) return;
    for (c = 0; c < 3; ++c) {
        const unsigned char *ch = v + 18 * c;
        CHECK(ch[0] == "BGR"[c] && ch[1] == 0);
        if (c == 0) out->pixel_type = (int)u32le(ch + 2);
        CHECK((int)u32le(ch + 2) == out->pixel_type);
        CHECK(ch[6] == 0 && ch[7] == 0 && ch[8] == 0 && ch[9] == 0);
        CHECK(u32le(ch + 10) == 1 && u32le(ch + 14) == 1);
    }
    CHECK(v[54] == 0);
    CHECK(out->pixel_type == 1 || out->pixel_type == 2);
    v = find_attribute(p, size, "compression", "compression", 1);
    CHECK(v && (v[0] == 0 || v[0] == 3));
    out->compression = v ? v[0] : -1;
    v = find_attribute(p, size, "dataWindow", "box2i", 16);
    CHECK(v != NULL);
    for (k = 0; v && k < 4; ++k) out->data[k] = i32le(v + 4 * k);
    v = find_attribute(p, size, "displayWindow", "box2i", 16);
    CHECK(v != NULL);
    for (k = 0; v && k < 4; ++k) out->display[k] = i32le(v + 4 * k);
    v = find_attribute(p, size, "lineOrder", "lineOrder", 1);
    CHECK(v && v[0] == 0);
    v = find_attribute(p, size, "pixelAspectRatio", "float", 4);
    CHECK(v && float_of_bits(u32le(v)) == 1.0f);
    v = find_attribute(p, size, "screenWindowCenter", "v2f", 8);
    CHECK(v && u32le(v) == 0 && u32le(v + 4) == 0);
    v = find_attribute(p, size, "screenWindowWidth", "float", 4);
    CHECK(v && float_of_bits(u32le(v)) == 1.0f);
    if (out->pixel_type != 1 && out->pixel_type != 2) return;
    if (out->compression != 0 && out->compression != 3) return;

    out->width = out->data[2] - out->data[0] + 1;
    out->height = out->data[3] - out->data[1] + 1;
    CHECK(out->width > 0 && out->height > 0);
    if (out->width <= 0 || out->height <= 0) return;
    value_bytes = out->pixel_type == 2 ? 4 : 2;
    line_bytes = (size_t)out->width * 3 * value_bytes;
    lines_per_chunk = out->compression == 3 ? 16 : 1;
    chunk_count = ((size_t)out->height + (size_t)lines_per_chunk - 1) / (size_t)lines_per_chunk;
    out->rgb = (float *)malloc((size_t)out->width * (size_t)out->height * 3 * sizeof(float));
    raw = (unsigned char *)malloc(line_bytes * (size_t)lines_per_chunk);
    tmp = (unsigned char *)malloc(line_bytes * (size_t)lines_per_chunk);
    CHECK(out->rgb && raw && tmp);
    CHECK(out->header_end + 8 * chunk_count <= size);
    if (!out->rgb || !raw || !tmp || out->header_end + 8 * chunk_count > size) goto done;

    /* The offset table: chunks back to back, in order, right after it, the
       last ending at the end of the file. */
    expected_offset = out->header_end + 8 * chunk_count;
    for (i = 0; i < chunk_count; ++i) {
        const unsigned char *e = p + out->header_end + 8 * i;
        uint64_t offset = (uint64_t)u32le(e) | (uint64_t)u32le(e + 4) << 32;
        int lines = out->height - (int)i * lines_per_chunk < lines_per_chunk ? out->height - (int)i * lines_per_chunk
                                                                           : lines_per_chunk;
        size_t chunk_raw = line_bytes * (size_t)lines, data_size, y, x;
        CHECKF(offset == expected_offset, "chunk %zu at %llu, expected %zu", i, (unsigned long long)offset,
               expected_offset);
        if (offset != expected_offset || offset + 8 > size) goto done;
        CHECK(i32le(p + offset) == out->data[1] + (int32_t)i * lines_per_chunk);
        data_size = u32le(p + offset + 4);
        CHECK(offset + 8 + data_size <= size);
        if (offset + 8 + data_size > size) goto done;
        if (data_size == chunk_raw) {
            memcpy(raw, p + offset + 8, chunk_raw);
            ++out->raw_chunks;
        } else {
            size_t n;
            CHECK(out->compression == 3 && data_size < chunk_raw);
            n = zlib_inflate(p + offset + 8, data_size, tmp, chunk_raw);
            CHECKF(n == chunk_raw, "chunk %zu inflates to %zu bytes, expected %zu", i, n, chunk_raw);
            if (n != chunk_raw) goto done;
            /* Undo the predictor, then the split into even and odd bytes. */
            for (k = 1; (size_t)k < n; ++k) tmp[k] = (unsigned char)(tmp[k - 1] + tmp[k] - 128);
            for (x = 0; x < n; ++x) raw[x] = (x & 1) ? tmp[(n + 1) / 2 + x / 2] : tmp[x / 2];
            ++out->compressed_chunks;
        }
        for (y = 0; y < (size_t)lines; ++y)
            for (c = 0; c < 3; ++c)
                for (x = 0; x < (size_t)out->width; ++x) {
                    const unsigned char *q = raw + y * line_bytes + ((size_t)c * (size_t)out->width + x) * value_bytes;
                    float value = value_bytes == 4 ? float_of_bits(u32le(q))
                                                   : (float)half_value((uint16_t)(q[0] | q[1] << 8));
                    size_t row = i * (size_t)lines_per_chunk + y;
                    out->rgb[3 * (row * (size_t)out->width + x) + (size_t)(2 - c)] = value;
                }
        expected_offset = offset + 8 + data_size;
    }
    CHECKF(expected_offset == size, "chunks end at %zu, the file at %zu", expected_offset, size);
    out->ok = expected_offset == size;
done:
    free(raw);
    free(tmp);
}

static int write_exr(const float *rgb, int width, int height, const rrv_exr_options *opt, byte_sink *sink)
{
    sink_init(sink, (size_t)-1);
    return rrv_write_exr_to(sink_write, sink, rgb, width, height, opt, NULL) == RRV_OK;
}

/* ---- tests ------------------------------------------------------------------------ */

static void half_conversion_table(void)
{
    static const struct { float value; uint16_t half; } table[] = {
        { 0.0f, 0x0000 }, { -0.0f, 0x8000 }, { 1.0f, 0x3C00 }, { -2.0f, 0xC000 },
        { 0.5f, 0x3800 }, { 65504.0f, 0x7BFF }, { -65504.0f, 0xFBFF },
        { 65505.0f, 0x7BFF }, { 65519.0f, 0x7BFF }, { 65520.0f, 0x7BFF }, /* clamped, not inf */
        { 1e10f, 0x7BFF }, { -3.4e38f, 0xFBFF }, { 6.103515625e-05f, 0x0400 }, /* 2^-14 */
        { 5.9604644775390625e-08f, 0x0001 },          /* 2^-24, smallest subnormal */
        { 2.98023223876953125e-08f, 0x0000 },         /* 2^-25: tie, to even zero */
        { 2.98023259404089e-08f, 0x0001 },            /* just above 2^-25 */
        { 8.94069671630859375e-08f, 0x0002 },         /* 3 * 2^-25: tie, to even 2 */
        { 6.09755516052246094e-05f, 0x03FF },         /* largest subnormal */
        { 6.10053539276123047e-05f, 0x0400 },         /* 2^-14 - 2^-25: tie, to even 0x400 */
        { 1.00048828125f, 0x3C00 },                   /* 1 + 2^-11: tie, to even */
        { 1.00146484375f, 0x3C02 },                   /* 1 + 3 * 2^-11: tie, to even */
        { 1.0004884004592896f, 0x3C01 },              /* just above the tie */
        { 2047.0f, 0x67FF }, { 2049.0f, 0x6800 },     /* 2049 ties between 2048 and 2050 */
        { 2051.0f, 0x6802 }, { 0.1f, 0x2E66 }, { 1e-30f, 0x0000 }, { -1e-30f, 0x8000 },
    };
    size_t i;
    for (i = 0; i < sizeof table / sizeof table[0]; ++i) {
        uint16_t got = rrv_half_from_float(table[i].value);
        CHECKF(got == table[i].half, "%.17g -> 0x%04X, expected 0x%04X", (double)table[i].value, got, table[i].half);
    }
    CHECK(rrv_half_from_float(INFINITY) == 0x7C00);
    CHECK(rrv_half_from_float(-INFINITY) == 0xFC00);
    {
        /* NaN stays NaN whatever its payload, the sign kept. */
        static const uint32_t nans[] = { 0x7FC00000u, 0x7F800001u, 0xFF800001u, 0x7FFFFFFFu, 0x7F802000u };
        for (i = 0; i < sizeof nans / sizeof nans[0]; ++i) {
            uint16_t h = rrv_half_from_float(float_of_bits(nans[i]));
            CHECKF((h & 0x7C00) == 0x7C00 && (h & 0x3FF) != 0 && (h >> 15) == (nans[i] >> 31),
                   "NaN 0x%08lX -> 0x%04X", (unsigned long)nans[i], h);
        }
    }
}

/* Every finite half converts back to itself; every midpoint between
   neighbours goes to the even one, and the floats next to it to the
   nearer side. That is round to nearest even over the whole range. */
static void half_conversion_exhaustive(void)
{
    int bad = 0;
    uint32_t h;
    for (h = 0; h < 0x7C00u; ++h) {
        int s;
        for (s = 0; s < 2; ++s) {
            uint16_t sign = (uint16_t)(s ? 0x8000u : 0u);
            float value = (float)half_value((uint16_t)(h | sign));
            if (rrv_half_from_float(value) != (h | sign)) ++bad;
            if (h + 1 < 0x7C00u) {
                float next = (float)half_value((uint16_t)((h + 1) | sign));
                /* halves have 11 significant bits, so the midpoint is exact in float */
                float mid = (float)(((double)value + (double)next) / 2.0);
                uint16_t even = (uint16_t)(((h & 1u) ? h + 1 : h) | sign);
                if (rrv_half_from_float(mid) != even) ++bad;
                if (rrv_half_from_float(nextafterf(mid, next)) != ((h + 1) | sign)) ++bad;
                if (rrv_half_from_float(nextafterf(mid, value)) != (h | sign)) ++bad;
            }
        }
    }
    CHECKF(bad == 0, "%d conversions off", bad);
}

static void exr_none_bytes(void)
{
    int width = 13, height = 7, bad = 0;
    float *rgb = make_image(width, height);
    rrv_exr_options opt;
    byte_sink sink;
    parsed_exr e;
    size_t i;
    memset(&opt, 0, sizeof opt);
    opt.compression = RRV_EXR_NO_COMPRESSION;
    CHECK(rgb && write_exr(rgb, width, height, &opt, &sink));
    parse_exr(sink.data, sink.size, &e);
    CHECK(e.ok && e.pixel_type == 1 && e.compression == 0);
    CHECK(e.data[0] == 0 && e.data[1] == 0 && e.data[2] == width - 1 && e.data[3] == height - 1);
    CHECK(e.display[0] == 0 && e.display[1] == 0 && e.display[2] == width - 1 && e.display[3] == height - 1);
    CHECK(e.raw_chunks == height && e.compressed_chunks == 0);
    /* 8 + 8 attributes + NUL, then the table and a line a chunk. */
    CHECK(sink.size == e.header_end + (size_t)height * (8 + 8 + (size_t)width * 6));
    for (i = 0; e.ok && i < (size_t)width * height * 3; ++i)
        if (bits_of_float(e.rgb[i]) != bits_of_float((float)half_value(rrv_half_from_float(rgb[i])))) ++bad;
    CHECKF(bad == 0, "%d values differ", bad);

    /* FLOAT stores the exact bits. */
    free(e.rgb);
    free(sink.data);
    opt.pixel = RRV_EXR_FLOAT;
    CHECK(write_exr(rgb, width, height, &opt, &sink));
    parse_exr(sink.data, sink.size, &e);
    CHECK(e.ok && e.pixel_type == 2);
    CHECK(e.ok && memcmp(e.rgb, rgb, (size_t)width * height * 3 * sizeof(float)) == 0);
    free(e.rgb);
    free(sink.data);
    free(rgb);
}

static void exr_zip_bytes(void)
{
    int sizes[][2] = { { 1, 1 }, { 5, 16 }, { 40, 17 }, { 257, 50 } }, k, p;
    for (k = 0; k < 4; ++k)
        for (p = 0; p < 2; ++p) {
            int width = sizes[k][0], height = sizes[k][1];
            float *rgb = make_image(width, height);
            rrv_exr_options opt;
            byte_sink sink;
            parsed_exr e;
            size_t n = (size_t)width * height * 3, i, uncompressed;
            int bad = 0;
            memset(&opt, 0, sizeof opt);
            opt.pixel = p ? RRV_EXR_FLOAT : RRV_EXR_HALF;
            CHECK(rgb && write_exr(rgb, width, height, &opt, &sink));
            parse_exr(sink.data, sink.size, &e);
            CHECK(e.ok && e.compression == 3 && e.pixel_type == (p ? 2 : 1));
            CHECK(e.raw_chunks + e.compressed_chunks == (height + 15) / 16);
            for (i = 0; e.ok && i < n; ++i) {
                float want = p ? rgb[i] : (float)half_value(rrv_half_from_float(rgb[i]));
                if (bits_of_float(e.rgb[i]) != bits_of_float(want)) ++bad;
            }
            CHECKF(bad == 0, "%dx%d %s: %d values differ", width, height, p ? "float" : "half", bad);
            /* The ramps shrink: the larger images must compress. */
            uncompressed = e.header_end + (size_t)((height + 15) / 16) * 16 + n * (p ? 4 : 2);
            if (width * height >= 600)
                CHECKF(sink.size < uncompressed * 3 / 4, "%dx%d: %zu bytes, %zu uncompressed", width, height,
                       sink.size, uncompressed);
            free(e.rgb);
            free(sink.data);
            free(rgb);
        }
}

/* Random bits do not compress: such chunks are stored raw, which a reader
   recognises by their size. */
static void exr_zip_stores_incompressible_chunks_raw(void)
{
    int width = 40, height = 20;
    size_t n = (size_t)width * height * 3, i;
    float *rgb = (float *)malloc(n * sizeof *rgb);
    rrv_exr_options opt;
    byte_sink sink;
    parsed_exr e;
    CHECK(rgb != NULL);
    if (!rgb) return;
    for (i = 0; i < n; ++i) rgb[i] = float_of_bits((lcg_next() << 8 ^ lcg_next()) & 0xBF7FFFFFu);
    memset(&opt, 0, sizeof opt);
    opt.pixel = RRV_EXR_FLOAT;
    CHECK(write_exr(rgb, width, height, &opt, &sink));
    parse_exr(sink.data, sink.size, &e);
    CHECK(e.ok && e.raw_chunks == 2 && e.compressed_chunks == 0);
    CHECK(e.ok && memcmp(e.rgb, rgb, n * sizeof *rgb) == 0);
    free(e.rgb);
    free(sink.data);
    free(rgb);
}

static void exr_data_window_inside_display_window(void)
{
    int width = 9, height = 21;
    float *rgb = make_image(width, height);
    rrv_exr_options opt;
    byte_sink sink;
    parsed_exr e;
    int compression;
    for (compression = 0; compression < 2; ++compression) {
        memset(&opt, 0, sizeof opt);
        opt.compression = compression ? RRV_EXR_NO_COMPRESSION : RRV_EXR_ZIP;
        opt.display_width = 100;
        opt.display_height = 50;
        opt.x = 30;
        opt.y = -4;
        CHECK(rgb && write_exr(rgb, width, height, &opt, &sink));
        parse_exr(sink.data, sink.size, &e);
        CHECK(e.ok && e.data[0] == 30 && e.data[1] == -4 && e.data[2] == 38 && e.data[3] == 16);
        CHECK(e.display[0] == 0 && e.display[1] == 0 && e.display[2] == 99 && e.display[3] == 49);
        CHECK(e.ok && e.width == width && e.height == height);
        free(e.rgb);
        free(sink.data);
    }
    free(rgb);
}

static void exr_refuses_bad_arguments(void)
{
    float rgb[12] = { 0 };
    rrv_exr_options opt;
    byte_sink sink;
    sink_init(&sink, (size_t)-1);
    CHECK(rrv_write_exr_to(NULL, &sink, rgb, 2, 2, NULL, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_exr_to(sink_write, &sink, NULL, 2, 2, NULL, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 0, 2, NULL, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, -1, NULL, NULL) == RRV_ERROR_ARGUMENT);
    memset(&opt, 0, sizeof opt);
    opt.pixel = (rrv_exr_pixel)7;
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 2, &opt, NULL) == RRV_ERROR_ARGUMENT);
    memset(&opt, 0, sizeof opt);
    opt.compression = (rrv_exr_compression)9;
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 2, &opt, NULL) == RRV_ERROR_ARGUMENT);
    memset(&opt, 0, sizeof opt);
    opt.display_width = -1;
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 2, &opt, NULL) == RRV_ERROR_ARGUMENT);
    memset(&opt, 0, sizeof opt);
    opt.x = INT_MAX; /* the data window's last column would not be an int */
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 2, &opt, NULL) == RRV_ERROR_ARGUMENT);
    opt.x = INT_MAX - 1;
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, 2, 2, &opt, NULL) == RRV_OK);
    /* A ZIP chunk of 16 float lines must have an int32 size: caught before
       anything is read from the (here too small) buffer. */
    memset(&opt, 0, sizeof opt);
    opt.pixel = RRV_EXR_FLOAT;
    CHECK(rrv_write_exr_to(sink_write, &sink, rgb, INT32_MAX / 190, 1, &opt, NULL) == RRV_ERROR_ARGUMENT);
    free(sink.data);
}

/* A callback that fails at any point makes the writer stop and report an
   I/O error, for both compressions. */
static void exr_write_failures(void)
{
    int width = 30, height = 20, compression;
    float *rgb = make_image(width, height);
    for (compression = 0; compression < 2; ++compression) {
        rrv_exr_options opt;
        byte_sink full, sink;
        size_t cut;
        int bad = 0;
        memset(&opt, 0, sizeof opt);
        opt.compression = compression ? RRV_EXR_NO_COMPRESSION : RRV_EXR_ZIP;
        CHECK(rgb && write_exr(rgb, width, height, &opt, &full));
        for (cut = 0; cut < full.size; cut += 97) {
            sink_init(&sink, cut);
            if (rrv_write_exr_to(sink_write, &sink, rgb, width, height, &opt, NULL) != RRV_ERROR_IO) ++bad;
            free(sink.data);
        }
        CHECKF(bad == 0, "%d cuts not reported", bad);
        free(full.data);
    }
    free(rgb);
}

static void exr_file_form(void)
{
    int width = 17, height = 19;
    float *rgb = make_image(width, height);
    char path[512];
    rrv_error err;
    byte_sink sink;
    FILE *f;
    unsigned char *file_bytes;
    long size;
    snprintf(path, sizeof path, "%s/test_exr_file.exr", build_dir);
    CHECK(rgb && rrv_write_exr(path, rgb, width, height, NULL, &err) == RRV_OK);
    CHECK(write_exr(rgb, width, height, NULL, &sink));
    f = fopen(path, "rb");
    CHECK(f != NULL);
    if (f) {
        fseek(f, 0, SEEK_END);
        size = ftell(f);
        fseek(f, 0, SEEK_SET);
        file_bytes = (unsigned char *)malloc((size_t)size + 1);
        CHECK(file_bytes && fread(file_bytes, 1, (size_t)size, f) == (size_t)size);
        CHECK((size_t)size == sink.size && memcmp(file_bytes, sink.data, sink.size) == 0);
        free(file_bytes);
        fclose(f);
    }
    remove(path);
    snprintf(path, sizeof path, "%s/no such folder/x.exr", build_dir);
    CHECK(rrv_write_exr(path, rgb, width, height, NULL, &err) == RRV_ERROR_IO);
    CHECK(strstr(err.message, "cannot write") != NULL && strcmp(err.file, path) == 0);
    CHECK(rrv_write_exr(NULL, rgb, width, height, NULL, &err) == RRV_ERROR_ARGUMENT);
    free(sink.data);
    free(rgb);
}

/* ---- the CLI ------------------------------------------------------------------------ */

static unsigned char *read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    unsigned char *data = NULL;
    long n;
    *size = 0;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
        data = (unsigned char *)malloc((size_t)n + 1);
        if (data && fread(data, 1, (size_t)n, f) == (size_t)n) *size = (size_t)n;
        else { free(data); data = NULL; }
    }
    fclose(f);
    return data;
}

static int run_rrv(const char *arguments)
{
    char command[4096];
    int status;
    snprintf(command, sizeof command, "'%s/rrv' %s >'%s/test_exr_cli.out' 2>&1 </dev/null", build_dir, arguments,
             build_dir);
    status = system(command);
#ifdef WEXITSTATUS
    return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
#else
    return status;
#endif
}

/* -o picks the format by extension; an EXR of a crop says where the crop
   lies in the frame, and holds the same pixels as the PFM of that crop. */
static void cli_writes_exr_by_extension(void)
{
    static const char *const flags[3] = { "--exr-float --exr-compression none", "--exr-float", "--exr-half" };
    char args[1024], pfm[512], exr[512];
    float *reference = NULL;
    int width = 0, height = 0, k;
    rrv_error err;
    snprintf(pfm, sizeof pfm, "%s/test_exr_cli.pfm", build_dir);
    snprintf(exr, sizeof exr, "%s/test_exr_cli.exr", build_dir);
    snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 --crop 8 6 40 30 -q -o '%s'", pfm);
    CHECK(run_rrv(args) == 0);
    CHECK(rrv_read_pfm(pfm, &reference, &width, &height, &err) == RRV_OK && width == 32 && height == 24);
    for (k = 0; k < 3 && reference; ++k) {
        size_t size, i;
        unsigned char *bytes;
        parsed_exr e;
        int bad = 0;
        snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 --crop 8 6 40 30 -q %s -o '%s'", flags[k], exr);
        CHECKF(run_rrv(args) == 0, "%s", args);
        bytes = read_file(exr, &size);
        CHECK(bytes != NULL);
        if (!bytes) continue;
        parse_exr(bytes, size, &e);
        CHECK(e.ok && e.pixel_type == (k < 2 ? 2 : 1) && e.compression == (k == 0 ? 0 : 3));
        CHECK(e.data[0] == 8 && e.data[1] == 6 && e.data[2] == 39 && e.data[3] == 29);
        /* smoke.rrv's camera is 480 x 320 */
        CHECK(e.display[0] == 0 && e.display[1] == 0 && e.display[2] == 479 && e.display[3] == 319);
        for (i = 0; e.ok && i < (size_t)width * height * 3; ++i) {
            float want = k < 2 ? reference[i] : (float)half_value(rrv_half_from_float(reference[i]));
            if (bits_of_float(e.rgb[i]) != bits_of_float(want)) ++bad;
        }
        CHECKF(bad == 0, "%s: %d values differ from the PFM", flags[k], bad);
        free(e.rgb);
        free(bytes);
    }
    rrv_free(reference);
    remove(pfm);
    remove(exr);
}

static void cli_refuses_unknown_formats(void)
{
    char args[1024], path[512], out[512], *text;
    size_t size;
    snprintf(path, sizeof path, "%s/test_exr_cli.tiff", build_dir);
    snprintf(out, sizeof out, "%s/test_exr_cli.out", build_dir);
    snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 -q -o '%s'", path);
    CHECK(run_rrv(args) == 1);
    text = (char *)read_file(out, &size);
    if (text) text[size] = '\0';
    CHECKF(text && strstr(text, "the output must end in .pfm or .exr"), "stderr: %s", text ? text : "(none)");
    free(text);
    {
        FILE *f = fopen(path, "rb"); /* nothing written */
        CHECK(f == NULL);
        if (f) fclose(f);
    }
    /* EXR options with a PFM output are a mistake, not something to ignore. */
    snprintf(path, sizeof path, "%s/test_exr_cli.pfm", build_dir);
    snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 -q --exr-half -o '%s'", path);
    CHECK(run_rrv(args) == 1);
    text = (char *)read_file(out, &size);
    if (text) text[size] = '\0';
    CHECKF(text && strstr(text, "--exr-half needs an .exr output"), "stderr: %s", text ? text : "(none)");
    free(text);
    snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 -q --exr-compression piz -o '%s'", path);
    CHECK(run_rrv(args) == 1);
    remove(out);
}

/* ---- the reader ----------------------------------------------------------------- */

/* What rrv writes, rrv reads back: FLOAT exactly, HALF as the half. */
static void exr_read_round_trip(void)
{
    int k;
    for (k = 0; k < 8; ++k) {
        int width = k & 4 ? 33 : 7, height = k & 4 ? 40 : 3, w = 0, h = 0, bad = 0;
        float *rgb = make_image(width, height), *back = NULL;
        rrv_exr_options opt, info;
        byte_sink sink;
        rrv_error err;
        size_t i;
        memset(&opt, 0, sizeof opt);
        opt.pixel = k & 1 ? RRV_EXR_FLOAT : RRV_EXR_HALF;
        opt.compression = k & 2 ? RRV_EXR_NO_COMPRESSION : RRV_EXR_ZIP;
        opt.display_width = 50;
        opt.display_height = 60;
        opt.x = 3;
        opt.y = -1;
        CHECK(rgb && write_exr(rgb, width, height, &opt, &sink));
        CHECKF(rrv_read_exr_memory(sink.data, sink.size, "mem.exr", &back, &w, &h, &info, &err) == RRV_OK,
               "%s", err.message);
        CHECK(w == width && h == height);
        CHECK(info.pixel == opt.pixel && info.compression == opt.compression && info.display_width == 50 &&
              info.display_height == 60 && info.x == 3 && info.y == -1);
        for (i = 0; back && i < (size_t)width * height * 3; ++i) {
            float want = k & 1 ? rgb[i] : (float)half_value(rrv_half_from_float(rgb[i]));
            if (bits_of_float(back[i]) != bits_of_float(want)) ++bad;
        }
        CHECKF(bad == 0, "variant %d: %d values differ", k, bad);
        rrv_free(back);
        free(sink.data);
        free(rgb);
    }
}

/* Every prefix of a file and every single-byte change either reads or is
   refused with a message; none reads outside the buffer (make test SAN=1
   checks that) and a refusal leaves no image behind. */
static void exr_read_hostile_bytes(void)
{
    int width = 20, height = 18, compression, bad = 0;
    float *rgb = make_image(width, height);
    for (compression = 0; compression < 2; ++compression) {
        rrv_exr_options opt;
        byte_sink sink;
        size_t cut, i;
        memset(&opt, 0, sizeof opt);
        opt.compression = compression ? RRV_EXR_NO_COMPRESSION : RRV_EXR_ZIP;
        CHECK(rgb && write_exr(rgb, width, height, &opt, &sink));
        for (cut = 0; cut < sink.size; ++cut) {
            /* a copy of exactly cut bytes, so ASan sees any overread */
            unsigned char *copy = (unsigned char *)malloc(cut ? cut : 1);
            float *back = &not_reset_value;
            int w = -1, h = -1;
            rrv_error err;
            memcpy(copy, sink.data, cut);
            if (rrv_read_exr_memory(copy, cut, "cut.exr", &back, &w, &h, NULL, &err) == RRV_OK ||
                back != NULL || w != 0 || h != 0 || err.message[0] == 0 || strcmp(err.file, "cut.exr") != 0)
                ++bad;
            free(copy);
        }
        for (i = 0; i < sink.size; ++i) {
            unsigned char *copy = (unsigned char *)malloc(sink.size);
            unsigned char flips[3] = { 0xFF, 0x01, 0x80 };
            int f;
            for (f = 0; f < 3; ++f) {
                float *back = NULL;
                int w, h;
                rrv_error err;
                rrv_result r;
                memcpy(copy, sink.data, sink.size);
                copy[i] ^= flips[f];
                r = rrv_read_exr_memory(copy, sink.size, "flip.exr", &back, &w, &h, NULL, &err);
                if (r == RRV_OK ? (back == NULL || w <= 0 || h <= 0) : (back != NULL || err.message[0] == 0)) ++bad;
                rrv_free(back);
            }
            free(copy);
        }
        free(sink.data);
    }
    CHECKF(bad == 0, "%d damaged files mishandled", bad);
    free(rgb);
}

static void exr_read_messages(void)
{
    float rgb[3 * 4] = { 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12 };
    byte_sink sink;
    float *back = NULL;
    int w, h;
    rrv_error err;
    unsigned char *pos;
    CHECK(write_exr(rgb, 2, 2, NULL, &sink));
    CHECK(rrv_read_exr_memory("PF\n1 1\n-1\n", 11, "a.exr", &back, &w, &h, NULL, &err) == RRV_ERROR_FORMAT);
    CHECK(strcmp(err.message, "not an OpenEXR file (no magic number 76 2f 31 01)") == 0);
    /* tiled */
    sink.data[5] = 0x02;
    CHECK(rrv_read_exr_memory(sink.data, sink.size, "a.exr", &back, &w, &h, NULL, &err) == RRV_ERROR_UNSUPPORTED);
    CHECKF(strcmp(err.message, "unsupported OpenEXR file: only single-part scanline images are read (tiled)") == 0,
           "%s", err.message);
    sink.data[5] = 0;
    /* PIZ, named */
    pos = (unsigned char *)memchr(sink.data, 'c', sink.size);
    while (pos && memcmp(pos, "compression\0compression\0", 24) != 0)
        pos = (unsigned char *)memchr(pos + 1, 'c', sink.size - (size_t)(pos + 1 - sink.data));
    CHECK(pos != NULL);
    if (pos) {
        pos[24 + 4] = 4;
        CHECK(rrv_read_exr_memory(sink.data, sink.size, "a.exr", &back, &w, &h, NULL, &err) == RRV_ERROR_UNSUPPORTED);
        CHECKF(strcmp(err.message, "OpenEXR compression PIZ is not supported; rrv reads NONE, RLE, ZIPS and ZIP") == 0,
               "%s", err.message);
    }
    CHECK(back == NULL);
    free(sink.data);
}

/* rrv diff compares EXRs with PFMs and EXRs. */
static void cli_diff_reads_exr(void)
{
    char args[1200 + 2 * 512], pfm[512], exr[512], out[512], *text;
    size_t size;
    snprintf(pfm, sizeof pfm, "%s/test_exr_diff.pfm", build_dir);
    snprintf(exr, sizeof exr, "%s/test_exr_diff.exr", build_dir);
    snprintf(out, sizeof out, "%s/test_exr_cli.out", build_dir);
    snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 --crop 0 0 24 16 -q -o '%s'", pfm);
    CHECK(run_rrv(args) == 0);
    snprintf(args, sizeof args, "render scenes/smoke.rrv --spp 1 --crop 0 0 24 16 -q --exr-float -o '%s'", exr);
    CHECK(run_rrv(args) == 0);
    snprintf(args, sizeof args, "diff '%s' '%s'", exr, pfm);
    CHECK(run_rrv(args) == 0);
    text = (char *)read_file(out, &size);
    if (text) text[size] = '\0';
    CHECKF(text && strstr(text, "width: 24\n") && strstr(text, "\nrmse: 0\n") && strstr(text, "max_abs_error: 0\n"),
           "%s", text ? text : "(none)");
    free(text);
    remove(pfm);
    remove(exr);
    remove(out);
}

/* The OpenEXR library reads what rrv writes (test/exr_check.cpp, built by
   the Makefile when pkg-config finds OpenEXR). Without it this fails: a
   test suite that silently skips the real reader proves nothing. */
static void openexr_reads_rrv_files(void)
{
    char program[512], command[1100];
    FILE *f;
    int status;
    snprintf(program, sizeof program, "%s/exr_check", build_dir);
    f = fopen(program, "rb");
    if (!f) {
        CHECKF(0, "%s is missing: OpenEXR was not found when building. Install it "
                  "(Debian: apt-get install -y libopenexr-dev openexr) and run make test again", program);
        return;
    }
    fclose(f);
    snprintf(command, sizeof command, "'%s' '%s'", program, build_dir);
    fflush(stdout);
    status = system(command);
    CHECKF(status == 0, "%s exited with status %d", program, status);
}

int main(int argc, char **argv)
{
    if (argc > 1) build_dir = argv[1];
    RUN(half_conversion_table);
    RUN(half_conversion_exhaustive);
    RUN(exr_none_bytes);
    RUN(exr_zip_bytes);
    RUN(exr_zip_stores_incompressible_chunks_raw);
    RUN(exr_data_window_inside_display_window);
    RUN(exr_refuses_bad_arguments);
    RUN(exr_write_failures);
    RUN(exr_file_form);
    RUN(cli_writes_exr_by_extension);
    RUN(cli_refuses_unknown_formats);
    RUN(exr_read_round_trip);
    RUN(exr_read_hostile_bytes);
    RUN(exr_read_messages);
    RUN(cli_diff_reads_exr);
    RUN(openexr_reads_rrv_files);
    return CHECK_EXIT_CODE();
}
