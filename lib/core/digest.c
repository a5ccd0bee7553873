/* SHA-256 through nettle; see digest.h. */
#include "digest.h"

#include <nettle/sha2.h>

void fg_sha256(const fg_span *parts, size_t n, uint8_t out[FG_SHA256_BYTES]) {
  struct sha256_ctx ctx;
  sha256_init(&ctx);
  for (size_t i = 0; i < n; i++)
    if (parts[i].len) sha256_update(&ctx, parts[i].len, parts[i].data);
  sha256_digest(&ctx, SHA256_DIGEST_SIZE, out);
}

void fg_sha256_to_hex(const uint8_t digest[FG_SHA256_BYTES], char out[FG_SHA256_HEX + 1]) {
  static const char hex[] = "0123456789abcdef";
  for (int i = 0; i < FG_SHA256_BYTES; i++) {
    out[2 * i] = hex[digest[i] >> 4];
    out[2 * i + 1] = hex[digest[i] & 15];
  }
  out[FG_SHA256_HEX] = '\0';
}

void fg_sha256_hex(const fg_span *parts, size_t n, char out[FG_SHA256_HEX + 1]) {
  uint8_t d[FG_SHA256_BYTES];
  fg_sha256(parts, n, d);
  fg_sha256_to_hex(d, out);
}
