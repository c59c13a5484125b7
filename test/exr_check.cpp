/* Reads EXR files written by rrv with the OpenEXR library itself and checks
   every attribute and every pixel: HALF and FLOAT, uncompressed and ZIP, a
   crop whose data window sits inside a larger display window, and one that
   starts at negative coordinates. Halves are compared with Imath's own
   float-to-half conversion (round to nearest even), floats bit for bit.
   `exrheader` must accept a file too. The other way round, rrv's reader
   reads files OpenEXR writes (NONE, RLE, ZIPS, ZIP; extra channels; both
   line orders) and refuses PIZ. Run by test/test_exr.c, which fails
   when this program was not built (OpenEXR missing). */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"

#include <ImfArray.h>
#include <ImfBoxAttribute.h>
#include <ImfChannelList.h>
#include <ImfCheckFile.h>
#include <ImfCompressionAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfLineOrderAttribute.h>
#include <ImfRgbaFile.h>
#include <ImfStandardAttributes.h>
#include <ImathBox.h>
#include <half.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

static std::string build_dir = "build";

static uint64_t rng_state = 0x9E3779B97F4A7C15ull;
static uint32_t next_u32()
{
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (uint32_t)(rng_state >> 32);
}

/* Smooth ramps (which ZIP shrinks), a band of noise, and the values where
   conversion has edges: signed zeros, half subnormals, the largest half,
   values beyond it, infinities and NaN. */
static std::vector<float> make_image(int width, int height)
{
    static const float specials[] = {
        0.0f, -0.0f, 1.0f, -1.0f, 5.9604645e-8f /* 2^-24 */, 2.9802322e-8f /* 2^-25 */,
        6.1035156e-5f /* 2^-14 */, 6.0975552e-5f, 65504.0f, 65519.0f, 65520.0f, 1e6f, -3e38f,
        1.0004883f /* 1 + 2^-11, a tie */, 1.0014648f /* 1 + 3*2^-11, a tie */,
        INFINITY, -INFINITY, NAN, 0.1f, 1e-30f };
    const int special_count = (int)(sizeof specials / sizeof specials[0]);
    std::vector<float> rgb((size_t)width * height * 3);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c) {
                size_t i = 3 * ((size_t)y * width + x) + c;
                float v;
                if (y == 1 && x < special_count) v = c == 1 ? -specials[x] : specials[x];
                else if (y % 7 == 3) v = (float)(next_u32() >> 8) / 16777216.0f * 40.0f - 2.0f;
                else v = 0.25f * (float)(c + 1) + (float)x / (float)width + 0.01f * (float)y;
                rgb[i] = v;
            }
    return rgb;
}

static bool same_float_bits(float a, float b)
{
    uint32_t ua, ub;
    std::memcpy(&ua, &a, 4);
    std::memcpy(&ub, &b, 4);
    return ua == ub;
}

/* The half OpenEXR would store, with rrv's documented clamp of finite
   values beyond the largest half. */
static float expected_half(float v)
{
    if (std::isfinite(v) && std::fabs(v) > 65504.0f) return v > 0 ? 65504.0f : -65504.0f;
    return (float)half(v);
}

struct case_spec {
    const char *name;
    rrv_exr_pixel pixel;
    rrv_exr_compression compression;
    int width, height, x, y, display_width, display_height;
};

static void check_file(const case_spec &spec)
{
    std::vector<float> rgb = make_image(spec.width, spec.height);
    std::string path = build_dir + "/exr_check_" + spec.name + ".exr";
    rrv_exr_options options;
    std::memset(&options, 0, sizeof options);
    options.pixel = spec.pixel;
    options.compression = spec.compression;
    options.x = spec.x;
    options.y = spec.y;
    options.display_width = spec.display_width;
    options.display_height = spec.display_height;
    rrv_error err;
    CHECKF(rrv_write_exr(path.c_str(), rgb.data(), spec.width, spec.height, &options, &err) == RRV_OK,
           "%s: %s", spec.name, err.message);

    try {
        Imf::InputFile file(path.c_str());
        const Imf::Header &h = file.header();
        Imath::Box2i data = h.dataWindow(), display = h.displayWindow();
        int dw = spec.display_width ? spec.display_width : spec.width;
        int dh = spec.display_height ? spec.display_height : spec.height;
        CHECKF(data.min.x == spec.x && data.min.y == spec.y && data.max.x == spec.x + spec.width - 1 &&
                   data.max.y == spec.y + spec.height - 1,
               "%s: dataWindow (%d %d)-(%d %d)", spec.name, data.min.x, data.min.y, data.max.x, data.max.y);
        CHECKF(display.min.x == 0 && display.min.y == 0 && display.max.x == dw - 1 && display.max.y == dh - 1,
               "%s: displayWindow (%d %d)-(%d %d)", spec.name, display.min.x, display.min.y,
               display.max.x, display.max.y);
        CHECK(h.compression() == (spec.compression == RRV_EXR_ZIP ? Imf::ZIP_COMPRESSION : Imf::NO_COMPRESSION));
        CHECK(h.lineOrder() == Imf::INCREASING_Y);
        CHECK(h.pixelAspectRatio() == 1.0f);
        CHECK(h.screenWindowCenter().x == 0.0f && h.screenWindowCenter().y == 0.0f);
        CHECK(h.screenWindowWidth() == 1.0f);
        Imf::PixelType want = spec.pixel == RRV_EXR_FLOAT ? Imf::FLOAT : Imf::HALF;
        int channels = 0;
        const char *order = "BGR";
        for (Imf::ChannelList::ConstIterator i = h.channels().begin(); i != h.channels().end(); ++i, ++channels) {
            CHECKF(channels < 3 && i.name()[0] == order[channels] && i.name()[1] == 0, "%s: channel %s",
                   spec.name, i.name());
            CHECK(i.channel().type == want && i.channel().xSampling == 1 && i.channel().ySampling == 1);
        }
        CHECK(channels == 3);

        /* Read as float into a buffer indexed from the data window's corner. */
        std::vector<float> back((size_t)spec.width * spec.height * 3, 12345.0f);
        Imf::FrameBuffer fb;
        size_t xs = 3 * sizeof(float), ys = xs * spec.width;
        char *base = (char *)back.data() - (ptrdiff_t)data.min.x * (ptrdiff_t)xs - (ptrdiff_t)data.min.y * (ptrdiff_t)ys;
        fb.insert("R", Imf::Slice(Imf::FLOAT, base, xs, ys));
        fb.insert("G", Imf::Slice(Imf::FLOAT, base + sizeof(float), xs, ys));
        fb.insert("B", Imf::Slice(Imf::FLOAT, base + 2 * sizeof(float), xs, ys));
        file.setFrameBuffer(fb);
        file.readPixels(data.min.y, data.max.y);
        int bad = 0;
        for (size_t i = 0; i < back.size(); ++i) {
            float src = rgb[i], got = back[i];
            bool ok;
            if (std::isnan(src)) ok = std::isnan(got);
            else if (spec.pixel == RRV_EXR_FLOAT) ok = same_float_bits(src, got);
            else ok = same_float_bits(expected_half(src), got);
            if (!ok && bad++ < 5)
                printf("  %s: value %zu (pixel %zu, channel %zu): wrote %.9g, OpenEXR read %.9g\n", spec.name,
                       i, i / 3, i % 3, (double)src, (double)got);
        }
        CHECKF(bad == 0, "%s: %d values differ", spec.name, bad);
    } catch (const std::exception &e) {
        CHECKF(0, "%s: OpenEXR refused the file: %s", spec.name, e.what());
    }
}

static void openexr_reads_every_variant()
{
    static const case_spec cases[] = {
        { "half_none", RRV_EXR_HALF, RRV_EXR_NO_COMPRESSION, 37, 23, 0, 0, 0, 0 },
        { "half_zip", RRV_EXR_HALF, RRV_EXR_ZIP, 37, 23, 0, 0, 0, 0 },
        { "float_none", RRV_EXR_FLOAT, RRV_EXR_NO_COMPRESSION, 37, 23, 0, 0, 0, 0 },
        { "float_zip", RRV_EXR_FLOAT, RRV_EXR_ZIP, 37, 23, 0, 0, 0, 0 },
        { "half_zip_wide", RRV_EXR_HALF, RRV_EXR_ZIP, 301, 67, 0, 0, 0, 0 },
        { "float_zip_wide", RRV_EXR_FLOAT, RRV_EXR_ZIP, 301, 67, 0, 0, 0, 0 },
        { "one_pixel", RRV_EXR_HALF, RRV_EXR_ZIP, 1, 1, 0, 0, 0, 0 },
        { "crop_half_zip", RRV_EXR_HALF, RRV_EXR_ZIP, 21, 35, 7, 5, 64, 48 },
        { "crop_float_none", RRV_EXR_FLOAT, RRV_EXR_NO_COMPRESSION, 21, 35, 40, 13, 64, 48 },
        { "crop_negative_origin", RRV_EXR_HALF, RRV_EXR_ZIP, 30, 20, -3, -2, 24, 16 },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) check_file(cases[i]);
}

/* Whole chunks of random bits do not shrink, so rrv stores them raw inside
   a ZIP file; OpenEXR must read them back bit for bit. */
static void openexr_reads_raw_chunks_in_zip_files()
{
    int width = 64, height = 40;
    std::vector<float> rgb((size_t)width * height * 3);
    for (size_t i = 0; i < rgb.size(); ++i) {
        uint32_t bits = next_u32() & 0xBF7FFFFFu; /* no infinities or NaN */
        std::memcpy(&rgb[i], &bits, 4);
    }
    std::string path = build_dir + "/exr_check_random.exr";
    rrv_exr_options options;
    std::memset(&options, 0, sizeof options);
    options.pixel = RRV_EXR_FLOAT;
    rrv_error err;
    CHECK(rrv_write_exr(path.c_str(), rgb.data(), width, height, &options, &err) == RRV_OK);
    try {
        Imf::InputFile file(path.c_str());
        std::vector<float> back(rgb.size());
        Imf::FrameBuffer fb;
        size_t xs = 3 * sizeof(float), ys = xs * width;
        fb.insert("R", Imf::Slice(Imf::FLOAT, (char *)back.data(), xs, ys));
        fb.insert("G", Imf::Slice(Imf::FLOAT, (char *)back.data() + 4, xs, ys));
        fb.insert("B", Imf::Slice(Imf::FLOAT, (char *)back.data() + 8, xs, ys));
        file.setFrameBuffer(fb);
        file.readPixels(0, height - 1);
        CHECK(std::memcmp(back.data(), rgb.data(), rgb.size() * 4) == 0);
    } catch (const std::exception &e) {
        CHECKF(0, "OpenEXR refused the file: %s", e.what());
    }
}

/* The RGBA interface, which most viewers use, fills in alpha = 1. */
static void openexr_rgba_interface_reads_halves()
{
    int width = 50, height = 33;
    std::vector<float> rgb = make_image(width, height);
    std::string path = build_dir + "/exr_check_rgba.exr";
    rrv_error err;
    CHECK(rrv_write_exr(path.c_str(), rgb.data(), width, height, NULL, &err) == RRV_OK);
    try {
        Imf::RgbaInputFile file(path.c_str());
        Imf::Array2D<Imf::Rgba> pixels(height, width);
        file.setFrameBuffer(&pixels[0][0], 1, width);
        file.readPixels(0, height - 1);
        CHECK(file.channels() == Imf::WRITE_RGB);
        int bad = 0;
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                const float *s = &rgb[3 * ((size_t)y * width + x)];
                const Imf::Rgba &p = pixels[y][x];
                float got[3] = { (float)p.r, (float)p.g, (float)p.b };
                for (int c = 0; c < 3; ++c)
                    if (std::isnan(s[c]) ? !std::isnan(got[c]) : !same_float_bits(expected_half(s[c]), got[c]))
                        ++bad;
                if ((float)p.a != 1.0f) ++bad;
            }
        CHECKF(bad == 0, "%d values differ", bad);
    } catch (const std::exception &e) {
        CHECKF(0, "OpenEXR refused the file: %s", e.what());
    }
}

/* rrv reads what OpenEXR writes: every codec rrv decodes, both pixel types,
   extra channels (skipped), an offset data window, decreasing line order;
   PIZ is refused by name. */
static void rrv_reads_openexr_files()
{
    struct variant {
        const char *name;
        Imf::Compression compression;
        Imf::PixelType type;
        Imf::LineOrder order;
    };
    static const variant variants[] = {
        { "none", Imf::NO_COMPRESSION, Imf::HALF, Imf::INCREASING_Y },
        { "rle", Imf::RLE_COMPRESSION, Imf::HALF, Imf::INCREASING_Y },
        { "zips", Imf::ZIPS_COMPRESSION, Imf::FLOAT, Imf::INCREASING_Y },
        { "zip", Imf::ZIP_COMPRESSION, Imf::HALF, Imf::INCREASING_Y },
        { "zip_float_decreasing", Imf::ZIP_COMPRESSION, Imf::FLOAT, Imf::DECREASING_Y },
        { "piz", Imf::PIZ_COMPRESSION, Imf::HALF, Imf::INCREASING_Y },
    };
    const int width = 45, height = 37, x0 = 5, y0 = -7;
    std::vector<float> rgb = make_image(width, height);
    std::vector<float> alpha((size_t)width * height, 0.5f);
    for (size_t v = 0; v < sizeof variants / sizeof variants[0]; ++v) {
        const variant &var = variants[v];
        std::string path = build_dir + "/exr_check_openexr_" + var.name + ".exr";
        /* OpenEXR's own half conversion makes infinities of big values;
           the expected values are what it stores. */
        std::vector<float> want(rgb);
        std::vector<half> halves(rgb.size());
        for (size_t i = 0; i < rgb.size(); ++i) {
            halves[i] = half(rgb[i]);
            if (var.type == Imf::HALF) want[i] = (float)halves[i];
        }
        try {
            Imf::Header header(Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(63, 63)),
                               Imath::Box2i(Imath::V2i(x0, y0), Imath::V2i(x0 + width - 1, y0 + height - 1)),
                               1, Imath::V2f(0, 0), 1, var.order, var.compression);
            const char *names[3] = { "R", "G", "B" };
            for (int c = 0; c < 3; ++c) header.channels().insert(names[c], Imf::Channel(var.type));
            header.channels().insert("A", Imf::Channel(Imf::HALF));
            header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
            Imf::OutputFile out(path.c_str(), header);
            Imf::FrameBuffer fb;
            size_t xs = 3 * (var.type == Imf::HALF ? sizeof(half) : sizeof(float));
            char *base = var.type == Imf::HALF ? (char *)halves.data() : (char *)rgb.data();
            size_t each = var.type == Imf::HALF ? sizeof(half) : sizeof(float);
            base -= (ptrdiff_t)x0 * (ptrdiff_t)xs + (ptrdiff_t)y0 * (ptrdiff_t)(xs * width);
            for (int c = 0; c < 3; ++c) fb.insert(names[c], Imf::Slice(var.type, base + c * each, xs, xs * width));
            char *abase = (char *)alpha.data() - (ptrdiff_t)x0 * 4 - (ptrdiff_t)y0 * 4 * width;
            fb.insert("Z", Imf::Slice(Imf::FLOAT, abase, 4, 4 * (size_t)width));
            out.setFrameBuffer(fb);
            out.writePixels(height);
        } catch (const std::exception &e) {
            CHECKF(0, "%s: OpenEXR could not write: %s", var.name, e.what());
            continue;
        }
        float *back = NULL;
        int w = 0, h = 0;
        rrv_exr_options info;
        rrv_error err;
        rrv_result r = rrv_read_exr(path.c_str(), &back, &w, &h, &info, &err);
        if (var.compression == Imf::PIZ_COMPRESSION) {
            CHECKF(r == RRV_ERROR_UNSUPPORTED && std::strstr(err.message, "PIZ is not supported"), "%s: %s",
                   var.name, err.message);
            continue;
        }
        CHECKF(r == RRV_OK, "%s: %s", var.name, err.message);
        if (r != RRV_OK) continue;
        CHECK(w == width && h == height && info.x == x0 && info.y == y0 && info.display_width == 64 &&
              info.display_height == 64);
        CHECK(info.pixel == (var.type == Imf::FLOAT ? RRV_EXR_FLOAT : RRV_EXR_HALF));
        int bad = 0;
        for (size_t i = 0; i < want.size(); ++i)
            if (std::isnan(want[i]) ? !std::isnan(back[i]) : !same_float_bits(want[i], back[i])) ++bad;
        CHECKF(bad == 0, "%s: %d values differ", var.name, bad);
        rrv_free(back);
    }
}

/* OpenEXR's own validator (the library behind exrcheck, with its C core
   check) finds nothing wrong in rrv's files, and does find a truncated one
   wrong, so the check can fail. It returns true when it found errors. */
static void openexr_validator_accepts_files()
{
    const char *names[] = { "half_none", "half_zip", "float_none", "float_zip", "half_zip_wide",
                            "float_zip_wide", "one_pixel", "crop_half_zip", "crop_float_none",
                            "crop_negative_origin", "random", "rgba" };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; ++i) {
        std::string path = build_dir + "/exr_check_" + names[i] + ".exr";
        CHECKF(!Imf::checkOpenEXRFile(path.c_str(), false, false, true), "%s has errors", path.c_str());
    }
    std::string path = build_dir + "/exr_check_half_zip_wide.exr";
    FILE *f = std::fopen(path.c_str(), "rb");
    std::vector<char> bytes(1 << 20);
    size_t n = f ? std::fread(bytes.data(), 1, bytes.size(), f) : 0;
    if (f) std::fclose(f);
    CHECK(n > 3000);
    CHECK(Imf::checkOpenEXRFile(bytes.data(), n / 2, false, false, true));
}

static void exrheader_accepts_files()
{
    const char *names[] = { "half_zip_wide", "crop_float_none" };
    for (int i = 0; i < 2; ++i) {
        std::string command = "exrheader " + build_dir + "/exr_check_" + names[i] + ".exr > " + build_dir +
                              "/exr_check_header.txt 2>&1";
        int status = std::system(command.c_str());
        CHECKF(status == 0, "`%s` exited with status %d (is the openexr package installed?)", command.c_str(),
               status);
    }
}

int main(int argc, char **argv)
{
    if (argc > 1) build_dir = argv[1];
    RUN(openexr_reads_every_variant);
    RUN(openexr_reads_raw_chunks_in_zip_files);
    RUN(openexr_rgba_interface_reads_halves);
    RUN(exrheader_accepts_files);
    RUN(openexr_validator_accepts_files);
    RUN(rrv_reads_openexr_files);
    return CHECK_EXIT_CODE();
}
