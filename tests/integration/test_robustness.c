/* Hostile input: deeply nested JSON, broken multipart bodies, path traversal through scene
 * names, and malformed HTTP on raw sockets. Each is refused with a 4xx (JSON error where the
 * request reached the API), the daemon keeps answering, and no data changes. */
#include <sys/stat.h>

#include "harness.h"

static json_t *g_frames; /* listing of scene s that nothing here may change */

static void check_intact(const char *what) {
  if (!h_alive()) FG_TEST_FAIL("the daemon died after: %s", what);
  h_resp *r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_get("/v1/scenes/s/frames");
  ASSERT_STATUS(r, 200);
  if (!json_equal(r->json, g_frames)) fprintf(stderr, "after: %s\n", what);
  ASSERT_JSON_EQUAL(RJSON(r), g_frames);
  h_resp_free(r);
  r = h_get("/v1/scenes");
  ASSERT_EQ(json_array_size(JGET(r->json, "scenes")), 1);
  h_resp_free(r);
}

static void expect_error(h_resp *r, long status, const char *code, const char *code2,
                         const char *what) {
  json_t *c = r->json ? h_jfind(r->json, "error.code") : NULL;
  const char *got = json_is_string(c) ? json_string_value(c) : "";
  const char *want = code2 && strcmp(got, code2) == 0 ? code2 : code;
  if (r->status != status || strcmp(got, want) != 0) fprintf(stderr, "case: %s\n", what);
  ASSERT_HTTP_ERROR(r, status, want);
  h_resp_free(r);
  check_intact(what);
}

static h_resp *post_raw(const char *path, const char *content_type, const void *body, size_t len) {
  h_req q = {.method = "POST", .path = path, .body = body, .body_len = len,
             .content_type = content_type};
  return h_request(&q);
}

/* A raw exchange must be answered with a 4xx status line; a connection closed without a
 * reply, or any other status, fails. */
static void raw_expect_4xx(const char *req, size_t len, const char *what) {
  char resp[8192];
  long n = h_raw_exchange(req, len, resp, sizeof resp);
  if (n <= 0) FG_TEST_FAIL("%s: the connection was closed without a reply, not a 4xx", what);
  if (strncmp(resp, "HTTP/1.", 7) != 0 || resp[9] != '4')
    FG_TEST_FAIL("%s: expected a 4xx reply, got: %.200s", what, resp);
  check_intact(what);
}

/* Bytes that hold no request line at all (no space in the first line): libmicrohttpd closes
 * the connection without a reply, as there is no HTTP request to answer. It must close (not
 * hang: h_raw_exchange gives up after 30 s), send nothing, and keep serving. */
static void raw_expect_closed(const char *req, size_t len, const char *what) {
  char resp[8192];
  long n = h_raw_exchange(req, len, resp, sizeof resp);
  if (n > 0) FG_TEST_FAIL("%s: expected the connection closed unanswered, got: %.200s", what, resp);
  check_intact(what);
}

static void test_json(void) {
  size_t depth = 100000;
  char *deep = malloc(2 * depth + 1);
  ASSERT(deep);
  memset(deep, '[', depth);
  memset(deep + depth, ']', depth);
  deep[2 * depth] = '\0';
  h_resp *r = h_post_json("/v1/scenes", deep);
  expect_error(r, 400, "malformed_json", NULL, "100000-deep JSON array");
  char *meta = h_fmt("{\"transform_matrix\": %s}", deep);
  uint8_t *png;
  size_t png_len;
  h_png(32, 24, 3, 8, 1, 0, &png, &png_len);
  r = h_upload("/v1/scenes/s/frames", png, png_len, meta, NULL, 0);
  expect_error(r, 400, "malformed_json", NULL, "100000-deep meta");
  free(meta);
  free(deep);
  free(png);
  /* Invalid UTF-8 is not JSON text. */
  r = h_post_json("/v1/scenes", "{\"name\": \"a\xff\xfe\"}");
  expect_error(r, 400, "malformed_json", NULL, "invalid UTF-8");
}

static void test_multipart(void) {
  const char *path = "/v1/scenes/s/frames";
  h_resp *r = post_raw(path, "multipart/form-data", "hello", 5);
  expect_error(r, 400, "invalid_request", NULL, "multipart without boundary");
  r = post_raw(path, "multipart/form-data; boundary=XX", "garbage garbage", 15);
  expect_error(r, 400, "missing_part", "invalid_request", "multipart garbage");
  const char *trunc = "--XX\r\nContent-Disposition: form-data; name=\"image\"\r\n\r\nabc";
  r = post_raw(path, "multipart/form-data; boundary=XX", trunc, strlen(trunc));
  expect_error(r, 400, "invalid_request", NULL, "multipart cut off in a part");

  uint8_t *png;
  size_t png_len;
  h_png(32, 24, 3, 8, 1, 0, &png, &png_len);
  const char *meta = "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
                     "\"fl_x\": 30, \"fl_y\": 30, \"cx\": 16, \"cy\": 12}";
  h_part twice[3] = {{"image", png, png_len, "a.png", "image/png"},
                     {"image", png, png_len, "b.png", "image/png"},
                     {"meta", meta, strlen(meta), NULL, NULL}};
  r = h_upload_parts(path, twice, 3);
  expect_error(r, 400, "invalid_request", NULL, "two image parts");
  h_part extra[3] = {{"image", png, png_len, "a.png", "image/png"},
                     {"meta", meta, strlen(meta), NULL, NULL},
                     {"surprise", "x", 1, NULL, NULL}};
  r = h_upload_parts(path, extra, 3);
  expect_error(r, 400, "invalid_request", NULL, "unknown part");
  free(png);
}

static void test_traversal(void) {
  static const char *const names[] = {"..", "%2e%2e", ".", "%2E", "..%2F..", "%2e%2e%2fstate"};
  for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
    char *p = h_fmt("/v1/scenes/%s", names[i]);
    h_resp *r = h_delete(p);
    /* Not a scene name: either it names no scene (404) or no route at all (404). */
    expect_error(r, 404, "scene_not_found", "not_found", p);
    r = h_get(p);
    expect_error(r, 404, "scene_not_found", "not_found", p);
    free(p);
  }
  /* The state dir and the scene's files are still there. */
  char *sdir = h_fmt("%s/scenes/s/scene.json", h_state_dir());
  struct stat st;
  ASSERT_EQ(stat(sdir, &st), 0);
  free(sdir);
}

static void test_raw_http(void) {
  raw_expect_closed("GARBAGE\r\n\r\n", 11, "a first line with no request in it");
  /* the start of a TLS ClientHello, as a line (without its end the connection waits for
   * more until the 120 s idle timeout, as any unfinished request does) */
  static const char hello[] = "\x16\x03\x01\x00\xa5\x01\x00\x00\xa1\x03\x03\r\n\r\n";
  raw_expect_closed(hello, sizeof hello - 1, "binary bytes as the first line");
  const char *method = "GARBAGE /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  raw_expect_4xx(method, strlen(method), "an unknown method");
  const char *proto = "GET /v1/health FOO/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  raw_expect_4xx(proto, strlen(proto), "a request line that is not HTTP");
  const char *nover = "GET /v1/health\r\n\r\n";
  raw_expect_4xx(nover, strlen(nover), "a request line without a version");
  const char *nocolon = "GET /v1/health HTTP/1.1\r\nHost x\r\n\r\n";
  raw_expect_4xx(nocolon, strlen(nocolon), "a header line without a colon");
  const char *neg = "POST /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: -5\r\n\r\n";
  raw_expect_4xx(neg, strlen(neg), "Content-Length -5");
  const char *huge = "POST /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                     "Content-Length: 99999999999999999999\r\n\r\n{}";
  raw_expect_4xx(huge, strlen(huge), "Content-Length 1e20");
  const char *big = "POST /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                    "Content-Length: 5000000000\r\n\r\n{}";
  raw_expect_4xx(big, strlen(big), "Content-Length 5 GB");
  const char *badchunk = "POST /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                         "Transfer-Encoding: chunked\r\n\r\nZZZ\r\n{}\r\n0\r\n\r\n";
  raw_expect_4xx(badchunk, strlen(badchunk), "a bad chunk size");

  /* A 200 KB header line. */
  size_t n = 200000;
  char *req = malloc(n + 128);
  ASSERT(req);
  int k = snprintf(req, 128, "GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: ");
  memset(req + k, 'a', n);
  memcpy(req + k + n, "\r\n\r\n", 5);
  raw_expect_4xx(req, strlen(req), "a 200 KB header");
  free(req);

  /* Connections that stop half-way through the headers, or say nothing. */
  for (int i = 0; i < 20; i++) {
    h_raw_abandon("GET /v1/scen", 12);
    h_raw_abandon("", 0);
    h_raw_abandon("POST /v1/scenes HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 100\r\n"
                  "\r\n{\"na", 70);
  }
  check_intact("half requests and silent connections");

  /* Two requests on one connection both get answered. */
  const char *two = "GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
                    "GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
  char out[8192];
  long got = h_raw_exchange(two, strlen(two), out, sizeof out);
  ASSERT(got > 0);
  int replies = 0;
  for (const char *p = strstr(out, "HTTP/1.1 200"); p; p = strstr(p + 1, "HTTP/1.1 200")) replies++;
  ASSERT_EQ(replies, 2);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  h_start();
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"s\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  uint8_t *png;
  size_t png_len;
  h_png(32, 24, 3, 8, 1, 0, &png, &png_len);
  r = h_upload("/v1/scenes/s/frames", png, png_len,
               "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0.5],[0,0,0,1]], "
               "\"fl_x\": 30, \"fl_y\": 30, \"cx\": 16, \"cy\": 12}",
               NULL, 0);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(png);
  r = h_get("/v1/scenes/s/frames");
  g_frames = json_incref(RJSON(r));
  h_resp_free(r);

  test_json();
  test_multipart();
  test_traversal();
  test_raw_http();

  h_stop();
  json_decref(g_frames);
  h_done();
  printf("ok\n");
  return 0;
}
