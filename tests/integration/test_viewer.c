/* The web viewer's server side, black-box over HTTP on the trained fixture's scenegen tabletop
 * (trained.h: its scene trained 250 steps at 1 cm voxels, and the same frames untrained):
 *   - GET / is the page (HTML that loads /viewer/three.min.js and /viewer/viewer.js);
 *     /viewer/{file} serves the viewer's files with their content types, three.min.js from
 *     [http] three_js (the libjs-three file, byte for byte); names that leave the folder,
 *     hidden files and unknown kinds are refused;
 *   - GET /v1/scenes/{s}/points: 404 unknown scene, 409 before training; the FGPC header
 *     (magic, version, sizes, the grid) and body length; the points are exactly the
 *     geometry's solid voxel centres with the geometry's colours (one voxel cache), alpha
 *     bytes at or over the threshold; max_points thins them to the documented even spread,
 *     the same bytes each time; another voxel size; every bad parameter's JSON error;
 *   - GET /v1/scenes/{s}/frames/{i}/image: the stored frame as an 8-bit RGB PNG, the data
 *     set's image; 404 frame_not_found, 400 for a number that is none;
 *   - after a reload with a token, [http] viewer_dir and a missing [http] three_js: the page
 *     and its files need no token, the points do; the page comes from viewer_dir; the missing
 *     three.js is a 404 naming the file and libjs-three.
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <math.h>

#include "core/error.h"
#include "io/image.h"
#include "io/ply.h"
#include "grasp_util.h"
#include "trained.h"
#include "training.h"

#define W G_W
#define H G_H
#define THREE_JS "/usr/share/javascript/three/three.min.js"
#define TOKEN "viewer-test-token"

static const double WS_MIN[3] = {0.1, -0.45, -0.05}, WS_MAX[3] = {0.8, 0.45, 0.35};
static char *g_data; /* the data set */

/* ---------------------------------------------------------------- FGPC */

typedef struct fgpc {
  uint32_t count, n_solid, n[3];
  float voxel, alpha, min[3];
  const float *xyz;    /* count x 3, into the reply (the body is 4-byte aligned: malloc) */
  const uint8_t *rgba; /* count x 4 */
} fgpc;

static uint32_t le32(const char *p) {
  const unsigned char *b = (const unsigned char *)p;
  return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

static float lef32(const char *p) {
  const uint32_t v = le32(p);
  float f;
  memcpy(&f, &v, sizeof f);
  return f;
}

/* The reply as FGPC, asserted 200 with a body of exactly the header's size. */
static fgpc fgpc_reply(const h_resp *r) {
  if (r->status != 200) fprintf(stderr, "points: %s\n", r->body);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "application/octet-stream");
  ASSERT(r->len >= 64);
  ASSERT(memcmp(r->body, "FGPC", 4) == 0);
  ASSERT_EQ(le32(r->body + 4), 1);
  ASSERT_EQ(le32(r->body + 8), 64);
  fgpc p;
  p.count = le32(r->body + 12);
  p.n_solid = le32(r->body + 16);
  p.voxel = lef32(r->body + 20);
  p.alpha = lef32(r->body + 24);
  for (int a = 0; a < 3; a++) {
    p.min[a] = lef32(r->body + 28 + 4 * a);
    p.n[a] = le32(r->body + 40 + 4 * a);
  }
  for (int i = 52; i < 64; i++) ASSERT_EQ(r->body[i], 0);
  ASSERT_EQ(r->len, 64 + (size_t)p.count * 16);
  ASSERT_EQ(strtoll(h_resp_header(r, "X-Point-Count"), NULL, 10), p.count);
  ASSERT_EQ(strtoll(h_resp_header(r, "X-Solid-Count"), NULL, 10), p.n_solid);
  ASSERT(p.count <= p.n_solid);
  p.xyz = (const float *)(r->body + 64); /* the test runs on little-endian machines only */
  p.rgba = (const uint8_t *)(r->body + 64 + (size_t)p.count * 12);
  return p;
}

static h_resp *points(const char *scene, const char *query) {
  char *path = h_fmt("/v1/scenes/%s/points%s%s", scene, query[0] ? "?" : "", query);
  h_resp *r = h_get(path);
  free(path);
  return r;
}

static void expect_error(const char *scene, const char *query, long status, const char *code) {
  h_resp *r = points(scene, query);
  if (r->status != status) fprintf(stderr, "points ?%s: %s\n", query, r->body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
}

/* ---------------------------------------------------------------- static files */

static void expect_file(const char *path, const char *type, const char *needle) {
  h_resp *r = h_get(path);
  if (r->status != 200) fprintf(stderr, "%s: %s\n", path, r->body);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), type);
  ASSERT_STREQ(h_resp_header(r, "Cache-Control"), "no-cache");
  if (needle) ASSERT_STRCONTAINS(r->body, needle);
  h_resp_free(r);
}

static void test_static(void) {
  expect_file("/", "text/html; charset=utf-8", "<script src=\"/viewer/viewer.js\"></script>");
  expect_file("/", "text/html; charset=utf-8", "<script src=\"/viewer/three.min.js\"></script>");
  expect_file("/viewer/index.html", "text/html; charset=utf-8", "<canvas id=\"canvas\">");
  expect_file("/viewer/viewer.js", "text/javascript; charset=utf-8", "window.fgViewer");
  expect_file("/viewer/viewer.css", "text/css; charset=utf-8", "#panel");
  /* three.js: Debian's file, as it is */
  size_t len;
  char *three = h_read_file(THREE_JS, &len);
  if (!three) FG_TEST_FAIL("%s is missing: install libjs-three", THREE_JS);
  h_resp *r = h_get("/viewer/three.min.js");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "text/javascript; charset=utf-8");
  ASSERT_EQ(r->len, len);
  ASSERT(memcmp(r->body, three, len) == 0);
  h_resp_free(r);
  free(three);

  /* Nothing outside the folder, nothing hidden, no other kind of file. */
  static const char *const refused[] = {
      "/viewer/%2e%2e", "/viewer/..%2fviewer%2findex.html", "/viewer/.hidden.js",
      "/viewer/meson.build", "/viewer/viewer.js~",
      "/viewer/a%20b.js", "/viewer/nothing.js"};
  for (size_t i = 0; i < sizeof refused / sizeof refused[0]; i++) {
    r = h_get(refused[i]);
    if (r->status != 404) fprintf(stderr, "%s: %ld %s\n", refused[i], r->status, r->body);
    ASSERT_HTTP_ERROR(r, 404, "not_found");
    h_resp_free(r);
  }
  /* a literal "..", which libcurl would resolve itself */
  static const char raw[] = "GET /viewer/../daemon.log HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                            "Connection: close\r\n\r\n";
  char reply[4096];
  ASSERT(h_raw_exchange(raw, sizeof raw - 1, reply, sizeof reply) > 0);
  ASSERT(strncmp(reply, "HTTP/1.1 404", 12) == 0);
  /* only GET */
  r = h_post_json("/viewer/viewer.js", "{}");
  ASSERT_EQ(r->status, 405);
  h_resp_free(r);
}

/* ---------------------------------------------------------------- points */

static void test_points(void) {
  const double t = t_now();
  h_resp *r = points("sg", "");
  const double ms = (t_now() - t) * 1e3;
  fgpc p = fgpc_reply(r);
  ASSERT_NEAR(p.voxel, 0.01, 1e-7);
  ASSERT_NEAR(p.alpha, 0.1, 1e-7);
  ASSERT_EQ(p.n[0], 70);
  ASSERT_EQ(p.n[1], 90);
  ASSERT_EQ(p.n[2], 40);
  for (int a = 0; a < 3; a++) ASSERT_NEAR(p.min[a], WS_MIN[a], 1e-6);
  ASSERT(p.count > 0);
  ASSERT_EQ(p.count, p.n_solid); /* fewer than the default max_points */

  /* The geometry's solid voxels at the same threshold: the same centres in the same order,
   * the same colours. */
  h_resp *g = h_get("/v1/scenes/sg/geometry?kind=points&threshold=0.1");
  ASSERT_STATUS(g, 200);
  fg_ply ply;
  ASSERT_OK(fg_ply_decode(g->body, g->len, &ply));
  ASSERT_EQ(ply.n_vertices, p.count);
  ASSERT(ply.rgb != NULL);
  size_t varied = 0;
  for (size_t i = 0; i < p.count; i++) {
    for (int a = 0; a < 3; a++) {
      const double x = p.xyz[3 * i + a];
      ASSERT(x == ply.xyz[3 * i + a]);
      /* in the workspace's voxel box, on a voxel centre */
      const double c = (x - WS_MIN[a]) / 0.01 - 0.5;
      ASSERT_NEAR(c, floor(c + 0.5), 1e-3);
      ASSERT(c > -0.5 && c < p.n[a] - 0.5);
      ASSERT(x < WS_MAX[a] + 0.005 + 1e-6);
    }
    for (int k = 0; k < 3; k++) ASSERT_EQ(p.rgba[4 * i + k], ply.rgb[3 * i + k]);
    ASSERT(p.rgba[4 * i + 3] >= 25); /* alpha >= 0.1, in bytes */
    varied += memcmp(p.rgba + 4 * i, p.rgba, 3) != 0;
  }
  ASSERT(varied > 0); /* colours come from the field: not one grey */
  printf("points: %u solid voxels at alpha >= 0.1, %zu bytes in %.0f ms\n", p.n_solid, r->len,
         ms);
  fg_ply_release(&ply);
  h_resp_free(g);

  /* Thinned: the k-th point is solid voxel floor(k * n_solid / max_points). */
  const uint32_t keep = p.n_solid > 7 ? p.n_solid / 7 : 1;
  char *q = h_fmt("max_points=%u", keep);
  h_resp *t1 = points("sg", q), *t2 = points("sg", q);
  fgpc th = fgpc_reply(t1);
  ASSERT_EQ(th.count, keep);
  ASSERT_EQ(th.n_solid, p.n_solid);
  for (uint32_t k = 0; k < keep; k++) {
    const size_t src = (size_t)((uint64_t)k * p.n_solid / keep);
    ASSERT(memcmp(th.xyz + 3 * k, p.xyz + 3 * src, 12) == 0);
    ASSERT(memcmp(th.rgba + 4 * k, p.rgba + 4 * src, 4) == 0);
  }
  ASSERT_EQ(t2->len, t1->len);
  ASSERT(memcmp(t1->body, t2->body, t1->len) == 0);
  free(q);
  h_resp_free(t1);
  h_resp_free(t2);

  /* A higher threshold keeps fewer; another voxel size has its own grid. */
  h_resp *hi = points("sg", "alpha=0.5&max_points=1");
  fgpc ph = fgpc_reply(hi);
  ASSERT(ph.n_solid < p.n_solid);
  ASSERT_EQ(ph.count, ph.n_solid ? 1 : 0);
  h_resp_free(hi);
  h_resp *coarse = points("sg", "voxel_size=0.02");
  fgpc pc = fgpc_reply(coarse);
  ASSERT_NEAR(pc.voxel, 0.02, 1e-7);
  ASSERT_EQ(pc.n[0], 35);
  ASSERT_EQ(pc.n[1], 45);
  ASSERT_EQ(pc.n[2], 20);
  for (size_t i = 0; i < pc.count; i++) {
    const double c = (pc.xyz[3 * i] - WS_MIN[0]) / 0.02 - 0.5;
    ASSERT_NEAR(c, floor(c + 0.5), 1e-3);
  }
  h_resp_free(coarse);
  h_resp_free(r);

  static const char *const bad[] = {
      "foo=1", "alpha=0", "alpha=1", "alpha=-0.5", "alpha=abc", "alpha=", "alpha=nan",
      "alpha=1e-300", "alpha=0.99999999999", /* 0 and 1 as the float they are kept as */
      "voxel_size=0", "voxel_size=-0.01", "voxel_size=abc", "voxel_size=inf", "max_points=0",
      "max_points=1.5", "max_points=-3", "max_points=abc", "max_points=99999999",
      "max_points=", "alpha=0.2&extra=1"};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    expect_error("sg", bad[i], 400, "invalid_request");
  expect_error("sg", "voxel_size=0.001", 400, "grid_too_large");
  expect_error("nope", "", 404, "scene_not_found");
  h_resp *m = h_post_json("/v1/scenes/sg/points", "{}");
  ASSERT_EQ(m->status, 405);
  h_resp_free(m);
}

/* ---------------------------------------------------------------- frame images */

static void test_frame_image(void) {
  h_resp *r = h_get("/v1/scenes/sg/frames/3/image");
  int w, h, bits, type;
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, W);
  ASSERT_EQ(h, H);
  ASSERT_EQ(bits, 8);
  ASSERT_EQ(type, 2); /* RGB */
  /* The data set's image 3 (the import keeps its size and colours). */
  char *path = h_fmt("%s/images/0003.png", g_data);
  size_t len;
  char *png = h_read_file(path, &len);
  ASSERT(png != NULL);
  const float bg[3] = {1, 1, 1};
  fg_image a, b;
  ASSERT_OK(fg_image_decode(png, len, bg, &a));
  ASSERT_OK(fg_image_decode(r->body, r->len, bg, &b));
  ASSERT_EQ(a.w, b.w);
  double err = 0;
  for (size_t i = 0; i < (size_t)W * H * 3; i++) err = fmax(err, fabs(a.rgb[i] - b.rgb[i]));
  ASSERT(err <= 1.0 / 255 + 1e-6);
  fg_image_release(&a);
  fg_image_release(&b);
  free(png);
  free(path);
  h_resp_free(r);

  r = h_get("/v1/scenes/sg/frames/999/image");
  ASSERT_HTTP_ERROR(r, 404, "frame_not_found");
  h_resp_free(r);
  r = h_get("/v1/scenes/nope/frames/0/image");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  static const char *const bad[] = {"abc", "-1", "+1", "1x", "99999999999"};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    char *p = h_fmt("/v1/scenes/sg/frames/%s/image", bad[i]);
    r = h_get(p);
    ASSERT_HTTP_ERROR(r, 400, "invalid_request");
    h_resp_free(r);
    free(p);
  }
}

/* ---------------------------------------------------------------- token and settings */

static void test_token_and_settings(void) {
  char *imports = h_fmt("%s/imports", h_tmpdir()); /* f_dataset's */
  /* A viewer folder of our own, and a three.js that is not there. */
  char *dir = h_fmt("%s/myviewer", h_tmpdir());
  h_mkdirs(dir);
  char *index = h_fmt("%s/index.html", dir);
  static const char page[] = "<!doctype html><title>my viewer</title>";
  h_write_file(index, page, sizeof page - 1);
  char *conf = h_fmt("[http]\ntoken = " TOKEN "\nviewer_dir = %s\nthree_js = %s/no-three.js\n"
                     "[state]\nimport_dirs = %s\n[train]\nthreads = 2\n", dir, h_tmpdir(),
                     imports);
  h_write_config(conf);
  h_set_token(TOKEN); /* for h_reload's own requests */
  h_reload();

  h_req req = {.path = "/", .auth = H_AUTH_NONE};
  h_resp *r = h_request(&req);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(r->body, page);
  h_resp_free(r);
  req.path = "/viewer/three.min.js";
  r = h_request(&req);
  ASSERT_HTTP_ERROR(r, 404, "not_found");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "no-three.js");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "libjs-three");
  h_resp_free(r);
  req.path = "/viewer/viewer.js"; /* not in this folder */
  r = h_request(&req);
  ASSERT_HTTP_ERROR(r, 404, "not_found");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), dir);
  h_resp_free(r);

  /* The data needs the token. */
  req.path = "/v1/scenes/sg/points";
  r = h_request(&req);
  ASSERT_HTTP_ERROR(r, 401, "unauthorized");
  h_resp_free(r);
  req.path = "/v1/scenes/sg/frames/0/image";
  r = h_request(&req);
  ASSERT_HTTP_ERROR(r, 401, "unauthorized");
  h_resp_free(r);
  req.path = "/v1/scenes/sg/points?max_points=5";
  req.auth = H_AUTH_TOKEN;
  req.token = TOKEN;
  r = h_request(&req);
  fgpc p = fgpc_reply(r);
  ASSERT(p.count <= 5);
  h_resp_free(r);

  /* Empty values: the built-in places again. */
  free(conf);
  conf = h_fmt("[http]\nviewer_dir =\nthree_js =\n[state]\nimport_dirs = %s\n", imports);
  h_write_config(conf);
  h_reload();
  h_set_token(NULL);
  expect_file("/", "text/html; charset=utf-8", "viewer.js");
  expect_file("/viewer/three.min.js", "text/javascript; charset=utf-8", NULL);
  free(conf);
  free(index);
  free(dir);
  free(imports);
}

/* ---------------------------------------------------------------- main */

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  const double t0 = t_now();
  char *imports = f_dataset(argv[2]);
  t_write_config(imports);
  g_data = h_fmt("%s/sg", imports);
  free(imports);
  f_scene("raw1", "raw"); /* untrained */
  f_scene("t250", "sg");
  h_start();
  test_static();
  expect_error("raw", "", 409, "not_trained");
  h_resp *r = points("raw", "max_points=10");
  ASSERT_HTTP_ERROR(r, 409, "not_trained");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "POST /v1/scenes/raw/train");
  h_resp_free(r);
  test_frame_image();

  const double t_setup = t_now();
  test_points();
  test_token_and_settings();
  printf("setup %.1f s, checks %.1f s\n", t_setup - t0, t_now() - t_setup);

  h_stop();
  free(g_data);
  h_done();
  return 0;
}
