/* The robot's audit log and the claim on the robot, against the simulator: a refused
 * command, a sent one, a gripper action, a dry run and a command answered at its
 * acknowledgement (with its end later) are each read back from GET /v1/robot/log with their
 * outcome, client address and request id; paging and bad parameters; the log survives a
 * kill -9; rotation keeps audit_keep files; a log that cannot be written refuses motions
 * (503) and sends nothing; a second daemon for the same robot refuses to start while the
 * first runs and starts once it is gone.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "robot_util.h"
#include "simproc.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#define MOVE_BODY                                                                              \
  "{\"command\": \"move\", \"pose\": {\"position\": [0.4, -0.1, 0.2], "                     \
  "\"quaternion\": [0, 1, 0, 0]}"

static simproc_write g_w[64];

/* POST with an X-Request-Id. */
static h_resp *post_rid(const char *path, const char *json, const char *rid) {
  char header[160];
  snprintf(header, sizeof header, "X-Request-Id: %s", rid);
  const char *headers[] = {header, NULL};
  h_req req = {.method = "POST", .path = path, .body = json, .body_len = strlen(json),
               .headers = headers};
  h_resp *r = h_request(&req);
  ASSERT_STREQ(h_resp_header(r, "X-Request-Id"), rid);
  return r;
}

/* GET /v1/robot/log with a query (may be ""), asserting 200; the caller frees. */
static h_resp *get_log(const char *query) {
  char *path = h_fmt("/v1/robot/log%s", query);
  h_resp *r = h_get(path);
  free(path);
  r_expect(r, 200, NULL);
  ASSERT(json_is_array(json_object_get(r->json, "entries")));
  return r;
}

static json_t *entry(const h_resp *r, size_t i) {
  json_t *e = json_array_get(json_object_get(r->json, "entries"), i);
  ASSERT(json_is_object(e));
  return e;
}

static const char *str(json_t *e, const char *key) {
  return json_string_value(json_object_get(e, key));
}

/* An entry of one request: its kind, route, outcome, status, request id and client. */
static void expect_request(json_t *e, const char *route, const char *outcome, int status,
                           const char *rid) {
  ASSERT_STREQ(str(e, "kind"), "request");
  ASSERT_STREQ(str(e, "route"), route);
  ASSERT_STREQ(str(e, "outcome"), outcome);
  ASSERT_EQ(json_integer_value(json_object_get(e, "http_status")), status);
  ASSERT_STREQ(str(e, "request_id"), rid);
  ASSERT(strncmp(str(e, "client"), "127.0.0.1:", 10) == 0);
  ASSERT(str(e, "time") && strlen(str(e, "time")) == 24); /* 2026-01-02T03:04:05.678Z */
}

/* Waits (10 s hang guard) until the newest entry of the log is of kind "end". */
static int wait_end_line(void) {
  for (double until = h_now_s() + 10; h_now_s() < until; h_sleep_ms(20)) {
    h_resp *r = get_log("?limit=1");
    json_t *e = json_array_get(json_object_get(r->json, "entries"), 0);
    const int done = e && strcmp(str(e, "kind"), "end") == 0;
    h_resp_free(r);
    if (done) return 1;
  }
  return 0;
}

/* Each kind of request once, then the log read back. */
static void check_entries(simproc *sim) {
  h_resp *r = post_rid("/v1/robot/commands", MOVE_BODY ", \"force\": 1.5}", "it-refused");
  r_expect(r, 400, "value_out_of_range");
  h_resp_free(r);
  r = post_rid("/v1/robot/commands", MOVE_BODY ", \"dry_run\": false}", "it-sent");
  r_expect(r, 200, NULL);
  const long long sent_id = json_integer_value(json_object_get(r->json, "id"));
  h_resp_free(r);
  r = post_rid("/v1/gripper/open", "{}", "it-gripper");
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = post_rid("/v1/robot/commands", MOVE_BODY ", \"dry_run\": true}", "it-dry");
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = post_rid("/v1/robot/commands", MOVE_BODY ", \"wait\": false}", "it-async");
  r_expect(r, 202, NULL);
  const long long async_id = json_integer_value(json_object_get(r->json, "id"));
  h_resp_free(r);
  ASSERT(wait_end_line());
  /* the robot got the two motions that were not dry runs, nothing else */
  ASSERT_EQ(simproc_writes(sim, 1, g_w, 64), 2);

  r = get_log("");
  ASSERT_EQ(json_array_size(json_object_get(r->json, "entries")), 6);
  ASSERT(json_is_null(json_object_get(r->json, "next_before")));
  for (size_t i = 0; i + 1 < 6; i++) /* newest first, numbered one by one */
    ASSERT_EQ(json_integer_value(json_object_get(entry(r, i), "seq")),
              json_integer_value(json_object_get(entry(r, i + 1), "seq")) + 1);
  json_t *e = entry(r, 0);
  ASSERT_STREQ(str(e, "kind"), "end");
  ASSERT_EQ(json_integer_value(json_object_get(e, "command_id")), async_id);
  ASSERT_STREQ(str(e, "outcome"), "done");
  ASSERT_STREQ(str(e, "request_id"), "it-async"); /* the request's context, carried over */
  expect_request(entry(r, 1), "/v1/robot/commands", "acknowledged", 202, "it-async");
  expect_request(entry(r, 2), "/v1/robot/commands", "planned", 200, "it-dry");
  ASSERT(json_is_true(json_object_get(entry(r, 2), "dry_run")));
  expect_request(entry(r, 3), "/v1/gripper/open", "done", 200, "it-gripper");
  ASSERT_STREQ(str(entry(r, 3), "command"), "open");
  e = entry(r, 4);
  expect_request(e, "/v1/robot/commands", "done", 200, "it-sent");
  ASSERT_EQ(json_integer_value(json_object_get(e, "command_id")), sent_id);
  ASSERT(json_is_false(json_object_get(e, "dry_run")));
  ASSERT_NEAR(json_real_value(json_array_get(json_object_get(json_object_get(e, "pose"),
                                                             "position"), 1)), -0.1, 1e-12);
  e = entry(r, 5);
  expect_request(e, "/v1/robot/commands", "refused", 400, "it-refused");
  ASSERT_STREQ(json_string_value(json_object_get(json_object_get(e, "error"), "code")),
               "value_out_of_range");
  ASSERT(json_string_value(json_object_get(json_object_get(e, "error"), "message")));
  ASSERT_NEAR(json_number_value(json_object_get(e, "force")), 1.5, 0);
  ASSERT(json_is_null(json_object_get(e, "command_id")));
  h_resp_free(r);

  /* a request id the daemon makes up, returned and logged */
  r = r_post("/v1/robot/commands", MOVE_BODY ", \"dry_run\": true}", NULL);
  const char *rid = h_resp_header(r, "X-Request-Id");
  ASSERT(rid && strlen(rid) == 16);
  h_resp *l = get_log("?limit=1");
  ASSERT_STREQ(str(entry(l, 0), "request_id"), rid);
  h_resp_free(l);
  h_resp_free(r);
}

/* limit and before page through the entries; bad values are 400. */
static void check_paging(void) {
  h_resp *all = get_log("");
  const size_t n = json_array_size(json_object_get(all->json, "entries"));
  ASSERT_EQ(n, 7);
  h_resp *p1 = get_log("?limit=3");
  ASSERT_EQ(json_array_size(json_object_get(p1->json, "entries")), 3);
  const long long next = json_integer_value(json_object_get(p1->json, "next_before"));
  ASSERT_EQ(next, json_integer_value(json_object_get(entry(all, 2), "seq")));
  char *q = h_fmt("?limit=100&before=%lld", next);
  h_resp *p2 = get_log(q);
  free(q);
  ASSERT_EQ(json_array_size(json_object_get(p2->json, "entries")), 4);
  ASSERT_EQ(json_integer_value(json_object_get(entry(p2, 0), "seq")), next - 1);
  h_resp_free(p1);
  h_resp_free(p2);
  h_resp_free(all);
  static const char *const bad[] = {"?limit=0", "?limit=1001", "?limit=abc", "?limit=2.5",
                                    "?before=0", "?before=-3", "?cursor=4"};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    char *path = h_fmt("/v1/robot/log%s", bad[i]);
    h_resp *r = h_get(path);
    r_expect(r, 400, "invalid_request");
    h_resp_free(r);
    free(path);
  }
}

/* The log after kill -9 and a restart with tiny files: the same entries, then rotation
 * that keeps audit_keep files and numbers that go on. */
static void check_restart_and_rotation(int port, const char *lockdir) {
  h_resp *before = get_log("");
  h_kill();
  char *extra = h_fmt("audit_max_mb = 0.001\naudit_keep = 2\nlock_dir = %s", lockdir);
  r_config(port, extra, port, NULL);
  free(extra);
  h_start();
  h_resp *after = get_log("");
  ASSERT_JSON_EQUAL(json_object_get(before->json, "entries"),
                    json_object_get(after->json, "entries"));
  const long long top = json_integer_value(json_object_get(entry(after, 0), "seq"));
  h_resp_free(before);
  h_resp_free(after);

  for (int i = 0; i < 8; i++) {
    h_resp *r = r_post("/v1/robot/commands", MOVE_BODY ", \"dry_run\": true}", NULL);
    r_expect(r, 200, NULL);
    h_resp_free(r);
  }
  char *dir = h_fmt("%s/audit", h_state_dir());
  char *p1 = h_fmt("%s/robot.log.2", dir), *p3 = h_fmt("%s/robot.log.3", dir);
  ASSERT(access(p1, F_OK) == 0);
  ASSERT(access(p3, F_OK) != 0);
  ASSERT_EQ(h_count_files(dir, "robot.log"), 3);
  h_resp *r = get_log("");
  const size_t n = json_array_size(json_object_get(r->json, "entries"));
  ASSERT(n >= 3 && n < 8 + 7); /* read across the files; the oldest are gone */
  ASSERT_EQ(json_integer_value(json_object_get(entry(r, 0), "seq")), top + 8);
  for (size_t i = 0; i + 1 < n; i++)
    ASSERT_EQ(json_integer_value(json_object_get(entry(r, i), "seq")),
              json_integer_value(json_object_get(entry(r, i + 1), "seq")) + 1);
  h_resp_free(r);
  free(p1);
  free(p3);
  free(dir);
}

/* Starts fieldgripd on the test's config with another state dir; waits (10 s) for it to
 * listen. Returns its pid; output goes to out_path. */
static pid_t start_other(const char *state, const char *out_path) {
  const int fd = open(out_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  ASSERT(fd >= 0);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  ASSERT(pid >= 0);
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    dup2(fd, 1);
    dup2(fd, 2);
    execl(h_daemon_path(), h_daemon_path(), "--config", h_config_path(), "--state-dir", state,
          "--listen", "127.0.0.1:0", (char *)NULL);
    _exit(127);
  }
  close(fd);
  for (double until = h_now_s() + 10; h_now_s() < until; h_sleep_ms(20)) {
    char *out = h_read_file(out_path, NULL);
    const int up = out && strstr(out, "listening on");
    free(out);
    if (up) return pid;
    int st;
    if (waitpid(pid, &st, WNOHANG) == pid) FG_TEST_FAIL("the second daemon exited");
  }
  kill(pid, SIGKILL);
  waitpid(pid, NULL, 0);
  FG_TEST_FAIL("the second daemon did not start listening in 10 s");
  return -1;
}

/* A second daemon for the same robot: refused while the first runs, with its pid named;
 * starts once the first was killed. */
static void check_claim(void) {
  char *state = h_fmt("%s/state2", h_tmpdir());
  const char *args[] = {"--config", h_config_path(), "--state-dir", state, "--listen",
                        "127.0.0.1:0", NULL};
  char *out = NULL;
  const int rc = h_run_daemon_capture(args, &out);
  ASSERT_NE(rc, 0);
  char *who = h_fmt("already driven by fieldgripd pid %d", (int)h_pid());
  ASSERT_STRCONTAINS(out, who);
  ASSERT_STRCONTAINS(out, "[robot]");
  free(who);
  free(out);
  h_kill(); /* the kernel drops the lock with the process */
  char *log = h_fmt("%s/other.log", h_tmpdir());
  const pid_t pid = start_other(state, log);
  kill(pid, SIGTERM);
  int st = 0;
  ASSERT_EQ(waitpid(pid, &st, 0), pid);
  ASSERT(WIFEXITED(st) && WEXITSTATUS(st) == 0);
  free(log);
  free(state);
}

/* <state>/audit made a file: motions are refused 503 and nothing is sent; dry runs work. */
static void check_unwritable(simproc *sim) {
  char *dir = h_fmt("%s/audit", h_state_dir());
  h_remove_tree(dir);
  h_write_file(dir, "x", 1);
  h_start();
  const int sent = simproc_writes(sim, -1, g_w, 64);
  h_resp *r = r_post("/v1/robot/commands", MOVE_BODY "}", NULL);
  r_expect(r, 503, "audit_unavailable");
  h_resp_free(r);
  r = r_post("/v1/gripper/close", "", NULL);
  r_expect(r, 503, "audit_unavailable");
  h_resp_free(r);
  r = r_post("/v1/robot/commands", MOVE_BODY ", \"dry_run\": true}", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(sim, -1, g_w, 64), sent);
  ASSERT(h_metric("fieldgrip_audit_write_errors_total") >= 3);
  h_stop();
  free(dir);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  simproc sim;
  /* done half a second after the acknowledgement: "wait": false is answered 202 before it */
  const char *sim_args[] = {"--done-delay-ms", "500", NULL};
  simproc_start(&sim, 0, sim_args);
  /* a lock folder of the test's own, so that runs on one machine never meet in /run/lock */
  char *lockdir = h_fmt("%s/locks", h_tmpdir());
  char *extra = h_fmt("lock_dir = %s", lockdir);
  r_config(sim.port, extra, sim.port, NULL);
  free(extra);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  ASSERT(r_wait_status("/v1/gripper", 10));
  check_entries(&sim);
  check_paging();
  check_restart_and_rotation(sim.port, lockdir);
  check_claim();
  check_unwritable(&sim);
  simproc_stop(&sim);
  free(lockdir);
  h_done();
  return 0;
}
