#include "modbus/peer.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "core/clock.h"
#include "core/error.h"

typedef struct job {
  fg_mb_job_fn fn;
  void *arg;
  void (*done)(void *arg, int rc);
} job;

struct fg_mb_peer {
  fg_mb_link *link;
  pthread_t thread;
  pthread_mutex_t lock;
  pthread_cond_t cond;
  job queue[FG_MB_PEER_QUEUE];
  int head, count, stop;
  int idle_ms;
  fg_mb_job_fn idle;
  void *idle_arg;
};

static void *worker(void *arg) {
  fg_mb_peer *p = arg;
  /* connect at once, so that the peer's state is known right after the start */
  if (fg_mb_link_ensure(p->link) == 0 && p->idle) p->idle(p->link, p->idle_arg);
  pthread_mutex_lock(&p->lock);
  for (;;) {
    if (p->stop) break;
    if (p->count == 0) {
      struct timespec until;
      fg_deadline_after_ms(&until, CLOCK_MONOTONIC, p->idle_ms);
      int rc = 0;
      while (!p->stop && p->count == 0 && rc != ETIMEDOUT)
        rc = pthread_cond_timedwait(&p->cond, &p->lock, &until);
      if (p->stop) break;
      if (p->count == 0) {
        pthread_mutex_unlock(&p->lock);
        if (fg_mb_link_ensure(p->link) == 0 && p->idle) p->idle(p->link, p->idle_arg);
        pthread_mutex_lock(&p->lock);
        continue;
      }
    }
    job j = p->queue[p->head];
    p->head = (p->head + 1) % FG_MB_PEER_QUEUE;
    p->count--;
    pthread_mutex_unlock(&p->lock);
    fg_error_clear();
    const int rc = j.fn(p->link, j.arg);
    if (j.done) j.done(j.arg, rc);
    pthread_mutex_lock(&p->lock);
  }
  while (p->count > 0) {
    job j = p->queue[p->head];
    p->head = (p->head + 1) % FG_MB_PEER_QUEUE;
    p->count--;
    pthread_mutex_unlock(&p->lock);
    fg_fail(FG_ECANCELED, "the Modbus peer is shutting down");
    if (j.done) j.done(j.arg, FG_ECANCELED);
    pthread_mutex_lock(&p->lock);
  }
  pthread_mutex_unlock(&p->lock);
  return NULL;
}

int fg_mb_peer_new(fg_mb_peer **out, const fg_mb_link_config *cfg, int idle_ms,
                   fg_mb_job_fn idle, void *idle_arg) {
  *out = NULL;
  fg_mb_peer *p = calloc(1, sizeof *p);
  if (!p) return FG_ENOMEM;
  int rc = fg_mb_link_new(&p->link, cfg);
  if (rc < 0) {
    free(p);
    return rc;
  }
  p->idle_ms = idle_ms > 0 ? idle_ms : 1000;
  p->idle = idle;
  p->idle_arg = idle_arg;
  pthread_condattr_t ca;
  pthread_condattr_init(&ca);
  pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
  pthread_cond_init(&p->cond, &ca);
  pthread_condattr_destroy(&ca);
  pthread_mutex_init(&p->lock, NULL);
  if (pthread_create(&p->thread, NULL, worker, p) != 0) {
    pthread_cond_destroy(&p->cond);
    pthread_mutex_destroy(&p->lock);
    fg_mb_link_free(p->link);
    free(p);
    return fg_fail(FG_ENOMEM, "cannot start the Modbus worker thread");
  }
  *out = p;
  return 0;
}

void fg_mb_peer_free(fg_mb_peer *p) {
  if (!p) return;
  pthread_mutex_lock(&p->lock);
  p->stop = 1;
  pthread_cond_broadcast(&p->cond);
  pthread_mutex_unlock(&p->lock);
  pthread_join(p->thread, NULL);
  pthread_cond_destroy(&p->cond);
  pthread_mutex_destroy(&p->lock);
  fg_mb_link_free(p->link);
  free(p);
}

int fg_mb_peer_post(fg_mb_peer *p, fg_mb_job_fn fn, void *arg, void (*done)(void *arg, int rc)) {
  pthread_mutex_lock(&p->lock);
  if (p->stop) {
    pthread_mutex_unlock(&p->lock);
    return fg_fail(FG_ECANCELED, "the Modbus peer at %s is shutting down",
                   fg_mb_link_address(p->link));
  }
  if (p->count == FG_MB_PEER_QUEUE) {
    pthread_mutex_unlock(&p->lock);
    return fg_fail(FG_EBUSY, "the Modbus peer at %s has %d requests waiting; try again",
                   fg_mb_link_address(p->link), FG_MB_PEER_QUEUE);
  }
  p->queue[(p->head + p->count) % FG_MB_PEER_QUEUE] = (job){fn, arg, done};
  p->count++;
  pthread_cond_broadcast(&p->cond);
  pthread_mutex_unlock(&p->lock);
  return 0;
}

/* A synchronous call: the caller waits on its own slot. */
typedef struct call {
  fg_mb_job_fn fn;
  void *arg;
  pthread_mutex_t lock;
  pthread_cond_t cond;
  int finished, rc;
  char detail[1024];
  const char *reason; /* fg_fail_as's, a string literal; NULL when none */
} call;

static int call_run(fg_mb_link *l, void *arg) {
  call *c = arg;
  return c->fn(l, c->arg);
}

static void call_done(void *arg, int rc) {
  call *c = arg;
  pthread_mutex_lock(&c->lock);
  c->rc = rc;
  snprintf(c->detail, sizeof c->detail, "%s", rc < 0 ? fg_error_detail() : "");
  c->reason = rc < 0 ? fg_error_reason() : NULL;
  c->finished = 1;
  pthread_cond_signal(&c->cond);
  pthread_mutex_unlock(&c->lock);
}

int fg_mb_peer_call(fg_mb_peer *p, fg_mb_job_fn fn, void *arg) {
  call c = {.fn = fn, .arg = arg};
  pthread_mutex_init(&c.lock, NULL);
  pthread_cond_init(&c.cond, NULL);
  int rc = fg_mb_peer_post(p, call_run, &c, call_done);
  if (rc == 0) {
    pthread_mutex_lock(&c.lock);
    while (!c.finished) pthread_cond_wait(&c.cond, &c.lock);
    pthread_mutex_unlock(&c.lock);
    rc = c.rc;
    if (rc < 0 && c.reason)
      fg_fail_as(rc, c.reason, "%s", c.detail);
    else if (rc < 0)
      fg_fail(rc, "%s", c.detail);
  }
  pthread_cond_destroy(&c.cond);
  pthread_mutex_destroy(&c.lock);
  return rc;
}

void fg_mb_peer_state(fg_mb_peer *p, fg_mb_link_state *st) { fg_mb_link_state_get(p->link, st); }

const char *fg_mb_peer_address(const fg_mb_peer *p) { return fg_mb_link_address(p->link); }
