/* The tokenizer's text cleaning (tokenizer.c, steps 2 and 3 of its comment) on Unicode code
 * points: strict and repairing UTF-8, Python's html.unescape, and strip() with runs of
 * White_Space made one space, each exactly as the Python reference does it. Used by
 * tokenizer.c; its tests go through fg_tokenizer_encode (tests/clip). */
#ifndef FG_CLIP_TEXT_CLEAN_H
#define FG_CLIP_TEXT_CLEAN_H

#include <stddef.h>
#include <stdint.h>

/* Writes c (<= U+10FFFF, not a surrogate) as UTF-8; returns the byte count (1-4). */
size_t fg_clip_utf8_put(uint8_t *o, uint32_t c);

/* Decodes strict UTF-8 s[0, len) into out (room for len code points); *n receives the count.
 * FG_EINVAL names the byte offset of the first bad sequence and what is wrong with it. */
int fg_clip_utf8_decode(const uint8_t *s, size_t len, uint32_t *out, size_t *n);

/* Copies s[0, len) to out replacing each maximal ill-formed subsequence with U+FFFD, as
 * Python's bytes.decode("utf-8", errors="replace"); out needs room for 3 * len bytes.
 * Returns the bytes written. */
size_t fg_clip_utf8_repair(const uint8_t *s, size_t len, uint8_t *out);

/* One pass of Python's html.unescape over c[0, n), in place; returns the new length. */
size_t fg_clip_html_unescape(uint32_t *c, size_t n);

/* \s of the regex module on str: the White_Space property. */
int fg_clip_is_white_space(uint32_t c);

/* Python's str.isspace, which strip() uses: White_Space plus the separators U+001C-U+001F. */
int fg_clip_is_py_space(uint32_t c);

/* strip(), then every run of White_Space to one space, in place; returns the new length. */
size_t fg_clip_clean_whitespace(uint32_t *c, size_t n);

#endif
