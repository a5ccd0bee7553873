/* Depth maps through the API (issue 13): an upload with a 16-bit PNG depth part and a .npy one,
 * every bad depth input refused with 400 invalid_depth naming the frame and nothing stored, the
 * frame JSON's depth {w, h, valid_fraction} before and after a restart; an import of a scenegen
 * data set with depth whose one depth file is missing (imported without, counted) and one
 * unusable (the frame skipped with the reason); a training with depth_weight, and bad
 * weights refused. argv[2]: fieldgrip-scenegen. */
#include "training.h"

#include <math.h>
#include <unistd.h>

#define FRAMES "/v1/scenes/d/frames"

static uint8_t *g_png; /* 64x48 RGB */
static size_t g_png_len;
static char *g_meta;

/* A float32 .npy of shape [h, w] with the given values. Caller frees *out. */
static void npy_f32(int h, int w, const float *v, uint8_t **out, size_t *len) {
  char hdr[128];
  int n = snprintf(hdr, sizeof hdr, "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d), }",
                   h, w);
  while ((10 + n + 1) % 64) hdr[n++] = ' ';
  hdr[n++] = '\n';
  *len = 10 + (size_t)n + (size_t)w * (size_t)h * 4;
  *out = malloc(*len);
  ASSERT(*out);
  memcpy(*out, "\x93NUMPY\x01\x00", 8);
  (*out)[8] = (uint8_t)(n & 0xff);
  (*out)[9] = (uint8_t)(n >> 8);
  memcpy(*out + 10, hdr, (size_t)n);
  memcpy(*out + 10 + n, v, (size_t)w * (size_t)h * 4);
}

static h_resp *upload_depth(const void *depth, size_t len, const char *meta) {
  h_part parts[3] = {
      {"image", g_png, g_png_len, "view.png", "image/png"},
      {"meta", meta, strlen(meta), NULL, "application/json"},
      {"depth", depth, len, "depth.bin", "application/octet-stream"},
  };
  return h_upload_parts(FRAMES, parts, depth ? 3 : 2);
}

static int frame_count(void) {
  h_resp *r = h_get(FRAMES);
  ASSERT_STATUS(r, 200);
  const int n = (int)json_array_size(JGET(r->json, "frames"));
  h_resp_free(r);
  return n;
}

/* An upload that must be refused with 400 invalid_depth, a message holding want and the
 * frame's name, and no frame stored. */
static void bad_depth(const char *what, const void *depth, size_t len, const char *meta,
                      const char *want) {
  const int before = frame_count();
  h_resp *r = upload_depth(depth, len, meta ? meta : g_meta);
  if (r->status != 400) fprintf(stderr, "case: %s\n", what);
  ASSERT_HTTP_ERROR(r, 400, "invalid_depth");
  const char *msg = JSTR(r->json, "error.message");
  if (!strstr(msg, want)) FG_TEST_FAIL("%s: message \"%s\" lacks \"%s\"", what, msg, want);
  if (depth && !strstr(msg, "view.png"))
    FG_TEST_FAIL("%s: message \"%s\" does not name the frame", what, msg);
  h_resp_free(r);
  ASSERT_EQ(frame_count(), before);
}

static void test_upload(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"d\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  h_png(64, 48, 3, 8, 1, 0, &g_png, &g_png_len);
  double T[16];
  h_pose(T, 0.1, -0.2, 0.05, 0.3, 0.1, 0.5);
  g_meta = h_meta(T, "opengl", 60, 32, 24, 64, 48);

  /* 16-bit PNG on a half-size grid, tenths of a millimetre */
  uint8_t *d16;
  size_t d16_len;
  h_png(32, 24, 1, 16, 3, 0, &d16, &d16_len);
  char *meta = h_fmt("%.*s, \"depth_scale\": 0.0001}", (int)strlen(g_meta) - 1, g_meta);
  r = upload_depth(d16, d16_len, meta);
  ASSERT_STATUS(r, 201);
  ASSERT_EQ(JINT(r->json, "depth.w"), 64);
  ASSERT_EQ(JINT(r->json, "depth.h"), 48);
  const double valid = JNUM(r->json, "depth.valid_fraction");
  ASSERT(valid > 0.5 && valid <= 1.0);
  h_resp_free(r);

  /* float32 .npy in metres, NaN and 0 invalid */
  float v[48 * 64];
  for (int i = 0; i < 48 * 64; i++) v[i] = i % 4 == 0 ? NAN : i % 4 == 1 ? 0.0f : 0.5f + 1e-4f * i;
  uint8_t *npy;
  size_t npy_len;
  npy_f32(48, 64, v, &npy, &npy_len);
  r = upload_depth(npy, npy_len, g_meta);
  ASSERT_STATUS(r, 201);
  ASSERT_NEAR(JNUM(r->json, "depth.valid_fraction"), 0.5, 1e-9);
  h_resp_free(r);
  free(npy);
  /* no depth part: no depth */
  r = upload_depth(NULL, 0, g_meta);
  ASSERT_STATUS(r, 201);
  ASSERT(json_is_null(JGET(r->json, "depth")));
  h_resp_free(r);

  /* every bad depth input: 400 invalid_depth, nothing stored */
  uint8_t *p8, *rgb16, *off;
  size_t p8_len, rgb16_len, off_len;
  h_png(64, 48, 1, 8, 4, 0, &p8, &p8_len);
  bad_depth("8-bit PNG", p8, p8_len, NULL, "8-bit");
  h_png(64, 48, 3, 16, 5, 0, &rgb16, &rgb16_len);
  bad_depth("colour PNG", rgb16, rgb16_len, NULL, "colour");
  h_png(30, 24, 1, 16, 6, 0, &off, &off_len);
  bad_depth("off the image's grid", off, off_len, NULL, "30x24");
  v[100] = -0.25f;
  npy_f32(48, 64, v, &npy, &npy_len);
  bad_depth("negative metres", npy, npy_len, NULL, "-0.25");
  free(npy);
  v[100] = INFINITY;
  npy_f32(48, 64, v, &npy, &npy_len);
  bad_depth("infinite metres", npy, npy_len, NULL, "inf");
  free(npy);
  char *m0 = h_fmt("%.*s, \"depth_scale\": 0}", (int)strlen(g_meta) - 1, g_meta);
  bad_depth("depth_scale 0", d16, d16_len, m0, "depth_scale must be a number > 0");
  char *mneg = h_fmt("%.*s, \"depth_scale\": -0.001}", (int)strlen(g_meta) - 1, g_meta);
  bad_depth("depth_scale < 0", d16, d16_len, mneg, "depth_scale");
  bad_depth("depth_scale without depth", NULL, 0, meta, "no 'depth' part");
  bad_depth("truncated PNG", d16, d16_len / 2, NULL, "depth");
  free(m0);
  free(mneg);
  free(meta);
  free(p8);
  free(rgb16);
  free(off);
  free(d16);
  ASSERT_EQ(frame_count(), 3);
}

/* The listing's depth of the three uploads, before and after a restart. */
static void check_listing(double valid0) {
  h_resp *r = h_get(FRAMES);
  ASSERT_STATUS(r, 200);
  json_t *fr = JGET(r->json, "frames");
  ASSERT_EQ(json_array_size(fr), 3);
  ASSERT_EQ(JINT(json_array_get(fr, 0), "depth.w"), 64);
  ASSERT_EQ(JINT(json_array_get(fr, 0), "depth.h"), 48);
  ASSERT_NEAR(JNUM(json_array_get(fr, 0), "depth.valid_fraction"), valid0, 1e-12);
  ASSERT_NEAR(JNUM(json_array_get(fr, 1), "depth.valid_fraction"), 0.5, 1e-9);
  ASSERT(json_is_null(JGET(json_array_get(fr, 2), "depth")));
  h_resp_free(r);
}

static void test_import_and_train(const char *scenegen, const char *imports) {
  char *dir = h_fmt("%s/tabletop", imports);
  t_scenegen_depth(scenegen, dir, 12, 64, 48, 8, 0, "png");
  /* view 3's depth file is gone; view 5's is an 8-bit PNG */
  char *gone = h_fmt("%s/depth/0003.png", dir), *bad = h_fmt("%s/depth/0005.png", dir);
  ASSERT_EQ(unlink(gone), 0);
  uint8_t *p8;
  size_t p8_len;
  h_png(64, 48, 1, 8, 7, 0, &p8, &p8_len);
  h_write_file(bad, p8, p8_len);
  free(p8);
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"t\", \"workspace\": {\"min\": [0.1, -0.45, "
                                        "-0.05], \"max\": [0.8, 0.45, 0.35]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  char *body = h_fmt("{\"path\": \"%s\"}", dir);
  r = h_post_json("/v1/scenes/t/import", body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), 11);
  ASSERT_EQ(JINT(r->json, "with_depth"), 10);
  ASSERT_EQ(JINT(r->json, "depth_missing"), 1);
  ASSERT_EQ(JINT(r->json, "skipped"), 1);
  json_t *sk = JGET(r->json, "skipped_frames");
  ASSERT_EQ(json_array_size(sk), 1);
  ASSERT_EQ(JINT(json_array_get(sk, 0), "frame"), 5);
  ASSERT(strstr(JSTR(json_array_get(sk, 0), "reason"), "8-bit"));
  h_resp_free(r);
  r = h_get("/v1/scenes/t/frames");
  ASSERT_STATUS(r, 200);
  int with = 0;
  for (size_t i = 0; i < json_array_size(JGET(r->json, "frames")); i++)
    with += !json_is_null(JGET(json_array_get(JGET(r->json, "frames"), i), "depth"));
  ASSERT_EQ(with, 10);
  h_resp_free(r);

  /* bad loss weights, then a training with the depth loss */
  const char *bad_bodies[] = {"{\"steps\": 5, \"depth_weight\": -1}",
                              "{\"steps\": 5, \"depth_weight\": \"a lot\"}",
                              "{\"steps\": 5, \"distortion_weight\": 1e9}"};
  for (size_t i = 0; i < sizeof bad_bodies / sizeof bad_bodies[0]; i++) {
    r = h_post_json("/v1/scenes/t/train", bad_bodies[i]);
    ASSERT_HTTP_ERROR(r, 400, "invalid_request");
    h_resp_free(r);
  }
  char *job = t_train("t", "{\"steps\": 30, \"depth_weight\": 0.5, \"distortion_weight\": 0.01}");
  json_t *j = t_wait_job(job, "done", 600);
  ASSERT_NEAR(JNUM(j, "depth_weight"), 0.5, 1e-12);
  ASSERT_NEAR(JNUM(j, "distortion_weight"), 0.01, 1e-9);
  json_decref(j);
  free(job);
  /* the configuration's default when a request names none */
  job = t_train("t", "{\"steps\": 5}");
  j = t_wait_job(job, "done", 600);
  ASSERT_NEAR(JNUM(j, "depth_weight"), 0.3, 1e-12);
  ASSERT_NEAR(JNUM(j, "distortion_weight"), 0.0, 0);
  json_decref(j);
  free(job);
  free(body);
  free(gone);
  free(bad);
  free(dir);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  char *imports = h_fmt("%s/imports", h_tmpdir());
  h_mkdirs(imports);
  t_write_config(imports);
  h_start();
  test_upload();
  h_resp *r = h_get(FRAMES);
  const double valid0 = JNUM(json_array_get(JGET(r->json, "frames"), 0), "depth.valid_fraction");
  h_resp_free(r);
  check_listing(valid0);
  h_stop();
  h_start();
  check_listing(valid0);
  test_import_and_train(argv[2], imports);
  free(imports);
  h_stop();
  free(g_png);
  free(g_meta);
  h_done();
  return 0;
}
