/* The HTTP layer: a libmicrohttpd server with a pool of polling threads, a route table,
 * bearer-token checks, body limits, multipart parsing and an offload pool for handlers that
 * take long (decoding images, importing data sets), so that they never hold a polling
 * thread while other connections wait.
 *
 * Floods and slow clients: a table of connections (http_conns.h) caps them at [http]
 * max_connections by shedding the oldest idle ones, and closes those that send their
 * headers or their body too slowly; the offload queue holds at most [http]
 * max_queued_requests (more are answered 503 server_busy with Retry-After); bodies are
 * refused 413 past max_json_kb, or max_upload_mb for FG_ROUTE_LARGE_BODY routes, before
 * they are read when their Content-Length says so.
 *
 * Every request passes the cross-site guards first (http_guard.h): its Host, its Origin when
 * it changes something, and its body's Content-Type.
 *
 * Handlers see a complete request (fg_req) and fill a response (fg_resp); they never touch
 * libmicrohttpd. */
#ifndef FG_DAEMON_HTTP_H
#define FG_DAEMON_HTTP_H

#include <stddef.h>
#include <stdint.h>

#include <jansson.h>

#define FG_HTTP_MAX_PARAMS 4
#define FG_HTTP_MAX_PARTS 8

struct fg_app;
struct fg_conf;

/* One part of a multipart/form-data body. */
typedef struct fg_part {
  char *name;         /* owned */
  char *filename;     /* owned; NULL for plain fields */
  char *content_type; /* owned; NULL when not given */
  uint8_t *data;      /* owned; NUL-terminated (not counted in len) */
  size_t len, cap;
} fg_part;

typedef struct fg_req {
  struct fg_app *app;
  const struct fg_conf *conf; /* the configuration this request runs under */
  const char *method;
  const char *path;
  char *params[FG_HTTP_MAX_PARAMS]; /* path segments captured by "{}" in the route */
  int n_params;
  const char *content_type;         /* may be NULL */
  uint8_t *body;                    /* raw body (not for multipart routes), NUL-terminated */
  size_t body_len;
  fg_part parts[FG_HTTP_MAX_PARTS]; /* multipart routes */
  int n_parts;
  void *mhd_conn;                   /* for header lookups via fg_req_header */
} fg_req;

/* A streamed body (Server-Sent Events): a producer the HTTP layer pulls bytes from while the
 * client is connected. See fg_resp_stream. */
typedef struct fg_stream_ops {
  /* Copies at most max bytes of the body into buf. Returns how many (> 0), 0 when there is
   * nothing to send now (the connection is then parked: taken out of libmicrohttpd's event
   * loop, holding no thread, until ready() says otherwise), or -1 at the end of the body.
   * closing = 1 says the server is stopping: return -1 now or after a last few bytes. Runs
   * on a polling thread: must not block. */
  long (*read)(void *ctx, char *buf, size_t max, int closing);
  /* Whether a parked stream has something to send at now_s (CLOCK_MONOTONIC seconds). The
   * layer asks every FG_HTTP_STREAM_TICK_MS for each parked stream, under a lock that read()
   * does not take: must be cheap and must not block. */
  int (*ready)(void *ctx, double now_s);
  /* Frees ctx once the connection is done with it (or the response was never sent). */
  void (*free)(void *ctx);
} fg_stream_ops;

#define FG_HTTP_STREAM_TICK_MS 50

typedef struct fg_resp {
  int status;
  char *body;               /* owned (malloc) */
  size_t len;
  const char *content_type; /* static string */
  char allow[64];           /* for 405 */
  char location[160];       /* Location header, when not empty (202, 201) */
  char header[256];         /* more headers as "Name: value" lines joined by "\r\n", when
                             * not empty */
  const fg_stream_ops *stream_ops; /* a streamed body instead of body (fg_resp_stream) */
  void *stream_ctx;                /* owned: given to stream_ops->free */
} fg_resp;

typedef int (*fg_handler)(fg_req *req, fg_resp *resp);

enum {
  FG_ROUTE_PUBLIC = 1,    /* no token needed */
  FG_ROUTE_OFFLOAD = 2,   /* run on the offload pool */
  FG_ROUTE_MULTIPART = 4, /* body is multipart/form-data */
  FG_ROUTE_LARGE_BODY = 8, /* body up to [http] max_upload_mb (images); else max_json_kb */
  FG_ROUTE_IMAGE_BODY = 16, /* body is an image file (image/..., application/octet-stream);
                             * else JSON (http_guard.h) */
};

typedef struct fg_route {
  const char *method;
  const char *pattern; /* "/v1/scenes/{}/frames"; "{}" captures one segment */
  const char *metric;  /* route label for metrics: "/v1/scenes/{s}/frames" */
  fg_handler handler;
  int flags;
} fg_route;

/* Looks up a request header (case-insensitive); NULL if absent. */
const char *fg_req_header(const fg_req *req, const char *name);

/* The client's address as "127.0.0.1:40312" or "[::1]:40312" into buf (size bytes); "" when
 * it is not known. Returns buf. */
char *fg_req_client(const fg_req *req, char *buf, size_t size);

/* Looks up a query-string argument ("?output=pooled"); NULL if absent, "" when given without
 * a value. */
const char *fg_req_query(const fg_req *req, const char *name);

/* The first query-string argument whose name is none of the n names known, or NULL when
 * all are known (for handlers that refuse unknown parameters). The string lives as long as
 * the request. */
const char *fg_req_query_unknown(const fg_req *req, const char *const *known, size_t n);

/* A whole query-string value (as fg_req_query returns it) as a finite number: 0 and *out,
 * or -1 when value is NULL, empty, not entirely a number, or not finite. */
int fg_query_number(const char *value, double *out);

/* Finds a multipart part by name; NULL if absent. */
const fg_part *fg_req_part(const fg_req *req, const char *name);

/* Sets a JSON response; steals the reference to obj. */
void fg_resp_json(fg_resp *resp, int status, json_t *obj);

/* Sets the error response {"error":{"code","message"}}. Returns 0 for handler chaining. */
int fg_resp_error(fg_resp *resp, int status, const char *code, const char *fmt, ...)
  __attribute__((format(printf, 4, 5)));

/* Sets a body with a content type; takes ownership of body (malloc'd). */
void fg_resp_take(fg_resp *resp, int status, const char *content_type, char *body, size_t len);

/* Answers with a body of unknown length pulled from ops (chunked transfer encoding), with
 * "Cache-Control: no-store" and "X-Accel-Buffering: no". Takes ownership of ctx: ops->free
 * runs once the connection ends, or at once if the response is replaced. Only for handlers
 * that run on a polling thread (not FG_ROUTE_OFFLOAD). */
void fg_resp_stream(fg_resp *resp, int status, const char *content_type,
                    const fg_stream_ops *ops, void *ctx);

typedef struct fg_http fg_http;

typedef struct fg_http_config {
  const char *listen;          /* "host:port" or "[v6]:port"; port 0 picks a free one */
  int poll_threads;            /* libmicrohttpd polling threads, >= 1 */
  int offload_threads;         /* threads running FG_ROUTE_OFFLOAD handlers, >= 1 */
  const fg_route *routes;
  size_t n_routes;
  struct fg_app *app;
  /* Returns the current configuration with a reference held, and drops it. The server asks
   * once per request, so a reload never changes the settings under a running request. */
  const struct fg_conf *(*conf_acquire)(struct fg_app *app);
  void (*conf_release)(struct fg_app *app, const struct fg_conf *conf);
} fg_http_config;

/* Starts listening. On success *out is owned by the caller (fg_http_stop). The bound address
 * is written to bound ("http://127.0.0.1:7070"). */
int fg_http_start(fg_http **out, const fg_http_config *cfg, char *bound, size_t bound_len);

/* Stops accepting, lets offloaded handlers finish, ends every streamed body (read() sees
 * closing = 1), closes every connection and frees. */
void fg_http_stop(fg_http *http);

#endif
