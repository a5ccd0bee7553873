/* Unit tests of daemon/decoder: images and depth images decoded by fieldgrip-decode children
 * give the same floats as fg_image_decode and fg_depth_decode in process, errors come back
 * with the child's detail, a child
 * that crashes or is killed is replaced, the pool stays within max_procs under concurrent
 * use, idle children are reaped, and fg_decoder_free leaves no process behind. Children run
 * confined (rlimits, no_new_privs, the system call filter); an image past the CPU or memory
 * limit is an error, not a crash of the caller, and the installed program has no test hooks.
 * argv[1] is the test build fieldgrip-decode-test (with the hooks), argv[2] the installed
 * fieldgrip-decode. */
#include "test.h"

#include "config.h"
#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "decoder/decoder.h"
#include "io/depth.h"
#include "io/image.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <signal.h>
#include <stdint.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static const char *program;  /* with the test hooks */
static const char *shipped;  /* as installed */

/* The crash and hang hooks of decode_main.c are armed with these prefixes. */
#define CRASH_MAGIC "FG-CRASH-TEST"
#define HANG_MAGIC "FG-HANG-TEST"

enum { W = 61, H = 37 };

/* An 8-bit RGBA PNG with every alpha from transparent to opaque, so compositing on the
 * background is exercised. The caller frees *png. */
static void make_rgba_png(uint8_t **png, size_t *len) {
  static uint8_t px[H][W][4];
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      px[y][x][0] = (uint8_t)(x * 4);
      px[y][x][1] = (uint8_t)(y * 7);
      px[y][x][2] = (uint8_t)((x * y) % 256);
      px[y][x][3] = (uint8_t)((x * 31 + y * 17) % 256);
    }
  ASSERT_OK(fg_image_encode_png(px, W, H, 4, 8, png, len));
}

static int process_exists(pid_t pid) {
  char path[64];
  snprintf(path, sizeof path, "/proc/%d", (int)pid);
  return access(path, F_OK) == 0;
}

static void assert_same_image(const fg_image *a, const fg_image *b) {
  ASSERT_EQ(a->w, b->w);
  ASSERT_EQ(a->h, b->h);
  ASSERT(memcmp(a->rgb, b->rgb, (size_t)a->w * (size_t)a->h * 3 * sizeof(float)) == 0);
}

static void test_same_pixels(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  const float bg[3] = {0.2f, 0.5f, 0.9f};
  fg_image direct, via;
  ASSERT_OK(fg_image_decode(png, len, bg, &direct));
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 2, 30));
  ASSERT_OK(fg_decoder_check(d));
  ASSERT_OK(fg_decoder_decode(d, png, len, bg, &via));
  assert_same_image(&direct, &via);
  fg_image_release(&via);
  /* A second request goes to the same child. */
  pid_t pids[4];
  ASSERT_EQ(fg_decoder_child_pids(d, pids, 4), 1);
  ASSERT_OK(fg_decoder_decode(d, png, len, bg, &via));
  assert_same_image(&direct, &via);
  pid_t again[4];
  ASSERT_EQ(fg_decoder_child_pids(d, again, 4), 1);
  ASSERT_EQ(again[0], pids[0]);
  fg_image_release(&via);
  /* A NULL background means white, as for fg_image_decode. */
  fg_image_release(&direct);
  ASSERT_OK(fg_image_decode(png, len, NULL, &direct));
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &via));
  assert_same_image(&direct, &via);
  fg_image_release(&via);
  fg_image_release(&direct);
  fg_decoder_free(d);
  free(png);
}

static void test_errors(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 1, 30));
  fg_image img;

  /* Truncated: same code and the very detail fg_image_decode gives. */
  ASSERT_ERR(fg_image_decode(png, len / 2, NULL, &img), FG_EFORMAT, "truncated");
  char direct[1024];
  snprintf(direct, sizeof direct, "%s", fg_error_detail());
  fg_error_clear();
  ASSERT_ERR(fg_decoder_decode(d, png, len / 2, NULL, &img), FG_EFORMAT, "truncated");
  ASSERT_STREQ(fg_error_detail(), direct);
  ASSERT(img.rgb == NULL);

  /* Random bytes, and nothing at all. */
  uint8_t noise[777];
  uint32_t s = 12345;
  for (size_t i = 0; i < sizeof noise; i++) {
    s = s * 1664525u + 1013904223u;
    noise[i] = (uint8_t)(s >> 24);
  }
  noise[0] = 0x42; /* no magic byte of a supported format */
  ASSERT_ERR(fg_decoder_decode(d, noise, sizeof noise, NULL, &img), FG_EFORMAT, "supported");
  ASSERT_ERR(fg_decoder_decode(d, noise, 0, NULL, &img), FG_EFORMAT, "empty");
  /* PNG magic on noise reaches the codec, and OpenImageIO's failure comes back. */
  memcpy(noise, "\x89PNG\r\n\x1a\n", 8);
  ASSERT_ERR(fg_decoder_decode(d, noise, sizeof noise, NULL, &img), FG_EFORMAT, "PNG");

  /* The child survived all of that. */
  pid_t pids[2];
  ASSERT_EQ(fg_decoder_child_pids(d, pids, 2), 1);
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  pid_t again[2];
  ASSERT_EQ(fg_decoder_child_pids(d, again, 2), 1);
  ASSERT_EQ(again[0], pids[0]);
  fg_decoder_free(d);
  free(png);
}

/* A 16-bit depth PNG in millimetres, with zeros (no reading) and the extremes. The caller
 * frees *png. */
static void make_depth_png(uint8_t **png, size_t *len) {
  static uint16_t mm[H][W];
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) mm[y][x] = (uint16_t)((x * 977 + y * 1783) % 65536);
  mm[0][0] = 0;
  mm[1][2] = 65535;
  mm[H - 1][W - 1] = 0;
  ASSERT_OK(fg_image_encode_png(mm, W, H, 1, 16, png, len));
}

static void test_depth(void) {
  uint8_t *png;
  size_t len;
  make_depth_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 1, 30));
  /* The same metres as in process, for both common scales. */
  static const double scales[2] = {0.001, 0.0001};
  for (int i = 0; i < 2; i++) {
    fg_depth_map direct, via;
    ASSERT_OK(fg_depth_decode(png, len, scales[i], &direct));
    ASSERT_OK(fg_decoder_decode_depth(d, png, len, scales[i], &via));
    ASSERT_EQ(via.w, W);
    ASSERT_EQ(via.h, H);
    ASSERT(memcmp(direct.m, via.m, (size_t)W * H * sizeof(float)) == 0);
    ASSERT(via.m[0] == 0 && via.m[1 * W + 2] == (float)(65535 * scales[i]));
    fg_depth_release(&direct);
    fg_depth_release(&via);
  }
  pid_t pids[2];
  ASSERT_EQ(fg_decoder_child_pids(d, pids, 2), 1);

  /* Refusals come back with the very detail fg_depth_decode gives, and the child lives. */
  static uint8_t grey8[H][W];
  uint8_t *png8;
  size_t len8;
  ASSERT_OK(fg_image_encode_png(grey8, W, H, 1, 8, &png8, &len8));
  static const struct {
    int cut, code;
    double scale;
    const char *says;
  } cases[] = {
      {0, FG_EINVAL, 0.001, "depth PNG is 8-bit"},  /* the 8-bit PNG */
      {1, FG_EINVAL, NAN, "depth scale is nan"},   /* the 16-bit PNG from here on */
      {1, FG_EINVAL, 0, "depth scale is 0"},
      {2, FG_EFORMAT, 0.001, "truncated"},
  };
  for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
    const uint8_t *b = cases[k].cut == 0 ? png8 : png;
    size_t n = cases[k].cut == 0 ? len8 : cases[k].cut == 1 ? len : len / 2;
    fg_depth_map m;
    ASSERT_ERR(fg_depth_decode(b, n, cases[k].scale, &m), cases[k].code, cases[k].says);
    char direct[1024];
    snprintf(direct, sizeof direct, "%s", fg_error_detail());
    fg_error_clear();
    ASSERT_ERR(fg_decoder_decode_depth(d, b, n, cases[k].scale, &m), cases[k].code,
               cases[k].says);
    ASSERT_STREQ(fg_error_detail(), direct);
    ASSERT(m.m == NULL && m.w == 0);
  }
  /* A colour image is refused as depth, and decodes as an image on the same child. */
  uint8_t *rgba;
  size_t rgba_len;
  make_rgba_png(&rgba, &rgba_len);
  fg_depth_map m;
  ASSERT_ERR(fg_decoder_decode_depth(d, rgba, rgba_len, 0.001, &m), FG_EINVAL,
             "looks like a colour image");
  fg_image img;
  ASSERT_OK(fg_decoder_decode(d, rgba, rgba_len, NULL, &img));
  fg_image_release(&img);
  pid_t again[2];
  ASSERT_EQ(fg_decoder_child_pids(d, again, 2), 1);
  ASSERT_EQ(again[0], pids[0]);

  /* A child that crashes on a depth image: FG_EFORMAT, and the next one gets a new child. */
  static const char hostile[] = CRASH_MAGIC " in place of a depth image";
  ASSERT_ERR(fg_decoder_decode_depth(d, hostile, sizeof hostile, 0.001, &m), FG_EFORMAT,
             "the image decoder stopped on this depth image (killed by signal 6)");
  ASSERT(m.m == NULL);
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  ASSERT_OK(fg_decoder_decode_depth(d, png, len, 0.001, &m));
  fg_depth_release(&m);
  ASSERT_ERR(fg_decoder_decode_depth(NULL, png, len, 0.001, &m), FG_EINVAL, "no decoder");
  fg_decoder_free(d);
  free(rgba);
  free(png8);
  free(png);
}

static void test_crash_and_kill(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 1, 30));
  fg_image img;
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  pid_t first;
  ASSERT_EQ(fg_decoder_child_pids(d, &first, 1), 1);

  /* A child that crashes on an image: FG_EFORMAT naming the signal, the child is gone. */
  static const char hostile[] = CRASH_MAGIC " and then whatever would have crashed a codec";
  ASSERT_ERR(fg_decoder_decode(d, hostile, sizeof hostile, NULL, &img), FG_EFORMAT,
             "the image decoder stopped on this image (killed by signal 6)");
  ASSERT_STRCONTAINS(fg_error_detail(), "corrupt or hostile");
  ASSERT(img.rgb == NULL);
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  ASSERT(!process_exists(first));

  /* The next image gets a fresh child. */
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  pid_t second;
  ASSERT_EQ(fg_decoder_child_pids(d, &second, 1), 1);
  ASSERT_NE(second, first);

  /* A child killed while idle is not the next image's fault: it is replaced silently. */
  ASSERT_EQ(kill(second, SIGKILL), 0);
  /* Until it is wholly dead (all its threads gone, so its pipes are closed), without reaping
   * it: that stays the decoder's job. */
  siginfo_t si;
  ASSERT_EQ(waitid(P_PID, (id_t)second, &si, WEXITED | WNOWAIT), 0);
  ASSERT_EQ(si.si_status, SIGKILL);
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  pid_t third;
  ASSERT_EQ(fg_decoder_child_pids(d, &third, 1), 1);
  ASSERT_NE(third, second);
  ASSERT(!process_exists(second)); /* reaped, not left a zombie */
  fg_decoder_free(d);
  ASSERT(!process_exists(third));
  free(png);
}

typedef struct worker {
  fg_decoder *d;
  const uint8_t *png;
  size_t len;
  const fg_image *expect;
  int failures;
} worker;

static void *worker_main(void *arg) {
  worker *w = arg;
  static const char bad[] = "not an image";
  for (int i = 0; i < 12; i++) {
    fg_image img;
    if (i % 4 == 3) { /* errors travel per thread */
      if (fg_decoder_decode(w->d, bad, sizeof bad, NULL, &img) != FG_EFORMAT ||
          !strstr(fg_error_detail(), "unrecognised"))
        w->failures++;
      continue;
    }
    if (fg_decoder_decode(w->d, w->png, w->len, NULL, &img) != 0) {
      fprintf(stderr, "decode failed: %s\n", fg_error_detail());
      w->failures++;
      continue;
    }
    if (img.w != w->expect->w || img.h != w->expect->h ||
        memcmp(img.rgb, w->expect->rgb, (size_t)img.w * (size_t)img.h * 3 * sizeof(float)) != 0)
      w->failures++;
    fg_image_release(&img);
  }
  return NULL;
}

static void test_concurrent(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_image expect;
  ASSERT_OK(fg_image_decode(png, len, NULL, &expect));
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 2, 30));
  enum { N = 8 };
  pthread_t th[N];
  worker w[N];
  for (int i = 0; i < N; i++) {
    w[i] = (worker){.d = d, .png = png, .len = len, .expect = &expect};
    ASSERT_EQ(pthread_create(&th[i], NULL, worker_main, &w[i]), 0);
  }
  for (int i = 0; i < N; i++) {
    pthread_join(th[i], NULL);
    ASSERT_EQ(w[i].failures, 0);
  }
  size_t n = fg_decoder_child_pids(d, NULL, 0);
  ASSERT(n >= 1 && n <= 2);
  /* The children outlive the threads that happened to need them first. */
  fg_image img;
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  fg_decoder_free(d);
  fg_image_release(&expect);
  free(png);
}

/* The reaper runs while children start: a child just started is busy from its start, never
 * an overrun of the busy limit (a start time of 0 once read as 60 s made the reaper kill
 * children before their first image). */
typedef struct reaper {
  fg_decoder *d;
  atomic_int stop;
} reaper;

static void *reaper_main(void *arg) {
  reaper *r = arg;
  while (!atomic_load(&r->stop)) fg_decoder_reap_idle(r->d);
  return NULL;
}

static void test_reap_while_starting(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  for (int i = 0; i < 20; i++) {
    reaper r = {0};
    ASSERT_OK(fg_decoder_new(&r.d, program, 1, 30));
    pthread_t th;
    ASSERT_EQ(pthread_create(&th, NULL, reaper_main, &r), 0);
    fg_image img;
    const int rc = fg_decoder_decode(r.d, png, len, NULL, &img);
    atomic_store(&r.stop, 1);
    pthread_join(th, NULL);
    if (rc != 0) FG_TEST_FAIL("start %d: %s", i, fg_error_detail());
    fg_image_release(&img);
    fg_decoder_free(r.d);
  }
  free(png);
}

static void test_reap_idle(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 2, 1));
  fg_image img;
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  const double used_s = fg_mono_s();
  fg_image_release(&img);
  pid_t pid;
  ASSERT_EQ(fg_decoder_child_pids(d, &pid, 1), 1);
  fg_decoder_reap_idle(d); /* just used: stays (unless this thread was held up for 1 s) */
  if (fg_mono_s() - used_s < 1.0) ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 1);
  struct timespec wait = {1, 300000000};
  nanosleep(&wait, NULL);
  fg_decoder_reap_idle(d);
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  ASSERT(!process_exists(pid));
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  pid_t again;
  ASSERT_EQ(fg_decoder_child_pids(d, &again, 1), 1);
  ASSERT_NE(again, pid);
  fg_decoder_free(d);
  ASSERT(!process_exists(again));
  free(png);
}

typedef struct hang_call {
  fg_decoder *d;
  int rc;
  char detail[512];
  volatile int done;
} hang_call;

static void *decode_hanging(void *arg) {
  hang_call *h = arg;
  static const char stuck[] = HANG_MAGIC " and then a codec that never returns";
  fg_image img;
  h->rc = fg_decoder_decode(h->d, stuck, sizeof stuck, NULL, &img);
  snprintf(h->detail, sizeof h->detail, "%s", fg_error_detail());
  h->done = 1;
  return NULL;
}

/* A child stuck on one image is killed once it passes the busy limit; the request fails
 * with a sentence that says so, and the pool goes on with a new child. */
static void test_busy_limit(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 1, 30));
  fg_decoder_set_busy_limit(d, 1);
  hang_call h = {.d = d};
  pthread_t t;
  ASSERT_EQ(pthread_create(&t, NULL, decode_hanging, &h), 0);
  for (int i = 0; i < 100 && !h.done; i++) { /* the daemon's main loop ticks like this */
    struct timespec tick = {0, 100000000};
    nanosleep(&tick, NULL);
    fg_decoder_reap_idle(d);
  }
  pthread_join(t, NULL);
  ASSERT_EQ(h.rc, FG_EFORMAT);
  ASSERT_STRCONTAINS(h.detail, "took longer than 1 s");
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  fg_image img;
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  fg_decoder_free(d);
  free(png);
}

static void test_free_leaves_nothing(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 3, 30));
  enum { N = 3 };
  pthread_t th[N];
  worker w[N];
  fg_image expect;
  ASSERT_OK(fg_image_decode(png, len, NULL, &expect));
  for (int i = 0; i < N; i++) {
    w[i] = (worker){.d = d, .png = png, .len = len, .expect = &expect};
    ASSERT_EQ(pthread_create(&th[i], NULL, worker_main, &w[i]), 0);
  }
  for (int i = 0; i < N; i++) pthread_join(th[i], NULL);
  pid_t pids[8];
  size_t n = fg_decoder_child_pids(d, pids, 8);
  ASSERT(n >= 1 && n <= 3);
  fg_decoder_free(d);
  for (size_t i = 0; i < n; i++) ASSERT(!process_exists(pids[i]));
  /* Nothing left to wait for: no zombie and no child of ours at all. */
  ASSERT_EQ(waitpid(-1, NULL, WNOHANG), -1);
  ASSERT_EQ(errno, ECHILD);
  fg_decoder_free(NULL);
  fg_image_release(&expect);
  free(png);
}

static void test_missing_program(void) {
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, "/nonexistent/fieldgrip-decode", 1, 30));
  ASSERT_ERR(fg_decoder_check(d), FG_ENOENT, "/nonexistent/fieldgrip-decode");
  fg_image img;
  ASSERT_ERR(fg_decoder_decode(d, "\x89PNG", 4, NULL, &img), FG_ENOENT,
             "/nonexistent/fieldgrip-decode is missing");
  fg_decoder_free(d);
  /* The default places: beside this test (not there) and the install folder. */
  ASSERT_OK(fg_decoder_new(&d, NULL, 1, 30));
  if (access(FG_LIBEXECDIR "/fieldgrip/fieldgrip-decode", X_OK) != 0) {
    ASSERT_ERR(fg_decoder_check(d), FG_ENOENT, FG_LIBEXECDIR "/fieldgrip/fieldgrip-decode");
    ASSERT_STRCONTAINS(fg_error_detail(), "tests/unit/fieldgrip-decode");
  }
  fg_decoder_free(d);
  ASSERT_ERR(fg_decoder_new(&d, program, 0, 30), FG_EINVAL, "max_procs");
  ASSERT(d == NULL);
}

/* Writes an executable shell script that stands in for fieldgrip-decode. */
static void write_script(const char *path, const char *body) {
  FILE *f = fopen(path, "w");
  ASSERT(f != NULL);
  fprintf(f, "#!/bin/sh\n%s\n", body);
  ASSERT_EQ(fclose(f), 0);
  ASSERT_EQ(chmod(path, 0755), 0);
}

/* Programs that answer wrongly: another protocol version is the installation's fault
 * (FG_EIO), a malformed reply is treated like a crash (FG_EFORMAT). */
static void test_impostors(void) {
  char dir[] = "/tmp/fg-test-decoder-XXXXXX";
  ASSERT(mkdtemp(dir) != NULL);
  char old[64], junk[64];
  snprintf(old, sizeof old, "%s/old", dir);
  snprintf(junk, sizeof junk, "%s/junk", dir);
  /* Each script waits for the first byte of its request: one that answered and exited at once
   * could be gone before the request is written, which is the "died while idle" case.
   * old: a reply header of version 1 (a fieldgrip-decode from before depth): "FGDR", 1,
   * then 24 zero bytes. */
  write_script(old,
               "head -c 1 >/dev/null; printf 'FGDR\\001\\000\\000\\000'; head -c 24 /dev/zero");
  write_script(junk,
               "head -c 1 >/dev/null; printf 'HTTP/1.1 200 OK\\r\\nContent-Length: 0\\r\\n\\r\\n'");
  fg_decoder *d;
  fg_image img;
  ASSERT_OK(fg_decoder_new(&d, old, 1, 30));
  ASSERT_ERR(fg_decoder_decode(d, "\x89PNG", 4, NULL, &img), FG_EIO, "protocol version 1");
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  fg_decoder_free(d);
  ASSERT_OK(fg_decoder_new(&d, junk, 1, 30));
  ASSERT_ERR(fg_decoder_decode(d, "\x89PNG", 4, NULL, &img), FG_EFORMAT,
             "the image decoder stopped on this image (exited with status 0)");
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  fg_decoder_free(d);
  ASSERT_EQ(unlink(old), 0);
  ASSERT_EQ(unlink(junk), 0);
  ASSERT_EQ(rmdir(dir), 0);
}

/* Talks to fieldgrip-decode directly: what it answers to a request it cannot accept. */
static void raw_exchange(const uint8_t *req, size_t req_len, int *rc, char *msg, size_t msglen,
                         int *status) {
  int in[2], out[2];
  ASSERT_EQ(pipe(in), 0);
  ASSERT_EQ(pipe(out), 0);
  pid_t pid = fork();
  ASSERT(pid >= 0);
  if (pid == 0) {
    dup2(in[0], 0);
    dup2(out[1], 1);
    close(in[0]), close(in[1]), close(out[0]), close(out[1]);
    execl(program, program, (char *)NULL);
    _exit(127);
  }
  close(in[0]);
  close(out[1]);
  ASSERT_EQ(fg_decoder_write_full(in[1], req, req_len), 0);
  close(in[1]);
  uint8_t hdr[FG_DECODER_REPLY_SIZE];
  ssize_t got = fg_decoder_read_full(out[0], hdr, sizeof hdr);
  *rc = 0;
  msg[0] = '\0';
  if (got == (ssize_t)sizeof hdr) {
    fg_decoder_reply rep;
    ASSERT_OK(fg_decoder_reply_unpack(hdr, &rep));
    *rc = rep.rc;
    ASSERT(rep.message_len < msglen);
    ASSERT_EQ(fg_decoder_read_full(out[0], msg, rep.message_len), rep.message_len);
    msg[rep.message_len] = '\0';
  } else {
    ASSERT_EQ(got, 0);
  }
  close(out[0]);
  ASSERT_EQ(waitpid(pid, status, 0), pid);
}

static void test_wire(void) {
  uint8_t req[FG_DECODER_REQUEST_SIZE];
  fg_decoder_request r = {.version = FG_DECODER_VERSION, .op = FG_DECODER_OP_DECODE,
                          .background = {0.25f, 0.5f, 1.0f}, .length = 123456789012ull};
  fg_decoder_request_pack(&r, req);
  ASSERT(memcmp(req, "FGDQ\x02\0\0\0\x01\0\0\0", 12) == 0);
  fg_decoder_request back;
  ASSERT_ERR(fg_decoder_request_unpack(req, &back), FG_EINVAL, "more than");
  ASSERT_EQ(back.length, 123456789012ull);
  ASSERT(back.background[0] == 0.25f && back.background[2] == 1.0f);
  r.length = 10;
  fg_decoder_request_pack(&r, req);
  ASSERT_OK(fg_decoder_request_unpack(req, &back));

  fg_decoder_reply rep = {.version = FG_DECODER_VERSION, .rc = 0, .w = 2, .h = 3,
                          .pixel_bytes = 2 * 3 * 12 + 4};
  uint8_t rb[FG_DECODER_REPLY_SIZE];
  fg_decoder_reply_pack(&rep, rb);
  fg_decoder_reply rback;
  ASSERT_ERR(fg_decoder_reply_unpack(rb, &rback), FG_EINVAL, "2x3");
  rep.pixel_bytes = 2 * 3 * 12;
  fg_decoder_reply_pack(&rep, rb);
  ASSERT_OK(fg_decoder_reply_unpack(rb, &rback));
  /* A depth reply carries one float per pixel, not three. */
  ASSERT_ERR(fg_decoder_reply_unpack_depth(rb, &rback), FG_EINVAL, "2x3");
  rep.pixel_bytes = 2 * 3 * 4;
  fg_decoder_reply_pack(&rep, rb);
  ASSERT_OK(fg_decoder_reply_unpack_depth(rb, &rback));

  /* A depth request: the op and the scale, bit for bit; no room for the scale is refused. */
  r.op = FG_DECODER_OP_DECODE_DEPTH;
  r.length = FG_DECODER_DEPTH_HEADER - 1;
  fg_decoder_request_pack(&r, req);
  ASSERT(memcmp(req + 8, "\x03\0\0\0", 4) == 0);
  ASSERT_ERR(fg_decoder_request_unpack(req, &back), FG_EINVAL, "no room for its 8-byte scale");
  r.length = FG_DECODER_DEPTH_HEADER;
  fg_decoder_request_pack(&r, req);
  ASSERT_OK(fg_decoder_request_unpack(req, &back));
  ASSERT_EQ(back.op, FG_DECODER_OP_DECODE_DEPTH);
  uint8_t dh[FG_DECODER_DEPTH_HEADER];
  fg_decoder_depth_header_pack(0.0001, dh);
  ASSERT(memcmp(dh, "\x2d\x43\x1c\xeb\xe2\x36\x1a\x3f", 8) == 0); /* 0.0001, little-endian */
  ASSERT(fg_decoder_depth_header_unpack(dh) == 0.0001);
  fg_decoder_depth_header_pack(NAN, dh);
  ASSERT(isnan(fg_decoder_depth_header_unpack(dh)));
  r.op = FG_DECODER_OP_DECODE;
  r.length = 10;
  fg_decoder_request_pack(&r, req);

  /* The program refuses a bad magic, a wrong version and an oversized image, and exits. */
  int rc, status;
  char msg[FG_DECODER_MAX_MESSAGE + 1];
  uint8_t bad[FG_DECODER_REQUEST_SIZE];
  memcpy(bad, req, sizeof bad);
  memcpy(bad, "GET ", 4);
  raw_exchange(bad, sizeof bad, &rc, msg, sizeof msg, &status);
  ASSERT_EQ(rc, FG_EINVAL);
  ASSERT_STRCONTAINS(msg, "magic");
  ASSERT(WIFEXITED(status) && WEXITSTATUS(status) != 0);
  r.version = 1; /* a daemon from before depth */
  fg_decoder_request_pack(&r, bad);
  raw_exchange(bad, sizeof bad, &rc, msg, sizeof msg, &status);
  ASSERT_EQ(rc, FG_EINVAL);
  ASSERT_STRCONTAINS(msg, "version 1");
  r.version = FG_DECODER_VERSION;
  r.length = FG_DECODER_MAX_REQUEST + 1;
  fg_decoder_request_pack(&r, bad);
  raw_exchange(bad, sizeof bad, &rc, msg, sizeof msg, &status);
  ASSERT_EQ(rc, FG_EINVAL);
  ASSERT_STRCONTAINS(msg, "more than");
  /* EOF before any request: a clean exit. */
  raw_exchange(bad, 0, &rc, msg, sizeof msg, &status);
  ASSERT(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

/* ---- confinement ------------------------------------------------------------------------ */

/* The line of /proc/PID/FILE that starts with key, or "" (static). */
static const char *proc_line(pid_t pid, const char *file, const char *key) {
  static char line[512];
  char path[64];
  snprintf(path, sizeof path, "/proc/%d/%s", (int)pid, file);
  FILE *f = fopen(path, "r");
  ASSERT(f);
  int found = 0;
  while (!found && fgets(line, sizeof line, f)) found = strncmp(line, key, strlen(key)) == 0;
  fclose(f);
  if (!found) line[0] = '\0';
  return line;
}

/* A live child of the installed program runs with the limits of decoder.h. */
static void test_child_limits(void) {
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, shipped, 1, 30));
  fg_image img;
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  pid_t pid;
  ASSERT_EQ(fg_decoder_child_pids(d, &pid, 1), 1);
  ASSERT_STRCONTAINS(proc_line(pid, "status", "NoNewPrivs:"), "1");
  /* the system call filter (decode_seccomp.h): one more than this process runs under */
  int filters = -1, ours = -1;
  const char *line = proc_line(pid, "status", "Seccomp_filters:");
  ASSERT(sscanf(line, "Seccomp_filters: %d", &filters) == 1);
  line = proc_line(getpid(), "status", "Seccomp_filters:");
  ASSERT(sscanf(line, "Seccomp_filters: %d", &ours) == 1);
  ASSERT_EQ(filters, ours + 1);
  unsigned long long soft, hard;
  const char *core = proc_line(pid, "limits", "Max core file size");
  ASSERT(sscanf(core + 26, "%llu %llu", &soft, &hard) == 2 && soft == 0 && hard == 0);
  const char *files = proc_line(pid, "limits", "Max open files");
  ASSERT(sscanf(files + 26, "%llu %llu", &soft, &hard) == 2);
  ASSERT_EQ(soft, FG_DECODER_MAX_FDS);
  ASSERT_EQ(hard, FG_DECODER_MAX_FDS);
  const char *cpu = proc_line(pid, "limits", "Max cpu time");
  ASSERT(sscanf(cpu + 26, "%llu", &soft) == 1 && soft >= FG_DECODER_CPU_SECONDS &&
         soft < FG_DECODER_CPU_SECONDS + 60);
#if !defined(__SANITIZE_ADDRESS__)
  const char *as = proc_line(pid, "limits", "Max address space");
  ASSERT(sscanf(as + 26, "%llu", &soft) == 1);
  ASSERT_EQ(soft, FG_DECODER_MAX_ADDRESS_BYTES);
#endif
  /* the file size limit is off only when our stderr is a regular file (a log) */
  struct stat st;
  const char *fsize = proc_line(pid, "limits", "Max file size");
  if (fstat(2, &st) == 0 && !S_ISREG(st.st_mode))
    ASSERT(sscanf(fsize + 26, "%llu", &soft) == 1 && soft == 0);
  fg_decoder_free(d);
  free(png);
}

/* JPEG, OpenEXR and TIFF, as a phone or a render farm writes them, decode in a child of the
 * installed program to the same floats as in process: its system call filter leaves the
 * codecs' threads, plugins and reads alone. */
static void test_formats_under_filter(void) {
  enum { FW = 40, FH = 30 };
  static float px[FH * FW * 3];
  for (int i = 0; i < FW * FH * 3; i++) px[i] = (float)((i * 37) % 101) / 100.0f;
  char dir[] = "/tmp/fg-decoder-XXXXXX";
  ASSERT(mkdtemp(dir));
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, shipped, 1, 30));
  static const char *const names[] = {"a.jpg", "a.exr", "a.tif"};
  for (int i = 0; i < 3; i++) {
    char *path = fg_path_join(dir, names[i]);
    ASSERT(path);
    ASSERT_OK(fg_image_write_file(path, px, FW, FH, 3));
    char *bytes;
    size_t len;
    ASSERT_OK(fg_read_file(path, 1u << 24, &bytes, &len));
    fg_image direct, via;
    ASSERT_OK(fg_image_decode(bytes, len, NULL, &direct));
    ASSERT_OK(fg_decoder_decode(d, bytes, len, NULL, &via));
    ASSERT_EQ(via.w, FW);
    assert_same_image(&direct, &via);
    fg_image_release(&direct);
    fg_image_release(&via);
    free(bytes);
    unlink(path);
    free(path);
  }
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 1); /* one child did all three */
  fg_decoder_free(d);
  rmdir(dir);
}

/* The installed program ignores the hooks' variables (main sets them): a marker that would
 * crash the test build is an ordinary bad image to it. */
static void test_shipped_has_no_hooks(void) {
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, shipped, 1, 30));
  static const char hostile[] = CRASH_MAGIC " and then whatever would have crashed a codec";
  fg_image img;
  int rc = fg_decoder_decode(d, hostile, sizeof hostile, NULL, &img);
  ASSERT(rc < 0);
  if (strstr(fg_error_detail(), "stopped on"))
    FG_TEST_FAIL("the installed decoder crashed on the test marker: %s", fg_error_detail());
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 1); /* the child lives on */
  fg_decoder_free(d);
}

/* A request that spins past the CPU limit: the child is ended by SIGXCPU, the call fails
 * with FG_EFORMAT saying so, and the pool goes on. */
static void test_cpu_limit(void) {
  setenv("FG_DECODE_SPIN_ON", "FG-SPIN-TEST", 1);
  setenv("FG_DECODE_TEST_CPU_S", "1", 1);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 1, 30));
  static const char spin[] = "FG-SPIN-TEST and then a codec that loops";
  fg_image img;
  ASSERT_ERR(fg_decoder_decode(d, spin, sizeof spin, NULL, &img), FG_EFORMAT, "of CPU time");
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 0);
  uint8_t *png;
  size_t len;
  make_rgba_png(&png, &len);
  ASSERT_OK(fg_decoder_decode(d, png, len, NULL, &img));
  fg_image_release(&img);
  fg_decoder_free(d);
  free(png);
  unsetenv("FG_DECODE_SPIN_ON");
  unsetenv("FG_DECODE_TEST_CPU_S");
}

/* An image whose pixels do not fit into the child's address space: FG_ERANGE saying the
 * decoder ran out of memory, answered by the child (which lives on), not a crash. */
static void test_memory_limit(void) {
#if defined(__SANITIZE_ADDRESS__)
  printf("memory limit: not checked under AddressSanitizer (no RLIMIT_AS there)\n");
  return;
#endif
  enum { BW = 4096, BH = 4096 }; /* 192 MiB of float RGB */
  uint8_t *px = calloc((size_t)BW * BH, 3);
  ASSERT(px);
  uint8_t *big;
  size_t big_len;
  ASSERT_OK(fg_image_encode_png(px, BW, BH, 3, 8, &big, &big_len));
  free(px);
  setenv("FG_DECODE_TEST_AS_HEADROOM_MB", "96", 1);
  fg_decoder *d;
  ASSERT_OK(fg_decoder_new(&d, program, 1, 30));
  fg_image img;
  ASSERT_ERR(fg_decoder_decode(d, big, big_len, NULL, &img), FG_ERANGE, "ran out of memory");
  printf("memory limit: %s\n", fg_error_detail());
  ASSERT(img.rgb == NULL);
  ASSERT_EQ(fg_decoder_child_pids(d, NULL, 0), 1);
  fg_decoder_free(d);
  unsetenv("FG_DECODE_TEST_AS_HEADROOM_MB");
  free(big);
}

int main(int argc, char **argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: %s PATH-OF-fieldgrip-decode-test PATH-OF-fieldgrip-decode\n",
            argv[0]);
    return 2;
  }
  program = argv[1];
  shipped = argv[2];
  /* The crash test aborts a child on purpose; no core file for it. */
  struct rlimit nocore = {0, 0};
  setrlimit(RLIMIT_CORE, &nocore);
  setenv("FG_DECODE_CRASH_ON", CRASH_MAGIC, 1);
  setenv("FG_DECODE_HANG_ON", HANG_MAGIC, 1);
  test_wire();
  test_same_pixels();
  test_errors();
  test_depth();
  test_crash_and_kill();
  test_concurrent();
  test_reap_idle();
  test_reap_while_starting();
  test_busy_limit();
  test_free_leaves_nothing();
  test_missing_program();
  test_impostors();
  test_child_limits();
  test_formats_under_filter();
  test_shipped_has_no_hooks();
  test_cpu_limit();
  test_memory_limit();
  printf("decoder: all passed\n");
  return 0;
}
