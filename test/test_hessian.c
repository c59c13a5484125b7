/* The derivative of grad eta that curved next-event estimation (nee shoot,
   nee manifold) propagates Jacobi fields with: rrv__refractivity_hessian and the
   helpers behind it, for every kind of IOR, against central differences of
   rrv's own gradient (rrv__scene_refractivity, the one the rays use):
   - trilinear grids (an IOR grid, a gas whose temperature is a grid, a
     baked noise field, an unbaked gridvol grid, a NanoVDB grid): their
     gradient is a trilinear blend of central differences, multilinear
     inside a cell, so central differences of it that stay in the cell are
     exact but for rounding; the derivative is not symmetric and is checked
     as it is, with its asymmetry shown to shrink as the grid is refined;
   - smooth fields (the cubic B-spline of a grid, blobs, Luneburg,
     fish-eye, shell, a gas from blobs of temperature and pressure): the
     differences err by O(delta^2) and the Hessian is symmetric;
   - the solver: the Jacobi field carried through the discrete steps in a
     grid medium against central differences of the traced endpoint, and
     Newton's method converging on a connection through it.
   Fixed seeds. HESSIAN_VERBOSE=1 prints the measured errors. */
#define RRV_RESEARCH /* the midpoint scheme and the leapfrog stepper, which this tests too */
#define RRV_IMPLEMENTATION
#include "../rrv.h"
#include "check.h"
#include "say.h"
#include "scene_builder.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The derivative of grad eta at p from the per-medium function alone
   (rrv__refractivity_hessian), where rrv__scene_refractivity takes the
   gradient: the reference the fused rrv__eta_gradient_hessian is checked
   against. */
static void scene_hessian(const rrv_scene *scene, rrv_vec3 p, double H[9])
{
    double ambient_r = rrv__ambient_ior(scene) - 1.0;
    int i, k;
    for (i = scene->medium_count - 1; i >= 0; --i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && rrv__inside_box(p, m->lo, m->hi)) {
            rrv__refractivity_hessian(m, p, ambient_r, H);
            return;
        }
    }
    for (k = 0; k < 9; ++k) H[k] = 0;
}


/* ---- fields to differentiate ------------------------------------------------------- */

/* A smooth refractivity-like function: a Gaussian bump with a tilt and a
   ripple, so that every second derivative is non-zero somewhere. */
static double bump(rrv_vec3 p)
{
    rrv_vec3 d = rrv__sub(p, rrv__v3(0.1, -0.15, 0.05));
    return exp(-rrv__dot(d, d) / (2.0 * 0.35 * 0.35)) + 0.1 * p.x - 0.05 * p.y * p.z +
           0.08 * sin(3.0 * p.x + 2.0 * p.y) * cos(2.5 * p.z);
}

/* An n^3 gridvol grid over [lo, hi] with samples a + b bump(x). */
static void fill_grid(rrv_field *f, int n, rrv_vec3 lo, rrv_vec3 hi, double a, double b)
{
    int x, y, z, dims[3];
    size_t i = 0;
    memset(f, 0, sizeof *f);
    f->kind = RRV_FIELD_GRID;
    f->grid.nx = f->grid.ny = f->grid.nz = n;
    f->grid.channels = 1;
    f->grid.lo = lo;
    f->grid.hi = hi;
    f->grid.data = (float *)malloc((size_t)n * n * n * sizeof(float));
    dims[0] = dims[1] = dims[2] = n;
    for (z = 0; z < n; ++z)
        for (y = 0; y < n; ++y)
            for (x = 0; x < n; ++x) f->grid.data[i++] = (float)(a + b * bump(rrv__lattice_point(lo, hi, dims, x, y, z)));
}

static rrv_scene *empty_scene(void)
{
    rrv_scene *s = tb_scene(4, 4);
    s->settings.integrator = RRV_INTEGRATOR_EIKONAL;
    s->settings.step = 0.01;
    return s;
}

/* A medium over [-1, 1]^3 without density; gas selects Hauf-Grigull. */
static int add_medium(rrv_scene *s, int gas, double ior_scale)
{
    rrv_medium desc;
    rrv_error err;
    int i;
    memset(&desc, 0, sizeof desc);
    desc.lo = rrv__v3(-1, -1, -1);
    desc.hi = rrv__v3(1, 1, 1);
    desc.ior_from_gas = gas;
    desc.ior_scale = ior_scale;
    tb_must(rrv_scene_add_medium(s, &desc, &i, &err), &err);
    s->media[i].sigma_a[0] = s->media[i].sigma_a[1] = s->media[i].sigma_a[2] = 0;
    s->media[i].sigma_s[0] = s->media[i].sigma_s[1] = s->media[i].sigma_s[2] = 0;
    return i;
}

static void set_field(rrv_scene *s, int medium, rrv_medium_field which, rrv_field *f)
{
    rrv_error err;
    tb_must(rrv_scene_set_field(s, medium, which, f, &err), &err);
    if (f->kind == RRV_FIELD_GRID) free(f->grid.data);
    if (f->kind == RRV_FIELD_BLOBS) free(f->blobs);
}

static void prepare(rrv_scene *s)
{
    rrv_error err;
    CHECKF(rrv_scene_prepare(s, &err) == RRV_OK, "prepare: %s", err.message);
}

/* An IOR grid (eta - 1 from 0.02 to 0.06), n^3 samples, trilinear or cubic. */
static rrv_scene *ior_grid_scene(int n, rrv_ior_interpolation interp)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 0, 1.0);
    rrv_field f;
    s->settings.ior_interpolation = interp;
    fill_grid(&f, n, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 0.02, 0.03);
    set_field(s, m, RRV_MEDIUM_IOR, &f);
    prepare(s);
    return s;
}

/* A gas whose temperature is a grid (300 to ~900 K), air scaled by 40. */
static rrv_scene *gas_grid_scene(int n)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 1, 40.0);
    rrv_field f;
    fill_grid(&f, n, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 300.0, 500.0);
    set_field(s, m, RRV_MEDIUM_TEMPERATURE, &f);
    s->settings.ambient_ior = 1.0 + 40.0 * 2.92e-4;
    prepare(s);
    return s;
}

/* A gas whose temperature grid covers [-1, 0.2]^3 only while its pressure
   grid covers the whole box: the bake follows the temperature's lattice,
   so beyond it the gradient is the unbaked blend of the pressure grid. */
static rrv_scene *gas_two_grids_scene(void)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 1, 40.0);
    rrv_field t, p;
    fill_grid(&t, 9, rrv__v3(-1, -1, -1), rrv__v3(0.2, 0.2, 0.2), 300.0, 400.0);
    fill_grid(&p, 17, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 101325.0, 20000.0);
    set_field(s, m, RRV_MEDIUM_TEMPERATURE, &t);
    set_field(s, m, RRV_MEDIUM_PRESSURE, &p);
    prepare(s);
    return s;
}

/* A gas whose temperature is noise (baked into a grid by prepare). */
static rrv_scene *gas_noise_scene(void)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 1, 40.0);
    rrv_field f;
    memset(&f, 0, sizeof f);
    f.kind = RRV_FIELD_NOISE;
    f.noise.octaves = 2;
    f.noise.frequency = 1.5;
    f.noise.seed = 3;
    f.amplitude = 600;
    f.base = 300;
    set_field(s, m, RRV_MEDIUM_TEMPERATURE, &f);
    s->settings.max_bake_samples = 24;
    prepare(s);
    return s;
}

/* A gas from blobs of temperature and of pressure (no grid, no bake). */
static rrv_scene *gas_blob_scene(void)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 1, 40.0);
    rrv_field t, p;
    rrv_blob *b;
    memset(&t, 0, sizeof t);
    memset(&p, 0, sizeof p);
    b = tb_blobs(&t, 2);
    b[0].center = rrv__v3(0, -0.2, 0); b[0].radius = 0.4; b[0].weight = 600;
    b[1].center = rrv__v3(0.2, 0.3, 0.1); b[1].radius = 0.25; b[1].weight = 300;
    t.base = 300;
    b = tb_blobs(&p, 1);
    b[0].center = rrv__v3(-0.1, 0.1, 0.2); b[0].radius = 0.5; b[0].weight = 30000;
    p.base = 101325;
    set_field(s, m, RRV_MEDIUM_TEMPERATURE, &t);
    set_field(s, m, RRV_MEDIUM_PRESSURE, &p);
    prepare(s);
    return s;
}

/* A gas from blobs of temperature at the ambient pressure (the fire
   plumes' kind, which rrv__gas_fused takes). */
static rrv_scene *gas_blob_temperature_scene(void)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 1, 40.0);
    rrv_field t;
    rrv_blob *b;
    memset(&t, 0, sizeof t);
    b = tb_blobs(&t, 3);
    b[0].center = rrv__v3(0, -0.2, 0); b[0].radius = 0.4; b[0].weight = 600;
    b[1].center = rrv__v3(0.2, 0.3, 0.1); b[1].radius = 0.25; b[1].weight = 300;
    b[2].center = rrv__v3(-0.3, 0.1, -0.2); b[2].radius = 0.1; b[2].weight = -250;
    t.base = 300;
    set_field(s, m, RRV_MEDIUM_TEMPERATURE, &t);
    prepare(s);
    return s;
}

/* One analytic IOR profile (or blobs) at the origin. */
static rrv_scene *profile_scene(rrv_field_kind kind)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 0, kind == RRV_FIELD_SHELL ? 1.0 : 0.5);
    rrv_field f;
    memset(&f, 0, sizeof f);
    f.kind = kind;
    f.center = rrv__v3(0.05, -0.02, 0.03);
    f.radius = 0.9;
    if (kind == RRV_FIELD_SHELL) {
        f.thickness = 0.3;
        f.edge = 0.1;
        f.amplitude = 0.05;
    }
    if (kind == RRV_FIELD_BLOBS) {
        rrv_blob *b = tb_blobs(&f, 2);
        b[0].center = rrv__v3(0.1, -0.05, 0); b[0].radius = 0.3; b[0].weight = 0.5;
        b[1].center = rrv__v3(-0.2, 0.2, 0.3); b[1].radius = 0.2; b[1].weight = -0.2;
    }
    set_field(s, m, RRV_MEDIUM_IOR, &f);
    prepare(s);
    return s;
}

/* ---- the Hessian against differences of the gradient ------------------------------- */

static rrv_vec3 gradient_at(const rrv_scene *s, rrv_vec3 p)
{
    rrv_vec3 g;
    rrv__scene_refractivity(s, p, &g);
    return g;
}

typedef struct hessian_error {
    double diff;      /* max |H - differences| over the points */
    double scale;     /* max |H_ij| over the points */
    double asymmetry; /* max |H_ij - H_ji| */
} hessian_error;

/* Central differences of the gradient at `count` points. With `cell` > 0
   the points are lattice cells of that spacing from `origin` plus a
   fraction in [0.02, 0.98] per axis, and delta (1e-4 of the spacing) keeps
   every difference inside its cell; with `cell` = 0 they are uniform in a
   ball of radius `reach` around `origin`. */
static hessian_error check_hessian(const rrv_scene *s, rrv_vec3 origin, double cell, int cells, double reach,
                                   double delta, int count, uint64_t seed)
{
    hessian_error e = {0, 0, 0};
    rrv__rng rng;
    int k, a, b;
    rrv__rng_seed(&rng, seed, 0, 0);
    for (k = 0; k < count; ++k) {
        double H[9], p3[3];
        rrv_vec3 p;
        if (cell > 0) {
            for (a = 0; a < 3; ++a)
                p3[a] = cell * ((int)(rrv__uniform(&rng) * cells) + 0.02 + 0.96 * rrv__uniform(&rng));
            p = rrv__add(origin, rrv__v3(p3[0], p3[1], p3[2]));
        } else {
            rrv_vec3 d;
            do {
                d = rrv__v3(2 * rrv__uniform(&rng) - 1, 2 * rrv__uniform(&rng) - 1,
                            2 * rrv__uniform(&rng) - 1);
            } while (rrv__dot(d, d) > 1.0);
            p = rrv__madd(origin, d, reach);
        }
        scene_hessian(s, p, H);
        for (b = 0; b < 3; ++b) {
            rrv_vec3 eb = rrv__v3(b == 0, b == 1, b == 2);
            rrv_vec3 fd = rrv__scale(rrv__sub(gradient_at(s, rrv__madd(p, eb, delta)),
                                              gradient_at(s, rrv__madd(p, eb, -delta))), 0.5 / delta);
            double col[3];
            col[0] = fd.x; col[1] = fd.y; col[2] = fd.z;
            for (a = 0; a < 3; ++a) {
                double d = fabs(H[3 * a + b] - col[a]);
                if (!(d <= e.diff)) e.diff = d; /* NaN sticks */
                e.scale = fmax(e.scale, fabs(H[3 * a + b]));
                e.asymmetry = fmax(e.asymmetry, fabs(H[3 * a + b] - H[3 * b + a]));
            }
        }
    }
    return e;
}

/* Trilinear (multilinear in a cell) kinds: the differences are exact but
   for rounding, |error| <~ 4 ulp |grad| / delta. With grad ~ |H| x (a cell)
   and delta = 1e-4 cell that is ~1e-11 |H|; 1e-8 leaves room and still
   catches any wrong term (those are O(1) of |H|). */
#define TRILINEAR_TOLERANCE 1e-8
/* Smooth kinds: truncation delta^2 / 6 |d^4 r| ~ (delta / L)^2 |H| for a
   feature scale L, 1e-8 |H| at delta = 1e-4 L, rounding ~1e-12 |H|;
   1e-6 leaves a factor 100. */
#define SMOOTH_TOLERANCE 1e-6

static void expect(const char *name, hessian_error e, double tolerance, int symmetric)
{
    SAY("  %-32s max |H| %.4g, differences off by %.2e relative, asymmetry %.2e relative\n", name, e.scale,
        e.diff / e.scale, e.asymmetry / e.scale);
    CHECKF(e.scale > 0, "%s: the Hessian is zero everywhere tested", name);
    CHECKF(e.diff <= tolerance * e.scale, "%s: |H - differences| %g above %g x max |H| %g", name, e.diff, tolerance,
           e.scale);
    if (symmetric) CHECKF(e.asymmetry <= 1e-12 * e.scale, "%s: asymmetry %g of %g", name, e.asymmetry, e.scale);
}

static void test_ior_grid_trilinear(void)
{
    rrv_scene *s = ior_grid_scene(17, RRV_IOR_INTERP_TRILINEAR);
    double cell = 2.0 / 16;
    CHECK(s->media[0].majorant->refraction.data != NULL); /* the baked path is the one tested */
    expect("IOR grid, trilinear (baked)",
           check_hessian(s, rrv__v3(-1, -1, -1), cell, 16, 0, 1e-4 * cell, 400, 1), TRILINEAR_TOLERANCE, 0);
    CHECK(rrv__solver_supports_scene(s));
    rrv_scene_free(s);
}

/* The blended gradient is not a gradient: its Jacobian's antisymmetric
   part is a discretisation error, first order in the voxel (a forward
   difference across the cell of central differences, read at a point of
   the cell rather than its middle), so refining the grid 2x about halves
   it (1.6x or more is asked). */
static void test_trilinear_asymmetry_is_discretisation(void)
{
    rrv_scene *coarse = ior_grid_scene(17, RRV_IOR_INTERP_TRILINEAR);
    rrv_scene *fine = ior_grid_scene(33, RRV_IOR_INTERP_TRILINEAR);
    hessian_error a = check_hessian(coarse, rrv__v3(-1, -1, -1), 2.0 / 16, 16, 0, 1e-4 * 2.0 / 16, 400, 2);
    hessian_error b = check_hessian(fine, rrv__v3(-1, -1, -1), 2.0 / 32, 32, 0, 1e-4 * 2.0 / 32, 400, 2);
    double ra = a.asymmetry / a.scale, rb = b.asymmetry / b.scale;
    SAY("  trilinear asymmetry relative to max |H|: %.3e at 17^3, %.3e at 33^3 (ratio %.2f)\n", ra, rb, ra / rb);
    CHECKF(ra > 1e-6, "17^3: asymmetry %g: the blend should not be a gradient", ra);
    CHECKF(rb < ra / 1.6, "asymmetry %g at 33^3 against %g at 17^3: not a discretisation error", rb, ra);
    rrv_scene_free(coarse);
    rrv_scene_free(fine);
}

static void test_ior_grid_cubic(void)
{
    rrv_scene *s = ior_grid_scene(17, RRV_IOR_INTERP_CUBIC);
    double cell = 2.0 / 16;
    CHECK(s->media[0].majorant->cubic != NULL);
    expect("IOR grid, cubic B-spline", check_hessian(s, rrv__v3(-1, -1, -1), cell, 16, 0, 1e-4 * cell, 400, 3),
           SMOOTH_TOLERANCE, 1);
    rrv_scene_free(s);
}

static void test_gas_temperature_grid(void)
{
    rrv_scene *s = gas_grid_scene(17);
    double cell = 2.0 / 16;
    CHECK(s->media[0].majorant->refraction.data != NULL);
    expect("gas, temperature grid (baked)",
           check_hessian(s, rrv__v3(-1, -1, -1), cell, 16, 0, 1e-4 * cell, 400, 4), TRILINEAR_TOLERANCE, 0);
    CHECK(rrv__solver_supports_scene(s));
    rrv_scene_free(s);
}

static void test_gas_unbaked_grid(void)
{
    rrv_scene *s = gas_two_grids_scene();
    double cell = 2.0 / 16;
    rrv__rng rng;
    int k, outside = 0;
    /* pressure cells wholly beyond the temperature lattice (x > 0.25) */
    expect("gas, pressure grid (unbaked)",
           check_hessian(s, rrv__v3(0.25, -1, -1), cell, 6, 0, 1e-4 * cell, 400, 5), TRILINEAR_TOLERANCE, 0);
    rrv__rng_seed(&rng, 6, 0, 0);
    for (k = 0; k < 100; ++k) {
        rrv_vec3 p = rrv__v3(0.25 + 0.7 * rrv__uniform(&rng), rrv__uniform(&rng), rrv__uniform(&rng));
        outside += rrv__refraction_grid_at(&s->media[0], p) == NULL;
    }
    CHECKF(outside == 100, "only %d of 100 points beyond the bake", outside);
    rrv_scene_free(s);
}

static void test_gas_noise(void)
{
    rrv_scene *s = gas_noise_scene();
    const rrv_grid *g = &s->media[0].majorant->refraction;
    double cell;
    CHECK(g->data != NULL && g->nx == g->ny && g->nx == g->nz);
    if (!g->data) { rrv_scene_free(s); return; }
    cell = 2.0 / (g->nx - 1);
    expect("gas, noise temperature (baked)",
           check_hessian(s, rrv__v3(-1, -1, -1), cell, g->nx - 1, 0, 1e-4 * cell, 400, 7), TRILINEAR_TOLERANCE, 0);
    CHECK(rrv__solver_supports_scene(s));
    rrv_scene_free(s);
}

static void test_gas_blobs(void)
{
    rrv_scene *s = gas_blob_scene();
    expect("gas, blobs of T and P", check_hessian(s, rrv__v3(0, 0, 0), 0, 0, 0.9, 1e-4 * 0.25, 400, 8),
           SMOOTH_TOLERANCE, 1);
    rrv_scene_free(s);
}

static void test_profiles(void)
{
    static const rrv_field_kind kinds[4] = {RRV_FIELD_BLOBS, RRV_FIELD_LUNEBURG, RRV_FIELD_FISHEYE, RRV_FIELD_SHELL};
    static const char *names[4] = {"IOR blobs", "Luneburg", "fish-eye", "shell"};
    /* inside the profiles' radius (their gradient jumps there); the shell's
       feature scale is its edge, 0.1 */
    static const double reach[4] = {0.9, 0.85, 0.85, 0.95}, scale[4] = {0.2, 0.9, 0.9, 0.1};
    int k;
    for (k = 0; k < 4; ++k) {
        rrv_scene *s = profile_scene(kinds[k]);
        expect(names[k], check_hessian(s, rrv__v3(0.05, -0.02, 0.03), 0, 0, reach[k], 1e-4 * scale[k], 400, 9 + k),
               SMOOTH_TOLERANCE, 1);
        CHECK(rrv__solver_supports_scene(s));
        rrv_scene_free(s);
    }
}

/* The NanoVDB stencil, unbaked (rrv__nv_gradient_jacobian), on the
   temperature grid of scenes/assets/pyro.nvdb: index fractions in [0.02,
   0.98] keep every difference inside its cells. */
static void test_nanovdb_stencil(void)
{
    rrv_nanovdb g;
    rrv_error err;
    rrv__rng rng;
    hessian_error e = {0, 0, 0};
    int k, a, b, tested = 0;
    if (rrv_nanovdb_read("scenes/assets/pyro.nvdb", "temperature", NULL, &g, &err) != RRV_OK) {
        CHECKF(0, "pyro.nvdb: %s", err.message);
        return;
    }
    rrv__rng_seed(&rng, 13, 0, 0);
    for (k = 0; k < 4000 && tested < 400; ++k) {
        double u[3], J[9], delta = 1e-4;
        rrv_vec3 p, pu;
        for (a = 0; a < 3; ++a)
            u[a] = (double)g.data_lo[a] + floor(rrv__uniform(&rng) * (g.data_hi[a] - g.data_lo[a])) + 0.02 +
                   0.96 * rrv__uniform(&rng);
        /* index to world: translation + map u */
        p = rrv__v3(g.translation[0] + g.map[0] * u[0] + g.map[1] * u[1] + g.map[2] * u[2],
                    g.translation[1] + g.map[3] * u[0] + g.map[4] * u[1] + g.map[5] * u[2],
                    g.translation[2] + g.map[6] * u[0] + g.map[7] * u[1] + g.map[8] * u[2]);
        {
            double back[3];
            rrv__nv_to_index(&g, p, back);
            pu = rrv__v3(back[0] - u[0], back[1] - u[1], back[2] - u[2]);
        }
        if (rrv__length(pu) > 1e-9) continue; /* not this map's convention: skip */
        if (rrv__length(rrv__nv_gradient(&g, p)) == 0) continue; /* background */
        ++tested;
        rrv__nv_gradient_jacobian(&g, p, J);
        for (b = 0; b < 3; ++b) {
            double step = delta * sqrt(g.map[b] * g.map[b] + g.map[3 + b] * g.map[3 + b] + g.map[6 + b] * g.map[6 + b]);
            rrv_vec3 eb = rrv__v3(b == 0, b == 1, b == 2);
            rrv_vec3 fd = rrv__scale(rrv__sub(rrv__nv_gradient(&g, rrv__madd(p, eb, step)),
                                              rrv__nv_gradient(&g, rrv__madd(p, eb, -step))), 0.5 / step);
            double col[3];
            col[0] = fd.x; col[1] = fd.y; col[2] = fd.z;
            for (a = 0; a < 3; ++a) {
                double d = fabs(J[3 * a + b] - col[a]);
                if (!(d <= e.diff)) e.diff = d;
                e.scale = fmax(e.scale, fabs(J[3 * a + b]));
                e.asymmetry = fmax(e.asymmetry, fabs(J[3 * a + b] - J[3 * b + a]));
            }
        }
    }
    CHECKF(tested >= 100, "only %d points with a gradient", tested);
    /* an axis-aligned map: world steps along an axis stay in the cells */
    CHECK(g.map[1] == 0 && g.map[2] == 0 && g.map[3] == 0 && g.map[5] == 0 && g.map[6] == 0 && g.map[7] == 0);
    expect("NanoVDB stencil (unbaked)", e, TRILINEAR_TOLERANCE, 0);
    rrv_nanovdb_free(&g);
}

/* ---- the fused lookup against the formulas it replaces ---------------------------- */

/* d/dt_axis of the trilinear blend of one channel of the refraction grid
   at its cell's lower corner d: the sum over the eight corners, each
   weighted by the product of its per-axis weights, the one along the axis
   replaced by its derivative (-1 at the lower corner, +1 at the upper).
   The library computed its Jacobian this way before it shared the blends
   with the value. */
static double corner_sum_slope(const float *d, size_t sy, size_t sz, const double t[3], int axis)
{
    const size_t stride[3] = {4, sy, sz};
    double sum = 0;
    int corner, a;
    for (corner = 0; corner < 8; ++corner) {
        double w = 1;
        size_t at = 0;
        for (a = 0; a < 3; ++a) {
            int upper = (corner >> a) & 1;
            if (a == axis) w *= upper ? 1.0 : -1.0;
            else w *= upper ? t[a] : 1.0 - t[a];
            if (upper) at += stride[a];
        }
        sum += w * (double)d[at];
    }
    return sum;
}

/* Points uniform in the grid's box (its last cells included, where the
   cell index is clamped): the fused lookup's value and gradient equal
   rrv__refraction_lookup's exactly, its Jacobian the corner sums within
   1e-12 of the largest entry at the point (the two orders of the same
   sums differ by a few ulp of the samples, and the samples of these
   smooth grids are within ~10 cells' slope of each other). */
static void check_fused_lookup(const rrv_scene *s, const char *name, uint64_t seed)
{
    const struct rrv__majorant_grid *mg = s->media[0].majorant;
    const rrv_grid *g = &mg->refraction;
    const double scale[3] = {mg->refraction_scale.x, mg->refraction_scale.y, mg->refraction_scale.z};
    double worst = 0;
    int k, a, b, same = 1;
    rrv__rng rng;
    rrv__rng_seed(&rng, seed, 0, 0);
    for (k = 0; k < 2000; ++k) {
        double u0 = rrv__uniform(&rng), u1 = rrv__uniform(&rng), u2 = rrv__uniform(&rng);
        rrv_vec3 p = rrv__v3(g->lo.x + u0 * (g->hi.x - g->lo.x), g->lo.y + u1 * (g->hi.y - g->lo.y),
                             g->lo.z + u2 * (g->hi.z - g->lo.z));
        rrv_vec3 grad, grad_ref;
        double J[9], J2[9], t[3], biggest = 0;
        size_t sy, sz;
        const float *d = rrv__refraction_cell(mg, p, &sy, &sz, t);
        double v = rrv__refraction_lookup_jacobian_fused(mg, p, &grad, J, NULL);
        double v_ref = rrv__refraction_lookup(mg, p, &grad_ref);
        rrv__refraction_lookup_jacobian(mg, p, J2);
        same &= v == v_ref && grad.x == grad_ref.x && grad.y == grad_ref.y && grad.z == grad_ref.z;
        for (a = 0; a < 9; ++a) same &= J[a] == J2[a];
        for (a = 0; a < 9; ++a) biggest = fmax(biggest, fabs(J[a]));
        for (a = 0; a < 3; ++a)
            for (b = 0; b < 3; ++b) {
                double ref = corner_sum_slope(d + 1 + a, sy, sz, t, b) * scale[b];
                worst = fmax(worst, fabs(J[3 * a + b] - ref) / biggest);
            }
    }
    SAY("  %-32s fused Jacobian against the corner sums: %.2e of max |J|\n", name, worst);
    CHECKF(same, "%s: the fused lookup's value, gradient or Jacobian differs from the separate lookups", name);
    CHECKF(worst <= 1e-12, "%s: fused Jacobian off the corner sums by %g of max |J|", name, worst);
}

static void test_fused_lookup_matches_corner_sums(void)
{
    rrv_scene *ior = ior_grid_scene(17, RRV_IOR_INTERP_TRILINEAR), *noise = gas_noise_scene();
    check_fused_lookup(ior, "IOR grid, trilinear", 31);
    check_fused_lookup(noise, "gas, noise temperature", 32);
    rrv_scene_free(ior);
    rrv_scene_free(noise);
}

/* The fused evaluations (rrv__profile_fused, rrv__gas_fused), which camera
   rays and shots take their steps from, give bit for bit what the
   separate functions give: rrv__refractivity's value, the gradient
   composed from rrv__profile_gradient or from the temperature field's
   rrv__field_gradient (grad r = -r grad T / T), and
   rrv__refractivity_hessian's matrix. */
static void test_fused_fields_are_the_parts(void)
{
    rrv_scene *scenes[3];
    static const char *names[3] = {"Luneburg", "fish-eye", "gas, blob temperature"};
    int k, i, a;
    scenes[0] = profile_scene(RRV_FIELD_LUNEBURG);
    scenes[1] = profile_scene(RRV_FIELD_FISHEYE);
    scenes[2] = gas_blob_temperature_scene();
    for (k = 0; k < 3; ++k) {
        const rrv_medium *m = &scenes[k]->media[0];
        double ambient_r = scenes[k]->settings.ambient_ior - 1.0;
        rrv__rng rng;
        int same = 1, fused = 1;
        rrv__rng_seed(&rng, 60 + (uint64_t)k, 0, 0);
        if (m->ior_from_gas) {
            double r0;
            rrv_vec3 g0;
            fused = rrv__gas_fused(m, rrv__v3(0, 0, 0), &r0, &g0, NULL);
        } else {
            double r0;
            rrv_vec3 g0;
            fused = rrv__profile_fused(rrv__field_of(m, RRV__IOR), rrv__v3(0, 0, 0), &r0, &g0, NULL);
        }
        CHECKF(fused, "%s: not taken by the fused evaluation", names[k]);
        for (i = 0; i < 500; ++i) {
            double u0 = rrv__uniform(&rng), u1 = rrv__uniform(&rng), u2 = rrv__uniform(&rng);
            rrv_vec3 p = rrv__v3(2 * u0 - 1, 2 * u1 - 1, 2 * u2 - 1), g, g2, g_ref;
            double H[9], H_ref[9], r = rrv__refractivity_gradient(m, p, ambient_r, &g);
            double r2 = rrv__refractivity_gradient_hessian(m, p, ambient_r, &g2, H, NULL);
            double r_ref = rrv__refractivity(m, p, ambient_r);
            if (m->ior_from_gas) {
                double T = fmax(rrv__temperature(m, p), 1e-3), P = rrv__pressure(m, p);
                rrv_vec3 gT = rrv__scale(rrv__field_gradient(rrv__field_of(m, RRV__TEMPERATURE), p),
                                         m->temperaturescale);
                rrv_vec3 gP = rrv__field_gradient(rrv__field_of(m, RRV__PRESSURE), p);
                g_ref = rrv__scale(rrv__sub(rrv__scale(gP, 1.0 / P), rrv__scale(gT, 1.0 / T)), r_ref);
            } else {
                g_ref = rrv__scale(rrv__profile_gradient(rrv__field_of(m, RRV__IOR), p), m->ior_scale);
            }
            rrv__refractivity_hessian(m, p, ambient_r, H_ref);
            same &= r == r_ref && r2 == r_ref && g.x == g_ref.x && g.y == g_ref.y && g.z == g_ref.z;
            same &= g2.x == g_ref.x && g2.y == g_ref.y && g2.z == g_ref.z;
            for (a = 0; a < 9; ++a) same &= H[a] == H_ref[a];
        }
        CHECKF(same, "%s: the fused evaluation differs from the separate functions", names[k]);
        rrv_scene_free(scenes[k]);
    }
}

/* rrv__eta_gradient_hessian, which the Jacobi steps call, gives exactly
   what rrv__eta_gradient and rrv__refractivity_hessian give, for every kind it
   dispatches on (the fused grid lookup, the cubic spline, an unbaked
   grid, a closed-form profile) and outside the media. */
static void test_eta_gradient_hessian_is_both(void)
{
    rrv_scene *scenes[5];
    static const char *names[5] = {"IOR grid, trilinear", "IOR grid, cubic", "gas, pressure grid (unbaked)",
                                   "gas, noise temperature", "Luneburg"};
    int k, i, a;
    scenes[0] = ior_grid_scene(17, RRV_IOR_INTERP_TRILINEAR);
    scenes[1] = ior_grid_scene(17, RRV_IOR_INTERP_CUBIC);
    scenes[2] = gas_two_grids_scene();
    scenes[3] = gas_noise_scene();
    scenes[4] = profile_scene(RRV_FIELD_LUNEBURG);
    for (k = 0; k < 5; ++k) {
        rrv__rng rng;
        int same = 1, outside = 0;
        rrv__rng_seed(&rng, 40 + (uint64_t)k, 0, 0);
        for (i = 0; i < 500; ++i) {
            /* [-1.2, 1.2]^3: the medium's box [-1, 1]^3 and a margin */
            double u0 = rrv__uniform(&rng), u1 = rrv__uniform(&rng), u2 = rrv__uniform(&rng);
            rrv_vec3 p = rrv__v3(2.4 * u0 - 1.2, 2.4 * u1 - 1.2, 2.4 * u2 - 1.2), g, g_ref;
            double H[9], H_ref[9];
            double eta = rrv__eta_gradient_hessian(scenes[k], p, &g, H, NULL);
            double eta_ref = rrv__eta_gradient(scenes[k], p, &g_ref);
            scene_hessian(scenes[k], p, H_ref);
            outside += !rrv__inside_box(p, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1));
            same &= eta == eta_ref && g.x == g_ref.x && g.y == g_ref.y && g.z == g_ref.z;
            for (a = 0; a < 9; ++a) same &= H[a] == H_ref[a];
        }
        CHECKF(same, "%s: rrv__eta_gradient_hessian differs from rrv__eta_gradient and rrv__refractivity_hessian", names[k]);
        CHECKF(outside > 0, "%s: no point outside the medium", names[k]);
        rrv_scene_free(scenes[k]);
    }
}

/* ---- the solver in grid media --------------------------------------------------- */

static void solver_context(rrv__context *ctx, const rrv_scene *s)
{
    memset(ctx, 0, sizeof *ctx);
    ctx->scene = s;
    ctx->eikonal = ctx->bends = 1;
    ctx->eta_camera2 = 1;
}

/* The Jacobi field that rrv__shoot carries through the discrete steps
   against central differences of the traced endpoint, projected on the
   plane perpendicular to the arriving chord (the part J_perp is). The
   endpoint is piecewise smooth: its derivative jumps where a step's
   evaluation point crosses a cell face (the blended gradient's derivative
   jumps there), so eps = 1e-7 keeps such a crossing between the two
   differenced shots rare and, where it happens, a single step's share. */
static double jacobian_error(rrv_scene *s, rrv_vec3 x0, rrv_vec3 w, rrv_vec3 y, const char *name)
{
    rrv__context ctx;
    rrv__shot base;
    rrv_vec3 e1, e2;
    const double eps = 1e-7;
    double worst = 0;
    int j;
    solver_context(&ctx, s);
    rrv__frame(w, &e1, &e2);
    rrv__shoot(&ctx, x0, w, e1, e2, y, NULL, NULL, NULL, &base);
    CHECKF(base.status == RRV__SHOT_REACHED, "%s: the shot did not reach y's plane", name);
    if (base.status != RRV__SHOT_REACHED) return 1;
    CHECKF(base.curved, "%s: the shot did not pass the medium", name);
    for (j = 0; j < 2; ++j) {
        rrv_vec3 ej = j ? e2 : e1, wp = rrv__normalize(rrv__madd(w, ej, eps)), wm = rrv__normalize(rrv__madd(w, ej, -eps));
        rrv_vec3 t1, t2, fd, an;
        rrv__shot plus, minus;
        double err;
        rrv__frame(wp, &t1, &t2);
        rrv__shoot(&ctx, x0, wp, t1, t2, y, NULL, NULL, NULL, &plus);
        rrv__frame(wm, &t1, &t2);
        rrv__shoot(&ctx, x0, wm, t1, t2, y, NULL, NULL, NULL, &minus);
        fd = rrv__scale(rrv__sub(plus.end, minus.end), 0.5 / eps);
        an = base.de[j];
        fd = rrv__madd(fd, base.dir, -rrv__dot(fd, base.dir));
        an = rrv__madd(an, base.dir, -rrv__dot(an, base.dir));
        err = rrv__length(rrv__sub(fd, an)) / rrv__length(an);
        SAY("  Jacobian %-30s column %d: |J| %.5f, relative difference to central differences %.1e (%ld segments)\n",
            name, j, rrv__length(an), err, base.segments);
        worst = fmax(worst, err);
    }
    return worst;
}

/* Trilinear grids, RK4 and leapfrog, and the cubic B-spline. The steps
   use eta's value too (v = eta d), and the Jacobi field differentiates it
   as grad eta . dx with the blended gradient; in a trilinear grid the
   value's own derivative is the trilinear one, which differs from the blend
   by O(voxel |H|). That leaves the Jacobi field off the discrete map's
   derivative by ~1e-5 relative on these paths (measured 1.6e-5 for the IOR
   grid, 2.5e-7 for the weaker gas, the same at eps = 1e-5 to 1e-8, so not
   the differences' error); the cubic spline, whose value and gradient
   agree, matches to ~1e-9. Bounds: 1e-4 (trilinear), 1e-7 (cubic). What
   the Hessian adds is the change of |J| from the straight |y - x0| =
   1.973: 10 % for the IOR grids (1.777), 0.2 % for the gas (1.978), so the
   bounds see a wrong term down to 1/1000 (IOR) and 1/20 (gas) of it. */
static void test_shoot_jacobian_in_grids(void)
{
    static const rrv_stepper steppers[2] = {RRV_STEPPER_RK4, RRV_STEPPER_LEAPFROG};
    rrv_vec3 w = rrv__normalize(rrv__v3(0.12, 0.05, 1.0));
    int k;
    for (k = 0; k < 2; ++k) {
        rrv_scene *a = ior_grid_scene(17, RRV_IOR_INTERP_TRILINEAR), *b = gas_grid_scene(17);
        rrv_scene *c = ior_grid_scene(17, RRV_IOR_INTERP_CUBIC);
        double ea, eb, ec;
        a->settings.stepper = b->settings.stepper = c->settings.stepper = steppers[k];
        ea = jacobian_error(a, rrv__v3(0.05, -0.1, -0.95), w, rrv__v3(0.4, 0.3, 0.95), k ? "IOR grid, leapfrog" : "IOR grid, RK4");
        eb = jacobian_error(b, rrv__v3(0.05, -0.1, -0.95), w, rrv__v3(0.4, 0.3, 0.95), k ? "gas grid, leapfrog" : "gas grid, RK4");
        ec = jacobian_error(c, rrv__v3(0.05, -0.1, -0.95), w, rrv__v3(0.4, 0.3, 0.95), k ? "cubic, leapfrog" : "cubic, RK4");
        CHECKF(ea < 1e-4 && eb < 1e-4 && ec < 1e-7, "stepper %d: relative errors %g %g %g", k, ea, eb, ec);
        rrv_scene_free(a);
        rrv_scene_free(b);
        rrv_scene_free(c);
    }
}

/* A shot across sharp interfaces: a box whose IOR is a linear slab
   (r = 0.1 + 0.3 x, so eta at its faces is 1.1 +- 0.15 against the
   ambient 1, and the jump varies along the faces), entered at its -z face
   and left at its +z face. The field is linear, so RK4's steps are exact
   but for rounding and the endpoint is smooth in w: the Jacobi field,
   carried across both faces by rrv__shot_refracts, matches central
   differences to 1e-6 relative (measured 1.7e-9). Leaving the
   refraction's Jacobian out (the directions' field unchanged across a
   face) is off by 4.8e-2, and leaving out the change of the IOR ratio
   along the face (dmu) by 3.1e-2. */
static const char sharp_slab_text[] =
    "camera eye 0 0 -3  look 0 0 0  up 0 1 0  fov 40  resolution 8 8\n"
    "render step 0.05\n"
    "medium s box -0.5 -0.5 -0.5 0.5 0.5 0.5  sigma_a 0 0 0  sigma_s 0 0 0\n"
    "ior s slab normal 1 0 0 base 0.1 gradient 0.3 center 0 0 0\n";

static void test_shoot_jacobian_across_sharp_faces(void)
{
    rrv_scene *s = NULL;
    rrv_error err;
    double jump[7], e;
    if (rrv_scene_parse(sharp_slab_text, sizeof sharp_slab_text - 1, "sharp slab", NULL, NULL, &s, &err) != RRV_OK) {
        CHECKF(0, "sharp slab: %s", err.message);
        return;
    }
    CHECK(rrv_medium_face_jumps(s, 0, jump) > 0.05);
    e = jacobian_error(s, rrv__v3(0.05, -0.1, -0.95), rrv__normalize(rrv__v3(0.12, 0.05, 1.0)), rrv__v3(0.4, 0.3, 0.95),
                       "sharp slab, RK4");
    CHECKF(e < 1e-6, "across sharp faces: relative error %g", e);
    rrv_scene_free(s);
}

/* Newton's method on the two angles finds a connection through a grid
   medium: the shot from the root ends at y, and its density agrees with
   the finite-difference Jacobian of the endpoint. */
static void test_solve_through_grid(void)
{
    rrv_scene *s = gas_grid_scene(17);
    rrv__context ctx;
    rrv__rng rng;
    rrv_vec3 x0 = rrv__v3(-0.1, 0.2, -0.95), y = rrv__v3(0.3, -0.2, 0.95);
    int k, found = 0;
    solver_context(&ctx, s);
    rrv__rng_seed(&rng, 21, 0, 0);
    for (k = 0; k < 10; ++k) {
        rrv__root root;
        rrv__shot shot;
        rrv_vec3 e1, e2;
        if (!rrv__solve_shot(&ctx, x0, y, NULL, rrv__solver_seed(x0, y, &rng), NULL, &root)) continue;
        ++found;
        rrv__frame(root.w0, &e1, &e2);
        rrv__shoot(&ctx, x0, root.w0, e1, e2, y, NULL, NULL, NULL, &shot);
        SAY("  solve through the gas grid: %d iterations, endpoint off by %.1e, bent by %.2e rad from the chord\n",
            root.iterations, rrv__length(rrv__sub(shot.end, y)),
            acos(fmin(1.0, rrv__dot(root.w0, rrv__normalize(rrv__sub(y, x0))))));
        /* the solver's tolerance: residual < 1e-9 (1 + |y - x0|) */
        CHECKF(rrv__length(rrv__sub(shot.end, y)) < 1e-8, "root %d ends %g from y", k,
               rrv__length(rrv__sub(shot.end, y)));
        CHECK(root.curved && root.det > 0 && root.det == root.det);
    }
    CHECKF(found >= 8, "only %d of 10 seeds converged", found);
    rrv_scene_free(s);
}

/* A gas grid as gas_grid_scene's with an absorbing density grid in it,
   so that ratio tracking along a connection draws random numbers. */
static rrv_scene *gas_grid_dense_scene(void)
{
    rrv_scene *s = empty_scene();
    int m = add_medium(s, 1, 40.0);
    rrv_field t, d;
    fill_grid(&t, 17, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 300.0, 500.0);
    fill_grid(&d, 9, rrv__v3(-1, -1, -1), rrv__v3(1, 1, 1), 1.0, 1.0);
    set_field(s, m, RRV_MEDIUM_TEMPERATURE, &t);
    set_field(s, m, RRV_MEDIUM_DENSITY, &d);
    s->media[m].sigma_a[0] = s->media[m].sigma_a[1] = s->media[m].sigma_a[2] = 0.7;
    s->settings.ambient_ior = 1.0 + 40.0 * 2.92e-4;
    prepare(s);
    return s;
}

/* What curved NEE saves on a connection changes no number: a solve whose
   polish is the memo's (a repeated trial) returns exactly what the same
   solve computes without the memo, and the transmittance tracked along
   the chords the root's last shot kept is exactly that of tracing the
   root again with the same random numbers. Connections from x0 to points
   y on a plane facing it, through a gas grid with density. */
static void test_memo_and_kept_chords_change_nothing(void)
{
    rrv_scene *s = gas_grid_dense_scene();
    rrv__context ctx;
    rrv__rng rng;
    rrv_vec3 x0 = rrv__v3(-0.1, 0.2, -0.95), down = rrv__v3(0, 0, -1);
    static rrv__chords kept;
    int k, hits = 0, connections = 0, tracked = 0;
    solver_context(&ctx, s);
    rrv__rng_seed(&rng, 51, 0, 0);
    for (k = 0; k < 20; ++k) {
        rrv_vec3 y = rrv__v3(0.6 * rrv__uniform(&rng) - 0.3, 0.6 * rrv__uniform(&rng) - 0.3, 0.95), e1, e2;
        rrv__polish_memo memo;
        rrv__root root, with_memo, without;
        rrv__rng at_trial, copy;
        rrv__shot shot;
        double T[3], T_again[3];
        int found, found_memo, found_plain;
        memo.valid = 0;
        found = rrv__solve_shot_seeded(&ctx, x0, y, &down, &rng, &memo, &kept, &root);
        if (!found) continue;
        ++connections;
        /* the root's transmittance, kept chords against a retrace */
        copy = rng;
        if (kept.n > 0) {
            int open = rrv__kept_transmittance(&ctx, &kept, &rng, T);
            rrv__frame(root.w0, &e1, &e2);
            rrv__shoot(&ctx, x0, root.w0, e1, e2, y, &down, &copy, T_again, &shot);
            CHECKF(open == (shot.status == RRV__SHOT_REACHED), "connection %d: kept chords open %d, retrace status %d",
                   k, open, shot.status);
            CHECKF(T[0] == T_again[0] && T[1] == T_again[1] && T[2] == T_again[2],
                   "connection %d: T %.17g along the kept chords, %.17g retraced", k, T[0], T_again[0]);
            CHECKF(rrv__uniform(&rng) == rrv__uniform(&copy), "connection %d: different random numbers used", k);
            tracked += T[0] < 1; /* some null collision happened */
        }
        /* a repeated trial, with and without the memo, from the same state */
        at_trial = rng;
        found_memo = rrv__solve_shot_seeded(&ctx, x0, y, &down, &rng, &memo, NULL, &with_memo);
        found_plain = rrv__solve_shot_seeded(&ctx, x0, y, &down, &at_trial, NULL, NULL, &without);
        CHECKF(found_memo == found_plain, "connection %d: found %d with the memo, %d without", k, found_memo,
               found_plain);
        if (found_memo && found_plain) {
            CHECKF(with_memo.w0.x == without.w0.x && with_memo.w0.y == without.w0.y && with_memo.w0.z == without.w0.z &&
                       with_memo.det == without.det,
                   "connection %d: the memo's root differs from the one computed", k);
            hits += with_memo.iterations < without.iterations;
        }
    }
    SAY("  memo: %d of %d repeated trials reused the polish; %d transmittances below 1\n", hits,
        connections, tracked);
    CHECKF(connections >= 15, "only %d of 20 connections solved", connections);
    CHECKF(hits >= connections - 2, "only %d of %d repeated trials reused the polish", hits, connections);
    CHECKF(tracked >= connections / 2, "only %d of %d transmittances below 1: the density is not tested", tracked,
           connections);
    rrv_scene_free(s);
}

int main(void)
{
    say_from_env("HESSIAN_VERBOSE");
    (void)tb_shape; /* the shared builder's; unused here */
    (void)tb_medium;
    RUN(test_ior_grid_trilinear);
    RUN(test_trilinear_asymmetry_is_discretisation);
    RUN(test_ior_grid_cubic);
    RUN(test_gas_temperature_grid);
    RUN(test_gas_unbaked_grid);
    RUN(test_gas_noise);
    RUN(test_gas_blobs);
    RUN(test_profiles);
    RUN(test_nanovdb_stencil);
    RUN(test_fused_lookup_matches_corner_sums);
    RUN(test_fused_fields_are_the_parts);
    RUN(test_eta_gradient_hessian_is_both);
    RUN(test_shoot_jacobian_in_grids);
    RUN(test_shoot_jacobian_across_sharp_faces);
    RUN(test_solve_through_grid);
    RUN(test_memo_and_kept_chords_change_nothing);
    return CHECK_EXIT_CODE();
}
