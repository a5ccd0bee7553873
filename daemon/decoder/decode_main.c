/* fieldgrip-decode: decodes images and depth images (and encodes rendered ones to PNG) for
 * fieldgripd in a process of its own, so that the daemon never links OpenImageIO and a codec
 * crashing on a hostile image takes down only this child.
 * Reads requests on stdin and writes replies on stdout in the format decoder.h describes,
 * one at a time, until EOF on stdin. Not meant to be run by hand. Before the first request it
 * confines itself (sandbox(); the limits are listed in decoder.h).
 *
 * Test hooks, compiled only into the test build fieldgrip-decode-test (FG_DECODE_TEST_HOOKS),
 * never into the installed program: when the environment has FG_DECODE_CRASH_ON=<text>, a
 * request whose image starts with those bytes makes the program abort(), standing in for a
 * codec crash; with FG_DECODE_HANG_ON=<text> it sleeps instead, standing in for a codec stuck
 * in a loop; with FG_DECODE_SPIN_ON=<text> it spins on the CPU. FG_DECODE_TEST_CPU_S and
 * FG_DECODE_TEST_AS_HEADROOM_MB lower the CPU limit per request and the address space limit
 * (to the address space in use at start plus that headroom) so tests can reach them. */
#include "decoder.h"
#include "decode_seccomp.h"

#include "config.h"
#include "core/error.h"
#include "io/depth.h"
#include "io/image.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

/* Sends one reply: header, message, and when rc is 0 the data (already in wire order: float
 * RGB, the PNG, or float metres, as decoder.h lists them per op). */
static int send_reply(int fd, int rc, const char *message, int w, int h, const void *data,
                      size_t data_len) {
  size_t mlen = strlen(message);
  if (mlen > FG_DECODER_MAX_MESSAGE) mlen = FG_DECODER_MAX_MESSAGE;
  fg_decoder_reply rep = {.version = FG_DECODER_VERSION, .rc = rc, .w = rc == 0 ? w : 0,
                          .h = rc == 0 ? h : 0, .message_len = (uint32_t)mlen,
                          .pixel_bytes = rc == 0 ? data_len : 0};
  uint8_t hdr[FG_DECODER_REPLY_SIZE];
  fg_decoder_reply_pack(&rep, hdr);
  if (fg_decoder_write_full(fd, hdr, sizeof hdr) != 0 ||
      fg_decoder_write_full(fd, message, mlen) != 0)
    return -1;
  return rc == 0 && data_len ? fg_decoder_write_full(fd, data, data_len) : 0;
}

/* An error reply, with no data. */
static int send_error(int fd, int rc, const char *message) {
  return send_reply(fd, rc, message, 0, 0, NULL, 0);
}

/* Encodes the payload of an encode request (decoder.h) to PNG and replies. */
static int encode_request(int fd, uint8_t *payload, uint64_t length) {
  int w, h, channels, bits;
  fg_error_clear();
  int rc = fg_decoder_encode_header_unpack(payload, length, &w, &h, &channels, &bits);
  uint8_t *png = NULL;
  size_t png_len = 0;
  if (rc == 0) {
    uint8_t *pixels = payload + FG_DECODER_ENCODE_HEADER;
    if (bits == 16)
      fg_decoder_u16_le((uint16_t *)(void *)pixels, (size_t)w * (size_t)h * (size_t)channels);
    rc = fg_image_encode_png(pixels, w, h, channels, bits, &png, &png_len);
  }
  if (rc == 0 && (png_len == 0 || png_len > FG_DECODER_MAX_REQUEST))
    rc = fg_fail(FG_EIO, "the PNG encoder produced %zu bytes", png_len);
  int sent = send_reply(fd, rc, rc == 0 ? "" : fg_error_detail(), w, h, png, png_len);
  free(png);
  return sent;
}

#ifdef FG_DECODE_TEST_HOOKS
static int starts_with_env(const char *var, const void *bytes, size_t len) {
  const char *magic = getenv(var);
  return magic && *magic && len >= strlen(magic) && memcmp(bytes, magic, strlen(magic)) == 0;
}

/* The test hooks (see the top of the file). */
static void crash_if_asked(const void *bytes, size_t len) {
  if (starts_with_env("FG_DECODE_CRASH_ON", bytes, len)) abort();
  if (starts_with_env("FG_DECODE_HANG_ON", bytes, len))
    for (;;) pause();
  if (starts_with_env("FG_DECODE_SPIN_ON", bytes, len))
    for (volatile unsigned long i = 0;; i++) {
    }
}

/* A test's override of a limit, or fallback. */
static long long env_or(const char *var, long long fallback) {
  const char *v = getenv(var);
  return v && *v ? strtoll(v, NULL, 10) : fallback;
}
#else
static void crash_if_asked(const void *bytes, size_t len) {
  (void)bytes;
  (void)len;
}
#endif

/* CPU seconds one request may use, over all threads. */
static long long cpu_seconds_per_request(void) {
#ifdef FG_DECODE_TEST_HOOKS
  return env_or("FG_DECODE_TEST_CPU_S", FG_DECODER_CPU_SECONDS);
#else
  return FG_DECODER_CPU_SECONDS;
#endif
}

/* The address space the process may use. */
static rlim_t address_space_limit(void) {
#ifdef FG_DECODE_TEST_HOOKS
  long long headroom_mb = env_or("FG_DECODE_TEST_AS_HEADROOM_MB", 0);
  unsigned long long pages = 0;
  FILE *f = headroom_mb > 0 ? fopen("/proc/self/statm", "re") : NULL;
  if (f) {
    if (fscanf(f, "%llu", &pages) != 1) pages = 0;
    fclose(f);
    if (pages)
      return (rlim_t)(pages * (unsigned long long)sysconf(_SC_PAGESIZE) +
                      ((unsigned long long)headroom_mb << 20));
  }
#endif
  return (rlim_t)FG_DECODER_MAX_ADDRESS_BYTES;
}

/* Sets one limit, soft and hard; a failure is reported and the program goes on (a limit the
 * kernel refuses is one less guard, not a reason to refuse images). */
static void limit(int resource, rlim_t value, const char *name) {
  struct rlimit rl = {value, value};
  if (setrlimit(resource, &rl) != 0)
    fprintf(stderr, "fieldgrip-decode: cannot set %s: %s\n", name, strerror(errno));
}

/* Confines the process before it reads untrusted data; see decoder.h for why each limit and
 * decode_seccomp.h for the system call filter. The CPU limit is set per request
 * (cpu_budget). */
static void sandbox(void) {
  if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0)
    fprintf(stderr, "fieldgrip-decode: cannot set no_new_privs: %s\n", strerror(errno));
  else if (fg_decode_seccomp() != 0)
    fprintf(stderr, "fieldgrip-decode: no system call filter: %s\n", fg_error_detail());
  limit(RLIMIT_CORE, 0, "RLIMIT_CORE");
  limit(RLIMIT_NOFILE, FG_DECODER_MAX_FDS, "RLIMIT_NOFILE");
#if !defined(__SANITIZE_ADDRESS__)
  /* (AddressSanitizer reserves terabytes of shadow memory: a sanitizer build goes without) */
  limit(RLIMIT_AS, address_space_limit(), "RLIMIT_AS");
#else
  (void)address_space_limit;
#endif
  /* No file may grow: the child writes only to pipes. A regular file as stderr (a daemon
   * whose output is redirected to a log file) would lose the child's messages, so then the
   * limit stays off. */
  struct stat st;
  if (fstat(2, &st) != 0 || !S_ISREG(st.st_mode)) {
    signal(SIGXFSZ, SIG_IGN); /* a write fails with EFBIG instead of killing */
    limit(RLIMIT_FSIZE, 0, "RLIMIT_FSIZE");
  }
}

/* Allows the next request cpu_seconds_per_request() of CPU on top of what was used: the
 * soft limit raises SIGXCPU, which ends the child (the daemon reports the image as
 * hostile). The hard limit stays unlimited so that the budget can move on. */
static void cpu_budget(void) {
  struct rusage ru;
  if (getrusage(RUSAGE_SELF, &ru) != 0) return;
  rlim_t used = (rlim_t)(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec + 1);
  struct rlimit rl = {used + (rlim_t)cpu_seconds_per_request(), RLIM_INFINITY};
  if (setrlimit(RLIMIT_CPU, &rl) != 0)
    fprintf(stderr, "fieldgrip-decode: cannot set RLIMIT_CPU: %s\n", strerror(errno));
}

/* Decodes the payload of a decode request (the encoded image) and replies. */
static int decode_request(int fd, const uint8_t *bytes, uint64_t length,
                          const float background[3]) {
  crash_if_asked(bytes, (size_t)length);
  fg_error_clear();
  fg_image img = {0};
  int rc = fg_image_decode(bytes, (size_t)length, background, &img);
  size_t n = rc == 0 ? (size_t)img.w * (size_t)img.h * 3 : 0;
  fg_decoder_floats_le(img.rgb, n);
  int sent = send_reply(fd, rc, rc == 0 ? "" : fg_error_detail(), img.w, img.h, img.rgb,
                        n * sizeof(float));
  fg_image_release(&img);
  return sent;
}

/* Decodes the payload of a depth request (scale, then the encoded depth image) and
 * replies. */
static int depth_request(int fd, const uint8_t *payload, uint64_t length) {
  double scale = fg_decoder_depth_header_unpack(payload);
  const uint8_t *bytes = payload + FG_DECODER_DEPTH_HEADER;
  size_t len = (size_t)length - FG_DECODER_DEPTH_HEADER;
  crash_if_asked(bytes, len);
  fg_error_clear();
  fg_depth_map d = {0};
  int rc = fg_depth_decode(bytes, len, scale, &d);
  size_t n = rc == 0 ? (size_t)d.w * (size_t)d.h : 0;
  fg_decoder_floats_le(d.m, n);
  int sent =
      send_reply(fd, rc, rc == 0 ? "" : fg_error_detail(), d.w, d.h, d.m, n * sizeof(float));
  fg_depth_release(&d);
  return sent;
}

int main(int argc, char **argv) {
  (void)argv;
  if (argc != 1 || isatty(0)) {
    fprintf(stderr, "fieldgrip-decode %s: the image decoder of fieldgripd, which starts it and "
                    "talks to it over pipes; it takes no arguments and is not meant to be run "
                    "by hand\n", FG_VERSION);
    return 2;
  }
  /* Die with the daemon (more exactly, with the daemon thread that started us, which lives
   * as long as the daemon's decoder pool). */
  prctl(PR_SET_PDEATHSIG, SIGKILL);

  /* Replies go out on a private copy of stdout; fd 1 itself is pointed at stderr, so that
   * anything a codec library prints cannot corrupt the stream of replies. */
  int out = fcntl(1, F_DUPFD_CLOEXEC, 3);
  if (out < 0 || dup2(2, 1) < 0) {
    fprintf(stderr, "fieldgrip-decode: cannot set up stdout: %s\n", strerror(errno));
    return 1;
  }
  sandbox();

  for (;;) {
    uint8_t hdr[FG_DECODER_REQUEST_SIZE];
    ssize_t got = fg_decoder_read_full(0, hdr, sizeof hdr);
    if (got == 0) return 0; /* the daemon is done with us */
    if (got != (ssize_t)sizeof hdr) {
      fprintf(stderr, "fieldgrip-decode: %s\n",
              got < 0 ? strerror(errno) : "the request header was cut short");
      return 1;
    }
    cpu_budget();
    fg_decoder_request req;
    if (fg_decoder_request_unpack(hdr, &req) != 0) {
      send_error(out, FG_EINVAL, fg_error_detail());
      return 1;
    }
    uint8_t *bytes = malloc(req.length ? (size_t)req.length : 1);
    if (!bytes) {
      send_error(out, FG_ENOMEM, "the image decoder is out of memory for the encoded image");
      return 1;
    }
    if (fg_decoder_read_full(0, bytes, (size_t)req.length) != (ssize_t)req.length) {
      fprintf(stderr, "fieldgrip-decode: the request's image was cut short\n");
      free(bytes);
      return 1;
    }
    int sent;
    if (req.op == FG_DECODER_OP_ENCODE_PNG)
      /* bytes is malloc'd, so the pixels after the 16-byte header are aligned for uint16. */
      sent = encode_request(out, bytes, req.length);
    else if (req.op == FG_DECODER_OP_DECODE_DEPTH)
      sent = depth_request(out, bytes, req.length);
    else
      sent = decode_request(out, bytes, req.length, req.background);
    free(bytes);
    if (sent != 0) {
      fprintf(stderr, "fieldgrip-decode: cannot send a reply: %s\n", strerror(errno));
      return 1;
    }
  }
}
