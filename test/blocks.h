/* Block statistics of renders, for the tests that compare two estimators
   of the same image: rendered in independent sample ranges, each 2 x 2
   block's mean and the standard error of that mean. Needs rrv.h (with its
   implementation, for rrv_render_rect) and check.h first. */
#ifndef RRV_TEST_BLOCKS_H
#define RRV_TEST_BLOCKS_H
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Block means of an image rendered in `batches` independent sample ranges:
   the mean and standard error of each block's mean radiance, R + G + B, or
   of one channel's (channel 0, 1 or 2). */
#define BW 2
#define BH 2
static void block_stats_of(rrv_scene *s, int channel, int batches, int spp, double mean[BW * BH],
                           double se[BW * BH])
{
    int w = s->camera.width, h = s->camera.height, b, i, k;
    float *img = (float *)malloc(sizeof(float) * 3 * (size_t)w * (size_t)h);
    double sum[BW * BH] = {0}, sum2[BW * BH] = {0};
    for (b = 0; b < batches; ++b) {
        double block[BW * BH] = {0};
        memset(img, 0, sizeof(float) * 3 * (size_t)w * (size_t)h);
        CHECK(rrv_render_rect(s, 0, 0, w, h, b * spp, (b + 1) * spp, img, w, NULL, NULL) == RRV_OK);
        for (i = 0; i < w * h; ++i) {
            int bx = (i % w) * BW / w, by = (i / w) * BH / h;
            block[by * BW + bx] += (channel < 0 ? img[3 * i] + img[3 * i + 1] + img[3 * i + 2] : img[3 * i + channel]) / spp;
        }
        for (k = 0; k < BW * BH; ++k) {
            sum[k] += block[k];
            sum2[k] += block[k] * block[k];
        }
    }
    for (k = 0; k < BW * BH; ++k) {
        mean[k] = sum[k] / batches;
        se[k] = sqrt(fmax(sum2[k] / batches - mean[k] * mean[k], 0.0) / (batches - 1));
    }
    free(img);
}

static void block_stats(rrv_scene *s, int batches, int spp, double mean[BW * BH], double se[BW * BH])
{
    block_stats_of(s, -1, batches, spp, mean, se);
}
#endif
