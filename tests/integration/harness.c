/* Integration harness: the daemon as a child process, HTTP over libcurl, JSON with jansson.
 * See harness.h for the contract of each helper. */
#include "harness.h"

#include <curl/curl.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <limits.h>
#include <netinet/in.h>
#include <arpa/inet.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <strings.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

/* ---------------------------------------------------------------------------------------- */
/* State of the one daemon a test process drives                                             */

static char g_daemon[PATH_MAX];
static char g_tmp[PATH_MAX];
static char g_state[PATH_MAX + 16];
static char g_conf[PATH_MAX + 32];
static char g_logpath[PATH_MAX + 16];
static const char *g_log_level = "debug";
static volatile pid_t g_pid = -1;
static int g_port = 0;
static int g_ok = 0;
static char g_token[512];
static int g_has_token = 0;
static pthread_mutex_t g_token_lock = PTHREAD_MUTEX_INITIALIZER;
static volatile sig_atomic_t g_cleaned = 0;

char *h_fmt(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  char *s = NULL;
  int n = vasprintf(&s, fmt, ap);
  va_end(ap);
  if (n < 0) FG_TEST_FAIL("out of memory");
  return s;
}

void h_sleep_ms(int ms) {
  struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
  }
}

double h_now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static int rm_cb(const char *path, const struct stat *sb, int flag, struct FTW *ftw) {
  (void)sb;
  (void)flag;
  (void)ftw;
  remove(path);
  return 0;
}

static void dump_log_tail(void) {
  size_t len = 0;
  char *log = h_read_file(g_logpath, &len);
  if (!log) return;
  size_t from = len > 6000 ? len - 6000 : 0;
  fprintf(stderr, "---- daemon log (last %zu bytes of %s) ----\n%s\n---- end of daemon log ----\n",
          len - from, g_logpath, log + from);
  free(log);
}

/* Kills the daemon and removes the temp dir. Runs at exit (also after a failed ASSERT, which
 * calls exit) and from the fatal-signal handler. */
static void cleanup(void) {
  if (g_cleaned) return;
  g_cleaned = 1;
  pid_t pid = g_pid;
  if (pid > 0) {
    kill(pid, SIGKILL);
    waitpid(pid, NULL, 0);
    g_pid = -1;
  }
  if (!g_ok && g_logpath[0]) dump_log_tail();
  if (g_tmp[0]) {
    if (getenv("FG_KEEP_TMP"))
      fprintf(stderr, "keeping %s\n", g_tmp);
    else
      h_remove_tree(g_tmp);
  }
}

static void on_fatal_signal(int sig) {
  cleanup();
  signal(sig, SIG_DFL);
  raise(sig);
}

void h_done(void) { g_ok = 1; }
const char *h_tmpdir(void) { return g_tmp; }
const char *h_state_dir(void) { return g_state; }
const char *h_config_path(void) { return g_conf; }
const char *h_daemon_path(void) { return g_daemon; }
int h_port(void) { return g_port; }
pid_t h_pid(void) { return g_pid; }

void h_init(int argc, char **argv) {
  const char *d = argc > 1 ? argv[1] : getenv("FG_DAEMON");
  if (!d || !*d) FG_TEST_FAIL("usage: %s PATH-TO-fieldgripd (or set FG_DAEMON)", argv[0]);
  if (!realpath(d, g_daemon)) FG_TEST_FAIL("daemon %s: %s", d, strerror(errno));
  if (access(g_daemon, X_OK) != 0) FG_TEST_FAIL("daemon %s is not executable", g_daemon);

  snprintf(g_tmp, sizeof g_tmp, "/tmp/fg-it-XXXXXX");
  if (!mkdtemp(g_tmp)) FG_TEST_FAIL("mkdtemp: %s", strerror(errno));
  atexit(cleanup);
  signal(SIGTERM, on_fatal_signal);
  signal(SIGINT, on_fatal_signal);
  signal(SIGABRT, on_fatal_signal); /* abort_on_error=1 sanitizer reports end in abort() */
  signal(SIGPIPE, SIG_IGN);

  snprintf(g_state, sizeof g_state, "%s/state", g_tmp);
  snprintf(g_conf, sizeof g_conf, "%s/fieldgripd.conf", g_tmp);
  snprintf(g_logpath, sizeof g_logpath, "%s/daemon.log", g_tmp);
  h_write_config("; written by the fieldgrip integration harness\n");
  if (curl_global_init(CURL_GLOBAL_ALL) != 0) FG_TEST_FAIL("curl_global_init failed");
  setvbuf(stdout, NULL, _IOLBF, 0);
}

void h_write_file(const char *path, const void *data, size_t len) {
  FILE *f = fopen(path, "wb");
  if (!f) FG_TEST_FAIL("open %s: %s", path, strerror(errno));
  if (len && fwrite(data, 1, len, f) != len) FG_TEST_FAIL("write %s: %s", path, strerror(errno));
  if (fclose(f) != 0) FG_TEST_FAIL("close %s: %s", path, strerror(errno));
}

char *h_read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 4096, n = 0;
  char *buf = malloc(cap + 1);
  if (!buf) FG_TEST_FAIL("out of memory");
  for (;;) {
    if (n == cap) {
      cap *= 2;
      buf = realloc(buf, cap + 1);
      if (!buf) FG_TEST_FAIL("out of memory");
    }
    size_t got = fread(buf + n, 1, cap - n, f);
    n += got;
    if (got == 0) break;
  }
  fclose(f);
  buf[n] = '\0';
  if (len) *len = n;
  return buf;
}

void h_mkdirs(const char *path) {
  char buf[PATH_MAX];
  snprintf(buf, sizeof buf, "%s", path);
  for (char *p = buf + 1; *p; p++) {
    if (*p != '/') continue;
    *p = '\0';
    if (mkdir(buf, 0755) != 0 && errno != EEXIST) FG_TEST_FAIL("mkdir %s: %s", buf, strerror(errno));
    *p = '/';
  }
  if (mkdir(buf, 0755) != 0 && errno != EEXIST) FG_TEST_FAIL("mkdir %s: %s", buf, strerror(errno));
}

void h_write_config(const char *text) { h_write_file(g_conf, text, strlen(text)); }

static off_t log_size(void) {
  struct stat st;
  return stat(g_logpath, &st) == 0 ? st.st_size : 0;
}

/* Reaps the child if it has exited; returns 1 and fills *status then. */
static int child_exited(int *status) {
  if (g_pid <= 0) return 1;
  pid_t r = waitpid(g_pid, status, WNOHANG);
  if (r == g_pid) {
    g_pid = -1;
    return 1;
  }
  return 0;
}

static void describe_status(int status, char *buf, size_t n) {
  if (WIFEXITED(status))
    snprintf(buf, n, "exit status %d", WEXITSTATUS(status));
  else if (WIFSIGNALED(status))
    snprintf(buf, n, "killed by signal %d (%s)", WTERMSIG(status), strsignal(WTERMSIG(status)));
  else
    snprintf(buf, n, "status 0x%x", status);
}

void h_set_log_level(const char *level) { g_log_level = level; }

void h_start(void) {
  if (g_pid > 0) FG_TEST_FAIL("h_start: the daemon is already running (pid %d)", (int)g_pid);
  h_mkdirs(g_state);
  off_t from = log_size();
  char marker[128];
  int mlen = snprintf(marker, sizeof marker, "\n==== harness: starting %s ====\n", g_daemon);
  int lfd = open(g_logpath, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (lfd < 0) FG_TEST_FAIL("open %s: %s", g_logpath, strerror(errno));
  if (write(lfd, marker, (size_t)mlen) < 0) FG_TEST_FAIL("write log: %s", strerror(errno));
  from += mlen;

  const char *argv[] = {g_daemon,    "--config", g_conf,  "--state-dir", g_state, "--listen",
                        "127.0.0.1:0", "--log-level", g_log_level, NULL};
  pid_t parent = getpid();
  pid_t pid = fork();
  if (pid < 0) FG_TEST_FAIL("fork: %s", strerror(errno));
  if (pid == 0) {
    /* Only async-signal-safe calls between fork and exec. The daemon dies with us. */
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    int nul = open("/dev/null", O_RDONLY);
    if (nul >= 0) dup2(nul, 0);
    dup2(lfd, 1);
    dup2(lfd, 2);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, NULL);
    signal(SIGPIPE, SIG_DFL);
    execv(g_daemon, (char *const *)argv);
    _exit(127);
  }
  close(lfd);
  g_pid = pid;
  g_port = 0;

  const char *needle = "listening on http://127.0.0.1:";
  double deadline = h_now_s() + 10.0;
  for (;;) {
    size_t len = 0;
    char *log = h_read_file(g_logpath, &len);
    if (log && (size_t)from <= len) {
      const char *p = strstr(log + from, needle);
      if (p) {
        p += strlen(needle);
        char *end = NULL;
        long port = strtol(p, &end, 10);
        if (end != p && *end != '\0' && port > 0 && port < 65536) {
          g_port = (int)port;
          free(log);
          return;
        }
      }
    }
    free(log);
    int status = 0;
    if (child_exited(&status)) {
      char why[128];
      describe_status(status, why, sizeof why);
      FG_TEST_FAIL("the daemon exited before it listened (%s)", why);
    }
    if (h_now_s() > deadline)
      FG_TEST_FAIL("no \"%s<port>\" line in %s within 10 s", needle, g_logpath);
    h_sleep_ms(20);
  }
}

static int wait_exit(double timeout_s, int *status) {
  double deadline = h_now_s() + timeout_s;
  while (!child_exited(status)) {
    if (h_now_s() > deadline) return 0;
    h_sleep_ms(10);
  }
  return 1;
}

void h_stop(void) {
  if (g_pid <= 0) FG_TEST_FAIL("h_stop: no daemon running");
  if (kill(g_pid, SIGTERM) != 0) FG_TEST_FAIL("kill SIGTERM: %s", strerror(errno));
  int status = 0;
  /* A hang guard, not a timing assertion: a clean shutdown must end at all. */
  if (!wait_exit(60.0, &status)) {
    kill(g_pid, SIGKILL);
    FG_TEST_FAIL("the daemon did not exit within 60 s of SIGTERM");
  }
  char why[128];
  describe_status(status, why, sizeof why);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    FG_TEST_FAIL("the daemon's SIGTERM shutdown ended with %s, expected exit status 0", why);
  g_port = 0;
}

void h_kill(void) {
  if (g_pid <= 0) FG_TEST_FAIL("h_kill: no daemon running");
  kill(g_pid, SIGKILL);
  int status = 0;
  waitpid(g_pid, &status, 0);
  g_pid = -1;
  g_port = 0;
}

void h_signal(int sig) {
  if (g_pid <= 0) FG_TEST_FAIL("h_signal: no daemon running");
  if (kill(g_pid, sig) != 0) FG_TEST_FAIL("kill %d: %s", sig, strerror(errno));
}

/* The reloads the daemon has finished, good and failed. */
static double reloads_finished(void) {
  return h_metric("fieldgrip_config_reloads_total{result=\"ok\"}") +
         h_metric("fieldgrip_config_reloads_total{result=\"failed\"}");
}

void h_reload(void) {
  const double before = reloads_finished();
  h_signal(SIGHUP);
  const double deadline = h_now_s() + 60;
  while (reloads_finished() < before + 1) {
    if (h_now_s() > deadline) FG_TEST_FAIL("no reload finished within 60 s of SIGHUP");
    h_sleep_ms(20);
  }
}

int h_alive(void) {
  int status = 0;
  if (child_exited(&status)) return 0;
  return kill(g_pid, 0) == 0;
}

char *h_log(void) {
  char *s = h_read_file(g_logpath, NULL);
  if (!s) FG_TEST_FAIL("cannot read %s", g_logpath);
  return s;
}

int h_log_count(const char *needle) {
  char *log = h_log();
  int n = 0;
  for (const char *p = strstr(log, needle); p; p = strstr(p + 1, needle)) n++;
  free(log);
  return n;
}

int h_wait_log(const char *needle, int min_count, double timeout_s) {
  double deadline = h_now_s() + timeout_s;
  for (;;) {
    if (h_log_count(needle) >= min_count) return 1;
    if (h_now_s() > deadline) return 0;
    h_sleep_ms(20);
  }
}

int h_run_daemon_capture(const char *const *args, char **out) {
  char path[PATH_MAX + 32];
  snprintf(path, sizeof path, "%s/capture.txt", g_tmp);
  int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) FG_TEST_FAIL("open %s: %s", path, strerror(errno));
  const char *argv[32];
  int n = 0;
  argv[n++] = g_daemon;
  for (int i = 0; args[i] && n < 31; i++) argv[n++] = args[i];
  argv[n] = NULL;
  pid_t parent = getpid();
  pid_t pid = fork();
  if (pid < 0) FG_TEST_FAIL("fork: %s", strerror(errno));
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    int nul = open("/dev/null", O_RDONLY);
    if (nul >= 0) dup2(nul, 0);
    dup2(fd, 1);
    dup2(fd, 2);
    signal(SIGPIPE, SIG_DFL);
    execv(g_daemon, (char *const *)argv);
    _exit(127);
  }
  close(fd);
  int status = 0;
  double deadline = h_now_s() + 60.0;
  for (;;) {
    pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) break;
    if (h_now_s() > deadline) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      FG_TEST_FAIL("%s did not exit within 60 s", g_daemon);
    }
    h_sleep_ms(10);
  }
  *out = h_read_file(path, NULL);
  if (!*out) FG_TEST_FAIL("cannot read %s", path);
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

/* ---------------------------------------------------------------------------------------- */
/* Files                                                                                      */

static const char *g_count_needle;
static int g_count;
static pthread_mutex_t g_count_lock = PTHREAD_MUTEX_INITIALIZER;

static int count_cb(const char *path, const struct stat *sb, int flag, struct FTW *ftw) {
  (void)sb;
  if (flag == FTW_F || flag == FTW_SL) {
    const char *name = path + ftw->base;
    if (strstr(name, g_count_needle)) {
      fprintf(stderr, "found %s\n", path);
      g_count++;
    }
  }
  return 0;
}

int h_count_files(const char *dir, const char *needle) {
  pthread_mutex_lock(&g_count_lock);
  g_count_needle = needle;
  g_count = 0;
  nftw(dir, count_cb, 16, FTW_PHYS);
  int n = g_count;
  pthread_mutex_unlock(&g_count_lock);
  return n;
}

void h_copy_tree(const char *from, const char *to) {
  h_mkdirs(to);
  DIR *d = opendir(from);
  if (!d) FG_TEST_FAIL("opendir %s: %s", from, strerror(errno));
  struct dirent *e;
  while ((e = readdir(d)) != NULL) {
    if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
    char *src = h_fmt("%s/%s", from, e->d_name), *dst = h_fmt("%s/%s", to, e->d_name);
    struct stat st;
    if (lstat(src, &st) != 0) FG_TEST_FAIL("stat %s: %s", src, strerror(errno));
    if (S_ISDIR(st.st_mode)) {
      h_copy_tree(src, dst);
    } else if (S_ISREG(st.st_mode)) {
      size_t len;
      char *data = h_read_file(src, &len);
      if (!data) FG_TEST_FAIL("read %s: %s", src, strerror(errno));
      h_write_file(dst, data, len);
      free(data);
    } else {
      FG_TEST_FAIL("copy %s: neither a file nor a folder", src);
    }
    free(src);
    free(dst);
  }
  closedir(d);
}

void h_remove_tree(const char *path) { nftw(path, rm_cb, 16, FTW_DEPTH | FTW_PHYS); }

char *h_shared_data(void) {
  const char *d = getenv("FG_SHARED_DATA");
  if (!d || !*d) FG_TEST_FAIL("FG_SHARED_DATA is not set (run through meson test)");
  char *r = realpath(d, NULL);
  if (!r) FG_TEST_FAIL("FG_SHARED_DATA=%s: %s", d, strerror(errno));
  return r;
}

/* ---------------------------------------------------------------------------------------- */
/* HTTP                                                                                       */

void h_set_token(const char *token) {
  pthread_mutex_lock(&g_token_lock);
  g_has_token = token != NULL;
  snprintf(g_token, sizeof g_token, "%s", token ? token : "");
  pthread_mutex_unlock(&g_token_lock);
}

void it_buf_add(it_buf *b, const void *data, size_t n) {
  if (b->n + n + 1 > b->cap) {
    size_t cap = b->cap ? b->cap : 256;
    while (cap < b->n + n + 1) cap *= 2;
    b->p = realloc(b->p, cap);
    if (!b->p) FG_TEST_FAIL("out of memory");
    b->cap = cap;
  }
  memcpy(b->p + b->n, data, n);
  b->n += n;
  b->p[b->n] = '\0';
}

static size_t on_body(char *ptr, size_t size, size_t nmemb, void *ud) {
  it_buf_add(ud, ptr, size * nmemb);
  return size * nmemb;
}

static size_t on_header(char *ptr, size_t size, size_t nmemb, void *ud) {
  h_resp *r = ud;
  size_t n = size * nmemb;
  if (n >= 5 && memcmp(ptr, "HTTP/", 5) == 0) {
    /* A new status line (after a 100 Continue): forget the earlier headers. */
    for (int i = 0; i < r->n_headers; i++) {
      free(r->headers[i].name);
      free(r->headers[i].value);
    }
    r->n_headers = 0;
    return n;
  }
  const char *colon = memchr(ptr, ':', n);
  if (!colon) return n;
  size_t nl = (size_t)(colon - ptr);
  const char *v = colon + 1;
  const char *end = ptr + n;
  while (v < end && (*v == ' ' || *v == '\t')) v++;
  while (end > v && (end[-1] == '\r' || end[-1] == '\n' || end[-1] == ' ')) end--;
  r->headers = realloc(r->headers, sizeof(h_header) * (size_t)(r->n_headers + 1));
  if (!r->headers) FG_TEST_FAIL("out of memory");
  r->headers[r->n_headers].name = strndup(ptr, nl);
  r->headers[r->n_headers].value = strndup(v, (size_t)(end - v));
  r->n_headers++;
  return n;
}

const char *h_resp_header(const h_resp *r, const char *name) {
  for (int i = 0; i < r->n_headers; i++)
    if (strcasecmp(r->headers[i].name, name) == 0) return r->headers[i].value;
  return NULL;
}

void h_resp_free(h_resp *r) {
  if (!r) return;
  for (int i = 0; i < r->n_headers; i++) {
    free(r->headers[i].name);
    free(r->headers[i].value);
  }
  free(r->headers);
  free(r->body);
  json_decref(r->json);
  free(r);
}

h_resp *h_request(const h_req *req) {
  if (g_port <= 0) FG_TEST_FAIL("h_request %s: the daemon is not running", req->path);
  h_resp *r = calloc(1, sizeof *r);
  if (!r) FG_TEST_FAIL("out of memory");
  CURL *c = curl_easy_init();
  if (!c) FG_TEST_FAIL("curl_easy_init failed");
  char url[1200];
  snprintf(url, sizeof url, "http://127.0.0.1:%d%s", g_port, req->path);
  const char *method = req->method ? req->method : "GET";
  curl_easy_setopt(c, CURLOPT_URL, url);
  curl_easy_setopt(c, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(c, CURLOPT_NOPROXY, "*");
  /* Send the path exactly as written ("/v1/scenes/.." must reach the daemon as such). */
  curl_easy_setopt(c, CURLOPT_PATH_AS_IS, 1L);
  /* A hang guard for a wedged daemon; meson's timeout is the real limit. */
  if (req->timeout_ms > 0)
    curl_easy_setopt(c, CURLOPT_TIMEOUT_MS, req->timeout_ms);
  else
    curl_easy_setopt(c, CURLOPT_TIMEOUT, 300L);
  curl_easy_setopt(c, CURLOPT_CONNECTTIMEOUT, 30L);
  it_buf body = {0};
  curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, on_body);
  curl_easy_setopt(c, CURLOPT_WRITEDATA, &body);
  curl_easy_setopt(c, CURLOPT_HEADERFUNCTION, on_header);
  curl_easy_setopt(c, CURLOPT_HEADERDATA, r);

  struct curl_slist *hdrs = NULL;
  char line[700];
  if (req->auth == H_AUTH_TOKEN) {
    snprintf(line, sizeof line, "Authorization: Bearer %s", req->token ? req->token : "");
    hdrs = curl_slist_append(hdrs, line);
  } else if (req->auth == H_AUTH_DEFAULT) {
    pthread_mutex_lock(&g_token_lock);
    if (g_has_token) {
      snprintf(line, sizeof line, "Authorization: Bearer %s", g_token);
      hdrs = curl_slist_append(hdrs, line);
    }
    pthread_mutex_unlock(&g_token_lock);
  }
  for (int i = 0; req->headers && req->headers[i]; i++) hdrs = curl_slist_append(hdrs, req->headers[i]);

  curl_mime *mime = NULL;
  if (req->n_parts > 0) {
    mime = curl_mime_init(c);
    for (int i = 0; i < req->n_parts; i++) {
      const h_part *p = &req->parts[i];
      curl_mimepart *mp = curl_mime_addpart(mime);
      curl_mime_name(mp, p->name);
      curl_mime_data(mp, p->data ? p->data : "", p->len);
      if (p->filename) curl_mime_filename(mp, p->filename);
      if (p->type) curl_mime_type(mp, p->type);
    }
    curl_easy_setopt(c, CURLOPT_MIMEPOST, mime);
    if (strcmp(method, "POST") != 0) curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  } else if (req->read_cb) {
    /* libcurl's own type for a POST is application/x-www-form-urlencoded, which the daemon
     * refuses (http_guard.h): JSON unless the caller set a type or a Content-Type line. */
    int typed = 0;
    for (int i = 0; req->headers && req->headers[i]; i++)
      typed |= strncasecmp(req->headers[i], "Content-Type:", 13) == 0;
    if (!typed) {
      snprintf(line, sizeof line, "Content-Type: %s",
               req->content_type ? req->content_type : "application/json");
      hdrs = curl_slist_append(hdrs, line);
    }
    curl_easy_setopt(c, CURLOPT_POST, 1L);
    curl_easy_setopt(c, CURLOPT_READFUNCTION, req->read_cb);
    curl_easy_setopt(c, CURLOPT_READDATA, req->read_ud);
    if (req->read_len >= 0)
      curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE_LARGE, (curl_off_t)req->read_len);
    else
      hdrs = curl_slist_append(hdrs, "Transfer-Encoding: chunked");
    if (strcmp(method, "POST") != 0) curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  } else if (req->body) {
    snprintf(line, sizeof line, "Content-Type: %s",
             req->content_type ? req->content_type : "application/json");
    hdrs = curl_slist_append(hdrs, line);
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, req->body);
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE_LARGE, (curl_off_t)req->body_len);
    if (strcmp(method, "POST") != 0) curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  } else if (strcmp(method, "GET") == 0) {
    curl_easy_setopt(c, CURLOPT_HTTPGET, 1L);
  } else if (strcmp(method, "HEAD") == 0) {
    curl_easy_setopt(c, CURLOPT_NOBODY, 1L);
  } else if (strcmp(method, "POST") == 0) {
    curl_easy_setopt(c, CURLOPT_POSTFIELDS, "");
    curl_easy_setopt(c, CURLOPT_POSTFIELDSIZE, 0L);
  } else {
    curl_easy_setopt(c, CURLOPT_CUSTOMREQUEST, method);
  }
  curl_easy_setopt(c, CURLOPT_HTTPHEADER, hdrs);

  r->curl_rc = (int)curl_easy_perform(c);
  curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, &r->status);
  if (r->curl_rc != CURLE_OK && r->status == 0)
    fprintf(stderr, "note: %s %s: %s\n", method, req->path, curl_easy_strerror((CURLcode)r->curl_rc));
  curl_easy_cleanup(c);
  curl_mime_free(mime);
  curl_slist_free_all(hdrs);
  if (!body.p) it_buf_add(&body, "", 0);
  r->body = body.p;
  r->len = body.n;
  r->json = json_loadb(r->body, r->len, JSON_DECODE_ANY, NULL);
  return r;
}

h_resp *h_get(const char *path) {
  h_req q = {.method = "GET", .path = path};
  return h_request(&q);
}

h_resp *h_delete(const char *path) {
  h_req q = {.method = "DELETE", .path = path};
  return h_request(&q);
}

h_resp *h_post_json(const char *path, const char *json_text) {
  h_req q = {.method = "POST", .path = path, .body = json_text, .body_len = strlen(json_text)};
  return h_request(&q);
}

h_resp *h_upload_parts(const char *path, const h_part *parts, int n_parts) {
  h_req q = {.method = "POST", .path = path, .parts = parts, .n_parts = n_parts};
  return h_request(&q);
}

h_resp *h_upload(const char *path, const void *image, size_t image_len, const char *meta,
                 const void *features, size_t features_len) {
  h_part parts[3];
  int n = 0;
  if (image) parts[n++] = (h_part){"image", image, image_len, "image.png", "image/png"};
  if (meta) parts[n++] = (h_part){"meta", meta, strlen(meta), NULL, "application/json"};
  if (features)
    parts[n++] = (h_part){"features", features, features_len, "features.npy",
                          "application/octet-stream"};
  return h_upload_parts(path, parts, n);
}

static int raw_connect(void) {
  int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) FG_TEST_FAIL("socket: %s", strerror(errno));
  struct sockaddr_in sa = {0};
  sa.sin_family = AF_INET;
  sa.sin_port = htons((uint16_t)g_port);
  sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (connect(fd, (struct sockaddr *)&sa, sizeof sa) != 0) FG_TEST_FAIL("connect: %s", strerror(errno));
  struct timeval tv = {30, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  return fd;
}

void h_raw_abandon(const void *req, size_t len) {
  if (g_port <= 0) FG_TEST_FAIL("h_raw_abandon: the daemon is not running");
  int fd = raw_connect();
  if (len) send(fd, req, len, MSG_NOSIGNAL);
  close(fd);
}

long h_raw_exchange(const void *req, size_t len, char *resp, size_t cap) {
  if (g_port <= 0) FG_TEST_FAIL("h_raw_exchange: the daemon is not running");
  int fd = raw_connect();
  size_t off = 0;
  while (off < len) {
    ssize_t n = send(fd, (const char *)req + off, len - off, MSG_NOSIGNAL);
    if (n <= 0) break; /* the daemon may close early on a bad request; read what it said */
    off += (size_t)n;
  }
  shutdown(fd, SHUT_WR);
  size_t got = 0;
  int reset = 0;
  while (got + 1 < cap) {
    ssize_t n = recv(fd, resp + got, cap - 1 - got, 0);
    if (n == 0) break;
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno == EAGAIN || errno == EWOULDBLOCK) FG_TEST_FAIL("no answer and no close within 30 s");
      reset = 1;
      break;
    }
    got += (size_t)n;
  }
  close(fd);
  resp[got] = '\0';
  return reset && got == 0 ? -1 : (long)got;
}

void h_multipart_build(const h_part *parts, int n_parts, const char *boundary, uint8_t **out,
                       size_t *out_len) {
  it_buf b = {0};
  for (int i = 0; i < n_parts; i++) {
    const h_part *p = &parts[i];
    char *head;
    if (p->filename)
      head = h_fmt("--%s\r\nContent-Disposition: form-data; name=\"%s\"; filename=\"%s\"\r\n"
                   "Content-Type: %s\r\n\r\n",
                   boundary, p->name, p->filename, p->type ? p->type : "application/octet-stream");
    else if (p->type)
      head = h_fmt("--%s\r\nContent-Disposition: form-data; name=\"%s\"\r\nContent-Type: %s\r\n\r\n",
                   boundary, p->name, p->type);
    else
      head = h_fmt("--%s\r\nContent-Disposition: form-data; name=\"%s\"\r\n\r\n", boundary, p->name);
    it_buf_add(&b, head, strlen(head));
    free(head);
    it_buf_add(&b, p->data, p->len);
    it_buf_add(&b, "\r\n", 2);
  }
  char *tail = h_fmt("--%s--\r\n", boundary);
  it_buf_add(&b, tail, strlen(tail));
  free(tail);
  *out = (uint8_t *)b.p;
  *out_len = b.n;
}

/* ---------------------------------------------------------------------------------------- */
/* Assertions                                                                                 */

static const char *preview(const h_resp *r) { return r->body ? r->body : "(none)"; }

void h_assert_status_at(const char *file, int line, const h_resp *r, long status) {
  if (r->status != status) {
    fprintf(stderr, "%s:%d: HTTP status %ld, expected %ld (curl: %s); body: %.2000s\n", file, line,
            r->status, status, curl_easy_strerror((CURLcode)r->curl_rc), preview(r));
    exit(1);
  }
}

void h_assert_error_at(const char *file, int line, const h_resp *r, long status,
                       const char *code) {
  h_assert_status_at(file, line, r, status);
  json_t *err = r->json ? json_object_get(r->json, "error") : NULL;
  json_t *c = err ? json_object_get(err, "code") : NULL;
  json_t *m = err ? json_object_get(err, "message") : NULL;
  if (!json_is_object(err) || !json_is_string(c) || !json_is_string(m)) {
    fprintf(stderr, "%s:%d: error reply is not {\"error\":{\"code\":str,\"message\":str}}: %.2000s\n",
            file, line, preview(r));
    exit(1);
  }
  if (strcmp(json_string_value(c), code) != 0) {
    fprintf(stderr, "%s:%d: error code \"%s\", expected \"%s\"; body: %.2000s\n", file, line,
            json_string_value(c), code, preview(r));
    exit(1);
  }
  if (json_string_length(m) == 0) {
    fprintf(stderr, "%s:%d: empty error message; body: %.2000s\n", file, line, preview(r));
    exit(1);
  }
  const char *ct = h_resp_header(r, "Content-Type");
  if (!ct || strncasecmp(ct, "application/json", 16) != 0) {
    fprintf(stderr, "%s:%d: error reply Content-Type \"%s\", expected application/json\n", file,
            line, ct ? ct : "(none)");
    exit(1);
  }
}

void h_expect_error_at(const char *file, int line, const char *method, const char *path,
                       const char *body, long status, const char *code) {
  h_req q = {.method = method, .path = path, .body = body, .body_len = body ? strlen(body) : 0};
  h_resp *r = h_request(&q);
  if (r->status != status)
    fprintf(stderr, "%s:%d: %s %s %s\n", file, line, method, path, body ? body : "");
  h_assert_error_at(file, line, r, status, code);
  h_resp_free(r);
}

json_t *h_jfind(json_t *root, const char *path) {
  json_t *cur = root;
  const char *p = path;
  while (cur && *p) {
    const char *dot = strchr(p, '.');
    size_t n = dot ? (size_t)(dot - p) : strlen(p);
    char key[256];
    if (n >= sizeof key) return NULL;
    memcpy(key, p, n);
    key[n] = '\0';
    if (json_is_object(cur)) {
      cur = json_object_get(cur, key);
    } else if (json_is_array(cur)) {
      char *end = NULL;
      long i = strtol(key, &end, 10);
      if (end == key || *end || i < 0) return NULL;
      cur = json_array_get(cur, (size_t)i);
    } else {
      return NULL;
    }
    p += n;
    if (*p == '.') p++;
  }
  return cur;
}

json_t *h_jget_at(const char *file, int line, json_t *root, const char *path) {
  if (!root) {
    fprintf(stderr, "%s:%d: no JSON (looking up \"%s\")\n", file, line, path);
    exit(1);
  }
  json_t *v = h_jfind(root, path);
  if (!v) {
    char *s = json_dumps(root, JSON_ENCODE_ANY | JSON_COMPACT);
    fprintf(stderr, "%s:%d: no \"%s\" in %.2000s\n", file, line, path, s ? s : "?");
    free(s);
    exit(1);
  }
  return v;
}

double h_jnum_at(const char *file, int line, json_t *root, const char *path) {
  json_t *v = h_jget_at(file, line, root, path);
  if (!json_is_number(v)) {
    fprintf(stderr, "%s:%d: \"%s\" is not a number\n", file, line, path);
    exit(1);
  }
  return json_number_value(v);
}

long long h_jint_at(const char *file, int line, json_t *root, const char *path) {
  json_t *v = h_jget_at(file, line, root, path);
  if (!json_is_integer(v)) {
    char *s = json_dumps(v, JSON_ENCODE_ANY);
    fprintf(stderr, "%s:%d: \"%s\" is not an integer: %s\n", file, line, path, s ? s : "?");
    free(s);
    exit(1);
  }
  return json_integer_value(v);
}

const char *h_jstr_at(const char *file, int line, json_t *root, const char *path) {
  json_t *v = h_jget_at(file, line, root, path);
  if (!json_is_string(v)) {
    char *s = json_dumps(v, JSON_ENCODE_ANY);
    fprintf(stderr, "%s:%d: \"%s\" is not a string: %s\n", file, line, path, s ? s : "?");
    free(s);
    exit(1);
  }
  return json_string_value(v);
}

void h_assert_vec_at(const char *file, int line, json_t *v, const double *x, int n, double tol) {
  if (!json_is_array(v) || (int)json_array_size(v) != n) {
    char *s = json_dumps(v, JSON_ENCODE_ANY);
    fprintf(stderr, "%s:%d: expected an array of %d numbers, got %s\n", file, line, n, s ? s : "?");
    free(s);
    exit(1);
  }
  for (int i = 0; i < n; i++) {
    json_t *e = json_array_get(v, (size_t)i);
    if (!json_is_number(e) || !(fabs(json_number_value(e) - x[i]) <= tol)) {
      char *s = json_dumps(v, JSON_ENCODE_ANY);
      fprintf(stderr, "%s:%d: element %d is %s, expected %.9g (tol %g)\n", file, line, i,
              s ? s : "?", x[i], tol);
      free(s);
      exit(1);
    }
  }
}

void h_assert_matrix_at(const char *file, int line, json_t *m, const double T[16], double tol) {
  if (!json_is_array(m) || json_array_size(m) != 4) {
    fprintf(stderr, "%s:%d: matrix is not an array of 4 rows\n", file, line);
    exit(1);
  }
  for (int r = 0; r < 4; r++) h_assert_vec_at(file, line, json_array_get(m, (size_t)r), T + 4 * r, 4, tol);
}

void h_assert_json_equal_at(const char *file, int line, json_t *a, json_t *b) {
  if (!a || !b || !json_equal(a, b)) {
    char *sa = a ? json_dumps(a, JSON_ENCODE_ANY | JSON_SORT_KEYS | JSON_COMPACT) : NULL;
    char *sb = b ? json_dumps(b, JSON_ENCODE_ANY | JSON_SORT_KEYS | JSON_COMPACT) : NULL;
    fprintf(stderr, "%s:%d: JSON differs:\n  %.3000s\nvs\n  %.3000s\n", file, line,
            sa ? sa : "(null)", sb ? sb : "(null)");
    free(sa);
    free(sb);
    exit(1);
  }
}

double h_metric(const char *series) {
  h_resp *r = h_get("/metrics");
  h_assert_status_at(__FILE__, __LINE__, r, 200);
  size_t n = strlen(series);
  for (const char *p = r->body; (p = strstr(p, series)) != NULL; p += n) {
    if ((p != r->body && p[-1] != '\n') || p[n] != ' ') continue;
    double v = strtod(p + n + 1, NULL);
    h_resp_free(r);
    return v;
  }
  char *body = h_fmt("%s", r->body);
  h_resp_free(r);
  FG_TEST_FAIL("no series %s in /metrics:\n%s", series, body);
}
