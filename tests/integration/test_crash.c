/* Crash consistency: fieldgripd is killed with SIGKILL at 20 random moments, spread over frame
 * uploads, imports, trainings, the save at a training's end, demo recording and task, demo
 * and scene deletion, and restarted each time on the same state dir. After every restart:
 *  - the daemon starts cleanly (nothing left out or unreadable, no temp file, no undone
 *    delete), and every scene's listing agrees with its frame files, each of which loads
 *    whole;
 *  - every acknowledged frame (a 2xx reply received before the kill) is there, bit for bit;
 *    every acknowledged import is there whole; every acknowledged demo is there as it was
 *    answered, and every acknowledged deletion holds;
 *  - the field of the last training seen `done` loads and renders, and its job still reads
 *    `done`;
 *  - the one operation in flight at the kill is either wholly there or wholly absent (an
 *    import: all of its frames or none).
 * The moments come from a seed, printed at the start; FG_CRASH_SEED=<seed> replays the same
 * choices (the timing of a loaded machine still varies). A random delay, not a wait for a
 * state, places each kill: that is the point of the test; every other wait polls a state. */
#include <dirent.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <time.h>
#include <unistd.h>

#include "crash_util.h"
#include "grasp_util.h"

#define ROUNDS 20
#define MAX_OPS 1024
#define N_QP 16 /* query points of the demos */

enum { K_UPLOAD, K_IMPORT, K_TRAIN, K_SAVE, K_DEMO, K_DELETE, N_KINDS };
static const char *const kind_names[N_KINDS] = {"frame upload", "import", "training",
                                                "checkpoint save", "demo recording",
                                                "deletion"};
/* How many of the 20 rounds kill during each kind; trainings cost the most time. */
static const int kind_rounds[N_KINDS] = {4, 3, 3, 3, 4, 3};

/* What the test knows of one operation. */
enum { OP_NONE = 0, OP_ACKED, OP_UNKNOWN, OP_ABSENT };

/* ---------------------------------------------------------------------------------------- */
/* Random moments                                                                            */

static uint64_t g_rng;

static uint64_t rnd_u64(void) { /* splitmix64 */
  uint64_t z = (g_rng += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

/* A whole number in [lo, hi]. */
static int rnd_int(int lo, int hi) { return lo + (int)(rnd_u64() % (uint64_t)(hi - lo + 1)); }

/* ---------------------------------------------------------------------------------------- */
/* The model: every operation sent and what its reply said                                   */

typedef struct up_op { /* a frame upload to scene "up" */
  unsigned seed;
  int state;
  long long index;
} up_op;

typedef struct import_op { /* an import of the data set into scene "imp" */
  int state;
  long long first; /* its first frame's number, once known */
} import_op;

typedef struct demo_op { /* a demo added to a task, and maybe deleted again */
  char task[32];
  const char *object;
  int state;     /* of the POST */
  int id;        /* once known */
  json_t *reply; /* the demo as the 201 (or, when it was in flight, the listing) showed it */
  int del;       /* OP_NONE, or the state of its DELETE */
} demo_op;

typedef struct name_op { /* a task or scene and its deletion */
  char name[32];
  int del;
} name_op;

static up_op g_up[MAX_OPS];
static int g_n_up;
static import_op g_imp[64];
static int g_n_imp;
static demo_op g_demo[MAX_OPS];
static int g_n_demo;
static name_op g_tasks[64], g_scenes[64];
static int g_n_tasks, g_n_scenes;
static json_t *g_imp_ref; /* the listing entries of the first import, as the reference */
static size_t g_n_views;

/* Trainings of scene "tr": the steps of the field the test knows is installed, the last job
 * seen done, and a training that was under way at the kill. */
static long long g_tr_steps;
static char g_tr_job[64];
static char g_unk_job[64];
static char g_last_job[64], g_last_state[16]; /* the scene's last job and its state */
static long long g_unk_steps;
static double g_step_s, g_save_s, g_import_s; /* measured while setting up */
static int g_render = 1; /* render scene tr at the next check */
static unsigned g_next_seed = 1;

static int ok_reply(const h_resp *r, long status) {
  return r->status == status && r->curl_rc == 0 && r->json;
}

/* A reply that is neither the expected success nor a cut connection fails the test. */
static int op_result(const h_resp *r, long status, const char *what) {
  if (ok_reply(r, status)) return OP_ACKED;
  if (r->status == 0 || r->curl_rc != 0) return OP_UNKNOWN;
  FG_TEST_FAIL("%s: HTTP %ld (expected %ld): %.1000s", what, r->status, status, r->body);
}

/* ---------------------------------------------------------------------------------------- */
/* Workers: one stream of operations while the main thread picks the moment to kill          */

typedef struct worker {
  pthread_t th;
  atomic_int stop;
  atomic_int acked; /* operations answered so far */
  int round;
  void *(*fn)(void *);
} worker;

static void *upload_worker(void *arg) {
  worker *w = arg;
  while (!atomic_load(&w->stop)) {
    up_op *op = &g_up[g_n_up++];
    ASSERT(g_n_up < MAX_OPS);
    op->seed = g_next_seed++;
    op->state = OP_UNKNOWN;
    h_resp *r = cu_upload("up", op->seed);
    op->state = op_result(r, 201, "upload");
    if (op->state == OP_ACKED) op->index = JINT(r->json, "frame");
    h_resp_free(r);
    if (op->state != OP_ACKED) break;
    atomic_fetch_add(&w->acked, 1);
  }
  return NULL;
}

static void *import_worker(void *arg) {
  worker *w = arg;
  while (!atomic_load(&w->stop)) {
    import_op *op = &g_imp[g_n_imp++];
    ASSERT(g_n_imp < 64);
    op->state = OP_UNKNOWN;
    h_resp *r = g_import("imp", NULL);
    op->state = op_result(r, 200, "import");
    if (op->state == OP_ACKED) op->first = JINT(r->json, "frames.0");
    h_resp_free(r);
    if (op->state != OP_ACKED) break;
    atomic_fetch_add(&w->acked, 1);
  }
  return NULL;
}

static const char *const objects[] = {"ball", "box", "mug", "bowl"};

/* Sends one demo of an object's ground-truth grasp to task; records it. */
static int post_demo(const char *task) {
  demo_op *op = &g_demo[g_n_demo++];
  ASSERT(g_n_demo < MAX_OPS);
  snprintf(op->task, sizeof op->task, "%s", task);
  op->object = objects[g_n_demo % 4]; /* not the seeded generator: workers run concurrently */
  op->state = OP_UNKNOWN;
  char qp[64];
  snprintf(qp, sizeof qp, "{\"n\": %d, \"std\": 0.02}", N_QP);
  char *body = g_demo_body_qp("tr", op->object, qp, "");
  char *path = h_fmt("/v1/tasks/%s/demos", task);
  h_resp *r = h_post_json(path, body);
  op->state = op_result(r, 201, "demo");
  if (op->state == OP_ACKED) {
    op->id = (int)JINT(r->json, "demo.id");
    op->reply = json_incref(JGET(r->json, "demo"));
  }
  h_resp_free(r);
  free(path);
  free(body);
  return op->state;
}

static name_op *add_name(name_op *list, int *n, const char *name) {
  ASSERT(*n < 64);
  name_op *t = &list[(*n)++];
  snprintf(t->name, sizeof t->name, "%s", name);
  t->del = OP_NONE;
  return t;
}

static void *demo_worker(void *arg) {
  worker *w = arg;
  /* The first demo of a new task creates its folder; the others go to "pick". */
  char task[32];
  snprintf(task, sizeof task, "n%d", w->round);
  add_name(g_tasks, &g_n_tasks, task);
  for (int i = 0; !atomic_load(&w->stop); i++) {
    if (post_demo(i == 0 ? task : "pick") != OP_ACKED) break;
    atomic_fetch_add(&w->acked, 1);
  }
  return NULL;
}

/* Deletions prepared by the round (see round_delete), in a random order. */
typedef struct del_item {
  int kind; /* 0 demo, 1 task, 2 scene */
  int index;
} del_item;
static del_item g_dels[64];
static int g_n_dels;

static void *delete_worker(void *arg) {
  worker *w = arg;
  for (int i = 0; i < g_n_dels && !atomic_load(&w->stop); i++) {
    del_item *d = &g_dels[i];
    char *path;
    int *state;
    if (d->kind == 0) {
      demo_op *op = &g_demo[d->index];
      path = h_fmt("/v1/tasks/%s/demos/%d", op->task, op->id);
      state = &op->del;
    } else if (d->kind == 1) {
      path = h_fmt("/v1/tasks/%s", g_tasks[d->index].name);
      state = &g_tasks[d->index].del;
    } else {
      path = h_fmt("/v1/scenes/%s", g_scenes[d->index].name);
      state = &g_scenes[d->index].del;
    }
    *state = OP_UNKNOWN;
    h_resp *r = h_delete(path);
    *state = op_result(r, 200, path);
    int acked = *state == OP_ACKED;
    h_resp_free(r);
    free(path);
    if (!acked) break;
    atomic_fetch_add(&w->acked, 1);
  }
  return NULL;
}

static void worker_start(worker *w, void *(*fn)(void *), int round) {
  atomic_init(&w->stop, 0);
  atomic_init(&w->acked, 0);
  w->round = round;
  ASSERT_EQ(pthread_create(&w->th, NULL, fn, w), 0);
}

/* Waits until the worker has had `acked` answers (or has ended). */
static void worker_wait(worker *w, int acked) {
  double deadline = t_now() + 120;
  while (atomic_load(&w->acked) < acked) {
    if (t_now() > deadline) FG_TEST_FAIL("the worker had %d answers in 120 s, waited for %d",
                                         atomic_load(&w->acked), acked);
    h_sleep_ms(2);
  }
}

/* SIGKILL now. A worker's request in flight sees its connection cut; no new one starts. */
static void kill_now(worker *w) {
  if (w) atomic_store(&w->stop, 1);
  h_signal(SIGKILL);
  if (w) ASSERT_EQ(pthread_join(w->th, NULL), 0);
  h_kill(); /* reaps it */
}

/* ---------------------------------------------------------------------------------------- */
/* Rounds: each sets an operation going and kills at a random moment of it                   */

static void round_upload(int r) {
  worker w;
  int acks = rnd_int(0, 3), delay_ms = rnd_int(0, 40);
  printf("round %d: kill after %d acknowledged uploads + %d ms\n", r + 1, acks, delay_ms);
  worker_start(&w, upload_worker, r);
  worker_wait(&w, acks);
  h_sleep_ms(delay_ms);
  kill_now(&w);
}

static void round_import(int r) {
  worker w;
  int delay_ms = rnd_int(0, (int)(1300 * g_import_s) + 5);
  printf("round %d: kill %d ms into the imports (one takes about %.0f ms)\n", r + 1, delay_ms,
         1000 * g_import_s);
  worker_start(&w, import_worker, r);
  h_sleep_ms(delay_ms);
  kill_now(&w);
}

/* Starts a training of "tr" whose step count differs from the installed field's, so that the
 * scene tells after the restart which field it holds. */
static char *start_training(long long *steps) {
  *steps = g_tr_steps == 2 ? 3 : 2;
  char *body = h_fmt("{\"steps\": %lld}", *steps);
  char *id = t_train("tr", body);
  free(body);
  snprintf(g_unk_job, sizeof g_unk_job, "%s", id);
  g_unk_steps = *steps;
  return id;
}

/* The job's state now; records a training seen done. */
static int job_seen_done(const char *id, long long steps, char *phase, size_t phase_len) {
  json_t *j = t_job(id);
  const char *st = JSTR(j, "state");
  if (strcmp(st, "failed") == 0 || strcmp(st, "cancelled") == 0)
    FG_TEST_FAIL("training %s ended %s: %s", id, st, json_dumps(j, JSON_COMPACT));
  int done = strcmp(st, "done") == 0;
  json_t *ph = json_object_get(j, "phase");
  if (phase) snprintf(phase, phase_len, "%s", json_is_string(ph) ? json_string_value(ph) : "");
  json_decref(j);
  if (done) {
    snprintf(g_tr_job, sizeof g_tr_job, "%s", id);
    snprintf(g_last_job, sizeof g_last_job, "%s", id);
    snprintf(g_last_state, sizeof g_last_state, "done");
    g_tr_steps = steps;
    g_unk_job[0] = '\0';
  }
  return done;
}

static void round_train(int r) {
  long long steps;
  char *id = start_training(&steps);
  int delay_ms = rnd_int(0, (int)(1000 * g_step_s * (double)steps));
  printf("round %d: kill %d ms into a training of %lld steps (job %s)\n", r + 1, delay_ms,
         steps, id);
  g_render = 1;
  double deadline = t_now() + 120;
  for (;;) { /* running (or, on a fast machine, done already) */
    json_t *j = t_job(id);
    int queued = strcmp(JSTR(j, "state"), "queued") == 0;
    json_decref(j);
    if (!queued) break;
    if (t_now() > deadline) FG_TEST_FAIL("job %s did not start in 120 s", id);
    h_sleep_ms(5);
  }
  h_sleep_ms(delay_ms);
  job_seen_done(id, steps, NULL, 0);
  kill_now(NULL);
  free(id);
}

static void round_save(int r) {
  long long steps;
  char *id = start_training(&steps);
  /* Half of these kills land at a random moment of the save; the other half right after the
   * job is first seen done, where the field and the job's state must already be on disk. */
  int at_done = rnd_int(0, 1), delay_ms = rnd_int(0, (int)(1000 * g_save_s) + 5);
  g_render = 1;
  if (at_done)
    printf("round %d: kill as soon as job %s is seen done\n", r + 1, id);
  else
    printf("round %d: kill %d ms after the save of job %s began\n", r + 1, delay_ms, id);
  char phase[32] = "";
  double deadline = t_now() + 300;
  int done = 0;
  while (!(done = job_seen_done(id, steps, phase, sizeof phase)) &&
         (at_done || strcmp(phase, "saving") != 0)) {
    if (t_now() > deadline) FG_TEST_FAIL("job %s did not reach its save in 300 s", id);
    h_sleep_ms(at_done ? 1 : 2);
  }
  if (!at_done) {
    h_sleep_ms(delay_ms);
    job_seen_done(id, steps, NULL, 0);
  }
  kill_now(NULL);
  free(id);
}

static void round_demo(int r) {
  worker w;
  int acks = rnd_int(0, 2), delay_ms = rnd_int(0, 30);
  printf("round %d: kill after %d acknowledged demos + %d ms\n", r + 1, acks, delay_ms);
  worker_start(&w, demo_worker, r);
  worker_wait(&w, acks);
  h_sleep_ms(delay_ms);
  kill_now(&w);
}

static int live_demos(const char *task) {
  int n = 0;
  for (int i = 0; i < g_n_demo; i++)
    n += strcmp(g_demo[i].task, task) == 0 && g_demo[i].state == OP_ACKED && !g_demo[i].del;
  return n;
}

static void round_delete(int r) {
  /* Something to delete: a scene with a frame, and demos of "pick" beyond the one kept. */
  char name[32];
  snprintf(name, sizeof name, "gone%d", r);
  char *body = h_fmt("{\"name\": \"%s\"}", name);
  h_resp *resp = h_post_json("/v1/scenes", body);
  ASSERT_STATUS(resp, 201);
  h_resp_free(resp);
  free(body);
  name_op *sc = add_name(g_scenes, &g_n_scenes, name);
  resp = cu_upload(name, g_next_seed++);
  ASSERT_STATUS(resp, 201);
  h_resp_free(resp);
  while (live_demos("pick") < 3) ASSERT_EQ(post_demo("pick"), OP_ACKED);

  g_n_dels = 0;
  g_dels[g_n_dels++] = (del_item){2, (int)(sc - g_scenes)};
  for (int i = 0; i < g_n_tasks; i++) /* tasks that exist: a first demo made them */
    if (strcmp(g_tasks[i].name, "pick") != 0 && !g_tasks[i].del && live_demos(g_tasks[i].name) &&
        g_n_dels < 64)
      g_dels[g_n_dels++] = (del_item){1, i};
  int keep = 1; /* "pick" keeps one demo */
  for (int i = 0; i < g_n_demo && g_n_dels < 64; i++)
    if (strcmp(g_demo[i].task, "pick") == 0 && g_demo[i].state == OP_ACKED && !g_demo[i].del) {
      if (keep-- > 0) continue;
      g_dels[g_n_dels++] = (del_item){0, i};
    }
  for (int i = g_n_dels - 1; i > 0; i--) { /* a random order */
    int j = rnd_int(0, i);
    del_item t = g_dels[i];
    g_dels[i] = g_dels[j];
    g_dels[j] = t;
  }
  worker w;
  int acks = rnd_int(0, g_n_dels - 1), delay_ms = rnd_int(0, 10);
  printf("round %d: kill after %d of %d acknowledged deletions + %d ms\n", r + 1, acks, g_n_dels,
         delay_ms);
  worker_start(&w, delete_worker, r);
  worker_wait(&w, acks);
  h_sleep_ms(delay_ms);
  kill_now(&w);
}

/* ---------------------------------------------------------------------------------------- */
/* Checks after a restart                                                                    */

static json_t *find_by(json_t *arr, const char *key, const char *value) {
  for (size_t i = 0; i < json_array_size(arr); i++) {
    json_t *v = json_object_get(json_array_get(arr, i), key);
    if (json_is_string(v) && strcmp(json_string_value(v), value) == 0)
      return json_array_get(arr, i);
  }
  return NULL;
}

static void verify_scenes(void) {
  h_resp *r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  json_t *list = JGET(r->json, "scenes");
  static const char *const fixed[] = {"up", "tr", "imp"};
  size_t expected = 3;
  for (int i = 0; i < 3; i++)
    if (!find_by(list, "name", fixed[i])) FG_TEST_FAIL("scene %s is gone", fixed[i]);
  for (int i = 0; i < g_n_scenes; i++) {
    name_op *s = &g_scenes[i];
    int listed = find_by(list, "name", s->name) != NULL;
    if (s->del == OP_UNKNOWN) s->del = listed ? OP_NONE : OP_ACKED;
    if (s->del == OP_ACKED && listed) FG_TEST_FAIL("deleted scene %s is back", s->name);
    if (s->del == OP_NONE && !listed) FG_TEST_FAIL("scene %s is gone, never deleted", s->name);
    if (s->del == OP_NONE) {
      json_t *frames = cu_check_scene_files(s->name);
      ASSERT_EQ(json_array_size(frames), 1);
      json_decref(frames);
      expected++;
    }
  }
  if (json_array_size(list) != expected) {
    char *s = json_dumps(list, JSON_COMPACT);
    FG_TEST_FAIL("%zu scenes listed, expected %zu: %.2000s", json_array_size(list), expected, s);
  }
  h_resp_free(r);
}

static void verify_uploads(void) {
  json_t *frames = cu_check_scene_files("up");
  size_t n = json_array_size(frames), matched = 0;
  for (int i = 0; i < g_n_up; i++) {
    up_op *op = &g_up[i];
    if (op->state != OP_ACKED && op->state != OP_UNKNOWN) continue;
    json_t *e = find_by(frames, "source", cu_source(op->seed));
    if (op->state == OP_UNKNOWN) { /* in flight at the kill: there whole, or not at all */
      op->state = e ? OP_ACKED : OP_ABSENT;
      if (e) op->index = JINT(e, "frame");
    }
    if (op->state == OP_ABSENT) continue;
    if (!e) FG_TEST_FAIL("acknowledged upload %s (frame %lld) is gone", cu_source(op->seed),
                         op->index);
    ASSERT_EQ(JINT(e, "frame"), op->index);
    cu_check_upload("up", e, op->seed);
    matched++;
  }
  if (matched != n) {
    char *s = json_dumps(frames, JSON_COMPACT);
    FG_TEST_FAIL("scene up lists %zu frames, but only %zu uploads made them: %.3000s", n, matched,
                 s);
  }
  json_decref(frames);
}

static void verify_imports(void) {
  json_t *frames = cu_check_scene_files("imp");
  size_t n = json_array_size(frames), v = g_n_views;
  if (n % v != 0) FG_TEST_FAIL("scene imp has %zu frames, not whole imports of %zu", n, v);
  size_t blocks = n / v, known = 0, unknown = 0;
  /* Each import is the data set in file order, at consecutive numbers. */
  for (size_t b = 0; b < blocks; b++) {
    long long first = JINT(json_array_get(frames, b * v), "frame");
    for (size_t j = 0; j < v; j++) {
      json_t *e = json_array_get(frames, b * v + j), *ref = json_array_get(g_imp_ref, j);
      ASSERT_EQ(JINT(e, "frame"), first + (long long)j);
      ASSERT_JSON_EQUAL(JGET(e, "source"), JGET(ref, "source"));
      ASSERT_JSON_EQUAL(JGET(e, "transform_matrix"), JGET(ref, "transform_matrix"));
      ASSERT_JSON_EQUAL(JGET(e, "camera"), JGET(ref, "camera"));
      ASSERT_JSON_EQUAL(JGET(e, "features"), JGET(ref, "features"));
    }
  }
  for (int i = 0; i < g_n_imp; i++) {
    import_op *op = &g_imp[i];
    known += op->state == OP_ACKED;
    unknown += op->state == OP_UNKNOWN;
    if (op->state != OP_ACKED) continue;
    int found = 0;
    for (size_t b = 0; b < blocks; b++)
      found |= JINT(json_array_get(frames, b * v), "frame") == op->first;
    if (!found) FG_TEST_FAIL("acknowledged import at frame %lld is gone", op->first);
  }
  ASSERT(unknown <= 1);
  if (blocks != known && blocks != known + unknown)
    FG_TEST_FAIL("scene imp holds %zu imports; %zu were acknowledged and %zu was in flight",
                 blocks, known, unknown);
  for (int i = 0; i < g_n_imp; i++)
    if (g_imp[i].state == OP_UNKNOWN) {
      g_imp[i].state = blocks > known ? OP_ACKED : OP_ABSENT;
      g_imp[i].first = JINT(json_array_get(frames, (blocks - 1) * v), "frame");
    }
  json_decref(frames);
}

static void verify_training(void) {
  json_t *tr = cu_check_scene_files("tr");
  ASSERT_EQ(json_array_size(tr), g_n_views);
  json_decref(tr);
  json_t *s = t_scene_json("tr");
  if (!json_is_true(JGET(s, "trained")) || !json_is_false(JGET(s, "partial")) ||
      !json_is_null(JGET(s, "checkpoint_error")))
    FG_TEST_FAIL("scene tr after the restart: %s", json_dumps(s, JSON_COMPACT));
  long long steps = JINT(s, "trained_steps");
  const char *job = JSTR(s, "last_job.id"), *state = JSTR(s, "last_job.state");
  if (g_unk_job[0] && strcmp(job, g_unk_job) != 0 && strcmp(job, g_last_job) == 0) {
    /* Killed before the daemon wrote down that the training had started: wholly absent. */
    g_unk_job[0] = '\0';
  }
  if (g_unk_job[0]) { /* a training was under way at the kill */
    ASSERT_STREQ(job, g_unk_job);
    if (steps == g_unk_steps) { /* it installed its field: then it is done */
      if (strcmp(state, "done") != 0)
        FG_TEST_FAIL("scene tr holds the field of job %s (%lld steps), but the job reads %s",
                     job, steps, state);
      snprintf(g_tr_job, sizeof g_tr_job, "%s", g_unk_job);
      g_tr_steps = steps;
    } else if (strcmp(state, "failed") != 0) {
      FG_TEST_FAIL("job %s reads %s after the kill, but scene tr holds the field of %lld steps "
                   "before it", job, state, steps);
    }
    snprintf(g_last_job, sizeof g_last_job, "%s", job);
    snprintf(g_last_state, sizeof g_last_state, "%s", state);
    g_unk_job[0] = '\0';
  } else {
    ASSERT_STREQ(job, g_last_job);
    ASSERT_STREQ(state, g_last_state);
  }
  if (steps != g_tr_steps)
    FG_TEST_FAIL("scene tr's field has %lld steps; the last training seen done (%s) took %lld",
                 steps, g_tr_job, g_tr_steps);
  json_t *j = t_job(job);
  ASSERT_STREQ(JSTR(j, "state"), state);
  json_decref(j);
  json_decref(s);
  /* The field renders: after the rounds that may have changed it (a render of a freshly
   * loaded field costs a second or two on a busy machine). */
  if (!g_render) return;
  g_render = 0;
  static const double eye[3] = {0.45, -0.6, 0.5}, target[3] = {0.45, 0, 0.05};
  char *cam = t_camera(eye, target, 30, 32, 24);
  char *body = h_fmt("{\"camera\": %s}", cam);
  h_resp *r = t_render("tr", body);
  int w, h, bits, type;
  t_png_header(r, &w, &h, &bits, &type);
  ASSERT_EQ(w, 32);
  ASSERT_EQ(h, 24);
  h_resp_free(r);
  free(body);
  free(cam);
}

/* Demo files on disk: exactly those the task lists. */
static void check_demo_files(const char *task, json_t *demos) {
  for (size_t i = 0; i < json_array_size(demos); i++) {
    char *f = h_fmt("%s/tasks/%s/demo-%lld.npy", h_state_dir(), task,
                    JINT(json_array_get(demos, i), "id"));
    if (access(f, R_OK) != 0) FG_TEST_FAIL("%s is missing", f);
    free(f);
  }
  char *dir = h_fmt("%s/tasks/%s", h_state_dir(), task);
  DIR *d = opendir(dir);
  if (!d) FG_TEST_FAIL("cannot open %s", dir);
  size_t files = 0;
  struct dirent *de;
  while ((de = readdir(d)) != NULL) files += strncmp(de->d_name, "demo-", 5) == 0;
  closedir(d);
  if (files != json_array_size(demos))
    FG_TEST_FAIL("%s holds %zu demo files for %zu demos", dir, files, json_array_size(demos));
  free(dir);
}

static void verify_task(name_op *t) {
  char *path = h_fmt("/v1/tasks/%s", t->name);
  h_resp *r = h_get(path);
  free(path);
  if (r->status != 404) ASSERT_STATUS(r, 200);
  int listed = r->status == 200;
  if (t->del == OP_UNKNOWN) t->del = listed ? OP_NONE : OP_ACKED;
  if (t->del == OP_ACKED && listed) FG_TEST_FAIL("deleted task %s is back", t->name);
  json_t *demos = listed ? JGET(r->json, "demos") : NULL;
  size_t matched = 0;
  for (int i = 0; i < g_n_demo; i++) {
    demo_op *op = &g_demo[i];
    if (strcmp(op->task, t->name) != 0) continue;
    if (t->del == OP_ACKED) { /* the task's deletion took its demos */
      if (op->state == OP_UNKNOWN) op->state = OP_ABSENT;
      if (op->state == OP_ACKED) op->del = OP_ACKED;
      continue;
    }
    json_t *e = NULL;
    if (op->state == OP_ACKED) {
      for (size_t k = 0; k < json_array_size(demos); k++)
        if (JINT(json_array_get(demos, k), "id") == op->id) e = json_array_get(demos, k);
    } else if (op->state == OP_UNKNOWN) { /* the demo in flight: an id no other demo has */
      for (size_t k = 0; k < json_array_size(demos) && !e; k++) {
        int id = (int)JINT(json_array_get(demos, k), "id"), known = 0;
        for (int m = 0; m < g_n_demo; m++)
          known |= g_demo[m].state == OP_ACKED && g_demo[m].id == id &&
                   strcmp(g_demo[m].task, t->name) == 0;
        if (!known) e = json_array_get(demos, k);
      }
      op->state = e ? OP_ACKED : OP_ABSENT;
      if (e) {
        op->id = (int)JINT(e, "id");
        op->reply = json_incref(e);
        ASSERT_STREQ(JSTR(e, "scene"), "tr");
        double p[3];
        for (int k = 0; k < 3; k++) {
          char key[32];
          snprintf(key, sizeof key, "grasp.position.%d", k);
          p[k] = JNUM(g_object(op->object), key);
        }
        ASSERT_VEC(JGET(e, "pose.position"), p, 3, 1e-9);
      }
    }
    if (op->state != OP_ACKED) continue;
    if (op->del == OP_UNKNOWN) op->del = e ? OP_NONE : OP_ACKED;
    if (op->del == OP_ACKED && e)
      FG_TEST_FAIL("demo %d of task %s is back after its deletion", op->id, t->name);
    if (op->del == OP_NONE && !e)
      FG_TEST_FAIL("acknowledged demo %d of task %s is gone", op->id, t->name);
    if (e) {
      ASSERT_JSON_EQUAL(e, op->reply);
      matched++;
    }
  }
  if (listed) {
    if (matched != json_array_size(demos))
      FG_TEST_FAIL("task %s lists %zu demos, %zu of them known: %s", t->name,
                   json_array_size(demos), matched, r->body);
    check_demo_files(t->name, demos);
  } else if (t->del != OP_ACKED) {
    /* Never listed: only a task whose first demo was cut off may be missing. */
    for (int i = 0; i < g_n_demo; i++)
      if (strcmp(g_demo[i].task, t->name) == 0 && g_demo[i].state == OP_ACKED)
        FG_TEST_FAIL("task %s is gone, never deleted", t->name);
  }
  h_resp_free(r);
}

static void verify_tasks(void) {
  for (int i = 0; i < g_n_tasks; i++) verify_task(&g_tasks[i]);
  h_resp *r = h_get("/v1/tasks");
  ASSERT_STATUS(r, 200);
  json_t *list = JGET(r->json, "tasks");
  for (size_t i = 0; i < json_array_size(list); i++) {
    const char *name = JSTR(json_array_get(list, i), "name");
    int known = 0;
    for (int k = 0; k < g_n_tasks; k++)
      known |= strcmp(g_tasks[k].name, name) == 0 && g_tasks[k].del == OP_NONE;
    if (!known) FG_TEST_FAIL("task %s is listed, but it was deleted or never made", name);
  }
  h_resp_free(r);
}

static void restart_and_verify(void) {
  size_t from = cu_log_size();
  h_start();
  cu_check_clean_start(from);
  cu_check_no_leftovers();
  verify_scenes();
  verify_uploads();
  verify_imports();
  verify_training();
  verify_tasks();
}

/* ---------------------------------------------------------------------------------------- */
/* Set-up                                                                                    */

static void setup(const char *scenegen) {
  char *imports = g_dataset(scenegen);
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = 2\nhalf_precision = "
                     "true\n", imports);
  h_write_config(conf);
  free(conf);
  free(imports);
  h_start();
  g_scene("tr", NULL);
  static const char *const names[] = {"up", "imp"};
  for (int i = 0; i < 2; i++) {
    char *body = h_fmt("{\"name\": \"%s\"}", names[i]);
    h_resp *r = h_post_json("/v1/scenes", body);
    ASSERT_STATUS(r, 201);
    h_resp_free(r);
    free(body);
  }

  /* One import, timed, as the reference of what an import holds. */
  double t0 = t_now();
  h_resp *r = g_import("imp", NULL);
  ASSERT_STATUS(r, 200);
  g_import_s = t_now() - t0;
  g_imp[g_n_imp++] = (import_op){OP_ACKED, JINT(r->json, "frames.0")};
  h_resp_free(r);
  r = h_get("/v1/scenes/imp/frames");
  ASSERT_STATUS(r, 200);
  g_imp_ref = json_incref(JGET(r->json, "frames"));
  g_n_views = json_array_size(g_imp_ref);
  ASSERT_EQ(g_n_views, G_VIEWS);
  h_resp_free(r);

  /* The first training of "tr", timed: its steps and its save. */
  char *id = t_train("tr", "{\"steps\": 3}");
  double run_s = 0, save_s = 0, deadline = t_now() + 600;
  char phase[32] = "";
  for (;;) {
    json_t *j = t_job(id);
    const char *st = JSTR(j, "state");
    json_t *ph = json_object_get(j, "phase");
    snprintf(phase, sizeof phase, "%s", json_is_string(ph) ? json_string_value(ph) : "");
    if (strcmp(st, "running") == 0 && run_s == 0) run_s = t_now();
    if (strcmp(phase, "saving") == 0 && save_s == 0) save_s = t_now();
    int done = strcmp(st, "done") == 0;
    if (!done && strcmp(st, "running") != 0 && strcmp(st, "queued") != 0)
      FG_TEST_FAIL("the first training ended %s", st);
    json_decref(j);
    if (done) break;
    if (t_now() > deadline) FG_TEST_FAIL("the first training took over 600 s");
    h_sleep_ms(5);
  }
  double end_s = t_now();
  if (save_s == 0) save_s = end_s;
  if (run_s == 0) run_s = save_s;
  g_step_s = (save_s - run_s) / 3;
  g_save_s = end_s - save_s;
  g_tr_steps = 3;
  snprintf(g_tr_job, sizeof g_tr_job, "%s", id);
  snprintf(g_last_job, sizeof g_last_job, "%s", id);
  snprintf(g_last_state, sizeof g_last_state, "done");
  free(id);
  printf("set-up: an import takes %.2f s, a training step %.2f s, its save %.2f s\n", g_import_s,
         g_step_s, g_save_s);

  add_name(g_tasks, &g_n_tasks, "pick");
  for (int i = 0; i < 2; i++) ASSERT_EQ(post_demo("pick"), OP_ACKED);
  for (int i = 0; i < 2; i++) {
    up_op *op = &g_up[g_n_up++];
    op->seed = g_next_seed++;
    h_resp *u = cu_upload("up", op->seed);
    ASSERT_STATUS(u, 201);
    op->state = OP_ACKED;
    op->index = JINT(u->json, "frame");
    h_resp_free(u);
  }
}

/* Rewrites scene tr's last_job.json as a training cut off while it installed its field. */
static void plant_committing_job(void) {
  char *path = h_fmt("%s/scenes/tr/last_job.json", h_state_dir());
  json_error_t e;
  json_t *o = json_load_file(path, 0, &e);
  if (!o) FG_TEST_FAIL("%s: %s", path, e.text);
  json_object_set_new(o, "state", json_string("running"));
  json_object_set_new(o, "committing", json_true());
  if (json_dump_file(o, path, 0) != 0) FG_TEST_FAIL("cannot write %s", path);
  json_decref(o);
  free(path);
}

static void copy_file(const char *from, const char *to) {
  size_t len;
  char *data = h_read_file(from, &len);
  if (!data) FG_TEST_FAIL("cannot read %s", from);
  h_write_file(to, data, len);
  free(data);
}

/* What a kill leaves at the narrowest moments, made by hand since a random kill seldom hits
 * them: an import cut off while its frames were renamed into place, and a training cut off
 * just before and just after the rename that installs its field. */
static void planted_crashes(void) {
  h_kill();
  char *dir = h_fmt("%s/scenes/imp/frames", h_state_dir());
  it_buf manifest = {0};
  for (size_t i = 0; i < g_n_views; i++) {
    char *line = h_fmt("%06zu.fgf\n", g_n_views + i);
    it_buf_add(&manifest, line, strlen(line));
    if (i < 5) { /* the first five made it */
      char *from = h_fmt("%s/%06zu.fgf", dir, i), *to = h_fmt("%s/%06zu.fgf", dir, g_n_views + i);
      copy_file(from, to);
      free(from);
      free(to);
    }
    free(line);
  }
  char *mpath = h_fmt("%s/.batch-4242-7", dir);
  h_write_file(mpath, manifest.p, manifest.n);
  free(mpath);
  free(manifest.p);
  free(dir);
  g_render = 1;
  /* Installed: field.next.fgc is gone, so the job is done. */
  plant_committing_job();
  restart_and_verify();

  /* Not installed: field.next.fgc is still there; the scene keeps its field, the job failed. */
  h_kill();
  plant_committing_job();
  char *fgc = h_fmt("%s/scenes/tr/field.fgc", h_state_dir());
  char *next = h_fmt("%s/scenes/tr/field.next.fgc", h_state_dir());
  copy_file(fgc, next);
  snprintf(g_unk_job, sizeof g_unk_job, "%s", g_tr_job);
  g_unk_steps = g_tr_steps + 1; /* not the installed field's */
  restart_and_verify();
  ASSERT_STREQ(g_last_state, "failed");
  if (access(next, F_OK) == 0) FG_TEST_FAIL("%s is still there after the start-up", next);
  free(fgc);
  free(next);
}

static uint64_t g_seed;
static int g_passed;

static void print_seed(void) {
  if (!g_passed) fprintf(stderr, "FAILED with seed %llu: FG_CRASH_SEED=%llu replays its choices\n",
                         (unsigned long long)g_seed, (unsigned long long)g_seed);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  const char *env = getenv("FG_CRASH_SEED");
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  g_seed = env && *env ? strtoull(env, NULL, 10)
                       : (uint64_t)ts.tv_sec * 1000003u ^ (uint64_t)ts.tv_nsec ^ (uint64_t)getpid();
  g_rng = g_seed;
  printf("seed %llu (FG_CRASH_SEED=%llu replays its choices)\n", (unsigned long long)g_seed,
         (unsigned long long)g_seed);
  atexit(print_seed);
  double start_s = t_now();
  setup(argv[2]);
  planted_crashes();

  /* The kinds of the rounds, in a random order. */
  int kinds[ROUNDS], n = 0;
  for (int k = 0; k < N_KINDS; k++)
    for (int i = 0; i < kind_rounds[k]; i++) kinds[n++] = k;
  ASSERT_EQ(n, ROUNDS);
  for (int i = ROUNDS - 1; i > 0; i--) {
    int j = rnd_int(0, i), t = kinds[i];
    kinds[i] = kinds[j];
    kinds[j] = t;
  }
  for (int r = 0; r < ROUNDS; r++) {
    printf("round %d of %d: SIGKILL during %s\n", r + 1, ROUNDS, kind_names[kinds[r]]);
    switch (kinds[r]) {
    case K_UPLOAD: round_upload(r); break;
    case K_IMPORT: round_import(r); break;
    case K_TRAIN: round_train(r); break;
    case K_SAVE: round_save(r); break;
    case K_DEMO: round_demo(r); break;
    default: round_delete(r); break;
    }
    restart_and_verify();
  }
  /* A clean stop and start at the end keep the same state. */
  h_stop();
  g_render = 1;
  restart_and_verify();
  h_stop();
  printf("ok: %d kills in %.1f s\n", ROUNDS, t_now() - start_s);
  g_passed = 1;
  h_done();
  return 0;
}
