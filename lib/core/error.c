#include "core/error.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static _Thread_local char detail[1024];
static _Thread_local const char *reason;

const char *fg_strerror(int err) {
  switch (err) {
  case FG_OK: return "success";
  case FG_EINVAL: return "invalid argument";
  case FG_ENOMEM: return "out of memory";
  case FG_EIO: return "input/output error";
  case FG_ENOENT: return "not found";
  case FG_EEXIST: return "already exists";
  case FG_EFORMAT: return "unsupported or corrupt format";
  case FG_ERANGE: return "value out of range";
  case FG_EBUSY: return "busy";
  case FG_ECANCELED: return "cancelled";
  case FG_EPERM: return "not permitted";
  case FG_ETIMEDOUT: return "timed out";
  case FG_EUNAVAIL: return "peer unavailable";
  case FG_EPEER: return "peer reported an error";
  case FG_ENOSPC: return "no space left on the device";
  case FG_ELIMIT: return "refused by a safety limit";
  case FG_ESTOPPED: return "stopped until reset";
  default: return "unknown error";
  }
}

/* Formats into a copy first: the arguments may include the detail itself. */
__attribute__((format(printf, 2, 0)))
static void record(const char *why, const char *fmt, va_list ap) {
  char msg[sizeof detail];
  vsnprintf(msg, sizeof msg, fmt, ap);
  memcpy(detail, msg, sizeof detail);
  reason = why;
}

int fg_fail(int err, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  record(NULL, fmt, ap);
  va_end(ap);
  return err;
}

int fg_fail_as(int err, const char *why, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  record(why, fmt, ap);
  va_end(ap);
  return err;
}

const char *fg_error_detail(void) { return detail; }

const char *fg_error_reason(void) { return reason; }

void fg_error_clear(void) {
  detail[0] = '\0';
  reason = NULL;
}
