#include "core/strbuf.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void fg_strbuf_reserve(fg_strbuf *b, size_t extra) {
  if (b->failed || b->n + extra + 1 <= b->cap) return;
  size_t cap = b->cap ? b->cap : 4096;
  while (cap < b->n + extra + 1) cap *= 2;
  char *s = realloc(b->s, cap);
  if (!s) {
    b->failed = 1;
    return;
  }
  b->s = s;
  b->cap = cap;
}

void fg_strbuf_add(fg_strbuf *b, const char *p, size_t n) {
  fg_strbuf_reserve(b, n);
  if (b->failed) return;
  memcpy(b->s + b->n, p, n);
  b->n += n;
  b->s[b->n] = '\0';
}

void fg_strbuf_puts(fg_strbuf *b, const char *s) { fg_strbuf_add(b, s, strlen(s)); }

void fg_strbuf_printf(fg_strbuf *b, const char *fmt, ...) {
  for (int pass = 0; pass < 2 && !b->failed; pass++) {
    va_list ap;
    va_start(ap, fmt);
    const size_t room = b->s ? b->cap - b->n : 0;
    const int k = vsnprintf(room ? b->s + b->n : NULL, room, fmt, ap);
    va_end(ap);
    if (k < 0) {
      b->failed = 1;
      return;
    }
    if ((size_t)k < room) {
      b->n += (size_t)k;
      return;
    }
    fg_strbuf_reserve(b, (size_t)k); /* the second pass fits */
  }
}

char *fg_strbuf_take(fg_strbuf *b, size_t *len) {
  char *s = b->failed ? NULL : b->s ? b->s : calloc(1, 1);
  if (!s) free(b->s);
  if (s && len) *len = b->n;
  memset(b, 0, sizeof *b);
  return s;
}
