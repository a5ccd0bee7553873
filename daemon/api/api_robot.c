/* The robot and the gripper over HTTP: POST /v1/robot/commands, GET /v1/robot and
 * /v1/robot/commands/{id}, GET /v1/gripper and POST /v1/gripper/{open,close,move,activate}.
 * Requests are checked here and run by robot.h; actuating requests may carry an
 * Idempotency-Key (idem.h). */
#include "api.h"
#include "api_decode.h"
#include "robot/cmd_ids.h"
#include "state/idem.h"
#include "state/json.h"
#include "robot/robot.h"

#include "core/error.h"
#include "core/log.h"

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const command_names[] = {NULL, "pick", "place", "open", "close", "move"};

/* ---------------------------------------------------------------- requests */

/* Reads the keys of a command or gripper request into *r. allowed: NULL-terminated key
 * names. Answers 400 itself and returns -1 on a bad request. */
int fg_api_parse_robot_request(json_t *body, const char *const *allowed, fg_robot_request *r,
                               fg_resp *resp) {
  memset(r, 0, sizeof *r);
  r->wait = 1;
  const char *key = fg_json_unknown_key(body, allowed);
  if (key) {
    char list[160] = "";
    for (int i = 0; allowed[i]; i++) {
      size_t n = strlen(list);
      snprintf(list + n, sizeof list - n, "%s%s", i ? ", " : "", allowed[i]);
    }
    fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; expected %s", key, list);
    return -1;
  }
  const char *cmd = NULL;
  if (fg_json_string(body, "command", &cmd) < 0 ||
      (json_object_get(body, "command") && !cmd)) {
    fg_resp_error(resp, 400, "invalid_request", "\"command\" must be a string");
    return -1;
  }
  if (cmd) {
    for (int c = FG_ROBOT_PICK; c <= FG_ROBOT_MOVE; c++)
      if (strcmp(cmd, command_names[c]) == 0) r->command = c;
    if (!r->command) {
      fg_resp_error(resp, 400, "invalid_request",
                    "unknown command \"%s\"; expected pick, place, open, close or move", cmd);
      return -1;
    }
  }
  json_t *pose = json_object_get(body, "pose");
  if (pose) {
    double T[16];
    /* the quaternion as given: its sign picks the rotation vector at a half turn */
    if (fg_json_pose_parse(pose, "pose", T, r->q_wxyz) < 0) {
      fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail());
      return -1;
    }
    r->has_pose = 1;
    for (int i = 0; i < 3; i++) r->p_world_m[i] = T[4 * i + 3];
  }
  static const char *const nums[] = {"width", "force", "speed", "approach", "retreat"};
  static const char *const units[] = {"metres", "newtons", "m/s", "metres", "metres"};
  double *dst[] = {&r->width_m, &r->force_n, &r->speed_mps, &r->approach_m, &r->retreat_m};
  int *has[] = {&r->has_width, &r->has_force, &r->has_speed, &r->has_approach,
                &r->has_retreat};
  for (int i = 0; i < 5; i++) {
    int rc = fg_json_number(body, nums[i], dst[i]);
    if (rc < 0 || (json_object_get(body, nums[i]) && rc == 0)) {
      fg_resp_error(resp, 400, "invalid_request", "\"%s\" must be a finite number (%s)",
                    nums[i], units[i]);
      return -1;
    }
    *has[i] = rc == 1;
  }
  static const char *const flags[] = {"dry_run", "wait", "allow_drop"};
  int *fl[] = {&r->dry_run, &r->wait, &r->allow_drop};
  for (int i = 0; i < 3; i++) {
    json_t *b = json_object_get(body, flags[i]);
    if (!b) continue;
    if (!json_is_boolean(b)) {
      fg_resp_error(resp, 400, "invalid_request", "\"%s\" must be true or false", flags[i]);
      return -1;
    }
    *fl[i] = json_is_true(b);
  }
  return 0;
}

/* ---------------------------------------------------------------- views */

static json_t *words_json(const uint16_t *w, int n) {
  json_t *a = json_array();
  for (int i = 0; a && i < n; i++) json_array_append_new(a, json_integer(w[i]));
  return a;
}

/* A time in seconds since the epoch as JSON (null when not set). */
static json_t *time_json(double s) { return fg_json_time_ms(s > 0 ? (int64_t)(s * 1000) : 0); }

static json_t *command_json(const fg_robot_cmd_view *v) {
  json_t *o = json_object();
  if (!o) return NULL;
  if (!v->req.dry_run && v->id) json_object_set_new(o, "id", json_integer((json_int_t)v->id));
  json_object_set_new(o, "command", json_string(command_names[v->command]));
  json_object_set_new(o, "dry_run", json_boolean(v->req.dry_run));
  if (!v->req.dry_run) {
    json_object_set_new(o, "state", json_string(fg_cmd_state_name(v->state)));
    json_object_set_new(o, "stage", json_string(v->stage));
  }
  json_object_set_new(o, "seq", v->seq ? json_integer(v->seq) : json_null());
  if (v->req.has_pose) json_object_set_new(o, "pose", fg_json_pose_quat(v->req.p_world_m, v->req.q_wxyz));
  if (v->req.has_width) json_object_set_new(o, "width", json_real(v->req.width_m));
  if (v->req.has_force) json_object_set_new(o, "force", json_real(v->req.force_n));
  if (v->req.has_speed) json_object_set_new(o, "speed", json_real(v->req.speed_mps));
  if (v->req.has_approach) json_object_set_new(o, "approach", json_real(v->req.approach_m));
  if (v->req.has_retreat) json_object_set_new(o, "retreat", json_real(v->req.retreat_m));
  if (!v->req.dry_run) {
    json_object_set_new(o, "wait", json_boolean(v->req.wait));
    json_object_set_new(o, "robot_status",
                        v->robot_status >= 0 ? json_integer(v->robot_status) : json_null());
    json_object_set_new(o, "ack_ms", v->ack_ms >= 0 ? json_real(v->ack_ms) : json_null());
    json_object_set_new(o, "object_detected", v->object_detected >= 0
                                                  ? json_boolean(v->object_detected)
                                                  : json_null());
    json_object_set_new(o, "gripper_width",
                        isnan(v->gripper_width_m) ? json_null() : json_real(v->gripper_width_m));
    json_object_set_new(o, "created", time_json(v->created_s));
    json_object_set_new(o, "finished", time_json(v->finished_s));
  }
  json_t *regs = json_object(), *grip = json_array();
  for (int i = 0; i < v->n_steps; i++) {
    const fg_robot_step *st = &v->steps[i];
    if (st->kind == FG_STEP_ROBOT) {
      json_object_set_new(
          regs, st->name,
          json_pack("{s:i, s:i, s:i, s:i, s:s, s:o}", "unit_id", v->robot_unit, "function", 16,
                    "address", st->address, "count", st->n_words, "encoding",
                    v->encoding == FG_POSE_FLOAT32 ? "float32" : "int16", "words",
                    words_json(st->words, st->n_words)));
    } else {
      json_array_append_new(
          grip, json_pack("{s:s, s:i, s:i, s:i, s:i, s:i, s:i, s:o}", "step", st->name,
                          "unit_id", v->gripper_unit, "function", 16, "address", st->address,
                          "position", st->position, "speed", st->speed, "force", st->force,
                          "words", words_json(st->words, st->n_words)));
    }
  }
  json_object_set_new(regs, "gripper", grip);
  json_object_set_new(o, "registers", regs);
  return o;
}

/* The answer to a command view: the command (200, 202), or the error with the command
 * beside it. *status gets the HTTP status. */
static json_t *answer_json(const fg_robot_cmd_view *v, int *status) {
  json_t *cmd = command_json(v);
  *status = v->req.dry_run || v->state == FG_CMD_DONE ? 200
            : v->finished_s == 0                     ? 202
                                                     : fg_api_status(v->code);
  if (*status < 400) return cmd;
  return json_pack("{s:{s:s, s:s}, s:o}", "error", "code", v->code, "message", v->message,
                   "command", cmd);
}

/* Sends o with status, and the command's Location while it runs (202). */
static void answer_send(fg_resp *resp, json_t *o, int status, uint64_t id) {
  if (status == 202 && id)
    snprintf(resp->location, sizeof resp->location, "/v1/robot/commands/%" PRIu64, id);
  fg_resp_json(resp, status, o);
}

/* The answer for an error a command stopped at before it ran; v holds what was planned (a
 * limit's refusal shows the limit and the words that were not sent). */
static int answer_refusal(fg_resp *resp, int rc, const fg_robot_cmd_view *v) {
  if (rc != FG_ELIMIT) return fg_api_fail(resp, rc);
  const fg_motion_violation *mv = &v->violation;
  fg_robot_cmd_view plan = *v; /* shown as a dry run: the words that were not sent */
  plan.req.dry_run = 1;
  const char *code = fg_api_fail_code(rc);
  json_t *o = json_pack("{s:{s:s, s:s, s:s?, s:o, s:o}, s:o}", "error", "code", code, "message",
                        fg_error_detail(), "limit", mv->limit, "value",
                        isfinite(mv->value) ? json_real(mv->value) : json_null(), "bound",
                        isfinite(mv->bound) ? json_real(mv->bound) : json_null(), "command",
                        command_json(&plan));
  fg_resp_json(resp, fg_api_status(code), o);
  return 0;
}

/* ---------------------------------------------------------------- idempotency */

/* The answer of an Idempotency-Key lookup: answers a replay (or a conflict) itself and
 * returns 1; returns 0 when the request is to run (FG_IDEM_NEW), -1 after answering an
 * error. */
static int idem_answer(fg_resp *resp, int rc, int status, char *body) {
  switch (rc) {
  case FG_IDEM_NEW: return 0;
  case FG_IDEM_RUNNING:
    return fg_resp_error(resp, 409, "idempotency_in_progress", "the request with this "
                         "Idempotency-Key is still running; ask again when it has finished"), 1;
  case FG_IDEM_CONFLICT:
    return fg_resp_error(resp, 422, "idempotency_key_reused", "this Idempotency-Key was used "
                         "for a different request; use a new key for a new command"), 1;
  case FG_IDEM_REPLAY: {
    /* kept current by fg_api_robot_finished: a command answered at its acknowledgement
     * (202) is replaced by its end once it has one */
    json_t *o = json_loads(body, 0, NULL);
    free(body);
    if (json_is_object(o)) json_object_set_new(o, "replayed", json_true());
    fg_resp_json(resp, status, o);
    return 1;
  }
  case FG_ERANGE:
    return fg_resp_error(resp, 507, "idempotency_store_full", "%s", fg_error_detail()), -1;
  case FG_ENOSPC:
    return fg_resp_error(resp, 507, "insufficient_storage", "the Idempotency-Key could not "
                         "be stored, so the command was not run: %s", fg_error_detail()), -1;
  default:
    return fg_resp_error(resp, 503, "state_unavailable", "the Idempotency-Key could not be "
                         "stored, so the command was not run: %s", fg_error_detail()), -1;
  }
}

static fg_idem_request idem_request(const fg_req *req) {
  return (fg_idem_request){req->method, req->path, req->body, req->body_len};
}

int fg_api_idem_replay(fg_req *req, fg_resp *resp) {
  const char *key = fg_req_header(req, "Idempotency-Key");
  if (!key) return 0;
  if (!fg_idem_key_valid(key))
    return fg_resp_error(resp, 400, "invalid_request", "Idempotency-Key must be 1 to %d "
                         "printable ASCII characters", FG_IDEM_KEY_MAX), 1;
  int status = 0;
  char *body = NULL;
  const fg_idem_request rq = idem_request(req);
  const int rc = fg_idem_peek(req->app->idem, key, &rq, &status, &body);
  return idem_answer(resp, rc, status, body) != 0;
}

/* Takes the request's Idempotency-Key, if it has one (fg_api_idem_replay checked it first):
 * answers a replay (or a conflict: another request took it since the check) itself and
 * returns 1; returns 0 with *key set when the request is to run, -1 after answering an
 * error. */
static int idem_begin(fg_req *req, fg_resp *resp, const char **key) {
  *key = fg_req_header(req, "Idempotency-Key");
  if (!*key) return 0;
  int status = 0;
  char *body = NULL;
  const fg_idem_request rq = idem_request(req);
  const int rc = fg_idem_begin(req->app->idem, *key, &rq, &status, &body);
  return idem_answer(resp, rc, status, body);
}

/* ---------------------------------------------------------------- handlers */

void fg_api_robot_finished(void *ctx, const fg_robot_cmd_view *v) {
  fg_app *app = ctx;
  fg_api_audit_finished(app, v);
  if (!v->req.key[0]) return;
  int status;
  json_t *o = answer_json(v, &status);
  char *text = o ? json_dumps(o, JSON_COMPACT) : NULL;
  json_decref(o);
  if (!text || fg_idem_update(app->idem, v->req.key, status, text) < 0)
    fg_warn("robot: the end of command %" PRIu64 " was not stored for its Idempotency-Key "
            "%s: %s", v->id, v->req.key, text ? fg_error_detail() : "out of memory");
  free(text);
}

/* The body as an object; an empty body is {} (a bare POST /v1/gripper/close). */
static json_t *body_or_empty(fg_req *req, fg_resp *resp) {
  if (req->body_len == 0) return json_object();
  return fg_api_body_object(req, resp);
}

/* Runs an actuating request under its Idempotency-Key: run() fills *v or returns a refusal. */
typedef int (*run_fn)(fg_req *req, const char *action, const fg_robot_request *r,
                      fg_robot_cmd_view *v);

static int run_robot(fg_req *req, const char *action, const fg_robot_request *r,
                     fg_robot_cmd_view *v) {
  (void)action;
  return r->dry_run ? fg_robot_plan(req->app->robot, r, v)
                    : fg_robot_execute(req->app->robot, r, v);
}

static int run_gripper(fg_req *req, const char *action, const fg_robot_request *r,
                       fg_robot_cmd_view *v) {
  return fg_gripper_action(req->app->robot, action, r, v);
}

static int actuate(fg_req *req, fg_resp *resp, const char *action, fg_robot_request *r,
                   run_fn run) {
  const char *key = NULL;
  if (!r->dry_run) {
    int ir = idem_begin(req, resp, &key);
    if (ir != 0) return 0;
    if (key) snprintf(r->key, sizeof r->key, "%s", key);
  }
  fg_robot_cmd_view v;
  memset(&v, 0, sizeof v);
  int rc = run(req, action, r, &v);
  if (rc < 0) {
    if (key) fg_idem_cancel(req->app->idem, key); /* nothing ran: the key may be used again */
    return answer_refusal(resp, rc, &v);
  }
  int status;
  json_t *o = answer_json(&v, &status);
  if (action && o) {
    json_t *cmd = status < 400 ? o : json_object_get(o, "command");
    json_object_del(cmd, "command");
    json_object_set_new(cmd, "action", json_string(action));
  }
  if (key) {
    char *text = json_dumps(o, JSON_COMPACT);
    if (!text || fg_idem_finish(req->app->idem, key, status, text) < 0)
      fg_warn("robot: the answer of Idempotency-Key %s was not stored: %s", key,
              fg_error_detail());
    free(text);
  }
  answer_send(resp, o, status, v.id);
  return 0;
}

int fg_api_robot_command(fg_req *req, fg_resp *resp) {
  if (fg_api_idem_replay(req, resp)) return 0;
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return 0;
  static const char *const keys[] = {"command", "pose",    "width",   "force", "speed",
                                     "approach", "retreat", "dry_run", "wait",  NULL};
  fg_robot_request r;
  int rc = fg_api_parse_robot_request(body, keys, &r, resp);
  json_decref(body);
  if (rc < 0) return 0;
  if (!r.command)
    return fg_resp_error(resp, 400, "invalid_request",
                         "\"command\" is required: pick, place, open, close or move");
  return actuate(req, resp, NULL, &r, run_robot);
}

int fg_api_robot_run(fg_req *req, fg_resp *resp, fg_robot_request *r) {
  return actuate(req, resp, NULL, r, run_robot);
}

int fg_api_robot_command_get(fg_req *req, fg_resp *resp) {
  char *end;
  const unsigned long long id = strtoull(req->params[0], &end, 10);
  fg_robot_cmd_view v;
  if (*end || end == req->params[0])
    return fg_resp_error(resp, 404, "not_found", "no command \"%s\": ids are whole numbers",
                         req->params[0]);
  const uint64_t first = fg_cmd_ids_first(req->app->cmd_ids);
  if (id < first)
    return fg_resp_error(resp, 404, "not_found", "command %llu is from before the daemon last "
                         "started (this run's commands start at %" PRIu64 "); its record is "
                         "not kept", id, first);
  if (fg_robot_command_get(req->app->robot, id, &v) < 0)
    return fg_resp_error(resp, 404, "not_found", "no command %llu (ids are never reused; the "
                         "newest 1000 commands since the daemon last started are kept)", id);
  fg_resp_json(resp, 200, command_json(&v));
  return 0;
}

static json_t *error_json(const char *msg, double at_s) {
  if (!msg[0]) return json_null();
  return json_pack("{s:s, s:o}", "message", msg, "at", time_json(at_s));
}

/* The keys both peers report: configured, profile, address, unit_id, connected,
 * last_error, counters. */
static json_t *peer_json(const fg_peer_view *p, const char *profile) {
  return json_pack("{s:b, s:s, s:s?, s:i, s:b, s:o, s:{s:I, s:I, s:I, s:I, s:I}}",
                   "configured", p->configured, "profile", profile, "address",
                   p->configured ? p->address : NULL, "unit_id", p->unit_id, "connected",
                   p->connected, "last_error", error_json(p->last_error, p->last_error_s),
                   "counters", "requests", (json_int_t)p->requests, "errors",
                   (json_int_t)p->errors, "timeouts", (json_int_t)p->timeouts, "exceptions",
                   (json_int_t)p->exceptions, "reconnects", (json_int_t)p->reconnects);
}

static json_t *int_or_null(int v) { return v >= 0 ? json_integer(v) : json_null(); }

static json_t *vec3_json(const double v[3]) { return json_pack("[f, f, f]", v[0], v[1], v[2]); }

/* The limits in force and the path defaults, as GET /v1/robot shows them. */
static json_t *limits_json(fg_robot_svc *svc) {
  fg_motion_limits l;
  fg_robot_limits_get(svc, &l);
  double approach, retreat, speed;
  fg_robot_path_defaults(svc, &approach, &retreat, &speed);
  return json_pack("{s:o, s:o, s:f, s:f, s:f, s:f, s:f, s:f, s:f}", "position_box",
                   l.has_box ? json_pack("{s:o, s:o}", "min", vec3_json(l.box_min_m), "max",
                                         vec3_json(l.box_max_m))
                             : json_null(),
                   "reach", l.reach_m > 0 ? json_real(l.reach_m) : json_null(),
                   "approach_cone_deg", l.cone_rad * (180 / M_PI), "max_force", l.max_force_n,
                   "max_speed", l.max_speed_mps, "max_width", l.max_width_m, "speed", speed,
                   "approach", approach, "retreat", retreat);
}

static json_t *latch_json(fg_robot_svc *svc) {
  fg_robot_latch l;
  fg_robot_latch_get(svc, &l);
  if (!l.latched) return json_null();
  return json_pack("{s:s, s:o, s:o, s:b, s:b}", "reason", l.reason, "at", time_json(l.at_s),
                   "command", l.command ? json_integer((json_int_t)l.command) : json_null(),
                   "stop_written", l.stop_written, "clear_pending", l.clear_pending);
}

/* POST /v1/robot/stop: always answers 200 once latched; says whether the robot got it. */
int fg_api_robot_stop(fg_req *req, fg_resp *resp) {
  json_t *body = body_or_empty(req, resp);
  if (!body) return 0;
  const char *reason = "POST /v1/robot/stop";
  const char *key;
  json_t *v;
  json_object_foreach(body, key, v) {
    if (strcmp(key, "reason") != 0 || !json_is_string(v) || json_string_length(v) > 200) {
      json_decref(body);
      return fg_resp_error(resp, 400, "invalid_request", "stop takes only \"reason\": a text "
                           "of at most 200 characters (the body may also be empty)");
    }
    reason = json_string_value(v);
  }
  char why[256];
  snprintf(why, sizeof why, "stopped: %s", reason);
  json_decref(body);
  int written;
  uint64_t id;
  const int rc = fg_robot_stop(req->app->robot, why, &written, &id);
  if (rc < 0) return fg_api_fail(resp, rc);
  fg_resp_json(resp, 200, json_pack("{s:b, s:b, s:o, s:o}", "latched", 1, "stop_written",
                                    written, "stopped_command",
                                    id ? json_integer((json_int_t)id) : json_null(), "robot",
                                    latch_json(req->app->robot)));
  return 0;
}

/* POST /v1/robot/reset: clears the latch once the robot's stop register is back at 0. */
int fg_api_robot_reset(fg_req *req, fg_resp *resp) {
  if (req->body_len) {
    json_t *body = fg_api_body_object(req, resp);
    if (!body) return 0;
    const size_t n = json_object_size(body);
    json_decref(body);
    if (n) return fg_resp_error(resp, 400, "invalid_request", "reset takes no keys");
  }
  const int rc = fg_robot_reset(req->app->robot);
  if (rc < 0) return fg_api_fail(resp, rc);
  fg_resp_json(resp, 200, json_pack("{s:b}", "latched", 0));
  return 0;
}

/* The last TCP pose read (world frame) and when; null before the first. */
static json_t *tcp_json(const fg_robot_tcp *t) {
  if (!t->have) return json_null();
  json_t *o = fg_json_pose_quat(t->p_m, t->q_wxyz);
  json_object_set_new(o, "read_at", fg_json_time_ms(t->read_ms));
  return o;
}

int fg_api_robot_get(fg_req *req, fg_resp *resp) {
  fg_robot_state st;
  fg_robot_state_get(req->app->robot, &st);
  json_t *o = peer_json(&st.peer, "pose-registers");
  json_object_set_new(o, "base", json_integer(st.base));
  json_object_set_new(o, "encoding",
                      json_string(st.encoding == FG_POSE_FLOAT32 ? "float32" : "int16"));
  json_object_set_new(o, "busy", json_boolean(st.busy));
  json_object_set_new(o, "last_seq", st.last_seq ? json_integer(st.last_seq) : json_null());
  json_object_set_new(o, "ack", int_or_null(st.ack));
  json_object_set_new(o, "status", int_or_null(st.status));
  json_object_set_new(o, "limits", limits_json(req->app->robot));
  json_object_set_new(o, "latched", latch_json(req->app->robot));
  json_object_set_new(o, "tcp_pose_base", int_or_null(st.tcp_pose_base));
  json_object_set_new(o, "tcp_pose", tcp_json(&st.tcp));
  json_object_set_new(o, "tcp_pose_error", st.tcp.error[0] ? json_string(st.tcp.error)
                                                           : json_null());
  fg_robot_cmd_view v;
  json_object_set_new(o, "last_command",
                      st.last_command && fg_robot_command_get(req->app->robot, st.last_command,
                                                              &v) == 0
                          ? command_json(&v)
                          : json_null());
  fg_resp_json(resp, 200, o);
  return 0;
}

int fg_api_gripper_get(fg_req *req, fg_resp *resp) {
  fg_gripper_state st;
  fg_gripper_state_get(req->app->robot, &st);
  const fg_robotiq_status *s = &st.status;
  json_t *o = peer_json(&st.peer, "robotiq-2f");
  json_object_set_new(o, "model", json_string(st.model));
  const int have = st.have_status;
  json_object_set_new(o, "activated", have ? json_boolean(s->sta == 3 && s->act) : json_null());
  json_object_set_new(o, "width", have ? json_real(st.width_m) : json_null());
  json_object_set_new(o, "object_detected",
                      have ? json_boolean(fg_robotiq_object_detected(s)) : json_null());
  json_object_set_new(o, "fault", have && s->flt ? json_pack("{s:i, s:s}", "code", s->flt, "name",
                                                             fg_robotiq_fault_name(s->flt))
                                                 : json_null());
  if (have)
    json_object_set_new(o, "registers",
                        json_pack("{s:i, s:i, s:i, s:i, s:i, s:i, s:i, s:i, s:i}", "gACT",
                                  s->act, "gGTO", s->gto, "gSTA", s->sta, "gOBJ", s->obj,
                                  "gFLT", s->flt, "kFLT", s->kflt, "gPR", s->echo, "gPO",
                                  s->position, "gCU", s->current));
  json_object_set_new(o, "state", json_string(!st.peer.configured ? "not_configured"
                                              : !st.peer.connected ? "disconnected"
                                              : !have ? "connected"
                                              : s->flt >= 0x08 ? "fault"
                                              : s->sta == 3 && s->act ? "ready"
                                              : s->sta == 1 ? "activating"
                                                            : "not_activated"));
  fg_resp_json(resp, 200, o);
  return 0;
}

int fg_api_gripper_action(fg_req *req, fg_resp *resp) {
  if (fg_api_idem_replay(req, resp)) return 0;
  static const char *const actions[] = {"open", "close", "move", "activate", NULL};
  const char *action = NULL;
  for (int i = 0; actions[i]; i++)
    if (strcmp(req->params[0], actions[i]) == 0) action = actions[i];
  if (!action)
    return fg_resp_error(resp, 404, "not_found", "no gripper action \"%s\"; expected open, "
                         "close, move or activate", req->params[0]);
  json_t *body = body_or_empty(req, resp);
  if (!body) return 0;
  static const char *const keys[] = {"width", "speed", "force", "dry_run", NULL};
  static const char *const activate_keys[] = {"dry_run", "allow_drop", NULL};
  fg_robot_request r;
  int rc = fg_api_parse_robot_request(body, strcmp(action, "activate") == 0 ? activate_keys : keys,
                                      &r, resp);
  json_decref(body);
  if (rc < 0) return 0;
  return actuate(req, resp, action, &r, run_gripper);
}
