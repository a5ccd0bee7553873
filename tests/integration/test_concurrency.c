/* Concurrency: 8 clients creating one scene at once get one 201 and seven 409; 8 clients
 * uploading 4 frames each to one scene at once get 32 distinct frame numbers 0..31, each
 * listed with the pose its client sent; and while an import of the lego data set runs,
 * /v1/health and the scene list keep answering, each within a second. */
#include <pthread.h>
#include <stdatomic.h>
#include <time.h>

#include "harness.h"

#define THREADS 8
#define PER_THREAD 4

typedef struct uploader {
  int id;
  int frames[PER_THREAD]; /* numbers the daemon gave */
} uploader;

/* The pose of upload (thread t, k-th): the translation encodes t and k. */
static void pose_of(int t, int k, double T[16]) {
  h_pose(T, 0.1 * t, 0.05 * k, -0.1, 0.01 * t, 0.1 * k, 0.5);
}

static void *upload_thread(void *arg) {
  uploader *u = arg;
  for (int k = 0; k < PER_THREAD; k++) {
    uint8_t *png, *npy;
    size_t png_len, npy_len;
    h_png(48, 36, 3, 8, (unsigned)(u->id * 10 + k), 0, &png, &png_len);
    static const int shape[3] = {3, 4, 8};
    h_npy("<f4", shape, 3, (unsigned)u->id, &npy, &npy_len);
    double T[16];
    pose_of(u->id, k, T);
    char *meta = h_meta(T, "opengl", 40, 24, 18, 48, 36);
    h_resp *r = h_upload("/v1/scenes/c/frames", png, png_len, meta, npy, npy_len);
    ASSERT_STATUS(r, 201);
    u->frames[k] = (int)JINT(r->json, "frame");
    h_resp_free(r);
    free(meta);
    free(png);
    free(npy);
  }
  return NULL;
}

static void test_parallel_uploads(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"c\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  pthread_t th[THREADS];
  uploader u[THREADS];
  for (int t = 0; t < THREADS; t++) {
    u[t].id = t;
    ASSERT_EQ(pthread_create(&th[t], NULL, upload_thread, &u[t]), 0);
  }
  for (int t = 0; t < THREADS; t++) ASSERT_EQ(pthread_join(th[t], NULL), 0);

  int owner[THREADS * PER_THREAD];
  for (int i = 0; i < THREADS * PER_THREAD; i++) owner[i] = -1;
  for (int t = 0; t < THREADS; t++)
    for (int k = 0; k < PER_THREAD; k++) {
      int n = u[t].frames[k];
      ASSERT(n >= 0 && n < THREADS * PER_THREAD);
      if (owner[n] != -1) FG_TEST_FAIL("frame number %d given twice", n);
      owner[n] = t * PER_THREAD + k;
      if (k > 0) ASSERT(n > u[t].frames[k - 1]); /* one client's uploads are in order */
    }

  r = h_get("/v1/scenes/c/frames");
  ASSERT_STATUS(r, 200);
  json_t *frames = JGET(r->json, "frames");
  ASSERT_EQ(json_array_size(frames), THREADS * PER_THREAD);
  for (int i = 0; i < THREADS * PER_THREAD; i++) {
    json_t *f = json_array_get(frames, (size_t)i);
    ASSERT_EQ(JINT(f, "frame"), i);
    double T[16];
    pose_of(owner[i] / PER_THREAD, owner[i] % PER_THREAD, T);
    ASSERT_MATRIX(JGET(f, "transform_matrix"), T, 1e-6);
    ASSERT_EQ(JINT(f, "features.d"), 8);
  }
  h_resp_free(r);
  r = h_get("/v1/scenes/c");
  ASSERT_EQ(JINT(r->json, "frames"), THREADS * PER_THREAD);
  ASSERT_EQ(JINT(r->json, "feature_dim"), 8);
  h_resp_free(r);
}

/* ---- /v1/health and the scene list while an import runs ---- */

/* An answer slower than this, even on a loaded two-core machine, waited for the import. */
#define PROBE_LIMIT_S 1.0
/* A probe that does not come back is cut off here, so that the test fails rather than hangs. */
#define PROBE_GIVE_UP_MS 5000
/* Health answers the daemon's log must place inside the import's own service time. */
#define PROBES_INSIDE_MIN 10

typedef struct importer {
  char *body;
  atomic_int started, done;
  long status;
  long long imported;
} importer;

static void *import_thread(void *arg) {
  importer *im = arg;
  atomic_store(&im->started, 1);
  h_resp *r = h_post_json("/v1/scenes/lego/import", im->body);
  im->status = r->status;
  if (r->status == 200) im->imported = JINT(r->json, "imported");
  else fprintf(stderr, "import: %ld %s\n", r->status, r->body);
  h_resp_free(r);
  atomic_store(&im->done, 1);
  return NULL;
}

/* GET path with the probe's cut-off, asserted 200; the caller frees the reply. */
static h_resp *probe_get(const char *path) {
  h_req q = {.path = path, .timeout_ms = PROBE_GIVE_UP_MS};
  h_resp *r = h_request(&q);
  if (r->status == 0)
    FG_TEST_FAIL("GET %s: no answer within %d ms while an import runs", path, PROBE_GIVE_UP_MS);
  ASSERT_STATUS(r, 200);
  return r;
}

/* Milliseconds since the epoch of a daemon log line's "YYYY-MM-DDTHH:MM:SS.mmmZ" stamp; -1
 * when the line does not start with one. */
static double log_stamp_ms(const char *line) {
  struct tm tm = {0};
  int ms;
  if (sscanf(line, "%4d-%2d-%2dT%2d:%2d:%2d.%3dZ", &tm.tm_year, &tm.tm_mon, &tm.tm_mday,
             &tm.tm_hour, &tm.tm_min, &tm.tm_sec, &ms) != 7)
    return -1;
  tm.tm_year -= 1900;
  tm.tm_mon -= 1;
  return (double)timegm(&tm) * 1e3 + ms;
}

/* The daemon logs each request at its end: "STAMP debug METHOD PATH -> STATUS in D ms". Finds
 * the lines of "METHOD PATH -> 200" and reports each one's service interval [end - D, end]
 * in log milliseconds through fn. Returns how many there were. */
static int log_requests(const char *log, const char *method_path,
                        void (*fn)(double begin_ms, double end_ms, void *ud), void *ud) {
  char *needle = h_fmt(" %s -> 200 in ", method_path);
  int n = 0;
  for (const char *p = strstr(log, needle); p; p = strstr(p + 1, needle)) {
    const char *line = p;
    while (line > log && line[-1] != '\n') line--;
    const double end_ms = log_stamp_ms(line);
    ASSERT(end_ms > 0);
    const double d_ms = strtod(p + strlen(needle), NULL);
    fn(end_ms - d_ms, end_ms, ud);
    n++;
  }
  free(needle);
  return n;
}

typedef struct span {
  double begin_ms, end_ms;
  int inside;
} span;

static void take_span(double begin_ms, double end_ms, void *ud) {
  span *s = ud;
  s->begin_ms = begin_ms;
  s->end_ms = end_ms;
}

/* Counts the requests served wholly inside the span (a millisecond's margin each side for
 * the log's rounding). */
static void count_inside(double begin_ms, double end_ms, void *ud) {
  span *s = ud;
  if (begin_ms >= s->begin_ms + 1 && end_ms <= s->end_ms - 1) s->inside++;
}

/* While the lego import (100 frames decoded) runs, GET /v1/health and GET /v1/scenes/c are
 * answered without waiting for it: every one asked before the import's reply came must take
 * under PROBE_LIMIT_S, and the daemon's own log must place at least PROBES_INSIDE_MIN health
 * answers wholly inside the import's service time, so that they are known to have been
 * answered while it was running. A daemon whose import held a lock that health or the scene
 * list needs, or ran on the thread that answers them, fails one or the other. */
static void test_health_during_import(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"lego\", \"workspace\": {\"min\": [-1.5, -1.5, -1.5], "
                                        "\"max\": [1.5, 1.5, 1.5]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  char *shared = h_shared_data();
  importer im = {0};
  im.body = h_fmt("{\"path\": \"%s/lego\", \"transforms\": \"transforms_train.json\"}", shared);
  free(shared);
  pthread_t th;
  ASSERT_EQ(pthread_create(&th, NULL, import_thread, &im), 0);
  while (!atomic_load(&im.started)) h_sleep_ms(1);

  int asked = 0;
  double worst_s = 0;
  while (!atomic_load(&im.done)) {
    const double t0 = h_now_s();
    r = probe_get("/v1/health");
    ASSERT_STREQ(JSTR(r->json, "status"), "ok");
    h_resp_free(r);
    r = probe_get("/v1/scenes/c");
    ASSERT_EQ(JINT(r->json, "frames"), THREADS * PER_THREAD);
    h_resp_free(r);
    const double took_s = h_now_s() - t0;
    if (took_s > worst_s) worst_s = took_s;
    if (took_s > PROBE_LIMIT_S)
      FG_TEST_FAIL("health and the scene list took %.3f s while the import ran (limit %.1f s)",
                   took_s, PROBE_LIMIT_S);
    asked++;
    h_sleep_ms(20);
  }
  ASSERT_EQ(pthread_join(th, NULL), 0);
  ASSERT_EQ(im.status, 200);
  ASSERT_EQ(im.imported, 100);
  free(im.body);

  /* The daemon logs a request once its response has been sent, which may be a moment after
   * the client has read it: wait for the import's line (a state, not a time). */
  ASSERT(h_wait_log(" POST /v1/scenes/lego/import -> ", 1, 120));
  char *log = h_log();
  span import = {0};
  ASSERT_EQ(log_requests(log, "POST /v1/scenes/lego/import", take_span, &import), 1);
  log_requests(log, "GET /v1/health", count_inside, &import);
  free(log);
  printf("health and the scene list asked %d times while the import ran (slowest pair %.0f ms); "
         "%d health answers inside the import's %.0f ms\n",
         asked, worst_s * 1e3, import.inside, import.end_ms - import.begin_ms);
  if (import.inside < PROBES_INSIDE_MIN)
    FG_TEST_FAIL("only %d health answers lay inside the import's service time, not %d",
                 import.inside, PROBES_INSIDE_MIN);
  r = h_get("/v1/scenes/lego");
  ASSERT_EQ(JINT(r->json, "frames"), 100);
  h_resp_free(r);
}

/* ---- 8 clients create the same scene at once: one 201, seven 409 ---- */

typedef struct creator {
  long status;
  char code[64];
} creator;

static void *create_thread(void *arg) {
  creator *c = arg;
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"race\", \"voxel_size\": 0.02}");
  c->status = r->status;
  json_t *code = r->json ? h_jfind(r->json, "error.code") : NULL;
  snprintf(c->code, sizeof c->code, "%s", json_is_string(code) ? json_string_value(code) : "");
  h_resp_free(r);
  return NULL;
}

static void test_create_race(void) {
  pthread_t th[THREADS];
  creator c[THREADS];
  memset(c, 0, sizeof c);
  for (int t = 0; t < THREADS; t++) ASSERT_EQ(pthread_create(&th[t], NULL, create_thread, &c[t]), 0);
  for (int t = 0; t < THREADS; t++) ASSERT_EQ(pthread_join(th[t], NULL), 0);
  int created = 0, exists = 0;
  for (int t = 0; t < THREADS; t++) {
    if (c[t].status == 201) created++;
    else if (c[t].status == 409 && strcmp(c[t].code, "scene_exists") == 0) exists++;
    else FG_TEST_FAIL("concurrent create: %ld %s", c[t].status, c[t].code);
  }
  ASSERT_EQ(created, 1);
  ASSERT_EQ(exists, THREADS - 1);
  h_resp *r = h_get("/v1/scenes");
  int n = 0;
  json_t *scenes = JGET(r->json, "scenes");
  for (size_t i = 0; i < json_array_size(scenes); i++)
    if (strcmp(JSTR(json_array_get(scenes, i), "name"), "race") == 0) n++;
  ASSERT_EQ(n, 1);
  h_resp_free(r);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  char *shared = h_shared_data();
  char *conf = h_fmt("[state]\nimport_dirs = %s\n", shared);
  h_write_config(conf);
  free(conf);
  free(shared);
  h_start();
  test_create_race();
  test_parallel_uploads();
  test_health_during_import();
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
