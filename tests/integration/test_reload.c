/* Configuration: start-up errors name file, line and key; SIGHUP with a bad file keeps the old
 * settings (and logs "reload failed"); SIGHUP with a good file brings a new token, a new
 * upload limit and new declared scenes, re-creates a deleted declared scene, and leaves the
 * listening socket alone (listen changes need a restart); SIGHUPs in a burst, and SIGTERM,
 * arriving during a reload neither end the daemon nor get lost. */
#include <signal.h>

#include "harness.h"

static long status_with(const char *token, const char *path) {
  h_req q = {.method = "GET", .path = path, .auth = token ? H_AUTH_TOKEN : H_AUTH_NONE, .token = token};
  h_resp *r = h_request(&q);
  long st = r->status;
  if (st == 401) ASSERT_HTTP_ERROR(r, 401, "unauthorized");
  h_resp_free(r);
  return st;
}

static void expect_startup_error(const char *conf_text, const char *key, int line) {
  char *path = h_fmt("%s/bad.conf", h_tmpdir());
  h_write_file(path, conf_text, strlen(conf_text));
  char *state = h_fmt("%s/state-bad", h_tmpdir());
  const char *args[] = {"--config", path, "--state-dir", state, "--listen", "127.0.0.1:0", NULL};
  char *out = NULL;
  int rc = h_run_daemon_capture(args, &out);
  if (rc == 0 || rc >= 128) FG_TEST_FAIL("bad config: exit %d, expected a failure exit; output: %s", rc, out);
  char *where = h_fmt("%s:%d", path, line);
  ASSERT_STRCONTAINS(out, where);
  ASSERT_STRCONTAINS(out, key);
  ASSERT_EQ(strstr(out, "listening on") == NULL, 1);
  free(where);
  free(out);
  free(state);
  free(path);
}

static long long metric_value(const char *text, const char *series) {
  const char *p = strstr(text, series);
  while (p && p != text && p[-1] != '\n') p = strstr(p + 1, series);
  if (!p) FG_TEST_FAIL("no series %s in /metrics:\n%s", series, text);
  return strtoll(p + strlen(series), NULL, 10);
}

/* Asserts that /metrics counts n successful reloads. */
static void expect_reloads_ok(long long n) {
  h_resp *r = h_get("/metrics");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(metric_value(r->body, "fieldgrip_config_reloads_total{result=\"ok\"} "), n);
  h_resp_free(r);
}

static int upload_one(const char *scene) {
  uint8_t *png;
  size_t len;
  h_png(16, 16, 3, 8, 1, 0, &png, &len);
  char *path = h_fmt("/v1/scenes/%s/frames", scene);
  h_resp *r = h_upload(path, png, len,
                       "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0.3],[0,0,0,1]], "
                       "\"fl_x\": 20, \"fl_y\": 20, \"cx\": 8, \"cy\": 8}",
                       NULL, 0);
  ASSERT_STATUS(r, 201);
  int n = (int)JINT(r->json, "frame");
  h_resp_free(r);
  free(path);
  free(png);
  return n;
}

int main(int argc, char **argv) {
  h_init(argc, argv);

  /* Start-up errors name the file, the line and the key. */
  expect_startup_error("[http]\nlisten = 127.0.0.1:0\nbogus_key = 1\n", "bogus_key", 3);
  expect_startup_error("[http]\nmax_upload_mb = lots\n", "max_upload_mb", 2);
  expect_startup_error("[scene s]\nworkspace_min = 0 0\n", "workspace_min", 2);

  h_write_config("[http]\ntoken = tokenA\n");
  h_start();
  h_set_token("tokenA");
  ASSERT_EQ(status_with("tokenA", "/v1/scenes"), 200);
  ASSERT_EQ(status_with("tokenB", "/v1/scenes"), 401);

  /* A bad file: logged, old settings stay. */
  h_write_config("[http]\ntoken = tokenB\nno_such_key = 1\n");
  h_reload();
  ASSERT_EQ(h_log_count("reload failed"), 1);
  ASSERT(h_alive());
  char *log = h_log();
  /* The message names the file and line ("reload failed ... FILE:3: ..."). */
  char *where = h_fmt("%s:3:", h_config_path());
  const char *failed = strstr(log, "reload failed");
  ASSERT(failed != NULL);
  ASSERT_STRCONTAINS(failed, where);
  ASSERT_STRCONTAINS(failed, "no_such_key");
  free(where);
  free(log);
  h_resp *r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  ASSERT_EQ(status_with("tokenA", "/v1/scenes"), 200);
  ASSERT_EQ(status_with("tokenB", "/v1/scenes"), 401);
  ASSERT_EQ(status_with(NULL, "/v1/scenes"), 401);
  r = h_get("/v1/scenes");
  ASSERT_EQ(json_array_size(JGET(r->json, "scenes")), 0);
  h_resp_free(r);

  /* A good file: new token, new limit, a declared scene. */
  h_write_config("[http]\ntoken = tokenB\nmax_upload_mb = 1\n\n"
                 "[scene shelf]\nworkspace_min = -0.2 -0.3 0.0\nworkspace_max = 0.2 0.3 0.5\n"
                 "voxel_size = 0.005\n");
  /* Wait for the end of the reload, not for the new token: the declared scene is made and
   * the reload counted after the token changes. /metrics wants the token in force, which is
   * tokenB once the reload has installed it (h_reload asks with the old one). */
  h_set_token("tokenB");
  h_signal(SIGHUP);
  const double deadline = h_now_s() + 60;
  for (;;) {
    h_resp *m = h_get("/metrics");
    const int done = m->status == 200 &&
                     metric_value(m->body, "fieldgrip_config_reloads_total{result=\"ok\"} ") == 1;
    h_resp_free(m);
    if (done) break;
    if (h_now_s() > deadline) FG_TEST_FAIL("the good configuration was not reloaded in 60 s");
    h_sleep_ms(20);
  }
  ASSERT(h_alive());
  ASSERT_EQ(status_with("tokenB", "/v1/scenes"), 200);
  ASSERT_EQ(status_with("tokenA", "/v1/scenes"), 401);
  ASSERT_EQ(status_with(NULL, "/v1/scenes"), 401);
  ASSERT_EQ(status_with(NULL, "/v1/health"), 200);

  r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "scenes")), 1);
  json_t *shelf = JGET(r->json, "scenes.0");
  ASSERT_STREQ(JSTR(shelf, "name"), "shelf");
  ASSERT(json_is_true(JGET(shelf, "declared_in_config")));
  static const double mn[3] = {-0.2, -0.3, 0.0}, mx[3] = {0.2, 0.3, 0.5};
  ASSERT_VEC(JGET(shelf, "workspace.min"), mn, 3, 1e-12);
  ASSERT_VEC(JGET(shelf, "workspace.max"), mx, 3, 1e-12);
  ASSERT_NEAR(JNUM(shelf, "voxel_size"), 0.005, 1e-12);
  ASSERT_EQ(JINT(shelf, "frames"), 0);
  h_resp_free(r);

  /* The new upload limit holds. */
  {
    size_t n = 2 * 1024 * 1024;
    char *json = malloc(n + 64);
    ASSERT(json);
    int k = snprintf(json, 64, "{\"name\": \"big\", \"pad\": \"");
    memset(json + k, 'a', n);
    strcpy(json + k + n, "\"}");
    r = h_post_json("/v1/scenes", json);
    ASSERT_HTTP_ERROR(r, 413, "payload_too_large");
    h_resp_free(r);
    free(json);
  }

  /* Both reloads were counted. */
  r = h_get("/metrics");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(metric_value(r->body, "fieldgrip_config_reloads_total{result=\"failed\"} "), 1);
  ASSERT_EQ(metric_value(r->body, "fieldgrip_config_reloads_total{result=\"ok\"} "), 1);
  h_resp_free(r);

  /* A declared scene deleted through the API comes back, empty, at the next reload. */
  ASSERT_EQ(upload_one("shelf"), 0);
  r = h_delete("/v1/scenes/shelf");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_get("/v1/scenes/shelf");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  h_reload();
  expect_reloads_ok(2);
  r = h_get("/v1/scenes/shelf");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "frames"), 0);
  ASSERT(json_is_true(JGET(r->json, "declared_in_config")));
  h_resp_free(r);

  /* listen needs a restart: a reload that changes it keeps serving where it was. */
  int port = h_port();
  h_write_config("[http]\nlisten = 127.0.0.1:1\ntoken = tokenB\nmax_upload_mb = 1\n\n"
                 "[scene shelf]\nworkspace_min = -0.2 -0.3 0.0\nworkspace_max = 0.2 0.3 0.5\n"
                 "voxel_size = 0.005\n");
  h_reload();
  expect_reloads_ok(3);
  ASSERT(h_alive());
  ASSERT_EQ(h_port(), port);
  r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  ASSERT_EQ(status_with("tokenB", "/v1/scenes"), 200);

  /* SIGHUPs without pause until three more reloads have run, so that many arrive while one
   * runs: they are taken in turn (one that meets another still pending merges with it, as
   * signals do) and none ends the daemon. SIGTERM sent during a reload still stops it
   * cleanly (h_stop wants exit 0). */
  const double reloads_before = h_metric("fieldgrip_config_reloads_total{result=\"ok\"}");
  const double burst_deadline = h_now_s() + 30;
  while (h_metric("fieldgrip_config_reloads_total{result=\"ok\"}") < reloads_before + 3) {
    ASSERT(h_now_s() < burst_deadline);
    for (int i = 0; i < 100; i++) h_signal(SIGHUP);
    ASSERT(h_alive());
  }
  h_reload();
  ASSERT(h_alive());
  r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  h_signal(SIGHUP);

  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
