/* Scenes API: health, create/list/get/delete, defaults, validation of names and bodies,
 * duplicate 409, unknown 404, 405 with Allow, unknown paths, malformed JSON, and the flags
 * --version / --help. */
#include <strings.h>

#include "config.h"
#include "harness.h"

static const char *err_message(h_resp *r) { return JSTR(r->json, "error.message"); }

/* Splits an Allow header into a sorted, canonical "A,B,C" string for comparison. */
static void canonical_allow(const char *allow, char *out, size_t n) {
  char items[8][16];
  int k = 0;
  const char *p = allow;
  while (*p && k < 8) {
    while (*p == ' ' || *p == ',') p++;
    size_t len = strcspn(p, ", ");
    if (len == 0) break;
    snprintf(items[k++], sizeof items[0], "%.*s", (int)len, p);
    p += len;
  }
  for (int i = 1; i < k; i++)
    for (int j = i; j > 0 && strcmp(items[j - 1], items[j]) > 0; j--) {
      char t[16];
      memcpy(t, items[j], sizeof t);
      memcpy(items[j], items[j - 1], sizeof t);
      memcpy(items[j - 1], t, sizeof t);
    }
  out[0] = '\0';
  for (int i = 0; i < k; i++) {
    if (i) strncat(out, ",", n - strlen(out) - 1);
    strncat(out, items[i], n - strlen(out) - 1);
  }
}

static void expect_405(const char *method, const char *path, const char *allow_sorted) {
  h_req q = {.method = method, .path = path};
  h_resp *r = h_request(&q);
  ASSERT_HTTP_ERROR(r, 405, "method_not_allowed");
  const char *allow = h_resp_header(r, "Allow");
  if (!allow) FG_TEST_FAIL("%s %s: 405 without an Allow header", method, path);
  char got[128];
  canonical_allow(allow, got, sizeof got);
  if (strcmp(got, allow_sorted) != 0)
    FG_TEST_FAIL("%s %s: Allow \"%s\", expected the methods %s", method, path, allow, allow_sorted);
  h_resp_free(r);
}

static void expect_create_error(const char *body, long status, const char *code) {
  h_resp *r = h_post_json("/v1/scenes", body);
  if (r->status != status) fprintf(stderr, "request body: %s\n", body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
}

static void check_default_scene(json_t *s, const char *name) {
  static const double dmin[3] = {0.10, -0.45, 0.005}, dmax[3] = {0.80, 0.45, 0.35};
  static const double white[3] = {1, 1, 1};
  ASSERT_STREQ(JSTR(s, "name"), name);
  ASSERT_VEC(JGET(s, "workspace.min"), dmin, 3, 1e-12);
  ASSERT_VEC(JGET(s, "workspace.max"), dmax, 3, 1e-12);
  ASSERT_NEAR(JNUM(s, "voxel_size"), 0.01, 1e-12);
  ASSERT_VEC(JGET(s, "background"), white, 3, 0);
  ASSERT_EQ(JINT(s, "frames"), 0);
  ASSERT(json_is_null(JGET(s, "feature_dim")));
  ASSERT(json_is_false(JGET(s, "trained")));
  ASSERT(json_is_null(JGET(s, "last_job")));
  ASSERT(json_is_false(JGET(s, "declared_in_config")));
  const char *created = JSTR(s, "created");
  /* ISO 8601 UTC: 2026-11-22T00:00:00Z */
  ASSERT(strlen(created) >= 20);
  ASSERT_EQ(created[4], '-');
  ASSERT_EQ(created[10], 'T');
  ASSERT_EQ(created[strlen(created) - 1], 'Z');
}

static void test_flags(void) {
  char *out = NULL;
  const char *v[] = {"--version", NULL};
  ASSERT_EQ(h_run_daemon_capture(v, &out), 0);
  ASSERT_STRCONTAINS(out, FG_VERSION);
  free(out);
  const char *help[] = {"--help", NULL};
  ASSERT_EQ(h_run_daemon_capture(help, &out), 0);
  ASSERT_STRCONTAINS(out, "--config");
  ASSERT_STRCONTAINS(out, "--state-dir");
  ASSERT_STRCONTAINS(out, "--listen");
  ASSERT_STRCONTAINS(out, "--log-level");
  free(out);
  const char *bad[] = {"--no-such-flag", NULL};
  ASSERT_NE(h_run_daemon_capture(bad, &out), 0);
  free(out);
}

static void test_health(void) {
  h_resp *r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(JSTR(r->json, "status"), "ok");
  ASSERT_STREQ(JSTR(r->json, "version"), FG_VERSION);
  const char *ct = h_resp_header(r, "Content-Type");
  ASSERT(ct && strncasecmp(ct, "application/json", 16) == 0);
  h_resp_free(r);
}

static void test_create_list_get_delete(void) {
  h_resp *r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  ASSERT(json_is_array(JGET(r->json, "scenes")));
  ASSERT_EQ(json_array_size(JGET(r->json, "scenes")), 0);
  h_resp_free(r);

  /* Every field given. */
  r = h_post_json("/v1/scenes",
                  "{\"name\": \"tabletop\", \"workspace\": {\"min\": [0.1, -0.45, 0.005], "
                  "\"max\": [0.8, 0.45, 0.35]}, \"voxel_size\": 0.005, \"background\": [0, 0.5, 1]}");
  ASSERT_STATUS(r, 201);
  json_t *created = json_incref(RJSON(r));
  static const double mn[3] = {0.1, -0.45, 0.005}, mx[3] = {0.8, 0.45, 0.35}, bg[3] = {0, 0.5, 1};
  ASSERT_STREQ(JSTR(created, "name"), "tabletop");
  ASSERT_VEC(JGET(created, "workspace.min"), mn, 3, 1e-12);
  ASSERT_VEC(JGET(created, "workspace.max"), mx, 3, 1e-12);
  ASSERT_NEAR(JNUM(created, "voxel_size"), 0.005, 1e-12);
  ASSERT_VEC(JGET(created, "background"), bg, 3, 1e-12);
  ASSERT_EQ(JINT(created, "frames"), 0);
  ASSERT(json_is_null(JGET(created, "feature_dim")));
  ASSERT(json_is_false(JGET(created, "trained")));
  ASSERT(json_is_null(JGET(created, "last_job")));
  ASSERT(json_is_false(JGET(created, "declared_in_config")));
  h_resp_free(r);

  /* Only a name: the documented defaults. */
  r = h_post_json("/v1/scenes", "{\"name\": \"bench-2.a_B\"}");
  ASSERT_STATUS(r, 201);
  check_default_scene(RJSON(r), "bench-2.a_B");
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"alpha\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);

  /* GET returns what POST returned. */
  r = h_get("/v1/scenes/tabletop");
  ASSERT_STATUS(r, 200);
  ASSERT_JSON_EQUAL(RJSON(r), created);
  h_resp_free(r);
  r = h_get("/v1/scenes/bench-2.a_B");
  ASSERT_STATUS(r, 200);
  check_default_scene(RJSON(r), "bench-2.a_B");
  h_resp_free(r);

  /* The list is sorted by name. */
  r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  json_t *scenes = JGET(r->json, "scenes");
  ASSERT_EQ(json_array_size(scenes), 3);
  ASSERT_STREQ(JSTR(scenes, "0.name"), "alpha");
  ASSERT_STREQ(JSTR(scenes, "1.name"), "bench-2.a_B");
  ASSERT_STREQ(JSTR(scenes, "2.name"), "tabletop");
  ASSERT_JSON_EQUAL(JGET(scenes, "2"), created);
  h_resp_free(r);

  /* Duplicate. */
  r = h_post_json("/v1/scenes", "{\"name\": \"tabletop\"}");
  ASSERT_HTTP_ERROR(r, 409, "scene_exists");
  h_resp_free(r);
  r = h_get("/v1/scenes/tabletop");
  ASSERT_JSON_EQUAL(RJSON(r), created); /* the duplicate changed nothing */
  h_resp_free(r);

  /* Delete. */
  r = h_delete("/v1/scenes/alpha");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(JSTR(r->json, "deleted"), "alpha");
  h_resp_free(r);
  r = h_get("/v1/scenes/alpha");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_delete("/v1/scenes/alpha");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_get("/v1/scenes");
  ASSERT_EQ(json_array_size(JGET(r->json, "scenes")), 2);
  ASSERT_STREQ(JSTR(r->json, "scenes.0.name"), "bench-2.a_B");
  h_resp_free(r);
  /* A deleted name can be created again, empty. */
  r = h_post_json("/v1/scenes", "{\"name\": \"alpha\", \"voxel_size\": 0.02}");
  ASSERT_STATUS(r, 201);
  ASSERT_NEAR(JNUM(r->json, "voxel_size"), 0.02, 1e-12);
  h_resp_free(r);
  json_decref(created);
}

static void test_unknown(void) {
  h_resp *r = h_get("/v1/scenes/nope");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_get("/v1/scenes/nope/frames");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_delete("/v1/scenes/nope");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_post_json("/v1/scenes/nope/import", "{\"path\": \"/tmp\"}");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);

  static const char *const unknown[] = {"/nope", "/v1", "/v1/", "/v1/nope", "/v2/scenes",
                                        "/v1/scenes/tabletop/nope", "/v1/healthz",
                                        "/v1/scenes/tabletop/frames/0/x"};
  for (size_t i = 0; i < sizeof unknown / sizeof unknown[0]; i++) {
    r = h_get(unknown[i]);
    if (r->status != 404) fprintf(stderr, "GET %s\n", unknown[i]);
    ASSERT_HTTP_ERROR(r, 404, "not_found");
    h_resp_free(r);
  }
}

static void test_methods(void) {
  expect_405("PUT", "/v1/scenes", "GET,POST");
  expect_405("DELETE", "/v1/scenes", "GET,POST");
  expect_405("POST", "/v1/health", "GET");
  expect_405("DELETE", "/v1/health", "GET");
  expect_405("POST", "/v1/scenes/tabletop", "DELETE,GET,PATCH");
  expect_405("PUT", "/v1/scenes/tabletop", "DELETE,GET,PATCH");
  expect_405("PUT", "/v1/scenes/tabletop/frames", "GET,POST");
  expect_405("GET", "/v1/scenes/tabletop/import", "POST");
  expect_405("POST", "/metrics", "GET");
}

static void test_bad_bodies(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"x\",");
  ASSERT_HTTP_ERROR(r, 400, "malformed_json");
  /* The message helps the client find the spot: it carries a line/column. */
  const char *m = err_message(r);
  if (!strcasestr(m, "line") && !strcasestr(m, "column"))
    FG_TEST_FAIL("malformed_json message lacks the line/column: \"%s\"", m);
  h_resp_free(r);
  expect_create_error("", 400, "malformed_json");
  expect_create_error("{name: 'x'}", 400, "malformed_json");
  expect_create_error("{\"name\": \"x\"} trailing", 400, "malformed_json");
  expect_create_error("{\"name\": \"x\", \"voxel_size\": NaN}", 400, "malformed_json");

  /* Valid JSON of the wrong shape. */
  expect_create_error("[1, 2]", 400, "invalid_request");
  expect_create_error("\"tabletop2\"", 400, "invalid_request");
  expect_create_error("{}", 400, "invalid_request");
  expect_create_error("{\"name\": 5}", 400, "invalid_request");
  expect_create_error("{\"name\": null}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"workspace\": \"big\"}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"workspace\": {\"min\": [0, 0], \"max\": [1, 1, 1]}}", 400,
                      "invalid_request");
  expect_create_error("{\"name\": \"w\", \"workspace\": {\"min\": [0, \"a\", 0], \"max\": [1, 1, 1]}}",
                      400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"workspace\": {\"min\": [0, 0, 0]}}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"voxel_size\": \"0.01\"}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"voxel_size\": 0}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"voxel_size\": -0.01}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"background\": [1, 1]}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"background\": [2, 0, 0]}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"background\": [0, -0.1, 0]}", 400, "invalid_request");
  expect_create_error("{\"name\": \"w\", \"background\": \"white\"}", 400, "invalid_request");

  /* Workspace with min >= max on an axis (equal, then greater). */
  expect_create_error("{\"name\": \"w\", \"workspace\": {\"min\": [0, 0, 0], \"max\": [1, 0, 1]}}", 400,
                      "invalid_request");
  expect_create_error("{\"name\": \"w\", \"workspace\": {\"min\": [0, 0, 2], \"max\": [1, 1, 1]}}", 400,
                      "invalid_request");

  /* Names: 1..64 of [A-Za-z0-9_.-], not starting with '.'. */
  static const char *const bad_names[] = {
      "\"\"", "\".hidden\"", "\"..\"", "\"a/b\"", "\"a b\"", "\"a%2Fb\"", "\"caf\\u00e9\"",
      "\"tab\\tle\"",
      "\"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\"" /* 65 */};
  for (size_t i = 0; i < sizeof bad_names / sizeof bad_names[0]; i++) {
    char *body = h_fmt("{\"name\": %s}", bad_names[i]);
    expect_create_error(body, 400, "invalid_request");
    free(body);
  }
  /* 64 characters is still fine. */
  h_resp *ok = h_post_json("/v1/scenes",
                           "{\"name\": \"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\"}");
  ASSERT_STATUS(ok, 201);
  h_resp_free(ok);
  ok = h_delete("/v1/scenes/aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa");
  ASSERT_STATUS(ok, 200);
  h_resp_free(ok);

  /* None of the refused requests created anything. */
  r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  json_t *scenes = JGET(r->json, "scenes");
  ASSERT_EQ(json_array_size(scenes), 3);
  ASSERT_STREQ(JSTR(scenes, "0.name"), "alpha");
  ASSERT_STREQ(JSTR(scenes, "1.name"), "bench-2.a_B");
  ASSERT_STREQ(JSTR(scenes, "2.name"), "tabletop");
  h_resp_free(r);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  test_flags();
  h_start();
  test_health();
  test_create_list_get_delete();
  test_unknown();
  test_methods();
  test_bad_bodies();
  /* Still healthy after all that. */
  test_health();
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
