/* Scene construction (seeded placement, cameras, class embeddings) and the ray caster of
 * fieldgrip-scenegen (scene.h). */
#include "scene.h"

#include "core/error.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

const char *const sg_class_names[SG_N_CLASSES] = {"background", "table", "mug",
                                                  "bowl",       "box",   "ball"};

/* ---------------------------------------------------------------- random numbers */

/* splitmix64: tiny, well mixed, and the same on every platform; each purpose draws from its
 * own stream keyed by (seed, purpose, index) so that changing one never shifts another. */
typedef struct rng {
  uint64_t s;
} rng;

static uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

static uint64_t rng_next(rng *r) {
  r->s += 0x9e3779b97f4a7c15ull;
  return mix64(r->s);
}

static rng rng_stream(uint64_t seed, uint64_t purpose, uint64_t index) {
  rng r = {mix64(mix64(seed ^ 0x5ce9e9e9ull) ^ (purpose * 0x9e3779b97f4a7c15ull)) ^
           mix64(index + 0x632be59bd9b4e019ull)};
  return r;
}

/* Uniform in [0, 1). */
static double rng_uniform(rng *r) { return (double)(rng_next(r) >> 11) * 0x1.0p-53; }

static double rng_range(rng *r, double lo, double hi) { return lo + (hi - lo) * rng_uniform(r); }

/* Standard normal (Box-Muller; one value per call keeps streams simple). */
static double rng_gauss(rng *r) {
  double u1 = ((double)(rng_next(r) >> 11) + 1.0) * 0x1.0p-53; /* (0, 1] */
  double u2 = rng_uniform(r);
  return sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
}

enum { STREAM_EMBED = 1, STREAM_OBJECTS = 2, STREAM_CAMERAS = 3, STREAM_NOISE = 4 };

/* ---------------------------------------------------------------- configuration */

void sg_config_default(sg_config *cfg) {
  memset(cfg, 0, sizeof *cfg);
  cfg->seed = 0;
  cfg->embedding_seed = -1;
  cfg->n_views = 60;
  cfg->w = 320;
  cfg->h = 240;
  cfg->dim = 64;
  cfg->patch = 16;
  cfg->noise = 0.05;
  cfg->holdout = 10;
}

/* ---------------------------------------------------------------- geometry helpers */

static void normalize3(double v[3]) {
  double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  v[0] /= n, v[1] /= n, v[2] /= n;
}

static void cross3(const double a[3], const double b[3], double out[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Row-major rigid transform from rotation columns x, y, z and a translation. */
static void frame_from_axes(const double x[3], const double y[3], const double z[3],
                            const double t[3], double T[16]) {
  for (int i = 0; i < 3; i++) {
    T[4 * i + 0] = x[i];
    T[4 * i + 1] = y[i];
    T[4 * i + 2] = z[i];
    T[4 * i + 3] = t[i];
  }
  T[12] = T[13] = T[14] = 0;
  T[15] = 1;
}

static void mat4_mul(const double A[16], const double B[16], double C[16]) {
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) {
      double s = 0;
      for (int k = 0; k < 4; k++) s += A[4 * i + k] * B[4 * k + j];
      C[4 * i + j] = s;
    }
}

/* ---------------------------------------------------------------- objects */

/* The object's shape at scale s (sizes in metres at s = 1), standing with its base on z = 0
 * at (x, y), turned by yaw about +z. */
static void make_shape(sg_shape *sh, sg_shape_type type, double s, double x, double y,
                       double yaw) {
  memset(sh, 0, sizeof *sh);
  sh->type = type;
  double h = 0;
  switch (type) {
  case SG_SHAPE_MUG:
    sh->outer_radius = 0.040 * s;
    sh->inner_radius = 0.035 * s;
    sh->height = 0.100 * s;
    sh->bottom = 0.008 * s;
    /* The ring's centre sits just inside the wall, so the handle grows out of it. */
    sh->handle_center[0] = 0.038 * s;
    sh->handle_center[2] = 0.005 * s;
    sh->handle_major = 0.026 * s;
    sh->handle_minor = 0.0065 * s;
    sh->handle_clip_radius = (sh->outer_radius + sh->inner_radius) / 2;
    h = sh->height;
    break;
  case SG_SHAPE_BOWL:
    sh->outer_radius = 0.075 * s;
    sh->inner_radius = 0.069 * s;
    /* The sphere's bottom is cut 2 mm flat: a foot to stand on, a 4 mm thick floor. */
    sh->height = sh->outer_radius - 0.002 * s;
    sh->sphere_center_z = sh->height / 2;
    h = sh->height;
    break;
  case SG_SHAPE_BOX:
    /* The short side (y) fits a Panda's 8 cm opening. */
    sh->size[0] = 0.100 * s;
    sh->size[1] = 0.060 * s;
    sh->size[2] = 0.070 * s;
    h = sh->size[2];
    break;
  case SG_SHAPE_BALL:
    sh->radius = 0.035 * s;
    h = 2 * sh->radius;
    break;
  }
  double c = cos(yaw), sn = sin(yaw);
  double ax[3] = {c, sn, 0}, ay[3] = {-sn, c, 0}, az[3] = {0, 0, 1}, t[3] = {x, y, h / 2};
  frame_from_axes(ax, ay, az, t, sh->T_world_obj);
  sg_shape_finish(sh);
}

/* Radius of the object's footprint around its axis, for non-overlapping placement. */
static double footprint_radius(const sg_shape *sh) {
  double lo[3], hi[3];
  sg_shape_local_bounds(sh, lo, hi);
  double best = 0;
  for (int c = 0; c < 4; c++) {
    double px = (c & 1) ? hi[0] : lo[0], py = (c & 2) ? hi[1] : lo[1];
    double r = sqrt(px * px + py * py);
    if (sh->type != SG_SHAPE_BOX) r = fmax(fabs(px), fabs(py)); /* round in x-y */
    if (r > best) best = r;
  }
  return best;
}

/* One grasp per object in its own frame: the TCP position, the approach axis (+z of the
 * gripper) and the closing axis (+y). Rims of the mug and the bowl are pinched from above
 * (the mug's on the side away from its handle), the box is taken from above across its short
 * side, the ball from above at its equator. */
static void make_grasp(sg_object *ob) {
  const sg_shape *sh = &ob->shape;
  double p[3] = {0, 0, 0}, ay[3] = {0, 1, 0}, az[3] = {0, 0, -1};
  switch (sh->type) {
  case SG_SHAPE_MUG:
    p[0] = -(sh->outer_radius + sh->inner_radius) / 2;
    p[2] = sh->height / 2 - 0.015;
    ay[0] = 1, ay[1] = 0;
    ob->grasp_width_m = sh->outer_radius - sh->inner_radius;
    break;
  case SG_SHAPE_BOWL: {
    /* 1 cm below the rim the spherical wall is still nearly vertical; its radii there: */
    double dz = -0.01;
    double ro = sqrt(sh->outer_radius * sh->outer_radius - dz * dz);
    double ri = sqrt(sh->inner_radius * sh->inner_radius - dz * dz);
    p[0] = (ro + ri) / 2;
    p[2] = sh->sphere_center_z + dz;
    ay[0] = 1, ay[1] = 0;
    ob->grasp_width_m = ro - ri;
    break;
  }
  case SG_SHAPE_BOX:
    p[2] = sh->size[2] / 2 - fmin(0.025, sh->size[2] / 2);
    ob->grasp_width_m = sh->size[1];
    break;
  case SG_SHAPE_BALL: ob->grasp_width_m = 2 * sh->radius; break;
  }
  double ax[3], T_obj_grasp[16];
  cross3(ay, az, ax);
  frame_from_axes(ax, ay, az, p, T_obj_grasp);
  mat4_mul(sh->T_world_obj, T_obj_grasp, ob->T_world_grasp);
}

/* Objects stand wholly inside a disc of the table around the point the cameras look at, well
 * inside the default workspace (x 0.10..0.80, y -0.45..0.45), so that every camera sees every
 * object whole; PLACE_GAP_M apart at least. */
#define PLACE_RADIUS_M 0.25
#define PLACE_GAP_M 0.02

/* Moves the objects by cfg.moved_xy once the layout is placed, their grasps with them; each
 * moved object must stay on the table and PLACE_GAP_M from every other one present. */
static int move_objects(sg_scene *sc) {
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    const double *d = sc->cfg.moved_xy[k];
    sg_object *ob = &sc->objects[k];
    if (d[0] == 0 && d[1] == 0) continue;
    if (!ob->present)
      return fg_fail(FG_EINVAL, "the %s is both removed and moved", ob->name);
    ob->shape.T_world_obj[3] += d[0];
    ob->shape.T_world_obj[7] += d[1];
    sg_shape_finish(&ob->shape);
    make_grasp(ob);
  }
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    const sg_object *ob = &sc->objects[k];
    if (!ob->present || (sc->cfg.moved_xy[k][0] == 0 && sc->cfg.moved_xy[k][1] == 0)) continue;
    const double x = ob->shape.T_world_obj[3], y = ob->shape.T_world_obj[7];
    const double rk = footprint_radius(&ob->shape);
    if (x - rk < sc->table_min[0] || x + rk > sc->table_max[0] || y - rk < sc->table_min[1] ||
        y + rk > sc->table_max[1])
      return fg_fail(FG_EINVAL, "the %s moved to (%.3f, %.3f) would leave the table", ob->name,
                     x, y);
    for (int j = 0; j < SG_N_OBJECTS; j++) {
      const sg_object *o2 = &sc->objects[j];
      if (j == k || !o2->present) continue;
      const double dx = o2->shape.T_world_obj[3] - x, dy = o2->shape.T_world_obj[7] - y;
      if (hypot(dx, dy) < rk + footprint_radius(&o2->shape) + PLACE_GAP_M)
        return fg_fail(FG_EINVAL, "the %s moved to (%.3f, %.3f) would touch the %s", ob->name,
                       x, y, o2->name);
    }
  }
  return 0;
}

static int place_objects(sg_scene *sc) {
  static const sg_shape_type types[SG_N_OBJECTS] = {SG_SHAPE_MUG, SG_SHAPE_BOWL, SG_SHAPE_BOX,
                                                    SG_SHAPE_BALL};
  static const double albedo[SG_N_OBJECTS][3] = {
      {0.70, 0.06, 0.05}, /* mug: red */
      {0.06, 0.20, 0.70}, /* bowl: blue */
      {0.10, 0.50, 0.12}, /* box: green */
      {0.85, 0.60, 0.05}, /* ball: yellow */
  };
  rng r = rng_stream(sc->cfg.seed, STREAM_OBJECTS, 0);
  /* Rejection sampling of the whole layout: deterministic, and a dead end just restarts. */
  for (int attempt = 0; attempt < 100000; attempt++) {
    int ok = 1;
    for (int k = 0; k < SG_N_OBJECTS && ok; k++) {
      sg_object *ob = &sc->objects[k];
      double s = rng_range(&r, 0.9, 1.1);
      double x = sc->look_at_world[0] + rng_range(&r, -PLACE_RADIUS_M, PLACE_RADIUS_M);
      double y = sc->look_at_world[1] + rng_range(&r, -PLACE_RADIUS_M, PLACE_RADIUS_M);
      double yaw = rng_range(&r, -M_PI, M_PI);
      make_shape(&ob->shape, types[k], s, x, y, yaw);
      double rk = footprint_radius(&ob->shape);
      if (hypot(x - sc->look_at_world[0], y - sc->look_at_world[1]) + rk > PLACE_RADIUS_M) ok = 0;
      for (int j = 0; j < k && ok; j++) {
        const double *a = sc->objects[j].shape.T_world_obj;
        double dx = a[3] - x, dy = a[7] - y;
        if (sqrt(dx * dx + dy * dy) < rk + footprint_radius(&sc->objects[j].shape) + PLACE_GAP_M)
          ok = 0;
      }
    }
    if (!ok) continue;
    for (int k = 0; k < SG_N_OBJECTS; k++) {
      sg_object *ob = &sc->objects[k];
      ob->name = sg_class_names[SG_CLASS_MUG + k];
      ob->class_id = SG_CLASS_MUG + k;
      ob->present = !(sc->cfg.removed & (1u << k));
      memcpy(ob->albedo, albedo[k], sizeof ob->albedo);
      make_grasp(ob);
    }
    return move_objects(sc);
  }
  return fg_fail(FG_ERANGE, "could not place the objects without overlap");
}

/* ---------------------------------------------------------------- embeddings */

/* Random unit vectors, each drawn again until its cosine with every earlier class is below
 * SG_MAX_CLASS_COSINE; in a dimension too small for that to happen by chance, the last draw
 * is made orthogonal to the earlier ones (possible since dim >= SG_N_CLASSES). */
static void make_embeddings(sg_scene *sc) {
  int D = sc->cfg.dim;
  const uint64_t seed = sc->cfg.embedding_seed >= 0 ? (uint64_t)sc->cfg.embedding_seed
                                                    : sc->cfg.seed;
  rng r = rng_stream(seed, STREAM_EMBED, 0);
  double *v = malloc((size_t)D * sizeof *v);
  for (int k = 0; k < SG_N_CLASSES; k++) {
    float *e = sc->embeddings + (size_t)k * D;
    for (int attempt = 0;; attempt++) {
      for (int i = 0; i < D; i++) v[i] = rng_gauss(&r);
      if (attempt >= 10000)
        for (int j = 0; j < k; j++) {
          const float *f = sc->embeddings + (size_t)j * D;
          double p = 0;
          for (int i = 0; i < D; i++) p += v[i] * f[i];
          for (int i = 0; i < D; i++) v[i] -= p * f[i];
        }
      double n = 0;
      for (int i = 0; i < D; i++) n += v[i] * v[i];
      n = sqrt(n);
      for (int i = 0; i < D; i++) e[i] = (float)(v[i] / n);
      int ok = 1;
      for (int j = 0; j < k && ok; j++) {
        const float *f = sc->embeddings + (size_t)j * D;
        double c = 0;
        for (int i = 0; i < D; i++) c += (double)e[i] * f[i];
        if (c >= SG_MAX_CLASS_COSINE) ok = 0;
      }
      if (ok) break;
    }
  }
  free(v);
}

/* ---------------------------------------------------------------- cameras */

/* Views from the top of the elevation band (70 degrees, view 0) down to its bottom (25),
 * evenly in sin(elevation) so they cover the band's area evenly, turning by the golden angle
 * from a seeded start: every held-out subset spans all heights and directions. */
static void make_cameras(sg_scene *sc) {
  rng r = rng_stream(sc->cfg.seed, STREAM_CAMERAS, 0);
  double az0 = rng_range(&r, 0, 2 * M_PI);
  const double golden = M_PI * (3.0 - sqrt(5.0));
  double s_top = sin(70.0 * M_PI / 180), s_bot = sin(25.0 * M_PI / 180);
  int N = sc->cfg.n_views;
  for (int i = 0; i < N; i++) {
    double s = N > 1 ? s_top - (s_top - s_bot) * i / (N - 1) : s_top;
    double el = asin(s), az = az0 + golden * i;
    double dir[3] = {cos(el) * cos(az), cos(el) * sin(az), sin(el)}; /* target -> camera */
    double pos[3], fwd[3], right[3], up[3], back[3];
    for (int k = 0; k < 3; k++) {
      pos[k] = sc->look_at_world[k] + sc->camera_radius_m * dir[k];
      fwd[k] = -dir[k];
      back[k] = dir[k];
    }
    const double z_up[3] = {0, 0, 1};
    cross3(fwd, z_up, right);
    normalize3(right);
    cross3(right, fwd, up);
    /* OpenGL: +x right, +y up, the camera looks along -z. */
    frame_from_axes(right, up, back, pos, sc->T_world_cam + 16 * (size_t)i);
  }
}

/* ---------------------------------------------------------------- sRGB */

/* 8-bit sRGB of a linear value, rounded to nearest: the largest code whose decision threshold
 * (the linear value of code k - 0.5) lies below it. The 255 thresholds are computed once from
 * the sRGB formula; a binary search then costs eight comparisons instead of a pow. */
static double srgb_decode(double e) {
  return e <= 0.04045 ? e / 12.92 : pow((e + 0.055) / 1.055, 2.4);
}

static void srgb_init(float thresholds[256]) {
  thresholds[0] = 0;
  for (int k = 1; k < 256; k++) thresholds[k] = (float)srgb_decode((k - 0.5) / 255.0);
}

static uint8_t srgb8(const float thresholds[256], float linear) {
  int lo = 0;
  for (int step = 128; step > 0; step >>= 1)
    if (lo + step < 256 && linear >= thresholds[lo + step]) lo += step;
  return (uint8_t)lo;
}

/* ---------------------------------------------------------------- building */

int sg_scene_build(sg_scene *sc, const sg_config *cfg) {
  memset(sc, 0, sizeof *sc);
  sc->cfg = *cfg;
  if (cfg->n_views < 1 || cfg->w < 1 || cfg->h < 1 || cfg->patch < 1 || cfg->holdout < 0 ||
      !(cfg->noise >= 0))
    return fg_fail(FG_EINVAL, "views, width, height and patch must be positive, holdout and "
                              "noise not negative");
  if (cfg->dim < SG_N_CLASSES)
    return fg_fail(FG_EINVAL, "--dim must be at least %d (one direction per class)",
                   SG_N_CLASSES);
  sc->table_min[0] = -0.15, sc->table_min[1] = -0.70, sc->table_min[2] = -0.04;
  sc->table_max[0] = 1.05, sc->table_max[1] = 0.70, sc->table_max[2] = 0.0;
  sc->look_at_world[0] = 0.45, sc->look_at_world[1] = 0.0, sc->look_at_world[2] = 0.05;
  sc->camera_radius_m = 0.9;
  sc->light_dir_world[0] = 0.35, sc->light_dir_world[1] = -0.25, sc->light_dir_world[2] = 0.9;
  normalize3(sc->light_dir_world);
  sc->ambient = 0.35;
  sc->background_rgb[0] = sc->background_rgb[1] = sc->background_rgb[2] = 1.0f;
  /* 43 degrees across the shorter side (about 55 across the width of a 4:3 image), square
   * pixels, centred principal point: every object stays wholly in view from every camera
   * (objects stand within PLACE_RADIUS_M of the look-at point), as large as that allows. */
  double fl = 0.5 * (cfg->w < cfg->h ? cfg->w : cfg->h) / tan(21.5 * M_PI / 180);
  sc->cam = (fg_camera){.fl_x = fl, .fl_y = fl, .cx = 0.5 * cfg->w, .cy = 0.5 * cfg->h,
                        .w = cfg->w, .h = cfg->h, .model = FG_CAMERA_PINHOLE};
  sc->feat_h = (cfg->h + cfg->patch - 1) / cfg->patch;
  sc->feat_w = (cfg->w + cfg->patch - 1) / cfg->patch;
  sc->T_world_cam = malloc((size_t)cfg->n_views * 16 * sizeof(double));
  sc->embeddings = malloc((size_t)SG_N_CLASSES * (size_t)cfg->dim * sizeof(float));
  if (!sc->T_world_cam || !sc->embeddings) {
    sg_scene_free(sc);
    return fg_fail(FG_ENOMEM, "out of memory for %d views", cfg->n_views);
  }
  int rc = place_objects(sc);
  if (rc != 0) {
    sg_scene_free(sc);
    return rc;
  }
  make_embeddings(sc);
  make_cameras(sc);
  srgb_init(sc->srgb_thresholds);
  for (int c = 0; c < 3; c++) sc->background_linear[c] = (float)srgb_decode(sc->background_rgb[c]);
  return 0;
}

void sg_scene_free(sg_scene *sc) {
  free(sc->T_world_cam);
  free(sc->embeddings);
  sc->T_world_cam = NULL;
  sc->embeddings = NULL;
}

/* ---------------------------------------------------------------- ray casting */

static int table_hit(const sg_scene *sc, const double o[3], const double d[3], double t_min,
                     double t_max, sg_hit *hit) {
  double t0 = -INFINITY, t1 = INFINITY;
  int axis0 = -1;
  double sign0 = 0;
  for (int k = 0; k < 3; k++) {
    if (fabs(d[k]) < 1e-300) {
      if (o[k] < sc->table_min[k] || o[k] > sc->table_max[k]) return 0;
      continue;
    }
    double ta = (sc->table_min[k] - o[k]) / d[k], tb = (sc->table_max[k] - o[k]) / d[k];
    double sign = -1;
    if (ta > tb) {
      double tmp = ta;
      ta = tb, tb = tmp, sign = 1;
    }
    if (ta > t0) t0 = ta, axis0 = k, sign0 = sign;
    if (tb < t1) t1 = tb;
  }
  if (t0 > t1 || axis0 < 0 || !(t0 > t_min && t0 < t_max)) return 0;
  hit->t = t0;
  hit->n_world[0] = hit->n_world[1] = hit->n_world[2] = 0;
  hit->n_world[axis0] = sign0;
  return 1;
}

int sg_scene_trace(const sg_scene *sc, const double o[3], const double d[3], double t_min,
                   sg_hit *hit) {
  int cls = SG_CLASS_BACKGROUND;
  double t_max = INFINITY;
  sg_hit h;
  if (table_hit(sc, o, d, t_min, t_max, &h)) {
    *hit = h;
    t_max = h.t;
    cls = SG_CLASS_TABLE;
  }
  for (int k = 0; k < SG_N_OBJECTS; k++)
    if (sc->objects[k].present &&
        sg_shape_intersect(&sc->objects[k].shape, o, d, t_min, t_max, &h)) {
      *hit = h;
      t_max = h.t;
      cls = sc->objects[k].class_id;
    }
  return cls;
}

/* A smooth-enough periodic wave of period 1 in [-1, 1], cheaper than sin (the table's grain
 * costs two per hit). */
static double wave(double x) {
  double f = x - floor(x);
  return 8 * f * (1 - f) - 1;
}

/* Parquet of 6 cm tiles in two wood tones, each tile's grain running along x or y and its
 * tone varied by a hash, so a NeRF has texture to lock onto; the slab's sides are plain. */
static void table_albedo(const double p[3], const double n[3], float out[3]) {
  if (n[2] < 0.5) {
    out[0] = 0.30f, out[1] = 0.18f, out[2] = 0.10f;
    return;
  }
  const double tile = 0.06;
  double fi = floor(p[0] / tile), fj = floor(p[1] / tile);
  int64_t i = (int64_t)fi, j = (int64_t)fj;
  uint64_t hsh = mix64((uint64_t)i * 0x9e3779b97f4a7c15ull ^ (uint64_t)j * 0xc2b2ae3d27d4eb4full);
  double vary = 0.88 + 0.24 * (double)(hsh >> 11) * 0x1.0p-53;
  int odd = (int)((i + j) & 1);
  double along = odd ? p[1] : p[0], across = odd ? p[0] : p[1];
  double phase = (double)(hsh & 0xffff) / 65536.0;
  double grain = 0.5 + 0.5 * wave(across / 0.012 + 0.25 * wave(along * 7 + phase));
  double k = vary * (0.85 + 0.15 * grain);
  static const double light[3] = {0.55, 0.36, 0.20}, dark[3] = {0.40, 0.25, 0.13};
  const double *base = odd ? dark : light;
  for (int c = 0; c < 3; c++) out[c] = (float)(base[c] * k);
}

/* Lambertian colour (linear RGB) of the first surface along a ray; background colour when
 * nothing is hit. cls receives the class. */
static void shade_ray(const sg_scene *sc, const double o[3], const double d[3], float out[3],
                      int *cls_out) {
  sg_hit hit;
  int cls = sg_scene_trace(sc, o, d, 0, &hit);
  *cls_out = cls;
  if (cls == SG_CLASS_BACKGROUND) {
    for (int c = 0; c < 3; c++) out[c] = sc->background_linear[c];
    return;
  }
  double p[3], n[3] = {hit.n_world[0], hit.n_world[1], hit.n_world[2]};
  for (int c = 0; c < 3; c++) p[c] = o[c] + hit.t * d[c];
  if (n[0] * d[0] + n[1] * d[1] + n[2] * d[2] > 0) n[0] = -n[0], n[1] = -n[1], n[2] = -n[2];
  float albedo[3];
  if (cls == SG_CLASS_TABLE)
    table_albedo(p, n, albedo);
  else
    for (int c = 0; c < 3; c++) albedo[c] = (float)sc->objects[cls - SG_CLASS_MUG].albedo[c];
  const double *L = sc->light_dir_world;
  double diffuse = n[0] * L[0] + n[1] * L[1] + n[2] * L[2];
  if (diffuse > 0) {
    /* Shadows: only the objects can stand between a surface and a light from above. */
    double q[3] = {p[0] + 1e-6 * n[0], p[1] + 1e-6 * n[1], p[2] + 1e-6 * n[2]};
    sg_hit sh;
    for (int k = 0; k < SG_N_OBJECTS; k++)
      if (sc->objects[k].present &&
          sg_shape_intersect(&sc->objects[k].shape, q, L, 1e-6, INFINITY, &sh)) {
        diffuse = 0;
        break;
      }
  } else {
    diffuse = 0;
  }
  double light = sc->ambient + (1 - sc->ambient) * diffuse;
  for (int c = 0; c < 3; c++) out[c] = (float)(albedo[c] * light);
}

static void camera_ray(const sg_scene *sc, const double T[16], double px, double py,
                       double d[3]) {
  const fg_camera *cam = &sc->cam;
  double dc[3] = {(px - cam->cx) / cam->fl_x, -(py - cam->cy) / cam->fl_y, -1};
  sg_xform_dir(T, dc, d);
  normalize3(d);
}

void sg_scene_render(const sg_scene *sc, int view, uint8_t *rgb, uint8_t *mask, float *depth_m) {
  const double *T = sc->T_world_cam + 16 * (size_t)view;
  const double o[3] = {T[3], T[7], T[11]};
  /* The optical axis in the world: OpenGL cameras look along their -z. */
  const double axis_world[3] = {-T[2], -T[6], -T[10]};
  const int W = sc->cfg.w, H = sc->cfg.h;
  /* Colour averages a 2x2 grid per pixel against aliasing; the mask and the depth are those of
   * the ray through the pixel's centre, the ray a NeRF renders for that pixel. */
  static const double sub[4][2] = {{0.25, 0.25}, {0.75, 0.25}, {0.25, 0.75}, {0.75, 0.75}};
#pragma omp parallel for schedule(dynamic, 2)
  for (int v = 0; v < H; v++) {
    for (int u = 0; u < W; u++) {
      double d[3];
      float acc[3] = {0, 0, 0}, c[3];
      int cls;
      for (int s = 0; s < 4; s++) {
        camera_ray(sc, T, u + sub[s][0], v + sub[s][1], d);
        shade_ray(sc, o, d, c, &cls);
        for (int k = 0; k < 3; k++) acc[k] += c[k];
      }
      camera_ray(sc, T, u + 0.5, v + 0.5, d);
      sg_hit hit;
      cls = sg_scene_trace(sc, o, d, 0, &hit);
      mask[(size_t)v * W + u] = (uint8_t)cls;
      if (depth_m) {
        /* (hit - o) . axis with hit - o = t d: the z-depth of the hit. */
        double z = cls == SG_CLASS_BACKGROUND
                       ? 0
                       : hit.t * (d[0] * axis_world[0] + d[1] * axis_world[1] +
                                  d[2] * axis_world[2]);
        depth_m[(size_t)v * W + u] = (float)z;
      }
      uint8_t *out = rgb + ((size_t)v * W + u) * 3;
      for (int k = 0; k < 3; k++) out[k] = srgb8(sc->srgb_thresholds, acc[k] * 0.25f);
    }
  }
}

/* ---------------------------------------------------------------- features */

int sg_scene_features(const sg_scene *sc, int view, const uint8_t *mask, float *feat) {
  const int W = sc->cfg.w, H = sc->cfg.h, D = sc->cfg.dim;
  const int fh = sc->feat_h, fw = sc->feat_w;
  int *counts = calloc((size_t)fh * fw * SG_N_CLASSES, sizeof *counts);
  if (!counts) return fg_fail(FG_ENOMEM, "out of memory counting the classes of view %d", view);
  for (int v = 0; v < H; v++) {
    int i = (int)((int64_t)v * fh / H);
    for (int u = 0; u < W; u++) {
      int j = (int)((int64_t)u * fw / W);
      counts[((size_t)i * fw + j) * SG_N_CLASSES + mask[(size_t)v * W + u]]++;
    }
  }
  rng r = rng_stream(sc->cfg.seed, STREAM_NOISE, (uint64_t)view);
  double sigma = sc->cfg.noise / sqrt((double)D);
  for (size_t cell = 0; cell < (size_t)fh * fw; cell++) {
    const int *cnt = counts + cell * SG_N_CLASSES;
    int best = 0;
    for (int k = 1; k < SG_N_CLASSES; k++)
      if (cnt[k] > cnt[best]) best = k;
    const float *e = sc->embeddings + (size_t)best * D;
    float *f = feat + cell * D;
    double n = 0;
    for (int k = 0; k < D; k++) {
      double x = e[k] + sigma * rng_gauss(&r);
      f[k] = (float)x;
      n += x * x;
    }
    n = sqrt(n);
    for (int k = 0; k < D; k++) f[k] = (float)(f[k] / n);
  }
  free(counts);
  return 0;
}
