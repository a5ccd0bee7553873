/* See grasp_util.h. */
#include "grasp_util.h"

#include <math.h>

static json_t *g_gt_json;
static char *g_data;

char *g_dataset(const char *scenegen) {
  char *imports = h_fmt("%s/imports", h_tmpdir());
  char *dir = h_fmt("%s/sg", imports);
  t_scenegen(scenegen, dir, G_VIEWS, G_W, G_H, G_DIM, G_PATCH);
  g_dataset_at(dir);
  free(dir);
  return imports;
}

void g_dataset_at(const char *dir) {
  free(g_data);
  g_data = h_fmt("%s", dir);
  char *path = h_fmt("%s/gt.json", g_data);
  json_error_t e;
  json_decref(g_gt_json);
  g_gt_json = json_load_file(path, 0, &e);
  ASSERT(g_gt_json != NULL);
  free(path);
}

json_t *g_gt(void) { return g_gt_json; }
const char *g_dir(void) { return g_data; }

void g_config(const char *imports, const char *extra) {
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = 2\nsteps = 20\n\n%s\n",
                     imports, extra ? extra : "");
  h_write_config(conf);
  free(conf);
}

void g_scene(const char *name, const char *tf) { g_scene_at(name, tf, 0.02); }

void g_scene_at(const char *name, const char *tf, double voxel) {
  char *body = h_fmt("{\"name\": \"%s\", \"workspace\": {\"min\": [0.1, -0.45, -0.05], "
                     "\"max\": [0.8, 0.45, 0.35]}, \"voxel_size\": %g}", name, voxel);
  h_resp *r = h_post_json("/v1/scenes", body);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(body);
  r = g_import(name, tf);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), G_VIEWS);
  h_resp_free(r);
}

h_resp *g_import(const char *scene, const char *tf) {
  char *path = h_fmt("/v1/scenes/%s/import", scene);
  char *body = tf ? h_fmt("{\"path\": \"%s\", \"transforms\": \"%s\"}", g_data, tf)
                  : h_fmt("{\"path\": \"%s\"}", g_data);
  h_resp *r = h_post_json(path, body);
  free(body);
  free(path);
  return r;
}

void g_train(const char *scene, int steps) {
  char *body = h_fmt("{\"steps\": %d}", steps);
  t_train_done(scene, body, 600);
  free(body);
}

char *g_class_embedding(const char *name) {
  json_t *classes = JGET(g_gt_json, "classes");
  for (size_t i = 0; i < json_array_size(classes); i++) {
    json_t *c = json_array_get(classes, i);
    if (strcmp(JSTR(c, "name"), name) == 0) return json_dumps(JGET(c, "embedding"), JSON_COMPACT);
  }
  FG_TEST_FAIL("no class %s in gt.json", name);
}

json_t *g_object(const char *name) {
  json_t *objects = JGET(g_gt_json, "objects");
  for (size_t i = 0; i < json_array_size(objects); i++) {
    json_t *o = json_array_get(objects, i);
    if (strcmp(JSTR(o, "name"), name) == 0) return o;
  }
  FG_TEST_FAIL("no object %s in gt.json", name);
}

char *g_demo_body(const char *scene, const char *object, const char *extra) {
  char qp[32];
  snprintf(qp, sizeof qp, "{\"n\": %d}", G_NQ);
  return g_demo_body_qp(scene, object, qp, extra);
}

char *g_demo_body_qp(const char *scene, const char *object, const char *qp, const char *extra) {
  json_t *g = JGET(g_object(object), "grasp");
  char *p = json_dumps(JGET(g, "position"), JSON_COMPACT | JSON_REAL_PRECISION(17));
  char *q = json_dumps(JGET(g, "quaternion"), JSON_COMPACT | JSON_REAL_PRECISION(17));
  double w = JNUM(g, "width") + 0.01;
  if (w > 0.08) w = 0.08; /* within the stroke of either gripper the tests configure */
  char *s = h_fmt("{\"scene\": \"%s\", \"pose\": {\"position\": %s, \"quaternion\": %s}, "
                  "\"width\": %.4f%s%s%s%s}", scene, p, q, w, qp ? ", \"query_points\": " : "",
                  qp ? qp : "", extra[0] ? ", " : "", extra);
  free(p);
  free(q);
  return s;
}

char *g_demo_body_open(const char *scene, const char *object) {
  json_t *g = JGET(g_object(object), "grasp");
  json_t *o = json_pack("{s:s, s:{s:O, s:O}, s:f}", "scene", scene, "pose", "position",
                        JGET(g, "position"), "quaternion", JGET(g, "quaternion"), "width", 0.085);
  char *s = o ? json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(17)) : NULL;
  json_decref(o);
  if (!s) FG_TEST_FAIL("out of memory");
  return s;
}

double g_grasp_error(json_t *grasp, const char *object) {
  double d2 = 0;
  for (int k = 0; k < 3; k++) {
    const char idx[2] = {(char)('0' + k), 0};
    d2 += pow(JNUM(JGET(grasp, "pose.position"), idx) -
                  JNUM(JGET(g_object(object), "grasp.position"), idx), 2);
  }
  return sqrt(d2);
}

h_resp *g_post(const char *path, const char *body) { return h_post_json(path, body); }
