/* Idempotency keys of actuating requests (the Idempotency-Key header): the first request
 * with a key runs, later ones with the same key get its answer again without running.
 *
 * Keys live 24 hours whatever their number. They are kept in an append-only journal under
 * the state dir, one fsync'd line per event (a key taken, answered, or released), replayed
 * at start, so a daemon that restarts (or is killed) mid-command does not run a retried
 * command a second time: a key whose command was cut short (no answer, or only the 202 of
 * its acknowledgement) answers 504 outcome_unknown after a restart. A half-written last line
 * (a crash during an append) is dropped at start; a malformed line before it is an error.
 * When the journal has grown past twice what its live keys need (plus a floor), it is
 * rewritten atomically with only the live keys. The store is bounded: past max_keys keys or
 * max_bytes of them, a new key is refused (FG_ERANGE) rather than forgetting a key younger
 * than 24 hours, so a retry is never run twice.
 *
 * A key remembers its request by the SHA-256 of its method, path and the canonical JSON of
 * its body (keys sorted, no whitespace; an empty body is {}), so a retry that a client
 * serialised again with other spacing or key order is the same request; a body that is not
 * JSON is taken by its bytes. The journal is version 3. The whole-file stores of earlier
 * daemons (idempotency.json, version 2: SHA-256 of the path and the raw body; version 1:
 * 64-bit FNV-1a) are migrated at the first start; their keys are compared the old way until
 * they age out. */
#ifndef FG_DAEMON_IDEM_H
#define FG_DAEMON_IDEM_H

#include <stddef.h>
#include <stdint.h>

#define FG_IDEM_KEY_MAX 200
#define FG_IDEM_MAX_AGE_S (24 * 3600)
#define FG_IDEM_MAX_KEYS 100000
#define FG_IDEM_MAX_BYTES (64u << 20)

typedef struct fg_idem fg_idem;

typedef struct {
  size_t max_keys;  /* 0: FG_IDEM_MAX_KEYS */
  size_t max_bytes; /* of the live keys and answers; 0: FG_IDEM_MAX_BYTES */
  /* the wall clock in seconds; NULL: time(). Tests age keys with their own. */
  int64_t (*now_s)(void *ctx);
  void *now_ctx;
} fg_idem_config;

/* A request as a key remembers it; every pointer stays the caller's. */
typedef struct {
  const char *method, *path;
  const void *body;
  size_t len;
} fg_idem_request;

typedef enum {
  FG_IDEM_NEW = 0, /* fg_idem_begin: the key is now taken: run, then fg_idem_finish;
                      fg_idem_peek: the key is unknown, and still is */
  FG_IDEM_REPLAY,  /* answered before: *status and *body hold the answer */
  FG_IDEM_RUNNING, /* its request is still running */
  FG_IDEM_CONFLICT /* the key was used for a different request */
} fg_idem_result;

/* Opens (or creates) the store in folder dir: its journal idempotency.journal, migrating an
 * idempotency.json of an earlier daemon. cfg may be NULL (the defaults). 0, FG_EIO/FG_EFORMAT
 * with a detail, FG_ENOMEM. A corrupt journal is an error, not silently dropped. On success
 * the caller owns *out (fg_idem_free). */
int fg_idem_open(fg_idem **out, const char *dir, const fg_idem_config *cfg);
void fg_idem_free(fg_idem *s);

/* Checks that a header value is a usable key: 1..FG_IDEM_KEY_MAX printable ASCII. */
int fg_idem_key_valid(const char *key);

/* Looks key up without taking it: FG_IDEM_NEW when it is unknown, else as fg_idem_begin.
 * Handlers call it before they look at anything else, so that a retry is answered even when
 * what it refers to has gone since (a grasp forgotten by a restart or made stale by a
 * training). On FG_IDEM_REPLAY the caller owns *body (malloc'd). */
int fg_idem_peek(fg_idem *s, const char *key, const fg_idem_request *rq, int *status,
                 char **body);

/* Looks key up and takes it when it is unknown. On FG_IDEM_REPLAY the caller owns *body
 * (malloc'd). Returns the result, or a negative FG_E* when the key could not be stored (the
 * request must not run then): FG_ERANGE when the store is full of keys younger than 24 h,
 * FG_ENOSPC when the disk is, FG_EIO. */
int fg_idem_begin(fg_idem *s, const char *key, const fg_idem_request *rq, int *status,
                  char **body);

/* Stores the answer of a key taken by fg_idem_begin. 0 or FG_EIO/FG_ENOSPC. */
int fg_idem_finish(fg_idem *s, const char *key, int status, const char *body);

/* Replaces the answer of a key (taken or answered) with a later one: a command first
 * answered 202 at its acknowledgement, now ended. 0, FG_ENOENT (the key is gone) or
 * FG_EIO/FG_ENOSPC. */
int fg_idem_update(fg_idem *s, const char *key, int status, const char *body);

/* Releases a key taken by fg_idem_begin whose request did not run (refused before it
 * started), so that a retry with the key runs. 0 or FG_EIO. */
int fg_idem_cancel(fg_idem *s, const char *key);

/* How many keys are live and how many bytes the journal holds (for tests and metrics). */
void fg_idem_stats(fg_idem *s, size_t *keys, size_t *journal_bytes);

#endif
