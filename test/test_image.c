/* Tests of the image I/O section: checksums, PFM writing and reading (memory
   and file forms, both byte orders, grey, malformed input), and the PNG
   writer, whose output is taken apart here chunk by chunk and block by block
   with checksums written independently of the library's. */
#if defined(__unix__) || defined(__APPLE__)
/* POSIX only for setrlimit, which lets a test make fwrite fail half way,
   and for a FIFO, /dev/zero and folders as inputs. */
#define _POSIX_C_SOURCE 200809L
#endif
#include "../rrv.h"
#include "check.h"
#include "inflate.h"

#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <float.h>

#if defined(__unix__) || defined(__APPLE__)
#include <dirent.h>
#include <signal.h>
#include <unistd.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#define HAVE_FILE_SIZE_LIMIT 1
#else
#define HAVE_FILE_SIZE_LIMIT 0
#endif

static const char *build_dir = ".";
/* Output pointers start here so a test can see that a failing call reset them. */
static float not_reset;

/* ---- helpers -------------------------------------------------------------- */

/* A growable byte buffer that doubles as an rrv_write_func target; it can be
   told to fail once more than fail_after bytes would have been written. */
typedef struct byte_sink {
    unsigned char *data;
    size_t size, capacity;
    size_t fail_after;
    int failed;
    int calls, calls_after_failure;
    size_t largest_write;
} byte_sink;

static void sink_init(byte_sink *s, size_t fail_after)
{
    memset(s, 0, sizeof *s);
    s->fail_after = fail_after;
}

static int sink_append(byte_sink *s, const void *data, size_t size)
{
    if (s->size + size > s->capacity) {
        size_t capacity = s->capacity ? s->capacity : 256;
        unsigned char *bigger;
        while (capacity < s->size + size) capacity *= 2;
        bigger = (unsigned char *)realloc(s->data, capacity);
        if (!bigger) return 1;
        s->data = bigger;
        s->capacity = capacity;
    }
    if (size > 0) memcpy(s->data + s->size, data, size);
    s->size += size;
    return 0;
}

static int sink_write(void *user, const void *data, size_t size)
{
    byte_sink *s = (byte_sink *)user;
    ++s->calls;
    if (s->failed) {
        ++s->calls_after_failure;
        return 1;
    }
    if (size > s->largest_write) s->largest_write = size;
    if (s->size + size > s->fail_after) {
        s->failed = 1;
        return 1;
    }
    return sink_append(s, data, size);
}

static void sink_free(byte_sink *s)
{
    free(s->data);
    memset(s, 0, sizeof *s);
}

static void sink_append_text(byte_sink *s, const char *text) { sink_append(s, text, strlen(text)); }

static uint32_t float_bits(float f)
{
    uint32_t bits;
    memcpy(&bits, &f, sizeof bits);
    return bits;
}

static void sink_append_float(byte_sink *s, float f, int big_endian)
{
    uint32_t bits = float_bits(f);
    unsigned char b[4];
    int i;
    for (i = 0; i < 4; ++i) b[big_endian ? 3 - i : i] = (unsigned char)(bits >> (8 * i));
    sink_append(s, b, 4);
}

static uint32_t read_u32_le(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint32_t read_u32_be(const unsigned char *p)
{
    return (uint32_t)p[3] | (uint32_t)p[2] << 8 | (uint32_t)p[1] << 16 | (uint32_t)p[0] << 24;
}

/* Reference checksums, written the slow obvious way so they share nothing
   with the library's table-driven and deferred-modulo versions. */
static uint32_t bitwise_crc32(const unsigned char *p, size_t n)
{
    uint32_t crc = 0xFFFFFFFFu;
    size_t i;
    int k;
    for (i = 0; i < n; ++i) {
        crc ^= p[i];
        for (k = 0; k < 8; ++k) crc = (crc & 1u) ? (crc >> 1) ^ 0xEDB88320u : crc >> 1;
    }
    return crc ^ 0xFFFFFFFFu;
}

static uint32_t naive_adler32(const unsigned char *p, size_t n)
{
    uint32_t a = 1, b = 0;
    size_t i;
    for (i = 0; i < n; ++i) {
        a = (a + p[i]) % 65521u;
        b = (b + a) % 65521u;
    }
    return (b << 16) | a;
}

static uint32_t lcg_state = 12345u;
static uint32_t lcg_next(void)
{
    lcg_state = lcg_state * 1664525u + 1013904223u;
    return lcg_state >> 8;
}

static float *make_image(int width, int height)
{
    float *rgb = (float *)malloc((size_t)width * (size_t)height * 3 * sizeof *rgb);
    size_t i, n = (size_t)width * (size_t)height * 3;
    if (!rgb) return NULL;
    for (i = 0; i < n; ++i) rgb[i] = (float)((double)lcg_next() / (1 << 24) * 3.0 - 1.0);
    return rgb;
}

/* Floats whose sRGB bytes are uniformly random (each the linear value of a
   byte's centre). */
static float *make_noise_image(int width, int height)
{
    float *rgb = (float *)malloc((size_t)width * (size_t)height * 3 * sizeof *rgb);
    size_t i, n = (size_t)width * (size_t)height * 3;
    if (!rgb) return NULL;
    for (i = 0; i < n; ++i) {
        double e = ((double)(lcg_next() >> 16 & 255u)) / 255.0;
        rgb[i] = (float)(e <= 0.04045 ? e / 12.92 : pow((e + 0.055) / 1.055, 2.4));
    }
    return rgb;
}

/* A sky-like gradient with a disc and a few hard edges: what a render
   without noise looks like. */
static float *make_smooth_image(int width, int height)
{
    float *rgb = (float *)malloc((size_t)width * (size_t)height * 3 * sizeof *rgb);
    int x, y;
    if (!rgb) return NULL;
    for (y = 0; y < height; ++y)
        for (x = 0; x < width; ++x) {
            float *px = rgb + ((size_t)y * (size_t)width + (size_t)x) * 3;
            double u = (double)x / width, v = (double)y / height;
            double dx = u - 0.6, dy = v - 0.4, disc = dx * dx + dy * dy < 0.04 ? 0.5 : 0.0;
            int checker = ((x / 25) + (y / 25)) & 1;
            px[0] = (float)(0.1 + 0.5 * v + disc);
            px[1] = (float)(0.2 + 0.3 * u * v + (v > 0.8 ? 0.2 * checker : 0.0));
            px[2] = (float)(0.6 - 0.4 * v + disc * u);
        }
    return rgb;
}

static int file_exists(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (f) fclose(f);
    return f != NULL;
}

static void make_path(char *out, size_t size, const char *name)
{
    snprintf(out, size, "%s/%s", build_dir, name);
}

static int write_bytes_file(const char *path, const void *data, size_t size)
{
    FILE *f = fopen(path, "wb");
    int ok;
    if (!f) return 0;
    ok = fwrite(data, 1, size, f) == size;
    return fclose(f) == 0 && ok;
}

static int write_text_file(const char *path, const char *text)
{
    return write_bytes_file(path, text, strlen(text));
}

static int text_file_is(const char *path, const char *text)
{
    char buf[256];
    size_t n;
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    n = fread(buf, 1, sizeof buf, f);
    fclose(f);
    return n == strlen(text) && memcmp(buf, text, n) == 0;
}

/* The writers' temporary files left in the build folder: names that start
   with prefix and end in ".tmp", except the two "<output>.tmp" files the
   test made itself to see that they survive. */
static int count_temp_files(const char *prefix)
{
#if HAVE_FILE_SIZE_LIMIT
    DIR *dir = opendir(build_dir);
    struct dirent *entry;
    int count = 0;
    if (!dir) return -1;
    while ((entry = readdir(dir)) != NULL) {
        const char *name = entry->d_name;
        size_t n = strlen(name);
        if (strncmp(name, prefix, strlen(prefix)) != 0 || n < 4 || strcmp(name + n - 4, ".tmp") != 0)
            continue;
        if (strcmp(name, "test_image_tmp.pfm.tmp") == 0 || strcmp(name, "test_image_tmp.png.tmp") == 0)
            continue;
        ++count;
    }
    closedir(dir);
    return count;
#else
    (void)prefix;
    return 0;
#endif
}

/* ---- checksums -------------------------------------------------------------- */

static void test_checksums(void)
{
    static unsigned char big[200000];
    size_t i;
    CHECKF(rrv_crc32(0, "123456789", 9) == 0xCBF43926u, "got %08lx", (unsigned long)rrv_crc32(0, "123456789", 9));
    CHECKF(rrv_adler32(1, "Wikipedia", 9) == 0x11E60398u, "got %08lx", (unsigned long)rrv_adler32(1, "Wikipedia", 9));
    CHECK(rrv_crc32(0, NULL, 0) == 0);
    CHECK(rrv_adler32(1, NULL, 0) == 1);
    CHECK(rrv_crc32(rrv_crc32(0, "1234", 4), "56789", 5) == 0xCBF43926u);
    CHECK(rrv_adler32(rrv_adler32(1, "Wiki", 4), "pedia", 5) == 0x11E60398u);

    /* All 0xFF is the worst case for the deferred modulo in Adler-32. */
    memset(big, 0xFF, sizeof big);
    CHECK(rrv_adler32(1, big, sizeof big) == naive_adler32(big, sizeof big));
    CHECK(rrv_crc32(0, big, sizeof big) == bitwise_crc32(big, sizeof big));
    for (i = 0; i < sizeof big; ++i) big[i] = (unsigned char)lcg_next();
    CHECK(rrv_adler32(1, big, sizeof big) == naive_adler32(big, sizeof big));
    CHECK(rrv_crc32(0, big, sizeof big) == bitwise_crc32(big, sizeof big));
    CHECK(rrv_adler32(rrv_adler32(1, big, 7777), big + 7777, sizeof big - 7777) == naive_adler32(big, sizeof big));
    CHECK(rrv_crc32(rrv_crc32(0, big, 7777), big + 7777, sizeof big - 7777) == bitwise_crc32(big, sizeof big));
}

/* ---- PFM writing and reading in memory ------------------------------------------ */

static void check_pfm_round_trip(int width, int height)
{
    static const float specials[] = { -0.0f, 1e-40f /* subnormal */, FLT_MAX, -FLT_MAX, -1.5f, 0.0f, 12345.5f };
    size_t n = (size_t)width * (size_t)height * 3, i, header_len;
    float *rgb = make_image(width, height), *back = NULL;
    char header[64];
    byte_sink sink;
    int w = -1, h = -1, x, y, c;
    rrv_error err;
    rrv_result r;

    if (!rgb) { CHECK(rgb != NULL); return; }
    for (i = 0; i < n && i < sizeof specials / sizeof specials[0]; ++i) rgb[n - 1 - i] = specials[i];
    if (n > 3) rgb[n / 2] = INFINITY;
    rgb[0] = 12345.5f; /* the top-left pixel, which PFM stores in its last row */

    sink_init(&sink, (size_t)-1);
    r = rrv_write_pfm_to(sink_write, &sink, rgb, width, height, NULL);
    CHECKF(r == RRV_OK, "%dx%d: %s", width, height, rrv_result_string(r));
    snprintf(header, sizeof header, "PF\n%d %d\n-1.0\n", width, height);
    header_len = strlen(header);
    CHECKF(sink.size == header_len + n * 4, "%dx%d: %lu bytes", width, height, (unsigned long)sink.size);
    if (sink.size != header_len + n * 4) { sink_free(&sink); free(rgb); return; }
    CHECKF(memcmp(sink.data, header, header_len) == 0, "%dx%d: header differs", width, height);

    /* Rows bottom to top, floats little-endian, whatever the host. */
    CHECK(read_u32_le(sink.data + header_len + (size_t)(height - 1) * (size_t)width * 12) == float_bits(12345.5f));
    for (y = 0; y < height; ++y)
        for (x = 0; x < width; ++x)
            for (c = 0; c < 3; ++c) {
                size_t file_row = (size_t)(height - 1 - y);
                const unsigned char *p = sink.data + header_len + ((file_row * (size_t)width + (size_t)x) * 3 + (size_t)c) * 4;
                uint32_t want = float_bits(rgb[((size_t)y * (size_t)width + (size_t)x) * 3 + (size_t)c]);
                if (read_u32_le(p) != want) {
                    CHECKF(read_u32_le(p) == want, "%dx%d pixel %d,%d channel %d", width, height, x, y, c);
                    y = height; x = width; break;
                }
            }

    r = rrv_read_pfm_memory(sink.data, sink.size, "mem.pfm", &back, &w, &h, &err);
    CHECKF(r == RRV_OK, "%dx%d: %s", width, height, err.message);
    CHECK(err.code == RRV_OK);
    CHECK(w == width && h == height);
    CHECK(back && memcmp(back, rgb, n * sizeof *rgb) == 0);
    rrv_free(back);
    sink_free(&sink);
    free(rgb);
}

static void test_pfm_memory_round_trip(void)
{
    check_pfm_round_trip(1, 1);
    check_pfm_round_trip(7, 3);
    check_pfm_round_trip(3, 7);
    check_pfm_round_trip(64, 33);
    /* more than one 64 KiB piece of output */
    check_pfm_round_trip(160, 120);
}

/* The header fields may be separated by any whitespace, and exactly one
   whitespace byte ends the header even when the data starts with bytes that
   look like whitespace. */
static void test_pfm_byte_orders_and_grey(void)
{
    float values[6 * 3];
    float *rgb = NULL;
    int w = 0, h = 0, i, x, y, c;
    byte_sink file;
    rrv_error err;
    rrv_result r;

    for (i = 0; i < 18; ++i) values[i] = (float)(i * 0.75 - 4.0);
    /* bit patterns whose first file byte is ' ' or '\n' */
    memcpy(&values[0], &(uint32_t){ 0x3F800020u }, 4);
    memcpy(&values[9], &(uint32_t){ 0x4000000Au }, 4);

    /* big-endian RGB, 2 wide and 3 high; the file lists the bottom row first */
    sink_init(&file, (size_t)-1);
    sink_append_text(&file, "PF\n2 3\n1.0\n");
    for (y = 2; y >= 0; --y)
        for (x = 0; x < 2; ++x)
            for (c = 0; c < 3; ++c) sink_append_float(&file, values[(y * 2 + x) * 3 + c], 1);
    r = rrv_read_pfm_memory(file.data, file.size, "be.pfm", &rgb, &w, &h, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(w == 2 && h == 3);
    CHECK(rgb && memcmp(rgb, values, sizeof values) == 0);
    rrv_free(rgb);
    rgb = NULL;
    sink_free(&file);

    /* little-endian RGB with the leading data byte ' ' and an integer scale */
    sink_init(&file, (size_t)-1);
    sink_append_text(&file, "PF\n2 3\n-1\n");
    for (y = 2; y >= 0; --y)
        for (x = 0; x < 2; ++x)
            for (c = 0; c < 3; ++c) sink_append_float(&file, values[(y * 2 + x) * 3 + c], 0);
    r = rrv_read_pfm_memory(file.data, file.size, "le.pfm", &rgb, &w, &h, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(w == 2 && h == 3);
    CHECK(rgb && memcmp(rgb, values, sizeof values) == 0);
    rrv_free(rgb);
    rgb = NULL;
    sink_free(&file);

    /* grey, both byte orders, unusual spacing and scale spelling */
    for (i = 0; i < 2; ++i) {
        int big_endian = i == 1;
        float grey[6];
        for (x = 0; x < 6; ++x) grey[x] = (float)(x * 1.25 - 2.0);
        memcpy(&grey[3], &(uint32_t){ 0x0A0A0A0Au }, 4);
        sink_init(&file, (size_t)-1);
        sink_append_text(&file, big_endian ? "Pf \t3\r\n2  +2.5e0\n" : "Pf\n3\n2\n-.5E+1 ");
        for (y = 1; y >= 0; --y)
            for (x = 0; x < 3; ++x) sink_append_float(&file, grey[y * 3 + x], big_endian);
        r = rrv_read_pfm_memory(file.data, file.size, "grey.pfm", &rgb, &w, &h, &err);
        CHECKF(r == RRV_OK, "%s endian: %s", big_endian ? "big" : "little", err.message);
        CHECK(w == 3 && h == 2);
        if (rgb && r == RRV_OK)
            for (x = 0; x < 6; ++x)
                for (c = 0; c < 3; ++c)
                    CHECKF(float_bits(rgb[x * 3 + c]) == float_bits(grey[x]), "pixel %d channel %d", x, c);
        rrv_free(rgb);
        rgb = NULL;
        sink_free(&file);
    }

    /* bytes after the pixel data are ignored */
    sink_init(&file, (size_t)-1);
    sink_append_text(&file, "PF\n1 1\n-1.0\n");
    for (c = 0; c < 3; ++c) sink_append_float(&file, (float)c, 0);
    sink_append_text(&file, "trailing");
    r = rrv_read_pfm_memory(file.data, file.size, "tail.pfm", &rgb, &w, &h, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(rgb && rgb[0] == 0.0f && rgb[1] == 1.0f && rgb[2] == 2.0f);
    rrv_free(rgb);
    sink_free(&file);
}

/* ---- malformed PFM input ----------------------------------------------------------- */

/* Copies the input to a block of exactly its size so the sanitizers catch any
   read past its end. */
static void expect_format_error(const void *data, size_t size, const char *label)
{
    unsigned char *copy = (unsigned char *)malloc(size ? size : 1);
    float *rgb = &not_reset;
    int w = -1, h = -1;
    rrv_error err;
    rrv_result r;
    if (!copy) { CHECK(copy != NULL); return; }
    if (size) memcpy(copy, data, size);
    memset(&err, 0x55, sizeof err);
    r = rrv_read_pfm_memory(copy, size, "bad.pfm", &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_FORMAT, "%s: got %s", label, rrv_result_string(r));
    CHECKF(err.code == RRV_ERROR_FORMAT && err.line == 0 && strcmp(err.file, "bad.pfm") == 0,
           "%s: error not filled in", label);
    CHECKF(err.message[0] != '\0' && memchr(err.message, '\0', sizeof err.message) != NULL,
           "%s: no message", label);
    CHECKF(rgb == NULL && w == 0 && h == 0, "%s: outputs not reset", label);
    if (r == RRV_OK) rrv_free(rgb);

    /* The file form reads the header and then the data on its own, and must
       come to the same verdict with the same words. */
    {
        char path[1024];
        FILE *f;
        rrv_error file_err;
        make_path(path, sizeof path, "test_image_malformed.pfm");
        f = fopen(path, "wb");
        CHECK(f != NULL);
        if (f) {
            CHECK(fwrite(copy, 1, size, f) == size);
            CHECK(fclose(f) == 0);
            rgb = &not_reset;
            r = rrv_read_pfm(path, &rgb, &w, &h, &file_err);
            CHECKF(r == RRV_ERROR_FORMAT && strcmp(file_err.message, err.message) == 0,
                   "%s: the file form says %s \"%s\", the memory form \"%s\"", label,
                   rrv_result_string(r), file_err.message, err.message);
            CHECKF(rgb == NULL && w == 0 && h == 0, "%s: file form: outputs not reset", label);
            if (r == RRV_OK) rrv_free(rgb);
            remove(path);
        }
    }
    free(copy);
}

static void expect_format_error_text(const char *header, size_t data_bytes, const char *label)
{
    byte_sink s;
    size_t i;
    sink_init(&s, (size_t)-1);
    sink_append_text(&s, header);
    for (i = 0; i < data_bytes; ++i) sink_append(&s, "\x3f", 1);
    expect_format_error(s.data, s.size, label);
    sink_free(&s);
}

static void test_pfm_malformed(void)
{
    byte_sink good;
    float pixels[3 * 2 * 3];
    size_t i, header_len;
    int trial;

    expect_format_error("", 0, "empty");
    expect_format_error("P", 1, "one byte");
    expect_format_error_text("P6\n1 1\n255\n", 3, "binary PPM");
    expect_format_error_text("pf\n1 1\n-1.0\n", 12, "lower-case magic");
    expect_format_error_text("PF1 1\n-1.0\n", 12, "no space after magic");
    expect_format_error_text("PF\n0 3\n-1.0\n", 36, "zero width");
    expect_format_error_text("PF\n3 0\n-1.0\n", 36, "zero height");
    expect_format_error_text("PF\n-2 3\n-1.0\n", 72, "negative width");
    expect_format_error_text("PF\n+2 3\n-1.0\n", 72, "signed width");
    expect_format_error_text("PF\n2x 3\n-1.0\n", 72, "junk after width");
    expect_format_error_text("PF\n2\n", 0, "no height");
    expect_format_error_text("PF\n2 3\n", 0, "no scale");
    expect_format_error_text("PF\n99999999999 1\n-1.0\n", 12, "width beyond int");
    expect_format_error_text("PF\n100000000 100000000\n-1.0\n", 0, "huge dimensions");
    expect_format_error_text("PF\n2147483647 2147483647\n-1.0\n", 64, "byte count overflows");
    expect_format_error_text("Pf\n2147483647 2147483647\n-1.0\n", 64, "grey byte count overflows");
    expect_format_error_text("PF\n2 2\n0.0\n", 48, "zero scale");
    expect_format_error_text("PF\n2 2\n-0\n", 48, "negative zero scale");
    expect_format_error_text("PF\n2 2\n-1e-999\n", 48, "scale underflows to zero");
    expect_format_error_text("PF\n2 2\n1e999\n", 48, "infinite scale");
    expect_format_error_text("PF\n2 2\nnan\n", 48, "NaN scale");
    expect_format_error_text("PF\n2 2\ninf\n", 48, "inf scale");
    expect_format_error_text("PF\n2 2\n-\n", 48, "sign only");
    expect_format_error_text("PF\n2 2\n.\n", 48, "dot only");
    expect_format_error_text("PF\n2 2\n1e\n", 48, "empty exponent");
    expect_format_error_text("PF\n2 2\n-1.0x\n", 48, "junk after scale");
    expect_format_error_text("PF\n2 2\n-1.0", 0, "header ends at scale");
    expect_format_error_text("PF\n2 2\n-1.0\n", 0, "no pixel data");
    expect_format_error_text("PF\n2 2\n-1.0\n", 47, "one byte short");
    expect_format_error_text("Pf\n2 2\n-1.0\n", 15, "grey one byte short");

    /* Every proper prefix of a good file is truncated. */
    for (i = 0; i < sizeof pixels / sizeof pixels[0]; ++i) pixels[i] = (float)i;
    sink_init(&good, (size_t)-1);
    CHECK(rrv_write_pfm_to(sink_write, &good, pixels, 3, 2, NULL) == RRV_OK);
    for (i = 0; i < good.size; ++i) {
        char label[64];
        snprintf(label, sizeof label, "prefix of %lu bytes", (unsigned long)i);
        expect_format_error(good.data, i, label);
    }

    /* Random damage to the header must never crash; whatever is accepted
       must describe a buffer that fits in the input. */
    header_len = strlen("PF\n3 2\n-1.0\n");
    for (trial = 0; trial < 3000; ++trial) {
        unsigned char *copy = (unsigned char *)malloc(good.size);
        float *rgb = NULL;
        int w = 0, h = 0, k;
        rrv_error err;
        rrv_result r;
        if (!copy) break;
        memcpy(copy, good.data, good.size);
        for (k = 0; k < 1 + trial % 3; ++k) {
            size_t at = lcg_next() % header_len;
            static const char alphabet[] = "PFf0123456789 \n-+.eE\tx";
            copy[at] = (trial & 1) ? (unsigned char)lcg_next()
                                   : (unsigned char)alphabet[lcg_next() % (sizeof alphabet - 1)];
        }
        r = rrv_read_pfm_memory(copy, good.size, "fuzz.pfm", &rgb, &w, &h, &err);
        CHECKF(r == RRV_OK || r == RRV_ERROR_FORMAT, "trial %d: %s", trial, rrv_result_string(r));
        if (trial % 10 == 0) { /* the file form agrees, on a sample of the trials */
            char path[1024];
            FILE *f;
            make_path(path, sizeof path, "test_image_damaged.pfm");
            f = fopen(path, "wb");
            if (f && fwrite(copy, 1, good.size, f) == good.size && fclose(f) == 0) {
                float *file_rgb = NULL;
                int fw = 0, fh = 0;
                rrv_error file_err;
                rrv_result fr = rrv_read_pfm(path, &file_rgb, &fw, &fh, &file_err);
                CHECKF(fr == r && (r != RRV_OK || (fw == w && fh == h &&
                                                   memcmp(file_rgb, rgb, (size_t)w * h * 3 * sizeof(float)) == 0)) &&
                           (r == RRV_OK || strcmp(file_err.message, err.message) == 0),
                       "trial %d: file form %s \"%s\", memory form %s \"%s\"", trial,
                       rrv_result_string(fr), fr == RRV_OK ? "" : file_err.message,
                       rrv_result_string(r), r == RRV_OK ? "" : err.message);
                rrv_free(file_rgb);
            } else {
                CHECKF(0, "cannot write %s", path);
                if (f) fclose(f);
            }
            remove(path);
        }
        if (r == RRV_OK) {
            CHECK(rgb != NULL && w > 0 && h > 0 && (size_t)w * (size_t)h * 4 <= good.size);
            rrv_free(rgb);
        } else {
            CHECK(rgb == NULL);
        }
        free(copy);
    }
    sink_free(&good);
}

/* ---- PNG structure ----------------------------------------------------------------- */

static unsigned char expected_srgb8(float value, double exposure)
{
    double linear = (double)value * pow(2.0, exposure), encoded;
    if (isnan(linear) || linear <= 0.0) return 0;
    if (linear >= 1.0) return 255;
    if (linear <= 0.0031308) encoded = 12.92 * linear;
    else encoded = 1.055 * pow(linear, 1.0 / 2.4) - 0.055;
    return (unsigned char)floor(encoded * 255.0 + 0.5);
}

/* What check_png saw in the zlib stream. */
typedef struct png_stats {
    int blocks[3];       /* deflate blocks: stored, fixed Huffman, dynamic Huffman */
    int filters[5];      /* rows filtered with None, Sub, Up, Average, Paeth */
    size_t zlib_size;    /* the IDAT payload */
} png_stats;

/* PNG's Paeth predictor, as the specification writes it. */
static int paeth_predictor(int a, int b, int c)
{
    int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
    if (pa <= pb && pa <= pc) return a;
    if (pb <= pc) return b;
    return c;
}

/* Takes a PNG apart, inflates it with test/inflate.h, undoes the row filters
   and checks every byte of it against the float image. */
static void check_png(const byte_sink *png, const float *rgb, int width, int height, double exposure,
                      png_stats *stats_out, const char *label)
{
    static const unsigned char signature[8] = { 137, 80, 78, 71, 13, 10, 26, 10 };
    const unsigned char *p = png->data;
    size_t pos = 8, idat_size = 0, raw_size = 0, stride = 1 + 3 * (size_t)width;
    size_t expected_raw = (size_t)height * stride;
    unsigned char *idat = NULL, *raw = NULL, *pixels = NULL;
    int chunk_index = 0, seen_iend = 0, idat_done = 0, x, y, c, mismatches = 0;
    png_stats stats;

    memset(&stats, 0, sizeof stats);
    CHECKF(png->size >= 8 && memcmp(p, signature, 8) == 0, "%s: signature", label);
    if (png->size < 8) return;
    idat = (unsigned char *)malloc(png->size);
    raw = (unsigned char *)malloc(expected_raw + 1);
    pixels = (unsigned char *)malloc(expected_raw + 1);
    if (!idat || !raw || !pixels) { CHECK(idat && raw && pixels); free(idat); free(raw); free(pixels); return; }

    while (pos < png->size && !seen_iend) {
        uint32_t length, crc_stored;
        char type[5];
        const unsigned char *body;
        if (png->size - pos < 12) { CHECKF(0, "%s: chunk header cut off at %lu", label, (unsigned long)pos); break; }
        length = read_u32_be(p + pos);
        memcpy(type, p + pos + 4, 4);
        type[4] = '\0';
        if (length > png->size - pos - 12) { CHECKF(0, "%s: chunk %s length %lu overruns", label, type, (unsigned long)length); break; }
        body = p + pos + 8;
        crc_stored = read_u32_be(body + length);
        CHECKF(crc_stored == bitwise_crc32(p + pos + 4, 4 + (size_t)length), "%s: chunk %d (%s) CRC", label, chunk_index, type);
        if (chunk_index == 0) {
            CHECKF(strcmp(type, "IHDR") == 0 && length == 13, "%s: first chunk is %s", label, type);
            if (length == 13) {
                CHECK(read_u32_be(body) == (uint32_t)width);
                CHECK(read_u32_be(body + 4) == (uint32_t)height);
                CHECK(body[8] == 8);  /* bit depth */
                CHECK(body[9] == 2);  /* RGB */
                CHECK(body[10] == 0 && body[11] == 0 && body[12] == 0);
            }
        } else if (strcmp(type, "IDAT") == 0) {
            CHECKF(!idat_done, "%s: IDAT chunks must be consecutive", label);
            memcpy(idat + idat_size, body, length);
            idat_size += length;
        } else if (strcmp(type, "IEND") == 0) {
            CHECK(length == 0);
            seen_iend = 1;
        } else {
            CHECKF(0, "%s: unexpected chunk %s", label, type);
        }
        if (idat_size > 0 && strcmp(type, "IDAT") != 0) idat_done = 1;
        pos += 12 + (size_t)length;
        ++chunk_index;
    }
    CHECKF(seen_iend && pos == png->size, "%s: IEND missing or not last", label);
    CHECKF(chunk_index >= 3, "%s: only %d chunks", label, chunk_index);

    /* zlib: rrv's header, then whatever blocks; the inflate checks the Adler-32 */
    stats.zlib_size = idat_size;
    CHECKF(idat_size >= 2 && idat[0] == 0x78 && idat[1] == 0x01, "%s: zlib header", label);
    raw_size = zlib_inflate_blocks(idat, idat_size, raw, expected_raw + 1, stats.blocks);
    CHECKF(raw_size == expected_raw, "%s: inflates to %ld filtered bytes, expected %lu", label,
           raw_size == (size_t)-1 ? -1L : (long)raw_size, (unsigned long)expected_raw);

    if (raw_size == expected_raw) {
        /* undo the filters; the row above the first is zeros */
        for (y = 0; y < height; ++y) {
            const unsigned char *in = raw + (size_t)y * stride;
            unsigned char *out = pixels + (size_t)y * stride, *up = y > 0 ? out - stride : NULL;
            int filter = in[0];
            CHECKF(filter <= 4, "%s: row %d filter %d", label, y, filter);
            if (filter > 4) break;
            ++stats.filters[filter];
            for (x = 1; x < (int)stride; ++x) {
                int a = x > 3 ? out[x - 3] : 0, b = up ? up[x] : 0, cc = x > 3 && up ? up[x - 3] : 0;
                int predicted = filter == 0 ? 0 : filter == 1 ? a : filter == 2 ? b
                              : filter == 3 ? (a + b) / 2 : paeth_predictor(a, b, cc);
                out[x] = (unsigned char)((in[x] + predicted) & 255);
            }
        }
        for (y = 0; y < height && mismatches < 5; ++y) {
            const unsigned char *row = pixels + (size_t)y * stride;
            for (x = 0; x < width; ++x)
                for (c = 0; c < 3; ++c) {
                    float v = rgb[((size_t)y * (size_t)width + (size_t)x) * 3 + (size_t)c];
                    unsigned char want = expected_srgb8(v, exposure), got = row[1 + 3 * x + c];
                    if (got != want && mismatches++ < 5)
                        CHECKF(got == want, "%s: pixel %d,%d channel %d value %g: got %d, expected %d",
                               label, x, y, c, (double)v, got, want);
                }
        }
    }
    if (stats_out) *stats_out = stats;
    free(idat);
    free(raw);
    free(pixels);
}

static void write_and_check_png(const float *rgb, int width, int height, double exposure,
                                png_stats *stats, const char *label)
{
    byte_sink sink;
    rrv_result r;
    sink_init(&sink, (size_t)-1);
    r = rrv_write_png_to(sink_write, &sink, rgb, width, height, exposure, NULL);
    CHECKF(r == RRV_OK, "%s: %s", label, rrv_result_string(r));
    if (r == RRV_OK) check_png(&sink, rgb, width, height, exposure, stats, label);
    sink_free(&sink);
}

static void test_png_structure(void)
{
    /* channel 0 holds the value itself; 1 and 2 scaled copies */
    static const float base[4][5] = {
        { 0.0f, 1.0f, 2.5f, -1.0f, NAN },
        { 0.5f, 0.25f, 0.18f, 1e-4f, INFINITY },
        { -INFINITY, 0.0031308f, 0.999f, 0.05f, 1e-30f },
        { 0.9f, 0.001f, 1.0001f, -0.0f, 0.75f },
    };
    float small[4 * 5 * 3];
    float *big = make_image(200, 120);
    float one[3] = { 0.5f, NAN, 3.0f };
    byte_sink sink;
    int x, y;

    /* the reference encoder itself, on values worked out by hand */
    CHECK(expected_srgb8(0.5f, 0.0) == 188);
    CHECK(expected_srgb8(0.25f, 1.0) == 188);
    CHECK(expected_srgb8(0.18f, 0.0) == 118);
    CHECK(expected_srgb8(0.9f, 0.0) == 243);
    CHECK(expected_srgb8(0.001f, 0.0) == 3);
    CHECK(expected_srgb8(1.0f, 0.0) == 255 && expected_srgb8(2.5f, 0.0) == 255);
    CHECK(expected_srgb8(-1.0f, 0.0) == 0 && expected_srgb8(NAN, 0.0) == 0);

    for (y = 0; y < 4; ++y)
        for (x = 0; x < 5; ++x) {
            float v = base[y][x];
            small[(y * 5 + x) * 3 + 0] = v;
            small[(y * 5 + x) * 3 + 1] = v * 0.5f;
            small[(y * 5 + x) * 3 + 2] = v * 0.25f;
        }
    write_and_check_png(small, 5, 4, 0.0, NULL, "5x4 exposure 0");
    write_and_check_png(small, 5, 4, 1.0, NULL, "5x4 exposure 1");
    write_and_check_png(small, 5, 4, -0.5, NULL, "5x4 exposure -0.5");
    write_and_check_png(one, 1, 1, 0.0, NULL, "1x1");
    if (big) {
        for (x = 0; x < 200 * 120 * 3; x += 97) big[x] = NAN;
        write_and_check_png(big, 200, 120, 0.0, NULL, "200x120 exposure 0");
        write_and_check_png(big, 200, 120, 1.0, NULL, "200x120 exposure 1");
    } else {
        CHECK(big != NULL);
    }
    free(big);
    big = make_noise_image(200, 120);
    if (big) {
        /* Uniformly random bytes do not shrink: every block must fall back
           to stored, 5 bytes of header per 64 KiB (72120 bytes: 2 blocks). */
        png_stats st;
        write_and_check_png(big, 200, 120, 0.0, &st, "200x120 noise");
        CHECKF(st.blocks[0] >= 2 && st.blocks[1] == 0 && st.blocks[2] == 0,
               "noise: %d stored, %d fixed, %d dynamic blocks", st.blocks[0], st.blocks[1], st.blocks[2]);
        CHECKF(st.zlib_size <= 2 + 120 * 601 + 5 * 2 + 4, "noise: %lu zlib bytes", (unsigned long)st.zlib_size);

        /* streamed in pieces, not handed over as one block */
        sink_init(&sink, (size_t)-1);
        CHECK(rrv_write_png_to(sink_write, &sink, big, 200, 120, 0.0, NULL) == RRV_OK);
        CHECKF(sink.calls >= 4 && sink.largest_write < sink.size / 2,
               "%d calls, largest %lu of %lu", sink.calls, (unsigned long)sink.largest_write, (unsigned long)sink.size);
        sink_free(&sink);
        sink_init(&sink, (size_t)-1);
        CHECK(rrv_write_pfm_to(sink_write, &sink, big, 200, 120, NULL) == RRV_OK);
        CHECKF(sink.calls >= 2 && sink.largest_write < sink.size,
               "%d calls, largest %lu of %lu", sink.calls, (unsigned long)sink.largest_write, (unsigned long)sink.size);
        sink_free(&sink);
    } else {
        CHECK(big != NULL);
    }
    free(big);
    big = make_smooth_image(400, 300);
    if (big) {
        /* 300 rows of 1201 bytes is 360300 bytes, more than one 256 KiB
           block. A smooth image must really compress: every block with
           Huffman codes, the whole under 1/8 of the filtered bytes (a
           stored or a filter-less stream would be far above it), and the
           filters in use beyond None. */
        png_stats st;
        int f, used = 0;
        write_and_check_png(big, 400, 300, 0.0, &st, "400x300 smooth");
        CHECKF(st.blocks[2] >= 2 && st.blocks[0] == 0,
               "smooth: %d stored, %d fixed, %d dynamic blocks", st.blocks[0], st.blocks[1], st.blocks[2]);
        CHECKF(st.zlib_size < 300 * 1201 / 8, "smooth: %lu zlib bytes of 360300", (unsigned long)st.zlib_size);
        for (f = 1; f < 5; ++f) used += st.filters[f] > 0;
        CHECKF(st.filters[0] < 300 && used >= 1, "smooth: filters None %d Sub %d Up %d Average %d Paeth %d",
               st.filters[0], st.filters[1], st.filters[2], st.filters[3], st.filters[4]);
        write_and_check_png(big, 400, 300, -2.0, NULL, "400x300 smooth exposure -2");
    } else {
        CHECK(big != NULL);
    }
    free(big);

    /* Rows longer than a deflate block (90000 pixels, 270001 bytes): each
       row is a block of its own, stored ones split into 64 KiB pieces. */
    big = make_smooth_image(90000, 2);
    if (big) write_and_check_png(big, 90000, 2, 0.0, NULL, "90000x2 smooth");
    CHECK(big != NULL);
    free(big);
    big = make_noise_image(90000, 2);
    if (big) {
        png_stats st;
        write_and_check_png(big, 90000, 2, 0.0, &st, "90000x2 noise");
        CHECKF(st.blocks[0] >= 9, "90000x2 noise: %d stored blocks", st.blocks[0]);
    }
    CHECK(big != NULL);
    free(big);
}

/* ---- write failures and bad arguments ------------------------------------------------ */

static void test_writer_failures(void)
{
    static const size_t fail_points[] = { 0, 1, 8, 12, 32, 33, 45, 100, 40000, 65536, 65537, 100000 };
    float *img = make_image(200, 120);
    float pixel[3] = { 1, 2, 3 };
    byte_sink sink;
    size_t total_pfm, total_png, i;
    int kind;

    if (!img) { CHECK(img != NULL); return; }
    sink_init(&sink, (size_t)-1);
    CHECK(rrv_write_pfm_to(sink_write, &sink, img, 200, 120, NULL) == RRV_OK);
    total_pfm = sink.size;
    sink_free(&sink);
    sink_init(&sink, (size_t)-1);
    CHECK(rrv_write_png_to(sink_write, &sink, img, 200, 120, 0.0, NULL) == RRV_OK);
    total_png = sink.size;
    sink_free(&sink);

    for (kind = 0; kind < 2; ++kind) {
        size_t total = kind ? total_png : total_pfm;
        for (i = 0; i <= sizeof fail_points / sizeof fail_points[0] + 1; ++i) {
            size_t fail_after = i < sizeof fail_points / sizeof fail_points[0] ? fail_points[i]
                              : i == sizeof fail_points / sizeof fail_points[0] ? total - 1 : total - 12;
            rrv_result r;
            if (fail_after >= total) continue;
            sink_init(&sink, fail_after);
            r = kind ? rrv_write_png_to(sink_write, &sink, img, 200, 120, 0.0, NULL)
                     : rrv_write_pfm_to(sink_write, &sink, img, 200, 120, NULL);
            CHECKF(r == RRV_ERROR_IO, "%s failing after %lu bytes: %s", kind ? "PNG" : "PFM",
                   (unsigned long)fail_after, rrv_result_string(r));
            CHECKF(sink.calls_after_failure == 0, "%s: %d writes after the failure", kind ? "PNG" : "PFM",
                   sink.calls_after_failure);
            sink_free(&sink);
        }
        sink_init(&sink, total);
        CHECK((kind ? rrv_write_png_to(sink_write, &sink, img, 200, 120, 0.0, NULL)
                    : rrv_write_pfm_to(sink_write, &sink, img, 200, 120, NULL)) == RRV_OK);
        sink_free(&sink);
    }

    sink_init(&sink, (size_t)-1);
    CHECK(rrv_write_pfm_to(NULL, &sink, pixel, 1, 1, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_pfm_to(sink_write, &sink, NULL, 1, 1, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_pfm_to(sink_write, &sink, pixel, 0, 1, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_pfm_to(sink_write, &sink, pixel, 1, -1, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png_to(NULL, &sink, pixel, 1, 1, 0.0, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png_to(sink_write, &sink, NULL, 1, 1, 0.0, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png_to(sink_write, &sink, pixel, -3, 1, 0.0, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png_to(sink_write, &sink, pixel, 1, 0, 0.0, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png_to(sink_write, &sink, pixel, 1, 1, NAN, NULL) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png_to(sink_write, &sink, pixel, 1, 1, INFINITY, NULL) == RRV_ERROR_ARGUMENT);
    CHECKF(sink.calls == 0, "%d writes for rejected arguments", sink.calls);
    sink_free(&sink);

    {
        float *rgb = &not_reset;
        int w = 1, h = 1;
        rrv_error err;
        CHECK(rrv_read_pfm_memory(NULL, 5, "x", &rgb, &w, &h, &err) == RRV_ERROR_ARGUMENT);
        CHECK(rgb == NULL && w == 0 && h == 0);
        CHECK(rrv_read_pfm_memory("PF", 2, "x", NULL, &w, &h, &err) == RRV_ERROR_ARGUMENT);
        CHECK(rrv_read_pfm_memory("PF", 2, "x", &rgb, &w, &h, NULL) == RRV_ERROR_FORMAT);
    }
    free(img);
}

/* ---- file forms ---------------------------------------------------------------------- */

static void read_file_bytes(const char *path, byte_sink *out)
{
    FILE *f = fopen(path, "rb");
    unsigned char buffer[4096];
    size_t got;
    sink_init(out, (size_t)-1);
    if (!f) return;
    while ((got = fread(buffer, 1, sizeof buffer, f)) > 0) sink_append(out, buffer, got);
    fclose(f);
}

static void expect_pfm_file(const char *path, const float *rgb, int width, int height, const char *label)
{
    float *back = NULL;
    int w = 0, h = 0;
    rrv_error err;
    rrv_result r = rrv_read_pfm(path, &back, &w, &h, &err);
    CHECKF(r == RRV_OK, "%s: %s: %s", label, path, err.message);
    CHECKF(w == width && h == height, "%s: %dx%d", label, w, h);
    CHECKF(back && w == width && h == height
           && memcmp(back, rgb, (size_t)width * (size_t)height * 3 * sizeof *rgb) == 0, "%s: pixels differ", label);
    rrv_free(back);
}

static void test_pfm_png_files(void)
{
    char path[1024], temp[1100], png_path[1024], png_temp[1100], missing[1024];
    float *first = make_image(7, 5), *second = make_image(9, 2);
    float *rgb = &not_reset;
    int w = 1, h = 1;
    byte_sink from_file, from_callback;
    rrv_error err;
    rrv_result r;

    if (!first || !second) { CHECK(first && second); free(first); free(second); return; }
    make_path(path, sizeof path, "test_image_tmp.pfm");
    snprintf(temp, sizeof temp, "%s.tmp", path);
    make_path(png_path, sizeof png_path, "test_image_tmp.png");
    snprintf(png_temp, sizeof png_temp, "%s.tmp", png_path);
    remove(path);
    remove(png_path);
    /* A file that happens to be called "<out>.tmp" is not the writer's. */
    CHECK(write_text_file(temp, "not yours"));
    CHECK(write_text_file(png_temp, "not yours either"));

    r = rrv_write_pfm(path, first, 7, 5, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(err.code == RRV_OK);
    expect_pfm_file(path, first, 7, 5, "first write");
    /* replacing an existing file */
    r = rrv_write_pfm(path, second, 9, 2, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    expect_pfm_file(path, second, 9, 2, "overwrite");

    /* invalid arguments touch nothing */
    CHECK(rrv_write_pfm(path, NULL, 9, 2, &err) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_pfm(path, first, 0, 2, &err) == RRV_ERROR_ARGUMENT);
    CHECK(rrv_write_png(png_path, first, 7, 5, NAN, &err) == RRV_ERROR_ARGUMENT);
    CHECK(!file_exists(png_path));
    expect_pfm_file(path, second, 9, 2, "after rejected arguments");

    /* the file form writes exactly what the callback form produces */
    r = rrv_write_png(png_path, first, 7, 5, 0.5, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    read_file_bytes(png_path, &from_file);
    sink_init(&from_callback, (size_t)-1);
    CHECK(rrv_write_png_to(sink_write, &from_callback, first, 7, 5, 0.5, NULL) == RRV_OK);
    CHECK(from_file.size == from_callback.size && from_file.size > 0
          && memcmp(from_file.data, from_callback.data, from_file.size) == 0);
    check_png(&from_file, first, 7, 5, 0.5, NULL, "PNG file");
    sink_free(&from_file);
    sink_free(&from_callback);

    /* a folder that does not exist */
    make_path(missing, sizeof missing, "no_such_folder_for_test_image/out.pfm");
    r = rrv_write_pfm(missing, first, 7, 5, &err);
    CHECKF(r == RRV_ERROR_IO && err.code == RRV_ERROR_IO, "got %s", rrv_result_string(r));
    CHECKF(strcmp(err.file, missing) == 0, "file %s", err.file);
    CHECKF(strncmp(err.message, "cannot write", 12) == 0, "message %s", err.message);
    CHECK(err.line == 0);
    CHECK(!file_exists(missing));
    CHECK(rrv_write_png(missing, first, 7, 5, 0.0, &err) == RRV_ERROR_IO);

    /* reading a file that is not there */
    make_path(missing, sizeof missing, "test_image_no_such_file.pfm");
    r = rrv_read_pfm(missing, &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_IO && err.code == RRV_ERROR_IO, "got %s", rrv_result_string(r));
    CHECKF(strcmp(err.file, missing) == 0 && strcmp(err.message, "cannot open: no such file") == 0, "%s: %s", err.file, err.message);
    CHECK(rgb == NULL && w == 0 && h == 0);

    /* a malformed file reports its own path */
    r = rrv_read_pfm(png_path, &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_FORMAT && strcmp(err.file, png_path) == 0, "%s: %s", err.file, err.message);

#if HAVE_FILE_SIZE_LIMIT
    /* Writes that fail part way, here by a file size limit that makes fwrite
       or fclose fail, leave the existing file as it was and no temp file. */
    {
        struct rlimit saved, small;
        float *large = make_image(64, 64);
        void (*old_handler)(int) = signal(SIGXFSZ, SIG_IGN);
        if (large && getrlimit(RLIMIT_FSIZE, &saved) == 0) {
            small = saved;
            small.rlim_cur = 4096;
            if (saved.rlim_cur == RLIM_INFINITY || saved.rlim_cur > small.rlim_cur) {
                rrv_result pfm_result, png_result;
                rrv_error pfm_err, png_err;
                if (setrlimit(RLIMIT_FSIZE, &small) == 0) {
                    pfm_result = rrv_write_pfm(path, large, 64, 64, &pfm_err);
                    png_result = rrv_write_png(png_path, large, 64, 64, 0.0, &png_err);
                    setrlimit(RLIMIT_FSIZE, &saved);
                    CHECKF(pfm_result == RRV_ERROR_IO, "PFM over the size limit: %s", rrv_result_string(pfm_result));
                    CHECKF(png_result == RRV_ERROR_IO, "PNG over the size limit: %s", rrv_result_string(png_result));
                    CHECK(strcmp(pfm_err.file, path) == 0 && strncmp(pfm_err.message, "cannot write", 12) == 0);
                    CHECK(strcmp(png_err.file, png_path) == 0 && strncmp(png_err.message, "cannot write", 12) == 0);
                    CHECK(count_temp_files("test_image_tmp.p") == 0);
                    expect_pfm_file(path, second, 9, 2, "after a failed write");
                    read_file_bytes(png_path, &from_file);
                    check_png(&from_file, first, 7, 5, 0.5, NULL, "PNG after a failed write");
                    sink_free(&from_file);
                }
            }
        }
        signal(SIGXFSZ, old_handler == SIG_ERR ? SIG_DFL : old_handler);
        free(large);
    }
#endif

    CHECK(text_file_is(temp, "not yours") && text_file_is(png_temp, "not yours either"));
    CHECK(count_temp_files("test_image_tmp.p") == 0);
    remove(temp);
    remove(png_temp);
    remove(path);
    remove(png_path);
    free(first);
    free(second);
}

/* The file reader reads the header, then exactly the data it announces. */
static void test_pfm_file_reader_bounds(void)
{
    char path[1024], spaces[1200];
    float *rgb = &not_reset, pixel[3] = {1.0f, 2.0f, 3.0f};
    int w = 1, h = 1;
    rrv_error err;
    rrv_result r;
    byte_sink s;

    make_path(path, sizeof path, "test_image_bounds.pfm");

    /* data after the announced pixels is left unread */
    sink_init(&s, (size_t)-1);
    CHECK(rrv_write_pfm_to(sink_write, &s, pixel, 1, 1, NULL) == RRV_OK);
    sink_append_text(&s, "trailing bytes that are not pixels");
    CHECK(write_bytes_file(path, s.data, s.size));
    sink_free(&s);
    r = rrv_read_pfm(path, &rgb, &w, &h, &err);
    CHECKF(r == RRV_OK && w == 1 && h == 1 && rgb[0] == 1.0f && rgb[2] == 3.0f, "%s",
           r == RRV_OK ? "wrong pixels" : err.message);
    if (r == RRV_OK) rrv_free(rgb);

    /* a header without end is refused after a bounded read */
    memset(spaces, ' ', sizeof spaces);
    memcpy(spaces, "PF", 2);
    CHECK(write_bytes_file(path, spaces, sizeof spaces));
    r = rrv_read_pfm(path, &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_FORMAT && strcmp(err.message, "bad PFM header: longer than 1024 bytes") == 0,
           "%s: %s", rrv_result_string(r), err.message);

    /* a header announcing far more than the file holds */
    CHECK(write_text_file(path, "PF\n100000 100000\n-1\nabcd"));
    r = rrv_read_pfm(path, &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_FORMAT &&
               strcmp(err.message, "truncated PFM: 100000x100000 needs 120000000000 bytes of pixel "
                                   "data but the file has 4") == 0,
           "%s: %s", rrv_result_string(r), err.message);
    remove(path);

#if HAVE_FILE_SIZE_LIMIT
    /* a device without end, a folder and a FIFO are no regular files:
       refused when opened, nothing read (before, /dev/zero was read for its
       header and a FIFO without a writer blocked in fopen: the alarm ends
       a reader that still does, and the test with it) */
    r = rrv_read_pfm("/dev/zero", &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_IO && strcmp(err.message, "cannot open: not a regular file") == 0,
           "/dev/zero: %s: %s", rrv_result_string(r), err.message);
    r = rrv_read_pfm(build_dir, &rgb, &w, &h, &err);
    CHECKF(r == RRV_ERROR_IO && strcmp(err.message, "cannot open: is a directory") == 0,
           "a folder: %s: %s", rrv_result_string(r), err.message);
    CHECK(rgb == NULL && w == 0 && h == 0);
    make_path(path, sizeof path, "test_image_fifo.pfm");
    remove(path);
    if (mkfifo(path, 0600) == 0) {
        alarm(20);
        r = rrv_read_pfm(path, &rgb, &w, &h, &err);
        CHECKF(r == RRV_ERROR_IO && strcmp(err.file, path) == 0 &&
                   strcmp(err.message, "cannot open: not a regular file") == 0,
               "FIFO: %s: %s", rrv_result_string(r), err.message);
        r = rrv_read_exr(path, &rgb, &w, &h, NULL, &err);
        CHECKF(r == RRV_ERROR_IO && strcmp(err.message, "cannot open: not a regular file") == 0,
               "FIFO as EXR: %s: %s", rrv_result_string(r), err.message);
        alarm(0);
        CHECK(rgb == NULL);
        remove(path);
    } else {
        CHECKF(0, "mkfifo %s failed", path);
    }
#endif
}

/* The file writers refuse an existing target that is not a regular file
   (it stays what it was, and no temporary file is left), also through a
   symbolic link; a link to a regular file, or a dangling one, is replaced
   by the image and the file it pointed to is left alone. */
static void test_writers_refuse_non_regular_targets(void)
{
#if HAVE_FILE_SIZE_LIMIT
    char fifo[1024], folder[1024], link_fifo[1024], kept[1024], link_kept[1024], dangling[1024];
    float pixel[3] = {1, 2, 3};
    struct stat st;
    rrv_error err;
    rrv_result r;
    int kind;
    make_path(fifo, sizeof fifo, "test_image_target_fifo");
    make_path(folder, sizeof folder, "test_image_target_folder");
    make_path(link_fifo, sizeof link_fifo, "test_image_target_link_fifo");
    make_path(kept, sizeof kept, "test_image_target_kept");
    make_path(link_kept, sizeof link_kept, "test_image_target_link_kept");
    make_path(dangling, sizeof dangling, "test_image_target_dangling");
    remove(fifo);
    rmdir(folder);
    remove(link_fifo);
    remove(link_kept);
    remove(dangling);
    CHECK(mkfifo(fifo, 0600) == 0);
    CHECK(mkdir(folder, 0700) == 0);
    CHECK(symlink("test_image_target_fifo", link_fifo) == 0);
    alarm(20); /* a writer that opened the FIFO would block */
    for (kind = 0; kind < 3; ++kind) {
        const char *names[3] = {"PFM", "PNG", "EXR"};
        const char *targets[4] = {fifo, link_fifo, folder, "/dev/null"};
        const char *kinds[4] = {"a FIFO", "a FIFO", "a directory", "a character device"};
        char want[128];
        int t;
        /* /dev/null last, and only after the FIFO was refused: a writer
           that replaces device nodes must not get to replace the system's */
        for (t = 0; t < 4 && !check__failed_in_test; ++t) {
            r = kind == 0   ? rrv_write_pfm(targets[t], pixel, 1, 1, &err)
                : kind == 1 ? rrv_write_png(targets[t], pixel, 1, 1, 0.0, &err)
                            : rrv_write_exr(targets[t], pixel, 1, 1, NULL, &err);
            snprintf(want, sizeof want, "cannot write: it is %s, not a regular file", kinds[t]);
            CHECKF(r == RRV_ERROR_IO && strcmp(err.file, targets[t]) == 0 && strcmp(err.message, want) == 0,
                   "%s to %s: %s: %s", names[kind], targets[t], rrv_result_string(r), err.message);
        }
    }
    alarm(0);
    CHECK(lstat(fifo, &st) == 0 && S_ISFIFO(st.st_mode));
    CHECK(lstat(link_fifo, &st) == 0 && S_ISLNK(st.st_mode));
    CHECK(stat(folder, &st) == 0 && S_ISDIR(st.st_mode));
    CHECK(stat("/dev/null", &st) == 0 && S_ISCHR(st.st_mode));
    CHECK(count_temp_files("test_image_target") == 0);

    /* a link to a regular file: the link becomes the image, the file stays */
    CHECK(write_text_file(kept, "keep me"));
    CHECK(symlink("test_image_target_kept", link_kept) == 0);
    CHECK(symlink("test_image_target_nowhere", dangling) == 0);
    r = rrv_write_pfm(link_kept, pixel, 1, 1, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(lstat(link_kept, &st) == 0 && S_ISREG(st.st_mode));
    CHECK(text_file_is(kept, "keep me"));
    r = rrv_write_pfm(dangling, pixel, 1, 1, &err);
    CHECKF(r == RRV_OK, "%s", err.message);
    CHECK(lstat(dangling, &st) == 0 && S_ISREG(st.st_mode));
    {
        float *rgb = NULL;
        int w = 0, h = 0;
        CHECK(rrv_read_pfm(link_kept, &rgb, &w, &h, &err) == RRV_OK && w == 1 && h == 1 && rgb[1] == 2.0f);
        rrv_free(rgb);
    }
    remove(fifo);
    rmdir(folder);
    remove(link_fifo);
    remove(kept);
    remove(link_kept);
    remove(dangling);
#endif
}

int main(int argc, char **argv)
{
    if (argc > 1) build_dir = argv[1];
    RUN(test_checksums);
    RUN(test_pfm_memory_round_trip);
    RUN(test_pfm_byte_orders_and_grey);
    RUN(test_pfm_malformed);
    RUN(test_png_structure);
    RUN(test_writer_failures);
    RUN(test_pfm_png_files);
    RUN(test_pfm_file_reader_bounds);
    RUN(test_writers_refuse_non_regular_targets);
    return CHECK_EXIT_CODE();
}
