/* A scene's field settings (field_scale, learn_background): created with a scene, changed by
 * PATCH /v1/scenes/{s} (one key keeps the other; other keys, bad values, a declared scene and
 * a missing one refused, the settings then as they were), set by a [scene NAME] section, kept
 * across a restart; "auto" chosen from the frames by each training (a tabletop cell's cameras:
 * scale 2 and no learned background, by the cameras without depth and by the depth hits
 * with it; cameras far beyond a small workspace: a larger cube and a learned background), the
 * settings taken as given when not auto, an update keeping its field's (409 field_mismatch
 * for a setting that differs), and what chose them in the training's job.
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <math.h>

#include "training.h"

#define VIEWS 8
#define STEPS "{\"steps\": 3}"

static json_t *patch(const char *scene, const char *body) {
  char *path = h_fmt("/v1/scenes/%s", scene);
  h_req q = {.method = "PATCH", .path = path, .body = body, .body_len = strlen(body)};
  h_resp *r = h_request(&q);
  ASSERT_STATUS(r, 200);
  json_t *o = json_incref(RJSON(r));
  h_resp_free(r);
  free(path);
  return o;
}

/* The scene's settings are scale (0: "auto") and learn_bg (-1: "auto"). */
static void assert_settings(json_t *scene, double scale, int learn_bg) {
  json_t *s = JGET(scene, "field_scale"), *b = JGET(scene, "learn_background");
  if (scale == 0) ASSERT_STREQ(json_string_value(s), "auto");
  else ASSERT(json_is_number(s) && json_number_value(s) == scale);
  if (learn_bg < 0) ASSERT_STREQ(json_string_value(b), "auto");
  else ASSERT(json_is_boolean(b) && json_is_true(b) == learn_bg);
}

static void assert_scene_settings(const char *scene, double scale, int learn_bg) {
  json_t *s = t_scene_json(scene);
  assert_settings(s, scale, learn_bg);
  json_decref(s);
}

/* Trains scene (init "random" or "current") and asserts what its job and the scene say of the
 * field: its scale, learned background and what chose them. */
static void train_expect(const char *scene, const char *init, double scale, int learn_bg,
                         const char *chosen_by) {
  char *body = h_fmt("{\"steps\": 3, \"init\": \"%s\"}", init);
  char *id = t_train(scene, body);
  json_t *job = t_wait_job(id, "done", 600);
  printf("%s (%s): field scale %g, learn_background %d, chosen by %s\n", scene, init,
         JNUM(job, "field.scale"), json_is_true(JGET(job, "field.learn_background")),
         JSTR(job, "field.chosen_by"));
  ASSERT(fabs(JNUM(job, "field.scale") - scale) < 1e-9);
  ASSERT_EQ(json_is_true(JGET(job, "field.learn_background")), learn_bg);
  ASSERT_STREQ(JSTR(job, "field.chosen_by"), chosen_by);
  json_t *s = t_scene_json(scene);
  ASSERT(fabs(JNUM(s, "field.scale") - scale) < 1e-9);
  ASSERT_EQ(json_is_true(JGET(s, "field.learn_background")), learn_bg);
  json_decref(s);
  json_decref(job);
  free(id);
  free(body);
}

static void import_into(const char *scene, const char *dir) {
  char *path = h_fmt("/v1/scenes/%s/import", scene), *body = h_fmt("{\"path\": \"%s\"}", dir);
  h_resp *r = h_post_json(path, body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), VIEWS);
  h_resp_free(r);
  free(body);
  free(path);
}

static void test_create_and_patch(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"plain\"}");
  ASSERT_STATUS(r, 201);
  assert_settings(RJSON(r), 0, -1);
  ASSERT(json_is_null(JGET(r->json, "field")));
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"set\", \"field_scale\": 4, "
                  "\"learn_background\": true}");
  ASSERT_STATUS(r, 201);
  assert_settings(RJSON(r), 4, 1);
  h_resp_free(r);

  /* bad values create nothing */
  static const char *const bad_create[] = {
    "{\"name\": \"b\", \"field_scale\": 0.5}", "{\"name\": \"b\", \"field_scale\": 65}",
    "{\"name\": \"b\", \"field_scale\": \"big\"}", "{\"name\": \"b\", \"field_scale\": [2]}",
    "{\"name\": \"b\", \"learn_background\": \"yes\"}",
    "{\"name\": \"b\", \"learn_background\": 1}"};
  for (size_t i = 0; i < sizeof bad_create / sizeof *bad_create; i++)
    EXPECT_ERROR("POST", "/v1/scenes", bad_create[i], 400, "invalid_request");
  EXPECT_ERROR("GET", "/v1/scenes/b", NULL, 404, "scene_not_found");

  /* PATCH: one key keeps the other */
  json_decref(patch("plain", "{\"field_scale\": 8}"));
  assert_scene_settings("plain", 8, -1);
  json_t *s = patch("plain", "{\"learn_background\": false}");
  assert_settings(s, 8, 0);
  json_decref(s);
  json_decref(patch("plain", "{}"));
  assert_scene_settings("plain", 8, 0);
  s = patch("plain", "{\"field_scale\": \"auto\", \"learn_background\": \"auto\"}");
  assert_settings(s, 0, -1);
  json_decref(s);
  json_decref(patch("plain", "{\"field_scale\": 2.5, \"learn_background\": null}"));
  assert_scene_settings("plain", 2.5, -1);

  /* refused, and the settings as they were */
  static const char *const bad_patch[] = {
    "{\"field_scale\": 0}", "{\"field_scale\": 1e9}", "{\"learn_background\": \"on\"}",
    "{\"workspace\": {\"min\": [0, 0, 0], \"max\": [1, 1, 1]}}", "{\"voxel_size\": 0.02}",
    "{\"field_scale\": 4, \"background\": [0, 0, 0]}", "[]"};
  for (size_t i = 0; i < sizeof bad_patch / sizeof *bad_patch; i++)
    EXPECT_ERROR("PATCH", "/v1/scenes/plain", bad_patch[i], 400, "invalid_request");
  EXPECT_ERROR("PATCH", "/v1/scenes/plain", "not json", 400, "malformed_json");
  assert_scene_settings("plain", 2.5, -1);
  EXPECT_ERROR("PATCH", "/v1/scenes/nope", "{\"field_scale\": 4}", 404, "scene_not_found");
  EXPECT_ERROR("PATCH", "/v1/scenes/decl", "{\"field_scale\": 8}", 409, "declared_in_config");
  assert_scene_settings("decl", 4, 1); /* the configuration's */
}

/* scenegen's cameras stand 0.9 m from (0.45, 0, 0.05), inside the cube of scale 2 over its
 * tabletop workspace: the cell's field. Over a 10 cm workspace at the same spot they are
 * 8.5 workspaces away: the cube of 32 (the smallest power of two whose cube holds them:
 * 2 x 0.85 / 0.1 = 17 would not), with a learned background. */
static void test_auto(const char *colour, const char *rgbd) {
  t_scene_from_dataset("cell", colour, VIEWS);
  train_expect("cell", "random", 2, 0, "cameras");
  t_scene_from_dataset("rgbd", rgbd, VIEWS);
  train_expect("rgbd", "random", 2, 0, "depth");

  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"small\", \"workspace\": {\"min\": "
                          "[0.40, -0.05, 0.0], \"max\": [0.50, 0.05, 0.10]}, "
                          "\"voxel_size\": 0.01}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  import_into("small", colour);
  train_expect("small", "random", 32, 1, "cameras");
  json_t *s = t_scene_json("small");
  ASSERT(fabs(JNUM(s, "field.box_size") - 3.2) < 1e-9);
  ASSERT(fabs(JNUM(s, "field.box_min.0") - (0.45 - 1.6)) < 1e-9);
  json_decref(s);

  /* settings given: taken as they are */
  json_decref(patch("small", "{\"field_scale\": 4, \"learn_background\": false}"));
  train_expect("small", "random", 4, 0, "settings");
  /* an update on auto keeps its field's; a setting that differs is refused before it runs */
  json_decref(patch("small", "{\"field_scale\": \"auto\", \"learn_background\": \"auto\"}"));
  train_expect("small", "current", 4, 0, "current field");
  json_decref(patch("small", "{\"field_scale\": 8}"));
  EXPECT_ERROR("POST", "/v1/scenes/small/train", "{\"steps\": 3, \"init\": \"current\"}", 409,
               "field_mismatch");
  json_decref(patch("small", "{\"field_scale\": \"auto\", \"learn_background\": true}"));
  EXPECT_ERROR("POST", "/v1/scenes/small/train", "{\"steps\": 3, \"init\": \"current\"}", 409,
               "field_mismatch");
  s = t_scene_json("small"); /* the field is the one trained before */
  ASSERT(fabs(JNUM(s, "field.scale") - 4) < 1e-9);
  ASSERT(json_is_false(JGET(s, "field.learn_background")));
  json_decref(s);
}

static void test_restart(void) {
  json_t *small = t_scene_json("small"), *plain = t_scene_json("plain");
  h_stop();
  h_start();
  json_t *small2 = t_scene_json("small"), *plain2 = t_scene_json("plain");
  assert_settings(small2, 0, 1);
  assert_settings(plain2, 2.5, -1);
  ASSERT_JSON_EQUAL(JGET(small, "field"), JGET(small2, "field"));
  ASSERT_JSON_EQUAL(JGET(plain, "field"), JGET(plain2, "field"));
  /* the last job keeps what chose its field */
  char *path = h_fmt("/v1/jobs/%s", JSTR(small2, "last_job.id"));
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(JSTR(r->json, "field.chosen_by"), "current field");
  h_resp_free(r);
  free(path);
  json_decref(small);
  json_decref(plain);
  json_decref(small2);
  json_decref(plain2);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  char *imports = h_fmt("%s/imports", h_tmpdir());
  char *colour = h_fmt("%s/sg", imports), *rgbd = h_fmt("%s/sgd", imports);
  t_scenegen(argv[2], colour, VIEWS, 32, 24, 8, 0);
  t_scenegen_depth(argv[2], rgbd, VIEWS, 32, 24, 8, 0, "png");
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = 2\nsteps = 20\n\n"
                     "[scene decl]\nfield_scale = 4\nlearn_background = true\n", imports);
  h_write_config(conf);
  h_start();
  test_create_and_patch();
  test_auto(colour, rgbd);
  test_restart();
  h_stop();
  free(conf);
  free(rgbd);
  free(colour);
  free(imports);
  h_done();
  printf("field_settings: ok\n");
  return 0;
}
