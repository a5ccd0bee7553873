/* The configuration parser's errors, paths and value parsers (conf_parse.h). */
#include "conf_parse.h"
#include "secret.h"

#include "core/error.h"

#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* ---------------------------------------------------------------- errors */

/* Records "FILE:LINE: [section] key: message" unless an error on an earlier line is already
 * recorded, and returns 0 so that handler paths stay one line (inih's "failed" value). */
int conf_fail_at(conf_parse *st, int line, const char *section, const char *key,
                      const char *fmt, ...) {
  if (st->failed && st->err_line <= line) return 0;
  char msg[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  if (section && key)
    snprintf(st->err, sizeof st->err, "%s:%d: [%s] %s: %s", st->path, line, section, key, msg);
  else if (section)
    snprintf(st->err, sizeof st->err, "%s:%d: [%s]: %s", st->path, line, section, msg);
  else if (key)
    snprintf(st->err, sizeof st->err, "%s:%d: %s: %s", st->path, line, key, msg);
  else
    snprintf(st->err, sizeof st->err, "%s:%d: %s", st->path, line, msg);
  st->failed = 1;
  st->err_line = line;
  st->err_code = FG_EINVAL;
  return 0;
}

/* An allocation failure while parsing: not the file's fault, but reported the same way. */
int conf_fail_nomem(conf_parse *st) {
  int earlier = st->failed && st->err_line <= st->line;
  conf_fail_at(st, st->line, NULL, NULL, "out of memory");
  if (!earlier) st->err_code = FG_ENOMEM;
  return 0;
}

/* ---------------------------------------------------------------- paths */

/* Joins base and p (unless p is absolute) and removes ".", ".." and repeated slashes
 * lexically, so that the daemon logs and compares clean absolute paths. ".." is applied to
 * the text, not through symlinks; the base itself comes from realpath(), so this only differs
 * from the kernel's view when the value itself walks back out of a symlink. NULL on
 * allocation failure. */
char *conf_path_absolute(const char *base, const char *p) {
  size_t blen = p[0] == '/' ? 0 : strlen(base);
  size_t plen = strlen(p);
  char *joined = malloc(blen + plen + 2);
  char *out = malloc(blen + plen + 2);
  if (!joined || !out) {
    free(joined);
    free(out);
    return NULL;
  }
  memcpy(joined, base, blen);
  joined[blen] = '/';
  memcpy(joined + blen + 1, p, plen + 1);

  size_t n = 0; /* out holds "/a/b" without a trailing slash ("" means "/") */
  char *save = NULL;
  for (char *c = strtok_r(joined, "/", &save); c; c = strtok_r(NULL, "/", &save)) {
    if (strcmp(c, ".") == 0) continue;
    if (strcmp(c, "..") == 0) {
      while (n > 0 && out[n - 1] != '/') n--;
      if (n > 0) n--; /* drop the slash too; ".." at the root stays at the root */
      continue;
    }
    out[n++] = '/';
    size_t clen = strlen(c);
    memcpy(out + n, c, clen);
    n += clen;
  }
  if (n == 0) out[n++] = '/';
  out[n] = '\0';
  free(joined);
  return out;
}

/* The folder holding the file at path, made absolute through realpath() so that relative
 * values do not depend on the daemon's working directory at reload time. The folder of a
 * symlinked file is the link's folder, which is where the user looks. */
char *conf_folder_of(const char *path) {
  const char *slash = strrchr(path, '/');
  char *dir;
  if (!slash)
    dir = strdup(".");
  else if (slash == path)
    dir = strdup("/");
  else
    dir = strndup(path, (size_t)(slash - path));
  if (!dir) return NULL;
  char *real = realpath(dir, NULL);
  free(dir);
  return real;
}

/* ---------------------------------------------------------------- value parsers */

/* Each returns 1 and stores the value, or records an error naming the current line and key
 * and returns 0. */

int conf_parse_int(conf_parse *st, const char *key, const char *v, long lo, long hi, int *out) {
  char *end;
  errno = 0;
  long x = strtol(v, &end, 10);
  if (end == v || *end != '\0' || errno == ERANGE || x < lo || x > hi)
    return conf_fail_at(st, st->line, st->sec_text, key,
                        "expected an integer from %ld to %ld, got '%s'", 
                        lo, hi, v);
  *out = (int)x;
  return 1;
}

/* Reads one finite number from *s, advancing it; 0 when there is none. */
static int scan_double(const char **s, double *out) {
  char *end;
  errno = 0;
  double x = strtod(*s, &end);
  if (end == *s || errno == ERANGE || !isfinite(x)) return 0;
  *s = end;
  *out = x;
  return 1;
}

int conf_parse_double(conf_parse *st, const char *key, const char *v, double *out) {
  const char *s = v;
  double x;
  if (!scan_double(&s, &x) || *s != '\0')
    return conf_fail_at(st, st->line, st->sec_text, key, "expected a finite number, got '%s'", v);
  *out = x;
  return 1;
}

/* Three numbers separated by whitespace; what they mean ("x y z", "R G B") goes into the
 * message. */
int conf_parse_vec3(conf_parse *st, const char *key, const char *v, const char *what,
                         double out[3]) {
  const char *s = v;
  double x[3];
  for (int i = 0; i < 3; i++) {
    if (!scan_double(&s, &x[i]) || (i < 2 && !isspace((unsigned char)*s)))
      return conf_fail_at(st, st->line, st->sec_text, key,
                          "expected 3 finite numbers separated by spaces (%s), got '%s'", what, v);
  }
  if (*s != '\0')
    return conf_fail_at(st, st->line, st->sec_text, key,
                        "expected exactly 3 numbers separated by spaces (%s), got '%s'", what, v);
  memcpy(out, x, sizeof x);
  return 1;
}

/* Matches v against a NULL-terminated list of names. */
int conf_parse_enum(conf_parse *st, const char *key, const char *v, const char *const *names,
                         int *out) {
  char expected[160] = "";
  for (int i = 0; names[i]; i++) {
    if (strcmp(v, names[i]) == 0) {
      *out = i;
      return 1;
    }
    size_t n = strlen(expected);
    snprintf(expected + n, sizeof expected - n, "%s%s", i == 0 ? "" : (names[i + 1] ? ", " : " or "),
             names[i]);
  }
  return conf_fail_at(st, st->line, st->sec_text, key, "expected %s, got '%s'", expected, v);
}

int conf_set_string(conf_parse *st, char **dst, const char *v) {
  char *copy = strdup(v);
  if (!copy) return conf_fail_nomem(st);
  free(*dst);
  *dst = copy;
  return 1;
}

/* A file or folder value, taken relative to the configuration file's folder. */
int conf_set_path(conf_parse *st, const char *key, char **dst, const char *v) {
  if (v[0] == '\0')
    return conf_fail_at(st, st->line, st->sec_text, key, "expected a path, got nothing");
  char *p = conf_path_absolute(st->base_dir, v);
  if (!p) return conf_fail_nomem(st);
  free(*dst);
  *dst = p;
  return 1;
}

static void free_dirs(char **dirs, size_t n) {
  for (size_t i = 0; i < n; i++) free(dirs[i]);
  free(dirs);
}

/* token_file: a path, relative to the file's folder like the others, or one that starts with
 * ${CREDENTIALS_DIRECTORY}, the folder where systemd puts what LoadCredential= gives the
 * service (systemd/fieldgripd.service). Empty: none, as for token. The file itself is read
 * in check_final, once it is known whether token is set as well. */
#define CREDENTIALS_VAR "${CREDENTIALS_DIRECTORY}"
int conf_set_token_file(conf_parse *st, const char *key, const char *v) {
  const size_t nv = strlen(CREDENTIALS_VAR);
  if (!v[0]) {
    free(st->conf->token_file);
    st->conf->token_file = NULL;
    return 1;
  }
  if (strncmp(v, CREDENTIALS_VAR, nv) != 0) return conf_set_path(st, key, &st->conf->token_file, v);
  const char *dir = getenv("CREDENTIALS_DIRECTORY");
  if (!dir || dir[0] != '/')
    return conf_fail_at(st, st->line, st->sec_text, key, "%s is not set: systemd sets it for a "
                        "service with LoadCredential= (see systemd/fieldgripd.service); started "
                        "otherwise, name the token file itself", CREDENTIALS_VAR);
  if (v[nv] != '/' || !v[nv + 1])
    return conf_fail_at(st, st->line, st->sec_text, key, "expected %s/NAME, got '%s'",
                        CREDENTIALS_VAR, v);
  char *p = malloc(strlen(dir) + strlen(v + nv) + 1);
  if (!p) return conf_fail_nomem(st);
  sprintf(p, "%s%s", dir, v + nv);
  free(st->conf->token_file);
  st->conf->token_file = p;
  return 1;
}

/* import_dirs: colon-separated folders. Empty entries ("a::b", a trailing colon) are skipped
 * rather than read as "the current folder", which would be a surprising thing to export.
 * The folders need not exist yet (a share may be mounted after start-up). */
int conf_set_import_dirs(conf_parse *st, const char *key, const char *v) {
  char **dirs = NULL;
  size_t n = 0;
  const char *s = v;
  while (*s) {
    const char *colon = strchr(s, ':');
    size_t len = colon ? (size_t)(colon - s) : strlen(s);
    if (len > 0) {
      char *part = strndup(s, len);
      char *abs = part ? conf_path_absolute(st->base_dir, part) : NULL;
      free(part);
      char **grown = abs ? realloc(dirs, (n + 1) * sizeof *dirs) : NULL;
      if (!grown) {
        free(abs);
        free_dirs(dirs, n);
        return conf_fail_nomem(st);
      }
      dirs = grown;
      dirs[n++] = abs;
    }
    s += len;
    if (*s == ':') s++;
  }
  free_dirs(st->conf->import_dirs, st->conf->n_import_dirs);
  st->conf->import_dirs = dirs;
  st->conf->n_import_dirs = n;
  return 1;
}
