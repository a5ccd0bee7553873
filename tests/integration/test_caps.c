/* The memory and scene caps of [state]: with max_scenes = 3 one scene more answers 507
 * scene_limit naming the key, the others stay listed and usable, and a delete makes room;
 * a scene declared in the configuration past the cap is logged, not created. With
 * max_loaded_fields = 1, two trained scenes rendered A, B, A, B answer the same bytes as
 * before any eviction while /metrics never shows more than one loaded field and counts the
 * evictions and loads, and GET /v1/scenes/{s} tells which field is loaded. (A field pinned
 * by a request, and 503 memory_limit, are checked in tests/unit/test_store_fields.c: a
 * black-box test cannot hold a request still.)
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include "training.h"

static char *g_camera;
static char *g_imports;

static void write_config(const char *extra) {
  char *conf = h_fmt("[state]\nimport_dirs = %s\nmax_scenes = 3\nmax_loaded_fields = 1\n\n"
                     "[train]\nthreads = 2\nsteps = 20\n%s", g_imports, extra);
  h_write_config(conf);
  free(conf);
}

static h_resp *render(const char *scene) {
  char *body = h_fmt("{\"camera\": %s}", g_camera);
  h_resp *r = t_render(scene, body);
  free(body);
  int w, h, bits, type;
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 32);
  return r;
}

static void assert_same_bytes(const h_resp *a, const h_resp *b) {
  ASSERT_EQ(a->len, b->len);
  ASSERT(memcmp(a->body, b->body, a->len) == 0);
}

static int scene_loaded(const char *name) {
  json_t *s = t_scene_json(name);
  ASSERT(json_is_true(JGET(s, "trained")));
  int loaded = json_is_true(JGET(s, "loaded"));
  json_decref(s);
  return loaded;
}

static size_t scene_count(void) {
  h_resp *r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  size_t n = json_array_size(JGET(r->json, "scenes"));
  h_resp_free(r);
  return n;
}

static void test_scene_limit(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"c\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"d\"}");
  ASSERT_HTTP_ERROR(r, 507, "scene_limit");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "[state] max_scenes = 3");
  h_resp_free(r);
  ASSERT_EQ(scene_count(), 3);
  r = h_get("/v1/scenes/d");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  /* the others are untouched and usable */
  r = h_get("/v1/scenes/a/frames");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "frames")), 4);
  h_resp_free(r);

  /* declared in the configuration past the cap: logged, not created, the rest applied */
  write_config("\n[scene e]\n");
  h_reload();
  ASSERT_EQ(h_log_count("scene e from the configuration file: scene 'e' was not created: "
                        "the daemon holds 3 scenes, its limit ([state] max_scenes = 3)"), 1);
  ASSERT_EQ(scene_count(), 3);
  write_config("");
  h_reload();

  /* a delete makes room */
  r = h_delete("/v1/scenes/c");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"d\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  r = h_delete("/v1/scenes/d");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
}

static void test_field_lru(void) {
  /* a's field as trained, before anything was evicted */
  t_train_done("a", "{\"steps\": 8, \"holdout_every\": 4}", 600);
  ASSERT(scene_loaded("a"));
  h_resp *a0 = render("a");
  ASSERT_EQ(h_metric("fieldgrip_field_evictions_total"), 0);

  /* b's training commits: a, in nobody's use, leaves memory */
  t_train_done("b", "{\"steps\": 12, \"holdout_every\": 4}", 600);
  ASSERT_EQ(h_metric("fieldgrip_fields_loaded"), 1);
  ASSERT_EQ(h_metric("fieldgrip_fields_loaded_max"), 1);
  ASSERT_EQ(h_metric("fieldgrip_field_evictions_total"), 1);
  ASSERT(!scene_loaded("a"));
  ASSERT(scene_loaded("b"));
  h_resp *b0 = render("b");
  ASSERT(a0->len != b0->len || memcmp(a0->body, b0->body, a0->len) != 0);

  /* A, B, A, B: each loaded again from its checkpoint, the same pixels each time */
  for (int round = 0; round < 2; round++) {
    h_resp *a = render("a");
    assert_same_bytes(a, a0);
    h_resp_free(a);
    ASSERT(scene_loaded("a"));
    ASSERT(!scene_loaded("b"));
    ASSERT_EQ(h_metric("fieldgrip_fields_loaded"), 1);
    h_resp *b = render("b");
    assert_same_bytes(b, b0);
    h_resp_free(b);
    ASSERT(!scene_loaded("a"));
    ASSERT_EQ(h_metric("fieldgrip_fields_loaded"), 1);
  }
  ASSERT_EQ(h_metric("fieldgrip_field_loads_total"), 4);
  ASSERT_EQ(h_metric("fieldgrip_field_evictions_total"), 5);
  ASSERT_EQ(h_metric("fieldgrip_trained_scenes"), 2);

  /* a restart keeps one field in memory and serves the other from its checkpoint */
  h_stop();
  h_start();
  ASSERT_EQ(h_metric("fieldgrip_fields_loaded"), 1);
  h_resp *a = render("a");
  assert_same_bytes(a, a0);
  h_resp_free(a);
  h_resp *b = render("b");
  assert_same_bytes(b, b0);
  h_resp_free(b);
  ASSERT_EQ(h_metric("fieldgrip_fields_loaded"), 1);
  h_resp_free(a0);
  h_resp_free(b0);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  /* tiny: two trainings of a few steps on 4 views of 32x24 */
  char *sg = t_dataset(argv[2], 4, 32, 24, 8, 0);
  g_imports = h_fmt("%s/imports", h_tmpdir());
  write_config("");
  static const double eye[3] = {0.45, -0.75, 0.55}, target[3] = {0.45, 0, 0.05};
  g_camera = t_camera(eye, target, 30, 32, 24);
  h_start();
  t_scene_from_dataset("a", sg, 4);
  t_scene_from_dataset("b", sg, 4);
  test_scene_limit();
  test_field_lru();
  free(g_camera);
  free(g_imports);
  free(sg);
  h_done();
  return 0;
}
