/* fieldgrip-decode: decodes images and depth images (and encodes rendered ones to PNG) for
 * fieldgripd in a process of its own, so that the daemon never links OpenImageIO and a codec
 * crashing on a hostile image takes down only this child.
 * Reads requests on stdin and writes replies on stdout in the format decoder.h describes,
 * one at a time, until EOF on stdin. Not meant to be run by hand.
 *
 * Test hooks: when the environment has FG_DECODE_CRASH_ON=<text>, a request whose image
 * starts with those bytes makes the program abort(), standing in for a codec crash; with
 * FG_DECODE_HANG_ON=<text> it sleeps instead, standing in for a codec stuck in a loop. */
#include "decoder.h"

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

static int starts_with_env(const char *var, const void *bytes, size_t len) {
  const char *magic = getenv(var);
  return magic && *magic && len >= strlen(magic) && memcmp(bytes, magic, strlen(magic)) == 0;
}

/* The test hooks (see the top of the file). */
static void crash_if_asked(const void *bytes, size_t len) {
  if (starts_with_env("FG_DECODE_CRASH_ON", bytes, len)) abort();
  if (starts_with_env("FG_DECODE_HANG_ON", bytes, len))
    for (;;) pause();
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

  for (;;) {
    uint8_t hdr[FG_DECODER_REQUEST_SIZE];
    ssize_t got = fg_decoder_read_full(0, hdr, sizeof hdr);
    if (got == 0) return 0; /* the daemon is done with us */
    if (got != (ssize_t)sizeof hdr) {
      fprintf(stderr, "fieldgrip-decode: %s\n",
              got < 0 ? strerror(errno) : "the request header was cut short");
      return 1;
    }
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
