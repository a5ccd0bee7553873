/* Training jobs: POST .../train and its errors, one job per scene at a time (409), polling
 * GET /v1/jobs/{id} to done, the Server-Sent Events stream (progress events, a final event,
 * 64 streams attached while /v1/health answers, 503 beyond that), cancelling (DELETE), FIFO
 * queueing across scenes, the training threads' nice value against the HTTP threads', the
 * metrics, deleting a scene with a running job, and restarts: a job that was running or queued
 * reports "interrupted by a daemon restart", a training stopped by SIGTERM keeps its field as
 * field.next.fgc, which becomes the scene's (partial) field only when there is no field.fgc.
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <arpa/inet.h>
#include <dirent.h>
#include <math.h>
#include <netinet/in.h>
#include <pthread.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "training.h"

/* A training long enough to be cancelled or interrupted before it ends. */
#define LONG_JOB "{\"steps\": 1000000}"

static char *g_sg;  /* data set folder */

static int file_exists(const char *scene, const char *name) {
  char *p = h_fmt("%s/scenes/%s/%s", h_state_dir(), scene, name);
  int ok = access(p, F_OK) == 0;
  free(p);
  return ok;
}

static void expect_error(const char *path, const char *body, long status, const char *code) {
  h_resp *r = h_post_json(path, body);
  if (r->status != status) fprintf(stderr, "POST %s %s\n", path, body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
}

static void cancel(const char *id) {
  char *path = h_fmt("/v1/jobs/%s", id);
  h_resp *r = h_delete(path);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(JSTR(r->json, "state"), "cancelled");
  h_resp_free(r);
  free(path);
}

/* Waits until the worker has let go of a cancelled job (it logs so), so the next one runs. */
static void wait_stopped(const char *id) {
  char *needle = h_fmt("job %s: stopped (cancelled)", id);
  if (!h_wait_log(needle, 1, 600)) FG_TEST_FAIL("the daemon never logged \"%s\"", needle);
  free(needle);
}

/* ---------------------------------------------------------------- errors */

static void test_errors(void) {
  expect_error("/v1/scenes/nope/train", "{}", 404, "scene_not_found");
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"empty\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  expect_error("/v1/scenes/empty/train", "{\"steps\": 5}", 409, "no_frames");
  static const char *const bad[] = {
    "{\"steps\": 0}", "{\"steps\": 1000001}", "{\"steps\": 2.5}", "{\"steps\": \"10\"}",
    "{\"seed\": -1}", "{\"seed\": \"12x\"}", "{\"max_seconds\": 0}", "{\"max_seconds\": -3}",
    "{\"holdout_every\": -1}", "{\"holdout_every\": 1}", "{\"bogus\": 1}", "[1, 2]",
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
    expect_error("/v1/scenes/sg/train", bad[i], 400, "invalid_request");
  expect_error("/v1/scenes/sg/train", "{\"steps\": ", 400, "malformed_json");
  r = h_get("/v1/jobs/j000000000000-000000");
  ASSERT_HTTP_ERROR(r, 404, "job_not_found");
  h_resp_free(r);
  r = h_delete("/v1/jobs/nope");
  ASSERT_HTTP_ERROR(r, 404, "job_not_found");
  h_resp_free(r);
  r = h_get("/v1/jobs/nope/events");
  ASSERT_HTTP_ERROR(r, 404, "job_not_found");
  h_resp_free(r);
  r = h_get("/v1/jobs");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "jobs")), 0);
  h_resp_free(r);
  json_t *s = t_scene_json("sg");
  ASSERT(json_is_false(JGET(s, "trained")));
  ASSERT(json_is_null(JGET(s, "last_job")));
  ASSERT_EQ(JINT(s, "trained_steps"), 0);
  ASSERT(json_is_null(JGET(s, "checkpoint_error")));
  json_decref(s);
}

/* ---------------------------------------------------------------- one training, its events */

typedef struct sse_client {
  char *path;
  h_resp *resp;
} sse_client;

static void *sse_thread(void *arg) {
  sse_client *c = arg;
  c->resp = h_get(c->path); /* returns when the daemon ends the stream */
  return NULL;
}

static char *g_first_job;

static void test_train_and_events(void) {
  char *id = t_train("sg", "{\"steps\": 8, \"holdout_every\": 4, \"seed\": 7}");
  g_first_job = id;
  /* One job per scene at a time. */
  h_resp *r = h_post_json("/v1/scenes/sg/train", "{\"steps\": 5}");
  ASSERT_HTTP_ERROR(r, 409, "training_in_progress");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), id);
  h_resp_free(r);

  sse_client c = {h_fmt("/v1/jobs/%s/events", id), NULL};
  pthread_t th;
  ASSERT_EQ(pthread_create(&th, NULL, sse_thread, &c), 0);
  /* Other requests answer while the scene trains (no timing assertion: that they answer). */
  int seen_running = 0;
  for (;;) {
    h_resp *hr = h_get("/v1/health");
    ASSERT_STATUS(hr, 200);
    h_resp_free(hr);
    json_t *j = t_job(id);
    const char *st = JSTR(j, "state");
    seen_running |= strcmp(st, "running") == 0;
    int end = strcmp(st, "queued") != 0 && strcmp(st, "running") != 0;
    json_decref(j);
    if (end) break;
    h_sleep_ms(50);
  }
  ASSERT(seen_running);
  json_t *j = t_wait_job(id, "done", 600);
  ASSERT_EQ(JINT(j, "step"), 8);
  ASSERT_EQ(JINT(j, "steps"), 8);
  ASSERT_STREQ(JSTR(j, "kind"), "train");
  ASSERT_STREQ(JSTR(j, "scene"), "sg");
  ASSERT(isfinite(JNUM(j, "loss")) && JNUM(j, "loss") >= 0);
  ASSERT(json_is_number(JGET(j, "psnr")));
  ASSERT(JNUM(j, "psnr") > 0);
  ASSERT(json_is_null(JGET(j, "error")));
  ASSERT(JNUM(j, "elapsed_s") > 0);
  ASSERT(JNUM(j, "samples_per_s") > 0);
  ASSERT_EQ(JINT(j, "frames"), 12);
  ASSERT_EQ(JINT(j, "heldout_frames"), 3);
  ASSERT_EQ(JINT(j, "seed"), 7);
  ASSERT_EQ(JINT(j, "holdout_every"), 4);
  json_decref(j);

  ASSERT_EQ(pthread_join(th, NULL), 0);
  ASSERT_STATUS(c.resp, 200);
  ASSERT_STRCONTAINS(h_resp_header(c.resp, "Content-Type"), "text/event-stream");
  ASSERT_STRCONTAINS(c.resp->body, "event: progress\ndata: {");
  const char *fin = strstr(c.resp->body, "event: done\ndata: {");
  ASSERT(fin != NULL);
  ASSERT(strstr(fin + 1, "event:") == NULL); /* the final event is the last one */
  ASSERT(strstr(c.resp->body, "\"state\":\"running\"") != NULL);
  h_resp_free(c.resp);

  /* A finished job's stream gives its final event at once and ends. */
  c.resp = h_get(c.path);
  ASSERT_STATUS(c.resp, 200);
  ASSERT(strncmp(c.resp->body, "event: done\ndata: {", 19) == 0);
  ASSERT(strstr(c.resp->body + 1, "event:") == NULL);
  h_resp_free(c.resp);
  free(c.path);

  json_t *s = t_scene_json("sg");
  ASSERT(json_is_true(JGET(s, "trained")));
  ASSERT_EQ(JINT(s, "trained_steps"), 8);
  ASSERT(JINT(s, "checkpoint_bytes") > 0);
  ASSERT(json_is_false(JGET(s, "partial")));
  ASSERT_STREQ(JSTR(s, "last_job.id"), id);
  ASSERT_STREQ(JSTR(s, "last_job.state"), "done");
  json_decref(s);
  ASSERT(file_exists("sg", "field.fgc"));
  ASSERT(file_exists("sg", "last_job.json"));
  ASSERT(!file_exists("sg", "field.next.fgc"));
  /* The scene list carries the same fields. */
  r = h_get("/v1/scenes");
  ASSERT_STATUS(r, 200);
  json_t *list = JGET(r->json, "scenes");
  int found = 0;
  for (size_t i = 0; i < json_array_size(list); i++) {
    json_t *e = json_array_get(list, i);
    if (strcmp(JSTR(e, "name"), "sg") != 0) continue;
    found = 1;
    ASSERT(json_is_true(JGET(e, "trained")));
    ASSERT_STREQ(JSTR(e, "last_job.state"), "done");
  }
  ASSERT(found);
  h_resp_free(r);
}

/* ---------------------------------------------------------------- thread priorities */

/* Checks /proc/<pid>/task/ * /stat: the training threads ("fg-train", the worker and its
 * OpenMP team) run at nice 10, the HTTP threads (libmicrohttpd's "MHD-*", the offload pool
 * "fg-offload") and the main thread at 0. */
static void check_nice(void) {
  char *dir = h_fmt("/proc/%d/task", (int)h_pid());
  char main_tid[16];
  snprintf(main_tid, sizeof main_tid, "%d", (int)h_pid());
  DIR *d = opendir(dir);
  ASSERT(d != NULL);
  int train = 0, http = 0;
  struct dirent *e;
  while ((e = readdir(d)) != NULL) {
    if (e->d_name[0] == '.') continue;
    char *p = h_fmt("%s/%s/stat", dir, e->d_name);
    char *stat = h_read_file(p, NULL);
    free(p);
    if (!stat) continue; /* the thread ended meanwhile */
    const char *open = strchr(stat, '('), *close = strrchr(stat, ')');
    ASSERT(open && close);
    char comm[64];
    snprintf(comm, sizeof comm, "%.*s", (int)(close - open - 1), open + 1);
    /* after ") ": state ppid pgrp session tty tpgid flags minflt cminflt majflt cmajflt utime
     * stime cutime cstime priority nice: nice is the 17th field after the command. */
    const char *q = close + 2;
    for (int k = 0; k < 16; k++) {
      q = strchr(q, ' ');
      ASSERT(q);
      q++;
    }
    int nice = atoi(q);
    if (strcmp(comm, "fg-train") == 0) {
      train++;
      if (nice != 10) FG_TEST_FAIL("training thread %s has nice %d, expected 10", e->d_name, nice);
    } else if (strncmp(comm, "MHD", 3) == 0 || strcmp(comm, "fg-offload") == 0 ||
               strcmp(e->d_name, main_tid) == 0) {
      http++;
      if (nice != 0) FG_TEST_FAIL("thread %s (%s) has nice %d, expected 0", e->d_name, comm, nice);
    }
    free(stat);
  }
  closedir(d);
  free(dir);
  printf("threads: %d training at nice 10, %d HTTP/main at nice 0\n", train, http);
  ASSERT(train >= 2); /* [train] threads = 2: the worker and one more */
  ASSERT(http >= 2);
}

/* ---------------------------------------------------------------- many event streams */

static int sse_connect(const char *id, char *head, size_t cap) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  ASSERT(fd >= 0);
  struct sockaddr_in sa = {0};
  sa.sin_family = AF_INET;
  sa.sin_port = htons((uint16_t)h_port());
  sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(connect(fd, (struct sockaddr *)&sa, sizeof sa), 0);
  struct timeval tv = {30, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  char *req = h_fmt("GET /v1/jobs/%s/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", id);
  ASSERT_EQ(send(fd, req, strlen(req), MSG_NOSIGNAL), (long long)strlen(req));
  free(req);
  /* Read the headers and, for a stream, its first event (or a whole error reply). */
  size_t got = 0;
  while (got + 1 < cap) {
    ssize_t n = recv(fd, head + got, cap - 1 - got, 0);
    if (n <= 0) break;
    got += (size_t)n;
    head[got] = '\0';
    const char *body = strstr(head, "\r\n\r\n");
    if (body && strstr(head, " 200 ") && strstr(body, "\n\n")) break;
    if (body && !strstr(head, " 200 ") && strstr(body + 4, "}}")) break;
  }
  head[got] = '\0';
  return fd;
}

static void test_streams_and_cancel(const char *id) {
  enum { N = 64 }; /* FG_API_MAX_EVENT_STREAMS */
  int fds[N];
  char head[8192];
  for (int i = 0; i < N; i++) {
    fds[i] = sse_connect(id, head, sizeof head);
    if (!strstr(head, "HTTP/1.1 200") || !strstr(head, "text/event-stream") ||
        !strstr(head, "event: progress"))
      FG_TEST_FAIL("stream %d: %s", i, head);
    if (i == 31) { /* 32 attached: the daemon answers everything else at once */
      h_resp *r = h_get("/v1/health");
      ASSERT_STATUS(r, 200);
      h_resp_free(r);
      r = h_get("/v1/scenes/sg");
      ASSERT_STATUS(r, 200);
      h_resp_free(r);
    }
  }
  h_resp *r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  char *path = h_fmt("/v1/jobs/%s/events", id);
  r = h_get(path);
  ASSERT_HTTP_ERROR(r, 503, "too_many_streams");
  h_resp_free(r);
  /* Half the clients go away; the other half see the job's end. */
  for (int i = 0; i < N / 2; i++) close(fds[i]);

  /* DELETE reports "cancelled" at once (the training stops after its current step). */
  cancel(id);
  json_t *j = t_job(id);
  ASSERT_STREQ(JSTR(j, "state"), "cancelled");
  ASSERT(json_is_null(JGET(j, "error")));
  json_decref(j);
  char *job_path = h_fmt("/v1/jobs/%s", id);
  r = h_delete(job_path);
  ASSERT_HTTP_ERROR(r, 409, "job_finished");
  h_resp_free(r);
  free(job_path);
  for (int i = N / 2; i < N; i++) {
    /* the rest of the stream: more progress events maybe, then the final one, then the end */
    size_t got = 0;
    char buf[16384];
    for (;;) {
      ssize_t n = recv(fds[i], buf + got, sizeof buf - 1 - got, 0);
      if (n <= 0 || got + (size_t)n >= sizeof buf - 1) break;
      got += (size_t)n;
      buf[got] = '\0';
      if (strstr(buf, "\r\n0\r\n\r\n")) break; /* the chunked body's end */
    }
    buf[got] = '\0';
    if (!strstr(buf, "event: cancelled\ndata: {")) FG_TEST_FAIL("stream %d ended with: %s", i, buf);
    close(fds[i]);
  }
  wait_stopped(id);
  /* Every stream is gone now: new ones open again. */
  double deadline = t_now() + 30;
  for (;;) {
    r = h_get(path);
    long st = r->status;
    h_resp_free(r);
    if (st == 200) break;
    ASSERT_EQ(st, 503);
    if (t_now() > deadline) FG_TEST_FAIL("event streams stay taken after their clients left");
    h_sleep_ms(100);
  }
  free(path);
}

/* ---------------------------------------------------------------- two scenes */

static void test_queue(void) {
  char *a = t_train("sg", "{\"steps\": 4}");
  char *b = t_train("sg2", "{\"steps\": 2, \"max_seconds\": 600}");
  json_t *jb = t_job(b);
  ASSERT_STREQ(JSTR(jb, "state"), "queued"); /* the worker runs one training at a time */
  json_decref(jb);
  json_t *ja = t_wait_job(a, "done", 600);
  jb = t_wait_job(b, "done", 600);
  ASSERT_EQ(JINT(jb, "step"), 2);
  /* FIFO: b started once a had finished. */
  ASSERT(strcmp(JSTR(jb, "started"), JSTR(ja, "finished")) >= 0);
  ASSERT(JNUM(jb, "max_seconds") == 600);
  ASSERT(json_is_null(JGET(jb, "psnr"))); /* nothing held out */
  json_decref(ja);
  json_decref(jb);
  /* Newest first. */
  h_resp *r = h_get("/v1/jobs");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(JSTR(r->json, "jobs.0.id"), b);
  ASSERT_STREQ(JSTR(r->json, "jobs.1.id"), a);
  h_resp_free(r);
  json_t *s = t_scene_json("sg2");
  ASSERT_EQ(JINT(s, "trained_steps"), 2);
  json_decref(s);
  s = t_scene_json("sg");
  ASSERT_EQ(JINT(s, "trained_steps"), 4);
  json_decref(s);
  free(a);
  free(b);
}

/* ---------------------------------------------------------------- metrics */

static double metric_value(const char *text, const char *line_start) {
  const char *p = strstr(text, line_start);
  if (!p) FG_TEST_FAIL("no \"%s\" in /metrics", line_start);
  return strtod(p + strlen(line_start), NULL);
}

static void test_metrics(void) {
  h_resp *r = h_get("/metrics");
  ASSERT_STATUS(r, 200);
  ASSERT(metric_value(r->body, "\nfieldgrip_jobs{state=\"done\"} ") >= 3);
  ASSERT(metric_value(r->body, "\nfieldgrip_jobs{state=\"cancelled\"} ") >= 2);
  ASSERT_EQ(metric_value(r->body, "\nfieldgrip_jobs{state=\"running\"} "), 0);
  ASSERT(metric_value(r->body, "\nfieldgrip_training_steps_total ") >= 14);
  ASSERT(metric_value(r->body, "\nfieldgrip_training_samples_per_second ") > 0);
  ASSERT_EQ(metric_value(r->body, "\nfieldgrip_trained_scenes "), 2);
  ASSERT_STRCONTAINS(r->body, "# TYPE fieldgrip_jobs gauge");
  ASSERT_STRCONTAINS(r->body, "# TYPE fieldgrip_training_steps_total counter");
  ASSERT_STRCONTAINS(r->body, "route=\"/v1/scenes/{s}/train\",method=\"POST\",code=\"202\"");
  h_resp_free(r);
}

/* ---------------------------------------------------------------- deleting a scene */

static void test_delete_scene(void) {
  t_scene_from_dataset("gone", g_sg, 12);
  char *id = t_train("gone", LONG_JOB);
  t_wait_running(id, 1, 600);
  h_resp *r = h_delete("/v1/scenes/gone");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  json_t *j = t_job(id);
  ASSERT_STREQ(JSTR(j, "state"), "cancelled");
  json_decref(j);
  wait_stopped(id);
  char *p = h_fmt("%s/scenes/gone", h_state_dir());
  ASSERT(access(p, F_OK) != 0);
  free(p);
  free(id);
}

/* ---------------------------------------------------------------- restarts */

static void test_restart(void) {
  /* A training stopped by SIGTERM on a scene without field.fgc: its field survives as
   * field.next.fgc and is the scene's (partial) field after the restart; a job queued behind
   * it is interrupted too. */
  t_scene_from_dataset("fresh", g_sg, 12);
  char *run = t_train("fresh", LONG_JOB);
  t_wait_running(run, 1, 600);
  char *queued = t_train("sg", "{\"steps\": 2}");
  /* An event stream attached while the daemon stops: the shutdown ends it and exits 0. */
  char head[8192];
  int fd = sse_connect(run, head, sizeof head);
  ASSERT_STRCONTAINS(head, "event: progress");
  h_stop();
  close(fd);
  ASSERT(file_exists("fresh", "field.next.fgc"));
  ASSERT(!file_exists("fresh", "field.fgc"));
  h_start();
  h_resp *r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  for (int k = 0; k < 2; k++) {
    json_t *j = t_job(k ? queued : run);
    ASSERT_STREQ(JSTR(j, "state"), "failed");
    ASSERT_STREQ(JSTR(j, "error"), "interrupted by a daemon restart");
    json_decref(j);
  }
  json_t *s = t_scene_json("fresh");
  ASSERT(json_is_true(JGET(s, "trained")));
  ASSERT(json_is_true(JGET(s, "partial")));
  ASSERT(JINT(s, "trained_steps") >= 1);
  ASSERT_STREQ(JSTR(s, "last_job.state"), "failed");
  json_decref(s);
  ASSERT(h_log_count("loaded field.next.fgc") == 1);
  s = t_scene_json("sg");
  ASSERT(json_is_true(JGET(s, "trained")));
  ASSERT(json_is_false(JGET(s, "partial")));
  ASSERT_EQ(JINT(s, "trained_steps"), 4);
  ASSERT_STREQ(JSTR(s, "last_job.id"), queued);
  json_decref(s);
  /* Earlier jobs of this run are gone; each scene's last one stays. */
  r = h_get("/v1/jobs");
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(json_array_size(JGET(r->json, "jobs")), 3); /* fresh, sg, sg2 */
  h_resp_free(r);
  char *first = h_fmt("/v1/jobs/%s", g_first_job);
  r = h_get(first);
  ASSERT_HTTP_ERROR(r, 404, "job_not_found");
  h_resp_free(r);
  free(first);

  /* A new training of the partial scene makes its partial field field.fgc first, so
   * cancelling that training cannot lose it. */
  char *again = t_train("fresh", LONG_JOB);
  t_wait_running(again, 1, 600);
  ASSERT(file_exists("fresh", "field.fgc"));
  cancel(again);
  wait_stopped(again);
  ASSERT(!file_exists("fresh", "field.next.fgc"));
  s = t_scene_json("fresh");
  ASSERT(json_is_true(JGET(s, "trained")));
  json_decref(s);

  /* SIGTERM while a scene with field.fgc trains: at the next start its field.next.fgc is
   * removed and field.fgc stays the field. */
  char *sg_run = t_train("sg", LONG_JOB);
  t_wait_running(sg_run, 1, 600);
  h_stop();
  ASSERT(file_exists("sg", "field.next.fgc"));
  h_start();
  ASSERT(!file_exists("sg", "field.next.fgc"));
  ASSERT(h_log_count("scene sg: removed field.next.fgc") == 1);
  s = t_scene_json("sg");
  ASSERT(json_is_false(JGET(s, "partial")));
  ASSERT_EQ(JINT(s, "trained_steps"), 4);
  json_decref(s);
  json_t *j = t_job(sg_run);
  ASSERT_STREQ(JSTR(j, "error"), "interrupted by a daemon restart");
  json_decref(j);

  /* kill -9 mid-training: the job is interrupted, the field is untouched. */
  char *killed = t_train("sg2", LONG_JOB);
  t_wait_running(killed, 1, 600);
  h_kill();
  h_start();
  j = t_job(killed);
  ASSERT_STREQ(JSTR(j, "state"), "failed");
  ASSERT_STREQ(JSTR(j, "error"), "interrupted by a daemon restart");
  json_decref(j);
  s = t_scene_json("sg2");
  ASSERT_EQ(JINT(s, "trained_steps"), 2);
  json_decref(s);
  ASSERT_EQ(h_count_files(h_state_dir(), ".tmp."), 0);
  free(run);
  free(queued);
  free(again);
  free(sg_run);
  free(killed);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  g_sg = t_dataset(argv[2], 12, 64, 48, 8, 0);
  h_start();
  t_scene_from_dataset("sg", g_sg, 12);
  t_scene_from_dataset("sg2", g_sg, 12);

  test_errors();
  test_train_and_events();

  char *long_job = t_train("sg", LONG_JOB);
  t_wait_running(long_job, 1, 600);
  check_nice();
  test_streams_and_cancel(long_job);
  free(long_job);
  json_t *s = t_scene_json("sg");
  ASSERT_EQ(JINT(s, "trained_steps"), 8); /* the cancelled job changed nothing */
  ASSERT(!file_exists("sg", "field.next.fgc"));
  json_decref(s);

  test_queue();
  test_delete_scene();
  test_metrics();
  test_restart();

  h_stop();
  free(g_first_job);
  free(g_sg);
  h_done();
  return 0;
}
