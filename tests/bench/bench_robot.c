/* Robot command round trips through fieldgripd to a Modbus peer (proto/modbus.md, profile
 * pose-registers), normally fieldgrip-sim with --ack-delay-ms 0 and --log. Sends N `move`
 * commands with "wait": true in a row over one kept-alive HTTP connection, each to a
 * different pose (negative coordinates and the int16 limits among them), and times each
 * POST /v1/robot/commands on the client's clock; then N_NOWAIT more with "wait": false,
 * answered at the acknowledgement, each followed (untimed) by GET /v1/robot/commands/{id}
 * until it is done, since the robot takes one command at a time.
 *
 * Then it reads the simulator's request log (one line per write request, appended from the
 * size it had before the first command) and checks every command of both phases:
 *   - each reply is 200 (202 allowed without wait) with state done, and its seq is the one
 *     after the previous reply's (65535 is followed by 1);
 *   - the log holds one function-16 write of the robot block per command, in order, whose
 *     words are the reply's registers.robot.words;
 *   - every seq from seq_first to seq_last is in the log exactly once (lost, duplicated);
 *   - with the int16 encoding, the words carry the command (5, move) and the pose: x, y, z
 *     in 0.1 mm exactly, the rotation vector in mrad within 1.
 *
 * Prints three lines of key=value pairs:
 *   bench=robot_execute n=... p50_ms= p90_ms= p99_ms= max_ms= mean_ms= ack_p50_ms=
 *     ack_p99_ms= errors= connects= seq_first= seq_last= seq_checked= logged= other_writes=
 *     lost= duplicated= reply_gaps= out_of_order= words_mismatched= pose_mismatched=
 *     checks=pass|fail
 *   bench=robot_execute_nowait n=... p50_ms= p90_ms= p99_ms= max_ms= ack_p50_ms= errors=
 *     polls=
 *   bench=robot_execute_baseline n=200 get_robot_p50_ms= get_robot_p99_ms= dry_run_p50_ms=
 *     dry_run_p99_ms= errors=
 * The baseline, timed after the commands on the same connection, is the HTTP cost without
 * Modbus: GET /v1/robot answers on the HTTP thread, a dry-run move goes through the offload
 * pool and the planner like a command but sends nothing. It does not affect the exit status.
 * The first line's checks and errors cover both phases (errors: commands that failed or were
 * not sent, as it stops after 20 failures in a row). Percentiles are nearest-rank;
 * ack_ms is the daemon's own figure (pose write sent to ack read); connects counts the TCP
 * connections the client opened over the whole run (1: one kept-alive connection);
 * other_writes counts robot-unit writes that are not the pose block (there should be none).
 * The exit status is 1 when a check failed or a command went wrong (the figures are printed
 * all the same), 2 on bad arguments or an unusable daemon.
 * Usage: bench_robot BASE_URL SIM_LOG [N [N_NOWAIT]]   (defaults 1000 and 200) */
#include "benchstat.h"

#include <curl/curl.h>
#include <jansson.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#define ROBOT_WORDS 10     /* the int16 block: seq, command, x, y, z, rx, ry, rz, width, force */
#define MAX_WORDS 32       /* more than either encoding writes */
#define CMD_MOVE 5
#define MAX_ERRORS_IN_ROW 20
#define BASELINE_N 200     /* GETs and dry runs timed after the commands */

/* One command as sent and as answered. */
typedef struct {
  double p_world_m[3];     /* position sent, metres (whole 0.1 mm) */
  double rotvec_rad[3];    /* the rotation vector of the quaternion sent */
  double ms;               /* client round trip of the POST */
  double ack_ms;           /* the reply's ack_ms, or -1 */
  int ok;                  /* the reply was as expected (status, state, seq, words) */
  long seq;                /* the reply's seq, or -1 */
  int n_words;
  uint16_t words[MAX_WORDS]; /* the reply's registers.robot.words */
} bench_cmd;

/* One robot-block write from the simulator's log. */
typedef struct {
  int n_words;
  uint16_t words[MAX_WORDS];
} log_write;

typedef struct {
  CURL *curl;
  const char *base;        /* http://127.0.0.1:PORT, not owned */
  struct curl_slist *hdrs; /* owned */
  char *body;              /* the last reply, owned, NUL-terminated */
  size_t len, cap;
  long connects;           /* connections opened, over all requests */
} http_client;

static double now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec * 1e3 + 1e-6 * (double)ts.tv_nsec;
}

static uint16_t seq_next(uint16_t s) { return s == 65535 ? 1 : (uint16_t)(s + 1); }

/* ---------------------------------------------------------------- HTTP */

static size_t on_body(char *p, size_t size, size_t n, void *arg) {
  http_client *h = arg;
  const size_t add = size * n;
  if (h->len + add + 1 > h->cap) {
    size_t cap = h->cap ? h->cap : 4096;
    while (cap < h->len + add + 1) cap *= 2;
    char *b = realloc(h->body, cap);
    if (!b) return 0; /* curl reports a write error */
    h->body = b;
    h->cap = cap;
  }
  memcpy(h->body + h->len, p, add);
  h->len += add;
  h->body[h->len] = '\0';
  return add;
}

/* Sets up one easy handle for every request, so libcurl keeps the connection alive. Returns 0
 * or -1. h->base is borrowed from the caller. */
static int http_init(http_client *h, const char *base) {
  memset(h, 0, sizeof *h);
  h->base = base;
  h->curl = curl_easy_init();
  if (!h->curl) return -1;
  h->hdrs = curl_slist_append(NULL, "Content-Type: application/json");
  h->hdrs = curl_slist_append(h->hdrs, "Expect:");
  curl_easy_setopt(h->curl, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(h->curl, CURLOPT_NOPROXY, "*");
  curl_easy_setopt(h->curl, CURLOPT_TCP_NODELAY, 1L);
  curl_easy_setopt(h->curl, CURLOPT_TIMEOUT, 30L);
  curl_easy_setopt(h->curl, CURLOPT_WRITEFUNCTION, on_body);
  curl_easy_setopt(h->curl, CURLOPT_WRITEDATA, h);
  return 0;
}

static void http_free(http_client *h) {
  curl_slist_free_all(h->hdrs);
  curl_easy_cleanup(h->curl);
  free(h->body);
}

/* GET (body NULL) or POST of a JSON body to base + path. Returns the HTTP status, or -1 when
 * no answer came (after a message); the reply's text is in h->body. */
static long http_do(http_client *h, const char *path, const char *body) {
  char url[512];
  snprintf(url, sizeof url, "%s%s", h->base, path);
  h->len = 0;
  if (h->body) h->body[0] = '\0';
  curl_easy_setopt(h->curl, CURLOPT_URL, url);
  if (body) {
    curl_easy_setopt(h->curl, CURLOPT_HTTPHEADER, h->hdrs);
    curl_easy_setopt(h->curl, CURLOPT_POSTFIELDS, body);
    curl_easy_setopt(h->curl, CURLOPT_POSTFIELDSIZE, (long)strlen(body));
  } else {
    curl_easy_setopt(h->curl, CURLOPT_HTTPHEADER, NULL);
    curl_easy_setopt(h->curl, CURLOPT_HTTPGET, 1L);
  }
  CURLcode rc = curl_easy_perform(h->curl);
  if (rc != CURLE_OK) {
    fprintf(stderr, "bench_robot: %s %s: %s\n", body ? "POST" : "GET", url,
            curl_easy_strerror(rc));
    return -1;
  }
  long status = 0, connects = 0;
  curl_easy_getinfo(h->curl, CURLINFO_RESPONSE_CODE, &status);
  curl_easy_getinfo(h->curl, CURLINFO_NUM_CONNECTS, &connects);
  h->connects += connects;
  return status;
}

/* The last reply as JSON (new reference), or NULL. */
static json_t *http_json(const http_client *h) {
  return h->body ? json_loads(h->body, 0, NULL) : NULL;
}

/* ---------------------------------------------------------------- commands */

/* Pose i: positions on the 0.1 mm grid, in and around the tabletop, a fifth of them below
 * the table (z < 0), half with y < 0, every 97th at the int16 limits (-3.2768, 3.2767 m);
 * the rotation a turn of 0.1 .. 3.0 rad (so w > 0) about a varying axis. q_wxyz is unit. */
static void pose_for(int i, double p_world_m[3], double q_wxyz[4], double rotvec_rad[3]) {
  p_world_m[0] = round(1e4 * (0.30 + 0.25 * sin(0.37 * i))) / 1e4;
  p_world_m[1] = round(1e4 * (0.45 * sin(0.23 * i + 1.0))) / 1e4;
  p_world_m[2] = round(1e4 * (-0.05 + 0.25 * (0.5 + 0.5 * sin(0.11 * i)))) / 1e4;
  if (i % 97 == 0) {
    p_world_m[0] = -3.2768;
    p_world_m[1] = 3.2767;
  }
  double a[3] = {sin(0.5 * i), cos(0.3 * i), 0.5 - cos(0.7 * i)};
  const double an = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  const double angle_rad = 0.1 + 2.9 * (0.5 + 0.5 * sin(0.17 * i));
  q_wxyz[0] = cos(angle_rad / 2);
  for (int k = 0; k < 3; k++) {
    a[k] /= an;
    q_wxyz[k + 1] = sin(angle_rad / 2) * a[k];
    rotvec_rad[k] = angle_rad * a[k];
  }
}

/* Reads the reply of command c (status already known to be acceptable) into c; returns 0, or
 * -1 after a message when it is not a finished command with a seq and robot words. */
static int read_reply(const http_client *h, bench_cmd *c, json_t **out) {
  json_t *o = http_json(h);
  *out = o;
  json_t *seq = json_object_get(o, "seq");
  json_t *ack = json_object_get(o, "ack_ms");
  json_t *words = json_object_get(json_object_get(json_object_get(o, "registers"), "robot"),
                                  "words");
  c->ack_ms = json_is_number(ack) ? json_number_value(ack) : -1;
  if (!json_is_integer(seq) || !json_is_array(words) || json_array_size(words) < 2 ||
      json_array_size(words) > MAX_WORDS) {
    fprintf(stderr, "bench_robot: unexpected reply: %s\n", h->body ? h->body : "");
    return -1;
  }
  c->seq = (long)json_integer_value(seq);
  c->n_words = (int)json_array_size(words);
  for (int k = 0; k < c->n_words; k++)
    c->words[k] = (uint16_t)json_integer_value(json_array_get(words, (size_t)k));
  if (c->words[0] != c->seq) {
    fprintf(stderr, "bench_robot: reply seq %ld but words[0] %u\n", c->seq, c->words[0]);
    return -1;
  }
  return 0;
}

/* The body of move command i into body[size] ("dry_run": true when dry), and its pose into
 * c (cleared first). */
static void command_body(int i, int wait, int dry, bench_cmd *c, char *body, size_t size) {
  double q[4];
  memset(c, 0, sizeof *c);
  c->seq = -1;
  c->ack_ms = -1;
  pose_for(i, c->p_world_m, q, c->rotvec_rad);
  snprintf(body, size,
           "{\"command\":\"move\",\"pose\":{\"position\":[%.4f,%.4f,%.4f],"
           "\"quaternion\":[%.9f,%.9f,%.9f,%.9f]},\"wait\":%s%s}",
           c->p_world_m[0], c->p_world_m[1], c->p_world_m[2], q[0], q[1], q[2], q[3],
           wait ? "true" : "false", dry ? ",\"dry_run\":true" : "");
}

/* Sends command i (wait or not) and fills c. Without wait, polls the command until it is done
 * (untimed, counted in *polls). Returns 0 or -1 (an error, after a message). */
static int run_command(http_client *h, int i, int wait, bench_cmd *c, long *polls) {
  char body[512];
  command_body(i, wait, 0, c, body, sizeof body);
  const double t0 = now_ms();
  const long status = http_do(h, "/v1/robot/commands", body);
  c->ms = now_ms() - t0;
  if (status != 200 && !(status == 202 && !wait)) {
    if (status > 0) fprintf(stderr, "bench_robot: command %d: HTTP %ld: %s\n", i, status, h->body);
    return -1;
  }
  json_t *o;
  int rc = read_reply(h, c, &o);
  const char *state = json_string_value(json_object_get(o, "state"));
  const json_int_t id = json_integer_value(json_object_get(o, "id"));
  const int finished = state && strcmp(state, "done") == 0;
  if (rc == 0 && wait && !finished) {
    fprintf(stderr, "bench_robot: command %d ended %s\n", i, state ? state : "?");
    rc = -1;
  }
  json_decref(o);
  if (rc < 0 || wait || finished) {
    c->ok = rc == 0;
    return rc;
  }
  char path[64];
  snprintf(path, sizeof path, "/v1/robot/commands/%lld", (long long)id);
  const double until = now_ms() + 30e3;
  while (now_ms() < until) {
    ++*polls;
    if (http_do(h, path, NULL) != 200) return -1;
    o = http_json(h);
    state = json_string_value(json_object_get(o, "state"));
    const int done = state && strcmp(state, "done") == 0;
    const int open = state && (strcmp(state, "pending") == 0 || strcmp(state, "acknowledged") == 0);
    if (!done && !open) fprintf(stderr, "bench_robot: command %d ended %s\n", i, state ? state : "?");
    json_decref(o);
    if (done) {
      c->ok = 1;
      return 0;
    }
    if (!open) return -1;
    const struct timespec ts = {0, 100 * 1000L}; /* 0.1 ms between polls */
    nanosleep(&ts, NULL);
  }
  fprintf(stderr, "bench_robot: command %d did not finish within 30 s\n", i);
  return -1;
}

/* The same connection without the robot: n GET /v1/robot (answered on the HTTP thread) into
 * get_ms[n] and n dry-run moves (handed to the offload pool, planned, no Modbus) into
 * dry_ms[n]. Returns the number of requests that were not answered 200. */
static int time_baseline(http_client *h, int n, double *get_ms, double *dry_ms) {
  int errors = 0;
  for (int i = 0; i < n; i++) {
    double t0 = now_ms();
    errors += http_do(h, "/v1/robot", NULL) != 200;
    get_ms[i] = now_ms() - t0;
    bench_cmd c;
    char body[512];
    command_body(i, 1, 1, &c, body, sizeof body);
    t0 = now_ms();
    errors += http_do(h, "/v1/robot/commands", body) != 200;
    dry_ms[i] = now_ms() - t0;
  }
  return errors;
}

/* Waits up to 5 s for GET /v1/robot to report a connected robot and reads its unit id, base
 * and encoding. Returns 0 or -1 after a message. */
static int robot_ready(http_client *h, int *unit, int *base, int *int16) {
  for (int tries = 0; tries < 100; tries++) {
    if (http_do(h, "/v1/robot", NULL) == 200) {
      json_t *o = http_json(h);
      const int conf = json_is_true(json_object_get(o, "configured"));
      const int conn = json_is_true(json_object_get(o, "connected"));
      *unit = (int)json_integer_value(json_object_get(o, "unit_id"));
      *base = (int)json_integer_value(json_object_get(o, "base"));
      const char *enc = json_string_value(json_object_get(o, "encoding"));
      *int16 = enc && strcmp(enc, "int16") == 0;
      json_decref(o);
      if (!conf) {
        fprintf(stderr, "bench_robot: the daemon has no [robot] configured\n");
        return -1;
      }
      if (conn) return 0;
    }
    struct timespec ts = {0, 50 * 1000000L};
    nanosleep(&ts, NULL);
  }
  fprintf(stderr, "bench_robot: the robot did not connect within 5 s: %s\n", h->body);
  return -1;
}

/* ---------------------------------------------------------------- the simulator's log */

static long file_size(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 ? (long)st.st_size : 0;
}

/* Reads the function-16 writes of unit at address base from path, from byte `from` on, into
 * a new array *out (owned by the caller, free()). Counts other robot-unit writes in *other.
 * Returns the number of writes, or -1 after a message. */
static int read_log(const char *path, long from, int unit, int base, log_write **out,
                    int *other) {
  *out = NULL;
  *other = 0;
  FILE *f = fopen(path, "r");
  if (!f) {
    perror(path);
    return -1;
  }
  fseek(f, from, SEEK_SET);
  int n = 0, cap = 0;
  log_write *v = NULL;
  char line[1024];
  while (fgets(line, sizeof line, f)) {
    int u, fn, addr, cnt, pos = 0;
    if (sscanf(line, "write unit=%d fn=%d addr=%d n=%d words=%n", &u, &fn, &addr, &cnt, &pos) < 4 ||
        pos == 0 || u != unit)
      continue;
    if (fn != 16 || addr != base) {
      ++*other;
      continue;
    }
    if (n == cap) {
      cap = cap ? 2 * cap : 1024;
      log_write *nv = realloc(v, (size_t)cap * sizeof *v);
      if (!nv) {
        free(v);
        fclose(f);
        return -1;
      }
      v = nv;
    }
    log_write *w = &v[n++];
    w->n_words = 0;
    for (char *p = line + pos; *p && *p != '\n' && w->n_words < MAX_WORDS;) {
      char *end;
      w->words[w->n_words++] = (uint16_t)strtoul(p, &end, 10);
      if (end == p) break;
      p = *end == ',' ? end + 1 : end;
    }
  }
  fclose(f);
  *out = v;
  return n;
}

/* The signed int16 in register word w. */
static int as_int16(uint16_t w) { return w > 32767 ? (int)w - 65536 : (int)w; }

/* Whether the int16 words of c carry a move to its pose (positions exact, rotation within
 * 1 mrad). */
static int pose_matches(const bench_cmd *c) {
  if (c->n_words != ROBOT_WORDS || c->words[1] != CMD_MOVE) return 0;
  for (int k = 0; k < 3; k++) {
    if (as_int16(c->words[2 + k]) != (int)lround(c->p_world_m[k] * 1e4)) return 0;
    if (abs(as_int16(c->words[5 + k]) - (int)lround(c->rotvec_rad[k] * 1e3)) > 1) return 0;
  }
  return 1;
}

/* What the replies and the simulator's log say about the commands. */
typedef struct {
  long seq_first, seq_last; /* of the first and last answered command; -1 without one */
  int seq_checked;          /* seqs from seq_first to seq_last */
  int n_log;                /* robot-block writes logged; -1 when the log was unreadable */
  int other;                /* other writes to the robot unit */
  int lost;                 /* seqs from seq_first to seq_last never written */
  int duplicated;           /* writes of a seq already written */
  int reply_gaps;           /* answered commands whose seq does not follow the previous one */
  int out_of_order;         /* answered commands written before the previous one */
  int words_mismatched;     /* answered commands whose logged words differ from the reply */
  int pose_mismatched;      /* int16 words that do not carry the move and the pose sent */
} checks;

/* Checks cmds[0..n-1] (those answered: ok) against each other and against the robot-block
 * writes of unit/base logged in log_path from byte log_from on; fills *k. */
static void check_commands(const bench_cmd *cmds, int n, const char *log_path, long log_from,
                           int unit, int base, int int16, checks *k) {
  memset(k, 0, sizeof *k);
  k->seq_first = k->seq_last = -1;
  long prev = -1;
  for (int i = 0; i < n; i++) {
    const bench_cmd *c = &cmds[i];
    if (!c->ok) continue;
    if (k->seq_first < 0) k->seq_first = c->seq;
    if (prev >= 0 && c->seq != seq_next((uint16_t)prev)) k->reply_gaps++;
    if (int16 && !pose_matches(c)) k->pose_mismatched++;
    prev = k->seq_last = c->seq;
  }
  log_write *lw = NULL;
  k->n_log = read_log(log_path, log_from, unit, base, &lw, &k->other);
  if (k->n_log < 0 || k->seq_first < 0) {
    free(lw);
    return;
  }
  /* where each seq was first written, and how often */
  static int count[65536], at[65536];
  memset(count, 0, sizeof count);
  for (int i = 0; i < k->n_log; i++) {
    if (lw[i].n_words == 0) continue;
    const uint16_t s = lw[i].words[0];
    if (count[s]++ == 0) at[s] = i;
  }
  for (uint16_t s = (uint16_t)k->seq_first;; s = seq_next(s)) {
    k->seq_checked++;
    k->lost += count[s] == 0;
    if (s == (uint16_t)k->seq_last || k->seq_checked > 65535) break;
  }
  for (int s = 0; s < 65536; s++) k->duplicated += count[s] > 1 ? count[s] - 1 : 0;
  int prev_at = -1;
  for (int i = 0; i < n; i++) {
    const bench_cmd *c = &cmds[i];
    if (!c->ok) continue;
    const uint16_t s = (uint16_t)c->seq;
    if (count[s] == 0) {
      k->words_mismatched++;
      continue;
    }
    const log_write *w = &lw[at[s]];
    if (w->n_words != c->n_words ||
        memcmp(w->words, c->words, (size_t)c->n_words * sizeof c->words[0]) != 0)
      k->words_mismatched++;
    if (at[s] < prev_at) k->out_of_order++;
    prev_at = at[s];
  }
  free(lw);
}

/* ---------------------------------------------------------------- main */

int main(int argc, char **argv) {
  if (argc < 3 || argc > 5) {
    fprintf(stderr, "usage: bench_robot BASE_URL SIM_LOG [N [N_NOWAIT]]   (defaults 1000, 200)\n");
    return 2;
  }
  const char *base_url = argv[1], *log_path = argv[2];
  const int n_wait = argc > 3 ? atoi(argv[3]) : 1000;
  const int n_nowait = argc > 4 ? atoi(argv[4]) : 200;
  if (n_wait < 1 || n_nowait < 0 || n_wait + n_nowait > 60000) {
    fprintf(stderr, "bench_robot: N must be 1.. and N + N_NOWAIT at most 60000\n");
    return 2;
  }
  curl_global_init(CURL_GLOBAL_DEFAULT);
  http_client h;
  if (http_init(&h, base_url) < 0) {
    fprintf(stderr, "bench_robot: curl_easy_init failed\n");
    return 2;
  }
  int unit = 0, base = 0, int16 = 0;
  if (robot_ready(&h, &unit, &base, &int16) < 0) return 2;
  const long log_from = file_size(log_path);

  const int total = n_wait + n_nowait;
  bench_cmd *cmds = calloc((size_t)total, sizeof *cmds);
  double *ms = malloc((size_t)total * sizeof *ms), *ack = malloc((size_t)total * sizeof *ack);
  if (!cmds || !ms || !ack) return 2;
  int errors[2] = {0, 0}, in_row = 0, sent = 0;
  long polls = 0;
  for (int i = 0; i < total && in_row < MAX_ERRORS_IN_ROW; i++, sent++) {
    const int wait = i < n_wait;
    const int rc = run_command(&h, i, wait, &cmds[i], &polls);
    errors[!wait] += rc < 0;
    in_row = rc < 0 ? in_row + 1 : 0;
  }
  if (in_row >= MAX_ERRORS_IN_ROW)
    fprintf(stderr, "bench_robot: stopped after %d errors in a row\n", in_row);
  const long connects = h.connects;
  double *get_ms = malloc(BASELINE_N * sizeof *get_ms), *dry_ms = malloc(BASELINE_N * sizeof *dry_ms);
  if (!get_ms || !dry_ms) return 2;
  const int base_errors = time_baseline(&h, BASELINE_N, get_ms, dry_ms);

  checks k;
  check_commands(cmds, sent, log_path, log_from, unit, base, int16, &k);
  const int all_errors = errors[0] + errors[1] + (sent < total ? total - sent : 0);
  const int pass = all_errors == 0 && k.n_log == total && k.other == 0 && k.lost == 0 &&
                   k.duplicated == 0 && k.reply_gaps == 0 && k.words_mismatched == 0 &&
                   k.out_of_order == 0 && k.pose_mismatched == 0 && k.seq_checked == total;

  /* figures, phase by phase */
  for (int phase = 0; phase < 2; phase++) {
    const int lo = phase ? n_wait : 0, hi = phase ? sent : (sent < n_wait ? sent : n_wait);
    int n = 0, na = 0;
    double sum = 0;
    for (int i = lo; i < hi; i++) {
      if (!cmds[i].ok) continue;
      ms[n++] = cmds[i].ms;
      sum += cmds[i].ms;
      if (cmds[i].ack_ms >= 0) ack[na++] = cmds[i].ack_ms;
    }
    if (phase && n_nowait == 0) break;
    const double p50 = bench_percentile(ms, n, 0.50), p90 = bench_percentile(ms, n, 0.90);
    const double p99 = bench_percentile(ms, n, 0.99), mx = bench_percentile(ms, n, 1.0);
    const double a50 = bench_percentile(ack, na, 0.50), a99 = bench_percentile(ack, na, 0.99);
    if (phase == 0) {
      printf("bench=robot_execute n=%d p50_ms=%.3f p90_ms=%.3f p99_ms=%.3f max_ms=%.3f "
             "mean_ms=%.3f ack_p50_ms=%.3f ack_p99_ms=%.3f errors=%d connects=%ld "
             "seq_first=%ld seq_last=%ld seq_checked=%d logged=%d other_writes=%d lost=%d "
             "duplicated=%d reply_gaps=%d out_of_order=%d words_mismatched=%d "
             "pose_mismatched=%d checks=%s\n",
             n_wait, p50, p90, p99, mx, n ? sum / n : NAN, a50, a99, all_errors, connects,
             k.seq_first, k.seq_last, k.seq_checked, k.n_log, k.other, k.lost, k.duplicated,
             k.reply_gaps, k.out_of_order, k.words_mismatched, k.pose_mismatched,
             pass ? "pass" : "fail");
    } else {
      printf("bench=robot_execute_nowait n=%d p50_ms=%.3f p90_ms=%.3f p99_ms=%.3f max_ms=%.3f "
             "ack_p50_ms=%.3f errors=%d polls=%ld\n",
             n_nowait, p50, p90, p99, mx, a50, errors[1], polls);
    }
  }
  printf("bench=robot_execute_baseline n=%d get_robot_p50_ms=%.3f get_robot_p99_ms=%.3f "
         "dry_run_p50_ms=%.3f dry_run_p99_ms=%.3f errors=%d\n", BASELINE_N,
         bench_percentile(get_ms, BASELINE_N, 0.5), bench_percentile(get_ms, BASELINE_N, 0.99),
         bench_percentile(dry_ms, BASELINE_N, 0.5), bench_percentile(dry_ms, BASELINE_N, 0.99), base_errors);
  free(get_ms);
  free(dry_ms);
  free(cmds);
  free(ms);
  free(ack);
  http_free(&h);
  curl_global_cleanup();
  return pass ? 0 : 1;
}
