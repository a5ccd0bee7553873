/* POST /v1/scenes/{s}/render: 409 before training; after it, an 8-bit RGB PNG, a 16-bit grey
 * depth PNG and an 8-bit RGB normal PNG of the asked size (intrinsics inside "camera" or at the
 * top level, OpenGL or OpenCV convention); the same bytes for the same request; bad cameras and
 * outputs refused with JSON errors; renders keep using the old field while a new training runs,
 * and a cancelled training leaves the field as it was; the same bytes after a restart; a
 * truncated checkpoint leaves the daemon healthy and the scene untrained (409,
 * checkpoint_error); and the daemon never loads OpenImageIO (PNG encoding happens in
 * fieldgrip-decode).
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <sys/stat.h>
#include <unistd.h>

#include "training.h"

static char *g_camera; /* a camera JSON object looking at the table */

static h_resp *render_camera(const char *scene, const char *camera, const char *extra) {
  char *body = h_fmt("{\"camera\": %s%s%s}", camera, extra ? ", " : "", extra ? extra : "");
  h_resp *r = t_render(scene, body);
  free(body);
  return r;
}

static void expect_error(const char *body, long status, const char *code) {
  h_resp *r = t_render("sg", body);
  if (r->status != status) fprintf(stderr, "render %s\n", body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
}

/* The RGB render of g_camera; caller frees. */
static h_resp *reference_render(void) {
  h_resp *r = render_camera("sg", g_camera, NULL);
  int w, h, bits, type;
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 64);
  ASSERT_EQ(h, 48);
  return r;
}

static void assert_same_bytes(const h_resp *a, const h_resp *b) {
  ASSERT_EQ(a->len, b->len);
  ASSERT(memcmp(a->body, b->body, a->len) == 0);
}

static void test_formats(void) {
  int w, h, bits, type;
  h_resp *r = render_camera("sg", g_camera, "\"output\": \"rgb\"");
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 64);
  ASSERT_EQ(h, 48);
  ASSERT_EQ(bits, 8);
  ASSERT_EQ(type, 2); /* RGB */
  h_resp_free(r);

  r = render_camera("sg", g_camera, "\"output\": \"depth\"");
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 64);
  ASSERT_EQ(h, 48);
  ASSERT_EQ(bits, 16);
  ASSERT_EQ(type, 0); /* grey */
  h_resp_free(r);

  /* Surface normals: 8-bit RGB too (their values are checked on a longer-trained field in
   * geometry_checks.c). */
  r = render_camera("sg", g_camera, "\"output\": \"normal\"");
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 64);
  ASSERT_EQ(h, 48);
  ASSERT_EQ(bits, 8);
  ASSERT_EQ(type, 2); /* RGB */
  h_resp *again = render_camera("sg", g_camera, "\"output\": \"normal\"");
  ASSERT_EQ(again->len, r->len);
  ASSERT(memcmp(again->body, r->body, r->len) == 0);
  h_resp_free(again);
  h_resp_free(r);

  /* Intrinsics at the top level, as in a transforms.json frame; the OpenCV convention; a
   * camera_angle_x instead of focal lengths. */
  double T[16];
  h_pose(T, 2.4, 0, 0, 0.45, 0.5, 0.6);
  char *m = h_matrix_json(T);
  char *body = h_fmt("{\"camera\": {\"transform_matrix\": %s}, \"convention\": \"opencv\", "
                     "\"camera_angle_x\": 0.9, \"w\": 40, \"h\": 30, \"output\": \"rgb\"}", m);
  r = t_render("sg", body);
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 40);
  ASSERT_EQ(h, 30);
  ASSERT_EQ(bits, 8);
  h_resp_free(r);
  free(body);
  /* The pose as position + quaternion, everything at the top level. */
  body = h_fmt("{\"pose\": {\"position\": [0.45, -0.6, 0.6], \"quaternion\": [0.9239, 0.3827, "
               "0, 0]}, \"fl_x\": 30, \"fl_y\": 30, \"cx\": 8, \"cy\": 6, \"w\": 16, \"h\": 12}");
  r = t_render("sg", body);
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 16);
  ASSERT_EQ(h, 12);
  h_resp_free(r);
  free(body);
  free(m);

  /* The same request gives the same bytes. */
  h_resp *a = reference_render(), *b = reference_render();
  assert_same_bytes(a, b);
  h_resp_free(a);
  h_resp_free(b);
}

static void test_errors(void) {
  const char *good = "[[1,0,0,0.45],[0,1,0,0],[0,0,1,0.9],[0,0,0,1]]";
  char *b;
#define BAD(status, code, ...)                                                                 \
  do {                                                                                         \
    b = h_fmt(__VA_ARGS__);                                                                    \
    expect_error(b, status, code);                                                             \
    free(b);                                                                                   \
  } while (0)
  /* NaN is not JSON: the body does not parse. */
  BAD(400, "malformed_json", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": NaN, \"fl_y\": 50, "
      "\"w\": 64, \"h\": 48}}", good);
  BAD(400, "malformed_json", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 1e999, "
      "\"w\": 64, \"h\": 48}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 0, \"fl_y\": 50, "
      "\"w\": 64, \"h\": 48}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": -5, "
      "\"w\": 64, \"h\": 48}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"h\": 48}}",
      good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"w\": 64, \"h\": 48}}",
      good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, "
      "\"w\": 4097, \"h\": 48}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, "
      "\"w\": 0, \"h\": 48}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, "
      "\"w\": 64.5, \"h\": 48}}", good);
  BAD(400, "invalid_camera", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, "
      "\"w\": 64, \"h\": 48, \"k1\": 0.1}}", good);
  BAD(400, "invalid_camera", "{\"camera\": [1, 2]}");
  BAD(400, "invalid_pose", "{\"camera\": {\"fl_x\": 50, \"w\": 64, \"h\": 48}}");
  BAD(400, "invalid_pose", "{\"camera\": {\"transform_matrix\": [[2,0,0,0],[0,1,0,0],[0,0,1,0],"
      "[0,0,0,1]], \"fl_x\": 50, \"w\": 64, \"h\": 48}}");
  BAD(400, "invalid_pose", "{\"camera\": {\"transform_matrix\": [[1,0,0],[0,1,0]], "
      "\"fl_x\": 50, \"w\": 64, \"h\": 48}}");
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fx\": 50, \"w\": 64, "
      "\"h\": 48}}", good);
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"w\": 64}", good);
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"colour\": \"red\"}", good);
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"output\": \"normals\"}", good);
  /* The message of an unknown output lists the choices. */
  b = h_fmt("{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, \"h\": 48}, "
            "\"output\": \"albedo\"}", good);
  h_resp *out = t_render("sg", b);
  ASSERT_HTTP_ERROR(out, 400, "invalid_request");
  for (int i = 0; i < 4; i++) {
    static const char *const choices[] = {"\"rgb\"", "\"depth\"", "\"normal\"", "\"heatmap\""};
    ASSERT_STRCONTAINS(JSTR(out->json, "error.message"), choices[i]);
  }
  h_resp_free(out);
  free(b);
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"output\": \"normal\", \"embedding\": [1, 0, 0, 0, 0, 0, 0, 2]}", good);
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"convention\": \"directx\"}", good);
  /* heatmap: the query is checked (D = 8 here, no [clip]); test_heatmap renders them */
  BAD(400, "invalid_query", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"output\": \"heatmap\"}", good);
  BAD(400, "invalid_query", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"output\": \"heatmap\", \"embedding\": [1, 0, 0]}", good);
  BAD(409, "clip_not_configured", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, "
      "\"w\": 64, \"h\": 48}, \"output\": \"heatmap\", \"text\": \"a mug\"}", good);
  BAD(400, "invalid_request", "{\"camera\": {\"transform_matrix\": %s, \"fl_x\": 50, \"w\": 64, "
      "\"h\": 48}, \"output\": \"rgb\", \"embedding\": [1, 0, 0, 0, 0, 0, 0, 2]}", good);
  BAD(400, "invalid_request", "[]");
#undef BAD
  /* A valid query renders an 8-bit RGB PNG of the camera's size. */
  int w, h, bits, type;
  h_resp *r = render_camera("sg", g_camera, "\"output\": \"heatmap\", \"embedding\": [1, 0, 0, 0, "
                            "0, 0, 0, 2]");
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 64);
  ASSERT_EQ(h, 48);
  ASSERT_EQ(bits, 8);
  ASSERT_EQ(type, 2);
  h_resp_free(r);
  r = render_camera("nope", g_camera, NULL);
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
}

static char *field_path(void) { return h_fmt("%s/scenes/sg/field.fgc", h_state_dir()); }

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  char *sg = t_dataset(argv[2], 12, 64, 48, 8, 0);
  static const double eye[3] = {0.45, -0.75, 0.55}, target[3] = {0.45, 0, 0.05};
  g_camera = t_camera(eye, target, 60, 64, 48);
  h_start();
  t_scene_from_dataset("sg", sg, 12);

  /* Untrained: 409 saying how to train. */
  h_resp *r = render_camera("sg", g_camera, NULL);
  ASSERT_HTTP_ERROR(r, 409, "not_trained");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "/v1/scenes/sg/train");
  h_resp_free(r);

  t_train_done("sg", "{\"steps\": 8, \"holdout_every\": 4}", 600);
  test_formats();
  test_errors();

  /* While a new training runs, renders use the field they had; a cancelled training leaves
   * it as it was. */
  h_resp *before = reference_render();
  char *id = t_train("sg", "{\"steps\": 1000000}");
  t_wait_running(id, 1, 600);
  r = reference_render();
  assert_same_bytes(r, before);
  h_resp_free(r);
  char *path = h_fmt("/v1/jobs/%s", id);
  r = h_delete(path);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  char *needle = h_fmt("job %s: stopped (cancelled)", id);
  ASSERT(h_wait_log(needle, 1, 600));
  r = reference_render();
  assert_same_bytes(r, before);
  h_resp_free(r);
  free(needle);
  free(path);
  free(id);

  /* A restart loads the same field: the same bytes. */
  h_stop();
  h_start();
  r = reference_render();
  assert_same_bytes(r, before);
  h_resp_free(r);

  /* The daemon never loaded OpenImageIO: PNGs are encoded in fieldgrip-decode. */
  char *maps_path = h_fmt("/proc/%d/maps", (int)h_pid());
  char *maps = h_read_file(maps_path, NULL);
  ASSERT(maps != NULL);
  if (strstr(maps, "OpenImageIO")) FG_TEST_FAIL("fieldgripd has OpenImageIO mapped");
  free(maps);
  free(maps_path);

  /* A truncated checkpoint: the daemon starts, the scene is untrained and says why. */
  h_stop();
  char *fp = field_path();
  struct stat st;
  ASSERT_EQ(stat(fp, &st), 0);
  ASSERT_EQ(truncate(fp, st.st_size / 2), 0);
  h_start();
  r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_get("/v1/scenes/sg");
  ASSERT_STATUS(r, 200);
  ASSERT(json_is_false(JGET(r->json, "trained")));
  ASSERT(json_is_string(JGET(r->json, "checkpoint_error")));
  ASSERT_STRCONTAINS(JSTR(r->json, "checkpoint_error"), "field.fgc");
  ASSERT_EQ(JINT(r->json, "trained_steps"), 0);
  h_resp_free(r);
  r = render_camera("sg", g_camera, NULL);
  ASSERT_HTTP_ERROR(r, 409, "not_trained");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "does not load");
  h_resp_free(r);
  ASSERT(h_log_count("the trained field does not load") >= 1);
  /* The file is left for inspection; training again replaces it. */
  ASSERT_EQ(stat(fp, &st), 0);
  t_train_done("sg", "{\"steps\": 2}", 600);
  r = h_get("/v1/scenes/sg");
  ASSERT(json_is_true(JGET(r->json, "trained")));
  ASSERT(json_is_null(JGET(r->json, "checkpoint_error")));
  h_resp_free(r);
  r = reference_render();
  h_resp_free(r);

  h_resp_free(before);
  h_stop();
  free(fp);
  free(g_camera);
  free(sg);
  h_done();
  return 0;
}
