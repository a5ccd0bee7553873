/* Unit tests of the Idempotency-Key store (daemon/idem.c): a key's request is known by the
 * SHA-256 of its path and body, the file says so, and a version 1 file (64-bit FNV-1a
 * hashes) still loads and still tells a retry from another request. */
#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "idem.h"

#include <time.h>
#include <unistd.h>

static char tmpdir[] = "/tmp/fg-test-idem-XXXXXX";

static const char PATH[] = "/v1/robot/commands";
static const char BODY[] = "{\"command\":\"open\"}";
static const char OTHER[] = "{\"command\":\"close\"}";

/* The file's text (malloc'd). */
static char *file_text(const char *path) {
  char *text;
  size_t len;
  ASSERT_OK(fg_read_file(path, 1 << 20, &text, &len));
  return text;
}

/* sha256sum of the path, a NUL and the body, computed outside the daemon's code. */
static void expected_digest(const char *body, char out[65]) {
  char cmd[512];
  snprintf(cmd, sizeof cmd, "printf '%%s\\0%%s' '%s' '%s' | sha256sum", PATH, body);
  FILE *p = popen(cmd, "r");
  ASSERT(p && fscanf(p, "%64s", out) == 1);
  pclose(p);
}

static int begin(fg_idem *s, const char *key, const char *body, int *status, char **answer) {
  return fg_idem_begin(s, key, PATH, body, strlen(body), status, answer);
}

static void test_sha256_keys(const char *file) {
  fg_idem *s;
  ASSERT_OK(fg_idem_open(&s, file));
  int status = 0;
  char *answer = NULL;
  ASSERT_EQ(begin(s, "k1", BODY, &status, &answer), FG_IDEM_NEW);
  ASSERT_EQ(begin(s, "k1", BODY, &status, &answer), FG_IDEM_RUNNING);
  ASSERT_OK(fg_idem_finish(s, "k1", 200, "{\"ok\":1}"));
  ASSERT_EQ(begin(s, "k1", BODY, &status, &answer), FG_IDEM_REPLAY);
  ASSERT_EQ(status, 200);
  ASSERT_STREQ(answer, "{\"ok\":1}");
  free(answer);
  ASSERT_EQ(begin(s, "k1", OTHER, &status, &answer), FG_IDEM_CONFLICT);
  /* the same body to another path is another request */
  ASSERT_EQ(fg_idem_begin(s, "k1", "/v1/gripper/open", BODY, strlen(BODY), &status, &answer),
            FG_IDEM_CONFLICT);
  fg_idem_free(s);

  /* the file holds the digest as sha256sum prints it, and reads back */
  char want[65], *text = file_text(file);
  expected_digest(BODY, want);
  ASSERT_STRCONTAINS(text, "\"version\":2");
  ASSERT_STRCONTAINS(text, want);
  free(text);
  ASSERT_OK(fg_idem_open(&s, file));
  ASSERT_EQ(begin(s, "k1", BODY, &status, &answer), FG_IDEM_REPLAY);
  free(answer);
  ASSERT_EQ(begin(s, "k1", OTHER, &status, &answer), FG_IDEM_CONFLICT);
  fg_idem_free(s);
}

/* FNV-1a 64, as version 1 stored it. */
static uint64_t fnv(const char *p, size_t len) {
  uint64_t h = 1469598103934665603ULL;
  for (size_t i = 0; i < len; i++) {
    h ^= (unsigned char)p[i];
    h *= 1099511628211ULL;
  }
  return h;
}

static void test_version1_file(const char *file) {
  const uint64_t h = fnv(PATH, strlen(PATH)) ^ fnv(BODY, strlen(BODY)) * 31;
  char text[512];
  snprintf(text, sizeof text, "{\"version\":1,\"keys\":[{\"key\":\"old\",\"hash\":\"%016" PRIx64
           "\",\"status\":200,\"body\":\"{\\\"old\\\":1}\",\"created\":%lld}]}", h,
           (long long)time(NULL));
  ASSERT_OK(fg_write_file_atomic(file, text, strlen(text)));
  fg_idem *s;
  ASSERT_OK(fg_idem_open(&s, file));
  int status = 0;
  char *answer = NULL;
  ASSERT_EQ(begin(s, "old", BODY, &status, &answer), FG_IDEM_REPLAY);
  ASSERT_STREQ(answer, "{\"old\":1}");
  free(answer);
  ASSERT_EQ(begin(s, "old", OTHER, &status, &answer), FG_IDEM_CONFLICT);
  /* a new key is written as version 2; the old one keeps its hash until it ages out */
  ASSERT_EQ(begin(s, "new", BODY, &status, &answer), FG_IDEM_NEW);
  fg_idem_free(s);
  char *now = file_text(file);
  ASSERT_STRCONTAINS(now, "\"version\":2");
  ASSERT_STRCONTAINS(now, "\"hash\"");
  ASSERT_STRCONTAINS(now, "\"sha256\"");
  free(now);
  /* "new" was saved before its command had an answer (a daemon killed then): it answers
   * outcome_unknown now, and is not run again */
  ASSERT_OK(fg_idem_open(&s, file));
  ASSERT_EQ(begin(s, "old", BODY, &status, &answer), FG_IDEM_REPLAY);
  free(answer);
  ASSERT_EQ(begin(s, "new", BODY, &status, &answer), FG_IDEM_REPLAY);
  ASSERT_EQ(status, 504);
  ASSERT_STRCONTAINS(answer, "outcome_unknown");
  free(answer);
  fg_idem_free(s);
}

static void test_malformed(const char *file) {
  /* a digest that is not 64 hex digits, and an entry with both kinds */
  const char *bad[] = {
      "{\"version\":2,\"keys\":[{\"key\":\"a\",\"sha256\":\"12ab\",\"status\":200,"
      "\"body\":\"{}\",\"created\":1}]}",
      "{\"version\":2,\"keys\":[{\"key\":\"a\",\"hash\":\"12ab\",\"sha256\":\"12ab\","
      "\"status\":200,\"body\":\"{}\",\"created\":1}]}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
    ASSERT_OK(fg_write_file_atomic(file, bad[i], strlen(bad[i])));
    fg_idem *s;
    ASSERT_ERR(fg_idem_open(&s, file), FG_EFORMAT, "malformed");
  }
}

int main(void) {
  ASSERT(mkdtemp(tmpdir));
  char *file = fg_path_join(tmpdir, "idempotency.json");
  test_sha256_keys(file);
  unlink(file);
  test_version1_file(file);
  test_malformed(file);
  free(file);
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("idem: ok\n");
  return 0;
}
