/* Compares renders with a reference image, reading both with the OpenEXR
   library (tests and benchmarks only; rrv itself never links it).

   ref_compare REF.exr IMG.exr
       prints "rmse R relmse M mse E" over all pixels and channels, where
       relmse is the mean of (img - ref)^2 / (ref^2 + 0.01) (the 0.01 keeps
       dark pixels from dominating).

   ref_compare --floor REF_VAR.exr REF_SPP
       prints "floor F": the MSE the reference's own noise adds to an
       error measured against it (its per-sample variance over REF_SPP,
       averaged over pixels and channels).

   ref_compare --merge OUT.exr OUT_VAR.exr M IMG_1.exr ... IMG_C.exr
       `make refs`: C independent renders (different seeds) of M samples per
       pixel each become the reference OUT.exr (their mean) and OUT_VAR.exr,
       the variance of one sample per pixel (M times the sample variance of
       the C values) in R, G, B and, in S, of R + G + B.

   ref_compare --check REF.exr REF_VAR.exr REF_SPP SPP IMG_1.exr ... IMG_K.exr
       the statistical consistency check run by test/test_refs.c: K
       independent renders (fixed seeds) of SPP samples per pixel against the
       reference. The image is cut into 8 x 8 pixel blocks; for each block,
       with s = R + G + B per pixel (one statistic per block, since the
       channels of a pixel are strongly correlated):
         z = (mean over the K images and the block of s
              - the same mean of the reference) / sqrt(V),
         V = sum over the block's n pixels of v / n^2 * (1/(K SPP) + 1/REF_SPP)
       where v, the variance of one sample at the pixel, is the larger of the
       K renders' own estimate (SPP times the sample variance of their K
       values) and the reference's (REF_VAR's S, from REF_SPP samples):
       renders of a few samples miss rare paths (a scatter in thin smoke, a
       path that finds a small light) and then see no variance where there
       is some. Pixels are independent (each has its own random stream), so
       an unbiased renderer gives z ~ N(0, 1), independent across blocks. The
       check fails when any |z| > 4 (a 4-sigma bound: over 100 blocks a false
       alarm has probability 0.6 %; the seeds are fixed) or when
       chi^2 = sum z^2 exceeds its mean M (the number of blocks) by more than
       4 of its standard deviations sqrt(2M). Prints the statistics and PASS
       or FAIL; exits 0 on PASS. */
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImathBox.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <algorithm>
#include <string>
#include <vector>

struct image {
    int width = 0, height = 0, x0 = 0, y0 = 0;
    std::vector<float> rgb;
};

/* Reads R, G, B, or with `channel` that one channel alone into all three. */
static bool read_exr(const char *path, image &img, const char *channel = nullptr)
{
    try {
        Imf::InputFile file(path);
        const Imf::Header &h = file.header();
        Imath::Box2i data = h.dataWindow();
        const char *names[3] = {"R", "G", "B"};
        if (channel) names[0] = names[1] = names[2] = channel;
        for (const char *c : names)
            if (!h.channels().findChannel(c)) {
                std::fprintf(stderr, "ref_compare: %s has no channel %s\n", path, c);
                return false;
            }
        img.x0 = data.min.x;
        img.y0 = data.min.y;
        img.width = data.max.x - data.min.x + 1;
        img.height = data.max.y - data.min.y + 1;
        img.rgb.assign((size_t)img.width * img.height * 3, 0.0f);
        char *base = (char *)img.rgb.data() - ((size_t)data.min.y * img.width + data.min.x) * 3 * sizeof(float);
        size_t xs = 3 * sizeof(float), ys = xs * img.width;
        Imf::FrameBuffer fb;
        if (channel) {
            fb.insert(channel, Imf::Slice(Imf::FLOAT, base, xs, ys));
        } else {
            fb.insert("R", Imf::Slice(Imf::FLOAT, base, xs, ys));
            fb.insert("G", Imf::Slice(Imf::FLOAT, base + sizeof(float), xs, ys));
            fb.insert("B", Imf::Slice(Imf::FLOAT, base + 2 * sizeof(float), xs, ys));
        }
        file.setFrameBuffer(fb);
        file.readPixels(data.min.y, data.max.y);
        if (channel)
            for (size_t i = 0; i < img.rgb.size(); i += 3) img.rgb[i + 1] = img.rgb[i + 2] = img.rgb[i];
    } catch (const std::exception &e) {
        std::fprintf(stderr, "ref_compare: %s: %s\n", path, e.what());
        return false;
    }
    return true;
}

static bool same_window(const image &a, const image &b, const char *path)
{
    if (a.width == b.width && a.height == b.height && a.x0 == b.x0 && a.y0 == b.y0) return true;
    std::fprintf(stderr, "ref_compare: %s is %dx%d at (%d,%d), the reference %dx%d at (%d,%d)\n", path,
                 b.width, b.height, b.x0, b.y0, a.width, a.height, a.x0, a.y0);
    return false;
}

static int compare(const char *ref_path, const char *img_path)
{
    image ref, img;
    if (!read_exr(ref_path, ref) || !read_exr(img_path, img) || !same_window(ref, img, img_path)) return 2;
    double se = 0, rel = 0;
    size_t n = ref.rgb.size();
    for (size_t i = 0; i < n; ++i) {
        double d = (double)img.rgb[i] - ref.rgb[i];
        se += d * d;
        rel += d * d / ((double)ref.rgb[i] * ref.rgb[i] + 0.01);
    }
    std::printf("rmse %.6e relmse %.6e mse %.6e\n", std::sqrt(se / n), rel / n, se / n);
    return std::isfinite(se) ? 0 : 1;
}

/* Writes R, G, B (and S when given) as FLOAT with ZIP compression. */
static bool write_exr(const char *path, int width, int height, const std::vector<float> &rgb,
                      const std::vector<float> *sum)
{
    try {
        Imf::Header h(width, height);
        h.compression() = Imf::ZIP_COMPRESSION;
        const char *names[4] = {"R", "G", "B", "S"};
        int channels = sum ? 4 : 3;
        for (int c = 0; c < channels; ++c) h.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
        Imf::OutputFile file(path, h);
        Imf::FrameBuffer fb;
        size_t xs = 3 * sizeof(float), ys = xs * width;
        for (int c = 0; c < 3; ++c)
            fb.insert(names[c], Imf::Slice(Imf::FLOAT, (char *)(rgb.data() + c), xs, ys));
        if (sum) fb.insert("S", Imf::Slice(Imf::FLOAT, (char *)sum->data(), sizeof(float), sizeof(float) * width));
        file.setFrameBuffer(fb);
        file.writePixels(height);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "ref_compare: %s: %s\n", path, e.what());
        return false;
    }
    return true;
}

/* C renders of M samples each, independent seeds: their mean is the
   reference, and M times the sample variance of the C values of a pixel
   estimates the variance of one sample there (R, G, B, and S of R+G+B). */
static int merge(const char *mean_path, const char *var_path, double m, int c, char **paths)
{
    std::vector<image> imgs((size_t)c);
    for (int i = 0; i < c; ++i)
        if (!read_exr(paths[i], imgs[(size_t)i]) || !same_window(imgs[0], imgs[(size_t)i], paths[i])) return 2;
    size_t pixels = (size_t)imgs[0].width * imgs[0].height;
    std::vector<float> mean(pixels * 3), var(pixels * 3), sum(pixels);
    for (size_t p = 0; p < pixels; ++p) {
        double vs = 0;
        for (int ch = 0; ch <= 3; ++ch) {
            double mu = 0, v = 0;
            for (int i = 0; i < c; ++i) {
                const float *q = &imgs[(size_t)i].rgb[3 * p];
                mu += ch < 3 ? q[ch] : (double)q[0] + q[1] + q[2];
            }
            mu /= c;
            for (int i = 0; i < c; ++i) {
                const float *q = &imgs[(size_t)i].rgb[3 * p];
                double d = (ch < 3 ? q[ch] : (double)q[0] + q[1] + q[2]) - mu;
                v += d * d;
            }
            v = m * v / (c - 1);
            if (ch < 3) {
                mean[3 * p + ch] = (float)mu;
                var[3 * p + ch] = (float)v;
            } else {
                vs = v;
            }
        }
        sum[p] = (float)vs;
    }
    return write_exr(mean_path, imgs[0].width, imgs[0].height, mean, nullptr) &&
                   write_exr(var_path, imgs[0].width, imgs[0].height, var, &sum)
               ? 0
               : 2;
}

static int check(const char *ref_path, const char *var_path, double ref_spp, double spp, int k, char **paths)
{
    image ref, refvar;
    std::vector<image> imgs((size_t)k);
    if (!read_exr(ref_path, ref) || !read_exr(var_path, refvar, "S") || !same_window(ref, refvar, var_path))
        return 2;
    for (int i = 0; i < k; ++i)
        if (!read_exr(paths[i], imgs[(size_t)i]) || !same_window(ref, imgs[(size_t)i], paths[i])) return 2;
    const int B = 8, w = ref.width, h = ref.height;
    int blocks = 0, worst_x = 0, worst_y = 0, own_larger = 0;
    double chi2 = 0, worst = 0, worst_mean = 0, worst_ref = 0, sum_mean = 0, sum_ref = 0;
    bool finite = true;
    std::vector<double> resolution;
    double power = 0;
    for (int by = 0; by < h; by += B)
        for (int bx = 0; bx < w; bx += B) {
            double mean = 0, refmean = 0, var = 0;
            int n = 0;
            for (int y = by; y < by + B && y < h; ++y)
                for (int x = bx; x < bx + B && x < w; ++x) {
                    size_t p = 3 * ((size_t)y * w + x);
                    double s[64], m = 0, v = 0;
                    for (int i = 0; i < k; ++i) {
                        const float *q = &imgs[(size_t)i].rgb[p];
                        s[i] = (double)q[0] + q[1] + q[2];
                        m += s[i];
                    }
                    m /= k;
                    for (int i = 0; i < k; ++i) v += (s[i] - m) * (s[i] - m);
                    /* One sample's variance: the larger of the two estimates
                       (the renders' own spread misses rare paths that the
                       reference's many more samples have seen). */
                    double own = k > 1 ? spp * v / (k - 1) : 0.0, from_ref = refvar.rgb[p];
                    if (own > from_ref) ++own_larger;
                    mean += m;
                    var += own > from_ref ? own : from_ref;
                    refmean += (double)ref.rgb[p] + ref.rgb[p + 1] + ref.rgb[p + 2];
                    ++n;
                }
            mean /= n;
            refmean /= n;
            var = var / ((double)n * n) * (1.0 / (k * spp) + 1.0 / ref_spp);
            /* Blocks without noise (only sky) still differ by the rounding
               of sums made in different orders. */
            double floor = 1e-6 * std::fabs(refmean) + 1e-12;
            var += floor * floor;
            double z = (mean - refmean) / std::sqrt(var);
            if (!std::isfinite(z)) finite = false;
            if (refmean > 0) resolution.push_back(4.0 * std::sqrt(var) / refmean);
            power += refmean * refmean / var;
            chi2 += z * z;
            sum_mean += mean * n;
            sum_ref += refmean * n;
            if (std::fabs(z) > std::fabs(worst) || !std::isfinite(z)) {
                worst = z;
                worst_x = bx;
                worst_y = by;
                worst_mean = mean;
                worst_ref = refmean;
            }
            ++blocks;
        }
    double limit = blocks + 4.0 * std::sqrt(2.0 * blocks);
    /* The power of the check: a bias of this fraction of a block's mean
       fails it in the median block. */
    double detectable = 0;
    if (!resolution.empty()) {
        std::nth_element(resolution.begin(), resolution.begin() + resolution.size() / 2, resolution.end());
        detectable = resolution[resolution.size() / 2];
    }
    /* A bias of the same fraction d of every block's mean adds d^2 power
       to chi^2: this d reaches the chi^2 limit. */
    double uniform = power > 0 ? std::sqrt((limit - blocks) / power) : 0;
    bool pass = finite && std::fabs(worst) <= 4.0 && chi2 <= limit;
    std::printf("%d x %g spp against %g spp, %d blocks of 8x8: chi2 %.1f (limit %.1f), max |z| %.2f at (%d,%d) "
                "(%.5g against %.5g), mean ratio %.5f, own variance larger in %.0f%% of pixels; "
                "a bias of %.1f%% fails the median block, %.2f%% in every block fails chi2: %s\n",
                k, spp, ref_spp, blocks, chi2, limit, std::fabs(worst), worst_x, worst_y, worst_mean, worst_ref,
                sum_ref != 0 ? sum_mean / sum_ref : 1.0, 100.0 * own_larger / ((double)w * h),
                100.0 * detectable, 100.0 * uniform, pass ? "PASS" : "FAIL");
    return pass ? 0 : 1;
}

int main(int argc, char **argv)
{
    std::string mode = argc > 1 ? argv[1] : "";
    if (argc == 3 && mode[0] != '-') return compare(argv[1], argv[2]);
    if (argc >= 7 && mode == "--check") {
        int k = argc - 6;
        double ref_spp = std::atof(argv[4]), spp = std::atof(argv[5]);
        if (k <= 64 && ref_spp > 0 && spp > 0) return check(argv[2], argv[3], ref_spp, spp, k, argv + 6);
    }
    if (argc == 4 && mode == "--floor") {
        image var;
        double spp = std::atof(argv[3]), sum = 0;
        if (!read_exr(argv[2], var) || !(spp > 0)) return 2;
        for (float v : var.rgb) sum += v;
        std::printf("floor %.6e\n", sum / var.rgb.size() / spp);
        return 0;
    }
    if (argc >= 7 && mode == "--merge") {
        double m = std::atof(argv[4]);
        if (m > 0) return merge(argv[2], argv[3], m, argc - 5, argv + 5);
    }
    std::fprintf(stderr,
                 "usage: ref_compare REF.exr IMG.exr\n"
                 "       ref_compare --check REF.exr REF_VAR.exr REF_SPP SPP IMG_1.exr ... IMG_K.exr  (K <= 64)\n"
                 "       ref_compare --floor REF_VAR.exr REF_SPP\n"
                 "       ref_compare --merge OUT.exr OUT_VAR.exr SPP_EACH IMG_1.exr ... IMG_C.exr  (C >= 2)\n");
    return 2;
}
