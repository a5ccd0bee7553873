/* Carving one allocation into named arrays, so that a training step or a render keeps all its
 * scratch in one block (llm.c's habit). Use in two passes over the same fg_arena_take calls:
 * the first with base NULL only adds up the sizes (the pointers it returns are NULL), then
 * fg_arena_alloc allocates the total and the second pass hands out the real pointers:
 *
 *   fg_arena a = {0};
 *   for (int pass = 0; pass < 2; pass++) {
 *     if (pass && fg_arena_alloc(&a) < 0) return FG_ENOMEM;
 *     buf->x = fg_arena_take(&a, 3 * S * sizeof(float));
 *     ...
 *   }
 *   ... free(a.base) when done.
 * Every array starts on a 64-byte boundary. */
#ifndef FG_CORE_ARENA_H
#define FG_CORE_ARENA_H

#include <stddef.h>
#include <stdlib.h>

typedef struct fg_arena {
  char *base;  /* the block (owned by the caller after fg_arena_alloc; free() it) */
  size_t used; /* bytes handed out so far in this pass */
} fg_arena;

static inline void *fg_arena_take(fg_arena *a, size_t bytes) {
  void *p = a->base ? a->base + a->used : NULL;
  a->used += (bytes + 63) & ~(size_t)63;
  return p;
}

/* Allocates the size the first pass added up and rewinds for the second. 0 or -1. */
static inline int fg_arena_alloc(fg_arena *a) {
  a->base = aligned_alloc(64, a->used ? a->used : 64);
  if (!a->base) return -1;
  a->used = 0;
  return 0;
}

#endif
