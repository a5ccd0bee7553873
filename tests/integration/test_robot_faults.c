/* Failures of the robot and gripper peers, each reported and none re-sent: no acknowledgement
 * (504, unknown), a Modbus exception (502 naming it), a robot that reports failure, peers
 * down at start (the daemon serves, commands answer 503) and coming up later, a peer killed
 * mid-command and restarted (unknown, then the next command works), a second command or a
 * gripper action while one runs (409), Idempotency-Key replays of a running command and of
 * one cut short by a daemon that was killed, a gripper status that belongs to its connection,
 * no [robot] at all, and the Modbus lines of /metrics.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "robot_util.h"
#include "simproc.h"

#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

static simproc_write g_w[64];

static const char move[] = "{\"command\": \"move\", \"pose\": {\"position\": [0.4, -0.2, 0.1], "
                           "\"quaternion\": [0, 1, 0, 0]}";

static h_resp *send_move(const char *tail, const char *key) {
  char body[512];
  snprintf(body, sizeof body, "%s%s}", move, tail ? tail : "");
  return r_post("/v1/robot/commands", body, key);
}

static const char *state_of(const h_resp *r) {
  return json_string_value(json_object_get(r_command(r), "state"));
}

/* A loopback port nobody listens on. */
static int closed_port(void) {
  int s = socket(AF_INET, SOCK_STREAM, 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
  ASSERT_EQ(bind(s, (struct sockaddr *)&a, sizeof a), 0);
  socklen_t len = sizeof a;
  ASSERT_EQ(getsockname(s, (struct sockaddr *)&a, &len), 0);
  close(s);
  return ntohs(a.sin_port);
}

static void check_no_ack(void) {
  simproc sim;
  const char *args[] = {"--never-ack", NULL};
  simproc_start(&sim, 0, args);
  r_config(sim.port, "ack_timeout_ms = 300", 0, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  h_resp *r = send_move(NULL, "k-noack");
  r_expect(r, 504, "ack_timeout");
  ASSERT_STREQ(state_of(r), "unknown");
  ASSERT(strstr(json_string_value(json_object_get(json_object_get(r->json, "error"), "message")),
                "not sent again"));
  const json_int_t id = json_integer_value(json_object_get(r_command(r), "id"));
  h_resp_free(r);
  ASSERT(r_wait_state(id, "unknown", 1));
  /* the retry with its key is the same answer, and nothing is sent again */
  r = send_move(NULL, "k-noack");
  r_expect(r, 504, "ack_timeout");
  ASSERT(json_is_true(json_object_get(r->json, "replayed")));
  h_resp_free(r);
  /* the block, then a no-op under the next seq: a robot program that comes back later finds
   * nothing armed (written by the robot's worker once the command has answered: wait for
   * the latch to say so) */
  for (int i = 0;; i++) {
    r = h_get("/v1/robot");
    json_t *l = json_object_get(r->json, "latched");
    const int cleared = json_is_object(l) && json_is_false(json_object_get(l, "clear_pending"));
    h_resp_free(r);
    if (cleared) break;
    ASSERT(i < 1000); /* 10 s */
    h_sleep_ms(10);
  }
  ASSERT_EQ(simproc_writes(&sim, 1, g_w, 64), 2);
  ASSERT_EQ(g_w[0].words[1], 5);
  ASSERT_EQ(g_w[1].words[0], g_w[0].words[0] + 1);
  ASSERT_EQ(g_w[1].words[1], 0);
  r = h_get("/metrics");
  ASSERT(strstr(r->body, "fieldgrip_robot_commands_total{state=\"unknown\"} 1"));
  h_resp_free(r);
  /* the unknown outcome latches: the next command is refused and sends nothing */
  r = h_get("/v1/robot");
  json_t *latched = json_object_get(r->json, "latched");
  ASSERT(json_is_object(latched));
  ASSERT_EQ(json_integer_value(json_object_get(latched, "command")), id);
  ASSERT(json_is_false(json_object_get(latched, "clear_pending")));
  h_resp_free(r);
  r = send_move(NULL, "k-after-unknown");
  r_expect(r, 409, "robot_stopped");
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&sim, 1, g_w, 64), 2);
  /* the latch outlives a restart, until an operator resets it */
  h_stop();
  h_start();
  r = send_move(NULL, NULL);
  r_expect(r, 409, "robot_stopped");
  h_resp_free(r);
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  r = r_post("/v1/robot/reset", "", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = h_get("/v1/robot");
  ASSERT(json_is_null(json_object_get(r->json, "latched")));
  h_resp_free(r);
  const int n = simproc_writes(&sim, 1, g_w, 64);
  ASSERT_EQ(g_w[n - 1].n, 1); /* the stop register back to 0 */
  ASSERT_EQ(g_w[n - 1].addr, 128 + 15);
  ASSERT_EQ(g_w[n - 1].words[0], 0);
  r = h_get("/metrics");
  ASSERT(strstr(r->body, "fieldgrip_modbus_connected{peer=\"robot\"} 1"));
  ASSERT(!strstr(r->body, "peer=\"gripper\""));
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

static void check_exception_and_failure(void) {
  simproc sim;
  const char *args[] = {"--exception", "2", NULL};
  simproc_start(&sim, 0, args);
  r_config(sim.port, NULL, 0, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  h_resp *r = send_move(NULL, NULL);
  r_expect(r, 502, "modbus_exception");
  ASSERT(strstr(r->body, "illegal data address"));
  ASSERT_STREQ(state_of(r), "error");
  h_resp_free(r);
  r = h_get("/metrics");
  ASSERT(strstr(r->body, "fieldgrip_modbus_errors_total{peer=\"robot\",kind=\"exception\"} 1"));
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);

  simproc fail;
  const char *fargs[] = {"--fail", "--done-delay-ms", "20", NULL};
  simproc_start(&fail, 0, fargs);
  r_config(fail.port, NULL, 0, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  r = send_move(NULL, NULL);
  r_expect(r, 502, "robot_failed");
  ASSERT_STREQ(state_of(r), "failed");
  ASSERT_EQ(json_integer_value(json_object_get(r_command(r), "robot_status")), 3);
  h_resp_free(r);
  h_stop();
  simproc_stop(&fail);
}

/* Peers down at start: the daemon serves; commands say the peer is down; once the peer is
 * up the worker connects without a request and commands run. */
static void check_down_at_start(void) {
  const int port = closed_port();
  r_config(port, NULL, port, NULL);
  h_start();
  h_resp *r = h_get("/v1/health");
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = h_get("/v1/gripper");
  ASSERT(json_is_false(json_object_get(r->json, "connected")));
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "disconnected");
  h_resp_free(r);
  r = send_move(NULL, NULL);
  r_expect(r, 503, "robot_disconnected");
  ASSERT_STREQ(state_of(r), "error");
  ASSERT(strstr(r->body, "nothing was sent"));
  h_resp_free(r);
  r = r_post("/v1/robot/commands", R_EXAMPLE_BODY "}", NULL);
  r_expect(r, 503, "gripper_disconnected"); /* a pick opens the gripper first */
  ASSERT(json_is_null(json_object_get(r_command(r), "gripper_width"))); /* nothing was read */
  h_resp_free(r);
  r = r_post("/v1/gripper/close", "", NULL);
  r_expect(r, 503, "gripper_disconnected");
  h_resp_free(r);
  /* the log says so once per peer, not at every attempt of the backoff: wait until each
   * peer's worker has been refused three times, then count */
  ASSERT(h_wait_log("unreachable", 2, 5));
  const double deadline = h_now_s() + 20;
  while (h_metric("fieldgrip_modbus_errors_total{peer=\"robot\",kind=\"connect\"}") < 3 ||
         h_metric("fieldgrip_modbus_errors_total{peer=\"gripper\",kind=\"connect\"}") < 3) {
    ASSERT(h_now_s() < deadline);
    h_sleep_ms(20);
  }
  ASSERT_EQ(h_log_count("unreachable"), 2);

  simproc sim;
  simproc_start(&sim, port, NULL);
  ASSERT(r_wait_true("/v1/robot", "connected", 10));
  ASSERT(r_wait_true("/v1/gripper", "connected", 10));
  r = send_move(NULL, NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&sim, 1, g_w, 64), 1);
  h_stop();
  simproc_stop(&sim);
}

/* The robot dies while a command runs: the command ends unknown; the robot comes back and the
 * next command works. Meanwhile a second command is refused. */
static void check_killed_mid_command(void) {
  simproc sim;
  const char *args[] = {"--done-delay-ms", "3000", NULL};
  simproc_start(&sim, 0, args);
  r_config(sim.port, NULL, sim.port, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  h_resp *r = send_move(", \"wait\": false", "k-async");
  r_expect(r, 202, NULL);
  ASSERT_STREQ(state_of(r), "acknowledged");
  ASSERT(h_resp_header(r, "Location"));
  const json_int_t id = json_integer_value(json_object_get(r->json, "id"));
  h_resp_free(r);
  /* its key while it runs: the answer of the acknowledgement again */
  r = send_move(", \"wait\": false", "k-async");
  r_expect(r, 202, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "replayed")));
  ASSERT_STREQ(state_of(r), "acknowledged");
  h_resp_free(r);
  r = send_move(NULL, NULL);
  r_expect(r, 409, "robot_busy");
  h_resp_free(r);
  r = r_post("/v1/gripper/open", "", NULL); /* not between the steps of a command */
  r_expect(r, 409, "robot_busy");
  h_resp_free(r);
  r = h_get("/v1/robot");
  ASSERT(json_is_true(json_object_get(r->json, "busy")));
  h_resp_free(r);

  simproc_kill(&sim);
  ASSERT(r_wait_state(id, "unknown", 5));
  /* the poll that found the connection gone is a transport error, not a failed connect */
  ASSERT(h_metric("fieldgrip_modbus_errors_total{peer=\"robot\",kind=\"transport\"}") >= 1);
  /* its key answered at the acknowledgement; a retry now gets the command as it ended */
  r = send_move(", \"wait\": false", "k-async");
  r_expect(r, 502, "robot_unknown");
  ASSERT(json_is_true(json_object_get(r->json, "replayed")));
  ASSERT_STREQ(state_of(r), "unknown");
  ASSERT_EQ(json_integer_value(json_object_get(r_command(r), "id")), id);
  h_resp_free(r);
  r = h_get("/v1/robot");
  ASSERT(json_is_false(json_object_get(r->json, "connected")));
  ASSERT(json_is_false(json_object_get(r->json, "busy")));
  ASSERT(!json_is_null(json_object_get(r->json, "last_error")));
  h_resp_free(r);

  const char *fast[] = {"--done-delay-ms", "10", NULL};
  simproc_restart(&sim, fast);
  ASSERT(r_wait_true("/v1/robot", "connected", 10));
  /* the unknown outcome latched: motion waits for an operator's reset */
  r = send_move(NULL, NULL);
  r_expect(r, 409, "robot_stopped");
  h_resp_free(r);
  r = r_post("/v1/robot/reset", "", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = send_move(NULL, NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(state_of(r), "done");
  h_resp_free(r);
  r = h_get("/v1/robot");
  ASSERT(json_integer_value(json_object_get(json_object_get(r->json, "counters"),
                                            "reconnects")) >= 1);
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

/* The daemon dies while a keyed command runs: after the restart the key answers
 * outcome_unknown and the command is not sent again. */
static void check_daemon_killed(void) {
  simproc sim;
  const char *args[] = {"--done-delay-ms", "5000", NULL};
  simproc_start(&sim, 0, args);
  r_config(sim.port, NULL, 0, NULL);
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  h_resp *r = send_move(", \"wait\": false", "k-cut");
  r_expect(r, 202, NULL);
  h_resp_free(r);
  h_kill();
  h_start();
  ASSERT(r_wait_true("/v1/robot", "connected", 5));
  r = send_move(", \"wait\": false", "k-cut");
  r_expect(r, 504, "outcome_unknown");
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&sim, 1, g_w, 64), 1);
  h_stop();
  simproc_stop(&sim);
}

/* The gripper stops answering (SIGSTOP) once activated: two timeouts close the connection
 * and the worker reconnects (the kernel completes the handshake for the stopped process).
 * Until a status is read on the new connection the state is "connected", not the earlier
 * connection's "ready": the gripper may have been power cycled in between. */
static void check_status_per_connection(void) {
  simproc sim;
  const char *args[] = {"--activation-ms", "50", NULL};
  simproc_start(&sim, 0, args);
  r_config(0, NULL, sim.port, NULL);
  h_start();
  h_resp *r = r_post("/v1/gripper/activate", "", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT(r_wait_status("/v1/gripper", 10));
  r = h_get("/v1/gripper");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "ready");
  h_resp_free(r);

  ASSERT_EQ(kill(sim.pid, SIGSTOP), 0);
  /* every reply below is read whole: connected, the reconnection and the state together */
  const double deadline = h_now_s() + 30;
  int seen = 0;
  while (!seen) {
    ASSERT(h_now_s() < deadline);
    r = h_get("/v1/gripper");
    json_t *o = r->json;
    if (json_is_true(json_object_get(o, "connected")) &&
        json_integer_value(json_object_get(json_object_get(o, "counters"), "reconnects")) >= 1) {
      ASSERT_STREQ(json_string_value(json_object_get(o, "state")), "connected");
      ASSERT(json_is_null(json_object_get(o, "activated")));
      ASSERT(json_is_null(json_object_get(o, "width")));
      seen = 1;
    } else if (json_is_true(json_object_get(o, "connected"))) {
      ASSERT_STREQ(json_string_value(json_object_get(o, "state")), "ready"); /* still the first */
    }
    h_resp_free(r);
    if (!seen) h_sleep_ms(10);
  }
  ASSERT_EQ(kill(sim.pid, SIGCONT), 0);
  ASSERT(r_wait_status("/v1/gripper", 20));
  r = h_get("/v1/gripper");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "ready");
  h_resp_free(r);
  h_stop();
  simproc_stop(&sim);
}

static void check_not_configured(void) {
  h_write_config("");
  h_start();
  h_resp *r = send_move(NULL, NULL);
  r_expect(r, 409, "not_configured");
  ASSERT(strstr(r->body, "[robot]"));
  h_resp_free(r);
  /* a dry run reports what the real command would be refused for: no scene, no box */
  r = send_move(", \"dry_run\": true", NULL);
  r_expect(r, 422, "motion_limit");
  ASSERT_STREQ(json_string_value(json_object_get(json_object_get(r->json, "error"), "limit")),
               "position_box");
  h_resp_free(r);
  r = r_post("/v1/gripper/open", "", NULL);
  r_expect(r, 409, "not_configured");
  h_resp_free(r);
  r = h_get("/v1/gripper");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "not_configured");
  h_resp_free(r);
  r = h_get("/v1/robot");
  ASSERT(json_is_false(json_object_get(r->json, "configured")));
  h_resp_free(r);
  /* a reload does not swap peers under running commands: it says so, and nothing changes */
  r_config(closed_port(), NULL, 0, NULL);
  h_reload();
  ASSERT_EQ(h_log_count("keep their settings until the next restart"), 1);
  r = h_get("/v1/robot");
  ASSERT(json_is_false(json_object_get(r->json, "configured")));
  h_resp_free(r);
  h_stop();
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  check_no_ack();
  check_exception_and_failure();
  check_down_at_start();
  check_killed_mid_command();
  check_daemon_killed();
  check_status_per_connection();
  check_not_configured();
  h_done();
  printf("ok\n");
  return 0;
}
