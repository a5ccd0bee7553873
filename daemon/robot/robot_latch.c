/* The latch of the robot service (robot.h): set by a stop or an unconfirmed outcome, kept in
 * a file under the state dir, synced to the robot's registers by its worker, cleared by a
 * reset. */
#include "robot_priv.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"

/* ---------------------------------------------------------------- the latch */

/* Latches (under the lock) with reason and the command that caused it; the first cause is
 * kept while latched. stop: the stop register is to hold 1. */
void robot_latch_set_locked(fg_robot_svc *svc, const char *reason, uint64_t command,
                             int stop) {
  fg_robot_latch *l = &svc->latch;
  if (!l->latched) {
    l->latched = 1;
    snprintf(l->reason, sizeof l->reason, "%.500s", reason);
    l->at_s = fg_real_s();
    l->command = command;
  }
  if (stop) {
    svc->latch_stop = 1;
    l->stop_written = 0;
  }
  l->clear_pending = 1;
}

/* Writes the latch to its file (atomically), so that a restarted daemon is latched too. A
 * failure is logged: the latch holds in memory either way. */
void robot_latch_persist(fg_robot_svc *svc) {
  if (!svc->latch_path) return;
  pthread_mutex_lock(&svc->lock);
  json_t *o = json_pack("{s:s, s:f, s:I, s:b}", "reason", svc->latch.reason, "at",
                        svc->latch.at_s, "command", (json_int_t)svc->latch.command, "stop",
                        svc->latch_stop);
  pthread_mutex_unlock(&svc->lock);
  char *text = o ? json_dumps(o, JSON_COMPACT) : NULL;
  json_decref(o);
  if (!text || fg_write_file_atomic(svc->latch_path, text, strlen(text)) < 0)
    fg_error("robot: the latch could not be written to %s (%s); it holds until this daemon "
             "stops", svc->latch_path, text ? fg_error_detail() : "out of memory");
  free(text);
}

/* Reads the latch file of an earlier run, if any. */
void robot_latch_load(fg_robot_svc *svc) {
  char *buf = NULL;
  size_t len = 0;
  if (fg_read_file(svc->latch_path, 1 << 16, &buf, &len) < 0) return; /* none: not latched */
  json_t *o = json_loadb(buf, len, 0, NULL);
  free(buf);
  const char *reason = "latched before the daemon restarted";
  json_t *jr = json_object_get(o, "reason"), *jc = json_object_get(o, "command");
  if (json_is_string(jr)) reason = json_string_value(jr);
  robot_latch_set_locked(svc, reason, json_is_integer(jc) ? (uint64_t)json_integer_value(jc) : 0,
                   json_is_true(json_object_get(o, "stop")));
  double at = json_real_value(json_object_get(o, "at"));
  if (at > 0) svc->latch.at_s = at;
  json_decref(o);
  fg_warn("robot: latched since an earlier run (%s); motion is refused until POST "
          "/v1/robot/reset", svc->latch.reason);
}

/* A no-op block under a new seq: a robot program that finds a block it has not run yet
 * runs this instead. Clears clear_pending once written. */
static int clear_block(fg_robot_svc *svc, fg_mb_link *l) {
  pthread_mutex_lock(&svc->lock);
  uint16_t seq = fg_seq_next(svc->last_seq);
  if (seq == svc->ack) seq = fg_seq_next(seq);
  svc->last_seq = seq;
  pthread_mutex_unlock(&svc->lock);
  const fg_pose_block b = {.seq = seq, .command = FG_ROBOT_NOOP};
  uint16_t w[FG_POSE_MAX_WORDS];
  FG_TRY(fg_pose_block_encode(&b, svc->rp.encoding, w));
  FG_TRY(fg_robot_write(l, &svc->rp, w));
  pthread_mutex_lock(&svc->lock);
  svc->latch.clear_pending = 0;
  pthread_mutex_unlock(&svc->lock);
  fg_info("robot: wrote a no-op block (seq %u) so that nothing stays armed", seq);
  return 0;
}

/* Writes what the latch still owes the robot: the stop word, the no-op block. */
int robot_latch_sync(fg_robot_svc *svc, fg_mb_link *l) {
  pthread_mutex_lock(&svc->lock);
  const int stop = svc->latch.latched && svc->latch_stop && !svc->latch.stop_written;
  const int clear = svc->latch.latched && svc->latch.clear_pending;
  pthread_mutex_unlock(&svc->lock);
  if (stop) {
    FG_TRY(fg_robot_write_stop(l, &svc->rp, 1));
    pthread_mutex_lock(&svc->lock);
    svc->latch.stop_written = 1;
    pthread_mutex_unlock(&svc->lock);
  }
  if (clear) FG_TRY(clear_block(svc, l));
  return 0;
}

void fg_robot_latch_get(fg_robot_svc *svc, fg_robot_latch *out) {
  pthread_mutex_lock(&svc->lock);
  *out = svc->latch;
  pthread_mutex_unlock(&svc->lock);
}

