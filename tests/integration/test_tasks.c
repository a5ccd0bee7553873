/* The demonstration library over HTTP (GET/DELETE /v1/tasks..., POST /v1/tasks/{t}/demos) on
 * a trained scenegen tabletop:
 *   - every bad demo answers its JSON error and stores nothing (no task, no file);
 *   - demos create tasks, fix their query points (by default the box between the pads of
 *     the configured gripper, the Gaussian when asked for), kind and D, list, read and
 *     delete;
 *   - demo files are float32 [N_q, D] .npy files beside task.json;
 *   - tasks survive a clean restart and a kill -9, and a demo survives its scene;
 *   - a task.json written before the box layout (a Gaussian without "layout") loads and
 *     takes demos at its own query points;
 *   - a task folder that does not load is logged and skipped, and its name refused.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include "grasp_util.h"
#include "trained.h"

#include "core/error.h"
#include "grasp/grasp.h"
#include "io/npy.h"

#include <sys/stat.h>

static int tasks_on_disk(void) {
  char *dir = h_fmt("%s/tasks", h_state_dir());
  int n = h_count_files(dir, ".json") + h_count_files(dir, ".npy");
  free(dir);
  return n;
}

static void expect_nothing_stored(void) {
  h_resp *r = h_get("/v1/tasks");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "tasks")), 0);
  h_resp_free(r);
  ASSERT_EQ(tasks_on_disk(), 0);
}

static void expect_demo_error(const char *task, const char *body, long status, const char *code) {
  char *path = h_fmt("/v1/tasks/%s/demos", task);
  h_resp *r = g_post(path, body);
  if (r->status != status) fprintf(stderr, "demo %s -> %s\n", body, r->body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
  free(path);
}

/* A demo that must be refused with code, before anything is stored. */
static void refused(const char *body, long status, const char *code) {
  expect_demo_error("t1", body, status, code);
  expect_nothing_stored();
}

static h_resp *add_demo(const char *task, const char *body) {
  char *path = h_fmt("/v1/tasks/%s/demos", task);
  h_resp *r = g_post(path, body);
  if (r->status != 201) fprintf(stderr, "demo -> %s\n", r->body);
  ASSERT_STATUS(r, 201);
  char *loc = h_fmt("/v1/tasks/%s", task);
  ASSERT_STREQ(h_resp_header(r, "Location"), loc);
  free(loc);
  free(path);
  return r;
}

static json_t *task_get(const char *name) {
  char *path = h_fmt("/v1/tasks/%s", name);
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  json_t *j = json_incref(RJSON(r));
  h_resp_free(r);
  free(path);
  return j;
}

static void check_npy(const char *task, int id, int exists) {
  char *path = h_fmt("%s/tasks/%s/demo-%d.npy", h_state_dir(), task, id);
  size_t len = 0;
  char *buf = h_read_file(path, &len);
  if (!exists) {
    ASSERT(buf == NULL);
    free(path);
    return;
  }
  ASSERT(buf != NULL);
  fg_npy npy;
  ASSERT_OK(fg_npy_parse(buf, len, &npy));
  ASSERT_EQ(npy.dtype, FG_DTYPE_F32);
  ASSERT_EQ(npy.ndim, 2);
  ASSERT_EQ(npy.shape[0], G_NQ);
  ASSERT_EQ(npy.shape[1], G_DIM);
  double s = 0;
  const float *z = npy.data;
  for (size_t i = 0; i < npy.count; i++) s += fabs(z[i]);
  ASSERT(s > 0); /* the ground-truth grasp holds the object between its query points */
  free(buf);
  free(path);
}

static void bad_inputs(void) {
  char *good = g_demo_body("sg", "ball", "");
  json_error_t e;
  json_t *gj = json_loads(good, 0, &e);
  char *pos = json_dumps(JGET(gj, "pose.position"), JSON_COMPACT | JSON_REAL_PRECISION(17));
  json_decref(gj);
  refused("{\"scene\": ", 400, "malformed_json");
  refused("[1, 2]", 400, "invalid_request");
  refused("{\"scene\": \"sg\", \"pose\": {\"position\": [0.4, 0, 0.05], \"quaternion\": [0, 1, 0, "
          "0]}, \"colour\": 1}", 400, "invalid_request");
  refused("{\"pose\": {\"position\": [0.4, 0, 0.05], \"quaternion\": [0, 1, 0, 0]}}", 400,
          "invalid_request");
  refused("{\"scene\": \"sg\"}", 400, "invalid_pose");
  refused("{\"scene\": \"nope\", \"pose\": {\"position\": [0.4, 0, 0.05], \"quaternion\": [0, 1, "
          "0, 0]}}", 404, "scene_not_found");
  /* |q| off by more than 1e-3; a matrix that is not a rotation; a pose outside the workspace */
  char *b = h_fmt("{\"scene\": \"sg\", \"pose\": {\"position\": %s, \"quaternion\": [0, 1.01, 0, "
                  "0]}}", pos);
  refused(b, 400, "invalid_pose");
  free(b);
  refused("{\"scene\": \"sg\", \"pose\": {\"matrix\": [[1, 0, 0, 0.4], [0, 2, 0, 0], [0, 0, 1, "
          "0.05], [0, 0, 0, 1]]}}", 400, "invalid_pose");
  refused("{\"scene\": \"sg\", \"pose\": {\"position\": [2, 0, 0.05], \"quaternion\": [0, 1, 0, "
          "0]}}", 400, "pose_outside_workspace");
  /* query points */
  static const char *const qps[] = {"{\"n\": 0}", "{\"n\": -3}", "{\"n\": 1001}",
                                    "{\"std\": 0}", "{\"std\": -0.01}", "{\"std\": \"wide\"}",
                                    "{\"n\": 2.5}", "{\"mean\": [0, 0]}", "{\"spread\": 1}",
                                    "7", "{\"layout\": \"cone\"}", "{\"layout\": 1}",
                                    "{\"std\": 0.01, \"size\": [0.02, 0.05, 0.02]}",
                                    "{\"layout\": \"box\", \"std\": 0.01}",
                                    "{\"layout\": \"gaussian\", \"size\": [0.02, 0.05, 0.02]}",
                                    "{\"size\": [0.02, 0, 0.02]}", "{\"size\": [0.02, 0.05]}",
                                    "{\"size\": [0.02, 2, 0.02]}"};
  for (size_t i = 0; i < sizeof qps / sizeof qps[0]; i++) {
    b = h_fmt("{\"scene\": \"sg\", \"pose\": {\"position\": %s, \"quaternion\": [0, 1, 0, 0]}, "
              "\"query_points\": %s}", pos, qps[i]);
    refused(b, 400, "invalid_query_points");
    free(b);
  }
  /* std = 1e999 is not finite: jansson refuses the number itself */
  b = h_fmt("{\"scene\": \"sg\", \"pose\": {\"position\": %s, \"quaternion\": [0, 1, 0, 0]}, "
            "\"query_points\": {\"std\": 1e999}}", pos);
  refused(b, 400, "malformed_json");
  free(b);
  static const char *const others[] = {"\"kind\": \"throw\"", "\"width\": 0",
                                       "\"width\": 0.5", "\"width\": \"wide\"",
                                       "\"approach\": -0.1"};
  for (size_t i = 0; i < sizeof others / sizeof others[0]; i++) {
    b = h_fmt("{\"scene\": \"sg\", \"pose\": {\"position\": %s, \"quaternion\": [0, 1, 0, 0]}, "
              "%s}", pos, others[i]);
    refused(b, 400, "invalid_request");
    free(b);
  }
  expect_demo_error(".hidden", good, 400, "invalid_name");
  expect_demo_error("a%20b", good, 400, "invalid_name");
  expect_nothing_stored();
  /* untrained, trained without features */
  b = g_demo_body("raw", "ball", "");
  refused(b, 409, "not_trained");
  free(b);
  b = g_demo_body("nofeat", "ball", "");
  refused(b, 409, "no_features");
  free(b);
  /* a pose whose query points all lie outside the field (half a metre above the workspace) */
  b = h_fmt("{\"scene\": \"sg\", \"pose\": {\"position\": [0.45, 0, 0.3], \"quaternion\": "
            "[1, 0, 0, 0]}, \"query_points\": {\"mean\": [0, 0, 0.5]}}");
  refused(b, 400, "demo_in_free_space");
  free(b);
  free(pos);
  free(good);
}

/* A task written before the box layout: ball's demo 1 under a task.json whose query points
 * are {"n", "std", "mean"} without "layout". It loads as the Gaussian it was, and a demo
 * without query points joins it at those points. Deleted again at the end. */
static void legacy_task(const char *ball) {
  char *src = h_fmt("%s/tasks/ball", h_state_dir());
  char *dir = h_fmt("%s/tasks/legacy", h_state_dir());
  char *src_json = h_fmt("%s/task.json", src), *src_npy = h_fmt("%s/demo-1.npy", src);
  json_error_t e;
  json_t *tj = json_load_file(src_json, 0, &e);
  ASSERT(tj);
  json_t *demos = JGET(tj, "demos");
  while (json_array_size(demos) > 1) json_array_remove(demos, 1);
  json_object_set_new(tj, "name", json_string("legacy"));
  json_object_set_new(tj, "next_id", json_integer(2));
  json_object_set_new(tj, "query_points", json_pack("{s:i, s:f, s:[f, f, f]}", "n", G_NQ, "std",
                                                    0.012, "mean", 0.0, 0.0, 0.0));
  h_mkdirs(dir);
  char *dst_json = h_fmt("%s/task.json", dir), *dst_npy = h_fmt("%s/demo-1.npy", dir);
  ASSERT_EQ(json_dump_file(tj, dst_json, 0), 0);
  json_decref(tj);
  size_t len = 0;
  char *npy = h_read_file(src_npy, &len);
  ASSERT(npy);
  h_write_file(dst_npy, npy, len);
  free(npy);
  h_stop();
  h_start();
  json_t *t = task_get("legacy");
  ASSERT_EQ(JINT(t, "n_demos"), 1);
  ASSERT_STREQ(JSTR(t, "query_points.layout"), "gaussian");
  ASSERT_NEAR(JNUM(t, "query_points.std"), 0.012, 1e-12);
  json_decref(t);
  h_resp *r = add_demo("legacy", ball);
  ASSERT_EQ(JINT(r->json, "demo.id"), 2);
  ASSERT_STREQ(JSTR(r->json, "task.query_points.layout"), "gaussian");
  ASSERT_NEAR(JNUM(r->json, "task.query_points.std"), 0.012, 1e-12);
  h_resp_free(r);
  r = h_delete("/v1/tasks/legacy");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  free(src);
  free(dir);
  free(src_json);
  free(src_npy);
  free(dst_json);
  free(dst_npy);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  double t0 = t_now();
  char *imports = f_dataset(argv[2]); /* with transforms_nofeat.json, for colour only */
  g_config(imports, NULL);
  f_scene("t60", "sg");        /* trained {"steps": 60} at 2 cm */
  f_scene("raw", "raw");       /* untrained */
  f_scene("nofeat", "nofeat"); /* trained {"steps": 2} without features */
  h_start();

  /* Untrained: 409, nothing stored. */
  char *ball = g_demo_body("sg", "ball", "");
  char *raw_ball = g_demo_body("raw", "ball", "");
  expect_demo_error("t1", raw_ball, 409, "not_trained");
  free(raw_ball);
  expect_nothing_stored();
  h_resp *r = h_get("/v1/tasks/t1");
  ASSERT_HTTP_ERROR(r, 404, "task_not_found");
  h_resp_free(r);

  double t_ready = t_now();
  bad_inputs();

  /* The first demo creates the task and fixes its query points, kind and D. */
  r = add_demo("ball", ball);
  ASSERT_EQ(JINT(r->json, "demo.id"), 1);
  ASSERT_STREQ(JSTR(r->json, "demo.scene"), "sg");
  ASSERT_STREQ(JSTR(r->json, "demo.kind"), "grasp");
  ASSERT_STREQ(JSTR(r->json, "task.name"), "ball");
  ASSERT_EQ(JINT(r->json, "task.dim"), G_DIM);
  ASSERT_EQ(JINT(r->json, "task.n_demos"), 1);
  ASSERT_EQ(JINT(r->json, "task.query_points.n"), G_NQ);
  { /* by default the box the fingers close on: the pads of the panda at the demo's width */
    double mean[3], size[3];
    ASSERT_OK(fg_grasp_query_box_default(FG_GRIPPER_PANDA, JNUM(r->json, "demo.width"), mean,
                                         size));
    ASSERT_STREQ(JSTR(r->json, "task.query_points.layout"), "box");
    ASSERT_VEC(JGET(r->json, "task.query_points.size"), size, 3, 1e-12);
    ASSERT_VEC(JGET(r->json, "task.query_points.mean"), mean, 3, 1e-12);
    ASSERT(json_object_get(JGET(r->json, "task.query_points"), "std") == NULL);
  }
  ASSERT_NEAR(JNUM(r->json, "task.approach"), 0.10, 1e-12);
  /* the pose comes back as given (quaternion, position) and as a matrix */
  json_t *g = JGET(g_object("ball"), "grasp");
  ASSERT_VEC(JGET(r->json, "demo.pose.position"), ((double[]){JNUM(g, "position.0"),
             JNUM(g, "position.1"), JNUM(g, "position.2")}), 3, 1e-9);
  ASSERT_EQ(json_array_size(JGET(r->json, "demo.pose.matrix")), 4);
  h_resp_free(r);
  /* a second demo without query_points takes the task's; a third with a wider approach */
  char *ball2 = g_demo_body_qp("sg", "ball", NULL, "\"approach\": 0.2");
  r = add_demo("ball", ball2);
  ASSERT_EQ(JINT(r->json, "demo.id"), 2);
  ASSERT_NEAR(JNUM(r->json, "task.approach"), 0.15, 1e-12); /* the mean of the demos' */
  h_resp_free(r);
  free(ball2);
  /* other query points, another kind, too many points: 409 / 400, nothing changes */
  char *b = g_demo_body("sg", "ball", "\"kind\": \"place\"");
  expect_demo_error("ball", b, 409, "kind_mismatch");
  free(b);
  b = h_fmt("{\"scene\": \"sg\", \"pose\": {\"position\": [0.45, 0, 0.05], \"quaternion\": [0, 1, "
            "0, 0]}, \"query_points\": {\"n\": 40}}");
  expect_demo_error("ball", b, 409, "query_points_mismatch");
  free(b);
  b = g_demo_body_qp("sg", "ball", "{\"n\": 32, \"std\": 0.01}", "");
  expect_demo_error("ball", b, 409, "query_points_mismatch");
  free(b);
  json_t *tb = task_get("ball");
  ASSERT_EQ(JINT(tb, "n_demos"), 2);
  ASSERT_EQ(json_array_size(JGET(tb, "demos")), 2);
  json_decref(tb);
  char *box = g_demo_body("sg", "box", "");
  r = add_demo("box", box);
  h_resp_free(r);
  /* the Gaussian, asked for: F3RM's, with the former default std */
  char *place = g_demo_body_qp("sg", "mug", "{\"n\": 32, \"layout\": \"gaussian\"}",
                               "\"kind\": \"place\"");
  r = add_demo("mug_place", place);
  ASSERT_STREQ(JSTR(r->json, "task.kind"), "place");
  ASSERT_STREQ(JSTR(r->json, "task.query_points.layout"), "gaussian");
  ASSERT_NEAR(JNUM(r->json, "task.query_points.std"), FG_GRASP_DEFAULT_STD_M, 1e-12);
  ASSERT_VEC(JGET(r->json, "task.query_points.mean"), ((double[]){0, 0, 0}), 3, 0.0);
  h_resp_free(r);

  /* List (by name), read, files. */
  r = h_get("/v1/tasks");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "tasks")), 3);
  ASSERT_STREQ(JSTR(r->json, "tasks.0.name"), "ball");
  ASSERT_STREQ(JSTR(r->json, "tasks.1.name"), "box");
  ASSERT_STREQ(JSTR(r->json, "tasks.2.name"), "mug_place");
  ASSERT_EQ(JINT(r->json, "tasks.0.n_demos"), 2);
  h_resp_free(r);
  check_npy("ball", 1, 1);
  check_npy("ball", 2, 1);

  /* Delete a demo; unknown ones and tasks are 404. */
  r = h_delete("/v1/tasks/ball/demos/2");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "task.n_demos"), 1);
  ASSERT_NEAR(JNUM(r->json, "task.approach"), 0.10, 1e-12);
  h_resp_free(r);
  check_npy("ball", 2, 0);
  r = h_delete("/v1/tasks/ball/demos/2");
  ASSERT_HTTP_ERROR(r, 404, "demo_not_found");
  h_resp_free(r);
  r = h_delete("/v1/tasks/ball/demos/two");
  ASSERT_HTTP_ERROR(r, 404, "demo_not_found");
  h_resp_free(r);
  r = h_delete("/v1/tasks/nope/demos/1");
  ASSERT_HTTP_ERROR(r, 404, "task_not_found");
  h_resp_free(r);
  r = h_delete("/v1/tasks/nope");
  ASSERT_HTTP_ERROR(r, 404, "task_not_found");
  h_resp_free(r);
  /* ids are never reused */
  r = add_demo("ball", ball);
  ASSERT_EQ(JINT(r->json, "demo.id"), 3);
  h_resp_free(r);

  /* A clean restart: the same tasks. */
  json_t *before = task_get("ball");
  h_stop();
  h_start();
  json_t *after = task_get("ball");
  ASSERT_JSON_EQUAL(before, after);
  json_decref(after);

  /* kill -9 right after a demo was answered: it is there after the restart. */
  r = add_demo("box", box);
  ASSERT_EQ(JINT(r->json, "demo.id"), 2);
  h_resp_free(r);
  h_kill();
  h_start();
  json_t *bx = task_get("box");
  ASSERT_EQ(JINT(bx, "n_demos"), 2);
  ASSERT_EQ(JINT(bx, "demos.1.id"), 2);
  json_decref(bx);
  after = task_get("ball");
  ASSERT_JSON_EQUAL(before, after);
  json_decref(after);
  json_decref(before);

  /* Delete a task: gone, also after a restart. */
  r = h_delete("/v1/tasks/mug_place");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_get("/v1/tasks/mug_place");
  ASSERT_HTTP_ERROR(r, 404, "task_not_found");
  h_resp_free(r);
  char *mp = h_fmt("%s/tasks/mug_place", h_state_dir());
  struct stat st;
  ASSERT(stat(mp, &st) != 0);
  free(mp);

  legacy_task(ball);

  /* A task folder that does not load: logged, skipped, its name refused; the rest serves. */
  char *bd = h_fmt("%s/tasks/broken", h_state_dir());
  h_mkdirs(bd);
  char *bj = h_fmt("%s/task.json", bd);
  h_write_file(bj, "{\"format\": 1, \"name\": \"broken\"", 31);
  h_stop();
  h_start();
  ASSERT(h_wait_log("task broken is left out", 1, 5));
  r = h_get("/v1/tasks");
  ASSERT_EQ(json_array_size(JGET(r->json, "tasks")), 2);
  h_resp_free(r);
  expect_demo_error("broken", ball, 409, "task_unreadable");
  char *text = h_read_file(bj, NULL);
  ASSERT_STREQ(text, "{\"format\": 1, \"name\": \"broken\""); /* left untouched */
  free(text);
  free(bj);
  free(bd);

  /* A demo keeps its sample: deleting its scene changes nothing. */
  before = task_get("ball");
  r = h_delete("/v1/scenes/sg");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  h_stop();
  h_start();
  after = task_get("ball");
  ASSERT_JSON_EQUAL(before, after);
  json_decref(after);
  json_decref(before);
  check_npy("ball", 1, 1);

  printf("setup %.1f s, total %.1f s\n", t_ready - t0, t_now() - t0);
  free(ball);
  free(box);
  free(place);
  free(imports);
  h_stop();
  h_done();
  return 0;
}
