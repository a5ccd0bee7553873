/* The wire format between fieldgripd and fieldgrip-decode (decoder.h): packing and checking
 * of requests and replies, byte order, and whole-buffer pipe I/O. Apart from the pool
 * (decoder.c) because the child needs only this half. */
#include "decoder.h"

#include "core/error.h"

#include <errno.h>
#include <limits.h>
#include <string.h>
#include <unistd.h>

static void put_u32(uint8_t *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static void put_u64(uint8_t *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static uint32_t get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t get_u64(const uint8_t *p) {
  return (uint64_t)get_u32(p) | (uint64_t)get_u32(p + 4) << 32;
}

static void put_f32(uint8_t *p, float v) {
  uint32_t u;
  memcpy(&u, &v, 4);
  put_u32(p, u);
}

static float get_f32(const uint8_t *p) {
  uint32_t u = get_u32(p);
  float v;
  memcpy(&v, &u, 4);
  return v;
}

static void put_f64(uint8_t *p, double v) {
  uint64_t u;
  memcpy(&u, &v, 8);
  put_u64(p, u);
}

static double get_f64(const uint8_t *p) {
  uint64_t u = get_u64(p);
  double v;
  memcpy(&v, &u, 8);
  return v;
}

void fg_decoder_request_pack(const fg_decoder_request *req, uint8_t out[FG_DECODER_REQUEST_SIZE]) {
  memcpy(out, "FGDQ", 4);
  put_u32(out + 4, req->version);
  put_u32(out + 8, req->op);
  put_u32(out + 12, 0);
  for (int k = 0; k < 3; k++) put_f32(out + 16 + 4 * k, req->background[k]);
  put_u32(out + 28, 0);
  put_u64(out + 32, req->length);
}

int fg_decoder_request_unpack(const uint8_t in[FG_DECODER_REQUEST_SIZE], fg_decoder_request *req) {
  req->version = get_u32(in + 4);
  req->op = get_u32(in + 8);
  for (int k = 0; k < 3; k++) req->background[k] = get_f32(in + 16 + 4 * k);
  req->length = get_u64(in + 32);
  if (memcmp(in, "FGDQ", 4) != 0)
    return fg_fail(FG_EINVAL, "decoder request: bad magic %02x %02x %02x %02x, expected FGDQ",
                   in[0], in[1], in[2], in[3]);
  if (req->version != FG_DECODER_VERSION)
    return fg_fail(FG_EINVAL, "decoder request: protocol version %u, this decoder speaks %u",
                   (unsigned)req->version, FG_DECODER_VERSION);
  if (req->op != FG_DECODER_OP_DECODE && req->op != FG_DECODER_OP_ENCODE_PNG &&
      req->op != FG_DECODER_OP_DECODE_DEPTH)
    return fg_fail(FG_EINVAL, "decoder request: unknown op %u", (unsigned)req->op);
  if (req->length > FG_DECODER_MAX_REQUEST)
    return fg_fail(FG_EINVAL, "decoder request: %llu bytes of image, more than the %llu allowed",
                   (unsigned long long)req->length, (unsigned long long)FG_DECODER_MAX_REQUEST);
  if (req->op == FG_DECODER_OP_ENCODE_PNG && req->length < FG_DECODER_ENCODE_HEADER)
    return fg_fail(FG_EINVAL, "decoder request: an encode request of %llu bytes has no room for "
                   "its %d-byte header", (unsigned long long)req->length,
                   FG_DECODER_ENCODE_HEADER);
  if (req->op == FG_DECODER_OP_DECODE_DEPTH && req->length < FG_DECODER_DEPTH_HEADER)
    return fg_fail(FG_EINVAL, "decoder request: a depth request of %llu bytes has no room for "
                   "its %d-byte scale", (unsigned long long)req->length,
                   FG_DECODER_DEPTH_HEADER);
  return 0;
}

void fg_decoder_depth_header_pack(double scale, uint8_t out[FG_DECODER_DEPTH_HEADER]) {
  put_f64(out, scale);
}

double fg_decoder_depth_header_unpack(const uint8_t in[FG_DECODER_DEPTH_HEADER]) {
  return get_f64(in);
}

void fg_decoder_encode_header_pack(int w, int h, int channels, int bits,
                                   uint8_t out[FG_DECODER_ENCODE_HEADER]) {
  put_u32(out, (uint32_t)w);
  put_u32(out + 4, (uint32_t)h);
  put_u32(out + 8, (uint32_t)channels);
  put_u32(out + 12, (uint32_t)bits);
}

int fg_decoder_encode_header_unpack(const uint8_t in[FG_DECODER_ENCODE_HEADER], uint64_t length,
                                    int *w, int *h, int *channels, int *bits) {
  uint32_t uw = get_u32(in), uh = get_u32(in + 4), uc = get_u32(in + 8), ub = get_u32(in + 12);
  *w = *h = *channels = *bits = 0;
  if (uw < 1 || uh < 1 || uw > FG_IMAGE_MAX_SIDE || uh > FG_IMAGE_MAX_SIDE ||
      (uint64_t)uw * uh > FG_IMAGE_MAX_PIXELS)
    return fg_fail(FG_EINVAL, "encode request: a %ux%u image is outside the limits (sides up to "
                   "%d, %u pixels)", (unsigned)uw, (unsigned)uh, FG_IMAGE_MAX_SIDE,
                   FG_IMAGE_MAX_PIXELS);
  if ((uc != 1 && uc != 3 && uc != 4) || (ub != 8 && ub != 16))
    return fg_fail(FG_EINVAL, "encode request: %u channels of %u bits; PNG encoding takes 1, 3 "
                   "or 4 channels of 8 or 16 bits", (unsigned)uc, (unsigned)ub);
  uint64_t need = FG_DECODER_ENCODE_HEADER + (uint64_t)uw * uh * uc * (ub / 8);
  if (length != need)
    return fg_fail(FG_EINVAL, "encode request: %llu bytes, expected %llu for a %ux%u image of "
                   "%u channels of %u bits", (unsigned long long)length,
                   (unsigned long long)need, (unsigned)uw, (unsigned)uh, (unsigned)uc,
                   (unsigned)ub);
  *w = (int)uw;
  *h = (int)uh;
  *channels = (int)uc;
  *bits = (int)ub;
  return 0;
}

void fg_decoder_reply_pack(const fg_decoder_reply *rep, uint8_t out[FG_DECODER_REPLY_SIZE]) {
  memcpy(out, "FGDR", 4);
  put_u32(out + 4, rep->version);
  put_u32(out + 8, (uint32_t)rep->rc);
  put_u32(out + 12, (uint32_t)rep->w);
  put_u32(out + 16, (uint32_t)rep->h);
  put_u32(out + 20, rep->message_len);
  put_u64(out + 24, rep->pixel_bytes);
}

/* The checks every reply gets; *done = 1 when nothing is left to check (an error reply). */
static int reply_unpack_common(const uint8_t in[FG_DECODER_REPLY_SIZE], fg_decoder_reply *rep,
                               int *done) {
  *done = 0;
  rep->version = get_u32(in + 4);
  rep->rc = (int32_t)get_u32(in + 8);
  rep->w = (int32_t)get_u32(in + 12);
  rep->h = (int32_t)get_u32(in + 16);
  rep->message_len = get_u32(in + 20);
  rep->pixel_bytes = get_u64(in + 24);
  if (memcmp(in, "FGDR", 4) != 0)
    return fg_fail(FG_EINVAL, "decoder reply: bad magic %02x %02x %02x %02x, expected FGDR",
                   in[0], in[1], in[2], in[3]);
  if (rep->version != FG_DECODER_VERSION)
    return fg_fail(FG_EINVAL, "decoder reply: protocol version %u, this daemon speaks %u",
                   (unsigned)rep->version, FG_DECODER_VERSION);
  if (rep->message_len > FG_DECODER_MAX_MESSAGE)
    return fg_fail(FG_EINVAL, "decoder reply: message of %u bytes", (unsigned)rep->message_len);
  if (rep->rc > 0 || rep->rc < -1000)
    return fg_fail(FG_EINVAL, "decoder reply: rc %d is not an error code", (int)rep->rc);
  if (rep->rc != 0) {
    if (rep->pixel_bytes != 0 || rep->w != 0 || rep->h != 0)
      return fg_fail(FG_EINVAL, "decoder reply: an error with pixels");
    *done = 1;
  }
  return 0;
}

int fg_decoder_reply_unpack_encode(const uint8_t in[FG_DECODER_REPLY_SIZE],
                                   fg_decoder_reply *rep) {
  int done;
  FG_TRY(reply_unpack_common(in, rep, &done));
  if (done) return 0;
  if (rep->w <= 0 || rep->h <= 0 || rep->w > FG_IMAGE_MAX_SIDE || rep->h > FG_IMAGE_MAX_SIDE ||
      rep->pixel_bytes == 0 || rep->pixel_bytes > FG_DECODER_MAX_REQUEST)
    return fg_fail(FG_EINVAL, "decoder reply: a %dx%d PNG of %llu bytes", (int)rep->w,
                   (int)rep->h, (unsigned long long)rep->pixel_bytes);
  return 0;
}

/* A reply that carries nch floats per pixel of a w x h image within the image limits. */
static int reply_unpack_floats(const uint8_t in[FG_DECODER_REPLY_SIZE], fg_decoder_reply *rep,
                               uint64_t nch) {
  int done;
  FG_TRY(reply_unpack_common(in, rep, &done));
  if (done) return 0;
  if (rep->w <= 0 || rep->h <= 0 || rep->w > FG_IMAGE_MAX_SIDE || rep->h > FG_IMAGE_MAX_SIDE ||
      (uint64_t)rep->w * (uint64_t)rep->h > FG_IMAGE_MAX_PIXELS ||
      rep->pixel_bytes != (uint64_t)rep->w * (uint64_t)rep->h * nch * sizeof(float))
    return fg_fail(FG_EINVAL, "decoder reply: %dx%d image with %llu bytes of pixels", (int)rep->w,
                   (int)rep->h, (unsigned long long)rep->pixel_bytes);
  return 0;
}

int fg_decoder_reply_unpack(const uint8_t in[FG_DECODER_REPLY_SIZE], fg_decoder_reply *rep) {
  return reply_unpack_floats(in, rep, 3);
}

int fg_decoder_reply_unpack_depth(const uint8_t in[FG_DECODER_REPLY_SIZE],
                                  fg_decoder_reply *rep) {
  return reply_unpack_floats(in, rep, 1);
}

void fg_decoder_floats_le(float *v, size_t n) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  for (size_t i = 0; i < n; i++) {
    uint32_t u;
    memcpy(&u, &v[i], 4);
    u = __builtin_bswap32(u);
    memcpy(&v[i], &u, 4);
  }
#else
  (void)v;
  (void)n;
#endif
}

void fg_decoder_u16_le(uint16_t *v, size_t n) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  for (size_t i = 0; i < n; i++) v[i] = __builtin_bswap16(v[i]);
#else
  (void)v;
  (void)n;
#endif
}

ssize_t fg_decoder_read_full(int fd, void *buf, size_t n) {
  size_t got = 0;
  while (got < n) {
    size_t want = n - got < (size_t)SSIZE_MAX ? n - got : (size_t)SSIZE_MAX;
    ssize_t r = read(fd, (char *)buf + got, want);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return -1;
    if (r == 0) break;
    got += (size_t)r;
  }
  return (ssize_t)got;
}

int fg_decoder_write_full(int fd, const void *buf, size_t n) {
  size_t done = 0;
  while (done < n) {
    size_t want = n - done < (size_t)SSIZE_MAX ? n - done : (size_t)SSIZE_MAX;
    ssize_t r = write(fd, (const char *)buf + done, want);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return -1;
    done += (size_t)r;
  }
  return 0;
}
