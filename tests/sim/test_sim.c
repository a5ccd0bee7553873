/* Tests of fieldgrip-sim (argv[1]) through a real libmodbus TCP client on 127.0.0.1: the robot
 * block's acknowledgement timeline and its failure modes, the Robotiq gripper's activation,
 * motion and object detection, several clients at once, the request log, and a restart on
 * the same port right after SIGKILL. Each case starts its own simulator. */
#include <errno.h>
#include <limits.h>
#include <modbus.h>
#include <signal.h>
#include <unistd.h>

#include "simproc.h"
#include "test.h"

#define SLACK_MS 1500 /* upper bounds on timings: 2 shared cores, maybe AddressSanitizer */
#define BASE 128
#define ROBOT 1
#define GRIPPER 9

/* ---------------------------------------------------------------- helpers */

static modbus_t *client(int port, int unit) {
  modbus_t *c = modbus_new_tcp("127.0.0.1", port);
  ASSERT(c != NULL);
  ASSERT_EQ(modbus_set_slave(c, unit), 0);
  ASSERT_EQ(modbus_set_response_timeout(c, 3, 0), 0);
  if (modbus_connect(c) != 0) FG_TEST_FAIL("connect to %d: %s", port, modbus_strerror(errno));
  return c;
}

static void client_free(modbus_t *c) {
  modbus_close(c);
  modbus_free(c);
}

static void rd(modbus_t *c, int addr, int n, uint16_t *out) {
  int rc = modbus_read_registers(c, addr, n, out);
  if (rc != n) FG_TEST_FAIL("read %d x %d: %d (%s)", addr, n, rc, modbus_strerror(errno));
}

static void rd_in(modbus_t *c, int addr, int n, uint16_t *out) {
  int rc = modbus_read_input_registers(c, addr, n, out);
  if (rc != n) FG_TEST_FAIL("read input %d x %d: %d (%s)", addr, n, rc, modbus_strerror(errno));
}

static void wr(modbus_t *c, int addr, int n, const uint16_t *w) {
  int rc = modbus_write_registers(c, addr, n, w);
  if (rc != n) FG_TEST_FAIL("write %d x %d: %d (%s)", addr, n, rc, modbus_strerror(errno));
}

/* The robot's motions take no time here: these tests time the handshake itself. */
static const char *const k_instant[] = {"--time-scale", "0", NULL};

/* The int16 block of a command with sequence number seq (proto/modbus.md worked example). */
static void block_int16(uint16_t seq, uint16_t *w) {
  const uint16_t ex[13] = {7, 1, 4523, 64329, 350, 2902, 64334, 0, 800, 40, 1000, 1000, 100};
  memcpy(w, ex, sizeof ex);
  w[0] = seq;
}

static void write_seq(modbus_t *c, uint16_t seq) {
  uint16_t w[13];
  block_int16(seq, w);
  wr(c, BASE, 13, w);
}

/* Reads ack and status (offsets 13 and 14) in one request. */
static void ack_status(modbus_t *c, uint16_t *ack, uint16_t *status) {
  uint16_t v[2];
  rd(c, BASE + 13, 2, v);
  *ack = v[0];
  *status = v[1];
}

/* Expects a failed call with errno = want. */
#define ASSERT_FAILS_WITH(expr, want)                                                      \
  do {                                                                                     \
    errno = 0;                                                                             \
    int rc_ = (expr);                                                                      \
    int e_ = errno;                                                                        \
    if (rc_ != -1 || e_ != (want))                                                         \
      FG_TEST_FAIL("%s: rc %d errno %d (%s), expected errno %d (%s)", #expr, rc_, e_,      \
                   modbus_strerror(e_), (int)(want), modbus_strerror(want));               \
  } while (0)

/* ---------------------------------------------------------------- gripper helpers */

typedef struct {
  int act, gto, sta, obj, flt, pr, po, cu;
} grip_status;

static grip_status grip_read(modbus_t *c) {
  uint16_t in[3];
  rd_in(c, 0x07D0, 3, in);
  int st = in[0] >> 8;
  ASSERT_EQ(in[0] & 0xFF, 0);
  return (grip_status){.act = st & 1,
                       .gto = (st >> 3) & 1,
                       .sta = (st >> 4) & 3,
                       .obj = (st >> 6) & 3,
                       .flt = in[1] >> 8,
                       .pr = in[1] & 0xFF,
                       .po = in[2] >> 8,
                       .cu = in[2] & 0xFF};
}

static void grip_write(modbus_t *c, uint16_t action, uint16_t pos, uint16_t speed_force) {
  const uint16_t w[3] = {action, pos, speed_force};
  wr(c, 0x03E8, 3, w);
}

/* Reset then rACT = 1; waits for gSTA = 3. */
static void grip_activate(modbus_t *c) {
  grip_write(c, 0, 0, 0);
  grip_write(c, 0x0100, 0, 0);
  double deadline = simproc_now_ms() + 10000;
  while (grip_read(c).sta != 3) {
    ASSERT(simproc_now_ms() < deadline);
    simproc_sleep_ms(2);
  }
}

/* Sends a move and polls until gOBJ != 0; returns the final status and the elapsed time.
 * Checks that the echo is at once and that the position moves monotonically, and that any
 * read sent 5 ms or more after the write (a few position units at the slowest speed) that
 * finds the fingers still moving (gOBJ 0) finds them away from the start: the fingers move
 * gradually, not in one jump at the end. *saw_between is 1 when such a read was made, 0 when
 * this thread was held up past the whole motion and could not look. */
static grip_status grip_move(modbus_t *c, int pos, int speed, int force, double *elapsed_ms,
                             int *saw_between) {
  grip_status start = grip_read(c);
  double t0 = simproc_now_ms();
  grip_write(c, 0x0900, (uint16_t)pos, (uint16_t)(speed << 8 | force));
  const double t_written = simproc_now_ms(); /* the motion began before this */
  grip_status st = grip_read(c);
  ASSERT_EQ(st.pr, pos);
  ASSERT_EQ(st.gto, 1);
  ASSERT_EQ(st.flt, 0);
  int last = start.po, dir = pos > start.po ? 1 : -1;
  *saw_between = 0;
  while (st.obj == 0) {
    ASSERT((st.po - last) * dir >= 0);
    last = st.po;
    ASSERT(simproc_now_ms() - t0 < 10000);
    simproc_sleep_ms(2);
    const double t_sent = simproc_now_ms();
    st = grip_read(c);
    if (st.obj == 0 && t_sent - t_written >= 5) {
      ASSERT(st.po != start.po);
      *saw_between = 1;
    }
  }
  *elapsed_ms = simproc_now_ms() - t0;
  ASSERT_EQ(st.pr, pos);
  return st;
}

/* ---------------------------------------------------------------- robot block */

static void test_args(void) {
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--encoding", "int32", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--exception", "12", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--robot-unit", "9", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--bogus", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--listen", "127.0.0.1", NULL}), 2);
}

static void test_robot_immediate(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  char *err = simproc_read(p.err);
  char want[96];
  snprintf(want, sizeof want, "fieldgrip-sim: listening on 127.0.0.1:%d\n", p.port);
  ASSERT_STREQ(err, want);
  free(err);

  modbus_t *c = client(p.port, ROBOT);
  uint16_t v[16], w[13];
  rd(c, BASE, 16, v);
  for (int i = 0; i < 16; i++) ASSERT_EQ(v[i], 0);

  block_int16(7, w);
  wr(c, BASE, 13, w);
  rd(c, BASE, 16, v);
  for (int i = 0; i < 13; i++) ASSERT_EQ(v[i], w[i]);
  ASSERT_EQ(v[13], 7); /* ack */
  ASSERT_EQ(v[14], 2); /* done */

  /* The same seq again is not a new command; a single-register write of seq is. */
  uint16_t ack, status;
  ASSERT_EQ(modbus_write_register(c, BASE + 14, 0), 1);
  wr(c, BASE, 13, w);
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 7);
  ASSERT_EQ(status, 0);
  ASSERT_EQ(modbus_write_register(c, BASE, 8), 1);
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 8);
  ASSERT_EQ(status, 2);

  /* seq 0 is never a command. */
  ASSERT_EQ(modbus_write_register(c, BASE, 0), 1);
  ASSERT_EQ(modbus_write_register(c, BASE + 14, 0), 1);
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 8);
  ASSERT_EQ(status, 0);

  /* Outside the block, input registers, coils, other units. */
  ASSERT_FAILS_WITH(modbus_read_registers(c, BASE, 17, v), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_registers(c, BASE - 1, 2, v), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_write_registers(c, BASE + 15, 2, w), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_input_registers(c, BASE, 2, v), EMBXILADD);
  uint8_t bits[8];
  ASSERT_FAILS_WITH(modbus_read_bits(c, 0, 8, bits), EMBXILFUN);
  ASSERT_EQ(modbus_set_slave(c, 5), 0);
  ASSERT_FAILS_WITH(modbus_read_registers(c, BASE, 2, v), EMBXGTAR);
  ASSERT_EQ(modbus_set_slave(c, GRIPPER), 0);
  ASSERT_FAILS_WITH(modbus_read_registers(c, BASE, 2, v), EMBXILADD);
  ASSERT_EQ(modbus_set_slave(c, ROBOT), 0);
  rd(c, BASE, 1, v); /* the connection survived every exception */
  ASSERT_EQ(v[0], 0);
  client_free(c);
  simproc_stop(&p);
}

static void test_robot_delays(void) {
  simproc p;
  const int ack_ms = 150, done_ms = 400;
  simproc_start(&p, 0,
                (const char *const[]){"--ack-delay-ms", "150", "--done-delay-ms", "400", NULL});
  modbus_t *c = client(p.port, ROBOT);
  uint16_t ack, status;
  double t0 = simproc_now_ms();
  write_seq(c, 1);
  ack_status(c, &ack, &status);
  double t_first = simproc_now_ms();
  if (t_first - t0 < ack_ms) {
    ASSERT_EQ(ack, 0);
    ASSERT_EQ(status, 0);
  }
  while (ack != 1) {
    ASSERT_EQ(ack, 0);
    ASSERT(simproc_now_ms() - t0 < ack_ms + SLACK_MS);
    simproc_sleep_ms(2);
    ack_status(c, &ack, &status);
  }
  double t_ack = simproc_now_ms() - t0;
  ASSERT(t_ack >= ack_ms);
  /* busy, when the read that saw the ack came before the done was due (400 ms later) */
  if (t_ack < ack_ms + done_ms) ASSERT_EQ(status, 1);
  while (status != 2) {
    ASSERT_EQ(status, 1);
    ASSERT_EQ(ack, 1);
    ASSERT(simproc_now_ms() - t0 < ack_ms + done_ms + SLACK_MS);
    simproc_sleep_ms(2);
    ack_status(c, &ack, &status);
  }
  double t_done = simproc_now_ms() - t0;
  ASSERT(t_done >= ack_ms + done_ms);
  fprintf(stderr, "ack after %.1f ms (delay %d), done after %.1f ms (delay %d + %d)\n", t_ack,
          ack_ms, t_done, ack_ms, done_ms);
  client_free(c);
  simproc_stop(&p);
}

/* A newer seq written before the older one was acknowledged supersedes it. */
static void test_robot_supersede(void) {
  simproc p;
  const int ack_ms = 300;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--ack-delay-ms", "300", NULL});
  modbus_t *c = client(p.port, ROBOT);
  double t0 = simproc_now_ms();
  write_seq(c, 1);
  simproc_sleep_ms(20);
  write_seq(c, 2);
  double t1 = simproc_now_ms();
  uint16_t ack, status;
  int saw_one = 0;
  do {
    ASSERT(simproc_now_ms() - t0 < ack_ms + SLACK_MS);
    simproc_sleep_ms(2);
    ack_status(c, &ack, &status);
    if (ack == 1) saw_one = 1;
  } while (ack != 2);
  ASSERT_EQ(status, 2);
  double t_ack = simproc_now_ms() - t1;
  ASSERT(t_ack >= ack_ms - (t1 - t0)); /* due 300 ms after the second write was received */
  if (t1 - t0 < ack_ms)
    ASSERT_EQ(saw_one, 0);
  else
    fprintf(stderr, "note: the two writes were %.0f ms apart, supersede not checked\n", t1 - t0);
  client_free(c);
  simproc_stop(&p);
}

static void test_robot_never_ack(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--never-ack", NULL});
  modbus_t *c = client(p.port, ROBOT);
  write_seq(c, 1);
  simproc_sleep_ms(250);
  uint16_t ack, status;
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 0);
  ASSERT_EQ(status, 0);
  uint16_t v[1];
  rd(c, BASE, 1, v);
  ASSERT_EQ(v[0], 1);
  client_free(c);
  simproc_stop(&p);
}

static void test_robot_fail(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--fail", "--done-delay-ms", "50", NULL});
  modbus_t *c = client(p.port, ROBOT);
  write_seq(c, 3);
  uint16_t ack, status;
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 3);
  double t0 = simproc_now_ms();
  while (status != 3) {
    ASSERT_EQ(status, 1);
    ASSERT(simproc_now_ms() - t0 < 50 + SLACK_MS);
    simproc_sleep_ms(2);
    ack_status(c, &ack, &status);
  }
  client_free(c);
  simproc_stop(&p);
}

static void test_robot_exception(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--exception", "4", NULL});
  modbus_t *c = client(p.port, ROBOT);
  uint16_t w[13], v[16];
  block_int16(5, w);
  ASSERT_FAILS_WITH(modbus_write_registers(c, BASE, 13, w), MODBUS_ENOBASE + 4);
  ASSERT_FAILS_WITH(modbus_write_register(c, BASE, 5), MODBUS_ENOBASE + 4);
  rd(c, BASE, 16, v); /* reads still answer; nothing was written */
  for (int i = 0; i < 16; i++) ASSERT_EQ(v[i], 0);
  /* The gripper is not affected. */
  ASSERT_EQ(modbus_set_slave(c, GRIPPER), 0);
  grip_write(c, 0x0100, 0, 0);
  ASSERT_EQ(grip_read(c).act, 1);
  client_free(c);
  simproc_stop(&p);

  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--exception", "11", NULL});
  c = client(p.port, ROBOT);
  ASSERT_FAILS_WITH(modbus_write_registers(c, BASE, 13, w), EMBXGTAR);
  client_free(c);
  simproc_stop(&p);
}

/* The third request is applied and its connection closed unanswered; the count runs over
 * all connections and only that one request is dropped. */
static void test_robot_drop(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--drop-after", "3", NULL});
  modbus_t *a = client(p.port, ROBOT);
  modbus_t *b = client(p.port, ROBOT);
  uint16_t v[16];
  rd(a, BASE, 1, v); /* 1 */
  rd(b, BASE, 1, v); /* 2 */
  uint16_t w[13];
  block_int16(5, w);
  double t0 = simproc_now_ms();
  ASSERT_FAILS_WITH(modbus_write_registers(a, BASE, 13, w), ECONNRESET); /* 3 */
  ASSERT(simproc_now_ms() - t0 < 2500); /* closed, not a response timeout */
  rd(b, BASE, 16, v); /* 4: the other connection is still served */
  for (int i = 0; i < 13; i++) ASSERT_EQ(v[i], w[i]);
  ASSERT_EQ(v[13], 5);
  ASSERT_EQ(v[14], 2);
  client_free(a);
  a = client(p.port, ROBOT);
  rd(a, BASE, 1, v);
  ASSERT_EQ(v[0], 5);
  write_seq(a, 6);
  client_free(a);
  client_free(b);
  simproc_stop(&p);
}

static void test_robot_ack_init(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--ack-init", "41", NULL});
  modbus_t *c = client(p.port, ROBOT);
  uint16_t ack, status;
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 41);
  ASSERT_EQ(status, 0);
  write_seq(c, 41); /* already acknowledged: the robot must not act on it */
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 41);
  ASSERT_EQ(status, 0);
  write_seq(c, 42);
  ack_status(c, &ack, &status);
  ASSERT_EQ(ack, 42);
  ASSERT_EQ(status, 2);
  client_free(c);
  simproc_stop(&p);
}

static void test_robot_float32(void) {
  simproc p;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--encoding", "float32", "--base", "200", NULL});
  modbus_t *c = client(p.port, ROBOT);
  uint16_t v[27];
  rd(c, 200, 26, v);
  ASSERT_FAILS_WITH(modbus_read_registers(c, 200, 27, v), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_registers(c, BASE, 1, v), EMBXILADD);
  const uint16_t w[23] = {9,      1,      0x3EE7, 0x93DE, 0xBDF7, 0x3190, 0x3D0F, 0x5C29,
                          0x4039, 0xC1CB, 0xBF99, 0xE2DA, 0,      0,      0x3DA3, 0xD70A,
                          40,     0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD};
  wr(c, 200, 23, w);
  rd(c, 200, 26, v);
  for (int i = 0; i < 23; i++) ASSERT_EQ(v[i], w[i]);
  ASSERT_EQ(v[23], 9);
  ASSERT_EQ(v[24], 2);
  client_free(c);
  simproc_stop(&p);

  /* The int16 layout ends at offset 15. */
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--encoding", "int16", NULL});
  c = client(p.port, ROBOT);
  rd(c, BASE, 16, v);
  ASSERT_FAILS_WITH(modbus_read_registers(c, BASE, 17, v), EMBXILADD);
  client_free(c);
  simproc_stop(&p);
}

/* ---------------------------------------------------------------- gripper */

static void test_gripper_activation_and_moves(void) {
  simproc p;
  const int act_ms = 200, stroke_ms = 100;
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--activation-ms", "200", "--stroke-ms", "100", NULL});
  modbus_t *c = client(p.port, GRIPPER);
  grip_status st = grip_read(c);
  ASSERT_EQ(st.act + st.gto + st.sta + st.obj + st.flt + st.pr + st.po + st.cu, 0);
  uint16_t r[3];
  rd(c, 0x03E8, 3, r);
  ASSERT_FAILS_WITH(modbus_read_registers(c, 0x03E8, 4, r), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_input_registers(c, 0x07D0, 4, r), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_registers(c, 0x07D0, 3, r), EMBXILADD);

  /* A go-to without activation: fault 0x07; the reset clears it. */
  grip_write(c, 0x0800, 255, 0xFF00);
  st = grip_read(c);
  ASSERT_EQ(st.flt, 0x07);
  ASSERT_EQ(st.act, 0);
  ASSERT_EQ(st.gto, 1);
  ASSERT_EQ(st.sta, 0);
  ASSERT_EQ(st.po, 0);
  grip_write(c, 0, 0, 0);
  st = grip_read(c);
  ASSERT_EQ(st.flt, 0);
  ASSERT_EQ(st.gto, 0);

  /* Activation: gSTA 1 for activation-ms, then 3 with the fingers open. */
  double t0 = simproc_now_ms();
  grip_write(c, 0x0100, 0, 0);
  st = grip_read(c);
  double t_first = simproc_now_ms() - t0;
  ASSERT_EQ(st.act, 1);
  if (t_first < act_ms) ASSERT_EQ(st.sta, 1);
  while (st.sta != 3) {
    ASSERT_EQ(st.sta, 1);
    ASSERT(simproc_now_ms() - t0 < act_ms + SLACK_MS);
    simproc_sleep_ms(2);
    st = grip_read(c);
  }
  double t_act = simproc_now_ms() - t0;
  ASSERT(t_act >= act_ms);
  ASSERT_EQ(st.act, 1);
  ASSERT_EQ(st.po, 0);
  ASSERT_EQ(st.flt, 0);

  /* Close at full speed: a full stroke takes stroke-ms; no object, so gOBJ 3 at 255. */
  double ms;
  int between;
  st = grip_move(c, 255, 255, 100, &ms, &between);
  ASSERT_EQ(st.obj, 3);
  ASSERT_EQ(st.po, 255);
  ASSERT_EQ(st.cu, 0);
  if (!between) fprintf(stderr, "note: no read during the close to see the fingers partway\n");
  ASSERT(ms >= stroke_ms - 1);
  ASSERT(ms < stroke_ms + SLACK_MS);
  double close_ms = ms;
  /* Open at the slowest speed: a quarter of the rate, so four times as long. */
  st = grip_move(c, 0, 0, 100, &ms, &between);
  ASSERT_EQ(st.obj, 3);
  ASSERT_EQ(st.po, 0);
  if (!between) fprintf(stderr, "note: no read during the open to see the fingers partway\n");
  ASSERT(ms >= 4 * stroke_ms - 1);
  ASSERT(ms < 4 * stroke_ms + SLACK_MS);
  fprintf(stderr, "activation %.1f ms (%d), close %.1f ms (%d), slow open %.1f ms (%d)\n", t_act,
          act_ms, close_ms, stroke_ms, ms, 4 * stroke_ms);
  /* Partway, then a move to where the fingers are ends at once. */
  st = grip_move(c, 128, 255, 100, &ms, &between);
  ASSERT_EQ(st.obj, 3);
  ASSERT_EQ(st.po, 128);
  grip_write(c, 0x0900, 128, 0xFF64);
  st = grip_read(c);
  ASSERT_EQ(st.obj, 3);
  ASSERT_EQ(st.po, 128);

  /* A go-to that arrives during the activation waits for it (fault 0x05 meanwhile). */
  grip_write(c, 0, 0, 0);
  st = grip_read(c);
  ASSERT_EQ(st.sta, 0);
  ASSERT_EQ(st.act, 0);
  t0 = simproc_now_ms();
  grip_write(c, 0x0900, 255, 0xFF00);
  st = grip_read(c);
  if (simproc_now_ms() - t0 < act_ms) {
    ASSERT_EQ(st.sta, 1);
    ASSERT_EQ(st.flt, 0x05);
  }
  while (!(st.sta == 3 && st.obj == 3)) {
    ASSERT(simproc_now_ms() - t0 < act_ms + stroke_ms + SLACK_MS);
    simproc_sleep_ms(2);
    st = grip_read(c);
  }
  ASSERT(simproc_now_ms() - t0 >= act_ms + stroke_ms - 1);
  ASSERT_EQ(st.flt, 0);
  ASSERT_EQ(st.po, 255);
  ASSERT_EQ(st.pr, 255);
  client_free(c);
  simproc_stop(&p);
}

static void test_gripper_object(void) {
  simproc p;
  /* 40 mm in an 85 mm stroke: P = round(255 * 45 / 85) = 135. */
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--object-width-mm", "40", "--activation-ms", "0",
                                              "--stroke-ms", "100", NULL});
  modbus_t *c = client(p.port, GRIPPER);
  grip_write(c, 0x0100, 0, 0);
  grip_status st = grip_read(c);
  ASSERT_EQ(st.sta, 3);
  double ms;
  int between;
  st = grip_move(c, 255, 255, 0, &ms, &between);
  ASSERT_EQ(st.obj, 2);
  ASSERT_EQ(st.po, 135);
  ASSERT(st.cu > 0);
  ASSERT(ms >= 100.0 * 135 / 255 - 1);
  int cu_low = st.cu;
  /* Closing again on the object: contact at once, current grows with the force byte. */
  grip_write(c, 0x0900, 255, 0xFFFF);
  st = grip_read(c);
  ASSERT_EQ(st.obj, 2);
  ASSERT_EQ(st.po, 135);
  ASSERT(st.cu > cu_low);
  st = grip_move(c, 0, 255, 0, &ms, &between);
  ASSERT_EQ(st.obj, 3);
  ASSERT_EQ(st.po, 0);
  ASSERT_EQ(st.cu, 0);
  /* Short of the object: at the target. */
  st = grip_move(c, 100, 255, 0, &ms, &between);
  ASSERT_EQ(st.obj, 3);
  ASSERT_EQ(st.po, 100);
  st = grip_move(c, 255, 255, 0, &ms, &between);
  ASSERT_EQ(st.obj, 2);
  ASSERT_EQ(st.po, 135);
  client_free(c);
  simproc_stop(&p);

  /* 2F-140 holding 70 mm: P = round(255 * 70 / 140) = round(127.5) = 128. */
  simproc_start(&p, 0, (const char *const[]){"--time-scale", "0", "--stroke-mm", "140", "--object-width-mm", "70",
                                              "--activation-ms", "0", "--stroke-ms", "50", NULL});
  c = client(p.port, GRIPPER);
  grip_write(c, 0x0100, 0, 0);
  st = grip_move(c, 255, 255, 0, &ms, &between);
  ASSERT_EQ(st.obj, 2);
  ASSERT_EQ(st.po, 128);
  client_free(c);
  simproc_stop(&p);
}

/* ---------------------------------------------------------------- server */

static void test_two_clients(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  modbus_t *idle = client(p.port, ROBOT); /* connected, never sends */
  modbus_t *robot = client(p.port, ROBOT);
  modbus_t *grip = client(p.port, GRIPPER);
  grip_activate(grip);
  for (int i = 1; i <= 50; i++) {
    write_seq(robot, (uint16_t)i);
    ASSERT_EQ(modbus_set_slave(grip, ROBOT), 0);
    uint16_t v[16];
    rd(grip, BASE, 16, v);
    ASSERT_EQ(v[0], i);
    ASSERT_EQ(v[13], i);
    ASSERT_EQ(modbus_set_slave(grip, GRIPPER), 0);
    ASSERT_EQ(grip_read(grip).sta, 3);
  }
  client_free(robot);
  ASSERT_EQ(grip_read(grip).sta, 3); /* one client leaving does not disturb another */
  uint16_t v[1];
  rd(idle, BASE, 1, v);
  ASSERT_EQ(v[0], 50);
  client_free(idle);
  client_free(grip);
  simproc_stop(&p);
}

static void test_log(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  modbus_t *c = client(p.port, ROBOT);
  uint16_t w[13], v[16];
  block_int16(7, w);
  wr(c, BASE, 13, w);
  rd(c, BASE, 16, v); /* reads are not logged */
  ASSERT_EQ(modbus_write_register(c, BASE + 1, 3), 1);
  ASSERT_FAILS_WITH(modbus_write_registers(c, BASE + 14, 3, w), EMBXILADD);
  ASSERT_EQ(modbus_set_slave(c, GRIPPER), 0);
  grip_write(c, 0x0900, 255, 0xFF40);
  ASSERT_EQ(modbus_set_slave(c, 5), 0);
  ASSERT_FAILS_WITH(modbus_write_register(c, 1, 65535), EMBXGTAR);

  /* After a rename and SIGUSR1 the simulator appends to a new file. */
  char rotated[PATH_MAX + 8];
  snprintf(rotated, sizeof rotated, "%s.1", p.log);
  ASSERT_EQ(rename(p.log, rotated), 0);
  ASSERT_EQ(kill(p.pid, SIGUSR1), 0);
  /* the signal reaches the main loop through a handler on whichever thread takes it: wait
   * until the new file is there, then write */
  const double deadline = simproc_now_ms() + 10000;
  while (access(p.log, F_OK) != 0) {
    if (simproc_now_ms() > deadline) FG_TEST_FAIL("no new log %s after SIGUSR1", p.log);
    usleep(1000);
  }
  ASSERT_EQ(modbus_set_slave(c, ROBOT), 0);
  ASSERT_EQ(modbus_write_register(c, BASE, 8), 1);

  char *log = simproc_read(rotated);
  ASSERT_STREQ(log, "write unit=1 fn=16 addr=128 n=13 "
                    "words=7,1,4523,64329,350,2902,64334,0,800,40,1000,1000,100\n"
                    "write unit=1 fn=6 addr=129 n=1 words=3\n"
                    "write unit=1 fn=16 addr=142 n=3 words=7,1,4523\n"
                    "write unit=9 fn=16 addr=1000 n=3 words=2304,255,65344\n"
                    "write unit=5 fn=6 addr=1 n=1 words=65535\n");
  free(log);
  log = simproc_read(p.log);
  ASSERT_STREQ(log, "write unit=1 fn=6 addr=128 n=1 words=8\n");
  free(log);
  client_free(c);
  simproc_stop(&p);
}

/* A simulator killed with an established connection leaves the port in TIME_WAIT; the next
 * one binds the same port at once (SO_REUSEADDR) and starts from a fresh state. */
static void test_restart_same_port(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  int port = p.port;
  modbus_t *c = client(port, ROBOT);
  write_seq(c, 4);
  simproc_kill(&p);
  uint16_t v[16];
  ASSERT_EQ(modbus_read_registers(c, BASE, 1, v), -1);
  client_free(c);

  double t0 = simproc_now_ms();
  simproc_start(&p, port, NULL);
  ASSERT_EQ(p.port, port);
  fprintf(stderr, "restart on port %d took %.1f ms\n", port, simproc_now_ms() - t0);
  c = client(port, ROBOT);
  rd(c, BASE, 16, v);
  ASSERT_EQ(v[0], 0);
  ASSERT_EQ(v[10], 0);
  client_free(c);
  simproc_stop(&p);
}

/* ---------------------------------------------------------------- TCP pose */

#define TCP 400

static void tcp_read(modbus_t *c, int16_t v[6]) {
  uint16_t w[6];
  rd(c, TCP, 6, w);
  for (int i = 0; i < 6; i++) v[i] = (int16_t)w[i];
}

/* Registers 400-405 as a UR controller's: the home pose, then where a pick ended (the worked
 * example's pose lifted 0.10 m), read only, and none with --tcp-pose-base none. */
static void test_tcp_pose(void) {
  simproc p;
  simproc_start(&p, 0, k_instant);
  modbus_t *c = client(p.port, ROBOT);
  int16_t v[6];
  tcp_read(c, v);
  const int16_t home[6] = {3000, 0, 4000, 3142, 0, 0}; /* pointing down: pi about x */
  for (int i = 0; i < 6; i++) ASSERT_EQ(v[i], home[i]);

  write_seq(c, 7);
  uint16_t ack, status;
  ack_status(c, &ack, &status);
  ASSERT_EQ(status, 2);
  tcp_read(c, v);
  /* the block's 4523, -1207, 350 (0.1 mm) and 2902, -1202, 0 (mrad), lifted by its retreat */
  const int16_t end[6] = {4523, -1207, 1350, 2902, -1202, 0};
  for (int i = 0; i < 6; i++)
    if (abs(v[i] - end[i]) > (i < 3 ? 0 : 1))
      FG_TEST_FAIL("TCP register %d: %d, expected %d", TCP + i, v[i], end[i]);

  uint16_t w[7] = {0};
  ASSERT_FAILS_WITH(modbus_write_registers(c, TCP, 6, w), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_write_register(c, TCP + 2, 0), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_registers(c, TCP, 7, w), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_registers(c, TCP - 1, 2, w), EMBXILADD);
  ASSERT_FAILS_WITH(modbus_read_input_registers(c, TCP, 6, w), EMBXILADD);
  tcp_read(c, v); /* the writes changed nothing */
  ASSERT_EQ(v[2], 1350);
  client_free(c);
  simproc_stop(&p);

  const char *none[] = {"--time-scale", "0", "--tcp-pose-base", "none", NULL};
  simproc_start(&p, 0, none);
  c = client(p.port, ROBOT);
  ASSERT_FAILS_WITH(modbus_read_registers(c, TCP, 6, w), EMBXILADD);
  client_free(c);
  simproc_stop(&p);
  /* overlapping the robot block: refused at start */
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--tcp-pose-base", "140", NULL}), 2);
  ASSERT_EQ(simproc_exit_status((const char *const[]){"--base", "395", NULL}), 2);
}

int main(int argc, char **argv) {
  const char *s = argc > 1 ? argv[1] : getenv("FG_SIM");
  if (!s || !*s) FG_TEST_FAIL("usage: %s PATH-TO-fieldgrip-sim", argv[0]);
  simproc_init(s, NULL);
  signal(SIGPIPE, SIG_IGN);

  static const struct {
    const char *name;
    void (*fn)(void);
  } cases[] = {
      {"args", test_args},
      {"robot_immediate", test_robot_immediate},
      {"robot_delays", test_robot_delays},
      {"robot_supersede", test_robot_supersede},
      {"robot_never_ack", test_robot_never_ack},
      {"robot_fail", test_robot_fail},
      {"robot_exception", test_robot_exception},
      {"robot_drop", test_robot_drop},
      {"robot_ack_init", test_robot_ack_init},
      {"robot_float32", test_robot_float32},
      {"gripper_activation_and_moves", test_gripper_activation_and_moves},
      {"gripper_object", test_gripper_object},
      {"two_clients", test_two_clients},
      {"log", test_log},
      {"tcp_pose", test_tcp_pose},
      {"restart_same_port", test_restart_same_port},
  };
  const char *only = argc > 2 ? argv[2] : NULL;
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    if (only && strcmp(only, cases[i].name) != 0) continue;
    double t0 = simproc_now_ms();
    cases[i].fn();
    fprintf(stderr, "ok %s (%.0f ms)\n", cases[i].name, simproc_now_ms() - t0);
  }
  return 0;
}
