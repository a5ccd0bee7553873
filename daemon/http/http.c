#include "http.h"

#include "conf/conf.h"
#include "http_conns.h"
#include "http_guard.h"
#include "metrics/metrics.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/log.h"

#include <microhttpd.h>

#include <math.h>
#include <arpa/inet.h>
#include <netdb.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/resource.h>
#include <time.h>

/* How often the connection table is swept for connections past their deadlines. */
#define SWEEP_MS 250

/* The metrics count closed connections by fg_conn_reason under their own names. */
_Static_assert((int)FG_METRICS_CLOSE_SHED == FG_CONN_SHED &&
                   (int)FG_METRICS_CLOSE_HEADER_TIMEOUT == FG_CONN_HEADER_TIMEOUT &&
                   (int)FG_METRICS_CLOSE_IDLE_TIMEOUT == FG_CONN_IDLE_TIMEOUT &&
                   (int)FG_METRICS_CLOSE_BODY_TOO_SLOW == FG_CONN_BODY_TOO_SLOW &&
                   (int)FG_METRICS_CLOSE_REASONS == FG_CONN_REASONS,
               "metrics.h's close reasons follow http_conns.h's");

/* File descriptors kept for everything but client connections: state files, the decoder
 * children's pipes, Modbus peers, the log. */
#define FD_RESERVE 256

/* ---------------------------------------------------------------- per-request state */

enum { STAGE_RECEIVING, STAGE_OFFLOADED, STAGE_DONE };

typedef struct conn_ctx {
  struct fg_http *http;
  struct MHD_Connection *conn;
  fg_req req;
  fg_resp resp;
  const fg_route *route;
  int route_idx;
  int stage;
  int ready;                  /* an offloaded handler finished; its response waits */
  size_t limit, received;
  int too_large;
  int bad_multipart;          /* the multipart body could not be parsed */
  char multipart_error[160];
  struct MHD_PostProcessor *pp;
  struct timespec start;
  fg_conn *track;             /* the connection's entry in the table; NULL if untracked */
  struct conn_ctx *next;      /* offload queue */
} conn_ctx;

/* A streamed body in flight (fg_resp_stream): owned by libmicrohttpd's response object,
 * freed by its free callback (stream_free). */
typedef struct http_stream {
  struct fg_http *http;
  struct MHD_Connection *conn;
  const fg_stream_ops *ops;
  void *ctx;
  int parked;                 /* suspended until the ticker resumes it; guarded by slock */
  struct http_stream *prev, *next;
} http_stream;

struct fg_http {
  struct MHD_Daemon *mhd;
  fg_http_config cfg;
  pthread_t *workers;
  int n_workers;
  pthread_mutex_t qlock;
  pthread_cond_t qcond;
  conn_ctx *qhead, *qtail;
  int n_queued, n_running;    /* requests in the offload queue, and handlers running */
  int stopping;
  /* Client connections (http_conns.h) and the thread that enforces their deadlines. */
  fg_conns *conns;
  pthread_cond_t sweep_cond;  /* with qlock; signalled at stop */
  int sweeper_started;
  pthread_t sweeper;
  int idle_timeout_s;         /* libmicrohttpd's default connection timeout, set at start */
  /* Streamed bodies: every live one, and the ticker thread that resumes parked ones. */
  pthread_mutex_t slock;
  pthread_cond_t scond;
  http_stream *streams;
  int streams_closing;        /* fg_http_stop began: no stream parks any more */
  int ticker_started;
  pthread_t ticker;
};

/* ---------------------------------------------------------------- routing */

/* Matches a path against a pattern whose "{}" segments capture one non-empty segment.
 * Captured segments are copied into params (owned by the caller) only on a match. */
static int match_path(const char *pattern, const char *path, char **params, int *n_params) {
  const char *p = pattern, *s = path;
  const char *caps[FG_HTTP_MAX_PARAMS];
  size_t lens[FG_HTTP_MAX_PARAMS];
  int n = 0;
  while (*p && *s) {
    if (p[0] == '{' && p[1] == '}') {
      const char *end = strchr(s, '/');
      size_t len = end ? (size_t)(end - s) : strlen(s);
      if (len == 0 || n == FG_HTTP_MAX_PARAMS) return 0;
      caps[n] = s;
      lens[n++] = len;
      s += len;
      p += 2;
    } else if (*p == *s) {
      p++, s++;
    } else {
      return 0;
    }
  }
  if (*s == '/' && s[1] == '\0') s++; /* tolerate one trailing slash */
  if (*p || *s) return 0;
  if (params) {
    for (int i = 0; i < n; i++) params[i] = strndup(caps[i], lens[i]);
    *n_params = n;
  }
  return 1;
}

/* Compares a presented secret with the configured one in time that depends only on the
 * configured one's length. */
static int token_equal(const char *given, size_t given_len, const char *secret) {
  size_t n = strlen(secret);
  unsigned diff = (unsigned)(given_len != n);
  for (size_t i = 0; i < n; i++)
    diff |= (unsigned char)(i < given_len ? given[i] : 0) ^ (unsigned char)secret[i];
  return diff == 0;
}

/* Checks the bearer token. public_route says the path is one that needs none; unknown
 * paths need the token too, so that the API's shape is not visible without it. */
static int authorized(const conn_ctx *c, int public_route) {
  const char *token = c->req.conf->token;
  if (!token || !*token || public_route) return 1;
  const char *h = fg_req_header(&c->req, MHD_HTTP_HEADER_AUTHORIZATION);
  if (!h || strncasecmp(h, "Bearer ", 7) != 0) return 0;
  h += 7;
  while (*h == ' ') h++;
  return token_equal(h, strlen(h), token);
}

/* ---------------------------------------------------------------- streamed bodies */

/* Streamed bodies and libmicrohttpd 0.9.75. The server runs a pool of polling threads with
 * epoll (MHD_USE_INTERNAL_POLLING_THREAD + MHD_OPTION_THREAD_POOL_SIZE), each thread serving
 * many connections. A content-reader callback that blocks until an event would hold its
 * polling thread and every connection on it. Returning 0 ("nothing yet") alone is allowed
 * but spins: the connection stays in MHD_CONNECTION_CHUNKED_BODY_UNREADY on the thread's
 * "ready" list, which makes its epoll_wait time out at once (MHD_get_timeout) and call the
 * reader again, so each idle stream would burn a polling thread's core (microhttpd.h: "use
 * zero only with MHD_suspend_connection() to avoid busy waiting"). MHD allows suspending
 * from inside the reader: the connection leaves the event loop (no thread, no CPU, no
 * timeout) until MHD_resume_connection(), after which MHD calls the reader again.
 *
 * So: stream_reader asks the producer for bytes; when it has none, it marks the stream
 * parked and suspends the connection, both under slock. The ticker thread wakes every
 * FG_HTTP_STREAM_TICK_MS while any stream is parked, asks each parked stream's producer whether
 * it is ready, and resumes those that are, clearing parked under the same lock; so resume
 * always follows a completed suspend. A dead client is noticed when the next write fails
 * (producers send a keep-alive comment now and then). fg_http_stop sets streams_closing,
 * resumes every parked stream and lets the readers end their bodies, so no connection is
 * suspended when MHD_stop_daemon runs (an API violation in libmicrohttpd). */


static ssize_t stream_reader(void *cls, uint64_t pos, char *buf, size_t max) {
  (void)pos;
  http_stream *hs = cls;
  fg_http *h = hs->http;
  pthread_mutex_lock(&h->slock);
  int closing = h->streams_closing;
  pthread_mutex_unlock(&h->slock);
  long n = hs->ops->read(hs->ctx, buf, max, closing);
  if (n > 0) return (ssize_t)(n > (long)max ? (long)max : n);
  if (n < 0) return MHD_CONTENT_READER_END_OF_STREAM;
  pthread_mutex_lock(&h->slock);
  if (h->streams_closing) { /* fg_http_stop began after the read: never park now */
    pthread_mutex_unlock(&h->slock);
    n = hs->ops->read(hs->ctx, buf, max, 1);
    return n > 0 ? (ssize_t)(n > (long)max ? (long)max : n) : MHD_CONTENT_READER_END_OF_STREAM;
  }
  hs->parked = 1;
  MHD_suspend_connection(hs->conn);
  pthread_cond_signal(&h->scond);
  pthread_mutex_unlock(&h->slock);
  return 0;
}

static void stream_free(void *cls) {
  http_stream *hs = cls;
  fg_http *h = hs->http;
  pthread_mutex_lock(&h->slock);
  if (hs->prev) hs->prev->next = hs->next;
  else h->streams = hs->next;
  if (hs->next) hs->next->prev = hs->prev;
  pthread_mutex_unlock(&h->slock);
  if (hs->ops->free) hs->ops->free(hs->ctx);
  free(hs);
}

/* Resumes parked streams whose producer is ready; sleeps while no stream is parked. */
static void *ticker_main(void *arg) {
  fg_http *h = arg;
  pthread_setname_np(pthread_self(), "fg-stream");
  pthread_mutex_lock(&h->slock);
  while (!h->streams_closing) {
    int any_parked = 0;
    double now = fg_mono_s();
    for (http_stream *hs = h->streams; hs; hs = hs->next) {
      if (!hs->parked) continue;
      if (hs->ops->ready(hs->ctx, now)) {
        hs->parked = 0;
        MHD_resume_connection(hs->conn);
      } else {
        any_parked = 1;
      }
    }
    if (!any_parked) {
      pthread_cond_wait(&h->scond, &h->slock); /* a stream parked, or stop */
      continue;
    }
    struct timespec until;
    fg_deadline_after_ms(&until, CLOCK_REALTIME, FG_HTTP_STREAM_TICK_MS);
    pthread_cond_timedwait(&h->scond, &h->slock, &until);
  }
  pthread_mutex_unlock(&h->slock);
  return NULL;
}

/* Hands a streamed body to libmicrohttpd; r->stream_* are owned by it afterwards. */
static struct MHD_Response *stream_response(conn_ctx *c) {
  fg_http *h = c->http;
  fg_resp *r = &c->resp;
  http_stream *hs = calloc(1, sizeof *hs);
  if (!hs) return NULL;
  hs->http = h;
  hs->conn = c->conn;
  hs->ops = r->stream_ops;
  hs->ctx = r->stream_ctx;
  struct MHD_Response *mr =
    MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, stream_reader, hs, stream_free);
  if (!mr) {
    free(hs);
    return NULL;
  }
  r->stream_ops = NULL; /* stream_free owns the producer now */
  r->stream_ctx = NULL;
  pthread_mutex_lock(&h->slock);
  hs->next = h->streams;
  if (h->streams) h->streams->prev = hs;
  h->streams = hs;
  pthread_mutex_unlock(&h->slock);
  MHD_add_response_header(mr, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
  MHD_add_response_header(mr, "X-Accel-Buffering", "no");
  return mr;
}

/* ---------------------------------------------------------------- sending */

static enum MHD_Result send_response(conn_ctx *c) {
  fg_resp *r = &c->resp;
  if (r->status == 0) fg_resp_error(r, 500, "internal_error", "the handler produced no response");
  struct MHD_Response *mr = NULL;
  if (r->stream_ops) {
    mr = stream_response(c);
    if (!mr) fg_resp_error(r, 500, "internal_error", "out of memory starting the stream");
  }
  if (!mr)
    mr = r->body ? MHD_create_response_from_buffer(r->len, r->body, MHD_RESPMEM_MUST_FREE)
                 : MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
  if (!mr) return MHD_NO;
  r->body = NULL; /* owned by libmicrohttpd now */
  if (r->content_type) MHD_add_response_header(mr, MHD_HTTP_HEADER_CONTENT_TYPE, r->content_type);
  if (r->allow[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_ALLOW, r->allow);
  if (r->location[0]) MHD_add_response_header(mr, MHD_HTTP_HEADER_LOCATION, r->location);
  for (char *line = r->header; line && *line;) { /* "Name: value" lines */
    char *end = strstr(line, "\r\n"), *colon = strstr(line, ": ");
    if (end) *end = 0;
    if (colon) {
      *colon = 0;
      MHD_add_response_header(mr, line, colon + 2);
    }
    line = end ? end + 2 : NULL;
  }
  if (r->status == 401)
    MHD_add_response_header(mr, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"fieldgrip\"");
  enum MHD_Result ok = MHD_queue_response(c->conn, (unsigned)r->status, mr);
  MHD_destroy_response(mr);
  c->stage = STAGE_DONE;
  return ok;
}

/* ---------------------------------------------------------------- multipart */

static enum MHD_Result on_part(void *cls, enum MHD_ValueKind kind, const char *key,
                               const char *filename, const char *content_type,
                               const char *transfer_encoding, const char *data, uint64_t off,
                               size_t size) {
  conn_ctx *c = cls;
  fg_req *q = &c->req;
  if (!key) return MHD_YES;
  fg_part *part = NULL;
  for (int i = 0; i < q->n_parts; i++)
    if (strcmp(q->parts[i].name, key) == 0) part = &q->parts[i];
  if (part && off == 0 && part->len > 0) {
    snprintf(c->multipart_error, sizeof c->multipart_error, "part '%s' appears twice", key);
    c->bad_multipart = 1;
    return MHD_NO;
  }
  if (!part) {
    if (q->n_parts == FG_HTTP_MAX_PARTS) {
      snprintf(c->multipart_error, sizeof c->multipart_error, "more than %d parts",
               FG_HTTP_MAX_PARTS);
      c->bad_multipart = 1;
      return MHD_NO;
    }
    part = &q->parts[q->n_parts++];
    part->name = strdup(key);
    part->filename = filename ? strdup(filename) : NULL;
    part->content_type = content_type ? strdup(content_type) : NULL;
    if (!part->name) return MHD_NO;
  }
  if (part->len + size + 1 > part->cap) {
    size_t cap = part->cap ? part->cap : 4096;
    while (cap < part->len + size + 1) cap *= 2;
    uint8_t *p = realloc(part->data, cap);
    if (!p) return MHD_NO;
    part->data = p;
    part->cap = cap;
  }
  memcpy(part->data + part->len, data, size);
  part->len += size;
  part->data[part->len] = 0;
  return MHD_YES;
}

static int append_body(fg_req *q, const char *data, size_t size) {
  uint8_t *p = realloc(q->body, q->body_len + size + 1);
  if (!p) return -1;
  memcpy(p + q->body_len, data, size);
  q->body = p;
  q->body_len += size;
  q->body[q->body_len] = 0;
  return 0;
}

/* ---------------------------------------------------------------- offload pool */

static void *offload_main(void *arg) {
  fg_http *h = arg;
  pthread_setname_np(pthread_self(), "fg-offload");
  for (;;) {
    pthread_mutex_lock(&h->qlock);
    while (!h->qhead && !h->stopping) pthread_cond_wait(&h->qcond, &h->qlock);
    conn_ctx *c = h->qhead;
    if (!c) {
      pthread_mutex_unlock(&h->qlock);
      return NULL;
    }
    h->qhead = c->next;
    if (!h->qhead) h->qtail = NULL;
    h->n_queued--;
    h->n_running++;
    fg_metrics_set_offload(h->n_workers, h->n_running, h->n_queued);
    pthread_mutex_unlock(&h->qlock);

    fg_error_clear();
    c->route->handler(&c->req, &c->resp);
    pthread_mutex_lock(&h->qlock);
    h->n_running--;
    fg_metrics_set_offload(h->n_workers, h->n_running, h->n_queued);
    pthread_mutex_unlock(&h->qlock);
    c->ready = 1;
    MHD_resume_connection(c->conn);
  }
}

/* Queues c for the pool. -1 once fg_http_stop has begun (the pool may be gone, and nothing
 * may stay suspended when MHD_stop_daemon runs); -2 when max_queued requests already wait:
 * a bounded queue keeps a burst of uploads from holding their bodies in memory without
 * end, and tells clients to come back instead. */
static int offload(fg_http *h, conn_ctx *c, int max_queued) {
  pthread_mutex_lock(&h->qlock);
  if (h->stopping || h->n_queued >= max_queued) {
    int rc = h->stopping ? -1 : -2;
    pthread_mutex_unlock(&h->qlock);
    return rc;
  }
  h->n_queued++;
  fg_metrics_set_offload(h->n_workers, h->n_running, h->n_queued);
  c->stage = STAGE_OFFLOADED;
  MHD_suspend_connection(c->conn);
  c->next = NULL;
  if (h->qtail) h->qtail->next = c;
  else h->qhead = c;
  h->qtail = c;
  pthread_cond_signal(&h->qcond);
  pthread_mutex_unlock(&h->qlock);
  return 0;
}

/* ---------------------------------------------------------------- the access handler */

static enum MHD_Result respond_now(conn_ctx *c, int status, const char *code, const char *msg) {
  fg_conns_request_ready(c->http->conns, c->track);
  fg_resp_error(&c->resp, status, code, "%s", msg);
  return send_response(c);
}

/* The 413 message for c's route: the body's size (0: unknown) and the key that sets the
 * limit. */
static void limit_message(const conn_ctx *c, char *msg, size_t cap, unsigned long long n) {
  char size[48] = "the body is larger";
  if (n) snprintf(size, sizeof size, "the body has %llu bytes,", n);
  if (c->route->flags & FG_ROUTE_LARGE_BODY)
    snprintf(msg, cap, "%s more than the limit of %zu MB ([http] max_upload_mb)", size,
             c->limit >> 20);
  else
    snprintf(msg, cap, "%s more than the limit of %zu KiB for a JSON body ([http] max_json_kb)",
             size, c->limit >> 10);
}

/* First call for a request: route it, check the token and the announced size, and get
 * ready to receive the body. Answers at once (before any body byte is read) when the
 * request cannot succeed. */
static enum MHD_Result begin_request(fg_http *h, conn_ctx *c, const char *url, const char *method) {
  c->req.conf = h->cfg.conf_acquire(h->cfg.app);
  c->req.app = h->cfg.app;
  c->req.method = method;
  c->req.path = url;
  c->req.mhd_conn = c->conn;
  c->req.content_type = fg_req_header(&c->req, MHD_HTTP_HEADER_CONTENT_TYPE);
  const fg_conf *conf = c->req.conf;
  if (conf->idle_timeout_s != h->idle_timeout_s) /* changed by a reload */
    MHD_set_connection_option(c->conn, MHD_CONNECTION_OPTION_TIMEOUT,
                              (unsigned)conf->idle_timeout_s);

  /* Before the token and the routes: a rebound name must not even learn what exists. */
  const char *host = fg_req_header(&c->req, MHD_HTTP_HEADER_HOST);
  if (fg_guard_host(conf, host) != 0)
    return respond_now(c, 403, "host_not_allowed", fg_error_detail());
  if (fg_guard_origin(conf, method, host, fg_req_header(&c->req, "Origin")) != 0)
    return respond_now(c, 403, "origin_not_allowed", fg_error_detail());

  int path_known = 0, public_route = 0;
  for (size_t i = 0; i < h->cfg.n_routes; i++) {
    const fg_route *r = &h->cfg.routes[i];
    if (!match_path(r->pattern, url, NULL, NULL)) continue;
    path_known = 1;
    public_route |= (r->flags & FG_ROUTE_PUBLIC) && strcmp(r->method, method) == 0;
    if (strcmp(r->method, method) == 0) {
      c->route = r;
      c->route_idx = (int)i;
      match_path(r->pattern, url, c->req.params, &c->req.n_params);
      break;
    }
    size_t al = strlen(c->resp.allow);
    snprintf(c->resp.allow + al, sizeof c->resp.allow - al, "%s%s", al ? ", " : "", r->method);
  }
  if (!authorized(c, public_route)) {
    c->resp.allow[0] = 0;
    return respond_now(c, 401, "unauthorized",
                       "this server needs \"Authorization: Bearer <token>\" with the token of its "
                       "configuration ([http] token or the file [http] token_file names)");
  }
  if (!c->route) {
    if (path_known) {
      char msg[160];
      snprintf(msg, sizeof msg, "%s is not allowed on %s; allowed: %s", method, url, c->resp.allow);
      return respond_now(c, 405, "method_not_allowed", msg);
    }
    c->resp.allow[0] = 0;
    char msg[300];
    snprintf(msg, sizeof msg, "no endpoint at %.200s; see proto/openapi.yaml for the API", url);
    return respond_now(c, 404, "not_found", msg);
  }
  c->resp.allow[0] = 0;

  /* Images are large; every other body is JSON, kept small so that many clients at once
   * cannot make the daemon hold much. */
  c->limit = (c->route->flags & FG_ROUTE_LARGE_BODY) ? conf->max_upload_bytes
                                                     : conf->max_json_bytes;
  const char *cl = fg_req_header(&c->req, MHD_HTTP_HEADER_CONTENT_LENGTH);
  if (cl) {
    char *end;
    unsigned long long n = strtoull(cl, &end, 10);
    if (*end == '\0' && n > c->limit) {
      char msg[200];
      limit_message(c, msg, sizeof msg, n);
      return respond_now(c, 413, "payload_too_large", msg);
    }
  }
  const int has_body = (cl && strtoull(cl, NULL, 10) > 0) ||
                       fg_req_header(&c->req, MHD_HTTP_HEADER_TRANSFER_ENCODING);
  if (fg_guard_body_type(c->route->flags, method, has_body, c->req.content_type) != 0)
    return respond_now(c, 415, "unsupported_media_type", fg_error_detail());
  if (c->route->flags & FG_ROUTE_MULTIPART) {
    c->pp = MHD_create_post_processor(c->conn, 64 * 1024, on_part, c);
    if (!c->pp)
      return respond_now(c, 400, "invalid_request",
                         "the multipart/form-data body has no boundary parameter");
  }
  return MHD_YES;
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *conn, const char *url,
                                  const char *method, const char *version, const char *upload_data,
                                  size_t *upload_data_size, void **con_cls) {
  fg_http *h = cls;
  conn_ctx *c = *con_cls;
  if (!c) {
    c = calloc(1, sizeof *c);
    if (!c) return MHD_NO;
    *con_cls = c;
    c->http = h;
    c->conn = conn;
    c->route_idx = -1;
    clock_gettime(CLOCK_MONOTONIC, &c->start);
    const union MHD_ConnectionInfo *ci =
      MHD_get_connection_info(conn, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
    c->track = ci ? ci->socket_context : NULL;
    fg_conns_request_begin(h->conns, c->track,
                           (double)c->start.tv_sec + (double)c->start.tv_nsec * 1e-9);
    return begin_request(h, c, url, method);
  }
  if (c->ready) { /* back from the offload pool */
    c->ready = 0;
    return send_response(c);
  }
  if (c->stage != STAGE_RECEIVING) {
    *upload_data_size = 0; /* answered or in the pool: discard what is still arriving */
    return MHD_YES;
  }
  if (*upload_data_size) {
    size_t n = *upload_data_size;
    *upload_data_size = 0;
    c->received += n;
    fg_conns_body(h->conns, c->track, n);
    if (c->received > c->limit) {
      c->too_large = 1;
      /* Discard, so the client gets its 413; a body that goes on far past the limit is cut. */
      return c->received > 2 * c->limit ? MHD_NO : MHD_YES;
    }
    if (c->pp) {
      if (!c->bad_multipart && MHD_post_process(c->pp, upload_data, n) != MHD_YES &&
          !c->bad_multipart) {
        c->bad_multipart = 1;
        snprintf(c->multipart_error, sizeof c->multipart_error, "malformed multipart body");
      }
    } else if (append_body(&c->req, upload_data, n) != 0) {
      return MHD_NO;
    }
    return MHD_YES;
  }
  /* The whole body is in. */
  fg_conns_request_ready(h->conns, c->track);
  if (c->too_large) {
    char msg[200];
    limit_message(c, msg, sizeof msg, 0);
    return respond_now(c, 413, "payload_too_large", msg);
  }
  if (c->pp) {
    if (MHD_destroy_post_processor(c->pp) != MHD_YES && !c->bad_multipart) {
      c->bad_multipart = 1;
      snprintf(c->multipart_error, sizeof c->multipart_error,
               "the multipart body ends early or is malformed");
    }
    c->pp = NULL;
  }
  if (c->bad_multipart) {
    char msg[240];
    snprintf(msg, sizeof msg, "cannot read the multipart/form-data body: %s", c->multipart_error);
    return respond_now(c, 400, "invalid_request", msg);
  }
  if (c->route->flags & FG_ROUTE_OFFLOAD) {
    int rc = offload(h, c, c->req.conf->max_queued_requests);
    if (rc == 0) return MHD_YES;
    if (rc == -1)
      return respond_now(c, 503, "shutting_down", "the daemon is shutting down; send the "
                         "request again once it is back");
    fg_metrics_count_offload_rejected();
    snprintf(c->resp.header, sizeof c->resp.header, "Retry-After: 1");
    char msg[200];
    snprintf(msg, sizeof msg, "%d requests for long work are waiting already ([http] "
             "max_queued_requests); send this one again in a second",
             c->req.conf->max_queued_requests);
    return respond_now(c, 503, "server_busy", msg);
  }
  fg_error_clear();
  c->route->handler(&c->req, &c->resp);
  return send_response(c);
}

static void on_completed(void *cls, struct MHD_Connection *conn, void **con_cls,
                         enum MHD_RequestTerminationCode toe) {
  fg_http *h = cls;
  conn_ctx *c = *con_cls;
  if (!c) return;
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  double secs = (double)(now.tv_sec - c->start.tv_sec) + (now.tv_nsec - c->start.tv_nsec) * 1e-9;
  int status = c->resp.status ? c->resp.status : 499;
  fg_metrics_observe_request(c->route_idx, status, secs);
  fg_conns_request_end(h->conns, c->track, (double)now.tv_sec + (double)now.tv_nsec * 1e-9);
  fg_debug("%s %s -> %d in %.1f ms%s", c->req.method ? c->req.method : "?",
           c->req.path ? c->req.path : "?", status, secs * 1e3,
           toe == MHD_REQUEST_TERMINATED_COMPLETED_OK ? "" : " (connection ended early)");
  if (c->pp) MHD_destroy_post_processor(c->pp);
  for (int i = 0; i < c->req.n_params; i++) free(c->req.params[i]);
  for (int i = 0; i < c->req.n_parts; i++) {
    free(c->req.parts[i].name);
    free(c->req.parts[i].filename);
    free(c->req.parts[i].content_type);
    free(c->req.parts[i].data);
  }
  free(c->req.body);
  fg_resp_take(&c->resp, 0, NULL, NULL, 0); /* frees the body, or a stream never sent */
  if (c->req.conf) h->cfg.conf_release(h->cfg.app, c->req.conf);
  free(c);
  *con_cls = NULL;
}

/* ---------------------------------------------------------------- connections */

/* libmicrohttpd opened or closed a client connection: keep the table in step. The entry
 * goes into the connection's socket context, where the access handler finds it. */
static void on_connection(void *cls, struct MHD_Connection *conn, void **socket_context,
                          enum MHD_ConnectionNotificationCode code) {
  fg_http *h = cls;
  if (code == MHD_CONNECTION_NOTIFY_CLOSED) {
    fg_conns_close(h->conns, *socket_context);
    *socket_context = NULL;
    fg_metrics_add_http_connections(-1);
    return;
  }
  const union MHD_ConnectionInfo *ci =
    MHD_get_connection_info(conn, MHD_CONNECTION_INFO_CONNECTION_FD);
  if (ci) {
    int shed = 0;
    *socket_context = fg_conns_open(h->conns, ci->connect_fd, fg_mono_s(), &shed);
    if (shed) fg_metrics_count_http_closed(FG_METRICS_CLOSE_SHED, 1);
  }
  /* Counted once it is in the table (and uncounted above once it has left), so a scrape
   * that sees a connection can rely on its place in the shedding order. */
  fg_metrics_add_http_connections(1);
}

/* Shuts down connections past their deadlines every SWEEP_MS, under the limits of the
 * configuration in force (a reload changes them for every connection at the next sweep). */
static void *sweeper_main(void *arg) {
  fg_http *h = arg;
  pthread_setname_np(pthread_self(), "fg-http-sweep");
  pthread_mutex_lock(&h->qlock);
  while (!h->stopping) {
    pthread_mutex_unlock(&h->qlock);
    const fg_conf *conf = h->cfg.conf_acquire(h->cfg.app);
    fg_conns_limits lim = {.header_timeout_s = conf->header_timeout_s,
                           .idle_timeout_s = conf->idle_timeout_s,
                           .min_body_bytes_per_s = (double)conf->min_body_bytes_per_s};
    h->cfg.conf_release(h->cfg.app, conf);
    size_t closed[FG_CONN_REASONS] = {0};
    if (fg_conns_sweep(h->conns, &lim, fg_mono_s(), closed) > 0)
      for (int r = 0; r < FG_CONN_REASONS; r++)
        if (closed[r]) fg_metrics_count_http_closed(r, closed[r]);
    struct timespec until;
    fg_deadline_after_ms(&until, CLOCK_MONOTONIC, SWEEP_MS);
    pthread_mutex_lock(&h->qlock);
    if (!h->stopping) pthread_cond_timedwait(&h->sweep_cond, &h->qlock, &until);
  }
  pthread_mutex_unlock(&h->qlock);
  return NULL;
}

/* The connection cap that fits the open-files limit: libmicrohttpd's hard limit (a little
 * above the cap, where it refuses new connections outright) plus FD_RESERVE must stay under
 * it, or accept() would fail with EMFILE and leave every new client waiting in the kernel's
 * backlog. */
static size_t cap_for_fds(size_t want) {
  struct rlimit rl;
  if (getrlimit(RLIMIT_NOFILE, &rl) != 0 || rl.rlim_cur == RLIM_INFINITY) return want;
  size_t avail = rl.rlim_cur > FD_RESERVE + 16 + 18 ? (size_t)rl.rlim_cur - FD_RESERVE - 16 : 18;
  size_t fit = avail * 8 / 9; /* fit + fit / 8 + 16 <= rlim_cur - FD_RESERVE */
  if (want <= fit) return want;
  fg_warn("[http] max_connections %zu does not fit the open-files limit of %llu (raise "
          "LimitNOFILE=); keeping at most %zu connections", want,
          (unsigned long long)rl.rlim_cur, fit);
  return fit;
}

__attribute__((format(printf, 2, 0)))
static void on_mhd_log(void *cls, const char *fmt, va_list ap) {
  char buf[512];
  vsnprintf(buf, sizeof buf, fmt, ap);
  size_t n = strlen(buf);
  while (n && (buf[n - 1] == '\n' || buf[n - 1] == '\r')) buf[--n] = 0;
  fg_debug("http: %s", buf);
}

/* ---------------------------------------------------------------- start and stop */

int fg_http_start(fg_http **out, const fg_http_config *cfg, char *bound, size_t bound_len) {
  *out = NULL;
  char *host = NULL;
  int port = 0;
  FG_TRY(fg_conf_parse_listen(cfg->listen, &host, &port));
  struct addrinfo hints = {.ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
                           .ai_flags = AI_PASSIVE | AI_NUMERICSERV};
  struct addrinfo *ai = NULL;
  char portstr[16];
  snprintf(portstr, sizeof portstr, "%d", port);
  int gai = getaddrinfo(host, portstr, &hints, &ai);
  if (gai != 0) {
    int rc = fg_fail(FG_EINVAL, "cannot resolve listen address '%s': %s", cfg->listen,
                     gai_strerror(gai));
    free(host);
    return rc;
  }

  fg_http *h = calloc(1, sizeof *h);
  if (!h) {
    freeaddrinfo(ai);
    free(host);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  h->cfg = *cfg;
  const fg_conf *conf = cfg->conf_acquire(cfg->app);
  size_t max_conns = cap_for_fds((size_t)conf->max_connections);
  h->idle_timeout_s = conf->idle_timeout_s;
  cfg->conf_release(cfg->app, conf);
  if (fg_conns_new(&h->conns, max_conns) != 0) {
    free(h);
    freeaddrinfo(ai);
    free(host);
    return FG_ENOMEM;
  }
  pthread_condattr_t ca;
  pthread_condattr_init(&ca);
  pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
  pthread_cond_init(&h->sweep_cond, &ca);
  pthread_condattr_destroy(&ca);
  pthread_mutex_init(&h->qlock, NULL);
  pthread_cond_init(&h->qcond, NULL);
  pthread_mutex_init(&h->slock, NULL);
  pthread_cond_init(&h->scond, NULL);
  for (size_t i = 0; i < cfg->n_routes && i < FG_METRICS_MAX_ROUTES; i++)
    fg_metrics_set_route((int)i, cfg->routes[i].method, cfg->routes[i].metric);

  unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_EPOLL_LINUX_ONLY |
                   MHD_ALLOW_SUSPEND_RESUME | MHD_USE_ERROR_LOG | MHD_USE_TURBO;
  if (ai->ai_family == AF_INET6) flags |= MHD_USE_IPv6;
  h->mhd = MHD_start_daemon(
    flags, (uint16_t)port, NULL, NULL, on_request, h,
    MHD_OPTION_EXTERNAL_LOGGER, on_mhd_log, NULL,
    MHD_OPTION_SOCK_ADDR, ai->ai_addr,
    MHD_OPTION_THREAD_POOL_SIZE, (unsigned)(cfg->poll_threads > 0 ? cfg->poll_threads : 1),
    MHD_OPTION_NOTIFY_COMPLETED, on_completed, h,
    MHD_OPTION_NOTIFY_CONNECTION, on_connection, h,
    /* The backstop: the table sheds idle connections at max_conns already. */
    MHD_OPTION_CONNECTION_LIMIT, (unsigned)(max_conns + max_conns / 8 + 16),
    MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)h->idle_timeout_s,
    MHD_OPTION_LISTENING_ADDRESS_REUSE, (unsigned)1,
    MHD_OPTION_END);
  freeaddrinfo(ai);
  if (!h->mhd) {
    int rc = fg_fail(FG_EIO, "cannot listen on %s (address in use, or not an address of this "
                     "machine?)", cfg->listen);
    pthread_mutex_destroy(&h->qlock);
    pthread_cond_destroy(&h->qcond);
    pthread_mutex_destroy(&h->slock);
    pthread_cond_destroy(&h->scond);
    pthread_cond_destroy(&h->sweep_cond);
    fg_conns_free(h->conns);
    free(h);
    free(host);
    return rc;
  }
  const union MHD_DaemonInfo *info = MHD_get_daemon_info(h->mhd, MHD_DAEMON_INFO_BIND_PORT);
  int bound_port = info ? info->port : port;
  if (strchr(host, ':')) snprintf(bound, bound_len, "http://[%s]:%d", host, bound_port);
  else snprintf(bound, bound_len, "http://%s:%d", host, bound_port);
  free(host);

  h->n_workers = cfg->offload_threads > 0 ? cfg->offload_threads : 1;
  h->workers = calloc((size_t)h->n_workers, sizeof *h->workers);
  for (int i = 0; h->workers && i < h->n_workers; i++)
    if (pthread_create(&h->workers[i], NULL, offload_main, h) != 0) {
      h->n_workers = i;
      break;
    }
  fg_metrics_set_offload(h->n_workers, 0, 0);
  h->ticker_started = pthread_create(&h->ticker, NULL, ticker_main, h) == 0;
  h->sweeper_started = pthread_create(&h->sweeper, NULL, sweeper_main, h) == 0;
  if (!h->workers || h->n_workers == 0 || !h->ticker_started || !h->sweeper_started) {
    free(h->workers);
    h->workers = NULL;
    h->n_workers = 0;
    fg_http_stop(h);
    return fg_fail(FG_ENOMEM, "cannot start the request worker, stream or sweeper threads");
  }
  *out = h;
  return 0;
}

/* No MHD_quiesce_daemon: with a thread pool on epoll, libmicrohttpd 0.9.75's quiesce and its
 * workers both take the listening socket out of the workers' epoll sets, unsynchronised, and
 * the loser aborts the process ("Failed to remove listen FD from epoll set"). Connections that
 * arrive while stopping are answered instead: 503 for work the pool would have done. */
void fg_http_stop(fg_http *h) {
  if (!h) return;
  pthread_mutex_lock(&h->qlock);
  h->stopping = 1;
  pthread_cond_broadcast(&h->qcond);
  pthread_cond_broadcast(&h->sweep_cond);
  pthread_mutex_unlock(&h->qlock);
  for (int i = 0; i < h->n_workers; i++) pthread_join(h->workers[i], NULL);
  if (h->sweeper_started) pthread_join(h->sweeper, NULL);
  /* End streamed bodies: nothing may stay suspended when MHD_stop_daemon runs. */
  pthread_mutex_lock(&h->slock);
  h->streams_closing = 1;
  for (http_stream *hs = h->streams; hs; hs = hs->next)
    if (hs->parked) {
      hs->parked = 0;
      MHD_resume_connection(hs->conn);
    }
  pthread_cond_broadcast(&h->scond);
  pthread_mutex_unlock(&h->slock);
  if (h->ticker_started) pthread_join(h->ticker, NULL);
  MHD_stop_daemon(h->mhd);
  fg_conns_free(h->conns);
  pthread_cond_destroy(&h->sweep_cond);
  pthread_mutex_destroy(&h->qlock);
  pthread_cond_destroy(&h->qcond);
  pthread_mutex_destroy(&h->slock);
  pthread_cond_destroy(&h->scond);
  free(h->workers);
  free(h);
}
