/* The image decoder pool: children running fieldgrip-decode, started on demand, ended when
 * idle, discarded when they die on an image. The wire format they speak (decoder.h) is
 * packed and checked in decoder_wire.c.
 *
 * Locking: one mutex guards the child list and the spawn queue; no I/O and no waiting on a
 * child happens under it. A child is used by one thread at a time (checked out as busy). */
#include "decoder.h"

#include "config.h"
#include "core/error.h"
#include "core/clock.h"
#include "core/log.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

/* ---- the pool --------------------------------------------------------------------------- */

typedef struct child {
  pid_t pid;
  int to_fd;        /* the child's stdin */
  int from_fd;      /* the child's stdout */
  int busy;         /* checked out by a decode */
  double busy_since; /* CLOCK_MONOTONIC seconds when checked out */
  int overran;      /* killed by the reaper for taking longer than the busy limit */
  double last_used; /* CLOCK_MONOTONIC seconds when last checked in */
  struct child *next;
} child;

/* A request to the spawner thread for one new child. */
typedef struct spawn_ticket {
  child *result; /* the new child, or NULL with rc and message */
  int rc;
  int done;
  char message[512];
  struct spawn_ticket *next;
} spawn_ticket;

struct fg_decoder {
  char *program;      /* as given, or NULL for the default places */
  char *beside_exe;   /* <dir of /proc/self/exe>/fieldgrip-decode, or NULL */
  int max_procs, idle_seconds, busy_seconds;
  pthread_mutex_t lock;
  pthread_cond_t changed;   /* a child came back or went, a slot freed, a ticket done */
  pthread_cond_t spawn_cv;  /* work for the spawner */
  child *children;          /* every live child, idle or busy */
  int n_procs;              /* live children plus those being started */
  spawn_ticket *tickets;    /* queue for the spawner */
  int stopping;
  pthread_t spawner;
  uint64_t started, died_idle, requests[FG_DECODER_RESULTS]; /* under lock */
};

#define DEFAULT_INSTALLED FG_LIBEXECDIR "/fieldgrip/fieldgrip-decode"

/* The program to start: the one given, else the first default place that exists. */
static int resolve_program(const fg_decoder *d, const char **out) {
  if (d->program) {
    if (access(d->program, X_OK) != 0)
      return fg_fail(FG_ENOENT, "the image decoder program %s is missing or not executable (%s)",
                     d->program, strerror(errno));
    *out = d->program;
    return 0;
  }
  if (d->beside_exe && access(d->beside_exe, X_OK) == 0) {
    *out = d->beside_exe;
    return 0;
  }
  if (access(DEFAULT_INSTALLED, X_OK) == 0) {
    *out = DEFAULT_INSTALLED;
    return 0;
  }
  return fg_fail(FG_ENOENT, "the image decoder program fieldgrip-decode is missing: looked for "
                 "%s and %s; build it with the daemon or reinstall fieldgrip",
                 d->beside_exe ? d->beside_exe : "(no path of the running program)",
                 DEFAULT_INSTALLED);
}

static void close_pipe(int fds[2]) {
  for (int i = 0; i < 2; i++)
    if (fds[i] >= 0) {
      close(fds[i]);
      fds[i] = -1;
    }
}

/* A pipe whose both ends are close-on-exec and above stderr, so that the child's dup2 onto
 * 0 and 1 cannot clobber one end with the other even when the daemon runs without stdio. */
static int pipe_above_stdio(int fds[2]) {
  if (pipe2(fds, O_CLOEXEC) != 0) {
    fds[0] = fds[1] = -1;
    return -1;
  }
  for (int i = 0; i < 2; i++) {
    if (fds[i] > 2) continue;
    int nfd = fcntl(fds[i], F_DUPFD_CLOEXEC, 3);
    close(fds[i]);
    fds[i] = nfd;
  }
  if (fds[0] < 0 || fds[1] < 0) {
    int e = errno;
    close_pipe(fds);
    errno = e;
    return -1;
  }
  /* A decoded 800x800 frame is 7.7 MB; a 1 MiB pipe (the unprivileged maximum) moves it in
   * 8 turns instead of 118 at the default 64 KiB. Best effort. */
  (void)fcntl(fds[0], F_SETPIPE_SZ, 1 << 20);
  return 0;
}

/* Starts one child; runs on the spawner thread (see spawner_main). */
static int spawn_child(fg_decoder *d, child **out) {
  const char *program = NULL;
  FG_TRY(resolve_program(d, &program));
  int in[2] = {-1, -1}, outp[2] = {-1, -1};
  if (pipe_above_stdio(in) != 0 || pipe_above_stdio(outp) != 0) {
    int e = errno;
    close_pipe(in);
    close_pipe(outp);
    return fg_fail(FG_EIO, "cannot create pipes for the image decoder: %s", strerror(e));
  }
  posix_spawn_file_actions_t fa;
  posix_spawnattr_t attr;
  posix_spawn_file_actions_init(&fa);
  posix_spawnattr_init(&attr);
  posix_spawn_file_actions_adddup2(&fa, in[0], 0);
  posix_spawn_file_actions_adddup2(&fa, outp[1], 1);
  posix_spawn_file_actions_addclosefrom_np(&fa, 3);
  /* The daemon blocks its stop signals in every thread and ignores SIGPIPE; the child gets
   * the defaults, so that it dies when the daemon stops reading its reply. */
  sigset_t none, deflt;
  sigemptyset(&none);
  sigemptyset(&deflt);
  sigaddset(&deflt, SIGPIPE);
  sigaddset(&deflt, SIGTERM);
  sigaddset(&deflt, SIGINT);
  sigaddset(&deflt, SIGHUP);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &deflt);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  char *argv[] = {(char *)program, NULL};
  pid_t pid;
  int err = posix_spawn(&pid, program, &fa, &attr, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&attr);
  close(in[0]);
  close(outp[1]);
  if (err != 0) {
    close(in[1]);
    close(outp[0]);
    return fg_fail(err == ENOENT || err == EACCES ? FG_ENOENT : FG_EIO,
                   "cannot start the image decoder %s: %s", program, strerror(err));
  }
  child *c = calloc(1, sizeof *c);
  if (!c) {
    close(in[1]);
    close(outp[0]);
    kill(pid, SIGKILL);
    while (waitpid(pid, NULL, 0) < 0 && errno == EINTR) {
    }
    return fg_fail(FG_ENOMEM, "out of memory starting the image decoder");
  }
  c->pid = pid;
  c->to_fd = in[1];
  c->from_fd = outp[0];
  c->busy = 1;
  /* Busy from now: the reaper may look at it before the waiting checkout takes it, and a
   * busy_since of 0 read as 60 s overrun killed children that had just started. */
  c->busy_since = fg_mono_s();
  c->last_used = c->busy_since;
  fg_debug("image decoder %s started as pid %d", program, (int)pid);
  *out = c;
  return 0;
}

/* Children are started from this one long-lived thread because the child asks the kernel
 * (PR_SET_PDEATHSIG) for SIGKILL when its parent *thread* exits: a child forked by an HTTP
 * worker or an OpenMP thread would die with that thread while another one uses it. */
static void *spawner_main(void *arg) {
  fg_decoder *d = arg;
  pthread_mutex_lock(&d->lock);
  for (;;) {
    while (!d->tickets && !d->stopping) pthread_cond_wait(&d->spawn_cv, &d->lock);
    if (d->stopping) break;
    spawn_ticket *t = d->tickets;
    d->tickets = t->next;
    pthread_mutex_unlock(&d->lock);
    child *c = NULL;
    int rc = spawn_child(d, &c);
    pthread_mutex_lock(&d->lock);
    t->result = c;
    t->rc = rc;
    if (rc != 0) snprintf(t->message, sizeof t->message, "%s", fg_error_detail());
    if (c) {
      c->next = d->children;
      d->children = c;
      d->started++;
    }
    t->done = 1;
    pthread_cond_broadcast(&d->changed);
  }
  pthread_mutex_unlock(&d->lock);
  return NULL;
}

/* Describes how a child ended, for messages. */
static void describe_status(int status, char *buf, size_t len) {
  if (WIFSIGNALED(status))
    snprintf(buf, len, "killed by signal %d", WTERMSIG(status));
  else if (WIFEXITED(status))
    snprintf(buf, len, "exited with status %d", WEXITSTATUS(status));
  else
    snprintf(buf, len, "status %#x", (unsigned)status);
}

/* Ends children that are no longer in the list: closes their pipes (an idle child exits at
 * once on EOF, one stuck writing a reply nobody reads on SIGPIPE), waits up to grace_ms for
 * all of them, SIGKILLs the rest and reaps every one. The last child's wait status goes to
 * *status when status is not NULL. Frees the nodes. */
static void end_children(child *list, int grace_ms, int *status) {
  for (child *c = list; c; c = c->next) {
    close(c->to_fd);
    close(c->from_fd);
  }
  int left = 0;
  for (child *c = list; c; c = c->next) left++;
  for (int waited = 0; left > 0; waited++) {
    int flags = waited <= grace_ms ? WNOHANG : 0;
    for (child *c = list; c; c = c->next) {
      if (c->pid <= 0) continue;
      int st;
      pid_t r = waitpid(c->pid, &st, flags);
      if (r == 0 || (r < 0 && errno == EINTR)) continue;
      if (r == c->pid && status) *status = st;
      fg_debug("image decoder pid %d ended", (int)c->pid);
      c->pid = 0; /* reaped (or not ours: ECHILD) */
      left--;
    }
    if (left == 0) break;
    if (waited == grace_ms) {
      for (child *c = list; c; c = c->next)
        if (c->pid > 0) kill(c->pid, SIGKILL);
    } else if (waited < grace_ms) {
      struct timespec ms = {0, 1000000};
      nanosleep(&ms, NULL);
    }
  }
  while (list) {
    child *next = list->next;
    free(list);
    list = next;
  }
}

/* Removes c from the list; the caller holds the lock. */
static void unlink_child(fg_decoder *d, child *c) {
  for (child **p = &d->children; *p; p = &(*p)->next)
    if (*p == c) {
      *p = c->next;
      c->next = NULL;
      return;
    }
}

int fg_decoder_new(fg_decoder **out, const char *program, int max_procs, int idle_seconds) {
  if (!out) return fg_fail(FG_EINVAL, "fg_decoder_new: no output");
  *out = NULL;
  if (max_procs < 1 || idle_seconds < 1)
    return fg_fail(FG_EINVAL, "fg_decoder_new: max_procs (%d) and idle_seconds (%d) must be "
                   "at least 1", max_procs, idle_seconds);
  fg_decoder *d = calloc(1, sizeof *d);
  if (!d) return fg_fail(FG_ENOMEM, "out of memory");
  d->max_procs = max_procs;
  d->idle_seconds = idle_seconds;
  d->busy_seconds = FG_DECODER_BUSY_SECONDS;
  if (program && !(d->program = strdup(program))) goto nomem;
  if (!program) {
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n > 0) {
      exe[n] = '\0';
      char *slash = strrchr(exe, '/');
      if (slash) {
        slash[1] = '\0';
        size_t need = strlen(exe) + sizeof "fieldgrip-decode";
        if (!(d->beside_exe = malloc(need))) goto nomem;
        snprintf(d->beside_exe, need, "%sfieldgrip-decode", exe);
      }
    }
  }
  pthread_mutex_init(&d->lock, NULL);
  pthread_cond_init(&d->changed, NULL);
  pthread_cond_init(&d->spawn_cv, NULL);
  int err = pthread_create(&d->spawner, NULL, spawner_main, d);
  if (err != 0) {
    pthread_cond_destroy(&d->spawn_cv);
    pthread_cond_destroy(&d->changed);
    pthread_mutex_destroy(&d->lock);
    free(d->program);
    free(d->beside_exe);
    free(d);
    return fg_fail(FG_EIO, "cannot start the decoder's spawner thread: %s", strerror(err));
  }
  *out = d;
  return 0;
nomem:
  free(d->program);
  free(d->beside_exe);
  free(d);
  return fg_fail(FG_ENOMEM, "out of memory");
}

void fg_decoder_free(fg_decoder *d) {
  if (!d) return;
  pthread_mutex_lock(&d->lock);
  child *all = d->children;
  d->children = NULL;
  d->n_procs = 0;
  pthread_mutex_unlock(&d->lock);
  /* Children first: they die with the spawner thread (PR_SET_PDEATHSIG), and ending them
   * through EOF lets them exit normally. */
  end_children(all, 1000, NULL);
  pthread_mutex_lock(&d->lock);
  d->stopping = 1;
  pthread_cond_signal(&d->spawn_cv);
  pthread_mutex_unlock(&d->lock);
  pthread_join(d->spawner, NULL);
  pthread_cond_destroy(&d->spawn_cv);
  pthread_cond_destroy(&d->changed);
  pthread_mutex_destroy(&d->lock);
  free(d->program);
  free(d->beside_exe);
  free(d);
}

int fg_decoder_check(fg_decoder *d) {
  if (!d) return fg_fail(FG_EINVAL, "fg_decoder_check: no decoder");
  const char *program = NULL;
  return resolve_program(d, &program);
}

/* Takes the most recently used idle child (so that the others age out and get reaped), or
 * has a new one started, or waits for one to come back. */
static int checkout(fg_decoder *d, child **out) {
  pthread_mutex_lock(&d->lock);
  for (;;) {
    child *best = NULL;
    for (child *c = d->children; c; c = c->next)
      if (!c->busy && (!best || c->last_used > best->last_used)) best = c;
    if (best) {
      best->busy = 1;
      best->busy_since = fg_mono_s();
      pthread_mutex_unlock(&d->lock);
      *out = best;
      return 0;
    }
    if (d->n_procs < d->max_procs) break;
    pthread_cond_wait(&d->changed, &d->lock);
  }
  d->n_procs++;
  spawn_ticket t = {0};
  spawn_ticket **tail = &d->tickets;
  while (*tail) tail = &(*tail)->next;
  *tail = &t;
  pthread_cond_signal(&d->spawn_cv);
  while (!t.done) pthread_cond_wait(&d->changed, &d->lock);
  if (t.rc != 0) {
    d->n_procs--;
    pthread_cond_broadcast(&d->changed);
    pthread_mutex_unlock(&d->lock);
    return fg_fail(t.rc, "%s", t.message);
  }
  t.result->busy_since = fg_mono_s();
  pthread_mutex_unlock(&d->lock);
  *out = t.result;
  return 0;
}

static void checkin(fg_decoder *d, child *c) {
  pthread_mutex_lock(&d->lock);
  c->busy = 0;
  c->last_used = fg_mono_s();
  pthread_cond_broadcast(&d->changed);
  pthread_mutex_unlock(&d->lock);
}

/* Takes a broken child out of the pool and ends it; *status receives its wait status. */
static void discard(fg_decoder *d, child *c, int *status) {
  pthread_mutex_lock(&d->lock);
  unlink_child(d, c);
  d->n_procs--;
  pthread_cond_broadcast(&d->changed);
  pthread_mutex_unlock(&d->lock);
  /* A crashing child may still be writing a sanitizer report; give it two seconds. */
  end_children(c, 2000, status);
}

/* Writes to a child with SIGPIPE blocked on this thread, so that a child that died makes the
 * write fail with EPIPE instead of killing a caller that does not ignore SIGPIPE (the daemon
 * does; tests and tools may not). A SIGPIPE this raised is consumed before unblocking. */
static int write_nosigpipe(int fd, const void *buf, size_t n) {
  sigset_t pipe_set, old, pending;
  sigemptyset(&pipe_set);
  sigaddset(&pipe_set, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &pipe_set, &old);
  sigpending(&pending);
  int was_pending = sigismember(&pending, SIGPIPE);
  int rc = fg_decoder_write_full(fd, buf, n);
  int e = errno;
  if (rc != 0 && e == EPIPE && !was_pending) {
    struct timespec zero = {0, 0};
    while (sigtimedwait(&pipe_set, NULL, &zero) < 0 && errno == EINTR) {
    }
  }
  pthread_sigmask(SIG_SETMASK, &old, NULL);
  errno = e;
  return rc;
}

/* What went wrong in one exchange. */
enum { EXCHANGE_OK = 0, EXCHANGE_DEAD_BEFORE, EXCHANGE_BROKEN, EXCHANGE_VERSION };

/* One request to a child: the header, a payload in up to two pieces, and where the reply's
 * data goes (image for a decode, bytes for an encode, depth for a depth decode). */
typedef struct job_io {
  fg_decoder_request req;
  const void *p1, *p2;
  size_t n1, n2;
  fg_image *image;  /* op 1 */
  uint8_t **bytes;  /* op 2 */
  size_t *bytes_len;
  fg_depth_map *depth; /* op 3 */
} job_io;

/* One request and its reply. Returns EXCHANGE_OK with *rc the child's result (the child
 * is healthy), EXCHANGE_DEAD_BEFORE when the child was gone before it saw anything of this
 * request, EXCHANGE_VERSION when it is a fieldgrip-decode of another protocol version, or
 * EXCHANGE_BROKEN when it died or misbehaved on this request (*why says how). */
static int exchange(child *c, job_io *io, int *rc, char *why, size_t why_len) {
  uint8_t hdr[FG_DECODER_REQUEST_SIZE];
  io->req.version = FG_DECODER_VERSION;
  io->req.length = io->n1 + io->n2;
  fg_decoder_request_pack(&io->req, hdr);
  /* The header fits in an empty pipe, so it fails only when nobody reads: the child died
   * while idle (killed, OOM) and this request is not to blame. */
  if (write_nosigpipe(c->to_fd, hdr, sizeof hdr) != 0) {
    snprintf(why, why_len, "writing to it failed: %s", strerror(errno));
    return errno == EPIPE ? EXCHANGE_DEAD_BEFORE : EXCHANGE_BROKEN;
  }
  if ((io->n1 && write_nosigpipe(c->to_fd, io->p1, io->n1) != 0) ||
      (io->n2 && write_nosigpipe(c->to_fd, io->p2, io->n2) != 0)) {
    snprintf(why, why_len, "writing to it failed: %s", strerror(errno));
    return EXCHANGE_BROKEN;
  }
  uint8_t rhdr[FG_DECODER_REPLY_SIZE];
  ssize_t got = fg_decoder_read_full(c->from_fd, rhdr, sizeof rhdr);
  if (got != (ssize_t)sizeof rhdr) {
    snprintf(why, why_len, "%s", got < 0 ? strerror(errno) : "no reply");
    return EXCHANGE_BROKEN;
  }
  fg_decoder_reply rep;
  int encode = io->req.op == FG_DECODER_OP_ENCODE_PNG;
  int depth = io->req.op == FG_DECODER_OP_DECODE_DEPTH;
  if ((encode  ? fg_decoder_reply_unpack_encode(rhdr, &rep)
       : depth ? fg_decoder_reply_unpack_depth(rhdr, &rep)
               : fg_decoder_reply_unpack(rhdr, &rep)) != 0) {
    snprintf(why, why_len, "%s", fg_error_detail());
    int other = memcmp(rhdr, "FGDR", 4) == 0 && rep.version != FG_DECODER_VERSION;
    return other ? EXCHANGE_VERSION : EXCHANGE_BROKEN;
  }
  char msg[FG_DECODER_MAX_MESSAGE + 1];
  if (fg_decoder_read_full(c->from_fd, msg, rep.message_len) != (ssize_t)rep.message_len) {
    snprintf(why, why_len, "the reply's message was cut short");
    return EXCHANGE_BROKEN;
  }
  msg[rep.message_len] = '\0';
  if (rep.rc != 0) {
    *rc = fg_fail(rep.rc, "%s", msg);
    return EXCHANGE_OK;
  }
  size_t n = (size_t)rep.pixel_bytes;
  void *data = malloc(n);
  if (!data) {
    /* The data is still in the pipe; this child cannot be reused. */
    *rc = fg_fail(FG_ENOMEM, "out of memory receiving a %dx%d image", (int)rep.w, (int)rep.h);
    snprintf(why, why_len, "out of memory");
    return EXCHANGE_BROKEN;
  }
  if (fg_decoder_read_full(c->from_fd, data, n) != (ssize_t)n) {
    free(data);
    snprintf(why, why_len, "the %s were cut short", encode ? "PNG bytes" : "pixels");
    return EXCHANGE_BROKEN;
  }
  if (encode) {
    *io->bytes = data;
    *io->bytes_len = n;
  } else if (depth) {
    fg_decoder_floats_le(data, n / sizeof(float));
    io->depth->w = rep.w;
    io->depth->h = rep.h;
    io->depth->m = data;
  } else {
    fg_decoder_floats_le(data, n / sizeof(float));
    io->image->w = rep.w;
    io->image->h = rep.h;
    io->image->rgb = data;
  }
  *rc = 0;
  return EXCHANGE_OK;
}

/* Counts one request's end and passes its return code on. */
static int count_result(fg_decoder *d, fg_decoder_result result, int rc) {
  pthread_mutex_lock(&d->lock);
  d->requests[result]++;
  pthread_mutex_unlock(&d->lock);
  return rc;
}

static int run_job_counted(fg_decoder *d, job_io *io, size_t len, const char *what,
                           fg_decoder_result *result);

/* Runs one request on a child of the pool, replacing children found dead; what names the
 * work in messages ("image", "image to encode", "depth image"). */
static int run_job(fg_decoder *d, job_io *io, size_t len, const char *what) {
  fg_decoder_result result = FG_DECODER_ERROR;
  int rc = run_job_counted(d, io, len, what, &result);
  return count_result(d, result, rc);
}

/* run_job's work; *result says how it ended. */
static int run_job_counted(fg_decoder *d, job_io *io, size_t len, const char *what,
                           fg_decoder_result *result) {
  /* A child found dead before it saw the request is replaced; twice is plenty (each try
   * after the first runs on a child started for it). */
  for (int attempt = 0; attempt < 3; attempt++) {
    child *c = NULL;
    FG_TRY(checkout(d, &c));
    int rc = 0;
    char why[256] = "";
    int how = exchange(c, io, &rc, why, sizeof why);
    if (how == EXCHANGE_OK) {
      checkin(d, c);
      *result = rc == 0 ? FG_DECODER_OK : FG_DECODER_REFUSED;
      /* The child's memory is capped (FG_DECODER_MAX_ADDRESS_BYTES): running out there is
       * the image's doing (too large, or a decompression bomb), not the daemon's. */
      if (rc == FG_ENOMEM) {
        char detail[512];
        snprintf(detail, sizeof detail, "%s", fg_error_detail());
        return fg_fail(FG_ERANGE, "the image decoder ran out of memory on this %s (it may use "
                       "%llu GiB): %s", what, FG_DECODER_MAX_ADDRESS_BYTES >> 30, detail);
      }
      return rc;
    }
    pid_t pid = c->pid;
    pthread_mutex_lock(&d->lock);
    int overran = c->overran;
    pthread_mutex_unlock(&d->lock);
    int status = 0;
    discard(d, c, &status);
    *result = overran ? FG_DECODER_TIMEOUT : FG_DECODER_CRASHED;
    if (overran)
      return fg_fail(FG_EFORMAT, "the image decoder took longer than %d s on this %s and was "
                     "stopped; the data is corrupt or hostile", d->busy_seconds, what);
    char ended[64];
    describe_status(status, ended, sizeof ended);
    if (how == EXCHANGE_DEAD_BEFORE) {
      fg_warn("image decoder pid %d had died while idle (%s); starting another", (int)pid,
              ended);
      pthread_mutex_lock(&d->lock);
      d->died_idle++;
      pthread_mutex_unlock(&d->lock);
      *result = FG_DECODER_ERROR;
      continue;
    }
    if (WIFSIGNALED(status) && WTERMSIG(status) == SIGXCPU) {
      *result = FG_DECODER_TIMEOUT;
      return fg_fail(FG_EFORMAT, "the image decoder used more than %d s of CPU time on this "
                     "%s and was stopped; the data is corrupt or hostile",
                     FG_DECODER_CPU_SECONDS, what);
    }
    if (rc == FG_ENOMEM || how == EXCHANGE_VERSION) *result = FG_DECODER_ERROR;
    if (rc == FG_ENOMEM) return rc;
    if (how == EXCHANGE_VERSION)
      return fg_fail(FG_EIO, "the image decoder does not speak this daemon's protocol (%s); "
                     "install fieldgrip-decode from the same build as fieldgripd", why);
    fg_warn("image decoder pid %d stopped on one %s of %zu bytes (%s; %s)", (int)pid, what, len,
            ended, why);
    if (WIFSIGNALED(status))
      return fg_fail(FG_EFORMAT, "the image decoder stopped on this %s (killed by signal %d); "
                     "the data is corrupt or hostile", what, WTERMSIG(status));
    return fg_fail(FG_EFORMAT, "the image decoder stopped on this %s (%s); the data is "
                   "corrupt or hostile", what, ended);
  }
  return fg_fail(FG_EIO, "the image decoder keeps dying before it reads a request; see the "
                 "daemon's log");
}

int fg_decoder_decode(fg_decoder *d, const void *bytes, size_t len,
                      const float background_rgb[3], fg_image *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_decoder_decode: no output image");
  memset(out, 0, sizeof *out);
  if (!d) return fg_fail(FG_EINVAL, "fg_decoder_decode: no decoder");
  if (!bytes && len) return fg_fail(FG_EINVAL, "fg_decoder_decode: no bytes");
  if (len > FG_DECODER_MAX_REQUEST)
    return fg_fail(FG_ERANGE, "the image is %zu bytes; the decoder takes at most %llu",
                   len, (unsigned long long)FG_DECODER_MAX_REQUEST);
  static const float white[3] = {1, 1, 1};
  const float *bg = background_rgb ? background_rgb : white;
  job_io io = {.req = {.op = FG_DECODER_OP_DECODE}, .p1 = bytes, .n1 = len, .image = out};
  for (int k = 0; k < 3; k++) io.req.background[k] = bg[k];
  return run_job(d, &io, len, "image");
}

int fg_decoder_decode_sent(fg_decoder *d, const void *bytes, size_t len,
                           const float background_rgb[3], fg_image *out) {
  const int rc = fg_decoder_decode(d, bytes, len, background_rgb, out);
  if (rc == 0) return 0;
  if (rc == FG_ENOENT || rc == FG_EIO || rc == FG_ENOMEM)
    return fg_fail_as(rc, "internal_error", "cannot decode the image: %s", fg_error_detail());
  return fg_fail_as(rc, "invalid_image", "%s", fg_error_detail());
}

int fg_decoder_decode_depth(fg_decoder *d, const void *bytes, size_t len, double scale,
                            fg_depth_map *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_decoder_decode_depth: no output depth map");
  memset(out, 0, sizeof *out);
  if (!d) return fg_fail(FG_EINVAL, "fg_decoder_decode_depth: no decoder");
  if (!bytes && len) return fg_fail(FG_EINVAL, "fg_decoder_decode_depth: no bytes");
  if (len > FG_DECODER_MAX_REQUEST - FG_DECODER_DEPTH_HEADER)
    return fg_fail(FG_ERANGE, "the depth image is %zu bytes; the decoder takes at most %llu",
                   len, (unsigned long long)(FG_DECODER_MAX_REQUEST - FG_DECODER_DEPTH_HEADER));
  uint8_t head[FG_DECODER_DEPTH_HEADER];
  fg_decoder_depth_header_pack(scale, head);
  job_io io = {.req = {.op = FG_DECODER_OP_DECODE_DEPTH}, .p1 = head, .n1 = sizeof head,
               .p2 = bytes, .n2 = len, .depth = out};
  return run_job(d, &io, len, "depth image");
}

int fg_decoder_encode_png(fg_decoder *d, const void *pixels, int w, int h, int channels,
                          int bits, uint8_t **out, size_t *out_len) {
  if (!out || !out_len) return fg_fail(FG_EINVAL, "fg_decoder_encode_png: no output");
  *out = NULL;
  *out_len = 0;
  if (!d || !pixels) return fg_fail(FG_EINVAL, "fg_decoder_encode_png: no decoder or pixels");
  uint8_t head[FG_DECODER_ENCODE_HEADER];
  fg_decoder_encode_header_pack(w, h, channels, bits, head);
  uint64_t n = w > 0 && h > 0 && channels > 0 && bits > 0
                 ? (uint64_t)w * (uint64_t)h * (uint64_t)channels * (uint64_t)(bits / 8) : 0;
  int iw, ih, ic, ib;
  FG_TRY(fg_decoder_encode_header_unpack(head, FG_DECODER_ENCODE_HEADER + n, &iw, &ih, &ic,
                                         &ib));
  const void *payload = pixels;
  uint16_t *swapped = NULL;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  if (bits == 16) {
    swapped = malloc((size_t)n);
    if (!swapped) return fg_fail(FG_ENOMEM, "out of memory");
    memcpy(swapped, pixels, (size_t)n);
    fg_decoder_u16_le(swapped, (size_t)n / 2);
    payload = swapped;
  }
#endif
  job_io io = {.req = {.op = FG_DECODER_OP_ENCODE_PNG}, .p1 = head, .n1 = sizeof head,
               .p2 = payload, .n2 = (size_t)n, .bytes = out, .bytes_len = out_len};
  int rc = run_job(d, &io, (size_t)n, "image to encode");
  free(swapped);
  return rc;
}

void fg_decoder_reap_idle(fg_decoder *d) {
  if (!d) return;
  double now = fg_mono_s();
  child *old = NULL;
  pthread_mutex_lock(&d->lock);
  for (child **p = &d->children; *p;) {
    child *c = *p;
    if (c->busy && !c->overran && now - c->busy_since > (double)d->busy_seconds) {
      /* Its decode sees the pipe close and discards it; see fg_decoder_decode. */
      c->overran = 1;
      kill(c->pid, SIGKILL);
      fg_warn("image decoder pid %d took longer than %d s on one image; stopped it", (int)c->pid,
              d->busy_seconds);
    }
    if (!c->busy && now - c->last_used > (double)d->idle_seconds) {
      *p = c->next;
      c->next = old;
      old = c;
      d->n_procs--;
    } else {
      p = &c->next;
    }
  }
  if (old) pthread_cond_broadcast(&d->changed);
  pthread_mutex_unlock(&d->lock);
  if (!old) return;
  end_children(old, 1000, NULL);
  /* Decoding has been idle for a while, so the megabytes of decoded images that passed
   * through this process are free; glibc keeps such chunks in its arenas (its mmap threshold
   * grows past an image's size after the first one is freed), which left an idle daemon at
   * 30-110 MB after an import instead of ~15. Handing them back now is cheap. */
  malloc_trim(0);
}

void fg_decoder_set_busy_limit(fg_decoder *d, int seconds) {
  pthread_mutex_lock(&d->lock);
  d->busy_seconds = seconds >= 1 ? seconds : 1;
  pthread_mutex_unlock(&d->lock);
}

void fg_decoder_get_stats(fg_decoder *d, fg_decoder_stats *out) {
  memset(out, 0, sizeof *out);
  if (!d) return;
  pthread_mutex_lock(&d->lock);
  for (child *c = d->children; c; c = c->next) {
    if (c->busy) out->busy++;
    else out->idle++;
  }
  out->started = d->started;
  out->died_idle = d->died_idle;
  memcpy(out->requests, d->requests, sizeof out->requests);
  pthread_mutex_unlock(&d->lock);
}

size_t fg_decoder_child_pids(fg_decoder *d, pid_t *pids, size_t max) {
  if (!d) return 0;
  size_t n = 0;
  pthread_mutex_lock(&d->lock);
  for (child *c = d->children; c; c = c->next, n++)
    if (n < max) pids[n] = c->pid;
  pthread_mutex_unlock(&d->lock);
  return n;
}
