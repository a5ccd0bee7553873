/* The robot and gripper profiles against peers that are not fieldgrip's own code paths:
 * Debian's pymodbus (python3-pymodbus) as the robot controller, checked register by register,
 * and the gripper over Modbus RTU through a socat pseudo-terminal pair to fieldgrip-sim.
 * argv[1]: fieldgripd, argv[2]: fieldgrip-sim. Needs /usr/bin/python3 with pymodbus and
 * /usr/bin/socat (the CI script installs both). */
#include "robot_util.h"
#include "simproc.h"

#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static simproc_write g_w[16];
static pid_t g_socat = -1;

static void stop_socat(void) {
  if (g_socat > 0) {
    kill(g_socat, SIGTERM);
    waitpid(g_socat, NULL, 0);
    g_socat = -1;
  }
}

/* The worked example through pymodbus's server: every word as proto/modbus.md says. */
static void check_pymodbus(void) {
  const char *src = getenv("FG_SOURCE_DIR");
  ASSERT(src);
  char script[1024];
  snprintf(script, sizeof script, "%s/tests/sim/pymodbus_server.py", src);
  ASSERT(access("/usr/bin/python3", X_OK) == 0);
  const char *argv[] = {"/usr/bin/python3", script, "--base", "128", "--unit", "1", NULL};
  simproc peer;
  simproc_start_argv(&peer, argv);
  r_config(peer.port, NULL, 0, NULL);
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  h_resp *r = h_get("/v1/robot");
  ASSERT(json_is_integer(json_object_get(r->json, "ack"))); /* read, not null */
  ASSERT_EQ(json_integer_value(json_object_get(r->json, "ack")), 0);
  h_resp_free(r);
  /* seq 1 here (the peer starts at ack 0); the rest is the worked example */
  r = r_post("/v1/robot/commands", R_EXAMPLE_BODY "}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "done");
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&peer, 1, g_w, 16), 1);
  ASSERT_EQ(g_w[0].fn, 16);
  ASSERT_EQ(g_w[0].addr, 128);
  ASSERT_EQ(g_w[0].n, 13);
  ASSERT_EQ(g_w[0].words[0], 1);
  for (int i = 1; i < 13; i++)
    if (g_w[0].words[i] != r_example_int16[i])
      FG_TEST_FAIL("pymodbus received word %d = %u, expected %u", i, g_w[0].words[i],
                   r_example_int16[i]);
  /* and a second command continues the sequence */
  r = r_post("/v1/robot/commands", "{\"command\": \"move\", \"pose\": {\"position\": [-0.1, 0.2, "
             "0.3], \"quaternion\": [0, 1, 0, 0]}}", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&peer, 1, g_w, 16), 2);
  ASSERT_EQ(g_w[1].words[0], 2);
  ASSERT_EQ((int16_t)g_w[1].words[2], -1000);
  h_stop();
  simproc_stop(&peer);
}

/* The gripper on a serial line: socat links two pseudo-terminals; the simulator serves one,
 * the daemon's [gripper.modbus] transport = rtu opens the other. */
static void check_rtu(void) {
  ASSERT(access("/usr/bin/socat", X_OK) == 0);
  char a[600], b[600], pa[640], pb[640];
  snprintf(a, sizeof a, "%s/ttyA", h_tmpdir());
  snprintf(b, sizeof b, "%s/ttyB", h_tmpdir());
  snprintf(pa, sizeof pa, "pty,raw,echo=0,link=%s", a);
  snprintf(pb, sizeof pb, "pty,raw,echo=0,link=%s", b);
  atexit(stop_socat);
  const pid_t parent = getpid();
  g_socat = fork();
  ASSERT(g_socat >= 0);
  if (g_socat == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    execl("/usr/bin/socat", "socat", pa, pb, (char *)NULL);
    _exit(127);
  }
  struct stat st;
  for (int i = 0; i < 500 && (stat(a, &st) != 0 || stat(b, &st) != 0); i++) {
    const struct timespec ts = {0, 10000000};
    nanosleep(&ts, NULL);
  }
  ASSERT(stat(a, &st) == 0 && stat(b, &st) == 0);

  simproc sim;
  const char *args[] = {"--rtu", a, "--object-width-mm", "30", "--activation-ms", "50", NULL};
  simproc_start(&sim, 0, args);
  char text[1024];
  snprintf(text, sizeof text,
           "[gripper]\nmodel = robotiq-2f85\n[gripper.modbus]\ntransport = rtu\ndevice = %s\n"
           "baud = 115200\nunit_id = 9\n", b);
  h_write_config(text);
  h_start();
  ASSERT(r_wait_true("/v1/gripper", "connected", 10));
  h_resp *r = r_post("/v1/gripper/close", "", NULL);
  r_expect(r, 200, NULL);
  ASSERT(json_is_true(json_object_get(r->json, "object_detected")));
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "gripper_width")), 0.030, 0.0005);
  h_resp_free(r);
  r = r_post("/v1/gripper/move", "{\"width\": 0.07}", NULL);
  r_expect(r, 200, NULL);
  ASSERT_NEAR(json_real_value(json_object_get(r->json, "gripper_width")), 0.07, 0.0005);
  h_resp_free(r);
  r = h_get("/v1/gripper");
  ASSERT_STREQ(json_string_value(json_object_get(r->json, "state")), "ready");
  ASSERT_EQ(json_integer_value(json_object_get(json_object_get(r->json, "counters"), "errors")),
            0);
  h_resp_free(r);
  /* reset, activate, close, move: each once, as written */
  ASSERT_EQ(simproc_writes(&sim, 9, g_w, 16), 4);
  ASSERT_EQ(g_w[0].words[0], 0);
  ASSERT_EQ(g_w[1].words[0], 0x0100);
  ASSERT_EQ(g_w[2].words[1], 255);
  ASSERT_EQ(g_w[3].words[1], 45); /* round(255 x 0.015 / 0.085) */
  h_stop();
  simproc_stop(&sim);
  stop_socat();
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  check_pymodbus();
  check_rtu();
  h_done();
  printf("ok\n");
  return 0;
}
