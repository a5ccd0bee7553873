/* POST /v1/scenes/{s}/grasps and .../grasps/{id}/execute on a briefly trained scenegen
 * tabletop, with fieldgrip-sim as the robot and the gripper:
 *   - grasps of a named task: top_k, distinct poses (NMS), pre_grasp exactly `approach` back
 *     along the pose's -z, search statistics, X-Took-Ms and no timing in the body;
 *   - the same request twice, and again after a restart: the same bytes;
 *   - a query (class embedding) retrieves the task shown on that object;
 *   - an empty result (nothing passes the language mask) is 200 with a reason;
 *   - bad requests answer their JSON errors;
 *   - health answers while a long grasp request runs;
 *   - execute: a dry run carries the pick's register words for the grasp's pose and width,
 *     a real one closes the simulator's gripper on its object; Idempotency-Key replays;
 *     404 for unknown ids; 409 grasp_stale once the scene was trained again.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen, argv[3]: fieldgrip-sim. */
#include "grasp_util.h"
#include "trained.h"
#include "robot_util.h"
#include "simproc.h"

#include "core/error.h"
#include "core/pose.h"
#include "modbus/regs.h"

#include <pthread.h>

/* The demos ask for F3RM's Gaussian of 7.5 mm around the TCP (the default before the box
 * between the pads): on this field, 60 steps on 2 cm voxels, only the objects' centres carry
 * features that tell the ball from the box. Measured, the ball's class embedding against the
 * tasks' mean query-point features: 0.279 for the ball and 0.232 for the box with the
 * Gaussian; -0.166 and -0.102 with the 2F-85's default box, which retrieves the box. */
#define QP_GAUSSIAN "{\"n\": 32, \"std\": 0.0075}"

static char *demo_body(const char *object, const char *extra) {
  return g_demo_body_qp("sg", object, QP_GAUSSIAN, extra);
}

static h_resp *grasps(const char *body) { return g_post("/v1/scenes/sg/grasps", body); }

static h_resp *grasps_ok(const char *body) {
  h_resp *r = grasps(body);
  if (r->status != 200) fprintf(stderr, "grasps %s -> %s\n", body, r->body);
  ASSERT_STATUS(r, 200);
  return r;
}

static void expect_error(const char *body, long status, const char *code) {
  h_resp *r = grasps(body);
  if (r->status != status) fprintf(stderr, "grasps %s -> %s\n", body, r->body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
}

/* voxel_cache.bytes of scene sg: its voxel features and their grasp field once built. */
static long long cache_bytes(void) {
  h_resp *r = h_get("/v1/scenes/sg");
  ASSERT_STATUS(r, 200);
  long long bytes = JINT(r->json, "voxel_cache.bytes");
  h_resp_free(r);
  return bytes;
}

static void matrix_of(json_t *pose, double T[16]) {
  for (int i = 0; i < 16; i++)
    T[i] = json_number_value(json_array_get(json_array_get(JGET(pose, "matrix"), i / 4), i % 4));
}

/* The checks every grasp reply of a task must pass; returns the number of grasps. */
static int check_reply(const h_resp *r, const char *task, int top_k, double approach) {
  ASSERT(h_resp_header(r, "X-Took-Ms") != NULL);
  ASSERT(h_jfind(r->json, "took_ms") == NULL);
  ASSERT_STREQ(JSTR(r->json, "task"), task);
  ASSERT(JINT(r->json, "search.candidates") > 0);
  ASSERT(JINT(r->json, "search.poses_scored") >= JINT(r->json, "search.candidates") * 8);
  /* why poses were refused: collisions checked (and some rejected), limits */
  ASSERT(JINT(r->json, "search.collision_checks") > 0);
  ASSERT(JINT(r->json, "search.rejected_collisions") >= 0);
  ASSERT(JINT(r->json, "search.rejected_collisions") <= JINT(r->json, "search.collision_checks"));
  ASSERT(JINT(r->json, "search.rejected_limits") >= 0);
  json_t *a = JGET(r->json, "grasps");
  int n = (int)json_array_size(a);
  ASSERT(n <= top_k);
  if (n == 0) ASSERT(json_is_string(JGET(r->json, "reason")));
  for (int i = 0; i < n; i++) {
    json_t *g = json_array_get(a, i);
    ASSERT_EQ(strlen(JSTR(g, "id")), 17);
    ASSERT_STREQ(JSTR(g, "task"), task);
    ASSERT_STREQ(JSTR(g, "kind"), "grasp");
    ASSERT(json_is_true(JGET(g, "collision_free")));
    ASSERT(JNUM(g, "width") > 0);
    if (i) ASSERT(JNUM(g, "score") <= JNUM(json_array_get(a, i - 1), "score") + 0.2);
    double T[16], P[16];
    matrix_of(JGET(g, "pose"), T);
    matrix_of(JGET(g, "pre_grasp"), P);
    ASSERT_OK(fg_pose_validate(T));
    /* within [robot]'s default approach cone: the tool's +z within 60 degrees of down */
    ASSERT(-T[10] >= cos(60 * M_PI / 180) - 1e-9);
    for (int k = 0; k < 3; k++) {
      ASSERT_NEAR(P[4 * k + 3], T[4 * k + 3] - approach * T[4 * k + 2], 1e-9);
      const char idx[2] = {(char)('0' + k), 0};
      ASSERT_NEAR(JNUM(JGET(g, "pose.position"), idx), T[4 * k + 3], 1e-12);
      for (int c = 0; c < 3; c++) ASSERT_NEAR(P[4 * k + c], T[4 * k + c], 1e-12);
    }
    /* NMS: no two grasps are the same pose */
    for (int j = 0; j < i; j++) {
      double U[16];
      matrix_of(JGET(json_array_get(a, j), "pose"), U);
      double d = 0, m = 0;
      for (int k = 0; k < 3; k++) d += pow(T[4 * k + 3] - U[4 * k + 3], 2);
      for (int k = 0; k < 12; k++) m += fabs(T[k] - U[k]);
      ASSERT(sqrt(d) > 1e-6 || m > 1e-6);
      ASSERT(strcmp(JSTR(g, "id"), JSTR(json_array_get(a, j), "id")) != 0);
    }
  }
  return n;
}

/* ---------------------------------------------------------------- health during a search */

typedef struct bg {
  h_resp *r;
  volatile int done;
} bg;

static void *bg_grasp(void *ud) {
  bg *b = ud;
  b->r = grasps("{\"task\": \"ball\", \"rotations\": 1024, \"seed\": 5}");
  __atomic_store_n(&b->done, 1, __ATOMIC_SEQ_CST);
  return NULL;
}

static void health_during_grasp(void) {
  bg b = {0};
  pthread_t th;
  ASSERT_EQ(pthread_create(&th, NULL, bg_grasp, &b), 0);
  int answered_while_running = 0;
  while (!__atomic_load_n(&b.done, __ATOMIC_SEQ_CST)) {
    h_resp *r = h_get("/v1/health");
    ASSERT_STATUS(r, 200);
    h_resp_free(r);
    if (!__atomic_load_n(&b.done, __ATOMIC_SEQ_CST)) answered_while_running++;
  }
  pthread_join(th, NULL);
  ASSERT_STATUS(b.r, 200);
  printf("health answered %d times during a grasp search\n", answered_while_running);
  ASSERT(answered_while_running >= 1);
  h_resp_free(b.r);
}

/* ---------------------------------------------------------------- execute */

/* How many writes the simulator has seen, robot and gripper: a replay adds none. */
static int sim_writes(const simproc *sim) {
  static simproc_write w[64];
  return simproc_writes(sim, -1, w, 64);
}

static h_resp *execute(const char *id, const char *body, const char *key) {
  char *path = h_fmt("/v1/scenes/sg/grasps/%s/execute", id);
  h_resp *r = r_post(path, body, key);
  free(path);
  return r;
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 4) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN FIELDGRIP-SIM", argv[0]);
  double t0 = t_now();
  simproc_init(argv[3], NULL);
  simproc sim;
  const char *sim_args[] = {"--object-width-mm", "30", "--activation-ms", "20", NULL};
  simproc_start(&sim, 0, sim_args);
  char *imports = f_dataset(argv[2]);
  char *extra = h_fmt("[gripper]\nmodel = robotiq-2f85\n\n[robot]\ntransport = tcp\nhost = "
                      "127.0.0.1\nport = %d\ntimeout_ms = 300\n\n[gripper.modbus]\ntransport = "
                      "tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 300\n", sim.port, sim.port);
  g_config(imports, extra);
  f_scene("t60", "sg"); /* trained {"steps": 60} at 2 cm */
  h_start();
  double t_ready = t_now();

  /* A heatmap builds the voxel features alone; the first demo adds their grasp field to the
   * cache (and its bytes to the cache's); later demos and searches share it. */
  char *emb = g_class_embedding("ball");
  char *b = h_fmt("{\"embedding\": %s}", emb);
  h_resp *r = g_post("/v1/scenes/sg/heatmap", b);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  free(b);
  free(emb);
  const long long features_bytes = cache_bytes();
  ASSERT(features_bytes > 0);
  b = demo_body("ball", "");
  r = g_post("/v1/tasks/ball/demos", b);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(b);
  const long long with_field_bytes = cache_bytes();
  ASSERT(with_field_bytes > features_bytes);
  b = demo_body("box", "\"approach\": 0.05");
  r = g_post("/v1/tasks/box/demos", b);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(b);

  /* By task: top_k, NMS, pre_grasp; the same bytes twice. */
  r = grasps_ok("{\"task\": \"ball\", \"top_k\": 5}");
  int n = check_reply(r, "ball", 5, 0.10);
  ASSERT(n >= 1);
  ASSERT(h_jfind(r->json, "retrieval") == NULL);
  json_t *best = JGET(r->json, "grasps.0");
  printf("ball: %d grasps, best at %.3f %.3f %.3f score %.3f; ball at %.3f %.3f %.3f\n", n,
         JNUM(best, "pose.position.0"), JNUM(best, "pose.position.1"),
         JNUM(best, "pose.position.2"), JNUM(best, "score"),
         JNUM(g_object("ball"), "grasp.position.0"), JNUM(g_object("ball"), "grasp.position.1"),
         JNUM(g_object("ball"), "grasp.position.2"));
  h_resp *r2 = grasps_ok("{\"task\": \"ball\", \"top_k\": 5}");
  ASSERT_EQ(r2->len, r->len);
  ASSERT(memcmp(r2->body, r->body, r->len) == 0);
  h_resp_free(r2);
  r2 = grasps_ok("{\"task\": \"ball\", \"top_k\": 1}");
  ASSERT(json_array_size(JGET(r2->json, "grasps")) <= 1);
  h_resp_free(r2);
  r2 = grasps_ok("{\"task\": \"box\", \"top_k\": 3}");
  check_reply(r2, "box", 3, 0.05);
  h_resp_free(r2);
  ASSERT_EQ(cache_bytes(), with_field_bytes);
  char *first_id = h_fmt("%s", JSTR(r->json, "grasps.0.id"));
  char *body1 = h_fmt("%.*s", (int)r->len, r->body);
  double T[16];
  matrix_of(JGET(best, "pose"), T);
  double width = JNUM(best, "width");
  h_resp_free(r);

  /* By query: the class embedding retrieves the task shown on that object. */
  const char *objs[] = {"ball", "box"};
  for (int i = 0; i < 2; i++) {
    char *e = g_class_embedding(objs[i]);
    char *q = h_fmt("{\"embedding\": %s, \"top_k\": 3}", e);
    r = grasps_ok(q);
    json_t *ret = JGET(r->json, "retrieval");
    ASSERT_EQ(json_array_size(ret), 2);
    printf("query %s: retrieval %s %.3f, %s %.3f; %zu grasps\n", objs[i], JSTR(ret, "0.task"),
           JNUM(ret, "0.score"), JSTR(ret, "1.task"), JNUM(ret, "1.score"),
           json_array_size(JGET(r->json, "grasps")));
    ASSERT_STREQ(JSTR(ret, "0.task"), objs[i]);
    ASSERT(JNUM(ret, "0.score") >= JNUM(ret, "1.score"));
    ASSERT_STREQ(JSTR(r->json, "task"), objs[i]);
    h_resp_free(r);
    free(q);
    /* the same with the cost weighted by the query (J_lang): a well-formed answer */
    q = h_fmt("{\"embedding\": %s, \"top_k\": 3, \"language_weight\": true}", e);
    r = grasps_ok(q);
    ASSERT_STREQ(JSTR(r->json, "task"), objs[i]);
    h_resp_free(r);
    free(q);
    /* the opposite direction scores below 0.5 everywhere: nothing passes the mask */
    json_error_t je;
    json_t *v = json_loads(e, 0, &je);
    for (size_t k = 0; k < json_array_size(v); k++)
      json_array_set_new(v, k, json_real(-json_number_value(json_array_get(v, k))));
    char *neg = json_dumps(v, JSON_COMPACT);
    q = h_fmt("{\"embedding\": %s, \"task\": \"%s\"}", neg, objs[i]);
    r = grasps_ok(q);
    ASSERT_EQ(json_array_size(JGET(r->json, "grasps")), 0);
    ASSERT_STRCONTAINS(JSTR(r->json, "reason"), "mask");
    h_resp_free(r);
    free(q);
    free(neg);
    json_decref(v);
    free(e);
  }

  /* Bad requests. */
  expect_error("{\"task\": ", 400, "malformed_json");
  expect_error("{}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"top_k\": 0}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"top_k\": 101}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"rotations\": 4}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"seed\": -1}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"gripper\": \"x\"}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"language_weight\": true}", 400, "invalid_request");
  expect_error("{\"task\": \"ball\", \"language_weight\": 1}", 400, "invalid_request");
  expect_error("{\"task\": \"nope\"}", 404, "task_not_found");
  expect_error("{\"embedding\": [1, 0, 0]}", 400, "invalid_query");
  expect_error("{\"text\": \"a ball\"}", 409, "clip_not_configured");
  b = demo_body("ball", "");
  r = g_post("/v1/tasks/empty/demos", b);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(b);
  r = h_delete("/v1/tasks/empty/demos/1");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  expect_error("{\"task\": \"empty\"}", 409, "task_empty");
  r = g_post("/v1/scenes/nope/grasps", "{\"task\": \"ball\"}");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);

  health_during_grasp();

  /* Execute: a dry run has the pick's words for the grasp's pose and width. */
  ASSERT(r_wait_true("/v1/robot", "connected", 10));
  ASSERT(r_wait_true("/v1/gripper", "connected", 10));
  r = execute(first_id, "{\"dry_run\": true}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(JSTR(r->json, "command"), "pick");
  uint16_t w[32];
  ASSERT_EQ(r_robot_words(r, w, 32), 13);
  ASSERT_EQ(w[10], 1000); /* the task's approach: the robot comes in from its pre_grasp */
  double p[3], q[4], rv[3];
  fg_pose_to_quat(T, p, q);
  fg_rotvec_from_quat(q, rv);
  ASSERT_EQ(w[1], 1);
  for (int k = 0; k < 3; k++) {
    ASSERT(abs((int16_t)w[2 + k] - (int)lround(p[k] * 1e4)) <= 1);
    ASSERT(abs((int16_t)w[5 + k] - (int)lround(rv[k] * 1e3)) <= 1);
  }
  ASSERT(abs((int)w[8] - (int)lround(width * 1e4)) <= 1);
  h_resp_free(r);
  /* ... and a real one closes the gripper on the simulator's object. */
  r = execute(first_id, "{}", "exec-1");
  r_expect(r, 200, NULL);
  ASSERT_STREQ(JSTR(r->json, "state"), "done");
  ASSERT(json_is_true(JGET(r->json, "object_detected")));
  h_resp_free(r);
  const int picked = sim_writes(&sim);
  r = execute(first_id, "{}", "exec-1");
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(JGET(r->json, "replayed")));
  const json_int_t exec_id = json_integer_value(JGET(r->json, "id"));
  h_resp_free(r);
  ASSERT_EQ(sim_writes(&sim), picked);
  r = execute("g0123456789abcdef", "{}", NULL);
  r_expect(r, 404, "grasp_not_found");
  h_resp_free(r);
  r = g_post("/v1/scenes/nope/grasps/g0123456789abcdef/execute", "{}");
  r_expect(r, 404, "scene_not_found");
  h_resp_free(r);
  r = execute(first_id, "{\"dry_run\": 1}", NULL);
  r_expect(r, 400, "invalid_request");
  h_resp_free(r);

  /* After a restart the grasp is forgotten until the next search, but a retry of its
   * execute is known by its key first: it answers the pick it made, and picks nothing
   * (an empty body with other spacing is the same request). */
  h_stop();
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 10));
  r = execute(first_id, "{\"dry_run\": true}", NULL);
  r_expect(r, 404, "grasp_not_found");
  h_resp_free(r);
  r = execute(first_id, " { } ", "exec-1");
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(JGET(r->json, "replayed")));
  ASSERT_EQ(json_integer_value(JGET(r->json, "id")), exec_id);
  h_resp_free(r);
  ASSERT_EQ(sim_writes(&sim), picked);

  /* After a restart: the same request, the same bytes (and ids). */
  r = grasps_ok("{\"task\": \"ball\", \"top_k\": 5}");
  ASSERT_EQ(strlen(body1), r->len);
  ASSERT(memcmp(body1, r->body, r->len) == 0);
  h_resp_free(r);

  /* Trained again: the old ids are stale. */
  g_train("sg", 10);
  r = execute(first_id, "{\"dry_run\": true}", NULL);
  r_expect(r, 409, "grasp_stale");
  h_resp_free(r);
  /* ... but a retry of the pick made on the earlier field replays it, and picks nothing */
  r = execute(first_id, "{}", "exec-1");
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(JGET(r->json, "replayed")));
  h_resp_free(r);
  ASSERT_EQ(sim_writes(&sim), picked);

  printf("setup %.1f s, total %.1f s\n", t_ready - t0, t_now() - t0);
  free(body1);
  free(first_id);
  free(extra);
  free(imports);
  h_stop();
  simproc_stop(&sim);
  h_done();
  return 0;
}
