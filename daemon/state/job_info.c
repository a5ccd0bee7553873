/* A job's record: its state's names and its JSON both ways; see job_info.h. */
#include "job_info.h"

#include "json.h"

#include "core/error.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const state_names[FG_JOB_N_STATES] = {"queued", "running", "done", "failed",
                                                         "cancelled"};

const char *fg_job_state_name(fg_job_state s) {
  return s >= 0 && s < FG_JOB_N_STATES ? state_names[s] : "unknown";
}

int fg_job_state_finished(fg_job_state s) {
  return s == FG_JOB_DONE || s == FG_JOB_FAILED || s == FG_JOB_CANCELLED;
}

static json_t *num_or_null(double v) { return isfinite(v) ? json_real(v) : json_null(); }

json_t *fg_job_info_json(const fg_job_info *j) {
  json_t *o = json_object();
  if (!o) return NULL;
  json_t *seed = j->params.seed <= (uint64_t)INT64_MAX
                   ? json_integer((json_int_t)j->params.seed)
                   : NULL;
  if (!seed) {
    char s[24];
    snprintf(s, sizeof s, "%llu", (unsigned long long)j->params.seed);
    seed = json_string(s);
  }
  json_object_set_new(o, "id", json_string(j->id));
  json_object_set_new(o, "scene", j->camera[0] ? json_null() : json_string(j->scene));
  if (j->camera[0]) json_object_set_new(o, "camera", json_string(j->camera));
  json_object_set_new(o, "kind", json_string(j->kind));
  json_object_set_new(o, "state", json_string(fg_job_state_name(j->state)));
  json_object_set_new(o, "step", json_integer(j->step));
  json_object_set_new(o, "steps", json_integer(j->params.steps));
  json_object_set_new(o, "loss", num_or_null(j->loss));
  json_object_set_new(o, "psnr", num_or_null(j->psnr));
  json_object_set_new(o, "psnr_full", json_boolean(isfinite(j->psnr) && j->psnr_full));
  json_object_set_new(o, "elapsed_s", json_real(j->elapsed_s));
  json_object_set_new(o, "eta_s", num_or_null(j->eta_s));
  json_t *err = j->error[0] ? json_string(j->error) : json_null();
  if (!err) err = json_string("the job failed (the message is not UTF-8; see the daemon's log)");
  json_object_set_new(o, "error", err);
  json_object_set_new(o, "samples_per_s", num_or_null(j->samples_per_s));
  json_object_set_new(o, "seed", seed);
  json_object_set_new(o, "max_seconds",
                      j->params.max_seconds > 0 ? json_real(j->params.max_seconds) : json_null());
  json_object_set_new(o, "holdout_every", json_integer(j->params.holdout_every));
  json_object_set_new(o, "depth_weight", json_real(j->params.depth_weight));
  json_object_set_new(o, "distortion_weight", json_real(j->params.distortion_weight));
  json_t *captures = NULL;
  if (j->params.all_captures) {
    captures = json_string("all");
  } else if (j->params.n_captures == 0) {
    captures = json_string("latest");
  } else {
    captures = json_array();
    for (int i = 0; captures && i < j->params.n_captures; i++)
      json_array_append_new(captures, json_integer((json_int_t)j->params.captures[i]));
  }
  json_object_set_new(o, "captures", captures);
  json_object_set_new(o, "init", json_string(j->params.init_current ? "current" : "random"));
  json_object_set_new(o, "focus", json_real(j->params.focus));
  json_object_set_new(o, "changes", j->changes_cells
                                      ? json_pack("{s:I,s:I,s:I}", "cells",
                                                  (json_int_t)j->changes_cells, "changed",
                                                  (json_int_t)j->changes_changed, "kept",
                                                  (json_int_t)j->changes_kept)
                                      : json_null());
  json_object_set_new(o, "frames", json_integer(j->n_frames));
  json_object_set_new(o, "heldout_frames", json_integer(j->n_heldout));
  if (strcmp(j->kind, "scan") == 0 || strcmp(j->kind, "calibrate") == 0)
    json_object_set_new(o, "skipped", json_integer(j->skipped));
  json_object_set_new(o, "phase", j->phase[0] ? json_string(j->phase) : json_null());
  json_object_set_new(o, "features",
                      j->features_total
                        ? json_pack("{s:i,s:i,s:i}", "total", j->features_total, "done",
                                    j->features_done, "cached", j->features_cached)
                        : json_null());
  json_object_set_new(o, "field", j->field_chosen_by[0]
                                    ? json_pack("{s:f,s:b,s:s}", "scale", j->field_scale,
                                                "learn_background", j->field_learn_background,
                                                "chosen_by", j->field_chosen_by)
                                    : json_null());
  json_object_set_new(o, "created", fg_json_time_ms(j->created_ms));
  json_object_set_new(o, "started", fg_json_time_ms(j->started_ms));
  json_object_set_new(o, "finished", fg_json_time_ms(j->finished_ms));
  return o;
}

static double jnum(json_t *o, const char *key) {
  json_t *v = json_object_get(o, key);
  return json_is_number(v) ? json_number_value(v) : NAN;
}

static int64_t jint(json_t *o, const char *key) {
  json_t *v = json_object_get(o, key);
  return json_is_integer(v) ? (int64_t)json_integer_value(v) : 0;
}

int fg_job_info_from_json(json_t *o, fg_job_info *j) {
  memset(j, 0, sizeof *j);
  const char *id = json_string_value(json_object_get(o, "id"));
  const char *scene = json_string_value(json_object_get(o, "scene"));
  const char *state = json_string_value(json_object_get(o, "state"));
  const char *kind = json_string_value(json_object_get(o, "kind"));
  if (!kind) kind = "train"; /* every job was a training before kinds came */
  if (strlen(kind) >= sizeof j->kind) return fg_fail(FG_EFORMAT, "job kind '%s' is too long", kind);
  if (!id || !scene || !state || strlen(id) >= sizeof j->id || strlen(scene) >= sizeof j->scene)
    return fg_fail(FG_EFORMAT, "not a job: id, scene or state missing");
  for (const char *p = id; *p; p++)
    if (!((*p >= '0' && *p <= '9') || (*p >= 'a' && *p <= 'z') || *p == '-'))
      return fg_fail(FG_EFORMAT, "job id '%s' has characters other than a-z 0-9 -", id);
  int s = -1;
  for (int i = 0; i < FG_JOB_N_STATES; i++)
    if (strcmp(state, fg_job_state_name((fg_job_state)i)) == 0) s = i;
  if (s < 0) return fg_fail(FG_EFORMAT, "job %s: unknown state '%s'", id, state);
  snprintf(j->id, sizeof j->id, "%s", id);
  snprintf(j->scene, sizeof j->scene, "%s", scene);
  snprintf(j->kind, sizeof j->kind, "%s", kind);
  j->state = (fg_job_state)s;
  j->step = jint(o, "step");
  j->params.steps = jint(o, "steps");
  j->loss = jnum(o, "loss");
  j->psnr = jnum(o, "psnr");
  j->psnr_full = json_is_true(json_object_get(o, "psnr_full"));
  j->elapsed_s = jnum(o, "elapsed_s");
  if (!isfinite(j->elapsed_s)) j->elapsed_s = 0;
  j->eta_s = jnum(o, "eta_s");
  j->samples_per_s = jnum(o, "samples_per_s");
  const char *err = json_string_value(json_object_get(o, "error"));
  if (err) snprintf(j->error, sizeof j->error, "%s", err);
  json_t *seed = json_object_get(o, "seed");
  if (json_is_integer(seed)) j->params.seed = (uint64_t)json_integer_value(seed);
  else if (json_is_string(seed)) j->params.seed = strtoull(json_string_value(seed), NULL, 10);
  double ms = jnum(o, "max_seconds");
  j->params.max_seconds = isfinite(ms) ? ms : 0;
  j->params.holdout_every = (int)jint(o, "holdout_every");
  const double dw = jnum(o, "depth_weight"), dd = jnum(o, "distortion_weight");
  j->params.depth_weight = isfinite(dw) ? dw : 0.0; /* jobs recorded before these existed */
  j->params.distortion_weight = isfinite(dd) ? dd : 0.0;
  json_t *captures = json_object_get(o, "captures"); /* absent before captures: "latest" */
  j->params.all_captures =
    json_is_string(captures) && strcmp(json_string_value(captures), "all") == 0;
  for (size_t i = 0; json_is_array(captures) && i < json_array_size(captures) &&
                     j->params.n_captures < FG_JOB_MAX_CAPTURES; i++) {
    json_t *c = json_array_get(captures, i);
    if (json_is_integer(c)) j->params.captures[j->params.n_captures++] = json_integer_value(c);
  }
  const char *init = json_string_value(json_object_get(o, "init"));
  j->params.init_current = init && strcmp(init, "current") == 0;
  const double focus = jnum(o, "focus"); /* absent before focus: none */
  j->params.focus = isfinite(focus) ? focus : 0.0;
  json_t *changes = json_object_get(o, "changes");
  j->changes_cells = jint(changes, "cells");
  j->changes_changed = jint(changes, "changed");
  j->changes_kept = jint(changes, "kept");
  j->n_frames = (int)jint(o, "frames");
  j->n_heldout = (int)jint(o, "heldout_frames");
  const char *phase = json_string_value(json_object_get(o, "phase"));
  if (phase) snprintf(j->phase, sizeof j->phase, "%s", phase);
  json_t *feats = json_object_get(o, "features");
  j->features_total = (int)jint(feats, "total");
  j->features_done = (int)jint(feats, "done");
  j->features_cached = (int)jint(feats, "cached");
  json_t *field = json_object_get(o, "field");
  const char *by = json_string_value(json_object_get(field, "chosen_by"));
  if (by && isfinite(jnum(field, "scale"))) {
    j->field_scale = jnum(field, "scale");
    j->field_learn_background = json_is_true(json_object_get(field, "learn_background"));
    snprintf(j->field_chosen_by, sizeof j->field_chosen_by, "%s", by);
  }
  j->created_ms = jint(o, "created_ms");
  j->started_ms = jint(o, "started_ms");
  j->finished_ms = jint(o, "finished_ms");
  return 0;
}
