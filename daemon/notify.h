/* The one place that talks to systemd's notification socket. Without libsystemd at build
 * time every function compiles to nothing, so the daemon runs the same outside systemd. */
#ifndef FG_DAEMON_NOTIFY_H
#define FG_DAEMON_NOTIFY_H

#include <stdint.h>

/* READY=1 plus a STATUS line. */
void fg_notify_ready(const char *status);
/* STATUS=... (free text shown by systemctl status). */
void fg_notify_status(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* RELOADING=1 / READY=1 around a SIGHUP reload. */
void fg_notify_reloading(void);
/* STOPPING=1 at the start of a clean shutdown. */
void fg_notify_stopping(void);
/* WATCHDOG=1. */
void fg_notify_watchdog(void);
/* The watchdog interval systemd asked for (WatchdogSec=), in microseconds; 0 if none. */
uint64_t fg_notify_watchdog_usec(void);

#endif
