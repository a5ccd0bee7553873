/* Image decoding in child processes: a pool of fieldgrip-decode programs that the daemon talks
 * to over pipes, so that the daemon never links OpenImageIO (and the ~260 libraries it
 * brings) and a crash in a codec on a hostile image kills a child, not the daemon.
 *
 * The wire format (second half of this header) is shared with the child, decode_main.c. */
#ifndef FG_DAEMON_DECODER_H
#define FG_DAEMON_DECODER_H

#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "io/depth.h"
#include "io/image.h"

typedef struct fg_decoder fg_decoder;

/* Default seconds a child may sit idle before fg_decoder_reap_idle ends it. */
#define FG_DECODER_IDLE_SECONDS 30

/* Default seconds one image may take before fg_decoder_reap_idle kills the child decoding
 * it: an image within FG_IMAGE_MAX_PIXELS decodes in well under this, so a child that takes
 * longer is stuck on hostile data. */
#define FG_DECODER_BUSY_SECONDS 60

/* The limits every child sets on itself before it reads a request (decode_main.c), so that
 * a hostile image costs a bounded amount of the machine even if it takes over a codec:
 * address space FG_DECODER_MAX_ADDRESS_BYTES (room for the largest image FG_IMAGE_MAX_PIXELS
 * allows, as the encoded request and its float pixels, and the libraries' threads), CPU
 * time FG_DECODER_CPU_SECONDS per request (SIGXCPU ends the child; all threads count), no
 * core files, FG_DECODER_MAX_FDS open files, no file growth (RLIMIT_FSIZE 0, unless stderr
 * is a regular file: then the child's messages must still reach it), no_new_privs, and the
 * system call filter of decode_seccomp.h (no programs, processes, sockets, file changes or
 * other processes' signals). */
#define FG_DECODER_MAX_ADDRESS_BYTES (8ull << 30)
#define FG_DECODER_CPU_SECONDS 120
#define FG_DECODER_MAX_FDS 64

/* Creates a pool of at most max_procs (>= 1) children running program, started on demand and
 * ended after idle_seconds (>= 1) without work. program is copied; NULL means the default
 * places, tried in order at every start: fieldgrip-decode beside the running executable
 * (the build tree), then FG_LIBEXECDIR/fieldgrip/fieldgrip-decode (an install). A missing
 * program is not an error here (see fg_decoder_check). On success the caller owns *out and
 * frees it with fg_decoder_free; on failure *out is NULL. */
int fg_decoder_new(fg_decoder **out, const char *program, int max_procs, int idle_seconds);

/* Ends every child (closes its stdin, waits up to a second, then SIGKILL) and reaps it, so no
 * zombie is left; frees the pool. No decode may be running. Accepts NULL. */
void fg_decoder_free(fg_decoder *dec);

/* 0 when the decoder program can be found and executed, else FG_ENOENT with a detail naming
 * where it was looked for. Start-up uses it to warn early. */
int fg_decoder_check(fg_decoder *dec);

/* fg_image_decode in a child: same arguments, same contract, same return codes, and the
 * child's detail message re-raised with fg_fail on the calling thread. Besides those:
 * FG_EFORMAT when the child died on this image (a crash in a codec: the data is corrupt or
 * hostile; the next call starts a fresh child), FG_ENOENT when the program is missing,
 * FG_EIO when a child cannot be started or talked to. Blocks while max_procs decodes are
 * running. Thread-safe. On success the caller owns out->rgb (fg_image_release); on failure
 * *out is empty. */
int fg_decoder_decode(fg_decoder *dec, const void *bytes, size_t len,
                      const float background_rgb[3], fg_image *out);

/* fg_decoder_decode of an image a client sent: a failure the image caused carries the
 * reason invalid_image, the server's own (the program missing, a child that cannot be
 * started or talked to, memory) internal_error, each with the detail. */
int fg_decoder_decode_sent(fg_decoder *dec, const void *bytes, size_t len,
                           const float background_rgb[3], fg_image *out);

/* fg_depth_decode (io/depth.h) in a child: a PNG, TIFF or OpenEXR depth image read raw,
 * 16-bit values times scale (metres per unit), float values as metres. Same contract and
 * codes as fg_depth_decode, the child's detail re-raised with fg_fail on the calling thread,
 * and otherwise the codes of fg_decoder_decode (FG_EFORMAT for a child that died on the
 * image, FG_ENOENT, FG_EIO). .npy depth needs no codec: read it with fg_depth_from_npy.
 * Thread-safe; shares the pool and its limits with decoding. On success the caller owns
 * out->m (fg_depth_release); on failure *out is empty. */
int fg_decoder_decode_depth(fg_decoder *dec, const void *bytes, size_t len, double scale,
                            fg_depth_map *out);

/* Encodes pixels to PNG with fg_image_encode_png (io/image.h) in a child, so that the
 * daemon never loads the encoder's libraries either. pixels are [h][w][channels] of uint8_t
 * (bits 8) or uint16_t (bits 16, host order), channels 1, 3 or 4, w and h within
 * FG_IMAGE_MAX_SIDE and FG_IMAGE_MAX_PIXELS; pixels stay the caller's. On success the caller
 * owns *out (free); on failure *out is NULL. FG_EINVAL for bad arguments (detail), and the
 * codes of fg_decoder_decode for a child that is missing, cannot be talked to or dies.
 * Thread-safe; shares the pool and its limits with decoding. */
int fg_decoder_encode_png(fg_decoder *dec, const void *pixels, int w, int h, int channels,
                          int bits, uint8_t **out, size_t *out_len);

/* Changes the busy limit (default FG_DECODER_BUSY_SECONDS, >= 1); for tests. */
void fg_decoder_set_busy_limit(fg_decoder *dec, int seconds);

/* Ends children idle for more than idle_seconds, and kills those busy on one image for more
 * than the busy limit (their decode then fails with FG_EFORMAT saying so); the daemon calls
 * it every second or so.
 * Waits for them to exit (they do at once on EOF), so it may take a few milliseconds. When it
 * ended any, it also returns the process's free heap memory to the system (malloc_trim). */
void fg_decoder_reap_idle(fg_decoder *dec);

/* How requests to the pool ended: the child answered with the result (ok) or with an error
 * about the data (refused), the child died on the request (crashed), the reaper killed it
 * for overrunning the busy limit (timeout), or the pool could not run it at all (error: no
 * program, no child could be started or talked to, out of memory). */
typedef enum {
  FG_DECODER_OK = 0,
  FG_DECODER_REFUSED,
  FG_DECODER_CRASHED,
  FG_DECODER_TIMEOUT,
  FG_DECODER_ERROR,
  FG_DECODER_RESULTS
} fg_decoder_result;

/* The pool's counters since fg_decoder_new, for /metrics. */
typedef struct fg_decoder_stats {
  int idle, busy;                        /* children alive now, by state */
  uint64_t started;                      /* children started (a crashed one is replaced by a
                                            start too) */
  uint64_t died_idle;                    /* children found dead before a request reached
                                            them (killed from outside, OOM) */
  uint64_t requests[FG_DECODER_RESULTS]; /* decodes, depth decodes and encodes, by result */
} fg_decoder_stats;

/* Fills *out; a NULL pool gives zeros. Thread-safe. */
void fg_decoder_get_stats(fg_decoder *dec, fg_decoder_stats *out);

/* Test hook: writes the pids of up to max live children (idle or busy) to pids and returns
 * how many there are. */
size_t fg_decoder_child_pids(fg_decoder *dec, pid_t *pids, size_t max);

/* ---- wire format -----------------------------------------------------------------------
 * The daemon writes a request on the child's stdin and reads the reply on its stdout; every
 * integer is little-endian, floats are IEEE 754 binary32 (f32) or binary64 (f64) in
 * little-endian byte order.
 *
 *   request (40 bytes): "FGDQ", u32 version (2), u32 op, u32 reserved (0),
 *                       f32 background[3], u32 pad (0), u64 length; then length bytes of
 *                       payload:
 *                       op 1 (decode): the encoded image;
 *                       op 2 (encode PNG): u32 w, u32 h, u32 channels (1, 3, 4), u32 bits
 *                       (8, 16), then the pixels [h][w][channels] (uint16 little-endian
 *                       when bits is 16); length = 16 + w h channels bits / 8; background
 *                       is unused (zero);
 *                       op 3 (decode depth): f64 scale (metres per unit of 16-bit depth,
 *                       passed on unchecked: the child's fg_depth_decode judges it), then
 *                       the encoded depth image; length = 8 + its length; background is
 *                       unused (zero).
 *   reply (32 bytes):   "FGDR", u32 version, i32 rc (0 or an FG_E* code), i32 w, i32 h,
 *                       u32 message length, u64 pixel bytes; then the message (the child's
 *                       fg_error_detail(), no NUL), then, when rc is 0:
 *                       op 1: float RGB [h][w][3] (pixel bytes = w h 12);
 *                       op 2: the PNG file (pixel bytes = its length; w, h echo the
 *                       request's);
 *                       op 3: float metres [h][w], 0 where invalid (pixel bytes = w h 4).
 *
 * Version 2 added op 3. Daemon and child come from one build; a child that answers with
 * another version is refused as a broken installation rather than asked for ops it may not
 * know, and a request of another version gets an FG_EINVAL reply.
 *
 * The child reads a whole request before it replies, so the daemon may write the request and
 * then read the reply. A request the child cannot parse gets an FG_EINVAL reply, after which
 * the child exits; EOF on its stdin makes it exit 0. */

#define FG_DECODER_VERSION 2u
#define FG_DECODER_OP_DECODE 1u
#define FG_DECODER_OP_ENCODE_PNG 2u
#define FG_DECODER_OP_DECODE_DEPTH 3u
#define FG_DECODER_ENCODE_HEADER 16 /* the encode payload's w, h, channels, bits */
#define FG_DECODER_DEPTH_HEADER 8   /* the depth payload's scale */
#define FG_DECODER_REQUEST_SIZE 40
#define FG_DECODER_REPLY_SIZE 32
#define FG_DECODER_MAX_REQUEST (1ull << 30) /* bytes of encoded image */
#define FG_DECODER_MAX_MESSAGE 4096u

typedef struct fg_decoder_request {
  uint32_t version, op;
  float background[3];
  uint64_t length;
} fg_decoder_request;

typedef struct fg_decoder_reply {
  uint32_t version;
  int32_t rc, w, h;
  uint32_t message_len;
  uint64_t pixel_bytes;
} fg_decoder_reply;

void fg_decoder_request_pack(const fg_decoder_request *req, uint8_t out[FG_DECODER_REQUEST_SIZE]);
/* Checks the magic, the version, the op and the length; FG_EINVAL with a detail otherwise.
 * *req is filled as far as it could be read either way. */
int fg_decoder_request_unpack(const uint8_t in[FG_DECODER_REQUEST_SIZE], fg_decoder_request *req);

void fg_decoder_reply_pack(const fg_decoder_reply *rep, uint8_t out[FG_DECODER_REPLY_SIZE]);
/* Checks the magic, the version and that the sizes agree with rc, w and h for a reply to a
 * decode (op 1); FG_EINVAL with a detail otherwise. */
int fg_decoder_reply_unpack(const uint8_t in[FG_DECODER_REPLY_SIZE], fg_decoder_reply *rep);

/* The same for a reply to an encode (op 2): the PNG's length instead of the pixels'. */
int fg_decoder_reply_unpack_encode(const uint8_t in[FG_DECODER_REPLY_SIZE],
                                   fg_decoder_reply *rep);

/* The same for a reply to a depth decode (op 3): one float per pixel. */
int fg_decoder_reply_unpack_depth(const uint8_t in[FG_DECODER_REPLY_SIZE],
                                  fg_decoder_reply *rep);

/* The encode payload's header (FG_DECODER_ENCODE_HEADER bytes), packed and checked against
 * the request's length: sizes within the image limits, channels 1, 3 or 4, bits 8 or 16.
 * FG_EINVAL with a detail otherwise. */
void fg_decoder_encode_header_pack(int w, int h, int channels, int bits,
                                   uint8_t out[FG_DECODER_ENCODE_HEADER]);
int fg_decoder_encode_header_unpack(const uint8_t in[FG_DECODER_ENCODE_HEADER], uint64_t length,
                                    int *w, int *h, int *channels, int *bits);

/* The depth payload's header (FG_DECODER_DEPTH_HEADER bytes): the scale as f64. Any value
 * travels, NaN included; fg_depth_decode in the child refuses the bad ones. */
void fg_decoder_depth_header_pack(double scale, uint8_t out[FG_DECODER_DEPTH_HEADER]);
double fg_decoder_depth_header_unpack(const uint8_t in[FG_DECODER_DEPTH_HEADER]);

/* Converts n floats between host order and the wire's little-endian order, in place (a no-op
 * on little-endian hosts). */
void fg_decoder_floats_le(float *v, size_t n);

/* The same for n uint16 values. */
void fg_decoder_u16_le(uint16_t *v, size_t n);

/* read(2) and write(2) of exactly n bytes, through EINTR and short transfers. read returns
 * the bytes read (less than n only at EOF) or -1 with errno; write returns 0 or -1 with
 * errno (EPIPE when the reader is gone; the caller decides about SIGPIPE). */
ssize_t fg_decoder_read_full(int fd, void *buf, size_t n);
int fg_decoder_write_full(int fd, const void *buf, size_t n);

#endif
