/* Training jobs over HTTP: start a training, list, describe and cancel jobs, and follow one
 * as Server-Sent Events. */
#include "api.h"
#include "api_decode.h"
#include "state/job_train.h"
#include "state/jobs.h"
#include "state/json.h"

#include "core/clock.h"
#include "core/error.h"
#include "field/train.h"

#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---------------------------------------------------------------- POST .../train */

/* Reads key as a whole number in [lo, hi]: 1 present, 0 absent (or null), FG_EINVAL. */
static int json_whole(json_t *obj, const char *key, long long lo, long long hi, long long *out) {
  const int rc = fg_json_int_range(obj, key, lo, hi, out);
  if (rc < 0)
    return fg_fail(FG_EINVAL, "\"%s\" must be a whole number from %lld to %lld", key, lo, hi);
  return rc;
}

/* The seed: a JSON integer 0..2^63-1, or a decimal string 0..2^64-1 (JSON parsers, this
 * one included, hold integers in 64-bit signed numbers). */
static int json_seed(json_t *obj, uint64_t *out) {
  json_t *v = json_object_get(obj, "seed");
  if (!v || json_is_null(v)) return 0;
  if (json_is_integer(v) && json_integer_value(v) >= 0) {
    *out = (uint64_t)json_integer_value(v);
    return 1;
  }
  if (json_is_string(v)) {
    const char *s = json_string_value(v);
    char *end;
    errno = 0;
    unsigned long long x = strtoull(s, &end, 10);
    if (*s >= '0' && *s <= '9' && *end == '\0' && errno == 0) {
      *out = (uint64_t)x;
      return 1;
    }
  }
  return fg_fail(FG_EINVAL, "\"seed\" must be a whole number from 0 to 2^63-1, or a string of "
                 "decimal digits up to 2^64-1");
}

/* A loss weight: a number from 0 to FG_TRAIN_MAX_LOSS_WEIGHT, kept in *out when absent. */
static int json_loss_weight(json_t *obj, const char *key, double *out) {
  double w;
  const int rc = fg_json_number(obj, key, &w);
  FG_TRY(rc);
  if (rc && !(w >= 0.0 && w <= FG_TRAIN_MAX_LOSS_WEIGHT))
    return fg_fail(FG_EINVAL, "\"%s\" must be a number from 0 to %g", key,
                   (double)FG_TRAIN_MAX_LOSS_WEIGHT);
  if (rc) *out = w;
  return 0;
}

/* "captures": "latest" (the default), "all", or an array of 1..FG_JOB_MAX_CAPTURES distinct
 * capture numbers. */
static int json_captures(json_t *obj, fg_job_params *p) {
  json_t *v = json_object_get(obj, "captures");
  if (!v || json_is_null(v)) return 0;
  if (json_is_string(v) && strcmp(json_string_value(v), "latest") == 0) return 0;
  if (json_is_string(v) && strcmp(json_string_value(v), "all") == 0) {
    p->all_captures = 1;
    return 0;
  }
  const size_t n = json_is_array(v) ? json_array_size(v) : 0;
  int ok = n >= 1 && n <= FG_JOB_MAX_CAPTURES;
  for (size_t i = 0; ok && i < n; i++) {
    json_t *c = json_array_get(v, i);
    ok = json_is_integer(c) && json_integer_value(c) >= 1 &&
         json_integer_value(c) <= FG_CAPTURE_MAX;
    for (size_t k = 0; ok && k < i; k++) ok = p->captures[k] != json_integer_value(c);
    if (ok) p->captures[i] = json_integer_value(c);
  }
  if (!ok)
    return fg_fail(FG_EINVAL, "\"captures\" must be \"latest\", \"all\" or a list of 1 to %d "
                   "different capture numbers (GET .../captures lists them)",
                   FG_JOB_MAX_CAPTURES);
  p->n_captures = (int)n;
  return 0;
}

/* "init": "random" (the default) or "current". */
static int json_init(json_t *obj, fg_job_params *p) {
  json_t *v = json_object_get(obj, "init");
  if (!v || json_is_null(v)) return 0;
  const char *s = json_string_value(v);
  if (s && strcmp(s, "random") == 0) return 0;
  if (s && strcmp(s, "current") == 0) {
    p->init_current = 1;
    return 0;
  }
  return fg_fail(FG_EINVAL, "\"init\" must be \"random\" (a new field) or \"current\" (go on "
                 "from the scene's field)");
}

/* "focus": the share of an update's rays drawn where the views changed, 0..1; default
 * FG_TRAIN_FOCUS_FRACTION for an update, none for a new field (which has no views to
 * compare). After json_init. */
static int json_focus(json_t *obj, fg_job_params *p) {
  p->focus = p->init_current ? FG_TRAIN_FOCUS_FRACTION : 0.0;
  double f;
  const int rc = fg_json_number(obj, "focus", &f);
  FG_TRY(rc);
  if (!rc) return 0;
  if (!(f >= 0.0 && f <= 1.0))
    return fg_fail(FG_EINVAL, "\"focus\" must be a share of the rays from 0 to 1");
  if (f > 0.0 && !p->init_current)
    return fg_fail(FG_EINVAL, "\"focus\" draws an update's rays where the views differ from "
                   "the scene's field; it needs \"init\": \"current\"");
  p->focus = f;
  return 0;
}

/* Reads the body of POST .../train over the defaults. 0, or FG_EINVAL with a detail. */
static int train_params(json_t *body, const fg_conf *conf, fg_job_params *p) {
  static const char *const keys[] = {"steps",        "seed",
                                     "max_seconds",  "holdout_every",
                                     "depth_weight", "distortion_weight",
                                     "captures",     "init",
                                     "focus",        NULL};
  const char *key = fg_json_unknown_key(body, keys);
  if (key)
    return fg_fail(FG_EINVAL, "unknown key \"%s\"; a training takes steps, seed, max_seconds, "
                   "holdout_every, depth_weight, distortion_weight, captures, init and focus", key);
  memset(p, 0, sizeof *p);
  p->steps = conf->train_steps;
  long long x = 0;
  int rc = json_whole(body, "steps", 1, FG_TRAIN_MAX_STEPS, &x);
  FG_TRY(rc);
  if (rc) p->steps = x;
  FG_TRY(json_seed(body, &p->seed));
  double ms;
  rc = fg_json_number(body, "max_seconds", &ms);
  FG_TRY(rc);
  if (rc && !(ms > 0))
    return fg_fail(FG_EINVAL, "\"max_seconds\" must be a positive number of seconds (leave it "
                   "out for no limit)");
  if (rc) p->max_seconds = ms;
  rc = json_whole(body, "holdout_every", 0, 1000000, &x);
  FG_TRY(rc);
  if (rc) p->holdout_every = (int)x;
  p->depth_weight = conf->depth_weight;
  p->distortion_weight = conf->distortion_weight;
  FG_TRY(json_loss_weight(body, "depth_weight", &p->depth_weight));
  FG_TRY(json_loss_weight(body, "distortion_weight", &p->distortion_weight));
  FG_TRY(json_captures(body, p));
  FG_TRY(json_init(body, p));
  FG_TRY(json_focus(body, p));
  return 0;
}

int fg_api_parse_train(json_t *body, const fg_conf *conf, fg_job_params *p, fg_resp *resp) {
  if (train_params(body, conf, p) == 0) return 0;
  fg_resp_error(resp, 400, "invalid_request", "%s", fg_error_detail());
  return -1;
}

int fg_api_train_start(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  /* An empty body takes every default. */
  json_t *body = req->body_len == 0 ? json_object() : fg_api_body_object(req, resp);
  if (!body) goto out;
  fg_job_params p;
  if (fg_api_parse_train(body, req->conf, &p, resp) != 0) goto out;
  fg_job_info job;
  int rc = fg_train_check(req->app, s, &p);
  if (rc == 0) rc = fg_jobs_submit(req->app->jobs, FG_JOB_KIND_TRAIN, s, &p, NULL, &job);
  if (rc != 0) {
    fg_api_fail(resp, rc);
  } else {
    snprintf(resp->location, sizeof resp->location, "/v1/jobs/%s", job.id);
    fg_resp_json(resp, 202, json_pack("{s:s,s:s}", "job", job.id, "state",
                                      fg_job_state_name(job.state)));
  }
out:
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}

/* ---------------------------------------------------------------- jobs */

int fg_api_jobs_list(fg_req *req, fg_resp *resp) {
  fg_job_info *v;
  size_t n;
  if (fg_jobs_list(req->app->jobs, &v, &n) != 0)
    return fg_resp_error(resp, 500, "internal_error", "%s", fg_error_detail());
  json_t *arr = json_array();
  for (size_t i = 0; arr && i < n; i++) json_array_append_new(arr, fg_job_info_json(&v[i]));
  free(v);
  fg_resp_json(resp, 200, json_pack("{s:o}", "jobs", arr));
  return 0;
}

int fg_api_job_get(fg_req *req, fg_resp *resp) {
  fg_job *j = fg_jobs_get(req->app->jobs, req->params[0]);
  if (!j) return fg_api_fail(resp, FG_ENOENT);
  fg_job_info info;
  fg_job_get_info(j, &info);
  fg_job_unref(j);
  fg_resp_json(resp, 200, fg_job_info_json(&info));
  return 0;
}

int fg_api_job_cancel(fg_req *req, fg_resp *resp) {
  fg_job_info info;
  int rc = fg_jobs_cancel(req->app->jobs, req->params[0], &info);
  if (rc != 0) return fg_api_fail(resp, rc);
  fg_resp_json(resp, 200, fg_job_info_json(&info));
  return 0;
}

/* ---------------------------------------------------------------- GET /v1/jobs/{id}/events */

/* Seconds between progress events at most, and between keep-alive comments (which also let
 * the server notice a client that went away). */
#define SSE_MIN_INTERVAL 0.25
#define SSE_KEEPALIVE 15.0

static atomic_int n_streams;

typedef struct sse_stream {
  fg_job *job;           /* a reference */
  uint64_t sent_version; /* of the last progress event */
  double last_sent;      /* CLOCK_MONOTONIC seconds of the last event or comment; 0: none */
  int final_sent;
  char *pending;         /* bytes of the current event not yet handed over */
  size_t pending_len, pending_off;
} sse_stream;


/* One event: "event: NAME\ndata: JSON\n\n" (compact JSON has no newline). */
static void sse_event(sse_stream *st, const char *name, const fg_job_info *info) {
  json_t *o = fg_job_info_json(info);
  char *data = o ? json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(15)) : NULL;
  json_decref(o);
  free(st->pending);
  st->pending = NULL;
  st->pending_len = st->pending_off = 0;
  if (!data) return;
  int n = asprintf(&st->pending, "event: %s\ndata: %s\n\n", name, data);
  free(data);
  if (n < 0) st->pending = NULL;
  else st->pending_len = (size_t)n;
}

static long sse_read(void *ctx, char *buf, size_t max, int closing) {
  sse_stream *st = ctx;
  if (st->pending_off == st->pending_len) {
    if (st->final_sent || closing) return -1;
    fg_job_info info;
    fg_job_get_info(st->job, &info);
    double now = fg_mono_s();
    if (fg_job_state_finished(info.state)) {
      sse_event(st, fg_job_state_name(info.state), &info);
      st->final_sent = 1;
    } else if (st->last_sent == 0 ||
               (info.version != st->sent_version && now - st->last_sent >= SSE_MIN_INTERVAL)) {
      sse_event(st, "progress", &info);
      st->sent_version = info.version;
    } else if (now - st->last_sent >= SSE_KEEPALIVE) {
      free(st->pending);
      st->pending = strdup(": keep-alive\n\n");
      st->pending_len = st->pending ? strlen(st->pending) : 0;
      st->pending_off = 0;
    } else {
      return 0;
    }
    st->last_sent = now;
    if (!st->pending) return -1; /* out of memory: end the stream */
  }
  size_t n = st->pending_len - st->pending_off;
  if (n > max) n = max;
  memcpy(buf, st->pending + st->pending_off, n);
  st->pending_off += n;
  return (long)n;
}

static int sse_ready(void *ctx, double now) {
  sse_stream *st = ctx;
  if (st->pending_off < st->pending_len || st->final_sent) return 1;
  uint64_t version;
  fg_job_state state;
  fg_job_peek(st->job, &version, &state);
  return fg_job_state_finished(state) ||
         (version != st->sent_version && now - st->last_sent >= SSE_MIN_INTERVAL) ||
         now - st->last_sent >= SSE_KEEPALIVE;
}

static void sse_free(void *ctx) {
  sse_stream *st = ctx;
  fg_job_unref(st->job);
  free(st->pending);
  free(st);
  atomic_fetch_sub(&n_streams, 1);
}

static const fg_stream_ops sse_ops = {sse_read, sse_ready, sse_free};

int fg_api_job_events(fg_req *req, fg_resp *resp) {
  fg_job *j = fg_jobs_get(req->app->jobs, req->params[0]);
  if (!j) return fg_api_fail(resp, FG_ENOENT);
  if (atomic_fetch_add(&n_streams, 1) >= FG_API_MAX_EVENT_STREAMS) {
    atomic_fetch_sub(&n_streams, 1);
    fg_job_unref(j);
    return fg_resp_error(resp, 503, "too_many_streams", "%d event streams are open, the most "
                         "this server keeps; close one, or poll GET /v1/jobs/%s instead",
                         FG_API_MAX_EVENT_STREAMS, req->params[0]);
  }
  sse_stream *st = calloc(1, sizeof *st);
  if (!st) {
    atomic_fetch_sub(&n_streams, 1);
    fg_job_unref(j);
    return fg_resp_error(resp, 500, "internal_error", "out of memory");
  }
  st->job = j;
  fg_resp_stream(resp, 200, "text/event-stream; charset=utf-8", &sse_ops, st);
  return 0;
}
