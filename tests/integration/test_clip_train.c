/* CLIP features at training time: a scene whose frames have no uploaded features trains on
 * the CLIP features the job computes (equal to the library's own for the stored images), which
 * are cached in the scene's folder, read back by the next training and recomputed after new
 * weights and a SIGHUP; a scene that mixes uploaded features of another D with frames CLIP
 * would fill fails its job; and the heatmap render checks its query (text, embedding,
 * negatives) and renders, and so does a heatmap of a text query. */
#include <errno.h>
#include <math.h>
#include <sys/stat.h>
#include <unistd.h>

#include "clip_util.h"
#include "core/digest.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "io/npy.h"
#include "training.h"

#define VIEWS 4
#define W 48
#define H 36

static char *g_weights, *g_vocab, *g_sg;
static int g_E;

/* A copy of DIR/transforms.json without the frames' features_path. */
static void strip_features(const char *dir) {
  char *src = h_fmt("%s/transforms.json", dir), *dst = h_fmt("%s/transforms_rgb.json", dir);
  json_error_t err;
  json_t *t = json_load_file(src, 0, &err);
  if (!t) FG_TEST_FAIL("%s: %s", src, err.text);
  size_t i;
  json_t *f;
  json_array_foreach(json_object_get(t, "frames"), i, f) json_object_del(f, "features_path");
  ASSERT_EQ(json_dump_file(t, dst, JSON_INDENT(1)), 0);
  json_decref(t);
  free(src);
  free(dst);
}

/* The model's fingerprint, from POST /v1/embed/text (static). */
static const char *fingerprint(void) {
  static char fp[FG_SHA256_HEX + 1];
  h_resp *r = h_post_json("/v1/embed/text", "{\"text\": \"x\"}");
  ASSERT_STATUS(r, 200);
  snprintf(fp, sizeof fp, "%s", JSTR(r->json, "model.fingerprint"));
  h_resp_free(r);
  return fp;
}

static char *cache_path(const char *scene, int frame, const char *fp) {
  return h_fmt("%s/scenes/%s/clip/%06d.%s.npy", h_state_dir(), scene, frame, fp);
}

static struct timespec mtime_of(const char *path) {
  struct stat st;
  if (stat(path, &st) != 0) FG_TEST_FAIL("stat %s: %s", path, strerror(errno));
  return st.st_mtim;
}

/* Trains scene c for 3 steps and checks the features phase: total frames needed CLIP
 * features, cached of them came from the cache. Returns the finished job (caller decrefs). */
static json_t *train_checked(const char *scene, int total, int cached) {
  char *id = t_train(scene, "{\"steps\": 3}");
  json_t *j = t_wait_job(id, "done", 600);
  ASSERT_EQ(JINT(j, "features.total"), total);
  ASSERT_EQ(JINT(j, "features.done"), total);
  ASSERT_EQ(JINT(j, "features.cached"), cached);
  ASSERT_STREQ(JSTR(j, "phase"), "saving");
  ASSERT_EQ(JINT(j, "step"), 3);
  free(id);
  return j;
}

/* Every frame's cache file holds the library's features of the frame's image (as float16). */
static void check_cache(const char *scene, const char *fp) {
  for (int i = 0; i < VIEWS; i++) {
    char *path = cache_path(scene, i, fp);
    size_t len;
    char *buf = h_read_file(path, &len);
    if (!buf) FG_TEST_FAIL("no cache file %s", path);
    fg_npy npy;
    ASSERT_OK(fg_npy_parse(buf, len, &npy));
    ASSERT_EQ(npy.dtype, FG_DTYPE_F16);
    char *img_path = h_fmt("%s/images/%04d.png", g_sg, i);
    size_t img_len;
    char *img = h_read_file(img_path, &img_len);
    ASSERT(img);
    int hp, wp;
    float *mine = c_local_dense(g_weights, img, img_len, &hp, &wp);
    ASSERT_EQ(npy.ndim, 3);
    ASSERT_EQ(npy.shape[0], hp);
    ASSERT_EQ(npy.shape[1], wp);
    ASSERT_EQ(npy.shape[2], g_E);
    float *theirs = malloc(npy.count * sizeof *theirs);
    ASSERT(theirs);
    fg_half_to_float_n(npy.data, theirs, npy.count);
    /* float16 keeps 11 significant bits */
    for (size_t k = 0; k < npy.count; k++)
      ASSERT_NEAR(theirs[k], mine[k], 1e-3 * fmax(1.0, fabs(mine[k])));
    free(theirs);
    free(mine);
    free(img);
    free(img_path);
    free(buf);
    free(path);
  }
}

static void reload_weights(uint64_t seed, double loads) {
  c_write_model(g_weights, CLIPGEN_OPENAI, CLIPGEN_F16, seed);
  h_reload();
  ASSERT_EQ(h_metric("fieldgrip_clip_loads_total{result=\"ok\"}"), loads);
}

/* ---------------------------------------------------------------- heatmap queries */

static char *g_camera;

static void expect_query(const char *scene, const char *query, long status, const char *code) {
  char *body = h_fmt("{\"camera\": %s, \"output\": \"heatmap\"%s%s}", g_camera,
                     query[0] ? ", " : "", query);
  h_resp *r = t_render(scene, body);
  if (r->status != status) fprintf(stderr, "query: %s\n", query);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
  free(body);
}

/* A valid query renders the camera's 32x24 view as an 8-bit RGB PNG. */
static void expect_png(const char *scene, const char *query) {
  char *body = h_fmt("{\"camera\": %s, \"output\": \"heatmap\", %s}", g_camera, query);
  h_resp *r = t_render(scene, body);
  if (r->status != 200) fprintf(stderr, "query: %s: %s\n", query, r->body);
  int w, h, bits, type;
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 32);
  ASSERT_EQ(h, 24);
  ASSERT_EQ(bits, 8);
  ASSERT_EQ(type, 2);
  h_resp_free(r);
  free(body);
}

/* A JSON array of n numbers: e_k (a unit vector) when k >= 0, else all zeros. */
static char *vec(int n, int k) {
  it_buf b = {0};
  it_buf_add(&b, "[", 1);
  for (int i = 0; i < n; i++) it_buf_add(&b, i == k ? (i ? ", 2" : "2") : (i ? ", 0" : "0"),
                                         i ? 3 : 1);
  it_buf_add(&b, "]", 1);
  return b.p;
}

static void queries(void) {
  double eye[3] = {0.45, -0.6, 0.6}, target[3] = {0.45, 0, 0};
  g_camera = t_camera(eye, target, 40, 32, 24);
  char *e24 = vec(g_E, 3), *e8 = vec(8, 0), *zero = vec(g_E, -1);
  char *q;
  /* valid: text (default negatives through CLIP), several texts averaged, embedding, both
   * kinds of negatives */
  expect_png("c", "\"text\": \"a mug\"");
  expect_png("c", "\"text\": [\"a mug\", \"a cup\"]");
  expect_png("c", "\"text\": \"a mug\", \"negatives\": [], \"temperature\": 0.5");
  q = h_fmt("\"embedding\": %s", e24);
  expect_png("c", q);
  free(q);
  q = h_fmt("\"embedding\": %s, \"negatives\": [\"a cup\"]", e24);
  expect_png("c", q);
  free(q);
  q = h_fmt("\"text\": \"a mug\", \"negative_embeddings\": [%s, %s]", e24, e24);
  expect_png("c", q);
  free(q);
  /* the heatmap of texts: json with the scene's grid */
  h_resp *r = h_post_json("/v1/scenes/c/heatmap", "{\"text\": [\"a mug\", \"a cup\"], "
                          "\"alpha_threshold\": 0.001, \"max_points\": 3}");
  ASSERT_STATUS(r, 200);
  ASSERT(JINT(r->json, "returned") <= 3);
  ASSERT(json_is_array(JGET(r->json, "points")));
  ASSERT_NEAR(JNUM(r->json, "voxel_size"), 0.01, 1e-12);
  h_resp_free(r);
  /* malformed */
  expect_query("c", "", 400, "invalid_query");
  q = h_fmt("\"embedding\": %s", e8); /* the scene's D is 24 */
  expect_query("c", q, 400, "invalid_query");
  free(q);
  q = h_fmt("\"embedding\": %s", zero);
  expect_query("c", q, 400, "invalid_query");
  free(q);
  q = h_fmt("\"text\": \"a mug\", \"embedding\": %s", e24);
  expect_query("c", q, 400, "invalid_query");
  free(q);
  q = h_fmt("\"text\": \"a mug\", \"negative_embeddings\": [%s]", e8);
  expect_query("c", q, 400, "invalid_query");
  free(q);
  expect_query("c", "\"embedding\": [1, \"x\"]", 400, "invalid_query");
  expect_query("c", "\"text\": 5", 400, "invalid_query");
  expect_query("c", "\"text\": \"a mug\", \"negatives\": \"object\"", 400, "invalid_query");
  expect_query("c", "\"text\": \"a mug\", \"negatives\": [\"\"]", 400, "invalid_query");
  expect_query("c", "\"text\": \"a mug\", \"temperature\": 0", 400, "invalid_query");
  expect_query("c", "\"text\": \"a mug\", \"temperature\": -1", 400, "invalid_query");
  expect_query("c", "\"text\": \"a mug\", \"negatives\": [\"x\"], \"negative_embeddings\": []",
               400, "invalid_query");
  it_buf longtext = {0};
  for (int i = 0; i < 80; i++) it_buf_add(&longtext, "mug ", 4);
  q = h_fmt("\"text\": \"%s\"", longtext.p);
  expect_query("c", q, 400, "text_too_long");
  free(q);
  free(longtext.p);
  /* scene m has uploaded 8-d features: texts cannot query it, 8-d embeddings can */
  expect_query("m", "\"text\": \"a mug\"", 409, "feature_dim_mismatch");
  q = h_fmt("\"embedding\": %s", e8);
  expect_query("m", q, 409, "not_trained"); /* its training failed */
  free(q);
  free(e24);
  free(e8);
  free(zero);
  free(g_camera);
}

/* ---------------------------------------------------------------- mixed dimensions */

static void mixed_scene(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"m\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  uint8_t *png, *npy;
  size_t png_len, npy_len;
  h_png(32, 24, 3, 8, 5, 0, &png, &png_len);
  const int shape[3] = {3, 4, 8};
  h_npy("<f4", shape, 3, 1, &npy, &npy_len);
  double T[16];
  h_pose(T, 0.3, 0, 0, 0.45, 0, 0.5);
  char *meta = h_meta(T, "opengl", 30, 16, 12, 32, 24);
  r = h_upload("/v1/scenes/m/frames", png, png_len, meta, npy, npy_len);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  h_pose(T, -0.3, 0, 0, 0.45, 0, 0.5);
  free(meta);
  meta = h_meta(T, "opengl", 30, 16, 12, 32, 24);
  r = h_upload("/v1/scenes/m/frames", png, png_len, meta, NULL, 0);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  char *id = t_train("m", "{\"steps\": 2}");
  json_t *j = t_wait_job(id, "failed", 300);
  ASSERT_STRCONTAINS(JSTR(j, "error"), "D = 8");
  ASSERT_STRCONTAINS(JSTR(j, "error"), "E = 24");
  ASSERT_STREQ(JSTR(j, "phase"), "features");
  json_decref(j);
  free(id);
  /* nothing was computed for it */
  char *dir = h_fmt("%s/scenes/m/clip", h_state_dir());
  ASSERT_EQ(h_count_files(dir, ".npy"), 0);
  free(dir);
  free(meta);
  free(png);
  free(npy);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  char *imports = h_fmt("%s/imports", h_tmpdir());
  g_sg = h_fmt("%s/sg", imports);
  t_scenegen(argv[2], g_sg, VIEWS, W, H, 8, 0);
  strip_features(g_sg);
  g_weights = h_fmt("%s/clip.safetensors", h_tmpdir());
  g_vocab = c_vocab_path();
  c_write_model(g_weights, CLIPGEN_OPENAI, CLIPGEN_F32, 3);
  g_E = c_embed_dim(g_weights);
  char *conf = c_config(g_weights, g_vocab, imports);
  h_write_config(conf);
  free(conf);
  h_start();

  /* scene c: frames without features */
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"c\", \"workspace\": {\"min\": [0.1, -0.45, "
                          "-0.05], \"max\": [0.8, 0.45, 0.35]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  char *body = h_fmt("{\"path\": \"%s\", \"transforms\": \"transforms_rgb.json\"}", g_sg);
  r = h_post_json("/v1/scenes/c/import", body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), VIEWS);
  h_resp_free(r);
  free(body);
  r = h_get("/v1/scenes/c");
  ASSERT(json_is_null(JGET(r->json, "feature_dim")));
  h_resp_free(r);

  /* the first training computes every frame's features; a file named by the 16-digit
   * checksum fingerprint of earlier versions is another model's and goes */
  char fp0[FG_SHA256_HEX + 1];
  snprintf(fp0, sizeof fp0, "%s", fingerprint());
  char *clip_dir = h_fmt("%s/scenes/c/clip", h_state_dir());
  ASSERT_OK(fg_mkdir_p(clip_dir));
  free(clip_dir);
  char *legacy = cache_path("c", 0, "9a3c00e1f4b27d65");
  h_write_file(legacy, "x", 1);
  json_decref(train_checked("c", VIEWS, 0));
  ASSERT(access(legacy, F_OK) != 0);
  free(legacy);
  r = h_get("/v1/scenes/c");
  ASSERT_EQ(JINT(r->json, "feature_dim"), g_E);
  ASSERT(json_is_true(JGET(r->json, "trained")));
  h_resp_free(r);
  check_cache("c", fp0);
  ASSERT_EQ(h_metric("fieldgrip_clip_feature_frames_total{source=\"computed\"}"), VIEWS);
  ASSERT_EQ(h_metric("fieldgrip_clip_feature_frames_total{source=\"cached\"}"), 0);

  /* the second reads them back, leaving the files as they were */
  char *p0 = cache_path("c", 0, fp0);
  struct timespec m0 = mtime_of(p0);
  json_decref(train_checked("c", VIEWS, VIEWS));
  struct timespec m1 = mtime_of(p0);
  ASSERT(m0.tv_sec == m1.tv_sec && m0.tv_nsec == m1.tv_nsec);
  ASSERT_EQ(h_metric("fieldgrip_clip_feature_frames_total{source=\"computed\"}"), VIEWS);
  ASSERT_EQ(h_metric("fieldgrip_clip_feature_frames_total{source=\"cached\"}"), VIEWS);

  /* new weights: another fingerprint, the features are computed again and the old ones go */
  reload_weights(4, 2);
  char fp1[FG_SHA256_HEX + 1];
  snprintf(fp1, sizeof fp1, "%s", fingerprint());
  ASSERT(strcmp(fp0, fp1) != 0);
  json_decref(train_checked("c", VIEWS, 0));
  ASSERT_EQ(h_metric("fieldgrip_clip_feature_frames_total{source=\"computed\"}"), 2 * VIEWS);
  ASSERT(access(p0, F_OK) != 0);
  char *dir = h_fmt("%s/scenes/c/clip", h_state_dir());
  ASSERT_EQ(h_count_files(dir, ".npy"), VIEWS);
  ASSERT_EQ(h_count_files(dir, fp1), VIEWS);
  check_cache("c", fp1);

  mixed_scene();
  queries();

  /* the cache goes with its scene */
  r = h_delete("/v1/scenes/c");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  ASSERT(access(dir, F_OK) != 0);

  h_stop();
  free(dir);
  free(p0);
  free(g_weights);
  free(g_vocab);
  free(g_sg);
  free(imports);
  h_done();
  printf("ok\n");
  return 0;
}
