/* Training jobs: the "train" kind of the job registry (jobs.h).
 *
 * A training loads the frames of the captures it names (store.h; by default the newest),
 * gives the frames without uploaded features CLIP features when [clip] is configured
 * (clip_features.h), trains a field for `steps` steps or `max_seconds` of wall time,
 * evaluates held-out PSNR and installs the field in the scene. The field is new, from the
 * job's seed ("init": "random"), or a copy of the scene's field ("init": "current": an
 * update) whose occupancy grid starts fully occupied again, so that it is rebuilt from the
 * new frames, and whose step count, learning-rate schedule and optimiser start from zero.
 * Either way the result replaces the scene's field as a whole, and everything built from the
 * old one (voxel cache, grasp field, grasp ids, heatmaps) goes with it.
 *
 * Files, in the scene's folder:
 *   field.next.fgc   the field while it trains: written every FG_TRAIN_CHECKPOINT_SECONDS of
 *                    training and at the end; a done job renames it over field.fgc, a
 *                    cancelled or failed one removes it, a daemon that stops keeps it
 *   field.fgc        the trained field; only a done job replaces it, never touched otherwise
 *
 * Threads: [train] threads (fg_conf_threads), at the lowered priority of every job
 * (fg_job_lower_priority). */
#ifndef FG_DAEMON_JOB_TRAIN_H
#define FG_DAEMON_JOB_TRAIN_H

#include "jobs.h"

/* Seconds between partial checkpoints, and between sampled PSNR evaluations, of training. */
#define FG_TRAIN_CHECKPOINT_SECONDS 60.0
#define FG_TRAIN_EVAL_SECONDS 5.0

/* The kind's name, "train": GET /v1/jobs shows it as the job's "kind". */
#define FG_JOB_KIND_TRAIN "train"

/* The "train" kind: register it once with fg_jobs_register_kind, then submit trainings with
 * fg_jobs_submit(jobs, FG_JOB_KIND_TRAIN, scene, &params, NULL, &info) after fg_train_check.
 * It takes no parameters of its own (kind_params NULL): everything it needs is in
 * fg_job_params. */
extern const fg_job_kind fg_job_kind_train;

/* Checks a training of scene s with params p before it is queued, so that the request gets
 * the answer rather than the job: the captures it names exist (capture_not_found), they hold
 * frames (no_frames), holdout_every leaves some to train on (invalid_request), and
 * fg_train_check_init. 0 or the failure. The job checks again as it runs. */
struct fg_app;
int fg_train_check(struct fg_app *app, fg_scene *s, const fg_job_params *p);

/* An update's own check ("init": "current"; 0 for a training from random weights): the scene
 * has a field to go on from (not_trained), of the box, networks and feature dimension that
 * this training would make (field_mismatch, feature_dim_mismatch: the reason says what
 * differs). The feature dimension is the frames' uploaded one, else CLIP's when [clip] is
 * configured, else none. A scan that trains checks this alone: its frames are yet to come. */
int fg_train_check_init(struct fg_app *app, fg_scene *s, const fg_job_params *p);

#endif
