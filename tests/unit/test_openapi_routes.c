/* The documentation matches the server: every route fieldgripd registers (fieldgripd
 * --list-routes) is an operation of proto/openapi.yaml's `paths:`, and every operation there
 * is a route the daemon registers; and README.md walks the whole API: every route is called
 * by at least one of its curl examples. Fails naming each method and path that is on one
 * side only, or that no example calls.
 *
 * Usage: test_openapi_routes FIELDGRIPD OPENAPI_YAML README_MD */
#include "test.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_OPS 256

typedef struct op {
  char method[16]; /* upper case, "GET" */
  char path[200];  /* "/v1/scenes/{s}" */
} op;

typedef struct op_list {
  op ops[MAX_OPS];
  int n;
} op_list;

static void op_add(op_list *l, const char *method, const char *path, const char *where) {
  if (l->n == MAX_OPS) FG_TEST_FAIL("%s: more than %d operations", where, MAX_OPS);
  op *o = &l->ops[l->n++];
  snprintf(o->method, sizeof o->method, "%s", method);
  for (char *p = o->method; *p; p++)
    if (*p >= 'a' && *p <= 'z') *p = (char)(*p - 'a' + 'A');
  if (strlen(path) >= sizeof o->path) FG_TEST_FAIL("%s: path too long: %s", where, path);
  snprintf(o->path, sizeof o->path, "%s", path);
}

static int op_find(const op_list *l, const op *o) {
  for (int i = 0; i < l->n; i++)
    if (strcmp(l->ops[i].method, o->method) == 0 && strcmp(l->ops[i].path, o->path) == 0)
      return 1;
  return 0;
}

/* ---------------------------------------------------------------- openapi.yaml */

/* Number of leading spaces of line; -1 for a blank or comment-only line. */
static int indent_of(const char *line) {
  int n = 0;
  while (line[n] == ' ') n++;
  if (line[n] == '\0' || line[n] == '\n' || line[n] == '\r' || line[n] == '#') return -1;
  return n;
}

/* The mapping key of a "key:" or "key: value" line starting at s, unquoted, into key;
 * 0 when the line is not a plain mapping key. */
static int yaml_key(const char *s, char *key, size_t cap) {
  char quote = 0;
  if (*s == '\'' || *s == '"') quote = *s++;
  size_t n = 0;
  while (s[n] && s[n] != '\n' && (quote ? s[n] != quote : s[n] != ':')) n++;
  if (quote) {
    if (s[n] != quote || s[n + 1] != ':') return 0;
  } else if (s[n] != ':') {
    return 0;
  }
  if (n == 0 || n >= cap) return 0;
  memcpy(key, s, n);
  key[n] = '\0';
  return 1;
}

/* Reads the operations of the `paths:` section: path keys one level in, their HTTP-method
 * keys one level further (path-level `parameters:` and the like are skipped). */
static void read_openapi(const char *file, op_list *out) {
  static const char *const methods[] = {"get",    "put",  "post",    "delete",
                                        "patch",  "head", "options", "trace"};
  FILE *f = fopen(file, "r");
  if (!f) FG_TEST_FAIL("cannot open %s", file);
  char line[1024], path[200] = "", key[200], where[300];
  int in_paths = 0, path_indent = -1, op_indent = -1, lineno = 0, n_paths = 0;
  while (fgets(line, sizeof line, f)) {
    lineno++;
    int ind = indent_of(line);
    if (ind < 0) continue;
    if (ind == 0) {
      in_paths = strncmp(line, "paths:", 6) == 0;
      path_indent = -1;
      continue;
    }
    if (!in_paths || !yaml_key(line + ind, key, sizeof key)) continue;
    if (path_indent < 0) path_indent = ind;
    snprintf(where, sizeof where, "%s:%d", file, lineno);
    if (ind == path_indent) {
      if (key[0] != '/') FG_TEST_FAIL("%s: path key '%s' does not start with '/'", where, key);
      snprintf(path, sizeof path, "%s", key);
      op_indent = -1;
      n_paths++;
    } else if (path[0] && ind > path_indent) {
      /* Keys one level under the path only: a deeper "post:" is a property, not an
       * operation. */
      if (op_indent < 0) op_indent = ind;
      if (ind != op_indent) continue;
      for (size_t i = 0; i < sizeof methods / sizeof methods[0]; i++)
        if (strcmp(key, methods[i]) == 0) op_add(out, key, path, where);
    }
  }
  fclose(f);
  if (n_paths == 0) FG_TEST_FAIL("%s: no `paths:` section with path keys found", file);
}

/* ---------------------------------------------------------------- the daemon's routes */

static void read_routes(const char *daemon, op_list *out) {
  char cmd[4200];
  snprintf(cmd, sizeof cmd, "'%s' --list-routes", daemon);
  FILE *p = popen(cmd, "r");
  if (!p) FG_TEST_FAIL("cannot run %s", cmd);
  char line[512], method[32], path[256];
  while (fgets(line, sizeof line, p)) {
    if (sscanf(line, "%31s %255s", method, path) != 2)
      FG_TEST_FAIL("%s printed a line that is not \"METHOD PATH\": %s", cmd, line);
    op_add(out, method, path, cmd);
  }
  int st = pclose(p);
  if (st != 0) FG_TEST_FAIL("%s exited with status %d", cmd, st);
  if (out->n == 0) FG_TEST_FAIL("%s printed no routes", cmd);
}

/* ---------------------------------------------------------------- the parser itself */

/* The parser on a small document: quoted keys, path-level parameters, properties named like
 * methods deeper down, and a section after paths. */
static void test_parser(void) {
  char name[] = "/tmp/fg-openapi-XXXXXX";
  int fd = mkstemp(name);
  ASSERT(fd >= 0);
  FILE *f = fdopen(fd, "w");
  ASSERT(f != NULL);
  fputs("openapi: 3.0.3\n"
        "info:\n  title: x\n"
        "paths:\n"
        "  /a:\n"
        "    # a comment\n"
        "    get:\n"
        "      responses:\n"
        "        '200':\n"
        "          content:\n"
        "            application/json:\n"
        "              schema:\n"
        "                properties:\n"
        "                  post:\n"
        "                    type: string\n"
        "    delete:\n"
        "      summary: x\n"
        "\n"
        "  '/b/{id}':\n"
        "    parameters:\n"
        "      - name: id\n"
        "    post: {summary: x}\n"
        "components:\n"
        "  /c:\n"
        "    get:\n",
        f);
  fclose(f);
  op_list l = {0};
  read_openapi(name, &l);
  unlink(name);
  /* Not the property named post under /a's GET, nor /c outside paths. */
  ASSERT_EQ(l.n, 3);
  ASSERT_STREQ(l.ops[0].method, "GET");
  ASSERT_STREQ(l.ops[0].path, "/a");
  ASSERT_STREQ(l.ops[1].method, "DELETE");
  ASSERT_STREQ(l.ops[1].path, "/a");
  ASSERT_STREQ(l.ops[2].method, "POST");
  ASSERT_STREQ(l.ops[2].path, "/b/{id}");
}

/* ---------------------------------------------------------------- README.md */

/* 1 when path (no query string) fits template: each "{x}" of the template stands for one
 * or more characters other than '/'. */
static int path_matches(const char *tmpl, const char *path) {
  while (*tmpl && *path) {
    if (*tmpl == '{') {
      const char *close = strchr(tmpl, '}');
      if (!close || *path == '/') return 0;
      while (*path && *path != '/') path++;
      tmpl = close + 1;
    } else if (*tmpl++ != *path++) {
      return 0;
    }
  }
  return *tmpl == 0 && *path == 0;
}

/* The method and path of one curl command (its continuation lines joined): -X's method,
 * else POST with -d/-F, else GET; the path of its http:// URL without the query string. */
static int curl_call(const char *cmd, char *method, size_t mcap, char *path, size_t pcap) {
  const char *url = strstr(cmd, "http://");
  if (!url) return 0;
  const char *p = strchr(url + 7, '/');
  if (!p) return 0;
  size_t n = strcspn(p, " '\"?\\");
  if (n >= pcap) return 0;
  memcpy(path, p, n);
  path[n] = 0;
  const char *x = strstr(cmd, " -X ");
  if (x) {
    snprintf(method, mcap, "%.*s", (int)strcspn(x + 4, " "), x + 4);
  } else {
    snprintf(method, mcap, "%s", strstr(cmd, " -d ") || strstr(cmd, " -F ") ? "POST" : "GET");
  }
  return 1;
}

/* The curl commands of file's lines (a line ending in a backslash continues on the next),
 * as operations. */
static void read_readme(const char *file, op_list *out) {
  FILE *f = fopen(file, "r");
  if (!f) FG_TEST_FAIL("cannot open %s", file);
  static char cmd[1 << 16];
  char line[4096];
  size_t len = 0;
  while (fgets(line, sizeof line, f)) {
    size_t n = strcspn(line, "\n");
    line[n] = 0;
    const int more = n > 0 && line[n - 1] == '\\';
    if (more) line[--n] = 0;
    if (len + n + 1 < sizeof cmd) {
      memcpy(cmd + len, line, n);
      len += n;
      cmd[len++] = ' ';
      cmd[len] = 0;
    }
    if (more) continue;
    char method[16], path[200];
    const char *c = strstr(cmd, "curl ");
    if (c && curl_call(c, method, sizeof method, path, sizeof path)) op_add(out, method, path, file);
    len = 0;
    cmd[0] = 0;
  }
  fclose(f);
}

static int readme_calls(const op_list *calls, const op *route) {
  for (int i = 0; i < calls->n; i++)
    if (strcmp(calls->ops[i].method, route->method) == 0 &&
        path_matches(route->path, calls->ops[i].path))
      return 1;
  return 0;
}

static void test_readme_parser(void) {
  ASSERT(path_matches("/v1/scenes/{s}/frames", "/v1/scenes/lego/frames"));
  ASSERT(path_matches("/v1/jobs/{id}", "/v1/jobs/$JOB"));
  ASSERT(!path_matches("/v1/scenes/{s}", "/v1/scenes/a/frames"));
  ASSERT(!path_matches("/v1/scenes/{s}", "/v1/scenes/"));
  char m[16], p[200];
  ASSERT(curl_call("curl -s -X DELETE http://127.0.0.1:7070/v1/tasks/t1 ", m, sizeof m, p, sizeof p));
  ASSERT_STREQ(m, "DELETE");
  ASSERT_STREQ(p, "/v1/tasks/t1");
  ASSERT(curl_call("curl -s http://h:1/v1/scenes/a/frames -F image=@x ", m, sizeof m, p, sizeof p));
  ASSERT_STREQ(m, "POST");
  ASSERT(curl_call("curl -s 'http://h:1/v1/scenes/a/geometry?kind=points' ", m, sizeof m, p, sizeof p));
  ASSERT_STREQ(m, "GET");
  ASSERT_STREQ(p, "/v1/scenes/a/geometry");
}

int main(int argc, char **argv) {
  if (argc != 4) FG_TEST_FAIL("usage: %s FIELDGRIPD OPENAPI_YAML README_MD", argv[0]);
  test_parser();
  test_readme_parser();
  static op_list routes, doc, calls;
  read_routes(argv[1], &routes);
  read_openapi(argv[2], &doc);
  read_readme(argv[3], &calls);
  int missing = 0;
  for (int i = 0; i < routes.n; i++)
    if (!op_find(&doc, &routes.ops[i])) {
      fprintf(stderr, "served but not in %s: %s %s\n", argv[2], routes.ops[i].method,
              routes.ops[i].path);
      missing++;
    }
  for (int i = 0; i < doc.n; i++)
    if (!op_find(&routes, &doc.ops[i])) {
      fprintf(stderr, "in %s but not served: %s %s\n", argv[2], doc.ops[i].method,
              doc.ops[i].path);
      missing++;
    }
  for (int i = 0; i < routes.n; i++)
    if (!readme_calls(&calls, &routes.ops[i])) {
      fprintf(stderr, "no curl example in %s calls %s %s\n", argv[3], routes.ops[i].method,
              routes.ops[i].path);
      missing++;
    }
  for (int i = 0; i < routes.n; i++)
    for (int j = i + 1; j < routes.n; j++)
      if (strcmp(routes.ops[i].method, routes.ops[j].method) == 0 &&
          strcmp(routes.ops[i].path, routes.ops[j].path) == 0)
        FG_TEST_FAIL("route registered twice: %s %s", routes.ops[i].method, routes.ops[i].path);
  ASSERT_EQ(missing, 0);
  printf("%d routes, all documented and called by README examples (%d), nothing else "
         "documented\n", routes.n, calls.n);
  return 0;
}
