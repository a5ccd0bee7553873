/* What keeps a motion safe, through the real daemon against the simulator: the limits (a
 * move far outside the cell, a huge force, a speed above the limit, a pick below the table,
 * an approach from below, an approach that starts outside the box), each refused with 422
 * motion_limit naming the limit and sending nothing; the position box taken from the scenes
 * when [robot] sets none; the approach and the speed in the block and followed by the
 * simulator; a stop in the middle of a pick (the simulator halts where it is), the latch that
 * refuses motion and gripper actions until a reset, and the stop in the audit log; a stop
 * with nothing running; the default force held to a lower limit.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "robot_util.h"
#include "simproc.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static simproc_write g_w[64];

static int robot_writes(const simproc *p) { return simproc_writes(p, 1, g_w, 64); }

/* A pick at (x, y, z) with the tool pointing down, and an optional tail of keys. */
static h_resp *pick(double x, double y, double z, const char *tail) {
  char *body = h_fmt("{\"command\": \"pick\", \"pose\": {\"position\": [%g, %g, %g], "
                     "\"quaternion\": [0, 1, 0, 0]}%s}", x, y, z,
                     tail ? tail : "");
  h_resp *r = r_post("/v1/robot/commands", body, NULL);
  free(body);
  return r;
}

/* Asserts a 422 motion_limit naming limit. */
static void expect_limit(h_resp *r, const char *limit) {
  r_expect(r, 422, "motion_limit");
  ASSERT_STREQ(JSTR(r->json, "error.limit"), limit);
  h_resp_free(r);
}

/* The last line of the simulator's events that starts with prefix; malloc'd, NULL if none. */
static char *last_event(const simproc *p, const char *prefix) {
  char *text = simproc_read(p->events), *found = NULL;
  if (!text) return NULL;
  char *save = NULL;
  for (char *line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save))
    if (strncmp(line, prefix, strlen(prefix)) == 0) {
      free(found);
      found = strdup(line);
    }
  free(text);
  return found;
}

/* The point "name=x,y,z" of an events line. */
static void event_point(const char *line, const char *name, double p[3]) {
  char key[32];
  snprintf(key, sizeof key, " %s=", name);
  const char *s = strstr(line, key);
  ASSERT(s != NULL);
  ASSERT(sscanf(s + strlen(key), "%lf,%lf,%lf", &p[0], &p[1], &p[2]) == 3);
}

static const char k_cell[] = "limit_min = 0.1 -0.45 0.0\nlimit_max = 0.8 0.45 0.5\n"
                             "approach_cone_deg = 60\nmax_force_n = 100\nmax_speed_mps = 0.25";

static void check_limits(void) {
  simproc sim;
  simproc_start(&sim, 0, NULL);
  r_config(sim.port, k_cell, 0, NULL);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  h_resp *r = r_post("/v1/robot/commands",
                     "{\"command\": \"move\", \"pose\": {\"position\": [3.2, -3.2, -2.5], "
                     "\"quaternion\": [0, 1, 0, 0]}, \"force\": 65535}", NULL);
  r_expect(r, 422, "motion_limit");
  ASSERT_STREQ(JSTR(r->json, "error.limit"), "max_force");
  h_resp_free(r);
  r = r_post("/v1/robot/commands",
             "{\"command\": \"move\", \"pose\": {\"position\": [3.2, -3.2, -2.5], "
             "\"quaternion\": [0, 1, 0, 0]}}", NULL);
  r_expect(r, 422, "motion_limit");
  ASSERT_STREQ(JSTR(r->json, "error.limit"), "position_box");
  ASSERT_NEAR(JNUM(r->json, "error.value"), 3.2, 1e-9);
  ASSERT_NEAR(JNUM(r->json, "error.bound"), 0.8, 1e-9);
  h_resp_free(r);
  expect_limit(pick(0.4, 0.0, -0.30, NULL), "position_box");          /* under the table */
  expect_limit(pick(0.4, 0.0, 0.45, NULL), "position_box");           /* approach from 0.55 */
  expect_limit(pick(0.4, 0.0, 0.05, ", \"speed\": 1.0"), "max_speed");
  expect_limit(pick(0.4, 0.0, 0.05, ", \"width\": 0.09"), "width");
  /* from below: the tool's +z straight up */
  expect_limit(r_post("/v1/robot/commands",
                      "{\"command\": \"move\", \"pose\": {\"position\": [0.4, 0, 0.1], "
                      "\"quaternion\": [1, 0, 0, 0]}}", NULL), "approach_cone");
  /* a dry run reports the same, with the words that were not sent */
  r = r_post("/v1/robot/commands",
             "{\"command\": \"move\", \"pose\": {\"position\": [0.4, 0, -0.2], \"quaternion\": "
             "[0, 1, 0, 0]}, \"dry_run\": true}", NULL);
  r_expect(r, 422, "motion_limit");
  ASSERT_EQ(json_array_size(JGET(r->json, "command.registers.robot.words")), 13);
  h_resp_free(r);
  ASSERT_EQ(robot_writes(&sim), 0);

  /* inside: the block carries the approach (0.10 m), the retreat and the default speed */
  r = pick(0.4, 0.1, 0.05, ", \"approach\": 0.08");
  r_expect(r, 200, NULL);
  ASSERT_STREQ(JSTR(r->json, "state"), "done");
  h_resp_free(r);
  ASSERT_EQ(robot_writes(&sim), 1);
  ASSERT_EQ(g_w[0].words[10], 800);  /* approach 0.08 m */
  ASSERT_EQ(g_w[0].words[11], 1000); /* no gripper of fieldgrip's: the robot retreats itself */
  ASSERT_EQ(g_w[0].words[12], 100);  /* 0.10 m/s */
  /* the simulator came in along the tool's +z: from 0.08 m above the pose, straight down,
   * and lifted 0.10 m after */
  char *line = last_event(&sim, "motion ");
  ASSERT(line != NULL);
  double pre[3], pose[3], end[3];
  event_point(line, "pre", pre);
  event_point(line, "pose", pose);
  event_point(line, "end", end);
  free(line);
  ASSERT_NEAR(pose[0], 0.4, 1e-3);
  ASSERT_NEAR(pose[2], 0.05, 1e-3);
  ASSERT_NEAR(pre[0], pose[0], 1e-3);
  ASSERT_NEAR(pre[1], pose[1], 1e-3);
  ASSERT_NEAR(pre[2], 0.13, 1e-3);
  ASSERT_NEAR(end[2], 0.15, 1e-3);
  r = pick(0.4, 0.1, 0.05, ", \"speed\": 0.2");
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT_EQ(robot_writes(&sim), 2);
  ASSERT_EQ(g_w[1].words[12], 200);

  /* GET /v1/robot shows what is in force */
  r = h_get("/v1/robot");
  ASSERT_NEAR(JNUM(r->json, "limits.position_box.max.0"), 0.8, 1e-9);
  ASSERT_NEAR(JNUM(r->json, "limits.approach_cone_deg"), 60, 1e-9);
  ASSERT_NEAR(JNUM(r->json, "limits.max_force"), 100, 1e-9);
  ASSERT(json_is_null(JGET(r->json, "latched")));
  h_resp_free(r);
  h_stop();

  /* without limit_min/limit_max the box is the scenes' workspaces grown by limit_margin */
  char *conf = h_fmt("[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\n"
                     "timeout_ms = 300\nlimit_margin = 0.05\nmax_force_n = 30\n", sim.port);
  h_write_config(conf);
  free(conf);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  expect_limit(pick(0.4, 0.0, 0.05, NULL), "position_box"); /* no scene: no box */
  r = r_post("/v1/scenes", "{\"name\": \"cell\", \"workspace\": {\"min\": [0.1, -0.45, 0.0], "
             "\"max\": [0.8, 0.45, 0.35]}, \"voxel_size\": 0.01}", NULL);
  r_expect(r, 201, NULL);
  h_resp_free(r);
  r = pick(0.4, 0.0, 0.05, NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  const int n = robot_writes(&sim);
  ASSERT_EQ(g_w[n - 1].words[9], 30); /* the default force (40 N) is held to the limit */
  expect_limit(pick(0.9, 0.0, 0.05, NULL), "position_box"); /* 0.85 is the edge */
  r = h_get("/v1/robot");
  ASSERT_NEAR(JNUM(r->json, "limits.position_box.max.2"), 0.40, 1e-9);
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

static void check_stop(void) {
  simproc sim;
  /* real time: a slow pick takes seconds, time enough to stop it */
  simproc_start(&sim, 0, (const char *const[]){"--time-scale", "1", NULL});
  r_config(sim.port, NULL, sim.port, NULL);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  ASSERT(r_wait_status("/v1/gripper", 10));
  h_resp *r = pick(0.4, 0.1, 0.05, ", \"speed\": 0.02, \"wait\": false");
  r_expect(r, 202, NULL);
  ASSERT_STREQ(JSTR(r->json, "state"), "acknowledged");
  const long long id = JINT(r->json, "id");
  h_resp_free(r);
  r = r_post("/v1/robot/stop", "{\"reason\": \"a person in the cell\"}", NULL);
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(JGET(r->json, "stop_written")));
  ASSERT_EQ(JINT(r->json, "stopped_command"), id);
  h_resp_free(r);
  ASSERT(r_wait_state(id, "stopped", 20));
  /* the stop is in the audit log with its reason, beside the pick it stopped */
  r = h_get("/v1/robot/log?limit=5");
  json_t *entries = JGET(r->json, "entries"), *e;
  size_t i;
  int stop_seen = 0;
  json_array_foreach(entries, i, e) {
    const char *cmd = json_string_value(json_object_get(e, "command"));
    if (cmd && strcmp(cmd, "stop") == 0) {
      ASSERT_STREQ(JSTR(e, "outcome"), "done");
      ASSERT_STREQ(JSTR(e, "reason"), "a person in the cell");
      stop_seen = 1;
    }
  }
  ASSERT(stop_seen);
  h_resp_free(r);
  /* the simulator halted on its way: between where it started and the approach's start */
  char *line = last_event(&sim, "stop ");
  ASSERT(line != NULL);
  double at[3];
  event_point(line, "at", at);
  free(line);
  line = last_event(&sim, "motion ");
  double from[3], pre[3];
  event_point(line, "from", from);
  event_point(line, "pre", pre);
  free(line);
  ASSERT(at[2] <= from[2] && at[2] > pre[2]);
  /* the gripper was not closed: the command's later steps never ran */
  const int grip_writes = simproc_writes(&sim, 9, g_w, 64);
  /* latched: nothing moves, the gripper neither, until a reset */
  r = h_get("/v1/robot");
  ASSERT(strstr(JSTR(r->json, "latched.reason"), "a person in the cell") != NULL);
  h_resp_free(r);
  const int before = robot_writes(&sim);
  r = pick(0.4, 0.1, 0.05, NULL);
  r_expect(r, 409, "robot_stopped");
  h_resp_free(r);
  r = r_post("/v1/gripper/open", "", NULL);
  r_expect(r, 409, "robot_stopped");
  h_resp_free(r);
  ASSERT_EQ(robot_writes(&sim), before);
  ASSERT_EQ(simproc_writes(&sim, 9, g_w, 64), grip_writes);
  r = r_post("/v1/robot/reset", "", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  /* the simulator logs the stop register's return to 0 just after it answered the write */
  for (int k = 0; !(line = last_event(&sim, "run")); k++) {
    ASSERT(k < 1000); /* 10 s */
    h_sleep_ms(10);
  }
  free(line);
  r = r_post("/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [0.4, 0.1, "
             "0.2], \"quaternion\": [0, 1, 0, 0]}, \"speed\": 0.25}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(JSTR(r->json, "state"), "done");
  h_resp_free(r);

  /* a stop with nothing running latches as well, and the robot gets the word */
  r = r_post("/v1/robot/stop", "", NULL);
  r_expect(r, 200, NULL);
  ASSERT(json_is_null(JGET(r->json, "stopped_command")));
  ASSERT(json_is_true(JGET(r->json, "stop_written")));
  h_resp_free(r);
  const int n = robot_writes(&sim);
  ASSERT(n >= 2);
  ASSERT_EQ(g_w[n - 1].words[1], 0); /* the no-op block, after the stop word */
  ASSERT_EQ(g_w[n - 2].addr, 128 + 15);
  ASSERT_EQ(g_w[n - 2].words[0], 1);
  r = r_post("/v1/robot/stop", "{\"speed\": 1}", NULL);
  r_expect(r, 400, "invalid_request");
  h_resp_free(r);
  r = r_post("/v1/robot/reset", "", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  check_limits();
  check_stop();
  h_done();
  printf("ok\n");
  return 0;
}
