/* The robot's audit log (audit.h): durable appends, rotation, the pairing of a command's
 * request and end, and reading back across the rotated files. */
#include "audit.h"
#include "state/json.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define LOG_NAME "robot.log"
/* Read at open to find the last entry number: far more than one line (a line is below
 * 4 KiB: its longest strings are an error message and an Idempotency-Key). */
#define TAIL_BYTES 65536
/* Reserved past the end of robot.log by fg_audit_ready: room for the motion's line. */
#define RESERVE_BYTES 16384
/* Requests and ends waiting for their pair. Commands run one at a time, so two are in use
 * at most in practice; the rest is slack for a burst of refusals racing an end. */
#define N_PENDING 16
/* A rotated file read back whole: far above any audit_max_mb a deployment would set. */
#define READ_MAX ((size_t)1 << 30)

typedef enum { P_FREE = 0, P_CONTEXT, P_END, P_CLOSED } pending_kind;

/* A command between its two lines: P_CONTEXT holds the request's context until the end
 * comes, P_END an end that came first, P_CLOSED marks a command whose end is already
 * written (in its request's line). */
typedef struct pending {
  pending_kind kind;
  uint64_t id;
  uint64_t order; /* for eviction: the oldest goes first */
  json_t *obj;    /* owned: the context or the end */
} pending;

struct fg_audit {
  pthread_mutex_t lock;
  char *dir;
  size_t max_bytes;
  int keep;
  int fd;         /* robot.log, O_APPEND; -1 while unavailable */
  size_t size;    /* of robot.log */
  int torn;       /* the file may end inside a line: the next line starts with '\n' */
  uint64_t next_seq;
  uint64_t written, write_errors;
  pending pending[N_PENDING];
  uint64_t order;
};

/* ---------------------------------------------------------------- files */

/* The path of robot.log (i = 0) or robot.log.i into buf. */
static const char *file_path(const fg_audit *a, int i, char *buf, size_t size) {
  if (i == 0) snprintf(buf, size, "%s/" LOG_NAME, a->dir);
  else snprintf(buf, size, "%s/" LOG_NAME ".%d", a->dir, i);
  return buf;
}

/* The entry number of one line, 0 when it is not an entry (a line torn by a crash). */
static uint64_t line_seq(const char *line, size_t len) {
  json_t *o = json_loadb(line, len, 0, NULL);
  json_t *s = json_object_get(o, "seq");
  const uint64_t seq = json_is_integer(s) && json_integer_value(s) > 0
                           ? (uint64_t)json_integer_value(s) : 0;
  json_decref(o);
  return seq;
}

/* The largest entry number in the last TAIL_BYTES of path; 0 when none (or no file). */
static uint64_t tail_max_seq(const char *path) {
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  struct stat st;
  uint64_t max = 0;
  char *buf = malloc(TAIL_BYTES);
  if (buf && fstat(fd, &st) == 0) {
    const off_t from = st.st_size > TAIL_BYTES ? st.st_size - TAIL_BYTES : 0;
    const ssize_t n = pread(fd, buf, TAIL_BYTES, from);
    /* the first line of a window that starts mid-file is cut: begin after its newline */
    ssize_t i = 0;
    if (from > 0)
      while (i < n && buf[i] != '\n') i++;
    while (i < n) {
      ssize_t j = i;
      while (j < n && buf[j] != '\n') j++;
      const uint64_t s = j > i ? line_seq(buf + i, (size_t)(j - i)) : 0;
      if (s > max) max = s;
      i = j + 1;
    }
  }
  free(buf);
  close(fd);
  return max;
}

/* Deletes robot.log.N for N > keep: files of a larger audit_keep before, which the
 * rotation would otherwise never reach, leaving the disk use unbounded. */
static void remove_extra(const fg_audit *a) {
  DIR *d = opendir(a->dir);
  if (!d) return;
  struct dirent *e;
  char path[PATH_MAX];
  while ((e = readdir(d))) {
    if (strncmp(e->d_name, LOG_NAME ".", sizeof LOG_NAME) != 0) continue;
    const char *num = e->d_name + sizeof LOG_NAME;
    char *end;
    const long i = strtol(num, &end, 10);
    if (*num < '1' || *num > '9' || *end || i <= a->keep) continue;
    snprintf(path, sizeof path, "%s/%s", a->dir, e->d_name);
    if (unlink(path) == 0) fg_info("audit: removed %s (beyond [robot] audit_keep)", path);
  }
  closedir(d);
}

/* Counts and logs a failed write or opening; returns rc. */
static int write_failed(fg_audit *a, int rc, const char *what) {
  a->write_errors++;
  fg_warn("audit: %s failed: %s; motions are refused (503 audit_unavailable) until the log "
          "in %s can be written again", what, fg_error_detail(), a->dir);
  return rc;
}

/* Opens robot.log for appending. 0 or FG_EIO/FG_ENOSPC with a detail. */
static int open_current(fg_audit *a) {
  char path[PATH_MAX];
  file_path(a, 0, path, sizeof path);
  int rc = fg_mkdir_p(a->dir);
  if (rc < 0) return rc;
  /* O_RDWR only to read the last byte back: writes all go through O_APPEND */
  int fd = open(path, O_RDWR | O_APPEND | O_CREAT | O_CLOEXEC, 0640);
  if (fd < 0) return fg_fail(fg_io_error(errno), "cannot open %s: %s", path, strerror(errno));
  struct stat st;
  if (fstat(fd, &st) != 0) {
    rc = fg_fail(FG_EIO, "cannot stat %s: %s", path, strerror(errno));
    close(fd);
    return rc;
  }
  char last = '\n';
  if (st.st_size > 0 && pread(fd, &last, 1, st.st_size - 1) != 1) last = 0;
  a->fd = fd;
  a->size = (size_t)st.st_size;
  a->torn = last != '\n';
  return 0;
}

static void close_current(fg_audit *a) {
  if (a->fd >= 0) close(a->fd);
  a->fd = -1;
}

/* Shifts robot.log.(keep-1) .. robot.log to robot.log.keep .. robot.log.1 and opens a new
 * robot.log. Oldest first, so that a crash part way leaves a gap at worst, never two files
 * with the same name's worth of entries. 0 or FG_EIO with a detail. */
static int rotate(fg_audit *a) {
  char from[PATH_MAX], to[PATH_MAX];
  close_current(a);
  if (unlink(file_path(a, a->keep, to, sizeof to)) != 0 && errno != ENOENT)
    return fg_fail(FG_EIO, "cannot remove %s: %s", to, strerror(errno));
  for (int i = a->keep - 1; i >= 0; i--) {
    file_path(a, i, from, sizeof from);
    file_path(a, i + 1, to, sizeof to);
    if (rename(from, to) != 0 && errno != ENOENT)
      return fg_fail(FG_EIO, "cannot rename %s to %s: %s", from, to, strerror(errno));
  }
  int rc = fg_fsync_dir(a->dir);
  return rc < 0 ? rc : open_current(a);
}

/* ---------------------------------------------------------------- lifecycle */

int fg_audit_open(fg_audit **out, const fg_audit_config *cfg) {
  *out = NULL;
  if (!cfg || !cfg->dir || cfg->max_bytes < 1 || cfg->keep < 1)
    return fg_fail(FG_EINVAL, "audit log: a folder, max_bytes >= 1 and keep >= 1 are needed");
  fg_audit *a = calloc(1, sizeof *a);
  if (!a || !(a->dir = strdup(cfg->dir))) {
    free(a);
    return fg_fail(FG_ENOMEM, "out of memory opening the audit log");
  }
  pthread_mutex_init(&a->lock, NULL);
  a->max_bytes = cfg->max_bytes;
  a->keep = cfg->keep;
  a->fd = -1;
  /* Entry numbers go on from the largest in any file: each is scanned, since a crash in a
   * rotation can leave robot.log missing or empty. */
  char path[PATH_MAX];
  uint64_t max = 0;
  for (int i = 0; i <= a->keep; i++) {
    const uint64_t s = tail_max_seq(file_path(a, i, path, sizeof path));
    if (s > max) max = s;
  }
  a->next_seq = max + 1;
  if (open_current(a) < 0) write_failed(a, FG_EIO, "opening the audit log");
  else remove_extra(a);
  *out = a;
  return 0;
}

/* ---------------------------------------------------------------- writing */

/* Writes entry as the next line. Called with the lock held. */
static int append_locked(fg_audit *a, json_t *entry) {
  char when[32];
  fg_iso8601(fg_real_ms(), when);
  json_t *o = json_pack("{s:I, s:s}", "seq", (json_int_t)a->next_seq, "time", when);
  if (o && json_object_update_missing(o, entry) != 0) {
    json_decref(o);
    o = NULL;
  }
  char *text = o ? json_dumps(o, JSON_COMPACT) : NULL;
  json_decref(o);
  if (!text) return write_failed(a, fg_fail(FG_ENOMEM, "out of memory"), "an audit line");
  a->next_seq++;
  /* one buffer, one write: "\n" first when the file may end inside a torn line */
  const size_t tlen = strlen(text);
  char *line = malloc(tlen + 2);
  if (!line) {
    free(text);
    return write_failed(a, fg_fail(FG_ENOMEM, "out of memory"), "an audit line");
  }
  size_t len = 0;
  if (a->torn) line[len++] = '\n';
  memcpy(line + len, text, tlen);
  len += tlen;
  line[len++] = '\n';
  free(text);

  int rc = 0;
  if (a->fd < 0) rc = open_current(a);
  if (rc == 0 && a->size > 0 && a->size + len > a->max_bytes) {
    rc = rotate(a);
    if (rc == 0 && a->torn == 0 && line[0] == '\n') { /* a new file needs no separator */
      memmove(line, line + 1, --len);
    }
  }
  size_t done = 0;
  while (rc == 0 && done < len) {
    const ssize_t n = write(a->fd, line + done, len - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      a->torn = 1;
      rc = fg_fail(fg_io_error(n < 0 ? errno : ENOSPC), "cannot append to %s/" LOG_NAME ": %s",
                   a->dir, strerror(n < 0 ? errno : ENOSPC));
      break;
    }
    done += (size_t)n;
    a->size += (size_t)n;
  }
  if (rc == 0 && fdatasync(a->fd) != 0)
    rc = fg_fail(fg_io_error(errno), "cannot sync %s/" LOG_NAME ": %s", a->dir,
                 strerror(errno));
  free(line);
  if (rc < 0) {
    close_current(a); /* opened again by the next fg_audit_ready or line */
    return write_failed(a, rc, "writing an audit line");
  }
  a->torn = 0;
  a->written++;
  return 0;
}

int fg_audit_append(fg_audit *a, json_t *entry) {
  pthread_mutex_lock(&a->lock);
  int rc = append_locked(a, entry);
  pthread_mutex_unlock(&a->lock);
  return rc;
}

int fg_audit_ready(fg_audit *a) {
  pthread_mutex_lock(&a->lock);
  int rc = a->fd >= 0 ? 0 : open_current(a);
  if (rc < 0) {
    write_failed(a, rc, "opening the audit log");
  } else {
    /* Blocks for the next line now, so that a full disk refuses the motion instead of
     * failing its line after the robot moved. File systems without fallocate (or without
     * KEEP_SIZE) go on without the reservation. */
    int e = fallocate(a->fd, FALLOC_FL_KEEP_SIZE, (off_t)a->size, RESERVE_BYTES) == 0 ? 0 : errno;
    if (e == ENOSPC || e == EDQUOT || e == EIO) {
      rc = write_failed(a, fg_fail(fg_io_error(e), "cannot reserve room in %s/" LOG_NAME
                                   ": %s", a->dir, strerror(e)), "reserving an audit line");
    }
  }
  pthread_mutex_unlock(&a->lock);
  return rc;
}

/* ---------------------------------------------------------------- pairs */

static pending *pending_find(fg_audit *a, uint64_t id) {
  for (int i = 0; i < N_PENDING; i++)
    if (a->pending[i].kind != P_FREE && a->pending[i].id == id) return &a->pending[i];
  return NULL;
}

static void pending_clear(pending *p) {
  json_decref(p->obj);
  memset(p, 0, sizeof *p);
}

/* Takes a free slot for id, the oldest one made free when all are in use (an end it held is
 * written alone rather than lost). */
static void pending_new(fg_audit *a, pending_kind kind, uint64_t id, json_t *obj) {
  pending *p = NULL;
  for (int i = 0; i < N_PENDING && !p; i++)
    if (a->pending[i].kind == P_FREE) p = &a->pending[i];
  if (!p) {
    p = &a->pending[0];
    for (int i = 1; i < N_PENDING; i++)
      if (a->pending[i].order < p->order) p = &a->pending[i];
    if (p->kind == P_END) append_locked(a, p->obj);
    pending_clear(p);
  }
  p->kind = kind;
  p->id = id;
  p->order = ++a->order;
  p->obj = obj ? json_deep_copy(obj) : NULL;
}

int fg_audit_append_begun(fg_audit *a, uint64_t id, json_t *entry, int ends_later,
                          json_t *context) {
  pthread_mutex_lock(&a->lock);
  int rc = append_locked(a, entry);
  pending *p = pending_find(a, id);
  if (p && p->kind == P_END) {
    /* the end came first: written now after its request, unless the answer had it */
    if (ends_later) {
      json_object_update_missing(p->obj, context);
      const int rc2 = append_locked(a, p->obj);
      if (rc == 0) rc = rc2;
    }
    pending_clear(p);
  } else {
    if (p) pending_clear(p);
    pending_new(a, ends_later ? P_CONTEXT : P_CLOSED, id, context);
  }
  pthread_mutex_unlock(&a->lock);
  return rc;
}

int fg_audit_append_end(fg_audit *a, uint64_t id, json_t *entry) {
  pthread_mutex_lock(&a->lock);
  int rc = 0;
  pending *p = pending_find(a, id);
  if (p && p->kind == P_CONTEXT) {
    json_t *line = json_deep_copy(entry);
    if (line) json_object_update_missing(line, p->obj);
    rc = append_locked(a, line ? line : entry);
    json_decref(line);
    pending_clear(p);
  } else if (p && p->kind == P_CLOSED) {
    pending_clear(p);
  } else if (!p) {
    pending_new(a, P_END, id, entry);
  }
  pthread_mutex_unlock(&a->lock);
  return rc;
}

void fg_audit_free(fg_audit *a) {
  if (!a) return;
  for (int i = 0; i < N_PENDING; i++) {
    if (a->pending[i].kind == P_END) append_locked(a, a->pending[i].obj);
    pending_clear(&a->pending[i]);
  }
  close_current(a);
  pthread_mutex_destroy(&a->lock);
  free(a->dir);
  free(a);
}

/* ---------------------------------------------------------------- reading */

/* The entry number of the first whole line of path; 0 when unknown. */
static uint64_t head_seq(const char *path) {
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  char buf[8192];
  const ssize_t n = read(fd, buf, sizeof buf);
  close(fd);
  ssize_t j = 0;
  while (j < n && buf[j] != '\n') j++;
  return j < n ? line_seq(buf, (size_t)j) : 0;
}

/* Adds the entries of text (a whole file) below before, newest first, to arr until it
 * holds limit; sets *more and returns 1 once an entry beyond the limit is seen. */
static int collect(const char *text, size_t len, uint64_t before, int limit, json_t *arr,
                   int *more) {
  size_t end = len;
  while (end > 0) {
    size_t start = end;
    while (start > 0 && text[start - 1] != '\n') start--;
    if (end > start) {
      json_t *o = json_loadb(text + start, end - start, 0, NULL);
      json_t *s = json_object_get(o, "seq");
      if (json_is_integer(s) && json_integer_value(s) > 0 &&
          (before == 0 || (uint64_t)json_integer_value(s) < before)) {
        if ((int)json_array_size(arr) >= limit) {
          json_decref(o);
          *more = 1;
          return 1;
        }
        json_array_append_new(arr, o);
      } else {
        json_decref(o);
      }
    }
    end = start > 0 ? start - 1 : 0;
  }
  return 0;
}

int fg_audit_read(fg_audit *a, uint64_t before, int limit, json_t **out, int *more) {
  *out = NULL;
  *more = 0;
  json_t *arr = json_array();
  if (!arr) return fg_fail(FG_ENOMEM, "out of memory reading the audit log");
  int rc = 0;
  char path[PATH_MAX];
  /* Under the lock: a rotation between two files would show entries twice or not at all. */
  pthread_mutex_lock(&a->lock);
  for (int i = 0; i <= a->keep && rc == 0; i++) {
    file_path(a, i, path, sizeof path);
    const uint64_t head = head_seq(path);
    if (before && head >= before) continue; /* all of this file is at or past before */
    if (access(path, F_OK) != 0) continue; /* not rotated yet, or a gap left by a crash */
    char *text = NULL;
    size_t len = 0;
    rc = fg_read_file(path, READ_MAX, &text, &len);
    if (rc < 0) break;
    const int full = collect(text, len, before, limit, arr, more);
    free(text);
    if (full) break;
  }
  pthread_mutex_unlock(&a->lock);
  if (rc < 0) {
    json_decref(arr);
    return rc;
  }
  *out = arr;
  return 0;
}

size_t fg_audit_metrics(fg_audit *a, char *buf, size_t size) {
  if (!a || size == 0) return 0;
  pthread_mutex_lock(&a->lock);
  const uint64_t errors = a->write_errors, written = a->written;
  pthread_mutex_unlock(&a->lock);
  const int n = snprintf(
      buf, size,
      "# HELP fieldgrip_audit_write_errors_total Audit log lines (or openings of the log) that "
      "failed; motions are refused while the log cannot be written.\n"
      "# TYPE fieldgrip_audit_write_errors_total counter\n"
      "fieldgrip_audit_write_errors_total %" PRIu64 "\n"
      "# HELP fieldgrip_audit_entries_total Audit log lines written.\n"
      "# TYPE fieldgrip_audit_entries_total counter\n"
      "fieldgrip_audit_entries_total %" PRIu64 "\n",
      errors, written);
  if (n < 0) return 0;
  return (size_t)n < size ? (size_t)n : size - 1;
}
