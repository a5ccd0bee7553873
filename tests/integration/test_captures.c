/* Captures and updates: frames join a capture (the newest by default, "new", or a number),
 * GET .../captures, trainings on the newest capture by default, on "all" or on named ones
 * (404 for one that does not exist), "init": "current" (409 without a field, or with a field
 * of another workspace or feature dimension; an update goes on from the scene's field, is
 * deterministic, and a cancelled one leaves the field as it was), an update's focus where
 * the views changed ("focus": its default, 0, and 400s), deleting a capture (its
 * frames and their cached features gone, 404 the second time, 409 while a job runs, a
 * deletion cut short finished at the next start), and all of it across a restart.
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <sys/stat.h>
#include <unistd.h>

#include "training.h"

#define VIEWS 8
#define LONG_JOB "{\"steps\": 1000000, \"init\": \"current\"}"

static char *g_sg; /* data set folder */

static char *file_bytes(const char *scene, const char *name, size_t *len) {
  char *p = h_fmt("%s/scenes/%s/%s", h_state_dir(), scene, name);
  char *b = h_read_file(p, len);
  free(p);
  return b;
}

/* The captures of scene, as GET .../captures lists them (caller decrefs). */
static json_t *captures(const char *scene) {
  char *path = h_fmt("/v1/scenes/%s/captures", scene);
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  json_t *c = json_incref(JGET(r->json, "captures"));
  h_resp_free(r);
  free(path);
  return c;
}

/* Imports the data set into scene with `capture` (a JSON value text, or NULL for none);
 * returns the capture the frames joined. */
static long long import_into(const char *scene, const char *capture) {
  char *path = h_fmt("/v1/scenes/%s/import", scene);
  char *body = capture ? h_fmt("{\"path\": \"%s\", \"capture\": %s}", g_sg, capture)
                       : h_fmt("{\"path\": \"%s\"}", g_sg);
  h_resp *r = h_post_json(path, body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), VIEWS);
  const long long c = JINT(r->json, "capture");
  h_resp_free(r);
  free(body);
  free(path);
  return c;
}

/* Uploads one small frame (features of D = dim when dim > 0) with meta's capture (a JSON
 * value text, or NULL); returns the reply's capture. */
static long long upload(const char *scene, const char *capture, int dim) {
  uint8_t *png, *npy = NULL;
  size_t png_len, npy_len = 0;
  h_png(32, 24, 3, 8, 5, 0, &png, &png_len);
  if (dim > 0) h_npy("<f4", (const int[]){3, 4, dim}, 3, 2, &npy, &npy_len);
  double T[16];
  h_pose(T, 0.3, -0.2, 0.1, 0.45, -0.6, 0.5);
  char *meta0 = h_meta(T, "opengl", 30, 16, 12, 32, 24);
  char *meta = capture ? h_fmt("%.*s, \"capture\": %s}", (int)strlen(meta0) - 1, meta0, capture)
                       : h_fmt("%s", meta0);
  char *path = h_fmt("/v1/scenes/%s/frames", scene);
  h_resp *r = h_upload(path, png, png_len, meta, npy, npy_len);
  ASSERT_STATUS(r, 201);
  const long long c = JINT(r->json, "capture");
  h_resp_free(r);
  free(path);
  free(meta);
  free(meta0);
  free(png);
  free(npy);
  return c;
}

static json_t *train_done(const char *scene, const char *body) {
  char *id = t_train(scene, body);
  json_t *j = t_wait_job(id, "done", 600);
  free(id);
  return j;
}

/* ---------------------------------------------------------------- joining captures */

static void test_joining(void) {
  t_scene_from_dataset("cap", g_sg, VIEWS); /* no capture given: the first one */
  ASSERT_EQ(import_into("cap", "\"new\""), 2);
  json_t *c = captures("cap");
  ASSERT_EQ(json_array_size(c), 2);
  ASSERT_EQ(JINT(c, "0.capture"), 1);
  ASSERT_EQ(JINT(c, "0.frames"), VIEWS);
  ASSERT_EQ(JINT(c, "0.frame_range.0"), 0);
  ASSERT_EQ(JINT(c, "0.frame_range.1"), VIEWS - 1);
  ASSERT(json_is_false(JGET(c, "0.latest")));
  ASSERT_EQ(JINT(c, "1.capture"), 2);
  ASSERT_EQ(JINT(c, "1.frame_range.0"), VIEWS);
  ASSERT_EQ(JINT(c, "1.with_robot_pose"), 0);
  ASSERT(json_is_true(JGET(c, "1.latest")));
  json_decref(c);

  /* an upload without a capture joins the newest; a number joins (or opens) that one */
  ASSERT_EQ(upload("cap", NULL, 8), 2);
  ASSERT_EQ(upload("cap", "\"latest\"", 8), 2);
  ASSERT_EQ(upload("cap", "1", 8), 1);
  ASSERT_EQ(upload("cap", "7", 8), 7);
  ASSERT_EQ(upload("cap", NULL, 8), 7);
  json_t *s = t_scene_json("cap");
  ASSERT_EQ(JINT(s, "frames"), 2 * VIEWS + 5);
  ASSERT_EQ(JINT(s, "captures"), 3);
  ASSERT_EQ(JINT(s, "latest_capture"), 7);
  json_decref(s);
  h_resp *r = h_get("/v1/scenes/cap/frames");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "frames.0.capture"), 1);
  ASSERT_EQ(JINT(r->json, "frames.8.capture"), 2);
  ASSERT(json_is_null(JGET(r->json, "frames.8.robot_pose")));
  ASSERT_EQ(JINT(r->json, "frames.18.capture"), 1);
  h_resp_free(r);

  /* a capture that is not "latest", "new" or 1..10^9 */
  uint8_t *png;
  size_t png_len;
  h_png(32, 24, 3, 8, 5, 0, &png, &png_len);
  double T[16];
  h_pose(T, 0, 0, 0, 0.45, 0, 0.6);
  char *meta0 = h_meta(T, "opengl", 30, 16, 12, 32, 24);
  ASSERT(meta0 != NULL);
  const char *bad[] = {"0", "-3", "\"newest\"", "1.5", "[1]", "10000000000"};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    char *meta = h_fmt("%.*s, \"capture\": %s}", (int)strlen(meta0) - 1, meta0, bad[i]);
    r = h_upload("/v1/scenes/cap/frames", png, png_len, meta, NULL, 0);
    ASSERT_HTTP_ERROR(r, 400, "invalid_request");
    h_resp_free(r);
    free(meta);
  }
  free(meta0);
  free(png);
  char *body = h_fmt("{\"path\": \"%s\", \"capture\": \"old\"}", g_sg);
  EXPECT_ERROR("POST", "/v1/scenes/cap/import", body, 400, "invalid_request");
  free(body);
  s = t_scene_json("cap");
  ASSERT_EQ(JINT(s, "frames"), 2 * VIEWS + 5); /* nothing stored */
  json_decref(s);
}

/* ---------------------------------------------------------------- trainings */

static void test_training_captures(void) {
  /* by default the newest capture: 7, two frames */
  json_t *j = train_done("cap", "{\"steps\": 5}");
  ASSERT_EQ(JINT(j, "frames"), 2);
  ASSERT_STREQ(JSTR(j, "captures"), "latest");
  ASSERT_STREQ(JSTR(j, "init"), "random");
  json_decref(j);
  j = train_done("cap", "{\"steps\": 5, \"captures\": [1, 2]}");
  ASSERT_EQ(JINT(j, "frames"), 2 * VIEWS + 3);
  ASSERT_EQ(JINT(j, "captures.1"), 2);
  json_decref(j);
  j = train_done("cap", "{\"steps\": 5, \"captures\": \"all\"}");
  ASSERT_EQ(JINT(j, "frames"), 2 * VIEWS + 5);
  json_decref(j);

  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"captures\": [2, 99]}", 404,
               "capture_not_found");
  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"captures\": [2, 2]}", 400, "invalid_request");
  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"captures\": []}", 400, "invalid_request");
  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"captures\": \"newest\"}", 400,
               "invalid_request");
  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"init\": \"warm\"}", 400, "invalid_request");
  /* holdout counts the frames of the captures chosen: 2 here */
  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"holdout_every\": 1}", 400, "invalid_request");

  /* an update needs a field, of the feature dimension the frames give */
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"plain\", \"workspace\": {\"min\": "
                          "[0.1, -0.45, -0.05], \"max\": [0.8, 0.45, 0.35]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  EXPECT_ERROR("POST", "/v1/scenes/plain/train", "{\"init\": \"current\"}", 409, "no_frames");
  for (int i = 0; i < 3; i++) upload("plain", NULL, 0);
  EXPECT_ERROR("POST", "/v1/scenes/plain/train", "{\"init\": \"current\"}", 409, "not_trained");
  json_decref(train_done("plain", "{\"steps\": 3}"));
  json_decref(train_done("plain", "{\"steps\": 3, \"init\": \"current\"}"));
  ASSERT_EQ(upload("plain", "\"new\"", 8), 2); /* features of D = 8; the field has none */
  EXPECT_ERROR("POST", "/v1/scenes/plain/train", "{\"init\": \"current\"}", 409,
               "feature_dim_mismatch");
}

/* An update starts from the scene's field: its first step's loss is below a new field's, it
 * is deterministic, and a cancelled one leaves the field as it was. */
static void test_update(void) {
  json_decref(train_done("cap", "{\"steps\": 20, \"captures\": [1], \"seed\": 4}"));
  size_t base_len;
  char *base = file_bytes("cap", "field.fgc", &base_len);
  ASSERT(base != NULL);
  json_t *u = train_done("cap", "{\"steps\": 1, \"captures\": [1], \"init\": \"current\"}");
  ASSERT_STREQ(JSTR(u, "init"), "current");
  const double loss_update = JNUM(u, "loss");
  json_decref(u);
  json_t *fresh = train_done("cap", "{\"steps\": 1, \"captures\": [1]}");
  const double loss_new = JNUM(fresh, "loss");
  json_decref(fresh);
  fprintf(stderr, "first step's loss: %.5f from the trained field, %.5f from a new one\n",
          loss_update, loss_new);
  ASSERT(loss_update < 0.5 * loss_new);

  /* the same field and request give the same update, byte for byte */
  size_t a_len, b_len;
  json_decref(train_done("cap", "{\"steps\": 20, \"captures\": [1], \"seed\": 4}"));
  char *again = file_bytes("cap", "field.fgc", &a_len);
  ASSERT(a_len == base_len && memcmp(again, base, a_len) == 0);
  free(again);
  u = train_done("cap", "{\"steps\": 6, \"captures\": [2], \"init\": \"current\"}");
  /* an update draws half its rays where its views differ from the field by default */
  ASSERT(fabs(JNUM(u, "focus") - 0.5) < 1e-9);
  const long long cells = JINT(u, "changes.cells"), changed = JINT(u, "changes.changed");
  const long long kept = JINT(u, "changes.kept");
  fprintf(stderr, "update's focus: %lld of %lld cells changed, %lld kept\n", changed, cells, kept);
  ASSERT(cells > 0 && changed >= 0 && changed <= kept && kept <= cells);
  json_decref(u);
  char *a = file_bytes("cap", "field.fgc", &a_len);
  json_t *s = t_scene_json("cap");
  ASSERT_EQ(JINT(s, "trained_steps"), 6); /* the update's own */
  json_decref(s);
  json_decref(train_done("cap", "{\"steps\": 20, \"captures\": [1], \"seed\": 4}"));
  json_decref(train_done("cap", "{\"steps\": 6, \"captures\": [2], \"init\": \"current\"}"));
  char *b = file_bytes("cap", "field.fgc", &b_len);
  ASSERT(a_len == b_len && memcmp(a, b, a_len) == 0);
  ASSERT(a_len != base_len || memcmp(a, base, a_len) != 0);

  /* focus 0: every ray drawn as a new field's, nothing compared; a focus is a share, and a
   * new field has nothing to compare with */
  json_decref(train_done("cap", "{\"steps\": 20, \"captures\": [1], \"seed\": 4}"));
  u = train_done("cap", "{\"steps\": 6, \"captures\": [2], \"init\": \"current\", "
                 "\"focus\": 0}");
  ASSERT(JNUM(u, "focus") == 0.0);
  ASSERT(json_is_null(JGET(u, "changes")));
  json_decref(u);
  char *c = file_bytes("cap", "field.fgc", &b_len);
  ASSERT(b_len != a_len || memcmp(c, a, a_len) != 0); /* the focus changed the update */
  free(c);
  json_t *fresh_job = train_done("cap", "{\"steps\": 1, \"captures\": [1]}");
  ASSERT(JNUM(fresh_job, "focus") == 0.0);
  json_decref(fresh_job);
  static const char *const bad_focus[] = {
      "{\"init\": \"current\", \"focus\": 1.5}", "{\"init\": \"current\", \"focus\": -0.1}",
      "{\"init\": \"current\", \"focus\": \"half\"}", "{\"focus\": 0.5}"};
  for (size_t i = 0; i < sizeof bad_focus / sizeof *bad_focus; i++)
    EXPECT_ERROR("POST", "/v1/scenes/cap/train", bad_focus[i], 400, "invalid_request");
  free(b);
  b = file_bytes("cap", "field.fgc", &b_len); /* the field the cancelled update must keep */

  /* cancelled half way: the field stays; meanwhile no capture can be deleted */
  char *id = t_train("cap", LONG_JOB);
  t_wait_running(id, 1, 600);
  EXPECT_ERROR("DELETE", "/v1/scenes/cap/captures/7", NULL, 409, "training_in_progress");
  char *path = h_fmt("/v1/jobs/%s", id);
  h_resp *r = h_delete(path);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  char *needle = h_fmt("job %s: stopped (cancelled)", id);
  if (!h_wait_log(needle, 1, 600)) FG_TEST_FAIL("the daemon never logged \"%s\"", needle);
  char *after = file_bytes("cap", "field.fgc", &a_len);
  ASSERT(a_len == b_len && memcmp(after, b, a_len) == 0);
  free(after);
  free(needle);
  free(path);
  free(id);
  free(a);
  free(b);
  free(base);
}

/* A configuration that declares scene "decl" with its workspace up to z_max. */
static char *declared(const char *imports, double z_max) {
  return h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = 2\nsteps = 5\n\n"
               "[scene decl]\nworkspace_min = 0.1 -0.45 -0.05\nworkspace_max = 0.8 0.45 %g\n",
               imports, z_max);
}

/* A declared scene whose workspace changed cannot go on from its field. */
static void test_field_mismatch(void) {
  char *imports = h_fmt("%s/imports", h_tmpdir());
  char *conf = declared(imports, 0.35);
  h_write_config(conf);
  h_reload();
  char *body = h_fmt("{\"path\": \"%s\"}", g_sg);
  h_resp *r = h_post_json("/v1/scenes/decl/import", body);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  json_decref(train_done("decl", "{}"));
  json_decref(train_done("decl", "{\"init\": \"current\"}"));
  free(conf);
  conf = declared(imports, 0.55);
  h_write_config(conf);
  h_reload();
  r = h_post_json("/v1/scenes/decl/train", "{\"init\": \"current\"}");
  ASSERT_HTTP_ERROR(r, 409, "field_mismatch");
  ASSERT(strstr(JSTR(r->json, "error.message"), "box") != NULL);
  h_resp_free(r);
  json_decref(train_done("decl", "{\"init\": \"random\"}"));
  free(body);
  free(conf);
  free(imports);
}

/* ---------------------------------------------------------------- deleting */

static int frame_file_exists(const char *scene, int number) {
  char *p = h_fmt("%s/scenes/%s/frames/%06d.fgf", h_state_dir(), scene, number);
  const int yes = access(p, F_OK) == 0;
  free(p);
  return yes;
}

static void test_delete(void) {
  /* cached CLIP features of a frame of capture 1 and of capture 2 (any model's) */
  char *clip = h_fmt("%s/scenes/cap/clip", h_state_dir());
  h_mkdirs(clip);
  char *f1 = h_fmt("%s/000003.0123abcd.npy", clip), *f2 = h_fmt("%s/000009.0123abcd.npy", clip);
  h_write_file(f1, "x", 1);
  h_write_file(f2, "x", 1);

  h_resp *r = h_delete("/v1/scenes/cap/captures/1");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "deleted"), 1);
  ASSERT_EQ(JINT(r->json, "frames"), VIEWS + 1);
  ASSERT_EQ(JINT(r->json, "latest_capture"), 7);
  h_resp_free(r);
  ASSERT(!frame_file_exists("cap", 0) && !frame_file_exists("cap", 18));
  ASSERT(frame_file_exists("cap", VIEWS));
  ASSERT(access(f1, F_OK) != 0);
  ASSERT(access(f2, F_OK) == 0);
  EXPECT_ERROR("DELETE", "/v1/scenes/cap/captures/1", NULL, 404, "capture_not_found");
  EXPECT_ERROR("DELETE", "/v1/scenes/cap/captures/x1", NULL, 400, "invalid_request");
  EXPECT_ERROR("DELETE", "/v1/scenes/nope/captures/1", NULL, 404, "scene_not_found");
  EXPECT_ERROR("POST", "/v1/scenes/cap/train", "{\"captures\": [1]}", 404, "capture_not_found");
  json_t *c = captures("cap");
  ASSERT_EQ(json_array_size(c), 2);
  ASSERT_EQ(JINT(c, "0.capture"), 2);
  json_decref(c);
  /* the field trained on them stays */
  json_t *s = t_scene_json("cap");
  ASSERT(json_is_true(JGET(s, "trained")));
  ASSERT_EQ(JINT(s, "frames"), VIEWS + 4);
  json_decref(s);

  /* the newest capture gone: uploads join the highest left */
  r = h_delete("/v1/scenes/cap/captures/7");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "latest_capture"), 2);
  h_resp_free(r);
  ASSERT_EQ(upload("cap", NULL, 8), 2);

  /* a deletion cut short: its list of frames is finished at the next start */
  h_stop();
  char *manifest = h_fmt("%s/scenes/cap/frames/.delete-1-0", h_state_dir());
  char *list = h_fmt("%06d.fgf\n%06d.fgf\n", VIEWS, VIEWS + 1);
  h_write_file(manifest, list, strlen(list));
  h_start();
  ASSERT(access(manifest, F_OK) != 0);
  ASSERT(!frame_file_exists("cap", VIEWS) && !frame_file_exists("cap", VIEWS + 1));
  ASSERT(h_wait_log("a capture's deletion", 1, 10));
  s = t_scene_json("cap");
  ASSERT_EQ(JINT(s, "frames"), VIEWS + 1); /* capture 2's ten and one upload, less two */
  ASSERT_EQ(JINT(s, "latest_capture"), 2);
  json_decref(s);
  free(manifest);
  free(list);
  free(f1);
  free(f2);
  free(clip);
}

/* Captures are in the frame files: a restart lists the same ones, and the newest is still
 * the one uploads join. */
static void test_restart(void) {
  json_t *before = captures("cap");
  h_stop();
  h_start();
  json_t *after = captures("cap");
  ASSERT_JSON_EQUAL(before, after);
  json_decref(before);
  json_decref(after);
  ASSERT_EQ(upload("cap", NULL, 8), 2);
  ASSERT_EQ(upload("cap", "\"new\"", 8), 3);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  g_sg = t_dataset(argv[2], VIEWS, 32, 24, 8, 0);
  h_start();
  test_joining();
  test_training_captures();
  test_update();
  test_field_mismatch();
  test_delete();
  test_restart();
  h_stop();
  free(g_sg);
  h_done();
  printf("captures: ok\n");
  return 0;
}
