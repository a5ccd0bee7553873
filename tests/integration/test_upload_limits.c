/* Upload limits with [http] max_upload_mb = 1: bodies over the limit with a Content-Length are
 * refused 413 before being read; chunked bodies that grow past it are refused 413 or cut off;
 * the daemon keeps answering and stores nothing of them. */
#include <curl/curl.h>

#include "harness.h"

#define FRAMES "/v1/scenes/s/frames"

typedef struct stream {
  const uint8_t *data;
  size_t len, pos;
} stream;

/* Hands out the body in 64 KiB pieces, so a chunked upload arrives as many chunks. */
static size_t read_piece(char *out, size_t size, size_t nmemb, void *ud) {
  stream *s = ud;
  size_t n = size * nmemb;
  if (n > 65536) n = 65536;
  if (n > s->len - s->pos) n = s->len - s->pos;
  memcpy(out, s->data + s->pos, n);
  s->pos += n;
  return n;
}

static char *g_meta;

static void multipart_frame(int side, unsigned seed, uint8_t **body, size_t *len) {
  uint8_t *png;
  size_t png_len;
  h_png(side, side, 3, 8, seed, 1, &png, &png_len);
  h_part parts[2] = {{"image", png, png_len, "image.png", "image/png"},
                     {"meta", g_meta, strlen(g_meta), NULL, "application/json"}};
  h_multipart_build(parts, 2, "fgboundary7MA4YWxkTrZu0gW", body, len);
  free(png);
}

static h_resp *post_multipart(const uint8_t *body, size_t len, int chunked, int expect) {
  stream s = {body, len, 0};
  const char *hdrs[3] = {"Content-Type: multipart/form-data; boundary=fgboundary7MA4YWxkTrZu0gW",
                         expect ? "Expect: 100-continue" : "Expect:", NULL};
  h_req q = {.method = "POST", .path = FRAMES, .headers = hdrs, .read_cb = read_piece,
             .read_ud = &s, .read_len = chunked ? -1 : (long long)len};
  return h_request(&q);
}

static void check_alive_and_unchanged(json_t *baseline, const char *what) {
  if (!h_alive()) FG_TEST_FAIL("the daemon died after: %s", what);
  h_resp *r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_get(FRAMES);
  ASSERT_STATUS(r, 200);
  if (!json_equal(r->json, baseline)) fprintf(stderr, "after: %s\n", what);
  ASSERT_JSON_EQUAL(RJSON(r), baseline);
  h_resp_free(r);
  r = h_get("/v1/scenes/s");
  ASSERT_EQ(JINT(r->json, "frames"), json_array_size(JGET(baseline, "frames")));
  h_resp_free(r);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  h_write_config("[http]\nmax_upload_mb = 1\n");
  h_start();
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"s\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  g_meta = h_fmt("{\"transform_matrix\": [[1,0,0,0.2],[0,1,0,0.1],[0,0,1,0.5],[0,0,0,1]], "
                 "\"fl_x\": 500, \"fl_y\": 500, \"cx\": 270, \"cy\": 270}");

  /* Just under the limit (about 0.88 MB): accepted, and downscaled to max_image_side 400. */
  uint8_t *body;
  size_t len;
  multipart_frame(540, 1, &body, &len);
  ASSERT(len < 1000000);
  r = post_multipart(body, len, 0, 0);
  ASSERT_STATUS(r, 201);
  ASSERT_EQ(JINT(r->json, "frame"), 0);
  h_resp_free(r);
  free(body);
  r = h_get(FRAMES);
  ASSERT_STATUS(r, 200);
  json_t *baseline = json_incref(RJSON(r));
  h_resp_free(r);
  ASSERT_EQ(json_array_size(JGET(baseline, "frames")), 1);
  static const double src[2] = {540, 540};
  ASSERT_VEC(JGET(baseline, "frames.0.source_size"), src, 2, 0);
  ASSERT_EQ(JINT(baseline, "frames.0.camera.w"), 400);
  ASSERT_EQ(JINT(baseline, "frames.0.camera.h"), 400);
  ASSERT_NEAR(JNUM(baseline, "frames.0.camera.fl_x"), 500.0 * 400.0 / 540.0, 1e-3);
  ASSERT_NEAR(JNUM(baseline, "frames.0.camera.cx"), 200.0, 1e-3);

  /* 2 MB with a Content-Length, sent the way curl does it (Expect: 100-continue). */
  multipart_frame(820, 2, &body, &len);
  ASSERT(len > 2000000);
  r = post_multipart(body, len, 0, 1);
  ASSERT_HTTP_ERROR(r, 413, "payload_too_large");
  h_resp_free(r);
  check_alive_and_unchanged(baseline, "2 MB with Expect: 100-continue");

  /* The same without Expect: the whole body is on its way when the 413 is decided. */
  r = post_multipart(body, len, 0, 0);
  ASSERT_HTTP_ERROR(r, 413, "payload_too_large");
  h_resp_free(r);
  check_alive_and_unchanged(baseline, "2 MB without Expect");

  /* A curl_mime upload of the same size. */
  {
    uint8_t *png;
    size_t png_len;
    h_png(820, 820, 3, 8, 3, 1, &png, &png_len);
    r = h_upload(FRAMES, png, png_len, g_meta, NULL, 0);
    ASSERT_HTTP_ERROR(r, 413, "payload_too_large");
    h_resp_free(r);
    free(png);
    check_alive_and_unchanged(baseline, "2 MB curl_mime upload");
  }
  free(body);

  /* Any body, not only frames: a 2 MB JSON scene creation. */
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
    r = h_get("/v1/scenes/big");
    ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
    h_resp_free(r);
  }

  /* Chunked, 1.5 MB: past the limit, short of twice it: read, discarded, answered 413. */
  multipart_frame(724, 4, &body, &len);
  ASSERT(len > 1100000 && len < 2000000);
  r = post_multipart(body, len, 1, 0);
  ASSERT_HTTP_ERROR(r, 413, "payload_too_large");
  h_resp_free(r);
  free(body);
  check_alive_and_unchanged(baseline, "1.5 MB chunked");

  /* Chunked, 3 MB: 413, or the connection dropped; never accepted, never a crash. */
  multipart_frame(1024, 5, &body, &len);
  ASSERT(len > 3000000);
  r = post_multipart(body, len, 1, 0);
  if (r->status != 0) {
    ASSERT_HTTP_ERROR(r, 413, "payload_too_large");
  } else {
    ASSERT_NE(r->curl_rc, CURLE_OK);
    printf("3 MB chunked upload: connection dropped (%s)\n",
           curl_easy_strerror((CURLcode)r->curl_rc));
  }
  h_resp_free(r);
  free(body);
  check_alive_and_unchanged(baseline, "3 MB chunked");

  /* Chunked within the limit is fine, and takes the next frame number. */
  multipart_frame(300, 6, &body, &len);
  r = post_multipart(body, len, 1, 0);
  ASSERT_STATUS(r, 201);
  ASSERT_EQ(JINT(r->json, "frame"), 1);
  h_resp_free(r);
  free(body);

  r = h_get("/v1/scenes/s");
  ASSERT_EQ(JINT(r->json, "frames"), 2);
  h_resp_free(r);
  /* On disk: the two accepted frames and no leftovers of the refused bodies. */
  char *fdir = h_fmt("%s/scenes/s/frames", h_state_dir());
  ASSERT_EQ(h_count_files(fdir, ".fgf"), 2);
  free(fdir);
  ASSERT_EQ(h_count_files(h_state_dir(), ".tmp."), 0);
  h_stop();
  json_decref(baseline);
  free(g_meta);
  h_done();
  printf("ok\n");
  return 0;
}
