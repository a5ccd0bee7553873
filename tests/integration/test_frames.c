/* Frame uploads: PNGs made here (RGB, RGBA, 16-bit) with meta and .npy features made by hand;
 * the listing's poses and cameras (opencv converted to opengl, position+quaternion poses,
 * camera_angle_x); and every bad input, after each of which the scene must be unchanged. */
#include "harness.h"

#define SCENE "/v1/scenes/s/frames"

static uint8_t *g_png;      /* 64x48 RGB */
static size_t g_png_len;
static uint8_t *g_feat;     /* [6,8,16] <f4 */
static size_t g_feat_len;
static json_t *g_baseline;  /* GET frames before a bad request */
static int g_nframes;

/* Snapshot of the listing that bad requests must leave as it is. */
static void take_baseline(void) {
  h_resp *r = h_get(SCENE);
  ASSERT_STATUS(r, 200);
  json_decref(g_baseline);
  g_baseline = json_incref(RJSON(r));
  g_nframes = (int)json_array_size(JGET(g_baseline, "frames"));
  h_resp_free(r);
}

static void check_unchanged(const char *what) {
  h_resp *r = h_get(SCENE);
  ASSERT_STATUS(r, 200);
  if (!json_equal(RJSON(r), g_baseline)) fprintf(stderr, "after: %s\n", what);
  ASSERT_JSON_EQUAL(RJSON(r), g_baseline);
  h_resp_free(r);
  r = h_get("/v1/scenes/s");
  ASSERT_STATUS(r, 200);
  if (JINT(r->json, "frames") != g_nframes) fprintf(stderr, "after: %s\n", what);
  ASSERT_EQ(JINT(r->json, "frames"), g_nframes);
  h_resp_free(r);
}

/* An upload that must be refused with status/code and change nothing. code2 may name an
 * alternative code where the contract allows two readings (see the report). */
static void bad_upload(const char *what, const h_part *parts, int n, long status, const char *code,
                       const char *code2) {
  h_resp *r = h_upload_parts(SCENE, parts, n);
  json_t *c = r->json ? h_jfind(r->json, "error.code") : NULL;
  const char *got = json_is_string(c) ? json_string_value(c) : "";
  const char *want = code2 && strcmp(got, code2) == 0 ? code2 : code;
  if (r->status != status || strcmp(got, want) != 0) fprintf(stderr, "case: %s\n", what);
  ASSERT_HTTP_ERROR(r, status, want);
  h_resp_free(r);
  check_unchanged(what);
}

static void bad_meta(const char *what, const char *meta, long status, const char *code,
                     const char *code2) {
  h_part parts[3] = {
      {"image", g_png, g_png_len, "image.png", "image/png"},
      {"meta", meta, strlen(meta), NULL, "application/json"},
      {"features", g_feat, g_feat_len, "features.npy", "application/octet-stream"},
  };
  bad_upload(what, parts, 3, status, code, code2);
}

static void bad_matrix(const char *what, const char *matrix, long status, const char *code,
                       const char *code2) {
  char *meta = h_fmt("{\"transform_matrix\": %s, \"camera\": {\"fl_x\": 50, \"fl_y\": 50, "
                     "\"cx\": 32, \"cy\": 24, \"w\": 64, \"h\": 48}}",
                     matrix);
  bad_meta(what, meta, status, code, code2);
  free(meta);
}

static void bad_features(const char *what, const void *npy, size_t len) {
  double T[16];
  h_pose(T, 0, 0, 0, 0, 0, 0);
  char *meta = h_meta(T, "opengl", 50, 32, 24, 64, 48);
  h_part parts[3] = {
      {"image", g_png, g_png_len, "image.png", "image/png"},
      {"meta", meta, strlen(meta), NULL, "application/json"},
      {"features", npy, len, "features.npy", "application/octet-stream"},
  };
  bad_upload(what, parts, 3, 400, "invalid_features", NULL);
  free(meta);
}

static void check_upload_reply(h_resp *r, int frame, int w, int h, int fh, int fw, int fd) {
  ASSERT_STATUS(r, 201);
  ASSERT_EQ(JINT(r->json, "frame"), frame);
  ASSERT_EQ(JINT(r->json, "image.w"), w);
  ASSERT_EQ(JINT(r->json, "image.h"), h);
  if (fd) {
    ASSERT_EQ(JINT(r->json, "features.h"), fh);
    ASSERT_EQ(JINT(r->json, "features.w"), fw);
    ASSERT_EQ(JINT(r->json, "features.d"), fd);
  } else {
    ASSERT(json_is_null(JGET(r->json, "features")));
  }
}

static void check_camera(json_t *f, double fl_x, double fl_y, double cx, double cy, int w, int h) {
  ASSERT_NEAR(JNUM(f, "camera.fl_x"), fl_x, 1e-6);
  ASSERT_NEAR(JNUM(f, "camera.fl_y"), fl_y, 1e-6);
  ASSERT_NEAR(JNUM(f, "camera.cx"), cx, 1e-6);
  ASSERT_NEAR(JNUM(f, "camera.cy"), cy, 1e-6);
  ASSERT_EQ(JINT(f, "camera.w"), w);
  ASSERT_EQ(JINT(f, "camera.h"), h);
  ASSERT_STREQ(JSTR(f, "camera.camera_model"), "PINHOLE");
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  h_start();

  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"s\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);

  h_png(64, 48, 3, 8, 1, 0, &g_png, &g_png_len);
  uint8_t *rgba, *png16, *feat16;
  size_t rgba_len, png16_len, feat16_len;
  h_png(64, 48, 4, 8, 2, 0, &rgba, &rgba_len);
  h_png(32, 24, 3, 16, 3, 0, &png16, &png16_len);
  static const int shape[3] = {6, 8, 16};
  h_npy("<f4", shape, 3, 0, &g_feat, &g_feat_len);
  h_npy("<f2", shape, 3, 5, &feat16, &feat16_len);

  /* ---- good uploads ---- */
  double T0[16], T1[16], T2[16], T3[16];
  h_pose(T0, 0.1, 0.2, 0.3, 0.5, -0.2, 0.4);
  h_pose(T1, -0.4, 0.0, 1.2, 0.1, 0.3, 0.6);
  h_pose(T2, 0.0, 2.0, 0.0, -0.3, 0.0, 0.9);
  h_pose(T3, 2.5, -0.5, 0.3, 0.2, 0.2, 0.2);

  /* 0: RGB, camera object, float32 features. */
  char *meta0 = h_meta(T0, "opengl", 50, 32, 24, 64, 48);
  r = h_upload(SCENE, g_png, g_png_len, meta0, g_feat, g_feat_len);
  check_upload_reply(r, 0, 64, 48, 6, 8, 16);
  h_resp_free(r);

  /* 1: RGBA, intrinsics at the top level (as a transforms.json frame), no w/h, float16. */
  char *m1 = h_matrix_json(T1);
  char *meta1 = h_fmt("{\"transform_matrix\": %s, \"fl_x\": 60, \"fl_y\": 61, \"cx\": 31.5, "
                      "\"cy\": 23.5}",
                      m1);
  r = h_upload(SCENE, rgba, rgba_len, meta1, feat16, feat16_len);
  check_upload_reply(r, 1, 64, 48, 6, 8, 16);
  h_resp_free(r);

  /* 2: 16-bit RGB, camera_angle_x instead of a focal length, no features. */
  char *m2 = h_matrix_json(T2);
  char *meta2 = h_fmt("{\"transform_matrix\": %s, \"convention\": \"opengl\", "
                      "\"camera_angle_x\": 0.8}",
                      m2);
  r = h_upload(SCENE, png16, png16_len, meta2, NULL, 0);
  check_upload_reply(r, 2, 32, 24, 0, 0, 0);
  h_resp_free(r);

  /* 3: opencv convention; the listing shows it as opengl (y and z columns negated). */
  char *meta3 = h_meta(T3, "opencv", 50, 32, 24, 64, 48);
  r = h_upload(SCENE, g_png, g_png_len, meta3, g_feat, g_feat_len);
  check_upload_reply(r, 3, 64, 48, 6, 8, 16);
  h_resp_free(r);

  /* 4: position + quaternion [w,x,y,z]: 90 degrees about +x. */
  const char *meta4 = "{\"pose\": {\"position\": [0.1, 0.2, 0.3], "
                      "\"quaternion\": [0.70710678118654757, 0.70710678118654746, 0, 0]}, "
                      "\"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24}}";
  r = h_upload(SCENE, g_png, g_png_len, meta4, g_feat, g_feat_len);
  check_upload_reply(r, 4, 64, 48, 6, 8, 16);
  h_resp_free(r);

  /* 5: an OPENCV camera with distortion: undistorted on ingest, listed as PINHOLE. */
  char *m5 = h_matrix_json(T0);
  char *meta5 = h_fmt("{\"transform_matrix\": %s, \"camera\": {\"fl_x\": 50, \"fl_y\": 50, "
                      "\"cx\": 32, \"cy\": 24, \"camera_model\": \"OPENCV\", \"k1\": 0.1, "
                      "\"k2\": -0.02, \"p1\": 0.001, \"p2\": 0.0}}",
                      m5);
  r = h_upload(SCENE, g_png, g_png_len, meta5, g_feat, g_feat_len);
  check_upload_reply(r, 5, 64, 48, 6, 8, 16);
  h_resp_free(r);

  /* ---- the listing ---- */
  r = h_get(SCENE);
  ASSERT_STATUS(r, 200);
  json_t *frames = JGET(r->json, "frames");
  ASSERT_EQ(json_array_size(frames), 6);
  for (int i = 0; i < 6; i++) {
    json_t *f = json_array_get(frames, (size_t)i);
    ASSERT_EQ(JINT(f, "frame"), i);
    ASSERT_STREQ(JSTR(f, "convention"), "opengl");
    ASSERT(json_is_boolean(JGET(f, "undistorted")));
    ASSERT_EQ(json_is_true(JGET(f, "undistorted")), i == 5);
    JSTR(f, "created");
  }
  json_t *f5 = json_array_get(frames, 5);
  ASSERT_STREQ(JSTR(f5, "camera.camera_model"), "PINHOLE");
  ASSERT_EQ(JINT(f5, "camera.w"), 64);
  ASSERT_EQ(JINT(f5, "camera.h"), 48);
  ASSERT_MATRIX(JGET(f5, "transform_matrix"), T0, 1e-6);
  json_t *f0 = json_array_get(frames, 0);
  ASSERT_MATRIX(JGET(f0, "transform_matrix"), T0, 1e-6);
  check_camera(f0, 50, 50, 32, 24, 64, 48);
  static const double sz64[2] = {64, 48}, sz32[2] = {32, 24};
  ASSERT_VEC(JGET(f0, "source_size"), sz64, 2, 0);
  ASSERT_EQ(JINT(f0, "features.h"), 6);
  ASSERT_EQ(JINT(f0, "features.w"), 8);
  ASSERT_EQ(JINT(f0, "features.d"), 16);
  ASSERT_STREQ(JSTR(f0, "features.dtype"), "float32");

  json_t *f1 = json_array_get(frames, 1);
  ASSERT_MATRIX(JGET(f1, "transform_matrix"), T1, 1e-6);
  check_camera(f1, 60, 61, 31.5, 23.5, 64, 48);
  ASSERT_STREQ(JSTR(f1, "features.dtype"), "float16");
  ASSERT_EQ(JINT(f1, "features.d"), 16);

  json_t *f2 = json_array_get(frames, 2);
  ASSERT_MATRIX(JGET(f2, "transform_matrix"), T2, 1e-6);
  double fl2 = 0.5 * 32 / tan(0.5 * 0.8);
  check_camera(f2, fl2, fl2, 16, 12, 32, 24);
  ASSERT_VEC(JGET(f2, "source_size"), sz32, 2, 0);
  ASSERT(json_is_null(JGET(f2, "features")));

  json_t *f3 = json_array_get(frames, 3);
  double T3gl[16];
  memcpy(T3gl, T3, sizeof T3gl);
  for (int row = 0; row < 3; row++) {
    T3gl[4 * row + 1] = -T3[4 * row + 1];
    T3gl[4 * row + 2] = -T3[4 * row + 2];
  }
  ASSERT_MATRIX(JGET(f3, "transform_matrix"), T3gl, 1e-6);

  json_t *f4 = json_array_get(frames, 4);
  static const double T4[16] = {1, 0, 0, 0.1, 0, 0, -1, 0.2, 0, 1, 0, 0.3, 0, 0, 0, 1};
  ASSERT_MATRIX(JGET(f4, "transform_matrix"), T4, 1e-6);
  check_camera(f4, 50, 50, 32, 24, 64, 48);
  h_resp_free(r);

  r = h_get("/v1/scenes/s");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "frames"), 6);
  ASSERT_EQ(JINT(r->json, "feature_dim"), 16);
  h_resp_free(r);

  /* ---- bad inputs: each refused, nothing changes ---- */
  take_baseline();
  {
    h_part p[2] = {{"meta", meta0, strlen(meta0), NULL, "application/json"},
                   {"features", g_feat, g_feat_len, "features.npy", NULL}};
    bad_upload("no image part", p, 2, 400, "missing_part", NULL);
  }
  {
    h_part p[2] = {{"image", g_png, g_png_len, "image.png", "image/png"},
                   {"features", g_feat, g_feat_len, "features.npy", NULL}};
    bad_upload("no meta part", p, 2, 400, "missing_part", NULL);
  }
  {
    h_part p[1] = {{"features", g_feat, g_feat_len, "features.npy", NULL}};
    bad_upload("only features", p, 1, 400, "missing_part", NULL);
  }
  bad_meta("meta not JSON", "{\"transform_matrix\": [[1,0,0,0]", 400, "malformed_json", NULL);
  bad_meta("meta plain text", "hello", 400, "malformed_json", NULL);
  {
    uint8_t junk[2048];
    uint32_t s = 12345;
    for (size_t i = 0; i < sizeof junk; i++) {
      s ^= s << 13;
      s ^= s >> 17;
      s ^= s << 5;
      junk[i] = (uint8_t)s;
    }
    memcpy(junk, "JUNKDATA", 8); /* no image format starts like this */
    h_part p[2] = {{"image", junk, sizeof junk, "image.png", "image/png"},
                   {"meta", meta0, strlen(meta0), NULL, "application/json"}};
    bad_upload("random bytes as image", p, 2, 415, "unsupported_media_type", NULL);
  }
  {
    h_part p[2] = {{"image", g_png, g_png_len / 2, "image.png", "image/png"},
                   {"meta", meta0, strlen(meta0), NULL, "application/json"}};
    bad_upload("truncated PNG", p, 2, 400, "invalid_image", NULL);
    h_part e[2] = {{"image", "", 0, "image.png", "image/png"},
                   {"meta", meta0, strlen(meta0), NULL, "application/json"}};
    /* An empty part carries no image at all: either reading is a clear 4xx. */
    bad_upload("empty image part", e, 2, 400, "invalid_image", "missing_part");
  }
  bad_matrix("3x4 matrix", "[[1,0,0,0],[0,1,0,0],[0,0,1,0]]", 400, "invalid_pose", NULL);
  bad_matrix("4x3 matrix", "[[1,0,0],[0,1,0],[0,0,1],[0,0,0]]", 400, "invalid_pose", NULL);
  bad_matrix("flat matrix", "[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]", 400, "invalid_pose", NULL);
  bad_matrix("string in matrix", "[[1,0,0,0],[0,1,0,0],[0,0,1,\"x\"],[0,0,0,1]]", 400,
             "invalid_pose", NULL);
  /* NaN is not a JSON token: the meta is malformed JSON. */
  bad_matrix("NaN token", "[[1,0,0,NaN],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", 400, "malformed_json",
             NULL);
  /* 1e999 is valid JSON grammar but overflows a double (Inf); jansson refuses to parse it. */
  bad_matrix("1e999", "[[1,0,0,1e999],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", 400, "invalid_pose",
             "malformed_json");
  bad_matrix("scale 1.01", "[[1.01,0,0,0],[0,1.01,0,0],[0,0,1.01,0],[0,0,0,1]]", 400,
             "invalid_pose", NULL);
  bad_matrix("reflection", "[[1,0,0,0],[0,1,0,0],[0,0,-1,0],[0,0,0,1]]", 400, "invalid_pose",
             NULL);
  bad_matrix("shear", "[[1,0.1,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]", 400, "invalid_pose", NULL);
  bad_matrix("last row 0 0 0 2", "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,2]]", 400, "invalid_pose",
             NULL);
  bad_matrix("last row 0 .1 0 1", "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0.1,0,1]]", 400,
             "invalid_pose", NULL);
  bad_meta("no pose at all", "{\"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24}}",
           400, "invalid_pose", "invalid_request");
  bad_meta("quaternion of 3",
           "{\"pose\": {\"position\": [0, 0, 0], \"quaternion\": [1, 0, 0]}, "
           "\"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24}}",
           400, "invalid_pose", NULL);
  bad_meta("quaternion not of unit length",
           "{\"pose\": {\"position\": [0, 0, 0], \"quaternion\": [2, 0, 0, 0]}, "
           "\"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24}}",
           400, "invalid_pose", NULL);
  bad_meta("bad convention",
           "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
           "\"convention\": \"directx\", \"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24}}",
           400, "invalid_pose", "invalid_request");

  /* Intrinsics. */
  bad_meta("negative focal length",
           "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
           "\"camera\": {\"fl_x\": -50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24}}",
           400, "invalid_camera", NULL);
  bad_meta("w/h disagree with the image",
           "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
           "\"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24, \"w\": 100, \"h\": 48}}",
           400, "invalid_camera", NULL);
  bad_meta("unknown camera model",
           "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
           "\"camera\": {\"fl_x\": 50, \"fl_y\": 50, \"cx\": 32, \"cy\": 24, \"camera_model\": \"FISHEYE\"}}",
           400, "invalid_camera", NULL);
  bad_meta("no focal length",
           "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]], "
           "\"camera\": {\"cx\": 32, \"cy\": 24}}",
           400, "invalid_camera", NULL);

  /* Features. */
  {
    uint8_t *npy;
    size_t len;
    static const int s2[2] = {6, 8};
    h_npy("<f4", s2, 2, 0, &npy, &len);
    bad_features("features [h,w]", npy, len);
    free(npy);
    static const int s8[3] = {6, 8, 8};
    h_npy("<f4", s8, 3, 0, &npy, &len);
    bad_features("features D=8 in a D=16 scene", npy, len);
    free(npy);
    h_npy("<f8", shape, 3, 0, &npy, &len);
    bad_features("features <f8", npy, len);
    free(npy);
    static const int s4[4] = {1, 6, 8, 16};
    h_npy("<f4", s4, 4, 0, &npy, &len);
    bad_features("features 4-D", npy, len);
    free(npy);
    h_npy("<f4", shape, 3, 0, &npy, &len);
    bad_features("features truncated", npy, len - 100);
    float nan = NAN;
    memcpy(npy + len - 4 * 10, &nan, 4);
    bad_features("features with NaN", npy, len);
    float inf = INFINITY;
    memcpy(npy + len - 4 * 10, &inf, 4);
    bad_features("features with Inf", npy, len);
    free(npy);
    bad_features("features not npy", "this is not a numpy file, not even close to one", 48);
  }

  /* Not multipart at all. */
  {
    h_req q = {.method = "POST", .path = SCENE, .body = meta0, .body_len = strlen(meta0)};
    r = h_request(&q);
    ASSERT_HTTP_ERROR(r, 415, "unsupported_media_type");
    h_resp_free(r);
    check_unchanged("JSON body");
    h_req q2 = {.method = "POST", .path = SCENE, .body = g_png, .body_len = g_png_len,
                .content_type = "image/png"};
    r = h_request(&q2);
    ASSERT_HTTP_ERROR(r, 415, "unsupported_media_type");
    h_resp_free(r);
    check_unchanged("raw PNG body");
  }
  /* Unknown scene. */
  r = h_upload("/v1/scenes/nope/frames", g_png, g_png_len, meta0, NULL, 0);
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  check_unchanged("unknown scene");
  r = h_get("/v1/scenes/nope");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found"); /* the upload did not create it */
  h_resp_free(r);

  /* The refused uploads used no frame numbers: the next good one is 6. */
  r = h_upload(SCENE, g_png, g_png_len, meta0, feat16, feat16_len);
  check_upload_reply(r, 6, 64, 48, 6, 8, 16);
  h_resp_free(r);
  r = h_get(SCENE);
  ASSERT_EQ(json_array_size(JGET(r->json, "frames")), 7);
  json_t *base_frames = JGET(g_baseline, "frames"), *now_frames = JGET(r->json, "frames");
  for (size_t i = 0; i < 6; i++)
    ASSERT_JSON_EQUAL(json_array_get(now_frames, i), json_array_get(base_frames, i));
  ASSERT_EQ(JINT(r->json, "frames.6.frame"), 6);
  h_resp_free(r);

  /* D is per scene: another scene may use D=8, and then refuses D=16. */
  r = h_post_json("/v1/scenes", "{\"name\": \"t\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  {
    uint8_t *npy8;
    size_t len8;
    static const int s8[3] = {3, 4, 8};
    h_npy("<f4", s8, 3, 0, &npy8, &len8);
    r = h_upload("/v1/scenes/t/frames", g_png, g_png_len, meta0, npy8, len8);
    check_upload_reply(r, 0, 64, 48, 3, 4, 8);
    h_resp_free(r);
    r = h_upload("/v1/scenes/t/frames", g_png, g_png_len, meta0, g_feat, g_feat_len);
    ASSERT_HTTP_ERROR(r, 400, "invalid_features");
    h_resp_free(r);
    r = h_get("/v1/scenes/t");
    ASSERT_EQ(JINT(r->json, "frames"), 1);
    ASSERT_EQ(JINT(r->json, "feature_dim"), 8);
    h_resp_free(r);
    free(npy8);
  }

  h_stop();
  json_decref(g_baseline);
  free(meta0);
  free(m1);
  free(meta1);
  free(m2);
  free(meta2);
  free(meta3);
  free(m5);
  free(meta5);
  free(g_png);
  free(rgba);
  free(png16);
  free(g_feat);
  free(feat16);
  h_done();
  printf("ok\n");
  return 0;
}
