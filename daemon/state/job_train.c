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
#include "field/model.h"
#include "field/train.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The field's cube: twice the workspace's largest extent (model.h). */
#define FIELD_SCALE 2.0

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

/* ---------------------------------------------------------------- the phases */

/* The scene's frames, every one of them. */
static int load_frames(train_run *run) {
  fg_job_set_phase(run->job, "loading");
  int rc = fg_scene_load_frames(run->scene, &run->frames, &run->frame_numbers, &run->n_frames,
                                stop_requested, run);
  if (rc == FG_ECANCELED) return rc;
  if (rc != 0) {
    fg_job_fail(run->job, "cannot load the scene's frames: %s", fg_error_detail());
    return rc;
  }
  if (run->n_frames == 0) {
    fg_job_fail(run->job, "the scene has no frames; add some with POST /v1/scenes/%s/frames "
                "or .../import", fg_scene_name(run->scene));
    return FG_EINVAL;
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

/* A new field over the scene's workspace and its trainer over the frames. */
static int setup_trainer(train_run *run) {
  fg_job_set_phase(run->job, "training");
  int feature_dim = 0; /* the store keeps one D per scene; CLIP's E equals it (checked) */
  for (size_t i = 0; i < run->n_frames && !feature_dim; i++) feature_dim = run->frames[i].feat_d;
  fg_scene_info scene_info;
  fg_scene_get_info(run->scene, &scene_info);
  fg_field_config cfg;
  if (fg_field_config_for_workspace(&cfg, scene_info.params.workspace_min,
                                    scene_info.params.workspace_max, FIELD_SCALE,
                                    feature_dim) != 0 ||
      fg_field_new(&run->field, &cfg, run->params.seed) != 0) {
    fg_job_fail(run->job, "cannot set up the field: %s", fg_error_detail());
    return FG_EINVAL;
  }
  fg_train_opts opts;
  fg_train_opts_default(&opts);
  opts.n_threads = run->n_threads;
  opts.seed = run->params.seed;
  opts.holdout_every = run->params.holdout_every;
  opts.depth_weight = (float)run->params.depth_weight;
  opts.distortion_weight = (float)run->params.distortion_weight;
  for (int k = 0; k < 3; k++) opts.background[k] = (float)scene_info.params.background[k];
  int rc = fg_trainer_new(&run->trainer, run->field, run->frames, run->n_frames, &opts);
  if (rc != 0) {
    fg_job_fail(run->job, "cannot start training: %s", fg_error_detail());
    return rc;
  }
  run->n_heldout = fg_trainer_n_heldout(run->trainer);
  fg_job_info *info = fg_job_update_begin(run->job);
  info->n_frames = (int)run->n_frames;
  info->n_heldout = (int)run->n_heldout;
  fg_job_update_end(run->job);
  fg_info("job %s: training scene %s on %zu frames (%zu held out), %d threads", run->id,
          fg_scene_name(run->scene), run->n_frames, run->n_heldout, run->n_threads);
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
