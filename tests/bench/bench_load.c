/* Load on a daemon that trains: bench_load FIELDGRIPD FIELDGRIP-SCENEGEN [options].
 *
 * Starts fieldgripd (through the integration harness: free loopback port, temporary state
 * dir, log level info), makes a fieldgrip-scenegen tabletop (the grasp tests' coarse set:
 * 30 views at 160x120 with 32-d features, 2 cm voxels; tests/integration/grasp_util.h),
 * imports it as scene "a", trains it for --train-steps steps, builds its voxel cache with one
 * heatmap and records one demo of the ball's gt.json grasp as task "ball". Then it imports the
 * same set as scene "b" and starts a long training job on it, waits until that job runs, and
 * for --seconds drives three kinds of closed-loop clients at once, each on its own thread with
 * one kept-alive connection (a libcurl easy handle reused request after request):
 *   health   GET /v1/health
 *   heatmap  POST /v1/scenes/a/heatmap {"embedding": <the ball class's embedding>}
 *   grasps   POST /v1/scenes/a/grasps {"task": "ball"}
 * Every request's latency runs from the call to the end of the answer's body. An error is a
 * status other than 2xx or a transport failure (refused, reset, timed out after 60 s).
 * Afterwards the training job must still be running (it was under load the whole time); it is
 * cancelled and the daemon stopped, which must exit 0.
 *
 * Options (defaults in brackets): --seconds S [30], --health-clients N [4],
 * --heatmap-clients N [2], --grasp-clients N [1], --train-steps N [60], --train-threads N
 * [2] (the daemon's [train] threads).
 *
 * Output: one line per endpoint and a summary, space-separated key=value pairs:
 *   bench=load endpoint=health clients=4 requests=... requests_per_s=... p50_ms=...
 *     p99_ms=... max_ms=... errors=...
 *   bench=load_summary seconds=... training=running train_steps=... train_steps_per_s=...
 *     train_steps_per_s_without_load=... errors=... health_p99_ms=... target_errors=0
 *     target_max_health_p99_ms=50 pass=yes|no
 * (train_steps_per_s_without_load: the job's pace over 5 s just before the load.)
 * The exit status is 0 when both targets are met, 1 otherwise. */
#include "benchstat.h"
#include "grasp_util.h"

#include <curl/curl.h>
#include <pthread.h>

enum { EP_HEALTH, EP_HEATMAP, EP_GRASPS, N_EP };
static const char *const ep_name[N_EP] = {"health", "heatmap", "grasps"};

/* One client: its thread, its request and what it measured. */
typedef struct client {
  pthread_t thread;
  int ep;
  const char *url;     /* borrowed */
  const char *body;    /* borrowed; NULL for a GET */
  double until_s;      /* t_now() at which it stops sending */
  double *lat_s;       /* owned; one latency per request */
  size_t n, cap;
  long errors;
  char first_error[160]; /* what the first error was, for stderr */
} client;

static size_t discard(char *p, size_t size, size_t n, void *ud) {
  (void)p;
  (void)ud;
  return size * n;
}

static void client_note(client *c, double lat_s, int ok, const char *what) {
  if (c->n == c->cap) {
    c->cap = c->cap ? 2 * c->cap : 1024;
    c->lat_s = realloc(c->lat_s, c->cap * sizeof *c->lat_s);
    if (!c->lat_s) FG_TEST_FAIL("out of memory");
  }
  c->lat_s[c->n++] = lat_s;
  if (!ok && c->errors++ == 0) snprintf(c->first_error, sizeof c->first_error, "%s", what);
}

/* Sends the client's request again and again over one handle (so one kept-alive connection,
 * reopened by libcurl only if the daemon closed it) until until_s. */
static void *client_main(void *arg) {
  client *c = arg;
  CURL *h = curl_easy_init();
  if (!h) FG_TEST_FAIL("curl_easy_init failed");
  struct curl_slist *hdr = curl_slist_append(NULL, "Content-Type: application/json");
  curl_easy_setopt(h, CURLOPT_URL, c->url);
  curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, discard);
  curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(h, CURLOPT_TIMEOUT, 60L);
  curl_easy_setopt(h, CURLOPT_TCP_NODELAY, 1L);
  if (c->body) {
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, hdr);
    curl_easy_setopt(h, CURLOPT_POSTFIELDS, c->body);
  }
  while (t_now() < c->until_s) {
    double t0 = t_now();
    CURLcode rc = curl_easy_perform(h);
    double lat = t_now() - t0;
    long status = 0;
    curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
    char what[160];
    if (rc != CURLE_OK) snprintf(what, sizeof what, "transport: %s", curl_easy_strerror(rc));
    else snprintf(what, sizeof what, "HTTP %ld", status);
    client_note(c, lat, rc == CURLE_OK && status >= 200 && status < 300, what);
  }
  curl_slist_free_all(hdr);
  curl_easy_cleanup(h);
  return NULL;
}

static int arg_int(int argc, char **argv, const char *name, int dflt) {
  for (int i = 3; i + 1 < argc; i++)
    if (strcmp(argv[i], name) == 0) return atoi(argv[i + 1]);
  return dflt;
}

/* POST path with body; asserts status and frees the reply. */
static void post_ok(const char *path, const char *body, long status) {
  h_resp *r = g_post(path, body);
  if (r->status != status) fprintf(stderr, "POST %s -> %ld %s\n", path, r->status, r->body);
  ASSERT_STATUS(r, status);
  h_resp_free(r);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3)
    FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN [--seconds S] [--health-clients N] "
                 "[--heatmap-clients N] [--grasp-clients N] [--train-steps N] "
                 "[--train-threads N]", argv[0]);
  const int seconds = arg_int(argc, argv, "--seconds", 30);
  const int n_clients[N_EP] = {arg_int(argc, argv, "--health-clients", 4),
                               arg_int(argc, argv, "--heatmap-clients", 2),
                               arg_int(argc, argv, "--grasp-clients", 1)};
  const int train_steps = arg_int(argc, argv, "--train-steps", 60);
  const int train_threads = arg_int(argc, argv, "--train-threads", 2);
  if (seconds < 1 || train_steps < 1 || train_threads < 1 || n_clients[0] < 0 ||
      n_clients[1] < 0 || n_clients[2] < 0)
    FG_TEST_FAIL("bad option value");

  /* ---- the scene under load: trained, its voxel cache built, a task with a demo ---- */
  char *imports = g_dataset(argv[2]);
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = %d\n", imports,
                     train_threads);
  h_write_config(conf);
  free(conf);
  h_set_log_level("info");
  h_start();
  g_scene("a", NULL);
  g_train("a", train_steps);
  char *emb = g_class_embedding("ball");
  char *heatmap_body = h_fmt("{\"embedding\": %s}", emb);
  free(emb);
  post_ok("/v1/scenes/a/heatmap", heatmap_body, 200);
  char *demo = g_demo_body("a", "ball", "");
  post_ok("/v1/tasks/ball/demos", demo, 201);
  free(demo);
  const char *grasp_body = "{\"task\": \"ball\"}";
  post_ok("/v1/scenes/a/grasps", grasp_body, 200);

  /* ---- another scene training the whole time ---- */
  g_scene("b", NULL);
  char *job = t_train("b", "{\"steps\": 1000000}");
  t_wait_running(job, 1, 300);
  /* Its pace without the load, for comparison: the load's requests run at a higher
   * priority than training (jobs.h), so training slows down under them. */
  json_t *j = t_job(job);
  const long long step_idle0 = JINT(j, "step");
  json_decref(j);
  const double t_idle = t_now();
  h_sleep_ms(5000);
  j = t_job(job);
  const long long step0 = JINT(j, "step");
  json_decref(j);
  const double idle_steps_per_s = (double)(step0 - step_idle0) / (t_now() - t_idle);

  /* ---- the load ---- */
  char *url[N_EP] = {h_fmt("http://127.0.0.1:%d/v1/health", h_port()),
                     h_fmt("http://127.0.0.1:%d/v1/scenes/a/heatmap", h_port()),
                     h_fmt("http://127.0.0.1:%d/v1/scenes/a/grasps", h_port())};
  const char *body[N_EP] = {NULL, heatmap_body, grasp_body};
  const int total = n_clients[0] + n_clients[1] + n_clients[2];
  client *cl = calloc((size_t)(total ? total : 1), sizeof *cl);
  ASSERT(cl != NULL);
  const double t_start = t_now(), until = t_start + seconds;
  for (int e = 0, k = 0; e < N_EP; e++)
    for (int i = 0; i < n_clients[e]; i++, k++) {
      cl[k] = (client){.ep = e, .url = url[e], .body = body[e], .until_s = until};
      ASSERT_EQ(pthread_create(&cl[k].thread, NULL, client_main, &cl[k]), 0);
    }
  for (int k = 0; k < total; k++) pthread_join(cl[k].thread, NULL);
  const double elapsed = t_now() - t_start;

  j = t_job(job);
  const long long step1 = JINT(j, "step");
  char *train_state = strdup(JSTR(j, "state"));
  json_decref(j);
  char *path = h_fmt("/v1/jobs/%s", job);
  h_resp *r = h_delete(path);
  h_resp_free(r);
  free(path);
  json_decref(t_wait_job(job, "cancelled", 120));
  h_stop();

  /* ---- figures ---- */
  long errors_all = 0;
  double health_p99_ms = NAN;
  for (int e = 0; e < N_EP; e++) {
    if (n_clients[e] == 0) continue;
    size_t n = 0;
    long errors = 0;
    for (int k = 0; k < total; k++)
      if (cl[k].ep == e) n += cl[k].n;
    double *v = malloc((n ? n : 1) * sizeof *v);
    ASSERT(v != NULL);
    n = 0;
    for (int k = 0; k < total; k++) {
      if (cl[k].ep != e) continue;
      memcpy(v + n, cl[k].lat_s, cl[k].n * sizeof *v);
      n += cl[k].n;
      errors += cl[k].errors;
      if (cl[k].errors)
        fprintf(stderr, "bench_load: %s: %ld errors, the first %s\n", ep_name[e], cl[k].errors,
                cl[k].first_error);
    }
    const double p50 = bench_percentile(v, (int)n, 0.5) * 1e3; /* sorts v */
    const double p99 = bench_percentile(v, (int)n, 0.99) * 1e3;
    printf("bench=load endpoint=%s clients=%d requests=%zu requests_per_s=%.1f p50_ms=%.2f "
           "p99_ms=%.2f max_ms=%.2f errors=%ld\n",
           ep_name[e], n_clients[e], n, (double)n / elapsed, p50, p99, n ? v[n - 1] * 1e3 : NAN,
           errors);
    if (e == EP_HEALTH) health_p99_ms = p99;
    errors_all += errors;
    free(v);
  }
  const int pass = errors_all == 0 && health_p99_ms <= 50 && strcmp(train_state, "running") == 0;
  printf("bench=load_summary seconds=%.1f training=%s train_threads=%d train_steps=%lld "
         "train_steps_per_s=%.2f train_steps_per_s_without_load=%.2f errors=%ld "
         "health_p99_ms=%.2f target_errors=0 target_max_health_p99_ms=50 pass=%s\n",
         elapsed, train_state, train_threads, step1 - step0, (double)(step1 - step0) / elapsed,
         idle_steps_per_s, errors_all, health_p99_ms, pass ? "yes" : "no");

  for (int k = 0; k < total; k++) free(cl[k].lat_s);
  free(cl);
  for (int e = 0; e < N_EP; e++) free(url[e]);
  free(train_state);
  free(heatmap_body);
  free(job);
  free(imports);
  h_done();
  return pass ? 0 : 1;
}
