/* Jobs: the registry, its table of kinds, the queue and the worker; see jobs.h. What a job
 * does lives with its kind (job_train.c). */
#include "jobs.h"

#include "app.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/ref.h"

#include <errno.h>
#include <malloc.h>
#include <math.h>
#include <omp.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

/* The nice value of a job's threads (see jobs.h). */
#define JOB_NICE 10
/* Finished jobs kept in memory beyond each scene's last one. */
#define MAX_FINISHED_JOBS 1000

struct fg_job {
  fg_ref ref;
  pthread_mutex_t lock; /* guards everything below */
  fg_job_info info;
  double started_mono;  /* CLOCK_MONOTONIC seconds when it started running */
  int cancel;           /* cancelled while running: the worker stops after this step */
  int committing;       /* installing its result: too late to cancel */
  fg_scene *scene;      /* held while queued or running; NULL for jobs loaded from disk */
  struct fg_jobs *jobs; /* the registry, for fg_job_should_stop; NULL for jobs loaded from disk */
  const fg_job_kind *kind; /* NULL for jobs loaded from disk */
  void *kind_params;    /* the kind's own parameters, owned (kind->params_free) */
  struct fg_job *next;  /* registry, newest first (guarded by fg_jobs.lock) */
  struct fg_job *qnext; /* queue (guarded by fg_jobs.lock) */
};

struct fg_jobs {
  struct fg_app *app;
  pthread_mutex_t lock;
  pthread_cond_t cond;
  pthread_mutex_t persist_lock;
  fg_job *all; /* newest first */
  fg_job *qhead, *qtail;
  const fg_job_kind *kinds[FG_JOBS_MAX_KINDS]; /* registered at start-up, before any submit */
  int n_kinds;
  int stopping;
  int worker_started;
  pthread_t worker;
};

/* ---------------------------------------------------------------- job objects */

static fg_job *job_new(void) {
  fg_job *j = calloc(1, sizeof *j);
  if (!j) return NULL;
  fg_ref_init(&j->ref, 1);
  pthread_mutex_init(&j->lock, NULL);
  j->info.loss = j->info.psnr = j->info.eta_s = j->info.samples_per_s = NAN;
  return j;
}

void fg_job_unref(fg_job *j) {
  if (!j || !fg_ref_put(&j->ref)) return;
  if (j->scene) fg_scene_unref(j->scene);
  if (j->kind && j->kind->params_free) j->kind->params_free(j->kind_params);
  pthread_mutex_destroy(&j->lock);
  free(j);
}

/* Copies the info; the caller holds j->lock. A running job's elapsed time is read live. */
static void info_locked(const fg_job *j, fg_job_info *out) {
  *out = j->info;
  if (j->info.state == FG_JOB_RUNNING && j->started_mono > 0)
    out->elapsed_s = fg_mono_s() - j->started_mono;
}

void fg_job_get_info(fg_job *j, fg_job_info *out) {
  pthread_mutex_lock(&j->lock);
  info_locked(j, out);
  pthread_mutex_unlock(&j->lock);
}

void fg_job_peek(fg_job *j, uint64_t *version, fg_job_state *state) {
  pthread_mutex_lock(&j->lock);
  *version = j->info.version;
  *state = j->info.state;
  pthread_mutex_unlock(&j->lock);
}

/* A fresh id: "j" + the creation time (ms, 12 hex digits) + "-" + 24 random bits. Sortable by
 * creation and unique across restarts. */
static void make_id(char out[FG_JOB_ID_MAX]) {
  static atomic_uint counter;
  uint32_t rnd = 0;
  if (getrandom(&rnd, sizeof rnd, GRND_NONBLOCK) != (ssize_t)sizeof rnd)
    rnd = (uint32_t)getpid() * 2654435761u ^ atomic_fetch_add(&counter, 1) * 40503u;
  snprintf(out, FG_JOB_ID_MAX, "j%012llx-%06x", (unsigned long long)fg_real_ms(),
           (unsigned)(rnd & 0xffffffu));
}

/* Writes info (a state of job j) to its scene's last_job.json and the scene's description.
 * committing marks a running job that has saved its result and is about to install it: a
 * start-up that finds it so tells from the scene's files whether the install happened
 * (load_last_job). A scene deleted meanwhile has no folder: nothing to keep then. */
static void persist_info(fg_jobs *jobs, fg_scene *scene, const fg_job_info *info,
                         int committing) {
  pthread_mutex_lock(&jobs->persist_lock);
  if (scene) {
    fg_scene_set_last_job(scene, info->id, fg_job_state_name(info->state));
    json_t *o = fg_job_info_json(info);
    if (o) {
      json_object_set_new(o, "created_ms", json_integer(info->created_ms));
      json_object_set_new(o, "started_ms", json_integer(info->started_ms));
      json_object_set_new(o, "finished_ms", json_integer(info->finished_ms));
      if (committing && info->state == FG_JOB_RUNNING)
        json_object_set_new(o, "committing", json_true());
    }
    char *text = o ? json_dumps(o, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) : NULL;
    json_decref(o);
    char *path = fg_path_join(fg_scene_dir(scene), "last_job.json");
    if (text && path && !fg_scene_deleted(scene) &&
        fg_write_file_atomic(path, text, strlen(text)) != 0)
      fg_warn("job %s: cannot write %s: %s", info->id, path, fg_error_detail());
    free(path);
    free(text);
  }
  pthread_mutex_unlock(&jobs->persist_lock);
}

/* Writes the job's current state (see persist_info). */
static void persist(fg_jobs *jobs, fg_job *j) {
  fg_job_info info;
  pthread_mutex_lock(&j->lock);
  info_locked(j, &info);
  fg_scene *scene = j->scene;
  int committing = j->committing;
  pthread_mutex_unlock(&j->lock);
  persist_info(jobs, scene, &info, committing);
}

/* ---------------------------------------------------------------- the registry */

/* Drops the oldest finished jobs beyond MAX_FINISHED_JOBS, keeping each scene's newest. The
 * caller holds jobs->lock. */
static void prune_locked(fg_jobs *jobs) {
  size_t finished = 0;
  for (fg_job **p = &jobs->all; *p;) {
    fg_job *j = *p;
    pthread_mutex_lock(&j->lock);
    int done = fg_job_state_finished(j->info.state);
    pthread_mutex_unlock(&j->lock);
    int newest_of_scene = 1;
    for (fg_job *k = jobs->all; k != j; k = k->next)
      if (strcmp(k->info.scene, j->info.scene) == 0 && strcmp(k->info.camera, j->info.camera) == 0)
        newest_of_scene = 0;
    if (done && !newest_of_scene && ++finished > MAX_FINISHED_JOBS) {
      *p = j->next;
      fg_job_unref(j);
    } else {
      p = &j->next;
    }
  }
}

/* The job with that id, or NULL with the failure recorded; the caller holds jobs->lock. */
static fg_job *find_locked(fg_jobs *jobs, const char *id) {
  for (fg_job *j = jobs->all; j; j = j->next)
    if (strcmp(j->info.id, id) == 0) return j;
  fg_fail_as(FG_ENOENT, "job_not_found", "no job '%s'; GET /v1/jobs lists them (a scene's "
             "last job is kept across restarts, older ones are not)", id);
  return NULL;
}

fg_job *fg_jobs_get(fg_jobs *jobs, const char *id) {
  pthread_mutex_lock(&jobs->lock);
  fg_job *found = find_locked(jobs, id);
  if (found) fg_ref_get(&found->ref);
  pthread_mutex_unlock(&jobs->lock);
  return found;
}

int fg_jobs_list(fg_jobs *jobs, fg_job_info **out, size_t *n) {
  pthread_mutex_lock(&jobs->lock);
  size_t k = 0;
  for (fg_job *j = jobs->all; j; j = j->next) k++;
  fg_job_info *v = calloc(k ? k : 1, sizeof *v);
  if (!v) {
    pthread_mutex_unlock(&jobs->lock);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  size_t i = 0;
  for (fg_job *j = jobs->all; j; j = j->next) fg_job_get_info(j, &v[i++]);
  pthread_mutex_unlock(&jobs->lock);
  *out = v;
  *n = k;
  return 0;
}

void fg_jobs_count(fg_jobs *jobs, size_t counts[FG_JOB_N_STATES]) {
  memset(counts, 0, FG_JOB_N_STATES * sizeof counts[0]);
  pthread_mutex_lock(&jobs->lock);
  for (fg_job *j = jobs->all; j; j = j->next) {
    pthread_mutex_lock(&j->lock);
    counts[j->info.state]++;
    pthread_mutex_unlock(&j->lock);
  }
  pthread_mutex_unlock(&jobs->lock);
}

/* The registered kind of that name; NULL when none. Kinds are registered before the worker
 * sees a job and never removed, so the table is read without the lock. */
static const fg_job_kind *kind_find(const fg_jobs *jobs, const char *name) {
  for (int i = 0; i < jobs->n_kinds; i++)
    if (strcmp(jobs->kinds[i]->name, name) == 0) return jobs->kinds[i];
  return NULL;
}

int fg_jobs_register_kind(fg_jobs *jobs, const fg_job_kind *kind) {
  if (!kind || !kind->name || !kind->run) return fg_fail(FG_EINVAL, "job kind: NULL name or run");
  size_t len = strlen(kind->name);
  if (len == 0 || len >= FG_JOB_KIND_MAX ||
      strspn(kind->name, "abcdefghijklmnopqrstuvwxyz_") != len)
    return fg_fail(FG_EINVAL, "job kind '%s': names are 1 to %d characters of a-z and _",
                   kind->name, FG_JOB_KIND_MAX - 1);
  pthread_mutex_lock(&jobs->lock);
  int rc = 0;
  if (kind_find(jobs, kind->name))
    rc = fg_fail(FG_EEXIST, "job kind '%s' is registered already", kind->name);
  else if (jobs->n_kinds == FG_JOBS_MAX_KINDS)
    rc = fg_fail(FG_ERANGE, "job kind '%s': the registry holds %d kinds at most", kind->name,
                 FG_JOBS_MAX_KINDS);
  else
    jobs->kinds[jobs->n_kinds++] = kind;
  pthread_mutex_unlock(&jobs->lock);
  return rc;
}

/* What a job works on, for messages: "scene NAME" or "camera NAME". */
static const char *subject_kind(const fg_job_info *i) { return i->camera[0] ? "camera" : "scene"; }
static const char *subject_name(const fg_job_info *i) { return i->camera[0] ? i->camera : i->scene; }

/* FG_EBUSY when the subject of info (its scene, or its camera) has a queued or running job,
 * with the detail that names it; else 0. Under jobs->lock. */
static int idle_locked(fg_jobs *jobs, const fg_job_info *info) {
  for (fg_job *k = jobs->all; k; k = k->next) {
    if (strcmp(k->info.scene, info->scene) != 0 || strcmp(k->info.camera, info->camera) != 0)
      continue;
    pthread_mutex_lock(&k->lock);
    fg_job_state st = k->info.state;
    char id[FG_JOB_ID_MAX];
    snprintf(id, sizeof id, "%s", k->info.id);
    pthread_mutex_unlock(&k->lock);
    if (st == FG_JOB_QUEUED || st == FG_JOB_RUNNING)
      return fg_fail_as(FG_EBUSY, info->camera[0] ? "job_in_progress" : "training_in_progress",
                        "%s %s already has job %s %s; wait for it (GET /v1/jobs/%s) or "
                        "cancel it (DELETE /v1/jobs/%s)", subject_kind(info),
                        subject_name(info), id, fg_job_state_name(st), id, id);
  }
  return 0;
}

int fg_jobs_scene_idle(fg_jobs *jobs, const char *scene) {
  fg_job_info info = {0};
  snprintf(info.scene, sizeof info.scene, "%s", scene);
  pthread_mutex_lock(&jobs->lock);
  const int rc = idle_locked(jobs, &info);
  pthread_mutex_unlock(&jobs->lock);
  return rc;
}

/* Queues a new job on scene (a reference is taken) or, scene NULL, on camera. */
static int submit(fg_jobs *jobs, const char *kind_name, fg_scene *scene, const char *camera,
                  const fg_job_params *params, void *kind_params, fg_job_info *out) {
  const fg_job_kind *kind = kind_find(jobs, kind_name);
  if (!kind)
    return fg_fail_as(FG_EINVAL, "internal_error", "cannot queue the job: no job kind '%s' is "
                      "registered", kind_name);
  fg_job *j = job_new();
  if (!j) return fg_fail_as(FG_ENOMEM, "internal_error", "cannot queue the job: out of memory");
  if (scene)
    snprintf(j->info.scene, sizeof j->info.scene, "%s", fg_scene_name(scene));
  else
    snprintf(j->info.camera, sizeof j->info.camera, "%s", camera);
  pthread_mutex_lock(&jobs->lock);
  const int busy = idle_locked(jobs, &j->info);
  if (busy != 0) {
    pthread_mutex_unlock(&jobs->lock);
    fg_job_unref(j);
    return busy;
  }
  make_id(j->info.id);
  snprintf(j->info.kind, sizeof j->info.kind, "%s", kind->name);
  j->info.state = FG_JOB_QUEUED;
  j->info.params = *params;
  j->info.created_ms = fg_real_ms();
  j->info.version = 1;
  if (scene) {
    fg_scene_info si;
    fg_scene_get_info(scene, &si);
    j->info.n_frames = (int)si.n_frames;
    if (params->holdout_every > 0)
      j->info.n_heldout = (int)((si.n_frames + (size_t)params->holdout_every - 1) /
                                (size_t)params->holdout_every);
    if (fg_scene_deleted(scene)) {
      pthread_mutex_unlock(&jobs->lock);
      fg_job_unref(j);
      return fg_fail_as(FG_ENOENT, "scene_not_found", "scene %s was deleted",
                        fg_scene_name(scene));
    }
    fg_scene_ref(scene);
    j->scene = scene;
  }
  fg_ref_get(&j->ref); /* one for the registry, one for the queue */
  j->jobs = jobs;
  j->kind = kind;
  j->kind_params = kind_params;
  j->next = jobs->all;
  jobs->all = j;
  j->qnext = NULL;
  if (jobs->qtail) jobs->qtail->qnext = j;
  else jobs->qhead = j;
  jobs->qtail = j;
  pthread_cond_signal(&jobs->cond);
  if (out) fg_job_get_info(j, out);
  pthread_mutex_unlock(&jobs->lock);
  persist(jobs, j);
  fg_info("job %s: %s of %s %s queued (%lld steps, seed %llu)", j->info.id, kind->name,
          subject_kind(&j->info), subject_name(&j->info), (long long)params->steps,
          (unsigned long long)params->seed);
  return 0;
}

int fg_jobs_submit(fg_jobs *jobs, const char *kind, fg_scene *scene,
                   const fg_job_params *params, void *kind_params, fg_job_info *out) {
  return submit(jobs, kind, scene, NULL, params, kind_params, out);
}

int fg_jobs_submit_camera(fg_jobs *jobs, const char *kind, const char *camera,
                          const fg_job_params *params, void *kind_params, fg_job_info *out) {
  return submit(jobs, kind, NULL, camera, params, kind_params, out);
}

/* Removes j from the queue if it is there; the caller holds jobs->lock. */
static void dequeue_locked(fg_jobs *jobs, fg_job *j) {
  fg_job *prev = NULL;
  for (fg_job *k = jobs->qhead; k; prev = k, k = k->qnext) {
    if (k != j) continue;
    if (prev) prev->qnext = k->qnext;
    else jobs->qhead = k->qnext;
    if (jobs->qtail == k) jobs->qtail = prev;
    k->qnext = NULL;
    fg_job_unref(k); /* the queue's reference */
    return;
  }
}

/* Lets go of j->lock after a change of j->info when `changed`: every change a reader may see
 * gets a new version (GET .../events sends one event per version). */
static void unlock_changed(fg_job *j, int changed) {
  if (changed) j->info.version++;
  pthread_mutex_unlock(&j->lock);
}

/* Cancels j; the caller holds jobs->lock. Returns 0, or FG_EBUSY with a detail. */
static int cancel_locked(fg_jobs *jobs, fg_job *j) {
  pthread_mutex_lock(&j->lock);
  fg_job_state st = j->info.state;
  int rc = 0;
  if (fg_job_state_finished(st)) {
    rc = fg_fail_as(FG_EBUSY, "job_finished", "job %s has finished (%s); only queued or "
                    "running jobs can be cancelled", j->info.id, fg_job_state_name(st));
  } else if (j->committing) {
    rc = fg_fail_as(FG_EBUSY, "job_finished", "job %s has finished training and is installing "
                    "the new field; it is too late to cancel it", j->info.id);
  } else {
    if (st == FG_JOB_RUNNING) {
      j->cancel = 1;
      j->info.elapsed_s = fg_mono_s() - j->started_mono;
    }
    j->info.state = FG_JOB_CANCELLED;
    j->info.eta_s = NAN;
    j->info.finished_ms = fg_real_ms();
  }
  unlock_changed(j, rc == 0);
  if (rc == 0 && st == FG_JOB_QUEUED) dequeue_locked(jobs, j);
  return rc;
}

int fg_jobs_cancel(fg_jobs *jobs, const char *id, fg_job_info *out) {
  pthread_mutex_lock(&jobs->lock);
  fg_job *j = find_locked(jobs, id);
  if (!j) {
    pthread_mutex_unlock(&jobs->lock);
    return FG_ENOENT;
  }
  fg_ref_get(&j->ref);
  int rc = cancel_locked(jobs, j);
  pthread_mutex_unlock(&jobs->lock);
  if (rc == 0) {
    fg_info("job %s: cancelled", id);
    persist(jobs, j);
  }
  if (out) fg_job_get_info(j, out);
  fg_job_unref(j);
  return rc;
}

void fg_jobs_cancel_scene(fg_jobs *jobs, const char *scene) {
  pthread_mutex_lock(&jobs->lock);
  for (fg_job *j = jobs->all; j; j = j->next) {
    if (strcmp(j->info.scene, scene) != 0) continue;
    pthread_mutex_lock(&j->lock);
    int active = !fg_job_state_finished(j->info.state);
    pthread_mutex_unlock(&j->lock);
    if (active && cancel_locked(jobs, j) == 0)
      fg_info("job %s: cancelled, its scene %s is being deleted", j->info.id,
              j->info.scene);
  }
  pthread_mutex_unlock(&jobs->lock);
}

/* ---------------------------------------------------------------- for run functions */

const char *fg_job_id(const fg_job *j) { return j->info.id; }

fg_scene *fg_job_scene(fg_job *j) { return j->scene; }
const char *fg_job_camera(const fg_job *j) { return j->info.camera; }

double fg_job_started_s(fg_job *j) { return j->started_mono; }

int fg_job_cancelled(fg_job *j) {
  pthread_mutex_lock(&j->lock);
  int cancelled = j->cancel || j->info.state == FG_JOB_CANCELLED;
  pthread_mutex_unlock(&j->lock);
  return cancelled;
}

int fg_job_should_stop(fg_job *j) {
  pthread_mutex_lock(&j->lock);
  int cancelled = j->cancel;
  pthread_mutex_unlock(&j->lock);
  pthread_mutex_lock(&j->jobs->lock);
  int stopping = j->jobs->stopping;
  pthread_mutex_unlock(&j->jobs->lock);
  return cancelled || stopping;
}

fg_job_info *fg_job_update_begin(fg_job *j) {
  pthread_mutex_lock(&j->lock);
  return &j->info;
}

void fg_job_update_end(fg_job *j) { unlock_changed(j, 1); }

void fg_job_set_phase(fg_job *j, const char *phase) {
  fg_job_info *info = fg_job_update_begin(j);
  snprintf(info->phase, sizeof info->phase, "%s", phase);
  fg_job_update_end(j);
}

void fg_job_fail(fg_job *j, const char *fmt, ...) {
  char msg[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  pthread_mutex_lock(&j->lock);
  j->committing = 0;
  const int running = j->info.state == FG_JOB_RUNNING;
  if (running) {
    j->info.state = FG_JOB_FAILED;
    snprintf(j->info.error, sizeof j->info.error, "%s", msg);
    j->info.eta_s = NAN;
    j->info.elapsed_s = fg_mono_s() - j->started_mono;
    j->info.finished_ms = fg_real_ms();
  }
  unlock_changed(j, running);
  fg_warn("job %s: failed: %s", j->info.id, msg);
}

int fg_job_commit_begin(fg_job *j) {
  pthread_mutex_lock(&j->lock);
  int cancelled = j->cancel;
  if (!cancelled) j->committing = 1;
  pthread_mutex_unlock(&j->lock);
  if (cancelled) return FG_ECANCELED;
  /* On disk before the install: a kill during it leaves a job that the next start can tell
   * done or not from the scene's files, never one whose field is in but that reads failed. */
  if (j->jobs) persist(j->jobs, j);
  return 0;
}

void fg_job_finish(fg_job *j, fg_job_state state) {
  /* The final state goes to disk before any client can see it: a job seen done stays done
   * after a kill. */
  pthread_mutex_lock(&j->lock);
  fg_job_info info;
  info_locked(j, &info);
  fg_scene *scene = j->scene;
  pthread_mutex_unlock(&j->lock);
  info.state = state;
  info.eta_s = state == FG_JOB_DONE ? 0 : NAN;
  info.elapsed_s = fg_mono_s() - j->started_mono;
  info.finished_ms = fg_real_ms();
  if (j->jobs) persist_info(j->jobs, scene, &info, 0);
  pthread_mutex_lock(&j->lock);
  j->info.state = state;
  j->info.eta_s = info.eta_s;
  j->info.elapsed_s = info.elapsed_s;
  j->info.finished_ms = info.finished_ms;
  unlock_changed(j, 1);
}

void fg_job_lower_priority(int n_threads) {
  int tid = gettid();
  errno = 0;
  int current = getpriority(PRIO_PROCESS, (id_t)tid);
  if (!(errno == 0 && current >= JOB_NICE)) setpriority(PRIO_PROCESS, (id_t)tid, JOB_NICE);
#pragma omp parallel num_threads(n_threads)
  {
    int team_tid = gettid();
    errno = 0;
    int team_current = getpriority(PRIO_PROCESS, (id_t)team_tid);
    if (!(errno == 0 && team_current >= JOB_NICE))
      setpriority(PRIO_PROCESS, (id_t)team_tid, JOB_NICE);
  }
}

/* ---------------------------------------------------------------- the worker */

static void *worker_main(void *arg) {
  fg_jobs *jobs = arg;
  pthread_setname_np(pthread_self(), "fg-train"); /* tests and ps look for this name */
  for (;;) {
    pthread_mutex_lock(&jobs->lock);
    while (!jobs->qhead && !jobs->stopping) pthread_cond_wait(&jobs->cond, &jobs->lock);
    if (jobs->stopping) {
      pthread_mutex_unlock(&jobs->lock);
      return NULL;
    }
    fg_job *j = jobs->qhead; /* the queue's reference is ours now */
    jobs->qhead = j->qnext;
    if (!jobs->qhead) jobs->qtail = NULL;
    j->qnext = NULL;
    pthread_mutex_unlock(&jobs->lock);

    pthread_mutex_lock(&j->lock);
    int go = j->info.state == FG_JOB_QUEUED;
    if (go) {
      j->info.state = FG_JOB_RUNNING;
      j->info.started_ms = fg_real_ms();
      j->started_mono = fg_mono_s();
    }
    unlock_changed(j, go);
    if (go) {
      persist(jobs, j);
      fg_info("job %s: %s of %s %s started", j->info.id, j->kind->name, subject_kind(&j->info),
              subject_name(&j->info));
      j->kind->run(j, jobs->app, j->kind_params);
      persist(jobs, j);
      /* The job is over: its scene may go (the reference kept it alive while it ran). */
      pthread_mutex_lock(&j->lock);
      fg_scene *scene = fg_job_state_finished(j->info.state) ? j->scene : NULL;
      if (scene) j->scene = NULL;
      pthread_mutex_unlock(&j->lock);
      if (scene) fg_scene_unref(scene);
      /* A job's buffers (a training's are hundreds of MB) are free now; hand them back. */
      malloc_trim(0);
    }
    pthread_mutex_lock(&jobs->lock);
    prune_locked(jobs);
    pthread_mutex_unlock(&jobs->lock);
    fg_job_unref(j);
  }
}

/* ---------------------------------------------------------------- start and stop */

/* Reads one scene's last_job.json into the registry (see jobs.h). */
static void load_last_job(fg_jobs *jobs, fg_scene *scene) {
  char *path = fg_path_join(fg_scene_dir(scene), "last_job.json");
  if (!path) return;
  if (access(path, F_OK) != 0) {
    free(path);
    return;
  }
  json_error_t jerr;
  json_t *o = json_load_file(path, 0, &jerr);
  fg_job_info info;
  if (!o || fg_job_info_from_json(o, &info) != 0) {
    fg_warn("scene %s: %s is unreadable and is ignored: %s", fg_scene_name(scene), path,
            o ? fg_error_detail() : jerr.text);
    json_decref(o);
    free(path);
    return;
  }
  const int committing = json_is_true(json_object_get(o, "committing"));
  json_decref(o);
  free(path);
  snprintf(info.scene, sizeof info.scene, "%s", fg_scene_name(scene));
  fg_job *j = job_new();
  if (!j) return;
  int interrupted = !fg_job_state_finished(info.state);
  if (interrupted && committing && !fg_scene_had_next_checkpoint(scene)) {
    /* Stopped while it installed its field, after the rename that installs it (the
     * field.next.fgc it had saved is gone): it is done, and the scene has its field. */
    fg_info("job %s of scene %s had installed its field when the daemon stopped; it is "
            "reported done", info.id, info.scene);
    info.state = FG_JOB_DONE;
    info.eta_s = 0;
    if (!info.finished_ms) info.finished_ms = fg_real_ms();
    interrupted = 0;
    persist_info(jobs, scene, &info, 0);
  }
  if (interrupted) {
    fg_info("job %s of scene %s was %s when the daemon stopped; it is reported failed", info.id,
            info.scene, fg_job_state_name(info.state));
    info.state = FG_JOB_FAILED;
    snprintf(info.error, sizeof info.error, "interrupted by a daemon restart");
    info.eta_s = NAN;
    if (!info.finished_ms) info.finished_ms = fg_real_ms();
  }
  info.version = 1;
  j->info = info;
  pthread_mutex_lock(&jobs->lock);
  /* Newest first: insert by creation time. */
  fg_job **p = &jobs->all;
  while (*p && (*p)->info.created_ms > info.created_ms) p = &(*p)->next;
  j->next = *p;
  *p = j;
  pthread_mutex_unlock(&jobs->lock);
  fg_scene_set_last_job(scene, info.id, fg_job_state_name(info.state));
  if (interrupted) {
    j->scene = scene; /* for persist; dropped right after */
    persist(jobs, j);
    j->scene = NULL;
  }
}

int fg_jobs_new(fg_jobs **out, struct fg_app *app) {
  *out = NULL;
  fg_jobs *jobs = calloc(1, sizeof *jobs);
  if (!jobs) return fg_fail(FG_ENOMEM, "out of memory");
  jobs->app = app;
  pthread_mutex_init(&jobs->lock, NULL);
  pthread_cond_init(&jobs->cond, NULL);
  pthread_mutex_init(&jobs->persist_lock, NULL);
  fg_scene_info *infos = NULL;
  size_t n = 0;
  if (fg_store_list(app->store, &infos, &n) == 0) {
    for (size_t i = 0; i < n; i++) {
      fg_scene *s = fg_store_get(app->store, infos[i].name);
      if (!s) continue;
      load_last_job(jobs, s);
      fg_scene_unref(s);
    }
    free(infos);
  }
  int err = pthread_create(&jobs->worker, NULL, worker_main, jobs);
  if (err != 0) {
    fg_jobs_free(jobs);
    return fg_fail(FG_EIO, "cannot start the training thread: %s", strerror(err));
  }
  jobs->worker_started = 1;
  *out = jobs;
  return 0;
}

void fg_jobs_free(fg_jobs *jobs) {
  if (!jobs) return;
  pthread_mutex_lock(&jobs->lock);
  jobs->stopping = 1;
  pthread_cond_broadcast(&jobs->cond);
  pthread_mutex_unlock(&jobs->lock);
  if (jobs->worker_started) pthread_join(jobs->worker, NULL);
  /* Queued jobs stay "queued" in last_job.json: the next start reports them interrupted. */
  for (fg_job *j = jobs->qhead; j;) {
    fg_job *next = j->qnext;
    fg_job_unref(j);
    j = next;
  }
  for (fg_job *j = jobs->all; j;) {
    fg_job *next = j->next;
    fg_job_unref(j);
    j = next;
  }
  pthread_mutex_destroy(&jobs->persist_lock);
  pthread_cond_destroy(&jobs->cond);
  pthread_mutex_destroy(&jobs->lock);
  free(jobs);
}
