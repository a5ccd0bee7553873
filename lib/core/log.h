/* Levelled logging to stderr.
 *
 * Under systemd (JOURNAL_STREAM set) each line starts with the kernel-style "<N>" priority
 * prefix that journald understands; otherwise with a UTC timestamp and the level's name.
 * Thread-safe: one line is one write(2). */
#ifndef FG_CORE_LOG_H
#define FG_CORE_LOG_H

enum fg_log_level {
  FG_LOG_ERROR = 3,
  FG_LOG_WARN = 4,
  FG_LOG_INFO = 6,
  FG_LOG_DEBUG = 7,
};

/* Lines above this level are dropped; default FG_LOG_INFO. */
void fg_log_set_level(enum fg_log_level level);
enum fg_log_level fg_log_get_level(void);

/* Parses "error", "warn", "info" or "debug"; returns 0 or FG_EINVAL. */
int fg_log_level_parse(const char *name, enum fg_log_level *out);

void fg_log(enum fg_log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

#define fg_error(...) fg_log(FG_LOG_ERROR, __VA_ARGS__)
#define fg_warn(...) fg_log(FG_LOG_WARN, __VA_ARGS__)
#define fg_info(...) fg_log(FG_LOG_INFO, __VA_ARGS__)
#define fg_debug(...) fg_log(FG_LOG_DEBUG, __VA_ARGS__)

#endif
