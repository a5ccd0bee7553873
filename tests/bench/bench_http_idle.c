/* GET /v1/health while N idle connections are open: bench_http_idle BASE_URL [N [REQUESTS]].
 *
 * Opens N TCP connections to the daemon at BASE_URL (http://127.0.0.1:PORT) that send
 * nothing, waits until the daemon has taken every one (held open, or shed at [http]
 * max_connections: fieldgrip_http_connections plus the shed count reach N), then times
 * REQUESTS (default 200) health requests, each on a new connection with "Connection: close",
 * from connect() to the end of the answer. Prints one line:
 *   bench=http_idle idle=N open=... shed=... requests=... p50_ms=... p99_ms=... max_ms=...
 * (run.sh adds the target). Raises its own open-files limit to the hard one. */
#include "benchstat.h"

#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

static int g_port;

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void die(const char *what) {
  fprintf(stderr, "bench_http_idle: %s: %s\n", what, strerror(errno));
  printf("bench=http_idle error=%s pass=no\n", what);
  exit(1);
}

static int open_conn(int nonblock) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | (nonblock ? SOCK_NONBLOCK : 0), 0);
  if (fd < 0) die("socket");
  struct sockaddr_in sa = {.sin_family = AF_INET, .sin_port = htons((uint16_t)g_port),
                           .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
  if (connect(fd, (struct sockaddr *)&sa, sizeof sa) != 0 && errno != EINPROGRESS)
    die("connect");
  return fd;
}

/* GET path with Connection: close; the whole answer into buf (NUL-terminated). Returns its
 * length; dies on a timeout of 30 s. */
static size_t get(const char *path, char *buf, size_t cap) {
  int fd = open_conn(0);
  char req[256];
  int n = snprintf(req, sizeof req, "GET %s HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                   "Connection: close\r\n\r\n", path);
  if (send(fd, req, (size_t)n, MSG_NOSIGNAL) != n) die("send");
  size_t got = 0;
  for (;;) {
    struct pollfd p = {fd, POLLIN, 0};
    if (poll(&p, 1, 30000) <= 0) die("no_answer_within_30s");
    ssize_t k = recv(fd, buf + got, cap - 1 - got, 0);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0 || got + (size_t)k >= cap - 1) {
      if (k > 0) got += (size_t)k;
      break;
    }
    got += (size_t)k;
  }
  close(fd);
  buf[got] = '\0';
  return got;
}

/* The value of one series of /metrics, or -1 when absent. */
static double metric(const char *series) {
  static char buf[1 << 16];
  get("/metrics", buf, sizeof buf);
  size_t n = strlen(series);
  for (const char *p = buf; (p = strstr(p, series)) != NULL; p += n)
    if (p[-1] == '\n' && p[n] == ' ') return strtod(p + n + 1, NULL);
  return -1;
}

int main(int argc, char **argv) {
  if (argc < 2 || sscanf(argv[1], "http://127.0.0.1:%d", &g_port) != 1) {
    fprintf(stderr, "usage: bench_http_idle http://127.0.0.1:PORT [N [REQUESTS]]\n");
    return 2;
  }
  int n = argc > 2 ? atoi(argv[2]) : 10000;
  int reqs = argc > 3 ? atoi(argv[3]) : 200;
  if (n < 0 || reqs < 1) return 2;
  struct rlimit rl;
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
    rl.rlim_cur = rl.rlim_max;
    setrlimit(RLIMIT_NOFILE, &rl);
  }
  int *fds = malloc((size_t)(n ? n : 1) * sizeof *fds);
  if (!fds) die("out_of_memory");
  double t0 = now_s();
  for (int i = 0; i < n; i++) fds[i] = open_conn(1);
  double opened_s = now_s() - t0;

  /* Every idle connection taken by the daemon: open (the scrape's own counted out) or shed. */
  double open = 0, shed = 0, until = now_s() + 60;
  for (;;) {
    open = metric("fieldgrip_http_connections") - 1;
    shed = metric("fieldgrip_http_connections_closed_total{reason=\"shed\"}");
    if (open + shed >= n || now_s() > until) break;
    usleep(20000);
  }
  if (open + shed < n) {
    printf("bench=http_idle error=only_%.0f_of_%d_connections_accepted_in_60s pass=no\n",
           open + shed, n);
    return 1;
  }

  double *lat = malloc((size_t)reqs * sizeof *lat);
  if (!lat) die("out_of_memory");
  char buf[1024];
  for (int i = 0; i < reqs; i++) {
    double s = now_s();
    get("/v1/health", buf, sizeof buf);
    lat[i] = now_s() - s;
    if (strncmp(buf, "HTTP/1.1 200", 12) != 0) {
      printf("bench=http_idle error=health_not_200 pass=no\n");
      return 1;
    }
  }
  const double p50 = bench_percentile(lat, reqs, 0.5), p99 = bench_percentile(lat, reqs, 0.99);
  /* Read again after the requests: each one past the cap shed an idle connection too. */
  open = metric("fieldgrip_http_connections") - 1;
  shed = metric("fieldgrip_http_connections_closed_total{reason=\"shed\"}");
  printf("bench=http_idle idle=%d opened_in_s=%.2f open=%.0f shed=%.0f requests=%d "
         "p50_ms=%.3f p99_ms=%.3f max_ms=%.3f\n",
         n, opened_s, open, shed, reqs, p50 * 1e3, p99 * 1e3, lat[reqs - 1] * 1e3);
  for (int k = 0; k < n; k++) close(fds[k]);
  free(fds);
  free(lat);
  return 0;
}
