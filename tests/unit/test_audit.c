/* Unit tests of the robot's audit log (daemon/robot/audit.c): rotation keeps audit_keep files and
 * drops the oldest, reading back pages newest first across the files, entry numbers carry
 * on after a reopen (also past a torn last line), files beyond a smaller keep are removed,
 * and a command's end reported before its request's line still lands after it. */
#include "test.h"

#include "robot/audit.h"
#include "core/error.h"
#include "core/fsutil.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static char tmpdir[] = "/tmp/fg-test-audit-XXXXXX";

static fg_audit *open_log(const char *dir, size_t max_bytes, int keep) {
  fg_audit *a;
  const fg_audit_config cfg = {.dir = dir, .max_bytes = max_bytes, .keep = keep};
  ASSERT_OK(fg_audit_open(&a, &cfg));
  ASSERT_OK(fg_audit_ready(a));
  return a;
}

static void append_n(fg_audit *a, int n, const char *what) {
  for (int i = 0; i < n; i++) {
    json_t *e = json_pack("{s:s, s:i, s:s}", "kind", "request", "i", i, "what", what);
    ASSERT_OK(fg_audit_append(a, e));
    json_decref(e);
  }
}

static int exists(const char *dir, const char *name) {
  char *p = fg_path_join(dir, name);
  const int yes = access(p, F_OK) == 0;
  free(p);
  return yes;
}

static long long seq_at(json_t *arr, size_t i) {
  return json_integer_value(json_object_get(json_array_get(arr, i), "seq"));
}

/* Pages of 7 through 30 entries spread over several files give 30..1 exactly once each. */
static void test_rotation_and_paging(void) {
  char *dir = fg_path_join(tmpdir, "rot");
  /* one line is about 80 bytes: 200 bytes hold two, so 30 lines need 15 files; keep 20 */
  fg_audit *a = open_log(dir, 200, 20);
  append_n(a, 30, "x");
  ASSERT(exists(dir, "robot.log.14"));
  ASSERT(!exists(dir, "robot.log.15"));
  uint64_t before = 0, expect = 30;
  int pages = 0, more = 1;
  while (more) {
    json_t *arr;
    ASSERT_OK(fg_audit_read(a, before, 7, &arr, &more));
    for (size_t i = 0; i < json_array_size(arr); i++) ASSERT_EQ(seq_at(arr, i), (long long)expect--);
    before = (uint64_t)seq_at(arr, json_array_size(arr) - 1);
    json_decref(arr);
    pages++;
  }
  ASSERT_EQ(expect, 0);
  ASSERT_EQ(pages, 5); /* 7 + 7 + 7 + 7 + 2 */
  fg_audit_free(a);

  /* a smaller keep: the rotation deletes the oldest, and the open removes what is beyond */
  a = open_log(dir, 200, 3);
  ASSERT(!exists(dir, "robot.log.4"));
  ASSERT(!exists(dir, "robot.log.14"));
  append_n(a, 10, "y");
  ASSERT(exists(dir, "robot.log.3"));
  ASSERT(!exists(dir, "robot.log.4"));
  json_t *arr;
  int m;
  ASSERT_OK(fg_audit_read(a, 0, 1000, &arr, &m));
  ASSERT_EQ(m, 0);
  ASSERT(json_array_size(arr) <= 8); /* (keep + 1) files of at most two lines */
  ASSERT_EQ(seq_at(arr, 0), 40);     /* numbering went on after the reopen */
  json_decref(arr);
  fg_audit_free(a);
  free(dir);
}

/* A line torn by a crash is skipped and the next line starts on its own line. */
static void test_torn_line(void) {
  char *dir = fg_path_join(tmpdir, "torn");
  fg_audit *a = open_log(dir, 1 << 20, 2);
  append_n(a, 3, "z");
  fg_audit_free(a);
  char *path = fg_path_join(dir, "robot.log");
  FILE *f = fopen(path, "a");
  ASSERT(f);
  fputs("{\"seq\":4,\"time\":\"2026-", f); /* what a kill -9 inside write() can leave */
  fclose(f);
  a = open_log(dir, 1 << 20, 2);
  append_n(a, 1, "after");
  json_t *arr;
  int more;
  ASSERT_OK(fg_audit_read(a, 0, 10, &arr, &more));
  ASSERT_EQ(json_array_size(arr), 4);
  ASSERT_EQ(seq_at(arr, 0), 4);
  ASSERT_STREQ(json_string_value(json_object_get(json_array_get(arr, 0), "what")), "after");
  ASSERT_EQ(seq_at(arr, 1), 3);
  json_decref(arr);
  fg_audit_free(a);
  free(path);
  free(dir);
}

/* The end of command 5 reported before its request's line: written after it, with the
 * request's context; an end of a command whose answer had it already is not written. */
static void test_pairs(void) {
  char *dir = fg_path_join(tmpdir, "pairs");
  fg_audit *a = open_log(dir, 1 << 20, 2);
  json_t *end = json_pack("{s:s, s:s}", "kind", "end", "outcome", "done");
  json_t *req = json_pack("{s:s, s:s}", "kind", "request", "outcome", "acknowledged");
  json_t *ctx = json_pack("{s:s}", "request_id", "r-5");
  ASSERT_OK(fg_audit_append_end(a, 5, end));
  ASSERT_OK(fg_audit_append_begun(a, 5, req, 1, ctx));
  /* command 6: the request first, then its end */
  ASSERT_OK(fg_audit_append_begun(a, 6, req, 1, ctx));
  ASSERT_OK(fg_audit_append_end(a, 6, end));
  /* command 7 was answered with its end (200): a late end is dropped */
  ASSERT_OK(fg_audit_append_begun(a, 7, req, 0, ctx));
  ASSERT_OK(fg_audit_append_end(a, 7, end));
  json_t *arr;
  int more;
  ASSERT_OK(fg_audit_read(a, 0, 10, &arr, &more));
  ASSERT_EQ(json_array_size(arr), 5);
  static const char *const kinds[] = {"request", "end", "request", "end", "request"};
  for (int i = 0; i < 5; i++) {
    json_t *e = json_array_get(arr, 4 - (size_t)i); /* oldest first */
    ASSERT_STREQ(json_string_value(json_object_get(e, "kind")), kinds[i]);
  }
  ASSERT_STREQ(json_string_value(json_object_get(json_array_get(arr, 3), "request_id")), "r-5");
  json_decref(arr);
  json_decref(end);
  json_decref(req);
  json_decref(ctx);
  fg_audit_free(a);
  free(dir);
}

/* A folder that cannot be made: the log opens unavailable and says so. */
static void test_unavailable(void) {
  char *file = fg_path_join(tmpdir, "not-a-dir");
  FILE *f = fopen(file, "w");
  ASSERT(f);
  fclose(f);
  char *dir = fg_path_join(file, "audit");
  fg_audit *a;
  const fg_audit_config cfg = {.dir = dir, .max_bytes = 1000, .keep = 1};
  ASSERT_OK(fg_audit_open(&a, &cfg));
  ASSERT(fg_audit_ready(a) < 0);
  json_t *e = json_pack("{s:s}", "kind", "request");
  ASSERT(fg_audit_append(a, e) < 0);
  json_decref(e);
  char m[1024];
  fg_audit_metrics(a, m, sizeof m);
  ASSERT_STRCONTAINS(m, "fieldgrip_audit_write_errors_total 3");
  fg_audit_free(a);
  free(dir);
  free(file);
}

int main(void) {
  ASSERT(mkdtemp(tmpdir));
  test_rotation_and_paging();
  test_torn_line();
  test_pairs();
  test_unavailable();
  fg_rmtree(tmpdir);
  printf("audit: ok\n");
  return 0;
}
