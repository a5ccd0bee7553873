/* The robot service's state for GET /v1/robot and /v1/gripper, and its /metrics lines. */
#include "robot_priv.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

/* ---------------------------------------------------------------- state and metrics */

/* The connection part of a peer's state; p may be NULL (not configured). */
static void peer_view(fg_mb_peer *p, int unit_id, fg_peer_view *v) {
  memset(v, 0, sizeof *v);
  v->configured = p != NULL;
  v->unit_id = unit_id;
  if (!p) return;
  fg_mb_link_state ls;
  fg_mb_peer_state(p, &ls);
  v->connected = ls.connected;
  snprintf(v->address, sizeof v->address, "%s", fg_mb_peer_address(p));
  memcpy(v->last_error, ls.last_error, sizeof v->last_error);
  v->last_error_s = ls.last_error_s;
  v->requests = ls.requests;
  v->errors = ls.errors;
  v->timeouts = ls.timeouts;
  v->exceptions = ls.exceptions;
  v->reconnects = ls.reconnects;
  v->generation = ls.generation;
}

void fg_robot_state_get(fg_robot_svc *svc, fg_robot_state *st) {
  memset(st, 0, sizeof *st);
  peer_view(svc->robot, svc->robot_unit, &st->peer);
  st->base = svc->rp.base;
  st->encoding = svc->rp.encoding;
  pthread_mutex_lock(&svc->lock);
  st->last_seq = svc->last_seq;
  st->ack = svc->ack;
  st->status = svc->status;
  st->busy = svc->active != NULL;
  st->last_command = svc->next_id - 1;
  st->tcp_pose_base = svc->tcp_base;
  st->tcp = svc->tcp;
  pthread_mutex_unlock(&svc->lock);
}

void fg_gripper_state_get(fg_robot_svc *svc, fg_gripper_state *st) {
  memset(st, 0, sizeof *st);
  peer_view(svc->gripper, svc->gripper_unit, &st->peer);
  st->model = svc->model->name;
  st->width_m = NAN;
  if (!svc->gripper) return;
  pthread_mutex_lock(&svc->lock);
  /* a status of an earlier connection is not this one's: the gripper may have been power
   * cycled (and lost its activation) in between */
  st->have_status = svc->g_have && st->peer.connected && svc->g_gen == st->peer.generation;
  st->status = svc->g_status;
  pthread_mutex_unlock(&svc->lock);
  if (st->have_status) st->width_m = fg_robotiq_position_to_width(svc->model, st->status.position);
}

/* Appends printf output to buf at *len, never past size. */
static void append(char *buf, size_t size, size_t *len, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void append(char *buf, size_t size, size_t *len, const char *fmt, ...) {
  if (*len + 1 >= size) return;
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(buf + *len, size - *len, fmt, ap);
  va_end(ap);
  if (n > 0) *len += (size_t)n < size - *len ? (size_t)n : size - *len - 1;
}

size_t fg_robot_metrics(fg_robot_svc *svc, char *buf, size_t size) {
  fg_mb_peer *peers[2] = {svc->robot, svc->gripper};
  static const char *const names[2] = {"robot", "gripper"};
  fg_mb_link_state ls[2] = {{0}, {0}};
  for (int i = 0; i < 2; i++)
    if (peers[i]) fg_mb_peer_state(peers[i], &ls[i]);
  size_t len = 0;
  buf[0] = '\0';
  append(buf, size, &len, "# HELP fieldgrip_modbus_connected Whether the Modbus peer is "
         "connected (absent: not configured).\n# TYPE fieldgrip_modbus_connected gauge\n");
  for (int i = 0; i < 2; i++)
    if (peers[i])
      append(buf, size, &len, "fieldgrip_modbus_connected{peer=\"%s\"} %d\n", names[i],
             ls[i].connected);
  append(buf, size, &len, "# HELP fieldgrip_modbus_requests_total Modbus requests sent.\n"
         "# TYPE fieldgrip_modbus_requests_total counter\n");
  for (int i = 0; i < 2; i++)
    if (peers[i])
      append(buf, size, &len, "fieldgrip_modbus_requests_total{peer=\"%s\"} %llu\n", names[i],
             (unsigned long long)ls[i].requests);
  /* Four distinct causes: no answer in time, an exception reply, a request that failed on the
   * wire (the connection dropped or was reset, or the reply was garbled), and an attempt to
   * open the connection that failed. */
  append(buf, size, &len, "# HELP fieldgrip_modbus_errors_total Modbus errors by kind: timeout "
         "(no reply in time), exception (an exception reply), transport (a request failed on "
         "the wire: connection lost or reply garbled), connect (a connection attempt failed)."
         "\n# TYPE fieldgrip_modbus_errors_total counter\n");
  for (int i = 0; i < 2; i++) {
    if (!peers[i]) continue;
    const fg_mb_link_state *l = &ls[i];
    append(buf, size, &len,
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"timeout\"} %llu\n"
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"exception\"} %llu\n"
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"transport\"} %llu\n"
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"connect\"} %llu\n",
           names[i], (unsigned long long)l->timeouts, names[i],
           (unsigned long long)l->exceptions, names[i],
           (unsigned long long)(l->errors - l->timeouts - l->exceptions), names[i],
           (unsigned long long)l->connect_failures);
  }
  append(buf, size, &len, "# HELP fieldgrip_modbus_reconnects_total Connections made after "
         "the first.\n# TYPE fieldgrip_modbus_reconnects_total counter\n");
  for (int i = 0; i < 2; i++)
    if (peers[i])
      append(buf, size, &len, "fieldgrip_modbus_reconnects_total{peer=\"%s\"} %llu\n",
             names[i], (unsigned long long)ls[i].reconnects);
  uint64_t by[FG_CMD_STATES];
  pthread_mutex_lock(&svc->lock);
  memcpy(by, svc->by_state, sizeof by);
  pthread_mutex_unlock(&svc->lock);
  append(buf, size, &len, "# HELP fieldgrip_robot_commands_total Robot and gripper commands "
         "finished, by outcome.\n# TYPE fieldgrip_robot_commands_total counter\n");
  for (int s = FG_CMD_DONE; s < FG_CMD_STATES; s++)
    append(buf, size, &len, "fieldgrip_robot_commands_total{state=\"%s\"} %llu\n",
           fg_cmd_state_name(s), (unsigned long long)by[s]);
  return len;
}
