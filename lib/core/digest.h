/* SHA-256 (nettle's), for the places where "same bytes" must mean it: the identity of a CLIP
 * weights file and of an actuating request under an Idempotency-Key. A checksum such as
 * crc32 or a 64-bit FNV hash can be made to collide on purpose; SHA-256 cannot. */
#ifndef FG_CORE_DIGEST_H
#define FG_CORE_DIGEST_H

#include <stddef.h>
#include <stdint.h>

#define FG_SHA256_BYTES 32
#define FG_SHA256_HEX 64 /* characters, without the terminating NUL */

/* One piece of a message hashed in parts; the caller keeps data. */
typedef struct fg_span {
  const void *data;
  size_t len;
} fg_span;

/* The SHA-256 of the concatenation of parts[0..n): out [FG_SHA256_BYTES]. Parts are joined
 * as they are, so a caller hashing several fields separates them itself (a length or a byte
 * no field contains). Cannot fail. */
void fg_sha256(const fg_span *parts, size_t n, uint8_t out[FG_SHA256_BYTES]);

/* The same digest as lowercase hex, as sha256sum prints it: out [FG_SHA256_HEX + 1]. */
void fg_sha256_hex(const fg_span *parts, size_t n, char out[FG_SHA256_HEX + 1]);

/* Lowercase hex of a digest: out [FG_SHA256_HEX + 1]. */
void fg_sha256_to_hex(const uint8_t digest[FG_SHA256_BYTES], char out[FG_SHA256_HEX + 1]);

#endif
