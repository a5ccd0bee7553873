/* POST /v1/robot/commands and /v1/gripper/... against the simulator: the worked example of
 * proto/modbus.md as dry-run words and on the wire (int16 and float32), pick with an object
 * detected, place, open/close/move/activate, negative coordinates, values out of range, bad
 * requests, and Idempotency-Key replays, also across a restart.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "robot_util.h"
#include "simproc.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define MAXW 256
static simproc_write g_w[MAXW];

static int writes(const simproc *p, int unit) { return simproc_writes(p, unit, g_w, MAXW); }

static void expect_words(const simproc_write *w, int addr, const uint16_t *words, int n) {
  ASSERT_EQ(w->fn, 16);
  ASSERT_EQ(w->addr, addr);
  ASSERT_EQ(w->n, n);
  for (int i = 0; i < n; i++)
    if (w->words[i] != words[i])
      FG_TEST_FAIL("word %d at %d: %u, expected %u", i, addr, w->words[i], words[i]);
}

static void expect_reply_words(const h_resp *r, const uint16_t *words, int n) {
  uint16_t got[32];
  ASSERT_EQ(r_robot_words(r, got, 32), n);
  for (int i = 0; i < n; i++)
    if (got[i] != words[i]) FG_TEST_FAIL("reply word %d: %u, expected %u", i, got[i], words[i]);
}

/* The worked example, dry run and sent, in one encoding. */
static void check_example(const char *encoding, const uint16_t *words, int n) {
  simproc sim;
  const char *args[] = {"--ack-init", "6", "--encoding", encoding, NULL};
  simproc_start(&sim, 0, args);
  char extra[64];
  snprintf(extra, sizeof extra, "encoding = %s", encoding);
  r_config(sim.port, extra, 0, NULL);
  h_start();
  /* the daemon continues after the robot's ack (6), so the next seq is the example's 7: a
   * dry run plans with what was read, so wait for the read, not just the connection */
  ASSERT(r_wait_status("/v1/robot", 10));
  h_resp *r = r_post("/v1/robot/commands", R_EXAMPLE_BODY ", \"dry_run\": true}", NULL);
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "dry_run")));
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "seq")), 7);
  json_t *robot = json_object_get(json_object_get(r->json, "registers"), "robot");
  ASSERT_EQ(json_integer_value(json_object_get(robot, "address")), 128);
  ASSERT_EQ(json_integer_value(json_object_get(robot, "function")), 16);
  ASSERT_STREQ(json_string_value(json_object_get(robot, "encoding")), encoding);
  expect_reply_words(r, words, n);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, -1), 0); /* a dry run sends nothing */

  r = r_post("/v1/robot/commands", R_EXAMPLE_BODY "}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "robot_status")), 2);
  ASSERT(json_is_null(json_object_get(r->json, "object_detected"))); /* no gripper here */
  expect_reply_words(r, words, n);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 1);
  expect_words(&g_w[0], 128, words, n);

  r = h_get("/v1/robot");
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "last_seq")), 7);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "ack")), 7);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "encoding")), encoding);
  ASSERT_STREQ(json_string_value(json_object_get(
                   json_object_get(r->json, "last_command"), "state")), "done");
  /* where the robot reports the pick ended (registers 400-405, read after the motion): the
   * pose lifted by the block's 0.10 m retreat, turned as the pose asked */
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "tcp_pose_base")), 400);
  ASSERT(json_is_null(json_object_get(r->json, "tcp_pose_error")));
  json_t *tcp = json_object_get(r->json, "tcp_pose");
  const double want_p[3] = {0.4523, -0.1207, 0.1350}, want_q[4] = {0, 0.9238795, -0.3826834, 0};
  double dot = 0;
  for (int i = 0; i < 3; i++)
    ASSERT_NEAR(json_real_value(json_array_get(json_object_get(tcp, "position"), i)),
                want_p[i], 1e-9);
  for (int i = 0; i < 4; i++)
    dot += want_q[i] * json_real_value(json_array_get(json_object_get(tcp, "quaternion"), i));
  ASSERT(fabs(dot) > cos(0.002)); /* within 4 mrad: the registers' rounding */
  ASSERT(json_is_string(json_object_get(tcp, "read_at")));
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

/* A controller that publishes no TCP pose: tcp_pose_base = none, and nothing is read. */
static void check_tcp_pose_none(void) {
  simproc sim;
  const char *args[] = {"--tcp-pose-base", "none", NULL};
  simproc_start(&sim, 0, args);
  r_config(sim.port, "tcp_pose_base = none", 0, NULL);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  h_resp *r = r_post("/v1/robot/commands", R_EXAMPLE_BODY "}", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = h_get("/v1/robot");
  ASSERT(json_is_null(json_object_get(r->json, "tcp_pose_base")));
  ASSERT(json_is_null(json_object_get(r->json, "tcp_pose")));
  ASSERT(json_is_null(json_object_get(r->json, "tcp_pose_error")));
  /* no read reached the simulator, which would have answered exception 2 */
  ASSERT_EQ(json_integer_value(json_object_get(json_object_get(r->json, "counters"),
                                               "exceptions")), 0);
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

/* Pick with an object between the fingers, place, and the gripper endpoints. */
static void check_gripper(void) {
  simproc sim;
  const char *args[] = {"--object-width-mm", "40", "--activation-ms", "50", NULL};
  simproc_start(&sim, 0, args);
  r_config(sim.port, NULL, sim.port, NULL);
  h_start();
  /* "connected" until the first status read on the connection, then the gripper's state */
  ASSERT(r_wait_status("/v1/gripper", 10));
  h_resp *r = h_get("/v1/gripper");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "not_activated");
  h_resp_free(r);

  r = r_post("/v1/robot/commands", R_EXAMPLE_BODY "}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  ASSERT(json_is_true(json_object_get(r->json, "object_detected")));
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "gripper_width")), 0.040, 0.0005);
  h_resp_free(r);
  /* activation (reset, rACT), open to 0.08 m (position 15), the pose block, close, and the
   * retreat: a move 0.10 m straight up */
  const uint16_t reset[3] = {0, 0, 0}, act[3] = {0x0100, 0, 0};
  ASSERT_EQ(writes(&sim, -1), 6);
  expect_words(&g_w[0], 1000, reset, 3);
  expect_words(&g_w[1], 1000, act, 3);
  ASSERT_EQ(g_w[2].unit, 9);
  ASSERT_EQ(g_w[2].words[0], 0x0900);
  ASSERT_EQ(g_w[2].words[1], 15);
  ASSERT_EQ(g_w[3].unit, 1);
  ASSERT_EQ(g_w[3].words[1], 1); /* pick */
  ASSERT_EQ(g_w[4].unit, 9);
  ASSERT_EQ(g_w[4].words[1], 255);
  ASSERT_EQ(g_w[4].words[2] & 0xFF, 24); /* 40 N on the 2F-85's 20..235 N */
  ASSERT_EQ(g_w[3].words[10], 1000); /* approach 0.10 m */
  ASSERT_EQ(g_w[3].words[11], 0);    /* no retreat in the block: fieldgrip sends it */
  ASSERT_EQ(g_w[5].unit, 1);
  ASSERT_EQ(g_w[5].words[1], 5);     /* move */
  ASSERT_EQ(g_w[5].words[2], 4523);
  ASSERT_EQ(g_w[5].words[4], 1350);  /* 0.035 + 0.10 m */
  ASSERT_EQ(g_w[5].words[10], 0);

  r = r_post("/v1/robot/commands",
             "{\"command\": \"place\", \"pose\": {\"position\": [0.3, 0.2, 0.05], "
             "\"quaternion\": [0, 1, 0, 0]}, \"width\": 0.06}", NULL);
  r_expect(r, 200, NULL);
  ASSERT(json_is_null(json_object_get(r->json, "object_detected")));
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "gripper_width")), 0.06, 0.0005);
  h_resp_free(r);
  /* the block, the opening (no second activation), backing out along the tool's -z */
  ASSERT_EQ(writes(&sim, -1), 9);
  ASSERT_EQ(g_w[6].unit, 1);
  ASSERT_EQ(g_w[6].words[1], 2);
  ASSERT_EQ(g_w[7].unit, 9);
  ASSERT_EQ(g_w[7].words[1], 75); /* round(255 x 0.025 / 0.085) */
  ASSERT_EQ(g_w[8].unit, 1);
  ASSERT_EQ(g_w[8].words[1], 5);
  ASSERT_EQ(g_w[8].words[4], 1500); /* the tool points down: back out = up to 0.15 m */

  r = r_post("/v1/gripper/close", "", NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "action")), "close");
  ASSERT(json_is_true(json_object_get(r->json, "object_detected")));
  h_resp_free(r);
  r = h_get("/v1/gripper");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "ready");
  ASSERT(json_is_true(json_object_get(r->json, "activated")));
  ASSERT(json_is_true(json_object_get(r->json, "object_detected")));
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "width")), 0.040, 0.0005);
  h_resp_free(r);
  r = r_post("/v1/gripper/move", "{\"width\": 0.05, \"speed\": 0.1, \"force\": 100}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "gripper_width")), 0.05, 0.0005);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 9), 7);
  ASSERT_EQ(g_w[6].words[1], 105);
  ASSERT_EQ(g_w[6].words[2], (uint16_t)(157 << 8 | 95)); /* 0.1 m/s, 100 N */
  r = r_post("/v1/gripper/open", "{}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "gripper_width")), 0.085, 1e-9);
  h_resp_free(r);
  /* open and close as robot commands go to the gripper only when it is configured */
  const int robot_writes = writes(&sim, 1);
  r = r_post("/v1/robot/commands", "{\"command\": \"close\"}", NULL);
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "object_detected")));
  ASSERT(json_is_null(json_object_get(r->json, "seq")));
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), robot_writes);
  /* an activation opens the gripper: refused while it holds something, unless asked for */
  const int grip_writes = writes(&sim, 9);
  r = r_post("/v1/gripper/activate", "", NULL);
  r_expect(r, 409, "gripper_holding");
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 9), grip_writes);
  r = r_post("/v1/gripper/activate", "{\"allow_drop\": true}", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  const int n = writes(&sim, 9);
  expect_words(&g_w[n - 2], 1000, reset, 3);
  expect_words(&g_w[n - 1], 1000, act, 3);

  /* a dry run of a pick shows every step's words, and sends nothing */
  const int total = writes(&sim, -1);
  r = r_post("/v1/robot/commands", R_EXAMPLE_BODY ", \"dry_run\": true}", NULL);
  r_expect(r, 200, NULL);
  json_t *g = json_object_get(json_object_get(r->json, "registers"), "gripper");
  ASSERT_EQ(json_array_size(g), 2);
  ASSERT_STREQ(json_string_value(json_object_get(json_array_get(g, 0), "step")), "gripper_open");
  ASSERT_EQ(json_integer_value(json_object_get(json_array_get(g, 1), "position")), 255);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, -1), total);
  h_stop();
  simproc_stop(&sim);
}

/* Negative coordinates and rotations survive the int16 encoding; bad requests are refused
 * and send nothing. */
static void check_values(void) {
  simproc sim;
  simproc_start(&sim, 0, NULL);
  /* the encoding of any orientation: the approach cone admits every direction here */
  r_config(sim.port, "approach_cone_deg = 180", sim.port, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  /* a quarter turn clockwise about z: q = [cos(-pi/4), 0, 0, sin(-pi/4)] */
  h_resp *r = r_post("/v1/robot/commands",
                     "{\"command\": \"move\", \"pose\": {\"position\": [-0.25, -1.5, -0.01], "
                     "\"quaternion\": [0.7071067811865476, 0, 0, -0.7071067811865476]}}", NULL);
  r_expect(r, 200, NULL);
  /* ids go on from the earlier starts of this state dir */
  const json_int_t id = json_integer_value(json_object_get(r->json, "id"));
  ASSERT(id >= 1);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 1);
  const uint16_t *w = g_w[0].words;
  ASSERT_EQ(w[1], 5);
  ASSERT_EQ((int16_t)w[2], -2500);
  ASSERT_EQ((int16_t)w[3], -15000);
  ASSERT_EQ((int16_t)w[4], -100);
  ASSERT_EQ((int16_t)w[5], 0);
  ASSERT_EQ((int16_t)w[6], 0);
  ASSERT_EQ((int16_t)w[7], -1571); /* -pi/2 rad in mrad */
  ASSERT_EQ(w[8], 850);            /* width defaults to the 2F-85's stroke */

  static const struct {
    const char *path, *body;
    long status;
    const char *code;
  } bad[] = {
      {"/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [3.3, 0, 0], "
       "\"quaternion\": [1, 0, 0, 0]}}", 400, "value_out_of_range"},
      {"/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [0, -3.27685, 0], "
       "\"quaternion\": [1, 0, 0, 0]}}", 400, "value_out_of_range"},
      {"/v1/robot/commands", "{\"command\": \"pick\", \"pose\": {\"position\": [0.4, 0, 0.1], "
       "\"quaternion\": [1, 0, 0, 0]}, \"width\": 0.1}", 422, "motion_limit"},
      {"/v1/robot/commands", "{\"command\": \"pick\", \"pose\": {\"position\": [0.4, 0, 0.1], "
       "\"quaternion\": [1, 0, 0, 0]}, \"force\": 300}", 422, "motion_limit"},
      {"/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [0.4, 0, 0.1], "
       "\"quaternion\": [1, 0, 0, 0]}, \"force\": 1.5}", 400, "value_out_of_range"},
      {"/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [0.4, 0, 0.1], "
       "\"quaternion\": [0, 0, 0, 0]}}", 400, "invalid_pose"},
      {"/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [0.4, 0], "
       "\"quaternion\": [1, 0, 0, 0]}}", 400, "invalid_pose"},
      {"/v1/robot/commands", "{\"command\": \"pick\"}", 400, "invalid_request"},
      {"/v1/robot/commands", "{\"command\": \"jump\"}", 400, "invalid_request"},
      {"/v1/robot/commands", "{\"pose\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}", 400,
       "invalid_request"},
      {"/v1/robot/commands", "{\"command\": \"move\", \"speeed\": 1}", 400, "invalid_request"},
      {"/v1/robot/commands", "{\"command\": \"open\", \"pose\": {\"position\": [0, 0, 0], "
       "\"quaternion\": [1, 0, 0, 0]}}", 400, "invalid_request"},
      {"/v1/robot/commands", "{\"command\": \"move\", \"wait\": 1}", 400, "invalid_request"},
      {"/v1/robot/commands", "{\"command\": \"mo", 400, "malformed_json"},
      {"/v1/robot/commands", "[1, 2]", 400, "invalid_request"},
      {"/v1/gripper/move", "{}", 400, "invalid_request"},
      {"/v1/gripper/move", "{\"width\": -0.01}", 400, "value_out_of_range"},
      {"/v1/gripper/open", "{\"speed\": 2}", 400, "value_out_of_range"},
      {"/v1/gripper/close", "{\"width\": 0.02}", 400, "invalid_request"},
      {"/v1/gripper/squeeze", "{}", 404, "not_found"},
  };
  const int before = writes(&sim, -1);
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    r = r_post(bad[i].path, bad[i].body, NULL);
    r_expect(r, bad[i].status, bad[i].code);
    h_resp_free(r);
  }
  ASSERT_EQ(writes(&sim, -1), before);
  char *none = h_fmt("/v1/robot/commands/%lld", (long long)id + 500); /* not yet given */
  r = h_get(none);
  free(none);
  r_expect(r, 404, "not_found");
  ASSERT_STRCONTAINS(r->body, "ids are never reused");
  h_resp_free(r);
  char *path = h_fmt("/v1/robot/commands/%lld", (long long)id);
  r = h_get(path);
  free(path);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "command")), "move");
  h_resp_free(r);
  ASSERT(h_alive());
  h_stop();
  simproc_stop(&sim);
}

/* GET of a command id from before the daemon's last start: 404, saying so. */
static void expect_gone(json_int_t id) {
  char *path = h_fmt("/v1/robot/commands/%lld", (long long)id);
  h_resp *r = h_get(path);
  r_expect(r, 404, "not_found");
  ASSERT_STRCONTAINS(r->body, "before the daemon last started");
  h_resp_free(r);
  free(path);
}

/* The same Idempotency-Key twice actuates once, also after a restart of the daemon (and
 * when the client serialised the request again); command ids are unique across restarts. */
static void check_idempotency(void) {
  simproc sim;
  simproc_start(&sim, 0, NULL);
  r_config(sim.port, NULL, 0, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  const char *move = "{\"command\": \"move\", \"pose\": {\"position\": [0.5, 0.1, 0.2], "
                     "\"quaternion\": [0, 1, 0, 0]}}";
  h_resp *r = r_post("/v1/robot/commands", move, "pick-0001");
  r_expect(r, 200, NULL);
  const json_int_t id = json_integer_value(json_object_get(r->json, "id"));
  const json_int_t seq = json_integer_value(json_object_get(r->json, "seq"));
  ASSERT(!json_object_get(r->json, "replayed"));
  h_resp_free(r);
  r = r_post("/v1/robot/commands", move, "pick-0001");
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "replayed")));
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "id")), id);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "seq")), seq);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 1);
  /* the same request serialised again, with other spacing and key order */
  r = r_post("/v1/robot/commands", "{ \"pose\" : {\"quaternion\": [0, 1, 0, 0],\n"
             "\"position\": [0.5, 0.1, 0.2]}, \"command\": \"move\" }", "pick-0001");
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "replayed")));
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "id")), id);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 1);
  /* the key with another body */
  r = r_post("/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [0.5, 0.1, "
             "0.3], \"quaternion\": [0, 1, 0, 0]}}", "pick-0001");
  r_expect(r, 422, "idempotency_key_reused");
  h_resp_free(r);
  /* a refused request does not use its key up */
  r = r_post("/v1/robot/commands", "{\"command\": \"move\"}", "pick-0002");
  r_expect(r, 400, "invalid_request");
  h_resp_free(r);
  r = r_post("/v1/robot/commands", "{\"command\": \"move\", \"wait\": 1}", "bad key\x01");
  r_expect(r, 400, "invalid_request");
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 1);

  h_stop();
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  r = r_post("/v1/robot/commands", move, "pick-0001");
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "replayed")));
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "seq")), seq);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 1);
  /* a new key runs, and the restarted daemon goes on after the robot's ack */
  r = r_post("/v1/robot/commands", move, "pick-0003");
  r_expect(r, 200, NULL);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "seq")), seq + 1);
  /* command ids are not used again after a restart: the old one is not this command */
  const json_int_t id2 = json_integer_value(json_object_get(r->json, "id"));
  ASSERT(id2 > id);
  h_resp_free(r);
  ASSERT_EQ(writes(&sim, 1), 2);
  ASSERT_EQ(g_w[1].words[0], seq + 1);
  expect_gone(id);
  char *path = h_fmt("/v1/robot/commands/%lld", (long long)id2);
  r = h_get(path);
  r_expect(r, 200, NULL);
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "id")), id2);
  h_resp_free(r);
  free(path);

  /* ... nor after kill -9 */
  h_kill();
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  r = r_post("/v1/robot/commands", move, "pick-0004");
  r_expect(r, 200, NULL);
  ASSERT(json_integer_value(json_object_get(r->json, "id")) > id2);
  h_resp_free(r);
  expect_gone(id2);
  h_stop();
  simproc_stop(&sim);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  check_example("int16", r_example_int16, 13);
  check_example("float32", r_example_float32, 23);
  check_tcp_pose_none();
  check_gripper();
  check_values();
  check_idempotency();
  h_done();
  printf("ok\n");
  return 0;
}
