/* See crash_util.h. */
#include "crash_util.h"

#include "core/error.h"
#include "io/frame.h"

#include <dirent.h>
#include <sys/stat.h>

static const int feat_shape[3] = {4, 5, CU_FEAT_D};

/* The pose of upload seed: camera-to-world, OpenGL convention, metres. */
static void upload_pose(unsigned seed, double T[16]) {
  h_pose(T, 0.01 * (seed % 50), -0.2, 0.03 * (seed % 7), 0.001 * seed, 0.2, 0.5);
}

const char *cu_source(unsigned seed) {
  static char buf[32];
  snprintf(buf, sizeof buf, "u%u.png", seed);
  return buf;
}

h_resp *cu_upload(const char *scene, unsigned seed) {
  uint8_t *png, *npy;
  size_t png_len, npy_len;
  h_png(CU_W, CU_H, 3, 16, seed, 0, &png, &png_len);
  h_npy("<f4", feat_shape, 3, seed, &npy, &npy_len);
  double T[16];
  upload_pose(seed, T);
  char *meta = h_meta(T, "opengl", 40, CU_W / 2.0, CU_H / 2.0, CU_W, CU_H);
  char name[32];
  snprintf(name, sizeof name, "u%u.png", seed);
  h_part parts[3] = {{"image", png, png_len, name, "image/png"},
                     {"meta", meta, strlen(meta), NULL, "application/json"},
                     {"features", npy, npy_len, "f.npy", "application/octet-stream"}};
  char *path = h_fmt("/v1/scenes/%s/frames", scene);
  h_resp *r = h_upload_parts(path, parts, 3);
  free(path);
  free(meta);
  free(png);
  free(npy);
  return r;
}

static char *frame_path(const char *scene, long long index) {
  return h_fmt("%s/scenes/%s/frames/%06lld.fgf", h_state_dir(), scene, index);
}

void cu_check_upload(const char *scene, json_t *e, unsigned seed) {
  long long index = JINT(e, "frame");
  if (strcmp(JSTR(e, "source"), cu_source(seed)) != 0)
    FG_TEST_FAIL("scene %s frame %lld is %s, expected upload %s", scene, index, JSTR(e, "source"),
                 cu_source(seed));
  double T[16];
  upload_pose(seed, T);
  ASSERT_MATRIX(JGET(e, "transform_matrix"), T, 1e-9);
  ASSERT_EQ(JINT(e, "camera.w"), CU_W);
  ASSERT_EQ(JINT(e, "camera.h"), CU_H);
  ASSERT_EQ(JINT(e, "features.d"), CU_FEAT_D);

  /* The file itself: the library checks its CRC; the pixels are h_png's 16-bit pattern and
   * the features h_npy's values, both kept exactly. */
  char *path = frame_path(scene, index);
  fg_frame f;
  memset(&f, 0, sizeof f);
  int rc = fg_frame_load(path, &f);
  if (rc != 0) FG_TEST_FAIL("%s does not load: %s", path, fg_error_detail());
  ASSERT_EQ(f.cam.w, CU_W);
  ASSERT_EQ(f.cam.h, CU_H);
  for (int y = 0; y < CU_H; y++)
    for (int x = 0; x < CU_W; x++)
      for (int c = 0; c < 3; c++) {
        unsigned v = ((unsigned)(x * 5 + y * 3 + c * 40) + seed * 17u) % 256u * 257u;
        unsigned got = f.rgb[((size_t)y * CU_W + (size_t)x) * 3 + (size_t)c];
        if (got != v)
          FG_TEST_FAIL("%s: pixel (%d, %d) channel %d is %u, uploaded %u", path, x, y, c, got, v);
      }
  ASSERT_EQ(f.feat_dtype, FG_DTYPE_F32);
  ASSERT_EQ(f.feat_h * f.feat_w * f.feat_d, 4 * 5 * CU_FEAT_D);
  const float *feat = f.feat;
  for (int i = 0; i < 4 * 5 * CU_FEAT_D; i++) {
    float v = (float)(((size_t)i * 7 + seed) % 97) / 97.0f - 0.5f; /* as h_npy writes */
    if (feat[i] != v) FG_TEST_FAIL("%s: feature %d is %g, uploaded %g", path, i, feat[i], v);
  }
  fg_frame_clear(&f);
  free(path);
}

json_t *cu_check_scene_files(const char *scene) {
  char *p = h_fmt("/v1/scenes/%s/frames", scene);
  h_resp *r = h_get(p);
  free(p);
  ASSERT_STATUS(r, 200);
  json_t *frames = json_incref(JGET(r->json, "frames"));
  h_resp_free(r);
  size_t n = json_array_size(frames);
  for (size_t i = 0; i < n; i++) {
    json_t *e = json_array_get(frames, i);
    char *path = frame_path(scene, JINT(e, "frame"));
    fg_frame f;
    memset(&f, 0, sizeof f);
    if (fg_frame_load(path, &f) != 0)
      FG_TEST_FAIL("scene %s lists frame %lld, but %s does not load: %s", scene, JINT(e, "frame"),
                   path, fg_error_detail());
    ASSERT_EQ(f.cam.w, JINT(e, "camera.w"));
    ASSERT_EQ(f.cam.h, JINT(e, "camera.h"));
    fg_frame_clear(&f);
    free(path);
  }
  /* No frame file that the listing leaves out. */
  char *dir = h_fmt("%s/scenes/%s/frames", h_state_dir(), scene);
  DIR *d = opendir(dir);
  if (!d) FG_TEST_FAIL("cannot open %s", dir);
  size_t files = 0;
  struct dirent *de;
  while ((de = readdir(d)) != NULL) {
    size_t len = strlen(de->d_name);
    if (len > 4 && strcmp(de->d_name + len - 4, ".fgf") == 0 && de->d_name[0] != '.') files++;
  }
  closedir(d);
  if (files != n)
    FG_TEST_FAIL("scene %s: %zu frame files in %s but %zu frames listed", scene, files, dir, n);
  free(dir);
  return frames;
}

void cu_check_no_leftovers(void) {
  static const char *const needles[] = {".tmp.", ".incoming-", ".trash-", ".batch-"};
  for (size_t i = 0; i < sizeof needles / sizeof needles[0]; i++)
    if (h_count_files(h_state_dir(), needles[i]) != 0)
      FG_TEST_FAIL("files named *%s* are left under %s after the start-up", needles[i],
                   h_state_dir());
}

size_t cu_log_size(void) {
  char *log = h_log();
  size_t n = strlen(log);
  free(log);
  return n;
}

void cu_check_clean_start(size_t from) {
  static const char *const bad[] = {"is left out", "does not load", "unreadable",
                                    "is ignored", "cannot remove"};
  char *log = h_log();
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    const char *hit = strlen(log) > from ? strstr(log + from, bad[i]) : NULL;
    if (hit) {
      const char *line = hit;
      while (line > log + from && line[-1] != '\n') line--;
      const char *end = strchr(hit, '\n');
      FG_TEST_FAIL("the start-up after the kill reports a problem: %.*s",
                   (int)(end ? end - line : (long)strlen(line)), line);
    }
  }
  free(log);
}
