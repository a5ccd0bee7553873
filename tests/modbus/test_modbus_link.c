/* Tests of lib/modbus link, peer and devices against fieldgrip-sim (argv[1]) on 127.0.0.1:
 * requests and their error classes (exception, timeout, connection lost), the reconnection
 * policy (backoff, two timeouts in a row, a reply later than its request's timeout, a peer
 * that comes up late, a restart on the same port), whether a failed write may have been
 * applied, the robot's ack/done handshake in both encodings, the gripper's activation and moves, and the peer's worker thread (calls,
 * a full queue, cancellation at shutdown, the idle job). Each case starts its own
 * simulator. An optional second argument runs one case. */
#include <errno.h>
#include <netinet/in.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include "simproc.h"
#include "test.h"

#include "core/error.h"
#include "core/log.h"
#include "core/pose.h"
#include "modbus/devices.h"
#include "modbus/link.h"
#include "modbus/peer.h"
#include "modbus/regs.h"

#define SLACK_MS 1500 /* upper bounds on timings: 2 shared cores, maybe AddressSanitizer */
#define BASE 128
#define ROBOT 1
#define GRIPPER 9

/* ---------------------------------------------------------------- simulator processes */

/* The simulator's request log so far (one line per write received). */
static void assert_log(const simproc *p, const char *want) {
  char *log = simproc_read(p->log);
  ASSERT_STREQ(log, want);
  free(log);
}

/* ---------------------------------------------------------------- sockets and links */

/* A loopback port nothing listens on (bound, read, closed). */
static int free_port(void) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  ASSERT(fd >= 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
  ASSERT_EQ(bind(fd, (struct sockaddr *)&a, sizeof a), 0);
  socklen_t len = sizeof a;
  ASSERT_EQ(getsockname(fd, (struct sockaddr *)&a, &len), 0);
  close(fd);
  return ntohs(a.sin_port);
}

/* A listening socket that never accepts nor answers: connections complete through the
 * backlog and requests go unanswered. Returns the fd; *port gets its port. */
static int silent_listener(int *port) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  ASSERT(fd >= 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
  ASSERT_EQ(bind(fd, (struct sockaddr *)&a, sizeof a), 0);
  ASSERT_EQ(listen(fd, 16), 0);
  socklen_t len = sizeof a;
  ASSERT_EQ(getsockname(fd, (struct sockaddr *)&a, &len), 0);
  *port = ntohs(a.sin_port);
  return fd;
}

static fg_mb_link_config tcp_config(const char *name, int port, int unit, int timeout_ms) {
  return (fg_mb_link_config){.name = name,
                             .transport = FG_MB_TCP,
                             .host = "127.0.0.1",
                             .port = port,
                             .unit_id = unit,
                             .timeout_ms = timeout_ms};
}

static fg_mb_link *link_open(const char *name, int port, int unit, int timeout_ms) {
  const fg_mb_link_config cfg = tcp_config(name, port, unit, timeout_ms);
  fg_mb_link *l = NULL;
  ASSERT_OK(fg_mb_link_new(&l, &cfg));
  ASSERT(l != NULL);
  return l;
}

static fg_mb_link_state link_state(fg_mb_link *l) {
  fg_mb_link_state st;
  fg_mb_link_state_get(l, &st);
  return st;
}

/* The milliseconds of "next attempt in N ms" in the calling thread's detail. */
static int next_attempt_ms(void) {
  const char *d = strstr(fg_error_detail(), "next attempt in ");
  if (!d) FG_TEST_FAIL("detail \"%s\" lacks \"next attempt in\"", fg_error_detail());
  return atoi(d + strlen("next attempt in "));
}

/* Calls fg_mb_link_ensure every 2 ms until it connects; each refusal must be the backoff's.
 * Returns the milliseconds it took; fails after limit_ms. */
static double ensure_until_connected(fg_mb_link *l, double limit_ms) {
  const double t0 = simproc_now_ms();
  while (fg_mb_link_ensure(l) != 0) {
    if (simproc_now_ms() - t0 > limit_ms)
      FG_TEST_FAIL("no connection within %.0f ms: %s", limit_ms, fg_error_detail());
    simproc_sleep_ms(2);
  }
  return simproc_now_ms() - t0;
}

/* The block of proto/modbus.md's worked example with sequence number seq. */
static void example_words(uint16_t seq, fg_pose_encoding e, uint16_t *w) {
  fg_pose_block b = {.seq = seq, .command = FG_ROBOT_PICK, .width_m = 0.08, .force_n = 40,
                     .approach_m = 0.10, .retreat_m = 0.10, .speed_mps = 0.10};
  b.p_world_m[0] = 0.4523;
  b.p_world_m[1] = -0.1207;
  b.p_world_m[2] = 0.0350;
  const double q_wxyz[4] = {0, 0.9238795, -0.3826834, 0};
  fg_rotvec_from_quat(q_wxyz, b.rotvec_rad);
  ASSERT_OK(fg_pose_block_encode(&b, e, w));
}

/* The simulator's motions take no time here: these tests time the handshake itself. */
static const char *const k_instant[] = {"--time-scale", "0", NULL};

static const char *const k_example_log =
    "write unit=1 fn=16 addr=128 n=13 words=7,1,4523,64329,350,2902,64334,0,800,40,1000,1000,"
    "100\n";

/* ---------------------------------------------------------------- link */

static void test_connect_rw(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", NULL});
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  char addr[64];
  snprintf(addr, sizeof addr, "127.0.0.1:%d", p.port);
  ASSERT_STREQ(fg_mb_link_address(l), addr);
  fg_mb_link_state st = link_state(l);
  ASSERT_EQ(st.connected, 0);
  ASSERT_STREQ(st.last_error, "");
  ASSERT_EQ(fg_mb_link_generation(l), 0);

  ASSERT_OK(fg_mb_link_ensure(l));
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  ASSERT_OK(fg_mb_link_ensure(l)); /* already connected: nothing changes */
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  ASSERT_EQ(link_state(l).connected, 1);

  uint16_t v[26], w[FG_POSE_MAX_WORDS];
  for (int i = 0; i < 16; i++) v[i] = 0xDEAD;
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  for (int i = 0; i < 16; i++) ASSERT_EQ(v[i], 0);
  example_words(7, FG_POSE_INT16, w);
  ASSERT_OK(fg_mb_write_registers(l, BASE, 13, w));
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 1);
  ASSERT_EQ(fg_mb_link_exception(l), 0);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  for (int i = 0; i < 13; i++) ASSERT_EQ(v[i], w[i]);
  ASSERT_EQ(v[13], 7); /* ack */
  ASSERT_EQ(v[14], 2); /* done: the motion took no time (--time-scale 0) */
  ASSERT_EQ(v[15], 0); /* stop */
  assert_log(&p, k_example_log);

  /* Input registers on the gripper's unit over a second link to the same server. */
  fg_mb_link *g = link_open("gripper", p.port, GRIPPER, 1000);
  uint16_t in[3] = {1, 1, 1};
  ASSERT_OK(fg_mb_read_input_registers(g, FG_ROBOTIQ_STATUS_ADDR, 3, in));
  ASSERT_EQ(in[0] | in[1] | in[2], 0);
  fg_mb_link_free(g);

  /* An address outside the block: exception 2, the connection stays. */
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 17, v), FG_EPEER, "exception 2");
  ASSERT_EQ(fg_mb_link_exception(l), 2);
  ASSERT_EQ(link_state(l).connected, 1);

  st = link_state(l);
  ASSERT_EQ(st.requests, 4);
  ASSERT_EQ(st.errors, 1);
  ASSERT_EQ(st.exceptions, 1);
  ASSERT_EQ(st.timeouts, 0);
  ASSERT_EQ(st.reconnects, 0);
  ASSERT_EQ(st.connect_failures, 0);
  ASSERT_STRCONTAINS(st.last_error, "exception 2");
  ASSERT(st.last_error_s > 1.5e9);

  /* A close is not a failure: the next request reconnects at once. */
  fg_mb_link_close(l);
  ASSERT_EQ(link_state(l).connected, 0);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 1, v));
  ASSERT_EQ(v[0], 7);
  ASSERT_EQ(fg_mb_link_generation(l), 2);
  ASSERT_EQ(link_state(l).reconnects, 1);
  fg_mb_link_free(l);
  fg_mb_link_free(NULL);
  simproc_stop(&p);
}

static void test_bad_config(void) {
  fg_mb_link *l = (fg_mb_link *)1;
  fg_mb_link_config cfg = tcp_config("robot", 502, 1, 1000);
  cfg.transport = 0;
  ASSERT_EQ(fg_mb_link_new(&l, &cfg), FG_EINVAL);
  ASSERT(l == NULL);
  cfg = tcp_config("robot", 502, 248, 1000);
  ASSERT_EQ(fg_mb_link_new(&l, &cfg), FG_EINVAL);
  cfg = tcp_config("robot", 502, 1, 0);
  ASSERT_EQ(fg_mb_link_new(&l, &cfg), FG_EINVAL);
  cfg = tcp_config("robot", 502, 1, 1000);
  cfg.host = "";
  ASSERT_EQ(fg_mb_link_new(&l, &cfg), FG_EINVAL);
  cfg.host = NULL;
  ASSERT_EQ(fg_mb_link_new(&l, &cfg), FG_EINVAL);
  cfg = tcp_config("robot", 502, 1, 1000);
  cfg.host = "::1";
  ASSERT_OK(fg_mb_link_new(&l, &cfg));
  ASSERT_STREQ(fg_mb_link_address(l), "[::1]:502");
  fg_mb_link_free(l);

  /* RTU: the serial device is the address; a missing one is unavailable, not invalid. */
  const fg_mb_link_config rtu = {.name = "gripper",
                                 .transport = FG_MB_RTU,
                                 .device = "/nonexistent/ttyUSB9",
                                 .baud = 115200,
                                 .parity = 'N',
                                 .unit_id = 9,
                                 .timeout_ms = 100};
  ASSERT_OK(fg_mb_link_new(&l, &rtu));
  ASSERT_STREQ(fg_mb_link_address(l), "/nonexistent/ttyUSB9");
  ASSERT_ERR(fg_mb_link_ensure(l), FG_EUNAVAIL, "gripper /nonexistent/ttyUSB9");
  ASSERT_EQ(link_state(l).connect_failures, 1);
  fg_mb_link_free(l);

  /* A peer with a bad config does not start. */
  fg_mb_peer *peer = (fg_mb_peer *)1;
  cfg = tcp_config("robot", 502, 300, 1000);
  ASSERT_EQ(fg_mb_peer_new(&peer, &cfg, 100, NULL, NULL), FG_EINVAL);
  ASSERT(peer == NULL);
}

static void test_exception(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--exception", "2", NULL});
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  uint16_t w[FG_POSE_MAX_WORDS], v[16];
  example_words(5, FG_POSE_INT16, w);
  char want[96];
  snprintf(want, sizeof want, "robot 127.0.0.1:%d answered", p.port);
  const char *who = want;
  ASSERT_ERR(fg_mb_write_registers(l, BASE, 13, w), FG_EPEER, who);
  ASSERT_STRCONTAINS(fg_error_detail(), "exception 2 (illegal data address)");
  ASSERT_STRCONTAINS(fg_error_detail(), "write of 13 registers at 128");
  ASSERT_EQ(fg_mb_link_exception(l), 2);
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 1);
  /* The connection stays usable; the exception code is the last request's. */
  ASSERT_EQ(link_state(l).connected, 1);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  ASSERT_EQ(fg_mb_link_exception(l), 0);
  for (int i = 0; i < 16; i++) ASSERT_EQ(v[i], 0); /* nothing was written */
  ASSERT_ERR(fg_mb_write_registers(l, BASE, 13, w), FG_EPEER, "exception 2");
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  fg_mb_link_state st = link_state(l);
  ASSERT_EQ(st.exceptions, 2);
  ASSERT_EQ(st.errors, 2);
  ASSERT_EQ(st.requests, 3);
  ASSERT_EQ(st.reconnects, 0);
  fg_mb_link_free(l);
  simproc_stop(&p);

  ASSERT_STREQ(fg_mb_exception_name(1), "illegal function");
  ASSERT_STREQ(fg_mb_exception_name(2), "illegal data address");
  ASSERT_STREQ(fg_mb_exception_name(4), "server device failure");
  ASSERT_STREQ(fg_mb_exception_name(11), "gateway target device failed to respond");
  ASSERT_STREQ(fg_mb_exception_name(99), "unknown exception");
}

static void test_timeout(void) {
  int port;
  int lfd = silent_listener(&port);
  const int timeout_ms = 100;
  fg_mb_link *l = link_open("robot", port, ROBOT, timeout_ms);
  ASSERT_OK(fg_mb_link_ensure(l));
  uint16_t v[2] = {0, 0};
  double t0 = simproc_now_ms();
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 2, v), FG_ETIMEDOUT, "did not answer");
  double ms = simproc_now_ms() - t0;
  ASSERT_STRCONTAINS(fg_error_detail(), "within 100 ms");
  ASSERT(ms >= timeout_ms - 1 && ms < timeout_ms + SLACK_MS);
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 1);
  /* One timeout keeps the connection. */
  ASSERT_EQ(link_state(l).connected, 1);
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  t0 = simproc_now_ms();
  ASSERT_ERR(fg_mb_write_registers(l, BASE, 2, v), FG_ETIMEDOUT, "did not answer");
  ms = simproc_now_ms() - t0;
  ASSERT(ms >= timeout_ms - 1 && ms < timeout_ms + SLACK_MS);
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 1);
  /* The second in a row closes it; the reconnection is not held back by a backoff (the
   * first call connects: a backoff would refuse it with "next attempt in"). */
  ASSERT_EQ(link_state(l).connected, 0);
  ASSERT_OK(fg_mb_link_ensure(l));
  ASSERT_EQ(fg_mb_link_generation(l), 2);
  fg_mb_link_state st = link_state(l);
  ASSERT_EQ(st.timeouts, 2);
  ASSERT_EQ(st.errors, 2);
  ASSERT_EQ(st.reconnects, 1);
  ASSERT_EQ(st.connected, 1);
  ASSERT_STRCONTAINS(st.last_error, "did not answer");
  /* The count starts again on the new connection. */
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 2, v), FG_ETIMEDOUT, "did not answer");
  ASSERT_EQ(link_state(l).connected, 1);
  fg_mb_link_free(l);
  close(lfd);
}

/* The size of a Modbus TCP reply to a read of 12 registers: MBAP header (7), function code,
 * byte count, 12 words. */
static const int k_read16_reply_bytes = 7 + 1 + 1 + 2 * 16;

/* Waits until a socket of this process connected to 127.0.0.1:port holds at least bytes
 * unread bytes: a reply has reached a link's socket and no request has taken it yet. The
 * link's socket is libmodbus's, so it is found among the process's descriptors. */
static void wait_unread(int port, int bytes) {
  const double t0 = simproc_now_ms();
  for (;;) {
    for (int fd = 0; fd < 1024; fd++) {
      struct sockaddr_in a;
      socklen_t len = sizeof a;
      int n = 0;
      if (getpeername(fd, (struct sockaddr *)&a, &len) == 0 && a.sin_family == AF_INET &&
          ntohs(a.sin_port) == port && ioctl(fd, FIONREAD, &n) == 0 && n >= bytes)
        return;
    }
    if (simproc_now_ms() - t0 > SLACK_MS)
      FG_TEST_FAIL("no reply of %d bytes from port %d within %d ms", bytes, port, SLACK_MS);
    simproc_sleep_ms(1);
  }
}

/* A peer that answers late: the timed-out request's reply must not spoil the next request,
 * and a success in between means two timeouts are not "in a row". */
static void test_late_reply(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 150);
  uint16_t w[FG_POSE_MAX_WORDS], v[16];
  example_words(7, FG_POSE_INT16, w);
  ASSERT_OK(fg_mb_write_registers(l, BASE, 13, w));

  /* The stopped simulator cannot answer in time (SIGSTOP takes effect before it returns to
   * its poll loop); once continued it answers, and the test waits until that reply lies in
   * the link's socket before the next request. */
  ASSERT_EQ(kill(p.pid, SIGSTOP), 0);
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 16, v), FG_ETIMEDOUT, "did not answer");
  ASSERT_EQ(kill(p.pid, SIGCONT), 0);
  wait_unread(p.port, k_read16_reply_bytes);
  memset(v, 0, sizeof v);
  ASSERT_OK(fg_mb_read_registers(l, BASE + 13, 2, v));
  ASSERT_EQ(v[0], 7);
  ASSERT_EQ(v[1], 2);
  ASSERT_EQ(fg_mb_link_generation(l), 1);

  ASSERT_EQ(kill(p.pid, SIGSTOP), 0);
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 16, v), FG_ETIMEDOUT, "did not answer");
  ASSERT_EQ(link_state(l).connected, 1); /* the first timeout since the success */
  ASSERT_EQ(kill(p.pid, SIGCONT), 0);
  wait_unread(p.port, k_read16_reply_bytes);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 1, v));
  ASSERT_EQ(v[0], 7);
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  fg_mb_link_free(l);
  simproc_stop(&p);
}

/* Sends SIGCONT to a stopped simulator once the link has counted its requests-th request:
 * that request has passed its flush, so the reply to the request before it, which the
 * simulator sends first, arrives after the flush. */
typedef struct {
  fg_mb_link *link;
  pid_t pid;
  uint64_t requests;
} cont_after;

static void *cont_after_thread(void *arg) {
  cont_after *c = arg;
  fg_mb_link_state st;
  const double t0 = simproc_now_ms();
  do {
    simproc_sleep_ms(1);
    fg_mb_link_state_get(c->link, &st);
  } while (st.requests < c->requests && simproc_now_ms() - t0 < 10 * SLACK_MS);
  kill(c->pid, SIGCONT);
  return NULL;
}

/* A reply later than the flush before the next request reaches that request first: it is
 * dropped, and the request takes its own reply from the same connection, for a read and
 * for a write. */
static void test_reply_after_flush(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  uint16_t w[FG_POSE_MAX_WORDS], v[16];
  example_words(7, FG_POSE_INT16, w);
  ASSERT_OK(fg_mb_write_registers(l, BASE, 13, w));

  ASSERT_EQ(kill(p.pid, SIGSTOP), 0);
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 16, v), FG_ETIMEDOUT, "did not answer");
  cont_after c = {.link = l, .pid = p.pid, .requests = link_state(l).requests + 1};
  pthread_t t;
  ASSERT_EQ(pthread_create(&t, NULL, cont_after_thread, &c), 0);
  memset(v, 0, sizeof v);
  ASSERT_OK(fg_mb_read_registers(l, BASE + 13, 2, v));
  ASSERT_EQ(pthread_join(t, NULL), 0);
  ASSERT_EQ(v[0], 7);
  ASSERT_EQ(v[1], 2);

  ASSERT_EQ(kill(p.pid, SIGSTOP), 0);
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 16, v), FG_ETIMEDOUT, "did not answer");
  c.requests = link_state(l).requests + 1;
  ASSERT_EQ(pthread_create(&t, NULL, cont_after_thread, &c), 0);
  example_words(8, FG_POSE_INT16, w);
  ASSERT_OK(fg_mb_write_registers(l, BASE, 13, w));
  ASSERT_EQ(pthread_join(t, NULL), 0);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 1, v));
  ASSERT_EQ(v[0], 8);

  fg_mb_link_state st = link_state(l);
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  ASSERT_EQ(st.reconnects, 0);
  ASSERT_EQ(st.timeouts, 2);
  ASSERT_EQ(st.errors, 2);
  ASSERT_EQ(st.requests, 6);
  fg_mb_link_free(l);
  simproc_stop(&p);
}

/* Whether a call that returned just now was surely made inside a backoff of window_ms that
 * began no earlier than since_ms. */
static int inside_window(double since_ms, int window_ms) {
  return simproc_now_ms() - since_ms < window_ms - 1;
}

/* One run of test_peer_down_then_up. Returns 0 when a call meant to land inside a backoff
 * came too late to tell (a starved test thread), so that the case is run again, 1 when every
 * check was made. */
static int peer_down_then_up_once(void) {
  const int port = free_port();
  fg_mb_link *l = link_open("robot", port, ROBOT, 500);
  char want[96];
  snprintf(want, sizeof want, "robot 127.0.0.1:%d", port);
  const char *who = want;
  const double t_first = simproc_now_ms(); /* the backoff starts after this instant */
  ASSERT_ERR(fg_mb_link_ensure(l), FG_EUNAVAIL, who);
  ASSERT_STRCONTAINS(fg_error_detail(), "refused");
  fg_mb_link_state st = link_state(l);
  ASSERT_EQ(st.connected, 0);
  ASSERT_EQ(st.connect_failures, 1);
  ASSERT_STRCONTAINS(st.last_error, "refused");
  ASSERT(st.last_error_s > 1.5e9);

  /* At once again: refused by the backoff, without a connection attempt (the count of
   * refusals stays). */
  ASSERT_ERR(fg_mb_link_ensure(l), FG_EUNAVAIL, who);
  if (!inside_window(t_first, 100)) goto again;
  int ms = next_attempt_ms();
  ASSERT(ms > 0 && ms <= 100);
  ASSERT_STRCONTAINS(fg_error_detail(), "refused"); /* the cause is still told */
  ASSERT_EQ(link_state(l).connect_failures, 1);
  /* A request meanwhile fails the same way and cannot have been sent. */
  uint16_t v[16];
  ASSERT_EQ(fg_mb_read_registers(l, BASE, 16, v), FG_EUNAVAIL);
  if (!inside_window(t_first, 100)) goto again;
  ASSERT_STRCONTAINS(fg_error_detail(), "next attempt in");
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 0);
  ASSERT_EQ(link_state(l).requests, 0);
  ASSERT_EQ(link_state(l).connect_failures, 1);

  /* After the first backoff (100 ms) a real attempt, refused again: the backoff doubles.
   * Every call until then is refused by the backoff alone; the loop ends at the attempt. */
  double t_attempt;
  for (;;) {
    t_attempt = simproc_now_ms();
    ASSERT_ERR(fg_mb_link_ensure(l), FG_EUNAVAIL, who);
    if (link_state(l).connect_failures == 2) break;
    ASSERT_EQ(link_state(l).connect_failures, 1);
    ASSERT_STRCONTAINS(fg_error_detail(), "next attempt in");
    if (simproc_now_ms() - t_first > 100 + SLACK_MS)
      FG_TEST_FAIL("no second attempt within %d ms", 100 + SLACK_MS);
    simproc_sleep_ms(2);
  }
  ASSERT(simproc_now_ms() - t_first >= 100 - 1); /* not before the first backoff ran out */
  ASSERT_STRCONTAINS(fg_error_detail(), "refused");
  ASSERT_ERR(fg_mb_link_ensure(l), FG_EUNAVAIL, who);
  if (!inside_window(t_attempt, 200)) goto again;
  const double t_asked = simproc_now_ms();
  ms = next_attempt_ms();
  /* 200 ms from the refusal, which lies between t_attempt and t_asked */
  ASSERT(ms <= 200 && ms >= 200 - (t_asked - t_attempt) - 1);

  /* The peer comes up; only this thread calls ensure, so no attempt is made while it
   * starts, and the first one after the backoff connects. */
  simproc p;
  simproc_start(&p, port, NULL);
  const double up_ms = simproc_now_ms() - t_attempt;
  ensure_until_connected(l, 200 + SLACK_MS);
  const double connected_ms = simproc_now_ms() - t_attempt;
  fprintf(stderr, "peer up %.0f ms after the second refusal, connected after %.0f ms\n", up_ms,
          connected_ms);
  ASSERT(connected_ms >= 200 - 1); /* the backoff held until its end ... */
  ASSERT(connected_ms < (up_ms > 200 ? up_ms : 200) + SLACK_MS); /* ... and no longer */
  st = link_state(l);
  ASSERT_EQ(st.connect_failures, 2); /* the backoff, not more refusals, held it back */
  ASSERT_EQ(st.connected, 1);
  ASSERT_EQ(st.reconnects, 0);
  ASSERT_EQ(fg_mb_link_generation(l), 1);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  fg_mb_link_free(l);
  simproc_stop(&p);
  return 1;

again:
  fprintf(stderr, "peer_down_then_up: a call came after its backoff window; again\n");
  fg_mb_link_free(l);
  return 0;
}

/* Nothing listens at first: refusals, a backoff that doubles and refuses without trying,
 * then the peer comes up on that port and the first attempt after the backoff connects. */
static void test_peer_down_then_up(void) {
  for (int run = 0; run < 10; run++)
    if (peer_down_then_up_once()) return;
  FG_TEST_FAIL("ten runs in a row were too slow to call inside a 100 ms backoff");
}

/* The peer dies mid-session (SIGKILL) and a new one starts on the same port. */
static void test_peer_killed_restart(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  const int port = p.port;
  const int timeout_ms = 5000; /* far above any delay of a busy machine */
  fg_mb_link *l = link_open("robot", port, ROBOT, timeout_ms);
  uint16_t w[FG_POSE_MAX_WORDS], v[16];
  example_words(7, FG_POSE_INT16, w);
  ASSERT_OK(fg_mb_write_registers(l, BASE, 13, w));
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  ASSERT_EQ(v[13], 7);
  simproc_kill(&p);

  /* The request went out on what looked like a live connection: it may have been sent.
   * Noticed at once (FG_EUNAVAIL), not after the response timeout (FG_ETIMEDOUT). */
  double t0 = simproc_now_ms();
  ASSERT_ERR(fg_mb_read_registers(l, BASE, 16, v), FG_EUNAVAIL, "connection lost");
  ASSERT(simproc_now_ms() - t0 < timeout_ms);
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 1);
  ASSERT_EQ(link_state(l).connected, 0);
  /* The next one is refused by the backoff and cannot have been sent. (A call that a busy
   * machine delays past the backoff tries to connect, is refused, and cannot have been sent
   * either.) */
  ASSERT_EQ(fg_mb_write_registers(l, BASE, 13, w), FG_EUNAVAIL);
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 0);
  if (inside_window(t0, 100)) {
    ASSERT_STRCONTAINS(fg_error_detail(), "next attempt in");
    ASSERT(next_attempt_ms() <= 100);
  }

  simproc_start(&p, port, NULL);
  ASSERT_EQ(p.port, port);
  ensure_until_connected(l, 100 + SLACK_MS);
  ASSERT_EQ(fg_mb_link_generation(l), 2);
  fg_mb_link_state st = link_state(l);
  ASSERT_EQ(st.reconnects, 1);
  ASSERT_EQ(st.connected, 1);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  for (int i = 0; i < 12; i++) ASSERT_EQ(v[i], 0); /* a fresh peer */
  ASSERT_OK(fg_mb_write_registers(l, BASE, 13, w));
  assert_log(&p, k_example_log);
  fg_mb_link_free(l);
  simproc_stop(&p);
}

/* The peer applies a write and drops the connection without answering: the write fails,
 * says it may have been sent, and indeed was applied. */
static void test_drop_write(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--drop-after", "2", NULL});
  const int timeout_ms = 5000; /* far above any delay of a busy machine */
  fg_mb_link *l = link_open("robot", p.port, ROBOT, timeout_ms);
  uint16_t w[FG_POSE_MAX_WORDS], v[16];
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v)); /* request 1 */
  example_words(7, FG_POSE_INT16, w);
  double t0 = simproc_now_ms();
  ASSERT_ERR(fg_mb_write_registers(l, BASE, 13, w), FG_EUNAVAIL, "connection lost during");
  ASSERT(simproc_now_ms() - t0 < timeout_ms); /* the drop, not the response timeout */
  ASSERT_STRCONTAINS(fg_error_detail(), "write of 13 registers at 128");
  ASSERT_EQ(fg_mb_link_maybe_sent(l), 1);
  ASSERT_EQ(fg_mb_link_exception(l), 0);
  ASSERT_EQ(link_state(l).connected, 0);
  ensure_until_connected(l, 100 + SLACK_MS);
  ASSERT_OK(fg_mb_read_registers(l, BASE, 16, v));
  for (int i = 0; i < 13; i++) ASSERT_EQ(v[i], w[i]);
  ASSERT_EQ(v[13], 7); /* the robot accepted the "failed" write */
  assert_log(&p, k_example_log);
  fg_mb_link_free(l);
  simproc_stop(&p);
}

/* ---------------------------------------------------------------- robot */

static int g_cancel_calls;

static int cancel_after_three(void *arg) {
  (void)arg;
  return ++g_cancel_calls >= 3;
}

static void test_robot_handshake(void) {
  simproc p;
  simproc_start(&p, 0,
                (const char *const[]){"--ack-delay-ms", "50", "--done-delay-ms", "50", NULL});
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  const fg_robot_profile rp = {.base = BASE, .encoding = FG_POSE_INT16, .ack_timeout_ms = 1000,
                               .done_timeout_ms = 2000};
  uint16_t ack = 0xFFFF;
  int status = -1;
  ASSERT_OK(fg_robot_read_ack(l, &rp, &ack, &status));
  ASSERT_EQ(ack, 0);
  ASSERT_EQ(status, FG_ROBOT_IDLE);
  const uint16_t seq = fg_seq_next(ack);
  ASSERT_EQ(seq, 1);

  uint16_t w[FG_POSE_MAX_WORDS];
  example_words(seq, FG_POSE_INT16, w);
  double t0 = simproc_now_ms();
  ASSERT_OK(fg_robot_write(l, &rp, w));
  ASSERT_OK(fg_robot_wait_ack(l, &rp, seq, &status, NULL, NULL));
  double t_ack = simproc_now_ms() - t0;
  ASSERT(t_ack >= 50 - 1 && t_ack < 50 + SLACK_MS);
  /* Busy, unless this thread was held up past the done-delay as well. */
  if (t_ack < 100 - 1) ASSERT_EQ(status, FG_ROBOT_BUSY);
  ASSERT(status == FG_ROBOT_BUSY || status == FG_ROBOT_DONE);
  ASSERT_OK(fg_robot_wait_done(l, &rp, seq, &status, NULL, NULL));
  double t_done = simproc_now_ms() - t0;
  ASSERT(t_done >= 100 - 1 && t_done < 100 + SLACK_MS);
  ASSERT_EQ(status, FG_ROBOT_DONE);
  fprintf(stderr, "robot ack after %.1f ms (delay 50), done after %.1f ms (50 + 50)\n", t_ack,
          t_done);
  assert_log(&p, "write unit=1 fn=16 addr=128 n=13 "
                 "words=1,1,4523,64329,350,2902,64334,0,800,40,1000,1000,100\n");

  /* ... and the next seq completes as usual on the same connection. */
  example_words(2, FG_POSE_INT16, w);
  ASSERT_OK(fg_robot_write(l, &rp, w));
  ASSERT_OK(fg_robot_wait_ack(l, &rp, 2, &status, NULL, NULL));
  ASSERT_OK(fg_robot_wait_done(l, &rp, 2, &status, NULL, NULL));
  ASSERT_EQ(status, FG_ROBOT_DONE);
  fg_mb_link_free(l);
  simproc_stop(&p);

  /* wait_done notices that the robot moved on to another seq. A robot that never finishes
   * on its own: seq 2 cannot be done before seq 3 supersedes it, however slow this thread. */
  simproc_start(&p, 0,
                (const char *const[]){"--ack-delay-ms", "50", "--done-delay-ms", "60000", NULL});
  l = link_open("robot", p.port, ROBOT, 1000);
  example_words(2, FG_POSE_INT16, w);
  ASSERT_OK(fg_robot_write(l, &rp, w));
  ASSERT_OK(fg_robot_wait_ack(l, &rp, 2, &status, NULL, NULL));
  ASSERT_EQ(status, FG_ROBOT_BUSY);
  example_words(3, FG_POSE_INT16, w);
  ASSERT_OK(fg_robot_write(l, &rp, w));
  ASSERT_ERR(fg_robot_wait_done(l, &rp, 2, &status, NULL, NULL), FG_EINVAL, "from 2 to 3");
  ASSERT_EQ(status, FG_ROBOT_BUSY); /* seq 3 acknowledged and under way */
  fg_mb_link_free(l);
  simproc_stop(&p);
}

static void test_robot_never_ack(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--never-ack", NULL});
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  const fg_robot_profile rp = {.base = BASE, .encoding = FG_POSE_INT16, .ack_timeout_ms = 200,
                               .done_timeout_ms = 2000};
  uint16_t w[FG_POSE_MAX_WORDS];
  example_words(1, FG_POSE_INT16, w);
  ASSERT_OK(fg_robot_write(l, &rp, w));
  int status = -1;
  double t0 = simproc_now_ms();
  ASSERT_ERR(fg_robot_wait_ack(l, &rp, 1, &status, NULL, NULL), FG_ETIMEDOUT,
             "did not acknowledge seq 1 within 200 ms");
  double ms = simproc_now_ms() - t0;
  ASSERT_STRCONTAINS(fg_error_detail(), "ack register 141 holds 0");
  ASSERT(ms >= 200 - 1 && ms < 200 + SLACK_MS);
  ASSERT_EQ(status, FG_ROBOT_IDLE);
  fprintf(stderr, "no ack: gave up after %.1f ms (ack_timeout_ms 200)\n", ms);
  /* The link is fine: an ack timeout is the robot's, not the connection's. */
  ASSERT_EQ(link_state(l).connected, 1);
  ASSERT_EQ(link_state(l).errors, 0);
  /* The block is written once, never again. */
  assert_log(&p, "write unit=1 fn=16 addr=128 n=13 "
                 "words=1,1,4523,64329,350,2902,64334,0,800,40,1000,1000,100\n");

  /* A cancel function stops the wait early: with an ack timeout no run can reach, only the
   * cancel can end it, at its third call. */
  const fg_robot_profile rp_long = {.base = BASE, .encoding = FG_POSE_INT16,
                                    .ack_timeout_ms = 600000, .done_timeout_ms = 2000};
  g_cancel_calls = 0;
  t0 = simproc_now_ms();
  ASSERT_ERR(fg_robot_wait_ack(l, &rp_long, 1, &status, cancel_after_three, NULL), FG_ECANCELED,
             "stopped");
  ASSERT_EQ(g_cancel_calls, 3);
  ASSERT(simproc_now_ms() - t0 < SLACK_MS);
  fg_mb_link_free(l);
  simproc_stop(&p);
}

static void test_robot_fail(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--fail", "--done-delay-ms", "30", NULL});
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  const fg_robot_profile rp = {.base = BASE, .encoding = FG_POSE_INT16, .ack_timeout_ms = 1000,
                               .done_timeout_ms = 2000};
  uint16_t w[FG_POSE_MAX_WORDS];
  example_words(9, FG_POSE_INT16, w);
  ASSERT_OK(fg_robot_write(l, &rp, w));
  int status = -1;
  ASSERT_OK(fg_robot_wait_ack(l, &rp, 9, &status, NULL, NULL));
  ASSERT_EQ(status, FG_ROBOT_BUSY);
  ASSERT_OK(fg_robot_wait_done(l, &rp, 9, &status, NULL, NULL));
  ASSERT_EQ(status, FG_ROBOT_FAILED);
  fg_mb_link_free(l);
  simproc_stop(&p);

  /* A robot that stays busy: done_timeout_ms. */
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--done-delay-ms", "60000", NULL});
  l = link_open("robot", p.port, ROBOT, 1000);
  const fg_robot_profile rp2 = {.base = BASE, .encoding = FG_POSE_INT16, .ack_timeout_ms = 1000,
                                .done_timeout_ms = 150};
  example_words(4, FG_POSE_INT16, w);
  ASSERT_OK(fg_robot_write(l, &rp2, w));
  ASSERT_OK(fg_robot_wait_ack(l, &rp2, 4, &status, NULL, NULL));
  double t0 = simproc_now_ms();
  ASSERT_ERR(fg_robot_wait_done(l, &rp2, 4, &status, NULL, NULL), FG_ETIMEDOUT,
             "did not report seq 4 done within 150 ms");
  double ms = simproc_now_ms() - t0;
  ASSERT(ms >= 150 - 1 && ms < 150 + SLACK_MS);
  ASSERT_EQ(status, FG_ROBOT_BUSY);
  fg_mb_link_free(l);
  simproc_stop(&p);
}

static void test_robot_float32(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--encoding", "float32", "--base", "200",
                                              "--ack-init", "6", NULL});
  fg_mb_link *l = link_open("robot", p.port, ROBOT, 1000);
  const fg_robot_profile rp = {.base = 200, .encoding = FG_POSE_FLOAT32, .ack_timeout_ms = 1000,
                               .done_timeout_ms = 2000};
  uint16_t ack;
  int status;
  ASSERT_OK(fg_robot_read_ack(l, &rp, &ack, &status)); /* registers 223, 224 */
  ASSERT_EQ(ack, 6);
  const uint16_t seq = fg_seq_next(ack);
  uint16_t w[FG_POSE_MAX_WORDS];
  example_words(seq, FG_POSE_FLOAT32, w);
  ASSERT_OK(fg_robot_write(l, &rp, w));
  ASSERT_OK(fg_robot_wait_ack(l, &rp, seq, &status, NULL, NULL));
  ASSERT_OK(fg_robot_wait_done(l, &rp, seq, &status, NULL, NULL));
  ASSERT_EQ(status, FG_ROBOT_DONE);

  uint16_t v[26];
  ASSERT_OK(fg_mb_read_registers(l, 200, 26, v));
  const uint16_t want[23] = {0x0007, 0x0001, 0x3EE7, 0x93DE, 0xBDF7, 0x3190, 0x3D0F, 0x5C29,
                             0x4039, 0xC1CB, 0xBF99, 0xE2DA, 0x0000, 0x0000, 0x3DA3, 0xD70A,
                             0x0028, 0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD};
  for (int i = 0; i < 23; i++)
    if (v[i] != want[i]) FG_TEST_FAIL("register %d: 0x%04X, want 0x%04X", 200 + i, v[i], want[i]);
  ASSERT_EQ(v[23], 7);
  ASSERT_EQ(v[24], 2);
  fg_pose_block d;
  fg_pose_block_decode(v, FG_POSE_FLOAT32, &d);
  ASSERT_NEAR(d.p_world_m[1], -0.1207, 1e-7);
  ASSERT_NEAR(d.rotvec_rad[0], 2.902453, 1e-6);
  assert_log(&p, "write unit=1 fn=16 addr=200 n=23 words=7,1,16103,37854,48631,12688,15631,"
                 "23593,16441,49611,49049,58074,0,0,15779,55050,40,15820,52429,15820,52429,"
                 "15820,52429\n");
  fg_mb_link_free(l);
  simproc_stop(&p);
}

/* ---------------------------------------------------------------- gripper */

static void test_gripper(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--activation-ms", "100", "--stroke-ms", "100",
                                              "--object-width-mm", "40", NULL});
  fg_mb_link *l = link_open("gripper", p.port, GRIPPER, 1000);
  fg_robotiq_status s;
  ASSERT_OK(fg_gripper_read(l, &s));
  ASSERT_EQ(s.sta, 0);
  ASSERT_EQ(s.act, 0);
  /* Not activated: refused before anything is written. */
  ASSERT_ERR(fg_gripper_move(l, 255, 255, 255, 1000, &s), FG_EBUSY, "not activated");
  assert_log(&p, "");

  double t0 = simproc_now_ms();
  ASSERT_OK(fg_gripper_activate(l, 2000, &s));
  double t_act = simproc_now_ms() - t0;
  ASSERT(t_act >= 100 - 1 && t_act < 100 + SLACK_MS);
  ASSERT_EQ(s.sta, 3);
  ASSERT_EQ(s.act, 1);
  ASSERT_EQ(s.position, 0);
  assert_log(&p, "write unit=9 fn=16 addr=1000 n=3 words=0,0,0\n"
                 "write unit=9 fn=16 addr=1000 n=3 words=256,0,0\n");

  /* Close on the 40 mm object: contact while closing, at the object's position. */
  int obj_pos;
  ASSERT_OK(fg_robotiq_width_to_position(&fg_robotiq_2f85, 0.040, &obj_pos));
  ASSERT_EQ(obj_pos, 135);
  t0 = simproc_now_ms();
  ASSERT_OK(fg_gripper_move(l, 255, 255, 255, 2000, &s));
  double t_close = simproc_now_ms() - t0;
  ASSERT_EQ(s.obj, 2);
  ASSERT(fg_robotiq_object_detected(&s));
  ASSERT_EQ(s.echo, 255);
  ASSERT(abs(s.position - obj_pos) <= 1);
  ASSERT_NEAR(fg_robotiq_position_to_width(&fg_robotiq_2f85, s.position), 0.040, 0.0004);
  ASSERT(s.current > 0);
  ASSERT(t_close >= 100.0 * 135 / 255 - 1); /* the fingers took their time */
  ASSERT_EQ(s.flt, 0);

  /* Open fully: at the position, nothing detected. */
  ASSERT_OK(fg_gripper_move(l, 0, 255, 0, 2000, &s));
  ASSERT_EQ(s.obj, 3);
  ASSERT_EQ(s.position, 0);
  ASSERT_EQ(s.echo, 0);
  ASSERT(!fg_robotiq_object_detected(&s));
  /* Partway, short of the object. */
  ASSERT_OK(fg_gripper_move(l, 100, 128, 0, 2000, &s));
  ASSERT_EQ(s.obj, 3);
  ASSERT_EQ(s.position, 100);
  assert_log(&p, "write unit=9 fn=16 addr=1000 n=3 words=0,0,0\n"
                 "write unit=9 fn=16 addr=1000 n=3 words=256,0,0\n"
                 "write unit=9 fn=16 addr=1000 n=3 words=2304,255,65535\n"
                 "write unit=9 fn=16 addr=1000 n=3 words=2304,0,65280\n"
                 "write unit=9 fn=16 addr=1000 n=3 words=2304,100,32768\n");
  fg_mb_link_free(l);
  simproc_stop(&p);

  /* An activation that takes longer than allowed; a move meanwhile is refused. */
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--activation-ms", "5000", NULL});
  l = link_open("gripper", p.port, GRIPPER, 1000);
  t0 = simproc_now_ms();
  ASSERT_ERR(fg_gripper_activate(l, 100, &s), FG_ETIMEDOUT, "did not finish its activation");
  double ms = simproc_now_ms() - t0;
  ASSERT(ms >= 100 - 1 && ms < 100 + SLACK_MS);
  ASSERT_EQ(s.sta, 1);
  ASSERT_ERR(fg_gripper_move(l, 255, 255, 255, 1000, &s), FG_EBUSY, "gSTA 1");
  fg_mb_link_free(l);
  simproc_stop(&p);
}

/* ---------------------------------------------------------------- peer */

typedef struct {
  pthread_t thread;
  uint16_t regs[16];
} read_job;

static int job_read(fg_mb_link *l, void *arg) {
  read_job *j = arg;
  j->thread = pthread_self();
  return fg_mb_read_registers(l, BASE, 16, j->regs);
}

static int job_write_example(fg_mb_link *l, void *arg) {
  uint16_t w[FG_POSE_MAX_WORDS];
  example_words(*(uint16_t *)arg, FG_POSE_INT16, w);
  return fg_mb_write_registers(l, BASE, 13, w);
}

static int job_read_outside(fg_mb_link *l, void *arg) {
  uint16_t v[17];
  (void)arg;
  return fg_mb_read_registers(l, BASE, 17, v);
}

static int job_fail(fg_mb_link *l, void *arg) {
  (void)l;
  return fg_fail(FG_EPEER, "job detail %d", *(int *)arg);
}

static void test_peer_call(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  const fg_mb_link_config cfg = tcp_config("robot", p.port, ROBOT, 1000);
  fg_mb_peer *peer = NULL;
  ASSERT_OK(fg_mb_peer_new(&peer, &cfg, 1000, NULL, NULL));
  char addr[64];
  snprintf(addr, sizeof addr, "127.0.0.1:%d", p.port);
  ASSERT_STREQ(fg_mb_peer_address(peer), addr);

  read_job j;
  memset(&j, 0, sizeof j);
  j.thread = pthread_self();
  for (int i = 0; i < 16; i++) j.regs[i] = 0xDEAD;
  ASSERT_OK(fg_mb_peer_call(peer, job_read, &j));
  ASSERT(!pthread_equal(j.thread, pthread_self()));
  for (int i = 0; i < 16; i++) ASSERT_EQ(j.regs[i], 0);
  const pthread_t worker = j.thread;
  uint16_t seq = 7;
  ASSERT_OK(fg_mb_peer_call(peer, job_write_example, &seq));
  ASSERT_OK(fg_mb_peer_call(peer, job_read, &j));
  ASSERT(pthread_equal(j.thread, worker)); /* always the same thread */
  ASSERT_EQ(j.regs[0], 7);
  ASSERT_EQ(j.regs[13], 7);

  /* The job's code and detail reach the caller. */
  int n = 42;
  fg_error_clear();
  ASSERT_EQ(fg_mb_peer_call(peer, job_fail, &n), FG_EPEER);
  ASSERT_STREQ(fg_error_detail(), "job detail 42");
  ASSERT_ERR(fg_mb_peer_call(peer, job_read_outside, NULL), FG_EPEER,
             "exception 2 (illegal data address)");

  fg_mb_link_state st;
  fg_mb_peer_state(peer, &st);
  ASSERT_EQ(st.connected, 1);
  ASSERT_EQ(st.requests, 4);
  ASSERT_EQ(st.exceptions, 1);
  fg_mb_peer_free(peer);
  fg_mb_peer_free(NULL);
  assert_log(&p, k_example_log);
  simproc_stop(&p);
}

/* A job that blocks until released, and jobs that record the order they ran in. */
typedef struct {
  pthread_mutex_t lock;
  pthread_cond_t cond;
  int started, released;
  int ran[64], n_ran;       /* job indices in the order their fn ran */
  int done_rc[64], n_done;  /* done's rc by job index; n_done calls */
} job_board;

typedef struct {
  job_board *b;
  int index;
} board_job;

static void board_init(job_board *b) {
  memset(b, 0, sizeof *b);
  pthread_mutex_init(&b->lock, NULL);
  pthread_cond_init(&b->cond, NULL);
  for (int i = 0; i < 64; i++) b->done_rc[i] = 1;
}

static void board_free(job_board *b) {
  pthread_cond_destroy(&b->cond);
  pthread_mutex_destroy(&b->lock);
}

static int job_block(fg_mb_link *l, void *arg) {
  board_job *j = arg;
  (void)l;
  pthread_mutex_lock(&j->b->lock);
  j->b->started = 1;
  pthread_cond_broadcast(&j->b->cond);
  while (!j->b->released) pthread_cond_wait(&j->b->cond, &j->b->lock);
  pthread_mutex_unlock(&j->b->lock);
  return 5;
}

static int job_record(fg_mb_link *l, void *arg) {
  board_job *j = arg;
  (void)l;
  pthread_mutex_lock(&j->b->lock);
  j->b->ran[j->b->n_ran++] = j->index;
  pthread_mutex_unlock(&j->b->lock);
  return j->index;
}

static void job_done(void *arg, int rc) {
  board_job *j = arg;
  pthread_mutex_lock(&j->b->lock);
  j->b->done_rc[j->index] = rc;
  j->b->n_done++;
  pthread_cond_broadcast(&j->b->cond);
  pthread_mutex_unlock(&j->b->lock);
}

static void board_wait_started(job_board *b) {
  pthread_mutex_lock(&b->lock);
  while (!b->started) pthread_cond_wait(&b->cond, &b->lock);
  pthread_mutex_unlock(&b->lock);
}

static void board_release(job_board *b) {
  pthread_mutex_lock(&b->lock);
  b->released = 1;
  pthread_cond_broadcast(&b->cond);
  pthread_mutex_unlock(&b->lock);
}

static void board_wait_done(job_board *b, int n) {
  pthread_mutex_lock(&b->lock);
  while (b->n_done < n) pthread_cond_wait(&b->cond, &b->lock);
  pthread_mutex_unlock(&b->lock);
}

/* A peer nobody listens for: these jobs do not touch the link. */
static fg_mb_peer *peer_nowhere(void) {
  const fg_mb_link_config cfg = tcp_config("gripper", free_port(), GRIPPER, 200);
  fg_mb_peer *peer = NULL;
  ASSERT_OK(fg_mb_peer_new(&peer, &cfg, 1000, NULL, NULL));
  return peer;
}

static void test_peer_queue_full(void) {
  fg_mb_peer *peer = peer_nowhere();
  job_board b;
  board_init(&b);
  board_job jobs[FG_MB_PEER_QUEUE + 2];
  for (int i = 0; i < FG_MB_PEER_QUEUE + 2; i++) jobs[i] = (board_job){&b, i};
  /* Job 0 occupies the worker; 1 .. 32 fill the queue; 33 does not fit. */
  ASSERT_OK(fg_mb_peer_post(peer, job_block, &jobs[0], job_done));
  board_wait_started(&b);
  for (int i = 1; i <= FG_MB_PEER_QUEUE; i++)
    ASSERT_OK(fg_mb_peer_post(peer, job_record, &jobs[i], job_done));
  ASSERT_ERR(fg_mb_peer_post(peer, job_record, &jobs[FG_MB_PEER_QUEUE + 1], job_done), FG_EBUSY,
             "requests waiting");
  read_job rj;
  ASSERT_ERR(fg_mb_peer_call(peer, job_read, &rj), FG_EBUSY, "requests waiting");
  board_release(&b);
  board_wait_done(&b, FG_MB_PEER_QUEUE + 1);
  ASSERT_EQ(b.done_rc[0], 5);
  ASSERT_EQ(b.n_ran, FG_MB_PEER_QUEUE);
  for (int i = 1; i <= FG_MB_PEER_QUEUE; i++) {
    ASSERT_EQ(b.ran[i - 1], i); /* in the order posted */
    ASSERT_EQ(b.done_rc[i], i);
  }
  ASSERT_EQ(b.done_rc[FG_MB_PEER_QUEUE + 1], 1); /* refused: done never called */
  /* Room again. */
  ASSERT_OK(fg_mb_peer_post(peer, job_record, &jobs[FG_MB_PEER_QUEUE + 1], job_done));
  board_wait_done(&b, FG_MB_PEER_QUEUE + 2);
  ASSERT_EQ(b.done_rc[FG_MB_PEER_QUEUE + 1], FG_MB_PEER_QUEUE + 1);
  fg_mb_peer_free(peer);
  board_free(&b);
}

typedef struct {
  fg_mb_peer *peer;
  atomic_int calling;
  int rc;
  char detail[256];
  board_job job;
} call_thread_arg;

static void *call_thread(void *arg) {
  call_thread_arg *c = arg;
  atomic_store(&c->calling, 1);
  c->rc = fg_mb_peer_call(c->peer, job_record, &c->job);
  snprintf(c->detail, sizeof c->detail, "%s", fg_error_detail());
  return NULL;
}

static void *free_thread(void *arg) {
  fg_mb_peer_free(arg);
  return NULL;
}

static void test_peer_free_cancels(void) {
  fg_mb_peer *peer = peer_nowhere();
  job_board b;
  board_init(&b);
  board_job jobs[40];
  for (int i = 0; i < 40; i++) jobs[i] = (board_job){&b, i};
  ASSERT_OK(fg_mb_peer_post(peer, job_block, &jobs[0], job_done));
  board_wait_started(&b);
  for (int i = 1; i <= 5; i++) ASSERT_OK(fg_mb_peer_post(peer, job_record, &jobs[i], job_done));
  /* A synchronous caller waits behind them. */
  call_thread_arg c = {.peer = peer, .job = {&b, 6}};
  atomic_init(&c.calling, 0);
  pthread_t ct, ft;
  ASSERT_EQ(pthread_create(&ct, NULL, call_thread, &c), 0);
  while (!atomic_load(&c.calling)) simproc_sleep_ms(1);
  /* It queues its job meanwhile, or finds the peer stopping: either way it gets
   * FG_ECANCELED with "shutting down", so nothing below depends on which. */
  simproc_sleep_ms(100);

  ASSERT_EQ(pthread_create(&ft, NULL, free_thread, peer), 0);
  /* Once the peer is stopping, posts are refused; until then they queue (and are cancelled
   * with the rest). The worker is still blocked, so peer stays valid. */
  int extra = 7;
  const double t_free = simproc_now_ms();
  for (;;) {
    ASSERT(extra < 40);
    const int rc = fg_mb_peer_post(peer, job_record, &jobs[extra], job_done);
    if (rc == FG_ECANCELED) break;
    if (rc == FG_EBUSY) {
      /* a full queue (the 5, maybe the caller's, the extras) while the freeing thread has
       * not run yet: keep asking until it refuses for its own reason */
      ASSERT(5 + 1 + (extra - 7) >= FG_MB_PEER_QUEUE - 1);
    } else {
      ASSERT_OK(rc);
      extra++;
    }
    if (simproc_now_ms() - t_free > 10 * SLACK_MS) FG_TEST_FAIL("the peer never began to stop");
    simproc_sleep_ms(1);
  }
  board_release(&b);
  ASSERT_EQ(pthread_join(ft, NULL), 0);
  ASSERT_EQ(pthread_join(ct, NULL), 0);

  ASSERT_EQ(b.done_rc[0], 5);         /* the running job finished */
  ASSERT_EQ(b.n_ran, 0);              /* none of the queued ones ran */
  for (int i = 1; i <= 5; i++) ASSERT_EQ(b.done_rc[i], FG_ECANCELED);
  for (int i = 7; i < extra; i++) ASSERT_EQ(b.done_rc[i], FG_ECANCELED);
  ASSERT_EQ(b.n_done, 1 + 5 + (extra - 7));
  ASSERT_EQ(c.rc, FG_ECANCELED);
  ASSERT_STRCONTAINS(c.detail, "shutting down");
  board_free(&b);
}

typedef struct {
  atomic_int calls, ok, failed; /* idle jobs begun, succeeded, failed */
  atomic_int other_thread;
  pthread_t main_thread;
} idle_count;

static int idle_job(fg_mb_link *l, void *arg) {
  idle_count *ic = arg;
  atomic_fetch_add(&ic->calls, 1);
  if (!pthread_equal(pthread_self(), ic->main_thread)) atomic_store(&ic->other_thread, 1);
  fg_robotiq_status s;
  const int rc = fg_gripper_read(l, &s);
  if (rc == 0)
    atomic_fetch_add(&ic->ok, 1);
  else
    atomic_fetch_add(&ic->failed, 1);
  return rc;
}

/* Polls until *counter reaches at least want; fails the test after limit_ms, naming what. */
static void wait_count(atomic_int *counter, int want, double limit_ms, const char *what) {
  const double t0 = simproc_now_ms();
  while (atomic_load(counter) < want) {
    if (simproc_now_ms() - t0 > limit_ms)
      FG_TEST_FAIL("%s: %d, not %d, after %.0f ms", what, atomic_load(counter), want, limit_ms);
    simproc_sleep_ms(2);
  }
}

/* The idle job runs every idle_ms while nothing is queued and only while connected; the
 * worker reconnects by itself after the peer comes back. Every step waits for what it
 * checks (a count of jobs, the link's counters) rather than for a time, so that a starved
 * worker slows the case down but cannot fail it. */
static void test_peer_idle(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  const int port = p.port;
  idle_count ic;
  atomic_init(&ic.calls, 0);
  atomic_init(&ic.ok, 0);
  atomic_init(&ic.failed, 0);
  atomic_init(&ic.other_thread, 0);
  ic.main_thread = pthread_self();
  const fg_mb_link_config cfg = tcp_config("gripper", port, GRIPPER, 500);
  fg_mb_peer *peer = NULL;
  const double t0 = simproc_now_ms();
  ASSERT_OK(fg_mb_peer_new(&peer, &cfg, 20, idle_job, &ic));
  wait_count(&ic.ok, 5, 5 * 20 + SLACK_MS, "idle jobs done");
  /* calls before the clock: a job counted is one begun within span */
  const int calls = atomic_load(&ic.calls);
  const double span = simproc_now_ms() - t0;
  fprintf(stderr, "idle job: %d calls in %.0f ms (idle_ms 20)\n", calls, span);
  ASSERT(calls <= 1 + (int)(span / 20) + 1); /* never more often than every idle_ms */
  ASSERT_EQ(atomic_load(&ic.failed), 0);
  ASSERT_EQ(atomic_load(&ic.other_thread), 1);

  /* Peer gone: the idle job fails once, then is not run while the link is down, though the
   * worker keeps trying to reconnect (each refusal counted). */
  simproc_kill(&p);
  wait_count(&ic.failed, 1, 20 + SLACK_MS, "idle jobs failed after the kill");
  const int calls_down = atomic_load(&ic.calls);
  fg_mb_link_state st;
  fg_mb_peer_state(peer, &st);
  ASSERT_EQ(st.connected, 0);
  ASSERT_EQ(st.reconnects, 0);
  const double t_refused = simproc_now_ms();
  for (;;) {
    fg_mb_peer_state(peer, &st);
    if (st.connect_failures >= 2) break;
    if (simproc_now_ms() - t_refused > 100 + 200 + SLACK_MS)
      FG_TEST_FAIL("%llu connection attempts refused, not 2",
                   (unsigned long long)st.connect_failures);
    simproc_sleep_ms(2);
  }
  ASSERT_EQ(atomic_load(&ic.calls), calls_down);
  ASSERT_EQ(atomic_load(&ic.failed), 1);
  ASSERT_EQ(st.connected, 0);

  /* Back on the same port: the worker reconnects after the backoff, without a request. */
  simproc_start(&p, port, NULL);
  const int ok_before = atomic_load(&ic.ok);
  wait_count(&ic.ok, ok_before + 1, 400 + 100 + SLACK_MS, "idle jobs done after the restart");
  fg_mb_peer_state(peer, &st);
  if (st.reconnects != 1 || atomic_load(&ic.failed) != 1)
    FG_TEST_FAIL("after the restart: %llu reconnects, %d failed jobs, %llu timeouts, "
                 "%llu connect failures; last error \"%s\"",
                 (unsigned long long)st.reconnects, atomic_load(&ic.failed),
                 (unsigned long long)st.timeouts, (unsigned long long)st.connect_failures,
                 st.last_error);
  ASSERT_EQ(st.connected, 1);
  fg_mb_peer_free(peer);
  simproc_stop(&p);
}

int main(int argc, char **argv) {
  const char *s = argc > 1 ? argv[1] : getenv("FG_SIM");
  if (!s || !*s) FG_TEST_FAIL("usage: %s PATH-TO-fieldgrip-sim [CASE]", argv[0]);
  simproc_init(s, NULL);
  signal(SIGPIPE, SIG_IGN);
  fg_log_set_level(FG_LOG_WARN);

  static const struct {
    const char *name;
    void (*fn)(void);
  } cases[] = {
      {"connect_rw", test_connect_rw},
      {"bad_config", test_bad_config},
      {"exception", test_exception},
      {"timeout", test_timeout},
      {"late_reply", test_late_reply},
      {"reply_after_flush", test_reply_after_flush},
      {"peer_down_then_up", test_peer_down_then_up},
      {"peer_killed_restart", test_peer_killed_restart},
      {"drop_write", test_drop_write},
      {"robot_handshake", test_robot_handshake},
      {"robot_never_ack", test_robot_never_ack},
      {"robot_fail", test_robot_fail},
      {"robot_float32", test_robot_float32},
      {"gripper", test_gripper},
      {"peer_call", test_peer_call},
      {"peer_queue_full", test_peer_queue_full},
      {"peer_free_cancels", test_peer_free_cancels},
      {"peer_idle", test_peer_idle},
  };
  const char *only = argc > 2 ? argv[2] : NULL;
  int ran = 0;
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    if (only && strcmp(only, cases[i].name) != 0) continue;
    double t0 = simproc_now_ms();
    cases[i].fn();
    ran++;
    fprintf(stderr, "ok %s (%.0f ms)\n", cases[i].name, simproc_now_ms() - t0);
  }
  if (only && !ran) FG_TEST_FAIL("no case named %s", only);
  return 0;
}
