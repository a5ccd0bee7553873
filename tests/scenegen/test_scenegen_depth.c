/* Black-box tests of fieldgrip-scenegen's (argv[1]) depth maps: --depth png and --depth npy
 * write one file per view of the right type and size, named by depth_file_path in both
 * transforms files; every pixel's depth is the z-depth (along the optical axis) of the ray
 * through its centre, checked against an independent trace of that ray through the geometry
 * that gt.json and transforms.json record; background pixels are 0; table pixels back-project
 * onto the plane z = 0. --depth none writes no depth at all, the same bytes at any thread
 * count, and a bad --depth is refused with a message. */
#include "testutil.h"

#include <errno.h>
#include <jansson.h>
#include <sys/stat.h>

#include "gt.h"
#include "io/image.h"
#include "io/npy.h"
#include "io/transforms.h"
#include "scene.h"

/* Small, with two held-out views so that both transforms files carry frames. */
enum { VIEWS = 4, W = 160, H = 120, HOLDOUT = 2 };

static const char *program;

static char *generate(const char *depth, const char *threads) {
  char *dir = sg_test_tmpdir("scenegen-depth");
  ASSERT(setenv("OMP_NUM_THREADS", threads, 1) == 0);
  char views[16], w[16], h[16], holdout[16];
  snprintf(views, sizeof views, "%d", VIEWS);
  snprintf(w, sizeof w, "%d", W);
  snprintf(h, sizeof h, "%d", H);
  snprintf(holdout, sizeof holdout, "%d", HOLDOUT);
  const char *args[] = {"--out",   dir,    "--seed",    "9",     "--views", views,
                        "--width", w,      "--height",  h,       "--dim",   "8",
                        "--patch", "16",   "--holdout", holdout, "--depth", depth,
                        NULL};
  ASSERT_EQ(sg_test_run(program, args), 0);
  return dir;
}

static json_t *load_json(const char *dir, const char *name) {
  char *path = fg_path_join(dir, name);
  json_error_t err;
  json_t *j = json_load_file(path, 0, &err);
  if (!j) FG_TEST_FAIL("%s:%d: %s", path, err.line, err.text);
  free(path);
  return j;
}

static int exists(const char *dir, const char *name) {
  char *path = fg_path_join(dir, name);
  struct stat st;
  int rc = stat(path, &st);
  if (rc != 0 && errno != ENOENT) FG_TEST_FAIL("stat %s: %s", path, strerror(errno));
  free(path);
  return rc == 0;
}

/* ---------------------------------------------------------------- reading depth files */

/* A big-endian 32-bit integer of the PNG header. */
static uint32_t be32(const uint8_t *p) {
  return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* depth/NNNN.png of view i into metres (h, w): checks from the header itself that it is
 * 16-bit greyscale (IHDR bit depth 16, colour type 0) of the image's size. */
static void load_depth_png(const char *dir, int i, double *z_m) {
  char name[64], *buf;
  size_t len;
  snprintf(name, sizeof name, "depth/%04d.png", i);
  sg_test_read(dir, name, &buf, &len);
  const uint8_t *b = (const uint8_t *)buf;
  ASSERT_STREQ(fg_image_sniff(buf, len), "PNG");
  ASSERT(len > 26 && memcmp(b + 12, "IHDR", 4) == 0);
  ASSERT_EQ(be32(b + 16), W);
  ASSERT_EQ(be32(b + 20), H);
  ASSERT_EQ(b[24], 16); /* bit depth */
  ASSERT_EQ(b[25], 0);  /* colour type: greyscale, no alpha */
  fg_image img;
  ASSERT_OK(fg_image_decode(buf, len, NULL, &img));
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  for (size_t p = 0; p < (size_t)W * H; p++) {
    /* The decoder divides by 65535 and expands grey to RGB; both undo exactly. */
    long mm = lrintf(img.rgb[3 * p] * 65535.0f);
    ASSERT(img.rgb[3 * p + 1] == img.rgb[3 * p] && img.rgb[3 * p + 2] == img.rgb[3 * p]);
    z_m[p] = mm * 0.001;
  }
  fg_image_release(&img);
  free(buf);
}

/* depth/NNNN.npy of view i: float32 [H, W] metres. */
static void load_depth_npy(const char *dir, int i, double *z_m) {
  char name[64], *buf;
  size_t len;
  snprintf(name, sizeof name, "depth/%04d.npy", i);
  sg_test_read(dir, name, &buf, &len);
  fg_npy npy;
  ASSERT_OK(fg_npy_parse(buf, len, &npy));
  ASSERT_EQ(npy.dtype, FG_DTYPE_F32);
  ASSERT_EQ(npy.ndim, 2);
  ASSERT_EQ(npy.shape[0], H);
  ASSERT_EQ(npy.shape[1], W);
  const float *f = npy.data;
  for (size_t p = 0; p < (size_t)W * H; p++) z_m[p] = f[p];
  free(buf);
}

static void load_mask(const char *dir, int i, uint8_t *mask) {
  char name[64], *buf;
  size_t len;
  snprintf(name, sizeof name, "masks/%04d.png", i);
  sg_test_read(dir, name, &buf, &len);
  fg_image img;
  ASSERT_OK(fg_image_decode(buf, len, NULL, &img));
  ASSERT(img.w == W && img.h == H);
  for (size_t p = 0; p < (size_t)W * H; p++) mask[p] = (uint8_t)lrintf(img.rgb[3 * p] * 255.0f);
  fg_image_release(&img);
  free(buf);
}

/* ---------------------------------------------------------------- JSON */

/* Both transforms files name depth/NNNN.ext for every frame (the view's own number), and only
 * a PNG data set says how many metres one unit is. */
static void check_transforms_json(const char *dir, const char *ext) {
  static const char *const files[] = {"transforms.json", "transforms_test.json"};
  int frames = 0;
  for (int k = 0; k < 2; k++) {
    json_t *root = load_json(dir, files[k]);
    const json_t *scale = json_object_get(root, "depth_unit_scale_factor");
    if (strcmp(ext, "png") == 0) {
      ASSERT(json_is_number(scale));
      ASSERT_NEAR(json_number_value(scale), 0.001, 0);
    } else {
      ASSERT(scale == NULL);
    }
    const json_t *fr = json_object_get(root, "frames");
    ASSERT(json_is_array(fr) && json_array_size(fr) > 0);
    for (size_t f = 0; f < json_array_size(fr); f++) {
      const json_t *frame = json_array_get(fr, f);
      const char *file = json_string_value(json_object_get(frame, "file_path"));
      const char *depth = json_string_value(json_object_get(frame, "depth_file_path"));
      ASSERT(file != NULL);
      char want[64];
      snprintf(want, sizeof want, "depth/%04d.%s", atoi(file + strlen("images/")), ext);
      ASSERT_STREQ(depth, want);
      ASSERT(exists(dir, depth));
      frames++;
    }
    json_decref(root);
  }
  ASSERT_EQ(frames, VIEWS);
  json_t *gt = load_json(dir, "gt.json");
  ASSERT_STREQ(json_string_value(json_object_get(gt, "depth")), ext);
  json_decref(gt);
}

/* ---------------------------------------------------------------- depth values */

/* The scene as the files record it: the table and objects of gt.json. Only what
 * sg_scene_trace reads is filled in. */
static void scene_from_gt(const sg_gt *gt, sg_scene *sc) {
  memset(sc, 0, sizeof *sc);
  ASSERT_EQ(gt->n_objects, SG_N_OBJECTS);
  memcpy(sc->table_min, gt->table_min, sizeof sc->table_min);
  memcpy(sc->table_max, gt->table_max, sizeof sc->table_max);
  for (int k = 0; k < SG_N_OBJECTS; k++) {
    sc->objects[k].shape = gt->objects[k].shape;
    sc->objects[k].class_id = gt->objects[k].class_id;
    sc->objects[k].present = 1;
  }
}

typedef struct stats {
  long hits, background, table_top, class_mismatch;
  double worst_rel, worst_abs_m, worst_table_z_m;
} stats;

/* Compares view f's depth map z_m (h, w) with the z-depth of an independent trace of every
 * pixel-centre ray: within tol_rel of it relative (npy) or tol_abs_m absolute (png). */
static void check_view(const sg_scene *sc, const fg_transforms_frame *f, const uint8_t *mask,
                       const double *z_m, double tol_rel, double tol_abs_m, stats *st) {
  const double *T = f->T_world_cam;
  const fg_camera *cam = &f->cam;
  const double o[3] = {T[3], T[7], T[11]};
  for (int v = 0; v < H; v++)
    for (int u = 0; u < W; u++) {
      const size_t p = (size_t)v * W + u;
      if (mask[p] == SG_CLASS_BACKGROUND) {
        if (z_m[p] != 0) FG_TEST_FAIL("background pixel (%d, %d) has depth %g", u, v, z_m[p]);
        st->background++;
        continue;
      }
      /* The unit ray in the camera frame (OpenGL: -z ahead), then in the world. */
      double d_cam[3] = {(u + 0.5 - cam->cx) / cam->fl_x, -(v + 0.5 - cam->cy) / cam->fl_y, -1};
      double n = sqrt(d_cam[0] * d_cam[0] + d_cam[1] * d_cam[1] + d_cam[2] * d_cam[2]);
      for (int k = 0; k < 3; k++) d_cam[k] /= n;
      double d[3];
      for (int k = 0; k < 3; k++)
        d[k] = T[4 * k] * d_cam[0] + T[4 * k + 1] * d_cam[1] + T[4 * k + 2] * d_cam[2];
      sg_hit hit;
      int cls = sg_scene_trace(sc, o, d, 0, &hit);
      if (cls != mask[p]) {
        /* gt.json's poses come back through quaternions: a ray grazing a silhouette within
         * 1e-16 of it may land on the other side. Counted, and bounded below. */
        st->class_mismatch++;
        continue;
      }
      const double z_ref = hit.t * -d_cam[2];
      if (!(z_m[p] > 0)) FG_TEST_FAIL("pixel (%d, %d) of class %d has depth %g", u, v, cls, z_m[p]);
      double err = fabs(z_m[p] - z_ref);
      if (err > tol_rel * z_ref + tol_abs_m)
        FG_TEST_FAIL("pixel (%d, %d) class %d: depth %.9g m, ray says %.9g m", u, v, cls, z_m[p],
                     z_ref);
      if (err / z_ref > st->worst_rel) st->worst_rel = err / z_ref;
      if (err > st->worst_abs_m) st->worst_abs_m = err;
      st->hits++;
      /* Back-project (u + 0.5, v + 0.5, z) through the camera: on the table's top the point
       * lies on z = 0 (its sides, 4 cm down to the slab's bottom, are left out). */
      if (cls == SG_CLASS_TABLE && hit.n_world[2] > 0.5) {
        const double z = z_m[p];
        double p_cam[3] = {(u + 0.5 - cam->cx) / cam->fl_x * z,
                           -(v + 0.5 - cam->cy) / cam->fl_y * z, -z};
        double z_world = T[8] * p_cam[0] + T[9] * p_cam[1] + T[10] * p_cam[2] + T[11];
        if (!(fabs(z_world) < 1e-3))
          FG_TEST_FAIL("table pixel (%d, %d) back-projects to z = %.6f m", u, v, z_world);
        if (fabs(z_world) > st->worst_table_z_m) st->worst_table_z_m = fabs(z_world);
        st->table_top++;
      }
    }
}

static void check_depth_values(const char *dir, int png) {
  sg_gt gt;
  char *path = fg_path_join(dir, "gt.json");
  ASSERT_OK(sg_gt_load(path, &gt));
  free(path);
  sg_scene sc;
  scene_from_gt(&gt, &sc);
  uint8_t *mask = malloc((size_t)W * H);
  double *z = malloc(sizeof(double) * W * H);
  ASSERT(mask && z);
  stats st = {0};
  static const char *const files[] = {"transforms.json", "transforms_test.json"};
  for (int k = 0; k < 2; k++) {
    fg_transforms t;
    path = fg_path_join(dir, files[k]);
    ASSERT_OK(fg_transforms_load(path, &t));
    free(path);
    for (size_t i = 0; i < t.n_frames; i++) {
      const fg_transforms_frame *f = &t.frames[i];
      int view = atoi(f->file_path + strlen("images/"));
      load_mask(dir, view, mask);
      if (png)
        load_depth_png(dir, view, z);
      else
        load_depth_npy(dir, view, z);
      /* npy: float32 of the exact depth; png: rounded to the millimetre, from a float. */
      check_view(&sc, f, mask, z, png ? 0 : 1e-6, png ? 0.5e-3 + 1e-6 : 0, &st);
    }
    fg_transforms_free(&t);
  }
  fprintf(stderr,
          "%s: %ld hits (worst error %.3g relative, %.3g mm), %ld background, %ld table-top "
          "pixels (worst |z_world| %.3f mm), %ld class mismatches\n",
          png ? "png" : "npy", st.hits, st.worst_rel, st.worst_abs_m * 1e3, st.background,
          st.table_top, st.worst_table_z_m * 1e3, st.class_mismatch);
  ASSERT(st.background > 0);
  ASSERT(st.table_top > (long)W * H / 4);
  ASSERT(st.hits > (long)VIEWS * W * H / 2);
  ASSERT(st.class_mismatch * 10000 <= (long)VIEWS * W * H);
  free(mask);
  free(z);
  sg_gt_free(&gt);
}

/* ---------------------------------------------------------------- the tests */

static void count_depth_files(const char *dir, const char *ext) {
  for (int i = 0; i < VIEWS; i++) {
    char name[64];
    snprintf(name, sizeof name, "depth/%04d.%s", i, ext);
    ASSERT(exists(dir, name));
  }
  char name[64];
  snprintf(name, sizeof name, "depth/%04d.%s", VIEWS, ext);
  ASSERT(!exists(dir, name));
}

static int same_file(const char *a, const char *b, const char *name) {
  char *x, *y;
  size_t nx, ny;
  sg_test_read(a, name, &x, &nx);
  sg_test_read(b, name, &y, &ny);
  int same = nx == ny && memcmp(x, y, nx) == 0;
  free(x);
  free(y);
  return same;
}

/* One thread; two (whole views in parallel); four (each view's rows in parallel). */
static void test_png(void) {
  char *a = generate("png", "1");
  count_depth_files(a, "png");
  check_transforms_json(a, "png");
  check_depth_values(a, 1);
  static const char *const threads[] = {"2", "4"};
  for (int k = 0; k < 2; k++) {
    char *b = generate("png", threads[k]);
    for (int i = 0; i < VIEWS; i++) {
      char name[64];
      snprintf(name, sizeof name, "depth/%04d.png", i);
      if (!same_file(a, b, name)) FG_TEST_FAIL("%s differs with %s threads", name, threads[k]);
    }
    ASSERT(same_file(a, b, "transforms.json") && same_file(a, b, "gt.json"));
    ASSERT_OK(fg_rmtree(b));
    free(b);
  }
  ASSERT_OK(fg_rmtree(a));
  free(a);
}

static void test_npy(void) {
  char *a = generate("npy", "4");
  count_depth_files(a, "npy");
  check_transforms_json(a, "npy");
  check_depth_values(a, 0);
  char *b = generate("npy", "1");
  for (int i = 0; i < VIEWS; i++) {
    char name[64];
    snprintf(name, sizeof name, "depth/%04d.npy", i);
    if (!same_file(a, b, name)) FG_TEST_FAIL("%s differs between 4 threads and 1", name);
  }
  ASSERT_OK(fg_rmtree(b));
  free(b);
  ASSERT_OK(fg_rmtree(a));
  free(a);
}

/* The default: no depth folder, no depth keys anywhere. */
static void test_none(void) {
  char *dir = generate("none", "2");
  ASSERT(!exists(dir, "depth"));
  static const char *const files[] = {"transforms.json", "transforms_test.json"};
  for (int k = 0; k < 2; k++) {
    json_t *root = load_json(dir, files[k]);
    ASSERT(json_object_get(root, "depth_unit_scale_factor") == NULL);
    const json_t *fr = json_object_get(root, "frames");
    ASSERT(json_array_size(fr) > 0);
    for (size_t f = 0; f < json_array_size(fr); f++)
      ASSERT(json_object_get(json_array_get(fr, f), "depth_file_path") == NULL);
    json_decref(root);
  }
  json_t *gt = load_json(dir, "gt.json");
  ASSERT(json_object_get(gt, "depth") == NULL);
  json_decref(gt);
  ASSERT_OK(fg_rmtree(dir));
  free(dir);
}

static void test_bad_value(void) {
  char *dir = sg_test_tmpdir("scenegen-depth-args");
  char *log = fg_path_join(dir, "stderr.txt");
  char *out = fg_path_join(dir, "out");
  const char *args[] = {"--out", out, "--depth", "exr", NULL};
  ASSERT_EQ(sg_test_run_logged(program, args, log), 2);
  char *text;
  size_t len;
  ASSERT_OK(fg_read_file(log, 1 << 20, &text, &len));
  ASSERT_STRCONTAINS(text, "--depth wants none, png or npy, got \"exr\"");
  free(text);
  ASSERT(!exists(dir, "out"));
  free(log);
  free(out);
  ASSERT_OK(fg_rmtree(dir));
  free(dir);
}

int main(int argc, char **argv) {
  if (argc < 2) FG_TEST_FAIL("usage: %s PATH-TO-fieldgrip-scenegen", argv[0]);
  program = argv[1];
  test_png();
  test_npy();
  test_none();
  test_bad_value();
  return 0;
}
