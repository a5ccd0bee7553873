/* Error codes and per-thread error detail for libfieldgrip.
 *
 * Every library function that can fail returns int: 0 on success, a negative FG_E* code
 * otherwise. Where the cause is worth telling a user (bad input, a corrupt file), the function
 * also records a sentence in a thread-local buffer with fg_fail(); fg_error_detail() returns it
 * until the next fg_fail() on the same thread. */
#ifndef FG_CORE_ERROR_H
#define FG_CORE_ERROR_H

#include <stddef.h>

enum {
  FG_OK = 0,
  FG_EINVAL = -1,    /* malformed or out-of-range input */
  FG_ENOMEM = -2,    /* allocation failed */
  FG_EIO = -3,       /* read, write, fsync or rename failed */
  FG_ENOENT = -4,    /* no such file, scene or frame */
  FG_EEXIST = -5,    /* already exists */
  FG_EFORMAT = -6,   /* unsupported or corrupt file content */
  FG_ERANGE = -7,    /* a value or size beyond a documented limit */
  FG_EBUSY = -8,     /* the resource is in use */
  FG_ECANCELED = -9, /* stopped on request */
  FG_EPERM = -10,    /* not allowed (path outside an allowed folder) */
  FG_ETIMEDOUT = -11, /* a peer did not answer, or did not finish, in time */
  FG_EUNAVAIL = -12, /* a peer is not connected (refused, reset, unreachable) */
  FG_EPEER = -13,    /* a peer answered with an error (Modbus exception, gripper fault) */
  FG_ENOSPC = -14,   /* a write failed for want of space: the disk or the quota is full */
  FG_ELIMIT = -15,   /* refused by a configured safety limit (a motion outside its bounds) */
  FG_ESTOPPED = -16, /* refused while a stop (or an unconfirmed outcome) holds the machine
                      * until an operator resets it */
};

/* Returns a static, human-readable name of a FG_E* code; never NULL. */
const char *fg_strerror(int err);

/* Records a formatted detail message for the calling thread and returns err, so that error
 * paths stay one line: `return fg_fail(FG_EINVAL, "w must be positive, got %d", w);` */
int fg_fail(int err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* fg_fail with a reason: a short, stable name of what went wrong for a client to act on
 * ("task_not_found"), a string literal. The daemon answers with it as the error's code. */
int fg_fail_as(int err, const char *reason, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* The calling thread's last detail message; "" when none. Valid until the next fg_fail()
 * or fg_error_clear() on this thread. The detail may be an argument of the next fg_fail:
 * `fg_fail(rc, "demo %d: %s", id, fg_error_detail())` wraps it. */
const char *fg_error_detail(void);
/* The reason of the calling thread's last fg_fail_as; NULL after a plain fg_fail. */
const char *fg_error_reason(void);
void fg_error_clear(void);

/* Propagates a failing call's code; the callee has already recorded the detail. */
#define FG_TRY(expr)                                                                     \
  do {                                                                                   \
    int fg_try_rc_ = (expr);                                                             \
    if (fg_try_rc_ < 0) return fg_try_rc_;                                               \
  } while (0)

#endif
