/* Black-box harness for the integration tests: runs the real fieldgripd as a child process on a
 * free loopback port with a temporary state dir and drives it over HTTP with libcurl, the way a
 * robot stack would. One process per test (tests/test.h); a failed ASSERT exits, and an atexit
 * hook (plus PR_SET_PDEATHSIG in the child) makes sure no daemon and no temp dir outlive it.
 *
 * Everything here either succeeds or fails the test: helpers assert instead of returning error
 * codes, so test bodies read as a list of requests and expectations. */
#ifndef FG_IT_HARNESS_H
#define FG_IT_HARNESS_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "test.h"

/* ---------------------------------------------------------------------------------------- */
/* Daemon lifecycle                                                                          */

/* Finds the daemon (argv[1], else $FG_DAEMON), makes the temp dir <tmp> (mkdtemp under /tmp)
 * with <tmp>/state, <tmp>/fieldgripd.conf (empty) and <tmp>/daemon.log, and registers the
 * cleanup. Call first in main(). */
void h_init(int argc, char **argv);

/* Marks the test as passed: the cleanup then stays quiet instead of dumping the daemon log. */
void h_done(void);

const char *h_tmpdir(void);     /* the temp dir; removed at exit unless $FG_KEEP_TMP is set */
const char *h_state_dir(void);  /* <tmp>/state */
const char *h_config_path(void);/* <tmp>/fieldgripd.conf */
const char *h_daemon_path(void);

/* Replaces the config file's content (takes effect at the next start or SIGHUP). */
void h_write_config(const char *text);

/* Starts fieldgripd --config <conf> --state-dir <state> --listen 127.0.0.1:0 --log-level LEVEL
 * (h_set_log_level) with stdout and stderr appended to <tmp>/daemon.log, and waits up to 10 s
 * for the line "listening on http://127.0.0.1:PORT". Fails the test if the daemon exits or
 * never says it. */
void h_start(void);

/* The --log-level of the next h_start (default "debug", which logs every request). A static
 * string or one that outlives the test. Benchmarks pass "info", the daemon's default, so
 * that they measure what a deployment runs. */
void h_set_log_level(const char *level);

/* SIGTERM, then waits for the exit and asserts exit status 0. */
void h_stop(void);

/* SIGKILL, then reaps the child. */
void h_kill(void);

/* Sends a signal to the running daemon (SIGHUP for a reload). */
void h_signal(int sig);

/* Sends SIGHUP and waits (60 s hang guard) until the daemon has finished that reload, good
 * or failed: fieldgrip_config_reloads_total moves once a reload has done and logged
 * everything, while other signs (a new token accepted, a CLIP load counted, a log line)
 * come before its end. Reloads run one at a time; use this for every SIGHUP so that none is
 * in flight when the count is taken. */
void h_reload(void);

/* 1 while the daemon process is running (not exited, not a zombie that was reaped). */
int h_alive(void);

int h_port(void);
pid_t h_pid(void);

/* The whole daemon log so far (all starts), malloc'd, caller frees. */
char *h_log(void);

/* Waits until the daemon log contains needle at least min_count times; returns 1 when it does,
 * 0 after timeout_s. A wait for an event, not a timing assertion. */
int h_wait_log(const char *needle, int min_count, double timeout_s);

/* Number of occurrences of needle in the daemon log. */
int h_log_count(const char *needle);

/* Runs the daemon binary with extra arguments (NULL-terminated) and no other flags, captures
 * stdout+stderr into a malloc'd string (*out) and returns the exit status (or 128+signal). */
int h_run_daemon_capture(const char *const *args, char **out);

/* ---------------------------------------------------------------------------------------- */
/* HTTP over libcurl                                                                          */

typedef struct h_header {
  char *name;  /* as sent, e.g. "Content-Type" */
  char *value; /* trimmed */
} h_header;

typedef struct h_resp {
  long status;    /* HTTP status, 0 when no response came */
  int curl_rc;    /* CURLcode of the transfer */
  char *body;     /* NUL-terminated, never NULL */
  size_t len;
  h_header *headers;
  int n_headers;
  json_t *json;   /* the body parsed, or NULL when it is not JSON */
} h_resp;

/* One multipart/form-data part. filename and type may be NULL (a plain field). */
typedef struct h_part {
  const char *name;
  const void *data;
  size_t len;
  const char *filename;
  const char *type;
} h_part;

enum {
  H_AUTH_DEFAULT = 0, /* send the token set by h_set_token, if any */
  H_AUTH_NONE = 1,    /* no Authorization header */
  H_AUTH_TOKEN = 2,   /* "Authorization: Bearer <req.token>" */
};

typedef size_t (*h_read_fn)(char *buf, size_t size, size_t nmemb, void *ud);

typedef struct h_req {
  const char *method;       /* "GET" when NULL */
  const char *path;         /* "/v1/scenes" */
  const void *body;         /* raw body, or NULL */
  size_t body_len;
  const char *content_type; /* for a raw body, or read_cb without a Content-Type line in
                             * headers; "application/json" when NULL */
  const h_part *parts;      /* multipart/form-data (curl_mime) when n_parts > 0 */
  int n_parts;
  const char *const *headers; /* extra header lines, NULL-terminated, or NULL */
  int auth;
  const char *token;
  h_read_fn read_cb;        /* streamed body from a read callback (POST) */
  void *read_ud;
  long long read_len;       /* body length for read_cb; < 0: chunked transfer encoding */
  long timeout_ms;          /* the whole exchange; 0: the 300 s hang guard */
} h_req;

/* The default token for requests with auth H_AUTH_DEFAULT; NULL for none. Copied. */
void h_set_token(const char *token);

/* Performs a request; never fails the test on transport errors (status 0, curl_rc set), so
 * tests can assert on dropped connections. The caller frees with h_resp_free. */
h_resp *h_request(const h_req *req);
h_resp *h_get(const char *path);
h_resp *h_delete(const char *path);
h_resp *h_post_json(const char *path, const char *json_text);
h_resp *h_upload_parts(const char *path, const h_part *parts, int n_parts);
/* image, meta and features parts; a NULL pointer leaves its part out. */
h_resp *h_upload(const char *path, const void *image, size_t image_len, const char *meta,
                 const void *features, size_t features_len);
void h_resp_free(h_resp *r);

/* The value of a response header (case-insensitive name), or NULL. Borrowed from r. */
const char *h_resp_header(const h_resp *r, const char *name);

/* Sends raw bytes on a fresh TCP connection to the daemon, half-closes it, and reads what comes
 * back until the daemon closes (30 s hang guard). Returns the number of bytes read into resp
 * (NUL-terminated, at most cap-1), or -1 when the connection was reset before anything came. */
long h_raw_exchange(const void *req, size_t len, char *resp, size_t cap);

/* Connects, sends req (may be empty) and closes at once without reading: a client that
 * vanishes mid-request. */
void h_raw_abandon(const void *req, size_t len);

/* Builds a multipart/form-data body by hand (for streamed uploads). Caller frees *out. */
void h_multipart_build(const h_part *parts, int n_parts, const char *boundary, uint8_t **out,
                       size_t *out_len);

/* GET /metrics (asserting 200) and the value of one series, named with its labels exactly as
 * the exposition writes it: "fieldgrip_clip_loads_total{result=\"ok\"}". Fails the test when
 * the series is absent. */
double h_metric(const char *series);

/* ---------------------------------------------------------------------------------------- */
/* Assertions on replies                                                                      */

void h_assert_status_at(const char *file, int line, const h_resp *r, long status);
/* status, JSON body {"error":{"code":code,"message":non-empty string}}. */
void h_assert_error_at(const char *file, int line, const h_resp *r, long status,
                       const char *code);
/* Sends METHOD PATH with BODY (JSON, or NULL for none) and asserts its error reply as
 * h_assert_error_at does; a failure names the request. */
void h_expect_error_at(const char *file, int line, const char *method, const char *path,
                       const char *body, long status, const char *code);
json_t *h_jget_at(const char *file, int line, json_t *root, const char *path);
double h_jnum_at(const char *file, int line, json_t *root, const char *path);
long long h_jint_at(const char *file, int line, json_t *root, const char *path);
const char *h_jstr_at(const char *file, int line, json_t *root, const char *path);
void h_assert_matrix_at(const char *file, int line, json_t *m, const double T[16], double tol);
void h_assert_vec_at(const char *file, int line, json_t *v, const double *x, int n, double tol);
void h_assert_json_equal_at(const char *file, int line, json_t *a, json_t *b);

#define ASSERT_STATUS(r, st) h_assert_status_at(__FILE__, __LINE__, (r), (st))
#define ASSERT_HTTP_ERROR(r, st, code) h_assert_error_at(__FILE__, __LINE__, (r), (st), (code))
#define EXPECT_ERROR(method, path, body, st, code) \
  h_expect_error_at(__FILE__, __LINE__, (method), (path), (body), (st), (code))
/* Paths are dot-separated keys and array indices: "frames.0.camera.fl_x". Missing: fail. */
#define JGET(root, path) h_jget_at(__FILE__, __LINE__, (root), (path))
#define JNUM(root, path) h_jnum_at(__FILE__, __LINE__, (root), (path))
#define JINT(root, path) h_jint_at(__FILE__, __LINE__, (root), (path))
#define JSTR(root, path) h_jstr_at(__FILE__, __LINE__, (root), (path))
#define ASSERT_MATRIX(m, T, tol) h_assert_matrix_at(__FILE__, __LINE__, (m), (T), (tol))
#define ASSERT_VEC(v, x, n, tol) h_assert_vec_at(__FILE__, __LINE__, (v), (x), (n), (tol))
#define ASSERT_JSON_EQUAL(a, b) h_assert_json_equal_at(__FILE__, __LINE__, (a), (b))

/* The parsed JSON body of r; fails the test when the body is not JSON. Borrowed from r. */
#define RJSON(r) h_jget_at(__FILE__, __LINE__, (r)->json, "")

/* The same lookups without failing: NULL when the path does not exist. */
json_t *h_jfind(json_t *root, const char *path);

/* ---------------------------------------------------------------------------------------- */
/* Test data made by hand (fixtures.c)                                                        */

/* A PNG (zlib, no library of the project involved) with a deterministic pattern; channels 1,
 * 3 or 4, bits 8 or 16. noise != 0 fills it with pseudo-random bytes and stores it
 * uncompressed so its size is about w*h*channels*bits/8. Caller frees *out. */
void h_png(int w, int h, int channels, int bits, unsigned seed, int noise, uint8_t **out,
           size_t *out_len);

/* A .npy (format 1.0) with the given descr ("<f4", "<f2", "<f8"), shape and values
 * value(i) = ((i * 7 + seed) % 97) / 97 - 0.5 (rounded to float16 for "<f2"). Caller frees
 * *out. */
void h_npy(const char *descr, const int *shape, int ndim, unsigned seed, uint8_t **out,
           size_t *out_len);

/* T (row-major 4x4 camera-to-world) from a rotation vector (radians) and a translation (m). */
void h_pose(double T[16], double rx, double ry, double rz, double tx, double ty, double tz);

/* A 4x4 matrix as a JSON array text with %.17g numbers. Caller frees. */
char *h_matrix_json(const double T[16]);

/* A frame meta JSON: transform_matrix, convention and a PINHOLE camera. Caller frees. */
char *h_meta(const double T[16], const char *convention, double fl, double cx, double cy, int w,
             int h);

/* ---------------------------------------------------------------------------------------- */
/* Files                                                                                      */

/* printf into a malloc'd string. */
char *h_fmt(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void h_write_file(const char *path, const void *data, size_t len);
void h_mkdirs(const char *path);
/* Reads a whole file; NULL when it cannot be read. Caller frees. */
char *h_read_file(const char *path, size_t *len);
/* Copies folder from, with its folders, into to (made if missing): each file's bytes, never a
 * link, so that a test may change its copy. */
void h_copy_tree(const char *from, const char *to);
/* Removes path and, when it is a folder, everything under it; a missing path is no error. */
void h_remove_tree(const char *path);
/* Number of files under dir (recursive) whose name contains needle. */
int h_count_files(const char *dir, const char *needle);
/* realpath of $FG_SHARED_DATA; fails the test when it is unset or missing. Caller frees. */
char *h_shared_data(void);
void h_sleep_ms(int ms);
/* Seconds on the monotonic clock: for deadlines of waits and for latencies measured. */
double h_now_s(void);

/* A growable byte buffer, NUL-terminated past n; exits the test on allocation failure. */
typedef struct it_buf {
  char *p;
  size_t n, cap;
} it_buf;
void it_buf_add(it_buf *b, const void *data, size_t n);

#endif
