/* Idempotency keys of actuating requests (the Idempotency-Key header): the first request
 * with a key runs, later ones with the same key get its answer again without running.
 * Keys are kept in one file under the state dir, rewritten atomically when a key is taken
 * and when its answer is known, so a daemon that restarts (or is killed) mid-command does
 * not run a retried command a second time: a key whose command was cut short (no answer, or
 * only the 202 of its acknowledgement) answers 504 outcome_unknown after a restart. The newest
 * FG_IDEM_MAX keys of the last 24 hours are kept.
 *
 * A key remembers its request by the SHA-256 of its path and body, so a retry is told from a
 * different request by its bytes, not by a 64-bit hash that could be made to collide. The
 * file is version 2; a version 1 file (64-bit FNV-1a hashes) still loads, and its keys are
 * compared by that hash until they age out. */
#ifndef FG_DAEMON_IDEM_H
#define FG_DAEMON_IDEM_H

#include <stddef.h>
#include <stdint.h>

#define FG_IDEM_MAX 1000
#define FG_IDEM_KEY_MAX 200

typedef struct fg_idem fg_idem;

typedef enum {
  FG_IDEM_NEW = 0, /* the key is now taken: run the request, then fg_idem_finish */
  FG_IDEM_REPLAY,  /* answered before: *status and *body hold the answer */
  FG_IDEM_RUNNING, /* its request is still running */
  FG_IDEM_CONFLICT /* the key was used for a different request body */
} fg_idem_result;

/* Opens (or creates) the store at path. 0, FG_EIO/FG_EFORMAT with a detail, FG_ENOMEM. A
 * corrupt file is an error, not silently dropped. */
int fg_idem_open(fg_idem **out, const char *path);
void fg_idem_free(fg_idem *s);

/* Checks that a header value is a usable key: 1..FG_IDEM_KEY_MAX printable ASCII. */
int fg_idem_key_valid(const char *key);

/* Looks key up for the request to path with body req_body [req_len] (both kept by the
 * caller). On FG_IDEM_REPLAY the caller owns *body (malloc'd). Returns the result, or a
 * negative FG_E* when the key could not be stored (the request must not run then). */
int fg_idem_begin(fg_idem *s, const char *key, const char *path, const void *req_body,
                  size_t req_len, int *status, char **body);

/* Stores the answer of a key taken by fg_idem_begin. 0 or FG_EIO. */
int fg_idem_finish(fg_idem *s, const char *key, int status, const char *body);

/* Replaces the answer of a key (taken or answered) with a later one: a command first
 * answered 202 at its acknowledgement, now ended. 0, FG_ENOENT (the key is gone) or FG_EIO. */
int fg_idem_update(fg_idem *s, const char *key, int status, const char *body);

/* Releases a key taken by fg_idem_begin whose request did not run (refused before it
 * started), so that a retry with the key runs. 0 or FG_EIO. */
int fg_idem_cancel(fg_idem *s, const char *key);

#endif
