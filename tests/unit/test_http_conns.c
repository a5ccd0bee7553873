/* The HTTP layer's connection table (daemon/http/http_conns.h) on socket pairs: shedding the
 * oldest idle connection at the cap (never a busy one, never the newcomer), the header and
 * keep-alive deadlines, and the body-rate floor, each seen as the peer's end of the socket
 * reading end-of-file. Times are given, not waited for. */
#include "http/http_conns.h"

#include "core/error.h"
#include "test.h"

#include <errno.h>
#include <fcntl.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

typedef struct pair {
  int server, client; /* the table holds server; client sees what the table did */
} pair;

static pair pair_new(void) {
  int sv[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  ASSERT_EQ(fcntl(sv[1], F_SETFL, O_NONBLOCK), 0);
  return (pair){sv[0], sv[1]};
}

static void pair_close(pair *p) {
  close(p->server);
  close(p->client);
}

/* 1 when the table shut p's server end down (the client reads end-of-file), 0 while it is
 * open (the read would block). */
static int is_shut(const pair *p) {
  char b;
  ssize_t n = read(p->client, &b, 1);
  if (n == 0) return 1;
  ASSERT(n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK));
  return 0;
}

static const fg_conns_limits lim = {.header_timeout_s = 10, .idle_timeout_s = 60,
                                    .min_body_bytes_per_s = 1000};

static void test_shed(void) {
  fg_conns *t;
  ASSERT_OK(fg_conns_new(&t, 3));
  pair p[6];
  fg_conn *c[6];
  int shed = -1;
  for (int i = 0; i < 3; i++) {
    p[i] = pair_new();
    c[i] = fg_conns_open(t, p[i].server, 100.0 + i, &shed);
    ASSERT(c[i] != NULL);
    ASSERT_EQ(shed, 0);
  }
  /* The oldest one is busy with a request: the next oldest idle one goes. */
  fg_conns_request_begin(t, c[0], 103.0);
  p[3] = pair_new();
  c[3] = fg_conns_open(t, p[3].server, 104.0, &shed);
  ASSERT_EQ(shed, 1);
  ASSERT_EQ(is_shut(&p[0]), 0);
  ASSERT_EQ(is_shut(&p[1]), 1);
  ASSERT_EQ(is_shut(&p[2]), 0);
  ASSERT_EQ(is_shut(&p[3]), 0);
  ASSERT_EQ(fg_conns_count(t), 4); /* shut, its close not reported yet */
  fg_conns_close(t, c[1]);
  ASSERT_EQ(fg_conns_count(t), 3);

  /* A connection kept alive after its answer is idle from then on: the newest idle one, so
   * c[2] (idle since 102) goes before c[0] (idle since 105). */
  fg_conns_request_ready(t, c[0]);
  fg_conns_request_end(t, c[0], 105.0);
  p[4] = pair_new();
  c[4] = fg_conns_open(t, p[4].server, 106.0, &shed);
  ASSERT_EQ(shed, 1);
  ASSERT_EQ(is_shut(&p[2]), 1);
  ASSERT_EQ(is_shut(&p[0]), 0);
  fg_conns_close(t, c[2]);

  /* Every other connection busy: the newcomer is not shed for itself (the server's own
   * hard limit is the backstop). */
  fg_conns_request_begin(t, c[0], 107.0);
  fg_conns_request_begin(t, c[3], 107.0);
  fg_conns_request_begin(t, c[4], 107.0);
  p[5] = pair_new();
  c[5] = fg_conns_open(t, p[5].server, 108.0, &shed);
  ASSERT_EQ(shed, 0);
  ASSERT_EQ(is_shut(&p[5]), 0);
  ASSERT_EQ(fg_conns_count(t), 4);

  for (int i = 0; i < 6; i++) {
    if (i != 1 && i != 2) fg_conns_close(t, c[i]);
    pair_close(&p[i]);
  }
  ASSERT_EQ(fg_conns_count(t), 0);
  fg_conns_free(t);
}

static void test_deadlines(void) {
  fg_conns *t;
  ASSERT_OK(fg_conns_new(&t, 100));
  pair silent = pair_new(), kept = pair_new(), slow = pair_new(), fast = pair_new(),
       busy = pair_new();
  fg_conn *c_silent = fg_conns_open(t, silent.server, 0.0, NULL);
  fg_conn *c_kept = fg_conns_open(t, kept.server, 0.0, NULL);
  fg_conn *c_slow = fg_conns_open(t, slow.server, 0.0, NULL);
  fg_conn *c_fast = fg_conns_open(t, fast.server, 0.0, NULL);
  fg_conn *c_busy = fg_conns_open(t, busy.server, 0.0, NULL);
  fg_conns_request_begin(t, c_kept, 1.0);
  fg_conns_request_ready(t, c_kept);
  fg_conns_request_end(t, c_kept, 2.0);
  fg_conns_request_begin(t, c_slow, 1.0);
  fg_conns_request_begin(t, c_fast, 1.0);
  fg_conns_request_begin(t, c_busy, 1.0);
  fg_conns_request_ready(t, c_busy);

  size_t closed[FG_CONN_REASONS] = {0};
  /* At 10 s nobody is late: the headers had until 10 s, bodies owe nothing before 11 s. */
  ASSERT_EQ(fg_conns_sweep(t, &lim, 10.0, closed), 0);
  /* At 12 s the silent one is past its headers' deadline; the bodies owe 1000 bytes each. */
  fg_conns_body(t, c_slow, 999);
  fg_conns_body(t, c_fast, 1001);
  ASSERT_EQ(fg_conns_sweep(t, &lim, 12.0, closed), 2);
  ASSERT_EQ(closed[FG_CONN_HEADER_TIMEOUT], 1);
  ASSERT_EQ(closed[FG_CONN_BODY_TOO_SLOW], 1);
  ASSERT_EQ(is_shut(&silent), 1);
  ASSERT_EQ(is_shut(&slow), 1);
  ASSERT_EQ(is_shut(&fast), 0);
  /* Shut once: a later sweep does not count them again. */
  fg_conns_body(t, c_fast, 1000000);
  ASSERT_EQ(fg_conns_sweep(t, &lim, 13.0, closed), 0);
  /* The kept-alive one has until 2 + 60 s for its next request; the busy one has no
   * deadline here (the server's idle timeout covers a silent client). */
  ASSERT_EQ(fg_conns_sweep(t, &lim, 62.0, closed), 0);
  ASSERT_EQ(fg_conns_sweep(t, &lim, 62.5, closed), 1);
  ASSERT_EQ(closed[FG_CONN_IDLE_TIMEOUT], 1);
  ASSERT_EQ(is_shut(&kept), 1);
  ASSERT_EQ(is_shut(&busy), 0);
  ASSERT_EQ(is_shut(&fast), 0);
  /* With no rate floor a dripping body is left to the idle timeout. */
  fg_conns_limits no_floor = lim;
  no_floor.min_body_bytes_per_s = 0;
  fg_conns_request_begin(t, c_busy, 100.0);
  ASSERT_EQ(fg_conns_sweep(t, &no_floor, 1100.0, closed), 0);
  ASSERT_EQ(fg_conns_sweep(t, &lim, 1100.0, closed), 2); /* busy (receiving now) and fast */

  fg_conns_close(t, c_silent);
  fg_conns_close(t, c_kept);
  fg_conns_close(t, c_slow);
  fg_conns_close(t, c_fast);
  /* c_busy is left in the table: fg_conns_free frees it. */
  fg_conns_free(t);
  pair_close(&silent);
  pair_close(&kept);
  pair_close(&slow);
  pair_close(&fast);
  pair_close(&busy);
}

int main(void) {
  test_shed();
  test_deadlines();
  fg_conns_free(NULL);
  fg_conns_close(NULL, NULL); /* untracked connections are fine */
  printf("http_conns: ok\n");
  return 0;
}
