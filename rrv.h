/* rrv.h 0.20.0 - refractive volume renderer, a single-file C99 library.

   rrv renders participating media whose index of refraction varies in space
   (heat haze, shock fronts, the caustics of hot air) with refractive
   null-scattering: delta tracking in which every null collision refracts the
   ray (Fraboni, Chan, Vergne, Jeziorski, "Can You See the Heat?", SIGGRAPH
   2023 talk), next to a classic null-scattering volume path tracer
   (Miller et al. 2019) and an eikonal ray-marching reference (Ament et al. 2014).

   It does: media in boxes (density, temperature, pressure and IOR from
   constants, blobs, noise, gridvol and NanoVDB grids, the gas law), diffuse
   and checker spheres, quads and meshes, quad, triangle and sphere lights,
   a sky, blackbody flames, RGB, tiles and sample ranges that merge bit for
   bit. It does not: dispersion, glossy or specular surfaces, textures,
   motion, GPUs. The CLI (main.c) and the user's manual: README.md.

   EXAMPLE: a Luneburg lens built in code, rendered, written as PFM (make
   test cuts out the lines between the rulers, builds them as C99 and C++
   and runs them).
   ---- example ---------------------------------------------------------------
    #define RRV_IMPLEMENTATION
    #include "rrv.h"
    #include <stdio.h>
    #include <stdlib.h>
    #include <string.h>

    int main(void)
    {
        rrv_scene *scene = NULL;
        rrv_camera camera;
        rrv_settings settings;
        rrv_environment sky;
        rrv_medium lens;
        rrv_field ior;
        rrv_error err;
        float *sum = NULL;
        int w = 64, h = 48, spp = 4, lens_index, i;
        memset(&camera, 0, sizeof camera);       // zero means default
        memset(&settings, 0, sizeof settings);
        memset(&sky, 0, sizeof sky);
        memset(&lens, 0, sizeof lens);
        memset(&ior, 0, sizeof ior);
        camera.eye.z = 4;                        // looking at the origin
        camera.width = w, camera.height = h;
        settings.integrator = RRV_INTEGRATOR_REFRACTIVE;
        settings.spp = spp;
        sky.kind = RRV_ENV_GRADIENT;             // white above, black below
        sky.L[0] = sky.L[1] = sky.L[2] = 1;
        strcpy(lens.name, "lens");               // a box with no density
        lens.lo.x = lens.lo.y = lens.lo.z = -1;
        lens.hi.x = lens.hi.y = lens.hi.z = 1;
        ior.kind = RRV_FIELD_LUNEBURG;           // centred in the box
        ior.radius = 1;
        if (rrv_scene_create(&scene, &err) != RRV_OK ||
            rrv_scene_set_camera(scene, &camera, &err) != RRV_OK ||
            rrv_scene_set_settings(scene, &settings, &err) != RRV_OK ||
            rrv_scene_set_environment(scene, &sky, &err) != RRV_OK ||
            rrv_scene_add_medium(scene, &lens, &lens_index, &err) != RRV_OK ||
            rrv_scene_set_field(scene, lens_index, RRV_MEDIUM_IOR, &ior, &err) != RRV_OK ||
            rrv_scene_prepare(scene, &err) != RRV_OK)
            goto fail;
        sum = (float *)calloc((size_t)w * h * 3, sizeof *sum);
        if (!sum) goto fail;
        if (rrv_render_rect(scene, 0, 0, w, h, 0, spp, sum, w, NULL, &err) != RRV_OK)
            goto fail;
        for (i = 0; i < w * h * 3; ++i) sum[i] /= spp;
        if (rrv_write_pfm("lens.pfm", sum, w, h, &err) != RRV_OK) goto fail;
        free(sum);
        rrv_scene_free(scene);
        return 0;
    fail:
        fprintf(stderr, "%s:%d: %s\n", err.file, err.line, err.message);
        free(sum);
        rrv_scene_free(scene);
        return 1;
    }
   ---- end of example --------------------------------------------------------

   INTEGRATORS (rrv_settings.integrator; zero, the default, is chosen from
   the prepared scene by rrv_scene_integrator; the rule and why: NOTES)
     default     classic where no medium's IOR differs from the ambient IOR
                 (bit for bit); eikonal where the refracting media are clear
                 and a light is small seen from them (NOTES); else refractive.
     classic     IOR 1 everywhere: delta tracking, ratio-tracked NEE with
                 MIS, spectral MIS for chromatic media. The production baseline.
     refractive  the same, rays bent inside media that carry an IOR; scheme
                 rrv_settings.refraction: COMB (default: leapfrog kicks at
                 spaced points, second order) or POISSON (the paper's Snell
                 at every null event, first order).
     eikonal     d/ds(eta dx/ds) = grad eta marched by RK4, steps of
                 rrv_settings.step or, none given, placed by the field.
   NEXT-EVENT ESTIMATION (rrv_settings.nee; refractive and eikonal only:
   classic's straight shadow rays are exact for straight rays)
     DEFAULT (rrv_scene_nee) on eikonal MANIFOLD through clear weak gas, else
     SHOOT; AIM on refractive. STRAIGHT: straight shadow rays, biased across
     refracting media. NONE: lights only where paths hit them (unbiased).
     SHOOT: Newton on the first direction till the bent ray lands on the
     light. MANIFOLD: the paper's refractive ratio tracking, comb vertices
     solved by a dogleg or Levenberg-Marquardt (manifold_solver). AIM: bent
     shadow rays aimed at a light point (unbiased, no focusing). How each
     works, its MIS weights and its exact 1/p: NOTES at the end of this file.
   ALSO (rules and limits in NOTES): media's faces are sharp interfaces
   (Snell, Fresnel); without an `ambient ior` the air around a gas medium
   is that gas at its ambient state, so a plume whose faces are at it has
   no jump; a jump that remains is reported (rrv_medium_face_jumps); IOR
   grids are trilinear or tricubic (ior_interpolation); emissive media are
   lights where they are the only ones (emission_nee); shadow rays'
   transmittance is `ratio`, `residual` or `march` (all unbiased); runaway
   paths are cut and counted (rrv_render_stats.paths_cut); adaptive sampling
   (noise_threshold, rrv_render_rect_adaptive; its stop biases) is off.

   READING MAP (the paper's terms and their functions; `grep -n '/\* >>'
   rrv.h` lists the sections: a ray's life, building scenes, the modules)
     refractive delta tracking, the paper's Algorithm 1 (Snell at every null
       collision): rrv__refractive_delta_tracking, rrv__bend_at_null_event,
       rrv__refract_at_null_event (scheme POISSON)
     the comb: rrv__comb_step, rrv__comb_kick, rrv__comb_spacing
     Hauf-Grigull (a gas's IOR from T and P): rrv__refractivity, rrv__gas_fused
     refractive ratio tracking (nee MANIFOLD): rrv__manifold_nee; its solves
       rrv__manifold_dogleg, rrv__manifold_solve (LM) on the rrv__chain_*
     curved NEE by shooting and aiming: rrv__shoot_nee,
       rrv__solve_shot_seeded; rrv__aim_nee, rrv__cone_nee
     the eikonal reference (Ament et al.): rrv__eikonal_step,
       rrv__eikonal_step_controlled, rrv__eikonal_plan
     shadow rays: rrv__ratio_tracking_transmittance (rrv__transmittance);
       the path tracer: rrv__trace_path; a rectangle: rrv_render_rect

   USAGE
     #define RRV_IMPLEMENTATION before #include "rrv.h" in exactly one C or
     C++ file, elsewhere just #include "rrv.h". Load a scene (rrv_scene_load)
     or build one (above); rrv_render_rect adds the radiance sums of any
     rectangle and sample range into the caller's buffer, so tiles over
     threads or machines add up to one call's image bit for bit.

   FUNCTIONS (every public one; each that can fail returns rrv_result)
     rrv_scene_load, rrv_scene_parse  parse and prepare a scene file or text
     rrv_scene_prepare      build BVH, lights, majorant and baked grids (again after edits)
     rrv_scene_create, rrv_scene_free  an empty scene to build in code; free one
     rrv_scene_set_camera, rrv_scene_set_settings, rrv_scene_set_environment  check, set
     rrv_scene_add_material check and add a material
     rrv_scene_add_shape, rrv_scene_add_triangles  check and add a sphere, quad,
                            triangle or indexed mesh (a light if L > 0)
     rrv_scene_add_medium   check and add a medium's box and coefficients
     rrv_scene_set_field    check and set a medium's density, temperature, pressure or IOR
     rrv_medium_channel_groups which of a medium's channels share a free-flight majorant
     rrv_medium_face_jumps  a prepared medium's IOR jump at each face
     rrv_scene_integrator, rrv_scene_nee  what a prepared scene renders with
     rrv_render_rect        add the radiance sums of a pixel rectangle and sample range
     rrv_render_rect_adaptive the same, each pixel's samples until its error is below a threshold
     rrv_trace_ray          walk one ray through the refractive media
     rrv_grid_read, rrv_grid_read_memory  read and validate a gridvol file
     rrv_nanovdb_read, rrv_nanovdb_read_memory  read a NanoVDB grid by name
     rrv_nanovdb_voxel, rrv_nanovdb_sample  a value at an index / world point
     rrv_nanovdb_cell_centered  move a grid's values to cell centres (Blender's)
     rrv_nanovdb_type_name, rrv_nanovdb_free  a grid type's name; free a read
     rrv_write_pfm, rrv_write_exr, rrv_write_png  write PFM, OpenEXR (half or
                            float, ZIP or none), an 8-bit sRGB PNG preview
     rrv_write_pfm_to, rrv_write_exr_to, rrv_write_png_to  the same to a callback
     rrv_read_pfm, rrv_read_pfm_memory  read a PFM file
     rrv_read_exr, rrv_read_exr_memory  read a scanline RGB OpenEXR file
     rrv_open_read          open a file as every reader does (regular files only)
     rrv_exr_find_attribute an OpenEXR header attribute by name (rrv's parts)
     rrv_half_from_float    the IEEE half nearest a float (finite values clamped)
     rrv_crc32, rrv_adler32 the checksums the PNG and EXR writers use
     rrv_result_string, rrv_free  a result code's name; free what the library gave

   CONFIGURATION (define before including the implementation)
     RRV_MALLOC(sz) RRV_REALLOC(p,sz) RRV_FREE(p)   all three or none
     RRV_ASSERT(x)    defaults to assert(x)
     RRV_STATIC       make every public function static to the including file
     RRV_NO_STDIO     no FILE* I/O: load through rrv_load_options.read_file,
                      write through the callback writers
     RRV_NO_POSIX     plain fopen only (a FIFO given as input then blocks)
     RRV_RESEARCH     keep the variants no measurement favours (NOTES)
   Parts a build can leave out, in any combination; a call that needs one
   refuses, naming the switch (NOTES; sizes: RESULTS.md, "Build switches"):
     RRV_NO_SCENE_FILE no .rrv parser, OBJ loader or gridvol reader
     RRV_NO_NANOVDB   no NanoVDB reader
     RRV_NO_EXR       no OpenEXR writer or reader
     RRV_NO_PNG       no PNG writer
     RRV_NO_CURVED_NEE no solvers of nee shoot and manifold (the defaults aim)

   CONVENTIONS (the contract between scene files, the library and tests)
     Units: metres, kelvin, pascal; extinction in 1/m; linear RGB; the IOR
       is achromatic. Every input file is untrusted, read with bounds, and
       writers replace their target through a temporary file (NOTES).
     Grids: gridvol (Mitsuba 0.6's) and NanoVDB 32.x; NanoVDB values sit at
       OpenVDB's map * ijk + translation (`cellcentered on` takes Blender's
       map * (ijk + 0.5)).
     Gas IOR (Hauf-Grigull; Gladstone-Dale for an ideal gas): eta - 1 =
       (eta_ref - 1) (P / P_ref) (T_ref / T), defaults eta_ref = 1.000292,
       P_ref = 101325 Pa, T_ref = 300 K; its gradient is (eta - 1)(grad P / P
       - grad T / T); the artist scale k makes it 1 + k (eta - 1).
     Precision: air's eta - 1 is ~3e-4, about 2000 float ulps of 1, so rays
       carry the refractivity r = eta - 1 in double, and IOR ratios are
       formed as 1 + (r_i - r_o) / (1 + r_o).
     Radiance: L / eta^2 is invariant along a ray, so a path from an emitter
       at eta_e to the camera at eta_c scales by (eta_c / eta_e)^2; thermal
       emission is n^2 B (Kirchhoff), so a fire does not dim on leaving.
*/
#ifndef RRV_H_INCLUDED
#define RRV_H_INCLUDED

#include <stddef.h>
#include <stdint.h>
#ifndef RRV_NO_STDIO
#include <stdio.h> /* FILE, for rrv_open_read */
#endif

#define RRV_VERSION_MAJOR 0
#define RRV_VERSION_MINOR 20
#define RRV_VERSION_PATCH 0

#ifndef RRV_DEF
#ifdef RRV_STATIC
#if defined(__GNUC__) || defined(__clang__)
/* a static library copy need not use every function */
#define RRV_DEF static __attribute__((unused))
#else
#define RRV_DEF static
#endif
#else
#define RRV_DEF extern
#endif
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ---- results and errors ------------------------------------------------- */

#define RRV_RESULT_LIST(X)                                              \
    X(RRV_OK, "ok")                                                     \
    X(RRV_ERROR_ARGUMENT, "invalid argument")                           \
    X(RRV_ERROR_MEMORY, "out of memory")                                \
    X(RRV_ERROR_IO, "input/output error")                               \
    X(RRV_ERROR_PARSE, "malformed scene")                               \
    X(RRV_ERROR_FORMAT, "malformed file")                               \
    X(RRV_ERROR_LIMIT, "size limit exceeded")                           \
    X(RRV_ERROR_UNSUPPORTED, "not supported in this build")

typedef enum rrv_result {
#define RRV__ENUM(name, text) name,
    RRV_RESULT_LIST(RRV__ENUM)
#undef RRV__ENUM
    RRV_RESULT_COUNT
} rrv_result;

/* Filled by every fallible call. `file` names the file at fault (the scene,
   a grid, an OBJ, an image), `line` its 1-based line or 0 when lines do not
   apply; `message` says what is wrong without repeating file and line, so a
   caller prints "file:line: message". */
typedef struct rrv_error {
    rrv_result code;
    int line;
    char file[256];
    char message[256];
} rrv_error;

/* A static string for a result code; never NULL. */
RRV_DEF const char *rrv_result_string(rrv_result r);

/* Frees memory the library handed out (images from rrv_read_pfm). NULL is ok. */
RRV_DEF void rrv_free(void *p);

/* ---- math types --------------------------------------------------------- */

typedef struct rrv_vec3 { double x, y, z; } rrv_vec3;

/* ---- scalar fields -------------------------------------------------------
   A field is a scalar function of position inside a medium's box. Outside the
   box every field takes its ambient value (see rrv_medium). Density, gas
   temperature, gas pressure and IOR are all fields of these kinds. */

typedef enum rrv_field_kind {
    RRV_FIELD_NONE = 0, /* absent: the ambient value everywhere */
    RRV_FIELD_CONSTANT, /* value */
    RRV_FIELD_BLOBS,    /* base + sum_i weight_i exp(-|x-c_i|^2 / (2 radius_i^2)) */
    RRV_FIELD_NOISE,    /* base + amplitude * falloff(x) * fbm(x), fbm in [0,1] */
    RRV_FIELD_GRID,     /* trilinear in a gridvol file, corner-placed samples */
    /* IOR profiles; value is the IOR eta itself (rrv works with eta - 1 inside) */
    RRV_FIELD_LUNEBURG, /* eta = sqrt(2 - (r/R)^2) for r < R, 1 outside      */
    RRV_FIELD_FISHEYE,  /* eta = n0 / (1 + (r/R)^2) for r < R, n0/2 outside  */
    RRV_FIELD_SLAB,     /* eta - 1 = base + gradient * dot(x - center, normal) */
    RRV_FIELD_SHELL,    /* eta - 1 = base + amplitude * tanh-edged shell       */
    RRV_FIELD_NANOVDB   /* trilinear in a NanoVDB grid, values at index points */
} rrv_field_kind;

typedef struct rrv_blob {
    rrv_vec3 center; /* m */
    double radius;   /* standard deviation of the Gaussian, m, > 0 */
    double weight;   /* peak value added at the centre */
} rrv_blob;

/* The falloff that shapes fractal noise into a puff of smoke. */
typedef enum rrv_falloff_kind {
    RRV_FALLOFF_NONE = 0, /* 1 everywhere */
    RRV_FALLOFF_SPHERE,   /* 1 at center, smoothly 0 at radius */
    RRV_FALLOFF_PLUME     /* a rising column: sphere stretched along +y, widening upward */
} rrv_falloff_kind;

typedef struct rrv_noise {
    int octaves;        /* 1..12 */
    double frequency;   /* of the first octave, 1/m */
    double lacunarity;  /* frequency ratio between octaves */
    double gain;        /* amplitude ratio between octaves */
    double threshold;   /* fbm below this is 0; the rest rescaled to [0,1] */
    uint32_t seed;
    rrv_falloff_kind falloff;
    rrv_vec3 center;    /* of the falloff */
    double radius;      /* of the falloff, m */
} rrv_noise;

/* A regular grid as read from a gridvol file (corner-placed samples). */
typedef struct rrv_grid {
    int nx, ny, nz, channels; /* each >= 2; channels 1 or 3 */
    rrv_vec3 lo, hi;          /* the box the corner samples span */
    float *data;              /* ((z*ny + y)*nx + x)*channels + c, owned */
} rrv_grid;

/* One grid of a NanoVDB file (.nvdb, as nanovdb_convert writes it), kept
   as the file stores it and looked up in its tree (root tiles, 32^3 upper,
   16^3 lower and 8^3 leaf nodes), never densified: memory is the grid's
   size in the file. Values sit at integer index points; the map takes index
   ijk to world map * ijk + translation, and the field is trilinear between
   the eight index points around a position (gridvol instead puts its first
   and last samples on the faces of its box; Mitsuba 3 and pbrt put grid
   values at cell centres, i.e. at index points of a map shifted by half a
   voxel, which NanoVDB files do not need since their map is explicit).
   Everywhere without data the value is the grid's background. */
typedef enum rrv_nanovdb_type {
    RRV_NANOVDB_FLOAT = 1, /* NanoVDB's GridType codes */
    RRV_NANOVDB_FP4 = 13,
    RRV_NANOVDB_FP8 = 14,
    RRV_NANOVDB_FP16 = 15,
    RRV_NANOVDB_FPN = 16
} rrv_nanovdb_type;

typedef struct rrv_nanovdb {
    unsigned char *buffer;    /* the grid's bytes, owned; validated on reading */
    size_t size;
    char name[256];
    rrv_nanovdb_type type;
    double map[9], inverse[9], translation[3]; /* row-major 3x3 */
    int64_t data_lo[3], data_hi[3]; /* index box of every stored non-background value
                                   (leaf granularity); lo > hi: none */
    int64_t active_lo[3], active_hi[3]; /* the active voxels' index box, as the file says */
    rrv_vec3 lo, hi;          /* world box outside which the field is the background */
    double background, value_min, value_max; /* over every value stored */
    uint64_t active_voxels;
    uint32_t node_count[3];   /* leaf, lower, upper nodes */
    uint32_t root_tiles;
    size_t root;              /* offset of the root node in buffer */
} rrv_nanovdb;

typedef struct rrv_field {
    rrv_field_kind kind;
    double value;      /* CONSTANT */
    double base;       /* BLOBS, NOISE, SLAB, SHELL: added everywhere inside */
    double amplitude;  /* NOISE, SHELL */
    rrv_blob *blobs;   /* BLOBS, owned */
    int blob_count;
    rrv_noise noise;   /* NOISE */
    rrv_grid grid;     /* GRID */
    rrv_nanovdb nanovdb; /* NANOVDB */
    rrv_vec3 center;   /* LUNEBURG, FISHEYE, SLAB, SHELL */
    rrv_vec3 normal;   /* SLAB, unit */
    double radius;     /* LUNEBURG, FISHEYE, SHELL (outer radius), m */
    double thickness;  /* SHELL, m */
    double edge;       /* SHELL: tanh edge width, m */
    double gradient;   /* SLAB: d(eta)/ds along normal, 1/m */
    double n0;         /* FISHEYE: IOR at the centre */
} rrv_field;

/* ---- scene description --------------------------------------------------- */

typedef enum rrv_material_kind { RRV_MATERIAL_DIFFUSE = 0, RRV_MATERIAL_CHECKER } rrv_material_kind;

typedef struct rrv_material {
    char name[64];
    rrv_material_kind kind;
    double albedo[3];   /* DIFFUSE, or the first checker colour; each in [0,1] */
    double albedo2[3];  /* CHECKER second colour */
    double checker_scale; /* CHECKER: size of one square, m */
} rrv_material;

typedef enum rrv_shape_kind { RRV_SHAPE_SPHERE = 0, RRV_SHAPE_QUAD, RRV_SHAPE_TRIANGLE } rrv_shape_kind;

typedef struct rrv_shape {
    rrv_shape_kind kind;
    int material;       /* index into scene->materials */
    double L[3];        /* emitted radiance (already times its scale); zero: not a light */
    rrv_vec3 p0, e1, e2;/* QUAD: corner and edges; TRIANGLE: p0, p1 - p0, p2 - p0.
                           Lights emit on the side of cross(e1, e2) */
    rrv_vec3 center;    /* SPHERE (emits outward) */
    double radius;
} rrv_shape;

typedef enum rrv_environment_kind {
    RRV_ENV_NONE = 0, RRV_ENV_CONSTANT, RRV_ENV_GRADIENT
} rrv_environment_kind;

typedef struct rrv_environment {
    rrv_environment_kind kind;
    double L[3];      /* CONSTANT radiance, or GRADIENT at +y (already scaled) */
    double L2[3];     /* GRADIENT radiance at -y, blended linearly in direction.y */
} rrv_environment;

typedef struct rrv_camera {
    rrv_vec3 eye, look, up;
    double fov;       /* vertical field of view, degrees, (0,180) */
    int width, height;
} rrv_camera;

typedef enum rrv_integrator {
    RRV_INTEGRATOR_DEFAULT = 0, /* chosen from the scene (rrv_scene_integrator):
                                   CLASSIC where nothing refracts, else
                                   REFRACTIVE or EIKONAL by the rule in the
                                   manual (INTEGRATORS, "default") */
    RRV_INTEGRATOR_CLASSIC,     /* IOR 1 everywhere: the production baseline */
    RRV_INTEGRATOR_REFRACTIVE,  /* refractive delta tracking */
    RRV_INTEGRATOR_EIKONAL      /* ray-equation marching: the accuracy reference */
} rrv_integrator;

/* How the eikonal integrator steps the ray equation. */
typedef enum rrv_stepper {
    RRV_STEPPER_DEFAULT = 0, /* the stepper measured best at equal cost: RK4 */
    RRV_STEPPER_LEAPFROG,    /* kick-drift-kick (Pediredla et al. 2020) in the
                                optical-path parameter: symplectic, second order;
                                RRV_RESEARCH builds only */
    RRV_STEPPER_RK4          /* classic fourth-order Runge-Kutta on (x, eta dx/ds) */
} rrv_stepper;

/* Where the refractive integrator refracts, and with which normal and ratio. */
typedef enum rrv_refraction_scheme {
    RRV_REFRACTION_DEFAULT = 0, /* the scheme measured best: COMB */
    RRV_REFRACTION_POISSON,     /* the seed paper: at every null event, normal there */
    RRV_REFRACTION_MIDPOINT,    /* at every null event, normal at the chord midpoint;
                                   RRV_RESEARCH builds only */
    RRV_REFRACTION_COMB         /* at regularly spaced points (one random offset a
                                   segment), leapfrog kick d(eta d) = grad eta h */
} rrv_refraction_scheme;

/* How a refractivity that comes from a grid is interpolated for refraction. */
typedef enum rrv_ior_interpolation {
    RRV_IOR_INTERP_TRILINEAR = 0, /* r trilinear, grad r the trilinear blend of
                                     central differences at the samples: C0, so
                                     on grids the comb and RK4 lose order */
    RRV_IOR_INTERP_CUBIC          /* interpolating tricubic B-spline, value and
                                     gradient from one C2 function */
} rrv_ior_interpolation;

/* Next-event estimation (light sampling) in the refractive and eikonal
   integrators; the classic integrator always uses straight NEE, which is
   exact there (its rays are straight). */
typedef enum rrv_nee {
    RRV_NEE_DEFAULT = 0, /* SHOOT (with the refractive integrator, which
                            cannot solve, it aims: AIM) */
    RRV_NEE_NONE,        /* no light sampling: lights, emitters and the sky
                            count only where a (bent) path hits them, MIS
                            weight 1. Unbiased; the reference. */
    RRV_NEE_STRAIGHT,    /* straight shadow rays, MIS against phase/BSDF
                            sampling as if both sampled the same path: biased
                            wherever a connection or the sampled continuation
                            crosses a refracting medium */
    RRV_NEE_SHOOT,       /* eikonal: connections to area lights along bent
                            rays, found by Newton on the initial direction;
                            straight NEE only where it is exact (see manual);
                            refractive: AIM */
    RRV_NEE_MANIFOLD,    /* refractive and eikonal: a chain of refraction
                            vertices moved by Newton until each obeys Snell's
                            law (the paper's refractive ratio tracking) */
    RRV_NEE_AIM          /* refractive and eikonal: the shadow ray aimed at a
                            light sample and bent as camera rays are; what it
                            lands on counts (no solve: straight NEE's cost,
                            unbiased, no focusing; see manual) */
} rrv_nee;

/* nee MANIFOLD: the two unknowns of a chain vertex. */
typedef enum rrv_manifold_gauge {
    RRV_GAUGE_DEFAULT = 0, /* CHORD */
    RRV_GAUGE_CHORD,       /* in the plane perpendicular to the chord x0 -> y */
    RRV_GAUGE_ISO          /* in the tangent plane of the IOR isosurface (the
                              paper's; undefined where grad eta ~ 0) */
} rrv_manifold_gauge;

/* Whether emissive media are sampled as lights (next-event estimation
   toward their emission, MIS with the emission paths collect; manual,
   EMISSIVE MEDIA AS LIGHTS). */
typedef enum rrv_emission_nee {
    RRV_EMISSION_NEE_DEFAULT = 0, /* ON where there is no light shape (under
                                     the uniform light sampler, no sky either);
                                     beside light shapes, under the power
                                     sampler, a share of their draw; else OFF */
    RRV_EMISSION_NEE_ON,
    RRV_EMISSION_NEE_OFF          /* emission only where paths collect it */
} rrv_emission_nee;

/* nee MANIFOLD: how the chain is solved. */
typedef enum rrv_manifold_solver {
    RRV_MANIFOLD_SOLVER_DEFAULT = 0, /* DOGLEG (faster on every scene measured) */
    RRV_MANIFOLD_SOLVER_LM,          /* Levenberg-Marquardt (the paper's) */
    RRV_MANIFOLD_SOLVER_DOGLEG       /* trust-region Gauss-Newton, Powell's dogleg */
} rrv_manifold_solver;

/* Where a pixel's samples take their random numbers. */
typedef enum rrv_sampler {
    RRV_SAMPLER_DEFAULT = 0, /* Sobol (test/bench/RESULTS.md, "Samplers": never more than a few
                                per cent worse than PCG, up to 6x better) */
    RRV_SAMPLER_PCG,         /* an independent PCG32 stream per (pixel, sample) */
    RRV_SAMPLER_SOBOL        /* Owen-scrambled Sobol pairs per pixel, each
                                decision of a bounce at its own dimensions
                                (rrv__sobol_next); draws past a budget per
                                bounce from the PCG32 stream */
} rrv_sampler;

/* How shadow rays (and every other transmittance estimate) are tracked.
   Both are unbiased; they differ in variance per unit of work. */
typedef enum rrv_transmittance {
    RRV_TRANSMITTANCE_DEFAULT = 0, /* RATIO (test/bench/RESULTS.md, "Transmittance":
                                      MARCH wins per shadow ray, not per render),
                                      RESIDUAL for emission NEE's shadow rays */
    RRV_TRANSMITTANCE_RATIO,       /* ratio tracking against the majorant grid */
    RRV_TRANSMITTANCE_RESIDUAL,    /* residual ratio tracking: the majorant grid's
                                      minorant integrated exactly, ratio tracking of
                                      what lies above it (manual, TRANSMITTANCE) */
    RRV_TRANSMITTANCE_MARCH        /* unbiased ray marching: a jittered march
                                      corrected by a randomly truncated power series */
} rrv_transmittance;

/* Whether the in-scattered light of a light inside a scattering medium is
   also estimated with equiangular distance samples (classic integrator;
   manual, EQUIANGULAR SAMPLING). */
typedef enum rrv_equiangular {
    RRV_EQUIANGULAR_DEFAULT = 0, /* ON toward the lights that lie in a scattering
                                    medium's box, OFF toward the others */
    RRV_EQUIANGULAR_ON,          /* toward every light shape */
    RRV_EQUIANGULAR_OFF          /* free flights alone */
} rrv_equiangular;

/* How next-event estimation picks the light it samples (manual, LIGHT
   SAMPLING); the names are pbrt-v4's lightsampler's. */
typedef enum rrv_light_sampler {
    RRV_LIGHT_SAMPLER_POWER = 0, /* light shapes in proportion to their power; the sky
                                    only where it is the only light */
    RRV_LIGHT_SAMPLER_UNIFORM    /* every light shape and the sky alike */
} rrv_light_sampler;

typedef struct rrv_settings {
    int spp;              /* samples per pixel, >= 1 */
    int max_depth;        /* scattering/bounce vertices per path, >= 1 */
    uint64_t seed;
    rrv_integrator integrator;
    double bend_tolerance;/* refractive: radians of bending per event (default 0.01) */
    double mu_eta;        /* refractive: fixed refraction event rate, 1/m; 0 = automatic */
    rrv_refraction_scheme refraction; /* refractive */
    double step;          /* eikonal: step length h, m; 0 (the default): placed by the
                             field's bounds (STEPS in the manual) */
    rrv_stepper stepper;  /* eikonal */
    double ambient_ior;   /* IOR outside every medium, >= 1; 0 = the gas at its
                             ambient state (BOUNDARIES in the manual), else 1 */
    int majorant_cells;   /* majorant grid cells per axis; 0 = automatic, 1 = one
                             global majorant (for comparisons). Used by prepare. */
    rrv_ior_interpolation ior_interpolation; /* grid refractivity; used by prepare */
    int max_bake_samples; /* caps what prepare builds per axis (see rrv_load_options);
                             0 = no cap beyond the defaults */
    rrv_nee nee;          /* refractive and eikonal: light sampling */
    rrv_manifold_gauge manifold_gauge; /* nee manifold */
    int manifold_trials;  /* nee manifold: 0 = unbiased (trials until the root
                             recurs); M > 0 = M solves, distinct roots summed (biased) */
    double manifold_drop; /* nee manifold: leave out comb planes across which eta
                             along the chord changes by less than this (0: none; biased) */
    rrv_sampler sampler;
    rrv_emission_nee emission_nee;
    rrv_manifold_solver manifold_solver; /* nee manifold */
    rrv_transmittance transmittance;
    double noise_threshold; /* adaptive sampling's relative error, for the client to
                               pass to rrv_render_rect_adaptive; 0 = off (uniform) */
    rrv_equiangular equiangular; /* classic integrator */
    rrv_light_sampler light_sampler; /* used by prepare */
} rrv_settings;

struct rrv__majorant_grid;

typedef struct rrv_medium {
    char name[64];
    rrv_vec3 lo, hi;        /* the axis-aligned box the medium fills */
    double sigma_a[3];      /* absorption per unit density, 1/m */
    double sigma_s[3];      /* scattering per unit density, 1/m */
    double scale;           /* multiplies sigma_a and sigma_s (pbrt's "scale") */
    double g;               /* Henyey-Greenstein asymmetry, (-1,1) */
    double Le[3];           /* emitted radiance: adds sigma_a * Le * Lescale */
    double Lescale;
    rrv_field density;      /* extinction = density * scale * (sigma_a + sigma_s) */
    /* Gas state and IOR (CONVENTIONS: Hauf-Grigull). temperature_field gives
       T = (f - temperatureoffset) * temperaturescale in kelvin; with
       blackbody_emission the medium also emits sigma_a * Lescale * B(T). */
    rrv_field temperature;
    double temperatureoffset, temperaturescale;
    int blackbody_emission;
    rrv_field pressure;     /* Pa */
    rrv_field ior;          /* NONE: the medium does not refract */
    int ior_from_gas;       /* 1: eta from temperature and pressure */
    double eta_ref, P_ref, T_ref; /* Hauf-Grigull reference state */
    double ior_scale;       /* artist scale k on the refractivity eta - 1 */
    /* Scene lines of its medium statement and of the last density,
       temperature, pressure and ior statements, so that the limit checks of
       rrv_scene_prepare name the line that broke one; 0 = built in code. */
    int line[5];
    /* The grid or NanoVDB file each of those field statements read, as the
       scene wrote it (clipped to 127 bytes), or "": those checks name it
       beside the scene line. */
    char source[5][128];
    /* Built by rrv_scene_prepare; NULL before. */
    struct rrv__majorant_grid *majorant;
} rrv_medium;

/* Runs task(task_ctx, i) for every i in [0, count), in any order and on any
   threads, and returns once all have run. rrv_scene_prepare splits its bakes
   into such tasks; each writes only its own samples, so the scene is the
   same for any split and thread count. The library starts no threads: a
   client that has them passes this (main.c does, with POSIX threads). */
typedef void (*rrv_parallel_for_func)(void *user, int count, void (*task)(void *task_ctx, int index),
                                      void *task_ctx);

struct rrv__bvh_node;
struct rrv__emitters;
struct rrv__blackbody;

typedef struct rrv_scene {
    rrv_camera camera;
    rrv_settings settings;
    rrv_environment environment;
    rrv_material *materials; int material_count, material_capacity;
    rrv_shape *shapes;       int shape_count, shape_capacity;
    rrv_medium *media;       int medium_count, medium_capacity;
    /* Built by rrv_scene_prepare: */
    int *lights; int light_count;          /* indices of emissive shapes */
    double *light_cdf;                     /* running sums of the pick's weights over
                                              the lights, then the sky (rrv__light_pick) */
    int light_power;                       /* settings.light_sampler was power */
    double sky_weight;                     /* the sky's weight in that pick */
    double emit_share;                     /* the share of each vertex's light draw
                                              that goes to the emissive media beside
                                              the light shapes; 0: none, or a draw
                                              of their own (rrv__light_pick) */
    int sharp_faces;                       /* some refracting medium's face jumps by
                                              more than curved connections take as
                                              smooth (rrv_medium_face_jumps above
                                              1e-6): the manifold walk does not
                                              cross it */
    int sharp_rims;                        /* some sphere support's surface does,
                                              which shots do not cross either */
    struct rrv__bvh_node *bvh; int bvh_node_count;
    int *bvh_prims;                        /* shape indices in leaf order */
    double ambient_ior;                    /* the IOR outside every medium:
                                              settings.ambient_ior, or for 0
                                              the first gas medium's at its
                                              ambient state (1 without one) */
    int prepared;                          /* 1 after rrv_scene_prepare succeeded, 0 again
                                              after an edit through the calls */
    struct rrv__emitters *emitters;        /* emissive media as lights; NULL: none */
    struct rrv__blackbody *blackbody;      /* the blackbody's table; NULL: nothing glows */
    size_t bytes;                          /* heap bytes the scene holds */
    size_t grid_bytes;                     /* of which grid samples */
    size_t max_grid_bytes;                 /* the largest grid rrv_scene_prepare may
                                              build (majorant, bakes); set by the
                                              loader from rrv_load_options, 0 =
                                              RRV_DEFAULT_MAX_GRID_BYTES */
    rrv_parallel_for_func parallel_for;    /* from rrv_load_options; NULL: serial */
    void *parallel_for_user;
    char path[256];                        /* the file it came from, for messages */
} rrv_scene;

/* ---- loading -------------------------------------------------------------- */

/* Reads a whole file into a buffer of the callback's own. Return 0 on
   success, nonzero if it cannot be read (a buffer set anyway is released).
   The library hands every buffer back to the matching release callback
   when it is done with it (cgltf's read/release pair); without one the
   buffer must come from RRV_MALLOC and is freed with RRV_FREE. */
typedef int (*rrv_read_file_func)(void *user, const char *path, void **data, size_t *size);
typedef void (*rrv_release_file_func)(void *user, void *data);

/* Sees the path of every file the loader is about to read (the scene, OBJ
   meshes, grids), spelled as it will be opened: lets a client refuse to
   write its output over one of the inputs. */
typedef void (*rrv_input_func)(void *user, const char *path);

typedef struct rrv_load_options {
    size_t max_grid_bytes;       /* refuse a grid larger than this before
                                    allocating, a scene or OBJ file larger than
                                    this, and the grids prepare builds beyond it;
                                    0 = RRV_DEFAULT_MAX_GRID_BYTES */
    rrv_read_file_func read_file;/* NULL: stdio (unavailable with RRV_NO_STDIO) */
    void *read_file_user;        /* passed to read_file and release_file */
    rrv_release_file_func release_file; /* NULL: RRV_FREE */
    rrv_input_func on_input;     /* NULL: not called */
    void *on_input_user;
    int max_bake_samples;        /* 0 = default. Otherwise at most this many samples
                                    per axis (at least 2) in the noise fields prepare
                                    bakes (default at most 128) and at most this many
                                    majorant cells per axis (default up to 64, or
                                    render majorant_cells). For fuzzers and quick
                                    previews: prepare gets cheap, the noise renders
                                    smoother and the majorants looser (still bounds).
                                    Kept in scene->settings.max_bake_samples, so a
                                    later rrv_scene_prepare keeps it. */
    rrv_parallel_for_func parallel_for; /* NULL: prepare runs serially. Kept in
                                    the scene (as max_bake_samples is). */
    void *parallel_for_user;
} rrv_load_options;

#define RRV_DEFAULT_MAX_GRID_BYTES ((size_t)2 << 30)

/* Parses and prepares a scene file; paths inside are relative to its folder.
   opt may be NULL. On success *out owns everything; free with rrv_scene_free. */
RRV_DEF rrv_result rrv_scene_load(const char *path, const rrv_load_options *opt,
                                  rrv_scene **out, rrv_error *err);
/* The same from text in memory. `name` is used in messages, `base_dir` to
   resolve relative paths (NULL: the current directory). */
RRV_DEF rrv_result rrv_scene_parse(const char *text, size_t size, const char *name,
                                   const char *base_dir, const rrv_load_options *opt,
                                   rrv_scene **out, rrv_error *err);
/* Builds the BVH, light list and majorant grids. rrv_scene_load/parse call it;
   call it again after editing a scene by hand. */
RRV_DEF rrv_result rrv_scene_prepare(rrv_scene *scene, rrv_error *err);
RRV_DEF void rrv_scene_free(rrv_scene *scene);

/* Reads and validates a gridvol file (CONVENTIONS in the manual above). `nonnegative` rejects
   negative values (densities). On success grid->data is owned by the caller
   and freed with rrv_free. */
RRV_DEF rrv_result rrv_grid_read(const char *path, const rrv_load_options *opt,
                                 int nonnegative, rrv_grid *grid, rrv_error *err);
RRV_DEF rrv_result rrv_grid_read_memory(const void *data, size_t size, const char *name,
                                        size_t max_grid_bytes, int nonnegative,
                                        rrv_grid *grid, rrv_error *err);

/* Reads grid `grid_name` of a NanoVDB file (every offset, count and size in
   it is checked before use; a grid over opt->max_grid_bytes is refused).
   Grid types Float, Fp4, Fp8, Fp16 and FpN, uncompressed files only. On
   success free with rrv_nanovdb_free. */
RRV_DEF rrv_result rrv_nanovdb_read(const char *path, const char *grid_name,
                                    const rrv_load_options *opt, rrv_nanovdb *grid,
                                    rrv_error *err);
/* The same from a whole file in memory (copied; `data` stays the caller's). */
RRV_DEF rrv_result rrv_nanovdb_read_memory(const void *data, size_t size, const char *name,
                                           const char *grid_name, size_t max_grid_bytes,
                                           rrv_nanovdb *grid, rrv_error *err);
RRV_DEF void rrv_nanovdb_free(rrv_nanovdb *grid);
/* The value stored at index point (i, j, k); the background where none is. */
RRV_DEF double rrv_nanovdb_voxel(const rrv_nanovdb *grid, int64_t i, int64_t j, int64_t k);
/* The trilinear field at world position p. */
RRV_DEF double rrv_nanovdb_sample(const rrv_nanovdb *grid, rrv_vec3 p);
/* Moves the grid's values from OpenVDB's placement, value ijk at world
   map * ijk + translation (NanoVDB's, rrv's default), to the cell-centred
   one, at map * (ijk + 0.5) + translation, where Blender's Cycles renders
   its Mantaflow caches: translation and the world box move by map * 0.5. */
RRV_DEF void rrv_nanovdb_cell_centered(rrv_nanovdb *grid);
/* "float", "fp4", "fp8", "fp16" or "fpN". */
RRV_DEF const char *rrv_nanovdb_type_name(rrv_nanovdb_type type);

/* ---- building a scene in code -----------------------------------------------
   Zero means default, as in cgltf_options and sokol_gfx's desc structs: a
   zeroed rrv_camera, rrv_settings, rrv_material, rrv_shape, rrv_medium or
   rrv_field asks for the defaults of the scene format (scenes/README.md), and
   each call checks its object exactly as the parser checks a statement,
   refusing with a message that names the object ("medium \"smoke\": g must
   be in (-1, 1), got 1"). The descriptions are copied (blobs, grid samples
   and NanoVDB buffers too): the caller keeps what it passed.
   Defaults a zero asks for:
     camera    up (0,1,0), fov 40, 320 x 240 (eye and look have none)
     settings  spp 16, max_depth 32, bend_tolerance 0.01, step placed,
               ambient_ior from the gas, else 1 (BOUNDARIES); the enums'
               zero members are the defaults (integrator: chosen from
               the scene, INTEGRATORS)
     material  albedo 0.5 (diffuse) or 0.8 and albedo2 0.2 (checker),
               checker_scale 1
     medium    sigma_a and sigma_s 1 (when all six are zero), scale 1,
               Lescale 1, temperaturescale 1, eta_ref 1.000292, P_ref
               101325 Pa, T_ref 300 K, ior_scale 1
     field     noise: octaves 5, frequency 1, lacunarity 2, gain 0.5,
               amplitude 1, radius half the box's smallest side; the
               centre of noise and profiles is the box's centre; blob
               weight 1; fisheye n0 2; shell edge thickness / 4;
               temperature base 300 K, pressure base 101325 Pa; the noise
               falloff is taken as given (zero is NONE; files default to
               SPHERE)
   A zero that is itself wanted where the default is not zero (a black
   albedo, a scale of 0, an explicit centre at the origin) is set on the
   scene's arrays after the call; rrv_scene_prepare checks everything again.
   Lights are shapes with a nonzero L. Adding anything, or setting settings
   or a field, releases what rrv_scene_prepare built: prepare after the last
   edit (rrv_render_rect refuses an unprepared scene). */
typedef enum rrv_medium_field {
    RRV_MEDIUM_DENSITY = 0,
    RRV_MEDIUM_TEMPERATURE,
    RRV_MEDIUM_PRESSURE,
    RRV_MEDIUM_IOR
} rrv_medium_field;

/* An empty scene with the default camera and settings, named "scene" in
   messages. Free with rrv_scene_free. */
RRV_DEF rrv_result rrv_scene_create(rrv_scene **out, rrv_error *err);
RRV_DEF rrv_result rrv_scene_set_camera(rrv_scene *scene, const rrv_camera *camera,
                                        rrv_error *err);
RRV_DEF rrv_result rrv_scene_set_settings(rrv_scene *scene, const rrv_settings *settings,
                                          rrv_error *err);
/* kind NONE: no sky. CONSTANT with a zero L is a sky of radiance 1. */
RRV_DEF rrv_result rrv_scene_set_environment(rrv_scene *scene, const rrv_environment *env,
                                             rrv_error *err);
/* index (may be NULL) gets the position in scene->materials; the name must
   be new (an empty name becomes "material N"). */
RRV_DEF rrv_result rrv_scene_add_material(rrv_scene *scene, const rrv_material *material,
                                          int *index, rrv_error *err);
/* A sphere, quad or triangle; shape->material indexes scene->materials, and
   a scene without materials gets the grey "default" one for index 0. */
RRV_DEF rrv_result rrv_scene_add_shape(rrv_scene *scene, const rrv_shape *shape, int *index,
                                       rrv_error *err);
/* A triangle mesh: `points` holds point_count xyz triples, `indices`
   triangle_count index triples; every triangle copies proto's material and
   L. Zero-area triangles are dropped, as the OBJ loader drops them. */
RRV_DEF rrv_result rrv_scene_add_triangles(rrv_scene *scene, const rrv_shape *proto,
                                           const double *points, int point_count,
                                           const int *indices, int triangle_count,
                                           rrv_error *err);
/* The medium's own fields (density, temperature, ...) are ignored: give them
   with rrv_scene_set_field. The name must be new (empty: "medium N"). */
RRV_DEF rrv_result rrv_scene_add_medium(rrv_scene *scene, const rrv_medium *medium, int *index,
                                        rrv_error *err);
/* How the medium's channels share free-flight majorants: channels whose
   extinctions ((sigma_a + sigma_s) * scale) lie within 4x of their group's
   largest walk with that largest, a channel further below opens a group of
   its own, so that a thin channel does not take a dense one's null
   collisions. Returns the number of groups (1 to 3) and each channel's
   group in group[], 0 the densest. */
RRV_DEF int rrv_medium_channel_groups(const rrv_medium *medium, int group[3]);
/* Sets one field of medium `medium` (an index), replacing what it had. */
RRV_DEF rrv_result rrv_scene_set_field(rrv_scene *scene, int medium, rrv_medium_field which,
                                       const rrv_field *field, rrv_error *err);

/* ---- rendering -------------------------------------------------------------- */

/* The limits of BOUNDS (see the manual at the top). Scenes beyond the first
   four are refused at load; the next three cut a walk and count it. */
#define RRV_MIN_IOR 0.1             /* refractive index, everywhere */
#define RRV_MAX_IOR 10.0
#define RRV_MAX_OPTICAL_DEPTH 1e12  /* peak extinction times a medium's size */
#define RRV_MAX_RADIANCE 1e20       /* any emission times its scale */
#define RRV_MAX_SAMPLE 1e30         /* a sample above it is discarded as non-finite */
#define RRV_MAX_SEGMENT_EVENTS 4194304L /* collisions of one tracking walk */
#define RRV_MAX_SEGMENT_STEPS 10000000L /* refraction steps between real vertices */
#define RRV_MAX_SAMPLE_WORK 16777216L   /* loop iterations and collisions of one camera path */
#define RRV_MAX_BLOBS 4096          /* blobs in one field: each lookup sums them all */

typedef struct rrv_render_stats {
    uint64_t samples;   /* pixel samples taken */
    uint64_t paths;     /* camera paths plus shadow connections traced */
    uint64_t events;    /* tentative collisions (real and null) sampled */
    uint64_t nonfinite; /* samples discarded because they were NaN, infinite
                           or above RRV_MAX_SAMPLE (see BOUNDS) */
    uint64_t paths_cut; /* camera paths and shadow rays cut short at a work
                           bound (see BOUNDS): what they gathered before the
                           cut is kept, nothing after it */
    uint64_t cut_tracking; /* of which a delta or ratio tracking walk hit its
                              collision bound; the rest hit a leg's bound on
                              refraction events, kicks or eikonal steps, or
                              the sample's (cut_samples, at the end) */
    /* nee shoot: */
    uint64_t solves;            /* Newton solves attempted (first tries and trials) */
    uint64_t solves_converged;
    uint64_t solve_iterations;  /* summed over the solves attempted */
    uint64_t solve_segments;    /* chain length: segments of converged shots, summed */
    uint64_t solve_connections; /* curved connections tried (shoot, manifold) */
    uint64_t solve_trials;      /* solves a connection made: its tries and the trials
                                   estimating 1/q, summed over those */
    uint64_t solves_unsupported;/* vertices whose curved connections were left to
                                   forward paths because no curved NEE runs there:
                                   the Poisson and midpoint schemes, or (manifold) an
                                   IOR with no derivative of its gradient */
    /* nee aim (and shoot where it cannot solve): */
    uint64_t aim_shots;         /* bent shadow rays aimed at a light sample */
    uint64_t aim_missed;        /* of which refraction turned off their light (they
                                   met another surface, left the scene or met a
                                   sharp interface); the rest landed or were absorbed */
    /* nee shoot and manifold, toward strongly refracting supports: */
    uint64_t cone_shots;        /* bent rays drawn in a support's cone (a lens's) for
                                   the paths no solve stands for (rrv__cone_nee) */
    uint64_t cone_counted;      /* of which one landed on a light as such a path */
    uint64_t cut_samples;       /* of paths_cut, camera paths cut at the bound on a
                                   whole sample's work (see BOUNDS) */
    uint64_t trapped_paths;     /* of paths_cut, camera paths and bent shadow rays
                                   ended as trapped: a run through the refraction
                                   supports between two vertices beyond twice their
                                   straight length (see BOUNDS) */
} rrv_render_stats;

/* Renders pixels [x0,x1) x [y0,y1) of the image (row 0 at the top) for
   sample indices [sample_begin, sample_end) and ADDS each pixel's sum of RGB
   radiance into the caller's buffer for that rectangle only:
   sum[3*((y - y0)*stride + (x - x0)) + c], stride >= x1 - x0 pixels. Divide
   by the total sample count afterwards. To fill a whole image, pass
   sum + 3*(y0*width + x0) with stride = width.
   Random numbers depend only on (seed, pixel, sample index): splitting the
   pixels between calls (tiles, threads, machines) gives bit-identical sums;
   splitting a pixel's samples between calls changes them only by float
   rounding of the additions. stats may be NULL; if not, it is added to.
   Thread-safe for distinct pixels: the scene is only read (give each
   thread its own err, or NULL). With nee manifold each call allocates
   its solver's scratch (~250 KB, RRV_MALLOC) and frees it on return;
   RRV_ERROR_MEMORY, with nothing added, when that fails. Refused with
   RRV_ERROR_ARGUMENT, nothing added: a scene that was never prepared (or
   edited since: rrv_scene_prepare), a rectangle outside the image, and
   sample indices outside [0, RRV_MAX_SPP) -- the bound of a scene's spp,
   where a float sum stops counting (2^24 + 1 rounds to 2^24). */
#define RRV_MAX_SPP 16777216
RRV_DEF rrv_result rrv_render_rect(const rrv_scene *scene, int x0, int y0, int x1, int y1,
                                   int sample_begin, int sample_end,
                                   float *sum, int stride, rrv_render_stats *stats,
                                   rrv_error *err);

/* Adaptive sampling: renders up to spp samples of each pixel of [x0,x1) x
   [y0,y1), in blocks [0,16), [16,32), [32,64), ... [2^k, spp) of the sample
   tree main.c sums and merges by (README, "Rendering on a farm"), and stops
   a pixel after a block [n, 2n) once the estimated relative error of its
   mean is below threshold: the standard error of the 2n samples' R + G + B
   (their sample variance over 2n, square-rooted) over max(their mean,
   RRV_ADAPTIVE_FLOOR).
   STORES (not adds) each pixel's tree sum in sum (layout as
   rrv_render_rect's) and its sample count in counts[(y - y0)*stride + (x -
   x0)]; the image is sum / count. Each decision looks only at the pixel's
   own samples, so any split into rectangles, threads or tiles gives
   bit-identical sums and counts; a pixel that runs to spp has the sum of
   the uniform tree render (threshold 0 renders every sample). Refused as
   rrv_render_rect refuses, and for spp < 1, counts NULL or a negative or
   non-finite threshold. */
#define RRV_ADAPTIVE_BLOCK 16
#define RRV_ADAPTIVE_FLOOR 0.01
RRV_DEF rrv_result rrv_render_rect_adaptive(const rrv_scene *scene, int x0, int y0, int x1, int y1, int spp,
                                            double threshold, float *sum, int stride, int *counts,
                                            rrv_render_stats *stats, rrv_error *err);

/* The integrator rrv_render_rect uses for a prepared scene: its settings'
   one, or for RRV_INTEGRATOR_DEFAULT the manual's rule (INTEGRATORS,
   "default"): CLASSIC where no medium's IOR differs from the ambient one,
   EIKONAL (curved NEE solved by shooting) where every refracting medium is
   clear and a light is small as seen from one, REFRACTIVE
   otherwise. */
RRV_DEF rrv_integrator rrv_scene_integrator(const rrv_scene *scene);

/* The nee mode rrv_render_rect uses for a prepared scene: its settings'
   one, or for RRV_NEE_DEFAULT the manual's rule (NEXT-EVENT ESTIMATION,
   "default"): MANIFOLD (chains, the paper's method) with the eikonal
   integrator where every refracting medium is clear and bends weakly and
   no face or rim is a jump of the IOR, else SHOOT (which the refractive
   integrator turns into AIM). */
RRV_DEF rrv_nee rrv_scene_nee(const rrv_scene *scene);

/* The sharp interfaces of a prepared scene's medium: for each face of its
   box (-x, +x, -y, +y, -z, +z) and, for a Luneburg or fish-eye profile,
   its sphere (jump[6]; 0 for other media), the largest |eta just inside -
   eta just outside| on a 65 x 65 lattice of the face (the sphere: 128 x
   64 in longitude and latitude, where inside the box), where the refractivity on either side is
   that of the scene (the ambient IOR, or another medium's where boxes
   overlap). Jumps of 1e-7 or less, the float rounding of an IOR near 1,
   are 0; curved connections (nee shoot, manifold) take jumps up to 1e-6
   as smooth, passing straight where camera rays turn by at most 1e-6
   tan(theta). Returns the largest of the seven, 0 for a medium that does not
   refract or an index out of range. */
RRV_DEF double rrv_medium_face_jumps(const rrv_scene *scene, int medium, double jump[7]);
/* The largest jump curved connections take as smooth (above). */
#define RRV_SMOOTH_JUMP 1e-6

/* One walk of a ray through the refractive media only (absorption and
   scattering ignored), as `rrv trace` prints it. The visit callback, if not
   NULL, sees every vertex (position, direction after the vertex). */
typedef void (*rrv_trace_visit_func)(void *user, rrv_vec3 position, rrv_vec3 direction);
typedef struct rrv_trace_result {
    rrv_vec3 position, direction; /* where and how the ray left the last medium */
    uint64_t events;              /* refraction events (or eikonal steps) */
} rrv_trace_result;
RRV_DEF rrv_result rrv_trace_ray(const rrv_scene *scene, rrv_integrator integrator,
                                 rrv_vec3 origin, rrv_vec3 direction,
                                 uint64_t seed, uint64_t walk,
                                 rrv_trace_visit_func visit, void *user,
                                 rrv_trace_result *result, rrv_error *err);

/* ---- image I/O ----------------------------------------------------------------
   Images are float RGB, row 0 at the top, 3 floats a pixel. */

/* Return 0 on success; nonzero aborts the writer with RRV_ERROR_IO. The
   callback writers fill err (may be NULL) like every fallible call. */
typedef int (*rrv_write_func)(void *user, const void *data, size_t size);

/* PFM: "PF\n<w> <h>\n-1.0\n", little-endian floats, rows bottom to top. */
RRV_DEF rrv_result rrv_write_pfm_to(rrv_write_func write, void *user,
                                    const float *rgb, int width, int height, rrv_error *err);
/* PNG preview: 8-bit sRGB of rgb * 2^exposure, filtered and deflated. */
RRV_DEF rrv_result rrv_write_png_to(rrv_write_func write, void *user,
                                    const float *rgb, int width, int height, double exposure,
                                    rrv_error *err);
/* OpenEXR: single-part scanline file, channels B, G, R (the order the format
   requires), lineOrder INCREASING_Y, pixelAspectRatio 1, screenWindowCenter
   (0, 0), screenWindowWidth 1. A zeroed rrv_exr_options (or NULL) means
   HALF, ZIP and a display window equal to the image.
   HALF rounds to nearest even; finite values beyond the largest half
   (65504) are clamped to +-65504 rather than becoming infinite, infinities
   stay infinite and NaN stays NaN. ZIP is zlib (rrv's own LZ77 + dynamic
   Huffman deflate) over blocks of 16 scanlines after the format's byte
   split and delta predictor; a block that would not shrink is stored raw, as
   the format prescribes.
   Crops and tiles of a larger frame: the image is the data window, placed
   with its top-left pixel at (x, y) in a display window of display_width x
   display_height pixels (0 means the image's own size), so a compositor puts
   it where it belongs. The data window may extend past the display window,
   as the format allows; every coordinate must fit in an int. */
typedef enum rrv_exr_pixel { RRV_EXR_HALF = 0, RRV_EXR_FLOAT = 1 } rrv_exr_pixel;
typedef enum rrv_exr_compression { RRV_EXR_ZIP = 0, RRV_EXR_NO_COMPRESSION = 1 } rrv_exr_compression;
typedef struct rrv_exr_options {
    rrv_exr_pixel pixel;
    rrv_exr_compression compression;
    int display_width, display_height; /* 0: width, height of the image */
    int x, y;                          /* the image's origin in the display window */
    /* Writer: one extra attribute of type "string" when text_name is not NULL
       (a name of 1-63 bytes, text up to 4095 bytes, e.g. what a partial render
       holds); the reader sets both to NULL: rrv_exr_find_attribute finds it. */
    const char *text_name, *text;
} rrv_exr_options;
RRV_DEF rrv_result rrv_write_exr_to(rrv_write_func write, void *user, const float *rgb,
                                    int width, int height, const rrv_exr_options *options,
                                    rrv_error *err);
/* Finds the header attribute called attr_name in the OpenEXR file in data:
   RRV_OK with its type name and value (pointers into data), RRV_ERROR_FORMAT
   if the file or its header is malformed or has no such attribute. */
RRV_DEF rrv_result rrv_exr_find_attribute(const void *data, size_t size, const char *attr_name,
                                          const char **type, const void **value, size_t *value_size);
/* The half nearest to value by the rules above, as its 16-bit pattern. */
RRV_DEF uint16_t rrv_half_from_float(float value);
/* Reads a single-part scanline OpenEXR file's R, G and B channels (HALF or
   FLOAT; other channels are skipped) compressed with NONE, RLE, ZIPS or ZIP
   (the codecs rrv can decode; others are refused by name) into a new RGB
   buffer of the data window (free with rrv_free). info, if not NULL, gets
   the pixel type (FLOAT only if all three are), NO_COMPRESSION or ZIP (for
   any codec), the display window's size and the data window's origin in it.
   Every offset and size is checked against the buffer before use. */
RRV_DEF rrv_result rrv_read_exr_memory(const void *data, size_t size, const char *name, float **rgb,
                                       int *width, int *height, rrv_exr_options *info, rrv_error *err);
/* Reads a PFM (color "PF" or grey "Pf", either endianness) from memory into a
   new RGB buffer (free with rrv_free). */
RRV_DEF rrv_result rrv_read_pfm_memory(const void *data, size_t size, const char *name,
                                       float **rgb, int *width, int *height, rrv_error *err);
/* File forms. Writers write a new temporary file "<path>.<random>.tmp" next
   to path and rename it over path only when everything was written, so a
   failure never leaves half an image and never touches an existing file of
   another name. An existing path that is not a regular file (a device
   node, a FIFO, a socket, a folder) is refused with RRV_ERROR_IO and
   "cannot write: it is a FIFO, not a regular file" (or the kind it is),
   and nothing is written. A symbolic link is judged by what it points to:
   one to a device is refused; one to a regular file, or a dangling one, is
   replaced by the image (rename replaces the link itself; the file it
   pointed to is left as it was). The check and the rename are two steps,
   so a path swapped between them is not caught. All of this needs POSIX
   (CONFIGURATION: RRV_NO_POSIX); plain C cannot tell a device from a file
   nor create a file exclusively before C11, so there an existing device
   node at path is replaced and two writers can in rare cases pick the same
   temporary name: a client that needs more uses its platform's calls
   around rrv_write_pfm_to. The readers open only regular files, never
   blocking on a FIFO (rrv_open_read), and read the header first and then
   exactly the pixel data it announces. */
RRV_DEF rrv_result rrv_write_pfm(const char *path, const float *rgb, int width, int height,
                                 rrv_error *err);
RRV_DEF rrv_result rrv_write_png(const char *path, const float *rgb, int width, int height,
                                 double exposure, rrv_error *err);
RRV_DEF rrv_result rrv_write_exr(const char *path, const float *rgb, int width, int height,
                                 const rrv_exr_options *options, rrv_error *err);
RRV_DEF rrv_result rrv_read_pfm(const char *path, float **rgb, int *width, int *height,
                                rrv_error *err);
RRV_DEF rrv_result rrv_read_exr(const char *path, float **rgb, int *width, int *height,
                                rrv_exr_options *info, rrv_error *err);
#ifndef RRV_NO_STDIO
/* Opens path for reading ("rb") as every file reader of rrv does: only a
   regular file, and without blocking on the way (opening a FIFO with no
   writer, or a terminal, would wait forever). Anything else is refused with
   RRV_ERROR_IO and err naming path, line 0, with "not a regular file" (or
   "is a directory", "no such file", "permission denied"). *size gets the
   file's size in bytes, or UINT64_MAX where it cannot be told. Without
   POSIX (CONFIGURATION) it is plain fopen: a FIFO there still blocks. */
RRV_DEF rrv_result rrv_open_read(const char *path, FILE **file, uint64_t *size, rrv_error *err);
#endif

/* Checksums the PNG writer uses, exposed for tests and tools. Start with 0 (crc)
   and 1 (adler). */
RRV_DEF uint32_t rrv_crc32(uint32_t crc, const void *data, size_t size);
RRV_DEF uint32_t rrv_adler32(uint32_t adler, const void *data, size_t size);

#ifdef __cplusplus
}
#endif
#endif /* RRV_H_INCLUDED */

/* ============================================================================
   IMPLEMENTATION
   ============================================================================ */
#ifdef RRV_IMPLEMENTATION
#ifndef RRV_IMPLEMENTATION_INCLUDED
#define RRV_IMPLEMENTATION_INCLUDED

/* >> 1 common: configuration, allocation, errors ============================ */
#include <math.h>
#include <string.h>
#include <stdarg.h>
#include <stdio.h> /* vsnprintf is needed even with RRV_NO_STDIO */
#include <limits.h>
#include <float.h>

#if defined(RRV_MALLOC) && defined(RRV_REALLOC) && defined(RRV_FREE)
/* all three given */
#elif !defined(RRV_MALLOC) && !defined(RRV_REALLOC) && !defined(RRV_FREE)
#include <stdlib.h>
#define RRV_MALLOC(sz) malloc(sz)
#define RRV_REALLOC(p, sz) realloc(p, sz)
#define RRV_FREE(p) free(p)
#else
#error "rrv.h: define all of RRV_MALLOC, RRV_REALLOC and RRV_FREE, or none"
#endif

#ifndef RRV_ASSERT
#include <assert.h>
#define RRV_ASSERT(x) assert(x)
#endif

#define RRV__PI 3.14159265358979323846
#define RRV__INV_PI 0.31830988618379067154
#define RRV__INV_4PI 0.07957747154594766788

RRV_DEF const char *rrv_result_string(rrv_result r)
{
    static const char *const names[] = {
#define RRV__NAME(name, text) text,
        RRV_RESULT_LIST(RRV__NAME)
#undef RRV__NAME
    };
    if ((int)r < 0 || (int)r >= (int)RRV_RESULT_COUNT) return "unknown result";
    return names[r];
}

RRV_DEF void rrv_free(void *p) { RRV_FREE(p); }

/* Fills *err (which may be NULL) and returns code, so a failing call can
   `return rrv__fail(err, ...)` in one line. */
static rrv_result rrv__fail(rrv_error *err, rrv_result code, const char *file, int line,
                            const char *fmt, ...)
{
    if (err) {
        va_list args;
        err->code = code;
        err->line = line;
        if (file) {
            size_t n = strlen(file);
            if (n >= sizeof err->file) file += n - (sizeof err->file - 1);
            memcpy(err->file, file, strlen(file) + 1);
        } else {
            err->file[0] = '\0';
        }
        va_start(args, fmt);
        vsnprintf(err->message, sizeof err->message, fmt, args);
        va_end(args);
    }
    return code;
}

/* The refusal of a call that needs a part the build leaves out
   (CONFIGURATION): the part and the switch named, as RRV_NO_STDIO's are. */
#define rrv__left_out(err, file, part, name, hint) \
    rrv__fail((err), RRV_ERROR_UNSUPPORTED, (file), 0, "%s is disabled (%s)%s", (part), (name), (hint))

static void rrv__clear_error(rrv_error *err)
{
    if (err) {
        err->code = RRV_OK;
        err->line = 0;
        err->file[0] = '\0';
        err->message[0] = '\0';
    }
}

/* >> 2 math: vectors, orthonormal frames, the PCG32 stream, the Sobol sampler =
   Everything geometric is double: a fire changes the IOR of air by ~2e-4, and
   the positions and directions that carry such bends must not lose them. */

static rrv_vec3 rrv__v3(double x, double y, double z) { rrv_vec3 v; v.x = x; v.y = y; v.z = z; return v; }
static rrv_vec3 rrv__add(rrv_vec3 a, rrv_vec3 b) { return rrv__v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static rrv_vec3 rrv__sub(rrv_vec3 a, rrv_vec3 b) { return rrv__v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static rrv_vec3 rrv__scale(rrv_vec3 a, double s) { return rrv__v3(a.x * s, a.y * s, a.z * s); }
static rrv_vec3 rrv__madd(rrv_vec3 a, rrv_vec3 b, double s) { return rrv__v3(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s); }
static double rrv__dot(rrv_vec3 a, rrv_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static rrv_vec3 rrv__cross(rrv_vec3 a, rrv_vec3 b)
{
    return rrv__v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static double rrv__length(rrv_vec3 a) { return sqrt(rrv__dot(a, a)); }
static rrv_vec3 rrv__normalize(rrv_vec3 a)
{
    double len = rrv__length(a);
    return len > 0 ? rrv__scale(a, 1.0 / len) : a;
}
/* v divided by its largest absolute component (v itself when that is 0):
   the direction survives, and squares of the result cannot overflow. */
static rrv_vec3 rrv__unit_max(rrv_vec3 v)
{
    double m = fabs(v.x);
    if (fabs(v.y) > m) m = fabs(v.y);
    if (fabs(v.z) > m) m = fabs(v.z);
    return m > 0 && m <= DBL_MAX ? rrv__scale(v, 1.0 / m) : v;
}
static double rrv__axis(rrv_vec3 a, int axis) { return axis == 0 ? a.x : axis == 1 ? a.y : a.z; }
static rrv_vec3 rrv__vmin(rrv_vec3 a, rrv_vec3 b) { return rrv__v3(fmin(a.x, b.x), fmin(a.y, b.y), fmin(a.z, b.z)); }
static rrv_vec3 rrv__vmax(rrv_vec3 a, rrv_vec3 b) { return rrv__v3(fmax(a.x, b.x), fmax(a.y, b.y), fmax(a.z, b.z)); }
static double rrv__max3(const double c[3]) { return fmax(c[0], fmax(c[1], c[2])); }
static double rrv__clamp(double x, double lo, double hi) { return x < lo ? lo : x > hi ? hi : x; }
/* max/min that return a when b is NaN, inlined: libm's fmax is a call in
   hot loops without -ffast-math. Slab tests rely on ignoring the NaN of
   0 * inf when a ray lies in a slab plane. */
static double rrv__maxd(double a, double b) { return b > a ? b : a; }
static double rrv__mind(double a, double b) { return b < a ? b : a; }

/* Builds tangents t, b so that (t, b, n) is orthonormal, without a branch on a
   "safe" axis that would make the frame jump (Duff et al. 2017). */
static void rrv__frame(rrv_vec3 n, rrv_vec3 *t, rrv_vec3 *b)
{
    double sign = n.z >= 0 ? 1.0 : -1.0;
    double a = -1.0 / (sign + n.z);
    double c = n.x * n.y * a;
    *t = rrv__v3(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = rrv__v3(c, sign + n.y * n.y * a, -n.y);
}
static rrv_vec3 rrv__from_frame(rrv_vec3 n, double x, double y, double z)
{
    rrv_vec3 t, b;
    rrv__frame(n, &t, &b);
    return rrv__add(rrv__add(rrv__scale(t, x), rrv__scale(b, y)), rrv__scale(n, z));
}

/* PCG32 (O'Neill 2014): small state, good statistics, and independent
   streams, so each (pixel, sample) owns one and images do not depend on
   how the work is split between threads. */
/* The sampler's streams (rrv__uniform_in), RRV__STREAM_* below and each
   one's walk at RRV__STREAM_WALK past it. */
#define RRV__STREAMS 7

typedef struct rrv__rng {
    uint64_t state, inc;
    /* Sobol sampler (rrv__sobol_start, rrv__sampler_bounce): the pixel's
       scramble key, the sample's index in its pixel (bits reversed), whether Sobol is on,
       the bounce, the stream decisions come from (rrv__uniform_walk adds
       RRV__STREAM_WALK to it), the next dimension of every stream, and the
       second coordinate of each stream's pair last drawn, with the number
       of that pair plus one (0: none) */
    uint64_t sobol_key;
    uint32_t sobol_index_reversed;
    int sobol, bounce, stream;
    int next[RRV__STREAMS], paired[RRV__STREAMS];
    uint32_t sobol_y[RRV__STREAMS];
} rrv__rng;

static uint32_t rrv__next_u32(rrv__rng *rng)
{
    uint64_t old = rng->state;
    uint32_t xorshifted, rot;
    rng->state = old * 6364136223846793005ULL + rng->inc;
    xorshifted = (uint32_t)(((old >> 18) ^ old) >> 27);
    rot = (uint32_t)(old >> 59);
    return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
}

static uint64_t rrv__mix64(uint64_t z)
{
    z += 0x9E3779B97F4A7C15ULL;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static void rrv__rng_seed(rrv__rng *rng, uint64_t seed, uint64_t stream_a, uint64_t stream_b)
{
    uint64_t key = rrv__mix64(seed ^ rrv__mix64(stream_a ^ rrv__mix64(stream_b)));
    rng->state = 0;
    rng->inc = (rrv__mix64(key + 1) << 1) | 1u;
    rrv__next_u32(rng);
    rng->state += key;
    rrv__next_u32(rng);
    rng->sobol = rng->bounce = rng->stream = 0;
}

/* ---- the Sobol sampler: Owen-scrambled Sobol pairs (Burley 2020) ----------
   Sample s of a pixel takes its random numbers two at a time from the first
   two Sobol dimensions, a (0,2)-sequence, at index s shuffled by a nested
   uniform (Owen) scramble of its own per pair, each coordinate Owen-scrambled
   too. Every single sample is then uniform in the unit square and pairs are
   independent, so estimates stay unbiased; across a pixel's samples each
   pair is stratified. Everything is a hash of (seed, pixel, s): images are
   the same for any split into tiles, sample ranges and threads.

   Stratification only helps where the same dimension serves the same
   decision in every sample. A path in dense smoke draws a varying number of
   free flights, so numbering the draws of a path in order would give sample
   A's phase direction the dimension sample B spends on its fifth null
   collision. Dimensions are therefore named, not counted: (bounce, stream,
   k), bounce 0 the camera's and bounce b the walk to the b-th vertex and
   the choices made there, and each bounce's draws split into streams
   numbered on their own: the vertex's direction and roulette, its light
   sample, the walk of the path (free flights, collision events, comb
   kicks, faces), the walks of its shadow rays, and the equiangular sample
   of the segment that leads to the vertex (rrv__equiangular_nee) with its
   walks. A stream's first
   RRV__SOBOL_BUDGET numbers of a bounce are Sobol, the rest PCG32: they are
   the draws that vary in count, where alignment is lost anyway. */
#define RRV__SOBOL_BUDGET 32
enum { RRV__STREAM_DIRECTION, RRV__STREAM_LIGHT, RRV__STREAM_WALK, RRV__STREAM_EQUIANGULAR = 4 };

/* Every stream starts over at its first dimension. */
static void rrv__streams_restart(rrv__rng *rng)
{
    int k;
    for (k = 0; k < RRV__STREAMS; ++k) rng->next[k] = rng->paired[k] = 0;
}

static inline uint32_t rrv__reverse_bits(uint32_t x)
{
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0F0F0F0Fu) | ((x & 0x0F0F0F0Fu) << 4);
    /* the bytes in reverse order: gcc and clang see one byte-swap instruction */
    return (x << 24) | ((x & 0xFF00u) << 8) | ((x >> 8) & 0xFF00u) | (x >> 24);
}

/* A nested uniform scramble of binary digits held reversed (the first
   digit in bit 0): each digit is flipped by a hash of the digits before it.
   The Laine-Karras style hash Burley (2020) tuned: carries of the additions
   and products run from bit 0 up, i.e. from the first digits on. */
static uint32_t rrv__owen_reversed(uint32_t x, uint32_t seed)
{
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

/* Sobol's second dimension, its digits reversed (digit r in bit r): the
   generator matrix is Pascal's triangle mod 2 (polynomial x + 1), and by
   Lucas' theorem digit r is the XOR of the index bits k whose binary
   digits contain r's, a superset sum taken in five shifts. */
static uint32_t rrv__sobol_1_reversed(uint32_t i)
{
    i ^= (i >> 1) & 0x55555555u;
    i ^= (i >> 2) & 0x33333333u;
    i ^= (i >> 4) & 0x0F0F0F0Fu;
    i ^= (i >> 8) & 0x00FF00FFu;
    i ^= (i >> 16) & 0x0000FFFFu;
    return i;
}

/* Makes the numbers drawn from rng those of sample `index` of the pixel
   whose scramble key is `key`, at bounce 0 (the camera's). */
static void rrv__sobol_start(rrv__rng *rng, uint64_t key, uint32_t index)
{
    rng->sobol_key = key;
    rng->sobol_index_reversed = rrv__reverse_bits(index);
    rng->sobol = 1;
    rng->bounce = 0;
    rng->stream = RRV__STREAM_DIRECTION;
    rrv__streams_restart(rng);
}

/* The path reaches its next vertex: every stream starts over at the
   bounce's own dimensions. No-op for PCG. */
static void rrv__sampler_bounce(rrv__rng *rng)
{
    ++rng->bounce;
    rrv__streams_restart(rng);
}

/* Dimension k of a stream in this bounce. Dimension 0 of Sobol is the index
   with its bits reversed, so in reversed form the shuffled index i is its
   own first coordinate. The pair's scramble is a hash of its name, so no
   two dimensions of a sample share one. */
static double rrv__sobol_next(rrv__rng *rng, int stream)
{
    int k = rng->next[stream]++;
    uint64_t h;
    uint32_t i, x;
    if ((k & 1) && rng->paired[stream] == (k >> 1) + 1) return rng->sobol_y[stream] * (1.0 / 4294967296.0);
    rng->paired[stream] = (k >> 1) + 1;
    h = rrv__mix64(rng->sobol_key ^ rrv__mix64(((uint64_t)(uint32_t)rng->bounce << 32) |
                                                ((uint64_t)stream << 16) | (uint64_t)(k >> 1)));
    i = rrv__reverse_bits(rrv__owen_reversed(rng->sobol_index_reversed, (uint32_t)h));
    x = rrv__reverse_bits(rrv__owen_reversed(i, (uint32_t)(h >> 32)));
    rng->sobol_y[stream] =
        rrv__reverse_bits(rrv__owen_reversed(rrv__sobol_1_reversed(i), (uint32_t)(h >> 16) * 0x9E3779B9u));
    return (k & 1 ? rng->sobol_y[stream] : x) * (1.0 / 4294967296.0);
}

/* Uniform in [0,1): 53 random bits, so that -log(1-u) never sees 1. */
static double rrv__uniform_in(rrv__rng *rng, int stream)
{
    uint64_t hi, lo;
    if (rng->sobol && rng->next[stream] < RRV__SOBOL_BUDGET) return rrv__sobol_next(rng, stream);
    hi = rrv__next_u32(rng) >> 5;
    lo = rrv__next_u32(rng) >> 6;
    return (double)(hi * 67108864.0 + lo) * (1.0 / 9007199254740992.0);
}

/* A decision of the vertex (or of its light sample, in rrv__vertex_nee). */
static double rrv__uniform(rrv__rng *rng) { return rrv__uniform_in(rng, rng->stream); }

/* A draw of a walk: of the path's own, or of a shadow ray's while a light
   is sampled. */
static double rrv__uniform_walk(rrv__rng *rng) { return rrv__uniform_in(rng, rng->stream + RRV__STREAM_WALK); }

/* >> 3 sampling: free flights, directions, phase function, MIS ============== */

static double rrv__sample_free_flight(double majorant, rrv__rng *rng)
{
    return -log(1.0 - rrv__uniform_walk(rng)) / majorant;
}

static rrv_vec3 rrv__sample_uniform_sphere(double u1, double u2)
{
    double z = 1.0 - 2.0 * u1, r = sqrt(fmax(0.0, 1.0 - z * z)), phi = 2.0 * RRV__PI * u2;
    return rrv__v3(r * cos(phi), r * sin(phi), z);
}

static rrv_vec3 rrv__sample_cosine_hemisphere(rrv_vec3 n, double u1, double u2)
{
    double r = sqrt(u1), phi = 2.0 * RRV__PI * u2;
    return rrv__from_frame(n, r * cos(phi), r * sin(phi), sqrt(fmax(0.0, 1.0 - u1)));
}

/* Henyey-Greenstein with cos_theta = dot(incoming travel direction, outgoing
   direction), so g > 0 scatters forward; integrates to 1 over the sphere. */
static double rrv__hg_eval(double g, double cos_theta)
{
    double denom = 1.0 + g * g - 2.0 * g * cos_theta;
    return RRV__INV_4PI * (1.0 - g * g) / (denom * sqrt(fmax(denom, 1e-300)));
}

static rrv_vec3 rrv__hg_sample(double g, rrv_vec3 forward, double u1, double u2)
{
    double cos_theta, sin_theta, phi = 2.0 * RRV__PI * u2;
    if (fabs(g) < 1e-3) {
        cos_theta = 1.0 - 2.0 * u1;
    } else {
        double s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1);
        cos_theta = rrv__clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
    }
    sin_theta = sqrt(fmax(0.0, 1.0 - cos_theta * cos_theta));
    return rrv__from_frame(forward, sin_theta * cos(phi), sin_theta * sin(phi), cos_theta);
}

static double rrv__power_heuristic(double pdf_a, double pdf_b)
{
    double a = pdf_a * pdf_a, b = pdf_b * pdf_b;
    return a + b > 0 ? a / (a + b) : 0.0;
}

/* >> 4 geometry: ray-primitive intersection and the binned-SAH BVH ========== */

typedef struct rrv__hit {
    double t;
    rrv_vec3 p, n; /* n: geometric normal, unit, as the primitive defines it */
    int shape;
} rrv__hit;

typedef struct rrv__bvh_node rrv__bvh_node;
struct rrv__bvh_node {
    rrv_vec3 lo, hi;
    int first;     /* leaf: first index into bvh_prims; inner: right child */
    int count;     /* leaf: primitive count; inner: 0 (left child is next) */
};

static void rrv__shape_bounds(const rrv_shape *s, rrv_vec3 *lo, rrv_vec3 *hi)
{
    if (s->kind == RRV_SHAPE_SPHERE) {
        rrv_vec3 r = rrv__v3(s->radius, s->radius, s->radius);
        *lo = rrv__sub(s->center, r);
        *hi = rrv__add(s->center, r);
    } else {
        rrv_vec3 a = s->p0, b = rrv__add(s->p0, s->e1), c = rrv__add(s->p0, s->e2);
        *lo = rrv__vmin(a, rrv__vmin(b, c));
        *hi = rrv__vmax(a, rrv__vmax(b, c));
        if (s->kind == RRV_SHAPE_QUAD) {
            rrv_vec3 d = rrv__add(b, s->e2);
            *lo = rrv__vmin(*lo, d);
            *hi = rrv__vmax(*hi, d);
        }
    }
}

static int rrv__intersect_shape(const rrv_shape *s, rrv_vec3 o, rrv_vec3 d, double tmax, rrv__hit *hit)
{
    if (s->kind == RRV_SHAPE_SPHERE) {
        /* The half-b form with oc projected out keeps precision for spheres
           far from the ray origin (Haines et al., Ray Tracing Gems ch. 7). */
        rrv_vec3 oc = rrv__sub(o, s->center);
        double b = rrv__dot(oc, d);
        rrv_vec3 perp = rrv__madd(oc, d, -b);
        double disc = s->radius * s->radius - rrv__dot(perp, perp), sq, q, t0, t1, t;
        if (disc < 0) return 0;
        sq = sqrt(disc);
        q = b > 0 ? -b - sq : -b + sq;
        t0 = rrv__dot(oc, oc) - s->radius * s->radius;
        t0 = q != 0 ? t0 / q : 0;
        t1 = q;
        if (t0 > t1) { t = t0; t0 = t1; t1 = t; }
        t = t0 > 0 ? t0 : t1;
        if (t <= 0 || t >= tmax) return 0;
        hit->t = t;
        hit->p = rrv__madd(o, d, t);
        hit->n = rrv__scale(rrv__sub(hit->p, s->center), 1.0 / s->radius);
        return 1;
    } else {
        /* Moller-Trumbore; a quad is the same test with the (u, v) range
           widened from the triangle to the parallelogram. */
        rrv_vec3 pv = rrv__cross(d, s->e2), tv, qv;
        double det = rrv__dot(s->e1, pv), inv, u, v, t;
        if (det == 0) return 0;
        inv = 1.0 / det;
        tv = rrv__sub(o, s->p0);
        u = rrv__dot(tv, pv) * inv;
        if (u < 0 || u > 1) return 0;
        qv = rrv__cross(tv, s->e1);
        v = rrv__dot(d, qv) * inv;
        if (v < 0 || (s->kind == RRV_SHAPE_TRIANGLE ? u + v > 1 : v > 1)) return 0;
        t = rrv__dot(s->e2, qv) * inv;
        if (t <= 0 || t >= tmax) return 0;
        hit->t = t;
        hit->p = rrv__madd(o, d, t);
        hit->n = rrv__normalize(rrv__cross(s->e1, s->e2));
        return 1;
    }
}

static int rrv__box_hit(rrv_vec3 lo, rrv_vec3 hi, rrv_vec3 o, rrv_vec3 inv_d, double tmax, double *t_enter)
{
    double t0 = 0, t1 = tmax;
    int axis;
    for (axis = 0; axis < 3; ++axis) {
        double inv = rrv__axis(inv_d, axis), oa = rrv__axis(o, axis);
        double ta = (rrv__axis(lo, axis) - oa) * inv, tb = (rrv__axis(hi, axis) - oa) * inv;
        if (ta > tb) { double tmp = ta; ta = tb; tb = tmp; }
        /* NaN from 0*inf (origin on a slab plane, ray parallel) must not
           reject: rrv__maxd/rrv__mind ignore a NaN second operand. */
        t0 = rrv__maxd(t0, ta);
        t1 = rrv__mind(t1, tb);
        if (t0 > t1) return 0;
    }
    if (t_enter) *t_enter = t0;
    return 1;
}

/* Closest hit along o + t d, t in (0, tmax); returns 1 and fills hit.
   inv: the reciprocals of d's components (a comb chord has them, see
   rrv__reciprocals), or NULL to compute them here. */
static int rrv__intersect_line(const rrv_scene *scene, rrv_vec3 o, rrv_vec3 d, const double *inv, double tmax,
                               rrv__hit *hit)
{
    int stack[64], top = 0, found = 0, node_index = 0;
    rrv_vec3 inv_d;
    if (!scene->bvh_node_count) return 0;
    inv_d = inv ? rrv__v3(inv[0], inv[1], inv[2]) : rrv__v3(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    for (;;) {
        const rrv__bvh_node *node = &scene->bvh[node_index];
        double t_enter;
        if (rrv__box_hit(node->lo, node->hi, o, inv_d, tmax, &t_enter)) {
            if (node->count) {
                int i;
                for (i = 0; i < node->count; ++i) {
                    int prim = scene->bvh_prims[node->first + i];
                    if (rrv__intersect_shape(&scene->shapes[prim], o, d, tmax, hit)) {
                        hit->shape = prim;
                        tmax = hit->t;
                        found = 1;
                    }
                }
            } else {
                stack[top++] = node->first;
                node_index = node_index + 1;
                continue;
            }
        }
        if (!top) break;
        node_index = stack[--top];
    }
    return found;
}

static int rrv__intersect_scene(const rrv_scene *scene, rrv_vec3 o, rrv_vec3 d, double tmax, rrv__hit *hit)
{
    return rrv__intersect_line(scene, o, d, NULL, tmax, hit);
}

typedef struct rrv__bvh_build {
    const rrv_scene *scene;
    rrv__bvh_node *nodes;
    int node_count;
    int *prims;
    rrv_vec3 *centroids, *los, *his;
} rrv__bvh_build;

#define RRV__BVH_BINS 12

static void rrv__bvh_bounds(const rrv__bvh_build *b, int first, int count, rrv_vec3 *lo, rrv_vec3 *hi,
                            rrv_vec3 *clo, rrv_vec3 *chi)
{
    int i;
    *lo = *clo = rrv__v3(DBL_MAX, DBL_MAX, DBL_MAX);
    *hi = *chi = rrv__v3(-DBL_MAX, -DBL_MAX, -DBL_MAX);
    for (i = first; i < first + count; ++i) {
        int p = b->prims[i];
        *lo = rrv__vmin(*lo, b->los[p]);
        *hi = rrv__vmax(*hi, b->his[p]);
        *clo = rrv__vmin(*clo, b->centroids[p]);
        *chi = rrv__vmax(*chi, b->centroids[p]);
    }
}

static double rrv__half_area(rrv_vec3 lo, rrv_vec3 hi)
{
    rrv_vec3 e = rrv__sub(hi, lo);
    if (e.x < 0) return 0;
    return e.x * e.y + e.y * e.z + e.z * e.x;
}

/* Binned SAH (Wald 2007): 12 bins per axis are within a few percent of the
   full sweep and keep the build linear per level. Depth is capped so the
   fixed traversal stack cannot overflow. */
static void rrv__bvh_split(rrv__bvh_build *b, int node_index, int first, int count, int depth)
{
    rrv__bvh_node *node = &b->nodes[node_index];
    rrv_vec3 clo, chi;
    int axis, best_axis = -1, best_bin = 0, i, mid, left;
    double best_cost = DBL_MAX;
    rrv__bvh_bounds(b, first, count, &node->lo, &node->hi, &clo, &chi);
    node->first = first;
    node->count = count;
    if (count <= 2 || depth >= 60) return;
    for (axis = 0; axis < 3; ++axis) {
        double cmin = rrv__axis(clo, axis), extent = rrv__axis(chi, axis) - cmin;
        rrv_vec3 blo[RRV__BVH_BINS], bhi[RRV__BVH_BINS];
        int bcount[RRV__BVH_BINS], k;
        /* An extent that overflows (centroids near +-DBL_MAX) cannot bin:
           its fractions would be NaN, and a NaN cast to int is undefined. */
        if (!(extent > 0) || extent > DBL_MAX) continue;
        for (k = 0; k < RRV__BVH_BINS; ++k) {
            blo[k] = rrv__v3(DBL_MAX, DBL_MAX, DBL_MAX);
            bhi[k] = rrv__v3(-DBL_MAX, -DBL_MAX, -DBL_MAX);
            bcount[k] = 0;
        }
        for (i = first; i < first + count; ++i) {
            int p = b->prims[i];
            double f = RRV__BVH_BINS * ((rrv__axis(b->centroids[p], axis) - cmin) / extent);
            int bin = !(f > 0) ? 0 : f >= RRV__BVH_BINS ? RRV__BVH_BINS - 1 : (int)f;
            blo[bin] = rrv__vmin(blo[bin], b->los[p]);
            bhi[bin] = rrv__vmax(bhi[bin], b->his[p]);
            bcount[bin]++;
        }
        for (k = 1; k < RRV__BVH_BINS; ++k) {
            rrv_vec3 llo = rrv__v3(DBL_MAX, DBL_MAX, DBL_MAX), lhi = rrv__v3(-DBL_MAX, -DBL_MAX, -DBL_MAX);
            rrv_vec3 rlo = llo, rhi = lhi;
            int lc = 0, rc = 0, j;
            double cost;
            for (j = 0; j < k; ++j) { llo = rrv__vmin(llo, blo[j]); lhi = rrv__vmax(lhi, bhi[j]); lc += bcount[j]; }
            for (j = k; j < RRV__BVH_BINS; ++j) { rlo = rrv__vmin(rlo, blo[j]); rhi = rrv__vmax(rhi, bhi[j]); rc += bcount[j]; }
            if (!lc || !rc) continue;
            cost = lc * rrv__half_area(llo, lhi) + rc * rrv__half_area(rlo, rhi);
            if (cost < best_cost) { best_cost = cost; best_axis = axis; best_bin = k; }
        }
    }
    if (best_axis < 0 || best_cost >= count * rrv__half_area(node->lo, node->hi)) {
        if (count <= 8) return;
        if (best_axis < 0) return; /* all centroids coincide: nothing to split */
    }
    {
        double cmin = rrv__axis(clo, best_axis), extent = rrv__axis(chi, best_axis) - cmin;
        mid = first;
        for (i = first; i < first + count; ++i) {
            int p = b->prims[i];
            /* the binning's own expression: times the bins after the
               division, or a span near DBL_MAX overflows to inf */
            double f = RRV__BVH_BINS * ((rrv__axis(b->centroids[p], best_axis) - cmin) / extent);
            int bin = !(f > 0) ? 0 : f >= RRV__BVH_BINS ? RRV__BVH_BINS - 1 : (int)f;
            if (bin < best_bin) { b->prims[i] = b->prims[mid]; b->prims[mid] = p; mid++; }
        }
    }
    left = b->node_count++;
    node->count = 0;
    rrv__bvh_split(b, left, first, mid - first, depth + 1);
    b->nodes[node_index].first = b->node_count++;
    rrv__bvh_split(b, b->nodes[node_index].first, mid, first + count - mid, depth + 1);
}

static rrv_result rrv__build_bvh(rrv_scene *scene, rrv_error *err)
{
    rrv__bvh_build b;
    int n = scene->shape_count, i;
    size_t bytes;
    scene->bvh = NULL;
    scene->bvh_prims = NULL;
    scene->bvh_node_count = 0;
    if (n == 0) return RRV_OK;
    b.scene = scene;
    b.node_count = 1;
    bytes = (size_t)(2 * n) * sizeof(rrv__bvh_node) + (size_t)n * sizeof(int);
    b.nodes = (rrv__bvh_node *)RRV_MALLOC((size_t)(2 * n) * sizeof(rrv__bvh_node));
    b.prims = (int *)RRV_MALLOC((size_t)n * sizeof(int));
    b.centroids = (rrv_vec3 *)RRV_MALLOC((size_t)n * 3 * sizeof(rrv_vec3));
    if (!b.nodes || !b.prims || !b.centroids) {
        RRV_FREE(b.nodes); RRV_FREE(b.prims); RRV_FREE(b.centroids);
        return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory building the BVH");
    }
    b.los = b.centroids + n;
    b.his = b.centroids + 2 * n;
    for (i = 0; i < n; ++i) {
        rrv__shape_bounds(&scene->shapes[i], &b.los[i], &b.his[i]);
        b.centroids[i] = rrv__scale(rrv__add(b.los[i], b.his[i]), 0.5);
        b.prims[i] = i;
    }
    rrv__bvh_split(&b, 0, 0, n, 0);
    RRV_FREE(b.centroids);
    scene->bvh = b.nodes;
    scene->bvh_prims = b.prims;
    scene->bvh_node_count = b.node_count;
    scene->bytes += bytes;
    return RRV_OK;
}

/* >> 5 fields and refractivity: densities, grids, gas state, the IOR ======== */

static double rrv__smoothstep(double e0, double e1, double x)
{
    double t = rrv__clamp((x - e0) / (e1 - e0), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

static int rrv__inside_box(rrv_vec3 p, rrv_vec3 lo, rrv_vec3 hi)
{
    return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z;
}

/* Where p falls in a grid: the cell's lower sample, the trilinear weights,
   the sample spacing and the strides between samples. p must be inside. */
typedef struct rrv__grid_cell {
    int n[3], i0[3];
    double t[3], step[3];
    size_t stride[3], base; /* base: offset of the lower corner's channel 0 */
} rrv__grid_cell;

static void rrv__grid_locate(const rrv_grid *g, rrv_vec3 p, rrv__grid_cell *cell)
{
    double lo[3], hi[3], f[3];
    int a;
    cell->n[0] = g->nx; cell->n[1] = g->ny; cell->n[2] = g->nz;
    lo[0] = g->lo.x; lo[1] = g->lo.y; lo[2] = g->lo.z;
    hi[0] = g->hi.x; hi[1] = g->hi.y; hi[2] = g->hi.z;
    f[0] = p.x; f[1] = p.y; f[2] = p.z;
    cell->stride[0] = (size_t)g->channels;
    cell->stride[1] = cell->stride[0] * (size_t)g->nx;
    cell->stride[2] = cell->stride[1] * (size_t)g->ny;
    cell->base = 0;
    for (a = 0; a < 3; ++a) {
        double u = (f[a] - lo[a]) / (hi[a] - lo[a]) * (cell->n[a] - 1);
        int i = (int)u;
        if (i > cell->n[a] - 2) i = cell->n[a] - 2;
        if (i < 0) i = 0;
        cell->i0[a] = i;
        cell->t[a] = u - i;
        cell->step[a] = (hi[a] - lo[a]) / (cell->n[a] - 1);
        cell->base += (size_t)i * cell->stride[a];
    }
}

/* Trilinear blend of channel c around a located cell. In double: a float
   difference of neighbouring samples would round away what a refractivity
   grid resolves (a fire changes eta - 1 by ~2e-4, a few hundred float ulps
   of the stored values). */
static double rrv__grid_blend(const rrv_grid *g, const rrv__grid_cell *cell, int c)
{
    const float *d = g->data + cell->base + c;
    size_t sx = cell->stride[0], sy = cell->stride[1], sz = cell->stride[2];
    double tx = cell->t[0];
    double c00 = (double)d[0] + tx * ((double)d[sx] - d[0]);
    double c10 = (double)d[sy] + tx * ((double)d[sy + sx] - d[sy]);
    double c01 = (double)d[sz] + tx * ((double)d[sz + sx] - d[sz]);
    double c11 = (double)d[sz + sy] + tx * ((double)d[sz + sy + sx] - d[sz + sy]);
    c00 += cell->t[1] * (c10 - c00);
    c01 += cell->t[1] * (c11 - c01);
    return c00 + cell->t[2] * (c01 - c00);
}

/* Trilinear interpolation between corner-placed samples (CONVENTIONS):
   sample i along x sits at lo.x + i (hi.x - lo.x)/(nx - 1). Outside the
   grid's box the caller's ambient value applies. */
static double rrv__grid_sample(const rrv_grid *g, rrv_vec3 p, int channel, double outside)
{
    rrv__grid_cell cell;
    if (!rrv__inside_box(p, g->lo, g->hi)) return outside;
    rrv__grid_locate(g, p, &cell);
    return rrv__grid_blend(g, &cell, channel);
}

/* ---- NanoVDB grids: sparse lookup ---------------------------------------------
   The buffer was validated when it was read (the loader below the image
   I/O section): every node a lookup can reach lies inside it and has the
   size its type needs, so the lookups here read without checks. Bytes are
   decoded little-endian one by one: a grid sits at any offset in its file,
   so nothing here is aligned. */

/* Byte sizes and offsets of NanoVDB 32.x nodes (values are 4-byte floats
   in every supported type; internal tables hold 8-byte unions). */
#define RRV__NV_GRID 672
#define RRV__NV_TREE 64
#define RRV__NV_ROOT 64
#define RRV__NV_TILE 32
#define RRV__NV_UPPER 270400
#define RRV__NV_UPPER_TABLE 8256
#define RRV__NV_LOWER 33856
#define RRV__NV_LOWER_TABLE 1088
#define RRV__NV_LEAF_DATA 96

static uint32_t rrv__nv_u32(const unsigned char *b)
{
    return (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) | ((uint32_t)b[3] << 24);
}

static uint64_t rrv__nv_u64(const unsigned char *b)
{
    return (uint64_t)rrv__nv_u32(b) | ((uint64_t)rrv__nv_u32(b + 4) << 32);
}

static float rrv__nv_f32(const unsigned char *b)
{
    uint32_t u = rrv__nv_u32(b);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Value n (x << 6 | y << 3 | z) of a leaf. Quantised leaves decode as
   NanoVDB does, code * quantum + minimum in float, so they read back the
   very floats NanoVDB's own accessors return. */
static float rrv__nv_leaf_value(rrv_nanovdb_type type, const unsigned char *leaf, unsigned n)
{
    const unsigned char *v = leaf + RRV__NV_LEAF_DATA;
    unsigned code;
    switch (type) {
    case RRV_NANOVDB_FLOAT: return rrv__nv_f32(v + 4 * n);
    case RRV_NANOVDB_FP4: code = (v[n >> 1] >> ((n & 1) << 2)) & 15u; break;
    case RRV_NANOVDB_FP8: code = v[n]; break;
    case RRV_NANOVDB_FP16: code = (unsigned)v[2 * n] | ((unsigned)v[2 * n + 1] << 8); break;
    default: {
        /* FpN: 2^b bits a value, b = flags >> 5 in 0..4, packed in words */
        unsigned b = leaf[15] >> 5;
        uint32_t word = rrv__nv_u32(v + 4 * (n >> (5 - b)));
        code = (unsigned)((word >> ((n & ((32u >> b) - 1)) << b)) & ((1u << (1u << b)) - 1u));
        break;
    }
    }
    return (float)code * rrv__nv_f32(leaf + 84) + rrv__nv_f32(leaf + 80);
}

/* The leaf holding index point (i, j, k), or NULL with *value the tile (or
   background) value that covers it. */
static const unsigned char *rrv__nv_find(const rrv_nanovdb *g, int32_t i, int32_t j, int32_t k, float *value)
{
    const unsigned char *root = g->buffer + g->root, *tile = root + RRV__NV_ROOT, *node;
    uint64_t key = ((uint64_t)((uint32_t)i >> 12) << 42) | ((uint64_t)((uint32_t)j >> 12) << 21) |
                   (uint64_t)((uint32_t)k >> 12);
    uint32_t t, n;
    int64_t child;
    for (t = 0; t < g->root_tiles; ++t, tile += RRV__NV_TILE)
        if (rrv__nv_u64(tile) == key) break;
    if (t == g->root_tiles) {
        *value = (float)g->background;
        return NULL;
    }
    child = (int64_t)rrv__nv_u64(tile + 8);
    if (child == 0) {
        *value = rrv__nv_f32(tile + 20);
        return NULL;
    }
    node = root + child;
    n = ((((uint32_t)i & 4095u) >> 7) << 10) | ((((uint32_t)j & 4095u) >> 7) << 5) | (((uint32_t)k & 4095u) >> 7);
    if (!((node[32 + 4096 + (n >> 3)] >> (n & 7)) & 1)) {
        *value = rrv__nv_f32(node + RRV__NV_UPPER_TABLE + 8 * (size_t)n);
        return NULL;
    }
    node += (int64_t)rrv__nv_u64(node + RRV__NV_UPPER_TABLE + 8 * (size_t)n);
    n = ((((uint32_t)i & 127u) >> 3) << 8) | ((((uint32_t)j & 127u) >> 3) << 4) | (((uint32_t)k & 127u) >> 3);
    if (!((node[32 + 512 + (n >> 3)] >> (n & 7)) & 1)) {
        *value = rrv__nv_f32(node + RRV__NV_LOWER_TABLE + 8 * (size_t)n);
        return NULL;
    }
    return node + (int64_t)rrv__nv_u64(node + RRV__NV_LOWER_TABLE + 8 * (size_t)n);
}

RRV_DEF double rrv_nanovdb_voxel(const rrv_nanovdb *g, int64_t i, int64_t j, int64_t k)
{
    const unsigned char *leaf;
    float v;
    if (!g || !g->buffer) return 0.0;
    if (i < g->data_lo[0] || i > g->data_hi[0] || j < g->data_lo[1] || j > g->data_hi[1] ||
        k < g->data_lo[2] || k > g->data_hi[2])
        return g->background;
    leaf = rrv__nv_find(g, (int32_t)i, (int32_t)j, (int32_t)k, &v);
    if (leaf) v = rrv__nv_leaf_value(g->type, leaf, (unsigned)(((i & 7) << 6) | ((j & 7) << 3) | (k & 7)));
    return v;
}

/* World position to continuous index coordinates. */
static void rrv__nv_to_index(const rrv_nanovdb *g, rrv_vec3 p, double u[3])
{
    double d[3];
    int a;
    d[0] = p.x - g->translation[0];
    d[1] = p.y - g->translation[1];
    d[2] = p.z - g->translation[2];
    for (a = 0; a < 3; ++a) u[a] = g->inverse[3 * a] * d[0] + g->inverse[3 * a + 1] * d[1] + g->inverse[3 * a + 2] * d[2];
}

/* The eight values around leaf index n0 (corner bit 0: +x, 1: +y, 2: +z),
   none of them past the leaf's last row, with the type decided once. */
static void rrv__nv_leaf_corners(rrv_nanovdb_type type, const unsigned char *leaf, unsigned n0, double c[8])
{
    static const unsigned step[8] = {0, 64, 8, 72, 1, 65, 9, 73};
    int corner;
    if (type == RRV_NANOVDB_FLOAT) {
        const unsigned char *v = leaf + RRV__NV_LEAF_DATA + 4 * n0;
        for (corner = 0; corner < 8; ++corner) c[corner] = rrv__nv_f32(v + 4 * step[corner]);
        return;
    }
    for (corner = 0; corner < 8; ++corner) c[corner] = rrv__nv_leaf_value(type, leaf, n0 + step[corner]);
}

/* Trilinear at continuous index u. The eight index points lie in one leaf
   unless the lower ones sit on a leaf's last row along some axes; each
   distinct leaf (or tile) among them is descended to once: one descent for
   7/8 of the positions along each axis, at most eight at a leaf's corner.
   The one-leaf case (two positions in three) reads its corners in one go:
   it was most of a lookup's cost on a NanoVDB fire. */
static double rrv__nv_trilinear(const rrv_nanovdb *g, const double u[3])
{
    double f[3], t[3], c[8], c00, c10, c01, c11;
    const unsigned char *leaf[8];
    float tile[8];
    int64_t i0[3];
    int a, corner, cross = 0, near_edge = 0;
    for (a = 0; a < 3; ++a) {
        /* outside the data box (with one voxel to blend into) all is background */
        if (!(u[a] > (double)g->data_lo[a] - 1.0 && u[a] < (double)g->data_hi[a] + 1.0)) return g->background;
        /* a positive index truncates to its floor (and below 2^53 exactly) */
        f[a] = u[a] > 0 ? (double)(int64_t)u[a] : floor(u[a]);
        i0[a] = (int64_t)f[a];
        t[a] = u[a] - f[a];
        if ((i0[a] & 7) == 7) cross |= 1 << a;
        if (i0[a] < INT32_MIN || i0[a] >= INT32_MAX) near_edge = 1;
    }
    if (!cross && !near_edge) {
        const unsigned char *one = rrv__nv_find(g, (int32_t)i0[0], (int32_t)i0[1], (int32_t)i0[2], &tile[0]);
        if (one)
            rrv__nv_leaf_corners(g->type, one, (unsigned)(((i0[0] & 7) << 6) | ((i0[1] & 7) << 3) | (i0[2] & 7)), c);
        else
            for (corner = 0; corner < 8; ++corner) c[corner] = tile[0];
    } else {
        for (corner = 0; corner < 8; ++corner) {
            int64_t x = i0[0] + (corner & 1), y = i0[1] + ((corner >> 1) & 1), z = i0[2] + ((corner >> 2) & 1);
            int id = corner & cross;
            if (near_edge) {
                c[corner] = rrv_nanovdb_voxel(g, x, y, z);
                continue;
            }
            /* corners that differ only along axes that stay in the leaf share it */
            if (id == corner) leaf[id] = rrv__nv_find(g, (int32_t)x, (int32_t)y, (int32_t)z, &tile[id]);
            c[corner] = leaf[id] ? rrv__nv_leaf_value(g->type, leaf[id],
                                                      (unsigned)(((x & 7) << 6) | ((y & 7) << 3) | (z & 7)))
                                 : tile[id];
        }
    }
    /* corner bit 0: x, bit 1: y, bit 2: z */
    c00 = c[0] + t[0] * (c[1] - c[0]);
    c10 = c[2] + t[0] * (c[3] - c[2]);
    c01 = c[4] + t[0] * (c[5] - c[4]);
    c11 = c[6] + t[0] * (c[7] - c[6]);
    c00 += t[1] * (c10 - c00);
    c01 += t[1] * (c11 - c01);
    return c00 + t[2] * (c01 - c00);
}

RRV_DEF double rrv_nanovdb_sample(const rrv_nanovdb *g, rrv_vec3 p)
{
    double u[3];
    if (!g || !g->buffer) return 0.0;
    if (!rrv__inside_box(p, g->lo, g->hi)) return g->background;
    rrv__nv_to_index(g, p, u);
    return rrv__nv_trilinear(g, u);
}

/* Gradient in world space: central differences of the trilinear field one
   voxel apart along each index axis, mapped back by the inverse map's
   transpose (u = inverse (p - translation)). Second order and continuous
   across cell faces, as for gridvol grids. */
static rrv_vec3 rrv__nv_gradient(const rrv_nanovdb *g, rrv_vec3 p)
{
    double u[3], q[3], d[3];
    int a, b;
    rrv__nv_to_index(g, p, u);
    for (a = 0; a < 3; ++a) {
        double up, down;
        for (b = 0; b < 3; ++b) q[b] = u[b];
        q[a] = u[a] + 1.0;
        up = rrv__nv_trilinear(g, q);
        q[a] = u[a] - 1.0;
        down = rrv__nv_trilinear(g, q);
        d[a] = 0.5 * (up - down);
    }
    return rrv__v3(g->inverse[0] * d[0] + g->inverse[3] * d[1] + g->inverse[6] * d[2],
                   g->inverse[1] * d[0] + g->inverse[4] * d[1] + g->inverse[7] * d[2],
                   g->inverse[2] * d[0] + g->inverse[5] * d[1] + g->inverse[8] * d[2]);
}

#ifndef RRV_NO_CURVED_NEE /* derivatives of the gradient: the solvers' alone */
/* The Jacobian of rrv__nv_gradient (see the derivatives of the refractivity
   gradient below for why it is not symmetrised). In index space the
   gradient is d_a(u) = (T(u + e_a) - T(u - e_a)) / 2 of the trilinear T,
   which is linear along each axis inside a cell, so its slope along b at q
   is the difference of T at the two faces of q's cell along b. */
static double rrv__nv_slope(const rrv_nanovdb *g, const double q[3], int axis)
{
    double e[3];
    int a;
    for (a = 0; a < 3; ++a) e[a] = q[a];
    e[axis] = floor(q[axis]) + 1.0;
    {
        double up = rrv__nv_trilinear(g, e);
        e[axis] -= 1.0;
        return up - rrv__nv_trilinear(g, e);
    }
}

static void rrv__nv_gradient_jacobian(const rrv_nanovdb *g, rrv_vec3 p, double J[9])
{
    double u[3], q[3], D[9];
    int a, b, i, j;
    rrv__nv_to_index(g, p, u);
    for (a = 0; a < 3; ++a)
        for (b = 0; b < 3; ++b) {
            double up, down;
            for (i = 0; i < 3; ++i) q[i] = u[i];
            q[a] = u[a] + 1.0;
            up = rrv__nv_slope(g, q, b);
            q[a] = u[a] - 1.0;
            down = rrv__nv_slope(g, q, b);
            D[3 * a + b] = 0.5 * (up - down);
        }
    /* u_a = sum_j inverse[3 a + j] (p_j - translation_j) */
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) {
            double s = 0;
            for (a = 0; a < 3; ++a)
                for (b = 0; b < 3; ++b) s += g->inverse[3 * a + i] * D[3 * a + b] * g->inverse[3 * b + j];
            J[3 * i + j] = s;
        }
}
#endif

/* Tile extents by level: a root tile spans 4096 index points an axis, an
   upper node's entry 128, a lower node's entry 8 (one leaf). */
static const int rrv__nv_extent_log2[3] = {12, 7, 3};

static double rrv__nv_extreme(double best, double v, int upper) { return upper ? fmax(best, v) : fmin(best, v); }

/* The index box of the world box [lo, hi]: the map is affine, so its
   corners' (unrounded). */
static void rrv__nv_index_box(const rrv_nanovdb *g, rrv_vec3 lo, rrv_vec3 hi, double ulo[3], double uhi[3])
{
    int corner, a;
    for (a = 0; a < 3; ++a) {
        ulo[a] = DBL_MAX;
        uhi[a] = -DBL_MAX;
    }
    for (corner = 0; corner < 8; ++corner) {
        double u[3];
        rrv__nv_to_index(g, rrv__v3(corner & 1 ? hi.x : lo.x, corner & 2 ? hi.y : lo.y, corner & 4 ? hi.z : lo.z), u);
        for (a = 0; a < 3; ++a) {
            ulo[a] = fmin(ulo[a], u[a]);
            uhi[a] = fmax(uhi[a], u[a]);
        }
    }
}

/* A root tile's origin from its key: the top 20 bits of each coordinate,
   two's complement. */
static void rrv__nv_tile_origin(uint64_t key, int64_t o[3])
{
    o[0] = (int64_t)(int32_t)(uint32_t)(((key >> 42) & 0x1fffffu) << 12);
    o[1] = (int64_t)(int32_t)(uint32_t)(((key >> 21) & 0x1fffffu) << 12);
    o[2] = (int64_t)(int32_t)(uint32_t)((key & 0x1fffffu) << 12);
}

/* The largest (upper) or least value any index point in [lo, hi]
   (inclusive) holds below the node: tile values where tiles cover the box,
   leaf values inside it (a node's table leaves no index point out). Every
   stored value counts, active or not, since trilinear reads them all (the
   min/max NanoVDB keeps per node cover active values only). */
static double rrv__nv_node_extreme(const rrv_nanovdb *g, const unsigned char *node, int level, const int64_t o[3],
                                   const int64_t lo[3], const int64_t hi[3], int upper)
{
    double best = upper ? -DBL_MAX : DBL_MAX;
    int64_t a[3], b[3], x, y, z;
    int s = rrv__nv_extent_log2[level], dim = level == 1 ? 32 : 16, log2dim = level == 1 ? 5 : 4, c;
    size_t table = level == 1 ? RRV__NV_UPPER_TABLE : RRV__NV_LOWER_TABLE;
    size_t mask = level == 1 ? 32 + 4096 : 32 + 512;
    for (c = 0; c < 3; ++c) {
        a[c] = lo[c] > o[c] ? (lo[c] - o[c]) >> s : 0;
        b[c] = (hi[c] - o[c]) >> s;
        if (b[c] > dim - 1) b[c] = dim - 1;
    }
    for (x = a[0]; x <= b[0]; ++x)
        for (y = a[1]; y <= b[1]; ++y)
            for (z = a[2]; z <= b[2]; ++z) {
                unsigned n = (unsigned)((x << (2 * log2dim)) | (y << log2dim) | z);
                const unsigned char *entry = node + table + 8 * (size_t)n;
                if ((node[mask + (n >> 3)] >> (n & 7)) & 1) {
                    const unsigned char *child = node + (int64_t)rrv__nv_u64(entry);
                    int64_t co[3];
                    co[0] = o[0] + (x << s);
                    co[1] = o[1] + (y << s);
                    co[2] = o[2] + (z << s);
                    if (level == 1) {
                        best = rrv__nv_extreme(best, rrv__nv_node_extreme(g, child, 2, co, lo, hi, upper), upper);
                    } else {
                        int64_t i, j, k, l[3], h[3];
                        for (c = 0; c < 3; ++c) {
                            l[c] = lo[c] > co[c] ? lo[c] - co[c] : 0;
                            h[c] = hi[c] - co[c] < 7 ? hi[c] - co[c] : 7;
                        }
                        for (i = l[0]; i <= h[0]; ++i)
                            for (j = l[1]; j <= h[1]; ++j)
                                for (k = l[2]; k <= h[2]; ++k)
                                    best = rrv__nv_extreme(best, rrv__nv_leaf_value(g->type, child, (unsigned)((i << 6) | (j << 3) | k)),
                                                          upper);
                    }
                } else {
                    best = rrv__nv_extreme(best, rrv__nv_f32(entry), upper);
                }
            }
    return best;
}

/* An upper bound of the field over the world box [lo, hi]. */
static double rrv__nv_bound(const rrv_nanovdb *g, rrv_vec3 lo, rrv_vec3 hi)
{
    double ulo[3], uhi[3], best;
    int64_t ilo[3], ihi[3];
    const unsigned char *root = g->buffer + g->root;
    uint32_t t;
    int a;
    rrv__nv_index_box(g, lo, hi, ulo, uhi);
    best = g->background;
    for (a = 0; a < 3; ++a) {
        /* the index points whose cells touch the box, within the data */
        double l = fmax(floor(ulo[a]), (double)g->data_lo[a]), h = fmin(floor(uhi[a]) + 1.0, (double)g->data_hi[a]);
        if (!(l <= h)) return best;
        ilo[a] = (int64_t)l;
        ihi[a] = (int64_t)h;
    }
    for (t = 0; t < g->root_tiles; ++t) {
        const unsigned char *tile = root + RRV__NV_ROOT + (size_t)t * RRV__NV_TILE;
        uint64_t key = rrv__nv_u64(tile);
        int64_t o[3], child = (int64_t)rrv__nv_u64(tile + 8);
        int overlaps = 1;
        rrv__nv_tile_origin(key, o);
        for (a = 0; a < 3; ++a)
            if (o[a] > ihi[a] || o[a] + 4095 < ilo[a]) overlaps = 0;
        if (!overlaps) continue;
        if (child == 0)
            best = fmax(best, rrv__nv_f32(tile + 20));
        else
            best = fmax(best, rrv__nv_node_extreme(g, root + child, 1, o, ilo, ihi, 1));
    }
    return best;
}

/* A lower bound of the field over the world box [lo, hi]: the least value
   of the index points trilinear may read there, and the background wherever
   the box may reach beyond the data, beyond the grid's box, or into a root
   tile the tree does not hold (rrv__nv_bound's rules, the other way). */
static double rrv__nv_lower(const rrv_nanovdb *g, rrv_vec3 lo, rrv_vec3 hi)
{
    double ulo[3], uhi[3], least = DBL_MAX;
    int64_t ilo[3], ihi[3], blocks = 1, tiles = 0;
    const unsigned char *root = g->buffer + g->root;
    uint32_t t;
    int a;
    if (!g->buffer) return 0;
    if (!rrv__inside_box(lo, g->lo, g->hi) || !rrv__inside_box(hi, g->lo, g->hi)) least = g->background;
    rrv__nv_index_box(g, lo, hi, ulo, uhi);
    for (a = 0; a < 3; ++a) {
        double l = floor(ulo[a]), h = floor(uhi[a]) + 1.0;
        if (l < (double)g->data_lo[a] || h > (double)g->data_hi[a]) least = fmin(least, g->background);
        l = fmax(l, (double)g->data_lo[a]);
        h = fmin(h, (double)g->data_hi[a]);
        if (!(l <= h)) return fmin(least, g->background);
        ilo[a] = (int64_t)l;
        ihi[a] = (int64_t)h;
        /* root tiles (4096 points an axis) the box spans */
        blocks *= (ihi[a] >> 12) - (ilo[a] >> 12) + 1;
    }
    for (t = 0; t < g->root_tiles; ++t) {
        const unsigned char *tile = root + RRV__NV_ROOT + (size_t)t * RRV__NV_TILE;
        uint64_t key = rrv__nv_u64(tile);
        int64_t o[3], child = (int64_t)rrv__nv_u64(tile + 8);
        int overlaps = 1;
        rrv__nv_tile_origin(key, o);
        for (a = 0; a < 3; ++a)
            if (o[a] > ihi[a] || o[a] + 4095 < ilo[a]) overlaps = 0;
        if (!overlaps) continue;
        ++tiles;
        if (child == 0)
            least = fmin(least, rrv__nv_f32(tile + 20));
        else
            least = fmin(least, rrv__nv_node_extreme(g, root + child, 1, o, ilo, ihi, 0));
    }
    /* keys are distinct, so fewer tiles than blocks leaves a block to the background */
    if (tiles < blocks) least = fmin(least, g->background);
    return least < DBL_MAX ? fmax(0.0, least) : 0.0;
}

/* Value noise on an integer lattice hashed from the seed: cheap, bounded in
   [0,1] by construction, which is what lets the majorant be a true bound. */
static double rrv__lattice(uint32_t x, uint32_t y, uint32_t z, uint32_t seed)
{
    uint64_t h = rrv__mix64(((uint64_t)x * 73856093u) ^ ((uint64_t)y * 19349663u << 20) ^
                            ((uint64_t)z * 83492791u << 40) ^ ((uint64_t)seed << 12));
    return (double)(h >> 11) * (1.0 / 9007199254740992.0);
}

/* A lattice coordinate reduced modulo 2^32 in double before the cast: in a
   huge medium box floor(p) lies beyond int, where the conversion is
   undefined, and the hash only sees the low 32 bits anyway (the same bits
   the old int-then-unsigned conversion gave, so images did not change). */
static uint32_t rrv__lattice_coord(double f)
{
    double m;
    /* the usual case without fmod (a fifth of a noise bake once): an
       integer this small converts exactly, and its low 32 bits are the
       residue modulo 2^32 */
    if (f > -4503599627370496.0 && f < 4503599627370496.0) return (uint32_t)(uint64_t)(int64_t)f;
    m = fmod(f, 4294967296.0);
    if (m < 0) m += 4294967296.0;
    return m >= 0 && m < 4294967296.0 ? (uint32_t)m : 0u;
}

static double rrv__value_noise(rrv_vec3 p, uint32_t seed)
{
    double fx = floor(p.x), fy = floor(p.y), fz = floor(p.z);
    uint32_t x = rrv__lattice_coord(fx), y = rrv__lattice_coord(fy), z = rrv__lattice_coord(fz);
    double tx = p.x - fx, ty = p.y - fy, tz = p.z - fz;
    double sx = tx * tx * (3 - 2 * tx), sy = ty * ty * (3 - 2 * ty), sz = tz * tz * (3 - 2 * tz);
    double a = rrv__lattice(x, y, z, seed), b = rrv__lattice(x + 1, y, z, seed);
    double c = rrv__lattice(x, y + 1, z, seed), d = rrv__lattice(x + 1, y + 1, z, seed);
    double e = rrv__lattice(x, y, z + 1, seed), f = rrv__lattice(x + 1, y, z + 1, seed);
    double g = rrv__lattice(x, y + 1, z + 1, seed), h = rrv__lattice(x + 1, y + 1, z + 1, seed);
    double ab = a + sx * (b - a), cd = c + sx * (d - c), ef = e + sx * (f - e), gh = g + sx * (h - g);
    double lo = ab + sy * (cd - ab), hi = ef + sy * (gh - ef);
    return lo + sz * (hi - lo);
}

static double rrv__fbm(const rrv_noise *n, rrv_vec3 p)
{
    double sum = 0, norm = 0, amp = 1, freq = n->frequency, v;
    int o;
    for (o = 0; o < n->octaves; ++o) {
        /* Each octave is offset so that lattice points do not line up. */
        rrv_vec3 q = rrv__v3(p.x * freq + 17.3 * o, p.y * freq + 31.7 * o, p.z * freq + 5.1 * o);
        sum += amp * rrv__value_noise(q, n->seed + (uint32_t)o);
        norm += amp;
        amp *= n->gain;
        freq *= n->lacunarity;
    }
    v = norm > 0 ? sum / norm : 0;
    if (n->threshold > 0) v = fmax(0.0, (v - n->threshold) / (1.0 - n->threshold));
    return v;
}

/* The plume falloff: a column over `center` whose radius grows from 0.4 R at
   its base (center.y - R) to R at its top (center.y + 2R). */
static double rrv__plume_radius(const rrv_noise *n, double y)
{
    double s = rrv__clamp((y - (n->center.y - n->radius)) / (3.0 * n->radius), 0.0, 1.0);
    return n->radius * (0.4 + 0.6 * s);
}

static double rrv__falloff(const rrv_noise *n, rrv_vec3 p)
{
    rrv_vec3 d = rrv__sub(p, n->center);
    switch (n->falloff) {
    case RRV_FALLOFF_SPHERE:
        return 1.0 - rrv__smoothstep(0.5 * n->radius, n->radius, rrv__length(d));
    case RRV_FALLOFF_PLUME: {
        double rho = sqrt(d.x * d.x + d.z * d.z), r = rrv__plume_radius(n, p.y);
        double vertical = rrv__smoothstep(-n->radius, -0.7 * n->radius, d.y) *
                          (1.0 - rrv__smoothstep(1.5 * n->radius, 2.0 * n->radius, d.y));
        return vertical * (1.0 - rrv__smoothstep(0.5 * r, r, rho));
    }
    default:
        return 1.0;
    }
}

/* An upper bound of the falloff over a box, for the majorant grid. */
static double rrv__falloff_bound(const rrv_noise *n, rrv_vec3 lo, rrv_vec3 hi)
{
    rrv_vec3 c = n->center;
    rrv_vec3 nearest = rrv__vmax(lo, rrv__vmin(hi, c));
    switch (n->falloff) {
    case RRV_FALLOFF_SPHERE:
        return 1.0 - rrv__smoothstep(0.5 * n->radius, n->radius, rrv__length(rrv__sub(nearest, c)));
    case RRV_FALLOFF_PLUME: {
        double dx = nearest.x - c.x, dz = nearest.z - c.z;
        double rho = sqrt(dx * dx + dz * dz), r = rrv__plume_radius(n, hi.y);
        if (hi.y < c.y - n->radius || lo.y > c.y + 2.0 * n->radius) return 0.0;
        return 1.0 - rrv__smoothstep(0.5 * r, r, rho);
    }
    default:
        return 1.0;
    }
}

static double rrv__blobs_eval(const rrv_field *f, rrv_vec3 p)
{
    double sum = f->base;
    int i;
    for (i = 0; i < f->blob_count; ++i) {
        const rrv_blob *b = &f->blobs[i];
        rrv_vec3 d = rrv__sub(p, b->center);
        double q = rrv__dot(d, d) / (b->radius * b->radius);
        /* Beyond 6 sigma a blob adds < 1.6e-8 of its weight. */
        if (q < 72.0) sum += b->weight * exp(-0.5 * q);
    }
    return sum;
}

/* A field's value at p inside its medium's box (channel for 3-channel grids). */
static double rrv__field_eval(const rrv_field *f, rrv_vec3 p, int channel, double ambient)
{
    switch (f->kind) {
    case RRV_FIELD_CONSTANT: return f->value;
    case RRV_FIELD_BLOBS: return rrv__blobs_eval(f, p);
    case RRV_FIELD_NOISE:
        return f->base + f->amplitude * rrv__falloff(&f->noise, p) * rrv__fbm(&f->noise, p);
    case RRV_FIELD_GRID:
        return rrv__grid_sample(&f->grid, p, f->grid.channels == 3 ? channel : 0, ambient);
    case RRV_FIELD_NANOVDB: return rrv_nanovdb_sample(&f->nanovdb, p);
    default: return ambient;
    }
}

/* The samples [a, b] (per axis, inclusive) of a grid whose cells touch the
   box [lo, hi]; 0 if the box misses the grid. Trilinear values never exceed
   those samples, so their max bounds the field over the box. A box that
   reaches into a cell by less than 1e-9 of it is taken not to (unless the
   box is itself that thin, a medium inside one voxel of a huge grid, where
   skipping it would leave the medium empty): majorant
   cells aligned with the voxels otherwise pick up their neighbours' samples
   through the rounding of their corners (a single voxel of 1e8 then spread
   its majorant over 4^3 voxels of nothing), and what the sliver misses is
   at most 1e-9 of a voxel's optical depth. */
static int rrv__grid_span(const rrv_grid *g, rrv_vec3 lo, rrv_vec3 hi, int a[3], int b[3])
{
    int dim[3], c;
    double glo[3], ghi[3], blo[3], bhi[3];
    dim[0] = g->nx; dim[1] = g->ny; dim[2] = g->nz;
    glo[0] = g->lo.x; glo[1] = g->lo.y; glo[2] = g->lo.z;
    ghi[0] = g->hi.x; ghi[1] = g->hi.y; ghi[2] = g->hi.z;
    blo[0] = lo.x; blo[1] = lo.y; blo[2] = lo.z;
    bhi[0] = hi.x; bhi[1] = hi.y; bhi[2] = hi.z;
    for (c = 0; c < 3; ++c) {
        double s = (dim[c] - 1) / (ghi[c] - glo[c]);
        double fa = floor((blo[c] - glo[c]) * s + 1e-9), fb = ceil((bhi[c] - glo[c]) * s - 1e-9);
        if (fa > fb) { /* the box is itself a sliver: all of it counts */
            fa = floor((blo[c] - glo[c]) * s);
            fb = ceil((bhi[c] - glo[c]) * s);
        }
        if (!(fb >= 0) || !(fa <= dim[c] - 1)) return 0;
        a[c] = fa < 0 ? 0 : (int)fa;
        b[c] = fb > dim[c] - 1 ? dim[c] - 1 : (int)fb;
    }
    return 1;
}

/* Whether the box reaches into the grid's box by more than 1e-9 of a voxel
   on every axis, or by 1e-9 of the box where the box is thinner than a
   voxel (the sliver rule of rrv__grid_span, here for the grid's own
   faces): a majorant cell just outside a grid whose faces it shares would
   otherwise take the density on the face, and a ray through that cell,
   where the density is 0, pays null collisions at that rate. */
static int rrv__grid_reaches(const rrv_grid *g, rrv_vec3 lo, rrv_vec3 hi)
{
    int a;
    for (a = 0; a < 3; ++a) {
        double glo = rrv__axis(g->lo, a), ghi = rrv__axis(g->hi, a);
        int voxels = (a == 0 ? g->nx : a == 1 ? g->ny : g->nz) - 1;
        double overlap = rrv__mind(rrv__axis(hi, a), ghi) - rrv__maxd(rrv__axis(lo, a), glo);
        double extent = rrv__axis(hi, a) - rrv__axis(lo, a);
        if (!(overlap > 1e-9 * rrv__mind((ghi - glo) / voxels, extent))) return 0;
    }
    return 1;
}

/* The points of one axis of a grid at which rrv__grid_bound evaluates the
   field, as sample index i0 and fraction t of the way to sample i0 + 1:
   where the box lies within one voxel along the axis, the two points where
   its faces cut it; else every sample plane of its span. */
typedef struct rrv__grid_axis_points {
    int count, first, last_index;
    int cut_i0[2];
    double cut_t[2];
} rrv__grid_axis_points;

static void rrv__grid_axis_point(const rrv__grid_axis_points *pts, int j, int *i0, double *t)
{
    if (pts->count == 2 && pts->cut_i0[0] >= 0) {
        *i0 = pts->cut_i0[j];
        *t = pts->cut_t[j];
    } else {
        int k = pts->first + j;
        *i0 = k > pts->last_index ? pts->last_index : k;
        *t = (double)(k - *i0);
    }
}

/* An upper bound of a grid's (non-negative) trilinear field over the box,
   whose span of samples [a, b] is known. Along an axis where the box
   spans more than one voxel, the field (piecewise linear along it, with
   knots at the sample planes) is bounded by its values on the span's
   sample planes; where the box lies within one voxel, its max sits where
   the box's faces cut the axis, and taking those two points instead makes
   the bound exact. A box of more than a voxel on every axis (majorant
   cells over a fine grid) is thus bounded by the max of its samples, as
   always; a coarse grid under finer cells (a 2^3 grid of 1e10 in a
   corner) gets each cell's own max rather than the corner's value, which
   sent walks through the nearly empty rest into billions of null
   collisions. Exact because the field is multilinear in each voxel: with
   the other coordinates fixed, its max along each axis is at one of the
   axis's points. */
static double rrv__grid_bound(const rrv_grid *g, rrv_vec3 lo, rrv_vec3 hi, const int a[3], const int b[3])
{
    int dim[3], ax, i, j, k, c, corner, any_cut = 0;
    size_t stride[3];
    double samples = 0, best = 0;
    rrv__grid_axis_points pts[3];
    dim[0] = g->nx; dim[1] = g->ny; dim[2] = g->nz;
    stride[0] = (size_t)g->channels;
    stride[1] = stride[0] * (size_t)g->nx;
    stride[2] = stride[1] * (size_t)g->ny;
    for (ax = 0; ax < 3; ++ax) {
        pts[ax].first = a[ax];
        pts[ax].last_index = dim[ax] - 2;
        pts[ax].count = b[ax] - a[ax] + 1;
        pts[ax].cut_i0[0] = -1;
        if (b[ax] - a[ax] == 1) {
            double glo = rrv__axis(g->lo, ax), s = (dim[ax] - 1) / (rrv__axis(g->hi, ax) - glo);
            double u[2];
            int e;
            u[0] = rrv__clamp((rrv__axis(lo, ax) - glo) * s, a[ax], b[ax]);
            u[1] = rrv__clamp((rrv__axis(hi, ax) - glo) * s, a[ax], b[ax]);
            for (e = 0; e < 2; ++e) {
                pts[ax].cut_i0[e] = a[ax];
                pts[ax].cut_t[e] = u[e] - a[ax];
            }
            any_cut = 1;
        }
    }
    /* the samples' max: the bound where no axis is cut, else a cap */
    for (k = a[2]; k <= b[2]; ++k)
        for (j = a[1]; j <= b[1]; ++j)
            for (i = a[0]; i <= b[0]; ++i) {
                size_t n = (size_t)k * stride[2] + (size_t)j * stride[1] + (size_t)i * stride[0];
                for (c = 0; c < g->channels; ++c) samples = fmax(samples, g->data[n + (size_t)c]);
            }
    if (!any_cut) return samples;
    for (k = 0; k < pts[2].count; ++k)
        for (j = 0; j < pts[1].count; ++j)
            for (i = 0; i < pts[0].count; ++i) {
                int idx[3];
                double w[3];
                size_t n;
                rrv__grid_axis_point(&pts[0], i, &idx[0], &w[0]);
                rrv__grid_axis_point(&pts[1], j, &idx[1], &w[1]);
                rrv__grid_axis_point(&pts[2], k, &idx[2], &w[2]);
                n = (size_t)idx[2] * stride[2] + (size_t)idx[1] * stride[1] + (size_t)idx[0] * stride[0];
                for (c = 0; c < g->channels; ++c) {
                    double sum = 0;
                    for (corner = 0; corner < 8; ++corner) {
                        double weight = 1;
                        size_t at = n + (size_t)c;
                        for (ax = 0; ax < 3; ++ax) {
                            int up = (corner >> ax) & 1;
                            weight *= up ? w[ax] : 1.0 - w[ax];
                            if (up) at += stride[ax];
                        }
                        if (weight > 0) sum += weight * g->data[at];
                    }
                    best = fmax(best, sum);
                }
            }
    /* The lookups round too (their fractions carry the error of a position
       times the grid's resolution): a margin of 1e-9 of the samples covers
       that, and the samples' max stays a bound in any case. */
    return fmin(samples, best + 1e-9 * samples);
}

/* An upper bound of a non-negative field over a box (the majorant grid's cell). */
static double rrv__field_bound(const rrv_field *f, rrv_vec3 lo, rrv_vec3 hi)
{
    switch (f->kind) {
    case RRV_FIELD_CONSTANT: return f->value;
    case RRV_FIELD_BLOBS: {
        double sum = f->base;
        int i;
        for (i = 0; i < f->blob_count; ++i) {
            const rrv_blob *b = &f->blobs[i];
            rrv_vec3 d = rrv__sub(rrv__vmax(lo, rrv__vmin(hi, b->center)), b->center);
            if (b->weight > 0) sum += b->weight * exp(-0.5 * rrv__dot(d, d) / (b->radius * b->radius));
        }
        return sum;
    }
    case RRV_FIELD_NOISE:
        return f->base + fmax(0.0, f->amplitude) * rrv__falloff_bound(&f->noise, lo, hi);
    case RRV_FIELD_GRID: {
        const rrv_grid *g = &f->grid;
        int a[3], b[3];
        if (!rrv__grid_reaches(g, lo, hi) || !rrv__grid_span(g, lo, hi, a, b)) return 0;
        return rrv__grid_bound(g, lo, hi, a, b);
    }
    case RRV_FIELD_NANOVDB: return fmax(0.0, rrv__nv_bound(&f->nanovdb, lo, hi));
    default: return 0;
    }
}

static void rrv__grid_range(const rrv_grid *g, rrv_vec3 lo, rrv_vec3 hi, double *low, double *high);

/* A lower bound of a one-channel grid's trilinear field over a box inside
   the grid's box (0 where any of it lies outside, where lookups give 0):
   the exact range of rrv__grid_range where the box spans few sample planes,
   else the least sample of its span, since a trilinear value is a convex
   blend of samples. */
static double rrv__grid_lower(const rrv_grid *g, rrv_vec3 lo, rrv_vec3 hi)
{
    int a[3], b[3], i, j, k;
    double low, high, least = DBL_MAX;
    if (g->channels != 1 || !rrv__inside_box(lo, g->lo, g->hi) || !rrv__inside_box(hi, g->lo, g->hi)) return 0;
    rrv__grid_range(g, lo, hi, &low, &high);
    if (high < DBL_MAX) return low;
    if (!rrv__grid_span(g, lo, hi, a, b)) return 0;
    for (k = a[2]; k <= b[2]; ++k)
        for (j = a[1]; j <= b[1]; ++j)
            for (i = a[0]; i <= b[0]; ++i)
                least = fmin(least, g->data[((size_t)k * (size_t)g->ny + (size_t)j) * (size_t)g->nx + (size_t)i]);
    /* the span skips slivers under 1e-9 of a voxel (rrv__grid_span): so
       does this bound, by what a sliver's lookups can differ */
    return least;
}

/* A lower bound of a non-negative field over a box: the majorant grid's
   minorant, residual tracking's control. 0 where nothing better is known
   (noise, 3-channel grids), which leaves that cell's walk ratio tracking. */
static double rrv__field_lower(const rrv_field *f, rrv_vec3 lo, rrv_vec3 hi)
{
    if (!(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z)) return 0;
    switch (f->kind) {
    case RRV_FIELD_CONSTANT: return f->value;
    case RRV_FIELD_BLOBS: {
        /* each blob at its farthest point of the box (lookups drop a blob
           beyond 6 sigma, so then 0), a negative one at its nearest */
        double sum = f->base;
        int i;
        for (i = 0; i < f->blob_count; ++i) {
            const rrv_blob *b = &f->blobs[i];
            double r2 = b->radius * b->radius, q;
            rrv_vec3 d;
            if (b->weight < 0) {
                d = rrv__sub(rrv__vmax(lo, rrv__vmin(hi, b->center)), b->center);
            } else {
                d.x = fmax(fabs(lo.x - b->center.x), fabs(hi.x - b->center.x));
                d.y = fmax(fabs(lo.y - b->center.y), fabs(hi.y - b->center.y));
                d.z = fmax(fabs(lo.z - b->center.z), fabs(hi.z - b->center.z));
            }
            q = rrv__dot(d, d) / r2;
            if (b->weight < 0) sum += b->weight * exp(-0.5 * q);
            else if (q < 72.0) sum += b->weight * exp(-0.5 * q);
        }
        /* exp's rounding: a relative margin keeps this below every lookup */
        return sum - 1e-12 * fabs(sum);
    }
    case RRV_FIELD_GRID: return rrv__grid_lower(&f->grid, lo, hi);
    case RRV_FIELD_NANOVDB: return rrv__nv_lower(&f->nanovdb, lo, hi);
    default: return 0;
    }
}

/* ---- the refractive index: refractivity r = eta - 1 and its gradient ------ */

/* Refractivity of the medium's own IOR profile at p (not scaled). */
static double rrv__profile_refractivity(const rrv_field *f, rrv_vec3 p, double ambient_r)
{
    rrv_vec3 d = rrv__sub(p, f->center);
    double q;
    switch (f->kind) {
    case RRV_FIELD_LUNEBURG:
        q = rrv__dot(d, d) / (f->radius * f->radius);
        return q < 1.0 ? sqrt(2.0 - q) - 1.0 : 0.0;
    case RRV_FIELD_FISHEYE:
        q = rrv__dot(d, d) / (f->radius * f->radius);
        return q < 1.0 ? f->n0 / (1.0 + q) - 1.0 : f->n0 * 0.5 - 1.0;
    case RRV_FIELD_SLAB:
        return f->base + f->gradient * rrv__dot(d, f->normal);
    case RRV_FIELD_SHELL: {
        double r = rrv__length(d), inner = f->radius - f->thickness;
        return f->base + f->amplitude * 0.5 * (tanh((r - inner) / f->edge) - tanh((r - f->radius) / f->edge));
    }
    default:
        return rrv__field_eval(f, p, 0, ambient_r);
    }
}

/* What rrv_scene_prepare builds for a medium: the majorant grid (below) and
   procedural fields baked into grids. Fractal noise costs 5 octaves x 8
   hashed lattice corners a lookup; baked, a lookup is one trilinear fetch,
   and the majorant bound over it is exact. The user's fields stay as given. */
enum { RRV__DENSITY, RRV__TEMPERATURE, RRV__PRESSURE, RRV__IOR, RRV__FIELD_KINDS };

/* 1: the comb's chords are limited by a per-cell bound on how much the
   gradient's Jacobian varies (rrv__cell_jacobian_wander) instead of
   RRV__COMB_MAX_CELLS cells, where the gradient is a baked trilinear grid.
   Off by default: at equal landing error it measured no fewer kicks (README,
   "Refraction overhead"); a measurement build may set it. */
#ifndef RRV__COMB_WANDER
#define RRV__COMB_WANDER 0
#endif
/* Its h^2 W <= BUDGET tau tolerance (rrv__rate_distance); 4 bounds a
   kick's error by the tolerance, a measurement build may set another. */
#ifndef RRV__COMB_WANDER_BUDGET
#define RRV__COMB_WANDER_BUDGET 4.0
#endif

struct rrv__majorant_grid {
    int n[3];
    rrv_vec3 lo, hi, cell;
    rrv_vec3 inv_cell;     /* 1 / cell: a point's cell by multiplication */
    rrv_vec3 refraction_scale; /* (n - 1) / (hi - lo) of the refraction grid */
    double sigma_t_max;    /* max over channels of (sigma_a + sigma_s) * scale */
    double channel_scale[3]; /* per channel, the extinction its walks take for the
                              majorant's (times density_max): its channel group's
                              largest (rrv__group_channels) */
    int channel_groups;    /* 1 (grey or mildly chromatic): one majorant serves all
                              channels, as before there were groups */
    float *density_max;    /* per cell */
    float *density_min;    /* per cell, a lower bound of the density (rounded down):
                              residual tracking's control (rrv__field_lower) */
    float *grad_max;       /* per cell max |grad r|, NULL if the medium does not refract */
    float *jacobian_wander; /* with RRV__COMB_WANDER, per cell bound on |J(p) - J(q)|, J the
                              Jacobian of grad r, p, q in the cell, where grad r is a baked
                              trilinear grid's; -1 in a cell, or NULL for the medium, where none
                              is known (the comb's chords there keep RRV__COMB_MAX_CELLS) */
    float density_peak;    /* max of density_max: sizes the work bounds */
    float grad_peak;       /* max of grad_max, 0 if the medium does not refract */
    int flat_cells;        /* some cell has grad_max 0 */
    unsigned char *near_flat; /* with flat_cells, per cell: it or one of its 26
                              neighbours has grad_max 0 (rrv__eikonal_view), else NULL */
    double cell_min;       /* the shortest side of a cell */
    size_t bytes;          /* heap bytes built for this medium (grids, bakes) */
    int empty;             /* no extinction anywhere: density tracking can skip it */
    int surface_free;      /* no surface reaches into the box: chords inside need no ray cast */
    /* Where the density can be nonzero, when that is less than the box: a
       gridvol's own box (0 outside it), which may be far thinner than a
       cell. Density walks clip to it (rrv__majorant_iterator_start): a
       fuzzed grid 3e-20 m thick lent its cells' bound (1e10 per metre) to
       rays that met no density, and every walk ran to 2^22 events. */
    int density_clipped;
    rrv_vec3 density_lo, density_hi;
    int ior_inert;         /* the IOR is the ambient one throughout: the medium does not refract */
    rrv_field baked[RRV__FIELD_KINDS]; /* kind GRID where a noise field was baked */
    rrv_grid refraction;   /* 4 channels, r and grad r, where r comes from a grid;
                              with cubic interpolation only its lattice (no data) */
    double *cubic;         /* cubic interpolation: B-spline coefficients of r on
                              that lattice, one ghost layer each side, else NULL */
    double cubic_floor;    /* the lowest r the cubic may return (eta stays > 0) */
};

/* Does the medium bend light at all? Media without an IOR pay nothing. */
static int rrv__medium_refracts(const rrv_medium *m)
{
    if (m->majorant && m->majorant->ior_inert) return 0;
    return m->ior_from_gas || m->ior.kind != RRV_FIELD_NONE;
}

/* The IOR outside every medium: the scene's `ambient ior`, or where none
   was given the one rrv_scene_prepare derived (rrv__resolve_ambient). */
static double rrv__ambient_ior(const rrv_scene *scene)
{
    if (scene->settings.ambient_ior != 0.0) return scene->settings.ambient_ior;
    return scene->ambient_ior > 0.0 ? scene->ambient_ior : 1.0;
}

/* No `ambient ior`: the air around a gas medium is the same gas at its
   ambient state (T_ref, P_ref, where its fields end), so a plume whose
   faces are at that state has no IOR jump whatever its iorscale. The
   first gas medium listed sets it; another gas whose ambient state
   differs keeps a jump at its faces, which rrv_medium_face_jumps reports.
   Without a gas medium the ambient IOR is 1 (vacuum or unscaled air
   whose refractivity is left out, as classic does). */
static double rrv__resolve_ambient(const rrv_scene *scene)
{
    int i;
    if (scene->settings.ambient_ior != 0.0) return scene->settings.ambient_ior;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double eta;
        if (!m->ior_from_gas) continue;
        eta = 1.0 + (m->eta_ref - 1.0) * m->ior_scale;
        return eta >= 1.0 && eta <= RRV_MAX_IOR ? eta : 1.0;
    }
    return 1.0;
}

/* An IOR that is the ambient one everywhere in the box (a constant equal to
   it) bends nothing and has no interface: such a medium renders exactly as
   classic does, paying nothing for its IOR. */
static int rrv__ior_is_ambient(const rrv_scene *scene, const rrv_medium *m)
{
    double r;
    if (m->ior_from_gas) {
        if (m->temperature.kind != RRV_FIELD_NONE || m->pressure.kind != RRV_FIELD_NONE) return 0;
        r = (m->eta_ref - 1.0) * m->ior_scale;
    } else if (m->ior.kind == RRV_FIELD_CONSTANT) {
        r = m->ior.value * m->ior_scale;
    } else {
        return 0;
    }
    return r == rrv__ambient_ior(scene) - 1.0;
}

/* The field to evaluate: the baked copy when there is one. */
static const rrv_field *rrv__field_of(const rrv_medium *m, int which)
{
    const rrv_field *user = which == RRV__DENSITY ? &m->density : which == RRV__TEMPERATURE ? &m->temperature
                          : which == RRV__PRESSURE ? &m->pressure : &m->ior;
    if (m->majorant && m->majorant->baked[which].kind == RRV_FIELD_GRID) return &m->majorant->baked[which];
    return user;
}


/* The gas state at p: temperature (K) and pressure (Pa), ambient outside fields. */
static double rrv__temperature(const rrv_medium *m, rrv_vec3 p)
{
    double f;
    if (m->temperature.kind == RRV_FIELD_NONE) return m->T_ref;
    f = rrv__field_eval(rrv__field_of(m, RRV__TEMPERATURE), p, 0,
                        m->temperatureoffset + m->T_ref / m->temperaturescale);
    return (f - m->temperatureoffset) * m->temperaturescale;
}

static double rrv__pressure(const rrv_medium *m, rrv_vec3 p)
{
    if (m->pressure.kind == RRV_FIELD_NONE) return m->P_ref;
    return rrv__field_eval(rrv__field_of(m, RRV__PRESSURE), p, 0, m->P_ref);
}

/* Cubic B-spline weights of the four coefficients around a point at
   fraction t of its cell, and their derivatives in t. */
static void rrv__bspline_weights(double t, double w[4], double dw[4])
{
    double s = 1.0 - t, t2 = t * t;
    w[0] = s * s * s / 6.0;
    w[1] = (4.0 - 6.0 * t2 + 3.0 * t2 * t) / 6.0;
    w[2] = (1.0 + 3.0 * t + 3.0 * t2 - 3.0 * t2 * t) / 6.0;
    w[3] = t2 * t / 6.0;
    dw[0] = -0.5 * s * s;
    dw[1] = 0.5 * (3.0 * t2 - 4.0 * t);
    dw[2] = 0.5 * (1.0 + 2.0 * t - 3.0 * t2);
    dw[3] = 0.5 * t2;
}

/* The tricubic B-spline with coefficients c on the lattice of g (padded by
   one ghost coefficient each side) at p inside g's box: 64 coefficients,
   summed axis by axis. Value and gradient come from the same C2 function,
   so the gradient is the derivative of the value, which the trilinear pair
   is not. grad may be NULL. */
static double rrv__cubic_eval(const rrv_grid *g, const double *c, rrv_vec3 p, rrv_vec3 *grad)
{
    rrv__grid_cell cell;
    double w[3][4], dw[3][4], v = 0, gx = 0, gy = 0, gz = 0;
    size_t sy = (size_t)g->nx + 2, sz = sy * ((size_t)g->ny + 2);
    const double *base;
    int a, j, k;
    rrv__grid_locate(g, p, &cell);
    for (a = 0; a < 3; ++a) rrv__bspline_weights(cell.t[a], w[a], dw[a]);
    /* Cell i0 uses lattice coefficients i0-1 .. i0+2, padded i0 .. i0+3. */
    base = c + (size_t)cell.i0[0] + (size_t)cell.i0[1] * sy + (size_t)cell.i0[2] * sz;
    for (k = 0; k < 4; ++k) {
        double zv = 0, zx = 0, zy = 0;
        for (j = 0; j < 4; ++j) {
            const double *row = base + (size_t)j * sy + (size_t)k * sz;
            double a0 = w[0][0] * row[0] + w[0][1] * row[1] + w[0][2] * row[2] + w[0][3] * row[3];
            zv += w[1][j] * a0;
            if (grad) {
                zx += w[1][j] * (dw[0][0] * row[0] + dw[0][1] * row[1] + dw[0][2] * row[2] + dw[0][3] * row[3]);
                zy += dw[1][j] * a0;
            }
        }
        v += w[2][k] * zv;
        if (grad) {
            gx += w[2][k] * zx;
            gy += w[2][k] * zy;
            gz += dw[2][k] * zv;
        }
    }
    if (grad) *grad = rrv__v3(gx / cell.step[0], gy / cell.step[1], gz / cell.step[2]);
    return v;
}

/* The baked refractivity grid, if one covers p. */
static const rrv_grid *rrv__refraction_grid_at(const rrv_medium *m, rrv_vec3 p)
{
    const rrv_grid *g = m->majorant ? &m->majorant->refraction : NULL;
    return g && (g->data || m->majorant->cubic) && rrv__inside_box(p, g->lo, g->hi) ? g : NULL;
}

/* The trilinear blend of one channel at d (the lower corner), in double as
   rrv__grid_blend. */
static double rrv__blend8(const float *d, size_t sx, size_t sy, size_t sz, const double t[3])
{
    double c00 = (double)d[0] + t[0] * ((double)d[sx] - d[0]);
    double c10 = (double)d[sy] + t[0] * ((double)d[sy + sx] - d[sy]);
    double c01 = (double)d[sz] + t[0] * ((double)d[sz + sx] - d[sz]);
    double c11 = (double)d[sz + sy] + t[0] * ((double)d[sz + sy + sx] - d[sz + sy]);
    c00 += t[1] * (c10 - c00);
    c01 += t[1] * (c11 - c01);
    return c00 + t[2] * (c01 - c00);
}

/* The baked 4-channel refraction grid at p inside it: one location for all
   channels, found by multiplying with the precomputed sample density (the
   comb's kicks spent most of their lookup in rrv__grid_locate's divisions
   and per-channel set-up). */
/* The cell of the refraction grid holding p: its first sample (4 channels
   a sample), the strides of a row and a slice, the offsets t in it.
   Inline (as the comb's other per-kick helpers below): a call was a tenth
   of a kick's lookup. */
static inline const float *rrv__refraction_cell(const struct rrv__majorant_grid *mg, rrv_vec3 p, size_t *sy,
                                                size_t *sz, double t[3])
{
    const rrv_grid *g = &mg->refraction;
    const double u[3] = {(p.x - g->lo.x) * mg->refraction_scale.x, (p.y - g->lo.y) * mg->refraction_scale.y,
                         (p.z - g->lo.z) * mg->refraction_scale.z};
    const int n[3] = {g->nx, g->ny, g->nz};
    int i[3], a;
    *sy = 4 * (size_t)g->nx;
    *sz = *sy * (size_t)g->ny;
    for (a = 0; a < 3; ++a) {
        i[a] = (int)u[a];
        if (i[a] > n[a] - 2) i[a] = n[a] - 2;
        if (i[a] < 0) i[a] = 0;
        t[a] = u[a] - i[a];
    }
    return g->data + 4 * (size_t)i[0] + *sy * (size_t)i[1] + *sz * (size_t)i[2];
}

static double rrv__refraction_lookup(const struct rrv__majorant_grid *mg, rrv_vec3 p, rrv_vec3 *grad)
{
    size_t sy, sz;
    double t[3];
    const float *d = rrv__refraction_cell(mg, p, &sy, &sz, t);
    if (!grad) return rrv__blend8(d, 4, sy, sz, t);
    {
        /* the four channels side by side, so the compiler can blend them as
           one vector; in double, not float: a float blend weight quantises
           the position to 6e-8 of a cell, which makes the ray map a staircase
           at that scale, and Newton's solves (to 1e-9) and their Jacobians
           need it smooth */
        double v[4];
        int c;
        for (c = 0; c < 4; ++c) {
            double c00 = (double)d[c] + t[0] * ((double)d[4 + c] - d[c]);
            double c10 = (double)d[sy + c] + t[0] * ((double)d[sy + 4 + c] - d[sy + c]);
            double c01 = (double)d[sz + c] + t[0] * ((double)d[sz + 4 + c] - d[sz + c]);
            double c11 = (double)d[sz + sy + c] + t[0] * ((double)d[sz + sy + 4 + c] - d[sz + sy + c]);
            c00 += t[1] * (c10 - c00);
            c01 += t[1] * (c11 - c01);
            v[c] = c00 + t[2] * (c01 - c00);
        }
        *grad = rrv__v3(v[1], v[2], v[3]);
        return v[0];
    }
}

/* Asks the cache for the refraction grid's cell at p, which the comb's
   next kick will read: a baked grid of a few MiB overflows the core's own
   cache, and the kick's first load then waited for memory (a third of its
   lookup's time on the fire). Asked when the chord is planned, the load
   overlaps the chord's tracking and the next spacing's cell walk. The
   cell's samples lie in four runs of two (x and x + 1), each 32 bytes,
   that may straddle a cache line. Only a hint: without a compiler that
   offers it, nothing happens. */
static inline void rrv__prefetch_refraction(const struct rrv__majorant_grid *mg, rrv_vec3 p)
{
#if defined(__GNUC__) || defined(__clang__)
    size_t sy, sz;
    double t[3];
    const float *d;
    if (!mg->refraction.data || mg->cubic || !rrv__inside_box(p, mg->refraction.lo, mg->refraction.hi)) return;
    d = rrv__refraction_cell(mg, p, &sy, &sz, t);
    __builtin_prefetch(d);
    __builtin_prefetch(d + 7);
    __builtin_prefetch(d + sy);
    __builtin_prefetch(d + sy + 7);
    __builtin_prefetch(d + sz);
    __builtin_prefetch(d + sz + 7);
    __builtin_prefetch(d + sz + sy);
    __builtin_prefetch(d + sz + sy + 7);
#else
    (void)mg;
    (void)p;
#endif
}

/* ---- derivatives of the refractivity gradient (for nee shoot and manifold) ----
   The solver's variational equations differentiate the very gradient the
   ray steps use, so each function below is the exact derivative of one
   gradient above, row-major J[3 i + j] = d grad_i / d x_j. Where that
   gradient is a blend of differences rather than the derivative of a value
   (the trilinear grids, the NanoVDB stencil) the matrix is not symmetric:
   it is kept so, since the discrete ray map is what Newton's method and the
   geometry term need the derivative of, and its symmetric part alone would
   miss that derivative by the antisymmetric part (a discretisation error,
   first order in the voxel: 9 % of the largest entry on a 17^3 grid of a
   smooth field, 5 % at 33^3, test/test_hessian.c). The trilinear value's
   own Hessian, zero inside every cell, would miss it entirely. */

#ifndef RRV_NO_CURVED_NEE /* derivatives of the gradient: the solvers' alone */
/* The refraction grid's value, gradient and the gradient's Jacobian at p,
   from one location of its cell: the value and gradient are
   rrv__refraction_lookup's bit for bit (the same blends in the same
   order), J is the trilinear blend of the baked central differences
   differentiated in that cell (the one-sided slopes there; the derivative
   jumps at cell faces, where the gradient itself is continuous). Per
   channel, the slope along x is the (y, z) blend of the corners' x
   differences, and those along y and z are differences of the partial
   blends the value is built from, so they cost a few operations more
   than the value rather than a sum over the eight corners each. */
static double rrv__refraction_lookup_jacobian_fused(const struct rrv__majorant_grid *mg, rrv_vec3 p, rrv_vec3 *grad,
                                                    double J[9], rrv_vec3 *value_grad)
{
    size_t sy, sz;
    double t[3], v[4], slope[3][4];
    const float *d = rrv__refraction_cell(mg, p, &sy, &sz, t);
    int c;
    for (c = 0; c < 4; ++c) {
        /* x differences of the four x edges (rows y, z = 00, 10, 01, 11) */
        double dx00 = (double)d[4 + c] - d[c], dx10 = (double)d[sy + 4 + c] - d[sy + c];
        double dx01 = (double)d[sz + 4 + c] - d[sz + c], dx11 = (double)d[sz + sy + 4 + c] - d[sz + sy + c];
        double c00 = (double)d[c] + t[0] * dx00, c10 = (double)d[sy + c] + t[0] * dx10;
        double c01 = (double)d[sz + c] + t[0] * dx01, c11 = (double)d[sz + sy + c] + t[0] * dx11;
        double ey0 = c10 - c00, ey1 = c11 - c01, sx0 = dx00 + t[1] * (dx10 - dx00), sx1 = dx01 + t[1] * (dx11 - dx01);
        c00 += t[1] * ey0;
        c01 += t[1] * ey1;
        v[c] = c00 + t[2] * (c01 - c00);
        slope[0][c] = sx0 + t[2] * (sx1 - sx0);
        slope[1][c] = ey0 + t[2] * (ey1 - ey0);
        slope[2][c] = c01 - c00;
    }
    for (c = 0; c < 3; ++c) {
        J[3 * c] = slope[0][1 + c] * mg->refraction_scale.x;
        J[3 * c + 1] = slope[1][1 + c] * mg->refraction_scale.y;
        J[3 * c + 2] = slope[2][1 + c] * mg->refraction_scale.z;
    }
    *grad = rrv__v3(v[1], v[2], v[3]);
    /* the value's own slope in the cell, which the blended gradient is
       not: what eta moves by where the ray equation divides by it */
    if (value_grad)
        *value_grad = rrv__v3(slope[0][0] * mg->refraction_scale.x, slope[1][0] * mg->refraction_scale.y,
                              slope[2][0] * mg->refraction_scale.z);
    return v[0];
}

/* The Jacobian of the gradient rrv__refraction_lookup returns (see
   rrv__refraction_lookup_jacobian_fused). */
static void rrv__refraction_lookup_jacobian(const struct rrv__majorant_grid *mg, rrv_vec3 p, double J[9])
{
    rrv_vec3 grad;
    rrv__refraction_lookup_jacobian_fused(mg, p, &grad, J, NULL);
}

/* Second derivatives in t of the cubic B-spline weights. */
static void rrv__bspline_curvatures(double t, double ddw[4])
{
    ddw[0] = 1.0 - t;
    ddw[1] = 3.0 * t - 2.0;
    ddw[2] = 1.0 - 3.0 * t;
    ddw[3] = t;
}

/* The Hessian of the tricubic B-spline rrv__cubic_eval evaluates (its
   gradient is the value's derivative, so this one is symmetric): per pair
   of axes the 64 coefficients weighted by the weights' derivatives of the
   orders the pair asks for. */
static void rrv__cubic_hessian(const rrv_grid *g, const double *c, rrv_vec3 p, double H[9])
{
    rrv__grid_cell cell;
    double w[3][3][4]; /* axis, order of derivative, coefficient */
    size_t sy = (size_t)g->nx + 2, sz = sy * ((size_t)g->ny + 2);
    const double *base;
    int a, b, i, j, k;
    rrv__grid_locate(g, p, &cell);
    for (a = 0; a < 3; ++a) {
        rrv__bspline_weights(cell.t[a], w[a][0], w[a][1]);
        rrv__bspline_curvatures(cell.t[a], w[a][2]);
    }
    base = c + (size_t)cell.i0[0] + (size_t)cell.i0[1] * sy + (size_t)cell.i0[2] * sz;
    for (a = 0; a < 3; ++a)
        for (b = a; b < 3; ++b) {
            int order[3] = {0, 0, 0};
            double sum = 0;
            ++order[a];
            ++order[b];
            for (k = 0; k < 4; ++k)
                for (j = 0; j < 4; ++j) {
                    const double *row = base + (size_t)j * sy + (size_t)k * sz;
                    double x = 0;
                    for (i = 0; i < 4; ++i) x += w[0][order[0]][i] * row[i];
                    sum += w[2][order[2]][k] * w[1][order[1]][j] * x;
                }
            H[3 * a + b] = H[3 * b + a] = sum / (cell.step[a] * cell.step[b]);
        }
}

/* The Jacobian of rrv__baked_refractivity's gradient at p inside the bake. */
static void rrv__baked_refractivity_jacobian(const rrv_medium *m, const rrv_grid *baked, rrv_vec3 p, double J[9])
{
    if (m->majorant->cubic) rrv__cubic_hessian(baked, m->majorant->cubic, p, J);
    else rrv__refraction_lookup_jacobian(m->majorant, p, J);
}
#endif

/* The baked refractivity (and gradient if grad) at p inside the baked grid. */
static double rrv__baked_refractivity(const rrv_medium *m, const rrv_grid *baked, rrv_vec3 p, rrv_vec3 *grad)
{
    if (m->majorant->cubic) {
        /* The floor keeps eta > 0 where the spline overshoots a sharp
           feature; it lies far below any sample and is never met by a
           resolved field. */
        double r = rrv__cubic_eval(baked, m->majorant->cubic, p, grad);
        return r > m->majorant->cubic_floor ? r : m->majorant->cubic_floor;
    }
    (void)baked;
    return rrv__refraction_lookup(m->majorant, p, grad);
}

/* Refractivity eta - 1 of a refractive medium at p, including its artist
   scale; Hauf-Grigull for a gas: r = r_ref (P / P_ref) (T_ref / T). */
static double rrv__refractivity(const rrv_medium *m, rrv_vec3 p, double ambient_r)
{
    double r;
    const rrv_grid *baked = rrv__refraction_grid_at(m, p);
    if (baked) return rrv__baked_refractivity(m, baked, p, NULL);
    if (m->ior_from_gas) {
        double T = rrv__temperature(m, p), P = rrv__pressure(m, p);
        r = (m->eta_ref - 1.0) * (P / m->P_ref) * (m->T_ref / fmax(T, 1e-3));
    } else {
        const rrv_field *f = rrv__field_of(m, RRV__IOR);
        /* Outside its own box an IOR grid gives the ambient IOR, which the
           artist scale (meant for the grid's values) must not move: a scaled
           ambient would be a jump at the grid's box that no data holds. */
        if (f->kind == RRV_FIELD_GRID && !rrv__inside_box(p, f->grid.lo, f->grid.hi)) return ambient_r;
        if (f->kind == RRV_FIELD_NANOVDB && !rrv__inside_box(p, f->nanovdb.lo, f->nanovdb.hi)) return ambient_r;
        r = rrv__profile_refractivity(f, p, ambient_r);
    }
    return m->ior_scale * r;
}

/* ---- gradients of the refractivity ----------------------------------------- */

/* Gradient of a grid field: the trilinear blend of central differences at
   the eight samples around p. Inside the grid this equals central
   differences of the trilinear field with a one-voxel step, which is second
   order (the gradient of the trilinear interpolant itself is first order and
   jumps at cell faces), and locates the cell once instead of six times
   (measured 1.2x faster; precomputing the differences, as the refraction
   bake does, is 2.6x: test/measure_grin.c, grid stencil table). At the
   grid's faces the differences become one-sided. Zero outside the grid. */
static rrv_vec3 rrv__grid_gradient(const rrv_grid *g, rrv_vec3 p)
{
    rrv__grid_cell cell;
    double grad[3] = {0, 0, 0};
    int a, corner;
    if (!rrv__inside_box(p, g->lo, g->hi)) return rrv__v3(0, 0, 0);
    rrv__grid_locate(g, p, &cell);
    for (corner = 0; corner < 8; ++corner) {
        int c[3];
        double w = 1;
        size_t base = 0;
        for (a = 0; a < 3; ++a) {
            int bit = (corner >> a) & 1;
            c[a] = cell.i0[a] + bit;
            w *= bit ? cell.t[a] : 1.0 - cell.t[a];
            base += (size_t)c[a] * cell.stride[a];
        }
        for (a = 0; a < 3; ++a) {
            int m = c[a] > 0 ? c[a] - 1 : c[a], q = c[a] < cell.n[a] - 1 ? c[a] + 1 : c[a];
            double up = (double)g->data[base + (size_t)(q - c[a]) * cell.stride[a]];
            double down = (double)g->data[base - (size_t)(c[a] - m) * cell.stride[a]];
            grad[a] += w * (up - down) / ((q - m) * cell.step[a]);
        }
    }
    return rrv__v3(grad[0], grad[1], grad[2]);
}

#ifndef RRV_NO_CURVED_NEE /* derivatives of the gradient: the solvers' alone */
/* The Jacobian of rrv__grid_gradient: its eight corner differences (the
   same, one-sided at the grid's faces) with the trilinear weights
   differentiated. Not symmetric (see the derivatives of the refractivity
   gradient below). Zero outside the grid, as the gradient is. */
static void rrv__grid_gradient_jacobian(const rrv_grid *g, rrv_vec3 p, double J[9])
{
    rrv__grid_cell cell;
    int a, b, corner;
    for (a = 0; a < 9; ++a) J[a] = 0;
    if (!rrv__inside_box(p, g->lo, g->hi)) return;
    rrv__grid_locate(g, p, &cell);
    for (corner = 0; corner < 8; ++corner) {
        int c[3];
        double w[3], dw[3], diff[3];
        size_t base = 0;
        for (a = 0; a < 3; ++a) {
            int bit = (corner >> a) & 1;
            c[a] = cell.i0[a] + bit;
            w[a] = bit ? cell.t[a] : 1.0 - cell.t[a];
            dw[a] = (bit ? 1.0 : -1.0) / cell.step[a];
            base += (size_t)c[a] * cell.stride[a];
        }
        for (a = 0; a < 3; ++a) {
            int m = c[a] > 0 ? c[a] - 1 : c[a], q = c[a] < cell.n[a] - 1 ? c[a] + 1 : c[a];
            double up = (double)g->data[base + (size_t)(q - c[a]) * cell.stride[a]];
            double down = (double)g->data[base - (size_t)(c[a] - m) * cell.stride[a]];
            diff[a] = (up - down) / ((q - m) * cell.step[a]);
        }
        for (b = 0; b < 3; ++b) {
            double wb = dw[b] * w[(b + 1) % 3] * w[(b + 2) % 3];
            for (a = 0; a < 3; ++a) J[3 * a + b] += wb * diff[a];
        }
    }
}
#endif

/* Gradient of a scalar field: analytic where the field is, numeric else. */
static rrv_vec3 rrv__field_gradient(const rrv_field *f, rrv_vec3 p)
{
    switch (f->kind) {
    case RRV_FIELD_BLOBS: {
        rrv_vec3 g = rrv__v3(0, 0, 0);
        int i;
        for (i = 0; i < f->blob_count; ++i) {
            const rrv_blob *b = &f->blobs[i];
            rrv_vec3 d = rrv__sub(p, b->center);
            double s2 = b->radius * b->radius, q = rrv__dot(d, d) / s2;
            if (q < 72.0) g = rrv__madd(g, d, -b->weight * exp(-0.5 * q) / s2);
        }
        return g;
    }
    /* no NOISE case: prepare bakes every noise field into a grid, and
       callers pass rrv__field_of's baked copy */
    case RRV_FIELD_GRID:
        return rrv__grid_gradient(&f->grid, p);
    case RRV_FIELD_NANOVDB:
        return rrv__inside_box(p, f->nanovdb.lo, f->nanovdb.hi) ? rrv__nv_gradient(&f->nanovdb, p) : rrv__v3(0, 0, 0);
    default:
        return rrv__v3(0, 0, 0);
    }
}

#ifndef RRV_NO_CURVED_NEE /* derivatives of the gradient: the solvers' alone */
/* The derivative of rrv__field_gradient (a scalar field's Hessian where the
   gradient is the value's derivative); 0 for kinds it has none for here
   (an unbaked noise field, which rrv__field_gradient does not handle
   either). */
static int rrv__field_hessian(const rrv_field *f, rrv_vec3 p, double H[9])
{
    int i, k, l;
    for (i = 0; i < 9; ++i) H[i] = 0;
    switch (f->kind) {
    case RRV_FIELD_NONE:
    case RRV_FIELD_CONSTANT:
        return 1;
    case RRV_FIELD_BLOBS:
        for (i = 0; i < f->blob_count; ++i) {
            const rrv_blob *bl = &f->blobs[i];
            rrv_vec3 e = rrv__sub(p, bl->center);
            double s2 = bl->radius * bl->radius, q = rrv__dot(e, e) / s2, w, ee[3];
            if (!(q < 72.0)) continue; /* the cut-off the value and gradient use */
            w = bl->weight * exp(-0.5 * q) / s2;
            ee[0] = e.x; ee[1] = e.y; ee[2] = e.z;
            for (k = 0; k < 3; ++k)
                for (l = 0; l < 3; ++l) H[3 * k + l] += w * (ee[k] * ee[l] / s2 - (k == l ? 1.0 : 0.0));
        }
        return 1;
    case RRV_FIELD_GRID:
        rrv__grid_gradient_jacobian(&f->grid, p, H);
        return 1;
    case RRV_FIELD_NANOVDB:
        if (rrv__inside_box(p, f->nanovdb.lo, f->nanovdb.hi)) rrv__nv_gradient_jacobian(&f->nanovdb, p, H);
        return 1;
    default:
        return 0;
    }
}
#endif

static rrv_vec3 rrv__profile_gradient(const rrv_field *f, rrv_vec3 p)
{
    rrv_vec3 d = rrv__sub(p, f->center);
    double R2 = f->radius * f->radius, q;
    switch (f->kind) {
    case RRV_FIELD_LUNEBURG:
        q = rrv__dot(d, d) / R2;
        return q < 1.0 ? rrv__scale(d, -1.0 / (R2 * sqrt(2.0 - q))) : rrv__v3(0, 0, 0);
    case RRV_FIELD_FISHEYE:
        q = rrv__dot(d, d) / R2;
        return q < 1.0 ? rrv__scale(d, -2.0 * f->n0 / (R2 * (1.0 + q) * (1.0 + q))) : rrv__v3(0, 0, 0);
    case RRV_FIELD_SLAB:
        return rrv__scale(f->normal, f->gradient);
    case RRV_FIELD_SHELL: {
        double r = rrv__length(d), inner = f->radius - f->thickness, a, b;
        if (r == 0) return rrv__v3(0, 0, 0);
        a = cosh((r - inner) / f->edge);
        b = cosh((r - f->radius) / f->edge);
        return rrv__scale(d, f->amplitude * 0.5 * (1.0 / (a * a) - 1.0 / (b * b)) / (f->edge * r));
    }
    default:
        return rrv__field_gradient(f, p);
    }
}

/* rrv__profile_refractivity, rrv__profile_gradient and (with H)
   rrv__profile_hessian of the Luneburg, fish-eye and slab profiles at one
   point, the same numbers: a Luneburg lens takes one square root for all
   three where the three functions take one each, and an eikonal step
   looks up four points (eight with nee shoot's Jacobi field). 0 for the
   other kinds, left to those functions. */
static int rrv__profile_fused(const rrv_field *f, rrv_vec3 p, double *r, rrv_vec3 *grad, double H[9])
{
    rrv_vec3 d = rrv__sub(p, f->center);
    double R2 = f->radius * f->radius, q, a, b, dd[3];
    int i, j;
    switch (f->kind) {
    case RRV_FIELD_LUNEBURG: {
        double s;
        q = rrv__dot(d, d) / R2;
        if (q >= 1.0) {
            *r = 0.0;
            *grad = rrv__v3(0, 0, 0);
            if (H) for (i = 0; i < 9; ++i) H[i] = 0;
            return 1;
        }
        s = sqrt(2.0 - q);
        *r = s - 1.0;
        a = -1.0 / (R2 * s);
        *grad = rrv__scale(d, a);
        if (!H) return 1;
        b = a * a * a * R2; /* -1 / (R2^2 s^3) */
        break;
    }
    case RRV_FIELD_FISHEYE:
        q = rrv__dot(d, d) / R2;
        if (q >= 1.0) {
            *r = f->n0 * 0.5 - 1.0;
            *grad = rrv__v3(0, 0, 0);
            if (H) for (i = 0; i < 9; ++i) H[i] = 0;
            return 1;
        }
        *r = f->n0 / (1.0 + q) - 1.0;
        a = -2.0 * f->n0 / (R2 * (1.0 + q) * (1.0 + q));
        *grad = rrv__scale(d, a);
        if (!H) return 1;
        b = 8.0 * f->n0 / (R2 * R2 * (1.0 + q) * (1.0 + q) * (1.0 + q));
        break;
    case RRV_FIELD_SLAB:
        *r = f->base + f->gradient * rrv__dot(d, f->normal);
        *grad = rrv__scale(f->normal, f->gradient);
        if (H) for (i = 0; i < 9; ++i) H[i] = 0;
        return 1;
    default:
        return 0;
    }
    dd[0] = d.x; dd[1] = d.y; dd[2] = d.z;
    for (i = 0; i < 3; ++i)
        for (j = i; j < 3; ++j) H[3 * i + j] = H[3 * j + i] = (i == j ? a : 0.0) + b * dd[i] * dd[j];
    return 1;
}

#ifndef RRV_NO_CURVED_NEE /* derivatives of the gradient: the solvers' alone */
/* The derivative of rrv__profile_gradient (unscaled); 0 where there is
   none here. The radial profiles have grad r = phi'(d) e (e = d / |d|), so
   H = phi'' e e^T + (phi' / |d|) (I - e e^T), written as a I + b d d^T. */
static int rrv__profile_hessian(const rrv_field *f, rrv_vec3 p, double H[9])
{
    rrv_vec3 d = rrv__sub(p, f->center);
    double q, a = 0, b = 0, dd[3];
    int i, j;
    for (i = 0; i < 9; ++i) H[i] = 0;
    switch (f->kind) {
    case RRV_FIELD_CONSTANT:
        return 1;
    case RRV_FIELD_LUNEBURG:
    case RRV_FIELD_FISHEYE:
    case RRV_FIELD_SLAB: {
        rrv_vec3 g;
        return rrv__profile_fused(f, p, &q, &g, H);
    }
    case RRV_FIELD_SHELL: {
        /* phi' = A / (2 e) (sech^2 u - sech^2 v), u = (r - inner) / e, v =
           (r - R) / e; phi'' = A / e^2 (sech^2 v tanh v - sech^2 u tanh u).
           At the centre the gradient (zero there) is not differentiable; it
           is measure zero and gets the limit along a ray, phi'' I. */
        double r = rrv__length(d), inner = f->radius - f->thickness, e = f->edge;
        double cu = cosh((r - inner) / e), cv = cosh((r - f->radius) / e);
        double su = 1.0 / (cu * cu), sv = 1.0 / (cv * cv);
        double d1 = f->amplitude * 0.5 * (su - sv) / e;
        double d2 = f->amplitude * (sv * tanh((r - f->radius) / e) - su * tanh((r - inner) / e)) / (e * e);
        if (r == 0) {
            a = d2;
            break;
        }
        a = d1 / r;
        b = (d2 - a) / (r * r);
        break;
    }
    default:
        return rrv__field_hessian(f, p, H);
    }
    dd[0] = d.x; dd[1] = d.y; dd[2] = d.z;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) H[3 * i + j] = (i == j ? a : 0.0) + b * dd[i] * dd[j];
    return 1;
}
#endif

/* A gas whose temperature is a sum of blobs and whose pressure is uniform
   (the fire plumes): rrv__refractivity, rrv__refractivity_gradient and
   (with H) rrv__refractivity_hessian at p, the same numbers, from one
   exponential a blob where the three take four between them. 0 for other
   gases (or a baked one), left to those functions. */
static int rrv__gas_fused(const rrv_medium *m, rrv_vec3 p, double *r, rrv_vec3 *grad, double H[9])
{
    const rrv_field *tf = rrv__field_of(m, RRV__TEMPERATURE), *pf = rrv__field_of(m, RRV__PRESSURE);
    double sum = tf->base, T, P, ts = m->temperaturescale, HT[9], gt[3], k1;
    rrv_vec3 gT = rrv__v3(0, 0, 0);
    int i, k, l;
    if (m->temperature.kind == RRV_FIELD_NONE || tf->kind != RRV_FIELD_BLOBS ||
        !(pf->kind == RRV_FIELD_NONE || pf->kind == RRV_FIELD_CONSTANT))
        return 0;
    if (H) for (k = 0; k < 9; ++k) HT[k] = 0;
    for (i = 0; i < tf->blob_count; ++i) {
        const rrv_blob *b = &tf->blobs[i];
        rrv_vec3 d = rrv__sub(p, b->center);
        double s2 = b->radius * b->radius, q = rrv__dot(d, d) / s2, e, w, ee[3];
        if (!(q < 72.0)) continue; /* the cut-off of the value, gradient and Hessian */
        e = exp(-0.5 * q);
        sum += b->weight * e;
        w = -b->weight * e / s2; /* -(weight e / s2) exactly */
        gT = rrv__madd(gT, d, w);
        if (!H) continue;
        w = -w;
        ee[0] = d.x; ee[1] = d.y; ee[2] = d.z;
        for (k = 0; k < 3; ++k)
            for (l = k; l < 3; ++l) {
                /* symmetric: ee[k] ee[l] is ee[l] ee[k] to the bit */
                double add = w * (ee[k] * ee[l] / s2 - (k == l ? 1.0 : 0.0));
                HT[3 * k + l] += add;
                if (l != k) HT[3 * l + k] += add;
            }
    }
    P = m->pressure.kind == RRV_FIELD_NONE ? m->P_ref : pf->value;
    T = (sum - m->temperatureoffset) * ts; /* rrv__temperature */
    *r = m->ior_scale * ((m->eta_ref - 1.0) * (P / m->P_ref) * (m->T_ref / fmax(T, 1e-3)));
    T = fmax(T, 1e-3);
    gT = rrv__scale(gT, ts);
    /* rrv__refractivity_gradient and _hessian with grad P = 0, in their
       order of operations: grad r = -r grad T / T, H = r (u u^T - H_T / T +
       g g^T), u = -g, g = grad T / T */
    *grad = rrv__scale(rrv__scale(gT, -1.0 / T), *r);
    if (!H) return 1;
    gt[0] = gT.x / T; gt[1] = gT.y / T; gt[2] = gT.z / T;
    for (k = 0; k < 3; ++k)
        for (l = 0; l < 3; ++l) {
            k1 = gt[k] * gt[l] - HT[3 * k + l] * ts / T + gt[k] * gt[l];
            H[3 * k + l] = *r * k1;
        }
    return 1;
}

/* Refractivity and its gradient for one refractive medium at p. For a gas,
   grad r = r (grad P / P - grad T / T) (CONVENTIONS). */
static double rrv__refractivity_gradient(const rrv_medium *m, rrv_vec3 p, double ambient_r, rrv_vec3 *grad)
{
    double r;
    const rrv_grid *baked = rrv__refraction_grid_at(m, p);
    if (baked) return rrv__baked_refractivity(m, baked, p, grad);
    if (!m->ior_from_gas && rrv__profile_fused(rrv__field_of(m, RRV__IOR), p, &r, grad, NULL)) {
        *grad = rrv__scale(*grad, m->ior_scale);
        return m->ior_scale * r;
    }
    if (m->ior_from_gas && rrv__gas_fused(m, p, &r, grad, NULL)) return r;
    r = rrv__refractivity(m, p, ambient_r);
    if (m->ior_from_gas) {
        double T = fmax(rrv__temperature(m, p), 1e-3), P = rrv__pressure(m, p);
        rrv_vec3 gT = rrv__scale(rrv__field_gradient(rrv__field_of(m, RRV__TEMPERATURE), p), m->temperaturescale);
        rrv_vec3 gP = rrv__field_gradient(rrv__field_of(m, RRV__PRESSURE), p);
        *grad = rrv__scale(rrv__sub(rrv__scale(gP, 1.0 / P), rrv__scale(gT, 1.0 / T)), r);
    } else {
        *grad = rrv__scale(rrv__profile_gradient(rrv__field_of(m, RRV__IOR), p), m->ior_scale);
    }
    return r;
}

#ifndef RRV_NO_CURVED_NEE /* derivatives of the gradient: the solvers' alone */
/* The derivative of rrv__refractivity_gradient, 0 where there is none. For
   a gas, with u = grad P / P - grad T / T (so grad r = r u):
   H = r (u u^T + H_P / P - grad P grad P^T / P^2 - H_T / T + grad T grad T^T / T^2),
   symmetric where H_P and H_T are. T clamped at 1e-3 K (as the value does)
   is not differentiated: no gas gets there. */
static int rrv__refractivity_hessian(const rrv_medium *m, rrv_vec3 p, double ambient_r, double H[9])
{
    const rrv_grid *baked = rrv__refraction_grid_at(m, p);
    int k, l;
    if (baked) {
        rrv__baked_refractivity_jacobian(m, baked, p, H);
        return 1;
    }
    if (m->ior_from_gas) {
        double r = rrv__refractivity(m, p, ambient_r), T = fmax(rrv__temperature(m, p), 1e-3), P = rrv__pressure(m, p);
        double HT[9], HP[9], u[3], gt[3], gp[3];
        rrv_vec3 gT = rrv__scale(rrv__field_gradient(rrv__field_of(m, RRV__TEMPERATURE), p), m->temperaturescale);
        rrv_vec3 gP = rrv__field_gradient(rrv__field_of(m, RRV__PRESSURE), p);
        if (!rrv__field_hessian(rrv__field_of(m, RRV__TEMPERATURE), p, HT) ||
            !rrv__field_hessian(rrv__field_of(m, RRV__PRESSURE), p, HP)) {
            for (k = 0; k < 9; ++k) H[k] = 0;
            return 0;
        }
        gt[0] = gT.x / T; gt[1] = gT.y / T; gt[2] = gT.z / T;
        gp[0] = gP.x / P; gp[1] = gP.y / P; gp[2] = gP.z / P;
        for (k = 0; k < 3; ++k) u[k] = gp[k] - gt[k];
        for (k = 0; k < 3; ++k)
            for (l = 0; l < 3; ++l)
                H[3 * k + l] = r * (u[k] * u[l] + HP[3 * k + l] / P - gp[k] * gp[l] -
                                    HT[3 * k + l] * m->temperaturescale / T + gt[k] * gt[l]);
        return 1;
    }
    {
        const rrv_field *f = rrv__field_of(m, RRV__IOR);
        int ok = rrv__profile_hessian(f, p, H);
        for (k = 0; k < 9; ++k) H[k] *= m->ior_scale;
        return ok;
    }
}

/* rrv__refractivity_gradient and rrv__refractivity_hessian at one point:
   the same numbers, and for a baked trilinear grid one cell lookup for all
   three, for the closed-form profiles one evaluation (rrv__profile_fused)
   (the Jacobi fields of nee shoot take both at every stage of every
   step). */
static double rrv__refractivity_gradient_hessian(const rrv_medium *m, rrv_vec3 p, double ambient_r, rrv_vec3 *grad,
                                                 double H[9], rrv_vec3 *value_grad)
{
    const rrv_grid *baked = rrv__refraction_grid_at(m, p);
    double r;
    int k;
    if (baked && !m->majorant->cubic) return rrv__refraction_lookup_jacobian_fused(m->majorant, p, grad, H, value_grad);
    if (value_grad) {
        /* every other kind's gradient is its value's own derivative */
        r = rrv__refractivity_gradient_hessian(m, p, ambient_r, grad, H, NULL);
        *value_grad = *grad;
        return r;
    }
    if (!baked && !m->ior_from_gas && rrv__profile_fused(rrv__field_of(m, RRV__IOR), p, &r, grad, H)) {
        if (m->ior_scale == 1.0) return r;
        *grad = rrv__scale(*grad, m->ior_scale);
        for (k = 0; k < 9; ++k) H[k] *= m->ior_scale;
        return m->ior_scale * r;
    }
    if (!baked && m->ior_from_gas && rrv__gas_fused(m, p, &r, grad, H)) return r;
    rrv__refractivity_hessian(m, p, ambient_r, H);
    return rrv__refractivity_gradient(m, p, ambient_r, grad);
}
#endif

/* The refractivity of the scene at p: that of the last listed refractive
   medium whose box holds p, the ambient one elsewhere. */
static double rrv__scene_refractivity(const rrv_scene *scene, rrv_vec3 p, rrv_vec3 *grad)
{
    double ambient_r = rrv__ambient_ior(scene) - 1.0;
    int i;
    for (i = scene->medium_count - 1; i >= 0; --i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && rrv__inside_box(p, m->lo, m->hi)) {
            rrv_vec3 g;
            double r = rrv__refractivity_gradient(m, p, ambient_r, &g);
            if (grad) *grad = g;
            return r;
        }
    }
    if (grad) *grad = rrv__v3(0, 0, 0);
    return ambient_r;
}

/* >> 6 majorants and bounds: a medium's limits, majorant grids, the medium at a
   point, the emission grid ===================================================== */

/* ---- the limits a medium must respect (BOUNDS) --------------------------------
   Checked by rrv_scene_prepare (rrv__check_medium) once a medium is
   complete, with the lines the parser recorded in rrv_medium.line. */

/* The range [*lo, *hi] of a scalar field over a box (conservative: a grid
   reports all its samples, blobs the sums of their signed weights). */
static void rrv__field_range(const rrv_field *f, double ambient, double *lo, double *hi)
{
    int i;
    switch (f->kind) {
    case RRV_FIELD_CONSTANT: *lo = *hi = f->value; return;
    case RRV_FIELD_BLOBS:
        *lo = *hi = f->base;
        for (i = 0; i < f->blob_count; ++i) {
            if (f->blobs[i].weight < 0) *lo += f->blobs[i].weight;
            else *hi += f->blobs[i].weight;
        }
        return;
    case RRV_FIELD_NOISE: /* fbm and falloff are in [0, 1] */
        *lo = f->base + rrv__mind(0.0, f->amplitude);
        *hi = f->base + rrv__maxd(0.0, f->amplitude);
        return;
    case RRV_FIELD_GRID: {
        size_t n = (size_t)f->grid.nx * (size_t)f->grid.ny * (size_t)f->grid.nz * (size_t)f->grid.channels, k;
        *lo = DBL_MAX;
        *hi = -DBL_MAX;
        for (k = 0; k < n; ++k) {
            *lo = rrv__mind(*lo, f->grid.data[k]);
            *hi = rrv__maxd(*hi, f->grid.data[k]);
        }
        /* the ambient value holds between the grid's box and the medium's */
        *lo = rrv__mind(*lo, ambient);
        *hi = rrv__maxd(*hi, ambient);
        return;
    }
    case RRV_FIELD_NANOVDB: /* every stored value and the background */
        *lo = f->nanovdb.value_min;
        *hi = f->nanovdb.value_max;
        return;
    default: *lo = *hi = ambient; return;
    }
}

/* The range of the refractivity r = eta - 1 (artist scale included) that a
   refractive medium's fields can produce inside its box. */
static void rrv__medium_refractivity_range(const rrv_medium *m, double *lo, double *hi)
{
    const rrv_field *f = &m->ior;
    double a, b;
    if (m->ior_from_gas) {
        /* r = r_ref (P / P_ref) (T_ref / T) is monotone in P and in 1/T: its
           extremes sit at the corners of the (P, T) ranges. T is clamped as
           rrv__refractivity clamps it. */
        double t0, t1, p0, p1, r[4];
        int k;
        rrv__field_range(&m->temperature, m->temperatureoffset + m->T_ref / m->temperaturescale, &t0, &t1);
        t0 = rrv__maxd((t0 - m->temperatureoffset) * m->temperaturescale, 1e-3);
        t1 = rrv__maxd((t1 - m->temperatureoffset) * m->temperaturescale, 1e-3);
        rrv__field_range(&m->pressure, m->P_ref, &p0, &p1);
        for (k = 0; k < 4; ++k)
            r[k] = (m->eta_ref - 1.0) * ((k & 1 ? p1 : p0) / m->P_ref) * (m->T_ref / (k & 2 ? t1 : t0));
        a = rrv__mind(rrv__mind(r[0], r[1]), rrv__mind(r[2], r[3]));
        b = rrv__maxd(rrv__maxd(r[0], r[1]), rrv__maxd(r[2], r[3]));
    } else {
        switch (f->kind) {
        case RRV_FIELD_LUNEBURG: a = 0; b = sqrt(2.0) - 1.0; break;
        case RRV_FIELD_FISHEYE: a = 0.5 * f->n0 - 1.0; b = f->n0 - 1.0; break;
        case RRV_FIELD_SLAB: {
            int k;
            a = DBL_MAX;
            b = -DBL_MAX;
            for (k = 0; k < 8; ++k) {
                rrv_vec3 c = rrv__v3(k & 1 ? m->hi.x : m->lo.x, k & 2 ? m->hi.y : m->lo.y, k & 4 ? m->hi.z : m->lo.z);
                double r = f->base + f->gradient * rrv__dot(rrv__sub(c, f->center), f->normal);
                a = rrv__mind(a, r);
                b = rrv__maxd(b, r);
            }
            break;
        }
        case RRV_FIELD_SHELL: {
            /* the tanh pair peaks mid-shell at tanh(thickness / (2 edge)) */
            double peak = tanh(0.5 * f->thickness / f->edge);
            a = f->base + rrv__mind(0.0, f->amplitude * peak);
            b = f->base + rrv__maxd(0.0, f->amplitude * peak);
            break;
        }
        default: rrv__field_range(f, 0.0, &a, &b); break;
        }
    }
    *lo = m->ior_scale * a;
    *hi = m->ior_scale * b;
    if (!(*lo == *lo) || !(*hi == *hi)) *lo = *hi = DBL_MAX; /* NaN: refuse */
}

/* Whether a medium's IOR stays in [RRV_MIN_IOR, RRV_MAX_IOR]; fills the
   range of eta for the message. Outside it a ray is trapped or its radiance
   scale (eta_camera / eta)^2 overflows. */
static int rrv__medium_ior_ok(const rrv_medium *m, double *eta_lo, double *eta_hi)
{
    double lo, hi;
    if (!rrv__medium_refracts(m)) return 1;
    rrv__medium_refractivity_range(m, &lo, &hi);
    *eta_lo = 1.0 + lo;
    *eta_hi = 1.0 + hi;
    return *eta_lo >= RRV_MIN_IOR && *eta_hi <= RRV_MAX_IOR;
}

/* The length over which extinction is compared with RRV_MAX_OPTICAL_DEPTH:
   the box diagonal, or the box's distance from the origin if larger, since
   free flights must stay long against the rounding of the coordinates. */
static double rrv__medium_size(const rrv_medium *m)
{
    double size = rrv__length(rrv__sub(m->hi, m->lo));
    size = rrv__maxd(size, rrv__maxd(fabs(m->lo.x), rrv__maxd(fabs(m->lo.y), fabs(m->lo.z))));
    return rrv__maxd(size, rrv__maxd(fabs(m->hi.x), rrv__maxd(fabs(m->hi.y), fabs(m->hi.z))));
}

/* Peak extinction of a medium (1/m) and whether it times the medium's size
   stays below RRV_MAX_OPTICAL_DEPTH: beyond it the mean free flight shrinks
   toward the rounding step of the coordinates and tracking stalls. */
static int rrv__medium_extinction_ok(const rrv_medium *m, double *peak)
{
    double sigma_t = 0;
    int c;
    for (c = 0; c < 3; ++c) sigma_t = rrv__maxd(sigma_t, (m->sigma_a[c] + m->sigma_s[c]) * m->scale);
    double density = m->density.kind == RRV_FIELD_NONE ? 0.0 : rrv__maxd(0.0, rrv__field_bound(&m->density, m->lo, m->hi));
    *peak = density * sigma_t;
    /* majorant cells hold the density bound as a float */
    if (!(density <= FLT_MAX)) return 0;
    if (*peak == 0) return 1; /* also when sigma_t is infinite and the density 0 */
    return *peak * rrv__medium_size(m) <= RRV_MAX_OPTICAL_DEPTH;
}

/* Whether every emission a medium can make stays at most RRV_MAX_RADIANCE. */
static int rrv__medium_emission_ok(const rrv_medium *m)
{
    return m->Lescale <= RRV_MAX_RADIANCE && rrv__max3(m->Le) * m->Lescale <= RRV_MAX_RADIANCE;
}

/* The unit vector along v, whose components but one are zero (the zeros
   keep their signs, as dividing them by |v| would). */
static rrv_vec3 rrv__axis_unit(rrv_vec3 v)
{
    return rrv__v3(v.x == 0 ? v.x : v.x > 0 ? 1.0 : -1.0, v.y == 0 ? v.y : v.y > 0 ? 1.0 : -1.0,
                   v.z == 0 ? v.z : v.z > 0 ? 1.0 : -1.0);
}

/* Snell's law at a null event (seed Algorithm 1, CONVENTIONS). r_in is the
   refractivity the ray carries, r_out the one at the event, grad its
   gradient. The change of direction is formed directly, because m = eta_in /
   eta_out differs from 1 by ~1e-4 in air and m d - sqrt(k) n would cancel. */
static rrv_vec3 rrv__refract_at_null_event(rrv_vec3 d, double r_in, double r_out, rrv_vec3 grad, int *reflected)
{
    double delta, c, s2, e, k;
    rrv_vec3 n, out;
    *reflected = 0;
    if ((grad.x == 0) + (grad.y == 0) + (grad.z == 0) == 2) {
        /* along an axis (a box face's normal): the unit vector the general
           case below would compute exactly, without its divisions */
        if (!(fabs(grad.x + grad.y + grad.z) <= DBL_MAX)) return d;
        n = rrv__axis_unit(grad);
    } else {
        double big = fmax(fabs(grad.x), fmax(fabs(grad.y), fabs(grad.z)));
        if (!(big > 0) || big > DBL_MAX) return d;
        /* Dividing by the largest component first keeps a denormal gradient
           from overflowing 1/|grad| (its reciprocal is not representable). */
        n = rrv__normalize(rrv__v3(grad.x / big, grad.y / big, grad.z / big));
    }
    delta = (r_in - r_out) / (1.0 + r_out);
    if (delta == 0) return d;
    c = -rrv__dot(n, d);
    /* n must face the side the ray comes from (c >= 0). At exact grazing
       incidence that side is undefined; the IOR change defines it: a ray
       entering higher IOR (delta < 0) comes from the side grad points away
       from, and must bend toward grad. */
    if (c < 0 || (c == 0 && delta < 0)) { n = rrv__scale(n, -1.0); c = -c; }
    s2 = 1.0 - c * c;
    if (!(s2 > 0)) s2 = 0; /* fmax(0, s2) without the library call */
    e = delta * (2.0 + delta) * s2;
    k = c * c - e;
    if (k < 0) {
        *reflected = 1;
        out = rrv__madd(d, n, 2.0 * c);
    } else {
        out = rrv__madd(rrv__madd(d, d, delta), n, delta * c + e / (c + sqrt(k)));
    }
    return rrv__normalize(out);
}

/* ---- majorant grids ----------------------------------------------------------
   A coarse grid over each medium holds, per cell, an upper bound of the
   density and, for refractive media, of |grad r|. Delta and ratio tracking
   walk it with a 3D DDA, so their majorant is local (tight) instead of the
   medium-wide maximum. */

/* Cells per axis: a quarter of the density grid's samples (baked or given),
   4..64, else 16. Measured on the smoke scene: 32^3 cells over its 120-sample
   baked grid render 1.4x faster than 16^3; finer grids cost more DDA steps
   than their tighter bounds save. */
static int rrv__auto_cells(const rrv_medium *m, int axis)
{
    const rrv_field *density = rrv__field_of(m, RRV__DENSITY);
    if (density->kind == RRV_FIELD_GRID) {
        int n = axis == 0 ? density->grid.nx : axis == 1 ? density->grid.ny : density->grid.nz;
        n = (n + 3) / 4;
        return n < 4 ? 4 : n > 64 ? 64 : n;
    }
    if (density->kind == RRV_FIELD_NANOVDB) {
        /* a quarter of the voxels the medium box spans along the axis */
        const rrv_nanovdb *g = &density->nanovdb;
        double extent = rrv__axis(rrv__sub(m->hi, m->lo), axis);
        double voxel = sqrt(g->map[axis] * g->map[axis] + g->map[3 + axis] * g->map[3 + axis] +
                            g->map[6 + axis] * g->map[6 + axis]);
        double n = ceil(extent / voxel / 4.0);
        return !(n >= 4) ? 4 : n > 64 ? 64 : (int)n;
    }
    return 16;
}

/* The distances from c to the nearest and farthest points of a box. */
static void rrv__box_distances(rrv_vec3 c, rrv_vec3 lo, rrv_vec3 hi, double *dmin, double *dmax)
{
    rrv_vec3 far = rrv__v3(rrv__maxd(c.x - lo.x, hi.x - c.x), rrv__maxd(c.y - lo.y, hi.y - c.y),
                           rrv__maxd(c.z - lo.z, hi.z - c.z));
    *dmin = rrv__length(rrv__sub(rrv__vmax(lo, rrv__vmin(hi, c)), c));
    *dmax = rrv__length(far);
}

/* The distance from x to the interval [a, b]. */
static double rrv__interval_distance(double x, double a, double b)
{
    return x < a ? a - x : x > b ? x - b : 0.0;
}

/* max |grad r| of an IOR profile (unscaled) over a box, in closed form;
   returns 0 in *known for the kinds without one. Each profile's gradient is
   radial (slab: constant) with a magnitude that is monotone or unimodal in
   the distance d from its centre, so its max over [dmin, dmax] follows. */
static double rrv__profile_gradient_bound(const rrv_field *f, rrv_vec3 lo, rrv_vec3 hi, int *known)
{
    double dmin, dmax, R = f->radius, d, q;
    *known = 1;
    rrv__box_distances(f->center, lo, hi, &dmin, &dmax);
    switch (f->kind) {
    case RRV_FIELD_NONE:
    case RRV_FIELD_CONSTANT: return 0;
    case RRV_FIELD_SLAB: return fabs(f->gradient);
    case RRV_FIELD_LUNEBURG: /* d / (R^2 sqrt(2 - d^2/R^2)), rising in d */
        if (dmin >= R) return 0;
        d = rrv__mind(dmax, R);
        return d / (R * R * sqrt(2.0 - d * d / (R * R)));
    case RRV_FIELD_FISHEYE: /* 2 n0 d / (R^2 (1 + d^2/R^2)^2), peak at R / sqrt(3) */
        if (dmin >= R) return 0;
        d = rrv__clamp(R / sqrt(3.0), dmin, rrv__mind(dmax, R));
        q = 1.0 + d * d / (R * R);
        return 2.0 * f->n0 * d / (R * R * q * q);
    case RRV_FIELD_SHELL: { /* |A| / (2 e) |sech^2 at the inner edge - sech^2 at the outer| */
        double e = f->edge, ci = cosh(rrv__interval_distance(f->radius - f->thickness, dmin, dmax) / e);
        double co = cosh(rrv__interval_distance(f->radius, dmin, dmax) / e);
        return fabs(f->amplitude) / (2.0 * e) * rrv__maxd(1.0 / (ci * ci), 1.0 / (co * co));
    }
    case RRV_FIELD_BLOBS: { /* each |w| d / s^2 exp(-d^2 / (2 s^2)), peak at d = s */
        double sum = 0;
        int i;
        for (i = 0; i < f->blob_count; ++i) {
            const rrv_blob *b = &f->blobs[i];
            double s2 = b->radius * b->radius;
            rrv__box_distances(b->center, lo, hi, &dmin, &dmax);
            d = rrv__clamp(b->radius, dmin, dmax);
            sum += fabs(b->weight) * d / s2 * exp(-0.5 * d * d / s2);
        }
        return sum;
    }
    default: *known = 0; return 0;
    }
}

/* Whether the refractivity is flat wherever the baked refraction grid does
   not reach: then its gradient samples bound |grad r| over any cell. True
   for an IOR grid (ambient outside it) and for a gas whose other field is
   constant or absent. */
static int rrv__flat_beyond_bake(const rrv_medium *m)
{
    const rrv_field *t, *p;
    /* a NanoVDB grid's bake reaches one voxel past its data (or past the
       medium's box), beyond which its background is flat */
    int tg, pg;
    if (!m->ior_from_gas) {
        rrv_field_kind k = rrv__field_of(m, RRV__IOR)->kind;
        return k == RRV_FIELD_GRID || k == RRV_FIELD_NANOVDB;
    }
    t = rrv__field_of(m, RRV__TEMPERATURE);
    p = rrv__field_of(m, RRV__PRESSURE);
    tg = t->kind == RRV_FIELD_GRID || t->kind == RRV_FIELD_NANOVDB;
    pg = p->kind == RRV_FIELD_GRID || p->kind == RRV_FIELD_NANOVDB;
    return (tg && (p->kind == RRV_FIELD_NONE || p->kind == RRV_FIELD_CONSTANT)) ||
           (pg && (t->kind == RRV_FIELD_NONE || t->kind == RRV_FIELD_CONSTANT));
}

/* max |grad r| over a cell, times a margin of 1.5. It sets an event rate,
   not a bound that correctness depends on; the margin is the one the
   sampled estimate (below) always carried, so rates stayed where the
   measured tables put them. Closed forms and the baked grid's gradient
   samples make it cheap (it used to cost 64 gradient lookups a cell even
   for a constant IOR: minutes at 256^3 cells); only a gas with fields that
   are neither grids nor constant is still sampled, on a 4^3 lattice. */
static double rrv__cell_gradient_bound(const rrv_medium *m, rrv_vec3 lo, rrv_vec3 hi, double ambient_r)
{
    double best = 0;
    int i, j, k;
    const rrv_grid *baked = m->majorant ? &m->majorant->refraction : NULL;
    if (baked && baked->data && rrv__flat_beyond_bake(m)) {
        int a[3], b[3], x, y, z;
        if (!rrv__grid_span(baked, lo, hi, a, b)) return 0;
        for (z = a[2]; z <= b[2]; ++z)
            for (y = a[1]; y <= b[1]; ++y)
                for (x = a[0]; x <= b[0]; ++x) {
                    const float *v = baked->data + 4 * (((size_t)z * (size_t)baked->ny + (size_t)y) *
                                                            (size_t)baked->nx + (size_t)x);
                    best = rrv__maxd(best, sqrt((double)v[1] * v[1] + (double)v[2] * v[2] + (double)v[3] * v[3]));
                }
        return 1.5 * best;
    }
    if (!m->ior_from_gas) {
        int known;
        double bound = rrv__profile_gradient_bound(rrv__field_of(m, RRV__IOR), lo, hi, &known);
        if (known) return 1.5 * m->ior_scale * bound;
    } else {
        const rrv_field *t = rrv__field_of(m, RRV__TEMPERATURE), *p = rrv__field_of(m, RRV__PRESSURE);
        if ((t->kind == RRV_FIELD_NONE || t->kind == RRV_FIELD_CONSTANT) &&
            (p->kind == RRV_FIELD_NONE || p->kind == RRV_FIELD_CONSTANT))
            return 0;
    }
    for (k = 0; k < 4; ++k)
        for (j = 0; j < 4; ++j)
            for (i = 0; i < 4; ++i) {
                rrv_vec3 p = rrv__v3(lo.x + (hi.x - lo.x) * i / 3.0, lo.y + (hi.y - lo.y) * j / 3.0,
                                     lo.z + (hi.z - lo.z) * k / 3.0);
                rrv_vec3 g;
                rrv__refractivity_gradient(m, p, ambient_r, &g);
                best = fmax(best, rrv__length(g));
            }
    return 1.5 * best;
}

/* A bound on how far the Jacobian of the blended gradient of the baked
   refraction grid moves within a cell, |J(p) - J(q)| (Frobenius) for p, q
   in [lo, hi]. Inside a lattice cell, column a of J is a bilinear blend of
   the cell's four gradient differences along axis a over the sample
   spacing; so J(p) - J(q) lies in the box of those differences' ranges over
   the lattice cells [lo, hi] spans (across a lattice face J jumps, and both
   sides are in the ranges), and the box's diagonal bounds it. -1 where J is
   not that blend: closed forms, sampled gases, cubic interpolation, and a
   cell reaching past the bake (where the gradient drops to 0, a jump that
   no bound on J covers). */
static double rrv__cell_jacobian_wander(const rrv_medium *m, rrv_vec3 lo, rrv_vec3 hi)
{
    const struct rrv__majorant_grid *mg = m->majorant;
    const rrv_grid *baked = &mg->refraction;
    const size_t stride[3] = {4, 4 * (size_t)baked->nx, 4 * (size_t)baked->nx * (size_t)baked->ny};
    const double scale[3] = {mg->refraction_scale.x, mg->refraction_scale.y, mg->refraction_scale.z};
    double low[9], high[9], sum = 0;
    int a[3], b[3], x, y, z, axis, c, first[3] = {1, 1, 1};
    if (!baked->data || !rrv__flat_beyond_bake(m)) return -1;
    if (lo.x < baked->lo.x || lo.y < baked->lo.y || lo.z < baked->lo.z || hi.x > baked->hi.x ||
        hi.y > baked->hi.y || hi.z > baked->hi.z)
        return -1;
    if (!rrv__grid_span(baked, lo, hi, a, b)) return -1;
    for (z = a[2]; z <= b[2]; ++z)
        for (y = a[1]; y <= b[1]; ++y)
            for (x = a[0]; x <= b[0]; ++x) {
                const int at[3] = {x, y, z};
                const float *v = baked->data + (size_t)x * stride[0] + (size_t)y * stride[1] + (size_t)z * stride[2];
                for (axis = 0; axis < 3; ++axis) {
                    const float *w = v + stride[axis];
                    if (at[axis] >= b[axis]) continue; /* the edge along axis leaves the span */
                    for (c = 0; c < 3; ++c) {
                        double dj = ((double)w[1 + c] - v[1 + c]) * scale[axis];
                        int k = 3 * axis + c;
                        if (first[axis] || dj < low[k]) low[k] = dj;
                        if (first[axis] || dj > high[k]) high[k] = dj;
                    }
                    first[axis] = 0;
                }
            }
    for (axis = 0; axis < 3; ++axis)
        if (first[axis]) return -1; /* a lattice of one sample along an axis */
    for (c = 0; c < 9; ++c) sum += (high[c] - low[c]) * (high[c] - low[c]);
    return sqrt(sum);
}

/* Refuses a grid rrv_scene_prepare would build (majorant, bake) of `count`
   entries of `size` bytes above the scene's grid limit: the limit that keeps
   a hostile file from exhausting memory holds for what it makes us build. */
static rrv_result rrv__check_built_grid(const rrv_scene *scene, const rrv_medium *m, const char *what,
                                        size_t count, size_t size, rrv_error *err)
{
    size_t limit = scene->max_grid_bytes ? scene->max_grid_bytes : RRV_DEFAULT_MAX_GRID_BYTES;
    if (count > limit / size)
        return rrv__fail(err, RRV_ERROR_LIMIT, scene->path, 0,
                         "medium \"%s\": its %s would need %.1f MiB, above the grid limit of %.1f MiB", m->name,
                         what, (double)count * (double)size / 1048576.0, (double)limit / 1048576.0);
    return RRV_OK;
}

/* The position of sample (x, y, z) of an n[0] x n[1] x n[2] lattice whose
   corner samples lie on the faces of the box [lo, hi] (CONVENTIONS). */
static rrv_vec3 rrv__lattice_point(rrv_vec3 lo, rrv_vec3 hi, const int n[3], int x, int y, int z)
{
    return rrv__v3(lo.x + (hi.x - lo.x) * x / (n[0] - 1), lo.y + (hi.y - lo.y) * y / (n[1] - 1),
                   lo.z + (hi.z - lo.z) * z / (n[2] - 1));
}

/* Bakes a noise field over the medium box: four samples to the finest
   octave's wavelength (at two, trilinear interpolation of T and of r = k/T
   already disagreed by 10% in the bending of heat haze), at most 128
   samples an axis (8 MiB a field) or settings.max_bake_samples. */
/* Set-up work split into independent tasks: the client's parallel_for, or
   a plain loop. */
static void rrv__parallel_for(const rrv_scene *scene, int count, void (*task)(void *, int), void *ctx)
{
    int i;
    if (scene->parallel_for && count > 1) {
        scene->parallel_for(scene->parallel_for_user, count, task, ctx);
        return;
    }
    for (i = 0; i < count; ++i) task(ctx, i);
}

typedef struct rrv__noise_bake {
    const rrv_field *f;
    const rrv_medium *m;
    int n[3];
    float *data;
} rrv__noise_bake;

/* One z slice of a noise bake. */
static void rrv__bake_noise_slice(void *ctx, int z)
{
    const rrv__noise_bake *job = (const rrv__noise_bake *)ctx;
    size_t i = (size_t)z * (size_t)job->n[1] * (size_t)job->n[0];
    int x, y;
    for (y = 0; y < job->n[1]; ++y)
        for (x = 0; x < job->n[0]; ++x)
            job->data[i++] =
                (float)rrv__field_eval(job->f, rrv__lattice_point(job->m->lo, job->m->hi, job->n, x, y, z), 0, 0.0);
}

static rrv_result rrv__bake_noise(const rrv_scene *scene, const rrv_medium *m, const rrv_field *f, rrv_field *out,
                                  size_t *bytes, rrv_error *err)
{
    const rrv_noise *nz = &f->noise;
    double finest = nz->frequency * pow(nz->lacunarity, nz->octaves - 1);
    rrv_vec3 ext = rrv__sub(m->hi, m->lo);
    double longest = rrv__maxd(ext.x, rrv__maxd(ext.y, ext.z));
    int cap = scene->settings.max_bake_samples, n[3], a;
    double voxel;
    size_t count;
    float *data;
    cap = cap <= 0 || cap > 128 ? 128 : cap < 2 ? 2 : cap;
    voxel = rrv__maxd(0.25 / finest, longest / (cap - 1));
    for (a = 0; a < 3; ++a) {
        double cells = ceil(rrv__axis(ext, a) / voxel);
        n[a] = cells < 1 ? 2 : cells > cap - 1 ? cap : (int)cells + 1;
    }
    count = (size_t)n[0] * (size_t)n[1] * (size_t)n[2];
    {
        rrv_result res = rrv__check_built_grid(scene, m, "baked noise", count, sizeof(float), err);
        if (res != RRV_OK) return res;
    }
    data = (float *)RRV_MALLOC(count * sizeof(float));
    if (!data) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory baking a noise field");
    {
        rrv__noise_bake job;
        job.f = f;
        job.m = m;
        for (a = 0; a < 3; ++a) job.n[a] = n[a];
        job.data = data;
        rrv__parallel_for(scene, n[2], rrv__bake_noise_slice, &job);
    }
    memset(out, 0, sizeof *out);
    out->kind = RRV_FIELD_GRID;
    out->grid.nx = n[0];
    out->grid.ny = n[1];
    out->grid.nz = n[2];
    out->grid.channels = 1;
    out->grid.lo = m->lo;
    out->grid.hi = m->hi;
    out->grid.data = data;
    *bytes += count * sizeof(float);
    return RRV_OK;
}

/* Turns n samples f_i, stored at c[(i + 1) stride], into the coefficients
   c_{-1} .. c_n (at c[0] .. c[(n + 1) stride]) of the cubic B-spline that
   interpolates them. The end conditions clamp the spline's slope to the
   one-sided difference of the samples that is exact for cubics (four points;
   fewer on short lines), so the spline reproduces every cubic, the slope at
   a face is the field's and not forced to 0 as mirrored ends would. The
   system is tridiagonal and diagonally dominant: Thomas elimination, with
   scratch for 2n doubles. n >= 2. */
static void rrv__bspline_line(double *c, size_t stride, int n, double *scratch)
{
    double *cp = scratch, *dp = scratch + n, d0, d1, m;
    const double *f = c + stride;
    int i;
#define RRV__F(i) f[(size_t)(i) * stride]
    if (n >= 4) {
        d0 = (-11.0 * RRV__F(0) + 18.0 * RRV__F(1) - 9.0 * RRV__F(2) + 2.0 * RRV__F(3)) / 6.0;
        d1 = (11.0 * RRV__F(n - 1) - 18.0 * RRV__F(n - 2) + 9.0 * RRV__F(n - 3) - 2.0 * RRV__F(n - 4)) / 6.0;
    } else if (n == 3) {
        d0 = (-3.0 * RRV__F(0) + 4.0 * RRV__F(1) - RRV__F(2)) / 2.0;
        d1 = (3.0 * RRV__F(2) - 4.0 * RRV__F(1) + RRV__F(0)) / 2.0;
    } else {
        d0 = d1 = RRV__F(1) - RRV__F(0);
    }
    /* Rows: 4 c_0 + 2 c_1 = 6 f_0 + 2 d0; c_{i-1} + 4 c_i + c_{i+1} = 6 f_i;
       2 c_{n-2} + 4 c_{n-1} = 6 f_{n-1} - 2 d1 (the ghosts eliminated). */
    cp[0] = 0.5;
    dp[0] = (6.0 * RRV__F(0) + 2.0 * d0) / 4.0;
    for (i = 1; i < n; ++i) {
        double sub = i == n - 1 ? 2.0 : 1.0, rhs = 6.0 * RRV__F(i) - (i == n - 1 ? 2.0 * d1 : 0.0);
        m = 4.0 - sub * cp[i - 1];
        cp[i] = 1.0 / m;
        dp[i] = (rhs - sub * dp[i - 1]) / m;
    }
#undef RRV__F
    c[(size_t)n * stride] = dp[n - 1];
    for (i = n - 2; i >= 0; --i) c[(size_t)(i + 1) * stride] = dp[i] - cp[i] * c[(size_t)(i + 2) * stride];
    c[0] = c[2 * stride] - 2.0 * d0;
    c[(size_t)(n + 1) * stride] = c[(size_t)(n - 1) * stride] + 2.0 * d1;
}

/* Cubic interpolation of the refractivity on a grid's lattice: r at the
   samples, then the B-spline prefilter along x, y and z (the interpolating
   tensor-product spline is the three 1-D solves in turn). Coefficients stay
   double: their differences are the gradient, and float would round away
   the ~1e-9 a voxel by which air's refractivity changes. */
static rrv_result rrv__bake_cubic(const rrv_scene *scene, rrv_medium *m, const rrv_grid *lattice, size_t *bytes,
                                  rrv_error *err)
{
    struct rrv__majorant_grid *g = m->majorant;
    double ambient_r = rrv__ambient_ior(scene) - 1.0, rmin = DBL_MAX, *c, *scratch;
    int n[3], P[3], x, y, z, longest;
    size_t count, sx, sy, sz;
    n[0] = lattice->nx; n[1] = lattice->ny; n[2] = lattice->nz;
    for (x = 0; x < 3; ++x) P[x] = n[x] + 2;
    longest = n[0] > n[1] ? (n[0] > n[2] ? n[0] : n[2]) : (n[1] > n[2] ? n[1] : n[2]);
    count = (size_t)P[0] * (size_t)P[1] * (size_t)P[2];
    sx = 1; sy = (size_t)P[0]; sz = sy * (size_t)P[1];
    c = (double *)RRV_MALLOC(count * sizeof(double));
    scratch = (double *)RRV_MALLOC((size_t)longest * 2 * sizeof(double));
    if (!c || !scratch) {
        RRV_FREE(c);
        RRV_FREE(scratch);
        return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory baking a refractivity grid");
    }
    memset(c, 0, count * sizeof(double));
    for (z = 0; z < n[2]; ++z)
        for (y = 0; y < n[1]; ++y)
            for (x = 0; x < n[0]; ++x) {
                double r = rrv__refractivity(m, rrv__lattice_point(lattice->lo, lattice->hi, n, x, y, z), ambient_r);
                c[(size_t)(x + 1) * sx + (size_t)(y + 1) * sy + (size_t)(z + 1) * sz] = r;
                if (r < rmin) rmin = r;
            }
    for (z = 1; z <= n[2]; ++z)
        for (y = 1; y <= n[1]; ++y) rrv__bspline_line(c + (size_t)y * sy + (size_t)z * sz, sx, n[0], scratch);
    for (z = 1; z <= n[2]; ++z)
        for (x = 0; x < P[0]; ++x) rrv__bspline_line(c + (size_t)x + (size_t)z * sz, sy, n[1], scratch);
    for (y = 0; y < P[1]; ++y)
        for (x = 0; x < P[0]; ++x) rrv__bspline_line(c + (size_t)x + (size_t)y * sy, sz, n[2], scratch);
    RRV_FREE(scratch);
    g->refraction = *lattice;
    g->refraction.channels = 1;
    g->refraction.data = NULL;
    g->cubic = c;
    g->cubic_floor = rmin - 0.5 * (1.0 + rmin);
    *bytes += count * sizeof(double);
    return RRV_OK;
}

/* Bakes the refractivity r and its gradient into one 4-channel grid on the
   lattice of the grid the IOR comes from (a temperature, pressure or IOR
   grid, given or baked from noise): a refraction kick then costs one
   trilinear fetch instead of a temperature lookup, Hauf-Grigull and a
   48-sample gradient stencil. The gradient is the central difference at
   each sample (one-sided at the faces), blended trilinearly: the second-order
   stencil of rrv__grid_gradient. Analytic profiles keep their closed forms. */
/* The index points of a NanoVDB grid around the box [lo, hi] as a lattice
   of corner samples, for the refraction bake: only for maps without
   rotation or shear (the lattice must be axis-aligned), with at least two
   points an axis, and at most 2^24 points (256 MiB of baked samples; past
   that the refractivity comes from the tree at every kick). 0 if none. */
static int rrv__nv_lattice(const rrv_nanovdb *g, rrv_vec3 lo, rrv_vec3 hi, int cap, rrv_grid *out)
{
    double blo[3], bhi[3], w[2][3], count = 1;
    int a, n[3];
    blo[0] = lo.x; blo[1] = lo.y; blo[2] = lo.z;
    bhi[0] = hi.x; bhi[1] = hi.y; bhi[2] = hi.z;
    if (g->map[1] != 0 || g->map[2] != 0 || g->map[3] != 0 || g->map[5] != 0 || g->map[6] != 0 || g->map[7] != 0)
        return 0;
    for (a = 0; a < 3; ++a) {
        double s = g->map[4 * a], t = g->translation[a];
        double u0 = (blo[a] - t) / s, u1 = (bhi[a] - t) / s, i0, i1;
        if (u0 > u1) { double x = u0; u0 = u1; u1 = x; }
        /* One point beyond the cells that reach into the box, so that every
           sample whose gradient the box sees is a central difference, as
           inside a gridvol grid (a millionth of a voxel absorbs the rounding
           of a box face put on an index point). */
        i0 = fmax(floor(u0 + 1e-6) - 1.0, (double)g->data_lo[a] - 1.0);
        i1 = fmin(ceil(u1 - 1e-6) + 1.0, (double)g->data_hi[a] + 1.0);
        if (!(i1 - i0 >= 1.0) || i1 - i0 + 1.0 > (double)(1 << 24)) return 0;
        if (cap > 0 && i1 - i0 + 1.0 > (double)cap) return 0; /* settings.max_bake_samples */
        n[a] = (int)(i1 - i0) + 1;
        count *= n[a];
        w[0][a] = s * (s > 0 ? i0 : i1) + t;
        w[1][a] = s * (s > 0 ? i1 : i0) + t;
    }
    if (count > (double)(1 << 24)) return 0;
    memset(out, 0, sizeof *out);
    out->nx = n[0]; out->ny = n[1]; out->nz = n[2];
    out->channels = 1;
    out->lo = rrv__v3(w[0][0], w[0][1], w[0][2]);
    out->hi = rrv__v3(w[1][0], w[1][1], w[1][2]);
    return 1;
}

static rrv_result rrv__bake_refraction(const rrv_scene *scene, rrv_medium *m, size_t *bytes, rrv_error *err)
{
    const rrv_grid *lattice = NULL;
    rrv_grid nanovdb_lattice;
    const rrv_field *candidates[2];
    struct rrv__majorant_grid *g = m->majorant;
    double ambient_r = rrv__ambient_ior(scene) - 1.0;
    size_t count, i;
    int k, x, y, z, n[3];
    float *data;
    if (!rrv__medium_refracts(m)) return RRV_OK;
    candidates[0] = m->ior_from_gas ? rrv__field_of(m, RRV__TEMPERATURE) : rrv__field_of(m, RRV__IOR);
    candidates[1] = m->ior_from_gas ? rrv__field_of(m, RRV__PRESSURE) : NULL;
    for (k = 0; k < 2 && !lattice; ++k)
        if (candidates[k] && candidates[k]->kind == RRV_FIELD_GRID) lattice = &candidates[k]->grid;
    for (k = 0; k < 2 && !lattice; ++k)
        if (candidates[k] && candidates[k]->kind == RRV_FIELD_NANOVDB &&
            rrv__nv_lattice(&candidates[k]->nanovdb, m->lo, m->hi, scene->settings.max_bake_samples, &nanovdb_lattice))
            lattice = &nanovdb_lattice;
    if (!lattice) return RRV_OK;
    if (scene->settings.ior_interpolation == RRV_IOR_INTERP_CUBIC) return rrv__bake_cubic(scene, m, lattice, bytes, err);
    n[0] = lattice->nx; n[1] = lattice->ny; n[2] = lattice->nz;
    count = (size_t)n[0] * (size_t)n[1] * (size_t)n[2];
    {
        rrv_result res = rrv__check_built_grid(scene, m, "baked refractivity grid", count, 4 * sizeof(float), err);
        if (res != RRV_OK) return res;
    }
    data = (float *)RRV_MALLOC(count * 4 * sizeof(float));
    if (!data) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory baking a refractivity grid");
    i = 0;
    for (z = 0; z < n[2]; ++z)
        for (y = 0; y < n[1]; ++y)
            for (x = 0; x < n[0]; ++x, ++i) {
                rrv_vec3 p = rrv__lattice_point(lattice->lo, lattice->hi, n, x, y, z);
                data[4 * i] = (float)rrv__refractivity(m, p, ambient_r);
            }
    i = 0;
    for (z = 0; z < n[2]; ++z)
        for (y = 0; y < n[1]; ++y)
            for (x = 0; x < n[0]; ++x, ++i) {
                int c[3], a;
                size_t stride[3];
                double extent[3];
                c[0] = x; c[1] = y; c[2] = z;
                stride[0] = 1; stride[1] = (size_t)n[0]; stride[2] = (size_t)n[0] * (size_t)n[1];
                extent[0] = lattice->hi.x - lattice->lo.x;
                extent[1] = lattice->hi.y - lattice->lo.y;
                extent[2] = lattice->hi.z - lattice->lo.z;
                for (a = 0; a < 3; ++a) {
                    int lo = c[a] > 0 ? c[a] - 1 : c[a], hi = c[a] < n[a] - 1 ? c[a] + 1 : c[a];
                    double up = data[4 * (i + (size_t)(hi - c[a]) * stride[a])];
                    double down = data[4 * (i - (size_t)(c[a] - lo) * stride[a])];
                    data[4 * i + 1 + a] = (float)((up - down) / ((hi - lo) * extent[a] / (n[a] - 1)));
                }
            }
    g->refraction = *lattice;
    g->refraction.channels = 4;
    g->refraction.data = data;
    g->refraction_scale = rrv__v3((lattice->nx - 1) / (lattice->hi.x - lattice->lo.x),
                                  (lattice->ny - 1) / (lattice->hi.y - lattice->lo.y),
                                  (lattice->nz - 1) / (lattice->hi.z - lattice->lo.z));
    *bytes += count * 4 * sizeof(float);
    return RRV_OK;
}

typedef struct rrv__majorant_bake {
    const rrv_medium *m;
    struct rrv__majorant_grid *g;
    double ambient_r;
} rrv__majorant_bake;

/* The bounds of one z layer of majorant cells. */
static void rrv__majorant_slice(void *ctx, int z)
{
    const rrv__majorant_bake *job = (const rrv__majorant_bake *)ctx;
    const rrv_medium *m = job->m;
    struct rrv__majorant_grid *g = job->g;
    size_t c = (size_t)z * (size_t)g->n[1] * (size_t)g->n[0];
    int x, y;
    for (y = 0; y < g->n[1]; ++y)
        for (x = 0; x < g->n[0]; ++x, ++c) {
            rrv_vec3 lo = rrv__v3(g->lo.x + x * g->cell.x, g->lo.y + y * g->cell.y, g->lo.z + z * g->cell.z);
            rrv_vec3 hi = rrv__add(lo, g->cell);
            double d = rrv__mind(rrv__field_bound(rrv__field_of(m, RRV__DENSITY), lo, hi), FLT_MAX);
            /* Round the float bound up so it stays a bound (the loader
               refused densities beyond float). */
            float df = (float)d;
            if ((double)df < d) df = nextafterf(df, FLT_MAX);
            g->density_max[c] = df > 0 ? df : 0.0f;
            {
                /* rounded down, so it stays below the field; never above the bound */
                double l = rrv__field_lower(rrv__field_of(m, RRV__DENSITY), rrv__vmax(lo, m->lo), rrv__vmin(hi, m->hi));
                float lf = (float)rrv__mind(l, FLT_MAX);
                if ((double)lf > l) lf = nextafterf(lf, -FLT_MAX);
                g->density_min[c] = lf > 0 ? (lf < g->density_max[c] ? lf : g->density_max[c]) : 0.0f;
            }
            if (g->grad_max)
                g->grad_max[c] = (float)rrv__mind(rrv__cell_gradient_bound(m, lo, hi, job->ambient_r), FLT_MAX);
            if (g->jacobian_wander) {
                /* rounded up, as the density bound; -1 stays -1 */
                double v = rrv__mind(rrv__cell_jacobian_wander(m, lo, hi), FLT_MAX);
                float vf = (float)v;
                if ((double)vf < v) vf = nextafterf(vf, FLT_MAX);
                g->jacobian_wander[c] = vf;
            }
        }
}

/* Where the majorant cells lie: their count per axis, g->lo (a corner of
   the first cell) and the cell size; together they cover the medium's box.
   Normally the box is cut into rrv__auto_cells cells an axis. Where one cell
   could hold an optical depth above 64 (a voxel of 1e8 in an empty grid),
   null collisions around the large values swamp the walks through it, so
   the cells get finer: 4 times as many for fields without voxels; on a
   density grid, its voxels, each split into equal parts where that makes
   fewer than 16 cells across the box; at most 256 (or max_bake_samples)
   an axis.
   Cells on the voxels matter as much as their size: the bound over a part
   of a voxel is exact (rrv__grid_bound), but a cell across a voxel's face
   or the grid's own face, beyond which the density drops to 0, bounds the
   empty side by the full side, and a ray along the face pays a null
   collision per 1/majorant of its length. Those cells start from the
   grid's faces, so the first and last may reach past the medium's box;
   a refractive medium keeps its cells on its box, where the comb's spacing
   (rrv__rate_distance) ends its walk. */
static void rrv__majorant_lattice(const rrv_scene *scene, const rrv_medium *m, int refracts, int refine,
                                  struct rrv__majorant_grid *g)
{
    const rrv_field *density = rrv__field_of(m, RRV__DENSITY);
    int forced = scene->settings.majorant_cells, cap = 256, a;
    double lo[3], hi[3], cell[3];
    if (scene->settings.max_bake_samples > 0 && scene->settings.max_bake_samples < cap)
        cap = scene->settings.max_bake_samples;
    for (a = 0; a < 3; ++a) {
        g->n[a] = forced > 0 ? (forced > cap ? cap : forced) : rrv__auto_cells(m, a);
        if (g->n[a] > cap) g->n[a] = cap;
        lo[a] = rrv__axis(m->lo, a);
        hi[a] = rrv__axis(m->hi, a);
        cell[a] = (hi[a] - lo[a]) / g->n[a];
    }
    if (refine && forced <= 0 && rrv__field_bound(density, m->lo, m->hi) * g->sigma_t_max *
                               rrv__length(rrv__v3(cell[0], cell[1], cell[2])) > 64.0) {
        rrv_vec3 ext = rrv__sub(m->hi, m->lo);
        for (a = 0; a < 3; ++a) {
            double mlo = rrv__axis(m->lo, a), extent = rrv__axis(ext, a);
            int target = 4 * g->n[a] > cap ? cap : 4 * g->n[a], n = target;
            if (density->kind == RRV_FIELD_GRID) {
                const rrv_grid *d = &density->grid;
                int voxels = (a == 0 ? d->nx : a == 1 ? d->ny : d->nz) - 1;
                double glo = rrv__axis(d->lo, a), voxel = (rrv__axis(d->hi, a) - glo) / voxels;
                /* voxels wider than a 16th of the box are split */
                int parts = (int)rrv__clamp(ceil(voxel * (cap < 16 ? cap : 16) / extent - 1e-9), 1.0, (double)cap);
                if (!refracts) {
                    /* as many of those parts as fit under the cap */
                    for (; parts >= 1; --parts) {
                        double c = voxel / parts, first = glo - ceil((glo - mlo) / c - 1e-9) * c;
                        double count = ceil((mlo + extent - first) / c - 1e-9);
                        if (count <= cap) {
                            if (count > g->n[a]) {
                                g->n[a] = (int)count;
                                lo[a] = first;
                                hi[a] = first + count * c;
                                cell[a] = c;
                            }
                            break;
                        }
                    }
                    if (parts >= 1) continue;
                    parts = 1;
                }
                /* on the medium's box: as many cells as the parts make */
                n = voxels > cap / parts ? cap : voxels * parts;
            }
            if (n > g->n[a]) {
                g->n[a] = n;
                cell[a] = extent / n;
            }
        }
    }
    g->lo = rrv__v3(lo[0], lo[1], lo[2]);
    g->hi = rrv__v3(hi[0], hi[1], hi[2]);
    g->cell = rrv__v3(cell[0], cell[1], cell[2]);
    g->inv_cell = rrv__v3(1.0 / g->cell.x, 1.0 / g->cell.y, 1.0 / g->cell.z);
}

/* Channels whose extinctions lie within this factor of the largest in
   their group share that largest as their majorant's scale. One majorant
   for every channel costs each channel the densest one's collisions: with
   sigma_t (4, 6e10, 6) per metre a walk for red (the hero, or its shadow
   ray's ratio tracking, whose weight never falls) takes 1e10 collisions a
   metre; grouped, no channel walks faster than 4 times its own rate. 4
   keeps every scene in scenes/ (blast's 2.9 : 2.7 the most chromatic) in
   one group, where tracking is exactly what one majorant gives. */
#define RRV__CHANNEL_GROUP_SPAN 4.0

/* Sorts the channels by extinction k and groups them from the densest
   down: a channel joins the group whose largest is at most SPAN times its
   own, else opens the next: each channel's group scale into scale and its
   group (0 the densest) into group when given, the count returned. */
static int rrv__channel_group_scales(const double k[3], double scale[3], int group[3])
{
    int order[3] = {0, 1, 2}, i, j, groups = 0;
    double top = 0;
    for (i = 0; i < 3; ++i)
        for (j = i + 1; j < 3; ++j)
            if (k[order[j]] > k[order[i]]) { int t = order[i]; order[i] = order[j]; order[j] = t; }
    for (i = 0; i < 3; ++i) {
        double kc = k[order[i]];
        if (i == 0 || kc * RRV__CHANNEL_GROUP_SPAN < top) {
            top = kc;
            ++groups;
        }
        scale[order[i]] = top;
        if (group) group[order[i]] = groups - 1;
    }
    return groups;
}

static void rrv__group_channels(struct rrv__majorant_grid *g, const double k[3])
{
    g->channel_groups = rrv__channel_group_scales(k, g->channel_scale, NULL);
}

/* The extinction a unit of density gives each channel. */
static void rrv__channel_extinction(const rrv_medium *m, double k[3])
{
    int c;
    for (c = 0; c < 3; ++c) k[c] = (m->sigma_a[c] + m->sigma_s[c]) * m->scale;
}

RRV_DEF int rrv_medium_channel_groups(const rrv_medium *medium, int group[3])
{
    double k[3], scale[3];
    rrv__channel_extinction(medium, k);
    return rrv__channel_group_scales(k, scale, group);
}

static rrv_result rrv__build_majorant(const rrv_scene *scene, rrv_medium *m, size_t *baked_bytes, rrv_error *err)
{
    struct rrv__majorant_grid *g;
    size_t cells, c;
    int x, refracts = rrv__medium_refracts(m), arrays;
    g = (struct rrv__majorant_grid *)RRV_MALLOC(sizeof *g);
    if (!g) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
    memset(g, 0, sizeof *g);
    /* From here on the caller's release frees whatever was built. */
    m->majorant = g;
    g->ior_inert = rrv__ior_is_ambient(scene, m);
    refracts = rrv__medium_refracts(m);
    for (x = 0; x < RRV__FIELD_KINDS; ++x) {
        const rrv_field *user = x == RRV__DENSITY ? &m->density : x == RRV__TEMPERATURE ? &m->temperature
                              : x == RRV__PRESSURE ? &m->pressure : &m->ior;
        if (user->kind == RRV_FIELD_NOISE) {
            rrv_result res = rrv__bake_noise(scene, m, user, &g->baked[x], baked_bytes, err);
            if (res != RRV_OK) return res;
        }
    }
    {
        rrv_result res = rrv__bake_refraction(scene, m, baked_bytes, err);
        if (res != RRV_OK) return res;
    }
    {
        double k[3];
        rrv__channel_extinction(m, k);
        for (x = 0; x < 3; ++x) g->sigma_t_max = rrv__maxd(g->sigma_t_max, k[x]);
        rrv__group_channels(g, k);
    }
    /* density bounds; gradient bounds where it refracts; Jacobian wander
       bounds where that gradient is a baked trilinear blend */
    arrays = !refracts ? 1 : RRV__COMB_WANDER && g->refraction.data && rrv__flat_beyond_bake(m) ? 3 : 2;
    ++arrays; /* density_min, last */
    rrv__majorant_lattice(scene, m, refracts, 1, g);
    cells = (size_t)g->n[0] * (size_t)g->n[1] * (size_t)g->n[2];
    {
        /* finer cells save work, so they must not cost a refusal: above
           the grid limit the medium keeps the automatic ones */
        size_t limit = scene->max_grid_bytes ? scene->max_grid_bytes : RRV_DEFAULT_MAX_GRID_BYTES;
        if (cells > limit / (sizeof(float) * arrays)) {
            rrv__majorant_lattice(scene, m, refracts, 0, g);
            cells = (size_t)g->n[0] * (size_t)g->n[1] * (size_t)g->n[2];
        }
    }
    {
        rrv_result res = rrv__check_built_grid(scene, m, "majorant grid", cells, sizeof(float) * arrays, err);
        if (res != RRV_OK) return res;
    }
    g->density_max = (float *)RRV_MALLOC(cells * sizeof(float) * arrays);
    if (!g->density_max) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
    g->grad_max = refracts ? g->density_max + cells : NULL;
    g->jacobian_wander = arrays > 3 ? g->density_max + 2 * cells : NULL;
    g->density_min = g->density_max + (size_t)(arrays - 1) * cells;
    {
        rrv__majorant_bake job;
        job.m = m;
        job.g = g;
        job.ambient_r = rrv__ambient_ior(scene) - 1.0;
        rrv__parallel_for(scene, g->n[2], rrv__majorant_slice, &job);
    }
    g->flat_cells = 0;
    for (c = 0; c < cells; ++c) {
        g->density_peak = g->density_max[c] > g->density_peak ? g->density_max[c] : g->density_peak;
        if (refracts) g->grad_peak = g->grad_max[c] > g->grad_peak ? g->grad_max[c] : g->grad_peak;
        if (refracts && !(g->grad_max[c] > 0)) g->flat_cells = 1;
    }
    g->near_flat = NULL;
    g->cell_min = rrv__mind(g->cell.x, rrv__mind(g->cell.y, g->cell.z));
    /* (only a box support's march crosses flat cells, rrv__skip_grid: the
       test is rrv__has_sphere_support's) */
    if (g->flat_cells && (m->ior_from_gas || (m->ior.kind != RRV_FIELD_LUNEBURG && m->ior.kind != RRV_FIELD_FISHEYE))) {
        /* a segment no longer than a cell from a cell none of whose
           neighbours is flat meets no flat cell: the eikonal march skips
           its walk there, a tenth of a weak haze's instructions */
        int i, j, k, n0 = g->n[0], n1 = g->n[1], n2 = g->n[2];
        g->near_flat = (unsigned char *)RRV_MALLOC(cells);
        if (!g->near_flat) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
        memset(g->near_flat, 0, cells);
        for (k = 0; k < n2; ++k)
            for (j = 0; j < n1; ++j)
                for (i = 0; i < n0; ++i) {
                    int a, b2, c2;
                    if (g->grad_max[i + (size_t)n0 * (j + (size_t)n1 * k)] > 0) continue;
                    for (c2 = k > 0 ? k - 1 : 0; c2 <= k + 1 && c2 < n2; ++c2)
                        for (b2 = j > 0 ? j - 1 : 0; b2 <= j + 1 && b2 < n1; ++b2)
                            for (a = i > 0 ? i - 1 : 0; a <= i + 1 && a < n0; ++a)
                                g->near_flat[a + (size_t)n0 * (b2 + (size_t)n1 * c2)] = 1;
                }
    }
    g->empty = 1;
    for (c = 0; c < cells; ++c)
        if (g->density_max[c] > 0 && g->sigma_t_max > 0) { g->empty = 0; break; }
    g->surface_free = 1;
    for (x = 0; x < scene->shape_count && g->surface_free; ++x) {
        rrv_vec3 lo, hi;
        rrv__shape_bounds(&scene->shapes[x], &lo, &hi);
        if (lo.x <= m->hi.x && hi.x >= m->lo.x && lo.y <= m->hi.y && hi.y >= m->lo.y && lo.z <= m->hi.z &&
            hi.z >= m->lo.z)
            g->surface_free = 0;
    }
    {
        const rrv_field *density = rrv__field_of(m, RRV__DENSITY);
        g->density_lo = m->lo;
        g->density_hi = m->hi;
        if (density->kind == RRV_FIELD_GRID) {
            const rrv_grid *d = &density->grid;
            g->density_lo = rrv__vmax(m->lo, d->lo);
            g->density_hi = rrv__vmin(m->hi, d->hi);
        }
        g->density_clipped = !rrv__inside_box(m->lo, g->density_lo, g->density_hi) ||
                             !rrv__inside_box(m->hi, g->density_lo, g->density_hi);
    }
    m->majorant = g;
    return RRV_OK;
}

/* ---- the medium at a point ------------------------------------------------------ */

typedef struct rrv__coeffs {
    double sigma_a[3], sigma_s[3];
} rrv__coeffs;

static void rrv__medium_coeffs(const rrv_medium *m, rrv_vec3 p, rrv__coeffs *c)
{
    const rrv_field *density = rrv__field_of(m, RRV__DENSITY);
    int ch;
    double d = 0;
    int rgb = density->kind == RRV_FIELD_GRID && density->grid.channels == 3;
    if (!rgb) d = rrv__maxd(0.0, rrv__field_eval(density, p, 0, 0.0)) * m->scale;
    for (ch = 0; ch < 3; ++ch) {
        double dc = rgb ? rrv__maxd(0.0, rrv__field_eval(density, p, ch, 0.0)) * m->scale : d;
        c->sigma_a[ch] = dc * m->sigma_a[ch];
        c->sigma_s[ch] = dc * m->sigma_s[ch];
    }
}

/* Blackbody radiance in linear sRGB, normalised as pbrt-v4 normalises its
   BlackbodySpectrum: Planck's law divided by its value at the peak
   wavelength (Wien), so Lescale is the artist's intensity control while a
   cooler gas still glows dimmer and redder, and air at 300 K is black. The
   spectrum is integrated against the CIE 1931 matching functions (the
   multi-lobe Gaussian fit of Wyman et al. 2013) over 380-780 nm and divided
   by the integral of y-bar, so a flat spectrum of 1 has luminance 1.
   (Normalising every temperature to luminance 1 instead made 300 K glow:
   the fit's far-red tails turned its residue yellow or green.) */
/* The CIE 1931 matching functions x-bar, y-bar, z-bar of that fit at 380,
   385, ..., 780 nm: 0.362 g(l, 442, 0.0624, 0.0374) + 1.056 g(l, 599.8,
   0.0264, 0.0323) - 0.065 g(l, 501.1, 0.0490, 0.0382); 0.821 g(l, 568.8,
   0.0213, 0.0247) + 0.286 g(l, 530.9, 0.0613, 0.0322); 1.217 g(l, 437,
   0.0845, 0.0278) + 0.681 g(l, 459, 0.0385, 0.0725), where g(l, mu, a, b) =
   exp(-((l - mu) s)^2 / 2), s = a below mu and b above, evaluated in double
   and printed to 17 digits (so they read back as the same doubles): 8 of
   the 9 exponentials a wavelength do not depend on T, and a blackbody
   costs a ninth of what it did (emission is evaluated at every tentative
   collision in an emitter and at every emission sample). */
static const double rrv__cie_xyz[81][3] = {
    {0.00020353514902462391, 0.0002527216161851356, 0.0066850410766249946},
    {0.00064816576272339478, 0.00038563864827184712, 0.011843508464757234},
    {0.0018727180832361593, 0.00058182561464250704, 0.020444052841848935},
    {0.0049089741048371147, 0.0008679190992042249, 0.034957565228467498},
    {0.011674465044809247, 0.0012800878554606761, 0.060785994910504688},
    {0.025188857635337743, 0.0018666995923386377, 0.10989647883271014},
    {0.049306338497599682, 0.0026914307587138113, 0.20506110783135761},
    {0.087562184061747608, 0.0038367730758001768, 0.37838601057281807},
    {0.14107316123671221, 0.0054078313746207564, 0.65430199927399002},
    {0.20619370965966499, 0.0075362326940578584, 1.0169286279412841},
    {0.27339309010349, 0.010383879010947292, 1.3868227505422199},
    {0.32880149141790538, 0.014146181664307545, 1.6441215824894586},
    {0.35860065901128702, 0.019054328813013159, 1.7339135700731489},
    {0.35849194152118458, 0.025376094477837067, 1.7761983846982077},
    {0.34375002796377574, 0.033414799531508076, 1.7813850393059028},
    {0.31728521309460467, 0.043506550812104881, 1.7467562580292109},
    {0.28120983097812025, 0.056017438531931925, 1.6712173639319907},
    {0.23833296471132409, 0.071346083632105484, 1.5184400837323118},
    {0.19183216533509215, 0.089943955130487682, 1.2944733928112899},
    {0.14496879256097212, 0.11237525712448755, 1.0440589563318641},
    {0.10087664893663909, 0.13944221145672986, 0.80934717112864984},
    {0.062409751227693155, 0.17238145729395224, 0.61484457485254995},
    {0.03201220964991839, 0.21306878872894547, 0.46552538598462168},
    {0.011584264070840913, 0.26405065368359382, 0.35428887417831756},
    {0.0023552597470585801, 0.32811675536312651, 0.27076313304227401},
    {0.004351727309861303, 0.40718380121080011, 0.20645864072839659},
    {0.016480184108821939, 0.50061090898318839, 0.15596246665979799},
    {0.038426975909855499, 0.60364548219235614, 0.11613004862714002},
    {0.069841362788331932, 0.70711337765664362, 0.084991431046892538},
    {0.11035711554123546, 0.7991975402284448, 0.061058145879075418},
    {0.15960658713035328, 0.86905172801049269, 0.043035502499600552},
    {0.21718884440591191, 0.91708579118136901, 0.029754258384332238},
    {0.28259686465191514, 0.95416943907731988, 0.020178454143925249},
    {0.35511625009651682, 0.97999381543674691, 0.013422620711553555},
    {0.43371467213236936, 0.994462468844167, 0.008757821094157462},
    {0.51694532662138781, 0.9979280262656236, 0.0056048484436421724},
    {0.60288764670001027, 0.99108163947731143, 0.0035183633124598523},
    {0.68914405689755409, 0.97483260191064902, 0.0021663393617935628},
    {0.77290345047317388, 0.95010645680451278, 0.0013083420343359806},
    {0.85107188150489865, 0.9157805676584877, 0.00077504174465217301},
    {0.92046051603176704, 0.87213379050532147, 0.00045033727046969263},
    {0.97801188121321248, 0.82055573392065351, 0.00025666088295127809},
    {1.0210391985967395, 0.76258672265023186, 0.00014347970433186959},
    {1.0474508992835472, 0.69987678097925043, 7.8673823740378382e-05},
    {1.0559262692943967, 0.6341359279753237, 4.2313508796912072e-05},
    {1.0411847109084451, 0.56707483839642303, 2.2322190914992563e-05},
    {1.0002049114727773, 0.5003385394021016, 1.1550574684568099e-05},
    {0.93609524044089709, 0.43543873143009476, 5.8624528551210528e-06},
    {0.85353701936539206, 0.37369181431639437, 2.9185297872617804e-06},
    {0.75822248006543869, 0.3161695226872458, 1.4251411934993843e-06},
    {0.6562106303082047, 0.26366743954501598, 6.8259114979287463e-07},
    {0.55330212955343627, 0.21669408921137734, 3.2068039436514805e-07},
    {0.4545210232545146, 0.1754804581862334, 1.4777234365614339e-07},
    {0.36376272999406745, 0.14000724788100802, 6.6791763427169324e-08},
    {0.28363187338080842, 0.11004534326898177, 2.9611585031324308e-08},
    {0.21545892196414829, 0.085204077016220528, 1.287684285855169e-08},
    {0.15945808765907593, 0.064981858437182557, 5.4924502693460365e-09},
    {0.11497442378143685, 0.048814443822016017, 2.2979039261333558e-09},
    {0.080765996191174319, 0.036117290209222171, 9.4298893612926157e-10},
    {0.055274966636859491, 0.026319786494455714, 3.7956863995747625e-10},
    {0.036855393012671371, 0.018890460768474858, 1.4985907461702342e-10},
    {0.023941217219167161, 0.013353356060644545, 5.8034302023830893e-11},
    {0.015151793055417232, 0.0092965595978955554, 2.2044257782124376e-11},
    {0.0093423139093452082, 0.0063743430494247744, 8.2132528425414243e-12},
    {0.0056119979584816748, 0.0043045540245624184, 3.0015383780972304e-12},
    {0.0032843783119053029, 0.0028628542261229443, 1.07592402437954e-12},
    {0.0018726709334521573, 0.0018752010355135779, 3.78293000484681e-13},
    {0.0010402611667120734, 0.0012096881401825281, 1.3046199116722368e-13},
    {0.00056298383611276461, 0.00076855623298171106, 4.4131500694171594e-14},
    {0.00029683977123926583, 0.00048089945607455699, 1.4642741162998621e-14},
    {0.0001524828052830752, 0.00029635290494504072, 4.7654626649343994e-15},
    {7.6311902519527518e-05, 0.0001798623512694136, 1.5212365576805313e-15},
    {3.7207998717311479e-05, 0.00010750965361212982, 4.7631848084206316e-16},
    {1.7674737186470132e-05, 6.3289365578132636e-05, 1.4628746260852909e-16},
    {8.1797916321533919e-06, 3.6693579889726816e-05, 4.406824732883618e-17},
    {3.6881123262192519e-06, 2.0951999554539473e-05, 1.302127304218611e-17},
    {1.6200882084919243e-06, 1.178248539903807e-05, 3.7738975786221242e-18},
    {6.9333928035840174e-07, 6.5256590942992162e-06, 1.0728420062129135e-18},
    {2.8908500980434551e-07, 3.5594909192893856e-06, 2.9915097733790437e-19},
    {1.1742970290875581e-07, 1.9121740950535353e-06, 8.1818983342014193e-20},
    {4.6473242479929695e-08, 1.0116796270257484e-06, 2.1949605943071187e-20}
};

/* The blackbody's CIE XYZ, normalised as the comment above says; 0 at
   and below 100 K. */
static void rrv__blackbody_xyz(double T, double xyz[3])
{
    const double c2 = 1.4387769e-2; /* second radiation constant, m K */
    double X = 0, Y = 0, Z = 0, ybar_sum = 0, lambda, peak, peak_planck;
    int i = 0;
    if (!(T > 100.0)) { xyz[0] = xyz[1] = xyz[2] = 0; return; }
    peak = 2.8977721e-3 / T;
    peak_planck = 1.0 / (peak * peak * peak * peak * peak * (exp(c2 / (peak * T)) - 1.0));
    for (lambda = 380.0; lambda <= 780.0; lambda += 5.0, ++i) {
        double l = lambda * 1e-9;
        double planck = 1.0 / (l * l * l * l * l * (exp(c2 / (l * T)) - 1.0)) / peak_planck;
        double xb = rrv__cie_xyz[i][0], yb = rrv__cie_xyz[i][1], zb = rrv__cie_xyz[i][2];
        X += planck * xb; Y += planck * yb; Z += planck * zb;
        ybar_sum += yb;
    }
    xyz[0] = X / ybar_sum; xyz[1] = Y / ybar_sum; xyz[2] = Z / ybar_sum;
}

static void rrv__xyz_to_linear_srgb(const double xyz[3], double rgb[3])
{
    double X = xyz[0], Y = xyz[1], Z = xyz[2];
    rgb[0] = rrv__maxd(0.0, 3.2404542 * X - 1.5371385 * Y - 0.4985314 * Z);
    rgb[1] = rrv__maxd(0.0, -0.9692660 * X + 1.8760108 * Y + 0.0415560 * Z);
    rgb[2] = rrv__maxd(0.0, 0.0556434 * X - 0.2040259 * Y + 1.0572252 * Z);
}

static void rrv__blackbody_rgb(double T, double rgb[3])
{
    double xyz[3];
    rrv__blackbody_xyz(T, xyz);
    rrv__xyz_to_linear_srgb(xyz, rgb);
}

/* ---- the blackbody by table ------------------------------------------------------
   rrv__blackbody_rgb costs 82 exp; a flame asks for it at every collision
   and every emission sample (15 % of scenes/pyro.rrv's time, 30 % of
   test/bench/campfire.rrv's with emission NEE). rrv_scene_prepare tabulates
   it once for scenes with a blackbody medium: in u = 1/T, the smooth
   g(u) = ln X - 4 ln u per channel of XYZ and its exact derivative, at
   RRV__BLACKBODY_NODES nodes from T = 100 K to RRV__BLACKBODY_T_TOP, read
   by cubic Hermite interpolation. Removing 4 ln u matters: X itself goes as
   u^4 where T is large (Rayleigh-Jeans), whose logarithm no cubic follows
   near u = 0; g tends to a constant there and to Wien's line (ln X about
   -c2 u / lambda) where T is small. Relative error within 1e-6 of the exact
   sum at every temperature (test_blackbody_table); hotter than the table,
   the exact sum. */
#define RRV__BLACKBODY_NODES 1024
#define RRV__BLACKBODY_T_TOP 1e6

struct rrv__blackbody {
    double u0, h, inv_h;                        /* the first node, the spacing in u */
    double g[RRV__BLACKBODY_NODES][3], dg[RRV__BLACKBODY_NODES][3];
};

/* g and dg/du at one node, from the sums of rrv__blackbody_xyz (but not
   through it, which is 0 at the last node, 100 K): with a = c2 u / lambda,
   X is u^5 times a constant times the sum over lambda of xbar lambda^-5 /
   (e^a - 1), whose derivative in u brings each term a factor
   -(c2 / lambda) / (1 - e^-a). */
static void rrv__blackbody_node(double u, double g[3], double dg[3])
{
    const double c2 = 1.4387769e-2, wien = 2.8977721e-3;
    double sum[3] = {0, 0, 0}, dsum[3] = {0, 0, 0}, ybar_sum = 0, lambda, peak = wien * u, norm;
    int i = 0, a;
    for (lambda = 380.0; lambda <= 780.0; lambda += 5.0, ++i) {
        double l = lambda * 1e-9, ea = exp(c2 * u / l);
        double w = 1.0 / (l * l * l * l * l * (ea - 1.0)), dw = -(c2 / l) * w / (1.0 - 1.0 / ea);
        for (a = 0; a < 3; ++a) {
            sum[a] += rrv__cie_xyz[i][a] * w;
            dsum[a] += rrv__cie_xyz[i][a] * dw;
        }
        ybar_sum += rrv__cie_xyz[i][1];
    }
    /* 1 / Planck at the peak, over the y-bar sum */
    norm = peak * peak * peak * peak * peak * (exp(c2 / wien) - 1.0) / ybar_sum;
    for (a = 0; a < 3; ++a) {
        g[a] = log(sum[a] * norm) - 4.0 * log(u);
        dg[a] = 1.0 / u + dsum[a] / sum[a];
    }
}

static void rrv__blackbody_table_fill(struct rrv__blackbody *bb)
{
    int k;
    bb->u0 = 1.0 / RRV__BLACKBODY_T_TOP;
    bb->h = (1.0 / 100.0 - bb->u0) / (RRV__BLACKBODY_NODES - 1);
    bb->inv_h = 1.0 / bb->h;
    for (k = 0; k < RRV__BLACKBODY_NODES; ++k) rrv__blackbody_node(bb->u0 + k * bb->h, bb->g[k], bb->dg[k]);
}

/* rrv__blackbody_xyz from the table (NULL: the exact sum). */
static void rrv__blackbody_lookup_xyz(const struct rrv__blackbody *bb, double T, double xyz[3])
{
    double u, f, t, t2, t3, h00, h10, h01, h11, u4;
    int k, a;
    if (!bb || !(T > 100.0) || !(T < RRV__BLACKBODY_T_TOP)) {
        rrv__blackbody_xyz(T, xyz);
        return;
    }
    u = 1.0 / T;
    f = (u - bb->u0) * bb->inv_h;
    k = (int)f;
    if (k > RRV__BLACKBODY_NODES - 2) k = RRV__BLACKBODY_NODES - 2;
    if (k < 0) k = 0;
    t = f - k;
    t2 = t * t;
    t3 = t2 * t;
    h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    h10 = (t3 - 2.0 * t2 + t) * bb->h;
    h01 = 3.0 * t2 - 2.0 * t3;
    h11 = (t3 - t2) * bb->h;
    u4 = u * u * u * u;
    for (a = 0; a < 3; ++a)
        xyz[a] = exp(h00 * bb->g[k][a] + h10 * bb->dg[k][a] + h01 * bb->g[k + 1][a] + h11 * bb->dg[k + 1][a]) * u4;
}

static void rrv__blackbody_lookup(const struct rrv__blackbody *bb, double T, double rgb[3])
{
    double xyz[3];
    rrv__blackbody_lookup_xyz(bb, T, xyz);
    rrv__xyz_to_linear_srgb(xyz, rgb);
}

static int rrv__medium_emits(const rrv_medium *m)
{
    return m->Lescale > 0 && (m->blackbody_emission || m->Le[0] > 0 || m->Le[1] > 0 || m->Le[2] > 0);
}

/* Emitted radiance of the medium at p (multiplied by sigma_a by the caller).
   The given Le is radiance at the emitter's own IOR and is scaled by
   given_scale; thermal emission by thermal_scale (Kirchhoff: a blackbody in
   a medium of index n emits n^2 B, so it must not dim by 1/n^2 on leaving). */
static void rrv__medium_Le(const rrv_scene *scene, const rrv_medium *m, rrv_vec3 p, double given_scale,
                           double thermal_scale, double Le[3])
{
    int c;
    if (m->blackbody_emission) {
        rrv__blackbody_lookup(scene->blackbody, rrv__temperature(m, p), Le);
        for (c = 0; c < 3; ++c) Le[c] = (Le[c] * thermal_scale + m->Le[c] * given_scale) * m->Lescale;
    } else {
        for (c = 0; c < 3; ++c) Le[c] = m->Le[c] * given_scale * m->Lescale;
    }
}

/* ---- emissive media as lights: the emission grid --------------------------------
   Built by rrv_scene_prepare beside the majorant grids, from the same field
   bounds: each emissive medium's box cut into at most RRV__EMIT_CELLS cells
   along its longest side (proportionally fewer along the others), each cell
   weighted by the power it emits, sigma_a Le averaged over the channels
   and over the centres of the cell's 2 x 2 x 2 octants (the blackbody from
   a table of temperatures), but never below a thousandth of a bound of it
   (max sigma_a x density bound x Lescale x (max Le + the blackbody's
   largest channel at any temperature up to the cell's bound)), so that a
   feature between the octants' centres keeps some weight; one distribution
   over the cells of every emissive medium, normalised (pmf). Blocks of up
   to RRV__EMIT_BLOCK^3 cells are clusters, with the sum W_c of their
   cells' pmf, a centre, a radius and half-extents; blocks of up to
   RRV__EMIT_PAIR^3 clusters are super-clusters, with W_s = sum W_c alike.
   G(x) = 1 / max(|x - centre|^2, radius^2) of a cluster or super-cluster
   (light falls off as 1 / r^2, and a flame a metre across seen from a
   metre away spans a factor of 9 in it; at a surface times a bound of the
   cosine). From a vertex x a super-cluster s is picked in proportion to
   W_s G_s(x), a cluster c of it in proportion to W_c G_c(x), a cell of it
   by its pmf and a point uniformly in that cell: density
       p_nee(y) = [W_s G_s(x) / S(x)] [G_c(x) / S_s(x)] pmf(cell) / volume(cell),
       S = sum_s W_s G_s,  S_s = sum over s's clusters of W_c G_c.
   Two levels, since the pick costs a G per candidate at every vertex:
   with one level, 64 of them on test/bench/campfire.rrv, near a third of
   a render's time at maxdepth 32; with two, 8 + 8 (campfire 4.3x -> 5.0x
   over paths alone there, RESULTS.md). S_s of a super-cluster the sampler
   did not pick is summed only when a forward path's collision or the aim
   asks for the density there, and kept for the vertex.
   The weights steer samples only: any weights leave the estimate unbiased,
   since a cell the grid gives no weight is left to the paths alone (their
   MIS weight there is 1, rrv__emission_forward_weight), and the forward
   paths and the samples read the density through the one lookup,
   rrv__emission_pdf, with the S and S_s of their vertex
   (test/test_emission.c checks it against the sampler's draws). */
#define RRV__EMIT_CELLS 32
#define RRV__EMIT_BLOCK 8
#define RRV__EMIT_PAIR 2    /* clusters per axis in a super-cluster */
#define RRV__EMIT_KEEP 64   /* super-clusters whose W_s G_s a vertex keeps */
#define RRV__EMIT_SUPER_KEEP 32 /* and whose norm S_s (bits of a uint32_t) */
#define RRV__EMIT_TABLE 256 /* temperatures in the blackbody envelope */

typedef struct rrv__emitter_grid {
    int medium;           /* in scene->media */
    int n[3], nc[3], ns[3]; /* cells, clusters and super-clusters per axis */
    rrv_vec3 lo, cell, inv_cell;
    double inv_volume;    /* 1 / a cell's volume */
    size_t first;         /* its first cell in the scene's pmf */
    int first_cluster, first_super;
} rrv__emitter_grid;

/* A cluster of cells, or a super-cluster of clusters. */
typedef struct rrv__emit_cluster {
    rrv_vec3 centre;
    double radius2;       /* half its diagonal, squared */
    rrv_vec3 half;        /* half its extent along each axis */
    double weight;        /* W_c: the sum of its cells' pmf (W_s: of its clusters') */
    size_t begin, end;    /* its cells in order[] (its clusters in member[]) */
} rrv__emit_cluster;

struct rrv__emitters {
    double power;         /* their power over pi, as the light pick weighs shapes */
    rrv__emit_cluster lights; /* where light shapes share the draw: a box around
                                 them all, weight their total (rrv__vertex_emit_share) */
    int count, clusters, supers;
    rrv__emitter_grid *grid;
    int *of_medium;       /* a medium's grid, -1 where it does not emit */
    rrv__emit_cluster *cluster;
    rrv__emit_cluster *super;
    int *member;          /* the clusters of weight, super-cluster by super-cluster */
    int *super_of;        /* per cluster */
    size_t cells;
    double *pmf;          /* per cell, in the grids' order (x fastest) */
    double *cdf;          /* cells + 1: pmf summed in order[]'s order, cluster by cluster */
    size_t *order;        /* cell indices, cluster by cluster */
    size_t bytes;         /* counted in scene->bytes once built */
};

static void rrv__emitters_free(struct rrv__emitters *e)
{
    if (!e) return;
    RRV_FREE(e->grid);
    RRV_FREE(e->of_medium);
    RRV_FREE(e->cluster);
    RRV_FREE(e->super);
    RRV_FREE(e->member);
    RRV_FREE(e->super_of);
    RRV_FREE(e->pmf);
    RRV_FREE(e->cdf);
    RRV_FREE(e->order);
    RRV_FREE(e);
}

/* Can the medium emit anything at all? (It needs absorption to emit.) */
static int rrv__medium_emits_somewhere(const rrv_medium *m)
{
    return rrv__medium_emits(m) && m->density.kind != RRV_FIELD_NONE && m->scale > 0 &&
           rrv__max3(m->sigma_a) > 0;
}

/* An upper bound of the temperature over a box, from the field's bound and
   (for fields whose bound is loose or not one of temperatures: a grid's is 0
   outside it, where the ambient value applies) the ambient temperature. */
static double rrv__temperature_bound(const rrv_medium *m, rrv_vec3 lo, rrv_vec3 hi)
{
    double T = m->T_ref;
    if (m->temperature.kind != RRV_FIELD_NONE) {
        double f = rrv__field_bound(rrv__field_of(m, RRV__TEMPERATURE), lo, hi);
        T = rrv__maxd(T, (f - m->temperatureoffset) * m->temperaturescale);
    }
    return T;
}

/* Grid g's cell corner (i, j, k), and a cluster's or super-cluster's box. */
static rrv_vec3 rrv__emit_corner(const rrv__emitter_grid *g, int i, int j, int k)
{
    return rrv__v3(g->lo.x + i * g->cell.x, g->lo.y + j * g->cell.y, g->lo.z + k * g->cell.z);
}

static void rrv__emit_cluster_box(rrv__emit_cluster *c, rrv_vec3 lo, rrv_vec3 hi)
{
    c->centre = rrv__scale(rrv__add(lo, hi), 0.5);
    c->half = rrv__scale(rrv__sub(hi, lo), 0.5);
    c->radius2 = rrv__dot(c->half, c->half);
}

/* The clusters: blocks of RRV__EMIT_BLOCK^3 cells, each with its cells
   listed in order[] and their pmf summed in cdf[]. */
/* The weight of an emission cell a medium hides: the mean over the six
   axis directions of the transmittance from the cell's centre out of the
   grid's box (the extinction of every medium there, taken at the cells'
   centres, summed cell by cell), never below RRV__EMIT_SEEN. A sample deep
   inside a thick flame reaches no vertex outside it (its shadow ray is the
   cost of a sample and returns almost nothing), so the cells the flame
   shows its surroundings take the samples instead: on
   test/bench/campfire.rrv (optical depth ~2 across the flame) the
   variance of emission NEE at maxdepth 1 fell 1.4x (RESULTS.md, "Fire as
   a light: the cells a flame shows"). Any positive weights keep the
   estimate unbiased, since the sampler and the density read the same pmf;
   the floor bounds the loss where the mean misleads (a vertex inside the
   box, or one that sees a cell through its one thin side). sigma and seen
   are scratch of the grid's size. */
#define RRV__EMIT_SEEN 0.02
static void rrv__emit_escape(const rrv_scene *scene, const rrv__emitter_grid *g, double *pmf, double *sigma,
                             double *seen)
{
    const int n[3] = {g->n[0], g->n[1], g->n[2]};
    const size_t stride[3] = {1, (size_t)n[0], (size_t)n[0] * (size_t)n[1]};
    size_t c, cells = stride[2] * (size_t)n[2];
    int i[3], a, j, k;
    for (i[2] = 0, c = 0; i[2] < n[2]; ++i[2])
        for (i[1] = 0; i[1] < n[1]; ++i[1])
            for (i[0] = 0; i[0] < n[0]; ++i[0], ++c) {
                rrv_vec3 p = rrv__v3(g->lo.x + (i[0] + 0.5) * g->cell.x, g->lo.y + (i[1] + 0.5) * g->cell.y,
                                     g->lo.z + (i[2] + 0.5) * g->cell.z);
                double sum = 0;
                for (j = 0; j < scene->medium_count; ++j) {
                    const rrv_medium *m = &scene->media[j];
                    rrv__coeffs cf;
                    if (m->density.kind == RRV_FIELD_NONE || !rrv__inside_box(p, m->lo, m->hi)) continue;
                    rrv__medium_coeffs(m, p, &cf);
                    for (k = 0; k < 3; ++k) sum += (cf.sigma_a[k] + cf.sigma_s[k]) / 3.0;
                }
                sigma[c] = sum;
                seen[c] = 0;
            }
    /* every line of cells along each axis, walked both ways: the depth
       from a cell's centre out through the line's end is half its own
       cell's and all of those beyond it */
    for (a = 0; a < 3; ++a) {
        const int u = (a + 1) % 3, v = (a + 2) % 3;
        const double len = rrv__axis(g->cell, a);
        for (i[v] = 0; i[v] < n[v]; ++i[v])
            for (i[u] = 0; i[u] < n[u]; ++i[u]) {
                size_t first = (size_t)i[u] * stride[u] + (size_t)i[v] * stride[v];
                double down = 0, up = 0;
                for (k = 0; k < n[a]; ++k) {
                    size_t lo = first + (size_t)k * stride[a], hi = first + (size_t)(n[a] - 1 - k) * stride[a];
                    seen[lo] += exp(-(down + 0.5 * sigma[lo] * len));
                    down += sigma[lo] * len;
                    seen[hi] += exp(-(up + 0.5 * sigma[hi] * len));
                    up += sigma[hi] * len;
                }
            }
    }
    for (c = 0; c < cells; ++c) pmf[c] *= rrv__maxd(seen[c] / 6.0, RRV__EMIT_SEEN);
}

static void rrv__emit_clusters(struct rrv__emitters *e)
{
    size_t at = 0;
    int i, a;
    e->cdf[0] = 0;
    for (i = 0; i < e->count; ++i) {
        const rrv__emitter_grid *g = &e->grid[i];
        int cx, cy, cz, x, y, z;
        for (cz = 0; cz < g->nc[2]; ++cz)
            for (cy = 0; cy < g->nc[1]; ++cy)
                for (cx = 0; cx < g->nc[0]; ++cx) {
                    rrv__emit_cluster *c = &e->cluster[g->first_cluster + (cz * g->nc[1] + cy) * g->nc[0] + cx];
                    int b0[3], b1[3];
                    b0[0] = cx * RRV__EMIT_BLOCK; b0[1] = cy * RRV__EMIT_BLOCK; b0[2] = cz * RRV__EMIT_BLOCK;
                    for (a = 0; a < 3; ++a) b1[a] = b0[a] + RRV__EMIT_BLOCK < g->n[a] ? b0[a] + RRV__EMIT_BLOCK : g->n[a];
                    rrv__emit_cluster_box(c, rrv__emit_corner(g, b0[0], b0[1], b0[2]), rrv__emit_corner(g, b1[0], b1[1], b1[2]));
                    c->begin = at;
                    c->weight = 0;
                    for (z = b0[2]; z < b1[2]; ++z)
                        for (y = b0[1]; y < b1[1]; ++y)
                            for (x = b0[0]; x < b1[0]; ++x) {
                                size_t cell = g->first + ((size_t)z * (size_t)g->n[1] + (size_t)y) * (size_t)g->n[0] + (size_t)x;
                                e->order[at] = cell;
                                e->cdf[at + 1] = e->cdf[at] + e->pmf[cell];
                                c->weight += e->pmf[cell];
                                ++at;
                            }
                    c->end = at;
                }
    }
}

/* The super-clusters: blocks of RRV__EMIT_PAIR^3 clusters, each with its
   clusters of weight listed in member[]. */
static void rrv__emit_supers(struct rrv__emitters *e)
{
    size_t at = 0;
    int i, a;
    for (i = 0; i < e->count; ++i) {
        const rrv__emitter_grid *g = &e->grid[i];
        int sx, sy, sz, cx, cy, cz;
        for (sz = 0; sz < g->ns[2]; ++sz)
            for (sy = 0; sy < g->ns[1]; ++sy)
                for (sx = 0; sx < g->ns[0]; ++sx) {
                    int index = g->first_super + (sz * g->ns[1] + sy) * g->ns[0] + sx, b0[3], b1[3], e1[3];
                    rrv__emit_cluster *sc = &e->super[index];
                    b0[0] = sx * RRV__EMIT_PAIR; b0[1] = sy * RRV__EMIT_PAIR; b0[2] = sz * RRV__EMIT_PAIR;
                    for (a = 0; a < 3; ++a) {
                        b1[a] = b0[a] + RRV__EMIT_PAIR < g->nc[a] ? b0[a] + RRV__EMIT_PAIR : g->nc[a];
                        e1[a] = b1[a] * RRV__EMIT_BLOCK < g->n[a] ? b1[a] * RRV__EMIT_BLOCK : g->n[a];
                    }
                    rrv__emit_cluster_box(sc,
                                          rrv__emit_corner(g, b0[0] * RRV__EMIT_BLOCK, b0[1] * RRV__EMIT_BLOCK,
                                                           b0[2] * RRV__EMIT_BLOCK),
                                          rrv__emit_corner(g, e1[0], e1[1], e1[2]));
                    sc->begin = at;
                    sc->weight = 0;
                    for (cz = b0[2]; cz < b1[2]; ++cz)
                        for (cy = b0[1]; cy < b1[1]; ++cy)
                            for (cx = b0[0]; cx < b1[0]; ++cx) {
                                int c = g->first_cluster + (cz * g->nc[1] + cy) * g->nc[0] + cx;
                                e->super_of[c] = index;
                                if (!(e->cluster[c].weight > 0)) continue;
                                e->member[at++] = c;
                                sc->weight += e->cluster[c].weight;
                            }
                    sc->end = at;
                }
    }
}

static rrv_result rrv__build_emitters(rrv_scene *scene, rrv_error *err)
{
    struct rrv__emitters *e;
    double envelope[RRV__EMIT_TABLE], table[RRV__EMIT_TABLE][3], T_top = 0, total = 0;
    size_t cells = 0, at;
    int i, a, k;
    for (i = 0; i < scene->medium_count; ++i)
        if (rrv__medium_emits_somewhere(&scene->media[i])) break;
    if (i == scene->medium_count) return RRV_OK;
    e = (struct rrv__emitters *)RRV_MALLOC(sizeof *e);
    if (!e) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
    memset(e, 0, sizeof *e);
    scene->emitters = e;
    e->grid = (rrv__emitter_grid *)RRV_MALLOC((size_t)scene->medium_count * sizeof *e->grid);
    e->of_medium = (int *)RRV_MALLOC((size_t)scene->medium_count * sizeof *e->of_medium);
    if (!e->grid || !e->of_medium) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        rrv__emitter_grid *g = &e->grid[e->count];
        rrv_vec3 ext = rrv__sub(m->hi, m->lo);
        double longest = rrv__maxd(ext.x, rrv__maxd(ext.y, ext.z)), c[3];
        e->of_medium[i] = -1;
        if (!rrv__medium_emits_somewhere(m)) continue;
        e->of_medium[i] = e->count++;
        g->medium = i;
        for (a = 0; a < 3; ++a) {
            double side = rrv__axis(ext, a);
            g->n[a] = (int)rrv__clamp(ceil(RRV__EMIT_CELLS * side / longest - 1e-9), 1.0, (double)RRV__EMIT_CELLS);
            c[a] = side / g->n[a];
        }
        g->lo = m->lo;
        g->cell = rrv__v3(c[0], c[1], c[2]);
        g->inv_cell = rrv__v3(1.0 / c[0], 1.0 / c[1], 1.0 / c[2]);
        g->inv_volume = 1.0 / (c[0] * c[1] * c[2]);
        g->first = cells;
        cells += (size_t)g->n[0] * (size_t)g->n[1] * (size_t)g->n[2];
        g->first_cluster = e->clusters;
        for (a = 0; a < 3; ++a) g->nc[a] = (g->n[a] + RRV__EMIT_BLOCK - 1) / RRV__EMIT_BLOCK;
        e->clusters += g->nc[0] * g->nc[1] * g->nc[2];
        g->first_super = e->supers;
        for (a = 0; a < 3; ++a) g->ns[a] = (g->nc[a] + RRV__EMIT_PAIR - 1) / RRV__EMIT_PAIR;
        e->supers += g->ns[0] * g->ns[1] * g->ns[2];
        if (m->blackbody_emission) T_top = rrv__maxd(T_top, rrv__temperature_bound(m, m->lo, m->hi));
    }
    e->cells = cells;
    e->cdf = (double *)RRV_MALLOC((cells + 1) * sizeof *e->cdf);
    e->pmf = (double *)RRV_MALLOC(cells * sizeof *e->pmf);
    e->order = (size_t *)RRV_MALLOC(cells * sizeof *e->order);
    e->cluster = (rrv__emit_cluster *)RRV_MALLOC((size_t)e->clusters * sizeof *e->cluster);
    e->super = (rrv__emit_cluster *)RRV_MALLOC((size_t)e->supers * sizeof *e->super);
    e->member = (int *)RRV_MALLOC((size_t)e->clusters * sizeof *e->member);
    e->super_of = (int *)RRV_MALLOC((size_t)e->clusters * sizeof *e->super_of);
    if (!e->cdf || !e->pmf || !e->order || !e->cluster || !e->super || !e->member || !e->super_of)
        return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
    /* e->bytes stays 0 until the grid is complete and counted */
    /* the largest channel of B at any temperature up to table entry k
       (B is not monotonic in T once its peak moves into the visible) */
    for (k = 0; k < RRV__EMIT_TABLE; ++k) {
        double rgb[3];
        rrv__blackbody_rgb(T_top * k / (RRV__EMIT_TABLE - 1), rgb);
        envelope[k] = rrv__maxd(rrv__max3(rgb), k ? envelope[k - 1] : 0.0);
        for (a = 0; a < 3; ++a) table[k][a] = rgb[a];
    }
    at = 0;
    for (i = 0; i < e->count; ++i) {
        const rrv__emitter_grid *g = &e->grid[i];
        const rrv_medium *m = &scene->media[g->medium];
        const rrv_field *density = rrv__field_of(m, RRV__DENSITY);
        double sa = rrv__max3(m->sigma_a) * m->scale * m->Lescale, given = rrv__max3(m->Le);
        int x, y, z;
        for (z = 0; z < g->n[2]; ++z)
            for (y = 0; y < g->n[1]; ++y)
                for (x = 0; x < g->n[0]; ++x) {
                    rrv_vec3 lo = rrv__v3(g->lo.x + x * g->cell.x, g->lo.y + y * g->cell.y, g->lo.z + z * g->cell.z);
                    rrv_vec3 hi = rrv__add(lo, g->cell);
                    double w = rrv__field_bound(density, lo, hi) * sa, L = given;
                    if (w > 0 && m->blackbody_emission && T_top > 0) {
                        double T = rrv__temperature_bound(m, lo, hi);
                        int entry = (int)rrv__clamp(ceil(T / T_top * (RRV__EMIT_TABLE - 1)), 0.0, RRV__EMIT_TABLE - 1.0);
                        L += envelope[entry];
                    }
                    w *= L;
                    if (w > 0) {
                        double sum = 0;
                        int o;
                        for (o = 0; o < 8; ++o) {
                            rrv_vec3 p = rrv__v3(lo.x + g->cell.x * (o & 1 ? 0.75 : 0.25),
                                                 lo.y + g->cell.y * (o & 2 ? 0.75 : 0.25),
                                                 lo.z + g->cell.z * (o & 4 ? 0.75 : 0.25));
                            rrv__coeffs cf;
                            double Le[3] = {0, 0, 0};
                            if (m->blackbody_emission && T_top > 0) {
                                double f = rrv__clamp(rrv__temperature(m, p) / T_top * (RRV__EMIT_TABLE - 1), 0.0,
                                                      RRV__EMIT_TABLE - 1.0);
                                int t0 = (int)f < RRV__EMIT_TABLE - 1 ? (int)f : RRV__EMIT_TABLE - 2;
                                for (a = 0; a < 3; ++a)
                                    Le[a] = table[t0][a] + (f - t0) * (table[t0 + 1][a] - table[t0][a]);
                            }
                            rrv__medium_coeffs(m, p, &cf);
                            for (a = 0; a < 3; ++a) sum += cf.sigma_a[a] * (Le[a] + m->Le[a]) * m->Lescale;
                        }
                        w = rrv__maxd(sum / 24.0, 1e-3 * w);
                    }
                    /* the bound's own rounding must not make weight of nothing */
                    e->pmf[at++] = w > 0 && w < DBL_MAX ? w : 0.0;
                }
    }
    {
        /* scratch for the escape weights, as large as the largest grid */
        size_t most = 0;
        double *scratch;
        for (i = 0; i < e->count; ++i) {
            size_t n = (size_t)e->grid[i].n[0] * e->grid[i].n[1] * e->grid[i].n[2];
            if (n > most) most = n;
        }
        scratch = (double *)RRV_MALLOC(2 * most * sizeof *scratch);
        if (!scratch) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
        for (i = 0; i < e->count; ++i)
            rrv__emit_escape(scene, &e->grid[i], e->pmf + e->grid[i].first, scratch, scratch + most);
        RRV_FREE(scratch);
    }
    for (at = 0; at < cells; ++at) total += e->pmf[at];
    /* A unit volume radiates 4 pi sigma_a Le, a unit area of a one-sided
       light shape pi L: the weights (sigma_a Le, seen from outside) times
       the cells' volumes, times 4, are the media's power over pi. */
    e->power = 0;
    for (i = 0; i < e->count; ++i) {
        const rrv__emitter_grid *g = &e->grid[i];
        size_t n = (size_t)g->n[0] * g->n[1] * g->n[2], k;
        double sum = 0;
        for (k = 0; k < n; ++k) sum += e->pmf[g->first + k];
        e->power += 4.0 * sum / g->inv_volume;
    }
    if (!(total > 0)) {
        /* nothing can emit: the paths alone find it all */
        rrv__emitters_free(e);
        scene->emitters = NULL;
        return RRV_OK;
    }
    for (at = 0; at < cells; ++at) e->pmf[at] /= total;
    rrv__emit_clusters(e);
    rrv__emit_supers(e);
    e->bytes = sizeof *e + (size_t)scene->medium_count * (sizeof *e->grid + sizeof *e->of_medium) +
               (size_t)e->clusters * (sizeof *e->cluster + sizeof *e->member + sizeof *e->super_of) +
               (size_t)e->supers * sizeof *e->super + (cells + 1) * sizeof *e->cdf +
               cells * (sizeof *e->pmf + sizeof *e->order);
    scene->bytes += e->bytes;
    return RRV_OK;
}

/* The last real vertex, for the MIS weight of the emission the path
   collects after it (rrv__emission_forward_weight): on once that vertex
   sampled emissive media (rrv__emission_nee). */
typedef struct rrv__emit_from {
    int on, surface;
    rrv_vec3 x;              /* where the path restarted */
    rrv_vec3 n;              /* surface: facing the path's side */
    rrv_vec3 n_abs;          /* its components' magnitudes */
    rrv_vec3 d_in;           /* medium: the arriving direction */
    double g;
    double S;                /* rrv__emission_norm at x */
    uint32_t known;          /* bit s: S_s[s] holds super-cluster s's norm at x */
    double S_s[RRV__EMIT_SUPER_KEEP];
    rrv_vec3 w0;             /* the direction sampled there */
    double p_w0;             /* rrv__emission_dir_density of w0; < 0 until asked */
    int jumped;              /* the path crossed a sharp face since x */
    double pick;             /* the chance that x's light draw went to the emitters */
    int aim;                 /* a walk of rrv__emission_aim: it collects past r* alone */
} rrv__emit_from;

/* G_c(x) of the comment above (G_s of a super-cluster alike); at a surface
   vertex also a bound of the cosine toward the cluster's box, (n.d + h) / |d|
   clamped to [0, 1], h = |n| . half-extents the farthest the box reaches
   in front of the centre along n: it is 0 exactly when no point of the
   box lies in front of the surface, where alone the vertex's cosine lobe
   (and so its integrand) is nonzero. The box's, not its bounding
   sphere's: a super-cluster's sphere reaches in front where all its
   clusters lie behind, and a sample drawn there would find nothing. */
static double rrv__emit_cluster_g(const rrv__emit_cluster *c, const rrv__emit_from *from)
{
    rrv_vec3 d = rrv__sub(c->centre, from->x);
    double d2 = rrv__dot(d, d);
    if (from->surface) {
        double facing = rrv__dot(from->n, d) + rrv__dot(from->n_abs, c->half);
        if (!(facing > 0)) return 0.0;
        if (d2 <= c->radius2) return 1.0 / c->radius2;
        /* a bound of 1 needs no root */
        if (facing * facing >= d2) return 1.0 / d2;
        return facing / (d2 * sqrt(d2));
    }
    return 1.0 / rrv__maxd(d2, c->radius2);
}

/* S(x): what normalises the super-clusters' W_s G_s(x). With q, also each
   W_s G_s into it (the first RRV__EMIT_KEEP super-clusters), for the
   sampler. A new vertex forgets the norms of super-clusters. */
static double rrv__emission_norm(const struct rrv__emitters *e, rrv__emit_from *from, double *q)
{
    double S = 0;
    int s;
    from->known = 0;
    for (s = 0; s < e->supers; ++s) {
        double qs = e->super[s].weight > 0 ? e->super[s].weight * rrv__emit_cluster_g(&e->super[s], from) : 0.0;
        if (q && s < RRV__EMIT_KEEP) q[s] = qs;
        S += qs;
    }
    return S;
}

/* S_s(x): what normalises the W_c G_c(x) of super-cluster s's clusters,
   summed in one order by the sampler and the density alike, so that both
   see the same number; kept for the vertex (the first
   RRV__EMIT_SUPER_KEEP super-clusters). With q, also each W_c G_c, in
   member[]'s order (RRV__EMIT_PAIR^3 at most). */
static double rrv__emission_super_norm(const struct rrv__emitters *e, rrv__emit_from *from, int s, double *q)
{
    const rrv__emit_cluster *sc = &e->super[s];
    double S = 0;
    size_t i;
    if (!q && s < RRV__EMIT_SUPER_KEEP && (from->known >> s & 1u)) return from->S_s[s];
    for (i = sc->begin; i < sc->end; ++i) {
        const rrv__emit_cluster *c = &e->cluster[e->member[i]];
        double qc = c->weight * rrv__emit_cluster_g(c, from);
        if (q) q[i - sc->begin] = qc;
        S += qc;
    }
    if (s < RRV__EMIT_SUPER_KEEP) {
        from->S_s[s] = S;
        from->known |= 1u << s;
    }
    return S;
}

/* The probability that the sampler picks cluster c from x, times S(x):
   W_s G_s(x) G_c(x) W_c / S_s(x) of its super-cluster s, over W_c (the
   cell's pmf completes it); 0 where s has nothing in front of a surface. */
static double rrv__emission_cluster_share(const struct rrv__emitters *e, rrv__emit_from *from, int c)
{
    int s = e->super_of[c];
    double S_s = rrv__emission_super_norm(e, from, s, NULL);
    if (!(S_s > 0)) return 0.0;
    return e->super[s].weight * rrv__emit_cluster_g(&e->super[s], from) * rrv__emit_cluster_g(&e->cluster[c], from) /
           S_s;
}

/* The density, per unit volume, with which next-event estimation from x
   (S = rrv__emission_norm(e, x)) picks y in medium mi (rrv__emitter_sample),
   the chance from->pick that the vertex samples the emitters at all included;
   0 where it never does. */
static double rrv__emission_pdf(const struct rrv__emitters *e, int mi, rrv__emit_from *from, rrv_vec3 y)
{
    const rrv__emitter_grid *g;
    size_t cell;
    int idx[3], a, cluster;
    double u[3];
    if (!e || e->of_medium[mi] < 0 || !(from->S > 0)) return 0.0;
    g = &e->grid[e->of_medium[mi]];
    u[0] = (y.x - g->lo.x) * g->inv_cell.x;
    u[1] = (y.y - g->lo.y) * g->inv_cell.y;
    u[2] = (y.z - g->lo.z) * g->inv_cell.z;
    for (a = 0; a < 3; ++a) {
        if (!(u[a] >= 0.0 && u[a] <= (double)g->n[a])) return 0.0;
        idx[a] = (int)u[a];
        if (idx[a] > g->n[a] - 1) idx[a] = g->n[a] - 1;
    }
    cell = g->first + ((size_t)idx[2] * (size_t)g->n[1] + (size_t)idx[1]) * (size_t)g->n[0] + (size_t)idx[0];
    if (!(e->pmf[cell] > 0)) return 0.0;
    cluster = g->first_cluster + ((idx[2] / RRV__EMIT_BLOCK) * g->nc[1] + idx[1] / RRV__EMIT_BLOCK) * g->nc[0] +
              idx[0] / RRV__EMIT_BLOCK;
    return from->pick * rrv__emission_cluster_share(e, from, cluster) * e->pmf[cell] / from->S * g->inv_volume;
}

/* A point of an emissive medium seen from x from five uniform numbers: a
   super-cluster by W_s G_s(x) and a cluster of it by W_c G_c(x), both from
   u[0] (what is left of it past the first pick picks the second), a cell
   of the cluster by its pmf, a point uniform in the cell. q: the
   super-clusters' W_s G_s, or NULL. Returns the medium's index, or -1 if
   nothing was picked. */
static int rrv__emitter_sample(const struct rrv__emitters *e, rrv__emit_from *from, const double *q,
                               const double u[5], rrv_vec3 *y)
{
    const rrv__emitter_grid *g;
    const rrv__emit_cluster *c = NULL;
    size_t lo, hi, cell, rest;
    double target = u[0] * from->S, sum = 0, qs = 0, qc[RRV__EMIT_PAIR * RRV__EMIT_PAIR * RRV__EMIT_PAIR], S_s, v;
    int i, s = -1;
    for (i = 0; i < e->supers; ++i) {
        if (!(e->super[i].weight > 0)) continue;
        s = i;
        qs = q && i < RRV__EMIT_KEEP ? q[i] : e->super[i].weight * rrv__emit_cluster_g(&e->super[i], from);
        sum += qs;
        if (target < sum) break;
    }
    if (s < 0 || !(qs > 0)) return -1;
    S_s = rrv__emission_super_norm(e, from, s, qc);
    if (!(S_s > 0)) return -1;
    /* u[0]'s place within the super-cluster's share, in [0, 1) */
    v = (target - (sum - qs)) / qs;
    v = v > 0 ? (v < 1 ? v : 1.0 - DBL_EPSILON / 2) : 0.0;
    target = v * S_s;
    sum = 0;
    for (lo = e->super[s].begin; lo < e->super[s].end; ++lo) {
        c = &e->cluster[e->member[lo]];
        sum += qc[lo - e->super[s].begin];
        if (target < sum) break;
    }
    if (!c) return -1;
    /* the last cell of the cluster with cdf[k] <= v < cdf[k + 1] (an alias
       table saved 2 % of the time but lost the stratification of u[1]
       over the cells: 1.17x the error at maxdepth 1, RESULTS.md) */
    v = e->cdf[c->begin] + u[1] * (e->cdf[c->end] - e->cdf[c->begin]);
    lo = c->begin;
    hi = c->end;
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (e->cdf[mid] <= v) lo = mid;
        else hi = mid;
    }
    cell = e->order[lo];
    for (i = e->count - 1; i > 0 && e->grid[i].first > cell; --i) {}
    g = &e->grid[i];
    rest = cell - g->first;
    y->x = g->lo.x + ((double)(rest % (size_t)g->n[0]) + u[2]) * g->cell.x;
    rest /= (size_t)g->n[0];
    y->y = g->lo.y + ((double)(rest % (size_t)g->n[1]) + u[3]) * g->cell.y;
    rest /= (size_t)g->n[1];
    y->z = g->lo.z + ((double)rest + u[4]) * g->cell.z;
    return g->medium;
}

/* >> 7 tracking: majorant traversal, delta and ratio tracking ================ */

/* ---- majorant traversal: a DDA over one medium's majorant grid ----------------
   Like pbrt-v4's DDAMajorantIterator: the part of a ray inside a medium's
   box, cell by cell, each piece with the majorant that bounds the medium's
   extinction there, plus the refraction event rate when null events must
   also refract (the seed's Poisson scheme). Delta tracking, ratio tracking
   and the refraction events of rrv_trace_ray all walk it. */

#define RRV__MAX_MEDIA 64

typedef struct rrv__majorant_segment {
    double t0, t1;   /* the piece of the ray o + t d inside one cell */
    double majorant; /* 1/m, bounds the extinction (plus refraction rate) there */
    double density_max; /* the cell's density bound (times the density weight) */
    double density_min; /* with residual, its lower bound (else 0), which the
                           majorant then bounds the density above */
} rrv__majorant_segment;

typedef struct rrv__majorant_iterator {
    const struct rrv__majorant_grid *grid;
    int with_refraction;  /* add the refraction event rate to the majorant */
    double density_weight;/* 1, or 0 to see refraction events only (rrv trace) */
    double sigma_t_sample;/* the extinction scale of the majorant: sigma_t_max, or
                             one channel group's (rrv__walker_sample_channel) */
    double mu_eta_fixed, inv_tolerance;
    int residual;         /* majorants bound density - density_min (residual tracking) */
    double control;       /* with residual: the integral of density_min over the
                             segments handed out so far */
    double t, t_end;      /* where the next segment starts; where the ray leaves the box */
    int cell[3], step[3];
    double t_next[3], t_delta[3];
    int done;
    /* A crossing split into pieces (rrv__majorant_piece): the ray, the
       density field the pieces are bounded on, and the part left. */
    const rrv_medium *medium;
    rrv_vec3 o, d;
    int splitting;
    double piece_t, piece_end; /* the next piece starts at piece_t; the crossing ends at piece_end */
    double piece_h;            /* the last piece's length: the next one tries twice it */
    double piece_min;          /* the shortest piece (RRV__PIECE_FLOOR of the crossing) */
    double piece_cap;          /* the cell's density bound, which no piece's exceeds */
    double piece_floor;        /* with residual, the cell's minorant, which every piece's reaches */
    double piece_rate;         /* the cell's refraction event rate, every piece's too */
} rrv__majorant_iterator;

/* One axis of the iterator's box clip: the slab [lo, hi] narrows [*t0, *t1]
   (inv: the reciprocal of the direction's component; an infinite one, of
   a line parallel to the slab, gives infinite or NaN parameters that the
   comparisons pass over, as the clip always did). */
static inline void rrv__clip_axis(double o, double inv, double lo, double hi, double *t0, double *t1)
{
    double ta = (lo - o) * inv, tb = (hi - o) * inv;
    if (ta > tb) { double tmp = ta; ta = tb; tb = tmp; }
    if (ta > *t0) *t0 = ta;
    if (tb < *t1) *t1 = tb;
}

/* One axis of the iterator's set-up: the cell of o + t0 d clamped into the
   grid (clamped before the cast: a far point must not overflow the int),
   the step, the distance to the cell's next face and between faces. */
static inline void rrv__iterator_axis(double o, double d, double inv, double t0, double lo, double cs,
                                      double inv_cell, int n, int *cell, int *step, double *t_next,
                                      double *t_delta)
{
    double c = (o + t0 * d - lo) * inv_cell;
    int k = !(c >= 0) ? 0 : c >= n - 1 ? n - 1 : (int)c;
    *cell = k;
    if (d > 0) {
        *step = 1;
        *t_next = (lo + (k + 1) * cs - o) * inv;
        *t_delta = cs * inv;
    } else if (d < 0) {
        *step = -1;
        *t_next = (lo + k * cs - o) * inv;
        *t_delta = -cs * inv;
    } else {
        *step = 0;
        *t_next = DBL_MAX;
        *t_delta = DBL_MAX;
    }
}

/* Sets the iterator on the ray o + t d, t in [0, tmax). Returns 0 if the
   ray misses the box or the medium has nothing to collide with. inv_d: the
   reciprocals of d's components when the caller has them (a comb chord's
   line), else NULL. inside (only with inv_d): o lies in the box and o +
   tmax d inside it by more than rounding (a comb chord deep inside a
   support this box holds, rrv__comb_step), where the clip below gives
   [0, tmax] exactly: the box's exit along each axis exceeds tmax by that
   margin, far more than the clip's rounding, and o's entry is behind it. */
static int rrv__majorant_iterator_start(rrv__majorant_iterator *it, const rrv_medium *m, int with_refraction,
                                        const rrv_settings *s, const rrv_vec3 *o, const rrv_vec3 *d,
                                        const double *inv_d, double tmax, int inside)
{
    /* per axis, inline, straight from the vectors (by pointer: by value
       they go through the stack): walkers restart at every comb point,
       where this set-up was most of a restart's cost, and copying the
       vectors into arrays first was a third of it */
    const struct rrv__majorant_grid *g = m->majorant;
    double inv[3], t0 = 0, t1 = tmax;
    if (g->empty && !(with_refraction && g->grad_max)) return 0;
    if (inv_d) {
        inv[0] = inv_d[0];
        inv[1] = inv_d[1];
        inv[2] = inv_d[2];
    } else {
        inv[0] = 1.0 / d->x;
        inv[1] = 1.0 / d->y;
        inv[2] = 1.0 / d->z;
    }
    if (!inside) {
        rrv__clip_axis(o->x, inv[0], m->lo.x, m->hi.x, &t0, &t1);
        rrv__clip_axis(o->y, inv[1], m->lo.y, m->hi.y, &t0, &t1);
        rrv__clip_axis(o->z, inv[2], m->lo.z, m->hi.z, &t0, &t1);
    }
    if (g->density_clipped && !(with_refraction && g->grad_max)) {
        rrv__clip_axis(o->x, inv[0], g->density_lo.x, g->density_hi.x, &t0, &t1);
        rrv__clip_axis(o->y, inv[1], g->density_lo.y, g->density_hi.y, &t0, &t1);
        rrv__clip_axis(o->z, inv[2], g->density_lo.z, g->density_hi.z, &t0, &t1);
    }
    if (!(t0 < t1)) return 0;
    it->grid = g;
    it->with_refraction = with_refraction && g->grad_max != NULL;
    it->density_weight = 1.0;
    it->sigma_t_sample = g->sigma_t_max;
    it->mu_eta_fixed = s->mu_eta;
    /* a division per walk, which delta tracking's walks (one a comb chord) need not pay */
    it->inv_tolerance = it->with_refraction ? 1.0 / s->bend_tolerance : 0.0;
    it->residual = 0;
    it->control = 0;
    it->t = t0;
    it->t_end = t1;
    it->done = 0;
    it->splitting = 0;
    it->medium = m;
    it->o = *o;
    it->d = *d;
    rrv__iterator_axis(o->x, d->x, inv[0], t0, g->lo.x, g->cell.x, g->inv_cell.x, g->n[0], &it->cell[0], &it->step[0],
                       &it->t_next[0], &it->t_delta[0]);
    rrv__iterator_axis(o->y, d->y, inv[1], t0, g->lo.y, g->cell.y, g->inv_cell.y, g->n[1], &it->cell[1], &it->step[1],
                       &it->t_next[1], &it->t_delta[1]);
    rrv__iterator_axis(o->z, d->z, inv[2], t0, g->lo.z, g->cell.z, g->inv_cell.z, g->n[2], &it->cell[2], &it->step[2],
                       &it->t_next[2], &it->t_delta[2]);
    return 1;
}

/* ---- majorants that follow the density within a cell ----
   A cell's bound is constant, but the density under it need not be: a ray
   entering a 2^3 grid on the side where a ramp from 0 to 7e10 starts finds
   its real collision after ~sqrt(2 / 3.5e10) m, and every null collision
   before it was charged at the cell's bound (2.6e5 tentative collisions a
   sample on the render fuzzer's input). On a density grid, a crossing whose
   optical depth at the cell's bound exceeds RRV__SPLIT_DEPTH is walked in
   pieces instead, each bounded by the grid's exact range over the piece's
   bounding box (rrv__grid_range: a multilinear field's max and min over a
   box in a voxel sit at its corners). A piece tries twice the last one's
   length and is halved until its optical depth is at most
   RRV__PIECE_DEPTH or its range is within a factor 2 (the field nowhere
   below half the bound): so tentative collisions are at most twice the
   real ones, or 4 a piece, however steep the ramp, and a walk through a
   smooth field takes a few pieces a doubling of the density. Any bound
   keeps delta and ratio tracking exact; only null collisions change.
   The pieces depend on the ray and the medium only, never on the channel
   walked (depths at sigma_t_max): spectral MIS with channel groups weighs
   a path by every channel's majorant along it, which must be the one that
   channel's own walk would have used (pieces sized by the walk's own group
   measured biased, 0.19 against 0.22).
   Other density kinds keep the cell's bound: NanoVDB's bound is the max of
   the samples a box touches, which stops tightening at a voxel; blobs and
   constants have no steep ramps inside a cell worth the bounds.
   The threshold: every crossing of the scenes in scenes/ holds at most
   10.8 (a cell's diagonal at its bound, plume and haze), of the tests'
   media 16.4 (aside from test_budget's hostile grids, and test_render's
   constant densities of 6e10 and forced bound of 1e30, which never
   split), and of one global majorant (--majorant-cells 1, the benchmark's
   comparison) 173: at 1000 all of them walk as before, bit for bit, and a
   crossing under it costs at most ~1000 null collisions. */
#ifndef RRV__SPLIT_DEPTH
#define RRV__SPLIT_DEPTH 1000.0
#endif
#define RRV__PIECE_DEPTH 4.0
/* The shortest piece, as a fraction of its crossing: 2^-32 takes a
   crossing of depth 1.7e10 to pieces of 4 at a constant bound, and keeps
   a piece's halvings at 33 (its try starts at twice the last piece). Where
   the density is so high that a piece this short still holds more, the
   piece's collisions (at least 4 each) pay for it, under the walk's budget. */
#define RRV__PIECE_FLOOR (1.0 / 4294967296.0)
/* Sample planes a piece's box may span along an axis and still be bounded
   by its points (rrv__grid_range); a piece is far shorter than a cell. */
#define RRV__RANGE_POINTS 8

/* The range of a grid's trilinear field over the box [lo, hi]: along each
   axis the field is piecewise linear with knots at the sample planes, so
   its max and min over the box lie on the points where the box's faces cut
   the axis (a box within one voxel along it) or on the sample planes its
   span holds (a box across several: planes beyond the box too, which only
   widens the range). Unlike rrv__field_bound, a box reaching 1e-9 of a
   voxel or less into the grid or a voxel counts (a ray along an axis has a
   box of no width there), and the max carries rrv__grid_bound's margin for
   the lookups' rounding, 1e-9 of the samples' max. For 3 channels: the
   max of each channel's bounds, the range of the channel the majorant
   follows. 0 if the box misses the grid, where the density is 0. */
static void rrv__grid_range(const rrv_grid *g, rrv_vec3 lo, rrv_vec3 hi, double *low, double *high)
{
    int count[3], i0[3][RRV__RANGE_POINTS], ax, i, j, k, c, corner;
    double w[3][RRV__RANGE_POINTS], side[3][RRV__RANGE_POINTS][2], samples = 0, best = 0, least = 0;
    size_t stride[3], offset[8];
    stride[0] = (size_t)g->channels;
    stride[1] = stride[0] * (size_t)g->nx;
    stride[2] = stride[1] * (size_t)g->ny;
    *low = *high = 0;
    for (ax = 0; ax < 3; ++ax) {
        int n = (ax == 0 ? g->nx : ax == 1 ? g->ny : g->nz) - 1, a, b, e;
        double glo = rrv__axis(g->lo, ax), scale = n / (rrv__axis(g->hi, ax) - glo);
        double ulo = (rrv__axis(lo, ax) - glo) * scale, uhi = (rrv__axis(hi, ax) - glo) * scale;
        double fa = floor(ulo - 1e-9), fb = ceil(uhi + 1e-9);
        if (!(fb >= 0) || !(fa <= n)) return;
        a = fa < 0 ? 0 : (int)fa;
        b = fb > n ? n : (int)fb;
        if (b - a == 1) {
            count[ax] = 2;
            for (e = 0; e < 2; ++e) {
                i0[ax][e] = a;
                w[ax][e] = rrv__clamp((e ? uhi : ulo) - a, 0.0, 1.0);
            }
        } else if (b - a < RRV__RANGE_POINTS) {
            count[ax] = b - a + 1;
            for (e = 0; e <= b - a; ++e) {
                /* sample plane a + e, as the lower corner of its voxel (the last, the upper) */
                i0[ax][e] = a + e < n ? a + e : n - 1;
                w[ax][e] = a + e < n ? 0.0 : 1.0;
            }
        } else {
            /* spans too many voxels to list: the caller's cap (the cell's bound) stands */
            *high = DBL_MAX;
            return;
        }
        if (n == 0) { /* one sample along the axis: lookups clamp to it */
            count[ax] = 1;
            i0[ax][0] = 0;
            w[ax][0] = 0.0;
        }
    }
    /* The hottest loop of a split crossing (a piece's halvings each ask for
       a range): the weights of both sides of each axis are formed once, and
       the samples' max compares instead of calling fmax (which no sample,
       never NaN, tells apart); the products and sums are the same, in the
       same order, as a lookup's. */
    for (ax = 0; ax < 3; ++ax)
        for (i = 0; i < count[ax]; ++i) side[ax][i][0] = 1.0 - w[ax][i], side[ax][i][1] = w[ax][i];
    for (corner = 0; corner < 8; ++corner)
        offset[corner] = (corner & 1 ? stride[0] : 0) + (corner & 2 ? stride[1] : 0) + (corner & 4 ? stride[2] : 0);
    for (c = 0; c < g->channels; ++c) {
        double cmax = 0, cmin = DBL_MAX;
        for (k = 0; k < count[2]; ++k)
            for (j = 0; j < count[1]; ++j)
                for (i = 0; i < count[0]; ++i) {
                    const float *base = g->data + (size_t)i0[2][k] * stride[2] + (size_t)i0[1][j] * stride[1] +
                                        (size_t)i0[0][i] * stride[0] + (size_t)c;
                    double sum = 0;
                    for (corner = 0; corner < 8; ++corner) {
                        int ux = corner & 1, uy = (corner >> 1) & 1, uz = corner >> 2;
                        double weight = side[0][i][ux] * side[1][j][uy] * side[2][k][uz];
                        if (weight > 0) {
                            double v = base[offset[corner]];
                            sum += weight * v;
                            samples = v > samples ? v : samples;
                        }
                    }
                    cmax = fmax(cmax, sum);
                    cmin = fmin(cmin, sum);
                }
        best = fmax(best, cmax);
        least = fmax(least, cmin);
    }
    *high = best + 1e-9 * samples;
    *low = least;
}

/* The next piece of the crossing being split. */
static int rrv__majorant_piece(rrv__majorant_iterator *it, rrv__majorant_segment *seg)
{
    const rrv_grid *g = &rrv__field_of(it->medium, RRV__DENSITY)->grid;
    double t0 = it->piece_t, room = it->piece_end - t0, h = rrv__mind(2.0 * it->piece_h, room), low, high;
    int last;
    for (;;) {
        /* the ray's points o + t d as the walk computes them: rrv__madd is
           monotone in t on each axis, so they lie in the box of the ends */
        rrv_vec3 a, b;
        last = h >= room;
        a = rrv__madd(it->o, it->d, t0);
        b = rrv__madd(it->o, it->d, last ? it->piece_end : t0 + h);
        rrv__grid_range(g, rrv__vmin(a, b), rrv__vmax(a, b), &low, &high);
        high = rrv__mind(high, it->piece_cap);
        if (high * it->grid->sigma_t_max * h <= RRV__PIECE_DEPTH || low >= 0.5 * high) break;
        /* no shorter than the floor, and never so short that t stands still */
        if (0.5 * h < it->piece_min || !(t0 + 0.5 * h > t0)) break;
        h *= 0.5;
    }
    seg->t0 = t0;
    seg->t1 = last ? it->piece_end : t0 + h;
    seg->density_max = high * it->density_weight;
    if (it->residual) {
        /* the piece's own range, never below the cell's minorant nor above its bound */
        low = rrv__mind(rrv__maxd(low, it->piece_floor), high);
        seg->density_min = low * it->density_weight;
        seg->majorant = (high - low) * it->sigma_t_sample * it->density_weight + it->piece_rate;
        it->control += seg->density_min * (seg->t1 - seg->t0);
    } else {
        seg->density_min = 0;
        seg->majorant = high * it->sigma_t_sample * it->density_weight + it->piece_rate;
    }
    it->piece_t = seg->t1;
    it->piece_h = h;
    if (last) it->splitting = 0;
    return 1;
}

/* The next cell's segment; 0 once the ray has left the box. */
static int rrv__majorant_iterator_next(rrv__majorant_iterator *it, rrv__majorant_segment *seg)
{
    const struct rrv__majorant_grid *g = it->grid;
    int a = it->t_next[0] < it->t_next[1] ? (it->t_next[0] < it->t_next[2] ? 0 : 2)
                                          : (it->t_next[1] < it->t_next[2] ? 1 : 2);
    size_t c = ((size_t)it->cell[2] * (size_t)g->n[1] + (size_t)it->cell[1]) * (size_t)g->n[0] + (size_t)it->cell[0];
    double rate = 0;
    if (it->splitting) return rrv__majorant_piece(it, seg);
    if (it->done) return 0;
    seg->t0 = it->t;
    seg->t1 = rrv__mind(it->t_next[a], it->t_end);
    seg->density_max = g->density_max[c] * it->density_weight;
    if (it->residual) {
        seg->density_min = g->density_min[c] * it->density_weight;
        seg->majorant = ((double)g->density_max[c] - g->density_min[c]) * it->sigma_t_sample * it->density_weight;
    } else {
        seg->density_min = 0;
        seg->majorant = g->density_max[c] * it->sigma_t_sample * it->density_weight;
    }
    if (it->with_refraction)
        seg->majorant += rate = it->mu_eta_fixed > 0 ? it->mu_eta_fixed : g->grad_max[c] * it->inv_tolerance;
    it->t = seg->t1;
    if (seg->t1 >= it->t_end) {
        it->done = 1;
    } else {
        it->cell[a] += it->step[a];
        if (it->cell[a] < 0 || it->cell[a] >= g->n[a]) it->done = 1;
        it->t_next[a] += it->t_delta[a];
    }
    if (seg->density_max * g->sigma_t_max * (seg->t1 - seg->t0) > RRV__SPLIT_DEPTH) {
        /* grids only: their range over a piece is exact (rrv__grid_range) */
        if (rrv__field_of(it->medium, RRV__DENSITY)->kind == RRV_FIELD_GRID) {
            it->splitting = 1;
            it->piece_t = seg->t0;
            it->piece_end = seg->t1;
            it->piece_h = 0.5 * (seg->t1 - seg->t0);
            it->piece_min = RRV__PIECE_FLOOR * (seg->t1 - seg->t0);
            it->piece_cap = g->density_max[c];
            it->piece_floor = g->density_min[c];
            it->piece_rate = rate;
            return rrv__majorant_piece(it, seg);
        }
    }
    /* the pieces add their own */
    it->control += seg->density_min * (seg->t1 - seg->t0);
    return 1;
}

/* ---- tracking: tentative collisions along one medium's majorant segments ---- */

typedef struct rrv__walker {
    const rrv_medium *medium;
    rrv__majorant_iterator cells;
    rrv__majorant_segment cell;  /* the segment the walk is in */
    int in_cell;                 /* cell is valid */
    double t;                    /* the walk's position along the ray */
    double t_event, majorant;    /* pending tentative collision and its majorant */
    long budget;                 /* tentative collisions left before the walk is cut */
    int cut;                     /* the budget ran out: t_event is DBL_MAX, yet the
                                    walk did not leave the box */
    /* Channel groups (rrv__group_channels) in spectral delta tracking: a
       medium whose channels walk with different majorants reweights the
       path by each channel's majorant transmittance over the hero's, so the
       walk must know its density bound integrated up to any moment: it
       pauses at every cell face (at_face: the pending t_event is a face, not
       a collision), where the integral restarts with the next cell's bound. */
    int pauses;
    int at_face;
    double depth;                /* integral of density_max from the walk's start to t */
    double applied;              /* the part of depth the path has been reweighted for */
    double tau_left;             /* optical depth (majorant units) the drawn flight has
                                    left beyond t; 0: none drawn (rrv__walker_advance) */
} rrv__walker;

/* The walk's bound on tentative collisions (rrv__walker_start_line). */
static void rrv__walker_budget(rrv__walker *w, const rrv_settings *s)
{
    /* The count of tentative collisions on the chord is Poisson with a mean
       of at most the peak majorant times the chord, so 64 plus four times
       that mean is never reached by a correct walk (probability below
       1e-30); only a hostile scene reaches the fixed cap. */
    const struct rrv__majorant_grid *g = w->cells.grid;
    double mu = (double)g->density_peak * w->cells.sigma_t_sample, bound;
    if (w->cells.with_refraction) mu += s->mu_eta > 0 ? s->mu_eta : g->grad_peak / s->bend_tolerance;
    bound = 64.0 + 4.0 * mu * (w->cells.t_end - w->cells.t);
    w->budget = bound < (double)RRV_MAX_SEGMENT_EVENTS ? (long)bound : RRV_MAX_SEGMENT_EVENTS;
}

/* A walk along o + t d, t in [0, tmax); inv_d and inside as for the iterator. */
static int rrv__walker_start_line(rrv__walker *w, const rrv_medium *m, int with_refraction, const rrv_settings *s,
                                  const rrv_vec3 *o, const rrv_vec3 *d, const double *inv_d, double tmax,
                                  int inside)
{
    if (!rrv__majorant_iterator_start(&w->cells, m, with_refraction, s, o, d, inv_d, tmax, inside)) return 0;
    w->medium = m;
    w->in_cell = 0;
    w->t = w->cells.t;
    w->cut = 0;
    w->pauses = 0;
    w->at_face = 0;
    w->depth = w->applied = 0;
    w->tau_left = 0;
    rrv__walker_budget(w, s);
    w->t_event = DBL_MAX;
    return 1;
}

/* Before the first advance: the walk takes channel `channel`'s group's
   majorant (rrv__group_channels) instead of the largest; with `pauses`, it
   stops at cell faces too (rrv__walker). Its bound shrinks with the rate. */
static void rrv__walker_sample_channel(rrv__walker *w, const rrv_settings *s, int channel, int pauses)
{
    w->cells.sigma_t_sample = w->cells.grid->channel_scale[channel];
    w->pauses = pauses;
    rrv__walker_budget(w, s);
}

static int rrv__walker_start(rrv__walker *w, const rrv_medium *m, int with_refraction, const rrv_settings *s,
                             rrv_vec3 o, rrv_vec3 d, double tmax)
{
    return rrv__walker_start_line(w, m, with_refraction, s, &o, &d, NULL, tmax, 0);
}

static void rrv__walker_refraction_only(rrv__walker *w) { w->cells.density_weight = 0.0; }

/* Moves the walker to its next tentative collision (t_event), or sets
   t_event = DBL_MAX when it leaves the box first. The flight is drawn as
   an optical depth (an Exp(1) number of majorant units) and walked cell by
   cell, each cell spending its majorant times its length of it: inverse-CDF
   sampling of the piecewise constant rate, one random number a collision
   where drawing a new flight in every cell (as memorylessness also allows)
   took one a cell crossed. */
static void rrv__walker_advance(rrv__walker *w, rrv__rng *rng, uint64_t *events)
{
    for (;;) {
        if (!w->in_cell) {
            if (!rrv__majorant_iterator_next(&w->cells, &w->cell)) break;
            w->in_cell = 1;
        }
        if (w->cell.majorant > 0) {
            double span = w->cell.t1 > w->t ? (w->cell.t1 - w->t) * w->cell.majorant : 0.0;
            if (!(w->tau_left > 0)) w->tau_left = rrv__sample_free_flight(1.0, rng);
            if (w->tau_left >= span) {
                w->tau_left -= span;
            } else {
                double t = w->t + w->tau_left / w->cell.majorant;
                w->tau_left = 0;
                if (--w->budget < 0) {
                    w->cut = 1;
                    break;
                }
                if (w->pauses) {
                    w->depth += w->cell.density_max * (t - w->t);
                    w->at_face = 0;
                }
                w->t = t;
                w->t_event = t;
                w->majorant = w->cell.majorant;
                ++*events;
                return;
            }
        }
        if (w->pauses) {
            w->depth += w->cell.density_max * (w->cell.t1 - w->t);
            w->t = w->t_event = w->cell.t1;
            w->in_cell = 0;
            w->at_face = 1;
            return;
        }
        w->t = w->cell.t1;
        w->in_cell = 0;
    }
    w->t_event = DBL_MAX;
}

/* Where rrv_settings.step is 0 (automatic), the eikonal march places its
   steps by the field (rrv__eikonal_step_length); what else reads the step
   (the work bounds, shoot's coarse stage, the manifold chain's planes, the
   reach a march looks ahead) takes this fixed length instead. */
#define RRV__STEP_FALLBACK 0.01

static double rrv__step(const rrv_scene *scene)
{
    return scene->settings.step > 0 ? scene->settings.step : RRV__STEP_FALLBACK;
}

/* >> 8 refraction: eikonal marching, supports and faces, the comb ============ */

/* ---- eikonal: marching the ray equation d/ds(eta dx/ds) = grad eta ------------- */

/* The bending (radians) at which RK4's second difference of the gradient
   over one step marks a step that spans a feature of the IOR. At 0.05 no
   row of the convergence tables (test/measure_grin.c, steps 0.005 to 0.2)
   changes; at 0.01 Maxwell's fish-eye at h = 0.2 already halves. */
#define RRV__FEATURE_BEND 0.05

/* Eta and its gradient at p, in the variables the ray equation uses. */
static double rrv__eta_gradient(const rrv_scene *scene, rrv_vec3 p, rrv_vec3 *grad)
{
    return 1.0 + rrv__scene_refractivity(scene, p, grad);
}

/* One kick-drift-kick step of the ray equations in the optical-path
   parameter sigma (ds = eta dsigma), of length dsigma = h / eta0, with
   eta0 = eta(x), g0 = grad eta(x) and v = eta d for a ray. With h and eta0
   held fixed, as functions of (x, v), its three parts are shears by the
   gradients of potentials ((h/2) eta, a drift, (h / (4 eta0)) eta^2), so
   the step is a symplectic map of (x, v): its 6x6 tangent map has
   determinant 1 (test_grin). A ray step takes eta0 from its own start,
   which makes it an arc-length step; as a map of the start point that is
   no longer volume-preserving (the determinant is 1 - h (grad eta . d) /
   eta + O(h^2)), while the steps stay second order. */
static void rrv__leapfrog_kdk(const rrv_scene *scene, double h, double eta0, rrv_vec3 g0, rrv_vec3 x, rrv_vec3 v,
                              rrv_vec3 *x1, rrv_vec3 *v1)
{
    rrv_vec3 g1;
    double eta1;
    v = rrv__madd(v, g0, 0.5 * h);
    *x1 = rrv__madd(x, v, h / eta0);
    eta1 = rrv__eta_gradient(scene, *x1, &g1);
    *v1 = rrv__madd(v, g1, 0.5 * h * eta1 / eta0);
}

/* One step of arc length h from x along unit direction d, with v = eta d.
   RK4 integrates (x, v) with four gradients a step, leapfrog with two.
   Returns whether RK4's gradients disagree the way they do when the step
   spans a feature of the IOR (see rrv__eikonal_step_controlled). */
static int rrv__eikonal_step(const rrv_scene *scene, rrv_stepper stepper, double h, rrv_vec3 x, rrv_vec3 d,
                             rrv_vec3 *x_out, rrv_vec3 *d_out)
{
    double spread;
    rrv_vec3 g;
    double eta = rrv__eta_gradient(scene, x, &g);
    rrv_vec3 v = rrv__scale(d, eta);
    if (stepper != RRV_STEPPER_LEAPFROG) {
        rrv_vec3 k1x, k1v, k2x, k2v, k3x, k3v, k4x, k4v, xs, vs;
        double e;
        k1x = rrv__scale(v, 1.0 / eta); k1v = g;
        xs = rrv__madd(x, k1x, 0.5 * h); vs = rrv__madd(v, k1v, 0.5 * h);
        e = rrv__eta_gradient(scene, xs, &k2v); k2x = rrv__scale(vs, 1.0 / e);
        xs = rrv__madd(x, k2x, 0.5 * h); vs = rrv__madd(v, k2v, 0.5 * h);
        e = rrv__eta_gradient(scene, xs, &k3v); k3x = rrv__scale(vs, 1.0 / e);
        xs = rrv__madd(x, k3x, h); vs = rrv__madd(v, k3v, h);
        e = rrv__eta_gradient(scene, xs, &k4v); k4x = rrv__scale(vs, 1.0 / e);
        *x_out = rrv__madd(x, rrv__add(rrv__add(k1x, k4x), rrv__scale(rrv__add(k2x, k3x), 2.0)), h / 6.0);
        v = rrv__madd(v, rrv__add(rrv__add(k1v, k4v), rrv__scale(rrv__add(k2v, k3v), 2.0)), h / 6.0);
        /* the second difference k1 - k2 - k3 + k4 vanishes for a gradient
           linear along the step and is O(h^2) for a smooth one */
        spread = rrv__length(rrv__sub(rrv__add(k1v, k4v), rrv__add(k2v, k3v)));
    } else {
        /* Kick-drift-kick in the optical-path parameter sigma (ds = eta
           dsigma): there the ray equation is dx/dsigma = v, dv/dsigma = eta
           grad eta, a separable Hamiltonian, so leapfrog is symplectic and
           second order. Written with the arc-length step h (dsigma = h/eta),
           it is the arc-length form of Pediredla et al. except that the
           closing half kick carries eta(x1)/eta(x0); without that factor the
           scheme measured first order in strong GRIN. */
        rrv__leapfrog_kdk(scene, h, eta, g, x, v, x_out, &v);
        /* Two gradients give only a first difference, which is O(h) in any
           curved field and would halve steps the tables measure: leapfrog
           has no step control, only the work bound. */
        spread = 0;
    }
    *d_out = rrv__normalize(v);
    return h * spread > RRV__FEATURE_BEND * eta;
}

/* ---- refraction supports, their faces, and sharp interfaces ------------------
   Where a medium refracts: inside its box, and for a Luneburg or fish-eye
   profile only inside its sphere (outside it, in the box, the IOR is
   constant). Inside a support the IOR is smooth and bends rays by its
   gradient; across a face (of the box or the sphere) the gradient jumps and
   the IOR itself may jump, from the ambient IOR or another medium's to this
   one's. Every integrator ends its segments on faces: a step or comb chord
   straddling a jump of the gradient makes an error of the order of the step,
   and a jump of the IOR is a sharp interface (rrv__cross_face). */

static int rrv__has_sphere_support(const rrv_medium *m)
{
    return !m->ior_from_gas && (m->ior.kind == RRV_FIELD_LUNEBURG || m->ior.kind == RRV_FIELD_FISHEYE);
}

/* The interval of the line inside a profile's sphere, and its normals there. */
static int rrv__sphere_interval(const rrv_field *f, rrv_vec3 o, rrv_vec3 d, double *t0, double *t1, rrv_vec3 *n0,
                                rrv_vec3 *n1)
{
    rrv_vec3 oc = rrv__sub(o, f->center);
    double b = rrv__dot(oc, d);
    rrv_vec3 perp = rrv__madd(oc, d, -b);
    double disc = f->radius * f->radius - rrv__dot(perp, perp), sq;
    if (disc <= 0) return 0;
    sq = sqrt(disc);
    *t0 = -b - sq;
    *t1 = -b + sq;
    *n0 = rrv__madd(oc, d, *t0);
    *n1 = rrv__madd(oc, d, *t1);
    return 1;
}

/* Eikonal steps stop this far short of a face, so that a step's closing
   gradient is taken inside the support; the rest is a straight segment. */
#define RRV__EDGE_NUDGE 1e-9

/* Eikonal: cross majorant cells without a gradient straight (below,
   rrv__skip_grid); 0 in a measurement build marches them at the step. */
#ifndef RRV__EIKONAL_SKIP
#define RRV__EIKONAL_SKIP 1
#endif

/* The longest comb chord, in majorant cells (rrv__rate_distance); a
   measurement build may set another. */
#ifndef RRV__COMB_MAX_CELLS
#define RRV__COMB_MAX_CELLS 1
#endif

/* After crossing a face the ray is moved this far past it, so that which
   side it is on never rests on rounding (a ray left exactly on a face once
   found a 1e-16 remainder ahead, stepped by it and never moved again). */
static double rrv__face_gap(rrv_vec3 x)
{
    /* the largest |component| by comparisons: fmax is a library call */
    double big = fabs(x.x) > fabs(x.y) ? fabs(x.x) : fabs(x.y);
    if (fabs(x.z) > big) big = fabs(x.z);
    return RRV__EDGE_NUDGE * (1.0 + big);
}

/* What a ray from o along d sees of the refraction supports. */
typedef struct rrv__support_view {
    int inside;       /* o is inside a support */
    int surface_free; /* one support holding o has no surface reaching into it */
    double t_face;    /* distance to the next face crossed, entering or leaving; DBL_MAX: none */
    rrv_vec3 normal;  /* that face's normal (either orientation, not unit) */
    int face_unknown; /* not looked up (rrv__comb_step): t_face and normal are unset,
                         o lies inside the bender's sole support */
} rrv__support_view;

/* Offers the face crossed at parameter t to the view if it is the nearest ahead. */
static void rrv__view_face(rrv__support_view *v, double t, rrv_vec3 normal)
{
    if (t > 0 && t < v->t_face) { v->t_face = t; v->normal = normal; }
}

/* The reciprocals of a direction's components, which every cell walk along
   a line needs: a comb chord computes them once for its delta tracking's
   walkers and the next kick's spacing walk (a set each before). */
static void rrv__reciprocals(rrv_vec3 d, double inv[3])
{
    inv[0] = 1.0 / d.x;
    inv[1] = 1.0 / d.y;
    inv[2] = 1.0 / d.z;
}

/* One axis of rrv__look_along's box clip: the parameters where the line
   meets the box's two planes narrow [*t0, *t1], each remembering its axis;
   a line parallel to the planes misses unless it runs between them. It
   divides rather than multiplying by the chord's reciprocals, which would
   move faces by an ulp and every eikonal path with them (a statistical
   test of nee shoot that sits near its bound then failed). Inline, a call
   per axis: the look runs at every segment a bent ray plans, and the
   arrays it was written with were a third of its instructions. */
static inline void rrv__look_axis(double o, double d, double lo, double hi, int a, double *t0, double *t1,
                                  int *axis0, int *axis1, int *missed)
{
    if (d == 0) {
        *missed |= o < lo || o > hi;
    } else {
        double ta = (lo - o) / d, tb = (hi - o) / d;
        if (ta > tb) { double tmp = ta; ta = tb; tb = tmp; }
        if (ta > *t0) { *t0 = ta; *axis0 = a; }
        if (tb < *t1) { *t1 = tb; *axis1 = a; }
    }
}

/* What a ray from o along d sees of the supports. */
static void rrv__look_along(const rrv_scene *scene, rrv_vec3 o, rrv_vec3 d, rrv__support_view *v)
{
    int i;
    v->inside = v->surface_free = v->face_unknown = 0;
    v->t_face = DBL_MAX;
    v->normal = rrv__v3(0, 0, 1);
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double t0 = -DBL_MAX, t1 = DBL_MAX, s0, s1;
        rrv_vec3 n0, n1, sn0, sn1;
        int inside, axis0 = 0, axis1 = 0, missed = 0;
        if (!rrv__medium_refracts(m)) continue;
        /* A box behind the ray on one axis (o past a side, d not turning
           back to it) is missed, as the clip below would find, without its
           divisions: every ray that has just left a box looks from there. */
        if ((o.x > m->hi.x && d.x >= 0) || (o.x < m->lo.x && d.x <= 0) || (o.y > m->hi.y && d.y >= 0) ||
            (o.y < m->lo.y && d.y <= 0) || (o.z > m->hi.z && d.z >= 0) || (o.z < m->lo.z && d.z <= 0))
            continue;
        rrv__look_axis(o.x, d.x, m->lo.x, m->hi.x, 0, &t0, &t1, &axis0, &axis1, &missed);
        rrv__look_axis(o.y, d.y, m->lo.y, m->hi.y, 1, &t0, &t1, &axis0, &axis1, &missed);
        rrv__look_axis(o.z, d.z, m->lo.z, m->hi.z, 2, &t0, &t1, &axis0, &axis1, &missed);
        if (missed || !(t0 < t1) || !(t1 > 0)) continue;
        n0 = rrv__v3(axis0 == 0, axis0 == 1, axis0 == 2);
        n1 = rrv__v3(axis1 == 0, axis1 == 1, axis1 == 2);
        rrv__view_face(v, t0, n0);
        rrv__view_face(v, t1, n1);
        inside = t0 <= 0;
        if (rrv__has_sphere_support(m)) {
            inside = 0;
            if (rrv__sphere_interval(&m->ior, o, d, &s0, &s1, &sn0, &sn1) && s0 < t1 && s1 > t0) {
                if (s0 > t0) rrv__view_face(v, s0, sn0);
                if (s1 < t1) rrv__view_face(v, s1, sn1);
                inside = t0 <= 0 && s0 <= 0 && s1 > 0;
            }
        }
        if (inside) {
            v->inside = 1;
            if (m->majorant->surface_free) v->surface_free = 1;
        }
    }
}

/* How near to o any face of a support can be: a lower bound on the distance
   for every direction at once, and what rrv__look_along then finds for
   every direction alike (inside, surface_free), so that an eikonal step
   deep inside a support can skip its looks (rrv__safe_reach). Inside a box
   the bound is the distance to its nearest plane, outside it the largest
   gap on one axis (the Euclidean distance is at least that); a sphere's
   faces lie in its box, so they count only from inside the box, as
   | |o - c| - R |. Every face a look offers lies on one of these surfaces,
   and along a unit direction it is at least this far (the look divides
   gaps by components of size at most 1). The allowance taken off covers
   the look's rounding with room to spare: its gaps and divisions round by
   ulps of the coordinates; its sphere's square root, where the line grazes
   the sphere, by up to sqrt(ulp) R, but there the distance along the line
   exceeds | |o - c| - R | by far more. With the bound positive, no face
   lies between o and that margin, so the look's sign tests of inside go
   the way these comparisons go. Returns the bound, <= 0 when o is within
   the allowance of a face. */
static double rrv__support_safety(const rrv_scene *scene, rrv_vec3 o, int *inside, int *surface_free)
{
    const double os[3] = {o.x, o.y, o.z};
    double safe = DBL_MAX, big = rrv__maxd(fabs(o.x), rrv__maxd(fabs(o.y), fabs(o.z)));
    int i;
    *inside = *surface_free = 0;
    /* the comparisons below would pass over a NaN: a ray gone wrong is
       left to the looks, whatever they make of it */
    if (!(fabs(o.x) + fabs(o.y) + fabs(o.z) < DBL_MAX)) return 0;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        const double lo_box[3] = {m->lo.x, m->lo.y, m->lo.z}, hi_box[3] = {m->hi.x, m->hi.y, m->hi.z};
        double gap = -DBL_MAX, dist;
        int a, in_medium;
        if (!rrv__medium_refracts(m)) continue;
        /* gap: the largest signed distance outside one axis's slab,
           negative inside the box (then minus the nearest plane's distance) */
        for (a = 0; a < 3; ++a) {
            gap = rrv__maxd(gap, rrv__maxd(lo_box[a] - os[a], os[a] - hi_box[a]));
            big = rrv__maxd(big, rrv__maxd(fabs(lo_box[a]), fabs(hi_box[a])));
        }
        in_medium = gap < 0;
        dist = fabs(gap);
        if (rrv__has_sphere_support(m)) {
            const rrv_field *f = &m->ior;
            double sphere = rrv__length(rrv__sub(o, f->center)) - f->radius;
            big = rrv__maxd(big, f->radius + rrv__maxd(fabs(f->center.x),
                                                        rrv__maxd(fabs(f->center.y), fabs(f->center.z))));
            if (in_medium) {
                dist = rrv__mind(dist, fabs(sphere));
                in_medium = sphere < 0;
            }
        }
        safe = rrv__mind(safe, dist);
        if (in_medium) {
            *inside = 1;
            if (m->majorant->surface_free) *surface_free = 1;
        }
    }
    return safe - 1e-9 * (1.0 + big);
}

/* Fresnel reflectance of unpolarised light at a smooth dielectric interface,
   from the cosines of incidence and transmission. */
static double rrv__fresnel(double eta_i, double eta_t, double cos_i, double cos_t)
{
    double rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    double rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

/* An RK4 step of at most h, halved (up to 12 times) while it spans a
   feature of the IOR. A fixed step longer than a feature (a shock shell's
   3 cm edge at step 0.1) samples the gradient on both sides of it and
   kicks by the wrong amount; rays then drift into orbits no physical ray
   from outside can follow (a spherical field conserves n r sin(theta)) and
   circle until the work bound cuts them. In smooth fields the second
   difference is O(h^2) of the gradient and the steps stay as asked.
   Halving removes most such orbits, not all (measured with rrv_trace_ray,
   16 rays a pixel of a 40x30 view: a shell of amplitude 0.3 with 3 cm
   edges at step 0.1 traps 64 of 19200 camera rays at a fixed step, 16 with
   the control, none at a fixed step of 0.05): the rest are cut and
   counted. Returns the step taken. */
static double rrv__eikonal_step_controlled(const rrv_scene *scene, rrv_stepper stepper, double h, rrv_vec3 x,
                                           rrv_vec3 d, rrv_vec3 *x_out, rrv_vec3 *d_out)
{
    int halvings = 0;
    while (rrv__eikonal_step(scene, stepper, h, x, d, x_out, d_out) && halvings < 12 &&
           h > 4 * RRV__EDGE_NUDGE) {
        h *= 0.5;
        ++halvings;
    }
    return h;
}

/* ---- refraction along a walk: the seed's Poisson events, chord midpoints, comb --
   All three schemes approximate the ray equation d/ds(eta dx/ds) = grad eta
   by kicks of the direction; they differ in where the kicks happen and what
   a kick is. POISSON (the seed paper) and MIDPOINT apply Snell's law at null
   events; the COMB kicks at regularly spaced points with the leapfrog kick.
   Measured in README: the comb is second order, the others first.
   A walk is a sequence of straight segments, each ending in one event: a
   comb point, the end of an eikonal chord, or a support face. Delta
   tracking, surfaces and lights see only straight segments, and both the
   path tracer and rrv_trace_ray walk them with the same two calls:
   rrv__plan_segment and rrv__finish_segment. */

enum { RRV__END_NONE, RRV__END_FACE, RRV__END_KICK, RRV__END_STEP };

typedef struct rrv__bender {
    rrv_refraction_scheme scheme;
    int eikonal;       /* march the ray equation instead of a scheme */
    double r;          /* refractivity carried: of the last event (Poisson,
                          midpoint) or of the current chord's midpoint (comb) */
    rrv_vec3 last;     /* the previous event (midpoint scheme) */
    int pending;       /* a segment from the current point is planned */
    int end;           /* what ends it: RRV__END_* */
    double segment;    /* its length; DBL_MAX: the ray leaves every support */
    rrv_vec3 normal;   /* END_FACE: the face's normal */
    rrv_vec3 next_d;   /* END_STEP: the direction after the eikonal chord */
    double h;          /* END_STEP: the arc length the step integrated */
    int surface_free;  /* the segment lies where no surface reaches */
    int reflected;     /* the last face crossed reflected the ray */
    double run;        /* length of the segments ended by a kick or a step since the
                          last real vertex or reflection at a face: the ray's way
                          through the supports, which the trap bound holds
                          (rrv__trap_length) */
    int combing;       /* comb: a comb is running (its first half kick is done) */
    double chord;      /* comb: length of the chord behind the next point */
    int entering;      /* comb: the spacing to the next point ends where cells with a
                          gradient begin (1) or end (-1), else 0 */
    int behind_split;  /* comb: the chord behind the next point ran on through
                          stretches without a gradient (rrv__comb_step), so r is
                          not its midpoint's refractivity: the next kick takes
                          that from its own lookup */
    rrv__support_view ahead; /* END_KICK: the supports seen from the segment's end
                                along its direction (the same line as the segment's) */
    rrv_vec3 line_d;   /* the planned segment's direction (set with pending) */
    double line_inv[3];/* the reciprocals of its components */
    const rrv_medium *sole_support; /* the scene's one refraction support when it
                                       is a box (no sphere, no second refractive
                                       medium), else NULL: see rrv__comb_step */
    int face_known;    /* the last face crossed into a support looked up the
                          refractivity r and its gradient face_grad just past
                          it, at face_at: the comb's first half kick there */
    rrv_vec3 face_at, face_grad;
    double face_jump;  /* the last face crossed: |r past - r behind| */
    int refract_only;  /* a sharp face refracts the ray, never reflects it by chance
                          (total reflection still reflects): nee shoot's shots,
                          which carry the transmitted share (1 - F) as a weight */
    int skip_flat;     /* eikonal: cross cells without a gradient straight
                          (RRV__EIKONAL_SKIP; a test turns it off to compare) */
    int cell_face;     /* eikonal: the planned segment's face is one between
                          majorant cells with and without a gradient
                          (rrv__eikonal_view), where the IOR is continuous */
    int support_in_extinction; /* the sole support's box lies in the box of a
                                  medium with extinction: every chord in it
                                  meets extinction (rrv__chord_meets_extinction) */
    uint64_t holds_support;    /* bit i: media[i]'s box holds the sole support's */
    double inv_tolerance;      /* 1 / bend_tolerance, for the comb's spacings
                                  (a division a kick before) */
    int chord_inside;  /* the planned segment is a comb chord with both ends
                          inside the sole support (its end by more than
                          rounding): walkers of a medium whose box holds the
                          support need not clip it (rrv__majorant_iterator_start) */
    rrv_vec3 safe_at;  /* eikonal: from every point within sqrt(safe_inner2) of safe_at */
    double safe_inner2;/* no face lies within safe_reach and the point is inside a
                          support (rrv__safe_reach); <= 0: no such ball */
    double safe_reach;
    int safe_surface_free; /* a support holding the ball has no surface reaching into it */
} rrv__bender;

static rrv_refraction_scheme rrv__resolve_scheme(rrv_refraction_scheme s)
{
    return s == RRV_REFRACTION_DEFAULT ? RRV_REFRACTION_COMB : s;
}

/* A real vertex (the camera, scattering, a surface) starts a new straight ray. */
static void rrv__bender_restart(rrv__bender *b, const rrv_scene *scene, rrv_vec3 x)
{
    b->r = rrv__scene_refractivity(scene, x, NULL);
    b->last = x;
    b->pending = 0;
    b->combing = 0;
    b->reflected = 0;
    b->run = 0;
    b->face_known = 0;
    b->face_jump = 0;
    b->behind_split = 0;
    b->cell_face = 0;
}

/* The scene's one refraction support when it has exactly one and that is
   a box (not a sphere support), else NULL. */
static const rrv_medium *rrv__sole_support(const rrv_scene *scene)
{
    const rrv_medium *sole = NULL;
    int i, supports = 0;
    for (i = 0; i < scene->medium_count; ++i)
        if (rrv__medium_refracts(&scene->media[i])) {
            ++supports;
            sole = &scene->media[i];
        }
    return supports == 1 && !rrv__has_sphere_support(sole) ? sole : NULL;
}

static void rrv__bender_start(rrv__bender *b, const rrv_scene *scene, int eikonal, rrv_vec3 o)
{
    int i;
    b->scheme = rrv__resolve_scheme(scene->settings.refraction);
    b->eikonal = eikonal;
    b->chord = 0;
    b->sole_support = rrv__sole_support(scene);
    b->support_in_extinction = 0;
    b->holds_support = 0;
    b->inv_tolerance = 1.0 / scene->settings.bend_tolerance;
    b->skip_flat = RRV__EIKONAL_SKIP;
    b->refract_only = 0;
    b->chord_inside = 0;
    b->safe_at = o;
    b->safe_inner2 = 0;
    /* past the step by a sixteenth: RK4's stage slopes v / eta are not
       unit, so nothing bounds its chord by the step (in a smooth field it
       falls short of it but for terms of fifth order; test_grin saw none
       longer), and a chord beyond reach is looked along after all */
    b->safe_reach = rrv__step(scene) * (1.0 + 1.0 / 16) + 2 * RRV__EDGE_NUDGE;
    b->safe_surface_free = 0;
    for (i = 0; b->sole_support && i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i], *s = b->sole_support;
        if (m->lo.x <= s->lo.x && m->lo.y <= s->lo.y && m->lo.z <= s->lo.z && s->hi.x <= m->hi.x &&
            s->hi.y <= m->hi.y && s->hi.z <= m->hi.z) {
            b->holds_support |= (uint64_t)1 << i;
            if (!m->majorant->empty) b->support_in_extinction = 1;
        }
    }
    rrv__bender_restart(b, scene, o);
}

/* A lower bound on the t_face of every look from o along a unit direction
   (the bender's safe_reach) when o lies in the bender's safety ball, or in
   a fresh one at o, which then replaces it; else 0, also where o is
   outside every support: a ray there runs straight to the face, whose
   distance only the look gives. An eikonal step skips a look whose outcome
   the bound already decides, and its result is the same bit for bit,
   because each use compares t_face with a threshold and t_face >= bound
   makes that comparison go as it does for the bound: planning asks for
   min(step, t_face - nudge), which is step when bound - nudge >= step
   (rounding is monotonic); the chord is cut when its look finds a face
   within len + nudge, which none is when bound >= len + nudge. The chord
   is tested as taken, not bounded in advance. The ball's test compares
   squares (no square root a step); their rounding is far inside the
   allowance rrv__support_safety took off. */
static double rrv__safe_reach_fresh(rrv__bender *b, const rrv_scene *scene, rrv_vec3 o)
{
    int inside, surface_free;
    double inner = rrv__support_safety(scene, o, &inside, &surface_free) - b->safe_reach;
    if (!inside || !(inner > 0)) return 0;
    b->safe_at = o;
    b->safe_inner2 = inner * inner;
    b->safe_surface_free = surface_free;
    return b->safe_reach;
}

static inline double rrv__safe_reach(rrv__bender *b, const rrv_scene *scene, rrv_vec3 o)
{
    rrv_vec3 off = rrv__sub(o, b->safe_at);
    return rrv__dot(off, off) < b->safe_inner2 ? b->safe_reach : rrv__safe_reach_fresh(b, scene, o);
}

/* Does the bound let a step from o skip planning's look? */
static int rrv__safe_for_step(double step, double reach)
{
    return reach - RRV__EDGE_NUDGE >= step;
}

/* The view every look from o would give within reach: inside, no face
   nearer than reach (its normal unused: the step ends the segment). */
static void rrv__safe_view(const rrv__bender *b, double reach, rrv__support_view *v)
{
    v->inside = 1;
    v->surface_free = b->safe_surface_free;
    v->face_unknown = 0;
    v->t_face = reach;
    v->normal = rrv__v3(0, 0, 1);
}

/* Snell at a null event at x (Poisson and midpoint schemes). */
static rrv_vec3 rrv__bend_at_null_event(rrv__bender *b, const rrv_scene *scene, rrv_vec3 x, rrv_vec3 d)
{
    rrv_vec3 grad, nd;
    int reflected;
    double r = rrv__scene_refractivity(scene, x, &grad);
    if (b->scheme == RRV_REFRACTION_MIDPOINT)
        rrv__scene_refractivity(scene, rrv__scale(rrv__add(b->last, x), 0.5), &grad);
    nd = rrv__refract_at_null_event(d, b->r, r, grad, &reflected);
    b->r = r;
    b->last = x;
    b->pending = 0;
    return nd;
}

/* Do refractivities just behind and past a face differ by more than the
   rounding of a float grid of them? A baked refraction grid holds floats,
   so a field that ends exactly at the ambient value reads up to half a
   float's ulp (2^-24 of |r|) off it past the face: fire's haze box reads
   2.15e-9 off the ambient 0.146, a "jump" that refracted by ~1e-9 rad,
   drew a Fresnel number at every crossing (3.6 % of that render's CPU
   time) and reflected rays entering within 6e-5 of grazing. A jump the
   data holds (a grid that ends off the ambient) is many ulps. */
static int rrv__is_jump(double r_before, double r_after)
{
    double big = fabs(r_before) > fabs(r_after) ? fabs(r_before) : fabs(r_after);
    return !(fabs(r_after - r_before) <= FLT_EPSILON * big);
}

/* A sharp interface at a support face x: the IOR just behind and just past
   the face differ (a medium box whose field does not end at the ambient
   IOR, a fish-eye's rim). Real temperature grids rarely end exactly at the
   ambient value, so a jump is what the data says, and it is refracted once
   by Snell's law with the face normal, as a smooth dielectric surface: the
   ray reflects with the Fresnel probability (always, past the critical
   angle) and refracts otherwise, so the estimate stays unbiased with weight
   1. Refracting the jump with the interior gradient as the normal, as
   Poisson events once did, never converged (0.27 m off on a slab grid at
   any event rate). Moves x just past the face on the side the ray leaves to;
   known_before is the refractivity just behind the face (the comb's last
   half kick looked it up), or NULL to look it up here. */
static rrv_vec3 rrv__cross_face(rrv__bender *b, const rrv_scene *scene, rrv_vec3 *x, rrv_vec3 d, rrv_vec3 normal,
                                const double *known_before, rrv__rng *rng)
{
    double gap = rrv__face_gap(*x);
    rrv_vec3 after_at = rrv__madd(*x, d, gap), grad_after;
    double r_after = rrv__scene_refractivity(scene, after_at, &grad_after);
    rrv_vec3 nd = d;
    double r_before = known_before ? *known_before : rrv__scene_refractivity(scene, rrv__madd(*x, d, -gap), NULL);
    b->r = r_after;
    b->reflected = 0;
    /* the gradient came with the value: a comb starting past the face
       takes its first half kick from it (rrv__comb_step) */
    b->face_known = 1;
    b->face_at = after_at;
    b->face_grad = grad_after;
    b->face_jump = fabs(r_after - r_before);
    if (rrv__is_jump(r_before, r_after)) {
        int reflected;
        rrv_vec3 n = (normal.x == 0) + (normal.y == 0) + (normal.z == 0) == 2 ? rrv__axis_unit(normal)
                                                                               : rrv__normalize(normal);
        nd = rrv__refract_at_null_event(d, r_before, r_after, n, &reflected);
        if (!reflected && !b->refract_only) {
            double cos_i = fabs(rrv__dot(n, d)), cos_t = fabs(rrv__dot(n, nd));
            if (rrv__uniform_walk(rng) < rrv__fresnel(1.0 + r_before, 1.0 + r_after, cos_i, cos_t)) reflected = 1;
        }
        if (reflected) {
            nd = rrv__normalize(rrv__madd(d, n, -2.0 * rrv__dot(n, d)));
            b->r = r_before;
            b->reflected = 1;
            b->run = 0; /* a specular vertex, which the path's depth counts */
            b->face_known = 0;
        }
    }
    *x = rrv__madd(*x, nd, gap);
    b->last = *x;
    b->pending = 0;
    b->combing = 0;
    return nd;
}

/* The comb spacing from x (inside the grid's box) along d: the distance
   over which the kick rate, the cells' max |grad r| over the tolerance,
   integrates to tau along the ray (each cell's bound holds over the whole
   cell, so the bending a kick stands for is at most about the tolerance).
   Cells where the rate is low cost no kick: a chord runs across them until
   the rate adds up, and cells without a gradient are crossed straight (a
   ray through the empty part of a support runs to its face). A chord spans
   at most RRV__COMB_MAX_CELLS cells' length, so that one kick never stands
   for a stretch of the field longer than its cells resolve (measured in
   README: longer chords save kicks but land much further off).
   With RRV__COMB_WANDER, where the cells bound how much the Jacobian J of
   the gradient wanders (g->jacobian_wander), the cap gives way to
   h^2 W <= 4 tau tolerance, W the sum of the wander bounds of the cells the
   chord reaches: a kick stands for the half chords on both sides, and over
   one of length h/2 it misses the integral of grad r by J d h^2 / 8 (J at
   the kick; the two sides' terms cancel at equal chords) plus at most
   W h^2 / 8, so with every chord held to the rule a kick's bending error
   beyond that first-order term is at most the tolerance (over eta ~ 1, as
   the rate). It measured no fewer kicks at equal landing error (README).
   Where a kick falls hangs on the bounds, which a NanoVDB file and a gridvol of one
   grid round differently (by ~1e-7): their kicks move by as much. DBL_MAX if the ray leaves the box first. A DDA of its own,
   with the steps of the majorant iterator's; inv_d holds the reciprocals of
   d's components (the chord's, computed once for its whole line). */
/* One axis of rrv__rate_distance's cell walk set-up: the cell of x (clamped
   into the grid before the cast: a far point must not overflow the int),
   the step, the distance to the cell's next face and between faces.
   Inline, a call per axis, rather than a loop over arrays: the comb walks
   at every kick, and each axis then stays in registers (the loop was two
   thirds of the walk's cost). */
static inline void rrv__walk_axis(double x, double d, double inv, double lo, double cs, double inv_cell, int n,
                                  int *cell, int *step, double *t_next, double *t_delta)
{
    double c = (x - lo) * inv_cell;
    int k = !(c >= 0) ? 0 : c >= n - 1 ? n - 1 : (int)c;
    *cell = k;
    if (d != 0) {
        *step = d > 0 ? 1 : -1;
        *t_next = (lo + (k + (d > 0)) * cs - x) * inv;
        *t_delta = cs * (inv > 0 ? inv : -inv);
        if (*t_next < 0) *t_next = 0;
    } else {
        *step = 0;
        *t_next = *t_delta = DBL_MAX;
    }
}

static double rrv__rate_distance(const struct rrv__majorant_grid *g, const rrv_vec3 *x, const rrv_vec3 *d,
                                 const double inv_d[3], double tau, double inv_tolerance, int *entering)
{
    /* the wander bounds exist only in a RRV__COMB_WANDER build: without
       it the compiler drops their tests from the walk */
    const float *grad = g->grad_max, *wanders = RRV__COMB_WANDER ? g->jacobian_wander : NULL;
    double t_next[3], t_delta[3], t = 0, need = tau, cap, cell_min, wander = 0;
    /* h^2 wander <= 4 tau tolerance: the chord's share of a kick's error (above) */
    const double budget = wanders ? RRV__COMB_WANDER_BUDGET * tau / inv_tolerance : 0;
    const ptrdiff_t row = g->n[0], slice = (ptrdiff_t)g->n[0] * g->n[1];
    ptrdiff_t stride[3], idx;
    int cell[3], step[3], a, in_gradient;
    rrv__walk_axis(x->x, d->x, inv_d[0], g->lo.x, g->cell.x, g->inv_cell.x, g->n[0], &cell[0], &step[0],
                   &t_next[0], &t_delta[0]);
    rrv__walk_axis(x->y, d->y, inv_d[1], g->lo.y, g->cell.y, g->inv_cell.y, g->n[1], &cell[1], &step[1],
                   &t_next[1], &t_delta[1]);
    rrv__walk_axis(x->z, d->z, inv_d[2], g->lo.z, g->cell.z, g->inv_cell.z, g->n[2], &cell[2], &step[2],
                   &t_next[2], &t_delta[2]);
    idx = cell[0] + row * cell[1] + slice * cell[2];
    stride[0] = step[0] < 0 ? -1 : 1;
    stride[1] = step[1] < 0 ? -row : row;
    stride[2] = step[2] < 0 ? -slice : slice;
    in_gradient = grad[idx] > 0;
    cell_min = g->cell.x < g->cell.y ? g->cell.x : g->cell.y;
    if (g->cell.z < cell_min) cell_min = g->cell.z;
    cap = tau * RRV__COMB_MAX_CELLS * cell_min;
    if (wanders && wanders[idx] >= 0) {
        cap = DBL_MAX;
        wander = wanders[idx];
    }
    /* A kick stands for the chords on both sides of it, so a chord must not
       carry a gradient into a stretch without one: where the ray passes
       from cells with a gradient to cells without (*entering = -1), or back
       (1), the spacing ends on the face between them, where the gradient
       bound of one side is 0; there rrv__comb_step kicks nothing but runs
       the chord on (rrv__comb_run_on). */
    for (;;) {
        double t_face;
        a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
        t_face = t_next[a];
        if (in_gradient) {
            double rate = grad[idx] * inv_tolerance, span = t_face - t;
            /* the longest chord the Jacobian's wander allows, within cap */
            double limit = wander > 0 && budget < cap * cap * wander ? sqrt(budget / wander) : cap;
            if (rate * span >= need) {
                double h = t + need / rate;
                return h < limit ? h : limit;
            }
            if (t_face >= limit) return limit;
            need -= rate * span;
        }
        t = t_face;
        cell[a] += step[a];
        if (cell[a] < 0 || cell[a] >= g->n[a]) return DBL_MAX;
        idx += stride[a];
        if ((grad[idx] > 0) != in_gradient) {
            if (t > RRV__EDGE_NUDGE * (1.0 + rrv__length(*x))) {
                *entering = in_gradient ? -1 : 1;
                return t;
            }
            /* x lay on the face (within rounding): start the cell's spacing here */
            in_gradient = !in_gradient;
            wander = 0;
        }
        if (wanders && in_gradient) {
            /* the chord reaching into this cell takes on its wander; if
               even its start is too long for that, it ends on the face
               (t > 0: the chord so far kept t^2 wander <= budget). Into a
               cell without a bound, it reaches at most the cap. */
            if (wanders[idx] < 0) {
                cap = fmin(cap, t + tau * RRV__COMB_MAX_CELLS * cell_min);
            } else {
                wander += wanders[idx];
                if (t * t * wander > budget) return t;
            }
        }
        t_next[a] += t_delta[a];
    }
}

/* Comb spacing from x along d (inv_d: its reciprocals), tau spacings:
   1 / mu_eta when it is fixed, else from the majorant cells' gradient bounds
   (rrv__rate_distance). *medium is the refractive medium that holds x, the
   one whose field rrv__scene_refractivity would read there (NULL if none).
   Inline: the comb's every kick asks. */
static inline double rrv__comb_spacing(const rrv_scene *scene, const rrv__bender *b, const rrv_vec3 *x,
                                       const rrv_vec3 *d, const double inv_d[3], double tau, int *entering,
                                       const rrv_medium **medium)
{
    int i;
    *entering = 0;
    for (i = scene->medium_count - 1; i >= 0; --i) {
        /* with a sole support, the search is its box alone */
        const rrv_medium *m = b->sole_support ? b->sole_support : &scene->media[i];
        if (b->sole_support) i = 0;
        if (!rrv__medium_refracts(m) || !rrv__inside_box(*x, m->lo, m->hi)) continue;
        *medium = m;
        if (scene->settings.mu_eta > 0) return tau / scene->settings.mu_eta;
        return rrv__rate_distance(m->majorant, x, d, inv_d, tau, b->inv_tolerance, entering);
    }
    *medium = NULL;
    return fmin(rrv__step(scene), 1.0);
}

/* The kick at comb point x, standing for the length h_bar around it (half
   the chord behind, half the chord of length h ahead): the leapfrog kick of
   the ray equation, d(eta d) = grad eta h_bar, with eta taken at the midpoint
   of the chord behind (the staggered value that makes the scheme second
   order; eta at x itself measures first order). It is the limit Snell's law
   approaches for small IOR ratios, but Snell applied with the ratio between
   chord midpoints is only first order where a ray runs at a small angle c to
   the isosurfaces: its normal momentum misses the kick by ~|grad eta|^2 h^2 /
   (2 eta c) per point, and near turning points (c ~ 0) the ratio is noise
   that Snell amplifies to O(sqrt) kicks of either sign. The gradient is
   evaluated at grad_at (x, or a point just inside the support at its edge). */
/* The kick of *d with the refractivity r_here and its gradient grad at
   grad_at. Vectors by pointer and inline: a vector passed by value goes
   through the stack, and the comb kicks several times a ray. */
static inline void rrv__comb_kick_by(rrv__bender *b, const rrv_vec3 *x, rrv_vec3 *d, double h, double h_bar,
                                     const rrv_vec3 *grad_at, double r_here, const rrv_vec3 *grad)
{
    /* The refractivity at the midpoint of the chord ahead, from the value and
       gradient fetched anyway: its O(h^2) error keeps the kick second order
       (measured), and it halves the field lookups per kick. */
    double r_ahead = r_here + rrv__dot(*grad, rrv__sub(rrv__madd(*x, *d, 0.5 * h), *grad_at));
    *d = rrv__normalize(rrv__madd(rrv__scale(*d, 1.0 + b->r), *grad, h_bar));
    b->r = r_ahead;
}

/* The refractivity and its gradient at p for a kick. medium, when given, is
   the one rrv__scene_refractivity would find at p (the spacing's search
   found it), so the search is not repeated. */
static inline double rrv__kick_lookup(const rrv_scene *scene, rrv_vec3 p, const rrv_medium *medium,
                                      rrv_vec3 *grad)
{
    const struct rrv__majorant_grid *mg = medium ? medium->majorant : NULL;
    return mg && mg->refraction.data && !mg->cubic && rrv__inside_box(p, mg->refraction.lo, mg->refraction.hi)
               ? rrv__refraction_lookup(mg, p, grad)
           : medium ? rrv__refractivity_gradient(medium, p, rrv__ambient_ior(scene) - 1.0, grad)
                    : rrv__scene_refractivity(scene, p, grad);
}

static void rrv__comb_kick(rrv__bender *b, const rrv_scene *scene, const rrv_vec3 *x, rrv_vec3 *d, double h,
                           double h_bar, const rrv_vec3 *grad_at, const rrv_medium *medium)
{
    rrv_vec3 grad;
    double r_here = rrv__kick_lookup(scene, *grad_at, medium, &grad);
    rrv__comb_kick_by(b, x, d, h, h_bar, grad_at, r_here, &grad);
}

/* The comb from x along *d: the chord to the next point at spacing h,
   clipped to the next face, then the kick at x (a half kick when the comb
   starts), then the chord clipped again along the kicked direction, which
   may reach the face sooner. A spacing that ends where cells with a
   gradient begin or end runs on past that point (rrv__comb_run_on). */
/* Is p inside the box of m by more than margin on every side? */
static int rrv__deep_inside(const rrv_medium *m, rrv_vec3 p, double margin)
{
    return p.x > m->lo.x + margin && p.x < m->hi.x - margin && p.y > m->lo.y + margin && p.y < m->hi.y - margin &&
           p.z > m->lo.z + margin && p.z < m->hi.z - margin;
}

/* How far past the comb point x + d reach the chord ahead runs on, when
   the spacing to that point ended on a face between majorant cells with
   and without a gradient (edge, as b->entering). Such a point is not a
   kick: the gradient bound of the cells on one side is zero there, so its
   kick would be nothing but the lookup, the chord's ray cast and tracking
   set-up. The chord runs straight on through the cells without a gradient
   and a random fraction of a spacing into those with one beyond (as a
   comb starts, so it does not alias with pixels), and the kick there
   stands for the stretch with a gradient behind it, which starts at
   *from. DBL_MAX: the ray leaves the grid's box first. */
static double rrv__comb_run_on(rrv__bender *b, const rrv_medium *medium, rrv_vec3 x,
                               rrv_vec3 d, double reach, int edge, double *from, rrv__rng *rng)
{
    const double inv_tolerance = b->inv_tolerance;
    while (edge) {
        rrv_vec3 p = rrv__madd(x, d, reach);
        double tau = edge > 0 ? 1.0 - rrv__uniform_walk(rng) : 1.0, t;
        int next = 0;
        if (edge > 0) *from = reach;
        t = rrv__rate_distance(medium->majorant, &p, &d, b->line_inv, tau, inv_tolerance, &next);
        if (t == DBL_MAX) return DBL_MAX;
        reach += t;
        if (edge > 0) {
            /* the point past the stretch without a gradient: a kick
               (whatever the spacing from it meets next) */
            b->entering = next;
            return reach;
        }
        /* from inside cells without a gradient the spacing ends only where
           cells with one begin */
        *from = reach;
        edge = next;
    }
    b->entering = 0;
    return reach;
}

static void rrv__comb_step(rrv__bender *b, const rrv_scene *scene, rrv_vec3 x, rrv_vec3 *d, double h,
                           const rrv__support_view *view, const rrv_medium *medium, rrv__rng *rng)
{
    rrv__support_view after, looked;
    double ahead, reach, from = 0;
    if (view->face_unknown) {
        /* The chord's far end deep inside the sole support means its face
           lies beyond it (a box is convex); else the view is looked up now,
           from x along the line it was not looked along. */
        if (h < DBL_MAX && rrv__deep_inside(b->sole_support, rrv__madd(x, *d, h), RRV__EDGE_NUDGE * (1.0 + h))) {
            ahead = h;
        } else {
            rrv__look_along(scene, x, *d, &looked);
            view = &looked;
            ahead = rrv__mind(h, view->t_face);
        }
    } else {
        ahead = rrv__mind(h, view->t_face);
    }
    if (b->combing && b->behind_split) {
        /* the refractivity at the midpoint of the stretch with a gradient
           behind, from this point's value and gradient (second order, as
           r_ahead in rrv__comb_kick_by) */
        rrv_vec3 grad;
        double r_here = rrv__kick_lookup(scene, x, medium, &grad);
        b->r = r_here - 0.5 * b->chord * rrv__dot(grad, *d);
        rrv__comb_kick_by(b, &x, d, ahead, 0.5 * (b->chord + ahead), &x, r_here, &grad);
    } else if (b->combing) {
        rrv__comb_kick(b, scene, &x, d, ahead, 0.5 * (b->chord + ahead), &x, medium);
    } else if (b->face_known) {
        /* the first half kick past a face: the gradient just inside it,
           which crossing the face looked up with the refractivity */
        rrv__comb_kick_by(b, &x, d, ahead, 0.5 * ahead, &b->face_at, b->r, &b->face_grad);
        b->combing = 1;
    } else {
        /* the first half kick takes its gradient just ahead, inside */
        rrv_vec3 inside = rrv__madd(x, *d, 1e-3 * ahead);
        rrv__comb_kick(b, scene, &x, d, ahead, 0.5 * ahead, &inside, NULL);
        b->combing = 1;
    }
    /* the chord's line: its reciprocals serve the chord's delta tracking
       and the next kick's spacing */
    b->line_d = *d;
    rrv__reciprocals(*d, b->line_inv);
    reach = ahead;
    if (b->entering && ahead == h && medium && scene->settings.mu_eta <= 0)
        reach = rrv__comb_run_on(b, medium, x, *d, ahead, b->entering, &from, rng);
    b->behind_split = from > 0;
    if (b->sole_support && view->inside && reach < DBL_MAX &&
        rrv__deep_inside(b->sole_support, rrv__madd(x, *d, reach), RRV__EDGE_NUDGE * (1.0 + reach))) {
        /* Both ends of the chord inside the one box support: the chord
           crosses no face, and the look along it (a sixth of a kick's cost)
           waits until a later chord needs its face (face_unknown). x is in
           the box since the view from it is inside. */
        b->segment = reach;
        b->chord = reach - from;
        b->end = RRV__END_KICK;
        b->surface_free = b->sole_support->majorant->surface_free;
        rrv__prefetch_refraction(b->sole_support->majorant, rrv__madd(x, *d, reach));
        b->pending = 1;
        b->chord_inside = 1;
        b->ahead.inside = 1;
        b->ahead.surface_free = b->surface_free;
        b->ahead.face_unknown = 1;
        b->ahead.t_face = DBL_MAX;
        b->ahead.normal = rrv__v3(0, 0, 1);
        return;
    }
    b->chord_inside = 0;
    rrv__look_along(scene, x, *d, &after);
    /* a point within rounding of the face is the face (the view's distance
       to it may come from the previous chord's look, a few ulps off) */
    if (reach == DBL_MAX || after.t_face <= reach + RRV__EDGE_NUDGE * (1.0 + reach)) {
        b->segment = after.t_face;
        b->end = after.t_face < DBL_MAX ? RRV__END_FACE : RRV__END_NONE;
    } else {
        b->segment = reach;
        b->end = RRV__END_KICK;
    }
    b->normal = after.normal;
    b->surface_free = after.inside && after.surface_free;
    /* the stretch with a gradient behind the next point or face (none when
       the face comes within the stretch without) */
    b->chord = b->segment > from ? b->segment - from : 0;
    b->pending = 1;
    /* The kick point ahead lies on this line before its nearest face: what
       it sees along the line is this view moved up by the chord, so the
       next kick needs no second look. */
    b->ahead = after;
    if (b->ahead.t_face < DBL_MAX) b->ahead.t_face -= b->segment;
}

/* ---- eikonal: cells without a gradient crossed straight ----------------------
   A majorant cell whose bound on |grad r| is 0 holds a constant IOR, where
   the ray equation's solution is a straight line and every RK4 or leapfrog
   step of it is exactly the chord: marching it at the scene's step buys
   nothing but lookups. In a box support (the bender's sole support), the
   eikonal march therefore treats the faces between cells with and without
   a gradient as faces of the support: a run of cells without one is one
   straight segment to where cells with one begin, and steps in cells with
   a gradient are cut where those without begin, as at a support's face, so
   that no step straddles the edge and the march stays a continuous function
   of the ray (a step that began just inside a gradient cell would kick
   where one just outside it would not). The decisions are made per cell,
   so shoot's Jacobi fields cross these faces as they cross a support's
   (the face point's saltation, rrv__shoot_kept) and its Newton sees the
   same piecewise-smooth map camera rays take. RRV__EIKONAL_SKIP 0 (a
   measurement build, defined above the bender) marches every cell at the
   step. */

/* Does the eikonal march of this bender cross cells without a gradient
   straight? Only in a sole box support whose grid has such cells. */
static const struct rrv__majorant_grid *rrv__skip_grid(const rrv__bender *b)
{
    const struct rrv__majorant_grid *g;
    if (!b->skip_flat || !b->eikonal || !b->sole_support) return NULL;
    g = b->sole_support->majorant;
    return g && g->grad_max && g->near_flat ? g : NULL;
}

/* Can a segment from x no longer than limit meet a face between cells with
   and without a gradient? Not when it is no longer than a cell's shortest
   side and no neighbour of x's cell is flat: it stays among those
   neighbours. Conservative only: the walk it spares would have found no
   face. (A ball kept from one step to the next, clear of flat cells, saved
   no instructions on the haze: its rays pass mostly near flat cells.) */
static int rrv__may_meet_edge(const struct rrv__majorant_grid *g, rrv_vec3 x, double limit)
{
    const double xs[3] = {x.x, x.y, x.z}, lo[3] = {g->lo.x, g->lo.y, g->lo.z}, cs[3] = {g->cell.x, g->cell.y, g->cell.z};
    int k[3], a;
    if (!(limit <= g->cell_min)) return 1;
    for (a = 0; a < 3; ++a) {
        /* the cell as rrv__gradient_edge finds it (quotients, not products
           by the reciprocals, which may round a point on a face across it) */
        double c = (xs[a] - lo[a]) / cs[a];
        k[a] = !(c >= 0) ? 0 : c >= g->n[a] - 1 ? g->n[a] - 1 : (int)c;
    }
    return g->near_flat[k[0] + (size_t)g->n[0] * (k[1] + (size_t)g->n[1] * k[2])];
}

/* The distance from x along unit d to the first face between majorant
   cells where having a gradient changes from what x's cell has (*flat: x's
   cell has none), looked for up to limit; DBL_MAX if none comes first or
   the line leaves the grid. *normal gets that face's axis. Distances are
   quotients, as rrv__look_axis takes them, so that the march is the same
   bit for bit whoever asks. */
static double rrv__gradient_edge(const struct rrv__majorant_grid *g, rrv_vec3 x, rrv_vec3 d, double limit_with,
                                 double limit_flat, int *flat, rrv_vec3 *normal)
{
    const double xs[3] = {x.x, x.y, x.z}, ds[3] = {d.x, d.y, d.z};
    const double lo[3] = {g->lo.x, g->lo.y, g->lo.z}, cs[3] = {g->cell.x, g->cell.y, g->cell.z};
    double t_next[3];
    double limit;
    ptrdiff_t stride[3], idx = 0;
    int cell[3], step[3], a, with;
    stride[0] = 1;
    stride[1] = g->n[0];
    stride[2] = (ptrdiff_t)g->n[0] * g->n[1];
    for (a = 0; a < 3; ++a) {
        double c = (xs[a] - lo[a]) / cs[a];
        cell[a] = !(c >= 0) ? 0 : c >= g->n[a] - 1 ? g->n[a] - 1 : (int)c;
        idx += stride[a] * cell[a];
        if (ds[a] != 0) {
            step[a] = ds[a] > 0 ? 1 : -1;
            t_next[a] = (lo[a] + (cell[a] + (ds[a] > 0)) * cs[a] - xs[a]) / ds[a];
            if (t_next[a] < 0) t_next[a] = 0;
            stride[a] *= step[a];
        } else {
            step[a] = 0;
            t_next[a] = DBL_MAX;
        }
    }
    with = g->grad_max[idx] > 0;
    *flat = !with;
    limit = with ? limit_with : limit_flat;
    for (;;) {
        double t;
        a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
        t = t_next[a];
        if (!(t <= limit)) return DBL_MAX;
        cell[a] += step[a];
        if (cell[a] < 0 || cell[a] >= g->n[a]) return DBL_MAX;
        idx += stride[a];
        if ((g->grad_max[idx] > 0) != with) {
            *normal = rrv__v3(a == 0, a == 1, a == 2);
            return t;
        }
        /* the next face of this axis, from the cell's own plane (no sum
           of increments, which would drift from the quotient) */
        t_next[a] = (lo[a] + (cell[a] + (ds[a] > 0)) * cs[a] - xs[a]) / ds[a];
    }
}

/* The support view from x along unit d for the eikonal march, with the
   faces between cells with and without a gradient (rrv__skip_grid) as
   faces: from a cell without one the ray is outside every support up to
   the first cell with one (a straight segment), from a cell with one the
   nearest face may be where those without begin; that one is looked for
   only up to limit (what the caller uses of a nearer t_face: a step's
   reach), the straight run up to the view's own face. *cell_face: the
   view's face is such a face. */
static void rrv__eikonal_view(const rrv__bender *b, rrv_vec3 x, rrv_vec3 d, double limit, rrv__support_view *v,
                              int *cell_face)
{
    const struct rrv__majorant_grid *g = rrv__skip_grid(b);
    rrv_vec3 normal;
    double t;
    int flat;
    *cell_face = 0;
    if (!g || !v->inside || !rrv__inside_box(x, g->lo, g->hi) ||
        !rrv__may_meet_edge(g, x, fmin(limit, v->t_face)))
        return;
    t = rrv__gradient_edge(g, x, d, fmin(limit, v->t_face), v->t_face, &flat, &normal);
    if (flat) {
        /* the straight run goes to the first cell with a gradient, or to
           the support's face when none comes before it */
        if (t < v->t_face) {
            v->t_face = t;
            v->normal = normal;
            *cell_face = 1;
        }
        v->inside = 0;
        return;
    }
    if (t < v->t_face) {
        v->t_face = t;
        v->normal = normal;
        *cell_face = 1;
    }
}

/* Steps placed by the field (rrv_settings.step 0, the default; a given
   step is fixed, as references want). In a box support with gradient
   bounds (the scene's sole support, rrv__sole_support: the eikonal's steps,
   and the planes of nee manifold's chain), a step from x along d runs until the
   integral along its line of the majorant cells' bounds on |grad r| (how
   fast the ray can turn, per metre) reaches RRV__STEP_BEND bend
   tolerances, and at most RRV__STEP_CELLS of the cells' shortest side, so
   that a weak field's steps still sample its features at the scale its
   bounds resolve; elsewhere (sphere supports, overlapping media) the fixed
   RRV__STEP_FALLBACK. So the march takes few steps across weak heat and
   many where the bound says the ray turns fast: the rule optical-design
   codes use, kept per cell.
   The length is a continuous function of the ray: the integral of a
   piecewise constant bound along a line moves continuously with the line,
   so the march stays a continuous map for shoot's Newton. With grad it
   also returns its derivative with respect to x (grad[0..2]) and d
   (grad[3..5]): the integral I(h) = sum over the line's cells of rate_i
   times their length moves by (rate_before - rate_after) dt_f at each face
   crossed at t_f = (plane - x_a) / d_a, and by rate_end dh at the end, so
   dh = -(sum of those) / rate_end; 0 where the cap holds it. Shoot's Jacobi
   fields move the step's end along the curve by dh (rrv__shoot_plan), as
   they do where a face cuts a step. */
#define RRV__STEP_BEND 1.0
#define RRV__STEP_CELLS 1.0

static double rrv__field_step_length(const rrv_scene *scene, const rrv_medium *support, rrv_vec3 x, rrv_vec3 d,
                                     double grad[6])
{
    const struct rrv__majorant_grid *g = support->majorant;
    double budget, cap, xs[3], ds[3], lo[3], cs[3], t_next[3], t = 0, dI[6] = {0, 0, 0, 0, 0, 0};
    ptrdiff_t stride[3], idx = 0;
    int cell[3], dir[3], a, k;
    if (grad)
        for (k = 0; k < 6; ++k) grad[k] = 0;
    if (!g || !g->grad_max || !rrv__inside_box(x, g->lo, g->hi)) return RRV__STEP_FALLBACK;
    budget = RRV__STEP_BEND * scene->settings.bend_tolerance;
    cap = RRV__STEP_CELLS * g->cell_min;
    if (!(cap > RRV__STEP_FALLBACK)) return RRV__STEP_FALLBACK;
    xs[0] = x.x; xs[1] = x.y; xs[2] = x.z;
    ds[0] = d.x; ds[1] = d.y; ds[2] = d.z;
    lo[0] = g->lo.x; lo[1] = g->lo.y; lo[2] = g->lo.z;
    cs[0] = g->cell.x; cs[1] = g->cell.y; cs[2] = g->cell.z;
    stride[0] = 1;
    stride[1] = g->n[0];
    stride[2] = (ptrdiff_t)g->n[0] * g->n[1];
    for (a = 0; a < 3; ++a) {
        double c = (xs[a] - lo[a]) / cs[a];
        cell[a] = !(c >= 0) ? 0 : c >= g->n[a] - 1 ? g->n[a] - 1 : (int)c;
        idx += stride[a] * cell[a];
        if (ds[a] != 0) {
            dir[a] = ds[a] > 0 ? 1 : -1;
            t_next[a] = (lo[a] + (cell[a] + (ds[a] > 0)) * cs[a] - xs[a]) / ds[a];
            if (t_next[a] < 0) t_next[a] = 0;
            stride[a] *= dir[a];
        } else {
            dir[a] = 0;
            t_next[a] = DBL_MAX;
        }
    }
    for (;;) {
        double face, rate = g->grad_max[idx], next_rate;
        a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
        face = t_next[a];
        if (rate > 0 && rate * (face - t) >= budget) {
            double h = t + budget / rate;
            if (!(h < cap)) return cap;
            if (!(h > RRV__STEP_FALLBACK)) return RRV__STEP_FALLBACK;
            if (grad)
                for (k = 0; k < 6; ++k) grad[k] = -dI[k] / rate;
            return h;
        }
        budget -= rate * (face - t);
        if (!(face < cap)) return cap;
        t = face;
        cell[a] += dir[a];
        if (cell[a] < 0 || cell[a] >= g->n[a]) return cap;
        idx += stride[a];
        next_rate = g->grad_max[idx];
        /* dt_f / dx_a = -1 / d_a, dt_f / dd_a = -t_f / d_a */
        dI[a] -= (rate - next_rate) / ds[a];
        dI[3 + a] -= (rate - next_rate) * face / ds[a];
        t_next[a] = (lo[a] + (cell[a] + (ds[a] > 0)) * cs[a] - xs[a]) / ds[a];
    }
}

static double rrv__eikonal_step_length(const rrv__bender *b, const rrv_scene *scene, rrv_vec3 x, rrv_vec3 d,
                                       double grad[6])
{
    int k;
    if (scene->settings.step > 0 || !b->eikonal || !b->sole_support ||
        scene->settings.stepper == RRV_STEPPER_LEAPFROG) {
        if (grad)
            for (k = 0; k < 6; ++k) grad[k] = 0;
        return scene->settings.step > 0 ? scene->settings.step : RRV__STEP_FALLBACK;
    }
    return rrv__field_step_length(scene, b->sole_support, x, d, grad);
}

/* The nearest face between cells with and without a gradient from x along
   the unit chord direction c within limit (x's cell has a gradient), into
   *along where it is nearer than along's face. */
static void rrv__chord_edge(const rrv__bender *b, rrv_vec3 x, rrv_vec3 c, double limit, rrv__support_view *along)
{
    const struct rrv__majorant_grid *g = rrv__skip_grid(b);
    rrv_vec3 normal;
    int flat;
    double t;
    if (!g || !rrv__inside_box(x, g->lo, g->hi) || !rrv__may_meet_edge(g, x, limit)) return;
    t = rrv__gradient_edge(g, x, c, limit, limit, &flat, &normal);
    if (t < along->t_face) {
        along->t_face = t;
        along->normal = normal;
    }
}

/* One eikonal step of at most h from x that stops short of the next face
   (a step ending past it would take its closing kick from the other side's
   gradient); the curved step is shortened if its chord would cross a face.
   No face comes within reach of x (rrv__safe_reach). */
static void rrv__eikonal_plan(rrv__bender *b, const rrv_scene *scene, rrv_stepper stepper, double h, rrv_vec3 x,
                              rrv_vec3 *d, const rrv__support_view *view, double reach)
{
    const double nudge = RRV__EDGE_NUDGE;
    rrv_vec3 x1, chord;
    double len;
    rrv__support_view along;
    h = rrv__eikonal_step_controlled(scene, stepper, fmin(h, view->t_face - nudge), x, *d, &x1, &b->next_d);
    chord = rrv__sub(x1, x);
    len = rrv__length(chord);
    if (reach < len + nudge) rrv__look_along(scene, x, rrv__scale(chord, 1.0 / len), &along);
    else along.t_face = DBL_MAX;
    rrv__chord_edge(b, x, rrv__scale(chord, 1.0 / len), len + nudge, &along);
    if (along.t_face < len + nudge && along.t_face > 2 * nudge) {
        h = rrv__eikonal_step_controlled(scene, stepper, h * (along.t_face - nudge) / len, x, *d, &x1, &b->next_d);
        chord = rrv__sub(x1, x);
        len = rrv__length(chord);
    }
    *d = rrv__scale(chord, 1.0 / len);
    b->h = h;
    b->segment = len;
    b->end = RRV__END_STEP;
    b->surface_free = 0;
}

/* Plans the straight segment from o: it runs to the next face, comb point
   or eikonal chord end. May change *d (a comb's first half kick, an eikonal
   chord's direction). */
static void rrv__plan_segment(rrv__bender *b, const rrv_scene *scene, rrv_vec3 o, rrv_vec3 *d, rrv__rng *rng)
{
    rrv__support_view view;
    double reach = b->eikonal ? rrv__safe_reach(b, scene, o) : 0;
    double step = b->eikonal ? rrv__eikonal_step_length(b, scene, o, *d, NULL) : 0;
    b->line_d = *d;
    rrv__reciprocals(*d, b->line_inv);
    if (b->eikonal && rrv__safe_for_step(step, reach)) rrv__safe_view(b, reach, &view);
    else rrv__look_along(scene, o, *d, &view);
    if (b->eikonal) rrv__eikonal_view(b, o, *d, step + 2 * RRV__EDGE_NUDGE, &view, &b->cell_face);
    b->pending = 1;
    b->chord_inside = 0;
    b->segment = view.t_face;
    b->end = view.t_face < DBL_MAX ? RRV__END_FACE : RRV__END_NONE;
    b->normal = view.normal;
    b->surface_free = 0;
    if (!view.inside) {
        b->face_known = 0;
        return;
    }
    if (b->eikonal) {
        if (view.t_face > 2 * RRV__EDGE_NUDGE)
            rrv__eikonal_plan(b, scene, scene->settings.stepper, step, o, d, &view, reach);
    } else if (b->scheme == RRV_REFRACTION_COMB) {
        /* the first point a uniformly random fraction of a spacing ahead, so
           the comb does not alias with pixels */
        const rrv_medium *medium;
        double h = rrv__comb_spacing(scene, b, &o, d, b->line_inv, 1.0 - rrv__uniform_walk(rng), &b->entering, &medium);
        rrv__comb_step(b, scene, o, d, h, &view, medium, rng);
    }
    b->face_known = 0;
}

/* The ray has run the whole planned segment from *o: moves *o to its end
   and applies the event there. */
static void rrv__finish_segment(rrv__bender *b, const rrv_scene *scene, rrv_vec3 *o, rrv_vec3 *d, rrv__rng *rng)
{
    *o = rrv__madd(*o, *d, b->segment);
    if (b->end == RRV__END_KICK || b->end == RRV__END_STEP) b->run += b->segment;
    switch (b->end) {
    case RRV__END_STEP:
        *d = b->next_d;
        b->pending = 0;
        break;
    case RRV__END_KICK:
        /* rrv__comb_step reads the view ahead before it writes the next */
        if (b->ahead.inside) {
            /* entering cells with a gradient from a stretch without: the
               first point a random fraction of a spacing in, as at a
               segment's start, so the comb does not alias with pixels */
            double tau = b->entering > 0 ? 1.0 - rrv__uniform_walk(rng) : 1.0;
            const rrv_medium *medium;
            double h = rrv__comb_spacing(scene, b, o, d, b->line_inv, tau, &b->entering, &medium);
            rrv__comb_step(b, scene, *o, d, h, &b->ahead, medium, rng);
        } else {
            /* a kick that turned the chord out through a face it grazed:
               the comb ends here, without an interface to refract */
            b->r = rrv__scene_refractivity(scene, *o, NULL);
            b->pending = b->combing = 0;
        }
        break;
    case RRV__END_FACE:
        if (b->cell_face) {
            /* between cells with and without a gradient: the IOR is
               continuous, nothing to refract; past the face by the gap a
               support's face is crossed by */
            *o = rrv__madd(*o, *d, rrv__face_gap(*o));
            b->last = *o;
            b->pending = 0;
            b->cell_face = 0;
            b->reflected = 0;
            b->face_jump = 0;
        } else if (b->combing) {
            /* the comb's last half kick, gradient just behind the face, where
               the refractivity looked up with it is the face's r_before */
            rrv_vec3 at = rrv__madd(*o, *d, -rrv__face_gap(*o)), grad;
            double r_behind = rrv__scene_refractivity(scene, at, &grad);
            if (b->behind_split) b->r = r_behind - 0.5 * b->chord * rrv__dot(grad, *d);
            rrv__comb_kick_by(b, o, d, b->chord, 0.5 * b->chord, &at, r_behind, &grad);
            *d = rrv__cross_face(b, scene, o, *d, b->normal, &r_behind, rng);
        } else {
            *d = rrv__cross_face(b, scene, o, *d, b->normal, NULL, rng);
        }
        break;
    default:
        b->pending = 0;
        break;
    }
}

/* >> 9 path tracer: null-scattering paths, lights, curved NEE's classes, aim =
   From the integrators' paths and shadow rays, through the lights, to what
   every build keeps of curved NEE (the classes that sort connections, nee
   aim), then the camera paths. The path tracer reaches the solvers of nee
   shoot and manifold (>> 12) through one interface, declared at its head
   (THE CURVED-NEE INTERFACE). */

/* ---- integrators: classic and refractive null-scattering path tracing ---------- */

/* How far, in the light's size (the square root of its area), the bound
   on an aimed ray's turning (the chord's, rrv__chord_bend, times its
   length) may move its landing point before aiming is not worth a ray:
   beyond it the ray would mostly miss (a lens, a fire's strong haze) and
   the kicks through the strong field are the dearest part of a shadow
   ray. Efficiency only: either class is unbiased. */
#ifndef RRV__AIM_REACH
#define RRV__AIM_REACH 1.0
#endif

/* The supports toward which nee shoot and manifold draw rays of their own
   (rrv__cone_nee): those that can turn a ray by more than RRV__CONE_BEND
   radians across their diameter, at most RRV__CONE_MAX, the first listed.
   Efficiency only: the estimate is unbiased with any choice. */
#define RRV__CONE_BEND 0.05
#define RRV__CONE_MAX 8
/* The share of vertices that draw such a ray: each crosses the support,
   the dearest part of any ray there, and most find no light. */
#ifndef RRV__CONE_RATE
#define RRV__CONE_RATE 0.5
#endif

typedef struct rrv__context {
    const rrv_scene *scene;
    int refract_nulls;       /* refract at null events (Poisson, midpoint schemes) */
    int comb;                /* refract at comb points */
    int eikonal;             /* march the ray equation through refractive media */
    int bends;               /* any of the three: radiance scales with eta^2 */
    int emission;            /* NEE toward emissive media (rrv__emission_nee) */
    int sample_lights;       /* NEE on; off (nee none) every emitter found by
                                the path itself counts with MIS weight 1 */
    int partition;           /* nee shoot: straight NEE only for connections
                                outside refraction supports, curved ones by
                                shooting or (forward) by the path alone */
    int shoot;               /* nee shoot can run (eikonal, Hessians known) */
    int manifold;            /* nee manifold can run (Hessians known) */
    int aim;                 /* nee aim: bent shadow rays aimed at light
                                samples (also shoot where it cannot solve) */
    int equiangular;         /* equiangular samples (rrv__equiangular_nee): 0 none,
                                1 toward lights in scattering media' boxes, 2 all */
    double eta_floor;        /* the lowest eta anywhere (nee shoot and manifold's class) */
    int cone_count;          /* strongly refracting supports (rrv__cone_setup) */
    rrv_vec3 cone_center[RRV__CONE_MAX]; /* and the spheres that bound them */
    double cone_radius[RRV__CONE_MAX];
    double eta_camera2;      /* (1 + r at the camera)^2: radiance scales as eta^2 */
    double thermal_scale;    /* blackbody radiance at the camera over that in
                                ambient air: (eta_camera / eta_ambient)^2 */
    long step_bound;         /* rrv__step_bound: loop iterations between real vertices */
    double trap_length;      /* rrv__trap_length: a ray's run through the supports */
    uint64_t sample_bound;   /* rrv__sample_bound: loop iterations and collisions of a camera path */
    struct rrv__chain *chain; /* nee manifold's scratch (rrv__chain_new), NULL otherwise */
    struct rrv__chain *coarse_chain; /* its coarse stage's (rrv__manifold_try), NULL: none */
    rrv_render_stats stats;
} rrv__context;

/* A segment of a camera path set up for equiangular samples
   (rrv__equi_segment; the section comment above rrv__light_centre), and
   for a free flight's vertex on it, where along it the vertex lies. */
typedef struct rrv__equi {
    int on;            /* the segment meets exactly one scattering medium's box */
    int medium;        /* that medium */
    rrv_vec3 o, d;
    double a, b;       /* the span of that box on the segment */
    double t;          /* a vertex's distance along it */
} rrv__equi;

/* Spectral MIS (Miller et al. 2019): a hero channel drives every collision
   choice; ratio[k] is the pdf of the choices made so far had channel k been
   the hero, over the hero's own. A contribution is beta / mean(ratio), the
   balance heuristic over the three channels, so chromatic extinction does
   not compound weights the way channel-averaged probabilities would. */
typedef struct rrv__path {
    double beta[3], L[3];
    double ratio[3];
    int hero;
    rrv__bender bender;      /* refraction state (refractive integrator) */
    rrv__emit_from emit;
    rrv__equi eq;            /* the last vertex's segment, where it was a free flight's */
    double emit_share;       /* the emitters' share of the last vertex's light draw */
} rrv__path;

static void rrv__path_start(rrv__path *path, rrv__rng *rng)
{
    int c;
    for (c = 0; c < 3; ++c) {
        path->beta[c] = 1.0;
        path->L[c] = 0.0;
        path->ratio[c] = 1.0;
    }
    path->hero = (int)(rrv__uniform(rng) * 3.0);
    if (path->hero > 2) path->hero = 2;
    path->emit.on = 0;
    path->eq.on = 0;
    path->emit_share = 0.0;
}

/* The factor that turns beta into a contribution: 1 / mean(ratio). */
static double rrv__path_mis(const rrv__path *path)
{
    return 3.0 / (path->ratio[0] + path->ratio[1] + path->ratio[2]);
}

static void rrv__path_reweight(rrv__path *path, const double f[3])
{
    int c;
    double fh = f[path->hero];
    for (c = 0; c < 3; ++c) {
        double q = f[c] / fh;
        path->beta[c] *= q;
        path->ratio[c] *= q;
    }
}

/* inside: bit i, the chord lies inside media[i]'s box (rrv__bender's
   chord_inside). hero: the channel that samples the collisions (rrv__path);
   a medium with channel groups walks with its group's majorant and pauses
   at faces. */
static int rrv__start_walkers(const rrv__context *ctx, rrv__walker *walkers, int with_refraction,
                              const rrv_vec3 *o, const rrv_vec3 *d, const double *inv_d, uint64_t inside,
                              double tmax, int hero, rrv__rng *rng, uint64_t *events)
{
    const rrv_scene *scene = ctx->scene;
    int i, n = 0;
    for (i = 0; i < scene->medium_count; ++i) {
        rrv__walker *w = &walkers[n];
        if (rrv__walker_start_line(w, &scene->media[i], with_refraction, &scene->settings, o, d, inv_d, tmax,
                                   (int)(inside >> i & 1))) {
            if (w->cells.grid->channel_groups > 1) rrv__walker_sample_channel(w, &scene->settings, hero, 1);
            rrv__walker_advance(w, rng, events);
            if (w->t_event < DBL_MAX) ++n;
        }
    }
    return n;
}

/* Ratio tracking (Novak et al. 2014) of the transmittance along a straight
   segment, per channel, with Russian roulette once it is small. A medium
   whose channels fall into several groups (rrv__group_channels) is walked
   once per group, each walk with its group's majorant: a weight that
   stays near 1 (a thin channel's) must not pay for a dense channel's rate. */
static void rrv__ratio_tracking_transmittance(rrv__context *ctx, rrv_vec3 o, rrv_vec3 d, double tmax,
                                              rrv__rng *rng, double T[3])
{
    const rrv_scene *scene = ctx->scene;
    int i;
    T[0] = T[1] = T[2] = 1.0;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        int lead;
        if (m->density.kind == RRV_FIELD_NONE) continue;
        for (lead = 0; lead < 3; ++lead) {
            rrv__walker w;
            const double *scale = m->majorant->channel_scale;
            int member[3], ch;
            for (ch = 0; ch < 3; ++ch) member[ch] = scale[ch] == scale[lead];
            /* a group is walked from its first channel (one group: once),
               and not at all without extinction */
            if ((lead > 0 && member[0]) || (lead > 1 && member[1]) || !(scale[lead] > 0)) continue;
            if (!rrv__walker_start(&w, m, 0, &scene->settings, o, d, tmax)) break;
            if (m->majorant->channel_groups > 1) rrv__walker_sample_channel(&w, &scene->settings, lead, 0);
            for (;;) {
                rrv__coeffs c;
                double tmaxc = 0;
                rrv__walker_advance(&w, rng, &ctx->stats.events);
                if (w.t_event == DBL_MAX) {
                    if (!w.cut) break;
                    /* Cut: dark is the one answer that cannot blow up. */
                    ++ctx->stats.paths_cut;
                    ++ctx->stats.cut_tracking;
                    T[0] = T[1] = T[2] = 0;
                    return;
                }
                rrv__medium_coeffs(m, rrv__madd(o, d, w.t_event), &c);
                for (ch = 0; ch < 3; ++ch)
                    if (member[ch]) {
                        T[ch] *= 1.0 - (c.sigma_a[ch] + c.sigma_s[ch]) / w.majorant;
                        tmaxc = rrv__maxd(tmaxc, T[ch]);
                    }
                if (tmaxc < 0.1 && tmaxc > 0) {
                    if (rrv__uniform_walk(rng) < 0.5) {
                        tmaxc = 0;
                    } else {
                        for (ch = 0; ch < 3; ++ch) T[ch] *= member[ch] ? 2.0 : 1.0;
                    }
                }
                if (!(tmaxc > 0)) {
                    for (ch = 0; ch < 3; ++ch)
                        if (member[ch]) T[ch] = 0;
                    if (!(rrv__max3(T) > 0)) return;
                    break;
                }
            }
        }
    }
}

/* Residual ratio tracking (Novak et al. 2014) with the majorant grid's
   minorant as the control: per cell the density d splits into the
   minorant d_c, whose optical depth tau_c along the segment is integrated
   exactly (it is constant in the cell), and the residual d - d_c, which
   ratio tracking estimates against the majorant d_max - d_c:
     T = exp(-k tau_c) prod_i (1 - k (d(x_i) - d_c) / (s (d_max - d_c)))
   (k the channel's extinction per unit density, s its group's scale).
   Each factor is 1 - k/s (d - d_c)/(d_max - d_c), which lies in [0, 1]
   where d_c <= d <= d_max, and its expectation over the Poisson collisions
   is exp(-k int (d - d_c)) whatever the majorant, so the product is
   unbiased even where rounding puts d a hair below d_c (a factor a hair
   above 1) or above d_max (one a hair below 0): a signed weight, never a
   clamp, which would bias it. Where d_c = d_max (a constant density) a
   cell takes no collisions and its transmittance is exact: no variance.
   Collisions fall at the residual's rate, so the walk is cheaper, and each
   factor is nearer 1, so the estimate varies less. Russian roulette acts
   on the whole estimate so far, control included. Channel groups are
   walked as in ratio tracking, each with its own majorant. */
static void rrv__residual_tracking_transmittance(rrv__context *ctx, rrv_vec3 o, rrv_vec3 d, double tmax,
                                                 rrv__rng *rng, double T[3])
{
    const rrv_scene *scene = ctx->scene;
    int i;
    T[0] = T[1] = T[2] = 1.0;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double k[3];
        int lead;
        if (m->density.kind == RRV_FIELD_NONE) continue;
        rrv__channel_extinction(m, k);
        for (lead = 0; lead < 3; ++lead) {
            rrv__walker w;
            const double *scale = m->majorant->channel_scale;
            double W[3] = {1, 1, 1};
            int member[3], ch;
            for (ch = 0; ch < 3; ++ch) member[ch] = scale[ch] == scale[lead];
            if ((lead > 0 && member[0]) || (lead > 1 && member[1]) || !(scale[lead] > 0)) continue;
            if (!rrv__walker_start(&w, m, 0, &scene->settings, o, d, tmax)) break;
            if (m->majorant->channel_groups > 1) rrv__walker_sample_channel(&w, &scene->settings, lead, 0);
            w.cells.residual = 1;
            for (;;) {
                rrv__coeffs c;
                double most = 0;
                rrv__walker_advance(&w, rng, &ctx->stats.events);
                if (w.t_event == DBL_MAX) {
                    if (!w.cut) break;
                    ++ctx->stats.paths_cut;
                    ++ctx->stats.cut_tracking;
                    T[0] = T[1] = T[2] = 0;
                    return;
                }
                rrv__medium_coeffs(m, rrv__madd(o, d, w.t_event), &c);
                for (ch = 0; ch < 3; ++ch)
                    if (member[ch]) {
                        double control = w.cell.density_min * k[ch];
                        W[ch] *= 1.0 - (c.sigma_a[ch] + c.sigma_s[ch] - control) / w.majorant;
                        /* the control so far covers the walk's cell to its end: a
                           deterministic function of the ray, so a fair roulette input */
                        most = rrv__maxd(most, fabs(W[ch]) * T[ch] * exp(-w.cells.control * k[ch]));
                    }
                if (most < 0.1 && most > 0) {
                    if (rrv__uniform_walk(rng) < 0.5) {
                        most = 0;
                    } else {
                        for (ch = 0; ch < 3; ++ch) W[ch] *= member[ch] ? 2.0 : 1.0;
                    }
                }
                if (!(most > 0)) {
                    for (ch = 0; ch < 3; ++ch)
                        if (member[ch]) W[ch] = 0;
                    break;
                }
            }
            for (ch = 0; ch < 3; ++ch)
                if (member[ch]) T[ch] *= W[ch] == 0 ? 0.0 : W[ch] * exp(-w.cells.control * k[ch]);
            if (!(rrv__max3(T) != 0)) return;
        }
    }
}

/* Samples a unit of the residual majorant's optical depth takes in one
   march of rrv__march_transmittance (a measurement build may set another). */
#ifndef RRV__MARCH_RATE
#define RRV__MARCH_RATE 2.0
#endif
/* The series' terms a march estimate may take before it is cut. */
#define RRV__MARCH_TERMS 64

/* One jittered march along o + t d, t in [0, tmax), through medium m: an
   unbiased estimate of each channel's optical depth. The minorant's depth
   is exact (rrv__majorant_iterator's control); the residual above it is
   sampled at points evenly spaced in the residual majorant's optical depth
   s, 1 / RRV__MARCH_RATE apart, from one random offset: a point at s stands
   for the stretch of s around it, whose residual depth is
   integral (sigma - sigma_c) / mu ds, so each adds
   (sigma - sigma_c) / (mu RRV__MARCH_RATE), unbiased since the offset
   makes every s equally likely. The points fall where the majorant says
   the density may be (none where it is known), and each weight lies in
   [0, 1 / RATE] as a ratio-tracking factor's complement does; regular
   spacing instead of Poisson collisions is what takes the variance. */
static int rrv__march_depth(rrv__context *ctx, const rrv_medium *m, const double k[3], rrv_vec3 o, rrv_vec3 d,
                            double tmax, rrv__rng *rng, double tau[3], double *weight)
{
    rrv__majorant_iterator it;
    rrv__majorant_segment seg;
    double step = 1.0 / RRV__MARCH_RATE, next = step * rrv__uniform_walk(rng), at = 0;
    long left = RRV_MAX_SEGMENT_EVENTS;
    int ch;
    tau[0] = tau[1] = tau[2] = 0;
    if (!rrv__majorant_iterator_start(&it, m, 0, &ctx->scene->settings, &o, &d, NULL, tmax, 0)) return 1;
    it.residual = 1;
    while (rrv__majorant_iterator_next(&it, &seg)) {
        double span = seg.majorant * (seg.t1 - seg.t0);
        if (weight && span > 0) {
            /* the pivot's march: roulette once what it has gathered so far
               (its depth only grows) leaves under a tenth, where work is
               left (a march through known density stays exact) */
            double most = 0;
            for (ch = 0; ch < 3; ++ch) most = rrv__maxd(most, exp(-(tau[ch] + it.control * k[ch])));
            if (*weight * most < 0.1) {
                if (rrv__uniform_walk(rng) < 0.5) return 0;
                *weight *= 2.0;
            }
        }
        if (!(span > 0)) continue;
        for (; next < at + span && left > 0; next += step, --left) {
            rrv__coeffs c;
            double w = step / seg.majorant;
            rrv__medium_coeffs(m, rrv__madd(o, d, seg.t0 + (next - at) / seg.majorant), &c);
            for (ch = 0; ch < 3; ++ch) tau[ch] += w * (c.sigma_a[ch] + c.sigma_s[ch] - seg.density_min * k[ch]);
            ++ctx->stats.events;
        }
        at += span;
    }
    for (ch = 0; ch < 3; ++ch) tau[ch] += it.control * k[ch];
    return 1;
}

/* The unbiased ray-marching estimator of transmittance: a jittered march
   gives the pivot p (an estimate of the optical depth tau), and
   exp(-tau) = exp(-p) exp(p - tau) = exp(-p) sum_j (p - tau)^j / j!,
   the series taken term by term. Term j's (p - tau)^j is estimated without
   bias by the product of j independent X_i = p - tau_i, tau_i further
   marches independent of p (conditioned on p, each X_i has mean p - tau
   and they are independent, so their product has mean (p - tau)^j). The
   series is truncated at random: after term j (j >= 1) the next is taken
   with probability q_j = min(1, 2 |X_j| / (j + 1)) (a function of draws
   already made, the size of the next term relative to this one), and
   each term is divided by the probability of reaching it, which keeps the
   sum unbiased. The first correction (j = 1) is always taken: without it
   exp(-p) alone is biased low by Jensen. A march varies far less than a
   ratio-tracking walk of as many lookups where the density is smooth, and
   every X_i is then small, so the series stops after a term or two; where
   the density is constant in a cell the march is exact there. The estimate
   is signed: a term's product may be negative, and the sum can be too
   (rarely, where X is large); callers must add it, never clamp it.
   Channels share the marches (their depths are k_c times the density's
   where the density grid is grey), so no channel groups are needed; each
   medium is estimated on its own, the product of independent estimates. */
static void rrv__march_transmittance(rrv__context *ctx, rrv_vec3 o, rrv_vec3 d, double tmax, rrv__rng *rng,
                                     double T[3])
{
    const rrv_scene *scene = ctx->scene;
    int i, ch;
    T[0] = T[1] = T[2] = 1.0;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double k[3], pivot[3], term[3], sum[3], x[3], so_far, weight;
        int j;
        if (m->density.kind == RRV_FIELD_NONE || m->majorant->empty) continue;
        /* the roulette weighs the whole estimate, earlier media's part too */
        so_far = rrv__maxd(fabs(T[0]), rrv__maxd(fabs(T[1]), fabs(T[2])));
        if (!(so_far > 0)) return;
        weight = so_far;
        rrv__channel_extinction(m, k);
        if (!rrv__march_depth(ctx, m, k, o, d, tmax, rng, pivot, &weight)) {
            T[0] = T[1] = T[2] = 0;
            return;
        }
        weight /= so_far;
        for (ch = 0; ch < 3; ++ch) sum[ch] = term[ch] = 1.0;
        for (j = 1;; ++j) {
            double tau[3], big = 0, q;
            if (j > RRV__MARCH_TERMS) {
                ++ctx->stats.paths_cut;
                ++ctx->stats.cut_tracking;
                T[0] = T[1] = T[2] = 0;
                return;
            }
            rrv__march_depth(ctx, m, k, o, d, tmax, rng, tau, NULL);
            for (ch = 0; ch < 3; ++ch) {
                x[ch] = pivot[ch] - tau[ch];
                term[ch] *= x[ch] / j;
                sum[ch] += term[ch];
                big = rrv__maxd(big, fabs(x[ch]));
            }
            q = 2.0 * big / (j + 1);
            if (q < 1.0) {
                if (!(rrv__uniform_walk(rng) < q)) break;
                for (ch = 0; ch < 3; ++ch) term[ch] /= q;
            }
        }
        for (ch = 0; ch < 3; ++ch) T[ch] *= weight * exp(-pivot[ch]) * sum[ch];
    }
}

/* Whether a transmittance estimate adds anything: march's are signed, and
   a negative one must be added as it is, never dropped (dropping it biases
   the sum up); ratio tracking's are never negative, where this is T > 0. */
static int rrv__nonzero3(const double T[3]) { return T[0] != 0 || T[1] != 0 || T[2] != 0; }

/* Every transmittance estimate: the scene's choice of estimator. */
static void rrv__transmittance(rrv__context *ctx, rrv_vec3 o, rrv_vec3 d, double tmax, rrv__rng *rng, double T[3])
{
    switch (ctx->scene->settings.transmittance) {
    case RRV_TRANSMITTANCE_MARCH: rrv__march_transmittance(ctx, o, d, tmax, rng, T); break;
    case RRV_TRANSMITTANCE_RESIDUAL: rrv__residual_tracking_transmittance(ctx, o, d, tmax, rng, T); break;
    default: rrv__ratio_tracking_transmittance(ctx, o, d, tmax, rng, T); break;
    }
}

enum { RRV__FLIGHT_PASSED, RRV__FLIGHT_SCATTERED, RRV__FLIGHT_ABSORBED, RRV__FLIGHT_BENT, RRV__FLIGHT_CUT };

typedef struct rrv__flight {
    double t;                /* where it scattered or bent */
    const rrv_medium *medium;/* that scattered */
    rrv_vec3 direction;      /* after bending */
} rrv__flight;

/* ---- emissive media as lights: next-event estimation and its MIS weights ---------
   At a real vertex x the path picks a point y of an emissive medium
   (rrv__emitter_sample, density p_nee(y) per unit volume), connects x to y
   with a straight shadow ray whose transmittance is ratio-tracked (as light
   NEE's) and adds f(x, w) T(x, y) sigma_a(y) Le(y) / (|y - x|^2 p_nee(y)),
   w = (y - x) / |y - x|: the integral over volume of the emission that
   reaches x, written with dV = r^2 dr dw. The forward path collects the same
   emission at its tentative collisions (rrv__gather_emission). Both are
   weighed by the power heuristic on densities in one measure, per unit
   volume at y:
     p_nee(y) = the grid's, pmf(cell of y) / volume(cell);
     p_fwd(y) = p(w) sigma_t(y) / r^2, with p(w) the vertex's density of w
       (cosine lobe or phase function) and r^2 the Jacobian from solid angle
       and distance to volume. The forward path's tentative collisions land
       at distance r with density mu(y) times the probability of getting
       there; the majorant mu and that transmittance depend on how the walk
       was sampled, so the weight takes the medium's own extinction in mu's
       place and leaves the transmittance (a factor both estimators carry in
       their integrand) out.
   Any weights that are functions of (x, y) alone and sum to one at every y
   keep the sum unbiased; these are, since both estimators evaluate the same
   two functions, p_nee through the one grid lookup and p_fwd through
   rrv__emission_dir_pdf of the same x and y (test/test_emission.c checks
   the sum at sampled points). Where the grid gives y no weight, or the
   vertex's own sampling cannot reach it, the one estimator that can takes
   weight 1.
   Refraction: a connection is straight, so it is made only where the
   forward path from x to y is straight too: a chord that meets no box of a
   refracting medium (rrv__chord_meets_refraction), walked by a path that has
   not turned since x (its segment's direction is still the one sampled at
   x). A sample whose chord meets such a box is aimed instead: its
   direction is walked as the path would walk it (rrv__emission_aim), and
   the emission past the box's first face, which a path that turned also
   reaches, is weighed in solid angle (rrv__emission_dir_density). */

/* The span [*t0, *t1] (t >= 0) of the ray o + t d inside the closed box,
   or 0 if it misses. A zero component is inside or outside its slab. */
static int rrv__ray_box_span(rrv_vec3 o, rrv_vec3 d, rrv_vec3 lo, rrv_vec3 hi, double *t0, double *t1)
{
    int ax;
    *t0 = 0.0;
    *t1 = DBL_MAX;
    for (ax = 0; ax < 3; ++ax) {
        double oa = rrv__axis(o, ax), da = rrv__axis(d, ax), l = rrv__axis(lo, ax), h = rrv__axis(hi, ax);
        if (da == 0.0) {
            if (oa < l || oa > h) return 0;
        } else {
            double ta = (l - oa) / da, tb = (h - oa) / da;
            if (ta > tb) { double t = ta; ta = tb; tb = t; }
            if (ta > *t0) *t0 = ta;
            if (tb < *t1) *t1 = tb;
        }
    }
    return *t0 <= *t1;
}

/* Does the segment from a to b meet the box of a medium that refracts?
   (The slab test on the closed box: the ray a + t (b - a) meets it at a
   t <= 1. rrv__emission_dir_density finds r* with the same test, so a
   chord meets a box exactly when its end lies past r*.) */
static int rrv__chord_meets_refraction(const rrv_scene *scene, rrv_vec3 a, rrv_vec3 b)
{
    rrv_vec3 d = rrv__sub(b, a);
    double t0, t1;
    int i;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && rrv__ray_box_span(a, d, m->lo, m->hi, &t0, &t1) && t0 <= 1.0) return 1;
    }
    return 0;
}

/* Emission NEE through refracting air. A sampled point y whose chord from
   the vertex x meets a refracting medium's box is not connected straight:
   its direction w = (y - x) / |y - x| is, by rrv__emission_aim, which walks
   the bent ray from x along w as the path would and collects the emission
   it meets (all of it past r*, below), weighed by the power heuristic in
   solid angle against the vertex's own density of w; the forward path
   weighs the emission it collects past r* by the complement (its
   direction w0 sampled at x). Past r* and short of a sharp face (where the
   walk stops and the path keeps weight 1) the two estimate the same
   radiance along each w, so the sum is unbiased however the ray bends.
   r*(w): where the ray from x first meets the box of a refracting medium
   (0 inside one); the chords to points past it meet the box, those short
   of it do not (rrv__chord_meets_refraction: a straight connection's).
   The density of w is that of picking a y past r* on the line x + r w:
   the integral of p_nee(x + r w) r^2 dr from r* on. p_nee is constant
   in a cell of the emission grid, so each cell the line crosses from a to
   b adds p_nee (b^3 - a^3) / 3; 0 where no refracting box is on the line. */
static double rrv__emission_dir_density(const rrv_scene *scene, rrv__emit_from *from, rrv_vec3 w)
{
    const struct rrv__emitters *e = scene->emitters;
    double r_star = DBL_MAX, sum = 0.0, t0, t1;
    int i;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && rrv__ray_box_span(from->x, w, m->lo, m->hi, &t0, &t1) && t0 < r_star)
            r_star = t0;
    }
    if (!e || r_star == DBL_MAX || !(from->S > 0)) return 0.0;
    for (i = 0; i < e->count; ++i) {
        const rrv__emitter_grid *g = &e->grid[i];
        rrv_vec3 hi = rrv__v3(g->lo.x + g->n[0] * g->cell.x, g->lo.y + g->n[1] * g->cell.y, g->lo.z + g->n[2] * g->cell.z);
        int idx[3], step[3], a, last = -1;
        double next[3], delta[3], t, part = 0.0, share = 0.0;
        if (!rrv__ray_box_span(from->x, w, g->lo, hi, &t0, &t1)) continue;
        if (t0 < r_star) t0 = r_star;
        if (!(t0 < t1)) continue;
        for (a = 0; a < 3; ++a) {
            double da = rrv__axis(w, a), cell = rrv__axis(g->cell, a), lo = rrv__axis(g->lo, a);
            double u = floor((rrv__axis(from->x, a) + da * t0 - lo) / cell);
            /* NaN or below: the first cell (an int from NaN is undefined) */
            idx[a] = u >= 0.0 ? (u <= g->n[a] - 1.0 ? (int)u : g->n[a] - 1) : 0;
            step[a] = da > 0 ? 1 : da < 0 ? -1 : 0;
            if (step[a]) {
                next[a] = (lo + (idx[a] + (step[a] > 0)) * cell - rrv__axis(from->x, a)) / da;
                delta[a] = cell / fabs(da);
            } else {
                next[a] = delta[a] = DBL_MAX;
            }
        }
        for (t = t0; t < t1;) {
            int axis = next[0] <= next[1] ? (next[0] <= next[2] ? 0 : 2) : (next[1] <= next[2] ? 1 : 2);
            double b = next[axis] < t1 ? next[axis] : t1;
            size_t cell = g->first + ((size_t)idx[2] * (size_t)g->n[1] + (size_t)idx[1]) * (size_t)g->n[0] + (size_t)idx[0];
            int cluster = g->first_cluster + ((idx[2] / RRV__EMIT_BLOCK) * g->nc[1] + idx[1] / RRV__EMIT_BLOCK) * g->nc[0] +
                          idx[0] / RRV__EMIT_BLOCK;
            if (b > t && e->pmf[cell] > 0) {
                /* a line stays in a cluster for several cells */
                if (cluster != last) share = rrv__emission_cluster_share(e, from, cluster);
                last = cluster;
                part += share * e->pmf[cell] * (b - t) * (b * b + b * t + t * t);
            }
            t = b > t ? b : t;
            if (next[axis] >= t1) break;
            idx[axis] += step[axis];
            if (idx[axis] < 0 || idx[axis] >= g->n[axis]) break;
            next[axis] += delta[axis];
        }
        sum += part * g->inv_volume / 3.0;
    }
    sum *= from->pick / from->S;
    /* far beyond any scene's size the cubes overflow: no aim there, and
       the forward path's weight is then 1 */
    return sum < DBL_MAX ? sum : 0.0;
}

/* The vertex's density of direction w: the cosine lobe on the side the path
   is on, or the phase function. */
static double rrv__emission_dir_pdf(const rrv__emit_from *from, rrv_vec3 w)
{
    if (from->surface) return fmax(rrv__dot(from->n, w), 0.0) * RRV__INV_PI;
    return rrv__hg_eval(from->g, rrv__dot(from->d_in, w));
}

/* The power heuristic's weight of the estimator with density a against one
   with density b, a^2 / (a^2 + b^2), written so that no square overflows
   (p_fwd grows as 1 / r^2 near the vertex). weight(a, b) + weight(b, a) = 1
   to rounding whenever a + b > 0. */
static double rrv__emission_mis(double a, double b)
{
    double t;
    if (!(a > 0)) return 0.0;
    if (a >= b) {
        t = b / a;
        return 1.0 / (1.0 + t * t);
    }
    t = a / b;
    t *= t;
    return t / (1.0 + t);
}

/* The two densities at y of medium mi seen from the vertex; 0 when the
   connection x -> y is not made (see above). A chord through refracting
   air its callers turn away first (it is aimed, or the path's past r*).
   *pdf_dir: the vertex's p(w). */
static int rrv__emission_densities(const rrv__context *ctx, rrv__emit_from *from, int mi, rrv_vec3 y,
                                   const rrv__coeffs *c, double *p_nee, double *p_fwd, double *pdf_dir, double *r)
{
    rrv_vec3 w = rrv__sub(y, from->x);
    double r2 = rrv__dot(w, w), s;
    *r = sqrt(r2);
    if (!(*r > 0) || !(r2 < DBL_MAX)) return 0;
    w = rrv__scale(w, 1.0 / *r);
    *pdf_dir = rrv__emission_dir_pdf(from, w);
    if (!(*pdf_dir > 0)) return 0;
    *p_nee = rrv__emission_pdf(ctx->scene->emitters, mi, from, y);
    if (!(*p_nee > 0)) return 0;
    s = (c->sigma_a[0] + c->sigma_s[0] + c->sigma_a[1] + c->sigma_s[1] + c->sigma_a[2] + c->sigma_s[2]) / 3.0;
    *p_fwd = *pdf_dir * s / r2;
    return 1;
}

/* The forward path's MIS weight for emission it collects at y in medium m. */
static double rrv__emission_forward_weight(const rrv__context *ctx, rrv__path *path, const rrv_medium *m,
                                           rrv_vec3 y, const rrv__coeffs *c)
{
    rrv__emit_from *from = &path->emit;
    double p_nee, p_fwd, pdf_dir, r;
    if (!from->on) return 1.0;
    /* a path that turned since x, or a chord through refracting air: not a
       straight connection's (past r*, rrv__emission_dir_density) */
    if (ctx->bends && (path->bender.line_d.x != from->w0.x || path->bender.line_d.y != from->w0.y ||
                       path->bender.line_d.z != from->w0.z || rrv__chord_meets_refraction(ctx->scene, from->x, y))) {
        if (from->aim) return 1.0;
        if (from->jumped) return 1.0;
        if (from->p_w0 < 0) from->p_w0 = rrv__emission_dir_density(ctx->scene, from, from->w0);
        return rrv__emission_mis(rrv__emission_dir_pdf(from, from->w0), from->p_w0);
    }
    /* short of r*: the aim's walk leaves it to straight connections */
    if (from->aim) return 0.0;
    if (!rrv__emission_densities(ctx, from, (int)(m - ctx->scene->media), y, c, &p_nee, &p_fwd, &pdf_dir, &r))
        return 1.0;
    return rrv__emission_mis(p_fwd, p_nee);
}

/* Absorb: emission. The collision estimator (as pbrt-v4's volpath) adds
   sigma_a Le / mu at every tentative collision, not only at absorptions, so
   emission converges without waiting for the rare absorption event. */
static void rrv__gather_emission(const rrv__context *ctx, rrv__path *path, const rrv_medium *m, rrv_vec3 x,
                                 const rrv__coeffs *c, double mu, const double *mu_channels)
{
    double Le[3], k = rrv__path_mis(path) / mu, given = 1.0;
    int ch;
    /* with channel groups, each channel's collision density is its own
       majorant's: the balance heuristic over those densities weighs the
       ratios by them (pbrt-v4's choice; weighing by the ratios alone, the
       transmittances, also sums to one over the heroes) */
    if (mu_channels)
        k = 3.0 / (path->ratio[0] * mu_channels[0] + path->ratio[1] * mu_channels[1] +
                   path->ratio[2] * mu_channels[2]);
    if (ctx->bends) {
        double eta = 1.0 + rrv__scene_refractivity(ctx->scene, x, NULL);
        given = ctx->eta_camera2 / (eta * eta);
    }
    rrv__medium_Le(ctx->scene, m, x, given, ctx->thermal_scale, Le);
    if (path->emit.on) k *= rrv__emission_forward_weight(ctx, path, m, x, c);
    for (ch = 0; ch < 3; ++ch) path->L[ch] += path->beta[ch] * c->sigma_a[ch] * Le[ch] * k;
}

/* The reciprocals of d's components if the comb's planned chord runs
   along d (rrv__comb_step computed them once for its line), else NULL. */
static const double *rrv__chord_inv(const rrv__context *ctx, const rrv__bender *b, rrv_vec3 d)
{
    return ctx->comb && b->pending && b->line_d.x == d.x && b->line_d.y == d.y && b->line_d.z == d.z ? b->line_inv
                                                                                                      : NULL;
}

/* The first surface on the bender's planned segment from o along d, or 0
   (also where the bender knows none reaches the segment). A surface lying
   on the face that ends the segment belongs to it: looked for a gap past
   the end, it cannot slip between this segment's end and the next one's
   start. Inline: the comb asks at every chord, most often in vain. */
static inline int rrv__segment_hit(const rrv__context *ctx, const rrv__bender *b, rrv_vec3 o, rrv_vec3 d,
                                   double segment, rrv__hit *hit)
{
    if (b->surface_free) return 0;
    return rrv__intersect_line(ctx->scene, o, d, rrv__chord_inv(ctx, b, d),
                               segment < DBL_MAX ? segment + rrv__face_gap(rrv__madd(o, d, segment)) : DBL_MAX, hit);
}

/* Might the chord o + t d, t in [0, len], meet a medium with extinction?
   Its bounding box against the media's boxes: no divisions, and a false
   yes only costs the ordinary walk. The box by comparisons: the comb asks
   at every kick, and rrv__vmin's six fmin/fmax are library calls (three
   quarters of this test's cost); inline for the same reason. */
static inline int rrv__chord_meets_extinction(const rrv_scene *scene, rrv_vec3 o, rrv_vec3 d, double len)
{
    rrv_vec3 e = rrv__madd(o, d, len);
    rrv_vec3 lo = rrv__v3(rrv__mind(o.x, e.x), rrv__mind(o.y, e.y), rrv__mind(o.z, e.z));
    rrv_vec3 hi = rrv__v3(rrv__maxd(o.x, e.x), rrv__maxd(o.y, e.y), rrv__maxd(o.z, e.z));
    int i;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        if (m->majorant->empty) continue;
        if (lo.x <= m->hi.x && hi.x >= m->lo.x && lo.y <= m->hi.y && hi.y >= m->lo.y && lo.z <= m->hi.z &&
            hi.z >= m->lo.z)
            return 1;
    }
    return 0;
}

/* Moves walkers[best] to its next tentative collision or face, dropping it
   from the n walking once it has left its box. 0 if its budget ran out. */
static int rrv__advance_walker(rrv__walker *walkers, int *n, int best, rrv__rng *rng, uint64_t *events)
{
    rrv__walker *w = &walkers[best];
    rrv__walker_advance(w, rng, events);
    if (w->t_event == DBL_MAX) {
        if (w->cut) return 0;
        walkers[best] = walkers[--*n];
    }
    return 1;
}

/* Spectral MIS where a medium's channels walk with different majorants
   (channel groups, rrv__walker): channel c's path density carries its own
   majorant transmittance exp(-k_c D), D the density bound integrated along
   the walk, where the hero's walk carries exp(-k_hero D). Reweights the
   path (beta and ratio alike: for delta tracking's choices the integrand
   and each channel's density share the factor) by their quotient for the
   part of each pausing walker's D from where it was last reweighted to t.
   A pausing walker's last event and pending one share a cell, which holds
   t (t comes no later than any pending event), so D at t is exact. */
static void rrv__reweight_channel_depths(rrv__path *path, rrv__walker *walkers, int n, double t)
{
    double e[3] = {0, 0, 0};
    int i, c, any = 0;
    for (i = 0; i < n; ++i) {
        rrv__walker *w = &walkers[i];
        const double *k = w->cells.grid->channel_scale;
        double D;
        if (!w->pauses) continue;
        D = w->depth - w->cell.density_max * (w->t - t);
        if (!(D > w->applied)) continue;
        for (c = 0; c < 3; ++c) e[c] -= (k[c] - k[path->hero]) * (D - w->applied);
        w->applied = D;
        any = 1;
    }
    if (any) {
        double f[3];
        for (c = 0; c < 3; ++c) f[c] = exp(e[c]);
        rrv__path_reweight(path, f);
    }
}

/* Refractive delta tracking: the seed paper's Algorithm 1, along one straight
   segment o + t d, t < tmax. With refract_nulls off (classic, and the comb
   and eikonal integrators, which bend only at segment ends) it is classic
   null-scattering delta tracking (Miller et al. 2019).
   Every medium's tentative collisions form an independent Poisson process
   with its majorant, so the earliest pending one across media is the next
   collision. The hero channel chooses the event; the other channels are
   reweighted by spectral MIS. Returns at the first real event (the path
   tracer takes it from there) or when the ray bends, so that the next
   segment starts straight from the bend.
   The comb (the default refractive scheme) is this loop with its
   refraction taken out of the null events: the walk pauses at regularly
   spaced points (rrv__comb_step), which free-flight sampling allows since
   it is memoryless. Measured: second order where Algorithm 1 is first
   (README, "Accuracy against closed forms"). */
static int rrv__refractive_delta_tracking(rrv__context *ctx, rrv__path *path, rrv_vec3 o, rrv_vec3 d, double tmax,
                                          rrv__rng *rng, rrv__flight *out)
{
    rrv__walker walkers[RRV__MAX_MEDIA];
    const double *inv_d = rrv__chord_inv(ctx, &path->bender, d);
    /* the planned comb chord, if it lies inside the sole support: the media
       whose boxes hold the support need not clip it */
    uint64_t inside = inv_d && path->bender.chord_inside ? path->bender.holds_support : 0;
    int n = rrv__start_walkers(ctx, walkers, ctx->refract_nulls, &o, &d, inv_d, inside, tmax, path->hero, rng,
                               &ctx->stats.events);
    while (n > 0) {
        int i, best = 0, ch;
        rrv__walker *w;
        const rrv_medium *m;
        rrv_vec3 x;
        rrv__coeffs c;
        double mu, pa, ps, u, mu_channels[3];
        int emits;
        /* 1. sample a distance with the majorant: the earliest tentative
              collision of all media (each walker has drawn its own) */
        for (i = 1; i < n; ++i)
            if (walkers[i].t_event < walkers[best].t_event) best = i;
        w = &walkers[best];
        if (w->t_event >= tmax) break;
        if (w->at_face) {
            /* a pausing walker's cell face: no collision, only its depth */
            rrv__reweight_channel_depths(path, w, 1, w->t_event);
            if (!rrv__advance_walker(walkers, &n, best, rng, &ctx->stats.events)) return RRV__FLIGHT_CUT;
            continue;
        }
        m = w->medium;
        mu = w->majorant;
        if (w->pauses) {
            const double *k = w->cells.grid->channel_scale;
            rrv__reweight_channel_depths(path, walkers, n, w->t_event);
            for (ch = 0; ch < 3; ++ch) mu_channels[ch] = mu + w->cell.density_max * (k[ch] - k[path->hero]);
        } else {
            mu_channels[0] = mu_channels[1] = mu_channels[2] = mu;
        }
        x = rrv__madd(o, d, w->t_event);
        rrv__medium_coeffs(m, x, &c);
        /* 2. absorb: emission (gathered at every collision, see above) */
        emits = rrv__medium_emits(m);
        if (emits) rrv__gather_emission(ctx, path, m, x, &c, mu, w->pauses ? mu_channels : NULL);
        /* 3. sample the event A, S or N with probabilities sigma_a / mu,
              sigma_s / mu and sigma_n / mu */
        pa = c.sigma_a[path->hero] / mu;
        ps = c.sigma_s[path->hero] / mu;
        u = rrv__uniform_walk(rng);
        if (emits && pa > 0 && ps > 0 && u < pa + ps) {
            /* In a medium that emits, a real collision always scatters and
               the albedo weighs the path: the light a flame scatters toward
               a room then comes from every path that meets the flame, not
               from the few its albedo lets through. Measured on
               test/bench/campfire.rrv (albedo 0.05): by chance, those few
               carried the flame's whole radiance and were the fireflies of
               every depth past one. A channel takes this collision with
               sigma_t / mu and carries sigma_s. */
            double sigma_t[3];
            for (ch = 0; ch < 3; ++ch) sigma_t[ch] = c.sigma_a[ch] + c.sigma_s[ch];
            rrv__path_reweight(path, sigma_t);
            for (ch = 0; ch < 3; ++ch) path->beta[ch] *= sigma_t[ch] > 0 ? c.sigma_s[ch] / sigma_t[ch] : 0.0;
            out->t = w->t_event;
            out->medium = m;
            return RRV__FLIGHT_SCATTERED;
        }
        if (u < pa) return RRV__FLIGHT_ABSORBED;
        if (u < pa + ps) {
            /* scatter: the path tracer samples the phase function here */
            rrv__path_reweight(path, c.sigma_s);
            out->t = w->t_event;
            out->medium = m;
            return RRV__FLIGHT_SCATTERED;
        }
        {
            double sigma_n[3];
            for (ch = 0; ch < 3; ++ch) sigma_n[ch] = mu_channels[ch] - c.sigma_a[ch] - c.sigma_s[ch];
            if (sigma_n[0] != sigma_n[1] || sigma_n[1] != sigma_n[2]) rrv__path_reweight(path, sigma_n);
        }
        /* 4. null: refract by Snell's law with the ratio of the IOR the ray
              carries to the IOR here and the normal grad eta here */
        if (ctx->refract_nulls) {
            rrv_vec3 nd = rrv__bend_at_null_event(&path->bender, ctx->scene, x, d);
            if (nd.x != d.x || nd.y != d.y || nd.z != d.z) {
                out->t = w->t_event;
                out->direction = nd;
                return RRV__FLIGHT_BENT;
            }
        }
        /* and go on: this medium's next tentative collision */
        if (!rrv__advance_walker(walkers, &n, best, rng, &ctx->stats.events)) return RRV__FLIGHT_CUT;
    }
    rrv__reweight_channel_depths(path, walkers, n, tmax);
    return RRV__FLIGHT_PASSED;
}

/* ---- lights ------------------------------------------------------------------ */

static void rrv__environment_L(const rrv_environment *env, rrv_vec3 d, double L[3])
{
    int c;
    if (env->kind == RRV_ENV_GRADIENT) {
        double t = 0.5 * (d.y + 1.0);
        for (c = 0; c < 3; ++c) L[c] = env->L2[c] + t * (env->L[c] - env->L2[c]);
    } else if (env->kind == RRV_ENV_CONSTANT) {
        for (c = 0; c < 3; ++c) L[c] = env->L[c];
    } else {
        L[0] = L[1] = L[2] = 0;
    }
}

static double rrv__shape_area(const rrv_shape *s)
{
    if (s->kind == RRV_SHAPE_SPHERE) return 4.0 * RRV__PI * s->radius * s->radius;
    return rrv__length(rrv__cross(s->e1, s->e2)) * (s->kind == RRV_SHAPE_TRIANGLE ? 0.5 : 1.0);
}

static int rrv__light_choices(const rrv_scene *scene)
{
    return scene->light_count + (scene->environment.kind != RRV_ENV_NONE ? 1 : 0);
}

/* ---- which light NEE samples (LIGHT SAMPLING in the manual) ----
   A light shape's weight is its power over pi, its area times its mean
   radiance (quads and triangles emit on one side, spheres outward), so a
   vertex spends its one light sample on the lights that give the most
   (pbrt-v4's power light sampler). The sky is sampled in uniform
   directions, which is what an isotropic phase function samples too, and
   worse than a diffuse surface's cosine lobe: its light samples would only
   repeat the path's own, at the price of the light shapes' (scenes/smoke.rrv
   2.0x and scenes/plume.rrv 1.5x the efficiency without them, test/bench/
   RESULTS.md, "Light sampling"). So, as pbrt-v4 leaves a uniform sky to
   BSDF sampling, the sky weighs 0 beside a light shape, and the path's own
   directions take all of its light (their MIS weight is then 1); beside
   emissive media and no light shape the emitters take the samples instead
   (rrv__emitters_take_samples). Alone it is sampled as before, so
   sky-lit scenes keep their light samples. */
static int rrv__emitters_take_samples(const rrv_scene *scene)
{
    return scene->light_power && scene->light_count == 0 && scene->emitters &&
           scene->settings.emission_nee != RRV_EMISSION_NEE_OFF;
}

/* Beside light shapes, emissive media take a share of the same pick
   (rrv__vertex_emit_share: by power over squared distance under classic,
   by power, scene->emit_share, under refraction) unless the scene says
   `emissionnee on` (a sample of their own at every vertex, besides the
   light's) or off. A draw of their own beside a light that outshines
   them cost more than it saved (scenes/fire.rrv 0.46x), while leaving
   them to the paths cost 12x where they light most of the room
   (test/bench/campfire.rrv under a fill light, RESULTS.md, "Fire beside
   a light"); a share of one draw is never far from the better of the
   two. */
static int rrv__emitters_share_draws(const rrv_scene *scene)
{
    return scene->light_power && scene->light_count > 0 && scene->emitters &&
           scene->settings.emission_nee == RRV_EMISSION_NEE_DEFAULT;
}

/* The pick, its probabilities and the sky's weight are those prepare saw
   (light_power, sky_weight): a setting edited since changes nothing until
   the scene is prepared again, so the pick and the densities the
   estimators divide by always agree. */
static double rrv__light_weight(const rrv_scene *scene, const rrv_shape *s)
{
    if (!scene->light_power) return 1.0;
    if (!s) return scene->sky_weight;
    return rrv__shape_area(s) * (s->L[0] + s->L[1] + s->L[2]) / 3.0;
}

/* The probability that rrv__light_pick names light shape s (NULL: the sky)
   from a draw whose emit_share is emit_share. */
static double rrv__light_prob(const rrv_scene *scene, const rrv_shape *s, double emit_share)
{
    int choices = rrv__light_choices(scene);
    if (!scene->light_power) return 1.0 / choices;
    return scene->light_cdf
               ? (1.0 - emit_share) * rrv__light_weight(scene, s) / scene->light_cdf[choices - 1]
               : 0.0;
}

static rrv_result rrv__build_light_cdf(rrv_scene *scene, rrv_error *err)
{
    int choices = rrv__light_choices(scene), i;
    double sum = 0;
    scene->light_power = scene->settings.light_sampler == RRV_LIGHT_SAMPLER_POWER;
    scene->sky_weight = scene->light_count || rrv__emitters_take_samples(scene) ? 0.0 : 1.0;
    scene->emit_share = 0.0;
    if (!choices || !scene->light_power) return RRV_OK;
    scene->light_cdf = (double *)RRV_MALLOC((size_t)choices * sizeof(double));
    if (!scene->light_cdf) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
    scene->bytes += (size_t)choices * sizeof(double);
    for (i = 0; i < choices; ++i) {
        sum += rrv__light_weight(scene, i < scene->light_count ? &scene->shapes[scene->lights[i]] : NULL);
        scene->light_cdf[i] = sum;
    }
    if (sum == 0) {
        /* only a sky, and the emitters take the samples: nothing to pick */
        scene->bytes -= (size_t)choices * sizeof(double);
        RRV_FREE(scene->light_cdf);
        scene->light_cdf = NULL;
        return RRV_OK;
    }
    if (!(sum > 0) || !(sum < DBL_MAX))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0, "the lights' total power is %g", sum);
    if (rrv__emitters_share_draws(scene) && scene->emitters->power > 0 && scene->emitters->power < DBL_MAX) {
        rrv_vec3 lo = rrv__v3(DBL_MAX, DBL_MAX, DBL_MAX), hi = rrv__scale(lo, -1.0);
        scene->emit_share = scene->emitters->power / (scene->emitters->power + sum);
        /* the lights keep a sliver, so that their densities stay finite */
        if (!(scene->emit_share < 1.0 - 1e-9)) scene->emit_share = 1.0 - 1e-9;
        for (i = 0; i < scene->light_count; ++i) {
            rrv_vec3 a, b;
            rrv__shape_bounds(&scene->shapes[scene->lights[i]], &a, &b);
            lo = rrv__vmin(lo, a);
            hi = rrv__vmax(hi, b);
        }
        rrv__emit_cluster_box(&scene->emitters->lights, lo, hi);
        scene->emitters->lights.weight = sum;
    }
    return RRV_OK;
}

/* Solid-angle pdf of sampling direction toward point q on emitter s from p
   (sphere: the cone of directions it subtends). Selection not included. */
static double rrv__emitter_pdf(const rrv_shape *s, rrv_vec3 p, rrv_vec3 q, rrv_vec3 nq)
{
    if (s->kind == RRV_SHAPE_SPHERE) {
        double dc2 = rrv__dot(rrv__sub(s->center, p), rrv__sub(s->center, p));
        double sin2 = s->radius * s->radius / dc2;
        double one_minus_cos = sin2 / (1.0 + sqrt(fmax(0.0, 1.0 - sin2)));
        if (sin2 >= 1.0) return 0.0;
        return 1.0 / (2.0 * RRV__PI * one_minus_cos);
    } else {
        rrv_vec3 w = rrv__sub(q, p);
        double dist2 = rrv__dot(w, w), cosl = -rrv__dot(nq, w) / sqrt(dist2);
        return cosl > 0 ? dist2 / (rrv__shape_area(s) * cosl) : 0.0;
    }
}

typedef struct rrv__light_sample {
    rrv_vec3 wi;
    double dist;      /* DBL_MAX for the environment */
    double L[3];
    double pdf;       /* solid angle, selection included */
    rrv_vec3 point;   /* on the emitter, for the radiance scale with IOR */
} rrv__light_sample;

/* The random numbers of a vertex's one light sample: which emitter (u) and
   where on it (u1, u2). Straight NEE and the curved estimators (shoot, aim,
   manifold) take the same draw, so each light point goes to the one
   estimator its connection's class names (straight for a weak chord,
   curved otherwise), as a sample routed by its class rather than two
   independent samples of which each discards the other's part: at a floor
   point that sees part of a light straight and part through a lens, the
   two parts then no longer add their variances (the sum of two estimates
   that are each zero half the time). */
typedef struct rrv__light_draw {
    double u, u1, u2;
    double emit_share; /* the emissive media's share of it (rrv__light_pick) */
} rrv__light_draw;

/* Which of the rrv__light_choices the draw picks: an index into
   scene->lights, or light_count for the environment; -1 if there is none
   or the draw falls in the emissive media's share (u below emit_share,
   rrv__vertex_nee samples them). Straight and curved NEE pick through
   here, so one draw names one light. */
static int rrv__light_pick(const rrv_scene *scene, const rrv__light_draw *draw)
{
    int choices = rrv__light_choices(scene), pick, hi;
    double target;
    if (!choices || (scene->light_power && !scene->light_cdf)) return -1;
    if (!scene->light_power) {
        pick = (int)(draw->u * choices);
        return pick >= choices ? choices - 1 : pick;
    }
    /* the first running sum above u times the total: a choice of weight 0
       adds nothing to the sum and is never the first above it; past the
       emitters' share, what is left of u */
    target = draw->u;
    if (draw->emit_share > 0) {
        if (target < draw->emit_share) return -1;
        target = (target - draw->emit_share) / (1.0 - draw->emit_share);
    }
    target *= scene->light_cdf[choices - 1];
    for (pick = 0, hi = choices - 1; pick < hi;) {
        int mid = (pick + hi) / 2;
        if (target < scene->light_cdf[mid]) hi = mid;
        else pick = mid + 1;
    }
    /* where rounding put u times the total on the last sum: the last
       choice with a weight */
    while (pick > 0 && !(scene->light_cdf[pick] > scene->light_cdf[pick - 1])) --pick;
    return pick;
}

/* Whether the pick names nothing whatever the draw: no light at all, or
   only a sky the emitters took the samples from. */
static int rrv__light_pick_none(const rrv_scene *scene)
{
    return !rrv__light_choices(scene) ||
           (scene->light_power && !scene->light_cdf);
}

/* The point of a quad or triangle light that (u1, u2) names, uniform in area. */
static rrv_vec3 rrv__area_light_point(const rrv_shape *s, double u1, double u2)
{
    if (s->kind == RRV_SHAPE_TRIANGLE) {
        double su = sqrt(u1);
        return rrv__madd(rrv__madd(s->p0, s->e1, 1.0 - su), s->e2, u2 * su);
    }
    return rrv__madd(rrv__madd(s->p0, s->e1, u1), s->e2, u2);
}

static void rrv__draw_light(rrv__rng *rng, rrv__light_draw *draw)
{
    /* one a statement: the order of evaluation of arguments is unspecified */
    draw->u = rrv__uniform(rng);
    draw->u1 = rrv__uniform(rng);
    draw->u2 = rrv__uniform(rng);
    draw->emit_share = 0.0;
}

static int rrv__sample_light(const rrv_scene *scene, rrv_vec3 p, const rrv__light_draw *draw, rrv__light_sample *ls)
{
    int pick = rrv__light_pick(scene, draw), c;
    const double u1 = draw->u1, u2 = draw->u2;
    if (pick < 0) return 0;
    if (pick == scene->light_count) {
        ls->wi = rrv__sample_uniform_sphere(u1, u2);
        ls->dist = DBL_MAX;
        ls->pdf = RRV__INV_4PI * rrv__light_prob(scene, NULL, draw->emit_share);
        rrv__environment_L(&scene->environment, ls->wi, ls->L);
        ls->point = rrv__madd(p, ls->wi, 1e30);
        return ls->pdf > 0 && (ls->L[0] > 0 || ls->L[1] > 0 || ls->L[2] > 0);
    } else {
        const rrv_shape *s = &scene->shapes[scene->lights[pick]];
        rrv_vec3 q, nq;
        if (s->kind == RRV_SHAPE_SPHERE) {
            rrv_vec3 axis = rrv__sub(s->center, p);
            double dc = rrv__length(axis), sin2 = s->radius * s->radius / (dc * dc);
            double one_minus_cos_max, cos_t, sin_t, phi, b, disc;
            if (sin2 >= 1.0) return 0; /* inside an outward-emitting sphere: dark */
            one_minus_cos_max = sin2 / (1.0 + sqrt(1.0 - sin2));
            cos_t = 1.0 - u1 * one_minus_cos_max;
            sin_t = sqrt(fmax(0.0, 1.0 - cos_t * cos_t));
            phi = 2.0 * RRV__PI * u2;
            axis = rrv__scale(axis, 1.0 / dc);
            ls->wi = rrv__from_frame(axis, sin_t * cos(phi), sin_t * sin(phi), cos_t);
            /* distance to the near side of the sphere along wi */
            b = dc * cos_t;
            disc = s->radius * s->radius - dc * dc * sin_t * sin_t;
            ls->dist = b - sqrt(fmax(0.0, disc));
            ls->pdf = rrv__light_prob(scene, s, draw->emit_share) / (2.0 * RRV__PI * one_minus_cos_max);
            if (!(ls->pdf > 0)) return 0;
            q = rrv__madd(p, ls->wi, ls->dist);
        } else {
            q = rrv__area_light_point(s, u1, u2);
            nq = rrv__normalize(rrv__cross(s->e1, s->e2));
            ls->wi = rrv__sub(q, p);
            ls->dist = rrv__length(ls->wi);
            if (!(ls->dist > 0)) return 0;
            ls->wi = rrv__scale(ls->wi, 1.0 / ls->dist);
            ls->pdf = rrv__emitter_pdf(s, p, q, nq) * rrv__light_prob(scene, s, draw->emit_share);
            if (!(ls->pdf > 0)) return 0;
        }
        for (c = 0; c < 3; ++c) ls->L[c] = s->L[c];
        ls->point = q;
        return 1;
    }
}

/* Visibility (surfaces) times transmittance (media) between p and a light
   sample, with NEE rays kept straight. */
static void rrv__light_transmittance(rrv__context *ctx, rrv_vec3 p, const rrv__light_sample *ls, rrv__rng *rng,
                                     double T[3])
{
    rrv__hit hit;
    double tmax = ls->dist == DBL_MAX ? DBL_MAX : ls->dist * (1.0 - 1e-7);
    ++ctx->stats.paths;
    if (rrv__intersect_scene(ctx->scene, p, ls->wi, tmax, &hit)) {
        T[0] = T[1] = T[2] = 0;
        return;
    }
    rrv__transmittance(ctx, p, ls->wi, tmax, rng, T);
}

/* ---- equiangular sampling toward lights inside media ----------------------------
   A light inside a thin medium lights the medium around it as 1 / r^2:
   free flights, drawn in proportion to the transmittance, put few
   vertices where that glow is, and those far apart. An equiangular sample
   (Kulla and Fajardo 2012) draws the distance t along a segment in
   proportion to 1 / r(t)^2 from the light's centre c instead:
       p_eq(t) = h / ((theta_b - theta_a) (h^2 + (t - D)^2)),
   D = (c - o).d the foot of the perpendicular from c, h its length, theta
   = atan((t - D) / h) at the span's ends a and b. rrv__equiangular_nee
   takes one such sample a segment through a scattering medium and connects
   it to the light as straight NEE does; it is the third way to reach the
   same (t, direction to the light) that the free flight's vertex reaches
   by light sampling (A) and by its phase sample hitting the light (B).
   The three combine by the power heuristic over
       p_A = p_ff(t) p_light,  p_B = p_ff(t) p_phase,  p_C = p_eq(t) p_light,
   p_light the light sample's solid-angle density (its pick included),
   which every technique evaluates from the same t and direction, so the
   three weights sum to one wherever all three can reach. p_ff is the free
   flight's density, sigma_t T, which a heterogeneous medium does not give
   in closed form; any function of t the three share keeps the sum
   unbiased (it only steers the weights), so this uses sigma~(t) exp(-sigma~(t)
   (t - a)), sigma~ the channels' mean extinction at t: exact in a
   homogeneous medium that begins at a, a guess elsewhere.
   Restrictions, each a function of the segment alone so that every
   technique agrees on it: the classic integrator (a bent ray has no such
   density); segments whose ray meets exactly one scattering medium's box
   (there the phase function at t is that medium's, as the free flight's
   would be); light shapes (the sky has no centre), by default only those
   within a scattering medium's box (EQUIANGULAR SAMPLING in the manual);
   the span [a, b] the segment spends in that box. */

/* The point an equiangular sample aims at. */
static rrv_vec3 rrv__light_centre(const rrv_shape *s)
{
    if (s->kind == RRV_SHAPE_SPHERE) return s->center;
    if (s->kind == RRV_SHAPE_TRIANGLE) return rrv__madd(rrv__madd(s->p0, s->e1, 1.0 / 3.0), s->e2, 1.0 / 3.0);
    return rrv__madd(rrv__madd(s->p0, s->e1, 0.5), s->e2, 0.5);
}

/* A medium whose collisions can scatter: free flights make vertices in it. */
static int rrv__medium_scatters(const rrv_medium *m)
{
    return m->density.kind != RRV_FIELD_NONE && m->scale > 0 && rrv__max3(m->sigma_s) > 0;
}

/* Whether equiangular samples aim at light shape s on segments through
   medium m (ctx->equiangular 2: every light; 1, the default: a light
   whose centre lies in m's box, whose glow free flights miss). */
static int rrv__equi_aims_at(const rrv__context *ctx, const rrv_shape *s, const rrv_medium *m)
{
    return ctx->equiangular == 2 || rrv__inside_box(rrv__light_centre(s), m->lo, m->hi);
}

/* Sets up the segment o + t d, t < tmax: on when it meets exactly one
   scattering medium's box, with [a, b] its span there. */
static void rrv__equi_segment(const rrv__context *ctx, rrv_vec3 o, rrv_vec3 d, double tmax, rrv__equi *eq)
{
    const rrv_scene *scene = ctx->scene;
    int i;
    eq->on = 0;
    eq->o = o;
    eq->d = d;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double t0, t1;
        if (!rrv__medium_scatters(m) || !rrv__ray_box_span(o, d, m->lo, m->hi, &t0, &t1) || !(t0 < tmax)) continue;
        if (eq->on) {
            eq->on = 0;
            return;
        }
        eq->on = 1;
        eq->medium = i;
        eq->a = t0;
        eq->b = rrv__mind(t1, tmax);
    }
    if (eq->on && !(eq->b > eq->a && eq->b < DBL_MAX)) eq->on = 0;
}

/* The segment's geometry toward c: D, h and the angles of a and b; 0
   where the density degenerates (c on the ray's line). */
static int rrv__equi_frame(const rrv__equi *eq, rrv_vec3 c, double *D, double *h, double *theta_a, double *theta_b)
{
    rrv_vec3 oc = rrv__sub(c, eq->o);
    *D = rrv__dot(oc, eq->d);
    *h = rrv__length(rrv__sub(oc, rrv__scale(eq->d, *D)));
    if (!(*h > 1e-9 * (1.0 + rrv__length(oc)))) return 0;
    *theta_a = atan2(eq->a - *D, *h);
    *theta_b = atan2(eq->b - *D, *h);
    return *theta_b > *theta_a;
}

static double rrv__equi_pdf(const rrv__equi *eq, rrv_vec3 c, double t)
{
    double D, h, ta, tb;
    if (!(t >= eq->a && t <= eq->b) || !rrv__equi_frame(eq, c, &D, &h, &ta, &tb)) return 0.0;
    return h / ((tb - ta) * (h * h + (t - D) * (t - D)));
}

/* t in [a, b] by the equiangular density toward c (inverted CDF); 0 when
   there is none. */
static int rrv__equi_sample(const rrv__equi *eq, rrv_vec3 c, double u, double *t, double *pdf)
{
    double D, h, ta, tb;
    if (!rrv__equi_frame(eq, c, &D, &h, &ta, &tb)) return 0;
    *t = rrv__clamp(D + h * tan(ta + u * (tb - ta)), eq->a, eq->b);
    *pdf = h / ((tb - ta) * (h * h + (*t - D) * (*t - D)));
    return *pdf > 0 && *pdf < DBL_MAX;
}

/* p_ff of the section comment: what the weights take for the free
   flight's density at t. */
static double rrv__equi_free_flight(const rrv__context *ctx, const rrv__equi *eq, double t)
{
    rrv__coeffs c;
    double sigma = 0;
    int ch;
    rrv__medium_coeffs(&ctx->scene->media[eq->medium], rrv__madd(eq->o, eq->d, t), &c);
    for (ch = 0; ch < 3; ++ch) sigma += (c.sigma_a[ch] + c.sigma_s[ch]) / 3.0;
    return sigma * exp(-sigma * (t - eq->a));
}

/* The power heuristic's weight of technique `mine` among A, B and C. */
static double rrv__equi_weight(double mine, double p_a, double p_b, double p_c)
{
    double sum = p_a * p_a + p_b * p_b + p_c * p_c;
    return sum > 0 ? mine * mine / sum : 0.0;
}

/* The weight of a free flight's vertex at eq->t (A: p_own the light
   sample's density, B: the phase function's) toward light shape s, where
   the light sample's density is p_light and the phase function's p_phase;
   emit_share: the emitters' share of the vertex's light draw, which the
   equiangular sample's own pick of a shape does not have. */
static double rrv__equi_vertex_weight(const rrv__context *ctx, const rrv__equi *eq, const rrv_shape *s, int light_side,
                                      double p_light, double p_phase, double emit_share)
{
    double p_ff, p_eq;
    rrv_vec3 c;
    if (!eq->on || !rrv__equi_aims_at(ctx, s, &ctx->scene->media[eq->medium]))
        return light_side ? rrv__power_heuristic(p_light, p_phase) : rrv__power_heuristic(p_phase, p_light);
    c = rrv__light_centre(s);
    p_eq = rrv__equi_pdf(eq, c, eq->t);
    p_ff = rrv__equi_free_flight(ctx, eq, eq->t);
    return rrv__equi_weight(light_side ? p_ff * p_light : p_ff * p_phase, p_ff * p_light, p_ff * p_phase,
                            p_eq * p_light / (1.0 - emit_share));
}

/* The equiangular sample's own weight (C) at distance t toward light
   point density p_light (its pick's: never the emitters') and phase
   density p_phase, where a free flight's vertex at t would give the
   emitters emit_share of its light draw (A's density then (1 - emit_share)
   p_light). With rrv__equi_vertex_weight the three sum to one. */
static double rrv__equi_own_weight(const rrv__context *ctx, const rrv__equi *eq, rrv_vec3 c, double t, double p_light,
                                   double p_phase, double emit_share)
{
    double p_eq = rrv__equi_pdf(eq, c, t), p_ff = rrv__equi_free_flight(ctx, eq, t);
    return rrv__equi_weight(p_eq * p_light, p_ff * p_light * (1.0 - emit_share), p_ff * p_phase, p_eq * p_light);
}

static void rrv__material_albedo(const rrv_material *mat, rrv_vec3 p, rrv_vec3 n, double albedo[3])
{
    int c;
    if (mat->kind == RRV_MATERIAL_CHECKER) {
        /* Evaluated just below the surface so a plane lying on a lattice
           plane (y = 0) does not flicker between two rows of squares. */
        rrv_vec3 q = rrv__madd(p, n, -1e-4 * mat->checker_scale);
        /* Only the low bit matters; reduced in double first, since a far
           point's floor overflows a long (undefined behaviour). */
        uint32_t parity = rrv__lattice_coord(floor(q.x / mat->checker_scale)) +
                          rrv__lattice_coord(floor(q.y / mat->checker_scale)) +
                          rrv__lattice_coord(floor(q.z / mat->checker_scale));
        const double *a = (parity & 1) ? mat->albedo2 : mat->albedo;
        for (c = 0; c < 3; ++c) albedo[c] = a[c];
    } else {
        for (c = 0; c < 3; ++c) albedo[c] = mat->albedo[c];
    }
}

static double rrv__offset_scale(rrv_vec3 p)
{
    return 1e-6 * (1.0 + fmax(fabs(p.x), fmax(fabs(p.y), fabs(p.z))));
}

/* Radiance scale for light emitted where the refractivity is r_emit and seen
   by the camera: L / eta^2 is invariant along a ray (Ament et al. 2014). */
static double rrv__eta_scale(const rrv__context *ctx, rrv_vec3 p_emit)
{
    double eta;
    if (!ctx->bends) return 1.0;
    eta = 1.0 + rrv__scene_refractivity(ctx->scene, p_emit, NULL);
    return ctx->eta_camera2 / (eta * eta);
}

/* The loop iterations of one straight crossing of every medium at its
   densest rate (refraction events, comb kicks, eikonal steps at 4 times
   their nominal rate for halved steps, 2 for the faces), plus, with
   tracking, the tentative collisions of that crossing at the peak
   majorant. */
static double rrv__crossing_work(const rrv_scene *scene, rrv_integrator integrator, int tracking)
{
    const rrv_settings *st = &scene->settings;
    int comb = rrv__resolve_scheme(st->refraction) == RRV_REFRACTION_COMB, i;
    double crossing = 0;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        const struct rrv__majorant_grid *g = m->majorant;
        double diag = rrv__length(rrv__sub(m->hi, m->lo)), rate = 0;
        if (!g) continue;
        if (!rrv__medium_refracts(m) || integrator == RRV_INTEGRATOR_CLASSIC) {
            rate = 0;
        } else if (integrator == RRV_INTEGRATOR_EIKONAL) {
            rate = 4.0 / rrv__step(scene);
        } else {
            double mu_eta = st->mu_eta > 0 ? st->mu_eta : g->grad_peak / st->bend_tolerance;
            if (comb)
                rate = rrv__maxd(mu_eta, 1.0 / rrv__mind(g->cell.x, rrv__mind(g->cell.y, g->cell.z)));
            else
                rate = mu_eta + (double)g->density_peak * g->sigma_t_max;
        }
        if (tracking) rate += (double)g->density_peak * g->sigma_t_max;
        crossing += 2.0 + rate * diag;
    }
    return crossing;
}

/* The most iterations of the path loop (refraction events, comb kicks,
   eikonal steps, box entries) between two real vertices: 16 straight
   crossings of every medium at its densest rate (a curved ray may run
   longer than a straight one, but not 16 times through everything), at
   most RRV_MAX_SEGMENT_STEPS. Beyond it a ray can only be trapped (total
   internal reflection, an integrator error that closed an orbit) or the
   settings absurd; the path is cut and counted. */
static long rrv__step_bound(const rrv_scene *scene, rrv_integrator integrator)
{
    double bound = 64.0 + 16.0 * rrv__crossing_work(scene, integrator, 0);
    return bound < (double)RRV_MAX_SEGMENT_STEPS ? (long)bound : RRV_MAX_SEGMENT_STEPS;
}

/* The trap bound, in straight crossings of every refracting medium: see
   rrv__trap_length. A measurement build may set another. */
#ifndef RRV__TRAP_CROSSINGS
#define RRV__TRAP_CROSSINGS 2.83
#endif

/* The longest run a ray may make through the refraction supports between
   two vertices (real ones and reflections at faces), bent segment by bent
   segment (rrv__bender.run): RRV__TRAP_CROSSINGS times the sum of the
   refracting media's box diagonals, the longest a straight line can run
   inside them all (it crosses each box once). Past it the ray is taken to
   be trapped and is ended, counted (rrv_render_stats.trapped_paths).
   2.83 is just above 2 sqrt(2): a walk that turns by at most a half
   circle stays below it (BOUNDS says why), so only a ray that circled is
   ended; the bias is that of the leg bound (BOUNDS). */
static double rrv__trap_length(const rrv_scene *scene)
{
    double sum = 0;
    int i;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m)) sum += rrv__length(rrv__sub(m->hi, m->lo));
    }
    return RRV__TRAP_CROSSINGS * sum;
}

/* The most work of one camera path (a pixel sample): its loop iterations
   over all legs plus every tentative collision it and its shadow rays
   sample. Each leg is bounded, but max_depth of them at their bound is no
   bound a user can wait for (1024 legs of 1e7 eikonal steps). The scene's
   term is what the other bounds already allow: at each vertex a leg and a
   shadow ray, each of 64 + 16 crossings (loop and tracking, plus the
   vertex's own iteration) with a collision at every iteration, so it never
   cuts a path they would have let finish; what holds a hostile scene is
   the cap, RRV_MAX_SAMPLE_WORK, which the scenes in scenes/ stay far below
   (BOUNDS). */
static uint64_t rrv__sample_bound(const rrv_scene *scene, rrv_integrator integrator)
{
    double vertices = rrv__maxd((double)scene->settings.max_depth, 0.0) + 1.0;
    double leg = 64.0 + 16.0 * (1.0 + rrv__crossing_work(scene, integrator, 1));
    double bound = vertices * 2.0 * 2.0 * leg;
    return bound < (double)RRV_MAX_SAMPLE_WORK ? (uint64_t)bound : (uint64_t)RRV_MAX_SAMPLE_WORK;
}

/* What a vertex does to light arriving from a direction, for the solver. */
typedef struct rrv__vertex_bsdf {
    int surface;     /* diffuse surface (n, albedo) or medium (g, d_in) */
    rrv_vec3 n;      /* facing the side the path is on */
    double albedo[3];
    double g;
    rrv_vec3 d_in;
} rrv__vertex_bsdf;

/* ---- the classes of curved NEE: face jumps, supports, weak chords -----------
   What every build keeps of curved NEE (the solvers of nee shoot and manifold,
   which RRV_NO_CURVED_NEE leaves out, are in >> 12): the tests that sort a
   path into the class of the estimator that stands for it, the vertex's
   densities, nee AIM, and the light point a curved connection aims at. */

/* A face where the refractivity jumps by more than this is a sharp
   interface to curved connections: shots refract there (Snell, the
   Jacobian through the face, the transmitted share), the manifold walk
   stops there and the forward paths that cross it keep it. A smaller jump
   they treat as smooth: the camera's rays still refract at it (any jump
   above a float's rounding, rrv__is_jump), so a connection misses its
   turn, at most 1e-6 tan(theta) rad, and its reflectance, 2.5e-13 near
   normal incidence; total reflection takes the rays within 0.08 degrees
   of grazing it. A chain's own model is coarser than that (+0.012 %
   against shoot's steps on a plume, RESULTS.md). Such jumps are what a
   field's tail leaves at its box: a hot blob's Gaussian reaches 1.4e-7
   at the face of README's heat caustic box at iorscale 450, which sent
   the default from chains to shoot (2.1x less efficient there) when
   this bound was the rounding of the IOR, RRV__REPORT_JUMP. */
#define RRV__SOLVE_JUMP RRV_SMOOTH_JUMP
/* Jumps above this, a float's rounding of an IOR near 1 (the faces of a
   Luneburg lens, whose IOR meets the ambient one, differ by no more), are
   reported (rrv_medium_face_jumps). */
#define RRV__REPORT_JUMP 1e-7
/* The weak class's bound, in bend tolerances (rrv__weak_chord): 0, exact,
   unless a build sets it (see the manual's weak class). */
#ifndef RRV__WEAK_BEND
#define RRV__WEAK_BEND 0.0
#endif

/* Is a jump of the refractivity across a face (rrv__cross_face's
   face_jump) one that curved connections cannot solve across? */
static int rrv__jump_counts(double jump) { return jump > RRV__SOLVE_JUMP; }

/* Is x inside a refraction support (where rays bend)? */
static int rrv__in_support(const rrv_scene *scene, rrv_vec3 x)
{
    rrv__support_view v;
    rrv__look_along(scene, x, rrv__v3(0.6, 0.48, 0.64), &v);
    return v.inside;
}

/* A bound on how far the straight chord from x along unit d, length len,
   would turn a ray: the integral along it of each majorant cell's bound
   on |grad eta| over the lowest eta in the scene (the ray equation turns
   the direction at |grad_perp eta| / eta per metre). Stops counting once
   the sum passes stop. */
static double rrv__chord_bend(const rrv__context *ctx, rrv_vec3 x, rrv_vec3 d, double len, double stop)
{
    const rrv_scene *scene = ctx->scene;
    const double xs[3] = {x.x, x.y, x.z}, ds[3] = {d.x, d.y, d.z};
    /* a context set up by hand (tests) may leave it 0: the lowest eta allowed */
    double eta_floor = ctx->eta_floor > 0 ? ctx->eta_floor : RRV_MIN_IOR;
    double sum = 0, limit = stop * eta_floor;
    int i;
    for (i = 0; i < scene->medium_count && sum <= limit; ++i) {
        const rrv_medium *m = &scene->media[i];
        const struct rrv__majorant_grid *g = m->majorant;
        double t0 = 0, t1 = DBL_MAX, t, t_end, t_next[3], t_delta[3];
        ptrdiff_t stride[3], idx = 0;
        int cell[3], step[3], a, misses = 0;
        if (!rrv__medium_refracts(m) || !g || !g->grad_max) continue;
        for (a = 0; a < 3; ++a) { /* the grid's box clips the chord */
            const double lo = a == 0 ? g->lo.x : a == 1 ? g->lo.y : g->lo.z;
            const double hi = a == 0 ? g->hi.x : a == 1 ? g->hi.y : g->hi.z;
            if (ds[a] == 0) {
                misses |= xs[a] < lo || xs[a] > hi;
            } else {
                double ta = (lo - xs[a]) / ds[a], tb = (hi - xs[a]) / ds[a];
                if (ta > tb) { double swap = ta; ta = tb; tb = swap; }
                if (ta > t0) t0 = ta;
                if (tb < t1) t1 = tb;
            }
        }
        if (misses) continue;
        t = t0 > 0 ? t0 : 0;
        t_end = t1 < len ? t1 : len;
        if (!(t < t_end)) continue;
        stride[0] = 1;
        stride[1] = g->n[0];
        stride[2] = (ptrdiff_t)g->n[0] * g->n[1];
        for (a = 0; a < 3; ++a) {
            const double lo = a == 0 ? g->lo.x : a == 1 ? g->lo.y : g->lo.z;
            const double cs = a == 0 ? g->cell.x : a == 1 ? g->cell.y : g->cell.z;
            double c = (xs[a] + ds[a] * t - lo) / cs;
            cell[a] = !(c >= 0) ? 0 : c >= g->n[a] - 1 ? g->n[a] - 1 : (int)c;
            idx += stride[a] * cell[a];
            if (ds[a] != 0) {
                step[a] = ds[a] > 0 ? 1 : -1;
                t_next[a] = (lo + (cell[a] + (ds[a] > 0)) * cs - xs[a]) / ds[a];
                t_delta[a] = cs / fabs(ds[a]);
                stride[a] *= step[a];
                if (t_next[a] < t) t_next[a] = t;
            } else {
                step[a] = 0;
                t_next[a] = t_delta[a] = DBL_MAX;
            }
        }
        for (;;) {
            double t_face;
            a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
            t_face = t_next[a] < t_end ? t_next[a] : t_end;
            sum += (double)g->grad_max[idx] * (t_face - t);
            if (t_face >= t_end || sum > limit) break;
            t = t_face;
            cell[a] += step[a];
            if (cell[a] < 0 || cell[a] >= g->n[a]) break;
            idx += stride[a];
            t_next[a] += t_delta[a];
        }
    }
    return sum / eta_floor;
}

/* The class of a connection from x to a point len along unit d (len
   DBL_MAX: the sky in direction d) when the estimators share paths (nee
   shoot and manifold): weak, and left to straight NEE with its ordinary
   MIS, if its straight chord crosses no sharp interface and turns a ray by
   at most RRV__WEAK_BEND bend tolerances (rrv__chord_bend); else curved.
   A chord that touches no support is weak. It is a function of the two
   ends alone, so a forward path between them (not jumped) is sorted the
   same way from its end points. Treating a weak connection as straight is
   an approximation: the path straight NEE stands for is the chord, the
   real one turns by less than the bound, the same order as the bending
   one comb kick leaves out. */
/* The chord's bound on bending (rrv__chord_bend, counted until it passes
   stop) into *bound. A sharp interface on the chord: with sharp NULL
   (shoot's classes) returns 0; else (nee aim, whose bent rays refract
   there as camera rays do, a reflected one being the forward path's) sets
   *sharp and adds the turn Snell's law gives the chord there (a bound of
   the same heuristic kind as the bend's: it sorts, and the forward path
   sorts itself by the same function), 0 only where a face reflects it
   totally. */
static int rrv__chord_bound(const rrv__context *ctx, rrv_vec3 x, rrv_vec3 d, double len, double stop, double *bound,
                            int *sharp)
{
    const rrv_scene *scene = ctx->scene;
    double t = 0, turn = 0;
    int faces;
    rrv__support_view v;
    *bound = 0;
    if (sharp) *sharp = 0;
    rrv__look_along(scene, x, d, &v);
    if (!v.inside && !(v.t_face < len)) return 1;
    /* each support box has at most two faces and a sphere two more along
       a line; more crossings than that are rounding: call it curved */
    for (faces = 0; v.t_face < len - t; ++faces) {
        rrv_vec3 at = rrv__madd(x, d, t + v.t_face);
        double gap = rrv__face_gap(at), before, after;
        if (faces >= 4 * scene->medium_count) return 0;
        before = rrv__scene_refractivity(scene, rrv__madd(at, d, -gap), NULL);
        after = rrv__scene_refractivity(scene, rrv__madd(at, d, gap), NULL);
        if (rrv__jump_counts(fabs(after - before))) {
            int total;
            rrv_vec3 out;
            if (!sharp) return 0;
            out = rrv__refract_at_null_event(d, before, after, v.normal, &total);
            if (total) return 0;
            turn += rrv__length(rrv__cross(d, out));
            *sharp = 1;
        }
        t += v.t_face + gap;
        rrv__look_along(scene, rrv__madd(x, d, t), d, &v);
    }
    *bound = turn + rrv__chord_bend(ctx, x, d, len, stop);
    return 1;
}

static int rrv__weak_chord_bound(const rrv__context *ctx, rrv_vec3 x, rrv_vec3 d, double len, double *bound)
{
    double tolerance = RRV__WEAK_BEND * ctx->scene->settings.bend_tolerance;
    return rrv__chord_bound(ctx, x, d, len, tolerance, bound, NULL) && *bound <= tolerance;
}

static int rrv__weak_chord(const rrv__context *ctx, rrv_vec3 x, rrv_vec3 d, double len)
{
    double bound;
    return rrv__weak_chord_bound(ctx, x, d, len, &bound);
}

/* The class of a forward path from its last vertex x along w0 that ends
   along unit d at len (DBL_MAX: the sky): 0 if its chord is curved; 1 if
   the chord is weak and the path is the chord's near-straight root, the
   one straight NEE stands for (a ray that turns by at most the chord's
   bound leaves within that angle of it); 2 if the chord is weak but the
   path left at a wider angle: another root of the same two ends (a ray
   bent by a lens into a point whose chord only grazes it), which straight
   NEE never samples and curved NEE skips for weak chords: the forward path
   counts it in full, or with shoot and manifold shares it with the rays
   drawn toward strong supports (rrv__cone_nee). */
static int rrv__forward_weak(const rrv__context *ctx, rrv_vec3 x, rrv_vec3 w0, rrv_vec3 d, double len)
{
    double bound;
    if (!rrv__weak_chord_bound(ctx, x, d, len, &bound)) return 0;
    /* the sine of the angle, well conditioned where acos of a dot product
       near 1 is not; 1e-7 rad of slack for the nudges off faces and
       rounding along a path that went straight */
    return rrv__dot(w0, d) > 0 && rrv__length(rrv__cross(w0, d)) <= bound + 1e-7 ? 1 : 2;
}

/* Is a straight connection from x to a light sample one of the paths
   straight NEE stands for when shooting sorts paths into classes, i.e.
   does it stay out of every refraction support? Forward paths make the
   same test. */
static int rrv__straight_allowed(const rrv__context *ctx, rrv_vec3 x, const rrv__light_sample *ls)
{
    if (!ctx->partition) return 1;
    return rrv__weak_chord(ctx, x, ls->wi, ls->dist);
}

static void rrv__vertex_eval(const rrv__vertex_bsdf *v, rrv_vec3 w, double f[3])
{
    int c;
    if (v->surface) {
        double cosw = fmax(0.0, rrv__dot(v->n, w)) * RRV__INV_PI;
        for (c = 0; c < 3; ++c) f[c] = v->albedo[c] * cosw;
    } else {
        f[0] = f[1] = f[2] = rrv__hg_eval(v->g, rrv__dot(v->d_in, w));
    }
}

/* The density of the vertex's own sampling of w (cosine lobe, phase function). */
static double rrv__vertex_pdf(const rrv__vertex_bsdf *v, rrv_vec3 w)
{
    return v->surface ? fmax(0.0, rrv__dot(v->n, w)) * RRV__INV_PI : rrv__hg_eval(v->g, rrv__dot(v->d_in, w));
}

/* The area density with which rrv__pick_area_light names the point y of
   light s from x0, selection included: uniform on a quad or triangle; on
   a sphere the cone's solid-angle density turned into area at y, on the
   cap x0 sees (0 elsewhere: no draw names a point x0 does not see). */
static double rrv__light_area_pdf(const rrv_scene *scene, const rrv_shape *s, rrv_vec3 x0, rrv_vec3 y)
{
    if (s->kind == RRV_SHAPE_SPHERE) {
        rrv_vec3 to_x0 = rrv__sub(x0, y), n = rrv__sub(y, s->center);
        double dist2 = rrv__dot(to_x0, to_x0), facing = rrv__dot(n, to_x0) / s->radius;
        if (!(facing > 0) || !(dist2 > 0)) return 0.0;
        return rrv__emitter_pdf(s, x0, y, n) * facing / (sqrt(dist2) * dist2) * rrv__light_prob(scene, s, scene->emit_share);
    }
    return rrv__light_prob(scene, s, scene->emit_share) / rrv__shape_area(s);
}

/* The light point y the draw names from x0 for a curved connection, its
   normal and its area pdf (selection included); NULL for the sky, and for
   sphere lights unless spheres is set. A quad's or triangle's point is
   uniform in area; a sphere's is where the direction straight NEE draws
   uniformly in the sphere's cone from x0 meets its near side, so that
   one draw names one point whichever class routes it (straight NEE, a
   curved estimator). The estimators divide by pdf_area, and the forward
   paths weigh themselves with rrv__light_area_pdf, the same density. */
static const rrv_shape *rrv__pick_area_light(const rrv_scene *scene, const rrv__light_draw *draw, rrv_vec3 x0,
                                             int spheres, rrv_vec3 *y, rrv_vec3 *ny, double *pdf_area)
{
    int pick = rrv__light_pick(scene, draw);
    const rrv_shape *s;
    if (pick < 0 || pick == scene->light_count) return NULL;
    s = &scene->shapes[scene->lights[pick]];
    if (s->kind == RRV_SHAPE_SPHERE) {
        rrv__light_sample ls;
        if (!spheres || !rrv__sample_light(scene, x0, draw, &ls) || !(ls.dist > 0)) return NULL;
        *y = ls.point;
        *ny = rrv__scale(rrv__sub(ls.point, s->center), 1.0 / s->radius);
        *pdf_area = rrv__light_area_pdf(scene, s, x0, ls.point);
        return *pdf_area > 0 ? s : NULL;
    }
    *y = rrv__area_light_point(s, draw->u1, draw->u2);
    *ny = rrv__normalize(rrv__cross(s->e1, s->e2));
    *pdf_area = rrv__light_prob(scene, s, scene->emit_share) / rrv__shape_area(s);
    return s;
}

/* ---- nee AIM: bent shadow rays aimed at light samples -----------------------------
   Where the two-point problem is not solved (the comb, whose kick points
   move with the ray and have no Jacobi field; or by choice), light is still
   sampled: a point y on a light (rrv__pick_area_light) gives the
   direction w0 from x0 to it, and the shadow ray leaves along w0 bent
   exactly as a camera ray would be (the same comb kicks or eikonal steps,
   its transmittance ratio-tracked chord by chord). If it lands on the front
   of that light, the light's radiance counts. As an estimator this is
   sampling w0 with the solid-angle density pdf(w0) of the straight line
   from x0 along w0 meeting the light (rrv__aim_pdf), a function of w0 alone,
   whatever the bent ray then does; so the power heuristic against the
   vertex's own sampling of w0 is exact, and a forward path that reaches
   the light from x0 along w0 takes the complementary weight (in
   rrv__hit_surface), whether or not its end is where w0's line meets it.
   Unbiased for the discretisation camera rays use, at about the cost of a
   straight shadow ray plus the kicks along it. It does not focus: a ray
   that refraction turns off the light contributes nothing, so caustics of
   small lights come from forward paths, as with nee none; on weak heat
   haze nearly every aimed ray lands, and the estimate is as good as
   straight NEE's without its bias.
   The classes are shoot's, but for sharp interfaces: a weak chord
   (rrv__weak_chord) is straight NEE's; an aimed ray crosses a sharp
   interface as camera rays do, refracted or (with the Fresnel probability,
   or totally) reflected, and a reflected one is the forward path's alone,
   as is a chord that a face would reflect totally; the sky is not aimed
   at. A sphere light's w is straight NEE's draw in its cone
   (rrv__pick_area_light). */


/* Who carries a connection from x0 along unit w over len to a point of
   the light s: 0, straight NEE (a weak chord,
   rrv__weak_chord); 1, nee aim; 2, the forward path alone (the chord
   reflects totally at a sharp interface, or bends too much to be worth
   aiming: RRV__AIM_REACH, sharp faces' turns included). A function of x0
   and w alone (len and s are where w's line meets the light), so a forward
   path computes it for itself. */
static int rrv__aim_class(const rrv__context *ctx, const rrv_shape *s, rrv_vec3 x0, rrv_vec3 w, double len)
{
    double tolerance = RRV__WEAK_BEND * ctx->scene->settings.bend_tolerance;
    /* the light's size across: a sphere's by its disc's area */
    double size = s->kind == RRV_SHAPE_SPHERE ? sqrt(RRV__PI) * s->radius : sqrt(rrv__shape_area(s));
    double reach = RRV__AIM_REACH * size / len, bound;
    int sharp;
    if (!rrv__chord_bound(ctx, x0, w, len, rrv__maxd(reach, tolerance), &bound, &sharp)) return 2;
    if (bound <= tolerance && !sharp) return 0;
    return bound <= reach ? 1 : 2;
}

/* The solid-angle density of nee aim's w toward the light s from x0,
   light choice included: 0 where the line from x0 along unit w misses s.
   Both faces of a quad or triangle count: the point is drawn whatever
   side of s faces x0, and a bent ray aimed at the back may land on the
   front. A sphere's is its cone's (rrv__pick_area_light). *len: how far
   along w the line meets s. */
static double rrv__aim_pdf(const rrv_scene *scene, const rrv_shape *s, rrv_vec3 x0, rrv_vec3 w, double *len)
{
    rrv_vec3 n, rel;
    double n2, facing, t, a, b, cos_y;
    if (s->kind == RRV_SHAPE_SPHERE) {
        rrv_vec3 to_c = rrv__sub(s->center, x0);
        double along = rrv__dot(to_c, w), miss2 = rrv__dot(to_c, to_c) - along * along, r2 = s->radius * s->radius;
        if (!(along > 0) || !(miss2 < r2) || !(rrv__dot(to_c, to_c) > r2)) return 0.0;
        *len = along - sqrt(r2 - miss2);
        return rrv__emitter_pdf(s, x0, x0, w) * rrv__light_prob(scene, s, scene->emit_share);
    }
    n = rrv__cross(s->e1, s->e2);
    n2 = rrv__dot(n, n);
    facing = rrv__dot(n, w);
    if (!(facing != 0) || !(n2 > 0)) return 0.0;
    t = rrv__dot(n, rrv__sub(s->p0, x0)) / facing;
    if (!(t > 0) || !(t < DBL_MAX)) return 0.0;
    rel = rrv__sub(rrv__madd(x0, w, t), s->p0);
    a = rrv__dot(rrv__cross(rel, s->e2), n) / n2;
    b = rrv__dot(rrv__cross(s->e1, rel), n) / n2;
    if (a < 0 || b < 0 || (s->kind == RRV_SHAPE_TRIANGLE ? a + b > 1 : a > 1 || b > 1)) return 0.0;
    cos_y = fabs(facing) / sqrt(n2);
    *len = t;
    return t * t / (rrv__shape_area(s) * cos_y) * rrv__light_prob(scene, s, scene->emit_share);
}

/* The density nee (straight or aimed) draws w with from x0 toward the
   light s, 0 where it leaves w to forward paths: what a
   forward path that reached s from x0 along w weighs itself against. */
static double rrv__aim_forward_pdf(const rrv__context *ctx, const rrv_shape *s, rrv_vec3 x0, rrv_vec3 w)
{
    double len, pdf = rrv__aim_pdf(ctx->scene, s, x0, w, &len);
    return pdf > 0 && rrv__aim_class(ctx, s, x0, w, len) < 2 ? pdf : 0.0;
}

/* nee aim's shadow ray from o along *d, bent as camera rays are: the shape
   index of the first surface it meets (*hit, *d its direction there) and
   the transmittance up to it; -1 where T reaches 0 or the step bound
   (counted as cut), -2 where it leaves the scene or a sharp interface
   reflects it (a path with a specular vertex, the forward path's alone;
   refracted, it goes on, and the Fresnel draw stands for the transmitted
   share as it does for camera rays). */
static int rrv__aim_trace(rrv__context *ctx, rrv_vec3 o, rrv_vec3 *d, rrv__rng *rng, rrv__hit *hit, double T[3])
{
    const rrv_scene *scene = ctx->scene;
    rrv__bender b;
    long steps = 0;
    ++ctx->stats.paths;
    T[0] = T[1] = T[2] = 1.0;
    rrv__bender_start(&b, scene, ctx->eikonal, o);
    for (;;) {
        double segment, reach, Ts[3];
        int has_hit, c, end;
        if (++steps > ctx->step_bound) {
            ++ctx->stats.paths_cut;
            return -1;
        }
        if (b.run > ctx->trap_length) {
            ++ctx->stats.paths_cut;
            ++ctx->stats.trapped_paths;
            return -1;
        }
        if (!b.pending) rrv__plan_segment(&b, scene, o, d, rng);
        segment = b.segment;
        has_hit = rrv__segment_hit(ctx, &b, o, *d, segment, hit);
        if (!has_hit && !(segment < DBL_MAX)) return -2;
        reach = has_hit ? hit->t : segment;
        if (rrv__chord_meets_extinction(scene, o, *d, reach)) {
            rrv__transmittance(ctx, o, *d, reach, rng, Ts);
            for (c = 0; c < 3; ++c) T[c] *= Ts[c];
            if (!rrv__nonzero3(T)) return -1;
        }
        if (has_hit) return hit->shape;
        end = b.end;
        if (end == RRV__END_KICK || end == RRV__END_STEP) ++ctx->stats.events;
        rrv__finish_segment(&b, scene, &o, d, rng);
        if (end == RRV__END_FACE && b.reflected) return -2;
    }
}

/* nee aim from vertex x0 (the section's comment says why it is unbiased). */
static void rrv__aim_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                         const rrv__light_draw *draw, rrv__rng *rng)
{
    const rrv_scene *scene = ctx->scene;
    rrv_vec3 y, ny, w0, d;
    rrv__hit hit;
    double pdf_area, to_y, pdf_aim, pdf_dir, f[3], T[3], k;
    int c, met;
    const rrv_shape *s = rrv__pick_area_light(scene, draw, x0, 1, &y, &ny, &pdf_area);
    (void)pdf_area;
    if (!s) return;
    to_y = rrv__length(rrv__sub(y, x0));
    if (!(to_y > 0)) return;
    w0 = rrv__scale(rrv__sub(y, x0), 1.0 / to_y);
    rrv__vertex_eval(v, w0, f);
    if (!(f[0] > 0 || f[1] > 0 || f[2] > 0)) return;
    if (rrv__aim_class(ctx, s, x0, w0, to_y) != 1) return; /* straight NEE's or the forward path's */
    pdf_aim = rrv__aim_pdf(scene, s, x0, w0, &to_y);
    if (!(pdf_aim > 0) || !(pdf_aim < DBL_MAX)) return; /* y on the light's rim, seen edge-on */
    ++ctx->stats.aim_shots;
    d = w0;
    met = rrv__aim_trace(ctx, x0, &d, rng, &hit, T);
    if (met == -1) return;
    if (met == -2 || &scene->shapes[met] != s || !(rrv__dot(hit.n, d) < 0)) {
        ++ctx->stats.aim_missed;
        return;
    }
    pdf_dir = rrv__vertex_pdf(v, w0);
    k = rrv__power_heuristic(pdf_aim, pdf_dir) / pdf_aim * rrv__eta_scale(ctx, hit.p) * rrv__path_mis(path);
    for (c = 0; c < 3; ++c) path->L[c] += path->beta[c] * f[c] * T[c] * s->L[c] * k;
}

/* ---- the path tracer: camera paths, their vertices, next-event estimation -----
   pbrt-v4's VolPathIntegrator::Li in rrv's terms. A camera path is walked as
   straight segments (rrv__plan_segment), each delta-tracked
   (rrv__refractive_delta_tracking); a segment ends in a real vertex
   (scattering in a medium, a surface), the sky, or a bend. At every real
   vertex light is sampled (rrv__sample_direct_light, pbrt's SampleLd) and
   weighed by MIS against the vertex's own sampling of the next direction,
   or not sampled at all (nee none, bending integrators): then the path
   alone finds the lights and every hit counts in full. */

/* THE CURVED-NEE INTERFACE: all that this section and render (>> 10) reach
   of the solvers of nee shoot and manifold and of their cones (>> 12),
   which come after the tracer because they trace rays with its helpers.
   The rest of curved NEE (the classes, nee aim) is above, in every build.
     rrv__solver_supports_scene  can shoot and manifold solve in every
                                 refracting medium of the scene?
     rrv__solver_setup           a render's cones (shoot, manifold) and chain
                                 (manifold); 0 when out of memory
     rrv__solver_release         frees what setup allocated
     rrv__solver_nee             the curved connection at a vertex: shoot's
                                 or manifold's, then the cones'
     rrv__solver_forward_weight  the MIS weight of a forward path that hits
                                 a light where a solver or a cone stands for
                                 it (weak: its rrv__forward_weak class)
   A build with RRV_NO_CURVED_NEE gets the stubs at the end of >> 12, which
   answer "no curved estimator": no scene is supported, so ctx->shoot and
   ctx->manifold stay 0; setup has nothing to set up, a connection adds
   nothing, and a forward path keeps the weight that no solver and no cone
   shares (1; a weak chord's other root against a cone density of 0). */
static int rrv__solver_supports_scene(const rrv_scene *scene);
static int rrv__solver_setup(rrv__context *ctx);
static void rrv__solver_release(rrv__context *ctx);
static void rrv__solver_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                            const rrv__light_draw *draw, rrv__rng *rng);
static double rrv__solver_forward_weight(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, double pdf_dir,
                                         const rrv_shape *s, rrv_vec3 x, int weak, int jumped, int mirrored);

/* Curved NEE from a vertex (the light point of draw, straight NEE's), or
   the count of vertices that could not. */
static void rrv__curved_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                            const rrv__light_draw *draw, rrv__rng *rng)
{
    if (ctx->shoot || ctx->manifold) rrv__solver_nee(ctx, path, x0, v, draw, rng);
    else if (ctx->aim) rrv__aim_nee(ctx, path, x0, v, draw, rng);
    else if (ctx->partition) ++ctx->stats.solves_unsupported;
}

typedef struct rrv__camera_path {
    rrv__path path;      /* throughput, radiance, spectral MIS, refraction state */
    rrv_vec3 o, d;       /* the straight segment being walked */
    rrv_vec3 vertex;     /* the last real vertex: MIS pdfs are measured from it, not from bends */
    rrv_vec3 w0;         /* the direction sampled there, before any bend (nee shoot retraces it) */
    double prev_pdf;     /* solid-angle pdf of the last sampled direction; 0: camera */
    int depth;           /* real vertices and interface reflections so far */
    int touched, jumped; /* the path from the last vertex: touched, part of it lies in
                            a refraction support; jumped, it crossed a sharp interface
                            (shots never do). Decide which estimators could have made
                            it (nee shoot and manifold) */
    int mirrored;        /* a sharp interface reflected it since the last vertex (nee
                            aim crosses sharp interfaces, but only by refraction) */
    long steps;          /* loop iterations since the last real vertex (work bound) */
    uint64_t work, work_end; /* loop iterations of all legs; the sample is cut when they
                                plus the context's events reach work_end */
} rrv__camera_path;

/* Next-event estimation along a straight shadow ray (pbrt-v4's SampleLd):
   one light sample (draw, shared with curved NEE), its ratio-tracked
   transmittance, the power heuristic against the vertex's own sampling
   (phase function or cosine lobe). */
static void rrv__sample_direct_light(rrv__context *ctx, rrv__path *path, rrv_vec3 x, const rrv__vertex_bsdf *v,
                                     const rrv__light_draw *draw, rrv__rng *rng)
{
    static const double white[3] = {1.0, 1.0, 1.0};
    rrv__light_sample ls;
    const double *tint = white;
    double pdf, T[3], k, w;
    int c;
    if (!ctx->sample_lights || !rrv__sample_light(ctx->scene, x, draw, &ls) || !rrv__straight_allowed(ctx, x, &ls))
        return;
    if (v->surface) {
        pdf = rrv__dot(v->n, ls.wi);
        if (!(pdf > 0)) return;
        pdf *= RRV__INV_PI;
        tint = v->albedo;
    } else {
        pdf = rrv__hg_eval(v->g, rrv__dot(v->d_in, ls.wi));
    }
    rrv__light_transmittance(ctx, x, &ls, rng, T);
    if (!rrv__nonzero3(T)) return;
    if (!v->surface && path->eq.on && ls.dist < DBL_MAX) {
        /* a free flight's vertex on a segment that also takes equiangular samples */
        const rrv_shape *s = &ctx->scene->shapes[ctx->scene->lights[rrv__light_pick(ctx->scene, draw)]];
        w = rrv__equi_vertex_weight(ctx, &path->eq, s, 1, ls.pdf, pdf, draw->emit_share);
    } else {
        w = rrv__power_heuristic(ls.pdf, pdf);
    }
    k = pdf * w / ls.pdf * rrv__eta_scale(ctx, ls.point) * rrv__path_mis(path);
    for (c = 0; c < 3; ++c) path->L[c] += path->beta[c] * tint[c] * T[c] * ls.L[c] * k;
}

/* Records the vertex the path restarts from for the weights of both sides. */
static void rrv__emission_from_vertex(const rrv__context *ctx, rrv__emit_from *from, rrv_vec3 x,
                                      const rrv__vertex_bsdf *v, double *q)
{
    from->on = 1;
    from->surface = v->surface;
    from->x = x;
    from->n = v->n;
    from->n_abs = rrv__v3(fabs(v->n.x), fabs(v->n.y), fabs(v->n.z));
    from->d_in = v->d_in;
    from->g = v->g;
    from->S = rrv__emission_norm(ctx->scene->emitters, from, q);
    from->p_w0 = -1.0;
    from->jumped = 0;
    from->aim = 0;
    from->pick = 1.0;
}

/* One straight piece of a walk from o along d, at most segment long: the
   first surface on it (*has_hit, *hit) and delta tracking up to it. A comb
   chord with nothing to meet (no surface reaches the support, no medium
   with extinction near it), also one that ends at a face, needs no ray
   cast and no tracking: it passes. */
static int rrv__walk_segment(rrv__context *ctx, rrv__path *path, rrv_vec3 o, rrv_vec3 d, double segment,
                             rrv__rng *rng, rrv__hit *hit, int *has_hit, rrv__flight *flight)
{
    if (ctx->comb && path->bender.surface_free && segment < DBL_MAX && !path->bender.support_in_extinction &&
        !rrv__chord_meets_extinction(ctx->scene, o, d, segment)) {
        *has_hit = 0;
        return RRV__FLIGHT_PASSED;
    }
    *has_hit = ctx->bends ? rrv__segment_hit(ctx, &path->bender, o, d, segment, hit)
                          : rrv__intersect_line(ctx->scene, o, d, NULL, DBL_MAX, hit);
    return rrv__refractive_delta_tracking(ctx, path, o, d, *has_hit ? hit->t : segment, rng, flight);
}

/* The aim's MIS weight of direction w (density p_aim) against the
   vertex's own sampling; the forward path's is its complement
   (rrv__emission_forward_weight), both the power heuristic. */
static double rrv__emission_aim_weight(const rrv__emit_from *from, rrv_vec3 w, double p_aim)
{
    return rrv__emission_mis(p_aim, rrv__emission_dir_pdf(from, w));
}

/* The aim of emission NEE (rrv__emission_dir_density says why it is
   unbiased): from the vertex x along w, the path's own walk (segments,
   kicks, bends, faces, delta tracking) with its throughput scaled by
   tint f(w) / p(w) and the MIS weight; the emission its tentative
   collisions meet past r* goes to the path. It ends where the path would
   leave x's estimate: a real collision, a surface, the sky, a sharp face,
   a work bound. */
static void rrv__emission_aim(rrv__context *ctx, rrv__path *path, rrv_vec3 x, rrv_vec3 w, const double tint[3],
                              rrv__rng *rng)
{
    const rrv_scene *scene = ctx->scene;
    rrv__path walk = *path;
    rrv_vec3 o = x, d = w;
    double pdf_dir = rrv__emission_dir_pdf(&path->emit, w), p_aim, k;
    long steps = 0;
    int c;
    if (!(pdf_dir > 0)) return;
    p_aim = rrv__emission_dir_density(scene, &path->emit, w);
    if (!(p_aim > 0) || !(p_aim < DBL_MAX)) return;
    k = pdf_dir * rrv__emission_aim_weight(&path->emit, w, p_aim) / p_aim;
    for (c = 0; c < 3; ++c) {
        walk.beta[c] *= tint[c] * k;
        walk.L[c] = 0.0;
    }
    walk.emit.aim = 1;
    walk.emit.w0 = w;
    rrv__bender_start(&walk.bender, scene, ctx->eikonal, x);
    for (;;) {
        rrv__hit hit;
        rrv__flight flight;
        double segment;
        int has_hit, outcome, end;
        if (++steps > ctx->step_bound || walk.bender.run > ctx->trap_length) break;
        if (!walk.bender.pending) rrv__plan_segment(&walk.bender, scene, o, &d, rng);
        segment = walk.bender.segment;
        outcome = rrv__walk_segment(ctx, &walk, o, d, segment, rng, &hit, &has_hit, &flight);
        if (outcome == RRV__FLIGHT_BENT) {
            o = rrv__madd(o, d, flight.t);
            d = flight.direction;
            continue;
        }
        if (outcome != RRV__FLIGHT_PASSED || has_hit || !(segment < DBL_MAX)) break;
        end = walk.bender.end;
        if (end == RRV__END_KICK || end == RRV__END_STEP) ++ctx->stats.events;
        rrv__finish_segment(&walk.bender, scene, &o, &d, rng);
        if (end == RRV__END_FACE && rrv__jump_counts(walk.bender.face_jump)) break;
    }
    for (c = 0; c < 3; ++c) path->L[c] += walk.L[c];
}

/* Visibility times transmittance of an emission sample's shadow ray. Under
   the default estimator, residual tracking: the ray ends inside the
   emitter, whose dense core the minorant covers, and on
   test/bench/campfire.rrv it lowered the error at equal time (maxdepth
   32, 5.0x -> 5.7x over paths alone; RESULTS.md, 2026-12-05). A scene's
   own choice stands. */
static void rrv__emission_transmittance(rrv__context *ctx, rrv_vec3 x, const rrv__light_sample *ls, rrv__rng *rng,
                                        double T[3])
{
    rrv__hit hit;
    double tmax = ls->dist * (1.0 - 1e-7);
    if (ctx->scene->settings.transmittance != RRV_TRANSMITTANCE_DEFAULT) {
        rrv__light_transmittance(ctx, x, ls, rng, T);
        return;
    }
    ++ctx->stats.paths;
    if (rrv__intersect_scene(ctx->scene, x, ls->wi, tmax, &hit)) {
        T[0] = T[1] = T[2] = 0;
        return;
    }
    rrv__residual_tracking_transmittance(ctx, x, ls->wi, tmax, rng, T);
}

/* Whether x lies in the box of a medium that emits. */
static int rrv__inside_emitter(const rrv_scene *scene, rrv_vec3 x)
{
    int mi;
    for (mi = 0; mi < scene->emitters->count; ++mi) {
        const rrv_medium *e = &scene->media[scene->emitters->grid[mi].medium];
        if (rrv__inside_box(x, e->lo, e->hi)) return 1;
    }
    return 0;
}

/* Records the vertex x for the MIS weight of the emission the path then
   collects, where emission NEE samples from x (returns 1); q as for
   rrv__emission_norm. Scattered inside an emitter's box, the path's own
   collisions find the emission around it in proportion to the
   transmittance, which the samples (drawn by emission and distance only)
   do not: measured on test/bench/campfire.rrv at maxdepth 2, samples from
   such vertices raised the error 1.7x. Leaving them to the path (weight 1
   after such a vertex) is a choice per vertex, so the sum stays unbiased. */
static int rrv__emission_record(const rrv__context *ctx, rrv__path *path, rrv_vec3 x, const rrv__vertex_bsdf *v,
                                double *q)
{
    path->emit.on = 0;
    if (!v->surface && rrv__inside_emitter(ctx->scene, x)) return 0;
    rrv__emission_from_vertex(ctx, &path->emit, x, v, q);
    return 1;
}

/* Next-event estimation toward emissive media (section comment above
   rrv__chord_meets_refraction) from the vertex x that rrv__emission_record
   recorded (q: what it kept for the sampler). */
static void rrv__emission_sample(rrv__context *ctx, rrv__path *path, rrv_vec3 x, const rrv__vertex_bsdf *v,
                                 const double *q, rrv__rng *rng)
{
    static const double white[3] = {1.0, 1.0, 1.0};
    const rrv_scene *scene = ctx->scene;
    rrv__emit_from *from = &path->emit;
    rrv__light_sample ls;
    rrv__coeffs c;
    const rrv_medium *m;
    rrv_vec3 y;
    double u[5], p_nee, p_fwd, pdf_dir, r, T[3], Le[3], k, given = 1.0;
    int mi, ch;
    /* one a statement: the order of evaluation of arguments is unspecified */
    u[0] = rrv__uniform(rng);
    u[1] = rrv__uniform(rng);
    u[2] = rrv__uniform(rng);
    u[3] = rrv__uniform(rng);
    u[4] = rrv__uniform(rng);
    mi = rrv__emitter_sample(scene->emitters, from, q, u, &y);
    if (mi < 0) return;
    m = &scene->media[mi];
    if (ctx->bends && rrv__chord_meets_refraction(scene, x, y)) {
        double r0 = rrv__length(rrv__sub(y, x));
        if (r0 > 0) rrv__emission_aim(ctx, path, x, rrv__scale(rrv__sub(y, x), 1.0 / r0), v->surface ? v->albedo : white, rng);
        return;
    }
    rrv__medium_coeffs(m, y, &c);
    if (!(rrv__max3(c.sigma_a) > 0)) return;
    if (!rrv__emission_densities(ctx, from, mi, y, &c, &p_nee, &p_fwd, &pdf_dir, &r)) return;
    ls.wi = rrv__scale(rrv__sub(y, x), 1.0 / r);
    ls.dist = r;
    rrv__emission_transmittance(ctx, x, &ls, rng, T);
    if (!rrv__nonzero3(T)) return;
    if (ctx->bends) {
        double eta = 1.0 + rrv__scene_refractivity(scene, y, NULL);
        given = ctx->eta_camera2 / (eta * eta);
    }
    rrv__medium_Le(scene, m, y, given, ctx->thermal_scale, Le);
    k = pdf_dir * rrv__emission_mis(p_nee, p_fwd) / (r * r * p_nee) * rrv__path_mis(path);
    {
        const double *tint = v->surface ? v->albedo : white;
        for (ch = 0; ch < 3; ++ch) path->L[ch] += path->beta[ch] * tint[ch] * T[ch] * c.sigma_a[ch] * Le[ch] * k;
    }
}

/* Emission NEE with a draw of its own (rrv__vertex_nee). */
static void rrv__emission_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x, const rrv__vertex_bsdf *v,
                              rrv__rng *rng)
{
    double q[RRV__EMIT_KEEP];
    if (rrv__emission_record(ctx, path, x, v, q)) rrv__emission_sample(ctx, path, x, v, q, rng);
}

/* The emitters' share of a light draw from the vertex that `from` records
   (NULL: one that samples no emission, a scattering inside an emitter's
   box), where they share it with light shapes: the classic integrator
   weighs the two as the emission sampler weighs its blocks, power over
   squared distance (W G of the comment above rrv__emit_cluster_g), W_E S(x)
   against the lights' total weight times the G of a box around them all,
   so that a flame beside a wall takes the wall's samples from a far
   lamp; the refracting integrators keep the scene's share by power, which
   their curved estimators read (rrv__light_prob). Any share below one
   keeps the sum unbiased, as long as the vertex's samples and the
   forward paths from it read the same one. */
static double rrv__vertex_emit_share(const rrv__context *ctx, const rrv__emit_from *from)
{
    const struct rrv__emitters *e = ctx->scene->emitters;
    double mine, theirs, share;
    if (ctx->bends) return ctx->scene->emit_share;
    if (!from) return 0.0;
    mine = e->power * from->S;
    theirs = e->lights.weight * rrv__emit_cluster_g(&e->lights, from);
    share = mine > 0 ? mine / (mine + theirs) : 0.0;
    /* the lights keep a sliver, so that their densities stay finite */
    return share < 1.0 - 1e-9 ? share : 1.0 - 1e-9;
}

/* The emitters' share of the light draw of a scattering vertex at x
   (rrv__vertex_nee), for the equiangular technique's weights. */
static double rrv__point_emit_share(const rrv__context *ctx, rrv_vec3 x)
{
    rrv__emit_from at;
    if (!ctx->emission || !(ctx->scene->emit_share > 0)) return 0.0;
    if (ctx->bends) return ctx->scene->emit_share;
    if (rrv__inside_emitter(ctx->scene, x)) return 0.0;
    memset(&at, 0, sizeof at);
    at.x = x;
    at.S = rrv__emission_norm(ctx->scene->emitters, &at, NULL);
    return rrv__vertex_emit_share(ctx, &at);
}

/* A real vertex's next-event estimation: one light draw, taken by straight
   NEE and, where paths are sorted into classes, by curved NEE. Without
   light sampling (nee none) nothing is drawn. */
static void rrv__vertex_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x, const rrv__vertex_bsdf *v, rrv__rng *rng)
{
    rrv__light_draw draw;
    if (!ctx->sample_lights) return;
    /* the light sample's draws vary in count (shadow walks, solver trials):
       streams of their own keep the vertex's direction at fixed dimensions */
    rng->stream = RRV__STREAM_LIGHT;
    if (ctx->emission && !ctx->partition && rrv__light_pick_none(ctx->scene)) {
        /* no light to draw (fire alone lights the scene): the emitters'
           pick takes the first pair, and three numbers go unhashed */
        rng->next[RRV__STREAM_LIGHT] = 0;
        rrv__emission_nee(ctx, path, x, v, rng);
        rng->stream = RRV__STREAM_DIRECTION;
        return;
    }
    /* the light's choice takes the second coordinate of the first pair, so
       that the point on it gets the second pair whole */
    rng->next[RRV__STREAM_LIGHT] = 1;
    rrv__draw_light(rng, &draw);
    path->emit_share = 0.0;
    if (ctx->emission && ctx->scene->emit_share > 0) {
        /* one draw for the light shapes and the emitters (rrv__light_pick):
           the vertex is recorded either way, since the emission the path
           collects weighs itself against the chance the draw had, as the
           light it hits does (path->emit_share) */
        double q[RRV__EMIT_KEEP];
        int recorded = rrv__emission_record(ctx, path, x, v, q);
        draw.emit_share = path->emit_share = rrv__vertex_emit_share(ctx, recorded ? &path->emit : NULL);
        if (recorded) path->emit.pick = draw.emit_share;
        if (draw.u < draw.emit_share) {
            if (recorded) rrv__emission_sample(ctx, path, x, v, q, rng);
            rng->stream = RRV__STREAM_DIRECTION;
            return;
        }
    }
    rrv__sample_direct_light(ctx, path, x, v, &draw, rng);
    if (ctx->partition) rrv__curved_nee(ctx, path, x, v, &draw, rng);
    if (ctx->emission && !(ctx->scene->emit_share > 0)) rrv__emission_nee(ctx, path, x, v, rng);
    rng->stream = RRV__STREAM_DIRECTION;
}

/* The equiangular technique (C in the section comment above
   rrv__light_centre) on the segment eq, for a path whose throughput and
   spectral ratios were beta and ratio where the segment began: a light
   shape picked as NEE picks, a distance toward its centre, its light
   sampled from there, both legs' transmittance tracked. */
static void rrv__equiangular_sample(rrv__context *ctx, rrv__path *path, const double beta[3], const double ratio[3],
                                    const rrv__equi *eq, rrv__rng *rng)
{
    const rrv_scene *scene = ctx->scene;
    const rrv_medium *m = &scene->media[eq->medium];
    const rrv_shape *s;
    rrv__light_draw draw;
    rrv__light_sample ls;
    rrv__coeffs co;
    rrv_vec3 x;
    double u, t, p_eq, phase, T_in[3], T_out[3], k;
    int pick, ch;
    rrv__draw_light(rng, &draw);
    u = rrv__uniform(rng);
    pick = rrv__light_pick(scene, &draw);
    if (pick < 0 || pick >= scene->light_count) return;
    s = &scene->shapes[scene->lights[pick]];
    if (!rrv__equi_aims_at(ctx, s, m) || !rrv__equi_sample(eq, rrv__light_centre(s), u, &t, &p_eq)) return;
    x = rrv__madd(eq->o, eq->d, t);
    rrv__medium_coeffs(m, x, &co);
    if (!(rrv__max3(co.sigma_s) > 0) || !rrv__sample_light(scene, x, &draw, &ls)) return;
    phase = rrv__hg_eval(m->g, rrv__dot(eq->d, ls.wi));
    rrv__transmittance(ctx, eq->o, eq->d, t, rng, T_in);
    if (!rrv__nonzero3(T_in)) return;
    rrv__light_transmittance(ctx, x, &ls, rng, T_out);
    if (!rrv__nonzero3(T_out)) return;
    /* this pick never goes to the emitters, a vertex's at x would with
       the share there */
    k = phase * rrv__equi_own_weight(ctx, eq, rrv__light_centre(s), t, ls.pdf, phase, rrv__point_emit_share(ctx, x)) /
        (p_eq * ls.pdf) * 3.0 / (ratio[0] + ratio[1] + ratio[2]);
    for (ch = 0; ch < 3; ++ch) path->L[ch] += beta[ch] * T_in[ch] * co.sigma_s[ch] * T_out[ch] * ls.L[ch] * k;
}

static void rrv__equiangular_nee(rrv__context *ctx, rrv__path *path, const double beta[3], const double ratio[3],
                                 const rrv__equi *eq, rrv__rng *rng)
{
    /* its own stream: its draws then move none of the path's dimensions */
    rng->stream = RRV__STREAM_EQUIANGULAR;
    rrv__equiangular_sample(ctx, path, beta, ratio, eq, rng);
    rng->stream = RRV__STREAM_DIRECTION;
}

/* What every real vertex does once its light is sampled and its next
   direction chosen: the path restarts there, straight. */
static void rrv__restart_at_vertex(rrv__context *ctx, rrv__camera_path *cp, rrv_vec3 x)
{
    cp->o = cp->vertex = x;
    cp->w0 = cp->path.emit.w0 = cp->d;
    cp->path.emit.p_w0 = -1.0;
    cp->path.emit.jumped = 0;
    cp->steps = 0;
    if (ctx->bends) rrv__bender_restart(&cp->path.bender, ctx->scene, x);
    if (ctx->partition) {
        cp->touched = rrv__in_support(ctx->scene, x);
        cp->jumped = cp->mirrored = 0;
    }
}

/* Scattering in a medium at x: light sampled, the phase function sampled.
   Returns 0 when the path ends. */
static int rrv__scatter_in_medium(rrv__context *ctx, rrv__camera_path *cp, rrv_vec3 x, double g, rrv__rng *rng)
{
    rrv__vertex_bsdf vb;
    rrv_vec3 d_in = cp->d;
    if (++cp->depth > ctx->scene->settings.max_depth) return 0;
    memset(&vb, 0, sizeof vb);
    vb.g = g;
    vb.d_in = d_in;
    rrv__vertex_nee(ctx, &cp->path, x, &vb, rng);
    {
        /* two statements: C leaves the order of arguments unspecified,
           and gcc and clang once drew these in opposite orders */
        double u2 = rrv__uniform(rng), u1 = rrv__uniform(rng);
        cp->d = rrv__hg_sample(g, d_in, u1, u2);
    }
    cp->prev_pdf = rrv__hg_eval(g, rrv__dot(d_in, cp->d));
    rrv__restart_at_vertex(ctx, cp, x);
    return 1;
}

/* The path leaves every medium and surface: the sky's radiance, weighed by
   MIS against sampling the sky as a light. */
static void rrv__escape_to_sky(rrv__context *ctx, rrv__camera_path *cp)
{
    const rrv_scene *scene = ctx->scene;
    double Le[3], w = 1.0, k;
    int c;
    if (scene->environment.kind == RRV_ENV_NONE) return;
    rrv__environment_L(&scene->environment, cp->d, Le);
    if (cp->prev_pdf > 0 && ctx->sample_lights &&
        (!(ctx->partition && cp->touched) ||
         (!cp->jumped && rrv__forward_weak(ctx, cp->vertex, cp->w0, cp->d, DBL_MAX) == 1)))
        w = rrv__power_heuristic(cp->prev_pdf, RRV__INV_4PI * rrv__light_prob(scene, NULL, cp->path.emit_share));
    k = w * rrv__eta_scale(ctx, rrv__madd(cp->o, cp->d, 1e30)) * rrv__path_mis(&cp->path);
    for (c = 0; c < 3; ++c) cp->path.L[c] += cp->path.beta[c] * Le[c] * k;
}

/* A surface hit: its emission (weighed by MIS against the light sample
   that could have found it), then a diffuse bounce with light sampled.
   Returns 0 when the path ends. */
static int rrv__hit_surface(rrv__context *ctx, rrv__camera_path *cp, const rrv__hit *hit, rrv__rng *rng)
{
    const rrv_scene *scene = ctx->scene;
    const rrv_shape *s = &scene->shapes[hit->shape];
    rrv_vec3 n = hit->n, x = hit->p, p;
    rrv__vertex_bsdf vb;
    int front = rrv__dot(n, cp->d) < 0, c;
    if ((s->L[0] > 0 || s->L[1] > 0 || s->L[2] > 0) && front) {
        double w = 1.0;
        if (cp->prev_pdf > 0 && ctx->sample_lights && ctx->aim && cp->touched && !cp->mirrored) {
            /* nee aim draws w0 toward this light with a density the path's
               end does not change: the light's straight crossing along w0
               (rrv__aim_nee). A weak chord's path is that straight line, so
               this is the straight NEE's weight there too. Aimed rays
               refract at sharp interfaces as this path did; one that a
               face reflected is this path's alone (weight 1, below). */
            w = rrv__power_heuristic(cp->prev_pdf, rrv__aim_forward_pdf(ctx, s, cp->vertex, cp->w0));
        } else if (cp->prev_pdf > 0 && ctx->sample_lights) {
            double to_x = rrv__length(rrv__sub(x, cp->vertex));
            /* Sorted by its chord even where it crossed a sharp face: a
               weak chord's other roots are the cones' (rrv__cone_trace
               counts them refracted at faces, as this path was), so such
               a path takes the cones' complement, not weight 1 or
               shoot's (test_weak_roots_across_glass: manifold +10 %,
               shoot -1.5 % before). A face that reflected it made a path
               no estimator but this one draws. */
            int weak = ctx->partition && cp->touched && !cp->mirrored && to_x > 0
                           ? rrv__forward_weak(ctx, cp->vertex, cp->w0, rrv__scale(rrv__sub(x, cp->vertex), 1.0 / to_x),
                                               to_x)
                           : 0;
            if (!(ctx->partition && cp->touched) || weak == 1)
                w = rrv__equi_vertex_weight(
                    ctx, &cp->path.eq, s, 0,
                    rrv__emitter_pdf(s, cp->vertex, x, n) * rrv__light_prob(scene, s, cp->path.emit_share),
                    cp->prev_pdf, cp->path.emit_share);
            else
                w = rrv__solver_forward_weight(ctx, cp->vertex, cp->w0, cp->prev_pdf, s, x, weak, cp->jumped,
                                               cp->mirrored);
        }
        w *= rrv__eta_scale(ctx, x) * rrv__path_mis(&cp->path);
        for (c = 0; c < 3; ++c) cp->path.L[c] += cp->path.beta[c] * s->L[c] * w;
    }
    cp->path.eq.on = 0; /* a surface vertex: no equiangular technique reaches its light */
    if (++cp->depth > scene->settings.max_depth) return 0;
    if (!front) n = rrv__scale(n, -1.0);
    p = rrv__madd(x, n, rrv__offset_scale(x));
    memset(&vb, 0, sizeof vb);
    vb.surface = 1;
    vb.n = n;
    rrv__material_albedo(&scene->materials[s->material], x, n, vb.albedo);
    rrv__vertex_nee(ctx, &cp->path, p, &vb, rng);
    {
        double u2 = rrv__uniform(rng), u1 = rrv__uniform(rng); /* in this order on every compiler */
        cp->d = rrv__sample_cosine_hemisphere(n, u1, u2);
    }
    cp->prev_pdf = fmax(rrv__dot(n, cp->d), 0.0) * RRV__INV_PI;
    if (!(cp->prev_pdf > 0)) return 0;
    for (c = 0; c < 3; ++c) cp->path.beta[c] *= vb.albedo[c];
    rrv__restart_at_vertex(ctx, cp, p);
    return 1;
}

/* Russian roulette after three real vertices, on the MIS-weighted
   throughput, except at a vertex inside a medium that emits (in_emitter):
   there a path the roulette kept would carry a throughput raised toward 1
   into the flame's own radiance, a firefly as rare and as bright as those
   that weighing the albedo removed (rrv__refractive_delta_tracking);
   unrouletted, the weights keep falling by the albedo at every collision
   and the roulette at the first vertex outside ends the path. Returns 0
   when the path ends. */
static int rrv__russian_roulette(rrv__camera_path *cp, int in_emitter, rrv__rng *rng)
{
    int c;
    if (cp->depth >= 3 && !in_emitter) {
        double q = rrv__max3(cp->path.beta) * rrv__path_mis(&cp->path);
        if (q < 1.0) {
            if (rrv__uniform(rng) >= q) return 0;
            for (c = 0; c < 3; ++c) cp->path.beta[c] /= q;
        }
    }
    return rrv__max3(cp->path.beta) > 0;
}

/* One camera path from o along d; its radiance into L. */
static void rrv__trace_path(rrv__context *ctx, rrv_vec3 o, rrv_vec3 d, rrv__rng *rng, double L[3])
{
    const rrv_scene *scene = ctx->scene;
    rrv__camera_path cp;
    int c;
    cp.o = cp.vertex = o;
    cp.d = cp.w0 = d;
    cp.prev_pdf = 0;
    cp.depth = 0;
    cp.touched = cp.jumped = cp.mirrored = 0;
    cp.steps = 0;
    cp.work = 0;
    cp.work_end = ctx->stats.events + ctx->sample_bound;
    rrv__path_start(&cp.path, rng);
    rrv__sampler_bounce(rng); /* the camera's numbers are bounce 0's */
    cp.path.bender.run = 0; /* the trap bound's test reads it without a bender too */
    if (ctx->bends) rrv__bender_start(&cp.path.bender, scene, ctx->eikonal, o);
    ++ctx->stats.paths;
    for (;;) {
        rrv__hit hit;
        rrv__flight flight;
        rrv__equi seg;
        double segment = DBL_MAX; /* a straight piece of the (bent) ray */
        double beta[3], ratio[3]; /* the path's where the segment begins (equiangular) */
        int has_hit, outcome;
        if (++cp.steps > ctx->step_bound) {
            ++ctx->stats.paths_cut;
            break;
        }
        if (cp.path.bender.run > ctx->trap_length) {
            ++ctx->stats.paths_cut;
            ++ctx->stats.trapped_paths;
            break;
        }
        if (++cp.work + ctx->stats.events > cp.work_end) {
            ++ctx->stats.paths_cut;
            ++ctx->stats.cut_samples;
            break;
        }
        /* the next straight segment */
        if (ctx->bends) {
            if (!cp.path.bender.pending) rrv__plan_segment(&cp.path.bender, scene, cp.o, &cp.d, rng);
            segment = cp.path.bender.segment;
        }
        memcpy(beta, cp.path.beta, sizeof beta);
        memcpy(ratio, cp.path.ratio, sizeof ratio);
        outcome = rrv__walk_segment(ctx, &cp.path, cp.o, cp.d, segment, rng, &hit, &has_hit, &flight);
        if (ctx->equiangular && outcome != RRV__FLIGHT_CUT) {
            /* the segment is whole (free flights stop the path on it, not the
               segment): its samples take the path as it was when it began */
            rrv__equi_segment(ctx, cp.o, cp.d, has_hit ? hit.t : DBL_MAX, &seg);
            if (seg.on && cp.depth < scene->settings.max_depth)
                rrv__equiangular_nee(ctx, &cp.path, beta, ratio, &seg, rng);
            if (outcome == RRV__FLIGHT_SCATTERED) {
                cp.path.eq = seg;
                cp.path.eq.t = flight.t;
            }
        }
        if (outcome == RRV__FLIGHT_ABSORBED) break;
        if (outcome == RRV__FLIGHT_CUT) {
            ++ctx->stats.paths_cut;
            ++ctx->stats.cut_tracking;
            break;
        }
        if (outcome == RRV__FLIGHT_PASSED && !has_hit && segment < DBL_MAX) {
            /* the segment's end: a comb kick, an eikonal step, a face */
            int end = cp.path.bender.end;
            if (end == RRV__END_KICK || end == RRV__END_STEP) ++ctx->stats.events;
            rrv__finish_segment(&cp.path.bender, scene, &cp.o, &cp.d, rng);
            /* the jump crossing the face looked up (rrv__face_jumps would
               look up the same two refractivities again) */
            if (end == RRV__END_FACE && rrv__jump_counts(cp.path.bender.face_jump)) {
                cp.path.emit.jumped = 1;
                if (ctx->partition) {
                    cp.jumped = 1;
                    cp.mirrored |= cp.path.bender.reflected;
                }
            }
            if (ctx->partition) cp.touched = 1;
            /* Chords with nothing to meet (no surface reaches the support,
               no medium with extinction near them) go from kick to kick
               here: delta tracking and the ray cast would find nothing. */
            while (ctx->comb && cp.path.bender.pending && cp.path.bender.end == RRV__END_KICK &&
                   cp.path.bender.surface_free && cp.steps < ctx->step_bound &&
                   cp.path.bender.run <= ctx->trap_length &&
                   !cp.path.bender.support_in_extinction && cp.work + ctx->stats.events < cp.work_end &&
                   !rrv__chord_meets_extinction(scene, cp.o, cp.d, cp.path.bender.segment)) {
                ++cp.steps;
                ++cp.work;
                ++ctx->stats.events;
                rrv__finish_segment(&cp.path.bender, scene, &cp.o, &cp.d, rng);
            }
            /* A reflection at an interface is a specular vertex of the path
               and counts toward its depth: light trapped by total internal
               reflection in a lossless box would otherwise bounce forever. */
            if (end == RRV__END_FACE && cp.path.bender.reflected && ++cp.depth > scene->settings.max_depth) break;
            continue;
        }
        if (outcome == RRV__FLIGHT_BENT) {
            /* a null event refracted (Poisson, midpoint): a new segment */
            cp.touched = 1;
            cp.o = rrv__madd(cp.o, cp.d, flight.t);
            cp.d = flight.direction;
            continue;
        }
        if (outcome == RRV__FLIGHT_SCATTERED) {
            if (!rrv__scatter_in_medium(ctx, &cp, rrv__madd(cp.o, cp.d, flight.t), flight.medium->g, rng)) break;
        } else if (!has_hit) {
            rrv__escape_to_sky(ctx, &cp);
            break;
        } else {
            if (!rrv__hit_surface(ctx, &cp, &hit, rng)) break;
        }
        if (!rrv__russian_roulette(&cp, outcome == RRV__FLIGHT_SCATTERED && rrv__medium_emits(flight.medium), rng))
            break;
        rrv__sampler_bounce(rng);
    }
    for (c = 0; c < 3; ++c) L[c] = cp.path.L[c];
}


/* >> 10 render: preparing a scene, rendering rectangles, tracing one ray ===== */

/* ---- preparing a scene and rendering rectangles --------------------------------- */

/* Frees what rrv_scene_prepare built and takes its bytes back out of
   scene->bytes, so that preparing again accounts only once. */
static void rrv__scene_release_prepared(rrv_scene *scene)
{
    int i;
    if (!scene) return;
    if (scene->bvh)
        scene->bytes -= (size_t)(2 * scene->shape_count) * sizeof(rrv__bvh_node) +
                        (size_t)scene->shape_count * sizeof(int);
    if (scene->lights) scene->bytes -= (size_t)scene->light_count * sizeof(int);
    if (scene->light_cdf) scene->bytes -= (size_t)rrv__light_choices(scene) * sizeof(double);
    for (i = 0; i < scene->medium_count; ++i) {
        struct rrv__majorant_grid *g = scene->media[i].majorant;
        if (g) {
            int k;
            scene->bytes -= g->bytes;
            for (k = 0; k < RRV__FIELD_KINDS; ++k) RRV_FREE(g->baked[k].grid.data);
            RRV_FREE(g->refraction.data);
            RRV_FREE(g->cubic);
            RRV_FREE(g->density_max);
            RRV_FREE(g->near_flat);
            RRV_FREE(g);
            scene->media[i].majorant = NULL;
        }
    }
    if (scene->emitters) {
        scene->bytes -= scene->emitters->bytes;
        rrv__emitters_free(scene->emitters);
        scene->emitters = NULL;
    }
    if (scene->blackbody) {
        scene->bytes -= sizeof *scene->blackbody;
        RRV_FREE(scene->blackbody);
        scene->blackbody = NULL;
    }
    RRV_FREE(scene->bvh);
    RRV_FREE(scene->bvh_prims);
    RRV_FREE(scene->lights);
    RRV_FREE(scene->light_cdf);
    scene->bvh = NULL;
    scene->bvh_prims = NULL;
    scene->lights = NULL;
    scene->light_cdf = NULL;
    scene->emit_share = 0.0;
    scene->bvh_node_count = scene->light_count = 0;
    scene->prepared = 0;
}

/* The least value a field of the gas state can take in a medium's box:
   blobs by rrv__field_lower, which places each at its nearest or farthest
   point of the box (summing the weights alone would refuse two cold spots
   far apart), every other kind by the range of its values. */
static double rrv__gas_field_least(const rrv_medium *m, const rrv_field *f, double ambient)
{
    double lo, hi;
    if (f->kind == RRV_FIELD_BLOBS) return rrv__field_lower(f, m->lo, m->hi);
    rrv__field_range(f, ambient, &lo, &hi);
    return lo;
}

/* The gas relation divides by T and scales by P: a medium whose IOR comes
   from its gas state needs both above 0 throughout its box. Checked before
   the IOR's range, which would otherwise report the pole at T = 0 as an IOR
   of thousands and take a negative pressure for a plausible IOR below 1. */
static rrv_result rrv__check_gas_state(const rrv_scene *scene, const rrv_medium *m, rrv_error *err)
{
    static const char *const stmt[2] = {"temperature", "pressure"};
    double least[2];
    int k;
    if (!m->ior_from_gas) return RRV_OK;
    least[0] = (rrv__gas_field_least(m, &m->temperature, m->temperatureoffset + m->T_ref / m->temperaturescale) -
                m->temperatureoffset) * m->temperaturescale;
    least[1] = rrv__gas_field_least(m, &m->pressure, m->P_ref);
    for (k = 0; k < 2; ++k) {
        int at = 2 + k;
        const char *unit = k ? "Pa" : "K";
        if (least[k] > 0) continue;
        if (m->source[at][0])
            return rrv__fail(err, m->line[at] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[at],
                             "%s: grid \"%s\" gives medium \"%s\" a %s down to %g %s; its IOR comes from the gas, "
                             "which needs it above 0", stmt[k], m->source[at], m->name, stmt[k], least[k], unit);
        return rrv__fail(err, m->line[at] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[at],
                         "%s: medium \"%s\" may reach a %s of %g %s; its IOR comes from the gas, which needs it "
                         "above 0", stmt[k], m->name, stmt[k], least[k], unit);
    }
    return RRV_OK;
}

/* The limits of BOUNDS for one medium, with the scene line of the statement
   that broke each (the later of the lines involved). */
static rrv_result rrv__check_medium(const rrv_scene *scene, const rrv_medium *m, rrv_error *err)
{
    static const char *const stmt[5] = {"medium", "density", "temperature", "pressure", "ior"};
    double a, b;
    int c, at;
    rrv_result gas;
    for (c = 0; c < 3; ++c)
        if (!((m->sigma_a[c] + m->sigma_s[c]) * m->scale <= DBL_MAX))
            return rrv__fail(err, m->line[0] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[0],
                             "medium: (sigma_a + sigma_s) times scale is not finite");
    if (!rrv__medium_emission_ok(m))
        return rrv__fail(err, m->line[0] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[0], "medium: Le times Lescale must be at most %g",
                         RRV_MAX_RADIANCE);
    if (!rrv__medium_extinction_ok(m, &a)) {
        at = m->line[1] > m->line[0] ? 1 : 0;
        if (m->source[at][0])
            return rrv__fail(err, m->line[at] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[at],
                             "%s: grid \"%s\" gives medium \"%s\" an extinction of %g /m, over its %g m an "
                             "optical depth above the %g rrv accepts",
                             stmt[at], m->source[at], m->name, a, rrv__medium_size(m), RRV_MAX_OPTICAL_DEPTH);
        return rrv__fail(err, m->line[at] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[at],
                         "%s: medium \"%s\" reaches an extinction of %g /m, over its %g m an optical depth "
                         "above the %g rrv accepts",
                         stmt[at], m->name, a, rrv__medium_size(m), RRV_MAX_OPTICAL_DEPTH);
    }
    gas = rrv__check_gas_state(scene, m, err);
    if (gas != RRV_OK) return gas;
    if (!rrv__medium_ior_ok(m, &a, &b)) {
        at = 4;
        if (m->ior_from_gas) {
            if (m->line[2] > m->line[at]) at = 2;
            if (m->line[3] > m->line[at]) at = 3;
        }
        if (m->source[at][0])
            return rrv__fail(err, m->line[at] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[at],
                             "%s: grid \"%s\" gives medium \"%s\" an IOR from %g to %g; it must stay within "
                             "[%g, %g]", stmt[at], m->source[at], m->name, a, b, RRV_MIN_IOR, RRV_MAX_IOR);
        return rrv__fail(err, m->line[at] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, scene->path, m->line[at],
                         "%s: medium \"%s\" gets an IOR from %g to %g; it must stay within [%g, %g]", stmt[at],
                         m->name, a, b, RRV_MIN_IOR, RRV_MAX_IOR);
    }
    return RRV_OK;
}

static rrv_result rrv__scene_check(rrv_scene *scene, rrv_error *err); /* building scenes section, next */

RRV_DEF rrv_result rrv_scene_prepare(rrv_scene *scene, rrv_error *err)
{
    rrv_result res;
    int i, n = 0;
    rrv__clear_error(err);
    if (!scene) return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "no scene");
    rrv__scene_release_prepared(scene);
    if (scene->medium_count > RRV__MAX_MEDIA)
        return rrv__fail(err, RRV_ERROR_LIMIT, scene->path, 0, "%d media; at most %d are supported",
                         scene->medium_count, RRV__MAX_MEDIA);
    /* The parser refused all of this with a line; scenes built or edited in
       code get the same refusals here (the building scenes section: the checks). */
    res = rrv__scene_check(scene, err);
    if (res != RRV_OK) return res;
    scene->ambient_ior = rrv__resolve_ambient(scene);
    for (i = 0; i < scene->medium_count; ++i) {
        res = rrv__check_medium(scene, &scene->media[i], err);
        if (res != RRV_OK) return res;
    }
    for (i = 0; i < scene->shape_count; ++i) {
        const double *L = scene->shapes[i].L;
        if (!(rrv__max3(L) <= RRV_MAX_RADIANCE))
            return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0, "shape %d emits above %g", i,
                             RRV_MAX_RADIANCE);
        if (L[0] > 0 || L[1] > 0 || L[2] > 0) ++n;
    }
    if (n) {
        scene->lights = (int *)RRV_MALLOC((size_t)n * sizeof(int));
        if (!scene->lights) return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
        for (i = 0; i < scene->shape_count; ++i) {
            const double *L = scene->shapes[i].L;
            if (L[0] > 0 || L[1] > 0 || L[2] > 0) scene->lights[scene->light_count++] = i;
        }
        scene->bytes += (size_t)n * sizeof(int);
    }
    res = rrv__build_bvh(scene, err);
    if (res != RRV_OK) return res;
    for (i = 0; i < scene->medium_count; ++i) {
        struct rrv__majorant_grid *g;
        size_t baked = 0;
        res = rrv__build_majorant(scene, &scene->media[i], &baked, err);
        g = scene->media[i].majorant;
        if (g) {
            g->bytes = baked + sizeof *g;
            if (g->density_max)
                g->bytes += (size_t)g->n[0] * g->n[1] * g->n[2] * sizeof(float) *
                            (size_t)(2 + (g->grad_max != NULL) + (g->jacobian_wander != NULL));
            if (g->near_flat) g->bytes += (size_t)g->n[0] * g->n[1] * g->n[2];
            scene->bytes += g->bytes;
        }
        if (res != RRV_OK) { rrv__scene_release_prepared(scene); return res; }
    }
    scene->sharp_faces = scene->sharp_rims = 0;
    for (i = 0; i < scene->medium_count; ++i) {
        double jump[7];
        /* the faces curved connections do not solve across as smooth */
        if (rrv__jump_counts(rrv_medium_face_jumps(scene, i, jump))) scene->sharp_faces = 1;
        if (rrv__jump_counts(jump[6])) scene->sharp_rims = 1;
    }
    res = rrv__build_emitters(scene, err);
    if (res != RRV_OK) { rrv__scene_release_prepared(scene); return res; }
    res = rrv__build_light_cdf(scene, err);
    if (res != RRV_OK) { rrv__scene_release_prepared(scene); return res; }
    for (i = 0; i < scene->medium_count && !(scene->media[i].blackbody_emission && rrv__medium_emits_somewhere(&scene->media[i])); ++i) {}
    if (i < scene->medium_count) {
        scene->blackbody = (struct rrv__blackbody *)RRV_MALLOC(sizeof *scene->blackbody);
        if (!scene->blackbody) {
            rrv__scene_release_prepared(scene);
            return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "out of memory");
        }
        rrv__blackbody_table_fill(scene->blackbody);
        scene->bytes += sizeof *scene->blackbody;
    }
    scene->prepared = 1;
    return RRV_OK;
}

typedef struct rrv__camera_frame {
    rrv_vec3 eye, forward, right, up;
    double tan_half, aspect;
} rrv__camera_frame;

/* The unit vector along v, also where |v|^2 under- or overflows: the
   camera's check accepts any distinct finite eye and look and any nonzero
   finite up, and eye and look 1e-305 apart (a fuzzer's) made a direction
   whose square is 0, which rrv__normalize leaves as it is: every camera
   ray then had a length of 1e-305 and its walks ran to their caps. Such a
   vector is scaled to a largest component of 1 first; others take the
   plain division, bit for bit as before. */
static rrv_vec3 rrv__unit_direction(rrv_vec3 v)
{
    double len = rrv__length(v);
    return len >= 1e-150 && len <= 1e150 ? rrv__scale(v, 1.0 / len) : rrv__normalize(rrv__unit_max(v));
}

static void rrv__camera_setup(const rrv_camera *cam, rrv__camera_frame *f)
{
    f->eye = cam->eye;
    f->forward = rrv__unit_direction(rrv__sub(cam->look, cam->eye));
    f->right = rrv__unit_direction(rrv__cross(f->forward, cam->up));
    f->up = rrv__cross(f->right, f->forward);
    f->tan_half = tan(0.5 * cam->fov * RRV__PI / 180.0);
    f->aspect = (double)cam->width / cam->height;
}

static rrv_vec3 rrv__camera_ray(const rrv__camera_frame *f, const rrv_camera *cam, double px, double py)
{
    double sx = (2.0 * px / cam->width - 1.0) * f->tan_half * f->aspect;
    double sy = (1.0 - 2.0 * py / cam->height) * f->tan_half;
    return rrv__normalize(rrv__add(f->forward, rrv__add(rrv__scale(f->right, sx), rrv__scale(f->up, sy))));
}

/* The jump of the scene's refractivity across a surface at `at`, a few
   rounding gaps to either side along its normal; 0 where it is within the
   rounding of an IOR in float (RRV__REPORT_JUMP). */
static double rrv__jump_at(const rrv_scene *scene, rrv_vec3 at, rrv_vec3 normal)
{
    double gap = 4.0 * rrv__face_gap(at);
    double r_in = rrv__scene_refractivity(scene, rrv__madd(at, normal, -gap), NULL);
    double r_out = rrv__scene_refractivity(scene, rrv__madd(at, normal, gap), NULL);
    return rrv__is_jump(r_in, r_out) && fabs(r_in - r_out) > RRV__REPORT_JUMP ? fabs(r_in - r_out) : 0.0;
}

#define RRV__JUMP_LATTICE 65

RRV_DEF double rrv_medium_face_jumps(const rrv_scene *scene, int medium, double jump[7])
{
    const rrv_medium *m;
    double worst = 0;
    int f, i, j;
    for (f = 0; f < 7; ++f) jump[f] = 0;
    if (!scene || medium < 0 || medium >= scene->medium_count) return 0;
    m = &scene->media[medium];
    if (!rrv__medium_refracts(m)) return 0;
    for (f = 0; f < 6; ++f) {
        int a = f / 2, u = (a + 1) % 3, v = (a + 2) % 3;
        double lo[3], hi[3], n[3] = {0, 0, 0};
        lo[0] = m->lo.x; lo[1] = m->lo.y; lo[2] = m->lo.z;
        hi[0] = m->hi.x; hi[1] = m->hi.y; hi[2] = m->hi.z;
        n[a] = f & 1 ? 1.0 : -1.0;
        for (i = 0; i < RRV__JUMP_LATTICE; ++i)
            for (j = 0; j < RRV__JUMP_LATTICE; ++j) {
                double x[3];
                x[a] = f & 1 ? hi[a] : lo[a];
                /* cell centres: an edge belongs to two faces and to neither's normal */
                x[u] = lo[u] + (hi[u] - lo[u]) * (i + 0.5) / RRV__JUMP_LATTICE;
                x[v] = lo[v] + (hi[v] - lo[v]) * (j + 0.5) / RRV__JUMP_LATTICE;
                jump[f] = rrv__maxd(jump[f], rrv__jump_at(scene, rrv__v3(x[0], x[1], x[2]), rrv__v3(n[0], n[1], n[2])));
            }
    }
    if (rrv__has_sphere_support(m)) {
        const rrv_field *s = &m->ior;
        for (i = 0; i < 2 * (RRV__JUMP_LATTICE - 1); ++i)
            for (j = 0; j < RRV__JUMP_LATTICE - 1; ++j) {
                double phi = 2.0 * RRV__PI * (i + 0.5) / (2.0 * (RRV__JUMP_LATTICE - 1));
                double theta = RRV__PI * (j + 0.5) / (RRV__JUMP_LATTICE - 1);
                rrv_vec3 n = rrv__v3(sin(theta) * cos(phi), cos(theta), sin(theta) * sin(phi));
                rrv_vec3 at = rrv__madd(s->center, n, s->radius);
                if (!rrv__inside_box(at, m->lo, m->hi)) continue;
                jump[6] = rrv__maxd(jump[6], rrv__jump_at(scene, at, n));
            }
    }
    for (f = 0; f < 7; ++f) worst = rrv__maxd(worst, jump[f]);
    return worst;
}

/* The default integrator's light-size threshold: a light whose side (the
   square root of its area; a sphere's disc's) over its distance from a clear
   refracting medium's box centre is below this is small (test/bench/RESULTS.md,
   "Which integrator by default"). */
#define RRV__SMALL_LIGHT 0.7

static int rrv__boxes_overlap(const rrv_medium *a, const rrv_medium *b)
{
    return a->lo.x <= b->hi.x && b->lo.x <= a->hi.x && a->lo.y <= b->hi.y && b->lo.y <= a->hi.y &&
           a->lo.z <= b->hi.z && b->lo.z <= a->hi.z;
}

/* No medium with extinction overlaps m's box: what connects through m
   starts and ends on surfaces. */
static int rrv__medium_clear(const rrv_scene *scene, const rrv_medium *m)
{
    int j;
    for (j = 0; j < scene->medium_count; ++j)
        if (scene->media[j].majorant && !scene->media[j].majorant->empty && rrv__boxes_overlap(m, &scene->media[j]))
            return 0;
    return 1;
}

/* Shooting pays where its solves are few and the light it finds is
   focused: every refracting medium clear (no medium with extinction
   overlaps its box, so the only vertices that connect through it lie on
   surfaces, and the caustic they see is sharp), no sphere support whose
   surface is a jump of the IOR (shots refract at a box's sharp faces, not
   at a sphere's: there aimed shadow rays took an eighth of the time for
   the same noise) and some area light small
   from one of them (aimed shadow rays sample the straight cone of the
   light, which misses the bent rays' preimage once the light's angular
   size falls to the order of the bending). Elsewhere the comb with aimed
   shadow rays is the cheaper unbiased estimator (test/bench/RESULTS.md measures
   both). */
static rrv_integrator rrv__default_integrator(const rrv_scene *scene)
{
    int i, k, refracts = 0, clear = 1, small = 0;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        rrv_vec3 c;
        if (!rrv__medium_refracts(m)) continue;
        refracts = 1;
        if (!rrv__medium_clear(scene, m)) clear = 0;
        c = rrv__scale(rrv__add(m->lo, m->hi), 0.5);
        for (k = 0; k < scene->light_count; ++k) {
            const rrv_shape *l = &scene->shapes[scene->lights[k]];
            double area, d;
            rrv_vec3 at;
            if (l->kind == RRV_SHAPE_QUAD) {
                area = rrv__length(rrv__cross(l->e1, l->e2));
                at = rrv__add(l->p0, rrv__scale(rrv__add(l->e1, l->e2), 0.5));
            } else if (l->kind == RRV_SHAPE_TRIANGLE) {
                area = 0.5 * rrv__length(rrv__cross(l->e1, l->e2));
                at = rrv__add(l->p0, rrv__scale(rrv__add(l->e1, l->e2), 1.0 / 3.0));
            } else {
                area = RRV__PI * l->radius * l->radius; /* its disc, as seen from anywhere */
                at = l->center;
            }
            d = rrv__length(rrv__sub(at, c));
            if (sqrt(area) < RRV__SMALL_LIGHT * d) small = 1;
        }
    }
    if (!refracts) return RRV_INTEGRATOR_CLASSIC;
    if (clear && small && !scene->sharp_rims &&
        (scene->settings.nee == RRV_NEE_DEFAULT || scene->settings.nee == RRV_NEE_SHOOT ||
         scene->settings.nee == RRV_NEE_MANIFOLD) &&
        rrv__solver_supports_scene(scene))
        return RRV_INTEGRATOR_EIKONAL;
    return RRV_INTEGRATOR_REFRACTIVE;
}

/* The default nee's bend bound: a refracting medium's peak |grad eta| times
   its support's diameter (a bound on how far a ray crossing it turns, in
   radians) above which the default shoots rather than solving chains.
   Measured (test/bench/RESULTS.md, "Chains by default on heat caustics"):
   a blob of hot air from 0.38 to 2.56 solves about 2x more efficiently by
   chains, but at 4.3 0.09x, a grid plume at 2.54 0.04x (fireflies both)
   and the Luneburg lens caustic (3) 0.66x; 2 keeps a margin below them. */
#define RRV__CHAIN_BEND 2.0

/* Chains (nee manifold, the paper's method) pay where rays bend weakly and
   connect only on surfaces: eikonal, every refracting medium clear and
   weak (RRV__CHAIN_BEND), no sharp face or rim (chains stop at a jump, and
   shots refract through it; sphere lights are shot at either way,
   rrv__shoots_spheres). Elsewhere SHOOT, which the refractive integrator
   turns into AIM. */
static rrv_nee rrv__default_nee(const rrv_scene *scene, rrv_integrator integrator)
{
    int i;
    if (integrator != RRV_INTEGRATOR_EIKONAL || scene->sharp_faces || scene->sharp_rims ||
        !rrv__solver_supports_scene(scene))
        return RRV_NEE_SHOOT;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        double diameter;
        if (!rrv__medium_refracts(m)) continue;
        if (!m->majorant || !rrv__medium_clear(scene, m)) return RRV_NEE_SHOOT;
        diameter = rrv__has_sphere_support(m) ? 2.0 * m->ior.radius : rrv__length(rrv__sub(m->hi, m->lo));
        if (!((double)m->majorant->grad_peak * diameter <= RRV__CHAIN_BEND)) return RRV_NEE_SHOOT;
    }
    return RRV_NEE_MANIFOLD;
}

RRV_DEF rrv_nee rrv_scene_nee(const rrv_scene *scene)
{
    if (!scene) return RRV_NEE_DEFAULT;
    if (scene->settings.nee != RRV_NEE_DEFAULT) return scene->settings.nee;
    return rrv__default_nee(scene, rrv_scene_integrator(scene));
}

RRV_DEF rrv_integrator rrv_scene_integrator(const rrv_scene *scene)
{
    if (!scene) return RRV_INTEGRATOR_DEFAULT;
    if (scene->settings.integrator != RRV_INTEGRATOR_DEFAULT) return scene->settings.integrator;
    return rrv__default_integrator(scene);
}

/* Without RRV_RESEARCH, the variants that lose every measured row (NOTES,
   BUILD SWITCHES) are refused: why, where settings name one, else NULL. */
static const char *rrv__research_variant(const rrv_settings *s)
{
#ifdef RRV_RESEARCH
    (void)s;
#else
    if (s->refraction == RRV_REFRACTION_MIDPOINT)
        return "refraction midpoint is a research variant, not in this build (define RRV_RESEARCH); "
               "use comb or poisson";
    if (s->stepper == RRV_STEPPER_LEAPFROG)
        return "stepper leapfrog is a research variant, not in this build (define RRV_RESEARCH); use rk4";
#endif
    return NULL;
}

/* rrv_render_rect's arguments: a prepared scene, a rectangle inside its
   image, a stride that holds it, a range of sample indices. */
static rrv_result rrv__render_args_check(const rrv_scene *scene, int x0, int y0, int x1, int y1, int sample_begin,
                                         int sample_end, const float *sum, int stride, rrv_error *err)
{
    const char *research;
    if (!scene || !sum) return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_render_rect: NULL scene or sum");
    if (x0 < 0 || y0 < 0 || x1 > scene->camera.width || y1 > scene->camera.height || x0 > x1 || y0 > y1)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0,
                         "rrv_render_rect: pixels [%d,%d) x [%d,%d) are not inside the %d x %d image", x0,
                         x1, y0, y1, scene->camera.width, scene->camera.height);
    if (stride < x1 - x0)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0,
                         "rrv_render_rect: stride %d is below the rectangle's width %d", stride, x1 - x0);
    if (sample_begin < 0 || sample_begin > sample_end || sample_end > RRV_MAX_SPP)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0,
                         "rrv_render_rect: samples [%d,%d) are not a range of indices in [0, %d)", sample_begin,
                         sample_end, RRV_MAX_SPP);
    if (!scene->prepared)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0,
                         "rrv_render_rect: the scene is not prepared (call rrv_scene_prepare after editing it)");
    /* settings edited after prepare skip its check (rrv__settings_check) */
    if ((research = rrv__research_variant(&scene->settings)) != NULL)
        return rrv__fail(err, RRV_ERROR_UNSUPPORTED, scene->path, 0, "rrv_render_rect: %s", research);
#ifdef RRV_NO_CURVED_NEE
    if (scene->settings.nee == RRV_NEE_SHOOT || scene->settings.nee == RRV_NEE_MANIFOLD)
        return rrv__fail(err, RRV_ERROR_UNSUPPORTED, scene->path, 0,
                         "rrv_render_rect: nee %s is disabled (RRV_NO_CURVED_NEE); use nee aim",
                         scene->settings.nee == RRV_NEE_SHOOT ? "shoot" : "manifold");
#endif
    return RRV_OK;
}

/* The context of one rrv_render_rect call: which integrator and which
   estimators the scene's settings name (and which of them its media
   support), the bounds on work, and the camera. */
static rrv_result rrv__render_context(const rrv_scene *scene, rrv__context *ctx, rrv__camera_frame *frame, rrv_error *err)
{
    rrv_integrator integrator;
    rrv_nee nee;
    double r_camera;
    int i;
    memset(ctx, 0, sizeof *ctx);
    rrv__camera_setup(&scene->camera, frame);
    ctx->scene = scene;
    integrator = rrv_scene_integrator(scene);
    if (integrator == RRV_INTEGRATOR_REFRACTIVE) {
        ctx->comb = rrv__resolve_scheme(scene->settings.refraction) == RRV_REFRACTION_COMB;
        ctx->refract_nulls = !ctx->comb;
    }
    ctx->eikonal = integrator == RRV_INTEGRATOR_EIKONAL;
    ctx->bends = ctx->comb || ctx->refract_nulls || ctx->eikonal;
    ctx->step_bound = rrv__step_bound(scene, integrator);
    /* the schemes that refract at null events keep the leg bound alone
       (BOUNDS: the midpoint scheme's orbits leak out again) */
    ctx->trap_length = ctx->refract_nulls ? DBL_MAX : rrv__trap_length(scene);
    ctx->sample_bound = rrv__sample_bound(scene, integrator);
    /* shoot by default, also where it cannot solve (the refractive
       integrator), where it aims: manifold solves there, but at 100x-1000x
       straight NEE's cost on a scene like scenes/fire.rrv (test/bench/RESULTS.md), while
       aiming stays unbiased at about straight's cost */
    nee = scene->settings.nee != RRV_NEE_DEFAULT ? scene->settings.nee : rrv__default_nee(scene, integrator);
    ctx->sample_lights = !ctx->bends || nee != RRV_NEE_NONE;
    /* By default a draw of their own where no light shape is (there it
       pays: test/bench/campfire.rrv 22x the efficiency at maxdepth 1, 6.3x
       at the default 32; under a night sky, where the power light sampler
       gives it the sky's samples, 15x, 7.3x and 6.9x at maxdepth 1, 2 and
       32 on the lit surfaces), a share of the light shapes' draw beside
       them (rrv__emitters_share_draws): a draw of their own beside an
       area light and a sky (scenes/fire.rrv) cost more than the variance
       it saved (0.46x classic, 0.70x refractive; test/bench/RESULTS.md,
       "Fire as a light"). */
    ctx->emission = ctx->sample_lights && scene->emitters &&
                   (scene->settings.emission_nee == RRV_EMISSION_NEE_ON || scene->emit_share > 0 ||
                    (scene->settings.emission_nee == RRV_EMISSION_NEE_DEFAULT && scene->light_count == 0 &&
                     (scene->environment.kind == RRV_ENV_NONE || rrv__emitters_take_samples(scene))));
    /* Equiangular samples where some light shape can take them: none
       elsewhere, so such scenes render as before, draw for draw. */
    if (!ctx->bends && ctx->sample_lights && scene->settings.equiangular != RRV_EQUIANGULAR_OFF) {
        int l, aims = 0;
        ctx->equiangular = scene->settings.equiangular == RRV_EQUIANGULAR_ON ? 2 : 1;
        for (l = 0; l < scene->light_count; ++l)
            for (i = 0; i < scene->medium_count; ++i)
                aims |= rrv__medium_scatters(&scene->media[i]) &&
                        rrv__equi_aims_at(ctx, &scene->shapes[scene->lights[l]], &scene->media[i]);
        if (!aims) ctx->equiangular = 0;
    }
    /* without a medium that refracts every connection is straight: no
       curved NEE, so such a scene renders as classic does, draw for draw */
    for (i = 0; i < scene->medium_count && !rrv__medium_refracts(&scene->media[i]); ++i) {}
    ctx->partition = ctx->bends && i < scene->medium_count &&
                    (nee == RRV_NEE_SHOOT || nee == RRV_NEE_MANIFOLD || nee == RRV_NEE_AIM);
    ctx->shoot = ctx->partition && nee == RRV_NEE_SHOOT && ctx->eikonal && rrv__solver_supports_scene(scene);
    ctx->manifold = ctx->partition && nee == RRV_NEE_MANIFOLD && rrv__solver_supports_scene(scene);
    /* Where shoot cannot solve (the comb's kicks have no Jacobi field) it
       aims instead: the same classes, unbiased, at straight NEE's cost.
       Aiming needs ray geometry that does not hang on the density (the
       Poisson and midpoint schemes refract at null events): there the
       connections stay with forward paths. */
    ctx->aim = ctx->partition && !ctx->refract_nulls && (nee == RRV_NEE_AIM || (nee == RRV_NEE_SHOOT && !ctx->shoot));
    ctx->eta_floor = rrv__ambient_ior(scene);
    if (ctx->partition) {
        for (i = 0; i < scene->medium_count; ++i) {
            const rrv_medium *m = &scene->media[i];
            double eta_lo = 1, eta_hi = 1;
            if (!rrv__medium_refracts(m)) continue;
            /* a gridvol's range is a scan of the grid, too slow for every
               call (main.c makes one a sample and tile): there the floor is
               1, the comb's own measure (its kick rate leaves eta out) */
            if (m->ior.kind == RRV_FIELD_GRID ||
                (m->ior_from_gas && (m->temperature.kind == RRV_FIELD_GRID || m->pressure.kind == RRV_FIELD_GRID)))
                eta_lo = 1.0;
            else
                rrv__medium_ior_ok(m, &eta_lo, &eta_hi);
            ctx->eta_floor = rrv__mind(ctx->eta_floor, eta_lo);
        }
        ctx->eta_floor = rrv__maxd(ctx->eta_floor, RRV_MIN_IOR);
    }
    if (!rrv__solver_setup(ctx))
        return rrv__fail(err, RRV_ERROR_MEMORY, scene->path, 0, "rrv_render_rect: out of memory for nee manifold's chain");
    r_camera = ctx->bends ? rrv__scene_refractivity(scene, frame->eye, NULL) : 0.0;
    ctx->eta_camera2 = (1.0 + r_camera) * (1.0 + r_camera);
    /* Blackbody radiance B is taken as the ambient air's, so a classic
       render and a refractive one of a fire in air agree exactly. */
    ctx->thermal_scale = ctx->bends ? ctx->eta_camera2 / (rrv__ambient_ior(scene) * rrv__ambient_ior(scene)) : 1.0;
    return RRV_OK;
}

/* Adds one call's counts into the caller's. */
static void rrv__add_render_stats(rrv_render_stats *stats, const rrv_render_stats *from)
{
    stats->samples += from->samples;
    stats->paths += from->paths;
    stats->events += from->events;
    stats->nonfinite += from->nonfinite;
    stats->paths_cut += from->paths_cut;
    stats->cut_tracking += from->cut_tracking;
    stats->solves += from->solves;
    stats->solves_converged += from->solves_converged;
    stats->solve_iterations += from->solve_iterations;
    stats->solve_segments += from->solve_segments;
    stats->solve_connections += from->solve_connections;
    stats->solve_trials += from->solve_trials;
    stats->solves_unsupported += from->solves_unsupported;
    stats->aim_shots += from->aim_shots;
    stats->aim_missed += from->aim_missed;
    stats->cone_shots += from->cone_shots;
    stats->cone_counted += from->cone_counted;
    stats->cut_samples += from->cut_samples;
    stats->trapped_paths += from->trapped_paths;
}

/* Sample s of pixel (x, y) into L; 0 (counted in the stats) when it is
   discarded as non-finite. Random numbers depend on (seed, pixel, s) alone. */
static int rrv__pixel_sample(rrv__context *ctx, const rrv__camera_frame *frame, int sobol, int x, int y, int s,
                             double L[3])
{
    const rrv_scene *scene = ctx->scene;
    uint64_t pixel = (uint64_t)y * (uint64_t)scene->camera.width + (uint64_t)x;
    rrv__rng rng;
    rrv_vec3 d;
    double jy, jx;
    rrv__rng_seed(&rng, scene->settings.seed, pixel, (uint64_t)s);
    if (sobol) rrv__sobol_start(&rng, rrv__mix64(scene->settings.seed ^ rrv__mix64(pixel)), (uint32_t)s);
    jy = rrv__uniform(&rng); /* in this order on every compiler */
    jx = rrv__uniform(&rng);
    d = rrv__camera_ray(frame, &scene->camera, x + jx, y + jy);
    rrv__trace_path(ctx, frame->eye, d, &rng, L);
    ++ctx->stats.samples;
    /* NaN fails the comparison too */
    if (!(fabs(L[0]) <= RRV_MAX_SAMPLE && fabs(L[1]) <= RRV_MAX_SAMPLE && fabs(L[2]) <= RRV_MAX_SAMPLE)) {
        ++ctx->stats.nonfinite;
        return 0;
    }
    return 1;
}

RRV_DEF rrv_result rrv_render_rect(const rrv_scene *scene, int x0, int y0, int x1, int y1,
                                   int sample_begin, int sample_end,
                                   float *sum, int stride, rrv_render_stats *stats,
                                   rrv_error *err)
{
    rrv__context ctx;
    rrv__camera_frame frame;
    int x, y, s, c, sobol;
    rrv_result r;
    rrv__clear_error(err);
    if ((r = rrv__render_args_check(scene, x0, y0, x1, y1, sample_begin, sample_end, sum, stride, err)) != RRV_OK)
        return r;
    if ((r = rrv__render_context(scene, &ctx, &frame, err)) != RRV_OK) return r;
    sobol = scene->settings.sampler != RRV_SAMPLER_PCG;
    for (y = y0; y < y1; ++y) {
        for (x = x0; x < x1; ++x) {
            double acc[3] = {0, 0, 0};
            float *out = sum + 3 * ((size_t)(y - y0) * (size_t)stride + (size_t)(x - x0));
            for (s = sample_begin; s < sample_end; ++s) {
                double L[3];
                if (!rrv__pixel_sample(&ctx, &frame, sobol, x, y, s, L)) continue;
                acc[0] += L[0];
                acc[1] += L[1];
                acc[2] += L[2];
            }
            /* Saturate: sums the caller keeps adding to must never reach Inf
               (and a double beyond float's range must not be converted). */
            for (c = 0; c < 3; ++c) {
                float v = out[c] + (float)rrv__clamp(acc[c], -FLT_MAX, FLT_MAX);
                out[c] = v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : v;
            }
        }
    }
    if (stats) rrv__add_render_stats(stats, &ctx.stats);
    rrv__solver_release(&ctx);
    return RRV_OK;
}

/* ---- adaptive sampling --------------------------------------------------------
   A pixel's samples are added in the sample tree that main.c's renders and
   merges use (rrv_render_rect_adaptive's comment), so that a pixel which
   never stops is bit for bit the uniform render's, and one which stops at n
   samples holds the tree's own block [0, n). Blocks [n, 2n) of a power of
   two n are blocks of the tree over [0, spp) whenever 2n < spp, and [n, spp)
   is its right half when n is the largest power of two below spp: the
   doubling order below walks down the tree's left spine and back. */

static float rrv__add_saturated(float a, float b)
{
    float v = a + b;
    return v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : v;
}

/* The tree sum of samples [a, b) of pixel (x, y): [a, m) + [m, b) with m - a
   the largest power of two below b - a; a leaf is rounded as
   rrv_render_rect rounds a one-sample call into a zeroed buffer. moments
   gathers the sum and the sum of squares of each sample's R + G + B, in
   sample order (in double, beside the tree: they never touch its sums). */
static void rrv__tree_sum(rrv__context *ctx, const rrv__camera_frame *frame, int sobol, int x, int y, int a, int b,
                          float out[3], double moments[2])
{
    float right[3];
    int half = 1, c;
    if (b - a == 1) {
        double L[3], acc[3] = {0, 0, 0};
        if (rrv__pixel_sample(ctx, frame, sobol, x, y, a, L))
            for (c = 0; c < 3; ++c) acc[c] += L[c];
        moments[0] += acc[0] + acc[1] + acc[2];
        moments[1] += (acc[0] + acc[1] + acc[2]) * (acc[0] + acc[1] + acc[2]);
        for (c = 0; c < 3; ++c) out[c] = rrv__add_saturated(0.0f, (float)rrv__clamp(acc[c], -FLT_MAX, FLT_MAX));
        return;
    }
    while (half < (b - a) - half) half *= 2;
    rrv__tree_sum(ctx, frame, sobol, x, y, a, a + half, out, moments);
    rrv__tree_sum(ctx, frame, sobol, x, y, a + half, b, right, moments);
    for (c = 0; c < 3; ++c) out[c] = rrv__add_saturated(out[c], right[c]);
}

/* The estimated relative error of the mean of n samples of R + G + B from
   their moments: the standard error sqrt(s^2 / n), s^2 the unbiased
   sample variance, over the mean (floored so that black pixels stop: an
   absolute error of threshold x the floor is enough there). Not the
   difference of two halves' means: with one degree of freedom that is
   small by chance often enough that noisy pixels stopped at 32 samples,
   and it lost 1.5x-2x in RMSE to uniform sampling at equal CPU time
   where this is at par (test/bench/RESULTS.md, "Adaptive sampling"). */
static double rrv__relative_error(const double moments[2], int n)
{
    double mean = moments[0] / n, var = (moments[1] - n * mean * mean) / (n - 1);
    return sqrt(rrv__maxd(var, 0.0) / n) / rrv__maxd(mean, RRV_ADAPTIVE_FLOOR);
}

RRV_DEF rrv_result rrv_render_rect_adaptive(const rrv_scene *scene, int x0, int y0, int x1, int y1, int spp,
                                            double threshold, float *sum, int stride, int *counts,
                                            rrv_render_stats *stats, rrv_error *err)
{
    rrv__context ctx;
    rrv__camera_frame frame;
    int x, y, sobol;
    rrv_result r;
    rrv__clear_error(err);
    if ((r = rrv__render_args_check(scene, x0, y0, x1, y1, 0, spp, sum, stride, err)) != RRV_OK) return r;
    if (spp < 1 || !counts || !(threshold >= 0 && threshold <= DBL_MAX))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene->path, 0,
                         "rrv_render_rect_adaptive: needs spp >= 1, counts and a finite threshold >= 0 "
                         "(spp %d, threshold %g)", spp, threshold);
    if ((r = rrv__render_context(scene, &ctx, &frame, err)) != RRV_OK) return r;
    sobol = scene->settings.sampler != RRV_SAMPLER_PCG;
    for (y = y0; y < y1; ++y)
        for (x = x0; x < x1; ++x) {
            float *out = sum + 3 * ((size_t)(y - y0) * (size_t)stride + (size_t)(x - x0));
            float block[3];
            double moments[2] = {0, 0};
            int n = spp < RRV_ADAPTIVE_BLOCK ? spp : RRV_ADAPTIVE_BLOCK, c;
            rrv__tree_sum(&ctx, &frame, sobol, x, y, 0, n, out, moments);
            while (n < spp) {
                int end = 2 * n < spp ? 2 * n : spp, full = end == 2 * n;
                rrv__tree_sum(&ctx, &frame, sobol, x, y, n, end, block, moments);
                /* checked after doublings only: the last, shorter block
                   ends the pixel anyway */
                full = full && rrv__relative_error(moments, end) < threshold;
                for (c = 0; c < 3; ++c) out[c] = rrv__add_saturated(out[c], block[c]);
                n = end;
                if (full) break;
            }
            counts[(size_t)(y - y0) * (size_t)stride + (size_t)(x - x0)] = n;
        }
    if (stats) rrv__add_render_stats(stats, &ctx.stats);
    rrv__solver_release(&ctx);
    return RRV_OK;
}

RRV_DEF rrv_result rrv_trace_ray(const rrv_scene *scene, rrv_integrator integrator,
                                 rrv_vec3 origin, rrv_vec3 direction, uint64_t seed, uint64_t walk,
                                 rrv_trace_visit_func visit, void *user, rrv_trace_result *result, rrv_error *err)
{
    rrv__rng rng;
    rrv__bender bender;
    rrv_vec3 o = origin, d;
    uint64_t events = 0, unused = 0, bound, iterations = 0;
    rrv__clear_error(err);
    if (!scene || !result) return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "no scene or result");
    if (!(rrv__length(direction) > 0) || rrv__length(direction) > DBL_MAX)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "the ray direction must be finite and nonzero");
    d = rrv__normalize(direction);
    if (integrator == RRV_INTEGRATOR_DEFAULT) integrator = rrv_scene_integrator(scene);
    bound = (uint64_t)rrv__step_bound(scene, integrator == RRV_INTEGRATOR_EIKONAL ? integrator
                                                                             : RRV_INTEGRATOR_REFRACTIVE);
    rrv__rng_seed(&rng, seed, walk, 0x7261797472616365ULL);
    rrv__bender_start(&bender, scene, integrator == RRV_INTEGRATOR_EIKONAL, o);
    if (visit) visit(user, o, d);
    for (;;) {
        /* faces count too: a ray trapped by total internal reflection in a
           box of constant IOR meets nothing but faces */
        if (events > bound || ++iterations > 2 * bound)
            return rrv__fail(err, RRV_ERROR_LIMIT, scene->path, 0,
                             "the ray did not leave the refractive media after %llu events and %llu segments",
                             (unsigned long long)events, (unsigned long long)iterations);
        if (!bender.pending) rrv__plan_segment(&bender, scene, o, &d, &rng);
        if (bender.end == RRV__END_NONE) break;
        if (integrator != RRV_INTEGRATOR_EIKONAL && bender.scheme != RRV_REFRACTION_COMB) {
            /* Poisson and midpoint: null events of the refraction rate alone
               along the segment, the earliest across media first */
            rrv__walker walkers[RRV__MAX_MEDIA];
            int i, n = 0, best = 0;
            for (i = 0; i < scene->medium_count; ++i) {
                const rrv_medium *m = &scene->media[i];
                if (!rrv__medium_refracts(m)) continue;
                if (rrv__walker_start(&walkers[n], m, 1, &scene->settings, o, d, bender.segment)) {
                    rrv__walker_refraction_only(&walkers[n]);
                    rrv__walker_advance(&walkers[n], &rng, &unused);
                    if (walkers[n].t_event < bender.segment) ++n;
                }
            }
            for (i = 1; i < n; ++i)
                if (walkers[i].t_event < walkers[best].t_event) best = i;
            if (n) {
                o = rrv__madd(o, d, walkers[best].t_event);
                d = rrv__bend_at_null_event(&bender, scene, o, d);
                ++events;
                if (visit) visit(user, o, d);
                continue;
            }
        }
        if (bender.end != RRV__END_FACE) ++events;
        rrv__finish_segment(&bender, scene, &o, &d, &rng);
        if (visit) visit(user, o, d);
    }
    result->position = o;
    result->direction = d;
    result->events = events;
    return RRV_OK;
}

/* >> 11 building scenes: defaults, checks, the rrv_scene_* calls ============
   This section owns rrv_scene_create, rrv_scene_set_*, rrv_scene_add_* and
   rrv_scene_free, with the one home of every default and check. The key
   tables the scene file's statements are read with (>> 15) are also the
   ranges these calls check single values against, so every build keeps
   them, with the parser or without it (RRV_NO_SCENE_FILE). */

#define RRV__SF_NO_LO (-DBL_MAX)
#define RRV__SF_NO_HI DBL_MAX

/* Makes room for one more element; capacity doubles, counts stay ints. */
static int rrv__sf_reserve(void **array, int *capacity, int count, size_t elem)
{
    int cap;
    void *v;
    if (count < *capacity) return 1;
    if (*capacity > INT_MAX / 2) return 0;
    cap = *capacity ? *capacity * 2 : 8;
    if ((size_t)cap > SIZE_MAX / elem) return 0;
    v = RRV_REALLOC(*array, (size_t)cap * elem);
    if (!v) return 0;
    *array = v;
    *capacity = cap;
    return 1;
}

/* Blob arrays have no capacity field: their capacity is a function of the
   count (4, then powers of two), which also lets rrv__sf_scene_bytes count it. */
static size_t rrv__sf_blob_capacity(int count)
{
    size_t cap = 4;
    while (cap < (size_t)count)
        cap *= 2;
    return count > 0 ? cap : 0;
}

/* ---- keys: the per-statement tables ------------------------------------------ */

enum {
    RRV__SF_NUM, /* `arity` finite numbers */
    RRV__SF_INT, /* `arity` integers */
    RRV__SF_U64, /* one unsigned 64-bit integer */
    RRV__SF_WORD, /* one word: a name or a path */
    RRV__SF_CHOICE, /* one word out of `choices` ("a|b|c") */
    RRV__SF_NUMLIST, /* any count of finite numbers */
    RRV__SF_INTLIST /* any count of integers */
};
enum { RRV__SF_GT = 1, RRV__SF_LT = 2, RRV__SF_REQ = 4 };

typedef struct rrv__sf_key {
    const char *name;
    unsigned char kind, arity, flags;
    double lo, hi; /* RRV__SF_NO_LO / RRV__SF_NO_HI: unbounded; GT/LT make them strict */
    const char *choices;
} rrv__sf_key;

typedef struct rrv__sf_slot {
    int given;
    double v[6];
    uint64_t u;
    int choice;
    size_t tok; /* first value token */
    size_t count; /* list length */
} rrv__sf_slot;

#define RRV__SF_MAX_KEYS 20
#define RRV__SF_ANY RRV__SF_NO_LO, RRV__SF_NO_HI
#define RRV__SF_NN 0.0, RRV__SF_NO_HI /* >= 0 (or > 0 with RRV__SF_GT) */
#define RRV__SF_UNIT 0.0, 1.0
/* Positions and sizes in the scene, within 1e150 m as the camera's are: a
   squared distance then never overflows (a sphere of radius 1e200 had an
   infinite r^2 and vanished from the picture). */
#define RRV__SF_WORLD -1e150, 1e150
#define RRV__SF_SIZE 0.0, 1e150

static const rrv__sf_key rrv__sf_camera_keys[] = {
    /* The renderer squares distances from the camera in double precision,
       which overflows beyond about 1e154: farther cameras would see nothing. */
    {"eye", RRV__SF_NUM, 3, RRV__SF_REQ, -1e150, 1e150, NULL},
    {"look", RRV__SF_NUM, 3, RRV__SF_REQ, -1e150, 1e150, NULL},
    {"up", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"fov", RRV__SF_NUM, 1, RRV__SF_GT | RRV__SF_LT, 0.0, 180.0, NULL},
    {"resolution", RRV__SF_INT, 2, 0, 1.0, 16384.0, NULL},
};
static const rrv__sf_key rrv__sf_render_keys[] = {
    {"spp", RRV__SF_INT, 1, 0, 1.0, (double)RRV_MAX_SPP, NULL},
    {"maxdepth", RRV__SF_INT, 1, 0, 1.0, 1024.0, NULL},
    {"seed", RRV__SF_U64, 1, 0, RRV__SF_NN, NULL},
    {"integrator", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "default|classic|refractive|eikonal"},
    /* bounded so one event or step cannot be absurdly small (BOUNDS) */
    {"bendtolerance", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_UNIT, NULL}, /* and >= 1e-4 */
    {"mueta", RRV__SF_NUM, 1, 0, 0.0, 1e6, NULL},
    {"step", RRV__SF_NUM, 1, 0, 1e-6, 1e6, NULL},
    {"stepper", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "default|leapfrog|rk4"},
    {"refraction", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "default|poisson|midpoint|comb"},
    {"majorantcells", RRV__SF_INT, 1, 0, 0.0, 256.0, NULL},
    {"iorinterp", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "trilinear|cubic"},
    {"nee", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "none|straight|shoot|manifold|aim"},
    {"manifoldgauge", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "chord|iso"},
    {"manifoldtrials", RRV__SF_INT, 1, 0, 0.0, 1024.0, NULL},
    {"manifolddrop", RRV__SF_NUM, 1, 0, 0.0, 1.0, NULL},
    {"sampler", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "pcg|sobol"},
    {"emissionnee", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "on|off"},
    {"manifoldsolver", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "lm|dogleg"},
    {"transmittance", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "ratio|residual|march"},
    {"noisethreshold", RRV__SF_NUM, 1, 0, 0.0, 1e6, NULL},
    {"equiangular", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "on|off"},
    {"lightsampler", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "power|uniform"},
};
/* Choice index -> enum, spelled out so reordering an enum in api.h cannot
   silently change what a word means. */
static const rrv_integrator rrv__sf_integrators[] = {
    RRV_INTEGRATOR_DEFAULT, RRV_INTEGRATOR_CLASSIC, RRV_INTEGRATOR_REFRACTIVE, RRV_INTEGRATOR_EIKONAL};
static const rrv_stepper rrv__sf_steppers[] = {RRV_STEPPER_DEFAULT, RRV_STEPPER_LEAPFROG,
                                               RRV_STEPPER_RK4};
static const rrv_refraction_scheme rrv__sf_schemes[] = {
    RRV_REFRACTION_DEFAULT, RRV_REFRACTION_POISSON, RRV_REFRACTION_MIDPOINT, RRV_REFRACTION_COMB};
static const rrv_falloff_kind rrv__sf_falloffs[] = {RRV_FALLOFF_NONE, RRV_FALLOFF_SPHERE,
                                                    RRV_FALLOFF_PLUME};
static const rrv__sf_key rrv__sf_ambient_keys[] = {
    {"ior", RRV__SF_NUM, 1, RRV__SF_REQ, 1.0, RRV__SF_NO_HI, NULL},
};
static const rrv__sf_key rrv__sf_diffuse_keys[] = {
    {"albedo", RRV__SF_NUM, 3, 0, RRV__SF_UNIT, NULL},
};
static const rrv__sf_key rrv__sf_checker_keys[] = {
    {"albedo", RRV__SF_NUM, 3, 0, RRV__SF_UNIT, NULL},
    {"albedo2", RRV__SF_NUM, 3, 0, RRV__SF_UNIT, NULL},
    {"checkerscale", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
};
/* Shapes share their last three keys: material, L, scale. */
#define RRV__SF_SHAPE_TAIL                                                                         \
    {"material", RRV__SF_WORD, 1, 0, RRV__SF_ANY, NULL},                                           \
        {"L", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},                                                \
    {                                                                                              \
        "scale", RRV__SF_NUM, 1, 0, RRV__SF_NN, NULL                                               \
    }
static const rrv__sf_key rrv__sf_sphere_keys[] = {
    {"center", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    {"radius", RRV__SF_NUM, 1, RRV__SF_REQ | RRV__SF_GT, RRV__SF_SIZE, NULL},
    RRV__SF_SHAPE_TAIL,
};
static const rrv__sf_key rrv__sf_quad_keys[] = {
    {"origin", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    {"u", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    {"v", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    RRV__SF_SHAPE_TAIL,
};
static const rrv__sf_key rrv__sf_triangle_keys[] = {
    {"p0", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    {"p1", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    {"p2", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    RRV__SF_SHAPE_TAIL,
};
static const rrv__sf_key rrv__sf_mesh_keys[] = {
    {"file", RRV__SF_WORD, 1, 0, RRV__SF_ANY, NULL},
    {"points", RRV__SF_NUMLIST, 0, 0, RRV__SF_ANY, NULL},
    {"indices", RRV__SF_INTLIST, 0, 0, 0.0, (double)INT_MAX, NULL},
    {"translate", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"material", RRV__SF_WORD, 1, 0, RRV__SF_ANY, NULL},
    {"L", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},
    {"scale", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL}, /* geometry, not emission */
};
static const rrv__sf_key rrv__sf_env_constant_keys[] = {
    {"L", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},
    {"scale", RRV__SF_NUM, 1, 0, RRV__SF_NN, NULL},
};
static const rrv__sf_key rrv__sf_env_gradient_keys[] = {
    {"top", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_NN, NULL},
    {"bottom", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_NN, NULL},
    {"scale", RRV__SF_NUM, 1, 0, RRV__SF_NN, NULL},
};
static const rrv__sf_key rrv__sf_medium_keys[] = {
    {"box", RRV__SF_NUM, 6, RRV__SF_REQ, RRV__SF_WORLD, NULL},
    {"sigma_a", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},
    {"sigma_s", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},
    {"scale", RRV__SF_NUM, 1, 0, RRV__SF_NN, NULL},
    {"g", RRV__SF_NUM, 1, RRV__SF_GT | RRV__SF_LT, -1.0, 1.0, NULL},
    {"albedo", RRV__SF_NUM, 3, 0, RRV__SF_UNIT, NULL},
    {"sigma_t", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},
    {"Le", RRV__SF_NUM, 3, 0, RRV__SF_NN, NULL},
    {"Lescale", RRV__SF_NUM, 1, 0, RRV__SF_NN, NULL},
};

/* Field kinds. The `base` key sits last where a kind has one. */
static const rrv__sf_key rrv__sf_blob_keys[] = {
    {"center", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_ANY, NULL},
    {"radius", RRV__SF_NUM, 1, RRV__SF_REQ | RRV__SF_GT, RRV__SF_NN, NULL},
    {"weight", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
    {"base", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
};
static const rrv__sf_key rrv__sf_noise_keys[] = {
    {"octaves", RRV__SF_INT, 1, 0, 1.0, 12.0, NULL},
    {"frequency", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
    {"lacunarity", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
    {"gain", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_UNIT, NULL},
    {"threshold", RRV__SF_NUM, 1, RRV__SF_LT, RRV__SF_UNIT, NULL},
    {"seed", RRV__SF_INT, 1, 0, 0.0, 4294967295.0, NULL},
    {"falloff", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "none|sphere|plume"},
    {"center", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"radius", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
    {"amplitude", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
    {"base", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
};
static const rrv__sf_key rrv__sf_luneburg_keys[] = {
    {"center", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"radius", RRV__SF_NUM, 1, RRV__SF_REQ | RRV__SF_GT, RRV__SF_NN, NULL},
};
static const rrv__sf_key rrv__sf_fisheye_keys[] = {
    {"center", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"radius", RRV__SF_NUM, 1, RRV__SF_REQ | RRV__SF_GT, RRV__SF_NN, NULL},
    {"n0", RRV__SF_NUM, 1, 0, 1.0, RRV__SF_NO_HI, NULL},
};
static const rrv__sf_key rrv__sf_slab_keys[] = {
    {"center", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"normal", RRV__SF_NUM, 3, RRV__SF_REQ, RRV__SF_ANY, NULL},
    {"gradient", RRV__SF_NUM, 1, RRV__SF_REQ, RRV__SF_ANY, NULL},
    {"base", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
};
static const rrv__sf_key rrv__sf_shell_keys[] = {
    {"center", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL},
    {"radius", RRV__SF_NUM, 1, RRV__SF_REQ | RRV__SF_GT, RRV__SF_NN, NULL},
    {"thickness", RRV__SF_NUM, 1, RRV__SF_REQ | RRV__SF_GT, RRV__SF_NN, NULL},
    {"edge", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
    {"amplitude", RRV__SF_NUM, 1, RRV__SF_REQ, RRV__SF_ANY, NULL},
    {"base", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
};
static const rrv__sf_key rrv__sf_gas_keys[] = {
    {"eta_ref", RRV__SF_NUM, 1, 0, 1.0, RRV__SF_NO_HI, NULL},
    {"P_ref", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
    {"T_ref", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
};
static const rrv__sf_key rrv__sf_nanovdb_keys[] = {
    {"grid", RRV__SF_WORD, 1, 0, RRV__SF_ANY, NULL},
    {"cellcentered", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "on|off"},
};
/* Keys a field statement accepts whatever its kind. */
static const rrv__sf_key rrv__sf_ior_extra_keys[] = {
    {"iorscale", RRV__SF_NUM, 1, 0, RRV__SF_NN, NULL},
};
static const rrv__sf_key rrv__sf_temperature_extra_keys[] = {
    {"temperatureoffset", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL},
    {"temperaturescale", RRV__SF_NUM, 1, RRV__SF_GT, RRV__SF_NN, NULL},
    {"blackbody", RRV__SF_CHOICE, 1, 0, RRV__SF_ANY, "on|off"},
};

#define RRV__SF_COUNT(a) (int)(sizeof(a) / sizeof((a)[0]))

static int rrv__sf_in_range(const rrv__sf_key *k, double v)
{
    if (k->lo != RRV__SF_NO_LO && ((k->flags & RRV__SF_GT) ? !(v > k->lo) : !(v >= k->lo)))
        return 0;
    if (k->hi != RRV__SF_NO_HI && ((k->flags & RRV__SF_LT) ? !(v < k->hi) : !(v <= k->hi)))
        return 0;
    return 1;
}

static void rrv__sf_range_text(const rrv__sf_key *k, char *buf, size_t cap)
{
    int gt = (k->flags & RRV__SF_GT) != 0, lt = (k->flags & RRV__SF_LT) != 0;
    if (k->hi == RRV__SF_NO_HI)
        snprintf(buf, cap, "%s %.15g", gt ? ">" : ">=", k->lo);
    else if (k->lo == RRV__SF_NO_LO)
        snprintf(buf, cap, "%s %.15g", lt ? "<" : "<=", k->hi);
    else
        snprintf(buf, cap, "in %c%.15g, %.15g%c", gt ? '(' : '[', k->lo, k->hi, lt ? ')' : ']');
}

/* ---- building scenes in code: one home for defaults and checks -------------
   The parser is a client of this part: a statement starts from a zeroed
   object, lets rrv__*_def fill the defaults, writes the keys it was given
   over them (so an explicit zero survives) and hands the object to the
   same check and store the public rrv_scene_add_* calls use. The ranges
   of single values are the key tables above, for files and code alike;
   the checks here add what one key cannot say (eye against look, a box's
   corners, a quad's area, the limits of BOUNDS). rrv_scene_prepare runs
   every check again, so a scene edited by hand is held to the same rules. */

static int rrv__finite3(const double *v)
{
    int i;
    for (i = 0; i < 3; ++i)
        if (!(v[i] == v[i]) || v[i] > DBL_MAX || v[i] < -DBL_MAX) return 0;
    return 1;
}

static int rrv__vec_finite(rrv_vec3 v)
{
    double d[3];
    d[0] = v.x;
    d[1] = v.y;
    d[2] = v.z;
    return rrv__finite3(d);
}

static int rrv__vec_zero(rrv_vec3 v) { return v.x == 0.0 && v.y == 0.0 && v.z == 0.0; }


static rrv_vec3 rrv__box_center(const rrv_medium *m)
{
    return rrv__v3(m->lo.x * 0.5 + m->hi.x * 0.5, m->lo.y * 0.5 + m->hi.y * 0.5,
                   m->lo.z * 0.5 + m->hi.z * 0.5);
}

/* Who is checked, for messages: "what: problem" at file:line (line 0 and
   RRV_ERROR_ARGUMENT for objects built in code, RRV_ERROR_PARSE for
   statements). */
typedef struct rrv__ck {
    rrv_error *err;
    const char *file;
    int line;
    rrv_result code;
    char what[96];
} rrv__ck;

static void rrv__ck_init(rrv__ck *ck, rrv_error *err, const char *file, int line, rrv_result code,
                         const char *fmt, ...)
{
    va_list args;
    ck->err = err;
    ck->file = file;
    ck->line = line;
    ck->code = code;
    va_start(args, fmt);
    vsnprintf(ck->what, sizeof ck->what, fmt, args);
    va_end(args);
}

static rrv_result rrv__ck_fail(const rrv__ck *ck, rrv_result code, const char *fmt, ...)
{
    char buf[200];
    va_list args;
    va_start(args, fmt);
    vsnprintf(buf, sizeof buf, fmt, args);
    va_end(args);
    return rrv__fail(ck->err, code ? code : ck->code, ck->file, ck->line, "%s: %s", ck->what, buf);
}

/* One value against key k of a statement's table. */
static rrv_result rrv__ck_key(const rrv__ck *ck, const rrv__sf_key *k, double v)
{
    char range[96];
    if (!(v == v) || v > DBL_MAX || v < -DBL_MAX)
        return rrv__ck_fail(ck, RRV_OK, "%s must be finite, got %g", k->name, v);
    if (rrv__sf_in_range(k, v)) return RRV_OK;
    rrv__sf_range_text(k, range, sizeof range);
    return rrv__ck_fail(ck, RRV_OK, "%s must be %s, got %.15g", k->name, range, v);
}

static rrv_result rrv__ck_key3(const rrv__ck *ck, const rrv__sf_key *k, const double *v)
{
    int c;
    for (c = 0; c < 3; ++c) {
        rrv_result r = rrv__ck_key(ck, k, v[c]);
        if (r != RRV_OK) return r;
    }
    return RRV_OK;
}

static rrv_result rrv__ck_vec(const rrv__ck *ck, const rrv__sf_key *k, rrv_vec3 v)
{
    double d[3];
    d[0] = v.x;
    d[1] = v.y;
    d[2] = v.z;
    return rrv__ck_key3(ck, k, d);
}

#define RRV__CK(call)                                                                              \
    do {                                                                                           \
        rrv_result rrv__ck_r = (call);                                                             \
        if (rrv__ck_r != RRV_OK) return rrv__ck_r;                                                 \
    } while (0)

/* -- camera -- */

static void rrv__camera_def(rrv_camera *c)
{
    if (rrv__vec_zero(c->up)) c->up.y = 1.0;
    if (c->fov == 0.0) c->fov = 40.0;
    if (c->width == 0) c->width = 320;
    if (c->height == 0) c->height = 240;
}

static rrv_result rrv__camera_check(const rrv__ck *ck, const rrv_camera *c)
{
    const rrv__sf_key *k = rrv__sf_camera_keys;
    rrv_vec3 dir, d, u, x;
    double n2, d2;
    RRV__CK(rrv__ck_vec(ck, &k[0], c->eye));
    RRV__CK(rrv__ck_vec(ck, &k[1], c->look));
    RRV__CK(rrv__ck_key(ck, &k[3], c->fov));
    RRV__CK(rrv__ck_key(ck, &k[4], (double)c->width));
    RRV__CK(rrv__ck_key(ck, &k[4], (double)c->height));
    dir = rrv__sub(c->look, c->eye);
    if (rrv__vec_zero(dir) || !rrv__vec_finite(dir))
        return rrv__ck_fail(ck, RRV_OK, "eye and look must be distinct finite points");
    if (rrv__vec_zero(c->up) || !rrv__vec_finite(c->up))
        return rrv__ck_fail(ck, RRV_OK, "up must be a nonzero finite vector");
    /* Both vectors scaled to a largest component of 1 first: squaring a far
       camera's view direction (eye at 1e200) would overflow to inf and make
       any up look parallel. sin^2 of the angle below 1e-12 is too close to
       parallel for a frame. */
    d = rrv__unit_max(dir);
    u = rrv__unit_max(c->up);
    x = rrv__cross(d, u);
    n2 = rrv__dot(x, x);
    d2 = rrv__dot(d, d) * rrv__dot(u, u);
    if (!(n2 > 1e-12 * d2)) return rrv__ck_fail(ck, RRV_OK, "up is parallel to the view direction");
    return RRV_OK;
}

/* -- settings (`render` and `ambient`) -- */

static void rrv__settings_def(rrv_settings *s)
{
    if (s->spp == 0) s->spp = 16;
    if (s->max_depth == 0) s->max_depth = 32;
    if (s->bend_tolerance == 0.0) s->bend_tolerance = 0.01;
}

static rrv_result rrv__settings_check(const rrv__ck *ck, const rrv__ck *ambient,
                                      const rrv_settings *s)
{
    const char *research;
    const rrv__sf_key *k = rrv__sf_render_keys;
    RRV__CK(rrv__ck_key(ck, &k[0], (double)s->spp));
    RRV__CK(rrv__ck_key(ck, &k[1], (double)s->max_depth));
    if ((unsigned)s->integrator > (unsigned)RRV_INTEGRATOR_EIKONAL)
        return rrv__ck_fail(ck, RRV_OK, "integrator %d is not one of rrv_integrator", (int)s->integrator);
    RRV__CK(rrv__ck_key(ck, &k[4], s->bend_tolerance));
    /* bounded so one event or step cannot be absurdly small (BOUNDS) */
    if (s->bend_tolerance < 1e-4)
        return rrv__ck_fail(ck, RRV_OK, "bendtolerance must be at least 0.0001, got %g",
                            s->bend_tolerance);
    RRV__CK(rrv__ck_key(ck, &k[5], s->mu_eta));
    if (s->step != 0.0) RRV__CK(rrv__ck_key(ck, &k[6], s->step)); /* 0: placed by the field */
    if ((unsigned)s->stepper > (unsigned)RRV_STEPPER_RK4)
        return rrv__ck_fail(ck, RRV_OK, "stepper %d is not one of rrv_stepper", (int)s->stepper);
    if ((unsigned)s->refraction > (unsigned)RRV_REFRACTION_COMB)
        return rrv__ck_fail(ck, RRV_OK, "refraction %d is not one of rrv_refraction_scheme",
                            (int)s->refraction);
    if ((research = rrv__research_variant(s)) != NULL)
        return rrv__ck_fail(ck, RRV_ERROR_UNSUPPORTED, "%s", research);
    RRV__CK(rrv__ck_key(ck, &k[9], (double)s->majorant_cells));
    if ((unsigned)s->ior_interpolation > (unsigned)RRV_IOR_INTERP_CUBIC)
        return rrv__ck_fail(ck, RRV_OK, "ior_interpolation %d is not one of rrv_ior_interpolation",
                            (int)s->ior_interpolation);
    if ((unsigned)s->nee > (unsigned)RRV_NEE_AIM)
        return rrv__ck_fail(ck, RRV_OK, "nee %d is not one of rrv_nee", (int)s->nee);
#ifdef RRV_NO_CURVED_NEE
    /* refused, not aimed instead: a render must not quietly be another
       estimator than the one asked for */
    if (s->nee == RRV_NEE_SHOOT || s->nee == RRV_NEE_MANIFOLD)
        return rrv__ck_fail(ck, RRV_ERROR_UNSUPPORTED, "nee %s is disabled (RRV_NO_CURVED_NEE); use nee aim",
                            s->nee == RRV_NEE_SHOOT ? "shoot" : "manifold");
#endif
    if ((unsigned)s->sampler > (unsigned)RRV_SAMPLER_SOBOL)
        return rrv__ck_fail(ck, RRV_OK, "sampler %d is not one of rrv_sampler", (int)s->sampler);
    if ((unsigned)s->emission_nee > (unsigned)RRV_EMISSION_NEE_OFF)
        return rrv__ck_fail(ck, RRV_OK, "emission_nee %d is not one of rrv_emission_nee", (int)s->emission_nee);
    if ((unsigned)s->manifold_gauge > (unsigned)RRV_GAUGE_ISO)
        return rrv__ck_fail(ck, RRV_OK, "manifold_gauge %d is not one of rrv_manifold_gauge",
                            (int)s->manifold_gauge);
    if ((unsigned)s->transmittance > (unsigned)RRV_TRANSMITTANCE_MARCH)
        return rrv__ck_fail(ck, RRV_OK, "transmittance %d is not one of rrv_transmittance", (int)s->transmittance);
    if ((unsigned)s->equiangular > (unsigned)RRV_EQUIANGULAR_OFF)
        return rrv__ck_fail(ck, RRV_OK, "equiangular %d is not one of rrv_equiangular", (int)s->equiangular);
    if ((unsigned)s->light_sampler > (unsigned)RRV_LIGHT_SAMPLER_UNIFORM)
        return rrv__ck_fail(ck, RRV_OK, "light sampler %d is not one of rrv_light_sampler", (int)s->light_sampler);
    if ((unsigned)s->manifold_solver > (unsigned)RRV_MANIFOLD_SOLVER_DOGLEG)
        return rrv__ck_fail(ck, RRV_OK, "manifold_solver %d is not one of rrv_manifold_solver",
                            (int)s->manifold_solver);
    RRV__CK(rrv__ck_key(ck, &k[13], (double)s->manifold_trials));
    RRV__CK(rrv__ck_key(ck, &k[14], s->manifold_drop));
    RRV__CK(rrv__ck_key(ck, &k[19], s->noise_threshold));
    if (s->max_bake_samples < 0)
        return rrv__ck_fail(ck, RRV_OK, "max_bake_samples must be >= 0, got %d", s->max_bake_samples);
    if (s->ambient_ior != 0.0) /* 0: from the gas (rrv__resolve_ambient) */
        RRV__CK(rrv__ck_key(ambient, &rrv__sf_ambient_keys[0], s->ambient_ior));
    if (s->ambient_ior > RRV_MAX_IOR)
        return rrv__ck_fail(ambient, RRV_OK, "ior must be at most %g, got %g", RRV_MAX_IOR,
                            s->ambient_ior);
    return RRV_OK;
}

/* -- environment -- */

static void rrv__environment_def(rrv_environment *e)
{
    if (e->kind == RRV_ENV_CONSTANT && e->L[0] == 0.0 && e->L[1] == 0.0 && e->L[2] == 0.0)
        e->L[0] = e->L[1] = e->L[2] = 1.0;
}

static rrv_result rrv__environment_check(const rrv__ck *ck, const rrv_environment *e)
{
    int c;
    if ((unsigned)e->kind > (unsigned)RRV_ENV_GRADIENT)
        return rrv__ck_fail(ck, RRV_OK, "kind %d is not one of rrv_environment_kind", (int)e->kind);
    if (!rrv__finite3(e->L) || !rrv__finite3(e->L2))
        return rrv__ck_fail(ck, RRV_OK, "radiance times scale is not finite");
    for (c = 0; c < 3; ++c)
        if (e->L[c] < 0.0 || e->L2[c] < 0.0)
            return rrv__ck_fail(ck, RRV_OK, "radiance must be >= 0, got %g",
                                e->L[c] < 0.0 ? e->L[c] : e->L2[c]);
    if (rrv__maxd(rrv__max3(e->L), rrv__max3(e->L2)) > RRV_MAX_RADIANCE)
        return rrv__ck_fail(ck, RRV_OK, "radiance times scale must be at most %g", RRV_MAX_RADIANCE);
    return RRV_OK;
}

/* -- materials -- */

static void rrv__material_def(rrv_material *m)
{
    int c, black = m->albedo[0] == 0.0 && m->albedo[1] == 0.0 && m->albedo[2] == 0.0;
    for (c = 0; c < 3; ++c) {
        if (black) m->albedo[c] = m->kind == RRV_MATERIAL_CHECKER ? 0.8 : 0.5;
    }
    if (m->kind == RRV_MATERIAL_CHECKER) {
        if (m->albedo2[0] == 0.0 && m->albedo2[1] == 0.0 && m->albedo2[2] == 0.0)
            m->albedo2[0] = m->albedo2[1] = m->albedo2[2] = 0.2;
        if (m->checker_scale == 0.0) m->checker_scale = 1.0;
    }
}

static rrv_result rrv__material_check(const rrv__ck *ck, const rrv_material *m)
{
    const rrv__sf_key *k = rrv__sf_checker_keys;
    if ((unsigned)m->kind > (unsigned)RRV_MATERIAL_CHECKER)
        return rrv__ck_fail(ck, RRV_OK, "kind %d is not one of rrv_material_kind", (int)m->kind);
    RRV__CK(rrv__ck_key3(ck, &k[0], m->albedo));
    if (m->kind == RRV_MATERIAL_CHECKER) {
        RRV__CK(rrv__ck_key3(ck, &k[1], m->albedo2));
        RRV__CK(rrv__ck_key(ck, &k[2], m->checker_scale));
    }
    return RRV_OK;
}

/* -- shapes -- */

static const char *rrv__shape_name(rrv_shape_kind kind)
{
    return kind == RRV_SHAPE_SPHERE ? "sphere" : kind == RRV_SHAPE_QUAD ? "quad" : "triangle";
}

/* L is stored premultiplied by its scale. */
static rrv_result rrv__emission_check(const rrv__ck *ck, const double *L)
{
    int c;
    if (!rrv__finite3(L)) return rrv__ck_fail(ck, RRV_OK, "L times scale is not finite");
    for (c = 0; c < 3; ++c)
        if (L[c] < 0.0) return rrv__ck_fail(ck, RRV_OK, "L must be >= 0, got %g", L[c]);
    if (rrv__max3(L) > RRV_MAX_RADIANCE)
        return rrv__ck_fail(ck, RRV_OK, "L times scale must be at most %g, got %g", RRV_MAX_RADIANCE,
                            rrv__max3(L));
    return RRV_OK;
}

static rrv_result rrv__shape_check(const rrv__ck *ck, const rrv_scene *scene, const rrv_shape *s)
{
    static const rrv__sf_key any = {"p0", RRV__SF_NUM, 3, 0, RRV__SF_ANY, NULL};
    if ((unsigned)s->kind > (unsigned)RRV_SHAPE_TRIANGLE)
        return rrv__ck_fail(ck, RRV_OK, "kind %d is not one of rrv_shape_kind", (int)s->kind);
    if (s->material < 0 || s->material >= scene->material_count)
        return rrv__ck_fail(ck, RRV_OK, "material %d is not one of the scene's %d", s->material,
                            scene->material_count);
    RRV__CK(rrv__emission_check(ck, s->L));
    if (s->kind == RRV_SHAPE_SPHERE) {
        RRV__CK(rrv__ck_vec(ck, &rrv__sf_sphere_keys[0], s->center));
        return rrv__ck_key(ck, &rrv__sf_sphere_keys[1], s->radius);
    }
    RRV__CK(rrv__ck_vec(ck, &any, s->p0));
    if (!rrv__vec_finite(s->e1) || !rrv__vec_finite(s->e2))
        return rrv__ck_fail(ck, RRV_OK, "edges are not finite");
    if (rrv__vec_zero(rrv__cross(s->e1, s->e2)))
        return rrv__ck_fail(ck, RRV_OK, s->kind == RRV_SHAPE_QUAD
                                            ? "u and v are parallel (zero area)"
                                            : "the points are collinear (zero area)");
    return RRV_OK;
}

/* -- media -- */

static void rrv__medium_def(rrv_medium *m)
{
    int c, none = 1;
    for (c = 0; c < 3; ++c)
        if (m->sigma_a[c] != 0.0 || m->sigma_s[c] != 0.0) none = 0;
    for (c = 0; c < 3 && none; ++c)
        m->sigma_a[c] = m->sigma_s[c] = 1.0;
    if (m->scale == 0.0) m->scale = 1.0;
    if (m->Lescale == 0.0) m->Lescale = 1.0;
    if (m->temperaturescale == 0.0) m->temperaturescale = 1.0;
    if (m->eta_ref == 0.0) m->eta_ref = 1.000292;
    if (m->P_ref == 0.0) m->P_ref = 101325.0;
    if (m->T_ref == 0.0) m->T_ref = 300.0;
    if (m->ior_scale == 0.0) m->ior_scale = 1.0;
}

/* What a medium statement can get wrong; the fields and the limits of
   BOUNDS are checked by rrv__field_check and rrv__check_medium. */
static rrv_result rrv__medium_check(const rrv__ck *ck, const rrv_medium *m)
{
    const rrv__sf_key *k = rrv__sf_medium_keys;
    double lo[3], hi[3];
    int c;
    lo[0] = m->lo.x, lo[1] = m->lo.y, lo[2] = m->lo.z;
    hi[0] = m->hi.x, hi[1] = m->hi.y, hi[2] = m->hi.z;
    RRV__CK(rrv__ck_key3(ck, &k[0], lo));
    RRV__CK(rrv__ck_key3(ck, &k[0], hi));
    for (c = 0; c < 3; ++c)
        if (!(lo[c] < hi[c]))
            return rrv__ck_fail(ck, RRV_OK, "box is empty along %c (%g is not below %g)", "xyz"[c],
                                lo[c], hi[c]);
    RRV__CK(rrv__ck_key3(ck, &k[1], m->sigma_a));
    RRV__CK(rrv__ck_key3(ck, &k[2], m->sigma_s));
    RRV__CK(rrv__ck_key(ck, &k[3], m->scale));
    RRV__CK(rrv__ck_key(ck, &k[4], m->g));
    RRV__CK(rrv__ck_key3(ck, &k[7], m->Le));
    RRV__CK(rrv__ck_key(ck, &k[8], m->Lescale));
    RRV__CK(rrv__ck_key(ck, &rrv__sf_temperature_extra_keys[0], m->temperatureoffset));
    RRV__CK(rrv__ck_key(ck, &rrv__sf_temperature_extra_keys[1], m->temperaturescale));
    RRV__CK(rrv__ck_key(ck, &rrv__sf_gas_keys[0], m->eta_ref));
    RRV__CK(rrv__ck_key(ck, &rrv__sf_gas_keys[1], m->P_ref));
    RRV__CK(rrv__ck_key(ck, &rrv__sf_gas_keys[2], m->T_ref));
    RRV__CK(rrv__ck_key(ck, &rrv__sf_ior_extra_keys[0], m->ior_scale));
    return RRV_OK;
}

/* -- fields -- */

static void rrv__blob_def(rrv_blob *b)
{
    if (b->weight == 0.0) b->weight = 1.0;
}

/* The value a field kind adds everywhere when it does not say: the ambient
   state of air for temperature and pressure, nothing for density and IOR. */
static double rrv__field_base_default(rrv_medium_field which)
{
    return which == RRV_MEDIUM_TEMPERATURE ? 300.0 : which == RRV_MEDIUM_PRESSURE ? 101325.0 : 0.0;
}

static void rrv__field_def(rrv_field *f, rrv_medium_field which, const rrv_medium *m)
{
    int i;
    switch (f->kind) {
    case RRV_FIELD_BLOBS:
        for (i = 0; i < f->blob_count; ++i) rrv__blob_def(&f->blobs[i]);
        if (f->base == 0.0) f->base = rrv__field_base_default(which);
        break;
    case RRV_FIELD_NOISE: {
        rrv_noise *n = &f->noise;
        double sx = m->hi.x * 0.5 - m->lo.x * 0.5, sy = m->hi.y * 0.5 - m->lo.y * 0.5,
               sz = m->hi.z * 0.5 - m->lo.z * 0.5;
        if (n->octaves == 0) n->octaves = 5;
        if (n->frequency == 0.0) n->frequency = 1.0;
        if (n->lacunarity == 0.0) n->lacunarity = 2.0;
        if (n->gain == 0.0) n->gain = 0.5;
        if (rrv__vec_zero(n->center)) n->center = rrv__box_center(m);
        if (n->radius == 0.0) n->radius = sx < sy ? (sx < sz ? sx : sz) : (sy < sz ? sy : sz);
        if (f->amplitude == 0.0) f->amplitude = 1.0;
        if (f->base == 0.0) f->base = rrv__field_base_default(which);
        break;
    }
    case RRV_FIELD_LUNEBURG:
    case RRV_FIELD_FISHEYE:
    case RRV_FIELD_SLAB:
    case RRV_FIELD_SHELL:
        if (rrv__vec_zero(f->center)) f->center = rrv__box_center(m);
        if (f->kind == RRV_FIELD_FISHEYE && f->n0 == 0.0) f->n0 = 2.0;
        if (f->kind == RRV_FIELD_SHELL && f->edge == 0.0) f->edge = f->thickness / 4.0;
        if (f->kind == RRV_FIELD_SLAB && !rrv__vec_zero(f->normal) && rrv__vec_finite(f->normal)) {
            /* scaled first so squaring cannot overflow */
            rrv_vec3 n = rrv__unit_max(f->normal);
            f->normal = rrv__scale(n, 1.0 / rrv__length(n));
        }
        break;
    default:
        break;
    }
}

/* Blobs before first_blob were checked already (the parser adds one a line). */
static rrv_result rrv__field_check(const rrv__ck *ck, rrv_medium_field which, const rrv_medium *m,
                                   const rrv_field *f, int first_blob)
{
    int i;
    if ((unsigned)f->kind > (unsigned)RRV_FIELD_NANOVDB)
        return rrv__ck_fail(ck, RRV_OK, "kind %d is not one of rrv_field_kind", (int)f->kind);
    if (f->kind >= RRV_FIELD_LUNEBURG && f->kind <= RRV_FIELD_SHELL && which != RRV_MEDIUM_IOR)
        return rrv__ck_fail(ck, RRV_OK, "IOR profiles belong in the ior field");
    switch (f->kind) {
    case RRV_FIELD_CONSTANT: {
        double v = f->value;
        if (!(v == v) || v > DBL_MAX || v < -DBL_MAX)
            return rrv__ck_fail(ck, RRV_OK, "constant must be finite, got %g", v);
        if (which == RRV_MEDIUM_DENSITY && v < 0.0)
            return rrv__ck_fail(ck, RRV_OK, "constant must be >= 0, got %.15g", v);
        if (which == RRV_MEDIUM_PRESSURE && !(v > 0.0))
            return rrv__ck_fail(ck, RRV_OK, "constant must be > 0, got %.15g", v);
        if (which == RRV_MEDIUM_IOR && !(v > -1.0))
            return rrv__ck_fail(ck, RRV_OK,
                                "constant (the refractivity eta - 1) must be > -1, got %.15g", v);
        if (which == RRV_MEDIUM_TEMPERATURE) {
            double T = (v - m->temperatureoffset) * m->temperaturescale;
            if (!(T > 0.0) || T > DBL_MAX)
                return rrv__ck_fail(ck, RRV_OK, "constant %.15g gives T = %g K, must be > 0 and finite",
                                    v, T);
        }
        return RRV_OK;
    }
    case RRV_FIELD_BLOBS:
        if (f->blob_count < 1 || !f->blobs)
            return rrv__ck_fail(ck, RRV_OK, "blobs need at least one blob");
        if (f->blob_count > RRV_MAX_BLOBS)
            return rrv__ck_fail(ck, RRV_ERROR_LIMIT, "more than %d blobs in one field (a grid holds more)",
                                RRV_MAX_BLOBS);
        for (i = first_blob; i < f->blob_count; ++i) {
            RRV__CK(rrv__ck_vec(ck, &rrv__sf_blob_keys[0], f->blobs[i].center));
            RRV__CK(rrv__ck_key(ck, &rrv__sf_blob_keys[1], f->blobs[i].radius));
            RRV__CK(rrv__ck_key(ck, &rrv__sf_blob_keys[2], f->blobs[i].weight));
        }
        return rrv__ck_key(ck, &rrv__sf_blob_keys[3], f->base);
    case RRV_FIELD_NOISE: {
        const rrv__sf_key *k = rrv__sf_noise_keys;
        const rrv_noise *n = &f->noise;
        RRV__CK(rrv__ck_key(ck, &k[0], (double)n->octaves));
        RRV__CK(rrv__ck_key(ck, &k[1], n->frequency));
        RRV__CK(rrv__ck_key(ck, &k[2], n->lacunarity));
        RRV__CK(rrv__ck_key(ck, &k[3], n->gain));
        RRV__CK(rrv__ck_key(ck, &k[4], n->threshold));
        if ((unsigned)n->falloff > (unsigned)RRV_FALLOFF_PLUME)
            return rrv__ck_fail(ck, RRV_OK, "falloff %d is not one of rrv_falloff_kind", (int)n->falloff);
        RRV__CK(rrv__ck_vec(ck, &k[7], n->center));
        RRV__CK(rrv__ck_key(ck, &k[8], n->radius));
        RRV__CK(rrv__ck_key(ck, &k[9], f->amplitude));
        return rrv__ck_key(ck, &k[10], f->base);
    }
    case RRV_FIELD_GRID: {
        const rrv_grid *g = &f->grid;
        if (!g->data || g->nx < 2 || g->ny < 2 || g->nz < 2 || (g->channels != 1 && g->channels != 3))
            return rrv__ck_fail(ck, RRV_OK, "a grid needs data, each resolution >= 2 and 1 or 3 channels");
        if (!rrv__vec_finite(g->lo) || !rrv__vec_finite(g->hi) || !(g->lo.x < g->hi.x) ||
            !(g->lo.y < g->hi.y) || !(g->lo.z < g->hi.z))
            return rrv__ck_fail(ck, RRV_OK, "the grid's box is empty or not finite");
        if (which != RRV_MEDIUM_DENSITY && g->channels != 1)
            return rrv__ck_fail(ck, RRV_ERROR_FORMAT, "grids need 1 channel, found %d", g->channels);
        return RRV_OK;
    }
    case RRV_FIELD_NANOVDB:
#ifdef RRV_NO_NANOVDB
        return rrv__ck_fail(ck, RRV_ERROR_UNSUPPORTED, "NanoVDB grids are disabled (RRV_NO_NANOVDB)");
#endif
        if (!f->nanovdb.buffer) return rrv__ck_fail(ck, RRV_OK, "the NanoVDB grid has no data");
        return RRV_OK;
    case RRV_FIELD_LUNEBURG:
    case RRV_FIELD_FISHEYE:
        RRV__CK(rrv__ck_vec(ck, &rrv__sf_luneburg_keys[0], f->center));
        RRV__CK(rrv__ck_key(ck, &rrv__sf_luneburg_keys[1], f->radius));
        return f->kind == RRV_FIELD_FISHEYE ? rrv__ck_key(ck, &rrv__sf_fisheye_keys[2], f->n0) : RRV_OK;
    case RRV_FIELD_SLAB:
        RRV__CK(rrv__ck_vec(ck, &rrv__sf_slab_keys[0], f->center));
        if (rrv__vec_zero(f->normal) || !rrv__vec_finite(f->normal))
            return rrv__ck_fail(ck, RRV_OK, "slab normal must be nonzero");
        RRV__CK(rrv__ck_key(ck, &rrv__sf_slab_keys[2], f->gradient));
        return rrv__ck_key(ck, &rrv__sf_slab_keys[3], f->base);
    case RRV_FIELD_SHELL: {
        const rrv__sf_key *k = rrv__sf_shell_keys;
        RRV__CK(rrv__ck_vec(ck, &k[0], f->center));
        RRV__CK(rrv__ck_key(ck, &k[1], f->radius));
        RRV__CK(rrv__ck_key(ck, &k[2], f->thickness));
        RRV__CK(rrv__ck_key(ck, &k[3], f->edge));
        RRV__CK(rrv__ck_key(ck, &k[4], f->amplitude));
        return rrv__ck_key(ck, &k[5], f->base);
    }
    default:
        return RRV_OK;
    }
}

static rrv_field *rrv__medium_field_of(rrv_medium *m, rrv_medium_field which)
{
    return which == RRV_MEDIUM_DENSITY       ? &m->density
           : which == RRV_MEDIUM_TEMPERATURE ? &m->temperature
           : which == RRV_MEDIUM_PRESSURE    ? &m->pressure
                                             : &m->ior;
}

static const char *const rrv__medium_field_names[4] = {"density", "temperature", "pressure", "ior"};

/* -- the store: checks, then appends; shared by the parser and the API -- */

static rrv_scene *rrv__scene_new(const char *name)
{
    rrv_scene *s = (rrv_scene *)RRV_MALLOC(sizeof *s);
    size_t n = strlen(name);
    if (!s) return NULL;
    memset(s, 0, sizeof *s);
    if (n >= sizeof s->path) name += n - (sizeof s->path - 1); /* keep the file name's end */
    memcpy(s->path, name, strlen(name) + 1);
    rrv__camera_def(&s->camera);
    rrv__settings_def(&s->settings);
    return s;
}

static int rrv__name_taken(const rrv_scene *s, const char *name, int media)
{
    int i, n = media ? s->medium_count : s->material_count;
    for (i = 0; i < n; ++i)
        if (strcmp(media ? s->media[i].name : s->materials[i].name, name) == 0) return 1;
    return 0;
}

/* An empty material or medium name becomes "material N" or "medium N". */
static void rrv__name_default(const rrv_scene *s, char *name, int media)
{
    if (name[0] == '\0')
        snprintf(name, 64, "%s %d", media ? "medium" : "material",
                 media ? s->medium_count : s->material_count);
}

/* The name of a material or medium: printable, 1 to 63 bytes, new. */
static rrv_result rrv__name_check(const rrv__ck *ck, const rrv_scene *s, char *name, int media)
{
    size_t i;
    rrv__name_default(s, name, media);
    for (i = 0; name[i]; ++i)
        if ((unsigned char)name[i] < 32)
            return rrv__ck_fail(ck, RRV_OK, "the name has a control character");
    if (rrv__name_taken(s, name, media))
        return rrv__fail(ck->err, ck->code, ck->file, ck->line, "%s \"%s\" defined twice",
                         media ? "medium" : "material", name);
    return RRV_OK;
}

static rrv_result rrv__store_material(const rrv__ck *ck, rrv_scene *s, const rrv_material *m,
                                      int *index)
{
    rrv_material copy = *m;
    copy.name[sizeof copy.name - 1] = '\0';
    RRV__CK(rrv__name_check(ck, s, copy.name, 0));
    RRV__CK(rrv__material_check(ck, &copy));
    if (!rrv__sf_reserve((void **)&s->materials, &s->material_capacity, s->material_count,
                         sizeof copy))
        return rrv__ck_fail(ck, RRV_ERROR_MEMORY, "out of memory");
    if (index) *index = s->material_count;
    s->materials[s->material_count++] = copy;
    return RRV_OK;
}

/* The implicit grey "default" material, made on first use. */
static rrv_result rrv__default_material(const rrv__ck *ck, rrv_scene *s, int *index)
{
    rrv_material m;
    int i;
    for (i = 0; i < s->material_count; ++i)
        if (strcmp(s->materials[i].name, "default") == 0) {
            *index = i;
            return RRV_OK;
        }
    memset(&m, 0, sizeof m);
    memcpy(m.name, "default", 8);
    rrv__material_def(&m);
    return rrv__store_material(ck, s, &m, index);
}

static rrv_result rrv__store_shape(const rrv__ck *ck, rrv_scene *s, const rrv_shape *shape)
{
    RRV__CK(rrv__shape_check(ck, s, shape));
    if (!rrv__sf_reserve((void **)&s->shapes, &s->shape_capacity, s->shape_count, sizeof *shape))
        return rrv__ck_fail(ck, RRV_ERROR_MEMORY, "out of memory");
    s->shapes[s->shape_count++] = *shape;
    return RRV_OK;
}

/* A mesh triangle (a, b, c); zero-area ones are dropped. */
static rrv_result rrv__store_triangle(const rrv__ck *ck, rrv_scene *s, rrv_vec3 a, rrv_vec3 b,
                                      rrv_vec3 c, const rrv_shape *proto)
{
    rrv_shape t = *proto;
    t.kind = RRV_SHAPE_TRIANGLE;
    t.p0 = a;
    t.e1 = rrv__sub(b, a);
    t.e2 = rrv__sub(c, a);
    if (!rrv__vec_finite(a) || !rrv__vec_finite(t.e1) || !rrv__vec_finite(t.e2))
        return rrv__ck_fail(ck, RRV_OK, "a vertex is not finite after scale and translate");
    if (rrv__vec_zero(rrv__cross(t.e1, t.e2))) return RRV_OK;
    return rrv__store_shape(ck, s, &t);
}

static rrv_result rrv__store_medium(const rrv__ck *ck, rrv_scene *s, const rrv_medium *m, int *index)
{
    rrv_medium copy = *m;
    copy.name[sizeof copy.name - 1] = '\0';
    RRV__CK(rrv__name_check(ck, s, copy.name, 1));
    RRV__CK(rrv__medium_check(ck, &copy));
    if (s->medium_count >= RRV__MAX_MEDIA)
        return rrv__fail(ck->err, RRV_ERROR_LIMIT, ck->file, ck->line,
                         "medium: at most %d media are supported", RRV__MAX_MEDIA);
    if (!rrv__sf_reserve((void **)&s->media, &s->medium_capacity, s->medium_count, sizeof copy))
        return rrv__ck_fail(ck, RRV_ERROR_MEMORY, "out of memory");
    memset(&copy.density, 0, sizeof copy.density);
    memset(&copy.temperature, 0, sizeof copy.temperature);
    memset(&copy.pressure, 0, sizeof copy.pressure);
    memset(&copy.ior, 0, sizeof copy.ior);
    copy.majorant = NULL;
    if (index) *index = s->medium_count;
    s->media[s->medium_count++] = copy;
    return RRV_OK;
}

/* Every check again, for rrv_scene_prepare: a scene filled or edited by hand
   meets the rules a file meets. Media name the lines they came from. */
static rrv_result rrv__scene_check(rrv_scene *s, rrv_error *err)
{
    rrv__ck ck, ambient;
    int i, w;
    /* settings left zero take their defaults, as they always have here; a
       zero fov or an eye on the look point is refused instead */
    rrv__settings_def(&s->settings);
    rrv__ck_init(&ck, err, s->path, 0, RRV_ERROR_ARGUMENT, "camera");
    RRV__CK(rrv__camera_check(&ck, &s->camera));
    rrv__ck_init(&ck, err, s->path, 0, RRV_ERROR_ARGUMENT, "render");
    rrv__ck_init(&ambient, err, s->path, 0, RRV_ERROR_ARGUMENT, "ambient");
    RRV__CK(rrv__settings_check(&ck, &ambient, &s->settings));
    rrv__ck_init(&ck, err, s->path, 0, RRV_ERROR_ARGUMENT, "environment");
    RRV__CK(rrv__environment_check(&ck, &s->environment));
    for (i = 0; i < s->material_count; ++i) {
        rrv__ck_init(&ck, err, s->path, 0, RRV_ERROR_ARGUMENT, "material \"%s\"", s->materials[i].name);
        RRV__CK(rrv__material_check(&ck, &s->materials[i]));
    }
    for (i = 0; i < s->shape_count; ++i) {
        rrv__ck_init(&ck, err, s->path, 0, RRV_ERROR_ARGUMENT, "shape %d (%s)", i,
                     rrv__shape_name(s->shapes[i].kind));
        RRV__CK(rrv__shape_check(&ck, s, &s->shapes[i]));
    }
    for (i = 0; i < s->medium_count; ++i) {
        rrv_medium *m = &s->media[i];
        rrv__ck_init(&ck, err, s->path, m->line[0], m->line[0] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT,
                     "medium \"%s\"", m->name);
        RRV__CK(rrv__medium_check(&ck, m));
        for (w = 0; w < 4; ++w) {
            const rrv_field *f = rrv__medium_field_of(m, (rrv_medium_field)w);
            if (f->kind == RRV_FIELD_NONE) continue;
            rrv__ck_init(&ck, err, s->path, m->line[1 + w],
                         m->line[1 + w] ? RRV_ERROR_PARSE : RRV_ERROR_ARGUMENT, "%s of medium \"%s\"",
                         rrv__medium_field_names[w], m->name);
            RRV__CK(rrv__field_check(&ck, (rrv_medium_field)w, m, f, 0));
        }
    }
    return RRV_OK;
}

/* -- freeing a scene and counting its bytes -- */

static void rrv__sf_field_free(rrv_field *f)
{
    RRV_FREE(f->blobs);
    RRV_FREE(f->grid.data);
    rrv_nanovdb_free(&f->nanovdb);
    f->blobs = NULL;
    f->grid.data = NULL;
}

RRV_DEF void rrv_scene_free(rrv_scene *scene)
{
    int i;
    if (!scene) return;
    rrv__scene_release_prepared(scene);
    for (i = 0; i < scene->medium_count; ++i) {
        rrv__sf_field_free(&scene->media[i].density);
        rrv__sf_field_free(&scene->media[i].temperature);
        rrv__sf_field_free(&scene->media[i].pressure);
        rrv__sf_field_free(&scene->media[i].ior);
    }
    RRV_FREE(scene->materials);
    RRV_FREE(scene->shapes);
    RRV_FREE(scene->media);
    RRV_FREE(scene);
}

static size_t rrv__sf_field_bytes(const rrv_field *f)
{
    size_t b = rrv__sf_blob_capacity(f->blob_count) * sizeof(rrv_blob);
    if (f->grid.data)
        b += (size_t)f->grid.nx * (size_t)f->grid.ny * (size_t)f->grid.nz *
             (size_t)f->grid.channels * sizeof(float);
    b += f->nanovdb.size;
    return b;
}

static size_t rrv__sf_scene_bytes(const rrv_scene *s)
{
    size_t b = sizeof *s + (size_t)s->material_capacity * sizeof(rrv_material) +
               (size_t)s->shape_capacity * sizeof(rrv_shape) +
               (size_t)s->medium_capacity * sizeof(rrv_medium);
    int i;
    for (i = 0; i < s->medium_count; ++i)
        b += rrv__sf_field_bytes(&s->media[i].density) +
             rrv__sf_field_bytes(&s->media[i].temperature) +
             rrv__sf_field_bytes(&s->media[i].pressure) + rrv__sf_field_bytes(&s->media[i].ior);
    return b;
}

/* -- the public calls -- */

/* An edit invalidates what prepare built, and the bytes are counted anew. */
static void rrv__api_edited(rrv_scene *s)
{
    int i, w;
    rrv__scene_release_prepared(s);
    s->grid_bytes = 0;
    for (i = 0; i < s->medium_count; ++i)
        for (w = 0; w < 4; ++w) {
            const rrv_field *f = rrv__medium_field_of(&s->media[i], (rrv_medium_field)w);
            s->grid_bytes += rrv__sf_field_bytes(f) - rrv__sf_blob_capacity(f->blob_count) * sizeof(rrv_blob);
        }
    s->bytes = rrv__sf_scene_bytes(s);
}

RRV_DEF rrv_result rrv_scene_create(rrv_scene **out, rrv_error *err)
{
    rrv__clear_error(err);
    if (!out) return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_create: NULL argument");
    *out = rrv__scene_new("scene");
    if (!*out) return rrv__fail(err, RRV_ERROR_MEMORY, "scene", 0, "out of memory");
    (*out)->bytes = sizeof **out;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_set_camera(rrv_scene *scene, const rrv_camera *camera, rrv_error *err)
{
    rrv_camera c;
    rrv__ck ck;
    rrv__clear_error(err);
    if (!scene || !camera)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_set_camera: NULL argument");
    c = *camera;
    rrv__camera_def(&c);
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "camera");
    RRV__CK(rrv__camera_check(&ck, &c));
    scene->camera = c;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_set_settings(rrv_scene *scene, const rrv_settings *settings,
                                          rrv_error *err)
{
    rrv_settings s;
    rrv__ck ck, ambient;
    rrv__clear_error(err);
    if (!scene || !settings)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_set_settings: NULL argument");
    s = *settings;
    rrv__settings_def(&s);
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "settings");
    rrv__ck_init(&ambient, err, scene->path, 0, RRV_ERROR_ARGUMENT, "settings: ambient");
    RRV__CK(rrv__settings_check(&ck, &ambient, &s));
    rrv__api_edited(scene); /* majorant_cells and the bakes depend on settings */
    scene->settings = s;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_set_environment(rrv_scene *scene, const rrv_environment *env,
                                             rrv_error *err)
{
    rrv_environment e;
    rrv__ck ck;
    rrv__clear_error(err);
    if (!scene || !env)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_set_environment: NULL argument");
    e = *env;
    rrv__environment_def(&e);
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "environment");
    RRV__CK(rrv__environment_check(&ck, &e));
    scene->environment = e;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_add_material(rrv_scene *scene, const rrv_material *material,
                                          int *index, rrv_error *err)
{
    rrv_material m;
    rrv__ck ck;
    rrv_result r;
    rrv__clear_error(err);
    if (!scene || !material)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_add_material: NULL argument");
    m = *material;
    m.name[sizeof m.name - 1] = '\0';
    rrv__material_def(&m);
    rrv__name_default(scene, m.name, 0);
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "material \"%s\"", m.name);
    r = rrv__store_material(&ck, scene, &m, index);
    rrv__api_edited(scene);
    return r;
}

static rrv_result rrv__api_shape_material(rrv__ck *ck, rrv_scene *scene, rrv_shape *s)
{
    int index;
    if (scene->material_count > 0 || s->material != 0) return RRV_OK;
    RRV__CK(rrv__default_material(ck, scene, &index));
    s->material = index;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_add_shape(rrv_scene *scene, const rrv_shape *shape, int *index,
                                       rrv_error *err)
{
    rrv_shape s;
    rrv__ck ck;
    rrv_result r;
    rrv__clear_error(err);
    if (!scene || !shape)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_add_shape: NULL argument");
    s = *shape;
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "shape %d (%s)", scene->shape_count,
                 rrv__shape_name(s.kind));
    r = rrv__api_shape_material(&ck, scene, &s);
    if (r == RRV_OK) r = rrv__store_shape(&ck, scene, &s);
    if (r == RRV_OK && index) *index = scene->shape_count - 1;
    rrv__api_edited(scene);
    return r;
}

RRV_DEF rrv_result rrv_scene_add_triangles(rrv_scene *scene, const rrv_shape *proto,
                                           const double *points, int point_count,
                                           const int *indices, int triangle_count, rrv_error *err)
{
    rrv_shape s;
    rrv__ck ck;
    rrv_result r = RRV_OK;
    int i, c;
    rrv__clear_error(err);
    if (!scene || !proto || (point_count > 0 && !points) || (triangle_count > 0 && !indices) ||
        point_count < 0 || triangle_count < 0)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_add_triangles: invalid argument");
    s = *proto;
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "mesh");
    r = rrv__api_shape_material(&ck, scene, &s);
    for (i = 0; i < triangle_count && r == RRV_OK; ++i) {
        rrv_vec3 v[3];
        for (c = 0; c < 3; ++c) {
            int k = indices[3 * i + c];
            if (k < 0 || k >= point_count) {
                r = rrv__ck_fail(&ck, RRV_OK, "index %d is out of range (%d points)", k, point_count);
                break;
            }
            v[c] = rrv__v3(points[3 * k], points[3 * k + 1], points[3 * k + 2]);
        }
        if (r == RRV_OK) r = rrv__store_triangle(&ck, scene, v[0], v[1], v[2], &s);
    }
    rrv__api_edited(scene);
    return r;
}

RRV_DEF rrv_result rrv_scene_add_medium(rrv_scene *scene, const rrv_medium *medium, int *index,
                                        rrv_error *err)
{
    rrv_medium m;
    rrv__ck ck;
    rrv_result r;
    rrv__clear_error(err);
    if (!scene || !medium)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "rrv_scene_add_medium: NULL argument");
    m = *medium;
    m.name[sizeof m.name - 1] = '\0';
    memset(m.line, 0, sizeof m.line);
    rrv__medium_def(&m);
    rrv__name_default(scene, m.name, 1);
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "medium \"%s\"", m.name);
    r = rrv__store_medium(&ck, scene, &m, index);
    rrv__api_edited(scene);
    return r;
}

/* A deep copy, so the scene owns every array it frees. */
static int rrv__field_copy(rrv_field *dst, const rrv_field *src)
{
    *dst = *src;
    dst->blobs = NULL;
    dst->grid.data = NULL;
    dst->nanovdb.buffer = NULL;
    if (src->kind == RRV_FIELD_BLOBS && src->blob_count > 0 && src->blobs) {
        size_t cap = rrv__sf_blob_capacity(src->blob_count);
        if (src->blob_count > RRV_MAX_BLOBS) return 1; /* refused by the check */
        dst->blobs = (rrv_blob *)RRV_MALLOC(cap * sizeof(rrv_blob));
        if (!dst->blobs) return 0;
        memcpy(dst->blobs, src->blobs, (size_t)src->blob_count * sizeof(rrv_blob));
    } else {
        dst->blob_count = 0;
    }
    if (src->kind == RRV_FIELD_GRID && src->grid.data && src->grid.nx > 0 && src->grid.ny > 0 &&
        src->grid.nz > 0 && src->grid.channels > 0) {
        size_t n = (size_t)src->grid.nx * (size_t)src->grid.ny * (size_t)src->grid.nz *
                   (size_t)src->grid.channels;
        dst->grid.data = (float *)RRV_MALLOC(n * sizeof(float));
        if (!dst->grid.data) return 0;
        memcpy(dst->grid.data, src->grid.data, n * sizeof(float));
    }
    if (src->kind == RRV_FIELD_NANOVDB && src->nanovdb.buffer && src->nanovdb.size > 0) {
        dst->nanovdb.buffer = (unsigned char *)RRV_MALLOC(src->nanovdb.size);
        if (!dst->nanovdb.buffer) return 0;
        memcpy(dst->nanovdb.buffer, src->nanovdb.buffer, src->nanovdb.size);
    } else {
        dst->nanovdb.size = 0;
    }
    return 1;
}

RRV_DEF rrv_result rrv_scene_set_field(rrv_scene *scene, int medium, rrv_medium_field which,
                                       const rrv_field *field, rrv_error *err)
{
    rrv_field f;
    rrv_medium *m;
    rrv__ck ck;
    rrv_result r;
    rrv__clear_error(err);
    if (!scene || !field || medium < 0 || medium >= scene->medium_count ||
        (unsigned)which > (unsigned)RRV_MEDIUM_IOR)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, scene ? scene->path : NULL, 0,
                         "rrv_scene_set_field: invalid argument");
    m = &scene->media[medium];
    rrv__ck_init(&ck, err, scene->path, 0, RRV_ERROR_ARGUMENT, "%s of medium \"%s\"",
                 rrv__medium_field_names[which], m->name);
    if (!rrv__field_copy(&f, field)) {
        rrv__sf_field_free(&f);
        return rrv__ck_fail(&ck, RRV_ERROR_MEMORY, "out of memory");
    }
    rrv__field_def(&f, which, m);
    r = rrv__field_check(&ck, which, m, &f, 0);
    if (r != RRV_OK) {
        rrv__sf_field_free(&f);
        return r;
    }
    rrv__sf_field_free(rrv__medium_field_of(m, which));
    *rrv__medium_field_of(m, which) = f;
    m->line[1 + which] = 0;
    m->source[1 + which][0] = '\0';
    rrv__api_edited(scene);
    return RRV_OK;
}

/* >> 12 curved NEE (module): shoot, the cones, the manifold walk ==============
   Connections to lights along bent rays that a solver finds: nee SHOOT and
   MANIFOLD, with the cones, in the one block RRV_NO_CURVED_NEE leaves out.
   What every build keeps (the face jumps and weak-chord classes that sort
   paths, nee AIM, the light point a connection aims at) is in >> 9, before
   the path tracer; the tracer and render reach this section only through
   the curved-NEE interface declared there, defined at this section's end
   (the stubs after #else are what a build without it gets). */

/* Shots a solve may take: of the solves that converged within 40, 99 % took 15 or fewer. */
#define RRV__SOLVE_ITERATIONS 20
#define RRV__SOLVE_TRIALS 64          /* trials that estimate 1/p before Russian roulette (shoot, manifold) */
#define RRV__SOLVE_RESTARTS 3         /* seeds a solve may try */
/* eikonal: a solve first converges with steps at most this much longer
   (rrv__solve_coarse_step), each turning a ray by at most about
   RRV__SOLVE_COARSE_BEND radians */
#ifndef RRV__SOLVE_COARSE
#define RRV__SOLVE_COARSE 8
#endif
#ifndef RRV__SOLVE_COARSE_BEND
#define RRV__SOLVE_COARSE_BEND 0.6
#endif
#define RRV__SOLVE_SAME_ROOT 1e-5     /* roots whose directions differ less are one */
/* Halvings of the Newton step a solve may make: on the lens caustic (h =
   0.2, floor to light) 0.3 % of the solves that converged halved more than
   twice, and every one that failed by halving halved four times or more,
   after 9.4 shots on average (test/bench/RESULTS.md). */
#ifndef RRV__SOLVE_HALVINGS
#define RRV__SOLVE_HALVINGS 3
#endif
#define RRV__SOLVE_SEGMENTS 200000L   /* a shot longer than this is a failed one */

/* RRV_NO_CURVED_NEE leaves out the solvers of nee shoot and manifold and
   the cones that go with them; nee aim, the weak-chord classes and the
   face jumps stay (>> 9). Such a build supports no scene for solving, so the
   default integrator never picks eikonal for its shooting and the default
   nee aims; an explicit shoot or manifold is refused (rrv__settings_check). */
#ifndef RRV_NO_CURVED_NEE
/* ---- nee SHOOT: a curved connection solved by Newton's method ------------
   nee SHOOT (eikonal integrator). A connection from a vertex x0 to a point y
   on an area light along the bent ray is found by Newton's method on the two
   angles of the initial direction w0, the ray traced with exactly the
   segments a camera ray takes (rrv__plan_segment / rrv__finish_segment: RK4
   or leapfrog steps, straight chords between them, faces). The residual is
   the offset of y from where the path first crosses the light's plane from
   its front (for two interior points, as in the tests: from the chord that
   passes y, in the plane through y perpendicular to it). Its Jacobian comes from
   the variational (Jacobi-field) equations of the very same discrete steps,
   which need the Hessian of eta (rrv__eta_gradient_hessian). At the root
   dw0 = dA_y |cos theta_y| / |det J_perp|, J_perp the 2x2 derivative of the
   endpoint perpendicular to the arriving chord with respect to w0 per unit
   solid angle (r^2 I for straight rays: cos / r^2). */

/* Can shooting differentiate this medium's IOR? Every kind rrv__refractivity_
   hessian has a derivative for: the closed-form profiles, blobs, and grids
   (gridvol or NanoVDB, baked or not, trilinear or cubic: the derivative of
   the gradient the rays use), for a gas through the chain rule. Noise is
   always baked into a grid by prepare and differentiated as that grid (the
   noise's own value is a sum of hashed lattice octaves whose gradient rrv
   never evaluates). */
static int rrv__solver_supports(const rrv_medium *m)
{
    if (!rrv__medium_refracts(m)) return 1;
    if (m->ior_from_gas) {
        rrv_field_kind t = rrv__field_of(m, RRV__TEMPERATURE)->kind, p = rrv__field_of(m, RRV__PRESSURE)->kind;
        return t != RRV_FIELD_NOISE && p != RRV_FIELD_NOISE;
    }
    switch (rrv__field_of(m, RRV__IOR)->kind) {
    case RRV_FIELD_CONSTANT:
    case RRV_FIELD_SLAB:
    case RRV_FIELD_LUNEBURG:
    case RRV_FIELD_FISHEYE:
    case RRV_FIELD_SHELL:
    case RRV_FIELD_BLOBS:
    case RRV_FIELD_GRID:
    case RRV_FIELD_NANOVDB:
        return 1;
    default:
        return 0;
    }
}

static int rrv__solver_supports_scene(const rrv_scene *scene)
{
    int i;
    for (i = 0; i < scene->medium_count; ++i)
        if (!rrv__solver_supports(&scene->media[i])) return 0;
    return 1;
}

/* Eta, its gradient (rrv__eta_gradient's) and the gradient's derivative
   at p (row-major, d grad_i / d x_j; not symmetric in grids, see the
   media section), the medium found once; with value_grad also the
   derivative of eta itself, which a trilinear grid's blended gradient is
   not (rrv__refraction_lookup_jacobian_fused). */
static double rrv__eta_gradient_hessian(const rrv_scene *scene, rrv_vec3 p, rrv_vec3 *grad, double H[9],
                                        rrv_vec3 *value_grad)
{
    double ambient_r = rrv__ambient_ior(scene) - 1.0;
    int i, k;
    for (i = scene->medium_count - 1; i >= 0; --i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && rrv__inside_box(p, m->lo, m->hi))
            return 1.0 + rrv__refractivity_gradient_hessian(m, p, ambient_r, grad, H, value_grad);
    }
    for (k = 0; k < 9; ++k) H[k] = 0;
    *grad = rrv__v3(0, 0, 0);
    if (value_grad) *value_grad = *grad;
    return 1.0 + ambient_r;
}

static rrv_vec3 rrv__mat_apply(const double H[9], rrv_vec3 v)
{
    return rrv__v3(H[0] * v.x + H[1] * v.y + H[2] * v.z, H[3] * v.x + H[4] * v.y + H[5] * v.z,
                   H[6] * v.x + H[7] * v.y + H[8] * v.z);
}

/* Derivatives of a ray's position and unit direction with respect to the
   two angles of its initial direction. */
typedef struct rrv__jacobi { rrv_vec3 x[2], d[2]; } rrv__jacobi;

/* What one eikonal step of length h looked up at its stages (eta, its
   gradient and the gradient's derivative: four points for RK4, x and the
   drift's end for leapfrog) and made of them, so that a shot takes the
   step and carries its Jacobi field through it from one set of lookups. */
typedef struct rrv__step_stages {
    double h;
    rrv_vec3 x[4], v[4], g[4];
    rrv_vec3 ge[4];   /* grad of eta's value (rrv__eta_gradient_hessian), where eta divides */
    double eta[4], H[4][9];
    rrv_vec3 v1;      /* eta d at the step's end, before the renormalisation */
} rrv__step_stages;

/* rrv__eikonal_step from (x, d), the same arithmetic and so the same
   *x_out, *d_out and return bit for bit (eta and its gradient from
   rrv__eta_gradient_hessian are rrv__eta_gradient's), keeping its stages. */
static int rrv__eikonal_step_staged(const rrv_scene *scene, rrv_stepper stepper, double h, rrv_vec3 x, rrv_vec3 d,
                                    rrv_vec3 *x_out, rrv_vec3 *d_out, rrv__step_stages *st)
{
    double spread = 0, eta = rrv__eta_gradient_hessian(scene, x, &st->g[0], st->H[0], &st->ge[0]);
    rrv_vec3 v = rrv__scale(d, eta);
    st->h = h;
    st->x[0] = x;
    st->v[0] = v;
    st->eta[0] = eta;
    if (stepper != RRV_STEPPER_LEAPFROG) {
        rrv_vec3 kx[4];
        int s;
        kx[0] = rrv__scale(v, 1.0 / eta);
        for (s = 1; s < 4; ++s) {
            const double reach = s < 3 ? 0.5 * h : h;
            st->x[s] = rrv__madd(x, kx[s - 1], reach);
            st->v[s] = rrv__madd(v, st->g[s - 1], reach);
            st->eta[s] = rrv__eta_gradient_hessian(scene, st->x[s], &st->g[s], st->H[s], &st->ge[s]);
            kx[s] = rrv__scale(st->v[s], 1.0 / st->eta[s]);
        }
        *x_out = rrv__madd(x, rrv__add(rrv__add(kx[0], kx[3]), rrv__scale(rrv__add(kx[1], kx[2]), 2.0)), h / 6.0);
        st->v1 = rrv__madd(v, rrv__add(rrv__add(st->g[0], st->g[3]), rrv__scale(rrv__add(st->g[1], st->g[2]), 2.0)),
                           h / 6.0);
        spread = rrv__length(rrv__sub(rrv__add(st->g[0], st->g[3]), rrv__add(st->g[1], st->g[2])));
    } else {
        /* rrv__leapfrog_kdk; the half-kicked v is kept in v[0] */
        st->v[0] = rrv__madd(v, st->g[0], 0.5 * h);
        st->x[1] = *x_out = rrv__madd(x, st->v[0], h / eta);
        st->eta[1] = rrv__eta_gradient_hessian(scene, st->x[1], &st->g[1], st->H[1], &st->ge[1]);
        st->v1 = rrv__madd(st->v[0], st->g[1], 0.5 * h * st->eta[1] / eta);
    }
    *d_out = rrv__normalize(st->v1);
    return h * spread > RRV__FEATURE_BEND * eta;
}

/* Carries a Jacobi field through the step whose stages st holds (from
   (x, d) as rrv__eikonal_step_staged took it): the exact derivative of that
   discrete map, including the renormalisation of the direction that ends
   the step. */
static void rrv__step_stages_jacobi(const rrv__step_stages *st, rrv_stepper stepper, rrv_vec3 d, rrv__jacobi *J)
{
    const double h = st->h, eta = st->eta[0];
    const rrv_vec3 g = st->ge[0];
    rrv_vec3 dx[2], dv[2], v1 = st->v1;
    int j;
    for (j = 0; j < 2; ++j) {
        dx[j] = J->x[j];
        dv[j] = rrv__madd(rrv__scale(d, rrv__dot(g, dx[j])), J->d[j], eta); /* v = eta(x) d */
    }
    if (stepper != RRV_STEPPER_LEAPFROG) {
        static const double reach[3] = {0.5, 0.5, 1.0}, weight[4] = {1, 2, 2, 1};
        rrv_vec3 sx[2], sv[2], ax[2], av[2];
        int s;
        /* both columns stage by stage */
        for (j = 0; j < 2; ++j) {
            ax[j] = sx[j] = dx[j];
            av[j] = sv[j] = dv[j];
        }
        for (s = 0; s < 4; ++s) {
            const double wh = weight[s] * h / 6.0, inv_e = 1.0 / st->eta[s], inv_e2 = inv_e * inv_e;
            for (j = 0; j < 2; ++j) {
                /* d(v / eta) = dv / eta - v (grad eta . dx) / eta^2; d(grad eta) = H dx */
                rrv_vec3 kxs = rrv__sub(rrv__scale(sv[j], inv_e), rrv__scale(st->v[s], rrv__dot(st->ge[s], sx[j]) * inv_e2));
                rrv_vec3 kvs = rrv__mat_apply(st->H[s], sx[j]);
                ax[j] = rrv__madd(ax[j], kxs, wh);
                av[j] = rrv__madd(av[j], kvs, wh);
                if (s < 3) {
                    sx[j] = rrv__madd(dx[j], kxs, reach[s] * h);
                    sv[j] = rrv__madd(dv[j], kvs, reach[s] * h);
                }
            }
        }
        for (j = 0; j < 2; ++j) {
            J->x[j] = ax[j];
            dv[j] = av[j];
        }
        /* the end's eta d summed stage by stage, as the columns are (it
           differs from the step's own sum in rounding only) */
        v1 = st->v[0];
        for (s = 0; s < 4; ++s) v1 = rrv__madd(v1, st->g[s], weight[s] * h / 6.0);
    } else {
        /* kick (h/2) grad eta, drift (h / eta) v, kick (h/2) (eta1/eta) grad eta1 */
        const rrv_vec3 vh = st->v[0], g1 = st->g[1];
        const double eta1 = st->eta[1];
        for (j = 0; j < 2; ++j) {
            rrv_vec3 dvh = rrv__madd(dv[j], rrv__mat_apply(st->H[0], dx[j]), 0.5 * h);
            double ge = rrv__dot(st->ge[0], dx[j]);
            rrv_vec3 dx1 = rrv__add(dx[j], rrv__scale(rrv__sub(rrv__scale(dvh, 1.0 / eta),
                                                                 rrv__scale(vh, ge / (eta * eta))), h));
            double deta1 = rrv__dot(st->ge[1], dx1);
            rrv_vec3 kick = rrv__add(rrv__scale(g1, (deta1 / eta - eta1 * ge / (eta * eta))),
                                     rrv__scale(rrv__mat_apply(st->H[1], dx1), eta1 / eta));
            J->x[j] = dx1;
            dv[j] = rrv__madd(dvh, kick, 0.5 * h);
        }
    }
    {
        double inv_n1 = 1.0 / rrv__length(v1);
        rrv_vec3 d1 = rrv__scale(v1, inv_n1);
        for (j = 0; j < 2; ++j) J->d[j] = rrv__scale(rrv__madd(dv[j], d1, -rrv__dot(d1, dv[j])), inv_n1);
    }
}

/* rrv__eikonal_step_controlled with rrv__eikonal_step_staged: the same step,
   its stages in st. */
static double rrv__eikonal_step_controlled_staged(const rrv_scene *scene, rrv_stepper stepper, double h, rrv_vec3 x,
                                                  rrv_vec3 d, rrv_vec3 *x_out, rrv_vec3 *d_out, rrv__step_stages *st,
                                                  int *halvings)
{
    *halvings = 0;
    while (rrv__eikonal_step_staged(scene, stepper, h, x, d, x_out, d_out, st) && *halvings < 12 &&
           h > 4 * RRV__EDGE_NUDGE) {
        h *= 0.5;
        ++*halvings;
    }
    return h;
}

/* How a step's length moves with the ray's two angles (dh[0..1]), from
   its derivative with respect to the start point and direction
   (rrv__eikonal_step_length's grad) and the Jacobi field J there, times
   scale (a step halved by the stepper's control is that share of it). */
static void rrv__step_length_moves(const rrv__jacobi *J, const double grad[6], double scale, double dh[2])
{
    int j;
    for (j = 0; j < 2; ++j)
        dh[j] = scale * (grad[0] * J->x[j].x + grad[1] * J->x[j].y + grad[2] * J->x[j].z +
                         grad[3] * J->d[j].x + grad[4] * J->d[j].y + grad[5] * J->d[j].z);
}

/* How an RK4 step's end (*dx) and end direction (*dd) move with its length
   h, from the stages it looked up: the exact derivative of the discrete
   map, stage by stage (x_s = x + c_s h k_(s-1), v_s = v + c_s h g_(s-1), g_s
   moving by H_s dx_s). Where the field is smooth it is the curve's tangent
   and turning at the end; where a face ends the gradient inside the step
   (a stage past it, or a grid's box a rounding short of the medium's) it
   is not, and the end's turning alone missed the derivative by up to 10 %
   of the direction's field (nee shoot 3-5 % low past such faces). */
static void rrv__step_moves_with_h(const rrv__step_stages *st, rrv_vec3 *dx, rrv_vec3 *dd)
{
    static const double reach[3] = {0.5, 0.5, 1.0}, weight[4] = {1, 2, 2, 1};
    const double h = st->h;
    rrv_vec3 kx[4], dkx[4], dg[4], sum_k = rrv__v3(0, 0, 0), sum_dk = sum_k, sum_g = sum_k, sum_dg = sum_k, dv1, d1;
    int s;
    kx[0] = rrv__scale(st->v[0], 1.0 / st->eta[0]);
    dkx[0] = dg[0] = rrv__v3(0, 0, 0);
    for (s = 1; s < 4; ++s) {
        rrv_vec3 dxs = rrv__scale(rrv__madd(kx[s - 1], dkx[s - 1], h), reach[s - 1]);
        rrv_vec3 dvs = rrv__scale(rrv__madd(st->g[s - 1], dg[s - 1], h), reach[s - 1]);
        double inv_e = 1.0 / st->eta[s];
        dg[s] = rrv__mat_apply(st->H[s], dxs);
        kx[s] = rrv__scale(st->v[s], inv_e);
        dkx[s] = rrv__sub(rrv__scale(dvs, inv_e), rrv__scale(st->v[s], rrv__dot(st->ge[s], dxs) * inv_e * inv_e));
    }
    for (s = 0; s < 4; ++s) {
        sum_k = rrv__madd(sum_k, kx[s], weight[s]);
        sum_dk = rrv__madd(sum_dk, dkx[s], weight[s]);
        sum_g = rrv__madd(sum_g, st->g[s], weight[s]);
        sum_dg = rrv__madd(sum_dg, dg[s], weight[s]);
    }
    *dx = rrv__add(rrv__scale(sum_k, 1.0 / 6.0), rrv__scale(sum_dk, h / 6.0));
    dv1 = rrv__add(rrv__scale(sum_g, 1.0 / 6.0), rrv__scale(sum_dg, h / 6.0));
    d1 = rrv__normalize(st->v1);
    *dd = rrv__scale(rrv__madd(dv1, d1, -rrv__dot(d1, dv1)), 1.0 / rrv__length(st->v1));
}

/* A step's end moved along the curve by dh: the Jacobi field J1 at the end
   gains the curve's direction and its turning (the gradient of eta across
   it, over eta) times dh; for RK4, the step map's own derivative in its
   length (rrv__step_moves_with_h, st its stages). */
static int rrv__step_end_moves(const rrv_scene *scene, const rrv__bender *b, rrv_vec3 o, rrv_vec3 d, double len,
                               const double dh[2], const rrv__step_stages *st, rrv__jacobi *J1)
{
    rrv_vec3 g1, kappa;
    double eta1;
    int j;
    if (dh[0] == 0 && dh[1] == 0) return 1;
    if (scene->settings.stepper != RRV_STEPPER_LEAPFROG) {
        rrv_vec3 dx, dd;
        rrv__step_moves_with_h(st, &dx, &dd);
        for (j = 0; j < 2; ++j) {
            J1->x[j] = rrv__madd(J1->x[j], dx, dh[j]);
            J1->d[j] = rrv__madd(J1->d[j], dd, dh[j]);
        }
        return 1;
    }
    eta1 = rrv__eta_gradient(scene, rrv__madd(o, d, len), &g1);
    kappa = rrv__scale(rrv__madd(g1, b->next_d, -rrv__dot(b->next_d, g1)), 1.0 / eta1);
    for (j = 0; j < 2; ++j) {
        J1->x[j] = rrv__madd(J1->x[j], b->next_d, dh[j]);
        J1->d[j] = rrv__madd(J1->d[j], kappa, dh[j]);
    }
    return 1;
}

/* rrv__plan_segment for a shot's eikonal bender, with the Jacobi field:
   the same segment, direction and bender state bit for bit (it follows
   rrv__plan_segment's eikonal branch and rrv__eikonal_plan, and
   rrv__finish_segment then runs as after them), each step's stages looked
   up once for the step and its Jacobi field, and the faces that cut the
   step known from planning it. J holds the field at o; for a step (END_STEP)
   *J1 gets it at the step's end. A step shorter than the scene's (h <
   step) may have a length that depends on where it starts, and so does
   where the curve hands over to the straight segment behind it: dh enters
   as x1 += d1 dh, d1 += kappa1 dh (kappa1 = dd/ds at x1). The plan asks for
   min(step, t_face - nudge) along the straight line, which the step control
   may halve k times, exactly: then h = (t_face(x, d) - nudge) 2^-k,
   differentiated exactly (dh = 0 if the scene's step was asked for: halving
   alone moves nothing). Or, when the chord itself reached a face and the
   step was taken again shorter, the step's end is held on that face (the
   nudge neglected); that second step halved by the control (its end short
   of the face, its length a function of the first step's chord) has no
   derivative here and counts as a grazing face. Returns 0 at a grazing
   face. */
static int rrv__shoot_plan(rrv__bender *b, const rrv_scene *scene, rrv_vec3 o, rrv_vec3 *d, const rrv__jacobi *J,
                           rrv__jacobi *J1)
{
    double step_grad[6];
    const double nudge = RRV__EDGE_NUDGE, step = rrv__eikonal_step_length(b, scene, o, *d, step_grad);
    const rrv_stepper stepper = scene->settings.stepper;
    rrv__support_view view, along;
    rrv__step_stages st;
    rrv_vec3 d_start = *d, x1, chord;
    double h, first, len, dh[2], nd, asked, scale = 1.0, slack, reach = rrv__safe_reach(b, scene, o);
    int j, halvings, again = 0, seen = !rrv__safe_for_step(step, reach);
    b->line_d = *d;
    rrv__reciprocals(*d, b->line_inv);
    if (seen) rrv__look_along(scene, o, *d, &view);
    else rrv__safe_view(b, reach, &view);
    rrv__eikonal_view(b, o, *d, step + 2 * nudge, &view, &b->cell_face);
    b->pending = 1;
    b->segment = view.t_face;
    b->end = view.t_face < DBL_MAX ? RRV__END_FACE : RRV__END_NONE;
    b->normal = view.normal;
    b->surface_free = 0;
    b->face_known = 0;
    if (!view.inside || !(view.t_face > 2 * nudge)) return 1;
    first = fmin(step, view.t_face - nudge);
    h = rrv__eikonal_step_controlled_staged(scene, stepper, first, o, d_start, &x1, &b->next_d, &st, &halvings);
    chord = rrv__sub(x1, o);
    len = rrv__length(chord);
    if (reach < len + nudge) rrv__look_along(scene, o, rrv__scale(chord, 1.0 / len), &along);
    else along.t_face = DBL_MAX;
    rrv__chord_edge(b, o, rrv__scale(chord, 1.0 / len), len + nudge, &along);
    if (along.t_face < len + nudge && along.t_face > 2 * nudge) {
        /* which cut made the step is told below by the view's own t_face
           (the slack) and normal, which the bound does not give */
        if (!seen) {
            int cell_face;
            rrv__look_along(scene, o, d_start, &view);
            rrv__eikonal_view(b, o, d_start, step + 2 * nudge, &view, &cell_face);
        }
        h = rrv__eikonal_step_controlled_staged(scene, stepper, h * (along.t_face - nudge) / len, o, d_start, &x1,
                                                &b->next_d, &st, &again);
        chord = rrv__sub(x1, o);
        len = rrv__length(chord);
    }
    *d = rrv__scale(chord, 1.0 / len);
    b->h = h;
    b->segment = len;
    b->end = RRV__END_STEP;
    *J1 = *J;
    rrv__step_stages_jacobi(&st, stepper, d_start, J1);
    if (!(h < step)) {
        /* the whole step, whose length the field placed (it moves with the ray) */
        rrv__step_length_moves(J, step_grad, 1.0, dh);
        return rrv__step_end_moves(scene, b, o, *d, len, dh, &st, J1);
    }
    /* which cut made h: told apart by its length, as a step of the first
       cut rounded differently would be */
    asked = h;
    /* (a view from the safety bound has its own t_face, but there first is
       step, which a step only halved doubles back to exactly, and the
       return below is taken whatever the slack) */
    slack = 1e-12 * (1.0 + view.t_face);
    for (halvings = 0; halvings < 12 && asked < first - slack; ++halvings) {
        asked *= 2.0;
        scale *= 0.5;
    }
    if (fabs(asked - first) <= slack) {
        if (!(view.t_face - nudge < step)) { /* halved, not cut */
            rrv__step_length_moves(J, step_grad, scale, dh);
            return rrv__step_end_moves(scene, b, o, *d, len, dh, &st, J1);
        }
        nd = rrv__dot(view.normal, d_start);
        if (!(fabs(nd) > 1e-9 * rrv__length(view.normal))) return 0;
        for (j = 0; j < 2; ++j)
            dh[j] = -scale * rrv__dot(view.normal, rrv__madd(J->x[j], J->d[j], view.t_face)) / nd;
    } else {
        {
            int cell_face;
            rrv__look_along(scene, o, *d, &view);
            rrv__eikonal_view(b, o, *d, 1.5 * len, &view, &cell_face);
        }
        if (!(view.t_face < 1.5 * len)) return 0; /* the second step halved */
        nd = rrv__dot(view.normal, b->next_d);
        if (!(fabs(nd) > 1e-9 * rrv__length(view.normal))) return 0;
        for (j = 0; j < 2; ++j) dh[j] = -rrv__dot(view.normal, J1->x[j]) / nd;
    }
    return rrv__step_end_moves(scene, b, o, *d, len, dh, &st, J1);
}

enum { RRV__SHOT_REACHED, RRV__SHOT_MISSED, RRV__SHOT_INTERFACE, RRV__SHOT_BLOCKED };

typedef struct rrv__shot {
    int status;
    int curved;        /* part of the path lies in a refraction support */
    rrv_vec3 end;      /* where the path passes y: on the chord through y's plane */
    rrv_vec3 dir;      /* that chord's direction */
    rrv_vec3 de[2];    /* d(end)/d(angles of w0) */
    long segments;
    double fresnel;    /* the share its sharp faces transmit: the product of 1 - F */
} rrv__shot;

/* The straight chords of one shot that reached y, kept so that the
   transmittance along the root a solve found can be tracked without
   tracing the root again (rrv__kept_transmittance): from x[i] along d[i]
   for len[i], the last one ending where the shot passes y. A shot of more
   chords than fit is not kept (n = -1). */
#define RRV__CHORDS_KEPT 256
typedef struct rrv__chords {
    int n;
    rrv_vec3 x[RRV__CHORDS_KEPT], d[RRV__CHORDS_KEPT];
    double len[RRV__CHORDS_KEPT];
    double fresnel; /* the shot's: the share its sharp faces transmit */
} rrv__chords;

static void rrv__keep_chord(rrv__chords *kept, rrv_vec3 x, rrv_vec3 d, double len)
{
    if (kept->n < 0) return;
    if (kept->n == RRV__CHORDS_KEPT) { kept->n = -1; return; }
    kept->x[kept->n] = x;
    kept->d[kept->n] = d;
    kept->len[kept->n++] = len;
}

/* A shot across a sharp interface at a box's face (at, met along unit d,
   normal along an axis): Snell's law with the refractivities just behind
   and just past it, as rrv__cross_face refracts, and the Jacobi field's
   directions carried across. With mu = eta_behind / eta_past, c = -n.d
   (n turned to face the ray) and k = sqrt(1 - mu^2 (1 - c^2)), the ray
   leaves along d' = mu d + (mu c - k) n, so
     dd' = dmu d + mu dd + (dmu c + mu dc - dk) n,
     dc = -n.dd, dk = (mu^2 c dc - mu dmu (1 - c^2)) / k,
   dmu from the two refractivities' gradients along the face point's move
   (J1->x, already on the face; J->d the directions behind it). *share
   gets the transmitted share 1 - F. Returns 1 where the face is such a
   jump (rrv__face_jumps's test, from the same two lookups), 0 where it
   is none (nothing changed), -1 where the face reflects totally or is a
   sphere's rim (a curved face: left to the forward paths, as every sharp
   face was before 0.16.0). */
static int rrv__shot_refracts(const rrv_scene *scene, rrv_vec3 at, rrv_vec3 d, rrv_vec3 normal, const rrv__jacobi *J,
                              rrv__jacobi *J1, double *share)
{
    double gap = rrv__face_gap(at), r_behind, r_past, mu, c, k;
    rrv_vec3 g_behind, g_past, n;
    int j;
    r_behind = rrv__scene_refractivity(scene, rrv__madd(at, d, -gap), &g_behind);
    r_past = rrv__scene_refractivity(scene, rrv__madd(at, d, gap), &g_past);
    if (!rrv__jump_counts(fabs(r_past - r_behind))) return 0;
    if ((normal.x == 0) + (normal.y == 0) + (normal.z == 0) != 2) return -1;
    n = rrv__axis_unit(normal);
    mu = (1.0 + r_behind) / (1.0 + r_past);
    c = -rrv__dot(n, d);
    if (c < 0) {
        n = rrv__scale(n, -1.0);
        c = -c;
    }
    k = 1.0 - mu * mu * (1.0 - c * c);
    if (!(k > 0)) return -1;
    k = sqrt(k);
    for (j = 0; j < 2; ++j) {
        rrv_vec3 dx = J1->x[j], dd = J->d[j];
        double dmu = (rrv__dot(g_behind, dx) * (1.0 + r_past) - (1.0 + r_behind) * rrv__dot(g_past, dx)) /
                     ((1.0 + r_past) * (1.0 + r_past));
        double dc = -rrv__dot(n, dd), dk = (mu * mu * c * dc - mu * dmu * (1.0 - c * c)) / k;
        J1->d[j] = rrv__madd(rrv__madd(rrv__scale(d, dmu), dd, mu), n, dmu * c + mu * dc - dk);
    }
    *share = 1.0 - rrv__fresnel(1.0 + r_behind, 1.0 + r_past, c, k);
    return 1;
}

/* Traces the ray from x0 along w0 (tangent basis e1, e2 of the two angles)
   until it passes y: where it first crosses the plane through y with
   normal *plane from its front (a light's), or with plane NULL, where the
   chord through y's perpendicular plane is. With T, also tests every chord
   for surfaces (BLOCKED) and ratio-tracks the transmittance along them,
   and skips the Jacobi field (out->de is then undefined): that shot
   retraces a root whose solve already had it. With kept, records the
   chords of the shot (valid where it reached y). */
static void rrv__shoot_kept(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, rrv_vec3 e1, rrv_vec3 e2, rrv_vec3 y,
                            const rrv_vec3 *plane, rrv__rng *rng, double T[3], rrv__chords *kept, rrv__shot *out)
{
    const rrv_scene *scene = ctx->scene;
    rrv__bender b;
    rrv__jacobi J;
    rrv__rng fixed; /* faces crossed here do not reflect (jumps up to RRV__SOLVE_JUMP) */
    rrv_vec3 x = x0, d = w0;
    long n;
    int c;
    rrv__rng_seed(&fixed, 0, 0, 0);
    rrv__bender_start(&b, scene, 1, x0);
    b.refract_only = 1;
    out->fresnel = 1.0;
    J.x[0] = J.x[1] = rrv__v3(0, 0, 0);
    J.d[0] = e1;
    J.d[1] = e2;
    out->curved = rrv__in_support(scene, x0);
    if (T) T[0] = T[1] = T[2] = 1.0;
    if (kept) {
        kept->n = 0;
        kept->fresnel = 1.0;
    }
    for (n = 0; n < RRV__SOLVE_SEGMENTS; ++n) {
        rrv_vec3 dc[2];
        rrv__jacobi J1 = J;
        double len, s;
        int j;
        if (T) rrv__plan_segment(&b, scene, x, &d, &fixed);
        else if (!rrv__shoot_plan(&b, scene, x, &d, &J, &J1)) break;
        len = b.segment;
        if (b.end == RRV__END_STEP && T) {
            for (j = 0; j < 2; ++j) dc[j] = J.d[j];
        } else if (b.end == RRV__END_STEP) {
            for (j = 0; j < 2; ++j) {
                rrv_vec3 w = rrv__scale(rrv__sub(J1.x[j], J.x[j]), 1.0 / len);
                dc[j] = rrv__madd(w, d, -rrv__dot(w, d));
            }
        } else {
            for (j = 0; j < 2; ++j) dc[j] = J.d[j];
        }
        if (plane) {
            /* crossing the light's plane from its front: the first place a
               forward path could hit the light */
            double h0 = rrv__dot(rrv__sub(x, y), *plane), cn = rrv__dot(d, *plane);
            s = cn < 0 && h0 > 0 && h0 <= -cn * len ? h0 / -cn : DBL_MAX;
        } else {
            /* passing y: the chord's closest point to it, looked for only
               where the path runs toward y (it may start away from it) */
            s = rrv__dot(rrv__sub(y, x), d);
            if (s < 0) s = DBL_MAX;
        }
        if (s < DBL_MAX && s <= len) {
            if (kept) rrv__keep_chord(kept, x, d, s);
            out->end = rrv__madd(x, d, s);
            out->dir = d;
            for (j = 0; j < 2; ++j) {
                rrv_vec3 de = rrv__madd(J.x[j], dc[j], s);
                /* on the light's plane, the endpoint moves along it (the
                   chord's oblique projection); perpendicular planes drop
                   the part along d in the residual */
                out->de[j] = plane ? rrv__madd(de, d, -rrv__dot(*plane, de) / rrv__dot(d, *plane)) : de;
            }
            out->segments = n + 1;
            out->status = RRV__SHOT_REACHED;
            if (T) {
                rrv__hit hit;
                double Ts[3], tmax = s * (1.0 - 1e-6);
                ++ctx->stats.paths;
                if (rrv__intersect_scene(scene, x, d, tmax, &hit)) { out->status = RRV__SHOT_BLOCKED; return; }
                rrv__transmittance(ctx, x, d, tmax, rng, Ts);
                for (c = 0; c < 3; ++c) T[c] *= Ts[c];
            }
            return;
        }
        if (b.end == RRV__END_NONE) break; /* straight on forever, never passing y */
        if (kept) rrv__keep_chord(kept, x, d, len);
        if (T) {
            rrv__hit hit;
            double Ts[3];
            if (rrv__intersect_scene(scene, x, d, len, &hit)) { out->status = RRV__SHOT_BLOCKED; return; }
            rrv__transmittance(ctx, x, d, len, rng, Ts);
            for (c = 0; c < 3; ++c) T[c] *= Ts[c];
        }
        if (b.end == RRV__END_FACE) {
            /* The face point x + L d, L(x, d) its distance, moves on the face:
               dL = -N.(dx + L dd) / N.d. Not a small term: where the face
               ends a gradient (a Luneburg sphere), entering earlier or later
               bends the ray by a finite amount (the saltation of the
               variational equations across a jump of grad eta). */
            double nd = rrv__dot(b.normal, d), share;
            int jump;
            if (!(fabs(nd) > 1e-9 * rrv__length(b.normal))) break; /* grazing */
            for (j = 0; j < 2; ++j) {
                rrv_vec3 moved = rrv__madd(J.x[j], J.d[j], len);
                J1.x[j] = rrv__madd(moved, d, -rrv__dot(b.normal, moved) / nd);
            }
            /* a sharp interface: refracted (b.refract_only), its share
               1 - F carried as a weight, the directions' field across it */
            jump = b.cell_face ? 0 : rrv__shot_refracts(scene, rrv__madd(x, d, len), d, b.normal, &J, &J1, &share);
            if (jump < 0) {
                out->status = RRV__SHOT_INTERFACE;
                return;
            }
            if (jump) {
                out->fresnel *= share;
                if (kept) kept->fresnel *= share;
                if (T)
                    for (c = 0; c < 3; ++c) T[c] *= share;
            }
        }
        out->curved = 1;
        rrv__finish_segment(&b, scene, &x, &d, &fixed);
        if (b.reflected) { /* totally, where the test above saw none: rounding */
            out->status = RRV__SHOT_INTERFACE;
            return;
        }
        J = J1; /* a face without a jump leaves the direction as it was */
    }
    out->status = RRV__SHOT_MISSED;
}

static void rrv__shoot(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, rrv_vec3 e1, rrv_vec3 e2, rrv_vec3 y,
                       const rrv_vec3 *plane, rrv__rng *rng, double T[3], rrv__shot *out)
{
    rrv__shoot_kept(ctx, x0, w0, e1, e2, y, plane, rng, T, NULL, out);
}

/* The transmittance along the chords a shot kept, tracked as rrv__shoot
   with T tracks it along the same chords (the same tests and random
   numbers in the same order): 0 if a surface blocks them. */
static int rrv__kept_transmittance(rrv__context *ctx, const rrv__chords *kept, rrv__rng *rng, double T[3])
{
    int i, c;
    T[0] = T[1] = T[2] = 1.0;
    for (i = 0; i < kept->n; ++i) {
        rrv__hit hit;
        double Ts[3], len = kept->len[i];
        if (i == kept->n - 1) {
            ++ctx->stats.paths;
            len *= 1.0 - 1e-6;
        }
        if (rrv__intersect_scene(ctx->scene, kept->x[i], kept->d[i], len, &hit)) return 0;
        rrv__transmittance(ctx, kept->x[i], kept->d[i], len, rng, Ts);
        for (c = 0; c < 3; ++c) T[c] *= Ts[c];
    }
    for (c = 0; c < 3; ++c) T[c] *= kept->fresnel;
    return 1;
}

/* The residual (offset of y from the path in the light's plane, or in the
   plane through y perpendicular to the arriving chord) and its 2x2
   Jacobian: J_plane, or J_perp = J_plane |cos theta_y|. */
static void rrv__shot_residual(const rrv__shot *s, rrv_vec3 y, const rrv_vec3 *plane, double r[2], double Jp[4])
{
    rrv_vec3 f1, f2, off = rrv__sub(y, s->end);
    rrv__frame(plane ? *plane : s->dir, &f1, &f2);
    r[0] = rrv__dot(off, f1);
    r[1] = rrv__dot(off, f2);
    Jp[0] = rrv__dot(f1, s->de[0]);
    Jp[1] = rrv__dot(f1, s->de[1]);
    Jp[2] = rrv__dot(f2, s->de[0]);
    Jp[3] = rrv__dot(f2, s->de[1]);
}

typedef struct rrv__root {
    rrv_vec3 w0;      /* initial direction */
    rrv_vec3 dir;     /* arriving chord direction at y */
    double det;       /* det J_plane (on a light's plane) or J_perp, m^2 per steradian */
    int curved;
    long segments;
    int iterations;
    rrv_vec3 ahead;   /* w0 moved by one more Newton step (the linear model's root) if under 1e-4 rad, else w0:
                         where a polish starts */
} rrv__root;

/* Newton's method on the two angles of w0 from a seed direction, the step
   halved on a failed or worsening shot and doubled (up to 1) on success,
   each step at most 0.5 rad, until the residual is below tolerance (1 +
   |y - x0|). Returns 1 with the root, 0 if it did not converge, met a
   sharp interface, or stalled at a caustic (det J = 0). */
static int rrv__solve_shot_to(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 y, const rrv_vec3 *plane, rrv_vec3 seed,
                              double tolerance, rrv__chords *kept, rrv__root *root)
{
    rrv_vec3 w = seed, w_prev = seed, e1, e2, p1 = rrv__v3(0, 0, 0), p2 = p1;
    double prev_norm = DBL_MAX, step = 1.0, delta[2] = {0, 0};
    double tol = tolerance * (1.0 + rrv__length(rrv__sub(y, x0)));
    int it, have_prev = 0, halvings = 0;
    root->iterations = 0;
    for (it = 0; it < RRV__SOLVE_ITERATIONS; ++it) {
        rrv__shot shot;
        double r[2] = {0, 0}, Jp[4] = {0, 0, 0, 0}, norm, det, len;
        rrv__frame(w, &e1, &e2);
        rrv__shoot_kept(ctx, x0, w, e1, e2, y, plane, NULL, NULL, kept, &shot);
        root->iterations = it + 1;
        if (shot.status == RRV__SHOT_INTERFACE) return 0;
        norm = DBL_MAX;
        if (shot.status == RRV__SHOT_REACHED) {
            rrv__shot_residual(&shot, y, plane, r, Jp);
            norm = sqrt(r[0] * r[0] + r[1] * r[1]);
        }
        if (!(norm < prev_norm)) {
            /* worse, or lost: back to the last good direction, half the
               step. A solve that halved RRV__SOLVE_HALVINGS times in all
               (or the step to 1/8) is one whose linear model is wrong (on
               the lens caustic: a ray grazing a support's rim, whose
               endpoint moves as the square root of its depth) */
            if (!have_prev || ++halvings >= RRV__SOLVE_HALVINGS) return 0;
            step *= 0.5;
            if (step < 1.0 / 8) return 0;
            w = rrv__normalize(rrv__add(w_prev, rrv__add(rrv__scale(p1, step * delta[0]), rrv__scale(p2, step * delta[1]))));
            continue;
        }
        det = Jp[0] * Jp[3] - Jp[1] * Jp[2];
        if (norm < tol) {
            if (!(fabs(det) > 0) || !(fabs(det) < DBL_MAX)) return 0;
            root->w0 = w;
            root->dir = shot.dir;
            root->det = det;
            root->curved = shot.curved;
            root->segments = shot.segments;
            {
                /* the linear model's root, unless its step is large (a
                   nearly singular J, by a caustic): then the root itself */
                double a1 = (Jp[3] * r[0] - Jp[1] * r[1]) / det, a2 = (Jp[0] * r[1] - Jp[2] * r[0]) / det;
                root->ahead = a1 * a1 + a2 * a2 < 1e-8
                                  ? rrv__normalize(rrv__add(w, rrv__add(rrv__scale(e1, a1), rrv__scale(e2, a2))))
                                  : w;
            }
            return 1;
        }
        /* a singular Jacobian is a caustic: no finite density */
        if (!(fabs(det) > 1e-14 * (Jp[0] * Jp[0] + Jp[1] * Jp[1] + Jp[2] * Jp[2] + Jp[3] * Jp[3]))) return 0;
        if (have_prev) step = fmin(1.0, 2.0 * step);
        have_prev = 1;
        prev_norm = norm;
        w_prev = w;
        p1 = e1;
        p2 = e2;
        delta[0] = (Jp[3] * r[0] - Jp[1] * r[1]) / det;
        delta[1] = (Jp[0] * r[1] - Jp[2] * r[0]) / det;
        len = sqrt(delta[0] * delta[0] + delta[1] * delta[1]);
        if (len > 0.5) { delta[0] *= 0.5 / len; delta[1] *= 0.5 / len; }
        w = rrv__normalize(rrv__add(w_prev, rrv__add(rrv__scale(p1, step * delta[0]), rrv__scale(p2, step * delta[1]))));
    }
    return 0;
}

/* A solve to the polish's tolerance, the chords of its last shot in kept
   (may be NULL). */
static int rrv__solve_shot(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 y, const rrv_vec3 *plane, rrv_vec3 seed,
                           rrv__chords *kept, rrv__root *root)
{
    return rrv__solve_shot_to(ctx, x0, y, plane, seed, 1e-9, kept, root);
}

/* Seeds for the solver: a Gaussian around the straight direction to y, of
   0.05 rad (six times in ten) or 0.3 rad (three in ten), or a uniform
   direction (one in ten), so that every root's basin has a nonzero
   probability and the trials below are unbiased. The narrow one starts
   where the straight chord runs, inside the support: on the lens caustic
   a seed whose ray passes beside a Luneburg lens, where the endpoint moves
   as the square root of the depth of a grazing ray, sends Newton across
   the rim and back (measured there, floor to light: 0.3 rad alone
   converged 63 % of solves, this mixture 83 %; test/bench/RESULTS.md). */
static rrv_vec3 rrv__solver_seed(rrv_vec3 x0, rrv_vec3 y, rrv__rng *rng)
{
    double u = rrv__uniform(rng), u1 = rrv__uniform(rng), u2 = rrv__uniform(rng);
    if (u < 0.9) {
        double rad = (u < 0.6 ? 0.05 : 0.3) * sqrt(-2.0 * log(1.0 - u1)), phi = 2.0 * RRV__PI * u2;
        rrv_vec3 w = rrv__normalize(rrv__sub(y, x0)), t, b;
        rrv__frame(w, &t, &b);
        return rrv__normalize(rrv__add(w, rrv__add(rrv__scale(t, rad * cos(phi)), rrv__scale(b, rad * sin(phi)))));
    }
    return rrv__sample_uniform_sphere(u1, u2);
}

/* The step of a solve's coarse stage: RRV__SOLVE_COARSE times step (the
   scene's for shoot, a chain's mean spacing for manifold), but no longer
   than turns a ray at the steepest gradient of any support by bend
   radians (|d'| = |grad_perp eta| / eta; shoot's RRV__SOLVE_COARSE_BEND),
   and never shorter than step. The coarse stage only has to land its
   root in the basin where the polish at the scene's step converges in a
   shot or two. Longer is not safe: a root whose basin the coarse stage
   never converges to has probability zero, a bias, not noise. At 32x the
   scene's step (1.6 m on scenes/fire_caustic.rrv, whose hot blobs are
   0.1-0.2 m across) the caustic rendered 2 % dark, 6 standard errors off
   its reference in a block of the test of test/ref/, while the lens
   caustic's crop at its step 0.01 was 27 % faster. The bend's cap matters
   where the scene's step is long: on scenes/lens_caustic.rrv at step 0.2
   (eikonal, nee shoot, 64x48 crop, 8 spp, one thread) 8x took 1.45 s of
   CPU and the scene's own step 1.03 s; the cap gives 0.3 there (the
   lens's peak |grad eta| is 2 per metre). */
static double rrv__coarse_of(const rrv_scene *scene, double step, double bend, double eta_floor)
{
    double coarse = RRV__SOLVE_COARSE * step, peak = 0;
    int i;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && m->majorant && m->majorant->grad_peak > peak) peak = m->majorant->grad_peak;
    }
    if (peak > 0) coarse = rrv__mind(coarse, bend * eta_floor / peak);
    return rrv__maxd(coarse, step);
}

static double rrv__solve_coarse_step(const rrv_scene *scene, double eta_floor)
{
    return rrv__coarse_of(scene, rrv__step(scene), RRV__SOLVE_COARSE_BEND, eta_floor);
}

/* The last polish of one connection's solves (rrv__solve_shot_seeded):
   its seed and what it returned. */
typedef struct rrv__polish_memo {
    int valid;
    rrv_vec3 seed;
    int found;
    rrv__root root;
} rrv__polish_memo;

/* A direction on the lattice of spacing 2^-26 (1.5e-8) in each component,
   renormalised. The coarse roots that two solves of one connection reach
   from different seeds differ by 1e-15 to 1e-10 after the step to the
   linear model's root (measured on scenes/haze.rrv), and the polish's
   first shot misses y by ~1e-5 (the coarse steps' error), so the
   lattice's offsets are lost in the polish while the two seeds nearly
   always land on the same point. */
static rrv_vec3 rrv__snap_direction(rrv_vec3 w)
{
    const double per = 67108864.0; /* 2^26: the products and quotients are exact */
    return rrv__normalize(
        rrv__v3(floor(w.x * per + 0.5) / per, floor(w.y * per + 0.5) / per, floor(w.z * per + 0.5) / per));
}

/* A solve from seeds of rrv__solver_seed (rrv__solve_shot_seeded): up to
   RRV__SOLVE_RESTARTS of them, the next drawn when the last failed, so
   that a solve fails only when all did. Each seed (rrv__solve_shot_one,
   which adds its shots to *shots) is first converged (to 1e-6) with the longer
   eikonal steps of rrv__solve_coarse_step, a small part of the work a
   shot, and the camera rays' steps then polish that root (two or three
   shots), from
   the linear model's root at the coarse one snapped to a lattice
   (rrv__snap_direction): only the polished root counts, so this is one
   more deterministic map from seeds to roots. Every call draws its own
   seeds, so trials stay independent and identically distributed. The
   polish is a function of its seed alone (x0, y and the plane fixed), so
   with memo (one per connection, valid 0 at first) a polish whose seed
   is the last one's returns the last one's result without shooting:
   the repeated trials of a connection, which find the same root, cost a
   coarse solve each. With kept, the chords of the last shot taken are
   kept there (those of the root where one was found by shooting).
   root->iterations counts the shots taken. */
static int rrv__solve_shot_one(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 y, const rrv_vec3 *plane, rrv_vec3 seed,
                               rrv__polish_memo *memo, rrv__chords *kept, rrv__root *root, int *shots)
{
    rrv_scene coarse_scene = *ctx->scene;
    rrv__context coarse = *ctx;
    rrv__root near;
    int found;
    if (ctx->eikonal) {
        /* a context set up by hand (tests) may leave eta_floor 0 */
        coarse_scene.settings.step = rrv__solve_coarse_step(ctx->scene, ctx->eta_floor > 0 ? ctx->eta_floor : 1.0);
        coarse.scene = &coarse_scene;
        found = rrv__solve_shot_to(&coarse, x0, y, plane, seed, 1e-6, NULL, &near);
        *shots += near.iterations;
        if (!found) return 0;
        seed = rrv__snap_direction(near.ahead);
        if (memo && memo->valid && seed.x == memo->seed.x && seed.y == memo->seed.y && seed.z == memo->seed.z) {
            *root = memo->root;
            if (kept) kept->n = -1; /* not shot here */
            return memo->found;
        }
    }
    found = rrv__solve_shot(ctx, x0, y, plane, seed, kept, root);
    *shots += root->iterations;
    if (memo && ctx->eikonal) {
        memo->valid = 1;
        memo->seed = seed;
        memo->found = found;
        memo->root = *root;
    }
    return found;
}

static int rrv__solve_shot_seeded(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 y, const rrv_vec3 *plane, rrv__rng *rng,
                                  rrv__polish_memo *memo, rrv__chords *kept, rrv__root *root)
{
    int k, shots = 0, found = 0;
    for (k = 0; k < RRV__SOLVE_RESTARTS && !found; ++k)
        found = rrv__solve_shot_one(ctx, x0, y, plane, rrv__solver_seed(x0, y, rng), memo, kept, root, &shots);
    root->iterations = shots;
    return found;
}


/* The plane a shot toward light point y (normal ny) is solved in: a quad's
   or triangle's own, where the ray first crosses it from its front; for a
   sphere none (NULL), the solve aims the ray through y across its arriving
   chord, since a sphere's tangent plane at a point near its rim is crossed
   at a grazing angle, where the crossing point races along the plane and
   Newton's linear model fails (on a small sphere through a lens, 13 % of
   solves on the tangent plane failed). */
static const rrv_vec3 *rrv__shoot_plane(const rrv_shape *s, const rrv_vec3 *ny)
{
    return s->kind == RRV_SHAPE_SPHERE ? NULL : ny;
}

/* A root's det J_plane on the light's surface at y (normal ny): solved on
   the light's plane it is the solve's own; solved across the arriving
   chord (a sphere), det J_perp / |cos theta_y|, the area at y a unit of
   the chord's cross-section covers. 0 where the chord arrives from behind
   the surface or along it. */
static double rrv__root_det_on_light(const rrv__root *root, const rrv_vec3 *plane, rrv_vec3 ny)
{
    double cos_y;
    if (plane) return root->det;
    cos_y = -rrv__dot(root->dir, ny);
    return cos_y > 0 ? root->det / cos_y : 0.0;
}

/* The MIS weight of curved NEE for a curved path x0 -> y on light s whose
   initial direction w0 the vertex samples with density pdf_dir, the
   endpoint moving on the light's plane as dA_y = |det| dw0: the power
   heuristic between NEE's solid-angle density, had every solve found the
   root (|det| times the light point's area density), and pdf_dir. The forward path's weight is
   one minus it, computed from the same two numbers. */
static double rrv__shoot_mis_weight(double pdf_area, double det, double pdf_dir)
{
    return rrv__power_heuristic(fabs(det) * pdf_area, pdf_dir);
}

/* The MIS weight of a forward path that left the vertex x0 along w0
   (density pdf_dir), touched a refraction support without crossing a sharp
   interface and hit the light s at x: the one shot that curved NEE would
   trace for it, from x0 along w0 with the same steps and in the same
   plane (rrv__shoot_plane), gives its |det J_plane| at x. Where that shot
   does not pass x as the solve's residual measures it (it first crossed
   a quad's plane beside the light, an earlier chord of a shot toward a
   sphere came closest to x, a face grazed), or no draw names x (a
   sphere's side x0 does not see), no solve can return this path and the
   forward path keeps it whole. */
static double rrv__shoot_forward_weight(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, double pdf_dir, const rrv_shape *s,
                                        rrv_vec3 x)
{
    rrv_vec3 ny, e1, e2;
    const rrv_vec3 *plane;
    rrv__shot shot;
    rrv__root root;
    double r[2], Jp[4], det, pdf_area = rrv__light_area_pdf(ctx->scene, s, x0, x);
    if (!(pdf_area > 0)) return 1.0;
    ny = s->kind == RRV_SHAPE_SPHERE ? rrv__scale(rrv__sub(x, s->center), 1.0 / s->radius)
                                     : rrv__normalize(rrv__cross(s->e1, s->e2));
    plane = rrv__shoot_plane(s, &ny);
    rrv__frame(w0, &e1, &e2);
    rrv__shoot(ctx, x0, w0, e1, e2, x, plane, NULL, NULL, &shot);
    if (shot.status != RRV__SHOT_REACHED || !shot.curved) return 1.0;
    rrv__shot_residual(&shot, x, plane, r, Jp);
    if (!(sqrt(r[0] * r[0] + r[1] * r[1]) <= 1e-6 * (1.0 + rrv__length(rrv__sub(x, x0))))) return 1.0;
    root.det = Jp[0] * Jp[3] - Jp[1] * Jp[2];
    root.dir = shot.dir;
    det = rrv__root_det_on_light(&root, plane, ny);
    if (!(fabs(det) > 0) || !(fabs(det) < DBL_MAX)) return 1.0;
    return 1.0 - rrv__shoot_mis_weight(pdf_area, det, pdf_dir);
}

/* An unbiased estimate of 1/p from independent Bernoulli(p) trials
   (trial(user, rng) != 0 a success), with bounded expected work.
   Counting the trials up to the first success, N, is the plain estimate:
   N = sum_i [N >= i], and P(N >= i) = (1 - p)^(i-1) sums to 1/p; but
   its work is 1/p too, unbounded as p -> 0, and stopping at a cap M
   estimates (1 - (1 - p)^M) / p instead, low by the factor 1 - (1 -
   p)^M (a root with p = 1/200 counted at 27 % under M = 64). Here the
   trials beyond `start` continue by Russian roulette: trial i > start is
   made only if the walk survives to it, with probability S_i = (start /
   i)^2 (a survival draw with probability ((i - 1) / i)^2 before each),
   independent of the trials, and a trial made adds 1 / S_i. Then
   E[estimate] = sum_i P(N >= i) S_i / S_i = sum_i (1 - p)^(i-1) = 1/p
   exactly, for every p > 0. The expected number of trials is at most
   start + sum_(i > start) S_i < 2 start + 1 whatever p, and because
   S_i falls only polynomially the variance, sum_i (1 - p)^(i-1) / S_i
   and the cross terms, is finite for every p > 0 (a geometric roulette,
   S_i = q^(i - start), would leave it infinite for 1 - p >= q). Up to
   `start` trials it is the plain count and draws nothing else. */
typedef int (*rrv__trial_func)(void *user, rrv__rng *rng);
static double rrv__inverse_probability(rrv__rng *rng, int start, rrv__trial_func trial, void *user, long *trials)
{
    double estimate = 0;
    long i;
    for (i = 1;; ++i) {
        double survive = 1.0;
        if (i > start) {
            double q = (double)(i - 1) / (double)i;
            if (!(rrv__uniform(rng) < q * q)) { --i; break; }
            survive = (double)start / (double)i;
            survive *= survive;
        }
        estimate += 1.0 / survive;
        if (trial(user, rng)) break;
    }
    *trials = i;
    return estimate;
}

/* One trial of shoot's 1/q estimate: a fresh solve from random seeds
   toward the same light point that comes back to the root w0. */
typedef struct rrv__shot_recurrence {
    rrv__context *ctx;
    rrv_vec3 x0, y, w0;
    const rrv_vec3 *plane;
    rrv__polish_memo *memo;
} rrv__shot_recurrence;
static int rrv__shot_recurs(void *user, rrv__rng *rng)
{
    rrv__shot_recurrence *t = (rrv__shot_recurrence *)user;
    rrv__root again;
    int found;
    ++t->ctx->stats.solves;
    found = rrv__solve_shot_seeded(t->ctx, t->x0, t->y, t->plane, rng, t->memo, NULL, &again);
    t->ctx->stats.solve_iterations += (uint64_t)again.iterations;
    if (!found) return 0;
    ++t->ctx->stats.solves_converged;
    t->ctx->stats.solve_segments += (uint64_t)again.segments;
    return rrv__length(rrv__sub(again.w0, t->w0)) < RRV__SOLVE_SAME_ROOT;
}

/* What root carries from light point y to x0 per unit of its weight, into
   out (0 and no light where it carries none): the BSDF, the transmittance
   (the kept chords of its own solve, else a shot along it) and the
   measure's change, with shoot's MIS weight. */
static int rrv__shoot_carried(rrv__context *ctx, const rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                              rrv_vec3 y, rrv_vec3 ny, const rrv_vec3 *plane, double pdf_area,
                              const rrv__root *root, const rrv__chords *kept, rrv__rng *rng, double out[3])
{
    double T[3], f[3], det, k;
    int c;
    if (!root->curved || !(det = rrv__root_det_on_light(root, plane, ny))) return 0;
    rrv__vertex_eval(v, root->w0, f);
    if (!(rrv__max3(f) > 0)) return 0;
    if (kept->n > 0) {
        /* the root's own chords: its last shot in the solve */
        if (!rrv__kept_transmittance(ctx, kept, rng, T) || !rrv__nonzero3(T)) return 0;
    } else {
        rrv__shot shot;
        rrv_vec3 e1, e2;
        rrv__frame(root->w0, &e1, &e2);
        rrv__shoot(ctx, x0, root->w0, e1, e2, y, plane, rng, T, &shot);
        if (shot.status != RRV__SHOT_REACHED || !rrv__nonzero3(T)) return 0;
    }
    /* dw0 = dA_y / |det J_plane| (= dA_y |cos theta_y| / |det J_perp|) */
    k = rrv__shoot_mis_weight(pdf_area, det, rrv__vertex_pdf(v, root->w0)) / (fabs(det) * pdf_area) *
        rrv__eta_scale(ctx, y) * rrv__path_mis(path);
    for (c = 0; c < 3; ++c) out[c] = f[c] * T[c] * k;
    return 1;
}

/* The probability s of a connection's random try, after the chord's try
   (rrv__shoot_estimate, rrv__manifold_estimate): RRV__RANDOM_TRY, or 1
   where the chord's try failed and the random try is all there is (a
   choice that depends on the connection alone, so 1/(s q) stays exact).
   0: no random try this time. 1/2 measured best of 1/4, 1/2 and 1 on the
   lens caustic for both (test/bench/RESULTS.md, "The chord's root counted
   once"). */
#define RRV__RANDOM_TRY 0.5
static double rrv__random_try_share(int chord_found, rrv__rng *rng)
{
    if (!chord_found) return 1.0;
    return rrv__uniform(rng) < RRV__RANDOM_TRY ? RRV__RANDOM_TRY : 0.0;
}

/* A solve's work, into the stats. */
static void rrv__shoot_stats(rrv__context *ctx, int found, int shots, const rrv__root *root)
{
    ++ctx->stats.solves;
    ++ctx->stats.solve_trials;
    ctx->stats.solve_iterations += (uint64_t)shots;
    if (!found) return;
    ++ctx->stats.solves_converged;
    ctx->stats.solve_segments += (uint64_t)root->segments;
}

/* The estimate of one connection toward light point y (rrv__shoot_nee):
   the roots it counts, at most two, with their weights and what each
   carries (rrv__shoot_carried); returns how many. */
static int rrv__shoot_estimate(rrv__context *ctx, const rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                               rrv_vec3 y, rrv_vec3 ny, const rrv_vec3 *plane, double pdf_area, rrv__rng *rng,
                               rrv__root root[2], double weight[2], double carried[2][3])
{
    rrv__polish_memo memo;
    rrv__chords kept;
    rrv__root chord;
    rrv__shot_recurrence t;
    long count;
    int n = 0, shots = 0, chord_found, found;
    double share;
    memo.valid = 0;
    ++ctx->stats.solve_connections;
    chord_found = rrv__solve_shot_one(ctx, x0, y, plane, rrv__normalize(rrv__sub(y, x0)), &memo, &kept, &chord, &shots);
    rrv__shoot_stats(ctx, chord_found, shots, &chord);
    if (chord_found && rrv__shoot_carried(ctx, path, x0, v, y, ny, plane, pdf_area, &chord, &kept, rng, carried[0])) {
        root[0] = chord;
        weight[n++] = 1.0;
    }
    if (!(share = rrv__random_try_share(chord_found, rng))) return n;
    found = rrv__solve_shot_seeded(ctx, x0, y, plane, rng, &memo, &kept, &root[n]);
    rrv__shoot_stats(ctx, found, root[n].iterations, &root[n]);
    /* a random try that lands on the chord's root counts nothing */
    if (!found || (chord_found && rrv__length(rrv__sub(root[n].w0, chord.w0)) < RRV__SOLVE_SAME_ROOT) ||
        !rrv__shoot_carried(ctx, path, x0, v, y, ny, plane, pdf_area, &root[n], &kept, rng, carried[n]))
        return n;
    t.ctx = ctx;
    t.x0 = x0;
    t.y = y;
    t.plane = plane;
    t.w0 = root[n].w0;
    t.memo = &memo;
    weight[n] = rrv__inverse_probability(rng, RRV__SOLVE_TRIALS, rrv__shot_recurs, &t, &count) / share;
    ctx->stats.solve_trials += (uint64_t)count;
    return n + 1;
}

/* Curved NEE from vertex x0 by shooting: a point y uniform on one area
   light and two tries that split the roots of the two-point problem
   between them, as nee manifold's do (rrv__manifold_estimate): one from
   the chord's direction (a deterministic map, so its root counts once,
   weight 1), and with probability s (rrv__random_try_share) one from
   random seeds, whose root, if not the chord's, counts 1/(s q), 1/q estimated
   by repeating random solves until it recurs (Specular Manifold
   Sampling's estimate, Zeltner et al. 2020; past RRV__SOLVE_TRIALS
   trials by Russian roulette, rrv__inverse_probability: E = 1/q exactly).
   E = f(r_c) + sum over r != r_c of s q_r f(r) / (s q_r): every root once
   (test_shoot_estimate_is_unbiased). Only curved paths are counted here
   (part of them in a refraction support, no sharp interface crossed):
   straight ones belong to straight NEE. Curved paths to quad, triangle
   and sphere lights are shared with the forward path by the power
   heuristic (rrv__shoot_mis_weight): near a caustic |det| -> 0 and the
   forward path takes them, which keeps the estimate's 1/|det| bounded. A
   sphere's points are those x0 sees straight (rrv__pick_area_light): bent
   paths to its far side are the forward path's alone. The sky is left to
   forward paths. */
static void rrv__shoot_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                           const rrv__light_draw *draw, rrv__rng *rng)
{
    rrv_vec3 y, ny;
    rrv__root roots[2];
    double pdf_area, carried[2][3], weight[2];
    const rrv_shape *s = rrv__pick_area_light(ctx->scene, draw, x0, 1, &y, &ny, &pdf_area);
    /* a sphere's solve aims through y across the arriving chord (rrv__shoot_plane) */
    const rrv_vec3 *plane = s ? rrv__shoot_plane(s, &ny) : NULL;
    int n, i, c;
    if (!s) return;
    {
        double to_y = rrv__length(rrv__sub(y, x0));
        if (!(to_y > 0) || rrv__weak_chord(ctx, x0, rrv__scale(rrv__sub(y, x0), 1.0 / to_y), to_y)) return;
    }
    n = rrv__shoot_estimate(ctx, path, x0, v, y, ny, plane, pdf_area, rng, roots, weight, carried);
    for (i = 0; i < n; ++i)
        for (c = 0; c < 3; ++c) path->L[c] += path->beta[c] * carried[i][c] * s->L[c] * weight[i];
}


/* ---- rays drawn toward strong supports: the roots of weak chords ---------------------
   A connection whose straight chord passes beside a lens is straight
   NEE's (rrv__weak_chord), yet the lens may bend other rays from x0 onto
   the same point of the light: roots of that chord that no light sample
   stands for (rrv__forward_weak 2). Forward paths find them only as often
   as the vertex's own sampling sends rays into the lens, and carry the
   light's full radiance when they do: under small lights the heaviest
   tail of nee shoot's error (test/bench/RESULTS.md, "Weak connections"). So where a
   support turns rays strongly, nee shoot and manifold also draw at every
   vertex outside it one direction w0 uniformly in the cone of the sphere
   that bounds it (one support picked uniformly among those whose sphere
   does not hold x0), trace the bent ray along w0 as camera rays are traced,
   and count the light it lands on if the path is such a root. The density
   of w0 (rrv__cone_pdf) is a function of x0 and w0 alone, so the power
   heuristic against the vertex's own sampling is exact, and a forward
   path of that class weighs itself the same way. No light sample, no
   solve: the cost of one shadow ray. */

/* The strongly refracting supports of the scene and the spheres that
   bound them: a Luneburg or fish-eye profile's own sphere, else the
   medium's box's. Strong: the majorant's peak |grad eta| over the lowest
   eta, times the diameter, exceeds RRV__CONE_BEND. */
static void rrv__cone_setup(rrv__context *ctx)
{
    const rrv_scene *scene = ctx->scene;
    int i;
    ctx->cone_count = 0;
    for (i = 0; i < scene->medium_count && ctx->cone_count < RRV__CONE_MAX; ++i) {
        const rrv_medium *m = &scene->media[i];
        rrv_vec3 center;
        double radius;
        if (!rrv__medium_refracts(m) || !m->majorant) continue;
        if (rrv__has_sphere_support(m)) {
            center = m->ior.center;
            radius = m->ior.radius;
        } else {
            center = rrv__scale(rrv__add(m->lo, m->hi), 0.5);
            radius = 0.5 * rrv__length(rrv__sub(m->hi, m->lo));
        }
        if (!(radius > 0) || !((double)m->majorant->grad_peak * 2.0 * radius / ctx->eta_floor > RRV__CONE_BEND)) continue;
        ctx->cone_center[ctx->cone_count] = center;
        ctx->cone_radius[ctx->cone_count++] = radius;
    }
}

/* The squared sine of the half angle of support k's cone from x0 (*axis
   from x0 to its centre, *dist its length), or 0 where x0 is inside its
   sphere: no cone. */
static double rrv__cone_sin2(const rrv__context *ctx, int k, rrv_vec3 x0, rrv_vec3 *axis, double *dist)
{
    double r = ctx->cone_radius[k], d2;
    *axis = rrv__sub(ctx->cone_center[k], x0);
    d2 = rrv__dot(*axis, *axis);
    if (!(d2 > r * r * (1.0 + 1e-9))) return 0.0;
    *dist = sqrt(d2);
    return r * r / d2;
}

/* The solid-angle density with which rrv__cone_nee draws w0 from x0, the
   share of vertices that draw included. */
static double rrv__cone_pdf(const rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0)
{
    double sum = 0;
    int k, eligible = 0;
    for (k = 0; k < ctx->cone_count; ++k) {
        rrv_vec3 axis;
        double dist = 1, sin2 = rrv__cone_sin2(ctx, k, x0, &axis, &dist), cos_max;
        if (!(sin2 > 0)) continue;
        ++eligible;
        cos_max = sqrt(1.0 - sin2);
        /* over 2 pi (1 - cos_max), without the cancellation of small cones */
        if (rrv__dot(w0, axis) >= cos_max * dist) sum += (1.0 + cos_max) / (2.0 * RRV__PI * sin2);
    }
    return eligible ? RRV__CONE_RATE * sum / eligible : 0.0;
}

/* At a share RRV__CONE_RATE of the vertices, a direction from x0 uniform
   in the cone of one strong support, picked uniformly among those whose
   sphere does not hold x0, and its density (rrv__cone_pdf, the rate
   included); 0 where no ray is drawn (nothing at all where no support has
   a cone from x0) or the direction rounded out of its cone. */
static double rrv__cone_sample(const rrv__context *ctx, rrv_vec3 x0, rrv__rng *rng, rrv_vec3 *w0)
{
    rrv_vec3 axis = {0, 0, 1}, t, b;
    double dist = 1, sin2 = 0, u, u1, u2, one_minus_cos, sin_t;
    int pick, eligible = 0, k;
    for (k = 0; k < ctx->cone_count; ++k)
        if (rrv__cone_sin2(ctx, k, x0, &axis, &dist) > 0) ++eligible;
    if (!eligible) return 0.0;
    /* one statement each: C leaves the order of arguments unspecified */
    if (rrv__uniform(rng) >= RRV__CONE_RATE) return 0.0;
    u = rrv__uniform(rng);
    u1 = rrv__uniform(rng);
    u2 = rrv__uniform(rng);
    pick = (int)(u * eligible);
    if (pick >= eligible) pick = eligible - 1;
    for (k = 0; k < ctx->cone_count; ++k) {
        sin2 = rrv__cone_sin2(ctx, k, x0, &axis, &dist);
        if (sin2 > 0 && pick-- == 0) break;
    }
    /* 1 - cos theta uniform on [0, 1 - cos_max] */
    one_minus_cos = u1 * sin2 / (1.0 + sqrt(1.0 - sin2));
    sin_t = sqrt(fmax(0.0, one_minus_cos * (2.0 - one_minus_cos)));
    axis = rrv__scale(axis, 1.0 / dist);
    rrv__frame(axis, &t, &b);
    *w0 = rrv__normalize(rrv__add(rrv__scale(axis, 1.0 - one_minus_cos),
                                  rrv__add(rrv__scale(t, sin_t * cos(2.0 * RRV__PI * u2)),
                                           rrv__scale(b, sin_t * sin(2.0 * RRV__PI * u2)))));
    return rrv__cone_pdf(ctx, x0, *w0);
}

/* Where the bent ray from x0 along w0 lands as a root of a weak chord
   (rrv__forward_weak 2) on the front of a light: that light (*hit, T the
   transmittance up to it), else NULL. Sphere lights too: a forward path
   of that class weighs itself against the cones whatever light it hits. */
static const rrv_shape *rrv__cone_trace(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, rrv__rng *rng, rrv__hit *hit,
                                        double T[3])
{
    const rrv_shape *s;
    rrv_vec3 d = w0;
    double to_x;
    int met = rrv__aim_trace(ctx, x0, &d, rng, hit, T);
    if (met < 0) return NULL;
    s = &ctx->scene->shapes[met];
    if (!(s->L[0] > 0 || s->L[1] > 0 || s->L[2] > 0) || !(rrv__dot(hit->n, d) < 0)) return NULL;
    to_x = rrv__length(rrv__sub(hit->p, x0));
    if (!(to_x > 0) || rrv__forward_weak(ctx, x0, w0, rrv__scale(rrv__sub(hit->p, x0), 1.0 / to_x), to_x) != 2)
        return NULL;
    return s;
}

/* The ray toward a strong support from vertex x0 (the section's comment
   says why it is unbiased). Draws no random number where no support has
   a cone from x0, so scenes without strong supports render as before. */
static void rrv__cone_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v, rrv__rng *rng)
{
    rrv_vec3 w0;
    rrv__hit hit;
    double pdf_cone = rrv__cone_sample(ctx, x0, rng, &w0), f[3], T[3], k;
    const rrv_shape *s;
    int c;
    if (!(pdf_cone > 0) || !(pdf_cone < DBL_MAX)) return;
    rrv__vertex_eval(v, w0, f);
    if (!(f[0] > 0 || f[1] > 0 || f[2] > 0)) return;
    ++ctx->stats.cone_shots;
    if (!(s = rrv__cone_trace(ctx, x0, w0, rng, &hit, T))) return;
    ++ctx->stats.cone_counted;
    k = rrv__power_heuristic(pdf_cone, rrv__vertex_pdf(v, w0)) / pdf_cone * rrv__eta_scale(ctx, hit.p) *
        rrv__path_mis(path);
    for (c = 0; c < 3; ++c) path->L[c] += path->beta[c] * f[c] * T[c] * s->L[c] * k;
}

/* ---- nee MANIFOLD: a chain of refraction vertices moved by Newton ----------------
   The paper's refractive ratio tracking (section 2.3) with the generalised
   geometry term of Specular Manifold Sampling (Zeltner et al. 2020). A
   connection x0 -> y is a polyline x0, x_1 .. x_n, y. Vertices sit on the
   planes of a comb along the chord x0 -> y (spacing rrv_settings.step, one
   random offset for the whole estimate) over the part of the chord whose
   planes meet a refraction support, so every path from x0 to y through a
   support that runs forward along the chord has one vertex on each plane.
   Segment k has the IOR at its midpoint (the first and last at x0 and y);
   vertex k gives the ray the leapfrog kick of the ray equation, the comb
   integrator's own: the direction out is that of eta_(k-1) w_in + grad
   eta(x_k) h_k, h_k the length of path the vertex stands for (half the
   way to the planes beside it, the first and last to the ends of the
   support along the chord; rrv__chain_share), the gradient smeared over a
   band of one spacing where it jumps at a sphere support
   (rrv__chain_gradient); no kick where grad eta = 0. This is the comb
   model of the ray, second order in the spacing (test_nee: 1e-6 in
   direction and 5e-6 in density at h = 0.004). Snell's law between the
   segments' IORs, the earlier model, is as accurate away from grazing but
   jumps at total internal reflection where a ray turns (see
   rrv__chain_vertex), which kept 39 % of the lens caustic's solves from
   converging.
   Constraint, two per vertex: the two components of the outgoing
   direction across the kicked one, in a frame perpendicular to the
   kicked direction (to first order its two angle differences, no pole or
   2 pi wrap).
   Unknowns, two per vertex (the gauge): CHORD moves a vertex in its comb
   plane (perpendicular to the chord), ISO (the paper's) in the tangent
   plane of its IOR isosurface and projects it back onto the isosurface of
   eta at the chord's comb point; where grad eta ~ 0 the isosurface is
   undefined and ISO drops those planes; and its levels are the chord's,
   which a curved path through a lens's centre region need not reach, so
   ISO finds few roots there (measured in test/bench/RESULTS.md).
   The Jacobian is block tridiagonal with 2x2 blocks; the chain is solved
   by Levenberg-Marquardt, whose normal equations are block pentadiagonal
   and factored in O(n) (rrv__manifold_solve). At the root, block Thomas
   elimination of J (a singular pivot block: a caustic, the chain cannot
   follow y, fails the solve) with the derivative of the last
   residual with respect to y gives dx_1/dy and so the density of the
   connection, dw0/dA_y = |det (dw0/dy)|. A solve starts from a chain
   traced from a random direction and aimed at y by shooting
   (rrv__chain_aim). The chain's arrays are one heap block per render
   context (rrv__chain_new), not on the stack. */

#define RRV__CHAIN_MAX 512 /* comb planes a manifold chain may have (more: wider spacing) */
#define RRV__MANIFOLD_TOL 1e-9    /* max |residual| at a root (eta radians) */
#define RRV__MANIFOLD_FLAT 1e-9   /* |grad eta| below which a vertex has no isosurface */
#define RRV__MANIFOLD_ROOTS 8     /* distinct roots the fixed-trial variant keeps */
#define RRV__MANIFOLD_ITERATIONS 40 /* evaluations of the chain a trust-region solve may take */
#define RRV__AIM_ITERATIONS 16    /* shooting steps that seed a solve */

typedef struct rrv__chain {
    int n;                                /* inner vertices x[1..n] */
    int cap;                              /* most inner vertices the arrays hold */
    int iso;                              /* gauge ISO, else CHORD */
    int failed;                           /* a projection onto an isosurface failed */
    double h;                             /* spacing of the comb planes */
    double lo, hi;                        /* the chord's part the planes cover: (x - x0).c in [lo, hi] */
    rrv_vec3 c, c1, c2;                   /* chord direction and its frame */
    rrv_vec3 s1, s2;                      /* the light's tangent frame at y */
    /* arrays of cap + 2 entries, one allocation (rrv__chain_new) */
    double *t;                            /* vertex k's comb plane: (x - x0).c = t[k - 1] */
    double *level;                        /* ISO: eta of vertex k's isosurface */
    rrv_vec3 *x;                          /* x[0] = x0, x[n + 1] = y */
    rrv_vec3 *g;                          /* the gradient vertex k kicks with */
    double *em;                           /* of segment k: at its midpoint, at x0 for the first, y for the last */
    rrv_vec3 *gm;
    double *wa, *wb;                      /* d em_k = gm_k . (wa dx_k + wb dx_k+1) */
    rrv_vec3 *b1, *b2;                    /* gauge basis */
    double (*r)[2];                       /* residual of vertex k */
    double (*A)[4], (*B)[4], (*C)[4];     /* d r_k / d u_k-1, u_k, u_k+1 */
    double E[4];                          /* d r_n / d(y in the light's frame) */
    int *snell;                           /* ISO: vertex k has an isosurface normal nrm[k] */
    rrv_vec3 *nrm;
    /* the solver's workspace. A trial step is evaluated into the second
       half of the double-buffered state (xs, sb1, sb2, r_alt .. C_alt:
       positions, bases, residuals, Jacobian), which is swapped in when the
       step is taken and left when it is not, so a rejected step costs no
       evaluation of the chain it came from. */
    rrv_vec3 *xs, *sb1, *sb2;
    double (*r_alt)[2], (*A_alt)[4], (*B_alt)[4], (*C_alt)[4];
    double (*du)[4], (*Cp)[4];            /* rrv__chain_density's right-hand sides, Thomas's upper blocks */
    /* Levenberg-Marquardt: J^T J by blocks (diagonal, first and second
       below it), its LDL^T factors, Marquardt's scaling, J^T r, the step */
    double (*nd)[4], (*n1)[4], (*n2)[4];
    double (*l1)[4], (*l2)[4], (*dinv)[4];
    double (*scl)[2], (*grad)[2], (*step)[2];
} rrv__chain;

/* A chain for up to cap inner vertices in one RRV_MALLOC block (a render
   context holds one: ~250 KB at RRV__CHAIN_MAX, too much for a thread's
   stack); NULL when out of memory. */
static rrv__chain *rrv__chain_new(int cap)
{
    size_t slots = (size_t)cap + 2, doubles = 71, vectors = 9;
    size_t bytes = sizeof(rrv__chain) + slots * (doubles * sizeof(double) + vectors * sizeof(rrv_vec3) + sizeof(int));
    rrv__chain *ch = cap >= 0 ? (rrv__chain *)RRV_MALLOC(bytes) : NULL;
    double *d;
    rrv_vec3 *v;
    if (!ch) return NULL;
    memset(ch, 0, sizeof *ch);
    ch->cap = cap;
    /* doubles first (the struct ends on a pointer, so they are aligned), then vectors, then ints */
    d = (double *)(void *)(ch + 1);
    ch->t = d; d += slots;
    ch->level = d; d += slots;
    ch->em = d; d += slots;
    ch->wa = d; d += slots;
    ch->wb = d; d += slots;
    ch->r = (double (*)[2])d; d += 2 * slots;
    ch->A = (double (*)[4])d; d += 4 * slots;
    ch->B = (double (*)[4])d; d += 4 * slots;
    ch->C = (double (*)[4])d; d += 4 * slots;
    ch->r_alt = (double (*)[2])d; d += 2 * slots;
    ch->A_alt = (double (*)[4])d; d += 4 * slots;
    ch->B_alt = (double (*)[4])d; d += 4 * slots;
    ch->C_alt = (double (*)[4])d; d += 4 * slots;
    ch->du = (double (*)[4])d; d += 4 * slots;
    ch->Cp = (double (*)[4])d; d += 4 * slots;
    ch->nd = (double (*)[4])d; d += 4 * slots;
    ch->n1 = (double (*)[4])d; d += 4 * slots;
    ch->n2 = (double (*)[4])d; d += 4 * slots;
    ch->l1 = (double (*)[4])d; d += 4 * slots;
    ch->l2 = (double (*)[4])d; d += 4 * slots;
    ch->dinv = (double (*)[4])d; d += 4 * slots;
    ch->scl = (double (*)[2])d; d += 2 * slots;
    ch->grad = (double (*)[2])d; d += 2 * slots;
    ch->step = (double (*)[2])d; d += 2 * slots;
    v = (rrv_vec3 *)(void *)d;
    ch->x = v; v += slots;
    ch->g = v; v += slots;
    ch->gm = v; v += slots;
    ch->b1 = v; v += slots;
    ch->b2 = v; v += slots;
    ch->nrm = v; v += slots;
    ch->xs = v; v += slots;
    ch->sb1 = v; v += slots;
    ch->sb2 = v; v += slots;
    ch->snell = (int *)(void *)v;
    return ch;
}

static void rrv__chain_delete(rrv__chain *ch) { RRV_FREE(ch); }


/* 3x3 matrices row-major: M = s (I - w w^T), M += s a b^T, M = P Q. */
static void rrv__m3_proj(double M[9], rrv_vec3 w, double s)
{
    double v[3];
    int i, j;
    v[0] = w.x; v[1] = w.y; v[2] = w.z;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) M[3 * i + j] = s * ((i == j ? 1.0 : 0.0) - v[i] * v[j]);
}
static void rrv__m3_outer(double M[9], rrv_vec3 a, rrv_vec3 b, double s)
{
    double u[3], v[3];
    int i, j;
    u[0] = a.x; u[1] = a.y; u[2] = a.z;
    v[0] = b.x; v[1] = b.y; v[2] = b.z;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) M[3 * i + j] += s * u[i] * v[j];
}
static void rrv__m3_mul(const double P[9], const double Q[9], double M[9])
{
    int i, j, k;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) {
            double s = 0;
            for (k = 0; k < 3; ++k) s += P[3 * i + k] * Q[3 * k + j];
            M[3 * i + j] = s;
        }
}
/* The normal of the IOR's isosurface at x, whose tangent plane is the
   ISO gauge's: grad eta / |grad eta| in general; for a profile with a
   sphere support (Luneburg, fish-eye) the radial direction, which is that
   inside the sphere and stays defined beyond it (inside the box), where
   grad eta is 0. Returns 0 where there is none (grad eta ~ 0 away from a
   sphere support). */
static int rrv__vertex_normal(const rrv_scene *scene, rrv_vec3 x, rrv_vec3 g, rrv_vec3 *n)
{
    int i;
    double gl = rrv__length(g);
    for (i = scene->medium_count - 1; i >= 0; --i) {
        const rrv_medium *m = &scene->media[i];
        if (rrv__medium_refracts(m) && rrv__inside_box(x, m->lo, m->hi)) {
            if (rrv__has_sphere_support(m)) {
                rrv_vec3 d = rrv__sub(x, m->ior.center);
                double r = rrv__length(d);
                if (!(r > 1e-9 * m->ior.radius)) return 0;
                *n = rrv__scale(d, 1.0 / r);
                return 1;
            }
            break;
        }
    }
    if (!(gl > RRV__MANIFOLD_FLAT)) return 0;
    *n = rrv__scale(g, 1.0 / gl);
    return 1;
}

/* 2x2 helpers: inverse (0 if singular relative to its size), products. */
static int rrv__m2_inverse(const double M[4], double out[4])
{
    double det = M[0] * M[3] - M[1] * M[2];
    double size = M[0] * M[0] + M[1] * M[1] + M[2] * M[2] + M[3] * M[3];
    if (!(fabs(det) > 1e-13 * size) || !(size < DBL_MAX)) return 0;
    out[0] = M[3] / det;
    out[1] = -M[1] / det;
    out[2] = -M[2] / det;
    out[3] = M[0] / det;
    return 1;
}
static void rrv__m2_mul(const double P[4], const double Q[4], double out[4])
{
    double o[4];
    o[0] = P[0] * Q[0] + P[1] * Q[2];
    o[1] = P[0] * Q[1] + P[1] * Q[3];
    o[2] = P[2] * Q[0] + P[3] * Q[2];
    o[3] = P[2] * Q[1] + P[3] * Q[3];
    memcpy(out, o, sizeof o);
}

/* Solves the chain's block-tridiagonal system for `cols` right-hand sides
   (2 x cols blocks rhs[k], k = 1..n, overwritten by the solution) by block
   Thomas elimination: O(n), no pivoting across blocks. Returns 0 when a
   pivot block is singular. */
static int rrv__chain_thomas(const rrv__chain *ch, double (*rhs)[4], int cols, double (*Cp)[4])
{
    int k, n = ch->n, j;
    for (k = 1; k <= n; ++k) {
        double M[4], Mi[4], AC[4], d[4];
        memcpy(M, ch->B[k], sizeof M);
        if (k > 1) {
            rrv__m2_mul(ch->A[k], Cp[k - 1], AC);
            for (j = 0; j < 4; ++j) M[j] -= AC[j];
            /* rhs_k -= A_k rhs'_k-1 */
            for (j = 0; j < cols; ++j) {
                double a0 = rhs[k - 1][j], a1 = rhs[k - 1][2 + j];
                rhs[k][j] -= ch->A[k][0] * a0 + ch->A[k][1] * a1;
                rhs[k][2 + j] -= ch->A[k][2] * a0 + ch->A[k][3] * a1;
            }
        }
        if (!rrv__m2_inverse(M, Mi)) return 0;
        if (k < n) rrv__m2_mul(Mi, ch->C[k], Cp[k]);
        for (j = 0; j < cols; ++j) {
            double a0 = rhs[k][j], a1 = rhs[k][2 + j];
            d[j] = Mi[0] * a0 + Mi[1] * a1;
            d[2 + j] = Mi[2] * a0 + Mi[3] * a1;
        }
        for (j = 0; j < cols; ++j) { rhs[k][j] = d[j]; rhs[k][2 + j] = d[2 + j]; }
    }
    for (k = n - 1; k >= 1; --k)
        for (j = 0; j < cols; ++j) {
            double a0 = rhs[k + 1][j], a1 = rhs[k + 1][2 + j];
            rhs[k][j] -= Cp[k][0] * a0 + Cp[k][1] * a1;
            rhs[k][2 + j] -= Cp[k][2] * a0 + Cp[k][3] * a1;
        }
    for (k = 1; k <= n; ++k)
        for (j = 0; j < cols; ++j)
            if (!(fabs(rhs[k][j]) < DBL_MAX) || !(fabs(rhs[k][2 + j]) < DBL_MAX)) return 0;
    return 1;
}

/* Moves x onto the isosurface eta = level by Newton steps along grad eta. */
static int rrv__project_iso(const rrv_scene *scene, rrv_vec3 *x, double level)
{
    int it;
    for (it = 0; it < 20; ++it) {
        rrv_vec3 g;
        double e = rrv__eta_gradient(scene, *x, &g) - level, g2 = rrv__dot(g, g);
        if (fabs(e) < 1e-13) return 1;
        if (!(g2 > RRV__MANIFOLD_FLAT * RRV__MANIFOLD_FLAT)) return 0;
        *x = rrv__madd(*x, g, -e / g2);
    }
    return 0;
}

/* The gradient a vertex at x kicks with, and (dg) its derivative. Where
   the IOR's support is a sphere (Luneburg, fish-eye) grad eta jumps to 0
   on it, and a vertex crossing it would change the path's end by its
   whole kick at once; so there the gradient is smeared over the band
   |r - R| < h (h the chain's spacing): the gradient at the nearest point
   of the sphere's inside times a smoothstep from 1 at R - h to 0 at
   R + h, which keeps the integral of the gradient along a path the
   same. */
static rrv_vec3 rrv__chain_gradient(const rrv_scene *scene, rrv_vec3 x, double h, double dg[9])
{
    rrv_vec3 g;
    int i, j;
    for (i = scene->medium_count - 1; i >= 0; --i) {
        const rrv_medium *m = &scene->media[i];
        if (!rrv__medium_refracts(m)) continue;
        if (rrv__has_sphere_support(m)) {
            rrv_vec3 d = rrv__sub(x, m->ior.center), n;
            double R = m->ior.radius, r = rrv__length(d), inside = R * (1.0 - 1e-9), t, phi, dphi;
            if (!(r < R + h)) continue;
            if (r > R - h) {
                rrv_vec3 xc = r > inside ? rrv__madd(m->ior.center, d, inside / r) : x;
                double H[9], P[9];
                t = (R + h - r) / (2.0 * h);
                phi = t * t * (3.0 - 2.0 * t);
                dphi = -6.0 * t * (1.0 - t) / (2.0 * h); /* d phi / dr */
                n = rrv__scale(d, 1.0 / r);
                if (!dg) {
                    rrv__eta_gradient(scene, xc, &g);
                } else {
                    /* d g(xc) / dx = H(xc) dxc/dx, dxc/dx = (inside / r) (I - n n^T) outside */
                    rrv__eta_gradient_hessian(scene, xc, &g, H, NULL);
                    if (r > inside) {
                        rrv__m3_proj(P, n, inside / r);
                        rrv__m3_mul(H, P, dg);
                    } else {
                        memcpy(dg, H, sizeof H);
                    }
                    for (j = 0; j < 9; ++j) dg[j] *= phi;
                    rrv__m3_outer(dg, g, n, dphi);
                }
                return rrv__scale(g, phi);
            }
        } else if (!rrv__inside_box(x, m->lo, m->hi)) {
            continue;
        }
        break;
    }
    /* the gradient and its derivative from one lookup where the field
       gives both at once */
    if (dg) rrv__eta_gradient_hessian(scene, x, &g, dg, NULL);
    else rrv__eta_gradient(scene, x, &g);
    return g;
}

/* The chord lengths vertex k stands for behind and ahead of its plane:
   half the way to the planes beside it, and for the first and last the
   way to where the support begins and ends along the chord (or to x0, y
   inside it), so the vertices' kicks cover the support once; not the long
   first and last segments, which mostly run outside the support. */
static void rrv__chain_reach(const rrv__chain *ch, int k, double *back, double *ahead)
{
    *back = k == 1 ? ch->t[0] - ch->lo : 0.5 * (ch->t[k - 1] - ch->t[k - 2]);
    *ahead = k == ch->n ? ch->hi - ch->t[k - 1] : 0.5 * (ch->t[k] - ch->t[k - 1]);
}

/* The length of path vertex k stands for, back / ci + ahead / co for
   segments whose directions have cosines ci, co with the chord (half the
   two segments beside it where they join comb planes); DBL_MAX where a
   segment runs back along the chord. */
static double rrv__chain_share(const rrv__chain *ch, int k, double ci, double co)
{
    double back, ahead;
    if (!(ci > 1e-3) || !(co > 1e-3)) return DBL_MAX;
    rrv__chain_reach(ch, k, &back, &ahead);
    return back / ci + ahead / co;
}

/* The direction vertex k sends the ray on: the leapfrog kick of the ray
   equation, p = eta_behind w_in + grad eta(x_k) h_bar, h_bar its share
   of the path (the comb integrator's own kick), and |p|. */
static rrv_vec3 rrv__chain_kick(const rrv__chain *ch, int k, rrv_vec3 wi, double h_bar, double *length)
{
    rrv_vec3 p = rrv__madd(rrv__scale(wi, ch->em[k - 1]), ch->g[k], h_bar);
    *length = rrv__length(p);
    return rrv__scale(p, 1.0 / *length);
}

/* The residual of vertex k and, with jac, its three Jacobian blocks (and E
   at the last vertex). eta and the basis of k-1, k, k+1 must be set, and
   without jac g of k (with jac it is taken here, with its derivative).
   The kick is smooth in the positions: Snell's law about the isosurface
   normal, with the IOR ratio between segment midpoints, is as accurate
   away from grazing but near a turning point (where the ray runs along an
   isosurface, as every ray through a lens does once) its square root's
   derivative diverges and total internal reflection makes the map jump by
   ~sqrt(2 |ratio - 1|), leaving gaps no Newton step can close (measured
   on the lens caustic: most solves that hit the iteration cap had their
   worst vertex there). */
static void rrv__chain_vertex(const rrv_scene *scene, rrv__chain *ch, int k, int jac)
{
    rrv_vec3 a = rrv__sub(ch->x[k], ch->x[k - 1]), b = rrv__sub(ch->x[k + 1], ch->x[k]);
    double la = rrv__length(a), lb = rrv__length(b), ep = ch->em[k - 1], lp, ci, co, h_bar;
    rrv_vec3 wi = rrv__scale(a, 1.0 / la), wo = rrv__scale(b, 1.0 / lb), r, t1, t2;
    double H[9];
    int j, q;
    if (jac) ch->g[k] = rrv__chain_gradient(scene, ch->x[k], ch->h, H);
    ci = rrv__dot(wi, ch->c);
    co = rrv__dot(wo, ch->c);
    h_bar = rrv__chain_share(ch, k, ci, co);
    r = rrv__chain_kick(ch, k, wi, h_bar, &lp);
    if (!(lp > 1e-9 * ep) || !(h_bar < DBL_MAX)) {
        /* the kick stops the ray, or the chain runs back along the chord:
           unusable */
        ch->r[k][0] = ch->r[k][1] = DBL_MAX;
        return;
    }
    rrv__frame(r, &t1, &t2);
    {
        rrv_vec3 R = rrv__madd(wo, r, -rrv__dot(wo, r));
        ch->r[k][0] = rrv__dot(t1, R);
        ch->r[k][1] = rrv__dot(t2, R);
    }
    if (!jac) return;
    /* The blocks t_i^T M b_j of M = +-Pb - (wo.r) dr with dr = Q dp, Q =
       (I - r r^T) / |p| and dp = ep dwi + wi d(ep) + g d(h_bar) + h_bar H
       dx_k: t_i is normal to r, so t_i^T Q = t_i^T / |p|, and every
       term of dp is a projector or an outer product whose product with
       t_i and b_j takes a few dot products. The frame's own turn (the
       (wo.r) dr term) multiplies the residual, zero at a root. */
    {
        const rrv_vec3 t[2] = {t1, t2};
        rrv_vec3 pa = rrv__scale(rrv__madd(ch->c, wi, -ci), 1.0 / la);
        rrv_vec3 pb = rrv__scale(rrv__madd(ch->c, wo, -co), 1.0 / lb);
        rrv_vec3 dep[3], dh[3], base[3][2];
        rrv_vec3 t_H[2];
        double *out[3], back, ahead, fa, fb, turn = -rrv__dot(wo, r) / lp, t_wi[2], t_g[2], t_wo[2];
        rrv__chain_reach(ch, k, &back, &ahead);
        /* h_bar = back / ci + ahead / co, dci = c^T dwi, c^T Pa = (c - ci wi)^T / la */
        fa = -back / (ci * ci);
        fb = -ahead / (co * co);
        dh[0] = rrv__scale(pa, -fa);
        dh[1] = rrv__sub(rrv__scale(pa, fa), rrv__scale(pb, fb));
        dh[2] = rrv__scale(pb, fb);
        dep[0] = rrv__scale(ch->gm[k - 1], ch->wa[k - 1]);
        dep[1] = rrv__scale(ch->gm[k - 1], ch->wb[k - 1]);
        dep[2] = rrv__v3(0, 0, 0);
        for (j = 0; j < 2; ++j) {
            /* H is symmetric: t^T H b = (H t) . b */
            t_H[j] = rrv__scale(rrv__mat_apply(H, t[j]), h_bar);
            t_wi[j] = rrv__dot(t[j], wi);
            t_g[j] = rrv__dot(t[j], ch->g[k]);
            t_wo[j] = rrv__dot(t[j], wo);
        }
        out[0] = k > 1 ? ch->A[k] : NULL;
        base[0][0] = ch->b1[k - 1];
        base[0][1] = ch->b2[k - 1];
        out[1] = ch->B[k];
        base[1][0] = ch->b1[k];
        base[1][1] = ch->b2[k];
        out[2] = k < ch->n ? ch->C[k] : ch->E;
        base[2][0] = k < ch->n ? ch->b1[k + 1] : ch->s1;
        base[2][1] = k < ch->n ? ch->b2[k + 1] : ch->s2;
        for (q = 0; q < 3; ++q) {
            /* d(wi) = sw Pa dx, d(wo) = sb Pb dx over x_k-1, x_k, x_k+1;
               the Pa term carries ep / la, and all of dp is scaled by
               -(wo.r) / |p| */
            double swa = (q == 0 ? -1.0 : q == 1 ? 1.0 : 0.0) * ep / la, sbb = (q == 0 ? 0.0 : q == 1 ? -1.0 : 1.0) / lb;
            int m;
            if (!out[q]) continue;
            for (m = 0; m < 2; ++m) {
                rrv_vec3 bm = base[q][m];
                double wi_b = rrv__dot(wi, bm), wo_b = rrv__dot(wo, bm), dep_b = rrv__dot(dep[q], bm);
                double dh_b = rrv__dot(dh[q], bm);
                for (j = 0; j < 2; ++j) {
                    double t_b = rrv__dot(t[j], bm);
                    double t_dp = swa * (t_b - t_wi[j] * wi_b) + t_wi[j] * dep_b + t_g[j] * dh_b +
                                  (q == 1 ? rrv__dot(t_H[j], bm) : 0.0);
                    out[q][2 * j + m] = sbb * (t_b - t_wo[j] * wo_b) + turn * t_dp;
                }
            }
        }
    }
}

/* IORs, gradients, gauge bases, residuals and (jac) the Jacobian at the
   chain's positions. Returns the root of the sum of squared residuals (the
   merit Newton's step control uses) and sets *largest to the largest
   residual; DBL_MAX when the chain is not usable there (an ISO vertex off
   every isosurface, a degenerate segment, not finite). */
static double rrv__chain_eval(const rrv_scene *scene, rrv__chain *ch, int jac, double *largest)
{
    int k;
    double worst = 0, sum = 0;
    *largest = DBL_MAX;
    if (ch->failed) return DBL_MAX;
    for (k = 1; k <= ch->n; ++k) {
        /* with jac, rrv__chain_vertex takes g with its derivative */
        if (!jac || ch->iso) ch->g[k] = rrv__chain_gradient(scene, ch->x[k], ch->h, NULL);
        if (ch->iso) {
            ch->snell[k] = rrv__vertex_normal(scene, ch->x[k], ch->g[k], &ch->nrm[k]);
            if (!ch->snell[k]) return DBL_MAX;
            rrv__frame(ch->nrm[k], &ch->b1[k], &ch->b2[k]);
        } else {
            ch->b1[k] = ch->c1;
            ch->b2[k] = ch->c2;
        }
    }
    for (k = 0; k <= ch->n; ++k) {
        if (!(rrv__length(rrv__sub(ch->x[k + 1], ch->x[k])) > 1e-12)) return DBL_MAX;
        /* the end segments take the IOR of their ends, so the kicks of
           the vertices account for the whole change of eta from x0 to y
           whatever the comb's offset */
        ch->wa[k] = k == 0 ? 1.0 : k == ch->n ? 0.0 : 0.5;
        ch->wb[k] = 1.0 - ch->wa[k];
        if (ch->n == 0) ch->wa[k] = ch->wb[k] = 0.5;
        ch->em[k] = rrv__eta_gradient(scene, rrv__madd(ch->x[k], rrv__sub(ch->x[k + 1], ch->x[k]), ch->wb[k]), &ch->gm[k]);
    }
    for (k = 1; k <= ch->n; ++k) {
        rrv__chain_vertex(scene, ch, k, jac);
        worst = fmax(worst, fmax(fabs(ch->r[k][0]), fabs(ch->r[k][1])));
        sum += ch->r[k][0] * ch->r[k][0] + ch->r[k][1] * ch->r[k][1];
    }
    if (!(worst < DBL_MAX) || !(sum < DBL_MAX)) return DBL_MAX; /* NaN compares false: unusable */
    *largest = worst;
    return sqrt(sum);
}


/* Moves every vertex by its step du (gauge coordinates in the bases b1,
   b2 of the positions xs it steps from). */
static void rrv__chain_move(const rrv_scene *scene, rrv__chain *ch, const rrv_vec3 *xs, const rrv_vec3 *b1,
                            const rrv_vec3 *b2, double (*du)[2])
{
    int k;
    ch->failed = 0;
    for (k = 1; k <= ch->n; ++k) {
        ch->x[k] = rrv__madd(rrv__madd(xs[k], b1[k], du[k][0]), b2[k], du[k][1]);
        if (ch->iso && !rrv__project_iso(scene, &ch->x[k], ch->level[k])) ch->failed = 1;
    }
}

/* Sets up the chain x0 -> y: the comb planes over the part of the chord
   whose planes meet a refraction support (offset u in [0,1) of a spacing),
   ISO levels, and the light frame. Where no step is given and the scene
   has one box support, the planes are spaced as the eikonal's steps are
   placed along the chord (rrv__field_step_length): the fire caustic's
   chains went from 304 planes at the fixed 0.01 m to 54, each solve 5x
   cheaper (test/bench/RESULTS.md, "The paper's solver"). With drop > 0 a
   plane is left out where eta along the chord changes by less than drop
   across it (faster, biased). ISO leaves out planes where the chord has no isosurface. */
static void rrv__chain_setup_spaced(const rrv_scene *scene, rrv_vec3 x0, rrv_vec3 y, rrv_vec3 ny, int iso,
                                    double drop, double u, double spacing, rrv__chain *ch)
{
    rrv_vec3 d = rrv__sub(y, x0);
    double L = rrv__length(d), lo = DBL_MAX, hi = -DBL_MAX, h = spacing > 0 ? spacing : rrv__step(scene), prev_eta = 0;
    const rrv_medium *sole = scene->settings.step > 0 || spacing > 0 ? NULL : rrv__sole_support(scene);
    long count, i;
    int m;
    ch->n = 0;
    ch->h = h;
    ch->iso = iso;
    ch->failed = 0;
    ch->c = rrv__scale(d, 1.0 / L);
    rrv__frame(ch->c, &ch->c1, &ch->c2);
    rrv__frame(ny, &ch->s1, &ch->s2);
    ch->x[0] = x0;
    for (m = 0; m < scene->medium_count; ++m) {
        const rrv_medium *md = &scene->media[m];
        rrv_vec3 mid = rrv__scale(rrv__add(md->lo, md->hi), 0.5), half = rrv__scale(rrv__sub(md->hi, md->lo), 0.5);
        double cm = rrv__dot(rrv__sub(mid, x0), ch->c);
        double ext = fabs(half.x * ch->c.x) + fabs(half.y * ch->c.y) + fabs(half.z * ch->c.z);
        double a = cm - ext, b = cm + ext;
        if (!rrv__medium_refracts(md)) continue;
        if (rrv__has_sphere_support(md)) {
            double cs = rrv__dot(rrv__sub(md->ior.center, x0), ch->c);
            a = fmax(a, cs - md->ior.radius);
            b = fmin(b, cs + md->ior.radius);
        }
        if (a < b) { lo = fmin(lo, a); hi = fmax(hi, b); }
    }
    lo = fmax(lo, 0.0);
    hi = fmin(hi, L);
    ch->lo = lo;
    ch->hi = hi;
    if (!(lo < hi)) { ch->x[1] = y; return; }
    /* As many planes as the eikonal's placed steps along the chord, but
       evenly spaced: kicks at unevenly spaced planes are a leapfrog whose
       step varies, first order only (test/bench/RESULTS.md, "Chains by
       default on heat caustics": +0.46 % against +0.012 % on a plume) */
    if (sole) {
        double t = lo;
        for (count = 0; t < hi && count < ch->cap; ++count)
            t += rrv__field_step_length(scene, sole, rrv__madd(x0, ch->c, t), ch->c, NULL);
        if (count < 1) count = 1;
        h = (hi - lo) / (double)count;
    } else {
        count = (long)ceil((hi - lo) / h);
        if (count > ch->cap) { count = ch->cap; h = (hi - lo) / (ch->cap > 0 ? ch->cap : 1); }
    }
    for (i = 0; i < count; ++i) ch->t[i] = lo + ((double)i + u) * h;
    ch->h = h;
    /* kept planes overwrite ch->t from the front, never ahead of the one read */
    for (i = 0; i < count; ++i) {
        double t = ch->t[i];
        rrv_vec3 g, p = rrv__madd(x0, ch->c, t);
        double eta;
        if (!(t > 0 && t < L)) continue;
        eta = rrv__eta_gradient(scene, p, &g);
        if (i > 0 && drop > 0 && fabs(eta - prev_eta) < drop) continue;
        prev_eta = eta;
        if (iso && !(rrv__length(g) > RRV__MANIFOLD_FLAT)) continue;
        ch->t[ch->n] = t;
        ch->level[ch->n + 1] = eta;
        ++ch->n;
    }
    ch->x[ch->n + 1] = y;
}

static void rrv__chain_setup(const rrv_scene *scene, rrv_vec3 x0, rrv_vec3 y, rrv_vec3 ny, int iso, double drop,
                             double u, rrv__chain *ch)
{
    rrv__chain_setup_spaced(scene, x0, y, ny, iso, drop, u, 0.0, ch);
}

/* Seeds the chain from a direction w at x0: a parabola from x0 to y that
   leaves x0 along w (as nearly as a graph over the chord can), sampled at
   the comb planes, ISO vertices then projected onto their isosurfaces:
   the seed where aiming a traced chain fails. */
static void rrv__chain_seed(const rrv_scene *scene, rrv__chain *ch, rrv_vec3 w)
{
    rrv_vec3 y = ch->x[ch->n + 1], x0 = ch->x[0];
    double L = rrv__length(rrv__sub(y, x0)), wc = rrv__dot(w, ch->c);
    rrv_vec3 v = rrv__scale(rrv__madd(w, ch->c, -wc), 1.0 / fmax(wc, 0.1));
    int k;
    ch->failed = 0;
    for (k = 1; k <= ch->n; ++k) {
        double t = ch->t[k - 1];
        ch->x[k] = rrv__madd(rrv__madd(x0, ch->c, t), v, t * (L - t) / L);
        if (ch->iso && !rrv__project_iso(scene, &ch->x[k], ch->level[k])) ch->failed = 1;
    }
}

/* Seeds the chain from a direction w at x0 by tracing it: the ray from x0
   along w meets each comb plane in turn and is kicked there by the
   chain's own rule (its share of the path taken along the incoming
   direction, the segment's IOR at the middle of its chord along it), so
   every vertex but the last starts nearly satisfied. ISO vertices are then
   projected onto their isosurfaces. Returns 1 with miss, where the ray
   from the last vertex meets the plane through y perpendicular to the
   chord, in the frame c1, c2; 0 when the ray turns back along the chord
   (the seed fails) or the miss is not finite.
   With J (gauge CHORD only) the trace also carries its derivative by the
   offsets u of the initial direction normalize(w + u0 e1 + u1 e2), (e1,
   e2) rrv__frame(w), through every plane as a Jacobi field (dx, dd): the
   crossing point moves along the plane, the midpoint IOR with the
   gradient there, the kick with the gradient's derivative; J (2x2, rows
   miss, columns u) is dmiss / du. */
static int rrv__chain_miss(const rrv_scene *scene, rrv__chain *ch, rrv_vec3 w, double miss[2], double J[4])
{
    rrv_vec3 x0 = ch->x[0], y = ch->x[ch->n + 1], x = x0, d = w, g, gm, dx[2], dd[2];
    double e_prev = rrv__eta_gradient(scene, x0, &g), de_prev[2] = {0, 0}, H[9], dc, s;
    int k, j;
    if (J) rrv__frame(w, &dd[0], &dd[1]);
    dx[0] = dx[1] = rrv__v3(0, 0, 0);
    ch->failed = 0;
    for (k = 1; k <= ch->n + 1; ++k) {
        double half, e_next, back, ahead, hb, lp;
        rrv_vec3 p, dn;
        dc = rrv__dot(d, ch->c);
        if (!(dc > 1e-6)) {
            /* a ray turned back fails the seed; one that leaves the last
               vertex so only misses y's plane */
            if (k <= ch->n) ch->failed = 1;
            return 0;
        }
        /* the next plane, or at the end y's from the last vertex (ISO:
           as projected) */
        if (k > ch->n) x = ch->x[ch->n];
        s = (k <= ch->n ? ch->t[k - 1] - rrv__dot(rrv__sub(x, x0), ch->c) : rrv__dot(rrv__sub(y, x), ch->c)) / dc;
        for (j = 0; J && j < 2; ++j) {
            /* the crossing stays on the plane: c . dx = 0 after the move */
            double ds = -(rrv__dot(dx[j], ch->c) + s * rrv__dot(dd[j], ch->c)) / dc;
            dx[j] = rrv__madd(rrv__madd(dx[j], dd[j], s), d, ds);
        }
        x = rrv__madd(x, d, s);
        if (k > ch->n) break;
        ch->x[k] = x;
        half = 0.5 * ((k < ch->n ? ch->t[k] : rrv__dot(rrv__sub(y, x0), ch->c)) - ch->t[k - 1]);
        e_next = rrv__eta_gradient(scene, rrv__madd(x, d, half / dc), J ? &gm : NULL);
        g = rrv__chain_gradient(scene, x, ch->h, J ? H : NULL);
        rrv__chain_reach(ch, k, &back, &ahead);
        hb = (back + ahead) / dc;
        p = rrv__madd(rrv__scale(d, e_prev), g, hb);
        lp = rrv__length(p);
        dn = lp > 0 ? rrv__scale(p, 1.0 / lp) : p;
        for (j = 0; J && j < 2; ++j) {
            rrv_vec3 dm, dp;
            double ddc = rrv__dot(dd[j], ch->c);
            if (!(lp > 0)) { ch->failed = 1; return 0; }
            /* the midpoint x + d half / (d . c) */
            dm = rrv__madd(rrv__madd(dx[j], dd[j], half / dc), d, -half * ddc / (dc * dc));
            /* p = e_prev d + g (back + ahead) / (d . c) */
            dp = rrv__madd(rrv__madd(rrv__scale(d, de_prev[j]), dd[j], e_prev), rrv__mat_apply(H, dx[j]), hb);
            dp = rrv__madd(dp, g, -hb * ddc / dc);
            dd[j] = rrv__scale(rrv__madd(dp, dn, -rrv__dot(dn, dp)), 1.0 / lp);
            de_prev[j] = rrv__dot(gm, dm);
        }
        d = dn;
        e_prev = e_next;
        if (ch->iso && !rrv__project_iso(scene, &ch->x[k], ch->level[k])) ch->failed = 1;
    }
    if (ch->failed) return 0;
    miss[0] = rrv__dot(rrv__sub(x, y), ch->c1);
    miss[1] = rrv__dot(rrv__sub(x, y), ch->c2);
    for (j = 0; J && j < 2; ++j) {
        J[j] = rrv__dot(dx[j], ch->c1);
        J[2 + j] = rrv__dot(dx[j], ch->c2);
    }
    return miss[0] < DBL_MAX && miss[1] < DBL_MAX && miss[0] > -DBL_MAX && miss[1] > -DBL_MAX;
}

/* Seeds the chain by shooting: Newton on the initial direction of the
   traced chain until the trace passes y within a tenth of the spacing;
   the 2x2 Jacobian by differences of traces, then kept up to date by
   Broyden's rank-one updates (one trace a step), taken afresh by
   differences after a step that did not bring the trace closer, which is
   then halved. The traced chain satisfies every vertex's constraint, so
   the chain's own Newton has only the last bit of the miss to close, from
   the right basin: from a parabola, or a trace that misses y by much,
   Newton has the whole bend to find on a hundred unknowns (measured on the
   lens caustic: 61 % and 88 % of solves converged). Leaves the chain
   traced from the best direction found and counts the traces; returns 0
   if no trace reached y's plane. */
static int rrv__chain_aim(const rrv_scene *scene, rrv__chain *ch, rrv_vec3 w, int *traces)
{
    double u[2] = {0, 0}, best_u[2] = {0, 0}, miss[2], best_miss[2] = {0, 0}, best = DBL_MAX, step = 1.0, J[4];
    const double eps = 1e-6;
    rrv_vec3 e1, e2;
    int it, have_jacobian = 0, best_traced = 0;
    *traces = 0;
    if (ch->n == 0) { ch->failed = 0; return 1; }
    rrv__frame(w, &e1, &e2);
    for (it = 0; it < RRV__AIM_ITERATIONS; ++it) {
        double Ji[4], d0, d1, len, m;
        int j;
        ++*traces;
        m = rrv__chain_miss(scene, ch, rrv__normalize(rrv__add(w, rrv__add(rrv__scale(e1, u[0]), rrv__scale(e2, u[1])))), miss, NULL)
                ? sqrt(miss[0] * miss[0] + miss[1] * miss[1]) : DBL_MAX;
        if (m < best) {
            if (have_jacobian) {
                /* Broyden: J += (dm - J du) du^T / |du|^2 */
                double a0 = u[0] - best_u[0], a1 = u[1] - best_u[1], a2 = a0 * a0 + a1 * a1;
                double r0 = miss[0] - best_miss[0] - (J[0] * a0 + J[1] * a1);
                double r1 = miss[1] - best_miss[1] - (J[2] * a0 + J[3] * a1);
                if (a2 > 0) {
                    J[0] += r0 * a0 / a2; J[1] += r0 * a1 / a2;
                    J[2] += r1 * a0 / a2; J[3] += r1 * a1 / a2;
                }
            }
            best = m;
            best_u[0] = u[0]; best_u[1] = u[1];
            best_miss[0] = miss[0]; best_miss[1] = miss[1];
            best_traced = 1;
            if (best < 0.1 * ch->h) break;
            if (it) step = fmin(1.0, 2.0 * step);
        } else {
            best_traced = 0;
            if (best == DBL_MAX) return 0;
            step *= 0.5;
            if (step < 1e-3) break;
            have_jacobian = 0;
        }
        if (!have_jacobian) {
            for (j = 0; j < 2; ++j) {
                double mj[2], a = best_u[0] + (j ? 0.0 : eps), b = best_u[1] + (j ? eps : 0.0);
                ++*traces;
                best_traced = 0;
                if (!rrv__chain_miss(scene, ch, rrv__normalize(rrv__add(w, rrv__add(rrv__scale(e1, a), rrv__scale(e2, b)))), mj, NULL))
                    goto done;
                J[j] = (mj[0] - best_miss[0]) / eps;
                J[2 + j] = (mj[1] - best_miss[1]) / eps;
            }
            have_jacobian = 1;
        }
        if (!rrv__m2_inverse(J, Ji)) break;
        d0 = -(Ji[0] * best_miss[0] + Ji[1] * best_miss[1]);
        d1 = -(Ji[2] * best_miss[0] + Ji[3] * best_miss[1]);
        len = sqrt(d0 * d0 + d1 * d1);
        /* no turn of more than ~0.2 rad at once */
        if (len > 0.2) { d0 *= 0.2 / len; d1 *= 0.2 / len; }
        u[0] = best_u[0] + step * d0;
        u[1] = best_u[1] + step * d1;
    }
done:
    if (!best_traced) {
        ++*traces;
        rrv__chain_miss(scene, ch, rrv__normalize(rrv__add(w, rrv__add(rrv__scale(e1, best_u[0]), rrv__scale(e2, best_u[1])))), miss, NULL);
    }
    return !ch->failed;
}

/* The coarse chain's root by shooting alone: Newton on the initial
   direction with the traced Jacobian (rrv__chain_miss), a step
   halved from the best direction where the miss grew, until the trace
   meets y within 1e-9 of a spacing. The traced chain satisfies its own
   kicks at every plane, so it is the coarse stage's root without a solve
   on the chain: the coarse root only seeds the polish (rrv__chain_try_once),
   which takes the density. Before, the coarse stage aimed by differences
   of traces to a tenth of a spacing and closed the rest with the chain's
   trust-region solve (on the lens caustic 10 traces and 3.8 evaluations a
   solve). Leaves ch traced from the root and counts the traces; returns 0
   when no root was found within RRV__AIM_ITERATIONS traces. */
static int rrv__chain_shoot(const rrv_scene *scene, rrv__chain *ch, rrv_vec3 w, int *traces)
{
    double miss[2], J[4], best_miss[2] = {0, 0}, best_J[4] = {0, 0, 0, 0}, Ji[4], best = DBL_MAX, step = 1.0;
    double tol = 1e-9 * ch->h;
    rrv_vec3 best_w = w, cur = w, e1, e2;
    int it;
    *traces = 0;
    if (ch->n == 0 || ch->iso) return 0;
    for (it = 0; it < RRV__AIM_ITERATIONS; ++it) {
        double m, d0, d1, len;
        ++*traces;
        m = rrv__chain_miss(scene, ch, cur, miss, J) ? sqrt(miss[0] * miss[0] + miss[1] * miss[1]) : DBL_MAX;
        if (m < best) {
            if (m < tol) return 1;
            best = m;
            best_w = cur;
            memcpy(best_miss, miss, sizeof miss);
            memcpy(best_J, J, sizeof J);
            step = fmin(1.0, 2.0 * step);
        } else {
            if (best == DBL_MAX) return 0;
            step *= 0.5;
            if (step < 1e-3) return 0;
        }
        if (!rrv__m2_inverse(best_J, Ji)) return 0;
        d0 = -(Ji[0] * best_miss[0] + Ji[1] * best_miss[1]);
        d1 = -(Ji[2] * best_miss[0] + Ji[3] * best_miss[1]);
        len = sqrt(d0 * d0 + d1 * d1);
        /* no turn of more than ~0.2 rad at once */
        if (len > 0.2) { d0 *= 0.2 / len; d1 *= 0.2 / len; }
        rrv__frame(best_w, &e1, &e2);
        cur = rrv__normalize(rrv__add(best_w, rrv__add(rrv__scale(e1, step * d0), rrv__scale(e2, step * d1))));
    }
    return 0;
}

typedef struct rrv__mroot {
    rrv_vec3 w0;      /* initial direction */
    double density;   /* dw0 / dA_y, sr per m^2 */
    int iterations;
} rrv__mroot;

/* Does the refractivity jump across the face the ray along d meets at x (a chain's chords
   must not cross one)? */
static int rrv__face_jumps(const rrv_scene *scene, rrv_vec3 x, rrv_vec3 d)
{
    double gap = rrv__face_gap(x);
    double before = rrv__scene_refractivity(scene, rrv__madd(x, d, -gap), NULL);
    double after = rrv__scene_refractivity(scene, rrv__madd(x, d, gap), NULL);
    return fabs(after - before) > RRV__SOLVE_JUMP;
}

/* Can the chord from a to b cross a face of a refracting medium's box?
   Not where both ends lie inside the box by more than a few face gaps,
   nor where it misses the box grown by them: there the walk of its faces
   in rrv__chain_physical cannot find a jump (the refractivity changes at
   no other face), and a chain's inner chords, all inside the support's
   box, skip it. */
static int rrv__chord_may_cross_face(const rrv_scene *scene, rrv_vec3 a, rrv_vec3 b)
{
    double g = 4.0 * fmax(rrv__face_gap(a), rrv__face_gap(b)), t0, t1;
    rrv_vec3 gv = rrv__v3(g, g, g);
    int i;
    for (i = 0; i < scene->medium_count; ++i) {
        const rrv_medium *m = &scene->media[i];
        rrv_vec3 lo = rrv__add(m->lo, gv), hi = rrv__sub(m->hi, gv);
        if (!rrv__medium_refracts(m)) continue;
        if (rrv__inside_box(a, lo, hi) && rrv__inside_box(b, lo, hi)) continue;
        if (rrv__ray_box_span(a, rrv__sub(b, a), rrv__sub(m->lo, gv), rrv__add(m->hi, gv), &t0, &t1) && t0 <= 1.0)
            return 1;
    }
    return 0;
}

/* Is the converged chain a physical path, and no chord crosses a sharp
   interface? The constraint admits the direction opposite to the kicked
   one as well: a vertex must send the ray on forward. */
static int rrv__chain_physical(const rrv_scene *scene, const rrv__chain *ch)
{
    int k;
    for (k = 1; k <= ch->n; ++k) {
        rrv_vec3 a = rrv__sub(ch->x[k], ch->x[k - 1]), b = rrv__sub(ch->x[k + 1], ch->x[k]), wi, r;
        double lp, share;
        wi = rrv__normalize(a);
        share = rrv__chain_share(ch, k, rrv__dot(wi, ch->c), rrv__dot(rrv__normalize(b), ch->c));
        if (!(share < DBL_MAX)) return 0;
        r = rrv__chain_kick(ch, k, wi, share, &lp);
        if (!(rrv__dot(b, r) > 0)) return 0;
    }
    for (k = 0; k <= ch->n; ++k) {
        rrv_vec3 x = ch->x[k], d = rrv__sub(ch->x[k + 1], x);
        double len = rrv__length(d), done = 0;
        int faces;
        if (!rrv__chord_may_cross_face(scene, x, ch->x[k + 1])) continue;
        d = rrv__scale(d, 1.0 / len);
        for (faces = 0; faces < 64; ++faces) {
            rrv__support_view view;
            rrv_vec3 p = rrv__madd(x, d, done);
            rrv__look_along(scene, p, d, &view);
            if (!(view.t_face < len - done)) break;
            if (rrv__face_jumps(scene, rrv__madd(p, d, view.t_face), d)) return 0;
            done += view.t_face + 2.0 * rrv__face_gap(rrv__madd(p, d, view.t_face));
        }
    }
    return 1;
}

/* out = J v, or J^T v with transpose, for 2-vectors v[1..n] in the gauge
   coordinates (O(n): J is block tridiagonal). */
static void rrv__chain_apply(const rrv__chain *ch, double (*v)[2], double (*out)[2], int transpose)
{
    int k, n = ch->n;
    for (k = 1; k <= n; ++k) {
        const double *M[3], *x[3];
        double o0 = 0, o1 = 0;
        int m, count = 0;
        /* the blocks of row k of J, or of column k for J^T */
        M[count] = ch->B[k]; x[count++] = v[k];
        if (!transpose) {
            if (k > 1) { M[count] = ch->A[k]; x[count++] = v[k - 1]; }
            if (k < n) { M[count] = ch->C[k]; x[count++] = v[k + 1]; }
        } else {
            if (k < n) { M[count] = ch->A[k + 1]; x[count++] = v[k + 1]; }
            if (k > 1) { M[count] = ch->C[k - 1]; x[count++] = v[k - 1]; }
        }
        for (m = 0; m < count; ++m) {
            if (!transpose) {
                o0 += M[m][0] * x[m][0] + M[m][1] * x[m][1];
                o1 += M[m][2] * x[m][0] + M[m][3] * x[m][1];
            } else {
                o0 += M[m][0] * x[m][0] + M[m][2] * x[m][1];
                o1 += M[m][1] * x[m][0] + M[m][3] * x[m][1];
            }
        }
        out[k][0] = o0;
        out[k][1] = o1;
    }
}

/* The geometry term at a root: dx_1/dy from J Z = -E (E in the last row)
   by the same elimination, turned into dw0/dy. Returns 0 where J is
   singular (a caustic) or the density is not finite and positive. */
static int rrv__chain_density(rrv__chain *ch, rrv__mroot *root)
{
    double (*du)[4] = ch->du, D[4], l01;
    rrv_vec3 x1 = ch->x[1], w0, e1, e2, dw[2];
    int j, k, n = ch->n;
    if (n > 0) {
        for (k = 1; k <= n; ++k) du[k][0] = du[k][1] = du[k][2] = du[k][3] = 0;
        for (j = 0; j < 4; ++j) du[n][j] = -ch->E[j];
        if (!rrv__chain_thomas(ch, du, 2, ch->Cp)) return 0;
    }
    l01 = rrv__length(rrv__sub(x1, ch->x[0]));
    w0 = rrv__scale(rrv__sub(x1, ch->x[0]), 1.0 / l01);
    rrv__frame(w0, &e1, &e2);
    for (j = 0; j < 2; ++j) {
        rrv_vec3 dx = n > 0 ? rrv__add(rrv__scale(ch->b1[1], du[1][j]), rrv__scale(ch->b2[1], du[1][2 + j]))
                            : (j ? ch->s2 : ch->s1);
        dw[j] = rrv__scale(rrv__madd(dx, w0, -rrv__dot(dx, w0)), 1.0 / l01);
    }
    D[0] = rrv__dot(e1, dw[0]);
    D[1] = rrv__dot(e1, dw[1]);
    D[2] = rrv__dot(e2, dw[0]);
    D[3] = rrv__dot(e2, dw[1]);
    root->w0 = w0;
    root->density = fabs(D[0] * D[3] - D[1] * D[2]);
    return root->density < DBL_MAX && root->density > 0;
}

/* 2x2 blocks: out (+)= P^T Q. */
static void rrv__m2_tmul_add(const double P[4], const double Q[4], double out[4])
{
    out[0] += P[0] * Q[0] + P[2] * Q[2];
    out[1] += P[0] * Q[1] + P[2] * Q[3];
    out[2] += P[1] * Q[0] + P[3] * Q[2];
    out[3] += P[1] * Q[1] + P[3] * Q[3];
}

/* The normal equations of the chain's least squares, N = J^T J and
   grad = J^T r, by blocks: nd[k] = N_kk, n1[k] = N_k,k-1, n2[k] = N_k,k-2.
   Row k of J has blocks in columns k-1, k, k+1 (A_k, B_k, C_k), so two
   columns share a row only when at most two apart: N is block
   pentadiagonal, and columns two apart share only the row between them. */
static void rrv__chain_normal(rrv__chain *ch)
{
    int k, n = ch->n;
    for (k = 1; k <= n; ++k) {
        double *d = ch->nd[k], *g = ch->grad[k];
        const double *r = ch->r[k];
        memset(d, 0, 4 * sizeof *d);
        rrv__m2_tmul_add(ch->B[k], ch->B[k], d);
        g[0] = ch->B[k][0] * r[0] + ch->B[k][2] * r[1];
        g[1] = ch->B[k][1] * r[0] + ch->B[k][3] * r[1];
        if (k > 1) {
            const double *rp = ch->r[k - 1];
            rrv__m2_tmul_add(ch->C[k - 1], ch->C[k - 1], d);
            g[0] += ch->C[k - 1][0] * rp[0] + ch->C[k - 1][2] * rp[1];
            g[1] += ch->C[k - 1][1] * rp[0] + ch->C[k - 1][3] * rp[1];
            memset(ch->n1[k], 0, 4 * sizeof(double));
            rrv__m2_tmul_add(ch->C[k - 1], ch->B[k - 1], ch->n1[k]);
            rrv__m2_tmul_add(ch->B[k], ch->A[k], ch->n1[k]);
        }
        if (k > 2) {
            memset(ch->n2[k], 0, 4 * sizeof(double));
            rrv__m2_tmul_add(ch->C[k - 1], ch->A[k - 1], ch->n2[k]);
        }
        if (k < n) {
            const double *rn = ch->r[k + 1];
            rrv__m2_tmul_add(ch->A[k + 1], ch->A[k + 1], d);
            g[0] += ch->A[k + 1][0] * rn[0] + ch->A[k + 1][2] * rn[1];
            g[1] += ch->A[k + 1][1] * rn[0] + ch->A[k + 1][3] * rn[1];
        }
    }
}

/* Block LDL^T of the symmetric block-pentadiagonal M = N + lambda
   diag(scl) (blocks k = 1..n as rrv__chain_normal lays them out):
   L unit lower with blocks l1[k] = L_k,k-1 and l2[k] = L_k,k-2, D block
   diagonal, kept inverted in dinv. A band Cholesky keeps its band, so
   this is O(n) with no fill beyond two blocks: writing G_kj = L_kj D_j,
   M_k,k-2 = G_k,k-2 and M_k,k-1 = G_k,k-2 L_k-1,k-2^T + G_k,k-1, and
   D_k is what the two earlier columns leave of M_kk. The 2x2 D blocks
   take the place of Cholesky's square roots. Returns 0 when a D block is
   not positive definite (to rounding: then lambda must grow). */
static int rrv__band_factor(int n, double (*nd)[4], double (*n1)[4], double (*n2)[4], double (*scl)[2],
                            double lambda, double (*l1)[4], double (*l2)[4], double (*dinv)[4])
{
    int k, j;
    for (k = 1; k <= n; ++k) {
        double D[4], G1[4] = {0, 0, 0, 0}, G2[4] = {0, 0, 0, 0}, T[4];
        memcpy(D, nd[k], sizeof D);
        D[0] += lambda * scl[k][0];
        D[3] += lambda * scl[k][1];
        if (k > 2) {
            memcpy(G2, n2[k], sizeof G2);
            rrv__m2_mul(G2, dinv[k - 2], l2[k]);
        }
        if (k > 1) {
            memcpy(G1, n1[k], sizeof G1);
            if (k > 2) {
                /* G1 -= G2 l1[k-1]^T */
                const double *P = l1[k - 1];
                G1[0] -= G2[0] * P[0] + G2[1] * P[1];
                G1[1] -= G2[0] * P[2] + G2[1] * P[3];
                G1[2] -= G2[2] * P[0] + G2[3] * P[1];
                G1[3] -= G2[2] * P[2] + G2[3] * P[3];
            }
            rrv__m2_mul(G1, dinv[k - 1], l1[k]);
        }
        /* D -= G2 l2^T + G1 l1^T */
        for (j = 0; j < 2; ++j) {
            const double *G = j ? G2 : G1, *P = j ? l2[k] : l1[k];
            if (k <= 1 + j) continue;
            D[0] -= G[0] * P[0] + G[1] * P[1];
            D[1] -= G[0] * P[2] + G[1] * P[3];
            D[2] -= G[2] * P[0] + G[3] * P[1];
            D[3] -= G[2] * P[2] + G[3] * P[3];
        }
        /* symmetric to rounding; its average keeps dinv so */
        D[1] = D[2] = 0.5 * (D[1] + D[2]);
        if (!(D[0] > 0) || !(D[3] > 0) || !(D[0] * D[3] - D[1] * D[2] > 1e-14 * D[0] * D[3])) return 0;
        if (!rrv__m2_inverse(D, T)) return 0;
        memcpy(dinv[k], T, sizeof T);
    }
    return 1;
}

/* Solves L D L^T x = b in place (b[1..n]) with rrv__band_factor's factors:
   forward through L, the D blocks, back through L^T. */
static void rrv__band_solve(int n, double (*l1)[4], double (*l2)[4], double (*dinv)[4], double (*b)[2])
{
    int k;
    for (k = 2; k <= n; ++k) {
        b[k][0] -= l1[k][0] * b[k - 1][0] + l1[k][1] * b[k - 1][1];
        b[k][1] -= l1[k][2] * b[k - 1][0] + l1[k][3] * b[k - 1][1];
        if (k > 2) {
            b[k][0] -= l2[k][0] * b[k - 2][0] + l2[k][1] * b[k - 2][1];
            b[k][1] -= l2[k][2] * b[k - 2][0] + l2[k][3] * b[k - 2][1];
        }
    }
    for (k = 1; k <= n; ++k) {
        double a0 = b[k][0], a1 = b[k][1];
        b[k][0] = dinv[k][0] * a0 + dinv[k][1] * a1;
        b[k][1] = dinv[k][2] * a0 + dinv[k][3] * a1;
    }
    for (k = n - 1; k >= 1; --k) {
        b[k][0] -= l1[k + 1][0] * b[k + 1][0] + l1[k + 1][2] * b[k + 1][1];
        b[k][1] -= l1[k + 1][1] * b[k + 1][0] + l1[k + 1][3] * b[k + 1][1];
        if (k + 2 <= n) {
            b[k][0] -= l2[k + 2][0] * b[k + 2][0] + l2[k + 2][2] * b[k + 2][1];
            b[k][1] -= l2[k + 2][1] * b[k + 2][0] + l2[k + 2][3] * b[k + 2][1];
        }
    }
}

/* Swaps the chain's state (positions, bases, residuals, Jacobian) with
   the second half of its double buffer. */
static void rrv__chain_swap(rrv__chain *ch)
{
    rrv_vec3 *v;
    double (*p2)[2], (*p4)[4];
    v = ch->x; ch->x = ch->xs; ch->xs = v;
    v = ch->b1; ch->b1 = ch->sb1; ch->sb1 = v;
    v = ch->b2; ch->b2 = ch->sb2; ch->sb2 = v;
    p2 = ch->r; ch->r = ch->r_alt; ch->r_alt = p2;
    p4 = ch->A; ch->A = ch->A_alt; ch->A_alt = p4;
    p4 = ch->B; ch->B = ch->B_alt; ch->B_alt = p4;
    p4 = ch->C; ch->C = ch->C_alt; ch->C_alt = p4;
}

/* Levenberg-Marquardt's first damping, relative to Marquardt's scaling.
   The seeds are aimed, so the first step should be Gauss-Newton's; and
   the chain's slow modes (a long chain bending as a whole, a root near a
   caustic) have eigenvalues of J^T J ~1e-9 of its diagonal or less, so
   any damping above that slows them to linear convergence that |r| does
   not show: on the lens caustic 1e-9 took 5 evaluations where 1e-15 takes
   3 (medians), and a straight 200-vertex chain stopped with its first
   direction 6e-8 off at 1e-12, 6e-11 at 1e-15. */
#define RRV__LM_LAMBDA 1e-15
#define RRV__LM_LAMBDA_MAX 1e12 /* damping beyond which the chain is stuck */
/* Evaluations without |r| halving after which a solve has stalled: from
   raw seeds on the heat shadow every solve that failed had reached a
   local minimum of |r|^2 (|r| ~ 0.3) and spent the 40 evaluations there,
   the last 24 or more without |r| halving, while 2 % of those that
   converged went 12 or more without (test/bench/RESULTS.md). */
#define RRV__LM_STALL 12

/* Does a Newton step from a chain whose largest residual is `largest`
   finish the solve? Where the last step converged quadratically with
   constant K (|r'| ~ K |r|^2; 0 when it was not a full, well-predicted
   step), the next residual is about K largest^2: a thousandth of
   RRV__MANIFOLD_TOL or less, and largest already under 1e-6, and the
   step is taken without the evaluation that would confirm it (both
   solvers; LM only where its damped step leaves the linear model as
   small a residual). On the lens caustic the polish's evaluations went
   8e-3, 5e-5, 6e-9, 2e-14: the last one only confirmed the root. */
static int rrv__newton_finishes(double K, double largest)
{
    return K > 0 && largest < 1e-6 && K * largest * largest < 1e-3 * RRV__MANIFOLD_TOL;
}

/* That last step, taken without the evaluation that would confirm it:
   the positions move by it (gauge CHORD), the density comes from the
   Jacobian where it was taken, |step| ~ 1e-8 away. Returns the solve's
   result as at a confirmed root. */
static int rrv__chain_last_step(const rrv_scene *scene, rrv__chain *ch, double (*step)[2], rrv__mroot *root)
{
    rrv__chain_move(scene, ch, ch->x, ch->b1, ch->b2, step);
    return rrv__chain_physical(scene, ch) && rrv__chain_density(ch, root);
}

/* Levenberg-Marquardt on the chain from its seeded positions (the paper's
   solver): minimises |r|^2 over the vertices' gauge coordinates by steps
   delta with (J^T J + lambda S) delta = -J^T r. S is Marquardt's scaling,
   the largest diagonal of J^T J seen so far (Moré), so the damping means
   the same for every vertex whatever its Jacobian's size, and a direction
   that was once stiff stays damped as such. lambda -> 0 gives the
   Gauss-Newton (here Newton: J is square) step and its quadratic
   convergence; lambda large a short step along the scaled gradient, which
   lowers |r|^2 for any chain. A step is taken when it lowers |r|, judged
   by rho, the actual reduction of |r|^2 over the linear model's,
   |r|^2 - |r + J delta|^2 = delta . (lambda S delta - J^T r); lambda
   follows Nielsen's rule (1999): on a step taken lambda *= max(1/3,
   1 - (2 rho - 1)^3), nu = 2 (a model that predicted well, rho ~ 1, cuts
   lambda threefold; a poor one, rho ~ 0, keeps it), on one refused
   lambda *= nu, nu *= 2, so repeated refusals grow it geometrically
   faster. J^T J is block pentadiagonal (rrv__chain_normal), factored in
   O(n) (rrv__band_factor); a refused step only re-factors it with the new
   lambda, the chain's values where it stands (kept by the double buffer,
   rrv__chain_swap) are not evaluated again. Two guards beside Nielsen's
   rule, both on the linear algebra alone: from a tiny lambda a refusal's
   doubling leaves the step as long as before, so after a refusal lambda
   grows fourfold (factor and solve, no evaluation) until the step is at
   most half the refused one's length; and because forming J^T J squares
   J's condition number, each step is refined once by the corrected
   semi-normal equations (Björck): the residual of the normal equations
   taken from J itself, -J^T (r + J delta) - lambda S delta, solved with
   the same factors and added. At most RRV__MANIFOLD_ITERATIONS
   evaluations of the chain, each counted. Returns 1 with the root's
   initial direction and density, 0 when it did not converge to
   RRV__MANIFOLD_TOL, the root is not a physical path, or the Jacobian is
   singular there (rrv__chain_density). */
static int rrv__manifold_solve(const rrv_scene *scene, rrv__chain *ch, rrv__mroot *root)
{
    int it = 1, k, n = ch->n, halved_at = 1;
    double largest, norm = rrv__chain_eval(scene, ch, 1, &largest), lambda = RRV__LM_LAMBDA, nu = 2.0, refused = 0;
    double halved_norm = norm, newton = 0;
    root->iterations = 1;
    if (!(norm < DBL_MAX)) return 0;
    for (k = 1; k <= n; ++k) ch->scl[k][0] = ch->scl[k][1] = 0;
    for (;;) {
        double f2 = norm * norm, top = 0;
        if (largest < RRV__MANIFOLD_TOL) {
            root->iterations = it;
            return rrv__chain_physical(scene, ch) && rrv__chain_density(ch, root);
        }
        if (it >= RRV__MANIFOLD_ITERATIONS) break;
        if (norm <= 0.5 * halved_norm) {
            halved_norm = norm;
            halved_at = it;
        } else if (it - halved_at >= RRV__LM_STALL) {
            break;
        }
        rrv__chain_normal(ch);
        for (k = 1; k <= n; ++k) {
            ch->scl[k][0] = fmax(ch->scl[k][0], ch->nd[k][0]);
            ch->scl[k][1] = fmax(ch->scl[k][1], ch->nd[k][3]);
            top = fmax(top, fmax(ch->scl[k][0], ch->scl[k][1]));
        }
        if (!(top > 0) || !(top < DBL_MAX)) break;
        /* a column of J that is ~0 still gets a damping */
        for (k = 1; k <= n; ++k) {
            ch->scl[k][0] = fmax(ch->scl[k][0], 1e-12 * top);
            ch->scl[k][1] = fmax(ch->scl[k][1], 1e-12 * top);
        }
        for (;;) { /* steps from here until one is taken */
            double pred = 0, trial, tl, E[4], len;
            if (!rrv__band_factor(n, ch->nd, ch->n1, ch->n2, ch->scl, lambda, ch->l1, ch->l2, ch->dinv)) {
                lambda *= nu;
                nu *= 2.0;
                if (!(lambda < RRV__LM_LAMBDA_MAX)) goto failed;
                continue;
            }
            for (k = 1; k <= n; ++k) {
                ch->step[k][0] = -ch->grad[k][0];
                ch->step[k][1] = -ch->grad[k][1];
            }
            rrv__band_solve(n, ch->l1, ch->l2, ch->dinv, ch->step);
            {
                /* e = r + J delta and t in scratch that is free until the trial */
                double (*e)[2] = ch->r_alt, (*t)[2] = (double (*)[2])(void *)ch->du;
                rrv__chain_apply(ch, ch->step, e, 0);
                for (k = 1; k <= n; ++k) { e[k][0] += ch->r[k][0]; e[k][1] += ch->r[k][1]; }
                rrv__chain_apply(ch, e, t, 1);
                for (k = 1; k <= n; ++k) {
                    t[k][0] = -(t[k][0] + lambda * ch->scl[k][0] * ch->step[k][0]);
                    t[k][1] = -(t[k][1] + lambda * ch->scl[k][1] * ch->step[k][1]);
                }
                rrv__band_solve(n, ch->l1, ch->l2, ch->dinv, t);
                for (k = 1; k <= n; ++k) { ch->step[k][0] += t[k][0]; ch->step[k][1] += t[k][1]; }
            }
            len = 0;
            for (k = 1; k <= n; ++k) {
                double s0 = ch->step[k][0], s1 = ch->step[k][1];
                pred += s0 * (lambda * ch->scl[k][0] * s0 - ch->grad[k][0]) +
                        s1 * (lambda * ch->scl[k][1] * s1 - ch->grad[k][1]);
                len += s0 * s0 + s1 * s1;
            }
            if (refused > 0 && len > 0.25 * refused) { /* |step|^2 against a quarter of the refused one's */
                lambda *= 4.0;
                if (!(lambda < RRV__LM_LAMBDA_MAX)) goto failed;
                continue;
            }
            if (!(pred > 0) || !(pred < DBL_MAX)) goto failed; /* no step left that the model trusts */
            if (rrv__newton_finishes(newton, largest) && !ch->iso) {
                /* as the dogleg's last step, where the damped step leaves
                   the linear model a residual as small */
                double (*e)[2] = ch->r_alt, worst = 0;
                rrv__chain_apply(ch, ch->step, e, 0);
                for (k = 1; k <= n; ++k)
                    worst = fmax(worst, fmax(fabs(e[k][0] + ch->r[k][0]), fabs(e[k][1] + ch->r[k][1])));
                if (worst < 1e-3 * RRV__MANIFOLD_TOL) {
                    root->iterations = it;
                    return rrv__chain_last_step(scene, ch, ch->step, root);
                }
            }
            memcpy(E, ch->E, sizeof E);
            rrv__chain_swap(ch);
            ch->x[0] = ch->xs[0];
            ch->x[n + 1] = ch->xs[n + 1];
            rrv__chain_move(scene, ch, ch->xs, ch->sb1, ch->sb2, ch->step);
            trial = rrv__chain_eval(scene, ch, 1, &tl);
            ++it;
            if (trial < norm) {
                double rho = (f2 - trial * trial) / pred, t = 2.0 * rho - 1.0;
                newton = rho > 0.9 && rho < 1.1 ? tl / (largest * largest) : 0;
                lambda *= fmax(1.0 / 3.0, 1.0 - t * t * t);
                nu = 2.0;
                norm = trial;
                largest = tl;
                refused = 0;
                break;
            }
            /* refused: back to the values kept */
            rrv__chain_swap(ch);
            memcpy(ch->E, E, sizeof E);
            ch->failed = 0;
            lambda *= nu;
            nu *= 2.0;
            refused = len;
            if (it >= RRV__MANIFOLD_ITERATIONS) goto failed;
            if (!(lambda < RRV__LM_LAMBDA_MAX)) goto failed;
        }
    }
failed:
    root->iterations = it;
    return 0;
}

/* Trust-region Gauss-Newton (Powell's dogleg) on the chain from its seeded
   positions, all in O(n): the Newton step J du = -r by block Thomas where
   it lies inside the trust radius, else the dogleg path from the Cauchy
   point (along -J^T r) toward it, cut at the radius. The radius is the
   damping: halved on a step that does not lower |r| (the step is undone),
   also on one that lowers it much less than the linear model predicted,
   doubled (up to the chord's length a vertex) on one that the model
   predicted well and that reached it. A singular or ill-conditioned pivot
   block fails the solve (rrv__chain_thomas), and so does a chain that is
   not usable (rrv__chain_eval: a segment running back, non-finite values).
   At most RRV__MANIFOLD_ITERATIONS evaluations of the chain, each
   counted. Returns 1 with the root's initial direction and density, 0
   when it did not converge to RRV__MANIFOLD_TOL, the root is not a
   physical path, or the Jacobian is singular there. */
static int rrv__manifold_dogleg(const rrv_scene *scene, rrv__chain *ch, rrv__mroot *root)
{
    double (*du)[4] = ch->du, (*gn)[2] = ch->step, (*sd)[2] = ch->grad, (*jv)[2] = ch->scl;
    int it = 1, k, n = ch->n;
    double L = rrv__length(rrv__sub(ch->x[n + 1], ch->x[0])), scale = sqrt(n > 0 ? (double)n : 1.0);
    double radius = 0.25 * L * scale, largest, norm = rrv__chain_eval(scene, ch, 1, &largest), newton = 0;
    root->iterations = 1;
    if (!(norm < DBL_MAX)) return 0;
    for (;;) {
        double lgn = 0, lp, pred = 0, f2 = norm * norm, trial, rho, tl, E[4];
        if (largest < RRV__MANIFOLD_TOL) {
            root->iterations = it;
            return rrv__chain_physical(scene, ch) && rrv__chain_density(ch, root);
        }
        if (it >= RRV__MANIFOLD_ITERATIONS) break;
        for (k = 1; k <= n; ++k) {
            du[k][0] = -ch->r[k][0];
            du[k][2] = -ch->r[k][1];
        }
        if (!rrv__chain_thomas(ch, du, 1, ch->Cp)) break;
        for (k = 1; k <= n; ++k) {
            gn[k][0] = du[k][0];
            gn[k][1] = du[k][2];
            lgn += gn[k][0] * gn[k][0] + gn[k][1] * gn[k][1];
        }
        lgn = sqrt(lgn);
        if (lgn <= radius && rrv__newton_finishes(newton, largest) && !ch->iso) {
            root->iterations = it;
            return rrv__chain_last_step(scene, ch, gn, root);
        }
        if (lgn <= radius) {
            lp = lgn;
        } else {
            /* g = J^T r, the Cauchy point -alpha g with alpha = |g|^2 / |J g|^2 */
            double g2 = 0, jg2 = 0, alpha;
            rrv__chain_apply(ch, ch->r, sd, 1);
            rrv__chain_apply(ch, sd, jv, 0);
            for (k = 1; k <= n; ++k) {
                g2 += sd[k][0] * sd[k][0] + sd[k][1] * sd[k][1];
                jg2 += jv[k][0] * jv[k][0] + jv[k][1] * jv[k][1];
            }
            if (!(g2 > 0) || !(jg2 > 0) || !(g2 < DBL_MAX) || !(jg2 < DBL_MAX)) break;
            alpha = g2 / jg2;
            if (alpha * sqrt(g2) >= radius) {
                for (k = 1; k <= n; ++k) {
                    du[k][0] = -radius * sd[k][0] / sqrt(g2);
                    du[k][2] = -radius * sd[k][1] / sqrt(g2);
                }
            } else {
                /* |pc + tau (gn - pc)| = radius, tau in (0, 1) */
                double a = 0, b = 0, c = -radius * radius, tau;
                for (k = 1; k <= n; ++k) {
                    double p0 = -alpha * sd[k][0], p1 = -alpha * sd[k][1], d0 = gn[k][0] - p0, d1 = gn[k][1] - p1;
                    a += d0 * d0 + d1 * d1;
                    b += 2.0 * (p0 * d0 + p1 * d1);
                    c += p0 * p0 + p1 * p1;
                }
                tau = a > 0 ? (-b + sqrt(fmax(b * b - 4.0 * a * c, 0.0))) / (2.0 * a) : 0.0;
                for (k = 1; k <= n; ++k) {
                    du[k][0] = -alpha * sd[k][0] + tau * (gn[k][0] + alpha * sd[k][0]);
                    du[k][2] = -alpha * sd[k][1] + tau * (gn[k][1] + alpha * sd[k][1]);
                }
            }
            lp = radius;
        }
        /* the linear model's reduction of |r|^2: |r|^2 - |r + J p|^2 */
        for (k = 1; k <= n; ++k) {
            sd[k][0] = du[k][0];
            sd[k][1] = du[k][2];
        }
        rrv__chain_apply(ch, sd, jv, 0);
        for (k = 1; k <= n; ++k) {
            double a0 = ch->r[k][0] + jv[k][0], a1 = ch->r[k][1] + jv[k][1];
            pred += a0 * a0 + a1 * a1;
        }
        pred = f2 - pred;
        /* the trial into the other half of the double buffer, as for LM */
        memcpy(E, ch->E, sizeof E);
        rrv__chain_swap(ch);
        ch->x[0] = ch->xs[0];
        ch->x[n + 1] = ch->xs[n + 1];
        rrv__chain_move(scene, ch, ch->xs, ch->sb1, ch->sb2, sd);
        trial = rrv__chain_eval(scene, ch, 1, &tl);
        ++it;
        rho = trial < norm && pred > 0 ? (f2 - trial * trial) / pred : -1.0;
        if (trial < norm && rho > 1e-4) {
            /* the constant of Newton's quadratic convergence, |r'| / |r|^2,
               measured where a full step was taken and the model held */
            newton = lp == lgn && rho > 0.9 && rho < 1.1 ? tl / (largest * largest) : 0;
            norm = trial;
            largest = tl;
            if (rho > 0.75 && lp > 0.99 * radius) radius = fmin(2.0 * radius, L * scale);
            else if (rho < 0.25) radius *= 0.5;
            continue;
        }
        /* undo the step: the values kept where it started */
        rrv__chain_swap(ch);
        memcpy(ch->E, E, sizeof E);
        ch->failed = 0;
        radius = 0.5 * lp;
        if (!(radius > 1e-12 * L) || it >= RRV__MANIFOLD_ITERATIONS) break;
    }
    root->iterations = it;
    return 0;
}


/* The contribution of one root's path: visibility and ratio-tracked
   transmittance along its chords, the vertex's BSDF or phase function
   toward w0, 0 for a path that touches no refraction support (straight
   NEE's). Returns 0 when nothing arrives. */
static int rrv__chain_carry(rrv__context *ctx, const rrv__chain *ch, const rrv__vertex_bsdf *v, rrv__rng *rng,
                            double out[3])
{
    const rrv_scene *scene = ctx->scene;
    double T[3] = {1, 1, 1}, f[3];
    int k, c, touched = 0; /* vertices do not imply it: comb planes reach past the supports */
    rrv__vertex_eval(v, rrv__normalize(rrv__sub(ch->x[1], ch->x[0])), f);
    if (!(rrv__max3(f) > 0)) return 0;
    ++ctx->stats.paths;
    for (k = 0; k <= ch->n; ++k) {
        rrv_vec3 x = ch->x[k], d = rrv__sub(ch->x[k + 1], x);
        double len = rrv__length(d), Ts[3];
        rrv__hit hit;
        d = rrv__scale(d, 1.0 / len);
        if (!touched) {
            rrv__support_view view;
            rrv__look_along(scene, x, d, &view);
            touched = view.inside || view.t_face < len;
        }
        if (rrv__intersect_scene(scene, x, d, len * (1.0 - 1e-6), &hit)) return 0;
        rrv__transmittance(ctx, x, d, len * (1.0 - 1e-6), rng, Ts);
        for (c = 0; c < 3; ++c) T[c] *= Ts[c];
        if (!rrv__nonzero3(T)) return 0;
    }
    if (!touched) return 0;
    for (c = 0; c < 3; ++c) out[c] = f[c] * T[c];
    return 1;
}


/* A random seed's initial direction: a Gaussian around the chord of 0.02
   rad (half the time), of 0.2 rad (three times in eight) or uniform (one
   in eight), so every root's basin keeps a nonzero probability. The chord
   itself is not among them: it is the seed of the connection's
   deterministic try (rrv__manifold_nee). */
static rrv_vec3 rrv__chain_seed_direction(const rrv__chain *ch, rrv__rng *rng)
{
    double u = rrv__uniform(rng), u1 = rrv__uniform(rng), u2 = rrv__uniform(rng);
    if (u < 0.875) {
        double rad = (u < 0.5 ? 0.02 : 0.2) * sqrt(-2.0 * log(1.0 - u1)), phi = 2.0 * RRV__PI * u2;
        return rrv__normalize(rrv__add(ch->c, rrv__add(rrv__scale(ch->c1, rad * cos(phi)), rrv__scale(ch->c2, rad * sin(phi)))));
    }
    return rrv__sample_uniform_sphere(u1, u2);
}

/* What one connection's chain solves already know (rrv__manifold_try):
   the polishes of the first two roots found (the chord's and the random
   try's), each keyed by the snapped coarse root it started from. It lives
   for one connection, whose coarse chain (and so the key's length) is
   fixed. */
#define RRV__COARSE_MAX (RRV__CHAIN_MAX / RRV__SOLVE_COARSE)
#define RRV__MEMO_SLOTS 2
typedef struct rrv__chain_memo {
    int used;
    struct {
        int found;
        double seed[RRV__COARSE_MAX][3];
        rrv__mroot root;
    } slot[RRV__MEMO_SLOTS];
} rrv__chain_memo;
static void rrv__chain_memo_clear(rrv__chain_memo *memo)
{
    memo->used = 0;
}

/* The coarse chain's inner vertices relative to x0 in the chord's frame
   (along c, c1, c2), each snapped to a lattice of 2^-20 m: two solves
   that converged to one root (to 1e-9) snap to the same numbers but for
   one in a few hundred, which only polishes again. */
static void rrv__chain_snap(const rrv__chain *coarse, double (*key)[3])
{
    const double per = 1048576.0;
    int k;
    for (k = 1; k <= coarse->n; ++k) {
        rrv_vec3 o = rrv__sub(coarse->x[k], coarse->x[0]);
        key[k - 1][0] = floor(rrv__dot(o, coarse->c) * per + 0.5) / per;
        key[k - 1][1] = floor(rrv__dot(o, coarse->c1) * per + 0.5) / per;
        key[k - 1][2] = floor(rrv__dot(o, coarse->c2) * per + 0.5) / per;
    }
}

/* Knot i of the cubic below: x0 (i <= 0), the m snapped coarse vertices
   key (1..m) or y (i > m), L = |y - x0|. Returns t along the chord, the
   offset from it in o. */
static double rrv__chain_knot(const double (*key)[3], int m, double L, int i, double o[2])
{
    if (i <= 0 || i > m) {
        o[0] = o[1] = 0.0;
        return i <= 0 ? 0.0 : L;
    }
    o[0] = key[i - 1][1];
    o[1] = key[i - 1][2];
    return key[i - 1][0];
}

/* Seeds ch (same x0, y and so the same chord frame) on the cubic through
   the knots (rrv__chain_knot): the offset from the chord as a function
   of t along it, Hermite with centred-difference slopes (one-sided at
   the ends), ISO vertices then projected. */
static void rrv__chain_seed_between(const rrv_scene *scene, rrv__chain *ch, const double (*key)[3], int m)
{
    double L = rrv__length(rrv__sub(ch->x[ch->n + 1], ch->x[0]));
    int k, j = 0;
    ch->failed = 0;
    for (k = 1; k <= ch->n; ++k) {
        double t = ch->t[k - 1], oa[2], ob[2], op[2], on[2], o[2], ta, tb, tp, tn, h, s, h00, h10, h01, h11;
        int a;
        while (j < m && key[j][0] <= t) ++j; /* t lies between knots j and j + 1 */
        ta = rrv__chain_knot(key, m, L, j, oa);
        tb = rrv__chain_knot(key, m, L, j + 1, ob);
        tp = rrv__chain_knot(key, m, L, j - 1, op);
        tn = rrv__chain_knot(key, m, L, j + 2, on);
        h = fmax(tb - ta, 1e-12);
        s = fmin(fmax((t - ta) / h, 0.0), 1.0);
        h00 = (1 + 2 * s) * (1 - s) * (1 - s);
        h10 = s * (1 - s) * (1 - s);
        h01 = s * s * (3 - 2 * s);
        h11 = s * s * (s - 1);
        for (a = 0; a < 2; ++a) {
            double sa = j == 0 ? (ob[a] - oa[a]) / h : (ob[a] - op[a]) / fmax(tb - tp, 1e-12);
            double sb = j == m ? (ob[a] - oa[a]) / h : (on[a] - oa[a]) / fmax(tn - ta, 1e-12);
            o[a] = h00 * oa[a] + h10 * h * sa + h01 * ob[a] + h11 * h * sb;
        }
        ch->x[k] = rrv__madd(rrv__madd(rrv__madd(ch->x[0], ch->c, t), ch->c1, o[0]), ch->c2, o[1]);
        if (ch->iso && !rrv__project_iso(scene, &ch->x[k], ch->level[k])) ch->failed = 1;
    }
}

static int rrv__chain_solve(const rrv_scene *scene, rrv__chain *ch, rrv__mroot *root)
{
    return scene->settings.manifold_solver == RRV_MANIFOLD_SOLVER_LM ? rrv__manifold_solve(scene, ch, root)
                                                                    : rrv__manifold_dogleg(scene, ch, root);
}

/* Seeds ch from direction w and solves it: with shoot, the chain shot
   from w (rrv__chain_shoot); where that fails or without shoot, traced
   from w and aimed at y, or the parabola from it where no trace reaches
   y. *evaluations gets the traces and the solve's evaluations. */
static int rrv__chain_solve_from(const rrv_scene *scene, rrv__chain *ch, rrv_vec3 w, int shoot, rrv__mroot *root,
                                 int *evaluations)
{
    int traces = 0, aimed = 0, found;
    if (!shoot || !rrv__chain_shoot(scene, ch, w, &traces))
        if (!rrv__chain_aim(scene, ch, w, &aimed)) rrv__chain_seed(scene, ch, w);
    found = rrv__chain_solve(scene, ch, root);
    *evaluations += root->iterations + aimed + traces;
    return found;
}

/* One seed's solve. Most take two stages, as shoot's solve does with its
   coarse steps: the coarse chain (ctx->coarse_chain, planes about
   RRV__SOLVE_COARSE times as far apart) is shot from the seed w
   (rrv__chain_shoot; where the shot fails, aimed and solved as a chain);
   then the fine chain is seeded on the cubic through the coarse root's
   vertices, snapped to a lattice (rrv__chain_snap,
   rrv__chain_seed_between), and solved from there. From raw seeds the
   lens caustic's fine chains take 8 traces and 3 evaluations of 101
   planes; the polish 3.5 evaluations, and the coarse shot 8.5 traces
   of 30 planes.
   The map from seed to root stays deterministic. A seed whose coarse
   solve fails is solved on the fine chain directly, as is every random
   seed in a share RRV__CHAIN_DIRECT (direct, drawn by the caller): so every
   root the fine chain reaches from some seed keeps a nonzero probability,
   however the coarse chain's roots differ from it. The polish is a
   function of the snapped coarse root alone (test_manifold_memo_is_exact),
   so where a try's coarse root snaps onto one of the memo's, the memo's
   result is the polish's, bit for bit. The memo keeps the first roots
   found, the chord's and the random try's whose 1/p the trials estimate:
   a trial that comes back to either costs a coarse solve, whatever other
   roots the trials between found. */
#define RRV__CHAIN_DIRECT 0.0625
static int rrv__chain_try_once(rrv__context *ctx, rrv__chain *ch, rrv_vec3 w, int direct, rrv__chain_memo *memo,
                               rrv__mroot *root, int *evaluations)
{
    const rrv_scene *scene = ctx->scene;
    rrv__chain *coarse = ctx->coarse_chain;
    rrv__mroot near;
    double key[RRV__COARSE_MAX][3];
    int found = 0, i;
    if (!direct) {
        int traces;
        found = rrv__chain_shoot(scene, coarse, w, &traces);
        *evaluations += traces;
        if (!found) found = rrv__chain_solve_from(scene, coarse, w, 0, &near, evaluations);
    }
    if (!found) return rrv__chain_solve_from(scene, ch, w, 1, root, evaluations);
    rrv__chain_snap(coarse, key);
    for (i = 0; memo && i < memo->used; ++i)
        if (!memcmp(key, memo->slot[i].seed, (size_t)coarse->n * sizeof key[0])) {
            *root = memo->slot[i].root;
            return memo->slot[i].found;
        }
    rrv__chain_seed_between(scene, ch, (const double (*)[3])key, coarse->n);
    root->iterations = 0; /* a seed that failed is not solved */
    found = !ch->failed && rrv__chain_solve(scene, ch, root);
    *evaluations += root->iterations;
    if (memo && found && memo->used < RRV__MEMO_SLOTS) {
        i = memo->used++;
        memo->slot[i].found = found;
        memcpy(memo->slot[i].seed, key, (size_t)coarse->n * sizeof key[0]);
        memo->slot[i].root = *root;
    }
    return found;
}

/* One solve, counted in the stats: from the chord (from_chord; one seed,
   deterministic) or from fresh seeds of rrv__chain_seed_direction. On
   return with the memo's result, ch is left as it was: only the root's
   direction and density are read then. */
static int rrv__manifold_try(rrv__context *ctx, rrv__chain *ch, rrv__rng *rng, rrv__chain_memo *memo,
                             int from_chord, rrv__mroot *root)
{
    int found = 0, k, evaluations = 0, coarse = ctx->coarse_chain && ctx->coarse_chain->n > 0;
    if (from_chord) {
        /* never solved directly where a coarse stage exists: the random
           seeds' direct share keeps every root of the fine chain
           reachable, and a direct solve costs some five of a coarse one
           and its polish */
        found = rrv__chain_try_once(ctx, ch, ch->c, !coarse, memo, root, &evaluations);
    }
    /* up to RRV__SOLVE_RESTARTS random seeds, as shoot's solve: a solve
       that fails is not a return to the root, so each failure of the
       trials that estimate 1/p doubled a connection's weight or more (on
       the fire caustic 1.7 % of connections, 40x shoot's variance a
       sample) */
    for (k = 0; !from_chord && k < RRV__SOLVE_RESTARTS && !found; ++k) {
        rrv_vec3 w = rrv__chain_seed_direction(ch, rng);
        int direct = !coarse || rrv__uniform(rng) < RRV__CHAIN_DIRECT;
        found = rrv__chain_try_once(ctx, ch, w, direct, memo, root, &evaluations);
    }
    root->iterations = evaluations;
    ++ctx->stats.solves;
    ctx->stats.solve_iterations += (uint64_t)root->iterations;
    if (found) {
        ++ctx->stats.solves_converged;
        ctx->stats.solve_segments += (uint64_t)(ch->n + 1);
    }
    return found;
}

/* Does the solved chain reach the light y from the side it emits on (the
   normal ny, cross(e1, e2) of a quad or triangle)? A root that arrives
   from behind carries no light: forward paths that hit a light's back
   collect none either. */
static int rrv__chain_meets_front(const rrv__chain *ch, rrv_vec3 ny)
{
    return rrv__dot(rrv__sub(ch->x[ch->n + 1], ch->x[ch->n]), ny) < 0;
}

/* The MIS weight of a solved chain leaving x0 along w0 (density pdf_dir
   there) toward a light point of area density pdf_area, against the
   forward path. On the eikonal integrator, shoot's power heuristic
   (rrv__shoot_mis_weight) with the chain's own |det| = 1 / density; the
   forward path takes one minus shoot's weight from the shot along its own
   direction (rrv__solver_forward_weight), which agrees with the chain's
   wherever the two models of the ray do (within 2e-3 under a plume,
   test_nee). Near a caustic |det| -> 0, the forward path takes the
   connection and the estimate stays below 1 / (2 pdf_dir), as shoot's
   does. On the comb, whose forward paths have no det to weigh by, the
   chain keeps its paths alone (weight 1). */
static double rrv__manifold_mis_weight(const rrv__context *ctx, double density, double pdf_area, double pdf_dir)
{
    if (!ctx->eikonal) return 1.0;
    if (!(density > 0) || !(density < DBL_MAX)) return 0.0;
    return rrv__shoot_mis_weight(pdf_area, 1.0 / density, pdf_dir);
}

/* One trial of the 1/q estimate: a fresh solve from random seeds that
   comes back to the root w0. */
typedef struct rrv__manifold_recurrence {
    rrv__context *ctx;
    rrv_vec3 w0;
    rrv__chain_memo *memo;
} rrv__manifold_recurrence;
static int rrv__manifold_recurs(void *user, rrv__rng *rng)
{
    rrv__manifold_recurrence *t = (rrv__manifold_recurrence *)user;
    rrv__mroot again;
    return rrv__manifold_try(t->ctx, t->ctx->chain, rng, t->memo, 0, &again) &&
           rrv__length(rrv__sub(again.w0, t->w0)) < RRV__SOLVE_SAME_ROOT;
}

/* Sets up ctx->coarse_chain for the chain just set up in ctx->chain (light
   normal ny, comb offset u): even planes RRV__SOLVE_COARSE times the fine
   chain's mean spacing apart, but no farther than turns a ray by
   RRV__CHAIN_COARSE_BEND at the steepest gradient (rrv__coarse_of); no
   planes (no coarse stage) where that leaves more than half of the fine
   chain's. The bend's cap keeps the coarse chain's roots and basins close
   to the fine one's where several roots compete: on the lens caustic at
   shoot's 0.6 rad (13 planes, 0.16 rad a plane) the seeds found the roots
   in other proportions, and the estimate of 1/p gained more variance
   than the coarse stage saved time (efficiency 16.6 against 27.1 without
   it); at 0.1 (20 planes) 17.4 against 11.4 (test/bench/RESULTS.md,
   "Two-stage chain solves"). On the fire caustic and the heat shadow,
   one root a connection, the cap does not bind. */
#define RRV__CHAIN_COARSE_BEND 0.1
static void rrv__chain_setup_coarse(rrv__context *ctx, rrv_vec3 ny, double u)
{
    const rrv__chain *ch = ctx->chain;
    rrv__chain *coarse = ctx->coarse_chain;
    double spacing;
    if (!coarse) return;
    coarse->n = 0;
    if (ch->n < 4) return;
    spacing = rrv__coarse_of(ctx->scene, (ch->hi - ch->lo) / ch->n, RRV__CHAIN_COARSE_BEND,
                             ctx->eta_floor > 0 ? ctx->eta_floor : 1.0);
    rrv__chain_setup_spaced(ctx->scene, ch->x[0], ch->x[ch->n + 1], ny, ch->iso, ctx->scene->settings.manifold_drop,
                            u, spacing, coarse);
    if (2 * coarse->n > ch->n) coarse->n = 0;
}

/* The light of a solved root: its chain's transmittance carried, times
   weight, into the path. */
static void rrv__manifold_light(rrv__context *ctx, rrv__path *path, const rrv__vertex_bsdf *v, const rrv_shape *s,
                                rrv_vec3 y, double pdf_area, const rrv__mroot *root, const double carried[3],
                                double weight)
{
    double k = root->density / pdf_area * weight * rrv__eta_scale(ctx, y) * rrv__path_mis(path) *
               rrv__manifold_mis_weight(ctx, root->density, pdf_area, rrv__vertex_pdf(v, root->w0));
    int c;
    for (c = 0; c < 3; ++c) path->L[c] += path->beta[c] * carried[c] * s->L[c] * k;
}

/* Does the chain as solved carry light (it meets the light's front and
   rrv__chain_carry finds a way through)? */
static int rrv__manifold_carries(rrv__context *ctx, const rrv__vertex_bsdf *v, rrv_vec3 ny, rrv__rng *rng,
                                 double carried[3])
{
    return rrv__chain_meets_front(ctx->chain, ny) && rrv__chain_carry(ctx, ctx->chain, v, rng, carried);
}

/* The unbiased estimate of one connection (ctx->chain and its coarse
   stage set up, manifold_trials 0): the roots it counts, at most two,
   with their weights and carried throughputs; returns how many. Two
   tries split the roots between them:
     the chord's: one solve seeded on the chord, a deterministic map, so
       its root r_c (if it converges) is counted once with weight 1;
     a random one, made with probability s (rrv__random_try_share): one
       solve from random seeds, which reaches root r with probability
       q_r > 0.
       A root other than r_c counts f(r) / (s q), 1/q estimated by
       repeating random solves until r recurs (directions within
       RRV__SOLVE_SAME_ROOT), beyond RRV__SOLVE_TRIALS of them by Russian
       roulette (rrv__inverse_probability: E = 1/q exactly); r_c counts 0.
   So E = f(r_c) + sum over r != r_c of s q_r f(r) / (s q_r) = sum over
   all roots of f(r) (test_manifold_estimate_is_unbiased). The root
   through a lens, the chord's nearly always, is counted without the
   noise of a 1/p estimate, and the trials are made for the other roots
   alone, found with the random seeds' whole probability rather than a
   share of a mixture's. A root of small q found at all weighs 1/(s q):
   the smaller s, the cheaper a connection and the louder those.
   Measured on the lens caustic against one mixture of seeds (the chord
   3/4 of the time) for the first solve and every trial: see
   test/bench/RESULTS.md, "The chord's root counted once". */
static int rrv__manifold_estimate(rrv__context *ctx, const rrv__vertex_bsdf *v, rrv_vec3 ny, rrv__rng *rng,
                                  rrv__mroot root[2], double weight[2], double carried[2][3])
{
    rrv__chain_memo memo;
    rrv__manifold_recurrence again;
    rrv__mroot chord;
    double inverse_q, share;
    long count;
    int n = 0, chord_found;
    rrv__chain_memo_clear(&memo);
    chord_found = rrv__manifold_try(ctx, ctx->chain, rng, &memo, 1, &chord);
    ctx->stats.solve_trials += 1;
    if (chord_found && rrv__manifold_carries(ctx, v, ny, rng, carried[0])) {
        root[0] = chord;
        weight[n++] = 1.0;
    }
    if (!(share = rrv__random_try_share(chord_found, rng))) return n;
    ctx->stats.solve_trials += 1;
    /* a random try that lands on the chord's root may take its polish
       from the memo (the chain then left elsewhere), but counts nothing */
    if (!rrv__manifold_try(ctx, ctx->chain, rng, &memo, 0, &root[n]) ||
        (chord_found && rrv__length(rrv__sub(root[n].w0, chord.w0)) < RRV__SOLVE_SAME_ROOT) ||
        !rrv__manifold_carries(ctx, v, ny, rng, carried[n]))
        return n;
    again.ctx = ctx;
    again.w0 = root[n].w0;
    again.memo = &memo;
    inverse_q = rrv__inverse_probability(rng, RRV__SOLVE_TRIALS, rrv__manifold_recurs, &again, &count);
    ctx->stats.solve_trials += (uint64_t)count;
    weight[n] = inverse_q / share;
    return n + 1;
}

/* Curved NEE from x0 by the manifold walk. The light point y and the
   chain's comb offset are drawn once; conditioned on them the estimate is
   unbiased for the chain model (rrv__manifold_estimate). The fixed-trial
   mode (manifold_trials M) makes the chord's try and M - 1 random ones
   and sums each distinct root once (biased low where a root's basin is
   small, Zeltner et al.'s biased SMS). The partition of path space is
   shoot's (manual, NEXT-EVENT ESTIMATION). */
static void rrv__manifold_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                              const rrv__light_draw *draw, rrv__rng *rng)
{
    const rrv_scene *scene = ctx->scene;
    const rrv_settings *st = &scene->settings;
    rrv__chain *ch = ctx->chain;
    rrv__mroot root[2];
    rrv_vec3 y, ny, roots[RRV__MANIFOLD_ROOTS];
    double pdf_area, carried[2][3], weight[2], offset, to_y;
    const rrv_shape *s = rrv__pick_area_light(scene, draw, x0, 0, &y, &ny, &pdf_area);
    int nroots = 0, trial, i, n;
    if (!s || !ch) return;
    to_y = rrv__length(rrv__sub(y, x0));
    if (!(to_y > 0) || rrv__weak_chord(ctx, x0, rrv__scale(rrv__sub(y, x0), 1.0 / to_y), to_y)) return;
    offset = rrv__uniform(rng);
    rrv__chain_setup(scene, x0, y, ny, st->manifold_gauge == RRV_GAUGE_ISO, st->manifold_drop, offset, ch);
    rrv__chain_setup_coarse(ctx, ny, offset);
    ++ctx->stats.solve_connections;
    if (st->manifold_trials <= 0) {
        n = rrv__manifold_estimate(ctx, v, ny, rng, root, weight, carried);
        for (i = 0; i < n; ++i) rrv__manifold_light(ctx, path, v, s, y, pdf_area, &root[i], carried[i], weight[i]);
        return;
    }
    for (trial = 0; trial < st->manifold_trials; ++trial) {
        if (!rrv__manifold_try(ctx, ch, rng, NULL, trial == 0, &root[0]) || !rrv__chain_meets_front(ch, ny)) continue;
        for (i = 0; i < nroots; ++i)
            if (rrv__length(rrv__sub(roots[i], root[0].w0)) < RRV__SOLVE_SAME_ROOT) break;
        if (i < nroots || nroots == RRV__MANIFOLD_ROOTS) continue;
        roots[nroots++] = root[0].w0;
        if (rrv__chain_carry(ctx, ch, v, rng, carried[0]))
            rrv__manifold_light(ctx, path, v, s, y, pdf_area, &root[0], carried[0], 1.0);
    }
    ctx->stats.solve_trials += (uint64_t)st->manifold_trials;
}

/* ---- the curved-NEE interface (declared at the head of the path tracer) ---------- */

static int rrv__solver_setup(rrv__context *ctx)
{
    if (ctx->shoot || ctx->manifold) rrv__cone_setup(ctx);
    if (!ctx->manifold) return 1;
    ctx->chain = rrv__chain_new(RRV__CHAIN_MAX);
    ctx->coarse_chain = rrv__chain_new(RRV__COARSE_MAX);
    if (ctx->chain && ctx->coarse_chain) return 1;
    /* the caller releases nothing of a context whose setup failed */
    rrv__solver_release(ctx);
    ctx->chain = ctx->coarse_chain = NULL;
    return 0;
}

static void rrv__solver_release(rrv__context *ctx)
{
    rrv__chain_delete(ctx->chain);
    rrv__chain_delete(ctx->coarse_chain);
}

/* Chains end on quads and triangles; with the eikonal integrator, whose
   rays shots differentiate, nee manifold shoots at sphere lights (the
   same draw names the same light point either way), which the comb's
   chains leave to forward paths. */
static int rrv__shoots_spheres(const rrv__context *ctx) { return ctx->manifold && ctx->eikonal; }

/* Whether the light the draw names is connected by shooting. */
static int rrv__draw_is_shot(const rrv__context *ctx, const rrv__light_draw *draw)
{
    int pick;
    if (ctx->shoot) return 1;
    if (!rrv__shoots_spheres(ctx)) return 0;
    pick = rrv__light_pick(ctx->scene, draw);
    return pick >= 0 && pick < ctx->scene->light_count &&
           ctx->scene->shapes[ctx->scene->lights[pick]].kind == RRV_SHAPE_SPHERE;
}

static void rrv__solver_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                            const rrv__light_draw *draw, rrv__rng *rng)
{
    if (rrv__draw_is_shot(ctx, draw)) rrv__shoot_nee(ctx, path, x0, v, draw, rng);
    else if (ctx->manifold) rrv__manifold_nee(ctx, path, x0, v, draw, rng);
    else return;
    rrv__cone_nee(ctx, path, x0, v, rng);
}

/* A forward path from x0 (left along w0 with density pdf_dir) that hit
   light s at x, in a support's class (rrv__forward_weak gave weak, 0 or
   2); jumped: it crossed a sharp interface, which shots cross refracted
   and chains not at all; mirrored: one reflected it, which no solver
   does. */
static double rrv__solver_forward_weight(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, double pdf_dir,
                                         const rrv_shape *s, rrv_vec3 x, int weak, int jumped, int mirrored)
{
    if (weak == 2) /* a root no light sample stands for: the cones' (rrv__cone_nee) */
        return rrv__power_heuristic(pdf_dir, rrv__cone_pdf(ctx, x0, w0));
    if ((ctx->shoot || (s->kind == RRV_SHAPE_SPHERE && rrv__shoots_spheres(ctx))) && !mirrored)
        return rrv__shoot_forward_weight(ctx, x0, w0, pdf_dir, s, x); /* MIS with shooting */
    if (ctx->manifold && !jumped && s->kind != RRV_SHAPE_SPHERE) /* shoot's weight (rrv__manifold_mis_weight) */
        return ctx->eikonal ? rrv__shoot_forward_weight(ctx, x0, w0, pdf_dir, s, x) : 0.0;
    return 1.0;
}

#else /* RRV_NO_CURVED_NEE: the interface answers "no curved estimator" (no
         scene is supported for solving, so ctx->shoot and ctx->manifold
         stay 0, nothing is set up and no connection is made) */

static int rrv__solver_supports_scene(const rrv_scene *scene)
{
    (void)scene;
    return 0;
}

static int rrv__solver_setup(rrv__context *ctx)
{
    (void)ctx;
    return 1;
}

static void rrv__solver_release(rrv__context *ctx) { (void)ctx; }

static void rrv__solver_nee(rrv__context *ctx, rrv__path *path, rrv_vec3 x0, const rrv__vertex_bsdf *v,
                            const rrv__light_draw *draw, rrv__rng *rng)
{
    (void)ctx; (void)path; (void)x0; (void)v; (void)draw; (void)rng;
}

/* no cones: a weak chord's other root is weighed against the density 0 of
   a direction no cone draws; no solver shares any other */
static double rrv__solver_forward_weight(rrv__context *ctx, rrv_vec3 x0, rrv_vec3 w0, double pdf_dir,
                                         const rrv_shape *s, rrv_vec3 x, int weak, int jumped, int mirrored)
{
    (void)ctx; (void)x0; (void)w0; (void)s; (void)x; (void)jumped; (void)mirrored;
    return weak == 2 ? rrv__power_heuristic(pdf_dir, 0.0) : 1.0;
}
#endif /* RRV_NO_CURVED_NEE */

/* >> 13 image I/O (module): PFM, PNG and OpenEXR files, checksums ===========
   This section owns everything that turns a float RGB buffer into bytes and
   back: the PFM writer and reader, the PNG preview writer (with its own
   deflate, which the EXR writer's ZIP chunks share), the CRC-32 and
   Adler-32 those formats use, and the file forms that write through a
   temporary file so a failed write never replaces a good image with half of
   a new one. The file forms' one way of opening a file for reading also
   serves the whole-file reader at the end, which the NanoVDB and scene file
   modules share. */

/* Floats are moved through uint32_t bit patterns to fix their byte order. */
typedef char rrv__float_must_be_ieee_single[(sizeof(float) == 4 && FLT_MANT_DIG == 24) ? 1 : -1];

/* ---- checksums --------------------------------------------------------------- */

RRV_DEF uint32_t rrv_crc32(uint32_t crc, const void *data, size_t size)
{
    /* CRC of each 4-bit value (reflected polynomial 0xEDB88320): half a byte a
       step keeps the table small enough to write out and read-only. */
    static const uint32_t nibble_crc[16] = {
        0x00000000u, 0x1DB71064u, 0x3B6E20C8u, 0x26D930ACu,
        0x76DC4190u, 0x6B6B51F4u, 0x4DB26158u, 0x5005713Cu,
        0xEDB88320u, 0xF00F9344u, 0xD6D6A3E8u, 0xCB61B38Cu,
        0x9B64C2B0u, 0x86D3D2D4u, 0xA00AE278u, 0xBDBDF21Cu
    };
    const unsigned char *bytes = (const unsigned char *)data;
    size_t i;
    /* The pre- and post-inversion live here so that callers chain calls
       starting from 0, as with zlib's crc32(). */
    crc = ~crc;
    for (i = 0; i < size; ++i) {
        crc ^= bytes[i];
        crc = (crc >> 4) ^ nibble_crc[crc & 15u];
        crc = (crc >> 4) ^ nibble_crc[crc & 15u];
    }
    return ~crc;
}

RRV_DEF uint32_t rrv_adler32(uint32_t adler, const void *data, size_t size)
{
    enum { ADLER_MOD = 65521, ADLER_MAX_RUN = 5552 };
    const unsigned char *bytes = (const unsigned char *)data;
    uint32_t a = (adler & 0xFFFFu) % ADLER_MOD, b = (adler >> 16) % ADLER_MOD;
    while (size > 0) {
        /* ADLER_MAX_RUN is the longest run of 0xFF bytes after which b still
           fits in 32 bits, so the modulo is needed only once per run. */
        size_t run = size < (size_t)ADLER_MAX_RUN ? size : (size_t)ADLER_MAX_RUN;
        size -= run;
        for (; run > 0; --run) {
            a += *bytes++;
            b += a;
        }
        a %= ADLER_MOD;
        b %= ADLER_MOD;
    }
    return (b << 16) | a;
}

/* ---- shared helpers ----------------------------------------------------------- */

#if !defined(RRV_NO_PNG) || !defined(RRV_NO_EXR)
static void rrv__put_u32_be(unsigned char *out, uint32_t v)
{
    out[0] = (unsigned char)(v >> 24);
    out[1] = (unsigned char)(v >> 16);
    out[2] = (unsigned char)(v >> 8);
    out[3] = (unsigned char)v;
}
#endif

/* Returns RRV_OK when rgb can hold width x height pixels whose byte count
   fits in size_t, so later index arithmetic cannot overflow. */
static rrv_result rrv__check_image_args(const float *rgb, int width, int height)
{
    if (!rgb || width <= 0 || height <= 0) return RRV_ERROR_ARGUMENT;
    if ((size_t)width > SIZE_MAX / 3 / sizeof(float) / (size_t)height) return RRV_ERROR_ARGUMENT;
    return RRV_OK;
}

/* Collects output into pieces of a fixed size so the callback sees neither
   one call per float nor the whole image at once. Once a write fails every
   later put is ignored and the writer reports RRV_ERROR_IO. */
typedef struct rrv__piece_writer {
    rrv_write_func write;
    void *user;
    unsigned char *piece;
    size_t fill, capacity;
    int failed;
} rrv__piece_writer;

static void rrv__piece_flush(rrv__piece_writer *w)
{
    if (w->failed || w->fill == 0) return;
    if (w->write(w->user, w->piece, w->fill) != 0) w->failed = 1;
    w->fill = 0;
}

static void rrv__piece_put(rrv__piece_writer *w, const void *data, size_t size)
{
    const unsigned char *src = (const unsigned char *)data;
    while (size > 0 && !w->failed) {
        size_t room = w->capacity - w->fill;
        size_t take = size < room ? size : room;
        memcpy(w->piece + w->fill, src, take);
        w->fill += take;
        src += take;
        size -= take;
        if (w->fill == w->capacity) rrv__piece_flush(w);
    }
}

/* ---- PFM writer ------------------------------------------------------------------ */

#define RRV__PFM_PIECE_BYTES ((size_t)64 * 1024)

static rrv_result rrv__write_pfm_to(rrv_write_func write, void *user,
                                    const float *rgb, int width, int height)
{
    rrv__piece_writer w;
    char header[64];
    int header_len, y;
    size_t row_floats = (size_t)width * 3, i;

    if (!write || rrv__check_image_args(rgb, width, height) != RRV_OK) return RRV_ERROR_ARGUMENT;
    header_len = snprintf(header, sizeof header, "PF\n%d %d\n-1.0\n", width, height);
    if (header_len <= 0 || (size_t)header_len >= sizeof header) return RRV_ERROR_ARGUMENT;

    w.write = write;
    w.user = user;
    w.fill = 0;
    w.capacity = RRV__PFM_PIECE_BYTES;
    w.failed = 0;
    w.piece = (unsigned char *)RRV_MALLOC(w.capacity);
    if (!w.piece) return RRV_ERROR_MEMORY;

    rrv__piece_put(&w, header, (size_t)header_len);
    /* PFM stores the bottom row first; the buffer's row 0 is the top. */
    for (y = height - 1; y >= 0 && !w.failed; --y) {
        const float *row = rgb + (size_t)y * row_floats;
        for (i = 0; i < row_floats; ++i) {
            uint32_t bits;
            unsigned char le[4];
            memcpy(&bits, &row[i], sizeof bits);
            le[0] = (unsigned char)bits;
            le[1] = (unsigned char)(bits >> 8);
            le[2] = (unsigned char)(bits >> 16);
            le[3] = (unsigned char)(bits >> 24);
            rrv__piece_put(&w, le, 4);
        }
    }
    rrv__piece_flush(&w);
    RRV_FREE(w.piece);
    return w.failed ? RRV_ERROR_IO : RRV_OK;
}

/* Deflate serves PNG and the EXR writer: a build without both leaves it out. */
#if !defined(RRV_NO_PNG) || !defined(RRV_NO_EXR)
/* ---- deflate (zlib), for PNG's IDAT and EXR's ZIP chunks ---------------------
   Greedy LZ77 over a 32 KiB window with hash chains, then blocks with
   Huffman codes made for their tokens. rrv__zlib_compress writes one block
   into a buffer the size of the raw chunk; running out of room means the
   chunk does not shrink, and the EXR writer stores it raw instead. */

#define RRV__LZ_WINDOW 32768
#define RRV__LZ_HASH_BITS 15
#define RRV__LZ_MAX_CHAIN 48
#define RRV__HUFF_MAX_BITS 15

typedef struct rrv__bit_writer {
    unsigned char *out;
    size_t size, capacity;
    uint32_t bits;
    int count, full;
} rrv__bit_writer;

/* Appends n <= 16 bits, least significant first, as deflate packs them. */
static void rrv__bits_put(rrv__bit_writer *b, uint32_t value, int n)
{
    b->bits |= value << b->count;
    b->count += n;
    while (b->count >= 8) {
        if (b->size < b->capacity) b->out[b->size++] = (unsigned char)b->bits;
        else b->full = 1;
        b->bits >>= 8;
        b->count -= 8;
    }
}

/* Huffman codes go out most significant bit first. */
static void rrv__bits_put_code(rrv__bit_writer *b, uint32_t code, int length)
{
    uint32_t reversed = 0;
    int i;
    for (i = 0; i < length; ++i) reversed |= ((code >> i) & 1u) << (length - 1 - i);
    rrv__bits_put(b, reversed, length);
}

static const uint16_t rrv__deflate_length_base[29] = {
    3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31,
    35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258 };
static const unsigned char rrv__deflate_length_extra[29] = {
    0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0 };
static const uint16_t rrv__deflate_dist_base[30] = {
    1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769,
    1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577 };
static const unsigned char rrv__deflate_dist_extra[30] = {
    0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13 };

static int rrv__deflate_length_code(unsigned length)
{
    int i = 28;
    while (rrv__deflate_length_base[i] > length) --i;
    return i;
}

static int rrv__deflate_dist_code(unsigned dist)
{
    int i = 29;
    while (rrv__deflate_dist_base[i] > dist) --i;
    return i;
}

/* Code lengths of at most max_bits for the symbols' frequencies (unused
   symbols get 0). A Huffman tree too deep for the limit is rebuilt from
   halved frequencies, which flattens it; the caller makes sure at least two
   symbols are used, so every code is complete. */
static void rrv__huffman_lengths(const uint32_t *freq, int count, int max_bits, unsigned char *lengths)
{
    uint32_t weight[2 * 288];
    int parent[2 * 288], alive[2 * 288];
    uint32_t scaled[288];
    int i, shift = 0;
    for (;;) {
        int nodes = count, live = 0, deepest = 0;
        for (i = 0; i < count; ++i) {
            scaled[i] = freq[i] ? (freq[i] >> shift) | 1u : 0u;
            weight[i] = scaled[i];
            alive[i] = scaled[i] > 0;
            parent[i] = -1;
            live += alive[i];
        }
        /* Quadratic selection of the two lightest nodes: at most 288
           symbols, a few times per chunk. */
        while (live > 1) {
            int a = -1, b = -1;
            for (i = 0; i < nodes; ++i) {
                if (!alive[i]) continue;
                if (a < 0 || weight[i] < weight[a]) { b = a; a = i; }
                else if (b < 0 || weight[i] < weight[b]) b = i;
            }
            weight[nodes] = weight[a] + weight[b];
            alive[nodes] = 1;
            parent[nodes] = -1;
            alive[a] = alive[b] = 0;
            parent[a] = parent[b] = nodes;
            ++nodes;
            --live;
        }
        for (i = 0; i < count; ++i) {
            int depth = 0, n = i;
            if (!scaled[i]) { lengths[i] = 0; continue; }
            while (parent[n] >= 0) { n = parent[n]; ++depth; }
            lengths[i] = (unsigned char)depth;
            if (depth > deepest) deepest = depth;
        }
        if (deepest <= max_bits) return;
        ++shift;
    }
}

/* Canonical codes from code lengths (RFC 1951, 3.2.2). */
static void rrv__huffman_codes(const unsigned char *lengths, int count, uint16_t *codes)
{
    int bl_count[RRV__HUFF_MAX_BITS + 1] = { 0 }, bits, i;
    uint32_t next[RRV__HUFF_MAX_BITS + 1], code = 0;
    for (i = 0; i < count; ++i) ++bl_count[lengths[i]];
    bl_count[0] = 0;
    for (bits = 1; bits <= RRV__HUFF_MAX_BITS; ++bits) {
        code = (code + (uint32_t)bl_count[bits - 1]) << 1;
        next[bits] = code;
    }
    for (i = 0; i < count; ++i)
        codes[i] = lengths[i] ? (uint16_t)next[lengths[i]]++ : 0;
}

/* Scratch memory of one compressor, reused across chunks. A token is a
   literal byte (< 256) or (length << 16 | distance). */
typedef struct rrv__deflater {
    int32_t head[1 << RRV__LZ_HASH_BITS];
    int32_t prev[RRV__LZ_WINDOW];
    uint32_t *tokens; /* room for one token per input byte */
} rrv__deflater;

/* LZ77 tokens of data[start, size). data[0, start) was compressed before
   (the previous block of the same stream): it is only hashed, so matches can
   reach back into it. */
static size_t rrv__lz77(rrv__deflater *z, const unsigned char *data, size_t start, size_t size)
{
    size_t pos, count = 0, i;
    for (i = 0; i < ((size_t)1 << RRV__LZ_HASH_BITS); ++i) z->head[i] = -1;
#define RRV__LZ_HASH(p) ((((uint32_t)(p)[0] << 10) ^ ((uint32_t)(p)[1] << 5) ^ (uint32_t)(p)[2]) & \
                         ((1u << RRV__LZ_HASH_BITS) - 1u))
    for (pos = start > RRV__LZ_WINDOW ? start - RRV__LZ_WINDOW : 0; pos < start && pos + 3 <= size; ++pos) {
        uint32_t h = RRV__LZ_HASH(data + pos);
        z->prev[pos & (RRV__LZ_WINDOW - 1)] = z->head[h];
        z->head[h] = (int32_t)pos;
    }
    pos = start;
    while (pos < size) {
        size_t best = 0, best_dist = 0;
        if (pos + 3 <= size) {
            uint32_t h = RRV__LZ_HASH(data + pos);
            int32_t candidate = z->head[h];
            int chain = RRV__LZ_MAX_CHAIN;
            size_t limit = size - pos < 258 ? size - pos : 258;
            while (candidate >= 0 && pos - (size_t)candidate <= RRV__LZ_WINDOW && chain-- > 0) {
                const unsigned char *a = data + candidate, *b = data + pos;
                if (a[best] == b[best]) {
                    size_t n = 0;
                    while (n < limit && a[n] == b[n]) ++n;
                    if (n > best) {
                        best = n;
                        best_dist = pos - (size_t)candidate;
                        if (n == limit) break;
                    }
                }
                {
                    int32_t next = z->prev[candidate & (RRV__LZ_WINDOW - 1)];
                    if (next >= candidate) break;
                    candidate = next;
                }
            }
            z->prev[pos & (RRV__LZ_WINDOW - 1)] = z->head[h];
            z->head[h] = (int32_t)pos;
        }
        if (best >= 3) {
            z->tokens[count++] = (uint32_t)best << 16 | (uint32_t)best_dist;
            for (i = 1; i < best; ++i) {
                size_t p = pos + i;
                if (p + 3 <= size) {
                    uint32_t h = RRV__LZ_HASH(data + p);
                    z->prev[p & (RRV__LZ_WINDOW - 1)] = z->head[h];
                    z->head[h] = (int32_t)p;
                }
            }
            pos += best;
        } else {
            z->tokens[count++] = data[pos++];
        }
    }
#undef RRV__LZ_HASH
    return count;
}

/* Appends one deflate block with Huffman codes made for these tokens
   (BFINAL set when final). */
static void rrv__deflate_block(rrv__bit_writer *b, const uint32_t *token_list, size_t tokens, int final)
{
    static const unsigned char cl_order[19] = {
        16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15 };
    uint32_t lit_freq[288] = { 0 }, dist_freq[30] = { 0 }, cl_freq[19] = { 0 };
    unsigned char lit_len[288], dist_len[30], cl_len[19], all_len[288 + 30];
    uint16_t lit_code[288], dist_code[30], cl_code[19];
    unsigned char runs[288 + 30], run_extra[288 + 30];
    size_t t, run_count = 0;
    int hlit, hdist, hclen, total, i;

    for (t = 0; t < tokens; ++t) {
        uint32_t token = token_list[t];
        if (token < 256) {
            ++lit_freq[token];
        } else {
            ++lit_freq[257 + rrv__deflate_length_code(token >> 16)];
            ++dist_freq[rrv__deflate_dist_code(token & 0xFFFFu)];
        }
    }
    lit_freq[256] = 1;
    /* Two used distance codes at least, so that code is complete even in a
       chunk without matches (decoders differ on incomplete ones). */
    if (!dist_freq[0]) dist_freq[0] = 1;
    if (!dist_freq[1]) dist_freq[1] = 1;
    rrv__huffman_lengths(lit_freq, 288, RRV__HUFF_MAX_BITS, lit_len);
    rrv__huffman_lengths(dist_freq, 30, RRV__HUFF_MAX_BITS, dist_len);
    rrv__huffman_codes(lit_len, 288, lit_code);
    rrv__huffman_codes(dist_len, 30, dist_code);

    for (hlit = 286; hlit > 257 && lit_len[hlit - 1] == 0; --hlit) {}
    for (hdist = 30; hdist > 1 && dist_len[hdist - 1] == 0; --hdist) {}
    memcpy(all_len, lit_len, (size_t)hlit);
    memcpy(all_len + hlit, dist_len, (size_t)hdist);
    total = hlit + hdist;
    /* Runs of code lengths: 16 repeats the previous length 3-6 times, 17 and
       18 write 3-10 and 11-138 zeros. */
    for (i = 0; i < total;) {
        int run = 1;
        while (i + run < total && all_len[i + run] == all_len[i]) ++run;
        if (all_len[i] == 0 && run >= 3) {
            if (run > 138) run = 138;
            runs[run_count] = (unsigned char)(run >= 11 ? 18 : 17);
            run_extra[run_count++] = (unsigned char)(run >= 11 ? run - 11 : run - 3);
            i += run;
        } else if (all_len[i] != 0 && run >= 4) {
            if (run > 7) run = 7;
            runs[run_count] = all_len[i];
            run_extra[run_count++] = 0;
            runs[run_count] = 16;
            run_extra[run_count++] = (unsigned char)(run - 4);
            i += run;
        } else {
            runs[run_count] = all_len[i];
            run_extra[run_count++] = 0;
            ++i;
        }
    }
    for (t = 0; t < run_count; ++t) ++cl_freq[runs[t]];
    {
        int used = 0;
        for (i = 0; i < 19; ++i) used += cl_freq[i] > 0;
        for (i = 0; used < 2; ++i) if (!cl_freq[i]) { cl_freq[i] = 1; ++used; }
    }
    rrv__huffman_lengths(cl_freq, 19, 7, cl_len);
    rrv__huffman_codes(cl_len, 19, cl_code);
    for (hclen = 19; hclen > 4 && cl_len[cl_order[hclen - 1]] == 0; --hclen) {}

    rrv__bits_put(b, final ? 1u : 0u, 1); /* BFINAL */
    rrv__bits_put(b, 2, 2); /* dynamic Huffman */
    rrv__bits_put(b, (uint32_t)(hlit - 257), 5);
    rrv__bits_put(b, (uint32_t)(hdist - 1), 5);
    rrv__bits_put(b, (uint32_t)(hclen - 4), 4);
    for (i = 0; i < hclen; ++i) rrv__bits_put(b, cl_len[cl_order[i]], 3);
    for (t = 0; t < run_count; ++t) {
        rrv__bits_put_code(b, cl_code[runs[t]], cl_len[runs[t]]);
        if (runs[t] == 16) rrv__bits_put(b, run_extra[t], 2);
        else if (runs[t] == 17) rrv__bits_put(b, run_extra[t], 3);
        else if (runs[t] == 18) rrv__bits_put(b, run_extra[t], 7);
    }
    for (t = 0; t < tokens && !b->full; ++t) {
        uint32_t token = token_list[t];
        if (token < 256) {
            rrv__bits_put_code(b, lit_code[token], lit_len[token]);
        } else {
            unsigned length = token >> 16, dist = token & 0xFFFFu;
            int lc = rrv__deflate_length_code(length), dc = rrv__deflate_dist_code(dist);
            rrv__bits_put_code(b, lit_code[257 + lc], lit_len[257 + lc]);
            if (rrv__deflate_length_extra[lc])
                rrv__bits_put(b, length - rrv__deflate_length_base[lc], rrv__deflate_length_extra[lc]);
            rrv__bits_put_code(b, dist_code[dc], dist_len[dc]);
            if (rrv__deflate_dist_extra[dc])
                rrv__bits_put(b, dist - rrv__deflate_dist_base[dc], rrv__deflate_dist_extra[dc]);
        }
    }
    rrv__bits_put_code(b, lit_code[256], lit_len[256]);
}

#ifndef RRV_NO_EXR /* PNG streams its blocks itself */
/* Compresses data into out as a zlib stream of one block; returns its size,
   or 0 when it would not fit in capacity. */
static size_t rrv__zlib_compress(rrv__deflater *z, const unsigned char *data, size_t size,
                                 unsigned char *out, size_t capacity)
{
    rrv__bit_writer b;
    size_t tokens;
    if (capacity < 8) return 0;
    b.out = out;
    b.size = 0;
    b.capacity = capacity - 4; /* room for the Adler-32 trailer */
    b.bits = 0;
    b.count = 0;
    b.full = 0;
    out[b.size++] = 0x78; /* deflate, 32 KiB window */
    out[b.size++] = 0x01; /* no dictionary; (0x7801 % 31) == 0 */
    tokens = rrv__lz77(z, data, 0, size);
    rrv__deflate_block(&b, z->tokens, tokens, 1);
    if (b.count > 0) rrv__bits_put(&b, 0, 8 - b.count);
    if (b.full) return 0;
    rrv__put_u32_be(out + b.size, rrv_adler32(1, data, size));
    return b.size + 4;
}
#endif /* RRV_NO_EXR */
#endif /* deflate */

#ifndef RRV_NO_PNG
/* ---- PNG writer ------------------------------------------------------------------
   Each row takes the filter (None, Sub, Up, Average, Paeth) whose output has
   the smallest sum of absolute values as signed bytes, libpng's default
   heuristic: a cheap guess at what deflates best. The filtered rows are
   deflated in blocks of about RRV__PNG_BLOCK_BYTES, each with Huffman codes
   of its own; matches reach back into the previous block, and a block that
   would not shrink is stored instead. Memory stays a few MiB at any image
   size, and the callback still sees chunks of RRV__PNG_IDAT_BYTES. */

/* IDAT payload per chunk; the chunk's length, type and CRC frame it in the
   same buffer so each chunk reaches the callback in one call. */
#define RRV__PNG_IDAT_BYTES ((size_t)32 * 1024)
#define RRV__PNG_BLOCK_BYTES ((size_t)256 * 1024)
#define RRV__DEFLATE_STORED_MAX 65535u

typedef struct rrv__png_writer {
    rrv__piece_writer out;      /* piece = [length, "IDAT", payload, CRC] */
    rrv__deflater *z;
    rrv__bit_writer bits;       /* one block's whole bytes; its partial byte stays in bits */
    unsigned char *block;       /* [the previous window | filtered rows not yet deflated] */
    size_t history, fill;       /* block[0, history) is already out, [history, fill) is not */
    uint32_t adler;             /* of the filtered image bytes, for the zlib trailer */
} rrv__png_writer;

static void rrv__png_flush_idat(rrv__png_writer *png)
{
    rrv__piece_writer *w = &png->out;
    unsigned char *chunk = w->piece - 8;
    size_t payload = w->fill;
    if (w->failed || payload == 0) return;
    rrv__put_u32_be(chunk, (uint32_t)payload);
    memcpy(chunk + 4, "IDAT", 4);
    rrv__put_u32_be(chunk + 8 + payload, rrv_crc32(0, chunk + 4, 4 + payload));
    if (w->write(w->user, chunk, 12 + payload) != 0) w->failed = 1;
    w->fill = 0;
}

/* Appends bytes of the zlib stream, emitting an IDAT chunk whenever the
   payload buffer fills. */
static void rrv__png_put_zlib(rrv__png_writer *png, const unsigned char *src, size_t size)
{
    rrv__piece_writer *w = &png->out;
    while (size > 0 && !w->failed) {
        size_t room = w->capacity - w->fill;
        size_t take = size < room ? size : room;
        memcpy(w->piece + w->fill, src, take);
        w->fill += take;
        src += take;
        size -= take;
        if (w->fill == w->capacity) rrv__png_flush_idat(png);
    }
}

/* Room a block needs in the bit writer: stored, the worst case kept. */
static size_t rrv__png_stored_bound(size_t raw)
{
    return raw + 5 * (raw / RRV__DEFLATE_STORED_MAX + 1) + 2;
}

/* Deflates the rows gathered since the last block, then keeps the last
   window of them as the history the next block may match against. */
static void rrv__png_deflate(rrv__png_writer *png, int final)
{
    rrv__bit_writer *b = &png->bits;
    const unsigned char *raw = png->block + png->history;
    size_t raw_size = png->fill - png->history, tokens, keep;
    uint32_t bits_before = b->bits;
    int count_before = b->count;

    png->adler = rrv_adler32(png->adler, raw, raw_size);
    tokens = rrv__lz77(png->z, png->block, png->history, png->fill);
    b->size = 0;
    b->full = 0;
    rrv__deflate_block(b, png->z->tokens, tokens, final);
    if (b->full || b->size >= rrv__png_stored_bound(raw_size) - 2) {
        /* Noise-like rows: stored blocks cost 5 bytes per 64 KiB. */
        size_t done = 0;
        b->size = 0;
        b->full = 0;
        b->bits = bits_before;
        b->count = count_before;
        do {
            size_t len = raw_size - done < RRV__DEFLATE_STORED_MAX ? raw_size - done : RRV__DEFLATE_STORED_MAX;
            rrv__bits_put(b, final && done + len == raw_size ? 1u : 0u, 1);
            rrv__bits_put(b, 0, 2); /* BTYPE 00: stored */
            if (b->count > 0) rrv__bits_put(b, 0, 8 - b->count);
            b->out[b->size++] = (unsigned char)len;
            b->out[b->size++] = (unsigned char)(len >> 8);
            b->out[b->size++] = (unsigned char)~len;
            b->out[b->size++] = (unsigned char)(~len >> 8);
            memcpy(b->out + b->size, raw + done, len);
            b->size += len;
            done += len;
        } while (done < raw_size);
    }
    rrv__png_put_zlib(png, b->out, b->size);
    b->size = 0;
    keep = png->fill < RRV__LZ_WINDOW ? png->fill : RRV__LZ_WINDOW;
    memmove(png->block, png->block + png->fill - keep, keep);
    png->history = png->fill = keep;
}

static unsigned rrv__png_paeth(unsigned a, unsigned b, unsigned c)
{
    /* |p - a| = |b - c| etc. with p = a + b - c; no abs(), which needs
       <stdlib.h> (not included when the user brings an allocator) */
    unsigned pa = b > c ? b - c : c - b, pb = a > c ? a - c : c - a;
    unsigned pc = a + b > 2 * c ? a + b - 2 * c : 2 * c - a - b;
    if (pa <= pb && pa <= pc) return a;
    return pb <= pc ? b : c;
}

/* Appends the row (3 bytes a pixel) filtered against the row above it
   (zeros above the first row) with the filter of the least absolute sum. */
static void rrv__png_put_row(rrv__png_writer *png, const unsigned char *row, const unsigned char *above,
                             size_t n)
{
    uint64_t sum[5] = { 0, 0, 0, 0, 0 };
    unsigned char *out = png->block + png->fill;
    size_t i;
    int type, best = 0;
    for (i = 0; i < n; ++i) {
        unsigned x = row[i], a = i >= 3 ? row[i - 3] : 0, b = above[i], c = i >= 3 ? above[i - 3] : 0;
        unsigned char f[5];
        f[0] = (unsigned char)x;
        f[1] = (unsigned char)(x - a);
        f[2] = (unsigned char)(x - b);
        f[3] = (unsigned char)(x - ((a + b) >> 1));
        f[4] = (unsigned char)(x - rrv__png_paeth(a, b, c));
        for (type = 0; type < 5; ++type) sum[type] += f[type] < 128 ? f[type] : 256u - f[type];
    }
    for (type = 1; type < 5; ++type) if (sum[type] < sum[best]) best = type;
    out[0] = (unsigned char)best;
    for (i = 0; i < n; ++i) {
        unsigned x = row[i], a = i >= 3 ? row[i - 3] : 0, b = above[i], c = i >= 3 ? above[i - 3] : 0;
        unsigned predicted = best == 0 ? 0 : best == 1 ? a : best == 2 ? b
                           : best == 3 ? (a + b) >> 1 : rrv__png_paeth(a, b, c);
        out[1 + i] = (unsigned char)(x - predicted);
    }
    png->fill += 1 + n;
}

static unsigned char rrv__srgb8(float value, double gain)
{
    double linear = (double)value * gain;
    double encoded;
    if (!(linear > 0.0)) return 0; /* negative, zero and NaN */
    if (linear >= 1.0) return 255;
    encoded = linear <= 0.0031308 ? 12.92 * linear : 1.055 * pow(linear, 1.0 / 2.4) - 0.055;
    return (unsigned char)(encoded * 255.0 + 0.5);
}

static rrv_result rrv__write_png_to(rrv_write_func write, void *user,
                                    const float *rgb, int width, int height, double exposure)
{
    static const unsigned char signature[8] = { 137, 'P', 'N', 'G', '\r', '\n', 26, '\n' };
    static const unsigned char iend[12] = { 0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xAE, 0x42, 0x60, 0x82 };
    static const unsigned char zlib_header[2] = { 0x78, 0x01 }; /* 32K window, no dictionary */
    unsigned char head[8 + 25], trailer[4];
    unsigned char *idat = NULL, *rows = NULL, *packed = NULL;
    size_t row_bytes, max_raw, i;
    rrv__png_writer png;
    rrv_result result = RRV_OK;
    double gain;
    int y;

    if (!write || rrv__check_image_args(rgb, width, height) != RRV_OK) return RRV_ERROR_ARGUMENT;
    if (!isfinite(exposure)) return RRV_ERROR_ARGUMENT;
    gain = pow(2.0, exposure);
    row_bytes = 3 * (size_t)width;
    /* A block ends at the first row that reaches RRV__PNG_BLOCK_BYTES. */
    max_raw = RRV__PNG_BLOCK_BYTES + 1 + row_bytes;

    memcpy(head, signature, 8);
    rrv__put_u32_be(head + 8, 13);
    memcpy(head + 12, "IHDR", 4);
    rrv__put_u32_be(head + 16, (uint32_t)width);
    rrv__put_u32_be(head + 20, (uint32_t)height);
    head[24] = 8; /* bits per sample */
    head[25] = 2; /* colour type: RGB */
    head[26] = 0; /* compression: deflate */
    head[27] = 0; /* filter method 0 (adaptive, five filter types) */
    head[28] = 0; /* not interlaced */
    rrv__put_u32_be(head + 29, rrv_crc32(0, head + 12, 17));
    if (write(user, head, sizeof head) != 0) return RRV_ERROR_IO;

    memset(&png, 0, sizeof png);
    idat = (unsigned char *)RRV_MALLOC(RRV__PNG_IDAT_BYTES + 12);
    rows = (unsigned char *)RRV_MALLOC(2 * row_bytes);
    png.block = (unsigned char *)RRV_MALLOC(RRV__LZ_WINDOW + max_raw);
    packed = (unsigned char *)RRV_MALLOC(rrv__png_stored_bound(max_raw));
    png.z = (rrv__deflater *)RRV_MALLOC(sizeof *png.z);
    if (png.z) png.z->tokens = (uint32_t *)RRV_MALLOC(max_raw * sizeof *png.z->tokens);
    if (!idat || !rows || !png.block || !packed || !png.z || !png.z->tokens) {
        result = RRV_ERROR_MEMORY;
        goto done;
    }
    png.out.write = write;
    png.out.user = user;
    png.out.piece = idat + 8;
    png.out.capacity = RRV__PNG_IDAT_BYTES;
    png.bits.out = packed;
    png.bits.capacity = rrv__png_stored_bound(max_raw);
    png.adler = 1;

    rrv__png_put_zlib(&png, zlib_header, sizeof zlib_header);
    memset(rows, 0, row_bytes); /* the "row above" the first row */
    for (y = 0; y < height && !png.out.failed; ++y) {
        const float *pixels = rgb + (size_t)y * row_bytes;
        unsigned char *above = rows + (size_t)(y & 1) * row_bytes;
        unsigned char *row = rows + (size_t)((y + 1) & 1) * row_bytes;
        for (i = 0; i < row_bytes; ++i) row[i] = rrv__srgb8(pixels[i], gain);
        rrv__png_put_row(&png, row, above, row_bytes);
        if (y == height - 1) rrv__png_deflate(&png, 1);
        else if (png.fill - png.history >= RRV__PNG_BLOCK_BYTES) rrv__png_deflate(&png, 0);
    }
    /* The last block ends on a whole byte: pad its final bits. */
    if (png.bits.count > 0) {
        rrv__bits_put(&png.bits, 0, 8 - png.bits.count);
        rrv__png_put_zlib(&png, png.bits.out, png.bits.size);
    }
    rrv__put_u32_be(trailer, png.adler);
    rrv__png_put_zlib(&png, trailer, sizeof trailer);
    rrv__png_flush_idat(&png);
    if (png.out.failed) result = RRV_ERROR_IO;
    else if (write(user, iend, sizeof iend) != 0) result = RRV_ERROR_IO;
done:
    if (png.z) RRV_FREE(png.z->tokens);
    RRV_FREE(png.z);
    RRV_FREE(packed);
    RRV_FREE(png.block);
    RRV_FREE(rows);
    RRV_FREE(idat);
    return result;
}

#endif /* RRV_NO_PNG */

/* ---- OpenEXR writer ---------------------------------------------------------------
   Layout: magic, version 2 (single-part scanline), the header's attributes
   and a NUL, one 64-bit offset per chunk, then chunks of (int32 y, int32
   size, data). A chunk holds 1 scanline uncompressed or 16 with ZIP; inside
   it each scanline stores all B values, then G, then R, little endian. */

RRV_DEF uint16_t rrv_half_from_float(float value)
{
    uint32_t bits, magnitude, sign;
    memcpy(&bits, &value, sizeof bits);
    sign = (bits >> 16) & 0x8000u;
    magnitude = bits & 0x7FFFFFFFu;
    if (magnitude >= 0x7F800000u) { /* infinity, or NaN kept NaN by a forced quiet bit */
        if (magnitude == 0x7F800000u) return (uint16_t)(sign | 0x7C00u);
        return (uint16_t)(sign | 0x7E00u | ((magnitude >> 13) & 0x3FFu));
    }
    /* 0x477FE000 is 65504, the largest half: clamping instead of rounding to
       infinity keeps a bright but finite pixel finite in the file. */
    if (magnitude >= 0x477FE000u) return (uint16_t)(sign | 0x7BFFu);
    if (magnitude >= 0x38800000u) { /* normal half: >= 2^-14 */
        uint32_t half = ((magnitude >> 23) - 112u) << 10 | ((magnitude >> 13) & 0x3FFu);
        uint32_t rest = magnitude & 0x1FFFu;
        /* A carry out of the mantissa correctly bumps the exponent. */
        if (rest > 0x1000u || (rest == 0x1000u && (half & 1u))) ++half;
        return (uint16_t)(sign | half);
    }
    if (magnitude <= 0x33000000u) return (uint16_t)sign; /* <= 2^-25 rounds to (even) zero */
    {
        /* Subnormal half: the value in units of 2^-24 is the 24-bit mantissa
           shifted right by 126 - exponent, which lies in [14, 24] here. */
        uint32_t mantissa = (magnitude & 0x7FFFFFu) | 0x800000u;
        unsigned shift = 126u - (magnitude >> 23);
        uint32_t half = mantissa >> shift;
        uint32_t rest = mantissa & ((1u << shift) - 1u), tie = 1u << (shift - 1u);
        if (rest > tie || (rest == tie && (half & 1u))) ++half;
        return (uint16_t)(sign | half);
    }
}

#ifndef RRV_NO_EXR
/* -- the file ------------------------------------------------------------------ */

#define RRV__EXR_ZIP_LINES 16

typedef struct rrv__exr_header {
    unsigned char bytes[512 + 64 + 8 + 4 + 4096];
    size_t size;
} rrv__exr_header;

static void rrv__put_u32_le(unsigned char *out, uint32_t v)
{
    out[0] = (unsigned char)v;
    out[1] = (unsigned char)(v >> 8);
    out[2] = (unsigned char)(v >> 16);
    out[3] = (unsigned char)(v >> 24);
}

static void rrv__exr_attribute(rrv__exr_header *h, const char *name, const char *type,
                               const void *value, size_t size)
{
    size_t n = strlen(name) + 1, t = strlen(type) + 1;
    memcpy(h->bytes + h->size, name, n);
    memcpy(h->bytes + h->size + n, type, t);
    rrv__put_u32_le(h->bytes + h->size + n + t, (uint32_t)size);
    memcpy(h->bytes + h->size + n + t + 4, value, size);
    h->size += n + t + 4 + size;
}

static void rrv__exr_box(unsigned char *out, long x0, long y0, long x1, long y1)
{
    rrv__put_u32_le(out, (uint32_t)x0);
    rrv__put_u32_le(out + 4, (uint32_t)y0);
    rrv__put_u32_le(out + 8, (uint32_t)x1);
    rrv__put_u32_le(out + 12, (uint32_t)y1);
}

/* The raw bytes of scanlines [y0, y0 + lines) of the image as a chunk
   stores them: per line B, G, R runs of little-endian halves or floats. */
static void rrv__exr_pack_lines(const float *rgb, int width, int y0, int lines, int as_float,
                                unsigned char *out)
{
    int y, c, x;
    for (y = y0; y < y0 + lines; ++y) {
        const float *row = rgb + (size_t)y * (size_t)width * 3;
        for (c = 2; c >= 0; --c) { /* B, G, R */
            for (x = 0; x < width; ++x) {
                float v = row[3 * (size_t)x + (size_t)c];
                if (as_float) {
                    uint32_t bits;
                    memcpy(&bits, &v, sizeof bits);
                    rrv__put_u32_le(out, bits);
                    out += 4;
                } else {
                    uint16_t half = rrv_half_from_float(v);
                    out[0] = (unsigned char)half;
                    out[1] = (unsigned char)(half >> 8);
                    out += 2;
                }
            }
        }
    }
}

/* ZIP's preprocessing: even-indexed bytes first, then odd ones (so the high
   and low bytes of each value gather), then each byte replaced by its
   difference from the previous one plus 128. */
static void rrv__exr_zip_predict(const unsigned char *raw, size_t size, unsigned char *out)
{
    size_t half = (size + 1) / 2, i;
    unsigned previous;
    for (i = 0; i < size; ++i) out[(i & 1) ? half + i / 2 : i / 2] = raw[i];
    previous = out[0];
    for (i = 1; i < size; ++i) {
        unsigned current = out[i];
        out[i] = (unsigned char)(current - previous + 128u);
        previous = current;
    }
}

/* The header of rrv's scanline files: magic and version, the B, G, R
   channel list, the windows, the attributes every reader requires, the
   optional text attribute, and the closing NUL. */
static void rrv__exr_write_header(rrv__exr_header *h, const rrv_exr_options *opt, int width, int height, int as_float,
                                  int zip, long display_w, long display_h)
{
    static const unsigned char magic_version[8] = { 0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0 };
    unsigned char value[64];
    int c;
    h->size = 0;
    memcpy(h->bytes, magic_version, 8);
    h->size = 8;
    {
        /* chlist: per channel name, int32 type (1 HALF, 2 FLOAT), uint8
           pLinear, 3 reserved bytes, int32 x and y sampling; then a NUL. */
        size_t n = 0;
        static const char names[3] = { 'B', 'G', 'R' };
        for (c = 0; c < 3; ++c) {
            value[n++] = (unsigned char)names[c];
            value[n++] = 0;
            rrv__put_u32_le(value + n, as_float ? 2u : 1u);
            memset(value + n + 4, 0, 4);
            rrv__put_u32_le(value + n + 8, 1);
            rrv__put_u32_le(value + n + 12, 1);
            n += 16;
        }
        value[n++] = 0;
        rrv__exr_attribute(h, "channels", "chlist", value, n);
    }
    value[0] = (unsigned char)(zip ? 3 : 0); /* ZIP_COMPRESSION, NO_COMPRESSION */
    rrv__exr_attribute(h, "compression", "compression", value, 1);
    rrv__exr_box(value, opt->x, opt->y, (long)opt->x + width - 1, (long)opt->y + height - 1);
    rrv__exr_attribute(h, "dataWindow", "box2i", value, 16);
    rrv__exr_box(value, 0, 0, display_w - 1, display_h - 1);
    rrv__exr_attribute(h, "displayWindow", "box2i", value, 16);
    value[0] = 0; /* INCREASING_Y */
    rrv__exr_attribute(h, "lineOrder", "lineOrder", value, 1);
    {
        float one = 1.0f;
        uint32_t bits;
        memcpy(&bits, &one, sizeof bits);
        rrv__put_u32_le(value, bits);
        rrv__exr_attribute(h, "pixelAspectRatio", "float", value, 4);
        memset(value, 0, 8);
        rrv__exr_attribute(h, "screenWindowCenter", "v2f", value, 8);
        rrv__put_u32_le(value, bits);
        rrv__exr_attribute(h, "screenWindowWidth", "float", value, 4);
    }
    if (opt->text_name) rrv__exr_attribute(h, opt->text_name, "string", opt->text, strlen(opt->text));
    h->bytes[h->size++] = 0;
}

static rrv_result rrv__write_exr_to(rrv_write_func write, void *user, const float *rgb,
                                    int width, int height, const rrv_exr_options *options)
{
    rrv_exr_options opt;
    rrv__exr_header h;
    unsigned char *raw = NULL, *predicted = NULL, *packed = NULL, *offsets = NULL;
    uint32_t *chunk_sizes = NULL;
    rrv__deflater *z = NULL;
    int as_float, zip, lines_per_chunk, chunk_count, i;
    size_t value_bytes, line_bytes, chunk_bytes, packed_size = 0;
    uint64_t position;
    rrv_result result = RRV_OK;
    long display_w, display_h;

    if (!write || rrv__check_image_args(rgb, width, height) != RRV_OK) return RRV_ERROR_ARGUMENT;
    if (options) opt = *options;
    else memset(&opt, 0, sizeof opt);
    if ((opt.pixel != RRV_EXR_HALF && opt.pixel != RRV_EXR_FLOAT) ||
        (opt.compression != RRV_EXR_ZIP && opt.compression != RRV_EXR_NO_COMPRESSION) ||
        opt.display_width < 0 || opt.display_height < 0)
        return RRV_ERROR_ARGUMENT;
    if (opt.text_name && (!opt.text || !opt.text_name[0] || strlen(opt.text_name) > 63 || strlen(opt.text) > 4095))
        return RRV_ERROR_ARGUMENT;
    display_w = opt.display_width ? opt.display_width : width;
    display_h = opt.display_height ? opt.display_height : height;
    /* The data window's last pixel must be an int coordinate too. */
    if ((long long)opt.x + width - 1 > INT_MAX || (long long)opt.y + height - 1 > INT_MAX)
        return RRV_ERROR_ARGUMENT;
    as_float = opt.pixel == RRV_EXR_FLOAT;
    zip = opt.compression == RRV_EXR_ZIP;
    value_bytes = as_float ? 4 : 2;
    lines_per_chunk = zip ? RRV__EXR_ZIP_LINES : 1;
    chunk_count = (height + lines_per_chunk - 1) / lines_per_chunk;
    line_bytes = (size_t)width * 3 * value_bytes;
    /* A chunk's size is an int32 in the file. */
    if ((size_t)width > (size_t)INT32_MAX / 3 / value_bytes / (size_t)lines_per_chunk)
        return RRV_ERROR_ARGUMENT;
    chunk_bytes = line_bytes * (size_t)(height < lines_per_chunk ? height : lines_per_chunk);

    rrv__exr_write_header(&h, &opt, width, height, as_float, zip, display_w, display_h);

    raw = (unsigned char *)RRV_MALLOC(chunk_bytes);
    offsets = (unsigned char *)RRV_MALLOC((size_t)chunk_count * 8);
    chunk_sizes = (uint32_t *)RRV_MALLOC((size_t)chunk_count * sizeof *chunk_sizes);
    if (!raw || !offsets || !chunk_sizes) { result = RRV_ERROR_MEMORY; goto done; }

    if (zip) {
        /* Offsets come before the chunks and the callback cannot seek, so
           every chunk is compressed first; together they are never larger
           than the uncompressed pixels. */
        size_t packed_capacity = 0;
        predicted = (unsigned char *)RRV_MALLOC(chunk_bytes);
        z = (rrv__deflater *)RRV_MALLOC(sizeof *z);
        if (z) z->tokens = (uint32_t *)RRV_MALLOC(chunk_bytes * sizeof *z->tokens);
        if (!predicted || !z || !z->tokens) { result = RRV_ERROR_MEMORY; goto done; }
        packed_capacity = line_bytes * (size_t)height;
        packed = (unsigned char *)RRV_MALLOC(packed_capacity);
        if (!packed) { result = RRV_ERROR_MEMORY; goto done; }
        for (i = 0; i < chunk_count; ++i) {
            int y0 = i * lines_per_chunk;
            int lines = height - y0 < lines_per_chunk ? height - y0 : lines_per_chunk;
            size_t size = line_bytes * (size_t)lines, compressed;
            rrv__exr_pack_lines(rgb, width, y0, lines, as_float, raw);
            rrv__exr_zip_predict(raw, size, predicted);
            /* Smaller than raw or raw itself: a reader takes a chunk of the
               uncompressed size as uncompressed. */
            compressed = rrv__zlib_compress(z, predicted, size, packed + packed_size, size - 1);
            if (compressed == 0) {
                memcpy(packed + packed_size, raw, size);
                compressed = size;
            }
            chunk_sizes[i] = (uint32_t)compressed;
            packed_size += compressed;
        }
    } else {
        for (i = 0; i < chunk_count; ++i) chunk_sizes[i] = (uint32_t)line_bytes;
    }

    position = (uint64_t)h.size + (uint64_t)chunk_count * 8;
    for (i = 0; i < chunk_count; ++i) {
        uint64_t p = position;
        int k;
        for (k = 0; k < 8; ++k) offsets[8 * (size_t)i + (size_t)k] = (unsigned char)(p >> (8 * k));
        position += 8 + (uint64_t)chunk_sizes[i];
    }
    if (write(user, h.bytes, h.size) != 0 || write(user, offsets, (size_t)chunk_count * 8) != 0) {
        result = RRV_ERROR_IO;
        goto done;
    }
    {
        size_t consumed = 0;
        for (i = 0; i < chunk_count; ++i) {
            unsigned char prefix[8];
            int y0 = i * lines_per_chunk;
            int lines = height - y0 < lines_per_chunk ? height - y0 : lines_per_chunk;
            rrv__put_u32_le(prefix, (uint32_t)(opt.y + y0));
            rrv__put_u32_le(prefix + 4, chunk_sizes[i]);
            if (write(user, prefix, 8) != 0) { result = RRV_ERROR_IO; goto done; }
            if (zip) {
                if (write(user, packed + consumed, chunk_sizes[i]) != 0) { result = RRV_ERROR_IO; goto done; }
                consumed += chunk_sizes[i];
            } else {
                rrv__exr_pack_lines(rgb, width, y0, lines, as_float, raw);
                if (write(user, raw, chunk_sizes[i]) != 0) { result = RRV_ERROR_IO; goto done; }
            }
        }
    }
done:
    if (z) RRV_FREE(z->tokens);
    RRV_FREE(z);
    RRV_FREE(packed);
    RRV_FREE(predicted);
    RRV_FREE(chunk_sizes);
    RRV_FREE(offsets);
    RRV_FREE(raw);
    return result;
}

/* ---- OpenEXR reader --------------------------------------------------------------
   For rrv diff and round trips: single-part scanline files with R, G and B
   channels of HALF or FLOAT (other channels are skipped), compression NONE,
   RLE, ZIPS or ZIP, so it reads what rrv and most renderers write. Every
   offset and size comes from the file and is checked before it is used. */

static float rrv__float_from_half(uint16_t h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, exponent = (h >> 10) & 31u, mantissa = h & 0x3FFu, bits;
    if (exponent == 31) {
        bits = sign | 0x7F800000u | mantissa << 13;
    } else if (exponent != 0) {
        bits = sign | (exponent + 112u) << 23 | mantissa << 13;
    } else if (mantissa == 0) {
        bits = sign;
    } else {
        /* Subnormal half: normalise; the value is mantissa * 2^-24. */
        int shift = 0;
        while (!(mantissa & 0x400u)) { mantissa <<= 1; ++shift; }
        bits = sign | (uint32_t)(113 - shift) << 23 | (mantissa & 0x3FFu) << 13;
    }
    {
        float f;
        memcpy(&f, &bits, sizeof f);
        return f;
    }
}

/* -- inflate ---------------------------------------------------------------------- */

typedef struct rrv__inflater {
    const unsigned char *in;
    size_t in_size, in_pos;
    uint32_t bits;
    int count;
    unsigned char *out;
    size_t out_size, out_pos;
} rrv__inflater;

/* Canonical Huffman decoding: counts of codes per length and the symbols in
   code order. */
typedef struct rrv__huffman_decoder {
    uint16_t count[RRV__HUFF_MAX_BITS + 1];
    uint16_t symbol[288];
} rrv__huffman_decoder;

/* Returns -1 past the end of the input. */
static int rrv__inflate_bits(rrv__inflater *s, int n, uint32_t *value)
{
    while (s->count < n) {
        if (s->in_pos >= s->in_size) return -1;
        s->bits |= (uint32_t)s->in[s->in_pos++] << s->count;
        s->count += 8;
    }
    *value = s->bits & ((1u << n) - 1u);
    s->bits >>= n;
    s->count -= n;
    return 0;
}

/* Fails for over-subscribed lengths; incomplete codes are allowed as zlib
   allows them, a code that falls in the gap fails when decoded. */
static int rrv__huffman_decoder_build(rrv__huffman_decoder *d, const unsigned char *lengths, int n)
{
    uint16_t offset[RRV__HUFF_MAX_BITS + 2];
    int i, left = 1;
    memset(d->count, 0, sizeof d->count);
    for (i = 0; i < n; ++i) ++d->count[lengths[i]];
    d->count[0] = 0;
    for (i = 1; i <= RRV__HUFF_MAX_BITS; ++i) {
        left = 2 * left - d->count[i];
        if (left < 0) return 0;
    }
    offset[1] = 0;
    for (i = 1; i <= RRV__HUFF_MAX_BITS; ++i) offset[i + 1] = (uint16_t)(offset[i] + d->count[i]);
    for (i = 0; i < n; ++i)
        if (lengths[i]) d->symbol[offset[lengths[i]]++] = (uint16_t)i;
    return 1;
}

static int rrv__huffman_decode(rrv__inflater *s, const rrv__huffman_decoder *d)
{
    int code = 0, first = 0, index = 0, length;
    for (length = 1; length <= RRV__HUFF_MAX_BITS; ++length) {
        uint32_t bit;
        if (rrv__inflate_bits(s, 1, &bit) != 0) return -1;
        code |= (int)bit;
        if (code - first < d->count[length]) return d->symbol[index + code - first];
        index += d->count[length];
        first = (first + d->count[length]) << 1;
        code <<= 1;
    }
    return -1;
}

/* Inflates a zlib stream into exactly out_size bytes; returns 1 on success. */
static int rrv__zlib_inflate(const unsigned char *in, size_t in_size, unsigned char *out, size_t out_size)
{
    static const unsigned char cl_order[19] = {
        16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15 };
    rrv__inflater s;
    uint32_t last = 0, type, v;
    if (in_size < 6 || (in[0] & 0x0F) != 8 || (in[0] >> 4) > 7 || (in[1] & 0x20) ||
        (((uint32_t)in[0] << 8) | in[1]) % 31u != 0)
        return 0;
    s.in = in + 2;
    s.in_size = in_size - 6;
    s.in_pos = 0;
    s.bits = 0;
    s.count = 0;
    s.out = out;
    s.out_size = out_size;
    s.out_pos = 0;
    while (!last) {
        if (rrv__inflate_bits(&s, 1, &last) != 0 || rrv__inflate_bits(&s, 2, &type) != 0) return 0;
        if (type == 0) {
            size_t len;
            s.bits = 0; /* stored blocks start on a byte */
            s.count = 0;
            if (s.in_size - s.in_pos < 4) return 0;
            len = (size_t)s.in[s.in_pos] | (size_t)s.in[s.in_pos + 1] << 8;
            if ((len ^ 0xFFFFu) != ((size_t)s.in[s.in_pos + 2] | (size_t)s.in[s.in_pos + 3] << 8)) return 0;
            s.in_pos += 4;
            if (len > s.in_size - s.in_pos || len > s.out_size - s.out_pos) return 0;
            memcpy(s.out + s.out_pos, s.in + s.in_pos, len);
            s.in_pos += len;
            s.out_pos += len;
        } else if (type == 1 || type == 2) {
            unsigned char lengths[288 + 32];
            rrv__huffman_decoder lit, dist;
            uint32_t nlit = 288, ndist = 30;
            int i;
            if (type == 1) {
                for (i = 0; i < 288; ++i) lengths[i] = (unsigned char)(i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8);
                for (i = 0; i < 30; ++i) lengths[288 + i] = 5;
            } else {
                rrv__huffman_decoder cl;
                unsigned char cl_len[19];
                uint32_t ncl, k = 0;
                if (rrv__inflate_bits(&s, 5, &nlit) != 0 || rrv__inflate_bits(&s, 5, &ndist) != 0 ||
                    rrv__inflate_bits(&s, 4, &ncl) != 0)
                    return 0;
                nlit += 257;
                ndist += 1;
                ncl += 4;
                if (nlit > 286 || ndist > 30) return 0;
                memset(cl_len, 0, sizeof cl_len);
                for (i = 0; i < (int)ncl; ++i) {
                    if (rrv__inflate_bits(&s, 3, &v) != 0) return 0;
                    cl_len[cl_order[i]] = (unsigned char)v;
                }
                if (!rrv__huffman_decoder_build(&cl, cl_len, 19)) return 0;
                while (k < nlit + ndist) {
                    int symbol = rrv__huffman_decode(&s, &cl);
                    uint32_t repeat;
                    unsigned char value = 0;
                    if (symbol < 0) return 0;
                    if (symbol < 16) {
                        lengths[k++] = (unsigned char)symbol;
                        continue;
                    }
                    if (symbol == 16) {
                        if (k == 0 || rrv__inflate_bits(&s, 2, &repeat) != 0) return 0;
                        value = lengths[k - 1];
                        repeat += 3;
                    } else if (symbol == 17) {
                        if (rrv__inflate_bits(&s, 3, &repeat) != 0) return 0;
                        repeat += 3;
                    } else {
                        if (rrv__inflate_bits(&s, 7, &repeat) != 0) return 0;
                        repeat += 11;
                    }
                    if (repeat > nlit + ndist - k) return 0;
                    while (repeat-- > 0) lengths[k++] = value;
                }
                if (lengths[256] == 0) return 0; /* no end of block */
            }
            if (!rrv__huffman_decoder_build(&lit, lengths, (int)nlit) ||
                !rrv__huffman_decoder_build(&dist, lengths + nlit, (int)ndist))
                return 0;
            for (;;) {
                int symbol = rrv__huffman_decode(&s, &lit);
                if (symbol < 0) return 0;
                if (symbol < 256) {
                    if (s.out_pos >= s.out_size) return 0;
                    s.out[s.out_pos++] = (unsigned char)symbol;
                } else if (symbol == 256) {
                    break;
                } else {
                    uint32_t extra;
                    size_t length, distance;
                    int dc;
                    symbol -= 257;
                    if (symbol >= 29) return 0;
                    if (rrv__inflate_bits(&s, rrv__deflate_length_extra[symbol], &extra) != 0) return 0;
                    length = rrv__deflate_length_base[symbol] + extra;
                    dc = rrv__huffman_decode(&s, &dist);
                    if (dc < 0 || dc >= 30) return 0;
                    if (rrv__inflate_bits(&s, rrv__deflate_dist_extra[dc], &extra) != 0) return 0;
                    distance = rrv__deflate_dist_base[dc] + extra;
                    if (distance > s.out_pos || length > s.out_size - s.out_pos) return 0;
                    for (; length > 0; --length, ++s.out_pos) s.out[s.out_pos] = s.out[s.out_pos - distance];
                }
            }
        } else {
            return 0;
        }
    }
    if (s.out_pos != s.out_size) return 0;
    /* The Adler-32 trailer follows the last whole byte used. */
    if (s.in_size - s.in_pos != 0) return 0;
    {
        const unsigned char *t = in + in_size - 4;
        uint32_t want = (uint32_t)t[0] << 24 | (uint32_t)t[1] << 16 | (uint32_t)t[2] << 8 | t[3];
        return rrv_adler32(1, out, out_size) == want;
    }
}

/* OpenEXR's RLE: a signed count byte, then -count literal bytes or one byte
   repeated count + 1 times. */
static int rrv__exr_rle_decode(const unsigned char *in, size_t in_size, unsigned char *out, size_t out_size)
{
    size_t i = 0, o = 0;
    while (i < in_size) {
        int count = in[i] < 128 ? in[i] : (int)in[i] - 256;
        ++i;
        if (count < 0) {
            size_t n = (size_t)-count;
            if (n > in_size - i || n > out_size - o) return 0;
            memcpy(out + o, in + i, n);
            i += n;
            o += n;
        } else {
            size_t n = (size_t)count + 1;
            if (i >= in_size || n > out_size - o) return 0;
            memset(out + o, in[i], n);
            ++i;
            o += n;
        }
    }
    return o == out_size;
}

/* Undoes ZIP's and RLE's predictor and byte split. */
static void rrv__exr_unpredict(unsigned char *tmp, size_t size, unsigned char *raw)
{
    size_t half = (size + 1) / 2, i;
    for (i = 1; i < size; ++i) tmp[i] = (unsigned char)(tmp[i - 1] + tmp[i] - 128u);
    for (i = 0; i < size; ++i) raw[i] = tmp[(i & 1) ? half + i / 2 : i / 2];
}

static uint32_t rrv__get_u32_le(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static int32_t rrv__get_i32_le(const unsigned char *p)
{
    uint32_t u = rrv__get_u32_le(p);
    return u <= 0x7FFFFFFFu ? (int32_t)u : (int32_t)(u - 0x80000000u) - INT32_MAX - 1;
}

/* The largest expansion deflate allows is about 1032:1; a header promising
   more pixels than the file could hold is refused before allocating. */
#define RRV__EXR_MAX_RATIO 1100u

typedef struct rrv__exr_channel {
    int rgb;    /* 0 R, 1 G, 2 B, -1 another channel */
    int type;   /* 0 UINT, 1 HALF, 2 FLOAT */
    size_t offset; /* of this channel's run within a scanline, in bytes */
} rrv__exr_channel;

#define RRV__EXR_MAX_CHANNELS 64

RRV_DEF rrv_result rrv_exr_find_attribute(const void *data, size_t size, const char *attr_name,
                                          const char **type, const void **value, size_t *value_size)
{
    const unsigned char *p = (const unsigned char *)data;
    size_t pos = 8;
    if (type) *type = NULL;
    if (value) *value = NULL;
    if (value_size) *value_size = 0;
    if (!attr_name || (!data && size > 0)) return RRV_ERROR_ARGUMENT;
    if (size < 8 || p[0] != 0x76 || p[1] != 0x2f || p[2] != 0x31 || p[3] != 0x01) return RRV_ERROR_FORMAT;
    while (pos < size && p[pos] != 0) {
        const char *name = (const char *)p + pos, *type_name;
        const unsigned char *end = (const unsigned char *)memchr(p + pos, 0, size - pos);
        uint32_t n;
        if (!end) return RRV_ERROR_FORMAT;
        pos = (size_t)(end - p) + 1;
        type_name = (const char *)p + pos;
        end = pos < size ? (const unsigned char *)memchr(p + pos, 0, size - pos) : NULL;
        if (!end) return RRV_ERROR_FORMAT;
        pos = (size_t)(end - p) + 1;
        if (size - pos < 4) return RRV_ERROR_FORMAT;
        n = rrv__get_u32_le(p + pos);
        pos += 4;
        if (n > size - pos) return RRV_ERROR_FORMAT;
        if (strcmp(name, attr_name) == 0) {
            if (type) *type = type_name;
            if (value) *value = p + pos;
            if (value_size) *value_size = n;
            return RRV_OK;
        }
        pos += n;
    }
    return RRV_ERROR_FORMAT;
}

/* What rrv's reader keeps of an OpenEXR header. */
typedef struct rrv__exr_scan {
    rrv__exr_channel channels[RRV__EXR_MAX_CHANNELS];
    int channel_count, compression, rgb_type[3];
    int have[4];           /* channels, compression, dataWindow, displayWindow seen */
    int32_t dw[4], disp[4];
    size_t line_bytes;     /* bytes of one pixel, all channels */
} rrv__exr_scan;

/* Reads the header's attributes from *pos (after the magic and version)
   up to and past its closing NUL, and checks what the reader needs. */
static rrv_result rrv__exr_read_header(const unsigned char *p, size_t size, size_t *pos, const char *name,
                                       rrv__exr_scan *h, rrv_error *err)
{
    static const char *const compression_names[10] = {
        "NONE", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA", "DWAB" };
    int i;
    memset(h, 0, sizeof *h);
    h->rgb_type[0] = h->rgb_type[1] = h->rgb_type[2] = -1;
    /* The header: name, type, int32 size and value per attribute, then a NUL. */
    for (;;) {
        const char *attr_name, *type;
        size_t name_len, type_len;
        uint32_t value_size;
        const unsigned char *v;
        if (*pos >= size) return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "truncated OpenEXR header");
        if (p[*pos] == 0) break;
        attr_name = (const char *)p + *pos;
        for (name_len = 0; *pos + name_len < size && p[*pos + name_len] != 0 && name_len < 256; ++name_len) {}
        if (*pos + name_len >= size || name_len == 256)
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "truncated OpenEXR header");
        *pos += name_len + 1;
        type = (const char *)p + *pos;
        for (type_len = 0; *pos + type_len < size && p[*pos + type_len] != 0 && type_len < 256; ++type_len) {}
        if (*pos + type_len >= size || type_len == 256 || size - (*pos + type_len + 1) < 4)
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "truncated OpenEXR header");
        *pos += type_len + 1;
        value_size = rrv__get_u32_le(p + *pos);
        *pos += 4;
        if (value_size > size - *pos)
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR attribute %s runs past the end of the file",
                             attr_name);
        v = p + *pos;
        *pos += value_size;
        if (strcmp(attr_name, "channels") == 0 && strcmp(type, "chlist") == 0) {
            size_t k = 0, run = 0;
            h->have[0] = 1;
            while (k < value_size && v[k] != 0) {
                size_t n = 0;
                int ctype, c = -1;
                while (k + n < value_size && v[k + n] != 0) ++n;
                if (k + n + 1 + 16 > value_size)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "malformed OpenEXR channel list");
                if (n == 1 && (v[k] == 'R' || v[k] == 'G' || v[k] == 'B')) c = v[k] == 'R' ? 0 : v[k] == 'G' ? 1 : 2;
                ctype = rrv__get_i32_le(v + k + n + 1);
                if (ctype < 0 || ctype > 2)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR channel of unknown type %d", ctype);
                if (rrv__get_i32_le(v + k + n + 1 + 8) != 1 || rrv__get_i32_le(v + k + n + 1 + 12) != 1)
                    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, name, 0,
                                     "subsampled OpenEXR channels are not supported");
                if (h->channel_count == RRV__EXR_MAX_CHANNELS)
                    return rrv__fail(err, RRV_ERROR_LIMIT, name, 0, "more than %d OpenEXR channels",
                                     RRV__EXR_MAX_CHANNELS);
                if (c >= 0) {
                    if (ctype == 0)
                        return rrv__fail(err, RRV_ERROR_UNSUPPORTED, name, 0,
                                         "OpenEXR channel %c is UINT; rrv reads HALF or FLOAT", v[k]);
                    h->rgb_type[c] = ctype;
                }
                h->channels[h->channel_count].rgb = c;
                h->channels[h->channel_count].type = ctype;
                h->channels[h->channel_count].offset = run; /* per pixel for now */
                run += ctype == 1 ? 2 : 4;
                ++h->channel_count;
                k += n + 1 + 16;
            }
            h->line_bytes = run;
        } else if (strcmp(attr_name, "compression") == 0 && value_size == 1) {
            h->compression = v[0];
            h->have[1] = 1;
        } else if ((strcmp(attr_name, "dataWindow") == 0 || strcmp(attr_name, "displayWindow") == 0) &&
                   value_size == 16) {
            int32_t *box = attr_name[1] == 'a' ? h->dw : h->disp;
            for (i = 0; i < 4; ++i) box[i] = rrv__get_i32_le(v + 4 * i);
            if (attr_name[1] == 'a') h->have[2] = 1;
            else h->have[3] = 1;
        }
    }
    ++*pos; /* the header's NUL */
    if (!h->have[0] || !h->have[1] || !h->have[2] || !h->have[3])
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR header lacks %s",
                         !h->have[0] ? "channels" : !h->have[1] ? "compression"
                         : !h->have[2] ? "dataWindow" : "displayWindow");
    if (h->rgb_type[0] < 0 || h->rgb_type[1] < 0 || h->rgb_type[2] < 0)
        return rrv__fail(err, RRV_ERROR_UNSUPPORTED, name, 0, "OpenEXR file without R, G and B channels");
    if (h->compression != 0 && h->compression != 1 && h->compression != 2 && h->compression != 3)
        return rrv__fail(err, RRV_ERROR_UNSUPPORTED, name, 0,
                         "OpenEXR compression %s is not supported; rrv reads NONE, RLE, ZIPS and ZIP",
                         h->compression < 10 ? compression_names[h->compression] : "(unknown)");
    if (h->dw[2] < h->dw[0] || h->dw[3] < h->dw[1] || (int64_t)h->dw[2] - h->dw[0] >= INT_MAX || (int64_t)h->dw[3] - h->dw[1] >= INT_MAX ||
        h->disp[2] < h->disp[0] || h->disp[3] < h->disp[1] || (int64_t)h->disp[2] - h->disp[0] >= INT_MAX ||
        (int64_t)h->disp[3] - h->disp[1] >= INT_MAX)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR window (%ld %ld)-(%ld %ld) is empty or too large",
                         (long)h->dw[0], (long)h->dw[1], (long)h->dw[2], (long)h->dw[3]);
    if ((int64_t)h->dw[0] - h->disp[0] > INT_MAX || (int64_t)h->dw[0] - h->disp[0] < INT_MIN ||
        (int64_t)h->dw[1] - h->disp[1] > INT_MAX || (int64_t)h->dw[1] - h->disp[1] < INT_MIN)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR data window too far from the display window");
    return RRV_OK;
}

/* Decodes chunk number `chunk` of the offset table at pos into out (w x h
   pixels, lines_per_chunk scanlines a chunk); NULL, or what is wrong with it. */
static const char *rrv__exr_read_chunk(const unsigned char *p, size_t size, size_t pos, size_t chunk,
                                       const rrv__exr_scan *hd, size_t w, size_t h, int lines_per_chunk,
                                       size_t line_bytes, unsigned char *raw, unsigned char *tmp,
                                       unsigned char *seen, float *out)
{
    const rrv__exr_channel *channels = hd->channels;
    const int channel_count = hd->channel_count, compression = hd->compression;
    const int32_t *dw = hd->dw;
    int i;
    const unsigned char *entry = p + pos + 8 * chunk;
    uint64_t offset = (uint64_t)rrv__get_u32_le(entry) | (uint64_t)rrv__get_u32_le(entry + 4) << 32;
    int64_t y;
    size_t index, lines, expected, packed, line;
    const char *problem = NULL;
    if (offset > size || size - offset < 8) {
        problem = "chunk offset outside the file";
    } else {
        y = (int64_t)rrv__get_i32_le(p + offset) - dw[1];
        packed = rrv__get_u32_le(p + offset + 4);
        if (y < 0 || (uint64_t)y >= h || y % lines_per_chunk != 0) {
            problem = "chunk for a scanline outside the data window";
        } else if (seen[index = (size_t)y / (size_t)lines_per_chunk]) {
            problem = "two chunks for the same scanlines";
        } else if (packed > size - offset - 8) {
            problem = "chunk runs past the end of the file";
        } else {
            const unsigned char *src = p + offset + 8;
            seen[index] = 1;
            lines = h - (size_t)y < (size_t)lines_per_chunk ? h - (size_t)y : (size_t)lines_per_chunk;
            expected = line_bytes * lines;
            if (packed == expected) {
                memcpy(raw, src, expected);
            } else if (packed > expected || compression == 0) {
                problem = "chunk of the wrong size";
            } else if (compression == 1 ? !rrv__exr_rle_decode(src, packed, tmp, expected)
                                        : !rrv__zlib_inflate(src, packed, tmp, expected)) {
                problem = compression == 1 ? "corrupt RLE data" : "corrupt ZIP data";
            } else {
                rrv__exr_unpredict(tmp, expected, raw);
            }
            for (line = 0; !problem && line < lines; ++line) {
                float *row = out + ((size_t)y + line) * w * 3;
                const unsigned char *base = raw + line * line_bytes;
                for (i = 0; i < channel_count; ++i) {
                    const unsigned char *q = base + channels[i].offset;
                    size_t x;
                    int c = channels[i].rgb;
                    if (c < 0) continue;
                    if (channels[i].type == 1) {
                        for (x = 0; x < w; ++x, q += 2)
                            row[3 * x + (size_t)c] = rrv__float_from_half((uint16_t)(q[0] | q[1] << 8));
                    } else {
                        for (x = 0; x < w; ++x, q += 4) {
                            uint32_t bits = rrv__get_u32_le(q);
                            memcpy(&row[3 * x + (size_t)c], &bits, sizeof bits);
                        }
                    }
                }
            }
        }
    }
    return problem;
}

RRV_DEF rrv_result rrv_read_exr_memory(const void *data, size_t size, const char *name, float **rgb,
                                       int *width, int *height, rrv_exr_options *info, rrv_error *err)
{
    const unsigned char *p = (const unsigned char *)data;
    rrv__exr_scan hd;
    int i, lines_per_chunk;
    const int32_t *dw = hd.dw, *disp = hd.disp;
    size_t pos = 8, line_bytes, w, h, chunk_count, chunk;
    unsigned char *raw = NULL, *tmp = NULL, *seen = NULL;
    float *out = NULL;
    uint32_t version;
    rrv_result r;

    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    if (!rgb || !width || !height || (!data && size > 0))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, name, 0, "rrv_read_exr_memory: NULL argument");
    if (size < 8 || p[0] != 0x76 || p[1] != 0x2f || p[2] != 0x31 || p[3] != 0x01)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "not an OpenEXR file (no magic number 76 2f 31 01)");
    version = rrv__get_u32_le(p + 4);
    if ((version & 0xFFu) != 2)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "unsupported OpenEXR version %u", (unsigned)(version & 0xFFu));
    if (version & 0x1A00u) /* tiled, deep, multi-part */
        return rrv__fail(err, RRV_ERROR_UNSUPPORTED, name, 0,
                         "unsupported OpenEXR file: only single-part scanline images are read (%s)",
                         (version & 0x1000u) ? "multi-part" : (version & 0x800u) ? "deep" : "tiled");
    if ((r = rrv__exr_read_header(p, size, &pos, name, &hd, err)) != RRV_OK) return r;
    line_bytes = hd.line_bytes;
    w = (size_t)((int64_t)dw[2] - dw[0] + 1);
    h = (size_t)((int64_t)dw[3] - dw[1] + 1);
    lines_per_chunk = hd.compression == 3 ? 16 : 1;
    chunk_count = (h + (size_t)lines_per_chunk - 1) / (size_t)lines_per_chunk;
    /* Every size below is bounded by what the file could hold. */
    if (chunk_count > (size - pos) / 8)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "truncated OpenEXR file: %llu chunks do not fit",
                         (unsigned long long)chunk_count);
    /* a channel list whose sizes add up to 0 would divide by zero below */
    if (line_bytes == 0) return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR channels hold no bytes");
    if (w > (size_t)INT32_MAX / line_bytes / (size_t)lines_per_chunk ||
        (uint64_t)w * line_bytes * h / RRV__EXR_MAX_RATIO > (uint64_t)size || w > SIZE_MAX / 12 / h)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "OpenEXR data window of %llux%llu pixels is larger "
                         "than this file could hold", (unsigned long long)w, (unsigned long long)h);
    for (i = 0; i < hd.channel_count; ++i) hd.channels[i].offset *= w; /* per scanline */
    line_bytes *= w;

    out = (float *)RRV_MALLOC(w * h * 3 * sizeof *out);
    raw = (unsigned char *)RRV_MALLOC(line_bytes * (size_t)lines_per_chunk);
    tmp = (unsigned char *)RRV_MALLOC(line_bytes * (size_t)lines_per_chunk);
    seen = (unsigned char *)RRV_MALLOC(chunk_count);
    if (!out || !raw || !tmp || !seen) {
        RRV_FREE(out);
        RRV_FREE(raw);
        RRV_FREE(tmp);
        RRV_FREE(seen);
        return rrv__fail(err, RRV_ERROR_MEMORY, name, 0, "out of memory for a %llux%llu image",
                         (unsigned long long)w, (unsigned long long)h);
    }
    memset(seen, 0, chunk_count);
    for (chunk = 0; chunk < chunk_count; ++chunk) {
        const char *problem =
            rrv__exr_read_chunk(p, size, pos, chunk, &hd, w, h, lines_per_chunk, line_bytes, raw, tmp, seen, out);
        if (problem) {
            RRV_FREE(out);
            RRV_FREE(raw);
            RRV_FREE(tmp);
            RRV_FREE(seen);
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "bad OpenEXR chunk %llu: %s",
                             (unsigned long long)chunk, problem);
        }
    }
    RRV_FREE(raw);
    RRV_FREE(tmp);
    RRV_FREE(seen);
    *rgb = out;
    *width = (int)w;
    *height = (int)h;
    if (info) {
        memset(info, 0, sizeof *info);
        info->pixel = hd.rgb_type[0] == 2 && hd.rgb_type[1] == 2 && hd.rgb_type[2] == 2 ? RRV_EXR_FLOAT : RRV_EXR_HALF;
        info->compression = hd.compression == 0 ? RRV_EXR_NO_COMPRESSION : RRV_EXR_ZIP;
        info->display_width = (int)((int64_t)disp[2] - disp[0] + 1);
        info->display_height = (int)((int64_t)disp[3] - disp[1] + 1);
        info->x = (int)((int64_t)dw[0] - disp[0]);
        info->y = (int)((int64_t)dw[1] - disp[1]);
        info->text_name = info->text = NULL;
    }
    rrv__clear_error(err);
    return RRV_OK;
}

#endif /* RRV_NO_EXR */

/* ---- the callback writers' public forms: the result as an rrv_error ---- */

static rrv_result rrv__writer_error(rrv_result r, const char *writer, int width, int height,
                                    rrv_error *err)
{
    rrv__clear_error(err);
    if (r == RRV_OK) return r;
    if (r == RRV_ERROR_MEMORY) return rrv__fail(err, r, NULL, 0, "%s: out of memory", writer);
    if (r == RRV_ERROR_IO) return rrv__fail(err, r, NULL, 0, "%s: the write callback failed", writer);
    return rrv__fail(err, r, NULL, 0,
                     "%s: invalid arguments (a %d x %d image, a callback and pixels are needed; "
                     "finite exposure, EXR options and sizes that fit the format)",
                     writer, width, height);
}

RRV_DEF rrv_result rrv_write_pfm_to(rrv_write_func write, void *user, const float *rgb, int width,
                                    int height, rrv_error *err)
{
    return rrv__writer_error(rrv__write_pfm_to(write, user, rgb, width, height), "rrv_write_pfm_to",
                             width, height, err);
}

RRV_DEF rrv_result rrv_write_png_to(rrv_write_func write, void *user, const float *rgb, int width,
                                    int height, double exposure, rrv_error *err)
{
#ifdef RRV_NO_PNG
    (void)write; (void)user; (void)rgb; (void)width; (void)height; (void)exposure;
    return rrv__left_out(err, NULL, "PNG output", "RRV_NO_PNG", "");
#else
    return rrv__writer_error(rrv__write_png_to(write, user, rgb, width, height, exposure),
                             "rrv_write_png_to", width, height, err);
#endif
}

RRV_DEF rrv_result rrv_write_exr_to(rrv_write_func write, void *user, const float *rgb, int width,
                                    int height, const rrv_exr_options *options, rrv_error *err)
{
#ifdef RRV_NO_EXR
    (void)write; (void)user; (void)rgb; (void)width; (void)height; (void)options;
    return rrv__left_out(err, NULL, "OpenEXR output", "RRV_NO_EXR", "");
#else
    return rrv__writer_error(rrv__write_exr_to(write, user, rgb, width, height, options),
                             "rrv_write_exr_to", width, height, err);
#endif
}

#ifdef RRV_NO_EXR
/* The reader's public forms without it: refused, outputs cleared. */
RRV_DEF rrv_result rrv_exr_find_attribute(const void *data, size_t size, const char *attr_name,
                                          const char **type, const void **value, size_t *value_size)
{
    (void)data; (void)size; (void)attr_name;
    if (type) *type = NULL;
    if (value) *value = NULL;
    if (value_size) *value_size = 0;
    return RRV_ERROR_UNSUPPORTED;
}

RRV_DEF rrv_result rrv_read_exr_memory(const void *data, size_t size, const char *name, float **rgb,
                                       int *width, int *height, rrv_exr_options *info, rrv_error *err)
{
    (void)data; (void)size; (void)info;
    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    return rrv__left_out(err, name, "OpenEXR input", "RRV_NO_EXR", "");
}
#endif

/* ---- PFM reader ------------------------------------------------------------------ */

static int rrv__pfm_is_space(unsigned char c)
{
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

/* Skips whitespace; returns 0 if there was none, which PFM requires between
   header fields. */
static int rrv__pfm_skip_space(const unsigned char *p, size_t size, size_t *pos)
{
    size_t start = *pos;
    while (*pos < size && rrv__pfm_is_space(p[*pos])) ++*pos;
    return *pos > start;
}

static int rrv__pfm_token_ends(const unsigned char *p, size_t size, size_t pos)
{
    return pos == size || rrv__pfm_is_space(p[pos]);
}

/* Parses a decimal dimension. Returns 1 on success, 0 for anything that is not
   plain digits, -1 when it exceeds INT_MAX. */
static int rrv__pfm_parse_dimension(const unsigned char *p, size_t size, size_t *pos, int *out)
{
    size_t i = *pos;
    long long value = 0;
    int too_large = 0;
    if (i >= size || p[i] < '0' || p[i] > '9') return 0;
    for (; i < size && p[i] >= '0' && p[i] <= '9'; ++i) {
        if (!too_large) value = value * 10 + (p[i] - '0');
        if (value > INT_MAX) too_large = 1;
    }
    if (!rrv__pfm_token_ends(p, size, i)) return 0;
    *pos = i;
    if (too_large) return -1;
    *out = (int)value;
    return 1;
}

/* Parses the scale by hand because strtod needs a NUL-terminated copy and
   follows the locale's decimal point; only the sign of the scale and whether
   it is a finite nonzero number matter, so a rough value is enough. */
static int rrv__pfm_parse_scale(const unsigned char *p, size_t size, size_t *pos, double *out)
{
    enum { EXPONENT_CAP = 100000 };
    size_t i = *pos;
    int negative = 0, digits = 0, exponent = 0, fraction_shift = 0;
    double mantissa = 0.0;

    if (i < size && (p[i] == '+' || p[i] == '-')) negative = p[i++] == '-';
    for (; i < size && p[i] >= '0' && p[i] <= '9'; ++i, ++digits) mantissa = mantissa * 10.0 + (p[i] - '0');
    if (i < size && p[i] == '.') {
        for (++i; i < size && p[i] >= '0' && p[i] <= '9'; ++i, ++digits) {
            mantissa = mantissa * 10.0 + (p[i] - '0');
            if (fraction_shift > -EXPONENT_CAP) --fraction_shift;
        }
    }
    if (digits == 0) return 0;
    if (i < size && (p[i] == 'e' || p[i] == 'E')) {
        int exponent_negative = 0, exponent_digits = 0;
        ++i;
        if (i < size && (p[i] == '+' || p[i] == '-')) exponent_negative = p[i++] == '-';
        for (; i < size && p[i] >= '0' && p[i] <= '9'; ++i, ++exponent_digits)
            if (exponent < EXPONENT_CAP) exponent = exponent * 10 + (p[i] - '0');
        if (exponent_digits == 0) return 0;
        if (exponent_negative) exponent = -exponent;
    }
    if (!rrv__pfm_token_ends(p, size, i)) return 0;
    *pos = i;
    *out = (negative ? -mantissa : mantissa) * pow(10.0, (double)(exponent + fraction_shift));
    return 1;
}

static float rrv__float_from_bytes(const unsigned char *b, int little_endian)
{
    uint32_t bits = little_endian
        ? (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24
        : (uint32_t)b[3] | (uint32_t)b[2] << 8 | (uint32_t)b[1] << 16 | (uint32_t)b[0] << 24;
    float value;
    memcpy(&value, &bits, sizeof value);
    return value;
}

/* The parsed PFM header; `pos` is where the pixel data starts. */
typedef struct rrv__pfm_header {
    int width, height, channels, little_endian;
    size_t pos, data_bytes, out_bytes;
} rrv__pfm_header;

/* Parses the header at the start of p[0, size): magic, width, height, scale
   and the single whitespace byte after the scale. */
static rrv_result rrv__pfm_parse_header(const unsigned char *p, size_t size, const char *name,
                                        rrv__pfm_header *h, rrv_error *err)
{
    size_t pos, pixel_count;
    int w = 0, ht = 0, dim;
    double scale = 0.0;

    if (size < 2 || p[0] != 'P' || (p[1] != 'F' && p[1] != 'f'))
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "not a PFM file (it must start with \"PF\" or \"Pf\")");
    h->channels = p[1] == 'F' ? 3 : 1;
    pos = 2;

    if (!rrv__pfm_skip_space(p, size, &pos) || (dim = rrv__pfm_parse_dimension(p, size, &pos, &w)) == 0)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "bad PFM header: expected the width after \"P%c\"", p[1]);
    if (dim < 0 || w <= 0)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "bad PFM header: width must be from 1 to %d", INT_MAX);
    if (!rrv__pfm_skip_space(p, size, &pos) || (dim = rrv__pfm_parse_dimension(p, size, &pos, &ht)) == 0)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "bad PFM header: expected the height after the width");
    if (dim < 0 || ht <= 0)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "bad PFM header: height must be from 1 to %d", INT_MAX);
    if (!rrv__pfm_skip_space(p, size, &pos) || !rrv__pfm_parse_scale(p, size, &pos, &scale))
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "bad PFM header: expected the scale after the height");
    if (scale == 0.0 || !isfinite(scale))
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "bad PFM header: the scale must be a finite nonzero number (its sign gives the byte order)");
    h->little_endian = scale < 0.0;
    /* The pixel data starts right after one whitespace byte: any more would
       be the first bytes of the data. */
    if (pos >= size)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "truncated PFM: the header ends without pixel data");
    ++pos;

    if ((size_t)w > SIZE_MAX / (size_t)ht
        || (pixel_count = (size_t)w * (size_t)ht) > SIZE_MAX / 3 / sizeof(float))
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "PFM dimensions %dx%d are too large", w, ht);
    h->width = w;
    h->height = ht;
    h->pos = pos;
    h->data_bytes = pixel_count * (size_t)h->channels * 4;
    h->out_bytes = pixel_count * 3 * sizeof(float);
    return RRV_OK;
}

/* Turns the pixel data (h->data_bytes at p) into a new RGB buffer. */
static rrv_result rrv__pfm_decode(const unsigned char *p, const rrv__pfm_header *h, const char *name,
                                  float **rgb, rrv_error *err)
{
    int x, y;
    size_t i;
    float *out = (float *)RRV_MALLOC(h->out_bytes);
    if (!out)
        return rrv__fail(err, RRV_ERROR_MEMORY, name, 0, "out of memory for a %dx%d image",
                         h->width, h->height);
    /* The file stores the bottom row first; row 0 of the buffer is the top. */
    for (y = h->height - 1; y >= 0; --y) {
        float *row = out + (size_t)y * (size_t)h->width * 3;
        for (x = 0; x < h->width; ++x) {
            if (h->channels == 3) {
                for (i = 0; i < 3; ++i, p += 4) row[3 * (size_t)x + i] = rrv__float_from_bytes(p, h->little_endian);
            } else {
                float grey = rrv__float_from_bytes(p, h->little_endian);
                p += 4;
                row[3 * (size_t)x] = row[3 * (size_t)x + 1] = row[3 * (size_t)x + 2] = grey;
            }
        }
    }
    *rgb = out;
    return RRV_OK;
}

static rrv_result rrv__pfm_truncated(rrv_error *err, const char *name, const rrv__pfm_header *h,
                                     size_t have)
{
    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                     "truncated PFM: %dx%d needs %llu bytes of pixel data but the file has %llu",
                     h->width, h->height, (unsigned long long)h->data_bytes, (unsigned long long)have);
}

RRV_DEF rrv_result rrv_read_pfm_memory(const void *data, size_t size, const char *name,
                                       float **rgb, int *width, int *height, rrv_error *err)
{
    const unsigned char *p = (const unsigned char *)data;
    rrv__pfm_header h;
    rrv_result result;

    /* every field is set on success; zeroed so that gcc -O1, inlining
       differently without stdio, sees none read uninitialised */
    memset(&h, 0, sizeof h);
    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    if (!rgb || !width || !height || (!data && size > 0))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, name, 0, "rrv_read_pfm_memory: NULL argument");
    result = rrv__pfm_parse_header(p, size, name, &h, err);
    if (result != RRV_OK) return result;
    if (h.data_bytes > size - h.pos) return rrv__pfm_truncated(err, name, &h, size - h.pos);
    result = rrv__pfm_decode(p + h.pos, &h, name, rgb, err);
    if (result != RRV_OK) return result;
    *width = h.width;
    *height = h.height;
    rrv__clear_error(err);
    return RRV_OK;
}

/* ---- file forms ---------------------------------------------------------------- */

#ifndef RRV_NO_STDIO
#include <errno.h>
#include <time.h>
#if (defined(__unix__) || defined(__APPLE__)) && !defined(RRV_NO_POSIX)
#define RRV__POSIX 1
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#ifndef __cplusplus
/* POSIX's own prototype: glibc's <stdio.h> declares it only when a feature
   macro came before its first include, which the user's includes may have
   settled already (CONFIGURATION). C++ compilers define _GNU_SOURCE. */
FILE *fdopen(int fd, const char *mode);
#endif
#else
#define RRV__POSIX 0
#endif

static int rrv__fwrite_callback(void *user, const void *data, size_t size)
{
    return fwrite(data, 1, size, (FILE *)user) == size ? 0 : 1;
}

/* Why fopen or fread failed, in words that do not depend on the platform's
   strerror, or "" when errno says nothing we can name. The scene reader
   shares it. */
static const char *rrv__io_reason(int errnum)
{
#ifdef ENOENT
    if (errnum == ENOENT) return "no such file";
#endif
#ifdef EACCES
    if (errnum == EACCES) return "permission denied";
#endif
#ifdef EISDIR
    if (errnum == EISDIR) return "is a directory";
#endif
    (void)errnum;
    return "";
}

#if RRV__POSIX
static const char *rrv__file_kind(mode_t mode)
{
    if (S_ISDIR(mode)) return "a directory";
    if (S_ISCHR(mode)) return "a character device";
    if (S_ISBLK(mode)) return "a block device";
    if (S_ISFIFO(mode)) return "a FIFO";
#ifdef S_ISSOCK
    if (S_ISSOCK(mode)) return "a socket";
#endif
    return "not a regular file";
}
#endif

/* The one way every reader opens a file. O_NONBLOCK makes the open itself
   return at once for a FIFO without a writer (and O_NOCTTY keeps a terminal
   from becoming ours); fstat on the descriptor then judges the very file
   that was opened, not a name that may have been swapped since. A regular
   file never blocks, so the flag is cleared again before stdio reads. *why
   is "" or the reason in words; *size the size or UINT64_MAX. */
static FILE *rrv__open_read(const char *path, uint64_t *size, const char **why)
{
#if RRV__POSIX
    struct stat st;
    int fd, flags = O_RDONLY | O_NONBLOCK | O_NOCTTY;
    FILE *f;
#ifdef O_CLOEXEC
    flags |= O_CLOEXEC; /* a client's child processes need not inherit it */
#endif
    *size = UINT64_MAX;
    *why = "";
    errno = 0;
    fd = open(path, flags);
    if (fd < 0) {
        *why = rrv__io_reason(errno);
        return NULL;
    }
    if (fstat(fd, &st) != 0) {
        *why = rrv__io_reason(errno);
        close(fd);
        return NULL;
    }
    if (!S_ISREG(st.st_mode)) {
        /* a folder keeps the words fopen's EISDIR gave before */
        *why = S_ISDIR(st.st_mode) ? "is a directory" : "not a regular file";
        close(fd);
        errno = 0;
        return NULL;
    }
    flags = fcntl(fd, F_GETFL);
    if (flags == -1 || fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) == -1 || !(f = fdopen(fd, "rb"))) {
        *why = rrv__io_reason(errno);
        close(fd);
        return NULL;
    }
    if (st.st_size >= 0) *size = (uint64_t)st.st_size;
    return f;
#else
    FILE *f;
    *size = UINT64_MAX;
    errno = 0;
    f = fopen(path, "rb");
    *why = f ? "" : rrv__io_reason(errno);
    return f;
#endif
}

RRV_DEF rrv_result rrv_open_read(const char *path, FILE **file, uint64_t *size, rrv_error *err)
{
    const char *why = "";
    uint64_t bytes;
    if (file) *file = NULL;
    if (size) *size = UINT64_MAX;
    if (!path || !file) return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "rrv_open_read: NULL argument");
    *file = rrv__open_read(path, &bytes, &why);
    if (!*file) return rrv__fail(err, RRV_ERROR_IO, path, 0, "%s", why[0] ? why : "cannot open");
    if (size) *size = bytes;
    rrv__clear_error(err);
    return RRV_OK;
}

/* Stops a stream read early: sees the whole buffer after each piece. */
typedef int (*rrv__stream_stop_func)(const unsigned char *data, size_t have, size_t got);

/* Reads what is left of f into a buffer that starts at `first` bytes and
   doubles as data arrives (the PFM, EXR and scene readers share it): a size
   that a file claims is never trusted for an allocation (a folder's can be
   2^63), and a device or pipe costs only what it delivers. At most `limit`
   bytes are kept; with `over_is_error` one more byte is tried, and getting
   it is RRV_ERROR_LIMIT. Pieces are at most `piece` bytes, after each of
   which `stop` (if not NULL) may end the read. RRV_ERROR_IO keeps errno in
   *errnum; RRV_ERROR_MEMORY; RRV_OK with *data (NULL when nothing came). */
static rrv_result rrv__read_stream(FILE *f, size_t first, size_t piece, size_t limit,
                                   int over_is_error, rrv__stream_stop_func stop,
                                   unsigned char **data, size_t *size, int *errnum)
{
    unsigned char *buf = NULL;
    size_t have = 0, capacity = 0;
    size_t cap = over_is_error && limit < SIZE_MAX ? limit + 1 : limit;
    *data = NULL;
    *size = 0;
    *errnum = 0;
    for (;;) {
        size_t want, got;
        if (have == capacity) {
            size_t grown = capacity ? capacity * 2 : first;
            unsigned char *bigger;
            if (grown > cap || grown < capacity) grown = cap; /* the cap, or doubling overflowed */
            if (grown <= capacity) break;
            bigger = (unsigned char *)RRV_REALLOC(buf, grown);
            if (!bigger) {
                RRV_FREE(buf);
                return RRV_ERROR_MEMORY;
            }
            buf = bigger;
            capacity = grown;
        }
        want = capacity - have < piece ? capacity - have : piece;
        errno = 0;
        got = fread(buf + have, 1, want, f);
        have += got;
        if (stop && stop(buf, have, got)) break;
        if (over_is_error && have > limit) {
            RRV_FREE(buf);
            return RRV_ERROR_LIMIT;
        }
        if (got < want) break;
    }
    if (ferror(f)) {
        *errnum = errno;
        RRV_FREE(buf);
        return RRV_ERROR_IO;
    }
    *data = buf;
    *size = have;
    return RRV_OK;
}

/* Opens a new temporary file next to path. The name carries a value mixed
   from the clock, the address of the stack and the attempt, so two writers
   to one path (or a leftover file) rarely meet; a name that exists is
   skipped. POSIX's O_EXCL, or else C11's exclusive "x" mode, closes the
   remaining race where it is available. */
static FILE *rrv__open_temp(const char *path, char *temp_path, size_t cap)
{
    int attempt;
    for (attempt = 0; attempt < 64; ++attempt) {
        uint64_t mix = rrv__mix64((uint64_t)time(NULL) ^ ((uint64_t)clock() << 20) ^
                                  ((uint64_t)(uintptr_t)&attempt << 7) ^ (uint64_t)attempt);
        FILE *f;
        snprintf(temp_path, cap, "%s.%08lx.tmp", path, (unsigned long)(mix & 0xffffffffu));
#if RRV__POSIX
        {
            /* O_EXCL creates the name or fails, also where a link or a FIFO
               stands at it; 0666 less the umask is what fopen would give */
            int fd = open(temp_path, O_WRONLY | O_CREAT | O_EXCL | O_NOCTTY, 0666);
            if (fd < 0) {
                if (errno == EEXIST) continue;
                return NULL;
            }
            f = fdopen(fd, "wb");
            if (!f) {
                close(fd);
                remove(temp_path);
            }
            return f;
        }
#else
        f = fopen(temp_path, "rb");
        if (f) { /* taken: never write over a file we did not create */
            fclose(f);
            continue;
        }
#if defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L
        f = fopen(temp_path, "wbx");
#else
        f = fopen(temp_path, "wb");
#endif
        if (f) return f;
#ifdef EEXIST
        if (errno == EEXIST) continue;
#endif
        return NULL;
#endif
    }
    return NULL;
}

/* Writes through a new temporary file and renames it over path only after
   every fwrite and the fclose succeeded. */
enum { RRV__IMAGE_PFM, RRV__IMAGE_PNG, RRV__IMAGE_EXR };

static rrv_result rrv__write_image_file(const char *path, const float *rgb, int width, int height,
                                        int format, double exposure, const rrv_exr_options *exr,
                                        rrv_error *err)
{
    size_t cap;
    char *temp_path;
    FILE *file;
    rrv_result result;
    int closed;

#ifdef RRV_NO_EXR
    (void)exr;
#endif
    if (!path) return rrv__fail(err, RRV_ERROR_ARGUMENT, NULL, 0, "no output path");
    if (rrv__check_image_args(rgb, width, height) != RRV_OK)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "invalid image (%dx%d, data %s)",
                         width, height, rgb ? "given" : "NULL");
#ifdef RRV_NO_PNG
    if (format == RRV__IMAGE_PNG) return rrv__left_out(err, path, "PNG output", "RRV_NO_PNG", "");
#endif
#ifdef RRV_NO_EXR
    if (format == RRV__IMAGE_EXR) return rrv__left_out(err, path, "OpenEXR output", "RRV_NO_EXR", "");
#endif
    if (format == RRV__IMAGE_PNG && !isfinite(exposure))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "exposure must be finite");

#if RRV__POSIX
    {
        /* stat follows a link: what matters is what rename would replace
           for the reader of path, and a link to a device reads the device */
        struct stat st;
        if (stat(path, &st) == 0 && !S_ISREG(st.st_mode))
            return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot write: it is %s, not a regular file",
                             rrv__file_kind(st.st_mode));
    }
#endif
    cap = strlen(path) + 16; /* ".%08lx.tmp" and the NUL */
    temp_path = (char *)RRV_MALLOC(cap);
    if (!temp_path) return rrv__fail(err, RRV_ERROR_MEMORY, path, 0, "out of memory");
    errno = 0;
    file = rrv__open_temp(path, temp_path, cap);
    if (!file) {
        const char *why = rrv__io_reason(errno);
        RRV_FREE(temp_path);
        return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot write: cannot create a temporary file%s%s",
                         why[0] ? ": " : "", why);
    }
#ifndef RRV_NO_PNG
    if (format == RRV__IMAGE_PNG)
        result = rrv__write_png_to(rrv__fwrite_callback, file, rgb, width, height, exposure);
    else
#endif
#ifndef RRV_NO_EXR
    if (format == RRV__IMAGE_EXR)
        result = rrv__write_exr_to(rrv__fwrite_callback, file, rgb, width, height, exr);
    else
#endif
        result = rrv__write_pfm_to(rrv__fwrite_callback, file, rgb, width, height);
    closed = fclose(file) == 0;
    if (result != RRV_OK || !closed) {
        remove(temp_path);
        RRV_FREE(temp_path);
        if (result == RRV_ERROR_MEMORY) return rrv__fail(err, RRV_ERROR_MEMORY, path, 0, "out of memory");
        if (result == RRV_ERROR_ARGUMENT)
            return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0,
                             "invalid EXR options or an image too wide for an EXR chunk");
        return rrv__fail(err, RRV_ERROR_IO, path, 0,
                         result != RRV_OK ? "cannot write: writing failed" : "cannot write: closing failed");
    }
    if (rename(temp_path, path) != 0) {
#ifdef _WIN32
        /* Windows' rename refuses an existing target. Removing it first loses
           atomicity but still never leaves a partial image at path. */
        if (remove(path) != 0 || rename(temp_path, path) != 0)
#endif
        {
            remove(temp_path);
            RRV_FREE(temp_path);
            return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot write: cannot rename the temporary file");
        }
    }
    RRV_FREE(temp_path);
    rrv__clear_error(err);
    return RRV_OK;
}

RRV_DEF rrv_result rrv_write_pfm(const char *path, const float *rgb, int width, int height,
                                 rrv_error *err)
{
    return rrv__write_image_file(path, rgb, width, height, RRV__IMAGE_PFM, 0.0, NULL, err);
}

RRV_DEF rrv_result rrv_write_png(const char *path, const float *rgb, int width, int height,
                                 double exposure, rrv_error *err)
{
    return rrv__write_image_file(path, rgb, width, height, RRV__IMAGE_PNG, exposure, NULL, err);
}

RRV_DEF rrv_result rrv_write_exr(const char *path, const float *rgb, int width, int height,
                                 const rrv_exr_options *options, rrv_error *err)
{
    return rrv__write_image_file(path, rgb, width, height, RRV__IMAGE_EXR, 0.0, options, err);
}

/* A header longer than this is not a PFM: rrv writes 20-odd bytes, and a
   file of endless whitespace or digits must not be read to its end. */
#define RRV__PFM_HEADER_MAX 1024

/* Reads up to the single whitespace byte after the scale (the third field),
   stopping early at anything that cannot be a PFM header so that the
   parser's message describes it. Returns the bytes read. */
static size_t rrv__pfm_read_header(FILE *file, unsigned char *header, size_t cap)
{
    size_t n = 0;
    int fields = 0, in_field = 0, c;
    while (n < cap && (c = getc(file)) != EOF) {
        header[n++] = (unsigned char)c;
        if (n <= 2) {
            if (n == 1 ? c != 'P' : c != 'F' && c != 'f') break;
        } else if (rrv__pfm_is_space((unsigned char)c)) {
            if (in_field && ++fields == 3) break;
            in_field = 0;
        } else {
            in_field = 1;
        }
    }
    return n;
}

RRV_DEF rrv_result rrv_read_pfm(const char *path, float **rgb, int *width, int *height,
                                rrv_error *err)
{
    unsigned char header[RRV__PFM_HEADER_MAX], *data = NULL;
    size_t header_size, have = 0;
    rrv__pfm_header h;
    uint64_t file_size;
    const char *why;
    FILE *file;
    rrv_result result;
    int errnum;

    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    if (!path || !rgb || !width || !height)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "rrv_read_pfm: NULL argument");
    file = rrv__open_read(path, &file_size, &why);
    if (!file) return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot open%s%s", why[0] ? ": " : "", why);

    /* The header first, then exactly the pixel data it announces: a stream
       without end (a device, a pipe) is read no further than that. */
    errno = 0;
    header_size = rrv__pfm_read_header(file, header, sizeof header);
    if (ferror(file)) {
        const char *why = rrv__io_reason(errno);
        fclose(file);
        return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot read%s%s", why[0] ? ": " : "", why);
    }
    result = rrv__pfm_parse_header(header, header_size, path, &h, err);
    if (result != RRV_OK && header_size == sizeof header)
        result = rrv__fail(err, RRV_ERROR_FORMAT, path, 0, "bad PFM header: longer than %d bytes",
                           RRV__PFM_HEADER_MAX);
    if (result != RRV_OK) {
        fclose(file);
        return result;
    }

    /* A header announcing more than the file holds is refused by the
       file's size; where that is unknown the buffer grows with what
       arrives, so it costs at most twice what the file holds. */
    if (file_size != UINT64_MAX && header_size <= file_size && h.data_bytes > file_size - header_size) {
        fclose(file);
        return rrv__pfm_truncated(err, path, &h, (size_t)(file_size - header_size));
    }
    result = rrv__read_stream(file, (size_t)1 << 20, SIZE_MAX, h.data_bytes, 0, NULL, &data, &have,
                              &errnum);
    fclose(file);
    if (result == RRV_ERROR_MEMORY)
        return rrv__fail(err, RRV_ERROR_MEMORY, path, 0, "out of memory for a %dx%d image", h.width,
                         h.height);
    if (result != RRV_OK) return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot read");
    if (have < h.data_bytes) {
        RRV_FREE(data);
        return rrv__pfm_truncated(err, path, &h, have);
    }
    result = rrv__pfm_decode(data, &h, path, rgb, err);
    RRV_FREE(data);
    if (result != RRV_OK) return result;
    *width = h.width;
    *height = h.height;
    rrv__clear_error(err);
    return RRV_OK;
}

#ifndef RRV_NO_EXR
/* A file can be no larger than this to be read whole. */
#define RRV__EXR_FILE_MAX ((size_t)1 << 31)

/* Ends the read after the first 8 bytes unless they start an OpenEXR file. */
static int rrv__exr_stop(const unsigned char *data, size_t have, size_t got)
{
    (void)got;
    return have == 8 && (data[0] != 0x76 || data[1] != 0x2f || data[2] != 0x31 || data[3] != 0x01);
}

RRV_DEF rrv_result rrv_read_exr(const char *path, float **rgb, int *width, int *height,
                                rrv_exr_options *info, rrv_error *err)
{
    unsigned char *data = NULL;
    size_t have = 0;
    uint64_t file_size;
    const char *why;
    FILE *file;
    rrv_result result;
    int errnum;
    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    if (!path || !rgb || !width || !height)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "rrv_read_exr: NULL argument");
    file = rrv__open_read(path, &file_size, &why);
    if (!file) return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot open%s%s", why[0] ? ": " : "", why);
    /* The first read is 8 bytes, so a stream that is no EXR (a device, a
       pipe, where plain C cannot refuse them) is refused without reading on. */
    if (file_size != UINT64_MAX && file_size > RRV__EXR_FILE_MAX) {
        fclose(file);
        return rrv__fail(err, RRV_ERROR_LIMIT, path, 0, "OpenEXR file larger than %llu bytes",
                         (unsigned long long)RRV__EXR_FILE_MAX);
    }
    result = rrv__read_stream(file, 8, SIZE_MAX, RRV__EXR_FILE_MAX, 1, rrv__exr_stop, &data, &have,
                              &errnum);
    fclose(file);
    if (result == RRV_ERROR_LIMIT)
        return rrv__fail(err, RRV_ERROR_LIMIT, path, 0, "OpenEXR file larger than %llu bytes",
                         (unsigned long long)RRV__EXR_FILE_MAX);
    if (result == RRV_ERROR_MEMORY)
        return rrv__fail(err, RRV_ERROR_MEMORY, path, 0, "out of memory reading the file");
    if (result != RRV_OK) {
        const char *why = rrv__io_reason(errnum);
        return rrv__fail(err, RRV_ERROR_IO, path, 0, "cannot read%s%s", why[0] ? ": " : "", why);
    }
    result = rrv_read_exr_memory(data, have, path, rgb, width, height, info, err);
    RRV_FREE(data);
    return result;
}
#endif /* RRV_NO_EXR */

#else /* RRV_NO_STDIO */

RRV_DEF rrv_result rrv_write_exr(const char *path, const float *rgb, int width, int height,
                                 const rrv_exr_options *options, rrv_error *err)
{
    (void)rgb; (void)width; (void)height; (void)options;
    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, path, 0,
                     "file output is disabled (RRV_NO_STDIO); use rrv_write_exr_to");
}

RRV_DEF rrv_result rrv_read_exr(const char *path, float **rgb, int *width, int *height,
                                rrv_exr_options *info, rrv_error *err)
{
    (void)info;
    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, path, 0,
                     "file input is disabled (RRV_NO_STDIO); use rrv_read_exr_memory");
}

RRV_DEF rrv_result rrv_write_pfm(const char *path, const float *rgb, int width, int height,
                                 rrv_error *err)
{
    (void)rgb; (void)width; (void)height;
    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, path, 0,
                     "file output is disabled (RRV_NO_STDIO); use rrv_write_pfm_to");
}

RRV_DEF rrv_result rrv_write_png(const char *path, const float *rgb, int width, int height,
                                 double exposure, rrv_error *err)
{
    (void)rgb; (void)width; (void)height; (void)exposure;
    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, path, 0,
                     "file output is disabled (RRV_NO_STDIO); use rrv_write_png_to");
}

RRV_DEF rrv_result rrv_read_pfm(const char *path, float **rgb, int *width, int *height,
                                rrv_error *err)
{
    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, path, 0,
                     "file input is disabled (RRV_NO_STDIO); use rrv_read_pfm_memory");
}

#endif /* RRV_NO_STDIO */

#if defined(RRV_NO_EXR) && !defined(RRV_NO_STDIO)
RRV_DEF rrv_result rrv_read_exr(const char *path, float **rgb, int *width, int *height,
                                rrv_exr_options *info, rrv_error *err)
{
    (void)info;
    if (rgb) *rgb = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    return rrv__left_out(err, path, "OpenEXR input", "RRV_NO_EXR", "");
}
#endif

/* ---- whole files, for the NanoVDB and scene file readers ---------------- */

/* Kept here, after the file forms it reads through, as only those two modules read whole files. */
#if !defined(RRV_NO_SCENE_FILE) || !defined(RRV_NO_NANOVDB)

#ifndef RRV_NO_STDIO
/* A text file stops after the piece holding its first NUL byte: the parser
   refuses the file on that line anyway, and a device such as /dev/zero
   would otherwise be read up to the limit. */
static int rrv__sf_text_stop(const unsigned char *data, size_t have, size_t got)
{
    return memchr(data + have - got, '\0', got) != NULL;
}

/* A binary file (NanoVDB, the only one read whole) stops after its first
   piece unless it starts as one: where plain C cannot refuse a device,
   /dev/zero is not read up to the limit either. */
static int rrv__sf_binary_stop(const unsigned char *data, size_t have, size_t got)
{
    (void)got;
    return have >= 7 && memcmp(data, "NanoVDB", 7) != 0;
}

/* A whole file, at most max_bytes of it (rrv__read_stream): one larger by
   its size is refused before a byte is read, and a file of known size is
   read into one buffer of that size (plus the byte that finds growth). */
static rrv_result rrv__sf_stdio_read(const char *path, size_t max_bytes, int text, void **data,
                                     size_t *size, const char **why)
{
    enum { PIECE = 64 * 1024 };
    unsigned char *buf;
    size_t first = 2 * (size_t)PIECE;
    uint64_t file_size;
    rrv_result r;
    int errnum;
    FILE *f = rrv__open_read(path, &file_size, why);
    if (!f) return RRV_ERROR_IO;
    if (file_size != UINT64_MAX) {
        if (file_size > max_bytes) {
            fclose(f);
            return RRV_ERROR_LIMIT;
        }
        first = (size_t)file_size + 1;
    }
    r = rrv__read_stream(f, first, PIECE, max_bytes, 1, text ? rrv__sf_text_stop : rrv__sf_binary_stop,
                         &buf, size, &errnum);
    fclose(f);
    if (r == RRV_ERROR_IO) *why = rrv__io_reason(errnum);
    *data = buf;
    return r;
}
#endif

/* RRV_OK with the whole file; RRV_ERROR_IO (*why says why, or ""),
   RRV_ERROR_LIMIT past max_bytes, RRV_ERROR_MEMORY, or RRV_ERROR_UNSUPPORTED
   when there is no way to read files at all. */
/* Gives back a buffer rrv__sf_read_whole returned, to whoever allocated it. */
static void rrv__sf_release_whole(const rrv_load_options *opt, void *data)
{
    if (!data) return;
    if (opt && opt->read_file && opt->release_file)
        opt->release_file(opt->read_file_user, data);
    else
        RRV_FREE(data);
}

/* 1 when a buffer of rrv__sf_read_whole may be kept and later freed with
   RRV_FREE (a NanoVDB grid keeps its file's bytes). */
#ifndef RRV_NO_NANOVDB
static int rrv__sf_whole_is_ours(const rrv_load_options *opt)
{
    return !(opt && opt->read_file && opt->release_file);
}
#endif

static rrv_result rrv__sf_read_whole(const rrv_load_options *opt, const char *path, int text,
                                     size_t max_bytes, void **data, size_t *size, const char **why)
{
    *data = NULL;
    *size = 0;
    *why = "";
    if (opt && opt->on_input) opt->on_input(opt->on_input_user, path);
    if (opt && opt->read_file) {
        if (opt->read_file(opt->read_file_user, path, data, size) != 0) {
            rrv__sf_release_whole(opt, *data);
            *data = NULL;
            return RRV_ERROR_IO;
        }
        if (!*data && *size > 0) return RRV_ERROR_IO;
        if (*size > max_bytes) {
            rrv__sf_release_whole(opt, *data);
            *data = NULL;
            return RRV_ERROR_LIMIT;
        }
        return RRV_OK;
    }
#ifndef RRV_NO_STDIO
    return rrv__sf_stdio_read(path, max_bytes, text, data, size, why);
#else
    (void)text;
    return RRV_ERROR_UNSUPPORTED;
#endif
}

#endif /* whole files */

/* >> 14 NanoVDB files (module): segments, grids and the validation of trees ==
   Reads what nanovdb_convert writes: a file of segments, each a 16-byte
   header ("NanoVDB0" or the newer "NanoVDB2", version, grid count, codec)
   followed by 176 bytes of metadata and the name of each grid, then the
   grids' buffers; or, since NanoVDB 32.6, bare grid buffers one after the
   other (starting "NanoVDB1"). A grid buffer is GridData (672 bytes: magic,
   version, size, name, map, type), TreeData (node offsets and counts), the
   root (background, a table of tiles keyed by coordinate) and arrays of
   upper, lower and leaf nodes reached by signed byte offsets.
   Everything is untrusted: each node is checked to lie inside the grid's
   buffer at a position of its level's node array before it is read, each
   node is visited once (so shared children cannot multiply the work), and
   every value is checked finite, after which the lookups above need no
   checks. */

RRV_DEF const char *rrv_nanovdb_type_name(rrv_nanovdb_type type)
{
    switch (type) {
    case RRV_NANOVDB_FLOAT: return "float";
    case RRV_NANOVDB_FP4: return "fp4";
    case RRV_NANOVDB_FP8: return "fp8";
    case RRV_NANOVDB_FP16: return "fp16";
    case RRV_NANOVDB_FPN: return "fpN";
    default: return "unknown";
    }
}

/* Without the reader (RRV_NO_NANOVDB) no grid can be validated, so the
   lookups above stay but a NANOVDB field is refused (rrv__field_check). */
#ifndef RRV_NO_NANOVDB
static int32_t rrv__nv_s32(uint32_t u)
{
    return u <= 0x7fffffffu ? (int32_t)u : (int32_t)(u - 0x80000000u) - 0x7fffffff - 1;
}

static int rrv__nv_finite(double v) { return v == v && v <= DBL_MAX && v >= -DBL_MAX; }

/* One level's node array: nodes at first + k size, k < count. */
typedef struct rrv__nv_array {
    uint64_t first, count, size;
    unsigned char *seen; /* a byte a node, so each is checked once */
    uint64_t *starts;    /* FpN leaves have sizes of their own: their offsets */
} rrv__nv_array;

typedef struct rrv__nv_check {
    rrv_nanovdb *g;
    const unsigned char *b;
    uint64_t size;
    rrv__nv_array level[3]; /* leaf, lower, upper */
    const char *name;
    rrv_error *err;
} rrv__nv_check;

static const char *const rrv__nv_level_plurals[3] = {"leaves", "lower nodes", "upper nodes"};
/* Child offsets beyond this are refused before they are added to a
   position (< 2^62 too), so the sum cannot overflow. */
#define RRV__NV_FAR ((int64_t)1 << 62)

static void rrv__nv_include(rrv_nanovdb *g, const int64_t o[3], int64_t extent)
{
    int a;
    for (a = 0; a < 3; ++a) {
        if (o[a] < g->data_lo[a]) g->data_lo[a] = o[a];
        if (o[a] + extent - 1 > g->data_hi[a]) g->data_hi[a] = o[a] + extent - 1;
    }
}

static void rrv__nv_value_seen(rrv_nanovdb *g, double v)
{
    if (v < g->value_min) g->value_min = v;
    if (v > g->value_max) g->value_max = v;
}

/* The node of `level` at byte `at` of the grid (from a child offset):
   its index in the level's array, or -1 with the error filled. */
static int64_t rrv__nv_node_index(rrv__nv_check *c, int level, int64_t at, const char *from)
{
    rrv__nv_array *arr = &c->level[level];
    uint64_t k, off;
    if (at < 0 || (uint64_t)at < arr->first || (uint64_t)at >= c->size) goto bad;
    off = (uint64_t)at - arr->first;
    if (arr->starts) {
        uint64_t lo = 0, hi = arr->count;
        while (lo < hi) {
            uint64_t mid = lo + (hi - lo) / 2;
            if (arr->starts[mid] < (uint64_t)at) lo = mid + 1; else hi = mid;
        }
        if (lo < arr->count && arr->starts[lo] == (uint64_t)at) return (int64_t)lo;
        goto bad;
    }
    k = off / arr->size;
    if (off % arr->size != 0 || k >= arr->count) goto bad;
    return (int64_t)k;
bad:
    rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0,
              "grid \"%s\": %s points to byte %lld, which is not one of its %llu %s", c->g->name, from,
              (long long)at, (unsigned long long)arr->count, rrv__nv_level_plurals[level]);
    return -1;
}

static rrv_result rrv__nv_bad_value(rrv__nv_check *c, const char *where, const int64_t o[3])
{
    return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0,
                     "grid \"%s\": a %s value at index %lld %lld %lld is not finite", c->g->name, where,
                     (long long)o[0], (long long)o[1], (long long)o[2]);
}

static rrv_result rrv__nv_check_leaf(rrv__nv_check *c, uint64_t at, const int64_t o[3])
{
    const unsigned char *leaf = c->b + at;
    unsigned n;
    for (n = 0; n < 512; ++n) {
        double v = rrv__nv_leaf_value(c->g->type, leaf, n);
        if (!rrv__nv_finite(v)) {
            int64_t p[3];
            p[0] = o[0] + (n >> 6);
            p[1] = o[1] + ((n >> 3) & 7);
            p[2] = o[2] + (n & 7);
            return rrv__nv_bad_value(c, "voxel", p);
        }
        rrv__nv_value_seen(c->g, v);
    }
    rrv__nv_include(c->g, o, 8);
    return RRV_OK;
}

/* An internal node (level 2 upper, 1 lower) at byte `at` with origin o. */
static rrv_result rrv__nv_check_internal(rrv__nv_check *c, int level, uint64_t at, const int64_t o[3])
{
    const unsigned char *node = c->b + at;
    int log2dim = level == 2 ? 5 : 4, s = level == 2 ? 7 : 3;
    unsigned count = 1u << (3 * log2dim), n;
    size_t mask = 32 + (size_t)(count / 8), table = level == 2 ? RRV__NV_UPPER_TABLE : RRV__NV_LOWER_TABLE;
    rrv_result r;
    for (n = 0; n < count; ++n) {
        const unsigned char *entry = node + table + 8 * (size_t)n;
        int64_t co[3];
        co[0] = o[0] + ((int64_t)(n >> (2 * log2dim)) << s);
        co[1] = o[1] + ((int64_t)((n >> log2dim) & ((1u << log2dim) - 1)) << s);
        co[2] = o[2] + ((int64_t)(n & ((1u << log2dim) - 1)) << s);
        if ((node[mask + (n >> 3)] >> (n & 7)) & 1) {
            int64_t child = (int64_t)rrv__nv_u64(entry), k;
            if (child <= -RRV__NV_FAR || child >= RRV__NV_FAR) child = -(int64_t)at - 1;
            k = rrv__nv_node_index(c, level - 1, (int64_t)at + child, level == 2 ? "an upper node" : "a lower node");
            if (k < 0) return RRV_ERROR_FORMAT;
            if (c->level[level - 1].seen[k]) {
                /* a second parent: its region holds that data too */
                rrv__nv_include(c->g, co, (int64_t)1 << s);
                continue;
            }
            c->level[level - 1].seen[k] = 1;
            r = level == 2 ? rrv__nv_check_internal(c, 1, (uint64_t)((int64_t)at + child), co)
                           : rrv__nv_check_leaf(c, (uint64_t)((int64_t)at + child), co);
            if (r != RRV_OK) return r;
        } else {
            double v = rrv__nv_f32(entry);
            if (!rrv__nv_finite(v)) return rrv__nv_bad_value(c, level == 2 ? "upper-node tile" : "lower-node tile", co);
            rrv__nv_value_seen(c->g, v);
            if (v != c->g->background) rrv__nv_include(c->g, co, (int64_t)1 << s);
        }
    }
    return RRV_OK;
}

static uint64_t rrv__nv_leaf_size(rrv_nanovdb_type type)
{
    switch (type) {
    case RRV_NANOVDB_FLOAT: return 2144;
    case RRV_NANOVDB_FP4: return 352;
    case RRV_NANOVDB_FP8: return 608;
    case RRV_NANOVDB_FP16: return 1120;
    default: return 0;
    }
}

static const char *rrv__nv_any_type_name(uint32_t t)
{
    static const char *const names[] = {"unknown", "float", "double", "int16", "int32", "int64", "vec3f",
                                        "vec3d", "mask", "half", "uint32", "bool", "rgba8", "fp4",
                                        "fp8", "fp16", "fpN", "vec4f", "vec4d", "index"};
    return t < sizeof names / sizeof names[0] ? names[t] : "unknown";
}

/* The grid's header: its name (made printable), NanoVDB version, size and
   value type, into g. */
static rrv_result rrv__nv_check_header(const unsigned char *b, uint64_t size, const char *name, rrv_nanovdb *g,
                                       rrv_error *err)
{
    uint32_t version, type;
    int a;
    if (size < RRV__NV_GRID + RRV__NV_TREE)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "a grid of %llu bytes is shorter than its %d-byte header",
                         (unsigned long long)size, RRV__NV_GRID + RRV__NV_TREE);
    if (memcmp(b, "NanoVDB", 7) != 0 || (b[7] != '0' && b[7] != '1'))
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "a grid does not start with \"NanoVDB0\" or \"NanoVDB1\"");
    memcpy(g->name, b + 40, 255);
    g->name[255] = '\0';
    for (a = 0; g->name[a]; ++a)
        if ((unsigned char)g->name[a] < 32) g->name[a] = '?';
    version = rrv__nv_u32(b + 16);
    if (version >> 21 != 32)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "grid \"%s\" has NanoVDB version %u.%u.%u; rrv reads 32.x",
                         g->name, (unsigned)(version >> 21), (unsigned)((version >> 10) & 2047u),
                         (unsigned)(version & 1023u));
    if (rrv__nv_u64(b + 32) != size)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "grid \"%s\" says it has %llu bytes, the file holds %llu",
                         g->name, (unsigned long long)rrv__nv_u64(b + 32), (unsigned long long)size);
    type = rrv__nv_u32(b + 636);
    if (type != 1 && (type < 13 || type > 16))
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "grid \"%s\" holds %s values; rrv reads float, fp4, fp8, fp16 and fpN grids",
                         g->name, rrv__nv_any_type_name(type));
    g->type = (rrv_nanovdb_type)type;
    return RRV_OK;
}

/* The double-precision map (3x3 matrix, its inverse, translation) into g;
   the stored inverse must be the map's: world and index would otherwise
   disagree about where a voxel is. */
static rrv_result rrv__nv_check_map(const unsigned char *b, const char *name, rrv_nanovdb *g, rrv_error *err)
{
    double det;
    int a, ok, i, j, k;
    for (a = 0; a < 9; ++a) {
        uint64_t u = rrv__nv_u64(b + 384 + 8 * (size_t)a), v = rrv__nv_u64(b + 456 + 8 * (size_t)a);
        memcpy(&g->map[a], &u, 8);
        memcpy(&g->inverse[a], &v, 8);
    }
    for (a = 0; a < 3; ++a) {
        uint64_t u = rrv__nv_u64(b + 528 + 8 * (size_t)a);
        memcpy(&g->translation[a], &u, 8);
    }
    det = g->map[0] * (g->map[4] * g->map[8] - g->map[5] * g->map[7]) -
          g->map[1] * (g->map[3] * g->map[8] - g->map[5] * g->map[6]) +
          g->map[2] * (g->map[3] * g->map[7] - g->map[4] * g->map[6]);
    ok = rrv__nv_finite(det) && det != 0.0;
    for (a = 0; a < 9 && ok; ++a) ok = rrv__nv_finite(g->map[a]) && rrv__nv_finite(g->inverse[a]);
    for (a = 0; a < 3 && ok; ++a) ok = rrv__nv_finite(g->translation[a]);
    for (i = 0; i < 3 && ok; ++i)
        for (j = 0; j < 3 && ok; ++j) {
            double s = 0;
            for (k = 0; k < 3; ++k) s += g->map[3 * i + k] * g->inverse[3 * k + j];
            ok = fabs(s - (i == j ? 1.0 : 0.0)) < 1e-6;
        }
    if (!ok)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "grid \"%s\": its index-to-world map is not finite and invertible, or its stored inverse does not match it",
                         g->name);
    return RRV_OK;
}

/* The tree's three node arrays (leaves, lower, upper) fit in the grid;
   each gets its flags of nodes seen, and FpN leaves, which vary in size,
   the start of each. */
static rrv_result rrv__nv_check_levels(rrv__nv_check *c, uint64_t tree)
{
    const unsigned char *b = c->b;
    const uint64_t size = c->size;
    rrv_nanovdb *g = c->g;
    int lv;
    for (lv = 0; lv < 3; ++lv) {
        rrv__nv_array *arr = &c->level[lv];
        uint64_t offset = rrv__nv_u64(b + tree + 8 * (size_t)lv);
        arr->count = rrv__nv_u32(b + tree + 32 + 4 * (size_t)lv);
        arr->size = lv == 2 ? RRV__NV_UPPER : lv == 1 ? RRV__NV_LOWER : rrv__nv_leaf_size(g->type);
        g->node_count[lv] = (uint32_t)arr->count;
        if (arr->count == 0) continue;
        /* an FpN leaf has at least 1 bit a value: 96 + 64 bytes */
        if (offset > size - tree || arr->count > (size - tree - offset) / (arr->size ? arr->size : 160))
            return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0,
                             "grid \"%s\": its %llu %s at byte %llu do not fit in its %llu bytes", g->name,
                             (unsigned long long)arr->count, rrv__nv_level_plurals[lv],
                             (unsigned long long)(tree + offset), (unsigned long long)size);
        arr->first = tree + offset;
        arr->seen = (unsigned char *)RRV_MALLOC((size_t)arr->count);
        if (!arr->seen) return rrv__fail(c->err, RRV_ERROR_MEMORY, c->name, 0, "out of memory checking a grid");
        memset(arr->seen, 0, (size_t)arr->count);
    }
    if (g->type == RRV_NANOVDB_FPN && c->level[0].count) {
        /* FpN leaves follow each other, each 96 bytes plus 64 per bit */
        rrv__nv_array *arr = &c->level[0];
        uint64_t at = arr->first, k;
        arr->starts = (uint64_t *)RRV_MALLOC((size_t)arr->count * sizeof(uint64_t));
        if (!arr->starts) return rrv__fail(c->err, RRV_ERROR_MEMORY, c->name, 0, "out of memory checking a grid");
        for (k = 0; k < arr->count; ++k) {
            unsigned bits;
            if (at > size - RRV__NV_LEAF_DATA || (b[at + 15] >> 5) > 4)
                return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0, "grid \"%s\": fpN leaf %llu at byte %llu is %s",
                                 g->name, (unsigned long long)k, (unsigned long long)at,
                                 at > size - RRV__NV_LEAF_DATA ? "outside the grid" : "of an unknown bit width");
            bits = 1u << (b[at + 15] >> 5);
            if (64u * bits > size - at - RRV__NV_LEAF_DATA)
                return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0,
                                 "grid \"%s\": fpN leaf %llu at byte %llu ends outside the grid", g->name,
                                 (unsigned long long)k, (unsigned long long)at);
            arr->starts[k] = at;
            at += RRV__NV_LEAF_DATA + 64u * bits;
        }
    }
    return RRV_OK;
}

/* The root node and its tiles: g's root, background, active box and value
   range; every child reached from a tile is checked (rrv__nv_check_internal). */
static rrv_result rrv__nv_check_root(rrv__nv_check *c, uint64_t tree)
{
    const unsigned char *b = c->b;
    const uint64_t size = c->size;
    rrv_nanovdb *g = c->g;
    uint64_t root = rrv__nv_u64(b + tree + 24), tiles, t;
    rrv_result r = RRV_OK;
    int a;
    if (root > size - tree || size - tree - root < RRV__NV_ROOT)
        return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0, "grid \"%s\": its root node lies outside its %llu bytes",
                         g->name, (unsigned long long)size);
    root += tree;
    tiles = rrv__nv_u32(b + root + 24);
    if (tiles > (size - root - RRV__NV_ROOT) / RRV__NV_TILE)
        return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0,
                         "grid \"%s\": its root's %llu tiles do not fit in its %llu bytes", g->name,
                         (unsigned long long)tiles, (unsigned long long)size);
    g->root = (size_t)root;
    g->root_tiles = (uint32_t)tiles;
    g->background = rrv__nv_f32(b + root + 28);
    for (a = 0; a < 3; ++a) {
        g->active_lo[a] = rrv__nv_s32(rrv__nv_u32(b + root + 4 * (size_t)a));
        g->active_hi[a] = rrv__nv_s32(rrv__nv_u32(b + root + 12 + 4 * (size_t)a));
    }
    g->active_voxels = rrv__nv_u64(b + tree + 56);
    if (!rrv__nv_finite(g->background))
        return rrv__fail(c->err, RRV_ERROR_FORMAT, c->name, 0, "grid \"%s\": its background value is not finite",
                         g->name);
    g->value_min = g->value_max = g->background;
    for (a = 0; a < 3; ++a) {
        g->data_lo[a] = INT64_MAX;
        g->data_hi[a] = INT64_MIN;
    }
    for (t = 0; t < tiles && r == RRV_OK; ++t) {
        const unsigned char *tile = b + root + RRV__NV_ROOT + t * RRV__NV_TILE;
        uint64_t key = rrv__nv_u64(tile);
        int64_t child = (int64_t)rrv__nv_u64(tile + 8), o[3], k;
        o[0] = rrv__nv_s32((uint32_t)(((key >> 42) & 0x1fffffu) << 12));
        o[1] = rrv__nv_s32((uint32_t)(((key >> 21) & 0x1fffffu) << 12));
        o[2] = rrv__nv_s32((uint32_t)((key & 0x1fffffu) << 12));
        if (child == 0) {
            double v = rrv__nv_f32(tile + 20);
            if (!rrv__nv_finite(v)) { r = rrv__nv_bad_value(c, "root tile", o); break; }
            rrv__nv_value_seen(g, v);
            if (v != g->background) rrv__nv_include(g, o, 4096);
            continue;
        }
        if (child <= -RRV__NV_FAR || child >= RRV__NV_FAR) child = -(int64_t)root - 1;
        k = rrv__nv_node_index(c, 2, (int64_t)root + child, "a root tile");
        if (k < 0) { r = RRV_ERROR_FORMAT; break; }
        if (c->level[2].seen[k]) { rrv__nv_include(g, o, 4096); continue; }
        c->level[2].seen[k] = 1;
        r = rrv__nv_check_internal(c, 2, (uint64_t)((int64_t)root + child), o);
    }
    return r;
}

/* The world box of the index region the trilinear field can reach from
   the data: one voxel beyond it each side (no data: an empty box at the
   origin). */
static void rrv__nv_world_box(rrv_nanovdb *g)
{
    rrv_vec3 lo = rrv__v3(DBL_MAX, DBL_MAX, DBL_MAX), hi = rrv__v3(-DBL_MAX, -DBL_MAX, -DBL_MAX);
    int corner, a;
    if (g->data_lo[0] > g->data_hi[0]) {
        for (a = 0; a < 3; ++a) { g->data_lo[a] = 1; g->data_hi[a] = 0; }
        lo = hi = rrv__v3(g->translation[0], g->translation[1], g->translation[2]);
    }
    for (corner = 0; corner < 8 && g->data_lo[0] <= g->data_hi[0]; ++corner) {
        double u[3], w[3];
        u[0] = corner & 1 ? (double)g->data_hi[0] + 1.0 : (double)g->data_lo[0] - 1.0;
        u[1] = corner & 2 ? (double)g->data_hi[1] + 1.0 : (double)g->data_lo[1] - 1.0;
        u[2] = corner & 4 ? (double)g->data_hi[2] + 1.0 : (double)g->data_lo[2] - 1.0;
        for (a = 0; a < 3; ++a)
            w[a] = g->map[3 * a] * u[0] + g->map[3 * a + 1] * u[1] + g->map[3 * a + 2] * u[2] + g->translation[a];
        lo = rrv__vmin(lo, rrv__v3(w[0], w[1], w[2]));
        hi = rrv__vmax(hi, rrv__v3(w[0], w[1], w[2]));
    }
    g->lo = lo;
    g->hi = hi;
}

/* Checks the grid buffer b[0, size) and fills g (not g->buffer). */
static rrv_result rrv__nv_check_grid(const unsigned char *b, uint64_t size, const char *name, rrv_nanovdb *g,
                                     rrv_error *err)
{
    rrv__nv_check c;
    rrv_result r;
    int lv;
    memset(&c, 0, sizeof c);
    c.g = g;
    c.b = b;
    c.size = size;
    c.name = name;
    c.err = err;
    if ((r = rrv__nv_check_header(b, size, name, g, err)) != RRV_OK) return r;
    if ((r = rrv__nv_check_map(b, name, g, err)) != RRV_OK) return r;
    r = rrv__nv_check_levels(&c, RRV__NV_GRID);
    if (r == RRV_OK) r = rrv__nv_check_root(&c, RRV__NV_GRID);
    if (r == RRV_OK) rrv__nv_world_box(g);
    for (lv = 0; lv < 3; ++lv) {
        RRV_FREE(c.level[lv].seen);
        RRV_FREE(c.level[lv].starts);
    }
    return r;
}

/* Finds grid `want` in the file and returns its byte range. `names`
   collects the names seen, for the message when it is missing. */
static rrv_result rrv__nv_find_grid(const unsigned char *b, uint64_t size, const char *name, const char *want,
                                    uint64_t *at, uint64_t *grid_size, rrv_error *err)
{
    char names[160];
    size_t used = 0, wl = strlen(want);
    uint64_t pos = 0;
    int segments = 0;
    names[0] = '\0';
    if (size >= 8 && memcmp(b, "NanoVDB1", 8) == 0) {
        /* bare grid buffers, each announcing its own size */
        while (pos < size) {
            uint64_t gs;
            if (size - pos < RRV__NV_GRID || memcmp(b + pos, "NanoVDB1", 8) != 0)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "byte %llu does not start a grid",
                                 (unsigned long long)pos);
            gs = rrv__nv_u64(b + pos + 32);
            if (gs < RRV__NV_GRID || gs > size - pos)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                                 "the grid at byte %llu claims %llu bytes, the file has %llu left",
                                 (unsigned long long)pos, (unsigned long long)gs, (unsigned long long)(size - pos));
            /* GridData holds names of up to 255 bytes (longer ones live in blind data) */
            if (wl <= 255 && memcmp(b + pos + 40, want, wl) == 0 && b[pos + 40 + wl] == '\0') {
                *at = pos;
                *grid_size = gs;
                return RRV_OK;
            }
            if (used + 1 < sizeof names)
                used += (size_t)snprintf(names + used, sizeof names - used, "%s\"%.40s\"", used ? ", " : "",
                                         (const char *)b + pos + 40);
            pos += gs;
        }
    } else {
        while (pos < size) {
            uint32_t version, count, codec, i;
            uint64_t meta, data;
            if (size - pos < 8 || memcmp(b + pos, "NanoVDB", 7) != 0 || (b[pos + 7] != '0' && b[pos + 7] != '2')) {
                if (size - pos >= 8 && memcmp(b + pos, "0BDVonaN", 8) == 0)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "a big-endian NanoVDB file: rrv reads little-endian ones");
                if (segments == 0)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                                     "not a NanoVDB file: it does not start with \"NanoVDB0\", \"NanoVDB1\" or \"NanoVDB2\"");
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "byte %llu does not start a segment (\"NanoVDB\" header)",
                                 (unsigned long long)pos);
            }
            if (size - pos < 16)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "the file ends inside the segment header at byte %llu",
                                 (unsigned long long)pos);
            version = rrv__nv_u32(b + pos + 8);
            count = (uint32_t)b[pos + 12] | ((uint32_t)b[pos + 13] << 8);
            codec = (uint32_t)b[pos + 14] | ((uint32_t)b[pos + 15] << 8);
            if (version >> 21 != 32)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "NanoVDB version %u.%u.%u: rrv reads 32.x files",
                                 (unsigned)(version >> 21), (unsigned)((version >> 10) & 2047u), (unsigned)(version & 1023u));
            if (codec == 1 || codec == 2)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                                 "the grids are %s-compressed; rrv reads uncompressed files: re-convert with nanovdb_convert without -z/-b",
                                 codec == 1 ? "ZIP" : "BLOSC");
            if (codec != 0)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "unknown codec %u", (unsigned)codec);
            if (count == 0)
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "the segment at byte %llu holds no grids",
                                 (unsigned long long)pos);
            /* the metadata of all grids, then their buffers in the same order */
            meta = pos + 16;
            data = meta;
            for (i = 0; i < count; ++i) {
                uint32_t ns;
                if (size - data < 176)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "the file ends inside the metadata of grid %u of the segment at byte %llu",
                                     (unsigned)i, (unsigned long long)pos);
                ns = rrv__nv_u32(b + data + 136);
                if (ns == 0 || ns > size - data - 176)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "grid %u of the segment at byte %llu has a name of %lu bytes, more than the file holds",
                                     (unsigned)i, (unsigned long long)pos, (unsigned long)ns);
                data += 176 + (uint64_t)ns;
            }
            for (i = 0; i < count; ++i) {
                uint32_t ns = rrv__nv_u32(b + meta + 136);
                uint64_t gs = rrv__nv_u64(b + meta), fs = rrv__nv_u64(b + meta + 8);
                const unsigned char *gname = b + meta + 176;
                if (fs != gs)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "grid %u of the segment at byte %llu has %llu bytes in the file but %llu in memory",
                                     (unsigned)i, (unsigned long long)pos, (unsigned long long)fs, (unsigned long long)gs);
                if (gs > size - data)
                    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "grid %u of the segment at byte %llu needs %llu bytes, the file has %llu left",
                                     (unsigned)i, (unsigned long long)pos, (unsigned long long)gs, (unsigned long long)(size - data));
                if (ns == wl + 1 && memcmp(gname, want, wl) == 0 && gname[wl] == '\0') {
                    *at = data;
                    *grid_size = gs;
                    return RRV_OK;
                }
                if (used + 1 < sizeof names)
                    used += (size_t)snprintf(names + used, sizeof names - used, "%s\"%.*s\"", used ? ", " : "",
                                             (int)(ns - 1 > 40 ? 40 : ns - 1), (const char *)gname);
                data += gs;
                meta += 176 + (uint64_t)ns;
            }
            pos = data;
            ++segments;
        }
    }
    if (used >= sizeof names) used = sizeof names - 1;
    for (; used > 0; --used)
        if ((unsigned char)names[used - 1] < 32) names[used - 1] = '?';
    return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "no grid named \"%.60s\" (the file has %s)", want,
                     names[0] ? names : "no grids");
}

/* Finds, copies (or, with `own`, moves within `file` and keeps) and checks
   the grid. On failure `file` is still the caller's to free. */
static rrv_result rrv__nv_load(unsigned char *file, size_t size, int own, const char *name, const char *want,
                               size_t max_bytes, rrv_nanovdb *g, rrv_error *err, int *kept)
{
    uint64_t at = 0, gs = 0;
    unsigned char *buf;
    rrv_result r;
    *kept = 0;
    memset(g, 0, sizeof *g);
    r = rrv__nv_find_grid(file, size, name, want, &at, &gs, err);
    if (r != RRV_OK) return r;
    if (gs > max_bytes)
        return rrv__fail(err, RRV_ERROR_LIMIT, name, 0,
                         "grid \"%.60s\" has %llu bytes, over the limit of %llu bytes (raise it with --max-grid-mb N)",
                         want, (unsigned long long)gs, (unsigned long long)max_bytes);
    r = rrv__nv_check_grid(file + at, gs, name, g, err);
    if (r != RRV_OK) return r;
    if (own) {
        memmove(file, file + at, (size_t)gs);
        buf = (unsigned char *)RRV_REALLOC(file, gs ? (size_t)gs : 1);
        if (!buf) buf = file; /* shrinking failed: keep the larger block */
        *kept = 1;
    } else {
        buf = (unsigned char *)RRV_MALLOC((size_t)gs);
        if (!buf) return rrv__fail(err, RRV_ERROR_MEMORY, name, 0, "out of memory for a grid of %llu bytes", (unsigned long long)gs);
        memcpy(buf, file + at, (size_t)gs);
    }
    g->buffer = buf;
    g->size = (size_t)gs;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_nanovdb_read_memory(const void *data, size_t size, const char *name,
                                           const char *grid_name, size_t max_grid_bytes,
                                           rrv_nanovdb *grid, rrv_error *err)
{
    int kept;
    rrv__clear_error(err);
    if (!name) name = "<memory>";
    if (!grid || !grid_name || (!data && size > 0))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, name, 0, "rrv_nanovdb_read_memory: NULL argument");
    if (max_grid_bytes == 0) max_grid_bytes = RRV_DEFAULT_MAX_GRID_BYTES;
    return rrv__nv_load((unsigned char *)(uintptr_t)data, size, 0, name, grid_name, max_grid_bytes, grid, err, &kept);
}

/* Errors name `name`; an unreadable file gives RRV_ERROR_IO with *why the
   reason in words, or "". The file may hold other grids too, so the limit
   applies to the file as read and then to the grid kept. */
static rrv_result rrv__nv_read_file(const char *path, const char *name, const char *grid_name,
                                    const rrv_load_options *opt, rrv_nanovdb *grid, rrv_error *err,
                                    const char **why)
{
    size_t max_bytes = opt && opt->max_grid_bytes ? opt->max_grid_bytes : RRV_DEFAULT_MAX_GRID_BYTES;
    void *data;
    size_t size;
    int kept;
    rrv_result r = rrv__sf_read_whole(opt, path, 0, max_bytes, &data, &size, why);
    memset(grid, 0, sizeof *grid);
    if (r == RRV_ERROR_LIMIT)
        return rrv__fail(err, r, name, 0, "the file is larger than the limit of %llu bytes (raise it with --max-grid-mb N)",
                         (unsigned long long)max_bytes);
    if (r == RRV_ERROR_MEMORY) return rrv__fail(err, r, name, 0, "out of memory reading the file");
    if (r == RRV_ERROR_UNSUPPORTED)
        return rrv__fail(err, r, name, 0, "this build has no stdio (RRV_NO_STDIO): set rrv_load_options.read_file");
    if (r != RRV_OK) return rrv__fail(err, r, name, 0, "cannot read the file%s%s", (*why)[0] ? ": " : "", *why);
    r = rrv__nv_load((unsigned char *)data, size, rrv__sf_whole_is_ours(opt), name, grid_name,
                     max_bytes, grid, err, &kept);
    if (!kept) rrv__sf_release_whole(opt, data);
    return r;
}

RRV_DEF rrv_result rrv_nanovdb_read(const char *path, const char *grid_name,
                                    const rrv_load_options *opt, rrv_nanovdb *grid, rrv_error *err)
{
    const char *why;
    rrv__clear_error(err);
    if (!path || !grid || !grid_name)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "rrv_nanovdb_read: NULL argument");
    return rrv__nv_read_file(path, path, grid_name, opt, grid, err, &why);
}

#else /* RRV_NO_NANOVDB */

RRV_DEF rrv_result rrv_nanovdb_read_memory(const void *data, size_t size, const char *name,
                                           const char *grid_name, size_t max_grid_bytes,
                                           rrv_nanovdb *grid, rrv_error *err)
{
    (void)data; (void)size; (void)grid_name; (void)max_grid_bytes;
    if (grid) memset(grid, 0, sizeof *grid);
    return rrv__left_out(err, name, "reading NanoVDB grids", "RRV_NO_NANOVDB", "");
}

#ifndef RRV_NO_SCENE_FILE
/* The parser's `nanovdb` statement meets the refusal here. */
static rrv_result rrv__nv_read_file(const char *path, const char *name, const char *grid_name,
                                    const rrv_load_options *opt, rrv_nanovdb *grid, rrv_error *err,
                                    const char **why)
{
    (void)path; (void)grid_name; (void)opt;
    *why = "";
    memset(grid, 0, sizeof *grid);
    return rrv__left_out(err, name, "reading NanoVDB grids", "RRV_NO_NANOVDB", "");
}
#endif

RRV_DEF rrv_result rrv_nanovdb_read(const char *path, const char *grid_name,
                                    const rrv_load_options *opt, rrv_nanovdb *grid, rrv_error *err)
{
    (void)grid_name; (void)opt;
    if (grid) memset(grid, 0, sizeof *grid);
    return rrv__left_out(err, path, "reading NanoVDB grids", "RRV_NO_NANOVDB", "");
}
#endif /* RRV_NO_NANOVDB */

RRV_DEF void rrv_nanovdb_cell_centered(rrv_nanovdb *grid)
{
    double o[3];
    int a;
    if (!grid) return;
    for (a = 0; a < 3; ++a) {
        o[a] = 0.5 * (grid->map[3 * a] + grid->map[3 * a + 1] + grid->map[3 * a + 2]);
        grid->translation[a] += o[a];
    }
    grid->lo = rrv__add(grid->lo, rrv__v3(o[0], o[1], o[2]));
    grid->hi = rrv__add(grid->hi, rrv__v3(o[0], o[1], o[2]));
}

RRV_DEF void rrv_nanovdb_free(rrv_nanovdb *grid)
{
    if (!grid) return;
    RRV_FREE(grid->buffer);
    grid->buffer = NULL;
    grid->size = 0;
}

/* >> 15 scene file (module): the .rrv parser, OBJ, gridvol =================
   This section owns rrv_scene_load, rrv_scene_parse, rrv_grid_read and
   rrv_grid_read_memory, and the OBJ loader behind `mesh file`. A statement
   builds through the defaults, checks and stores of >> 11. RRV_NO_SCENE_FILE
   leaves out all of this section but the refusals at its end. Every input
   here is untrusted: scene text is not NUL-terminated, every count is
   checked before it is multiplied or allocated, and every error names the
   file, the line and the cause. The grammar lives in parts/SCENE_SPEC.md
   and scenes/README.md. */
#ifndef RRV_NO_SCENE_FILE
#include <stdlib.h> /* strtod, also when RRV_MALLOC is the caller's */

#define RRV__SF_GRID_HEADER 48 /* magic 3, version 1, encoding 4, res 12, channels 4, box 24 */
#define RRV__SF_PATH_MAX 1024
/* Tokens quoted in messages are clipped so one garbage line cannot drown the
   useful part of the 256-byte message. */
#define RRV__SF_CLIP(t) (int)((t)->n > 60 ? 60 : (t)->n), (t)->p

/* ---- file reading --------------------------------------------------------- */

static size_t rrv__sf_max_bytes(const rrv_load_options *opt)
{
    return opt && opt->max_grid_bytes ? opt->max_grid_bytes : RRV_DEFAULT_MAX_GRID_BYTES;
}

/* The message for a file rrv__sf_read_whole could not read: `what` is
   "scene file" or "OBJ file \"x\"". */
static void rrv__sf_read_message(rrv_result r, const char *what, const char *why, size_t max_bytes,
                                 char *buf, size_t cap)
{
    if (r == RRV_ERROR_LIMIT)
        snprintf(buf, cap, "%s is larger than the limit of %llu bytes", what,
                 (unsigned long long)max_bytes);
    else if (r == RRV_ERROR_MEMORY)
        snprintf(buf, cap, "out of memory reading %s", what);
    else
        snprintf(buf, cap, "cannot read %s%s%s", what, why[0] ? ": " : "", why);
}

#define RRV__SF_NO_READER_MESSAGE                                                                  \
    "this build has no stdio (RRV_NO_STDIO): set rrv_load_options.read_file"

/* Joins a path written in a scene onto the scene's folder. 0 if too long. */
static int rrv__sf_join_path(const char *base_dir, const char *path, char *out, size_t cap)
{
    size_t nb = base_dir ? strlen(base_dir) : 0, np = strlen(path);
    /* "C:x" and "\\x" are absolute only on Windows; elsewhere they are
       ordinary relative names. */
#ifdef _WIN32
    int absolute = path[0] == '/' || path[0] == '\\' ||
                   (((path[0] | 32) >= 'a' && (path[0] | 32) <= 'z') && path[1] == ':');
#else
    int absolute = path[0] == '/';
#endif
    if (absolute || nb == 0) {
        if (np >= cap) return 0;
        memcpy(out, path, np + 1);
        return 1;
    }
    {
#ifdef _WIN32
        int sep = base_dir[nb - 1] != '/' && base_dir[nb - 1] != '\\';
#else
        int sep = base_dir[nb - 1] != '/';
#endif
        if (nb + (size_t)sep + np >= cap) return 0;
        memcpy(out, base_dir, nb);
        if (sep) out[nb] = '/';
        memcpy(out + nb + (size_t)sep, path, np + 1);
    }
    return 1;
}

/* ---- gridvol ---------------------------------------------------------------- */

typedef struct rrv__sf_grid_header {
    int nx, ny, nz, channels;
    rrv_vec3 lo, hi;
    size_t count; /* floats */
} rrv__sf_grid_header;

static uint32_t rrv__sf_le32(const unsigned char *b)
{
    return (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) | ((uint32_t)b[3] << 24);
}

static int32_t rrv__sf_le32s(const unsigned char *b)
{
    uint32_t u = rrv__sf_le32(b);
    /* two's complement without implementation-defined conversion */
    return u <= 0x7fffffffu ? (int32_t)u : (int32_t)(u - 0x80000000u) - 0x7fffffff - 1;
}

static float rrv__sf_bits_float(uint32_t u)
{
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Classifies by bit pattern, so it stays right under -ffast-math. */
static int rrv__sf_bits_finite(uint32_t u) { return (u & 0x7f800000u) != 0x7f800000u; }
static int rrv__sf_bits_nan(uint32_t u)
{
    return !rrv__sf_bits_finite(u) && (u & 0x007fffffu) != 0;
}

/* Validates the 48-byte header against the whole file size `total`; `avail`
   header bytes are readable. Errors name `name`, line 0. */
static rrv_result rrv__sf_grid_parse_header(const unsigned char *h, size_t avail,
                                            unsigned long long total, const char *name,
                                            size_t max_bytes, rrv__sf_grid_header *out,
                                            rrv_error *err)
{
    static const char axis[3] = {'x', 'y', 'z'};
    int32_t version, encoding, res[3], channels;
    float box[6];
    unsigned long long count, bytes, have;
    int i;
    if (max_bytes == 0) max_bytes = RRV_DEFAULT_MAX_GRID_BYTES;
    if (avail < 3 || h[0] != 'V' || h[1] != 'O' || h[2] != 'L')
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "not a gridvol file: it does not start with \"VOL\"");
    if (avail < RRV__SF_GRID_HEADER)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "truncated header: the file has %llu bytes, the header needs %d", total,
                         RRV__SF_GRID_HEADER);
    version = h[3];
    if (version != 3)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "unsupported gridvol version %d (expected 3)", (int)version);
    encoding = rrv__sf_le32s(h + 4);
    if (encoding != 1)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "unsupported encoding %ld (only 1 = float32 is supported)",
                         (long)encoding);
    for (i = 0; i < 3; ++i)
        res[i] = rrv__sf_le32s(h + 8 + 4 * i);
    for (i = 0; i < 3; ++i)
        if (res[i] < 2)
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                             "resolution %ld x %ld x %ld: %cres is %ld, must be >= 2", (long)res[0],
                             (long)res[1], (long)res[2], axis[i], (long)res[i]);
    channels = rrv__sf_le32s(h + 20);
    if (channels != 1 && channels != 3)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "%ld channels: expected 1 or 3",
                         (long)channels);
    for (i = 0; i < 6; ++i) {
        uint32_t u = rrv__sf_le32(h + 24 + 4 * i);
        if (!rrv__sf_bits_finite(u))
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                             "bounding box is not finite (%c%s is %s)", axis[i % 3],
                             i < 3 ? "min" : "max", rrv__sf_bits_nan(u) ? "NaN" : "infinite");
        box[i] = rrv__sf_bits_float(u);
    }
    for (i = 0; i < 3; ++i)
        if (!(box[i] < box[i + 3]))
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                             "bounding box is empty: %cmin %g is not below %cmax %g", axis[i],
                             (double)box[i], axis[i], (double)box[i + 3]);
    /* Each factor is < 2^31, so checking before every multiplication keeps
       the product exact in 64 bits or reports the overflow. */
    count = (unsigned long long)res[0];
    if ((unsigned long long)res[1] > ULLONG_MAX / count) goto overflow;
    count *= (unsigned long long)res[1];
    if ((unsigned long long)res[2] > ULLONG_MAX / count) goto overflow;
    count *= (unsigned long long)res[2];
    if ((unsigned long long)channels > ULLONG_MAX / count) goto overflow;
    count *= (unsigned long long)channels;
    if (count > ULLONG_MAX / 4 || count > (unsigned long long)SIZE_MAX / 4) goto overflow;
    bytes = count * 4;
    if (bytes > (unsigned long long)max_bytes)
        return rrv__fail(err, RRV_ERROR_LIMIT, name, 0,
                         "%ld x %ld x %ld x %ld samples need %llu bytes, over the limit of "
                         "%llu bytes (raise it with --max-grid-mb N)",
                         (long)res[0], (long)res[1], (long)res[2], (long)channels, bytes,
                         (unsigned long long)max_bytes);
    have = total - RRV__SF_GRID_HEADER;
    if (have != bytes)
        return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                         "expected %llu bytes of samples, found %llu", bytes, have);
    out->nx = (int)res[0];
    out->ny = (int)res[1];
    out->nz = (int)res[2];
    out->channels = (int)channels;
    out->lo.x = box[0];
    out->lo.y = box[1];
    out->lo.z = box[2];
    out->hi.x = box[3];
    out->hi.y = box[4];
    out->hi.z = box[5];
    out->count = (size_t)count;
    return RRV_OK;
overflow:
    return rrv__fail(err, RRV_ERROR_LIMIT, name, 0,
                     "%ld x %ld x %ld x %ld samples: the byte count overflows", (long)res[0],
                     (long)res[1], (long)res[2], (long)channels);
}

/* Decodes `n` floats that start at sample index `first`, validating each. */
static rrv_result rrv__sf_grid_decode(const unsigned char *b, size_t n, size_t first,
                                      const rrv__sf_grid_header *h, int nonnegative, float *out,
                                      const char *name, rrv_error *err)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        uint32_t u = rrv__sf_le32(b + 4 * i);
        float v = rrv__sf_bits_float(u);
        const char *what = NULL;
        if (!rrv__sf_bits_finite(u))
            what = rrv__sf_bits_nan(u) ? "is NaN" : "is infinite";
        else if (nonnegative && v < 0.0f)
            what = "is negative";
        if (what) {
            size_t idx = first + i, s = idx / (size_t)h->channels;
            int c = (int)(idx % (size_t)h->channels);
            int x = (int)(s % (size_t)h->nx), y = (int)(s / (size_t)h->nx % (size_t)h->ny);
            int z = (int)(s / (size_t)h->nx / (size_t)h->ny);
            char where[64];
            if (h->channels > 1)
                sprintf(where, "x=%d y=%d z=%d c=%d", x, y, z, c);
            else
                sprintf(where, "x=%d y=%d z=%d", x, y, z);
            if (rrv__sf_bits_finite(u))
                return rrv__fail(err, RRV_ERROR_FORMAT, name, 0,
                                 "value %llu (%s) %s (%g), densities must be >= 0",
                                 (unsigned long long)idx, where, what, (double)v);
            return rrv__fail(err, RRV_ERROR_FORMAT, name, 0, "value %llu (%s) %s",
                             (unsigned long long)idx, where, what);
        }
        out[first + i] = v;
    }
    return RRV_OK;
}

static void rrv__sf_grid_fill(rrv_grid *grid, const rrv__sf_grid_header *h, float *data)
{
    grid->nx = h->nx;
    grid->ny = h->ny;
    grid->nz = h->nz;
    grid->channels = h->channels;
    grid->lo = h->lo;
    grid->hi = h->hi;
    grid->data = data;
}

RRV_DEF rrv_result rrv_grid_read_memory(const void *data, size_t size, const char *name,
                                        size_t max_grid_bytes, int nonnegative, rrv_grid *grid,
                                        rrv_error *err)
{
    const unsigned char *b = (const unsigned char *)data;
    rrv__sf_grid_header h;
    float *samples;
    rrv_result r;
    rrv__clear_error(err);
    memset(&h, 0, sizeof h);
    if (!name) name = "<memory>";
    if (!grid || (!data && size > 0))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, name, 0, "rrv_grid_read_memory: NULL argument");
    memset(grid, 0, sizeof *grid);
    r = rrv__sf_grid_parse_header(b, size, (unsigned long long)size, name, max_grid_bytes, &h, err);
    if (r != RRV_OK) return r;
    samples = (float *)RRV_MALLOC(h.count * sizeof(float));
    if (!samples)
        return rrv__fail(err, RRV_ERROR_MEMORY, name, 0, "out of memory for %llu grid samples",
                         (unsigned long long)h.count);
    r = rrv__sf_grid_decode(b + RRV__SF_GRID_HEADER, h.count, 0, &h, nonnegative, samples, name,
                            err);
    if (r != RRV_OK) {
        RRV_FREE(samples);
        return r;
    }
    rrv__sf_grid_fill(grid, &h, samples);
    return RRV_OK;
}

#ifndef RRV_NO_STDIO
static int rrv__sf_stdio_size(FILE *f, unsigned long long *size)
{
    long len;
    if (fseek(f, 0, SEEK_END) != 0) return 0;
    len = ftell(f);
    if (len < 0 || fseek(f, 0, SEEK_SET) != 0) return 0;
    *size = (unsigned long long)len;
    return 1;
}

/* Streams the samples so a grid never sits in memory twice, and reads the
   header first so the size limit applies before anything large is allocated. */
static rrv_result rrv__sf_grid_read_stdio(const char *path, const char *name, size_t max_bytes,
                                          int nonnegative, rrv_grid *grid, rrv_error *err,
                                          const char **why)
{
    unsigned char buf[16384];
    unsigned long long total = 0;
    size_t got, done = 0;
    rrv__sf_grid_header h;
    float *samples;
    rrv_result r;
    FILE *f;
    int sized;
    uint64_t file_size;
    f = rrv__open_read(path, &file_size, why);
    if (!f) return rrv__fail(err, RRV_ERROR_IO, name, 0, "cannot read the file%s%s", (*why)[0] ? ": " : "", *why);
    /* The header is read before the size is asked for: a folder opens and
       may claim any size, and only a read says what it is. */
    errno = 0;
    got = fread(buf, 1, RRV__SF_GRID_HEADER, f);
    if (got < RRV__SF_GRID_HEADER && ferror(f)) {
        *why = rrv__io_reason(errno);
        fclose(f);
        return rrv__fail(err, RRV_ERROR_IO, name, 0, "cannot read the file%s%s", (*why)[0] ? ": " : "", *why);
    }
    total = file_size;
    sized = file_size != UINT64_MAX || (rrv__sf_stdio_size(f, &total) && fseek(f, (long)got, SEEK_SET) == 0);
    if (!sized) {
        fclose(f);
        return rrv__fail(err, RRV_ERROR_IO, name, 0, "cannot read the file: cannot tell its size");
    }
    r = rrv__sf_grid_parse_header(buf, got, total, name, max_bytes, &h, err);
    if (r != RRV_OK) {
        fclose(f);
        return r;
    }
    samples = (float *)RRV_MALLOC(h.count * sizeof(float));
    if (!samples) {
        fclose(f);
        return rrv__fail(err, RRV_ERROR_MEMORY, name, 0, "out of memory for %llu grid samples",
                         (unsigned long long)h.count);
    }
    while (done < h.count) {
        size_t want = h.count - done;
        if (want > sizeof buf / 4) want = sizeof buf / 4;
        if (fread(buf, 4, want, f) != want) {
            RRV_FREE(samples);
            fclose(f);
            return rrv__fail(err, RRV_ERROR_IO, name, 0, "the file ended while reading samples");
        }
        r = rrv__sf_grid_decode(buf, want, done, &h, nonnegative, samples, name, err);
        if (r != RRV_OK) {
            RRV_FREE(samples);
            fclose(f);
            return r;
        }
        done += want;
    }
    fclose(f);
    rrv__sf_grid_fill(grid, &h, samples);
    return RRV_OK;
}
#endif

/* Errors name `name`, line 0. An unreadable file gives RRV_ERROR_IO and
   *why the reason in words, or "". */
static rrv_result rrv__sf_grid_load(const char *path, const char *name, const rrv_load_options *opt,
                                    int nonnegative, rrv_grid *grid, rrv_error *err,
                                    const char **why)
{
    size_t max_bytes = rrv__sf_max_bytes(opt);
    memset(grid, 0, sizeof *grid);
    *why = "";
    if (opt && opt->read_file) {
        void *data;
        size_t size;
        rrv_result r = rrv__sf_read_whole(opt, path, 0, SIZE_MAX, &data, &size, why);
        if (r != RRV_OK)
            return rrv__fail(err, r, name, 0, "cannot read the file%s%s", (*why)[0] ? ": " : "", *why);
        r = rrv_grid_read_memory(data, size, name, max_bytes, nonnegative, grid, err);
        rrv__sf_release_whole(opt, data);
        return r;
    }
#ifndef RRV_NO_STDIO
    if (opt && opt->on_input) opt->on_input(opt->on_input_user, path);
    return rrv__sf_grid_read_stdio(path, name, max_bytes, nonnegative, grid, err, why);
#else
    return rrv__fail(err, RRV_ERROR_UNSUPPORTED, name, 0, RRV__SF_NO_READER_MESSAGE);
#endif
}

RRV_DEF rrv_result rrv_grid_read(const char *path, const rrv_load_options *opt, int nonnegative,
                                 rrv_grid *grid, rrv_error *err)
{
    const char *why;
    rrv__clear_error(err);
    if (!path || !grid)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "rrv_grid_read: NULL argument");
    return rrv__sf_grid_load(path, path, opt, nonnegative, grid, err, &why);
}

/* ---- tokens ------------------------------------------------------------------ */

typedef struct rrv__sf_tok {
    const char *p;
    size_t n;
    int quoted;
} rrv__sf_tok;

typedef struct rrv__sf_toks {
    rrv__sf_tok *v;
    size_t n, cap;
} rrv__sf_toks;

static int rrv__sf_is_space(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/* Splits [s, e) into tokens. `#` ends the line outside quotes. Returns 0,
   1 for an unterminated quote, 2 when out of memory. */
static int rrv__sf_tokenize(rrv__sf_toks *t, const char *s, const char *e, int quotes)
{
    t->n = 0;
    for (;;) {
        rrv__sf_tok tok;
        while (s < e && rrv__sf_is_space(*s))
            ++s;
        if (s == e || *s == '#') return 0;
        tok.quoted = quotes && *s == '"';
        if (tok.quoted) {
            const char *q = ++s;
            while (q < e && *q != '"')
                ++q;
            if (q == e) return 1;
            tok.p = s;
            tok.n = (size_t)(q - s);
            s = q + 1;
        } else {
            tok.p = s;
            while (s < e && !rrv__sf_is_space(*s) && *s != '#')
                ++s;
            tok.n = (size_t)(s - tok.p);
        }
        if (t->n == t->cap) {
            size_t cap = t->cap ? t->cap * 2 : 32;
            rrv__sf_tok *v;
            if (cap > SIZE_MAX / sizeof *v) return 2;
            v = (rrv__sf_tok *)RRV_REALLOC(t->v, cap * sizeof *v);
            if (!v) return 2;
            t->v = v;
            t->cap = cap;
        }
        t->v[t->n++] = tok;
    }
}

/* Scene and OBJ files are text: a NUL or another control byte would be
   hidden or garbled in every message that quotes its token (a NUL ends
   "%.*s", so "1\0" would be shown as the number 1). Writes a message for the
   first one in [s, e) and returns 1, or returns 0. */
static int rrv__sf_control_byte(const char *s, const char *e, char *msg, size_t cap)
{
    const char *c;
    for (c = s; c < e; ++c) {
        unsigned char b = (unsigned char)*c;
        if (b >= 32 || b == '\t' || b == '\r' || b == '\v' || b == '\f') continue;
        if (b == 0)
            snprintf(msg, cap, "NUL byte in column %d: not a text file", (int)(c - s) + 1);
        else
            snprintf(msg, cap, "control character 0x%02X in column %d", b, (int)(c - s) + 1);
        return 1;
    }
    return 0;
}

static int rrv__sf_tok_is(const rrv__sf_tok *t, const char *s)
{
    size_t n = strlen(s);
    return !t->quoted && t->n == n && memcmp(t->p, s, n) == 0;
}

static int rrv__sf_tok_equals_name(const rrv__sf_tok *t, const char *name)
{
    size_t n = strlen(name);
    return t->n == n && memcmp(t->p, name, n) == 0;
}

/* 1 when the whole token is a decimal number: [+-] digits [. digits]
   [e [+-] digits], or inf, infinity or nan (the caller rejects those with a
   clearer message). strtod alone would also take hexadecimal ("0x1p3") and
   follow the host's LC_NUMERIC, so a host program in a decimal-comma locale
   could not load a scene: the syntax is checked here, and strtod then sees
   the number with the locale's own decimal point, which gives the correctly
   rounded value whatever the locale (as long as no other thread changes the
   locale meanwhile, which would race in strtod anyway). */
static int rrv__sf_tok_number(const rrv__sf_tok *t, double *v)
{
    char buf[128], probe[16], *end;
    const char *q = t->p, *stop = t->p + t->n, *point;
    size_t o = 0, point_len;
    int negative = 0, mantissa_digits = 0;
    if (t->quoted || t->n == 0 || t->n > 100) return 0;
    if (*q == '+' || *q == '-') negative = *q++ == '-';
    {
        size_t rest = (size_t)(stop - q), k;
        static const char *const words[] = {"inf", "infinity", "nan"};
        for (k = 0; k < 3; ++k) {
            size_t n = strlen(words[k]), i;
            if (rest != n) continue;
            for (i = 0; i < n && (q[i] | 32) == words[k][i]; ++i) {}
            if (i == n) {
                *v = k < 2 ? (negative ? -HUGE_VAL : HUGE_VAL) : (double)NAN;
                return 1;
            }
        }
    }
    {
        /* The locale's decimal point as printf writes it: unlike localeconv,
           snprintf is safe to call from several threads at once. */
        int n = snprintf(probe, sizeof probe, "%.1f", 1.5);
        if (n >= 3 && n - 2 <= 8 && probe[0] == '1' && probe[n - 1] == '5') {
            point = probe + 1;
            point_len = (size_t)n - 2;
        } else { /* a locale we cannot read: C's point */
            point = ".";
            point_len = 1;
        }
    }
    if (negative) buf[o++] = '-';
    for (; q < stop && *q >= '0' && *q <= '9'; ++q, ++mantissa_digits) buf[o++] = *q;
    if (q < stop && *q == '.') {
        memcpy(buf + o, point, point_len);
        o += point_len;
        for (++q; q < stop && *q >= '0' && *q <= '9'; ++q, ++mantissa_digits) buf[o++] = *q;
    }
    if (mantissa_digits == 0) return 0;
    if (q < stop && (*q == 'e' || *q == 'E')) {
        int exponent_digits = 0;
        buf[o++] = *q++;
        if (q < stop && (*q == '+' || *q == '-')) buf[o++] = *q++;
        for (; q < stop && *q >= '0' && *q <= '9'; ++q, ++exponent_digits) buf[o++] = *q;
        if (exponent_digits == 0) return 0;
    }
    if (q != stop) return 0;
    buf[o] = '\0';
    *v = strtod(buf, &end);
    return end == buf + o;
}

/* Decimal integer with optional sign. 0 if not one; *overflow when the
   magnitude does not fit 64 bits. */
static int rrv__sf_tok_integer(const rrv__sf_tok *t, int *neg, uint64_t *mag, int *overflow)
{
    size_t i = 0;
    *neg = 0;
    *mag = 0;
    *overflow = 0;
    if (t->quoted || t->n == 0) return 0;
    if (t->p[0] == '+' || t->p[0] == '-') {
        *neg = t->p[0] == '-';
        i = 1;
    }
    if (i == t->n) return 0;
    for (; i < t->n; ++i) {
        unsigned d = (unsigned)(unsigned char)t->p[i] - '0';
        if (d > 9) return 0;
        if (*mag > (UINT64_MAX - d) / 10)
            *overflow = 1;
        else
            *mag = *mag * 10 + d;
    }
    return 1;
}

/* ---- parser state and errors ------------------------------------------------- */

typedef struct rrv__sf_parser {
    rrv_scene *scene;
    const char *name; /* scene name for messages */
    const char *base_dir; /* NULL: the current directory */
    const rrv_load_options *opt;
    rrv_error *err;
    int line;
    rrv__sf_toks toks;
    int have_camera, have_render, have_environment, have_ambient;
    rrv_field *blob_field; /* so later blob statements of one field can be told apart */
} rrv__sf_parser;

static rrv_result rrv__sf_perr(rrv__sf_parser *p, rrv_result code, const char *fmt, ...)
{
    char buf[256];
    va_list args;
    va_start(args, fmt);
    vsnprintf(buf, sizeof buf, fmt, args);
    va_end(args);
    return rrv__fail(p->err, code, p->name, p->line, "%s", buf);
}

#define RRV__SF_OOM(p) rrv__sf_perr((p), RRV_ERROR_MEMORY, "out of memory")

/* "did you mean": the candidate nearest a misspelt word, by optimal string
   alignment (Levenshtein plus a swap of neighbours, the commonest typo).
   Only within two edits and fewer than half the longer word's length, so a
   short word does not match everything; ties go to the first candidate
   tried, which is table order. Words over 32 bytes are no typo of a name. */
#define RRV__SF_NEAR_MAX 32
typedef struct rrv__sf_near {
    const rrv__sf_tok *word;
    const char *best;
    size_t best_n;
    int d;
} rrv__sf_near;

static int rrv__sf_edit_distance(const char *a, size_t an, const char *b, size_t bn)
{
    int d[RRV__SF_NEAR_MAX + 1][RRV__SF_NEAR_MAX + 1];
    size_t i, j;
    if (an > RRV__SF_NEAR_MAX || bn > RRV__SF_NEAR_MAX) return INT_MAX;
    for (i = 0; i <= an; ++i) d[i][0] = (int)i;
    for (j = 0; j <= bn; ++j) d[0][j] = (int)j;
    for (i = 1; i <= an; ++i)
        for (j = 1; j <= bn; ++j) {
            int best = d[i - 1][j - 1] + (a[i - 1] != b[j - 1]);
            if (d[i - 1][j] + 1 < best) best = d[i - 1][j] + 1;
            if (d[i][j - 1] + 1 < best) best = d[i][j - 1] + 1;
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] && d[i - 2][j - 2] + 1 < best)
                best = d[i - 2][j - 2] + 1;
            d[i][j] = best;
        }
    return d[an][bn];
}

/* A distance of 0 is a quoted keyword: no hint, the quotes are the problem. */
static void rrv__sf_near_try(rrv__sf_near *nr, const char *c, size_t cn)
{
    size_t longer = cn > nr->word->n ? cn : nr->word->n;
    int d = rrv__sf_edit_distance(nr->word->p, nr->word->n, c, cn);
    if (d >= 1 && d <= 2 && (size_t)(2 * d) < longer && (!nr->best || d < nr->d)) {
        nr->best = c;
        nr->best_n = cn;
        nr->d = d;
    }
}

/* The hint to append to a message ("" without one); buf holds >= 64 bytes. */
static const char *rrv__sf_near_hint(const rrv__sf_near *nr, char *buf, size_t size)
{
    if (!nr->best) return "";
    snprintf(buf, size, " (did you mean \"%.*s\"?)", (int)nr->best_n, nr->best);
    return buf;
}

/* The hint for a word among the names of a key table. */
static const char *rrv__sf_near_key(const rrv__sf_tok *t, const rrv__sf_key *keys, int nkeys, char *buf,
                                    size_t size)
{
    rrv__sf_near nr;
    int k;
    memset(&nr, 0, sizeof nr);
    nr.word = t;
    for (k = 0; k < nkeys; ++k)
        rrv__sf_near_try(&nr, keys[k].name, strlen(keys[k].name));
    return rrv__sf_near_hint(&nr, buf, size);
}

/* The hint for a word among "a|b|c" choices, or "a, b or c" kind lists. */
static const char *rrv__sf_near_list(const rrv__sf_tok *t, const char *list, char *buf, size_t size)
{
    rrv__sf_near nr;
    memset(&nr, 0, sizeof nr);
    nr.word = t;
    while (*list) {
        size_t len = strcspn(list, "|, ");
        if (len && !(len == 2 && memcmp(list, "or", 2) == 0)) rrv__sf_near_try(&nr, list, len);
        list += len + (list[len] != '\0');
    }
    return rrv__sf_near_hint(&nr, buf, size);
}

static int rrv__sf_find_key(const rrv__sf_key *keys, int nkeys, const rrv__sf_tok *t)
{
    int k;
    for (k = 0; k < nkeys; ++k)
        if (rrv__sf_tok_is(t, keys[k].name)) return k;
    return -1;
}

static rrv_result rrv__sf_range_error(rrv__sf_parser *p, const char *stmt, const rrv__sf_key *k,
                                      const rrv__sf_tok *t)
{
    char range[96];
    rrv__sf_range_text(k, range, sizeof range);
    return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: %s must be %s, got %.*s", stmt, k->name, range,
                        RRV__SF_CLIP(t));
}

/* Parses one numeric value of key k from token t (already known to be a number). */
static rrv_result rrv__sf_value(rrv__sf_parser *p, const char *stmt, const rrv__sf_key *k,
                                const rrv__sf_tok *t, double *v, uint64_t *u)
{
    if (k->kind == RRV__SF_NUM || k->kind == RRV__SF_NUMLIST) {
        rrv__sf_tok_number(t, v);
        if (!(*v == *v) || *v > DBL_MAX || *v < -DBL_MAX)
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: %s must be finite, got %.*s", stmt,
                                k->name, RRV__SF_CLIP(t));
    } else {
        int neg, overflow;
        uint64_t mag;
        if (!rrv__sf_tok_integer(t, &neg, &mag, &overflow))
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: %s must be an integer, got %.*s", stmt,
                                k->name, RRV__SF_CLIP(t));
        if (k->kind == RRV__SF_U64) {
            if (overflow || (neg && mag != 0))
                return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                    "%s: %s must be in [0, 18446744073709551615], got %.*s", stmt,
                                    k->name, RRV__SF_CLIP(t));
            *u = mag;
            *v = (double)mag;
            return RRV_OK;
        }
        *v = overflow ? (neg ? -DBL_MAX : DBL_MAX) : (neg ? -(double)mag : (double)mag);
    }
    if (!rrv__sf_in_range(k, *v)) return rrv__sf_range_error(p, stmt, k, t);
    return RRV_OK;
}

/* Reads `key value... key value...` from token `first` on against a key
   table, checks counts, numbers, ranges, duplicates and required keys. */
static rrv_result rrv__sf_parse_keys(rrv__sf_parser *p, const char *stmt, size_t first,
                                     const rrv__sf_key *keys, int nkeys, rrv__sf_slot *slots)
{
    const rrv__sf_tok *toks = p->toks.v;
    size_t i = first, n = p->toks.n;
    int prev = -1, k;
    rrv_result r;
    memset(slots, 0, (size_t)nkeys * sizeof *slots);
    while (i < n) {
        const rrv__sf_tok *t = &toks[i];
        double dummy;
        k = rrv__sf_find_key(keys, nkeys, t);
        if (k < 0) {
            /* a number where a key should be: the previous key got too many */
            if (prev >= 0 &&
                (keys[prev].kind == RRV__SF_NUM || keys[prev].kind == RRV__SF_INT ||
                 keys[prev].kind == RRV__SF_U64) &&
                rrv__sf_tok_number(t, &dummy)) {
                size_t extra = 0;
                while (i + extra < n && rrv__sf_tok_number(&toks[i + extra], &dummy))
                    ++extra;
                return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: \"%s\" needs %d number%s, got %llu",
                                    stmt, keys[prev].name, keys[prev].arity,
                                    keys[prev].arity == 1 ? "" : "s",
                                    (unsigned long long)(keys[prev].arity + extra));
            }
            {
                char hint[96];
                return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: unknown key \"%.*s\"%s", stmt, RRV__SF_CLIP(t),
                                    rrv__sf_near_key(t, keys, nkeys, hint, sizeof hint));
            }
        }
        if (slots[k].given)
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: \"%s\" given twice", stmt, keys[k].name);
        slots[k].given = 1;
        slots[k].tok = ++i;
        switch (keys[k].kind) {
        case RRV__SF_NUM:
        case RRV__SF_INT:
        case RRV__SF_U64: {
            int a;
            for (a = 0; a < keys[k].arity; ++a, ++i) {
                if (i >= n || !rrv__sf_tok_number(&toks[i], &dummy)) {
                    if (i >= n || rrv__sf_find_key(keys, nkeys, &toks[i]) >= 0)
                        return rrv__sf_perr(
                            p, RRV_ERROR_PARSE, "%s: \"%s\" needs %d number%s, got %d", stmt,
                            keys[k].name, keys[k].arity, keys[k].arity == 1 ? "" : "s", a);
                    return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                        "%s: expected a number for \"%s\", got \"%.*s\"", stmt,
                                        keys[k].name, RRV__SF_CLIP(&toks[i]));
                }
                r = rrv__sf_value(p, stmt, &keys[k], &toks[i], &slots[k].v[a], &slots[k].u);
                if (r != RRV_OK) return r;
            }
            break;
        }
        case RRV__SF_WORD:
        case RRV__SF_CHOICE:
            if (i >= n)
                return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: \"%s\" needs a value", stmt,
                                    keys[k].name);
            if (keys[k].kind == RRV__SF_CHOICE) {
                const char *c = keys[k].choices;
                int index = 0, found = -1;
                while (*c) {
                    size_t len = strcspn(c, "|");
                    if (!toks[i].quoted && toks[i].n == len && memcmp(toks[i].p, c, len) == 0)
                        found = index;
                    c += len + (c[len] == '|');
                    ++index;
                }
                if (found < 0) {
                    char hint[96];
                    return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: %s must be one of %s, got \"%.*s\"%s", stmt,
                                        keys[k].name, keys[k].choices, RRV__SF_CLIP(&toks[i]),
                                        rrv__sf_near_list(&toks[i], keys[k].choices, hint, sizeof hint));
                }
                slots[k].choice = found;
            }
            ++i;
            break;
        default: /* lists */
            while (i < n && rrv__sf_tok_number(&toks[i], &dummy)) {
                r = rrv__sf_value(p, stmt, &keys[k], &toks[i], &dummy, &slots[k].u);
                if (r != RRV_OK) return r;
                ++i;
                ++slots[k].count;
            }
            if (i < n && slots[k].count == 0 && rrv__sf_find_key(keys, nkeys, &toks[i]) < 0)
                return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                    "%s: expected a number for \"%s\", got \"%.*s\"", stmt,
                                    keys[k].name, RRV__SF_CLIP(&toks[i]));
            break;
        }
        prev = k;
    }
    for (k = 0; k < nkeys; ++k)
        if ((keys[k].flags & RRV__SF_REQ) && !slots[k].given)
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: missing \"%s\"", stmt, keys[k].name);
    return RRV_OK;
}

static rrv_vec3 rrv__sf_slot_vec(const rrv__sf_slot *s, int at)
{
    rrv_vec3 v;
    v.x = s->v[at];
    v.y = s->v[at + 1];
    v.z = s->v[at + 2];
    return v;
}

static void rrv__sf_slot_rgb(const rrv__sf_slot *s, double *rgb)
{
    if (s->given) memcpy(rgb, s->v, 3 * sizeof(double));
}

/* Copies a name or path token into a C string; 0 if it does not fit or
   holds a control character. */
static int rrv__sf_tok_string(const rrv__sf_tok *t, char *out, size_t cap)
{
    size_t i;
    if (t->n >= cap) return 0;
    for (i = 0; i < t->n; ++i)
        if ((unsigned char)t->p[i] < 32) return 0;
    memcpy(out, t->p, t->n);
    out[t->n] = '\0';
    return 1;
}

/* ---- materials and shapes ------------------------------------------------------ */

static int rrv__sf_find_material(const rrv_scene *s, const rrv__sf_tok *t)
{
    int i;
    for (i = 0; i < s->material_count; ++i)
        if (rrv__sf_tok_equals_name(t, s->materials[i].name)) return i;
    return -1;
}

static int rrv__sf_find_medium(const rrv_scene *s, const rrv__sf_tok *t)
{
    int i;
    for (i = 0; i < s->medium_count; ++i)
        if (rrv__sf_tok_equals_name(t, s->media[i].name)) return i;
    return -1;
}

/* The hint for an undefined name among the materials (or media) defined so
   far: a misspelt name is the likely mistake, a name defined further down
   the file the other (the message's "not defined" covers that). */
static const char *rrv__sf_near_defined(const rrv_scene *s, const rrv__sf_tok *t, int media, char *buf, size_t size)
{
    rrv__sf_near nr;
    int i, n = media ? s->medium_count : s->material_count;
    memset(&nr, 0, sizeof nr);
    nr.word = t;
    for (i = 0; i < n; ++i) {
        const char *name = media ? s->media[i].name : s->materials[i].name;
        rrv__sf_near_try(&nr, name, strlen(name));
    }
    return rrv__sf_near_hint(&nr, buf, size);
}

/* Checks of the store name the statement and its line. */
static void rrv__sf_ck(rrv__sf_parser *p, rrv__ck *ck, const char *what)
{
    rrv__ck_init(ck, p->err, p->name, p->line, RRV_ERROR_PARSE, "%s", what);
}

/* The material a shape names, or the implicit grey "default". */
static rrv_result rrv__sf_shape_material(rrv__sf_parser *p, const char *stmt,
                                         const rrv__sf_slot *slot, int *index)
{
    rrv__ck ck;
    if (slot->given) {
        const rrv__sf_tok *t = &p->toks.v[slot->tok];
        *index = rrv__sf_find_material(p->scene, t);
        if (*index >= 0) return RRV_OK;
        if (!rrv__sf_tok_equals_name(t, "default")) {
            char hint[96];
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: material \"%.*s\" is not defined%s", stmt,
                                RRV__SF_CLIP(t), rrv__sf_near_defined(p->scene, t, 0, hint, sizeof hint));
        }
    }
    rrv__sf_ck(p, &ck, stmt);
    return rrv__default_material(&ck, p->scene, index);
}

/* Emission is stored premultiplied by its scale. */
static void rrv__sf_emission(const rrv__sf_slot *L, const rrv__sf_slot *scale, double *out)
{
    double k = scale && scale->given ? scale->v[0] : 1.0;
    int c;
    for (c = 0; c < 3; ++c)
        out[c] = L->given ? L->v[c] * k : 0.0;
}

static rrv_vec3 rrv__sf_transform(rrv_vec3 v, double scale, rrv_vec3 t)
{
    return rrv__add(rrv__scale(v, scale), t);
}

/* ---- OBJ ------------------------------------------------------------------------ */

typedef struct rrv__sf_objv {
    rrv_vec3 *v;
    int n, cap;
} rrv__sf_objv;

/* Resolves one face corner ("7", "-1", "7/2", "7//3", "7/2/3") to a 0-based
   vertex index. 0 = ok, 1 = not an index, 2 = out of range. */
static int rrv__sf_obj_index(const rrv__sf_tok *t, int nverts, int *out, long long *raw)
{
    rrv__sf_tok head = *t;
    int neg, overflow;
    uint64_t mag;
    const char *slash = (const char *)memchr(t->p, '/', t->n);
    if (slash) head.n = (size_t)(slash - t->p);
    head.quoted = 0;
    if (!rrv__sf_tok_integer(&head, &neg, &mag, &overflow)) return 1;
    *raw = overflow || mag > (uint64_t)LLONG_MAX ? (neg ? LLONG_MIN : LLONG_MAX)
                                                 : (neg ? -(long long)mag : (long long)mag);
    if (overflow || mag == 0 || mag > (uint64_t)nverts) return 2;
    *out = neg ? nverts - (int)mag : (int)mag - 1;
    return 0;
}

static rrv_result rrv__sf_obj_parse(rrv__sf_parser *p, const char *text, size_t size,
                                    const char *file, double scale, rrv_vec3 translate,
                                    const rrv_shape *proto)
{
    rrv__sf_objv verts = {NULL, 0, 0};
    rrv__sf_toks toks = {NULL, 0, 0};
    size_t pos = 0;
    int line = 0;
    rrv_result r = RRV_OK;
    while (pos < size && r == RRV_OK) {
        const char *s = text + pos, *e = (const char *)memchr(s, '\n', size - pos);
        int tr;
        if (!e) e = text + size;
        pos = (size_t)(e - text) + 1;
        if (line == INT_MAX) {
            r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line, "too many lines");
            break;
        }
        ++line;
        {
            char msg[96];
            if (rrv__sf_control_byte(s, e, msg, sizeof msg)) {
                r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line, "%s", msg);
                break;
            }
        }
        tr = rrv__sf_tokenize(&toks, s, e, 0);
        if (tr != 0) {
            r = rrv__fail(p->err, RRV_ERROR_MEMORY, file, line, "out of memory");
            break;
        }
        if (toks.n == 0) continue;
        if (rrv__sf_tok_is(&toks.v[0], "v")) {
            double c[3];
            int a;
            for (a = 0; a < 3; ++a) {
                if ((size_t)a + 1 >= toks.n) {
                    r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line,
                                  "v needs 3 coordinates, got %d", a);
                    break;
                }
                if (!rrv__sf_tok_number(&toks.v[a + 1], &c[a]) || !(c[a] == c[a]) ||
                    c[a] > DBL_MAX || c[a] < -DBL_MAX) {
                    r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line,
                                  "v: expected a finite number, got \"%.*s\"",
                                  RRV__SF_CLIP(&toks.v[a + 1]));
                    break;
                }
            }
            if (r != RRV_OK) break;
            if (!rrv__sf_reserve((void **)&verts.v, &verts.cap, verts.n, sizeof *verts.v)) {
                r = rrv__fail(p->err, RRV_ERROR_MEMORY, file, line, "out of memory");
                break;
            }
            verts.v[verts.n].x = c[0];
            verts.v[verts.n].y = c[1];
            verts.v[verts.n].z = c[2];
            ++verts.n;
        } else if (rrv__sf_tok_is(&toks.v[0], "f")) {
            int first = 0, prev = 0;
            size_t k;
            if (toks.n < 4) {
                r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line,
                              "f: a face needs at least 3 vertices, got %d", (int)toks.n - 1);
                break;
            }
            for (k = 1; k < toks.n && r == RRV_OK; ++k) {
                int idx = 0;
                long long raw = 0;
                int q = rrv__sf_obj_index(&toks.v[k], verts.n, &idx, &raw);
                if (q == 1)
                    r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line,
                                  "f: expected a vertex index, got \"%.*s\"",
                                  RRV__SF_CLIP(&toks.v[k]));
                else if (q == 2)
                    r = rrv__fail(p->err, RRV_ERROR_PARSE, file, line,
                                  "f: vertex index %lld is out of range (%d vertices so far)", raw,
                                  verts.n);
                else if (k == 1)
                    first = idx;
                else if (k >= 3) {
                    rrv__ck ck;
                    rrv__sf_ck(p, &ck, "mesh");
                    r = rrv__store_triangle(&ck, p->scene,
                                            rrv__sf_transform(verts.v[first], scale, translate),
                                            rrv__sf_transform(verts.v[prev], scale, translate),
                                            rrv__sf_transform(verts.v[idx], scale, translate), proto);
                }
                prev = idx;
            }
        }
    }
    RRV_FREE(verts.v);
    RRV_FREE(toks.v);
    return r;
}

/* ---- statements -------------------------------------------------------------------- */

static rrv_result rrv__sf_st_camera(rrv__sf_parser *p)
{
    rrv__sf_slot sl[RRV__SF_COUNT(rrv__sf_camera_keys)];
    rrv_camera *c = &p->scene->camera;
    rrv__ck ck;
    rrv_result r;
    if (p->have_camera) return rrv__sf_perr(p, RRV_ERROR_PARSE, "camera given twice");
    p->have_camera = 1;
    r = rrv__sf_parse_keys(p, "camera", 1, rrv__sf_camera_keys, RRV__SF_COUNT(rrv__sf_camera_keys),
                           sl);
    if (r != RRV_OK) return r;
    c->eye = rrv__sf_slot_vec(&sl[0], 0);
    c->look = rrv__sf_slot_vec(&sl[1], 0);
    if (sl[2].given) c->up = rrv__sf_slot_vec(&sl[2], 0);
    if (sl[3].given) c->fov = sl[3].v[0];
    if (sl[4].given) {
        c->width = (int)sl[4].v[0];
        c->height = (int)sl[4].v[1];
    }
    rrv__sf_ck(p, &ck, "camera");
    return rrv__camera_check(&ck, c);
}

static rrv_result rrv__sf_st_render(rrv__sf_parser *p)
{
    rrv__sf_slot sl[RRV__SF_COUNT(rrv__sf_render_keys)];
    rrv_settings *s = &p->scene->settings;
    rrv__ck ck, ambient;
    rrv_result r;
    if (p->have_render) return rrv__sf_perr(p, RRV_ERROR_PARSE, "render given twice");
    p->have_render = 1;
    r = rrv__sf_parse_keys(p, "render", 1, rrv__sf_render_keys, RRV__SF_COUNT(rrv__sf_render_keys),
                           sl);
    if (r != RRV_OK) return r;
    if (sl[0].given) s->spp = (int)sl[0].v[0];
    if (sl[1].given) s->max_depth = (int)sl[1].v[0];
    if (sl[2].given) s->seed = sl[2].u;
    if (sl[3].given) s->integrator = rrv__sf_integrators[sl[3].choice];
    if (sl[4].given) s->bend_tolerance = sl[4].v[0];
    if (sl[5].given) s->mu_eta = sl[5].v[0];
    if (sl[6].given) s->step = sl[6].v[0];
    if (sl[7].given) s->stepper = rrv__sf_steppers[sl[7].choice];
    if (sl[8].given) s->refraction = rrv__sf_schemes[sl[8].choice];
    if (sl[9].given) s->majorant_cells = (int)sl[9].v[0];
    if (sl[10].given) s->ior_interpolation = sl[10].choice ? RRV_IOR_INTERP_CUBIC : RRV_IOR_INTERP_TRILINEAR;
    if (sl[11].given) {
        static const rrv_nee modes[] = {RRV_NEE_NONE, RRV_NEE_STRAIGHT, RRV_NEE_SHOOT, RRV_NEE_MANIFOLD, RRV_NEE_AIM};
        s->nee = modes[sl[11].choice];
    }
    if (sl[12].given) s->manifold_gauge = sl[12].choice ? RRV_GAUGE_ISO : RRV_GAUGE_CHORD;
    if (sl[13].given) s->manifold_trials = (int)sl[13].v[0];
    if (sl[14].given) s->manifold_drop = sl[14].v[0];
    if (sl[15].given) s->sampler = sl[15].choice == 0 ? RRV_SAMPLER_PCG : RRV_SAMPLER_SOBOL;
    if (sl[16].given) s->emission_nee = sl[16].choice == 0 ? RRV_EMISSION_NEE_ON : RRV_EMISSION_NEE_OFF;
    if (sl[17].given) s->manifold_solver = sl[17].choice ? RRV_MANIFOLD_SOLVER_DOGLEG : RRV_MANIFOLD_SOLVER_LM;
    if (sl[18].given) {
        static const rrv_transmittance kinds[] = {RRV_TRANSMITTANCE_RATIO, RRV_TRANSMITTANCE_RESIDUAL,
                                                  RRV_TRANSMITTANCE_MARCH};
        s->transmittance = kinds[sl[18].choice];
    }
    if (sl[19].given) s->noise_threshold = sl[19].v[0];
    if (sl[20].given) s->equiangular = sl[20].choice == 0 ? RRV_EQUIANGULAR_ON : RRV_EQUIANGULAR_OFF;
    if (sl[21].given) s->light_sampler = sl[21].choice == 0 ? RRV_LIGHT_SAMPLER_POWER : RRV_LIGHT_SAMPLER_UNIFORM;
    rrv__sf_ck(p, &ck, "render");
    rrv__sf_ck(p, &ambient, "ambient");
    return rrv__settings_check(&ck, &ambient, s);
}

static rrv_result rrv__sf_st_ambient(rrv__sf_parser *p)
{
    rrv__sf_slot sl[1];
    rrv__ck ck, ambient;
    rrv_result r;
    if (p->have_ambient) return rrv__sf_perr(p, RRV_ERROR_PARSE, "ambient given twice");
    p->have_ambient = 1;
    r = rrv__sf_parse_keys(p, "ambient", 1, rrv__sf_ambient_keys, 1, sl);
    if (r != RRV_OK) return r;
    p->scene->settings.ambient_ior = sl[0].v[0];
    rrv__sf_ck(p, &ck, "render");
    rrv__sf_ck(p, &ambient, "ambient");
    return rrv__settings_check(&ck, &ambient, &p->scene->settings);
}

/* A `material` or `medium` name: present and short enough (the store
   refuses one already used). */
static rrv_result rrv__sf_new_name(rrv__sf_parser *p, const char *stmt, char *out)
{
    const rrv__sf_tok *t;
    if (p->toks.n < 2) return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: missing name", stmt);
    t = &p->toks.v[1];
    if (t->n == 0 || !rrv__sf_tok_string(t, out, 64))
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            "%s: name \"%.*s\" must be 1 to 63 printable characters", stmt,
                            RRV__SF_CLIP(t));
    return RRV_OK;
}

static rrv_result rrv__sf_st_material(rrv__sf_parser *p)
{
    rrv__sf_slot sl[RRV__SF_COUNT(rrv__sf_checker_keys)];
    rrv_material m;
    const rrv__sf_tok *kind;
    rrv__ck ck;
    rrv_result r;
    int checker;
    memset(&m, 0, sizeof m);
    r = rrv__sf_new_name(p, "material", m.name);
    if (r != RRV_OK) return r;
    if (p->toks.n < 3)
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "material: missing kind (diffuse or checker)");
    kind = &p->toks.v[2];
    if (rrv__sf_tok_is(kind, "diffuse"))
        checker = 0;
    else if (rrv__sf_tok_is(kind, "checker"))
        checker = 1;
    else {
        char hint[96];
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "material: unknown kind \"%.*s\" (expected diffuse or checker)%s",
                            RRV__SF_CLIP(kind), rrv__sf_near_list(kind, "diffuse|checker", hint, sizeof hint));
    }
    if (checker)
        r = rrv__sf_parse_keys(p, "material", 3, rrv__sf_checker_keys,
                               RRV__SF_COUNT(rrv__sf_checker_keys), sl);
    else
        r = rrv__sf_parse_keys(p, "material", 3, rrv__sf_diffuse_keys,
                               RRV__SF_COUNT(rrv__sf_diffuse_keys), sl);
    if (r != RRV_OK) return r;
    m.kind = checker ? RRV_MATERIAL_CHECKER : RRV_MATERIAL_DIFFUSE;
    rrv__material_def(&m);
    rrv__sf_slot_rgb(&sl[0], m.albedo);
    if (checker) {
        rrv__sf_slot_rgb(&sl[1], m.albedo2);
        if (sl[2].given) m.checker_scale = sl[2].v[0];
    }
    rrv__sf_ck(p, &ck, "material");
    return rrv__store_material(&ck, p->scene, &m, NULL);
}

/* sphere, quad and triangle: the last three slots are material, L, scale. */
static rrv_result rrv__sf_st_primitive(rrv__sf_parser *p)
{
    rrv__sf_slot sl[6];
    rrv_shape s;
    const char *stmt = p->toks.v[0].p[0] == 's'   ? "sphere"
                       : p->toks.v[0].p[0] == 'q' ? "quad"
                                                  : "triangle";
    const rrv__sf_key *keys = stmt[0] == 's'   ? rrv__sf_sphere_keys
                              : stmt[0] == 'q' ? rrv__sf_quad_keys
                                               : rrv__sf_triangle_keys;
    int nkeys = stmt[0] == 's' ? RRV__SF_COUNT(rrv__sf_sphere_keys) : 6;
    rrv__ck ck;
    rrv_result r = rrv__sf_parse_keys(p, stmt, 1, keys, nkeys, sl);
    if (r != RRV_OK) return r;
    memset(&s, 0, sizeof s);
    r = rrv__sf_shape_material(p, stmt, &sl[nkeys - 3], &s.material);
    if (r != RRV_OK) return r;
    rrv__sf_emission(&sl[nkeys - 2], &sl[nkeys - 1], s.L);
    if (stmt[0] == 's') {
        s.kind = RRV_SHAPE_SPHERE;
        s.center = rrv__sf_slot_vec(&sl[0], 0);
        s.radius = sl[1].v[0];
    } else if (stmt[0] == 'q') {
        s.kind = RRV_SHAPE_QUAD;
        s.p0 = rrv__sf_slot_vec(&sl[0], 0);
        s.e1 = rrv__sf_slot_vec(&sl[1], 0);
        s.e2 = rrv__sf_slot_vec(&sl[2], 0);
    } else {
        rrv_vec3 a = rrv__sf_slot_vec(&sl[0], 0);
        s.kind = RRV_SHAPE_TRIANGLE;
        s.p0 = a;
        s.e1 = rrv__sub(rrv__sf_slot_vec(&sl[1], 0), a);
        s.e2 = rrv__sub(rrv__sf_slot_vec(&sl[2], 0), a);
    }
    rrv__sf_ck(p, &ck, stmt);
    return rrv__store_shape(&ck, p->scene, &s);
}

static rrv_result rrv__sf_st_mesh(rrv__sf_parser *p)
{
    rrv__sf_slot sl[RRV__SF_COUNT(rrv__sf_mesh_keys)];
    rrv_shape proto;
    rrv_vec3 translate = {0, 0, 0};
    double scale;
    rrv__ck ck;
    rrv_result r =
        rrv__sf_parse_keys(p, "mesh", 1, rrv__sf_mesh_keys, RRV__SF_COUNT(rrv__sf_mesh_keys), sl);
    if (r != RRV_OK) return r;
    if (sl[0].given == sl[1].given)
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            sl[0].given ? "mesh: give \"file\" or \"points\", not both"
                                        : "mesh: missing \"file\" or \"points\"");
    if (sl[2].given && !sl[1].given)
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "mesh: \"indices\" needs \"points\"");
    memset(&proto, 0, sizeof proto);
    r = rrv__sf_shape_material(p, "mesh", &sl[4], &proto.material);
    if (r != RRV_OK) return r;
    rrv__sf_emission(&sl[5], NULL, proto.L);
    rrv__sf_ck(p, &ck, "mesh");
    r = rrv__emission_check(&ck, proto.L);
    if (r != RRV_OK) return r;
    if (sl[3].given) translate = rrv__sf_slot_vec(&sl[3], 0);
    scale = sl[6].given ? sl[6].v[0] : 1.0;
    if (sl[0].given) {
        char written[RRV__SF_PATH_MAX], full[RRV__SF_PATH_MAX];
        const rrv__sf_tok *t = &p->toks.v[sl[0].tok];
        const char *why;
        void *data;
        size_t size;
        if (!rrv__sf_tok_string(t, written, sizeof written) ||
            !rrv__sf_join_path(p->base_dir, written, full, sizeof full))
            return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                "mesh: path \"%.*s\" is too long or has control characters",
                                RRV__SF_CLIP(t));
        r = rrv__sf_read_whole(p->opt, full, 1, rrv__sf_max_bytes(p->opt), &data, &size, &why);
        if (r == RRV_ERROR_UNSUPPORTED)
            return rrv__sf_perr(p, r, "cannot read OBJ file \"%s\": " RRV__SF_NO_READER_MESSAGE,
                                written);
        if (r != RRV_OK) {
            char what[RRV__SF_PATH_MAX + 16], message[RRV__SF_PATH_MAX + 96];
            snprintf(what, sizeof what, "OBJ file \"%s\"", written);
            rrv__sf_read_message(r, what, why, rrv__sf_max_bytes(p->opt), message, sizeof message);
            return rrv__sf_perr(p, r, "%s", message);
        }
        r = rrv__sf_obj_parse(p, (const char *)data, size, full, scale, translate, &proto);
        rrv__sf_release_whole(p->opt, data);
        return r;
    } else {
        const rrv__sf_tok *toks = p->toks.v;
        size_t np = sl[1].count, ni = sl[2].count, i;
        if (np == 0 || np % 3 != 0)
            return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                "mesh: \"points\" needs a multiple of 3 numbers, got %llu",
                                (unsigned long long)np);
        if (!sl[2].given || ni == 0 || ni % 3 != 0)
            return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                "mesh: \"indices\" needs a multiple of 3 integers, got %llu",
                                (unsigned long long)ni);
        for (i = 0; i < ni; i += 3) {
            rrv_vec3 v[3];
            int c;
            for (c = 0; c < 3; ++c) {
                int neg, overflow;
                uint64_t idx;
                double x, y, z;
                rrv__sf_tok_integer(&toks[sl[2].tok + i + (size_t)c], &neg, &idx, &overflow);
                if (idx >= np / 3)
                    return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                        "mesh: index %llu is out of range (%llu points)",
                                        (unsigned long long)idx, (unsigned long long)(np / 3));
                rrv__sf_tok_number(&toks[sl[1].tok + 3 * (size_t)idx], &x);
                rrv__sf_tok_number(&toks[sl[1].tok + 3 * (size_t)idx + 1], &y);
                rrv__sf_tok_number(&toks[sl[1].tok + 3 * (size_t)idx + 2], &z);
                v[c].x = x;
                v[c].y = y;
                v[c].z = z;
                v[c] = rrv__sf_transform(v[c], scale, translate);
            }
            r = rrv__store_triangle(&ck, p->scene, v[0], v[1], v[2], &proto);
            if (r != RRV_OK) return r;
        }
    }
    return RRV_OK;
}

static rrv_result rrv__sf_st_environment(rrv__sf_parser *p)
{
    rrv__sf_slot sl[3];
    rrv_environment *env = &p->scene->environment;
    const rrv__sf_tok *kind;
    rrv__ck ck;
    double k;
    int c;
    rrv_result r;
    if (p->have_environment) return rrv__sf_perr(p, RRV_ERROR_PARSE, "environment given twice");
    p->have_environment = 1;
    if (p->toks.n < 2)
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "environment: missing kind (constant or gradient)");
    kind = &p->toks.v[1];
    if (rrv__sf_tok_is(kind, "constant")) {
        r = rrv__sf_parse_keys(p, "environment", 2, rrv__sf_env_constant_keys, 2, sl);
        if (r != RRV_OK) return r;
        k = sl[1].given ? sl[1].v[0] : 1.0;
        env->kind = RRV_ENV_CONSTANT;
        rrv__environment_def(env);
        for (c = 0; c < 3; ++c)
            env->L[c] = (sl[0].given ? sl[0].v[c] : env->L[c]) * k;
    } else if (rrv__sf_tok_is(kind, "gradient")) {
        r = rrv__sf_parse_keys(p, "environment", 2, rrv__sf_env_gradient_keys, 3, sl);
        if (r != RRV_OK) return r;
        k = sl[2].given ? sl[2].v[0] : 1.0;
        env->kind = RRV_ENV_GRADIENT;
        for (c = 0; c < 3; ++c) {
            env->L[c] = sl[0].v[c] * k;
            env->L2[c] = sl[1].v[c] * k;
        }
    } else {
        char hint[96];
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            "environment: unknown kind \"%.*s\" (expected constant or gradient)%s",
                            RRV__SF_CLIP(kind), rrv__sf_near_list(kind, "constant|gradient", hint, sizeof hint));
    }
    rrv__sf_ck(p, &ck, "environment");
    return rrv__environment_check(&ck, env);
}

static rrv_result rrv__sf_st_medium(rrv__sf_parser *p)
{
    rrv__sf_slot sl[RRV__SF_COUNT(rrv__sf_medium_keys)];
    rrv_medium m;
    rrv__ck ck;
    int c;
    rrv_result r;
    memset(&m, 0, sizeof m);
    r = rrv__sf_new_name(p, "medium", m.name);
    if (r != RRV_OK) return r;
    r = rrv__sf_parse_keys(p, "medium", 2, rrv__sf_medium_keys, RRV__SF_COUNT(rrv__sf_medium_keys),
                           sl);
    if (r != RRV_OK) return r;
    if ((sl[5].given || sl[6].given) && (sl[1].given || sl[2].given))
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            "medium: give albedo and sigma_t, or sigma_a and sigma_s, not both");
    if (sl[5].given != sl[6].given)
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            sl[5].given ? "medium: \"albedo\" needs \"sigma_t\""
                                        : "medium: \"sigma_t\" needs \"albedo\"");
    rrv__medium_def(&m);
    m.lo = rrv__sf_slot_vec(&sl[0], 0);
    m.hi = rrv__sf_slot_vec(&sl[0], 3);
    for (c = 0; c < 3; ++c) {
        if (sl[5].given) {
            m.sigma_s[c] = sl[5].v[c] * sl[6].v[c];
            m.sigma_a[c] = sl[6].v[c] - m.sigma_s[c];
            if (m.sigma_a[c] < 0.0) m.sigma_a[c] = 0.0; /* rounding only */
        }
    }
    rrv__sf_slot_rgb(&sl[1], m.sigma_a);
    rrv__sf_slot_rgb(&sl[2], m.sigma_s);
    rrv__sf_slot_rgb(&sl[7], m.Le);
    if (sl[3].given) m.scale = sl[3].v[0];
    if (sl[4].given) m.g = sl[4].v[0];
    if (sl[8].given) m.Lescale = sl[8].v[0];
    m.line[0] = p->line;
    rrv__ck_init(&ck, p->err, p->name, p->line, RRV_ERROR_PARSE, "medium \"%s\"", m.name);
    return rrv__store_medium(&ck, p->scene, &m, NULL);
}

/* One field statement (`density | temperature | pressure | ior MEDIUM KIND
   ...`) as the parser of its kind sees it. */
typedef struct rrv__sf_fs {
    const char *stmt;         /* density, temperature, pressure or ior */
    rrv_medium_field which;
    rrv_medium *m;
    const rrv__sf_tok *value; /* the token after the kind: constant, grid, nanovdb */
    const rrv__sf_slot *sl;   /* the kind's keys, in its table's order */
    int first;                /* not a later blob line of the same field */
} rrv__sf_fs;

/* Each kind fills f (a zeroed field; for blobs, the medium's own). */
typedef rrv_result (*rrv__sf_field_func)(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f);

static rrv_result rrv__sf_field_constant(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    static const rrv__sf_key any = {"constant", RRV__SF_NUM, 1, 0, RRV__SF_ANY, NULL};
    double v;
    uint64_t u;
    rrv_result r;
    if (!rrv__sf_tok_number(fs->value, &v))
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: expected a number for \"constant\", got \"%.*s\"",
                            fs->stmt, RRV__SF_CLIP(fs->value));
    r = rrv__sf_value(p, fs->stmt, &any, fs->value, &v, &u);
    if (r != RRV_OK) return r;
    f->kind = RRV_FIELD_CONSTANT;
    f->value = v;
    return RRV_OK;
}

static rrv_result rrv__sf_field_blob(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    const rrv__sf_slot *sl = fs->sl;
    rrv_blob b;
    memset(&b, 0, sizeof b);
    rrv__blob_def(&b);
    b.center = rrv__sf_slot_vec(&sl[0], 0);
    b.radius = sl[1].v[0];
    if (sl[2].given) b.weight = sl[2].v[0];
    if (fs->first) {
        f->kind = RRV_FIELD_BLOBS;
        rrv__field_def(f, fs->which, fs->m);
        if (sl[3].given) f->base = sl[3].v[0];
    }
    if (f->blob_count == INT_MAX) return RRV__SF_OOM(p);
    if (f->blob_count == 0 || (f->blob_count >= 4 && (f->blob_count & (f->blob_count - 1)) == 0)) {
        size_t cap = rrv__sf_blob_capacity(f->blob_count + 1);
        rrv_blob *grown;
        if (cap > SIZE_MAX / sizeof b) return RRV__SF_OOM(p);
        grown = (rrv_blob *)RRV_REALLOC(f->blobs, cap * sizeof b);
        if (!grown) return RRV__SF_OOM(p);
        f->blobs = grown;
    }
    f->blobs[f->blob_count++] = b;
    return RRV_OK;
}

/* Noise and the profiles write what was given, let rrv__field_def fill the
   rest and write it again: an explicit zero survives, and defaults that
   follow other keys (a shell's edge) see them. */
static void rrv__sf_noise_given(const rrv__sf_slot *sl, rrv_field *f)
{
    rrv_noise *n = &f->noise;
    if (sl[0].given) n->octaves = (int)sl[0].v[0];
    if (sl[1].given) n->frequency = sl[1].v[0];
    if (sl[2].given) n->lacunarity = sl[2].v[0];
    if (sl[3].given) n->gain = sl[3].v[0];
    if (sl[4].given) n->threshold = sl[4].v[0];
    if (sl[5].given) n->seed = (uint32_t)sl[5].v[0];
    if (sl[6].given) n->falloff = rrv__sf_falloffs[sl[6].choice];
    if (sl[7].given) n->center = rrv__sf_slot_vec(&sl[7], 0);
    if (sl[8].given) n->radius = sl[8].v[0];
    if (sl[9].given) f->amplitude = sl[9].v[0];
    if (sl[10].given) f->base = sl[10].v[0];
}

static rrv_result rrv__sf_field_noise(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    (void)p;
    f->kind = RRV_FIELD_NOISE;
    /* The file format's falloff is a sphere; rrv_noise's zero is NONE. */
    f->noise.falloff = RRV_FALLOFF_SPHERE;
    rrv__sf_noise_given(fs->sl, f);
    rrv__field_def(f, fs->which, fs->m);
    rrv__sf_noise_given(fs->sl, f);
    return RRV_OK;
}

static void rrv__sf_profile_given(int kind, const rrv__sf_slot *sl, rrv_field *f)
{
    if (sl[0].given) f->center = rrv__sf_slot_vec(&sl[0], 0);
    if (kind == RRV_FIELD_SLAB) {
        f->normal = rrv__sf_slot_vec(&sl[1], 0);
        f->gradient = sl[2].v[0];
        if (sl[3].given) f->base = sl[3].v[0];
        return;
    }
    f->radius = sl[1].v[0];
    if (kind == RRV_FIELD_FISHEYE && sl[2].given) f->n0 = sl[2].v[0];
    if (kind == RRV_FIELD_SHELL) {
        f->thickness = sl[2].v[0];
        if (sl[3].given) f->edge = sl[3].v[0];
        f->amplitude = sl[4].v[0];
        if (sl[5].given) f->base = sl[5].v[0];
    }
}

static rrv_result rrv__sf_field_profile(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f,
                                        rrv_field_kind kind)
{
    (void)p;
    f->kind = kind;
    rrv__sf_profile_given(kind, fs->sl, f);
    rrv__field_def(f, fs->which, fs->m);
    rrv__sf_profile_given(kind, fs->sl, f);
    if (kind == RRV_FIELD_SLAB) rrv__field_def(f, fs->which, fs->m); /* normalise the normal */
    return RRV_OK;
}

static rrv_result rrv__sf_field_luneburg(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    return rrv__sf_field_profile(p, fs, f, RRV_FIELD_LUNEBURG);
}
static rrv_result rrv__sf_field_fisheye(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    return rrv__sf_field_profile(p, fs, f, RRV_FIELD_FISHEYE);
}
static rrv_result rrv__sf_field_slab(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    return rrv__sf_field_profile(p, fs, f, RRV_FIELD_SLAB);
}
static rrv_result rrv__sf_field_shell(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    return rrv__sf_field_profile(p, fs, f, RRV_FIELD_SHELL);
}

/* `ior M gas`: the IOR follows temperature and pressure; the field stays NONE. */
static rrv_result rrv__sf_field_gas(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    const rrv__sf_slot *sl = fs->sl;
    (void)p;
    (void)f;
    fs->m->ior_from_gas = 1;
    if (sl[0].given) fs->m->eta_ref = sl[0].v[0];
    if (sl[1].given) fs->m->P_ref = sl[1].v[0];
    if (sl[2].given) fs->m->T_ref = sl[2].v[0];
    return RRV_OK;
}

/* The medium's limit checks name the file a field came from. */
static void rrv__sf_keep_source(rrv_medium *m, rrv_medium_field which, const char *written)
{
    size_t n = strlen(written);
    if (n >= sizeof m->source[0]) n = sizeof m->source[0] - 1;
    memcpy(m->source[1 + which], written, n);
    m->source[1 + which][n] = '\0';
}

static rrv_result rrv__sf_field_grid(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    char written[RRV__SF_PATH_MAX], full[RRV__SF_PATH_MAX];
    const char *why;
    const char *stmt = fs->stmt;
    const rrv__sf_tok *t = fs->value;
    rrv_error e;
    rrv_result r;
    if (!rrv__sf_tok_string(t, written, sizeof written) ||
        !rrv__sf_join_path(p->base_dir, written, full, sizeof full))
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            "%s: path \"%.*s\" is too long or has control characters", stmt,
                            RRV__SF_CLIP(t));
    rrv__clear_error(&e);
    r = rrv__sf_grid_load(full, written, p->opt, fs->which == RRV_MEDIUM_DENSITY, &f->grid, &e, &why);
    if (r == RRV_ERROR_IO)
        return rrv__sf_perr(p, r, "cannot read grid file \"%s\"%s%s", written, why[0] ? ": " : "", why);
    if (r == RRV_ERROR_UNSUPPORTED)
        return rrv__sf_perr(p, r, "cannot read grid file \"%s\": %s", written, e.message);
    if (r != RRV_OK) return rrv__sf_perr(p, r, "grid \"%s\": %s", written, e.message);
    f->kind = RRV_FIELD_GRID;
    p->scene->grid_bytes += (size_t)f->grid.nx * (size_t)f->grid.ny * (size_t)f->grid.nz *
                            (size_t)f->grid.channels * sizeof(float);
    if (fs->which != RRV_MEDIUM_DENSITY && f->grid.channels != 1)
        return rrv__sf_perr(p, RRV_ERROR_FORMAT, "grid \"%s\": %s grids need 1 channel, found %d",
                            written, stmt, f->grid.channels);
    rrv__sf_keep_source(fs->m, fs->which, written);
    return RRV_OK;
}

/* `nanovdb FILE [grid NAME] [cellcentered on|off]`: the grid named as the
   statement (pbrt-v4's "density" and "temperature") unless `grid` names
   another; `cellcentered on` takes Blender's placement (rrv_nanovdb_cell_centered). */
static rrv_result rrv__sf_field_nanovdb(rrv__sf_parser *p, const rrv__sf_fs *fs, rrv_field *f)
{
    char written[RRV__SF_PATH_MAX], full[RRV__SF_PATH_MAX], grid_name[256];
    const char *why;
    const char *stmt = fs->stmt;
    const rrv__sf_tok *t = fs->value;
    rrv_error e;
    rrv_result r;
    if (!rrv__sf_tok_string(t, written, sizeof written) ||
        !rrv__sf_join_path(p->base_dir, written, full, sizeof full))
        return rrv__sf_perr(p, RRV_ERROR_PARSE,
                            "%s: path \"%.*s\" is too long or has control characters", stmt,
                            RRV__SF_CLIP(t));
    if (fs->sl[0].given) {
        const rrv__sf_tok *g = &p->toks.v[fs->sl[0].tok];
        if (!rrv__sf_tok_string(g, grid_name, sizeof grid_name))
            return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                "%s: grid name \"%.*s\" is longer than 255 bytes or has control characters",
                                stmt, RRV__SF_CLIP(g));
    } else {
        strcpy(grid_name, stmt);
    }
    rrv__clear_error(&e);
    r = rrv__nv_read_file(full, written, grid_name, p->opt, &f->nanovdb, &e, &why);
    if (r == RRV_ERROR_IO)
        return rrv__sf_perr(p, r, "cannot read NanoVDB file \"%s\"%s%s", written, why[0] ? ": " : "", why);
    if (r != RRV_OK) return rrv__sf_perr(p, r, "NanoVDB file \"%s\": %s", written, e.message);
    f->kind = RRV_FIELD_NANOVDB;
    if (fs->sl[1].given && fs->sl[1].choice == 0) rrv_nanovdb_cell_centered(&f->nanovdb);
    p->scene->grid_bytes += f->nanovdb.size;
    rrv__sf_keep_source(fs->m, fs->which, written);
    return RRV_OK;
}

enum {
    RRV__SF_K_CONSTANT,
    RRV__SF_K_BLOB,
    RRV__SF_K_NOISE,
    RRV__SF_K_GRID,
    RRV__SF_K_LUNEBURG,
    RRV__SF_K_FISHEYE,
    RRV__SF_K_SLAB,
    RRV__SF_K_SHELL,
    RRV__SF_K_GAS,
    RRV__SF_K_NANOVDB,
    RRV__SF_K_COUNT
};

/* value: the kind takes a value token before its keys (the message when
   it is missing). */
static const struct rrv__sf_field_kind {
    const char *name;
    const rrv__sf_key *keys;
    int nkeys;
    int ior_only;
    rrv__sf_field_func parse;
    const char *value;
} rrv__sf_field_kinds[RRV__SF_K_COUNT] = {
    {"constant", NULL, 0, 0, rrv__sf_field_constant, "%s: \"constant\" needs 1 number, got 0"},
    {"blob", rrv__sf_blob_keys, RRV__SF_COUNT(rrv__sf_blob_keys), 0, rrv__sf_field_blob, NULL},
    {"noise", rrv__sf_noise_keys, RRV__SF_COUNT(rrv__sf_noise_keys), 0, rrv__sf_field_noise, NULL},
    {"grid", NULL, 0, 0, rrv__sf_field_grid, "%s: \"grid\" needs a file path"},
    {"luneburg", rrv__sf_luneburg_keys, RRV__SF_COUNT(rrv__sf_luneburg_keys), 1,
     rrv__sf_field_luneburg, NULL},
    {"fisheye", rrv__sf_fisheye_keys, RRV__SF_COUNT(rrv__sf_fisheye_keys), 1, rrv__sf_field_fisheye,
     NULL},
    {"slab", rrv__sf_slab_keys, RRV__SF_COUNT(rrv__sf_slab_keys), 1, rrv__sf_field_slab, NULL},
    {"shell", rrv__sf_shell_keys, RRV__SF_COUNT(rrv__sf_shell_keys), 1, rrv__sf_field_shell, NULL},
    {"gas", rrv__sf_gas_keys, RRV__SF_COUNT(rrv__sf_gas_keys), 1, rrv__sf_field_gas, NULL},
    {"nanovdb", rrv__sf_nanovdb_keys, RRV__SF_COUNT(rrv__sf_nanovdb_keys), 0, rrv__sf_field_nanovdb,
     "%s: \"nanovdb\" needs a file path"},
};

/* The keys every kind of one field takes (they set the medium), applied
   before the kind so a temperature constant is checked with them. */
static void rrv__sf_field_extras(const rrv__sf_fs *fs, const rrv__sf_slot *sl)
{
    rrv_medium *m = fs->m;
    if (fs->which == RRV_MEDIUM_IOR && sl[0].given) m->ior_scale = sl[0].v[0];
    if (fs->which == RRV_MEDIUM_TEMPERATURE) {
        if (sl[0].given) m->temperatureoffset = sl[0].v[0];
        if (sl[1].given) m->temperaturescale = sl[1].v[0];
        /* a temperature glows unless the file says `blackbody off` */
        if (sl[2].given)
            m->blackbody_emission = sl[2].choice == 0;
        else if (fs->first)
            m->blackbody_emission = 1;
    }
}

/* Which medium, which kind, whether this field may be given again; then the
   kind's keys and the field's extras, the kind's parser, and the check. */
static rrv_result rrv__sf_st_field(rrv__sf_parser *p)
{
    static const char *const kinds_ior = "constant, blob, noise, grid, nanovdb, luneburg, fisheye, "
                                         "slab, shell or gas";
    static const char *const kinds_other = "constant, blob, noise, grid or nanovdb";
    const rrv__sf_tok *toks = p->toks.v;
    rrv__sf_key keys[RRV__SF_MAX_KEYS];
    rrv__sf_slot sl[RRV__SF_MAX_KEYS];
    const rrv__sf_key *extra = NULL;
    int which, kind, nkeys, nextra = 0, mi;
    size_t first = 3;
    rrv__sf_fs fs;
    rrv_field *f, fresh, *target;
    rrv__ck ck;
    rrv_result r;
    for (which = 0; which < 3 && !rrv__sf_tok_is(&toks[0], rrv__medium_field_names[which]); ++which) {
    }
    memset(&fs, 0, sizeof fs);
    fs.stmt = rrv__medium_field_names[which];
    fs.which = (rrv_medium_field)which;
    if (p->toks.n < 2) return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: missing medium name", fs.stmt);
    mi = rrv__sf_find_medium(p->scene, &toks[1]);
    if (mi < 0) {
        char hint[96];
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: medium \"%.*s\" is not defined%s", fs.stmt,
                            RRV__SF_CLIP(&toks[1]), rrv__sf_near_defined(p->scene, &toks[1], 1, hint, sizeof hint));
    }
    fs.m = &p->scene->media[mi];
    f = rrv__medium_field_of(fs.m, fs.which);
    if (p->toks.n < 3)
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: missing kind (%s)", fs.stmt,
                            which == RRV_MEDIUM_IOR ? kinds_ior : kinds_other);
    for (kind = 0; kind < RRV__SF_K_COUNT; ++kind)
        if (rrv__sf_tok_is(&toks[2], rrv__sf_field_kinds[kind].name) &&
            (which == RRV_MEDIUM_IOR || !rrv__sf_field_kinds[kind].ior_only))
            break;
    if (kind == RRV__SF_K_COUNT) {
        char hint[96];
        const char *kinds = which == RRV_MEDIUM_IOR ? kinds_ior : kinds_other;
        return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: unknown kind \"%.*s\" (expected %s)%s", fs.stmt,
                            RRV__SF_CLIP(&toks[2]), kinds, rrv__sf_near_list(&toks[2], kinds, hint, sizeof hint));
    }
    /* blob statements accumulate; anything else may be given once */
    fs.first = f->kind != RRV_FIELD_BLOBS;
    if (f->kind != RRV_FIELD_NONE || (which == RRV_MEDIUM_IOR && fs.m->ior_from_gas)) {
        if (kind != RRV__SF_K_BLOB || f->kind != RRV_FIELD_BLOBS)
            return rrv__sf_perr(p, RRV_ERROR_PARSE,
                                f->kind == RRV_FIELD_BLOBS || kind == RRV__SF_K_BLOB
                                    ? "%s: blob cannot be mixed with other kinds (medium \"%s\")"
                                    : "%s: given twice for medium \"%s\"",
                                fs.stmt, fs.m->name);
    }
    if (rrv__sf_field_kinds[kind].value) {
        double dummy;
        if (p->toks.n < 4) return rrv__sf_perr(p, RRV_ERROR_PARSE, rrv__sf_field_kinds[kind].value, fs.stmt);
        if (kind == RRV__SF_K_CONSTANT && p->toks.n > 4 && rrv__sf_tok_number(&toks[3], &dummy) &&
            rrv__sf_tok_number(&toks[4], &dummy)) {
            size_t end = 4;
            while (end < p->toks.n && rrv__sf_tok_number(&toks[end], &dummy))
                ++end;
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s: \"constant\" needs 1 number, got %llu",
                                fs.stmt, (unsigned long long)(end - 3));
        }
        fs.value = &toks[3];
        first = 4;
    }
    nkeys = rrv__sf_field_kinds[kind].nkeys;
    if (nkeys) memcpy(keys, rrv__sf_field_kinds[kind].keys, (size_t)nkeys * sizeof *keys);
    if (which == RRV_MEDIUM_IOR) {
        extra = rrv__sf_ior_extra_keys;
        nextra = RRV__SF_COUNT(rrv__sf_ior_extra_keys);
    } else if (which == RRV_MEDIUM_TEMPERATURE) {
        extra = rrv__sf_temperature_extra_keys;
        nextra = RRV__SF_COUNT(rrv__sf_temperature_extra_keys);
    }
    if (nextra) memcpy(keys + nkeys, extra, (size_t)nextra * sizeof *keys);
    r = rrv__sf_parse_keys(p, fs.stmt, first, keys, nkeys + nextra, sl);
    if (r != RRV_OK) return r;
    fs.sl = sl;
    rrv__sf_field_extras(&fs, sl + nkeys);

    memset(&fresh, 0, sizeof fresh);
    target = kind == RRV__SF_K_BLOB ? f : &fresh;
    r = rrv__sf_field_kinds[kind].parse(p, &fs, target);
    if (r == RRV_OK && kind != RRV__SF_K_GAS) {
        rrv__sf_ck(p, &ck, fs.stmt);
        r = rrv__field_check(&ck, fs.which, fs.m, target,
                             kind == RRV__SF_K_BLOB ? target->blob_count - 1 : 0);
    }
    if (target == &fresh) {
        if (r == RRV_OK)
            *f = fresh;
        else
            rrv__sf_field_free(&fresh);
    }
    if (r == RRV_OK) {
        fs.m->line[1 + which] = p->line;
        /* the grid kinds wrote their file's name; every other kind clears it */
        if (kind != RRV__SF_K_GRID && kind != RRV__SF_K_NANOVDB) fs.m->source[1 + which][0] = '\0';
    }
    return r;
}

typedef rrv_result (*rrv__sf_statement_func)(rrv__sf_parser *p);
static const struct rrv__sf_statement {
    const char *name;
    rrv__sf_statement_func parse;
} rrv__sf_statements[] = {
    {"camera", rrv__sf_st_camera},           {"render", rrv__sf_st_render},
    {"ambient", rrv__sf_st_ambient},         {"material", rrv__sf_st_material},
    {"sphere", rrv__sf_st_primitive},        {"quad", rrv__sf_st_primitive},
    {"triangle", rrv__sf_st_primitive},      {"mesh", rrv__sf_st_mesh},
    {"environment", rrv__sf_st_environment}, {"medium", rrv__sf_st_medium},
    {"density", rrv__sf_st_field},           {"temperature", rrv__sf_st_field},
    {"pressure", rrv__sf_st_field},          {"ior", rrv__sf_st_field},
};

static rrv_result rrv__sf_parse_lines(rrv__sf_parser *p, const char *text, size_t size)
{
    size_t pos = 0;
    while (pos < size) {
        const char *s = text + pos, *e = (const char *)memchr(s, '\n', size - pos);
        int tr, k;
        rrv_result r;
        if (!e) e = text + size;
        pos = (size_t)(e - text) + 1;
        if (p->line == INT_MAX) return rrv__sf_perr(p, RRV_ERROR_LIMIT, "too many lines");
        ++p->line;
        {
            char msg[96];
            if (rrv__sf_control_byte(s, e, msg, sizeof msg))
                return rrv__sf_perr(p, RRV_ERROR_PARSE, "%s", msg);
        }
        tr = rrv__sf_tokenize(&p->toks, s, e, 1);
        if (tr == 1) return rrv__sf_perr(p, RRV_ERROR_PARSE, "unterminated quote");
        if (tr == 2) return RRV__SF_OOM(p);
        if (p->toks.n == 0) continue;
        for (k = 0; k < RRV__SF_COUNT(rrv__sf_statements); ++k)
            if (rrv__sf_tok_is(&p->toks.v[0], rrv__sf_statements[k].name)) break;
        if (k == RRV__SF_COUNT(rrv__sf_statements)) {
            rrv__sf_near nr;
            char hint[96];
            memset(&nr, 0, sizeof nr);
            nr.word = &p->toks.v[0];
            for (k = 0; k < RRV__SF_COUNT(rrv__sf_statements); ++k)
                rrv__sf_near_try(&nr, rrv__sf_statements[k].name, strlen(rrv__sf_statements[k].name));
            return rrv__sf_perr(p, RRV_ERROR_PARSE, "unknown statement \"%.*s\"%s", RRV__SF_CLIP(&p->toks.v[0]),
                                rrv__sf_near_hint(&nr, hint, sizeof hint));
        }
        r = rrv__sf_statements[k].parse(p);
        if (r != RRV_OK) return r;
    }
    if (!p->have_camera)
        return rrv__fail(p->err, RRV_ERROR_PARSE, p->name, 0, "no camera statement");
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_parse(const char *text, size_t size, const char *name,
                                   const char *base_dir, const rrv_load_options *opt,
                                   rrv_scene **out, rrv_error *err)
{
    rrv__sf_parser p;
    rrv_scene *s;
    rrv_result r;
    rrv__clear_error(err);
    if (!name) name = "<scene>";
    if (!out || (!text && size > 0))
        return rrv__fail(err, RRV_ERROR_ARGUMENT, name, 0, "rrv_scene_parse: NULL argument");
    *out = NULL;
    s = rrv__scene_new(name);
    if (!s) return rrv__fail(err, RRV_ERROR_MEMORY, name, 0, "out of memory");
    s->max_grid_bytes = opt ? opt->max_grid_bytes : 0;
    if (opt && opt->max_bake_samples > 0) s->settings.max_bake_samples = opt->max_bake_samples;
    if (opt) {
        s->parallel_for = opt->parallel_for;
        s->parallel_for_user = opt->parallel_for_user;
    }
    memset(&p, 0, sizeof p);
    p.scene = s;
    p.name = s->path;
    p.base_dir = base_dir;
    p.opt = opt;
    p.err = err;
    r = rrv__sf_parse_lines(&p, text, size);
    RRV_FREE(p.toks.v);
    if (r == RRV_OK) {
        s->bytes = rrv__sf_scene_bytes(s);
        r = rrv_scene_prepare(s, err);
    }
    if (r != RRV_OK) {
        rrv_scene_free(s);
        return r;
    }
    *out = s;
    return RRV_OK;
}

RRV_DEF rrv_result rrv_scene_load(const char *path, const rrv_load_options *opt, rrv_scene **out,
                                  rrv_error *err)
{
    char dir[RRV__SF_PATH_MAX];
    const char *slash = NULL, *c, *why;
    void *data;
    size_t size;
    rrv_result r;
    rrv__clear_error(err);
    if (out) *out = NULL;
    if (!path || !out)
        return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "rrv_scene_load: NULL argument");
    for (c = path; *c; ++c)
#ifdef _WIN32
        if (*c == '/' || *c == '\\') slash = c;
#else
        if (*c == '/') slash = c;
#endif
    if (slash) {
        size_t n = slash == path ? 1 : (size_t)(slash - path);
        if (n >= sizeof dir) return rrv__fail(err, RRV_ERROR_ARGUMENT, path, 0, "path is too long");
        memcpy(dir, path, n);
        dir[n] = '\0';
    }
    r = rrv__sf_read_whole(opt, path, 1, rrv__sf_max_bytes(opt), &data, &size, &why);
    if (r == RRV_ERROR_UNSUPPORTED) return rrv__fail(err, r, path, 0, RRV__SF_NO_READER_MESSAGE);
    if (r != RRV_OK) {
        char message[128];
        rrv__sf_read_message(r, "scene file", why, rrv__sf_max_bytes(opt), message, sizeof message);
        return rrv__fail(err, r, path, 0, "%s", message);
    }
    r = rrv_scene_parse((const char *)data, size, path, slash ? dir : NULL, opt, out, err);
    rrv__sf_release_whole(opt, data);
    return r;
}

#else /* RRV_NO_SCENE_FILE: scenes come from the building calls alone */

RRV_DEF rrv_result rrv_scene_parse(const char *text, size_t size, const char *name,
                                   const char *base_dir, const rrv_load_options *opt,
                                   rrv_scene **out, rrv_error *err)
{
    (void)text; (void)size; (void)base_dir; (void)opt;
    if (out) *out = NULL;
    return rrv__left_out(err, name, "the scene file parser", "RRV_NO_SCENE_FILE",
                         "; build the scene with rrv_scene_create and rrv_scene_add_*");
}

RRV_DEF rrv_result rrv_scene_load(const char *path, const rrv_load_options *opt, rrv_scene **out,
                                  rrv_error *err)
{
    (void)opt;
    if (out) *out = NULL;
    return rrv__left_out(err, path, "the scene file parser", "RRV_NO_SCENE_FILE",
                         "; build the scene with rrv_scene_create and rrv_scene_add_*");
}

RRV_DEF rrv_result rrv_grid_read_memory(const void *data, size_t size, const char *name,
                                        size_t max_grid_bytes, int nonnegative,
                                        rrv_grid *grid, rrv_error *err)
{
    (void)data; (void)size; (void)max_grid_bytes; (void)nonnegative;
    if (grid) memset(grid, 0, sizeof *grid);
    return rrv__left_out(err, name, "the gridvol reader", "RRV_NO_SCENE_FILE",
                         "; give the samples in rrv_field.grid");
}

RRV_DEF rrv_result rrv_grid_read(const char *path, const rrv_load_options *opt, int nonnegative,
                                 rrv_grid *grid, rrv_error *err)
{
    (void)opt;
    return rrv_grid_read_memory(NULL, 0, path, 0, nonnegative, grid, err);
}

#endif /* RRV_NO_SCENE_FILE */

#endif /* RRV_IMPLEMENTATION_INCLUDED */
#endif /* RRV_IMPLEMENTATION */

/*
------------------------------------------------------------------------------
NOTES: how the estimators work, and the rules behind BOUNDARIES, IOR GRIDS
and BOUNDS (moved here from the manual at the top, word for word)
------------------------------------------------------------------------------

   NEXT-EVENT ESTIMATION, in detail
     DEFAULT     with the eikonal integrator, MANIFOLD (dogleg) where
                 every refracting medium is clear and weak (its peak
                 |grad eta| times its support's diameter at most 2 rad,
                 as heat haze is) and no box face or sphere rim is a jump
                 of the IOR: the heat caustics,
                 where chains measured 1.35x to 3.8x shoot's efficiency;
                 else SHOOT, the most efficient curved mode measured there
                 (lenses, glass; test/bench/RESULTS.md; the default
                 integrator is eikonal where solving pays; rrv_scene_nee).
                 With the refractive integrator, which shooting cannot
                 differentiate, it aims (AIM): unbiased, about as cheap as
                 STRAIGHT, but without focusing, so caustics of small
                 lights stay noisy (MANIFOLD solves them there, at a high
                 cost).
     STRAIGHT    a straight shadow ray, ratio-tracked,
                 combined by the power heuristic with the phase/BSDF-sampled
                 continuation as though both sampled the same path. They do
                 not: the continuation bends and the shadow ray does not, so
                 wherever either crosses a refracting medium the sum is
                 biased: a lens caustic comes out at half its radiance and
                 white furnaces with refraction above 1 (test/test_nee.c).
     NONE        no light sampling: lights, emitters and the sky count only
                 where the bent path hits them, with MIS weight 1. Unbiased
                 (furnaces give exactly 1), but noisy for small lights.
     SHOOT       curved NEE by shooting (eikonal integrator), unbiased. The path from the last vertex to the
                 light decides which estimators may make it: touching no
                 refraction support (box or profile sphere), or weak (below),
                 straight NEE and the forward path, by the power heuristic,
                 as classic does; curved (part of it in a support, no sharp
                 interface reflecting it) and ending on a quad, triangle or
                 sphere light,
                 the curved connection and the forward path, by the power
                 heuristic on their solid-angle densities at the initial
                 direction w0: p_nee = |det J_plane| p_area(y) (NEE's
                 density had every solve found the root; the 1/p of the
                 trials is an unbiased factor on top) and the vertex's own
                 pdf of w0. The forward path computes det J_plane for itself
                 from one shot along its own w0 with the same steps, so both
                 sides evaluate the same function of the path, and the two
                 weights sum to one (test/test_nee.c); any such weights keep
                 the sum unbiased. Near a fold caustic det -> 0 and the
                 forward path takes the path, which bounds NEE's 1/|det|
                 (unweighted, its square is not integrable there).
                 Everything else (reflected at a sharp interface, to the
                 sky, to the far side of a sphere light) only by forward
                 paths, weight 1. A shot refracts at a box's sharp face by
                 Snell's law, never reflects by chance, and carries the
                 transmitted share 1 - F (Fresnel) as a weight, its Jacobi
                 field through the refraction (rrv__shot_refracts); a
                 forward path that only refracted there shares its light
                 with shoot as anywhere else. The connection: a point y on a light (uniform
                 on a quad or triangle, p_area = 1 / (area x light
                 choices); on a sphere, where straight NEE's direction
                 in its cone meets the side x0 sees, p_area that density
                 times cos theta_y / |y - x0|^2, on the tangent plane
                 at y), Newton on the
                 two angles of the initial direction so that the ray,
                 traced with the same steps camera rays take, first crosses
                 the light's plane from its front at y (at most 20 shots,
                 residual < 1e-9 (1 + |y - x0|), step halved on a worse or
                 failed shot and doubled up to 1, at most 0.5 rad, given up
                 when three halvings in a row fail; det J = 0, a caustic,
                 fails); the density from the Jacobi field of the same
                 discrete steps, dw0 = dA_y / |det J_plane|
                 (= |cos theta_y| / |det J_perp|); visibility and
                 ratio-tracked transmittance along every chord. Two
                 tries split the roots between them: one from the
                 straight direction (deterministic: its root counts once,
                 weight 1), and half the time (always where the first
                 failed) one from random seeds (Gaussians of 0.05 rad, 6
                 in 10, and 0.3 rad, 3 in 10, around the straight
                 direction, or a uniform direction; up to 3 seeds), which
                 reaches every root with some probability q > 0; its
                 root, if not the first's, counts 1/(s q), s the random
                 try's probability, 1/q estimated by repeating random
                 solves until the same root (within 1e-5) comes back,
                 past 64 trials by Russian roulette (Specular Manifold
                 Sampling's estimate, E = 1/q exactly). So every root
                 counts once in expectation, and the root nearest the
                 straight line, usually the brightest, without the noise
                 of a 1/p estimate. A failed solve contributes zero. The
                 derivative of grad eta has closed
                 forms for the profiles and blobs; for grids (gridvol,
                 NanoVDB, baked noise, a gas through Hauf-Grigull) it is
                 the exact derivative of the blended gradient the rays
                 use. With the refractive integrator SHOOT aims (AIM).
     MANIFOLD    curved NEE by the paper's method (refractive and eikonal
                 integrators, the same closed-form Hessians), partitioning
                 path space by the same classes (weights: 1 for the estimator a
                 path belongs to, 0 for the others; power heuristic only
                 between straight NEE and forward paths outside supports).
                 A point y uniform on a quad or triangle light (sphere
                 lights: with eikonal SHOOT's connection, with the comb
                 left to forward paths); a chain of
                 vertices on comb planes along the chord x0 -> y (spacing
                 `step`, or none given as many planes as the eikonal's
                 placed steps along the chord, evenly spaced, since a
                 leapfrog of varying step is first order; random offset,
                 at most 512, wider beyond), each
                 kicking the ray as the comb does (eta d += grad eta h,
                 h the path it stands for); Newton on two unknowns a vertex
                 (gauge `manifoldgauge chord`, the default: in the comb
                 plane; `iso`: in the isosurface's tangent plane, the
                 paper's, undefined where grad eta ~ 0) until every segment
                 follows its kicked direction within 1e-9 rad. By
                 default a trust-region Gauss-Newton solves it (Newton's
                 step by block Thomas inside the radius, Powell's dogleg
                 outside; faster on every scene measured,
                 test/bench/RESULTS.md); `manifoldsolver lm` takes the
                 paper's solver, Levenberg-Marquardt (Levenberg 1944,
                 Marquardt 1963): steps from (J^T J + lambda S) delta =
                 -J^T r, S Marquardt's diagonal scaling (the largest
                 diagonal of J^T J so far), lambda by Nielsen's rule
                 (taken step: lambda *= max(1/3, 1 - (2 rho - 1)^3); refused:
                 lambda *= nu, nu *= 2), a step taken when it lowers |r|
                 (rho, actual over predicted reduction, > 0); J is block
                 tridiagonal with 2x2 blocks, so J^T J is block
                 pentadiagonal and is factored by a block LDL^T in O(n); a
                 refused step re-factors with the new lambda and evaluates
                 nothing again; at most 40 evaluations, and 12 in a row
                 without |r| halving (a local minimum). A root that is not a
                 physical path (a segment against its kick, a sharp
                 interface crossed) or where J is singular (a caustic)
                 fails. Either takes its last step unconfirmed where the one
                 before converged quadratically and the next residual is
                 predicted ~1e-3 of the tolerance. The density
                 dw0/dA_y from block Thomas elimination of J (the
                 generalised geometry term of Specular Manifold Sampling).
                 Each connection makes two tries, which split the roots
                 between them: one seeded on the chord (deterministic, so
                 its root counts once, weight 1) and, half the time
                 (always where the first failed), one from random seeds
                 (a mixture of Gaussians around the chord, 0.02 rad half
                 the time and 0.2 rad 3 in 8, and uniform), whose root, if
                 not the chord's, counts 1/(s q), s the random try's
                 probability and q the random seeds' of reaching it: 1/q by
                 repeating random solves until the root recurs (initial
                 directions within 1e-5), beyond 64 trials by Russian
                 roulette (trial i made with probability (64/i)^2,
                 counted as its inverse): E = 1/q exactly, at most 129
                 trials expected whatever q. A seed is traced through the
                 planes by the chain's own rule and shot at y (Newton on
                 the initial direction, the Jacobian carried through the
                 planes; at most 16 traces; where that fails, aimed by
                 differences, or a parabola where no trace reaches y's
                 plane), in two stages where that saves work, as shoot's
                 are: first a coarse chain (planes 8x as far apart, at
                 most 0.1 rad of bend a plane), whose shot to 1e-9 of a
                 spacing is its root, then the fine one solved from the
                 cubic through the
                 coarse root's vertices snapped to a 2^-20 m lattice; a
                 seed whose coarse solve fails, and one random seed in 16,
                 is solved on the fine chain directly, so no root of the
                 fine chain loses its probability. A try whose coarse root
                 snaps onto the chord's or the random try's takes that
                 polish's result: exact, as a polish depends on the
                 snapped root alone. `manifoldtrials 0` is this unbiased
                 estimate (for the chain model; the default). The chain
                 model itself is second order in its plane spacing: on the
                 Luneburg lens caustic at its 0.01 m spacing it renders 0.7 %
                 above forward paths, 0.2 % at 0.005, within 0.1 % of shoot
                 on heat caustics (test/bench/RESULTS.md). `manifoldtrials M`: M
                 solves, the chord's and M - 1 random ones, each distinct
                 root counted once (biased low where a root's basin is
                 small).
                 `manifolddrop D`: leave out comb planes across which eta
                 on the chord changes by less than D (faster, biased; 0, the
                 default, keeps all). Unsupported IORs as for shoot.
     AIM         bent shadow rays (refractive comb and eikonal integrators;
                 the Poisson and midpoint schemes, whose rays bend at null
                 events, leave curved connections to forward paths, counted
                 in rrv_render_stats.solves_unsupported). The classes are
                 SHOOT's; for a curved one, a point y uniform on a quad or
                 triangle light, or straight NEE's direction in a sphere's
                 cone, gives w0 = (y - x0) / |y - x0|, and the
                 shadow ray leaves x0 along w0 bent as camera rays are (the
                 same comb kicks or eikonal steps), its transmittance
                 ratio-tracked chord by chord; the light's radiance counts
                 if the ray lands on that light's front, nothing if it meets
                 anything else, leaves, or is reflected at a sharp
                 interface (it refracts there as camera rays do, and a
                 forward path that a face reflected keeps weight 1). w0 has
                 the density of the straight line from x0 along w0 meeting
                 the light, (|y - x0|^2 / |cos theta_y|) / (area x light
                 choices), whichever face it meets: a function of w0 alone,
                 so the power heuristic against the vertex's pdf of w0 is
                 exact, and a forward path that reaches the light from x0
                 along w0 takes the complementary weight wherever it lands
                 on it. Unbiased for the integrator's own rays, no solve, no
                 trials; as with NONE, focusing shows only as noise, so it
                 suits weak heat haze (nearly every aimed ray lands) and not
                 the caustics of small lights, which SHOOT solves.
     The weak class (shoot, manifold and aim): a connection from x0 to y whose
     straight chord touches no refraction support (or only supports with
     zero gradient along it) is straight NEE's, with the ordinary MIS
     weights; curved NEE skips it. A forward path that crossed no sharp
     interface and ends at y (or leaves for the sky along d) is sorted by the
     same function of its two ends, and, if its chord is weak but the path
     itself turned (it left x0 at an angle to the chord larger than the
     chord's bound on bending), it is another root of those two ends that no
     light sample stands for. With aim it counts with weight 1; with shoot
     and manifold it is shared by the power heuristic with one more ray a
     vertex, drawn uniformly in the cone of a strongly refracting support
     (one that can turn a ray by more than 0.05 rad across it: a lens) and
     traced bent, which counts the light it lands on only for such roots
     (rrv__cone_nee; the cone's density is a function of x0 and w0, so the
     weights are exact). A build may set
     RRV__WEAK_BEND to K > 0 to treat chords whose bound on bending (the
     integral along the chord of each majorant cell's max |grad eta| over
     the lowest eta) is at most K bend tolerances as straight too: on weak
     heat haze that makes curved NEE cost ~1.3x straight NEE instead of
     ~36x, but it is biased where a strong medium's gradient varies within
     a cell (measured in test/bench/RESULTS.md, "Weak connections"), so it is off.

   EMISSIVE MEDIA AS LIGHTS (rrv_settings.emission_nee, scene `render
   emissionnee on|off`; by default a draw of their own at every vertex
   where the scene has no light shape, a sky or not; beside light shapes a
   share of theirs, in proportion to power; under `lightsampler uniform`,
   on only without a light shape or a sky. `on`: a draw of their own
   beside the light shapes' too; `off`: only the paths find them)
     Media that emit (Le, or a blackbody temperature) are sampled as lights
     at real vertices, as the area lights are. Beside light shapes, one
     draw a vertex picks the emitters with probability P and each shape
     by (1 - P) times its own share: under the classic integrator P =
     W_E S(x) / (W_E S(x) + W_L G_L(x)), power over squared distance as
     the emitter sampler weighs its blocks (below; G_L of a box around all
     the light shapes, W_L their weight, W_E the emitters' power over pi:
     4 times the cells' weights times their volumes, as a unit volume
     radiates 4 pi sigma_a Le where a unit area of light shape radiates pi
     L), so a wall beside a flame gives it most of its samples and smoke
     beside a lamp the lamp; under the refracting integrators, whose
     curved estimators read one P, P = W_E / (W_E + W_L). Every density
     the MIS weights read carries its P, so a forward path weighs the
     emission it meets against P p_nee and the light it hits against (1 -
     P) p_light, whichever way the draw went, and an equiangular sample
     (whose own pick is the light shapes') weighs a vertex's light sample
     with the P at its point (a draw of their own beside a light that
     outshone them measured 0.46x, none at all 12x worse where they light
     most of the room: test/bench/RESULTS.md, "Fire beside a light"). A
     point y of an emissive
     medium is drawn from an emission grid prepare builds beside the
     majorants (at most 32 cells along a medium's longest side, each
     weighted by its sigma_a Le at the centres of its octants, floored at
     a thousandth of a bound of it, times the mean transmittance out of
     the grid along the six axes, floored at 0.02, so that the cells a
     thick flame hides take fewer samples; blocks of 8^3 cells picked by their
     weight over max(r^2, radius^2) from the vertex, in two steps: first
     one of the blocks of 2^3 such blocks, then a block in it), joined to the vertex by a straight
     shadow ray whose transmittance is residual-tracked under the default
     estimator (a scene's `transmittance` choice stands) (not from
     vertices scattering inside an emitter's box, where the path's own
     collisions, which follow the transmittance, do better), and weighed
     by the power heuristic against the emission the path collects at its
     tentative collisions: p_nee(y) per unit volume against p(w) sigma_t(y)
     / r^2, the vertex's density of the direction times the medium's
     extinction in the majorant's place, over the Jacobian r^2 (the
     derivation above rrv__chord_meets_refraction). The two weights are
     functions of the vertex and y alone and sum to one
     (test/test_emission.c). Unbiased: against forward-only renders in
     blocks and against a slab's closed-form irradiance, within 4 standard
     errors. Kirchhoff's law is as for the paths (a blackbody seen from air
     does not dim by 1/n^2). Inside a medium that emits, a real collision
     always scatters, weighted by the albedo (sigma_s over sigma_t), and
     the roulette leaves such vertices alone: the light a flame scatters
     toward a room otherwise came from the rare paths that chance let
     scatter, each with the flame's whole radiance (test/bench/campfire.rrv
     at maxdepth 32: 1.6x -> 4.2x; test/test_emission.c checks it against
     chance in every channel). Where the air refracts, a sample whose
     chord meets the box of a refracting medium is aimed, not connected:
     the vertex walks the bent ray that leaves along the chord's direction
     as the path would (kicks, faces, delta tracking) and collects the
     emission it meets past that box's first face, weighed by the power
     heuristic in solid angle, against the path's own emission there: the
     density of a direction is that of the sampled points on its line past
     the face, exact from the grid (rrv__emission_dir_density). So fire
     inside hot air lights a room too (scenes/pyro.rrv's kind); a walk
     stops at a sharp face, past which the paths keep weight 1. Measured on
     test/bench/campfire.rrv (test/bench/RESULTS.md, "Fire as a light").

   EQUIANGULAR SAMPLING (rrv_settings.equiangular, scene `render
   equiangular on|off`; by default toward the light shapes whose centre
   lies in a scattering medium's box, nowhere else)
     The classic integrator also draws one distance a segment through a
     scattering medium by the equiangular density toward a light's centre
     (1 / r^2 from it), connects it to the light as straight NEE does, and
     weighs it by the power heuristic against the free flight's light
     sample and phase sample; the free flight's density, which a
     heterogeneous medium does not give in closed form, enters the weights
     as sigma exp(-sigma (t - a)) of the local mean extinction (any shared
     function of t keeps the sum unbiased; the derivation above
     rrv__light_centre). Segments whose ray meets two scattering media's
     boxes, and the refracting integrators, keep free flights alone.
     Measured (test/bench/RESULTS.md, "Equiangular samples"): a lamp in fog
     3.3x the efficiency of free flights alone; forced on toward a light
     outside dense smoke 0.81x, hence the default. Scenes where it stays
     off render as before, draw for draw.

   LIGHT SAMPLING (rrv_settings.light_sampler, scene `render lightsampler
   power|uniform`, pbrt-v4's names; power by default)
     A vertex's one light sample goes to one light, picked by `power` in
     proportion to its power (area times mean radiance; quads and
     triangles emit on one side; emissive media beside them by default
     take their share of the same pick, EMISSIVE MEDIA AS LIGHTS), and the
     sky only where there is no light shape and no emissive medium to take
     them: the sky's samples go in uniform directions, which a vertex's
     own phase or cosine sample matches or beats, so beside a light shape
     they only took its samples away, and the paths' own directions reach
     the sky with MIS weight 1 (pbrt-v4 leaves a uniform sky to BSDF
     sampling too). `uniform` picks every light shape and the sky alike,
     as rrv did before 0.13. Measured (test/bench/RESULTS.md, "Light
     sampling"): smoke 2.0x, plume 1.6x, luneburg 1.4x the efficiency of
     uniform; no bench scene slower beyond noise.

   BOUNDARIES (design decisions)
     Faces of refractive media (a medium's box; the sphere of a Luneburg or
     fish-eye profile) end every straight segment. An IOR that jumps across
     a face is a sharp interface: refracted once by Snell's law with the
     face normal, reflected with the Fresnel probability or by total
     internal reflection; such reflections count toward max_depth. A medium
     whose IOR equals the ambient IOR everywhere does not refract. The
     ambient IOR (rrv_settings.ambient_ior, scene `ambient ior`) left 0 is
     that of the air a gas medium (ior ... gas) sits in: the same gas
     relation at its ambient state (T_ref, P_ref, what its fields give
     outside their boxes), 1 + iorscale (eta_ref - 1), from the first gas
     medium listed; 1 without one. So a plume whose faces are at the
     ambient state has no jump whatever its iorscale; a given `ambient ior`
     is used as given. A jump that remains (a field that does not end at
     the ambient state, glass, a second gas with another iorscale) is a
     sharp interface: rrv_medium_face_jumps measures it per face and
     `rrv info` and the render summary report it. Outside an
     IOR grid's own box (inside its medium's) the IOR is the ambient one,
     unscaled by ior_scale.

   IOR GRIDS (rrv_settings.ior_interpolation, scene `render iorinterp`)
     Where the refractivity r = eta - 1 comes from a grid (IOR, gas state or
     baked noise), prepare bakes it. TRILINEAR, the default: r trilinear and
     grad r the trilinear blend of central differences, 16 bytes a sample.
     That pair is only C0 and its gradient is not the value's derivative, so
     on grids the comb and RK4 lose their orders (fitted 1.3 to 2.1 and 1.3
     to 2.0; between neighbouring comb rates anywhere from 0.03 to 5.7).
     CUBIC: the interpolating tricubic B-spline of r (end slopes from
     one-sided differences, so cubics are reproduced), value and gradient
     from one C2 function, 8 bytes a sample: the comb is second order and
     RK4 third (2.9 to 3.9 measured) on grids, and rays through grids of
     smooth fields land 65x to 550x closer to the fields' own, for ~1.4x the
     time a comb kick and ~1.5x an RK4 step (test/bench/RESULTS.md, "On IOR grids";
     test/measure_grin.c grids). It rings (alternating, 0.27x a voxel) next to
     features under ~2 voxels wide, where trilinear stays more faithful:
     hence an option, not the default. Its value is floored halfway between
     the lowest sample and -1, so eta stays positive where it overshoots.

   BOUNDS
     No input may hang a render, overflow a pixel or exhaust memory. Refused
     at load with file:line: message (rrv_scene_prepare checks the media once
     they are complete and names the statement that broke a limit; line 0 for
     scenes built in code):
       - an IOR outside [RRV_MIN_IOR, RRV_MAX_IOR] = [0.1, 10] anywhere in a
         medium's box, from any field kind or the gas state: beyond it rays
         are trapped or the radiance scale (eta_camera / eta)^2 explodes, and
         no transparent material comes near 10;
       - a peak extinction times the medium's size (its diagonal, or its
         distance from the origin if larger) above RRV_MAX_OPTICAL_DEPTH =
         1e12, or a density beyond float: the mean free flight must stay
         thousands of rounding steps of the coordinates long, or tracking
         stalls (an extinction of 3e38 gave flights of length 0);
       - emission (L x scale, Le x Lescale) above RRV_MAX_RADIANCE = 1e20:
         2^24 samples of it stay 1e11 below float's range;
       - an ambient IOR above 10, a bend tolerance below 1e-4, mu_eta above
         1e6 /m, an eikonal step outside [1e-6, 1e6] m (scene and CLI);
       - a majorant or baked grid above the grid limit (max_grid_bytes);
       - more than RRV_MAX_BLOBS = 4096 blobs in one field (every lookup
         sums them all: a grid is the tool for more).
     Cut and counted (rrv_render_stats.paths_cut, of them cut_tracking and
     cut_samples):
       - a tracking walk (one medium along one straight segment) after
         64 + 4 (peak majorant x chord) tentative collisions (the majorant
         of the channels it walks for: a channel whose extinction is 4x
         below the densest walks with one of its own), at most
         RRV_MAX_SEGMENT_EVENTS = 2^22: the count is Poisson with a mean of at
         most the second term, so a correct walk never gets there (P < 1e-30);
       - a leg of a path (between two real vertices) after 64 + 16 times the
         loop iterations of one straight crossing of every medium at its
         densest rate (comb kicks, null events, or 4 / step eikonal steps),
         at most RRV_MAX_SEGMENT_STEPS = 1e7: only trapped rays get there;
       - a camera path (one pixel sample; of paths_cut, cut_samples) when
         its loop iterations over all legs plus the tentative collisions it
         and its shadow rays sampled pass 4 (max_depth + 1) (64 + 16 (1 +
         one crossing's iterations and collisions at the peak majorant)):
         a leg and a shadow ray a vertex, each at the leg bound with a
         collision every iteration, which a path whose legs are within
         their bound passes only with collisions beyond 16 crossings a
         leg; at most RRV_MAX_SAMPLE_WORK = 2^24 (a second of one core in
         eikonal steps): legs each within their bound, 1025 of them (an
         eikonal step of 1e-6 m in a closed white room) were minutes a
         sample. It is checked once a loop iteration, so a sample overruns
         it by at most one walk and one vertex's light sampling. The
         scenes in scenes/ stay 310x below the cap with every integrator,
         NEE and scheme, and 7x below their own term (test/bench/RESULTS.md).
       - a ray trapped in a refracting medium (of paths_cut, trapped_paths):
         one whose run through the refraction supports since its last
         vertex (real, or a reflection at a face) passes 2.83 times the sum
         of the refracting boxes' diagonals, the longest straight run
         through them all (rrv__trap_length). That is a bound in the
         scene's scale, where the leg bound above counts iterations, which
         a thin feature's fine comb makes dense: a ray circling in the 1 mm
         layer of a shell of IOR 3 (a kick every 1.7 um) is ended after
         10.8 m instead of 14 (the sample's bound), in a 5 cm layer after
         1.3e5 kicks instead of 7.3e5. Safe: a walk that turns by at most a half circle in all
         (kicks, steps, refractions at faces summed) runs at most 2 sqrt(2)
         times that sum inside the boxes (split it where it has turned half
         of it: each half keeps within 45 degrees of its middle direction,
         so it advances along it by 1/sqrt(2) of its length, and in each
         box by at most the diagonal), so only a ray that turned by more
         than a half circle without a vertex is ended: one circling in a
         waveguide or an orbit (a camera or a scattering point inside a
         shell's layer of high IOR, inside Maxwell's fish-eye). The scenes
         in scenes/ stay 2.9x below it with the comb, Poisson and eikonal
         (test/bench/RESULTS.md). The schemes that refract at null events keep the leg
         bound alone: the midpoint scheme's first-order error sends rays
         from outside a Luneburg or fish-eye lens into orbits that leak out
         again past this bound (5.8% of luneburg.rrv's camera paths at 1
         spp), and ending them darkened those renders by 8% and 13%; the
         seed's Poisson events stay below it, but a bound that hangs on the
         scheme's error is not one to trust. The light such a ray would still gather is lost, as
         at the leg bound: none, for good, in an orbit without extinction
         or surfaces; that of a fibre that lets it go after more than the
         bound, or of a medium it would scatter in later. Its cost is an
         addition a segment and a comparison a loop iteration.
     A cut camera path keeps the light it gathered before the cut; a cut
     shadow ray is dark. That is biased, so it is never silent: the CLI's
     summary line prints the count. A sample above RRV_MAX_SAMPLE = 1e30 is
     discarded as non-finite; pixel sums saturate at FLT_MAX. To keep cuts
     rare, majorant cells follow the density voxels where a cell would hold
     an optical depth above 64 (split into equal parts where fewer than 16
     would cross the box, each bounded exactly; beside a grid's faces the
     cells bound 0), and RK4 halves steps that span a feature of the IOR.
     What is left is heavy-tailed: a path that scatters in the thin layer
     where a grid's density rises from 0 pays null collisions to leave it,
     about (cell size) x sqrt(2 x slope of the extinction) of them, so a
     2^3 grid of 7e10 on one face in a 2 m box takes ~3e5 events a sample
     at 16 cells an axis (test/test_budget.c).


   FILE FORMATS AND SNELL'S LAW (from CONVENTIONS above)
     Grids ("gridvol", as defined by Mitsuba 0.6), all little endian:
       3 bytes "VOL", 1 byte version 3, int32 encoding 1 (float32),
       int32 xres yres zres (each >= 2), int32 channels (1 or 3),
       float32 box xmin ymin zmin xmax ymax zmax, then float32 samples at
       index ((z*yres + y)*xres + x)*channels + c.
       Samples sit on corners: sample i along x is at xmin + i*(xmax-xmin)/
       (xres-1), so the first and last lie on the box faces. Outside the box
       a field takes its ambient value. A file is refused (with the reason)
       for a wrong magic or version, a resolution < 2 or an overflowing
       size, a byte count that does not match, an empty or non-finite box, a
       NaN or infinite sample, or a negative density.
     NanoVDB grids (.nvdb, NanoVDB 32.x as nanovdb_convert writes them,
       little endian, uncompressed; float, fp4, fp8, fp16, fpN): value ijk
       sits at world map * ijk + translation (the grid's own map), trilinear
       between index points; where no data is stored, the grid's background,
       and an IOR grid beyond one voxel past its data is the ambient IOR.
       Every offset is checked against the grid's buffer and every value
       must be finite; negative densities count as 0. See rrv_nanovdb.
     Snell at a null event: ratio m = eta_i / eta_o, normal n = grad eta / |
       grad eta| facing the incoming ray, c = -n.d, k = 1 - m^2 (1 - c^2);
       k < 0 reflects (d + 2 c n), else d' = m d + (m c - sqrt(k)) n, written
       as a change of d so that m ~ 1 does not cancel.

   THE DEFAULT INTEGRATOR, the rule
     rrv_scene_integrator: classic where no medium's IOR differs from the
     ambient one; eikonal with nee SHOOT where every refracting medium is
     clear (no medium with extinction overlaps its box), a light is small
     from one (its side, the square root of its area, or a sphere's disc's,
     under 0.7 x its distance from the medium's box centre), the IOR has
     the Hessian shooting needs and no Luneburg or fish-eye sphere's
     surface is a jump (shots refract at a box's sharp faces, not at a
     sphere's); refractive (the comb, nee AIM) otherwise.
     An explicit `nee` other than shoot keeps the comb. Classic's chromatic
     media: channels whose extinctions differ more than 4x walk with
     majorants of their own (spectral MIS).

   THE DEFAULT INTEGRATOR, why
     Aimed shadow rays sample the light's straight cone, at about straight
     NEE's cost, which is right while bending is small against the light's
     angular size, but a caustic of a small light lies outside that cone and
     only forward paths find it (noise); shooting solves the bent connection,
     at 4x-50x the cost a sample, which pays where the receivers are surfaces
     seen through clear media, and not where a scattering medium makes every
     vertex a connection. Measured in test/bench/RESULTS.md ("Which integrator
     by default"): within 1.25x of the best unbiased mode on the bench scenes.

   EIKONAL MARCH, flat cells
     In a medium box (not a Luneburg or fish-eye sphere), the majorant cells
     whose bound on |grad eta| is 0 hold a constant IOR and are crossed in one
     straight segment, steps ending where they begin, as at a face.

   TRANSMITTANCE, in detail
     The majorant grid also keeps a per-cell minorant (a true lower bound of
     the density, rounded down); `residual` integrates it exactly and
     ratio-tracks only what lies above it; `march` is unbiased ray marching: a
     jittered march (2 points a unit of the residual majorant's optical depth,
     the minorant exact) gives a pivot optical depth p, and exp(-tau) =
     exp(-p) sum_j (p - tau)^j / j! is estimated term by term from independent
     marches, truncated by roulette. Per shadow ray march has 1/6 to 1/9 of
     ratio tracking's variance x cost on plume, pyro and haze, but in whole
     renders shadow rays are a small part of the noise and march's extra work
     about cancels its gain, so ratio stays the default
     (test/bench/RESULTS.md, "Transmittance"), except for the shadow rays
     of emission NEE, which end inside the emitter's dense core that the
     minorant covers: residual there (campfire at maxdepth 32, 5.0x -> 5.7x
     over paths alone; RESULTS.md, "Emission NEE's cost per vertex"). Where a cell's density is
     constant, residual and march are exact there. March's estimates are
     signed (rarely negative); they are added as they are. Refracting media:
     every straight chord of a bent shadow ray is estimated the same way.

   RRV_NO_POSIX, in detail
     By default, where __unix__ or __APPLE__ is defined, the implementation
     uses POSIX's open, fstat and fcntl (and stat beside the writers' rename):
     every reader opens without blocking and refuses what is not a regular
     file (a FIFO, a device, a folder: rrv_open_read), the writers refuse such
     a target and create their temporary file exclusively. With RRV_NO_POSIX,
     or elsewhere, they use fopen alone: a FIFO given as input blocks until a
     writer opens it, an endless device is read up to the size limit, and a
     device node at a writer's target is replaced. The POSIX calls come from
     <fcntl.h>, <sys/stat.h> and <unistd.h>, which glibc declares under
     -std=c99 too, except fdopen: rrv.h declares that one itself (in C), so
     the header works after any includes of the user's. A libc that hides more
     under strict C wants _POSIX_C_SOURCE 200809L before its first header, as
     rrv_impl.c defines it.

   BUILD SWITCHES, in detail
     RRV_NO_SCENE_FILE no .rrv parser, OBJ loader or gridvol reader: scenes
                       are built with rrv_scene_create and rrv_scene_add_* /
                       set_* (a grid field's samples given in rrv_field.grid).
                       rrv_scene_load, rrv_scene_parse, rrv_grid_read and
                       rrv_grid_read_memory refuse.
     RRV_NO_NANOVDB   no NanoVDB reader: rrv_nanovdb_read and
                       rrv_nanovdb_read_memory refuse, and so do a scene's
                       `nanovdb` statement and a NANOVDB field (no grid can
                       be validated without the reader). The small lookups
                       (rrv_nanovdb_voxel, rrv_nanovdb_sample) stay.
     RRV_NO_EXR       no OpenEXR writer or reader (nor their inflate):
                       rrv_write_exr, rrv_write_exr_to, rrv_read_exr,
                       rrv_read_exr_memory and rrv_exr_find_attribute refuse
                       (the last, which has no rrv_error, by its result);
                       rrv_half_from_float stays.
     RRV_NO_PNG       no PNG writer: rrv_write_png and rrv_write_png_to
                       refuse. With RRV_NO_EXR too, deflate goes as well;
                       rrv_crc32 and rrv_adler32 stay.
     RRV_NO_CURVED_NEE no solvers of nee shoot and manifold (and the cones
                       that go with them; nee aim stays). NEE_SHOOT or
                       NEE_MANIFOLD asked for is refused, not replaced: by
                       the scene's `render` statement, rrv_scene_set_settings
                       and rrv_scene_prepare, and by rrv_render_rect for
                       settings edited after prepare. Unasked, the defaults
                       follow the rules for a scene no solver supports: the
                       default integrator is never EIKONAL for its shooting
                       (INTEGRATORS, "default"), and NEE_DEFAULT aims, as
                       the refractive integrator's does.
                       main.c builds with each switch (a RRV_NO_SCENE_FILE
                       CLI only says so, since it reads scene files); its
                       render refuses -o .exr, --png and --nee shoot or
                       manifold before rendering when they are left out.
     RRV_RESEARCH     the opposite way: it keeps two variants that lose
                       every row test/bench/RESULTS.md measures, which a
                       default build refuses (RRV_ERROR_UNSUPPORTED, by the
                       scene's `render` statement, rrv_scene_set_settings,
                       rrv_scene_prepare and rrv_render_rect, as above; the
                       CLI's --refraction and --stepper before rendering):
                       REFRACTION_MIDPOINT, the seed's Snell events with the
                       normal at the chord's midpoint (first order, 4.3e-4
                       on the Luneburg lens at 1000 events/m where the comb
                       reaches 6.9e-8 at 100 kicks/m in a sixteenth of the
                       time; POISSON stays, as the paper's reference), and
                       STEPPER_LEAPFROG for eikonal (second order: 6.3e-6 at
                       h = 0.01 in 39 us a ray where RK4 reaches 3.2e-8 at
                       h = 0.1 in 7 us; it takes no placed steps). Their code
                       stays, tested (test/internals.c defines the switch),
                       so results of either can be reproduced.

   FILES, in detail
     Every input is untrusted and read with bounds, and only from a regular
     file (rrv_open_read; a FIFO or a device is refused at once, unread):
     a scene, OBJ or NanoVDB file up to rrv_load_options.max_grid_bytes (a
     larger one refused by its size before any byte is read), a gridvol's
     48-byte header and then exactly the samples it announces, a PFM
     header and then exactly the pixels it announces (more than the file
     holds is refused by its size), an OpenEXR file whole (up to 2 GiB)
     with every offset and size checked against it. Scene numbers are
     decimal (no hexadecimal) and read the same in any locale. The file
     writers replace their target through a new temporary file and refuse
     a target that is no regular file; rrv_write_pfm says how links are
     treated and what plain C cannot promise there.
     Images out: rrv_write_pfm (float), rrv_write_exr (OpenEXR scanline, half
     or float, ZIP or uncompressed, a crop placed in a larger display
     window; rrv_half_from_float is its rounding), rrv_write_png (8-bit sRGB
     preview), each also as a *_to form writing through a callback. Images
     in: rrv_read_pfm, rrv_read_exr (scanline RGB, NONE, RLE, ZIPS or ZIP),
     and their *_memory forms.

------------------------------------------------------------------------------
VERSION HISTORY
------------------------------------------------------------------------------
     0.20.0 emissive media beside light shapes share each vertex's light
            draw with them (the default emissionnee, power light sampler):
            classic by power over squared distance at the vertex, the
            refracting integrators by power; before, one light shape left
            a flame to the paths (campfire beside a fill light: 8-20x the
            efficiency of the old default); rrv info prints the share;
            NanoVDB trilinear lookups read a leaf's eight corners at once
            (renders bit-identical, a smoky NanoVDB fire 10.6 % fewer
            instructions); fixed: nee shoot's Jacobian of a step cut at a
            face took the end's turning for the step map's derivative in
            its length, which a face that ends the gradient breaks (shoot
            3-5 % low past grid plumes' faces; |det| now within 1e-4 of
            finite differences), and a trilinear grid's Jacobi field takes
            eta's own slope where the ray equation divides by eta
     0.19.0 curved connections take IOR jumps up to 1e-6 (RRV_SMOOTH_JUMP)
            as smooth, not 1e-7: the Gaussian tail of a hot blob leaves
            1.4e-7 at the faces of README's heat caustic box at iorscale
            450, which sent the default from chains to shoot there (2.1x
            less efficient) and gave an explicit nee manifold fireflies;
            such jumps are still reported, and the render summary says
            that curved nee passes them; the midpoint scheme and the
            leapfrog stepper, which lose every measured row, are left out
            of a default build (refused, naming RRV_RESEARCH, which keeps
            them; test/internals.c and the tables build with it); emission
            NEE weighs each emission cell by the media's mean transmittance
            out of the grid (campfire 14.9x -> 21.9x forward paths'
            efficiency at maxdepth 1, 5.7x -> 6.3x at 32); fixed: a forward
            path that crossed a sharp face to a light along a weak chord's
            other root took weight 1 (manifold, +10 % there) or shoot's
            (-1.5 %) while the cones also counted it; it takes the cones'
            complement
     0.18.0 the default nee solves chains (nee manifold, the paper's
            method) with the eikonal integrator where the refracting
            media are clear, weak gas without sharp faces (the heat
            caustics); eikonal's nee manifold shoots at sphere lights
            (left to forward paths before); the manifold's default solver
            is the dogleg (`manifoldsolver lm` the paper's); an explicit
            nee manifold without an integrator key takes eikonal where
            shoot would; rrv_scene_nee, and `rrv info` prints the nee:
            the default 2.5x 0.17.0's on the fire caustic, 1.35x on the
            heat shadow; chains on placed steps space their planes
            evenly (the kicks' second order: a plume's bias against
            shoot +0.46 % -> +0.012 %)
     0.17.0 nee manifold's chains are seeded by shooting (Newton on the
            initial direction with a Jacobi field through the planes): the
            coarse stage's shot is its root; the dogleg's last step is
            taken unconfirmed after quadratic convergence: lens caustic
            1.45x the efficiency (dogleg), fire caustic and heat shadow
            ahead of shoot
     0.16.0 nee aim and shoot cross a box's sharp interfaces (refracted
            as camera rays are, shots weighted by 1 - F with their Jacobi
            field through Snell's law; a reflected path is the forward
            path's), and the default shoots under a small light whatever
            the box's faces: a hot-air box whose faces miss the ambient
            IOR 9.5x (aim), glass under a small light ~2000x; blast 1.16x;
            the chain's gradient and its derivative from one lookup
     0.15.0 nee shoot and manifold split a connection's roots between a
            try from the chord (its root counted once, weight 1) and a
            random try (the others, 1/(s q)): shoot 1.8x (lens caustic)
            to 3.8x (fire caustic) the efficiency, renders of curved NEE
            change within their noise; the manifold's seeds start on the
            chord, its Jacobian blocks from dot products
     0.14.0 eikonal steps placed by the field where no step is given
            (a bend tolerance of turn each, at most a majorant cell, at
            least 0.01 m; shoot's Jacobi fields follow the steps' lengths):
            heat_shadow 2x the efficiency; a given step is fixed as before
     0.13.0 light samples by power (render lightsampler power|uniform):
            light shapes in proportion to their power, the sky only where
            it is the only light (smoke 2.0x, plume 1.5x the efficiency;
            renders of scenes with a sky and a light shape change, within
            their noise); where there is no light shape, emissive media
            take the samples a sky would have had (emission NEE on by
            default under a sky too); equiangular samples toward lights
            inside media (render equiangular); emission NEE picks a
            cluster in two levels and tracks its shadow rays with residual
            ratio tracking; the Sobol sampler a little cheaper (renders
            identical)
     0.12.0 fire lights a room with less noise: in media that emit, real
            collisions scatter weighted by the albedo and the roulette
            spares their vertices (renders of emissive media change, within
            their noise); the blackbody from a table prepared per scene
            (within 1e-6 of the sum, 82 exp -> 3); emission clusters keep
            their radius (renders identical); emissive media are lit
            through refracting air: a sample whose chord meets a
            refracting box is aimed along the bent ray and weighed in
            solid angle (rrv__emission_aim)
     0.11.0 adaptive sampling (rrv_render_rect_adaptive, --noise-threshold,
            `render noisethreshold`; off by default, biased by its stop);
            the scene-building calls a core section of their own and each
            optional module one block; the tracer reaches curved NEE through
            one interface of five calls; the manual in 200 lines; README's
            commands run by make test; rrv__grid_range faster (renders
            identical)
     0.10.0 the integrator chosen from the scene when it names none (classic
            where nothing refracts, eikonal with nee shoot for clear media
            under small lights, else the comb aiming), the ambient IOR from
            the gas, face jumps reported; the paper's solver a real
            Levenberg-Marquardt (the dogleg selectable); shoot's and
            manifold's 1/p exact by roulette past 64 trials; curved NEE to
            sphere lights; emissive media as lights (emissionnee); shadow
            rays' transmittance selectable (ratio, residual, unbiased
            ray marching); Sobol points for every dimension of a path;
            the eikonal march crosses cells without a gradient straight;
            build switches RRV_NO_SCENE_FILE, NANOVDB, EXR, PNG,
            CURVED_NEE; no function over 150 lines
     0.9.1  the refraction floor measured per sample (the comb without
            kicks costs 1.40x / 1.51x classic's instructions on fire /
            haze, above the 1.25x target; test/bench/per_sample.py);
            cheaper looks for faces and majorant iterator set-up, the next
            kick's cell prefetched (bit-identical); rrv info and
            rrv_medium_channel_groups show a medium's channel groups; a
            camera frame from vectors whose squares underflow is unit
     0.9.0  channel groups: channels whose extinctions differ more than 4x
            walk with majorants of their own (a thin channel no longer
            takes a dense one's collisions: sigma_t 4, 6e10, 6 per metre
            took 4e6-collision walks); with that, the Sobol sampler is the
            default (lens caustic, 1 m light: shoot 7x none, from 1.6x);
            free flights drawn as an optical depth walked through the
            majorant cells (one random number a collision, not a cell)
     0.8.0  one light draw a vertex shared by straight and curved NEE;
            eikonal steps skip their support looks inside a safety ball
            (bit-identical); shoot's coarse stage capped at 0.6 rad a
            step; the Sobol sampler measured on every scene (up to 6x
            less variance where light is sampled through refraction:
            lens caustic, 1 m light, shoot 7x none with sobol), not yet
            the default
     0.7.0  nee shoot and manifold also draw rays toward strongly
            refracting supports, for the roots of weak chords that
            forward paths carried alone (the heavy tail of small-light
            caustics); shoot's solves 1.7x-3x cheaper (steps and Jacobi
            fields share lookups, fused profile and gas evaluations);
            comb chords' walks and set-up cheaper (refraction 2.30x
            classic on fire, 2.28x on haze, from 2.38x and 2.39x)
     0.6.0  nee aim: bent shadow rays aimed at light samples, unbiased at
            about straight NEE's cost, the refractive default (as shoot);
            shoot's solve 3.4x cheaper on haze (fused Jacobian
            lookup, polish memo, the root's own chords); cheaper faces of
            refractive boxes (float rounding is no interface); a comb
            spacing bounded by the gradient's variation, measured and
            left off
     0.5.0  unbiased NEE by default (shoot: curved connections solved with
            the eikonal integrator, left to forward paths with the
            refractive one); shoot shares paths with the
            forward path by MIS; manifold's kick model, trust region and heap
            scratch; exact derivatives of every IOR kind's gradient, so both
            run in grids and gas states; exact majorants of coarse grids;
            the comb's rate integrated cell by cell; scenes fire_caustic and
            haze
     0.4.0  scenes built in code (rrv_scene_create and friends: zero means
            default, one check per object, the parser a client); nee manifold
            (the paper's refractive ratio tracking); Sobol sampler; parallel
            set-up (parallel_for); cheaper comb spacing; errors from
            rrv_render_rect and the writers; deflated PNG; EXR attributes
     0.3.0  boundaries: support faces are sharp interfaces (Snell, Fresnel,
            total internal reflection) in every integrator; work bounds and
            load-time limits; nee none|straight|shoot; OpenEXR in and out;
            NanoVDB grids; cubic IOR grids; one segment planner shared by the
            path tracer and rrv_trace_ray
     0.2.0  refraction: IOR fields (gas state, profiles, grids), refractive
            and eikonal integrators, rrv_trace_ray
     0.1.0  classic null-scattering path tracer, scene format, image I/O
*/

/*
------------------------------------------------------------------------------
LICENSE (MIT)
Copyright (c) 2026 the rrv authors
Permission is hereby granted, free of charge, to any person obtaining a copy of
this software and associated documentation files (the "Software"), to deal in
the Software without restriction, including without limitation the rights to
use, copy, modify, merge, publish, distribute, sublicense, and/or sell copies
of the Software, and to permit persons to whom the Software is furnished to do
so, subject to the following conditions:
The above copyright notice and this permission notice shall be included in all
copies or substantial portions of the Software.
THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
SOFTWARE.
------------------------------------------------------------------------------
*/
