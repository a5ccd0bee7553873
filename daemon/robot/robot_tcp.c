/* The TCP pose the robot reports (proto/modbus.md "The TCP pose, read back"): read on the
 * robot's worker at each idle poll and after each motion and kept for GET /v1/robot, or read
 * afresh for a frame taken now. */
#include "robot_priv.h"

#include <stdio.h>
#include <string.h>

#include "core/clock.h"
#include "core/error.h"
#include "core/pose.h"

/* Reads the pose on the worker and keeps it (or the failure). 0 or the read's error. */
static int tcp_read(fg_robot_svc *svc, fg_mb_link *l, fg_robot_tcp *out) {
  double p[3], rv[3];
  const int rc = fg_robot_read_tcp(l, svc->tcp_base, p, rv);
  pthread_mutex_lock(&svc->lock);
  fg_robot_tcp *t = &svc->tcp;
  if (rc == 0) {
    t->have = 1;
    memcpy(t->p_m, p, sizeof p);
    fg_quat_from_rotvec(rv, t->q_wxyz);
    t->read_ms = fg_real_ms();
    t->generation = fg_mb_link_generation(l);
    t->error[0] = '\0';
  } else {
    snprintf(t->error, sizeof t->error, "%s", fg_error_detail());
  }
  if (out) *out = *t;
  pthread_mutex_unlock(&svc->lock);
  return rc;
}

void robot_tcp_refresh(fg_robot_svc *svc, fg_mb_link *l) {
  if (svc->tcp_base >= 0) tcp_read(svc, l, NULL);
}

void fg_robot_tcp_get(fg_robot_svc *svc, fg_robot_tcp *out) {
  pthread_mutex_lock(&svc->lock);
  *out = svc->tcp;
  pthread_mutex_unlock(&svc->lock);
}

typedef struct tcp_job {
  fg_robot_svc *svc;
  fg_robot_tcp out;
} tcp_job;

static int tcp_job_run(fg_mb_link *l, void *arg) {
  tcp_job *j = arg;
  FG_TRY(fg_mb_link_ensure(l));
  return tcp_read(j->svc, l, &j->out);
}

int fg_robot_tcp_read(fg_robot_svc *svc, fg_robot_tcp *out) {
  if (!svc->robot)
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "no robot is configured: set [robot] "
                      "transport to read its TCP pose");
  if (svc->tcp_base < 0)
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "[robot] tcp_pose_base is none: the "
                      "controller publishes no TCP pose; give the pose itself");
  pthread_mutex_lock(&svc->lock);
  const uint64_t running = svc->active ? svc->active->v.id : 0;
  pthread_mutex_unlock(&svc->lock);
  if (running)
    return fg_fail_as(FG_EBUSY, "robot_busy", "command %llu is moving the robot; its pose is "
                      "read once it ends", (unsigned long long)running);
  tcp_job j = {.svc = svc};
  const int rc = fg_mb_peer_call(svc->robot, tcp_job_run, &j);
  if (rc == 0) {
    *out = j.out;
    return 0;
  }
  char why[512];
  snprintf(why, sizeof why, "%s", fg_error_detail());
  if (rc == FG_EPEER && fg_error_reason() && strcmp(fg_error_reason(), "tcp_pose_invalid") == 0)
    return fg_fail_as(rc, "tcp_pose_invalid", "%s", why);
  if (rc == FG_EPEER)
    return fg_fail_as(rc, "modbus_exception", "reading the TCP pose at %d: %s", svc->tcp_base,
                      why);
  if (rc == FG_ETIMEDOUT)
    return fg_fail_as(rc, "robot_timeout", "reading the TCP pose: %s", why);
  if (rc == FG_EBUSY || rc == FG_ECANCELED)
    return fg_fail_as(rc, "busy", "reading the TCP pose: %s", why);
  return fg_fail_as(FG_EUNAVAIL, "robot_disconnected", "reading the TCP pose: %s", why);
}
