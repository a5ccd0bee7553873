/* Fuzz target for the framing between the daemon and its image-decoder children
 * (decoder_wire.c, the format in decoder.h), in both directions. The first byte picks the
 * message; the rest is it (zero-padded to the fixed size when short):
 *   0: a request header, as the child reads it (then, by op, the encode or depth payload
 *      header that follows it);
 *   1, 2, 3: a reply header, as the daemon reads it after a decode, an encode or a depth
 *      decode.
 * Every input either unpacks or fails with FG_EINVAL; what unpacks obeys the limits the
 * reader relies on (sizes within the image limits, lengths that add up) and packs back to
 * the same bytes. */
#include "core/error.h"
#include "io/image.h"
#include "decoder/decoder.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Copies up to n bytes of the input after *off into out, zero-padding the rest. */
static void take(const uint8_t *data, size_t size, size_t *off, uint8_t *out, size_t n) {
  size_t k = *off < size ? size - *off : 0;
  if (k > n) k = n;
  memset(out, 0, n);
  if (k) memcpy(out, data + *off, k);
  *off += n;
}

static void check_request(const uint8_t *data, size_t size, size_t off) {
  uint8_t in[FG_DECODER_REQUEST_SIZE], back[FG_DECODER_REQUEST_SIZE];
  take(data, size, &off, in, sizeof in);
  fg_decoder_request req;
  int rc = fg_decoder_request_unpack(in, &req);
  if (rc != 0) {
    if (rc != FG_EINVAL) abort();
    return;
  }
  if (req.version != FG_DECODER_VERSION || req.length > FG_DECODER_MAX_REQUEST) abort();
  fg_decoder_request_pack(&req, back);
  /* the reserved words are not kept: compare the rest */
  if (memcmp(in, back, 12) != 0 || memcmp(in + 16, back + 16, 12) != 0 ||
      memcmp(in + 32, back + 32, 8) != 0)
    abort();
  if (req.op == FG_DECODER_OP_ENCODE_PNG) {
    uint8_t eh[FG_DECODER_ENCODE_HEADER], eb[FG_DECODER_ENCODE_HEADER];
    take(data, size, &off, eh, sizeof eh);
    int w, h, ch, bits;
    rc = fg_decoder_encode_header_unpack(eh, req.length, &w, &h, &ch, &bits);
    if (rc == 0) {
      if (w < 1 || h < 1 || w > FG_IMAGE_MAX_SIDE || h > FG_IMAGE_MAX_SIDE ||
          (uint64_t)w * (uint64_t)h > FG_IMAGE_MAX_PIXELS ||
          req.length != FG_DECODER_ENCODE_HEADER + (uint64_t)w * h * ch * (bits / 8))
        abort();
      fg_decoder_encode_header_pack(w, h, ch, bits, eb);
      if (memcmp(eh, eb, sizeof eh) != 0) abort();
    } else if (rc != FG_EINVAL || w || h || ch || bits) {
      abort();
    }
  } else if (req.op == FG_DECODER_OP_DECODE_DEPTH) {
    uint8_t dh[FG_DECODER_DEPTH_HEADER], db[FG_DECODER_DEPTH_HEADER];
    take(data, size, &off, dh, sizeof dh);
    fg_decoder_depth_header_pack(fg_decoder_depth_header_unpack(dh), db);
    if (memcmp(dh, db, sizeof dh) != 0) abort(); /* any f64 travels, NaN payloads included */
  }
}

static void check_reply(const uint8_t *data, size_t size, size_t off, int kind) {
  uint8_t in[FG_DECODER_REPLY_SIZE], back[FG_DECODER_REPLY_SIZE];
  take(data, size, &off, in, sizeof in);
  fg_decoder_reply rep;
  int rc = kind == 1   ? fg_decoder_reply_unpack(in, &rep)
           : kind == 2 ? fg_decoder_reply_unpack_encode(in, &rep)
                       : fg_decoder_reply_unpack_depth(in, &rep);
  if (rc != 0) {
    if (rc != FG_EINVAL) abort();
    return;
  }
  if (rep.version != FG_DECODER_VERSION || rep.message_len > FG_DECODER_MAX_MESSAGE ||
      rep.rc > 0)
    abort();
  if (rep.rc == 0) {
    if (rep.w < 1 || rep.h < 1 || rep.w > FG_IMAGE_MAX_SIDE || rep.h > FG_IMAGE_MAX_SIDE)
      abort();
    /* what the daemon then allocates and reads */
    uint64_t px = (uint64_t)rep.w * (uint64_t)rep.h;
    if (kind == 1 && rep.pixel_bytes != px * 12) abort();
    if (kind == 3 && rep.pixel_bytes != px * 4) abort();
    if (kind == 2 && (rep.pixel_bytes == 0 || rep.pixel_bytes > FG_DECODER_MAX_REQUEST)) abort();
    if (kind != 2 && px > FG_IMAGE_MAX_PIXELS) abort();
  } else if (rep.w || rep.h || rep.pixel_bytes) {
    abort();
  }
  fg_decoder_reply_pack(&rep, back);
  if (memcmp(in, back, sizeof in) != 0) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size == 0) return 0;
  int kind = data[0] & 3;
  if (kind == 0)
    check_request(data, size, 1);
  else
    check_reply(data, size, 1, kind);
  return 0;
}
