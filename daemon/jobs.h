/* Jobs: trainings of scenes' feature fields, queued FIFO and run one at a time by one worker
 * thread, so that a training uses every core it is given and never competes with another.
 *
 * A job is created queued by fg_jobs_submit, runs (loads the scene's frames, gives the frames
 * without uploaded features CLIP features when [clip] is configured (clip_features.h), trains
 * a new field from its seed, evaluates held-out PSNR, checkpoints), and ends done, failed or
 * cancelled. Its progress is a fg_job_info that HTTP handlers copy under the job's lock; every
 * change bumps `version`, so a Server-Sent Events stream knows when to send.
 *
 * Files, in the scene's folder:
 *   field.next.fgc   the field while it trains: written every 60 s of training and at the end;
 *                    a done job renames it over field.fgc, a cancelled or failed one removes it
 *   field.fgc        the trained field; only a done job replaces it, never touched otherwise
 *   last_job.json    the scene's last job (the job JSON plus created_ms, started_ms,
 *                    finished_ms), rewritten atomically at every change of state; at start-up
 *                    a job that was queued or running becomes failed, "interrupted by a daemon
 *                    restart", so GET /v1/jobs/{id} answers for it after a restart
 *
 * Threads: the worker lowers its own priority and that of its OpenMP team to nice 10
 * (Linux: a per-thread nice), so HTTP threads, imports and renders, each with their own team,
 * stay responsive while a training saturates the cores. */
#ifndef FG_DAEMON_JOBS_H
#define FG_DAEMON_JOBS_H

#include <stddef.h>
#include <stdint.h>

#include <jansson.h>

#include "conf.h"
#include "store.h"

struct fg_app;
typedef struct fg_jobs fg_jobs;
typedef struct fg_job fg_job;

/* The order of the metrics gauge's labels (metrics.h). */
typedef enum fg_job_state {
  FG_JOB_QUEUED = 0,
  FG_JOB_RUNNING,
  FG_JOB_DONE,
  FG_JOB_FAILED,
  FG_JOB_CANCELLED,
  FG_JOB_N_STATES
} fg_job_state;

/* "queued", "running", "done", "failed", "cancelled". */
const char *fg_job_state_name(fg_job_state s);
/* 1 for done, failed and cancelled. */
int fg_job_state_finished(fg_job_state s);

#define FG_TRAIN_MAX_STEPS 1000000
/* Seconds between partial checkpoints, and between sampled PSNR evaluations, of training. */
#define FG_TRAIN_CHECKPOINT_SECONDS 60.0
#define FG_TRAIN_EVAL_SECONDS 5.0

typedef struct fg_train_params {
  int64_t steps;      /* 1..FG_TRAIN_MAX_STEPS */
  uint64_t seed;
  double max_seconds; /* wall-clock limit, > 0; 0: none */
  int holdout_every;  /* 0: no frame held out; k: frames i with i % k == 0 (i counts the
                         scene's frames in number order from 0) are held out for PSNR */
} fg_train_params;

/* A consistent copy of a job. Times in Unix milliseconds, 0 when not yet. */
typedef struct fg_job_info {
  char id[FG_JOB_ID_MAX];
  char scene[FG_SCENE_NAME_MAX + 1];
  fg_job_state state;
  fg_train_params params;
  int64_t step;          /* steps taken */
  double loss;           /* last step's loss; NaN before the first step */
  double psnr;           /* held-out PSNR in dB; NaN while unknown or nothing is held out */
  int psnr_full;         /* psnr covers every held-out pixel (1) or a fixed sample (0) */
  int n_frames;          /* frames of the scene the job trains on, held-out ones included */
  int n_heldout;
  double elapsed_s;      /* wall time since it started running */
  double eta_s;          /* seconds to go; NaN when unknown */
  double samples_per_s;  /* over the last step; NaN before the first step */
  int64_t created_ms, started_ms, finished_ms;
  char phase[16];        /* "loading" (frames), "features" (CLIP), "training", "saving";
                            "" until it runs; a finished job keeps its last */
  int features_total;    /* frames that need CLIP features; 0 when there was no such phase */
  int features_done;     /* of those, the ones that have them */
  int features_cached;   /* of done, the ones read from the scene's cache */
  char error[512];       /* "" unless failed */
  uint64_t version;      /* +1 for every change */
} fg_job_info;

/* Creates the job registry, loads every scene's last_job.json (see above) and starts the
 * worker thread. The app's store must be open; app must outlive the registry. On success the
 * caller owns *out (fg_jobs_free). */
int fg_jobs_new(fg_jobs **out, struct fg_app *app);

/* Stops the worker: a running training stops after its current step, writes its partial
 * checkpoint (field.next.fgc, used at the next start only when the scene has no field.fgc)
 * and stays "running" in last_job.json, which the next start reports as interrupted; queued
 * jobs likewise. Frees everything. Accepts NULL. */
void fg_jobs_free(fg_jobs *jobs);

/* Queues a training of scene. FG_EBUSY when the scene has a queued or running job (the
 * detail names it), FG_ENOMEM. On success *out receives the new job (queued). */
int fg_jobs_submit(fg_jobs *jobs, fg_scene *scene, const fg_train_params *params,
                   fg_job_info *out);

/* The job with that id, with a reference (fg_job_unref); NULL when unknown. */
fg_job *fg_jobs_get(fg_jobs *jobs, const char *id);
void fg_job_unref(fg_job *job);
void fg_job_get_info(fg_job *job, fg_job_info *out);

/* The job's version and state without copying the rest (for event streams). */
void fg_job_peek(fg_job *job, uint64_t *version, fg_job_state *state);

/* Cancels a queued or running job: it reports "cancelled" at once; a running training stops
 * after its current step and leaves field.fgc and the scene's field as they were. FG_ENOENT
 * for an unknown id, FG_EBUSY when the job has finished or is installing its result (the
 * detail says which). *out (may be NULL) receives the job afterwards. */
int fg_jobs_cancel(fg_jobs *jobs, const char *id, fg_job_info *out);

/* Cancels the queued or running job of a scene, if any (the scene is being deleted). */
void fg_jobs_cancel_scene(fg_jobs *jobs, const char *scene);

/* Every job known, newest first, in a malloc'd array the caller frees. */
int fg_jobs_list(fg_jobs *jobs, fg_job_info **out, size_t *n);

/* Number of jobs in each state. */
void fg_jobs_count(fg_jobs *jobs, size_t counts[FG_JOB_N_STATES]);

/* The job object of the API (proto/openapi.yaml, Job). */
json_t *fg_job_info_json(const fg_job_info *info);

#endif
