/* Fuzz target for the HTTP layer's request parsing, multipart uploads above all: the input
 * is one raw HTTP request (or several, pipelined) sent to the real fg_http server (http.c,
 * libmicrohttpd underneath) over loopback, so libmicrohttpd's post processor and http.c's
 * on_part (part accumulation, a part given twice, the part count limit), the body limits and
 * the routing all run as they do in the daemon. The route table is small: one multipart
 * route like the frame upload (POST /up, offloaded) and one JSON route (POST /json, its body
 * through fg_api_body_object).
 *
 * The server starts once, on 127.0.0.1 with a free port; each input opens a connection,
 * writes the bytes, half-closes and reads the answer until the server closes (an answer
 * that takes longer than the server's own timeouts is a finding: abort). The handlers
 * check what the layer hands them: at most FG_HTTP_MAX_PARTS parts, each named, distinct,
 * NUL-terminated at its length. A broken invariant aborts in the server's thread, which the
 * sanitizers and libFuzzer report as a crash of this input. */
#include "api/api.h"
#include "conf/conf.h"
#include "http/http.h"

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static fg_conf *conf;

static const fg_conf *conf_acquire(fg_app *app) {
  (void)app;
  return conf;
}

static void conf_release(fg_app *app, const fg_conf *c) {
  (void)app;
  (void)c;
}

static int upload(fg_req *req, fg_resp *resp) {
  if (req->n_parts < 0 || req->n_parts > FG_HTTP_MAX_PARTS) abort();
  for (int i = 0; i < req->n_parts; i++) {
    const fg_part *p = &req->parts[i];
    if (!p->name || (p->len && !p->data) || (p->data && p->data[p->len] != 0)) abort();
    if (p->len > p->cap) abort();
    for (int j = 0; j < i; j++)
      if (strcmp(req->parts[j].name, p->name) == 0) abort();
    if (fg_req_part(req, p->name) != p) abort();
  }
  fg_resp_json(resp, 200, json_pack("{s:i}", "parts", req->n_parts));
  return 0;
}

static int json_body(fg_req *req, fg_resp *resp) {
  if (req->body && req->body[req->body_len] != 0) abort();
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return 0;
  fg_resp_json(resp, 200, json_pack("{s:i}", "keys", (int)json_object_size(body)));
  json_decref(body);
  return 0;
}

static const fg_route routes[] = {
  {"POST", "/up", "/up", upload, FG_ROUTE_MULTIPART | FG_ROUTE_OFFLOAD | FG_ROUTE_LARGE_BODY},
  {"POST", "/json", "/json", json_body, 0},
};

static struct sockaddr_in server;

/* Starts the server once; exits when it cannot (no loopback: nothing to fuzz). */
static void start(void) {
  if (conf) return;
  conf = fg_conf_defaults();
  if (!conf) exit(2);
  /* small limits, so that the 413 paths are reachable by small inputs */
  conf->max_json_bytes = 4096;
  conf->max_upload_bytes = 16384;
  /* short timeouts: a FIN the server missed (below) costs a second, not a minute, so the
   * client's 30 s guard is never reached however loaded the machine is */
  conf->header_timeout_s = 1;
  conf->idle_timeout_s = 1;
  /* the seeds say "Host: x": a name, refused unless listed, which would stop every input at
   * the Host check before the parsing this target is about */
  if (fg_conf_split_list("x", fg_conf_check_host_name, &conf->allowed_hosts,
                         &conf->n_allowed_hosts) != 0)
    exit(2);
  fg_http_config cfg = {
    .listen = "127.0.0.1:0", .poll_threads = 1, .offload_threads = 1, .routes = routes,
    .n_routes = sizeof routes / sizeof routes[0], .conf_acquire = conf_acquire,
    .conf_release = conf_release};
  fg_http *h;
  char bound[128];
  if (fg_http_start(&h, &cfg, bound, sizeof bound) != 0) {
    fprintf(stderr, "fuzz_multipart: cannot start the server on loopback\n");
    exit(2);
  }
  const char *port = strrchr(bound, ':');
  server.sin_family = AF_INET;
  server.sin_port = htons((uint16_t)atoi(port + 1));
  server.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  /* h lives as long as the process: every input talks to it */
}

/* connect() to the server. A signal (libFuzzer's timer) may interrupt it; the connection
 * then completes on its own and its outcome is read once the socket is writable. */
static int connect_server(int fd) {
  if (connect(fd, (const struct sockaddr *)&server, sizeof server) == 0) return 0;
  if (errno != EINTR) return -1;
  struct pollfd p = {.fd = fd, .events = POLLOUT};
  int n;
  while ((n = poll(&p, 1, 30000)) < 0 && errno == EINTR) {
  }
  int err = 0;
  socklen_t len = sizeof err;
  if (n != 1 || getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len) != 0) return -1;
  errno = err;
  return err ? -1 : 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  start();
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0 || connect_server(fd) != 0) {
    fprintf(stderr, "fuzz_multipart: cannot connect to the server: %s\n", strerror(errno));
    abort();
  }
  /* The server may answer and close before it has read everything (413): stop writing then. */
  size_t off = 0;
  while (off < size) {
    ssize_t w = send(fd, data + off, size - off, MSG_NOSIGNAL);
    if (w <= 0) break;
    off += (size_t)w;
  }
  /* libmicrohttpd (epoll, edge-triggered) takes a short read for a drained socket, so a FIN
   * that arrives together with the request's last bytes goes unnoticed until a timeout closes
   * the connection (the header timeout for an unfinished body, the idle timeout after an
   * answer; both 1 s here). Half-close only once the server has answered or had a moment to
   * read, so the FIN is usually an event of its own and an input takes microseconds. */
  struct pollfd first = {.fd = fd, .events = POLLIN};
  (void)poll(&first, 1, 5);
  shutdown(fd, SHUT_WR);
  char buf[4096];
  for (;;) {
    struct pollfd p = {.fd = fd, .events = POLLIN};
    /* generous: the server closes at once on EOF; only a stuck server runs into this */
    int n = poll(&p, 1, 30000);
    if (n == 0) {
      fprintf(stderr, "fuzz_multipart: the server did not close the connection in 30 s\n");
      abort();
    }
    if (n < 0) break;
    ssize_t r = recv(fd, buf, sizeof buf, 0);
    if (r <= 0) break;
  }
  /* The client closes second, so its end of every connection would wait in TIME_WAIT for a
   * minute: at hundreds of inputs a second that uses up loopback's ephemeral ports and
   * connect() fails. A reset leaves nothing behind. */
  const struct linger reset = {.l_onoff = 1, .l_linger = 0};
  setsockopt(fd, SOL_SOCKET, SO_LINGER, &reset, sizeof reset);
  close(fd);
  return 0;
}
