#include "notify.h"

#include "config.h"

#include <stdarg.h>
#include <stdio.h>

#if HAVE_LIBSYSTEMD
#include <systemd/sd-daemon.h>

void fg_notify_ready(const char *status) { sd_notifyf(0, "READY=1\nSTATUS=%s", status); }

void fg_notify_status(const char *fmt, ...) {
  char buf[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  sd_notifyf(0, "STATUS=%s", buf);
}

void fg_notify_reloading(void) { sd_notify(0, "RELOADING=1"); }
void fg_notify_stopping(void) { sd_notify(0, "STOPPING=1"); }
void fg_notify_watchdog(void) { sd_notify(0, "WATCHDOG=1"); }

uint64_t fg_notify_watchdog_usec(void) {
  uint64_t usec = 0;
  return sd_watchdog_enabled(0, &usec) > 0 ? usec : 0;
}

#else

void fg_notify_ready(const char *status) { (void)status; }
void fg_notify_status(const char *fmt, ...) { (void)fmt; }
void fg_notify_reloading(void) {}
void fg_notify_stopping(void) {}
void fg_notify_watchdog(void) {}
uint64_t fg_notify_watchdog_usec(void) { return 0; }

#endif
