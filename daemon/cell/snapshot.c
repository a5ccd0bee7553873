/* One image from a camera's source (cameras.h: fg_snapshot_fetch): an HTTP snapshot with
 * libcurl, or a frame of a V4L2 device from a fieldgrip-grab child. */
#include "cameras.h"

#include <curl/curl.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "core/clock.h"
#include "core/error.h"

typedef struct sink {
  uint8_t *buf;
  size_t len, max;
  int too_big;
} sink;

static size_t on_data(char *p, size_t size, size_t n, void *arg) {
  sink *s = arg;
  const size_t add = size * n;
  if (s->len + add > s->max) {
    s->too_big = 1;
    return 0; /* aborts the transfer */
  }
  uint8_t *b = realloc(s->buf, s->len + add + 1);
  if (!b) return 0;
  memcpy(b + s->len, p, add);
  s->buf = b;
  s->len += add;
  return add;
}

static int fetch_http(const char *url, int timeout_ms, size_t max_bytes, uint8_t **out,
                      size_t *len) {
  CURL *curl = curl_easy_init();
  if (!curl) return fg_fail(FG_ENOMEM, "libcurl");
  sink s = {.max = max_bytes};
  char err[CURL_ERROR_SIZE] = "";
  curl_easy_setopt(curl, CURLOPT_URL, url);
  curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, (long)timeout_ms);
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, (long)timeout_ms);
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, on_data);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &s);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, err);
  const CURLcode rc = curl_easy_perform(curl);
  long status = 0;
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
  curl_easy_cleanup(curl);
  int ret = 0;
  if (s.too_big)
    ret = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s sent more than %zu bytes", url,
                     max_bytes);
  else if (rc == CURLE_OPERATION_TIMEDOUT)
    ret = fg_fail_as(FG_ETIMEDOUT, "camera_timeout", "%s did not answer within %d ms", url,
                     timeout_ms);
  else if (rc != CURLE_OK)
    ret = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s: %s", url,
                     err[0] ? err : curl_easy_strerror(rc));
  else if (status != 200)
    ret = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s answered HTTP %ld", url, status);
  if (ret < 0) {
    free(s.buf);
    return ret;
  }
  *out = s.buf;
  *len = s.len;
  return 0;
}

extern char **environ;

/* Appends what fd has to *b (at most max bytes; more sets *too_big); 0 at its end. */
static int drain(int fd, sink *b) {
  char chunk[65536];
  const ssize_t n = read(fd, chunk, sizeof chunk);
  if (n < 0) return errno == EINTR || errno == EAGAIN ? 1 : 0;
  if (n == 0) return 0;
  if (!b->too_big && on_data(chunk, 1, (size_t)n, b) != (size_t)n) b->too_big = 1;
  return 1;
}

/* The last line of a child's stderr, for a message. */
static const char *last_line(sink *err) {
  if (!err->buf) return "it said nothing";
  err->buf[err->len] = 0;
  while (err->len && (err->buf[err->len - 1] == '\n' || err->buf[err->len - 1] == '\r'))
    err->buf[--err->len] = 0;
  const char *nl = strrchr((char *)err->buf, '\n');
  return nl ? nl + 1 : (const char *)err->buf;
}

/* A frame of device from the grabber program within timeout_ms: its stdout. */
static int fetch_grab(const char *grabber, const char *device, int timeout_ms, size_t max_bytes,
                      uint8_t **out, size_t *len) {
  int po[2] = {-1, -1}, pe[2] = {-1, -1};
  if (pipe2(po, O_CLOEXEC) != 0 || pipe2(pe, O_CLOEXEC) != 0) {
    const int e = errno;
    for (int i = 0; i < 2; i++) {
      if (po[i] >= 0) close(po[i]);
      if (pe[i] >= 0) close(pe[i]);
    }
    return fg_fail(FG_EIO, "pipe: %s", strerror(e));
  }
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, po[1], 1);
  posix_spawn_file_actions_adddup2(&fa, pe[1], 2);
  char *const argv[] = {(char *)grabber, (char *)device, NULL};
  pid_t pid;
  const int sp = posix_spawn(&pid, grabber, &fa, NULL, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  close(po[1]);
  close(pe[1]);
  if (sp != 0) {
    close(po[0]);
    close(pe[0]);
    return fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "cannot run %s for %s: %s", grabber,
                      device, strerror(sp));
  }
  sink img = {.max = max_bytes}, err = {.max = 4096};
  const double deadline = fg_mono_s() + timeout_ms / 1000.0;
  int open_o = 1, open_e = 1, timed_out = 0;
  while ((open_o || open_e) && !img.too_big) {
    struct pollfd fds[2] = {{.fd = open_o ? po[0] : -1, .events = POLLIN},
                            {.fd = open_e ? pe[0] : -1, .events = POLLIN}};
    const double left = deadline - fg_mono_s();
    if (left <= 0) {
      timed_out = 1;
      break;
    }
    const int n = poll(fds, 2, (int)(left * 1000) + 1);
    if (n < 0 && errno != EINTR) break;
    if (n <= 0) continue;
    if (open_o && fds[0].revents) open_o = drain(po[0], &img);
    if (open_e && fds[1].revents) open_e = drain(pe[0], &err);
  }
  /* stopped early (timeout, too big, a failed poll): the child must not outlive the wait */
  if (timed_out || img.too_big || open_o || open_e) kill(pid, SIGKILL);
  close(po[0]);
  close(pe[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  int rc = 0;
  if (timed_out)
    rc = fg_fail_as(FG_ETIMEDOUT, "camera_timeout", "v4l2:%s gave no frame within %d ms",
                    device, timeout_ms);
  else if (img.too_big)
    rc = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "v4l2:%s: a frame of more than %zu "
                    "bytes", device, max_bytes);
  else if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    rc = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "v4l2:%s: %s", device, last_line(&err));
  else if (img.len == 0)
    rc = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "v4l2:%s: the grabber wrote no frame",
                    device);
  free(err.buf);
  if (rc < 0) {
    free(img.buf);
    return rc;
  }
  *out = img.buf;
  *len = img.len;
  return 0;
}

int fg_snapshot_fetch(const char *grabber, const char *source, int timeout_ms, size_t max_bytes,
                      uint8_t **out, size_t *len) {
  *out = NULL;
  *len = 0;
  if (strncmp(source, FG_SOURCE_V4L2, strlen(FG_SOURCE_V4L2)) == 0)
    return fetch_grab(grabber, source + strlen(FG_SOURCE_V4L2), timeout_ms, max_bytes, out, len);
  return fetch_http(source, timeout_ms, max_bytes, out, len);
}
