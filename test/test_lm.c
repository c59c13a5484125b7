/* The pieces of nee manifold's solver that can be checked on their own:
   - the Levenberg-Marquardt normal equations of a chain (J^T J + lambda S,
     block pentadiagonal) and their block LDL^T solve in O(n), against a
     dense elimination of the same system built from a dense J, on random
     well-conditioned chains of 1 to 60 vertices (1e-10 relative);
   - the inverse-probability estimate 1/p by Bernoulli trials with a
     Russian-roulette tail, on a two-root toy problem whose basins have
     known probabilities (Newton on x^2 = 1 from a uniform seed): its mean
     for the rare root (p = 1/200, well past the 64 trials the roulette
     starts at) and the whole estimator's mean (the number of roots, 2)
     within 4 standard errors, fixed seed; and its expected work bounded;
   - a chain of 256 vertices solved on a thread whose whole stack is
     64 KB: the solver's arrays are the render context's heap chain, not
     on the caller's stack.
   LM_VERBOSE=1 prints the values. */
#define _POSIX_C_SOURCE 200112L
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "say.h"
#include "scene_builder.h"
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

/* ---- the block-pentadiagonal solve ------------------------------------------------ */

/* Dense Gaussian elimination with partial pivoting: M x = b, M m x m
   row-major (overwritten), b overwritten by x. */
static void dense_solve(int m, double *M, double *b)
{
    int i, j, k;
    for (k = 0; k < m; ++k) {
        int p = k;
        for (i = k + 1; i < m; ++i)
            if (fabs(M[i * m + k]) > fabs(M[p * m + k])) p = i;
        if (p != k) {
            for (j = 0; j < m; ++j) {
                double t = M[k * m + j];
                M[k * m + j] = M[p * m + j];
                M[p * m + j] = t;
            }
            { double t = b[k]; b[k] = b[p]; b[p] = t; }
        }
        for (i = k + 1; i < m; ++i) {
            double f = M[i * m + k] / M[k * m + k];
            for (j = k; j < m; ++j) M[i * m + j] -= f * M[k * m + j];
            b[i] -= f * b[k];
        }
    }
    for (k = m - 1; k >= 0; --k) {
        double s = b[k];
        for (j = k + 1; j < m; ++j) s -= M[k * m + j] * b[j];
        b[k] = s / M[k * m + k];
    }
}

/* Random chain blocks: B near 2 I, A and C small, so J is diagonally
   dominant and J^T J well conditioned. */
static void random_chain(rrv__chain *ch, int n, rrv__rng *rng)
{
    int k, j;
    ch->n = n;
    for (k = 1; k <= n; ++k) {
        for (j = 0; j < 4; ++j) {
            ch->A[k][j] = 0.6 * (rrv__uniform(rng) - 0.5);
            ch->B[k][j] = (j == 0 || j == 3 ? 2.0 : 0.0) + 0.6 * (rrv__uniform(rng) - 0.5);
            ch->C[k][j] = 0.6 * (rrv__uniform(rng) - 0.5);
        }
        ch->r[k][0] = rrv__uniform(rng) - 0.5;
        ch->r[k][1] = rrv__uniform(rng) - 0.5;
        ch->scl[k][0] = 0.5 + rrv__uniform(rng);
        ch->scl[k][1] = 0.5 + rrv__uniform(rng);
    }
}

static void test_band_solve_against_dense(void)
{
    static const int sizes[] = {1, 2, 3, 4, 7, 20, 60};
    rrv__chain *ch = rrv__chain_new(64);
    rrv__rng rng;
    double worst = 0, worst_grad = 0;
    int t, rep;
    rrv__rng_seed(&rng, 7, 0, 0);
    for (t = 0; t < (int)(sizeof sizes / sizeof *sizes); ++t)
        for (rep = 0; rep < 5; ++rep) {
            int n = sizes[t], m = 2 * n, k, i, j;
            double lambda = rep == 0 ? 0.0 : pow(10.0, -6.0 + 2.0 * rep), *J, *M, *b, num = 0, den = 0, g2 = 0, gd = 0;
            J = (double *)calloc((size_t)(m * m), sizeof *J);
            M = (double *)calloc((size_t)(m * m), sizeof *M);
            b = (double *)calloc((size_t)m, sizeof *b);
            random_chain(ch, n, &rng);
            /* dense J: row pair k-1 (vertex k), column pair of vertex k-1, k, k+1 */
            for (k = 1; k <= n; ++k)
                for (i = 0; i < 2; ++i)
                    for (j = 0; j < 2; ++j) {
                        int row = 2 * (k - 1) + i;
                        if (k > 1) J[row * m + 2 * (k - 2) + j] = ch->A[k][2 * i + j];
                        J[row * m + 2 * (k - 1) + j] = ch->B[k][2 * i + j];
                        if (k < n) J[row * m + 2 * k + j] = ch->C[k][2 * i + j];
                    }
            for (i = 0; i < m; ++i) {
                for (j = 0; j < m; ++j) {
                    double s = 0;
                    int q;
                    for (q = 0; q < m; ++q) s += J[q * m + i] * J[q * m + j];
                    M[i * m + j] = s + (i == j ? lambda * ch->scl[i / 2 + 1][i % 2] : 0.0);
                }
                for (j = 0, b[i] = 0; j < m; ++j) b[i] -= J[j * m + i] * ch->r[j / 2 + 1][j % 2];
            }
            rrv__chain_normal(ch);
            for (k = 1; k <= n; ++k)
                for (i = 0; i < 2; ++i) {
                    gd += (ch->grad[k][i] + b[2 * (k - 1) + i]) * (ch->grad[k][i] + b[2 * (k - 1) + i]);
                    g2 += b[2 * (k - 1) + i] * b[2 * (k - 1) + i];
                    ch->step[k][i] = -ch->grad[k][i];
                }
            CHECKF(rrv__band_factor(n, ch->nd, ch->n1, ch->n2, ch->scl, lambda, ch->l1, ch->l2, ch->dinv),
                   "n %d lambda %g: factor refused an SPD system", n, lambda);
            rrv__band_solve(n, ch->l1, ch->l2, ch->dinv, ch->step);
            dense_solve(m, M, b);
            for (k = 1; k <= n; ++k)
                for (i = 0; i < 2; ++i) {
                    double d = ch->step[k][i] - b[2 * (k - 1) + i];
                    num += d * d;
                    den += b[2 * (k - 1) + i] * b[2 * (k - 1) + i];
                }
            worst = fmax(worst, sqrt(num / den));
            worst_grad = fmax(worst_grad, sqrt(gd / g2));
            free(J);
            free(M);
            free(b);
        }
    SAY("  band LDL^T against dense: worst relative difference %.1e (step), %.1e (J^T r)\n", worst, worst_grad);
    CHECKF(worst < 1e-10, "block-pentadiagonal solve off the dense one by %.2e relative", worst);
    CHECKF(worst_grad < 1e-12, "J^T r off the dense one by %.2e relative", worst_grad);
    /* a singular system is refused, not divided by */
    random_chain(ch, 3, &rng);
    memset(ch->A, 0, 5 * sizeof *ch->A);
    memset(ch->B, 0, 5 * sizeof *ch->B);
    memset(ch->C, 0, 5 * sizeof *ch->C);
    rrv__chain_normal(ch);
    CHECK(!rrv__band_factor(3, ch->nd, ch->n1, ch->n2, ch->scl, 0.0, ch->l1, ch->l2, ch->dinv));
    rrv__chain_delete(ch);
}

/* ---- the 1/p estimate --------------------------------------------------------------- */

/* Newton on x^2 = 1 from x uniform on (lo, hi): x > 0 goes to +1, x < 0
   to -1, so the root +1 has probability hi / (hi - lo) when lo < 0 < hi. */
typedef struct toy {
    double lo, hi;
    double want;  /* the root a trial must come back to */
    long solves;
} toy;

static double toy_solve(toy *t, rrv__rng *rng)
{
    double x = t->lo + (t->hi - t->lo) * rrv__uniform(rng);
    int it;
    ++t->solves;
    for (it = 0; it < 200 && fabs(x * x - 1.0) > 1e-12; ++it) x -= (x * x - 1.0) / (2.0 * x);
    return x;
}

static int toy_recurs(void *user, rrv__rng *rng)
{
    toy *t = (toy *)user;
    return fabs(toy_solve(t, rng) - t->want) < 1e-6;
}

static void test_inverse_probability_two_roots(void)
{
    /* p(+1) = 1/200, p(-1) = 199/200 */
    toy t = {-0.995, 0.005, 1.0, 0};
    const double p = 0.005;
    rrv__rng rng;
    long i, trials, work = 0, most = 0;
    const long runs = 100000, samples = 2000000;
    double sum = 0, sum2 = 0, mean, se;
    rrv__rng_seed(&rng, 2024, 1, 0);
    /* conditioned on the rare root: E = 1/p = 200 */
    for (i = 0; i < runs; ++i) {
        double e = rrv__inverse_probability(&rng, RRV__SOLVE_TRIALS, toy_recurs, &t, &trials);
        sum += e;
        sum2 += e * e;
        work += trials;
        if (trials > most) most = trials;
    }
    mean = sum / runs;
    se = sqrt((sum2 / runs - mean * mean) / (runs - 1));
    SAY("  1/p for p = 1/200: mean %.2f +- %.2f (want %.0f), %.1f trials a run, most %ld\n", mean, se, 1.0 / p,
        (double)work / runs, most);
    CHECKF(fabs(mean - 1.0 / p) < 4.0 * se, "1/p for p = 1/200: %.3f +- %.3f, expected %.0f", mean, se, 1.0 / p);
    /* the expected work: at most 2 x 64 + 1 trials whatever p (4 se above) */
    CHECKF((double)work / runs < 2.0 * RRV__SOLVE_TRIALS + 1, "%.1f trials a run", (double)work / runs);

    /* the whole estimator: one solve finds a root, 1/p of that root
       estimated; summed over roots its mean is the number of roots */
    sum = sum2 = 0;
    for (i = 0; i < samples; ++i) {
        double e;
        t.want = toy_solve(&t, &rng) > 0 ? 1.0 : -1.0;
        e = rrv__inverse_probability(&rng, RRV__SOLVE_TRIALS, toy_recurs, &t, &trials);
        sum += e;
        sum2 += e * e;
    }
    mean = sum / samples;
    se = sqrt((sum2 / samples - mean * mean) / (samples - 1));
    SAY("  roots counted: mean %.4f +- %.4f (want 2)\n", mean, se);
    CHECKF(fabs(mean - 2.0) < 4.0 * se, "two roots counted as %.4f +- %.4f", mean, se);
}

/* ---- a long chain on a small stack ------------------------------------------------ */

typedef struct long_chain {
    rrv_scene *scene;
    int found, vertices;
    double w0_error;
} long_chain;

/* The Luneburg lens (IOR 2 - r^2 in the unit sphere) of step h. */
static rrv_scene *lens(double h)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_medium *m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.0, 0.0);
    rrv_error err;
    m->density.kind = RRV_FIELD_NONE;
    m->ior.kind = RRV_FIELD_LUNEBURG;
    m->ior.center = rrv__v3(0, 0, 0);
    m->ior.radius = 1;
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.step = h;
    if (rrv_scene_prepare(s, &err) != RRV_OK) {
        printf("  prepare: %s\n", err.message);
        rrv_scene_free(s);
        return NULL;
    }
    return s;
}

static void *solve_long_chain(void *user)
{
    long_chain *lc = (long_chain *)user;
    rrv__chain *ch = rrv__chain_new(RRV__CHAIN_MAX);
    const rrv_vec3 x0 = rrv__v3(0.5, 0.0, 0.0), y = rrv__v3(-0.5, 0.1, 0.0);
    rrv__rng rng;
    rrv__mroot root;
    int k;
    if (!ch) return NULL;
    rrv__rng_seed(&rng, 5, 0, 0);
    rrv__chain_setup(lc->scene, x0, y, rrv__normalize(rrv__sub(y, x0)), 0, 0.0, 0.5, ch);
    lc->vertices = ch->n;
    for (k = 0; k < 8 && !lc->found; ++k) {
        rrv_vec3 w = k == 0 ? ch->c : rrv__chain_seed_direction(ch, &rng);
        int aimed;
        if (!rrv__chain_aim(lc->scene, ch, w, &aimed)) rrv__chain_seed(lc->scene, ch, w);
        lc->found = rrv__manifold_solve(lc->scene, ch, &root);
    }
    if (lc->found) {
        /* the root bends: its first direction is not the chord's */
        lc->w0_error = rrv__length(rrv__sub(root.w0, rrv__normalize(rrv__sub(y, x0))));
    }
    rrv__chain_delete(ch);
    return NULL;
}

static void test_long_chain_small_stack(void)
{
    long_chain lc = {NULL, 0, 0, 0};
    pthread_attr_t attr;
    pthread_t thread;
    const size_t stack = 64 * 1024;
    /* ~1 m of chord inside the lens at h = 0.0039: 257 comb planes */
    if (!(lc.scene = lens(0.0039))) {
        CHECK(0);
        return;
    }
    CHECK(pthread_attr_init(&attr) == 0);
    CHECK(pthread_attr_setstacksize(&attr, stack) == 0);
    CHECK(pthread_create(&thread, &attr, solve_long_chain, &lc) == 0);
    CHECK(pthread_join(thread, NULL) == 0);
    pthread_attr_destroy(&attr);
    SAY("  %d vertices on a %zu KB stack: found %d, w0 %.3f rad off the chord\n", lc.vertices, stack / 1024, lc.found,
        lc.w0_error);
    CHECKF(lc.vertices >= 256, "%d vertices", lc.vertices);
    CHECK(lc.found && lc.w0_error > 1e-3);
    rrv_scene_free(lc.scene);
}

int main(void)
{
    say_from_env("LM_VERBOSE");
    (void)tb_shape;
    (void)tb_blobs;
    RUN(test_band_solve_against_dense);
    RUN(test_inverse_probability_two_roots);
    RUN(test_long_chain_small_stack);
    return CHECK_EXIT_CODE();
}
