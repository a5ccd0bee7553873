/* Unit tests of the Idempotency-Key store (daemon/state/idem.c): a key knows its request by the
 * canonical JSON of its body, lives 24 hours whatever the number of keys, is kept in a
 * journal that replays after a restart (a torn last line dropped), is compacted, and is
 * refused at the store's cap rather than forgetting a younger key; the whole-file stores of
 * earlier daemons (versions 1 and 2) migrate. Time is the test's own clock. */
#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "state/idem.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmpdir[] = "/tmp/fg-test-idem-XXXXXX";
static char *journal, *legacy;

static const char PATH[] = "/v1/robot/commands";
static const char BODY[] = "{\"command\":\"open\"}";
static const char OTHER[] = "{\"command\":\"close\"}";

static int64_t clock_s = 1700000000;
static int64_t test_now(void *ctx) {
  (void)ctx;
  return clock_s;
}

static fg_idem *store_open(size_t max_keys, size_t max_bytes) {
  fg_idem_config cfg = {max_keys, max_bytes, test_now, NULL};
  fg_idem *s;
  ASSERT_OK(fg_idem_open(&s, tmpdir, &cfg));
  return s;
}

static void store_reset(void) {
  unlink(journal);
  unlink(legacy);
}

static char *file_text(const char *path) {
  char *text;
  size_t len;
  ASSERT_OK(fg_read_file(path, 16 << 20, &text, &len));
  return text;
}

/* fg_idem_begin of method, path and body; *answer freed here unless wanted. */
static int begin_req(fg_idem *s, const char *key, const char *method, const char *path,
                     const char *body, int *status) {
  const fg_idem_request rq = {method, path, body, strlen(body)};
  char *answer = NULL;
  int rc = fg_idem_begin(s, key, &rq, status, &answer);
  free(answer);
  return rc;
}

static int begin(fg_idem *s, const char *key, const char *body, int *status) {
  return begin_req(s, key, "POST", PATH, body, status);
}

/* The stored answer of a key that must replay (malloc'd). */
static char *replay(fg_idem *s, const char *key, const char *body, int *status) {
  const fg_idem_request rq = {"POST", PATH, body, strlen(body)};
  char *answer = NULL;
  ASSERT_EQ(fg_idem_begin(s, key, &rq, status, &answer), FG_IDEM_REPLAY);
  return answer;
}

static void test_canonical_request(void) {
  store_reset();
  fg_idem *s = store_open(0, 0);
  int status = 0;
  ASSERT_EQ(begin(s, "k1", "{\"width\":0.05,\"command\":\"move\"}", &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "k1", 200, "{\"ok\":1}"));
  /* spacing and key order are the client's serialiser, not another request */
  ASSERT_EQ(begin(s, "k1", " {\n \"command\" : \"move\",\t\"width\": 0.05 }\n", &status),
            FG_IDEM_REPLAY);
  ASSERT_EQ(status, 200);
  ASSERT_EQ(begin(s, "k1", "{\"command\":\"move\",\"width\":0.06}", &status), FG_IDEM_CONFLICT);
  ASSERT_EQ(begin_req(s, "k1", "POST", "/v1/gripper/move", "{\"command\":\"move\","
                      "\"width\":0.05}", &status), FG_IDEM_CONFLICT);
  ASSERT_EQ(begin_req(s, "k1", "PUT", PATH, "{\"command\":\"move\",\"width\":0.05}", &status),
            FG_IDEM_CONFLICT);
  /* a bare POST is the request {} */
  ASSERT_EQ(begin_req(s, "k2", "POST", "/v1/gripper/close", "", &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "k2", 200, "{}"));
  ASSERT_EQ(begin_req(s, "k2", "POST", "/v1/gripper/close", " { } ", &status), FG_IDEM_REPLAY);
  /* a body that is not JSON is known by its bytes */
  ASSERT_EQ(begin(s, "k3", "{not json", &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "k3", 400, "{}"));
  ASSERT_EQ(begin(s, "k3", "{not json", &status), FG_IDEM_REPLAY);
  ASSERT_EQ(begin(s, "k3", "{not  json", &status), FG_IDEM_CONFLICT);
  fg_idem_free(s);
}

static void test_peek_does_not_take(void) {
  store_reset();
  fg_idem *s = store_open(0, 0);
  const fg_idem_request rq = {"POST", PATH, BODY, strlen(BODY)};
  int status = 0;
  char *answer = NULL;
  ASSERT_EQ(fg_idem_peek(s, "p", &rq, &status, &answer), FG_IDEM_NEW);
  ASSERT_EQ(fg_idem_peek(s, "p", &rq, &status, &answer), FG_IDEM_NEW);
  ASSERT_EQ(begin(s, "p", BODY, &status), FG_IDEM_NEW);
  ASSERT_EQ(fg_idem_peek(s, "p", &rq, &status, &answer), FG_IDEM_RUNNING);
  ASSERT_OK(fg_idem_finish(s, "p", 201, "{\"p\":1}"));
  ASSERT_EQ(fg_idem_peek(s, "p", &rq, &status, &answer), FG_IDEM_REPLAY);
  ASSERT_EQ(status, 201);
  ASSERT_STREQ(answer, "{\"p\":1}");
  free(answer);
  fg_idem_free(s);
}

static void test_journal_replay(void) {
  store_reset();
  fg_idem *s = store_open(0, 0);
  int status = 0;
  ASSERT_EQ(begin(s, "done", BODY, &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "done", 200, "{\"done\":1}"));
  ASSERT_EQ(begin(s, "running", BODY, &status), FG_IDEM_NEW);
  ASSERT_EQ(begin(s, "ended", BODY, &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "ended", 202, "{\"state\":\"acknowledged\"}"));
  ASSERT_OK(fg_idem_update(s, "ended", 200, "{\"state\":\"done\"}"));
  ASSERT_EQ(begin(s, "acked", BODY, &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "acked", 202, "{\"state\":\"acknowledged\"}"));
  ASSERT_EQ(begin(s, "refused", BODY, &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_cancel(s, "refused"));
  size_t keys, bytes;
  fg_idem_stats(s, &keys, &bytes);
  ASSERT_EQ(keys, 4u);
  fg_idem_free(s); /* as kill -9 would: every line was fsync'd when it was written */

  char *text = file_text(journal);
  ASSERT(strncmp(text, "{\"version\":3}\n", 14) == 0);
  ASSERT_STRCONTAINS(text, "\"op\":\"cancel\"");
  free(text);

  s = store_open(0, 0);
  char *answer = replay(s, "done", BODY, &status);
  ASSERT_EQ(status, 200);
  ASSERT_STREQ(answer, "{\"done\":1}");
  free(answer);
  answer = replay(s, "ended", BODY, &status);
  ASSERT_EQ(status, 200);
  ASSERT_STREQ(answer, "{\"state\":\"done\"}");
  free(answer);
  /* cut short: no answer, or only the acknowledgement */
  const char *cut[] = {"running", "acked"};
  for (int i = 0; i < 2; i++) {
    answer = replay(s, cut[i], BODY, &status);
    ASSERT_EQ(status, 504);
    ASSERT_STRCONTAINS(answer, "outcome_unknown");
    free(answer);
  }
  ASSERT_EQ(begin(s, "refused", BODY, &status), FG_IDEM_NEW);
  fg_idem_free(s);
}

static void test_expiry_by_age(void) {
  store_reset();
  fg_idem *s = store_open(0, 0);
  int status = 0;
  char key[32];
  /* more than the 1,000 keys an earlier daemon kept: all live for their 24 hours */
  for (int i = 0; i < 1200; i++) {
    snprintf(key, sizeof key, "age-%d", i);
    ASSERT_EQ(begin(s, key, BODY, &status), FG_IDEM_NEW);
    ASSERT_OK(fg_idem_finish(s, key, 200, "{}"));
  }
  clock_s += 24 * 3600;
  ASSERT_EQ(begin(s, "age-0", BODY, &status), FG_IDEM_REPLAY);
  ASSERT_EQ(begin(s, "age-1199", BODY, &status), FG_IDEM_REPLAY);
  fg_idem_free(s);
  s = store_open(0, 0);
  ASSERT_EQ(begin(s, "age-0", BODY, &status), FG_IDEM_REPLAY);
  size_t keys, bytes;
  fg_idem_stats(s, &keys, &bytes);
  ASSERT_EQ(keys, 1200u);
  /* a second later they are past 24 hours: gone, in memory and after a restart */
  clock_s += 1;
  ASSERT_EQ(begin(s, "age-1", OTHER, &status), FG_IDEM_NEW);
  fg_idem_stats(s, &keys, &bytes);
  ASSERT_EQ(keys, 1u);
  fg_idem_free(s);
  s = store_open(0, 0);
  fg_idem_stats(s, &keys, &bytes);
  ASSERT_EQ(keys, 1u);
  ASSERT_EQ(begin(s, "age-2", BODY, &status), FG_IDEM_NEW);
  fg_idem_free(s);
}

static void test_cap(void) {
  store_reset();
  fg_idem *s = store_open(3, 0);
  int status = 0;
  const char *keys[] = {"c1", "c2", "c3"};
  for (int i = 0; i < 3; i++) {
    ASSERT_EQ(begin(s, keys[i], BODY, &status), FG_IDEM_NEW);
    ASSERT_OK(fg_idem_finish(s, keys[i], 200, "{}"));
  }
  ASSERT_ERR(begin(s, "c4", BODY, &status), FG_ERANGE, "full");
  /* the younger keys are all kept, and the refused one was not taken */
  for (int i = 0; i < 3; i++) ASSERT_EQ(begin(s, keys[i], BODY, &status), FG_IDEM_REPLAY);
  clock_s += 24 * 3600 + 1;
  ASSERT_EQ(begin(s, "c4", BODY, &status), FG_IDEM_NEW);
  fg_idem_free(s);

  /* the cap in bytes: answers of 10 KiB in a 64 KiB store */
  store_reset();
  s = store_open(0, 64 << 10);
  static char big[10 << 10];
  memset(big, 'x', sizeof big - 1);
  int taken = 0, rc;
  char key[16];
  for (;;) {
    snprintf(key, sizeof key, "b%d", taken);
    if ((rc = begin(s, key, BODY, &status)) != FG_IDEM_NEW) break;
    ASSERT_OK(fg_idem_finish(s, key, 200, big));
    taken++;
  }
  ASSERT_EQ(rc, FG_ERANGE);
  ASSERT(taken >= 4 && taken <= 6);
  fg_idem_free(s);
}

static void test_compaction(void) {
  store_reset();
  fg_idem *s = store_open(0, 64 << 10); /* a floor of 1 KiB: compacts soon */
  int status = 0;
  ASSERT_EQ(begin(s, "long", BODY, &status), FG_IDEM_NEW);
  char answer[64];
  size_t keys, bytes, most = 0;
  for (int i = 0; i < 2000; i++) {
    snprintf(answer, sizeof answer, "{\"step\":%d}", i);
    ASSERT_OK(fg_idem_update(s, "long", 202, answer));
    fg_idem_stats(s, &keys, &bytes);
    if (bytes > most) most = bytes;
  }
  /* 2,000 answers of ~60 bytes each would be 120 KB; the journal stayed small */
  ASSERT(most < 8192);
  ASSERT_OK(fg_idem_update(s, "long", 200, "{\"final\":true}"));
  fg_idem_free(s);
  s = store_open(0, 64 << 10);
  char *got = replay(s, "long", BODY, &status);
  ASSERT_EQ(status, 200);
  ASSERT_STREQ(got, "{\"final\":true}");
  free(got);
  fg_idem_free(s);

  /* expired keys leave the journal at its next compaction */
  store_reset();
  s = store_open(0, 64 << 10);
  char key[16];
  for (int i = 0; i < 100; i++) {
    snprintf(key, sizeof key, "old%d", i);
    ASSERT_EQ(begin(s, key, BODY, &status), FG_IDEM_NEW);
    ASSERT_OK(fg_idem_finish(s, key, 200, "{}"));
  }
  size_t before;
  fg_idem_stats(s, &keys, &before);
  clock_s += 24 * 3600 + 1;
  ASSERT_EQ(begin(s, "new", BODY, &status), FG_IDEM_NEW);
  fg_idem_stats(s, &keys, &bytes);
  ASSERT_EQ(keys, 1u);
  ASSERT(bytes < before / 4);
  fg_idem_free(s);
}

/* Appends raw bytes to the journal, as a write cut short by a crash leaves them. */
static void journal_append(const char *bytes) {
  int fd = open(journal, O_WRONLY | O_APPEND);
  ASSERT(fd >= 0);
  ASSERT_EQ(write(fd, bytes, strlen(bytes)), (ssize_t)strlen(bytes));
  close(fd);
}

static void test_torn_line(void) {
  store_reset();
  fg_idem *s = store_open(0, 0);
  int status = 0;
  ASSERT_EQ(begin(s, "whole", BODY, &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "whole", 200, "{\"whole\":1}"));
  fg_idem_free(s);
  journal_append("{\"op\":\"take\",\"key\":\"half\",\"kind\":\"ca");
  s = store_open(0, 0);
  char *answer = replay(s, "whole", BODY, &status);
  ASSERT_STREQ(answer, "{\"whole\":1}");
  free(answer);
  /* the half line was not a take (its request never ran), and is gone from the file, so
   * that the next lines do not land behind it */
  ASSERT_EQ(begin(s, "half", BODY, &status), FG_IDEM_NEW);
  ASSERT_OK(fg_idem_finish(s, "half", 200, "{}"));
  fg_idem_free(s);
  s = store_open(0, 0);
  ASSERT_EQ(begin(s, "half", BODY, &status), FG_IDEM_REPLAY);
  fg_idem_free(s);

  /* a malformed line with more after it is not a crash's doing: refused */
  journal_append("garbage\n{\"op\":\"cancel\",\"key\":\"half\"}\n");
  fg_idem *bad = NULL;
  ASSERT_ERR(fg_idem_open(&bad, tmpdir, NULL), FG_EFORMAT, "malformed");
}

/* sha256sum of the path, a NUL and the body, computed outside the daemon's code. */
static void raw_digest(const char *body, char out[65]) {
  char cmd[512];
  snprintf(cmd, sizeof cmd, "printf '%%s\\0%%s' '%s' '%s' | sha256sum", PATH, body);
  FILE *p = popen(cmd, "r");
  ASSERT(p && fscanf(p, "%64s", out) == 1);
  pclose(p);
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

static void test_migration(void) {
  store_reset();
  char sha[65], text[1024];
  raw_digest(BODY, sha);
  const uint64_t h = fnv(PATH, strlen(PATH)) ^ fnv(BODY, strlen(BODY)) * 31;
  snprintf(text, sizeof text, "{\"version\":2,\"keys\":["
           "{\"key\":\"v2\",\"sha256\":\"%s\",\"status\":200,\"body\":\"{\\\"v2\\\":1}\","
           "\"created\":%lld},"
           "{\"key\":\"v1\",\"hash\":\"%016" PRIx64 "\",\"status\":200,\"body\":\"{}\","
           "\"created\":%lld},"
           "{\"key\":\"cut\",\"sha256\":\"%s\",\"status\":0,\"body\":null,\"created\":%lld}]}",
           sha, (long long)clock_s, h, (long long)clock_s, sha, (long long)clock_s);
  ASSERT_OK(fg_write_file_atomic(legacy, text, strlen(text)));
  fg_idem *s = store_open(0, 0);
  ASSERT_EQ(access(legacy, F_OK), -1); /* its keys are in the journal now */
  int status = 0;
  for (int round = 0; round < 2; round++) {
    char *answer = replay(s, "v2", BODY, &status);
    ASSERT_STREQ(answer, "{\"v2\":1}");
    free(answer);
    /* an old key knew its request by the bytes: those bytes still match */
    ASSERT_EQ(begin(s, "v2", OTHER, &status), FG_IDEM_CONFLICT);
    ASSERT_EQ(begin(s, "v1", BODY, &status), FG_IDEM_REPLAY);
    ASSERT_EQ(begin(s, "v1", OTHER, &status), FG_IDEM_CONFLICT);
    ASSERT_EQ(begin(s, "cut", BODY, &status), FG_IDEM_REPLAY);
    ASSERT_EQ(status, 504);
    fg_idem_free(s);
    s = store_open(0, 0); /* and again from the journal */
  }
  fg_idem_free(s);

  /* a malformed legacy file is an error, not dropped */
  store_reset();
  const char *bad[] = {
      "{\"version\":2,\"keys\":[{\"key\":\"a\",\"sha256\":\"12ab\",\"status\":200,"
      "\"body\":\"{}\",\"created\":1}]}",
      "{\"version\":2,\"keys\":[{\"key\":\"a\",\"hash\":\"12ab\",\"sha256\":\"12ab\","
      "\"status\":200,\"body\":\"{}\",\"created\":1}]}",
  };
  for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
    ASSERT_OK(fg_write_file_atomic(legacy, bad[i], strlen(bad[i])));
    ASSERT_ERR(fg_idem_open(&s, tmpdir, NULL), FG_EFORMAT, "malformed");
  }
  unlink(legacy);
}

int main(void) {
  ASSERT(mkdtemp(tmpdir));
  journal = fg_path_join(tmpdir, "idempotency.journal");
  legacy = fg_path_join(tmpdir, "idempotency.json");
  test_canonical_request();
  test_peek_does_not_take();
  test_journal_replay();
  test_expiry_by_age();
  test_cap();
  test_compaction();
  test_torn_line();
  test_migration();
  free(journal);
  free(legacy);
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("idem: ok\n");
  return 0;
}
