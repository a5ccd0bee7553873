/* The robot's audit log: one JSON line for every motion and gripper request, refused or sent,
 * and one more for a command answered before it ended, kept under <state>/audit so that
 * what the daemon told the robot can be reconstructed after a crash.
 *
 * Lifecycle: fg_audit_open at start-up (a folder that cannot be written does not stop the
 * daemon: the log is then unavailable and fg_audit_ready refuses); fg_audit_ready before a
 * request may move anything; fg_audit_append (or the pair fg_audit_append_begun /
 * fg_audit_append_end) once it has an outcome; fg_audit_read for GET /v1/robot/log;
 * fg_audit_free at exit.
 *
 * Files: robot.log, the newest, and robot.log.1 .. robot.log.<keep>, older the higher the
 * number. A line is written with one write() on an O_APPEND descriptor and made durable
 * with fdatasync() before the call returns: motions are rare, and a line lost in a crash is
 * the one that mattered. Before a line would take robot.log past max_bytes, the files are
 * shifted (robot.log.<keep> deleted), so the log holds at most about (keep + 1) * max_bytes.
 *
 * Every line is an object that starts with "seq", an entry number that increases by one per
 * line written and carries on after a restart (the largest number found in the files at
 * open, plus one), and "time" (ISO 8601, UTC, milliseconds). A line torn by a crash is
 * skipped when read back. Thread-safe: one mutex serialises writes, reads and rotation. */
#ifndef FG_DAEMON_AUDIT_H
#define FG_DAEMON_AUDIT_H

#include <stddef.h>
#include <stdint.h>

#include <jansson.h>

typedef struct fg_audit fg_audit;

typedef struct fg_audit_config {
  const char *dir;  /* the log's folder, created when missing (<state>/audit) */
  size_t max_bytes; /* robot.log is rotated before a line would take it past this, >= 1 */
  int keep;         /* rotated files kept, >= 1 (so the entry numbers survive a rotation) */
} fg_audit_config;

/* Opens (or starts) the log in cfg->dir and finds the next entry number. A folder or file
 * that cannot be opened is not an error here: it is logged, counted as a write error, and
 * the log stays unavailable until fg_audit_ready manages to open it. 0 and *out (owned by
 * the caller: fg_audit_free); FG_ENOMEM or FG_EINVAL with a detail, *out NULL. */
int fg_audit_open(fg_audit **out, const fg_audit_config *cfg);

/* Closes and frees; a line still waiting for its pair (fg_audit_append_end) is written
 * first. NULL is fine. */
void fg_audit_free(fg_audit *a);

/* Whether a line can be written now: the file is open (opened again after a failed write)
 * and space for the next line is reserved where the file system allows it. Asked before a
 * request may move the robot, so that a motion is not sent unrecorded. 0, or FG_EIO /
 * FG_ENOSPC with a detail saying why. */
int fg_audit_ready(fg_audit *a);

/* Appends entry (an object; borrowed, left unchanged) as one line, its "seq" and "time"
 * first. 0, or FG_EIO / FG_ENOSPC / FG_ENOMEM with a detail; a failure is also logged as a
 * warning and counted (fieldgrip_audit_write_errors_total). */
int fg_audit_append(fg_audit *a, json_t *entry);

/* The two lines of a command whose end comes after its answer. The request's line and the
 * command's end are written by different threads, in either order, but always land in the
 * file request first, the end carrying the request's context (who asked).
 *
 * fg_audit_append_begun: appends the request's line (entry) for command id. ends_later
 * says the answer did not have the end (202): context (an object: borrowed; its keys are
 * copied into the end's line where the end lacks them) is kept for fg_audit_append_end,
 * and an end already reported is written now after the request. Otherwise the command's
 * end is in entry already, and an end reported for id, now or later, is not written again.
 *
 * fg_audit_append_end: appends the end (entry, borrowed) of command id once its request's
 * line is written; until then it is held (at most a few; the oldest is written alone when
 * more come).
 *
 * Both return what fg_audit_append returns for the line(s) they write. */
int fg_audit_append_begun(fg_audit *a, uint64_t id, json_t *entry, int ends_later,
                          json_t *context);
int fg_audit_append_end(fg_audit *a, uint64_t id, json_t *entry);

/* Up to limit (>= 1) entries, newest first, with a seq below before (0: from the newest),
 * across robot.log and the rotated files, into *out (a new array the caller owns). *more is
 * set to 1 when older entries may remain. 0, or FG_ENOMEM / FG_EIO with a detail. */
int fg_audit_read(fg_audit *a, uint64_t before, int limit, json_t **out, int *more);

/* Appends the Prometheus lines of the log (write errors, entries written) to buf (at most
 * size bytes, NUL-terminated); returns the length written. NULL a: nothing. */
size_t fg_audit_metrics(fg_audit *a, char *buf, size_t size);

#endif
