#include "modbus/devices.h"

#include <time.h>

#include "core/error.h"
#include "core/clock.h"

static void sleep_ms(int ms) {
  const struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}

/* The pause between two status reads, started_ms into a wait: a quarter of a millisecond
 * for the first FG_MB_FAST_MS (a controller that answers within a cycle is seen at once),
 * then FG_MB_POLL_MS (a long motion does not flood the peer). */
static void poll_pause(double started_ms) {
  if ((fg_mono_s() * 1e3) - started_ms < FG_MB_FAST_MS) {
    const struct timespec ts = {0, 250000L};
    nanosleep(&ts, NULL);
  } else {
    sleep_ms(FG_MB_POLL_MS);
  }
}

/* ---------------------------------------------------------------- robot */

int fg_robot_read_ack(fg_mb_link *l, const fg_robot_profile *rp, uint16_t *ack, int *status) {
  uint16_t w[2];
  FG_TRY(fg_mb_read_registers(l, rp->base + fg_pose_ack_offset(rp->encoding), 2, w));
  *ack = w[0];
  *status = w[1];
  return 0;
}

int fg_robot_read_tcp(fg_mb_link *l, int base, double p_m[3], double rotvec_rad[3]) {
  uint16_t w[FG_TCP_POSE_WORDS];
  FG_TRY(fg_mb_read_registers(l, base, FG_TCP_POSE_WORDS, w));
  return fg_tcp_pose_decode(w, p_m, rotvec_rad);
}

int fg_robot_write(fg_mb_link *l, const fg_robot_profile *rp, const uint16_t *words) {
  return fg_mb_write_registers(l, rp->base, fg_pose_block_words(rp->encoding), words);
}

int fg_robot_write_stop(fg_mb_link *l, const fg_robot_profile *rp, int stop) {
  const uint16_t w = stop ? 1 : 0;
  return fg_mb_write_registers(l, rp->base + fg_pose_stop_offset(rp->encoding), 1, &w);
}

int fg_robot_wait_ack(fg_mb_link *l, const fg_robot_profile *rp, uint16_t seq, int *status,
                      fg_mb_cancel_fn cancel, void *cancel_arg) {
  const double start = (fg_mono_s() * 1e3), until = start + rp->ack_timeout_ms;
  uint16_t ack = 0;
  for (;;) {
    FG_TRY(fg_robot_read_ack(l, rp, &ack, status));
    if (ack == seq) return 0;
    if ((fg_mono_s() * 1e3) >= until)
      return fg_fail(FG_ETIMEDOUT, "the robot did not acknowledge seq %u within %d ms (ack "
                     "register %d holds %u)", seq, rp->ack_timeout_ms,
                     rp->base + fg_pose_ack_offset(rp->encoding), ack);
    if (cancel && cancel(cancel_arg)) return fg_fail(FG_ECANCELED, "stopped while waiting");
    poll_pause(start);
  }
}

int fg_robot_wait_done(fg_mb_link *l, const fg_robot_profile *rp, uint16_t seq, int *status,
                       fg_mb_cancel_fn cancel, void *cancel_arg) {
  const double start = (fg_mono_s() * 1e3), until = start + rp->done_timeout_ms;
  for (;;) {
    uint16_t ack;
    FG_TRY(fg_robot_read_ack(l, rp, &ack, status));
    if (ack != seq)
      return fg_fail(FG_EINVAL, "the robot's ack changed from %u to %u before it reported "
                     "seq %u done", seq, ack, seq);
    if (*status == FG_ROBOT_DONE || *status == FG_ROBOT_FAILED || *status == FG_ROBOT_STOPPED)
      return 0;
    if ((fg_mono_s() * 1e3) >= until)
      return fg_fail(FG_ETIMEDOUT, "the robot did not report seq %u done within %d ms "
                     "(status %d)", seq, rp->done_timeout_ms, *status);
    if (cancel && cancel(cancel_arg)) return fg_fail(FG_ECANCELED, "stopped while waiting");
    poll_pause(start);
  }
}

/* ---------------------------------------------------------------- gripper */

int fg_gripper_read(fg_mb_link *l, fg_robotiq_status *s) {
  uint16_t w[FG_ROBOTIQ_WORDS];
  FG_TRY(fg_mb_read_input_registers(l, FG_ROBOTIQ_STATUS_ADDR, FG_ROBOTIQ_WORDS, w));
  fg_robotiq_status_decode(w, s);
  return 0;
}

/* Faults from 0x08 on stop the gripper; below that they are advisories. */
static int fault_check(const fg_robotiq_status *s) {
  if (s->flt >= 0x08)
    return fg_fail(FG_EPEER, "the gripper reports fault 0x%02X: %s", s->flt,
                   fg_robotiq_fault_name(s->flt));
  return 0;
}

int fg_gripper_activate(fg_mb_link *l, int timeout_ms, fg_robotiq_status *s) {
  uint16_t w[FG_ROBOTIQ_WORDS];
  fg_robotiq_request(0, 0, 0, 0, w);
  FG_TRY(fg_mb_write_registers(l, FG_ROBOTIQ_REQUEST_ADDR, FG_ROBOTIQ_WORDS, w));
  fg_robotiq_request(FG_ROBOTIQ_ACT, 0, 0, 0, w);
  FG_TRY(fg_mb_write_registers(l, FG_ROBOTIQ_REQUEST_ADDR, FG_ROBOTIQ_WORDS, w));
  const double until = (fg_mono_s() * 1e3) + timeout_ms;
  for (;;) {
    FG_TRY(fg_gripper_read(l, s));
    if (s->sta == 3 && s->act) return 0;
    FG_TRY(fault_check(s));
    if ((fg_mono_s() * 1e3) >= until)
      return fg_fail(FG_ETIMEDOUT, "the gripper did not finish its activation within %d ms "
                     "(gSTA %d, fault 0x%02X)", timeout_ms, s->sta, s->flt);
    sleep_ms(FG_MB_POLL_MS * 5);
  }
}

int fg_gripper_move(fg_mb_link *l, int position, int speed, int force, int timeout_ms,
                    fg_robotiq_status *s) {
  FG_TRY(fg_gripper_read(l, s));
  if (s->sta != 3)
    return fg_fail(FG_EBUSY, "the gripper is not activated (gSTA %d)", s->sta);
  uint16_t w[FG_ROBOTIQ_WORDS];
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_GTO, position, speed, force, w);
  FG_TRY(fg_mb_write_registers(l, FG_ROBOTIQ_REQUEST_ADDR, FG_ROBOTIQ_WORDS, w));
  const double start = (fg_mono_s() * 1e3), until = start + timeout_ms;
  for (;;) {
    FG_TRY(fg_gripper_read(l, s));
    FG_TRY(fault_check(s));
    if (s->echo == position && s->obj != 0) return 0;
    if ((fg_mono_s() * 1e3) >= until)
      return fg_fail(FG_ETIMEDOUT, "the gripper did not finish its move to position %d within "
                     "%d ms (at %d, gOBJ %d)", position, timeout_ms, s->position, s->obj);
    poll_pause(start);
  }
}
