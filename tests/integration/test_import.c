/* POST /v1/scenes/{s}/import: the real NeRF lego data set (100 frames of 800x800 RGBA,
 * downscaled to max_image_side 400), the import_dirs sandbox (outside, "..", symlinks, missing),
 * and small synthetic data sets: a missing image (skipped and named), features_path, frame
 * files leading out of the import folders, and corrupt images, poses, features or transforms
 * files that fail the whole import. */
#include <errno.h>
#include <limits.h>
#include <unistd.h>

#include "harness.h"

static char *g_shared;  /* realpath of FG_SHARED_DATA */
static char g_imports[PATH_MAX];

static int scene_frames(const char *scene) {
  char path[128];
  snprintf(path, sizeof path, "/v1/scenes/%s", scene);
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  int n = (int)JINT(r->json, "frames");
  h_resp_free(r);
  return n;
}

static h_resp *import(const char *scene, const char *dir, const char *transforms) {
  char path[128];
  snprintf(path, sizeof path, "/v1/scenes/%s/import", scene);
  json_t *body = json_object();
  json_object_set_new(body, "path", json_string(dir));
  if (transforms) json_object_set_new(body, "transforms", json_string(transforms));
  char *text = json_dumps(body, 0);
  h_resp *r = h_post_json(path, text);
  free(text);
  json_decref(body);
  return r;
}

/* An import that must fail with status and code (or code2 where the contract leaves two
 * readings open), adding nothing; if names is not NULL the message must contain it. */
static void bad_import(const char *scene, const char *dir, const char *transforms, long status,
                       const char *code, const char *code2, const char *names) {
  int before = scene_frames(scene);
  h_resp *r = import(scene, dir, transforms);
  json_t *c = r->json ? h_jfind(r->json, "error.code") : NULL;
  const char *got = json_is_string(c) ? json_string_value(c) : "";
  const char *want = code2 && strcmp(got, code2) == 0 ? code2 : code;
  if (r->status != status || strcmp(got, want) != 0)
    fprintf(stderr, "import of %s (transforms %s)\n", dir, transforms ? transforms : "default");
  ASSERT_HTTP_ERROR(r, status, want);
  if (names) ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), names);
  h_resp_free(r);
  ASSERT_EQ(scene_frames(scene), before);
}

/* ---- synthetic data sets ---- */

typedef struct synth_frame {
  const char *file_path;   /* as written in transforms.json */
  const char *write_as;    /* the file actually written, NULL: none (missing) */
  int corrupt;             /* write a truncated PNG */
  const char *matrix;      /* JSON, NULL: a valid pose */
  const char *features;    /* features_path, NULL: none */
  int feat_d;              /* D of the written .npy */
} synth_frame;

static void write_synth(const char *name, const char *header, const synth_frame *fr, int n) {
  char dir[PATH_MAX + 64];
  snprintf(dir, sizeof dir, "%s/%s/img", g_imports, name);
  h_mkdirs(dir);
  char *frames = h_fmt("%s", "");
  for (int i = 0; i < n; i++) {
    double T[16];
    h_pose(T, 0.1 * i, 0.2, -0.1 * i, 0.5 + 0.1 * i, -0.2, 0.6);
    char *m = fr[i].matrix ? h_fmt("%s", fr[i].matrix) : h_matrix_json(T);
    char *feat = fr[i].features ? h_fmt(", \"features_path\": \"%s\"", fr[i].features) : h_fmt("%s", "");
    char *next = h_fmt("%s%s{\"file_path\": \"%s\", \"transform_matrix\": %s%s}", frames, i ? ", " : "",
                       fr[i].file_path, m, feat);
    free(frames);
    free(m);
    free(feat);
    frames = next;
    if (fr[i].write_as) {
      uint8_t *png;
      size_t len;
      h_png(40, 30, i % 2 ? 4 : 3, 8, (unsigned)i, 0, &png, &len);
      char *p = h_fmt("%s/%s/%s", g_imports, name, fr[i].write_as);
      h_write_file(p, png, fr[i].corrupt ? len / 2 : len);
      free(p);
      free(png);
    }
    if (fr[i].features) {
      uint8_t *npy;
      size_t len;
      int shape[3] = {5, 4, fr[i].feat_d};
      h_npy("<f4", shape, 3, (unsigned)i, &npy, &len);
      char *p = h_fmt("%s/%s/%s", g_imports, name, fr[i].features);
      h_write_file(p, npy, len);
      free(p);
      free(npy);
    }
  }
  char *json = h_fmt("{%s, \"frames\": [%s]}", header, frames);
  char *p = h_fmt("%s/%s/transforms.json", g_imports, name);
  h_write_file(p, json, strlen(json));
  free(p);
  free(json);
  free(frames);
}

static void test_lego(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"lego\", \"workspace\": {\"min\": [-1.5, -1.5, -1.5], "
                                        "\"max\": [1.5, 1.5, 1.5]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);

  char *lego = h_fmt("%s/lego", g_shared);
  r = import("lego", lego, "transforms_train.json");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), 100);
  ASSERT_EQ(JINT(r->json, "skipped"), 0);
  ASSERT_EQ(json_array_size(JGET(r->json, "skipped_files")), 0);
  json_t *ids = JGET(r->json, "frames");
  ASSERT_EQ(json_array_size(ids), 100);
  for (size_t i = 0; i < 100; i++) ASSERT_EQ(json_integer_value(json_array_get(ids, i)), (long long)i);
  h_resp_free(r);

  /* The listing against transforms_train.json itself. */
  char *tpath = h_fmt("%s/transforms_train.json", lego);
  json_error_t jerr;
  json_t *tf = json_load_file(tpath, 0, &jerr);
  if (!tf) FG_TEST_FAIL("%s: %s", tpath, jerr.text);
  double angle = JNUM(tf, "camera_angle_x");
  double fl800 = 0.5 * 800 / tan(0.5 * angle);
  ASSERT_NEAR(fl800, 1111.111, 1e-2);
  r = h_get("/v1/scenes/lego/frames");
  ASSERT_STATUS(r, 200);
  json_t *frames = JGET(r->json, "frames");
  ASSERT_EQ(json_array_size(frames), 100);
  for (size_t i = 0; i < 100; i++) {
    json_t *f = json_array_get(frames, i);
    json_t *src = json_array_get(JGET(tf, "frames"), i);
    ASSERT_EQ(JINT(f, "frame"), (long long)i);
    ASSERT_EQ(JINT(f, "camera.w"), 400);
    ASSERT_EQ(JINT(f, "camera.h"), 400);
    ASSERT_NEAR(JNUM(f, "camera.fl_x"), fl800 / 2, 1e-2);
    ASSERT_NEAR(JNUM(f, "camera.fl_y"), fl800 / 2, 1e-2);
    ASSERT_NEAR(JNUM(f, "camera.fl_x"), 555.555, 1e-2);
    ASSERT_NEAR(JNUM(f, "camera.cx"), 200, 1e-6);
    ASSERT_NEAR(JNUM(f, "camera.cy"), 200, 1e-6);
    ASSERT_STREQ(JSTR(f, "camera.camera_model"), "PINHOLE");
    static const double s800[2] = {800, 800};
    ASSERT_VEC(JGET(f, "source_size"), s800, 2, 0);
    ASSERT_STREQ(JSTR(f, "convention"), "opengl");
    ASSERT(json_is_null(JGET(f, "features")));
    double T[16];
    for (int k = 0; k < 16; k++) {
      char p[32];
      snprintf(p, sizeof p, "transform_matrix.%d.%d", k / 4, k % 4);
      T[k] = JNUM(src, p);
    }
    ASSERT_MATRIX(JGET(f, "transform_matrix"), T, 1e-6);
    char base[32];
    snprintf(base, sizeof base, "r_%zu", i);
    ASSERT_STRCONTAINS(JSTR(f, "source"), base);
  }
  h_resp_free(r);
  json_decref(tf);
  free(tpath);
  ASSERT_EQ(scene_frames("lego"), 100);

  /* The sandbox. */
  bad_import("lego", "/etc", NULL, 403, "forbidden_path", NULL, NULL);
  bad_import("lego", "/", NULL, 403, "forbidden_path", NULL, NULL);
  char *dotdot = h_fmt("%s/lego/../lego", g_shared);
  bad_import("lego", dotdot, "transforms_train.json", 403, "forbidden_path", NULL, NULL);
  free(dotdot);
  char *up = h_fmt("%s/..", g_shared);
  bad_import("lego", up, NULL, 403, "forbidden_path", NULL, NULL);
  free(up);
  bad_import("lego", "../lego", "transforms_train.json", 403, "forbidden_path", NULL, NULL);
  char *missing = h_fmt("%s/no-such-dir", g_shared);
  bad_import("lego", missing, NULL, 404, "path_not_found", NULL, NULL);
  free(missing);
  bad_import("lego", lego, "no-such-transforms.json", 404, "path_not_found", NULL, NULL);
  bad_import("lego", lego, NULL, 404, "path_not_found", NULL, NULL); /* no transforms.json */
  bad_import("lego", lego, "../lego/transforms_train.json", 403, "forbidden_path",
             "invalid_request", NULL);
  /* A symlink inside an import dir that leads out of it. */
  char *link = h_fmt("%s/escape", g_imports);
  if (symlink("/etc", link) != 0) FG_TEST_FAIL("symlink: %s", strerror(errno));
  bad_import("lego", link, NULL, 403, "forbidden_path", NULL, NULL);
  free(link);
  /* A folder whose name merely starts like an import dir is not inside it. */
  char *sibling = h_fmt("%s-evil", g_imports);
  h_mkdirs(sibling);
  bad_import("lego", sibling, NULL, 403, "forbidden_path", NULL, NULL);
  free(sibling);

  /* Bodies of the wrong shape. */
  r = h_post_json("/v1/scenes/lego/import", "{}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  r = h_post_json("/v1/scenes/lego/import", "{\"path\": 5}");
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  r = h_post_json("/v1/scenes/lego/import", "{\"path\": ");
  ASSERT_HTTP_ERROR(r, 400, "malformed_json");
  h_resp_free(r);
  r = import("nope", lego, "transforms_train.json");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  ASSERT_EQ(scene_frames("lego"), 100);
  free(lego);
}

static void test_synthetic(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"syn\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);

  /* One image missing: skipped, counted and named; the others imported. */
  static const synth_frame missing[3] = {
      {"./img/f_0", "img/f_0.png", 0, NULL, NULL, 0},
      {"./img/f_1", NULL, 0, NULL, NULL, 0},
      {"./img/f_2", "img/f_2.png", 0, NULL, NULL, 0},
  };
  write_synth("synth_missing", "\"camera_angle_x\": 0.9", missing, 3);
  char *dir = h_fmt("%s/synth_missing", g_imports);
  r = import("syn", dir, NULL);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), 2);
  ASSERT_EQ(JINT(r->json, "skipped"), 1);
  ASSERT_EQ(json_array_size(JGET(r->json, "skipped_files")), 1);
  ASSERT_STREQ(JSTR(r->json, "skipped_files.0"), "./img/f_1");
  ASSERT_EQ(json_array_size(JGET(r->json, "frames")), 2);
  ASSERT_EQ(JINT(r->json, "frames.0"), 0);
  ASSERT_EQ(JINT(r->json, "frames.1"), 1);
  h_resp_free(r);
  free(dir);
  r = h_get("/v1/scenes/syn/frames");
  ASSERT_EQ(json_array_size(JGET(r->json, "frames")), 2);
  double T0[16], T2[16];
  h_pose(T0, 0.0, 0.2, 0.0, 0.5, -0.2, 0.6);
  h_pose(T2, 0.2, 0.2, -0.2, 0.7, -0.2, 0.6);
  ASSERT_MATRIX(JGET(r->json, "frames.0.transform_matrix"), T0, 1e-6);
  ASSERT_MATRIX(JGET(r->json, "frames.1.transform_matrix"), T2, 1e-6);
  ASSERT_EQ(JINT(r->json, "frames.1.camera.w"), 40);
  ASSERT_EQ(JINT(r->json, "frames.1.camera.h"), 30);
  ASSERT_NEAR(JNUM(r->json, "frames.1.camera.fl_x"), 20.0 / tan(0.45), 1e-6);
  ASSERT_STRCONTAINS(JSTR(r->json, "frames.1.source"), "f_2");
  h_resp_free(r);

  /* Explicit intrinsics, file names with extensions, features_path; the folder given
   * relative to the import dir that holds it. */
  static const synth_frame ok[2] = {
      {"img/a.png", "img/a.png", 0, NULL, "img/a.npy", 8},
      {"img/b.png", "img/b.png", 0, NULL, "img/b.npy", 8},
  };
  write_synth("synth_ok", "\"fl_x\": 35, \"fl_y\": 36, \"cx\": 20, \"cy\": 15, \"w\": 40, \"h\": 30", ok, 2);
  r = import("syn", "synth_ok", NULL);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), 2);
  ASSERT_EQ(JINT(r->json, "skipped"), 0);
  ASSERT_EQ(JINT(r->json, "frames.0"), 2);
  ASSERT_EQ(JINT(r->json, "frames.1"), 3);
  h_resp_free(r);
  r = h_get("/v1/scenes/syn/frames");
  ASSERT_EQ(json_array_size(JGET(r->json, "frames")), 4);
  ASSERT_NEAR(JNUM(r->json, "frames.2.camera.fl_x"), 35, 1e-9);
  ASSERT_NEAR(JNUM(r->json, "frames.2.camera.fl_y"), 36, 1e-9);
  ASSERT_EQ(JINT(r->json, "frames.3.features.d"), 8);
  ASSERT_EQ(JINT(r->json, "frames.3.features.h"), 5);
  ASSERT_EQ(JINT(r->json, "frames.3.features.w"), 4);
  ASSERT_STREQ(JSTR(r->json, "frames.3.features.dtype"), "float32");
  json_t *listing = json_incref(RJSON(r));
  h_resp_free(r);
  r = h_get("/v1/scenes/syn");
  ASSERT_EQ(JINT(r->json, "feature_dim"), 8);
  h_resp_free(r);

  /* A corrupt image fails the whole import and names the frame. */
  static const synth_frame corrupt[3] = {
      {"./img/f_0", "img/f_0.png", 0, NULL, NULL, 0},
      {"./img/f_1", "img/f_1.png", 1, NULL, NULL, 0},
      {"./img/f_2", "img/f_2.png", 0, NULL, NULL, 0},
  };
  write_synth("synth_corrupt", "\"camera_angle_x\": 0.9", corrupt, 3);
  dir = h_fmt("%s/synth_corrupt", g_imports);
  bad_import("syn", dir, NULL, 400, "invalid_image", "invalid_transforms", "./img/f_1");
  free(dir);

  /* So does a bad pose (a 1.01 scale) in the last frame. */
  static const synth_frame badpose[3] = {
      {"./img/f_0", "img/f_0.png", 0, NULL, NULL, 0},
      {"./img/f_1", "img/f_1.png", 0, NULL, NULL, 0},
      {"./img/f_2", "img/f_2.png", 0, "[[1.01,0,0,0],[0,1.01,0,0],[0,0,1.01,0],[0,0,0,1]]", NULL, 0},
  };
  write_synth("synth_badpose", "\"camera_angle_x\": 0.9", badpose, 3);
  dir = h_fmt("%s/synth_badpose", g_imports);
  bad_import("syn", dir, NULL, 400, "invalid_pose", "invalid_transforms", "./img/f_2");
  free(dir);

  /* Features whose D differs from the scene's (8). */
  static const synth_frame badfeat[2] = {
      {"./img/f_0", "img/f_0.png", 0, NULL, "img/f_0.npy", 8},
      {"./img/f_1", "img/f_1.png", 0, NULL, "img/f_1.npy", 16},
  };
  write_synth("synth_badfeat", "\"camera_angle_x\": 0.9", badfeat, 2);
  dir = h_fmt("%s/synth_badfeat", g_imports);
  bad_import("syn", dir, NULL, 400, "invalid_features", "invalid_transforms", "./img/f_1");
  free(dir);

  /* Frames whose files lead out of the import folders: "..", an absolute path, a symlink, a
   * features_path. The whole import is refused, naming the frame. */
  {
    char *outside = h_fmt("%s/outside", h_tmpdir());
    h_mkdirs(outside);
    uint8_t *png, *npy;
    size_t png_len, npy_len;
    h_png(40, 30, 3, 8, 1, 0, &png, &png_len);
    static const int fshape[3] = {5, 4, 8};
    h_npy("<f4", fshape, 3, 0, &npy, &npy_len);
    char *p = h_fmt("%s/x.png", outside);
    h_write_file(p, png, png_len);
    free(p);
    p = h_fmt("%s/f.npy", outside);
    h_write_file(p, npy, npy_len);
    free(p);
    char *ds = h_fmt("%s/synth_escape", g_imports);
    h_mkdirs(ds);
    p = h_fmt("%s/ok.png", ds);
    h_write_file(p, png, png_len);
    free(p);
    char *link = h_fmt("%s/link.png", ds);
    char *target = h_fmt("%s/x.png", outside);
    if (symlink(target, link) != 0) FG_TEST_FAIL("symlink: %s", strerror(errno));
    free(link);
    const char *id = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    char *cases[4][2] = {
        {h_fmt("\"file_path\": \"../../outside/x.png\""), h_fmt("../../outside/x.png")},
        {h_fmt("\"file_path\": \"%s\"", target), h_fmt("%s", target)},
        {h_fmt("\"file_path\": \"link.png\""), h_fmt("link.png")},
        {h_fmt("\"file_path\": \"ok.png\", \"features_path\": \"../../outside/f.npy\""), h_fmt("ok.png")},
    };
    for (int i = 0; i < 4; i++) {
      char *json = h_fmt("{\"camera_angle_x\": 0.9, \"frames\": [{\"file_path\": \"ok.png\", "
                         "\"transform_matrix\": %s}, {%s, \"transform_matrix\": %s}]}",
                         id, cases[i][0], id);
      char *name = h_fmt("t%d.json", i);
      p = h_fmt("%s/%s", ds, name);
      h_write_file(p, json, strlen(json));
      free(p);
      bad_import("syn", ds, name, 403, "forbidden_path", NULL, cases[i][1]);
      free(name);
      free(json);
      free(cases[i][0]);
      free(cases[i][1]);
    }
    free(target);
    free(ds);
    free(outside);
    free(png);
    free(npy);
  }

  /* transforms.json that is not JSON, or has no frames. */
  char *bad = h_fmt("%s/synth_badjson", g_imports);
  h_mkdirs(bad);
  char *p = h_fmt("%s/transforms.json", bad);
  h_write_file(p, "{\"frames\": [", 12);
  bad_import("syn", bad, NULL, 400, "invalid_transforms", NULL, NULL);
  const char *nomatrix = "{\"camera_angle_x\": 0.9, \"frames\": [{\"file_path\": \"x\"}]}";
  h_write_file(p, nomatrix, strlen(nomatrix));
  bad_import("syn", bad, NULL, 400, "invalid_transforms", NULL, NULL);
  free(p);
  free(bad);

  /* Nothing of the failed imports is listed. */
  r = h_get("/v1/scenes/syn/frames");
  ASSERT_JSON_EQUAL(RJSON(r), listing);
  h_resp_free(r);
  json_decref(listing);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  g_shared = h_shared_data();
  char *imp = h_fmt("%s/imports", h_tmpdir());
  h_mkdirs(imp);
  if (!realpath(imp, g_imports)) FG_TEST_FAIL("realpath %s: %s", imp, strerror(errno));
  free(imp);
  char *conf = h_fmt("[state]\nimport_dirs = %s:%s\n", g_shared, g_imports);
  h_write_config(conf);
  free(conf);
  h_start();

  test_synthetic();
  test_lego();

  /* Without import_dirs nothing may be imported. */
  h_stop();
  h_write_config("; no import_dirs\n");
  h_start();
  char *dir = h_fmt("%s/synth_ok", g_imports);
  bad_import("syn", dir, NULL, 403, "forbidden_path", NULL, NULL);
  free(dir);
  ASSERT_EQ(scene_frames("syn"), 4);
  ASSERT_EQ(scene_frames("lego"), 100);
  h_stop();
  free(g_shared);
  h_done();
  printf("ok\n");
  return 0;
}
