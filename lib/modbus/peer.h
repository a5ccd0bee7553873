/* A Modbus peer: one link (link.h) owned by one worker thread, and a queue through which
 * other threads have work done on it. Between jobs the worker keeps the link alive: every
 * idle_ms it reconnects when the backoff allows and runs the idle job (a status read), so
 * that the peer's state is current without a request. */
#ifndef FG_MODBUS_PEER_H
#define FG_MODBUS_PEER_H

#include "modbus/link.h"

/* Work on the link, run on the worker thread. Returns 0 or a negative FG_E* code. */
typedef int (*fg_mb_job_fn)(fg_mb_link *l, void *arg);

typedef struct fg_mb_peer fg_mb_peer;

/* Most jobs waiting at once; more are FG_EBUSY. */
#define FG_MB_PEER_QUEUE 32

/* Starts the worker for a link of cfg. idle (may be NULL) runs every idle_ms while the queue
 * is empty, with idle_arg (which the caller keeps alive until fg_mb_peer_free). 0,
 * FG_EINVAL (cfg) or FG_ENOMEM; *out NULL on failure. */
int fg_mb_peer_new(fg_mb_peer **out, const fg_mb_link_config *cfg, int idle_ms,
                   fg_mb_job_fn idle, void *idle_arg);

/* Stops the worker after its current job; jobs still queued complete with FG_ECANCELED.
 * NULL is fine. */
void fg_mb_peer_free(fg_mb_peer *p);

/* Runs fn(link, arg) on the worker and waits for it; returns its result (FG_EBUSY when the
 * queue is full, FG_ECANCELED when the peer stops first). The detail of a failure, and its
 * reason (fg_fail_as), are copied to the calling thread. */
int fg_mb_peer_call(fg_mb_peer *p, fg_mb_job_fn fn, void *arg);

/* Queues fn(link, arg) and returns at once; done(arg, rc) runs on the worker afterwards
 * (rc FG_ECANCELED when the peer stops before fn ran). 0, FG_EBUSY (queue full) or
 * FG_ECANCELED (stopping); done is then not called. */
int fg_mb_peer_post(fg_mb_peer *p, fg_mb_job_fn fn, void *arg, void (*done)(void *arg, int rc));

/* The link's state (link.h); any thread. */
void fg_mb_peer_state(fg_mb_peer *p, fg_mb_link_state *st);

/* "127.0.0.1:502" or the serial device. */
const char *fg_mb_peer_address(const fg_mb_peer *p);

#endif
