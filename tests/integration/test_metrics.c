/* /metrics in the Prometheus text format: request counters by method, route template and
 * code, the duration histogram, scene/frame gauges and the ingested-frames counter, checked
 * against the exact requests this test made; the process_* families against /proc, the
 * image decoder pool's families, and the kinds of Modbus errors. Also the process itself:
 * started without OpenMP settings, the daemon runs with a short spin (daemon/main.c). */
#include <arpa/inet.h>
#include <dirent.h>
#include <netinet/in.h>
#include <math.h>
#include <strings.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "config.h"
#include "harness.h"

/* Sum of the values of every series of family `name` whose labels include all of `want`
 * ("key", "value", ..., NULL). -1 when no series matches. Label order is free. */
static double metric(const char *text, const char *name, const char *const *want) {
  double sum = -1;
  size_t nl = strlen(name);
  for (const char *line = text; line && *line; line = strchr(line, '\n') ? strchr(line, '\n') + 1 : NULL) {
    if (*line == '#' || strncmp(line, name, nl) != 0) continue;
    const char *p = line + nl;
    char labels[1024] = "";
    if (*p == '{') {
      /* the closing brace outside quoted values: routes such as "/v1/scenes/{s}" hold braces */
      const char *end = p + 1;
      for (int quoted = 0; *end && (quoted || *end != '}'); end++) {
        if (*end == '\\' && end[1]) end++;
        else if (*end == '"') quoted = !quoted;
      }
      if (*end != '}') continue;
      if ((size_t)(end - p) >= sizeof labels) continue;
      memcpy(labels, p + 1, (size_t)(end - p - 1));
      labels[end - p - 1] = '\0';
      p = end + 1;
    }
    if (*p != ' ') continue; /* a longer name with the same prefix */
    int match = 1;
    for (int i = 0; want && want[i]; i += 2) {
      char kv[512];
      snprintf(kv, sizeof kv, "%s=\"%s\"", want[i], want[i + 1]);
      /* the pair must start a label: at the beginning or after a comma */
      const char *q = labels;
      int found = 0;
      while ((q = strstr(q, kv)) != NULL) {
        if ((q == labels || q[-1] == ',') && (q[strlen(kv)] == ',' || q[strlen(kv)] == '\0')) {
          found = 1;
          break;
        }
        q++;
      }
      if (!found) match = 0;
    }
    if (!match) continue;
    double v = strtod(p + 1, NULL);
    sum = sum < 0 ? v : sum + v;
  }
  return sum;
}

static void expect_requests(const char *text, const char *method, const char *route,
                            const char *code, double n) {
  const char *want[] = {"method", method, "route", route, "code", code, NULL};
  double v = metric(text, "fieldgrip_http_requests_total", want);
  if (v != n)
    FG_TEST_FAIL("fieldgrip_http_requests_total{method=\"%s\",route=\"%s\",code=\"%s\"} is %g, "
                 "expected %g; /metrics:\n%s",
                 method, route, code, v, n, text);
}

/* The duration histogram of one route: its cumulative buckets rise to its count, n; its sum
 * is above zero, within what the buckets allow (each duration above the bucket below its own
 * and at most its bound; the daemon sums whole microseconds, so each may be up to one lower)
 * and at most n times wall_s, the time in which all n requests were made and counted. A sum
 * in the wrong unit, one that is not added to, or buckets that disagree with it fail. */
static void expect_histogram(const char *text, const char *route, double n, double wall_s) {
  char prefix[256];
  snprintf(prefix, sizeof prefix, "fieldgrip_http_request_duration_seconds_bucket{route=\"%s\",",
           route);
  double lo = 0, hi = 0, prev_le = 0, prev_cum = 0;
  int buckets = 0;
  for (const char *line = strstr(text, prefix); line; line = strstr(line + 1, prefix)) {
    if (line != text && line[-1] != '\n') continue;
    const char *le = strstr(line, "le=\"");
    ASSERT(le != NULL);
    le += 4;
    const double bound = strncmp(le, "+Inf", 4) == 0 ? INFINITY : strtod(le, NULL);
    const char *val = strstr(le, "} ");
    ASSERT(val != NULL);
    const double cum = strtod(val + 2, NULL);
    ASSERT(cum >= prev_cum); /* cumulative */
    const double in_bucket = cum - prev_cum;
    lo += in_bucket * prev_le;
    hi += in_bucket > 0 ? in_bucket * bound : 0;
    prev_le = bound;
    prev_cum = cum;
    buckets++;
  }
  ASSERT(buckets > 1);
  ASSERT(isinf(prev_le));
  ASSERT_EQ(prev_cum, n);
  const char *rw[] = {"route", route, NULL};
  ASSERT_EQ(metric(text, "fieldgrip_http_request_duration_seconds_count", rw), n);
  const double sum = metric(text, "fieldgrip_http_request_duration_seconds_sum", rw);
  if (!(sum > 0 && sum >= lo - n * 1e-6 - 1e-6 && sum <= hi + 1e-6 && sum <= n * wall_s))
    FG_TEST_FAIL("%s: duration sum %.6f s for %g requests; the buckets allow %.6f .. %.6f s and "
                 "the requests took place within %.3f s", route, sum, n, lo, hi, wall_s);
}

/* Requests are counted when their response has been sent, which may be a moment after the
 * client has read it. Scrapes until the counters of the API routes add up to `requests` (at most
 * 10 s: waiting for an event, not timing it); returns the last scrape and counts the scrapes. */
static h_resp *scrape_settled(double requests, int *scrapes) {
  for (int i = 0;; i++) {
    h_resp *r = h_get("/metrics");
    ASSERT_STATUS(r, 200);
    (*scrapes)++;
    double all = metric(r->body, "fieldgrip_http_requests_total", NULL);
    const char *mw[] = {"route", "/metrics", NULL};
    double m = metric(r->body, "fieldgrip_http_requests_total", mw);
    double api = all - (m > 0 ? m : 0);
    if (api == requests) return r;
    if (api > requests || i >= 500)
      FG_TEST_FAIL("fieldgrip_http_requests_total adds up to %g for the API routes, expected %g:\n%s",
                   api, requests, r->body);
    h_resp_free(r);
    h_sleep_ms(20);
  }
}

/* ---------------------------------------------------------------- process, decoder, Modbus */

/* The family's one sample, checking its TYPE line. */
static double family(const char *text, const char *name, const char *type) {
  char want[160];
  snprintf(want, sizeof want, "# TYPE %s %s\n", name, type);
  if (!strstr(text, want)) FG_TEST_FAIL("no \"%s\" in /metrics:\n%s", want, text);
  double v = metric(text, name, NULL);
  if (v < 0) FG_TEST_FAIL("no sample of %s in /metrics:\n%s", name, text);
  return v;
}

static double fds_of(pid_t pid) {
  char path[64];
  snprintf(path, sizeof path, "/proc/%d/fd", (int)pid);
  DIR *d = opendir(path);
  ASSERT(d);
  double n = 0;
  for (struct dirent *e; (e = readdir(d)) != NULL;) n += e->d_name[0] != '.';
  closedir(d);
  return n;
}

/* The standard process_* families, checked against what /proc says about the daemon from
 * outside it. */
static void check_process_metrics(void) {
  h_resp *r = h_get("/metrics");
  ASSERT_STATUS(r, 200);
  const char *text = r->body;
  const pid_t pid = h_pid();
  const double rss = family(text, "process_resident_memory_bytes", "gauge");
  const double vsz = family(text, "process_virtual_memory_bytes", "gauge");
  const double fds = family(text, "process_open_fds", "gauge");
  const double max_fds = family(text, "process_max_fds", "gauge");
  const double start = family(text, "process_start_time_seconds", "gauge");
  const double cpu = family(text, "process_cpu_seconds_total", "counter");
  char path[64], buf[256];
  snprintf(path, sizeof path, "/proc/%d/statm", (int)pid);
  FILE *f = fopen(path, "r");
  ASSERT(f && fgets(buf, sizeof buf, f));
  fclose(f);
  unsigned long long pages, resident;
  ASSERT(sscanf(buf, "%llu %llu", &pages, &resident) == 2);
  const double page = (double)sysconf(_SC_PAGESIZE);
  /* a scrape apart, so within a factor of two */
  ASSERT(rss > 1e6 && rss < 2 * (double)resident * page && rss > 0.5 * (double)resident * page);
  ASSERT(vsz >= rss);
  ASSERT(fds >= 3 && fabs(fds - fds_of(pid)) <= 8);
  snprintf(path, sizeof path, "/proc/%d/limits", (int)pid);
  f = fopen(path, "r");
  ASSERT(f);
  double want_max = -1;
  while (fgets(buf, sizeof buf, f))
    if (strncmp(buf, "Max open files", 14) == 0) want_max = strtod(buf + 26, NULL);
  fclose(f);
  ASSERT_EQ(max_fds, want_max);
  const double now = (double)time(NULL);
  ASSERT(start > now - 600 && start <= now + 1);
  ASSERT(cpu >= 0 && cpu < 600);
  h_resp_free(r);
}

/* Decoder children, and requests by result: the two frames of main decoded, then a
 * "PNG" that is not one is refused by a child, which stays alive. */
static void check_decoder_metrics(void) {
  h_resp *r = h_get("/metrics");
  const char *ok[] = {"result", "ok", NULL};
  const char *refused[] = {"result", "refused", NULL};
  ASSERT(metric(r->body, "fieldgrip_decoder_requests_total", ok) >= 2);
  ASSERT_EQ(metric(r->body, "fieldgrip_decoder_requests_total", refused), 0);
  ASSERT(family(r->body, "fieldgrip_decoder_starts_total", "counter") >= 1);
  family(r->body, "fieldgrip_decoder_processes", "gauge");
  family(r->body, "fieldgrip_decoder_idle_deaths_total", "counter");
  h_resp_free(r);

  static const char junk[] = "\x89PNG\r\n\x1a\n but not a PNG at all";
  const char *meta = "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0.5],[0,0,0,1]], "
                     "\"fl_x\": 30, \"fl_y\": 30, \"cx\": 16, \"cy\": 12}";
  r = h_upload("/v1/scenes/m/frames", junk, sizeof junk - 1, meta, NULL, 0);
  ASSERT(r->status == 400 || r->status == 415);
  h_resp_free(r);
  r = h_get("/metrics");
  ASSERT_EQ(metric(r->body, "fieldgrip_decoder_requests_total", refused), 1);
  const char *crashed[] = {"result", "crashed", NULL};
  ASSERT_EQ(metric(r->body, "fieldgrip_decoder_requests_total", crashed), 0);
  ASSERT(metric(r->body, "fieldgrip_decoder_processes", NULL) >= 1);
  h_resp_free(r);
}

/* A robot on a port where nothing listens: failed connection attempts count as
 * kind="connect", and no other kind moves; "connection" is not a kind any more. */
static void check_modbus_error_kinds(void) {
  int s = socket(AF_INET, SOCK_STREAM, 0);
  struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
  socklen_t alen = sizeof a;
  ASSERT(s >= 0 && bind(s, (struct sockaddr *)&a, sizeof a) == 0 &&
         getsockname(s, (struct sockaddr *)&a, &alen) == 0);
  close(s); /* the port is now closed: connecting to it is refused */
  char *conf = h_fmt("[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\n"
                     "timeout_ms = 300\n", ntohs(a.sin_port));
  h_stop();
  h_write_config(conf);
  free(conf);
  h_start();
  /* a command makes it try at once, besides its own retries */
  h_resp *r = h_post_json("/v1/robot/commands", "{\"command\": \"open\"}");
  ASSERT(r->status >= 500);
  h_resp_free(r);
  const char *connect[] = {"peer", "robot", "kind", "connect", NULL};
  for (int i = 0;; i++) {
    r = h_get("/metrics");
    double n = metric(r->body, "fieldgrip_modbus_errors_total", connect);
    if (n >= 1) break;
    if (i >= 500) FG_TEST_FAIL("no failed connection attempt counted:\n%s", r->body);
    h_resp_free(r);
    h_sleep_ms(20);
  }
  const char *transport[] = {"peer", "robot", "kind", "transport", NULL};
  const char *old[] = {"kind", "connection", NULL};
  ASSERT_EQ(metric(r->body, "fieldgrip_modbus_errors_total", transport), 0);
  ASSERT_EQ(metric(r->body, "fieldgrip_modbus_errors_total", old), -1);
  ASSERT_STRCONTAINS(r->body, "transport (a request failed on the wire");
  h_resp_free(r);
}

/* The environment the daemon runs with has GOMP_SPINCOUNT=1000, though it was started
 * without one. */
static void check_omp_spin(pid_t pid) {
  char path[64];
  snprintf(path, sizeof path, "/proc/%d/environ", (int)pid);
  FILE *f = fopen(path, "rb");
  ASSERT(f);
  char buf[65536];
  const size_t n = fread(buf, 1, sizeof buf - 1, f);
  fclose(f);
  buf[n] = 0;
  int found = 0;
  for (size_t i = 0; i < n; i += strlen(buf + i) + 1)
    if (strcmp(buf + i, "GOMP_SPINCOUNT=1000") == 0) found = 1;
  ASSERT(found);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  unsetenv("GOMP_SPINCOUNT"); /* the test environment sets it; the daemon must on its own */
  unsetenv("OMP_WAIT_POLICY");
  h_start();
  check_omp_spin(h_pid());

  const double t_first = h_now_s();
  for (int i = 0; i < 3; i++) {
    h_resp *r = h_get("/v1/health");
    ASSERT_STATUS(r, 200);
    h_resp_free(r);
  }
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"m\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"m\"}");
  ASSERT_HTTP_ERROR(r, 409, "scene_exists");
  h_resp_free(r);
  r = h_get("/v1/scenes/nope");
  ASSERT_HTTP_ERROR(r, 404, "scene_not_found");
  h_resp_free(r);
  r = h_get("/v1/scenes/m");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);

  uint8_t *png, *npy;
  size_t png_len, npy_len;
  h_png(32, 24, 3, 8, 1, 0, &png, &png_len);
  static const int shape[3] = {3, 4, 8};
  h_npy("<f4", shape, 3, 0, &npy, &npy_len);
  const char *meta = "{\"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0.5],[0,0,0,1]], "
                     "\"fl_x\": 30, \"fl_y\": 30, \"cx\": 16, \"cy\": 12}";
  for (int i = 0; i < 2; i++) {
    r = h_upload("/v1/scenes/m/frames", png, png_len, meta, npy, npy_len);
    ASSERT_STATUS(r, 201);
    h_resp_free(r);
  }
  r = h_upload("/v1/scenes/m/frames", png, png_len, NULL, npy, npy_len);
  ASSERT_HTTP_ERROR(r, 400, "missing_part");
  h_resp_free(r);
  free(png);
  free(npy);

  int scrapes = 0;
  r = scrape_settled(3 + 1 + 1 + 1 + 1 + 2 + 1, &scrapes);
  const double wall_s = h_now_s() - t_first;
  const char *ct = h_resp_header(r, "Content-Type");
  ASSERT(ct && strncasecmp(ct, "text/plain", 10) == 0);
  ASSERT_STRCONTAINS(ct, "version=0.0.4");
  const char *text = r->body;
  ASSERT_STRCONTAINS(text, "fieldgrip_http_requests_total{");
  ASSERT_STRCONTAINS(text, "# TYPE fieldgrip_http_requests_total counter");
  ASSERT_STRCONTAINS(text, "# TYPE fieldgrip_http_request_duration_seconds histogram");
  ASSERT_STRCONTAINS(text, "fieldgrip_frames_ingested_total");

  const char *bi[] = {"version", FG_VERSION, NULL};
  ASSERT_EQ(metric(text, "fieldgrip_build_info", bi), 1);
  expect_requests(text, "GET", "/v1/health", "200", 3);
  expect_requests(text, "POST", "/v1/scenes", "201", 1);
  expect_requests(text, "POST", "/v1/scenes", "409", 1);
  expect_requests(text, "GET", "/v1/scenes/{s}", "404", 1);
  expect_requests(text, "GET", "/v1/scenes/{s}", "200", 1);
  expect_requests(text, "POST", "/v1/scenes/{s}/frames", "201", 2);
  expect_requests(text, "POST", "/v1/scenes/{s}/frames", "400", 1);
  ASSERT_EQ(metric(text, "fieldgrip_frames_ingested_total", NULL), 2);
  ASSERT_EQ(metric(text, "fieldgrip_frames", NULL), 2);
  ASSERT_EQ(metric(text, "fieldgrip_scenes", NULL), 1);

  /* The histograms, per route. */
  expect_histogram(text, "/v1/health", 3, wall_s);
  expect_histogram(text, "/v1/scenes/{s}/frames", 3, wall_s);
  h_resp_free(r);

  /* Later scrapes see the earlier ones (once they are recorded), and nothing else changed. */
  int before = scrapes;
  for (int i = 0;; i++) {
    r = h_get("/metrics");
    ASSERT_STATUS(r, 200);
    scrapes++;
    const char *mw[] = {"method", "GET", "route", "/metrics", "code", "200", NULL};
    double seen = metric(r->body, "fieldgrip_http_requests_total", mw);
    ASSERT(seen <= scrapes);
    expect_requests(r->body, "GET", "/v1/health", "200", 3);
    h_resp_free(r);
    if (seen >= before) break;
    if (i >= 500) FG_TEST_FAIL("the /metrics route counts %g scrapes after %d", seen, scrapes);
    h_sleep_ms(20);
  }

  check_process_metrics();
  check_decoder_metrics();
  check_modbus_error_kinds();
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
