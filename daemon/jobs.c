/* Jobs: the registry, the FIFO queue, the worker thread and the training loop (jobs.h).
 *
 * Locking: fg_jobs.lock guards the registry list and the queue; fg_job.lock guards a job's
 * info and flags. Order: registry lock, then a job's lock. persist_lock serialises writes of
 * last_job.json so that the last write always carries the latest state. The worker holds no
 * lock while it trains; it takes a job's lock for a moment after every step. */
#include "jobs.h"

#include "app.h"
#include "clip_features.h"
#include "clip_svc.h"
#include "metrics.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "field/checkpoint.h"
#include "field/model.h"
#include "field/train.h"
#include "json.h"

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

/* The nice value of the training threads (see jobs.h). */
#define TRAIN_NICE 10
/* Finished jobs kept in memory beyond each scene's last one. */
#define MAX_FINISHED_JOBS 1000
/* The field's cube: twice the workspace's largest extent (model.h). */
#define FIELD_SCALE 2.0

struct fg_job {
  atomic_int refs;
  pthread_mutex_t lock; /* guards everything below */
  fg_job_info info;
  double started_mono;  /* CLOCK_MONOTONIC seconds when it started running */
  int cancel;           /* cancelled while running: the worker stops after this step */
  int committing;       /* installing its result: too late to cancel */
  fg_scene *scene;      /* held while queued or running; NULL for jobs loaded from disk */
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
  int stopping;
  int worker_started;
  pthread_t worker;
};

static const char *const state_names[FG_JOB_N_STATES] = {"queued", "running", "done", "failed",
                                                         "cancelled"};

const char *fg_job_state_name(fg_job_state s) {
  return s >= 0 && s < FG_JOB_N_STATES ? state_names[s] : "unknown";
}

int fg_job_state_finished(fg_job_state s) {
  return s == FG_JOB_DONE || s == FG_JOB_FAILED || s == FG_JOB_CANCELLED;
}

static int64_t now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

static double mono_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* ---------------------------------------------------------------- job objects */

static fg_job *job_new(void) {
  fg_job *j = calloc(1, sizeof *j);
  if (!j) return NULL;
  atomic_init(&j->refs, 1);
  pthread_mutex_init(&j->lock, NULL);
  j->info.loss = j->info.psnr = j->info.eta_s = j->info.samples_per_s = NAN;
  return j;
}

void fg_job_unref(fg_job *j) {
  if (!j || atomic_fetch_sub(&j->refs, 1) != 1) return;
  if (j->scene) fg_scene_unref(j->scene);
  pthread_mutex_destroy(&j->lock);
  free(j);
}

/* Copies the info; the caller holds j->lock. A running job's elapsed time is read live. */
static void info_locked(const fg_job *j, fg_job_info *out) {
  *out = j->info;
  if (j->info.state == FG_JOB_RUNNING && j->started_mono > 0)
    out->elapsed_s = mono_s() - j->started_mono;
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
  snprintf(out, FG_JOB_ID_MAX, "j%012llx-%06x", (unsigned long long)now_ms(),
           (unsigned)(rnd & 0xffffffu));
}

/* ---------------------------------------------------------------- JSON */

static json_t *num_or_null(double v) { return isfinite(v) ? json_real(v) : json_null(); }

static json_t *time_or_null(int64_t ms) {
  if (ms <= 0) return json_null();
  char t[32];
  fg_iso8601(ms, t);
  return json_string(t);
}

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
  json_object_set_new(o, "scene", json_string(j->scene));
  json_object_set_new(o, "kind", json_string("train"));
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
  json_object_set_new(o, "frames", json_integer(j->n_frames));
  json_object_set_new(o, "heldout_frames", json_integer(j->n_heldout));
  json_object_set_new(o, "phase", j->phase[0] ? json_string(j->phase) : json_null());
  json_object_set_new(o, "features",
                      j->features_total
                        ? json_pack("{s:i,s:i,s:i}", "total", j->features_total, "done",
                                    j->features_done, "cached", j->features_cached)
                        : json_null());
  json_object_set_new(o, "created", time_or_null(j->created_ms));
  json_object_set_new(o, "started", time_or_null(j->started_ms));
  json_object_set_new(o, "finished", time_or_null(j->finished_ms));
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

/* Reads a job back from last_job.json (the API object plus created_ms, started_ms,
 * finished_ms). FG_EFORMAT when it is not one. */
static int info_from_json(json_t *o, fg_job_info *j) {
  memset(j, 0, sizeof *j);
  const char *id = json_string_value(json_object_get(o, "id"));
  const char *scene = json_string_value(json_object_get(o, "scene"));
  const char *state = json_string_value(json_object_get(o, "state"));
  if (!id || !scene || !state || strlen(id) >= sizeof j->id || strlen(scene) >= sizeof j->scene)
    return fg_fail(FG_EFORMAT, "not a job: id, scene or state missing");
  for (const char *p = id; *p; p++)
    if (!((*p >= '0' && *p <= '9') || (*p >= 'a' && *p <= 'z') || *p == '-'))
      return fg_fail(FG_EFORMAT, "job id '%s' has characters other than a-z 0-9 -", id);
  int s = -1;
  for (int i = 0; i < FG_JOB_N_STATES; i++)
    if (strcmp(state, state_names[i]) == 0) s = i;
  if (s < 0) return fg_fail(FG_EFORMAT, "job %s: unknown state '%s'", id, state);
  snprintf(j->id, sizeof j->id, "%s", id);
  snprintf(j->scene, sizeof j->scene, "%s", scene);
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
  j->n_frames = (int)jint(o, "frames");
  j->n_heldout = (int)jint(o, "heldout_frames");
  const char *phase = json_string_value(json_object_get(o, "phase"));
  if (phase) snprintf(j->phase, sizeof j->phase, "%s", phase);
  json_t *feats = json_object_get(o, "features");
  j->features_total = (int)jint(feats, "total");
  j->features_done = (int)jint(feats, "done");
  j->features_cached = (int)jint(feats, "cached");
  j->created_ms = jint(o, "created_ms");
  j->started_ms = jint(o, "started_ms");
  j->finished_ms = jint(o, "finished_ms");
  return 0;
}

/* Writes the job's current state to its scene's last_job.json and the scene's description.
 * A scene deleted meanwhile has no folder: nothing to keep then. */
static void persist(fg_jobs *jobs, fg_job *j) {
  pthread_mutex_lock(&jobs->persist_lock);
  fg_job_info info;
  pthread_mutex_lock(&j->lock);
  info_locked(j, &info);
  fg_scene *scene = j->scene;
  pthread_mutex_unlock(&j->lock);
  if (scene) {
    fg_scene_set_last_job(scene, info.id, fg_job_state_name(info.state));
    json_t *o = fg_job_info_json(&info);
    if (o) {
      json_object_set_new(o, "created_ms", json_integer(info.created_ms));
      json_object_set_new(o, "started_ms", json_integer(info.started_ms));
      json_object_set_new(o, "finished_ms", json_integer(info.finished_ms));
    }
    char *text = o ? json_dumps(o, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) : NULL;
    json_decref(o);
    char *path = fg_path_join(fg_scene_dir(scene), "last_job.json");
    if (text && path && !fg_scene_deleted(scene) &&
        fg_write_file_atomic(path, text, strlen(text)) != 0)
      fg_warn("job %s: cannot write %s: %s", info.id, path, fg_error_detail());
    free(path);
    free(text);
  }
  pthread_mutex_unlock(&jobs->persist_lock);
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
      if (strcmp(k->info.scene, j->info.scene) == 0) newest_of_scene = 0;
    if (done && !newest_of_scene && ++finished > MAX_FINISHED_JOBS) {
      *p = j->next;
      fg_job_unref(j);
    } else {
      p = &j->next;
    }
  }
}

fg_job *fg_jobs_get(fg_jobs *jobs, const char *id) {
  pthread_mutex_lock(&jobs->lock);
  fg_job *found = NULL;
  for (fg_job *j = jobs->all; j && !found; j = j->next)
    if (strcmp(j->info.id, id) == 0) found = j;
  if (found) atomic_fetch_add(&found->refs, 1);
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

int fg_jobs_submit(fg_jobs *jobs, fg_scene *scene, const fg_train_params *params,
                   fg_job_info *out) {
  const char *name = fg_scene_name(scene);
  fg_job *j = job_new();
  if (!j) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_lock(&jobs->lock);
  for (fg_job *k = jobs->all; k; k = k->next) {
    if (strcmp(k->info.scene, name) != 0) continue;
    pthread_mutex_lock(&k->lock);
    fg_job_state st = k->info.state;
    char id[FG_JOB_ID_MAX];
    snprintf(id, sizeof id, "%s", k->info.id);
    pthread_mutex_unlock(&k->lock);
    if (st == FG_JOB_QUEUED || st == FG_JOB_RUNNING) {
      pthread_mutex_unlock(&jobs->lock);
      fg_job_unref(j);
      return fg_fail(FG_EBUSY, "scene %s already has job %s %s; wait for it (GET /v1/jobs/%s) "
                     "or cancel it (DELETE /v1/jobs/%s)", name, id, fg_job_state_name(st), id,
                     id);
    }
  }
  make_id(j->info.id);
  snprintf(j->info.scene, sizeof j->info.scene, "%s", name);
  j->info.state = FG_JOB_QUEUED;
  j->info.params = *params;
  j->info.created_ms = now_ms();
  j->info.version = 1;
  fg_scene_info si;
  fg_scene_get_info(scene, &si);
  j->info.n_frames = (int)si.n_frames;
  if (params->holdout_every > 0)
    j->info.n_heldout = (int)((si.n_frames + (size_t)params->holdout_every - 1) /
                              (size_t)params->holdout_every);
  if (fg_scene_deleted(scene)) {
    pthread_mutex_unlock(&jobs->lock);
    fg_job_unref(j);
    return fg_fail(FG_ENOENT, "scene %s was deleted", name);
  }
  atomic_fetch_add(&j->refs, 1); /* one for the registry, one for the queue */
  fg_scene_ref(scene);
  j->scene = scene;
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
  fg_info("job %s: training of scene %s queued (%lld steps, seed %llu)", j->info.id, name,
          (long long)params->steps, (unsigned long long)params->seed);
  return 0;
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

/* Cancels j; the caller holds jobs->lock. Returns 0, or FG_EBUSY with a detail. */
static int cancel_locked(fg_jobs *jobs, fg_job *j) {
  pthread_mutex_lock(&j->lock);
  fg_job_state st = j->info.state;
  int rc = 0;
  if (fg_job_state_finished(st)) {
    rc = fg_fail(FG_EBUSY, "job %s has finished (%s); only queued or running jobs can be "
                 "cancelled", j->info.id, fg_job_state_name(st));
  } else if (j->committing) {
    rc = fg_fail(FG_EBUSY, "job %s has finished training and is installing the new field; it "
                 "is too late to cancel it", j->info.id);
  } else {
    if (st == FG_JOB_RUNNING) {
      j->cancel = 1;
      j->info.elapsed_s = mono_s() - j->started_mono;
    }
    j->info.state = FG_JOB_CANCELLED;
    j->info.eta_s = NAN;
    j->info.finished_ms = now_ms();
    j->info.version++;
  }
  pthread_mutex_unlock(&j->lock);
  if (rc == 0 && st == FG_JOB_QUEUED) dequeue_locked(jobs, j);
  return rc;
}

int fg_jobs_cancel(fg_jobs *jobs, const char *id, fg_job_info *out) {
  pthread_mutex_lock(&jobs->lock);
  fg_job *j = NULL;
  for (fg_job *k = jobs->all; k && !j; k = k->next)
    if (strcmp(k->info.id, id) == 0) j = k;
  if (!j) {
    pthread_mutex_unlock(&jobs->lock);
    return fg_fail(FG_ENOENT, "no job '%s'; GET /v1/jobs lists them", id);
  }
  atomic_fetch_add(&j->refs, 1);
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

/* ---------------------------------------------------------------- the training */

/* Lowers the calling thread and the OpenMP team it leads (libgomp keeps one team per
 * calling thread, so other threads' teams keep their priority) to TRAIN_NICE; never raises
 * a priority the daemon was started with. */
static void lower_priority(int n_threads) {
  int tid = gettid();
  errno = 0;
  int cur = getpriority(PRIO_PROCESS, (id_t)tid);
  if (!(errno == 0 && cur >= TRAIN_NICE)) setpriority(PRIO_PROCESS, (id_t)tid, TRAIN_NICE);
#pragma omp parallel num_threads(n_threads)
  {
    int t = gettid();
    errno = 0;
    int c = getpriority(PRIO_PROCESS, (id_t)t);
    if (!(errno == 0 && c >= TRAIN_NICE)) setpriority(PRIO_PROCESS, (id_t)t, TRAIN_NICE);
  }
}

typedef struct run_ctx {
  fg_jobs *jobs;
  fg_job *job;
} run_ctx;

/* Whether the job should stop: cancelled, or the daemon is stopping. */
static int should_stop(void *ud) {
  run_ctx *r = ud;
  pthread_mutex_lock(&r->job->lock);
  int c = r->job->cancel;
  pthread_mutex_unlock(&r->job->lock);
  pthread_mutex_lock(&r->jobs->lock);
  int s = r->jobs->stopping;
  pthread_mutex_unlock(&r->jobs->lock);
  return c || s;
}

/* Ends a job as failed with a message (unless it was cancelled meanwhile). */
static void job_fail(fg_job *j, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void job_fail(fg_job *j, const char *fmt, ...) {
  char msg[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  pthread_mutex_lock(&j->lock);
  if (j->info.state == FG_JOB_RUNNING) {
    j->info.state = FG_JOB_FAILED;
    snprintf(j->info.error, sizeof j->info.error, "%s", msg);
    j->info.eta_s = NAN;
    j->info.elapsed_s = mono_s() - j->started_mono;
    j->info.finished_ms = now_ms();
    j->info.version++;
  }
  pthread_mutex_unlock(&j->lock);
  fg_warn("job %s: failed: %s", j->info.id, msg);
}

/* Records the phase the job is in. */
static void set_phase(fg_job *j, const char *phase) {
  pthread_mutex_lock(&j->lock);
  snprintf(j->info.phase, sizeof j->info.phase, "%s", phase);
  j->info.version++;
  pthread_mutex_unlock(&j->lock);
}

/* Progress of the CLIP features phase (clip_features.h). */
static void on_features(void *ud, const fg_clip_features_progress *p) {
  run_ctx *r = ud;
  pthread_mutex_lock(&r->job->lock);
  r->job->info.features_done = (int)p->done;
  r->job->info.features_cached = (int)p->cached;
  r->job->info.elapsed_s = mono_s() - r->job->started_mono;
  r->job->info.version++;
  pthread_mutex_unlock(&r->job->lock);
}

/* Total pixels of the frames the trainer holds out (frames i with i % k == 0). */
static double heldout_pixels(const fg_frame *frames, size_t n, int k) {
  double px = 0;
  for (size_t i = 0; k > 0 && i < n; i += (size_t)k)
    px += (double)frames[i].cam.w * (double)frames[i].cam.h;
  return px;
}

/* Trains j's scene. Leaves the job done, failed, cancelled or (daemon stopping) running. */
static void run_training(fg_jobs *jobs, fg_job *j) {
  fg_app *app = jobs->app;
  run_ctx rc_ud = {jobs, j};
  fg_scene *scene = j->scene;
  const char *id = j->info.id;
  const fg_conf *conf = fg_app_conf_acquire(app);
  const int n_threads = fg_conf_threads(conf), half = conf->half_precision;
  fg_app_conf_release(app, conf);
  /* The CLIP model this job starts with serves it to the end, whatever a reload brings. Its
   * team may be larger than training's: lower every thread either may use. */
  fg_clip_model *clip = app->clip ? fg_clip_svc_acquire(app->clip) : NULL;
  lower_priority(clip && fg_clip_model_threads(clip) > n_threads ? fg_clip_model_threads(clip)
                                                                  : n_threads);
  /* This training writes and removes field.next.fgc: if the scene's field came from that file
   * (an interrupted training), make it field.fgc first so that nothing can lose it. */
  fg_scene_keep_partial(scene);

  fg_frame *frames = NULL;
  int *indices = NULL;
  size_t n = 0;
  fg_field *field = NULL;
  fg_trainer *t = NULL;
  char *next_path = fg_path_join(fg_scene_dir(scene), "field.next.fgc");
  int keep_partial = 0;
  if (!next_path) {
    job_fail(j, "out of memory");
    goto out;
  }

  set_phase(j, "loading");
  int rc = fg_scene_load_frames(scene, &frames, &indices, &n, should_stop, &rc_ud);
  if (rc == FG_ECANCELED) goto stopped;
  if (rc != 0) {
    job_fail(j, "cannot load the scene's frames: %s", fg_error_detail());
    goto out;
  }
  if (n == 0) {
    job_fail(j, "the scene has no frames; add some with POST /v1/scenes/%s/frames or .../import",
             j->info.scene);
    goto out;
  }
  /* ---- CLIP features for the frames that have none ---- */
  size_t need = clip ? fg_clip_features_needed(frames, n) : 0;
  if (need) {
    pthread_mutex_lock(&j->lock);
    snprintf(j->info.phase, sizeof j->info.phase, "features");
    j->info.features_total = (int)need;
    j->info.features_done = j->info.features_cached = 0;
    j->info.version++;
    pthread_mutex_unlock(&j->lock);
    double t0 = mono_s();
    rc = fg_clip_features_attach(clip, fg_scene_dir(scene), frames, indices, n, should_stop,
                                 on_features, &rc_ud);
    if (rc == FG_ECANCELED) goto stopped;
    if (rc != 0) {
      job_fail(j, "cannot give the frames CLIP features: %s", fg_error_detail());
      goto out;
    }
    pthread_mutex_lock(&j->lock);
    int cached = j->info.features_cached;
    pthread_mutex_unlock(&j->lock);
    fg_info("job %s: CLIP features of %zu frames (model %s): %zu computed, %d from the cache, "
            "in %.1f s", id, need, fg_clip_model_info(clip)->fingerprint, need - (size_t)cached,
            cached, mono_s() - t0);
  }
  fg_clip_model_release(clip);
  clip = NULL;
  int feature_dim = 0; /* the store keeps one D per scene; CLIP's E equals it (checked) */
  for (size_t i = 0; i < n && !feature_dim; i++) feature_dim = frames[i].feat_d;

  set_phase(j, "training");
  fg_scene_info si;
  fg_scene_get_info(scene, &si);
  fg_train_params p = j->info.params;
  fg_field_config cfg;
  if (fg_field_config_for_workspace(&cfg, si.params.workspace_min, si.params.workspace_max,
                                    FIELD_SCALE, feature_dim) != 0 ||
      fg_field_new(&field, &cfg, p.seed) != 0) {
    job_fail(j, "cannot set up the field: %s", fg_error_detail());
    goto out;
  }
  fg_train_opts opts;
  fg_train_opts_default(&opts);
  opts.n_threads = n_threads;
  opts.seed = p.seed;
  opts.holdout_every = p.holdout_every;
  for (int k = 0; k < 3; k++) opts.background[k] = (float)si.params.background[k];
  if (fg_trainer_new(&t, field, frames, n, &opts) != 0) {
    job_fail(j, "cannot start training: %s", fg_error_detail());
    goto out;
  }
  size_t n_heldout = fg_trainer_n_heldout(t);
  pthread_mutex_lock(&j->lock);
  j->info.n_frames = (int)n;
  j->info.n_heldout = (int)n_heldout;
  j->info.version++;
  pthread_mutex_unlock(&j->lock);
  fg_info("job %s: training scene %s on %zu frames (%zu held out), %d threads", id,
          j->info.scene, n, n_heldout, n_threads);

  /* ---- the loop ---- */
  double t_start = j->started_mono, t_loop = mono_s();
  double last_eval = t_loop, last_ckpt = t_loop;
  int64_t step = 0;
  for (; step < p.steps; ) {
    if (should_stop(&rc_ud)) goto stopped;
    double t0 = mono_s();
    if (p.max_seconds > 0 && t0 - t_start >= p.max_seconds) break;
    fg_train_stats st;
    rc = fg_trainer_step(t, &st);
    double t1 = mono_s();
    if (rc != 0) {
      job_fail(j, "training stopped at step %lld: %s%s", (long long)step, fg_error_detail(),
               rc == FG_ERANGE ? "; try another seed" : "");
      goto out;
    }
    step++;
    fg_metrics_add_training_steps(1);
    double sps = t1 > t0 ? (double)st.samples / (t1 - t0) : NAN;
    if (isfinite(sps)) fg_metrics_set_training_samples_per_s(sps);
    double elapsed = t1 - t_start, per_step = (t1 - t_loop) / (double)step;
    double eta = per_step * (double)(p.steps - step);
    if (p.max_seconds > 0 && p.max_seconds - elapsed < eta) eta = fmax(0, p.max_seconds - elapsed);
    double psnr = NAN;
    if (n_heldout > 0 && t1 - last_eval >= FG_TRAIN_EVAL_SECONDS) {
      if (fg_trainer_eval(t, 0, &psnr) != 0) psnr = NAN;
      last_eval = mono_s();
    }
    pthread_mutex_lock(&j->lock);
    j->info.step = step;
    j->info.loss = st.loss;
    j->info.samples_per_s = sps;
    j->info.elapsed_s = elapsed;
    j->info.eta_s = eta;
    if (isfinite(psnr)) {
      j->info.psnr = psnr;
      j->info.psnr_full = 0;
    }
    j->info.version++;
    pthread_mutex_unlock(&j->lock);
    if (mono_s() - last_ckpt >= FG_TRAIN_CHECKPOINT_SECONDS) {
      if (fg_checkpoint_save(field, next_path, half) == 0) {
        fg_debug("job %s: partial checkpoint at step %lld", id, (long long)step);
      } else {
        fg_warn("job %s: cannot write the partial checkpoint %s: %s", id, next_path,
                fg_error_detail());
      }
      last_ckpt = mono_s();
    }
  }

  /* ---- the end: PSNR over every held-out pixel when that is cheap, then commit ---- */
  if (n_heldout > 0) {
    double psnr = NAN, t0 = mono_s();
    if (fg_trainer_eval(t, 0, &psnr) != 0) psnr = NAN;
    double sampled_s = mono_s() - t0;
    double px = heldout_pixels(frames, n, p.holdout_every);
    double est_full = px > 0 ? sampled_s * px / fmin(px, 16384.0) : INFINITY;
    int full = 0;
    if (est_full < 0.1 * (mono_s() - t_loop) && !should_stop(&rc_ud)) {
      double psnr_full = NAN;
      if (fg_trainer_eval(t, 1, &psnr_full) == 0 && isfinite(psnr_full)) {
        psnr = psnr_full;
        full = 1;
      }
    }
    pthread_mutex_lock(&j->lock);
    if (isfinite(psnr)) {
      j->info.psnr = psnr;
      j->info.psnr_full = full;
    }
    j->info.version++;
    pthread_mutex_unlock(&j->lock);
  }
  if (should_stop(&rc_ud)) goto stopped;
  set_phase(j, "saving");
  if (fg_checkpoint_save(field, next_path, half) != 0) {
    job_fail(j, "cannot save the trained field: %s", fg_error_detail());
    goto out;
  }
  /* From here on a DELETE is too late: the job installs its result. */
  pthread_mutex_lock(&j->lock);
  int cancelled = j->cancel;
  if (!cancelled) j->committing = 1;
  pthread_mutex_unlock(&j->lock);
  if (cancelled) goto stopped;
  rc = fg_scene_commit_field(scene, field, next_path);
  if (rc == FG_ENOENT) { /* the scene was deleted meanwhile */
    pthread_mutex_lock(&j->lock);
    j->info.state = FG_JOB_CANCELLED;
    j->info.finished_ms = now_ms();
    j->info.version++;
    pthread_mutex_unlock(&j->lock);
    goto out;
  }
  if (rc != 0) {
    pthread_mutex_lock(&j->lock);
    j->committing = 0;
    pthread_mutex_unlock(&j->lock);
    job_fail(j, "cannot install the trained field: %s", fg_error_detail());
    goto out;
  }
  field = NULL; /* the scene's now */
  pthread_mutex_lock(&j->lock);
  j->info.state = FG_JOB_DONE;
  j->info.step = step;
  j->info.eta_s = 0;
  j->info.elapsed_s = mono_s() - j->started_mono;
  j->info.finished_ms = now_ms();
  j->info.version++;
  pthread_mutex_unlock(&j->lock);
  fg_info("job %s: done: scene %s trained for %lld steps in %.1f s", id, j->info.scene,
          (long long)step, j->info.elapsed_s);
  goto out;

stopped:
  pthread_mutex_lock(&j->lock);
  int was_cancelled = j->cancel || j->info.state == FG_JOB_CANCELLED;
  pthread_mutex_unlock(&j->lock);
  if (!was_cancelled) {
    /* The daemon is stopping: keep what was learnt as the partial checkpoint; the job stays
     * "running" on disk and the next start reports it interrupted. */
    keep_partial = 1;
    if (field && t && field->trained_steps > 0) {
      if (fg_checkpoint_save(field, next_path, half) == 0)
        fg_info("job %s: interrupted by the shutdown after %lld steps; its field is kept as "
                "field.next.fgc", id, (long long)field->trained_steps);
      else
        fg_warn("job %s: cannot save field.next.fgc at shutdown: %s", id, fg_error_detail());
    }
  } else {
    fg_info("job %s: stopped (cancelled); the scene's field is as it was", id);
  }

out:
  if (next_path && !keep_partial) {
    pthread_mutex_lock(&j->lock);
    int done = j->info.state == FG_JOB_DONE;
    pthread_mutex_unlock(&j->lock);
    if (!done && unlink(next_path) == 0) fg_debug("job %s: removed %s", id, next_path);
  }
  fg_trainer_free(t);
  fg_field_free(field);
  fg_scene_frames_free(frames, n);
  free(indices);
  fg_clip_model_release(clip);
  free(next_path);
}

/* ---------------------------------------------------------------- the worker */

static void *worker_main(void *arg) {
  fg_jobs *jobs = arg;
  pthread_setname_np(pthread_self(), "fg-train");
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
      j->info.started_ms = now_ms();
      j->started_mono = mono_s();
      j->info.version++;
    }
    pthread_mutex_unlock(&j->lock);
    if (go) {
      persist(jobs, j);
      fg_info("job %s: training of scene %s started", j->info.id, j->info.scene);
      run_training(jobs, j);
      persist(jobs, j);
      /* The job is over: its scene may go (the reference kept it alive while it ran). */
      pthread_mutex_lock(&j->lock);
      fg_scene *scene = fg_job_state_finished(j->info.state) ? j->scene : NULL;
      if (scene) j->scene = NULL;
      pthread_mutex_unlock(&j->lock);
      if (scene) fg_scene_unref(scene);
      /* Training's buffers (hundreds of MB) are free now; hand them back to the system. */
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
  if (!o || info_from_json(o, &info) != 0) {
    fg_warn("scene %s: %s is unreadable and is ignored: %s", fg_scene_name(scene), path,
            o ? fg_error_detail() : jerr.text);
    json_decref(o);
    free(path);
    return;
  }
  json_decref(o);
  free(path);
  snprintf(info.scene, sizeof info.scene, "%s", fg_scene_name(scene));
  fg_job *j = job_new();
  if (!j) return;
  int interrupted = !fg_job_state_finished(info.state);
  if (interrupted) {
    fg_info("job %s of scene %s was %s when the daemon stopped; it is reported failed", info.id,
            info.scene, fg_job_state_name(info.state));
    info.state = FG_JOB_FAILED;
    snprintf(info.error, sizeof info.error, "interrupted by a daemon restart");
    info.eta_s = NAN;
    if (!info.finished_ms) info.finished_ms = now_ms();
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
