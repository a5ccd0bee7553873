/* Jobs: long work on a scene (trainings, scans) or on a camera (a calibration the robot
 * drives), queued FIFO and run one at a time by one worker thread, so that a job uses every
 * core it is given and never competes with another, and two jobs never move the robot at once.
 *
 * What a job does is its kind's: a table of kinds (fg_job_kind: a name and a run function)
 * that the daemon fills at start-up with fg_jobs_register_kind ("train", job_train.h, first).
 * fg_jobs_submit queues a job of a registered kind; the worker marks it running and calls the
 * kind's run function, which reports progress through the functions of "For run functions"
 * below and ends the job done, failed or cancelled. A job's progress is a fg_job_info that
 * HTTP handlers copy under the job's lock; every change bumps `version`, so a Server-Sent
 * Events stream knows when to send.
 *
 * Files, in the scene's folder:
 *   last_job.json    the scene's last job (the job JSON plus created_ms, started_ms,
 *                    finished_ms), rewritten atomically at every change of state; at start-up
 *                    a job that was queued or running becomes failed, "interrupted by a daemon
 *                    restart", so GET /v1/jobs/{id} answers for it after a restart
 *   (a kind's own files: job_train.h)
 *
 * Threads: a run function lowers its own priority and that of its OpenMP team to nice 10
 * (fg_job_lower_priority; Linux: a per-thread nice), so HTTP threads, imports and renders,
 * each with their own team, stay responsive while a job saturates the cores. */
#ifndef FG_DAEMON_JOBS_H
#define FG_DAEMON_JOBS_H

#include <stddef.h>
#include <stdint.h>

#include "conf/conf.h"
#include "job_info.h"
#include "store.h"

struct fg_app;
typedef struct fg_jobs fg_jobs;
typedef struct fg_job fg_job;

/* At most FG_JOBS_MAX_KINDS kinds (names: job_info.h, FG_JOB_KIND_MAX). */
#define FG_JOBS_MAX_KINDS 8

/* A kind of job. The struct must outlive the registry (a static const, as
 * fg_job_kind_train). */
typedef struct fg_job_kind {
  const char *name; /* the job's "kind" in the API, e.g. "train" (see FG_JOB_KIND_MAX) */
  /* Runs one job on the worker thread once it is "running"; app is the registry's, params
   * the kind_params given to fg_jobs_submit (the job keeps owning them). It must return with
   * the job finished (fg_job_finish, fg_job_fail; a job cancelled meanwhile already is) or,
   * when fg_job_should_stop says the daemon is stopping (fg_job_cancelled is 0), still
   * "running": the next start reports it interrupted. */
  void (*run)(fg_job *job, struct fg_app *app, void *params);
  /* Frees the kind_params of a job when the job goes; NULL when they need no freeing. */
  void (*params_free)(void *params);
} fg_job_kind;

/* Creates the job registry, loads every scene's last_job.json (see above) and starts the
 * worker thread. The registry has no kinds yet: register them (fg_jobs_register_kind) before
 * the first fg_jobs_submit. The app's store must be open; app must outlive the registry. On
 * success the caller owns *out (fg_jobs_free). */
int fg_jobs_new(fg_jobs **out, struct fg_app *app);

/* Stops the worker: a running training stops after its current step, writes its partial
 * checkpoint (field.next.fgc, used at the next start only when the scene has no field.fgc)
 * and stays "running" in last_job.json, which the next start reports as interrupted; queued
 * jobs likewise. Frees everything. Accepts NULL. */
void fg_jobs_free(fg_jobs *jobs);

/* Adds kind to the registry's table, so that jobs of kind->name can be submitted. kind stays
 * the caller's and must outlive the registry. FG_EINVAL for a name that is not 1..15 of
 * [a-z_] or a missing run function, FG_EEXIST for a name already registered, FG_ERANGE beyond
 * FG_JOBS_MAX_KINDS kinds. Call it before jobs are submitted (start-up). */
int fg_jobs_register_kind(fg_jobs *jobs, const fg_job_kind *kind);

/* Queues a job of the registered kind `kind` on scene with the common params (copied) and
 * the kind's own kind_params (may be NULL): on success the job owns kind_params (freed with
 * the kind's params_free when the job goes), on failure they stay with the caller.
 * FG_EINVAL for a kind that is not registered, FG_EBUSY when the scene has a queued or
 * running job (the detail names it), FG_ENOENT when the scene was deleted, FG_ENOMEM. On
 * success *out (may be NULL) receives the new job (queued). */
int fg_jobs_submit(fg_jobs *jobs, const char *kind, fg_scene *scene,
                   const fg_job_params *params, void *kind_params, fg_job_info *out);

/* Queues a job of kind on camera (a [camera NAME]), as fg_jobs_submit does for a scene:
 * FG_EBUSY (job_in_progress) when the camera has a queued or running job. The job's
 * run function finds the name with fg_job_camera; fg_job_scene is NULL. */
int fg_jobs_submit_camera(fg_jobs *jobs, const char *kind, const char *camera,
                          const fg_job_params *params, void *kind_params, fg_job_info *out);

/* 0 when scene has no queued or running job, else FG_EBUSY (training_in_progress) with a
 * detail that names the job. */
int fg_jobs_scene_idle(fg_jobs *jobs, const char *scene);

/* The job with that id, with a reference (fg_job_unref); NULL when unknown, with the failure
 * recorded (FG_ENOENT job_not_found). */
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

/* ---------------------------------------------------------------- for run functions
 * Called by a kind's run function, on the worker thread, while its job runs. */

/* The job's id and scene, or camera; constant while it runs (the job holds a reference to
 * the scene). A scene's job has no camera (""), a camera's job no scene (NULL). */
const char *fg_job_id(const fg_job *job);
fg_scene *fg_job_scene(fg_job *job);
const char *fg_job_camera(const fg_job *job);

/* fg_mono_s() (core/clock.h) when the job started running. */
double fg_job_started_s(fg_job *job);

/* 1 when the job should stop at the next opportunity: it was cancelled (DELETE, or its
 * scene is being deleted) or the daemon is stopping; fg_job_cancelled tells which. */
int fg_job_should_stop(fg_job *job);
int fg_job_cancelled(fg_job *job);

/* Changes of the job's progress: fg_job_update_begin locks the job and returns its live
 * info to write into (never its state: see below); fg_job_update_end bumps the version (event
 * streams send it) and unlocks. Nothing in between may block or take another job's lock. */
fg_job_info *fg_job_update_begin(fg_job *job);
void fg_job_update_end(fg_job *job);

/* Records the phase the job is in (fg_job_info.phase; at most 15 characters). */
void fg_job_set_phase(fg_job *job, const char *phase);

/* Ends a running job as failed with a message for the client (also logged); a job cancelled
 * meanwhile stays cancelled. */
void fg_job_fail(fg_job *job, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Before a job installs its result: FG_ECANCELED when it was cancelled (install nothing),
 * else 0, and from then on a DELETE answers that it is too late. */
int fg_job_commit_begin(fg_job *job);

/* Ends a running job as done (eta 0) or cancelled (its scene went while it committed), with
 * its elapsed and finished times. */
void fg_job_finish(fg_job *job, fg_job_state state);

/* Lowers the calling thread and the OpenMP team of n_threads it leads (libgomp keeps one
 * team per calling thread, so other threads' teams keep their priority) to nice 10; never
 * raises a priority the daemon was started with. */
void fg_job_lower_priority(int n_threads);

#endif
