/* transforms.json reader: instant-ngp (lego) and nerfstudio layouts written into a temp
 * folder, every error class, and the real NeRF lego data set from $FG_SHARED_DATA. */
#include "io/transforms.h"

#include "core/error.h"
#include "io/camera.h"
#include "test.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static char root[PATH_MAX];

/* Writes text to root/rel, creating the folders on the way; returns the malloc'd path. */
static char *put(const char *rel, const char *text) {
  char *path = malloc(strlen(root) + strlen(rel) + 2);
  ASSERT(path != NULL);
  sprintf(path, "%s/%s", root, rel);
  for (char *s = path + strlen(root) + 1; (s = strchr(s, '/')); s++) {
    *s = '\0';
    mkdir(path, 0700);
    *s = '/';
  }
  FILE *f = fopen(path, "w");
  ASSERT(f != NULL);
  ASSERT_EQ(fwrite(text, 1, strlen(text), f), strlen(text));
  ASSERT_EQ(fclose(f), 0);
  return path;
}

static char *path_in_root(const char *rel) {
  char *p = malloc(strlen(root) + strlen(rel) + 2);
  ASSERT(p != NULL);
  sprintf(p, "%s/%s", root, rel);
  return p;
}

#define IDENTITY "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]"

/* Loads root/rel (written from json) and expects code with a detail holding both substrings. */
static void expect_fail_at(int src_line, const char *rel, const char *json, int code,
                           const char *want1, const char *want2) {
  char *path = put(rel, json);
  fg_transforms t;
  memset(&t, 0xab, sizeof t);
  int rc = fg_transforms_load(path, &t);
  const char *d = fg_error_detail();
  if (rc != code || (want1 && !strstr(d, want1)) || (want2 && !strstr(d, want2)))
    FG_TEST_FAIL("(from test line %d) rc %d (expected %d), detail \"%s\" (expected \"%s\", "
                 "\"%s\")\n--- json ---\n%s",
                 src_line, rc, code, d, want1 ? want1 : "", want2 ? want2 : "", json);
  if (getenv("FG_TEST_VERBOSE")) fprintf(stderr, "%s\n", d);
  ASSERT(t.frames == NULL);
  ASSERT_EQ(t.n_frames, 0);
  free(path);
}
#define EXPECT_FAIL(rel, json, code, w1, w2) expect_fail_at(__LINE__, rel, json, code, w1, w2)

/* ---------------------------------------------------------------- instant-ngp / Blender */

static void test_lego_style(void) {
  free(put("lego/train/r_0.png", "png"));
  free(put("lego/train/r_1.PNG", "png"));
  free(put("lego/train/r_3", "exact name, no extension"));
  char *path = put("lego/transforms_train.json",
                   "{\n"
                   "  \"camera_angle_x\": 0.6911112070083618,\n"
                   "  \"frames\": [\n"
                   "    {\"file_path\": \"./train/r_0\", \"rotation\": 0.0125,\n"
                   "     \"transform_matrix\": [[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12],"
                   " [0, 0, 0, 1]]},\n"
                   "    {\"file_path\": \"./train/r_1\", \"transform_matrix\": " IDENTITY "},\n"
                   "    {\"file_path\": \"./train/r_2\", \"transform_matrix\": " IDENTITY "},\n"
                   "    {\"file_path\": \"train/r_3\", \"transform_matrix\": " IDENTITY "}\n"
                   "  ]\n"
                   "}\n");
  fg_transforms t;
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_EQ(t.n_frames, 4);
  ASSERT_EQ(t.n_missing, 1);

  char *want = path_in_root("lego/train/r_0.png");
  ASSERT_STREQ(t.frames[0].image_path, want);
  free(want);
  want = path_in_root("lego/train/r_1.PNG");
  ASSERT_STREQ(t.frames[1].image_path, want);
  free(want);
  ASSERT(t.frames[2].image_path == NULL);
  want = path_in_root("lego/train/r_3");
  ASSERT_STREQ(t.frames[3].image_path, want);
  free(want);
  ASSERT_STREQ(t.frames[0].file_path, "./train/r_0");
  ASSERT_STREQ(t.frames[2].file_path, "./train/r_2");
  ASSERT(t.frames[0].features_path == NULL);

  /* row-major, as written */
  for (int i = 0; i < 12; i++) ASSERT_NEAR(t.frames[0].T_world_cam[i], i + 1, 0);
  ASSERT_NEAR(t.frames[0].T_world_cam[15], 1, 0);

  /* no size in the file: the focal length waits for the image */
  fg_transforms_frame *f = &t.frames[0];
  ASSERT_EQ(f->has_size, 0);
  ASSERT_EQ(f->cam.w, 0);
  ASSERT_NEAR(f->camera_angle_x, 0.6911112070083618, 0);
  ASSERT_EQ(f->cam.model, FG_CAMERA_PINHOLE);
  ASSERT_OK(fg_transforms_complete_camera(f, 800, 800));
  ASSERT_EQ(f->cam.w, 800);
  ASSERT_EQ(f->cam.h, 800);
  double fl = 0.5 * 800 / tan(0.5 * 0.6911112070083618);
  ASSERT_NEAR(f->cam.fl_x, fl, 1e-9);
  ASSERT_NEAR(f->cam.fl_y, fl, 1e-9);
  ASSERT_NEAR(f->cam.fl_x, 1111.1110311937682, 1e-6);
  ASSERT_NEAR(f->cam.cx, 400, 0);
  ASSERT_NEAR(f->cam.cy, 400, 0);
  /* the angle scales with whatever size the image has */
  ASSERT_OK(fg_transforms_complete_camera(&t.frames[1], 400, 300));
  ASSERT_NEAR(t.frames[1].cam.fl_x, fl / 2, 1e-9);
  ASSERT_NEAR(t.frames[1].cam.fl_y, fl / 2, 1e-9);
  ASSERT_NEAR(t.frames[1].cam.cy, 150, 0);
  ASSERT_ERR(fg_transforms_complete_camera(&t.frames[1], 0, 300), FG_EINVAL, "not positive");
  ASSERT_ERR(fg_transforms_complete_camera(&t.frames[1], 40000, 300), FG_EINVAL, "32768");
  fg_transforms_free(&t);
  ASSERT(t.frames == NULL);
  ASSERT_EQ(t.n_frames, 0);
  fg_transforms_free(&t); /* twice is harmless */
  fg_transforms_free(NULL);
  free(path);
}

/* ---------------------------------------------------------------- nerfstudio */

static void test_nerfstudio_style(void) {
  free(put("ns/images/frame_00001.jpg", "jpg"));
  free(put("ns/images/frame_00002.jpg", "jpg"));
  free(put("ns/images/frame_00003.jpg", "jpg"));
  free(put("ns/features/f1.npy", "npy"));
  free(put("ns/features/f2.npy", "npy"));
  char *path = put("ns/transforms.json",
                   "{\n"
                   "  \"w\": 640, \"h\": 480.0,\n"
                   "  \"fl_x\": 500.5, \"fl_y\": 510.25, \"cx\": 321.5, \"cy\": 239.5,\n"
                   "  \"camera_model\": \"OPENCV\",\n"
                   "  \"k1\": 0.1, \"k2\": -0.05, \"k3\": 0.01, \"p1\": 0.001, \"p2\": -0.002,\n"
                   "  \"aabb_scale\": 16,\n"
                   "  \"frames\": [\n"
                   "    {\"file_path\": \"images/frame_00001.jpg\", \"transform_matrix\": " IDENTITY
                   ",\n     \"features_path\": \"features/f1.npy\", \"colmap_im_id\": 1},\n"
                   "    {\"file_path\": \"images/frame_00002.jpg\", \"transform_matrix\": " IDENTITY
                   ",\n     \"fl_x\": 600, \"features_path\": \"./features/f2\"},\n"
                   "    {\"file_path\": \"images/frame_00003.jpg\", \"transform_matrix\": " IDENTITY
                   ",\n     \"w\": 320, \"h\": 240, \"cx\": 160, \"cy\": 120, \"k3\": null}\n"
                   "  ]\n"
                   "}\n");
  fg_transforms t;
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_EQ(t.n_frames, 3);
  ASSERT_EQ(t.n_missing, 0);

  const fg_camera *c = &t.frames[0].cam;
  ASSERT_EQ(t.frames[0].has_size, 1);
  ASSERT_EQ(c->w, 640);
  ASSERT_EQ(c->h, 480);
  ASSERT_NEAR(c->fl_x, 500.5, 0);
  ASSERT_NEAR(c->fl_y, 510.25, 0);
  ASSERT_NEAR(c->cx, 321.5, 0);
  ASSERT_NEAR(c->cy, 239.5, 0);
  ASSERT_EQ(c->model, FG_CAMERA_OPENCV);
  ASSERT_NEAR(c->k1, 0.1, 0);
  ASSERT_NEAR(c->k2, -0.05, 0);
  ASSERT_NEAR(c->k3, 0.01, 0);
  ASSERT_NEAR(c->p1, 0.001, 0);
  ASSERT_NEAR(c->p2, -0.002, 0);
  char *want = path_in_root("ns/features/f1.npy");
  ASSERT_STREQ(t.frames[0].features_path, want);
  free(want);
  want = path_in_root("ns/images/frame_00001.jpg");
  ASSERT_STREQ(t.frames[0].image_path, want);
  free(want);

  /* frame 1 overrides fl_x only; its features_path has no extension */
  c = &t.frames[1].cam;
  ASSERT_NEAR(c->fl_x, 600, 0);
  ASSERT_NEAR(c->fl_y, 510.25, 0);
  ASSERT_NEAR(c->cx, 321.5, 0);
  ASSERT_EQ(c->w, 640);
  want = path_in_root("ns/features/f2.npy");
  ASSERT_STREQ(t.frames[1].features_path, want);
  free(want);

  /* frame 2 overrides the size and principal point; a null k3 falls back to the top level */
  c = &t.frames[2].cam;
  ASSERT_EQ(c->w, 320);
  ASSERT_EQ(c->h, 240);
  ASSERT_NEAR(c->cx, 160, 0);
  ASSERT_NEAR(c->cy, 120, 0);
  ASSERT_NEAR(c->fl_x, 500.5, 0);
  ASSERT_NEAR(c->k3, 0.01, 0);
  ASSERT(t.frames[2].features_path == NULL);

  /* the image must have the size the file claims */
  ASSERT_OK(fg_transforms_complete_camera(&t.frames[0], 640, 480));
  ASSERT_NEAR(t.frames[0].cam.cx, 321.5, 0); /* explicit values stay */
  ASSERT_NEAR(t.frames[0].cam.fl_y, 510.25, 0);
  ASSERT_ERR(fg_transforms_complete_camera(&t.frames[0], 641, 480), FG_EINVAL, "641x480");
  ASSERT_ERR(fg_transforms_complete_camera(&t.frames[2], 640, 480), FG_EINVAL, "w 320, h 240");
  ASSERT_OK(fg_transforms_complete_camera(&t.frames[2], 320, 240));
  fg_transforms_free(&t);
  free(path);
}

/* Intrinsics resolution: model inference, angle_y, one-axis focal lengths, deferred cx/cy. */
static void test_intrinsics(void) {
  free(put("intr/a.png", "png"));
  char *path = put("intr/t.json",
                   "{\"frames\": [\n"
                   " {\"file_path\": \"a\", \"transform_matrix\": " IDENTITY ", \"fl_x\": 300,"
                   "  \"k1\": 0.2},\n"
                   " {\"file_path\": \"a\", \"transform_matrix\": " IDENTITY ", \"fl_y\": 300,"
                   "  \"k1\": 0, \"cx\": 10},\n"
                   " {\"file_path\": \"a\", \"transform_matrix\": " IDENTITY ","
                   "  \"camera_angle_x\": 1.0, \"camera_angle_y\": 0.5},\n"
                   " {\"file_path\": \"a\", \"transform_matrix\": " IDENTITY ","
                   "  \"camera_angle_y\": 0.5, \"camera_model\": \"PINHOLE\"}\n"
                   "]}\n");
  fg_transforms t;
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_EQ(t.n_missing, 0);

  /* non-zero distortion without a model means OPENCV; fl_y follows fl_x before completion */
  fg_transforms_frame *f = &t.frames[0];
  ASSERT_EQ(f->cam.model, FG_CAMERA_OPENCV);
  ASSERT_NEAR(f->cam.fl_y, 300, 0);
  ASSERT_OK(fg_transforms_complete_camera(f, 200, 100));
  ASSERT_NEAR(f->cam.fl_x, 300, 0);
  ASSERT_NEAR(f->cam.fl_y, 300, 0);
  ASSERT_NEAR(f->cam.cx, 100, 0);
  ASSERT_NEAR(f->cam.cy, 50, 0);

  /* only fl_y: fl_x follows it; an explicit cx survives completion */
  f = &t.frames[1];
  ASSERT_EQ(f->cam.model, FG_CAMERA_PINHOLE);
  ASSERT_OK(fg_transforms_complete_camera(f, 200, 100));
  ASSERT_NEAR(f->cam.fl_x, 300, 0);
  ASSERT_NEAR(f->cam.cx, 10, 0);
  ASSERT_NEAR(f->cam.cy, 50, 0);

  /* both angles, each with its own side */
  f = &t.frames[2];
  ASSERT_OK(fg_transforms_complete_camera(f, 200, 100));
  ASSERT_NEAR(f->cam.fl_x, 100 / tan(0.5), 1e-9);
  ASSERT_NEAR(f->cam.fl_y, 50 / tan(0.25), 1e-9);

  /* only camera_angle_y: fl_x = fl_y */
  f = &t.frames[3];
  ASSERT_NEAR(f->camera_angle_y, 0.5, 0);
  ASSERT_OK(fg_transforms_complete_camera(f, 200, 100));
  ASSERT_NEAR(f->cam.fl_y, 50 / tan(0.25), 1e-9);
  ASSERT_NEAR(f->cam.fl_x, f->cam.fl_y, 0);
  fg_transforms_free(&t);
  free(path);

  /* a frame's camera_angle_x replaces a top-level fl_x (the frame is the more specific) */
  path = put("intr/t2.json",
             "{\"fl_x\": 999, \"w\": 200, \"h\": 100, \"frames\": [\n"
             " {\"file_path\": \"a.png\", \"transform_matrix\": " IDENTITY "},\n"
             " {\"file_path\": \"a.png\", \"transform_matrix\": " IDENTITY ","
             "  \"camera_angle_x\": 1.0}\n"
             "]}\n");
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_NEAR(t.frames[0].cam.fl_x, 999, 0);
  ASSERT_NEAR(t.frames[0].cam.fl_y, 999, 0);
  ASSERT_NEAR(t.frames[1].cam.fl_x, 100 / tan(0.5), 1e-9);
  ASSERT_NEAR(t.frames[1].cam.fl_y, 100 / tan(0.5), 1e-9);
  ASSERT_NEAR(t.frames[1].cam.cx, 100, 0);
  fg_transforms_free(&t);
  free(path);
}

/* ---------------------------------------------------------------- errors */

static void test_errors(void) {
  free(put("err/img.png", "png"));

  /* missing features file: names the frame */
  EXPECT_FAIL("err/feat.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "},\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY ","
              "  \"features_path\": \"feat/missing.npy\"}\n]}\n",
              FG_ENOENT, "frame 1", "feat/missing.npy");
  /* ...unless the frame's image is missing too: it will be skipped anyway */
  {
    char *path = put("err/feat2.json",
                     "{\"camera_angle_x\": 0.7, \"frames\": [\n"
                     " {\"file_path\": \"gone\", \"transform_matrix\": " IDENTITY ","
                     "  \"features_path\": \"feat/missing.npy\"}\n]}\n");
    fg_transforms t;
    ASSERT_OK(fg_transforms_load(path, &t));
    ASSERT_EQ(t.n_missing, 1);
    ASSERT(t.frames[0].features_path == NULL);
    fg_transforms_free(&t);
    free(path);
  }

  /* malformed JSON: line and column */
  EXPECT_FAIL("err/bad.json", "{\n  \"frames\": [\n    {\"file_path\": \"img\",,}\n  ]\n}\n",
              FG_EFORMAT, "line 3", "not valid JSON");
  EXPECT_FAIL("err/trunc.json", "{\"frames\": [", FG_EFORMAT, "line 1", "column");
  EXPECT_FAIL("err/empty.json", "", FG_EFORMAT, "not valid JSON", NULL);

  /* the matrix: shape, types */
  EXPECT_FAIL("err/m1.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "},\n"
              " {\"file_path\": \"img\", \"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}"
              "\n]}\n",
              FG_EFORMAT, "frame 1: transform_matrix has 3 rows", "4 rows of 4");
  EXPECT_FAIL("err/m2.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1],"
              "[0,0,0,1]]}\n]}\n",
              FG_EFORMAT, "frame 0: transform_matrix row 2 has 3 entries", NULL);
  EXPECT_FAIL("err/m3.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "},\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "},\n"
              " {\"file_path\": \"img\", \"transform_matrix\": [[1,0,0,0],[0,1,\"0\",0],[0,0,1,0],"
              "[0,0,0,1]]}\n]}\n",
              FG_EFORMAT, "frame 2: transform_matrix[1][2] is a string", "expected a number");
  EXPECT_FAIL("err/m4.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}"
              "\n]}\n",
              FG_EFORMAT, "frame 0: transform_matrix is a flat list of 16 numbers", NULL);
  EXPECT_FAIL("err/m5.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": \"identity\"}\n]}\n",
              FG_EFORMAT, "frame 0: transform_matrix must be 4 rows of 4 numbers, got a string",
              NULL);
  EXPECT_FAIL("err/m6.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n {\"file_path\": \"img\"}\n]}\n",
              FG_EFORMAT, "frame 0: transform_matrix is missing", NULL);
  EXPECT_FAIL("err/m7.json",
              "{\"camera_angle_x\": 0.7, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],"
              "[0,0,0,1e999]]}\n]}\n",
              FG_EFORMAT, "not valid JSON", NULL); /* jansson refuses the overflow itself */

  /* camera models */
  EXPECT_FAIL("err/c1.json",
              "{\"camera_model\": \"OPENCV_FISHEYE\", \"fl_x\": 5, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "OPENCV_FISHEYE", "PINHOLE and OPENCV");
  EXPECT_FAIL("err/c2.json",
              "{\"fl_x\": 5, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "},\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY ","
              "  \"camera_model\": \"EQUIRECTANGULAR\"}\n]}\n",
              FG_EFORMAT, "frame 1", "PINHOLE and OPENCV");
  EXPECT_FAIL("err/c3.json",
              "{\"fl_x\": 5, \"is_fisheye\": true, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "fisheye", "PINHOLE and OPENCV");
  EXPECT_FAIL("err/c4.json",
              "{\"fl_x\": 5, \"camera_model\": \"PINHOLE\", \"k1\": 0.3, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "frame 0: camera_model is PINHOLE", "OPENCV");
  EXPECT_FAIL("err/c5.json",
              "{\"fl_x\": 5, \"camera_model\": 3, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "top level: camera_model must be a string", NULL);

  /* intrinsics */
  EXPECT_FAIL("err/i1.json",
              "{\"w\": 10, \"h\": 10, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "frame 0: no focal length", "camera_angle_x");
  EXPECT_FAIL("err/i2.json",
              "{\"fl_x\": \"500\", \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "top level: fl_x must be a number, got a string", NULL);
  EXPECT_FAIL("err/i3.json",
              "{\"fl_x\": 500, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY ", \"w\": 640}\n]}\n",
              FG_EFORMAT, "frame 0: w is given without h", NULL);
  EXPECT_FAIL("err/i4.json",
              "{\"fl_x\": 500, \"w\": 640.5, \"h\": 480, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "top level: w must be a whole number", NULL);
  EXPECT_FAIL("err/i5.json",
              "{\"camera_angle_x\": 50, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY "}\n]}\n",
              FG_EFORMAT, "camera_angle_x must be a field of view in radians", NULL);
  EXPECT_FAIL("err/i6.json",
              "{\"fl_x\": 500, \"frames\": [\n"
              " {\"file_path\": \"img\", \"transform_matrix\": " IDENTITY ", \"fl_y\": -1}\n]}\n",
              FG_EFORMAT, "frame 0: fl_y must be positive", NULL);

  /* structure */
  EXPECT_FAIL("err/s1.json", "[1, 2]", FG_EFORMAT, "top level must be an object", NULL);
  EXPECT_FAIL("err/s2.json", "{\"fl_x\": 5}", FG_EFORMAT, "\"frames\" must be a non-empty array",
              "got nothing");
  EXPECT_FAIL("err/s3.json", "{\"fl_x\": 5, \"frames\": []}", FG_EFORMAT, "an empty array", NULL);
  EXPECT_FAIL("err/s4.json", "{\"fl_x\": 5, \"frames\": [3]}", FG_EFORMAT,
              "frame 0 must be an object", NULL);
  EXPECT_FAIL("err/s5.json",
              "{\"fl_x\": 5, \"frames\": [{\"transform_matrix\": " IDENTITY "}]}", FG_EFORMAT,
              "frame 0: file_path is missing", NULL);
  EXPECT_FAIL("err/s6.json",
              "{\"fl_x\": 5, \"frames\": [{\"file_path\": 7, \"transform_matrix\": " IDENTITY
              "}]}",
              FG_EFORMAT, "frame 0: file_path must be a non-empty path string, got a number",
              NULL);

  /* no such file */
  char *missing = path_in_root("err/none.json");
  fg_transforms t;
  ASSERT_ERR(fg_transforms_load(missing, &t), FG_ENOENT, "cannot open");
  free(missing);
  ASSERT_ERR(fg_transforms_load(root, &t), FG_EINVAL, "not a file");
  ASSERT_ERR(fg_transforms_load(NULL, &t), FG_EINVAL, "no transforms file");
}

/* ---------------------------------------------------------------- the real lego data set */

static void test_real_lego(void) {
  const char *shared = getenv("FG_SHARED_DATA");
  if (!shared || !shared[0]) {
    printf("transforms: FG_SHARED_DATA not set; real lego data set not checked\n");
    return;
  }
  char path[PATH_MAX];
  snprintf(path, sizeof path, "%s/lego/transforms_train.json", shared);
  struct stat sb;
  if (stat(path, &sb) != 0)
    FG_TEST_FAIL("FG_SHARED_DATA is %s but %s is missing; the lego data set must be there",
                 shared, path);
  fg_transforms t;
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_EQ(t.n_frames, 100);
  ASSERT_EQ(t.n_missing, 0);
  for (size_t i = 0; i < t.n_frames; i++) {
    ASSERT(t.frames[i].image_path != NULL);
    ASSERT_EQ(t.frames[i].has_size, 0);
    ASSERT_OK(fg_transforms_complete_camera(&t.frames[i], 800, 800));
    ASSERT_NEAR(t.frames[i].cam.fl_x, 1111.11, 0.01);
    ASSERT_NEAR(t.frames[i].cam.fl_y, 1111.11, 0.01);
    ASSERT_NEAR(t.frames[i].T_world_cam[15], 1, 0);
  }
  ASSERT_STREQ(t.frames[0].file_path, "./train/r_0");
  ASSERT(strstr(t.frames[0].image_path, "train/r_0.png") != NULL);
  fg_transforms_free(&t);
}

/* nerfstudio's depth keys: depth_file_path resolved like file_path, depth_unit_scale_factor
 * from the top level or the frame; a missing depth file is counted, not an error. */
static void test_depth_keys(void) {
  free(put("dp/images/a.png", "png"));
  free(put("dp/images/b.png", "png"));
  free(put("dp/images/c.png", "png"));
  free(put("dp/depth/a.png", "png"));
  free(put("dp/depth/b.npy", "npy"));
  char *path = put("dp/transforms.json",
                   "{\"fl_x\": 500, \"depth_unit_scale_factor\": 0.0001, \"frames\": [\n"
                   "  {\"file_path\": \"images/a.png\", \"transform_matrix\": " IDENTITY
                   ", \"depth_file_path\": \"depth/a.png\"},\n"
                   "  {\"file_path\": \"images/b.png\", \"transform_matrix\": " IDENTITY
                   ", \"depth_file_path\": \"depth/b\", \"depth_unit_scale_factor\": 0.001},\n"
                   "  {\"file_path\": \"images/c.png\", \"transform_matrix\": " IDENTITY
                   ", \"depth_file_path\": \"depth/c.png\"},\n"
                   "  {\"file_path\": \"images/d.png\", \"transform_matrix\": " IDENTITY
                   ", \"depth_file_path\": \"depth/d.png\"}\n"
                   "]}\n");
  fg_transforms t;
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_EQ(t.n_frames, 4);
  ASSERT_EQ(t.n_missing, 1);       /* d: no image */
  ASSERT_EQ(t.n_depth_missing, 1); /* c: image but no depth file */
  ASSERT(strstr(t.frames[0].depth_path, "dp/depth/a.png"));
  ASSERT(strstr(t.frames[1].depth_path, "dp/depth/b.npy"));
  ASSERT(t.frames[2].depth_path == NULL && t.frames[2].depth_missing);
  ASSERT_NEAR(t.frames[0].depth_scale, 0.0001, 0);
  ASSERT_NEAR(t.frames[1].depth_scale, 0.001, 0);
  fg_transforms_free(&t);
  free(path);
  /* without the key: millimetres */
  path = put("dp/t2.json", "{\"fl_x\": 500, \"frames\": [{\"file_path\": \"images/a.png\", "
             "\"transform_matrix\": " IDENTITY ", \"depth_file_path\": \"depth/a.png\"}]}");
  ASSERT_OK(fg_transforms_load(path, &t));
  ASSERT_NEAR(t.frames[0].depth_scale, 0.001, 0);
  ASSERT(t.frames[0].depth_path && !t.frames[0].depth_missing);
  fg_transforms_free(&t);
  free(path);
  EXPECT_FAIL("dp/t3.json", "{\"fl_x\": 500, \"depth_unit_scale_factor\": 0, \"frames\": "
              "[{\"file_path\": \"images/a.png\", \"transform_matrix\": " IDENTITY "}]}",
              FG_EFORMAT, "top level", "depth_unit_scale_factor must be > 0");
  EXPECT_FAIL("dp/t4.json", "{\"fl_x\": 500, \"frames\": [{\"file_path\": \"images/a.png\", "
              "\"transform_matrix\": " IDENTITY ", \"depth_unit_scale_factor\": -1}]}",
              FG_EFORMAT, "frame 0", "depth_unit_scale_factor");
  EXPECT_FAIL("dp/t5.json", "{\"fl_x\": 500, \"frames\": [{\"file_path\": \"images/a.png\", "
              "\"transform_matrix\": " IDENTITY ", \"depth_file_path\": 3}]}",
              FG_EFORMAT, "frame 0", "depth_file_path must be a non-empty path");
}

int main(void) {
  char tmpl[] = "/tmp/fg_test_transforms.XXXXXX";
  ASSERT(mkdtemp(tmpl) != NULL);
  ASSERT(realpath(tmpl, root) != NULL);

  test_lego_style();
  test_nerfstudio_style();
  test_intrinsics();
  test_errors();
  test_depth_keys();
  test_real_lego();

  char cmd[PATH_MAX + 16];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", root);
  ASSERT_EQ(system(cmd), 0);
  printf("transforms: ok\n");
  return 0;
}
