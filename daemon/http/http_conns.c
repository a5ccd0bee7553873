#include "http_conns.h"

#include "core/error.h"

#include <pthread.h>
#include <stdlib.h>
#include <sys/socket.h>

typedef enum { CONN_WAITING, CONN_RECEIVING, CONN_BUSY } conn_state;

struct fg_conn {
  int fd;
  conn_state state;
  int first;              /* WAITING for the connection's first request */
  int shut;               /* shut down by the table, close not yet reported */
  double since_s;         /* when the current state began */
  size_t received;        /* body bytes of the current request */
  fg_conn *prev, *next;
};

/* The list runs from the oldest entry to the newest; an entry that becomes WAITING again
 * moves to the tail, so WAITING entries are in the order of since_s and the first one met
 * from the head is the one to shed. */
struct fg_conns {
  pthread_mutex_t lock;
  fg_conn *head, *tail;
  size_t count;    /* entries in the list */
  size_t n_shut;   /* of which shut down, close pending */
  size_t max_open;
};

static void list_remove(fg_conns *t, fg_conn *c) {
  if (c->prev) c->prev->next = c->next;
  else t->head = c->next;
  if (c->next) c->next->prev = c->prev;
  else t->tail = c->prev;
  c->prev = c->next = NULL;
}

static void list_append(fg_conns *t, fg_conn *c) {
  c->prev = t->tail;
  c->next = NULL;
  if (t->tail) t->tail->next = c;
  else t->head = c;
  t->tail = c;
}

/* Shuts c down, once; the lock is held. */
static void shut_down(fg_conns *t, fg_conn *c) {
  if (c->shut) return;
  c->shut = 1;
  t->n_shut++;
  shutdown(c->fd, SHUT_RDWR);
}

int fg_conns_new(fg_conns **out, size_t max_open) {
  *out = NULL;
  fg_conns *t = calloc(1, sizeof *t);
  if (!t) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_init(&t->lock, NULL);
  t->max_open = max_open ? max_open : 1;
  *out = t;
  return 0;
}

void fg_conns_free(fg_conns *t) {
  if (!t) return;
  for (fg_conn *c = t->head, *next; c; c = next) {
    next = c->next;
    free(c);
  }
  pthread_mutex_destroy(&t->lock);
  free(t);
}

fg_conn *fg_conns_open(fg_conns *t, int fd, double now_s, int *shed) {
  if (shed) *shed = 0;
  fg_conn *c = calloc(1, sizeof *c);
  if (!c) return NULL;
  c->fd = fd;
  c->state = CONN_WAITING;
  c->first = 1;
  c->since_s = now_s;
  pthread_mutex_lock(&t->lock);
  list_append(t, c);
  t->count++;
  if (t->count - t->n_shut > t->max_open) {
    for (fg_conn *o = t->head; o && o != c; o = o->next)
      if (o->state == CONN_WAITING && !o->shut) {
        shut_down(t, o);
        if (shed) *shed = 1;
        break;
      }
  }
  pthread_mutex_unlock(&t->lock);
  return c;
}

void fg_conns_close(fg_conns *t, fg_conn *c) {
  if (!c) return;
  pthread_mutex_lock(&t->lock);
  list_remove(t, c);
  t->count--;
  if (c->shut) t->n_shut--;
  pthread_mutex_unlock(&t->lock);
  free(c);
}

void fg_conns_request_begin(fg_conns *t, fg_conn *c, double now_s) {
  if (!c) return;
  pthread_mutex_lock(&t->lock);
  c->state = CONN_RECEIVING;
  c->first = 0;
  c->since_s = now_s;
  c->received = 0;
  pthread_mutex_unlock(&t->lock);
}

void fg_conns_body(fg_conns *t, fg_conn *c, size_t bytes) {
  if (!c) return;
  pthread_mutex_lock(&t->lock);
  c->received += bytes;
  pthread_mutex_unlock(&t->lock);
}

void fg_conns_request_ready(fg_conns *t, fg_conn *c) {
  if (!c) return;
  pthread_mutex_lock(&t->lock);
  c->state = CONN_BUSY;
  pthread_mutex_unlock(&t->lock);
}

void fg_conns_request_end(fg_conns *t, fg_conn *c, double now_s) {
  if (!c) return;
  pthread_mutex_lock(&t->lock);
  c->state = CONN_WAITING;
  c->since_s = now_s;
  list_remove(t, c);
  list_append(t, c);
  pthread_mutex_unlock(&t->lock);
}

/* Why c is past its deadline at now_s, or -1 while it is not. */
static int overdue(const fg_conn *c, const fg_conns_limits *lim, double now_s) {
  double age_s = now_s - c->since_s;
  switch (c->state) {
  case CONN_WAITING:
    if (c->first) return age_s > lim->header_timeout_s ? FG_CONN_HEADER_TIMEOUT : -1;
    return age_s > lim->idle_timeout_s ? FG_CONN_IDLE_TIMEOUT : -1;
  case CONN_RECEIVING: {
    /* An average over the whole body so far: a client may pause, but must catch up. */
    double owed = lim->min_body_bytes_per_s * (age_s - lim->header_timeout_s);
    return lim->min_body_bytes_per_s > 0 && owed > (double)c->received ? FG_CONN_BODY_TOO_SLOW
                                                                        : -1;
  }
  case CONN_BUSY: break;
  }
  return -1;
}

size_t fg_conns_sweep(fg_conns *t, const fg_conns_limits *lim, double now_s,
                      size_t closed[FG_CONN_REASONS]) {
  size_t n = 0;
  pthread_mutex_lock(&t->lock);
  for (fg_conn *c = t->head; c; c = c->next) {
    if (c->shut) continue;
    int why = overdue(c, lim, now_s);
    if (why < 0) continue;
    shut_down(t, c);
    closed[why]++;
    n++;
  }
  pthread_mutex_unlock(&t->lock);
  return n;
}

size_t fg_conns_count(fg_conns *t) {
  pthread_mutex_lock(&t->lock);
  size_t n = t->count;
  pthread_mutex_unlock(&t->lock);
  return n;
}
