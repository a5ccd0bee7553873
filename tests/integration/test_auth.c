/* Bearer token: with [http] token set, every request but GET /v1/health needs
 * "Authorization: Bearer <token>"; anything else is 401 "unauthorized" with WWW-Authenticate.
 * [http] token_file: the token read from a file of the daemon's own, at start and at each
 * reload, and a file others may read refused at start-up. */
#include "harness.h"

#include <signal.h>
#include <sys/stat.h>

#define TOKEN "s3cret-Token_1"

static h_resp *req_auth(const char *method, const char *path, const char *header_line,
                        const char *body) {
  const char *hdrs[2] = {header_line, NULL};
  h_req q = {.method = method, .path = path, .auth = H_AUTH_NONE, .headers = header_line ? hdrs : NULL,
             .body = body, .body_len = body ? strlen(body) : 0};
  return h_request(&q);
}

static void expect_401(const char *method, const char *path, const char *header_line,
                       const char *body) {
  h_resp *r = req_auth(method, path, header_line, body);
  if (r->status != 401)
    fprintf(stderr, "%s %s with %s\n", method, path, header_line ? header_line : "no token");
  ASSERT_HTTP_ERROR(r, 401, "unauthorized");
  const char *www = h_resp_header(r, "WWW-Authenticate");
  ASSERT_STREQ(www, "Bearer realm=\"fieldgrip\"");
  h_resp_free(r);
}

/* Writes a token file under the temp dir with the given mode; returns its malloc'd path. */
static char *token_file(const char *text, mode_t mode) {
  char *path = h_fmt("%s/token", h_tmpdir());
  unlink(path);
  h_write_file(path, text, strlen(text));
  ASSERT_EQ(chmod(path, mode), 0);
  return path;
}

/* Status of GET /v1/scenes with the given token. */
static int scenes_status(const char *token) {
  char *hdr = h_fmt("Authorization: Bearer %s", token);
  h_resp *r = req_auth("GET", "/v1/scenes", hdr, NULL);
  int status = r->status;
  h_resp_free(r);
  free(hdr);
  return status;
}

/* Runs the daemon on the current config file and expects it to refuse to start with a
 * message holding want. */
static void expect_start_refused(const char *want) {
  char *state = h_fmt("%s/state-refused", h_tmpdir());
  const char *args[] = {"--config", h_config_path(), "--state-dir", state, "--listen",
                        "127.0.0.1:0", NULL};
  char *out = NULL;
  int rc = h_run_daemon_capture(args, &out);
  if (rc == 0 || rc >= 128) FG_TEST_FAIL("exit %d, expected a failure exit; output: %s", rc, out);
  ASSERT_STRCONTAINS(out, want);
  ASSERT_STRCONTAINS(out, "token_file");
  ASSERT(strstr(out, "listening on") == NULL);
  free(out);
  free(state);
}

static void check_token_file(void) {
  char *path = token_file("from-a-file\n", 0600);
  h_write_config("[http]\ntoken_file = token\n"); /* relative to the config's folder */
  h_start();
  ASSERT_EQ(scenes_status("from-a-file"), 200);
  ASSERT_EQ(scenes_status("from-a-fil"), 401);
  expect_401("GET", "/v1/scenes", NULL, NULL);

  /* a reload reads the file again: the new token works at once, the old one no more */
  free(token_file("rotated-token\n", 0400));
  h_signal(SIGHUP);
  for (int i = 0; scenes_status("rotated-token") != 200; i++) {
    if (i >= 500) FG_TEST_FAIL("the rotated token is not taken after SIGHUP");
    h_sleep_ms(20);
  }
  ASSERT_EQ(scenes_status("from-a-file"), 401);
  /* a reload that finds the file readable by others keeps the running token */
  free(token_file("leaked\n", 0644));
  h_signal(SIGHUP);
  if (!h_wait_log("reload failed", 1, 10.0)) FG_TEST_FAIL("no \"reload failed\" after SIGHUP");
  ASSERT_EQ(scenes_status("rotated-token"), 200);
  ASSERT_EQ(scenes_status("leaked"), 401);
  h_stop();

  /* at start-up: readable by others, empty, missing, both keys */
  expect_start_refused("chmod 600");
  free(token_file("\n", 0600));
  expect_start_refused("is empty");
  unlink(path);
  expect_start_refused("cannot open");
  free(token_file("x\n", 0600));
  h_write_config("[http]\ntoken = abc\ntoken_file = token\n");
  expect_start_refused("keep one");
  free(path);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  check_token_file();
  h_write_config("[http]\ntoken = " TOKEN "\n");
  h_start();

  /* Health needs no token, whatever is sent. */
  h_resp *r = req_auth("GET", "/v1/health", NULL, NULL);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(JSTR(r->json, "status"), "ok");
  h_resp_free(r);
  r = req_auth("GET", "/v1/health", "Authorization: Bearer wrong", NULL);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);

  /* No token, wrong tokens, wrong scheme. */
  expect_401("GET", "/v1/scenes", NULL, NULL);
  expect_401("GET", "/v1/scenes", "Authorization: Bearer wrong", NULL);
  expect_401("GET", "/v1/scenes", "Authorization: Bearer s3cret", NULL);           /* prefix */
  expect_401("GET", "/v1/scenes", "Authorization: Bearer " TOKEN "x", NULL);       /* longer */
  expect_401("GET", "/v1/scenes", "Authorization: Bearer ", NULL);                 /* empty */
  expect_401("GET", "/v1/scenes", "Authorization: Basic czNjcmV0LVRva2VuXzE=", NULL);
  expect_401("GET", "/v1/scenes", "Authorization: " TOKEN, NULL);
  expect_401("GET", "/v1/scenes", "X-Token: " TOKEN, NULL);

  /* The right token. */
  r = req_auth("GET", "/v1/scenes", "Authorization: Bearer " TOKEN, NULL);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "scenes")), 0);
  h_resp_free(r);

  /* Writes without the token change nothing. */
  expect_401("POST", "/v1/scenes", NULL, "{\"name\": \"a\"}");
  expect_401("POST", "/v1/scenes", "Authorization: Bearer nope", "{\"name\": \"a\"}");
  h_set_token(TOKEN);
  r = h_get("/v1/scenes/a");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"a\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  expect_401("DELETE", "/v1/scenes/a", NULL, NULL);
  expect_401("GET", "/v1/scenes/a", NULL, NULL);
  expect_401("GET", "/v1/scenes/a/frames", NULL, NULL);
  expect_401("POST", "/v1/scenes/a/import", NULL, "{\"path\": \"/tmp\"}");
  {
    uint8_t *png;
    size_t len;
    h_png(16, 16, 3, 8, 1, 0, &png, &len);
    const char *meta = "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
                       "\"fl_x\": 20, \"fl_y\": 20, \"cx\": 8, \"cy\": 8}";
    h_part parts[2] = {{"image", png, len, "image.png", "image/png"},
                       {"meta", meta, strlen(meta), NULL, "application/json"}};
    h_req q = {.method = "POST", .path = "/v1/scenes/a/frames", .parts = parts, .n_parts = 2,
               .auth = H_AUTH_NONE};
    r = h_request(&q);
    ASSERT_HTTP_ERROR(r, 401, "unauthorized");
    h_resp_free(r);
    /* With the token the same upload works (frame 0: the refused one stored nothing). */
    r = h_upload_parts("/v1/scenes/a/frames", parts, 2);
    ASSERT_STATUS(r, 201);
    ASSERT_EQ(JINT(r->json, "frame"), 0);
    h_resp_free(r);
    free(png);
  }
  r = h_get("/v1/scenes/a");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "frames"), 1);
  h_resp_free(r);

  /* Unknown paths are behind the token too (no probing of the API without it). */
  expect_401("GET", "/v1/nope", NULL, NULL);

  /* /metrics needs the token. */
  expect_401("GET", "/metrics", NULL, NULL);
  expect_401("GET", "/metrics", "Authorization: Bearer wrong", NULL);
  r = h_get("/metrics");
  ASSERT_STATUS(r, 200);
  ASSERT_STRCONTAINS(r->body, "fieldgrip_http_requests_total");
  h_resp_free(r);

  r = h_delete("/v1/scenes/a");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
