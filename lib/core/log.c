#include "core/log.h"
#include "core/error.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static atomic_int log_level = FG_LOG_INFO;

void fg_log_set_level(enum fg_log_level level) { atomic_store(&log_level, (int)level); }

enum fg_log_level fg_log_get_level(void) { return (enum fg_log_level)atomic_load(&log_level); }

int fg_log_level_parse(const char *name, enum fg_log_level *out) {
  static const struct { const char *name; enum fg_log_level level; } names[] = {
    {"error", FG_LOG_ERROR}, {"warn", FG_LOG_WARN}, {"info", FG_LOG_INFO}, {"debug", FG_LOG_DEBUG},
  };
  for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
    if (strcmp(name, names[i].name) == 0) {
      *out = names[i].level;
      return 0;
    }
  }
  return fg_fail(FG_EINVAL, "unknown log level '%s' (use error, warn, info or debug)", name);
}

static const char *level_name(int level) {
  switch (level) {
  case FG_LOG_ERROR: return "error";
  case FG_LOG_WARN: return "warn";
  case FG_LOG_INFO: return "info";
  default: return "debug";
  }
}

void fg_log(enum fg_log_level level, const char *fmt, ...) {
  if ((int)level > atomic_load(&log_level)) return;
  static int journal = -1;
  if (journal < 0) journal = getenv("JOURNAL_STREAM") != NULL;

  char line[2048];
  int n;
  if (journal) {
    n = snprintf(line, sizeof line, "<%d>", (int)level);
  } else {
    struct timespec ts;
    struct tm tm;
    clock_gettime(CLOCK_REALTIME, &ts);
    gmtime_r(&ts.tv_sec, &tm);
    n = snprintf(line, sizeof line, "%04d-%02d-%02dT%02d:%02d:%02d.%03ldZ %-5s ", tm.tm_year + 1900,
                 tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, ts.tv_nsec / 1000000,
                 level_name(level));
  }
  va_list ap;
  va_start(ap, fmt);
  int m = vsnprintf(line + n, sizeof line - (size_t)n - 1, fmt, ap);
  va_end(ap);
  size_t len = (size_t)n + (m < 0 ? 0 : (size_t)m);
  if (len > sizeof line - 2) len = sizeof line - 2;
  line[len++] = '\n';
  ssize_t w = write(STDERR_FILENO, line, len);
  (void)w;
}
