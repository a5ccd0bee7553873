/* Chromium over the DevTools protocol's pipe transport: see cdp.h. */
#include "cdp.h"
#include "harness.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

static pid_t g_pid = -1;    /* the browser; also its process group */
static int g_to = -1;       /* its fd 3: our commands */
static int g_from = -1;     /* its fd 4: replies and events */
static it_buf g_in;         /* bytes read but not yet split into messages */
static json_t *g_events;    /* every event, oldest first */
static long g_next_id = 1;

/* ---------------------------------------------------------------- the process */

/* The browser program: $FG_CHROMIUM, else the first known name on the PATH. NULL if none. */
static char *find_browser(void) {
  const char *env = getenv("FG_CHROMIUM");
  if (env && *env) return strdup(env);
  static const char *const names[] = {"chromium", "chromium-browser", "google-chrome"};
  const char *path = getenv("PATH");
  if (!path) path = "/usr/bin:/bin";
  for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
    const char *p = path;
    while (*p) {
      size_t n = strcspn(p, ":");
      char *full = h_fmt("%.*s/%s", (int)n, p, names[i]);
      if (access(full, X_OK) == 0) return full;
      free(full);
      p += n;
      if (*p == ':') p++;
    }
  }
  return NULL;
}

static void reap(double timeout_s) {
  if (g_pid <= 0) return;
  const double deadline = h_now_s() + timeout_s;
  for (;;) {
    int st;
    pid_t r = waitpid(g_pid, &st, WNOHANG);
    if (r == g_pid || (r < 0 && errno != EINTR)) break;
    if (h_now_s() > deadline) {
      kill(-g_pid, SIGKILL);
      waitpid(g_pid, &st, 0);
      break;
    }
    h_sleep_ms(20);
  }
  /* whatever the browser started and left behind (renderer, GPU process) */
  kill(-g_pid, SIGKILL);
  g_pid = -1;
}

static int send_message(const char *text);

void cdp_stop(void) {
  if (g_pid <= 0) return;
  /* A clean close lets the browser end its children; the process group goes anyway. */
  if (g_to >= 0) {
    char *msg = h_fmt("{\"id\": %ld, \"method\": \"Browser.close\"}", g_next_id++);
    send_message(msg);
    free(msg);
  }
  reap(10);
  if (g_to >= 0) close(g_to);
  if (g_from >= 0) close(g_from);
  g_to = g_from = -1;
}

static void cdp_atexit(void) { cdp_stop(); }

/* Moves fd to at least 10 so that the child's dup2 onto 3 and 4 cannot clobber it. */
static int high_fd(int fd) {
  int h = fcntl(fd, F_DUPFD_CLOEXEC, 10);
  if (h < 0) FG_TEST_FAIL("fcntl: %s", strerror(errno));
  close(fd);
  return h;
}

int cdp_start(double timeout_s, char *version, size_t version_len, char *why, size_t why_len) {
  char *exe = find_browser();
  if (!exe) {
    snprintf(why, why_len, "no Chromium: none of chromium, chromium-browser, google-chrome is "
             "on the PATH and $FG_CHROMIUM is not set (apt-get install chromium)");
    return -1;
  }
  int to[2], from[2];
  if (pipe(to) != 0 || pipe(from) != 0) FG_TEST_FAIL("pipe: %s", strerror(errno));
  to[0] = high_fd(to[0]), to[1] = high_fd(to[1]);
  from[0] = high_fd(from[0]), from[1] = high_fd(from[1]);
  char *profile = h_fmt("%s/chromium", h_tmpdir());
  char *log = h_fmt("%s/chromium.log", h_tmpdir());
  char *profile_arg = h_fmt("--user-data-dir=%s", profile);
  const char *argv[] = {exe, "--headless", "--no-sandbox", "--remote-debugging-pipe",
                        profile_arg,
                        /* WebGL on the CPU: no GPU in CI */
                        "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                        "--window-size=1200,800", "--hide-scrollbars", "--mute-audio",
                        "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                        "--disable-background-networking", "--disable-component-update",
                        "--disable-sync", "--disable-default-apps", "--disable-dev-shm-usage",
                        "--password-store=basic", "about:blank", NULL};
  fflush(NULL);
  pid_t pid = fork();
  if (pid < 0) FG_TEST_FAIL("fork: %s", strerror(errno));
  if (pid == 0) {
    setpgid(0, 0);
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    int out = open(log, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (out >= 0) {
      dup2(out, 1);
      dup2(out, 2);
    }
    if (dup2(to[0], 3) < 0 || dup2(from[1], 4) < 0) _exit(126);
    execv(exe, (char *const *)argv);
    _exit(127);
  }
  setpgid(pid, pid); /* also here: no race with the kill at exit */
  g_pid = pid;
  close(to[0]);
  close(from[1]);
  g_to = to[1];
  g_from = from[0];
  atexit(cdp_atexit);
  signal(SIGPIPE, SIG_IGN);
  free(profile);
  free(profile_arg);

  /* The first reply says the browser runs; a browser that cannot start closes the pipe. */
  char *msg = h_fmt("{\"id\": %ld, \"method\": \"Browser.getVersion\"}", g_next_id);
  const long id = g_next_id++;
  int rc = send_message(msg);
  free(msg);
  const double deadline = h_now_s() + timeout_s;
  while (rc == 0) {
    char *end = g_in.n ? memchr(g_in.p, 0, g_in.n) : NULL;
    if (end) {
      json_error_t jerr;
      json_t *m = json_loads(g_in.p, 0, &jerr);
      const size_t used = (size_t)(end - g_in.p) + 1;
      memmove(g_in.p, g_in.p + used, g_in.n - used);
      g_in.n -= used;
      if (m && json_integer_value(json_object_get(m, "id")) == id) {
        json_t *product = json_object_get(json_object_get(m, "result"), "product");
        snprintf(version, version_len, "%s",
                 json_is_string(product) ? json_string_value(product) : "?");
        json_decref(m);
        free(exe);
        free(log);
        return 0;
      }
      json_decref(m);
      continue;
    }
    const int left_ms = (int)((deadline - h_now_s()) * 1e3);
    struct pollfd p = {.fd = g_from, .events = POLLIN};
    if (left_ms <= 0 || poll(&p, 1, left_ms) <= 0) break;
    char buf[65536];
    const ssize_t n = read(g_from, buf, sizeof buf);
    if (n <= 0) break;
    it_buf_add(&g_in, buf, (size_t)n);
  }
  size_t log_len = 0;
  char *text = h_read_file(log, &log_len);
  const char *tail = text && log_len > 600 ? text + log_len - 600 : text ? text : "";
  snprintf(why, why_len, "%s did not start: no answer to Browser.getVersion within %g s; "
           "its output ends: %s", exe, timeout_s, tail);
  free(text);
  cdp_stop();
  free(exe);
  free(log);
  return -1;
}

/* ---------------------------------------------------------------- messages */

static int send_message(const char *text) {
  const size_t n = strlen(text) + 1; /* with the NUL that ends a message */
  size_t off = 0;
  while (off < n) {
    const ssize_t w = write(g_to, text + off, n - off);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return -1;
    off += (size_t)w;
  }
  return 0;
}

/* The next message, waiting up to deadline; NULL at the deadline. Fails the test when the
 * browser closed its end. */
static json_t *next_message(double deadline) {
  for (;;) {
    char *end = g_in.n ? memchr(g_in.p, 0, g_in.n) : NULL;
    if (end) {
      json_error_t jerr;
      json_t *m = json_loads(g_in.p, 0, &jerr);
      if (!m) FG_TEST_FAIL("the browser sent a message that is not JSON: %s", jerr.text);
      const size_t used = (size_t)(end - g_in.p) + 1;
      memmove(g_in.p, g_in.p + used, g_in.n - used);
      g_in.n -= used;
      return m;
    }
    const int left_ms = (int)((deadline - h_now_s()) * 1e3);
    if (left_ms <= 0) return NULL;
    struct pollfd p = {.fd = g_from, .events = POLLIN};
    const int pr = poll(&p, 1, left_ms);
    if (pr < 0 && errno == EINTR) continue;
    if (pr <= 0) return NULL;
    char buf[65536];
    const ssize_t n = read(g_from, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) FG_TEST_FAIL("the browser closed the DevTools pipe (it crashed or exited)");
    it_buf_add(&g_in, buf, (size_t)n);
  }
}

json_t *cdp_call(const char *session, const char *method, json_t *params, double timeout_s) {
  if (g_pid <= 0) FG_TEST_FAIL("%s: the browser is not running", method);
  const long id = g_next_id++;
  json_t *m = json_pack("{s:I, s:s, s:o}", "id", (json_int_t)id, "method", method, "params",
                        params ? params : json_object());
  if (session) json_object_set_new(m, "sessionId", json_string(session));
  char *text = json_dumps(m, JSON_COMPACT);
  json_decref(m);
  if (!text || send_message(text) != 0) FG_TEST_FAIL("%s: cannot write to the browser", method);
  free(text);
  if (!g_events) g_events = json_array();
  const double deadline = h_now_s() + timeout_s;
  for (;;) {
    json_t *r = next_message(deadline);
    if (!r) FG_TEST_FAIL("%s: no reply from the browser within %g s", method, timeout_s);
    json_t *rid = json_object_get(r, "id");
    if (!rid) { /* an event */
      json_array_append_new(g_events, r);
      continue;
    }
    if (json_integer_value(rid) != id) { /* a late reply to a command that timed out */
      json_decref(r);
      continue;
    }
    json_t *err = json_object_get(r, "error");
    if (err) {
      char *e = json_dumps(err, JSON_COMPACT);
      FG_TEST_FAIL("%s: the browser answered an error: %s", method, e ? e : "?");
    }
    json_t *result = json_incref(json_object_get(r, "result"));
    json_decref(r);
    return result ? result : json_object();
  }
}

json_t *cdp_events(void) {
  if (!g_events) g_events = json_array();
  return g_events;
}

/* ---------------------------------------------------------------- pages */

char *cdp_open_page(int width, int height) {
  json_t *t = cdp_call(NULL, "Target.createTarget", json_pack("{s:s}", "url", "about:blank"), 30);
  json_t *a = cdp_call(NULL, "Target.attachToTarget",
                       json_pack("{s:O, s:b}", "targetId", json_object_get(t, "targetId"),
                                 "flatten", 1), 30);
  char *session = strdup(json_string_value(json_object_get(a, "sessionId")));
  json_decref(t);
  json_decref(a);
  json_decref(cdp_call(session, "Emulation.setDeviceMetricsOverride",
                       json_pack("{s:i, s:i, s:f, s:b}", "width", width, "height", height,
                                 "deviceScaleFactor", 1.0, "mobile", 0), 30));
  static const char *const domains[] = {"Page.enable", "Runtime.enable", "Log.enable"};
  for (size_t i = 0; i < 3; i++) json_decref(cdp_call(session, domains[i], NULL, 30));
  return session;
}

/* Index of the first event named method of session at or after index from; -1 if none. */
static long find_event(const char *session, const char *method, size_t from) {
  json_t *ev = cdp_events();
  for (size_t i = from; i < json_array_size(ev); i++) {
    json_t *e = json_array_get(ev, i);
    const char *s = json_string_value(json_object_get(e, "sessionId"));
    if (strcmp(json_string_value(json_object_get(e, "method")), method) == 0 &&
        (!session || (s && strcmp(s, session) == 0)))
      return (long)i;
  }
  return -1;
}

void cdp_navigate(const char *session, const char *url, double timeout_s) {
  const size_t from = json_array_size(cdp_events());
  json_t *r = cdp_call(session, "Page.navigate", json_pack("{s:s}", "url", url), timeout_s);
  json_t *err = json_object_get(r, "errorText");
  if (err) FG_TEST_FAIL("navigating to %s: %s", url, json_string_value(err));
  json_decref(r);
  const double deadline = h_now_s() + timeout_s;
  while (find_event(session, "Page.loadEventFired", from) < 0) {
    json_t *m = next_message(deadline);
    if (!m) FG_TEST_FAIL("%s did not load within %g s", url, timeout_s);
    if (json_object_get(m, "id")) json_decref(m); /* a late reply */
    else json_array_append_new(cdp_events(), m);
  }
}

json_t *cdp_eval(const char *session, const char *expression, double timeout_s) {
  json_t *r = cdp_call(session, "Runtime.evaluate",
                       json_pack("{s:s, s:b, s:b}", "expression", expression, "awaitPromise", 1,
                                 "returnByValue", 1), timeout_s);
  json_t *ex = json_object_get(r, "exceptionDetails");
  if (ex) {
    json_t *desc = json_object_get(json_object_get(ex, "exception"), "description");
    json_t *text = json_object_get(ex, "text");
    FG_TEST_FAIL("the page threw evaluating %.200s: %s %s", expression,
                 json_is_string(text) ? json_string_value(text) : "",
                 json_is_string(desc) ? json_string_value(desc) : "");
  }
  json_t *v = json_object_get(json_object_get(r, "result"), "value");
  json_t *out = v ? json_incref(v) : json_null();
  json_decref(r);
  return out;
}

/* ---------------------------------------------------------------- screenshots */

static int b64_value(char c) {
  if (c >= 'A' && c <= 'Z') return c - 'A';
  if (c >= 'a' && c <= 'z') return c - 'a' + 26;
  if (c >= '0' && c <= '9') return c - '0' + 52;
  if (c == '+') return 62;
  if (c == '/') return 63;
  return -1;
}

void cdp_screenshot(const char *session, uint8_t **png, size_t *len) {
  json_t *r = cdp_call(session, "Page.captureScreenshot", json_pack("{s:s}", "format", "png"),
                       60);
  const char *b64 = json_string_value(json_object_get(r, "data"));
  if (!b64) FG_TEST_FAIL("Page.captureScreenshot: no data");
  const size_t n = strlen(b64);
  uint8_t *out = malloc(n / 4 * 3 + 3);
  if (!out) FG_TEST_FAIL("out of memory");
  size_t k = 0;
  uint32_t acc = 0;
  int bits = 0;
  for (size_t i = 0; i < n && b64[i] != '='; i++) {
    const int v = b64_value(b64[i]);
    if (v < 0) FG_TEST_FAIL("Page.captureScreenshot: not base64 at %zu", i);
    acc = acc << 6 | (uint32_t)v;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out[k++] = (uint8_t)(acc >> bits);
    }
  }
  json_decref(r);
  *png = out;
  *len = k;
}
