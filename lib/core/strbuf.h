/* A growing, NUL-terminated string built by appends: for texts written by hand because they
 * are long (a heatmap of 10^5 points, the metrics page, a model file). A failed allocation
 * is sticky: later appends do nothing and fg_strbuf_take returns NULL. */
#ifndef FG_CORE_STRBUF_H
#define FG_CORE_STRBUF_H

#include <stddef.h>

typedef struct fg_strbuf {
  char *s;      /* NULL until the first append */
  size_t n;     /* bytes written, not counting the NUL */
  size_t cap;
  int failed;
} fg_strbuf;

/* Room for `extra` more bytes (and the NUL) at once: a writer that knows the size it will
 * reach spares the doublings. */
void fg_strbuf_reserve(fg_strbuf *b, size_t extra);

/* Appends the n bytes at p. */
void fg_strbuf_add(fg_strbuf *b, const char *p, size_t n);

/* Appends the string s. */
void fg_strbuf_puts(fg_strbuf *b, const char *s);

/* Appends the formatted text. */
void fg_strbuf_printf(fg_strbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* The text, malloc'd and NUL-terminated ("" after no append), with its length in *len (may
 * be NULL); NULL when an append failed. Either way b holds nothing afterwards. */
char *fg_strbuf_take(fg_strbuf *b, size_t *len);

#endif
