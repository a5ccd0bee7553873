/* Training jobs: the "train" kind; see job_train.h.
 *
 * One training is a train_run that goes through the phases in order: load the frames, attach
 * CLIP features, set up the trainer, the step loop, the final PSNR, save and commit. Each
 * phase function returns 0 to go on, FG_ECANCELED when the job should stop (cancelled, or the
 * daemon is stopping), or another negative code once it has failed the job itself. */
#include "job_train.h"

#include "app.h"
#include "clip_features.h"
#include "clip_svc.h"
#include "metrics/metrics.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "field/checkpoint.h"
#include "field/extent.h"
#include "field/model.h"
#include "field/train.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* One training, from its start to its end. Owns everything it points to but job and app. */
typedef struct train_run {
  fg_job *job;
  fg_app *app;
  fg_scene *scene;        /* the job's; referenced by the job while it runs */
  const char *id;         /* the job's id */
  fg_job_params params;   /* as submitted */
  int n_threads;          /* [train] threads when the job started */
  int half_precision;     /* checkpoints in half precision ([train] half_precision) */
  fg_clip_model *clip;    /* the CLIP model the job started with; NULL once features are in */
  char *next_path;        /* <scene>/field.next.fgc */
  fg_frame *frames;       /* (n_frames), loaded from the scene */
  int *frame_numbers;     /* (n_frames), each frame's number in the scene */
  size_t n_frames;
  fg_field *field;        /* the field it trains; NULL once the scene has it */
  fg_field_ref *before;   /* an update's field as it was, until its focus is set up */
  fg_trainer *trainer;
  size_t n_heldout;       /* frames held out for PSNR */
  int64_t steps_done;
  double loop_start_s;    /* fg_mono_s() when the step loop began */
} train_run;

/* fg_scene_load_frames and fg_clip_features_attach callback: ud is the train_run. */
static int stop_requested(void *ud) {
  train_run *run = ud;
  return fg_job_should_stop(run->job);
}

/* Progress of the CLIP features phase (clip_features.h). */
static void on_features_progress(void *ud, const fg_clip_features_progress *progress) {
  train_run *run = ud;
  fg_job_info *info = fg_job_update_begin(run->job);
  info->features_done = (int)progress->done;
  info->features_cached = (int)progress->cached;
  info->elapsed_s = fg_mono_s() - fg_job_started_s(run->job);
  fg_job_update_end(run->job);
}

/* Total pixels of the frames the trainer holds out (frames i with i % every == 0). */
static double heldout_pixels(const fg_frame *frames, size_t n_frames, int every) {
  double pixels = 0;
  for (size_t i = 0; every > 0 && i < n_frames; i += (size_t)every)
    pixels += (double)frames[i].cam.w * (double)frames[i].cam.h;
  return pixels;
}

/* ---------------------------------------------------------------- the checks */

/* The captures a training uses, as fg_scene_load_frames takes them. Used in place: captures
 * may point at latest. */
typedef struct capture_choice {
  const int64_t *captures; /* NULL: every capture */
  size_t n;
  int64_t latest;   /* "latest": the newest capture that holds frames */
  size_t n_frames;  /* frames in the captures chosen */
} capture_choice;

static int choose_captures(fg_scene *s, const fg_job_params *p, capture_choice *c) {
  memset(c, 0, sizeof *c);
  fg_scene_capture_info *v;
  size_t n;
  FG_TRY(fg_scene_list_captures(s, &v, &n));
  int rc = 0;
  if (p->all_captures) {
    for (size_t i = 0; i < n; i++) c->n_frames += v[i].n_frames;
  } else if (p->n_captures == 0) {
    c->captures = &c->latest;
    if (n) {
      c->latest = v[n - 1].capture;
      c->n = 1;
      c->n_frames = v[n - 1].n_frames;
    }
  } else {
    c->captures = p->captures;
    c->n = (size_t)p->n_captures;
    for (int k = 0; k < p->n_captures && rc == 0; k++) {
      size_t i = 0;
      while (i < n && v[i].capture != p->captures[k]) i++;
      if (i < n)
        c->n_frames += v[i].n_frames;
      else
        rc = fg_fail_as(FG_ENOENT, "capture_not_found", "scene '%s' has no capture %lld; GET "
                        "/v1/scenes/%s/captures lists them", fg_scene_name(s),
                        (long long)p->captures[k], fg_scene_name(s));
    }
  }
  free(v);
  return rc;
}

static int no_frames(fg_scene *s) {
  const char *name = fg_scene_name(s);
  return fg_fail_as(FG_EINVAL, "no_frames", "scene '%s' has no frames to train on; add them "
                    "with POST /v1/scenes/%s/frames or POST /v1/scenes/%s/import first", name,
                    name, name);
}

/* The feature dimension a training of s would give its field: the frames' uploaded one,
 * else CLIP's when [clip] is configured, else 0. */
static int expected_feature_dim(fg_app *app, const fg_scene_info *info) {
  if (info->feature_dim > 0) return info->feature_dim;
  fg_clip_model *m = app->clip ? fg_clip_svc_acquire(app->clip) : NULL;
  const int E = m ? fg_clip_model_info(m)->embed_dim : 0;
  fg_clip_model_release(m);
  return E;
}

/* FG_EINVAL (field_mismatch or feature_dim_mismatch) when the configuration of `have`, the
 * scene's field, is not `want`. */
static int same_config(fg_scene *s, const fg_field_config *have, const fg_field_config *want) {
  char why[256];
  if (fg_field_config_same(have, want, why, sizeof why)) return 0;
  return fg_fail_as(FG_EINVAL, have->feature_dim != want->feature_dim ? "feature_dim_mismatch"
                                                                      : "field_mismatch",
                    "scene '%s': its field cannot go on training on these frames (\"init\": "
                    "\"current\"): %s; train it anew with \"init\": \"random\"",
                    fg_scene_name(s), why);
}

static double largest_extent(const fg_scene_params *p) {
  double extent = 0;
  for (int k = 0; k < 3; k++) extent = fmax(extent, p->workspace_max[k] - p->workspace_min[k]);
  return extent;
}

/* The configuration of the field a training makes over the scene's workspace, and what chose
 * its cube and background: the scene's settings where they are not "auto"; where they are,
 * the field an update goes on from (current, NULL for a new field) keeps its own, and a new
 * field takes what the frames call for (field/extent.h). */
static int field_config(const fg_scene_info *info, const fg_field *current,
                        const fg_frame *frames, size_t n_frames, int feature_dim,
                        fg_field_config *cfg, const char **chosen_by) {
  const fg_scene_params *p = &info->params;
  double scale = p->field_scale;
  int learn_bg = p->learn_background;
  *chosen_by = "settings";
  if (scale == FG_FIELD_SCALE_AUTO || learn_bg == FG_LEARN_BACKGROUND_AUTO) {
    fg_field_extent e;
    if (current) {
      e.field_scale = current->cfg.box_size / largest_extent(p);
      e.learn_background = current->cfg.learn_background;
      *chosen_by = "current field";
    } else {
      fg_field_extent_choose(p->workspace_min, p->workspace_max, frames, n_frames, &e);
      *chosen_by = e.from_depth ? "depth" : "cameras";
    }
    if (scale == FG_FIELD_SCALE_AUTO) scale = e.field_scale;
    if (learn_bg == FG_LEARN_BACKGROUND_AUTO) learn_bg = e.learn_background;
  }
  if (fg_field_config_for_workspace(cfg, p->workspace_min, p->workspace_max,
                                    fmin(fmax(scale, 1.0), 64.0), feature_dim) != 0)
    return fg_fail_as(FG_EINVAL, "invalid_request", "cannot set up the field: %s",
                      fg_error_detail());
  cfg->learn_background = learn_bg;
  return 0;
}

int fg_train_check_init(fg_app *app, fg_scene *s, const fg_job_params *p) {
  if (!p->init_current) return 0;
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  fg_field_ref *ref = NULL;
  FG_TRY(fg_scene_field_acquire(s, &ref));
  if (!ref)
    return fg_fail_as(FG_EINVAL, "not_trained", "scene '%s' has no field to go on from "
                      "(\"init\": \"current\"); train it with \"init\": \"random\" first",
                      info.name);
  const fg_field *have = fg_field_ref_field(ref);
  fg_field_config want;
  const char *chosen_by;
  int rc = field_config(&info, have, NULL, 0, expected_feature_dim(app, &info), &want,
                        &chosen_by);
  if (rc == 0) rc = same_config(s, &have->cfg, &want);
  fg_field_ref_release(ref);
  return rc;
}

int fg_train_check(fg_app *app, fg_scene *s, const fg_job_params *p) {
  capture_choice c;
  FG_TRY(choose_captures(s, p, &c));
  if (c.n_frames == 0) return no_frames(s);
  if (p->holdout_every > 0) {
    const size_t k = (size_t)p->holdout_every, held = (c.n_frames + k - 1) / k;
    if (held >= c.n_frames)
      return fg_fail_as(FG_EINVAL, "invalid_request", "holdout_every %d holds out all %zu "
                        "frames the training would use in scene '%s'; use a larger value (or "
                        "0) so that some frames train", p->holdout_every, c.n_frames,
                        fg_scene_name(s));
  }
  return fg_train_check_init(app, s, p);
}

/* ---------------------------------------------------------------- the phases */

/* The frames of the captures the job names. */
static int load_frames(train_run *run) {
  fg_job_set_phase(run->job, "loading");
  capture_choice c;
  int rc = choose_captures(run->scene, &run->params, &c);
  if (rc == 0 && c.n_frames == 0) rc = no_frames(run->scene);
  if (rc == 0)
    rc = fg_scene_load_frames(run->scene, c.captures, c.n, &run->frames, &run->frame_numbers,
                              &run->n_frames, stop_requested, run);
  if (rc == FG_ECANCELED) return rc;
  if (rc == 0 && run->n_frames == 0) rc = no_frames(run->scene); /* deleted meanwhile */
  if (rc != 0) {
    fg_job_fail(run->job, "cannot load the scene's frames: %s", fg_error_detail());
    return rc;
  }
  return 0;
}

/* CLIP features for the frames that came without uploaded ones, when [clip] is configured;
 * drops the job's reference to the model afterwards. */
static int attach_clip_features(train_run *run) {
  size_t needed = run->clip ? fg_clip_features_needed(run->frames, run->n_frames) : 0;
  if (needed) {
    fg_job_info *info = fg_job_update_begin(run->job);
    snprintf(info->phase, sizeof info->phase, "features");
    info->features_total = (int)needed;
    info->features_done = info->features_cached = 0;
    fg_job_update_end(run->job);
    double start_s = fg_mono_s();
    int rc = fg_clip_features_attach(run->clip, fg_scene_dir(run->scene), run->frames,
                                     run->frame_numbers, run->n_frames, stop_requested,
                                     on_features_progress, run);
    if (rc == FG_ECANCELED) return rc;
    if (rc != 0) {
      fg_job_fail(run->job, "cannot give the frames CLIP features: %s", fg_error_detail());
      return rc;
    }
    fg_job_info now;
    fg_job_get_info(run->job, &now);
    fg_info("job %s: CLIP features of %zu frames (model %s): %zu computed, %d from the cache, "
            "in %.1f s", run->id, needed, fg_clip_model_info(run->clip)->fingerprint,
            needed - (size_t)now.features_cached, now.features_cached, fg_mono_s() - start_s);
  }
  fg_clip_model_release(run->clip);
  run->clip = NULL;
  return 0;
}

/* The field over the scene's workspace in run->field: the scene's, copied to go on training
 * (init "current": fg_field_copy_for_update), or a new one. */
static int make_field(train_run *run, const fg_scene_info *info, int feature_dim) {
  fg_field_ref *ref = NULL;
  int rc = run->params.init_current ? fg_scene_field_acquire(run->scene, &ref) : 0;
  if (rc == 0 && run->params.init_current && !ref)
    rc = fg_fail(FG_EINVAL, "the scene has no field to go on from (\"init\": \"current\")");
  const fg_field *current = ref ? fg_field_ref_field(ref) : NULL;
  fg_field_config cfg;
  const char *chosen_by = "";
  if (rc == 0)
    rc = field_config(info, current, run->frames, run->n_frames, feature_dim, &cfg, &chosen_by);
  if (rc == 0 && current) rc = same_config(run->scene, &current->cfg, &cfg);
  if (rc == 0)
    rc = current ? fg_field_copy_for_update(current, &run->field)
                 : fg_field_new(&run->field, &cfg, run->params.seed);
  if (rc == 0 && current && run->params.focus > 0.0) {
    run->before = ref; /* setup_trainer compares the new views with it */
    ref = NULL;
  }
  fg_field_ref_release(ref);
  if (rc != 0) return rc;
  fg_job_info *ji = fg_job_update_begin(run->job);
  ji->field_scale = cfg.box_size / largest_extent(&info->params);
  ji->field_learn_background = cfg.learn_background;
  snprintf(ji->field_chosen_by, sizeof ji->field_chosen_by, "%s", chosen_by);
  fg_job_update_end(run->job);
  fg_info("job %s: the field's cube is %g m (%g times the workspace), %s background, chosen "
          "by the %s", run->id, cfg.box_size, cfg.box_size / largest_extent(&info->params),
          cfg.learn_background ? "a learned" : "the scene's", chosen_by);
  return 0;
}

/* The field, new or the scene's (init), and its trainer over the frames. */
static int setup_trainer(train_run *run) {
  fg_job_set_phase(run->job, "training");
  int feature_dim = 0; /* the store keeps one D per scene; CLIP's E equals it (checked) */
  for (size_t i = 0; i < run->n_frames && !feature_dim; i++) feature_dim = run->frames[i].feat_d;
  fg_scene_info scene_info;
  fg_scene_get_info(run->scene, &scene_info);
  int rc = make_field(run, &scene_info, feature_dim);
  if (rc != 0) {
    fg_job_fail(run->job, "cannot set up the field: %s", fg_error_detail());
    return rc;
  }
  fg_train_opts opts;
  fg_train_opts_default(&opts);
  opts.n_threads = run->n_threads;
  opts.seed = run->params.seed;
  opts.holdout_every = run->params.holdout_every;
  opts.depth_weight = (float)run->params.depth_weight;
  opts.distortion_weight = (float)run->params.distortion_weight;
  for (int k = 0; k < 3; k++) opts.background[k] = (float)scene_info.params.background[k];
  rc = fg_trainer_new(&run->trainer, run->field, run->frames, run->n_frames, &opts);
  if (rc != 0) {
    fg_job_fail(run->job, "cannot start training: %s", fg_error_detail());
    return rc;
  }
  run->n_heldout = fg_trainer_n_heldout(run->trainer);
  if (run->before) {
    const double t0 = fg_mono_s();
    fg_train_focus_stats st;
    rc = fg_trainer_focus(run->trainer, fg_field_ref_field(run->before), (float)run->params.focus,
                          &st);
    fg_field_ref_release(run->before);
    run->before = NULL;
    if (rc != 0) {
      fg_job_fail(run->job, "cannot compare the views with the scene's field: %s",
                  fg_error_detail());
      return rc;
    }
    fg_job_info *ji = fg_job_update_begin(run->job);
    ji->changes_cells = st.cells;
    ji->changes_changed = st.changed;
    ji->changes_kept = st.kept;
    fg_job_update_end(run->job);
    fg_info("job %s: the views changed in %lld of %lld cells; %g of the rays drawn from %lld "
            "cells around them (%.2f s)", run->id, (long long)st.changed, (long long)st.cells,
            run->params.focus, (long long)st.kept, fg_mono_s() - t0);
  }
  fg_job_info *info = fg_job_update_begin(run->job);
  info->n_frames = (int)run->n_frames;
  info->n_heldout = (int)run->n_heldout;
  fg_job_update_end(run->job);
  fg_info("job %s: training scene %s on %zu frames (%zu held out), %d threads, from %s",
          run->id, fg_scene_name(run->scene), run->n_frames, run->n_heldout, run->n_threads,
          run->params.init_current ? "the scene's field" : "random weights");
  return 0;
}

/* Publishes one step's progress: loss, throughput, elapsed time, the ETA (by the mean step
 * time so far, capped by max_seconds) and a sampled PSNR when one was measured. */
static void report_step(train_run *run, const fg_train_stats *stats, double step_start_s,
                        double step_end_s, double psnr) {
  fg_metrics_add_training_steps(1);
  double samples_per_s = step_end_s > step_start_s
                           ? (double)stats->samples / (step_end_s - step_start_s)
                           : NAN;
  if (isfinite(samples_per_s)) fg_metrics_set_training_samples_per_s(samples_per_s);
  const fg_job_params *p = &run->params;
  double elapsed_s = step_end_s - fg_job_started_s(run->job);
  double seconds_per_step = (step_end_s - run->loop_start_s) / (double)run->steps_done;
  double eta_s = seconds_per_step * (double)(p->steps - run->steps_done);
  if (p->max_seconds > 0 && p->max_seconds - elapsed_s < eta_s)
    eta_s = fmax(0, p->max_seconds - elapsed_s);
  fg_job_info *info = fg_job_update_begin(run->job);
  info->step = run->steps_done;
  info->loss = stats->loss;
  info->samples_per_s = samples_per_s;
  info->elapsed_s = elapsed_s;
  info->eta_s = eta_s;
  if (isfinite(psnr)) {
    info->psnr = psnr;
    info->psnr_full = 0;
  }
  fg_job_update_end(run->job);
}

/* Writes field.next.fgc; a failure is logged and training goes on. */
static void save_partial_checkpoint(train_run *run) {
  if (fg_checkpoint_save(run->field, run->next_path, run->half_precision) == 0)
    fg_debug("job %s: partial checkpoint at step %lld", run->id, (long long)run->steps_done);
  else
    fg_warn("job %s: cannot write the partial checkpoint %s: %s", run->id, run->next_path,
            fg_error_detail());
}

/* Steps until `steps` are done or `max_seconds` have passed since the job started, with a
 * sampled PSNR every FG_TRAIN_EVAL_SECONDS and a partial checkpoint every
 * FG_TRAIN_CHECKPOINT_SECONDS. */
static int train_steps(train_run *run) {
  const fg_job_params *p = &run->params;
  run->loop_start_s = fg_mono_s();
  double last_eval_s = run->loop_start_s, last_checkpoint_s = run->loop_start_s;
  while (run->steps_done < p->steps) {
    if (fg_job_should_stop(run->job)) return FG_ECANCELED;
    double step_start_s = fg_mono_s();
    if (p->max_seconds > 0 && step_start_s - fg_job_started_s(run->job) >= p->max_seconds)
      break;
    fg_train_stats stats;
    int rc = fg_trainer_step(run->trainer, &stats);
    double step_end_s = fg_mono_s();
    if (rc != 0) {
      fg_job_fail(run->job, "training stopped at step %lld: %s%s", (long long)run->steps_done,
                  fg_error_detail(), rc == FG_ERANGE ? "; try another seed" : "");
      return rc;
    }
    run->steps_done++;
    double psnr = NAN;
    if (run->n_heldout > 0 && step_end_s - last_eval_s >= FG_TRAIN_EVAL_SECONDS) {
      if (fg_trainer_eval(run->trainer, 0, &psnr) != 0) psnr = NAN;
      last_eval_s = fg_mono_s();
    }
    report_step(run, &stats, step_start_s, step_end_s, psnr);
    if (fg_mono_s() - last_checkpoint_s >= FG_TRAIN_CHECKPOINT_SECONDS) {
      save_partial_checkpoint(run);
      last_checkpoint_s = fg_mono_s();
    }
  }
  return 0;
}

/* The held-out PSNR at the end: over every held-out pixel when that costs less than a tenth
 * of the training time so far, else over the trainer's fixed sample. */
static void measure_final_psnr(train_run *run) {
  if (run->n_heldout == 0) return;
  double psnr = NAN, start_s = fg_mono_s();
  if (fg_trainer_eval(run->trainer, 0, &psnr) != 0) psnr = NAN;
  double sampled_s = fg_mono_s() - start_s;
  double pixels = heldout_pixels(run->frames, run->n_frames, run->params.holdout_every);
  double full_estimate_s = pixels > 0 ? sampled_s * pixels / fmin(pixels, 16384.0) : INFINITY;
  int full = 0;
  if (full_estimate_s < 0.1 * (fg_mono_s() - run->loop_start_s) &&
      !fg_job_should_stop(run->job)) {
    double psnr_full = NAN;
    if (fg_trainer_eval(run->trainer, 1, &psnr_full) == 0 && isfinite(psnr_full)) {
      psnr = psnr_full;
      full = 1;
    }
  }
  fg_job_info *info = fg_job_update_begin(run->job);
  if (isfinite(psnr)) {
    info->psnr = psnr;
    info->psnr_full = full;
  }
  fg_job_update_end(run->job);
}

/* Saves the field and installs it in the scene; the job ends done (or cancelled, when the
 * scene was deleted meanwhile). */
static int save_and_commit(train_run *run) {
  if (fg_job_should_stop(run->job)) return FG_ECANCELED;
  fg_job_set_phase(run->job, "saving");
  int rc = fg_checkpoint_save(run->field, run->next_path, run->half_precision);
  if (rc != 0) {
    fg_job_fail(run->job, "cannot save the trained field: %s", fg_error_detail());
    return rc;
  }
  /* From here on a DELETE is too late: the job installs its result. */
  if (fg_job_commit_begin(run->job) != 0) return FG_ECANCELED;
  rc = fg_scene_commit_field(run->scene, run->field, run->next_path);
  if (rc == FG_ENOENT) { /* the scene was deleted meanwhile */
    fg_job_finish(run->job, FG_JOB_CANCELLED);
    return 0;
  }
  if (rc != 0) {
    fg_job_fail(run->job, "cannot install the trained field: %s", fg_error_detail());
    return rc;
  }
  run->field = NULL; /* the scene's now */
  fg_job_info *info = fg_job_update_begin(run->job);
  info->step = run->steps_done;
  fg_job_update_end(run->job);
  fg_job_finish(run->job, FG_JOB_DONE);
  fg_job_info done;
  fg_job_get_info(run->job, &done);
  fg_info("job %s: done: scene %s trained for %lld steps in %.1f s", run->id, done.scene,
          (long long)run->steps_done, done.elapsed_s);
  return 0;
}

/* The job stopped before its end. Cancelled: the scene keeps its field. The daemon stopping:
 * what was learnt becomes the partial checkpoint, and the job stays "running" on disk for the
 * next start to report as interrupted. Returns 1 when field.next.fgc must be kept. */
static int handle_stop(train_run *run) {
  if (fg_job_cancelled(run->job)) {
    fg_info("job %s: stopped (cancelled); the scene's field is as it was", run->id);
    return 0;
  }
  if (run->field && run->trainer && run->field->trained_steps > 0) {
    if (fg_checkpoint_save(run->field, run->next_path, run->half_precision) == 0)
      fg_info("job %s: interrupted by the shutdown after %lld steps; its field is kept as "
              "field.next.fgc", run->id, (long long)run->field->trained_steps);
    else
      fg_warn("job %s: cannot save field.next.fgc at shutdown: %s", run->id, fg_error_detail());
  }
  return 1;
}

static void train_run_free(train_run *run) {
  fg_field_ref_release(run->before);
  fg_trainer_free(run->trainer);
  fg_field_free(run->field);
  fg_scene_frames_free(run->frames, run->n_frames);
  free(run->frame_numbers);
  fg_clip_model_release(run->clip);
  free(run->next_path);
}

/* ---------------------------------------------------------------- the kind */

/* fg_job_kind.run of "train": leaves the job done, failed, cancelled or (daemon stopping)
 * running. */
static void train_job_run(fg_job *job, fg_app *app, void *kind_params) {
  (void)kind_params;
  fg_job_info start;
  fg_job_get_info(job, &start);
  train_run run = {.job = job, .app = app, .scene = fg_job_scene(job), .id = fg_job_id(job),
                   .params = start.params};
  const fg_conf *conf = fg_app_conf_acquire(app);
  run.n_threads = fg_conf_threads(conf);
  run.half_precision = conf->half_precision;
  fg_app_conf_release(app, conf);
  /* The CLIP model this job starts with serves it to the end, whatever a reload brings. Its
   * team may be larger than training's: lower every thread either may use. */
  run.clip = app->clip ? fg_clip_svc_acquire(app->clip) : NULL;
  int clip_threads = run.clip ? fg_clip_model_threads(run.clip) : 0;
  fg_job_lower_priority(clip_threads > run.n_threads ? clip_threads : run.n_threads);
  /* This training writes and removes field.next.fgc: if the scene's field came from that file
   * (an interrupted training), make it field.fgc first so that nothing can lose it. */
  fg_scene_keep_partial(run.scene);

  int keep_partial = 0;
  run.next_path = fg_path_join(fg_scene_dir(run.scene), "field.next.fgc");
  int rc = run.next_path ? 0 : (fg_job_fail(job, "out of memory"), FG_ENOMEM);
  if (rc == 0) rc = load_frames(&run);
  if (rc == 0) rc = attach_clip_features(&run);
  if (rc == 0) rc = setup_trainer(&run);
  if (rc == 0) rc = train_steps(&run);
  if (rc == 0) measure_final_psnr(&run);
  if (rc == 0) rc = save_and_commit(&run);
  if (rc == FG_ECANCELED) keep_partial = handle_stop(&run);

  if (run.next_path && !keep_partial) {
    fg_job_info end;
    fg_job_get_info(job, &end);
    if (end.state != FG_JOB_DONE && unlink(run.next_path) == 0)
      fg_debug("job %s: removed %s", run.id, run.next_path);
  }
  train_run_free(&run);
}

const fg_job_kind fg_job_kind_train = {
  .name = FG_JOB_KIND_TRAIN,
  .run = train_job_run,
  .params_free = NULL,
};
