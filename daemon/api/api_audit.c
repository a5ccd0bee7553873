/* The audit trail of the routes that move the robot or the gripper (POST /v1/robot/commands,
 * POST /v1/gripper/{action}, POST /v1/scenes/{s}/grasps/{id}/execute, and the jobs that
 * drive the robot: POST /v1/scenes/{s}/scan, POST /v1/cameras/{c}/calibrate with "drive"),
 * and GET /v1/robot/log that reads it back.
 *
 * The trail wraps those routes' handlers rather than living inside them, so that every
 * answer is recorded, whichever of the many places in them (decoding, a grasp not found,
 * Idempotency-Key replays, the robot's refusals, the command's end) gave it: the request as
 * the client sent it, and the outcome as the client received it. A request that is not a
 * dry run is refused (503 audit_unavailable) before its handler runs when the log cannot be
 * written: no motion without its line. A line that fails after the motion was sent is
 * logged as a warning and counted in /metrics; the answer stays what the robot did.
 *
 * Each answer of these routes carries X-Request-Id: the client's own when it sent a usable
 * one (1 to 128 visible ASCII characters), else one made here; the same id is in the log. */
#include "api.h"
#include "robot/audit.h"
#include "state/json.h"
#include "robot/robot.h"

#include "core/clock.h"
#include "core/error.h"

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>

#define REQUEST_ID_MAX 128

/* ---------------------------------------------------------------- the request */

/* The client's X-Request-Id when usable, else 16 random hex digits, into out. */
static void request_id(const fg_req *req, char out[REQUEST_ID_MAX + 1]) {
  const char *h = fg_req_header(req, "X-Request-Id");
  size_t n = h ? strlen(h) : 0;
  int ok = n >= 1 && n <= REQUEST_ID_MAX;
  for (size_t i = 0; ok && i < n; i++) ok = h[i] > 0x20 && h[i] < 0x7f;
  if (ok) {
    memcpy(out, h, n + 1);
    return;
  }
  uint64_t r = 0;
  if (getrandom(&r, sizeof r, GRND_NONBLOCK) != (ssize_t)sizeof r)
    r ^= (uint64_t)(uintptr_t)req ^ (uint64_t)(fg_mono_s() * 1e9); /* unique enough for a log */
  snprintf(out, REQUEST_ID_MAX + 1, "%016" PRIx64, r);
}

/* Adds "X-Request-Id: id" to the answer's other headers. */
static void header_add(fg_resp *resp, const char *id) {
  const size_t n = strlen(resp->header);
  snprintf(resp->header + n, sizeof resp->header - n, "%sX-Request-Id: %s", n ? "\r\n" : "", id);
}

/* The body as an object, or NULL (empty, not JSON, not an object: the handler says why). */
static json_t *body_object(const fg_req *req) {
  if (req->body_len == 0) return NULL;
  json_t *o = json_loadb((const char *)req->body, req->body_len, 0, NULL);
  if (!json_is_object(o)) {
    json_decref(o);
    return NULL;
  }
  return o;
}

/* ---------------------------------------------------------------- the line */

/* The line of one answered request. Values come from the body as sent; what the body does
 * not hold (a grasp execution's pose and width) from the command in the answer. */
static json_t *request_entry(const fg_req *req, const fg_resp *resp, json_t *body,
                             const char *client, const char *rid) {
  json_t *answer = resp->body && resp->len
                       ? json_loadb(resp->body, resp->len, 0, NULL) : NULL;
  json_t *err = json_object_get(answer, "error");
  json_t *cmd = resp->status < 400 ? answer : json_object_get(answer, "command");
  if (!json_is_object(cmd)) cmd = NULL;

  json_t *e = json_pack("{s:s, s:s}", "kind", "request", "route", req->path);
  const char *command = NULL;
  if (strncmp(req->path, "/v1/gripper/", 12) == 0) command = req->params[0];
  if (strcmp(req->path, "/v1/robot/stop") == 0) command = "stop";
  if (strcmp(req->path, "/v1/robot/reset") == 0) command = "reset";
  const size_t plen = strlen(req->path);
  if (plen > 5 && strcmp(req->path + plen - 5, "/scan") == 0) command = "scan";
  if (plen > 10 && strcmp(req->path + plen - 10, "/calibrate") == 0) command = "calibrate";
  if (!command) command = json_string_value(json_object_get(body, "command"));
  if (!command) command = json_string_value(json_object_get(cmd, "command"));
  json_object_set_new(e, "command", command ? json_string(command) : json_null());
  json_t *id = json_object_get(cmd, "id");
  json_object_set_new(e, "command_id", json_is_integer(id) ? json_incref(id) : json_null());
  static const char *const values[] = {"pose", "width", "force", "speed"};
  for (int i = 0; i < 4; i++) {
    json_t *v = json_object_get(body, values[i]);
    if (!v) v = json_object_get(cmd, values[i]);
    if (v) json_object_set(e, values[i], v);
  }
  json_object_set_new(e, "dry_run", json_boolean(json_is_true(json_object_get(body, "dry_run"))));
  json_t *wait = json_object_get(body, "wait");
  json_object_set_new(e, "wait", json_boolean(!json_is_false(wait)));

  const char *state = json_string_value(json_object_get(cmd, "state"));
  const int latch_route =
      command && (strcmp(command, "stop") == 0 || strcmp(command, "reset") == 0);
  const char *outcome = json_is_true(json_object_get(answer, "replayed")) ? "replayed"
                        : state                                          ? state
                        : resp->status < 400 && latch_route             ? "done"
                        : resp->status < 400                             ? "planned"
                                                                         : "refused";
  json_t *reason = json_object_get(body, "reason");
  if (latch_route && json_is_string(reason)) json_object_set(e, "reason", reason);
  json_object_set_new(e, "outcome", json_string(outcome));
  if (state && strcmp(outcome, "replayed") == 0) json_object_set_new(e, "state", json_string(state));
  json_object_set_new(e, "http_status", json_integer(resp->status));
  if (json_is_object(err))
    json_object_set_new(e, "error", json_pack("{s:O?, s:O?}", "code",
                                              json_object_get(err, "code"), "message",
                                              json_object_get(err, "message")));
  json_t *seq = json_object_get(cmd, "seq");
  if (json_is_integer(seq)) json_object_set(e, "robot_seq", seq);
  json_object_set_new(e, "client", json_string(client));
  json_object_set_new(e, "request_id", json_string(rid));
  const char *key = fg_req_header(req, "Idempotency-Key");
  json_object_set_new(e, "idempotency_key", key ? json_string(key) : json_null());
  json_decref(answer);
  return e;
}

/* Records one answered request; a command answered at its acknowledgement (202) gets its
 * end's line later (fg_api_audit_finished). */
static void record(fg_req *req, const fg_resp *resp, json_t *body, const char *client,
                   const char *rid) {
  json_t *e = request_entry(req, resp, body, client, rid);
  if (!e) return; /* out of memory: fg_audit_append would fail the same way, uncounted */
  json_t *id = json_object_get(e, "command_id");
  const int ends_later = resp->status == 202;
  const int dry = json_is_true(json_object_get(e, "dry_run"));
  if (json_is_integer(id) && !dry && json_is_false(json_object_get(e, "wait"))) {
    json_t *ctx = json_pack("{s:O, s:O, s:O, s:O, s:O}", "route", json_object_get(e, "route"),
                            "command", json_object_get(e, "command"), "client",
                            json_object_get(e, "client"), "request_id",
                            json_object_get(e, "request_id"), "idempotency_key",
                            json_object_get(e, "idempotency_key"));
    fg_audit_append_begun(req->app->audit, (uint64_t)json_integer_value(id), e, ends_later,
                          ctx);
    json_decref(ctx);
  } else {
    fg_audit_append(req->app->audit, e);
  }
  json_decref(e);
}

/* ---------------------------------------------------------------- the wrapped routes */

/* Runs handler under the audit: refuses a request that may move anything while the log
 * cannot be written, records the answer, and adds X-Request-Id. */
static int audited(fg_req *req, fg_resp *resp, fg_handler handler) {
  char rid[REQUEST_ID_MAX + 1], client[80];
  request_id(req, rid);
  fg_req_client(req, client, sizeof client);
  json_t *body = body_object(req);
  const int dry = json_is_true(json_object_get(body, "dry_run"));
  if (!dry && fg_audit_ready(req->app->audit) < 0) {
    fg_resp_error(resp, 503, "audit_unavailable", "nothing was sent: the robot's audit log "
                  "cannot be written (%s); free space or repair %s/audit and retry (dry runs "
                  "still work)", fg_error_detail(), req->conf->state_dir);
  } else {
    handler(req, resp);
  }
  record(req, resp, body, client, rid);
  json_decref(body);
  header_add(resp, rid);
  return 0;
}

/* A stop and a reset are recorded but never refused for want of the log: a stop must always
 * go through, and a reset moves nothing (motions after it still need the log). */
static int recorded(fg_req *req, fg_resp *resp, fg_handler handler) {
  char rid[REQUEST_ID_MAX + 1], client[80];
  request_id(req, rid);
  fg_req_client(req, client, sizeof client);
  json_t *body = body_object(req);
  handler(req, resp);
  record(req, resp, body, client, rid);
  json_decref(body);
  header_add(resp, rid);
  return 0;
}

int fg_api_audit_robot_stop(fg_req *req, fg_resp *resp) {
  return recorded(req, resp, fg_api_robot_stop);
}

int fg_api_audit_robot_reset(fg_req *req, fg_resp *resp) {
  return recorded(req, resp, fg_api_robot_reset);
}

int fg_api_audit_robot_command(fg_req *req, fg_resp *resp) {
  return audited(req, resp, fg_api_robot_command);
}

int fg_api_audit_gripper_action(fg_req *req, fg_resp *resp) {
  return audited(req, resp, fg_api_gripper_action);
}

int fg_api_audit_grasp_execute(fg_req *req, fg_resp *resp) {
  return audited(req, resp, fg_api_grasp_execute);
}

int fg_api_audit_scene_scan(fg_req *req, fg_resp *resp) {
  return audited(req, resp, fg_api_scene_scan);
}

/* A calibration moves the robot only when it drives it ("drive"); one on the views kept is
 * not the audit's. */
int fg_api_audit_camera_calibrate(fg_req *req, fg_resp *resp) {
  json_t *body = body_object(req);
  const int drives = json_object_get(body, "drive") != NULL;
  json_decref(body);
  return drives ? audited(req, resp, fg_api_camera_calibrate)
                : fg_api_camera_calibrate(req, resp);
}

void fg_api_audit_finished(fg_app *app, const fg_robot_cmd_view *v) {
  /* a command that was waited for has its end in its request's line already */
  if (!app->audit || v->req.dry_run || v->req.wait) return;
  char when[32];
  fg_iso8601((int64_t)(v->finished_s * 1000), when);
  const int status = v->state == FG_CMD_DONE ? 200 : fg_api_status(v->code);
  json_t *e = json_pack("{s:s, s:I, s:s, s:i, s:s}", "kind", "end", "command_id",
                        (json_int_t)v->id, "outcome", fg_cmd_state_name(v->state),
                        "http_status", status, "finished", when);
  if (!e) return;
  if (status >= 400)
    json_object_set_new(e, "error", json_pack("{s:s, s:s}", "code", v->code, "message",
                                              v->message));
  if (v->seq) json_object_set_new(e, "robot_seq", json_integer(v->seq));
  fg_audit_append_end(app->audit, v->id, e);
  json_decref(e);
}

/* ---------------------------------------------------------------- GET /v1/robot/log */

/* A query parameter as a whole number in [lo, hi]: 1 and *out, 0 when absent, -1 after
 * answering 400. */
static int query_count(fg_req *req, fg_resp *resp, const char *name, double lo, double hi,
                       uint64_t *out) {
  const char *s = fg_req_query(req, name);
  if (!s) return 0;
  double x;
  if (fg_query_number(s, &x) < 0 || x < lo || x > hi || x != floor(x)) {
    fg_resp_error(resp, 400, "invalid_request", "%s must be a whole number from %.0f to %.0f, "
                  "got \"%s\"", name, lo, hi, s);
    return -1;
  }
  *out = (uint64_t)x;
  return 1;
}

int fg_api_robot_log(fg_req *req, fg_resp *resp) {
  static const char *const known[] = {"limit", "before"};
  const char *unknown = fg_req_query_unknown(req, known, 2);
  if (unknown)
    return fg_resp_error(resp, 400, "invalid_request", "unknown parameter \"%s\"; expected "
                         "limit (1 to 1000) or before (an entry's seq)", unknown);
  uint64_t limit = 100, before = 0;
  if (query_count(req, resp, "limit", 1, 1000, &limit) < 0 ||
      query_count(req, resp, "before", 1, 9007199254740992.0, &before) < 0)
    return 0;
  json_t *entries;
  int more;
  if (fg_audit_read(req->app->audit, before, (int)limit, &entries, &more) < 0)
    return fg_resp_error(resp, 500, "internal_error", "cannot read the audit log: %s",
                         fg_error_detail());
  const size_t n = json_array_size(entries);
  json_t *last = n ? json_object_get(json_array_get(entries, n - 1), "seq") : NULL;
  fg_resp_json(resp, 200, json_pack("{s:o, s:O}", "entries", entries, "next_before",
                                    more && last ? last : json_null()));
  return 0;
}
