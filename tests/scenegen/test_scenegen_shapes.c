/* In-process tests of the scene generator's geometry (shapes.c, scene.c, gt.c): layouts for
 * many seeds keep objects apart, in the workspace and in every view; ray hits agree with the
 * inside tests; the mug is open with a handle that has a hole; class embeddings stay apart in
 * any dimension; features carry the promised noise; gt.json's shape parameters round-trip. */
#include "test.h"

#include "core/error.h"
#include "gt.h"
#include "scene.h"

/* A tiny deterministic generator for sample points (not the scene's). */
static uint64_t lcg_state = 12345;
static double urand(void) {
  lcg_state = lcg_state * 6364136223846793005ull + 1442695040888963407ull;
  return (double)(lcg_state >> 11) * 0x1.0p-53;
}

static int project(const sg_scene *sc, int view, const double p[3], double *u, double *v) {
  const double *T = sc->T_world_cam + 16 * view;
  double d[3] = {p[0] - T[3], p[1] - T[7], p[2] - T[11]}, c[3];
  for (int i = 0; i < 3; i++) c[i] = T[i] * d[0] + T[4 + i] * d[1] + T[8 + i] * d[2];
  if (c[2] >= 0) return 0;
  *u = sc->cam.cx + sc->cam.fl_x * c[0] / -c[2];
  *v = sc->cam.cy - sc->cam.fl_y * c[1] / -c[2];
  return 1;
}

static double cosine(const float *a, const float *b, int n) {
  double ab = 0, aa = 0, bb = 0;
  for (int i = 0; i < n; i++) {
    ab += (double)a[i] * b[i];
    aa += (double)a[i] * a[i];
    bb += (double)b[i] * b[i];
  }
  return ab / sqrt(aa * bb);
}

static void check_embeddings(const sg_scene *sc) {
  int D = sc->cfg.dim;
  for (int k = 0; k < SG_N_CLASSES; k++) {
    ASSERT_NEAR(cosine(sc->embeddings + k * D, sc->embeddings + k * D, D), 1.0, 1e-9);
    for (int j = 0; j < k; j++)
      ASSERT(cosine(sc->embeddings + k * D, sc->embeddings + j * D, D) < SG_MAX_CLASS_COSINE);
  }
}

/* ---------------------------------------------------------------- layouts */

static void test_layouts(void) {
  sg_config cfg;
  sg_config_default(&cfg);
  for (uint64_t seed = 0; seed < 100; seed++) {
    cfg.seed = seed;
    sg_scene sc;
    ASSERT_OK(sg_scene_build(&sc, &cfg));
    check_embeddings(&sc);
    double mn[SG_N_OBJECTS][3], mx[SG_N_OBJECTS][3];
    for (int k = 0; k < SG_N_OBJECTS; k++) {
      sg_shape_world_aabb(&sc.objects[k].shape, mn[k], mx[k]);
      /* On the table, inside the default workspace. */
      ASSERT(mn[k][0] >= 0.10 && mx[k][0] <= 0.80 && mn[k][1] >= -0.45 && mx[k][1] <= 0.45);
      ASSERT_NEAR(mn[k][2], 0.0, 1e-12);
      /* Wholly in every view. */
      for (int v = 0; v < cfg.n_views; v++)
        for (int c = 0; c < 8; c++) {
          double p[3] = {(c & 1) ? mx[k][0] : mn[k][0], (c & 2) ? mx[k][1] : mn[k][1],
                         (c & 4) ? mx[k][2] : mn[k][2]};
          double u, w;
          ASSERT(project(&sc, v, p, &u, &w));
          if (!(u >= 0 && u <= cfg.w && w >= 0 && w <= cfg.h))
            FG_TEST_FAIL("seed %d: %s corner %d at (%.1f, %.1f) outside view %d", (int)seed,
                         sc.objects[k].name, c, u, w, v);
        }
    }
    /* No point is inside two objects: sample where their boxes overlap. */
    for (int a = 0; a < SG_N_OBJECTS; a++)
      for (int b = 0; b < a; b++) {
        double lo[3], hi[3];
        int overlap = 1;
        for (int i = 0; i < 3; i++) {
          lo[i] = fmax(mn[a][i], mn[b][i]);
          hi[i] = fmin(mx[a][i], mx[b][i]);
          overlap &= lo[i] < hi[i];
        }
        for (int s = 0; overlap && s < 2000; s++) {
          double p[3];
          for (int i = 0; i < 3; i++) p[i] = lo[i] + (hi[i] - lo[i]) * urand();
          ASSERT(!(sg_shape_inside(&sc.objects[a].shape, p) &&
                   sg_shape_inside(&sc.objects[b].shape, p)));
        }
      }
    sg_scene_free(&sc);
  }
}

/* ---------------------------------------------------------------- hits versus insides */

static void test_hits_agree_with_inside(void) {
  sg_config cfg;
  sg_config_default(&cfg);
  cfg.seed = 3;
  sg_scene sc;
  ASSERT_OK(sg_scene_build(&sc, &cfg));
  long hits = 0, bad = 0;
  for (int view = 0; view < cfg.n_views; view += 6) {
    const double *T = sc.T_world_cam + 16 * view;
    const double o[3] = {T[3], T[7], T[11]};
    for (int y = 0; y < cfg.h; y += 2)
      for (int x = 0; x < cfg.w; x += 2) {
        double dc[3] = {(x + 0.5 - sc.cam.cx) / sc.cam.fl_x, -(y + 0.5 - sc.cam.cy) / sc.cam.fl_y,
                        -1};
        double d[3];
        sg_xform_dir(T, dc, d);
        double n = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int i = 0; i < 3; i++) d[i] /= n;
        sg_hit hit;
        int cls = sg_scene_trace(&sc, o, d, 0, &hit);
        if (cls < SG_CLASS_MUG) continue;
        hits++;
        double before[3], after[3];
        for (int i = 0; i < 3; i++) {
          before[i] = o[i] + (hit.t - 1e-6) * d[i];
          after[i] = o[i] + (hit.t + 1e-6) * d[i];
        }
        int ok = sg_shape_inside(&sc.objects[cls - SG_CLASS_MUG].shape, after);
        for (int k = 0; k < SG_N_OBJECTS; k++) ok &= !sg_shape_inside(&sc.objects[k].shape, before);
        /* The normal faces the ray. */
        ok &= hit.n_world[0] * d[0] + hit.n_world[1] * d[1] + hit.n_world[2] * d[2] < 0;
        bad += !ok;
      }
  }
  fprintf(stderr, "hits: %ld object hits, %ld disagree with the inside test\n", hits, bad);
  ASSERT(hits > 10000);
  /* Grazing hits may cross a sliver thinner than the 1 um probe. */
  ASSERT(bad * 1000 <= hits);

  /* Completeness: a ray from a camera towards any solid point hits something no farther. */
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    const sg_shape *sh = &sc.objects[k].shape;
    double mn[3], mx[3];
    sg_shape_world_aabb(sh, mn, mx);
    int tried = 0;
    while (tried < 2000) {
      double p[3];
      for (int i = 0; i < 3; i++) p[i] = mn[i] + (mx[i] - mn[i]) * urand();
      if (!sg_shape_inside(sh, p)) continue;
      tried++;
      const double *T = sc.T_world_cam + 16 * (tried % cfg.n_views);
      double d[3] = {p[0] - T[3], p[1] - T[7], p[2] - T[11]};
      double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      for (int i = 0; i < 3; i++) d[i] /= dist;
      const double o[3] = {T[3], T[7], T[11]};
      sg_hit hit;
      int cls = sg_scene_trace(&sc, o, d, 0, &hit);
      ASSERT(cls >= SG_CLASS_MUG);
      ASSERT(hit.t <= dist + 1e-9);
    }
  }
  sg_scene_free(&sc);
}

/* ---------------------------------------------------------------- shape details */

static void test_mug_and_bowl(void) {
  sg_config cfg;
  sg_config_default(&cfg);
  cfg.seed = 5;
  sg_scene sc;
  ASSERT_OK(sg_scene_build(&sc, &cfg));
  const sg_shape *mug = &sc.objects[0].shape, *bowl = &sc.objects[1].shape;
  ASSERT_EQ(mug->type, SG_SHAPE_MUG);
  ASSERT_EQ(bowl->type, SG_SHAPE_BOWL);
  const double down[3] = {0, 0, -1};
  sg_hit hit;

  /* Straight down the mug's axis: through the open top onto its floor. */
  const double *M = mug->T_world_obj;
  double o[3] = {M[3], M[7], 1.0};
  ASSERT(sg_shape_intersect(mug, o, down, 0, INFINITY, &hit));
  ASSERT_NEAR(1.0 - hit.t, mug->bottom, 1e-12);
  ASSERT_NEAR(hit.n_world[2], 1.0, 1e-12);

  /* Straight down the bowl's axis: onto the inside of its floor. */
  const double *B = bowl->T_world_obj;
  double ob[3] = {B[3], B[7], 1.0};
  ASSERT(sg_shape_intersect(bowl, ob, down, 0, INFINITY, &hit));
  ASSERT_NEAR(1.0 - hit.t, B[11] + bowl->sphere_center_z - bowl->inner_radius, 1e-12);
  ASSERT_NEAR(hit.n_world[2], 1.0, 1e-12);

  /* From far out along the handle's direction, at the ring's height: the handle's outer edge. */
  double reach = mug->handle_center[0] + mug->handle_major + mug->handle_minor;
  double lp[3] = {1.0, 0, mug->handle_center[2]}, wp[3], ld[3] = {-1, 0, 0}, wd[3];
  sg_xform_point(M, lp, wp);
  sg_xform_dir(M, ld, wd);
  ASSERT(sg_shape_intersect(mug, wp, wd, 0, INFINITY, &hit));
  ASSERT_NEAR(hit.t, 1.0 - reach, 1e-6);
  double nl[3];
  sg_xform_dir(mug->T_obj_world, hit.n_world, nl);
  ASSERT_NEAR(nl[0], 1.0, 1e-3);

  /* Sideways through the handle's hole: nothing. Through its tube: the handle. */
  double hole_x = mug->handle_center[0] + 0.5 * (mug->handle_major - mug->handle_minor);
  ASSERT(hole_x > mug->outer_radius);
  double lh[3] = {hole_x, -1.0, mug->handle_center[2]}, ly[3] = {0, 1, 0}, wy[3];
  sg_xform_point(M, lh, wp);
  sg_xform_dir(M, ly, wy);
  ASSERT(!sg_shape_intersect(mug, wp, wy, 0, INFINITY, &hit));
  double lt[3] = {mug->handle_center[0] + mug->handle_major, -1.0, mug->handle_center[2]};
  sg_xform_point(M, lt, wp);
  ASSERT(sg_shape_intersect(mug, wp, wy, 0, INFINITY, &hit));
  ASSERT_NEAR(hit.t, 1.0 - mug->handle_minor, 1e-6);

  /* The handle's inner half, inside the cup, is not there. */
  double inner[3] = {mug->handle_center[0] - mug->handle_major, 0, mug->handle_center[2]}, wi[3];
  ASSERT(sg_mug_handle_sdf(mug, inner) < 0);
  sg_xform_point(M, inner, wi);
  ASSERT(!sg_shape_inside(mug, wi));
  sg_scene_free(&sc);
}

/* gt.json's shape parameters describe the same solids. */
static void test_shape_json_round_trip(void) {
  sg_config cfg;
  sg_config_default(&cfg);
  cfg.seed = 9;
  sg_scene sc;
  ASSERT_OK(sg_scene_build(&sc, &cfg));
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    const sg_shape *a = &sc.objects[k].shape;
    json_t *j = sg_shape_to_json(a);
    char *text = json_dumps(j, 0);
    json_decref(j);
    json_t *back = json_loads(text, 0, NULL);
    free(text);
    ASSERT(back != NULL);
    sg_shape b;
    ASSERT_OK(sg_shape_from_json(back, a->T_world_obj, &b));
    json_decref(back);
    ASSERT_EQ(b.type, a->type);
    double mn[3], mx[3];
    sg_shape_world_aabb(a, mn, mx);
    int inside = 0;
    for (int s = 0; s < 20000; s++) {
      double p[3];
      for (int i = 0; i < 3; i++) p[i] = mn[i] - 0.01 + (mx[i] - mn[i] + 0.02) * urand();
      int ia = sg_shape_inside(a, p);
      ASSERT_EQ(ia, sg_shape_inside(&b, p));
      /* The box bounds the solid. */
      if (ia)
        for (int i = 0; i < 3; i++) ASSERT(p[i] >= mn[i] - 1e-12 && p[i] <= mx[i] + 1e-12);
      inside += ia;
    }
    ASSERT(inside > 100);
  }
  sg_scene_free(&sc);
}

/* ---------------------------------------------------------------- embeddings and features */

static void test_embeddings_any_dim(void) {
  static const int dims[] = {6, 7, 8, 16, 64, 512};
  sg_config cfg;
  sg_config_default(&cfg);
  cfg.n_views = 1;
  for (size_t i = 0; i < sizeof dims / sizeof dims[0]; i++)
    for (uint64_t seed = 0; seed < 5; seed++) {
      cfg.dim = dims[i];
      cfg.seed = seed;
      sg_scene sc;
      ASSERT_OK(sg_scene_build(&sc, &cfg));
      check_embeddings(&sc);
      sg_scene_free(&sc);
    }
  cfg.dim = 5;
  sg_scene sc;
  ASSERT_ERR(sg_scene_build(&sc, &cfg), FG_EINVAL, "--dim");
}

static void test_feature_noise(void) {
  sg_config cfg;
  sg_config_default(&cfg);
  cfg.n_views = 2;
  cfg.dim = 512;
  cfg.noise = 0.2;
  sg_scene sc;
  ASSERT_OK(sg_scene_build(&sc, &cfg));
  size_t px = (size_t)cfg.w * cfg.h, cells = (size_t)sc.feat_h * sc.feat_w;
  uint8_t *mask = malloc(px);
  float *feat = malloc(cells * cfg.dim * sizeof(float));
  /* Left half mug, right half ball. */
  for (int v = 0; v < cfg.h; v++)
    for (int u = 0; u < cfg.w; u++)
      mask[v * cfg.w + u] = u < cfg.w / 2 ? SG_CLASS_MUG : SG_CLASS_BALL;
  ASSERT_OK(sg_scene_features(&sc, 1, mask, feat));
  double sum = 0;
  for (int a = 0; a < sc.feat_h; a++)
    for (int b = 0; b < sc.feat_w; b++) {
      int cls = b < sc.feat_w / 2 ? SG_CLASS_MUG : SG_CLASS_BALL;
      const float *f = feat + ((size_t)a * sc.feat_w + b) * cfg.dim;
      ASSERT_NEAR(cosine(f, f, cfg.dim), 1.0, 1e-6);
      sum += cosine(f, sc.embeddings + cls * cfg.dim, cfg.dim);
    }
  /* Noise of expected norm 0.2 on a unit vector: cosine about 1 / sqrt(1 + 0.04). */
  ASSERT_NEAR(sum / (double)cells, 1 / sqrt(1.04), 0.005);
  /* Without noise the features are the embeddings. */
  sc.cfg.noise = 0;
  ASSERT_OK(sg_scene_features(&sc, 0, mask, feat));
  ASSERT_NEAR(cosine(feat, sc.embeddings + SG_CLASS_MUG * cfg.dim, cfg.dim), 1.0, 1e-6);
  free(mask);
  free(feat);
  sg_scene_free(&sc);
}

int main(void) {
  test_layouts();
  test_hits_agree_with_inside();
  test_mug_and_bowl();
  test_shape_json_round_trip();
  test_embeddings_any_dim();
  test_feature_noise();
  return 0;
}
