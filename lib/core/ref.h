/* Reference counts: an object shared between threads carries an fg_ref, starts with the
 * references its creator hands out, and is freed by whoever drops the last one. */
#ifndef FG_CORE_REF_H
#define FG_CORE_REF_H

#include <stdatomic.h>

typedef struct fg_ref {
  atomic_int n;
} fg_ref;

/* n references to start with (the creator's, and any it hands out at once). */
static inline void fg_ref_init(fg_ref *r, int n) { atomic_init(&r->n, n); }

/* One more reference. */
static inline void fg_ref_get(fg_ref *r) { atomic_fetch_add(&r->n, 1); }

/* Drops one reference: 1 when it was the last, and the caller frees the object. */
static inline int fg_ref_put(fg_ref *r) { return atomic_fetch_sub(&r->n, 1) == 1; }

/* 1 when the caller's is the only reference (no other thread can take one meanwhile: the
 * object is reachable only through a lock the caller holds). */
static inline int fg_ref_only(fg_ref *r) { return atomic_load(&r->n) == 1; }

#endif
