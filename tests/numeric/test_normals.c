/* Surfaces of a field whose density is known in closed form: one dense hash-grid level holds
 * log sigma = a (z0 - z) (a plane) or a (R - |x - c|) (a sphere) at its vertices, and the
 * density network passes that feature through unchanged, so sigma = exp(that) in 1/m (the
 * field's cube is the unit cube of the world). Then
 *   - fg_field_density_gradient matches the central difference of the closed form;
 *   - fg_field_render_normals gives unit normals, exactly +z on the plane, -grad sigma at the
 *     expected termination point on the sphere (radial up to the hash grid's interpolation),
 *     and (0, 0, 0) for rays that see nothing;
 *   - fg_voxel_alpha and fg_mesh_marching_cubes put the sphere's mesh where alpha = 1 - exp(-
 *     sigma voxel_size) crosses the threshold, closed, with outward normals;
 *   - fg_field_colour and fg_mesh_colour give the colour network's output (zero weights:
 *     sigmoid(0) = 0.5, so 128 in 8 bits);
 *   - fg_field_render_image of a camera above the plane, over more than one chunk of rays:
 *     depth 500 mm along the optical axis at every pixel, normals +z, colour the rounding of
 *     fg_field_render_camera's; fg_heatmap_render_view of a random field with features is
 *     byte for byte the blend of fg_field_render_camera's colour and scored features. */
#include "field/image.h"
#include "field/model.h"

#include <stdint.h>

#include "core/error.h"
#include "core/rng.h"
#include "field/occupancy.h"
#include "io/camera.h"
#include "query/colormap.h"
#include "query/heatmap_view.h"
#include "query/geometry.h"
#include "test.h"

#define LEVEL 4     /* the finest dense level of the default density grid (57 cells a side) */
#define SLOPE 300.0 /* a: log sigma changes by 1 over 3.3 mm */

static const double Z0 = 0.4;                       /* the plane, metres */
static const double C[3] = {0.5, 0.5, 0.45}, R = 0.3; /* the sphere, metres */

typedef enum { PLANE, SPHERE, SHELL } shape;

/* log sigma of the shape at x (world = cube coordinates). SHELL is a sheet of matter at
 * z = Z0, a few millimetres thick, as depth training makes a surface. */
static double log_sigma(shape s, const double x[3]) {
  if (s == PLANE) return SLOPE * (Z0 - x[2]);
  if (s == SHELL) return 10.0 - SLOPE * fabs(x[2] - Z0);
  const double d[3] = {x[0] - C[0], x[1] - C[1], x[2] - C[2]};
  return SLOPE * (R - sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
}

/* A field over the unit cube whose density is exp(log_sigma) (clamped to exp(+-15), as the
 * density activation does), up to the trilinear interpolation of level LEVEL. */
static fg_field *shape_field(shape s, int D) {
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, lo, hi, 1.0, D));
  fg_field *f;
  ASSERT_OK(fg_field_alloc(&f, &cfg));
  ASSERT_NEAR(f->cfg.box_size, 1.0, 0);
  fg_hashgrid_level lv;
  ASSERT_OK(fg_hashgrid_level_info(&cfg.grid, LEVEL, &lv));
  ASSERT(lv.dense);
  float *grid = fg_field_group(f, FG_FIELD_GRID, NULL);
  const uint32_t n = lv.resolution;
  const int F = cfg.grid.n_features;
  for (uint32_t cz = 0; cz < n; cz++)
    for (uint32_t cy = 0; cy < n; cy++)
      for (uint32_t cx = 0; cx < n; cx++) {
        /* vertex c stands at x = (c - 0.5) / scale (hashgrid.h) */
        const double x[3] = {(cx - 0.5) / lv.scale, (cy - 0.5) / lv.scale,
                             (cz - 0.5) / lv.scale};
        const size_t e = cx + (size_t)cy * n + (size_t)cz * n * n;
        grid[lv.offset + e * (size_t)F] = (float)log_sigma(s, x);
      }
  /* out[0] = relu(enc) - relu(-enc) = enc of column LEVEL * F. */
  float *W = fg_field_group(f, FG_FIELD_DENSITY, NULL);
  const fg_mlp_config *net = &f->density_net;
  float *W0 = W + fg_mlp_layer_offset(net, 0), *W1 = W + fg_mlp_layer_offset(net, 1);
  const int n_in = fg_mlp_layer_fan_in(net, 0), n_hid = fg_mlp_layer_fan_in(net, 1);
  W0[0 * n_in + LEVEL * F] = 1.0f;
  W0[1 * n_in + LEVEL * F] = -1.0f;
  W1[0 * n_hid + 0] = 1.0f;
  W1[0 * n_hid + 1] = -1.0f;
  return f;
}

/* The density at x in closed form. */
static double sigma_at(shape s, const double x[3]) {
  double v = log_sigma(s, x);
  return exp(v < -15 ? -15 : v > 15 ? 15 : v);
}

static void test_gradient(void) {
  fg_field *f = shape_field(PLANE, 0);
  enum { B = 5 };
  const float x[B * 3] = {0.5f, 0.5f, 0.41f, 0.2f, 0.7f, 0.395f, 0.8f, 0.3f, 0.42f,
                          0.31f, 0.33f, 0.38f, 0.6f, 0.6f, 0.44f};
  float sigma[B], grad[B * 3];
  ASSERT_OK(fg_field_density(f, x, B, sigma, 2));
  const float h = 0.004f;
  ASSERT_OK(fg_field_density_gradient(f, x, B, h, grad, 2));
  for (int i = 0; i < B; i++) {
    const double p[3] = {x[3 * i], x[3 * i + 1], x[3 * i + 2]};
    ASSERT_NEAR(sigma[i] / sigma_at(PLANE, p), 1.0, 1e-3);
    const double pz[3] = {p[0], p[1], p[2] + h}, mz[3] = {p[0], p[1], p[2] - h};
    const double gz = (sigma_at(PLANE, pz) - sigma_at(PLANE, mz)) / (2 * h);
    ASSERT_NEAR(grad[3 * i + 2] / gz, 1.0, 2e-3);
    ASSERT(fabs(grad[3 * i + 0]) <= 1e-4 * fabs(gz));
    ASSERT(fabs(grad[3 * i + 1]) <= 1e-4 * fabs(gz));
  }
  ASSERT_ERR(fg_field_density_gradient(f, x, B, 0.0f, grad, 2), FG_EINVAL, "step");
  ASSERT_ERR(fg_field_density_gradient(f, x, B, NAN, grad, 2), FG_EINVAL, "step");
  ASSERT_OK(fg_field_density_gradient(f, x, 0, h, grad, 2));
  fg_field_free(f);
}

/* R = n x n rays from eye towards points spread around target (spread metres a side). */
static void rays_towards(const double eye[3], const double target[3], double spread, int n,
                         float *o, float *d) {
  for (int v = 0; v < n; v++)
    for (int u = 0; u < n; u++) {
      const int r = v * n + u;
      const double t[3] = {target[0] + spread * ((u + 0.5) / n - 0.5),
                           target[1] + spread * ((v + 0.5) / n - 0.5), target[2]};
      double dir[3] = {t[0] - eye[0], t[1] - eye[1], t[2] - eye[2]};
      const double len = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
      for (int k = 0; k < 3; k++) {
        o[3 * r + k] = (float)eye[k];
        d[3 * r + k] = (float)(dir[k] / len);
      }
    }
}

static void test_plane_normals(void) {
  fg_field *f = shape_field(PLANE, 0);
  enum { N = 12, RAYS = N * N };
  float o[RAYS * 3], d[RAYS * 3], nrm[RAYS * 3], op[RAYS];
  const double eye[3] = {0.3, 0.2, 0.85}, target[3] = {0.55, 0.6, Z0};
  rays_towards(eye, target, 0.3, N, o, d);
  ASSERT_OK(fg_field_render_normals(f, o, d, RAYS, 0.005f, nrm, op, 2));
  for (int r = 0; r < RAYS; r++) {
    ASSERT(op[r] > 0.999f);
    ASSERT_NEAR(nrm[3 * r + 0], 0.0, 1e-4);
    ASSERT_NEAR(nrm[3 * r + 1], 0.0, 1e-4);
    ASSERT_NEAR(nrm[3 * r + 2], 1.0, 1e-6);
  }
  /* Rays that leave the cube upwards see next to nothing, where the density is clamped flat:
   * no gradient, zero normals. */
  for (int r = 0; r < RAYS; r++) d[3 * r + 2] = -d[3 * r + 2];
  ASSERT_OK(fg_field_render_normals(f, o, d, RAYS, 0.005f, nrm, op, 2));
  for (int r = 0; r < RAYS; r++) {
    ASSERT(op[r] < 1e-3f);
    ASSERT(nrm[3 * r] == 0.0f && nrm[3 * r + 1] == 0.0f && nrm[3 * r + 2] == 0.0f);
  }
  ASSERT_ERR(fg_field_render_normals(f, o, d, RAYS, -1.0f, nrm, op, 2), FG_EINVAL, "step");
  fg_field_free(f);
}

static void test_sphere_normals(void) {
  fg_field *f = shape_field(SPHERE, 0);
  enum { N = 16, RAYS = N * N };
  float o[RAYS * 3], d[RAYS * 3], nrm[RAYS * 3], op[RAYS], depth[RAYS], op2[RAYS];
  const double eye[3] = {0.45, 0.05, 0.8}, target[3] = {C[0], C[1], C[2]};
  rays_towards(eye, target, 0.3, N, o, d);
  ASSERT_OK(fg_field_render_normals(f, o, d, RAYS, 0.005f, nrm, op, 2));
  const float bg[3] = {0, 0, 0};
  ASSERT_OK(fg_field_render_rays(f, o, d, RAYS, bg, NULL, depth, op2, NULL, 2));
  /* The normal is -grad sigma at the expected termination point, normalised... */
  float p[RAYS * 3], grad[RAYS * 3];
  for (int r = 0; r < RAYS; r++)
    for (int k = 0; k < 3; k++) p[3 * r + k] = o[3 * r + k] + depth[r] / op2[r] * d[3 * r + k];
  ASSERT_OK(fg_field_density_gradient(f, p, RAYS, 0.005f, grad, 2));
  /* ... and that is radial up to the trilinear interpolation of |x - c| between the level's
   * vertices 1.75 cm apart, which turns the gradient by up to 6 degrees (3.8 median) at this
   * radius (a Python model of the hash grid says so). */
  int hits = 0, within_4 = 0;
  double worst = 1.0;
  for (int r = 0; r < RAYS; r++) {
    ASSERT(op[r] == op2[r]);
    if (op[r] < 0.999f) continue;
    hits++;
    const double t = depth[r] / op[r];
    double radial[3], len = 0.0, dot = 0.0, nn = 0.0, gl = 0.0;
    for (int k = 0; k < 3; k++) {
      radial[k] = o[3 * r + k] + t * d[3 * r + k] - C[k];
      len += radial[k] * radial[k];
      nn += (double)nrm[3 * r + k] * nrm[3 * r + k];
      gl += (double)grad[3 * r + k] * grad[3 * r + k];
    }
    for (int k = 0; k < 3; k++) {
      dot += nrm[3 * r + k] * radial[k] / sqrt(len);
      ASSERT_NEAR(nrm[3 * r + k], -grad[3 * r + k] / sqrt(gl), 1e-6);
    }
    ASSERT_NEAR(sqrt(nn), 1.0, 1e-6);
    ASSERT_NEAR(sqrt(len), R, 0.03); /* the termination point lies on the surface */
    if (dot < worst) worst = dot;
    within_4 += dot > cos(4.0 * M_PI / 180.0);
  }
  printf("sphere: %d of %d rays hit, %d normals within 4 degrees of the radius, the worst at "
         "%.2f\n", hits, RAYS, within_4, acos(worst < 1.0 ? worst : 1.0) * 180.0 / M_PI);
  ASSERT(hits > RAYS / 2);
  ASSERT(worst > cos(7.0 * M_PI / 180.0));
  ASSERT(within_4 > hits / 2);

  /* Colours: zero colour weights give sigmoid(0) = 0.5 whatever the point and direction. */
  float rgb[RAYS * 3];
  ASSERT_OK(fg_field_colour(f, o, d, RAYS, rgb, 2));
  for (int i = 0; i < RAYS * 3; i++) ASSERT(rgb[i] == 0.5f);
  fg_field_free(f);
}

/* The field sampled on a voxel grid and meshed: the iso-surface lies where
 * 1 - exp(-mean sigma vs) = threshold. Across the sphere's surface, where the density is
 * exp(a (R - r)) along the normal, the mean over a voxel's 4 sub-samples per axis (at +-1/8
 * and +-3/8 of a voxel from its centre) is k = mean_j exp(a o_j vs) times the centre's
 * density (for a normal along an axis; 3.0 there and 3.6 on a diagonal), so the surface lies
 * at radius R - ln(-ln(1 - threshold) / (vs k)) / a. */
static void test_sphere_mesh(void) {
  fg_field *f = shape_field(SPHERE, 0);
  const double lo[3] = {0.2, 0.2, 0.15}, hi[3] = {0.8, 0.8, 0.75}, vs = 0.02;
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, lo, hi, vs));
  float *alpha = malloc(fg_voxel_grid_count(&g) * sizeof *alpha);
  ASSERT_OK(fg_voxel_alpha(f, &g, alpha, 2));
  const float thr = 0.1f;
  double kk = 0.0;
  for (int j = 0; j < 4; j++) kk += exp(SLOPE * (j - 1.5) / 4.0 * vs) / 4.0;
  const double r_iso = R - log(-log(1.0 - thr) / (vs * kk)) / SLOPE;
  fg_mesh m;
  ASSERT_OK(fg_mesh_marching_cubes(&g, alpha, thr, &m));
  ASSERT(m.n_faces > 1000);
  double worst = 0.0;
  for (size_t v = 0; v < m.n_vertices; v++) {
    const float *p = m.p_world + 3 * v;
    const double r = sqrt((p[0] - C[0]) * (p[0] - C[0]) + (p[1] - C[1]) * (p[1] - C[1]) +
                          (p[2] - C[2]) * (p[2] - C[2]));
    if (fabs(r - r_iso) > worst) worst = fabs(r - r_iso);
  }
  printf("sphere mesh: %zu vertices, %zu faces, worst radial error %.3f voxel\n", m.n_vertices,
         m.n_faces, worst / vs);
  ASSERT(worst < 0.5 * vs);
  for (size_t t = 0; t < m.n_faces; t++) { /* outward */
    const float *a = m.p_world + 3 * m.faces[3 * t], *b = m.p_world + 3 * m.faces[3 * t + 1],
                *c = m.p_world + 3 * m.faces[3 * t + 2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                         u[0] * w[1] - u[1] * w[0]};
    double out = 0.0;
    for (int k = 0; k < 3; k++) out += n[k] * (a[k] - C[k]);
    ASSERT(out > 0.0);
  }
  ASSERT_OK(fg_mesh_colour(&m, f, (float)(0.5 * vs), 2));
  ASSERT(m.rgb != NULL);
  for (size_t i = 0; i < 3 * m.n_vertices; i++) ASSERT_EQ(m.rgb[i], 128);
  fg_mesh_release(&m);
  /* Points of the same grid: the voxels inside r_iso. */
  ASSERT_OK(fg_mesh_points(&g, alpha, thr, &m));
  ASSERT_NEAR((double)m.n_vertices * vs * vs * vs / (4.0 / 3.0 * M_PI * pow(r_iso, 3)), 1.0,
              0.05);
  ASSERT_OK(fg_mesh_colour(&m, f, 0.01f, 2));
  for (size_t i = 0; i < 3 * m.n_vertices; i++) ASSERT_EQ(m.rgb[i], 128);
  fg_mesh_release(&m);
  free(alpha);
  fg_field_free(f);
}

/* A voxel's alpha is its mean density, not its centre's: a sheet of matter on the faces
 * between two layers of 10 cm voxels, 5 cm from every centre, occupies both layers (alpha at
 * the centres about 7e-4); and nothing counts where the field's occupancy grid is empty. */
static void test_shell_alpha(void) {
  fg_field *f = shape_field(SHELL, 0);
  const double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {1.0, 1.0, 1.0}, vs = 0.1;
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, lo, hi, vs));
  const size_t N = fg_voxel_grid_count(&g);
  float *alpha = malloc(N * sizeof *alpha), *centres = malloc(N * 3 * sizeof *centres);
  float *sigma = malloc(N * sizeof *sigma);
  ASSERT_OK(fg_voxel_alpha(f, &g, alpha, 2));
  fg_voxel_grid_centres(&g, centres);
  ASSERT_OK(fg_field_density(f, centres, (int64_t)N, sigma, 2));
  size_t n_sheet = 0;
  for (size_t i = 0; i < N; i++) {
    const int iz = (int)(i / 100);
    ASSERT(1.0 - exp(-sigma[i] * vs) < 0.01); /* a centre sample misses the sheet */
    if (iz == 3 || iz == 4) { /* z in [0.3, 0.5): the layers that touch Z0 = 0.4 */
      ASSERT(alpha[i] >= 0.9);
      n_sheet++;
    } else {
      ASSERT(alpha[i] < 0.01);
    }
  }
  ASSERT_EQ(n_sheet, 200);
  /* an empty occupancy grid: the renderer never samples the sheet, so no voxel holds it */
  const int n_occ = fg_occgrid_resolution(f->occ);
  uint64_t *bits = calloc((size_t)n_occ * n_occ * n_occ / 64, sizeof *bits);
  ASSERT_OK(fg_occgrid_set_bits(f->occ, bits, 2));
  ASSERT_OK(fg_voxel_alpha(f, &g, alpha, 2));
  for (size_t i = 0; i < N; i++) ASSERT(alpha[i] == 0.0f);
  free(bits);
  free(alpha);
  free(centres);
  free(sigma);
  fg_field_free(f);
}

/* A pinhole camera w x h with its principal point in the middle, looking straight down (-z)
 * from eye: OpenGL's camera with an identity rotation. */
static fg_camera down_camera(int w, int h, double fl, const double eye[3], double T[16]) {
  fg_camera cam = {.model = FG_CAMERA_PINHOLE, .w = w, .h = h, .fl_x = fl, .fl_y = fl,
                   .cx = 0.5 * w, .cy = 0.5 * h};
  for (int i = 0; i < 16; i++) T[i] = (i % 5 == 0) ? 1.0 : 0.0;
  for (int k = 0; k < 3; k++) T[4 * k + 3] = eye[k];
  return cam;
}

static void test_plane_images(void) {
  fg_field *f = shape_field(PLANE, 0);
  double T[16];
  const double eye[3] = {0.5, 0.5, Z0 + 0.005}; /* close: short rays, a cheap test */
  /* 300 x 220 = 66000 rays: two chunks of FG_FIELD_IMAGE_CHUNK */
  const fg_camera cam = down_camera(300, 220, 500.0, eye, T);
  const int64_t n = (int64_t)cam.w * cam.h;
  ASSERT(n > FG_FIELD_IMAGE_CHUNK);
  const float bg[3] = {0, 0, 0};
  uint16_t *mm = malloc((size_t)n * sizeof *mm);
  uint8_t *px = malloc((size_t)n * 3);
  float *rgb = malloc((size_t)n * 3 * sizeof *rgb), *depth = malloc((size_t)n * sizeof *depth);
  float *op = malloc((size_t)n * sizeof *op);
  ASSERT(mm && px && rgb && depth && op);
  ASSERT_OK(fg_field_render_image(f, T, &cam, FG_FIELD_IMAGE_DEPTH, bg, 0.005f, 2, mm));
  ASSERT_OK(fg_field_render_camera(f, T, &cam, bg, rgb, depth, op, NULL, 2));
  int lo = 65535, hi = 0;
  for (int64_t i = 0; i < n; i++) {
    lo = mm[i] < lo ? mm[i] : lo, hi = mm[i] > hi ? mm[i] : hi;
    /* z = distance along the ray times the ray's cosine to the axis */
    const double u = (double)(i % cam.w) + 0.5 - cam.cx, v = (double)(i / cam.w) + 0.5 - cam.cy;
    const double cosine = 1.0 / sqrt(1.0 + (u * u + v * v) / (cam.fl_x * cam.fl_x));
    ASSERT(op[i] >= FG_FIELD_SURFACE_MIN_OPACITY);
    ASSERT(abs((int)mm[i] - (int)lround(depth[i] / op[i] * cosine * 1000.0)) <= 1);
  }
  /* the density's e-folding length is 3.3 mm: rays end about 17 mm into the plane */
  printf("plane 5 mm below the camera: depth image %d..%d mm\n", lo, hi);
  ASSERT(lo >= 5 && hi <= 35);
  ASSERT(hi - lo <= 1); /* z along the axis: one value, where the distance along rays varies */
  ASSERT_OK(fg_field_render_image(f, T, &cam, FG_FIELD_IMAGE_NORMAL, bg, 0.005f, 2, px));
  for (int64_t i = 0; i < n; i++) {
    ASSERT(px[3 * i] == 127 || px[3 * i] == 128);
    ASSERT(px[3 * i + 1] == 127 || px[3 * i + 1] == 128);
    ASSERT_EQ(px[3 * i + 2], 255);
  }
  ASSERT_OK(fg_field_render_image(f, T, &cam, FG_FIELD_IMAGE_RGB, bg, 0.005f, 2, px));
  for (int64_t i = 0; i < 3 * n; i++) {
    const float x = rgb[i] > 0 ? (rgb[i] < 1 ? rgb[i] : 1) : 0;
    ASSERT_EQ(px[i], (uint8_t)lrintf(x * 255.0f));
    ASSERT(px[i] == 127 || px[i] == 128); /* sigmoid(0) */
  }
  fg_camera bad = cam;
  bad.fl_x = 0;
  ASSERT_ERR(fg_field_render_image(f, T, &bad, FG_FIELD_IMAGE_RGB, bg, 0.005f, 2, px), FG_EINVAL,
             "focal");
  free(op), free(depth), free(rgb), free(px), free(mm);
  fg_field_free(f);
}

static void test_heatmap_view(void) {
  enum { D = 8 };
  fg_field *f = shape_field(PLANE, D);
  /* features from random weights of the feature branch (zero in shape_field) */
  static const int groups[] = {FG_FIELD_FEAT_GRID, FG_FIELD_FEAT_MLP, FG_FIELD_FEAT_OUT};
  for (int g = 0; g < 3; g++) {
    size_t np;
    float *p = fg_field_group(f, groups[g], &np);
    for (size_t i = 0; i < np; i++) p[i] = (float)(fg_rng_uniform((uint64_t)g, i) - 0.5);
  }
  double T[16];
  const double eye[3] = {0.5, 0.5, Z0 + 0.03};
  const fg_camera cam = down_camera(80, 60, 60.0, eye, T); /* 4800 rays: two heatmap chunks */
  const int64_t n = (int64_t)cam.w * cam.h;
  ASSERT(n > FG_HEATMAP_VIEW_CHUNK);
  const float pos[D] = {1, -0.5f, 0.25f, 0, 0.1f, -1, 0.3f, 0.7f}, neg[D] = {0, 1, 0, 0, 0, 0, 0, 0};
  fg_query q;
  ASSERT_OK(fg_query_init(&q, D, pos, 1, neg, 1, 0.1f));
  const float bg[3] = {0.2f, 0.3f, 0.4f};
  uint8_t *got = malloc((size_t)n * 3), *want = malloc((size_t)n * 3);
  float *rgb = malloc((size_t)n * 3 * sizeof *rgb), *op = malloc((size_t)n * sizeof *op);
  float *feat = malloc((size_t)n * D * sizeof *feat), *scores = malloc((size_t)n * sizeof *scores);
  ASSERT(got && want && rgb && op && feat && scores);
  ASSERT_OK(fg_heatmap_render_view(f, T, &cam, &q, bg, 2, got));
  ASSERT_OK(fg_field_render_camera(f, T, &cam, bg, rgb, NULL, op, feat, 2));
  ASSERT_OK(fg_query_score_features(&q, feat, n, D, op, FG_HEATMAP_VIEW_MIN_OPACITY, scores, 2));
  int64_t scored = 0;
  for (int64_t i = 0; i < n; i++) scored += !isnan(scores[i]);
  printf("heatmap view: %lld of %lld pixels scored\n", (long long)scored, (long long)n);
  ASSERT(scored > n / 2);
  fg_heatmap_blend(rgb, scores, n, NAN, NAN, want);
  ASSERT(memcmp(got, want, (size_t)n * 3) == 0);
  fg_query_release(&q);
  free(scores), free(feat), free(op), free(rgb), free(want), free(got);
  fg_field_free(f);
}

int main(void) {
  test_plane_images();
  test_heatmap_view();
  test_gradient();
  test_shell_alpha();
  test_plane_normals();
  test_sphere_normals();
  test_sphere_mesh();
  printf("normals: ok\n");
  return 0;
}
