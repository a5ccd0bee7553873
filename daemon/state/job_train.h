/* Training jobs: the "train" kind of the job registry (jobs.h).
 *
 * A training loads the scene's frames, gives the frames without uploaded features CLIP
 * features when [clip] is configured (clip_features.h), trains a new field from the job's
 * seed for `steps` steps or `max_seconds` of wall time, evaluates held-out PSNR and installs
 * the field in the scene.
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
 * fg_jobs_submit(jobs, FG_JOB_KIND_TRAIN, scene, &params, NULL, &info). It takes no
 * parameters of its own (kind_params NULL): everything it needs is in fg_job_params. */
extern const fg_job_kind fg_job_kind_train;

#endif
