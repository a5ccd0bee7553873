/* Black-box tests of a data set written by fieldgrip-scenegen (argv[1]): file counts and image
 * sizes, transforms.json through the library's reader, feature grids through fg_npy_parse,
 * features that agree with the masks, objects whose projected centres land on their own mask
 * pixels, grasps whose fingertips meet the surface, background pixels of the recorded colour,
 * and a frame that the daemon's ingest (fg_frame_prepare) accepts. */
#include "testutil.h"

#include <dirent.h>

#include "core/half.h"
#include "core/pose.h"
#include "gt.h"
#include "io/frame.h"
#include "io/image.h"
#include "io/npy.h"
#include "io/transforms.h"

/* A small configuration whose image size is not a multiple of the patch, so the feature grid
 * follows SPEC.md's cell rule rather than v / P. */
enum { VIEWS = 12, W = 250, H = 180, DIM = 16, PATCH = 16, HOLDOUT = 4 };
enum { FH = (H + PATCH - 1) / PATCH, FW = (W + PATCH - 1) / PATCH };

static const char *program;
static char *dir;
static sg_gt gt;

static void generate(void) {
  dir = sg_test_tmpdir("scenegen");
  char views[16], w[16], h[16], dim[16], patch[16], holdout[16];
  snprintf(views, sizeof views, "%d", VIEWS);
  snprintf(w, sizeof w, "%d", W);
  snprintf(h, sizeof h, "%d", H);
  snprintf(dim, sizeof dim, "%d", DIM);
  snprintf(patch, sizeof patch, "%d", PATCH);
  snprintf(holdout, sizeof holdout, "%d", HOLDOUT);
  const char *args[] = {"--out", dir,         "--seed",  "7",         "--views",
                        views,   "--width",   w,         "--height",  h,
                        "--dim", dim,         "--patch", patch,       "--holdout",
                        holdout, "--noise",   "0.05",    NULL};
  ASSERT_EQ(sg_test_run(program, args), 0);
  char *path = fg_path_join(dir, "gt.json");
  ASSERT_OK(sg_gt_load(path, &gt));
  free(path);
}

static int count_files(const char *sub, const char *ext) {
  char *path = fg_path_join(dir, sub);
  DIR *d = opendir(path);
  ASSERT(d != NULL);
  int n = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    size_t len = strlen(e->d_name), el = strlen(ext);
    if (len > el && strcmp(e->d_name + len - el, ext) == 0) n++;
  }
  closedir(d);
  free(path);
  return n;
}

/* Decoded mask of view i: class indices (H, W). */
static void load_mask(int i, uint8_t *mask) {
  char name[64], *buf;
  size_t len;
  snprintf(name, sizeof name, "masks/%04d.png", i);
  sg_test_read(dir, name, &buf, &len);
  fg_image img;
  ASSERT_OK(fg_image_decode(buf, len, NULL, &img));
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  for (size_t p = 0; p < (size_t)W * H; p++) {
    long v = lrintf(img.rgb[3 * p] * 255.0f);
    ASSERT(v >= 0 && v < gt.n_classes);
    mask[p] = (uint8_t)v;
  }
  fg_image_release(&img);
  free(buf);
}

/* Decoded image of view i, floats (H, W, 3). */
static void load_image(int i, fg_image *img) {
  char name[64], *buf;
  size_t len;
  snprintf(name, sizeof name, "images/%04d.png", i);
  sg_test_read(dir, name, &buf, &len);
  ASSERT_STREQ(fg_image_sniff(buf, len), "PNG");
  ASSERT_OK(fg_image_decode(buf, len, NULL, img));
  free(buf);
}

/* ---------------------------------------------------------------- files */

static void test_files(void) {
  ASSERT_EQ(count_files("images", ".png"), VIEWS);
  ASSERT_EQ(count_files("masks", ".png"), VIEWS);
  ASSERT_EQ(count_files("features", ".npy"), VIEWS);
  for (int i = 0; i < VIEWS; i++) {
    fg_image img;
    load_image(i, &img);
    ASSERT_EQ(img.w, W);
    ASSERT_EQ(img.h, H);
    fg_image_release(&img);
  }
  ASSERT_EQ(gt.width, W);
  ASSERT_EQ(gt.height, H);
  ASSERT_EQ(gt.views, VIEWS);
  ASSERT_EQ(gt.feature_dim, DIM);
  ASSERT_EQ(gt.patch, PATCH);
  ASSERT_EQ(gt.seed, 7);
}

/* ---------------------------------------------------------------- transforms */

/* Finds view i among the training and held-out frames. */
static const fg_transforms_frame *find_view(const fg_transforms *train, const fg_transforms *test,
                                            int i) {
  char want[64];
  snprintf(want, sizeof want, "images/%04d.png", i);
  for (size_t k = 0; k < train->n_frames; k++)
    if (strcmp(train->frames[k].file_path, want) == 0) return &train->frames[k];
  for (size_t k = 0; k < test->n_frames; k++)
    if (strcmp(test->frames[k].file_path, want) == 0) return &test->frames[k];
  FG_TEST_FAIL("view %d is in neither transforms file", i);
}

static fg_transforms train, test;

static void check_frames(const fg_transforms *t, int held_out) {
  for (size_t k = 0; k < t->n_frames; k++) {
    const fg_transforms_frame *f = &t->frames[k];
    ASSERT(f->image_path != NULL);
    ASSERT(f->features_path != NULL);
    ASSERT_OK(fg_pose_validate(f->T_world_cam));
    ASSERT_EQ(f->has_size, 1);
    ASSERT_EQ(f->cam.w, W);
    ASSERT_EQ(f->cam.h, H);
    ASSERT_EQ(f->cam.model, FG_CAMERA_PINHOLE);
    ASSERT_NEAR(f->cam.cx, W / 2.0, 1e-12);
    ASSERT_NEAR(f->cam.cy, H / 2.0, 1e-12);
    ASSERT_NEAR(f->cam.fl_x, f->cam.fl_y, 1e-12);
    int view = atoi(f->file_path + strlen("images/"));
    ASSERT_EQ(view % HOLDOUT == 0, held_out);
    char want[64];
    snprintf(want, sizeof want, "features/%04d.npy", view);
    ASSERT_STRCONTAINS(f->features_path, want);
    /* The camera sits on the 0.9 m hemisphere around the look-at point, 25..70 degrees up,
     * and looks at it (OpenGL: along -z). */
    const double *T = f->T_world_cam;
    const double c[3] = {0.45, 0, 0.05};
    double v[3] = {T[3] - c[0], T[7] - c[1], T[11] - c[2]};
    double r = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    ASSERT_NEAR(r, 0.9, 1e-9);
    double el = asin(v[2] / r) * 180 / M_PI;
    ASSERT(el >= 25 - 1e-9 && el <= 70 + 1e-9);
    for (int a = 0; a < 3; a++) ASSERT_NEAR(T[4 * a + 2], v[a] / r, 1e-9);
  }
}

static void test_transforms(void) {
  char *path = fg_path_join(dir, "transforms.json");
  ASSERT_OK(fg_transforms_load(path, &train));
  free(path);
  path = fg_path_join(dir, "transforms_test.json");
  ASSERT_OK(fg_transforms_load(path, &test));
  free(path);
  ASSERT_EQ(train.n_missing, 0);
  ASSERT_EQ(test.n_missing, 0);
  ASSERT_EQ(test.n_frames, (VIEWS + HOLDOUT - 1) / HOLDOUT);
  ASSERT_EQ(train.n_frames + test.n_frames, VIEWS);
  check_frames(&train, 0);
  check_frames(&test, 1);
}

/* ---------------------------------------------------------------- classes and features */

static double cosine(const float *a, const float *b, int n) {
  double ab = 0, aa = 0, bb = 0;
  for (int i = 0; i < n; i++) {
    ab += (double)a[i] * b[i];
    aa += (double)a[i] * a[i];
    bb += (double)b[i] * b[i];
  }
  return ab / sqrt(aa * bb);
}

static void test_classes(void) {
  static const char *const names[] = {"background", "table", "mug", "bowl", "box", "ball"};
  ASSERT_EQ(gt.n_classes, 6);
  for (int k = 0; k < 6; k++) {
    ASSERT_STREQ(gt.class_names[k], names[k]);
    const float *e = gt.embeddings + (size_t)k * DIM;
    ASSERT_NEAR(cosine(e, e, DIM), 1.0, 1e-6);
    double n = 0;
    for (int i = 0; i < DIM; i++) n += (double)e[i] * e[i];
    ASSERT_NEAR(n, 1.0, 1e-5);
    for (int j = 0; j < k; j++)
      ASSERT(cosine(e, gt.embeddings + (size_t)j * DIM, DIM) < 0.3);
  }
  ASSERT_EQ(gt.n_objects, 4);
  for (int k = 0; k < 4; k++) {
    ASSERT_STREQ(gt.objects[k].name, names[k + 2]);
    ASSERT_EQ(gt.objects[k].class_id, k + 2);
  }
}

static void test_features(void) {
  uint8_t *mask = malloc((size_t)W * H);
  float *feat = malloc(sizeof(float) * FH * FW * DIM);
  ASSERT(mask && feat);
  int mug_cells = 0, mug_pixels_checked = 0;
  double min_cos = 1;
  for (int i = 0; i < VIEWS; i++) {
    load_mask(i, mask);
    char name[64], *buf;
    size_t len;
    snprintf(name, sizeof name, "features/%04d.npy", i);
    sg_test_read(dir, name, &buf, &len);
    fg_npy npy;
    ASSERT_OK(fg_npy_parse(buf, len, &npy));
    ASSERT_EQ(npy.dtype, FG_DTYPE_F16);
    ASSERT_EQ(npy.ndim, 3);
    ASSERT_EQ(npy.shape[0], FH);
    ASSERT_EQ(npy.shape[1], FW);
    ASSERT_EQ(npy.shape[2], DIM);
    ASSERT_OK(fg_frame_check_features(&npy));
    fg_half_to_float_n(npy.data, feat, (size_t)FH * FW * DIM);
    free(buf);

    /* Each cell's plurality class, counted with SPEC.md's pixel-to-cell rule. */
    int counts[FH][FW][6];
    memset(counts, 0, sizeof counts);
    for (int v = 0; v < H; v++)
      for (int u = 0; u < W; u++) counts[v * FH / H][u * FW / W][mask[v * W + u]]++;
    for (int a = 0; a < FH; a++)
      for (int b = 0; b < FW; b++) {
        int best = 0;
        for (int k = 1; k < 6; k++)
          if (counts[a][b][k] > counts[a][b][best]) best = k;
        const float *f = feat + ((size_t)a * FW + b) * DIM;
        double c = cosine(f, gt.embeddings + (size_t)best * DIM, DIM);
        if (c < min_cos) min_cos = c;
        ASSERT(c > 0.9);
        /* Unit length up to float16 rounding. */
        ASSERT_NEAR(cosine(f, f, DIM), 1.0, 1e-6);
        if (best == 2) mug_cells++;
      }
    /* The brief's check: at every pixel the mask calls "mug" whose cell is mostly mug, the
     * feature is the mug's. */
    for (int v = 0; v < H; v++)
      for (int u = 0; u < W; u++) {
        if (mask[v * W + u] != 2) continue;
        int a = v * FH / H, b = u * FW / W;
        int total = 0;
        for (int k = 0; k < 6; k++) total += counts[a][b][k];
        if (2 * counts[a][b][2] <= total) continue;
        ASSERT(cosine(feat + ((size_t)a * FW + b) * DIM, gt.embeddings + 2 * DIM, DIM) > 0.9);
        mug_pixels_checked++;
      }
  }
  fprintf(stderr, "features: %d mug cells, %d mug pixels checked, min cosine %.4f\n", mug_cells,
          mug_pixels_checked, min_cos);
  ASSERT(mug_cells >= VIEWS);
  ASSERT(mug_pixels_checked > 0);
  free(mask);
  free(feat);
}

/* ---------------------------------------------------------------- geometry */

/* In view 0 (the highest camera) each object's centre projects onto its own mask pixels, and
 * the segment from the camera to it crosses no other object (the inside test agrees). */
static void test_projected_centres(void) {
  const fg_transforms_frame *f = find_view(&train, &test, 0);
  uint8_t *mask = malloc((size_t)W * H);
  load_mask(0, mask);
  const double *T = f->T_world_cam;
  for (int k = 0; k < gt.n_objects; k++) {
    const sg_gt_object *ob = &gt.objects[k];
    double u, v;
    ASSERT(sg_test_project(&f->cam, T, ob->position, &u, &v));
    ASSERT(u >= 0 && u < W && v >= 0 && v < H);
    int px = (int)floor(u), py = (int)floor(v);
    if (mask[py * W + px] != ob->class_id)
      FG_TEST_FAIL("%s projects to (%d, %d) where the mask holds %d", ob->name, px, py,
                   mask[py * W + px]);
    for (int s = 1; s < 400; s++) {
      double a = s / 400.0, p[3];
      for (int c = 0; c < 3; c++) p[c] = ob->position[c] + a * (T[4 * c + 3] - ob->position[c]);
      for (int j = 0; j < gt.n_objects; j++)
        if (j != k) ASSERT(!sg_gt_inside(&gt, j, p));
    }
  }
  free(mask);
}

/* Objects stand on the table inside the default workspace, and all of them are in every view. */
static void test_in_view(void) {
  for (int k = 0; k < gt.n_objects; k++) {
    const sg_gt_object *ob = &gt.objects[k];
    ASSERT(ob->aabb_min[0] >= 0.10 && ob->aabb_max[0] <= 0.80);
    ASSERT(ob->aabb_min[1] >= -0.45 && ob->aabb_max[1] <= 0.45);
    ASSERT_NEAR(ob->aabb_min[2], 0.0, 1e-9);
    ASSERT(ob->aabb_max[2] <= 0.35);
    ASSERT(sg_gt_inside(&gt, k, ob->position) || ob->shape.type == SG_SHAPE_MUG ||
           ob->shape.type == SG_SHAPE_BOWL);
    /* the shape read back from gt.json intersects rays like the one the scene drew: a ray
     * straight down onto the top face of the bounding box's centre hits it */
    {
      const double o[3] = {(ob->aabb_min[0] + ob->aabb_max[0]) / 2,
                           (ob->aabb_min[1] + ob->aabb_max[1]) / 2, 1.0};
      const double down[3] = {0, 0, -1};
      sg_hit hit;
      ASSERT(sg_shape_intersect(&ob->shape, o, down, 0, INFINITY, &hit));
      ASSERT(hit.t > 1.0 - ob->aabb_max[2] - 1e-9 && hit.t < 1.0 + 1e-9);
    }
    for (int i = 0; i < VIEWS; i++) {
      const fg_transforms_frame *f = find_view(&train, &test, i);
      for (int c = 0; c < 8; c++) {
        double p[3] = {(c & 1) ? ob->aabb_max[0] : ob->aabb_min[0],
                       (c & 2) ? ob->aabb_max[1] : ob->aabb_min[1],
                       (c & 4) ? ob->aabb_max[2] : ob->aabb_min[2]};
        double u, v;
        ASSERT(sg_test_project(&f->cam, f->T_world_cam, p, &u, &v));
        ASSERT(u >= 0 && u <= W && v >= 0 && v <= H);
      }
    }
  }
}

/* Each grasp approaches from above, closes horizontally, and its fingertips, width / 2 either
 * side of the TCP along +y, sit on the object's surface: just inside is solid, just outside is
 * free. */
static void test_grasps(void) {
  for (int k = 0; k < gt.n_objects; k++) {
    const sg_gt_object *ob = &gt.objects[k];
    const double *G = ob->T_world_grasp;
    ASSERT_OK(fg_pose_validate(G));
    double y[3] = {G[1], G[5], G[9]}, z[3] = {G[2], G[6], G[10]}, p[3] = {G[3], G[7], G[11]};
    ASSERT(z[2] < -0.999);
    ASSERT_NEAR(y[2], 0.0, 1e-9);
    ASSERT(ob->grasp_width_m > 0.002 && ob->grasp_width_m <= 0.08);
    for (int c = 0; c < 3; c++) ASSERT(p[c] >= ob->aabb_min[c] && p[c] <= ob->aabb_max[c]);
    double half = ob->grasp_width_m / 2, margin = fmin(1e-3, half / 4);
    for (int side = -1; side <= 1; side += 2) {
      double in[3], out[3];
      for (int c = 0; c < 3; c++) {
        in[c] = p[c] + side * (half - margin) * y[c];
        out[c] = p[c] + side * (half + margin) * y[c];
      }
      if (!sg_gt_inside(&gt, k, in)) FG_TEST_FAIL("%s: fingertip %d not on solid", ob->name, side);
      if (sg_gt_inside(&gt, k, out)) FG_TEST_FAIL("%s: fingertip %d buried", ob->name, side);
    }
  }
}

/* Rays that miss the table show exactly the recorded background colour. */
static void test_background(void) {
  uint8_t *mask = malloc((size_t)W * H);
  int seen = 0;
  for (int i = 0; i < VIEWS; i++) {
    load_mask(i, mask);
    fg_image img;
    load_image(i, &img);
    for (int v = 1; v < H - 1; v++)
      for (int u = 1; u < W - 1; u++) {
        int all = 1;
        for (int dv = -1; dv <= 1; dv++)
          for (int du = -1; du <= 1; du++) all &= mask[(v + dv) * W + u + du] == 0;
        if (!all) continue;
        for (int c = 0; c < 3; c++)
          ASSERT_NEAR(img.rgb[3 * (v * W + u) + c], gt.background_rgb[c], 1e-6);
        seen++;
      }
    fg_image_release(&img);
  }
  ASSERT(seen > 0);
  free(mask);
}

/* ---------------------------------------------------------------- ingest */

static void test_ingest(void) {
  const fg_transforms_frame *f = &train.frames[0];
  char *img, *npy_buf;
  size_t img_len, npy_len;
  ASSERT_OK(fg_read_file(f->image_path, (size_t)1 << 26, &img, &img_len));
  ASSERT_OK(fg_read_file(f->features_path, (size_t)1 << 26, &npy_buf, &npy_len));
  fg_npy npy;
  ASSERT_OK(fg_npy_parse(npy_buf, npy_len, &npy));
  fg_transforms_frame fc = *f;
  ASSERT_OK(fg_transforms_complete_camera(&fc, W, H));
  fg_ingest_opts opts = {.max_image_side = 0};
  memcpy(opts.background_rgb, gt.background_rgb, sizeof opts.background_rgb);
  fg_frame frame;
  ASSERT_OK(fg_frame_prepare(&frame, img, img_len, &fc.cam, fc.T_world_cam, &npy, &opts));
  ASSERT_EQ(frame.cam.w, W);
  ASSERT_EQ(frame.cam.h, H);
  ASSERT_EQ(frame.feat_h, FH);
  ASSERT_EQ(frame.feat_w, FW);
  ASSERT_EQ(frame.feat_d, DIM);
  ASSERT_EQ(frame.feat_dtype, FG_DTYPE_F16);
  fg_frame_clear(&frame);
  free(img);
  free(npy_buf);
}

int main(int argc, char **argv) {
  if (argc < 2) FG_TEST_FAIL("usage: %s PATH-TO-fieldgrip-scenegen", argv[0]);
  program = argv[1];
  generate();
  test_files();
  test_transforms();
  test_classes();
  test_features();
  test_projected_centres();
  test_in_view();
  test_grasps();
  test_background();
  test_ingest();
  fg_transforms_free(&train);
  fg_transforms_free(&test);
  sg_gt_free(&gt);
  ASSERT_OK(fg_rmtree(dir));
  free(dir);
  return 0;
}
