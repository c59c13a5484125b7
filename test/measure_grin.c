/* Convergence, cost and precision of the refraction schemes on GRIN media
   with closed-form answers. Not a test (make test does not run it): build with
     cc -std=c99 -O2 -I/work/main -o build/measure_grin test/measure_grin.c -lm
   and run it; it prints markdown tables.

   Sections:
     1. Luneburg lens (b = 0.5): error of POISSON / MIDPOINT / COMB versus the
        refraction event rate, and of LEAPFROG / RK4 versus the step, with
        log-log slopes, field evaluations and wall time per ray.
     2. The same sweeps on the linear slab and on a Gaussian blob.
     3. Float versus double ray state, delta versus naive Snell form.
     4. Gradient stencils on a grid.
     5. IOR grids (also alone: `build/measure_grin grids`): orders of the comb,
        leapfrog and RK4 against the ray through the same grid, trilinear
        against cubic interpolation, how far each grid's ray is from the
        analytic field's, and the cost of both. */
#define RRV_RESEARCH /* the midpoint scheme and the leapfrog stepper, which the tables measure too */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "scene_builder.h"
#include <time.h>

/* ---- the analytic cases -------------------------------------------------------- */

enum { CASE_LUNEBURG, CASE_SLAB, CASE_BLOB };

/* Slab: eta - 1 = 0.2 - 0.4 y in y in [-0.5, 0.5], so eta falls to the
   ambient 1 at the top face (no jump where the ray leaves) and the ray starts
   inside (no jump where it enters). */
#define SLAB_BASE 0.2
#define SLAB_G (-0.4)
#define SLAB_Y0 (-0.45)
#define SLAB_TOP 0.5
/* Blob: strong enough that the schemes' errors rise above the Born error,
   compared with an RK4 reference at a tiny step. */
#define BLOB_A 1e-2
#define BLOB_S 0.1
#define BLOB_B 0.1

static rrv_scene *make_case(int which)
{
    rrv_scene *s = tb_scene(4, 4);
    rrv_medium *m;
    rrv_error err;
    if (which == CASE_LUNEBURG) {
        m = tb_medium(s, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0, 0);
        m->density.kind = RRV_FIELD_NONE;
        m->ior.kind = RRV_FIELD_LUNEBURG;
        m->ior.center = rrv__v3(0, 0, 0);
        m->ior.radius = 1;
    } else if (which == CASE_SLAB) {
        m = tb_medium(s, rrv__v3(-2, -0.5, -1), rrv__v3(2, SLAB_TOP, 1), 0, 0);
        m->density.kind = RRV_FIELD_NONE;
        m->ior.kind = RRV_FIELD_SLAB;
        m->ior.center = rrv__v3(0, 0, 0);
        m->ior.normal = rrv__v3(0, 1, 0);
        m->ior.gradient = SLAB_G;
        m->ior.base = SLAB_BASE;
    } else {
        rrv_blob *b;
        m = tb_medium(s, rrv__v3(-0.6, -0.6, -0.6), rrv__v3(0.6, 0.6, 0.6), 0, 0);
        m->density.kind = RRV_FIELD_NONE;
        b = tb_blobs(&m->ior, 1);
        b->center = rrv__v3(0, 0, 0);
        b->radius = BLOB_S;
        b->weight = BLOB_A;
    }
    if (rrv_scene_prepare(s, &err) != RRV_OK) {
        fprintf(stderr, "prepare: %s\n", err.message);
        exit(1);
    }
    return s;
}

/* Slab closed form. With eta(y) linear, eta d_h (the horizontal part of the
   direction) is conserved: K = eta0 cos(theta0). Parametrising by sigma with
   ds = eta dsigma, eta = K cosh(psi), eta dy/ds = K sinh(psi), psi = psi0 +
   G sigma, x = x0 + K sigma: the ray is a catenary. At the face y = top:
   eta_t = K cosh(psi_t), psi_t = acosh(eta_t / K) (still rising), so
   x_t = x0 + K (psi_t - psi0) / G and the direction is (K/eta_t, sqrt(1 -
   (K/eta_t)^2)) in the (horizontal, y) plane. */
static double slab_eta(double y) { return 1.0 + SLAB_BASE + SLAB_G * y; }
static void slab_exact(double theta0, double *dx_exit, double *dir_h, double *dir_y)
{
    double eta0 = slab_eta(SLAB_Y0), K = eta0 * cos(theta0), eta_t = slab_eta(SLAB_TOP);
    double psi0 = asinh(tan(theta0)), psit = acosh(eta_t / K);
    *dx_exit = K * (psit - psi0) / SLAB_G;
    *dir_h = K / eta_t;
    *dir_y = sqrt(1.0 - *dir_h * *dir_h);
}

/* Error of one traced ray for a case: Luneburg, distance of the exit ray
   (as a line) from the focus (0,0,1); slab, |x where the exit ray crosses
   y = top - exact|; blob, |deflection - reference| (direction x component). */
static double case_error(int which, const rrv_trace_result *r, double ref)
{
    if (which == CASE_LUNEBURG) {
        rrv_vec3 f = rrv__sub(rrv__v3(0, 0, 1), r->position);
        return rrv__length(rrv__cross(f, r->direction));
    } else if (which == CASE_SLAB) {
        double t = (SLAB_TOP - r->position.y) / r->direction.y;
        return fabs(r->position.x + t * r->direction.x - ref);
    }
    return fabs(r->direction.x - ref);
}

static rrv_result case_trace(const rrv_scene *s, int which, rrv_integrator integ, uint64_t walk,
                             rrv_trace_result *res)
{
    rrv_error err;
    rrv_vec3 o, d;
    if (which == CASE_LUNEBURG) {
        o = rrv__v3(0.5, 0, -2);
        d = rrv__v3(0, 0, 1);
    } else if (which == CASE_SLAB) {
        double th = 60.0 * RRV__PI / 180.0;
        o = rrv__v3(-1, SLAB_Y0, 0);
        d = rrv__v3(cos(th), sin(th), 0);
    } else {
        o = rrv__v3(BLOB_B, 0, -0.7);
        d = rrv__v3(0, 0, 1);
    }
    return rrv_trace_ray(s, integ, o, d, 42, walk, NULL, NULL, res, &err);
}

static double case_reference(int which)
{
    if (which == CASE_SLAB) {
        double dx, dh, dy;
        slab_exact(60.0 * RRV__PI / 180.0, &dx, &dh, &dy);
        return -1 + dx;
    } else if (which == CASE_BLOB) {
        /* RK4 at h = 1e-4 converges to ~1e-15 here (fourth order): the
           reference, since the Born integral is itself off by O(A). */
        rrv_scene *s = make_case(CASE_BLOB);
        rrv_trace_result r;
        double ref;
        s->settings.stepper = RRV_STEPPER_RK4;
        s->settings.step = 1e-4;
        case_trace(s, CASE_BLOB, RRV_INTEGRATOR_EIKONAL, 0, &r);
        ref = r.direction.x;
        rrv_scene_free(s);
        return ref;
    }
    return 0;
}

/* ---- sweeps ------------------------------------------------------------------------ */

typedef struct method {
    const char *name;
    rrv_integrator integ;
    rrv_refraction_scheme scheme;
    rrv_stepper stepper;
    double evals_per_event; /* calls of rrv__scene_refractivity per event/step, read from the code */
    double grads_per_event; /* of which with a gradient */
} method;

static const method METHODS[] = {
    {"POISSON", RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_POISSON, RRV_STEPPER_DEFAULT, 1, 1},
    {"MIDPOINT", RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_MIDPOINT, RRV_STEPPER_DEFAULT, 2, 2},
    {"COMB", RRV_INTEGRATOR_REFRACTIVE, RRV_REFRACTION_COMB, RRV_STEPPER_DEFAULT, 1, 1},
    {"LEAPFROG", RRV_INTEGRATOR_EIKONAL, RRV_REFRACTION_DEFAULT, RRV_STEPPER_LEAPFROG, 2, 2},
    {"RK4", RRV_INTEGRATOR_EIKONAL, RRV_REFRACTION_DEFAULT, RRV_STEPPER_RK4, 4, 4},
};

typedef struct sweep_row {
    double param, err, se, median, events, evals, grads, usec;
} sweep_row;

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Runs `walks` rays (1 for the deterministic eikonal) at one rate or step. */
static sweep_row run_one(int which, const method *me, double param, int walks, double ref)
{
    rrv_scene *s = make_case(which);
    sweep_row row;
    double sum = 0, sum2 = 0, ev = 0;
    clock_t t0;
    int i, reps;
    double *errs;
    memset(&row, 0, sizeof row);
    s->settings.integrator = me->integ;
    s->settings.refraction = me->scheme;
    s->settings.stepper = me->stepper;
    if (me->integ == RRV_INTEGRATOR_EIKONAL) {
        s->settings.step = param;
        walks = 1;
    } else {
        s->settings.mu_eta = param;
    }
    errs = (double *)malloc((size_t)walks * sizeof(double));
    for (i = 0; i < walks; ++i) {
        rrv_trace_result r;
        double e;
        if (case_trace(s, which, me->integ, (uint64_t)i, &r) != RRV_OK) {
            fprintf(stderr, "trace failed\n");
            exit(1);
        }
        e = case_error(which, &r, ref);
        errs[i] = e;
        sum += e;
        sum2 += e * e;
        ev += (double)r.events;
    }
    /* Time: repeat until at least 0.05 s has passed, for a stable clock(). */
    reps = 0;
    t0 = clock();
    do {
        for (i = 0; i < walks; ++i) {
            rrv_trace_result r;
            case_trace(s, which, me->integ, (uint64_t)i, &r);
        }
        ++reps;
    } while (clock() - t0 < CLOCKS_PER_SEC / 20);
    row.usec = 1e6 * (double)(clock() - t0) / CLOCKS_PER_SEC / ((double)reps * walks);
    row.param = param;
    row.err = sum / walks;
    qsort(errs, (size_t)walks, sizeof(double), cmp_double);
    row.median = errs[walks / 2];
    free(errs);
    row.se = walks > 1 ? sqrt(fmax(0.0, sum2 / walks - row.err * row.err) / (walks - 1)) : 0;
    row.events = ev / walks;
    /* +1: the comb's opening half kick is not counted as an event. */
    row.evals = (row.events + (me->scheme == RRV_REFRACTION_COMB && me->integ != RRV_INTEGRATOR_EIKONAL)) *
                me->evals_per_event;
    row.grads = (row.events + (me->scheme == RRV_REFRACTION_COMB && me->integ != RRV_INTEGRATOR_EIKONAL)) *
                me->grads_per_event;
    rrv_scene_free(s);
    return row;
}

static const double RATES[] = {30, 100, 300, 1000, 3000};
static const double STEPS[] = {0.2, 0.1, 0.05, 0.02, 0.01, 0.005};

static void sweep(int which, const char *title, const int *method_ids, int nmethods, int walks)
{
    double ref = case_reference(which);
    int k, i;
    printf("\n### %s\n\n", title);
    printf("| method | events/m or h | mean error | std. error | slope (order) | median error | median slope | "
           "events/ray | field evals/ray | of which gradients | us/ray |\n");
    printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (k = 0; k < nmethods; ++k) {
        const method *me = &METHODS[method_ids[k]];
        int eik = me->integ == RRV_INTEGRATOR_EIKONAL;
        int n = eik ? (int)(sizeof STEPS / sizeof STEPS[0]) : (int)(sizeof RATES / sizeof RATES[0]);
        sweep_row prev;
        for (i = 0; i < n; ++i) {
            sweep_row row = run_one(which, me, eik ? STEPS[i] : RATES[i], walks, ref);
            char slope[32] = "", mslope[32] = "";
            if (i > 0 && row.err > 0 && prev.err > 0) {
                /* order p in err ~ h^p = mu^-p */
                double p = log(row.err / prev.err) / log(row.param / prev.param);
                sprintf(slope, "%.2f", eik ? p : -p);
            }
            if (i > 0 && row.median > 0 && prev.median > 0 && !eik) {
                double p = log(row.median / prev.median) / log(row.param / prev.param);
                sprintf(mslope, "%.2f", -p);
            }
            printf("| %s | %g | %.3e | %.1e | %s | %.3e | %s | %.0f | %.0f | %.0f | %.1f |\n", me->name, row.param,
                   row.err, row.se, slope, row.median, mslope, row.events, row.evals, row.grads, row.usec);
            prev = row;
        }
    }
}

/* ---- precision: float versus double ray state ------------------------------------- */

/* The same comb-like kick-drift loop in three precisions. The field is air at
   r0 = 3e-4 with a hot blob of -2e-4 (sigma 0.3 m): the kicks between
   neighbouring points change r by ~1e-9, far below float's 6e-8 half-ulp of
   1.0, where float refractivity would lose the deflection. */
#define PREC_R0 3e-4
#define PREC_A (-2e-4)
#define PREC_S 0.3
#define PREC_KICKS 100000
#define PREC_LEN 2.0

#define DEFINE_PREC(T, SUF, EXP, SQRT)                                                                 \
    static T field_##SUF(const T x[3], T g[3])                                                          \
    {                                                                                                   \
        T q = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) / (T)(PREC_S * PREC_S);                         \
        T e = (T)PREC_A * EXP((T)-0.5 * q);                                                             \
        int a;                                                                                          \
        for (a = 0; a < 3; ++a) g[a] = -e * x[a] / (T)(PREC_S * PREC_S);                                \
        return (T)PREC_R0 + e;                                                                          \
    }                                                                                                   \
    /* naive = 1: d' = m d + (m c - sqrt(k)) n with m = (1 + r_in)/(1 + r_out) formed in T. */         \
    static void refract_##SUF(T d[3], T r_in, T r_out, const T g[3], int naive)                         \
    {                                                                                                   \
        T len = SQRT(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]), n[3], c, s2, k, delta, e, m, f, nl;      \
        int a;                                                                                          \
        if (!(len > 0)) return;                                                                         \
        for (a = 0; a < 3; ++a) n[a] = g[a] / len;                                                      \
        c = -(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);                                                 \
        if (c < 0) { for (a = 0; a < 3; ++a) n[a] = -n[a]; c = -c; }                                   \
        s2 = (T)1 - c * c;                                                                              \
        if (s2 < 0) s2 = 0;                                                                             \
        if (naive) {                                                                                    \
            m = ((T)1 + r_in) / ((T)1 + r_out);                                                         \
            k = (T)1 - m * m * s2;                                                                      \
            if (k < 0) { /* TIR, as the library does */                                                 \
                for (a = 0; a < 3; ++a) d[a] = d[a] + (T)2 * c * n[a];                                  \
            } else {                                                                                    \
                f = m * c - SQRT(k);                                                                    \
                for (a = 0; a < 3; ++a) d[a] = m * d[a] + f * n[a];                                     \
            }                                                                                           \
        } else {                                                                                        \
            delta = (r_in - r_out) / ((T)1 + r_out);                                                    \
            e = delta * ((T)2 + delta) * s2;                                                            \
            k = c * c - e;                                                                              \
            f = delta * c + e / (c + SQRT(k));                                                          \
            for (a = 0; a < 3; ++a) d[a] = d[a] + delta * d[a] + f * n[a];                              \
        }                                                                                               \
        nl = SQRT(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);                                             \
        for (a = 0; a < 3; ++a) d[a] /= nl;                                                             \
    }                                                                                                   \
    /* Kick at x with the ratio between the chord midpoints behind and ahead, then drift h.            \
       round_field = 1 rounds r and grad r to float first (what a float grid stores). */              \
    static void walk_##SUF(const double o[3], const double d0[3], int naive, int round_field,          \
                           double out_x[3], double out_d[3])                                            \
    {                                                                                                   \
        T x[3], d[3], g[3], mid[3], gm[3], r_carried, r_ahead, h = (T)(PREC_LEN / PREC_KICKS);           \
        int a, i;                                                                                       \
        for (a = 0; a < 3; ++a) { x[a] = (T)o[a]; d[a] = (T)d0[a]; }                                    \
        r_carried = field_##SUF(x, g);                                                                  \
        if (round_field) r_carried = (T)(float)r_carried;                                               \
        for (i = 0; i < PREC_KICKS; ++i) {                                                              \
            for (a = 0; a < 3; ++a) mid[a] = x[a] + (T)0.5 * h * d[a];                                  \
            r_ahead = field_##SUF(mid, gm);                                                             \
            field_##SUF(x, g);                                                                          \
            if (round_field) {                                                                          \
                r_ahead = (T)(float)r_ahead;                                                            \
                for (a = 0; a < 3; ++a) g[a] = (T)(float)g[a];                                          \
            }                                                                                           \
            refract_##SUF(d, r_carried, r_ahead, g, naive);                                             \
            r_carried = r_ahead;                                                                        \
            for (a = 0; a < 3; ++a) x[a] += h * d[a];                                                   \
        }                                                                                               \
        for (a = 0; a < 3; ++a) { out_x[a] = (double)x[a]; out_d[a] = (double)d[a]; }                   \
    }

DEFINE_PREC(float, f, expf, sqrtf)
DEFINE_PREC(double, d, exp, sqrt)
DEFINE_PREC(long double, ld, expl, sqrtl)

static double angle_between(const double a[3], const double b[3])
{
    double c[3], cn, dt;
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
    cn = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    dt = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    return atan2(cn, dt);
}

static void precision_study(void)
{
    /* Oblique start so no direction component is ~0 (a component near zero
       keeps float's relative precision and would flatter float). */
    double o[3] = {-0.8, 0.12, -0.35}, d0[3] = {0.8, 0.3, 0.35}, n;
    double xr[3], dr[3], x[3], d[3];
    int a;
    struct { const char *name; int prec, naive, round_field; } rows[] = {
        {"double, delta form", 1, 0, 0},
        {"double, naive form", 1, 1, 0},
        {"double state, r and grad r rounded to float (float grid)", 1, 0, 1},
        {"float, delta form", 0, 0, 0},
        {"float, naive form", 0, 1, 0},
        {"long double, naive form", 2, 1, 0},
    };
    int i;
    n = sqrt(d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]);
    for (a = 0; a < 3; ++a) d0[a] /= n;
    walk_ld(o, d0, 0, 0, xr, dr);
    printf("\n### Precision: %d kicks over %.0f m, air r = %.0e with a %.0e hot blob (sigma %.1f m)\n\n",
           PREC_KICKS, PREC_LEN, PREC_R0, PREC_A, PREC_S);
    printf("Reference: the same loop in long double (64-bit mantissa), delta form. Total deflection "
           "of the reference: %.3e rad.\n\n", angle_between(d0, dr));
    printf("| state and form | direction error (rad) | relative to deflection | position error (m) |\n");
    printf("|---|---|---|---|\n");
    for (i = 0; i < (int)(sizeof rows / sizeof rows[0]); ++i) {
        double dx, ang, pe = 0;
        if (rows[i].prec == 0) walk_f(o, d0, rows[i].naive, rows[i].round_field, x, d);
        else if (rows[i].prec == 1) walk_d(o, d0, rows[i].naive, rows[i].round_field, x, d);
        else walk_ld(o, d0, rows[i].naive, rows[i].round_field, x, d);
        ang = angle_between(d, dr);
        for (a = 0; a < 3; ++a) { dx = x[a] - xr[a]; pe += dx * dx; }
        printf("| %s | %.2e | %.2e | %.2e |\n", rows[i].name, ang, ang / angle_between(d0, dr), sqrt(pe));
    }
}

/* ---- gradient stencils on a grid --------------------------------------------------- */

#define STEN_S 0.2

static double sten_r(double x, double y, double z) { return exp(-0.5 * (x * x + y * y + z * z) / (STEN_S * STEN_S)); }
static rrv_vec3 sten_grad(rrv_vec3 p)
{
    return rrv__scale(p, -sten_r(p.x, p.y, p.z) / (STEN_S * STEN_S));
}

/* (ii) the exact gradient of the trilinear interpolant: piecewise, jumps at
   cell faces. */
static rrv_vec3 trilinear_gradient(const rrv_grid *g, rrv_vec3 p)
{
    double fx = (p.x - g->lo.x) / (g->hi.x - g->lo.x) * (g->nx - 1);
    double fy = (p.y - g->lo.y) / (g->hi.y - g->lo.y) * (g->ny - 1);
    double fz = (p.z - g->lo.z) / (g->hi.z - g->lo.z) * (g->nz - 1);
    int ix = (int)fx, iy = (int)fy, iz = (int)fz;
    double tx, ty, tz, c[2][2][2];
    int a, b, e;
    rrv_vec3 r;
    if (ix > g->nx - 2) ix = g->nx - 2;
    if (iy > g->ny - 2) iy = g->ny - 2;
    if (iz > g->nz - 2) iz = g->nz - 2;
    tx = fx - ix; ty = fy - iy; tz = fz - iz;
    for (e = 0; e < 2; ++e)
        for (b = 0; b < 2; ++b)
            for (a = 0; a < 2; ++a) c[e][b][a] = g->data[((size_t)(iz + e) * g->ny + (size_t)(iy + b)) * g->nx + (size_t)(ix + a)];
    r.x = ((1 - ty) * (1 - tz) * (c[0][0][1] - c[0][0][0]) + ty * (1 - tz) * (c[0][1][1] - c[0][1][0]) +
           (1 - ty) * tz * (c[1][0][1] - c[1][0][0]) + ty * tz * (c[1][1][1] - c[1][1][0])) *
          (g->nx - 1) / (g->hi.x - g->lo.x);
    r.y = ((1 - tx) * (1 - tz) * (c[0][1][0] - c[0][0][0]) + tx * (1 - tz) * (c[0][1][1] - c[0][0][1]) +
           (1 - tx) * tz * (c[1][1][0] - c[1][0][0]) + tx * tz * (c[1][1][1] - c[1][0][1])) *
          (g->ny - 1) / (g->hi.y - g->lo.y);
    r.z = ((1 - tx) * (1 - ty) * (c[1][0][0] - c[0][0][0]) + tx * (1 - ty) * (c[1][0][1] - c[0][0][1]) +
           (1 - tx) * ty * (c[1][1][0] - c[0][1][0]) + tx * ty * (c[1][1][1] - c[0][1][1])) *
          (g->nz - 1) / (g->hi.z - g->lo.z);
    return r;
}

/* (iii) central differences at the samples (one-sided at the faces), stored
   as a 3-channel grid and interpolated trilinearly: continuous, second order,
   3 more floats per sample. */
static float *gradient_grid(const rrv_grid *g)
{
    int n[3], i[3], a;
    float *out = (float *)malloc((size_t)g->nx * g->ny * g->nz * 3 * sizeof(float));
    double vox[3];
    n[0] = g->nx; n[1] = g->ny; n[2] = g->nz;
    vox[0] = (g->hi.x - g->lo.x) / (g->nx - 1);
    vox[1] = (g->hi.y - g->lo.y) / (g->ny - 1);
    vox[2] = (g->hi.z - g->lo.z) / (g->nz - 1);
    for (i[2] = 0; i[2] < n[2]; ++i[2])
        for (i[1] = 0; i[1] < n[1]; ++i[1])
            for (i[0] = 0; i[0] < n[0]; ++i[0])
                for (a = 0; a < 3; ++a) {
                    int lo[3], hi[3], b;
                    for (b = 0; b < 3; ++b) lo[b] = hi[b] = i[b];
                    lo[a] = i[a] > 0 ? i[a] - 1 : 0;
                    hi[a] = i[a] < n[a] - 1 ? i[a] + 1 : n[a] - 1;
                    out[(((size_t)i[2] * n[1] + i[1]) * n[0] + i[0]) * 3 + a] =
                        (float)((g->data[((size_t)hi[2] * n[1] + hi[1]) * n[0] + hi[0]] -
                                 g->data[((size_t)lo[2] * n[1] + lo[1]) * n[0] + lo[0]]) /
                                ((hi[a] - lo[a]) * vox[a]));
                }
    return out;
}

static rrv_vec3 interp_gradient(const rrv_grid *g, const float *gg, rrv_vec3 p)
{
    double fx = (p.x - g->lo.x) / (g->hi.x - g->lo.x) * (g->nx - 1);
    double fy = (p.y - g->lo.y) / (g->hi.y - g->lo.y) * (g->ny - 1);
    double fz = (p.z - g->lo.z) / (g->hi.z - g->lo.z) * (g->nz - 1);
    int ix = (int)fx, iy = (int)fy, iz = (int)fz, a, b, e, c;
    double tx, ty, tz, acc[3] = {0, 0, 0};
    if (ix > g->nx - 2) ix = g->nx - 2;
    if (iy > g->ny - 2) iy = g->ny - 2;
    if (iz > g->nz - 2) iz = g->nz - 2;
    tx = fx - ix; ty = fy - iy; tz = fz - iz;
    for (e = 0; e < 2; ++e)
        for (b = 0; b < 2; ++b)
            for (a = 0; a < 2; ++a) {
                double w = (a ? tx : 1 - tx) * (b ? ty : 1 - ty) * (e ? tz : 1 - tz);
                const float *s = gg + (((size_t)(iz + e) * g->ny + (size_t)(iy + b)) * g->nx + (size_t)(ix + a)) * 3;
                for (c = 0; c < 3; ++c) acc[c] += w * s[c];
            }
    return rrv__v3(acc[0], acc[1], acc[2]);
}


/* The stencil the library's fused grid gradient equals: central differences
   of the trilinear field with a step of h (one voxel), from six lookups. */
static rrv_vec3 central_difference_gradient(const rrv_field *f, rrv_vec3 p, double ambient, double h)
{
    rrv_vec3 g;
    g.x = (rrv__field_eval(f, rrv__v3(p.x + h, p.y, p.z), 0, ambient) -
           rrv__field_eval(f, rrv__v3(p.x - h, p.y, p.z), 0, ambient)) / (2 * h);
    g.y = (rrv__field_eval(f, rrv__v3(p.x, p.y + h, p.z), 0, ambient) -
           rrv__field_eval(f, rrv__v3(p.x, p.y - h, p.z), 0, ambient)) / (2 * h);
    g.z = (rrv__field_eval(f, rrv__v3(p.x, p.y, p.z + h), 0, ambient) -
           rrv__field_eval(f, rrv__v3(p.x, p.y, p.z - h), 0, ambient)) / (2 * h);
    return g;
}
static void stencil_study(void)
{
    static const int sizes[] = {16, 32, 64};
    int si;
    printf("\n### Grid gradient stencils: Gaussian r = exp(-|x|^2 / (2 * 0.2^2)) on [-0.5,0.5]^3\n\n");
    printf("Errors of grad r against the analytic gradient at 200000 random points in [-0.4,0.4]^3, "
           "relative to the RMS of |grad r| there.\n\n");
    printf("| grid | stencil | RMS rel. error | max rel. error | order (RMS) | ns/eval |\n");
    printf("|---|---|---|---|---|---|\n");
    {
        double prev_rms[4] = {0, 0, 0, 0};
        for (si = 0; si < 3; ++si) {
            int N = sizes[si], x, y, z, k, i, method;
            const int npts = 200000;
            rrv_field f;
            rrv_vec3 *pts = (rrv_vec3 *)malloc((size_t)npts * sizeof(rrv_vec3));
            float *gg;
            rrv__rng rng;
            double vox = 1.0 / (N - 1), gnorm2 = 0;
            memset(&f, 0, sizeof f);
            f.kind = RRV_FIELD_GRID;
            f.grid.nx = f.grid.ny = f.grid.nz = N;
            f.grid.channels = 1;
            f.grid.lo = rrv__v3(-0.5, -0.5, -0.5);
            f.grid.hi = rrv__v3(0.5, 0.5, 0.5);
            f.grid.data = (float *)malloc((size_t)N * N * N * sizeof(float));
            for (z = 0; z < N; ++z)
                for (y = 0; y < N; ++y)
                    for (x = 0; x < N; ++x)
                        f.grid.data[((size_t)z * N + y) * N + x] =
                            (float)sten_r(-0.5 + x * vox, -0.5 + y * vox, -0.5 + z * vox);
            gg = gradient_grid(&f.grid);
            rrv__rng_seed(&rng, 9, (uint64_t)N, 0);
            for (i = 0; i < npts; ++i) {
                pts[i] = rrv__v3(-0.4 + 0.8 * rrv__uniform(&rng), -0.4 + 0.8 * rrv__uniform(&rng),
                                 -0.4 + 0.8 * rrv__uniform(&rng));
                gnorm2 += rrv__dot(sten_grad(pts[i]), sten_grad(pts[i]));
            }
            gnorm2 /= npts;
            for (method = 0; method < 4; ++method) {
                static const char *names[] = {"(i) central diff. of trilinear, step 1 voxel (6 lookups)",
                                              "(ii) exact gradient of trilinear",
                                              "(iii) sample central diff. precomputed, trilinear",
                                              "(iv) (i) fused: blend of sample central diff. (library)"};
                /* (iv) is (i) computed as (iii) on the fly, which rrv does */
                int method_fused = method == 3;
                double voxel = (f.grid.hi.x - f.grid.lo.x) / (f.grid.nx - 1);
                double se = 0, mx = 0, sink = 0, ns;
                clock_t t0;
                int reps = 0;
                for (i = 0; i < npts; ++i) {
                    rrv_vec3 g = method == 0 || method_fused ? (method_fused ? rrv__grid_gradient(&f.grid, pts[i]) : central_difference_gradient(&f, pts[i], 0, voxel))
                               : method == 1 ? trilinear_gradient(&f.grid, pts[i])
                                             : interp_gradient(&f.grid, gg, pts[i]);
                    double e2 = rrv__dot(rrv__sub(g, sten_grad(pts[i])), rrv__sub(g, sten_grad(pts[i])));
                    se += e2;
                    mx = fmax(mx, e2);
                }
                t0 = clock();
                do {
                    for (i = 0; i < npts; ++i) {
                        rrv_vec3 g = method == 0 || method_fused ? (method_fused ? rrv__grid_gradient(&f.grid, pts[i]) : central_difference_gradient(&f, pts[i], 0, voxel))
                                   : method == 1 ? trilinear_gradient(&f.grid, pts[i])
                                                 : interp_gradient(&f.grid, gg, pts[i]);
                        sink += g.x + g.y + g.z;
                    }
                    ++reps;
                } while (clock() - t0 < CLOCKS_PER_SEC / 10);
                ns = 1e9 * (double)(clock() - t0) / CLOCKS_PER_SEC / ((double)reps * npts);
                se = sqrt(se / npts / gnorm2);
                k = method;
                {
                    char order[16] = "";
                    if (si > 0) sprintf(order, "%.2f", log(prev_rms[k] / se) / log((double)(sizes[si] - 1) / (sizes[si - 1] - 1)));
                    printf("| %d^3 | %s | %.2e | %.2e | %s | %.1f |%s\n", N, names[method], se, sqrt(mx / gnorm2),
                           order, ns, sink == 12345.678 ? " " : "");
                }
                prev_rms[k] = se;
            }
            free(gg);
            free(pts);
            free(f.grid.data);
        }
    }
}

/* ---- the same fields sampled into IOR grids ------------------------------------
   The order question on a grid: how fast does each integrator converge to the
   ray of the SAME interpolated field? The reference for RK4 and leapfrog is
   the library's RK4 at a tiny step (both solve d/ds(v) = grad eta, dx/ds =
   v / eta); for the comb it is RK4 on the direction form it converges to,
   dx/ds = d, dd/ds = (grad r - (grad r . d) d) / (1 + r). The two limits
   differ only where the value and gradient channels disagree (trilinear),
   and the table prints by how much. Separately, how far the grid's ray is
   from the analytic field's (discretisation, not the integrator). */

enum { GCASE_BLOB, GCASE_LENS, GCASE_LUNEBURG, GCASE_COUNT };
static const char *const GCASE_NAMES[] = {
    "weak Gaussian blob (A = 1e-2, sigma = 0.1) on [-0.6, 0.6]^3, b = 0.1 to 0.128",
    "strong Gaussian lens (A = 0.2, sigma = 0.25) on [-1.5, 1.5]^3, b = 0.25 to 0.306",
    "Luneburg lens (R = 1) on [-1.25, 1.25]^3, b = 0.5 to 0.563 (gradient jumps at the sphere)"};
#define LENS_A 0.2
#define LENS_S 0.25
#define GRAYS 8 /* rays a case: impact parameters spread over ~1 voxel, so
                   errors average over where steps fall in the cells */

static double gcase_r(int which, double x, double y, double z)
{
    double q = x * x + y * y + z * z;
    if (which == GCASE_LUNEBURG) return q < 1.0 ? sqrt(2.0 - q) - 1.0 : 0.0;
    if (which == GCASE_LENS) return LENS_A * exp(-0.5 * q / (LENS_S * LENS_S));
    return BLOB_A * exp(-0.5 * q / (BLOB_S * BLOB_S));
}

/* Half widths: the fields have fallen to < 1e-8 at the faces, so no jump to
   the ambient IOR there adds the box-face error to the interior one. */
static double gcase_half(int which) { return which == GCASE_BLOB ? 0.6 : which == GCASE_LENS ? 1.5 : 1.25; }
static double gcase_plane(int which) { return gcase_half(which) + 0.5; } /* errors: where exit rays cross z = this */

static rrv_scene *make_grid_case(int which, int N, rrv_ior_interpolation interp)
{
    rrv_scene *s = tb_scene(4, 4);
    double hw = gcase_half(which), vox = 2.0 * hw / (N - 1);
    rrv_medium *m = tb_medium(s, rrv__v3(-hw, -hw, -hw), rrv__v3(hw, hw, hw), 0, 0);
    rrv_error err;
    int x, y, z;
    m->density.kind = RRV_FIELD_NONE;
    m->ior.kind = RRV_FIELD_GRID;
    m->ior.grid.nx = m->ior.grid.ny = m->ior.grid.nz = N;
    m->ior.grid.channels = 1;
    m->ior.grid.lo = m->lo;
    m->ior.grid.hi = m->hi;
    m->ior.grid.data = (float *)malloc((size_t)N * N * N * sizeof(float));
    for (z = 0; z < N; ++z)
        for (y = 0; y < N; ++y)
            for (x = 0; x < N; ++x)
                m->ior.grid.data[((size_t)z * N + y) * N + x] =
                    (float)gcase_r(which, -hw + x * vox, -hw + y * vox, -hw + z * vox);
    s->settings.ior_interpolation = interp;
    if (rrv_scene_prepare(s, &err) != RRV_OK) {
        fprintf(stderr, "prepare: %s\n", err.message);
        exit(1);
    }
    return s;
}

/* Ray j of a case: along +z at impact parameter b_j, 0.3 rad off the x
   axis so no coordinate plane of the lattice contains it. */
static void gcase_ray(int which, int j, rrv_vec3 *o, rrv_vec3 *d)
{
    double b = which == GCASE_BLOB ? BLOB_B + 0.004 * j : which == GCASE_LENS ? 0.25 + 0.008 * j : 0.5 + 0.009 * j;
    *o = rrv__v3(b * cos(0.3), b * sin(0.3), -gcase_half(which) - 0.5);
    *d = rrv__v3(0, 0, 1);
}

static rrv_vec3 plane_hit(int which, rrv_vec3 p, rrv_vec3 d)
{
    return rrv__madd(p, d, (gcase_plane(which) - p.z) / d.z);
}

/* RK4 on (x, d) with the comb's limit equation, through the whole box. */
static rrv_vec3 direction_ode_hit(const rrv_scene *s, int which, int j, double h)
{
    rrv_vec3 x, d, kx[4], kd[4], xs, ds;
    double hw = gcase_half(which);
    int k;
    gcase_ray(which, j, &x, &d);
    x = rrv__madd(x, d, (-hw - x.z) / d.z); /* straight to the box */
    while (x.z < hw) {
        /* The last step ends on the exit face: a step straddling the jump
           to the ambient value there would be first order. */
        if (x.z + h * d.z > hw) h = (hw - x.z) / d.z * (1.0 + 1e-12);
        for (k = 0; k < 4; ++k) {
            rrv_vec3 g;
            double r, c = k == 0 ? 0 : k == 3 ? 1 : 0.5;
            xs = k == 0 ? x : rrv__madd(x, kx[k - 1], c * h);
            ds = k == 0 ? d : rrv__madd(d, kd[k - 1], c * h);
            r = rrv__scene_refractivity(s, xs, &g);
            kx[k] = ds;
            kd[k] = rrv__scale(rrv__madd(g, ds, -rrv__dot(g, ds)), 1.0 / (1.0 + r));
        }
        x = rrv__madd(x, rrv__add(rrv__add(kx[0], kx[3]), rrv__scale(rrv__add(kx[1], kx[2]), 2.0)), h / 6.0);
        d = rrv__madd(d, rrv__add(rrv__add(kd[0], kd[3]), rrv__scale(rrv__add(kd[1], kd[2]), 2.0)), h / 6.0);
        d = rrv__normalize(d);
    }
    return plane_hit(which, x, d);
}

static rrv_vec3 trace_hit(const rrv_scene *s, int which, int j, rrv_integrator integ, uint64_t walk, uint64_t *events)
{
    rrv_trace_result r;
    rrv_error err;
    rrv_vec3 o, d;
    gcase_ray(which, j, &o, &d);
    if (rrv_trace_ray(s, integ, o, d, 42, walk, NULL, NULL, &r, &err) != RRV_OK) {
        fprintf(stderr, "trace failed: %s\n", err.message);
        exit(1);
    }
    if (events) *events = r.events;
    return plane_hit(which, r.position, r.direction);
}

static void set_method(rrv_scene *s, const method *me, double param)
{
    s->settings.integrator = me->integ;
    s->settings.refraction = me->scheme;
    s->settings.stepper = me->stepper;
    if (me->integ == RRV_INTEGRATOR_EIKONAL) s->settings.step = param;
    else s->settings.mu_eta = param;
}

static rrv_vec3 eikonal_ref_hit(rrv_scene *s, int which, int j, double h)
{
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.stepper = RRV_STEPPER_RK4;
    s->settings.step = h;
    return trace_hit(s, which, j, RRV_INTEGRATOR_EIKONAL, 0, NULL);
}

/* The analytic field's rays (RK4 at h = 1e-4 through the closed form). */
static void analytic_hits(int which, rrv_vec3 *hits)
{
    rrv_scene *s;
    int j;
    if (which == GCASE_LUNEBURG) {
        s = make_case(CASE_LUNEBURG);
    } else {
        rrv_medium *m;
        rrv_blob *bl;
        rrv_error err;
        double hw = gcase_half(which);
        s = tb_scene(4, 4);
        m = tb_medium(s, rrv__v3(-hw, -hw, -hw), rrv__v3(hw, hw, hw), 0, 0);
        m->density.kind = RRV_FIELD_NONE;
        bl = tb_blobs(&m->ior, 1);
        bl->center = rrv__v3(0, 0, 0);
        bl->radius = which == GCASE_LENS ? LENS_S : BLOB_S;
        bl->weight = which == GCASE_LENS ? LENS_A : BLOB_A;
        if (rrv_scene_prepare(s, &err) != RRV_OK) exit(1);
    }
    for (j = 0; j < GRAYS; ++j) hits[j] = eikonal_ref_hit(s, which, j, 1e-4);
    rrv_scene_free(s);
}

#define GRID_WALKS 50 /* comb walks per ray: 400 a rate */
static const double GRID_RATES[] = {30, 100, 300, 1000, 3000};
static const double GRID_STEPS[] = {0.2, 0.1, 0.05, 0.02, 0.01, 0.005};
#define GREF_H 4e-5

/* Least-squares slope of log err against log param over rows from..n-1. */
static double fitted_order(const double *param, const double *err, int from, int n)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int i, m = n - from;
    for (i = from; i < n; ++i) {
        double x = log(param[i]), y = log(err[i]);
        sx += x; sy += y; sxx += x * x; sxy += x * y;
    }
    return fabs((m * sxy - sx * sy) / (m * sxx - sx * sx));
}

static void grid_sweep(int which, int N, rrv_ior_interpolation interp)
{
    static const int ids[] = {2, 3, 4}; /* COMB, LEAPFROG, RK4 */
    rrv_scene *s = make_grid_case(which, N, interp);
    rrv_vec3 ref_eik[GRAYS], ref_dir[GRAYS];
    double check_eik, check_dir, limits = 0, discretisation = 0;
    rrv_vec3 ana[GRAYS];
    int k, i, j;
    analytic_hits(which, ana);
    for (j = 0; j < GRAYS; ++j) {
        ref_eik[j] = eikonal_ref_hit(s, which, j, GREF_H);
        ref_dir[j] = direction_ode_hit(s, which, j, GREF_H);
        limits = fmax(limits, rrv__length(rrv__sub(ref_eik[j], ref_dir[j])));
        discretisation += rrv__length(rrv__sub(ref_eik[j], ana[j])) / GRAYS;
    }
    check_eik = rrv__length(rrv__sub(ref_eik[0], eikonal_ref_hit(s, which, 0, 2 * GREF_H)));
    check_dir = rrv__length(rrv__sub(ref_dir[0], direction_ode_hit(s, which, 0, 2 * GREF_H)));
    printf("\n#### %s, %d^3 (voxel %.3g m), %s\n\n", GCASE_NAMES[which], N, 2 * gcase_half(which) / (N - 1),
           interp == RRV_IOR_INTERP_CUBIC ? "cubic" : "trilinear");
    printf("References per ray: RK4 (eikonal) and direction-form RK4 (comb) at h = %g; from h = %g they move "
           "by %.1e / %.1e; the two limits differ by up to %.1e. The grid's rays miss the analytic "
           "field's by %.2e on average (discretisation, not the integrator).\n\n",
           GREF_H, 2 * GREF_H, check_eik, check_dir, limits, discretisation);
    printf("| method | events/m or h | mean error vs same grid | std. error | order | events/ray |\n|---|---|---|---|---|---|\n");
    for (k = 0; k < 3; ++k) {
        const method *me = &METHODS[ids[k]];
        int eik = me->integ == RRV_INTEGRATOR_EIKONAL;
        int n = eik ? (int)(sizeof GRID_STEPS / sizeof GRID_STEPS[0]) : (int)(sizeof GRID_RATES / sizeof GRID_RATES[0]);
        double params[8], errs[8], lo = 1e9, hi = 0;
        for (i = 0; i < n; ++i) {
            double param = eik ? GRID_STEPS[i] : GRID_RATES[i], sum = 0, sum2 = 0, ev = 0, err, se;
            int w, walks = eik ? 1 : GRID_WALKS;
            char order[16] = "";
            set_method(s, me, param);
            for (j = 0; j < GRAYS; ++j)
                for (w = 0; w < walks; ++w) {
                    uint64_t events;
                    double e = rrv__length(rrv__sub(trace_hit(s, which, j, me->integ, (uint64_t)w, &events),
                                                    eik ? ref_eik[j] : ref_dir[j]));
                    sum += e;
                    sum2 += e * e;
                    ev += (double)events;
                }
            walks *= GRAYS;
            err = sum / walks;
            se = sqrt(fmax(0.0, sum2 / walks - err * err) / (walks - 1));
            params[i] = param;
            errs[i] = err;
            if (i > 0 && err > 0 && errs[i - 1] > 0)
                sprintf(order, "%.2f", fabs(log(err / errs[i - 1]) / log(param / params[i - 1])));
            printf("| %s | %g | %.3e | %.1e | %s | %.0f |\n", me->name, param, err, se, order, ev / walks);
            if (i > 0) {
                double p = fabs(log(err / errs[i - 1]) / log(param / params[i - 1]));
                lo = fmin(lo, p);
                hi = fmax(hi, p);
            }
        }
        printf("| %s | fitted order (all rows); range of the pairwise orders | | | **%.2f**; %.2f to %.2f | |\n",
               me->name, fitted_order(params, errs, 0, n), lo, hi);
    }
    rrv_scene_free(s);
}

/* Cost of one ray, trilinear against cubic: rounds alternate which goes
   first, each times a batch of rays; medians of CPU time (user+sys, clock()). */
static void grid_cost(int which, int N)
{
    static const int ids[] = {2, 4};
    static const double params[] = {300, 0.02};
    enum { ROUNDS = 11 };
    int k;
    printf("\n#### Cost per ray, %s, %d^3 (median of %d interleaved rounds, CPU user+sys)\n\n", GCASE_NAMES[which], N,
           ROUNDS);
    printf("| method | trilinear us/ray | cubic us/ray | cubic / trilinear | events/ray | trilinear ns/event | cubic ns/event |\n");
    printf("|---|---|---|---|---|---|---|\n");
    for (k = 0; k < 2; ++k) {
        const method *me = &METHODS[ids[k]];
        rrv_scene *sc[2];
        double t[2][ROUNDS], med[2];
        uint64_t events = 0;
        int round, v, w, walks = me->integ == RRV_INTEGRATOR_EIKONAL ? 400 : 200;
        for (v = 0; v < 2; ++v) {
            sc[v] = make_grid_case(which, N, v ? RRV_IOR_INTERP_CUBIC : RRV_IOR_INTERP_TRILINEAR);
            set_method(sc[v], me, params[k]);
        }
        trace_hit(sc[0], which, 0, me->integ, 0, &events);
        for (round = 0; round < ROUNDS; ++round)
            for (v = 0; v < 2; ++v) {
                int which_v = (round & 1) ? 1 - v : v;
                clock_t t0 = clock();
                double sink = 0;
                for (w = 0; w < walks; ++w) sink += trace_hit(sc[which_v], which, 0, me->integ, (uint64_t)w, NULL).x;
                t[which_v][round] = 1e6 * (double)(clock() - t0) / CLOCKS_PER_SEC / walks + (sink == 1e300);
            }
        for (v = 0; v < 2; ++v) {
            qsort(t[v], ROUNDS, sizeof(double), cmp_double);
            med[v] = t[v][ROUNDS / 2];
            rrv_scene_free(sc[v]);
        }
        printf("| %s %g | %.1f | %.1f | %.2f | %llu | %.0f | %.0f |\n", me->name, params[k], med[0], med[1],
               med[1] / med[0], (unsigned long long)events, 1e3 * med[0] / (double)events,
               1e3 * med[1] / (double)events);
    }
}

/* Load-time cost: rrv_scene_prepare of a 128^3 IOR grid (the bake, plus the
   majorant grid both share), interleaved, median of 5 rounds. */
static void grid_bake_cost(void)
{
    enum { ROUNDS = 5 };
    double t[2][ROUNDS];
    int round, v;
    for (round = 0; round < ROUNDS; ++round)
        for (v = 0; v < 2; ++v) {
            int which_v = (round & 1) ? 1 - v : v;
            clock_t t0 = clock();
            rrv_scene *s = make_grid_case(GCASE_LENS, 128, which_v ? RRV_IOR_INTERP_CUBIC : RRV_IOR_INTERP_TRILINEAR);
            t[which_v][round] = (double)(clock() - t0) / CLOCKS_PER_SEC;
            rrv_scene_free(s);
        }
    for (v = 0; v < 2; ++v) qsort(t[v], ROUNDS, sizeof(double), cmp_double);
    printf("\nSampling and preparing a 128^3 IOR grid (CPU s, median of %d interleaved): trilinear %.3f, "
           "cubic %.3f; baked bytes a sample: trilinear 16, cubic 8 (doubles, plus one ghost layer).\n",
           ROUNDS, t[0][ROUNDS / 2], t[1][ROUNDS / 2]);
}

static void grid_study(void)
{
    static const int sizes[] = {32, 64};
    int which, si, interp;
    printf("\n### IOR grids: order of each integrator on the grid's own field\n\n");
    printf("Error: distance, where the exit ray crosses z = (box half width + 0.5), from the reference ray "
           "through the same interpolated grid; mean over %d rays (comb: %d walks each).\n", GRAYS, GRID_WALKS);
    for (which = 0; which < GCASE_COUNT; ++which)
        for (si = 0; si < 2; ++si)
            for (interp = 0; interp < 2; ++interp) grid_sweep(which, sizes[si], (rrv_ior_interpolation)interp);
    for (which = 0; which < GCASE_COUNT; ++which) grid_cost(which, 64);
    grid_bake_cost();
}

int main(int argc, char **argv)
{
    (void)tb_shape; /* the shared builder's; unused here */
    static const int refr_and_eik[] = {0, 1, 2, 3, 4};
    clock_t t0 = clock();
    printf("## rrv GRIN convergence (measure_grin)\n");
    printf("\nError: Luneburg (R = 1, ray at b = 0.5 along +z): distance of the exit ray from the focus (0,0,1). "
           "Slab (eta - 1 = 0.2 - 0.4 y, start inside at y = -0.45, 60 deg): |x - exact| where the exit ray "
           "crosses y = 0.5. Blob (A = 1e-2, sigma = 0.1, b = 0.1): |exit d_x - RK4 reference at h = 1e-4|. "
           "Stochastic schemes: mean over 400 walks (std. error of that mean given); eikonal: one deterministic ray. "
           "Field evals: calls of rrv__scene_refractivity per ray, counted from the code "
           "(POISSON 1, MIDPOINT 2, COMB 1 (with gradient), LEAPFROG 2, RK4 4 per event/step).\n");
    if (argc > 1 && strcmp(argv[1], "grids") == 0) {
        grid_study();
        printf("\n(total %.1f s)\n", (double)(clock() - t0) / CLOCKS_PER_SEC);
        return 0;
    }
    sweep(CASE_LUNEBURG, "Luneburg lens, b = 0.5", refr_and_eik, 5, 400);
    sweep(CASE_SLAB, "Linear slab, 60 degrees", refr_and_eik, 5, 400);
    sweep(CASE_BLOB, "Gaussian blob A = 1e-2, sigma = 0.1, b = 0.1", refr_and_eik, 5, 400);
    precision_study();
    stencil_study();
    grid_study();
    printf("\n(total %.1f s)\n", (double)(clock() - t0) / CLOCKS_PER_SEC);
    return 0;
}
